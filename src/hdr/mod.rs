//! HDR fusion: the camera's response curve from an exposure stack, and the scene's radiance
//! merged from it.
//!
//! `run(&Input, &Config)` is the solver `lumen hdr` calls: frames of code values with their
//! exposure times in, the response per channel (`response`: Debevec & Malik 1997, Robertson
//! et al. 2003, or a given curve) and the merged radiance with its mask (`merge`) out. The
//! radiance has the response's arbitrary scale per channel (g(z_mid) = 0): exposure × time
//! is known only up to that factor. The merge's noise weights take the sensor's full well and
//! read noise as given, or as the stack itself shows them (`noise`, `Weights::NoiseFromStack`,
//! `lumen hdr`'s default; `Config::default` keeps Debevec & Malik's hat weights). With the
//! noise known, a fitted curve's toe, where one code says little of its exposure, is refitted
//! as the sensor's mean response and the stack merged again through it (`toe`).
//!
//! `tonemap` holds Reinhard et al.'s global operator for PNG previews; `fusion` Mertens et
//! al.'s exposure fusion, an LDR picture blended from the frames without a response.

pub mod fusion;
pub mod input;
pub mod merge;
pub mod noise;
pub mod response;
pub mod toe;
pub mod tonemap;

pub use merge::Weights;
pub use response::Response;

use serde::{Deserialize, Serialize};

/// The hdr fit's error: the one the colour fit has too.
pub use crate::fit::FitError as Error;

/// One exposure: interleaved RGB code values.
#[derive(Clone, Debug)]
pub struct Frame {
    pub name: String,
    /// Exposure time in seconds (any consistent unit: only ratios matter).
    pub time_s: f64,
    pub codes: Vec<u16>,
}

#[derive(Clone, Debug)]
pub struct Input {
    pub width: usize,
    pub height: usize,
    /// Code values run from 0 to `levels − 1` (256 for 8-bit frames).
    pub levels: usize,
    pub frames: Vec<Frame>,
    /// Pixels to leave out of the response fit (registration borders): `true` to use.
    pub usable: Option<Vec<bool>>,
}

#[derive(Clone, Debug)]
pub enum Method {
    /// `lambda`: smoothness weight; `samples_per_value`: sample pixels per code value;
    /// `smoothness`: the variable the smoothness term's g″ is taken in.
    Debevec {
        lambda: f64,
        samples_per_value: usize,
        smoothness: response::Smoothness,
    },
    Robertson {
        iterations: usize,
    },
    Given(Response),
}

/// Debevec's default smoothness weight: with exposure ratios all equal (the usual bracket) and
/// photon noise, λ = 10⁴ suppresses the ripples such stacks leave free; measured on the `hdr`
/// stage's renders for gamma, film-like and sRGB curves (a noise-free stack with unequal
/// ratios needs far less).
pub const DEFAULT_LAMBDA: f64 = 1e4;
/// Largest smoothness weight taken: 10⁴ times the default, where the fitted curve is already
/// the smoothness prior's straight line whatever the data say.
pub const MAX_LAMBDA: f64 = 1e8;
/// Debevec's default sample pixels per value.
pub const DEFAULT_SAMPLES_PER_VALUE: usize = 4;
/// Most sample pixels per value taken.
pub const MAX_SAMPLES_PER_VALUE: usize = 1000;
/// Exposure times taken, in seconds: a picosecond to eleven days. Radiance is exp(g)/t in
/// float32; times far outside these put it beyond float32's range.
pub const MIN_TIME_S: f64 = 1e-12;
pub const MAX_TIME_S: f64 = 1e6;
/// Robertson's iteration cap: the fit stops earlier once g changes by less than 10⁻⁴ between
/// iterations (on the Memorial stack it does before 50).
pub const ROBERTSON_MAX_ITERATIONS: usize = 200;

/// A response fit by name: `debevec` or `robertson`. The one parser of `lumen hdr --response`
/// and a pipeline entry's `method`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fit {
    Debevec,
    Robertson,
}

impl std::str::FromStr for Fit {
    type Err = crate::error::Invalid;
    fn from_str(s: &str) -> Result<Fit, Self::Err> {
        match s {
            "debevec" => Ok(Fit::Debevec),
            "robertson" => Ok(Fit::Robertson),
            other => Err(format!("`{other}`: expected debevec or robertson").into()),
        }
    }
}

