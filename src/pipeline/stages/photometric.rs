//! The `photometric` stage: renders an object scene once per distant light with the path
//! tracer (cast shadows and interreflections included), runs the same photometric-stereo
//! solver `lumen ps` runs, and compares its normals with the renderer's truth normals.
//!
//! Lights: `lights` directions spread by the golden angle in azimuth, elevations evenly from
//! `elevation_deg[0]` to `[1]` above the plane facing the camera, each with the same
//! irradiance. Data reach the solver as DiLiGenT's would: directions and normals in its frame
//! (x right, y up, z towards the camera), the images' linear radiance, the light intensities.
//! The view direction of each pixel comes from the camera model (the reversed ray through its
//! centre), as a calibrated setup would give it. The mask is the object's pixels whose 3×3
//! neighbourhood is all object (edge pixels mix in the background). Truth: the normal
//! averaged over each pixel's footprint (`render::truth::footprint_normals`, 8×8 rays), the
//! normal a Lambertian pixel's brightness is linear in; pixels whose footprint holds normals
//! more than 10° from that mean (the object occluding itself, creases) are left out.
//!
//! The solver is `photometric::run`, the function `lumen ps` calls; it never sees the truth.
//! Each light's render goes through the render cache.
//!
//! A chained case (`camera = "from:CASE"`, `chain`) is given a calibrated camera, as a user
//! who calibrated first is: each render (made through the scene's true camera, as a
//! photograph is) is undistorted through it onto a pinhole of its own intrinsics (OpenCV's
//! `undistort` with the same camera matrix), bilinear, and the pinhole's rays give the views.
//! The truth is taken on those rays, with the true pose: the normal of the surface a pixel's
//! believed ray meets, which is what a normal map is used as (integrated to depth, fused with
//! a reconstruction). A wrong calibration so misplaces the normals it recovers, besides
//! bending the views. The mask is the object on those rays and, as the undistorted image holds
//! it, at all four taps of the pixel's source. Run alone, the same case undistorts through the
//! true camera.
//!
//! A case with `dataset` instead of `scene` (`DataConfig`) reads a real capture in DiLiGenT's
//! layout, as `lumen ps --dataset` does, and compares with the dataset's own ground-truth
//! normals (`Normal_gt.mat`); it has no albedo truth. When the folder is absent (no
//! `../shared` beside a fresh clone) the case is skipped with the reason.
//!
//! Metrics: `mean_angular_error_deg`, `median_angular_error_deg`, `masked_pixels` (mask
//! pixels left without a normal) and `masked_share` (their share of the mask), `mean_albedo_rel_err` (|π·ρ − kd|/kd against the truth
//! albedo image, over channels and solved pixels), `light_condition_number`, `pixel_lights_per_s`,
//! `time_per_megapixel_s`; with `model = "blinn-phong"` also the robust Lambertian model's
//! error on the same images (`robust_lambertian_mean_angular_error_deg`), the ratio of the
//! two (`improvement_over_lambertian`, higher is better), `pixels_without_specular`, and a
//! note with the mean error after each iteration (from the solver's trace of
//! normals, compared with truth here).

