//! Camera response recovery from an exposure stack: g(Z) = ln f⁻¹(Z), the log exposure that
//! gives pixel value Z, per channel.
//!
//! - **Debevec & Malik**, "Recovering high dynamic range radiance maps from photographs",
//!   SIGGRAPH 1997: least squares over sample pixels i and frames j,
//!
//!     Σᵢⱼ {w(Zᵢⱼ)·[g(Zᵢⱼ) − ln Eᵢ − ln Δtⱼ]}² + λ Σ_z [w(z)·g″(z)]²,  g(z_mid) = 0,
//!
//!   with the hat weight w(z) = min(z − z_min, z_max − z) that is 0 at both ends (so clipped
//!   and black values carry no data). Two departures from the paper:
//!   - g″ is taken in the logit of the value, u = ln(z/(N − z)) for N levels, not in z
//!     (`Smoothness::Logit`, the default; `Even` is the paper's).
//!     Curves are nearly straight in u: a power law or an sRGB toe is g ≈ γ·ln z at the dark
//!     end, where its second difference in z is −γ/z² and an even-z penalty flattens it;
//!     a shoulder is g ≈ −(N − z)/(N·f′) at the bright end, whose curvature in u vanishes.
//!     A strong λ then costs the true curve little while it suppresses the ripples periodic
//!     in ln exposure that equal exposure ratios leave free (Grossberg & Nayar 2003). At the
//!     middle value the penalty weighs as the paper's even second difference. Where the
//!     exposure ratios differ and noise is low, nothing is left free and a weak λ suffices:
//!     there the paper's even penalty is as good or better near a steep shoulder.
//!   - The normal equations are reduced to g alone: each ln Eᵢ enters only its own rows, so
//!     its block is diagonal and its Schur complement leaves a dense system of one row per
//!     value (Cholesky), whatever the number of samples.
//!
//!   Samples are chosen to cover the whole range of values: for every value z of the middle frame, the
//!   pixel nearest the image's centre of those that show z there, then pixels of the other
//!   frames for values the middle one lacks, never random pixels; only pixels whose values
//!   grow with the exposure time are candidates.
//! - **Robertson, Borman & Stevenson**, "Estimation-theoretic approach to dynamic range
//!   enhancement using multiple exposures", J. Electronic Imaging 12(2), 2003: alternating
//!   Eᵢ = Σⱼ w tⱼ I(Zᵢⱼ) / Σⱼ w tⱼ² and I(m) = mean of Eᵢ tⱼ over the (i, j) with Zᵢⱼ = m, over
//!   every pixel, with the same hat weights (Robertson's Gaussian-like weights make the same
//!   point: the ends carry nothing), normalised to I(z_mid) = 1, until g changes by less than
//!   10⁻⁴ (a hundredth of a percent in exposure). With equal exposure ratios g is fixed only
//!   up to a function periodic in ln exposure (Grossberg & Nayar 2003), which Robertson's
//!   iteration lets grow into ripples; ln I is smoothed by a [1 4 6 4 1]/16 filter after each
//!   update (Debevec's λ term does the same for his fit).
//!
//! Values that never occur with a non-zero weight (among the sample pixels for Debevec's fit,
//! among all usable pixels for Robertson's: below the darkest or above the brightest value
//! seen, or gaps between) have no data: gaps are filled by linear interpolation of g,
//! and the ends by continuing g with the mean slope of the 8 nearest observed values. The
//! curve is then made strictly increasing (pool-adjacent-violators on g, then a rise of at
//! least 10⁻⁶ per value), so every value maps to a finite exposure and larger values to
//! larger exposures.
//!
//! Inputs above 10 bits are binned to 1024 levels for the fit (a 65536-level system would be
//! mostly empty); g is then interpolated between bin centres.

