//! Denoising Monte Carlo images with weights computed from the pixels' own noise.
//!
//! Three methods, one weighted average (`kernel`'s docs give the formulas):
//! - **bilateral**: a spatial Gaussian times a range term from which the noise variance is
//!   removed, pixel to pixel (patch radius 0);
//! - **nlmeans**: non-local means with the variance-cancelling distance averaged over patches
//!   (Rousselle, Knaus & Zwicker 2012, "Adaptive rendering with non-local means filtering");
//! - **feature**: the nlmeans colour weight combined, by the minimum, with cross-bilateral
//!   weights on feature buffers (albedo, normal, depth), each normalised by its own variance
//!   and gradient (Rousselle, Manzi & Zwicker 2013, "Robust denoising using feature and color
//!   information").
//!
//! **Variance.** The filters need the variance of each pixel's mean. Given only a variance
//! image, the weights come from the noisy image itself. Given two half buffers A and B (each
//! the mean of half the samples), the variance is made robust and the filtering unbiased in
//! its weights, as RMZ13 do:
//! - the sample variance's shape is kept and its level set by the two-buffer estimate:
//!   Var_half = G₁(2·Var) · G₂((A − B)²/2) / G₂(2·Var), Gₛ a Gaussian of σ = s px (where
//!   there is no sample variance, G₂((A − B)²/2) itself). G₁ spreads the variance of a
//!   pixel's neighbours to a pixel whose few samples happened to agree;
//! - A is filtered with B's weights and B with A's, and the output is their mean. Each
//!   filter's weights are then independent of the data it averages.
//!
//! **Strengths and SURE.** Several strengths s (k and k_f scaled by s) are filtered at once.
//! Per pixel, the one with the smallest Stein's unbiased risk estimate is kept (Li, Wu &
//! Chuang 2012; RMZ13):
//!
//!   SURE(p) = Σᵢ (Fᵢ(p) − yᵢ(p))² + 2·Varᵢ(p)·∂Fᵢ(p)/∂yᵢ(p) − Varᵢ(p),   ∂F(p)/∂y(p) = w(p,p)/Σ_q w(p,q)
//!
//! The derivative is exact for cross-filtered halves (the weights do not depend on the data
//! they average) and a first-order approximation otherwise. The unfiltered image is one more
//! candidate (F = y: its risk is Var), so a pixel that every strength would move further
//! than its noise allows is kept as it was: a quiet pixel beside fireflies, whose spread
//! variance lets the weights take in their light. SURE maps are smoothed (Gaussian,
//! σ = 1.5 px) before the choice, and the one-hot choice maps are smoothed (σ = 1 px) and
//! used as blending weights, so no seam shows where the choice changes. Nothing here reads a
//! reference image.
//!
//! **No noise.** An image whose variance is 0 at every pixel (and no half buffers) is known
//! exactly: it comes back as it went in. A single pixel of zero variance is not: in a Monte
//! Carlo render it is most often one whose few samples all missed the light, and it is
//! filtered like the others.
//!
//! Hand-written rather than taken from a crate: no Rust crate has a variance-aware NL-means
//! or feature-guided filter; OIDN, the peer, is a trained network on another runtime.

pub mod kernel;

use super::filter::Grey;
use super::Image;
use crate::error::{Fault, Invalid};
use kernel::{FeatureGuide, Guide, Params, Planes};
use serde::{Deserialize, Serialize};

/// Which filter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    Bilateral,
    Nlmeans,
    Feature,
}

impl Method {
    pub const ALL: [Method; 3] = [Method::Bilateral, Method::Nlmeans, Method::Feature];

