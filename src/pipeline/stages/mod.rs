//! The stages, one file each, and the one table of them (`REGISTRY`). Every stage is three
//! plain functions around its solver:
//!
//! - `synthesize(&Config, &Context) -> Synthesis<Input, Truth>`: renders the stage's input
//!   through the render cache and keeps the truth beside it (its findings: notes, and the
//!   input files an entry asks to keep), or, in a share of the shard passes, only asks for
//!   the renders (`None`); a case on real data `read`s its input instead;
//! - `solve(&Config, &Input) -> Output`: the solver module's `run`, the function the CLI
//!   calls too, with a `Config` built from the pipeline entry;
//! - `validate(&Config, &Output, &Truth) -> Findings`: the only place that holds an
//!   estimate and its truth together.
//!
//! `run_case` times the three apart, so a solver is never credited or blamed for the
//! renderer. A stage's entry settings implement `Settings`: its headline metric, the case
//! run through those three functions, and its share of the shard passes (`share`). A new
//! stage is one file here and one line in `REGISTRY`.

pub mod calibrate;
pub mod chain;
pub mod chart;
pub mod color;
pub mod color_chain;
pub mod hdr;
pub mod novel_view;
pub mod photometric;
pub mod render;
pub mod sfm;

pub use chain::{from_case, Exports};

/// What a pipeline entry's own settings do: one implementation per kind of entry.
pub trait Settings: std::fmt::Debug + Send + Sync {
    /// The error metric a sweep's plot shows unless the entry names another.
    fn headline(&self) -> &'static str;
    /// Runs the case: synthesis (or reading its data), solve, validation (`run_case`).
    fn run(&self, ctx: &Context) -> Result<CaseResult, StageError>;
    /// The case's share of a shard pass (`pipeline::render_share`): asks for its renders (and
    /// in the matches pass its pairs) through `ctx.cache`; `None` when it has nothing to share
    /// in `pass` (real data other than structure from motion's, renders timed afresh).
    fn share(&self, _ctx: &Context, _pass: Pass) -> Option<Result<(), StageError>> {
        None
    }
    /// The earlier cases this one takes an output from, as its `from:CASE` fields name them:
    /// (field, case, the kind of output).
    fn upstream(&self) -> Vec<(&'static str, String, &'static str)> {
        Vec::new()
    }
    /// The kinds of output this case hands on to later cases (`Exports`).
    fn provides(&self) -> &'static [&'static str] {
        &[]
    }
}

/// A stage of a pipeline entry with its settings.
#[derive(Debug)]
pub struct Stage {
    name: &'static str,
    settings: Box<dyn Settings>,
}

impl Stage {
    pub fn name(&self) -> &'static str {
        self.name
    }
    pub fn headline(&self) -> &'static str {
        self.settings.headline()
    }
    pub fn run(&self, ctx: &Context) -> Result<CaseResult, StageError> {
        self.settings.run(ctx)
    }
    pub fn share(&self, ctx: &Context, pass: Pass) -> Option<Result<(), StageError>> {
        self.settings.share(ctx, pass)
    }
    pub fn upstream(&self) -> Vec<(&'static str, String, &'static str)> {
        self.settings.upstream()
    }
    pub fn provides(&self) -> &'static [&'static str] {
        self.settings.provides()
    }
}

/// One kind of entry: a stage on renders or on real data.
pub struct Kind {
    /// The entry's `stage`.
    pub stage: &'static str,
    /// The key that selects this kind among the stage's kinds (the first kind whose key the
    /// entry has, else the stage's kind without one).
    pub marked_by: Option<&'static str>,
    /// The key naming this kind's real data: an entry may not give it beside `scene`.
    pub real_data: Option<&'static str>,
    pub parse: fn(toml::Table) -> Result<Box<dyn Settings>, Invalid>,
}

fn parse<T: Settings + serde::de::DeserializeOwned + 'static>(
    t: toml::Table,
) -> Result<Box<dyn Settings>, Invalid> {
    from_table::<T>(t).map(|c| Box::new(c) as Box<dyn Settings>)
}

