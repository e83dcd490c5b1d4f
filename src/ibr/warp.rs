//! Depth-based rendering: a new view from source views with depth (McMillan 1997; the two
//! mappings as Mark, McMillan & Bishop 1997 and Shade et al. 1998 set them out).
//!
//! Every source pixel x_s with depth z lifts to the point X = z·n(x_s), n the undistorted ray
//! with n_z = 1, which the relative pose T_ts = T_tw·T_ws carries into the target frame and
//! the target camera projects: x_t = π(T_ts·X).
//!
//! - **Forward** mapping splats each source pixel's colour onto the target pixel nearest x_t
//!   through a z-buffer: the nearest splat, from whichever source, is what the pixel shows. Where the target magnifies the source, splats leave cracks; where the
//!   target sees what no source saw, holes.
//! - **Backward** mapping splats only the depth, then filters it: a 3×3 median over the depths
//!   present replaces the background that shows through a crack in a foreground (a depth
//!   behind the median) and fills empty pixels with enough neighbours (at least 5 of 8;
//!   `fill_passes` times). Each target
//!   pixel with a depth then lifts to X and is looked up in every source: bilinear over the
//!   four pixels around π_s(X) whose depth agrees with X's (relative `depth_tolerance`), so a
//!   source that does not see X (occluded, or out of its frame) gives nothing.
//!
//! In backward mapping several sources blend with weights 1/(θ + 1°), θ the angle at X between the rays to the
//! source's and the target's centres (as a chord, `angle_weight`) (the angle penalty of Buehler et al. 2001's unstructured
//! lumigraph): the source that sees X most nearly as the target does dominates. Pixels no
//! source sees are 0 and marked in the mask.

use super::{Error, Projector, Source, View};
use crate::image::Image;
use crate::math::Pose;
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    Forward,
    Backward,
}

impl std::str::FromStr for Mode {
    type Err = crate::error::Invalid;
    fn from_str(s: &str) -> Result<Mode, Self::Err> {
        match s {
            "forward" => Ok(Mode::Forward),
            "backward" => Ok(Mode::Backward),
            _ => Err(format!("`{s}`: expected `forward` or `backward`").into()),
        }
    }
}

#[derive(Clone, Debug)]
pub struct Config {
    pub mode: Mode,
    /// Backward mapping: the relative depth difference under which two depths are one surface (default 0.02: a
    /// surface at 70° from the view, seen at a focal length of 250 px, changes depth by about
    /// 1 % of itself per pixel).
    pub depth_tolerance: f64,
    /// Median-filter passes over the splatted depth in backward mapping (default 2: a pass
    /// closes cracks one pixel wide).
    pub fill_passes: usize,
}

impl Default for Config {
    fn default() -> Config {
        Config { mode: Mode::Backward, depth_tolerance: 0.02, fill_passes: 2 }
    }
}

pub struct Output {
    /// The new view, the sources' channels.
    pub image: Image,
    /// One channel: 1 where a source was seen, 0 in the holes.
    pub mask: Image,
    /// Camera-frame z of what the new view shows, 0 in the holes.
    pub depth: Image,
    /// Share of the new view's pixels that no source sees.
    pub hole_fraction: f64,
}

/// The angle weight 1/(θ + 1°) of a source whose centre is `c_source` (target frame) for the
/// point `p` (target frame). θ is taken as the chord |â − b̂| = 2·sin(θ/2), equal to θ within
/// 1 % below 20° and, unlike acos, cheap and exact near 0.
fn angle_weight(p: DVec3, c_source: DVec3) -> f32 {
    let b = p - c_source;
    let cos = p.dot(b) / (p.length_squared() * b.length_squared()).sqrt();
    (1.0 / ((2.0 - 2.0 * cos).max(0.0).sqrt() + 1f64.to_radians())) as f32
}

