//! The `hdr` stage: renders an HDR scene once as linear radiance (the truth), exposes it into
//! a stack through the sensor model with a camera response curve, and runs `hdr::run`, the
//! function `lumen hdr` calls.
//!
//! Frame k (0-based) has the exposure time t_k = 2^(−k·stop_step) (longest first, 1 s), and
//! its codes are the sensor's `expose` of the radiance with exposure × t_k, each frame with its
//! own noise seed. The render goes through the render cache; the stack, cheap, does not.
//!
//! Truth: the radiance, and the response's inverse: the code z of a `bits`-bit sensor is
//! reached at the exposure f⁻¹(z/(2^bits − 1)) (fraction of full scale), so the true
//! g(z) = ln f⁻¹(z/(2^bits − 1)) up to the offset every recovery is free to choose.
//!
//! Metrics:
//! - `response_err_ln`: the largest |g − g_true − offset| over the values that occur in the
//!   stack (offset: the mean difference), channels included, among the values a single
//!   observation pins down: those whose noise in ln exposure, σ = √(σ_q² + σ_e²), is below
//!   0.1, with σ_q = (bin width in ln exposure)/√12 for the fit's bins (1 code up to 1024
//!   levels, 2^(bits−10) codes above) and σ_e = √(e + σ_r²)/e for e electrons of photon noise
//!   and σ_r of read noise. Below that a fit regresses towards the scene's own distribution
//!   of exposures (an error of order σ² times the slope of its log density, Fuller 1987's
//!   errors in variables) rather than towards f⁻¹; the values in the fit's end bins (weight
//!   0: black and saturated) are left out too. `response_err_ln_all` is the same over every
//!   value that occurs, for the record;
//! - `response_toe_err_sigmas`: the toe, the values that occur below the pinned ones and
//!   above the sensor's mean code at black, against what the sensor does there: its mean
//!   response E[z | x] under photon, read and quantisation noise and the clip at black
//!   (`mean_response`). At each toe value z, the fitted curve's exposure (with the offset of
//!   the pinned values) gives a mean code; the worst |mean − z| over the code's own standard
//!   deviation there. An error ε in ln exposure shows as ε/σ of these units where a code's
//!   noise in ln exposure is σ: at the toe's end (σ = 0.1) the pinned values' 0.02 is 0.2;
//! - `radiance_median_rel_err`, `radiance_p95_rel_err`: against the true radiance over the
//!   pixel channels well exposed (a mean signal of 10 % to 90 % of the full well) in at least
//!   one frame, after one scale per channel (the median ratio); `radiance_median_err_stops`
//!   the same in stops;
//! - `radiance_worst_decade_bias`: the bias a median over the image can hide: per channel,
//!   after that one scale, the median ratio estimate/truth in each decade of true radiance
//!   (with at least `DECADE_MIN_SAMPLES` well-exposed pixel channels), the worst |median − 1|;
//! - `floor_median_rel_err`, `floor_p95_rel_err`: the same for the stack merged through the
//!   true curve with the same weights, the noise floor no response recovery can beat, and
//!   `radiance_median_over_floor`, `radiance_p95_over_floor` the ratios to it;
//! - `saturated_pixels`, `dark_pixels` (masked as bounds), `true_dynamic_range` (brightest
//!   over darkest positive true luminance), `merge_megapixel_frames_per_s`;
//! - with `weights = "noise-from-stack"`, `full_well_rel_err`: the stack's estimate of the
//!   full well (`hdr::noise`) against the sensor's.

use super::Synthesis;
use super::{apply_overrides, Context, Findings, SettingsKey, StageError};
use super::{run_case, CaseResult, Settings};
use crate::hdr::{self, Frame, Method, Weights};
use crate::image::Image;
use crate::pipeline::cache::scene_digest;
use crate::pipeline::cache::Pass;
use crate::pipeline::metric::{Better, Metric};
use crate::render::{self, sensor::Response};
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Scene file, relative to the pipeline file.
    pub scene: String,
    /// The camera's pose instead of the scene's (`{ origin, target, up }`, as a scene's
    /// `[camera] look_at`): one view of a scene other cases share.
    pub look_at: Option<render::scene::LookAt>,
    /// Number of exposures (default 7, at least 2).
    #[serde(default = "default_exposures")]
    pub exposures: usize,
    /// Stops between consecutive exposures (default 2).
    #[serde(default = "default_stop_step")]
    pub stop_step: f64,
    /// Exposure of the longest frame: radiance → fraction of full scale (default 1).
    #[serde(default = "one")]
    pub exposure: f64,
    /// The sensor's response (default: a gamma of 2.2), as a scene's `[sensor] response`.
    pub response: Option<Response>,
    /// Bits per sample: 8, 10, 12 or 16 (default 8).
    pub bits: Option<u8>,
    /// Electrons at full scale (default 20000) and read noise in electrons (default 3).
    pub full_well: Option<f64>,
    pub read_noise: Option<f64>,
    /// `true`: the stack is photographed through the scene's own `[sensor]` (its response,
    /// bits, full well and read noise; this case's `exposure` sets the longest frame), the one
    /// camera of a whole session; `response`, `bits`, `full_well` and `read_noise` are then
    /// not given (default false).
    #[serde(default)]
    pub scene_sensor: bool,
    /// `debevec` or `robertson` (default debevec).
    #[serde(default = "default_method")]
    pub method: String,
    /// Debevec's λ and sample pixels per value (defaults: `hdr::DEFAULT_LAMBDA`,
    /// `hdr::DEFAULT_SAMPLES_PER_VALUE`, as `lumen hdr`'s).
    #[serde(default = "default_lambda")]
    pub lambda: f64,
    #[serde(default = "default_samples_per_value")]
    pub samples_per_value: usize,
    /// Debevec's smoothness term in `logit` of the value (default) or `even` in the value.
    #[serde(default)]
    pub smoothness: hdr::response::Smoothness,
    /// `hat`, `noise` (the default: the sensor's own full well and read noise, as its data
    /// sheet gives them) or `noise-from-stack` (estimated from the frames, `hdr::noise`, as
    /// `lumen hdr` does by default).
    #[serde(default = "default_weights")]
    pub weights: String,
    /// Samples per pixel (default: the scene's).
    pub spp: Option<u32>,
    /// Denoise the truth render (`stages::truth_render`): `true` or the filter's settings.
    #[serde(default)]
    pub denoise: super::Denoise,
    /// The scene is a colour chart, and the radiance is its camera signal rendered spectrally
    /// as the `color` stage renders it (`{ camera = "nikon-d5100", illuminant = "d65" }`,
    /// those the defaults): a later colour case can then take the merged radiance
    /// (`image = "from:CASE/radiance"`). Default: the scene's RGB radiance.
    pub spectral: Option<Spectral>,
}

