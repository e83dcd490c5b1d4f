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
        let r = (3.0 * sigma).ceil() as isize;
        let k: Vec<f32> = (-r..=r).map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp() as f32).collect();
        let norm: f32 = k.iter().sum();
        let k: Vec<f32> = k.iter().map(|v| v / norm).collect();
        let (w, h) = (self.width, self.height);
        // Rows: each padded by repeating its end pixels, then shifted copies scaled and added;
        // rows in parallel (each row's sums are the same whatever the thread count).
        use rayon::prelude::*;
        let mut tmp = vec![0.0f32; w * h];
        tmp.par_chunks_exact_mut(w).zip(self.data.par_chunks_exact(w)).for_each_init(
            || vec![0.0f32; w + 2 * r as usize],
            |padded, (dst, src)| {
                let r = r as usize;
                padded[..r].fill(src[0]);
                padded[r..r + w].copy_from_slice(src);
                padded[r + w..].fill(src[w - 1]);
                for (t, &kv) in k.iter().enumerate() {
                    for (d, s) in dst.iter_mut().zip(&padded[t..t + w]) {
                        *d += kv * s;
                    }
                }
            },
        );
        // Columns: whole rows scaled and added (clamped at the top and bottom), which the
        // compiler vectorises.
        let mut out = vec![0.0f32; w * h];
        out.par_chunks_exact_mut(w).enumerate().for_each(|(y, dst)| {
            for (t, &kv) in k.iter().enumerate() {
                let sy = (y as isize + t as isize - r).clamp(0, h as isize - 1) as usize;
                for (d, s) in dst.iter_mut().zip(&tmp[sy * w..(sy + 1) * w]) {
                    *d += kv * s;
                }
            }
        });
        Grey { width: w, height: h, data: out }
    }
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
