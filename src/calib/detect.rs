//! Chessboard detection: find the inner corners of a board with `cols × rows` inner corners,
//! order them consistently, refine them to sub-pixel accuracy.
//!
//! 1. **Candidates**: saddle points of the blurred image (σ = 1.5 px), where the Hessian's
//!    determinant is negative: R = I_xy² − I_xx·I_yy > 0, local maxima over 7×7.
//! 2. **X-junction check**: on a circle around the candidate the intensity must alternate
//!    dark/light exactly four times, at angles that come in opposite pairs (two straight edges
//!    crossing); this rejects the T- and L-shaped corners at a board's rim and texture that
//!    merely curves.
//! 3. **Grid growing**: from a seed and its two nearest neighbours joined to it by a square's
//!    edge (not a diagonal: the image differs across the segment), each next corner is
//!    predicted by extrapolating its row or column (which follows perspective) and adopted when
//!    a candidate lies within 30 % of a square of the prediction and is joined to it by an
//!    edge. Growth can run onto the board's rim, so the board is the fully populated
//!    `cols × rows` window of the grid whose surrounding squares continue its checker pattern
//!    best (at least 75 % of them); without one the view is skipped with the size of grid found.
//! 4. **Order**: rows of `cols` corners; the first row runs to the right of the first column
//!    (image y down), and corner 0 is the one diagonally next to the board's darker corner
//!    square. For boards whose two diagonal corner squares differ in colour (`cols + rows` odd,
//!    such as 9×6) this is unambiguous and never flips between views — unlike OpenCV's classic
//!    detector, which starts at either end.
//! 5. **Sub-pixel**: the corner p minimises Σ w(q)·(∇I(q)·(q − p))² over a window (the
//!    gradient at every q on an edge through p is orthogonal to q − p), the equation OpenCV's
//!    `cornerSubPix` solves, iterated to 1e-4 px. The window is a parallelogram along the
//!    board's two directions through the corner, a fixed fraction of the local square: a
//!    square window on a steep view reaches the edges of the next, foreshortened squares,
//!    which pull the corner off (0.9 px RMS at 70°–75° of tilt, against 0.06 px). Unlike
//!    `cornerSubPix`, the gradients are taken at whole pixels (the window's weights centred on
//!    p) rather than interpolated at p + offsets: bilinear interpolation at one shared
//!    sub-pixel phase biases every sample the same way, and on renders this alone cut the
//!    corner error from 0.042 to 0.030 px RMS. Gradients are central differences of the image
//!    blurred with σ = 1 px (0.7 px: 0.031, 1.4 px: 0.053 px). With a response given
//!    (`DetectOptions::response`), that image is the codes made linear (`calib::linear`).

use crate::error::Invalid;
use crate::image::filter::Grey;
use crate::render::sensor::Response;
use glam::DVec2;
use std::collections::HashMap;

/// Inner-corner counts: `cols` along a row, `rows` rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct BoardSize {
    pub cols: usize,
    pub rows: usize,
}

/// Detector settings.
#[derive(Clone, Debug)]
pub struct DetectOptions {
    /// Half-size of a square sub-pixel window in pixels, as `cornerSubPix`'s; `None` (the
    /// default) shapes the window by the board around each corner (`refine`).
    pub subpix_half_window: Option<usize>,
    /// The response the codes were written through, undone before the corners are refined
    /// (`calib::linear`; default linear: the codes as they are).
    pub response: Response,
}

impl Default for DetectOptions {
    fn default() -> Self {
        DetectOptions { subpix_half_window: None, response: Response::Linear }
    }
}

/// Detects the board; `Err` says why the view has no complete board.
pub fn detect(img: &Grey, board: BoardSize, opts: &DetectOptions) -> Result<Vec<DVec2>, Invalid> {
    find(img, board, opts).map(|f| f.corners)
}

/// A detection: the board's corners in order and, when they are a window of a complete grid
/// of corners larger than the board asked for, that grid's size as (cols, rows) in the
/// board's orientation (the board size given is then likely wrong: a sub-grid was fitted).
pub struct Found {
    pub corners: Vec<DVec2>,
    pub larger_grid: Option<(usize, usize)>,
}