/// `Config::spectral`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Spectral {
    #[serde(default = "default_camera")]
    pub camera: String,
    #[serde(default = "default_illuminant")]
    pub illuminant: String,
}

fn default_camera() -> String {
    "nikon-d5100".into()
}
fn default_illuminant() -> String {
    "d65".into()
}

fn default_exposures() -> usize {
    7
}
fn default_stop_step() -> f64 {
    2.0
}
fn one() -> f64 {
    1.0
}
fn default_samples_per_value() -> usize {
    hdr::DEFAULT_SAMPLES_PER_VALUE
}
impl Config {
    fn response(&self) -> Response {
        self.response.unwrap_or(Response::Gamma { gamma: 2.2 })
    }
    fn bits(&self) -> u8 {
        self.bits.unwrap_or(8)
    }
    fn full_well(&self) -> f64 {
        self.full_well.unwrap_or(20000.0)
    }
    fn read_noise(&self) -> f64 {
        self.read_noise.unwrap_or(3.0)
    }

    /// The case with `scene_sensor` resolved: the scene's sensor in the four fields it sets.
    fn resolved(&self, ctx: &Context) -> Result<Config, StageError> {
        if !self.scene_sensor {
            return Ok(self.clone());
        }
        let given: Vec<&str> = [
            ("response", self.response.is_some()),
            ("bits", self.bits.is_some()),
            ("full_well", self.full_well.is_some()),
            ("read_noise", self.read_noise.is_some()),
        ]
        .into_iter()
        .filter_map(|(name, is)| is.then_some(name))
        .collect();
        if !given.is_empty() {
            return Err(StageError::Config(format!(
                "scene_sensor = true and {}: the scene's sensor sets them",
                given.join(", ")
            )));
        }
        let scene = render::load(&ctx.dir.join(&self.scene))?;
        let Some(sn) = scene.sensor else {
            return Err(StageError::Config(format!("scene_sensor = true: {} has no [sensor]", self.scene)));
        };
        Ok(Config {
            response: Some(sn.response),
            bits: Some(sn.bits),
            full_well: Some(sn.full_well),
            read_noise: Some(sn.read_noise),
            ..self.clone()
        })
    }
}
fn default_method() -> String {
    "debevec".into()
}
fn default_lambda() -> f64 {
    hdr::DEFAULT_LAMBDA
}
fn default_weights() -> String {
    "noise".into()
}

pub struct Truth {
    radiance: Image,
    response: Response,
    max_code: f64,
    /// The sensor's electrons at full scale and read noise in electrons.
    full_well: f64,
    read_noise: f64,
    /// Per channel: which code values occur in the stack.
    occurs: Vec<Vec<bool>>,
    /// Per channel and pixel: some frame holds it well exposed (10 % to 90 % of the full well).
    well_exposed: Vec<Vec<bool>>,
    /// Per channel and value, the true g(z) and whether one observation pins it down
    /// (`true_response`).
    g_true: Vec<Vec<f64>>,
    pinned: Vec<Vec<bool>>,
    /// The radiance's darkest and brightest positive luminance.
    luminance_range: Option<(f64, f64)>,
    /// The median and 95th-percentile errors of the frames merged through the true curve.
    floor: Option<(f64, f64)>,
}

#[derive(Serialize)]
struct FilmRecipe<'a> {
    product: &'static str,
    scene: &'a str,
    settings: SettingsKey,
}

/// The sensor an entry describes (the longest frame's exposure).
fn sensor(c: &Config) -> render::sensor::Sensor {
    render::sensor::Sensor {
        exposure: c.exposure,
        full_well: c.full_well(),
        photon_noise: true,
        read_noise: c.read_noise(),
        bits: c.bits(),
        response: c.response(),
    }
}

