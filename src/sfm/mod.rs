//! Structure from motion: keypoints and descriptors (`features`), matching (`matching`),
//! two-view geometry (`two_view`), tracks (`tracks`), PnP (`pnp`), bundle adjustment
//! (`bundle`), the incremental mapper (`mapper`), the COLMAP text model (`colmap`) and the
//! comparison with ground truth (`eval`); reading photographs, cameras and ground truth
//! (`input`), and a photograph's focal length from its EXIF metadata (`exif`).
//!
//! [`run`] is what `lumen sfm` calls: features per image, keypoints undistorted through each
//! image's camera model, then the mapper on the given intrinsics (refining the shared ones
//! `mapper::Options::refine` names where they are a guess).

use crate::error::Invalid;
pub mod bundle;
pub mod bytes;
pub mod colmap;
pub mod eval;
pub mod exif;
pub mod features;
pub mod five_point;
pub mod input;
pub mod mapper;
pub mod matching;
pub mod p3p;
pub mod pnp;
pub mod reduced;
pub mod tracks;
pub mod two_view;

use crate::image::filter::Grey;
use crate::math::CameraModel;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The images or a setting are wrong (names what and why).
    #[error("{0}")]
    BadInput(String),
    /// A camera, ground-truth or folder file that is malformed.
    #[error("{path}: {message}")]
    File { path: std::path::PathBuf, message: String },
    /// A file or folder that could not be read or written.
    #[error("{path}: {message}")]
    Io { path: std::path::PathBuf, message: String },
    #[error(transparent)]
    Image(#[from] crate::image::io::Error),
}

impl Error {
    pub fn fault(&self) -> crate::Fault {
        use crate::Fault;
        match self {
            Error::BadInput(_) | Error::File { .. } => Fault::BadInput,
            Error::Io { .. } => Fault::Io,
            Error::Image(e) => e.fault(),
        }
    }
}

/// One image: its name, grey levels in [0, 1], 8-bit colours (row-major, for the points'
/// colours; may be empty) and its camera.
pub struct Image {
    pub name: String,
    pub grey: Grey,
    pub rgb8: Vec<[u8; 3]>,
    pub camera: CameraModel,
    /// Where a guessed camera's focal length came from (`input::read_images`); `None` for a
    /// camera given.
    pub guess: Option<String>,
}

pub struct Input {
    pub images: Vec<Image>,
    /// Work done beforehand, by other processes (a pipeline's shares), that the run takes as
    /// it is instead of doing it again.
    pub prepared: Prepared,
}

/// Features and verified pairs computed beforehand, by the same functions `run` calls
/// (`features::detect` with the run's options on each image's `grey`; `mapper::verify_pair`
/// on `ideal_features` with the run's mapper options and `intrinsics`).
#[derive(Clone, Debug, Default)]
pub struct Prepared {
    /// Per image, or shorter: its features as detected, where known.
    pub features: Vec<Option<features::Features>>,
    /// Verified pairs: any of them, in any order.
    pub pairs: Vec<mapper::VerifiedPair>,
}

#[derive(Clone, Copy, Debug, Default)]
pub struct Config {
    pub features: features::Options,
    pub mapper: mapper::Options,
    /// Progress bars on stderr for feature extraction and matching (`lumen sfm`'s; hidden
    /// when stderr is not a terminal).
    pub progress: bool,
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
    /// Images whose features, and pairs whose verification, came from `Input::prepared`.
    pub prepared_images: usize,
    pub prepared_pairs: usize,
}

/// Checks that the images can be reconstructed at all (their number, sizes and cameras).
fn check(images: &[Image]) -> Result<(), Error> {
    if images.len() < 2 {
        return Err(Error::BadInput(format!(
            "{} image(s): structure from motion needs at least 2",
            images.len()
        )));
    }
    for im in images {
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
        plausible(&im.camera).map_err(|m| Error::BadInput(format!("{}: camera: {m}", im.name)))?;
    }
    Ok(())
}

