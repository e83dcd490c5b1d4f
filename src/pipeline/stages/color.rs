//! The `color` stage: renders a ColorChecker spectrally, exposes it through the sensor model,
//! samples its patches and fits a colour-correction model with `color::run`, the function
//! `lumen color fit` calls.
//!
//! Spectral rendering through the RGB path tracer: light transport is linear and, per
//! wavelength, independent, so the chart is rendered once per three wavelengths of the
//! tables' 81 (380–780 nm every 5 nm; 27 renders), each channel carrying one wavelength:
//! every `patch-NN` material's albedo becomes that patch's reflectance at the three
//! wavelengths, every other material keeps the mean of its RGB albedo as a flat spectrum, and
//! the scene's one directional light emits the illuminant's power there, scaled so that a
//! perfect white facing the light would give 1 in the camera's strongest channel. The
//! camera's signal is then c = Σ_λ L_λ·c̄(λ) per pixel, with its measured sensitivities c̄.
//! Only this stage pays for spectra; the RGB tracer is untouched. The renders go through the
//! render cache: exposure, noise and model changes reuse them.
//!
//! The camera signal goes through the scene's `[sensor]` (exposure, photon and read noise,
//! quantisation, clipping), as a photograph's raw values, scaled to full scale = 1. The
//! corners of the cell grid come from projecting the chart's geometry (found from the
//! patch-01, patch-02 and patch-07 quads of the scene file) through its camera.
//!
//! Truth: each patch's XYZ under the illuminant (CIE 1931 2°, Y = 1 for a perfect white), and
//! its noise-free camera value at the sensor (exposure × cos θ × Σ S·R·c̄ / norm). With
//! `reference = "spectral"` the solver fits against that XYZ, relative to the illuminant's
//! white (what a spectrophotometer reading the chart under the same light gives); with
//! `"published"`, against the published D50 values.
//!
//! Metrics: `mean_de2000`, `max_de2000`, `loo_mean_de2000` (leave-one-out), `mean_de76`,
//! `used_patches`, `patch_rgb_rel_err` (sampled camera values against the noise-free truth:
//! the render, sensor and sampling chain), `patch_rgb_chi2` (the same errors squared over
//! the variance the sensor model predicts for them: about 1 when the chain is unbiased),
//! `misflagged_clipped_patches` (the sampler's clipped flags against the truth, where it is
//! 3σ sure), `fit_s` and `loo_s`.

use super::Synthesis;
use super::{apply_overrides, Context, Findings, Kept, SettingsKey, StageError};
use super::{run_case, CaseResult, Settings};
use crate::color::{self, chart, spectra, Model};
use crate::image::Image;
use crate::pipeline::cache::scene_digest;
use crate::pipeline::cache::Pass;
use crate::pipeline::metric::{Better, Metric};
use crate::render::{self, scene::Light, texture::Texture};
use glam::{DVec2, DVec3, Vec3A};
use serde::{Deserialize, Serialize};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Scene file with the chart (materials `patch-01` … `patch-24`), its camera, sensor and
    /// one directional light, relative to the pipeline file.
    pub scene: String,
    /// `nikon-d5100` or `sigma-sd-merrill` (default nikon-d5100).
    #[serde(default = "default_camera")]
    pub camera: String,
    /// `d65`, `d50`, `a` or `fl2` (default d65).
    #[serde(default = "default_illuminant")]
    pub illuminant: String,
    /// The model (`color::models`; default root-poly-2).
    #[serde(default = "default_model")]
    pub model: String,
    /// `spectral` (the patches' XYZ under the illuminant) or `published` (ColorChecker
    /// values under D50); default spectral.
    #[serde(default = "default_reference")]
    pub reference: String,
    /// Overrides the sensor's exposure (radiance → fraction of full scale; 1e-6 to 1e6).
    pub exposure: Option<f64>,
    /// Overrides the sensor's bits per sample (8 or 16).
    pub bits: Option<u8>,
    /// Overrides the sensor's read noise (electrons).
    pub read_noise: Option<f64>,
    /// Overrides the sensor's full-well capacity (electrons).
    pub full_well: Option<f64>,
    /// Samples per pixel (default: the scene's).
    pub spp: Option<u32>,
    /// Denoise the truth render of each wavelength band (`stages::truth_render`): `true` or
    /// the filter's settings.
    #[serde(default)]
    pub denoise: super::Denoise,
    /// Keep the exposed chart image as `<case>.exr` in the output folder (full scale = 1), so
    /// `lumen color fit` can be run on it; its corners are in the report's notes.
    #[serde(default)]
    pub save_image: bool,
}

