//! The `color` stage: renders a ColorChecker spectrally, exposes it through the sensor model,
//! samples its patches and fits a colour-correction model with `color::run`, the function
//! `lumen color fit` calls.
//!
//! Spectral rendering through the RGB path tracer: light transport is linear and, per
//! wavelength, independent, so the chart is rendered once per three wavelengths of the
//! tables' 81 (380–780 nm every 5 nm; 27 renders), each channel carrying one wavelength:
//! every `patch-NN` material's albedo becomes that patch's reflectance at the three
//! wavelengths, every other material keeps the mean of its RGB albedo (over its texture) as
//! a flat spectrum, and the scene's directional lights emit the illuminant's power there,
//! each at its share of their summed irradiance, scaled so that a perfect white facing a
//! lone light would give 1 in the camera's strongest channel. The
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
//! its noise-free camera value at the sensor (exposure × Σ share·cos θ × Σ S·R·c̄ / norm, the
//! first sum over the lights, each θ off the chart's normal; the chart must be unshadowed). With
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
//!
//! A chained case fits the chart in an earlier hdr case's merged radiance (`image`) or in
//! one exposure made linear through the response it recovered (`response`): `color_chain`.

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
    /// directional lights, relative to the pipeline file.
    pub scene: String,
    /// The camera's pose instead of the scene's (`{ origin, target, up }`, as a scene's
    /// `[camera] look_at`): one view of a scene other cases share.
    pub look_at: Option<render::scene::LookAt>,
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
    /// `"from:CASE/radiance"`: fit on the radiance an earlier hdr case merged from its
    /// exposures of this chart (`spectral` with this case's camera and illuminant), instead of
    /// one exposure through the sensor (a chained case; no sensor setting, `spp` or `denoise`
    /// then). It runs alone too, on the true radiance, and once per channel with the true
    /// radiance raised to the power 1 + that channel's inherited slope error (or ± 2 % where
    /// smaller), for the sensitivity (`chain`).
    pub image: Option<String>,
    /// `"from:CASE"`: photograph the chart once through the camera an earlier hdr case's
    /// stack came from (its sensor: response curve, bits, full well, read noise; this case's
    /// exposure), and make the codes linear through the response that case recovered, not
    /// the true one (a chained case; no `bits`, `read_noise` or `full_well` then). It runs
    /// alone too, linear through the true response, and once per channel with the true g
    /// scaled by 1 + that channel's inherited slope error (or ± 2 % where smaller).
    pub response: Option<String>,
    /// A deliberate error added to the inherited radiance or response (a chained case only):
    /// every channel raised to the power 1 + `slope` (default none).
    pub perturb: Option<super::color_chain::SlopePerturb>,
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

#[derive(Clone)]
pub struct Truth {
    /// Noise-free camera value of each patch at the sensor (full scale = 1).
    pub(super) rgb: Vec<[f64; 3]>,
    /// The variance of one pixel the sensor model predicts for each patch:
    /// (t·FW + read²)/FW² + q²/12 (photon and read noise, quantisation step q); `None` for an
    /// image that did not come through the sensor in one exposure (a merged radiance).
    pub(super) pixel_variance: Option<Vec<[f64; 3]>>,
    /// The pixels each patch was sampled from.
    pub(super) pixels: Vec<usize>,
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

/// A colour chart's scene, as the stage renders it (module docs).
pub(super) struct Chart {
    /// The scene as loaded (its camera, pose and sensor), the patches' materials flat.
    pub scene: render::Scene,
    digest: String,
    /// The chart's cell grid in the world (`chart_grid`).
    grid: (DVec3, DVec3, DVec3, DVec3),
    /// The scene's directional lights: towards each, and its share of their summed irradiance.
    lights: Vec<(Vec3A, f32)>,
    /// Each patch's material.
    patch_material: Vec<usize>,
    /// The chart's irradiance over that of a surface facing every light: each light's share
    /// times the cosine of its angle off the chart's normal, summed.
    pub cos_theta: f64,
    pub camera: [spectra::Spectrum; 3],
    pub illuminant: spectra::Spectrum,
}

/// A chart's camera signal: per pixel c = Σ_λ L_λ·c̄(λ), a perfect white facing the light
/// at 1 in the camera's strongest channel; the samples per pixel and renders it took.
pub(super) struct Signal {
    pub image: Image,
    pub spp: u32,
    pub bands: usize,
}

impl Chart {
    /// The corners of the cell grid in the image (OpenCV pixels).
    pub fn corners(&self, scene_name: &str) -> Result<[[f64; 2]; 4], StageError> {
        let (origin, step_u, step_v, _) = self.grid;
        let t_cam_world = self.scene.t_world_cam.inverse();
        let project = |p: DVec3| self.scene.camera.project(t_cam_world.transform_point(p));
        let world =
            [origin, origin + 6.0 * step_u, origin + 6.0 * step_u + 4.0 * step_v, origin + 4.0 * step_v];
        let mut corners = [[0.0; 2]; 4];
        for (k, p) in world.iter().enumerate() {
            let px: DVec2 = project(*p).ok_or_else(|| {
                StageError::Config(format!(
                    "{scene_name}: chart corner {} is not in front of the camera",
                    k + 1
                ))
            })?;
            corners[k] = [px.x, px.y];
        }
        Ok(corners)
    }

