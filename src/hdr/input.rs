//! An exposure stack from files, as `lumen hdr` and the pipeline's `hdr` cases on photographs
//! read it: exposure times as fractions or decimals, a list file with a name and a time per
//! line, and 8- or 16-bit frames read as code values (no transfer function).

use super::{Error, Frame, Input};
use crate::error::Invalid;
use std::path::{Path, PathBuf};

/// `1/30`, `0.5` or `6.1035e-05` seconds.
pub fn parse_time(s: &str) -> Result<f64, Invalid> {
    let bad = || format!("exposure time `{s}`: expected a number or a fraction such as 1/30");
    let v = match s.split_once('/') {
        Some((a, b)) => {
            let a: f64 = a.trim().parse().map_err(|_| bad())?;
            let b: f64 = b.trim().parse().map_err(|_| bad())?;
            a / b
        }
        None => s.trim().parse().map_err(|_| bad())?,
    };
    if !(v.is_finite() && v > 0.0) {
        return Err(format!("exposure time `{s}`: expected a positive, finite number of seconds").into());
    }
    Ok(v)
}

/// The frames and times of a list file: a name and a time per line, names relative to the
/// file's folder, `#` comments and blank lines skipped.
pub fn read_list(list: &Path) -> Result<Vec<(PathBuf, f64)>, Error> {
    let file_err = |message: String| Error::File { path: list.into(), message };
    let text = std::fs::read_to_string(list)
        .map_err(|e| Error::Io { path: list.into(), message: format!("cannot read: {e}") })?;
    let dir = list.parent().unwrap_or(Path::new("."));
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut parts = line.split_whitespace();
        let (Some(name), Some(time), None) = (parts.next(), parts.next(), parts.next()) else {
            return Err(file_err(format!(
                "line {}: expected a file name and an exposure time in seconds",
                n + 1
            )));
        };
        let t = parse_time(time).map_err(|m| file_err(format!("line {}: {m}", n + 1)))?;
        out.push((dir.join(name), t));
    }
    Ok(out)
}

/// Reads an 8- or 16-bit image's code values as RGB, with its number of levels.
fn read_codes(path: &Path) -> Result<(u32, u32, usize, Vec<u16>), Error> {
    use ::image::DynamicImage as D;
    let file_err = |message: String| Error::File { path: path.into(), message };
    let img = crate::image::io::open_limited(path)?;
    let (w, h) = (img.width(), img.height());
    let (levels, codes) = match img {
        D::ImageLuma8(_) | D::ImageLumaA8(_) | D::ImageRgb8(_) | D::ImageRgba8(_) => {
            (256, img.into_rgb8().into_raw().into_iter().map(u16::from).collect())
        }
        D::ImageLuma16(_) | D::ImageLumaA16(_) | D::ImageRgb16(_) | D::ImageRgba16(_) => {
            (65536, img.into_rgb16().into_raw())
        }
        _ => {
            return Err(file_err(
                "expected 8- or 16-bit integer samples (a float image is already radiance)".into(),
            ))
        }
    };
    Ok((w, h, levels, codes))
}

/// The stack of `frames` (path, exposure time), all the same size and bit depth. With
/// `exclude`, pixels of that colour (R, G, B code values) in any frame are left out of the
/// response fit (`Input::usable`), as registration borders must be.
pub fn read_stack(frames_in: &[(PathBuf, f64)], exclude: Option<[u16; 3]>) -> Result<Input, Error> {
    if frames_in.len() < 2 {
        return Err(Error::BadInput(format!(
            "{} image(s): a stack needs at least 2 exposures",
            frames_in.len()
        )));
    }
    let mut frames = Vec::new();
    let (mut size, mut levels) = (None, 0);
    for (path, time) in frames_in {
        let (w, h, l, codes) = read_codes(path)?;
        match size {
            None => {
                size = Some((w, h));
                levels = l;
            }
            Some((w0, h0)) if (w0, h0) != (w, h) => {
                return Err(Error::File {
                    path: path.clone(),
                    message: format!(
                        "{w}×{h}, but {} is {w0}×{h0}: every frame must have the same size",
                        frames_in[0].0.display()
                    ),
                })
            }
            Some(_) if l != levels => {
                return Err(Error::File {
                    path: path.clone(),
                    message: format!("{l} levels, but the first frame has {levels}: mixed bit depths"),
                })
            }
            Some(_) => {}
        }
        frames.push(Frame { name: path.display().to_string(), time_s: *time, codes });
    }
    let (w, h) = size.unwrap_or((0, 0));
    let n = (w * h) as usize;
    let usable = exclude.map(|c| {
        (0..n).map(|i| frames.iter().all(|f| f.codes[3 * i..3 * i + 3] != c)).collect::<Vec<bool>>()
    });
    Ok(Input { width: w as usize, height: h as usize, levels, frames, usable })
}
