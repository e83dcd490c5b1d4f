//! A texture for a mesh from photographs with known cameras.
//!
//! Each texel's surface point X (its atlas triangle, `atlas`) takes the colour c that
//! minimises
//!
//!   E(c) = Σ_t Σ_v w_tv·|c_t − g_v ⊙ I_v(π_v(X_t))|² + λ·Σ_(t,n) |c_t − c_n|²,
//!
//! the seed's objective: a data term over the photographs v that see X, and a smoothness term
//! over neighbouring texels (4-neighbours in a chart, and pairs across chart seams: the texels
//! on either side of a mesh edge two charts share).
//!
//! - **Visibility.** X is seen by v when no surface of the mesh lies in front of it: the
//!   mesh's z-buffer in v (`raster`) at the four pixels around π_v(X) is no nearer than X by
//!   more than `depth_tolerance` (relative), and one of them is X's surface.
//! - **Weights** w_tv = (cos θ · f_v / z)² · s_v: the texel's footprint in the photograph
//!   (pixels per unit area; θ the angle between the surface normal and the ray, z the depth,
//!   f_v the focal length) times the photograph's sharpness s_v (the mean squared Laplacian of
//!   its grey image, a focus measure, over the sharpest's). Views beyond `max_angle_deg` are
//!   left out.
//! - **Exposure and white balance.** Photographs differ in gain: g_v (per channel) is fitted
//!   first on texels seen by two or more views, alternating the texels' weighted means with
//!   each view's median ratio mean / I_v, the gains' geometric mean held at 1.
//! - **Solve.** With normalised data weights (Σ_v w_tv = 1 where a texel is seen, 0 where not)
//!   the minimum is found by Jacobi iteration (at most 200 steps), started from the data, and
//!   for texels no photograph sees from the nearest seen texel; those are then smoothed by
//!   the smoothness term alone (diffusion). The gutter around each chart is then
//!   filled from the chart, so bilinear lookups at chart edges read the chart's colours.

use super::atlas::{self, Atlas, Texel};
use super::raster::{self, Raster};
use super::{Error, Projector, View};
use crate::image::Image;
use crate::surface::march::Mesh;
use glam::{DVec2, DVec3};
use rayon::prelude::*;

/// A photograph and its camera.
pub struct Photo<'a> {
    pub name: String,
    pub image: &'a Image,
    pub view: View,
}

#[derive(Clone, Debug)]
pub struct Config {
    /// Texels per side of the square texture, 64 to 16384 (default 1024).
    pub size: u32,
    /// λ, the smoothness weight against a data term of weight 1 (default 0.02: a seen texel
    /// keeps at least 1/(1 + 4λ) ≈ 93 % of its own colour).
    pub smoothness: f64,
    /// Views that see the surface more obliquely than this are left out (default 75°).
    pub max_angle_deg: f64,
    /// Relative depth under which a surface in front of X does not hide it (default 0.01).
    pub depth_tolerance: f64,
    /// Fit a gain per photograph and channel (default true).
    pub equalise: bool,
}

