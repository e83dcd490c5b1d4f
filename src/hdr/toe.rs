//! The response's toe refitted as the sensor's mean response.
//!
//! Below some value a single code says little about its exposure: photon and read noise
//! spread it over many codes, and the clip at black pushes the mean code up. There the
//! noiseless curve f is not what the frames show; their codes scatter about the mean
//! response h(X) = E[z | X], which lies above f and flattens towards the mean code of no
//! light at all. A fit of ln X on z (Debevec & Malik's rows, Robertson's update) answers
//! E[ln X | z] instead, which leans towards whatever exposures the scene happens to hold
//! (errors in variables, Fuller 1987): on a steep toe it is off by up to several ln units,
//! and differently for every scene.
//!
//! So the toe is fitted the other way round, the code on the exposure: every pixel whose
//! exposure the merge pins down (a frame above the toe) gives, in each frame j, the pair
//! (ln Eᵢ + ln Δtⱼ, Zᵢⱼ); the pairs are sorted by exposure and averaged in groups, and a
//! non-decreasing fit of the code on ln exposure (pool adjacent violators) is h. Each toe
//! value z then gets g(z) = h⁻¹(z), interpolated between the pooled groups. The exposure is
//! known to a few percent (the merge averages frames above the toe), the codes carry the
//! noise: the regression of z on ln X is then unbiased, whatever the scene. Values below the
//! mean code at the darkest exposure seen have no inverse and continue the curve (as
//! `response` continues unseen ends).
//!
//! The toe ends where a code's own noise in ln exposure, √var(X)/X with var(X) the merge's
//! (`merge::exposure_variance`), falls below `PINNED_SIGMA` for good: above it, one
//! observation pins its value and the fit of g on z stands.

use super::merge::exposure_variance;
use super::response::{pool_adjacent_violators, Channel};

/// Noise in ln exposure of one observation below which a value is pinned by its data.
pub const PINNED_SIGMA: f64 = 0.1;

/// Exposure/code pairs averaged per group, at least.
const MIN_GROUP: usize = 100;

/// Groups the pairs are split into, at most: each group's mean code is then within a few
/// hundredths of one code's spread for the pairs a small stack gives (10⁵), and a group spans
/// about a hundredth of the toe's range of exposure, over which h is nearly straight.
const GROUPS: usize = 100;

/// The first value of the range above the toe: from it up to the value below saturation,
/// every code's noise in ln exposure is below `PINNED_SIGMA`. 1 when no toe needs refitting;
/// `None` when no value is pinned.
pub fn end(g: &[f64], full_well: f64, read_noise: f64) -> Option<usize> {
    let x: Vec<f64> = g.iter().map(|v| v.exp()).collect();
    let below_top = g.len() - 2;
    let sigma = |z: usize| exposure_variance(&x, z, full_well, read_noise).sqrt() / x[z];
    let last_unpinned = (1..=below_top).rev().find(|&z| !(sigma(z) < PINNED_SIGMA));
    match last_unpinned {
        Some(z) if z == below_top => None,
        Some(z) => Some(z + 1),
        None => Some(1),
    }
}

