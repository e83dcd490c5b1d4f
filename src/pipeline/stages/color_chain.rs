//! The colour stage's chained cases (docs/pipeline.md):
//! - the correction fitted on a chart inside the radiance an earlier hdr case merged
//!   (`image = "from:CASE/radiance"`), alone on the true radiance;
//! - the chart photographed once through the camera of an earlier hdr case's stack and made
//!   linear through the response that case recovered (`response = "from:CASE"`), alone
//!   through the true response. The codes are drawn once; each run only linearises them.
//!
//! What a colour fit inherits is each patch's value off by a little, about 0.1–0.2 % in ln.
//! Little of it is the inherited curve's log–log slope (`chain::LnError`): most lies in the
//! response's wiggles at the patches' own codes and in the merge's noise there. So the
//! sensitivity moves both, one at a time: each channel's slope (on the whole image), and each
//! patch's value in each channel (`patch_ln`), by the patch's own inherited error in ln (its
//! value chained over its value alone) less the slope's line and less the channel's mean, a
//! scale per channel to which the fit (root-polynomial, homogeneous of degree 1) is blind.
//! The prediction carries the patches' leave-one-out colours to first order over all of them.

use super::chain::{run_chained, Chain, LnError, Parameter};
use super::color::{chart_input, chart_signal, load_chart, solve, validate, Chart, Config, Truth};
use super::{run_case, CaseResult, Context, Findings, StageError};
use crate::color;
use crate::image::Image;
use crate::render;
use serde::Deserialize;

/// What a chained colour case reports of what it inherits.
const CHAIN: Chain = Chain {
    headline: "loo_mean_de2000",
    unit: "ΔE00",
    errors: &["loo_mean_de2000", "mean_de2000", "max_de2000", "patch_rgb_rel_err"],
};

/// `Config::perturb`.
#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SlopePerturb {
    pub slope: f64,
}

/// The case and output a `from:CASE/OUTPUT` field names (`OUTPUT` defaults to `radiance`).
pub(super) fn image_source(image: &Option<String>) -> Option<(String, String)> {
    let reference = super::from_case(image)?;
    Some(match reference.rsplit_once('/') {
        Some((case, output)) => (case.to_string(), output.to_string()),
        None => (reference, "radiance".to_string()),
    })
}

/// A colour run's input: the chart sampled in an image, its truth and notes.
struct Sampled {
    input: color::Input,
    truth: Truth,
    notes: Vec<String>,
}

/// The sensitivity's step for a patch's value in ln: 0.1 %, about what a merge or a
/// recovered response leaves on a patch.
const PATCH_STEP: f64 = 1e-3;

/// Runs the colour case on a sampled chart, with patch `k`'s channel `ch` first scaled by
/// e^δ where `moved` = (k, ch, δ) is given.
fn run_sampled(
    c: &Config,
    s: &Sampled,
    moved: Option<(usize, usize, f64)>,
) -> Result<CaseResult, StageError> {
    let mut input = s.input.clone();
    if let Some((k, ch, delta)) = moved {
        input.patches[k].rgb[ch] *= delta.exp();
    }
    run_case(
        || Ok(Some((input, s.truth.clone(), Findings { notes: s.notes.clone(), ..Default::default() }))),
        |i| solve(c, i),
        |o, t| validate(c, o, t),
    )
}

/// The `patch_ln` parameters (module docs), with each one's patch and channel: the patches
/// sampled usable (unflagged, positive) both chained and alone.
fn patch_parameters(
    chained: &color::Input,
    alone: &color::Input,
    slope: [f64; 3],
) -> Vec<(Parameter, usize, usize)> {
    let mut out = Vec::new();
    for ch in 0..3 {
        // Per usable patch: its ln value alone u and its ln error e.
        let ue: Vec<(usize, f64, f64)> = chained
            .patches
            .iter()
            .zip(&alone.patches)
            .enumerate()
            .filter(|(_, (p, a))| p.flag.is_none() && a.flag.is_none() && p.rgb[ch] > 0.0 && a.rgb[ch] > 0.0)
            .map(|(k, (p, a))| (k, a.rgb[ch].ln(), (p.rgb[ch] / a.rgb[ch]).ln()))
            .collect();
        let n = ue.len().max(1) as f64;
        let (mu, me) = ue.iter().fold((0.0, 0.0), |(a, b), (_, u, e)| (a + u / n, b + e / n));
        for &(k, u, e) in &ue {
            let name = format!("{} ({})", alone.patches[k].name, ["R", "G", "B"][ch]);
            let error = e - me - slope[ch] * (u - mu);
            out.push((Parameter { name, error, step: PATCH_STEP, group: Some("patch_ln") }, k, ch));
        }
    }
    out
}

