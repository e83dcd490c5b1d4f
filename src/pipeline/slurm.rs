//! `lumen slurm`: the four plain `sbatch` scripts that run a pipeline on a Slurm cluster:
//! - `render.sbatch`, a job array with one task per shard, each making its share of every
//!   case's renders in the shared cache (`lumen run --shard K/N --renders-only`), so the views
//!   or lights of one large case are spread over all tasks (with the features of the
//!   structure-from-motion views each task renders);
//! - `match.sbatch`, a second array after it, each task matching and verifying its share of
//!   the structure-from-motion cases' blocks of image pairs (`--matches-only`), which need
//!   every view's features;
//! - `run.sbatch`, a third array after that, each task running its shard's cases from the
//!   full cache (`lumen run --shard K/N`);
//! - `merge.sbatch`, the merge job after that (`lumen merge OUT`).
//!
//! lumen never talks to Slurm except through `sbatch`; users read and adapt the scripts.

use crate::error::Invalid;
use std::path::{Path, PathBuf};

/// What the scripts run and ask Slurm for. Paths are absolute: the jobs start on other nodes,
/// in whatever folder Slurm gives them.
#[derive(Clone, Debug)]
pub struct Job {
    /// The lumen binary the tasks run.
    pub lumen: PathBuf,
    pub pipeline: PathBuf,
    pub out: PathBuf,
    /// The render cache every shard shares.
    pub cache: PathBuf,
    pub name: String,
    pub shards: usize,
    pub cpus_per_task: usize,
    /// `--time`, as Slurm reads it (e.g. `1:00:00`), when given.
    pub time: Option<String>,
    pub partition: Option<String>,
}

/// Refuses a value that would break a script line (`--partition`, `--time`): it must be a
/// plain word of letters, digits and `-_:.,+`.
pub fn check_word(flag: &str, value: &str) -> Result<(), Invalid> {
    let plain = |c: char| c.is_ascii_alphanumeric() || "-_:.,+".contains(c);
    if value.is_empty() || !value.chars().all(plain) {
        return Err(format!("{flag} {value:?}: expected letters, digits and -_:.,+ only").into());
    }
    Ok(())
}

/// A path for a shell line, in single quotes.
fn quoted(p: &Path) -> String {
    format!("'{}'", p.display().to_string().replace('\'', r"'\''"))
}

fn header(job: &Job, what: &str, log: &str) -> String {
    let mut s = format!(
        "#!/bin/bash\n# {what}\n#SBATCH --job-name=lumen-{}\n#SBATCH --cpus-per-task={}\n#SBATCH --output={}\n",
        job.name,
        job.cpus_per_task,
        job.out.join("slurm").join(log).display()
    );
    if let Some(t) = &job.time {
        s += &format!("#SBATCH --time={t}\n");
    }
    if let Some(p) = &job.partition {
        s += &format!("#SBATCH --partition={p}\n");
    }
    s
}

/// An array's script: its header, then task i's `lumen run` of shard i + 1 with `flags`
/// (`--out …` or `--renders-only`), the shared cache and the task's CPUs as threads.
fn array(job: &Job, what: &str, log: &str, flags: &str) -> String {
    let mut s = header(job, what, log);
    s += &format!("#SBATCH --array=0-{}\n", job.shards - 1);
    s += &format!(
        "set -u\nshard=$((SLURM_ARRAY_TASK_ID + 1))/{n}\n{lumen} run {pipeline} --shard \"$shard\" {flags} --cache {cache} --threads \"${{SLURM_CPUS_PER_TASK:-{c}}}\"\n",
        n = job.shards,
        lumen = quoted(&job.lumen),
        pipeline = quoted(&job.pipeline),
        cache = quoted(&job.cache),
        c = job.cpus_per_task,
    );
    s
}

/// The render array's script: task i makes share i + 1 of every case's renders.
pub fn render_script(job: &Job) -> String {
    let p = job.pipeline.display();
    array(
        job,
        &format!("lumen: the renders of {p} in {} shares, one array task each", job.shards),
        "render-%a.log",
        "--renders-only",
    )
}

/// The matches array's script: task i verifies share i + 1 of every case's blocks of pairs.
pub fn match_script(job: &Job) -> String {
    let p = job.pipeline.display();
    array(
        job,
        &format!("lumen: the image pairs of {p} in {} shares, one array task each", job.shards),
        "match-%a.log",
        "--matches-only",
    )
}

/// The run array's script: task i runs shard i + 1. A shard whose metrics miss a bound (exit 3)
/// still counts as done, so the merge runs and its report shows the miss (the merge exits 3).
pub fn array_script(job: &Job) -> String {
    let p = job.pipeline.display();
    let mut s = array(
        job,
        &format!("lumen: {p} as {} shards, one array task each", job.shards),
        "shard-%a.log",
        &format!("--out {}", quoted(&job.out)),
    );
    s += "code=$?\n# 3: a metric missed its bound, which the merged report shows\nif [ \"$code\" -eq 3 ]; then exit 0; fi\nexit \"$code\"\n";
    s
}

/// The merge job's script (submitted with `--dependency=afterok:ARRAY_JOB`).
pub fn merge_script(job: &Job) -> String {
    let mut s = header(job, "lumen: joins the shards' fragments into one report", "merge.log");
    s += &format!("set -u\nexec {} merge {}\n", quoted(&job.lumen), quoted(&job.out));
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scripts_name_every_shard_and_quote_paths() {
        let job = Job {
            lumen: "/opt/lumen".into(),
            pipeline: "/data/it's.toml".into(),
            out: "/scratch/out".into(),
            cache: "/scratch/cache".into(),
            name: "all".into(),
            shards: 3,
            cpus_per_task: 2,
            time: Some("1:00:00".into()),
            partition: None,
        };
        let a = array_script(&job);
        assert!(a.contains("#SBATCH --array=0-2\n") && a.contains("#SBATCH --time=1:00:00\n"), "{a}");
        assert!(a.contains("'/data/it'\\''s.toml'") && a.contains("$((SLURM_ARRAY_TASK_ID + 1))/3"), "{a}");
        assert!(!a.contains("--partition"));
        assert!(merge_script(&job).contains("exec '/opt/lumen' merge '/scratch/out'"));
        let r = render_script(&job);
        assert!(
            r.contains("#SBATCH --array=0-2\n") && r.contains("--renders-only --cache '/scratch/cache'"),
            "{r}"
        );
        let m = match_script(&job);
        assert!(m.contains("--matches-only --cache '/scratch/cache'") && m.contains("match-%a.log"), "{m}");
        assert!(check_word("--partition", "gpu,debug").is_ok());
        for bad in ["", "a b", "x\n#SBATCH --mem=1T", "$(rm)"] {
            assert!(check_word("--partition", bad).is_err(), "{bad:?}");
        }
    }
}
