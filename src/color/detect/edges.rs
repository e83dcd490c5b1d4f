//! The chart's homography refined on the patches' edges, at full resolution.
//!
//! Region centroids place the lattice to a few tenths of a working pixel, but a centroid is
//! not the image of a square's centre under perspective, and the working scale is coarse.
//! The edges are where a patch meets its black surround: four straight lines per patch, at
//! u = col + ½ ± hᵤ and v = row + ½ ± hᵥ in the chart's cell coordinates (hᵤ, hᵥ the patch's
//! half side as a share of the pitch, fitted too). Seven points along each edge (away from
//! the corners, where the two edges' blur meets) are searched for across it: the position
//! of the steepest colour change along a short segment crossing the predicted edge, to a
//! fraction of a pixel by a parabola through the three samples around the peak. Then
//! H = H₀·(I + Δ) and (hᵤ, hᵥ) are fitted by Gauss–Newton to the points' distances from
//! their lines (Huber weights, 1 px), and the search is repeated over a narrower segment.
//! Edges with too little contrast (black 2 and neutral 3.5 against the black surround) give
//! no points and so no weight.

use super::lattice::apply;
use super::regions::Encoded;
use nalgebra::{Matrix3, SMatrix, SVector};

/// Searched segments' half lengths, in cells, for the two rounds.
const REACH: [f64; 2] = [0.09, 0.04];
/// Fewest edge points a refinement needs (a quarter of the chart's 672).
const MIN_POINTS: usize = 160;
/// Smallest colour change across an edge that is searched (sRGB-encoded).
const MIN_CONTRAST: f32 = 0.06;
const HUBER_PX: f64 = 1.0;

/// One radial term of lens distortion about the image centre c (division form):
/// x_u = c + (x − c)(1 + k·ρ²), ρ = |x − c| / the half diagonal. A phone's lens leaves some
/// after its own correction, and a chart half the frame wide shows it: without it the edges
/// fit a homography to 1.4–2.3 px RMS on the shared photographs.
#[derive(Clone, Copy, Debug)]
pub struct Lens {
    pub centre: [f64; 2],
    pub inv_radius: f64,
    pub k: f64,
}

impl Lens {
    pub fn new(width: usize, height: usize, k: f64) -> Lens {
        let centre = [0.5 * (width as f64 - 1.0), 0.5 * (height as f64 - 1.0)];
        Lens { centre, inv_radius: 1.0 / centre[0].hypot(centre[1]).max(1.0), k }
    }

    pub fn undistort(&self, x: [f64; 2]) -> [f64; 2] {
        let (dx, dy) = (x[0] - self.centre[0], x[1] - self.centre[1]);
        let f = 1.0 + self.k * (dx * dx + dy * dy) * self.inv_radius * self.inv_radius;
        [self.centre[0] + dx * f, self.centre[1] + dy * f]
    }

    /// The inverse of `undistort`, by fixed-point steps (k is small: a few suffice).
    pub fn distort(&self, xu: [f64; 2]) -> [f64; 2] {
        let mut x = xu;
        for _ in 0..6 {
            let (dx, dy) = (x[0] - self.centre[0], x[1] - self.centre[1]);
            let f = 1.0 + self.k * (dx * dx + dy * dy) * self.inv_radius * self.inv_radius;
            x = [
                self.centre[0] + (xu[0] - self.centre[0]) / f,
                self.centre[1] + (xu[1] - self.centre[1]) / f,
            ];
        }
        x
    }
}

pub struct Refined {
    pub lens: Lens,
    pub h: Matrix3<f64>,
    /// Half side of a patch per axis, as a share of the pitch.
    pub half: [f64; 2],
    pub points: usize,
    /// RMS distance of the edge points from their lines (px).
    pub rms_px: f64,
}

/// An edge point: its position, and the line it belongs to (axis 0: u = value, 1: v = value).
struct Point {
    x: [f64; 2],
    axis: usize,
    cell: i32,
    sign: f64,
}

fn line_value(p: &Point, half: [f64; 2]) -> f64 {
    p.cell as f64 + 0.5 + p.sign * half[p.axis]
}

