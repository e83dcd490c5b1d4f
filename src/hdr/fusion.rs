//! Exposure fusion: Mertens, Kautz & Van Reeth, "Exposure Fusion", Pacific Graphics 2007.
//!
//! An LDR picture blended straight from the frames, with no response and no radiance: each
//! frame's pixels are weighed by
//!
//!   W = C^ω_c · S^ω_s · E^ω_e + 10⁻¹²
//!
//! with C the absolute Laplacian of the frame's grey values (contrast), S the standard
//! deviation of R, G and B (saturation) and E = Π_c exp(−(I_c − ½)²/(2·0.2²)) (well-exposedness),
//! values I in [0, 1] as the codes over the top code. The weights are normalised over the
//! frames per pixel and the frames blended level by level: the Laplacian pyramid of each
//! frame times the Gaussian pyramid of its weights, summed, then collapsed. The pyramid uses
//! the 5-tap binomial kernel [1 4 6 4 1]/16 with mirrored borders (reflect-101), as OpenCV's
//! `pyrDown`/`pyrUp` and `MergeMertens` do, over ⌊log₂ min(width, height)⌋ levels. The result
//! is in the frames' own encoding (display-referred, not linear) and clamped to [0, 1].
//!
//! Hand-written: the image crates offer no pyramid, and the blend needs f32 pyramids of
//! weights and signed differences.

use super::Input;
use crate::error::Invalid;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The exponents of the three measures (Mertens et al.'s defaults: 1, 1, 1).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Mertens {
    #[serde(default = "one")]
    pub contrast: f64,
    #[serde(default = "one")]
    pub saturation: f64,
    #[serde(default = "one")]
    pub exposedness: f64,
}

fn one() -> f64 {
    1.0
}

impl Default for Mertens {
    fn default() -> Mertens {
        Mertens { contrast: 1.0, saturation: 1.0, exposedness: 1.0 }
    }
}

impl Mertens {
    pub fn validate(&self) -> Result<(), Invalid> {
        for (name, v) in
            [("contrast", self.contrast), ("saturation", self.saturation), ("exposedness", self.exposedness)]
        {
            if !(v.is_finite() && (0.0..=10.0).contains(&v)) {
                return Err(format!("fusion {name} exponent = {v}: expected 0 to 10").into());
            }
        }
        Ok(())
    }
}

/// An f32 image of `c` interleaved channels: 1 (weights) or 3 (RGB).
#[derive(Clone, Debug)]
struct Plane {
    w: usize,
    h: usize,
    c: usize,
    data: Vec<f32>,
}

impl Plane {
    fn zeros(w: usize, h: usize, c: usize) -> Plane {
        Plane { w, h, c, data: vec![0.0; w * h * c] }
    }
}

/// Mirrors an index into 0..n without repeating the edge (reflect-101: −1 → 1, n → n − 2).
fn mirror(i: isize, n: usize) -> usize {
    let n = n as isize;
    if n == 1 {
        return 0;
    }
    let period = 2 * (n - 1);
    let mut k = i.rem_euclid(period);
    if k >= n {
        k = period - k;
    }
    k as usize
}

const TAPS: [f32; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];

/// Blurs with the 5-tap kernel and keeps every second sample into `dst` (⌈w/2⌉ × ⌈h/2⌉, as
/// many channels). The vertical pass runs first, over whole rows (which vectorises), the
/// horizontal one on its output; `line` holds one row of it.
fn pyr_down_into(src: &Plane, dst: &mut Plane, line: &mut Vec<f32>) {
    let (w, h, c) = (src.w, src.h, src.c);
    debug_assert!(dst.w == w.div_ceil(2) && dst.h == h.div_ceil(2) && dst.c == c);
    let row = |y: isize| {
        let sy = mirror(y, h);
        &src.data[sy * w * c..(sy + 1) * w * c]
    };
    line.resize(w * c, 0.0);
    for (y, out) in dst.data.chunks_exact_mut(dst.w * c).enumerate() {
        let y = 2 * y as isize;
        let (a, b, m, d, e) = (row(y - 2), row(y - 1), row(y), row(y + 1), row(y + 2));
        let outer = a.iter().zip(e).zip(b.iter().zip(d));
        for ((t, m), ((a, e), (b, d))) in line.iter_mut().zip(m).zip(outer) {
            *t = (a + e + 4.0 * (b + d) + 6.0 * m) * (1.0 / 16.0);
        }
        // Planes hold one channel (weights) or three (RGB).
        if c == 1 {
            down_row::<1>(line, out, w)
        } else {
            down_row::<3>(line, out, w)
        }
    }
}

