//! The sensor's noise from the stack itself: its full well (electrons at full scale) and read
//! noise, so that the merge's inverse-variance weights (`merge::Weights::Noise`) need no
//! data sheet.
//!
//! Method (after Granados et al. 2010 and Aguerrebere et al. 2014, who calibrate the same
//! model from pixels seen in several exposures): a pixel inside the range in two frames j
//! (longer) and j′ with r = Δtⱼ/Δtⱼ′ gives, through the recovered response X(z) = exp(g(z))
//! in fractions x = X/X(top) of full scale, two estimates of the same exposure, xⱼ and r·xⱼ′.
//! Their difference d = xⱼ − r·xⱼ′ has variance
//!
//!   var d = α·x̄·(1 + r) + β·(1 + r²) + (x′ⱼ² + r²·x′ⱼ′²)/12
//!
//! with α = 1/full_well (photon noise: var x = x/full_well), β = (read noise/full_well)² and
//! the last term the quantisation of each code (x′ the response's step per code). Pairs of
//! consecutive frames are binned by level (a quarter stop wide; the level (r·xⱼ + r·xⱼ′)/(r + 1),
//! which under photon noise is uncorrelated with d, so binning does not select by d) and by
//! r; a bin where one
//! frame of some pairs is clipped at black or saturation is left out (those pairs are missing
//! from it, so the rest are a truncated sample whose spread is too small); each bin's variance
//! about its own mean (a response biased at the toe shifts d, it does not widen it), with
//! values beyond six robust deviations left out (motion, misregistration), is one equation
//! (where it exceeds the quantisation's: below it the codes hardly move between frames and
//! the bin cannot show the noise)
//! linear in α and β, weighted by count/variance² (the variance of a variance estimate).
//! Weighted least squares gives α and β; full well = 1/α, read noise = √β/α.
//!
//! All three channels share the sensor, so their bins enter one fit.

use super::response::Response;
use serde::{Deserialize, Serialize};

/// What the stack says of its sensor.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    /// Electrons at full scale.
    pub full_well: f64,
    /// Read noise in electrons.
    pub read_noise: f64,
    /// Pixel-channel pairs of frames the fit used.
    pub pairs: usize,
    /// Level bins (equations) the fit used.
    pub bins: usize,
}

/// Fewest pairs a bin needs to count: its variance is then known to about √(2/200) = 10 %.
const MIN_BIN_PAIRS: usize = 200;

/// Largest share of a bin's pairs that may have had a frame clipped at black or saturation:
/// beyond it the pairs left are a truncated sample, their spread too small (cutting a normal
/// 3.1σ from its mean, 0.1 % of it, narrows it by under 2 %).
const MAX_CLIPPED: f64 = 1e-3;

/// Pairs of frames (pixel channels) the estimate looks at, at most.
const MAX_PAIRS: usize = 2_000_000;

/// Bin width in stops of level.
const BIN_STOPS: f64 = 0.25;

