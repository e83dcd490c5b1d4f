//! Feature buffers for denoising: the albedo, normal and depth at each camera sample's first
//! hit, averaged over the pixel's samples like the colour, with the variance of that mean.
//!
//! Unlike `truth` (one ray through the pixel centre), these see what the render's samples
//! see: the same camera rays (`integrators::camera_path`, so the pixel filter, distortion and
//! thin lens), so an edge, a defocused foreground or a texture is as blurred in the features
//! as in the colour, and the variance says where a pixel straddles two surfaces. A ray that
//! misses gives 0 in every feature.
//!
//! Through smooth glass, mirrors and null surfaces the albedo and normal are those of the
//! first surface that is not a delta one, found along each delta surface's more likely lobe
//! (refraction unless Fresnel reflection exceeds one half), the albedo tinted by the colours
//! passed: what the camera sees through a glass sphere is the room behind it, and features of
//! the sphere's smooth surface would tell the filter nothing about where that image has edges.
//! The depth stays the first hit's, the distance along the line of sight.
//!
//! | buffer  | channels | value at the first hit                                   |
//! |---------|----------|----------------------------------------------------------|
//! | albedo  | R G B    | the material's albedo (its reflectance colour)           |
//! | normal  | R G B    | world-frame geometric normal, turned towards the camera  |
//! | depth   | Y        | camera-frame z (scene units)                              |

use super::film::pixel_stats;
use super::geometry::Ray;
use super::integrators::{camera_path, Settings};
use super::scene::Scene;
use super::transport::{self, epsilon};
use crate::image::Image;
use glam::{DVec3, Vec3A};
use rayon::prelude::*;

/// A feature's mean and the variance of that mean, per pixel.
pub struct Buffer {
    pub mean: Image,
    pub variance: Image,
}

pub struct Features {
    pub albedo: Buffer,
    pub normal: Buffer,
    pub depth: Buffer,
}

impl Features {
    /// The buffers with their names (the file suffixes `lumen render --denoise` writes).
    pub fn named(&self) -> [(&'static str, &Buffer); 3] {
        [("albedo", &self.albedo), ("normal", &self.normal), ("depth", &self.depth)]
    }
}

/// The feature buffers over the settings' crop, from the settings' `spp` camera samples per
/// pixel (the render's own, sample for sample).
pub fn features(scene: &Scene, settings: &Settings) -> Features {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let [x0, y0, x1, y1] = settings.crop.unwrap_or([0, 0, w, h]);
    let (fw, fh) = (x1.saturating_sub(x0), y1.saturating_sub(y0));
    let cam_from_world = scene.t_world_cam.inverse();
    let rows: Vec<Vec<[([f32; 3], [f32; 3]); 3]>> = (y0..y1)
        .into_par_iter()
        .map(|y| {
            (x0..x1)
                .map(|x| {
                    let mut samples = Vec::with_capacity(settings.spp as usize);
                    for k in 0..settings.spp {
                        samples.push(first_hit(scene, settings, &cam_from_world, x, y, k));
                    }
                    let stats = |i: usize| {
                        let (m, v, _) = pixel_stats(samples.iter().map(|s| s[i]));
                        (m, v)
                    };
                    [stats(0), stats(1), stats(2)]
                })
                .collect()
        })
        .collect();
    let buffer = |i: usize, channels: u32| {
        let mut mean = Image::new(fw, fh, channels);
        let mut variance = Image::new(fw, fh, channels);
        for (j, row) in rows.iter().enumerate() {
            for (k, px) in row.iter().enumerate() {
                let c = channels as usize;
                mean.pixel_mut(k as u32, j as u32).copy_from_slice(&px[i].0[..c]);
                variance.pixel_mut(k as u32, j as u32).copy_from_slice(&px[i].1[..c]);
            }
        }
        Buffer { mean, variance }
    };
    Features { albedo: buffer(0, 3), normal: buffer(1, 3), depth: buffer(2, 1) }
}

/// Albedo, normal and depth (in x) at sample `k`'s first hit.
fn first_hit(
    scene: &Scene,
    settings: &Settings,
    cam_from_world: &crate::math::pose::WorldToCamera,
    x: u32,
    y: u32,
    k: u32,
) -> [Vec3A; 3] {
    let (_, ray) = camera_path(scene, settings, x, y, k);
    let Some(ray) = ray else {
        return [Vec3A::ZERO; 3];
    };
    let Some(hit) = scene.bvh.intersect(&ray, 0.0, f32::INFINITY) else {
        return [Vec3A::ZERO; 3];
    };
    let s = scene.surface(&ray, &hit);
    let p = DVec3::from(s.p.to_array().map(f64::from));
    let z = cam_from_world.transform_point(p).z as f32;
    let (mut ray, mut hit, mut s) = (ray, hit, s);
    let mut tint = Vec3A::ONE;
    for _ in 0..MAX_DELTA_BOUNCES {
        let mat = &scene.materials[s.material as usize];
        let wo = -ray.dir;
        let front = s.n.dot(wo) >= 0.0;
        if !mat.bsdf.is_delta() || mat.roughness.is_some() || mat.emission.is_some() {
            break;
        }
        let n = if front { s.n } else { -s.n };
        let albedo = scene.albedo(s.material, &hit, s.p);
        let Some(next) = mat.bsdf.facing(front).sample(albedo, n, wo, 0.5, 0.5, 0.5) else {
            break;
        };
        let origin = transport::offset(s.p, n, next.wi, epsilon(s.p));
        let next_ray = Ray { origin, dir: next.wi };
        let Some(next_hit) = scene.bvh.intersect(&next_ray, 0.0, f32::INFINITY) else {
            // Out to the environment: no surface to describe.
            return [Vec3A::ZERO, Vec3A::ZERO, Vec3A::new(z, 0.0, 0.0)];
        };
        tint *= albedo;
        s = scene.surface(&next_ray, &next_hit);
        (ray, hit) = (next_ray, next_hit);
    }
    let n = if s.n.dot(ray.dir) > 0.0 { -s.n } else { s.n };
    [tint * scene.albedo(s.material, &hit, s.p), n, Vec3A::new(z, 0.0, 0.0)]
}

/// Delta surfaces followed before the features stop at whatever surface is reached.
const MAX_DELTA_BOUNCES: usize = 8;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::bsdf::Bsdf;

    /// Through the glass sphere of the Cornell box the albedo and normal are the room's, not
    /// the sphere's; the depth stays the first hit's. The same scene with the glass made
    /// Lambertian (same colour) gives the sphere's own: they must differ on the sphere's
    /// pixels, and only there.
    #[test]
    fn features_see_through_smooth_glass() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("pipelines/scenes/cornell-glass.toml");
        let glass = crate::render::load(&path).unwrap();
        let mut opaque = crate::render::load(&path).unwrap();
        for m in &mut opaque.materials {
            if m.bsdf.is_delta() {
                m.bsdf = Bsdf::Lambertian;
            }
        }
        let settings = Settings { spp: 1, crop: None, ..Settings::from_scene(&glass) };
        let (a, b) = (features(&glass, &settings), features(&opaque, &settings));
        assert_eq!(a.depth.mean, b.depth.mean);
        let pixels = a.normal.mean.data.len() / 3;
        let differ = (0..pixels)
            .filter(|&i| {
                (0..3).any(|c| (a.normal.mean.data[3 * i + c] - b.normal.mean.data[3 * i + c]).abs() > 1e-3)
            })
            .count();
        // The sphere covers a few per cent of the image.
        assert!(differ > pixels / 100 && differ < pixels / 4, "{differ} of {pixels} pixels");
    }
}