/// `pyr_down_into` a new plane.
#[cfg(test)]
fn pyr_down(src: &Plane) -> Plane {
    let mut dst = Plane::zeros(src.w.div_ceil(2), src.h.div_ceil(2), src.c);
    pyr_down_into(src, &mut dst, &mut Vec::new());
    dst
}

/// The horizontal pass of `pyr_down` on one row of `C` interleaved channels; `C` fixed at
/// compile time so the inner loops unroll.
fn down_row<const C: usize>(line: &[f32], out: &mut [f32], w: usize) {
    let dw = out.len() / C;
    // Inside: outputs 1 .. while 2x + 2 < w.
    let inside_end = if w >= 3 { ((w - 3) / 2 + 1).min(dw) } else { 0 };
    for x in 1..inside_end {
        let a = &line[(2 * x - 2) * C..(2 * x + 3) * C];
        let o = &mut out[x * C..(x + 1) * C];
        for ch in 0..C {
            o[ch] = (a[ch] + a[4 * C + ch] + 4.0 * (a[C + ch] + a[3 * C + ch]) + 6.0 * a[2 * C + ch])
                * (1.0 / 16.0);
        }
    }
    for x in std::iter::once(0).chain(inside_end.max(1)..dw) {
        down_edge(line, &mut out[x * C..(x + 1) * C], x, w, C);
    }
}

/// One output of `pyr_down`'s horizontal pass with mirrored taps.
fn down_edge(line: &[f32], o: &mut [f32], x: usize, w: usize, c: usize) {
    o.fill(0.0);
    for (k, t) in TAPS.iter().enumerate() {
        let at = mirror(2 * x as isize + k as isize - 2, w) * c;
        o.iter_mut().zip(&line[at..at + c]).for_each(|(o, v)| *o += t * v);
    }
}

/// The source samples and weights output sample `x` of an expand to `n_dst` draws on: the
/// even p = x + k − 2, mirrored on the output's grid (which keeps the weights' sum at 1 at
/// both ends, for an even or odd length), give source p/2 with twice the tap.
fn up_taps(x: usize, n_src: usize, n_dst: usize) -> Vec<(usize, f32)> {
    if n_dst == 1 {
        return vec![(0, 1.0)];
    }
    let mut taps: Vec<(usize, f32)> = Vec::with_capacity(3);
    for (k, t) in TAPS.iter().enumerate() {
        let p = mirror(x as isize + k as isize - 2, n_dst);
        if p.is_multiple_of(2) && p / 2 < n_src {
            match taps.iter_mut().find(|e| e.0 == p / 2) {
                Some(e) => e.1 += 2.0 * t,
                None => taps.push((p / 2, 2.0 * t)),
            }
        }
    }
    taps
}

/// The expand of `src` to `w` × `h` (each 2·src or 2·src − 1), handed to `each` row by row
/// (row index, values): zeros inserted between the samples, then the 5-tap kernel times 4, so
/// a constant stays constant. Inside, even x = 2s gets (src[s−1] + 6 src[s] + src[s+1])/8 and
/// odd x = 2s + 1 the mean of src[s] and src[s+1]; rows likewise. Row by row, so a caller
/// adds or subtracts the expand without a full-size copy of it; `rows` and `out` are working
/// buffers (the horizontal pass, one output row), kept by the caller from call to call.
fn pyr_up_rows(
    src: &Plane,
    w: usize,
    h: usize,
    (rows, out): (&mut Vec<f32>, &mut Vec<f32>),
    mut each: impl FnMut(usize, &[f32]),
) {
    let c = src.c;
    let (sw, sh) = (src.w, src.h);
    // The horizontal pass over the source's rows (half the output's height).
    rows.resize(w * sh * c, 0.0);
    out.resize(w * c, 0.0);
    for (line, out) in src.data.chunks_exact(sw * c).zip(rows.chunks_exact_mut(w * c)) {
        if c == 1 {
            up_row::<1>(line, out, w)
        } else {
            up_row::<3>(line, out, w)
        }
    }
    let row = |s: usize| &rows[s * w * c..(s + 1) * w * c];
    for y in 0..h {
        let s = y / 2;
        if s >= 1 && s + 1 < sh {
            let (a, b, d) = (row(s - 1), row(s), row(s + 1));
            if y % 2 == 0 {
                for (o, (a, (b, d))) in out.iter_mut().zip(a.iter().zip(b.iter().zip(d))) {
                    *o = (a + 6.0 * b + d) * 0.125;
                }
            } else {
                for (o, (b, d)) in out.iter_mut().zip(b.iter().zip(d)) {
                    *o = 0.5 * (b + d);
                }
            }
        } else {
            out.fill(0.0);
            for (sy, t) in up_taps(y, sh, h) {
                out.iter_mut().zip(row(sy)).for_each(|(o, v)| *o += t * v);
            }
        }
        each(y, out);
    }
}

