//! Colorimetric calibration from a colour chart: the model that maps a camera's linear RGB to
//! CIE XYZ, fitted to a chart's patches and judged in CIEDE2000.
//!
//! `run(&Input, &Config)` is the solver `lumen color fit` and the pipeline's `color` stage
//! both call: the patches' camera RGB and reference XYZ in, the fitted model (`models`) and
//! its report out: per patch ΔE00 and ΔE*ab against the reference (L*a*b* relative to the
//! input's white), their mean and maximum over the patches the fit used, and the
//! leave-one-out mean: each patch predicted by the model fitted to the other patches, the
//! error a patch that was not in the fit can expect, so over-fitting shows (a 35-term
//! polynomial reproduces 24 patches nearly exactly and predicts the 25th badly).
//!
//! Patches flagged clipped or dark by the sampler (`chart`) are left out of the fit with a
//! warning; too few usable patches for the model's terms is a clear error, never NaN.
//!
//! `spectra` holds the spectral data the pipeline's chart renders use and the published
//! chart values; `delta_e` the colour differences.

use crate::error::Invalid;
pub mod chart;
pub mod delta_e;
pub mod detect;
pub mod models;
pub mod spectra;

pub use chart::Flag;
pub use models::{Fitted, Model};

use delta_e::{delta_e2000, delta_e76, lab};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The colour fit's error: the one the hdr fit has too.
pub use crate::fit::FitError as Error;

/// One patch as the solver sees it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PatchInput {
    pub name: String,
    /// Linear camera RGB.
    pub rgb: [f64; 3],
    /// Reference XYZ (Y = 1 for a perfect white).
    pub reference_xyz: [f64; 3],
    /// Set by the sampler: the patch is left out of the fit.
    pub flag: Option<Flag>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Input {
    pub patches: Vec<PatchInput>,
    /// The white of L*a*b* and ΔE (XYZ, Y = 1).
    pub white: [f64; 3],
}

impl Input {
    /// The solver's input from a chart's sampled patches, each beside its name and reference
    /// XYZ (both in chart order).
    pub fn from_samples<'a>(
        samples: &[chart::Sample],
        reference: impl IntoIterator<Item = (&'a str, [f64; 3])>,
        white: [f64; 3],
    ) -> Input {
        let patches = samples
            .iter()
            .zip(reference)
            .map(|(s, (name, xyz))| PatchInput {
                name: name.to_string(),
                rgb: s.rgb,
                reference_xyz: xyz,
                flag: s.flag,
            })
            .collect();
        Input { patches, white }
    }
}

#[derive(Clone, Debug)]
pub struct Config {
    pub model: Model,
    /// The patch (0-based) `white-preserving` maps exactly (default 18, "white 9.5").
    pub white_patch: usize,
    /// Compute the leave-one-out errors (one more fit per patch; default true).
    pub leave_one_out: bool,
}

impl Config {
    pub fn new(model: Model) -> Config {
        Config { model, white_patch: WHITE_PATCH, leave_one_out: true }
    }
}

