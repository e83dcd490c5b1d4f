//! Scene files (TOML) and the scene the integrator traces.
//!
//! A scene file holds a `[camera]`, optional `[render]` defaults and `[sensor]`, a list of
//! `[[materials]]`, `[[shapes]]` and `[[lights]]`. Paths inside it are relative to the file.
//! Units are the scene's own length unit; radiance in W·sr⁻¹·m⁻² (linear RGB), point-light
//! intensity in W·sr⁻¹ (or power in W), directional-light irradiance in W·m⁻².
//! See `pipelines/scenes/*.toml` for examples of every field.
//!
//! `file` is the schema, `build` checks it and builds the scene; this module holds the built
//! scene, its lights and the queries the integrator makes of it.

mod aim;
mod build;
mod emission;
pub mod file;
pub mod mitsuba;
mod query;

pub use query::{epsilon, Surface};

pub use aim::Aim;
pub use build::{build, MAX_SCENE_VALUE};
pub use emission::Emission;
pub use file::*;

use super::bvh::Bvh;
use super::geometry::{Prim, PrimInfo};
use super::texture::Texture;
use super::{bsdf::Bsdf, Error};
use crate::math::{CameraModel, CameraToWorld};
use glam::{DVec2, DVec3, Vec3A};
use std::path::Path;

/// A thin lens in the camera's optical frame: lens points on the disk of `aperture_radius`
/// at z = 0, rays through the pixel's point on the plane z = `focus_distance`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThinLens {
    pub aperture_radius: f64,
    pub focus_distance: f64,
}

// ---------------------------------------------------------------------------------------------
// The built scene
// ---------------------------------------------------------------------------------------------

pub struct Material {
    pub name: String,
    /// The diffuse colour kd.
    pub albedo: Texture,
    pub emission: Option<Vec3A>,
    pub bsdf: Bsdf,
    /// A textured conductor roughness α (in the x channel), replacing the model's per hit.
    pub roughness: Option<Texture>,
    /// Black from the side its normal points away from, as Mitsuba's BSDFs without
    /// `twosided` are; lumen's surfaces are two-sided otherwise.
    pub one_sided: bool,
}

#[derive(Clone, Copy, Debug)]
pub enum Light {
    Point {
        position: Vec3A,
        intensity: Vec3A,
    },
    Directional {
        to_light: Vec3A,
        irradiance: Vec3A,
    },
    /// Constant radiance from every direction, or (with the scene's `environment_map`) the
    /// map's radiance times `radiance`; `mean` is the mean radiance over the sphere.
    Environment {
        radiance: Vec3A,
        mean: Vec3A,
    },
    /// Angles in radians; `axis` is the unit direction the spot points along.
    Spot {
        position: Vec3A,
        axis: Vec3A,
        intensity: Vec3A,
        cutoff: f32,
        beam: f32,
    },
    /// An emissive primitive (index into the BVH's leaf-ordered primitives).
    Area {
        prim: u32,
        radiance: Vec3A,
        area: f32,
    },
}

pub struct Scene {
    pub camera: CameraModel,
    pub t_world_cam: CameraToWorld,
    /// Depth of field; `None` for a pinhole (truth images always come from the pinhole).
    pub lens: Option<ThinLens>,
    pub render: RenderSpec,
    pub sensor: Option<super::sensor::Sensor>,
    pub materials: Vec<Material>,
    pub bvh: Bvh,
    /// Per primitive, in the BVH's leaf order.
    pub info: Vec<PrimInfo>,
    pub lights: Vec<Light>,
    /// Cumulative light-selection probabilities, proportional to power, with a leading 0
    /// (`lights.len() + 1` entries).
    pub light_cdf: Vec<f32>,
    /// Per primitive (BVH order), the index of its area light in `lights`, or `u32::MAX`.
    pub light_of_prim: Vec<u32>,
    /// The environment light's index in `lights`, if any (looked up on every escaping ray).
    pub environment_light: Option<usize>,
    /// The environment light's image, when it has one.
    pub environment_map: Option<super::envmap::EnvMap>,
    /// Object names by id (index 0 is the background).
    pub object_names: Vec<String>,
    /// The participating media (`render::media`), by index.
    pub media: Vec<super::media::Medium>,
    /// Per primitive (BVH order), the media inside and outside it (`None`: vacuum) where its
    /// shape bounds media, `None` where it does not; empty when no shape does.
    pub boundaries: Vec<Option<[Option<u32>; 2]>>,
    /// The medium the camera sits in.
    pub camera_medium: Option<u32>,
    /// Centre and radius of a sphere bounding the geometry.
    pub bounds_center: Vec3A,
    pub bounds_radius: f32,
}

/// Reads a scene file: lumen's TOML, or Mitsuba 3's XML (by the extension `.xml`).
pub fn load(path: &Path) -> Result<Scene, Error> {
    if mitsuba::is_mitsuba(path) {
        return load_mitsuba(path, &[]);
    }
    let text = std::fs::read_to_string(path)
        .map_err(|e| Error::Io { path: path.to_path_buf(), message: e.to_string() })?;
    let file: SceneFile = toml::from_str(&text)
        .map_err(|e| Error::Parse { path: path.to_path_buf(), message: e.to_string() })?;
    build(&file, path)
}

