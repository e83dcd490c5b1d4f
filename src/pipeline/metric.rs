//! A stage's measured quantities, each with the direction that is better, its bound and its
//! verdict. A value that could not be measured is `None` with the reason, never a sentinel
//! such as NaN or infinity: a missing or non-finite value misses any bound it has.
//!
//! A bound is a range, `{ min = a, max = b }` with either end optional; a plain number in a
//! pipeline file is the end the metric's own direction makes it (an upper bound on an error,
//! a lower bound on a count of what was found). A declared miss is a claim too: once every
//! case of its entry meets the bound, the run fails until the declaration goes, as a strict
//! expected failure does (`Report::misses_now_met`).

use crate::error::Invalid;
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Better {
    Lower,
    Higher,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Metric {
    pub name: String,
    /// `None` when the quantity could not be measured (`missing` says why).
    pub value: Option<f64>,
    pub unit: String,
    /// Whether the bound is an upper (`lower` is better) or a lower bound.
    pub better: Better,
    pub bound: Option<Bound>,
    pub pass: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub missing: Option<String>,
    /// Not measured on purpose (its data are absent, e.g. `../shared`): no verdict, no miss.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skipped: Option<String>,
    /// Not measured because it has no meaning for this case (a per-pixel z-test on a denoised
    /// image, a denoising gain on a raw render): no verdict, no miss, and nothing is absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub not_applicable: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub expected_miss: Option<String>,
}

impl Metric {
    /// A measured value; a non-finite one is recorded as missing ("not finite: NaN").
    pub fn new(name: &str, value: f64, unit: &str, better: Better) -> Metric {
        if value.is_finite() {
            Metric { value: Some(value), ..Metric::empty(name, unit, better) }
        } else {
            Metric::missing(name, unit, better, format!("not finite: {value}"))
        }
    }

    /// A quantity that could not be measured, with the reason.
    pub fn missing(name: &str, unit: &str, better: Better, why: impl Into<String>) -> Metric {
        Metric { missing: Some(why.into()), ..Metric::empty(name, unit, better) }
    }

    /// A quantity left unmeasured on purpose, with the reason (shown as skipped).
    pub fn skipped(name: &str, unit: &str, better: Better, why: impl Into<String>) -> Metric {
        Metric { skipped: Some(why.into()), ..Metric::empty(name, unit, better) }
    }

    /// A quantity that has no meaning for this case, with the reason (shown as n/a).
    pub fn not_applicable(name: &str, unit: &str, better: Better, why: impl Into<String>) -> Metric {
        Metric { not_applicable: Some(why.into()), ..Metric::empty(name, unit, better) }
    }

    /// Why the metric gets no verdict on purpose: skipped or not applicable.
    pub fn unjudged(&self) -> Option<&str> {
        self.skipped.as_deref().or(self.not_applicable.as_deref())
    }

    /// No value, bound or verdict yet.
    fn empty(name: &str, unit: &str, better: Better) -> Metric {
        Metric {
            name: name.into(),
            value: None,
            unit: unit.into(),
            better,
            bound: None,
            pass: None,
            missing: None,
            skipped: None,
            not_applicable: None,
            expected_miss: None,
        }
    }

    /// A value of `Some(v)` as measured, `None` as missing for `why`.
    pub fn maybe(name: &str, value: Option<f64>, unit: &str, better: Better, why: &str) -> Metric {
        match value {
            Some(v) => Metric::new(name, v, unit, better),
            None => Metric::missing(name, unit, better, why),
        }
    }

    /// Whether the value meets `bound`; a missing value meets none.
    pub fn meets(&self, bound: Bound) -> bool {
        self.value.is_some_and(|v| bound.min.is_none_or(|lo| v >= lo) && bound.max.is_none_or(|hi| v <= hi))
    }

    /// A metric that missed its bound without a declared expected miss.
    pub fn failed(&self) -> bool {
        self.pass == Some(false) && self.expected_miss.is_none()
    }
}

/// An accepted range of a metric's value; either end may be open.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Bound {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
}

impl Bound {
    /// `≤ b`, `≥ a`, or `a to b`, as the report shows it.
    pub fn text(&self) -> String {
        match (self.min, self.max) {
            (Some(a), Some(b)) => format!("{} to {}", fmt_value(a), fmt_value(b)),
            (Some(a), None) => format!("≥ {}", fmt_value(a)),
            (None, Some(b)) => format!("≤ {}", fmt_value(b)),
            (None, None) => "—".into(),
        }
    }
}

/// A bound as a pipeline file writes it: a number (its end set by the metric's direction) or
/// a table `{ min = a, max = b }`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BoundSpec {
    Plain(f64),
    Range(Bound),
}

impl BoundSpec {
    /// The range this bound is for a metric whose better direction is `better`.
    pub fn resolve(self, better: Better) -> Bound {
        match (self, better) {
            (BoundSpec::Plain(b), Better::Lower) => Bound { min: None, max: Some(b) },
            (BoundSpec::Plain(b), Better::Higher) => Bound { min: Some(b), max: None },
            (BoundSpec::Range(r), _) => r,
        }
    }

    /// Refuses a non-finite end, an empty table, or min above max.
    pub fn check(&self) -> Result<(), Invalid> {
        let ends = match self {
            BoundSpec::Plain(b) => vec![("", *b)],
            BoundSpec::Range(r) => {
                let ends: Vec<(&str, f64)> = [(".min", r.min), (".max", r.max)]
                    .into_iter()
                    .filter_map(|(k, v)| v.map(|v| (k, v)))
                    .collect();
                if ends.is_empty() {
                    return Err(" = {}: expected a number, or `min`, `max` or both".into());
                }
                ends
            }
        };
        for (key, v) in &ends {
            if !v.is_finite() {
                return Err(format!("{key} = {v}: expected a finite number").into());
            }
        }
        if let BoundSpec::Range(Bound { min: Some(a), max: Some(b) }) = self {
            if a > b {
                return Err(
                    format!(" = {{ min = {a}, max = {b} }}: min is above max, so no value meets it").into()
                );
            }
        }
        Ok(())
    }
}

impl<'de> Deserialize<'de> for BoundSpec {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Plain(f64),
            Range(RangeRaw),
        }
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct RangeRaw {
            min: Option<f64>,
            max: Option<f64>,
        }
        // Untagged enums lose the inner message; say what is accepted instead.
        match Raw::deserialize(d) {
            Ok(Raw::Plain(b)) => Ok(BoundSpec::Plain(b)),
            Ok(Raw::Range(r)) => Ok(BoundSpec::Range(Bound { min: r.min, max: r.max })),
            Err(_) => Err(serde::de::Error::custom(
                "expected a number, or a table with `min`, `max` or both (numbers), e.g. { max = 0 }",
            )),
        }
    }
}

/// Numbers as a person reads them: 4 significant digits, scientific when tiny or huge.
pub fn fmt_value(v: f64) -> String {
    if v == 0.0 || (1e-3..1e6).contains(&v.abs()) {
        let s = format!("{v:.6}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        s.to_string()
    } else {
        format!("{v:.3e}")
    }
}