pub fn synthesize(c: &Config, ctx: &Context) -> Result<Synthesis<hdr::Input, Truth>, StageError> {
    if c.exposures < 2 || c.exposures > 64 {
        return Err(StageError::Config(format!("exposures = {}: expected 2 to 64", c.exposures)));
    }
    if !(c.stop_step.is_finite() && c.stop_step > 0.0 && c.stop_step <= 10.0) {
        return Err(StageError::Config(format!("stop_step = {}: expected a number in (0, 10]", c.stop_step)));
    }
    let sensor = sensor(c);
    sensor.validate()?;
    // Settings checked before the render; the weights also serve the noise floor below.
    let (_, weights) = method(c)?;
    let (radiance, spp) = match &c.spectral {
        Some(sp) => {
            let mut chart =
                super::color::load_chart(&c.scene, c.look_at.as_ref(), &sp.camera, &sp.illuminant, ctx)?;
            let Some(signal) = super::color::chart_signal(&mut chart, c.spp, &c.denoise, ctx)? else {
                return Ok(None);
            };
            (signal.image, signal.spp)
        }
        None => {
            let scene_path = ctx.dir.join(&c.scene);
            let mut scene = render::load(&scene_path)?;
            let mut digest = scene_digest(&scene_path)?;
            super::aim(&mut scene, &mut digest, c.look_at.as_ref())?;
            let mut settings = render::Settings::from_scene(&scene);
            apply_overrides(&mut settings, c.spp, None)?;
            settings.seed = ctx.seed;
            let recipe = FilmRecipe {
                product: "hdr-film",
                scene: &digest,
                settings: SettingsKey::denoised(&settings, &c.denoise),
            };
            let film = ctx.cache.images(ctx.case, "radiance", &recipe, || {
                Ok::<_, StageError>(vec![super::truth_render(&scene, &settings, &c.denoise)?])
            })?;
            let Some(film) = film else { return Ok(None) };
            let Some(radiance) = film.into_iter().next() else {
                return Err(StageError::Config("the cached render is empty".into()));
            };
            (radiance, settings.spp)
        }
    };
    let max_code = sensor.max_code() as f64;
    let frames: Vec<Frame> = (0..c.exposures)
        .map(|k| {
            let t = 2f64.powf(-(k as f64) * c.stop_step);
            let s = render::sensor::Sensor { exposure: c.exposure * t, ..sensor.clone() };
            let codes = s.expose(&radiance, render::sampler::mix64(ctx.seed ^ (0x4d52 + k as u64)));
            Frame { name: format!("frame {k} ({t} s)"), time_s: t, codes }
        })
        .collect();
    let levels = sensor.max_code() as usize + 1;
    let n = (radiance.width * radiance.height) as usize;
    let mut occurs = vec![vec![false; levels]; 3];
    for f in &frames {
        for (k, &z) in f.codes.iter().enumerate() {
            occurs[k % 3][z as usize] = true;
        }
    }
    // Well exposed: a frame's mean signal is 10 % to 90 % of full scale (of the sensor's
    // electrons, not of its code values: a gamma curve puts 10 % of the codes at 0.6 % of full
    // scale, where photon noise alone is 9 %).
    let mut well_exposed = vec![vec![false; n]; 3];
    for f in &frames {
        for (k, &l) in radiance.data.iter().enumerate() {
            let x = l as f64 * c.exposure * f.time_s;
            if (0.1..=0.9).contains(&x) {
                well_exposed[k % 3][k / 3] = true;
            }
        }
    }
    let input = hdr::Input {
        width: radiance.width as usize,
        height: radiance.height as usize,
        levels,
        frames,
        usable: None,
    };
    let luminance_range = crate::image::luminance_range(radiance.data.chunks_exact(3));
    // The noise floor: the stack merged through the true curve with the stage's weights.
    let (g_true, pinned) = true_response(&c.response(), max_code, c.full_well(), c.read_noise(), levels);
    let true_curve = hdr::Response { levels, g: g_true.clone() };
    let codes: Vec<&[u16]> = input.frames.iter().map(|f| f.codes.as_slice()).collect();
    let times: Vec<f64> = input.frames.iter().map(|f| f.time_s).collect();
    // Weights from the stack are judged against the sensor's true constants.
    let floor_weights = match weights {
        Weights::NoiseFromStack => Weights::Noise { full_well: c.full_well(), read_noise: c.read_noise() },
        w => w,
    };
    let (floor_radiance, _) = hdr::merge::merge(&codes, &times, &true_curve, floor_weights);
    let (lo, hi) = luminance_range.unwrap_or((0.0, 0.0));
    let mut notes = vec![format!(
        "{}: {}×{} px, {} spp, luminance from {lo:.3e} to {hi:.3e}; {} exposures {} stops apart from 1 s, sensor {} bits, response {:?}, full well {} e⁻, read noise {} e⁻.",
        c.scene,
        radiance.width,
        radiance.height,
        spp,
        c.exposures,
        c.stop_step,
        c.bits(),
        c.response(),
        c.full_well(),
        c.read_noise()
    )];
    if let Some(sp) = &c.spectral {
        notes.push(format!(
            "The radiance is the chart's camera signal ({} under {}), rendered spectrally.",
            sp.camera, sp.illuminant
        ));
    }
    notes.extend(super::denoise_note(&c.denoise, spp));
    let mut truth = Truth {
        radiance,
        response: c.response(),
        max_code,
        full_well: c.full_well(),
        read_noise: c.read_noise(),
        occurs,
        well_exposed,
        g_true,
        pinned,
        luminance_range,
        floor: None,
    };
    let floor = radiance_errors(&truth, &floor_radiance);
    truth.floor = quantile(&floor, 0.5).zip(quantile(&floor, 0.95));
    Ok(Some((input, truth, Findings { notes, ..Default::default() })))
}

