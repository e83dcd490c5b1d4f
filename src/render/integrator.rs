//! Unidirectional path tracing with next-event estimation and Russian roulette.
//!
//! For a path x₀ (camera) → x₁ → … the estimator adds, at every vertex xₖ, one light sample:
//!
//!   L += β · f(xₖ) · Lₑ · cos θₖ · G / (p_light · p_pick),  β = Π f·cos / p_bsdf
//!
//! At a Lambertian vertex that light sample is the only estimate of direct light, and emission
//! found by BSDF sampling is counted only on the camera ray. At a glossy vertex (Blinn-Phong,
//! conductor) the two strategies are combined by multiple importance sampling (Veach 1997,
//! power heuristic): the light sample of an area light is weighted p_light²/(p_light² + p_bsdf²)
//! and an emitter the BSDF-sampled ray reaches counts with p_bsdf²/(p_light² + p_bsdf²), both
//! densities in solid angle (p_light = p_pick·r²/(A·cos θ_light)); samples of point and
//! directional lights, which BSDF sampling cannot hit, keep weight 1. A constant environment
//! is sampled uniformly over the sphere (p_light = p_pick/4π), an image one by its luminance
//! (`render::envmap`), and, like an emitter, counted when a ray leaves the scene: on the
//! camera ray, or after a glossy vertex with its MIS weight. Scenes without glossy materials
//! do none of this bookkeeping. At a mirror or smooth dielectric (delta) vertex there is no
//! light sample (it could not land on the one direction the vertex scatters into), and the
//! emitter or environment the scattered ray reaches counts in full. Surfaces are two-sided;
//! emitters emit on their front side only; a dielectric's inside is the side its normal
//! points away from. A thin lens, when the camera has one, moves each camera ray's origin
//! over the aperture (`lens_ray`).
//!
//! Depth follows Mitsuba's convention: `max_depth` counts path segments, so 1 shows emitters
//! seen directly and 2 is direct lighting only. Russian roulette starts after 5 segments (as in
//! Mitsuba) with survival probability min(max(β), 0.95).
//!
//! Film: each pixel (i, j) of the image is integrated over the box [i − ½, i + ½) × [j − ½, j + ½)
//! in OpenCV's pixel coordinates (centre at the integer), so sample position = index + ξ − ½.
//! The film keeps the mean and the variance of that mean (sample variance / n) per channel.
//!
//! Scenes of Lambertian surfaces under triangle area lights, point lights and directional
//! lights (the Cornell box among them) are traced eight paths at a time by `render::lanes`,
//! which computes exactly this loop's numbers, about 1.2–1.3× as fast.

use super::bsdf::Bsdf;
use super::camera_ray::{camera_direction, camera_ray, needs_lens_sample};
use super::film::{pixel_stats, RR_START};
pub use super::film::{Film, Settings};
use super::geometry::{Hit, Prim, Ray};
use super::sampler::Sampler;
use super::scene::{Light, Scene};
use super::texture::Texture;
use crate::image::Image;
use glam::{Vec2, Vec3A};
use rayon::prelude::*;
use std::f32::consts::PI;

/// Offset for spawning rays off a surface, scaled with the coordinates' magnitude.
#[inline]
fn epsilon(p: Vec3A) -> f32 {
    1e-4 * (1.0 + p.abs().max_element())
}

/// Surface data at a hit.
pub struct Surface {
    pub p: Vec3A,
    /// Geometric normal, flipped for reversed shapes: the side emitters emit from.
    pub n: Vec3A,
    pub material: u32,
    pub object_id: u32,
}

impl Scene {
    pub fn surface(&self, ray: &Ray, hit: &Hit) -> Surface {
        let info = &self.info[hit.prim as usize];
        let p = ray.origin + ray.dir * hit.t;
        let n = match self.bvh.prims[hit.prim as usize] {
            Prim::Triangle { .. } => info.normal,
            Prim::Sphere { center, .. } => {
                let n = (p - center).normalize();
                if info.reverse {
                    -n
                } else {
                    n
                }
            }
        };
        Surface { p, n, material: info.material, object_id: info.object_id }
    }

