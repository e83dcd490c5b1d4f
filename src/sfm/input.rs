//! Reading a photograph folder and its camera into an [`Input`](super::Input): what
//! `lumen sfm` and the pipeline's `sfm` stage both read, and the ground-truth cameras of the
//! Strecha et al. format (Herz-Jesu-P8 and its benchmark siblings) that validation compares
//! with.

use super::{Error, Image, Input};
use crate::image::filter::Grey;
use crate::math::{CameraModel, Distortion, Intrinsics};
use nalgebra::{Matrix3, Vector3};
use std::path::{Path, PathBuf};

/// Photograph extensions a folder is read for.
pub const EXTENSIONS: [&str; 5] = ["jpg", "jpeg", "png", "tif", "tiff"];

fn file_error(path: &Path, message: impl Into<String>) -> Error {
    Error::File { path: path.to_path_buf(), message: message.into() }
}

/// The whitespace-separated numbers of a text file; `expected` says what, when one is not.
fn numbers(path: &Path, expected: &str) -> Result<Vec<f64>, Error> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| Error::Io { path: path.into(), message: format!("cannot read: {e}") })?;
    text.split_whitespace()
        .map(str::parse::<f64>)
        .collect::<Result<_, _>>()
        .map_err(|_| file_error(path, expected))
}

/// A camera: a calibration from `lumen calibrate` or OpenCV (.yaml/.yml/.json), or a text
/// file of the 3×3 camera matrix K, row by row (no distortion; its width and height then
/// come from the images, as 0 here).
pub fn read_camera(path: &Path) -> Result<CameraModel, Error> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if ext != "txt" {
        let c = crate::calib::file::read(path).map_err(|e| match e.fault() {
            crate::Fault::Io => Error::Io { path: path.into(), message: e.to_string() },
            _ => file_error(path, e.to_string()),
        })?;
        return Ok(c.camera());
    }
    let v = numbers(path, "expected 9 numbers (K, row by row)")?;
    let k_form = "a 3×3 camera matrix [fx s cx; 0 fy cy; 0 0 1], row by row";
    if v.len() != 9 {
        return Err(file_error(path, format!("{} numbers: expected 9 numbers, {k_form}", v.len())));
    }
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(file_error(
            path,
            format!("number {} is {}: expected finite numbers, {k_form}", i + 1, v[i]),
        ));
    }
    if v[6] != 0.0 || v[7] != 0.0 || v[8] != 1.0 {
        return Err(file_error(
            path,
            format!("last row {} {} {}: expected 0 0 1, {k_form}", v[6], v[7], v[8]),
        ));
    }
    if v[0] <= 0.0 || v[4] <= 0.0 {
        return Err(file_error(path, format!("focal lengths {} and {} must be positive", v[0], v[4])));
    }
    Ok(CameraModel {
        width: 0,
        height: 0,
        intrinsics: Intrinsics { fx: v[0], fy: v[4], cx: v[2], cy: v[5] },
        distortion: Distortion::default(),
    })
}

/// The photographs of a folder, in name order (`EXTENSIONS`).
pub fn photographs(dir: &Path) -> Result<Vec<PathBuf>, Error> {
    let files = crate::image::io::files_with_extensions(dir, &EXTENSIONS)
        .map_err(|e| Error::Io { path: dir.into(), message: format!("not a readable folder: {e}") })?;
    if files.len() < 2 {
        return Err(file_error(
            dir,
            format!("{} photograph(s) ({}), at least 2 needed", files.len(), EXTENSIONS.join(", ")),
        ));
    }
    Ok(files)
}

/// The focal length assumed without a camera or EXIF: 1.2 × the longer side, as COLMAP's
/// default.
pub fn assumed_camera(width: u32, height: u32) -> CameraModel {
    CameraModel::centred(width, height, 1.2 * width.max(height) as f64)
}