/// Narrowest and widest horizontal field of view taken, in degrees: a 4000 mm lens on a
/// full-frame sensor sees 0.5°, a fisheye beyond 170° needs a fisheye model, which this
/// pinhole with radial distortion is not.
pub const FIELD_OF_VIEW_DEG: [f64; 2] = [0.5, 170.0];

/// Refuses a camera no photograph can have been taken with: a field of view outside
/// `FIELD_OF_VIEW_DEG`, or a distortion that folds back (stops growing with the radius)
/// inside the ellipse inscribed in the image, where keypoints could not be undistorted.
/// Beyond that ellipse, in the corners, a calibration may fold; keypoints there are dropped.
pub fn plausible(cam: &CameraModel) -> Result<(), Invalid> {
    let (w, h) = (cam.width as f64, cam.height as f64);
    let k = &cam.intrinsics;
    let fov = |size: f64, f: f64| 2.0 * (size / (2.0 * f)).atan().to_degrees();
    let [lo, hi] = FIELD_OF_VIEW_DEG;
    let f_range = |size: f64| {
        (size / (2.0 * (hi / 2.0).to_radians().tan()), size / (2.0 * (lo / 2.0).to_radians().tan()))
    };
    for (name, size, f) in [("fx", w, k.fx), ("fy", h, k.fy)] {
        let (f_lo, f_hi) = f_range(size);
        if !(f_lo..=f_hi).contains(&f) {
            return Err(format!(
                "{name} = {f:e} px gives a field of view of {:.3}° over {size} pixels: expected {lo}° to {hi}° ({name} from {f_lo:.1} to {f_hi:.0} px)",
                fov(size, f)
            ).into());
        }
    }
    if !cam.distortion.is_zero() {
        let edges = [(0.0, k.cy), (w - 1.0, k.cy), (k.cx, 0.0), (k.cx, h - 1.0)];
        for (x, y) in edges {
            if cam.undistort_pixel(glam::DVec2::new(x, y)).is_none_or(|p| !p.is_finite()) {
                let d = &cam.distortion;
                return Err(format!(
                    "the distortion (k1 {}, k2 {}, k3 {}) folds back before the image's edge at pixel ({x:.0}, {y:.0}): no point maps there, so it cannot be this camera's",
                    d.k1, d.k2, d.k3
                ).into());
            }
        }
    }
    Ok(())
}

/// The keypoints of `im` its camera model can undistort (far outside its valid region it
/// cannot), as detected and as ideal pixels (the mapper's), in the same order, with the
/// colour under each.
pub fn ideal_features(im: &Image, detected: &features::Features) -> IdealFeatures {
    let mut kept = features::Features::default();
    let mut ideal = features::Features::default();
    for (kp, d) in detected.keypoints.iter().zip(&detected.descriptors) {
        let k = &im.camera;
        let p = if k.distortion.is_zero() {
            Some(glam::DVec2::new(kp.x as f64, kp.y as f64))
        } else {
            k.undistort_pixel(glam::DVec2::new(kp.x as f64, kp.y as f64)).map(|n| k.normalized_to_pixel(n))
        };
        if let Some(p) = p.filter(|p| p.is_finite()) {
            kept.keypoints.push(*kp);
            kept.descriptors.push(*d);
            ideal.keypoints.push(features::Keypoint { x: p.x as f32, y: p.y as f32, ..*kp });
            ideal.descriptors.push(*d);
        }
    }
    let w = im.grey.width;
    let colours = kept
        .keypoints
        .iter()
        .map(|kp| {
            let (x, y) =
                ((kp.x.round() as usize).min(w - 1), (kp.y.round() as usize).min(im.grey.height - 1));
            im.rgb8.get(y * w + x).copied().unwrap_or([128, 128, 128])
        })
        .collect();
    IdealFeatures { kept, ideal, colours }
}

