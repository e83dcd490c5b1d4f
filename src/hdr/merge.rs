//! Radiance from an exposure stack and a response, per pixel and channel.
//!
//! Each frame j with code Zⱼ gives an estimate Eⱼ = exp(g(Zⱼ))/Δtⱼ. The merge averages them
//! with weights
//!
//! - `hat`: w = hat(Zⱼ) (Debevec & Malik 1997's weights, 0 at black and saturation), with
//!   their average of ln E: ln E = Σ w·(g(Zⱼ) − ln Δtⱼ) / Σ w, in which a dark frame's coarse
//!   codes move the result by their share of the weight in ln units, not in linear ones;
//! - `noise`: inverse variance of Eⱼ under photon, read and quantisation noise (Granados et
//!   al., "Optimal HDR reconstruction with linear digital cameras", CVPR 2010; Hasinoff et
//!   al. 2010): with X = exp(g(Z)) the linearised value, var(Eⱼ) = (k·X + σ_r² + X′²/12)/Δtⱼ²,
//!   with k = X(full scale)/full_well the gain (linear units per electron, from the recovered
//!   response's value at full scale and the sensor's full-well capacity), σ_r = k·read noise
//!   and X′ the response's step per code; so w = Δtⱼ² / (k·X + σ_r² + X′²/12), averaging Eⱼ
//!   itself; codes at black or saturation get weight 0. The full well and read noise are the
//!   sensor's data sheet's, or the stack's own (`hdr::noise`, `Weights::NoiseFromStack`).
//!
//! A pixel whose every frame is saturated in a channel has no estimate: it is given the
//! shortest frame's value as a lower bound and marked `saturated` in the mask; one black in
//! every frame the longest frame's value as an upper bound, marked `dark`.

use super::response::{hat, Response};
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Weights {
    Hat,
    /// The sensor's electrons at full scale and its read noise in electrons.
    Noise {
        full_well: f64,
        read_noise: f64,
    },
    /// `Noise` with the full well and read noise the stack itself gives (`hdr::noise`),
    /// resolved by `hdr::run` (hat weights where the stack gives no estimate); `merge` given
    /// it directly uses hat weights.
    NoiseFromStack,
}

/// The mask's values per pixel: 0 well exposed in some frame (every channel), 1 saturated
/// in every frame in some channel (its value a lower bound), 2 black in every frame in some
/// channel (an upper bound).
pub const WELL_EXPOSED: u8 = 0;
pub const SATURATED: u8 = 1;
pub const DARK: u8 = 2;

/// The variance of the linear exposure X = exp(g(z)) a code `z` stands for (module docs):
/// k·X + σ_r² + X′²/12, with `x` the response's exp(g) per code.
pub fn exposure_variance(x: &[f64], z: usize, full_well: f64, read_noise: f64) -> f64 {
    let levels = x.len();
    let gain = x[levels - 1] / full_well;
    let read = gain * read_noise;
    let slope = 0.5 * (x[(z + 1).min(levels - 1)] - x[z.saturating_sub(1)]);
    gain * x[z] + read * read + slope * slope / 12.0
}

/// Merges `frames` (per frame, interleaved RGB codes) into linear radiance (interleaved RGB)
/// and the mask.
pub fn merge(frames: &[&[u16]], times: &[f64], response: &Response, weights: Weights) -> (Vec<f32>, Vec<u8>) {
    let n = frames.first().map_or(0, |f| f.len() / 3);
    let levels = response.levels;
    let top = (levels - 1) as u16;
    let (shortest, longest) = {
        let mut order: Vec<usize> = (0..times.len()).collect();
        order.sort_by(|&a, &b| times[a].total_cmp(&times[b]));
        (order[0], order[order.len() - 1])
    };
    // Per channel and code: exp(g), its slope, and the weight without the time factor.
    let tables: Vec<(Vec<f64>, Vec<f64>)> = (0..3)
        .map(|c| {
            let x: Vec<f64> = response.g[c].iter().map(|g| g.exp()).collect();
            let w: Vec<f64> = (0..levels)
                .map(|z| match weights {
                    _ if z == 0 || z == levels - 1 => 0.0,
                    Weights::Hat | Weights::NoiseFromStack => hat(z, levels),
                    Weights::Noise { full_well, read_noise } => {
                        1.0 / exposure_variance(&x, z, full_well, read_noise).max(1e-300)
                    }
                })
                .collect();
            (x, w)
        })
        .collect();
    let time_factor = |t: f64| match weights {
        Weights::Hat | Weights::NoiseFromStack => 1.0,
        Weights::Noise { .. } => t * t,
    };
    let log_times: Vec<f64> = times.iter().map(|t| t.ln()).collect();
    use rayon::prelude::*;
    let results: Vec<([f32; 3], u8)> = (0..n)
        .into_par_iter()
        .map(|i| {
            let mut out = [0.0f32; 3];
            let mut mask = WELL_EXPOSED;
            for c in 0..3 {
                let (x, w) = &tables[c];
                // Hat: Debevec & Malik's average of ln E; noise: the linear average.
                let estimate = |z: usize, j: usize| match weights {
                    Weights::Hat | Weights::NoiseFromStack => response.g[c][z] - log_times[j],
                    Weights::Noise { .. } => x[z] / times[j],
                };
                let finish = |v: f64| match weights {
                    Weights::Hat | Weights::NoiseFromStack => v.exp(),
                    Weights::Noise { .. } => v,
                };
                let (mut num, mut den) = (0.0f64, 0.0f64);
                for (j, f) in frames.iter().enumerate() {
                    let z = (f[3 * i + c].min(top)) as usize;
                    let wj = w[z] * time_factor(times[j]);
                    num += wj * estimate(z, j);
                    den += wj;
                }
                if den > 0.0 {
                    out[c] = finish(num / den) as f32;
                } else {
                    // No frame is inside the range: a bound from the nearest end.
                    let all_high = frames.iter().all(|f| f[3 * i + c] >= top);
                    let j = if all_high { shortest } else { longest };
                    let z = (frames[j][3 * i + c].min(top)) as usize;
                    out[c] = (x[z] / times[j]) as f32;
                    if all_high {
                        mask = SATURATED;
                    } else if mask == WELL_EXPOSED {
                        mask = DARK;
                    }
                }
            }
            (out, mask)
        })
        .collect();
    let radiance = results.iter().flat_map(|(v, _)| *v).collect();
    let mask = results.iter().map(|(_, m)| *m).collect();
    (radiance, mask)
}
