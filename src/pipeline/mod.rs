//! Pipeline files: which stages run, on which scenes, with which seeds and bounds; the runner
//! that runs them; and the report.
//!
//! A pipeline file (TOML) looks like
//!
//! ```toml
//! name = "all"            # optional; default: the file's stem
//! seed = 1                # seed of every stage that does not set its own
//! [[stages]]
//! stage = "render"        # which stage
//! case = "cornell-box"    # the case's name in the report
//! scene = "scenes/cornell-box.toml"   # paths are relative to the pipeline file
//! spp = 256
//! reference = "../../shared/data/scenes/cornell-box/reference.exr"
//! reference_variance = "../../shared/data/scenes/cornell-box/reference_variance.exr"
//! bounds = { mean_rel_err_r = 0.01, z_test_pass_fraction = 0.9975 }
//! expected_miss = { some_metric = "why it is not met yet" }
//! ```
//!
//! Stage dispatch is an enum and a match. Only listed stages run, and each renders only what
//! it consumes.

pub mod report;
pub mod stage_calibrate;
pub mod stage_photometric;
pub mod stage_render;

use report::{Metric, Report, StageReport};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("cannot read pipeline {path}: {message}")]
    Io { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("{path}: stage {stage} ({case}): {message}")]
    Stage { path: PathBuf, stage: usize, case: String, message: String },
    #[error("cannot write {path}: {message}")]
    Write { path: PathBuf, message: String },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PipelineFile {
    pub name: Option<String>,
    #[serde(default = "default_seed")]
    pub seed: u64,
    pub stages: Vec<StageSpec>,
}

fn default_seed() -> u64 {
    1
}

#[derive(Debug, Deserialize)]
#[serde(tag = "stage", rename_all = "lowercase")]
pub enum StageSpec {
    Render(stage_render::RenderStage),
    Calibrate(stage_calibrate::CalibrateStage),
    Photometric(stage_photometric::PhotometricStage),
}

/// What every stage entry has besides its own settings (each stage's file struct carries
/// these fields itself: serde's `flatten` would silently switch off `deny_unknown_fields`).
#[derive(Debug, Default)]
pub struct Common {
    pub case: String,
    pub seed: Option<u64>,
    /// Bound per metric name. Whether it is an upper or lower bound is the metric's own.
    pub bounds: BTreeMap<String, f64>,
    /// Metric name → why its bound is not met yet. Shown in the report; does not fail the run.
    pub expected_miss: BTreeMap<String, String>,
}

impl StageSpec {
    fn common(&self) -> Common {
        match self {
            StageSpec::Render(s) => s.common(),
            StageSpec::Calibrate(s) => s.common(),
            StageSpec::Photometric(s) => s.common(),
        }
    }
    fn name(&self) -> &'static str {
        match self {
            StageSpec::Render(_) => "render",
            StageSpec::Calibrate(_) => "calibrate",
            StageSpec::Photometric(_) => "photometric",
        }
    }
}

/// Options of a run that are not in the pipeline file.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    pub threads: Option<usize>,
    pub progress: bool,
    /// The output folder, where stages save images they are asked to keep.
    pub out_dir: PathBuf,
}

pub fn load(path: &Path) -> Result<PipelineFile, Error> {
    let text =
        std::fs::read_to_string(path).map_err(|e| Error::Io { path: path.into(), message: e.to_string() })?;
    let file: PipelineFile =
        toml::from_str(&text).map_err(|e| Error::Parse { path: path.into(), message: e.to_string() })?;
    if file.stages.is_empty() {
        return Err(Error::Parse { path: path.into(), message: "`stages` is empty: nothing to run".into() });
    }
    Ok(file)
}

/// The name a pipeline's outputs go under: `name`, or the file's stem.
pub fn pipeline_name(file: &PipelineFile, path: &Path) -> String {
    file.name
        .clone()
        .unwrap_or_else(|| path.file_stem().and_then(|s| s.to_str()).unwrap_or("pipeline").to_string())
}

/// Runs every stage of a pipeline file and returns the report (not yet written). With
/// `opts.threads`, all of a stage's parallel work (rendering, detection, solving) shares that
/// many threads.
pub fn run(path: &Path, file: &PipelineFile, opts: &RunOptions) -> Result<Report, Error> {
    let pool = opts.threads.and_then(|n| rayon::ThreadPoolBuilder::new().num_threads(n.max(1)).build().ok());
    match pool {
        Some(pool) => pool.install(|| run_stages(path, file, opts)),
        None => run_stages(path, file, opts),
    }
}

fn run_stages(path: &Path, file: &PipelineFile, opts: &RunOptions) -> Result<Report, Error> {
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut stages = Vec::new();
    for (i, spec) in file.stages.iter().enumerate() {
        let common = spec.common();
        let stage_err = |message: String| Error::Stage {
            path: path.into(),
            stage: i + 1,
            case: common.case.clone(),
            message,
        };
        let seed = common.seed.unwrap_or(file.seed);
        let t = std::time::Instant::now();
        let out = match spec {
            StageSpec::Render(s) => stage_render::run(s, &dir, seed, opts).map_err(stage_err)?,
            StageSpec::Calibrate(s) => stage_calibrate::run(s, &dir, seed, opts).map_err(stage_err)?,
            StageSpec::Photometric(s) => stage_photometric::run(s, &dir, seed, opts).map_err(stage_err)?,
        };
        let mut timings = out.timings_s;
        timings.insert("total".into(), t.elapsed().as_secs_f64());
        let metrics = apply_bounds(out.metrics, &common).map_err(stage_err)?;
        stages.push(StageReport {
            stage: spec.name().into(),
            case: common.case.clone(),
            mode: "alone".into(),
            seed,
            metrics,
            timings_s: timings,
            notes: out.notes,
        });
    }
    Ok(Report::new(pipeline_name(file, path), file.seed, stages))
}

/// What a stage hands back: its metrics (bounds not yet applied), timings and notes.
pub struct StageOutput {
    pub metrics: Vec<Metric>,
    pub timings_s: BTreeMap<String, f64>,
    pub notes: Vec<String>,
}

/// Attaches each metric's bound and verdict. A bound or expected miss that names a metric the
/// stage did not produce is an error, so a typo cannot silently disable a check.
fn apply_bounds(mut metrics: Vec<Metric>, common: &Common) -> Result<Vec<Metric>, String> {
    for name in common.bounds.keys().chain(common.expected_miss.keys()) {
        if !metrics.iter().any(|m| &m.name == name) {
            let known: Vec<&str> = metrics.iter().map(|m| m.name.as_str()).collect();
            return Err(format!("bound or expected_miss names metric `{name}`, which this stage does not report (it reports: {})", known.join(", ")));
        }
    }
    for m in &mut metrics {
        if let Some(&b) = common.bounds.get(&m.name) {
            m.bound = Some(b);
            m.pass = Some(m.meets(b));
        }
        m.expected_miss = common.expected_miss.get(&m.name).cloned();
    }
    Ok(metrics)
}
