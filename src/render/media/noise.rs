//! A procedural density for clouds and smoke: fractal value noise over the unit cube.
//!
//! `octaves` layers of random values on lattices of `cells`, 2·`cells`, 4·`cells` … nodes
//! across, each half the amplitude of the one before, smoothly interpolated (3t² − 2t³) and
//! normalised to [0, 1); then the part above `threshold` is stretched back to [0, 1],
//! ρ = max(0, (n − threshold)/(1 − threshold)), so that clear air lies between puffs.
//!
//! The noise is evaluated into a voxel grid of `resolution`³ cells (`Grid::from_values`), so
//! that a procedural medium is tracked exactly as a `.vol` one is (trilinear between cell
//! centres, one majorant) and can be written out as one. A finer grid follows the noise more
//! closely; the finest octave's lattice should stay coarser than the grid.

use super::grid::Grid;
use crate::render::sampler::mix64;
use rayon::prelude::*;

/// Cells per side of the grid a noise density is evaluated into, at most.
pub const MAX_RESOLUTION: u32 = 512;

/// The density grid of a noise (module docs).
pub fn density_grid(seed: u64, octaves: u32, cells: u32, threshold: f32, resolution: u32) -> Grid {
    let n = resolution as usize;
    let smooth = |t: f32| t * t * (3.0 - 2.0 * t);
    let mut sum = vec![0.0f32; n * n * n];
    let mut total = 0.0f32;
    for o in 0..octaves {
        let lattice = (cells as u64) << o;
        let amplitude = 0.5f32.powi(o as i32);
        total += amplitude;
        let node = |i: u64, j: u64, k: u64| {
            let h = mix64(seed ^ mix64((o as u64) << 60 ^ i << 40 ^ j << 20 ^ k));
            (h >> 40) as f32 / (1u64 << 24) as f32
        };
        let coord = |x: usize| {
            let f = (x as f32 + 0.5) / n as f32 * lattice as f32;
            (f.floor() as u64, smooth(f.fract()))
        };
        // One z-slice per task: a 512³ grid is 1.3·10⁸ voxels per octave.
        sum.par_chunks_mut(n * n).enumerate().for_each(|(z, slice)| {
            let (k, tz) = coord(z);
            for y in 0..n {
                let (j, ty) = coord(y);
                for x in 0..n {
                    let (i, tx) = coord(x);
                    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
                    let plane = |k: u64| {
                        let row = |j: u64| lerp(node(i, j, k), node(i + 1, j, k), tx);
                        lerp(row(j), row(j + 1), ty)
                    };
                    slice[y * n + x] += amplitude * lerp(plane(k), plane(k + 1), tz);
                }
            }
        });
    }
    let data = sum.iter().map(|v| ((v / total - threshold) / (1.0 - threshold)).max(0.0)).collect();
    Grid::from_values([n, n, n], 1, data)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Densities in [0, 1], the same for the same seed and different for another, and with a
    /// threshold a share of clear air that grows with it.
    #[test]
    fn noise_density_is_bounded_deterministic_and_thresholded() {
        let a = density_grid(7, 4, 4, 0.0, 24);
        let b = density_grid(7, 4, 4, 0.0, 24);
        let c = density_grid(8, 4, 4, 0.0, 24);
        let values = |g: &Grid| {
            let mut v = Vec::new();
            for z in 0..24 {
                for y in 0..24 {
                    for x in 0..24 {
                        let p = glam::Vec3A::new(x as f32 + 0.5, y as f32 + 0.5, z as f32 + 0.5) / 24.0;
                        v.push(g.eval(p).x);
                    }
                }
            }
            v
        };
        let (va, vb, vc) = (values(&a), values(&b), values(&c));
        assert!(va.iter().all(|v| (0.0..1.0).contains(v)) && a.max < 1.0 && a.max > 0.5);
        assert_eq!(va, vb);
        assert!(va.iter().zip(&vc).filter(|(x, y)| x != y).count() > va.len() / 2);
        let clear = |t: f32| {
            let g = density_grid(7, 4, 4, t, 24);
            values(&g).iter().filter(|v| **v == 0.0).count() as f64 / va.len() as f64
        };
        let (c0, c4, c6) = (clear(0.0), clear(0.4), clear(0.6));
        assert!(c0 < 0.01 && c4 > 0.1 && c6 > c4 && c6 < 1.0, "clear shares {c0} {c4} {c6}");
    }
}