/// Reads a camera file: a scene file's `[camera]` table on its own, as TOML or (by the
/// extension `.json`) JSON, or a whole TOML scene file (its camera), checked as a scene's
/// camera is. `lumen render --aov depth` writes
/// one beside the render (`NAME.camera.json`, `camera_spec`). A thin lens is refused: what
/// reads camera files (`lumen warp`) models pinhole views.
pub fn load_camera(path: &Path) -> Result<(CameraModel, CameraToWorld), Error> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| Error::Io { path: path.to_path_buf(), message: e.to_string() })?;
    let is_json = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("json"));
    let spec: CameraSpec = if is_json {
        serde_json::from_str(&text)
            .map_err(|e| Error::Parse { path: path.to_path_buf(), message: e.to_string() })?
    } else {
        let parse = |e: toml::de::Error| Error::Parse { path: path.to_path_buf(), message: e.to_string() };
        let table: toml::Table = toml::from_str(&text).map_err(parse)?;
        match table.get("camera") {
            // A whole scene file: its camera.
            Some(toml::Value::Table(camera)) if !table.contains_key("width") => {
                camera.clone().try_into().map_err(parse)?
            }
            _ => table.try_into().map_err(parse)?,
        }
    };
    if spec.aperture_radius.is_some_and(|r| r != 0.0) {
        return Err(Error::Invalid {
            path: path.to_path_buf(),
            field: "aperture_radius".into(),
            message: "a thin lens: expected a pinhole camera (no aperture_radius)".into(),
        });
    }
    build::build_camera(&spec, path)
}

/// The camera file (`load_camera`) of a camera and its pose: intrinsics, distortion, and the
/// pose as a rotation (rows) and translation.
pub fn camera_spec(camera: &CameraModel, pose: &CameraToWorld) -> CameraSpec {
    let i = camera.intrinsics;
    let r = pose.rotation.transpose().to_cols_array_2d();
    CameraSpec {
        width: camera.width,
        height: camera.height,
        fov_deg: None,
        fx: Some(i.fx),
        fy: Some(i.fy),
        cx: Some(i.cx),
        cy: Some(i.cy),
        distortion: (!camera.distortion.is_zero()).then(|| camera.distortion.to_array()),
        look_at: None,
        t_world_cam: Some(TransformSpec {
            rotation: Some(r),
            translation: pose.translation.to_array(),
            ..TransformSpec::default()
        }),
        aperture_radius: None,
        focus_distance: None,
        medium: None,
    }
}

/// Reads and builds a Mitsuba 3 scene; `params` are its `$name` values (`-D name=value`).
pub fn load_mitsuba(path: &Path, params: &[(String, String)]) -> Result<Scene, Error> {
    let read = mitsuba::read(path, params)?;
    let scene = build(&read.scene, path)?;
    // lumen's camera rays do not clip: accept clip planes that would cut nothing.
    let (near, far) = read.clip;
    let eye = scene.t_world_cam.translation.as_vec3();
    for prim in &scene.bvh.prims {
        let (lo, hi) = prim.bounds();
        let (lo, hi) = (glam::Vec3::from(lo), glam::Vec3::from(hi));
        let nearest = eye.clamp(lo, hi).distance(eye) as f64;
        let farthest = (eye - lo).abs().max((eye - hi).abs()).length() as f64;
        if nearest < near || farthest > far {
            return Err(Error::MitsubaUnsupported {
                at: format!("the sensor of {}", path.display()),
                message: format!(
                    "near_clip {near} / far_clip {far} would cut geometry between {nearest:.4} and {farthest:.4} from the camera, and lumen does not clip: widen them or leave them out"
                ),
            });
        }
    }
    Ok(scene)
}

pub(super) fn bounding_sphere(prims: &[Prim], camera: DVec3) -> (Vec3A, f32) {
    let mut lo = Vec3A::from(camera.as_vec3());
    let mut hi = lo;
    for p in prims {
        let (a, b) = p.bounds();
        lo = lo.min(a);
        hi = hi.max(b);
    }
    ((lo + hi) * 0.5, ((hi - lo) * 0.5).length().max(1e-3))
}

/// Light power used to choose among lights: mean over channels of Φ.
pub fn light_power(l: &Light, scene_radius: f32) -> f32 {
    let pi = std::f32::consts::PI;
    let mean = |v: Vec3A| (v.x + v.y + v.z) / 3.0;
    match *l {
        Light::Point { intensity, .. } => 4.0 * pi * mean(intensity),
        Light::Directional { irradiance, .. } => pi * scene_radius * scene_radius * mean(irradiance),
        Light::Area { radiance, area, .. } => pi * area * mean(radiance),
        Light::Spot { intensity, cutoff, beam, .. } => {
            spot_power_per_intensity(cutoff, beam) * mean(intensity)
        }
        // The flux into the bounding sphere: 4πR² · πL.
        Light::Environment { mean: m, .. } => 4.0 * pi * pi * scene_radius * scene_radius * mean(m),
    }
}

