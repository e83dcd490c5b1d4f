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
//! Metrics: `mean_angular_error_deg`, `median_angular_error_deg`, `masked_pixels` (mask
//! pixels left without a normal), `mean_albedo_rel_err` (|π·ρ − kd|/kd against the truth
//! albedo image, over channels and solved pixels), `light_condition_number`, `pixel_lights_per_s`,
//! `time_per_megapixel_s`; with `model = "blinn-phong"` also the robust Lambertian model's
//! error on the same images (`robust_lambertian_mean_angular_error_deg`), the ratio of the
//! two (`improvement_over_lambertian`, higher is better), `pixels_without_specular`, and a
//! note with the mean error after each Gauss-Newton iteration.

use super::report::{Better, Metric};
use super::{Common, RunOptions, StageOutput};
use crate::photometric::{self, dataset::Dataset, Model, Observations};
use crate::render::{self, scene::Light};
use glam::{DVec3, Vec3A};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhotometricStage {
    pub case: String,
    pub seed: Option<u64>,
    #[serde(default)]
    pub bounds: BTreeMap<String, f64>,
    #[serde(default)]
    pub expected_miss: BTreeMap<String, String>,
    /// Scene file with the object and camera, relative to the pipeline file; its own point and
    /// directional lights are replaced by the stage's.
    pub scene: String,
    /// Number of distant lights (default 24, at least 3).
    #[serde(default = "default_lights")]
    pub lights: usize,
    /// Lowest and highest light elevation in degrees above the plane facing the camera
    /// (default [25, 70]).
    #[serde(default = "default_elevation")]
    pub elevation_deg: [f64; 2],
    /// Irradiance of every light on a surface facing it (default 3).
    #[serde(default = "default_irradiance")]
    pub irradiance: f64,
    /// Samples per pixel (default: the scene's).
    pub spp: Option<u32>,
    /// Longest path (default: the scene's); 2 renders direct light only, without
    /// interreflections.
    pub max_depth: Option<u32>,
    /// `lambertian`, `robust` or `blinn-phong` (default robust).
    #[serde(default = "default_model")]
    pub model: String,
    /// Overrides the shininess (exponent) of every Blinn-Phong material in the scene.
    pub shininess: Option<f64>,
    /// Makes every material Lambertian, keeping its diffuse colour (default false).
    #[serde(default)]
    pub diffuse_only: bool,
}

/// Largest angle between a pixel's mean normal and any normal in its footprint for the
/// pixel to be in the truth mask (degrees).
const MAX_SPREAD_DEG: f64 = 10.0;

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

impl PhotometricStage {
    pub fn common(&self) -> Common {
        Common {
            case: self.case.clone(),
            seed: self.seed,
            bounds: self.bounds.clone(),
            expected_miss: self.expected_miss.clone(),
        }
    }
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

pub fn run(s: &PhotometricStage, dir: &Path, seed: u64, opts: &RunOptions) -> Result<StageOutput, String> {
    let model: Model = s.model.parse()?;
    if s.lights < 3 {
        return Err(format!("lights = {}: photometric stereo needs at least 3", s.lights));
    }
    let [e0, e1] = s.elevation_deg;
    if !(0.0..=90.0).contains(&e0) || !(0.0..=90.0).contains(&e1) {
        return Err(format!("elevation_deg = {:?}: expected angles in [0, 90]", s.elevation_deg));
    }
    if !(s.irradiance.is_finite() && s.irradiance > 0.0) {
        return Err(format!("irradiance = {}: expected a positive number", s.irradiance));
    }
    let mut scene = render::load(&dir.join(&s.scene)).map_err(|e| e.to_string())?;
    if s.diffuse_only {
        for m in &mut scene.materials {
            m.bsdf = render::bsdf::Bsdf::Lambertian;
        }
    }
    if let Some(e) = s.shininess {
        if !(e.is_finite() && e > 0.0) {
            return Err(format!("shininess = {e}: expected a positive number"));
        }
        for m in &mut scene.materials {
            if let render::bsdf::Bsdf::BlinnPhong { exponent, .. } = &mut m.bsdf {
                *exponent = e as f32;
            }
        }
    }
    let mut settings = render::Settings::from_scene(&scene);
    settings.threads = opts.threads;
    if let Some(n) = s.spp {
        settings.spp = n.max(1);
    }
    if let Some(d) = s.max_depth {
        if d < 2 {
            return Err(format!("max_depth = {d}: the object is lit only from depth 2 on"));
        }
        settings.max_depth = d;
    }
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);

    // Truth and mask.
    let truth = render::truth(&scene, None);
    let object = |x: usize, y: usize| truth.id.data[y * w + x] > 0.0;
    let pixels: Vec<usize> = (1..h.saturating_sub(1))
        .flat_map(|y| (1..w.saturating_sub(1)).map(move |x| (x, y)))
        .filter(|&(x, y)| (0..3).all(|dy| (0..3).all(|dx| object(x + dx - 1, y + dy - 1))))
        .map(|(x, y)| y * w + x)
        .collect();
    if pixels.is_empty() {
        return Err(format!("{}: the object covers no whole pixel", s.scene));
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
        return Err(format!("{}: no pixel sees one smooth piece of the object", s.scene));
    }