    pub fn name(self) -> &'static str {
        match self {
            Method::Bilateral => "bilateral",
            Method::Nlmeans => "nlmeans",
            Method::Feature => "feature",
        }
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Method {
    type Err = Invalid;
    fn from_str(s: &str) -> Result<Method, Invalid> {
        Method::ALL.into_iter().find(|m| m.name() == s).ok_or_else(|| {
            Invalid(format!("`{s}` is not a denoising method: expected bilateral, nlmeans or feature"))
        })
    }
}

/// The filter's settings (`[denoise]` in a pipeline case, flags of `lumen denoise`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Settings {
    /// The method; by default the best the inputs allow (feature when a feature buffer is
    /// given, nlmeans otherwise).
    pub method: Option<Method>,
    /// Patch radius f in pixels, for nlmeans and feature (default 3: 7×7 patches, RKZ12's).
    /// The bilateral filter compares single pixels: its patch radius is 0.
    pub patch_radius: Option<u32>,
    /// Window radius r in pixels: neighbours within (2r+1)² (default 10, RKZ12's). At most 50.
    pub window_radius: u32,
    /// Colour sensitivity k (default 0.45, RKZ12's): larger smooths more.
    pub k: f32,
    /// Feature sensitivity k_f (default 0.6, RMZ13's).
    pub k_feature: f32,
    /// Floor τ of the feature normaliser (default 1e-3, RMZ13's), in the feature's squared units.
    pub tau: f32,
    /// Spatial σ_s of the bilateral filter in pixels (default r / 2).
    pub spatial_sigma: Option<f32>,
    /// Strength multipliers of k and k_f tried per pixel, chosen by SURE (default 0.5, 1, 2).
    /// One value: no choice.
    pub strengths: Vec<f32>,
}

impl Default for Settings {
    fn default() -> Settings {
        Settings {
            method: None,
            patch_radius: None,
            window_radius: 10,
            k: 0.45,
            k_feature: 0.6,
            tau: 1e-3,
            spatial_sigma: None,
            strengths: vec![0.5, 1.0, 2.0],
        }
    }
}

/// Largest window radius accepted: (2·50+1)² = 10201 neighbours per pixel already takes
/// minutes per megapixel.
pub const MAX_WINDOW: u32 = 50;
/// Largest patch radius accepted.
pub const MAX_PATCH: u32 = 10;

/// A feature buffer (albedo, normal, depth …) and the variance of its pixel means, if known.
pub struct Feature<'a> {
    pub name: String,
    pub image: &'a Image,
    pub variance: Option<&'a Image>,
}

/// What to denoise.
pub struct Input<'a> {
    /// The noisy image: the mean of each pixel's samples.
    pub color: &'a Image,
    /// The variance of each pixel's mean (not of one sample), per channel.
    pub variance: Option<&'a Image>,
    /// Two half buffers, each the mean of half the samples (their mean is `color`).
    pub halves: Option<[&'a Image; 2]>,
    pub features: Vec<Feature<'a>>,
}

/// The denoised image and what was done.
#[derive(Clone, Debug)]
pub struct Output {
    pub image: Image,
    pub method: Method,
    /// Whether the two half buffers were cross-filtered.
    pub halves: bool,
    /// The strengths tried, and the share of pixels SURE gave to each.
    pub strengths: Vec<f32>,
    pub chosen: Vec<f64>,
    /// Whether the image was passed through unchanged (its variance is 0 everywhere).
    pub unchanged: bool,
}

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{0}")]
    Invalid(#[from] Invalid),
    #[error("denoising {width}×{height} pixels needs about {:.1} GB, which could not be allocated", *bytes as f64 / 1e9)]
    Memory { width: u32, height: u32, bytes: u64 },
}

impl Error {
    pub fn fault(&self) -> Fault {
        Fault::BadInput
    }
}

impl Settings {
    /// The method these settings and inputs give, or why none.
    pub fn method_for(&self, features: usize) -> Result<Method, Invalid> {
        let m = self.method.unwrap_or(if features > 0 { Method::Feature } else { Method::Nlmeans });
        if m == Method::Feature && features == 0 {
            return Err(
                "the feature method needs at least one feature buffer (albedo, normal or depth)".into()
            );
        }
        Ok(m)
    }

