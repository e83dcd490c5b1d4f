//! Reading Mitsuba's parameters off a plugin element: `Props` (each lookup marks its child
//! used, so what no lookup asked for is refused), numbers, points, colours (`rgb`, `float`,
//! `spectrum`), textures (`checkerboard`, `bitmap`) and `transform`s.

use super::super::super::texture::{CheckerSpec, TextureSpec};
use super::super::super::Error;
use super::spectrum;
use super::xml::Elem;
use glam::{DAffine3, DMat3, DVec3};
use std::cell::RefCell;

/// Mitsuba's parameters as lumen reads them off one plugin element: each lookup marks its
/// child used, and `finish` refuses the children no lookup asked for.
pub(super) struct Props<'a> {
    e: &'a Elem,
    used: RefCell<Vec<bool>>,
}

impl<'a> Props<'a> {
    pub(super) fn new(e: &'a Elem) -> Self {
        Props { e, used: RefCell::new(vec![false; e.children.len()]) }
    }

    pub(super) fn find(&self, name: &str) -> Option<&'a Elem> {
        let i = self.e.children.iter().position(|c| c.attr("name") == Some(name))?;
        self.used.borrow_mut()[i] = true;
        Some(&self.e.children[i])
    }

    /// Nested plugins of a tag (named or not).
    pub(super) fn objects(&self, tag: &str) -> Vec<&'a Elem> {
        let mut out = Vec::new();
        for (i, c) in self.e.children.iter().enumerate() {
            if c.tag == tag {
                self.used.borrow_mut()[i] = true;
                out.push(c);
            }
        }
        out
    }

    /// Marks a parameter read whose value does not change what lumen renders.
    pub(super) fn accept(&self, names: &[&str]) {
        for n in names {
            self.find(n);
        }
    }

    fn value(&self, c: &Elem) -> Result<String, Error> {
        c.attr("value").map(str::to_string).ok_or_else(|| c.error("needs `value`"))
    }

    pub(super) fn float(&self, name: &str) -> Result<Option<f64>, Error> {
        let Some(c) = self.find(name) else { return Ok(None) };
        if c.tag != "float" && c.tag != "integer" {
            return Err(c.error(format!("`{name}` must be a <float>")));
        }
        number(c, &self.value(c)?).map(Some)
    }

    pub(super) fn int(&self, name: &str) -> Result<Option<i64>, Error> {
        let Some(c) = self.find(name) else { return Ok(None) };
        let v = self.value(c)?;
        if c.tag != "integer" {
            return Err(c.error(format!("`{name}` must be an <integer>")));
        }
        v.trim().parse().map(Some).map_err(|_| c.error(format!("\"{v}\" is not an integer")))
    }

    pub(super) fn string(&self, name: &str) -> Result<Option<String>, Error> {
        let Some(c) = self.find(name) else { return Ok(None) };
        if c.tag != "string" {
            return Err(c.error(format!("`{name}` must be a <string>")));
        }
        self.value(c).map(Some)
    }

    pub(super) fn boolean(&self, name: &str) -> Result<Option<bool>, Error> {
        let Some(c) = self.find(name) else { return Ok(None) };
        match (c.tag.as_str(), self.value(c)?.as_str()) {
            ("boolean", "true") => Ok(Some(true)),
            ("boolean", "false") => Ok(Some(false)),
            (_, v) => Err(c.error(format!("`{name}` = \"{v}\": expected <boolean> true or false"))),
        }
    }

    /// A `point` or `vector`: `value="x, y, z"` or `x`, `y`, `z` attributes (default 0).
    pub(super) fn point(&self, name: &str) -> Result<Option<DVec3>, Error> {
        let Some(c) = self.find(name) else { return Ok(None) };
        if c.tag != "point" && c.tag != "vector" {
            return Err(c.error(format!("`{name}` must be a <point> or <vector>")));
        }
        triple(c, 0.0).map(Some)
    }

    /// A colour: `rgb`, a constant `spectrum`, a `float`, or a texture.
    pub(super) fn color(&self, name: &str) -> Result<Option<Color>, Error> {
        let Some(c) = self.find(name) else { return Ok(None) };
        color(c).map(Some)
    }

    pub(super) fn transform(&self, name: &str) -> Result<Option<DAffine3>, Error> {
        let Some(c) = self.find(name) else { return Ok(None) };
        if c.tag != "transform" {
            return Err(c.error(format!("`{name}` must be a <transform>")));
        }
        transform(c).map(Some)
    }

    /// Refuses every child no lookup asked for.
    pub(super) fn finish(self, supported: &str) -> Result<(), Error> {
        let used = self.used.borrow();
        match self.e.children.iter().zip(used.iter()).find(|(_, &u)| !u) {
            None => Ok(()),
            Some((c, _)) => Err(c.unsupported(format!(
                "in {}: lumen does not read this parameter here (it reads {supported})",
                self.e.describe()
            ))),
        }
    }
}