/// Calls `visit(target pixel, z there, source pixel)` for every source pixel with a depth
/// that lands in the target (the nearest pixel centre), in parallel over the source's rows.
fn for_each_splat(
    source: &Source,
    target: &Projector,
    t_tgt_src: &Pose,
    visit: impl Fn(usize, f32, usize) + Sync,
) {
    let cam = &source.view.camera;
    let w = cam.width as usize;
    let tw = target.camera.width as usize;
    source.depth.data.par_chunks(w).enumerate().for_each_init(
        || vec![None; w],
        |rays, (y, row)| {
            cam.undistort_row(y as u32, rays);
            for ((x, &z), n) in row.iter().enumerate().zip(rays.iter()) {
                let Some(n) = n.filter(|_| z > 0.0) else {
                    continue;
                };
                let i = y * w + x;
                let p = t_tgt_src.transform_point(DVec3::new(n.x, n.y, 1.0) * z as f64);
                if let Some(px) = target.project(p) {
                    // `project` keeps both coordinates above −0.5: truncating x + 0.5 rounds
                    // (a conversion instruction, where `round` is a call into libm; to i64,
                    // one instruction, where f64 to usize takes a branch and two).
                    let (u, v) = ((px.x + 0.5) as i64 as usize, (px.y + 0.5) as i64 as usize);
                    visit(v * tw + u, p.z as f32, i);
                }
            }
        },
    );
}

/// The pose carrying source-camera coordinates into target-camera coordinates.
fn relative_pose(source: &View, target: &View) -> Pose {
    target.t_world_cam.inverse().0.compose(&source.t_world_cam.0)
}

/// Checks the sources and the target; the sources' channel count.
fn check(sources: &[Source], target: &View) -> Result<u32, Error> {
    let Some(first) = sources.first() else {
        return Err(Error::BadInput("no source view: expected at least one".into()));
    };
    target.camera.validate().map_err(|e| Error::BadInput(format!("the target camera: {e}")))?;
    let (w, h) = (target.camera.width as u64, target.camera.height as u64);
    if w * h > 1 << 28 {
        return Err(Error::BadInput(format!("the target camera is {w}×{h}: expected at most 2^28 pixels")));
    }
    for s in sources {
        s.view.camera.validate().map_err(|e| Error::BadInput(format!("{}: its camera: {e}", s.name)))?;
        s.check()?;
        if s.image.channels != first.image.channels {
            return Err(Error::BadInput(format!(
                "{} has {} channels, {} has {}: expected the same",
                s.name, s.image.channels, first.name, first.image.channels
            )));
        }
    }
    Ok(first.image.channels)
}

/// The new view `target` from `sources` (module docs).
pub fn warp(sources: &[Source], target: &View, config: &Config) -> Result<Output, Error> {
    let channels = check(sources, target)?;
    if !(config.depth_tolerance > 0.0 && config.depth_tolerance < 1.0) {
        return Err(Error::BadInput(format!(
            "depth tolerance {}: expected a relative difference in (0, 1)",
            config.depth_tolerance
        )));
    }
    let projector = Projector::new(&target.camera);
    let (w, h) = (target.camera.width, target.camera.height);
    let poses: Vec<Pose> = sources.iter().map(|s| relative_pose(&s.view, target)).collect();
    let (image, mask, depth) = match config.mode {
        Mode::Forward => forward(sources, &projector, &poses, w, h, channels)?,
        Mode::Backward => {
            // Positive floats order as their bits do: the nearest depth is an atomic minimum
            // of the bits (splats from far-apart rows seldom meet at one pixel at once).
            let nearest: Vec<AtomicU32> =
                (0..w * h).map(|_| AtomicU32::new(f32::INFINITY.to_bits())).collect();
            for (s, pose) in sources.iter().zip(&poses) {
                for_each_splat(s, &projector, pose, |t, z, _| {
                    nearest[t].fetch_min(z.to_bits(), Ordering::Relaxed);
                });
            }
            let mut zbuf: Vec<f32> = nearest.into_iter().map(|z| f32::from_bits(z.into_inner())).collect();
            for _ in 0..config.fill_passes {
                zbuf = median_fill(&zbuf, w as usize, h as usize, config.depth_tolerance as f32);
            }
            backward(sources, &poses, target, &zbuf, channels, config.depth_tolerance)
        }
    };
    let holes = mask.data.iter().filter(|&&m| m == 0.0).count();
    Ok(Output { image, mask, depth, hole_fraction: holes as f64 / (w * h) as f64 })
}