/// The response fit an entry names (`hdr::Fit`, the parser `lumen hdr --response` uses):
/// parsed when the case runs, so a wrong name is the case's declared error, not the file's.
fn fit(
    name: &str,
    lambda: f64,
    samples_per_value: usize,
    smoothness: hdr::response::Smoothness,
) -> Result<Method, StageError> {
    let fit: hdr::Fit = name.parse().map_err(|e| StageError::Config(format!("method = {e}")))?;
    Ok(fit.method(lambda, samples_per_value, smoothness))
}

fn method(c: &Config) -> Result<(Method, Weights), StageError> {
    let m = fit(&c.method, c.lambda, c.samples_per_value, c.smoothness)?;
    // `noise` is the sensor's specification, as a camera's data sheet gives it.
    let w = c
        .weights
        .parse::<hdr::WeightsName>()
        .and_then(|w| w.resolve(Some(c.full_well()), c.read_noise()))
        .map_err(|e| StageError::Config(format!("weights = {e}")))?;
    Ok((m, w))
}

pub fn solve(c: &Config, input: &hdr::Input) -> Result<hdr::Output, StageError> {
    let (method, weights) = method(c)?;
    Ok(hdr::run(input, &hdr::Config { method, weights, fusion: None })?)
}

/// Per channel, the (truth, estimate) pairs of the well-exposed pixel channels with a positive
/// truth, the estimate divided by one scale per channel (the median ratio): the radiance's
/// arbitrary scale taken out.
fn scaled_pairs(truth: &Truth, radiance: &[f32]) -> Vec<Vec<(f64, f64)>> {
    let n = truth.well_exposed[0].len();
    (0..3)
        .map(|c| {
            let pairs: Vec<(f64, f64)> = (0..n)
                .filter(|&i| truth.well_exposed[c][i])
                .map(|i| (truth.radiance.data[3 * i + c] as f64, radiance[3 * i + c] as f64))
                .filter(|(t, _)| *t > 0.0)
                .collect();
            if pairs.is_empty() {
                return pairs;
            }
            let mut ratios: Vec<f64> = pairs.iter().map(|(t, e)| e / t).collect();
            ratios.sort_by(f64::total_cmp);
            let k = ratios[ratios.len() / 2];
            pairs.into_iter().map(|(t, e)| (t, e / k)).collect()
        })
        .collect()
}

/// Relative errors of a merged radiance against the truth over the well-exposed pixel
/// channels, after one scale per channel (the median ratio), sorted.
fn radiance_errors(truth: &Truth, radiance: &[f32]) -> Vec<f64> {
    let mut errs: Vec<f64> =
        scaled_pairs(truth, radiance).into_iter().flatten().map(|(t, e)| (e - t).abs() / t).collect();
    errs.sort_by(f64::total_cmp);
    errs
}

/// Pixel channels a decade of radiance needs for its median ratio to count in
/// `worst_decade_bias`: the median of 100 ratios is within about 1.25·σ/10 of the decade's
/// own, a tenth of one observation's noise.
const DECADE_MIN_SAMPLES: usize = 100;

/// The bias a median over the whole image can hide: per channel, after the same one scale
/// as `radiance_errors` (the median ratio), the median ratio estimate/truth of the
/// well-exposed pixel channels in each decade of true radiance holding at least
/// `DECADE_MIN_SAMPLES`; the worst |median − 1| over decades and channels.
fn worst_decade_bias(truth: &Truth, radiance: &[f32]) -> Option<f64> {
    let mut worst: Option<f64> = None;
    for pairs in scaled_pairs(truth, radiance) {
        let mut by_decade: std::collections::BTreeMap<i64, Vec<f64>> = Default::default();
        for (t, e) in &pairs {
            by_decade.entry(t.log10().floor() as i64).or_default().push(e / t);
        }
        for mut r in by_decade.into_values().filter(|r| r.len() >= DECADE_MIN_SAMPLES) {
            r.sort_by(f64::total_cmp);
            let bias = (r[r.len() / 2] - 1.0).abs();
            worst = Some(worst.map_or(bias, |w: f64| w.max(bias)));
        }
    }
    worst
}

