//! The physically based path tracer that renders each stage's synthetic input with its truth.
//!
//! `scene` reads scene files and answers the queries of light transport; `bvh` and `geometry`
//! find hits; `integrators` are the light-transport algorithms, by name, that fill a `Film`
//! (mean + variance); `truth` writes ground-truth images; `sensor` turns radiance into noisy,
//! quantised code values.

pub mod bsdf;
pub mod bvh;
pub mod camera_ray;
pub mod denoised;
pub mod envmap;
pub mod features;
pub mod film;
pub mod filter;
pub mod geometry;
pub mod integrators;
pub mod lanes;
pub mod media;
pub mod microfacet;
pub mod obj;
pub mod photons;
pub mod plastic;
pub mod ply;
pub mod rough_dielectric;
pub mod sampler;
pub mod scene;
pub mod sensor;
pub mod specular;
pub mod surfaces;
pub mod texture;
pub mod transport;
pub mod truth;

pub use film::Film;
pub use integrators::Settings;
pub use integrators::{render, try_render};
pub use scene::{load, Scene};
pub use truth::{truth, Truth};

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("cannot read {path}: {message}")]
    Io { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("{path}: `{field}` {message}")]
    Invalid { path: PathBuf, field: String, message: String },
    /// A Mitsuba scene element that is malformed (`at` names the element, file and line).
    #[error("{at}: {message}")]
    Mitsuba { at: String, message: String },
    /// A Mitsuba scene element lumen does not support; the message says what it supports.
    #[error("{at}: {message}")]
    MitsubaUnsupported { at: String, message: String },
    /// What a setting asks for that lumen cannot do with this scene.
    #[error("{what} {message}")]
    Unsupported { what: String, message: String },
    #[error(transparent)]
    Obj(#[from] obj::ObjError),
    #[error(transparent)]
    Ply(#[from] ply::PlyError),
    #[error(transparent)]
    Grid(#[from] media::grid::GridError),
    #[error("{path}: the mesh has no faces")]
    EmptyMesh { path: PathBuf },
    #[error(transparent)]
    Image(#[from] crate::image::io::Error),
    #[error(transparent)]
    Denoise(#[from] crate::image::denoise::Error),
    /// The film (or another buffer a render needs) could not be allocated.
    #[error("{what} needs {bytes} bytes ({gib:.2} GiB), which could not be allocated: render fewer pixels (the camera's width and height)", gib = *bytes as f64 / (1u64 << 30) as f64)]
    OutOfMemory { what: String, bytes: u64 },
}

impl Error {
    pub fn fault(&self) -> crate::Fault {
        use crate::Fault;
        match self {
            Error::Io { .. } => Fault::Io,
            Error::Obj(e) => e.fault(),
            Error::Ply(e) => e.fault(),
            Error::Grid(e) => e.fault(),
            Error::Image(e) => e.fault(),
            Error::Denoise(e) => e.fault(),
            Error::MitsubaUnsupported { .. } | Error::Unsupported { .. } => Fault::Unsupported,
            Error::Parse { .. }
            | Error::Mitsuba { .. }
            | Error::Invalid { .. }
            | Error::EmptyMesh { .. }
            | Error::OutOfMemory { .. } => Fault::BadInput,
        }
    }
}

/// A progress bar on stderr when `show` is set and stderr is a terminal; hidden otherwise.
pub fn progress_bar(len: u64, what: &str, show: bool) -> indicatif::ProgressBar {
    if !show {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{msg:>10} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta}",
    ) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(what.to_string());
    bar
}