/// The ColorChecker's "white 9.5 (.05 D)", 0-based.
pub const WHITE_PATCH: usize = 18;

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PatchResult {
    pub name: String,
    pub rgb: [f64; 3],
    pub reference_xyz: [f64; 3],
    pub predicted_xyz: [f64; 3],
    pub de2000: f64,
    pub de76: f64,
    /// The patch predicted by the model fitted without it: its XYZ and ΔE2000.
    #[serde(default)]
    pub loo_xyz: Option<[f64; 3]>,
    pub loo_de2000: Option<f64>,
    /// Whether the fit used the patch.
    pub used: bool,
    pub flag: Option<Flag>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Output {
    pub fitted: Fitted,
    pub white: [f64; 3],
    pub patches: Vec<PatchResult>,
    pub used_patches: usize,
    /// Over the patches the fit used.
    pub mean_de2000: f64,
    pub max_de2000: f64,
    pub mean_de76: f64,
    /// Mean of `loo_de2000` over the used patches it exists for.
    pub loo_mean_de2000: Option<f64>,
    pub loo_max_de2000: Option<f64>,
    pub warnings: Vec<String>,
    /// Seconds for the fit alone and for the leave-one-out fits.
    pub fit_s: f64,
    pub loo_s: f64,
}

pub fn run(input: &Input, config: &Config) -> Result<Output, Error> {
    check_input(input)?;
    let mut warnings = Vec::new();
    let used: Vec<usize> = (0..input.patches.len()).filter(|&i| input.patches[i].flag.is_none()).collect();
    for (i, p) in input.patches.iter().enumerate() {
        if let Some(flag) = p.flag {
            let why = match flag {
                Flag::Clipped => "clipped (over 10 % of its pixels at saturation)",
                Flag::Dark => "too dark (its value is not above the noise)",
            };
            warnings.push(format!("patch {} ({}) is {why}: left out of the fit", i + 1, p.name));
        }
    }
    let white_patch = used.iter().position(|&i| i == config.white_patch);
    if config.model == Model::WhitePreserving && config.white_patch >= input.patches.len() {
        return Err(Error::BadInput(format!(
            "white_patch = {}: the chart has {} patches",
            config.white_patch + 1,
            input.patches.len()
        )));
    }
    let rgb: Vec<[f64; 3]> = used.iter().map(|&i| input.patches[i].rgb).collect();
    let xyz: Vec<[f64; 3]> = used.iter().map(|&i| input.patches[i].reference_xyz).collect();
    let t = std::time::Instant::now();
    let fitted = models::fit(config.model, &rgb, &xyz, input.white, white_patch).map_err(|e| {
        // The patches left out are often why a fit fails: their warnings go with the error.
        let left_out =
            if warnings.is_empty() { String::new() } else { format!(" ({})", warnings.join("; ")) };
        let msg = format!("model {}: {e}{left_out}", config.model.name());
        match e {
            models::FitError::TooFew { .. } | models::FitError::NoWhite | models::FitError::Overflow => {
                Error::BadInput(msg)
            }
            models::FitError::RankDeficient { .. } => Error::Unsolvable(msg),
        }
    })?;
    let fit_s = t.elapsed().as_secs_f64();

    let t = std::time::Instant::now();
    let mut loo = vec![None; input.patches.len()];
    if config.leave_one_out {
        use rayon::prelude::*;
        // One fit per patch, independent of each other: in parallel.
        let folds: Vec<(usize, Result<[f64; 3], models::FitError>)> = used
            .par_iter()
            .enumerate()
            .filter(|&(j, _)| !(config.model == Model::WhitePreserving && Some(j) == white_patch))
            .map(|(j, &i)| {
                let keep = |v: &[[f64; 3]]| -> Vec<[f64; 3]> {
                    v.iter().enumerate().filter(|&(k, _)| k != j).map(|(_, x)| *x).collect()
                };
                let wp = white_patch.map(|w| if w > j { w - 1 } else { w });
                let fit = models::fit(config.model, &keep(&rgb), &keep(&xyz), input.white, wp);
                (i, fit.map(|f| f.apply(rgb[j])))
            })
            .collect();
        if let Some(w) = white_patch.filter(|_| config.model == Model::WhitePreserving) {
            warnings.push(format!(
                "leave-one-out: patch {} is the white white-preserving maps exactly, so it has no fit without it",
                used[w] + 1
            ));
        }
        let mut failed = Vec::new();
        for (i, r) in folds {
            match r {
                Ok(x) => loo[i] = Some(x),
                Err(e) => failed.push(format!("{} ({e})", i + 1)),
            }
        }
        if !failed.is_empty() {
            warnings.push(format!("leave-one-out: no fit without patch {}", failed.join(", ")));
        }
    }
    let loo_s = t.elapsed().as_secs_f64();

    let patches: Vec<PatchResult> = input
        .patches
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let predicted = fitted.apply(p.rgb);
            let (a, b) = (lab(predicted, input.white), lab(p.reference_xyz, input.white));
            PatchResult {
                name: p.name.clone(),
                rgb: p.rgb,
                reference_xyz: p.reference_xyz,
                predicted_xyz: predicted,
                de2000: delta_e2000(a, b),
                de76: delta_e76(a, b),
                loo_xyz: loo[i],
                loo_de2000: loo[i].map(|x| delta_e2000(lab(x, input.white), b)),
                used: p.flag.is_none(),
                flag: p.flag,
            }
        })
        .collect();
    let used_results: Vec<&PatchResult> = patches.iter().filter(|p| p.used).collect();
    let n = used_results.len() as f64;
    let mean = |f: &dyn Fn(&PatchResult) -> f64| used_results.iter().map(|p| f(p)).sum::<f64>() / n;
    let loo_values: Vec<f64> = used_results.iter().filter_map(|p| p.loo_de2000).collect();
    let out = Output {
        mean_de2000: mean(&|p| p.de2000),
        max_de2000: used_results.iter().map(|p| p.de2000).fold(0.0, f64::max),
        mean_de76: mean(&|p| p.de76),
        loo_mean_de2000: (!loo_values.is_empty())
            .then(|| loo_values.iter().sum::<f64>() / loo_values.len() as f64),
        loo_max_de2000: loo_values.iter().copied().reduce(f64::max),
        used_patches: used_results.len(),
        fitted,
        white: input.white,
        patches,
        warnings,
        fit_s,
        loo_s,
    };
    if out.patches.iter().any(|p| !(p.de2000.is_finite() && p.predicted_xyz.iter().all(|v| v.is_finite()))) {
        return Err(Error::Unsolvable(format!(
            "model {}: the fit predicts a non-finite colour",
            config.model.name()
        )));
    }
    Ok(out)
}

