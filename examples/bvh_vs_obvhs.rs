//! Traversal speed of lumen's BVH against obvhs (a BVH crate with a PLOC-built, compressed
//! 8-wide BVH) on the same triangles and the same incoherent rays, one thread, closest hit.
//!
//! cargo run --release --example bvh_vs_obvhs

use glam::Vec3A;
use lumen::render::bvh::Bvh;
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

fn compare(name: &str, tris: &[Triangle]) {
    let prims: Vec<Prim> =
        tris.iter().map(|t| Prim::Triangle { v0: t.v0, e1: t.v1 - t.v0, e2: t.v2 - t.v0 }).collect();
    let t = Instant::now();
    let ours = Bvh::build(&prims);
    let build_ours = t.elapsed().as_secs_f64();
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

    let mut best_ours = f64::INFINITY;
    let mut best_theirs = f64::INFINITY;
    let mut hits_ours = Vec::new();
    let mut hits_theirs = Vec::new();
    for _ in 0..3 {
        let t = Instant::now();
        hits_ours = rays
            .iter()
            .map(|r| ours.intersect(r, 0.0, f32::INFINITY).map_or(f32::INFINITY, |h| h.t))
            .collect();
        best_ours = best_ours.min(t.elapsed().as_secs_f64());
        let t = Instant::now();
        hits_theirs = rays
            .iter()
            .map(|r| {
                let ray = obvhs::ray::Ray::new(r.origin, r.dir, 0.0, f32::INFINITY);
                let mut hit = RayHit::none();
                theirs.ray_traverse(ray, &mut hit, |ray, id| their_tris[id].intersect(ray));
                hit.t
            })
            .collect();
        best_theirs = best_theirs.min(t.elapsed().as_secs_f64());
    }
    let agree = hits_ours
        .iter()
        .zip(&hits_theirs)
        .filter(|(a, b)| {
            a == b || (a.is_finite() && b.is_finite() && (*a - *b).abs() <= 1e-4 * a.abs().max(1.0))
        })
        .count();
    let n = rays.len() as f64;
    println!(
        "{name}: {} triangles; lumen 4-wide SAH: {:.2} M rays/s (build {:.3} s); obvhs CWBVH: {:.2} M rays/s (build {:.3} s); same hit for {:.4} % of rays",
        tris.len(),
        n / best_ours / 1e6,
        build_ours,
        n / best_theirs / 1e6,
        build_theirs,
        100.0 * agree as f64 / n
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
