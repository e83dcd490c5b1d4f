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
//! emitter or environment the scattered ray reaches counts in full. Surfaces are two-sided
//! unless their material is one-sided (black from behind, as Mitsuba's BSDFs without `twosided`);
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
//! lights (the Cornell box among them) are traced eight paths at a time (`lanes`), with
//! exactly this loop's numbers.

mod lanes;

pub use lanes::supported as lanes_supported;

use super::super::bsdf::{Bsdf, Sample};
use super::super::film::{pixel_stats, Film, RR_START};
use super::super::geometry::Ray;
use super::super::sampler::Sampler;
use super::super::scene::Scene;
use super::super::transport::{self, epsilon};
use super::Settings;
use super::{camera_path, power_heuristic, render_rows};
use glam::Vec3A;

/// Renders with `lanes` where the scene and processor allow it and `settings.lanes` is set,
/// one path at a time otherwise (the same image).
pub fn render(scene: &Scene, settings: &Settings, film: &mut Film) {
    let tracer = if settings.lanes { lanes::Tracer::new(scene, settings) } else { None };
    render_rows(settings, film, |y, x0, x1| match &tracer {
        Some(lanes) => lanes.render_row(settings, y, x0, x1),
        None => (x0..x1).map(|x| render_pixel(scene, settings, x, y)).collect(),
    });
}

/// Mean and variance of the mean of one pixel, and the number of non-finite samples dropped.
fn render_pixel(scene: &Scene, settings: &Settings, x: u32, y: u32) -> ([f32; 3], [f32; 3], u64) {
    pixel_stats((0..settings.spp).map(|k| {
        let (mut s, ray) = camera_path(scene, settings, x, y, k);
        ray.map_or(Vec3A::ZERO, |ray| trace(scene, ray, settings.max_depth, &mut s))
    }))
}

/// Radiance along a camera ray.
pub fn trace(scene: &Scene, mut ray: Ray, max_depth: u32, s: &mut Sampler) -> Vec3A {
    let mut beta = Vec3A::ONE;
    let mut l = Vec3A::ZERO;
    // The solid-angle density of the BSDF sample that made `ray`, when its vertex was
    // glossy (module docs).
    let mut mis_pdf: Option<f32> = None;
    // A half-open range: `1..=max_depth` costs a check per vertex.
    for depth in 1..max_depth.saturating_add(1) {
        let Some(hit) = scene.bvh.intersect(&ray, 0.0, f32::INFINITY) else {
            // Leaving the scene: the environment, counted as emission is (module docs).
            if depth == 1 || mis_pdf.is_some() {
                if let Some((le, p_light)) = scene.environment(ray.dir) {
                    l += beta * le * mis_pdf.map_or(1.0, |p_bsdf| power_heuristic(p_bsdf, p_light));
                }
            }
            break;
        };
        let surf = scene.surface(&ray, &hit);
        let mat = &scene.materials[surf.material as usize];
        let wo = -ray.dir;
        if let Some(le) = mat.emission {
            if surf.n.dot(wo) > 0.0 {
                if depth == 1 {
                    l += beta * le;
                } else if let Some(p_bsdf) = mis_pdf {
                    let p_light = scene.area_light_pdf(hit.prim, ray.origin, surf.p, surf.n);
                    l += beta * le * power_heuristic(p_bsdf, p_light);
                }
            }
        }
        if depth == max_depth {
            break;
        }
        // Two-sided surfaces: shade with the normal on the side the path arrived from; a
        // one-sided one is black from behind, and the path ends there.
        let front = surf.n.dot(wo) >= 0.0;
        if !front && mat.one_sided {
            break;
        }
        let n = if front { surf.n } else { -surf.n };
        let albedo = scene.albedo(surf.material, &hit, surf.p);
        let eps = epsilon(surf.p);
        // The material's model by reference: a copy of the enum per vertex is measurable.
        let changed;
        let bsdf = match (&mat.bsdf, &mat.roughness) {
            (_, Some(alpha)) => {
                changed = mat.bsdf.facing(front).with_alpha(alpha.eval(scene.uv(&hit, surf.p)).x);
                &changed
            }
            (Bsdf::Dielectric { .. } | Bsdf::RoughDielectric { .. }, None) if !front => {
                changed = mat.bsdf.facing(front);
                &changed
            }
            (b, None) => b,
        };

        let delta = bsdf.is_delta();
        let glossy = bsdf.is_glossy();
        let u_light = s.next2();
        if !delta {
            if let Some((li, wi, dist, p_light)) = scene.sample_light(u_light, surf.p) {
                // Light through the surface counts only for a model that transmits; the shadow
                // ray then leaves from the far side.
                let cos = n.dot(wi);
                let side = if cos > 0.0 { n } else { -n };
                if (cos > 0.0 || (cos < 0.0 && bsdf.transmits()))
                    && scene.unoccluded(surf.p + side * eps, surf.p, wi, dist)
                {
                    let w = match p_light {
                        Some(p) if glossy => power_heuristic(p, bsdf.pdf(albedo, n, wo, wi)),
                        _ => 1.0,
                    };
                    l += beta * bsdf.eval(albedo, n, wo, wi) * (cos.abs() * w) * li;
                }
            }
        }

        let (u1, u2) = s.next2();
        let u3 = if bsdf.needs_third_number() { s.next() } else { 0.0 };
        let Some(Sample { wi, weight, delta: delta_lobe }) = bsdf.sample(albedo, n, wo, u1, u2, u3) else {
            break;
        };
        // After a delta vertex the emitter the ray reaches counts in full (weight 1).
        mis_pdf = if delta_lobe { Some(f32::INFINITY) } else { glossy.then(|| bsdf.pdf(albedo, n, wo, wi)) };
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
        ray = Ray { origin: transport::offset(surf.p, n, wi, eps), dir: wi };
    }
    l
}
