//! Textures of colour and roughness: constant, image (bilinear, wrapping) and procedural
//! checkerboard, and their scene-file schema (`TextureSpec`, `RoughnessSpec`).

use super::Error;
use glam::{Vec2, Vec3A};
use serde::Deserialize;
use std::path::Path;

/// A colour: constant `[r, g, b]`, an image `{ texture = "file.png" }` (8-bit files are
/// sRGB-decoded, 16-bit and EXR taken as linear) or a procedural checkerboard
/// `{ checker = { squares = [nu, nv], even = [..], odd = [..] } }` over texture coordinates.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
pub enum TextureSpec {
    Constant([f64; 3]),
    Image { texture: String },
    Checker { checker: CheckerSpec },
}

/// A roughness: a number, a greyscale image `{ texture = "alpha.png" }` (first channel, taken
/// as data: 8-bit values are v/255 with no sRGB decoding, and clamped to [0.001, 1]), or a
/// checkerboard `{ checker = { squares = [nu, nv], even = a, odd = b } }`.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
pub enum RoughnessSpec {
    Constant(f64),
    Image { texture: String },
    Checker { checker: RoughnessCheckerSpec },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoughnessCheckerSpec {
    pub squares: [u32; 2],
    pub even: f64,
    pub odd: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CheckerSpec {
    /// Number of squares along u and v over the [0, 1]² texture domain.
    pub squares: [u32; 2],
    pub even: [f64; 3],
    pub odd: [f64; 3],
}

pub enum Texture {
    Constant(Vec3A),
    Image { width: u32, height: u32, texels: Vec<Vec3A> },
    Checker { squares: [u32; 2], even: Vec3A, odd: Vec3A },
}

impl Texture {
    /// Multiplies every value by `s` (in [0, 1], so an albedo stays an albedo).
    pub fn scale(&mut self, s: f32) {
        match self {
            Texture::Constant(v) => *v *= s,
            Texture::Image { texels, .. } => texels.iter_mut().for_each(|t| *t *= s),
            Texture::Checker { even, odd, .. } => {
                *even *= s;
                *odd *= s;
            }
        }
    }
}

/// An albedo above 1 would create energy; each value must lie in [0, 1].
fn albedo3(v: [f64; 3], path: &Path, field: &str) -> Result<Vec3A, Error> {
    if v.iter().all(|c| c.is_finite() && (0.0..=1.0).contains(c)) {
        Ok(Vec3A::new(v[0] as f32, v[1] as f32, v[2] as f32))
    } else {
        Err(Error::Invalid {
            path: path.into(),
            field: field.into(),
            message: format!("{v:?}: each value must be in [0, 1]"),
        })
    }
}

/// A checkerboard's square counts, each at least 1.
fn squares(squares: [u32; 2], path: &Path, field: &str) -> Result<[u32; 2], Error> {
    if squares.contains(&0) {
        return Err(Error::Invalid {
            path: path.into(),
            field: format!("{field}.checker.squares"),
            message: "must be at least 1 each".into(),
        });
    }
    Ok(squares)
}

impl Texture {
    pub fn build(spec: &TextureSpec, dir: &Path, path: &Path, field: &str) -> Result<Texture, Error> {
        Ok(match spec {
            TextureSpec::Constant(v) => Texture::Constant(albedo3(*v, path, field)?),
            TextureSpec::Checker { checker } => Texture::Checker {
                squares: squares(checker.squares, path, field)?,
                even: albedo3(checker.even, path, &format!("{field}.checker.even"))?,
                odd: albedo3(checker.odd, path, &format!("{field}.checker.odd"))?,
            },
            TextureSpec::Image { texture } => {
                let file = dir.join(texture);
                let img = crate::image::io::read(&file)?;
                let eight_bit = is_eight_bit(&file);
                let c = img.channels as usize;
                let texels = img
                    .data
                    .chunks_exact(c)
                    .map(|p| {
                        let rgb = if c >= 3 { [p[0], p[1], p[2]] } else { [p[0]; 3] };
                        let lin = rgb.map(|v| if eight_bit { crate::image::srgb_decode(v) } else { v });
                        Vec3A::from(lin).clamp(Vec3A::ZERO, Vec3A::ONE)
                    })
                    .collect();
                Texture::Image { width: img.width, height: img.height, texels }
            }
        })
    }

    /// A roughness texture (`RoughnessSpec`), its value in every channel, within [0.001, 1].
    pub fn build_roughness(
        spec: &RoughnessSpec,
        dir: &Path,
        path: &Path,
        field: &str,
    ) -> Result<Texture, Error> {
        let check = |a: f64, field: String| {
            if (0.001..=1.0).contains(&a) {
                Ok(Vec3A::splat(a as f32))
            } else {
                Err(Error::Invalid { path: path.into(), field, message: format!("{a}: expected [0.001, 1]") })
            }
        };
        Ok(match spec {
            RoughnessSpec::Constant(a) => Texture::Constant(check(*a, field.into())?),
            RoughnessSpec::Checker { checker } => Texture::Checker {
                squares: squares(checker.squares, path, field)?,
                even: check(checker.even, format!("{field}.checker.even"))?,
                odd: check(checker.odd, format!("{field}.checker.odd"))?,
            },
            RoughnessSpec::Image { texture } => {
                let img = crate::image::io::read(&dir.join(texture))?;
                let c = img.channels as usize;
                let texels = img.data.chunks_exact(c).map(|p| Vec3A::splat(p[0].clamp(0.001, 1.0))).collect();
                Texture::Image { width: img.width, height: img.height, texels }
            }
        })
    }

    /// Value at texture coordinates (u, v); v = 0 is the bottom row of an image, as in OBJ.
    #[inline]
    pub fn eval(&self, uv: Vec2) -> Vec3A {
        match self {
            Texture::Constant(c) => *c,
            Texture::Checker { squares, even, odd } => {
                let i = (uv.x * squares[0] as f32).floor() as i64 + (uv.y * squares[1] as f32).floor() as i64;
                if i.rem_euclid(2) == 0 {
                    *even
                } else {
                    *odd
                }
            }
            Texture::Image { width, height, texels } => {
                let (w, h) = (*width as i64, *height as i64);
                let x = uv.x * w as f32 - 0.5;
                let y = (1.0 - uv.y) * h as f32 - 0.5;
                let (x0, y0) = (x.floor(), y.floor());
                let (fx, fy) = (x - x0, y - y0);
                let at = |i: i64, j: i64| texels[(j.rem_euclid(h) * w + i.rem_euclid(w)) as usize];
                let (i, j) = (x0 as i64, y0 as i64);
                (at(i, j) * (1.0 - fx) + at(i + 1, j) * fx) * (1.0 - fy)
                    + (at(i, j + 1) * (1.0 - fx) + at(i + 1, j + 1) * fx) * fy
            }
        }
    }
}

/// 8-bit images hold sRGB-encoded values; 16-bit and float ones are taken as linear.
fn is_eight_bit(path: &Path) -> bool {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if ext == "exr" {
        return false;
    }
    image::open(path)
        .map(|i| {
            matches!(
                i.color(),
                image::ColorType::L8
                    | image::ColorType::La8
                    | image::ColorType::Rgb8
                    | image::ColorType::Rgba8
            )
        })
        .unwrap_or(false)
}
