//! Grey-level image helpers for detectors: conversion, Gaussian blur, bilinear sampling.

/// A single-channel f32 image, row-major.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Grey {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

impl Grey {
    /// Mean of the channels of an image.
    pub fn from_image(img: &super::Image) -> Grey {
        let c = img.channels as usize;
        let data = img.data.chunks_exact(c).map(|p| p.iter().sum::<f32>() / c as f32).collect();
        Grey { width: img.width as usize, height: img.height as usize, data }
    }

    #[inline]
    pub fn at(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.width + x]
    }

    /// Clamped-to-edge pixel.
    #[inline]
    pub fn at_clamped(&self, x: isize, y: isize) -> f32 {
        let x = x.clamp(0, self.width as isize - 1) as usize;
        let y = y.clamp(0, self.height as isize - 1) as usize;
        self.data[y * self.width + x]
    }

    /// Bilinear interpolation at (x, y), pixel centres at integers, clamped at the border.
    #[inline]
    pub fn sample(&self, x: f64, y: f64) -> f64 {
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (i, j) = (x0 as isize, y0 as isize);
        if i >= 0 && j >= 0 && (i as usize) + 1 < self.width && (j as usize) + 1 < self.height {
            // Inside: the four neighbours without clamping (the common case).
            let k = j as usize * self.width + i as usize;
            let (a, b) = (self.data[k] as f64, self.data[k + 1] as f64);
            let (c, d) = (self.data[k + self.width] as f64, self.data[k + self.width + 1] as f64);
            return (a * (1.0 - fx) + b * fx) * (1.0 - fy) + (c * (1.0 - fx) + d * fx) * fy;
        }
        let a = self.at_clamped(i, j) as f64;
        let b = self.at_clamped(i + 1, j) as f64;
        let c = self.at_clamped(i, j + 1) as f64;
        let d = self.at_clamped(i + 1, j + 1) as f64;
        (a * (1.0 - fx) + b * fx) * (1.0 - fy) + (c * (1.0 - fx) + d * fx) * fy
    }

    /// Separable Gaussian blur with standard deviation `sigma` pixels (kernel radius 3σ).
    pub fn blur(&self, sigma: f64) -> Grey {
        if sigma <= 0.0 || self.width == 0 || self.height == 0 {
            return self.clone();
        }
        let w = self.width;
        // Bands of rows in parallel, each made row by row (`BlurRows`): no image-sized
        // intermediate, whose fresh pages cost more to fault in than the blur's arithmetic.
        use rayon::prelude::*;
        let mut out = vec![0.0f32; w * self.height];
        out.par_chunks_mut(w * BAND).enumerate().for_each(|(b, band)| {
            let mut rows = BlurRows::new(self, sigma, b * BAND);
            for (i, dst) in band.chunks_exact_mut(w).enumerate() {
                rows.row(b * BAND + i, dst);
            }
        });
        Grey { width: w, height: self.height, data: out }
    }
}

/// Rows a parallel band of `Grey::blur` holds.
const BAND: usize = 32;

/// The rows of an image's Gaussian blur, made in order from a first row: each row is blurred
/// along x once (edges repeated) into a ring of the 2r + 1 rows the next output row needs,
/// which are then summed along y (edges clamped). The sums and their order are those of a
/// whole-image pass along x and then along y, so the result is the same to the bit; the loops
/// are compiled for the widest vectors the processor has (chosen at run time; the baseline
/// x86-64 build has SSE2 only), with no fused multiply-adds, so the same at every width.
pub struct BlurRows<'a> {
    img: &'a Grey,
    k: Vec<f32>,
    padded: Vec<f32>,
    ring: Vec<f32>,
    /// The next source row (possibly outside the image: clamped) to blur along x.
    next: isize,
}

