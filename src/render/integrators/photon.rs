//! Photon mapping (Jensen 1996; Jensen 2001, "Realistic Image Synthesis Using Photon
//! Mapping"): two passes.
//!
//! 1. Photons. `count` light paths (`particle::walk`) leave the lights, half of them aimed at
//!    the scene's mirrors and glass (`scene::Aim`, Jensen's projection maps); wherever one meets a
//!    surface that is not a delta one it leaves a photon: the point, the direction the light
//!    came from, its flux β/count and the normal on that side. Russian roulette ends the
//!    paths as it ends camera paths. Every photon goes into the global map; those whose light
//!    came only through delta bounces (mirrors, glass: L S⁺ D) also into the caustic map.
//!    The maps are indexed by kiddo's kd-tree (`render::photons`).
//! 2. Camera paths follow delta bounces to the first other surface x and estimate the radiance
//!    leaving it towards the camera from the photons near x:
//!
//!      L(x, ωo) ≈ Σₚ f(x, ωo, ωₚ)·Φₚ·K(dₚ/r)/r²,  K(t) = (2/π)(1 − t²) (Epanechnikov),
//!
//!    over the photons within r, a fixed `radius`, or else the distance to the `k`-th nearest
//!    (photons on surfaces turned more than 45° from x's are left out: a wall's photons at a
//!    corner, the far side of a thin wall). Emitters and the environment a camera path reaches
//!    before x count as the path tracer counts them.
//!
//! With `final_gather`, x's radiance is split as Jensen splits it: direct light by light
//! sampling, caustics from the caustic map, and the rest by one BSDF-sampled ray to the next
//! surface y (through delta bounces), whose radiance comes from the global map there; the
//! blur of the density estimate then reaches the image only after a diffuse bounce.
//!
//! The estimate is biased (the kernel blurs, by about r) and consistent as photons grow and r
//! shrinks. The film's variance of the mean is that of the camera samples: the photon map is
//! one for every sample, so its noise is not in it.
//!
//! Index: the k nearest photons are found by kiddo's kd-tree (the grid cannot find them). For
//! a fixed radius the default is the hashed grid below 10⁷ photons and the kd-tree above:
//! `lumen bench photons` finds the grid's radius queries faster and its build two to five
//! times faster up to millions of photons, and the kd-tree's queries faster once the grid's
//! table (two buckets per photon) outgrows the caches (docs/measurements.md); `index`
//! chooses either.

use super::super::bsdf::Bsdf;
use super::super::film::{pixel_stats, Film};
use super::super::geometry::Ray;
use super::super::photons::{Index, IndexKind};
use super::super::sampler::Sampler;
use super::super::scene::{Aim, Scene};
use super::super::transport::{self, epsilon};
use super::particle::{shading, walk};
use super::{camera_path, render_rows, Settings};
use glam::Vec3A;
use rayon::prelude::*;
use std::f32::consts::FRAC_2_PI;

/// Keeps photon paths' random streams apart from camera paths' with the same seed.
const STREAM: u64 = 0x7068_6f74_6f6e_7321;
/// Photon paths a worker traces at a time.
const CHUNK: u64 = 4096;
/// Photons up to which a fixed radius is looked up in the grid by default (module docs).
const GRID_UP_TO: usize = 10_000_000;
/// A photon counts where its surface and x's normals are within 45°.
const SAME_SURFACE: f32 = std::f32::consts::FRAC_1_SQRT_2;

/// A photon (module docs).
#[derive(Clone, Copy, Debug)]
pub struct Photon {
    pub p: Vec3A,
    /// Unit direction towards where its light came from.
    pub w_l: Vec3A,
    /// Flux, W.
    pub power: Vec3A,
    /// The surface normal on the side the light arrived on.
    pub n: Vec3A,
}

/// Photons and their index.
pub struct PhotonMap {
    photons: Vec<Photon>,
    index: Option<Index>,
}

impl PhotonMap {
    pub fn new(photons: Vec<Photon>, kind: Option<IndexKind>, radius: Option<f32>) -> PhotonMap {
        let points: Vec<[f32; 3]> = photons.iter().map(|p| p.p.to_array()).collect();
        // The k nearest need the kd-tree; a fixed radius takes the faster one (module docs).
        let kind = match (radius, kind) {
            (None, _) => IndexKind::Kdtree,
            (Some(_), Some(kind)) => kind,
            (Some(_), None) if points.len() < GRID_UP_TO => IndexKind::Grid,
            (Some(_), None) => IndexKind::Kdtree,
        };
        let index = Index::build(kind, &points, radius.unwrap_or(1.0));
        PhotonMap { photons, index }
    }

