//! Chained cases (docs/pipeline.md): a case that names an earlier one (`camera =
//! "from:CASE"`) is given that case's output, never its truth. It also runs alone (upstream
//! from truth), and the report shows both and the error it inherits, with the sensitivity
//! that predicts it: the case run again with the true upstream moved by the inherited error
//! in one parameter at a time (or by a step, when that error is smaller).
//!
//! The headline error's secant slope per parameter is reported. The prediction is made one
//! level down, where the stage gives its errors item by item (`Linear`: per pixel, per pair of
//! images): each item's error components ε are carried to first order,
//! ε ≈ ε_alone + Σ_i (ε_i − ε_alone)·e_i/δ_i for the inherited errors e_i and steps δ_i, and
//! the headline is computed from them. A headline error is a norm, and norms of errors that
//! partly cancel (a focal length too long, a principal point shifted back) do not add; their
//! components do. Where a stage gives no items, the prediction is Σ_i slope_i·e_i. Either is
//! first order, and meaningful where the inherited error is above the stage's own noise.

use super::{CaseResult, Context, StageError};
use crate::math::CameraModel;
use crate::pipeline::metric::{Better, Metric};
use serde::Deserialize;

/// What a case hands on to the later cases that name it (`from:CASE`): its estimate, and the
/// truth beside it, so the later case can say how far off what it inherits is.
#[derive(Clone, Debug, Default)]
pub struct Exports {
    /// `camera`: the calibrated camera, and the true one.
    pub camera: Option<(CameraModel, CameraModel)>,
    /// `radiance`: an hdr case's merged radiance.
    pub radiance: Option<Radiance>,
    /// `response`: an hdr case's recovered response.
    pub response: Option<InheritedResponse>,
}

/// An hdr case's recovered response, with the sensor that made its stack (the camera a later
/// case photographs through).
#[derive(Clone, Debug)]
pub struct InheritedResponse {
    /// Per channel and code value, the recovered ln exposure g(z) (its offset arbitrary).
    pub g: Vec<Vec<f64>>,
    pub sensor: crate::render::sensor::Sensor,
    /// The error of g against the true g.
    pub error: LnError,
}

/// An error e(u) in ln exposure against the true ln exposure u (a recovered response's or a
/// merged radiance's), per channel, as its least-squares line e ≈ a + slope·(u − c) about the
/// middle c of the range it was measured on; the offset a is free (a scale), the slope is the
/// log–log slope less 1. (Bend and twist terms were tried too: they explain no more of the
/// error a colour fit inherits, which sits in the curve's wiggles at the patches' own values;
/// `color_chain` moves each patch for those.)
#[derive(Clone, Debug, Default)]
pub struct LnError {
    pub centre: [f64; 3],
    pub slope: [f64; 3],
}

/// The sensitivity's step: a slope of 2 %.
const SLOPE_STEP: f64 = 0.02;

impl LnError {
    /// Fits each channel's (u, e) pairs; a channel with fewer than 2 pairs or no spread in u
    /// keeps a slope of 0.
    pub fn fit(pairs: [Vec<(f64, f64)>; 3]) -> LnError {
        let mut out = LnError::default();
        for (ch, p) in pairs.iter().enumerate() {
            let n = p.len() as f64;
            let (mu, me) = p.iter().fold((0.0, 0.0), |(a, b), (u, e)| (a + u / n, b + e / n));
            let (sue, suu) =
                p.iter().fold((0.0, 0.0), |(a, b), (u, e)| (a + (u - mu) * (e - me), b + (u - mu).powi(2)));
            if p.len() >= 2 && suu > 0.0 {
                out.centre[ch] = mu;
                out.slope[ch] = sue / suu;
            }
        }
        out
    }

    /// The sensitivity's parameters, one per channel.
    pub fn parameters(&self) -> Vec<Parameter> {
        ["slope_r", "slope_g", "slope_b"]
            .iter()
            .zip(self.slope)
            .map(|(name, error)| Parameter { name: name.to_string(), error, step: SLOPE_STEP, group: None })
            .collect()
    }

    /// After the estimate is raised to the power 1 + `s` (ln scaled by 1 + s): u + e becomes
    /// (1 + s)(u + e), so the slope becomes (1 + s)(1 + slope) − 1.
    pub fn raised(&mut self, s: f64) {
        self.slope = self.slope.map(|k| (1.0 + s) * (1.0 + k) - 1.0);
    }

