//! Photometric stereo: per-pixel normals and albedo from images under known distant lights.
//!
//! `dataset` reads DiLiGenT's layout, `lambertian` holds the least-squares solvers (Woodham
//! 1980) and their robust variant, `blinn_phong` the non-linear fit of a glossy model,
//! `integrate` turns normals into a depth map and a mesh, `mat` reads MATLAB v5 ground truth.
//!
//! `run(&Input, &Config)` is the stage function the CLI (`lumen ps`) and the pipeline both
//! call: it solves every masked pixel with the chosen model and never sees ground truth.
//! `accuracy` measures an output against truth normals; `write` puts the result files in a
//! folder.

use crate::error::Invalid;
pub mod blinn_phong;
pub mod dataset;
pub mod integrate;
pub mod lambertian;
pub mod mat;

use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{path}: {message}")]
    BadInput { path: PathBuf, message: String },
    #[error("{message}")]
    Input { message: String },
    /// The data determine no pixel's normal (e.g. every light in one plane).
    #[error("no pixel could be solved: {message}")]
    Unsolvable { message: String },
    #[error(transparent)]
    Image(#[from] crate::image::io::Error),
    #[error("cannot write {path}: {message}")]
    Write { path: PathBuf, message: String },
    /// A dataset file that could not be read.
    #[error("{path}: {message}")]
    Read { path: PathBuf, message: String },
}

impl Error {
    pub fn fault(&self) -> crate::Fault {
        use crate::Fault;
        match self {
            Error::BadInput { .. } | Error::Input { .. } => Fault::BadInput,
            Error::Unsolvable { .. } => Fault::Numerical,
            Error::Image(e) => e.fault(),
            Error::Write { .. } | Error::Read { .. } => Fault::Io,
        }
    }
}

/// Raw values (fractions of the largest code) at or above this are saturated.
pub const SATURATED: f32 = 0.999;

/// Observations of many pixels under many lights, pixel-major: `lights` RGB triples per pixel,
/// divided by the light's intensity, each with a flag saying whether it may be used (false
/// when a channel was saturated).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Observations {
    lights: usize,
    data: Vec<[f32; 3]>,
    valid: Vec<bool>,
}

impl Observations {
    pub fn new(pixels: usize, lights: usize) -> Observations {
        Observations { lights, data: vec![[0.0; 3]; pixels * lights], valid: vec![true; pixels * lights] }
    }
    /// Stores a raw observation (code values as fractions of the largest code) under a light
    /// of the given per-channel intensity.
    pub fn set_raw(&mut self, pixel: usize, light: usize, raw: [f32; 3], intensity: [f64; 3]) {
        let k = pixel * self.lights + light;
        self.data[k] = std::array::from_fn(|c| (raw[c] as f64 / intensity[c]) as f32);
        self.valid[k] = raw.iter().all(|&v| v < SATURATED);
    }
    /// Stores a linear observation that no sensor clipped (a render's radiance, which may
    /// exceed 1): always usable.
    pub fn set_linear(&mut self, pixel: usize, light: usize, radiance: [f32; 3], intensity: [f64; 3]) {
        let k = pixel * self.lights + light;
        self.data[k] = std::array::from_fn(|c| (radiance[c] as f64 / intensity[c]) as f32);
        self.valid[k] = true;
    }
    /// All observations of one pixel, in light order.
    pub fn pixel(&self, pixel: usize) -> &[[f32; 3]] {
        &self.data[pixel * self.lights..(pixel + 1) * self.lights]
    }
    /// Which of them may be used.
    pub fn valid(&self, pixel: usize) -> &[bool] {
        &self.valid[pixel * self.lights..(pixel + 1) * self.lights]
    }
}

/// Which reflectance model to fit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Model {
    /// Least squares over every light, on the mean of the channels.
    Lambertian,
    /// Least squares over the observations a Lambertian surface explains (`lambertian` docs).
    Robust,
    /// Normal, diffuse and specular albedo and shininess of Blinn-Phong (`blinn_phong` docs).
    BlinnPhong,
}

