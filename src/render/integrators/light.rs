//! Light tracing (Mitsuba 3's `ptracer`, Veach 1997 §10.2): paths start at the lights, and
//! every vertex they reach is joined to the camera and splatted into the film.
//!
//! A ray leaves a light with flux weight β (`Scene::sample_emission`). At each surface point x
//! it reaches, with the light arriving from w_l, the camera link (`camera_ray::link_point`:
//! an aperture point, the direction w_c to it at distance r, the pixel position and the
//! camera's importance W) adds
//!
//!   β · f(x, w_c, w_l) · |cos θ_c| / r² · W
//!
//! to the pixels whose filter covers that position (`filter::splat`), if nothing blocks the
//! link; f is evaluated as the path tracer evaluates it, with w_c as the outgoing direction.
//! The path then scatters as light does (`particle::walk`).
//!
//! Emitters seen directly (one segment) take their own samples per path: a point uniform on
//! an area light picked by power, joined to the camera, as in Mitsuba; and, where the scene
//! has an environment, a camera ray from a position uniform over the image, which adds
//! L·W·H where it escapes. (Mitsuba draws the environment's direction by its own density
//! instead, which leaves a dim sky seen beside a bright sun with a rare, heavy-tailed
//! estimate.) Point, spot and directional lights are never seen directly (as with camera
//! paths). A mirror or smooth glass seen by the camera shows
//! nothing: no link can pass through a delta BSDF. Depth counts segments as the path tracer
//! does (a vertex k segments from the light is splatted when k + 1 ≤ max_depth), and Russian
//! roulette starts at the same depth with the same rule.
//!
//! Passes: a pass traces as many light paths as the image has pixels (Mitsuba's
//! `samples_per_pass` convention: `spp` passes trace spp·W·H paths) and is an unbiased
//! estimate of the whole image; the film's mean is the mean of the passes. The passes are
//! summed in up to 64 batches of n_b passes each, and the variance of the mean is
//! σ²/N with σ² = Σ n_b·(X_b − m)²/(B − 1) from the batches' estimates X_b (0 with one
//! pass): one sum of a pixel's batch per batch, not per pass, which for a small image and many
//! passes would cost as much as the paths. Paths are drawn from streams keyed by (path,
//! pass), traced in parallel in fixed chunks whose splats are added in path order, so the
//! image does not depend on the thread count, and a crop holds exactly the full image's
//! pixels. Media are not supported (`Kind::media`).

use super::super::camera_ray::{camera_ray, link_point, needs_lens_sample};
use super::super::film::{Film, PixelSums};
use super::super::filter;
use super::super::sampler::Sampler;
use super::super::scene::{Light, Scene};
use super::super::transport::epsilon;
use super::particle::{shading, walk};
use super::Settings;
use glam::{DVec2, Vec3A};
use rayon::prelude::*;

/// Paths a worker traces before its splats are handed back.
const CHUNK: u64 = 1024;
/// Paths traced before their splats are added to the pass: bounds the splats held at once.
const GROUP: u64 = 64 * CHUNK;
/// Passes are summed in at most this many batches, whose spread gives the variance.
const BATCHES: u64 = 64;
/// Keeps light paths' random streams apart from camera paths' with the same seed.
const STREAM: u64 = 0x6c69_6768_7470_7468;

/// One contribution to one film pixel (index into the film's pixels).
type Splat = (u32, [f32; 3]);

pub fn render(scene: &Scene, settings: &Settings, film: &mut Film) {
    splat_passes(scene, settings, film, false, |path, pass, _, splat| {
        trace(scene, settings, path, pass, splat);
        Vec3A::ZERO
    });
}

