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
//! - `relmse`: relative mean squared error against the reference, mean((x − ref)²/(ref² +
//!   0.01)) over pixel channels (`image::metrics::relmse`), and `relmse_region` over the
//!   case's `region` (a caustic, say): what error-against-time comparisons of integrators
//!   plot;
//! - `max_rel_err`, `mean_rel_err`: against a uniform expected radiance;
//! - `mean_err_sigmas`: against a uniform expected radiance, the image mean's distance from it
//!   in standard errors of that mean (from the film's per-pixel variance), the largest over
//!   channels: a test of bias that noise alone passes (|z| ≤ 4 but once in 16 000);
//! - `lit_pixels`: pixels with any channel above zero;
//! - `lit_pixels_off_emitters`: with `max_depth = 1`, lit pixels farther than one pixel from
//!   any pixel whose square sees an emitter or the environment (`render::truth::emitter_footprint`,
//!   8×8 rays; the one-pixel margin holds a sliver of emitter the rays pass by): must be 0;
//! - `nonfinite_samples`: samples that came out NaN or infinite (must be 0);
//! - `relmse_raw`: with `denoise`, the render's relMSE before the filter (the reference
//!   metrics above then measure the denoised image; the z-test is n/a, since filtered
//!   pixels are correlated), and `relmse_gain`, relmse_raw / relmse: what the filter bought
//!   (below 1, it made the image worse). n/a for the undenoised cases of a sweep over
//!   `denoise`, so one entry can bound it;
//! - `mpaths_per_s`: million camera paths per second (no bound: speed is for benchmarks);
//! - `denoise_s_per_megapixel`: with `denoise`, the seconds of the feature buffers and the
//!   filter per megapixel (no bound either).
//!
//! When the reference files are absent (`../shared` is not beside the checkout) the reference
//! metrics are reported as skipped, with the missing file named.

use super::Synthesis;
use super::{apply_overrides, Context, Findings, Kept, StageError};
use super::{run_case, CaseResult, Settings};
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
    /// The light-transport algorithm by name, `render::integrators::REGISTRY` (default: the
    /// scene's `[render] integrator`, or `sppm` where that is the path tracer and the scene
    /// has a caustic: `render::integrators::choose`, whose choice and reason the report
    /// notes).
    pub integrator: Option<&'static render::integrators::Kind>,
    /// Samples per pixel (default: the scene's).
    pub spp: Option<u32>,
    /// Longest path in segments (default: the scene's).
    pub max_depth: Option<u32>,
    /// Photons for `pm` (in all) and `sppm` (per pass) (default: the scene's
    /// `[render.photon] count`).
    pub photons: Option<u64>,
    /// Reference render (EXR) and the variance of its mean (EXR), relative to the pipeline
    /// file. When the files are absent the comparison is skipped with a note.
    pub reference: Option<String>,
    pub reference_variance: Option<String>,
    /// Pixel window [x0, y0, x1, y1) over which `relmse_region` is measured against the
    /// reference (the part of the image a comparison is about, such as a caustic).
    pub region: Option<[u32; 4]>,
    /// Closed-form radiance every pixel must have (linear RGB, finite).
    pub expect_uniform: Option<[f64; 3]>,
    /// File name (.exr or .png) to save the rendered image under, in the output folder.
    pub save: Option<String>,
    /// Denoise the render (`render::denoised`): `true` for the default filter or a table of
    /// its settings. The reference metrics then measure the denoised image, `relmse_raw` the
    /// render before it, and the case's time includes the features and the filter.
    #[serde(default)]
    pub denoise: super::Denoise,
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
    /// With `max_depth = 1`, the pixels that may be lit (`emitter_footprint`); `Err` says why
    /// it is not known.
    footprint: Option<Result<Vec<bool>, &'static str>>,
}

pub struct Output {
    film: render::Film,
    settings: render::Settings,
    /// Seconds of the render alone.
    seconds: f64,
    denoised: Option<Denoised>,
}

