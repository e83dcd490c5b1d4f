//! Descriptor matching: exact nearest neighbours by brute force, Lowe's ratio test and a
//! mutual (cross) check, as COLMAP's exhaustive matcher does.
//!
//! RootSIFT descriptors have unit length (before their quantisation to bytes), so the squared
//! distance is ‖a − b‖² = 2 − 2·a·b and nearest neighbours are largest dot products. All
//! dot products of a pair are one matrix product (nalgebra's, through `matrixmultiply`'s
//! SIMD kernels), taken in blocks of rows on all cores: for 8192 × 8192 descriptors that is
//! 1.1·10¹⁰ multiply-adds, far less work than a k-d tree pays in 128 dimensions, where it
//! visits most leaves for exact answers.

use nalgebra::DMatrix;
use rayon::prelude::*;

/// One match: indices into the two descriptor sets and the descriptor distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Match {
    pub a: u32,
    pub b: u32,
    pub distance: f32,
}

/// Matching settings (defaults as COLMAP's).
#[derive(Clone, Copy, Debug)]
pub struct Options {
    /// Largest ratio of the nearest to the second-nearest distance (0.8).
    pub max_ratio: f32,
    /// Largest distance between unit descriptors (0.7).
    pub max_distance: f32,
    /// Keep a match only if each is the other's nearest neighbour (true).
    pub cross_check: bool,
}

impl Default for Options {
    fn default() -> Options {
        Options { max_ratio: 0.8, max_distance: 0.7, cross_check: true }
    }
}

/// Rows of descriptors scaled back to unit length, as a 128 × n matrix (one column each).
fn unit_columns(d: &[[u8; 128]]) -> DMatrix<f32> {
    let mut m = DMatrix::<f32>::zeros(128, d.len());
    for (j, v) in d.iter().enumerate() {
        let norm = v.iter().map(|&x| (x as f32) * (x as f32)).sum::<f32>().sqrt().max(1e-6);
        for (k, &x) in v.iter().enumerate() {
            m[(k, j)] = x as f32 / norm;
        }
    }
    m
}

/// The two largest values (and the index of the largest) seen so far.
#[derive(Clone, Copy)]
struct Best {
    index: u32,
    first: f32,
    second: f32,
}

impl Best {
    const NONE: Best = Best { index: u32::MAX, first: -2.0, second: -2.0 };
}

/// Rows of A per block of the product.
const BLOCK: usize = 512;

/// Matches of `a` against `b` (ascending in `a`).
pub fn match_descriptors(a: &[[u8; 128]], b: &[[u8; 128]], opts: &Options) -> Vec<Match> {
    matches_where(a, b, opts, None::<fn(usize, usize) -> bool>)
}

/// Guided matching: as `match_descriptors`, among only the pairs (i, j) that `allowed` keeps
/// (those near each other's epipolar line once a pair's geometry is known): the nearest,
/// second-nearest and mutual neighbours are taken within them, so a descriptor whose twin
/// lies elsewhere in the image (repeated texture) is no longer ambiguous.
pub fn match_guided(
    a: &[[u8; 128]],
    b: &[[u8; 128]],
    opts: &Options,
    allowed: impl Fn(usize, usize) -> bool + Sync,
) -> Vec<Match> {
    matches_where(a, b, opts, Some(allowed))
}

