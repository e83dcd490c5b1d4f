//! Camera rays: the pinhole direction through a pixel from the shared f64 camera model (so
//! projection and distortion have one source of truth for renderer and calibration), and the
//! thin lens; and the way back, for integrators that start paths at the lights: where a
//! scene point reaches the image, and the camera's importance there.
//!
//! Importance. A camera path draws its pixel position uniformly over the pixel (unit area,
//! before the filter) and its aperture point uniformly over the lens, so a pixel's value is
//! ∫ L dpixel. Seen from the aperture point, a pixel position maps to a direction ω; the
//! pinhole direction through the focus-plane point q = F·(x, y, 1) has normalised
//! coordinates (x, y), pixel = K·distort(x, y), and the solid angle of the ray from the
//! aperture to q is dω = cos³θ·dx·dy (θ from the optical axis). Hence
//!
//!   W(ω) = |∂pixel/∂ω| = fx·fy·det J_distort(x, y) / cos³θ,
//!
//! the density, in pixels per steradian, that turns radiance arriving at the aperture along
//! ω into the pixel value; the aperture's 1/area cancels against drawing its point
//! uniformly. A point p at distance r whose surface makes angle θp with the link then adds
//! f·|cos θp|/r²·W (Veach 1997, §10.2; pbrt-v4's `PerspectiveCamera::SampleWi`), with
//! distortion and the thin lens taken into account as the camera ray takes them.

use super::geometry::Ray;
use super::scene::Scene;
use glam::{DVec2, Vec3A};

/// The pinhole direction (camera frame) through pixel (x, y) at the point the pixel filter
/// draws with `jitter` ∈ [0, 1)² (`render::filter`); `None` beyond the fold of the distortion.
pub fn camera_direction(scene: &Scene, x: u32, y: u32, jitter: (f32, f32)) -> Option<glam::DVec3> {
    let f = scene.render.filter;
    let px =
        DVec2::new(f.position(x, scene.camera.width, jitter.0), f.position(y, scene.camera.height, jitter.1));
    scene.camera.pixel_ray(px)
}

/// Whether the camera ray for the pinhole direction `d` takes a thin-lens sample.
pub fn needs_lens_sample(scene: &Scene, d: glam::DVec3) -> bool {
    scene.lens.is_some() && d.z > 0.0
}

/// The world-space camera ray for the pinhole direction `d`, through the point `lens_u` of
/// the aperture when `needs_lens_sample`.
pub fn camera_ray(scene: &Scene, d: glam::DVec3, lens_u: Option<(f32, f32)>) -> Ray {
    let origin = Vec3A::from(scene.t_world_cam.translation.as_vec3());
    let rot = scene.t_world_cam.rotation;
    match (scene.lens, lens_u) {
        (Some(lens), Some(u)) => {
            let (lo, ld) = lens_ray(lens, d, u);
            Ray { origin: origin + Vec3A::from((rot * lo).as_vec3()), dir: Vec3A::from((rot * ld).as_vec3()) }
        }
        _ => Ray { origin, dir: Vec3A::from((rot * d).as_vec3()) },
    }
}

/// The path from a scene point to the camera (`link_point`).
#[derive(Clone, Copy, Debug)]
pub struct CameraLink {
    /// The aperture point (the pinhole without a lens), world frame.
    pub aperture: Vec3A,
    /// Unit direction from the scene point towards `aperture`, and the distance.
    pub dir: Vec3A,
    pub dist: f32,
    /// Where the ray lands on the image, OpenCV pixel coordinates.
    pub pixel: DVec2,
    /// The camera's importance W for that ray (module docs), pixels per steradian.
    pub importance: f32,
}

/// The link from the world point `p` to the camera through the aperture point `lens_u`
/// draws (ignored for a pinhole); `None` where it cannot add to the image: behind the camera,
/// outside the image, beyond the fold of the distortion, or on the aperture itself.
pub fn link_point(scene: &Scene, p: Vec3A, lens_u: (f32, f32)) -> Option<CameraLink> {
    let pose = &scene.t_world_cam;
    let to_cam = pose.rotation.transpose();
    let p_cam = to_cam * (glam::DVec3::from(glam::Vec3::from(p)) - pose.translation);
    let o = scene.lens.map_or(glam::DVec3::ZERO, |lens| lens_point(lens, lens_u));
    let v = p_cam - o;
    let (pixel, importance) = image_point(scene, o, v)?;
    let dist = v.length();
    let aperture = pose.translation + pose.rotation * o;
    Some(CameraLink {
        aperture: Vec3A::from(aperture.as_vec3()),
        dir: Vec3A::from((pose.rotation * (-v / dist)).as_vec3()),
        dist: dist as f32,
        pixel,
        importance: importance as f32,
    })
}