/// Signed distance (px) of x from the image of the chart line {axis = value} under h.
fn distance(hinv_t: &Matrix3<f64>, x: [f64; 2], axis: usize, value: f64) -> f64 {
    let g = if axis == 0 {
        nalgebra::Vector3::new(1.0, 0.0, -value)
    } else {
        nalgebra::Vector3::new(0.0, 1.0, -value)
    };
    let l = hinv_t * g;
    (l[0] * x[0] + l[1] * x[1] + l[2]) / (l[0] * l[0] + l[1] * l[1]).sqrt()
}

/// Finds the edge points around the predicted edges.
fn search(img: &Encoded, h: &Matrix3<f64>, lens: &Lens, half: [f64; 2], reach: f64) -> Vec<Point> {
    let mut out = Vec::new();
    let (w, hh) = (img.width as f64, img.height as f64);
    for k in 0..24 {
        let (col, row) = ((k % 6) as i32, (k / 6) as i32);
        for axis in 0..2 {
            for sign in [-1.0, 1.0] {
                for t in [-0.6, -0.4, -0.2, 0.0, 0.2, 0.4, 0.6] {
                    // Chart coordinates of the predicted edge point and of the segment's ends.
                    let along = if axis == 0 { row } else { col } as f64 + 0.5 + t * half[1 - axis];
                    let value = if axis == 0 { col } else { row } as f64 + 0.5 + sign * half[axis];
                    let at = |s: f64| if axis == 0 { [value + s, along] } else { [along, value + s] };
                    let (a, b) = (lens.distort(apply(h, at(-reach))), lens.distort(apply(h, at(reach))));
                    let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
                    if !(len.is_finite() && len >= 1.0) {
                        continue;
                    }
                    let inside =
                        |p: [f64; 2]| p[0] >= 1.0 && p[1] >= 1.0 && p[0] <= w - 2.0 && p[1] <= hh - 2.0;
                    if !(inside(a) && inside(b)) {
                        continue;
                    }
                    // Quarter-pixel steps, and at least 8, so a short segment (a small chart)
                    // still has a peak away from its ends.
                    let n = ((4.0 * len).ceil() as usize).max(8);
                    let profile: Vec<[f32; 3]> = (0..=n)
                        .map(|i| {
                            let f = i as f64 / n as f64;
                            img.at(a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]))
                        })
                        .collect();
                    let diff = |p: [f32; 3], q: [f32; 3]| {
                        ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
                    };
                    if diff(profile[0], profile[n]) < MIN_CONTRAST {
                        continue;
                    }
                    let grad: Vec<f32> = (1..n).map(|i| diff(profile[i + 1], profile[i - 1])).collect();
                    let (imax, gmax) =
                        grad.iter()
                            .enumerate()
                            .fold((0, 0f32), |b, (i, &g)| if g > b.1 { (i, g) } else { b });
                    if imax == 0 || imax + 1 >= grad.len() {
                        continue;
                    }
                    let (g0, g1, g2) = (grad[imax - 1] as f64, gmax as f64, grad[imax + 1] as f64);
                    let curv = g0 - 2.0 * g1 + g2;
                    let off = if curv < 0.0 { (0.5 * (g0 - g2) / curv).clamp(-0.5, 0.5) } else { 0.0 };
                    let f = (imax as f64 + 1.0 + off) / n as f64;
                    out.push(Point {
                        x: [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])],
                        axis,
                        cell: if axis == 0 { col } else { row },
                        sign,
                    });
                }
            }
        }
    }
    out
}

/// H₀·(I + Δ) from the 8 entries of Δ.
fn perturbed(h0: &Matrix3<f64>, d: &[f64]) -> Matrix3<f64> {
    h0 * Matrix3::new(1.0 + d[0], d[1], d[2], d[3], 1.0 + d[4], d[5], d[6], d[7], 1.0)
}

fn residuals(h0: &Matrix3<f64>, lens: &Lens, p: &SVector<f64, 11>, points: &[Point]) -> Option<Vec<f64>> {
    let h = perturbed(h0, &p.as_slice()[..8]);
    let hinv_t = h.try_inverse()?.transpose();
    let half = [p[8], p[9]];
    let lens = Lens { k: p[10], ..*lens };
    Some(points.iter().map(|q| distance(&hinv_t, lens.undistort(q.x), q.axis, line_value(q, half))).collect())
}

