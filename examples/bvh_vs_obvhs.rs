//! Traversal speed of lumen's BVH, 4- and 8-wide, against obvhs (a BVH crate with a
//! PLOC-built, compressed 8-wide BVH) on the same triangles and the same incoherent rays, one
//! thread: closest hit, and lumen's any-hit (shadow) query.
//!
//! cargo run --release --example bvh_vs_obvhs

use glam::Vec3A;
use lumen::render::bvh::{Bvh, Width};
use lumen::render::geometry::{Prim, Ray};
use lumen::render::sampler::Sampler;
use obvhs::{cwbvh::builder::build_cwbvh_from_tris, ray::RayHit, triangle::Triangle, BvhBuildParams};
use std::time::{Duration, Instant};

fn rays(lo: Vec3A, hi: Vec3A, n: usize) -> Vec<Ray> {
    (0..n)
        .map(|i| {
            let mut s = Sampler::new(9, i as u64, 0);
            let o = lo + (hi - lo) * Vec3A::new(s.next(), s.next(), s.next());
            let z = 1.0 - 2.0 * s.next();
            let phi = 2.0 * std::f32::consts::PI * s.next();
            let r = (1.0 - z * z).max(0.0).sqrt();
            Ray { origin: o, dir: Vec3A::new(r * phi.cos(), r * phi.sin(), z) }
        })
        .collect()
}

/// Best of three timings of `trace` over all rays, and the hit distances of the last.
fn time(rays: &[Ray], trace: impl Fn(&Ray) -> f32) -> (f64, Vec<f32>) {
    let mut best = f64::INFINITY;
    let mut hits = Vec::new();
    for _ in 0..3 {
        let t = Instant::now();
        hits = rays.iter().map(&trace).collect();
        best = best.min(t.elapsed().as_secs_f64());
    }
    (rays.len() as f64 / best / 1e6, hits)
}

/// Fraction of rays on which two traversals report the same hit distance.
fn agreement(a: &[f32], b: &[f32]) -> f64 {
    let same = a
        .iter()
        .zip(b)
        .filter(|(a, b)| {
            a == b || (a.is_finite() && b.is_finite() && (*a - *b).abs() <= 1e-4 * a.abs().max(1.0))
        })
        .count();
    100.0 * same as f64 / a.len() as f64
}

fn closest(bvh: &Bvh, ray: &Ray) -> f32 {
    bvh.intersect(ray, 0.0, f32::INFINITY).map_or(f32::INFINITY, |h| h.t)
}

fn compare(name: &str, tris: &[Triangle]) {
    let prims: Vec<Prim> =
        tris.iter().map(|t| Prim::Triangle { v0: t.v0, e1: t.v1 - t.v0, e2: t.v2 - t.v0 }).collect();
    let t = Instant::now();
    let four = Bvh::build_width(&prims, Width::Four);
    let build_four = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let eight = Bvh::build_width(&prims, Width::Eight);
    let build_eight = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let theirs = build_cwbvh_from_tris(tris, BvhBuildParams::medium_build(), &mut Duration::default());
    let their_tris: Vec<Triangle> = theirs.primitive_indices.iter().map(|&i| tris[i as usize]).collect();
    let build_theirs = t.elapsed().as_secs_f64();

    let (mut lo, mut hi) = (Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY));
    for p in &prims {
        let (a, b) = p.bounds();
        lo = lo.min(a);
        hi = hi.max(b);
    }
    let shrink = (hi - lo) * 0.1;
    let rays = rays(lo + shrink, hi - shrink, 2_000_000);

    let (speed_four, hits_four) = time(&rays, |r| closest(&four, r));
    let (speed_eight, hits_eight) = time(&rays, |r| closest(&eight, r));
    let (speed_theirs, hits_theirs) = time(&rays, |r| {
        let ray = obvhs::ray::Ray::new(r.origin, r.dir, 0.0, f32::INFINITY);
        let mut hit = RayHit::none();
        theirs.ray_traverse(ray, &mut hit, |ray, id| their_tris[id].intersect(ray));
        hit.t
    });
    let (shadow_four, _) = time(&rays, |r| four.occluded(r, 0.0, 0.5) as u8 as f32);
    let (shadow_eight, _) = time(&rays, |r| eight.occluded(r, 0.0, 0.5) as u8 as f32);
    println!("{name}: {} triangles, M rays/s (build s), closest hit; any hit within 0.5", tris.len());
    println!("  lumen 4-wide: {speed_four:.2} ({build_four:.3}); {shadow_four:.2}");
    let label = if eight.width() == Width::Eight { "8-wide" } else { "8-wide (no AVX2: 4-wide)" };
    println!("  lumen {label}: {speed_eight:.2} ({build_eight:.3}); {shadow_eight:.2}");
    println!("  obvhs CWBVH:  {speed_theirs:.2} ({build_theirs:.3})");
    println!(
        "  same hit as obvhs: 4-wide {:.4} %, 8-wide {:.4} %",
        agreement(&hits_four, &hits_theirs),
        agreement(&hits_eight, &hits_theirs)
    );
}

fn main() {
    let scene = lumen::render::load(std::path::Path::new("pipelines/scenes/cornell-box.toml"))
        .expect("run from the project root");
    let cornell: Vec<Triangle> = scene
        .bvh
        .prims
        .iter()
        .filter_map(|p| match *p {
            Prim::Triangle { v0, e1, e2 } => Some(Triangle { v0, v1: v0 + e1, v2: v0 + e2 }),
            _ => None,
        })
        .collect();
    compare("Cornell box", &cornell);
    compare("icosphere (subdivided 6 times)", &obvhs::test_util::geometry::icosphere(6));
}