impl Fit {
    /// The method with Debevec's settings (Robertson's iterations are `ROBERTSON_MAX_ITERATIONS`).
    pub fn method(self, lambda: f64, samples_per_value: usize, smoothness: response::Smoothness) -> Method {
        match self {
            Fit::Debevec => Method::Debevec { lambda, samples_per_value, smoothness },
            Fit::Robertson => Method::Robertson { iterations: ROBERTSON_MAX_ITERATIONS },
        }
    }
}

/// Merge weights by name: `hat`, `noise` or `noise-from-stack`. The one parser of `lumen hdr
/// --weights` and a pipeline entry's `weights`; `resolve` adds the sensor's numbers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WeightsName {
    Hat,
    Noise,
    NoiseFromStack,
}

impl std::str::FromStr for WeightsName {
    type Err = crate::error::Invalid;
    fn from_str(s: &str) -> Result<WeightsName, Self::Err> {
        match s {
            "hat" => Ok(WeightsName::Hat),
            "noise" => Ok(WeightsName::Noise),
            "noise-from-stack" => Ok(WeightsName::NoiseFromStack),
            other => Err(format!("`{other}`: expected hat, noise or noise-from-stack").into()),
        }
    }
}

impl WeightsName {
    /// The weights, with the sensor's full well and read noise in electrons for `noise`. With
    /// no full well given, `noise` is the noise the stack itself shows (`NoiseFromStack`), and
    /// a read noise without a full well is refused.
    pub fn resolve(self, full_well: Option<f64>, read_noise: f64) -> Result<Weights, crate::error::Invalid> {
        Ok(match (self, full_well) {
            (WeightsName::Hat, _) => Weights::Hat,
            (WeightsName::NoiseFromStack, _) => Weights::NoiseFromStack,
            (WeightsName::Noise, Some(fw)) if fw.is_finite() && fw >= 1.0 && read_noise.is_finite() && read_noise >= 0.0 => {
                Weights::Noise { full_well: fw, read_noise }
            }
            (WeightsName::Noise, Some(fw)) => {
                return Err(format!(
                    "full well {fw}, read noise {read_noise}: expected at least 1 electron and a non-negative read noise"
                )
                .into())
            }
            (WeightsName::Noise, None) if read_noise != 0.0 => {
                return Err(format!(
                    "read noise {read_noise}: give it with the full well (without, both come from the stack)"
                )
                .into())
            }
            (WeightsName::Noise, None) => Weights::NoiseFromStack,
        })
    }
}

#[derive(Clone, Debug)]
pub struct Config {
    pub method: Method,
    pub weights: Weights,
    /// Also blend an LDR picture by Mertens et al.'s exposure fusion (`fusion`), if given.
    pub fusion: Option<fusion::Mertens>,
}

impl Default for Config {
    fn default() -> Config {
        Config {
            method: Method::Debevec {
                lambda: DEFAULT_LAMBDA,
                samples_per_value: DEFAULT_SAMPLES_PER_VALUE,
                smoothness: response::Smoothness::Logit,
            },
            weights: Weights::Hat,
            fusion: None,
        }
    }
}

