//! A UV atlas for a triangle mesh: charts by normal clustering, each flattened by projection
//! and packed into one square texture.
//!
//! - **Charts.** Each triangle takes the one of the six axis directions (±x, ±y, ±z) nearest
//!   its normal (Sander et al. 2001's normal clustering with the six axes as fixed centres, as
//!   "cube mapping" atlases do); a triangle whose label its neighbours do not share takes
//!   their majority label where that axis is within 70° of its normal, so noise does not
//!   scatter one-triangle charts. A chart is a connected set of triangles (by shared edges)
//!   with one label.
//! - **Flattening.** A chart is projected orthographically along its axis: every normal in it
//!   is within 70° of the axis (55° before the relabelling), so texels stretch by at most
//!   1/cos 70° ≈ 2.9 (≤ 1.7 for most). Projection is affine, so barycentrics in the texture
//!   are those on the surface.
//! - **Packing.** Charts' bounding boxes, with a gutter of `PAD` texels around each, are packed
//!   in shelves (tallest first) into `size`²; the scale (texels per scene unit) is the largest
//!   that fits, found by bisection.
//!
//! A chart folded over itself along its axis (an S-shaped strip facing one way) would share
//! texels between its layers; the six axes keep that to surfaces with overhangs finer than a
//! chart.

use super::Error;
use crate::surface::march::Mesh;
use glam::{DVec2, DVec3};
use std::collections::HashMap;

/// Texels of gutter around each chart: bilinear lookups near a chart's edge read the gutter,
/// which is filled from the chart.
pub const PAD: u32 = 2;

pub struct Atlas {
    /// The texture is `size` × `size` texels; texel (i, j) covers [i, i+1) × [j, j+1).
    pub size: u32,
    /// Per triangle, its vertices' texture coordinates in texels.
    pub uv: Vec<[DVec2; 3]>,
    /// Per triangle, its chart.
    pub chart: Vec<u32>,
    pub charts: usize,
    /// Texels per scene unit.
    pub scale: f64,
}

/// A texel a triangle covers (its centre inside): the texel's index (row-major), the
/// triangle, and the barycentrics (b1, b2) of the centre.
#[derive(Clone, Copy, Debug)]
pub struct Texel {
    pub index: u32,
    pub triangle: u32,
    pub bary: [f64; 2],
}

const AXES: [DVec3; 6] = [DVec3::X, DVec3::NEG_X, DVec3::Y, DVec3::NEG_Y, DVec3::Z, DVec3::NEG_Z];

/// The unit normal of each triangle (zero for a degenerate one).
pub fn face_normals(mesh: &Mesh) -> Vec<DVec3> {
    mesh.triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
            (b - a).cross(c - a).normalize_or_zero()
        })
        .collect()
}

/// Every edge (its vertices, lower first) with the triangles around it: each triangle and the
/// edge's place k in it (from vertex k to vertex k + 1).
pub fn edges(mesh: &Mesh) -> HashMap<(u32, u32), Vec<(u32, usize)>> {
    let mut by_edge: HashMap<(u32, u32), Vec<(u32, usize)>> = HashMap::new();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            by_edge.entry((a.min(b), a.max(b))).or_default().push((t as u32, k));
        }
    }
    by_edge
}

/// The triangles sharing each edge with each triangle.
fn neighbours(mesh: &Mesh) -> Vec<Vec<u32>> {
    let mut out = vec![Vec::new(); mesh.triangles.len()];
    for tris in edges(mesh).values() {
        for &(a, _) in tris {
            for &(b, _) in tris {
                if a != b {
                    out[a as usize].push(b);
                }
            }
        }
    }
    out
}

/// Each triangle's axis label (module docs).
fn labels(normals: &[DVec3], near: &[Vec<u32>]) -> Vec<u8> {
    let best =
        |n: DVec3| (0..6).max_by(|&a, &b| n.dot(AXES[a]).total_cmp(&n.dot(AXES[b]))).unwrap_or(0) as u8;
    let mut label: Vec<u8> = normals.iter().map(|&n| best(n)).collect();
    let cos_max = 70f64.to_radians().cos();
    for _ in 0..2 {
        let before = label.clone();
        for (t, ns) in near.iter().enumerate() {
            let mut count = [0usize; 6];
            ns.iter().for_each(|&n| count[before[n as usize] as usize] += 1);
            let own = count[before[t] as usize];
            let (top, top_count) = (0..6).map(|a| (a, count[a])).max_by_key(|&(_, c)| c).unwrap_or((0, 0));
            if own == 0 && top_count >= 2 && normals[t].dot(AXES[top]) > cos_max {
                label[t] = top as u8;
            }
        }
    }
    label
}

/// Connected triangles of one label, numbered from 0.
fn charts(label: &[u8], near: &[Vec<u32>]) -> (Vec<u32>, usize) {
    let mut chart = vec![u32::MAX; label.len()];
    let mut count = 0u32;
    let mut stack = Vec::new();
    for seed in 0..label.len() {
        if chart[seed] != u32::MAX {
            continue;
        }
        chart[seed] = count;
        stack.push(seed);
        while let Some(t) = stack.pop() {
            for &n in &near[t] {
                let n = n as usize;
                if chart[n] == u32::MAX && label[n] == label[t] {
                    chart[n] = count;
                    stack.push(n);
                }
            }
        }
        count += 1;
    }
    (chart, count as usize)
}