    // Towards the camera from each pixel's surface point: the reversed ray through the pixel
    // centre (OpenCV pixel coordinates), from the calibrated camera, not from truth.
    let views: Vec<DVec3> = pixels
        .iter()
        .map(|&i| {
            let px = glam::DVec2::new((i % w) as f64, (i / w) as f64);
            let ray = scene.camera.pixel_ray(px).map_or(DVec3::Z, |r| r.normalize());
            to_dataset(-ray)
        })
        .collect();
    let dirs = light_directions(s.lights, s.elevation_deg);
    let rot = scene.t_world_cam.rotation;
    let t0 = std::time::Instant::now();
    let bar = render::progress_bar(s.lights as u64, "lights", opts.progress);
    let mut obs = Observations::new(pixels.len(), s.lights);
    for (j, d) in dirs.iter().enumerate() {
        let to_light = (rot * to_dataset(*d)).as_vec3();
        scene.replace_lights(&[Light::Directional {
            to_light: Vec3A::from(to_light),
            irradiance: Vec3A::splat(s.irradiance as f32),
        }]);
        settings.seed = render::sampler::mix64(seed ^ (j as u64 + 1));
        let film = render::render(&scene, &settings);
        for (p, &i) in pixels.iter().enumerate() {
            let v = &film.mean.data[3 * i..3 * i + 3];
            obs.set_raw(p, j, [v[0], v[1], v[2]], [s.irradiance; 3]);
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let render_s = t0.elapsed().as_secs_f64();

    let data = Dataset {
        width: w,
        height: h,
        lights: dirs,
        intensities: vec![[s.irradiance; 3]; s.lights],
        pixels,
        obs,
        truth: Some(normals),
        views: Some(views),
    };
    let out = photometric::run(&data, model);
    let sm = &out.summary;
    let mut m = Vec::new();
    m.push(Metric::new(
        "mean_angular_error_deg",
        sm.mean_angular_error_deg.unwrap_or(f64::INFINITY),
        "°",
        Better::Lower,
    ));
    m.push(Metric::new(
        "median_angular_error_deg",
        sm.median_angular_error_deg.unwrap_or(f64::INFINITY),
        "°",
        Better::Lower,
    ));
    m.push(Metric::new("masked_pixels", sm.masked_pixels as f64, "pixels", Better::Lower));
    // Albedo: the solvers' ρ is kd/π in the renderer's terms (observations are radiance over
    // irradiance), so π·ρ is compared with the truth albedo image, relative, per channel.
    let mut rel = Vec::new();
    for (k, &i) in data.pixels.iter().enumerate() {
        if out.normals[k].is_some() {
            for c in 0..3 {
                let kd = truth.albedo.data[3 * i + c] as f64;
                if kd > 0.0 {
                    rel.push((std::f64::consts::PI * out.albedo[k][c] - kd).abs() / kd);
                }
            }
        }
    }
    let albedo_err = if rel.is_empty() { f64::INFINITY } else { rel.iter().sum::<f64>() / rel.len() as f64 };
    m.push(Metric::new("mean_albedo_rel_err", albedo_err, "", Better::Lower));
    m.push(Metric::new("light_condition_number", sm.light_condition_number, "", Better::Lower));
    m.push(Metric::new("pixel_lights_per_s", sm.pixel_lights_per_s, "1/s", Better::Higher));
    m.push(Metric::new("time_per_megapixel_s", sm.time_per_megapixel_s, "s", Better::Lower));
    let mut notes = Vec::new();
    if model == Model::BlinnPhong {
        // The Lambertian baseline on the same images, for the improvement the glossy model buys.
        let base = photometric::run(&data, Model::Robust).summary.mean_angular_error_deg.unwrap_or(f64::NAN);
        let ours = sm.mean_angular_error_deg.unwrap_or(f64::INFINITY);
        m.push(Metric::new("robust_lambertian_mean_angular_error_deg", base, "°", Better::Lower));
        m.push(Metric::new("improvement_over_lambertian", base / ours.max(1e-12), "×", Better::Higher));
        m.push(Metric::new(
            "pixels_without_specular",
            sm.pixels_without_specular.unwrap_or(0) as f64,
            "pixels",
            Better::Lower,
        ));
        if let Some(curve) = &sm.mean_angular_error_by_iteration_deg {
            let shown: Vec<String> = curve
                .iter()
                .enumerate()
                .filter(|&(k, _)| k <= 8 || k.is_power_of_two() || k + 1 == curve.len())
                .map(|(k, e)| format!("{k}: {e:.4}°"))
                .collect();
            notes.push(format!("Mean angular error after k Gauss-Newton iterations: {}.", shown.join(", ")));
        }
    }
    notes.insert(
        0,
        format!(
            "{} lights at {e0}°–{e1}° elevation, {} object pixels in the mask ({} more left out: their \
             footprint straddles an occlusion edge or crease), {}x{} px, {} spp, model {}.",
            s.lights,
            data.pixels.len(),
            object_pixels - data.pixels.len(),
            w,
            h,
            settings.spp,
            s.model
        ),
    );
    let mut timings_s = BTreeMap::new();
    timings_s.insert("render".into(), render_s);
    timings_s.insert("solve".into(), sm.time_s);
    timings_s.insert("total".into(), render_s + sm.time_s);
    Ok(StageOutput { metrics: m, timings_s, notes })
}
