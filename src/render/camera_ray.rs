//! Camera rays: the pinhole direction through a pixel from the shared f64 camera model (so
//! projection and distortion have one source of truth for renderer and calibration), and the
//! thin lens.

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

/// A thin-lens camera ray (camera frame) for the pinhole direction `d` (d.z > 0): from a
/// point uniform on the aperture disk (Shirley–Chiu concentric map) towards the point where
/// the pinhole ray meets the plane in focus, so that plane stays sharp and a point at depth D
/// blurs into a disk of radius fx·r·|1/F − 1/D| pixels.
fn lens_ray(lens: super::scene::ThinLens, d: glam::DVec3, u: (f32, f32)) -> (glam::DVec3, glam::DVec3) {
    let (a, b) = (2.0 * u.0 as f64 - 1.0, 2.0 * u.1 as f64 - 1.0);
    let (r, phi) = if a == 0.0 && b == 0.0 {
        (0.0, 0.0)
    } else if a.abs() > b.abs() {
        (a, std::f64::consts::FRAC_PI_4 * (b / a))
    } else {
        (b, std::f64::consts::FRAC_PI_2 - std::f64::consts::FRAC_PI_4 * (a / b))
    };
    let o = glam::DVec3::new(r * phi.cos(), r * phi.sin(), 0.0) * lens.aperture_radius;
    let focus = d * (lens.focus_distance / d.z);
    (o, (focus - o).normalize())
}