impl<'a> BlurRows<'a> {
    /// Rows from `first` on, blurred with standard deviation `sigma` (> 0) pixels.
    pub fn new(img: &'a Grey, sigma: f64, first: usize) -> BlurRows<'a> {
        let k = gaussian_kernel(sigma);
        let (w, n) = (img.width, k.len());
        BlurRows {
            img,
            padded: vec![0.0; w + n - 1],
            ring: vec![0.0; n * w],
            next: first as isize - (n / 2) as isize,
            k,
        }
    }

    /// Blurred row `y` into `dst` (`width` long); rows are asked for in order, one after another.
    pub fn row(&mut self, y: usize, dst: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx512f")]
            fn avx512(b: &mut BlurRows, y: usize, dst: &mut [f32]) {
                b.row_with(y, dst)
            }
            #[target_feature(enable = "avx2")]
            fn avx2(b: &mut BlurRows, y: usize, dst: &mut [f32]) {
                b.row_with(y, dst)
            }
            if std::is_x86_feature_detected!("avx512f") {
                // SAFETY: the processor has AVX-512F.
                return unsafe { avx512(self, y, dst) };
            }
            if std::is_x86_feature_detected!("avx2") {
                // SAFETY: the processor has AVX2.
                return unsafe { avx2(self, y, dst) };
            }
        }
        self.row_with(y, dst)
    }

    #[inline(always)]
    fn row_with(&mut self, y: usize, dst: &mut [f32]) {
        let (w, h) = (self.img.width, self.img.height);
        let n = self.k.len();
        let r = (n / 2) as isize;
        // Rows up to y + r blurred along x, each into ring slot (row mod n).
        while self.next <= y as isize + r {
            let sy = self.next.clamp(0, h as isize - 1) as usize;
            let src = &self.img.data[sy * w..(sy + 1) * w];
            let p = &mut self.padded;
            p[..n / 2].fill(src[0]);
            p[n / 2..n / 2 + w].copy_from_slice(src);
            p[n / 2 + w..].fill(src[w - 1]);
            let slot = self.next.rem_euclid(n as isize) as usize;
            let out = &mut self.ring[slot * w..(slot + 1) * w];
            out.fill(0.0);
            for (t, &kv) in self.k.iter().enumerate() {
                for (d, s) in out.iter_mut().zip(&p[t..t + w]) {
                    *d += kv * s;
                }
            }
            self.next += 1;
        }
        dst.fill(0.0);
        for (t, &kv) in self.k.iter().enumerate() {
            let slot = (y as isize - r + t as isize).rem_euclid(n as isize) as usize;
            for (d, s) in dst.iter_mut().zip(&self.ring[slot * w..(slot + 1) * w]) {
                *d += kv * s;
            }
        }
    }
}

/// The normalised Gaussian kernel of standard deviation `sigma` pixels, radius ⌈3σ⌉.
fn gaussian_kernel(sigma: f64) -> Vec<f32> {
    let r = (3.0 * sigma).ceil() as isize;
    let k: Vec<f32> = (-r..=r).map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp() as f32).collect();
    let norm: f32 = k.iter().sum();
    k.iter().map(|v| v / norm).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The blur against the 2D convolution it stands for, with edges clamped, on a random
    /// image whose size is not a multiple of anything.
    #[test]
    fn blur_is_the_clamped_gaussian_convolution() {
        let (w, h) = (37usize, 23usize);
        let mut state = 12345u64;
        let data: Vec<f32> = (0..w * h)
            .map(|_| {
                state = crate::render::sampler::mix64(state);
                (state >> 40) as f32 / (1u64 << 24) as f32
            })
            .collect();
        let img = Grey { width: w, height: h, data };
        let sigma = 1.3;
        let b = img.blur(sigma);
        let r = (3.0 * sigma).ceil() as isize;
        let g = |i: isize| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp();
        let norm: f64 = (-r..=r).map(g).sum();
        for (x, y) in [(0, 0), (5, 7), (36, 22), (18, 0), (2, 21)] {
            let mut s = 0.0;
            for dy in -r..=r {
                for dx in -r..=r {
                    s += g(dx) * g(dy) * img.at_clamped(x + dx, y + dy) as f64;
                }
            }
            let want = s / (norm * norm);
            let got = b.at(x as usize, y as usize) as f64;
            assert!((got - want).abs() < 1e-5, "({x}, {y}): {got} vs {want}");
        }
        assert!(Grey { width: 0, height: 0, data: vec![] }.blur(1.0).data.is_empty());
    }
}