    /// Texture coordinates at a hit: interpolated for triangles, (longitude, colatitude) / (2π,
    /// π) for spheres.
    pub fn uv(&self, hit: &Hit, p: Vec3A) -> Vec2 {
        let info = &self.info[hit.prim as usize];
        match self.bvh.prims[hit.prim as usize] {
            Prim::Triangle { .. } => {
                info.uv[0] * (1.0 - hit.b1 - hit.b2) + info.uv[1] * hit.b1 + info.uv[2] * hit.b2
            }
            Prim::Sphere { center, .. } => {
                let d = (p - center).normalize();
                Vec2::new(0.5 + d.z.atan2(d.x) / (2.0 * PI), d.y.clamp(-1.0, 1.0).acos() / PI)
            }
        }
    }

    /// Diffuse albedo of a material at a hit (texture coordinates only when textured).
    #[inline]
    pub fn albedo(&self, material: u32, hit: &Hit, p: Vec3A) -> Vec3A {
        match &self.materials[material as usize].albedo {
            Texture::Constant(c) => *c,
            t => t.eval(self.uv(hit, p)),
        }
    }

    /// Radiance along a camera ray.
    pub fn trace(&self, mut ray: Ray, max_depth: u32, s: &mut Sampler) -> Vec3A {
        let mut beta = Vec3A::ONE;
        let mut l = Vec3A::ZERO;
        // The solid-angle density of the BSDF sample that made `ray`, when its vertex was
        // glossy (module docs).
        let mut mis_pdf: Option<f32> = None;
        // A half-open range: `1..=max_depth` costs a check per vertex.
        for depth in 1..max_depth.saturating_add(1) {
            let Some(hit) = self.bvh.intersect(&ray, 0.0, f32::INFINITY) else {
                // Leaving the scene: the environment, counted as emission is (module docs).
                if depth == 1 || mis_pdf.is_some() {
                    if let Some((le, p_light)) = self.environment(ray.dir) {
                        l += beta * le * mis_pdf.map_or(1.0, |p_bsdf| power_heuristic(p_bsdf, p_light));
                    }
                }
                break;
            };
            let surf = self.surface(&ray, &hit);
            let mat = &self.materials[surf.material as usize];
            let wo = -ray.dir;
            if let Some(le) = mat.emission {
                if surf.n.dot(wo) > 0.0 {
                    if depth == 1 {
                        l += beta * le;
                    } else if let Some(p_bsdf) = mis_pdf {
                        let p_light = self.area_light_pdf(hit.prim, ray.origin, surf.p, surf.n);
                        l += beta * le * power_heuristic(p_bsdf, p_light);
                    }
                }
            }
            if depth == max_depth {
                break;
            }
            // Two-sided surfaces: shade with the normal on the side the path arrived from.
            let front = surf.n.dot(wo) >= 0.0;
            let n = if front { surf.n } else { -surf.n };
            let albedo = self.albedo(surf.material, &hit, surf.p);
            let eps = epsilon(surf.p);
            // The material's model by reference: a copy of the enum per vertex is measurable.
            let changed;
            let bsdf = match (&mat.bsdf, &mat.roughness) {
                (Bsdf::Dielectric { .. }, _) if !front => {
                    changed = mat.bsdf.facing(front);
                    &changed
                }
                (_, Some(alpha)) => {
                    changed = mat.bsdf.with_alpha(alpha.eval(self.uv(&hit, surf.p)).x);
                    &changed
                }
                (b, None) => b,
            };

            let delta = bsdf.is_delta();
            // Named by the glossy variants: written as "neither Lambertian nor delta", the test
            // let LLVM call `Bsdf::pdf` on every Lambertian vertex and throw the result away
            // (6 % of a Cornell path's instructions).
            let glossy = matches!(bsdf, Bsdf::BlinnPhong { .. } | Bsdf::Conductor { .. });
            let u_light = s.next2();
            if !delta {
                if let Some((li, wi, dist, p_light)) = self.sample_light(u_light, surf.p) {
                    let cos = n.dot(wi);
                    if cos > 0.0 && self.unoccluded(surf.p + n * eps, surf.p, wi, dist) {
                        let w = match p_light {
                            Some(p) if glossy => power_heuristic(p, bsdf.pdf(albedo, n, wo, wi)),
                            _ => 1.0,
                        };
                        l += beta * bsdf.eval(albedo, n, wo, wi) * (cos * w) * li;
                    }
                }
            }

            let (u1, u2) = s.next2();
            let Some((wi, weight)) = bsdf.sample(albedo, n, wo, u1, u2) else {
                break;
            };
            // After a delta vertex the emitter the ray reaches counts in full (weight 1).
            mis_pdf = if delta { Some(f32::INFINITY) } else { glossy.then(|| bsdf.pdf(albedo, n, wo, wi)) };
            beta *= weight;
            if depth >= RR_START {
                let q = beta.max_element().min(0.95);
                if s.next() >= q {
                    break;
                }
                beta /= q;
            }
            if beta == Vec3A::ZERO {
                break;
            }
            // Refracted rays leave from the far side.
            let origin = surf.p + if n.dot(wi) >= 0.0 { n * eps } else { -n * eps };
            ray = Ray { origin, dir: wi };
        }
        l
    }

