//! Pipeline files. An entry of `[[stages]]` is parsed in two passes, both refusing unknown
//! keys: first the fields every entry has (`Common`), then the rest as the stage's own
//! `Config`. (serde's `flatten` would do it in one pass but silently switches off
//! `deny_unknown_fields`.) A `sweep` expands one entry into several cases.
//!
//! ```toml
//! name = "all"            # optional; default: the file's stem
//! seed = 1                # seed of every case that does not set its own
//! [[stages]]
//! stage = "calibrate"     # which stage
//! case = "barrel-noisy"   # the case's name in the report (unique in the file)
//! seed = 2                # optional
//! scene = "scenes/calib-board.toml"   # the stage's own fields; paths relative to this file
//! views = 64
//! bounds = { fx_rel_err = 0.001, views_missed = { max = 0 }, points = { min = 100, max = 900 } }
//!                         # metric → bound: a number is the end the metric's direction makes it
//!                         # (upper on an error, lower on a count found); a table says its ends
//! expected_miss = { some_metric = "why it is not met yet" }   # fails the run once it is met
//! sweep = { views = [8, 16, 32, 64] } # one case per value, named "barrel-noisy[views=8]" …
//! plot = "fx_rel_err"     # the error a sweep's plot shows (default: the stage's headline)
//! expect_error = "numerical"          # the case must fail with this kind of error
//! ```

use super::metric::BoundSpec;
use super::stages::{from_table, parse_stage, Stage};
use crate::error::{Fault, Invalid};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("cannot read pipeline {path}: {message}")]
    Io { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    Parse { path: PathBuf, message: String },
}

impl Error {
    pub fn fault(&self) -> Fault {
        match self {
            Error::Io { .. } => Fault::Io,
            Error::Parse { .. } => Fault::BadInput,
        }
    }
}

/// What every entry has besides its stage's settings.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Common {
    pub case: String,
    /// Seed (default: the pipeline's).
    pub seed: Option<u64>,
    /// Bound per metric name: a number (an upper or lower bound, as the metric's direction
    /// makes it) or `{ min = a, max = b }`.
    #[serde(default)]
    pub bounds: BTreeMap<String, BoundSpec>,
    /// Metric name → why its bound is not met yet. Shown in the report; a miss does not fail
    /// the run, the bound met does (the declaration is then out of date).
    #[serde(default)]
    pub expected_miss: BTreeMap<String, String>,
    /// Stage field → values: one case per value (per combination, with several fields).
    #[serde(default)]
    pub sweep: BTreeMap<String, Vec<toml::Value>>,
    /// The metric a sweep's error-against-time plot shows.
    pub plot: Option<String>,
    /// The kind of error the case must end with (`bad-input`, `numerical` or `io`): a stiff
    /// case whose right outcome is a clear refusal.
    pub expect_error: Option<String>,
}

/// One case to run: an entry, or one point of an entry's sweep.
#[derive(Debug)]
pub struct Case {
    pub common: Common,
    pub stage: Stage,
    /// The entry's position in the file (1-based) and its line.
    pub entry: usize,
    pub line: usize,
    /// The entry's own case name: the group a sweep's cases are plotted in.
    pub group: String,
    /// The swept fields' values of this case (empty outside a sweep).
    pub sweep: BTreeMap<String, String>,
    /// The earlier cases this one takes an output from (`from:CASE`), by index.
    pub upstream: Vec<usize>,
}

#[derive(Debug)]
pub struct PipelineFile {
    pub name: Option<String>,
    pub seed: u64,
    pub cases: Vec<Case>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    name: Option<String>,
    #[serde(default = "default_seed")]
    seed: u64,
    stages: Vec<toml::Spanned<toml::Table>>,
}

fn default_seed() -> u64 {
    1
}

const COMMON_KEYS: [&str; 8] =
    ["stage", "case", "seed", "bounds", "expected_miss", "sweep", "plot", "expect_error"];

/// Largest number of cases one entry's sweep may expand into.
pub const MAX_SWEEP_CASES: usize = 256;