    pub fn len(&self) -> usize {
        self.photons.len()
    }

    pub fn is_empty(&self) -> bool {
        self.photons.is_empty()
    }

    /// The density estimate of the radiance leaving `x` towards `wo` (module docs); `n` is
    /// the normal on wo's side.
    #[allow(clippy::too_many_arguments)]
    pub fn radiance(
        &self,
        bsdf: &Bsdf,
        albedo: Vec3A,
        x: Vec3A,
        n: Vec3A,
        wo: Vec3A,
        radius: Option<f32>,
        k: u32,
        max_radius: f32,
    ) -> Vec3A {
        let Some(index) = &self.index else { return Vec3A::ZERO };
        let mut sum = Vec3A::ZERO;
        let mut add = |i: u32, d2: f32, r2: f32| {
            let ph = &self.photons[i as usize];
            if ph.n.dot(n).abs() >= SAME_SURFACE {
                sum += bsdf.eval(albedo, n, wo, ph.w_l) * ph.power * (1.0 - d2 / r2);
            }
        };
        let r2 = match radius {
            Some(r) => {
                let r2 = r * r;
                index.within(x, r, |i, d2| add(i, d2, r2));
                r2
            }
            None => {
                let near = index.nearest(x, k as usize, max_radius);
                let Some(&(_, r2)) = near.last() else { return Vec3A::ZERO };
                if !(r2 > 0.0) {
                    return Vec3A::ZERO;
                }
                for (i, d2) in near {
                    add(i, d2, r2);
                }
                r2
            }
        };
        sum * (FRAC_2_PI / r2)
    }
}

/// The photon pass: `count` photon paths, as (global map's photons, caustic map's), in path
/// order whatever the thread count.
pub fn trace_photons(
    scene: &Scene,
    settings: &Settings,
    count: u64,
    pass: u64,
) -> (Vec<Photon>, Vec<Photon>) {
    let aim = Aim::of(scene);
    let chunks: Vec<(Vec<Photon>, Vec<Photon>)> = (0..count)
        .step_by(CHUNK as usize)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|c| {
            let (mut global, mut caustic) = (Vec::new(), Vec::new());
            for path in c..(c + CHUNK).min(count) {
                let mut s = Sampler::with_kind(settings.sampler, settings.seed ^ STREAM, path, pass);
                walk(scene, aim.as_ref(), &mut s, settings.max_depth, |v, _| {
                    if v.mat.bsdf.is_delta() {
                        return;
                    }
                    let n = if v.n.dot(v.w_l) >= 0.0 { v.n } else { -v.n };
                    let ph = Photon { p: v.p, w_l: v.w_l, power: v.beta / count as f32, n };
                    if v.specular_chain && v.depth >= 2 {
                        caustic.push(ph);
                    }
                    global.push(ph);
                });
            }
            (global, caustic)
        })
        .collect();
    let (mut global, mut caustic) = (Vec::new(), Vec::new());
    for (g, c) in chunks {
        global.extend(g);
        caustic.extend(c);
    }
    (global, caustic)
}

struct Maps {
    global: PhotonMap,
    caustic: Option<PhotonMap>,
}

pub fn render(scene: &Scene, settings: &Settings, film: &mut Film) {
    let ps = &settings.photon;
    let count = ps.count.unwrap_or(16 * scene.camera.width as u64 * scene.camera.height as u64);
    let (global, caustic) = trace_photons(scene, settings, count, 0);
    let maps = Maps {
        global: PhotonMap::new(global, ps.index, ps.radius),
        caustic: ps.final_gather.then(|| PhotonMap::new(caustic, ps.index, ps.radius)),
    };
    render_rows(settings, film, |y, x0, x1| {
        (x0..x1)
            .map(|x| {
                pixel_stats((0..settings.spp).map(|k| {
                    let (mut s, ray) = camera_path(scene, settings, x, y, k);
                    ray.map_or(Vec3A::ZERO, |ray| radiance(scene, settings, &maps, ray, &mut s))
                }))
            })
            .collect()
    });
}

