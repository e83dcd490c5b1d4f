//! `lumen run`, `lumen merge` and `lumen slurm`: a pipeline run whole, as shards or render
//! shares, its fragments merged, and the sbatch scripts that run it on a Slurm cluster.

use anyhow::{bail, Context, Result};
use lumen::pipeline;
use std::path::{Path, PathBuf};

/// Exit code of `lumen run` when a metric missed its bound without a declared expected miss,
/// or met a bound declared a miss.
const EXIT_METRIC_MISSED: i32 = 3;

pub fn run_pipeline(path: &Path, out: Option<PathBuf>, opts: pipeline::RunOptions) -> Result<i32> {
    let file = pipeline::load(path)?;
    let name = pipeline::pipeline_name(&file, path);
    let out = out.unwrap_or_else(|| Path::new("out").join(&name));
    let report = pipeline::run(path, &file, &opts)?;
    let dir = opts.shard.map_or_else(|| out.clone(), |s| s.dir(&out));
    report.write(&dir)?;
    eprintln!("wrote {} and {}", dir.join("report.json").display(), dir.join("report.md").display());
    if let Some(s) = opts.shard {
        eprintln!(
            "this is shard {}/{}: once every shard has run, `lumen merge {}` joins them",
            s.k,
            s.n,
            out.display()
        );
    }
    Ok(summarize(&report))
}

pub fn render_share(
    path: &Path,
    cache: PathBuf,
    share: lumen::pipeline::shard::Shard,
    pass: pipeline::cache::Pass,
    threads: Option<usize>,
) -> Result<i32> {
    let file = pipeline::load(path)?;
    let c = pipeline::render_share(path, &file, cache.clone(), share, pass, threads, true)?;
    let (name, what) = match pass {
        pipeline::cache::Pass::Renders => ("render", "render requests"),
        pipeline::cache::Pass::Matches => ("matches", "blocks of image pairs"),
    };
    eprintln!(
        "{name} share {}/{}: {} of the pipeline's {what} are this share's, {} made in {} ({} already there); {} are other shares'",
        share.k,
        share.n,
        c.owned,
        c.rendered,
        cache.display(),
        c.owned - c.rendered,
        c.others
    );
    Ok(0)
}

pub fn merge_cmd(out: &Path) -> Result<i32> {
    let report = pipeline::shard::merge(out)?;
    report.write(out)?;
    eprintln!("wrote {} and {}", out.join("report.json").display(), out.join("report.md").display());
    Ok(summarize(&report))
}

/// `lumen slurm`'s flags (`Command::Slurm`).
pub struct SlurmArgs {
    pub shards: usize,
    pub out: Option<PathBuf>,
    pub cache: Option<PathBuf>,
    pub partition: Option<String>,
    pub time: Option<String>,
    pub cpus_per_task: usize,
    pub submit: bool,
    pub wait: bool,
}

