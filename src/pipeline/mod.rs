//! Pipelines: which stages run, on which scenes, with which seeds and bounds (`file`); the
//! runner (`run`); the stages, one file each and one table of them (`stages::REGISTRY`); the
//! render cache (`cache`); metrics and their verdicts (`metric`); the report (`report`). Every
//! stage is three plain functions (`stages` docs); only listed cases run, and each renders
//! only what it consumes.

use crate::error::Invalid;
pub mod cache;
pub mod docs;
pub mod file;
pub mod metric;
pub mod names;
pub mod report;
pub mod shard;
pub mod slurm;
pub mod stages;

pub use file::{load, PipelineFile};

use file::Case;
use metric::Metric;
use report::{Outcome, Renders, Report, StageFailure, StageReport};
use stages::{CaseResult, Context, StageError};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    File(#[from] file::Error),
    #[error("{path}: stages[{entry}] (line {line}, case {case}): {kind} error: {error}")]
    Stage { path: PathBuf, entry: usize, line: usize, case: String, kind: crate::Fault, error: StageError },
    #[error("{path}: {message}")]
    Bounds { path: PathBuf, message: String },
    #[error("--threads {0}: expected 1 to {MAX_THREADS}")]
    Threads(usize),
    #[error("cannot start {0} worker threads: {1}")]
    Pool(usize, String),
    #[error("cannot write {path}: {message}")]
    Write { path: PathBuf, message: String },
    #[error("cannot merge: {path}: {message}")]
    Merge { path: PathBuf, message: String },
    /// A report that is not one `lumen report` can use.
    #[error("{path}: {message}")]
    Report { path: PathBuf, message: String },
    /// A report that cannot be read.
    #[error("cannot read {path}: {message}")]
    ReadReport { path: PathBuf, message: String },
}

impl Error {
    pub fn fault(&self) -> crate::Fault {
        use crate::Fault;
        match self {
            Error::File(e) => e.fault(),
            Error::Stage { error, .. } => error.fault(),
            Error::Bounds { .. } | Error::Threads(_) | Error::Merge { .. } | Error::Report { .. } => {
                Fault::BadInput
            }
            Error::Pool(..) | Error::Write { .. } | Error::ReadReport { .. } => Fault::Io,
        }
    }
}

impl From<crate::image::io::Error> for Error {
    fn from(e: crate::image::io::Error) -> Error {
        use crate::image::io::Error as I;
        match e {
            I::Write { path, message } | I::Read { path, message } | I::Decode { path, message } => {
                Error::Write { path, message }
            }
            I::Format { path } => Error::Write { path, message: "expected a .exr or .png file name".into() },
        }
    }
}

/// Most worker threads a run may ask for: more than any machine lumen runs on has cores, few
/// enough that a typo (`--threads 100000`) is refused rather than starving the machine.
pub const MAX_THREADS: usize = 1024;

/// Options of a run that are not in the pipeline file.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Worker threads of the run's one pool (default: all cores).
    pub threads: Option<usize>,
    /// Progress bars (on a terminal) and a line per case on stderr.
    pub progress: bool,
    /// Where renders are cached (`None`: not cached).
    pub cache_dir: Option<PathBuf>,
    /// Run only this shard's cases; the report is then a fragment (`shard`).
    pub shard: Option<shard::Shard>,
}

/// The name a pipeline's outputs go under: `name`, or the file's stem.
pub fn pipeline_name(file: &PipelineFile, path: &Path) -> String {
    file.name
        .clone()
        .unwrap_or_else(|| path.file_stem().and_then(|s| s.to_str()).unwrap_or("pipeline").to_string())
}

/// Runs every case of a pipeline file in one thread pool and returns the report (not yet
/// written). A case whose error it did not declare stops the run with that error.
pub fn run(path: &Path, file: &PipelineFile, opts: &RunOptions) -> Result<Report, Error> {
    in_pool(opts.threads, || run_cases(path, file, opts))
}

/// Runs `f` in a pool of `threads` workers (default: all cores).
fn in_pool<T>(threads: Option<usize>, f: impl FnOnce() -> Result<T, Error> + Send) -> Result<T, Error>
where
    T: Send,
{
    let threads = match threads {
        Some(n) if n == 0 || n > MAX_THREADS => return Err(Error::Threads(n)),
        Some(n) => n,
        None => std::thread::available_parallelism().map_or(1, |n| n.get()),
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| Error::Pool(threads, e.to_string()))?;
    pool.install(f)
}