impl Default for Config {
    fn default() -> Config {
        Config { size: 1024, smoothness: 0.02, max_angle_deg: 75.0, depth_tolerance: 0.01, equalise: true }
    }
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct PhotoSummary {
    pub name: String,
    /// Texels this photograph contributes to.
    pub texels: usize,
    /// Its gain per channel (g_v).
    pub gain: Vec<f64>,
    /// Its sharpness relative to the sharpest (s_v).
    pub sharpness: f64,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct Summary {
    pub triangles: usize,
    pub charts: usize,
    pub size: u32,
    /// Texels per scene unit.
    pub texels_per_unit: f64,
    /// Texels on the surface.
    pub texels: usize,
    /// Share of them that some photograph sees.
    pub seen_fraction: f64,
    pub photos: Vec<PhotoSummary>,
    pub seconds: f64,
}

pub struct Output {
    pub atlas: Atlas,
    pub texture: Image,
    pub summary: Summary,
}

/// One photograph's look at a texel: its index, weight and colour (before gain).
#[derive(Clone, Copy)]
struct Look {
    view: u32,
    weight: f64,
    colour: [f32; 4],
}

fn check(mesh: &Mesh, photos: &[Photo], config: &Config) -> Result<u32, Error> {
    if mesh.triangles.is_empty() {
        return Err(Error::BadInput("the mesh has no faces: expected triangles".into()));
    }
    if let Some(i) = mesh.vertices.iter().position(|v| !v.is_finite()) {
        return Err(Error::BadInput(format!(
            "vertex {} is {:?}: expected finite coordinates",
            i + 1,
            mesh.vertices[i]
        )));
    }
    let n = mesh.vertices.len() as u32;
    if let Some(t) = mesh.triangles.iter().position(|t| t.iter().any(|&i| i >= n)) {
        return Err(Error::BadInput(format!(
            "face {} refers to vertex {:?} of {n}: expected indices of the mesh's vertices",
            t + 1,
            mesh.triangles[t]
        )));
    }
    let Some(first) = photos.first() else {
        return Err(Error::BadInput("no photograph: expected at least one".into()));
    };
    for p in photos {
        p.view.camera.validate().map_err(|e| Error::BadInput(format!("{}: its camera: {e}", p.name)))?;
        let (w, h) = (p.view.camera.width, p.view.camera.height);
        if (p.image.width, p.image.height) != (w, h) {
            return Err(Error::BadInput(format!(
                "{}: the photograph is {}×{}, its camera {w}×{h}: expected the same size",
                p.name, p.image.width, p.image.height
            )));
        }
        if p.image.channels != first.image.channels || p.image.channels > 4 {
            return Err(Error::BadInput(format!(
                "{}: {} channels, {} has {}: expected the same number, at most 4",
                p.name, p.image.channels, first.name, first.image.channels
            )));
        }
        if p.image.has_non_finite() {
            return Err(Error::BadInput(format!("{}: the photograph holds NaN or infinite values", p.name)));
        }
    }
    let ok = |v: f64, lo: f64, hi: f64| v.is_finite() && v >= lo && v <= hi;
    if !ok(config.smoothness, 0.0, 1e3)
        || !ok(config.max_angle_deg, 1.0, 89.0)
        || !ok(config.depth_tolerance, 1e-6, 0.5)
    {
        return Err(Error::BadInput(format!(
            "smoothness {}, max angle {}°, depth tolerance {}: expected 0 to 1000, 1° to 89°, 10⁻⁶ to 0.5",
            config.smoothness, config.max_angle_deg, config.depth_tolerance
        )));
    }
    Ok(first.image.channels)
}

/// The mean squared Laplacian of a photograph's grey levels (a focus measure).
fn sharpness(img: &Image) -> f64 {
    let (w, h, c) = (img.width as usize, img.height as usize, img.channels as usize);
    if w < 3 || h < 3 {
        return 0.0;
    }
    let grey = |x: usize, y: usize| -> f64 {
        let p = &img.data[(y * w + x) * c..][..c];
        p.iter().map(|&v| v as f64).sum::<f64>() / c as f64
    };
    let sum: f64 = (1..h - 1)
        .into_par_iter()
        .map(|y| {
            (1..w - 1)
                .map(|x| {
                    let l =
                        grey(x - 1, y) + grey(x + 1, y) + grey(x, y - 1) + grey(x, y + 1) - 4.0 * grey(x, y);
                    l * l
                })
                .sum::<f64>()
        })
        .sum();
    sum / ((w - 2) * (h - 2)) as f64
}

/// What each photograph makes of the texel at `x` with normal `n` (module docs).
struct Looker<'a> {
    photos: &'a [Photo<'a>],
    /// Each photograph's world-to-camera pose.
    from_world: Vec<crate::math::WorldToCamera>,
    rasters: Vec<Raster>,
    projectors: Vec<Projector>,
    sharpness: Vec<f64>,
    cos_max: f64,
    tolerance: f32,
}