/// Estimates full well and read noise from `frames` (interleaved RGB codes, any order) with
/// their `times` and the recovered `response`, over the `usable` pixels; `None` when the stack
/// has too few pixels seen in two frames, or the fit gives no positive photon noise.
pub fn estimate(frames: &[&[u16]], times: &[f64], response: &Response, usable: &[bool]) -> Option<Estimate> {
    let levels = response.levels;
    if levels < 4 || frames.len() < 2 {
        return None;
    }
    // Every `stride`-th pixel: about `MAX_PAIRS` pairs are plenty (each bin's variance from
    // hundreds), and a large stack would otherwise spend more here than in the merge.
    let candidates = usable.iter().filter(|&&u| u).count() * 3 * (frames.len() - 1);
    let stride = candidates.div_ceil(MAX_PAIRS).max(1);
    let mut order: Vec<usize> = (0..frames.len()).collect();
    order.sort_by(|&a, &b| times[b].total_cmp(&times[a]));
    // Per bin key (level bin, r in hundredths): the differences, with the level and the
    // quantisation variance summed.
    let mut bins: std::collections::BTreeMap<(i64, i64), Bin> = Default::default();
    for c in 0..3 {
        let x: Vec<f64> = response.g[c].iter().map(|g| g.exp()).collect();
        let top = x[levels - 1];
        if !(top.is_finite() && top > 0.0) {
            return None;
        }
        let frac: Vec<f64> = x.iter().map(|v| v / top).collect();
        let step: Vec<f64> =
            (0..levels).map(|z| 0.5 * (frac[(z + 1).min(levels - 1)] - frac[z.saturating_sub(1)])).collect();
        for w in order.windows(2) {
            let (j, k) = (w[0], w[1]);
            let r = times[j] / times[k];
            if !(r.is_finite() && r > 1.0) {
                continue;
            }
            let r_key = (r * 100.0).round() as i64;
            for (i, _) in usable.iter().enumerate().filter(|(_, &u)| u).step_by(stride) {
                let (zj, zk) = (frames[j][3 * i + c] as usize, frames[k][3 * i + c] as usize);
                let inside = |z: usize| z > 0 && z < levels - 1;
                let key = |level: f64| ((level.log2() / BIN_STOPS).floor() as i64, r_key);
                // Binned by the level d is uncorrelated with: under photon noise var(r·xⱼ′) =
                // r·var(xⱼ), so (r·xⱼ + r·xⱼ′)/(r + 1); the plain mean would select pairs by
                // their difference and narrow each bin's spread.
                let level_of = |xj: f64, xk: f64| (r * xj + xk) / (r + 1.0);
                if !(inside(zj) && inside(zk)) {
                    // One frame inside, the other clipped (the shorter at black, the longer at
                    // saturation): the bin this pair would have fallen in holds a truncated
                    // sample (module docs). Its level, with the clipped frame at its clip.
                    let level = match (inside(zj), inside(zk)) {
                        (true, false) if zk == 0 => level_of(frac[zj], 0.0),
                        (false, true) if zj == levels - 1 => level_of(1.0, r * frac[zk]),
                        _ => continue,
                    };
                    if level > 0.0 {
                        bins.entry(key(level)).or_default().clipped += 1;
                    }
                    continue;
                }
                let (xj, xk) = (frac[zj], r * frac[zk]);
                let level = level_of(xj, xk);
                if level <= 0.0 {
                    continue;
                }
                let b = bins.entry(key(level)).or_default();
                b.d.push(xj - xk);
                b.level += level;
                b.quant += (step[zj].powi(2) + (r * step[zk]).powi(2)) / 12.0;
                b.r = r;
            }
        }
    }
    // One equation per bin: var − quantisation = α·u + β·v, with its pair count.
    let mut eqs: Vec<Equation> = Vec::new();
    let mut pairs = 0;
    for b in bins
        .values_mut()
        .filter(|b| b.d.len() >= MIN_BIN_PAIRS && b.clipped as f64 <= MAX_CLIPPED * b.d.len() as f64)
    {
        let n = b.d.len() as f64;
        let (level, quant) = (b.level / n, b.quant / n);
        let Some(var) = robust_variance(&mut b.d, quant) else { continue };
        // A spread below the codes' own quantisation: the codes hardly move between the
        // frames (a flat dark area, film's base), so the bin cannot show the noise.
        if var <= quant {
            continue;
        }
        eqs.push(Equation { u: level * (1.0 + b.r), v: 1.0 + b.r * b.r, quant, var, n });
        pairs += b.d.len();
    }
    if eqs.len() < 2 {
        return None;
    }
    // Weighted by count / variance², the variance of a bin's variance: first the measured
    // one, then (twice) the model's, so that a bin whose spread came out small by chance
    // does not steer the fit.
    let mut fit = solve(&eqs, |e| e.var)?;
    for _ in 0..2 {
        let (a, b) = fit;
        fit = solve(&eqs, |e| (a * e.u + b * e.v + e.quant).max(e.quant).max(1e-300))?;
    }
    let (alpha, beta) = fit;
    if !(alpha.is_finite() && alpha > 0.0 && beta.is_finite()) {
        return None;
    }
    let used = eqs.len();
    let full_well = 1.0 / alpha;
    Some(Estimate { full_well, read_noise: beta.sqrt() * full_well, pairs, bins: used })
}

/// One bin's equation: var − quant = α·u + β·v, from n pairs.
struct Equation {
    u: f64,
    v: f64,
    quant: f64,
    var: f64,
    n: f64,
}

