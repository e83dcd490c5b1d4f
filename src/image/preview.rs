//! PNG previews of EXR images, for people with nothing that opens EXR: radiance tone-mapped
//! (Reinhard's global operator, `hdr::tonemap`) and sRGB-encoded; normals as (n + 1)/2;
//! depth (0: no hit) and other scalars in viridis over their range with a labelled colour bar; object ids
//! in distinct colours; albedo sRGB-encoded as it is; positions with each axis over its range.
//! Pixels without a value (depth exactly 0, normal 0, id 0, not finite) are black.

use super::{colormap, io, Image};
use crate::error::Invalid;
use std::path::{Path, PathBuf};

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kind {
    Radiance,
    Normal,
    Depth,
    Id,
    Albedo,
    Position,
    /// Any other one- or three-channel value (a variance, a shininess map), shown as the
    /// mean over channels.
    Scalar,
}

pub const KIND_NAMES: &str = "radiance, normal, depth, id, albedo, position or scalar";

impl std::str::FromStr for Kind {
    type Err = Invalid;
    fn from_str(s: &str) -> Result<Kind, Invalid> {
        Ok(match s {
            "radiance" => Kind::Radiance,
            "normal" | "normal_camera" => Kind::Normal,
            "depth" => Kind::Depth,
            "id" => Kind::Id,
            "albedo" => Kind::Albedo,
            "position" => Kind::Position,
            "scalar" | "variance" => Kind::Scalar,
            other => return Err(format!("kind `{other}`: expected {KIND_NAMES}").into()),
        })
    }
}

/// The kind of an EXR from its name as `lumen render --aov` writes it (`NAME.<aov>.exr`, and
/// `normals.exr`, `depth.exr` … as `lumen ps` does), else from its channels: one a scalar,
/// three radiance.
pub fn kind_of(path: &Path, img: &Image) -> Kind {
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("");
    let last = stem.rsplit('.').next().unwrap_or(stem);
    let named = match last {
        "normals" => Some(Kind::Normal),
        "shininess" | "specular" => Some(Kind::Scalar),
        other => other.parse().ok(),
    };
    named.unwrap_or(if img.channels == 1 { Kind::Scalar } else { Kind::Radiance })
}

/// The preview's RGB8 pixels and size (a colour bar widens scalar previews).
pub fn rgb8(img: &Image, kind: Kind) -> (Vec<u8>, u32, u32) {
    let c = img.channels as usize;
    let px = || img.data.chunks_exact(c);
    let byte = |v: f64| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    let srgb = |v: f32| byte(super::srgb_encode(v.max(0.0)) as f64);
    let (w, h) = (img.width, img.height);
    let three = |f: &dyn Fn(&[f32]) -> [u8; 3]| -> Vec<u8> { px().flat_map(f).collect() };
    match kind {
        Kind::Radiance => {
            let rgb = first_three(img);
            let mapped = crate::hdr::tonemap::reinhard(&finite_or_zero(&rgb));
            (mapped.data.iter().map(|&v| srgb(v)).collect(), w, h)
        }
        Kind::Albedo => (three(&|p| [0, 1, 2].map(|k| srgb(p[k.min(c - 1)]))), w, h),
        Kind::Normal => (
            three(&|p| {
                let n = [0, 1, 2].map(|k| p[k.min(c - 1)]);
                if n.iter().all(|v| v.is_finite()) && n.iter().any(|v| *v != 0.0) {
                    n.map(|v| byte((v as f64 + 1.0) * 0.5))
                } else {
                    [0; 3]
                }
            }),
            w,
            h,
        ),
        Kind::Id => (
            three(&|p| {
                let id = p[0];
                if !(id.is_finite() && id >= 1.0) {
                    return [0; 3];
                }
                // Hues a golden angle apart: neighbouring ids differ, any number of them.
                let hue = (id as f64 * 0.618_033_988_75).fract();
                hsv(hue, 0.65, 0.95)
            }),
            w,
            h,
        ),
        Kind::Position => {
            let range: Vec<(f64, f64)> =
                (0..c.min(3)).map(|k| finite_range(px().map(|p| p[k]), false)).collect();
            let rgb = three(&|p| {
                [0, 1, 2].map(|k| match range.get(k) {
                    Some(&(lo, hi)) if p[k].is_finite() && hi > lo => byte((p[k] as f64 - lo) / (hi - lo)),
                    _ => 0,
                })
            });
            (rgb, w, h)
        }
        Kind::Depth | Kind::Scalar => {
            let depth = kind == Kind::Depth;
            let value = |p: &[f32]| p.iter().map(|&v| v as f64).sum::<f64>() / c as f64;
            let (lo, hi) = finite_range(px().map(|p| value(p) as f32), depth);
            let rgb = three(&|p| {
                let v = value(p);
                if !v.is_finite() || (depth && v == 0.0) {
                    [0; 3]
                } else {
                    colormap::viridis(if hi > lo { (v - lo) / (hi - lo) } else { 0.5 })
                }
            });
            colormap::with_colour_bar(&rgb, w, h, &colormap::label(lo), &colormap::label(hi))
        }
    }
}