use super::Synthesis;
use super::{apply_overrides, Context, Findings, Kept, SettingsKey, StageError, MAX_RENDERS};
use super::{run_case, CaseResult, Settings};
use crate::image::Image;
use crate::math::CameraModel;
use crate::photometric::{self, Model, Observations};
use crate::pipeline::cache::scene_digest;
use crate::pipeline::cache::Pass;
use crate::pipeline::metric::{Better, Metric};
use crate::render::{self, scene::Light};
use glam::{DVec2, DVec3, Vec3A};
use serde::{Deserialize, Serialize};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Scene file with the object and camera, relative to the pipeline file; its own point and
    /// directional lights are replaced by the stage's.
    pub scene: String,
    /// The camera's pose instead of the scene's (`{ origin, target, up }`, as a scene's
    /// `[camera] look_at`): one view of a scene other cases share.
    pub look_at: Option<crate::render::scene::LookAt>,
    /// The object's material: the mask is the pixels that see it (default: every shape, the
    /// object alone before an empty background). The other shapes (a room around the object)
    /// stay in every render, where they shadow the object and light it.
    pub object: Option<String>,
    /// Number of distant lights (default 24, 3 to 1000).
    #[serde(default = "default_lights")]
    pub lights: usize,
    /// Lowest and highest light elevation in degrees above the plane facing the camera
    /// (default [25, 70]).
    #[serde(default = "default_elevation")]
    pub elevation_deg: [f64; 2],
    /// Irradiance of every light on a surface facing it (default 3; 1e-30 to 1e30).
    #[serde(default = "default_irradiance")]
    pub irradiance: f64,
    /// Samples per pixel (default: the scene's).
    pub spp: Option<u32>,
    /// Longest path (default: the scene's); 2 renders direct light only, without
    /// interreflections.
    pub max_depth: Option<u32>,
    /// Denoise each light's render (`stages::truth_render`): `true` or the filter's settings.
    #[serde(default)]
    pub denoise: super::Denoise,
    /// `lambertian`, `robust` or `blinn-phong` (default robust).
    #[serde(default = "default_model")]
    pub model: String,
    /// Blinn-Phong: Gauss-Newton iterations from each start (default 8, 1 to 100;
    /// `photometric::Config::start_iterations`), the fit's time against its accuracy.
    #[serde(default = "default_start_iterations")]
    pub start_iterations: u64,
    /// Overrides the shininess (exponent) of every Blinn-Phong material in the scene.
    pub shininess: Option<f64>,
    /// Scales every material's diffuse albedo (default 1): 0.01 makes a nearly black object.
    #[serde(default = "one")]
    pub albedo_scale: f64,
    /// Makes every material Lambertian, keeping its diffuse colour (default false).
    #[serde(default)]
    pub diffuse_only: bool,
    /// Keep what the solver reads, in DiLiGenT's layout (one EXR per light, the lights, the
    /// mask and the truth normals as `Normal_gt.mat`), as the folder `<case>` in the output
    /// folder, so `lumen ps` can be run on exactly it (default false). `lumen ps` assumes an
    /// orthographic view, so only the Lambertian models give the stage's numbers there.
    #[serde(default)]
    pub save_dataset: bool,
    /// `"from:CASE"`: the camera an earlier calibrate case estimated (a chained case). The
    /// renders, made through the scene's true camera, are undistorted through it onto a
    /// pinhole of its intrinsics, and its rays give the views and the truth (module docs). It
    /// runs alone too, undistorted through the true camera. The calibrated camera must be
    /// this scene's.
    pub camera: Option<String>,
    /// A deliberate error added to the inherited camera (a chained case only): its focal
    /// lengths scaled by 1 + `focal_rel`, `k1` added to its k1 (default none).
    pub perturb: Option<super::chain::Perturb>,
}

/// Largest angle between a pixel's mean normal and any normal in its footprint for the
/// pixel to be in the truth mask (degrees).
const MAX_SPREAD_DEG: f64 = 10.0;

/// A case on a real dataset (module docs).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DataConfig {
    /// Folder in DiLiGenT's layout (`photometric::dataset`), relative to the pipeline file;
    /// it must hold `Normal_gt.mat`.
    pub dataset: String,
    /// `lambertian`, `robust` or `blinn-phong` (default robust).
    #[serde(default = "default_model")]
    pub model: String,
    /// As the rendered cases' `start_iterations`.
    #[serde(default = "default_start_iterations")]
    pub start_iterations: u64,
}

fn default_start_iterations() -> u64 {
    photometric::blinn_phong::START_ITERATIONS
}

/// The `start_iterations` field checked before anything is rendered or read.
fn check_start_iterations(k: u64) -> Result<u64, StageError> {
    photometric::check_start_iterations(k).map_err(|e| StageError::Config(format!("start_iterations = {e}")))
}

fn one() -> f64 {
    1.0
}
fn default_lights() -> usize {
    24
}
fn default_elevation() -> [f64; 2] {
    [25.0, 70.0]
}
fn default_irradiance() -> f64 {
    3.0
}
fn default_model() -> String {
    "robust".into()
}

/// Light directions in the dataset frame (module docs).
pub fn light_directions(n: usize, elevation_deg: [f64; 2]) -> Vec<DVec3> {
    (0..n)
        .map(|k| {
            let t = (k as f64 + 0.5) / n as f64;
            let e = (elevation_deg[0] + t * (elevation_deg[1] - elevation_deg[0])).to_radians();
            let a = k as f64 * 2.399_963_229_728_653; // the golden angle
            DVec3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin())
        })
        .collect()
}

