//! A preview of a radiance map: Reinhard, Stark, Shirley & Ferwerda, "Photographic tone
//! reproduction for digital images", SIGGRAPH 2002, global operator.
//!
//!   L̄ = exp(mean ln(δ + L)),  Lₘ = a·L/L̄,  L_d = Lₘ·(1 + Lₘ/L_white²)/(1 + Lₘ)
//!
//! with a = 0.18 (the key), L_white the 99.9th percentile of Lₘ, and each pixel's RGB
//! scaled by L_d/L; the result is sRGB-encoded when written as PNG.

use crate::image::Image;

/// Tone-maps linear RGB radiance to display values in [0, 1].
pub fn reinhard(radiance: &Image) -> Image {
    let c = radiance.channels as usize;
    let lum: Vec<f64> = radiance.data.chunks_exact(c).map(crate::image::luminance).collect();
    let n = lum.len().max(1) as f64;
    let delta = 1e-6 * lum.iter().copied().fold(0.0, f64::max).max(1e-30);
    let log_mean = (lum.iter().map(|l| (delta + l.max(0.0)).ln()).sum::<f64>() / n).exp();
    let key = 0.18;
    let scaled: Vec<f64> = lum.iter().map(|l| key * l.max(0.0) / log_mean).collect();
    let white = {
        let mut s = scaled.clone();
        s.sort_by(f64::total_cmp);
        s.get(((s.len() as f64) * 0.999) as usize).copied().unwrap_or(1.0).max(1e-12)
    };
    let mut out = Image::new(radiance.width, radiance.height, 3);
    for (i, (p, o)) in radiance.data.chunks_exact(c).zip(out.data.chunks_exact_mut(3)).enumerate() {
        let lm = scaled[i];
        let ld = lm * (1.0 + lm / (white * white)) / (1.0 + lm);
        let k = if lum[i] > 0.0 { ld / lum[i] } else { 0.0 };
        for ch in 0..3 {
            o[ch] = ((p[ch].max(0.0) as f64) * k).clamp(0.0, 1.0) as f32;
        }
    }
    out
}
