//! Patch values from a photograph of a 6×4 colour chart.
//!
//! The four outer corners of the chart's cell grid (top-left, top-right, bottom-right,
//! bottom-left; OpenCV pixel coordinates, pixel centres at integers) define a homography
//! from grid coordinates (u, v) ∈ [0, 6] × [0, 4] to the image. Patch k (0-based, rows of 6
//! from the top left) is sampled over the central `SAMPLED_FRACTION` of its cell in each
//! direction: every pixel whose centre maps inside that square. On a ColorChecker Classic
//! the printed patch covers about 85 % of the cell pitch, so the sampled half stays 17 % of
//! a pitch clear of each patch edge — room for a corner misplaced by a tenth of a cell, for
//! a blurred edge and for mild lens distortion, which the homography does not model.
//!
//! Each patch's value per channel is the 20 % trimmed mean of its pixels (robust to dust,
//! specks and a stray edge pixel, and nearly as efficient as the mean under Gaussian noise).
//! A patch is flagged `clipped` when more than `TRIM / 2` of its pixels reach the saturation
//! level in a channel: fewer clipped pixels are all among those the trimmed mean drops from
//! the top, so its value is unbiased; more bias it low. It is flagged `dark` when a channel's mean is not
//! above three standard errors of itself (σ/√n, σ from the median absolute deviation) or
//! not above zero: its value is lost in the
//! noise or the black level.

use crate::error::Invalid;
use crate::image::Image;
use glam::DVec2;
use serde::{Deserialize, Serialize};

/// The side of the sampled square, as a fraction of the cell pitch.
pub const SAMPLED_FRACTION: f64 = 0.5;
/// The fraction of each channel's sorted values dropped at either end.
pub const TRIM: f64 = 0.2;
/// Fewest pixels a patch must be sampled from.
pub const MIN_PIXELS: usize = 9;
pub const COLS: usize = 6;
pub const ROWS: usize = 4;

/// What is wrong with a patch's value.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Flag {
    Clipped,
    Dark,
}

/// One patch's sampled value.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Sample {
    /// Trimmed mean per channel.
    pub rgb: [f64; 3],
    /// Robust standard deviation of the pixels per channel (1.4826 × median absolute
    /// deviation).
    pub sd: [f64; 3],
    pub pixels: usize,
    pub flag: Option<Flag>,
}

/// Grid corners → image: the homography and its check.
pub fn grid_homography(
    corners: [[f64; 2]; 4],
    width: u32,
    height: u32,
) -> Result<crate::calib::zhang::Homography, Invalid> {
    if let Some(c) = corners.iter().flatten().find(|v| !v.is_finite()) {
        return Err(format!("corner coordinate {c}: expected finite numbers").into());
    }
    let (w, h) = (width as f64, height as f64);
    for (k, c) in corners.iter().enumerate() {
        if c[0] < -0.5 || c[1] < -0.5 || c[0] > w - 0.5 || c[1] > h - 0.5 {
            return Err(format!(
                "corner {} ({}, {}) lies outside the {width}×{height} image (pixel centres at integers: x in [−0.5, {}], y in [−0.5, {}])",
                k + 1,
                c[0],
                c[1],
                w - 0.5,
                h - 0.5
            ).into());
        }
    }
    // The quadrilateral must be convex and traversed clockwise on screen (top-left,
    // top-right, bottom-right, bottom-left with y down), so the cross products of
    // consecutive edges are all positive.
    let p: Vec<DVec2> = corners.iter().map(|c| DVec2::new(c[0], c[1])).collect();
    for k in 0..4 {
        let (a, b, c) = (p[k], p[(k + 1) % 4], p[(k + 2) % 4]);
        if (b - a).perp_dot(c - b) <= 0.0 {
            return Err(
                "the corners do not form a convex quadrilateral in the order top-left, top-right, bottom-right, bottom-left"
                    .into(),
            );
        }
    }
    let grid = [
        DVec2::new(0.0, 0.0),
        DVec2::new(COLS as f64, 0.0),
        DVec2::new(COLS as f64, ROWS as f64),
        DVec2::new(0.0, ROWS as f64),
    ];
    crate::calib::zhang::homography(&grid, &p).ok_or_else(|| "the corners define no homography".into())
}

