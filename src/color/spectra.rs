//! Spectral data compiled into the binary (from `data/color`, CSV as distributed by
//! colour-science 0.4.7, 380–780 nm every 5 nm): the CIE 1931 2° observer, the CIE
//! illuminants D65, D50, A and FL2, the 24 ColorChecker Classic reflectances (BabelColor
//! average), two cameras' measured spectral sensitivities (NPL), and the published
//! ColorChecker reference chromaticities (X-Rite, after November 2014, D50).
//!
//! Integrals are plain sums over the 81 samples (the tables' own sampling, as
//! colour-science's `sd_to_XYZ` with the "Integration" method over the same samples): a
//! camera's response to a surface of reflectance R under an illuminant S is
//! c = Σ S(λ)·R(λ)·c̄(λ), its tristimulus values X = Σ S·R·x̄ / Σ S·ȳ (so a perfect white has
//! Y = 1).

/// Samples per spectrum: 380, 385, …, 780 nm.
pub const SAMPLES: usize = 81;
/// The first wavelength and the step, in nanometres.
pub const FIRST_NM: f64 = 380.0;
pub const STEP_NM: f64 = 5.0;

pub type Spectrum = [f64; SAMPLES];

const CMF: &str = include_str!("../../data/color/cie1931_2deg_cmf.csv");
const D65: &str = include_str!("../../data/color/illuminant_d65.csv");
const D50: &str = include_str!("../../data/color/illuminant_d50.csv");
const A: &str = include_str!("../../data/color/illuminant_a.csv");
const FL2: &str = include_str!("../../data/color/illuminant_fl2.csv");
const CHART: &str = include_str!("../../data/color/colorchecker24_babelcolor_average.csv");
const CHART_XYY: &str = include_str!("../../data/color/colorchecker24_after_nov2014_xyY.csv");
const NIKON_D5100: &str = include_str!("../../data/color/camera_nikon_5100_npl.csv");
const SIGMA_SD_MERRILL: &str = include_str!("../../data/color/camera_sigma_sdmerill_npl.csv");

/// The illuminants' names, as a pipeline entry gives them.
pub const ILLUMINANTS: [&str; 4] = ["d65", "d50", "a", "fl2"];
/// The cameras' names.
pub const CAMERAS: [&str; 2] = ["nikon-d5100", "sigma-sd-merrill"];

/// The D50 white point of the published chart values, xy (CIE 1931 2°).
pub const D50_XY: [f64; 2] = [0.345_702_914_918_791, 0.358_538_596_679_933];

/// The data rows of a table (comment and header lines skipped), each split at commas.
fn rows(text: &str) -> impl Iterator<Item = Vec<&str>> {
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .skip(1)
        .map(|l| l.split(',').map(str::trim).collect())
}

fn number(s: &str) -> f64 {
    // The tables are compiled in and checked by a test: a bad cell is a build defect.
    s.parse().unwrap_or(f64::NAN)
}

/// Columns `first..first + n` of a table sampled one row per wavelength.
fn columns<const N: usize>(text: &str, first: usize) -> [Spectrum; N] {
    let mut out = [[0.0; SAMPLES]; N];
    for (k, row) in rows(text).take(SAMPLES).enumerate() {
        for (c, s) in out.iter_mut().enumerate() {
            s[k] = row.get(first + c).map_or(f64::NAN, |v| number(v));
        }
    }
    out
}

/// x̄, ȳ, z̄.
pub fn cmf() -> [Spectrum; 3] {
    columns::<3>(CMF, 1)
}

/// A CIE illuminant's relative spectral power by name (`ILLUMINANTS`).
pub fn illuminant(name: &str) -> Option<Spectrum> {
    let text = match name {
        "d65" => D65,
        "d50" => D50,
        "a" => A,
        "fl2" => FL2,
        _ => return None,
    };
    Some(columns::<1>(text, 1)[0])
}

/// A camera's spectral sensitivities r̄, ḡ, b̄ by name (`CAMERAS`).
pub fn camera(name: &str) -> Option<[Spectrum; 3]> {
    let text = match name {
        "nikon-d5100" => NIKON_D5100,
        "sigma-sd-merrill" => SIGMA_SD_MERRILL,
        _ => return None,
    };
    Some(columns::<3>(text, 1))
}