    /// The slopes as a note.
    pub fn describe(&self) -> String {
        let [r, g, b] = self.slope;
        format!("slope {r:+.5} (R), {g:+.5} (G), {b:+.5} (B)")
    }
}

/// An hdr case's merged radiance and what a later case checks and predicts with.
#[derive(Clone, Debug)]
pub struct Radiance {
    /// The merged radiance (an arbitrary scale per channel) and the true radiance.
    pub estimate: crate::image::Image,
    pub truth: crate::image::Image,
    /// The scene file, resolved, and for a chart's camera signal its camera and illuminant.
    pub scene: std::path::PathBuf,
    pub spectral: Option<super::hdr::Spectral>,
    /// The camera's pose given by the case (`look_at`), when not the scene's own.
    pub look_at: Option<crate::render::scene::LookAt>,
    /// The estimate's error in ln radiance against the truth's ln radiance.
    pub error: LnError,
}

/// A run's errors item by item (module docs): per item (a pixel, a pair of images) by its key,
/// the components of its error, which move smoothly with the inherited camera; and the
/// headline error computed from such items.
#[derive(Clone, Debug)]
pub struct Linear {
    pub items: std::collections::BTreeMap<u64, Vec<f64>>,
    pub headline: fn(&mut dyn Iterator<Item = &[f64]>) -> Option<f64>,
}

/// The first-order prediction of the headline from the alone run's items and each moved
/// run's, with its weight e_i/δ_i, over the items every run has; and the alone run's headline
/// over the same items.
fn predict(alone: &Linear, moved: &[(&Linear, f64)]) -> Option<(f64, f64)> {
    let mut base = Vec::new();
    let mut predicted = Vec::new();
    'items: for (key, a) in &alone.items {
        let mut p = a.clone();
        for (run, weight) in moved {
            let Some(v) = run.items.get(key).filter(|v| v.len() == a.len()) else {
                continue 'items;
            };
            for ((p, v), a) in p.iter_mut().zip(v).zip(a) {
                *p += (v - a) * weight;
            }
        }
        base.push(a.as_slice());
        predicted.push(p);
    }
    let alone_value = (alone.headline)(&mut base.into_iter())?;
    let predicted_value = (alone.headline)(&mut predicted.iter().map(Vec::as_slice))?;
    Some((predicted_value, alone_value))
}

/// A field's `from:CASE`, the case it names; `None` for any other value.
pub fn from_case(value: &Option<String>) -> Option<String> {
    value.as_deref().and_then(|v| v.strip_prefix("from:")).map(str::to_string)
}

/// A chained case's `perturb`: a deliberate error added to the inherited camera, its focal
/// lengths scaled by 1 + `focal_rel` and `k1` added to its k1 (default none).
#[derive(Clone, Copy, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Perturb {
    #[serde(default)]
    pub focal_rel: f64,
    #[serde(default)]
    pub k1: f64,
}

/// `camera` with its focal lengths scaled by 1 + `focal_rel` and `k1` added.
fn perturbed(camera: CameraModel, focal_rel: f64, k1: f64) -> CameraModel {
    let mut c = camera;
    c.intrinsics.fx *= 1.0 + focal_rel;
    c.intrinsics.fy *= 1.0 + focal_rel;
    c.distortion.k1 += k1;
    c
}

/// How far a camera (first) is off the true one (second) in one parameter.
type Off = fn(&CameraModel, &CameraModel) -> f64;

/// The camera parameters the sensitivity moves, one at a time: name, the step when the
/// inherited error is smaller (0.1 % of a focal length, a quarter pixel of the principal
/// point, 0.01 of k1 and k2), and how far a camera is off the truth in it.
const PARAMETERS: [(&str, f64, Off); 6] = [
    ("fx_rel", 1e-3, |e, t| (e.intrinsics.fx - t.intrinsics.fx) / t.intrinsics.fx),
    ("fy_rel", 1e-3, |e, t| (e.intrinsics.fy - t.intrinsics.fy) / t.intrinsics.fy),
    ("cx_px", 0.25, |e, t| e.intrinsics.cx - t.intrinsics.cx),
    ("cy_px", 0.25, |e, t| e.intrinsics.cy - t.intrinsics.cy),
    ("k1", 1e-2, |e, t| e.distortion.k1 - t.distortion.k1),
    ("k2", 1e-2, |e, t| e.distortion.k2 - t.distortion.k2),
];

