//! Linear float images, their file formats, and image metrics.

pub mod colormap;
pub mod denoise;
pub mod filter;
pub mod io;
pub mod metrics;
pub mod preview;

use serde::{Deserialize, Serialize};

/// A linear float image with interleaved channels, row-major from the top-left pixel.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub channels: u32,
    pub data: Vec<f32>,
}

impl Image {
    pub fn new(width: u32, height: u32, channels: u32) -> Image {
        Image { width, height, channels, data: vec![0.0; (width * height * channels) as usize] }
    }

    /// A zero image, or `None` (with nothing allocated) when its memory cannot be had: for
    /// sizes a user chooses, where `new` would abort the process.
    pub fn try_new(width: u32, height: u32, channels: u32) -> Option<Image> {
        let n = (width as usize).checked_mul(height as usize)?.checked_mul(channels as usize)?;
        let mut data = Vec::new();
        data.try_reserve_exact(n).ok()?;
        data.resize(n, 0.0);
        Some(Image { width, height, channels, data })
    }

    pub fn pixel(&self, x: u32, y: u32) -> &[f32] {
        let i = ((y * self.width + x) * self.channels) as usize;
        &self.data[i..i + self.channels as usize]
    }

    pub fn pixel_mut(&mut self, x: u32, y: u32) -> &mut [f32] {
        let i = ((y * self.width + x) * self.channels) as usize;
        &mut self.data[i..i + self.channels as usize]
    }

    /// Mean of each channel over all pixels, in f64.
    pub fn channel_means(&self) -> Vec<f64> {
        let c = self.channels as usize;
        let mut sums = vec![0.0f64; c];
        for px in self.data.chunks_exact(c) {
            for (s, &v) in sums.iter_mut().zip(px) {
                *s += v as f64;
            }
        }
        let n = (self.width * self.height).max(1) as f64;
        sums.iter().map(|s| s / n).collect()
    }

    /// The first four channels at `px` (pixel centres at integer coordinates), bilinear;
    /// clamped to the last pixel centres, so a point outside the frame takes the edge's value.
    pub fn bilinear(&self, px: glam::DVec2) -> [f32; 4] {
        let (w, h, c) = (self.width as usize, self.height as usize, (self.channels as usize).min(4));
        let x = px.x.clamp(0.0, (w - 1) as f64);
        let y = px.y.clamp(0.0, (h - 1) as f64);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
        let (fx, fy) = ((x - x0 as f64) as f32, (y - y0 as f64) as f32);
        let mut out = [0.0f32; 4];
        for (xx, yy, b) in [
            (x0, y0, (1.0 - fx) * (1.0 - fy)),
            (x1, y0, fx * (1.0 - fy)),
            (x0, y1, (1.0 - fx) * fy),
            (x1, y1, fx * fy),
        ] {
            let i = (yy * w + xx) * self.channels as usize;
            for (o, &v) in out.iter_mut().zip(&self.data[i..i + c]) {
                *o += b * v;
            }
        }
        out
    }

    pub fn has_non_finite(&self) -> bool {
        self.data.iter().any(|v| !v.is_finite())
    }
}

/// Luminance of a linear RGB pixel (Rec. 709 / sRGB primaries).
pub fn luminance(p: &[f32]) -> f64 {
    0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64
}

/// The darkest and the brightest positive luminance among RGB pixels, or `None` when no
/// pixel's luminance is positive.
pub fn luminance_range<'a>(pixels: impl Iterator<Item = &'a [f32]>) -> Option<(f64, f64)> {
    pixels.map(luminance).filter(|&l| l > 0.0).fold(None, |r, l| match r {
        None => Some((l, l)),
        Some((lo, hi)) => Some((lo.min(l), hi.max(l))),
    })
}

/// sRGB transfer function (linear → encoded), IEC 61966-2-1.
pub fn srgb_encode(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// sRGB transfer function (encoded → linear).
pub fn srgb_decode(v: f32) -> f32 {
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trip() {
        for i in 0..=100 {
            let v = i as f32 / 100.0;
            assert!((srgb_decode(srgb_encode(v)) - v).abs() < 1e-6);
        }
    }
}