    pub fn validate(&self) -> Result<(), Invalid> {
        if self.window_radius > MAX_WINDOW {
            return Err(format!(
                "window radius {} is above the largest accepted, {MAX_WINDOW}",
                self.window_radius
            )
            .into());
        }
        if let Some(f) = self.patch_radius {
            if f > MAX_PATCH {
                return Err(format!("patch radius {f} is above the largest accepted, {MAX_PATCH}").into());
            }
            if f > 0 && self.method == Some(Method::Bilateral) {
                return Err(
                    format!("patch radius {f}: the bilateral filter compares single pixels (0)").into()
                );
            }
        }
        let positive = |name: &str, v: f32| -> Result<(), Invalid> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("{name} = {v}: expected a positive finite number").into())
            }
        };
        positive("k", self.k)?;
        positive("k_feature", self.k_feature)?;
        positive("tau", self.tau)?;
        if let Some(s) = self.spatial_sigma {
            positive("spatial_sigma", s)?;
        }
        if self.strengths.is_empty() || self.strengths.len() > 8 {
            return Err(format!("{} strengths: expected 1 to 8", self.strengths.len()).into());
        }
        for &s in &self.strengths {
            positive("strength", s)?;
        }
        Ok(())
    }
}

/// Denoises `input` with `settings`.
pub fn denoise(input: &Input, settings: &Settings) -> Result<Output, Error> {
    settings.validate()?;
    let method = settings.method_for(input.features.len())?;
    let color = input.color;
    let (w, h, c) = (color.width as usize, color.height as usize, color.channels as usize);
    let ns = settings.strengths.len();
    // Peak memory, roughly: the planar copies of colour, variance, halves and features, and one
    // filtered image with its centre shares per strength and half.
    let feature_channels: usize = input.features.iter().map(|f| 2 * f.image.channels as usize + 1).sum();
    let planes = 4 * c + 4 * c + feature_channels + 2 * ns * (c + 1) + 2 * ns + 4;
    let bytes = (w * h) as u64 * planes as u64 * 4;
    if Vec::<u8>::new().try_reserve_exact(bytes as usize).is_err() {
        return Err(Error::Memory { width: color.width, height: color.height, bytes });
    }
    check_inputs(input)?;
    let params = Params {
        patch: match method {
            Method::Bilateral => 0,
            _ => settings.patch_radius.unwrap_or(3) as usize,
        },
        window: settings.window_radius as usize,
        k: settings.k,
        spatial_sigma: match method {
            Method::Bilateral => {
                Some(settings.spatial_sigma.unwrap_or((settings.window_radius as f32 / 2.0).max(0.5)))
            }
            _ => settings.spatial_sigma,
        },
        strengths: settings.strengths.clone(),
    };
    let features: Vec<FeatureGuide> = match method {
        Method::Feature => input.features.iter().map(|f| feature_guide(f, settings)).collect(),
        _ => Vec::new(),
    };
    let y = planes_of(color);
    let var = match input.variance {
        Some(v) => Some(planes_of(v)),
        None => None,
    };

    // Per strength: the filtered image and its SURE map.
    let mut candidates: Vec<(Planes, Vec<f32>)> = Vec::with_capacity(ns);
    let halves = input.halves.is_some();
    if let (None, Some(v)) = (input.halves, var.as_ref()) {
        if v.data.iter().all(|&x| x == 0.0) {
            return Ok(Output {
                image: color.clone(),
                method,
                halves,
                strengths: settings.strengths.clone(),
                chosen: vec![0.0; ns],
                unchanged: true,
            });
        }
    }
    match input.halves {
        Some([a, b]) => {
            let (a, b) = (planes_of(a), planes_of(b));
            let vh = half_variance(&a, &b, var.as_ref());
            let fa = kernel::filter(&Guide { color: &b, variance: &vh, features: &features }, &a, &params);
            let fb = kernel::filter(&Guide { color: &a, variance: &vh, features: &features }, &b, &params);
            for ((ya, ca), (yb, cb)) in fa.into_iter().zip(fb) {
                let mut sure = sure_map(&ya, &a, &vh, &ca);
                for (s, t) in sure.iter_mut().zip(sure_map(&yb, &b, &vh, &cb)) {
                    *s += t;
                }
                let mean = Planes {
                    w,
                    h,
                    c,
                    data: ya.data.iter().zip(&yb.data).map(|(p, q)| 0.5 * (p + q)).collect(),
                };
                candidates.push((mean, sure));
            }
            // Each half's SURE was summed: so is the unfiltered candidate's.
            candidates.push(unfiltered(&y, &vh, 2.0));
        }
        None => {
            let Some(v) = var.as_ref() else {
                return Err(Invalid(
                    "no noise level given: the filters need the variance of each pixel's mean, or two half buffers".into(),
                )
                .into());
            };
            for (f, centre) in
                kernel::filter(&Guide { color: &y, variance: v, features: &features }, &y, &params)
            {
                let sure = sure_map(&f, &y, v, &centre);
                candidates.push((f, sure));
            }
            candidates.push(unfiltered(&y, v, 1.0));
        }
    }
    let (blend, chosen) = choose(&candidates, w, h);
    let mut out = Image::new(color.width, color.height, color.channels);
    for (p, px) in out.data.chunks_exact_mut(c).enumerate() {
        for (ch, v) in px.iter_mut().enumerate() {
            *v = candidates.iter().zip(&blend).map(|((f, _), b)| b[p] * f.data[ch * w * h + p]).sum();
        }
    }
    Ok(Output { image: out, method, halves, strengths: settings.strengths.clone(), chosen, unchanged: false })
}