/// `detect`, saying whether the board found lies inside a larger grid.
pub fn find(img: &Grey, board: BoardSize, opts: &DetectOptions) -> Result<Found, Invalid> {
    if board.cols < 2 || board.rows < 2 {
        return Err(
            format!("a board needs at least 2×2 inner corners, not {}×{}", board.cols, board.rows).into()
        );
    }
    let sampler = img.blur(1.0);
    let points = corner_candidates(img, &sampler);
    if points.len() < board.cols * board.rows {
        return Err(format!(
            "found {} chessboard-like corners, fewer than the {} of a {}×{} board",
            points.len(),
            board.cols * board.rows,
            board.cols,
            board.rows
        )
        .into());
    }
    let (grid, larger_grid) = find_grid(&points, board, &sampler)?;
    let ordered = order(&grid, board, &sampler);
    // The board is found on the codes; its corners are refined where light is linear.
    let sampler = match opts.response {
        Response::Linear => sampler,
        r => super::linear::linearise(img, &r).blur(1.0),
    };
    Ok(Found { corners: refine(&sampler, &ordered, board, opts), larger_grid })
}

/// Saddle points that pass the X-junction check (steps 1 and 2).
pub fn corner_candidates(img: &Grey, sampler: &Grey) -> Vec<DVec2> {
    let ring = Ring::new();
    saddle_candidates(img).into_iter().filter(|p| is_x_junction(sampler, *p, &ring)).collect()
}

/// Saddle points of the image blurred with σ = 1.5 px: local maxima of R = I_xy² − I_xx·I_yy
/// above 1 % of the strongest, strongest first. The blurred rows are made one at a time
/// (`BlurRows`) as R's rows need them, not kept as an image.
fn saddle_candidates(img: &Grey) -> Vec<DVec2> {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx2")]
        fn avx2(img: &Grey) -> Vec<DVec2> {
            saddle_candidates_with(img)
        }
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2.
            return unsafe { avx2(img) };
        }
    }
    saddle_candidates_with(img)
}

/// `saddle_candidates`, inlined into a caller compiled for the processor's vectors (no fused
/// multiply-adds: the same responses at every width).
#[inline(always)]
fn saddle_candidates_with(img: &Grey) -> Vec<DVec2> {
    let (w, h) = (img.width, img.height);
    let mut r = vec![0.0f32; w * h];
    if w >= 5 && h >= 5 {
        let mut blurred = crate::image::filter::BlurRows::new(img, 1.5, 1);
        let mut rows = [vec![0.0f32; w], vec![0.0f32; w], vec![0.0f32; w]];
        blurred.row(1, &mut rows[0]);
        blurred.row(2, &mut rows[1]);
        for y in 2..h - 2 {
            // Blurred row j is kept in rows[(j + 2) % 3].
            blurred.row(y + 1, &mut rows[y % 3]);
            let (up, row, down) = (&rows[(y + 1) % 3], &rows[(y + 2) % 3], &rows[y % 3]);
            // Pixels 2 … w − 3 and their neighbours as slices of one length, so that the loop
            // has no bounds checks and vectorises.
            let n = w - 4;
            fn shifted(v: &[f32], dx: usize, n: usize) -> &[f32] {
                &v[1 + dx..1 + dx + n]
            }
            let at = |v, dx| shifted(v, dx, n);
            let out = &mut r[y * w + 2..y * w + 2 + n];
            let (l, c, rr) = (at(row, 0), at(row, 1), at(row, 2));
            let (ul, u, ur) = (at(up, 0), at(up, 1), at(up, 2));
            let (dl, d, dr) = (at(down, 0), at(down, 1), at(down, 2));
            for i in 0..n {
                let ixx = rr[i] - 2.0 * c[i] + l[i];
                let iyy = d[i] - 2.0 * c[i] + u[i];
                let ixy = 0.25 * (dr[i] - ur[i] - dl[i] + ul[i]);
                out[i] = ixy * ixy - ixx * iyy;
            }
        }
    }
    // The largest response, in eight lanes so the loop vectorises.
    let lanes = r.chunks_exact(8).fold([0.0f32; 8], |mut m, c| {
        for (a, &v) in m.iter_mut().zip(c) {
            *a = if v > *a { v } else { *a };
        }
        m
    });
    let max = lanes.into_iter().chain(r.chunks_exact(8).remainder().iter().copied()).fold(0.0f32, f32::max);
    let mut out: Vec<(f32, DVec2)> = Vec::new();
    if max <= 0.0 {
        return Vec::new();
    }
    let rad = 3isize;
    // The largest response of each 7×7 window: per row, the columns' maxima over its seven
    // rows, then their maxima over seven columns (both vectorise); a pixel below its
    // window's maximum is no local maximum, which settles nearly every pixel at once.
    let mut column = vec![0.0f32; w];
    for y in 4..h.saturating_sub(4) {
        column.copy_from_slice(&r[(y - 3) * w..(y - 2) * w]);
        for row in r[(y - 2) * w..(y + 4) * w].chunks_exact(w) {
            // (`max`, not a conditional store, which becomes a slow masked store.)
            for (c, &v) in column.iter_mut().zip(row) {
                *c = c.max(v);
            }
        }
        for x in 4..w.saturating_sub(4) {
            let v = r[y * w + x];
            let window = column[x - 3..=x + 3].iter().fold(column[x], |m, &c| if c > m { c } else { m });
            if v < 0.01 * max || v < window {
                continue;
            }
            // Ties are broken towards the earlier pixel so a plateau yields one point.
            let beaten = |dx: isize, dy: isize| {
                let u = r[(y as isize + dy) as usize * w + (x as isize + dx) as usize];
                (dx, dy) != (0, 0) && (u > v || (u == v && (dy < 0 || (dy == 0 && dx < 0))))
            };
            if !(-rad..=rad).any(|dy| (-rad..=rad).any(|dx| beaten(dx, dy))) {
                out.push((v, DVec2::new(x as f64, y as f64)));
            }
        }
    }
    out.sort_by(|a, b| b.0.total_cmp(&a.0));
    out.truncate(2000);
    out.into_iter().map(|(_, p)| p).collect()
}