/// The largest magnitude of an RGB or XYZ value the solver takes.
pub const MAX_VALUE: f64 = 1e30;

fn check_input(input: &Input) -> Result<(), Error> {
    if input.patches.is_empty() {
        return Err(Error::BadInput("no patches".into()));
    }
    if !input.white.iter().all(|v| v.is_finite() && *v > 0.0 && *v <= MAX_VALUE) {
        return Err(Error::BadInput(format!(
            "white {:?}: expected three positive numbers up to 1e30 (XYZ)",
            input.white
        )));
    }
    for (i, p) in input.patches.iter().enumerate() {
        // Beyond 1e30 (float32 images end near 3e38) a degree-4 term overflows f64.
        if let Some(v) = p.rgb.iter().chain(&p.reference_xyz).find(|v| v.abs() > MAX_VALUE) {
            return Err(Error::BadInput(format!(
                "patch {} ({}): value {v:e} is beyond ±1e30: expected linear RGB and XYZ near 0 to 1",
                i + 1,
                p.name
            )));
        }
        if !p.rgb.iter().chain(&p.reference_xyz).all(|v| v.is_finite()) {
            return Err(Error::BadInput(format!(
                "patch {} ({}): RGB {:?} or reference XYZ {:?} is not finite",
                i + 1,
                p.name,
                p.rgb,
                p.reference_xyz
            )));
        }
        if p.reference_xyz.iter().any(|&v| v < 0.0) {
            return Err(Error::BadInput(format!(
                "patch {} ({}): reference XYZ {:?} is negative",
                i + 1,
                p.name,
                p.reference_xyz
            )));
        }
    }
    // A chart's patches reflect light, and none more than the perfect white the references
    // are relative to: an all-black reference, or a white darker than the brightest patch,
    // would make every ΔE small without saying anything.
    let (k, brightest) = input
        .patches
        .iter()
        .enumerate()
        .map(|(k, p)| (k, p.reference_xyz[1]))
        .fold((0, 0.0f64), |a, b| if b.1 > a.1 { b } else { a });
    if brightest <= 0.0 {
        return Err(Error::BadInput(
            "every patch's reference Y is 0: a chart's patches reflect light (Y near 0.03 to 0.9 of the white)".into(),
        ));
    }
    if brightest > WHITE_MARGIN * input.white[1] {
        return Err(Error::BadInput(format!(
            "patch {} ({}) has reference Y {brightest} but the white's Y is {:e}: the white is the perfect white the references are relative to, brighter than any patch (Y = 1 with patches near 0.03 to 0.9)",
            k + 1,
            input.patches[k].name,
            input.white[1]
        )));
    }
    Ok(())
}

/// How far above the white's Y a patch's reference Y may lie: no reflective patch exceeds the
/// perfect white, but measured references carry a few per cent of error.
const WHITE_MARGIN: f64 = 1.1;

