//! Reading and writing images: OpenEXR (linear float) and PNG (8- or 16-bit).
//!
//! Writes go to a temporary file beside the target and are renamed into place, so an error
//! never leaves a half-written result file.

use super::Image;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The file is missing or unreadable.
    #[error("cannot read image {path}: {message}")]
    Read { path: PathBuf, message: String },
    /// The file was read but is not an image lumen can decode, or is too large to.
    #[error("cannot read image {path}: {message}")]
    Decode { path: PathBuf, message: String },
    #[error("cannot write {path}: {message}")]
    Write { path: PathBuf, message: String },
    #[error("unsupported image format for {path}: expected a .exr or .png file name")]
    Format { path: PathBuf },
}

impl Error {
    pub fn fault(&self) -> crate::error::Fault {
        use crate::error::Fault;
        match self {
            Error::Read { .. } | Error::Write { .. } => Fault::Io,
            Error::Format { .. } | Error::Decode { .. } => Fault::BadInput,
        }
    }
}

/// The files of `dir` whose extension is one of `extensions` (lower case; matched without
/// case), in name order.
pub fn files_with_extensions(dir: &Path, extensions: &[&str]) -> std::io::Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            let e = p.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
            p.is_file() && extensions.contains(&e.as_str())
        })
        .collect();
    files.sort();
    Ok(files)
}

/// Writes to `path.tmp` with `write`, then renames to `path`.
pub fn write_atomically<E: std::fmt::Display>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), Error> {
    let err = |message: String| Error::Write { path: path.to_path_buf(), message };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| err(e.to_string()))?;
    }
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    let tmp = path.with_extension(format!("partial.{ext}"));
    if let Err(e) = write(&tmp) {
        let _ = std::fs::remove_file(&tmp);
        return Err(err(e.to_string()));
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        err(e.to_string())
    })
}