/// A share of a pipeline's work before its cases run (`cache` module docs). In the renders
/// pass (`lumen run --shard K/N --renders-only`) every case's renders, whichever shard runs
/// the case, are requested in file order through a cache that makes only the entries share K
/// owns, with the features of the structure-from-motion views it renders; in the matches pass
/// (`--matches-only`, after every renders share) the structure-from-motion cases make the
/// blocks of verified pairs share K owns. Nothing else runs and no report is written: once
/// every share of both passes has run, the shards run their cases from the full cache.
/// A case whose synthesis fails (a setting out of range, a declared error) is left to the
/// shard that runs it, which reports it; here it is only named on stderr with `progress`.
pub fn render_share(
    path: &Path,
    file: &PipelineFile,
    cache_dir: PathBuf,
    share: shard::Shard,
    pass: cache::Pass,
    threads: Option<usize>,
    progress: bool,
) -> Result<cache::ShareCount, Error> {
    in_pool(threads, || {
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let cache = cache::Cache::share(cache_dir.clone(), share.k, share.n, pass);
        let n = file.cases.len();
        for (k, case) in file.cases.iter().enumerate() {
            let seed = case.common.seed.unwrap_or(file.seed);
            let none = Default::default();
            let ctx = Context {
                dir: &dir,
                case: &case.common.case,
                seed,
                cache: &cache,
                progress: false,
                upstream: &none,
            };
            let before = cache.share_count();
            let Some(result) = case.stage.share(&ctx, pass) else { continue };
            if progress {
                let now = cache.share_count();
                let what = match result {
                    Ok(()) => String::new(),
                    Err(e) => format!(" (stopped: {e})"),
                };
                let kind = match pass {
                    cache::Pass::Renders => "renders",
                    cache::Pass::Matches => "blocks of pairs",
                };
                eprintln!(
                    "[{}/{n}] {} {}: {} of its {kind} are this share's, {} made{what}",
                    k + 1,
                    case.stage.name(),
                    case.common.case,
                    now.owned - before.owned,
                    now.rendered - before.rendered,
                );
            }
        }
        // The share exists to fill the cache: an entry it could not write fails it.
        if let Some(w) = cache.warnings().into_iter().next() {
            return Err(Error::Write { path: cache_dir, message: w });
        }
        Ok(cache.share_count())
    })
}

fn run_cases(path: &Path, file: &PipelineFile, opts: &RunOptions) -> Result<Report, Error> {
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let cache = cache::Cache::new(opts.cache_dir.clone());
    let bars = opts.progress && std::io::stderr().is_terminal();
    let started = std::time::Instant::now();
    let start_time = humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string();
    let mut stages = Vec::new();
    let mut files = Vec::new();
    // A chained case runs in its chain's first case's shard, after it.
    let taken: Vec<usize> =
        (0..file.cases.len()).filter(|&i| opts.shard.is_none_or(|s| s.takes(file.root(i)))).collect();
    let mut handed_on: std::collections::BTreeMap<String, stages::Exports> = Default::default();
    let n = taken.len();
    for (k, case) in taken.iter().map(|&i| &file.cases[i]).enumerate() {
        let seed = case.common.seed.unwrap_or(file.seed);
        let ctx = Context {
            dir: &dir,
            case: &case.common.case,
            seed,
            cache: &cache,
            progress: bars,
            upstream: &handed_on,
        };
        if opts.progress {
            eprintln!("[{}/{n}] {} {} ...", k + 1, case.stage.name(), case.common.case);
        }
        let t = std::time::Instant::now();
        let mut result = case.stage.run(&ctx);
        let total = t.elapsed().as_secs_f64();
        if let Ok(r) = &mut result {
            handed_on.insert(case.common.case.clone(), std::mem::take(&mut r.exports));
        }
        let (mut st, kept) = report_case(path, case, seed, result)?;
        st.timings_s.insert("total".into(), total);
        st.renders = Renders::from_events(&cache.events_of(&case.common.case));
        if opts.progress {
            let verdict = match (&st.skipped, st.failed()) {
                (Some(_), _) => "skipped (its data are absent)",
                (None, true) => "MISSED",
                (None, false) => "ok",
            };
            eprintln!(
                "[{}/{n}] {} {}: {verdict}, {:.1} s ({} rendered, {} reused; {:.0} s elapsed)",
                k + 1,
                st.stage,
                st.case,
                total,
                st.renders.rendered,
                st.renders.reused,
                started.elapsed().as_secs_f64()
            );
        }
        stages.push(st);
        files.extend(kept);
    }
    let mut report =
        Report::new(pipeline_name(file, path), file.seed, stages, started.elapsed().as_secs_f64());
    if let Some(s) = opts.shard {
        report.fragment = Some(shard::Fragment {
            shard: s.k,
            shards: s.n,
            pipeline_digest: shard::digest(path)?,
            cases: file.cases.len(),
            indices: taken,
            kept: files.iter().map(|(name, _)| name.clone()).collect(),
        });
        report.judge();
    }
    report.files = files;
    report.started = start_time;
    report.warnings = cache.warnings();
    Ok(report)
}