pub fn load(path: &Path) -> Result<PipelineFile, Error> {
    let text =
        std::fs::read_to_string(path).map_err(|e| Error::Io { path: path.into(), message: e.to_string() })?;
    parse(&text, path)
}

pub fn parse(text: &str, path: &Path) -> Result<PipelineFile, Error> {
    let raw: RawFile =
        toml::from_str(text).map_err(|e| Error::Parse { path: path.into(), message: e.to_string() })?;
    if raw.stages.is_empty() {
        return Err(Error::Parse { path: path.into(), message: "`stages` is empty: nothing to run".into() });
    }
    let mut cases: Vec<Case> = Vec::new();
    for (i, spanned) in raw.stages.iter().enumerate() {
        let line = text[..spanned.span().start.min(text.len())].lines().count().max(1);
        let err = |message: String| Error::Parse {
            path: path.into(),
            message: format!("stages[{i}] (line {line}): {message}"),
        };
        let table = spanned.get_ref();
        let (mut common_t, mut own) = (toml::Table::new(), toml::Table::new());
        for (k, v) in table {
            if COMMON_KEYS.contains(&k.as_str()) {
                common_t.insert(k.clone(), v.clone());
            } else {
                own.insert(k.clone(), v.clone());
            }
        }
        let stage_name = match common_t.remove("stage") {
            Some(toml::Value::String(s)) => s,
            Some(other) => return Err(err(format!("`stage` = {other}: expected a stage name"))),
            None => {
                return Err(err("missing `stage` (render, calibrate, photometric, color, hdr or sfm)".into()))
            }
        };
        let common: Common = from_table(common_t).map_err(|e| err(e.0))?;
        let err = |message: String| Error::Parse {
            path: path.into(),
            message: format!("stages[{i}] (line {line}, case {}): {message}", common.case),
        };
        check_common(&common).map_err(|e| err(e.0))?;
        for (key, values) in &common.sweep {
            if COMMON_KEYS.contains(&key.as_str()) {
                return Err(err(format!("sweep.{key}: only a stage's own fields can be swept")));
            }
            if values.is_empty() {
                return Err(err(format!("sweep.{key} is empty: give at least one value")));
            }
        }
        let count = common.sweep.values().try_fold(1usize, |n, v| n.checked_mul(v.len()));
        if count.is_none_or(|n| n > MAX_SWEEP_CASES) {
            return Err(err(format!("the sweep expands into more than {MAX_SWEEP_CASES} cases")));
        }
        for point in sweep_points(&common.sweep) {
            let mut t = own.clone();
            let mut shown = BTreeMap::new();
            for (k, v) in &point {
                t.insert(k.clone(), v.clone());
                shown.insert(k.clone(), v.to_string());
            }
            let stage = parse_stage(&stage_name, t).map_err(|e| err(e.0))?;
            let mut c = Common {
                case: common.case.clone(),
                seed: common.seed,
                bounds: common.bounds.clone(),
                expected_miss: common.expected_miss.clone(),
                sweep: BTreeMap::new(),
                plot: common.plot.clone(),
                expect_error: common.expect_error.clone(),
            };
            if !shown.is_empty() {
                let label: Vec<String> = shown.iter().map(|(k, v)| format!("{k}={v}")).collect();
                c.case = format!("{}[{}]", common.case, label.join(","));
            }
            if cases.iter().any(|x| x.common.case == c.case) {
                return Err(err(format!("case `{}` is named twice: case names must be unique", c.case)));
            }
            cases.push(Case {
                common: c,
                stage,
                entry: i + 1,
                line,
                group: common.case.clone(),
                sweep: shown,
                upstream: Vec::new(),
            });
        }
    }
    resolve_upstream(&mut cases, path)?;
    Ok(PipelineFile { name: raw.name, seed: raw.seed, cases })
}

impl PipelineFile {
    /// The first case of the chain case `i` belongs to (`from:` followed back), so that a
    /// shard runs a chained case after its source, in the same process.
    pub fn root(&self, mut i: usize) -> usize {
        while let Some(&j) = self.cases[i].upstream.first() {
            i = j;
        }
        i
    }
}

