//! Scale- and rotation-invariant keypoints with SIFT descriptors: Lowe, "Distinctive image
//! features from scale-invariant keypoints", IJCV 60(2), 2004, with RootSIFT (Arandjelović &
//! Zisserman, "Three things everyone should know to improve object retrieval", CVPR 2012).
//!
//! - **Scale space.** Octaves of `levels + 3` Gaussian images L(x, y, σ) with σ = σ₀·2^(s/S)
//!   (σ₀ = 1.6, S = `levels`), the input taken as already blurred by 0.5 px; each octave
//!   starts from the one before's image at 2σ₀, every second pixel. Differences of
//!   neighbouring levels, D = L(kσ) − L(σ), approximate (k − 1)·σ²∇²L.
//! - **Keypoints.** Extrema of D among their 26 neighbours in space and scale, refined by the
//!   quadratic fit x̂ = −(∂²D/∂x²)⁻¹·∂D/∂x (up to five moves to a neighbouring sample when
//!   |x̂| > ½ in any of x, y, s); kept when |D(x̂)| ≥ `peak_threshold` and the ratio of the
//!   principal curvatures is below `edge_threshold` (tr²H/det H < (r + 1)²/r).
//! - **Orientation.** A 36-bin histogram of gradient directions within 3·1.5σ, weighted by the
//!   magnitude and a Gaussian of 1.5σ, smoothed, each peak within 80 % of the highest one a
//!   keypoint of its own, interpolated by a parabola.
//! - **Descriptor.** 4 × 4 cells of 3σ, 8 orientation bins each, gradients rotated to the
//!   keypoint's orientation, Gaussian-weighted (σ = half the window) and spread trilinearly;
//!   normalised, clipped at 0.2, normalised again; then RootSIFT: L1-normalised and square-
//!   rooted, so the Euclidean distance between descriptors is the Hellinger distance between
//!   the histograms. Stored as bytes (×512, saturated, as OpenCV and VLFeat store theirs).
//!
//! Pixel coordinates follow OpenCV's convention (centres at integers). Angles are measured
//! from +x towards +y (image y down). The blur, the extrema search and the descriptors run
//! on all cores; the result does not depend on the thread count.

use crate::image::filter::Grey;
use rayon::prelude::*;

/// One keypoint, in input-image pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Keypoint {
    pub x: f32,
    pub y: f32,
    /// Scale: the σ of the Gaussian it was found at, in input pixels.
    pub sigma: f32,
    /// Orientation in radians, from +x towards +y.
    pub angle: f32,
    /// |D| at the refined extremum (contrast).
    pub response: f32,
}

/// Keypoints and their 128-byte descriptors, in the same order.
#[derive(Clone, Debug, Default)]
pub struct Features {
    pub keypoints: Vec<Keypoint>,
    pub descriptors: Vec<[u8; 128]>,
}

/// Detector settings (defaults as COLMAP's SIFT extraction).
#[derive(Clone, Copy, Debug)]
pub struct Options {
    /// Keep at most this many, the highest-contrast ones (COLMAP: 8192).
    pub max_features: usize,
    /// Scale levels per octave, S (3).
    pub levels: usize,
    /// Smallest |D| of a kept extremum, for images in [0, 1] (COLMAP: 0.02/S).
    pub peak_threshold: f32,
    /// Largest ratio of principal curvatures (10).
    pub edge_threshold: f32,
    /// −1 doubles the image first (more small keypoints, four times the work); 0 starts at
    /// the input's resolution.
    pub first_octave: i32,
}

impl Default for Options {
    fn default() -> Options {
        Options {
            max_features: 8192,
            levels: 3,
            peak_threshold: 0.02 / 3.0,
            edge_threshold: 10.0,
            first_octave: 0,
        }
    }
}

const SIGMA0: f32 = 1.6;
const INPUT_SIGMA: f32 = 0.5;
/// Pixels left out at each octave's border (the descriptor window needs room).
const BORDER: usize = 5;
const ORI_BINS: usize = 36;
const DESC_CELLS: usize = 4;
const DESC_BINS: usize = 8;

/// One octave: its Gaussian levels, their differences, and the pixel size in input pixels.
struct Octave {
    gauss: Vec<Grey>,
    dog: Vec<Grey>,
    step: f32,
}

