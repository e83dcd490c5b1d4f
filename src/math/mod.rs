//! Shared f64 geometry and numerics: the camera model (intrinsics + Brown–Conrady distortion),
//! rigid poses and rotations, robust statistics, Levenberg–Marquardt (`lm`), the RANSAC
//! driver (`ransac`) and small dense linear algebra (`linear`).
//!
//! Renderer and solvers both use these types, so projection and distortion have one source of
//! truth: a 3D point projected here lands where the renderer draws it.

pub mod camera;
pub mod linear;
pub mod lm;
pub mod pose;
pub mod ransac;
pub mod stats;

pub use camera::{CameraModel, Distortion, Intrinsics};
pub use pose::{CameraToWorld, Pose, WorldToCamera};