/// `truth` with PARAMETERS[k] moved by `delta`.
fn moved(truth: CameraModel, k: usize, delta: f64) -> CameraModel {
    let mut c = truth;
    match k {
        0 => c.intrinsics.fx *= 1.0 + delta,
        1 => c.intrinsics.fy *= 1.0 + delta,
        2 => c.intrinsics.cx += delta,
        3 => c.intrinsics.cy += delta,
        4 => c.distortion.k1 += delta,
        _ => c.distortion.k2 += delta,
    }
    c
}

/// A case's camera as its `camera` and `perturb` fields give it: `None` for the scene's true
/// camera (no `camera`), else the source case's name, its estimate (moved by `perturb`) and
/// the true camera beside it. Refused by name: a `camera` that is not `from:CASE`, `perturb`
/// without it, a source that handed on no camera, a perturbation out of range.
pub fn inherited_camera(
    camera: &Option<String>,
    perturb: Option<Perturb>,
    ctx: &Context,
) -> Result<Option<(String, CameraModel, CameraModel)>, StageError> {
    let Some(source) = from_case(camera) else {
        if let Some(v) = camera {
            return Err(StageError::Config(format!(
                "camera = \"{v}\": expected \"from:CASE\", a calibrate case earlier in the file (a rendered case's true camera is its scene's)"
            )));
        }
        if perturb.is_some() {
            return Err(StageError::Config(
                "perturb: only on a chained case (camera = \"from:CASE\"), whose inherited camera it moves"
                    .into(),
            ));
        }
        return Ok(None);
    };
    let Some((estimate, truth)) = ctx.upstream.get(&source).and_then(|e| e.camera) else {
        return Err(StageError::Config(format!(
            "camera = \"from:{source}\": case `{source}` handed on no camera (it failed or ended in a declared error)"
        )));
    };
    let estimate = match perturb {
        None => estimate,
        Some(p)
            if p.focal_rel.is_finite() && p.k1.is_finite() && p.focal_rel.abs() < 0.5 && p.k1.abs() < 1.0 =>
        {
            perturbed(estimate, p.focal_rel, p.k1)
        }
        Some(p) => {
            return Err(StageError::Config(format!(
                "perturb = {{ focal_rel = {}, k1 = {} }}: expected |focal_rel| < 0.5 and |k1| < 1",
                p.focal_rel, p.k1
            )))
        }
    };
    Ok(Some((source, estimate, truth)))
}

/// The one check of a chained case's scene: it must see through the camera its source
/// calibrated (`field` is the case's `camera` value, for the message).
pub fn check_same_camera(
    field: &str,
    upstream_truth: &CameraModel,
    camera: &CameraModel,
) -> Result<(), StageError> {
    if upstream_truth == camera {
        return Ok(());
    }
    let (u, c) = (upstream_truth, camera);
    Err(StageError::Config(format!(
        "camera = \"{field}\": that case calibrated a camera of {}×{} px, fx {}, k1 {}; this scene's is {}×{} px, fx {}, k1 {}: a chained case must see through the camera its source calibrated",
        u.width, u.height, u.intrinsics.fx, u.distortion.k1, c.width, c.height, c.intrinsics.fx, c.distortion.k1
    )))
}

/// What a chained case reports besides its runs.
pub struct Chain<'a> {
    /// The headline error the sensitivity is of, and its unit.
    pub headline: &'a str,
    pub unit: &'a str,
    /// The errors whose inherited part is reported.
    pub errors: &'a [&'a str],
}

/// One inherited quantity the sensitivity moves: its name, how far the inherited value is off
/// the truth in it, and the step when that is smaller. Parameters of one `group` (many alike,
/// such as each patch's value) are reported together: the RMS of their slopes, and the
/// largest of their contributions in the note.
pub struct Parameter {
    pub name: String,
    pub error: f64,
    pub step: f64,
    pub group: Option<&'static str>,
}

