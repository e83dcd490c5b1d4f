//! Eight paths at once: `path::trace` for scenes of Lambertian surfaces lit by triangle area
//! lights, point lights and directional lights (the Cornell box, the calibration and
//! photometric scenes), with the shading between hits done for eight paths in the lanes of
//! AVX2 registers.
//!
//! Rays are still traced one at a time (the BVH's 8-wide tests already use the lanes for one
//! ray), and so are a hit's surface look-ups and a new path's camera ray. What the lanes take
//! over is the rest of a vertex: the light pick (a branch-free binary search over the power
//! CDF), the light sample, the shadow ray's set-up, the Lambertian contribution, the
//! cosine-weighted bounce, the throughput, Russian roulette, and the random numbers themselves
//! (`render::lanes::samplers`). A lane whose path ends takes the next (pixel, sample) of its
//! group of pixels at once, so the lanes stay full while paths of different lengths run side
//! by side.
//!
//! The vertex's arithmetic is `render::transport`'s, the same functions the one-path loop and
//! the scene's light sampling call on `f32`: a change to light transport is made there once.
//! Each lane draws the same numbers from its own (pixel, sample) stream, and the film sums each
//! pixel's samples in sample order, so the image is bit-identical to the one-path loop's
//! (tested on both samplers, a thin lens, spheres, textures and every light kind taken). What
//! is this file's own is the control: which lanes shade, which light kind each keeps, when a
//! path ends. Scenes with anything else (glossy or delta materials, textured roughness, spot,
//! sphere or environment lights) and processors without AVX2 take the one-path loop.
//!
//! `trace` is the path loop; this module decides which scenes take the lanes and lays out
//! their lights.

use crate::render::bsdf::Bsdf;
use crate::render::camera_ray::{camera_direction, camera_ray, needs_lens_sample};
use crate::render::film::{pixel_stats, RR_START};
use crate::render::geometry::{Prim, Ray};
use crate::render::integrators::Settings;
use crate::render::sampler::Sampler;
use crate::render::scene::{Light, Scene};
use glam::Vec3A;

/// Whether `render` may draw this scene eight paths at a time.
pub fn supported(scene: &Scene, settings: &Settings) -> bool {
    crate::render::lanes::available()
        && settings.max_depth >= 1
        // The light pick gathers from the light table: a scene without a light (or whose
        // emitters are all black) takes the one-path loop, which renders it black.
        && !scene.lights.is_empty()
        && scene.environment_light.is_none()
        && scene.materials.iter().all(|m| matches!(m.bsdf, Bsdf::Lambertian) && m.roughness.is_none())
        && scene.lights.iter().all(|l| match *l {
            Light::Point { .. } | Light::Directional { .. } => true,
            Light::Area { prim, .. } => matches!(scene.bvh.prims[prim as usize], Prim::Triangle { .. }),
            _ => false,
        })
}

/// Samples per group of pixels whose paths share the lanes: enough that the group's last,
/// longest paths leave the lanes idle for a small share of the time.
const GROUP_SAMPLES: usize = 4096;

/// A scene `supported` accepts, with its lights laid out for the lanes (once per render).
pub struct Tracer<'a> {
    scene: &'a Scene,
    lights: LightTable,
}

impl<'a> Tracer<'a> {
    /// `None` where the scene or the processor needs the one-path loop.
    pub fn new(scene: &'a Scene, settings: &Settings) -> Option<Tracer<'a>> {
        supported(scene, settings).then(|| Tracer { scene, lights: LightTable::new(scene) })
    }

    /// Mean, variance of the mean and dropped samples of the pixels x0..x1 of row y, as
    /// `path::render_pixel` gives them.
    pub fn render_row(
        &self,
        settings: &Settings,
        y: u32,
        x0: u32,
        x1: u32,
    ) -> Vec<([f32; 3], [f32; 3], u64)> {
        let spp = settings.spp as usize;
        if spp == 0 {
            return (x0..x1).map(|_| pixel_stats(std::iter::empty())).collect();
        }
        let group = (GROUP_SAMPLES / spp).max(1) as u32;
        let mut out = Vec::with_capacity((x1 - x0) as usize);
        let mut radiance = Vec::new();
        let mut gx = x0;
        while gx < x1 {
            let gx1 = (gx + group).min(x1);
            radiance.clear();
            radiance.resize((gx1 - gx) as usize * spp, Vec3A::ZERO);
            // SAFETY: `supported` checked that the processor has AVX2.
            unsafe { simd::trace_group(self.scene, &self.lights, settings, y, gx, gx1, &mut radiance) };
            out.extend(radiance.chunks(spp).map(|c| pixel_stats(c.iter().copied())));
            gx = gx1;
        }
        out
    }
}

/// The lights as the lanes gather them by index, one array per component: a triangle (v0,
/// e1, e2, unit normal, area), a point (position in v0) or a direction (towards the light, in
/// v0), and `power`: radiance, intensity or irradiance.
struct LightTable {
    v0: [Vec<f32>; 3],
    e1: [Vec<f32>; 3],
    e2: [Vec<f32>; 3],
    n: [Vec<f32>; 3],
    power: [Vec<f32>; 3],
    area: Vec<f32>,
    kind: Vec<i32>,
}

const TRIANGLE: i32 = 0;
const POINT: i32 = 1;
const DIRECTIONAL: i32 = 2;

impl LightTable {
    fn new(scene: &Scene) -> LightTable {
        let none = || [Vec::new(), Vec::new(), Vec::new()];
        let mut t = LightTable {
            v0: none(),
            e1: none(),
            e2: none(),
            n: none(),
            power: none(),
            area: Vec::new(),
            kind: Vec::new(),
        };
        for light in &scene.lights {
            let z = Vec3A::ZERO;
            let (kind, v0, e1, e2, n, power, area) = match *light {
                Light::Point { position, intensity } => (POINT, position, z, z, z, intensity, 0.0),
                Light::Directional { to_light, irradiance } => {
                    (DIRECTIONAL, to_light, z, z, z, irradiance, 0.0)
                }
                Light::Area { prim, radiance, area } => match scene.bvh.prims[prim as usize] {
                    Prim::Triangle { v0, e1, e2 } => {
                        (TRIANGLE, v0, e1, e2, scene.info[prim as usize].normal, radiance, area)
                    }
                    Prim::Sphere { .. } => (TRIANGLE, z, z, z, z, z, 0.0),
                },
                _ => (TRIANGLE, z, z, z, z, z, 0.0),
            };
            for (table, v) in
                [(&mut t.v0, v0), (&mut t.e1, e1), (&mut t.e2, e2), (&mut t.n, n), (&mut t.power, power)]
            {
                for a in 0..3 {
                    table[a].push(v[a]);
                }
            }
            t.area.push(area);
            t.kind.push(kind);
        }
        t
    }
}

#[cfg(not(target_arch = "x86_64"))]
mod simd {
    pub unsafe fn trace_group(
        _: &super::Scene,
        _: &super::LightTable,
        _: &super::Settings,
        _: u32,
        _: u32,
        _: u32,
        _: &mut [super::Vec3A],
    ) {
        unreachable!("supported() is false without AVX2")
    }
}

#[cfg(target_arch = "x86_64")]
mod trace;
#[cfg(target_arch = "x86_64")]
use trace as simd;