impl Model {
    /// The name `--model` and pipeline files use.
    pub fn name(self) -> &'static str {
        match self {
            Model::Lambertian => "lambertian",
            Model::Robust => "robust",
            Model::BlinnPhong => "blinn-phong",
        }
    }
}

impl std::str::FromStr for Model {
    type Err = Invalid;
    fn from_str(s: &str) -> Result<Model, Invalid> {
        match s {
            "lambertian" => Ok(Model::Lambertian),
            "robust" => Ok(Model::Robust),
            "blinn-phong" => Ok(Model::BlinnPhong),
            _ => Err(format!("unknown model `{s}`: expected lambertian, robust or blinn-phong").into()),
        }
    }
}

/// What the solver reads: the masked pixels' observations, the lights, and the view
/// directions. Ground truth never reaches it (`dataset::Dataset` keeps truth beside it).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Input {
    pub width: usize,
    pub height: usize,
    /// Unit light directions (dataset frame).
    pub lights: Vec<DVec3>,
    /// Per-channel light intensities, one row per image.
    pub intensities: Vec<[f64; 3]>,
    /// Pixel indices (y·width + x) inside the mask, in raster order.
    pub pixels: Vec<usize>,
    /// Observations of those pixels, divided by the light intensities, saturation flagged.
    pub obs: Observations,
    /// Unit directions from each masked pixel's surface point towards the camera; `None` for
    /// an orthographic view along +z (DiLiGenT's assumption: its objects are small and far).
    pub views: Option<Vec<DVec3>>,
}

/// How to solve.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct Config {
    pub model: Model,
    /// Keep every pixel's normal after each iteration (Blinn-Phong), so the
    /// error after k iterations can be measured against truth outside the solver. Costs
    /// about 24 bytes per pixel and iteration (default false).
    pub trace: bool,
    /// Gauss-Newton iterations from each Blinn-Phong start before the lowest cost goes on
    /// (`blinn_phong` module docs; default 8, 1 to 100): the fit's time against its accuracy.
    /// Fewer are faster and choose among the starts earlier, which on the renders can pick the
    /// narrow-lobe basin the starts are there to avoid.
    pub start_iterations: u64,
}

/// The range of `Config::start_iterations`.
pub const START_ITERATIONS: std::ops::RangeInclusive<u64> = 1..=100;

/// `k` if it is a valid `Config::start_iterations`, else "k: expected 1 to 100", for the
/// caller to prefix with the name the user gave it.
pub fn check_start_iterations(k: u64) -> Result<u64, Invalid> {
    if START_ITERATIONS.contains(&k) {
        Ok(k)
    } else {
        Err(format!("{k}: expected {} to {}", START_ITERATIONS.start(), START_ITERATIONS.end()).into())
    }
}

impl Config {
    pub fn new(model: Model) -> Config {
        Config { model, trace: false, start_iterations: blinn_phong::START_ITERATIONS }
    }
}

/// The solution over the masked pixels, and what the report needs.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Output {
    pub model: Model,
    /// Unit normals (dataset frame), `None` where the pixel could not be solved.
    pub normals: Vec<Option<DVec3>>,
    pub albedo: Vec<[f64; 3]>,
    /// Blinn-Phong only: specular albedo σ and shininess e per pixel (0 where the pixel kept
    /// the Lambertian solution or was not solved).
    pub specular: Option<Vec<[f64; 2]>>,
    /// With `Config::trace`, Blinn-Phong: per pixel, its normal after each iteration, the
    /// robust Lambertian start first (empty for unsolved pixels).
    pub trace: Option<Vec<Vec<DVec3>>>,
    pub summary: Summary,
}

