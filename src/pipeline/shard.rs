//! One pipeline over several processes or nodes: `lumen run --shard K/N` runs every N-th case
//! (case i goes to shard i mod N + 1, so the split depends only on the file and N; a chained
//! case goes with the first case of its chain, `PipelineFile::root`, and runs after it) and writes a
//! fragment, a report of its cases, to `OUT/shards/K-of-N/`; `lumen merge OUT` checks that the
//! fragments belong together and cover every case once, and writes the one report to `OUT`.
//! Shards share the render cache, whose entries are written under a private name and renamed.

use super::report::Report;
use super::Error;
use crate::error::Invalid;
use std::path::{Path, PathBuf};

/// Shard `k` of `n`, counted from 1.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub k: usize,
    pub n: usize,
}

/// Most shards a pipeline may be split into (Slurm's own default array limit is 1001 tasks).
pub const MAX_SHARDS: usize = 1000;

impl Shard {
    /// `K/N` with 1 ≤ K ≤ N ≤ `MAX_SHARDS`.
    pub fn parse(s: &str) -> Result<Shard, Invalid> {
        let expected = format!("expected K/N with 1 <= K <= N <= {MAX_SHARDS}, e.g. 2/3");
        let (k, n) = s.split_once('/').ok_or_else(|| expected.clone())?;
        match (k.trim().parse::<usize>(), n.trim().parse::<usize>()) {
            (Ok(k), Ok(n)) if 1 <= k && k <= n && n <= MAX_SHARDS => Ok(Shard { k, n }),
            _ => Err(expected.into()),
        }
    }

    /// Whether the pipeline's case `index` (0-based, in file order) is this shard's.
    pub fn takes(&self, index: usize) -> bool {
        index % self.n == self.k - 1
    }

    /// The folder of this shard's fragment.
    pub fn dir(&self, out: &Path) -> PathBuf {
        out.join("shards").join(format!("{}-of-{}", self.k, self.n))
    }
}

pub use super::report::Fragment;

/// The digest a fragment records for the pipeline file at `path`.
pub fn digest(path: &Path) -> Result<String, Error> {
    // Read when a shard's report is made, not merged: a failure is the pipeline file's.
    let bytes = std::fs::read(path)
        .map_err(|e| super::file::Error::Io { path: path.into(), message: e.to_string() })?;
    Ok(format!("{:032x}", super::cache::fnv128(&bytes)))
}

