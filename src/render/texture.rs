//! Textures of colour and roughness: constant, image (bilinear, wrapping) and procedural
//! checkerboard, and their scene-file schema (`TextureSpec`, `RoughnessSpec`).

use super::Error;
use glam::{Vec2, Vec3A};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A colour: constant `[r, g, b]`, an image `{ texture = "file.png" }` (8-bit files are
/// sRGB-decoded, 16-bit and EXR taken as linear), a procedural checkerboard
/// `{ checker = { squares = [nu, nv], even = [..], odd = [..] } }` over texture coordinates,
/// or coloured noise `{ noise = { seed = 1, low = [..], high = [..] } }` (`NoiseSpec`).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(untagged)]
pub enum TextureSpec {
    Constant([f64; 3]),
    Image { texture: String },
    Checker { checker: CheckerSpec },
    Noise { noise: NoiseSpec },
}

/// Coloured value noise over the texture domain: `octaves` layers of random values on
/// lattices of 4, 8, 16 … cells across, each 0.7 times the amplitude of the one before, smoothly
/// interpolated and wrapping at the domain's edges, through a steep contrast curve, with
/// values between `low` and `high` per channel. Blobs of every size with no repeat: what
/// feature detectors need, as a photographed wall or ground has it (a checkerboard's corners
/// all look alike).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseSpec {
    pub seed: u64,
    /// Octaves, 1 to 8 (default 6).
    #[serde(default = "default_octaves")]
    pub octaves: u32,
    /// Texels per side of the image the noise is evaluated into, 16 to 2048 (default 512).
    #[serde(default = "default_noise_size")]
    pub size: u32,
    pub low: [f64; 3],
    pub high: [f64; 3],
}

fn default_octaves() -> u32 {
    6
}
fn default_noise_size() -> u32 {
    512
}