/// Samples on the circle of the X-junction check.
const RING: usize = 48;

/// The X-junction check's circle: `RING` samples, 4.5 px out. Each sample's offset, and for
/// a whole-pixel centre (every candidate is one, so all share the samples' sub-pixel phases)
/// its pixel offset and the bilinear weights of the 2×2 pixels there.
struct Ring {
    offsets: Vec<DVec2>,
    taps: Vec<(isize, isize, [f64; 4])>,
}

impl Ring {
    fn new() -> Ring {
        let offsets: Vec<DVec2> = (0..RING)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / RING as f64;
                4.5 * DVec2::new(a.cos(), a.sin())
            })
            .collect();
        let taps = offsets
            .iter()
            .map(|o| {
                let (x0, y0) = (o.x.floor(), o.y.floor());
                let (fx, fy) = (o.x - x0, o.y - y0);
                (
                    x0 as isize,
                    y0 as isize,
                    [(1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy],
                )
            })
            .collect();
        Ring { offsets, taps }
    }

    /// The circle's samples around `p` in `img` (bilinear, as `Grey::sample`).
    fn values(&self, img: &Grey, p: DVec2) -> [f64; RING] {
        let (w, h) = (img.width as isize, img.height as isize);
        let (x, y) = (p.x as isize, p.y as isize);
        // The taps reach 5 px to either side (4.5 px, and the next pixel).
        let whole = p.x.fract() == 0.0 && p.y.fract() == 0.0;
        if whole && x >= 5 && y >= 5 && x + 6 < w && y + 6 < h {
            let d = &img.data;
            return std::array::from_fn(|k| {
                let (dx, dy, wt) = self.taps[k];
                let i = ((y + dy) * w + x + dx) as usize;
                let (a, b, c, e) =
                    (d[i] as f64, d[i + 1] as f64, d[i + w as usize] as f64, d[i + w as usize + 1] as f64);
                wt[0] * a + wt[1] * b + wt[2] * c + wt[3] * e
            });
        }
        std::array::from_fn(|k| img.sample(p.x + self.offsets[k].x, p.y + self.offsets[k].y))
    }
}

/// Four alternating dark/light sectors on a circle around `p` (`ring`).
fn is_x_junction(img: &Grey, p: DVec2, ring: &Ring) -> bool {
    const N: usize = RING;
    let v = ring.values(img, p);
    let (lo, hi) = v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| (l.min(x), h.max(x)));
    if hi - lo < 0.03 {
        return false;
    }
    let mid = 0.5 * (lo + hi);
    let band = 0.15 * (hi - lo);
    // Hysteresis: a sample only changes the state when clearly above or below the middle.
    let state = |x: f64, prev: Option<bool>| {
        if x > mid + band {
            Some(true)
        } else if x < mid - band {
            Some(false)
        } else {
            prev
        }
    };
    // The state of every sample, after one lap to settle the hysteresis.
    let mut cur = None;
    for &x in &v {
        cur = state(x, cur);
    }
    let Some(mut cur) = cur else { return false };
    let mut changes = Vec::new();
    for (k, &x) in v.iter().enumerate() {
        let next = state(x, Some(cur)).unwrap_or(cur);
        if next != cur {
            changes.push(k);
            cur = next;
        }
    }
    if changes.len() != 4 {
        return false;
    }
    // Each sector must span a few samples (cyclic distances between changes), and the two
    // edges must be straight lines through the corner, so that each change has its opposite
    // half a turn away (within 1/8 of a turn): T- and L-junctions at a board's rim fail this.
    let gap = |a: usize, b: usize| (changes[b % 4] + N - changes[a]) % N;
    (0..4).all(|k| gap(k, k + 1) >= 3) && (0..2).all(|k| gap(k, k + 2).abs_diff(N / 2) <= N / 8)
}