/// Writes `img`'s preview as an 8-bit PNG.
pub fn write(path: &Path, img: &Image, kind: Kind) -> Result<(), io::Error> {
    let (rgb, w, h) = rgb8(img, kind);
    let values: Vec<u16> = rgb.into_iter().map(u16::from).collect();
    io::write_png_raw(path, w, h, 3, &values, 8)
}

/// `x.exr` → `x.png`, beside it.
pub fn png_path(exr: &Path) -> PathBuf {
    exr.with_extension("png")
}

/// RGB from the first three channels (grey repeated; alpha dropped).
fn first_three(img: &Image) -> Image {
    let c = img.channels as usize;
    let data = img.data.chunks_exact(c).flat_map(|p| [0, 1, 2].map(|k| p[k.min(c - 1)])).collect();
    Image { width: img.width, height: img.height, channels: 3, data }
}

fn finite_or_zero(img: &Image) -> Image {
    let data = img.data.iter().map(|&v| if v.is_finite() { v } else { 0.0 }).collect();
    Image { data, ..img.clone() }
}

/// The smallest and largest finite values (0 left out with `skip_zero`: a depth's "no hit");
/// (0, 0) when none.
fn finite_range(values: impl Iterator<Item = f32>, skip_zero: bool) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && (!skip_zero || *v != 0.0))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v as f64), hi.max(v as f64)));
    if lo <= hi {
        (lo, hi)
    } else {
        (0.0, 0.0)
    }
}

fn hsv(h: f64, s: f64, v: f64) -> [u8; 3] {
    let f = |n: f64| {
        let k = (n + h * 6.0) % 6.0;
        v - v * s * k.min(4.0 - k).clamp(0.0, 1.0)
    };
    [f(5.0), f(3.0), f(1.0)].map(|x| (x * 255.0 + 0.5) as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_come_from_names_then_channels() {
        let one = Image::new(2, 2, 1);
        let three = Image::new(2, 2, 3);
        assert_eq!(kind_of(Path::new("box.depth.exr"), &one), Kind::Depth);
        assert_eq!(kind_of(Path::new("box.normal_camera.exr"), &three), Kind::Normal);
        assert_eq!(kind_of(Path::new("ps/normals.exr"), &three), Kind::Normal);
        assert_eq!(kind_of(Path::new("box.exr"), &three), Kind::Radiance);
        assert_eq!(kind_of(Path::new("box.variance.exr"), &three), Kind::Scalar);
        assert_eq!(kind_of(Path::new("thing.exr"), &one), Kind::Scalar);
        assert!("shiny".parse::<Kind>().unwrap_err().0.contains("expected radiance"));
    }

    #[test]
    fn depth_runs_over_its_range_and_misses_are_black() {
        let img = Image { width: 3, height: 1, channels: 1, data: vec![0.0, 1.0, 3.0] };
        let (rgb, w, h) = rgb8(&img, Kind::Depth);
        assert!(w > 3 && h == 64);
        let at = |x: usize| [rgb[3 * x], rgb[3 * x + 1], rgb[3 * x + 2]];
        assert_eq!(at(0), [0, 0, 0]);
        assert_eq!(at(1), colormap::viridis(0.0));
        assert_eq!(at(2), colormap::viridis(1.0));
        let n = Image { width: 2, height: 1, channels: 3, data: vec![0.0, 0.0, 1.0, 0.0, 0.0, 0.0] };
        let (rgb, _, _) = rgb8(&n, Kind::Normal);
        assert_eq!(rgb, vec![128, 128, 255, 0, 0, 0]);
        let bad = Image {
            width: 2,
            height: 1,
            channels: 3,
            data: vec![f32::NAN, 1e30, f32::INFINITY, 0.5, 0.5, 0.5],
        };
        let (rgb, _, _) = rgb8(&bad, Kind::Radiance);
        assert_eq!(rgb.len(), 6);
    }
}
