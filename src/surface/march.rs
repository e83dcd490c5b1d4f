//! Meshing the implicit function's zero set by marching tetrahedra (Doi & Koide 1991): f is
//! sampled at the corners of a uniform grid, only near the points; each cube is split into six
//! tetrahedra, and each tetrahedron whose corners change sign gives one triangle or a quad, its
//! vertices where f crosses zero along the edges (linearly). Unlike marching cubes' and surface
//! nets' cells, a tetrahedron has no ambiguous case, so where the sampled surface is closed the
//! mesh is closed and manifold, with no case table. Each vertex is then moved onto the surface
//! by two Newton steps along the local fit's gradient. (Surface nets were tried first: on a noisy torus they left an
//! edge shared by four triangles.)

use super::{implicit, Cloud, Error, Method};
use glam::DVec3;
use rayon::prelude::*;

/// Most grid corners a mesh may sample (2²⁷, about 512³: 512 MB of f32).
pub const MAX_CORNERS: u64 = 1 << 27;

pub struct Mesh {
    pub vertices: Vec<DVec3>,
    pub triangles: Vec<[u32; 3]>,
}

struct Grid {
    lo: DVec3,
    cell: f64,
    dims: [usize; 3],
}

impl Grid {
    fn index(&self, i: usize, j: usize, k: usize) -> usize {
        (k * self.dims[1] + j) * self.dims[0] + i
    }
    fn corner(&self, i: usize, j: usize, k: usize) -> DVec3 {
        self.lo + self.cell * DVec3::new(i as f64, j as f64, k as f64)
    }
}

pub fn mesh(cloud: &mut Cloud, method: Method, resolution: usize) -> Result<Mesh, Error> {
    let (mut lo, mut hi) = (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN));
    for p in &cloud.points {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let extent = (hi - lo).max_element();
    let cell = extent / resolution as f64;
    if !(cell.is_finite() && cell > 0.0) {
        return Err(Error::BadInput(format!(
            "the points span {extent} across: expected a positive, finite extent"
        )));
    }
    // Room for the surface beyond the outermost points.
    let margin = 2.0 * cell + cloud.radius.iter().copied().fold(0.0, f64::max).min(0.25 * extent);
    lo -= DVec3::splat(margin);
    hi += DVec3::splat(margin);
    let dims = ((hi - lo) / cell).ceil().as_uvec3().to_array().map(|d| d as usize + 1);
    let total = dims.iter().map(|&d| d as u64).product::<u64>();
    if total > MAX_CORNERS {
        return Err(Error::BadInput(format!(
            "resolution {resolution}: a {}×{}×{} grid, above the limit of {MAX_CORNERS} corners (lower --resolution)",
            dims[0], dims[1], dims[2]
        )));
    }
    let grid = Grid { lo, cell, dims };
    // A corner one cell diagonal from the surface must still find its points within 0.7 of
    // the radius (`implicit::value`).
    cloud.floor = 2.0 * 3f64.sqrt() * cell;
    let cloud = &*cloud;
    // Corners near the points: within the smaller of each point's radius and two cells or
    // its spacing, where the surface can pass.
    let mut active = vec![false; total as usize];
    for (p, r) in cloud.points.iter().zip(&cloud.radius) {
        let r = r.max(cloud.floor);
        let reach = r.min((2.0 * cell).max(0.6 * r));
        let a = ((*p - DVec3::splat(reach) - lo) / cell).floor().max(DVec3::ZERO);
        let b = ((*p + DVec3::splat(reach) - lo) / cell).ceil();
        for k in a.z as usize..=(b.z as usize).min(dims[2] - 1) {
            for j in a.y as usize..=(b.y as usize).min(dims[1] - 1) {
                for i in a.x as usize..=(b.x as usize).min(dims[0] - 1) {
                    active[grid.index(i, j, k)] = true;
                }
            }
        }
    }
    let list: Vec<usize> = (0..total as usize).filter(|&i| active[i]).collect();
    drop(active);
    let values: Vec<(usize, f32)> = list
        .par_iter()
        .filter_map(|&g| {
            let (i, j, k) = (g % dims[0], (g / dims[0]) % dims[1], g / (dims[0] * dims[1]));
            implicit::value(cloud, method, grid.corner(i, j, k)).map(|v| (g, v as f32))
        })
        .collect();
    let mut f = vec![f32::NAN; total as usize];
    for (g, v) in values {
        f[g] = v;
    }
    // Every cube split into six tetrahedra along its main diagonal (Freudenthal's split: each
    // follows the axes in one order from corner 0 to corner 7, so neighbouring cubes split
    // their shared faces alike); each tetrahedron whose corners are all known and change sign
    // gives a triangle or two, their vertices on its edges, shared through a map keyed by the
    // edge's two grid corners.
    const ORDERS: [[usize; 3]; 6] = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];
    let mut vertices: Vec<DVec3> = Vec::new();
    let mut on_edge: std::collections::HashMap<(usize, usize), u32> = std::collections::HashMap::new();
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    for k in 0..dims[2] - 1 {
        for j in 0..dims[1] - 1 {
            for i in 0..dims[0] - 1 {
                let base = [i, j, k];
                let corner_id = |c: [usize; 3]| grid.index(c[0], c[1], c[2]);
                // Skip cubes with no sign change or an unknown corner.
                let ids: [usize; 8] =
                    std::array::from_fn(|b| corner_id([i + (b & 1), j + ((b >> 1) & 1), k + ((b >> 2) & 1)]));
                let vals = ids.map(|g| f[g]);
                if vals.iter().any(|v| v.is_nan())
                    || vals.iter().all(|&v| v < 0.0)
                    || vals.iter().all(|&v| v >= 0.0)
                {
                    continue;
                }
                for order in ORDERS {
                    let mut c = base;
                    let mut tet = [corner_id(c); 4];
                    for (t, &axis) in order.iter().enumerate() {
                        c[axis] += 1;
                        tet[t + 1] = corner_id(c);
                    }
                    polygonise(&grid, &f, tet, &mut vertices, &mut on_edge, &mut triangles);
                }
            }
        }
    }
    // Onto the surface: two Newton steps along the fit's own gradient.
    vertices.par_iter_mut().for_each(|v| {
        for _ in 0..2 {
            let Some((f0, grad)) = implicit::fit(cloud, method, *v) else { return };
            let g2 = grad.length_squared();
            if !(g2 > 1e-12) {
                return;
            }
            let step = f0 / g2 * grad;
            // Never further than a cell: a step that long is off the local fit.
            if step.length() > cell {
                return;
            }
            *v -= step;
        }
    });
    Ok(Mesh { vertices, triangles })
}