/// Grows grids from seeds; returns grid coordinates → point for the first grid of the board's
/// size.
/// The board's window of the grid of candidates (module docs), and the size of the complete
/// grid around it when that is larger (`Found::larger_grid`).
#[allow(clippy::type_complexity)]
fn find_grid(
    points: &[DVec2],
    board: BoardSize,
    img: &Grey,
) -> Result<(HashMap<(i32, i32), DVec2>, Option<(usize, usize)>), Invalid> {
    let mut largest = (0usize, 0i32, 0i32);
    let ring = Ring::new();
    for seed in 0..points.len().min(60) {
        let s = points[seed];
        // The axes: the nearest candidates joined to the seed by a square's edge, the second
        // not parallel to the first. Nearness alone does not tell an edge from a diagonal: on
        // a steep board whose squares are foreshortened to a third along a diagonal, the
        // neighbour across a square's diagonal is nearer than the one along its long side.
        let contrast = local_contrast(img, s, &ring);
        let mut near: Vec<usize> = (0..points.len()).filter(|&i| i != seed).collect();
        near.sort_by(|&a, &b| points[a].distance(s).total_cmp(&points[b].distance(s)));
        let mut edges = near.into_iter().take(12).filter(|&i| is_edge(img, s, points[i], contrast));
        let Some(n1) = edges.next() else { continue };
        let u = (points[n1] - s).normalize();
        let Some(n2) = edges.find(|&i| (points[i] - s).normalize().dot(u).abs() < 0.95) else { continue };
        let grid = grow(points, seed, n1, n2, &|a, b| is_edge(img, a, b, contrast));
        let (imin, imax, jmin, jmax) = extent(&grid);
        let (ni, nj) = (imax - imin + 1, jmax - jmin + 1);
        if grid.len() > largest.0 {
            largest = (grid.len(), ni, nj);
        }
        // Every fully populated window of the board's size, in either orientation; the one
        // whose surrounding squares best continue the checker pattern is the board.
        let mut best: Option<(f64, i32, i32, i32, i32)> = None;
        for (wi, wj) in [(board.cols as i32, board.rows as i32), (board.rows as i32, board.cols as i32)] {
            for i0 in imin..=imax - wi + 1 {
                for j0 in jmin..=jmax - wj + 1 {
                    let full = (i0..i0 + wi).all(|i| (j0..j0 + wj).all(|j| grid.contains_key(&(i, j))));
                    if !full {
                        continue;
                    }
                    let at = |i: i32, j: i32| points[grid[&(i, j)]];
                    let score = ring_score(&at, i0, j0, wi, wj, img);
                    if best.is_none_or(|b| score > b.0) {
                        best = Some((score, i0, j0, wi, wj));
                    }
                }
            }
        }
        if let Some((score, i0, j0, wi, wj)) = best {
            if score >= 0.75 {
                let window = (i0..i0 + wi)
                    .flat_map(|i| (j0..j0 + wj).map(move |j| (i, j)))
                    .map(|(i, j)| ((i - i0, j - j0), points[grid[&(i, j)]]))
                    .collect();
                // The complete grid around the window: grown a row or column at a time while
                // the new one is fully populated.
                let full = |(a, b, c, d): (i32, i32, i32, i32)| {
                    (a..=b).all(|i| (c..=d).all(|j| grid.contains_key(&(i, j))))
                };
                let (mut a, mut b, mut c, mut d) = (i0, i0 + wi - 1, j0, j0 + wj - 1);
                loop {
                    let before = (a, b, c, d);
                    if full((a - 1, a - 1, c, d)) {
                        a -= 1;
                    }
                    if full((b + 1, b + 1, c, d)) {
                        b += 1;
                    }
                    if full((a, b, c - 1, c - 1)) {
                        c -= 1;
                    }
                    if full((a, b, d + 1, d + 1)) {
                        d += 1;
                    }
                    if (a, b, c, d) == before {
                        break;
                    }
                }
                let (ni, nj) = ((b - a + 1) as usize, (d - c + 1) as usize);
                let larger = (ni > wi as usize || nj > wj as usize).then_some({
                    if wi as usize == board.cols {
                        (ni, nj)
                    } else {
                        (nj, ni)
                    }
                });
                return Ok((window, larger));
            }
        }
    }
    Err(format!(
        "the largest grid of corners found spans {}×{} with {} corners, not a whole {}×{} board: is the whole board visible?",
        largest.1, largest.2, largest.0, board.cols, board.rows
    ).into())
}

