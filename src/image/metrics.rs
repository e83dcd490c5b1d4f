//! Image metrics: comparison of a Monte Carlo render with a reference render.

use super::Image;
use crate::error::Invalid;
use crate::math::stats;
use serde::Serialize;

/// How a render (mean + variance of the mean) agrees with a reference (mean + variance).
#[derive(Clone, Debug, Serialize)]
pub struct Agreement {
    /// Per channel: (mean of render − mean of reference) / mean of reference.
    pub mean_rel_err: Vec<f64>,
    /// Fraction of pixel channels passing the z-test (with a float32 rounding floor on the
    /// variance; where both variances are zero, matching to 1e-4 relative).
    pub pass_fraction: f64,
    /// Per-test significance after Šidák correction.
    pub alpha_sidak: f64,
    /// |z| above which a pixel channel fails.
    pub z_critical: f64,
    pub failed: usize,
    pub tested: usize,
}

/// Per-pixel z-test of `a` against `b` with their variances of the mean, at family level
/// `alpha` with Šidák's correction over all pixel channels, as Mitsuba 3's render tests do:
/// z = (a − b) / √(σ²_a + σ²_b), fail where the two-sided p-value is below α_Šidák.
/// Pixels whose variance is zero in both must agree to 1e-4 relative; elsewhere a float32
/// rounding floor (2·10⁻⁵·max(|a|, |b|))² joins the variance, so that two renderers'
/// rounding of the same noiseless value (Mitsuba's RGB emitter gives 0.899996 for 0.9, a
/// smooth conductor's Fresnel differs in the 7th digit) is not mistaken for a difference.
pub fn agreement(
    a: &Image,
    var_a: &Image,
    b: &Image,
    var_b: &Image,
    alpha: f64,
) -> Result<Agreement, Invalid> {
    for (name, img) in [("variance", var_a), ("reference", b), ("reference variance", var_b)] {
        if (img.width, img.height, img.channels) != (a.width, a.height, a.channels) {
            return Err(format!(
                "{name} is {}x{}x{}, the render {}x{}x{}",
                img.width, img.height, img.channels, a.width, a.height, a.channels
            )
            .into());
        }
    }
    let tested = a.data.len();
    let alpha_sidak = stats::sidak_alpha(alpha, tested);
    // Find z_critical with two_sided_p(z) = alpha_sidak by bisection (p falls with |z|).
    let (mut lo, mut hi) = (0.0f64, 40.0f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if stats::two_sided_p(mid) > alpha_sidak {
            lo = mid
        } else {
            hi = mid
        }
    }
    let z_critical = hi;
    let mut failed = 0;
    for i in 0..tested {
        let (x, y) = (a.data[i] as f64, b.data[i] as f64);
        let v = var_a.data[i] as f64 + var_b.data[i] as f64;
        let ok = if v > 0.0 {
            let v = v + (2e-5 * x.abs().max(y.abs())).powi(2);
            ((x - y) / v.sqrt()).abs() <= z_critical
        } else {
            (x - y).abs() <= 1e-4 * x.abs().max(y.abs()).max(1e-30)
        };
        if !ok {
            failed += 1;
        }
    }
    let (ma, mb) = (a.channel_means(), b.channel_means());
    Ok(Agreement {
        mean_rel_err: ma.iter().zip(&mb).map(|(x, y)| (x - y) / y.abs().max(1e-30)).collect(),
        pass_fraction: 1.0 - failed as f64 / tested.max(1) as f64,
        alpha_sidak,
        z_critical,
        failed,
        tested,
    })
}

/// Root-mean-square difference over every channel of two images of one size (NaN when the
/// sizes differ or either is empty, which a caller records as missing).
/// Relative mean squared error of `a` against the reference `b`, mean((a − b)²/(b² + 0.01))
/// over the pixel channels of the window [x0, y0, x1, y1) (the whole image when `None`): the
/// 0.01 keeps black pixels of the reference from dominating (Rousselle et al. 2011's form, as
/// denoising and light-transport papers report it). NaN when the images' shapes differ or the
/// window holds no pixel.
pub fn relmse(a: &Image, b: &Image, window: Option<[u32; 4]>) -> f64 {
    if (a.width, a.height, a.channels) != (b.width, b.height, b.channels) {
        return f64::NAN;
    }
    let [x0, y0, x1, y1] = window.unwrap_or([0, 0, a.width, a.height]);
    let (x1, y1) = (x1.min(a.width), y1.min(a.height));
    let c = a.channels as usize;
    let (mut sum, mut n) = (0.0, 0usize);
    for y in y0..y1 {
        for x in x0..x1 {
            let i = (y as usize * a.width as usize + x as usize) * c;
            for k in i..i + c {
                let (p, r) = (a.data[k] as f64, b.data[k] as f64);
                sum += (p - r).powi(2) / (r * r + 0.01);
                n += 1;
            }
        }
    }
    if n == 0 {
        f64::NAN
    } else {
        sum / n as f64
    }
}

pub fn rmse(a: &Image, b: &Image) -> f64 {
    if (a.width, a.height, a.channels) != (b.width, b.height, b.channels) || a.data.is_empty() {
        return f64::NAN;
    }
    let se: f64 = a.data.iter().zip(&b.data).map(|(x, y)| (*x as f64 - *y as f64).powi(2)).sum();
    (se / a.data.len() as f64).sqrt()
}
