//! Image-based rendering: new views made from photographs (or renders) whose depth and
//! cameras are known.
//!
//! - `warp`: depth-based rendering. Forward mapping splats every source pixel, lifted to 3-D
//!   by its depth, into the new view through a z-buffer; backward mapping forward-projects
//!   only the depth, filters it, then looks every new pixel's colour up in the sources.
//!
//! A view is a camera (`math::CameraModel`) and its pose (`CameraToWorld`), read from a camera
//! file: a scene file's `[camera]` table on its own (`render::scene::load_camera`).

pub mod warp;

use crate::image::Image;
use crate::math::{CameraModel, CameraToWorld};

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
