//! Candidate squares grouped into a lattice: integer cells (a, b) and a homography from cell
//! coordinates to the working image.
//!
//! Every candidate seeds hypotheses. Its nearest neighbour of similar size, by the distance
//! in the candidate's own moment frame (`Candidate::mahalanobis2`, which an affine view does
//! not change: a neighbour one pitch away sits at √12/q ≈ 4 where q ≈ 0.85 is the patch's
//! share of the pitch), gives one lattice axis. The neighbour most nearly perpendicular to it
//! in that frame, at a similar distance, gives the other. The three fix an affine map, and the
//! lattice grows from the seed outwards: candidates within `CELL_TOLERANCE` of a cell centre
//! and of a plausible size for that cell join it, the map is refitted (a homography once
//! the members span two rows and two columns), and the reach grows ring by ring, so
//! perspective is followed step by step rather than extrapolated from one patch. Members are
//! kept inside the best-filled 6 × 4 (or 4 × 6) window, since a chart has no more cells.

use super::regions::Candidate;
use glam::DVec2;
use nalgebra::Matrix3;
use std::collections::HashMap;

/// Largest distance, in cells, of a member from its cell's centre.
pub const CELL_TOLERANCE: f64 = 0.3;
/// The chart's cells.
const LONG: i32 = 6;
const SHORT: i32 = 4;

/// Cells found and the map from cell coordinates (cell centres at integers) to the image.
#[derive(Clone, Debug)]
pub struct Lattice {
    /// (candidate index, cell).
    pub members: Vec<(usize, [i32; 2])>,
    pub h: Matrix3<f64>,
}

pub fn apply(h: &Matrix3<f64>, p: [f64; 2]) -> [f64; 2] {
    let w = h[(2, 0)] * p[0] + h[(2, 1)] * p[1] + h[(2, 2)];
    [
        (h[(0, 0)] * p[0] + h[(0, 1)] * p[1] + h[(0, 2)]) / w,
        (h[(1, 0)] * p[0] + h[(1, 1)] * p[1] + h[(1, 2)]) / w,
    ]
}

/// |det| of the map's Jacobian at p: the image area of a unit cell there.
pub fn cell_area(h: &Matrix3<f64>, p: [f64; 2]) -> f64 {
    let e = 0.5;
    let (x0, x1) = (apply(h, [p[0] - e, p[1]]), apply(h, [p[0] + e, p[1]]));
    let (y0, y1) = (apply(h, [p[0], p[1] - e]), apply(h, [p[0], p[1] + e]));
    let (du, dv) = ([x1[0] - x0[0], x1[1] - x0[1]], [y1[0] - y0[0], y1[1] - y0[1]]);
    (du[0] * dv[1] - du[1] * dv[0]).abs()
}

/// The map fitted to cell ↔ image pairs: a homography when the cells span at least two rows
/// and two columns beyond a line (four or more, not collinear), else the least-squares
/// affine map (three or more).
pub fn fit(pairs: &[([f64; 2], [f64; 2])]) -> Option<Matrix3<f64>> {
    let rows = |k: usize| {
        let mut v: Vec<i64> = pairs.iter().map(|(c, _)| c[k].round() as i64).collect();
        v.sort_unstable();
        v.dedup();
        v.len()
    };
    if pairs.len() >= 5 && rows(0) >= 2 && rows(1) >= 2 {
        let cells: Vec<DVec2> = pairs.iter().map(|(c, _)| DVec2::new(c[0], c[1])).collect();
        let image: Vec<DVec2> = pairs.iter().map(|(_, p)| DVec2::new(p[0], p[1])).collect();
        if let Some(h) = crate::calib::zhang::homography(&cells, &image) {
            if h.iter().all(|v| v.is_finite()) {
                return Some(h);
            }
        }
    }
    affine(pairs)
}

fn affine(pairs: &[([f64; 2], [f64; 2])]) -> Option<Matrix3<f64>> {
    if pairs.len() < 3 {
        return None;
    }
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atx = nalgebra::Vector3::<f64>::zeros();
    let mut aty = nalgebra::Vector3::<f64>::zeros();
    for (c, p) in pairs {
        let r = nalgebra::Vector3::new(c[0], c[1], 1.0);
        ata += r * r.transpose();
        atx += r * p[0];
        aty += r * p[1];
    }
    let inv = ata.try_inverse()?;
    let (x, y) = (inv * atx, inv * aty);
    Some(Matrix3::new(x[0], x[1], x[2], y[0], y[1], y[2], 0.0, 0.0, 1.0))
}