/// The sensor's mean response: on a grid of ln x (exposure as a fraction of full scale, as
/// the true g), rising from 10⁻³ electrons to `ln_hi` (at most full scale), the mean and
/// standard deviation of the code under photon, read and quantisation noise and the clip at
/// black. With
/// e = Poisson(x·full_well) + Normal(0, σ_r²) electrons and e_z = full_well·f⁻¹((z − ½)/max)
/// the electrons at which the code reaches z, code = Σ_z 1[e ≥ e_z] and code² =
/// Σ_z (2z − 1)·1[e ≥ e_z], so both moments are sums of P(e ≥ e_z).
fn mean_response(truth: &Truth, c: usize, ln_hi: f64) -> Vec<(f64, f64, f64)> {
    use crate::math::stats::normal_cdf;
    let (fw, sr, max) = (truth.full_well, truth.read_noise, truth.max_code);
    let thresholds: Vec<f64> =
        (1..=max as usize).map(|z| fw * truth.response.inverse_channel(c, (z as f64 - 0.5) / max)).collect();
    // (E[code], E[code²]) given e ~ Normal(mean, s²).
    let moments = |mean: f64, s: f64| -> (f64, f64) {
        let (lo, hi) = if s <= 0.0 {
            let k = thresholds.partition_point(|&t| t <= mean);
            (k, k)
        } else {
            (
                thresholds.partition_point(|&t| t < mean - 9.0 * s),
                thresholds.partition_point(|&t| t <= mean + 9.0 * s),
            )
        };
        let (mut m1, mut m2) = (lo as f64, (lo * lo) as f64);
        for (k, &t) in thresholds[lo..hi].iter().enumerate() {
            let p = normal_cdf((mean - t) / s);
            m1 += p;
            m2 += (2 * (lo + k + 1) - 1) as f64 * p;
        }
        (m1, m2)
    };
    // Under Poisson photons (means up to `POISSON`): the moments per photon count, once.
    const POISSON: f64 = 200.0;
    let per_count: Vec<(f64, f64)> =
        (0..(POISSON + 12.0 * POISSON.sqrt() + 20.0) as usize).map(|k| moments(k as f64, sr)).collect();
    let expected = |e: f64| -> (f64, f64) {
        if e > POISSON {
            return moments(e, (e + sr * sr).sqrt());
        }
        let (mut p, mut sum) = ((-e).exp(), (0.0, 0.0));
        for (k, &(a, b)) in per_count.iter().enumerate().take((e + 12.0 * e.sqrt() + 20.0) as usize) {
            sum = (sum.0 + p * a, sum.1 + p * b);
            p *= e / (k + 1) as f64;
        }
        sum
    };
    let ln_lo = (1e-3 / fw).ln();
    let ln_hi = ln_hi.min(0.0).max(ln_lo + 1.0);
    let steps = 2000;
    (0..=steps)
        .map(|k| {
            let l = ln_lo + (ln_hi - ln_lo) * k as f64 / steps as f64;
            let (m1, m2) = expected(l.exp() * fw);
            (l, m1, (m2 - m1 * m1).max(0.0).sqrt())
        })
        .collect()
}

/// The value at quantile `q` of sorted values.
fn quantile(sorted: &[f64], q: f64) -> Option<f64> {
    (!sorted.is_empty()).then(|| sorted[((sorted.len() - 1) as f64 * q) as usize])
}

/// Per channel and value, the true g(z) = ln f⁻¹(z/max), and whether a single observation
/// pins the value down (module docs: its noise in ln exposure below 0.1, outside the end bins).
/// `response` is the sensor's, reaching code `max_code` at full scale, with `full_well`
/// electrons there and `read_noise` electrons of read noise.
fn true_response(
    response: &Response,
    max_code: f64,
    full_well: f64,
    read_noise: f64,
    levels: usize,
) -> (Vec<Vec<f64>>, Vec<Vec<bool>>) {
    let true_g =
        |c: usize, z: f64| response.inverse_channel(c, (z / max_code).clamp(0.0, 1.0)).max(1e-300).ln();
    // The fit's resolution: above 1024 levels it works on bins (`hdr::response`).
    let bin = (levels / hdr::response::MAX_FIT_LEVELS).max(1);
    let g_true: Vec<Vec<f64>> = (0..3).map(|c| (0..levels).map(|z| true_g(c, z as f64)).collect()).collect();
    let pinned = (0..3)
        .map(|c| {
            (0..levels)
                .map(|z| {
                    let half = 0.5 * bin as f64;
                    let sigma_q = (true_g(c, z as f64 + half) - true_g(c, z as f64 - half)) / 12f64.sqrt();
                    let e = g_true[c][z].exp() * full_well;
                    let sigma_e = (e + read_noise.powi(2)).sqrt() / e;
                    z >= bin && z + bin < levels && (sigma_q.powi(2) + sigma_e.powi(2)).sqrt() < 0.1
                })
                .collect()
        })
        .collect();
    (g_true, pinned)
}