/// What validation compares with, per masked pixel: the footprint-mean normal (dataset
/// frame) and the renderer's albedo kd.
pub struct Truth {
    /// The masked pixels (row-major indices), as the input has them.
    pixels: Vec<usize>,
    normals: Vec<DVec3>,
    /// `None` for a real dataset.
    albedo: Option<Vec<[f64; 3]>>,
}

/// The solver's output, and for Blinn-Phong the robust Lambertian model's on the same data.
pub struct Output {
    main: photometric::Output,
    baseline: Option<photometric::Output>,
}

/// One light's render, as the cache keys it.
#[derive(Serialize)]
struct LightRecipe<'a> {
    product: &'static str,
    scene: &'a str,
    diffuse_only: bool,
    shininess: Option<f64>,
    albedo_scale: f64,
    to_light: [f32; 3],
    irradiance: f64,
    settings: SettingsKey,
}

pub fn synthesize(c: &Config, ctx: &Context) -> Result<Synthesis<photometric::Input, Truth>, StageError> {
    synthesize_given(c, ctx, None)
}

/// `synthesize`, with the renders undistorted through `given`'s first camera (an upstream
/// case's estimate, or the truth it had, which is the second) onto a pinhole of its
/// intrinsics (module docs).
fn synthesize_given(
    c: &Config,
    ctx: &Context,
    given: Option<(CameraModel, CameraModel)>,
) -> Result<Synthesis<photometric::Input, Truth>, StageError> {
    let model: Model = c.model.parse()?;
    check_start_iterations(c.start_iterations)?;
    if !(3..=MAX_RENDERS).contains(&c.lights) {
        return Err(StageError::Config(format!(
            "lights = {}: expected 3 to {MAX_RENDERS} (photometric stereo needs at least 3; each is a render)",
            c.lights
        )));
    }
    let [e0, e1] = c.elevation_deg;
    if !(0.0..=90.0).contains(&e0) || !(0.0..=90.0).contains(&e1) {
        return Err(StageError::Config(format!(
            "elevation_deg = {:?}: expected angles in [0, 90]",
            c.elevation_deg
        )));
    }
    // Radiance is f32 in the renderer: keep it well inside f32's normal range.
    if !(1e-30..=1e30).contains(&c.irradiance) {
        return Err(StageError::Config(format!(
            "irradiance = {}: expected a number from 1e-30 to 1e30 (the renderer's radiance is float32)",
            c.irradiance
        )));
    }
    let scene_path = ctx.dir.join(&c.scene);
    let mut scene = render::load(&scene_path)?;
    let mut digest = scene_digest(&scene_path)?;
    super::aim(&mut scene, &mut digest, c.look_at.as_ref())?;
    // The ids of the shapes that are the object.
    let object_ids: Option<Vec<u32>> = match &c.object {
        None => None,
        Some(name) => {
            let m = scene.materials.iter().position(|m| &m.name == name).ok_or_else(|| {
                StageError::Config(format!(
                    "object = \"{name}\": {} has no material of that name (it has {})",
                    c.scene,
                    scene.materials.iter().map(|m| format!("`{}`", m.name)).collect::<Vec<_>>().join(", ")
                ))
            })?;
            let mut ids: Vec<u32> =
                scene.info.iter().filter(|i| i.material as usize == m).map(|i| i.object_id).collect();
            ids.sort_unstable();
            ids.dedup();
            Some(ids)
        }
    };
    let is_object = |id: f32| id > 0.0 && object_ids.as_ref().is_none_or(|ids| ids.contains(&(id as u32)));
    if c.diffuse_only {
        for m in &mut scene.materials {
            m.bsdf = render::bsdf::Bsdf::Lambertian;
        }
    }
    if !(c.albedo_scale.is_finite() && c.albedo_scale > 0.0 && c.albedo_scale <= 1.0) {
        return Err(StageError::Config(format!(
            "albedo_scale = {}: expected a number in (0, 1]",
            c.albedo_scale
        )));
    }
    if c.albedo_scale != 1.0 {
        for m in &mut scene.materials {
            m.albedo.scale(c.albedo_scale as f32);
        }
    }
    if let Some(e) = c.shininess {
        if !(e.is_finite() && e > 0.0 && e <= 1e4) {
            return Err(StageError::Config(format!("shininess = {e}: expected a positive number up to 1e4")));
        }
        for m in &mut scene.materials {
            if let render::bsdf::Bsdf::BlinnPhong { exponent, .. } = &mut m.bsdf {
                *exponent = e as f32;
            }
        }
    }
    let mut settings = render::Settings::from_scene(&scene);
    apply_overrides(&mut settings, c.spp, c.max_depth)?;
    if settings.max_depth < 2 {
        return Err(StageError::Config(format!(
            "max_depth = {}: the object is lit only from depth 2 on",
            settings.max_depth
        )));
    }
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    let true_camera = scene.camera;
    // Undistorted through a given camera: each pixel's source in the render, and the object
    // as the render holds it (all four bilinear taps on the object).
    let (mut sources, mut undistort) = (None, None);
    if let Some((camera, upstream_truth)) = given {
        super::chain::check_same_camera(c.camera.as_deref().unwrap_or(""), &upstream_truth, &true_camera)?;
        if scene.lens.is_some() {
            return Err(StageError::Config(format!(
                "{}: a thin lens cannot be undistorted through a calibrated pinhole camera",
                c.scene
            )));
        }
        let seen = render::truth(&scene, None);
        let pinhole = CameraModel { distortion: Default::default(), ..camera };
        let at: Vec<Option<DVec2>> = (0..w * h)
            .map(|i| {
                let p = DVec2::new((i % w) as f64, (i / w) as f64);
                let s = crate::calib::undistort::source_pixel(&camera, &pinhole.intrinsics, p);
                let inside = s.x >= 0.0 && s.y >= 0.0 && s.x < (w - 1) as f64 && s.y < (h - 1) as f64;
                let (x0, y0) = (s.x.floor() as usize, s.y.floor() as usize);
                let object = |x: usize, y: usize| is_object(seen.id.data[y * w + x]);
                (inside
                    && object(x0, y0)
                    && object(x0 + 1, y0)
                    && object(x0, y0 + 1)
                    && object(x0 + 1, y0 + 1))
                .then_some(s)
            })
            .collect();
        sources = Some(at);
        undistort = Some((camera, pinhole.intrinsics));
        scene.camera = pinhole;
    }

    // Truth and mask, in the frame the solver sees.
    let truth = render::truth(&scene, None);
    let object = |x: usize, y: usize| is_object(truth.id.data[y * w + x]);
    let pixels: Vec<usize> = (1..h.saturating_sub(1))
        .flat_map(|y| (1..w.saturating_sub(1)).map(move |x| (x, y)))
        .filter(|&(x, y)| (0..3).all(|dy| (0..3).all(|dx| object(x + dx - 1, y + dy - 1))))
        .map(|(x, y)| y * w + x)
        .filter(|&i| sources.as_ref().is_none_or(|s: &Vec<Option<DVec2>>| s[i].is_some()))
        .collect();
    if pixels.is_empty() {
        return Err(StageError::Config(format!("{}: the object covers no whole pixel", c.scene)));
    }
    // OpenCV camera frame (x right, y down, z forward) to the dataset's: flip y and z.
    let to_dataset = |v: DVec3| DVec3::new(v.x, -v.y, -v.z);
    // Truth: the normal averaged over each pixel's footprint (`render::truth` docs); pixels
    // whose footprint holds normals more than MAX_SPREAD_DEG from that mean (occlusion edges
    // of an object with itself, creases) are left out: no one normal is right for them.
    let xy: Vec<(u32, u32)> = pixels.iter().map(|&i| ((i % w) as u32, (i / w) as u32)).collect();
    let mean = render::truth::footprint_normals(&scene, &xy, 8);
    let object_pixels = pixels.len();
    let (pixels, normals): (Vec<usize>, Vec<DVec3>) = pixels
        .iter()
        .zip(&mean)
        .filter_map(|(&i, m)| m.filter(|m| m.1 <= MAX_SPREAD_DEG).map(|m| (i, to_dataset(m.0))))
        .unzip();
    if pixels.is_empty() {
        return Err(StageError::Config(format!("{}: no pixel sees one smooth piece of the object", c.scene)));
    }
    // A translucent object (a medium behind a null surface) has no surface albedo to compare
    // the solver's with.
    let surfaceless = scene.materials.iter().any(|m| matches!(m.bsdf, render::bsdf::Bsdf::Null));
    let albedo = (!surfaceless).then(|| {
        pixels.iter().map(|&i| std::array::from_fn(|ch| truth.albedo.data[3 * i + ch] as f64)).collect()
    });

    // Towards the camera from each pixel's surface point: the reversed ray through the pixel
    // centre (OpenCV pixel coordinates), from the scene's camera model, as a calibrated setup
    // would give it (the camera is an input of photometric stereo, not what it estimates).
    let views: Vec<DVec3> = pixels
        .iter()
        .map(|&i| {
            let px = glam::DVec2::new((i % w) as f64, (i / w) as f64);
            let ray = scene.camera.pixel_ray(px).map_or(DVec3::Z, |r| r.normalize());
            to_dataset(-ray)
        })
        .collect();
    // The renders are photographs through the true camera.
    scene.camera = true_camera;
    let dirs = light_directions(c.lights, c.elevation_deg);
    let rot = scene.t_world_cam.rotation;
    let bar = render::progress_bar(c.lights as u64, &format!("{} lights", ctx.case), ctx.progress);
    let mut obs = Observations::new(pixels.len(), c.lights);
    let mut kept_images = Vec::new();
    for (j, d) in dirs.iter().enumerate() {
        let to_light = (rot * to_dataset(*d)).as_vec3();
        scene.replace_lights(&[Light::Directional {
            to_light: Vec3A::from(to_light),
            irradiance: Vec3A::splat(c.irradiance as f32),
        }]);
        settings.seed = render::sampler::mix64(ctx.seed ^ (j as u64 + 1));
        let recipe = LightRecipe {
            product: "photometric-film",
            scene: &digest,
            diffuse_only: c.diffuse_only,
            shininess: c.shininess,
            albedo_scale: c.albedo_scale,
            to_light: to_light.to_array(),
            irradiance: c.irradiance,
            settings: SettingsKey::denoised(&settings, &c.denoise),
        };
        let film = ctx.cache.images(ctx.case, &format!("light {j}"), &recipe, || {
            Ok::<_, StageError>(vec![super::truth_render(&scene, &settings, &c.denoise)?])
        })?;
        let Some(film) = film else { continue };
        let Some(img) = film.first().filter(|f: &&Image| f.data.len() == 3 * w * h) else {
            return Err(StageError::Config(format!("light {j}: the cached render has the wrong size")));
        };
        for (p, &i) in pixels.iter().enumerate() {
            let v = match sources.as_ref().and_then(|s| s[i]) {
                Some(s) => img.bilinear(s),
                None => [img.data[3 * i], img.data[3 * i + 1], img.data[3 * i + 2], 0.0],
            };
            // Linear radiance without a sensor: nothing is clipped, whatever its size.
            obs.set_linear(p, j, [v[0], v[1], v[2]], [c.irradiance; 3]);
        }
        if c.save_dataset {
            let kept = match &undistort {
                Some((camera, new)) => crate::calib::undistort::undistort_image(img, camera, new),
                None => img.clone(),
            };
            kept_images.push((format!("{:03}.exr", j + 1), kept));
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    if ctx.renders_only() {
        return Ok(None);
    }
    let mut notes = vec![format!(
        "{} lights at {e0}°–{e1}° elevation, {} object pixels in the mask ({} more left out: their \
         footprint straddles an occlusion edge or crease), {}x{} px, {} spp, model {}.",
        c.lights,
        pixels.len(),
        object_pixels - pixels.len(),
        w,
        h,
        settings.spp,
        model.name()
    )];
    notes.extend(super::denoise_note(&c.denoise, settings.spp));
    let input = photometric::Input {
        width: w,
        height: h,
        lights: dirs,
        intensities: vec![[c.irradiance; 3]; c.lights],
        pixels,
        obs,
        views: Some(views),
    };
    let mut files = Vec::new();
    if c.save_dataset {
        let folder = std::path::PathBuf::from(crate::pipeline::names::file_stem(ctx.case));
        let (images, bytes) = photometric::dataset::layout(&input, kept_images, Some(&normals));
        files.extend(images.into_iter().map(|(n, img)| (folder.join(n), Kept::Image(img))));
        files.extend(bytes.into_iter().map(|(n, b)| (folder.join(n), Kept::Bytes(b))));
    }
    let pixels = input.pixels.clone();
    Ok(Some((input, Truth { pixels, normals, albedo }, Findings { notes, files, ..Default::default() })))
}

/// Reads a real dataset (`DataConfig`), keeping its ground truth apart from the input.
pub fn read(c: &DataConfig, ctx: &Context) -> Result<(photometric::Input, Truth, Findings), StageError> {
    let model: Model = c.model.parse()?;
    check_start_iterations(c.start_iterations)?;
    let dir = super::dataset_path(ctx, &c.dataset)?;
    let data = photometric::dataset::read(&dir)?;
    let Some(normals) = data.truth else {
        return Err(StageError::Config(format!(
            "dataset = \"{}\": {} has no Normal_gt.mat to validate against",
            c.dataset,
            dir.display()
        )));
    };
    let input = data.input;
    let notes = vec![format!(
        "Real data: {} ({} lights, {} mask pixels of {}x{}), model {}; the truth is the dataset's Normal_gt.mat.",
        dir.display(),
        input.lights.len(),
        input.pixels.len(),
        input.width,
        input.height,
        model.name()
    )];
    let pixels = input.pixels.clone();
    Ok((input, Truth { pixels, normals, albedo: None }, Findings { notes, ..Default::default() }))
}

pub fn solve(c: &Config, input: &photometric::Input) -> Result<Output, StageError> {
    solve_model(&c.model, c.start_iterations, input)
}

pub fn solve_data(c: &DataConfig, input: &photometric::Input) -> Result<Output, StageError> {
    solve_model(&c.model, c.start_iterations, input)
}

fn solve_model(model: &str, start_iterations: u64, input: &photometric::Input) -> Result<Output, StageError> {
    let model: Model = model.parse()?;
    let config = photometric::Config { model, trace: model == Model::BlinnPhong, start_iterations };
    let main = photometric::run(input, &config)?;
    // The Lambertian baseline on the same images, for the improvement the glossy model buys.
    let baseline = (model == Model::BlinnPhong)
        .then(|| photometric::run(input, &photometric::Config::new(Model::Robust)))
        .transpose()?;
    Ok(Output { main, baseline })
}

pub fn validate(out: &Output, truth: &Truth) -> Findings {
    let mut f = Findings::default();
    let sm = &out.main.summary;
    let acc = photometric::accuracy(&out.main, &truth.normals);
    // Per solved pixel its normal and the truth's, for a chained case's prediction.
    let items = truth
        .pixels
        .iter()
        .zip(&out.main.normals)
        .zip(&truth.normals)
        .filter_map(|((&i, n), t)| n.map(|n| (i as u64, vec![n.x, n.y, n.z, t.x, t.y, t.z])))
        .collect();
    f.linear = Some(super::chain::Linear { items, headline: mean_angular_error_deg });
    let none = "no solved pixel";
    let m = &mut f.metrics;
    m.push(Metric::maybe(
        "mean_angular_error_deg",
        acc.as_ref().map(|a| a.mean_angular_error_deg),
        "°",
        Better::Lower,
        none,
    ));
    m.push(Metric::maybe(
        "median_angular_error_deg",
        acc.as_ref().map(|a| a.median_angular_error_deg),
        "°",
        Better::Lower,
        none,
    ));
    m.push(Metric::new("masked_pixels", sm.masked_pixels as f64, "pixels", Better::Lower));
    // The share refused: an error over the solved pixels alone could fall by refusing more.
    let mask = sm.pixels + sm.masked_pixels;
    m.push(Metric::maybe(
        "masked_share",
        (mask > 0).then(|| sm.masked_pixels as f64 / mask as f64),
        "",
        Better::Lower,
        "the mask is empty",
    ));
    // Albedo: the solvers' ρ is kd/π in the renderer's terms (observations are radiance over
    // irradiance), so π·ρ is compared with the truth albedo, relative, per channel.
    if let Some(albedo) = &truth.albedo {
        let mut rel = Vec::new();
        for (k, kd) in albedo.iter().enumerate() {
            if out.main.normals[k].is_some() {
                for ch in 0..3 {
                    if kd[ch] > 0.0 {
                        rel.push((std::f64::consts::PI * out.main.albedo[k][ch] - kd[ch]).abs() / kd[ch]);
                    }
                }
            }
        }
        let albedo_err = (!rel.is_empty()).then(|| rel.iter().sum::<f64>() / rel.len() as f64);
        m.push(Metric::maybe("mean_albedo_rel_err", albedo_err, "", Better::Lower, none));
    }
    m.push(Metric::new("light_condition_number", sm.light_condition_number, "", Better::Lower));
    if sm.lights_nearly_coplanar {
        f.notes.push(format!(
            "warning: the light matrix has condition number {:.3} (above 5): the lights nearly lie in a plane, and the normals' component across it is poorly determined.",
            sm.light_condition_number
        ));
    }
    m.push(Metric::new("pixel_lights_per_s", sm.pixel_lights_per_s, "1/s", Better::Higher));
    m.push(Metric::new("time_per_megapixel_s", sm.time_per_megapixel_s, "s", Better::Lower));
    if let Some(base) = &out.baseline {
        let base = photometric::accuracy(base, &truth.normals).map(|a| a.mean_angular_error_deg);
        let ours = acc.as_ref().map(|a| a.mean_angular_error_deg);
        m.push(Metric::maybe("robust_lambertian_mean_angular_error_deg", base, "°", Better::Lower, none));
        let ratio = base.zip(ours).map(|(b, o)| b / o.max(1e-12));
        m.push(Metric::maybe("improvement_over_lambertian", ratio, "×", Better::Higher, none));
        m.push(Metric::new(
            "pixels_without_specular",
            sm.pixels_without_specular.unwrap_or(0) as f64,
            "pixels",
            Better::Lower,
        ));
        if let Some(curve) = acc.as_ref().and_then(|a| a.mean_angular_error_by_iteration_deg.as_ref()) {
            let shown: Vec<String> = curve
                .iter()
                .enumerate()
                .filter(|&(k, _)| k <= 8 || k.is_power_of_two() || k + 1 == curve.len())
                .map(|(k, e)| format!("{k}: {e:.4}°"))
                .collect();
            f.notes.push(format!("Mean angular error after k iterations: {}.", shown.join(", ")));
        }
    }
    f
}

/// `mean_angular_error_deg` from pixels' normals and truth normals (`chain::Linear`), as
/// `photometric::accuracy` takes it.
fn mean_angular_error_deg(items: &mut dyn Iterator<Item = &[f64]>) -> Option<f64> {
    let (normals, truth): (Vec<Option<DVec3>>, Vec<DVec3>) = items
        .filter(|v| v.len() == 6)
        .map(|v| (DVec3::new(v[0], v[1], v[2]).try_normalize(), DVec3::new(v[3], v[4], v[5])))
        .unzip();
    let errors = photometric::angular_errors(&normals, &truth);
    (!errors.is_empty()).then(|| errors.iter().sum::<f64>() / errors.len() as f64)
}

impl Settings for Config {
    fn headline(&self) -> &'static str {
        "mean_angular_error_deg"
    }
    fn run(&self, ctx: &Context) -> Result<CaseResult, StageError> {
        let chain = super::chain::Chain {
            headline: "mean_angular_error_deg",
            unit: "°",
            errors: &[
                "mean_angular_error_deg",
                "median_angular_error_deg",
                "mean_albedo_rel_err",
                "masked_share",
            ],
        };
        super::chain::run_on_camera(&self.camera, self.perturb, ctx, &chain, |given| {
            run_case(|| synthesize_given(self, ctx, given), |i| solve(self, i), validate)
        })
    }
    fn share(&self, ctx: &Context, pass: Pass) -> Option<Result<(), StageError>> {
        (pass == Pass::Renders).then(|| synthesize(self, ctx).map(|_| ()))
    }
    fn upstream(&self) -> Vec<(&'static str, String, &'static str)> {
        super::chain::camera_upstream(&self.camera)
    }
}

impl Settings for DataConfig {
    fn headline(&self) -> &'static str {
        "mean_angular_error_deg"
    }
    fn run(&self, ctx: &Context) -> Result<CaseResult, StageError> {
        run_case(|| read(self, ctx).map(Some), |i| solve_data(self, i), validate)
    }
}