fn map(h: &crate::calib::zhang::Homography, p: DVec2) -> DVec2 {
    let w = h[(2, 0)] * p.x + h[(2, 1)] * p.y + h[(2, 2)];
    DVec2::new(
        (h[(0, 0)] * p.x + h[(0, 1)] * p.y + h[(0, 2)]) / w,
        (h[(1, 0)] * p.x + h[(1, 1)] * p.y + h[(1, 2)]) / w,
    )
}

/// Samples the 24 patches. `saturation` is the level at which a channel clips (1 for
/// images scaled to full scale).
pub fn sample(image: &Image, corners: [[f64; 2]; 4], saturation: f64) -> Result<Vec<Sample>, Invalid> {
    if image.channels < 3 {
        return Err(format!("the image has {} channel(s): expected RGB", image.channels).into());
    }
    let h = grid_homography(corners, image.width, image.height)?;
    let inv = h.try_inverse().ok_or("the corners define no invertible homography")?;
    let c = image.channels as usize;
    let mut out = Vec::with_capacity(COLS * ROWS);
    for k in 0..COLS * ROWS {
        let (col, row) = ((k % COLS) as f64, (k / COLS) as f64);
        let (lo, hi) = (0.5 - SAMPLED_FRACTION / 2.0, 0.5 + SAMPLED_FRACTION / 2.0);
        let square =
            [(lo, lo), (hi, lo), (hi, hi), (lo, hi)].map(|(u, v)| map(&h, DVec2::new(col + u, row + v)));
        let (min, max) = square.iter().fold((DVec2::MAX, DVec2::MIN), |(a, b), &p| (a.min(p), b.max(p)));
        let x0 = min.x.ceil().max(0.0) as u32;
        let y0 = min.y.ceil().max(0.0) as u32;
        let x1 = (max.x.floor().min(image.width as f64 - 1.0)).max(-1.0) as i64;
        let y1 = (max.y.floor().min(image.height as f64 - 1.0)).max(-1.0) as i64;
        let mut values: [Vec<f64>; 3] = Default::default();
        for y in y0 as i64..=y1 {
            for x in x0 as i64..=x1 {
                let g = map(&inv, DVec2::new(x as f64, y as f64));
                let (u, v) = (g.x - col, g.y - row);
                if (lo..=hi).contains(&u) && (lo..=hi).contains(&v) {
                    let i = (y as usize * image.width as usize + x as usize) * c;
                    for ch in 0..3 {
                        values[ch].push(image.data[i + ch] as f64);
                    }
                }
            }
        }
        let n = values[0].len();
        if n < MIN_PIXELS {
            return Err(format!(
                "patch {} is sampled from {n} pixel(s) (the central {:.0} % of its cell): expected at least {MIN_PIXELS}; is the chart that small in the image, or are the corners wrong?",
                k + 1,
                100.0 * SAMPLED_FRACTION
            ).into());
        }
        if let Some(v) = values.iter().flatten().find(|v| !v.is_finite()) {
            return Err(format!("patch {} holds a pixel value {v}: expected finite numbers", k + 1).into());
        }
        let clipped = values
            .iter()
            .any(|ch| ch.iter().filter(|&&v| v >= saturation).count() as f64 > 0.5 * TRIM * n as f64);
        let mut rgb = [0.0; 3];
        let mut sd = [0.0; 3];
        for ch in 0..3 {
            rgb[ch] = trimmed_mean(&mut values[ch]);
            sd[ch] = robust_sd(&values[ch]);
        }
        let dark = (0..3).any(|ch| !(rgb[ch] > 0.0 && rgb[ch] > 3.0 * sd[ch] / (n as f64).sqrt()));
        let flag = if clipped {
            Some(Flag::Clipped)
        } else if dark {
            Some(Flag::Dark)
        } else {
            None
        };
        out.push(Sample { rgb, sd, pixels: n, flag });
    }
    Ok(out)
}

/// The mean of the values left after dropping `TRIM` of them at each end.
fn trimmed_mean(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let cut = ((v.len() as f64) * TRIM).floor() as usize;
    let kept = &v[cut..v.len() - cut];
    kept.iter().sum::<f64>() / kept.len() as f64
}