pub fn validate(_c: &Config, out: &hdr::Output, truth: &Truth) -> Findings {
    let mut f = Findings::default();
    let levels = out.response.levels;
    // The response against the truth, over the values a single observation pins down
    // (module docs), and over every value that occurs.
    let (g_true, pinned) = (&truth.g_true, &truth.pinned);
    let bin = (levels / hdr::response::MAX_FIT_LEVELS).max(1);
    // Per channel, the values that occur and `keep` holds, and the fit's mean offset from the
    // truth over them (the offset every recovery is free to choose); `None` when there are none.
    let offset_over = |c: usize, keep: &dyn Fn(usize, usize) -> bool| {
        let zs: Vec<usize> = (1..levels - 1).filter(|&z| truth.occurs[c][z] && keep(c, z)).collect();
        if zs.is_empty() {
            return None;
        }
        let (g, gt) = (&out.response.g[c], &g_true[c]);
        let offset = zs.iter().map(|&z| g[z] - gt[z]).sum::<f64>() / zs.len() as f64;
        Some((zs, offset))
    };
    let worst_over = |keep: &dyn Fn(usize, usize) -> bool| {
        let mut worst: Option<f64> = None;
        for c in 0..3 {
            let Some((zs, offset)) = offset_over(c, keep) else { continue };
            let (g, gt) = (&out.response.g[c], &g_true[c]);
            let w = zs.iter().map(|&z| (g[z] - gt[z] - offset).abs()).fold(0.0, f64::max);
            worst = Some(worst.map_or(w, |v: f64| v.max(w)));
        }
        worst
    };
    let worst = worst_over(&|c, z| pinned[c][z]);
    let worst_all = worst_over(&|_, _| true);
    // The toe: the values that occur below the pinned ones (outside the end bins) and above
    // the sensor's mean code at black; the fitted curve's exposure for each (with the offset
    // of the pinned values) against the mean code the sensor gives there, in units of the
    // code's own spread.
    let mut toe: Option<f64> = None;
    for c in 0..3 {
        let Some(first) = (0..levels).find(|&z| pinned[c][z]) else { continue };
        let Some((_, offset)) = offset_over(c, &|c, z| pinned[c][z]) else { continue };
        let g = &out.response.g[c];
        // Up to an exposure past the toe's end: the fit's toe values lie below it.
        let curve = mean_response(truth, c, g_true[c][first] + 1.0);
        let black = curve[0].1;
        for z in (bin..first).filter(|&z| truth.occurs[c][z] && z as f64 > black) {
            let l = g[z] - offset;
            let k = curve.partition_point(|p| p.0 < l).clamp(1, curve.len() - 1);
            let (a, b) = (curve[k - 1], curve[k]);
            let f = ((l - a.0) / (b.0 - a.0)).clamp(0.0, 1.0);
            let (mean, sd) = (a.1 + f * (b.1 - a.1), a.2 + f * (b.2 - a.2));
            let e = (mean - z as f64).abs() / sd.max(1e-9);
            toe = Some(toe.map_or(e, |t: f64| t.max(e)));
        }
    }
    let m = &mut f.metrics;
    m.push(Metric::maybe("response_err_ln", worst, "ln", Better::Lower, "no value inside the range occurs"));
    m.push(Metric::maybe("response_err_ln_all", worst_all, "ln", Better::Lower, "no value occurs"));
    m.push(Metric::maybe(
        "response_toe_err_sigmas",
        toe,
        "σ",
        Better::Lower,
        "no value below the pinned ones occurs above the sensor's mean code at black",
    ));
    // The radiance against the truth.
    let errs = radiance_errors(truth, &out.radiance);
    let pick = |q: f64| quantile(&errs, q);
    let none = "no pixel well exposed in any frame";
    m.push(Metric::maybe("radiance_median_rel_err", pick(0.5), "", Better::Lower, none));
    m.push(Metric::maybe("radiance_p95_rel_err", pick(0.95), "", Better::Lower, none));
    m.push(Metric::maybe(
        "radiance_worst_decade_bias",
        worst_decade_bias(truth, &out.radiance),
        "",
        Better::Lower,
        "no decade of radiance holds enough well-exposed pixel channels",
    ));
    // The noise floor: the same frames merged through the true curve.
    let (floor_median, floor_p95) = truth.floor.unzip();
    m.push(Metric::maybe("floor_median_rel_err", floor_median, "", Better::Lower, none));
    m.push(Metric::maybe("floor_p95_rel_err", floor_p95, "", Better::Lower, none));
    let over = |e: Option<f64>, f: Option<f64>| e.zip(f).filter(|(_, f)| *f > 0.0).map(|(e, f)| e / f);
    m.push(Metric::maybe(
        "radiance_median_over_floor",
        over(pick(0.5), floor_median),
        "×",
        Better::Lower,
        none,
    ));
    m.push(Metric::maybe("radiance_p95_over_floor", over(pick(0.95), floor_p95), "×", Better::Lower, none));
    m.push(Metric::maybe(
        "radiance_median_err_stops",
        pick(0.5).map(|e| (1.0 + e).log2()),
        "stops",
        Better::Lower,
        none,
    ));
    let s = &out.summary;
    m.push(Metric::new("saturated_pixels", s.saturated_pixels as f64, "pixels", Better::Lower));
    m.push(Metric::new("dark_pixels", s.dark_pixels as f64, "pixels", Better::Lower));
    let range = truth.luminance_range.map(|(lo, hi)| hi / lo);
    m.push(Metric::maybe("true_dynamic_range", range, "×", Better::Higher, "no light"));
    m.push(Metric::new(
        "merge_megapixel_frames_per_s",
        s.merge_megapixel_frames_per_s,
        "1/s",
        Better::Higher,
    ));
    m.push(Metric::new("response_s", s.response_s, "s", Better::Lower));
    if let Some(e) = &s.noise {
        m.push(Metric::new(
            "full_well_rel_err",
            (e.full_well / truth.full_well - 1.0).abs(),
            "",
            Better::Lower,
        ));
    }
    f.notes.push(format!("Merge weights: {}.", s.weights));
    f
}