/// Fraction of the squares around a window of corners whose brightness continues the checker
/// pattern of the squares inside it (1 for a whole board, about ½ for a window shifted onto
/// the board's margin).
fn ring_score(at: &dyn Fn(i32, i32) -> DVec2, i0: i32, j0: i32, wi: i32, wj: i32, img: &Grey) -> f64 {
    let centre = |a: DVec2, b: DVec2, c: DVec2, d: DVec2| (a + b + c + d) * 0.25;
    let value = |p: DVec2| img.sample(p.x, p.y);
    // Inside: parity 0 and parity 1 squares.
    let (mut s0, mut n0, mut s1, mut n1) = (0.0, 0, 0.0, 0);
    for i in i0..i0 + wi - 1 {
        for j in j0..j0 + wj - 1 {
            let v = value(centre(at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1)));
            if (i + j) % 2 == 0 {
                s0 += v;
                n0 += 1;
            } else {
                s1 += v;
                n1 += 1;
            }
        }
    }
    if n0 == 0 || n1 == 0 {
        return 0.0;
    }
    let (m0, m1) = (s0 / n0 as f64, s1 / n1 as f64);
    let mid = 0.5 * (m0 + m1);
    let even_is_light = m0 > m1;
    // Outside: extrapolate each border square half a row outwards; parity continues.
    let (mut ok, mut total) = (0, 0);
    let mut check = |p: DVec2, parity: i32| {
        let light = value(p) > mid;
        total += 1;
        if light == ((parity.rem_euclid(2) == 0) == even_is_light) {
            ok += 1;
        }
    };
    for i in i0..i0 + wi - 1 {
        for (j, jn, jo) in [(j0, j0 + 1, j0 - 1), (j0 + wj - 1, j0 + wj - 2, j0 + wj - 1)] {
            let edge = (at(i, j) + at(i + 1, j)) * 0.5;
            let inner = (at(i, jn) + at(i + 1, jn)) * 0.5;
            check(edge + (edge - inner) * 0.5, i + jo);
        }
    }
    for j in j0..j0 + wj - 1 {
        for (i, inn, io) in [(i0, i0 + 1, i0 - 1), (i0 + wi - 1, i0 + wi - 2, i0 + wi - 1)] {
            let edge = (at(i, j) + at(i, j + 1)) * 0.5;
            let inner = (at(inn, j) + at(inn, j + 1)) * 0.5;
            check(edge + (edge - inner) * 0.5, io + j);
        }
    }
    ok as f64 / total.max(1) as f64
}

/// The range of brightness on the X-junction check's circle (`ring`) around `p`.
fn local_contrast(img: &Grey, p: DVec2, ring: &Ring) -> f64 {
    let (lo, hi) = ring
        .values(img, p)
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| (l.min(v), h.max(v)));
    hi - lo
}

/// Whether corners `a` and `b` are joined by a square's edge: 1.5 px to either side of the
/// segment, at 30 %, 50 % and 70 % of its length, the image differs by at least 0.35 of the
/// local `contrast`, with the same sign. Across a square's diagonal both sides are the square.
fn is_edge(img: &Grey, a: DVec2, b: DVec2, contrast: f64) -> bool {
    let d = b - a;
    let len = d.length();
    if len < 2.0 {
        return false;
    }
    let n = DVec2::new(-d.y, d.x) * (1.5 / len);
    let diffs = [0.3, 0.5, 0.7].map(|t| {
        let m = a + d * t;
        img.sample(m.x + n.x, m.y + n.y) - img.sample(m.x - n.x, m.y - n.y)
    });
    let sign = diffs[0].signum();
    diffs.iter().all(|&x| x.signum() == sign && x.abs() > 0.35 * contrast)
}

fn extent<T>(grid: &HashMap<(i32, i32), T>) -> (i32, i32, i32, i32) {
    let mut e = (i32::MAX, i32::MIN, i32::MAX, i32::MIN);
    for &(i, j) in grid.keys() {
        e = (e.0.min(i), e.1.max(i), e.2.min(j), e.3.max(j));
    }
    e
}