#[derive(Clone, Debug)]
pub struct Output {
    pub response: Response,
    /// Linear radiance, interleaved RGB, width × height.
    pub radiance: Vec<f32>,
    /// Per pixel: `merge::WELL_EXPOSED`, `SATURATED` (a lower bound) or `DARK` (an upper bound).
    pub mask: Vec<u8>,
    /// Mertens et al.'s fusion, interleaved RGB in [0, 1] in the frames' encoding, when asked.
    pub fusion: Option<Vec<f32>>,
    pub summary: Summary,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Summary {
    pub frames: usize,
    pub width: usize,
    pub height: usize,
    pub levels: usize,
    pub method: String,
    /// Sample pixels of Debevec's fit (0 for the others).
    pub samples: usize,
    /// The merge's weights, with the noise constants they used and where they came from.
    pub weights: String,
    /// The full well and read noise the stack gave (`Weights::NoiseFromStack`).
    pub noise: Option<noise::Estimate>,
    /// Seconds for that estimate (0 without it).
    pub noise_s: f64,
    pub saturated_pixels: usize,
    pub dark_pixels: usize,
    /// log₂ of the brightest over the darkest positive luminance among the pixels not
    /// masked saturated or dark.
    pub dynamic_range_stops: f64,
    pub response_s: f64,
    pub merge_s: f64,
    /// Megapixels × frames merged per second.
    pub merge_megapixel_frames_per_s: f64,
    /// Seconds for the exposure fusion (0 without it).
    pub fusion_s: f64,
}

pub fn run(input: &Input, config: &Config) -> Result<Output, Error> {
    check(input)?;
    let n = input.width * input.height;
    let usable = input.usable.clone().unwrap_or_else(|| vec![true; n]);
    // Frames sorted by time, longest first, for the response fits' "middle frame".
    let mut order: Vec<usize> = (0..input.frames.len()).collect();
    order.sort_by(|&a, &b| input.frames[b].time_s.total_cmp(&input.frames[a].time_s));
    let times: Vec<f64> = order.iter().map(|&j| input.frames[j].time_s).collect();
    let frames: Vec<&[u16]> = order.iter().map(|&j| input.frames[j].codes.as_slice()).collect();
    // Channel c of the frames, read in place.
    let channel = |c: usize| response::Channel {
        frames: &frames,
        stride: 3,
        offset: c,
        times: &times,
        levels: input.levels,
    };
    let t = std::time::Instant::now();
    let mut samples = 0;
    let (response, mut method) = match &config.method {
        Method::Given(r) => {
            if r.levels != input.levels || r.g.len() != 3 || r.g.iter().any(|g| g.len() != r.levels) {
                return Err(Error::BadInput(format!(
                    "the given response has {} levels in {} channel(s); the frames need {} levels in 3",
                    r.levels,
                    r.g.len(),
                    input.levels
                )));
            }
            (r.clone(), "given".to_string())
        }
        Method::Debevec { lambda, samples_per_value, smoothness } => {
            if !(lambda.is_finite() && (0.0..=MAX_LAMBDA).contains(lambda)) {
                return Err(Error::BadInput(format!(
                    "lambda = {lambda:e}: expected 0 to {MAX_LAMBDA:e} (beyond it the curve is the smoothness prior's whatever the frames say)"
                )));
            }
            if !(1..=MAX_SAMPLES_PER_VALUE).contains(samples_per_value) {
                return Err(Error::BadInput(format!(
                    "samples_per_value = {samples_per_value}: expected 1 to {MAX_SAMPLES_PER_VALUE}"
                )));
            }
            check_fit_data(input)?;
            use rayon::prelude::*;
            let fits = (0..3)
                .into_par_iter()
                .map(|c| {
                    let ch = channel(c);
                    let s = response::choose_samples(
                        &ch,
                        input.width,
                        input.height,
                        (*samples_per_value).max(1),
                        &usable,
                    );
                    let g = response::debevec(&ch, &s, *lambda, *smoothness)
                        .map_err(|m| Error::Unsolvable(format!("channel {c}: {m}")))?;
                    Ok((g, s.len()))
                })
                .collect::<Result<Vec<_>, Error>>()?;
            samples = fits.iter().map(|f| f.1).max().unwrap_or(0);
            let g = fits.into_iter().map(|f| f.0).collect();
            (
                Response { levels: input.levels, g },
                format!("debevec (λ = {lambda}, {smoothness:?} smoothness)"),
            )
        }
        Method::Robertson { iterations } => {
            check_fit_data(input)?;
            use rayon::prelude::*;
            let g = (0..3)
                .into_par_iter()
                .map(|c| {
                    let ch = channel(c);
                    response::robertson(&ch, &usable, *iterations)
                        .map_err(|m| Error::Unsolvable(format!("channel {c}: {m}")))
                })
                .collect::<Result<Vec<_>, _>>()?;
            (Response { levels: input.levels, g }, "robertson".to_string())
        }
    };
    let mut response_s = t.elapsed().as_secs_f64();
    // Noise weights from the stack itself where asked: hat weights where it gives none.
    let t = std::time::Instant::now();
    let (mut weights, mut noise, mut weights_used) =
        resolve_weights(config.weights, &frames, &times, &response, &usable);
    let mut noise_s = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let (mut radiance, mut mask) = merge::merge(&frames, &times, &response, weights);
    let mut merge_s = t.elapsed().as_secs_f64();
    // With the noise known, a fitted curve's toe is refitted as the sensor's mean response
    // (`toe`) and the stack merged again through it.
    let mut response = response;
    let mut toe_ends = Vec::new();
    if let (Weights::Noise { full_well, read_noise }, false) =
        (weights, matches!(config.method, Method::Given(_)))
    {
        let t = std::time::Instant::now();
        for c in 0..3 {
            let Some(end) = toe::end(&response.g[c], full_well, read_noise).filter(|&e| e > 1) else {
                continue;
            };
            let ln_e: Vec<f64> = (0..n)
                .map(|i| if usable[i] { (radiance[3 * i + c] as f64).ln() } else { f64::NAN })
                .collect();
            if let Some(g) = toe::refit(&channel(c), &response.g[c], &ln_e, end) {
                response.g[c] = g;
                toe_ends.push((c, end));
            }
        }
        response_s += t.elapsed().as_secs_f64();
        if !toe_ends.is_empty() {
            // The noise seen through the final curve, as a merge given that curve sees it.
            let t = std::time::Instant::now();
            (weights, noise, weights_used) =
                resolve_weights(config.weights, &frames, &times, &response, &usable);
            noise_s += t.elapsed().as_secs_f64();
            let t = std::time::Instant::now();
            (radiance, mask) = merge::merge(&frames, &times, &response, weights);
            merge_s = t.elapsed().as_secs_f64();
        }
    }
    if !toe_ends.is_empty() {
        let ends: Vec<String> =
            toe_ends.iter().map(|(c, e)| format!("{} {e}", ["R", "G", "B"][*c])).collect();
        method += &format!("; toe refitted as the mean response below value {}", ends.join(", "));
    }
    if radiance.iter().any(|v| !v.is_finite()) {
        let (lo, hi) = response
            .g
            .iter()
            .flatten()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &g| (a.min(g), b.max(g)));
        return Err(Error::Unsolvable(format!(
            "the merge gave a radiance beyond float32's range: the response's ln exposure spans {lo:.3e} to {hi:.3e} and the times {:e} to {:e} s, so e^g / t does not fit",
            times.iter().cloned().fold(f64::INFINITY, f64::min),
            times.iter().cloned().fold(0.0, f64::max)
        )));
    }
    let t = std::time::Instant::now();
    let fusion = match &config.fusion {
        Some(p) => {
            p.validate()?;
            Some(fusion::mertens(input, p))
        }
        None => None,
    };
    let fusion_s = t.elapsed().as_secs_f64();
    let well = radiance.chunks_exact(3).zip(&mask).filter(|(_, &m)| m == merge::WELL_EXPOSED);
    let range = crate::image::luminance_range(well.map(|(p, _)| p));
    let summary = Summary {
        frames: input.frames.len(),
        width: input.width,
        height: input.height,
        levels: input.levels,
        method,
        samples,
        weights: weights_used,
        noise,
        noise_s,
        saturated_pixels: mask.iter().filter(|&&m| m == merge::SATURATED).count(),
        dark_pixels: mask.iter().filter(|&&m| m == merge::DARK).count(),
        dynamic_range_stops: range.map_or(0.0, |(lo, hi)| (hi / lo).log2()),
        response_s,
        merge_s,
        merge_megapixel_frames_per_s: (n * input.frames.len()) as f64 / 1e6 / merge_s.max(1e-9),
        fusion_s,
    };
    Ok(Output { response, radiance, mask, fusion, summary })
}

