//! Mitsuba's `<spectrum>` in its RGB variants: wavelength:value pairs integrated against the
//! CIE 1931 observer into linear sRGB as Mitsuba's `spectrum_list_to_srgb` does it — the
//! spectrum linearly interpolated at 1000 wavelengths spread over 360–830 nm, weighted by the
//! D65 illuminant for a reflectance (so a flat 1 is white) and by nothing for an emitter
//! (so a flat 1 has luminance 1), normalised by Mitsuba's ∫ȳ, through Mitsuba's XYZ → sRGB
//! matrix; out-of-gamut results are clipped to [0, 1] for reflectances and to ≥ 0 otherwise.
//! A flat spectrum given as one number is that grey for a reflectance and, for an emitter,
//! that number times the sRGB colour of the equal-energy white, as Mitsuba makes it.
//!
//! The observer and D65 come from `color::spectra` (380–780 nm, 5 nm; Mitsuba's tables reach
//! 360–830 nm, where the observer is below 10⁻³ of its peak).

use crate::color::spectra::{cmf, illuminant, FIRST_NM, SAMPLES, STEP_NM};

/// Mitsuba's 1/∫ȳ(λ)dλ and its D65 normalisation (`MI_CIE_Y_NORMALIZATION`,
/// `MI_CIE_D65_NORMALIZATION`, Mitsuba 3.9).
const CIE_Y_NORMALIZATION: f64 = 1.0 / 106.750_259_399_414_06;
const CIE_D65_NORMALIZATION: f64 = 0.010_101_273_599_490_354;

/// Mitsuba's XYZ → linear sRGB matrix (rows).
const XYZ_TO_SRGB: [[f64; 3]; 3] =
    [[3.240479, -1.53715, -0.498535], [-0.969256, 1.875991, 0.041556], [0.055648, -0.204043, 1.057311]];

/// How a spectrum is used: reflectances are bounded and seen under D65.
#[derive(Clone, Copy, PartialEq, Debug)]
pub enum Use {
    Reflectance,
    /// Unbounded but weighted by D65 (a conductor's η, k).
    Unbounded,
    Emission,
}

fn xyz_to_srgb(xyz: [f64; 3]) -> [f64; 3] {
    XYZ_TO_SRGB.map(|r| r[0] * xyz[0] + r[1] * xyz[1] + r[2] * xyz[2])
}

/// A table of the 380–780 nm samples at `w` nm, linearly interpolated (0 outside).
fn at(table: &[f64; SAMPLES], w: f64) -> f64 {
    let x = (w - FIRST_NM) / STEP_NM;
    if !(0.0..=(SAMPLES - 1) as f64).contains(&x) {
        return 0.0;
    }
    let k = (x as usize).min(SAMPLES - 2);
    let t = x - k as f64;
    table[k] * (1.0 - t) + table[k + 1] * t
}

/// A uniform spectrum's RGB.
pub fn uniform(v: f64, usage: Use) -> [f64; 3] {
    match usage {
        Use::Emission => xyz_to_srgb([1.0; 3]).map(|c| v * c),
        _ => [v; 3],
    }
}

/// Wavelength:value pairs (wavelengths increasing, at least two) as RGB.
pub fn to_rgb(wavelengths: &[f64], values: &[f64], usage: Use) -> [f64; 3] {
    let [x, y, z] = cmf();
    let d65 = illuminant("d65").unwrap_or([0.0; SAMPLES]);
    let (lo, hi) = (360.0, 830.0);
    let steps = 1000;
    let mut xyz = [0.0; 3];
    let last = wavelengths.len() - 1;
    for i in 0..steps {
        let w = lo + (i as f64 / (steps - 1) as f64) * (hi - lo);
        if w < wavelengths[0] || w > wavelengths[last] {
            continue;
        }
        let k = wavelengths.partition_point(|&x| x <= w).saturating_sub(1).min(last - 1);
        let (w0, w1, v0, v1) = (wavelengths[k], wavelengths[k + 1], values[k], values[k + 1]);
        let v = ((w - w1) * v0 + (w0 - w) * v1) / (w0 - w1);
        let weight = if usage == Use::Emission { 1.0 } else { at(&d65, w) * CIE_D65_NORMALIZATION };
        for (c, table) in [&x, &y, &z].into_iter().enumerate() {
            xyz[c] += at(table, w) * v * weight;
        }
    }
    let scale = (hi - lo) / steps as f64 * CIE_Y_NORMALIZATION;
    let rgb = xyz_to_srgb(xyz.map(|c| c * scale));
    match usage {
        Use::Reflectance => rgb.map(|c| c.clamp(0.0, 1.0)),
        _ => rgb.map(|c| c.max(0.0)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against Mitsuba 3.9.1 `scalar_rgb`: the values it makes of these spectra (read back
    /// from the loaded plugins with `mi.traverse`). The tolerance covers the observer's tails
    /// beyond 380–780 nm that lumen's tables lack.
    #[test]
    fn matches_mitsubas_conversion() {
        let cases: [(&[f64], &[f64], Use, [f64; 3]); 6] = [
            (
                &[400.0, 500.0, 600.0, 700.0],
                &[0.2, 0.8, 0.4, 0.9],
                Use::Reflectance,
                [0.389742, 0.652266, 0.513271],
            ),
            (&[380.0, 780.0], &[0.5, 0.5], Use::Reflectance, [0.499466, 0.499456, 0.499272]),
            (&[360.0, 830.0], &[1.0, 1.0], Use::Reflectance, [0.998985, 0.998874, 0.998802]),
            (&[550.0, 560.0], &[0.3, 0.9], Use::Reflectance, [0.010265, 0.0812775, 0.0]),
            (&[450.0, 550.0, 650.0], &[1.0, 2.0, 3.0], Use::Emission, [3.00899, 1.92661, 0.379881]),
            (&[400.0, 700.0], &[10.0, 10.0], Use::Emission, [11.9969, 9.4952, 9.03443]),
        ];
        for (w, v, usage, expected) in cases {
            let rgb = to_rgb(w, v, usage);
            for c in 0..3 {
                assert!(
                    (rgb[c] - expected[c]).abs() <= 2e-3 * expected[c].max(0.1),
                    "{w:?} {v:?}: {rgb:?} vs Mitsuba's {expected:?}"
                );
            }
        }
        // A flat emitter spectrum of 1 over 360–830 nm: Mitsuba gives [1.20488, 0.948228,
        // 0.909267], the equal-energy white.
        let e = uniform(1.0, Use::Emission);
        assert!(
            (e[0] - 1.20488).abs() < 2e-3 && (e[1] - 0.948228).abs() < 2e-3 && (e[2] - 0.909267).abs() < 2e-3,
            "{e:?}"
        );
    }
}