fn matches_where(
    a: &[[u8; 128]],
    b: &[[u8; 128]],
    opts: &Options,
    allowed: Option<impl Fn(usize, usize) -> bool + Sync>,
) -> Vec<Match> {
    if a.is_empty() || b.is_empty() {
        return Vec::new();
    }
    let (ma, mb) = (unit_columns(a), unit_columns(b));
    let nb = b.len();
    // Per block of A: each row's best two in B, and each column's best in the block.
    let blocks: Vec<(Vec<Best>, Vec<Best>)> = (0..a.len().div_ceil(BLOCK))
        .into_par_iter()
        .map(|k| {
            let start = k * BLOCK;
            let rows = BLOCK.min(a.len() - start);
            // rows × nb, column-major: A's rows as a matrix times B's columns, a plain product
            // that nalgebra hands to matrixmultiply's kernels.
            let a_rows = ma.columns(start, rows).transpose();
            let mut dots = &a_rows * &mb;
            if let Some(allowed) = &allowed {
                // A pair left out is as far as two opposite descriptors.
                for (j, col) in dots.as_mut_slice().chunks_exact_mut(rows).enumerate() {
                    for (i, v) in col.iter_mut().enumerate() {
                        if !allowed(start + i, j) {
                            *v = -2.0;
                        }
                    }
                }
            }
            // Row bests as three arrays updated with selects, which vectorise; each
            // column's best by a scan of its contiguous values.
            let (mut first, mut second) = (vec![-2f32; rows], vec![-2f32; rows]);
            let mut index = vec![u32::MAX; rows];
            let mut col_best = vec![Best::NONE; nb];
            for (j, cb) in col_best.iter_mut().enumerate() {
                let col = &dots.as_slice()[j * rows..(j + 1) * rows];
                let ju = j as u32;
                for (((&v, f), s), ix) in
                    col.iter().zip(first.iter_mut()).zip(second.iter_mut()).zip(index.iter_mut())
                {
                    let above = v > *f;
                    *s = if above { *f } else { s.max(v) };
                    *ix = if above { ju } else { *ix };
                    *f = if above { v } else { *f };
                }
                let (mut bi, mut bv) = (0usize, f32::NEG_INFINITY);
                for (i, &v) in col.iter().enumerate() {
                    if v > bv {
                        bv = v;
                        bi = i;
                    }
                }
                *cb = Best { index: (start + bi) as u32, first: bv, second: -2.0 };
            }
            let row_best: Vec<Best> =
                (0..rows).map(|i| Best { index: index[i], first: first[i], second: second[i] }).collect();
            (row_best, col_best)
        })
        .collect();
    // Each column's best over all blocks (only its index is needed, for the mutual check).
    let mut col_best = vec![Best::NONE; nb];
    for (_, cb) in &blocks {
        for (c, b) in col_best.iter_mut().zip(cb) {
            if b.first > c.first {
                *c = *b;
            }
        }
    }
    let dist = |dot: f32| (2.0 - 2.0 * dot).max(0.0).sqrt();
    let mut out = Vec::new();
    for (k, (row_best, _)) in blocks.iter().enumerate() {
        for (i, r) in row_best.iter().enumerate() {
            if r.index == u32::MAX {
                continue;
            }
            let ia = (k * BLOCK + i) as u32;
            let (d1, d2) = (dist(r.first), dist(r.second));
            if d1 > opts.max_distance || (nb > 1 && d1 > opts.max_ratio * d2) {
                continue;
            }
            if opts.cross_check && col_best[r.index as usize].index != ia {
                continue;
            }
            out.push(Match { a: ia, b: r.index, distance: d1 });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random_descriptor(seed: u64) -> [u8; 128] {
        let mut d = [0u8; 128];
        let mut s = seed;
        for v in d.iter_mut() {
            s = crate::render::sampler::mix64(s);
            *v = (s >> 58) as u8 * 4;
        }
        d
    }

    /// Brute force over shuffled copies with a little noise: every descriptor finds its copy,
    /// and the result equals a plain double loop's.
    #[test]
    fn finds_copies_and_agrees_with_a_double_loop() {
        let n = 1300; // more than two blocks
        let a: Vec<[u8; 128]> = (0..n).map(|i| random_descriptor(i as u64 + 7)).collect();
        let perm: Vec<usize> = (0..n).map(|i| (i * 677) % n).collect();
        let b: Vec<[u8; 128]> = perm
            .iter()
            .map(|&i| {
                let mut d = a[i];
                d[(i * 13) % 128] = d[(i * 13) % 128].saturating_add(3);
                d
            })
            .collect();
        let m = match_descriptors(&a, &b, &Options { max_distance: 2.0, ..Options::default() });
        assert_eq!(m.len(), n);
        for x in &m {
            assert_eq!(perm[x.b as usize], x.a as usize);
        }
        // A double loop over the same unit vectors.
        let (ma, mb) = (unit_columns(&a), unit_columns(&b));
        for x in m.iter().step_by(97) {
            let best = (0..n)
                .max_by(|&p, &q| {
                    ma.column(x.a as usize)
                        .dot(&mb.column(p))
                        .total_cmp(&ma.column(x.a as usize).dot(&mb.column(q)))
                })
                .unwrap();
            assert_eq!(best as u32, x.b);
        }
    }

    /// Repeated texture: every descriptor of `a` has two near twins in `b`, so the ratio test
    /// refuses every match; guided to one twin each (as an epipolar band would), every
    /// descriptor finds it, and no match leaves the allowed pairs.
    #[test]
    fn guidance_resolves_twins_and_keeps_within_the_allowed_pairs() {
        let n = 600;
        let a: Vec<[u8; 128]> = (0..n).map(|i| random_descriptor(i as u64 + 11)).collect();
        // Each twin differs from its original in one element, by the same amount.
        let twin = |d: &[u8; 128], k: usize| {
            let mut d = *d;
            d[k % 128] = if d[k % 128] >= 8 { d[k % 128] - 8 } else { d[k % 128] + 8 };
            d
        };
        let b: Vec<[u8; 128]> = a
            .iter()
            .enumerate()
            .map(|(i, d)| twin(d, 13 * i))
            .chain(a.iter().enumerate().map(|(i, d)| twin(d, 29 * i + 5)))
            .collect();
        let opts = Options::default();
        assert!(match_descriptors(&a, &b, &opts).is_empty());
        // The twin allowed for a[i]: b[i] for even i, b[i + n] for odd i.
        let allowed = |i: usize, j: usize| j == if i % 2 == 0 { i } else { i + n };
        let m = match_guided(&a, &b, &opts, allowed);
        assert_eq!(m.len(), n);
        assert!(m.iter().all(|x| allowed(x.a as usize, x.b as usize)));
    }
}