/// Radiance along a camera ray (module docs).
fn radiance(scene: &Scene, settings: &Settings, maps: &Maps, ray: Ray, s: &mut Sampler) -> Vec3A {
    let ps = &settings.photon;
    let mut l = Vec3A::ZERO;
    let Some(x) = first_diffuse(scene, settings.max_depth, ray, s, Some(&mut l)) else { return l };
    let estimate = |map: &PhotonMap| {
        map.radiance(&x.bsdf, x.albedo, x.p, x.n, x.wo, ps.radius, ps.k, scene.bounds_radius)
    };
    match &maps.caustic {
        None => l += x.beta * estimate(&maps.global),
        Some(caustic) => {
            l += x.beta * direct(scene, &x, s);
            l += x.beta * estimate(caustic);
            // One bounce into the global map.
            let (u1, u2) = s.next2();
            let u3 = if x.bsdf.needs_third_number() { s.next() } else { 0.0 };
            if let Some(b) = x.bsdf.sample(x.albedo, x.n, x.wo, u1, u2, u3) {
                let origin = transport::offset(x.p, x.n, b.wi, epsilon(x.p));
                l += x.beta * b.weight * gather(scene, settings, maps, Ray { origin, dir: b.wi }, s);
            }
        }
    }
    l
}

/// The first surface other than a delta one a camera ray reaches through delta bounces
/// (mirrors, glass): where photon mapping estimates radiance.
#[derive(Clone, Copy)]
pub struct Diffuse {
    pub p: Vec3A,
    /// The normal on ωo's side.
    pub n: Vec3A,
    pub wo: Vec3A,
    pub albedo: Vec3A,
    /// The throughput of the delta bounces before it.
    pub beta: Vec3A,
    pub bsdf: Bsdf,
}

/// Follows `ray` through delta bounces to the first other surface, adding to `emitted`
/// (when given) the emitters and environment it meets on the way, that surface's own emission
/// included, as the path tracer counts them; `None` where the path leaves the scene, ends
/// on a one-sided surface's back or runs out of depth.
pub fn first_diffuse(
    scene: &Scene,
    max_depth: u32,
    mut ray: Ray,
    s: &mut Sampler,
    mut emitted: Option<&mut Vec3A>,
) -> Option<Diffuse> {
    let mut beta = Vec3A::ONE;
    for _ in 0..max_depth {
        let Some(hit) = scene.bvh.intersect(&ray, 0.0, f32::INFINITY) else {
            if let (Some(l), Some((le, _))) = (emitted.as_deref_mut(), scene.environment(ray.dir)) {
                *l += beta * le;
            }
            return None;
        };
        let surf = scene.surface(&ray, &hit);
        let mat = &scene.materials[surf.material as usize];
        let wo = -ray.dir;
        let front = surf.n.dot(wo) >= 0.0;
        if let (Some(l), Some(le), true) = (emitted.as_deref_mut(), mat.emission, front) {
            *l += beta * le;
        }
        if !front && mat.one_sided {
            return None;
        }
        let n = if front { surf.n } else { -surf.n };
        let albedo = scene.albedo(surf.material, &hit, surf.p);
        let bsdf = shading(scene, mat, &hit, surf.p, front);
        if !bsdf.is_delta() {
            return Some(Diffuse { p: surf.p, n, wo, albedo, beta, bsdf });
        }
        let (u1, u2) = s.next2();
        let b = bsdf.sample(albedo, n, wo, u1, u2, 0.0)?;
        beta *= b.weight;
        ray = Ray { origin: transport::offset(surf.p, n, b.wi, epsilon(surf.p)), dir: b.wi };
    }
    None
}

/// Direct light at x by one light sample (no emitter a BSDF sample finds is counted with it).
pub fn direct(scene: &Scene, x: &Diffuse, s: &mut Sampler) -> Vec3A {
    let Some((li, wi, dist, _)) = scene.sample_light(s.next2(), x.p) else { return Vec3A::ZERO };
    let cos = x.n.dot(wi);
    if !(cos > 0.0 || (cos < 0.0 && x.bsdf.transmits())) {
        return Vec3A::ZERO;
    }
    let side = if cos > 0.0 { x.n } else { -x.n };
    if !scene.unoccluded(x.p + side * epsilon(x.p), x.p, wi, dist) {
        return Vec3A::ZERO;
    }
    x.bsdf.eval(x.albedo, x.n, x.wo, wi) * cos.abs() * li
}

/// The global map's radiance at the first surface other than a delta one that `ray` reaches
/// through delta bounces; emitters found on the way are left out (light sampling and the
/// caustic map counted them).
fn gather(scene: &Scene, settings: &Settings, maps: &Maps, ray: Ray, s: &mut Sampler) -> Vec3A {
    let ps = &settings.photon;
    first_diffuse(scene, settings.max_depth, ray, s, None).map_or(Vec3A::ZERO, |x| {
        x.beta * maps.global.radiance(&x.bsdf, x.albedo, x.p, x.n, x.wo, ps.radius, ps.k, scene.bounds_radius)
    })
}