/// Writes a set of files that belong together into `dir` all or nothing: `write` writes them
/// into a fresh staging folder beside `dir` (`.<name>.partial-<pid>`), and only when it has
/// succeeded are they moved into `dir` (created if need be; other files there are left
/// alone). On an error the staging folder is removed and `dir` is as it was.
pub fn write_together<T, E: From<Error>>(
    dir: &Path,
    write: impl FnOnce(&Path) -> Result<T, E>,
) -> Result<T, E> {
    let err = write_error;
    let name = dir.file_name().and_then(|n| n.to_str()).unwrap_or("out");
    let parent = dir.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent).map_err(|e| err(parent, e))?;
    let stage = parent.join(format!(".{name}.partial-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&stage);
    std::fs::create_dir_all(&stage).map_err(|e| err(&stage, e))?;
    let result = write(&stage).and_then(|value| {
        // Every target is checked before the first is moved: a later one that cannot be
        // replaced (a folder where a file goes) would otherwise leave the first ones behind.
        check_targets(&stage, dir)?;
        move_into(&stage, dir)?;
        Ok(value)
    });
    let _ = std::fs::remove_dir_all(&stage);
    result
}

fn write_error(path: &Path, e: std::io::Error) -> Error {
    Error::Write { path: path.to_path_buf(), message: e.to_string() }
}

/// Refuses, naming it, a target in `to` a file of `from` cannot replace: a folder where a file
/// goes, or anything but a folder where a folder goes.
fn check_targets(from: &Path, to: &Path) -> Result<(), Error> {
    let err = |path: &Path, message: &str| Error::Write { path: path.to_path_buf(), message: message.into() };
    match std::fs::symlink_metadata(to) {
        Ok(m) if !m.is_dir() => return Err(err(to, "is not a folder: expected a folder to write into")),
        Ok(_) => {}
        Err(_) => return Ok(()), // created afresh
    }
    for entry in std::fs::read_dir(from).map_err(|e| write_error(from, e))? {
        let source = entry.map_err(|e| write_error(from, e))?.path();
        let target = to.join(source.file_name().unwrap_or_default());
        if source.is_dir() {
            check_targets(&source, &target)?;
        } else if target.is_dir() {
            return Err(err(&target, "is a folder: expected a file name to write to (nothing was written)"));
        }
    }
    Ok(())
}

/// Moves the files of `from` into `to`, subfolders merged into existing ones.
fn move_into(from: &Path, to: &Path) -> Result<(), Error> {
    let err = write_error;
    std::fs::create_dir_all(to).map_err(|e| err(to, e))?;
    for entry in std::fs::read_dir(from).map_err(|e| err(from, e))? {
        let source = entry.map_err(|e| err(from, e))?.path();
        let target = to.join(source.file_name().unwrap_or_default());
        if source.is_dir() {
            move_into(&source, &target)?;
        } else {
            std::fs::rename(&source, &target).map_err(|e| err(&target, e))?;
        }
    }
    Ok(())
}

fn extension(path: &Path) -> String {
    path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase()
}

/// Channel names used for 1, 3 and 4 channel images.
fn channel_names(channels: u32) -> Vec<String> {
    match channels {
        1 => vec!["Y".into()],
        3 => vec!["R".into(), "G".into(), "B".into()],
        4 => vec!["R".into(), "G".into(), "B".into(), "A".into()],
        n => (0..n).map(|i| format!("C{i}")).collect(),
    }
}

/// Writes a linear float OpenEXR file (f32 samples; channels Y, or R G B, or R G B A).
pub fn write_exr(path: &Path, img: &Image) -> Result<(), Error> {
    use exr::prelude::{
        AnyChannel, AnyChannels, Encoding, FlatSamples, Layer, LayerAttributes, SmallVec, WritableImage,
    };
    let (w, h, c) = (img.width as usize, img.height as usize, img.channels as usize);
    let names = channel_names(img.channels);
    let list: SmallVec<[AnyChannel<FlatSamples>; 4]> = names
        .iter()
        .enumerate()
        .map(|(k, name)| {
            let samples: Vec<f32> = img.data.iter().skip(k).step_by(c).copied().collect();
            AnyChannel::new(name.as_str(), FlatSamples::F32(samples))
        })
        .collect();
    let layer =
        Layer::new((w, h), LayerAttributes::default(), Encoding::SMALL_LOSSLESS, AnyChannels::sort(list));
    let image = exr::image::Image::from_layer(layer);
    write_atomically(path, |tmp| image.write().to_file(tmp).map_err(|e| e.to_string()))
}

/// Largest decoded image any reader accepts, in bytes: the `image` crate's default limit for
/// PNG and JPEG, applied to EXR as well (its header is checked before any pixel is read), so a
/// 600-byte file claiming 100000 × 100000 pixels is refused instead of allocating 40 GB.
pub const MAX_DECODED_BYTES: u64 = 512 * 1024 * 1024;

/// Reads the first layer of an OpenEXR file as f32: R G B if present, else Y (one channel).
pub fn read_exr(path: &Path) -> Result<Image, Error> {
    use exr::prelude::{read, ReadChannels, ReadLayers};
    let err = |message: String| Error::Decode { path: path.to_path_buf(), message };
    let exr_err = |e: exr::error::Error| match e {
        exr::error::Error::Io(e) if e.kind() != std::io::ErrorKind::UnexpectedEof => {
            Error::Read { path: path.to_path_buf(), message: e.to_string() }
        }
        e => err(e.to_string()),
    };
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(exr_err)?;
    for h in &meta.headers {
        let (w, hh) = (h.layer_size.0 as u64, h.layer_size.1 as u64);
        let bytes = w.saturating_mul(hh).saturating_mul(h.channels.list.len() as u64).saturating_mul(4);
        if bytes > MAX_DECODED_BYTES {
            return Err(err(format!(
                "{w}×{hh} pixels × {} channels would take {:.1} GB decoded, above the limit of {} MB",
                h.channels.list.len(),
                bytes as f64 / 1e9,
                MAX_DECODED_BYTES >> 20
            )));
        }
    }
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(exr_err)?;
    let layer = &image.layer_data;
    let (w, h) = (layer.size.0, layer.size.1);
    let find =
        |name: &str| layer.channel_data.list.iter().find(|c| c.name.to_string().eq_ignore_ascii_case(name));
    let wanted: Vec<_> = match (find("R"), find("G"), find("B"), find("Y")) {
        (Some(r), Some(g), Some(b), _) => vec![r, g, b],
        (_, _, _, Some(y)) => vec![y],
        _ => return Err(err("no R, G, B or Y channel".into())),
    };
    let c = wanted.len();
    let mut out = Image::new(w as u32, h as u32, c as u32);
    for (k, ch) in wanted.iter().enumerate() {
        for (i, v) in ch.sample_data.values_as_f32().enumerate() {
            out.data[i * c + k] = v;
        }
    }
    Ok(out)
}

/// Writes an 8-bit sRGB-encoded PNG of a linear image (values clipped to [0, 1]).
pub fn write_png_srgb(path: &Path, img: &Image) -> Result<(), Error> {
    let bytes: Vec<u8> = img.data.iter().map(|&v| (super::srgb_encode(v) * 255.0 + 0.5) as u8).collect();
    write_png_bytes(path, img.width, img.height, img.channels, &bytes)
}

fn color_type(channels: u32, sixteen: bool) -> Option<image::ExtendedColorType> {
    use image::ExtendedColorType as T;
    Some(match (channels, sixteen) {
        (1, false) => T::L8,
        (3, false) => T::Rgb8,
        (4, false) => T::Rgba8,
        (1, true) => T::L16,
        (3, true) => T::Rgb16,
        (4, true) => T::Rgba16,
        _ => return None,
    })
}

/// Writes 8-bit code values as they are (1, 3 or 4 channels).
pub fn write_png_bytes(path: &Path, w: u32, h: u32, c: u32, bytes: &[u8]) -> Result<(), Error> {
    let ct = color_type(c, false)
        .ok_or_else(|| Error::Write { path: path.into(), message: format!("{c} channels") })?;
    write_atomically(path, |tmp| {
        image::save_buffer_with_format(tmp, bytes, w, h, ct, image::ImageFormat::Png)
            .map_err(|e| e.to_string())
    })
}

/// Writes code values in [0, 1] (what `read` gives for a PNG or JPEG) as an 8-bit PNG, no
/// encoding applied: the inverse of `read` for 8-bit files.
pub fn write_png_codes(path: &Path, img: &Image) -> Result<(), Error> {
    let bytes: Vec<u8> = img.data.iter().map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8).collect();
    write_png_bytes(path, img.width, img.height, img.channels, &bytes)
}