use super::Error;
use crate::error::Invalid;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// A response: g per channel over `levels` code values, ln exposure (arbitrary offset per
/// channel: g(z_mid) = 0 after recovery).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Response {
    pub levels: usize,
    pub g: Vec<Vec<f64>>,
}

impl Response {
    /// ln exposure of code value `z` in channel `c`.
    pub fn ln_exposure(&self, c: usize, z: u16) -> f64 {
        self.g[c][(z as usize).min(self.levels - 1)]
    }
}

/// Largest number of levels a fit solves for; finer codes are binned.
pub const MAX_FIT_LEVELS: usize = 1024;

/// The hat weight of a code value among `levels`: 0 at both ends, largest in the middle.
pub fn hat(z: usize, levels: usize) -> f64 {
    let top = (levels - 1) as f64;
    let z = z as f64;
    z.min(top - z).max(0.0)
}

/// One channel of a stack, read in place: per frame, codes interleaved with `stride` samples
/// per pixel (this channel's at `offset`), and the frames' exposure times.
pub struct Channel<'a> {
    pub frames: &'a [&'a [u16]],
    pub stride: usize,
    pub offset: usize,
    pub times: &'a [f64],
    pub levels: usize,
}

impl Channel<'_> {
    /// Frame `j`'s codes in pixel order.
    fn frame(&self, j: usize) -> impl Iterator<Item = u16> + '_ {
        self.frames[j][self.offset..].iter().step_by(self.stride).copied()
    }

    pub(super) fn code(&self, j: usize, i: usize) -> u16 {
        self.frames[j][i * self.stride + self.offset]
    }
}

/// Bins codes of `levels` values to at most `MAX_FIT_LEVELS`.
fn binning(levels: usize) -> (usize, usize) {
    let mut shift = 0;
    while (levels >> shift) > MAX_FIT_LEVELS {
        shift += 1;
    }
    ((levels >> shift).max(2), shift)
}

/// Expands a curve fitted on bins to every code value (linear between bin centres).
fn unbin(g_bins: &[f64], shift: usize, levels: usize) -> Vec<f64> {
    if shift == 0 {
        return g_bins.to_vec();
    }
    let width = (1usize << shift) as f64;
    (0..levels)
        .map(|z| {
            let x = (z as f64 + 0.5) / width - 0.5;
            let k = (x.floor().max(0.0) as usize).min(g_bins.len() - 2);
            let f = (x - k as f64).clamp(-1.0, 2.0);
            g_bins[k] + f * (g_bins[k + 1] - g_bins[k])
        })
        .collect()
}

