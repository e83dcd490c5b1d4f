//! Exact nearest-neighbour matching of SIFT descriptors by brute force (`lumen::sfm::matching`,
//! one matrix product per pair) against kiddo's k-d tree (`ImmutableKdTree<f32, 128>`, the
//! two nearest per query for Lowe's ratio, the nearest back for the mutual check), on the
//! first two Herz-Jesu-P8 photographs (8192 descriptors each), both on all cores, in turn.
//!
//! Run from the repository: `cargo run --release --manifest-path tools/match-kdtree/Cargo.toml
//! [../shared/data/sfm/herz-jesu-p8/images]`. A separate crate, so that kiddo is not a
//! dependency of lumen.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use lumen::image::filter::Grey;
use lumen::sfm::{features, matching};
use rayon::prelude::*;
use std::num::NonZero;
use std::time::Instant;

fn main() {
    let dir = std::env::args().nth(1).unwrap_or_else(|| "../shared/data/sfm/herz-jesu-p8/images".into());
    let dir = std::path::Path::new(&dir);
    let f: Vec<features::Features> = (0..2)
        .map(|k| {
            let img = lumen::image::io::read(&dir.join(format!("{k:04}.jpg"))).unwrap();
            features::detect(&Grey::from_image(&img), &features::Options::default())
        })
        .collect();
    let (a, b) = (&f[0].descriptors, &f[1].descriptors);
    println!("{} x {} descriptors", a.len(), b.len());
    let opts = matching::Options::default();
    let as_f32 = |d: &Vec<[u8; 128]>| -> Vec<[f32; 128]> {
        d.iter().map(|x| std::array::from_fn(|i| x[i] as f32 / 512.0)).collect()
    };
    for round in 0..3 {
        let t = Instant::now();
        let brute = matching::match_descriptors(a, b, &opts);
        let tb = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let (fa, fb) = (as_f32(a), as_f32(b));
        let tree_b: ImmutableKdTree<f32, 128> = ImmutableKdTree::new_from_slice(&fb);
        let tree_a: ImmutableKdTree<f32, 128> = ImmutableKdTree::new_from_slice(&fa);
        let t_build = t.elapsed().as_secs_f64();
        let two = NonZero::new(2).unwrap();
        let fwd: Vec<Option<(u32, f32)>> = fa
            .par_iter()
            .map(|q| {
                let n = tree_b.nearest_n::<SquaredEuclidean>(q, two);
                let (d1, d2) = (n[0].distance.sqrt(), n.get(1).map_or(f32::INFINITY, |x| x.distance.sqrt()));
                (d1 <= opts.max_distance && d1 <= opts.max_ratio * d2).then_some((n[0].item as u32, d1))
            })
            .collect();
        let back: Vec<u32> = fb.par_iter().map(|q| tree_a.nearest_one::<SquaredEuclidean>(q).item as u32).collect();
        let kd: Vec<(u32, u32)> = fwd
            .iter()
            .enumerate()
            .filter_map(|(i, m)| m.filter(|(j, _)| back[*j as usize] == i as u32).map(|(j, _)| (i as u32, j)))
            .collect();
        let tk = t.elapsed().as_secs_f64();
        let bset: std::collections::BTreeSet<(u32, u32)> = brute.iter().map(|m| (m.a, m.b)).collect();
        let kset: std::collections::BTreeSet<(u32, u32)> = kd.iter().copied().collect();
        println!(
            "round {round}: brute force {tb:.3} s, {} matches; kiddo {tk:.3} s (trees {t_build:.3} s), {} matches, {} in common",
            bset.len(),
            kset.len(),
            bset.intersection(&kset).count()
        );
    }
}