/// Forward mapping: each target pixel shows the nearest splat, the atomic minimum of its
/// depth's bits (positive floats order as their bits do) with the splat's number below them.
fn forward(
    sources: &[Source],
    projector: &Projector,
    poses: &[Pose],
    w: u32,
    h: u32,
    channels: u32,
) -> Result<(Image, Image, Image), Error> {
    let mut offsets = Vec::with_capacity(sources.len());
    let mut total = 0u64;
    for s in sources {
        offsets.push(total);
        total += s.depth.data.len() as u64;
    }
    if total > u32::MAX as u64 {
        return Err(Error::BadInput(format!(
            "{total} source pixels: expected at most 2^32 for forward mapping"
        )));
    }
    let nearest: Vec<AtomicU64> = (0..w * h).map(|_| AtomicU64::new(u64::MAX)).collect();
    for ((s, pose), &offset) in sources.iter().zip(poses).zip(&offsets) {
        for_each_splat(s, projector, pose, |t, z, i| {
            nearest[t].fetch_min(((z.to_bits() as u64) << 32) | (offset + i as u64), Ordering::Relaxed);
        });
    }
    let c = channels as usize;
    let mut image = Image::new(w, h, channels);
    let mut mask = Image::new(w, h, 1);
    let mut depth = Image::new(w, h, 1);
    image
        .data
        .par_chunks_mut(c)
        .zip(mask.data.par_chunks_mut(1))
        .zip(depth.data.par_chunks_mut(1))
        .zip(nearest.par_iter())
        .for_each(|(((px, m), d), key)| {
            let key = key.load(Ordering::Relaxed);
            if key == u64::MAX {
                return;
            }
            let id = key & 0xffff_ffff;
            let k = offsets.partition_point(|&o| o <= id) - 1;
            let i = (id - offsets[k]) as usize;
            px.copy_from_slice(&sources[k].image.data[i * c..][..c]);
            m[0] = 1.0;
            d[0] = f32::from_bits((key >> 32) as u32);
        });
    Ok((image, mask, depth))
}

/// One pass of the 3×3 median over the depths present (`INFINITY`: none): a depth behind the
/// median by more than `tolerance` (relative) takes it, and so does an empty pixel when at
/// least 5 of its 8 neighbours have a depth.
fn median_fill(z: &[f32], w: usize, h: usize, tolerance: f32) -> Vec<f32> {
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, out_row)| {
        let rows: Vec<&[f32]> = (y.saturating_sub(1)..(y + 2).min(h)).map(|yy| &z[yy * w..][..w]).collect();
        let row = &z[y * w..][..w];
        for (x, out) in out_row.iter_mut().enumerate() {
            let (x0, x1) = (x.saturating_sub(1), (x + 2).min(w));
            let zi = row[x];
            let present = zi.is_finite();
            // The nearest depth around, the pixel's own included (∞ where none).
            let nearest = rows.iter().flat_map(|r| &r[x0..x1]).fold(f32::INFINITY, |m, &d| m.min(d));
            // Not behind the nearest neighbour, so not behind the median: kept.
            if present && zi <= nearest * (1.0 + tolerance) {
                *out = zi;
                continue;
            }
            let mut v = [0.0f32; 9];
            let mut n = 0;
            for &d in rows.iter().flat_map(|r| &r[x0..x1]) {
                if d.is_finite() {
                    v[n] = d;
                    n += 1;
                }
            }
            if n == 0 || (!present && n < 5) {
                *out = zi;
                continue;
            }
            let v = &mut v[..n];
            v.sort_unstable_by(f32::total_cmp);
            let median = v[n / 2];
            // A depth present is replaced only where it lies behind its neighbourhood: the
            // background through a crack. At a silhouette the median could pick the other
            // layer; a depth that agrees or is nearer stays.
            *out = if present && zi <= median * (1.0 + tolerance) { zi } else { median };
        }
    });
    out
}