/// The case's report from its result, or the error that stops the run.
fn report_case(
    path: &Path,
    case: &Case,
    seed: u64,
    result: Result<CaseResult, StageError>,
) -> Result<(StageReport, Vec<(PathBuf, stages::Kept)>), Error> {
    let common = &case.common;
    let declared = common.expect_error.as_ref().map_or("result".to_string(), |k| format!("error: {k}"));
    let mut st = StageReport {
        stage: case.stage.name().into(),
        case: common.case.clone(),
        group: case.group.clone(),
        sweep: case.sweep.clone(),
        mode: if case.upstream.is_empty() { "alone" } else { "chained" }.into(),
        seed,
        outcome: Outcome { declared, actual: "result".into() },
        error: None,
        metrics: Vec::new(),
        timings_s: Default::default(),
        renders: Renders::default(),
        plot_metric: common.plot.clone().unwrap_or_else(|| case.stage.headline().to_string()),
        notes: Vec::new(),
        skipped: None,
    };
    match result {
        Err(StageError::Absent(p)) => {
            st.outcome.actual = "skipped".into();
            st.skipped = Some(format!("{} is absent: the case reads real data from there", p.display()));
            Ok((st, Vec::new()))
        }
        Ok(r) => {
            st.metrics = apply_bounds(r.metrics, common).map_err(|message| Error::Bounds {
                path: path.into(),
                message: format!(
                    "stages[{}] (line {}, case {}): {message}",
                    case.entry - 1,
                    case.line,
                    common.case
                ),
            })?;
            st.timings_s = r.timings_s;
            st.notes = r.notes;
            Ok((st, r.files))
        }
        Err(e) if common.expect_error.is_some() => {
            st.outcome.actual = format!("error: {}", e.fault());
            st.error = Some(StageFailure { kind: e.fault().to_string(), message: e.to_string() });
            Ok((st, Vec::new()))
        }
        Err(error) => Err(Error::Stage {
            path: path.into(),
            entry: case.entry - 1,
            line: case.line,
            case: common.case.clone(),
            kind: error.fault(),
            error,
        }),
    }
}

/// Attaches each metric's bound and verdict. A bound or expected miss that names a metric the
/// stage did not produce is an error, so a typo cannot silently disable a check; a skipped or
/// not applicable metric keeps its bound but gets no verdict.
fn apply_bounds(mut metrics: Vec<Metric>, common: &file::Common) -> Result<Vec<Metric>, Invalid> {
    for name in common.bounds.keys().chain(common.expected_miss.keys()) {
        if !metrics.iter().any(|m| &m.name == name) {
            let known: Vec<&str> = metrics.iter().map(|m| m.name.as_str()).collect();
            return Err(format!(
                "bound or expected_miss names metric `{name}`, which this stage does not report (it reports: {})",
                known.join(", ")
            ).into());
        }
    }
    for m in &mut metrics {
        if let Some(&b) = common.bounds.get(&m.name) {
            let b = b.resolve(m.better);
            m.bound = Some(b);
            if m.unjudged().is_none() {
                m.pass = Some(m.meets(b));
            }
        }
        m.expected_miss = common.expected_miss.get(&m.name).cloned();
    }
    Ok(metrics)
}
