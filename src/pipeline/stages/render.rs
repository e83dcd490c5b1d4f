//! The `render` stage: renders a scene and checks the image against what is known of it —
//! a reference render with its variance (Mitsuba 3's Cornell box), or a closed-form uniform
//! radiance (the furnace). Here the renderer is what is measured, so its image is rendered
//! afresh on every run (not through the cache) and `mpaths_per_s` is the real speed.
//!
//! Metrics:
//! - `mean_rel_err_{r,g,b}`: |mean of render − mean of reference| / mean of reference;
//! - `z_test_pass_fraction`: pixel channels passing the per-pixel z-test against the reference
//!   (Šidák-corrected, α = 0.01; see `image::metrics::agreement`);
//! - `rmse`: root-mean-square difference from the reference over pixel channels;
//! - `max_rel_err`, `mean_rel_err`: against a uniform expected radiance;
//! - `nonfinite_samples`: samples that came out NaN or infinite (must be 0);
//! - `mpaths_per_s`: million camera paths per second (no bound: speed is for benchmarks).
//!
//! When the reference files are absent (`../shared` is not beside the checkout) the reference
//! metrics are reported as skipped, with the missing file named.

use super::{apply_overrides, Context, Findings, Kept, StageError};
use crate::image::{io, metrics, Image};
use crate::pipeline::metric::{Better, Metric};
use crate::render;
use serde::Deserialize;
use std::path::PathBuf;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Scene file, relative to the pipeline file.
    pub scene: String,
    /// Samples per pixel (default: the scene's).
    pub spp: Option<u32>,
    /// Longest path in segments (default: the scene's).
    pub max_depth: Option<u32>,
    /// Reference render (EXR) and the variance of its mean (EXR), relative to the pipeline
    /// file. When the files are absent the comparison is skipped with a note.
    pub reference: Option<String>,
    pub reference_variance: Option<String>,
    /// Closed-form radiance every pixel must have (linear RGB, finite).
    pub expect_uniform: Option<[f64; 3]>,
    /// File name (.exr or .png) to save the rendered image under, in the output folder.
    pub save: Option<String>,
}

pub struct Input {
    scene: render::Scene,
    settings: render::Settings,
}

pub enum Reference {
    None,
    /// Why it is absent (the missing file).
    Absent(String),
    Images {
        path: PathBuf,
        mean: Image,
        variance: Image,
    },
}

pub struct Truth {
    reference: Reference,
    uniform: Option<[f64; 3]>,
}

pub struct Output {
    film: render::Film,
    settings: render::Settings,
    seconds: f64,
}

pub fn synthesize(c: &Config, ctx: &Context) -> Result<(Input, Truth, Findings), StageError> {
    let scene = render::load(&ctx.dir.join(&c.scene))?;
    let mut settings = render::Settings::from_scene(&scene);
    settings.seed = ctx.seed;
    settings.progress = ctx.progress;
    apply_overrides(&mut settings, c.spp, c.max_depth)?;
    if let Some(e) = c.expect_uniform {
        if !e.iter().all(|v| v.is_finite() && *v > 0.0) {
            return Err(StageError::Config(format!(
                "expect_uniform = {e:?}: expected three finite positive radiances"
            )));
        }
    }
    let reference = match (&c.reference, &c.reference_variance) {
        (Some(r), Some(rv)) => {
            let (rp, rvp) = (ctx.dir.join(r), ctx.dir.join(rv));
            let missing = [&rp, &rvp].into_iter().find(|p| !p.exists()).map(|p| clean(p));
            match missing {
                Some(m) => Reference::Absent(format!("{} not found", m.display())),
                None => {
                    Reference::Images { mean: io::read_exr(&rp)?, variance: io::read_exr(&rvp)?, path: rp }
                }
            }
        }
        (None, None) => Reference::None,
        _ => {
            return Err(StageError::Config(
                "give both `reference` and `reference_variance`, or neither".into(),
            ))
        }
    };
    if let Reference::Images { path, mean, variance } = &reference {
        let (w, h) = (scene.camera.width, scene.camera.height);
        for (what, img) in [("reference", mean), ("reference_variance", variance)] {
            if (img.width, img.height, img.channels) != (w, h, 3) {
                return Err(StageError::Config(format!(
                    "{what} {}: {}×{}×{}, but the scene renders {w}×{h}×3",
                    clean(path).display(),
                    img.width,
                    img.height,
                    img.channels
                )));
            }
        }
        if mean.has_non_finite() || variance.has_non_finite() {
            return Err(StageError::Config(format!("reference {}: holds non-finite pixels", path.display())));
        }
    }
    let mut found = Findings::default();
    if scene.lights.is_empty() {
        found.notes.push(format!(
            "{}: the scene has no light (or only black emitters): the image is black.",
            c.scene
        ));
    }
    Ok((Input { scene, settings }, Truth { reference, uniform: c.expect_uniform }, found))
}

