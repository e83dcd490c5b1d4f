//! A PLY reader (Turk 1994; the format Mitsuba, Meshlab and scanners write): ASCII, binary
//! little- and big-endian; every scalar type; vertices `x y z` with optional normals
//! `nx ny nz` and texture coordinates (`u v`, `s t` or `texture_u texture_v`); faces as a list
//! `vertex_indices` (or `vertex_index`), polygons fan-triangulated; other elements and
//! properties read past. The result is the OBJ reader's mesh, so both feed one mesh builder.
//!
//! Hand-written rather than a crate for the reason `obj` gives: every error names the file and
//! what is wrong, counts are checked against the file's size before anything is allocated, and
//! an out-of-range index is an error, not a panic.

use super::obj::{ObjMesh, ObjTriangle};
use glam::{DVec2, DVec3};
use std::path::Path;

#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct PlyError {
    pub path: String,
    pub message: String,
    /// The file could not be read at all (rather than read and found malformed).
    pub unreadable: bool,
}

impl PlyError {
    pub fn fault(&self) -> crate::Fault {
        if self.unreadable {
            crate::Fault::Io
        } else {
            crate::Fault::BadInput
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Format {
    Ascii,
    Little,
    Big,
}

#[derive(Clone, Copy, Debug)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Debug)]
struct Property {
    name: String,
    /// `Some(count type)` for a list.
    list: Option<Scalar>,
    kind: Scalar,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

/// Most vertices or faces a file may declare (2³¹): more than any mesh lumen can trace.
const MAX_COUNT: usize = 1 << 31;

struct Header {
    format: Format,
    elements: Vec<Element>,
    /// Byte offset of the data after `end_header`.
    data: usize,
}

fn header(bytes: &[u8], err: &dyn Fn(String) -> PlyError) -> Result<Header, PlyError> {
    let end = bytes
        .windows(10)
        .position(|w| w == b"end_header")
        .ok_or_else(|| err("no `end_header`: not a PLY file, or a truncated one".into()))?;
    let mut data = end + 10;
    // The header ends with one line break (\n or \r\n).
    if bytes.get(data) == Some(&b'\r') {
        data += 1;
    }
    if bytes.get(data) == Some(&b'\n') {
        data += 1;
    }
    let text = std::str::from_utf8(&bytes[..end]).map_err(|_| err("the header is not text".into()))?;
    let mut lines = text.lines().map(str::trim);
    if lines.next() != Some("ply") {
        return Err(err("does not start with `ply`: not a PLY file".into()));
    }
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    for line in lines {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            [] | ["comment", ..] | ["obj_info", ..] => {}
            ["format", f, _version] => {
                format = Some(match *f {
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::Little,
                    "binary_big_endian" => Format::Big,
                    o => {
                        return Err(err(format!(
                            "format `{o}`: expected ascii, binary_little_endian or binary_big_endian"
                        )))
                    }
                })
            }
            ["element", name, count] => {
                let count: usize = count.parse().ok().filter(|&c| c <= MAX_COUNT).ok_or_else(|| {
                    err(format!("element {name} count `{count}`: expected 0 to {MAX_COUNT}"))
                })?;
                elements.push(Element { name: name.to_string(), count, properties: Vec::new() });
            }
            ["property", "list", count, kind, name] => {
                let (Some(c), Some(k)) = (Scalar::parse(count), Scalar::parse(kind)) else {
                    return Err(err(format!("property list {count} {kind} {name}: unknown type")));
                };
                let e =
                    elements.last_mut().ok_or_else(|| err(format!("property {name} before any element")))?;
                e.properties.push(Property { name: name.to_string(), list: Some(c), kind: k });
            }
            ["property", kind, name] => {
                let k = Scalar::parse(kind)
                    .ok_or_else(|| err(format!("property {name}: unknown type `{kind}`")))?;
                let e =
                    elements.last_mut().ok_or_else(|| err(format!("property {name} before any element")))?;
                e.properties.push(Property { name: name.to_string(), list: None, kind: k });
            }
            _ => return Err(err(format!("header line `{line}` is not PLY"))),
        }
    }
    let format = format.ok_or_else(|| err("the header has no `format` line".into()))?;
    Ok(Header { format, elements, data })
}

/// Whether a PLY file's vertices carry normals (from its header; false when unreadable, which
/// `read` then reports).
pub fn has_normals(path: &Path) -> bool {
    let Ok(bytes) = std::fs::read(path) else { return false };
    let err = |m: String| PlyError { path: String::new(), message: m, unreadable: false };
    header(&bytes, &err).is_ok_and(|h| {
        h.elements.iter().any(|e| e.name == "vertex" && e.properties.iter().any(|p| p.name == "nx"))
    })
}

/// Reads the values of a file's data section, in order.
struct Data<'a> {
    bytes: &'a [u8],
    at: usize,
    format: Format,
}

impl Data<'_> {
    fn next(&mut self, kind: Scalar) -> Option<f64> {
        if self.format == Format::Ascii {
            let rest = &self.bytes[self.at..];
            let start = rest.iter().position(|b| !b.is_ascii_whitespace())?;
            let len =
                rest[start..].iter().position(|b| b.is_ascii_whitespace()).unwrap_or(rest.len() - start);
            self.at += start + len;
            let v: f64 = std::str::from_utf8(&rest[start..start + len]).ok()?.parse().ok()?;
            return v.is_finite().then_some(v);
        }
        let n = kind.size();
        let b = self.bytes.get(self.at..self.at + n)?;
        self.at += n;
        let mut a = [0u8; 8];
        a[..n].copy_from_slice(b);
        if self.format == Format::Big {
            a[..n].reverse();
        }
        let v = match kind {
            Scalar::I8 => a[0] as i8 as f64,
            Scalar::U8 => a[0] as f64,
            Scalar::I16 => i16::from_le_bytes([a[0], a[1]]) as f64,
            Scalar::U16 => u16::from_le_bytes([a[0], a[1]]) as f64,
            Scalar::I32 => i32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Scalar::U32 => u32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Scalar::F32 => f32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Scalar::F64 => f64::from_le_bytes(a),
        };
        Some(v)
    }
}

pub fn read(path: &Path) -> Result<ObjMesh, PlyError> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| PlyError {
        path: name.clone(),
        message: format!("cannot read: {e}"),
        unreadable: true,
    })?;
    parse(&bytes, &name)
}