/// A case with a `camera` field and `perturb`: run on the scene's true camera when the field
/// names no source (`run_given(None)`), else chained on the source's camera (`run_chained`),
/// its parameters those `PARAMETERS` names, each moved on the true camera. `run_given` is
/// given the camera to use and the true one.
pub fn run_on_camera(
    camera: &Option<String>,
    perturb: Option<Perturb>,
    ctx: &Context,
    chain: &Chain,
    run_given: impl Fn(Option<(CameraModel, CameraModel)>) -> Result<CaseResult, StageError>,
) -> Result<CaseResult, StageError> {
    let Some((source, estimate, truth)) = inherited_camera(camera, perturb, ctx)? else {
        return run_given(None);
    };
    let parameters: Vec<Parameter> = PARAMETERS
        .iter()
        .map(|(name, step, off)| Parameter {
            name: name.to_string(),
            error: off(&estimate, &truth),
            step: *step,
            group: None,
        })
        .collect();
    run_chained(
        &camera_error(&source, &estimate, &truth),
        chain,
        &parameters,
        || run_given(Some((estimate, truth))),
        || run_given(Some((truth, truth))),
        |k, delta| run_given(Some((moved(truth, k, delta), truth))),
    )
}

/// The `upstream` of a case with a `camera` field: the case its `from:CASE` names.
pub fn camera_upstream(camera: &Option<String>) -> Vec<(&'static str, String, &'static str)> {
    from_case(camera).map(|s| vec![("camera", s, "camera")]).unwrap_or_default()
}

/// A chained case run chained (`run_estimate`), alone (`run_truth`) and once per inherited
/// parameter, moved on the truth (`run_moved(k, δ)`), for the sensitivity of the headline
/// error (module docs): the chained metrics, `alone_…`, `inherited_…`,
/// `sensitivity_<headline>_per_<parameter>` and `predicted_inherited_<headline>`. `upstream`
/// (what was inherited and how far off it is) starts the note.
pub fn run_chained(
    upstream: &str,
    chain: &Chain,
    parameters: &[Parameter],
    run_estimate: impl FnOnce() -> Result<CaseResult, StageError>,
    run_truth: impl FnOnce() -> Result<CaseResult, StageError>,
    run_moved: impl Fn(usize, f64) -> Result<CaseResult, StageError>,
) -> Result<CaseResult, StageError> {
    let headline = chain.headline;
    let chained = run_estimate()?;
    let alone = run_truth()?;
    let value = |r: &CaseResult| r.metrics.iter().find(|m| m.name == headline).and_then(|m| m.value);
    let (mut sensitivity, mut linear) = (Vec::new(), Vec::new());
    for (k, p) in parameters.iter().enumerate() {
        let delta = if p.error.abs() > p.step { p.error } else { p.step.copysign(p.error) };
        let run = run_moved(k, delta)?;
        let slope = match (value(&run), value(&alone)) {
            (Some(e), Some(a)) => Some((e - a) / delta),
            _ => None,
        };
        sensitivity.push((p, slope));
        linear.push(run.linear.map(|l| (l, p.error / delta)));
    }
    // Item by item where every run gave its items, else from the slopes.
    let runs: Option<Vec<(&Linear, f64)>> = linear.iter().map(|r| r.as_ref().map(|(l, w)| (l, *w))).collect();
    let by_items = match (&alone.linear, runs) {
        (Some(a), Some(runs)) => predict(a, &runs).map(|(p, a)| p - a),
        _ => None,
    };
    let mut result = chained_result(chained, alone, chain.errors, upstream);
    let unit = chain.unit;
    let per = format!("{unit} per unit");
    let from_slopes = sensitivity.iter().try_fold(0.0, |sum, (p, slope)| slope.map(|s| sum + s * p.error));
    let mut said = Vec::new();
    for (p, slope) in sensitivity.iter().filter(|(p, _)| p.group.is_none()) {
        let metric = format!("sensitivity_{headline}_per_{}", p.name);
        result.metrics.push(match slope {
            Some(s) => Metric::new(&metric, *s, &per, Better::Lower),
            None => Metric::missing(&metric, &per, Better::Lower, format!("no {headline} to compare")),
        });
        said.push(format!(
            "{} {unit} per unit of {n} (inherited {n} {e:+.5})",
            slope.map_or("—".into(), |s| format!("{s:.4}")),
            n = p.name,
            e = p.error
        ));
    }
    let mut groups: Vec<&str> = Vec::new();
    for g in sensitivity.iter().filter_map(|(p, _)| p.group) {
        if !groups.contains(&g) {
            groups.push(g);
        }
    }
    for group in groups {
        let members: Vec<(&Parameter, f64)> = sensitivity
            .iter()
            .filter(|(p, _)| p.group == Some(group))
            .filter_map(|(p, s)| s.map(|s| (*p, s)))
            .collect();
        let n = members.len().max(1) as f64;
        let rms = |f: &dyn Fn(&(&Parameter, f64)) -> f64| {
            (members.iter().map(|m| f(m).powi(2)).sum::<f64>() / n).sqrt()
        };
        let metric = format!("sensitivity_{headline}_per_{group}_rms");
        result.metrics.push(Metric::maybe(
            &metric,
            (!members.is_empty()).then(|| rms(&|m| m.1)),
            &per,
            Better::Lower,
            &format!("no {headline} to compare"),
        ));
        let mut largest = members.clone();
        largest.sort_by(|a, b| (b.1 * b.0.error).abs().total_cmp(&(a.1 * a.0.error).abs()));
        said.push(format!(
            "{} {unit} per unit of {group} as RMS over its {} parameters (their inherited values RMS {:.5}; together {:+.5} {unit}, most from {})",
            if members.is_empty() { "—".into() } else { format!("{:.4}", rms(&|m| m.1)) },
            members.len(),
            rms(&|m| m.0.error),
            members.iter().map(|(p, s)| s * p.error).sum::<f64>(),
            largest.iter().take(3).map(|(p, s)| format!("{} {:+.5}", p.name, s * p.error)).collect::<Vec<_>>().join(", ")
        ));
    }
    let predicted = by_items.or(from_slopes);
    result.metrics.push(Metric::maybe(
        &format!("predicted_inherited_{headline}"),
        predicted,
        unit,
        Better::Lower,
        "no sensitivity",
    ));
    result.notes.push(format!(
        "Sensitivity of {headline}: {}; predicted inherited {} ({}).",
        said.join(", "),
        predicted.map_or("—".into(), |p| format!("{p:+.6} {unit}")),
        if by_items.is_some() {
            "its errors carried item by item to first order"
        } else {
            "the slopes times the inherited errors"
        }
    ));
    Ok(result)
}

