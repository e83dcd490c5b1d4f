//! Candidate squares: the flat regions an edge map leaves, kept when they are shaped like a
//! patch seen in perspective.
//!
//! The photograph is box-averaged down by a whole factor to the working scale, in
//! sRGB-encoded values (where a step of colour is about as visible in the shadows as in the
//! highlights, so one edge threshold serves a dark patch and a light one). A pixel is an edge
//! where the colour gradient (Sobel, all three channels) exceeds `EDGE_STEP`; the non-edge
//! pixels are joined 4-connected into regions. A region is a candidate patch when:
//! - it holds at least `MIN_PIXELS` pixels and does not touch the image border;
//! - it is shaped like a parallelogram: for any parallelogram of area A the second moments
//!   satisfy 12·√det Σ = A, whatever its affine distortion (a disk gives 4π/12 ≈ 1.05, a
//!   ragged or hollow region much more), and its moments' aspect stays below `MAX_ASPECT`
//!   (a square seen 70° out of plane);
//! - its colour is flat: every channel's standard deviation below `MAX_SPREAD` (carpet,
//!   wood grain and printed text are not).

use crate::image::Image;

/// Colour step (sRGB-encoded, full scale 1) per working pixel that makes an edge: 10 of 255
/// codes, 5–10× the pixel noise of a phone JPEG's flat patch and a fifth of the weakest
/// contrast between a ColorChecker patch and its black surround (the dark grey "neutral 3.5").
pub const EDGE_STEP: f32 = 0.04;
/// Fewest pixels of a candidate's interior at the working scale.
pub const MIN_PIXELS: usize = 12;
/// Largest aspect of a candidate's moment ellipse (√(λ₁/λ₂)).
pub const MAX_ASPECT: f64 = 3.5;
/// Largest per-channel standard deviation inside a patch (sRGB-encoded).
pub const MAX_SPREAD: f64 = 0.05;

/// The photograph at the working scale, sRGB-encoded, and how it maps to full resolution.
pub struct Work {
    pub width: usize,
    pub height: usize,
    /// Interleaved RGB, encoded values in [0, 1].
    pub rgb: Vec<f32>,
    /// Full-resolution pixels per working pixel (each way).
    pub factor: usize,
}

impl Work {
    /// Box-averages `encoded` (a full-resolution encoded RGB sampler) by `factor`.
    pub fn new(full: &Encoded, factor: usize) -> Work {
        let (width, height) = (full.width / factor, full.height / factor);
        let mut rgb = vec![0f32; width * height * 3];
        let norm = 1.0 / (factor * factor) as f32;
        for y in 0..height {
            for x in 0..width {
                let mut s = [0f32; 3];
                for dy in 0..factor {
                    for dx in 0..factor {
                        let p = full.pixel(x * factor + dx, y * factor + dy);
                        (0..3).for_each(|c| s[c] += p[c]);
                    }
                }
                let o = 3 * (y * width + x);
                (0..3).for_each(|c| rgb[o + c] = s[c] * norm);
            }
        }
        Work { width, height, rgb, factor }
    }

    pub fn pixel(&self, x: usize, y: usize) -> [f32; 3] {
        let o = 3 * (y * self.width + x);
        [self.rgb[o], self.rgb[o + 1], self.rgb[o + 2]]
    }

    /// A working-scale position in full-resolution pixel coordinates (centres at integers).
    pub fn to_full(&self, p: [f64; 2]) -> [f64; 2] {
        let f = self.factor as f64;
        [f * p[0] + 0.5 * (f - 1.0), f * p[1] + 0.5 * (f - 1.0)]
    }
}

/// The full-resolution photograph as sRGB-encoded RGB: code values as they are for an
/// encoded file, a linear image multiplied by an exposure and encoded.
pub struct Encoded<'a> {
    pub width: usize,
    pub height: usize,
    image: &'a Image,
    /// Applied to linear values before encoding; `None` for encoded input.
    linear_scale: Option<f32>,
}