/// Pixel indices for Debevec's fit (module docs): per frame, starting at the middle one, for
/// each binned value not yet covered, the pixel nearest the image centre showing it.
pub fn choose_samples(
    ch: &Channel,
    width: usize,
    height: usize,
    per_value: usize,
    valid: &[bool],
) -> Vec<usize> {
    let (bins, shift) = binning(ch.levels);
    let n = valid.len();
    let frames = ch.frames.len();
    // A pixel whose value does not grow with the exposure time (registration borders,
    // moving objects, specks) would teach the fit a wrong curve: only pixels whose values are
    // non-decreasing in time (to one bin) and inside the range in two frames are sampled.
    let mut by_time: Vec<usize> = (0..frames).collect();
    by_time.sort_by(|&a, &b| ch.times[a].total_cmp(&ch.times[b]));
    // Frame by frame in time order (each a sequential pass), per pixel: the last bin, how
    // many frames show it inside the range, and whether it has grown so far; per frame, which
    // bins it shows.
    let mut previous = vec![0u16; n];
    let mut inside = vec![0u8; n];
    let mut usable = valid.to_vec();
    let mut shows = vec![vec![false; bins]; frames];
    for &j in &by_time {
        let show = &mut shows[j];
        let per_pixel = usable.iter_mut().zip(previous.iter_mut()).zip(inside.iter_mut());
        for (code, ((u, p), k)) in ch.frame(j).zip(per_pixel) {
            let z = code >> shift;
            *u &= z + 1 >= *p;
            *p = z;
            *k = k.saturating_add(u8::from(z > 0 && (z as usize) + 1 < bins));
            show[z as usize] = true;
        }
    }
    // Pixels still free to be chosen: usable and not yet taken.
    let mut free = usable;
    for (u, &k) in free.iter_mut().zip(&inside) {
        *u &= k >= 2;
    }
    // Nearest the centre first: squared distance, doubled to stay an integer, then index.
    let mut frame_order: Vec<usize> = (0..frames).collect();
    let mid = frames / 2;
    frame_order.sort_by_key(|&j| (j as i64 - mid as i64).abs());
    let mut count = vec![0usize; bins];
    let mut chosen = Vec::new();
    for &j in &frame_order {
        // Per value, the nearest pixels still wanted, in one pass over the frame in memory
        // order; `worst` caches each full list's farthest key, so most pixels cost one
        // comparison.
        let mut best: Vec<Vec<((i64, usize), usize)>> = vec![Vec::new(); bins];
        let mut worst = vec![(i64::MAX, usize::MAX); bins];
        // A frame showing no value still wanted needs no pass.
        if !(1..bins - 1).any(|b| shows[j][b] && count[b] < per_value) {
            continue;
        }
        // Per bin, how many pixels this frame may still give (none at black or saturation).
        let wanted: Vec<usize> = (0..bins)
            .map(|b| if b == 0 || b + 1 == bins { 0 } else { per_value.saturating_sub(count[b]) })
            .collect();
        let mut codes = ch.frame(j);
        for y in 0..height {
            let dy = 2 * y as i64 - (height as i64 - 1);
            for x in 0..width {
                let i = y * width + x;
                let b = (codes.next().unwrap_or(0) as usize) >> shift;
                let want = wanted[b];
                if want == 0 || !free[i] {
                    continue;
                }
                let dx = 2 * x as i64 - (width as i64 - 1);
                let k = (dx * dx + dy * dy, i);
                if k >= worst[b] {
                    continue;
                }
                let list = &mut best[b];
                if list.len() < want {
                    list.push((k, i));
                } else if let Some(far) = list.iter_mut().max_by_key(|e| e.0) {
                    *far = (k, i);
                }
                if list.len() == want {
                    worst[b] = list.iter().map(|e| e.0).max().unwrap_or((i64::MAX, usize::MAX));
                }
            }
        }
        for (b, list) in best.into_iter().enumerate() {
            for (_, i) in list {
                count[b] += 1;
                free[i] = false;
                chosen.push(i);
            }
        }
    }
    chosen.sort_unstable();
    chosen
}

/// The variable Debevec's g″ is taken in (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Smoothness {
    /// In the logit of the value, u = ln(z/(N − z)).
    #[default]
    Logit,
    /// In the value itself, as in the paper (and OpenCV).
    Even,
}

impl std::str::FromStr for Smoothness {
    type Err = Invalid;
    fn from_str(s: &str) -> Result<Smoothness, Invalid> {
        match s {
            "logit" => Ok(Smoothness::Logit),
            "even" => Ok(Smoothness::Even),
            other => Err(format!("smoothness \"{other}\": expected logit or even").into()),
        }
    }
}