/// Grows a lattice from three candidates: `seed` at (0, 0), `a` at (1, 0), `b` at (0, 1).
fn grow(cands: &[Candidate], seed: usize, a: usize, b: usize) -> Option<Lattice> {
    let c = |i: usize| cands[i].centre;
    let mut members = vec![(seed, [0, 0]), (a, [1, 0]), (b, [0, 1])];
    let mut h = affine(
        &members.iter().map(|&(i, cell)| ([cell[0] as f64, cell[1] as f64], c(i))).collect::<Vec<_>>(),
    )?;
    let seed_pixels = cands[seed].pixels as f64;
    for reach in [1, 2, 3, 5, 8] {
        let inv = h.try_inverse()?;
        let mut best: HashMap<[i32; 2], (usize, f64)> = HashMap::new();
        for (i, cand) in cands.iter().enumerate() {
            let ratio = cand.pixels as f64 / seed_pixels;
            if !(0.2..=5.0).contains(&ratio) {
                continue;
            }
            let q = apply(&inv, cand.centre);
            if !q.iter().all(|v| v.is_finite()) {
                continue;
            }
            let cell = [q[0].round() as i32, q[1].round() as i32];
            if cell[0].abs().max(cell[1].abs()) > reach {
                continue;
            }
            let err = ((q[0] - cell[0] as f64).powi(2) + (q[1] - cell[1] as f64).powi(2)).sqrt();
            if err > CELL_TOLERANCE {
                continue;
            }
            // A patch's interior covers about q² ≈ 0.72 of its cell, less the edge band the
            // edge map takes from it; far less is a speck, more is not a patch of this lattice.
            let fill = cand.pixels as f64 / cell_area(&h, [cell[0] as f64, cell[1] as f64]);
            if !(0.15..=1.0).contains(&fill) {
                continue;
            }
            if best.get(&cell).is_none_or(|&(_, e)| err < e) {
                best.insert(cell, (i, err));
            }
        }
        let mut found: Vec<(usize, [i32; 2])> = best.into_iter().map(|(cell, (i, _))| (i, cell)).collect();
        found.sort_by_key(|&(i, cell)| (cell, i));
        let found = window(&found);
        if found.len() < 3 {
            return None;
        }
        members = found;
        let pairs: Vec<_> =
            members.iter().map(|&(i, cell)| ([cell[0] as f64, cell[1] as f64], c(i))).collect();
        h = fit(&pairs)?;
    }
    Some(Lattice { members, h })
}

/// The members inside the 6 × 4 or 4 × 6 window holding the most of them.
fn window(found: &[(usize, [i32; 2])]) -> Vec<(usize, [i32; 2])> {
    let (mut best, mut best_n) = (None, 0);
    let (amin, amax) = found.iter().fold((i32::MAX, i32::MIN), |(l, h), m| (l.min(m.1[0]), h.max(m.1[0])));
    let (bmin, bmax) = found.iter().fold((i32::MAX, i32::MIN), |(l, h), m| (l.min(m.1[1]), h.max(m.1[1])));
    for (wa, wb) in [(LONG, SHORT), (SHORT, LONG)] {
        for a0 in (amin - wa + 1).max(amin - 8)..=amin.max(amax - wa + 1) {
            for b0 in (bmin - wb + 1).max(bmin - 8)..=bmin.max(bmax - wb + 1) {
                let inside = |c: [i32; 2]| (a0..a0 + wa).contains(&c[0]) && (b0..b0 + wb).contains(&c[1]);
                let n = found.iter().filter(|m| inside(m.1)).count();
                if n > best_n {
                    best_n = n;
                    best = Some((a0, b0, wa, wb));
                }
            }
        }
    }
    match best {
        Some((a0, b0, wa, wb)) => found
            .iter()
            .copied()
            .filter(|m| (a0..a0 + wa).contains(&m.1[0]) && (b0..b0 + wb).contains(&m.1[1]))
            .collect(),
        None => Vec::new(),
    }
}

/// The lattices the candidates form, largest first, no candidate in two.
pub fn find(cands: &[Candidate]) -> Vec<Lattice> {
    let n = cands.len();
    let mut grown: Vec<Lattice> = Vec::new();
    let mut in_large = vec![false; n];
    for i in 0..n {
        if in_large[i] {
            continue;
        }
        // Neighbours of similar size, one to 2.5 pitches away in i's own frame.
        let mut near: Vec<(f64, usize)> = (0..n)
            .filter(|&j| j != i)
            .filter(|&j| (0.4..=2.5).contains(&(cands[j].pixels as f64 / cands[i].pixels as f64)))
            .filter_map(|j| {
                let d = [cands[j].centre[0] - cands[i].centre[0], cands[j].centre[1] - cands[i].centre[1]];
                let m2 = cands[i].mahalanobis2(d);
                (9.0..=100.0).contains(&m2).then_some((m2.sqrt(), j))
            })
            .collect();
        near.sort_by(|x, y| x.0.total_cmp(&y.0));
        for &(dj, j) in near.iter().take(2) {
            let dvec =
                |k: usize| [cands[k].centre[0] - cands[i].centre[0], cands[k].centre[1] - cands[i].centre[1]];
            let (vj, ci) = (dvec(j), &cands[i]);
            // The cosine of the angle between the two offsets in i's moment frame.
            let cos = |vk: [f64; 2], dk: f64| {
                let sum = [vj[0] + vk[0], vj[1] + vk[1]];
                // (|a+b|² − |a|² − |b|²) / 2 = a·b in the metric.
                (ci.mahalanobis2(sum) - dj * dj - dk * dk) / (2.0 * dj * dk)
            };
            let k = near
                .iter()
                .filter(|&&(dk, k)| k != j && (0.7..=1.45).contains(&(dk / dj)))
                .map(|&(dk, k)| (cos(dvec(k), dk).abs(), k))
                .filter(|&(c, _)| c < 0.35)
                .min_by(|x, y| x.0.total_cmp(&y.0));
            if let Some((_, k)) = k {
                if let Some(l) = grow(cands, i, j, k) {
                    if l.members.len() >= 12 {
                        l.members.iter().for_each(|&(m, _)| in_large[m] = true);
                    }
                    grown.push(l);
                }
            }
        }
    }
    grown.sort_by(|x, y| y.members.len().cmp(&x.members.len()));
    let mut used = vec![false; n];
    let mut out = Vec::new();
    for l in grown {
        if l.members.iter().any(|&(m, _)| used[m]) {
            continue;
        }
        l.members.iter().for_each(|&(m, _)| used[m] = true);
        out.push(l);
    }
    out
}