struct Denoised {
    image: Image,
    method: crate::image::denoise::Method,
    halves: bool,
    /// Seconds of the feature buffers and the filter.
    seconds: f64,
}

pub fn synthesize(c: &Config, ctx: &Context) -> Result<Synthesis<Input, Truth>, StageError> {
    let scene = render::load(&ctx.dir.join(&c.scene))?;
    let mut settings = render::Settings::from_scene(&scene);
    settings.seed = ctx.seed;
    settings.progress = ctx.progress;
    let mut found = Findings::default();
    settings.integrator = match c.integrator {
        Some(kind) => kind,
        None => {
            let (kind, why) = render::integrators::choose(&scene);
            found.notes.push(format!("integrator chosen: {why}."));
            kind
        }
    };
    apply_overrides(&mut settings, c.spp, c.max_depth)?;
    settings.photon.count = c.photons.or(settings.photon.count);
    settings.photon.validate().map_err(|e| StageError::Config(format!("photons: {e}")))?;
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
    if let Some([x0, y0, x1, y1]) = c.region {
        let (w, h) = (scene.camera.width, scene.camera.height);
        if !(x0 < x1 && y0 < y1 && x1 <= w && y1 <= h) {
            return Err(StageError::Config(format!(
                "region = [{x0}, {y0}, {x1}, {y1}]: expected a window [x0, y0, x1, y1) with x0 < x1 ≤ {w} and y0 < y1 ≤ {h} (the image)"
            )));
        }
        if c.reference.is_none() {
            return Err(StageError::Config("`region` measures against a `reference`: give one".into()));
        }
    }
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
    if scene.lights.is_empty() {
        found.notes.push(format!(
            "{}: the scene has no light (or only black emitters): the image is black.",
            c.scene
        ));
    }
    let footprint = (settings.max_depth == 1).then(|| {
        render::truth::emitter_footprint(&scene, 8)
            .map(|f| dilate(&f, scene.camera.width as usize))
            .ok_or("the scene has a thin lens; the footprint is traced through a pinhole")
    });
    Ok(Some((Input { scene, settings }, Truth { reference, uniform: c.expect_uniform, footprint }, found)))
}