/// Gauss–Newton with Huber weights over Δ, the half sides and the lens's k.
fn fit(
    h0: &Matrix3<f64>,
    lens: &Lens,
    fit_lens: bool,
    half: [f64; 2],
    points: &[Point],
) -> Option<(Matrix3<f64>, Lens, [f64; 2], f64)> {
    let mut p = SVector::<f64, 11>::zeros();
    p[8] = half[0];
    p[9] = half[1];
    p[10] = lens.k;
    let mut r = residuals(h0, lens, &p, points)?;
    for _ in 0..20 {
        let eps = 1e-7;
        let mut jac = vec![SVector::<f64, 11>::zeros(); points.len()];
        for j in 0..if fit_lens { 11 } else { 10 } {
            let mut q = p;
            q[j] += eps;
            let rq = residuals(h0, lens, &q, points)?;
            for (i, v) in rq.iter().enumerate() {
                jac[i][j] = (v - r[i]) / eps;
            }
        }
        let mut jtj = SMatrix::<f64, 11, 11>::zeros();
        let mut jtr = SVector::<f64, 11>::zeros();
        for (i, ji) in jac.iter().enumerate() {
            let w = if r[i].abs() <= HUBER_PX { 1.0 } else { HUBER_PX / r[i].abs() };
            jtj += w * ji * ji.transpose();
            jtr += w * ji * r[i];
        }
        if !fit_lens {
            // k held: its column is zero, and this keeps the system invertible with no step.
            jtj[(10, 10)] = 1.0;
        }
        let step = jtj.try_inverse()? * jtr;
        let next = p - step;
        let rn = residuals(h0, lens, &next, points)?;
        let cost = |r: &[f64]| {
            r.iter()
                .map(
                    |v| if v.abs() <= HUBER_PX { 0.5 * v * v } else { HUBER_PX * (v.abs() - 0.5 * HUBER_PX) },
                )
                .sum::<f64>()
        };
        if cost(&rn) > cost(&r) {
            break;
        }
        p = next;
        r = rn;
        if step.norm() < 1e-9 {
            break;
        }
    }
    let h = perturbed(h0, &p.as_slice()[..8]);
    let rms = (r.iter().map(|v| v * v).sum::<f64>() / r.len() as f64).sqrt();
    Some((h / h[(2, 2)], Lens { k: p[10], ..*lens }, [p[8], p[9]], rms))
}

/// Refines `h` (chart cell coordinates → full-resolution pixels), or `None` where the edges
/// are too few or the fit fails (the caller keeps the centroids' homography).
pub fn refine(img: &Encoded, h: &Matrix3<f64>, half: [f64; 2]) -> Option<Refined> {
    let (mut h, mut half) = (*h, half);
    let mut lens = Lens::new(img.width, img.height, 0.0);
    // Over a chart small in the frame a radial term is all but a homography's perspective: it
    // is fitted only when the chart spans 40 % of the frame's diagonal.
    let span = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]);
    let diagonal = span(apply(&h, [0.0, 0.0]), apply(&h, [6.0, 4.0]))
        .max(span(apply(&h, [6.0, 0.0]), apply(&h, [0.0, 4.0])));
    let fit_lens = diagonal >= 0.4 * (img.width as f64).hypot(img.height as f64);
    let mut last = None;
    for reach in REACH {
        // A segment of at least 1.2 px each way, so a small chart's edges are still searched;
        // never beyond the first round's reach, which stays short of the neighbour's edge.
        let pitch = super::lattice::cell_area(&h, [3.0, 2.0]).sqrt();
        let reach = reach.max(1.2 / pitch).min(REACH[0]);
        let points = search(img, &h, &lens, half, reach);
        if points.len() < MIN_POINTS {
            break;
        }
        let Some((hn, lensn, halfn, rms)) = fit(&h, &lens, fit_lens, half, &points) else { break };
        // |k| beyond 0.3 moves the frame's corners by a third of the half diagonal: no lens a
        // photograph is taken through, so the fit went astray.
        if !(halfn.iter().all(|v| (0.2..0.5).contains(v))
            && hn.iter().all(|v| v.is_finite())
            && lensn.k.abs() < 0.3)
        {
            break;
        }
        h = hn;
        half = halfn;
        lens = lensn;
        last = Some((points.len(), rms));
    }
    let (points, rms_px) = last?;
    Some(Refined { lens, h, half, points, rms_px })
}