pub(super) enum Color {
    Rgb([f64; 3]),
    Texture(TextureSpec),
}

impl Color {
    pub(super) fn rgb(self, at: &Elem, what: &str) -> Result<[f64; 3], Error> {
        match self {
            Color::Rgb(v) => Ok(v),
            Color::Texture(_) => {
                Err(at.unsupported(format!("a texture for `{what}`: lumen takes a colour here")))
            }
        }
    }

    pub(super) fn texture(self) -> TextureSpec {
        match self {
            Color::Rgb(v) => TextureSpec::Constant(v),
            Color::Texture(t) => t,
        }
    }
}

pub(super) fn number(at: &Elem, v: &str) -> Result<f64, Error> {
    v.trim()
        .parse::<f64>()
        .ok()
        .filter(|x| x.is_finite())
        .ok_or_else(|| at.error(format!("\"{v}\" is not a finite number")))
}

/// Numbers separated by commas or spaces.
fn numbers(at: &Elem, v: &str) -> Result<Vec<f64>, Error> {
    v.split(|c: char| c == ',' || c.is_whitespace())
        .filter(|s| !s.is_empty())
        .map(|s| number(at, s))
        .collect()
}

/// Three numbers from `value` (one number repeated, or three) or from `x`, `y`, `z`.
fn triple(e: &Elem, default: f64) -> Result<DVec3, Error> {
    if let Some(v) = e.attr("value") {
        return match numbers(e, v)?.as_slice() {
            [a] => Ok(DVec3::splat(*a)),
            [a, b, c] => Ok(DVec3::new(*a, *b, *c)),
            _ => Err(e.error(format!("`value` \"{v}\": expected one or three numbers"))),
        };
    }
    let get = |k: &str| e.attr(k).map_or(Ok(default), |v| number(e, v));
    Ok(DVec3::new(get("x")?, get("y")?, get("z")?))
}

