//! Light leaving the emitters: rays drawn from the lights, for integrators that start paths
//! there (light tracing), with the densities they are drawn with.
//!
//! A light is picked in proportion to its power (`Scene::pick_light`, as light sampling picks
//! it), then a ray from it:
//!
//! - area light (triangle or sphere): a point uniform in area, a cosine-weighted direction
//!   about its emitting normal: β = Le·π·A / p_pick;
//! - point light: a direction uniform over the sphere: β = 4π·I / p_pick;
//! - spot light: a direction uniform in the cone of its cutoff angle θc:
//!   β = I·falloff(θ)·2π(1 − cos θc) / p_pick;
//! - directional light: a point uniform on the disk of the scene's bounding sphere that faces
//!   the light, tangent to the sphere (so outside the scene): β = E·πR² / p_pick;
//! - environment: a direction ω drawn as light sampling draws it (the map's luminance, or
//!   uniform), then a point on the disk facing ω as for a directional light:
//!   β = L(ω)·πR² / (p(ω)·p_pick).
//!
//! β is the ray's flux: the emitted radiance times the cosine, divided by every density, in
//! watts, so the mean of β over rays is the power `light_power` counts (the pick's
//! weights), and the rays of an area light leave it as its radiance does.

use super::super::geometry::{Prim, Ray};
use super::super::transport;
use super::{Light, Scene};
use glam::Vec3A;
use std::f32::consts::PI;

/// A ray leaving a light (module docs).
#[derive(Clone, Copy, Debug)]
pub struct Emission {
    pub ray: Ray,
    /// The point on the light it left (before the ray's offset off an area light) and the
    /// light's normal there (zero for point and spot lights; the travel direction for
    /// directional and environment light).
    pub p: Vec3A,
    pub n: Vec3A,
    /// The ray's flux weight, W.
    pub beta: Vec3A,
    /// The light it left, by index in `Scene::lights`.
    pub light: usize,
}

impl Scene {
    /// A ray from a light picked by `u_pick` (its point drawn with `u_pos`, its direction
    /// with `u_dir`); `None` without lights or where the ray carries nothing.
    pub fn sample_emission(&self, u_pick: f32, u_pos: (f32, f32), u_dir: (f32, f32)) -> Option<Emission> {
        let (i, p_pick, _) = self.pick_light(u_pick)?;
        let mut at = None;
        let (origin, dir, beta) = match self.lights[i] {
            Light::Area { prim, radiance, area } => {
                let (y, n) = self.area_light_point(prim, u_pos);
                let dir = self.emission_direction(i, n, u_dir);
                at = Some((y, n));
                (transport::offset(y, n, dir, transport::epsilon(y)), dir, radiance * (PI * area / p_pick))
            }
            Light::Point { position, intensity } => {
                (position, self.emission_direction(i, Vec3A::ZERO, u_dir), intensity * (4.0 * PI / p_pick))
            }
            Light::Spot { position, axis, intensity, cutoff, beam } => {
                let cos_max = cutoff.cos();
                let cos_t = 1.0 - u_dir.0 * (1.0 - cos_max);
                let dir = around(axis, cos_t, u_dir.1);
                let falloff = super::spot_falloff(cos_t.clamp(-1.0, 1.0).acos(), cutoff, beam);
                (position, dir, intensity * (falloff * 2.0 * PI * (1.0 - cos_max) / p_pick))
            }
            Light::Directional { to_light, irradiance } => {
                let r = self.bounds_radius;
                (self.disk_point(to_light, u_pos), -to_light, irradiance * (PI * r * r / p_pick))
            }
            Light::Environment { .. } => {
                let (w, le, pdf) = self.sample_environment(u_dir)?;
                let r = self.bounds_radius;
                (self.disk_point(w, u_pos), -w, le * (PI * r * r / (pdf * p_pick)))
            }
        };
        let (p, n) = at.unwrap_or(match self.lights[i] {
            Light::Point { .. } | Light::Spot { .. } => (origin, Vec3A::ZERO),
            _ => (origin, dir),
        });
        (beta.max_element() > 0.0 && beta.is_finite()).then_some(Emission {
            ray: Ray { origin, dir },
            p,
            n,
            beta,
            light: i,
        })
    }