/// A chained case's result: the chained run's metrics under their names, the alone run's as
/// `alone_<name>`, and for each of the `errors` both runs measured the error inherited,
/// `inherited_<name>` = chained − alone; `upstream` (what was inherited) and the inherited
/// errors as a note; the two runs' times added.
pub fn chained_result(chained: CaseResult, alone: CaseResult, errors: &[&str], upstream: &str) -> CaseResult {
    let mut metrics = chained.metrics.clone();
    for a in &alone.metrics {
        metrics.push(Metric { name: format!("alone_{}", a.name), ..a.clone() });
    }
    let mut lines = Vec::new();
    for name in errors {
        let value = |r: &CaseResult| r.metrics.iter().find(|m| m.name == *name).and_then(|m| m.value);
        let metric = chained.metrics.iter().find(|m| m.name == *name);
        if let (Some(cv), Some(av), Some(m)) = (value(&chained), value(&alone), metric) {
            metrics.push(Metric::new(&format!("inherited_{name}"), cv - av, &m.unit, m.better));
            lines.push(format!("{name} {av:.6} alone, {cv:.6} chained ({:+.6} inherited)", cv - av));
        }
    }
    let mut notes = vec![format!("{upstream} {}.", lines.join("; "))];
    notes.extend(chained.notes);
    let mut timings_s = chained.timings_s;
    for (k, v) in alone.timings_s {
        *timings_s.entry(k).or_insert(0.0) += v;
    }
    let mut files = chained.files;
    files.extend(alone.files);
    CaseResult { metrics, notes, timings_s, files, exports: chained.exports, linear: None }
}

/// What an inherited camera is off by, for a chained case's notes.
pub fn camera_error(source: &str, estimate: &CameraModel, truth: &CameraModel) -> String {
    let (e, t) = (&estimate.intrinsics, &truth.intrinsics);
    let (ed, td) = (estimate.distortion.to_array(), truth.distortion.to_array());
    format!(
        "Chained: the camera from case `{source}` is off the truth by fx {:+.4} %, fy {:+.4} %, cx {:+.3} px, cy {:+.3} px, k1 {:+.5}, k2 {:+.5}; inherited:",
        100.0 * (e.fx - t.fx) / t.fx,
        100.0 * (e.fy - t.fy) / t.fy,
        e.cx - t.cx,
        e.cy - t.cy,
        ed[0] - td[0],
        ed[1] - td[1]
    )
}
