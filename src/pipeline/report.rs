//! The run report: `report.json` (machine-readable) and `report.md` (tables for a person).
//! The report is the only place that sees estimates and truth side by side.

use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

#[derive(Clone, Copy, Debug, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Better {
    Lower,
    Higher,
}

#[derive(Clone, Debug, Serialize)]
pub struct Metric {
    pub name: String,
    pub value: f64,
    pub unit: String,
    /// Whether the bound is an upper (`lower` is better) or a lower bound.
    pub better: Better,
    pub bound: Option<f64>,
    pub pass: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub expected_miss: Option<String>,
}

impl Metric {
    pub fn new(name: &str, value: f64, unit: &str, better: Better) -> Metric {
        Metric {
            name: name.into(),
            value,
            unit: unit.into(),
            better,
            bound: None,
            pass: None,
            expected_miss: None,
        }
    }

    pub fn meets(&self, bound: f64) -> bool {
        match self.better {
            Better::Lower => self.value <= bound,
            Better::Higher => self.value >= bound,
        }
    }

    /// A metric that missed its bound without a declared expected miss.
    pub fn failed(&self) -> bool {
        self.pass == Some(false) && self.expected_miss.is_none()
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct StageReport {
    pub stage: String,
    pub case: String,
    /// `alone` (upstream quantities from truth) or `chained` (from the previous stage).
    pub mode: String,
    pub seed: u64,
    pub metrics: Vec<Metric>,
    pub timings_s: BTreeMap<String, f64>,
    pub notes: Vec<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub pipeline: String,
    pub seed: u64,
    pub lumen_version: String,
    pub threads: usize,
    pub stages: Vec<StageReport>,
    /// Every metric met its bound or has a declared expected miss.
    pub passed: bool,
}

impl Report {
    pub fn new(pipeline: String, seed: u64, stages: Vec<StageReport>) -> Report {
        let passed = !stages.iter().flat_map(|s| &s.metrics).any(Metric::failed);
        Report {
            pipeline,
            seed,
            lumen_version: env!("CARGO_PKG_VERSION").into(),
            threads: rayon::current_num_threads(),
            stages,
            passed,
        }
    }

    /// `stage/case/metric` of every metric that failed.
    pub fn failures(&self) -> Vec<String> {
        let mut v = Vec::new();
        for s in &self.stages {
            for m in s.metrics.iter().filter(|m| m.failed()) {
                let (op, b) = match m.better {
                    Better::Lower => ("≤", m.bound.unwrap_or(f64::NAN)),
                    Better::Higher => ("≥", m.bound.unwrap_or(f64::NAN)),
                };
                v.push(format!(
                    "{}/{}/{} = {} {}, bound {op} {b}",
                    s.stage,
                    s.case,
                    m.name,
                    fmt_value(m.value),
                    m.unit
                ));
            }
        }
        v
    }

    pub fn to_markdown(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "# lumen report: {}\n", self.pipeline);
        let _ = writeln!(
            s,
            "seed {}, lumen {}, {} threads. Result: **{}**\n",
            self.seed,
            self.lumen_version,
            self.threads,
            if self.passed {
                "all metrics met their bounds or declared misses"
            } else {
                "a metric missed its bound"
            }
        );
        let _ = writeln!(s, "| stage | case | mode | time (s) | metrics met |\n|---|---|---|---:|---|");
        for st in &self.stages {
            let bounded = st.metrics.iter().filter(|m| m.bound.is_some()).count();
            let met = st.metrics.iter().filter(|m| m.pass == Some(true)).count();
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.2} | {met}/{bounded} |",
                st.stage,
                st.case,
                st.mode,
                st.timings_s.get("total").copied().unwrap_or(0.0)
            );
        }
        for st in &self.stages {
            let _ = writeln!(s, "\n## {} — {}\n", st.stage, st.case);
            let _ = writeln!(s, "| metric | value | unit | bound | verdict |\n|---|---:|---|---:|---|");
            for m in &st.metrics {
                let bound = match (m.bound, m.better) {
                    (Some(b), Better::Lower) => format!("≤ {}", fmt_value(b)),
                    (Some(b), Better::Higher) => format!("≥ {}", fmt_value(b)),
                    (None, _) => "—".into(),
                };
                let verdict = match (m.pass, &m.expected_miss) {
                    (Some(true), _) => "pass".to_string(),
                    (Some(false), Some(why)) => format!("expected miss: {why}"),
                    (Some(false), None) => "**MISS**".to_string(),
                    (None, _) => "—".to_string(),
                };
                let _ =
                    writeln!(s, "| {} | {} | {} | {bound} | {verdict} |", m.name, fmt_value(m.value), m.unit);
            }
            let times: Vec<String> = st.timings_s.iter().map(|(k, v)| format!("{k} {v:.3} s")).collect();
            let _ = writeln!(s, "\nTimings: {}.", times.join(", "));
            for n in &st.notes {
                let _ = writeln!(s, "\n- {n}");
            }
        }
        s
    }

    /// Writes `report.json` and `report.md` into `dir`, each atomically.
    pub fn write(&self, dir: &Path) -> Result<(), super::Error> {
        let json = serde_json::to_string_pretty(self)
            .map_err(|e| super::Error::Write { path: dir.join("report.json"), message: e.to_string() })?;
        for (name, text) in [("report.json", json), ("report.md", self.to_markdown())] {
            let path = dir.join(name);
            crate::image::io::write_atomically(&path, |tmp| {
                std::fs::write(tmp, &text).map_err(|e| e.to_string())
            })
            .map_err(|e| super::Error::Write { path: path.clone(), message: e.to_string() })?;
        }
        Ok(())
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