/// `mask` (row-major, `w` wide) grown by one pixel in each of the eight directions.
fn dilate(mask: &[bool], w: usize) -> Vec<bool> {
    let h = mask.len() / w.max(1);
    let mut out = vec![false; mask.len()];
    for (i, _) in mask.iter().enumerate().filter(|(_, &m)| m) {
        let (x, y) = (i % w, i / w);
        for yy in y.saturating_sub(1)..(y + 2).min(h) {
            for xx in x.saturating_sub(1)..(x + 2).min(w) {
                out[yy * w + xx] = true;
            }
        }
    }
    out
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

pub fn solve(c: &Config, input: &Input) -> Result<Output, StageError> {
    let settings = input.settings.clone();
    if let Some(filter) = &c.denoise.0 {
        let d = render::denoised::render_denoised(&input.scene, &settings, filter)?;
        let denoised = Denoised {
            image: d.output.image,
            method: d.output.method,
            halves: d.output.halves,
            seconds: d.feature_seconds + d.filter_seconds,
        };
        return Ok(Output { film: d.film, settings, seconds: d.render_seconds, denoised: Some(denoised) });
    }
    let t = std::time::Instant::now();
    let film = render::try_render(&input.scene, &settings)?;
    Ok(Output { film, settings, seconds: t.elapsed().as_secs_f64(), denoised: None })
}

pub fn validate(c: &Config, out: &Output, truth: &Truth) -> Findings {
    let (film, settings) = (&out.film, &out.settings);
    let paths = film.mean.width as f64 * film.mean.height as f64 * settings.spp as f64;
    let mut f = Findings::default();
    f.metrics.push(Metric::new("nonfinite_samples", film.dropped_samples as f64, "samples", Better::Lower));
    f.metrics.push(Metric::new("mpaths_per_s", paths / out.seconds.max(1e-9) / 1e6, "M/s", Better::Higher));
    f.notes.push(format!(
        "{}x{} pixels, {} spp, max depth {}, integrator `{}`.",
        film.mean.width, film.mean.height, settings.spp, settings.max_depth, settings.integrator.name
    ));
    // What the metrics measure: the denoised image when there is one.
    let image = out.denoised.as_ref().map_or(&film.mean, |d| &d.image);
    if let Some(d) = &out.denoised {
        let megapixels = film.mean.width as f64 * film.mean.height as f64 / 1e6;
        f.metrics.push(Metric::new(
            "denoise_s_per_megapixel",
            d.seconds / megapixels.max(1e-12),
            "s/MP",
            Better::Lower,
        ));
        f.notes.push(format!(
            "denoised ({}{}) in {:.2} s after a render of {:.2} s; the reference metrics measure the denoised image, relmse_raw the render.",
            d.method,
            if d.halves { ", half buffers cross-filtered" } else { "" },
            d.seconds,
            out.seconds
        ));
    }
    let mut reference_metrics = vec!["mean_rel_err_r", "mean_rel_err_g", "mean_rel_err_b", "rmse", "relmse"];
    if c.region.is_some() {
        reference_metrics.push("relmse_region");
    }
    if c.denoise.0.is_some() {
        reference_metrics.extend(["relmse_raw", "relmse_gain"]);
    }
    match &truth.reference {
        Reference::None => {}
        Reference::Absent(why) => {
            for name in &reference_metrics {
                f.metrics.push(Metric::skipped(name, "", Better::Lower, why.clone()));
            }
            f.metrics.push(Metric::skipped("z_test_pass_fraction", "", Better::Higher, why.clone()));
            f.notes.push(format!("reference {why}: comparison skipped."));
        }
        Reference::Images { path, mean, variance } => {
            match metrics::agreement(image, &film.variance, mean, variance, 0.01) {
                Ok(a) => {
                    for (ch, name) in ["r", "g", "b"].iter().enumerate() {
                        f.metrics.push(Metric::new(
                            &format!("mean_rel_err_{name}"),
                            a.mean_rel_err[ch].abs(),
                            "",
                            Better::Lower,
                        ));
                    }
                    f.metrics.push(Metric::new("rmse", metrics::rmse(image, mean), "", Better::Lower));
                    f.metrics.push(Metric::new(
                        "relmse",
                        metrics::relmse(image, mean, None),
                        "",
                        Better::Lower,
                    ));
                    if let Some(region) = c.region {
                        f.metrics.push(Metric::new(
                            "relmse_region",
                            metrics::relmse(image, mean, Some(region)),
                            "",
                            Better::Lower,
                        ));
                    }
                    if out.denoised.is_some() {
                        let raw = metrics::relmse(&film.mean, mean, None);
                        let gain = raw / metrics::relmse(image, mean, None);
                        f.metrics.push(Metric::new("relmse_raw", raw, "", Better::Lower));
                        let why = "a noiseless image matching the reference exactly: no error to divide by";
                        f.metrics.push(Metric::maybe(
                            "relmse_gain",
                            gain.is_finite().then_some(gain),
                            "×",
                            Better::Higher,
                            why,
                        ));
                        // A filtered pixel is a weighted mean of its neighbours: its error is
                        // no longer the independent noise the z-test assumes.
                        let why = "the denoised image's pixels are correlated: no per-pixel z-test";
                        f.metrics.push(Metric::not_applicable(
                            "z_test_pass_fraction",
                            "",
                            Better::Higher,
                            why,
                        ));
                    } else {
                        let why = "the render is not denoised";
                        f.metrics.push(Metric::not_applicable("relmse_gain", "×", Better::Higher, why));
                        f.metrics.push(Metric::new(
                            "z_test_pass_fraction",
                            a.pass_fraction,
                            "",
                            Better::Higher,
                        ));
                        f.notes.push(format!(
                            "z-test against {}: {} of {} pixel channels beyond |z| = {:.2} (Šidák α = {:.2e}).",
                            clean(path).display(),
                            a.failed,
                            a.tested,
                            a.z_critical,
                            a.alpha_sidak
                        ));
                    }
                }
                Err(e) => {
                    let why = format!("reference {}: {e}", clean(path).display());
                    for name in &reference_metrics {
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
        for px in image.data.chunks_exact(3) {
            for ch in 0..3 {
                let rel = (px[ch] as f64 - e[ch]).abs() / e[ch];
                finite &= rel.is_finite();
                max_rel = max_rel.max(rel);
                sum_rel += rel;
            }
        }
        let why = "the image holds a non-finite pixel";
        let n = image.data.len().max(1) as f64;
        f.metrics.push(Metric::maybe("max_rel_err", finite.then_some(max_rel), "", Better::Lower, why));
        f.metrics.push(Metric::maybe("mean_rel_err", finite.then_some(sum_rel / n), "", Better::Lower, why));
        let sigmas = bias_sigmas(image, &film.variance, e);
        f.metrics.push(Metric::maybe("mean_err_sigmas", sigmas, "σ", Better::Lower, why));
    }
    let lit: Vec<bool> = film.mean.data.chunks_exact(3).map(|px| px.iter().any(|&v| v > 0.0)).collect();
    f.metrics.push(Metric::new(
        "lit_pixels",
        lit.iter().filter(|&&l| l).count() as f64,
        "pixels",
        Better::Higher,
    ));
    match &truth.footprint {
        None => {}
        Some(Err(why)) => {
            f.metrics.push(Metric::missing("lit_pixels_off_emitters", "pixels", Better::Lower, *why))
        }
        Some(Ok(may)) if may.len() != lit.len() => f.metrics.push(Metric::missing(
            "lit_pixels_off_emitters",
            "pixels",
            Better::Lower,
            "the film is a crop of the image",
        )),
        Some(Ok(may)) => {
            let off = lit.iter().zip(may).filter(|&(&l, &m)| l && !m).count();
            f.metrics.push(Metric::new("lit_pixels_off_emitters", off as f64, "pixels", Better::Lower));
        }
    }
    if let Some(name) = &c.save {
        f.files.push((PathBuf::from(name), Kept::Image(image.clone())));
    }
    f
}

/// The largest over channels of |image mean − expected| over the standard error of the image
/// mean, from the render's per-pixel variance of the mean (pixels are independent, so their
/// variances add; a denoiser's weighted means of them keep the image mean's standard error
/// about the same); `None` when the image holds a non-finite value. A noiseless image exactly
/// on the expected value is 0 σ away.
fn bias_sigmas(image: &Image, variance: &Image, expected: [f64; 3]) -> Option<f64> {
    let n = (image.data.len() / 3).max(1) as f64;
    let mut worst = 0.0f64;
    for (ch, e) in expected.iter().enumerate() {
        let sum: f64 = image.data.iter().skip(ch).step_by(3).map(|&v| v as f64).sum();
        let var: f64 = variance.data.iter().skip(ch).step_by(3).map(|&v| v as f64).sum();
        let (diff, se) = ((sum / n - e).abs(), var.sqrt() / n);
        if !(diff.is_finite() && se.is_finite()) {
            return None;
        }
        worst = worst.max(if diff == 0.0 { 0.0 } else { diff / se });
    }
    Some(worst)
}

impl Settings for Config {
    fn headline(&self) -> &'static str {
        if self.reference.is_some() {
            "rmse"
        } else {
            "mean_rel_err"
        }
    }
    fn run(&self, ctx: &Context) -> Result<CaseResult, StageError> {
        run_case(|| synthesize(self, ctx), |i| solve(self, i), |o, t| validate(self, o, t))
    }
}
