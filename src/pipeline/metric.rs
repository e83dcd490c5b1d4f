//! A stage's measured quantities, each with the direction that is better, its bound and its
//! verdict. A value that could not be measured is `None` with the reason, never a sentinel
//! such as NaN or infinity: a missing or non-finite value misses any bound it has.

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
    pub bound: Option<f64>,
    pub pass: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub missing: Option<String>,
    /// Not measured on purpose (its data are absent, e.g. `../shared`): no verdict, no miss.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skipped: Option<String>,
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
    pub fn meets(&self, bound: f64) -> bool {
        match (self.value, self.better) {
            (Some(v), Better::Lower) => v <= bound,
            (Some(v), Better::Higher) => v >= bound,
            (None, _) => false,
        }
    }

    /// A metric that missed its bound without a declared expected miss.
    pub fn failed(&self) -> bool {
        self.pass == Some(false) && self.expected_miss.is_none()
    }
}