/// Largest |X|, |Y| or |Z| a fitted model may give for camera values within the unit cube:
/// a model that sends the camera's white beyond it (a correction to XYZ near 1) is not a
/// colour correction.
pub const MAX_MODEL_OUTPUT: f64 = 1e6;

/// Refuses a model whose output for camera values in the unit cube (its corners and greys)
/// is not finite or beyond `MAX_MODEL_OUTPUT`.
fn check_model_range(m: &models::Fitted) -> Result<(), Invalid> {
    let mut probes: Vec<[f64; 3]> =
        (0..8).map(|c| [(c & 1) as f64, ((c >> 1) & 1) as f64, ((c >> 2) & 1) as f64]).collect();
    probes.extend([0.01, 0.18, 0.5].map(|g| [g, g, g]));
    for rgb in probes {
        let xyz = m.apply(rgb);
        if !xyz.iter().all(|v| v.is_finite() && v.abs() <= MAX_MODEL_OUTPUT) {
            return Err(format!(
                "camera RGB {rgb:?} maps to XYZ {xyz:?}: expected finite values within ±{MAX_MODEL_OUTPUT:e} for camera values from 0 to 1"
            ).into());
        }
    }
    Ok(())
}

/// The published ColorChecker 24 values (X-Rite, after November 2014) under D50, and the D50
/// white: the default reference.
pub fn published_reference() -> (Vec<(String, [f64; 3])>, [f64; 3]) {
    (spectra::chart_reference_d50(), spectra::d50_white())
}

/// Reads reference values: CSV with the header `patch,X,Y,Z`, patches 1 to 24 each once
/// (any order), Y = 1 for a perfect white; `#` starts a comment line.
pub fn read_reference(path: &Path) -> Result<Vec<[f64; 3]>, Error> {
    read_table(path, ["patch", "x", "y", "z"], false)
}

/// Reads measured patch values: CSV with the header `patch,R,G,B` (linear camera RGB),
/// patches 1 to 24 each once.
pub fn read_patch_rgb(path: &Path) -> Result<Vec<[f64; 3]>, Error> {
    read_table(path, ["patch", "r", "g", "b"], true)
}

fn read_table(path: &Path, columns: [&str; 4], negative_ok: bool) -> Result<Vec<[f64; 3]>, Error> {
    let err = |message: String| Error::File { path: path.into(), message };
    let text =
        std::fs::read_to_string(path).map_err(|e| Error::Io { path: path.into(), message: e.to_string() })?;
    let mut lines =
        text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    let header: Vec<String> = lines
        .next()
        .map(|(_, l)| l.split(',').map(|s| s.trim().to_lowercase()).collect())
        .unwrap_or_default();
    let shown = format!(
        "{},{},{},{}",
        columns[0],
        columns[1].to_uppercase(),
        columns[2].to_uppercase(),
        columns[3].to_uppercase()
    );
    if header != columns {
        return Err(err(format!("expected the header `{shown}`")));
    }
    let mut values: Vec<Option<[f64; 3]>> = vec![None; 24];
    for (n, line) in lines {
        let at = |m: String| err(format!("line {}: {m}", n + 1));
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        if cells.len() != 4 {
            return Err(at(format!("{} fields: expected 4 ({shown})", cells.len())));
        }
        let patch: usize =
            cells[0].parse().map_err(|_| at(format!("patch `{}`: expected a number 1 to 24", cells[0])))?;
        if !(1..=24).contains(&patch) {
            return Err(at(format!("patch {patch}: expected 1 to 24")));
        }
        let mut v = [0.0; 3];
        for c in 0..3 {
            let x: f64 =
                cells[c + 1].parse().map_err(|_| at(format!("`{}`: expected a number", cells[c + 1])))?;
            if !(x.is_finite() && (negative_ok || x >= 0.0)) {
                let kind = if negative_ok { "finite" } else { "finite, non-negative" };
                return Err(at(format!("{x}: expected a {kind} number")));
            }
            v[c] = x;
        }
        if values[patch - 1].replace(v).is_some() {
            return Err(at(format!("patch {patch} is given twice")));
        }
    }
    let missing: Vec<String> =
        (0..24).filter(|&i| values[i].is_none()).map(|i| (i + 1).to_string()).collect();
    if !missing.is_empty() {
        return Err(err(format!("no values for patch {}", missing.join(", "))));
    }
    Ok(values.into_iter().flatten().collect())
}

