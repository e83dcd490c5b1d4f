//! Points found by position: the photons of photon mapping and the visible points of
//! progressive photon mapping, indexed by a kd-tree (kiddo's `ImmutableKdTree`, built once
//! over the points, the crate lumen uses for its point sets) or by a hashed uniform grid
//! (pbrt-v4's for SPPM: cells of the query radius, each point in the cell holding it, hashed
//! into a table twice as long as the points are many).
//!
//! Both answer "every point within r of q" (the grid's cells are the radius it was built
//! for, so it serves queries of at most that radius); only the kd-tree answers "the k
//! nearest". `lumen bench photons` times both, and a brute-force scan, on the same points;
//! which one an integrator uses by default, and why, is in its module docs.

use glam::Vec3A;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use std::num::NonZeroUsize;

/// Which index finds points.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum IndexKind {
    /// kiddo's kd-tree (the default).
    #[default]
    Kdtree,
    /// A hashed grid of cells the size of the query radius.
    Grid,
}

impl std::str::FromStr for IndexKind {
    type Err = crate::error::Invalid;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "kdtree" => Ok(IndexKind::Kdtree),
            "grid" => Ok(IndexKind::Grid),
            _ => Err(format!("`{s}`: expected kdtree or grid").into()),
        }
    }
}

/// An index over a set of points.
pub enum Index {
    KdTree(ImmutableKdTree<f32, 3>),
    Grid(Grid),
}

impl Index {
    /// Indexes `points`; the grid's cells are `radius` wide (the largest radius it will be
    /// asked for). `None` for more than 2³² − 1 points.
    pub fn build(kind: IndexKind, points: &[[f32; 3]], radius: f32) -> Option<Index> {
        if points.len() >= u32::MAX as usize {
            return None;
        }
        Some(match kind {
            IndexKind::Kdtree => Index::KdTree(ImmutableKdTree::new_from_slice(points).ok()?),
            IndexKind::Grid => Index::Grid(Grid::new(points, radius)),
        })
    }

    /// Calls `visit(i, d²)` for every point i within `radius` of `q` (at most the grid's
    /// radius), in no particular order.
    #[inline]
    pub fn within(&self, q: Vec3A, radius: f32, mut visit: impl FnMut(u32, f32)) {
        match self {
            Index::KdTree(tree) => {
                for r in tree
                    .query(&q.to_array())
                    .within::<SquaredEuclidean<f32>>(radius * radius)
                    .unsorted()
                    .execute()
                {
                    visit(r.item, r.distance);
                }
            }
            Index::Grid(grid) => grid.within(q, radius, visit),
        }
    }

    /// The `k` points nearest `q` within `max_radius` (kd-tree only; the grid returns none),
    /// as (index, d²), nearest first.
    pub fn nearest(&self, q: Vec3A, k: usize, max_radius: f32) -> Vec<(u32, f32)> {
        let (Index::KdTree(tree), Some(k)) = (self, NonZeroUsize::new(k)) else { return Vec::new() };
        tree.query(&q.to_array())
            .nearest_n::<SquaredEuclidean<f32>>(k)
            .within(max_radius * max_radius)
            .execute()
            .into_iter()
            .map(|r| (r.item, r.distance))
            .collect()
    }
}

/// A hashed uniform grid (module docs).
pub struct Grid {
    points: Vec<Vec3A>,
    lo: Vec3A,
    cell: f32,
    /// Hash table of `mask + 1` buckets: bucket b's points are `entries[start[b]..start[b + 1]]`.
    start: Vec<u32>,
    entries: Vec<u32>,
    mask: u64,
}

impl Grid {
    pub fn new(points: &[[f32; 3]], radius: f32) -> Grid {
        let points: Vec<Vec3A> = points.iter().map(|p| Vec3A::from(*p)).collect();
        let lo = points.iter().fold(Vec3A::splat(f32::INFINITY), |a, &p| a.min(p));
        let lo = if lo.is_finite() { lo } else { Vec3A::ZERO };
        let cell = if radius > 0.0 && radius.is_finite() { radius } else { 1.0 };
        let buckets = (2 * points.len()).next_power_of_two().max(1);
        let mask = buckets as u64 - 1;
        let mut grid = Grid { points, lo, cell, start: vec![0; buckets + 1], entries: Vec::new(), mask };
        let ids: Vec<u32> = grid.points.iter().map(|&p| grid.bucket(grid.cell_of(p))).collect();
        for &b in &ids {
            grid.start[b as usize + 1] += 1;
        }
        for b in 0..buckets {
            grid.start[b + 1] += grid.start[b];
        }
        let mut fill = grid.start.clone();
        grid.entries = vec![0; ids.len()];
        for (i, &b) in ids.iter().enumerate() {
            grid.entries[fill[b as usize] as usize] = i as u32;
            fill[b as usize] += 1;
        }
        grid
    }