/// Debevec & Malik's fit of one channel over the sample pixels (module docs).
pub fn debevec(
    ch: &Channel,
    samples: &[usize],
    lambda: f64,
    smoothness: Smoothness,
) -> Result<Vec<f64>, Error> {
    let (bins, shift) = binning(ch.levels);
    if samples.is_empty() {
        return Err(Error::Unsolvable(
            "no sample pixel with a value strictly between black and saturation".into(),
        ));
    }
    // The normal equations [[A, B], [Bᵀ, D]]·[g; ln E] = [r_g; r_E], with D diagonal (each
    // ln Eᵢ enters only its own rows), reduced to the Schur complement over g:
    // (A − B D⁻¹ Bᵀ)·g = r_g − B D⁻¹ r_E, a bins × bins system whatever the sample count.
    let mut s_mat = DMatrix::<f64>::zeros(bins, bins);
    let mut r = DVector::<f64>::zeros(bins);
    let mut data_rows = 0usize;
    // One sample's rows, merged per value: (z, Σ w², Σ w² ln Δt).
    let mut rows: Vec<(usize, f64, f64)> = Vec::with_capacity(ch.frames.len());
    for &i in samples {
        rows.clear();
        for j in 0..ch.frames.len() {
            let z = (ch.code(j, i) as usize) >> shift;
            let w2 = hat(z, bins).powi(2);
            if w2 == 0.0 {
                continue;
            }
            data_rows += 1;
            let lt = ch.times[j].ln();
            match rows.iter_mut().find(|e| e.0 == z) {
                Some(e) => {
                    e.1 += w2;
                    e.2 += w2 * lt;
                }
                None => rows.push((z, w2, w2 * lt)),
            }
        }
        // D_ii = Σ w², r_E = −Σ w² ln Δt; B[z, i] = −Σ_{j: Zᵢⱼ = z} w².
        let d: f64 = rows.iter().map(|e| e.1).sum();
        if d == 0.0 {
            continue;
        }
        let r_e: f64 = -rows.iter().map(|e| e.2).sum::<f64>();
        for &(z, w2, w2lt) in &rows {
            s_mat[(z, z)] += w2;
            r[z] += w2lt;
            // −B D⁻¹ r_E and −B D⁻¹ Bᵀ with B = −w².
            r[z] += w2 * r_e / d;
            for &(z2, w2b, _) in &rows {
                s_mat[(z, z2)] -= w2 * w2b / d;
            }
        }
    }
    if data_rows == 0 {
        return Err(Error::Unsolvable("every sample is black or saturated in every frame".into()));
    }
    // Smoothness: λ·w(z)·d²g/du², u the logit of the value or the value (module docs), scaled to the data
    // rows per value so λ means the same at any number of samples (Debevec & Malik's λ was
    // set for about 50 samples of 11 frames) and at any bit depth.
    let per_value = data_rows as f64 / bins as f64 / (50.0 * 11.0 / 256.0);
    let scale = (bins as f64 / 256.0).powi(2) * per_value.sqrt();
    let width = (1usize << shift) as f64;
    let mid = bins / 2;
    let top = bins as f64 * width;
    let u = |z: usize| {
        let c = ((z as f64 + 0.5) * width - 0.5).max(0.5);
        match smoothness {
            Smoothness::Logit => (c / (top - c)).ln(),
            Smoothness::Even => c,
        }
    };
    let du_mid = u(mid + 1) - u(mid);
    for z in 1..bins - 1 {
        let (h0, h1) = (u(z) - u(z - 1), u(z + 1) - u(z));
        // The second divided difference on the uneven grid, times √(cell width) so that the
        // sum of squares is an integral over u, in units of an even grid of step du_mid (at
        // the middle value λ weighs as in Debevec & Malik's even second difference).
        let cell = 0.5 * (h0 + h1);
        let k = lambda.sqrt() * hat(z, bins) * scale * du_mid.powf(1.5) * cell.sqrt();
        let coef = [k * 2.0 / (h0 * (h0 + h1)), -k * 2.0 / (h0 * h1), k * 2.0 / (h1 * (h0 + h1))];
        let idx = [z - 1, z, z + 1];
        for (p, &ip) in idx.iter().enumerate() {
            for (q, &iq) in idx.iter().enumerate() {
                s_mat[(ip, iq)] += coef[p] * coef[q];
            }
        }
    }
    // g(z_mid) = 0, weighted like the strongest data row.
    let anchor = hat(mid, bins);
    s_mat[(mid, mid)] += anchor * anchor;
    // Values no sample shows carry no data row; the smoothness rows tie them to their
    // neighbours, and a tiny ridge keeps an unseen end from being singular.
    for k in 0..bins {
        s_mat[(k, k)] += 1e-12 * anchor * anchor;
    }
    let sol = s_mat
        .clone()
        .cholesky()
        .map(|c| c.solve(&r))
        .or_else(|| s_mat.lu().solve(&r))
        .ok_or_else(|| Error::Unsolvable("the response's normal equations are singular".into()))?;
    // Values the samples show carry data; the others only smoothness (filled: module docs).
    let seen: Vec<bool> = observed(ch, shift, bins, samples.iter().copied());
    let g: Vec<f64> = sol.iter().copied().collect();
    if g.iter().any(|v| !v.is_finite()) {
        return Err(Error::Unsolvable("the response's least-squares solution is not finite".into()));
    }
    Ok(unbin(&finish(g, &seen), shift, ch.levels))
}