/// The merge's weights for `asked`: `NoiseFromStack` resolved to the stack's noise through
/// `response` (hat weights where it gives none), with the estimate and a description.
fn resolve_weights(
    asked: Weights,
    frames: &[&[u16]],
    times: &[f64],
    response: &Response,
    usable: &[bool],
) -> (Weights, Option<noise::Estimate>, String) {
    match asked {
        Weights::NoiseFromStack => match noise::estimate(frames, times, response, usable) {
            Some(e) => (
                Weights::Noise { full_well: e.full_well, read_noise: e.read_noise },
                Some(e),
                format!(
                    "noise (from the stack: full well {:.0} e⁻, read noise {:.2} e⁻, from {} pairs of frames in {} levels)",
                    e.full_well, e.read_noise, e.pairs, e.bins
                ),
            ),
            None => (
                Weights::Hat,
                None,
                "hat (the stack gave no noise estimate: too few levels where consecutive frames overlap with a spread above the codes' quantisation, or no positive photon noise in them)".into(),
            ),
        },
        Weights::Hat => (Weights::Hat, None, "hat".into()),
        Weights::Noise { full_well, read_noise } => (
            asked,
            None,
            format!("noise (given: full well {full_well} e⁻, read noise {read_noise} e⁻)"),
        ),
    }
}