/// The horizontal pass of `pyr_up_rows` on one row of `C` interleaved channels: outputs 2s
/// and 2s + 1 together for each source sample s inside, the ends with mirrored taps.
fn up_row<const C: usize>(line: &[f32], out: &mut [f32], w: usize) {
    let sw = line.len() / C;
    let mut done_to = 2.min(w);
    for s in 1..sw.saturating_sub(1) {
        if 2 * s + 1 >= w {
            break;
        }
        let a = &line[(s - 1) * C..(s + 2) * C];
        let o = &mut out[2 * s * C..(2 * s + 2) * C];
        for ch in 0..C {
            o[ch] = (a[ch] + 6.0 * a[C + ch] + a[2 * C + ch]) * 0.125;
            o[C + ch] = 0.5 * (a[C + ch] + a[2 * C + ch]);
        }
        done_to = 2 * s + 2;
    }
    for x in (0..2.min(w)).chain(done_to..w) {
        up_edge(line, &mut out[x * C..(x + 1) * C], x, w, C);
    }
}

/// One output of the expand's horizontal pass with mirrored taps (`up_taps`).
fn up_edge(line: &[f32], o: &mut [f32], x: usize, w: usize, c: usize) {
    o.fill(0.0);
    for (sx, t) in up_taps(x, line.len() / c, w) {
        o.iter_mut().zip(&line[sx * c..(sx + 1) * c]).for_each(|(o, v)| *o += t * v);
    }
}

/// `pyr_up_rows` gathered into a plane.
#[cfg(test)]
fn pyr_up(src: &Plane, w: usize, h: usize) -> Plane {
    let mut dst = Plane::zeros(w, h, src.c);
    let n = w * src.c;
    let mut scratch = (Vec::new(), Vec::new());
    pyr_up_rows(src, w, h, (&mut scratch.0, &mut scratch.1), |y, row| {
        dst.data[y * n..(y + 1) * n].copy_from_slice(row)
    });
    dst
}

/// Levels below the full image: ⌊log₂ min(w, h)⌋ (OpenCV's choice), at least 0.
fn levels(w: usize, h: usize) -> usize {
    (w.min(h).max(1) as f64).log2().floor() as usize
}

/// Per code value: the value in [0, 1], and the well-exposedness exp(−(v − ½)²/(2·0.2²)), so
/// the weights need no division or exp per pixel.
struct Tables {
    value: Vec<f32>,
    exposedness: Vec<f32>,
}

impl Tables {
    fn new(levels: usize) -> Tables {
        let top = (levels - 1) as f32;
        let value: Vec<f32> = (0..levels).map(|z| z as f32 / top).collect();
        let exposedness = value.iter().map(|v| (-(v - 0.5).powi(2) / (2.0 * 0.2 * 0.2)).exp()).collect();
        Tables { value, exposedness }
    }
}

/// The unnormalised weight of every pixel of one frame (module docs) into `out` (`w` × `h`):
/// `codes` interleaved RGB; `grey` a working buffer for the frame's grey values.
fn weights(
    codes: &[u16],
    w: usize,
    h: usize,
    tables: &Tables,
    p: &Mertens,
    out: &mut [f32],
    grey: &mut Vec<f32>,
) {
    let value = &tables.value;
    grey.clear();
    grey.extend(
        codes.chunks_exact(3).map(|z| {
            0.299 * value[z[0] as usize] + 0.587 * value[z[1] as usize] + 0.114 * value[z[2] as usize]
        }),
    );
    // The paper's exponents (all 1) get a loop without `powf`: a branch on the exponent
    // inside the loop is compiled to a select that calls `powf` anyway.
    if *p == Mertens::default() {
        weights_with::<true>(codes, w, h, tables, p, out, grey)
    } else {
        weights_with::<false>(codes, w, h, tables, p, out, grey)
    }
}