    #[inline]
    fn cell_of(&self, p: Vec3A) -> [i64; 3] {
        let c = ((p - self.lo) / self.cell).floor();
        [c.x as i64, c.y as i64, c.z as i64]
    }

    #[inline]
    fn bucket(&self, c: [i64; 3]) -> u32 {
        // pbrt's spatial hash: the cell's coordinates times three large primes, XORed.
        let h = (c[0].wrapping_mul(73_856_093)
            ^ c[1].wrapping_mul(19_349_663)
            ^ c[2].wrapping_mul(83_492_791)) as u64;
        (h & self.mask) as u32
    }

    /// Every point within `radius` (≤ the cell size) of `q`: the 2 × 2 × 2 or more cells the
    /// query's box touches, each bucket once (two cells may hash to one).
    #[inline]
    pub fn within(&self, q: Vec3A, radius: f32, mut visit: impl FnMut(u32, f32)) {
        let (a, b) = (self.cell_of(q - Vec3A::splat(radius)), self.cell_of(q + Vec3A::splat(radius)));
        let mut seen = [u32::MAX; 27];
        let mut n = 0;
        let r2 = radius * radius;
        for x in a[0]..=b[0] {
            for y in a[1]..=b[1] {
                for z in a[2]..=b[2] {
                    let bucket = self.bucket([x, y, z]);
                    if seen[..n].contains(&bucket) {
                        continue;
                    }
                    if n < seen.len() {
                        seen[n] = bucket;
                        n += 1;
                    }
                    let (s, e) = (self.start[bucket as usize], self.start[bucket as usize + 1]);
                    for &i in &self.entries[s as usize..e as usize] {
                        let d2 = self.points[i as usize].distance_squared(q);
                        if d2 <= r2 {
                            visit(i, d2);
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both indexes find exactly the points a brute-force scan finds, and the kd-tree's k
    /// nearest are the scan's.
    #[test]
    fn indexes_find_what_a_scan_finds() {
        let mut s = crate::render::sampler::Sampler::new(1, 2, 3);
        let points: Vec<[f32; 3]> = (0..5000)
            .map(|_| {
                let (a, b) = s.next2();
                [a * 2.0, b, s.next() * 0.5]
            })
            .collect();
        for kind in [IndexKind::Kdtree, IndexKind::Grid] {
            let r = 0.07;
            let index = Index::build(kind, &points, r).unwrap();
            for _ in 0..200 {
                let (a, b) = s.next2();
                let q = Vec3A::new(a * 2.2 - 0.1, b, s.next() * 0.6);
                let mut found = Vec::new();
                index.within(q, r, |i, d2| {
                    assert!((d2 - Vec3A::from(points[i as usize]).distance_squared(q)).abs() < 1e-6);
                    found.push(i)
                });
                found.sort();
                let scan: Vec<u32> = (0..points.len() as u32)
                    .filter(|&i| Vec3A::from(points[i as usize]).distance_squared(q) <= r * r)
                    .collect();
                assert_eq!(found, scan, "{kind:?} at {q}");
                if kind == IndexKind::Kdtree {
                    let near = index.nearest(q, 8, 10.0);
                    let mut d: Vec<f32> =
                        points.iter().map(|p| Vec3A::from(*p).distance_squared(q)).collect();
                    d.sort_by(f32::total_cmp);
                    let got: Vec<f32> = near.iter().map(|x| x.1).collect();
                    assert_eq!(got.len(), 8);
                    for (g, e) in got.iter().zip(&d) {
                        assert!((g - e).abs() < 1e-6, "{got:?} vs {:?}", &d[..8]);
                    }
                }
            }
        }
    }
}