/// A roughness: a number, a greyscale image `{ texture = "alpha.png" }` (first channel, taken
/// as data: 8-bit values are v/255 with no sRGB decoding; values must lie in [0, 1], and those
/// below 0.001 are raised to it), or a
/// checkerboard `{ checker = { squares = [nu, nv], even = a, odd = b } }`.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(untagged)]
pub enum RoughnessSpec {
    Constant(f64),
    Image { texture: String },
    Checker { checker: RoughnessCheckerSpec },
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RoughnessCheckerSpec {
    pub squares: [u32; 2],
    pub even: f64,
    pub odd: f64,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
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
    /// The mean value over the texture's domain.
    pub fn mean(&self) -> Vec3A {
        match self {
            Texture::Constant(v) => *v,
            Texture::Image { texels, .. } => {
                texels.iter().fold(Vec3A::ZERO, |s, t| s + *t) / texels.len().max(1) as f32
            }
            Texture::Checker { even, odd, .. } => (*even + *odd) / 2.0,
        }
    }

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
            TextureSpec::Noise { noise } => {
                let low = albedo3(noise.low, path, &format!("{field}.noise.low"))?;
                let high = albedo3(noise.high, path, &format!("{field}.noise.high"))?;
                if !(1..=8).contains(&noise.octaves) || !(16..=2048).contains(&noise.size) {
                    return Err(Error::Invalid {
                        path: path.into(),
                        field: format!("{field}.noise"),
                        message: format!(
                            "octaves = {}, size = {}: expected 1 to 8 octaves and 16 to 2048 texels",
                            noise.octaves, noise.size
                        ),
                    });
                }
                value_noise(noise.seed, noise.octaves, noise.size, low, high)
            }
            TextureSpec::Image { texture } => {
                let file = dir.join(texture);
                let img = crate::image::io::read(&file)?;
                texels_in_unit_range(&img.data, &file, path, field, "an albedo")?;
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
                let file = dir.join(texture);
                let img = crate::image::io::read(&file)?;
                // Within [0, 1] as a constant must be; values below 0.001 (a black texel) are
                // raised to it, as documented.
                texels_in_unit_range(&img.data, &file, path, field, "a roughness")?;
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

/// A texture's values must be finite and lie in [0, 1], as the constant they stand for must:
/// refused naming the file otherwise, never clamped silently.
fn texels_in_unit_range(
    data: &[f32],
    file: &Path,
    path: &Path,
    field: &str,
    what: &str,
) -> Result<(), Error> {
    let bad = data.iter().filter(|v| !(v.is_finite() && (0.0..=1.0).contains(*v))).count();
    if bad == 0 {
        return Ok(());
    }
    let (mn, mx) = data
        .iter()
        .filter(|v| v.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), v| (a.min(*v), b.max(*v)));
    Err(Error::Invalid {
        path: path.into(),
        field: field.into(),
        message: format!(
            "{}: {bad} values are not finite or outside [0, 1] (finite ones from {mn} to {mx}); {what} must lie in [0, 1]",
            file.display()
        ),
    })
}

/// `NoiseSpec`'s texture, evaluated into a `size`² image.
fn value_noise(seed: u64, octaves: u32, size: u32, low: Vec3A, high: Vec3A) -> Texture {
    use super::sampler::mix64;
    let n = size as usize;
    let mut sum = vec![Vec3A::ZERO; n * n];
    let smooth = |t: f32| t * t * (3.0 - 2.0 * t);
    for o in 0..octaves {
        let cells = 4u64 << o;
        let amplitude = 0.7f32.powi(o as i32);
        // A lattice value per node and channel in [0, 1), wrapping every `cells` nodes.
        let node = |i: u64, j: u64| {
            let h = mix64(seed ^ mix64((o as u64) << 48 ^ (i % cells) << 24 ^ (j % cells)));
            Vec3A::new(
                (h & 0xffff) as f32 / 65536.0,
                ((h >> 16) & 0xffff) as f32 / 65536.0,
                ((h >> 32) & 0xffff) as f32 / 65536.0,
            )
        };
        for y in 0..n {
            let fy = (y as f32 + 0.5) / n as f32 * cells as f32;
            let (j, ty) = (fy.floor() as u64, smooth(fy.fract()));
            for x in 0..n {
                let fx = (x as f32 + 0.5) / n as f32 * cells as f32;
                let (i, tx) = (fx.floor() as u64, smooth(fx.fract()));
                let top = node(i, j).lerp(node(i + 1, j), tx);
                let bottom = node(i, j + 1).lerp(node(i + 1, j + 1), tx);
                sum[y * n + x] += top.lerp(bottom, ty) * amplitude;
            }
        }
    }
    // Stretched so that each channel spans [low, high].
    let (mut lo, mut hi) = (Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY));
    for v in &sum {
        lo = lo.min(*v);
        hi = hi.max(*v);
    }
    let span = (hi - lo).max(Vec3A::splat(1e-6));
    // A steep contrast curve turns the smooth noise into patches with crisp edges at every
    // scale, as paint, stone and foliage have them (smooth noise has weak corners and blobs).
    let curve = |t: f32| 0.5 + 0.5 * (4.0 * (t - 0.5)).tanh() / 2f32.tanh();
    let texels = sum
        .iter()
        .map(|v| {
            // Mostly one noise in every channel, so that the grey image a detector sees keeps
            // the contrast (three independent channels would average out), a little of each
            // channel's own for colour.
            let t = (*v - lo) / span;
            let t = Vec3A::splat(0.75 * t.x) + 0.25 * t;
            low + (high - low) * Vec3A::new(curve(t.x), curve(t.y), curve(t.z))
        })
        .collect();
    Texture::Image { width: size, height: size, texels }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(seed: u64, octaves: u32) -> Texture {
        let spec = TextureSpec::Noise {
            noise: NoiseSpec { seed, octaves, size: 64, low: [0.1, 0.2, 0.3], high: [0.8, 0.7, 0.9] },
        };
        Texture::build(&spec, Path::new("."), Path::new("s.toml"), "albedo").unwrap()
    }

    /// Noise spans [low, high] per channel, is the same for a seed and differs between seeds,
    /// and wraps: the left and right edges, and the top and bottom, continue each other.
    #[test]
    fn noise_spans_its_range_repeats_per_seed_and_wraps() {
        let Texture::Image { texels, width, .. } = noise(7, 6) else { panic!("an image texture") };
        let n = width as usize;
        for (c, (lo, hi)) in [(0.1f32, 0.8f32), (0.2, 0.7), (0.3, 0.9)].into_iter().enumerate() {
            let (mn, mx) = texels.iter().fold((1f32, 0f32), |(a, b), t| (a.min(t[c]), b.max(t[c])));
            assert!(mn >= lo - 1e-5 && mx <= hi + 1e-5 && mx - mn > 0.5 * (hi - lo), "{c}: {mn}..{mx}");
        }
        let Texture::Image { texels: again, .. } = noise(7, 6) else { panic!() };
        assert_eq!(texels, again);
        let Texture::Image { texels: other, .. } = noise(8, 6) else { panic!() };
        assert_ne!(texels, other);
        // Across the wrap the step is no larger than between neighbours inside.
        let step = |a: Vec3A, b: Vec3A| (a - b).abs().max_element();
        let inside = (0..n).map(|y| step(texels[y * n], texels[y * n + 1])).fold(0.0, f32::max);
        let wrap = (0..n).map(|y| step(texels[y * n], texels[y * n + n - 1])).fold(0.0, f32::max);
        assert!(wrap <= 2.0 * inside, "wrap step {wrap} against {inside} inside");
        let spec = TextureSpec::Noise {
            noise: NoiseSpec { seed: 1, octaves: 9, size: 64, low: [0.0; 3], high: [1.0; 3] },
        };
        let e =
            Texture::build(&spec, Path::new("."), Path::new("s.toml"), "albedo").err().unwrap().to_string();
        assert!(e.contains("albedo.noise") && e.contains("octaves = 9"), "{e}");
    }
}