/// Finds the case each `from:CASE` names: it must exist, come earlier in the file (so there is
/// no cycle), and hand on the kind of output the field takes.
fn resolve_upstream(cases: &mut [Case], path: &Path) -> Result<(), Error> {
    for i in 0..cases.len() {
        let mut found = Vec::new();
        for (field, name, kind) in cases[i].stage.upstream() {
            let c = &cases[i];
            // A radiance is named as CASE/radiance, a camera or a response by its case alone.
            let reference = if kind == "radiance" { format!("{name}/radiance") } else { name.clone() };
            let err = |message: String| Error::Parse {
                path: path.into(),
                message: format!(
                    "stages[{}] (line {}, case {}): `{field}` = \"from:{reference}\": {message}",
                    c.entry - 1,
                    c.line,
                    c.common.case
                ),
            };
            let Some(j) = cases.iter().position(|x| x.common.case == name) else {
                return Err(err(format!("no case `{name}` in this file")));
            };
            if j >= i {
                return Err(err(format!(
                    "case `{name}` is {}: a case takes only from an earlier one",
                    if j == i { "this case" } else { "a later one" }
                )));
            }
            if !cases[j].stage.provides().contains(&kind) {
                return Err(err(format!(
                    "case `{name}` is a {} case, which hands on no {kind}{}",
                    cases[j].stage.name(),
                    match kind {
                        "camera" => " (a calibrate case on renders does)",
                        "radiance" => " (an hdr case on renders does)",
                        _ => "",
                    }
                )));
            }
            found.push(j);
        }
        cases[i].upstream = found;
    }
    Ok(())
}

fn check_common(c: &Common) -> Result<(), Invalid> {
    if c.case.trim().is_empty() {
        return Err("`case` is empty: give the case a name".into());
    }
    for (name, b) in &c.bounds {
        b.check().map_err(|e| format!("bounds.{name}{e}"))?;
    }
    for name in c.expected_miss.keys() {
        if !c.bounds.contains_key(name) {
            return Err(
                format!("expected_miss.{name}: `{name}` has no bound, so there is nothing to miss").into()
            );
        }
    }
    if let Some(k) = &c.expect_error {
        if k.parse::<Fault>().is_err() {
            let names: Vec<&str> = Fault::ALL.iter().map(|f| f.name()).collect();
            return Err(format!("expect_error = \"{k}\": expected one of {}", names.join(", ")).into());
        }
    }
    Ok(())
}

