//! An image environment light: a latitude-longitude map of radiance around the scene,
//! importance-sampled by luminance.
//!
//! Mapping, as Mitsuba 3's `envmap` (so the two renderers light a scene alike): world y is up;
//! a direction d has
//!
//!   u = atan2(d.x, −d.z) / 2π  (wrapped to [0, 1)),   v = acos(d.y) / π,
//!
//! so u = 0 looks along −z, u = ¼ along +x, and v = 0 is straight up. Texel (x, y) of a
//! W × H image is the radiance at u = (x + ½)/W, v = y/(H − 1): the first and last rows lie on
//! the poles, the columns wrap around, and radiance between texels is bilinear. (This mixed
//! convention is Mitsuba's, measured against its `envmap` emitter's `eval` to 2·10⁻⁵.)
//!
//! Sampling: the sphere is cut into the W × (H − 1) cells between neighbouring texels (cell
//! (i, j) spans u ∈ [(i + ½)/W, (i + 1½)/W), wrapping, and v ∈ [j/(H − 1), (j + 1)/(H − 1))), each
//! weighted by the mean luminance of its four corners times its solid angle
//! Ω = (2π/W)·(cos θⱼ − cos θⱼ₊₁). A row is picked from the marginal distribution, a cell
//! within it from the conditional one (both piecewise-constant, inverted by binary search),
//! and the direction is uniform in solid angle inside the cell (uniform in φ and cos θ), so
//! the density is P(cell)/Ω — exact and piecewise-constant in solid angle. A cell whose four
//! corners are black has no light and is never picked.
//!
//! A rotation (Mitsuba's `to_world`) turns the map: a world direction d looks up the map at
//! R⁻¹·d, and sampled directions are turned by R; densities are unchanged.

use crate::error::Invalid;
use crate::image::Image;
use glam::{Mat3A, Vec3A};
use std::f32::consts::PI;

#[derive(Debug)]
pub struct EnvMap {
    /// The map's frame in the world (a rotation; identity unless turned), and its inverse.
    to_world: Mat3A,
    to_map: Mat3A,
    width: usize,
    height: usize,
    texels: Vec<Vec3A>,
    /// cos θ at each texel row, from 1 (up) to −1.
    cos_rows: Vec<f32>,
    /// Cumulative probability of rows of cells (H − 1 entries, the last 1).
    row_cdf: Vec<f32>,
    /// Per row of cells, the cumulative probability of its W cells given the row.
    cell_cdf: Vec<f32>,
    /// Probability of each cell (row-major, (H − 1) × W).
    cell_prob: Vec<f32>,
    /// Mean radiance over the sphere of directions, ∫L dω / 4π (from the cells).
    pub mean_radiance: Vec3A,
}

/// (u, v) of a unit direction (module docs).
#[inline]
pub fn direction_to_uv(d: Vec3A) -> (f32, f32) {
    let mut u = d.x.atan2(-d.z) / (2.0 * PI);
    if u < 0.0 {
        u += 1.0;
    }
    (u.min(1.0), d.y.clamp(-1.0, 1.0).acos() / PI)
}

/// The unit direction at (φ = 2πu, cos θ).
#[inline]
fn direction(phi: f32, cos_t: f32) -> Vec3A {
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    Vec3A::new(sin_t * phi.sin(), cos_t, -sin_t * phi.cos())
}

/// Index of the interval of a cumulative distribution `cdf` (ending at 1) that holds `u`, and
/// `u`'s position within it, rescaled to [0, 1).
#[inline]
fn invert(cdf: &[f32], u: f32) -> Option<(usize, f32)> {
    let i = cdf.partition_point(|&c| c <= u).min(cdf.len() - 1);
    let lo = if i == 0 { 0.0 } else { cdf[i - 1] };
    let p = cdf[i] - lo;
    (p > 0.0).then(|| (i, ((u - lo) / p).clamp(0.0, 1.0 - f32::EPSILON)))
}