/// Writes the scripts and, when asked, submits them; the exit code is the merge job's when
/// waiting for it, else 0.
pub fn slurm_cmd(path: &Path, a: SlurmArgs) -> Result<i32> {
    use lumen::pipeline::{shard::MAX_SHARDS, slurm};
    if !(1..=MAX_SHARDS).contains(&a.shards) {
        bail!("--shards {}: expected 1 to {MAX_SHARDS}", a.shards);
    }
    if !(1..=pipeline::MAX_THREADS).contains(&a.cpus_per_task) {
        bail!("--cpus-per-task {}: expected 1 to {}", a.cpus_per_task, pipeline::MAX_THREADS);
    }
    for (flag, value) in [("--partition", &a.partition), ("--time", &a.time)] {
        if let Some(v) = value {
            slurm::check_word(flag, v).map_err(anyhow::Error::msg)?;
        }
    }
    let file = pipeline::load(path)?;
    let name = pipeline::pipeline_name(&file, path);
    let absolute =
        |p: &Path| std::path::absolute(p).with_context(|| format!("cannot resolve {}", p.display()));
    let out = absolute(&a.out.unwrap_or_else(|| Path::new("out").join(&name)))?;
    let cache = match a.cache {
        Some(c) => absolute(&c)?,
        None => out.parent().unwrap_or(&out).join("cache"),
    };
    let job = slurm::Job {
        lumen: std::env::current_exe().context("cannot find the lumen binary's path")?,
        pipeline: absolute(path)?,
        out: out.clone(),
        cache,
        name: pipeline::names::file_stem(&name),
        shards: a.shards,
        cpus_per_task: a.cpus_per_task,
        time: a.time,
        partition: a.partition,
    };
    let dir = out.join("slurm");
    let scripts = [
        ("render.sbatch", slurm::render_script(&job)),
        ("match.sbatch", slurm::match_script(&job)),
        ("run.sbatch", slurm::array_script(&job)),
        ("merge.sbatch", slurm::merge_script(&job)),
    ];
    lumen::image::io::write_together(&dir, |staged| -> Result<()> {
        for (name, text) in &scripts {
            let p = staged.join(name);
            std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))?;
        }
        Ok(())
    })?;
    let [render, matches, run, merge] = scripts.map(|(name, _)| dir.join(name));
    eprintln!("wrote {}, {}, {} and {}", render.display(), matches.display(), run.display(), merge.display());
    // A task that fails leaves the next job's dependency unmet: Slurm then cancels that job
    // instead of holding it pending for ever.
    let after = "--kill-on-invalid-dep=yes";
    if !a.submit {
        eprintln!(
            "submit with: r=$(sbatch --parsable {}) && m=$(sbatch --parsable --dependency=afterok:$r {after} {}) && s=$(sbatch --parsable --dependency=afterok:$m {after} {}) && sbatch --dependency=afterok:$s {after} {}",
            render.display(),
            matches.display(),
            run.display(),
            merge.display()
        );
        return Ok(0);
    }
    let sbatch = |args: &[&str]| -> Result<(String, Option<i32>)> {
        let o = std::process::Command::new("sbatch")
            .args(args)
            .output()
            .context("cannot run sbatch (is Slurm installed and on PATH?)")?;
        // --parsable prints `ID` or `ID;CLUSTER`.
        let text = String::from_utf8_lossy(&o.stdout);
        let id = text.trim().split(';').next().unwrap_or("").to_string();
        // With --wait, sbatch exits with the job's own code once it has been submitted.
        if !o.status.success() && (id.is_empty() || !args.contains(&"--wait")) {
            bail!("sbatch {} failed: {}", args.join(" "), String::from_utf8_lossy(&o.stderr).trim());
        }
        Ok((id, o.status.code()))
    };
    // sbatch --wait exits 0 for a merge Slurm cancelled (a shard failed): only a report.json
    // the merge wrote anew says it ran.
    let report = out.join("report.json");
    let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    let before = modified(&report);
    let (renders, _) = sbatch(&["--parsable", &render.to_string_lossy()])?;
    let (pairs, _) = sbatch(&[
        "--parsable",
        &format!("--dependency=afterok:{renders}"),
        after,
        &matches.to_string_lossy(),
    ])?;
    let (array, _) =
        sbatch(&["--parsable", &format!("--dependency=afterok:{pairs}"), after, &run.to_string_lossy()])?;
    let dependency = format!("--dependency=afterok:{array}");
    let mut args = vec!["--parsable", &dependency, after];
    if a.wait {
        eprintln!(
            "render job {renders}, matches job {pairs} and array job {array} submitted; waiting for the merge job"
        );
        args.push("--wait");
    }
    let script = merge.to_string_lossy();
    args.push(&script);
    let (merge_id, code) = sbatch(&args)?;
    println!("render job {renders}, matches job {pairs}, array job {array}, merge job {merge_id}");
    if !a.wait {
        return Ok(0);
    }
    let logs = dir.join("{render,match,shard}-*.log");
    match code {
        Some(c @ (0 | 3)) if modified(&report).is_some_and(|m| Some(m) != before) => Ok(c),
        Some(0 | 3) => bail!(
            "merge job {merge_id} ended without writing {}: a shard failed and Slurm cancelled the merge (see {})",
            report.display(),
            logs.display()
        ),
        Some(c) => bail!(
            "merge job {merge_id} ended with exit code {c}: see {} and {}",
            dir.join("merge.log").display(),
            logs.display()
        ),
        None => bail!("sbatch --wait for merge job {merge_id} was stopped by a signal"),
    }
}

/// One line per case and per failure on stderr; the exit code the report earns.
fn summarize(report: &pipeline::report::Report) -> i32 {
    let width = report.stages.iter().map(|s| s.case.chars().count()).max().unwrap_or(0);
    for s in &report.stages {
        if let Some(why) = &s.skipped {
            eprintln!("  {:<11} {:<width$} skipped: {why}", s.stage, s.case);
            continue;
        }
        let met = s.metrics.iter().filter(|m| m.pass == Some(true)).count();
        let bounded = s.metrics.iter().filter(|m| m.bound.is_some() && m.unjudged().is_none()).count();
        eprintln!(
            "  {:<11} {:<width$} {met}/{bounded} bounds met, {:>8.2} s, {} rendered, {} reused",
            s.stage,
            s.case,
            s.timings_s.get("total").copied().unwrap_or(0.0),
            s.renders.rendered,
            s.renders.reused
        );
    }
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    let failures = report.failures();
    if failures.is_empty() {
        return 0;
    }
    for f in failures {
        eprintln!("error: metric {f}");
    }
    EXIT_METRIC_MISSED
}