    /// Whether the light point `p + wi·dist` (or the direction `wi`, for an infinite `dist`)
    /// is visible from the offset ray origin `origin`. The shadow ray aims at the point itself
    /// rather than along wi: near a sphere light's silhouette, moving the origin by the offset
    /// moves where a grazing ray enters the sphere by many times that offset.
    #[inline]
    fn unoccluded(&self, origin: Vec3A, p: Vec3A, wi: Vec3A, dist: f32) -> bool {
        if !dist.is_finite() {
            return !self.bvh.occluded(&Ray { origin, dir: wi }, 0.0, f32::INFINITY);
        }
        let to = p + wi * dist - origin;
        let len = to.length();
        len > 0.0 && !self.bvh.occluded(&Ray { origin, dir: to / len }, 0.0, len * (1.0 - 1e-4) - epsilon(p))
    }

    /// An emitting sphere seen from outside is sampled by the cone of directions it subtends
    /// (uniform in solid angle, cos θ_max = √(1 − R²/d²)), not by its area: every sample
    /// then reaches the visible cap, and the density 1/(2π(1 − cos θ_max)) stays bounded
    /// however small or far the sphere. Returns (direction, distance to the sphere, density);
    /// `None` for other primitives, inward-emitting spheres and points inside or on one.
    #[inline]
    fn sample_sphere_cone(&self, prim: u32, p: Vec3A, u: (f32, f32)) -> Option<(Vec3A, f32, f32)> {
        let (w, d, one_minus) = self.sphere_cone(prim, p)?;
        let Prim::Sphere { radius, .. } = self.bvh.prims[prim as usize] else { return None };
        let cos_t = 1.0 - u.0 * one_minus;
        let sin2 = (1.0 - cos_t * cos_t).max(0.0);
        let phi = 2.0 * PI * u.1;
        let (t, b) = super::bsdf::basis(w);
        let s = sin2.sqrt();
        let wi = (t * (s * phi.cos()) + b * (s * phi.sin()) + w * cos_t).normalize();
        // Nearest intersection along wi with the sphere.
        let dist = d * cos_t - (radius * radius - d * d * sin2).max(0.0).sqrt();
        Some((wi, dist.max(0.0), 1.0 / (2.0 * PI * one_minus)))
    }

    /// The cone an outward-emitting sphere light subtends from `p`: (axis, distance to the
    /// centre, 1 − cos θ_max computed without cancellation as sin²θ_max / (1 + cos θ_max)).
    #[inline]
    fn sphere_cone(&self, prim: u32, p: Vec3A) -> Option<(Vec3A, f32, f32)> {
        let Prim::Sphere { center, radius } = self.bvh.prims[prim as usize] else { return None };
        if self.info[prim as usize].reverse {
            return None;
        }
        let dc = center - p;
        let d2 = dc.length_squared();
        let sin2 = radius * radius / d2;
        if !(sin2 < 1.0 - 1e-4) {
            return None;
        }
        let cos_max = (1.0 - sin2).sqrt();
        let d = d2.sqrt();
        Some((dc / d, d, sin2 / (1.0 + cos_max)))
    }