/// Writes raw integer sample values (already quantised) as an 8- or 16-bit PNG. Values of 10
/// or 12 bits are stored in 16-bit samples shifted to the top bits (a 10-bit 1023 is written
/// 65472), as cameras' 16-bit files hold them, so full scale stays full scale for a reader.
pub fn write_png_raw(path: &Path, w: u32, h: u32, c: u32, values: &[u16], bits: u8) -> Result<(), Error> {
    if bits == 8 {
        let bytes: Vec<u8> = values.iter().map(|&v| v.min(255) as u8).collect();
        return write_png_bytes(path, w, h, c, &bytes);
    }
    let shift = 16u32.saturating_sub(bits as u32).min(8);
    let shifted: Vec<u16>;
    let values = if shift > 0 {
        shifted = values.iter().map(|&v| v << shift).collect();
        &shifted
    } else {
        values
    };
    let ct = color_type(c, true)
        .ok_or_else(|| Error::Write { path: path.into(), message: format!("{c} channels") })?;
    // PNG stores 16-bit samples big-endian; `save_buffer` expects native-endian u16 bytes.
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_ne_bytes()).collect();
    write_atomically(path, |tmp| {
        image::save_buffer_with_format(tmp, &bytes, w, h, ct, image::ImageFormat::Png)
            .map_err(|e| e.to_string())
    })
}

