//! What an integrator asks of the scene: the surface at a hit (point, normal, material, texture
//! coordinates, albedo), whether a light point is visible, and light samples with their
//! densities. The scene holds the data; the transport loops live in `render::integrators`.

use super::super::geometry::{Hit, Prim, Ray};
use super::super::texture::Texture;
use super::super::transport;
use super::{Light, Scene};
use glam::{Vec2, Vec3A};
use std::f32::consts::PI;

pub use super::super::transport::epsilon;

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

    /// The medium a path is in after crossing or leaving primitive `prim` (normal `n`) along
    /// `dir`, having been in `current`: the shape's exterior where `dir` goes the way its
    /// normal points, its interior otherwise, and `current` where the shape bounds no medium.
    #[inline]
    pub fn medium_after(&self, prim: u32, n: Vec3A, dir: Vec3A, current: Option<u32>) -> Option<u32> {
        match self.boundaries.get(prim as usize) {
            Some(Some([inside, outside])) => {
                if n.dot(dir) > 0.0 {
                    *outside
                } else {
                    *inside
                }
            }
            _ => current,
        }
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

    /// Whether the light point `p + wi·dist` (or the direction `wi`, for an infinite `dist`)
    /// is visible from the offset ray origin `origin`. The shadow ray aims at the point itself
    /// rather than along wi: near a sphere light's silhouette, moving the origin by the offset
    /// moves where a grazing ray enters the sphere by many times that offset.
    #[inline]
    pub fn unoccluded(&self, origin: Vec3A, p: Vec3A, wi: Vec3A, dist: f32) -> bool {
        if !dist.is_finite() {
            return !self.bvh.occluded(&Ray { origin, dir: wi }, 0.0, f32::INFINITY);
        }
        let (dir, t_max, has_length) = transport::shadow_segment(origin, p, wi, dist);
        has_length && !self.bvh.occluded(&Ray { origin, dir }, 0.0, t_max)
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
        let (t, b) = super::super::bsdf::basis(w);
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
        sphere_cone(center, radius, p)
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
                let (wi, r, r2) = transport::towards(p, position);
                Some((transport::point_light(intensity, r2, p_pick), wi, r, None))
            }
            Light::Directional { to_light, irradiance } => {
                Some((irradiance / p_pick, to_light, f32::INFINITY, None))
            }
            Light::Environment { .. } => {
                let (wi, le, pdf) = self.sample_environment(u)?;
                let pdf = p_pick * pdf;
                Some((le / pdf, wi, f32::INFINITY, Some(pdf)))
            }
            Light::Spot { position, axis, intensity, cutoff, beam } => {
                let d = position - p;
                let r2 = d.length_squared();
                let r = r2.sqrt();
                let wi = d / r;
                let theta = (-wi).dot(axis).clamp(-1.0, 1.0).acos();
                let falloff = super::spot_falloff(theta, cutoff, beam);
                (falloff > 0.0).then(|| (intensity * (falloff / (r2 * p_pick)), wi, r, None))
            }
            Light::Area { prim, radiance, area } => {
                if let Some((wi, dist, pdf)) = self.sample_sphere_cone(prim, p, u) {
                    let pdf = p_pick * pdf;
                    return Some((radiance / pdf, wi, dist, Some(pdf)));
                }
                let (y, ny) = self.area_light_point(prim, u);
                let (wi, r, r2) = transport::towards(p, y);
                let (li, pdf, lit) = transport::area_light(wi, r2, ny, radiance, area, p_pick);
                lit.then_some((li, wi, r, Some(pdf)))
            }
        }
    }
}

/// The cone the sphere (`center`, `radius`) subtends from `p`: (axis, distance to the centre,
/// 1 − cos θ_max computed without cancellation as sin²θ_max / (1 + cos θ_max)); `None` from
/// inside the sphere or on it.
#[inline]
pub(super) fn sphere_cone(center: Vec3A, radius: f32, p: Vec3A) -> Option<(Vec3A, f32, f32)> {
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
