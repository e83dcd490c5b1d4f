//! lumen: camera calibration, reconstruction, colour, HDR and photometric stereo, each validated
//! against images rendered by its own physically based path tracer where the truth is known.
//!
//! # Conventions
//!
//! - **Frames.** `t_a_b` maps coordinates in frame b to frame a (`t_world_cam`: camera to
//!   world). The camera frame is OpenCV's: x right, y down, z forward.
//! - **Pixels.** Every pixel coordinate a user sees follows OpenCV: pixel centres at integer
//!   coordinates, so a centred principal point is ((W−1)/2, (H−1)/2). The renderer integrates
//!   pixel (i, j) over [i − ½, i + ½) × [j − ½, j + ½); the conversion lives in one place,
//!   `render::camera_ray`.
//! - **Numbers.** f64 for everything estimated or compared with truth (camera model, poses);
//!   f32 (`glam::Vec3A`) for radiance, film and BVH traversal.
//! - **Radiometry.** Linear RGB radiance in W·sr⁻¹·m⁻²; EXR files are linear; PNG previews are
//!   sRGB-encoded; sensor PNGs hold raw linear code values.
//! - **Depth.** Path depth counts segments (Mitsuba's `max_depth`).
//! - **Errors.** One error enum per module, lifted into [`Error`]; each says whose fault it is
//!   ([`Fault`]: bad input, numerical, I/O, unsupported), decided where the error arises. A
//!   solver that fails returns an error, never NaN.
//! - **Determinism.** Every random number is a hash of (seed, pixel, sample, dimension), so
//!   results do not depend on the thread count.

pub mod calib;
pub mod color;
#[cfg(feature = "opencv")]
pub mod cv;
pub mod error;
pub mod fit;
pub mod hdr;
pub mod ibr;
pub mod image;
pub mod math;
pub mod photometric;
pub mod pipeline;
pub mod render;
pub mod sfm;
pub mod surface;

pub use error::Fault;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Calib(#[from] calib::Error),
    #[error(transparent)]
    Render(#[from] render::Error),
    #[error(transparent)]
    Image(#[from] image::io::Error),
    #[error(transparent)]
    Pipeline(#[from] pipeline::Error),
    #[error(transparent)]
    Photometric(#[from] photometric::Error),
    /// The colour or the hdr fit's.
    #[error(transparent)]
    Fit(#[from] fit::FitError),
    #[error(transparent)]
    Sfm(#[from] sfm::Error),
    #[error(transparent)]
    Denoise(#[from] image::denoise::Error),
    #[error(transparent)]
    Surface(#[from] surface::Error),
    #[error(transparent)]
    Ibr(#[from] ibr::Error),
}

impl Error {
    /// Whose fault it is, as the module that raised it decided.
    pub fn fault(&self) -> Fault {
        match self {
            Error::Calib(e) => e.fault(),
            Error::Render(e) => e.fault(),
            Error::Image(e) => e.fault(),
            Error::Pipeline(e) => e.fault(),
            Error::Photometric(e) => e.fault(),
            Error::Fit(e) => e.fault(),
            Error::Sfm(e) => e.fault(),
            Error::Denoise(e) => e.fault(),
            Error::Surface(e) => e.fault(),
            Error::Ibr(e) => e.fault(),
        }
    }
}