impl Looker<'_> {
    fn looks(&self, x: DVec3, n: DVec3, out: &mut Vec<Look>) {
        out.clear();
        for (v, p) in self.photos.iter().enumerate() {
            let centre = p.view.t_world_cam.centre();
            let to_cam = centre - x;
            let cos = (n.dot(to_cam) / to_cam.length()).abs();
            if !(cos >= self.cos_max) {
                continue;
            }
            let q = self.from_world[v].transform_point(x);
            let Some(px) = self.projectors[v].project(q) else {
                continue;
            };
            let Some(taps) = self.rasters[v].taps(px) else {
                continue;
            };
            let z = q.z as f32;
            let nearest = taps.iter().copied().fold(f32::INFINITY, f32::min);
            if nearest < z * (1.0 - self.tolerance) || nearest > z * (1.0 + self.tolerance) {
                continue;
            }
            let footprint = cos * p.view.camera.intrinsics.fx / q.z;
            out.push(Look {
                view: v as u32,
                weight: footprint * footprint * self.sharpness[v],
                colour: p.image.bilinear(px),
            });
        }
    }
}

/// Gains per photograph and channel from texels seen more than once (module docs).
fn fit_gains(samples: &[Vec<Look>], views: usize, channels: usize) -> Vec<[f64; 4]> {
    let mut gain = vec![[1.0f64; 4]; views];
    for _ in 0..5 {
        let mut ratios: Vec<Vec<Vec<f64>>> = vec![vec![Vec::new(); channels]; views];
        for looks in samples {
            for ch in 0..channels {
                let (mut sum, mut wsum) = (0.0, 0.0);
                for l in looks {
                    sum += l.weight * gain[l.view as usize][ch] * l.colour[ch] as f64;
                    wsum += l.weight;
                }
                let mean = sum / wsum;
                for l in looks {
                    let v = l.colour[ch] as f64;
                    if v > 1e-4 && mean > 1e-4 {
                        ratios[l.view as usize][ch].push(mean / v);
                    }
                }
            }
        }
        for ch in 0..channels {
            let mut log_sum = 0.0;
            for v in 0..views {
                if let Some(m) = crate::math::stats::median(&mut ratios[v][ch]) {
                    gain[v][ch] = m;
                }
                log_sum += gain[v][ch].ln();
            }
            let norm = (-log_sum / views as f64).exp();
            gain.iter_mut().for_each(|g| g[ch] *= norm);
        }
    }
    gain
}

/// The texel pairs across chart seams: along every mesh edge two charts share, points one
/// texel apart, each mapped to the covered texel it falls in on either side.
fn seam_pairs(mesh: &Mesh, atlas: &Atlas, slot: &[u32]) -> Vec<(u32, u32)> {
    let size = atlas.size as i64;
    let texel_at = |p: DVec2| -> Option<u32> {
        let (x, y) = (p.x.floor() as i64, p.y.floor() as i64);
        if x < 0 || y < 0 || x >= size || y >= size {
            return None;
        }
        let s = slot[(y * size + x) as usize];
        (s != u32::MAX).then_some(s)
    };
    let mut pairs = Vec::new();
    for (&(lo, _), sides) in &atlas::edges(mesh) {
        let [(t1, k1), (t2, k2)] = sides[..] else { continue };
        if atlas.chart[t1 as usize] == atlas.chart[t2 as usize] {
            continue;
        }
        // Each side's edge from vertex `lo` to the other end, in its chart.
        let ends = |t: u32, k: usize| {
            let uv = atlas.uv[t as usize];
            let (a, b) = (uv[k], uv[(k + 1) % 3]);
            if mesh.triangles[t as usize][k] == lo {
                (a, b)
            } else {
                (b, a)
            }
        };
        let ((a1, b1), (a2, b2)) = (ends(t1, k1), ends(t2, k2));
        let steps = ((b1 - a1).length().max((b2 - a2).length()).ceil() as usize).max(1);
        for s in 0..=steps {
            let f = (s as f64 + 0.5) / (steps + 1) as f64;
            if let (Some(p), Some(q)) = (texel_at(a1.lerp(b1, f)), texel_at(a2.lerp(b2, f))) {
                if p != q {
                    pairs.push((p, q));
                }
            }
        }
    }
    pairs.sort_unstable();
    pairs.dedup();
    pairs
}

