//! Whose fault an error is, and the errors modules share.
//!
//! Every module has its own error enum (image-rs's `error.rs` and kornia-rs's per-crate enums
//! are the examples), and every one of them answers `fault()`: the variant is chosen where the
//! error arises, and the variant decides the fault. The pipeline's `expect_error` and the
//! command line's message read it from there; nothing classifies an error after the fact.
//! (The error the colour and hdr fits share is `crate::fit::FitError`.)

/// Whose fault an error is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Fault {
    /// The input is wrong: a setting, a value, a file's content, an image without the thing
    /// it should show. The message names which and what was expected.
    BadInput,
    /// A solver could not reach an answer from input that was well formed (a degenerate
    /// configuration, an ill-conditioned system).
    Numerical,
    /// A file could not be read or written (missing, unreadable, disk full).
    Io,
    /// The input is well formed but asks for something lumen does not do.
    Unsupported,
}

impl Fault {
    pub const ALL: [Fault; 4] = [Fault::BadInput, Fault::Numerical, Fault::Io, Fault::Unsupported];

    /// The name a pipeline's `expect_error` and the report use.
    pub fn name(self) -> &'static str {
        match self {
            Fault::BadInput => "bad-input",
            Fault::Numerical => "numerical",
            Fault::Io => "io",
            Fault::Unsupported => "unsupported",
        }
    }
}

impl std::fmt::Display for Fault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Fault {
    type Err = Invalid;
    fn from_str(s: &str) -> Result<Fault, Invalid> {
        Fault::ALL.into_iter().find(|f| f.name() == s).ok_or_else(|| {
            let names: Vec<String> = Fault::ALL.iter().map(|f| format!("`{f}`")).collect();
            Invalid(format!("`{s}` is not a kind of error: expected one of {}", names.join(", ")))
        })
    }
}

/// A value, setting or piece of text that is not what was expected. The message names the
/// value and what was expected; the caller adds the file or field it came from. Its fault is
/// always `BadInput`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct Invalid(pub String);

impl Invalid {
    pub fn fault(&self) -> Fault {
        Fault::BadInput
    }
}

impl From<String> for Invalid {
    fn from(s: String) -> Invalid {
        Invalid(s)
    }
}

impl From<&str> for Invalid {
    fn from(s: &str) -> Invalid {
        Invalid(s.into())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fault_names_read_back() {
        for f in Fault::ALL {
            assert_eq!(f.name().parse::<Fault>(), Ok(f));
        }
        let e = "flood".parse::<Fault>().unwrap_err();
        assert_eq!(e.fault(), Fault::BadInput);
        assert!(e.0.contains("`flood`") && e.0.contains("`numerical`"), "{e}");
    }
}