/// The exposures a linear image is tried at, most likely first: its brightest 0.5 % at full
/// scale (a chart filling much of the frame), its brightest 0.01 % (a chart small in a dark
/// frame, where the 0.5 % is background), and its brightest 4 × 4 block (a few specular
/// pixels aside). Exposures within a factor 1.5 of one tried already are left out.
pub fn exposures(image: &Image) -> Vec<f32> {
    let c = image.channels as usize;
    let (w, h) = (image.width as usize, image.height as usize);
    let bright = |p: &[f32]| p[..3].iter().fold(0f32, |a, &v| if v.is_finite() { a.max(v) } else { a });
    let mut m: Vec<f32> = image.data.chunks_exact(c).map(bright).collect();
    let mut quantile = |q: f64| {
        let k = (((m.len() as f64) * q) as usize).min(m.len().saturating_sub(1));
        *m.select_nth_unstable_by(k, f32::total_cmp).1
    };
    let mut levels = vec![quantile(0.995), quantile(0.9999)];
    let mut block = 0f32;
    for by in 0..h / 4 {
        for bx in 0..w / 4 {
            let mut s = 0f32;
            for y in 4 * by..4 * by + 4 {
                for x in 4 * bx..4 * bx + 4 {
                    s += bright(&image.data[c * (y * w + x)..c * (y * w + x) + c]);
                }
            }
            block = block.max(s / 16.0);
        }
    }
    levels.push(block);
    let mut out: Vec<f32> = Vec::new();
    for l in levels.into_iter().filter(|l| *l > 0.0 && l.is_finite()) {
        let s = 1.0 / l;
        if out.iter().all(|&o| (o / s).max(s / o) > 1.5) {
            out.push(s);
        }
    }
    if out.is_empty() {
        out.push(1.0);
    }
    out
}

impl<'a> Encoded<'a> {
    /// `exposure`: `None` for sRGB-encoded code values, else the factor a linear image is
    /// multiplied by before encoding (`exposures`).
    pub fn new(image: &'a Image, exposure: Option<f32>) -> Encoded<'a> {
        Encoded { width: image.width as usize, height: image.height as usize, image, linear_scale: exposure }
    }

    pub fn pixel(&self, x: usize, y: usize) -> [f32; 3] {
        let c = self.image.channels as usize;
        let o = c * (y * self.width + x);
        let p = &self.image.data[o..o + 3];
        let clean = |v: f32| if v.is_finite() { v } else { 0.0 };
        match self.linear_scale {
            None => [clean(p[0]).clamp(0.0, 1.0), clean(p[1]).clamp(0.0, 1.0), clean(p[2]).clamp(0.0, 1.0)],
            Some(s) => [0, 1, 2].map(|k| crate::image::srgb_encode(clean(p[k]) * s)),
        }
    }

    /// Bilinear sample at a full-resolution position (pixel centres at integers), clamped to
    /// the image.
    pub fn at(&self, x: f64, y: f64) -> [f32; 3] {
        let xf = x.clamp(0.0, (self.width - 1) as f64);
        let yf = y.clamp(0.0, (self.height - 1) as f64);
        let (x0, y0) = (xf.floor() as usize, yf.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (tx, ty) = ((xf - x0 as f64) as f32, (yf - y0 as f64) as f32);
        let (a, b, c, d) = (self.pixel(x0, y0), self.pixel(x1, y0), self.pixel(x0, y1), self.pixel(x1, y1));
        [0, 1, 2].map(|k| (a[k] * (1.0 - tx) + b[k] * tx) * (1.0 - ty) + (c[k] * (1.0 - tx) + d[k] * tx) * ty)
    }
}

/// One candidate patch at the working scale.
#[derive(Clone, Debug)]
pub struct Candidate {
    /// Centroid (working pixels).
    pub centre: [f64; 2],
    /// Second moments of the region (xx, xy, yy), each pixel counted as a unit square.
    pub cov: [f64; 3],
    pub pixels: usize,
}

impl Candidate {
    /// Σ⁻¹ applied to d, dotted with d: the squared distance in the candidate's own frame.
    pub fn mahalanobis2(&self, d: [f64; 2]) -> f64 {
        let [a, b, c] = self.cov;
        let det = a * c - b * b;
        (c * d[0] * d[0] - 2.0 * b * d[0] * d[1] + a * d[1] * d[1]) / det
    }
}

/// The edge map: `true` where the colour gradient exceeds `EDGE_STEP`.
fn edges(work: &Work) -> Vec<bool> {
    let (w, h) = (work.width, work.height);
    let mut edge = vec![true; w * h];
    if w < 3 || h < 3 {
        return edge;
    }
    let at = |x: usize, y: usize, c: usize| work.rgb[3 * (y * w + x) + c];
    let step2 = EDGE_STEP * EDGE_STEP;
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let mut g2 = 0f32;
            for c in 0..3 {
                let gx = (at(x + 1, y - 1, c) + 2.0 * at(x + 1, y, c) + at(x + 1, y + 1, c))
                    - (at(x - 1, y - 1, c) + 2.0 * at(x - 1, y, c) + at(x - 1, y + 1, c));
                let gy = (at(x - 1, y + 1, c) + 2.0 * at(x, y + 1, c) + at(x + 1, y + 1, c))
                    - (at(x - 1, y - 1, c) + 2.0 * at(x, y - 1, c) + at(x + 1, y - 1, c));
                // Sobel sums 4 × the step across 2 pixels: / 8 gives the step per pixel.
                g2 += (gx * gx + gy * gy) / 64.0;
            }
            edge[y * w + x] = g2 > step2;
        }
    }
    edge
}

