//! Structure from motion: keypoints and descriptors (`features`), matching (`matching`),
//! two-view geometry (`two_view`), tracks (`tracks`), PnP (`pnp`), bundle adjustment
//! (`bundle`), the incremental mapper (`mapper`), the COLMAP text model (`colmap`) and the
//! comparison with ground truth (`eval`); reading photographs, cameras and ground truth
//! (`input`).
//!
//! [`run`] is what `lumen sfm` calls: features per image, keypoints undistorted through each
//! image's camera model, then the mapper on the given intrinsics (refining their shared focal
//! length where `mapper::Options::refine_focal` says they are a guess).

pub mod bundle;
pub mod colmap;
pub mod eval;
pub mod features;
pub mod five_point;
pub mod input;
pub mod mapper;
pub mod matching;
pub mod p3p;
pub mod pnp;
pub mod tracks;
pub mod two_view;

use crate::image::filter::Grey;
use crate::math::CameraModel;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The images or a setting are wrong (names what and why).
    #[error("{0}")]
    BadInput(String),
    /// A camera, ground-truth or folder file that cannot be read or is malformed.
    #[error("{path}: {message}")]
    File { path: std::path::PathBuf, message: String },
    #[error(transparent)]
    Image(#[from] crate::image::io::Error),
}

/// One image: its name, grey levels in [0, 1], 8-bit colours (row-major, for the points'
/// colours; may be empty) and its camera.
pub struct Image {
    pub name: String,
    pub grey: Grey,
    pub rgb8: Vec<[u8; 3]>,
    pub camera: CameraModel,
}

pub struct Input {
    pub images: Vec<Image>,
}

#[derive(Clone, Copy, Debug, Default)]
pub struct Config {
    pub features: features::Options,
    pub mapper: mapper::Options,
}

pub struct Output {
    /// Per image: its keypoints as detected (distorted pixels) and descriptors.
    pub features: Vec<features::Features>,
    /// Per image and keypoint: its colour.
    pub colours: Vec<Vec<[u8; 3]>>,
    pub reconstruction: mapper::Reconstruction,
    /// Per image: its camera as the model ends with it (the input's, with the refined focal
    /// length where it was refined).
    pub cameras: Vec<CameraModel>,
    pub extraction_s: f64,
}

/// Features, undistortion and the mapper (module docs).
pub fn run(input: &Input, config: &Config) -> Result<Output, Error> {
    if input.images.len() < 2 {
        return Err(Error::BadInput(format!(
            "{} image(s): structure from motion needs at least 2",
            input.images.len()
        )));
    }
    for im in &input.images {
        let (w, h) = (im.grey.width, im.grey.height);
        if w != im.camera.width as usize || h != im.camera.height as usize {
            return Err(Error::BadInput(format!(
                "{}: {w}×{h} pixels, but its camera is {}×{}",
                im.name, im.camera.width, im.camera.height
            )));
        }
        if w < 64 || h < 64 {
            return Err(Error::BadInput(format!("{}: {w}×{h} pixels, expected at least 64×64", im.name)));
        }
        im.camera.validate().map_err(|m| Error::BadInput(format!("{}: camera: {m}", im.name)))?;
    }
    let t = std::time::Instant::now();
    let mut features = Vec::new();
    let mut undistorted = Vec::new();
    let mut colours = Vec::new();
    for im in &input.images {
        let f = features::detect(&im.grey, &config.features);
        // Keypoints the distortion model cannot invert (far outside its valid region) are
        // left out of both copies, so that indices agree.
        let mut kept = features::Features::default();
        let mut ideal = features::Features::default();
        for (kp, d) in f.keypoints.iter().zip(&f.descriptors) {
            let k = &im.camera;
            let p = if k.distortion.is_zero() {
                Some(glam::DVec2::new(kp.x as f64, kp.y as f64))
            } else {
                k.undistort_pixel(glam::DVec2::new(kp.x as f64, kp.y as f64))
                    .map(|n| k.normalized_to_pixel(n))
            };
            if let Some(p) = p.filter(|p| p.is_finite()) {
                kept.keypoints.push(*kp);
                kept.descriptors.push(*d);
                ideal.keypoints.push(features::Keypoint { x: p.x as f32, y: p.y as f32, ..*kp });
                ideal.descriptors.push(*d);
            }
        }
        let w = im.grey.width;
        colours.push(
            kept.keypoints
                .iter()
                .map(|kp| {
                    let (x, y) =
                        ((kp.x.round() as usize).min(w - 1), (kp.y.round() as usize).min(im.grey.height - 1));
                    im.rgb8.get(y * w + x).copied().unwrap_or([128, 128, 128])
                })
                .collect(),
        );
        features.push(kept);
        undistorted.push(ideal);
    }
    let extraction_s = t.elapsed().as_secs_f64();
    let k: Vec<nalgebra::Matrix3<f64>> = input
        .images
        .iter()
        .map(|im| {
            let i = &im.camera.intrinsics;
            nalgebra::Matrix3::new(i.fx, 0.0, i.cx, 0.0, i.fy, i.cy, 0.0, 0.0, 1.0)
        })
        .collect();
    let reconstruction = mapper::reconstruct(&undistorted, &k, &config.mapper);
    let cameras = input
        .images
        .iter()
        .zip(&reconstruction.intrinsics)
        .map(|(im, k)| {
            let mut c = im.camera.clone();
            (c.intrinsics.fx, c.intrinsics.fy) = (k[(0, 0)], k[(1, 1)]);
            c
        })
        .collect();
    Ok(Output { features, colours, reconstruction, cameras, extraction_s })
}