/// An `hdr` case on photographs (an entry with `list`): the stack `lumen hdr --list` reads,
/// with no truth. What can be checked without one: the response is finite and strictly
/// increasing on every channel (OpenCV's fits are not on the Memorial stack), the merge spans
/// the exposure times' range, and the stack agrees with itself: each frame, left out of the
/// merge, is predicted from the others through the recovered curve.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DataConfig {
    /// The list file, a frame name and an exposure time per line (as `lumen hdr --list`),
    /// relative to the pipeline file.
    pub list: String,
    /// Pixels of this colour (R, G, B code values) in any frame are left out of the fit
    /// (registration borders), as `lumen hdr --exclude-color`.
    pub exclude_color: Option<[u16; 3]>,
    /// `debevec` or `robertson` (default debevec), with Debevec's λ, samples and smoothness
    /// as in `Config`. The merge is `lumen hdr`'s default: noise weights with the full well
    /// and read noise the stack itself gives (`hdr::noise`); the leave-one-out check merges
    /// with hat weights, which need no estimate from the frame left out.
    #[serde(default = "default_method")]
    pub method: String,
    #[serde(default = "default_lambda")]
    pub lambda: f64,
    #[serde(default = "default_samples_per_value")]
    pub samples_per_value: usize,
    #[serde(default)]
    pub smoothness: hdr::response::Smoothness,
}

/// A photographed stack's own frames, against which the merge is checked.
pub struct Stack {
    input: hdr::Input,
}

pub fn read(c: &DataConfig, ctx: &Context) -> Result<(hdr::Input, Stack, Findings), StageError> {
    fit(&c.method, c.lambda, c.samples_per_value, c.smoothness)?;
    let list = super::dataset_path(ctx, &c.list)?;
    let frames = hdr::input::read_list(&list)?;
    let input = hdr::input::read_stack(&frames, c.exclude_color)?;
    let (lo, hi) = frames.iter().fold((f64::INFINITY, 0f64), |(lo, hi), f| (lo.min(f.1), hi.max(f.1)));
    let notes = vec![format!(
        "Real data: {} frames listed in {} ({}×{} px, {} levels), exposure times {lo:.4e} to {hi:.4e} s ({:.1} stops){}.",
        input.frames.len(),
        list.display(),
        input.width,
        input.height,
        input.levels,
        (hi / lo).log2(),
        match c.exclude_color {
            Some([r, g, b]) => format!("; pixels coloured {r},{g},{b} in any frame left out of the fit"),
            None => String::new(),
        }
    )];
    Ok((input.clone(), Stack { input }, Findings { notes, ..Default::default() }))
}

pub fn solve_data(c: &DataConfig, input: &hdr::Input) -> Result<hdr::Output, StageError> {
    let method = fit(&c.method, c.lambda, c.samples_per_value, c.smoothness)?;
    // The merge `lumen hdr` makes by default: noise weights with the stack's own estimate.
    Ok(hdr::run(input, &hdr::Config { method, weights: Weights::NoiseFromStack, fusion: None })?)
}

/// Metrics:
/// - `non_monotone_values`, `non_finite_values`: steps z → z + 1 where a channel's g does not
///   rise, and values of g that are not finite, over the three channels;
/// - `dynamic_range_stops`: the merge's range (`hdr::Summary`);
/// - `loo_median_abs_ln`, `loo_worst_frame_bias_ln`: each frame left out of the merge in
///   turn and predicted from the others: |g(z) − (ln E + ln Δt)| in ln exposure over the
///   pixel channels whose code lies in the middle half of the range (where g is best
///   determined) and where the others' merge is well exposed (borders the fit left out are
///   left out here too), its median over all frames, and the largest |median| of the signed
///   difference of one frame: a frame whose effective exposure differs from its stated time
///   (film's reciprocity failure at long times, a shutter's error) shows there, and every
///   frame's is listed in a note;
/// - `saturated_pixels`, `dark_pixels`, `response_s`, `merge_megapixel_frames_per_s`.
pub fn validate_data(out: &hdr::Output, stack: &Stack) -> Findings {
    let mut f = Findings::default();
    let r = &out.response;
    let non_finite = r.g.iter().flatten().filter(|v| !v.is_finite()).count();
    let non_monotone: usize = r.g.iter().map(|g| g.windows(2).filter(|p| !(p[1] > p[0])).count()).sum();
    let input = &stack.input;
    let n = input.width * input.height;
    let middle = (input.levels / 4) as u16..=(3 * input.levels / 4) as u16;
    let mut all_abs = Vec::new();
    let mut biases = Vec::new();
    if non_finite == 0 {
        for k in 0..input.frames.len() {
            let others: Vec<&hdr::Frame> =
                input.frames.iter().enumerate().filter(|(j, _)| *j != k).map(|(_, f)| f).collect();
            let codes: Vec<&[u16]> = others.iter().map(|f| f.codes.as_slice()).collect();
            let times: Vec<f64> = others.iter().map(|f| f.time_s).collect();
            let (radiance, mask) = hdr::merge::merge(&codes, &times, r, Weights::Hat);
            let frame = &input.frames[k];
            let ln_t = frame.time_s.ln();
            let mut signed = Vec::new();
            for i in 0..n {
                if mask[i] != hdr::merge::WELL_EXPOSED || input.usable.as_ref().is_some_and(|u| !u[i]) {
                    continue;
                }
                for c in 0..3 {
                    let z = frame.codes[3 * i + c];
                    let e = radiance[3 * i + c] as f64;
                    if middle.contains(&z) && e > 0.0 {
                        signed.push(r.g[c][z as usize] - (e.ln() + ln_t));
                    }
                }
            }
            signed.sort_by(f64::total_cmp);
            if let Some(b) = quantile(&signed, 0.5) {
                biases.push((frame.time_s, b));
            }
            all_abs.extend(signed.iter().map(|d| d.abs()));
        }
    }
    all_abs.sort_by(f64::total_cmp);
    let m = &mut f.metrics;
    m.push(Metric::new("non_monotone_values", non_monotone as f64, "values", Better::Lower));
    m.push(Metric::new("non_finite_values", non_finite as f64, "values", Better::Lower));
    m.push(Metric::new("dynamic_range_stops", out.summary.dynamic_range_stops, "stops", Better::Higher));
    let none = "the response is not finite, or no frame holds a code in the middle of the range";
    m.push(Metric::maybe("loo_median_abs_ln", quantile(&all_abs, 0.5), "ln", Better::Lower, none));
    let worst = biases.iter().map(|(_, b)| b.abs()).reduce(f64::max);
    m.push(Metric::maybe("loo_worst_frame_bias_ln", worst, "ln", Better::Lower, none));
    let s = &out.summary;
    m.push(Metric::new("saturated_pixels", s.saturated_pixels as f64, "pixels", Better::Lower));
    m.push(Metric::new("dark_pixels", s.dark_pixels as f64, "pixels", Better::Lower));
    m.push(Metric::new("response_s", s.response_s, "s", Better::Lower));
    m.push(Metric::new(
        "merge_megapixel_frames_per_s",
        s.merge_megapixel_frames_per_s,
        "1/s",
        Better::Higher,
    ));
    f.notes.push(format!(
        "Response by {} in {:.3} s ({} samples); {} pixel channels predicted with each frame left out.",
        s.method,
        s.response_s,
        s.samples,
        all_abs.len()
    ));
    let listed: Vec<String> = biases.iter().map(|(t, b)| format!("{t:.4e} s: {b:+.3}")).collect();
    f.notes.push(format!(
        "Each frame left out, the median of g(z) − ln(E·Δt) (ln; positive: the frame is brighter than the others predict): {}.",
        listed.join(", ")
    ));
    f
}

