//! Pinhole camera with OpenCV's intrinsics and Brown–Conrady distortion, in f64.
//!
//! Conventions (as OpenCV's `projectPoints`): camera frame x right, y down, z forward; pixel
//! centres at integer coordinates, so a centred principal point is ((W−1)/2, (H−1)/2).
//!
//! Distortion of normalised coordinates (x, y), r² = x² + y²:
//!
//!   x_d = x·(1 + k1·r² + k2·r⁴ + k3·r⁶) + 2·p1·x·y + p2·(r² + 2x²)
//!   y_d = y·(1 + k1·r² + k2·r⁴ + k3·r⁶) + p1·(r² + 2y²) + 2·p2·x·y
//!   u = fx·x_d + cx,  v = fy·y_d + cy
//!
//! Undistortion solves that system by Newton's method with the analytic Jacobian (OpenCV's
//! `undistortPoints` uses a fixed-point iteration that stops far from machine precision; Newton
//! reaches 1e-12 px in a few steps, which the renderer needs for exact primary rays).

use crate::error::Invalid;
use glam::{DVec2, DVec3};
use serde::{Deserialize, Serialize};

/// Focal lengths and principal point in pixels (OpenCV convention).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Intrinsics {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

/// Brown–Conrady coefficients in OpenCV's order (k1, k2, p1, p2, k3).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Distortion {
    pub k1: f64,
    pub k2: f64,
    pub p1: f64,
    pub p2: f64,
    pub k3: f64,
}

impl Distortion {
    pub fn from_array(c: [f64; 5]) -> Self {
        Distortion { k1: c[0], k2: c[1], p1: c[2], p2: c[3], k3: c[4] }
    }

    pub fn to_array(&self) -> [f64; 5] {
        [self.k1, self.k2, self.p1, self.p2, self.k3]
    }

    pub fn is_zero(&self) -> bool {
        self.to_array().iter().all(|&c| c == 0.0)
    }

    /// Distorts normalised coordinates.
    pub fn distort(&self, p: DVec2) -> DVec2 {
        let (x, y) = (p.x, p.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        DVec2::new(
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        )
    }

    /// Distorted point and the 2×2 Jacobian ∂(x_d, y_d)/∂(x, y) as rows.
    pub fn distort_with_jacobian(&self, p: DVec2) -> (DVec2, [[f64; 2]; 2]) {
        let (x, y) = (p.x, p.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        // d(radial)/d(r²)
        let dradial = self.k1 + r2 * (2.0 * self.k2 + 3.0 * r2 * self.k3);
        let dxd_dx = radial + 2.0 * x * x * dradial + 2.0 * self.p1 * y + 6.0 * self.p2 * x;
        let dxd_dy = 2.0 * x * y * dradial + 2.0 * self.p1 * x + 2.0 * self.p2 * y;
        let dyd_dx = 2.0 * x * y * dradial + 2.0 * self.p1 * x + 2.0 * self.p2 * y;
        let dyd_dy = radial + 2.0 * y * y * dradial + 6.0 * self.p1 * y + 2.0 * self.p2 * x;
        (self.distort(p), [[dxd_dx, dxd_dy], [dyd_dx, dyd_dy]])
    }

    /// Inverts `distort` by Newton's method. Returns `None` where no undistorted point maps
    /// there on the invertible branch (beyond the fold of a strong barrel distortion).
    pub fn undistort(&self, pd: DVec2) -> Option<DVec2> {
        if self.is_zero() {
            return Some(pd);
        }
        let mut p = pd;
        for _ in 0..50 {
            let (d, j) = self.distort_with_jacobian(p);
            let r = d - pd;
            let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
            if !(det > 1e-12) {
                return None;
            }
            let step =
                DVec2::new((j[1][1] * r.x - j[0][1] * r.y) / det, (-j[1][0] * r.x + j[0][0] * r.y) / det);
            p -= step;
            if !p.is_finite() {
                return None;
            }
            if step.length_squared() < 1e-34 * (1.0 + p.length_squared()) {
                break;
            }
        }
        let (d, j) = self.distort_with_jacobian(p);
        let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
        ((d - pd).length() < 1e-13 && det > 0.0).then_some(p)
    }
}

/// A full pinhole camera: image size, intrinsics and distortion.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraModel {
    pub width: u32,
    pub height: u32,
    pub intrinsics: Intrinsics,
    pub distortion: Distortion,
}

impl CameraModel {
    /// A centred camera whose field of view `fov_deg` spans the shorter image side
    /// (Mitsuba's `fov_axis = "smaller"`): f = (min(W, H)/2) / tan(fov/2).
    pub fn from_fov(width: u32, height: u32, fov_deg: f64) -> Self {
        CameraModel::centred(
            width,
            height,
            0.5 * width.min(height) as f64 / (0.5 * fov_deg.to_radians()).tan(),
        )
    }