/// One channel's g with the values below `end` refitted (module docs), from the stack's
/// channel `ch` and each pixel's merged ln exposure `ln_e` in g's scale (not finite where
/// unknown). `None` when too few pairs reach below the toe's end.
pub fn refit(ch: &Channel, g: &[f64], ln_e: &[f64], end: usize) -> Option<Vec<f64>> {
    let levels = g.len();
    if end <= 1 {
        return None;
    }
    let frames = 0..ch.frames.len();
    let ln_times: Vec<f64> = ch.times.iter().map(|t| t.ln()).collect();
    // Pixels the merge pins down: some frame shows them above the toe, below saturation.
    let top = (levels - 1) as u16;
    let pinned =
        |i: usize| ln_e[i].is_finite() && frames.clone().any(|j| (end as u16..top).contains(&ch.code(j, i)));
    // Pairs up to an exposure a little above the toe's end, so the fit meets the rest.
    let reach = g[(2 * end).min(levels - 2).max(end)];
    let mut pairs: Vec<(f64, f64)> = Vec::new();
    for i in (0..ln_e.len()).filter(|&i| pinned(i)) {
        for j in frames.clone() {
            let l = ln_e[i] + ln_times[j];
            if l <= reach {
                pairs.push((l, ch.code(j, i) as f64));
            }
        }
    }
    if pairs.len() < 10 * MIN_GROUP {
        return None;
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Groups of equal count, then pool adjacent violators of a non-decreasing code.
    let size = MIN_GROUP.max(pairs.len() / GROUPS);
    let blocks = pool_adjacent_violators(pairs.chunks(size).map(|chunk| {
        let (sl, sz) = chunk.iter().fold((0.0, 0.0), |(a, b), p| (a + p.0, b + p.1));
        (sl, sz, chunk.len())
    }));
    let h: Vec<(f64, f64)> = blocks.iter().map(|&(sl, sz, n)| (sl / n as f64, sz / n as f64)).collect();
    let mut out = g.to_vec();
    let mut inverted = vec![false; levels];
    for z in 1..end {
        let zf = z as f64;
        let k = h.partition_point(|&(_, m)| m < zf);
        if k == 0 || k == h.len() {
            continue;
        }
        let ((l0, m0), (l1, m1)) = (h[k - 1], h[k]);
        out[z] = l0 + (l1 - l0) * (zf - m0) / (m1 - m0);
        inverted[z] = true;
    }
    let first = (1..end).find(|&z| inverted[z])?;
    // Below the first inverted value: continue with the mean slope of the next 8.
    let last = (first..end).filter(|&z| inverted[z]).take(8).last().unwrap_or(first);
    let slope =
        if last > first { ((out[last] - out[first]) / (last - first) as f64).max(1e-6) } else { 1e-3 };
    for z in 0..first {
        out[z] = out[first] - slope * (first - z) as f64;
    }
    // Gaps between inverted values (a code no group's mean crosses): linear.
    let mut prev = first;
    for z in first + 1..end {
        if inverted[z] {
            for y in prev + 1..z {
                out[y] = out[prev] + (out[z] - out[prev]) * (y - prev) as f64 / (z - prev) as f64;
            }
            prev = z;
        }
    }
    for y in prev + 1..end {
        out[y] = out[prev] + (g[end] - out[prev]) * (y - prev) as f64 / (end - prev) as f64;
    }
    // Strictly increasing across the join.
    for z in (0..end).rev() {
        if out[z] > out[z + 1] - 1e-6 {
            out[z] = out[z + 1] - 1e-6;
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::{Distribution, Normal};

    /// A linear 8-bit sensor with 2 codes of read noise, 8 frames one stop apart over a scene
    /// of exposures spread evenly in ln: from 10 codes up, where the clip at black moves the
    /// mean code by under 10⁻⁶, the mean response is the noiseless line, g(z) = ln(z/255).
    /// Given a toe 0.3 too high, the refit puts it back within 0.02 over 10..end, and keeps
    /// the curve strictly increasing everywhere.
    #[test]
    fn refits_a_wrong_toe_to_the_mean_response() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        let noise = Normal::new(0.0, 2.0).unwrap_or_else(|_| unreachable!());
        let (pixels, frames, end) = (20_000, 8, 40);
        let ln_e: Vec<f64> = (0..pixels).map(|_| rng.gen_range(-7.0..0.0)).collect();
        let ln_times: Vec<f64> = (0..frames).map(|j| -(j as f64) * std::f64::consts::LN_2).collect();
        let codes: Vec<Vec<u16>> = ln_times
            .iter()
            .map(|lt| {
                ln_e.iter()
                    .map(|l| {
                        ((l + lt).exp() * 255.0 + noise.sample(&mut rng)).round().clamp(0.0, 255.0) as u16
                    })
                    .collect()
            })
            .collect();
        let frames: Vec<&[u16]> = codes.iter().map(|f| f.as_slice()).collect();
        let times: Vec<f64> = ln_times.iter().map(|l| l.exp()).collect();
        let ch = Channel { frames: &frames, stride: 1, offset: 0, times: &times, levels: 256 };
        let truth = |z: usize| (z.max(1) as f64 / 255.0).ln();
        let g: Vec<f64> = (0..256).map(|z| truth(z) + if z < end { 0.3 } else { 0.0 }).collect();
        let refit = refit(&ch, &g, &ln_e, end).expect("enough pairs");
        for z in 10..end {
            assert!((refit[z] - truth(z)).abs() < 0.02, "z = {z}: {} against {}", refit[z], truth(z));
        }
        assert!(refit.windows(2).all(|w| w[1] > w[0]), "not increasing");
        assert_eq!(refit[end..], g[end..]);
    }
}
