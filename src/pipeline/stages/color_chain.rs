//! The colour stage's chained cases (docs/pipeline.md): the correction fitted on a chart
//! inside the radiance an earlier hdr case merged (`image = "from:CASE/radiance"`), alone on
//! the true radiance, with the sensitivity to each channel's log–log slope (`chain`).

use super::color::{chart_input, load_chart, solve, validate, Config, Truth};
use super::{run_case, CaseResult, Context, Findings, StageError, Synthesis};
use crate::color;
use crate::image::Image;
use serde::Deserialize;

/// `Config::perturb`.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SlopePerturb {
    pub slope: f64,
}

/// The steps of the sensitivity to a merged radiance's log–log slope per channel.
const STEP_SLOPE: f64 = 0.02;

/// The case and output a `from:CASE/OUTPUT` field names (`OUTPUT` defaults to `radiance`).
pub(super) fn image_source(image: &Option<String>) -> Option<(String, String)> {
    let reference = super::from_case(image)?;
    Some(match reference.rsplit_once('/') {
        Some((case, output)) => (case.to_string(), output.to_string()),
        None => (reference, "radiance".to_string()),
    })
}

/// A chained case's input: the chart sampled in `image`, a merged radiance of it (module docs).
fn synthesize_radiance(
    c: &Config,
    ctx: &Context,
    image: &Image,
    source: &str,
) -> Result<Synthesis<color::Input, Truth>, StageError> {
    let chart = load_chart(&c.scene, &c.camera, &c.illuminant, ctx)?;
    let (w, h) = (chart.scene.camera.width, chart.scene.camera.height);
    if (image.width, image.height) != (w, h) {
        return Err(StageError::Config(format!(
            "image = \"from:{source}/radiance\": a {}×{} radiance for a {w}×{h} chart image",
            image.width, image.height
        )));
    }
    let corners = chart.corners(&c.scene)?;
    // A merged radiance has no full scale: nothing in it is clipped.
    let (input, pixels) = chart_input(c, &chart, image, corners, f64::INFINITY)?;
    let notes = vec![format!(
        "{} under {}, camera {}: the chart sampled in the radiance case `{source}` merged; reference {}.",
        c.scene, c.illuminant, c.camera, c.reference
    )];
    let truth = Truth { rgb: chart.patch_rgb(), pixel_variance: None, pixels };
    Ok(Some((input, truth, Findings { notes, ..Default::default() })))
}

/// Raises an RGB image's channel `channel` (every channel for `None`) to the power 1 + `s`.
fn raise(image: &mut Image, channel: Option<usize>, s: f64) {
    for (k, v) in image.data.iter_mut().enumerate() {
        if channel.is_none_or(|c| k % 3 == c) {
            *v = v.max(0.0).powf(1.0 + s as f32);
        }
    }
}

/// A chained case on a merged radiance (`image = "from:CASE/radiance"`, module docs).
pub(super) fn run_radiance(
    c: &Config,
    ctx: &Context,
    source: &str,
    output: &str,
) -> Result<CaseResult, StageError> {
    let field = format!("image = \"from:{source}/{output}\"");
    if output != "radiance" {
        return Err(StageError::Config(format!("{field}: expected from:CASE/radiance")));
    }
    let sensor_settings = [
        ("exposure", c.exposure.is_some()),
        ("bits", c.bits.is_some()),
        ("read_noise", c.read_noise.is_some()),
        ("full_well", c.full_well.is_some()),
        ("spp", c.spp.is_some()),
        ("denoise", c.denoise.0.is_some()),
        ("save_image", c.save_image),
    ];
    if let Some((name, _)) = sensor_settings.iter().find(|(_, given)| *given) {
        return Err(StageError::Config(format!(
            "{field} and {name}: a chained colour case fits the merged radiance, which renders and exposes nothing of its own"
        )));
    }
    let Some(mut r) = ctx.upstream.get(source).and_then(|e| e.radiance.clone()) else {
        return Err(StageError::Config(format!(
            "{field}: case `{source}` handed on no radiance (it failed or ended in a declared error)"
        )));
    };
    if let Some(p) = c.perturb {
        if !(p.slope.is_finite() && p.slope.abs() < 0.5) {
            return Err(StageError::Config(format!(
                "perturb = {{ slope = {} }}: expected |slope| < 0.5",
                p.slope
            )));
        }
        raise(&mut r.estimate, None, p.slope);
        // (x^a)^(1+s) against x: the slope a(1 + s).
        r.slope_err = r.slope_err.map(|e| (1.0 + e) * (1.0 + p.slope) - 1.0);
    }
    let here = super::render::clean(&ctx.dir.join(&c.scene));
    let same_chart =
        r.spectral.as_ref().is_some_and(|sp| sp.camera == c.camera && sp.illuminant == c.illuminant);
    if r.scene != here || !same_chart {
        return Err(StageError::Config(format!(
            "{field}: that case merged {} ({}); this case's chart is {} ({} under {}): a chained colour case must fit the chart its source merged",
            r.scene.display(),
            r.spectral.as_ref().map_or("RGB radiance, not spectral".into(), |sp| format!("{} under {}", sp.camera, sp.illuminant)),
            here.display(),
            c.camera,
            c.illuminant
        )));
    }
    let run_on = |image: &Image| {
        run_case(|| synthesize_radiance(c, ctx, image, source), |i| solve(c, i), |o, t| validate(c, o, t))
    };
    let parameters: Vec<super::chain::Parameter> = ["slope_r", "slope_g", "slope_b"]
        .iter()
        .zip(r.slope_err)
        .map(|(name, error)| super::chain::Parameter { name, error, step: STEP_SLOPE })
        .collect();
    let chain = super::chain::Chain {
        upstream: format!(
            "Chained: the radiance merged by case `{source}` is off the truth in log–log slope by {:+.5} (R), {:+.5} (G), {:+.5} (B); inherited:",
            r.slope_err[0], r.slope_err[1], r.slope_err[2]
        ),
        headline: "loo_mean_de2000",
        unit: "ΔE00",
        errors: &["loo_mean_de2000", "mean_de2000", "max_de2000", "patch_rgb_rel_err"],
    };
    super::chain::run_chained(
        &chain,
        &parameters,
        || run_on(&r.estimate),
        || run_on(&r.truth),
        |k, delta| {
            let mut moved = r.truth.clone();
            raise(&mut moved, Some(k), delta);
            run_on(&moved)
        },
    )
}