/// The camera guessed for a photograph without one: centred, no distortion, the focal length
/// from its EXIF metadata (`exif::focal_px`) or else `assumed_camera`'s; and where it came from.
pub fn guessed_camera(path: &Path, width: u32, height: u32) -> (CameraModel, String) {
    match super::exif::focal_px(path, width, height) {
        Some(f) => {
            let cam = CameraModel::centred(width, height, f.px);
            match super::plausible(&cam) {
                Ok(()) => (cam, f.source),
                Err(why) => (
                    assumed_camera(width, height),
                    format!("1.2 × the longer side ({} left aside: {why})", f.source),
                ),
            }
        }
        None => (assumed_camera(width, height), "1.2 × the longer side (no EXIF focal length)".into()),
    }
}

/// Reads `files` with their camera (`None`: `guessed_camera`, per image and its size),
/// calling `on_image(k, n, file)` before each. A camera matrix without a size (K.txt) takes
/// the first image's: one K fits one image size, so an image of another size is refused by
/// `sfm::run`, named, rather than given a principal point off its centre.
pub fn read_images(
    files: &[PathBuf],
    mut camera: Option<CameraModel>,
    mut on_image: impl FnMut(usize, usize, &Path),
) -> Result<Input, Error> {
    let mut images = Vec::new();
    for (n, f) in files.iter().enumerate() {
        on_image(n, files.len(), f);
        let img = crate::image::io::read(f)?;
        let (camera, guess) = match &mut camera {
            Some(cam) => {
                if cam.width == 0 {
                    cam.width = img.width;
                    cam.height = img.height;
                }
                (*cam, None)
            }
            None => {
                let (cam, source) = guessed_camera(f, img.width, img.height);
                (cam, Some(source))
            }
        };
        let name = f.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        images.push(Image { guess, ..image(name, &img, camera) });
    }
    Ok(Input { images, prepared: Default::default() })
}

/// An image as the solver takes it, from code values in [0, 1] (as `image::io::read` gives a
/// photograph's): its grey levels, and its colours as 8-bit for the point cloud.
pub fn image(name: String, img: &crate::image::Image, camera: CameraModel) -> Image {
    let grey = Grey::from_image(img);
    let c = img.channels as usize;
    let q = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    let rgb8 = img
        .data
        .chunks_exact(c)
        .map(|p| if c >= 3 { [q(p[0]), q(p[1]), q(p[2])] } else { [q(p[0]); 3] })
        .collect();
    Image { name, grey, rgb8, camera, guess: None }
}

/// K, the camera-to-world rotation R and the centre C.
pub type StrechaCamera = (Matrix3<f64>, Matrix3<f64>, Vector3<f64>);

/// A ground-truth camera of the Strecha et al. format: K (3 rows), distortion (3 numbers),
/// the camera-to-world rotation R (3 rows), the centre C, width and height; projection
/// x ~ K [Rᵀ | −RᵀC] X. Returns K, R and C. R is replaced by its nearest rotation (UVᵀ): the
/// files carry six digits, whose 10⁻⁶-level non-orthogonality would add an error of its own
/// to 0.01°-level comparisons.
pub fn read_strecha_camera(path: &Path) -> Result<StrechaCamera, Error> {
    let v = numbers(path, "expected numbers only (K, distortion, R, C, width height)")?;
    if v.len() < 24 || v[..24].iter().any(|x| !x.is_finite()) {
        return Err(file_error(path, format!("{} numbers, expected at least 24 finite ones", v.len())));
    }
    let svd = Matrix3::from_row_slice(&v[12..21]).svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return Err(file_error(path, "the rotation's SVD failed"));
    };
    let r = u * vt;
    if r.determinant() < 0.5 || svd.singular_values.iter().any(|s| (s - 1.0).abs() > 1e-3) {
        return Err(file_error(path, "rows 5–7 are not a rotation matrix"));
    }
    Ok((Matrix3::from_row_slice(&v[0..9]), r, Vector3::new(v[21], v[22], v[23])))
}