/// Reads the fragments in `out/shards`, checks them and joins them into one report, with the
/// kept files of every fragment. The report's time is the longest shard's; its warnings are
/// every fragment's.
pub fn merge(out: &Path) -> Result<Report, Error> {
    let shards = out.join("shards");
    let err = |path: &Path, message: String| Error::Merge { path: path.into(), message };
    let entries = std::fs::read_dir(&shards).map_err(|e| {
        err(
            &shards,
            format!(
                "{e}: expected the fragments `lumen run PIPELINE --shard K/N --out {}` writes",
                out.display()
            ),
        )
    })?;
    let mut found: Vec<(Shard, PathBuf)> = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| err(&shards, e.to_string()))?.path();
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("").to_string();
        if name.starts_with('.') {
            continue; // a fragment being written
        }
        let shard = name
            .split_once("-of-")
            .and_then(|(k, n)| Shard::parse(&format!("{k}/{n}")).ok())
            .ok_or_else(|| err(&path, "expected only folders named K-of-N in shards/".into()))?;
        found.push((shard, path));
    }
    found.sort_by_key(|(s, _)| (s.n, s.k));
    let n = found.first().map(|(s, _)| s.n).ok_or_else(|| err(&shards, "holds no fragment".into()))?;
    if let Some((other, path)) = found.iter().find(|(s, _)| s.n != n) {
        return Err(err(
            path,
            format!(
                "a fragment of {} shards beside fragments of {n}: remove the fragments of the other split",
                other.n
            ),
        ));
    }
    let missing: Vec<String> =
        (1..=n).filter(|k| !found.iter().any(|(s, _)| s.k == *k)).map(|k| format!("{k}-of-{n}")).collect();
    if !missing.is_empty() {
        return Err(err(
            &shards,
            format!(
                "missing fragment(s) {}: run `lumen run PIPELINE --shard K/{n}` for each",
                missing.join(", ")
            ),
        ));
    }
    let mut parts = Vec::new();
    for (shard, dir) in &found {
        let path = dir.join("report.json");
        let text = std::fs::read_to_string(&path).map_err(|e| err(&path, e.to_string()))?;
        let report: Report =
            serde_json::from_str(&text).map_err(|e| err(&path, format!("not a fragment: {e}")))?;
        let f =
            report.fragment.clone().ok_or_else(|| err(&path, "is a whole report, not a fragment".into()))?;
        if (f.shard, f.shards) != (shard.k, shard.n) || f.indices.len() != report.stages.len() {
            return Err(err(
                &path,
                format!("holds shard {}/{} but sits in {}-of-{}", f.shard, f.shards, shard.k, shard.n),
            ));
        }
        parts.push((dir.clone(), path, report, f));
    }
    let (_, first_path, first, first_f) = &parts[0];
    for (_, path, r, f) in &parts[1..] {
        let mismatch = [
            ("pipeline", r.pipeline != first.pipeline),
            ("pipeline file (its digest)", f.pipeline_digest != first_f.pipeline_digest),
            ("seed", r.seed != first.seed),
            ("lumen version", r.lumen_version != first.lumen_version),
            ("git commit", r.git_commit != first.git_commit),
            ("number of cases", f.cases != first_f.cases),
        ];
        if let Some((what, _)) = mismatch.iter().find(|(_, differs)| *differs) {
            return Err(err(
                path,
                format!("its {what} differs from {}'s: rerun every shard", first_path.display()),
            ));
        }
    }
    // Every case sits in exactly one fragment, so the fragments' stages count the cases: a
    // count claimed beyond them is refused before anything is allocated for it.
    let held: usize = parts.iter().map(|(_, _, r, _)| r.stages.len()).sum();
    if first_f.cases != held {
        return Err(err(
            first_path,
            format!(
                "claims {} cases in the pipeline, but the {n} fragments hold {held}: rerun every shard",
                first_f.cases
            ),
        ));
    }
    for (_, path, _, f) in &parts {
        if let Some(bad) = f.kept.iter().find(|k| !inside(k)) {
            return Err(err(
                path,
                format!(
                    "kept file `{}` is not a relative path inside the fragment's folder: refused, so that nothing is read or written outside {}",
                    bad.display(),
                    out.display()
                ),
            ));
        }
    }
    let mut slots: Vec<Option<super::report::StageReport>> = vec![None; first_f.cases];
    let (mut files, mut warnings) = (Vec::new(), Vec::new());
    let mut total_s: f64 = 0.0;
    for (dir, path, r, f) in &parts {
        for (&i, st) in f.indices.iter().zip(&r.stages) {
            let slot =
                slots.get_mut(i).ok_or_else(|| err(path, format!("case index {i} beyond the pipeline")))?;
            if slot.is_some() {
                return Err(err(path, format!("case {} is in two fragments", st.case)));
            }
            *slot = Some(st.clone());
        }
        for name in &f.kept {
            let source = dir.join(name);
            let bytes = std::fs::read(&source).map_err(|e| err(&source, e.to_string()))?;
            files.push((name.clone(), super::stages::Kept::Bytes(bytes)));
        }
        warnings.extend(r.warnings.iter().map(|w| format!("shard {}/{}: {w}", f.shard, f.shards)));
        total_s = total_s.max(r.total_s);
    }
    let stages = slots
        .into_iter()
        .enumerate()
        .map(|(i, s)| s.ok_or_else(|| err(&shards, format!("no fragment holds case {i} (0-based)"))))
        .collect::<Result<Vec<_>, _>>()?;
    let mut report = Report::new(first.pipeline.clone(), first.seed, stages, total_s);
    report.lumen_version = first.lumen_version.clone();
    report.git_commit = first.git_commit.clone();
    report.started = parts.iter().map(|(_, _, r, _)| r.started.clone()).min().unwrap_or_default();
    report.machine = first.machine.clone();
    report.threads = first.threads;
    report.warnings = warnings;
    report.files = files;
    Ok(report)
}

/// Whether `p` is a non-empty relative path made only of names (no `..`, root or prefix).
fn inside(p: &Path) -> bool {
    p.components().next().is_some() && p.components().all(|c| matches!(c, std::path::Component::Normal(_)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_and_split() {
        assert_eq!(Shard::parse("2/3"), Ok(Shard { k: 2, n: 3 }));
        for bad in ["0/3", "4/3", "3", "a/b", "1/0", "1/1001", ""] {
            assert!(Shard::parse(bad).is_err(), "{bad}");
        }
        // Every case goes to exactly one shard.
        let shards: Vec<Shard> = (1..=3).map(|k| Shard { k, n: 3 }).collect();
        for i in 0..10 {
            assert_eq!(shards.iter().filter(|s| s.takes(i)).count(), 1);
        }
    }
}