/// Writes a 24-row table with the header `patch,A,B,C` (full precision), atomically.
pub fn write_table(path: &Path, columns: [&str; 3], rows: &[[f64; 3]], comment: &str) -> Result<(), Error> {
    let mut text = format!("# {comment}\npatch,{},{},{}\n", columns[0], columns[1], columns[2]);
    for (i, r) in rows.iter().enumerate() {
        text.push_str(&format!("{},{:e},{:e},{:e}\n", i + 1, r[0], r[1], r[2]));
    }
    Ok(crate::image::io::write_atomically(path, |tmp| std::fs::write(tmp, &text))?)
}

/// Parses `X,Y,Z` (a white) or `x1,y1,…` (corners): `n` finite numbers.
pub fn parse_numbers<const N: usize>(s: &str, what: &str) -> Result<[f64; N], Invalid> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("{what} `{s}`: expected {N} comma-separated numbers"))?;
    let arr: [f64; N] =
        v.try_into().map_err(|v: Vec<f64>| format!("{what} `{s}`: {} numbers, expected {N}", v.len()))?;
    if arr.iter().any(|x| !x.is_finite()) {
        return Err(format!("{what} `{s}`: expected finite numbers").into());
    }
    Ok(arr)
}

/// The fitted model as `lumen color fit` writes it and `lumen color apply` reads it.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CcmFile {
    /// Always `lumen-ccm`: what the file is.
    pub format: String,
    pub fitted: Fitted,
    /// The reference white (XYZ) the model's output is relative to.
    pub white: [f64; 3],
    /// The fit's report (absent when written by hand).
    #[serde(default)]
    pub report: Option<Output>,
    /// Where the patch values came from: the file, how its values were read (an sRGB JPEG
    /// is the camera's rendering, not linear data), and whether the chart's corners were
    /// given or found.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
}

pub const CCM_FORMAT: &str = "lumen-ccm";

pub fn read_ccm(path: &Path) -> Result<CcmFile, Error> {
    let err = |message: String| Error::File { path: path.into(), message };
    let text =
        std::fs::read_to_string(path).map_err(|e| Error::Io { path: path.into(), message: e.to_string() })?;
    let de = &mut serde_json::Deserializer::from_str(&text);
    let file: CcmFile =
        serde_path_to_error::deserialize(de).map_err(|e| err(format!("{}: {}", e.path(), e.inner())))?;
    if file.format != CCM_FORMAT {
        return Err(err(format!("format `{}`: expected `{CCM_FORMAT}`", file.format)));
    }
    file.fitted.check().map_err(|m| err(format!("fitted: {m}")))?;
    check_model_range(&file.fitted).map_err(|m| err(format!("fitted: {m}")))?;
    if !file.white.iter().all(|v| v.is_finite() && *v > 0.0) {
        return Err(err(format!("white {:?}: expected three positive numbers", file.white)));
    }
    Ok(file)
}

/// XYZ (relative to `white`) → linear sRGB (D65), through the Bradford chromatic adaptation
/// from `white` to D65 (IEC 61966-2-1's matrix).
pub fn xyz_to_linear_srgb(white: [f64; 3]) -> [[f64; 3]; 3] {
    use glam::DMat3;
    let bradford =
        DMat3::from_cols_array(&[0.8951, -0.7502, 0.0389, 0.2664, 1.7135, -0.0685, -0.1614, 0.0367, 1.0296]);
    let d65 = glam::DVec3::new(0.95047, 1.0, 1.08883);
    let src = bradford * glam::DVec3::from_array(white);
    let dst = bradford * d65;
    let adapt = bradford.inverse() * DMat3::from_diagonal(dst / src) * bradford;
    let to_srgb = DMat3::from_cols_array(&[
        3.2404542, -0.9692660, 0.0556434, -1.5371385, 1.8760108, -0.2040259, -0.4985314, 0.0415560, 1.0572252,
    ]);
    let m = to_srgb * adapt;
    let r = m.transpose().to_cols_array_2d();
    [r[0], r[1], r[2]]
}