/// Which bins occur with a non-zero weight at the given pixels.
fn observed(
    ch: &Channel,
    shift: usize,
    bins: usize,
    pixels: impl Iterator<Item = usize> + Clone,
) -> Vec<bool> {
    let mut seen = vec![false; bins];
    for j in 0..ch.frames.len() {
        for i in pixels.clone() {
            seen[(ch.code(j, i) as usize) >> shift] = true;
        }
    }
    seen[0] = false;
    seen[bins - 1] = false;
    seen
}

/// Robertson's iteration stops when no observed value's g moves by more than this.
const CONVERGED: f64 = 1e-4;

/// Robertson et al.'s fit of one channel over every pixel (module docs).
pub fn robertson(ch: &Channel, valid: &[bool], max_iterations: usize) -> Result<Vec<f64>, Error> {
    let (bins, shift) = binning(ch.levels);
    let n = valid.len();
    let mid = bins / 2;
    // Start: linear response, I(m) = m / m_mid.
    let mut inv: Vec<f64> = (0..bins).map(|m| (m as f64 + 0.5) / (mid as f64 + 0.5)).collect();
    let seen = observed(ch, shift, bins, (0..n).filter(|&i| valid[i]));
    if !seen.iter().any(|&s| s) {
        return Err(Error::Unsolvable("every pixel is black or saturated in every frame".into()));
    }
    // Every pixel is read once per iteration: the channel is copied out of the interleaved
    // frames once, so each pass reads contiguous codes.
    let codes: Vec<Vec<u16>> = (0..ch.frames.len()).map(|j| ch.frame(j).collect()).collect();
    let mut e = vec![0.0f64; n];
    let mut previous: Option<Vec<f64>> = None;
    for _ in 0..max_iterations {
        for i in 0..n {
            if !valid[i] {
                continue;
            }
            let (mut num, mut den) = (0.0, 0.0);
            for (j, frame) in codes.iter().enumerate() {
                let z = (frame[i] as usize) >> shift;
                let w = hat(z, bins);
                num += w * ch.times[j] * inv[z];
                den += w * ch.times[j] * ch.times[j];
            }
            e[i] = if den > 0.0 { num / den } else { 0.0 };
        }
        let mut sum = vec![0.0f64; bins];
        let mut count = vec![0usize; bins];
        for (j, frame) in codes.iter().enumerate() {
            for i in 0..n {
                if valid[i] && e[i] > 0.0 {
                    let z = (frame[i] as usize) >> shift;
                    sum[z] += e[i] * ch.times[j];
                    count[z] += 1;
                }
            }
        }
        for m in 0..bins {
            if count[m] > 0 && seen[m] {
                inv[m] = sum[m] / count[m] as f64;
            }
        }
        // With equal exposure ratios the data fix g only up to a function periodic in
        // ln exposure (Grossberg & Nayar, "What is the space of camera response functions?",
        // CVPR 2003): a [1 4 6 4 1]/16 filter over the observed values after each update
        // keeps that ambiguity from growing into ripples (its bias is g″/2 per value, 0.006 in
        // ln units at value 14 of a gamma-2.2 curve).
        smooth_observed(&mut inv, &seen);
        let norm = inv[mid];
        if !(norm.is_finite() && norm > 0.0) {
            return Err(Error::Unsolvable(
                "the middle value never occurs in a well-exposed pixel: no scale for the response".into(),
            ));
        }
        inv.iter_mut().for_each(|v| *v /= norm);
        let g: Vec<f64> = inv.iter().map(|&v| if v > 0.0 { v.ln() } else { f64::NAN }).collect();
        if let Some(p) = &previous {
            let change = g
                .iter()
                .zip(p)
                .zip(&seen)
                .filter(|&(_, &s)| s)
                .map(|((a, b), _)| (a - b).abs())
                .fold(0.0, f64::max);
            if change < CONVERGED {
                break;
            }
        }
        previous = Some(g);
    }
    let g: Vec<f64> =
        inv.iter().zip(&seen).map(|(&v, &s)| if s && v > 0.0 { v.ln() } else { f64::NAN }).collect();
    let mut seen = seen;
    for (s, v) in seen.iter_mut().zip(&g) {
        *s &= v.is_finite();
    }
    Ok(unbin(&finish(g, &seen), shift, ch.levels))
}

