//! Light paths, which light tracing and photon mapping share: a ray drawn from a light
//! (`Scene::sample_emission`) with flux weight β, followed from surface to surface as light
//! goes.
//!
//! At each surface point the path reaches, the caller sees the vertex (`walk`'s visitor);
//! then the next direction is drawn by the BSDF from the direction the light came from, w_l,
//! and β takes the adjoint weight f(x, w_next, w_l)·|cos θ_next|/p. The models are reciprocal
//! except across a dielectric, where radiance carries the 1/η² of the change of solid angle
//! and flux does not: a refraction's weight is the camera path's times η² (Veach 1997, §5.2).
//! A one-sided surface reached from behind ends the path (it is black there). Depth counts
//! segments as the path tracer does: the vertex k segments from the light is seen when
//! k + 1 ≤ max_depth (one segment at least joins it to the camera), and Russian roulette
//! starts at the path tracer's depth with its rule.

use super::super::bsdf::Bsdf;
use super::super::film::RR_START;
use super::super::geometry::{Hit, Ray};
use super::super::sampler::Sampler;
use super::super::scene::{Aim, Material, Scene};
use super::super::transport::{self, epsilon};
use glam::Vec3A;

/// A surface point a light path reached.
pub struct Vertex<'a> {
    pub hit: Hit,
    pub p: Vec3A,
    /// The geometric normal (not turned to either side).
    pub n: Vec3A,
    pub mat: &'a Material,
    pub albedo: Vec3A,
    /// Unit direction towards where the light came from.
    pub w_l: Vec3A,
    /// The path's flux weight arriving here, W.
    pub beta: Vec3A,
    /// Segments from the light.
    pub depth: u32,
    /// Whether every bounce before this vertex was a delta one (mirror, glass): light that
    /// reaches a diffuse surface so is a caustic.
    pub specular_chain: bool,
}

/// Draws a light path with `s` and shows `visit` each vertex it reaches (module docs); with
/// `aim`, its first direction is aimed at the scene's delta objects half of the time
/// (`scene::Aim`).
pub fn walk(
    scene: &Scene,
    aim: Option<&Aim>,
    s: &mut Sampler,
    max_depth: u32,
    mut visit: impl FnMut(&Vertex, &mut Sampler),
) {
    if max_depth < 2 {
        return;
    }
    let (u_pick, u_pos, u_dir) = (s.next(), s.next2(), s.next2());
    let e = match aim {
        Some(aim) => aim.sample_emission(scene, u_pick, u_pos, u_dir, s.next()),
        None => scene.sample_emission(u_pick, u_pos, u_dir),
    };
    let Some(e) = e else { return };
    let (mut ray, mut beta) = (e.ray, e.beta);
    let mut specular_chain = true;
    for depth in 1..max_depth {
        let Some(hit) = scene.bvh.intersect(&ray, 0.0, f32::INFINITY) else { break };
        let surf = scene.surface(&ray, &hit);
        let mat = &scene.materials[surf.material as usize];
        let w_l = -ray.dir;
        let front = surf.n.dot(w_l) >= 0.0;
        if !front && mat.one_sided {
            break;
        }
        let albedo = scene.albedo(surf.material, &hit, surf.p);
        let v = Vertex { hit, p: surf.p, n: surf.n, mat, albedo, w_l, beta, depth, specular_chain };
        visit(&v, s);
        if depth + 1 >= max_depth {
            break;
        }
        let bsdf = shading(scene, mat, &hit, surf.p, front);
        let n = if front { surf.n } else { -surf.n };
        let (u1, u2) = s.next2();
        let u3 = if bsdf.needs_third_number() { s.next() } else { 0.0 };
        let Some(sample) = bsdf.sample(albedo, n, w_l, u1, u2, u3) else { break };
        beta *= sample.weight * adjoint(&bsdf, n, sample.wi);
        specular_chain &= sample.delta;
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
        ray = Ray { origin: transport::offset(surf.p, n, sample.wi, epsilon(surf.p)), dir: sample.wi };
    }
}

/// The material's model at a hit, for a path on the front (`true`) or back of the surface:
/// a dielectric seen from inside inverted, a textured roughness applied.
pub fn shading(scene: &Scene, mat: &Material, hit: &Hit, p: Vec3A, front: bool) -> Bsdf {
    let bsdf = mat.bsdf.facing(front);
    match &mat.roughness {
        Some(alpha) => bsdf.with_alpha(alpha.eval(scene.uv(hit, p)).x),
        None => bsdf,
    }
}

/// What turns the camera path's sample weight into the light path's: η² for a refraction
/// through a dielectric of relative index η (module docs), 1 otherwise.
#[inline]
pub fn adjoint(bsdf: &Bsdf, n: Vec3A, wi: Vec3A) -> f32 {
    match *bsdf {
        Bsdf::Dielectric { eta } | Bsdf::RoughDielectric { eta, .. } if n.dot(wi) < 0.0 => eta * eta,
        _ => 1.0,
    }
}