fn weights_with<const ONES: bool>(
    codes: &[u16],
    w: usize,
    h: usize,
    tables: &Tables,
    p: &Mertens,
    out: &mut [f32],
    grey: &[f32],
) {
    if w == 0 {
        return;
    }
    let (value, exposedness) = (&tables.value, &tables.exposedness);
    let (ec, es, ee) = (p.contrast as f32, p.saturation as f32, p.exposedness as f32);
    // One row at a time: the table look-ups first (R, G, B apart, and the well-exposedness),
    // then the rest in a loop over plain arrays, which vectorises.
    let (mut rgb, mut expo) = (vec![[0.0f32; 3]; w], vec![0.0f32; w]);
    for (y, row) in out.chunks_exact_mut(w).enumerate() {
        let line = |dy: isize| {
            let sy = mirror(y as isize + dy, h);
            &grey[sy * w..(sy + 1) * w]
        };
        let (up, mid, down) = (line(-1), line(0), line(1));
        let pixels = codes[y * w * 3..(y + 1) * w * 3].chunks_exact(3);
        for ((q, e), z) in rgb.iter_mut().zip(expo.iter_mut()).zip(pixels) {
            *q = [value[z[0] as usize], value[z[1] as usize], value[z[2] as usize]];
            *e = exposedness[z[0] as usize] * exposedness[z[1] as usize] * exposedness[z[2] as usize];
        }
        let weight = |q: &[f32; 3], e: f32, lap: f32| {
            let mean = (q[0] + q[1] + q[2]) * (1.0 / 3.0);
            let sat = (((q[0] - mean).powi(2) + (q[1] - mean).powi(2) + (q[2] - mean).powi(2)) / 3.0).sqrt();
            if ONES {
                lap.abs() * sat * e + 1e-12
            } else {
                lap.abs().powf(ec) * sat.powf(es) * e.powf(ee) + 1e-12
            }
        };
        // Mirrored neighbours (reflect-101) at both ends, the inside from shifted slices.
        let lap_at = |x: usize| {
            let left = if x > 0 { x - 1 } else { 1.min(w - 1) };
            let right = if x + 1 < w { x + 1 } else { x.saturating_sub(1) };
            up[x] + down[x] + mid[left] + mid[right] - 4.0 * mid[x]
        };
        for x in [0, w - 1] {
            row[x] = weight(&rgb[x], expo[x], lap_at(x));
        }
        if w > 2 {
            let inside = row[1..w - 1].iter_mut().zip(&rgb[1..w - 1]).zip(&expo[1..w - 1]);
            let around = up[1..w - 1].iter().zip(&down[1..w - 1]).zip(mid[..w - 2].iter().zip(&mid[2..]));
            for (((o, q), &e), (((u, d), (l, r)), m)) in inside.zip(around.zip(&mid[1..w - 1])) {
                *o = weight(q, e, u + d + l + r - 4.0 * m);
            }
        }
    }
}

/// One frame's pyramids, kept from frame to frame by each part of the blend (`mertens`):
/// allocated anew for every frame and level, the first touch of their fresh pages (and, freed
/// from several threads, the TLB shootdowns) cost more than the arithmetic on them.
struct Scratch {
    /// The frame's values and their Gaussian pyramid, RGB.
    gauss: Vec<Plane>,
    /// Its normalised weights and their Gaussian pyramid.
    weights: Vec<Plane>,
    /// The frame's grey values (`weights`), and working rows of `pyr_down_into` and
    /// `pyr_up_rows`.
    grey: Vec<f32>,
    line: Vec<f32>,
    rows: Vec<f32>,
    out: Vec<f32>,
}

impl Scratch {
    fn new(sizes: &[(usize, usize)]) -> Scratch {
        Scratch {
            gauss: sizes.iter().map(|&(w, h)| Plane::zeros(w, h, 3)).collect(),
            weights: sizes.iter().map(|&(w, h)| Plane::zeros(w, h, 1)).collect(),
            grey: Vec::new(),
            line: Vec::new(),
            rows: Vec::new(),
            out: Vec::new(),
        }
    }
}