impl EnvMap {
    /// Builds the map from a linear RGB (or grey) image of at least 2 × 2 texels. Errors name
    /// the problem: too small, or a negative or non-finite texel.
    pub fn new(img: &Image) -> Result<EnvMap, Invalid> {
        let (w, h) = (img.width as usize, img.height as usize);
        if w < 2 || h < 2 {
            return Err(format!("{w}×{h}: a latitude-longitude map needs at least 2×2 texels").into());
        }
        if img.channels == 2 {
            return Err("2 channels: expected RGB (or one grey channel)".into());
        }
        let mut texels = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let c = img.pixel(x as u32, y as u32);
                let v = if c.len() >= 3 { Vec3A::new(c[0], c[1], c[2]) } else { Vec3A::splat(c[0]) };
                if !v.is_finite() || v.min_element() < 0.0 {
                    return Err(
                        format!("texel ({x}, {y}) is {v}: expected finite, non-negative radiance").into()
                    );
                }
                texels.push(v);
            }
        }
        let cos_rows: Vec<f32> =
            (0..h).map(|y| (std::f64::consts::PI * y as f64 / (h - 1) as f64).cos() as f32).collect();
        // Cell weights: mean corner luminance × solid angle; the mean radiance from the same
        // corners (exact for the bilinear interpolant's mean over φ, close in θ).
        let mut weight = vec![0.0f64; (h - 1) * w];
        let mut sum_radiance = [0.0f64; 3];
        for j in 0..h - 1 {
            let omega = 2.0 * std::f64::consts::PI / w as f64 * (cos_rows[j] as f64 - cos_rows[j + 1] as f64);
            for i in 0..w {
                let i1 = (i + 1) % w;
                let corners = texels[j * w + i]
                    + texels[j * w + i1]
                    + texels[(j + 1) * w + i]
                    + texels[(j + 1) * w + i1];
                weight[j * w + i] = 0.25 * super::bsdf::luminance(corners) as f64 * omega.max(0.0);
                for c in 0..3 {
                    sum_radiance[c] += 0.25 * corners[c] as f64 * omega;
                }
            }
        }
        let total: f64 = weight.iter().sum();
        let mean_radiance = Vec3A::new(
            (sum_radiance[0] / (4.0 * std::f64::consts::PI)) as f32,
            (sum_radiance[1] / (4.0 * std::f64::consts::PI)) as f32,
            (sum_radiance[2] / (4.0 * std::f64::consts::PI)) as f32,
        );
        let mut row_cdf = Vec::with_capacity(h - 1);
        let mut cell_cdf = Vec::with_capacity((h - 1) * w);
        let mut cell_prob = Vec::with_capacity((h - 1) * w);
        let mut acc = 0.0f64;
        let last_lit = (0..h - 1).rev().find(|&j| weight[j * w..(j + 1) * w].iter().sum::<f64>() > 0.0);
        for j in 0..h - 1 {
            let row = &weight[j * w..(j + 1) * w];
            let row_sum: f64 = row.iter().sum();
            let mut racc = 0.0f64;
            for &c in row {
                racc += c;
                cell_cdf.push(if row_sum > 0.0 { (racc / row_sum) as f32 } else { 0.0 });
                cell_prob.push(if total > 0.0 { (c / total) as f32 } else { 0.0 });
            }
            if row_sum > 0.0 {
                let last = cell_cdf.len() - 1;
                cell_cdf[last] = 1.0;
            }
            acc += row_sum;
            // From the last row with light on, the distribution is exactly 1 (rounding must
            // not leave a black row a sliver of probability).
            let done = last_lit.is_some_and(|l| j >= l);
            row_cdf.push(if done {
                1.0
            } else if total > 0.0 {
                (acc / total) as f32
            } else {
                0.0
            });
        }
        Ok(EnvMap {
            to_world: Mat3A::IDENTITY,
            to_map: Mat3A::IDENTITY,
            width: w,
            height: h,
            texels,
            cos_rows,
            row_cdf,
            cell_cdf,
            cell_prob,
            mean_radiance,
        })
    }

    /// The map turned by the rotation `r` (map frame → world; orthonormal, determinant 1).
    pub fn rotated(self, r: Mat3A) -> EnvMap {
        EnvMap { to_world: r, to_map: r.transpose(), ..self }
    }

    /// Bilinear radiance in direction `d` (unit).
    #[inline]
    pub fn eval(&self, d: Vec3A) -> Vec3A {
        let (u, v) = direction_to_uv(self.to_map * d);
        let (w, h) = (self.width, self.height);
        let (i0, fx) = Self::column(u, w);
        let y = v * (h - 1) as f32;
        let j0 = (y as usize).min(h - 2);
        let fy = y - j0 as f32;
        let i1 = (i0 + 1) % w;
        let t = |i: usize, j: usize| self.texels[j * w + i];
        (t(i0, j0) * (1.0 - fx) + t(i1, j0) * fx) * (1.0 - fy)
            + (t(i0, j0 + 1) * (1.0 - fx) + t(i1, j0 + 1) * fx) * fy
    }

    /// The texel column at or left of `u` (texel centres at (x + ½)/W, wrapping) and the
    /// fraction of the way to the next one.
    #[inline]
    fn column(u: f32, w: usize) -> (usize, f32) {
        let x = u * w as f32 - 0.5;
        let f = x.floor();
        let i = (f as i64).rem_euclid(w as i64) as usize;
        (i, (x - f).clamp(0.0, 1.0))
    }

    /// The cell (row j, column i) holding direction `d`.
    #[inline]
    fn cell(&self, d: Vec3A) -> (usize, usize) {
        let (u, v) = direction_to_uv(self.to_map * d);
        let (i, _) = Self::column(u, self.width);
        let j = ((v * (self.height - 1) as f32) as usize).min(self.height - 2);
        (j, i)
    }

    /// Solid angle of a cell in row j.
    #[inline]
    fn cell_solid_angle(&self, j: usize) -> f32 {
        2.0 * PI / self.width as f32 * (self.cos_rows[j] - self.cos_rows[j + 1])
    }

    /// Density (solid angle) with which `sample` returns `d`.
    #[inline]
    pub fn pdf(&self, d: Vec3A) -> f32 {
        let (j, i) = self.cell(d);
        let omega = self.cell_solid_angle(j);
        if omega > 0.0 {
            self.cell_prob[j * self.width + i] / omega
        } else {
            0.0
        }
    }

    /// A direction drawn in proportion to luminance, and its density; `None` for a black map.
    #[inline]
    pub fn sample(&self, u: (f32, f32)) -> Option<(Vec3A, f32)> {
        let (j, t) = invert(&self.row_cdf, u.0)?;
        let w = self.width;
        let (i, s) = invert(&self.cell_cdf[j * w..(j + 1) * w], u.1)?;
        let cos_t = self.cos_rows[j] + (self.cos_rows[j + 1] - self.cos_rows[j]) * t;
        let phi = 2.0 * PI * (i as f32 + 0.5 + s) / w as f32;
        let omega = self.cell_solid_angle(j);
        let pdf = self.cell_prob[j * w + i] / omega;
        (pdf > 0.0 && pdf.is_finite()).then(|| (self.to_world * direction(phi, cos_t), pdf))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(w: u32, h: u32, f: impl Fn(u32, u32) -> [f32; 3]) -> EnvMap {
        let mut img = Image::new(w, h, 3);
        for y in 0..h {
            for x in 0..w {
                let c = f(x, y);
                for (k, v) in c.iter().enumerate() {
                    img.data[3 * (y * w + x) as usize + k] = *v;
                }
            }
        }
        EnvMap::new(&img).unwrap()
    }

    #[test]
    fn mapping_follows_mitsuba() {
        let uv = |d: Vec3A| direction_to_uv(d.normalize());
        assert!(uv(-Vec3A::Z).0.abs() < 1e-6 && (uv(-Vec3A::Z).1 - 0.5).abs() < 1e-6);
        assert!((uv(Vec3A::X).0 - 0.25).abs() < 1e-6);
        assert!((uv(Vec3A::Z).0 - 0.5).abs() < 1e-6);
        assert!((uv(-Vec3A::X).0 - 0.75).abs() < 1e-6);
        assert!(uv(Vec3A::Y).1.abs() < 1e-6 && (uv(-Vec3A::Y).1 - 1.0).abs() < 1e-6);
        // direction() inverts it.
        for (u, v) in [(0.1f32, 0.3f32), (0.6, 0.8), (0.95, 0.05)] {
            let d = direction(2.0 * PI * u, (PI * v).cos());
            let (u2, v2) = direction_to_uv(d);
            assert!((u - u2).abs() < 1e-5 && (v - v2).abs() < 1e-5, "{u} {v}: {u2} {v2}");
        }
        // Texels sit at u = (x + ½)/W, v = y/(H − 1); bilinear in between, wrapping.
        let m = map(4, 3, |x, y| [x as f32 + 10.0 * y as f32, 1.0, 0.0]);
        let at = |u: f32, v: f32| m.eval(direction(2.0 * PI * u, (PI * v).cos())).x;
        assert!((at(0.375, 0.5) - 11.0).abs() < 1e-4, "{}", at(0.375, 0.5));
        assert!((at(0.5, 0.25) - (1.5 + 5.0)).abs() < 1e-3, "{}", at(0.5, 0.25));
        assert!((at(0.0, 0.5) - 11.5).abs() < 1e-3, "wraps: {}", at(0.0, 0.5));
        assert!((at(0.99, 0.5) - (10.0 + 3.0 - 3.0 * 0.46)).abs() < 1e-3, "wraps: {}", at(0.99, 0.5));
    }

    #[test]
    fn sampling_density_is_normalised_and_consistent() {
        // A sky with a bright patch, a black band and an all-black row of cells.
        let m = map(16, 9, |x, y| {
            if y >= 7 {
                [0.0; 3]
            } else if (5..8).contains(&x) && (2..4).contains(&y) {
                [50.0, 40.0, 30.0]
            } else {
                [0.2 + 0.05 * y as f32, 0.3, 0.5]
            }
        });
        // ∫ pdf dω = 1 by quadrature, and each sample's pdf is pdf(direction).
        let (nt, np) = (900, 1600);
        let mut total = 0.0f64;
        for a in 0..nt {
            let ct = 1.0 - 2.0 * (a as f64 + 0.5) / nt as f64;
            for b in 0..np {
                let phi = 2.0 * std::f64::consts::PI * (b as f64 + 0.5) / np as f64;
                total += m.pdf(direction(phi as f32, ct as f32)) as f64;
            }
        }
        total *= 4.0 * std::f64::consts::PI / (nt * np) as f64;
        assert!((total - 1.0).abs() < 2e-3, "∫pdf = {total}");
        let mut s = crate::render::sampler::Sampler::with_kind(Default::default(), 3, 0, 0);
        for _ in 0..10_000 {
            let (d, p) = m.sample(s.next2()).unwrap();
            assert!((d.length() - 1.0).abs() < 1e-5);
            let q = m.pdf(d);
            assert!((p - q).abs() <= 1e-3 * p, "{p} vs {q} at {d}");
            // Never into the black bottom rows.
            assert!(m.eval(d).max_element() > 0.0, "sampled black at {d}");
        }
        let black = map(4, 4, |_, _| [0.0; 3]);
        assert!(black.sample((0.5, 0.5)).is_none());
        assert_eq!(black.mean_radiance, Vec3A::ZERO);
    }

    #[test]
    fn bad_maps_are_refused() {
        assert!(EnvMap::new(&Image::new(1, 4, 3)).unwrap_err().0.contains("2×2"));
        assert!(EnvMap::new(&Image::new(4, 4, 2)).unwrap_err().0.contains("RGB"));
        let mut grey = Image::new(4, 4, 1);
        grey.data.fill(0.5);
        assert_eq!(EnvMap::new(&grey).unwrap().mean_radiance, Vec3A::splat(0.5));
        let mut img = Image::new(4, 4, 3);
        img.data[7] = -1.0;
        assert!(EnvMap::new(&img).unwrap_err().0.contains("texel (2, 0)"));
        img.data[7] = f32::NAN;
        assert!(EnvMap::new(&img).unwrap_err().0.contains("non-negative"));
    }
}