/// Every kind of pipeline entry.
pub const REGISTRY: &[Kind] = &[
    Kind { stage: "render", marked_by: None, real_data: None, parse: parse::<render::Config> },
    Kind {
        stage: "calibrate",
        marked_by: Some("images"),
        real_data: Some("images"),
        parse: parse::<calibrate::DataConfig>,
    },
    Kind { stage: "calibrate", marked_by: None, real_data: None, parse: parse::<calibrate::Config> },
    Kind {
        stage: "photometric",
        marked_by: Some("dataset"),
        real_data: Some("dataset"),
        parse: parse::<photometric::DataConfig>,
    },
    Kind { stage: "photometric", marked_by: None, real_data: None, parse: parse::<photometric::Config> },
    Kind { stage: "color", marked_by: None, real_data: None, parse: parse::<color::Config> },
    Kind {
        stage: "chart",
        marked_by: Some("photos"),
        real_data: Some("photos"),
        parse: parse::<chart::PhotoConfig>,
    },
    Kind { stage: "chart", marked_by: None, real_data: None, parse: parse::<chart::Config> },
    Kind { stage: "hdr", marked_by: Some("list"), real_data: Some("list"), parse: parse::<hdr::DataConfig> },
    Kind { stage: "hdr", marked_by: None, real_data: None, parse: parse::<hdr::Config> },
    Kind { stage: "sfm", marked_by: Some("scene"), real_data: None, parse: parse::<sfm::RenderConfig> },
    Kind { stage: "sfm", marked_by: None, real_data: Some("images"), parse: parse::<sfm::Config> },
    Kind { stage: "novel-view", marked_by: None, real_data: None, parse: parse::<novel_view::Config> },
];

/// The entry's stage from its name and its own keys, through `REGISTRY`.
pub fn parse_stage(name: &str, own: toml::Table) -> Result<Stage, Invalid> {
    let kinds: Vec<&Kind> = REGISTRY.iter().filter(|k| k.stage == name).collect();
    let Some(first) = kinds.first() else {
        let mut names: Vec<&str> = Vec::new();
        for k in REGISTRY {
            if !names.contains(&k.stage) {
                names.push(k.stage);
            }
        }
        let (last, rest) = names.split_last().map_or(("", &[][..]), |(l, r)| (*l, r));
        return Err(format!("unknown stage `{name}`: expected {} or {last}", rest.join(", ")).into());
    };
    // A stage on real data is told apart from its rendered variant by one key; both keys
    // given would blame the other variant's keys, so the pair is refused by name.
    if let Some(key) = kinds.iter().find_map(|k| k.real_data) {
        if own.contains_key(key) && own.contains_key("scene") {
            return Err(format!(
                "`{key}` and `scene` are both given: a {name} entry runs on real data (`{key}`) or on renders of a scene (`scene`), not both"
            ).into());
        }
    }
    let kind = kinds
        .iter()
        .find(|k| k.marked_by.is_some_and(|key| own.contains_key(key)))
        .or_else(|| kinds.iter().find(|k| k.marked_by.is_none()))
        .unwrap_or(first);
    Ok(Stage { name: kind.stage, settings: (kind.parse)(own)? })
}

/// Deserialises a table, naming the key at fault in the error.
pub fn from_table<T: serde::de::DeserializeOwned>(t: toml::Table) -> Result<T, Invalid> {
    serde_path_to_error::deserialize(toml::Value::Table(t)).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner().message().trim().to_string();
        Invalid(if path == "." { inner } else { format!("`{path}`: {inner}") })
    })
}

/// The folder or file a dataset case reads, relative to the pipeline file, shown without `..`
/// detours. When it is not there the case is skipped (`Absent`) only if the whole data tree
/// is missing: its nearest existing folder encloses the pipeline file's (as when `../shared`
/// is not beside a fresh clone). A path missing inside a data tree that is there is a typo,
/// refused by name.
pub fn dataset_path(ctx: &Context, path: &str) -> Result<PathBuf, StageError> {
    let p = render::clean(&ctx.dir.join(path));
    if p.exists() {
        return Ok(p);
    }
    let here = render::clean(&ctx.dir);
    let existing = p.ancestors().skip(1).find(|a| a.as_os_str().is_empty() || a.exists());
    match existing {
        Some(a) if !a.as_os_str().is_empty() && !here.starts_with(a) => Err(StageError::Config(format!(
            "{} does not exist, though {} does: a mistyped path? (a case is skipped only when its whole data folder is absent)",
            p.display(),
            a.display()
        ))),
        _ => Err(StageError::Absent(p)),
    }
}