/// Detects keypoints and computes their descriptors on a grey image with values in [0, 1].
pub fn detect(image: &Grey, opts: &Options) -> Features {
    let levels = opts.levels.max(1);
    let mut base = if opts.first_octave < 0 { upsample(image) } else { image.clone() };
    let first_step = if opts.first_octave < 0 { 0.5 } else { 1.0 };
    let input_sigma = INPUT_SIGMA / first_step;
    base = base.blur(((SIGMA0 * SIGMA0 - input_sigma * input_sigma).max(0.01)).sqrt() as f64);
    let k = 2f32.powf(1.0 / levels as f32);
    let mut octaves = Vec::new();
    let mut step = first_step;
    loop {
        if base.width < 2 * BORDER + 8 || base.height < 2 * BORDER + 8 {
            break;
        }
        let mut gauss = vec![base];
        for s in 1..levels + 3 {
            // Blur from σ₀·k^(s−1) to σ₀·k^s.
            let prev = SIGMA0 * k.powi(s as i32 - 1);
            let inc = prev * (k * k - 1.0).sqrt();
            let next = gauss[s - 1].blur(inc as f64);
            gauss.push(next);
        }
        let dog = (0..levels + 2).map(|s| difference(&gauss[s + 1], &gauss[s])).collect();
        let next = halve(&gauss[levels]);
        octaves.push(Octave { gauss, dog, step });
        base = next;
        step *= 2.0;
    }
    // Extrema, refined, per octave and level (rows in parallel).
    let mut found: Vec<(usize, Candidate)> = Vec::new();
    for (o, oct) in octaves.iter().enumerate() {
        for s in 1..=levels {
            let c = extrema(oct, s, levels, opts);
            found.extend(c.into_iter().map(|c| (o, c)));
        }
    }
    // The strongest first; ties by position so the order never depends on threads.
    found.sort_by(|a, b| {
        b.1.response.total_cmp(&a.1.response).then(a.1.y.total_cmp(&b.1.y)).then(a.1.x.total_cmp(&b.1.x))
    });
    // Each candidate gives at least one keypoint: no more are needed than the cap.
    found.truncate(opts.max_features);
    // Orientations and descriptors in parallel; a keypoint may give several orientations.
    let described: Vec<Vec<(Keypoint, [u8; 128])>> = found
        .par_iter()
        .map(|(o, c)| {
            let oct = &octaves[*o];
            let level = (c.level.round() as usize).clamp(0, levels + 2);
            let g = &oct.gauss[level];
            // σ in this octave's pixels.
            let sigma_o = SIGMA0 * 2f32.powf(c.level / levels as f32);
            orientations(g, c.x, c.y, sigma_o)
                .into_iter()
                .map(|angle| {
                    let kp = Keypoint {
                        x: c.x * oct.step,
                        y: c.y * oct.step,
                        sigma: sigma_o * oct.step,
                        angle,
                        response: c.response,
                    };
                    (kp, descriptor(g, c.x, c.y, sigma_o, angle))
                })
                .collect()
        })
        .collect();
    let mut out = Features::default();
    for (kp, d) in described.into_iter().flatten().take(opts.max_features) {
        out.keypoints.push(kp);
        out.descriptors.push(d);
    }
    out
}

/// A refined extremum in its octave's pixels and (fractional) level.
#[derive(Clone, Copy, Debug)]
struct Candidate {
    x: f32,
    y: f32,
    level: f32,
    response: f32,
}

fn difference(a: &Grey, b: &Grey) -> Grey {
    Grey { width: a.width, height: a.height, data: a.data.iter().zip(&b.data).map(|(p, q)| p - q).collect() }
}

/// Every second pixel, starting at (0, 0).
fn halve(g: &Grey) -> Grey {
    let (w, h) = (g.width / 2, g.height / 2);
    let mut data = Vec::with_capacity(w * h);
    for y in 0..h {
        data.extend((0..w).map(|x| g.data[2 * y * g.width + 2 * x]));
    }
    Grey { width: w, height: h, data }
}

/// Twice the size, bilinear (pixel (2x, 2y) is the input's (x, y)).
fn upsample(g: &Grey) -> Grey {
    let (w, h) = (g.width * 2, g.height * 2);
    let data = (0..w * h).map(|i| g.sample((i % w) as f64 * 0.5, (i / w) as f64 * 0.5) as f32).collect();
    Grey { width: w, height: h, data }
}