fn color(c: &Elem) -> Result<Color, Error> {
    match c.tag.as_str() {
        "rgb" | "float" => {
            let v = c.attr("value").ok_or_else(|| c.error("needs `value`"))?;
            match numbers(c, v)?.as_slice() {
                [a] => Ok(Color::Rgb([*a; 3])),
                [r, g, b] if c.tag == "rgb" => Ok(Color::Rgb([*r, *g, *b])),
                _ => Err(c.error(format!("`value` \"{v}\": expected one or three numbers"))),
            }
        }
        "spectrum" => {
            if c.attr("type") == Some("blackbody") {
                return Err(c.unsupported(
                    "a blackbody is spectral only: Mitsuba's RGB variants cannot evaluate it either (\"not implemented for non-spectral modes\"); give its colour as <rgb>",
                ));
            }
            if c.attr("type").is_some() || c.attr("filename").is_some() {
                return Err(c.unsupported(
                    "a spectrum plugin or file: lumen reads a constant spectrum or wavelength:value pairs here",
                ));
            }
            let v = c.attr("value").ok_or_else(|| c.error("needs `value`"))?;
            // How Mitsuba turns it into RGB depends on what it is for.
            let usage = match c.attr("name").unwrap_or("") {
                "radiance" | "intensity" | "irradiance" => spectrum::Use::Emission,
                "eta" | "k" => spectrum::Use::Unbounded,
                _ => spectrum::Use::Reflectance,
            };
            if !v.contains(':') {
                return match numbers(c, v)?.as_slice() {
                    [a] => Ok(Color::Rgb(spectrum::uniform(*a, usage))),
                    _ => {
                        Err(c
                            .error(format!("`value` \"{v}\": expected one number or wavelength:value pairs")))
                    }
                };
            }
            let mut w = Vec::new();
            let mut vals = Vec::new();
            for pair in v.split(',').map(str::trim).filter(|p| !p.is_empty()) {
                let Some((a, b)) = pair.split_once(':') else {
                    return Err(c.error(format!("\"{pair}\": expected wavelength:value")));
                };
                w.push(number(c, a)?);
                vals.push(number(c, b)?);
            }
            if w.len() < 2 || w.windows(2).any(|p| p[1] <= p[0]) {
                return Err(c.error("needs at least two wavelength:value pairs, wavelengths increasing"));
            }
            Ok(Color::Rgb(spectrum::to_rgb(&w, &vals, usage)))
        }
        "texture" => texture(c).map(Color::Texture),
        t => Err(c.error(format!("<{t}> is not a colour: expected <rgb>, <spectrum>, <float> or <texture>"))),
    }
}

fn texture(e: &Elem) -> Result<TextureSpec, Error> {
    let p = Props::new(e);
    let tex = match e.plugin() {
        "checkerboard" => {
            let even = p.color("color0")?.map(|c| c.rgb(e, "color0")).transpose()?.unwrap_or([0.4; 3]);
            let odd = p.color("color1")?.map(|c| c.rgb(e, "color1")).transpose()?.unwrap_or([0.2; 3]);
            // Mitsuba's checkerboard is 2 × 2 squares over [0, 1]², colour0 where u and v fall
            // in the same half; `to_uv` may scale it by whole numbers.
            let mut squares = [2u32, 2];
            if let Some(m) = p.transform("to_uv")? {
                let (sx, sy) = (m.matrix3.x_axis.x, m.matrix3.y_axis.y);
                let whole = |s: f64| s > 0.0 && (s - s.round()).abs() < 1e-9 && s <= 1e4;
                if m.matrix3.x_axis.y != 0.0
                    || m.matrix3.y_axis.x != 0.0
                    || m.translation != glam::DVec3::ZERO
                    || !whole(sx)
                    || !whole(sy)
                {
                    return Err(e.unsupported("a `to_uv` other than a scale by whole numbers: lumen's checkerboard has whole squares over [0, 1]²"));
                }
                squares = [2 * sx.round() as u32, 2 * sy.round() as u32];
            }
            TextureSpec::Checker { checker: CheckerSpec { squares, even, odd } }
        }
        "bitmap" => {
            let f = p.string("filename")?.ok_or_else(|| e.error("needs `filename`"))?;
            if p.boolean("raw")? == Some(true) {
                return Err(e.unsupported(
                    "`raw` = true: lumen decodes 8-bit colour images as sRGB, as Mitsuba does by default",
                ));
            }
            match p.string("filter_type")?.as_deref() {
                None | Some("bilinear") => {}
                Some(o) => {
                    return Err(
                        e.unsupported(format!("filter_type \"{o}\": lumen filters bitmaps bilinearly"))
                    )
                }
            }
            match p.string("wrap_mode")?.as_deref() {
                None | Some("repeat") => {}
                Some(o) => return Err(e.unsupported(format!("wrap_mode \"{o}\": lumen repeats bitmaps"))),
            }
            TextureSpec::Image { texture: f }
        }
        other => {
            return Err(e.unsupported(format!("texture \"{other}\": lumen reads bitmap and checkerboard")))
        }
    };
    p.finish("color0, color1, to_uv (checkerboard); filename, filter_type, wrap_mode, raw (bitmap)")?;
    Ok(tex)
}