/// Where the ray from the world aperture point `aperture` (a pinhole's centre, or a point a
/// `link_point` drew) towards the world point `p` lands, and its importance: (pixel,
/// importance), `None` where `link_point` would give none.
pub fn importance(scene: &Scene, aperture: Vec3A, p: Vec3A) -> Option<(DVec2, f32)> {
    let pose = &scene.t_world_cam;
    let to_cam = pose.rotation.transpose();
    let o = to_cam * (glam::DVec3::from(glam::Vec3::from(aperture)) - pose.translation);
    let o = glam::DVec3::new(o.x, o.y, 0.0);
    let v = to_cam * (glam::DVec3::from(glam::Vec3::from(p)) - pose.translation) - o;
    image_point(scene, o, v).map(|(px, w)| (px, w as f32))
}

/// The pixel position and importance of the ray from the aperture point `o` along `v`
/// (camera frame, any length): through the focus-plane point it aims at, with the camera
/// model's distortion, inverting `camera_direction` and `lens_ray`; `None` off the image.
fn image_point(scene: &Scene, o: glam::DVec3, v: glam::DVec3) -> Option<(DVec2, f64)> {
    let len = v.length();
    if !(v.z > 0.0 && len > 0.0 && len.is_finite()) {
        return None;
    }
    // The pinhole direction through the same pixel: the focus-plane point seen from the centre.
    let q = match scene.lens {
        Some(lens) => o + v * (lens.focus_distance / v.z),
        None => v,
    };
    let n = DVec2::new(q.x / q.z, q.y / q.z);
    let cam = &scene.camera;
    let (nd, det) = if cam.distortion.is_zero() {
        (n, 1.0)
    } else {
        let (nd, j) = cam.distortion.distort_with_jacobian(n);
        let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
        // Beyond the fold no camera ray leaves along v: the pixel's undistortion finds the
        // other branch (or none), which is what the camera path traces.
        let back = cam.distortion.undistort(nd)?;
        if !(det > 0.0) || (back - n).length() > 1e-9 * (1.0 + n.length()) {
            return None;
        }
        (nd, det)
    };
    let px = cam.normalized_to_pixel(nd);
    let inside = |t: f64, n: u32| t >= -0.5 && t < n as f64 - 0.5;
    if !(inside(px.x, cam.width) && inside(px.y, cam.height)) {
        return None;
    }
    let cos = v.z / len;
    let k = &cam.intrinsics;
    Some((px, k.fx * k.fy * det / (cos * cos * cos)))
}

/// The aperture point (camera frame, z = 0) the numbers `u` draw: uniform on the disk
/// (Shirley–Chiu concentric map).
fn lens_point(lens: super::scene::ThinLens, u: (f32, f32)) -> glam::DVec3 {
    let (a, b) = (2.0 * u.0 as f64 - 1.0, 2.0 * u.1 as f64 - 1.0);
    let (r, phi) = if a == 0.0 && b == 0.0 {
        (0.0, 0.0)
    } else if a.abs() > b.abs() {
        (a, std::f64::consts::FRAC_PI_4 * (b / a))
    } else {
        (b, std::f64::consts::FRAC_PI_2 - std::f64::consts::FRAC_PI_4 * (a / b))
    };
    glam::DVec3::new(r * phi.cos(), r * phi.sin(), 0.0) * lens.aperture_radius
}

/// A thin-lens camera ray (camera frame) for the pinhole direction `d` (d.z > 0): from a
/// point uniform on the aperture disk (Shirley–Chiu concentric map) towards the point where
/// the pinhole ray meets the plane in focus, so that plane stays sharp and a point at depth D
/// blurs into a disk of radius fx·r·|1/F − 1/D| pixels.
fn lens_ray(lens: super::scene::ThinLens, d: glam::DVec3, u: (f32, f32)) -> (glam::DVec3, glam::DVec3) {
    let o = lens_point(lens, u);
    let focus = d * (lens.focus_distance / d.z);
    (o, (focus - o).normalize())
}
