//! The focal length a photograph's EXIF metadata gives, in pixels: `lumen sfm`'s starting
//! guess without `--camera` where the file has one (COLMAP's feature extractor reads the same
//! tags), read by `kamadak-exif` from JPEG, TIFF, PNG, WebP or HEIF.
//!
//! 1. FocalLengthIn35mmFilm: the focal length a 36 × 24 mm frame would need for the same
//!    field of view, which the EXIF standard (CIPA DC-008) relates through the diagonal:
//!    f_px = f₃₅ · √(w² + h²) / √(36² + 24²) for an image of w × h pixels. (COLMAP takes
//!    f₃₅ / 35 · max(w, h), 4 % longer on a 3:2 image.)
//! 2. Otherwise FocalLength in millimetres with the sensor's FocalPlaneXResolution and
//!    FocalPlaneResolutionUnit (pixels per inch, centimetre, millimetre or micrometre, at the
//!    size the camera wrote, PixelXDimension): f_px = f_mm · (pixels per mm) · w / PixelXDimension,
//!    the last factor for an image resized since.
//!
//! A missing, zero, negative or non-finite value, or unreadable metadata, gives `None`: the
//! caller keeps its default guess. Tested in `tests/sfm.rs` (`exif_focal_lengths`), on JPEGs
//! written with these tags.

use exif::{In, Tag, Value};
use std::path::Path;

/// A focal length from EXIF, and which tags gave it (for the user).
#[derive(Clone, Debug, PartialEq)]
pub struct Focal {
    pub px: f64,
    pub source: String,
}

/// The first number of a field, as f64.
fn number(exif: &exif::Exif, tag: Tag) -> Option<f64> {
    let field = exif.get_field(tag, In::PRIMARY)?;
    let v = match &field.value {
        Value::Rational(v) => v.first().filter(|r| r.denom != 0).map(|r| r.to_f64()),
        Value::SRational(v) => v.first().filter(|r| r.denom != 0).map(|r| r.to_f64()),
        other => other.get_uint(0).map(f64::from),
    }?;
    (v.is_finite() && v > 0.0).then_some(v)
}

/// The focal length in pixels of the photograph at `path`, `width` × `height` pixels, from its
/// EXIF metadata (module docs), or `None`.
pub fn focal_px(path: &Path, width: u32, height: u32) -> Option<Focal> {
    let file = std::fs::File::open(path).ok()?;
    let exif = exif::Reader::new().read_from_container(&mut std::io::BufReader::new(file)).ok()?;
    focal_of(&exif, width, height)
}

fn focal_of(exif: &exif::Exif, width: u32, height: u32) -> Option<Focal> {
    let (w, h) = (width as f64, height as f64);
    if let Some(f35) = number(exif, Tag::FocalLengthIn35mmFilm) {
        let px = f35 * w.hypot(h) / 36f64.hypot(24.0);
        return Some(Focal { px, source: format!("EXIF FocalLengthIn35mmFilm {f35} mm") });
    }
    let f_mm = number(exif, Tag::FocalLength)?;
    let resolution = number(exif, Tag::FocalPlaneXResolution)?;
    // TIFF's resolution units: 2 inch (the default), 3 cm, 4 mm, 5 µm.
    let unit_mm = match number(exif, Tag::FocalPlaneResolutionUnit).map_or(2, |u| u as u32) {
        2 => 25.4,
        3 => 10.0,
        4 => 1.0,
        5 => 1e-3,
        _ => return None,
    };
    let written = number(exif, Tag::PixelXDimension).unwrap_or(w);
    let px = f_mm * resolution / unit_mm * w / written;
    px.is_finite().then(|| Focal {
        px,
        source: format!(
            "EXIF FocalLength {f_mm} mm at {resolution} pixels per {unit_mm} mm of the focal plane"
        ),
    })
}