/// The texture of `mesh` from `photos` (module docs).
pub fn run(mesh: &Mesh, photos: &[Photo], config: &Config) -> Result<Output, Error> {
    let start = std::time::Instant::now();
    let channels = check(mesh, photos, config)? as usize;
    let atlas = atlas::build(mesh, config.size)?;
    let texels: Vec<Texel> = atlas::texels(&atlas);
    let normals = atlas::face_normals(mesh);
    let sharp: Vec<f64> = photos.iter().map(|p| sharpness(p.image)).collect();
    let sharpest = sharp.iter().copied().fold(0.0, f64::max);
    let looker = Looker {
        photos,
        from_world: photos.iter().map(|p| p.view.t_world_cam.inverse()).collect(),
        rasters: photos.iter().map(|p| raster::rasterise(mesh, &p.view)).collect(),
        projectors: photos.iter().map(|p| Projector::new(&p.view.camera)).collect(),
        sharpness: sharp
            .iter()
            .map(|&s| if sharpest > 0.0 { (s / sharpest).max(1e-3) } else { 1.0 })
            .collect(),
        cos_max: config.max_angle_deg.to_radians().cos(),
        tolerance: config.depth_tolerance as f32,
    };
    let point = |t: &Texel| {
        let [a, b, c] = mesh.triangles[t.triangle as usize].map(|i| mesh.vertices[i as usize]);
        a * (1.0 - t.bary[0] - t.bary[1]) + b * t.bary[0] + c * t.bary[1]
    };
    // Gains from an even subset of the texels seen twice or more.
    let gain = if config.equalise && photos.len() > 1 {
        let stride = (texels.len() / 50_000).max(1);
        let samples: Vec<Vec<Look>> = texels
            .par_iter()
            .step_by(stride)
            .filter_map(|t| {
                let mut looks = Vec::new();
                looker.looks(point(t), normals[t.triangle as usize], &mut looks);
                (looks.len() > 1).then_some(looks)
            })
            .collect();
        fit_gains(&samples, photos.len(), channels)
    } else {
        vec![[1.0; 4]; photos.len()]
    };
    // The data term: each texel's weighted mean and whether it is seen; the views it used.
    let data: Vec<(Option<[f32; 4]>, Vec<u32>)> = texels
        .par_iter()
        .map_init(Vec::new, |looks, t| {
            looker.looks(point(t), normals[t.triangle as usize], looks);
            let wsum: f64 = looks.iter().map(|l| l.weight).sum();
            if !(wsum > 0.0) {
                return (None, Vec::new());
            }
            let mut mean = [0.0f32; 4];
            for l in looks.iter() {
                for ch in 0..channels {
                    mean[ch] += (l.weight / wsum * gain[l.view as usize][ch]) as f32 * l.colour[ch];
                }
            }
            (Some(mean), looks.iter().map(|l| l.view).collect())
        })
        .collect();
    let mut used = vec![0usize; photos.len()];
    data.iter().flat_map(|d| &d.1).for_each(|&v| used[v as usize] += 1);
    let seen = data.iter().filter(|d| d.0.is_some()).count();
    if seen == 0 {
        return Err(Error::BadInput(format!(
            "no photograph sees the mesh ({} photographs, {} texels): expected cameras that look at it, in the mesh's frame and units",
            photos.len(),
            texels.len()
        )));
    }
    let colours =
        solve(&atlas, &texels, &data.iter().map(|d| d.0).collect::<Vec<_>>(), mesh, config.smoothness);
    let texture = paint(&atlas, &texels, &colours, channels);
    let summary = Summary {
        triangles: mesh.triangles.len(),
        charts: atlas.charts,
        size: atlas.size,
        texels_per_unit: atlas.scale,
        texels: texels.len(),
        seen_fraction: seen as f64 / texels.len().max(1) as f64,
        photos: photos
            .iter()
            .enumerate()
            .map(|(v, p)| PhotoSummary {
                name: p.name.clone(),
                texels: used[v],
                gain: gain[v][..channels].to_vec(),
                sharpness: looker.sharpness[v],
            })
            .collect(),
        seconds: start.elapsed().as_secs_f64(),
    };
    Ok(Output { atlas, texture, summary })
}