    /// Each patch's noise-free camera value, the light's cos θ included (in the signal's units).
    pub fn patch_rgb(&self) -> Vec<[f64; 3]> {
        spectra::chart()
            .iter()
            .map(|(_, r)| spectra::camera_rgb(r, &self.illuminant, &self.camera).map(|v| v * self.cos_theta))
            .collect()
    }
}

/// The camera and illuminant by name, refused by name when unknown.
fn camera_and_illuminant(
    camera: &str,
    illuminant: &str,
) -> Result<([spectra::Spectrum; 3], spectra::Spectrum), StageError> {
    let cam = spectra::camera(camera).ok_or_else(|| {
        StageError::Config(format!("camera = \"{camera}\": expected one of {}", spectra::CAMERAS.join(", ")))
    })?;
    let ill = spectra::illuminant(illuminant).ok_or_else(|| {
        StageError::Config(format!(
            "illuminant = \"{illuminant}\": expected one of {}",
            spectra::ILLUMINANTS.join(", ")
        ))
    })?;
    Ok((cam, ill))
}

/// Loads the chart of `scene_file` (relative to the pipeline file), its camera posed by
/// `look_at` when given: its patches, grid and lights, refused by name where the stage cannot
/// render it.
pub(super) fn load_chart(
    scene_file: &str,
    look_at: Option<&render::scene::LookAt>,
    camera: &str,
    illuminant: &str,
    ctx: &Context,
) -> Result<Chart, StageError> {
    let (cam, ill) = camera_and_illuminant(camera, illuminant)?;
    let scene_path = ctx.dir.join(scene_file);
    let mut scene = render::load(&scene_path)?;
    let mut digest = scene_digest(&scene_path)?;
    super::aim(&mut scene, &mut digest, look_at)?;
    let grid = chart_grid(&scene_path)?;
    // Every light becomes the illuminant, at its own strength: distant lights only, whose
    // irradiance on the flat chart is the same on every patch.
    let mut lights = Vec::new();
    for light in &scene.lights {
        match light {
            Light::Directional { to_light, irradiance } => {
                lights.push((to_light.normalize(), (irradiance.x + irradiance.y + irradiance.z) / 3.0))
            }
            _ => {
                return Err(StageError::Config(format!(
                    "{scene_file}: the colour stage needs directional lights only (it gives each the illuminant's spectrum)"
                )))
            }
        }
    }
    let total: f32 = lights.iter().map(|l| l.1).sum();
    if lights.is_empty() || !(total > 0.0) {
        return Err(StageError::Config(format!(
            "{scene_file}: the colour stage needs a directional light that shines on the chart"
        )));
    }
    lights.iter_mut().for_each(|l| l.1 /= total);
    let (origin, step_u, step_v, normal) = grid;
    let centre = origin + 3.0 * step_u + 2.0 * step_v;
    let facing = normal.dot(scene.t_world_cam.translation - centre);
    if let Some(k) = lights.iter().position(|(d, _)| normal.dot(d.as_dvec3()) * facing <= 0.0) {
        return Err(StageError::Config(format!(
            "{scene_file}: light {} does not reach the chart's face the camera sees",
            k + 1
        )));
    }
    let cos_theta = lights.iter().map(|(d, w)| *w as f64 * normal.dot(d.as_dvec3()).abs()).sum::<f64>();

    // Materials: the patches by name; the others keep a flat spectrum, their mean.
    let mut patch_material = vec![None; 24];
    let mut flat = Vec::new();
    for (m, mat) in scene.materials.iter().enumerate() {
        match mat.name.strip_prefix("patch-").and_then(|n| n.parse::<usize>().ok()) {
            Some(k @ 1..=24) => patch_material[k - 1] = Some(m),
            _ => {
                let mean = mat.albedo.mean();
                flat.push((m, (mean.x + mean.y + mean.z) / 3.0));
            }
        }
    }
    if let Some(k) = patch_material.iter().position(Option::is_none) {
        return Err(StageError::Config(format!("{}: no material patch-{:02}", scene_file, k + 1)));
    }
    for (m, mean) in &flat {
        scene.materials[*m].albedo = Texture::Constant(Vec3A::splat(*mean));
    }

    let patch_material = patch_material.into_iter().map(|m| m.unwrap_or(0)).collect();
    Ok(Chart { scene, digest, grid, lights, patch_material, cos_theta, camera: cam, illuminant: ill })
}

/// Renders the chart spectrally and integrates the renders against the camera's
/// sensitivities (module docs); `None` in a share of the shard passes, which only asks for
/// the renders.
pub(super) fn chart_signal(
    chart: &mut Chart,
    spp: Option<u32>,
    denoise: &super::Denoise,
    ctx: &Context,
) -> Result<Option<Signal>, StageError> {
    let (cam, ill) = (chart.camera, chart.illuminant);
    let lights = &chart.lights;
    let scene = &mut chart.scene;
    let digest = &chart.digest;
    let patch_material = &chart.patch_material;
    let mut settings = render::Settings::from_scene(scene);
    apply_overrides(&mut settings, spp, None)?;
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
            scene.materials[*m].albedo = Texture::Constant(Vec3A::from_array(patches[k]));
        }
        let each: Vec<Light> = lights
            .iter()
            .map(|&(to_light, share)| Light::Directional {
                to_light,
                irradiance: Vec3A::from_array(irradiance) * share,
            })
            .collect();
        scene.replace_lights(&each);
        let recipe = BandRecipe {
            product: "color-band",
            scene: digest,
            patches: patches.clone(),
            irradiance,
            settings: SettingsKey::denoised(&settings, denoise),
        };
        let film = ctx.cache.images(ctx.case, &format!("wavelengths {}", b), &recipe, || {
            Ok::<_, StageError>(vec![super::truth_render(scene, &settings, denoise)?])
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

    let image = Image {
        width: w as u32,
        height: h as u32,
        channels: 3,
        data: signal.iter().map(|&v| v as f32).collect(),
    };
    Ok(Some(Signal { image, spp: settings.spp, bands }))
}

pub fn synthesize(c: &Config, ctx: &Context) -> Result<Synthesis<color::Input, Truth>, StageError> {
    camera_and_illuminant(&c.camera, &c.illuminant)?;
    c.model.parse::<Model>()?;
    if !["spectral", "published"].contains(&c.reference.as_str()) {
        return Err(StageError::Config(format!(
            "reference = \"{}\": expected spectral or published",
            c.reference
        )));
    }
    let scene_path = ctx.dir.join(&c.scene);
    let mut sensor = render::load(&scene_path)?.sensor.unwrap_or_default();
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

    let mut chart = load_chart(&c.scene, c.look_at.as_ref(), &c.camera, &c.illuminant, ctx)?;
    let Some(signal) = chart_signal(&mut chart, c.spp, &c.denoise, ctx)? else {
        return Ok(None);
    };
    let (w, h) = (signal.image.width, signal.image.height);
    let max = sensor.max_code() as f32;
    let codes = sensor.expose(&signal.image, render::sampler::mix64(ctx.seed ^ 0xc0_10e5));
    let exposed =
        Image { width: w, height: h, channels: 3, data: codes.iter().map(|&v| v as f32 / max).collect() };
    let corners = chart.corners(&c.scene)?;
    let (input, pixels) = chart_input(c, &chart, &exposed, corners, 1.0)?;
    let truth_rgb: Vec<[f64; 3]> = chart.patch_rgb().iter().map(|t| t.map(|v| v * sensor.exposure)).collect();
    let fw = sensor.full_well;
    let q = 1.0 / sensor.max_code() as f64;
    let shot = if sensor.photon_noise { 1.0 } else { 0.0 };
    let pixel_variance = truth_rgb
        .iter()
        .map(|t| t.map(|v| (shot * v * fw + sensor.read_noise.powi(2)) / (fw * fw) + q * q / 12.0))
        .collect();
    let corner_text: Vec<String> = corners.iter().map(|p| format!("{:.3},{:.3}", p[0], p[1])).collect();
    let mut notes = vec![format!(
        "{} under {}, camera {}, {} renders of three wavelengths, {}×{} px, {} spp; sensor exposure {}, {} bits, full well {} e⁻, read noise {} e⁻; light {:.1}° off the chart's normal; reference {}; grid corners {}.",
        scene_path.file_name().map_or(c.scene.clone(), |n| n.to_string_lossy().into_owned()),
        c.illuminant,
        c.camera,
        signal.bands,
        w,
        h,
        signal.spp,
        sensor.exposure,
        sensor.bits,
        sensor.full_well,
        sensor.read_noise,
        chart.cos_theta.acos().to_degrees(),
        c.reference,
        corner_text.join(",")
    )];
    notes.extend(super::denoise_note(&c.denoise, signal.spp));
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
        Truth { rgb: truth_rgb, pixel_variance: Some(pixel_variance), pixels },
        Findings { notes, files, ..Default::default() },
    )))
}