/// Sizes, channel counts and values: everything the filters assume, checked with the name of
/// what is wrong.
fn check_inputs(input: &Input) -> Result<(), Invalid> {
    let color = input.color;
    if color.width == 0 || color.height == 0 {
        return Err(
            format!("the image is {}×{}: expected at least one pixel", color.width, color.height).into()
        );
    }
    if color.channels == 0 || color.channels > 4 {
        return Err(format!("the image has {} channels: expected 1 to 4", color.channels).into());
    }
    let same_size = |name: &str, img: &Image, channels: &[u32]| -> Result<(), Invalid> {
        if (img.width, img.height) != (color.width, color.height) {
            return Err(format!(
                "{name} is {}×{}, the image {}×{}: expected the same size",
                img.width, img.height, color.width, color.height
            )
            .into());
        }
        if !channels.contains(&img.channels) {
            let want: Vec<String> = channels.iter().map(|c| c.to_string()).collect();
            return Err(
                format!("{name} has {} channels: expected {}", img.channels, want.join(" or ")).into()
            );
        }
        Ok(())
    };
    let finite = |name: &str, img: &Image| -> Result<(), Invalid> {
        match img.data.iter().position(|v| !v.is_finite()) {
            Some(i) => {
                let p = i / img.channels as usize;
                Err(format!(
                    "{name} has a non-finite value ({}) at pixel ({}, {}): expected finite numbers",
                    img.data[i],
                    p % img.width as usize,
                    p / img.width as usize
                )
                .into())
            }
            None => Ok(()),
        }
    };
    let variance = |name: &str, img: &Image| -> Result<(), Invalid> {
        finite(name, img)?;
        match img.data.iter().position(|&v| v < 0.0) {
            Some(i) => {
                let p = i / img.channels as usize;
                Err(format!(
                    "{name} is negative ({}) at pixel ({}, {}): a variance is ≥ 0",
                    img.data[i],
                    p % img.width as usize,
                    p / img.width as usize
                )
                .into())
            }
            None => Ok(()),
        }
    };
    finite("the image", color)?;
    if let Some(v) = input.variance {
        same_size("the variance", v, &[color.channels])?;
        variance("the variance", v)?;
    }
    if let Some([a, b]) = input.halves {
        for (name, img) in [("the first half buffer", a), ("the second half buffer", b)] {
            same_size(name, img, &[color.channels])?;
            finite(name, img)?;
        }
    }
    for f in &input.features {
        same_size(&f.name, f.image, &[1, 2, 3, 4])?;
        finite(&f.name, f.image)?;
        if let Some(v) = f.variance {
            let name = format!("{} variance", f.name);
            same_size(&name, v, &[f.image.channels])?;
            variance(&name, v)?;
        }
    }
    Ok(())
}

fn planes_of(img: &Image) -> Planes {
    let (w, h, c) = (img.width as usize, img.height as usize, img.channels as usize);
    let mut data = vec![0.0f32; w * h * c];
    for (p, px) in img.data.chunks_exact(c).enumerate() {
        for (ch, &v) in px.iter().enumerate() {
            data[ch * w * h + p] = v;
        }
    }
    Planes { w, h, c, data }
}

fn grey(w: usize, h: usize, data: Vec<f32>) -> Grey {
    Grey { width: w, height: h, data }
}