/// Every combination of the swept values (one empty point without a sweep).
fn sweep_points(sweep: &BTreeMap<String, Vec<toml::Value>>) -> Vec<Vec<(String, toml::Value)>> {
    let mut points = vec![Vec::new()];
    for (k, values) in sweep {
        points = points
            .into_iter()
            .flat_map(|p| {
                values.iter().map(move |v| {
                    let mut q = p.clone();
                    q.push((k.clone(), v.clone()));
                    q
                })
            })
            .collect();
    }
    points
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_str(s: &str) -> Result<PipelineFile, Error> {
        parse(s, Path::new("p.toml"))
    }

    const ENTRY: &str = "[[stages]]\nstage = \"render\"\ncase = \"f\"\nscene = \"s.toml\"\n";

    #[test]
    fn two_passes_refuse_unknown_keys_in_either() {
        let f = parse_str(ENTRY).unwrap();
        assert_eq!(f.cases.len(), 1);
        let e = parse_str(&format!("{ENTRY}spp_typo = 3\n")).unwrap_err().to_string();
        assert!(e.contains("spp_typo") && e.contains("line 1") && e.contains("case f"), "{e}");
        let e = parse_str(&format!("{ENTRY}bounds = {{ x = nan }}\n")).unwrap_err().to_string();
        assert!(e.contains("bounds.x = NaN"), "{e}");
        let e = parse_str("[[stages]]\nstage = \"teleport\"\ncase = \"x\"\n").unwrap_err().to_string();
        assert!(e.contains("unknown stage `teleport`"), "{e}");
        let e = parse_str(&format!("{ENTRY}{ENTRY}")).unwrap_err().to_string();
        assert!(e.contains("named twice"), "{e}");
        let photos = "[[stages]]\nstage = \"sfm\"\ncase = \"p\"\nimages = \"d\"\ncamera = \"k.txt\"\nscene = \"s.toml\"\n";
        let e = parse_str(photos).unwrap_err().to_string();
        assert!(e.contains("`images` and `scene` are both given"), "{e}");
    }

    #[test]
    fn from_names_an_earlier_case_that_hands_on_its_kind() {
        let cal = "[[stages]]\nstage = \"calibrate\"\ncase = \"cal\"\nscene = \"b.toml\"\n";
        let sfm = |from: &str| {
            format!("[[stages]]\nstage = \"sfm\"\ncase = \"s\"\nscene = \"c.toml\"\ntarget = [0.0, 0.0, 0.0]\nradius = 1.0\nheight = 1.0\narc_deg = 40\ncamera = \"from:{from}\"\n")
        };
        let f = parse_str(&format!("{ENTRY}{cal}{}", sfm("cal"))).unwrap();
        assert_eq!(f.cases[2].upstream, vec![1]);
        assert_eq!((f.root(2), f.root(1), f.root(0)), (1, 1, 0));
        let e = parse_str(&format!("{cal}{}", sfm("nope"))).unwrap_err().to_string();
        assert!(e.contains("`camera` = \"from:nope\": no case `nope`") && e.contains("case s"), "{e}");
        let e = parse_str(&format!("{}{cal}", sfm("cal"))).unwrap_err().to_string();
        assert!(e.contains("case `cal` is a later one"), "{e}");
        let e = parse_str(&sfm("s")).unwrap_err().to_string();
        assert!(e.contains("case `s` is this case"), "{e}");
        let e = parse_str(&format!("{ENTRY}{}", sfm("f"))).unwrap_err().to_string();
        assert!(e.contains("case `f` is a render case, which hands on no camera"), "{e}");
        // A radiance is named as CASE/radiance, and only an hdr case on renders hands one on.
        let color = |from: &str| {
            format!(
                "[[stages]]\nstage = \"color\"\ncase = \"k\"\nscene = \"d.toml\"\nimage = \"from:{from}\"\n"
            )
        };
        let hdr = "[[stages]]\nstage = \"hdr\"\ncase = \"h\"\nscene = \"d.toml\"\n";
        let f = parse_str(&format!("{hdr}{}", color("h/radiance"))).unwrap();
        assert_eq!(f.cases[1].upstream, vec![0]);
        let f = parse_str(&format!("{hdr}{}", color("h").replace("image", "response"))).unwrap();
        assert_eq!(f.cases[1].upstream, vec![0]);
        let e = parse_str(&format!("{cal}{}", color("cal").replace("image", "response")))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(
                "`response` = \"from:cal\": case `cal` is a calibrate case, which hands on no response"
            ),
            "{e}"
        );
        let e = parse_str(&format!("{cal}{}", color("cal/radiance"))).unwrap_err().to_string();
        assert!(
            e.contains("`image` = \"from:cal/radiance\": case `cal` is a calibrate case, which hands on no radiance (an hdr case on renders does)"),
            "{e}"
        );
    }

    #[test]
    fn sweeps_expand_into_named_cases() {
        let f = parse_str(&format!("{ENTRY}sweep = {{ spp = [4, 16], max_depth = [2, 3, 4] }}\n")).unwrap();
        assert_eq!(f.cases.len(), 6);
        assert_eq!(f.cases[0].common.case, "f[max_depth=2,spp=4]");
        assert!(f.cases.iter().all(|c| c.group == "f"));
        let last = format!("{:?}", f.cases[5].stage);
        assert_eq!(f.cases[5].stage.name(), "render");
        assert!(last.contains("spp: Some(16)") && last.contains("max_depth: Some(4)"), "{last}");
        let e = parse_str(&format!("{ENTRY}sweep = {{ spp = [\"many\"] }}\n")).unwrap_err().to_string();
        assert!(e.contains("`spp`: invalid type: string \"many\""), "{e}");
        let e = parse_str(&format!("{ENTRY}sweep = {{ seed = [1, 2] }}\n")).unwrap_err().to_string();
        assert!(e.contains("only a stage's own fields"), "{e}");
    }
}