pub fn parse(bytes: &[u8], name: &str) -> Result<ObjMesh, PlyError> {
    let err = |m: String| PlyError { path: name.to_string(), message: m, unreadable: false };
    let h = header(bytes, &err)?;
    // Every element's smallest size (a list counts its length only) against what the file
    // holds, before anything is allocated: a header may claim 10⁹ vertices.
    let minimum: usize = h
        .elements
        .iter()
        .map(|e| {
            let per: usize = e
                .properties
                .iter()
                .map(|p| if h.format == Format::Ascii { 2 } else { p.list.unwrap_or(p.kind).size() })
                .sum();
            e.count.saturating_mul(per)
        })
        .fold(0usize, usize::saturating_add);
    let available = bytes.len() - h.data;
    if minimum > available + 1 {
        return Err(err(format!(
            "the header declares at least {minimum} bytes of data, and the file holds {available}: truncated, or a wrong count"
        )));
    }
    let mut data = Data { bytes, at: h.data, format: h.format };
    let mut mesh = ObjMesh { objects: vec![stem(name)], ..ObjMesh::default() };
    let mut uvs_present = false;
    for e in &h.elements {
        let index = |n: &str| e.properties.iter().position(|p| p.name == n && p.list.is_none());
        let (ix, iy, iz) = (index("x"), index("y"), index("z"));
        let normal_at = match (index("nx"), index("ny"), index("nz")) {
            (Some(a), Some(b), Some(c)) if e.name == "vertex" => Some([a, b, c]),
            _ => None,
        };
        let iu = index("u").or(index("s")).or(index("texture_u"));
        let iv = index("v").or(index("t")).or(index("texture_v"));
        let faces = e
            .properties
            .iter()
            .position(|p| p.list.is_some() && (p.name == "vertex_indices" || p.name == "vertex_index"));
        if e.name == "vertex" {
            if ix.is_none() || iy.is_none() || iz.is_none() {
                return Err(err("the vertex element needs properties x, y and z".into()));
            }
            mesh.positions.reserve(e.count);
            uvs_present = iu.is_some() && iv.is_some();
        }
        let mut values = vec![0.0; e.properties.len()];
        let mut polygon: Vec<u32> = Vec::new();
        for k in 0..e.count {
            polygon.clear();
            for (j, p) in e.properties.iter().enumerate() {
                let truncated =
                    || err(format!("{} {k} of {}: data ends early or holds a bad number", e.name, e.count));
                match p.list {
                    None => values[j] = data.next(p.kind).ok_or_else(truncated)?,
                    Some(count) => {
                        let n = data.next(count).ok_or_else(truncated)?;
                        if !(n >= 0.0 && n.fract() == 0.0 && n <= 1e6) {
                            return Err(err(format!("{} {k}: list length {n}", e.name)));
                        }
                        for _ in 0..n as usize {
                            let v = data.next(p.kind).ok_or_else(truncated)?;
                            if Some(j) == faces {
                                if !(v >= 0.0 && v.fract() == 0.0 && v <= u32::MAX as f64) {
                                    return Err(err(format!("face {k}: vertex index {v}")));
                                }
                                polygon.push(v as u32);
                            }
                        }
                    }
                }
            }
            if e.name == "vertex" {
                let (x, y, z) = (values[ix.unwrap()], values[iy.unwrap()], values[iz.unwrap()]);
                mesh.positions.push(DVec3::new(x, y, z));
                if let Some([a, b, c]) = normal_at {
                    mesh.normals.push(DVec3::new(values[a], values[b], values[c]));
                }
                if uvs_present {
                    mesh.uvs.push(DVec2::new(values[iu.unwrap()], values[iv.unwrap()]));
                }
            } else if e.name == "face" && faces.is_some() {
                if polygon.len() < 3 {
                    return Err(err(format!("face {k} has {} vertices: expected at least 3", polygon.len())));
                }
                for &v in &polygon {
                    if v as usize >= mesh.positions.len() {
                        return Err(err(format!(
                            "face {k} names vertex {v}, and there are {} (faces must follow the vertices)",
                            mesh.positions.len()
                        )));
                    }
                }
                for i in 1..polygon.len() - 1 {
                    let v = [polygon[0], polygon[i], polygon[i + 1]];
                    mesh.triangles.push(ObjTriangle {
                        v,
                        vt: uvs_present.then_some(v),
                        object: 0,
                        material: None,
                    });
                }
            }
        }
    }
    Ok(mesh)
}