/// Filters ln I over runs of observed values with [1 4 6 4 1]/16 (shorter at a run's ends).
fn smooth_observed(inv: &mut [f64], seen: &[bool]) {
    let ln: Vec<f64> = inv.iter().map(|&v| if v > 0.0 { v.ln() } else { f64::NAN }).collect();
    let taps = [1.0, 4.0, 6.0, 4.0, 1.0];
    for z in 0..inv.len() {
        if !seen[z] || !ln[z].is_finite() {
            continue;
        }
        let (mut num, mut den) = (0.0, 0.0);
        for (k, &w) in taps.iter().enumerate() {
            let Some(y) = (z + k).checked_sub(2) else { continue };
            if y < inv.len() && seen[y] && ln[y].is_finite() {
                num += w * ln[y];
                den += w;
            }
        }
        inv[z] = (num / den).exp();
    }
}

/// Fills the values without data and makes g strictly increasing (module docs).
fn finish(mut g: Vec<f64>, seen: &[bool]) -> Vec<f64> {
    let n = g.len();
    let idx: Vec<usize> = (0..n).filter(|&z| seen[z] && g[z].is_finite()).collect();
    if idx.is_empty() {
        return (0..n).map(|z| (z as f64 - n as f64 / 2.0) / n as f64).collect();
    }
    // Monotone on the observed values first (pool adjacent violators, equal weights).
    let mono = isotonic(&idx.iter().map(|&z| g[z]).collect::<Vec<_>>());
    for (k, &z) in idx.iter().enumerate() {
        g[z] = mono[k];
    }
    // Gaps: linear interpolation between observed neighbours.
    for w in idx.windows(2) {
        let (a, b) = (w[0], w[1]);
        for z in a + 1..b {
            g[z] = g[a] + (g[b] - g[a]) * (z - a) as f64 / (b - a) as f64;
        }
    }
    // Ends: the mean slope of the 8 nearest observed values, at least a small rise.
    let slope = |ks: &[usize]| -> f64 {
        if ks.len() < 2 {
            return 1.0 / n as f64;
        }
        let (a, b) = (ks[0], ks[ks.len() - 1]);
        ((g[b] - g[a]) / (b - a) as f64).max(1e-6)
    };
    let (lo, hi) = (idx[0], idx[idx.len() - 1]);
    let s_lo = slope(&idx[..idx.len().min(8)]);
    let s_hi = slope(&idx[idx.len().saturating_sub(8)..]);
    for z in 0..lo {
        g[z] = g[lo] - s_lo * (lo - z) as f64;
    }
    for z in hi + 1..n {
        g[z] = g[hi] + s_hi * (z - hi) as f64;
    }
    for z in 1..n {
        if g[z] < g[z - 1] + 1e-6 {
            g[z] = g[z - 1] + 1e-6;
        }
    }
    g
}