/// A chained colour case (module docs): chained on `chained`, alone on `alone`, the slope
/// parameters of `error` moved by `run_slope(ch, δ)`, the patches' on `alone`'s input.
fn run_colour_chain(
    c: &Config,
    upstream: &str,
    error: &LnError,
    chained: &Sampled,
    alone: &Sampled,
    run_slope: impl Fn(usize, f64) -> Result<CaseResult, StageError>,
) -> Result<CaseResult, StageError> {
    let mut parameters = error.parameters();
    let n = parameters.len();
    let patches: Vec<(usize, usize)> = patch_parameters(&chained.input, &alone.input, error.slope)
        .into_iter()
        .map(|(p, k, ch)| {
            parameters.push(p);
            (k, ch)
        })
        .collect();
    run_chained(
        upstream,
        &CHAIN,
        &parameters,
        || run_sampled(c, chained, None),
        || run_sampled(c, alone, None),
        |k, delta| match k.checked_sub(n) {
            None => run_slope(k, delta),
            Some(i) => run_sampled(c, alone, Some((patches[i].0, patches[i].1, delta))),
        },
    )
}

/// The chart sampled in `image`, a merged radiance of it (module docs).
fn sample_radiance(c: &Config, chart: &Chart, image: &Image, source: &str) -> Result<Sampled, StageError> {
    let (w, h) = (chart.scene.camera.width, chart.scene.camera.height);
    if (image.width, image.height) != (w, h) {
        return Err(StageError::Config(format!(
            "image = \"from:{source}/radiance\": a {}×{} radiance for a {w}×{h} chart image",
            image.width, image.height
        )));
    }
    let corners = chart.corners(&c.scene)?;
    // A merged radiance has no full scale: nothing in it is clipped.
    let (input, pixels) = chart_input(c, chart, image, corners, f64::INFINITY)?;
    let notes = vec![format!(
        "{} under {}, camera {}: the chart sampled in the radiance case `{source}` merged; reference {}.",
        c.scene, c.illuminant, c.camera, c.reference
    )];
    Ok(Sampled { input, truth: Truth { rgb: chart.patch_rgb(), pixel_variance: None, pixels }, notes })
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
    refuse_given(
        &field,
        &[
            ("exposure", c.exposure.is_some()),
            ("bits", c.bits.is_some()),
            ("read_noise", c.read_noise.is_some()),
            ("full_well", c.full_well.is_some()),
            ("spp", c.spp.is_some()),
            ("denoise", c.denoise.0.is_some()),
            ("save_image", c.save_image),
        ],
        "a chained colour case fits the merged radiance, which renders and exposes nothing of its own",
    )?;
    let mut r =
        handed_on(ctx.upstream.get(source).and_then(|e| e.radiance.clone()), &field, source, "radiance")?;
    if let Some(p) = c.perturb {
        let s = check_perturb(p)?;
        for v in &mut r.estimate.data {
            *v = v.max(0.0).powf(1.0 + s as f32);
        }
        r.error.raised(s);
    }
    let here = super::render::clean(&ctx.dir.join(&c.scene));
    let same_chart =
        r.spectral.as_ref().is_some_and(|sp| sp.camera == c.camera && sp.illuminant == c.illuminant);
    if r.look_at != c.look_at {
        return Err(StageError::Config(format!(
            "{field}: that case saw the chart from {}, this case from {}: a chained colour case must look at the chart its source merged from the same pose",
            r.look_at.as_ref().map_or("the scene's camera".into(), |l| format!("look_at {l:?}")),
            c.look_at.as_ref().map_or("the scene's camera".into(), |l| format!("look_at {l:?}")),
        )));
    }
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
    let chart = load_chart(&c.scene, c.look_at.as_ref(), &c.camera, &c.illuminant, ctx)?;
    let chained = sample_radiance(c, &chart, &r.estimate, source)?;
    let alone = sample_radiance(c, &chart, &r.truth, source)?;
    run_colour_chain(
        c,
        &format!(
            "Chained: the radiance merged by case `{source}` is off the truth in ln by {}; inherited:",
            r.error.describe()
        ),
        &r.error,
        &chained,
        &alone,
        |ch, delta| {
            // The true radiance with one channel's slope moved: raised to the power 1 + δ.
            let mut moved = r.truth.clone();
            for v in moved.data.iter_mut().skip(ch).step_by(3) {
                *v = v.max(0.0).powf(1.0 + delta as f32);
            }
            run_sampled(c, &sample_radiance(c, &chart, &moved, source)?, None)
        },
    )
}