/// The variance of one half buffer's pixel means (module docs).
fn half_variance(a: &Planes, b: &Planes, var: Option<&Planes>) -> Planes {
    let (w, h, c) = (a.w, a.h, a.c);
    let n = w * h;
    let mut out = Vec::with_capacity(n * c);
    for ch in 0..c {
        let (pa, pb) = (a.plane(ch), b.plane(ch));
        let two_buffer: Vec<f32> = pa.iter().zip(pb).map(|(x, y)| 0.5 * (x - y) * (x - y)).collect();
        let g_two = grey(w, h, two_buffer).blur(2.0).data;
        match var {
            Some(v) => {
                let sample: Vec<f32> = v.plane(ch).iter().map(|x| 2.0 * x).collect();
                let g_sample = grey(w, h, sample.clone()).blur(2.0).data;
                let spread = grey(w, h, sample).blur(1.0).data;
                out.extend(spread.iter().zip(&g_two).zip(&g_sample).map(|((&s, &t), &gs)| {
                    if gs > 0.0 {
                        s * t / gs
                    } else {
                        t
                    }
                }));
            }
            None => out.extend(g_two),
        }
    }
    Planes { w, h, c, data: out }
}

/// SURE per pixel (module docs), summed over channels.
fn sure_map(f: &Planes, y: &Planes, var: &Planes, centre: &[f32]) -> Vec<f32> {
    let n = f.w * f.h;
    let mut out = vec![0.0f32; n];
    for ch in 0..f.c {
        let (pf, py, pv) = (f.plane(ch), y.plane(ch), var.plane(ch));
        for p in 0..n {
            let d = pf[p] - py[p];
            out[p] += d * d + 2.0 * pv[p] * centre[p] - pv[p];
        }
    }
    out
}

/// The unfiltered image as a candidate, its SURE `halves` × its variance (F = y, ∂F/∂y = 1):
/// where every strength moves a pixel further than its noise allows, SURE keeps the pixel as
/// it was.
fn unfiltered(y: &Planes, var: &Planes, halves: f32) -> (Planes, Vec<f32>) {
    let mut sure = sure_map(y, y, var, &vec![1.0; y.w * y.h]);
    for s in &mut sure {
        *s *= halves;
    }
    (y.clone(), sure)
}

/// Per-pixel blending weights of the candidates from their smoothed SURE maps, and the share
/// of pixels each won.
fn choose(candidates: &[(Planes, Vec<f32>)], w: usize, h: usize) -> (Vec<Vec<f32>>, Vec<f64>) {
    let n = w * h;
    if candidates.len() == 1 {
        return (vec![vec![1.0; n]], vec![1.0]);
    }
    let smoothed: Vec<Vec<f32>> =
        candidates.iter().map(|(_, s)| grey(w, h, s.clone()).blur(1.5).data).collect();
    let mut onehot = vec![vec![0.0f32; n]; candidates.len()];
    let mut wins = vec![0usize; candidates.len()];
    for p in 0..n {
        let best =
            (0..candidates.len()).min_by(|&i, &j| smoothed[i][p].total_cmp(&smoothed[j][p])).unwrap_or(0);
        onehot[best][p] = 1.0;
        wins[best] += 1;
    }
    let mut blend: Vec<Vec<f32>> = onehot.into_iter().map(|m| grey(w, h, m).blur(1.0).data).collect();
    // The blurred one-hot maps sum to 1 up to rounding; divided by their sum, a pixel whose
    // neighbourhood chose one candidate takes exactly that candidate's value.
    for p in 0..n {
        let total: f32 = blend.iter().map(|b| b[p]).sum();
        for b in blend.iter_mut() {
            b[p] /= total;
        }
    }
    (blend, wins.iter().map(|&k| k as f64 / n as f64).collect())
}

