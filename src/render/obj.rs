//! A small Wavefront OBJ reader: `v`, `vt`, `f` (polygons fan-triangulated, `v`, `v/vt`,
//! `v//vn`, `v/vt/vn`, negative indices), `o`/`g` object names and `usemtl`. Normals (`vn`)
//! are read past: shading uses geometric normals. Everything else is ignored.
//!
//! Hand-written rather than a crate so that every error names the file and line, and an out
//! of range index is an error rather than a panic.

use glam::{DVec2, DVec3};
use std::path::Path;

#[derive(Debug, thiserror::Error)]
#[error("{path}:{line}: {message}")]
pub struct ObjError {
    pub path: String,
    /// 1-based; 0 when the file could not be read at all.
    pub line: usize,
    pub message: String,
}

impl ObjError {
    pub fn fault(&self) -> crate::Fault {
        if self.line == 0 {
            crate::Fault::Io
        } else {
            crate::Fault::BadInput
        }
    }
}

#[derive(Clone, Debug, Default)]
pub struct ObjMesh {
    pub positions: Vec<DVec3>,
    /// Per-vertex normals, one per position when the file gives them (PLY's `nx ny nz`), else
    /// empty.
    pub normals: Vec<DVec3>,
    pub uvs: Vec<DVec2>,
    /// Triangles: position indices and (optional) uv indices.
    pub triangles: Vec<ObjTriangle>,
    /// Object names; `ObjTriangle::object` indexes this (`"default"` when the file names none).
    pub objects: Vec<String>,
    /// `usemtl` names; `ObjTriangle::material` indexes this.
    pub materials: Vec<String>,
}

#[derive(Clone, Copy, Debug)]
pub struct ObjTriangle {
    pub v: [u32; 3],
    pub vt: Option<[u32; 3]>,
    pub object: u32,
    pub material: Option<u32>,
}

pub fn read(path: &Path) -> Result<ObjMesh, ObjError> {
    let text = std::fs::read_to_string(path).map_err(|e| ObjError {
        path: path.display().to_string(),
        line: 0,
        message: format!("cannot read: {e}"),
    })?;
    parse(&text, &path.display().to_string())
}

pub fn parse(text: &str, name: &str) -> Result<ObjMesh, ObjError> {
    let mut m = ObjMesh::default();
    let mut object: Option<u32> = None;
    let mut material: Option<u32> = None;
    for (ln, raw) in text.lines().enumerate() {
        let line_no = ln + 1;
        let err = |message: String| ObjError { path: name.to_string(), line: line_no, message };
        let line = raw.split('#').next().unwrap_or("").trim();
        let mut words = line.split_whitespace();
        let Some(tag) = words.next() else { continue };
        let rest: Vec<&str> = words.collect();
        let numbers = |n: usize| -> Result<Vec<f64>, ObjError> {
            if rest.len() < n {
                return Err(err(format!("'{tag}' needs {n} numbers, found {}", rest.len())));
            }
            rest[..n]
                .iter()
                .map(|w| match w.parse::<f64>() {
                    Ok(v) if v.is_finite() => Ok(v),
                    _ => Err(err(format!("'{w}' is not a finite number"))),
                })
                .collect()
        };
        match tag {
            "v" => {
                let c = numbers(3)?;
                m.positions.push(DVec3::new(c[0], c[1], c[2]));
            }
            "vt" => {
                let c = numbers(2)?;
                m.uvs.push(DVec2::new(c[0], c[1]));
            }
            "o" | "g" => {
                let nm = rest.join(" ");
                m.objects.push(if nm.is_empty() { format!("object{}", m.objects.len()) } else { nm });
                object = Some(m.objects.len() as u32 - 1);
            }
            "usemtl" => {
                let nm = rest.join(" ");
                let idx = match m.materials.iter().position(|x| *x == nm) {
                    Some(i) => i,
                    None => {
                        m.materials.push(nm);
                        m.materials.len() - 1
                    }
                };
                material = Some(idx as u32);
            }
            "f" => {
                if rest.len() < 3 {
                    return Err(err(format!("a face needs at least 3 vertices, found {}", rest.len())));
                }
                let mut vs = Vec::with_capacity(rest.len());
                let mut vts = Vec::with_capacity(rest.len());
                for w in &rest {
                    let mut parts = w.split('/');
                    let v = resolve(parts.next().unwrap_or(""), m.positions.len(), "vertex", &err)?;
                    vs.push(v);
                    match parts.next() {
                        Some(t) if !t.is_empty() => {
                            vts.push(resolve(t, m.uvs.len(), "texture coordinate", &err)?)
                        }
                        _ => {}
                    }
                }
                let has_uv = vts.len() == vs.len();
                let obj = match object {
                    Some(o) => o,
                    None => {
                        m.objects.push("default".into());
                        object = Some(m.objects.len() as u32 - 1);
                        m.objects.len() as u32 - 1
                    }
                };
                for k in 1..vs.len() - 1 {
                    m.triangles.push(ObjTriangle {
                        v: [vs[0], vs[k], vs[k + 1]],
                        vt: has_uv.then(|| [vts[0], vts[k], vts[k + 1]]),
                        object: obj,
                        material,
                    });
                }
            }
            _ => {} // vn, s, mtllib, l, p, …: not needed by the renderer
        }
    }
    Ok(m)
}

/// Resolves a 1-based (or negative, relative) OBJ index against `count` items so far.
fn resolve(word: &str, count: usize, what: &str, err: &dyn Fn(String) -> ObjError) -> Result<u32, ObjError> {
    let i: i64 = word.parse().map_err(|_| err(format!("'{word}' is not a {what} index")))?;
    let idx = if i > 0 { i - 1 } else { count as i64 + i };
    if i == 0 || idx < 0 || idx >= count as i64 {
        return Err(err(format!("{what} index {i} is out of range (1..={count} defined so far)")));
    }
    Ok(idx as u32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quads_fan_and_negative_indices() {
        let m = parse("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\no quad\nf -4 -3 -2 -1\n", "t.obj").unwrap();
        assert_eq!(m.triangles.len(), 2);
        assert_eq!(m.triangles[1].v, [0, 2, 3]);
        assert_eq!(m.objects, vec!["quad".to_string()]);
    }

    #[test]
    fn bad_index_names_line() {
        let e = parse("v 0 0 0\nv 1 0 0\nf 1 2 3\n", "bad.obj").unwrap_err();
        assert_eq!(e.line, 3);
        assert!(e.to_string().contains("bad.obj:3"), "{e}");
    }
}
