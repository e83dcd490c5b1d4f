//! Point-set surfaces: a closed mesh from a point cloud (`lumen surface`).
//!
//! The surface is the zero set of an implicit function fitted locally to the points
//! (`implicit`: moving least squares, Alexa et al. 2001/2003, or algebraic point-set surfaces,
//! Guennebaud & Gross 2007), meshed by marching tetrahedra on a grid sampled only near the points
//! (`march`). Normals, when the cloud has none, are estimated and turned consistently
//! (`normals`, Hoppe et al. 1992).
//!
//! The local radius: given, or chosen per point from its spacing, 2.5 × the distance to its
//! 8th nearest neighbour (about 40 points in reach on a surface sampled evenly), so density
//! that varies tenfold across the surface still gives every fit its neighbours. Points whose
//! spacing is over `OUTLIER_SPACING` times the median are outliers, left out before anything
//! is fitted.
//!
//! kiddo's kd-tree answers the neighbour queries (k nearest and within a radius).

pub mod implicit;
pub mod march;
pub mod normals;

use glam::DVec3;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use serde::Serialize;
use std::num::NonZeroUsize;

/// Which local fit (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    Mls,
    Apss,
}

impl std::str::FromStr for Method {
    type Err = crate::error::Invalid;
    fn from_str(s: &str) -> Result<Method, Self::Err> {
        match s {
            "mls" => Ok(Method::Mls),
            "apss" => Ok(Method::Apss),
            _ => Err(format!("method `{s}`: expected mls or apss").into()),
        }
    }
}

/// A point whose spacing exceeds this many times the median spacing is an outlier.
pub const OUTLIER_SPACING: f64 = 6.0;
/// A point whose 8 nearest neighbours spread this much across their plane (smallest over
/// largest eigenvalue of their covariance; (σ_across / σ_along)²) is an outlier: points on a
/// surface with noise of a third of their spacing stay near 0.1, points scattered in space
/// reach 0.3 and more.
pub const OUTLIER_FLATNESS: f64 = 0.15;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The points or a setting are not usable (names which and why).
    #[error("{0}")]
    BadInput(String),
    /// The fits gave no surface.
    #[error("{0}")]
    Empty(String),
}

impl Error {
    pub fn fault(&self) -> crate::Fault {
        match self {
            Error::BadInput(_) => crate::Fault::BadInput,
            Error::Empty(_) => crate::Fault::Numerical,
        }
    }
}

#[derive(Clone, Debug)]
pub struct Config {
    pub method: Method,
    /// The fits' radius in the points' units; `None`: per point from its spacing.
    pub radius: Option<f64>,
    /// Grid cells across the points' longest extent (default 128).
    pub resolution: usize,
    /// Neighbours a normal is estimated from (default 24).
    pub k: usize,
}

impl Default for Config {
    fn default() -> Config {
        Config { method: Method::Apss, radius: None, resolution: 128, k: 24 }
    }
}

pub struct Input {
    pub points: Vec<DVec3>,
    /// One per point, or empty (estimated).
    pub normals: Vec<DVec3>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub points: usize,
    /// Points left out as outliers (spacing over `OUTLIER_SPACING` × the median, or
    /// neighbours not on a surface).
    pub outliers: usize,
    /// Pieces of the mesh removed for holding under `SMALL_PIECE` of the largest's triangles.
    pub pieces_dropped: usize,
    pub normals_estimated: bool,
    /// The fits' radius: the given one, or the median of the per-point radii.
    pub radius: f64,
    pub vertices: usize,
    pub triangles: usize,
    /// Every edge shared by exactly two triangles.
    pub watertight: bool,
    /// Connected parts, and the genus from the Euler characteristic (closed meshes only).
    pub components: usize,
    pub genus: Option<i64>,
    pub seconds: f64,
}

pub struct Output {
    pub mesh: march::Mesh,
    /// The points' normals, estimated or as given (unit).
    pub normals: Vec<DVec3>,
    pub summary: Summary,
}