/// Breadth-first growth of a grid from a seed and its two axis neighbours.
fn grow(
    points: &[DVec2],
    seed: usize,
    n1: usize,
    n2: usize,
    edge: &dyn Fn(DVec2, DVec2) -> bool,
) -> HashMap<(i32, i32), usize> {
    let mut grid: HashMap<(i32, i32), usize> = HashMap::new();
    let mut used = vec![false; points.len()];
    for (cell, k) in [((0, 0), seed), ((1, 0), n1), ((0, 1), n2)] {
        grid.insert(cell, k);
        used[k] = true;
    }
    let global = [points[n1] - points[seed], points[n2] - points[seed]];
    let mut queue: std::collections::VecDeque<(i32, i32)> = [(0, 0), (1, 0), (0, 1)].into_iter().collect();
    while let Some((i, j)) = queue.pop_front() {
        let p = points[grid[&(i, j)]];
        for (di, dj) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
            let cell = (i + di, j + dj);
            if grid.contains_key(&cell) {
                continue;
            }
            let at = |c: (i32, i32)| grid.get(&c).map(|&k| points[k]);
            // Step along (di, dj): from the opposite neighbour, else from a parallel row or
            // column, else the seed's axes.
            let step = if let Some(q) = at((i - di, j - dj)) {
                p - q
            } else if let (Some(a), Some(b)) = (at((i + di + dj, j + dj + di)), at((i + dj, j + di))) {
                a - b
            } else if let (Some(a), Some(b)) = (at((i + di - dj, j + dj - di)), at((i - dj, j - di))) {
                a - b
            } else {
                let axis = if di != 0 { global[0] } else { global[1] };
                axis * (di + dj) as f64
            };
            let predicted = p + step;
            let tol = 0.3 * step.length();
            let found = points
                .iter()
                .enumerate()
                .filter(|(k, q)| !used[*k] && q.distance(predicted) < tol)
                .min_by(|a, b| a.1.distance(predicted).total_cmp(&b.1.distance(predicted)))
                .filter(|(_, q)| edge(p, **q));
            if let Some((k, _)) = found {
                grid.insert(cell, k);
                used[k] = true;
                queue.push_back(cell);
            }
        }
    }
    grid
}

/// Orders grid points into rows of `cols` (see the module docs for the rule).
fn order(grid: &HashMap<(i32, i32), DVec2>, board: BoardSize, img: &Grey) -> Vec<DVec2> {
    let imax = grid.keys().map(|&(i, _)| i).max().unwrap_or(0);
    let transpose = (imax as usize + 1) != board.cols;
    let (c, r) = (board.cols as i32, board.rows as i32);
    let get = |i: i32, j: i32| if transpose { grid[&(j, i)] } else { grid[&(i, j)] };
    let mut pts: Vec<DVec2> =
        (0..r).flat_map(|j| (0..c).map(move |i| (i, j))).map(|(i, j)| get(i, j)).collect();
    let at = |pts: &Vec<DVec2>, i: i32, j: i32| pts[(j * c + i) as usize];
    // Handedness: the first row runs to the right of the first column (image y is down).
    let a = at(&pts, c - 1, 0) - at(&pts, 0, 0);
    let b = at(&pts, 0, r - 1) - at(&pts, 0, 0);
    if a.x * b.y - a.y * b.x < 0.0 {
        pts = (0..r).flat_map(|j| (0..c).map(move |i| (i, r - 1 - j))).map(|(i, j)| at(&pts, i, j)).collect();
    }
    // Colour: corner 0 sits diagonally next to the darker of the two diagonal corner squares.
    let outside = |pts: &Vec<DVec2>, i: i32, j: i32, di: i32, dj: i32| {
        let p = at(pts, i, j);
        let q = p + (p - at(pts, i + di, j + dj)) * 0.5;
        img.sample(q.x, q.y)
    };
    if outside(&pts, 0, 0, 1, 1) > outside(&pts, c - 1, r - 1, -1, -1) {
        pts.reverse(); // a 180° turn of the board
    }
    pts
}

/// Sub-pixel refinement of every corner (module docs, step 5); `g` is the image blurred with
/// σ = 1 px. The window follows the board: it spans ±`WINDOW` of the local square along each
/// of the board's two directions through the corner (a parallelogram, with Gaussian weights of
/// that width), at most `MAX_WINDOW_PX` along either, so on a steep view it stays inside the
/// four squares that meet at the corner instead of reaching the edges of the next ones.
fn refine(g: &Grey, pts: &[DVec2], board: BoardSize, opts: &DetectOptions) -> Vec<DVec2> {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx2")]
        fn avx2(g: &Grey, pts: &[DVec2], board: BoardSize, opts: &DetectOptions) -> Vec<DVec2> {
            refine_with(g, pts, board, opts)
        }
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2.
            return unsafe { avx2(g, pts, board, opts) };
        }
    }
    refine_with(g, pts, board, opts)
}

