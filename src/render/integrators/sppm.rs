//! Stochastic progressive photon mapping (Hachisuka & Jensen 2009; pbrt-v3's
//! `SPPMIntegrator` is the model). Each pass (`spp` passes):
//!
//! 1. Camera: one camera path per pixel follows delta bounces to its first other surface,
//!    the pixel's visible point x (throughput β, direction ωo, its BSDF). Emitters and the
//!    environment reached before x, and direct light at x by one light sample, add to the
//!    pixel's direct sum L_d.
//! 2. Photons: `count` light paths (`particle::walk`), half of them aimed at the scene's
//!    mirrors and glass (`scene::Aim`: the caustic's photons drawn about 19 times as often on
//!    `tests/data/mitsuba/caustic.xml`, unbiased); where one meets a surface that is not a
//!    delta one, after its first segment (direct light is L_d's), every visible point within
//!    its pixel's radius R takes φ += f(x, ωo, ωₚ)·βₚ and M += 1.
//! 3. Each pixel with new photons shrinks its radius and rescales its flux (α, default ⅔):
//!
//!      N' = N + α·M,   R' = R·√(N'/(N + M)),   τ' = (τ + β·φ)·R'²/R².
//!
//! After P passes of `count` photons, L = L_d/P + τ/(P·count·π·R²). The radius shrinks so that
//! the bias (the blur of the kernel) vanishes while the variance falls: the estimate is
//! consistent, which `tests/render_closed_form` checks by its error falling over passes.
//!
//! The initial radius is `radius`, or else one pixel footprint at each pixel's first visible
//! point (the width a pixel covers there, so the first passes blur over about two pixels).
//! Where a pixel gathers many photons per pass its radius shrinks by pass, not by photon
//! (R'²/R² = (N + αM)/(N + M) ≈ 1 − (1 − α)/(α·P) at pass P, once N ≈ α·M·P), so the
//! blur of a caustic's sharp focus falls only with passes: the start is what sets it. With
//! photons aimed at the glass, the variance left room for a smaller start: on the caustic of
//! `tests/data/mitsuba/caustic.xml`, one footprint has 0.3× the error of a start about two
//! wide at equal passes (docs/measurements.md, "Photons aimed at the glass").
//! Visible points are found by the hashed grid of `render::photons` (cells of the largest
//! radius; a photon visits the cells around it and keeps the points within their own radius),
//! or by kiddo's kd-tree with `index = "kdtree"`. The grid is the default: a pass holds about
//! as many points as pixels, and at such sizes (up to a few million) the grid answers radius
//! queries faster than the kd-tree and builds faster, while the kd-tree wins only once the
//! grid's table outgrows the caches (`lumen bench photons`; docs/measurements.md). A
//! photon's contributions are added in path order, so the image does not depend on the
//! thread count. The film's variance is 0: the passes are not independent samples of one
//! estimate, so no variance of the mean follows from them; compare against a reference
//! (the render stage's relMSE) instead. With a time budget, passes run until the next would
//! overrun it.

use super::super::film::Film;
use super::super::geometry::Ray;
use super::super::photons::{Index, IndexKind};
use super::super::sampler::Sampler;
use super::super::scene::{Aim, Scene};

use super::particle::walk;
use super::photon::{direct, first_diffuse, Diffuse};
use super::{camera_path, Settings};
use glam::Vec3A;
use rayon::prelude::*;
use std::f32::consts::PI;

/// Keeps photon paths' random streams apart from camera paths' with the same seed.
const STREAM: u64 = 0x7370_706d_7068_6f74;
/// Photon paths a worker traces at a time.
const CHUNK: u64 = 4096;

/// A pixel's visible point in this pass: its camera path's first surface other than a delta
/// one.
type Visible = Diffuse;

/// A pixel's progressive state.
#[derive(Clone, Copy, Default)]
struct Pixel {
    radius: f32,
    n: f32,
    tau: Vec3A,
    direct: Vec3A,
    phi: Vec3A,
    m: u32,
}

