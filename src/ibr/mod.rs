//! Image-based rendering: new views made from photographs (or renders) whose depth and
//! cameras are known.
//!
//! - `warp`: depth-based rendering. Forward mapping splats every source pixel, lifted to 3-D
//!   by its depth, into the new view through a z-buffer; backward mapping forward-projects
//!   only the depth, filters it, then looks every new pixel's colour up in the sources.
//!
//! - `texture`: a texture for a mesh from photographs with known cameras, on a UV atlas
//!   (`atlas`), with occlusion tested against the mesh's z-buffer in each photograph
//!   (`raster`).
//!
//! A view is a camera (`math::CameraModel`) and its pose (`CameraToWorld`), read from a camera
//! file: a scene file's `[camera]` table on its own (`render::scene::load_camera`).

pub mod atlas;
pub mod raster;
pub mod texture;
pub mod warp;

use crate::image::Image;
use crate::math::{CameraModel, CameraToWorld};
use glam::{DVec2, DVec3};

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An image, depth or camera that does not fit (names which and what was expected).
    #[error("{0}")]
    BadInput(String),
}

impl Error {
    pub fn fault(&self) -> crate::Fault {
        match self {
            Error::BadInput(_) => crate::Fault::BadInput,
        }
    }
}

/// A camera and where it is.
#[derive(Clone, Copy, Debug)]
pub struct View {
    pub camera: CameraModel,
    pub t_world_cam: CameraToWorld,
}

/// A source view: its colour, its depth (camera-frame z per pixel, as the renderer's depth
/// AOV: 0 where nothing was seen), its view, and a name for messages.
pub struct Source<'a> {
    pub name: String,
    pub image: &'a Image,
    pub depth: &'a Image,
    pub view: View,
}

impl Source<'_> {
    /// Checks that the image, the depth and the camera agree in size and that every depth is
    /// a finite number ≥ 0.
    pub fn check(&self) -> Result<(), Error> {
        let (w, h) = (self.view.camera.width, self.view.camera.height);
        let name = &self.name;
        for (what, img) in [("image", self.image), ("depth", self.depth)] {
            if (img.width, img.height) != (w, h) {
                return Err(Error::BadInput(format!(
                    "{name}: the {what} is {}×{}, its camera {w}×{h}: expected the same size",
                    img.width, img.height
                )));
            }
        }
        if self.depth.channels != 1 {
            return Err(Error::BadInput(format!(
                "{name}: the depth has {} channels: expected one (camera-frame z)",
                self.depth.channels
            )));
        }
        if let Some(i) = self.depth.data.iter().position(|z| !(z.is_finite() && *z >= 0.0)) {
            let (x, y) = (i as u32 % w, i as u32 / w);
            return Err(Error::BadInput(format!(
                "{name}: depth {} at pixel ({x}, {y}): expected a finite camera-frame z ≥ 0 (0: nothing seen)",
                self.depth.data[i]
            )));
        }
        if self.image.has_non_finite() {
            return Err(Error::BadInput(format!("{name}: the image holds NaN or infinite values")));
        }
        if !self.depth.data.iter().any(|&z| z > 0.0) {
            return Err(Error::BadInput(format!("{name}: the depth is 0 everywhere: the view sees nothing")));
        }
        Ok(())
    }
}

/// The largest |n|² the camera's frame shows (its corners and edge midpoints, undistorted),
/// with a margin: beyond the fold of a strong distortion a point far outside the frame can
/// project into it, so projections of rays wider than this are refused.
fn max_ray2(camera: &CameraModel) -> f64 {
    let (w, h) = (camera.width as f64 - 1.0, camera.height as f64 - 1.0);
    let probes =
        [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h), (w / 2.0, 0.0), (w / 2.0, h), (0.0, h / 2.0), (w, h / 2.0)];
    let worst = probes
        .iter()
        .filter_map(|&(x, y)| camera.undistort_pixel(DVec2::new(x, y)))
        .map(|n| n.length_squared())
        .fold(0.0, f64::max);
    if worst > 0.0 {
        1.44 * worst
    } else {
        f64::INFINITY
    }
}

/// A camera's projection with the guard of `max_ray2`.
pub struct Projector {
    camera: CameraModel,
    max_ray2: f64,
    distorted: bool,
}

impl Projector {
    pub fn new(camera: &CameraModel) -> Projector {
        Projector { camera: *camera, max_ray2: max_ray2(camera), distorted: !camera.distortion.is_zero() }
    }

    /// The pixel a camera-frame point projects to, inside the frame or not; `None` behind
    /// the camera or beyond `max_ray2`.
    pub fn image(&self, p: DVec3) -> Option<DVec2> {
        if !(p.z > 0.0) {
            return None;
        }
        let n = DVec2::new(p.x / p.z, p.y / p.z);
        if n.length_squared() > self.max_ray2 {
            return None;
        }
        let d = if self.distorted { self.camera.distortion.distort(n) } else { n };
        Some(self.camera.normalized_to_pixel(d))
    }

    /// `image`, inside the frame only (within half a pixel of a pixel centre).
    pub fn project(&self, p: DVec3) -> Option<DVec2> {
        let x = self.image(p)?;
        let (w, h) = (self.camera.width as f64, self.camera.height as f64);
        (x.x > -0.5 && x.y > -0.5 && x.x < w - 0.5 && x.y < h - 0.5).then_some(x)
    }
}