/// `refine`, inlined into a caller compiled for the processor's vectors (no fused
/// multiply-adds: the same corners at every width).
#[inline(always)]
fn refine_with(g: &Grey, pts: &[DVec2], board: BoardSize, opts: &DetectOptions) -> Vec<DVec2> {
    let (c, r) = (board.cols, board.rows);
    let at = |i: usize, j: usize| pts[j * c + i];
    // The local square along one direction: half the step between the two neighbours, or the
    // step to the one neighbour at the board's edge.
    let step = |prev: Option<DVec2>, here: DVec2, next: Option<DVec2>| match (prev, next) {
        (Some(a), Some(b)) => (b - a) * 0.5,
        (Some(a), None) => here - a,
        (None, Some(b)) => b - here,
        (None, None) => DVec2::ZERO,
    };
    pts.iter()
        .enumerate()
        .map(|(k, &p0)| {
            let (i, j) = (k % c, k / c);
            let a = step((i > 0).then(|| at(i - 1, j)), p0, (i + 1 < c).then(|| at(i + 1, j)));
            let b = step((j > 0).then(|| at(i, j - 1)), p0, (j + 1 < r).then(|| at(i, j + 1)));
            // Lattice coordinates (s, t) of an offset: offset = s·a + t·b.
            let det = a.x * b.y - a.y * b.x;
            let window = match opts.subpix_half_window {
                Some(hw) => Window::Square(hw as f64),
                None if det.abs() > 1.0 => {
                    // At most MAX_WINDOW_PX along either direction, at least 2 px.
                    let limit = |v: DVec2| WINDOW.min(MAX_WINDOW_PX / v.length()).max(2.0 / v.length());
                    Window::Lattice { a, b, det, sa: limit(a), sb: limit(b) }
                }
                None => Window::Square(2.0),
            };
            let reach = window.reach();
            let mut p = p0;
            // The box's pixels and gradient products, made again only when p's nearest pixel
            // moves (the weights alone follow p).
            let mut terms = BoxTerms::default();
            let mut centre = None;
            for _ in 0..50 {
                let (px, py) = (p.x.round() as isize, p.y.round() as isize);
                if centre != Some((px, py)) {
                    terms.fill(g, px, py, reach);
                    centre = Some((px, py));
                }
                window.weights(p, &terms.qx, &terms.qy, &mut terms.w);
                let w = &terms.w;
                let (a00, a01, a11) = (dot(w, &terms.xx), dot(w, &terms.xy), dot(w, &terms.yy));
                let (b0, b1) = (dot(w, &terms.bx), dot(w, &terms.by));
                let det = a00 * a11 - a01 * a01;
                if !(det.abs() > 1e-12) {
                    break;
                }
                let next = DVec2::new((a11 * b0 - a01 * b1) / det, (a00 * b1 - a01 * b0) / det);
                let moved = next.distance(p);
                p = next;
                if moved < 1e-4 {
                    break;
                }
            }
            // A corner that wandered off its window was not a clean corner: keep the pixel one.
            if p.is_finite() && window.weight(p - p0).is_some() {
                p
            } else {
                p0
            }
        })
        .collect()
}

/// Half-width of the sub-pixel window in lattice units (a fraction of the local square). A
/// window shaped by the board can reach further than a square one without meeting the edges
/// of the next squares: on noiseless renders (12 views, 64 spp), 0.45, 0.55 and 0.65 gave
/// 0.026, 0.022 and 0.019 px RMS on small boards but 0.030, 0.029 and 0.035 px at 70°–75°.
const WINDOW: f64 = 0.55;

/// Longest reach of the window along either board direction, in pixels: on the real
/// photographs a 12 px reach instead of 8 raised the RMS reprojection error from 0.176 to
/// 0.47 px (lens blur and residual curvature of the edges).
const MAX_WINDOW_PX: f64 = 8.0;

/// The sub-pixel window around a corner.
enum Window {
    /// ±hw pixels, Gaussian weights of σ = hw.
    Square(f64),
    /// Offsets s·a + t·b with |s| ≤ sa, |t| ≤ sb, Gaussian weights of σ = sa/√2, sb/√2 (a
    /// narrower weight than σ = sa: 0.029 against 0.031 px at 70°–75°, 0.022 against 0.024 px
    /// on small boards, on the same renders).
    Lattice { a: DVec2, b: DVec2, det: f64, sa: f64, sb: f64 },
}

/// A sub-pixel window's box of pixels around a corner: each pixel's position q, its
/// gradient's products gx², gx·gy, gy², and (gx², gx·gy)·q, (gx·gy, gy²)·q, the terms of the
/// normal equations; and the weights of the current iteration.
#[derive(Default)]
struct BoxTerms {
    qx: Vec<f64>,
    qy: Vec<f64>,
    xx: Vec<f64>,
    xy: Vec<f64>,
    yy: Vec<f64>,
    bx: Vec<f64>,
    by: Vec<f64>,
    w: Vec<f64>,
}