/// The points indexed for the fits: positions, unit normals, each point's radius.
pub struct Cloud {
    pub points: Vec<DVec3>,
    pub normals: Vec<DVec3>,
    pub radius: Vec<f64>,
    /// The smallest radius a fit uses: the mesher sets it to its grid's scale, since a
    /// surface finer than the grid cannot be meshed, and a grid corner must find points.
    pub floor: f64,
    tree: ImmutableKdTree<f64, 3>,
}

impl Cloud {
    /// The points, indexed (no normals or radii yet).
    pub fn new(points: Vec<DVec3>) -> Result<Cloud, Error> {
        let raw: Vec<[f64; 3]> = points.iter().map(|p| p.to_array()).collect();
        let tree = ImmutableKdTree::new_from_slice(&raw)
            .map_err(|e| Error::BadInput(format!("the points could not be indexed: {e:?}")))?;
        Ok(Cloud { points, normals: Vec::new(), radius: Vec::new(), floor: 0.0, tree })
    }

    /// The `k` points nearest `q`, nearest first.
    pub fn nearest(&self, q: DVec3, k: usize) -> Vec<u32> {
        let Some(k) = NonZeroUsize::new(k) else { return Vec::new() };
        self.tree
            .query(&q.to_array())
            .nearest_n::<SquaredEuclidean<f64>>(k)
            .execute()
            .into_iter()
            .map(|r| r.item as u32)
            .collect()
    }

    /// Calls `visit(i, d²)` for every point within `r` of `q`.
    pub fn within(&self, q: DVec3, r: f64, mut visit: impl FnMut(u32, f64)) {
        for n in self.tree.query(&q.to_array()).within::<SquaredEuclidean<f64>>(r * r).unsorted().execute() {
            visit(n.item as u32, n.distance);
        }
    }
}

