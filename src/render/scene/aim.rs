//! Light paths aimed at what focuses light, for photon mapping: Jensen's projection maps
//! (Jensen 2001, §9.1.1), with the delta objects' bounding spheres for the map.
//!
//! A caustic is made only by the light paths that reach a mirror or glass. From a small light
//! those are few: in `tests/data/mitsuba/caustic.xml` the glass sphere subtends 0.17 sr from
//! the lamp, about 1.4 % of the directions it emits in, so 98.6 % of the photons a pass traces
//! add nothing to the caustic. Here the direction leaving an area, point or spot light is
//! drawn from a one-sample mixture: with probability ½ uniformly in the cone that one of the
//! K delta objects' bounding spheres subtends from the light's point (the sphere picked
//! uniformly), otherwise as `Scene::sample_emission` draws it. The ray's flux weight divides
//! by the mixture's density
//!
//!   p(ω) = ½·(1/K)·Σₖ [ω ∈ Cₖ] / (2π(1 − cos θₖ)) + ½·p_light(ω),
//!
//! so every direction keeps its expected share of the light's power (the estimate stays
//! unbiased) while the directions that reach the glass are drawn about 19 times as often
//! there (26 % of the rays instead of 1.4 %: half of the aimed directions leave a point of the
//! spherical lamp through its back, where it does not emit). Photons not aimed still carry the light everywhere else (the global photons); where
//! delta objects are large or absent from the light's view, the mixture costs at most half of
//! those. Environment and directional lights are drawn as `sample_emission` draws them.
//! Delta objects are grouped by object id; past `MAX_SPHERES` of them, one sphere bounds all.

use super::super::bsdf::Bsdf;
use super::super::geometry::Prim;
use super::super::transport;
use super::emission::{around, uniform_sphere, Emission};
use super::query::sphere_cone;
use super::{spot_falloff, Light, Scene};
use glam::Vec3A;
use std::collections::BTreeMap;
use std::f32::consts::PI;

/// The share of light paths aimed at the delta objects.
const AIMED: f32 = 0.5;
/// More delta objects than this are bounded by one sphere (the density sums over spheres).
const MAX_SPHERES: usize = 32;

/// The bounding spheres of the scene's delta objects (module docs).
pub struct Aim {
    spheres: Vec<(Vec3A, f32)>,
}

impl Aim {
    /// The scene's delta objects (mirrors, glass; not emitters, not `null`) as bounding
    /// spheres; `None` when it has none.
    pub fn of(scene: &Scene) -> Option<Aim> {
        let delta = |info: &super::super::geometry::PrimInfo| {
            let mat = &scene.materials[info.material as usize];
            mat.bsdf.is_delta() && !matches!(mat.bsdf, Bsdf::Null) && mat.emission.is_none()
        };
        // Each object's box, then the sphere about its centre through its farthest point.
        let mut boxes: BTreeMap<u32, (Vec3A, Vec3A)> = BTreeMap::new();
        for (prim, info) in scene.bvh.prims.iter().zip(&scene.info).filter(|(_, i)| delta(i)) {
            let (lo, hi) = prim.bounds();
            let b = boxes.entry(info.object_id).or_insert((lo, hi));
            *b = (b.0.min(lo), b.1.max(hi));
        }
        let merged = boxes.len() > MAX_SPHERES;
        if merged {
            let all = boxes
                .values()
                .fold((Vec3A::INFINITY, Vec3A::NEG_INFINITY), |a, b| (a.0.min(b.0), a.1.max(b.1)));
            boxes = BTreeMap::from([(0, all)]);
        }
        let mut spheres: BTreeMap<u32, (Vec3A, f32)> =
            boxes.into_iter().map(|(id, (lo, hi))| (id, ((lo + hi) * 0.5, 0.0))).collect();
        for (prim, info) in scene.bvh.prims.iter().zip(&scene.info).filter(|(_, i)| delta(i)) {
            let Some((c, r)) = spheres.get_mut(&if merged { 0 } else { info.object_id }) else { continue };
            let far = match *prim {
                Prim::Triangle { v0, e1, e2 } => {
                    [v0, v0 + e1, v0 + e2].map(|v| v.distance(*c)).into_iter().fold(0.0, f32::max)
                }
                Prim::Sphere { center, radius } => center.distance(*c) + radius,
            };
            *r = r.max(far);
        }
        let spheres: Vec<(Vec3A, f32)> = spheres.into_values().map(|(c, r)| (c, r.max(1e-6))).collect();
        (!spheres.is_empty()).then_some(Aim { spheres })
    }