/// Most pixels an image file may have: 2²⁷ (134 million, 16384 × 8192), checked from the
/// header before decoding. Its floats (3 channels) take 1.6 GB; the `image` crate's own limit
/// (512 MB of decoded bytes) alone let a 16384² grey PNG through, to several GB of copies.
pub const MAX_PIXELS: u64 = 1 << 27;

/// Opens a PNG, JPEG or TIFF, refusing from its header one above `MAX_PIXELS`, and turned as
/// its EXIF orientation says (as OpenCV's `imread` and every photo viewer show it), so a
/// phone's portrait photograph stored sideways is read upright.
pub fn open_limited(path: &Path) -> Result<image::DynamicImage, Error> {
    use image::ImageDecoder;
    let err = |message: String| Error::Decode { path: path.to_path_buf(), message };
    let unreadable = |e: std::io::Error| Error::Read { path: path.to_path_buf(), message: e.to_string() };
    let decode = |e: image::ImageError| match e {
        image::ImageError::IoError(e) => unreadable(e),
        e => err(e.to_string()),
    };
    let reader = image::ImageReader::open(path).and_then(|r| r.with_guessed_format()).map_err(unreadable)?;
    let mut decoder = reader.into_decoder().map_err(decode)?;
    let (w, h) = decoder.dimensions();
    if w as u64 * h as u64 > MAX_PIXELS {
        return Err(err(format!(
            "{w}×{h} pixels, above the limit of {} million ({MAX_PIXELS} pixels)",
            MAX_PIXELS / 1_000_000
        )));
    }
    // An unreadable EXIF block leaves the pixels as stored rather than refusing the image.
    let orientation = decoder.orientation().unwrap_or(image::metadata::Orientation::NoTransforms);
    let mut img = image::DynamicImage::from_decoder(decoder).map_err(decode)?;
    img.apply_orientation(orientation);
    Ok(img)
}

/// Reads a PNG or JPEG as linear floats in [0, 1] without any transfer function (raw code
/// values / max code value), keeping 16-bit depth. Colour images give 3 channels, grey 1.
pub fn read_raw(path: &Path) -> Result<Image, Error> {
    let dynimg = open_limited(path)?;
    let (w, h) = (dynimg.width(), dynimg.height());
    let grey = !dynimg.color().has_color();
    Ok(if grey {
        let buf = dynimg.into_luma16();
        Image { width: w, height: h, channels: 1, data: buf.iter().map(|&v| v as f32 / 65535.0).collect() }
    } else {
        let buf = dynimg.into_rgb16();
        Image { width: w, height: h, channels: 3, data: buf.iter().map(|&v| v as f32 / 65535.0).collect() }
    })
}

/// Writes by extension: `.exr` linear float, `.png` 8-bit sRGB.
pub fn write(path: &Path, img: &Image) -> Result<(), Error> {
    match extension(path).as_str() {
        "exr" => write_exr(path, img),
        "png" => write_png_srgb(path, img),
        _ => Err(Error::Format { path: path.into() }),
    }
}