fn default_camera() -> String {
    "nikon-d5100".into()
}
fn default_illuminant() -> String {
    "d65".into()
}
fn default_model() -> String {
    "root-poly-2".into()
}
fn default_reference() -> String {
    "spectral".into()
}

pub struct Truth {
    /// Noise-free camera value of each patch at the sensor (full scale = 1).
    rgb: Vec<[f64; 3]>,
    /// The variance of one pixel the sensor model predicts for each patch:
    /// (t·FW + read²)/FW² + q²/12 (photon and read noise, quantisation step q).
    pixel_variance: Vec<[f64; 3]>,
    /// The pixels each patch was sampled from.
    pixels: Vec<usize>,
}

/// Variance of a 20 %-trimmed mean over the mean's, for Gaussian samples (Stigler 1973).
const TRIMMED_MEAN_EFFICIENCY: f64 = 0.94;

/// One three-wavelength render, as the cache keys it.
#[derive(Serialize)]
struct BandRecipe<'a> {
    product: &'static str,
    scene: &'a str,
    /// Per patch the three reflectances, then the light's three irradiances.
    patches: Vec<[f32; 3]>,
    irradiance: [f32; 3],
    settings: SettingsKey,
}

/// The chart's cell grid in the world, from the scene file's patch quads: its top-left
/// corner and the steps of one cell along a row and down a column.
pub(super) fn chart_grid(scene_path: &std::path::Path) -> Result<(DVec3, DVec3, DVec3, DVec3), StageError> {
    let text = std::fs::read_to_string(scene_path).map_err(|e| {
        StageError::Render(render::Error::Io { path: scene_path.into(), message: e.to_string() })
    })?;
    let file: render::scene::SceneFile = toml::from_str(&text).map_err(|e| {
        StageError::Render(render::Error::Parse { path: scene_path.into(), message: e.to_string() })
    })?;
    let centre = |name: &str| {
        file.shapes.iter().find_map(|s| match s {
            render::scene::ShapeSpec::Quad { corner, edge_u, edge_v, material, .. } if material == name => {
                let [c, u, v] = [corner, edge_u, edge_v].map(|a| DVec3::from_array(*a));
                Some((c + 0.5 * (u + v), u.cross(v)))
            }
            _ => None,
        })
    };
    let (Some((c1, n)), Some((c2, _)), Some((c7, _))) =
        (centre("patch-01"), centre("patch-02"), centre("patch-07"))
    else {
        return Err(StageError::Config(format!(
            "{}: expected quads with the materials patch-01, patch-02 and patch-07 (the chart's first patches across and down)",
            scene_path.display()
        )));
    };
    let (step_u, step_v) = (c2 - c1, c7 - c1);
    if step_u.length() == 0.0 || step_v.length() == 0.0 || n.length() == 0.0 {
        return Err(StageError::Config(format!(
            "{}: the patch quads do not form a grid",
            scene_path.display()
        )));
    }
    Ok((c1 - 0.5 * (step_u + step_v), step_u, step_v, n.normalize()))
}

