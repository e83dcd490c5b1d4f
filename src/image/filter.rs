//! Grey-level image helpers for detectors: conversion, Gaussian blur, bilinear sampling.

/// A single-channel f32 image, row-major.
#[derive(Clone, Debug)]
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
        let a = self.at_clamped(i, j) as f64;
        let b = self.at_clamped(i + 1, j) as f64;
        let c = self.at_clamped(i, j + 1) as f64;
        let d = self.at_clamped(i + 1, j + 1) as f64;
        (a * (1.0 - fx) + b * fx) * (1.0 - fy) + (c * (1.0 - fx) + d * fx) * fy
    }

    /// Separable Gaussian blur with standard deviation `sigma` pixels (kernel radius 3σ).
    pub fn blur(&self, sigma: f64) -> Grey {
        if sigma <= 0.0 {
            return self.clone();
        }
        let r = (3.0 * sigma).ceil() as isize;
        let k: Vec<f32> = (-r..=r).map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp() as f32).collect();
        let norm: f32 = k.iter().sum();
        let k: Vec<f32> = k.iter().map(|v| v / norm).collect();
        let (w, h) = (self.width, self.height);
        let mut tmp = vec![0.0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                let mut s = 0.0;
                for (t, kv) in k.iter().enumerate() {
                    s += kv * self.at_clamped(x as isize + t as isize - r, y as isize);
                }
                tmp[y * w + x] = s;
            }
        }
        let tmp = Grey { width: w, height: h, data: tmp };
        let mut out = vec![0.0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                let mut s = 0.0;
                for (t, kv) in k.iter().enumerate() {
                    s += kv * tmp.at_clamped(x as isize, y as isize + t as isize - r);
                }
                out[y * w + x] = s;
            }
        }
        Grey { width: w, height: h, data: out }
    }
}