/// Per-region sums, accumulated in one pass over the labels.
#[derive(Clone, Default)]
struct Sums {
    n: usize,
    sx: f64,
    sy: f64,
    sxx: f64,
    sxy: f64,
    syy: f64,
    rgb: [f64; 3],
    rgb2: [f64; 3],
    border: bool,
}

/// Segments the working image into flat regions and keeps those shaped like patches.
pub fn find(work: &Work) -> Vec<Candidate> {
    let (w, h) = (work.width, work.height);
    let edge = edges(work);
    // Labels by a scan-line flood fill (4-connected), one region at a time.
    let mut label = vec![u32::MAX; w * h];
    let mut sums: Vec<Sums> = Vec::new();
    let mut stack: Vec<usize> = Vec::new();
    for start in 0..w * h {
        if edge[start] || label[start] != u32::MAX {
            continue;
        }
        let id = sums.len() as u32;
        let mut s = Sums::default();
        label[start] = id;
        stack.push(start);
        while let Some(i) = stack.pop() {
            let (x, y) = (i % w, i / w);
            let (fx, fy) = (x as f64, y as f64);
            s.n += 1;
            s.sx += fx;
            s.sy += fy;
            s.sxx += fx * fx;
            s.sxy += fx * fy;
            s.syy += fy * fy;
            let p = work.pixel(x, y);
            for c in 0..3 {
                s.rgb[c] += p[c] as f64;
                s.rgb2[c] += (p[c] as f64) * (p[c] as f64);
            }
            if x == 0 || y == 0 || x + 1 == w || y + 1 == h {
                s.border = true;
            }
            let mut visit = |j: usize| {
                if !edge[j] && label[j] == u32::MAX {
                    label[j] = id;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - w);
            }
            if y + 1 < h {
                visit(i + w);
            }
        }
        sums.push(s);
    }
    let largest = w * h / 16;
    sums.iter()
        .filter(|s| !s.border && s.n >= MIN_PIXELS && s.n <= largest)
        .filter_map(|s| {
            let n = s.n as f64;
            let (mx, my) = (s.sx / n, s.sy / n);
            // Each pixel is a unit square: its own spread, 1/12 each way, adds to the centres'.
            let cov =
                [s.sxx / n - mx * mx + 1.0 / 12.0, s.sxy / n - mx * my, s.syy / n - my * my + 1.0 / 12.0];
            let det = cov[0] * cov[2] - cov[1] * cov[1];
            if det <= 0.0 {
                return None;
            }
            let fill = 12.0 * det.sqrt() / n;
            let tr = cov[0] + cov[2];
            let disc = (0.25 * tr * tr - det).max(0.0).sqrt();
            let (l1, l2) = (0.5 * tr + disc, 0.5 * tr - disc);
            if !(0.85..=1.2).contains(&fill) || l2 <= 0.0 || (l1 / l2).sqrt() > MAX_ASPECT {
                return None;
            }
            let rgb = s.rgb.map(|v| v / n);
            let flat = (0..3).all(|c| (s.rgb2[c] / n - rgb[c] * rgb[c]).max(0.0).sqrt() <= MAX_SPREAD);
            flat.then_some(Candidate { centre: [mx, my], cov, pixels: s.n })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn work_of(w: usize, h: usize, f: impl Fn(usize, usize) -> [f32; 3]) -> Work {
        let mut rgb = Vec::with_capacity(w * h * 3);
        for y in 0..h {
            for x in 0..w {
                rgb.extend_from_slice(&f(x, y));
            }
        }
        Work { width: w, height: h, rgb, factor: 1 }
    }

    /// A light square on black is one candidate at its centre; a ring around it is not (its
    /// moments are those of a square far larger than its area).
    #[test]
    fn a_square_is_a_candidate_and_a_ring_is_not() {
        let square = work_of(120, 120, |x, y| {
            if (20..40).contains(&x) && (10..30).contains(&y) {
                [0.8, 0.5, 0.2]
            } else {
                [0.05; 3]
            }
        });
        let r = find(&square);
        let inner: Vec<_> = r.iter().filter(|c| c.pixels < 400).collect();
        assert_eq!(inner.len(), 1, "{:?}", r);
        let c = inner[0];
        assert!((c.centre[0] - 29.5).abs() < 0.01 && (c.centre[1] - 19.5).abs() < 0.01, "{:?}", c.centre);
        let ring = work_of(120, 120, |x, y| {
            let d = (x as i32 - 30).abs().max((y as i32 - 30).abs());
            if (12..18).contains(&d) {
                [0.8; 3]
            } else if d == 18 || d == 11 {
                [0.4; 3]
            } else {
                [0.05; 3]
            }
        });
        let r = find(&ring);
        // The dark square inside the ring is a candidate; the ring itself (about 600 pixels) is not.
        assert!(r.iter().all(|c| c.pixels < 400), "{:?}", r);
        assert_eq!(r.len(), 1, "{:?}", r);
    }
}