pub fn render(scene: &Scene, settings: &Settings, film: &mut Film) {
    let start = std::time::Instant::now();
    let (fw, fh) = (film.mean.width, film.mean.height);
    let [x0, y0] = film.origin;
    let count = settings.photon.count.unwrap_or(scene.camera.width as u64 * scene.camera.height as u64);
    let mut pixels = vec![
        Pixel { radius: settings.photon.radius.unwrap_or(0.0), ..Default::default() };
        (fw * fh) as usize
    ];
    let aim = Aim::of(scene);
    let bar = super::super::progress_bar(settings.spp as u64, "sppm", settings.progress);
    let mut passes = 0u32;
    while passes < settings.spp {
        let pass = settings.first_sample + passes;
        // 1. Visible points and direct light, pixels in parallel.
        let visible: Vec<Option<Visible>> = pixels
            .par_iter_mut()
            .enumerate()
            .map(|(i, px)| {
                let (x, y) = (x0 + i as u32 % fw, y0 + i as u32 / fw);
                let (mut s, ray) = camera_path(scene, settings, x, y, pass);
                let (direct, vp) =
                    ray.map_or((Vec3A::ZERO, None), |ray| camera(scene, settings, ray, &mut s));
                px.direct += direct;
                if let Some(v) = &vp {
                    if px.radius == 0.0 {
                        px.radius = footprint(scene, v.p);
                    }
                }
                vp
            })
            .collect();
        // 2. Photons against the visible points.
        let (points, owners): (Vec<[f32; 3]>, Vec<u32>) =
            visible.iter().enumerate().filter_map(|(i, v)| v.map(|v| (v.p.to_array(), i as u32))).unzip();
        let r_max = owners.iter().map(|&i| pixels[i as usize].radius).fold(0.0f32, f32::max);
        if let (Some(index), true) =
            (Index::build(settings.photon.index.unwrap_or(IndexKind::Grid), &points, r_max), r_max > 0.0)
        {
            let chunks: Vec<Vec<(u32, Vec3A)>> = (0..count)
                .step_by(CHUNK as usize)
                .collect::<Vec<_>>()
                .into_par_iter()
                .map(|c| {
                    let mut out = Vec::new();
                    for path in c..(c + CHUNK).min(count) {
                        let mut s =
                            Sampler::with_kind(settings.sampler, settings.seed ^ STREAM, path, pass as u64);
                        walk(scene, aim.as_ref(), &mut s, settings.max_depth, |ph, _| {
                            if ph.depth < 2 || ph.mat.bsdf.is_delta() {
                                return;
                            }
                            index.within(ph.p, r_max, |k, d2| {
                                let owner = owners[k as usize];
                                let r = pixels[owner as usize].radius;
                                if d2 <= r * r {
                                    let Some(v) = &visible[owner as usize] else { return };
                                    let f = v.bsdf.eval(v.albedo, v.n, v.wo, ph.w_l);
                                    if f.max_element() > 0.0 {
                                        out.push((owner, f * ph.beta));
                                    }
                                }
                            });
                        });
                    }
                    out
                })
                .collect();
            for (owner, phi) in chunks.into_iter().flatten() {
                let px = &mut pixels[owner as usize];
                px.phi += phi;
                px.m += 1;
            }
        }
        // 3. Radii and fluxes.
        let alpha = settings.photon.alpha;
        for (px, v) in pixels.iter_mut().zip(&visible) {
            if let (Some(v), true) = (v, px.m > 0) {
                let m = px.m as f32;
                let n_new = px.n + alpha * m;
                let r_new = px.radius * (n_new / (px.n + m)).sqrt();
                px.tau = (px.tau + v.beta * px.phi) * (r_new * r_new / (px.radius * px.radius));
                px.n = n_new;
                px.radius = r_new;
            }
            px.phi = Vec3A::ZERO;
            px.m = 0;
        }
        passes += 1;
        bar.inc(1);
        if let Some(budget) = settings.time_budget {
            let elapsed = start.elapsed().as_secs_f64();
            if elapsed * (passes + 1) as f64 / passes as f64 > budget {
                break;
            }
        }
    }
    bar.finish_and_clear();
    let np = passes as f32 * count as f32;
    for (i, px) in pixels.iter().enumerate() {
        let flux = if px.radius > 0.0 { px.tau / (np * PI * px.radius * px.radius) } else { Vec3A::ZERO };
        let l = px.direct / passes.max(1) as f32 + flux;
        let l = if l.is_finite() { l } else { Vec3A::ZERO };
        film.mean.data[3 * i..3 * i + 3].copy_from_slice(&l.to_array());
        film.variance.data[3 * i..3 * i + 3].fill(0.0);
    }
    film.samples = passes;
}

/// The camera path of a pass: (emission and direct light it gathered, the visible point).
fn camera(scene: &Scene, settings: &Settings, ray: Ray, s: &mut Sampler) -> (Vec3A, Option<Visible>) {
    let mut l = Vec3A::ZERO;
    let visible = first_diffuse(scene, settings.max_depth, ray, s, Some(&mut l));
    if let Some(v) = &visible {
        l += v.beta * direct(scene, v, s);
    }
    (l, visible)
}

/// One pixel footprint at `p`: the width one pixel covers at p's distance from the camera
/// (the focal length in pixels gives a pixel's angle).
fn footprint(scene: &Scene, p: Vec3A) -> f32 {
    let eye = Vec3A::from(scene.t_world_cam.translation.as_vec3());
    let f = scene.camera.intrinsics.fx.min(scene.camera.intrinsics.fy) as f32;
    (p.distance(eye) / f).max(1e-6 * scene.bounds_radius)
}