/// The solver's input from a chart image: its patches sampled inside the grid's `corners`
/// (`saturation`: the image's full scale), with the reference the entry names; and the pixels
/// each patch was sampled from.
pub(super) fn chart_input(
    c: &Config,
    chart: &Chart,
    image: &Image,
    corners: [[f64; 2]; 4],
    saturation: f64,
) -> Result<(color::Input, Vec<usize>), StageError> {
    let samples = chart::sample(image, corners, saturation)
        .map_err(|m| StageError::Config(format!("{}: {m}", c.scene)))?;
    let patches = spectra::chart();
    let (reference, white) = if c.reference == "spectral" {
        (
            patches.iter().map(|(_, r)| spectra::xyz(r, &chart.illuminant)).collect::<Vec<_>>(),
            spectra::white(&chart.illuminant),
        )
    } else {
        let (published, d50) = color::published_reference();
        (published.into_iter().map(|(_, x)| x).collect(), d50)
    };
    let input = color::Input::from_samples(
        &samples,
        patches.iter().map(|(name, _)| name.as_str()).zip(reference.iter().copied()),
        white,
    );
    Ok((input, samples.iter().map(|s| s.pixels).collect()))
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
    // A merged radiance has an arbitrary scale per channel (the response's offset): one scale
    // per channel, the median ratio over the used patches, is taken out first.
    let scale: [f64; 3] = match &truth.pixel_variance {
        Some(_) => [1.0; 3],
        None => std::array::from_fn(|ch| {
            let mut r: Vec<f64> = out
                .patches
                .iter()
                .zip(&truth.rgb)
                .filter(|(p, t)| p.used && t[ch] > 0.0)
                .map(|(p, t)| p.rgb[ch] / t[ch])
                .collect();
            crate::math::stats::median(&mut r).filter(|k| *k > 0.0).unwrap_or(1.0)
        }),
    };
    let rel: Vec<f64> = out
        .patches
        .iter()
        .zip(&truth.rgb)
        .filter(|(p, _)| p.used)
        .flat_map(|(p, t)| (0..3).map(move |ch| (p.rgb[ch] / scale[ch] - t[ch]).abs() / t[ch].max(1e-12)))
        .collect();
    let mean_rel = (!rel.is_empty()).then(|| rel.iter().sum::<f64>() / rel.len() as f64);
    m.push(Metric::maybe("patch_rgb_rel_err", mean_rel, "", Better::Lower, "no usable patch"));
    match &truth.pixel_variance {
        Some(variance) => sensor_metrics(m, out, truth, variance),
        None => {
            let why = "the image is a merged radiance, not one exposure through the sensor model";
            m.push(Metric::missing("patch_rgb_chi2", "", Better::Lower, why));
            m.push(Metric::missing("misflagged_clipped_patches", "patches", Better::Lower, why));
        }
    }
    // Per patch its leave-one-out prediction, reference and white, for a chained case's
    // prediction.
    let items = out
        .patches
        .iter()
        .enumerate()
        .filter(|(_, p)| p.used)
        .filter_map(|(k, p)| {
            let x = p.loo_xyz?;
            Some((k as u64, [x, p.reference_xyz, out.white].concat()))
        })
        .collect();
    f.linear = Some(super::chain::Linear { items, headline: loo_mean_de2000 });
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

/// The metrics of a chart exposed once through the sensor model, whose noise it predicts
/// (`variance`: per patch, one pixel's).
fn sensor_metrics(m: &mut Vec<Metric>, out: &color::Output, truth: &Truth, variance: &[[f64; 3]]) {
    // (sampled − truth)²/σ² over the used patches' channels, σ² the sensor model's: about 1
    // when the render, sensor and sampling chain is right and unbiased.
    let z2: Vec<f64> = out
        .patches
        .iter()
        .zip(truth.rgb.iter().zip(variance).zip(&truth.pixels))
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
        .zip(truth.rgb.iter().zip(variance))
        .filter(|(p, (t, v))| {
            let pixel_sd = |ch: usize| v[ch].sqrt();
            let over = (0..3).any(|ch| t[ch] > 1.0 + 3.0 * pixel_sd(ch));
            let under = (0..3).all(|ch| t[ch] < 1.0 - 3.0 * pixel_sd(ch));
            let flagged = p.flag == Some(color::Flag::Clipped);
            (over && !flagged) || (under && flagged)
        })
        .count();
    m.push(Metric::new("misflagged_clipped_patches", misflagged as f64, "patches", Better::Lower));
}

/// `loo_mean_de2000` from patches' leave-one-out XYZ, reference XYZ and white
/// (`chain::Linear`), as `color::run` takes it.
fn loo_mean_de2000(items: &mut dyn Iterator<Item = &[f64]>) -> Option<f64> {
    use crate::color::delta_e::{delta_e2000, lab};
    let errors: Vec<f64> = items
        .filter(|v| v.len() == 9)
        .map(|v| {
            let white = [v[6], v[7], v[8]];
            delta_e2000(lab([v[0], v[1], v[2]], white), lab([v[3], v[4], v[5]], white))
        })
        .collect();
    (!errors.is_empty()).then(|| errors.iter().sum::<f64>() / errors.len() as f64)
}

impl Settings for Config {
    fn headline(&self) -> &'static str {
        "loo_mean_de2000"
    }
    fn run(&self, ctx: &Context) -> Result<CaseResult, StageError> {
        if let Some(source) = super::from_case(&self.response) {
            return super::color_chain::run_response(self, ctx, &source);
        }
        if let Some(v) = &self.response {
            return Err(StageError::Config(format!(
                "response = \"{v}\": expected \"from:CASE\", an hdr case earlier in the file"
            )));
        }
        match super::color_chain::image_source(&self.image) {
            Some((source, output)) => super::color_chain::run_radiance(self, ctx, &source, &output),
            None if self.image.is_some() => Err(StageError::Config(format!(
                "image = \"{}\": expected \"from:CASE/radiance\", an hdr case earlier in the file",
                self.image.as_deref().unwrap_or("")
            ))),
            None if self.perturb.is_some() => Err(StageError::Config(
                "perturb: only on a chained case (image = \"from:CASE/radiance\"), whose inherited radiance it moves"
                    .into(),
            )),
            None => run_case(|| synthesize(self, ctx), |i| solve(self, i), |o, t| validate(self, o, t)),
        }
    }
    fn upstream(&self) -> Vec<(&'static str, String, &'static str)> {
        let mut from = Vec::new();
        if let Some((source, output)) = super::color_chain::image_source(&self.image) {
            if output == "radiance" {
                from.push(("image", source, "radiance"));
            }
        }
        if let Some(source) = super::from_case(&self.response) {
            from.push(("response", source, "response"));
        }
        from
    }
    /// A chained case's renders are made when it runs (a radiance's: by its source).
    fn share(&self, ctx: &Context, pass: Pass) -> Option<Result<(), StageError>> {
        (pass == Pass::Renders && self.image.is_none() && self.response.is_none())
            .then(|| synthesize(self, ctx).map(|_| ()))
    }
}