/// Fills the film with `spp` passes of one light path per image pixel, `trace(path, pass,
/// pixel, splat)` splatting each path's contributions (module docs: batches, variance, order).
///
/// With `camera_samples` (bidirectional path tracing), light path p of a pass also takes that
/// pass's camera sample of image pixel p = y·W + x, where (x, y) is in the film: `trace` gets
/// `Some([x, y])` and returns the sample's value, and the film is the sum of the splats' mean
/// and the camera samples' per-pixel mean (`film::PixelSums`, the samples taken in pass
/// order), its variance the sum of theirs. Each light path is then traced once for both.
pub fn splat_passes(
    scene: &Scene,
    settings: &Settings,
    film: &mut Film,
    camera_samples: bool,
    trace: impl Fn(u64, u64, Option<[u32; 2]>, &mut dyn FnMut(DVec2, Vec3A)) -> Vec3A + Sync,
) {
    let width = scene.camera.width as u64;
    let paths = width * scene.camera.height as u64;
    let (origin, size) = film_window(film);
    let pixels = film.mean.width as usize * film.mean.height as usize;
    let spp = settings.spp as u64;
    let per_batch = spp.div_ceil(BATCHES);
    // Per pixel channel: the sum of every splat, and Σ n_b·X_b² over the batches, X_b the
    // batch's estimate of the pixel (n_b passes).
    let mut sum = vec![0.0f64; 3 * pixels];
    let mut sum_sq = vec![0.0f64; 3 * pixels];
    let mut batch = vec![0.0f64; 3 * pixels];
    // The camera samples' sums per pixel.
    let mut camera = camera_samples.then(|| vec![PixelSums::default(); pixels]);
    // The film pixel (x, y, index) of light path `path`, where it takes a camera sample.
    let film_pixel = |path: u64| {
        let (x, y) = ((path % width) as u32, (path / width) as u32);
        let (fx, fy) = (x.checked_sub(origin[0])?, y.checked_sub(origin[1])?);
        (camera_samples && fx < size[0] && fy < size[1]).then_some(([x, y], fy * size[0] + fx))
    };
    let label = if camera_samples { "bdpt" } else { "light" };
    let bar = super::super::progress_bar(spp, label, settings.progress);
    let mut dropped = 0;
    let mut batches = 0u64;
    for first in (0..spp).step_by(per_batch as usize) {
        let passes = per_batch.min(spp - first);
        batch.iter_mut().for_each(|v| *v = 0.0);
        // Path g of the batch is path g mod (W·H) of pass first + g / (W·H).
        let total = passes * paths;
        for start in (0..total).step_by(GROUP as usize) {
            let end = (start + GROUP).min(total);
            let chunks: Vec<(Vec<Splat>, Vec<(u32, Vec3A)>, u64)> = (start..end)
                .step_by(CHUNK as usize)
                .collect::<Vec<_>>()
                .into_par_iter()
                .map(|c| {
                    let mut out = Vec::with_capacity(4 * CHUNK as usize);
                    let mut samples = Vec::new();
                    let mut lost = 0;
                    for g in c..(c + CHUNK).min(end) {
                        let (pass, path) = (settings.first_sample as u64 + first + g / paths, g % paths);
                        let pixel = film_pixel(path);
                        let l = trace(path, pass, pixel.map(|p| p.0), &mut |px, v| {
                            splat(scene, (origin, size), px, v, &mut out, &mut lost)
                        });
                        if let Some((_, i)) = pixel {
                            samples.push((i, l));
                        }
                    }
                    (out, samples, lost)
                })
                .collect();
            for (splats, samples, lost) in chunks {
                dropped += lost;
                for (i, v) in splats {
                    for c in 0..3 {
                        batch[3 * i as usize + c] += v[c] as f64;
                    }
                }
                if let Some(camera) = camera.as_mut() {
                    dropped += samples.iter().filter(|&&(i, l)| !camera[i as usize].add(l)).count() as u64;
                }
            }
            bar.set_position(first + end / paths);
        }
        let n_b = passes as f64;
        for ((s, s2), b) in sum.iter_mut().zip(sum_sq.iter_mut()).zip(&batch) {
            let x = b / (n_b * paths as f64);
            *s += b;
            *s2 += n_b * x * x;
        }
        batches += 1;
    }
    bar.finish_and_clear();
    // The passes' variance σ² from the batches, Σ n_b·(X_b − m)² / (B − 1), and that of the
    // mean of N passes, σ²/N.
    let n = spp as f64;
    for i in 0..3 * pixels {
        let m = sum[i] / (n * paths as f64);
        film.mean.data[i] = m as f32;
        film.variance.data[i] = if batches > 1 {
            ((sum_sq[i] - n * m * m).max(0.0) / (batches - 1) as f64 / n) as f32
        } else {
            0.0
        };
    }
    if let Some(camera) = camera {
        for (i, sums) in camera.iter().enumerate() {
            let (mean, var) = sums.stats();
            for c in 0..3 {
                film.mean.data[3 * i + c] += mean[c];
                film.variance.data[3 * i + c] += var[c];
            }
        }
    }
    film.dropped_samples += dropped;
}