pub fn synthesize(c: &Config, ctx: &Context) -> Result<Synthesis<color::Input, Truth>, StageError> {
    let cam = spectra::camera(&c.camera).ok_or_else(|| {
        StageError::Config(format!(
            "camera = \"{}\": expected one of {}",
            c.camera,
            spectra::CAMERAS.join(", ")
        ))
    })?;
    let ill = spectra::illuminant(&c.illuminant).ok_or_else(|| {
        StageError::Config(format!(
            "illuminant = \"{}\": expected one of {}",
            c.illuminant,
            spectra::ILLUMINANTS.join(", ")
        ))
    })?;
    c.model.parse::<Model>()?;
    if !["spectral", "published"].contains(&c.reference.as_str()) {
        return Err(StageError::Config(format!(
            "reference = \"{}\": expected spectral or published",
            c.reference
        )));
    }
    let scene_path = ctx.dir.join(&c.scene);
    let mut scene = render::load(&scene_path)?;
    let digest = scene_digest(&scene_path)?;
    let (origin, step_u, step_v, normal) = chart_grid(&scene_path)?;

    let mut sensor = scene.sensor.clone().unwrap_or_default();
    if let Some(e) = c.exposure {
        if !(1e-6..=1e6).contains(&e) {
            return Err(StageError::Config(format!("exposure = {e}: expected a number from 1e-6 to 1e6")));
        }
        sensor.exposure = e;
    }
    sensor.bits = c.bits.unwrap_or(sensor.bits);
    sensor.read_noise = c.read_noise.unwrap_or(sensor.read_noise);
    sensor.full_well = c.full_well.unwrap_or(sensor.full_well);
    sensor.validate()?;

    let to_light = match scene.lights.as_slice() {
        [Light::Directional { to_light, .. }] => to_light.normalize(),
        _ => {
            return Err(StageError::Config(format!(
                "{}: the colour stage needs exactly one directional light (it replaces its spectrum)",
                c.scene
            )))
        }
    };
    let cos_theta = normal.dot(DVec3::from(to_light.as_dvec3())).abs();

    // Materials: the patches by name; the others keep a flat spectrum.
    let mut patch_material = vec![None; 24];
    let mut flat = Vec::new();
    for (m, mat) in scene.materials.iter().enumerate() {
        match mat.name.strip_prefix("patch-").and_then(|n| n.parse::<usize>().ok()) {
            Some(k @ 1..=24) => patch_material[k - 1] = Some(m),
            _ => {
                let mean = match &mat.albedo {
                    Texture::Constant(v) => (v.x + v.y + v.z) / 3.0,
                    _ => {
                        return Err(StageError::Config(format!(
                            "material `{}`: the colour stage needs constant albedos outside the patches",
                            mat.name
                        )))
                    }
                };
                flat.push((m, mean));
            }
        }
    }
    if let Some(k) = patch_material.iter().position(Option::is_none) {
        return Err(StageError::Config(format!("{}: no material patch-{:02}", c.scene, k + 1)));
    }
    for (m, mean) in &flat {
        scene.materials[*m].albedo = Texture::Constant(Vec3A::splat(*mean));
    }

    let mut settings = render::Settings::from_scene(&scene);
    apply_overrides(&mut settings, c.spp, None)?;
    settings.seed = ctx.seed;
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    let chart = spectra::chart();
    let norm = spectra::camera_norm(&ill, &cam);
    let mut signal = vec![0.0f64; 3 * w * h];
    let bands = spectra::SAMPLES.div_ceil(3);
    let bar = render::progress_bar(bands as u64, &format!("{} wavelengths", ctx.case), ctx.progress);
    for b in 0..bands {
        let lambdas: Vec<usize> = (3 * b..(3 * b + 3).min(spectra::SAMPLES)).collect();
        let pick = |s: &spectra::Spectrum| -> [f32; 3] {
            std::array::from_fn(|ch| lambdas.get(ch).map_or(0.0, |&l| s[l] as f32))
        };
        // E(λ) = π·S(λ)/norm: a white Lambertian facing the light has radiance S(λ)/norm.
        let irradiance = pick(&ill.map(|s| std::f64::consts::PI * s / norm));
        let patches: Vec<[f32; 3]> = chart.iter().map(|(_, r)| pick(r)).collect();
        for (k, m) in patch_material.iter().enumerate() {
            scene.materials[m.unwrap_or(0)].albedo = Texture::Constant(Vec3A::from_array(patches[k]));
        }
        scene.replace_lights(&[Light::Directional { to_light, irradiance: Vec3A::from_array(irradiance) }]);
        let recipe = BandRecipe {
            product: "color-band",
            scene: &digest,
            patches: patches.clone(),
            irradiance,
            settings: SettingsKey::denoised(&settings, &c.denoise),
        };
        let film = ctx.cache.images(ctx.case, &format!("wavelengths {}", b), &recipe, || {
            Ok::<_, StageError>(vec![super::truth_render(&scene, &settings, &c.denoise)?])
        })?;
        let Some(film) = film else { continue };
        let Some(img) = film.first().filter(|f: &&Image| f.data.len() == 3 * w * h) else {
            return Err(StageError::Config(format!("band {b}: the cached render has the wrong size")));
        };
        for (px, v) in img.data.chunks_exact(3).enumerate() {
            for (ch, &l) in lambdas.iter().enumerate() {
                for k in 0..3 {
                    signal[3 * px + k] += v[ch] as f64 * cam[k][l];
                }
            }
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    if ctx.renders_only() {
        return Ok(None);
    }

    let radiance = Image {
        width: w as u32,
        height: h as u32,
        channels: 3,
        data: signal.iter().map(|&v| v as f32).collect(),
    };
    let max = sensor.max_code() as f32;
    let codes = sensor.expose(&radiance, render::sampler::mix64(ctx.seed ^ 0xc0_10e5));
    let exposed = Image {
        width: w as u32,
        height: h as u32,
        channels: 3,
        data: codes.iter().map(|&v| v as f32 / max).collect(),
    };

    // Corners of the cell grid in the image (OpenCV pixels).
    let t_cam_world = scene.t_world_cam.inverse();
    let project = |p: DVec3| scene.camera.project(t_cam_world.transform_point(p));
    let world = [origin, origin + 6.0 * step_u, origin + 6.0 * step_u + 4.0 * step_v, origin + 4.0 * step_v];
    let mut corners = [[0.0; 2]; 4];
    for (k, p) in world.iter().enumerate() {
        let px: DVec2 = project(*p).ok_or_else(|| {
            StageError::Config(format!("{}: chart corner {} is not in front of the camera", c.scene, k + 1))
        })?;
        corners[k] = [px.x, px.y];
    }
    let samples =
        chart::sample(&exposed, corners, 1.0).map_err(|m| StageError::Config(format!("{}: {m}", c.scene)))?;

    let (reference, white) = if c.reference == "spectral" {
        (chart.iter().map(|(_, r)| spectra::xyz(r, &ill)).collect::<Vec<_>>(), spectra::white(&ill))
    } else {
        let (published, d50) = color::published_reference();
        (published.into_iter().map(|(_, x)| x).collect(), d50)
    };
    let input = color::Input::from_samples(
        &samples,
        chart.iter().map(|(name, _)| name.as_str()).zip(reference.iter().copied()),
        white,
    );
    let truth_rgb: Vec<[f64; 3]> = chart
        .iter()
        .map(|(_, r)| spectra::camera_rgb(r, &ill, &cam).map(|v| v * sensor.exposure * cos_theta))
        .collect();
    let fw = sensor.full_well;
    let q = 1.0 / sensor.max_code() as f64;
    let shot = if sensor.photon_noise { 1.0 } else { 0.0 };
    let pixel_variance = truth_rgb
        .iter()
        .map(|t| t.map(|v| (shot * v * fw + sensor.read_noise.powi(2)) / (fw * fw) + q * q / 12.0))
        .collect();
    let pixels = samples.iter().map(|s| s.pixels).collect();
    let corner_text: Vec<String> = corners.iter().map(|p| format!("{:.3},{:.3}", p[0], p[1])).collect();
    let mut notes = vec![format!(
        "{} under {}, camera {}, {} renders of three wavelengths, {}×{} px, {} spp; sensor exposure {}, {} bits, full well {} e⁻, read noise {} e⁻; light {:.1}° off the chart's normal; reference {}; grid corners {}.",
        scene_path.file_name().map_or(c.scene.clone(), |n| n.to_string_lossy().into_owned()),
        c.illuminant,
        c.camera,
        bands,
        w,
        h,
        settings.spp,
        sensor.exposure,
        sensor.bits,
        sensor.full_well,
        sensor.read_noise,
        cos_theta.acos().to_degrees(),
        c.reference,
        corner_text.join(",")
    )];
    notes.extend(super::denoise_note(&c.denoise, settings.spp));
    let mut files = Vec::new();
    if c.save_image {
        let name = format!("{}.exr", crate::pipeline::names::file_stem(ctx.case));
        notes.push(format!(
            "The exposed chart is {name}: `lumen color fit --image {name} --corners {}`.",
            corner_text.join(",")
        ));
        files.push((std::path::PathBuf::from(name), Kept::Image(exposed)));
    }
    Ok(Some((
        input,
        Truth { rgb: truth_rgb, pixel_variance, pixels },
        Findings { notes, files, ..Default::default() },
    )))
}

pub fn solve(c: &Config, input: &color::Input) -> Result<color::Output, StageError> {
    let model: Model = c.model.parse()?;
    Ok(color::run(input, &color::Config::new(model))?)
}

pub fn validate(_c: &Config, out: &color::Output, truth: &Truth) -> Findings {
    let mut f = Findings::default();
    let m = &mut f.metrics;
    m.push(Metric::new("mean_de2000", out.mean_de2000, "ΔE00", Better::Lower));
    m.push(Metric::new("max_de2000", out.max_de2000, "ΔE00", Better::Lower));
    m.push(Metric::maybe(
        "loo_mean_de2000",
        out.loo_mean_de2000,
        "ΔE00",
        Better::Lower,
        "no leave-one-out fit (too few patches for the model without one more)",
    ));
    m.push(Metric::new("mean_de76", out.mean_de76, "ΔE*ab", Better::Lower));
    m.push(Metric::new("used_patches", out.used_patches as f64, "patches", Better::Higher));
    let rel: Vec<f64> = out
        .patches
        .iter()
        .zip(&truth.rgb)
        .filter(|(p, _)| p.used)
        .flat_map(|(p, t)| (0..3).map(move |ch| (p.rgb[ch] - t[ch]).abs() / t[ch].max(1e-12)))
        .collect();
    let mean_rel = (!rel.is_empty()).then(|| rel.iter().sum::<f64>() / rel.len() as f64);
    m.push(Metric::maybe("patch_rgb_rel_err", mean_rel, "", Better::Lower, "no usable patch"));
    // (sampled − truth)²/σ² over the used patches' channels, σ² the sensor model's: about 1
    // when the render, sensor and sampling chain is right and unbiased.
    let z2: Vec<f64> = out
        .patches
        .iter()
        .zip(truth.rgb.iter().zip(&truth.pixel_variance).zip(&truth.pixels))
        .filter(|(p, _)| p.used)
        .flat_map(|(p, ((t, v), &n))| {
            (0..3).map(move |ch| {
                (p.rgb[ch] - t[ch]).powi(2) * TRIMMED_MEAN_EFFICIENCY * n as f64 / v[ch].max(1e-300)
            })
        })
        .collect();
    let chi2 = (!z2.is_empty()).then(|| z2.iter().sum::<f64>() / z2.len() as f64);
    m.push(Metric::maybe("patch_rgb_chi2", chi2, "", Better::Lower, "no usable patch"));
    // A patch is surely clipped when its noise-free value is 3σ (of one pixel) above full
    // scale, surely not when 3σ below; the sampler's flag must agree where it is sure.
    let misflagged = out
        .patches
        .iter()
        .zip(truth.rgb.iter().zip(&truth.pixel_variance))
        .filter(|(p, (t, v))| {
            let pixel_sd = |ch: usize| v[ch].sqrt();
            let over = (0..3).any(|ch| t[ch] > 1.0 + 3.0 * pixel_sd(ch));
            let under = (0..3).all(|ch| t[ch] < 1.0 - 3.0 * pixel_sd(ch));
            let flagged = p.flag == Some(color::Flag::Clipped);
            (over && !flagged) || (under && flagged)
        })
        .count();
    m.push(Metric::new("misflagged_clipped_patches", misflagged as f64, "patches", Better::Lower));
    m.push(Metric::new("fit_s", out.fit_s, "s", Better::Lower));
    m.push(Metric::new("loo_s", out.loo_s, "s", Better::Lower));
    f.notes.extend(out.warnings.iter().map(|w| format!("warning: {w}")));
    let worst = out
        .patches
        .iter()
        .enumerate()
        .filter(|(_, p)| p.used)
        .max_by(|a, b| a.1.de2000.total_cmp(&b.1.de2000));
    if let Some((i, p)) = worst {
        f.notes.push(format!("Largest ΔE00: patch {} ({}), {:.3}.", i + 1, p.name, p.de2000));
    }
    f
}

impl Settings for Config {
    fn headline(&self) -> &'static str {
        "loo_mean_de2000"
    }
    fn run(&self, ctx: &Context) -> Result<CaseResult, StageError> {
        run_case(|| synthesize(self, ctx), |i| solve(self, i), |o, t| validate(self, o, t))
    }
    fn share(&self, ctx: &Context, pass: Pass) -> Option<Result<(), StageError>> {
        (pass == Pass::Renders).then(|| synthesize(self, ctx).map(|_| ()))
    }
}