impl BoxTerms {
    /// The box of ±`reach` pixels around (px, py) of `g`.
    /// Gradients are central differences, taken only where a window looks, edges clamped.
    #[inline(always)]
    fn fill(&mut self, g: &Grey, px: isize, py: isize, reach: isize) {
        let all = [
            &mut self.qx,
            &mut self.qy,
            &mut self.xx,
            &mut self.xy,
            &mut self.yy,
            &mut self.bx,
            &mut self.by,
        ];
        for v in all {
            v.clear();
        }
        for qy in py - reach..=py + reach {
            for qx in px - reach..=px + reach {
                let (x, y) = (qx as f64, qy as f64);
                let ex = 0.5 * (g.at_clamped(qx + 1, qy) - g.at_clamped(qx - 1, qy)) as f64;
                let ey = 0.5 * (g.at_clamped(qx, qy + 1) - g.at_clamped(qx, qy - 1)) as f64;
                let (xx, xy, yy) = (ex * ex, ex * ey, ey * ey);
                self.qx.push(x);
                self.qy.push(y);
                self.xx.push(xx);
                self.xy.push(xy);
                self.yy.push(yy);
                self.bx.push(xx * x + xy * y);
                self.by.push(xy * x + yy * y);
            }
        }
        self.w.resize(self.qx.len(), 0.0);
    }
}

/// Σ aᵢ·bᵢ in four running sums, so that it vectorises.
#[inline(always)]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut s = [0.0f64; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = ca.remainder().iter().zip(cb.remainder()).map(|(x, y)| x * y).sum();
    for (x, y) in ca.zip(cb) {
        for k in 0..4 {
            s[k] += x[k] * y[k];
        }
    }
    (s[0] + s[1]) + (s[2] + s[3]) + tail
}

/// eˣ for the window's weights, x in [−2, 0]: (e^(x/8))⁸ with e^(x/8) as its Taylor series
/// to the 12th power (truncation below 10⁻¹⁷ relative there), by Horner's rule; a polynomial
/// where libm's exp is a call per pixel, which cost a fifth of the detection.
#[inline(always)]
fn exp_window(x: f64) -> f64 {
    let y = x * 0.125;
    let mut p = INV_FACTORIAL[12];
    for c in INV_FACTORIAL[..12].iter().rev() {
        // (Not `mul_add`: without FMA in the target it is a call to libm.)
        p = p * y + c;
    }
    let p2 = p * p;
    let p4 = p2 * p2;
    p4 * p4
}

/// 1/n! for n = 0 … 12.
const INV_FACTORIAL: [f64; 13] = {
    let mut a = [1.0; 13];
    let mut n = 1;
    while n < 13 {
        a[n] = a[n - 1] / n as f64;
        n += 1;
    }
    a
};

impl Window {
    /// The weight of every pixel (qx, qy) of a box around the corner at `p` into `w`: 0
    /// outside the window (`weight`, branch-free so that it vectorises).
    #[inline(always)]
    fn weights(&self, p: DVec2, qx: &[f64], qy: &[f64], w: &mut [f64]) {
        match *self {
            Window::Square(hw) => {
                let k = -1.0 / (2.0 * hw * hw);
                for ((w, &x), &y) in w.iter_mut().zip(qx).zip(qy) {
                    let (dx, dy) = (x - p.x, y - p.y);
                    let e = exp_window(k * (dx * dx + dy * dy));
                    *w = if dx.abs() <= hw && dy.abs() <= hw { e } else { 0.0 };
                }
            }
            Window::Lattice { a, b, det, sa, sb } => {
                let (ia, ib) = (1.0 / (det * sa), 1.0 / (det * sb));
                for ((w, &x), &y) in w.iter_mut().zip(qx).zip(qy) {
                    let (dx, dy) = (x - p.x, y - p.y);
                    // s/sa and t/sb (`weight`).
                    let u = (dx * b.y - dy * b.x) * ia;
                    let v = (a.x * dy - a.y * dx) * ib;
                    let e = exp_window(-(u * u + v * v));
                    *w = if u.abs() <= 1.0 && v.abs() <= 1.0 { e } else { 0.0 };
                }
            }
        }
    }

    /// The pixel box that holds the window.
    fn reach(&self) -> isize {
        match *self {
            Window::Square(hw) => hw.ceil() as isize,
            Window::Lattice { a, b, sa, sb, .. } => {
                let (ea, eb) = (a * sa, b * sb);
                (ea.x.abs() + eb.x.abs()).max(ea.y.abs() + eb.y.abs()).ceil() as isize
            }
        }
    }

    /// The weight of offset `d` from the corner, `None` outside the window.
    fn weight(&self, d: DVec2) -> Option<f64> {
        match *self {
            Window::Square(hw) => {
                (d.x.abs() <= hw && d.y.abs() <= hw).then(|| (-d.length_squared() / (2.0 * hw * hw)).exp())
            }
            Window::Lattice { a, b, det, sa, sb } => {
                let s = (d.x * b.y - d.y * b.x) / det;
                let t = (a.x * d.y - a.y * d.x) / det;
                (s.abs() <= sa && t.abs() <= sb).then(|| (-((s / sa).powi(2) + (t / sb).powi(2))).exp())
            }
        }
    }
}