/// Least-squares non-decreasing fit (pool adjacent violators).
fn isotonic(y: &[f64]) -> Vec<f64> {
    pool_adjacent_violators(y.iter().map(|&v| (0.0, v, 1)))
        .iter()
        .flat_map(|&(_, sy, k)| std::iter::repeat_n(sy / k as f64, k))
        .collect()
}

/// Pool adjacent violators over blocks (Σx, Σy, count) in order: neighbours whose mean y
/// falls are merged until the means rise (weakly), each block weighing by its count.
pub(super) fn pool_adjacent_violators(
    blocks: impl IntoIterator<Item = (f64, f64, usize)>,
) -> Vec<(f64, f64, usize)> {
    let mut out: Vec<(f64, f64, usize)> = Vec::new();
    for b in blocks {
        out.push(b);
        while out.len() > 1 {
            let (b, a) = (out[out.len() - 1], out[out.len() - 2]);
            if a.1 / a.2 as f64 <= b.1 / b.2 as f64 {
                break;
            }
            out.truncate(out.len() - 2);
            out.push((a.0 + b.0, a.1 + b.1, a.2 + b.2));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A noise-free stack through a gamma-2.2 response, four frames two stops apart: both fits
    /// give a finite, strictly increasing curve everywhere; Debevec's, with either smoothness
    /// term, is the true g up to an offset within 0.02 (ln units) over 20..235. (Robertson's
    /// accuracy, and the merge, are checked in tests/hdr.rs.)
    #[test]
    fn recovers_a_known_response() {
        let (w, h) = (64usize, 48usize);
        let times = [1.0, 0.25, 1.0 / 16.0, 1.0 / 64.0];
        let e: Vec<f64> = (0..w * h)
            .map(|i| 1e-3 * 10f64.powf(4.0 * ((i * 7919) % (w * h)) as f64 / (w * h) as f64))
            .collect();
        let response = |x: f64| (255.0 * (x.clamp(0.0, 1.0)).powf(1.0 / 2.2)).round() as u16;
        let codes: Vec<Vec<u16>> =
            times.iter().map(|&t| e.iter().map(|&v| response(v * t * 4.0)).collect()).collect();
        let frames: Vec<&[u16]> = codes.iter().map(|f| f.as_slice()).collect();
        let ch = Channel { frames: &frames, stride: 1, offset: 0, times: &times, levels: 256 };
        let valid = vec![true; w * h];
        let samples = choose_samples(&ch, w, h, 1, &valid);
        let fits = [
            ("debevec, even", debevec(&ch, &samples, 10.0, Smoothness::Even).unwrap()),
            ("debevec, logit", debevec(&ch, &samples, 1e4, Smoothness::Logit).unwrap()),
            ("robertson", robertson(&ch, &valid, 50).unwrap()),
        ];
        for (name, g) in &fits {
            assert!(g.iter().all(|v| v.is_finite()), "{name}");
            assert!(g.windows(2).all(|p| p[1] > p[0]), "{name}");
        }
        let truth = |z: usize| 2.2 * (z as f64 / 255.0).ln();
        for (name, g) in &fits[..2] {
            let offset = (20..236).map(|z| g[z] - truth(z)).sum::<f64>() / 216.0;
            let worst = (20..236).map(|z| (g[z] - truth(z) - offset).abs()).fold(0.0, f64::max);
            assert!(worst < 0.02, "{name}: worst {worst}");
        }
    }

    #[test]
    fn isotonic_pools_violators() {
        assert_eq!(isotonic(&[1.0, 3.0, 2.0, 4.0]), vec![1.0, 2.5, 2.5, 4.0]);
    }
}

/// The response as a table a person can plot: `value,ln_exposure_r,ln_exposure_g,ln_exposure_b`.
pub fn to_csv(r: &Response) -> String {
    let mut s = String::from("# g(z) = ln exposure of pixel value z, per channel (offset: g(middle value) = 0)\nvalue,ln_exposure_r,ln_exposure_g,ln_exposure_b\n");
    for z in 0..r.levels {
        s.push_str(&format!("{z},{:e},{:e},{:e}\n", r.g[0][z], r.g[1][z], r.g[2][z]));
    }
    s
}

/// Reads a table written by `to_csv` (or by hand): one row per value 0, 1, …, levels − 1,
/// finite and strictly increasing in every channel.
pub fn from_csv(text: &str) -> Result<Response, Invalid> {
    let mut rows =
        text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    match rows.next() {
        Some((_, h)) if h.trim().to_lowercase().starts_with("value,") => {}
        _ => return Err("expected the header `value,ln_exposure_r,ln_exposure_g,ln_exposure_b`".into()),
    }
    let mut g = vec![Vec::new(), Vec::new(), Vec::new()];
    for (n, line) in rows {
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        if cells.len() != 4 {
            return Err(format!("line {}: {} fields, expected 4", n + 1, cells.len()).into());
        }
        let z: usize =
            cells[0].parse().map_err(|_| format!("line {}: value `{}` is not a number", n + 1, cells[0]))?;
        if z != g[0].len() {
            return Err(
                format!("line {}: value {z}, expected {} (rows in order from 0)", n + 1, g[0].len()).into()
            );
        }
        for c in 0..3 {
            let v: f64 = cells[c + 1]
                .parse()
                .map_err(|_| format!("line {}: `{}` is not a number", n + 1, cells[c + 1]))?;
            if !v.is_finite() {
                return Err(format!("line {}: {v} is not finite", n + 1).into());
            }
            // Radiance is e^g / t in float32: with times down to 10⁻¹² s, |g| ≤ 60 keeps it
            // within float32's range (e^60 · 10¹² ≈ 10³⁸).
            if v.abs() > 60.0 {
                return Err(format!(
                    "line {}: ln exposure {v:e} is outside ±60: e^g would leave float32's range in the radiance",
                    n + 1
                ).into());
            }
            g[c].push(v);
        }
    }
    let levels = g[0].len();
    if !(2..=65536).contains(&levels) {
        return Err(format!("{levels} values: expected 2 to 65536").into());
    }
    for (c, gc) in g.iter().enumerate() {
        if let Some(z) = gc.windows(2).position(|w| w[1] <= w[0]) {
            return Err(
                format!("channel {c}: ln exposure does not increase from value {z} to {}", z + 1).into()
            );
        }
    }
    Ok(Response { levels, g })
}

/// An SVG plot of the response: ln exposure against pixel value, one line per channel.
pub fn plot_svg(r: &Response, title: &str) -> String {
    use plotters::prelude::*;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (720, 480)).into_drawing_area();
        let _ = root.fill(&WHITE);
        let (lo, hi) =
            r.g.iter().flatten().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
        let (lo, hi) = if lo.is_finite() && hi > lo { (lo, hi) } else { (-1.0, 1.0) };
        let chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..(r.levels - 1) as f64, lo..hi);
        if let Ok(mut chart) = chart {
            let _ = chart.configure_mesh().x_desc("pixel value").y_desc("ln exposure").draw();
            for (c, colour) in [RED, GREEN, BLUE].iter().enumerate() {
                let pts = r.g[c].iter().enumerate().map(|(z, &v)| (z as f64, v));
                let _ = chart.draw_series(LineSeries::new(pts, colour));
            }
        }
        let _ = root.present();
    }
    svg
}