/// A path without `dir/../` detours, for messages.
pub fn clean(p: &std::path::Path) -> PathBuf {
    let mut out = PathBuf::new();
    for part in p.components() {
        match part {
            std::path::Component::ParentDir if out.file_name().is_some() => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

pub fn solve(_c: &Config, input: &Input) -> Result<Output, StageError> {
    let t = std::time::Instant::now();
    let film = render::render(&input.scene, &input.settings);
    Ok(Output { film, settings: input.settings.clone(), seconds: t.elapsed().as_secs_f64() })
}

pub fn validate(c: &Config, out: &Output, truth: &Truth) -> Findings {
    let (film, settings) = (&out.film, &out.settings);
    let paths = film.mean.width as f64 * film.mean.height as f64 * settings.spp as f64;
    let mut f = Findings::default();
    f.metrics.push(Metric::new("nonfinite_samples", film.dropped_samples as f64, "samples", Better::Lower));
    f.metrics.push(Metric::new("mpaths_per_s", paths / out.seconds.max(1e-9) / 1e6, "M/s", Better::Higher));
    f.notes.push(format!(
        "{}x{} pixels, {} spp, max depth {}.",
        film.mean.width, film.mean.height, settings.spp, settings.max_depth
    ));
    let reference_metrics = ["mean_rel_err_r", "mean_rel_err_g", "mean_rel_err_b", "rmse"];
    match &truth.reference {
        Reference::None => {}
        Reference::Absent(why) => {
            for name in reference_metrics {
                f.metrics.push(Metric::skipped(name, "", Better::Lower, why.clone()));
            }
            f.metrics.push(Metric::skipped("z_test_pass_fraction", "", Better::Higher, why.clone()));
            f.notes.push(format!("reference {why}: comparison skipped."));
        }
        Reference::Images { path, mean, variance } => {
            match metrics::agreement(&film.mean, &film.variance, mean, variance, 0.01) {
                Ok(a) => {
                    for (ch, name) in ["r", "g", "b"].iter().enumerate() {
                        f.metrics.push(Metric::new(
                            &format!("mean_rel_err_{name}"),
                            a.mean_rel_err[ch].abs(),
                            "",
                            Better::Lower,
                        ));
                    }
                    f.metrics.push(Metric::new("rmse", metrics::rmse(&film.mean, mean), "", Better::Lower));
                    f.metrics.push(Metric::new("z_test_pass_fraction", a.pass_fraction, "", Better::Higher));
                    f.notes.push(format!(
                        "z-test against {}: {} of {} pixel channels beyond |z| = {:.2} (Šidák α = {:.2e}).",
                        clean(path).display(),
                        a.failed,
                        a.tested,
                        a.z_critical,
                        a.alpha_sidak
                    ));
                }
                Err(e) => {
                    let why = format!("reference {}: {e}", clean(path).display());
                    for name in reference_metrics {
                        f.metrics.push(Metric::missing(name, "", Better::Lower, why.clone()));
                    }
                    f.metrics.push(Metric::missing("z_test_pass_fraction", "", Better::Higher, why));
                }
            }
        }
    }
    if let Some(e) = truth.uniform {
        let (mut max_rel, mut sum_rel) = (0.0f64, 0.0f64);
        let mut finite = true;
        for px in film.mean.data.chunks_exact(3) {
            for ch in 0..3 {
                let rel = (px[ch] as f64 - e[ch]).abs() / e[ch];
                finite &= rel.is_finite();
                max_rel = max_rel.max(rel);
                sum_rel += rel;
            }
        }
        let why = "the image holds a non-finite pixel";
        let n = film.mean.data.len().max(1) as f64;
        f.metrics.push(Metric::maybe("max_rel_err", finite.then_some(max_rel), "", Better::Lower, why));
        f.metrics.push(Metric::maybe("mean_rel_err", finite.then_some(sum_rel / n), "", Better::Lower, why));
    }
    if let Some(name) = &c.save {
        f.files.push((PathBuf::from(name), Kept::Image(film.mean.clone())));
    }
    f
}
