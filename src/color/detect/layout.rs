//! Which way round the chart lies: the placement of the 6 × 4 chart on a lattice whose
//! colours best match the ColorChecker Classic's.
//!
//! A lattice fixes cells, not which of them is patch 1. The chart can lie in four rotations
//! (a photograph never mirrors it, so a lattice whose axes turn the other way on screen is
//! swapped first), and a lattice missing whole rows or columns can sit at several offsets
//! under the chart. Each placement predicts the 24 patches' colours; the observed ones are
//! compared with the chart's published XYZ through the affine map (3 × 4, least squares)
//! that best relates them, which absorbs the light's colour, the exposure and the camera's
//! primaries. Only the right placement leaves a small residual: any other puts the neutral
//! row where the chart has colours, which no affine map can follow.
//!
//! The residual ρ is the fit's RMS over the observed colours' own RMS spread (linear values,
//! sRGB-decoded from the working image), over the patches inside the image (at least 12) and,
//! channel by channel, not clipped. The runner-up's ρ says how sure the choice is.

use super::lattice::{apply, Lattice};
use super::regions::Work;
use nalgebra::{Matrix3, Matrix4, Vector4};

pub const COLS: i32 = 6;
pub const ROWS: i32 = 4;
/// A placement whose residual exceeds this is not a ColorChecker Classic. The right placement
/// of a rendered chart leaves about 0.04 (the sensor's noise), of the shared phone photographs
/// 0.15–0.2 (their tone curve, which no affine map follows); a wrong placement, or the chart's
/// colours in another order, leaves most of the colours' spread (0.9).
pub const MAX_RESIDUAL: f64 = 0.3;

/// A channel at or above this (linear; 98 % of full scale encoded) is taken as clipped: it
/// follows no map of the chart's colours, so it is left out of that channel's match.
const CLIPPED: f64 = 0.955;

/// One placement of the chart on the lattice.
#[derive(Clone, Debug)]
pub struct Placement {
    /// Chart cell-grid coordinates (u, v) ∈ [0, 6] × [0, 4] → working image.
    pub h: Matrix3<f64>,
    /// Relative residual of the colour match.
    pub residual: f64,
    /// Patches (0-based, chart order) whose centre lies outside the image.
    pub outside: Vec<usize>,
}

/// The colour of a patch at the working scale: the median of each channel over the central
/// fifth of its cell (at least the pixel under the centre).
fn patch_colour(work: &Work, h: &Matrix3<f64>, col: i32, row: i32) -> Option<[f64; 3]> {
    let c = apply(h, [col as f64 + 0.5, row as f64 + 0.5]);
    let (w, hh) = (work.width as f64, work.height as f64);
    if !(c[0] >= 0.0 && c[1] >= 0.0 && c[0] <= w - 1.0 && c[1] <= hh - 1.0) {
        return None;
    }
    let e = apply(h, [col as f64 + 0.6, row as f64 + 0.6]);
    let r = ((e[0] - c[0]).abs().max((e[1] - c[1]).abs())).max(0.5);
    let (x0, x1) = ((c[0] - r).round().max(0.0) as usize, (c[0] + r).round().min(w - 1.0) as usize);
    let (y0, y1) = ((c[1] - r).round().max(0.0) as usize, (c[1] + r).round().min(hh - 1.0) as usize);
    let mut ch: [Vec<f32>; 3] = Default::default();
    for y in y0..=y1 {
        for x in x0..=x1 {
            let p = work.pixel(x, y);
            (0..3).for_each(|k| ch[k].push(p[k]));
        }
    }
    Some(ch.map(|mut v| {
        let m = v.len() / 2;
        let (_, med, _) = v.select_nth_unstable_by(m, f32::total_cmp);
        crate::image::srgb_decode(*med) as f64
    }))
}

/// ρ of the best affine map from `reference` XYZ to `observed` linear RGB, over the pairs
/// given. Each output channel is its own least-squares fit, over the patches where that
/// channel is not clipped (`CLIPPED`; at least 8 of them, else ∞).
pub fn residual(observed: &[[f64; 3]], reference: &[[f64; 3]]) -> f64 {
    let (mut res, mut spread) = (0.0, 0.0);
    for k in 0..3 {
        let pairs: Vec<(f64, Vector4<f64>)> = observed
            .iter()
            .zip(reference)
            .filter(|(o, _)| o[k] < CLIPPED)
            .map(|(o, r)| (o[k], Vector4::new(r[0], r[1], r[2], 1.0)))
            .collect();
        if pairs.len() < 8 {
            return f64::INFINITY;
        }
        let mut ata = Matrix4::<f64>::zeros();
        let mut atb = Vector4::<f64>::zeros();
        for (o, x) in &pairs {
            ata += x * x.transpose();
            atb += x * *o;
        }
        let Some(inv) = ata.try_inverse() else { return f64::INFINITY };
        let coef = inv * atb;
        let mean = pairs.iter().map(|p| p.0).sum::<f64>() / pairs.len() as f64;
        for (o, x) in &pairs {
            res += (o - coef.dot(x)).powi(2);
            spread += (o - mean).powi(2);
        }
    }
    if spread > 0.0 {
        (res / spread).sqrt()
    } else {
        f64::INFINITY
    }
}

