//! Normals for a point cloud that has none: a plane fitted to each point's k nearest
//! neighbours (the smallest principal axis of their covariance), turned consistently by
//! Hoppe et al. 1992's minimum spanning tree over the k-nearest-neighbour graph with edge
//! cost 1 − |nᵢ·nⱼ|, so the turn propagates first where the tangent planes agree. The tree is
//! rooted at the point farthest from the centroid, whose normal is turned away from the
//! centroid: outward for a closed surface.

use super::Cloud;
use glam::DVec3;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// Unit normals, one per point, from `k` neighbours each.
pub fn estimate(cloud: &Cloud, k: usize) -> Vec<DVec3> {
    let n = cloud.points.len();
    let neighbours: Vec<Vec<u32>> = {
        use rayon::prelude::*;
        (0..n).into_par_iter().map(|i| cloud.nearest(cloud.points[i], k + 1)).collect()
    };
    let mut normals: Vec<DVec3> = neighbours
        .iter()
        .map(|nb| {
            let pts: Vec<DVec3> = nb.iter().map(|&j| cloud.points[j as usize]).collect();
            plane_normal(&pts).unwrap_or(DVec3::Z)
        })
        .collect();
    orient(cloud, &neighbours, &mut normals);
    // A point the tree turned against most of its neighbours (where noise made two tangent
    // planes disagree along the tree) is turned back by them, twice over.
    for _ in 0..2 {
        let flip: Vec<bool> = neighbours
            .iter()
            .enumerate()
            .map(|(i, nb)| {
                let against = nb
                    .iter()
                    .filter(|&&j| j as usize != i && normals[j as usize].dot(normals[i]) < 0.0)
                    .count();
                2 * against > nb.len().saturating_sub(1)
            })
            .collect();
        for (n, f) in normals.iter_mut().zip(flip) {
            if f {
                *n = -*n;
            }
        }
    }
    normals
}

/// The smallest principal axis of the points' covariance (unit), or `None` for fewer than 3.
pub fn plane_normal(pts: &[DVec3]) -> Option<DVec3> {
    (pts.len() >= 3).then(|| smallest_axis(&scatter(pts))).flatten()
}

/// Σ (p − c)(p − c)ᵀ about the points' centroid c.
fn scatter(pts: &[DVec3]) -> nalgebra::Matrix3<f64> {
    let c = pts.iter().copied().sum::<DVec3>() / pts.len().max(1) as f64;
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    for p in pts {
        let d = nalgebra::Vector3::new(p.x - c.x, p.y - c.y, p.z - c.z);
        m += d * d.transpose();
    }
    m
}

/// The points' covariance's smallest over largest eigenvalue: 0 on a plane, 1 for points
/// spread evenly in every direction (1 for fewer than 3 points).
pub fn flatness(pts: &[DVec3]) -> f64 {
    if pts.len() < 3 {
        return 1.0;
    }
    let e = nalgebra::SymmetricEigen::new(scatter(pts)).eigenvalues;
    let (lo, hi) = (e.min(), e.max());
    if hi > 0.0 {
        lo.max(0.0) / hi
    } else {
        1.0
    }
}

/// The unit eigenvector of a symmetric 3 × 3 matrix's smallest eigenvalue.
pub fn smallest_axis(m: &nalgebra::Matrix3<f64>) -> Option<DVec3> {
    let e = nalgebra::SymmetricEigen::new(*m);
    let i = e.eigenvalues.imin();
    let v = e.eigenvectors.column(i);
    let n = DVec3::new(v[0], v[1], v[2]);
    (n.is_finite() && n.length() > 0.5).then(|| n.normalize())
}

#[derive(PartialEq)]
struct Edge(f64, u32, u32);
impl Eq for Edge {}
impl PartialOrd for Edge {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Edge {
    // Smallest cost first from a max-heap; ties by index, so the order is deterministic.
    fn cmp(&self, o: &Self) -> Ordering {
        o.0.total_cmp(&self.0).then_with(|| o.2.cmp(&self.2))
    }
}

/// Turns the normals consistently: Prim's tree over the neighbour graph from the outermost
/// point, each point turned to agree with the one it was reached from. Parts of the graph the
/// tree does not reach (a separate cluster) start again from their own outermost point.
fn orient(cloud: &Cloud, neighbours: &[Vec<u32>], normals: &mut [DVec3]) {
    let n = cloud.points.len();
    let centroid = cloud.points.iter().copied().sum::<DVec3>() / n as f64;
    let mut order: Vec<u32> = (0..n as u32).collect();
    order.sort_by(|&a, &b| {
        let (da, db) = (
            cloud.points[a as usize].distance_squared(centroid),
            cloud.points[b as usize].distance_squared(centroid),
        );
        db.total_cmp(&da).then(a.cmp(&b))
    });
    let mut done = vec![false; n];
    let mut heap = BinaryHeap::new();
    for &root in &order {
        if done[root as usize] {
            continue;
        }
        let r = root as usize;
        if normals[r].dot(cloud.points[r] - centroid) < 0.0 {
            normals[r] = -normals[r];
        }
        done[r] = true;
        let push = |heap: &mut BinaryHeap<Edge>, i: usize, normals: &[DVec3], done: &[bool]| {
            for &j in &neighbours[i] {
                if !done[j as usize] {
                    heap.push(Edge(1.0 - normals[i].dot(normals[j as usize]).abs(), i as u32, j));
                }
            }
        };
        push(&mut heap, r, normals, &done);
        while let Some(Edge(_, from, to)) = heap.pop() {
            let (f, t) = (from as usize, to as usize);
            if done[t] {
                continue;
            }
            if normals[t].dot(normals[f]) < 0.0 {
                normals[t] = -normals[t];
            }
            done[t] = true;
            push(&mut heap, t, normals, &done);
        }
    }
}