/// 1.4826 × the median absolute deviation from the median of sorted values: the standard
/// deviation of Gaussian noise, unmoved by a few specks.
fn robust_sd(sorted: &[f64]) -> f64 {
    let median = |v: &[f64]| {
        if v.len() % 2 == 1 {
            v[v.len() / 2]
        } else {
            0.5 * (v[v.len() / 2 - 1] + v[v.len() / 2])
        }
    };
    let m = median(sorted);
    let mut dev: Vec<f64> = sorted.iter().map(|v| (v - m).abs()).collect();
    dev.sort_by(f64::total_cmp);
    1.4826 * median(&dev)
}

/// The centres of the 24 cells in the image (for overlays and tests).
pub fn patch_centres(corners: [[f64; 2]; 4], width: u32, height: u32) -> Result<Vec<[f64; 2]>, Invalid> {
    let h = grid_homography(corners, width, height)?;
    Ok((0..COLS * ROWS)
        .map(|k| {
            let p = map(&h, DVec2::new((k % COLS) as f64 + 0.5, (k / COLS) as f64 + 0.5));
            [p.x, p.y]
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An image painted cell by cell, sampled through a rotated quadrilateral: every patch
    /// gets its own value; a speck inside a patch is trimmed away; a clipped and a black patch
    /// are flagged.
    #[test]
    fn samples_each_cell() {
        let (w, h) = (300u32, 220u32);
        let corners = [[20.0, 30.0], [270.0, 10.0], [285.0, 190.0], [30.0, 205.0]];
        let hom = grid_homography(corners, w, h).unwrap();
        let inv = hom.try_inverse().unwrap();
        let mut img = Image::new(w, h, 3);
        for y in 0..h {
            for x in 0..w {
                let g = map(&inv, DVec2::new(x as f64, y as f64));
                if g.x >= 0.0 && g.y >= 0.0 && g.x < 6.0 && g.y < 4.0 {
                    let k = g.y.floor() as usize * 6 + g.x.floor() as usize;
                    let v = match k {
                        3 => 1.0,
                        23 => 0.0,
                        _ => 0.02 * (k + 1) as f32,
                    };
                    img.pixel_mut(x, y).copy_from_slice(&[v, v * 0.5, v * 0.25]);
                }
            }
        }
        let centre = patch_centres(corners, w, h).unwrap()[7];
        img.pixel_mut(centre[0].round() as u32, centre[1].round() as u32).copy_from_slice(&[9.0, 9.0, 9.0]);
        let s = sample(&img, corners, 1.0).unwrap();
        for (k, p) in s.iter().enumerate() {
            assert!(p.pixels >= 100, "patch {k}: {} pixels", p.pixels);
            match k {
                3 => assert_eq!(p.flag, Some(Flag::Clipped)),
                23 => assert_eq!(p.flag, Some(Flag::Dark)),
                _ => {
                    let v = 0.02 * (k + 1) as f64;
                    assert!((p.rgb[0] - v as f32 as f64).abs() < 1e-7, "patch {k}: {:?}", p.rgb);
                    assert_eq!(p.flag, None, "patch {k}");
                }
            }
        }
    }

    /// Corners out of order, outside the image, not finite, or too small: clear refusals.
    #[test]
    fn bad_corners() {
        let img = Image::new(100, 80, 3);
        let good = [[5.0, 5.0], [95.0, 5.0], [95.0, 75.0], [5.0, 75.0]];
        assert!(sample(&img, good, 1.0).is_ok());
        let swapped = [[95.0, 5.0], [5.0, 5.0], [5.0, 75.0], [95.0, 75.0]];
        assert!(sample(&img, swapped, 1.0).unwrap_err().0.contains("convex"));
        let outside = [[5.0, 5.0], [120.0, 5.0], [95.0, 75.0], [5.0, 75.0]];
        assert!(sample(&img, outside, 1.0).unwrap_err().0.contains("corner 2"));
        let nan = [[f64::NAN, 5.0], [95.0, 5.0], [95.0, 75.0], [5.0, 75.0]];
        assert!(sample(&img, nan, 1.0).unwrap_err().0.contains("finite"));
        let tiny = [[5.0, 5.0], [11.0, 5.0], [11.0, 9.0], [5.0, 9.0]];
        assert!(sample(&img, tiny, 1.0).unwrap_err().0.contains("expected at least 9"));
        assert!(sample(&Image::new(100, 80, 1), good, 1.0).unwrap_err().0.contains("channel"));
    }
}