/// The film's window in the image: origin and size.
fn film_window(film: &Film) -> ([u32; 2], [u32; 2]) {
    (film.origin, [film.mean.width, film.mean.height])
}

/// Adds `v` at the image position `px` to the film pixels the filter covers; a value that is
/// not finite is dropped and counted.
fn splat(
    scene: &Scene,
    (origin, size): ([u32; 2], [u32; 2]),
    px: DVec2,
    v: Vec3A,
    out: &mut Vec<Splat>,
    lost: &mut u64,
) {
    if !v.is_finite() {
        *lost += 1;
        return;
    }
    let f = scene.render.filter;
    let (mut xs, mut ys) = ([(0, 0.0); 5], [(0, 0.0); 5]);
    let nx = filter::splat(f, px.x, scene.camera.width, &mut xs);
    let ny = filter::splat(f, px.y, scene.camera.height, &mut ys);
    for &(y, wy) in &ys[..ny] {
        let Some(fy) = y.checked_sub(origin[1]).filter(|&r| r < size[1]) else { continue };
        for &(x, wx) in &xs[..nx] {
            let Some(fx) = x.checked_sub(origin[0]).filter(|&c| c < size[0]) else { continue };
            let w = (wx * wy) as f32;
            out.push((fy * size[0] + fx, [v.x * w, v.y * w, v.z * w]));
        }
    }
}

/// Light path `path` of pass `pass`: every contribution it makes, as (image position, value).
fn trace(scene: &Scene, settings: &Settings, path: u64, pass: u64, splat: &mut dyn FnMut(DVec2, Vec3A)) {
    let mut s = Sampler::with_kind(settings.sampler, settings.seed ^ STREAM, path, pass);
    seen_directly(scene, &mut s, splat);
    walk(scene, None, &mut s, settings.max_depth, |v, s| {
        let Some(link) = link_point(scene, v.p, s.next2()) else { return };
        let towards = v.n.dot(link.dir) >= 0.0;
        if !towards && v.mat.one_sided {
            return;
        }
        let bsdf = shading(scene, v.mat, &v.hit, v.p, towards);
        let n = if towards { v.n } else { -v.n };
        let f = if bsdf.is_delta() { Vec3A::ZERO } else { bsdf.eval(v.albedo, n, link.dir, v.w_l) };
        if f.max_element() > 0.0 && scene.unoccluded(v.p + n * epsilon(v.p), v.p, link.dir, link.dist) {
            let g = n.dot(link.dir).abs() * link.importance / (link.dist * link.dist);
            splat(link.pixel, v.beta * f * g);
        }
    });
}

/// The emitters the camera sees directly (module docs): a point of an area light picked by
/// power, joined to the camera; and the environment through a camera ray from a position
/// uniform over the image.
fn seen_directly(scene: &Scene, s: &mut Sampler, splat: &mut dyn FnMut(DVec2, Vec3A)) {
    let (u_pick, u, u_lens) = (s.next(), s.next2(), s.next2());
    if let Some((i, p_pick, _)) = scene.pick_light(u_pick) {
        if let Light::Area { prim, radiance, area } = scene.lights[i] {
            let (y, ny) = scene.area_light_point(prim, u);
            if let Some(link) = link_point(scene, y, u_lens) {
                let cos = ny.dot(link.dir);
                if cos > 0.0 && scene.unoccluded(y + ny * epsilon(y), y, link.dir, link.dist) {
                    let g = cos * link.importance / (link.dist * link.dist);
                    splat(link.pixel, radiance * (g * area / p_pick));
                }
            }
        }
    }
    if scene.environment_light.is_some() {
        let (u, u_lens) = (s.next2(), s.next2());
        let (w, h) = (scene.camera.width as f64, scene.camera.height as f64);
        let px = DVec2::new(u.0 as f64 * w - 0.5, u.1 as f64 * h - 0.5);
        let Some(d) = scene.camera.pixel_ray(px) else { return };
        let ray = camera_ray(scene, d, needs_lens_sample(scene, d).then_some(u_lens));
        if scene.unoccluded(ray.origin, ray.origin, ray.dir, f32::INFINITY) {
            if let Some((le, _)) = scene.environment(ray.dir) {
                splat(px, le * (w * h) as f32);
            }
        }
    }
}