/// Weighted least squares for (α, β ≥ 0), weights n / expected(e)²; β = 0 (photon noise
/// alone) where the data give it no positive value.
fn solve(eqs: &[Equation], expected: impl Fn(&Equation) -> f64) -> Option<(f64, f64)> {
    let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for e in eqs {
        let w = e.n / expected(e).powi(2).max(1e-300);
        let y = e.var - e.quant;
        a11 += w * e.u * e.u;
        a12 += w * e.u * e.v;
        a22 += w * e.v * e.v;
        b1 += w * e.u * y;
        b2 += w * e.v * y;
    }
    let det = a11 * a22 - a12 * a12;
    let (mut alpha, mut beta) = if det > 1e-12 * a11 * a22 {
        ((b1 * a22 - b2 * a12) / det, (a11 * b2 - a12 * b1) / det)
    } else {
        (b1 / a11, 0.0)
    };
    if beta < 0.0 {
        beta = 0.0;
        alpha = b1 / a11;
    }
    (alpha.is_finite() && beta.is_finite()).then_some((alpha, beta))
}

#[derive(Default)]
struct Bin {
    d: Vec<f64>,
    /// Pairs at this level with one frame clipped (left out of `d`).
    clipped: usize,
    level: f64,
    quant: f64,
    r: f64,
}

/// The variance of `d` about its mean, leaving out values beyond six robust deviations (at
/// least the quantisation's) of the median.
fn robust_variance(d: &mut [f64], quant: f64) -> Option<f64> {
    d.sort_by(f64::total_cmp);
    let median = d[d.len() / 2];
    let mut dev: Vec<f64> = d.iter().map(|v| (v - median).abs()).collect();
    dev.sort_by(f64::total_cmp);
    // Codes are discrete: where most pairs share one difference the MAD is 0, so the plain
    // deviation (halved: outliers inflate it) bounds the cut from below too.
    let n = d.len() as f64;
    let mean_all = d.iter().sum::<f64>() / n;
    let sd_all = (d.iter().map(|v| (v - mean_all).powi(2)).sum::<f64>() / n).sqrt();
    let sigma = (1.4826 * dev[dev.len() / 2]).max(0.5 * sd_all).max(quant.sqrt());
    let kept: Vec<f64> = d.iter().copied().filter(|v| (v - median).abs() <= 6.0 * sigma).collect();
    if kept.len() < 2 {
        return None;
    }
    let mean = kept.iter().sum::<f64>() / kept.len() as f64;
    let var = kept.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (kept.len() - 1) as f64;
    (var.is_finite() && var > 0.0).then_some(var)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal, Poisson};

    /// A linear 12-bit sensor with 5000 e⁻ and 4 e⁻ of read noise, seen through its true
    /// curve: the estimate finds both within a few times the precision its bins give (about
    /// 30 levels of 15 000 pairs, each variance known to 1.2 %).
    #[test]
    fn recovers_full_well_and_read_noise() {
        let (levels, fw, rn) = (4096usize, 5000.0, 4.0);
        let g: Vec<f64> = (0..levels).map(|z| ((z as f64).max(0.5) / (levels - 1) as f64).ln()).collect();
        let response = Response { levels, g: vec![g; 3] };
        let times = [1.0, 0.5, 0.25, 0.125];
        let n = 65536;
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(3);
        let radiance: Vec<f64> = (0..n).map(|i| 10f64.powf(-3.0 + 3.0 * (i as f64 / n as f64))).collect();
        let read = Normal::new(0.0, rn).unwrap();
        let frames: Vec<Vec<u16>> = times
            .iter()
            .map(|t| {
                radiance
                    .iter()
                    .flat_map(|l| {
                        let mean = l * t * fw;
                        (0..3)
                            .map(|_| {
                                let e = Poisson::new(mean).unwrap().sample(&mut rng) + read.sample(&mut rng);
                                ((e / fw).clamp(0.0, 1.0) * (levels - 1) as f64).round() as u16
                            })
                            .collect::<Vec<_>>()
                    })
                    .collect()
            })
            .collect();
        let refs: Vec<&[u16]> = frames.iter().map(|f| f.as_slice()).collect();
        let e = estimate(&refs, &times, &response, &vec![true; n]).unwrap();
        eprintln!("{e:?}");
        assert!((e.full_well / fw - 1.0).abs() < 0.03, "{e:?}");
        assert!((e.read_noise - rn).abs() < 0.5, "{e:?}");
    }
}