/// Local extrema of D at level `s` (1..=levels), refined and filtered.
fn extrema(oct: &Octave, s: usize, levels: usize, opts: &Options) -> Vec<Candidate> {
    let d = &oct.dog;
    let (w, h) = (d[s].width, d[s].height);
    // A sample this far below the threshold cannot reach it by interpolation (OpenCV's 0.5).
    let pre = 0.5 * opts.peak_threshold;
    (BORDER..h - BORDER)
        .into_par_iter()
        .flat_map_iter(|y| {
            let mut row = Vec::new();
            for x in BORDER..w - BORDER {
                let v = d[s].data[y * w + x];
                if v.abs() <= pre {
                    continue;
                }
                if is_extremum(d, s, x, y, v) {
                    if let Some(c) = refine(oct, s, x, y, levels, opts) {
                        row.push(c);
                    }
                }
            }
            row
        })
        .collect()
}

fn is_extremum(d: &[Grey], s: usize, x: usize, y: usize, v: f32) -> bool {
    let w = d[s].width;
    let maximum = v > 0.0;
    for layer in &d[s - 1..=s + 1] {
        for yy in y - 1..=y + 1 {
            let row = &layer.data[yy * w + x - 1..yy * w + x + 2];
            for &u in row {
                // The centre itself compares equal and passes.
                if (maximum && u > v) || (!maximum && u < v) {
                    return false;
                }
            }
        }
    }
    true
}

/// Quadratic refinement of an extremum (module docs); None when it moves out, does not
/// settle, is too weak or lies on an edge.
fn refine(oct: &Octave, s0: usize, x0: usize, y0: usize, levels: usize, opts: &Options) -> Option<Candidate> {
    let d = &oct.dog;
    let (w, h) = (d[s0].width as i64, d[s0].height as i64);
    let (mut x, mut y, mut s) = (x0 as i64, y0 as i64, s0 as i64);
    for _ in 0..5 {
        let at = |ds: i64, dx: i64, dy: i64| -> f64 {
            d[(s + ds) as usize].data[((y + dy) * w + x + dx) as usize] as f64
        };
        let v = at(0, 0, 0);
        let g = [
            0.5 * (at(0, 1, 0) - at(0, -1, 0)),
            0.5 * (at(0, 0, 1) - at(0, 0, -1)),
            0.5 * (at(1, 0, 0) - at(-1, 0, 0)),
        ];
        let dxx = at(0, 1, 0) + at(0, -1, 0) - 2.0 * v;
        let dyy = at(0, 0, 1) + at(0, 0, -1) - 2.0 * v;
        let dss = at(1, 0, 0) + at(-1, 0, 0) - 2.0 * v;
        let dxy = 0.25 * (at(0, 1, 1) - at(0, -1, 1) - at(0, 1, -1) + at(0, -1, -1));
        let dxs = 0.25 * (at(1, 1, 0) - at(1, -1, 0) - at(-1, 1, 0) + at(-1, -1, 0));
        let dys = 0.25 * (at(1, 0, 1) - at(1, 0, -1) - at(-1, 0, 1) + at(-1, 0, -1));
        let hm = nalgebra::Matrix3::new(dxx, dxy, dxs, dxy, dyy, dys, dxs, dys, dss);
        let off = hm.lu().solve(&nalgebra::Vector3::new(-g[0], -g[1], -g[2]))?;
        if !off.iter().all(|v| v.is_finite()) {
            return None;
        }
        if off.iter().all(|v| v.abs() < 0.5) {
            let response = (v + 0.5 * (g[0] * off[0] + g[1] * off[1] + g[2] * off[2])).abs() as f32;
            if response < opts.peak_threshold {
                return None;
            }
            let (tr, det) = (dxx + dyy, dxx * dyy - dxy * dxy);
            let r = opts.edge_threshold as f64;
            if det <= 0.0 || tr * tr * r >= (r + 1.0) * (r + 1.0) * det {
                return None;
            }
            return Some(Candidate {
                x: (x as f64 + off[0]) as f32,
                y: (y as f64 + off[1]) as f32,
                level: (s as f64 + off[2]) as f32,
                response,
            });
        }
        x += off[0].round() as i64;
        y += off[1].round() as i64;
        s += off[2].round() as i64;
        let b = BORDER as i64;
        if s < 1 || s > levels as i64 || x < b || x >= w - b || y < b || y >= h - b {
            return None;
        }
    }
    None
}