/// Minimises E by Jacobi iteration (module docs): the texels' colours, in `texels`' order.
fn solve(
    atlas: &Atlas,
    texels: &[Texel],
    data: &[Option<[f32; 4]>],
    mesh: &Mesh,
    lambda: f64,
) -> Vec<[f32; 4]> {
    let size = atlas.size as usize;
    let mut slot = vec![u32::MAX; size * size];
    for (s, t) in texels.iter().enumerate() {
        slot[t.index as usize] = s as u32;
    }
    // Neighbours: 4-neighbours in the same chart, and seam pairs.
    let mut near: Vec<Vec<u32>> = texels
        .iter()
        .map(|t| {
            let (x, y) = ((t.index as usize % size) as i64, (t.index as usize / size) as i64);
            let chart = atlas.chart[t.triangle as usize];
            [(-1, 0), (1, 0), (0, -1), (0, 1)]
                .iter()
                .filter_map(|&(dx, dy)| {
                    let (xx, yy) = (x + dx, y + dy);
                    if xx < 0 || yy < 0 || xx >= size as i64 || yy >= size as i64 {
                        return None;
                    }
                    let s = slot[yy as usize * size + xx as usize];
                    (s != u32::MAX && atlas.chart[texels[s as usize].triangle as usize] == chart).then_some(s)
                })
                .collect()
        })
        .collect();
    for (p, q) in seam_pairs(mesh, atlas, &slot) {
        near[p as usize].push(q);
        near[q as usize].push(p);
    }
    // Start: the data where seen; elsewhere the colour of the nearest seen texel along the
    // neighbour graph (breadth first), so that the iteration only smooths what it inpaints.
    let mut c: Vec<[f32; 4]> = data.iter().map(|d| d.unwrap_or([0.0; 4])).collect();
    let mut reached: Vec<bool> = data.iter().map(|d| d.is_some()).collect();
    let mut queue: std::collections::VecDeque<u32> =
        (0..c.len() as u32).filter(|&t| reached[t as usize]).collect();
    while let Some(t) = queue.pop_front() {
        for &n in &near[t as usize] {
            if !reached[n as usize] {
                reached[n as usize] = true;
                c[n as usize] = c[t as usize];
                queue.push_back(n);
            }
        }
    }
    let lambda = lambda as f32;
    for _ in 0..200 {
        let next: Vec<[f32; 4]> = (0..c.len())
            .into_par_iter()
            .map(|t| {
                let (a, m) = match data[t] {
                    Some(m) => (1.0, m),
                    None => (0.0, [0.0; 4]),
                };
                let l = if a > 0.0 { lambda } else { 1.0 };
                let mut num = m.map(|v| a * v);
                for &n in &near[t] {
                    for k in 0..4 {
                        num[k] += l * c[n as usize][k];
                    }
                }
                let den = a + l * near[t].len() as f32;
                if den > 0.0 {
                    num.map(|v| v / den)
                } else {
                    c[t]
                }
            })
            .collect();
        let change = next
            .iter()
            .zip(&c)
            .map(|(a, b)| (0..4).map(|k| (a[k] - b[k]).abs()).fold(0.0, f32::max))
            .fold(0.0, f32::max);
        c = next;
        if change < 1e-5 {
            break;
        }
    }
    c
}