/// The grid corner of a flat index.
fn position(grid: &Grid, g: usize) -> DVec3 {
    let (i, j, k) = (g % grid.dims[0], (g / grid.dims[0]) % grid.dims[1], g / (grid.dims[0] * grid.dims[1]));
    grid.corner(i, j, k)
}

/// The triangles of one tetrahedron (corners as flat grid indices): one where a corner is
/// alone on its side of the surface, two (a quad) where the corners split two and two; each
/// turned to face the side where f ≥ 0.
fn polygonise(
    grid: &Grid,
    f: &[f32],
    tet: [usize; 4],
    vertices: &mut Vec<DVec3>,
    on_edge: &mut std::collections::HashMap<(usize, usize), u32>,
    triangles: &mut Vec<[u32; 3]>,
) {
    let inside: Vec<usize> = tet.iter().copied().filter(|&g| f[g] < 0.0).collect();
    let outside: Vec<usize> = tet.iter().copied().filter(|&g| f[g] >= 0.0).collect();
    if inside.is_empty() || outside.is_empty() {
        return;
    }
    let mut vertex = |a: usize, b: usize| {
        let key = (a.min(b), a.max(b));
        *on_edge.entry(key).or_insert_with(|| {
            let (fa, fb) = (f[a] as f64, f[b] as f64);
            let t = fa / (fa - fb);
            let (pa, pb) = (position(grid, a), position(grid, b));
            vertices.push(pa + t * (pb - pa));
            (vertices.len() - 1) as u32
        })
    };
    let polygon: Vec<u32> = match (inside.len(), outside.len()) {
        (1, 3) => outside.iter().map(|&o| vertex(inside[0], o)).collect(),
        (3, 1) => inside.iter().map(|&i| vertex(i, outside[0])).collect(),
        _ => {
            let (a, b, c, d) = (inside[0], inside[1], outside[0], outside[1]);
            vec![vertex(a, c), vertex(a, d), vertex(b, d), vertex(b, c)]
        }
    };
    // Face the outside: the polygon's normal along (outside's centroid − inside's).
    let centroid = |s: &[usize]| s.iter().map(|&g| position(grid, g)).sum::<DVec3>() / s.len() as f64;
    let out_dir = centroid(&outside) - centroid(&inside);
    let p: Vec<DVec3> = polygon.iter().map(|&v| vertices[v as usize]).collect();
    let normal = (p[1] - p[0]).cross(p[2] - p[0])
        + if p.len() == 4 { (p[2] - p[0]).cross(p[3] - p[0]) } else { DVec3::ZERO };
    let mut poly = polygon;
    if normal.dot(out_dir) < 0.0 {
        poly.reverse();
    }
    triangles.push([poly[0], poly[1], poly[2]]);
    if poly.len() == 4 {
        triangles.push([poly[0], poly[2], poly[3]]);
    }
}