/// Backward mapping: each target pixel with a depth looked up in every source.
/// `t_tgt_src[k]` carries source k's camera coordinates into the target's.
fn backward(
    sources: &[Source],
    t_tgt_src: &[Pose],
    target: &View,
    zbuf: &[f32],
    channels: u32,
    tolerance: f64,
) -> (Image, Image, Image) {
    let cam = &target.camera;
    let (w, h) = (cam.width, cam.height);
    let c = channels as usize;
    // Per source: its projection, the pose into it, and its centre in the target's frame.
    let lookups: Vec<(Projector, Pose, DVec3)> = sources
        .iter()
        .zip(t_tgt_src)
        .map(|(s, pose)| (Projector::new(&s.view.camera), pose.inverse(), pose.translation))
        .collect();
    let mut image = Image::new(w, h, channels);
    let mut mask = Image::new(w, h, 1);
    let mut depth = Image::new(w, h, 1);
    // Each row is blended in scratch rows and written out once. Summing into the output
    // itself would read its fresh pages before writing them: each page would first map the
    // shared zero page, then be copied on the write, with a flush of every other processor's
    // TLB (an interrupt to each, costly in a virtual machine), which took most of the time.
    let rows = image.data.par_chunks_mut(w as usize * c).zip(mask.data.par_chunks_mut(w as usize));
    rows.zip(depth.data.par_chunks_mut(w as usize)).enumerate().for_each_init(
        || (vec![None; w as usize], vec![0.0f32; c], vec![0.0f32; w as usize * c], vec![0.0f32; w as usize]),
        |(rays, colour, sum, weight), (y, ((image_row, mask_row), depth_row))| {
            cam.undistort_row(y as u32, rays);
            sum.fill(0.0);
            weight.fill(0.0);
            let zrow = &zbuf[y * w as usize..][..w as usize];
            for (x, (n, &z)) in rays.iter().zip(zrow).enumerate() {
                let Some(n) = n.filter(|_| z.is_finite()) else {
                    continue;
                };
                let p_tgt = DVec3::new(n.x, n.y, 1.0) * z as f64;
                for (source, (projector, t_src_tgt, c_source)) in sources.iter().zip(&lookups) {
                    let p = t_src_tgt.transform_point(p_tgt);
                    let Some(px) = projector.project(p) else {
                        continue;
                    };
                    let agreed = lookup(source, px, p.z as f32, tolerance as f32, colour);
                    if agreed <= 0.0 {
                        continue;
                    }
                    let wt = angle_weight(p_tgt, *c_source) * agreed;
                    for (acc, v) in sum[x * c..][..c].iter_mut().zip(colour.iter()) {
                        *acc += wt * v;
                    }
                    weight[x] += wt;
                }
            }
            // Normalised, with the mask and the depth: every output value written once.
            for (x, &wt) in weight.iter().enumerate() {
                let seen = wt > 0.0;
                for (out, &v) in image_row[x * c..][..c].iter_mut().zip(&sum[x * c..][..c]) {
                    *out = if seen { v / wt } else { 0.0 };
                }
                mask_row[x] = if seen { 1.0 } else { 0.0 };
                depth_row[x] = if seen { zrow[x] } else { 0.0 };
            }
        },
    );
    (image, mask, depth)
}

/// The source's colour at `px`, bilinear over the four pixels around it whose depth is within
/// `tolerance` (relative) of `z`, into `colour`; returns the bilinear weight those pixels
/// carry (0: the source does not see the point).
fn lookup(source: &Source, px: DVec2, z: f32, tolerance: f32, colour: &mut [f32]) -> f32 {
    let (w, h) = (source.depth.width as i64, source.depth.height as i64);
    // `project` keeps both coordinates above −0.5: truncating x + 1 and taking 1 away floors.
    let (x0, y0) = ((px.x + 1.0) as i64 - 1, (px.y + 1.0) as i64 - 1);
    let (fx, fy) = ((px.x - x0 as f64) as f32, (px.y - y0 as f64) as f32);
    let c = colour.len();
    colour.iter_mut().for_each(|v| *v = 0.0);
    let mut total = 0.0;
    for (dx, dy, b) in
        [(0, 0, (1.0 - fx) * (1.0 - fy)), (1, 0, fx * (1.0 - fy)), (0, 1, (1.0 - fx) * fy), (1, 1, fx * fy)]
    {
        let (x, y) = (x0 + dx, y0 + dy);
        if b <= 0.0 || x < 0 || y < 0 || x >= w || y >= h {
            continue;
        }
        let i = (y * w + x) as usize;
        let d = source.depth.data[i];
        if d <= 0.0 || (d - z).abs() > tolerance * z {
            continue;
        }
        for (acc, &v) in colour.iter_mut().zip(&source.image.data[i * c..][..c]) {
            *acc += b * v;
        }
        total += b;
    }
    if total > 0.0 {
        colour.iter_mut().for_each(|v| *v /= total);
    }
    total
}