/// The texture image: the texels' colours, the gutter filled from the charts (each empty
/// texel next to a filled one takes their mean, `PAD` + 1 times).
fn paint(atlas: &Atlas, texels: &[Texel], colours: &[[f32; 4]], channels: usize) -> Image {
    let size = atlas.size as usize;
    let mut img = Image::new(atlas.size, atlas.size, channels as u32);
    let mut filled = vec![false; size * size];
    for (t, c) in texels.iter().zip(colours) {
        img.data[t.index as usize * channels..][..channels].copy_from_slice(&c[..channels]);
        filled[t.index as usize] = true;
    }
    for _ in 0..=atlas::PAD {
        let mut add = Vec::new();
        for i in 0..size * size {
            if filled[i] {
                continue;
            }
            let (x, y) = ((i % size) as i64, (i / size) as i64);
            let mut sum = [0.0f32; 4];
            let mut n = 0;
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let (xx, yy) = (x + dx, y + dy);
                    if xx < 0 || yy < 0 || xx >= size as i64 || yy >= size as i64 {
                        continue;
                    }
                    let j = yy as usize * size + xx as usize;
                    if filled[j] {
                        for k in 0..channels {
                            sum[k] += img.data[j * channels + k];
                        }
                        n += 1;
                    }
                }
            }
            if n > 0 {
                add.push((i, sum.map(|v| v / n as f32)));
            }
        }
        for (i, c) in add {
            img.data[i * channels..][..channels].copy_from_slice(&c[..channels]);
            filled[i] = true;
        }
    }
    img
}

/// The textured mesh drawn into `view`: per pixel the texture, bilinear, at the nearest
/// surface's texture coordinates; and a mask (1 where the mesh is seen).
pub fn draw(mesh: &Mesh, atlas: &Atlas, texture: &Image, view: &View) -> (Image, Image) {
    let r = raster::rasterise(mesh, view);
    let c = texture.channels as usize;
    let mut img = Image::new(r.width, r.height, texture.channels);
    let mut mask = Image::new(r.width, r.height, 1);
    img.data.par_chunks_mut(c).zip(mask.data.par_chunks_mut(1)).enumerate().for_each(|(i, (px, m))| {
        let t = r.triangle[i];
        if t == u32::MAX {
            return;
        }
        let [a, b, cc] = atlas.uv[t as usize];
        let [b1, b2] = r.bary[i].map(|v| v as f64);
        let uv = a * (1.0 - b1 - b2) + b * b1 + cc * b2;
        // Texel centres are at +0.5.
        let colour = texture.bilinear(uv - DVec2::splat(0.5));
        px.copy_from_slice(&colour[..c]);
        m[0] = 1.0;
    });
    (img, mask)
}

/// The textured mesh as Wavefront OBJ text referring to `mtl` (material `texture`): every
/// vertex, three texture coordinates per triangle (v up, as OBJ has it), the faces.
pub fn obj_text(mesh: &Mesh, atlas: &Atlas, mtl: &str) -> String {
    use std::fmt::Write;
    let mut s = format!(
        "# lumen texture: {} vertices, {} triangles\nmtllib {mtl}\nusemtl texture\n",
        mesh.vertices.len(),
        mesh.triangles.len()
    );
    for v in &mesh.vertices {
        let _ = writeln!(s, "v {} {} {}", v.x, v.y, v.z);
    }
    let size = atlas.size as f64;
    for uv in &atlas.uv {
        for p in uv {
            let _ = writeln!(s, "vt {} {}", p.x / size, 1.0 - p.y / size);
        }
    }
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let vt = 3 * t + 1;
        let _ = writeln!(s, "f {}/{} {}/{} {}/{}", tri[0] + 1, vt, tri[1] + 1, vt + 1, tri[2] + 1, vt + 2);
    }
    s
}

/// The material file `obj_text` refers to: a white diffuse material with the texture image.
pub fn mtl_text(texture_file: &str) -> String {
    format!("newmtl texture\nKa 0 0 0\nKd 1 1 1\nKs 0 0 0\nmap_Kd {texture_file}\n")
}
