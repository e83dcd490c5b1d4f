//! Undistortion of images, with OpenCV's choice of the new camera matrix
//! (`getOptimalNewCameraMatrix`): the image border, undistorted, bounds an inner rectangle
//! (only valid pixels) and an outer one (every source pixel); `alpha` = 0 maps the inner one
//! onto the output image, 1 the outer one, and values between interpolate fx, fy, cx, cy.

use crate::error::Invalid;
use crate::image::Image;
use crate::math::{CameraModel, Intrinsics};
use glam::DVec2;

/// Undistorted normalised coordinates of points along the image border (400 per side, so the
/// extremes of each curved side are found to well under 1e-3 px).
fn border(cam: &CameraModel) -> Result<Vec<(DVec2, usize)>, Invalid> {
    let (w, h) = (cam.width as f64 - 1.0, cam.height as f64 - 1.0);
    let n = 400;
    let mut out = Vec::new();
    for k in 0..=n {
        let s = k as f64 / n as f64;
        // (point, side): 0 left, 1 right, 2 top, 3 bottom.
        for (p, side) in [
            (DVec2::new(0.0, s * h), 0),
            (DVec2::new(w, s * h), 1),
            (DVec2::new(s * w, 0.0), 2),
            (DVec2::new(s * w, h), 3),
        ] {
            let u = cam.undistort_pixel(p).ok_or_else(|| {
                format!("pixel {p} lies beyond the fold of the distortion model: it cannot be undistorted")
            })?;
            out.push((u, side));
        }
    }
    Ok(out)
}

/// The new intrinsics for `alpha` in [0, 1], for an output of the same size.
pub fn new_camera_matrix(cam: &CameraModel, alpha: f64) -> Result<Intrinsics, Invalid> {
    if !(0.0..=1.0).contains(&alpha) {
        return Err(format!("alpha = {alpha}: expected a value in [0, 1]").into());
    }
    if cam.width < 2 || cam.height < 2 {
        return Err(
            format!("a {}×{} image: undistortion needs at least 2×2 pixels", cam.width, cam.height).into()
        );
    }
    let pts = border(cam)?;
    let (mut outer_lo, mut outer_hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
    for (p, _) in &pts {
        outer_lo = outer_lo.min(*p);
        outer_hi = outer_hi.max(*p);
    }
    // Inner: the innermost extent of each side.
    let side = |s: usize, f: fn(DVec2) -> f64, pick: fn(f64, f64) -> f64, init: f64| {
        pts.iter().filter(|(_, k)| *k == s).map(|(p, _)| f(*p)).fold(init, pick)
    };
    let inner_lo = DVec2::new(
        side(0, |p| p.x, f64::max, f64::NEG_INFINITY),
        side(2, |p| p.y, f64::max, f64::NEG_INFINITY),
    );
    let inner_hi =
        DVec2::new(side(1, |p| p.x, f64::min, f64::INFINITY), side(3, |p| p.y, f64::min, f64::INFINITY));
    if !(inner_hi.x > inner_lo.x && inner_hi.y > inner_lo.y) {
        return Err(
            "the undistorted image has no interior: the distortion folds the image border over itself".into(),
        );
    }
    let (w, h) = (cam.width as f64 - 1.0, cam.height as f64 - 1.0);
    // Map [lo, hi] onto [0, w] × [0, h]: f = w / (hi − lo), c = −f·lo.
    let fit = |lo: DVec2, hi: DVec2| {
        let f = DVec2::new(w / (hi.x - lo.x), h / (hi.y - lo.y));
        (f, -f * lo)
    };
    let (f0, c0) = fit(inner_lo, inner_hi);
    let (f1, c1) = fit(outer_lo, outer_hi);
    let f = f0 * (1.0 - alpha) + f1 * alpha;
    let c = c0 * (1.0 - alpha) + c1 * alpha;
    Ok(Intrinsics { fx: f.x, fy: f.y, cx: c.x, cy: c.y })
}

/// Source pixel (in the distorted image) of output pixel `p` under the new intrinsics.
pub fn source_pixel(cam: &CameraModel, new: &Intrinsics, p: DVec2) -> DVec2 {
    let n = DVec2::new((p.x - new.cx) / new.fx, (p.y - new.cy) / new.fy);
    cam.normalized_to_pixel(cam.distortion.distort(n))
}

/// Undistorts an image (any channel count), bilinear; pixels with no source are 0.
pub fn undistort_image(img: &Image, cam: &CameraModel, new: &Intrinsics) -> Image {
    let c = img.channels as usize;
    let mut out = Image::new(img.width, img.height, img.channels);
    let (w, h) = (img.width as f64, img.height as f64);
    for y in 0..img.height {
        for x in 0..img.width {
            let s = source_pixel(cam, new, DVec2::new(x as f64, y as f64));
            if !(s.x >= -0.5 && s.y >= -0.5 && s.x <= w - 0.5 && s.y <= h - 0.5) {
                continue;
            }
            let (sx, sy) = (s.x.clamp(0.0, w - 1.0), s.y.clamp(0.0, h - 1.0));
            let (x0, y0) = (sx.floor() as u32, sy.floor() as u32);
            let (x1, y1) = ((x0 + 1).min(img.width - 1), (y0 + 1).min(img.height - 1));
            let (fx, fy) = ((sx - x0 as f64) as f32, (sy - y0 as f64) as f32);
            for k in 0..c {
                let v = (img.pixel(x0, y0)[k] * (1.0 - fx) + img.pixel(x1, y0)[k] * fx) * (1.0 - fy)
                    + (img.pixel(x0, y1)[k] * (1.0 - fx) + img.pixel(x1, y1)[k] * fx) * fy;
                out.pixel_mut(x, y)[k] = v;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Distortion;

    fn barrel() -> CameraModel {
        CameraModel {
            width: 640,
            height: 480,
            intrinsics: Intrinsics { fx: 520.0, fy: 518.0, cx: 322.5, cy: 238.0 },
            distortion: Distortion { k1: -0.3, k2: 0.1, p1: 0.0008, p2: -0.0006, k3: 0.0 },
        }
    }

    /// alpha = 0: every output pixel has a source pixel (no empty border); alpha = 1: every
    /// source border pixel lands inside the output.
    #[test]
    fn alpha_keeps_valid_or_all_pixels() {
        let cam = barrel();
        let (w, h) = (639.0, 479.0);
        let k0 = new_camera_matrix(&cam, 0.0).unwrap();
        for j in (0..480).step_by(4) {
            for i in (0..640).step_by(4) {
                let s = source_pixel(&cam, &k0, DVec2::new(i as f64, j as f64));
                assert!(
                    s.x >= -1e-3 && s.y >= -1e-3 && s.x <= w + 1e-3 && s.y <= h + 1e-3,
                    "({i}, {j}) ← {s}"
                );
            }
        }
        let k1 = new_camera_matrix(&cam, 1.0).unwrap();
        for (n, _) in border(&cam).unwrap() {
            let p = DVec2::new(k1.fx * n.x + k1.cx, k1.fy * n.y + k1.cy);
            assert!(p.x >= -1e-3 && p.y >= -1e-3 && p.x <= w + 1e-3 && p.y <= h + 1e-3, "{p}");
        }
        assert!(new_camera_matrix(&cam, 1.5).is_err());
    }
}