/// The two in-plane axes of a label's projection.
fn plane(label: u8) -> (DVec3, DVec3) {
    let n = AXES[label as usize];
    let u = if n.x.abs() > 0.5 { DVec3::Y } else { DVec3::X };
    let v = n.cross(u);
    (u, v)
}

/// Shelf packing of boxes (width, height in texels) into `size`²: each box's corner, or
/// `None` when they do not fit.
fn pack(boxes: &[(u32, u32)], size: u32) -> Option<Vec<(u32, u32)>> {
    let mut order: Vec<usize> = (0..boxes.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(boxes[i].1));
    let mut at = vec![(0, 0); boxes.len()];
    let (mut x, mut y, mut shelf) = (0u32, 0u32, 0u32);
    for i in order {
        let (w, h) = boxes[i];
        if w > size {
            return None;
        }
        if x + w > size {
            y += shelf;
            x = 0;
            shelf = 0;
        }
        if y + h > size {
            return None;
        }
        at[i] = (x, y);
        x += w;
        shelf = shelf.max(h);
    }
    Some(at)
}

/// Builds the atlas of `mesh` in a `size`² texture.
pub fn build(mesh: &Mesh, size: u32) -> Result<Atlas, Error> {
    if !(64..=16384).contains(&size) {
        return Err(Error::BadInput(format!("texture size {size}: expected 64 to 16384 texels")));
    }
    let normals = face_normals(mesh);
    let near = neighbours(mesh);
    let label = labels(&normals, &near);
    let (chart, count) = charts(&label, &near);
    // Each chart's extent in its plane.
    let mut lo = vec![DVec2::splat(f64::INFINITY); count];
    let mut hi = vec![DVec2::splat(f64::NEG_INFINITY); count];
    let mut flat = Vec::with_capacity(mesh.triangles.len());
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let (u, v) = plane(label[t]);
        let c = chart[t] as usize;
        let p = tri.map(|i| {
            let x = mesh.vertices[i as usize];
            DVec2::new(x.dot(u), x.dot(v))
        });
        for q in p {
            lo[c] = lo[c].min(q);
            hi[c] = hi[c].max(q);
        }
        flat.push(p);
    }
    let extent: Vec<DVec2> = (0..count).map(|c| hi[c] - lo[c]).collect();
    let boxes_at = |scale: f64| -> Vec<(u32, u32)> {
        extent
            .iter()
            .map(|e| ((e.x * scale).ceil() as u32 + 1 + 2 * PAD, (e.y * scale).ceil() as u32 + 1 + 2 * PAD))
            .collect()
    };
    let area: f64 = extent.iter().map(|e| e.x * e.y).sum::<f64>().max(1e-300);
    let (mut low, mut high) = (0.0, size as f64 / area.sqrt());
    if !high.is_finite() {
        return Err(Error::BadInput(
            "the mesh has no area: expected triangles of finite, non-zero size".into(),
        ));
    }
    if pack(&boxes_at(0.0), size).is_none() {
        return Err(Error::BadInput(format!(
            "{count} charts do not fit in a {size}² texture even as points: expected a larger --size"
        )));
    }
    for _ in 0..40 {
        let mid = 0.5 * (low + high);
        if pack(&boxes_at(mid), size).is_some() {
            low = mid;
        } else {
            high = mid;
        }
    }
    let scale = low;
    let at = pack(&boxes_at(scale), size).expect("the scale found fits");
    let uv = flat
        .iter()
        .enumerate()
        .map(|(t, p)| {
            let c = chart[t] as usize;
            let corner = DVec2::new(at[c].0 as f64, at[c].1 as f64) + DVec2::splat(PAD as f64 + 0.5);
            p.map(|q| corner + (q - lo[c]) * scale)
        })
        .collect();
    Ok(Atlas { size, uv, chart, charts: count, scale })
}

/// Every texel whose centre lies in a triangle, in texel order.
pub fn texels(atlas: &Atlas) -> Vec<Texel> {
    let mut out = Vec::new();
    let size = atlas.size as i64;
    for (t, [a, b, c]) in atlas.uv.iter().enumerate() {
        let area = (*b - *a).perp_dot(*c - *a);
        if !(area.abs() > 1e-12) {
            continue;
        }
        let x0 = (a.x.min(b.x).min(c.x) - 0.5).ceil().max(0.0) as i64;
        let x1 = ((a.x.max(b.x).max(c.x) - 0.5).floor() as i64).min(size - 1);
        let y0 = (a.y.min(b.y).min(c.y) - 0.5).ceil().max(0.0) as i64;
        let y1 = ((a.y.max(b.y).max(c.y) - 0.5).floor() as i64).min(size - 1);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let p = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                let b1 = (p - *a).perp_dot(*c - *a) / area;
                let b2 = (*b - *a).perp_dot(p - *a) / area;
                if b1 < 0.0 || b2 < 0.0 || b1 + b2 > 1.0 {
                    continue;
                }
                out.push(Texel { index: (y * size + x) as u32, triangle: t as u32, bary: [b1, b2] });
            }
        }
    }
    // A texel on an edge two triangles share is kept once.
    out.sort_by_key(|t| t.index);
    out.dedup_by_key(|t| t.index);
    out
}