fn check(input: &Input) -> Result<(), Error> {
    if input.frames.len() < 2 {
        return Err(Error::BadInput(format!(
            "{} frame(s): a stack needs at least 2 exposures",
            input.frames.len()
        )));
    }
    if !(2..=65536).contains(&input.levels) {
        return Err(Error::BadInput(format!("{} levels: expected 2 to 65536", input.levels)));
    }
    let n = input.width * input.height;
    if n == 0 {
        return Err(Error::BadInput("the frames have no pixels".into()));
    }
    for f in &input.frames {
        if !(f.time_s.is_finite() && (MIN_TIME_S..=MAX_TIME_S).contains(&f.time_s)) {
            return Err(Error::BadInput(format!(
                "{}: exposure time {:e} s: expected {MIN_TIME_S:e} to {MAX_TIME_S:e} s (a picosecond to eleven days; radiance is held as float32, which times far outside cannot represent)",
                f.name, f.time_s
            )));
        }
        if f.codes.len() != 3 * n {
            return Err(Error::BadInput(format!(
                "{}: {} values, expected {} ({}×{} RGB)",
                f.name,
                f.codes.len(),
                3 * n,
                input.width,
                input.height
            )));
        }
        if let Some(z) = f.codes.iter().find(|&&z| z as usize >= input.levels) {
            return Err(Error::BadInput(format!(
                "{}: code value {z} is not below {} levels",
                f.name, input.levels
            )));
        }
    }
    let mut times: Vec<f64> = input.frames.iter().map(|f| f.time_s).collect();
    times.sort_by(f64::total_cmp);
    if times.windows(2).all(|w| w[0] == w[1]) {
        return Err(Error::BadInput(format!(
            "every frame has the exposure time {} s: a stack needs at least two different times",
            times[0]
        )));
    }
    if let Some(u) = &input.usable {
        if u.len() != n {
            return Err(Error::BadInput(format!(
                "the usable-pixel mask has {} entries for {n} pixels",
                u.len()
            )));
        }
        if !u.iter().any(|&k| k) {
            return Err(Error::BadInput(
                "every pixel is left out of the fit (the excluded colour covers them all)".into(),
            ));
        }
    }
    if input.frames.windows(2).all(|w| w[0].codes == w[1].codes) {
        return Err(Error::BadInput(format!(
            "all {} frames hold the same values, yet their times differ: nothing in the stack changes with exposure (the same file given several times?)",
            input.frames.len()
        )));
    }
    // A longer exposure collects more light: a stack whose longest frame is darker than its
    // shortest has its times in another order than its frames.
    let mean = |f: &Frame| f.codes.iter().map(|&z| z as f64).sum::<f64>() / f.codes.len() as f64;
    let by_time = |a: &&Frame, b: &&Frame| a.time_s.total_cmp(&b.time_s);
    if let (Some(short), Some(long)) =
        (input.frames.iter().min_by(by_time), input.frames.iter().max_by(by_time))
    {
        if mean(long) < mean(short) {
            return Err(Error::BadInput(format!(
                "{} ({} s) is darker than {} ({} s) (mean value {:.1} against {:.1}): a longer exposure cannot be darker; are the times in the frames' order?",
                long.name,
                long.time_s,
                short.name,
                short.time_s,
                mean(long),
                mean(short)
            )));
        }
    }
    Ok(())
}

/// Debevec & Malik's condition for the data alone to determine a response of `bins` values:
/// N(P − 1) ≥ Z_max − Z_min over N pixels and P frames (their section 2.1).
fn check_fit_data(input: &Input) -> Result<(), Error> {
    let bins = input.levels.min(response::MAX_FIT_LEVELS);
    let (n, p) = (input.width * input.height, input.frames.len());
    if n * (p - 1) < bins - 1 {
        return Err(Error::BadInput(format!(
            "{n} pixel(s) in {p} frames: fitting a response of {bins} values needs N(P − 1) ≥ {} (Debevec & Malik), here {}; give larger frames, more frames, or a response to use as it is",
            bins - 1,
            n * (p - 1)
        )));
    }
    Ok(())
}