    /// A camera without distortion, of focal length `f` pixels, its principal point at the
    /// image centre ((W − 1)/2, (H − 1)/2).
    pub fn centred(width: u32, height: u32, f: f64) -> Self {
        CameraModel {
            width,
            height,
            intrinsics: Intrinsics {
                fx: f,
                fy: f,
                cx: (width as f64 - 1.0) / 2.0,
                cy: (height as f64 - 1.0) / 2.0,
            },
            distortion: Distortion::default(),
        }
    }

    /// Projects a point in the camera frame to pixel coordinates; `None` behind the camera.
    pub fn project(&self, p_cam: DVec3) -> Option<DVec2> {
        if !(p_cam.z > 0.0) {
            return None;
        }
        let n = DVec2::new(p_cam.x / p_cam.z, p_cam.y / p_cam.z);
        Some(self.normalized_to_pixel(self.distortion.distort(n)))
    }

    pub fn normalized_to_pixel(&self, n: DVec2) -> DVec2 {
        let k = &self.intrinsics;
        DVec2::new(k.fx * n.x + k.cx, k.fy * n.y + k.cy)
    }

    pub fn pixel_to_normalized(&self, px: DVec2) -> DVec2 {
        let k = &self.intrinsics;
        DVec2::new((px.x - k.cx) / k.fx, (px.y - k.cy) / k.fy)
    }

    /// Undistorts a pixel to ideal normalised coordinates (x, y) with z = 1.
    pub fn undistort_pixel(&self, px: DVec2) -> Option<DVec2> {
        self.distortion.undistort(self.pixel_to_normalized(px))
    }

    /// `undistort_pixel` of the pixels (x, y), x = 0, 1, …, `out.len()` − 1, into `out`.
    ///
    /// Neighbouring pixels have neighbouring solutions: each pixel's Newton iteration starts
    /// from the quadratic through its three left neighbours' solutions, 3·p₋₁ − 3·p₋₂ + p₋₃,
    /// off the root by about |∂³p|·(1/f)³ (10⁻¹⁰ for a focal length of 1000 px). One step
    /// from there lands within rounding of the root (Newton converges quadratically), and a
    /// step longer than 10⁻⁸ falls back to the full iteration, as does every pixel without
    /// three solved neighbours. An image's rays cost one evaluation of the distortion and its
    /// Jacobian per pixel instead of five to eight.
    pub fn undistort_row(&self, y: u32, out: &mut [Option<DVec2>]) {
        let d = &self.distortion;
        for x in 0..out.len() {
            let pd = self.pixel_to_normalized(DVec2::new(x as f64, y as f64));
            if d.is_zero() {
                out[x] = Some(pd);
                continue;
            }
            let fast = match x.checked_sub(3).map(|x3| (out[x3], out[x3 + 1], out[x3 + 2])) {
                Some((Some(p3), Some(p2), Some(p1))) => {
                    let guess = 3.0 * (p1 - p2) + p3;
                    let (dg, j) = d.distort_with_jacobian(guess);
                    let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
                    let r = dg - pd;
                    let step =
                        DVec2::new(j[1][1] * r.x - j[0][1] * r.y, -j[1][0] * r.x + j[0][0] * r.y) / det;
                    let p = guess - step;
                    (det > 1e-12 && step.length_squared() < 1e-16 && p.is_finite()).then_some(p)
                }
                _ => None,
            };
            out[x] = fast.or_else(|| d.undistort(pd));
        }
    }