/// A feature's guide: its planes, its variance (0 when not given), and the normaliser.
fn feature_guide(f: &Feature, settings: &Settings) -> FeatureGuide {
    let value = planes_of(f.image);
    let (w, h, c) = (value.w, value.h, value.c);
    let variance = match f.variance {
        Some(v) => planes_of(v),
        None => Planes { w, h, c, data: vec![0.0; w * h * c] },
    };
    let kf2 = settings.k_feature * settings.k_feature;
    let mut inv_norm = vec![0.0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            let p = y * w + x;
            let (xl, xr) = (x.saturating_sub(1), (x + 1).min(w - 1));
            let (yu, yd) = (y.saturating_sub(1), (y + 1).min(h - 1));
            let mut grad2 = 0.0;
            let mut var = 0.0;
            for ch in 0..c {
                let pl = value.plane(ch);
                let gx = (pl[y * w + xr] - pl[y * w + xl]) / (xr - xl).max(1) as f32;
                let gy = (pl[yd * w + x] - pl[yu * w + x]) / (yd - yu).max(1) as f32;
                grad2 += gx * gx + gy * gy;
                var += variance.plane(ch)[p];
            }
            let norm = settings.tau.max(var / c as f32).max(grad2 / c as f32);
            inv_norm[p] = 1.0 / (kf2 * norm);
        }
    }
    FeatureGuide { value, variance, inv_norm }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// `truth` plus Gaussian noise of standard deviation `sigma`, and the variance image.
    fn noisy(truth: &Image, sigma: f32, seed: u64) -> (Image, Image) {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let normal = Normal::new(0.0f32, sigma).unwrap();
        let mut img = truth.clone();
        for v in &mut img.data {
            *v += normal.sample(&mut rng);
        }
        let mut var = truth.clone();
        var.data.fill(sigma * sigma);
        (img, var)
    }

    fn constant(w: u32, h: u32, v: f32) -> Image {
        let mut img = Image::new(w, h, 3);
        img.data.fill(v);
        img
    }

    fn mean_std(data: &[f32]) -> (f64, f64) {
        let n = data.len() as f64;
        let m = data.iter().map(|&v| v as f64).sum::<f64>() / n;
        let v = data.iter().map(|&v| (v as f64 - m).powi(2)).sum::<f64>() / (n - 1.0);
        (m, v.sqrt())
    }

    /// On a constant image with known noise, every method keeps the mean (within four
    /// standard errors of the noisy input's own mean) and removes noise as an average over
    /// at least four independent pixels would.
    #[test]
    fn constant_image_keeps_its_mean() {
        let truth = constant(64, 48, 0.5);
        let sigma = 0.1f32;
        let (img, var) = noisy(&truth, sigma, 7);
        let n = img.data.len() as f64;
        let se = sigma as f64 / n.sqrt();
        for method in [Method::Bilateral, Method::Nlmeans] {
            let settings = Settings { method: Some(method), ..Settings::default() };
            let input = Input { color: &img, variance: Some(&var), halves: None, features: vec![] };
            let out = denoise(&input, &settings).unwrap();
            let (m, s) = mean_std(&out.image.data);
            assert!((m - 0.5).abs() < 4.0 * se, "{method}: mean {m} (standard error {se})");
            assert!(s < sigma as f64 / 2.0, "{method}: standard deviation {s} of {sigma}");
        }
    }

    /// Cross-filtered halves keep the mean of a constant image too.
    #[test]
    fn halves_keep_the_mean() {
        let truth = constant(64, 48, 0.5);
        let sigma = 0.1f32;
        let (a, _) = noisy(&truth, sigma, 1);
        let (b, _) = noisy(&truth, sigma, 2);
        let color =
            Image { data: a.data.iter().zip(&b.data).map(|(x, y)| 0.5 * (x + y)).collect(), ..a.clone() };
        let mut var = truth.clone();
        var.data.fill(sigma * sigma / 2.0);
        let input = Input { color: &color, variance: Some(&var), halves: Some([&a, &b]), features: vec![] };
        let out = denoise(&input, &Settings::default()).unwrap();
        assert!(out.halves);
        let n = color.data.len() as f64;
        let se = sigma as f64 / (2.0 * n).sqrt();
        let (m, s) = mean_std(&out.image.data);
        assert!((m - 0.5).abs() < 4.0 * se, "mean {m} (standard error {se})");
        assert!(s < sigma as f64 / 4.0, "standard deviation {s}");
    }

    /// A step between two flat regions stays where it was: averaged over rows, every pixel
    /// one or more pixels from the step is within a tenth of the step of its true value.
    #[test]
    fn an_edge_stays_within_one_pixel() {
        let (w, h) = (48u32, 48u32);
        let mut truth = Image::new(w, h, 3);
        for y in 0..h {
            for x in 0..w {
                truth.pixel_mut(x, y).fill(if x < 24 { 0.2 } else { 0.8 });
            }
        }
        let (img, var) = noisy(&truth, 0.05, 3);
        for method in Method::ALL {
            let mut features = vec![];
            if method == Method::Feature {
                features.push(Feature { name: "albedo".into(), image: &truth, variance: None });
            }
            let settings = Settings { method: Some(method), ..Settings::default() };
            let input = Input { color: &img, variance: Some(&var), halves: None, features };
            let out = denoise(&input, &settings).unwrap();
            for x in (0..w).filter(|&x| x != 23 && x != 24) {
                let mean = (0..h).map(|y| out.image.pixel(x, y)[1] as f64).sum::<f64>() / h as f64;
                let want = truth.pixel(x, 0)[1] as f64;
                assert!((mean - want).abs() < 0.06, "{method}: column {x}: {mean} for {want}");
            }
        }
    }

    /// A stripe a thousand times brighter than the rest, with a noise far below the step: the
    /// patch distances across its edge reach 10¹⁰, and the pixels whose window never reaches
    /// it must come out as they do without the stripe (no residue of those distances in the
    /// running box sums along rows and columns).
    #[test]
    fn a_far_edge_leaves_no_residue() {
        let (w, h) = (64u32, 48u32);
        let (plain, var) = noisy(&constant(w, h, 0.5), 0.01, 11);
        let mut striped = plain.clone();
        for y in 0..h {
            for x in 0..w {
                if x < 8 || y < 8 {
                    striped.pixel_mut(x, y).fill(1000.0);
                }
            }
        }
        for method in Method::ALL {
            let settings = Settings { method: Some(method), ..Settings::default() };
            let run = |img: &Image| {
                let mut features = vec![];
                if method == Method::Feature {
                    features.push(Feature { name: "albedo".into(), image: &var, variance: None });
                }
                let input = Input { color: img, variance: Some(&var), halves: None, features };
                denoise(&input, &settings).unwrap().image
            };
            let (a, b) = (run(&plain), run(&striped));
            let reach = 8 + settings.window_radius + settings.patch_radius.unwrap_or(3);
            for y in reach..h {
                for x in reach..w {
                    let (p, q) = (a.pixel(x, y)[0], b.pixel(x, y)[0]);
                    assert!(
                        (p - q).abs() < 1e-6,
                        "{method}: pixel ({x}, {y}): {q} beside the stripe, {p} without"
                    );
                }
            }
        }
    }

    /// A variance of zero everywhere means no noise: the image comes back as it went in.
    #[test]
    fn zero_variance_is_the_identity() {
        let (img, _) = noisy(&constant(20, 10, 0.3), 0.2, 5);
        let var = Image::new(20, 10, 3);
        let out = denoise(
            &Input { color: &img, variance: Some(&var), halves: None, features: vec![] },
            &Settings::default(),
        )
        .unwrap();
        assert_eq!(out.image, img);
        assert!(out.unchanged);
        // One black pixel of zero variance among noisy ones (all its samples missed the
        // light) is filtered like the others, not kept black.
        let (mut img, mut var) = noisy(&constant(20, 10, 0.3), 0.1, 5);
        let p = 3 * (5 * 20 + 10);
        img.data[p..p + 3].fill(0.0);
        var.data[p..p + 3].fill(0.0);
        let out = denoise(
            &Input { color: &img, variance: Some(&var), halves: None, features: vec![] },
            &Settings::default(),
        )
        .unwrap();
        assert!(!out.unchanged);
        assert!(out.image.data[p] > 0.15, "{}", out.image.data[p]);
    }

    #[test]
    fn one_pixel_and_zero_radii() {
        let img = constant(1, 1, 0.7);
        let mut var = img.clone();
        var.data.fill(0.01);
        let out = denoise(
            &Input { color: &img, variance: Some(&var), halves: None, features: vec![] },
            &Settings::default(),
        )
        .unwrap();
        assert_eq!(out.image, img);
        let (img, var) = noisy(&constant(9, 7, 0.5), 0.1, 9);
        let settings = Settings { window_radius: 0, patch_radius: Some(0), ..Settings::default() };
        let out =
            denoise(&Input { color: &img, variance: Some(&var), halves: None, features: vec![] }, &settings)
                .unwrap();
        assert_eq!(out.image, img);
    }

    /// A 16384 × 16384 image under an 8 GB address-space limit: refused with the size and the
    /// memory it would need, before any filtering. The check runs in a child process of this
    /// test binary, so the limit binds only it.
    #[test]
    fn a_16k_image_under_a_memory_limit_is_refused() {
        const CHILD: &str = "LUMEN_DENOISE_MEMORY_LIMIT_CHILD";
        if std::env::var_os(CHILD).is_none() {
            let name = "image::denoise::tests::a_16k_image_under_a_memory_limit_is_refused";
            let out = std::process::Command::new(std::env::current_exe().unwrap())
                .args([name, "--exact", "--nocapture", "--test-threads", "1"])
                .env(CHILD, "1")
                .output()
                .unwrap();
            let text =
                format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
            assert!(out.status.success() && text.contains("1 passed"), "{text}");
            return;
        }
        let limit = libc::rlimit { rlim_cur: 8 << 30, rlim_max: 8 << 30 };
        assert_eq!(unsafe { libc::setrlimit(libc::RLIMIT_AS, &limit) }, 0);
        // Zeroed allocations: the pages are not touched until read.
        let img = Image::new(16384, 16384, 3);
        let var = Image::new(16384, 16384, 3);
        let input = Input { color: &img, variance: Some(&var), halves: None, features: vec![] };
        let e = denoise(&input, &Settings::default()).unwrap_err().to_string();
        assert!(e.starts_with("denoising 16384×16384 pixels needs about"), "{e}");
        assert!(e.contains("which could not be allocated"), "{e}");
    }

    #[test]
    fn bad_inputs_are_named() {
        let (img, var) = noisy(&constant(8, 8, 0.5), 0.1, 4);
        let err = |input: &Input, settings: &Settings| denoise(input, settings).unwrap_err().to_string();
        let d = Settings::default();
        let small = constant(4, 8, 0.01);
        let e = err(&Input { color: &img, variance: Some(&small), halves: None, features: vec![] }, &d);
        assert!(e.contains("the variance is 4×8, the image 8×8"), "{e}");
        let mut neg = var.clone();
        neg.data[3 * 9 + 1] = -1.0;
        let e = err(&Input { color: &img, variance: Some(&neg), halves: None, features: vec![] }, &d);
        assert!(e.contains("negative (-1) at pixel (1, 1)"), "{e}");
        let mut nan = var.clone();
        nan.data[0] = f32::NAN;
        let e = err(&Input { color: &img, variance: Some(&nan), halves: None, features: vec![] }, &d);
        assert!(e.contains("non-finite value (NaN) at pixel (0, 0)"), "{e}");
        let e = err(&Input { color: &img, variance: None, halves: None, features: vec![] }, &d);
        assert!(e.contains("no noise level given"), "{e}");
        let big = Settings { window_radius: 1_000_000, ..Settings::default() };
        let e = err(&Input { color: &img, variance: Some(&var), halves: None, features: vec![] }, &big);
        assert!(e.contains("window radius 1000000 is above"), "{e}");
        let big = Settings { patch_radius: Some(1_000_000), ..Settings::default() };
        let e = err(&Input { color: &img, variance: Some(&var), halves: None, features: vec![] }, &big);
        assert!(e.contains("patch radius 1000000 is above"), "{e}");
        let feature = Settings { method: Some(Method::Feature), ..Settings::default() };
        let e = err(&Input { color: &img, variance: Some(&var), halves: None, features: vec![] }, &feature);
        assert!(e.contains("needs at least one feature"), "{e}");
        let wrong = Image::new(8, 9, 3);
        let features = vec![Feature { name: "the normal".into(), image: &wrong, variance: None }];
        let e = err(&Input { color: &img, variance: Some(&var), halves: None, features }, &d);
        assert!(e.contains("the normal is 8×9"), "{e}");
    }
}