/// Degrees about a unit axis, right-handed, as Mitsuba's `Transform4f::rotate`.
fn rotation(axis: DVec3, degrees: f64) -> DMat3 {
    DMat3::from_axis_angle(axis.normalize(), degrees.to_radians())
}

/// A `<transform>`: its children applied in order, each to the result of the ones before.
fn transform(t: &Elem) -> Result<DAffine3, Error> {
    let mut m = DAffine3::IDENTITY;
    for c in &t.children {
        let step = match c.tag.as_str() {
            "translate" => DAffine3::from_translation(triple(c, 0.0)?),
            "scale" => {
                let s = triple(c, 1.0)?;
                if s.x * s.y * s.z == 0.0 {
                    return Err(c.error("a zero scale flattens the shape"));
                }
                DAffine3::from_scale(s)
            }
            "rotate" => {
                let angle = c.attr("angle").ok_or_else(|| c.error("needs `angle` (degrees)"))?;
                let axis = triple(c, 0.0)?;
                if axis.length() == 0.0 {
                    return Err(c.error("needs a non-zero axis (`value` or `x`, `y`, `z`)"));
                }
                DAffine3::from_mat3(rotation(axis, number(c, angle)?))
            }
            "matrix" => {
                let v = c.attr("value").ok_or_else(|| c.error("needs `value`"))?;
                let n = numbers(c, v)?;
                let rows: [[f64; 4]; 4] = match n.len() {
                    16 => [0, 1, 2, 3].map(|r| [0, 1, 2, 3].map(|k| n[4 * r + k])),
                    9 => [
                        [n[0], n[1], n[2], 0.0],
                        [n[3], n[4], n[5], 0.0],
                        [n[6], n[7], n[8], 0.0],
                        [0.0, 0.0, 0.0, 1.0],
                    ],
                    k => return Err(c.error(format!("{k} numbers: expected 16 (or 9), row by row"))),
                };
                if rows[3] != [0.0, 0.0, 0.0, 1.0] {
                    return Err(c.unsupported(
                        "a projective matrix: lumen takes affine transforms (last row 0 0 0 1)",
                    ));
                }
                DAffine3::from_mat4(glam::DMat4::from_cols_array_2d(&rows).transpose())
            }
            "lookat" | "look_at" => {
                let get = |k: &str| -> Result<DVec3, Error> {
                    let v = c.attr(k).ok_or_else(|| c.error(format!("needs `{k}`")))?;
                    match numbers(c, v)?.as_slice() {
                        [a, b, d] => Ok(DVec3::new(*a, *b, *d)),
                        _ => Err(c.error(format!("`{k}` \"{v}\": expected three numbers"))),
                    }
                };
                let origin = get("origin")?;
                let up = if c.attr("up").is_some() { get("up")? } else { DVec3::Y };
                let dir = (get("target")? - origin).normalize();
                let left = up.cross(dir).normalize();
                if !(dir.is_finite() && left.is_finite()) {
                    return Err(c.error("origin equals target, or up is parallel to the view direction"));
                }
                let new_up = dir.cross(left);
                DAffine3::from_mat3_translation(DMat3::from_cols(left, new_up, dir), origin)
            }
            t => {
                return Err(c.unsupported(format!(
                    "<{t}> in a transform: lumen reads translate, rotate, scale, matrix and lookat"
                )))
            }
        };
        m = step * m;
    }
    Ok(m)
}

/// Rows of an affine transform, for `TransformSpec::matrix`.
pub(super) fn rows(m: &DAffine3) -> [[f64; 4]; 4] {
    let c = glam::DMat4::from(*m).transpose().to_cols_array_2d();
    [c[0], c[1], c[2], c[3]]
}