    /// Unit ray direction in the camera frame through pixel `px` (OpenCV pixel coordinates).
    pub fn pixel_ray(&self, px: DVec2) -> Option<DVec3> {
        self.undistort_pixel(px).map(|n| DVec3::new(n.x, n.y, 1.0).normalize())
    }

    /// Checks that the numbers describe a usable camera; names the first bad field.
    pub fn validate(&self) -> Result<(), Invalid> {
        let k = &self.intrinsics;
        if self.width == 0 || self.height == 0 {
            return Err(format!("image size {}x{} must be positive", self.width, self.height).into());
        }
        for (name, v) in [("fx", k.fx), ("fy", k.fy)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} = {v} must be a positive finite number of pixels").into());
            }
        }
        for (name, v) in [("cx", k.cx), ("cy", k.cy)] {
            if !v.is_finite() {
                return Err(format!("{name} = {v} must be finite").into());
            }
        }
        let names = ["k1", "k2", "p1", "p2", "k3"];
        for (name, v) in names.iter().zip(self.distortion.to_array()) {
            if !v.is_finite() {
                return Err(format!("distortion {name} = {v} must be finite").into());
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undistort_row_matches_undistort_pixel() {
        // A strong barrel distortion whose fold lies inside the frame's corners, with
        // tangential terms, and none.
        for distortion in [
            Distortion { k1: -0.45, k2: 0.05, p1: 0.002, p2: -0.003, k3: 0.0 },
            Distortion { k1: -0.12, ..Distortion::default() },
            Distortion::default(),
        ] {
            let cam = CameraModel { distortion, ..CameraModel::centred(160, 120, 70.0) };
            let mut row = vec![None; 160];
            let (mut solved, mut refused) = (0, 0);
            for y in 0..120 {
                cam.undistort_row(y, &mut row);
                for (x, got) in row.iter().enumerate() {
                    let want = cam.undistort_pixel(DVec2::new(x as f64, y as f64));
                    match (got, want) {
                        (Some(g), Some(w)) => {
                            assert!((*g - w).length() < 1e-13, "({x}, {y}): {g} against {w}");
                            solved += 1;
                        }
                        (None, None) => refused += 1,
                        _ => panic!("({x}, {y}): {got:?} against {want:?}"),
                    }
                }
            }
            assert!(solved > 0);
            if distortion.k1 < -0.4 {
                assert!(refused > 0, "the fold should lie inside the frame");
            }
        }
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let d = Distortion { k1: -0.3, k2: 0.12, p1: 0.001, p2: -0.002, k3: -0.02 };
        let p = DVec2::new(0.31, -0.22);
        let (_, j) = d.distort_with_jacobian(p);
        let h = 1e-7;
        for (c, e) in [DVec2::X, DVec2::Y].iter().enumerate() {
            let fd = (d.distort(p + *e * h) - d.distort(p - *e * h)) / (2.0 * h);
            assert!((fd.x - j[0][c]).abs() < 1e-7 && (fd.y - j[1][c]).abs() < 1e-7);
        }
    }

    #[test]
    fn fov_camera_is_centred() {
        let c = CameraModel::from_fov(256, 256, 39.3077);
        assert!((c.intrinsics.fx - 358.3995).abs() < 1e-3);
        assert_eq!(c.intrinsics.cx, 127.5);
    }
}