/// One frame's share of the result: its Laplacian pyramid times its weights' Gaussian
/// pyramid, added into `acc` (one plane per level). `s.gauss[0]` and `s.weights[0]` hold the
/// frame's values and normalised weights.
fn blend_into(acc: &mut [Plane], s: &mut Scratch) {
    let depth = acc.len() - 1;
    for l in 0..depth {
        let (fine, coarse) = s.gauss.split_at_mut(l + 1);
        pyr_down_into(&fine[l], &mut coarse[0], &mut s.line);
        let (fine, coarse) = s.weights.split_at_mut(l + 1);
        pyr_down_into(&fine[l], &mut coarse[0], &mut s.line);
    }
    // acc += (G_l − expand(G_{l+1}))·W_l, a row at a time; the coarsest level adds G·W.
    let mac = |acc: &mut [f32], g: &[f32], up: Option<&[f32]>, wt: &[f32]| {
        let (acc, g) = (acc.chunks_exact_mut(3), g.chunks_exact(3));
        match up {
            Some(up) => {
                for (((o, g), u), wt) in acc.zip(g).zip(up.chunks_exact(3)).zip(wt) {
                    o[0] += (g[0] - u[0]) * wt;
                    o[1] += (g[1] - u[1]) * wt;
                    o[2] += (g[2] - u[2]) * wt;
                }
            }
            None => {
                for ((o, g), wt) in acc.zip(g).zip(wt) {
                    o[0] += g[0] * wt;
                    o[1] += g[1] * wt;
                    o[2] += g[2] * wt;
                }
            }
        }
    };
    for (l, a) in acc.iter_mut().enumerate() {
        let (w, h) = (a.w, a.h);
        let (g, wt, a) = (&s.gauss[l].data, &s.weights[l].data, &mut a.data);
        if l < depth {
            pyr_up_rows(&s.gauss[l + 1], w, h, (&mut s.rows, &mut s.out), |y, up| {
                let (r, p) = (y * w * 3..(y + 1) * w * 3, y * w..(y + 1) * w);
                mac(&mut a[r.clone()], &g[r], Some(up), &wt[p]);
            });
        } else {
            mac(a, g, None, wt);
        }
    }
}

/// The partial sums of the weights and of the blend: frame j goes to part j mod PARTS, each
/// part takes its frames in order into its own sum, and the parts are added in order, so the
/// result does not depend on the thread count; up to PARTS threads work at once.
const PARTS: usize = 4;