/// Builds the surface (module docs).
pub fn run(input: &Input, config: &Config) -> Result<Output, Error> {
    let t = std::time::Instant::now();
    let n = input.points.len();
    if n < implicit::MIN_NEIGHBOURS + 1 {
        return Err(Error::BadInput(format!(
            "{n} point(s): a surface needs at least {} (each fit takes {} neighbours)",
            implicit::MIN_NEIGHBOURS + 1,
            implicit::MIN_NEIGHBOURS
        )));
    }
    if let Some((i, p)) = input.points.iter().enumerate().find(|(_, p)| !p.is_finite()) {
        return Err(Error::BadInput(format!("point {i} is {p}: expected finite coordinates")));
    }
    if n >= u32::MAX as usize {
        return Err(Error::BadInput(format!("{n} points: at most {} are indexed", u32::MAX - 1)));
    }
    if !input.normals.is_empty() {
        if input.normals.len() != n {
            return Err(Error::BadInput(format!(
                "{} normals for {n} points: expected one each",
                input.normals.len()
            )));
        }
        if let Some((i, v)) =
            input.normals.iter().enumerate().find(|(_, v)| !(v.is_finite() && v.length() > 0.0))
        {
            return Err(Error::BadInput(format!("normal {i} is {v}: expected a finite, non-zero vector")));
        }
    }
    if !(8..=1024).contains(&config.resolution) {
        return Err(Error::BadInput(format!(
            "resolution {}: expected 8 to 1024 cells across",
            config.resolution
        )));
    }
    if !(3..=256).contains(&config.k) {
        return Err(Error::BadInput(format!("k = {}: expected 3 to 256 neighbours", config.k)));
    }
    let mut cloud = Cloud::new(input.points.clone())?;
    let (lo, hi) = input.points.iter().fold((DVec3::MAX, DVec3::MIN), |(a, b), p| (a.min(*p), b.max(*p)));
    let extent = (hi - lo).max_element();
    if !(extent > 0.0 && extent.is_finite()) {
        return Err(Error::BadInput(format!(
            "the {n} points span {extent} across: expected points that are not all in one place"
        )));
    }
    // Each point's spacing (the distance to its 8th nearest neighbour) and how flat the 8 lie
    // (their covariance's smallest over largest eigenvalue).
    let (spacing, flatness): (Vec<f64>, Vec<f64>) = {
        use rayon::prelude::*;
        (0..n)
            .into_par_iter()
            .map(|i| {
                let nb = cloud.nearest(cloud.points[i], 9);
                let far = nb.last().map_or(0.0, |&j| cloud.points[j as usize].distance(cloud.points[i]));
                let pts: Vec<DVec3> = nb.iter().map(|&j| cloud.points[j as usize]).collect();
                (far, normals::flatness(&pts))
            })
            .unzip()
    };
    let mut sorted = spacing.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[n / 2];
    if !(median > 0.0) {
        return Err(Error::BadInput(
            "most points coincide with their 8 nearest neighbours: duplicate points? (remove them, or give --radius)".into(),
        ));
    }
    // Outliers: points whose spacing is over `OUTLIER_SPACING` times the median. A surface
    // sampled with density varying tenfold varies √10 ≈ 3.2× in spacing; a point scattered
    // off the surface is far sparser than that.
    // Points sparser than twice the median whose neighbours scatter in all three directions
    // rather than along a surface (`OUTLIER_FLATNESS`) are outliers too: scattered points can
    // be near each other. (A dense cloud with noise looks three-dimensional at the scale of
    // 8 neighbours, hence the spacing condition.)
    let keep: Vec<bool> = spacing
        .iter()
        .zip(&flatness)
        .map(|(&s, &f)| s <= OUTLIER_SPACING * median && !(f > OUTLIER_FLATNESS && s > 2.0 * median))
        .collect();
    let outliers = keep.iter().filter(|k| !**k).count();
    let (points, given_normals, spacing): (Vec<DVec3>, Vec<DVec3>, Vec<f64>) = if outliers > 0 {
        let pick =
            |v: &[DVec3]| v.iter().zip(&keep).filter(|(_, k)| **k).map(|(p, _)| *p).collect::<Vec<_>>();
        (
            pick(&input.points),
            if input.normals.is_empty() { Vec::new() } else { pick(&input.normals) },
            spacing.iter().zip(&keep).filter(|(_, k)| **k).map(|(s, _)| *s).collect(),
        )
    } else {
        (input.points.clone(), input.normals.clone(), spacing)
    };
    if outliers > 0 {
        cloud = Cloud::new(points)?;
    }
    let n_kept = cloud.points.len();
    cloud.radius = match config.radius {
        Some(r) => {
            if !(r.is_finite() && r > 0.0 && r <= extent) {
                return Err(Error::BadInput(format!(
                    "radius {}: expected a positive number no larger than the points' extent ({extent:.4})",
                    if r.abs() >= 1e6 { format!("{r:e}") } else { r.to_string() }
                )));
            }
            vec![r; n_kept]
        }
        None => spacing.iter().map(|s| 2.5 * s.max(0.5 * median)).collect(),
    };
    let estimated = given_normals.is_empty();
    cloud.normals = if estimated {
        normals::estimate(&cloud, config.k)
    } else {
        given_normals.iter().map(|v| v.normalize()).collect()
    };
    let mesh = march::mesh(&mut cloud, config.method, config.resolution)?;
    if mesh.triangles.is_empty() {
        return Err(Error::Empty(format!(
            "no surface: the fits found no sign change near the {n} points (too few neighbours in reach? give a larger --radius)"
        )));
    }
    let (mesh, pieces_dropped) = drop_small_pieces(mesh);
    let (watertight, components, genus) = topology(&mesh);
    let mut radii = cloud.radius.clone();
    radii.sort_by(f64::total_cmp);
    let summary = Summary {
        points: n,
        outliers,
        pieces_dropped,
        normals_estimated: estimated,
        radius: radii[n_kept / 2],
        vertices: mesh.vertices.len(),
        triangles: mesh.triangles.len(),
        watertight,
        components,
        genus,
        seconds: t.elapsed().as_secs_f64(),
    };
    Ok(Output { mesh, normals: cloud.normals, summary })
}

/// Pieces with fewer triangles than this share of the largest piece's are removed: the
/// bubbles an outlier that passed the tests can grow (MeshLab's "remove isolated pieces").
pub const SMALL_PIECE: f64 = 0.01;

