//! What the fitting solvers that read measurements or images and fit a model to them (`color`,
//! `hdr`) share: their error.

use crate::error::{Fault, Invalid};
use std::path::PathBuf;

/// The colour and the hdr fit's error.
#[derive(Debug, thiserror::Error)]
pub enum FitError {
    /// The input or a setting is wrong (names what and why).
    #[error("{0}")]
    BadInput(String),
    /// The measurements do not determine the model.
    #[error("{0}")]
    Unsolvable(String),
    /// A file that was read but whose content is wrong.
    #[error("{path}: {message}")]
    File { path: PathBuf, message: String },
    /// A file that could not be read or written.
    #[error("{path}: {message}")]
    Io { path: PathBuf, message: String },
    #[error(transparent)]
    Image(#[from] crate::image::io::Error),
}

impl FitError {
    pub fn fault(&self) -> Fault {
        match self {
            FitError::BadInput(_) | FitError::File { .. } => Fault::BadInput,
            FitError::Unsolvable(_) => Fault::Numerical,
            FitError::Io { .. } => Fault::Io,
            FitError::Image(e) => e.fault(),
        }
    }
}

impl From<Invalid> for FitError {
    fn from(e: Invalid) -> FitError {
        FitError::BadInput(e.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fit_error_takes_its_images_fault() {
        let read = crate::image::io::Error::Read { path: "a.png".into(), message: "gone".into() };
        assert_eq!(FitError::from(read).fault(), Fault::Io);
        let format = crate::image::io::Error::Format { path: "a.txt".into() };
        assert_eq!(FitError::from(format).fault(), Fault::BadInput);
        assert_eq!(FitError::Unsolvable("flat".into()).fault(), Fault::Numerical);
        assert_eq!(
            FitError::File { path: "l.txt".into(), message: "line 2".into() }.fault(),
            Fault::BadInput
        );
    }
}