/// What an hdr case hands on (`chain::Exports`): the merged radiance and the true one, the
/// scene, and the merged radiance's error in ln against the true ln radiance over the
/// well-exposed pixel channels; the recovered response with the sensor that made the stack,
/// and its error against the true g over the values that occur and a single observation pins
/// down (`chain::LnError` both).
fn export(c: &Config, ctx: &Context, out: &hdr::Output, truth: &Truth) -> super::Exports {
    let radiance_error = super::chain::LnError::fit(std::array::from_fn(|ch| {
        (0..truth.well_exposed[ch].len())
            .filter(|&i| truth.well_exposed[ch][i])
            .map(|i| (truth.radiance.data[3 * i + ch] as f64, out.radiance[3 * i + ch] as f64))
            .filter(|(t, e)| *t > 0.0 && *e > 0.0)
            .map(|(t, e)| (t.ln(), e.ln() - t.ln()))
            .collect()
    }));
    let levels = out.response.levels;
    let (g_true, pinned) = (&truth.g_true, &truth.pinned);
    let response_error = super::chain::LnError::fit(std::array::from_fn(|ch| {
        (0..levels)
            .filter(|&z| truth.occurs[ch][z] && pinned[ch][z])
            .map(|z| (g_true[ch][z], out.response.g[ch][z] - g_true[ch][z]))
            .collect()
    }));
    let r = &truth.radiance;
    super::Exports {
        radiance: Some(super::chain::Radiance {
            estimate: Image { width: r.width, height: r.height, channels: 3, data: out.radiance.clone() },
            truth: r.clone(),
            scene: super::render::clean(&ctx.dir.join(&c.scene)),
            spectral: c.spectral.clone(),
            look_at: c.look_at.clone(),
            error: radiance_error,
        }),
        response: Some(super::chain::InheritedResponse {
            g: out.response.g.clone(),
            sensor: sensor(c),
            error: response_error,
        }),
        ..Default::default()
    }
}

impl Settings for Config {
    fn headline(&self) -> &'static str {
        "radiance_median_rel_err"
    }
    fn run(&self, ctx: &Context) -> Result<CaseResult, StageError> {
        let c = &self.resolved(ctx)?;
        super::run_case_exporting(
            || synthesize(c, ctx),
            |i| solve(c, i),
            |o, t| validate(c, o, t),
            |o, t| export(c, ctx, o, t),
        )
    }
    fn provides(&self) -> &'static [&'static str] {
        &["radiance", "response"]
    }
    fn share(&self, ctx: &Context, pass: Pass) -> Option<Result<(), StageError>> {
        (pass == Pass::Renders).then(|| synthesize(&self.resolved(ctx)?, ctx).map(|_| ()))
    }
}

impl Settings for DataConfig {
    fn headline(&self) -> &'static str {
        "loo_median_abs_ln"
    }
    fn run(&self, ctx: &Context) -> Result<CaseResult, StageError> {
        run_case(|| read(self, ctx).map(Some), |i| solve_data(self, i), validate_data)
    }
}