/// What the solver says of its own run (`summary.json`, with the accuracy when the dataset
/// has ground truth).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Summary {
    pub model: Model,
    /// Pixels inside the mask that got a normal.
    pub pixels: usize,
    /// Pixels inside the mask left without one (fewer than 3 usable observations, or their
    /// lights nearly coplanar).
    pub masked_pixels: usize,
    pub lights: usize,
    /// σ_max / σ_min of the light matrix (rows: unit light directions).
    pub light_condition_number: f64,
    /// The lights nearly lie in a plane (condition number above 5; for a ring of lights at
    /// elevation e it is 1/(√2·tan e), so this flags rings within 8° of the horizon): the
    /// normals' component across the plane is poorly determined.
    pub lights_nearly_coplanar: bool,
    /// Mean number of observations a solved pixel used.
    pub mean_observations_used: f64,
    pub time_s: f64,
    /// Pixel-lights per second of the solve.
    pub pixel_lights_per_s: f64,
    /// Seconds per million masked pixels.
    pub time_per_megapixel_s: f64,
    /// Blinn-Phong only: solved pixels without a specular term (they kept the robust
    /// Lambertian solution, or no observation sampled their lobe; `blinn_phong` docs).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pixels_without_specular: Option<usize>,
}

/// Normals against ground truth: computed outside the solver, from its output.
#[derive(Clone, Debug, Serialize)]
pub struct Accuracy {
    /// Mean and median angular error over the solved pixels that have a truth normal (degrees).
    pub mean_angular_error_deg: f64,
    pub median_angular_error_deg: f64,
    /// Solved pixels left out of the error because their truth normal is zero or not finite
    /// (a mask wider than the object).
    pub pixels_without_truth: usize,
    /// With a trace: the mean angular error of the normals after k iterations (the winning
    /// start's Gauss-Newton iterations, then each round's accepted Levenberg-Marquardt steps),
    /// k = 0 (the robust Lambertian start), 1, 2, …; a pixel that stopped earlier counts with
    /// its final normal.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_angular_error_by_iteration_deg: Option<Vec<f64>>,
}

/// Condition number of the light matrix (infinite for fewer than 3 lights).
pub fn light_condition_number(lights: &[DVec3]) -> f64 {
    if lights.len() < 3 {
        return f64::INFINITY;
    }
    let m = nalgebra::DMatrix::from_fn(lights.len(), 3, |r, c| lights[r][c]);
    let sv = m.singular_values();
    let (lo, hi) = (sv.min(), sv.max());
    if lo > 0.0 {
        hi / lo
    } else {
        f64::INFINITY
    }
}

/// One pixel's solution under any model.
struct Solved {
    normal: DVec3,
    albedo: [f64; 3],
    used: usize,
    /// σ, e (Blinn-Phong).
    specular: [f64; 2],
    /// Normals after each iteration (Blinn-Phong).
    history: Vec<DVec3>,
}

impl From<lambertian::Pixel> for Solved {
    fn from(p: lambertian::Pixel) -> Solved {
        Solved { normal: p.normal, albedo: p.albedo, used: p.used, specular: [0.0; 2], history: Vec::new() }
    }
}