/// The 24 patches' names and spectral reflectances, row-major from "dark skin".
pub fn chart() -> Vec<(String, Spectrum)> {
    rows(CHART)
        .map(|row| {
            let mut s = [0.0; SAMPLES];
            for (k, v) in s.iter_mut().enumerate() {
                *v = row.get(2 + k).map_or(f64::NAN, |c| number(c));
            }
            (row.get(1).map_or("", |n| n).to_string(), s)
        })
        .collect()
}

/// The published reference XYZ of the 24 patches under D50 (Y = 1 for a perfect white).
pub fn chart_reference_d50() -> Vec<(String, [f64; 3])> {
    rows(CHART_XYY)
        .map(|row| {
            let [x, y, yy] = [2, 3, 4].map(|i| row.get(i).map_or(f64::NAN, |v| number(v)));
            (row.get(1).map_or("", |n| n).to_string(), xyy_to_xyz(x, y, yy))
        })
        .collect()
}

/// xyY → XYZ.
pub fn xyy_to_xyz(x: f64, y: f64, yy: f64) -> [f64; 3] {
    [x * yy / y, yy, (1.0 - x - y) * yy / y]
}

/// The D50 white point's XYZ with Y = 1.
pub fn d50_white() -> [f64; 3] {
    xyy_to_xyz(D50_XY[0], D50_XY[1], 1.0)
}

/// Σ a(λ)·b(λ)·c(λ).
pub fn integrate(a: &Spectrum, b: &Spectrum, c: &Spectrum) -> f64 {
    a.iter().zip(b).zip(c).map(|((a, b), c)| a * b * c).sum()
}

/// The tristimulus values of a reflectance under an illuminant, Y = 1 for a perfect white.
pub fn xyz(reflectance: &Spectrum, illuminant: &Spectrum) -> [f64; 3] {
    let cmf = cmf();
    let norm = illuminant.iter().zip(&cmf[1]).map(|(s, y)| s * y).sum::<f64>();
    cmf.map(|c| integrate(reflectance, illuminant, &c) / norm)
}

/// The illuminant's white point, Y = 1.
pub fn white(illuminant: &Spectrum) -> [f64; 3] {
    xyz(&[1.0; SAMPLES], illuminant)
}

/// A camera's response to a reflectance under an illuminant, scaled so that a perfect white
/// gives 1 in its strongest channel.
pub fn camera_rgb(reflectance: &Spectrum, illuminant: &Spectrum, camera: &[Spectrum; 3]) -> [f64; 3] {
    let norm = camera_norm(illuminant, camera);
    camera.map(|c| integrate(reflectance, illuminant, &c) / norm)
}

/// max over channels of Σ S(λ)·c̄(λ): the response of a perfect white's strongest channel.
pub fn camera_norm(illuminant: &Spectrum, camera: &[Spectrum; 3]) -> f64 {
    camera.iter().map(|c| integrate(&[1.0; SAMPLES], illuminant, c)).fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every table parses whole: 81 finite samples, 24 patches.
    #[test]
    fn tables_parse_whole() {
        let finite = |s: &Spectrum| s.iter().all(|v| v.is_finite());
        assert!(cmf().iter().all(finite));
        for name in ILLUMINANTS {
            assert!(finite(&illuminant(name).unwrap()), "{name}");
        }
        for name in CAMERAS {
            assert!(camera(name).unwrap().iter().all(finite), "{name}");
        }
        let chart = chart();
        assert_eq!(chart.len(), 24);
        assert!(chart.iter().all(|(_, s)| finite(s)));
        assert_eq!(chart[0].0, "dark skin");
        assert_eq!(chart[23].0, "black 2 (1.5 D)");
        let reference = chart_reference_d50();
        assert_eq!(reference.len(), 24);
        assert!(reference.iter().all(|(_, v)| v.iter().all(|x| x.is_finite())));
    }

    /// D65's white point from the 5 nm tables is the CIE's (0.95047, 1, 1.08883) to the
    /// tables' sampling (colour-science gives 0.95046, 1, 1.08906 at 5 nm; 4th decimal).
    #[test]
    fn d65_white_point() {
        let w = white(&illuminant("d65").unwrap());
        assert!(
            (w[0] - 0.9505).abs() < 5e-4 && (w[1] - 1.0).abs() < 1e-12 && (w[2] - 1.089).abs() < 1e-3,
            "{w:?}"
        );
    }
}