    /// Solid-angle density with which light sampling from `from` picks the point `y` (normal
    /// `ny`) of primitive `prim`: 0 unless it is an area light seen from its front. For a sphere
    /// seen from outside, the cone density whatever the point (a ray from outside first meets
    /// the cap the cone covers).
    pub fn area_light_pdf(&self, prim: u32, from: Vec3A, y: Vec3A, ny: Vec3A) -> f32 {
        let i = self.light_of_prim[prim as usize];
        let Some(&Light::Area { area, .. }) = self.lights.get(i as usize) else {
            return 0.0;
        };
        if let Some((.., one_minus)) = self.sphere_cone(prim, from) {
            return self.pick_probability(i as usize) / (2.0 * PI * one_minus);
        }
        let d = y - from;
        let r2 = d.length_squared();
        let cos_light = -ny.dot(d) / r2.sqrt();
        if cos_light <= 0.0 {
            return 0.0;
        }
        self.pick_probability(i as usize) * r2 / (area * cos_light)
    }

    /// One light sample seen from `p`, the light picked by `u.0` (`pick_light`) and its point
    /// drawn with what is left of `u.0` and `u.1`: (incident radiance divided by every pdf,
    /// unit direction towards the light, distance, solid-angle density of the sample, `None`
    /// for point and directional lights). `None` when the sample carries nothing.
    #[inline]
    pub fn sample_light(&self, u: (f32, f32), p: Vec3A) -> Option<(Vec3A, Vec3A, f32, Option<f32>)> {
        let (i, p_pick, u0) = self.pick_light(u.0)?;
        let u = (u0, u.1);
        match self.lights[i] {
            Light::Point { position, intensity } => {
                let d = position - p;
                let r2 = d.length_squared();
                let r = r2.sqrt();
                Some((intensity / (r2 * p_pick), d / r, r, None))
            }
            Light::Directional { to_light, irradiance } => {
                Some((irradiance / p_pick, to_light, f32::INFINITY, None))
            }
            Light::Environment { radiance, .. } => {
                if let Some(map) = &self.environment_map {
                    let (wi, pdf) = map.sample(u)?;
                    let pdf = p_pick * pdf;
                    return Some((radiance * map.eval(wi) / pdf, wi, f32::INFINITY, Some(pdf)));
                }
                // Uniform over the sphere of directions.
                let z = 1.0 - 2.0 * u.0;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let phi = 2.0 * PI * u.1;
                let pdf = p_pick / (4.0 * PI);
                Some((radiance / pdf, Vec3A::new(r * phi.cos(), r * phi.sin(), z), f32::INFINITY, Some(pdf)))
            }
            Light::Spot { position, axis, intensity, cutoff, beam } => {
                let d = position - p;
                let r2 = d.length_squared();
                let r = r2.sqrt();
                let wi = d / r;
                let theta = (-wi).dot(axis).clamp(-1.0, 1.0).acos();
                let falloff = super::scene::spot_falloff(theta, cutoff, beam);
                (falloff > 0.0).then(|| (intensity * (falloff / (r2 * p_pick)), wi, r, None))
            }
            Light::Area { prim, radiance, area } => {
                if let Some((wi, dist, pdf)) = self.sample_sphere_cone(prim, p, u) {
                    let pdf = p_pick * pdf;
                    return Some((radiance / pdf, wi, dist, Some(pdf)));
                }
                let shape = &self.bvh.prims[prim as usize];
                let info = &self.info[prim as usize];
                let (y, ny) = match shape {
                    // The stored unit normal, reversal applied.
                    Prim::Triangle { .. } => (shape.sample_area(u.0, u.1).0, info.normal),
                    Prim::Sphere { .. } => {
                        let (y, ny) = shape.sample_area(u.0, u.1);
                        (y, if info.reverse { -ny } else { ny })
                    }
                };
                let d = y - p;
                let r2 = d.length_squared();
                let r = r2.sqrt();
                let wi = d / r;
                let cos_light = -ny.dot(wi);
                if cos_light <= 0.0 || r2 == 0.0 {
                    return None;
                }
                // Area-measure pdf 1/A converted to solid angle: r² / (A cos θ_light).
                let pdf = p_pick * r2 / (area * cos_light);
                Some((radiance / pdf, wi, r, Some(pdf)))
            }
        }
    }
}

/// Veach's power heuristic (β = 2) weight of strategy a against b.
#[inline]
fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 > 0.0 && a2.is_finite() {
        a2 / (a2 + b2)
    } else if a.is_infinite() {
        1.0
    } else {
        0.0
    }
}

/// Renders the scene into a film.
pub fn render(scene: &Scene, settings: &Settings) -> Film {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let [x0, y0, x1, y1] = settings.crop.unwrap_or([0, 0, w, h]);
    let (fw, fh) = (x1.saturating_sub(x0), y1.saturating_sub(y0));
    render_into(scene, settings, Image::new(fw, fh, 3), Image::new(fw, fh, 3))
}