/// Every placement of the chart on the lattice that covers all its members, best first.
pub fn placements(work: &Work, lattice: &Lattice, reference: &[[f64; 3]]) -> Vec<Placement> {
    // Make the lattice's axes turn as the image's do (x right, y down), so the chart's own
    // frame (columns right, rows down, seen from the front) is a rotation of it.
    let c0 = lattice.members[0].1;
    let p0 = apply(&lattice.h, [c0[0] as f64, c0[1] as f64]);
    let pa = apply(&lattice.h, [c0[0] as f64 + 1.0, c0[1] as f64]);
    let pb = apply(&lattice.h, [c0[0] as f64, c0[1] as f64 + 1.0]);
    let turn = (pa[0] - p0[0]) * (pb[1] - p0[1]) - (pa[1] - p0[1]) * (pb[0] - p0[0]);
    let (h, cells): (Matrix3<f64>, Vec<[i32; 2]>) = if turn < 0.0 {
        let swap = Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        (lattice.h * swap, lattice.members.iter().map(|m| [m.1[1], m.1[0]]).collect())
    } else {
        (lattice.h, lattice.members.iter().map(|m| m.1).collect())
    };
    // Rotation r takes chart cell offsets (col, row) to lattice offsets.
    let rotate = |r: usize, c: i32, w: i32| match r {
        0 => [c, w],
        1 => [-w, c],
        2 => [-c, -w],
        _ => [w, -c],
    };
    let mut out = Vec::new();
    for r in 0..4 {
        // Lattice cells of the chart's corners for offset zero, to bound the offsets.
        let span: Vec<[i32; 2]> = [(0, 0), (COLS - 1, 0), (0, ROWS - 1), (COLS - 1, ROWS - 1)]
            .iter()
            .map(|&(c, w)| rotate(r, c, w))
            .collect();
        let (smin, smax) = span.iter().fold(([i32::MAX; 2], [i32::MIN; 2]), |(lo, hi), s| {
            ([lo[0].min(s[0]), lo[1].min(s[1])], [hi[0].max(s[0]), hi[1].max(s[1])])
        });
        let (mmin, mmax) = cells.iter().fold(([i32::MAX; 2], [i32::MIN; 2]), |(lo, hi), s| {
            ([lo[0].min(s[0]), lo[1].min(s[1])], [hi[0].max(s[0]), hi[1].max(s[1])])
        });
        // Offsets o with o + smin ≤ mmin and o + smax ≥ mmax: every member under the chart.
        for oa in (mmax[0] - smax[0])..=(mmin[0] - smin[0]) {
            for ob in (mmax[1] - smax[1])..=(mmin[1] - smin[1]) {
                // Chart (u, v) → lattice: the cell (col, row) centre (col + ½, row + ½) goes
                // to rotate(col, row) + o.
                let [ra, rb] = [rotate(r, 1, 0), rotate(r, 0, 1)];
                let (ox, oy) = (oa as f64, ob as f64);
                let cx = ox - 0.5 * (ra[0] + rb[0]) as f64;
                let cy = oy - 0.5 * (ra[1] + rb[1]) as f64;
                let t = Matrix3::new(
                    ra[0] as f64,
                    rb[0] as f64,
                    cx,
                    ra[1] as f64,
                    rb[1] as f64,
                    cy,
                    0.0,
                    0.0,
                    1.0,
                );
                let hc = h * t;
                let mut observed = Vec::new();
                let mut refs = Vec::new();
                let mut outside = Vec::new();
                for k in 0..(COLS * ROWS) as usize {
                    let (col, row) = (k as i32 % COLS, k as i32 / COLS);
                    match patch_colour(work, &hc, col, row) {
                        Some(c) => {
                            observed.push(c);
                            refs.push(reference[k]);
                        }
                        None => outside.push(k),
                    }
                }
                let residual = if observed.len() >= 12 { residual(&observed, &refs) } else { f64::INFINITY };
                out.push(Placement { h: hc, residual, outside });
            }
        }
    }
    out.sort_by(|a, b| a.residual.total_cmp(&b.residual));
    out
}