/// Solves every masked pixel with `config.model`. Fewer than 3 lights, an empty mask or
/// observations that do not match the pixels and lights are bad input; data that leave every
/// pixel unsolved (coplanar lights, all in shadow) are `Error::Unsolvable`.
pub fn run(input: &Input, config: &Config) -> Result<Output, Error> {
    let bad = |message: String| Error::Input { message };
    check_start_iterations(config.start_iterations).map_err(|e| bad(format!("start_iterations = {e}")))?;
    if input.lights.len() < 3 {
        return Err(bad(format!("{} light(s): photometric stereo needs at least 3", input.lights.len())));
    }
    if input.pixels.is_empty() {
        return Err(bad("the mask selects no pixel".into()));
    }
    if input.obs.lights != input.lights.len()
        || input.obs.data.len() != input.pixels.len() * input.lights.len()
    {
        return Err(bad(format!(
            "{} observations for {} pixels under {} lights",
            input.obs.data.len(),
            input.pixels.len(),
            input.lights.len()
        )));
    }
    if let Some(v) = &input.views {
        if v.len() != input.pixels.len() {
            return Err(bad(format!("{} view directions for {} pixels", v.len(), input.pixels.len())));
        }
    }
    let model = config.model;
    let t = std::time::Instant::now();
    let solved: Vec<Option<Solved>> = (0..input.pixels.len())
        .into_par_iter()
        .map(|p| {
            let obs = input.obs.pixel(p);
            match model {
                Model::Lambertian => lambertian::solve_plain(&input.lights, obs).map(Solved::from),
                Model::Robust => {
                    lambertian::solve_robust(&input.lights, obs, input.obs.valid(p)).map(Solved::from)
                }
                Model::BlinnPhong => {
                    let view = input.views.as_ref().map_or(DVec3::Z, |v| v[p]);
                    let valid = input.obs.valid(p);
                    blinn_phong::solve(&input.lights, view, obs, valid, config.start_iterations).map(|b| {
                        Solved {
                            normal: b.normal,
                            albedo: b.albedo,
                            used: b.used,
                            specular: [b.specular, b.exponent],
                            history: if config.trace { b.history } else { Vec::new() },
                        }
                    })
                }
            }
        })
        .collect();
    let time_s = t.elapsed().as_secs_f64();
    let cond = light_condition_number(&input.lights);
    if solved.iter().all(Option::is_none) {
        return Err(Error::Unsolvable {
            message: format!(
                "{} pixels under {} lights (light matrix condition number {cond:.3e}): every pixel has fewer than 3 usable observations or lights in one plane",
                input.pixels.len(),
                input.lights.len()
            ),
        });
    }
    let normals: Vec<Option<DVec3>> = solved.iter().map(|s| s.as_ref().map(|p| p.normal)).collect();
    let albedo = solved.iter().map(|s| s.as_ref().map_or([0.0; 3], |p| p.albedo)).collect();
    let ok: Vec<&Solved> = solved.iter().flatten().collect();
    let used = ok.iter().map(|p| p.used as f64).sum::<f64>() / ok.len().max(1) as f64;
    let glossy = model == Model::BlinnPhong;
    let summary = Summary {
        model,
        pixels: ok.len(),
        masked_pixels: input.pixels.len() - ok.len(),
        lights: input.lights.len(),
        light_condition_number: cond,
        lights_nearly_coplanar: !(cond <= 5.0),
        mean_observations_used: used,
        time_s,
        pixel_lights_per_s: (input.pixels.len() * input.lights.len()) as f64 / time_s.max(1e-9),
        time_per_megapixel_s: time_s / (input.pixels.len() as f64 / 1e6),
        pixels_without_specular: glossy.then(|| ok.iter().filter(|p| p.specular[0] == 0.0).count()),
    };
    let specular =
        glossy.then(|| solved.iter().map(|s| s.as_ref().map_or([0.0; 2], |p| p.specular)).collect());
    let trace = (glossy && config.trace)
        .then(|| solved.into_iter().map(|s| s.map_or_else(Vec::new, |p| p.history)).collect());
    Ok(Output { model, normals, albedo, specular, trace, summary })
}

/// Angle in degrees between a unit normal and a truth normal of any length.
fn angle_deg(n: DVec3, truth: DVec3) -> f64 {
    n.dot(truth.normalize()).clamp(-1.0, 1.0).acos().to_degrees()
}

/// A usable truth normal: finite and not zero.
fn usable(t: &DVec3) -> bool {
    t.is_finite() && t.length_squared() > 1e-12
}

/// The output's normals against truth normals (same pixels, dataset frame); `None` when no
/// solved pixel has a usable truth normal.
pub fn accuracy(out: &Output, truth: &[DVec3]) -> Option<Accuracy> {
    let errs = angular_errors(&out.normals, truth);
    let solved_with_truth = errs.len();
    let mean = mean_of(&errs)?;
    let median = median_of(&errs)?;
    let solved = out.normals.iter().zip(truth).filter(|(n, _)| n.is_some()).count();
    let by_iteration = out.trace.as_ref().map(|tr| error_by_iteration(tr, &out.normals, truth));
    Some(Accuracy {
        mean_angular_error_deg: mean,
        median_angular_error_deg: median,
        pixels_without_truth: solved - solved_with_truth,
        mean_angular_error_by_iteration_deg: by_iteration,
    })
}