/// `render`, refusing with `Error::OutOfMemory` (nothing allocated) a film whose memory
/// cannot be had, where `render` would abort: for films of a size a user chose.
pub fn try_render(scene: &Scene, settings: &Settings) -> Result<Film, super::Error> {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let [x0, y0, x1, y1] = settings.crop.unwrap_or([0, 0, w, h]);
    let (fw, fh) = (x1.saturating_sub(x0), y1.saturating_sub(y0));
    let oom = || super::Error::OutOfMemory {
        what: format!("a {fw}×{fh} film (mean and variance, 3 float32 channels each)"),
        bytes: 2 * 3 * 4 * fw as u64 * fh as u64,
    };
    let mean = Image::try_new(fw, fh, 3).ok_or_else(oom)?;
    let variance = Image::try_new(fw, fh, 3).ok_or_else(oom)?;
    Ok(render_into(scene, settings, mean, variance))
}

fn render_into(scene: &Scene, settings: &Settings, mut mean: Image, mut variance: Image) -> Film {
    let (x0, y0) = settings.crop.map_or((0, 0), |c| (c[0], c[1]));
    let (fw, fh) = (mean.width, mean.height);
    let x1 = x0 + fw;
    let bar = super::progress_bar(fh as u64, "render", settings.progress);
    let dropped = std::sync::atomic::AtomicU64::new(0);
    let lanes = if settings.lanes { super::lanes::Tracer::new(scene, settings) } else { None };
    let mut work = || {
        let (mean, variance) = (&mut mean, &mut variance);
        mean.data
            .par_chunks_mut(3 * fw as usize)
            .zip(variance.data.par_chunks_mut(3 * fw as usize))
            .enumerate()
            .for_each(|(row, (mrow, vrow))| {
                let y = y0 + row as u32;
                let mut lost = 0;
                let mut put = |i: usize, (m, v, d): ([f32; 3], [f32; 3], u64)| {
                    mrow[3 * i..3 * i + 3].copy_from_slice(&m);
                    vrow[3 * i..3 * i + 3].copy_from_slice(&v);
                    lost += d;
                };
                if let Some(lanes) = &lanes {
                    for (i, px) in lanes.render_row(settings, y, x0, x1).into_iter().enumerate() {
                        put(i, px);
                    }
                } else {
                    for i in 0..fw as usize {
                        put(i, render_pixel(scene, settings, x0 + i as u32, y));
                    }
                }
                if lost > 0 {
                    dropped.fetch_add(lost, std::sync::atomic::Ordering::Relaxed);
                }
                bar.inc(1);
            })
    };
    match settings.threads.and_then(|n| rayon::ThreadPoolBuilder::new().num_threads(n.max(1)).build().ok()) {
        Some(pool) => pool.install(work),
        None => work(),
    }
    bar.finish_and_clear();
    Film { mean, variance, origin: [x0, y0], dropped_samples: dropped.into_inner() }
}

/// Mean and variance of the mean of one pixel, and the number of non-finite samples dropped.
fn render_pixel(scene: &Scene, settings: &Settings, x: u32, y: u32) -> ([f32; 3], [f32; 3], u64) {
    pixel_stats((0..settings.spp).map(|k| {
        let (mut s, ray) = camera_path(scene, settings, x, y, k);
        ray.map_or(Vec3A::ZERO, |ray| scene.trace(ray, settings.max_depth, &mut s))
    }))
}

/// The start of sample `k` of pixel (x, y): its sampler, after the pixel position (and a thin
/// lens's sample) were drawn, and the camera ray, `None` beyond the fold of the distortion
/// (no scene ray maps there; the sample is black).
fn camera_path(scene: &Scene, settings: &Settings, x: u32, y: u32, k: u32) -> (Sampler, Option<Ray>) {
    let pixel_index = y as u64 * scene.camera.width as u64 + x as u64;
    let mut s = Sampler::with_kind(settings.sampler, settings.seed, pixel_index, k as u64);
    let ray = camera_direction(scene, x, y, s.next2()).map(|d| {
        let lens_u = needs_lens_sample(scene, d).then(|| s.next2());
        camera_ray(scene, d, lens_u)
    });
    (s, ray)
}