/// A chained case on a recovered response (`response = "from:CASE"`, module docs).
pub(super) fn run_response(c: &Config, ctx: &Context, source: &str) -> Result<CaseResult, StageError> {
    let field = format!("response = \"from:{source}\"");
    refuse_given(
        &field,
        &[
            ("image", c.image.is_some()),
            ("bits", c.bits.is_some()),
            ("read_noise", c.read_noise.is_some()),
            ("full_well", c.full_well.is_some()),
            ("save_image", c.save_image),
        ],
        "a case on an inherited response photographs through its source's camera, whose sensor that case describes",
    )?;
    let mut r =
        handed_on(ctx.upstream.get(source).and_then(|e| e.response.clone()), &field, source, "response")?;
    if let Some(p) = c.perturb {
        let s = check_perturb(p)?;
        for g in &mut r.g {
            g.iter_mut().for_each(|v| *v *= 1.0 + s);
        }
        r.error.raised(s);
    }
    let t = std::time::Instant::now();
    let mut chart = load_chart(&c.scene, c.look_at.as_ref(), &c.camera, &c.illuminant, ctx)?;
    let mut sensor = r.sensor;
    let scene_exposure = chart.scene.sensor.clone().unwrap_or_default().exposure;
    sensor.exposure = c.exposure.unwrap_or(scene_exposure);
    sensor.validate()?;
    let levels = sensor.max_code() as usize + 1;
    if r.g.len() != 3 || r.g.iter().any(|g| g.len() != levels) {
        return Err(StageError::Config(format!("{field}: the response has no 3 × {levels} values")));
    }
    // The chart, photographed once.
    let Some(signal) = chart_signal(&mut chart, c.spp, &c.denoise, ctx)? else {
        return Err(StageError::Config("the case's renders were asked for, but none came back".into()));
    };
    let codes = sensor.expose(&signal.image, render::sampler::mix64(ctx.seed ^ 0xc0_10e5));
    let render_s = t.elapsed().as_secs_f64();
    let corners = chart.corners(&c.scene)?;
    let truth_rgb: Vec<[f64; 3]> = chart.patch_rgb().iter().map(|t| t.map(|v| v * sensor.exposure)).collect();
    let max = sensor.max_code() as f64;
    let g_true: Vec<Vec<f64>> = (0..3)
        .map(|ch| {
            (0..levels)
                .map(|z| sensor.response.inverse_channel(ch, z as f64 / max).max(1e-300).ln())
                .collect()
        })
        .collect();
    let (w, h) = (signal.image.width, signal.image.height);
    // The chart sampled in the codes made linear through `g` (ln exposure per channel and
    // code), each channel scaled so its top code is 1 (a scale the fit is blind to), so the
    // top code is where a patch is clipped.
    let sample = |g: &[Vec<f64>]| -> Result<Sampled, StageError> {
        let data = codes
            .iter()
            .enumerate()
            .map(|(k, &z)| (g[k % 3][z as usize] - g[k % 3][levels - 1]).exp() as f32)
            .collect();
        let image = Image { width: w, height: h, channels: 3, data };
        let (input, pixels) = chart_input(c, &chart, &image, corners, 1.0)?;
        let notes = vec![format!(
            "{} under {}, camera {}, {} spp: one exposure of {} through the sensor of case `{source}` ({} bits, response {:?}), made linear through a response.",
            c.scene, c.illuminant, c.camera, signal.spp, sensor.exposure, sensor.bits, sensor.response
        )];
        Ok(Sampled { input, truth: Truth { rgb: truth_rgb.clone(), pixel_variance: None, pixels }, notes })
    };
    let mut result = run_colour_chain(
        c,
        &format!(
            "Chained: the response recovered by case `{source}` is off the truth (g against the true g) by {}; inherited:",
            r.error.describe()
        ),
        &r.error,
        &sample(&r.g)?,
        &sample(&g_true)?,
        |ch, delta| {
            // The true g with one channel's slope moved.
            let mut moved = g_true.clone();
            moved[ch].iter_mut().for_each(|v| *v *= 1.0 + delta);
            run_sampled(c, &sample(&moved)?, None)
        },
    )?;
    *result.timings_s.entry("render".into()).or_insert(0.0) += render_s;
    Ok(result)
}

/// Refuses the first setting of `given` (its name, and whether the entry gives it) that the
/// entry gives beside `field`, saying `why`.
fn refuse_given(field: &str, given: &[(&str, bool)], why: &str) -> Result<(), StageError> {
    match given.iter().find(|(_, g)| *g) {
        Some((name, _)) => Err(StageError::Config(format!("{field} and {name}: {why}"))),
        None => Ok(()),
    }
}

/// What the source case `source` handed on of `kind`, or the refusal naming it.
fn handed_on<T>(output: Option<T>, field: &str, source: &str, kind: &str) -> Result<T, StageError> {
    output.ok_or_else(|| {
        StageError::Config(format!(
            "{field}: case `{source}` handed on no {kind} (it failed or ended in a declared error)"
        ))
    })
}

/// A `perturb`'s slope, checked.
fn check_perturb(p: SlopePerturb) -> Result<f64, StageError> {
    if p.slope.is_finite() && p.slope.abs() < 0.5 {
        Ok(p.slope)
    } else {
        Err(StageError::Config(format!("perturb = {{ slope = {} }}: expected |slope| < 0.5", p.slope)))
    }
}