use super::cache::{Cache, Pass};
use super::metric::Metric;
use crate::error::{Fault, Invalid};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A stage's failure, by whose fault it is.
#[derive(Debug, thiserror::Error)]
pub enum StageError {
    /// A setting of the pipeline entry is out of range or inconsistent.
    #[error("{0}")]
    Config(String),
    /// The real data a case reads are not there (for example `../shared` beside a fresh
    /// clone): the case is skipped with this reason, not failed.
    #[error("{} is absent", .0.display())]
    Absent(PathBuf),
    #[error(transparent)]
    Render(#[from] crate::render::Error),
    #[error(transparent)]
    Image(#[from] crate::image::io::Error),
    #[error(transparent)]
    Calib(#[from] crate::calib::Error),
    #[error(transparent)]
    Photometric(#[from] crate::photometric::Error),
    /// The colour or the hdr fit's.
    #[error(transparent)]
    Fit(#[from] crate::fit::FitError),
    #[error(transparent)]
    Sfm(#[from] crate::sfm::Error),
    #[error(transparent)]
    Surface(#[from] crate::surface::Error),
    #[error(transparent)]
    Ibr(#[from] crate::ibr::Error),
}

impl From<Invalid> for StageError {
    fn from(e: Invalid) -> StageError {
        StageError::Config(e.0)
    }
}

impl StageError {
    /// Whose fault it is, as the module that raised the error decided.
    pub fn fault(&self) -> Fault {
        match self {
            StageError::Config(_) => Fault::BadInput,
            StageError::Absent(_) => Fault::Io,
            StageError::Render(e) => e.fault(),
            StageError::Image(e) => e.fault(),
            StageError::Calib(e) => e.fault(),
            StageError::Photometric(e) => e.fault(),
            StageError::Fit(e) => e.fault(),
            StageError::Sfm(e) => e.fault(),
            StageError::Surface(e) => e.fault(),
            StageError::Ibr(e) => e.fault(),
        }
    }
}

/// What a stage needs from the run besides its own settings.
pub struct Context<'a> {
    /// The pipeline file's folder: paths in an entry are relative to it.
    pub dir: &'a Path,
    /// The case's name (labels the cache's events and progress bars).
    pub case: &'a str,
    pub seed: u64,
    pub cache: &'a Cache,
    pub progress: bool,
    /// What the earlier cases of the run handed on, by case name.
    pub upstream: &'a BTreeMap<String, Exports>,
}

impl Context<'_> {
    /// Whether this is a share of the shard passes (`Cache::share`): its render requests
    /// hand no image back, so a stage's synthesis ends once it has asked for them all.
    pub fn renders_only(&self) -> bool {
        self.cache.renders_only()
    }
}

/// What a stage's synthesis gives: the case's input, truth and findings, or `None` in a
/// share of the shard passes, which only asks for the renders (`Context::renders_only`).
pub type Synthesis<I, T> = Option<(I, T, Findings)>;

/// What one case produced.
pub struct CaseResult {
    pub metrics: Vec<Metric>,
    pub notes: Vec<String>,
    /// `render` (synthesis: renders and truth), `solve` and `validate`, in seconds.
    pub timings_s: BTreeMap<String, f64>,
    /// Files to write into the output folder with the report.
    pub files: Vec<(PathBuf, Kept)>,
    /// What the case hands on to later cases.
    pub exports: Exports,
    /// The estimate's errors item by item, for a chained case's prediction (`chain::Linear`).
    pub linear: Option<chain::Linear>,
}

/// A file a case asks to keep in the output folder, written with the report.
#[derive(Clone, Debug)]
pub enum Kept {
    /// Written by extension (.exr linear float, .png 8-bit).
    Image(crate::image::Image),
    Bytes(Vec<u8>),
}

/// What a stage finds: metrics, notes for the report, files to keep (path relative to the
/// output folder).
#[derive(Default)]
pub struct Findings {
    pub metrics: Vec<Metric>,
    pub notes: Vec<String>,
    pub files: Vec<(PathBuf, Kept)>,
    /// The estimate's errors item by item (`chain::Linear`), from a stage whose chained cases
    /// predict their inherited error from them.
    pub linear: Option<chain::Linear>,
}

/// Runs one case: synthesis (or reading its data), solve, validation, each timed.
pub fn run_case<I, T, O>(
    synthesize: impl FnOnce() -> Result<Synthesis<I, T>, StageError>,
    solve: impl FnOnce(&I) -> Result<O, StageError>,
    validate: impl FnOnce(&O, &T) -> Findings,
) -> Result<CaseResult, StageError> {
    run_case_exporting(synthesize, solve, validate, |_, _| Exports::default())
}

/// `run_case`, with what the case hands on to later cases made from its output and truth.
pub fn run_case_exporting<I, T, O>(
    synthesize: impl FnOnce() -> Result<Synthesis<I, T>, StageError>,
    solve: impl FnOnce(&I) -> Result<O, StageError>,
    validate: impl FnOnce(&O, &T) -> Findings,
    export: impl FnOnce(&O, &T) -> Exports,
) -> Result<CaseResult, StageError> {
    let t = std::time::Instant::now();
    // A run's cache hands every render back; only a share's synthesis ends without input.
    let Some((input, truth, mut found)) = synthesize()? else {
        return Err(StageError::Config("the case's renders were asked for, but none came back".into()));
    };
    let render_s = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let output = solve(&input)?;
    let solve_s = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let more = validate(&output, &truth);
    let validate_s = t.elapsed().as_secs_f64();
    let exports = export(&output, &truth);
    found.metrics.extend(more.metrics);
    found.notes.extend(more.notes);
    found.files.extend(more.files);
    let linear = more.linear.or(found.linear);
    let timings_s = BTreeMap::from([
        ("render".into(), render_s),
        ("solve".into(), solve_s),
        ("validate".into(), validate_s),
    ]);
    Ok(CaseResult {
        metrics: found.metrics,
        notes: found.notes,
        timings_s,
        files: found.files,
        exports,
        linear,
    })
}

/// Most views (calibrate, sfm) or lights (photometric) one case may ask for: each is a render.
pub const MAX_RENDERS: usize = 1000;

/// The one rule for an entry's render overrides: `spp` and `max_depth` replace the scene's
/// when given and must be at least 1 (as `lumen render` requires).
pub fn apply_overrides(
    settings: &mut crate::render::Settings,
    spp: Option<u32>,
    max_depth: Option<u32>,
) -> Result<(), StageError> {
    if let Some(n) = spp {
        if n == 0 {
            return Err(StageError::Config("spp = 0: expected at least 1 sample per pixel".into()));
        }
        settings.spp = n;
    }
    if let Some(d) = max_depth {
        if d == 0 {
            return Err(StageError::Config("max_depth = 0: expected at least 1 path segment".into()));
        }
        settings.max_depth = d;
    }
    // The run's one thread pool is installed around every case: the renderer must not build
    // its own per image.
    settings.threads = None;
    Ok(())
}

/// One view's render through a scene's own camera, as the cache keys it (sfm, novel-view).
#[derive(serde::Serialize)]
pub struct ViewRecipe<'a> {
    pub product: &'static str,
    pub scene: &'a str,
    pub t_world_cam: [f64; 12],
    pub settings: SettingsKey,
}

/// Points a scene's camera as a case's `look_at` says (the scene's own pose when absent): a
/// scene shared by several cases, each looking at its own part of it, as a session's room is.
/// The scene's `digest` then names the pose too, so the cache keeps each view's renders apart.
pub fn aim(
    scene: &mut crate::render::Scene,
    digest: &mut String,
    look_at: Option<&crate::render::scene::LookAt>,
) -> Result<(), StageError> {
    let Some(l) = look_at else { return Ok(()) };
    let pose = l.pose().ok_or_else(|| {
        StageError::Config(format!(
            "look_at = {{ origin = {:?}, target = {:?}, up = {:?} }}: expected finite points within ±{:e}, the target apart from the origin and `up` not along the line of sight",
            l.origin, l.target, l.up, crate::render::scene::MAX_SCENE_VALUE
        ))
    })?;
    scene.t_world_cam = pose;
    digest.push_str(&format!(" look_at {:?}", pose_key(&pose)));
    Ok(())
}

/// A camera pose as a cache key holds it: the rotation's columns, then the translation.
pub fn pose_key(p: &crate::math::Pose) -> [f64; 12] {
    let mut key = [0.0; 12];
    key[..9].copy_from_slice(&p.rotation.to_cols_array());
    key[9..].copy_from_slice(&p.translation.to_array());
    key
}

/// The render settings a cache key depends on, and the filter a denoised truth render went
/// through (absent from the key of an unfiltered one, so those keys are as they always were).
#[derive(serde::Serialize)]
pub struct SettingsKey {
    pub spp: u32,
    pub max_depth: u32,
    pub seed: u64,
    pub sampler: crate::render::sampler::SamplerKind,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub denoise: Option<crate::image::denoise::Settings>,
}

impl From<&crate::render::Settings> for SettingsKey {
    fn from(s: &crate::render::Settings) -> SettingsKey {
        SettingsKey { spp: s.spp, max_depth: s.max_depth, seed: s.seed, sampler: s.sampler, denoise: None }
    }
}

impl SettingsKey {
    /// The key of a truth render made by `truth_render` with `denoise`.
    pub fn denoised(s: &crate::render::Settings, denoise: &Denoise) -> SettingsKey {
        SettingsKey { denoise: denoise.0.clone(), ..SettingsKey::from(s) }
    }
}

/// A stage's truth render: the film's mean, or with `denoise` that film filtered
/// (`render::denoised`: the halves cross-filtered, guided by the features of the same camera
/// samples), so fewer samples can give the noise of more.
pub fn truth_render(
    scene: &crate::render::Scene,
    settings: &crate::render::Settings,
    denoise: &Denoise,
) -> Result<crate::image::Image, crate::render::Error> {
    match &denoise.0 {
        None => Ok(crate::render::try_render(scene, settings)?.mean),
        Some(filter) => Ok(crate::render::denoised::render_denoised(scene, settings, filter)?.output.image),
    }
}

/// The report's note on a stage whose truth renders were denoised.
pub fn denoise_note(denoise: &Denoise, spp: u32) -> Option<String> {
    let f = denoise.0.as_ref()?;
    Some(format!(
        "truth renders at {spp} spp, denoised ({} filter{}, strengths {:?} chosen by SURE).",
        f.method.map_or("feature".to_string(), |m| m.to_string()),
        if spp >= 2 { ", half buffers cross-filtered" } else { "" },
        f.strengths
    ))
}

/// An entry's `denoise`: `true` for the default filter, `false` for none, or a table of the
/// filter's settings (`image::denoise::Settings`: `method`, `window_radius`, `k` …).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Denoise(pub Option<crate::image::denoise::Settings>);

impl<'de> serde::Deserialize<'de> for Denoise {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Denoise, D::Error> {
        struct Visit;
        impl<'de> serde::de::Visitor<'de> for Visit {
            type Value = Denoise;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("true, false, or a table of the filter's settings (method, window_radius, patch_radius, k, k_feature, tau, spatial_sigma, strengths)")
            }
            fn visit_bool<E: serde::de::Error>(self, on: bool) -> Result<Denoise, E> {
                Ok(Denoise(on.then(Default::default)))
            }
            fn visit_map<M: serde::de::MapAccess<'de>>(self, map: M) -> Result<Denoise, M::Error> {
                let s = <crate::image::denoise::Settings as serde::Deserialize>::deserialize(
                    serde::de::value::MapAccessDeserializer::new(map),
                )?;
                s.validate().map_err(|e| serde::de::Error::custom(e.0))?;
                Ok(Denoise(Some(s)))
            }
        }
        d.deserialize_any(Visit)
    }
}
