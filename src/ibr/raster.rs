//! A triangle mesh rasterised into a view through a z-buffer: per pixel the nearest triangle,
//! its depth and its (perspective-correct) barycentrics. Textures use it for occlusion (is a
//! surface point the nearest thing a photograph saw along its ray?) and to draw a textured
//! mesh into a new view.
//!
//! The vertices are projected through the camera, distortion included, and each triangle is
//! filled between its projected vertices (its edges straight in the distorted image: for
//! triangles of a few pixels, as meshed surfaces are, within a small fraction of a pixel).
//! Pixel centres are at integer coordinates (OpenCV). 1/z and b/z are interpolated linearly
//! in the image (the perspective-correct interpolation). A triangle with a vertex behind the
//! camera (z < 10⁻⁶ of the mesh's extent) is left out rather than clipped: the views a
//! texture is made from look at the mesh from outside.

use super::{Projector, View};
use crate::surface::march::Mesh;
use glam::DVec2;
use rayon::prelude::*;

/// What each pixel sees: `triangle` is `u32::MAX` where nothing is.
pub struct Raster {
    pub width: u32,
    pub height: u32,
    /// Camera-frame z of the nearest surface; `INFINITY` where none.
    pub depth: Vec<f32>,
    pub triangle: Vec<u32>,
    /// Barycentrics (b1, b2) of the pixel's point in its triangle (b0 = 1 − b1 − b2).
    pub bary: Vec<[f32; 2]>,
}

impl Raster {
    /// The nearest depth at the four pixels around `px` (bilinear taps), or `None` outside.
    pub fn taps(&self, px: DVec2) -> Option<[f32; 4]> {
        let (x0, y0) = (px.x.floor(), px.y.floor());
        if x0 < 0.0 || y0 < 0.0 || x0 + 1.0 >= self.width as f64 || y0 + 1.0 >= self.height as f64 {
            return None;
        }
        let (x, y, w) = (x0 as usize, y0 as usize, self.width as usize);
        let i = y * w + x;
        Some([self.depth[i], self.depth[i + 1], self.depth[i + w], self.depth[i + w + 1]])
    }
}

/// A vertex in the image: pixel position and camera-frame z.
#[derive(Clone, Copy)]
struct Projected {
    px: DVec2,
    z: f64,
}

/// Rasterises `mesh` into `view`.
pub fn rasterise(mesh: &Mesh, view: &View) -> Raster {
    let cam = Projector::new(&view.camera);
    let (w, h) = (view.camera.width as usize, view.camera.height as usize);
    let cam_from_world = view.t_world_cam.inverse();
    let extent = mesh.vertices.iter().fold(0.0f64, |m, v| m.max(v.abs().max_element()));
    let near = 1e-6 * extent.max(1e-300);
    let projected: Vec<Option<Projected>> = mesh
        .vertices
        .par_iter()
        .map(|&v| {
            let p = cam_from_world.transform_point(v);
            if p.z > near {
                cam.image(p).map(|px| Projected { px, z: p.z })
            } else {
                None
            }
        })
        .collect();
    // Triangles binned by the band of rows their bounding box touches, so that bands fill in
    // parallel without sharing pixels.
    const BAND: usize = 32;
    let bands = h.div_ceil(BAND);
    let mut binned: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let Some(v) = tri.iter().map(|&i| projected[i as usize]).collect::<Option<Vec<_>>>() else {
            continue;
        };
        let (lo, hi) = (
            v.iter().map(|p| p.px.y).fold(f64::INFINITY, f64::min),
            v.iter().map(|p| p.px.y).fold(f64::NEG_INFINITY, f64::max),
        );
        if hi < -0.5 || lo > h as f64 - 0.5 {
            continue;
        }
        let (b0, b1) = ((lo.max(0.0) as usize) / BAND, (hi.min(h as f64 - 1.0).max(0.0) as usize) / BAND);
        for b in binned.iter_mut().take(b1 + 1).skip(b0) {
            b.push(t as u32);
        }
    }
    let mut depth = vec![f32::INFINITY; w * h];
    let mut triangle = vec![u32::MAX; w * h];
    let mut bary = vec![[0.0f32; 2]; w * h];
    depth
        .par_chunks_mut(BAND * w)
        .zip(triangle.par_chunks_mut(BAND * w))
        .zip(bary.par_chunks_mut(BAND * w))
        .enumerate()
        .for_each(|(band, ((depth, triangle), bary))| {
            let y_lo = band * BAND;
            let y_hi = (y_lo + BAND).min(h);
            for &t in &binned[band] {
                let tri = mesh.triangles[t as usize];
                let [a, b, c] = tri.map(|i| projected[i as usize].expect("binned triangles are projected"));
                fill(a, b, c, w, y_lo, y_hi, |x, y, z, b1, b2| {
                    let i = (y - y_lo) * w + x;
                    if z < depth[i] {
                        depth[i] = z;
                        triangle[i] = t;
                        bary[i] = [b1, b2];
                    }
                });
            }
        });
    Raster { width: w as u32, height: h as u32, depth, triangle, bary }
}

/// Calls `plot(x, y, z, b1, b2)` for every pixel centre in rows [y_lo, y_hi) inside the
/// triangle (a, b, c), with the perspective-correct depth and barycentrics of b and c.
fn fill(
    a: Projected,
    b: Projected,
    c: Projected,
    w: usize,
    y_lo: usize,
    y_hi: usize,
    mut plot: impl FnMut(usize, usize, f32, f32, f32),
) {
    let area = (b.px - a.px).perp_dot(c.px - a.px);
    if !(area.abs() > 1e-12) {
        return;
    }
    let xs = [a.px.x, b.px.x, c.px.x];
    let ys = [a.px.y, b.px.y, c.px.y];
    let x0 = xs.iter().copied().fold(f64::INFINITY, f64::min).ceil().max(0.0) as usize;
    let x1 = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max).floor().min(w as f64 - 1.0);
    let y0 = (ys.iter().copied().fold(f64::INFINITY, f64::min).ceil().max(y_lo as f64)) as usize;
    let y1 = ys.iter().copied().fold(f64::NEG_INFINITY, f64::max).floor().min(y_hi as f64 - 1.0);
    if x1 < 0.0 || y1 < 0.0 {
        return;
    }
    let (x1, y1) = (x1 as usize, y1 as usize);
    let (iza, izb, izc) = (1.0 / a.z, 1.0 / b.z, 1.0 / c.z);
    for y in y0..=y1 {
        for x in x0..=x1 {
            let p = DVec2::new(x as f64, y as f64);
            // Screen-space barycentrics of b and c (a pixel on an edge two triangles share
            // is filled by both; the z-test keeps one).
            let lb = (p - a.px).perp_dot(c.px - a.px) / area;
            let lc = (b.px - a.px).perp_dot(p - a.px) / area;
            let la = 1.0 - lb - lc;
            if la < 0.0 || lb < 0.0 || lc < 0.0 {
                continue;
            }
            let iz = la * iza + lb * izb + lc * izc;
            let z = 1.0 / iz;
            plot(x, y, z as f32, (lb * izb * z) as f32, (lc * izc * z) as f32);
        }
    }
}
