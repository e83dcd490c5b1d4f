//! Volumetric path tracing: the path tracer (`path`) with participating media (`render::media`)
//! between its surfaces, as Mitsuba 3's `volpath`.
//!
//! A path knows the medium it is in: the camera's (`[camera] medium`) at the start, then
//! whatever the shapes it crosses bound (`Scene::medium_after`: a shape's exterior on the side
//! its normal points to, its interior on the other). Along each segment, inside a medium,
//! `Medium::sample_flight` decides whether the path scatters before the next surface; where it
//! does, the vertex is a medium vertex:
//!
//!   L += β · p(θ) · T · Lₑ / p_light,   then a new direction from the phase function p,
//!
//! with T the transmittance of the shadow ray, through every medium it crosses. Surfaces of
//! the `null` material bound media without scattering: paths and shadow rays pass straight
//! through them, and they count no segment (as in Mitsuba). Any other surface stops a shadow
//! ray, as in `path`; light through glass comes by BSDF sampling.
//!
//! Light sampling and phase (or BSDF) sampling are combined by the power heuristic at medium
//! vertices and glossy surfaces, with densities in solid angle from the last real vertex; an
//! emitter reached through null surfaces keeps that vertex's weight. At a
//! Lambertian vertex the light sample alone counts and at a delta one the BSDF sample alone, as
//! in `path`. Transmittance multiplies both strategies alike, so it leaves the weights as
//! they are.
//!
//! Depth as in `path` and Mitsuba: `max_depth` counts segments between real vertices (surface
//! or medium scattering); Russian roulette after 5 of them.

use super::super::bsdf::{Bsdf, Sample};
use super::super::film::{pixel_stats, Film, RR_START};
use super::super::geometry::Ray;
use super::super::media::Flight;
use super::super::sampler::Sampler;
use super::super::scene::Scene;
use super::super::transport::{self, epsilon};
use super::{camera_path, power_heuristic, render_rows, Settings};
use glam::Vec3A;

/// Null surfaces a path or shadow ray may cross in a row before it is given up as stuck
/// (numerically trapped between coincident boundaries).
const MAX_CROSSINGS: u32 = 256;

pub fn render(scene: &Scene, settings: &Settings, film: &mut Film) {
    render_rows(settings, film, |y, x0, x1| (x0..x1).map(|x| render_pixel(scene, settings, x, y)).collect());
}

fn render_pixel(scene: &Scene, settings: &Settings, x: u32, y: u32) -> ([f32; 3], [f32; 3], u64) {
    pixel_stats((0..settings.spp).map(|k| {
        let (mut s, ray) = camera_path(scene, settings, x, y, k);
        ray.map_or(Vec3A::ZERO, |ray| trace(scene, ray, settings.max_depth, &mut s))
    }))
}

/// Is the material of primitive `prim` the null interface?
fn is_null(scene: &Scene, prim: u32) -> bool {
    matches!(scene.materials[scene.info[prim as usize].material as usize].bsdf, Bsdf::Null)
}

/// The fraction of light that reaches `origin` from the light point `p + wi·dist` (or from
/// direction `wi`, for an infinite `dist`), leaving `origin` in `medium`: the product of the
/// media's transmittances over the way, 0 where a surface other than a null one is in it.
fn transmittance(
    scene: &Scene,
    s: &mut Sampler,
    mut origin: Vec3A,
    p: Vec3A,
    wi: Vec3A,
    dist: f32,
    mut medium: Option<u32>,
) -> Vec3A {
    let mut tr = Vec3A::ONE;
    for _ in 0..MAX_CROSSINGS {
        let (dir, t_max) = if dist.is_finite() {
            let (dir, t_max, has_length) = transport::shadow_segment(origin, p, wi, dist);
            if !has_length {
                return tr;
            }
            (dir, t_max)
        } else {
            (wi, f32::INFINITY)
        };
        let ray = Ray { origin, dir };
        let hit = scene.bvh.intersect(&ray, 0.0, t_max);
        if let Some(m) = medium {
            tr *= scene.media[m as usize].transmittance(&ray, hit.map_or(t_max, |h| h.t), s);
        }
        let Some(hit) = hit else { return tr };
        if !is_null(scene, hit.prim) || tr == Vec3A::ZERO {
            return Vec3A::ZERO;
        }
        let surf = scene.surface(&ray, &hit);
        medium = scene.medium_after(hit.prim, surf.n, dir, medium);
        origin = transport::offset(surf.p, surf.n, dir, epsilon(surf.p));
    }
    Vec3A::ZERO
}