/// Gradient (dx, dy) of a Gaussian level at an inside pixel, central differences.
#[inline]
fn gradient(g: &Grey, x: usize, y: usize) -> (f32, f32) {
    let w = g.width;
    let i = y * w + x;
    (0.5 * (g.data[i + 1] - g.data[i - 1]), 0.5 * (g.data[i + w] - g.data[i - w]))
}

/// Calls `f(x, y)` for every pixel of the square of `radius` around (cx, cy) whose central
/// differences stay inside the image.
fn inside_window(g: &Grey, cx: i64, cy: i64, radius: i64, mut f: impl FnMut(usize, usize)) {
    let (w, h) = (g.width as i64, g.height as i64);
    for yy in (cy - radius).max(1)..=(cy + radius).min(h - 2) {
        for xx in (cx - radius).max(1)..=(cx + radius).min(w - 2) {
            f(xx as usize, yy as usize);
        }
    }
}

/// The keypoint's dominant orientations (module docs).
fn orientations(g: &Grey, x: f32, y: f32, sigma: f32) -> Vec<f32> {
    let s = 1.5 * sigma;
    let radius = (3.0 * s).round() as i64;
    let (cx, cy) = (x.round() as i64, y.round() as i64);
    let mut hist = [0f32; ORI_BINS];
    let denom = -1.0 / (2.0 * s * s);
    inside_window(g, cx, cy, radius, |xx, yy| {
        let (dx, dy) = (xx as i64 - cx, yy as i64 - cy);
        let (gx, gy) = gradient(g, xx, yy);
        let weight = (((dx * dx + dy * dy) as f32) * denom).exp();
        let angle = gy.atan2(gx);
        let bin = ((angle / std::f32::consts::TAU * ORI_BINS as f32).round() as i64)
            .rem_euclid(ORI_BINS as i64) as usize;
        hist[bin] += weight * (gx * gx + gy * gy).sqrt();
    });
    // Smoothed with [1 4 6 4 1]/16 (circular), as OpenCV does.
    let mut smooth = [0f32; ORI_BINS];
    for i in 0..ORI_BINS {
        let at = |k: i64| hist[((i as i64 + k).rem_euclid(ORI_BINS as i64)) as usize];
        smooth[i] = (at(-2) + at(2)) / 16.0 + (at(-1) + at(1)) * 4.0 / 16.0 + at(0) * 6.0 / 16.0;
    }
    let max = smooth.iter().cloned().fold(0.0, f32::max);
    if max <= 0.0 {
        return vec![0.0];
    }
    let mut out = Vec::new();
    for i in 0..ORI_BINS {
        let (l, r) = (smooth[(i + ORI_BINS - 1) % ORI_BINS], smooth[(i + 1) % ORI_BINS]);
        let v = smooth[i];
        if v > l && v > r && v >= 0.8 * max {
            let shift = 0.5 * (l - r) / (l - 2.0 * v + r);
            let bin = i as f32 + if shift.is_finite() { shift } else { 0.0 };
            let mut angle = bin / ORI_BINS as f32 * std::f32::consts::TAU;
            if angle > std::f32::consts::PI {
                angle -= std::f32::consts::TAU;
            }
            out.push(angle);
        }
    }
    if out.is_empty() {
        out.push(0.0);
    }
    out
}