/// Mean angular error after each iteration (`Accuracy::mean_angular_error_by_iteration_deg`).
fn error_by_iteration(trace: &[Vec<DVec3>], normals: &[Option<DVec3>], truth: &[DVec3]) -> Vec<f64> {
    let longest = trace.iter().map(Vec::len).max().unwrap_or(0);
    (0..longest)
        .map(|k| {
            let (mut sum, mut n) = (0.0, 0usize);
            for ((hist, normal), t) in trace.iter().zip(normals).zip(truth) {
                if let (Some(last), true) = (normal, usable(t)) {
                    let normal = hist.get(k).or(hist.last()).copied().unwrap_or(*last);
                    sum += angle_deg(normal, *t);
                    n += 1;
                }
            }
            sum / n.max(1) as f64
        })
        .collect()
}

/// Angle in degrees between each solved normal and its truth (unsolved pixels and pixels
/// without a usable truth normal left out).
pub fn angular_errors(normals: &[Option<DVec3>], truth: &[DVec3]) -> Vec<f64> {
    normals
        .iter()
        .zip(truth)
        .filter(|(_, t)| usable(t))
        .filter_map(|(n, t)| n.map(|n| angle_deg(n, *t)))
        .collect()
}

/// The upper end of `error.png`'s scale: the 99th percentile of the angular errors, rounded up
/// to 1, 2 or 5 × 10^k degrees (so a 2° map is not nearly black on a fixed 20° scale).
pub fn error_scale_deg(out: &Output, truth: &[DVec3]) -> f64 {
    let mut e = angular_errors(&out.normals, truth);
    e.sort_by(f64::total_cmp);
    let p99 = e.get(e.len().saturating_sub(1) * 99 / 100).copied().unwrap_or(1.0);
    crate::image::colormap::nice_ceiling(p99)
}