/// Radiance along a camera ray.
pub fn trace(scene: &Scene, mut ray: Ray, max_depth: u32, s: &mut Sampler) -> Vec3A {
    let mut beta = Vec3A::ONE;
    // The channels' relative densities of the path's flights, and the hero channel that draws
    // them (`render::media`).
    let mut r = Vec3A::ONE;
    let hero = ((s.next() * 3.0) as usize).min(2);
    let mut l = Vec3A::ZERO;
    let mut medium = scene.camera_medium;
    // Real vertices so far: the current ray is segment `depth + 1`.
    let mut depth = 0u32;
    // Where the current ray's light would be sampled from: its last real vertex.
    let mut last = ray.origin;
    // The solid-angle density of the phase or BSDF sample that made the ray, when emission it
    // reaches is weighted against light sampling; infinite after a delta vertex (counted in
    // full); `None` after a Lambertian one (not counted).
    let mut mis_pdf: Option<f32> = Some(f32::INFINITY);
    let mut crossings = 0;
    loop {
        let hit = scene.bvh.intersect(&ray, 0.0, f32::INFINITY);
        let t_max = hit.map_or(f32::INFINITY, |h| h.t);
        if let Some(m) = medium {
            let m = &scene.media[m as usize];
            match m.sample_flight(&ray, t_max, hero, s, &mut beta, &mut r) {
                Flight::Absorbed => break,
                Flight::Through => {}
                Flight::Scatter(t) => {
                    depth += 1;
                    if depth >= max_depth {
                        break;
                    }
                    let p = ray.origin + ray.dir * t;
                    let u_light = s.next2();
                    if let Some((li, wi, dist, p_light)) = scene.sample_light(u_light, p) {
                        let tr = transmittance(scene, s, p, p, wi, dist, medium);
                        if tr != Vec3A::ZERO {
                            let f = m.phase.eval(ray.dir, wi);
                            let w = p_light.map_or(1.0, |pl| power_heuristic(pl, f));
                            l += beta * tr * li * (f * w);
                        }
                    }
                    let (u1, u2) = s.next2();
                    let wi = m.phase.sample(ray.dir, u1, u2);
                    mis_pdf = Some(m.phase.eval(ray.dir, wi));
                    last = p;
                    crossings = 0;
                    if depth >= RR_START {
                        let (killed, survivor) = transport::roulette(beta, s.next());
                        if killed {
                            break;
                        }
                        beta = survivor;
                    }
                    ray = Ray { origin: p, dir: wi };
                    continue;
                }
            }
        }
        let Some(hit) = hit else {
            // Leaving the scene: the environment, counted as emission is.
            if let (Some(p_bsdf), Some((le, p_light))) = (mis_pdf, scene.environment(ray.dir)) {
                l += beta * le * power_heuristic(p_bsdf, p_light);
            }
            break;
        };
        let surf = scene.surface(&ray, &hit);
        let mat = &scene.materials[surf.material as usize];
        let wo = -ray.dir;
        if let (Some(le), Some(p_bsdf)) = (mat.emission, mis_pdf) {
            if surf.n.dot(wo) > 0.0 {
                let p_light = scene.area_light_pdf(hit.prim, last, surf.p, surf.n);
                l += beta * le * power_heuristic(p_bsdf, p_light);
            }
        }
        if let Bsdf::Null = mat.bsdf {
            crossings += 1;
            if crossings > MAX_CROSSINGS {
                break;
            }
            medium = scene.medium_after(hit.prim, surf.n, ray.dir, medium);
            ray.origin = transport::offset(surf.p, surf.n, ray.dir, epsilon(surf.p));
            continue;
        }
        depth += 1;
        if depth >= max_depth {
            break;
        }
        let front = surf.n.dot(wo) >= 0.0;
        if !front && mat.one_sided {
            break;
        }
        let n = if front { surf.n } else { -surf.n };
        let albedo = scene.albedo(surf.material, &hit, surf.p);
        let eps = epsilon(surf.p);
        let bsdf = match (&mat.bsdf, &mat.roughness) {
            (_, Some(alpha)) => mat.bsdf.facing(front).with_alpha(alpha.eval(scene.uv(&hit, surf.p)).x),
            (b, None) => b.facing(front),
        };
        let delta = bsdf.is_delta();
        let glossy = bsdf.is_glossy();
        let u_light = s.next2();
        if !delta {
            if let Some((li, wi, dist, p_light)) = scene.sample_light(u_light, surf.p) {
                // Through the surface only for a model that transmits (`path`'s rule).
                let cos = n.dot(wi);
                if cos > 0.0 || (cos < 0.0 && bsdf.transmits()) {
                    let side = if cos > 0.0 { n } else { -n };
                    let towards = scene.medium_after(hit.prim, surf.n, wi, medium);
                    let tr = transmittance(scene, s, surf.p + side * eps, surf.p, wi, dist, towards);
                    if tr != Vec3A::ZERO {
                        let w = match p_light {
                            Some(p) if glossy => power_heuristic(p, bsdf.pdf(albedo, n, wo, wi)),
                            _ => 1.0,
                        };
                        l += beta * tr * bsdf.eval(albedo, n, wo, wi) * (cos.abs() * w) * li;
                    }
                }
            }
        }
        let (u1, u2) = s.next2();
        let u3 = if bsdf.needs_third_number() { s.next() } else { 0.0 };
        let Some(Sample { wi, weight, delta: delta_lobe }) = bsdf.sample(albedo, n, wo, u1, u2, u3) else {
            break;
        };
        mis_pdf = if delta_lobe { Some(f32::INFINITY) } else { glossy.then(|| bsdf.pdf(albedo, n, wo, wi)) };
        last = surf.p;
        crossings = 0;
        beta *= weight;
        if depth >= RR_START {
            let (killed, survivor) = transport::roulette(beta, s.next());
            if killed {
                break;
            }
            beta = survivor;
        }
        if beta == Vec3A::ZERO {
            break;
        }
        // A refracted or reflected path goes on in the medium on the side it leaves to.
        medium = scene.medium_after(hit.prim, surf.n, wi, medium);
        ray = Ray { origin: transport::offset(surf.p, n, wi, eps), dir: wi };
    }
    l
}