/// The RootSIFT descriptor at (x, y) with scale `sigma` and orientation `angle` (module docs),
/// all in the level's pixels.
fn descriptor(g: &Grey, x: f32, y: f32, sigma: f32, angle: f32) -> [u8; 128] {
    let d = DESC_CELLS as f32;
    let n = DESC_BINS as f32;
    let cell = 3.0 * sigma;
    let radius = ((cell * std::f32::consts::SQRT_2 * (d + 1.0) * 0.5).round() as i64)
        .min(((g.width * g.width + g.height * g.height) as f64).sqrt() as i64);
    let (cos, sin) = (angle.cos() / cell, angle.sin() / cell);
    let (cx, cy) = (x.round() as i64, y.round() as i64);
    let mut hist = [0f32; (DESC_CELLS + 2) * (DESC_CELLS + 2) * (DESC_BINS + 2)];
    let weight_denom = -1.0 / (d * d * 0.5);
    inside_window(g, cx, cy, radius, |xx, yy| {
        // Offsets from the keypoint itself (not its rounded pixel), rotated into its frame.
        let (ox, oy) = (xx as f32 - x, yy as f32 - y);
        let c_rot = ox * cos + oy * sin;
        let r_rot = -ox * sin + oy * cos;
        let rbin = r_rot + d / 2.0 - 0.5;
        let cbin = c_rot + d / 2.0 - 0.5;
        if rbin <= -1.0 || rbin >= d || cbin <= -1.0 || cbin >= d {
            return;
        }
        let (gx, gy) = gradient(g, xx, yy);
        let mag = (gx * gx + gy * gy).sqrt() * ((c_rot * c_rot + r_rot * r_rot) * weight_denom).exp();
        let mut ori = gy.atan2(gx) - angle;
        ori = ori.rem_euclid(std::f32::consts::TAU);
        let obin = ori / std::f32::consts::TAU * n;
        // Trilinear spreading into the padded histogram.
        let (r0, c0, o0) = (rbin.floor(), cbin.floor(), obin.floor());
        let (fr, fc, fo) = (rbin - r0, cbin - c0, obin - o0);
        let (r0, c0, o0) = (r0 as i64 + 1, c0 as i64 + 1, o0 as i64);
        for (ri, wr) in [(0, 1.0 - fr), (1, fr)] {
            for (ci, wc) in [(0, 1.0 - fc), (1, fc)] {
                for (oi, wo) in [(0, 1.0 - fo), (1, fo)] {
                    let o = ((o0 + oi) as usize) % DESC_BINS;
                    let idx =
                        (((r0 + ri) as usize) * (DESC_CELLS + 2) + (c0 + ci) as usize) * (DESC_BINS + 2) + o;
                    hist[idx] += mag * wr * wc * wo;
                }
            }
        }
    });
    let mut v = [0f32; 128];
    for r in 0..DESC_CELLS {
        for c in 0..DESC_CELLS {
            for o in 0..DESC_BINS {
                v[(r * DESC_CELLS + c) * DESC_BINS + o] =
                    hist[((r + 1) * (DESC_CELLS + 2) + c + 1) * (DESC_BINS + 2) + o];
            }
        }
    }
    // Normalise, clip at 0.2, normalise; then RootSIFT.
    let norm = v.iter().map(|a| a * a).sum::<f32>().sqrt().max(1e-12);
    let clip = 0.2 * norm;
    v.iter_mut().for_each(|a| *a = a.min(clip));
    let l1 = v.iter().sum::<f32>().max(1e-12);
    let mut out = [0u8; 128];
    for (o, a) in out.iter_mut().zip(&v) {
        *o = ((a / l1).sqrt() * 512.0).round().min(255.0) as u8;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Gaussian blob of σ_b on a flat background is found once, at its centre, at the scale
    /// the Laplacian of Gaussian peaks for it (σ = σ_b, since σ²∇²L peaks where σ² = σ_b²... up
    /// to the octave's sampling), and rotating the image by 90° turns its orientation by 90°
    /// and keeps its descriptor.
    #[test]
    fn a_blob_is_found_at_its_centre_and_scale() {
        let (w, h) = (96usize, 80usize);
        let (bx, by, sb) = (41.3f32, 37.6f32, 4.0f32);
        let data = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                // An elongated blob so that it has an orientation.
                let (dx, dy) = (x - bx, y - by);
                0.2 + 0.6 * (-(dx * dx / (2.0 * sb * sb * 1.4) + dy * dy / (2.0 * sb * sb / 1.4))).exp()
            })
            .collect();
        let img = Grey { width: w, height: h, data };
        let f = detect(&img, &Options::default());
        let near: Vec<&Keypoint> =
            f.keypoints.iter().filter(|k| (k.x - bx).abs() < 2.0 && (k.y - by).abs() < 2.0).collect();
        assert!(!near.is_empty(), "{:?}", f.keypoints);
        let k = near[0];
        assert!((k.x - bx).abs() < 0.3 && (k.y - by).abs() < 0.3, "{k:?}");
        assert!(k.sigma > 0.7 * sb && k.sigma < 1.4 * sb, "{k:?}");
    }
}