fn mean_of(v: &[f64]) -> Option<f64> {
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

fn median_of(v: &[f64]) -> Option<f64> {
    crate::math::stats::median(&mut v.to_vec())
}

/// Writes `normals.exr` / `.png`, `albedo.exr` / `.png`, for Blinn-Phong `specular.exr`
/// (σ) and `shininess.exr` (e; both 0 where a pixel has no specular term), `error.png` (with ground truth:
/// the angular error in viridis from 0° to `error_scale_deg`, with a labelled colour bar; white
/// where a pixel has no estimate, black outside the mask or without truth), the integrated surface as `depth.exr`
/// (orthographic, pixel units, mean 0) and `surface.obj`, and `summary.json` into `dir`. Normals are
/// unit vectors in the dataset's frame, zero outside the mask; the PNG shows (n + 1)/2. The
/// albedo PNG is scaled so that the brightest 1 % of pixels saturate.
/// The files are written together: on an error none of them is left in `dir`.
pub fn write(dir: &Path, data: &Input, out: &Output, truth: Option<&[DVec3]>) -> Result<(), Error> {
    crate::image::io::write_together(dir, |staged| write_files(staged, data, out, truth))
}

fn write_files(dir: &Path, data: &Input, out: &Output, truth: Option<&[DVec3]>) -> Result<(), Error> {
    use crate::image::{colormap, io, Image};
    std::fs::create_dir_all(dir).map_err(|e| Error::Write { path: dir.into(), message: e.to_string() })?;
    let (w, h) = (data.width as u32, data.height as u32);
    let mut normals = Image::new(w, h, 3);
    let mut albedo = Image::new(w, h, 3);
    for (k, &i) in data.pixels.iter().enumerate() {
        if let Some(n) = out.normals[k] {
            normals.data[3 * i..3 * i + 3].copy_from_slice(&[n.x as f32, n.y as f32, n.z as f32]);
        }
        for c in 0..3 {
            albedo.data[3 * i + c] = out.albedo[k][c] as f32;
        }
    }
    io::write_exr(&dir.join("normals.exr"), &normals)?;
    let shown: Vec<u16> =
        data_or_zero(&normals, data, |v| ((v + 1.0) * 0.5 * 255.0).round().clamp(0.0, 255.0) as u16);
    io::write_png_raw(&dir.join("normals.png"), w, h, 3, &shown, 8)?;
    io::write_exr(&dir.join("albedo.exr"), &albedo)?;
    let mut bright: Vec<f32> = albedo.data.iter().copied().filter(|v| *v > 0.0).collect();
    bright.sort_by(f32::total_cmp);
    let top = bright.get(bright.len() * 99 / 100).copied().unwrap_or(1.0).max(1e-12);
    let shown: Vec<u16> =
        albedo.data.iter().map(|v| (v / top * 255.0).round().clamp(0.0, 255.0) as u16).collect();
    io::write_png_raw(&dir.join("albedo.png"), w, h, 3, &shown, 8)?;
    if let Some(spec) = &out.specular {
        for (name, c) in [("specular.exr", 0), ("shininess.exr", 1)] {
            let mut img = Image::new(w, h, 1);
            for (k, &i) in data.pixels.iter().enumerate() {
                img.data[i] = spec[k][c] as f32;
            }
            io::write_exr(&dir.join(name), &img)?;
        }
    }
    if let Some(truth) = truth {
        let scale = error_scale_deg(out, truth);
        let mut err = vec![0u8; 3 * (w * h) as usize];
        for (k, &i) in data.pixels.iter().enumerate() {
            let c = match out.normals[k] {
                Some(_) if !usable(&truth[k]) => continue,
                Some(n) => colormap::viridis(angle_deg(n, truth[k]) / scale),
                None => [255; 3],
            };
            err[3 * i..3 * i + 3].copy_from_slice(&c);
        }
        let (rgb, ew, eh) =
            colormap::with_colour_bar(&err, w, h, "0°", &format!("{}°", colormap::label(scale)));
        let rgb: Vec<u16> = rgb.into_iter().map(u16::from).collect();
        io::write_png_raw(&dir.join("error.png"), ew, eh, 3, &rgb, 8)?;
    }
    if let Some(z) = integrate::depth(data.width, &data.pixels, &out.normals) {
        let mut depth = Image::new(w, h, 1);
        for (k, &i) in data.pixels.iter().enumerate() {
            depth.data[i] = z[k] as f32;
        }
        io::write_exr(&dir.join("depth.exr"), &depth)?;
        let obj = integrate::to_obj(data.width, &data.pixels, &out.normals, &z);
        let path = dir.join("surface.obj");
        io::write_atomically(&path, |tmp| std::fs::write(tmp, obj))?;
    }
    #[derive(Serialize)]
    struct Written<'a> {
        #[serde(flatten)]
        summary: &'a Summary,
        #[serde(flatten)]
        accuracy: Option<Accuracy>,
    }
    let written = Written { summary: &out.summary, accuracy: truth.and_then(|t| accuracy(out, t)) };
    let json = serde_json::to_string_pretty(&written)
        .map_err(|e| Error::Write { path: dir.join("summary.json"), message: e.to_string() })?;
    let path = dir.join("summary.json");
    io::write_atomically(&path, |tmp| std::fs::write(tmp, json))?;
    Ok(())
}

/// Maps every channel value of the masked pixels with `f`; pixels outside the mask are 0.
fn data_or_zero(img: &crate::image::Image, data: &Input, f: impl Fn(f32) -> u16) -> Vec<u16> {
    let mut out = vec![0u16; img.data.len()];
    for &i in &data.pixels {
        for c in 0..3 {
            out[3 * i + c] = f(img.data[3 * i + c]);
        }
    }
    out
}