    /// A ray from a light picked by `u_pick`, its direction aimed with probability ½ (`u_aim`
    /// chooses, and which sphere) and drawn with `u_dir` (module docs).
    pub fn sample_emission(
        &self,
        scene: &Scene,
        u_pick: f32,
        u_pos: (f32, f32),
        u_dir: (f32, f32),
        u_aim: f32,
    ) -> Option<Emission> {
        let (i, p_pick, _) = scene.pick_light(u_pick)?;
        let (y, n, pdf_pos) = match scene.lights[i] {
            Light::Area { prim, area, .. } => {
                let (y, n) = scene.area_light_point(prim, u_pos);
                (y, n, 1.0 / area)
            }
            Light::Point { position, .. } | Light::Spot { position, .. } => (position, Vec3A::ZERO, 1.0),
            Light::Directional { .. } | Light::Environment { .. } => {
                return scene.sample_emission(u_pick, u_pos, u_dir);
            }
        };
        let dir = if u_aim < AIMED {
            let k = ((u_aim / AIMED * self.spheres.len() as f32) as usize).min(self.spheres.len() - 1);
            cone_sample(self.spheres[k], y, u_dir)
        } else {
            scene.emission_direction(i, n, u_dir)
        };
        let emitted = match scene.lights[i] {
            Light::Area { radiance, .. } => radiance * n.dot(dir).max(0.0),
            Light::Point { intensity, .. } => intensity,
            Light::Spot { axis, intensity, cutoff, beam, .. } => {
                let cos = axis.dot(dir);
                if cos < cutoff.cos() {
                    Vec3A::ZERO
                } else {
                    intensity * spot_falloff(cos.clamp(-1.0, 1.0).acos(), cutoff, beam)
                }
            }
            _ => Vec3A::ZERO,
        };
        let pdf = self.pdf_dir(scene, i, y, n, dir);
        let beta = emitted / (p_pick * pdf_pos * pdf);
        if !(beta.max_element() > 0.0 && beta.is_finite()) {
            return None;
        }
        let origin = if n == Vec3A::ZERO { y } else { transport::offset(y, n, dir, transport::epsilon(y)) };
        Some(Emission { ray: super::super::geometry::Ray { origin, dir }, p: y, n, beta, light: i })
    }

    /// The solid-angle density with which `sample_emission`, having picked the area, point or
    /// spot light `i` and drawn its point `y` (normal `n`, zero for a point or spot light),
    /// draws `dir`: the mixture's (module docs).
    pub fn pdf_dir(&self, scene: &Scene, i: usize, y: Vec3A, n: Vec3A, dir: Vec3A) -> f32 {
        let aimed: f32 = self.spheres.iter().map(|&s| cone_pdf(s, y, dir)).sum();
        AIMED * aimed / self.spheres.len() as f32 + (1.0 - AIMED) * scene.emission_pdf(i, n, dir).1
    }
}

/// The cone the sphere `(c, r)` subtends from `y`: its axis and 1 − cos θ of its half-angle
/// (2, the whole sphere of directions, from inside or on it).
fn cone((c, r): (Vec3A, f32), y: Vec3A) -> (Vec3A, f32) {
    sphere_cone(c, r, y).map_or((Vec3A::Z, 2.0), |(axis, _, one_minus)| (axis, one_minus))
}

/// A direction uniform in the cone the sphere subtends from `y`.
fn cone_sample(sphere: (Vec3A, f32), y: Vec3A, u: (f32, f32)) -> Vec3A {
    match cone(sphere, y) {
        (_, 2.0) => uniform_sphere(u),
        (axis, one_minus) => around(axis, 1.0 - u.0 * one_minus, u.1),
    }
}

/// The density of `cone_sample` at `dir`.
fn cone_pdf(sphere: (Vec3A, f32), y: Vec3A, dir: Vec3A) -> f32 {
    let (axis, one_minus) = cone(sphere, y);
    // 1 − cos of the angle to the axis as |axis − dir|²/2, which keeps its precision in
    // narrow cones.
    if one_minus >= 2.0 || 0.5 * (axis - dir).length_squared() <= one_minus {
        1.0 / (2.0 * PI * one_minus)
    } else {
        0.0
    }
}