/// Reads by extension: `.exr` as stored; `.png`/`.jpg` as raw code values in [0, 1].
pub fn read(path: &Path) -> Result<Image, Error> {
    match extension(path).as_str() {
        "exr" => read_exr(path),
        "png" | "jpg" | "jpeg" | "tif" | "tiff" => read_raw(path),
        _ => Err(Error::Format { path: path.into() }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Files written together appear together: on an error none of them is in place and the
    /// staging folder is gone; on success all are, beside what the folder already held.
    #[test]
    fn files_written_together_appear_all_or_not_at_all() {
        let root = std::env::temp_dir().join(format!("lumen-io-together-{}", std::process::id()));
        let dir = root.join("out");
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("mine.txt"), "kept").unwrap();
        let failed: Result<(), Error> = write_together(&dir, |tmp| {
            std::fs::write(tmp.join("a.txt"), "a").unwrap();
            Err(Error::Write { path: tmp.join("b.txt"), message: "disk full".into() })
        });
        assert!(failed.is_err());
        assert!(!dir.join("a.txt").exists());
        assert_eq!(std::fs::read_dir(&root).unwrap().count(), 1, "the staging folder is removed");
        std::fs::create_dir_all(dir.join("sub")).unwrap();
        std::fs::write(dir.join("sub/old.txt"), "kept").unwrap();
        write_together(&dir, |tmp| {
            std::fs::write(tmp.join("a.txt"), "a").unwrap();
            std::fs::create_dir_all(tmp.join("sub")).unwrap();
            std::fs::write(tmp.join("sub/b.txt"), "b").unwrap();
            Ok::<_, Error>(())
        })
        .unwrap();
        for f in ["a.txt", "sub/b.txt", "sub/old.txt", "mine.txt"] {
            assert!(dir.join(f).is_file(), "{f}");
        }
        assert_eq!(std::fs::read_dir(&root).unwrap().count(), 1);
        std::fs::remove_dir_all(&root).unwrap();
    }

    /// A PNG whose header claims 20000 × 10000 pixels (a 70-byte file) is refused from its
    /// header, naming the size, before anything is decoded.
    #[test]
    fn png_above_the_pixel_limit_is_refused_from_its_header() {
        let chunk = |kind: &[u8], data: &[u8]| {
            let mut crc = flate2::Crc::new();
            crc.update(kind);
            crc.update(data);
            let mut c = (data.len() as u32).to_be_bytes().to_vec();
            c.extend(kind);
            c.extend(data);
            c.extend(crc.sum().to_be_bytes());
            c
        };
        let mut ihdr = 20000u32.to_be_bytes().to_vec();
        ihdr.extend(10000u32.to_be_bytes());
        ihdr.extend([8, 0, 0, 0, 0]);
        let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
        png.extend(chunk(b"IHDR", &ihdr));
        let z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
        png.extend(chunk(b"IDAT", &z.finish().unwrap()));
        png.extend(chunk(b"IEND", &[]));
        let p = std::env::temp_dir().join(format!("lumen-io-big-{}.png", std::process::id()));
        std::fs::write(&p, &png).unwrap();
        let e = read(&p).unwrap_err().to_string();
        std::fs::remove_file(&p).unwrap();
        assert!(e.contains("20000×10000 pixels") && e.contains("limit"), "{e}");
    }

    /// A small file whose header claims 100000 × 100000 pixels: refused from the header.
    #[test]
    fn exr_claiming_a_huge_size_is_refused() {
        let dir = std::env::temp_dir().join(format!("lumen-io-huge-{}", std::process::id()));
        let p = dir.join("huge.exr");
        write_exr(&p, &Image::new(4, 4, 3)).unwrap();
        let mut bytes = std::fs::read(&p).unwrap();
        let key = b"dataWindow\0box2i\0";
        let at = bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len() + 4;
        bytes[at + 8..at + 12].copy_from_slice(&99_999i32.to_le_bytes());
        bytes[at + 12..at + 16].copy_from_slice(&99_999i32.to_le_bytes());
        std::fs::write(&p, &bytes).unwrap();
        let e = read_exr(&p).unwrap_err().to_string();
        assert!(e.contains("huge.exr") && e.contains("100000×100000") && e.contains("limit"), "{e}");
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn exr_round_trip() {
        let dir = std::env::temp_dir().join(format!("lumen-io-{}", std::process::id()));
        let mut img = Image::new(5, 3, 3);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = i as f32 * 0.25 - 1.0;
        }
        let p = dir.join("a.exr");
        write_exr(&p, &img).unwrap();
        assert_eq!(read_exr(&p).unwrap(), img);
        let mut grey = Image::new(4, 2, 1);
        grey.data[3] = 7.5;
        write_exr(&p, &grey).unwrap();
        assert_eq!(read_exr(&p).unwrap(), grey);
        let _ = std::fs::remove_dir_all(dir);
    }
}