/// `ideal_features`' result.
pub struct IdealFeatures {
    pub kept: features::Features,
    pub ideal: features::Features,
    pub colours: Vec<[u8; 3]>,
}

/// What bundle adjustment refines when the intrinsics are a guess (no camera given): the
/// focal length and k1, as COLMAP's default camera model (SIMPLE_RADIAL) does. A lens with
/// barrel distortion needs k1 (a 6-view render through k1 = −0.12 gives 0.25° median rotation
/// error with the focal length alone, 0.015° with k1); on images without distortion it costs
/// a little (docs/measurements.md, "Structure from motion").
pub const GUESSED_REFINE: bundle::Refine =
    bundle::Refine { focal: true, principal_point: false, k1: true, k2: false };

/// The camera matrix K of a camera model.
pub fn intrinsics(camera: &CameraModel) -> nalgebra::Matrix3<f64> {
    let i = &camera.intrinsics;
    nalgebra::Matrix3::new(i.fx, 0.0, i.cx, 0.0, i.fy, i.cy, 0.0, 0.0, 1.0)
}

/// Features, undistortion and the mapper (module docs), taking what `input.prepared` holds.
pub fn run(input: &Input, config: &Config) -> Result<Output, Error> {
    check(&input.images)?;
    let n = input.images.len();
    let t = std::time::Instant::now();
    let mut features = Vec::new();
    let mut undistorted = Vec::new();
    let mut colours = Vec::new();
    let mut prepared_images = 0;
    let bar = crate::render::progress_bar(n as u64, "features", config.progress);
    for (i, im) in input.images.iter().enumerate() {
        let given = input.prepared.features.get(i).and_then(Option::as_ref);
        prepared_images += usize::from(given.is_some());
        let f = match given {
            Some(f) => ideal_features(im, f),
            None => ideal_features(im, &features::detect(&im.grey, &config.features)),
        };
        features.push(f.kept);
        undistorted.push(f.ideal);
        colours.push(f.colours);
        bar.inc(1);
    }
    bar.finish_and_clear();
    let extraction_s = t.elapsed().as_secs_f64();
    let k: Vec<nalgebra::Matrix3<f64>> = input.images.iter().map(|im| intrinsics(&im.camera)).collect();
    // The prepared pairs (the first of any repeated one), then every other pair.
    let mut done = vec![false; n * n];
    let mut pairs = Vec::new();
    for p in &input.prepared.pairs {
        let (a, b) = (p.report.a, p.report.b);
        if a < b && b < n && !done[a * n + b] && config.mapper.pairs.selects(a, b) {
            done[a * n + b] = true;
            pairs.push(p.clone());
        }
    }
    let prepared_pairs = pairs.len();
    let todo: Vec<(usize, usize)> =
        config.mapper.pairs.pairs(n).into_iter().filter(|&(a, b)| !done[a * n + b]).collect();
    let bar = crate::render::progress_bar(todo.len() as u64, "pairs", config.progress);
    pairs.extend(mapper::verify_pairs(&undistorted, &k, &todo, &config.mapper, &bar));
    bar.finish_and_clear();
    let reconstruction = mapper::reconstruct_verified(&undistorted, &k, pairs, &config.mapper);
    let cameras = input
        .images
        .iter()
        .zip(reconstruction.intrinsics.iter().zip(&reconstruction.radial))
        .map(|(im, (k, r))| {
            let mut c = im.camera.clone();
            (c.intrinsics.fx, c.intrinsics.fy) = (k[(0, 0)], k[(1, 1)]);
            (c.intrinsics.cx, c.intrinsics.cy) = (k[(0, 2)], k[(1, 2)]);
            // Radial terms are refined only for guessed cameras, which have no distortion.
            if *r != [0.0; 2] {
                (c.distortion.k1, c.distortion.k2) = (r[0], r[1]);
            }
            c
        })
        .collect();
    Ok(Output { features, colours, reconstruction, cameras, extraction_s, prepared_images, prepared_pairs })
}