/// The mesh without its small pieces (`SMALL_PIECE`), and how many were removed.
fn drop_small_pieces(mesh: march::Mesh) -> (march::Mesh, usize) {
    let labels = pieces(&mesh);
    let mut count: std::collections::HashMap<u32, usize> = std::collections::HashMap::new();
    for t in &mesh.triangles {
        *count.entry(labels[t[0] as usize]).or_default() += 1;
    }
    let largest = count.values().copied().max().unwrap_or(0);
    let small: std::collections::HashSet<u32> =
        count.iter().filter(|(_, &c)| (c as f64) < SMALL_PIECE * largest as f64).map(|(&l, _)| l).collect();
    if small.is_empty() {
        return (mesh, 0);
    }
    // Keep the other pieces' triangles and only the vertices they use, renumbered in order.
    let kept: Vec<[u32; 3]> =
        mesh.triangles.into_iter().filter(|t| !small.contains(&labels[t[0] as usize])).collect();
    let mut new_index = vec![u32::MAX; mesh.vertices.len()];
    let mut vertices = Vec::new();
    for t in &kept {
        for &v in t {
            if new_index[v as usize] == u32::MAX {
                new_index[v as usize] = vertices.len() as u32;
                vertices.push(mesh.vertices[v as usize]);
            }
        }
    }
    let triangles = kept.iter().map(|t| t.map(|v| new_index[v as usize])).collect();
    (march::Mesh { vertices, triangles }, small.len())
}

/// Each vertex's piece: the root of its set under union-find over the triangles.
fn pieces(mesh: &march::Mesh) -> Vec<u32> {
    let mut parent: Vec<u32> = (0..mesh.vertices.len() as u32).collect();
    fn root(p: &mut [u32], mut i: u32) -> u32 {
        while p[i as usize] != i {
            p[i as usize] = p[p[i as usize] as usize];
            i = p[i as usize];
        }
        i
    }
    for t in &mesh.triangles {
        let a = root(&mut parent, t[0]);
        for &v in &t[1..] {
            let b = root(&mut parent, v);
            parent[b as usize] = a;
        }
    }
    (0..mesh.vertices.len() as u32).map(|v| root(&mut parent, v)).collect()
}

/// Whether every edge has two triangles, the number of connected parts, and the genus of a
/// closed mesh from its Euler characteristic, V − E + F = 2·(parts − genus).
pub fn topology(mesh: &march::Mesh) -> (bool, usize, Option<i64>) {
    use std::collections::HashMap;
    let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
    for t in &mesh.triangles {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let watertight = edges.values().all(|&c| c == 2);
    let labels = pieces(mesh);
    let mut used = vec![false; mesh.vertices.len()];
    for t in &mesh.triangles {
        for &v in t {
            used[v as usize] = true;
        }
    }
    let vertices = used.iter().filter(|&&u| u).count() as i64;
    let mut roots: Vec<u32> = (0..mesh.vertices.len()).filter(|&v| used[v]).map(|v| labels[v]).collect();
    roots.sort_unstable();
    roots.dedup();
    let parts = roots.len();
    let chi = vertices - edges.len() as i64 + mesh.triangles.len() as i64;
    let genus = watertight.then(|| parts as i64 - chi / 2);
    (watertight, parts, genus)
}

/// Writes the mesh as a binary little-endian PLY (float vertices, int faces).
pub fn write_ply(path: &std::path::Path, mesh: &march::Mesh) -> Result<(), crate::image::io::Error> {
    let mut bytes = format!(
        "ply\nformat binary_little_endian 1.0\ncomment lumen surface\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.vertices.len(),
        mesh.triangles.len()
    )
    .into_bytes();
    for v in &mesh.vertices {
        for c in v.to_array() {
            bytes.extend_from_slice(&(c as f32).to_le_bytes());
        }
    }
    for t in &mesh.triangles {
        bytes.push(3);
        for &i in t {
            bytes.extend_from_slice(&(i as i32).to_le_bytes());
        }
    }
    crate::image::io::write_atomically(path, |tmp| std::fs::write(tmp, &bytes))
}