/// Mertens et al.'s fusion of the stack (module docs): interleaved RGB in [0, 1].
pub fn mertens(input: &Input, p: &Mertens) -> Vec<f32> {
    let (w, h) = (input.width, input.height);
    let depth = levels(w, h);
    let frames = input.frames.len();
    let tables = Tables::new(input.levels);
    let parts = PARTS.min(frames);
    // The weights' sum over the frames first; each frame's weights are computed again as it
    // is blended, which costs less than keeping them (an f32 per pixel and frame, freshly
    // allocated memory whose first touch costs more than the arithmetic).
    let totals: Vec<Vec<f32>> = (0..parts)
        .into_par_iter()
        .map(|part| {
            let (mut total, mut wj, mut grey) = (vec![0.0f32; w * h], vec![0.0f32; w * h], Vec::new());
            for j in (part..frames).step_by(PARTS) {
                weights(&input.frames[j].codes, w, h, &tables, p, &mut wj, &mut grey);
                total.iter_mut().zip(&wj).for_each(|(t, v)| *t += v);
            }
            total
        })
        .collect();
    let mut totals = totals.into_iter();
    let Some(mut total) = totals.next() else { return Vec::new() };
    for t in totals {
        total.iter_mut().zip(&t).for_each(|(a, b)| *a += b);
    }
    let sizes: Vec<(usize, usize)> =
        std::iter::successors(Some((w, h)), |&(a, b)| Some((a.div_ceil(2), b.div_ceil(2))))
            .take(depth + 1)
            .collect();
    let zeros = || sizes.iter().map(|&(a, b)| Plane::zeros(a, b, 3)).collect::<Vec<Plane>>();
    let parts: Vec<Vec<Plane>> = (0..parts)
        .into_par_iter()
        .map(|part| {
            let mut acc = zeros();
            let mut s = Scratch::new(&sizes);
            for j in (part..frames).step_by(PARTS) {
                let codes = &input.frames[j].codes;
                weights(codes, w, h, &tables, p, &mut s.weights[0].data, &mut s.grey);
                s.weights[0].data.iter_mut().zip(&total).for_each(|(v, t)| *v /= t);
                let values = tables.value.as_slice();
                s.gauss[0].data.iter_mut().zip(codes).for_each(|(v, &z)| *v = values[z as usize]);
                blend_into(&mut acc, &mut s);
            }
            acc
        })
        .collect();
    let mut parts = parts.into_iter();
    let Some(mut acc) = parts.next() else { return Vec::new() };
    for part in parts {
        for (x, y) in acc.iter_mut().zip(&part) {
            x.data.iter_mut().zip(&y.data).for_each(|(u, v)| *u += v);
        }
    }
    let (mut rows, mut out) = (Vec::new(), Vec::new());
    for l in (1..acc.len()).rev() {
        let (finer, coarser) = acc.split_at_mut(l);
        let fine = &mut finer[l - 1];
        let n = fine.w * 3;
        pyr_up_rows(&coarser[0], fine.w, fine.h, (&mut rows, &mut out), |y, up| {
            fine.data[y * n..(y + 1) * n].iter_mut().zip(up).for_each(|(a, b)| *a += b);
        });
    }
    let top = acc.swap_remove(0);
    top.data.into_iter().map(|v| if v.is_finite() { v.clamp(0.0, 1.0) } else { 0.0 }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane(w: usize, h: usize, f: impl Fn(usize, usize) -> f32) -> Plane {
        let data = (0..w * h).map(|i| f(i % w, i / w)).collect();
        Plane { w, h, c: 1, data }
    }

    /// A constant survives both pyramid steps at any size, odd or even; the expand of the
    /// reduce of a smooth ramp is the ramp away from the borders (the kernel keeps linear functions).
    #[test]
    fn pyramid_steps_keep_constants() {
        for (w, h) in [(1, 1), (2, 3), (7, 5), (16, 9)] {
            let p = plane(w, h, |_, _| 0.25);
            let d = pyr_down(&p);
            assert_eq!((d.w, d.h), (w.div_ceil(2), h.div_ceil(2)));
            assert!(d.data.iter().all(|v| (v - 0.25).abs() < 1e-6), "{w}×{h} down");
            let u = pyr_up(&d, w, h);
            assert!(u.data.iter().all(|v| (v - 0.25).abs() < 1e-6), "{w}×{h} up: {:?}", u.data);
        }
        let ramp = plane(32, 32, |x, _| x as f32);
        let back = pyr_up(&pyr_down(&ramp), 32, 32);
        for x in 4..28 {
            assert!((back.data[16 * 32 + x] - x as f32).abs() < 1e-4, "x {x}: {}", back.data[16 * 32 + x]);
        }
    }

    /// The same fusion, to the bit, on 1, 2 or 3 threads (the partial sums are fixed), for
    /// frames of odd and even size and a stack of fewer frames than parts.
    #[test]
    fn fusion_does_not_depend_on_the_thread_count() {
        for (w, h, n) in [(37, 23, 7), (16, 16, 2)] {
            let frames = (0..n)
                .map(|k| {
                    let codes =
                        (0..w * h * 3).map(|i| ((i * 37 + i / 3 * 11 + k * 50) % 256) as u16).collect();
                    crate::hdr::Frame { name: format!("f{k}"), time_s: 1.0 / (k + 1) as f64, codes }
                })
                .collect();
            let input = Input { width: w, height: h, levels: 256, frames, usable: None };
            let on = |threads: usize| {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                pool.install(|| mertens(&input, &Mertens::default()))
            };
            let one = on(1);
            assert_eq!(one.len(), w * h * 3);
            assert!(one.iter().all(|v| (0.0..=1.0).contains(v)));
            assert_eq!(one, on(2), "{w}×{h}, {n} frames");
            assert_eq!(one, on(3), "{w}×{h}, {n} frames");
        }
    }

    #[test]
    fn mirror_reflects_without_repeating_the_edge() {
        assert_eq!([-2, -1, 0, 4, 5, 6].map(|i| mirror(i, 5)), [2, 1, 0, 4, 3, 2]);
        assert_eq!(mirror(-3, 1), 0);
    }
}