    /// The direction `sample_emission` draws with `u` for the area, point or spot light `i`
    /// (`n` the area light's normal at the point drawn): cosine-weighted about `n`, uniform
    /// over the sphere, uniform in the spot's cone.
    pub(super) fn emission_direction(&self, i: usize, n: Vec3A, u: (f32, f32)) -> Vec3A {
        match self.lights[i] {
            Light::Spot { axis, cutoff, .. } => around(axis, 1.0 - u.0 * (1.0 - cutoff.cos()), u.1),
            Light::Point { .. } => uniform_sphere(u),
            _ => transport::cosine_hemisphere(n, u.0, u.1),
        }
    }

    /// The densities with which `sample_emission`, having picked light `i`, draws the ray
    /// leaving `y` (the light's normal `ny` there, for area lights) along `dir`: (position
    /// per unit area, 1 for the single point of a point or spot light; direction per
    /// steradian, 1 for a directional light's single direction). The pick's probability is
    /// not included.
    pub fn emission_pdf(&self, i: usize, ny: Vec3A, dir: Vec3A) -> (f32, f32) {
        let r = self.bounds_radius;
        match self.lights[i] {
            Light::Area { area, .. } => (1.0 / area, ny.dot(dir).max(0.0) / PI),
            Light::Point { .. } => (1.0, 1.0 / (4.0 * PI)),
            Light::Spot { axis, cutoff, .. } => {
                let inside = axis.dot(dir) >= cutoff.cos();
                (1.0, if inside { 1.0 / (2.0 * PI * (1.0 - cutoff.cos())) } else { 0.0 })
            }
            Light::Directional { .. } => (1.0 / (PI * r * r), 1.0),
            Light::Environment { .. } => {
                let p = match &self.environment_map {
                    Some(map) => map.pdf(-dir),
                    None => 1.0 / (4.0 * PI),
                };
                (1.0 / (PI * r * r), p)
            }
        }
    }

    /// A point uniform in area on the area light `prim`, and its emitting normal (the stored
    /// one, reversal applied).
    #[inline]
    pub fn area_light_point(&self, prim: u32, u: (f32, f32)) -> (Vec3A, Vec3A) {
        let shape = &self.bvh.prims[prim as usize];
        let info = &self.info[prim as usize];
        match shape {
            Prim::Triangle { .. } => (shape.sample_area(u.0, u.1).0, info.normal),
            Prim::Sphere { .. } => {
                let (y, ny) = shape.sample_area(u.0, u.1);
                (y, if info.reverse { -ny } else { ny })
            }
        }
    }

    /// A direction towards the environment as light sampling draws it: (direction, radiance
    /// arriving from it, solid-angle density without the light's pick).
    #[inline]
    pub fn sample_environment(&self, u: (f32, f32)) -> Option<(Vec3A, Vec3A, f32)> {
        let Light::Environment { radiance, .. } = self.lights[self.environment_light?] else {
            return None;
        };
        match &self.environment_map {
            Some(map) => {
                let (w, pdf) = map.sample(u)?;
                Some((w, radiance * map.eval(w), pdf))
            }
            None => Some((uniform_sphere(u), radiance, 1.0 / (4.0 * PI))),
        }
    }

    /// A point uniform on the disk of the bounding sphere's radius, tangent to the sphere on
    /// the side `w` points to, perpendicular to `w`.
    fn disk_point(&self, w: Vec3A, u: (f32, f32)) -> Vec3A {
        let r = self.bounds_radius;
        let (t, b) = transport::basis(w);
        let (rho, phi) = (u.0.sqrt(), 2.0 * PI * u.1);
        self.bounds_center + w * r + (t * phi.cos() + b * phi.sin()) * (rho * r)
    }
}

/// A direction uniform over the sphere.
#[inline]
pub(super) fn uniform_sphere(u: (f32, f32)) -> Vec3A {
    let z = 1.0 - 2.0 * u.0;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.1;
    Vec3A::new(r * phi.cos(), r * phi.sin(), z)
}

/// The unit direction at cosine `cos_t` from `axis`, turned by 2π·`u` about it.
pub(super) fn around(axis: Vec3A, cos_t: f32, u: f32) -> Vec3A {
    let (t, b) = transport::basis(axis);
    let s = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let (cos, sin) = transport::unit_circle(u);
    (t * (s * cos) + b * (s * sin) + axis * cos_t).normalize()
}