fn stem(name: &str) -> String {
    Path::new(name).file_stem().map_or_else(|| "ply".into(), |s| s.to_string_lossy().into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    const QUAD_ASCII: &str = "ply\nformat ascii 1.0\ncomment a unit square\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty float u\nproperty float v\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n0 1 0 0 1\n4 0 1 2 3\n";

    /// The same square in the three formats gives the same mesh.
    #[test]
    fn ascii_and_binary_agree() {
        let a = parse(QUAD_ASCII.as_bytes(), "a.ply").unwrap();
        assert_eq!(a.positions.len(), 4);
        assert_eq!(a.triangles.len(), 2);
        assert_eq!(a.triangles[1].v, [0, 2, 3]);
        assert_eq!(a.uvs[2], DVec2::new(1.0, 1.0));
        for (format, big) in [("binary_little_endian", false), ("binary_big_endian", true)] {
            let mut b = format!("ply\nformat {format} 1.0\nelement vertex 4\nproperty double x\nproperty double y\nproperty double z\nproperty float u\nproperty float v\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n").into_bytes();
            for p in &a.positions {
                for c in [p.x, p.y, p.z] {
                    b.extend(if big { c.to_be_bytes() } else { c.to_le_bytes() });
                }
                let uv = [p.x as f32, p.y as f32];
                for c in uv {
                    b.extend(if big { c.to_be_bytes() } else { c.to_le_bytes() });
                }
            }
            b.push(4);
            for i in 0u32..4 {
                b.extend(if big { i.to_be_bytes() } else { i.to_le_bytes() });
            }
            let m = parse(&b, "b.ply").unwrap();
            assert_eq!(m.positions, a.positions, "{format}");
            assert_eq!(m.uvs, a.uvs, "{format}");
            assert_eq!(
                m.triangles.iter().map(|t| t.v).collect::<Vec<_>>(),
                a.triangles.iter().map(|t| t.v).collect::<Vec<_>>()
            );
        }
    }

    #[test]
    fn malformed_files_are_refused() {
        let cases = [
            ("not a ply", "no `end_header`"),
            ("ply\nformat ascii 1.0\nelement vertex 1000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n", "truncated, or a wrong count"),
            ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n3 0 1 2\n", "names vertex 1"),
            ("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 nan 0\n", "vertex 1 of 2"),
            ("ply\nformat binary_middle_endian 1.0\nend_header\n", "format `binary_middle_endian`"),
            ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n0\n", "needs properties x, y and z"),
            ("ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n0\n", "unknown type `quad`"),
        ];
        for (text, expected) in cases {
            let e = parse(text.as_bytes(), "bad.ply").expect_err(text);
            assert!(e.to_string().contains(expected), "expected \"{expected}\" in: {e}");
            assert_eq!(e.fault(), crate::Fault::BadInput);
        }
    }
}