/// Spot light falloff at angle θ from its axis: 1 inside the beam, linear in θ to 0 at the
/// cutoff (Mitsuba's `spot`).
#[inline]
pub fn spot_falloff(theta: f32, cutoff: f32, beam: f32) -> f32 {
    if theta >= cutoff {
        0.0
    } else if theta <= beam {
        1.0
    } else {
        (cutoff - theta) / (cutoff - beam)
    }
}

/// Power of a spot light per unit on-axis intensity, 2π ∫ falloff(θ) sin θ dθ
/// = 2π [(1 − cos b) + cos b − (sin c − sin b)/(c − b)] for beam b < cutoff c (the second
/// part by parts over the linear transition).
pub fn spot_power_per_intensity(cutoff: f32, beam: f32) -> f32 {
    let (c, b) = (cutoff as f64, beam as f64);
    let transition = if c - b > 1e-9 { b.cos() - (c.sin() - b.sin()) / (c - b) } else { 0.0 };
    (2.0 * std::f64::consts::PI * ((1.0 - b.cos()) + transition)) as f32
}

impl Scene {
    /// Replaces the point, spot and directional lights (emissive shapes and the environment
    /// stay), as a stage
    /// that relights one scene does.
    pub fn replace_lights(&mut self, lights: &[Light]) {
        self.lights.retain(|l| matches!(l, Light::Area { .. } | Light::Environment { .. }));
        self.lights.extend(
            lights.iter().copied().filter(|l| !matches!(l, Light::Area { .. } | Light::Environment { .. })),
        );
        self.light_cdf = light_cdf(&self.lights, self.bounds_radius);
        self.light_of_prim = light_of_prim(&self.lights, self.bvh.prims.len());
        self.environment_light = self.lights.iter().position(|l| matches!(l, Light::Environment { .. }));
    }
}

pub(super) fn light_of_prim(lights: &[Light], prims: usize) -> Vec<u32> {
    let mut map = vec![u32::MAX; prims];
    for (i, l) in lights.iter().enumerate() {
        if let Light::Area { prim, .. } = l {
            map[*prim as usize] = i as u32;
        }
    }
    map
}

/// The cumulative pick probabilities with a leading 0: light i is picked for u in
/// [cdf[i], cdf[i + 1]). The leading 0 spares `pick_probability` a branch on i == 0, which
/// the processor would mispredict as often as the pick is random.
pub(super) fn light_cdf(lights: &[Light], scene_radius: f32) -> Vec<f32> {
    let powers: Vec<f64> = lights.iter().map(|l| light_power(l, scene_radius) as f64).collect();
    let total: f64 = powers.iter().sum();
    let mut acc = 0.0;
    std::iter::once(0.0)
        .chain(powers.iter().map(|p| {
            acc += if total > 0.0 { p / total } else { 1.0 / lights.len() as f64 };
            acc as f32
        }))
        .collect()
}

impl Scene {
    /// Picks a light in proportion to its power: (index, probability, `u` stretched over the
    /// light's share of [0, 1)). The stretched number is again uniform on [0, 1) and
    /// independent of the pick, so light sampling reuses it as its point's first coordinate:
    /// one stratified pair then covers pick and point together (the two triangles of a quad
    /// light are one stratified square), and no number is spent on the pick alone.
    #[inline]
    pub fn pick_light(&self, u: f32) -> Option<(usize, f32, f32)> {
        let n = self.lights.len();
        if n == 0 {
            return None;
        }
        let i = self.light_cdf[1..].partition_point(|&c| c <= u).min(n - 1);
        let p = self.pick_probability(i);
        if !(p > 0.0) {
            return None;
        }
        let reused = ((u - self.light_cdf[i]) / p).clamp(0.0, 1.0 - f32::EPSILON / 2.0);
        Some((i, p, reused))
    }

    /// The environment's radiance arriving along `-dir` (seen looking along `dir`) and the
    /// solid-angle density with which light sampling picks `dir` (the light's pick probability
    /// included), when the scene has an environment light.
    #[inline]
    pub fn environment(&self, dir: Vec3A) -> Option<(Vec3A, f32)> {
        let i = self.environment_light?;
        let Light::Environment { radiance, .. } = self.lights[i] else { return None };
        let p_pick = self.pick_probability(i);
        Some(match &self.environment_map {
            None => (radiance, p_pick / (4.0 * std::f32::consts::PI)),
            Some(map) => (radiance * map.eval(dir), p_pick * map.pdf(dir)),
        })
    }

    /// Probability that `pick_light` chooses light `i`.
    #[inline]
    pub fn pick_probability(&self, i: usize) -> f32 {
        self.light_cdf[i + 1] - self.light_cdf[i]
    }

    /// World-space ray origin and unit direction through OpenCV pixel coordinates `px`.
    pub fn camera_ray(&self, px: DVec2) -> Option<(DVec3, DVec3)> {
        let d = self.camera.pixel_ray(px)?;
        Some((self.t_world_cam.translation, self.t_world_cam.rotation * d))
    }
}
