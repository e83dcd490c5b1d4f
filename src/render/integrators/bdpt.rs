//! Bidirectional path tracing (Veach 1997, ch. 10; pbrt-v3's `BDPTIntegrator` is the model):
//! every sample traces a camera subpath z₀ … and a light subpath y₀ …, and joins every prefix
//! of one to every prefix of the other. A path of s light and t camera vertices is found by
//! the strategy (s, t):
//!
//! - s = 0: the camera subpath reaches an emitter (what the path tracer counts by BSDF
//!   sampling);
//! - s = 1: a point drawn on a light, picked by power, joined to z_{t−1} (light sampling);
//! - t = 1: y_{s−1} joined to a point drawn on the aperture and splatted where it lands on the
//!   image (light tracing, `integrators::light`), for s ≥ 2: a light seen directly is the
//!   camera's to find (s = 0, t = 2, weight 1, as in pbrt);
//! - otherwise y_{s−1} and z_{t−1} joined by a shadow ray.
//!
//! Each contribution is weighted by the power heuristic (β = 2) over every strategy that could
//! have made the same path (Veach's multiple importance sampling): the vertices keep the area
//! densities with which each subpath drew them forwards and would have drawn them backwards,
//! and the weight is 1/(1 + Σ rᵢ²), rᵢ the ratio of another strategy's density to this one's,
//! computed from them (pbrt-v3's `MISWeight` sums rᵢ, the balance heuristic; a delta density
//! counts as 1 in the ratios, and strategies that would join at a delta vertex, or need to hit
//! a point light, count none). The power heuristic, which Veach recommends (1997, §9.2.4),
//! takes less weight from a strategy that draws the path rarely: a camera path that
//! reaches a small light through glass keeps a share of a caustic under the balance heuristic
//! and brings it as rare, bright samples (docs/measurements.md, "Bidirectional path tracing as
//! it is now").
//! The camera's density of a direction is its importance W (`camera_ray`) over the image's
//! pixel count, since one light path per camera sample spreads over the whole image; so the
//! strategies t = 1 (one light path per pixel per pass, `light::splat_passes`) and t ≥ 2 (the
//! camera samples of each pixel) are weighed against each other as they are drawn. Delta
//! BSDFs and delta lights are the vertices' `delta` flags; the thin lens is the aperture point
//! the camera vertex sits on. Light subpaths scatter as `particle` scatters (the adjoint
//! weight across dielectrics); Russian roulette ends both subpaths as it ends camera paths,
//! which changes the densities the weights see by the survival probabilities only (the
//! weights of a path still sum to one, so the estimate stays unbiased).
//!
//! Light path p of pass k (`light::splat_passes`) is traced once and serves both: its splats
//! (t = 1), and the strategies t ≥ 2 of sample k of image pixel p, whose camera subpath is
//! traced beside it. The film is the sum of the camera samples' mean and the splats' mean,
//! its variance the sum of their variances (the covariance of the two, through the shared
//! light subpaths, is left out).
//!
//! Lights at infinity (environment, directional) are vertices at infinity, as in pbrt-v3: such
//! a vertex keeps a direction, not a point (`Vertex::far`, its `n` the direction light travels
//! in). A light subpath leaves one from a point on the disk facing it (`sample_emission`), so
//! its first surface is drawn with the disk's area density times the cosine there; a camera
//! subpath that leaves the scene ends on the environment's vertex; the densities of and
//! towards such a vertex stay in solid angle. A directional light is a delta in direction: no
//! camera subpath reaches it, as none reaches a point light.
//! Participating media are refused (`Kind::media`).

use super::super::bsdf::Bsdf;
use super::super::camera_ray::{importance, link_point};
use super::super::film::{Film, RR_START};
use super::super::geometry::{Hit, Ray};
use super::super::sampler::Sampler;
use super::super::scene::{spot_falloff, Light, Scene};
use super::super::transport::{self, epsilon};
use super::particle::{adjoint, shading};
use super::{camera_path, Settings};
use glam::Vec3A;

thread_local! {
    /// The camera and light subpaths' vertices, kept from sample to sample on each thread (an
    /// allocation per subpath cost a tenth of the time).
    static PATHS: std::cell::RefCell<(Vec<Vertex>, Vec<Vertex>)> =
        const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
}

/// Keeps the light subpaths' random streams apart from camera paths' with the same seed.
const STREAM: u64 = 0x6264_7074_6c69_6768;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Role {
    Camera,
    /// A light's own point (index in `Scene::lights`).
    Light(usize),
    Surface,
}

/// A subpath vertex.
#[derive(Clone, Copy, Debug)]
struct Vertex {
    role: Role,
    p: Vec3A,
    /// The geometric normal; zero for a point (a pinhole, a point or spot light).
    n: Vec3A,
    /// The subpath's throughput arriving here.
    beta: Vec3A,
    /// A surface's: a delta BSDF lobe was drawn here; a light's: no camera subpath can reach
    /// it (a point or spot light, a delta in position; a directional light, in direction).
    delta: bool,
    /// A light at infinity (environment, directional): `n` is the direction its light travels
    /// in, and `p` means nothing.
    far: bool,
    /// Area densities of this vertex: drawn from the subpath's previous vertex, and as the
    /// other subpath would draw it.
    pdf_fwd: f32,
    pdf_rev: f32,
    hit: Hit,
    material: u32,
    albedo: Vec3A,
}

impl Vertex {
    fn point(role: Role, p: Vec3A, n: Vec3A) -> Vertex {
        Vertex {
            role,
            p,
            n,
            beta: Vec3A::ONE,
            delta: false,
            far: false,
            pdf_fwd: 0.0,
            pdf_rev: 0.0,
            hit: Hit { t: 0.0, prim: 0, b1: 0.0, b2: 0.0 },
            material: 0,
            albedo: Vec3A::ZERO,
        }
    }

    /// The vertex at infinity of light `light`, whose light travels along `travel`.
    fn far(scene: &Scene, light: usize, travel: Vec3A) -> Vertex {
        let p = scene.bounds_center - travel * (2.0 * scene.bounds_radius);
        let mut v = Vertex::point(Role::Light(light), p, travel);
        v.far = true;
        v.delta = matches!(scene.lights[light], Light::Directional { .. });
        v
    }
}

/// The unit direction from `from` towards `to`, either of them possibly at infinity.
fn toward(from: &Vertex, to: &Vertex) -> Vec3A {
    if to.far {
        -to.n
    } else if from.far {
        from.n
    } else {
        (to.p - from.p).normalize()
    }
}

pub fn render(scene: &Scene, settings: &Settings, film: &mut Film) {
    super::light::splat_passes(scene, settings, film, true, |path, pass, pixel, splat| {
        PATHS.with_borrow_mut(|(camera, light)| {
            let mut ls = Sampler::with_kind(settings.sampler, settings.seed ^ STREAM, path, pass);
            light_subpath(scene, settings, &mut ls, light);
            // The strategies t = 1, splatted. s = 1, t = 1 (a light's point seen directly) is
            // left to the camera sample's s = 0, as in pbrt: the weight of a two-vertex path is 1.
            for s in 2..=light.len() {
                if s as u32 > settings.max_depth {
                    break;
                }
                let qs = &light[s - 1];
                if is_delta_bsdf(scene, qs) || (qs.role != Role::Surface && qs.delta) {
                    continue;
                }
                let Some(link) = link_point(scene, qs.p, ls.next2()) else { continue };
                let to_cam = link.dir;
                let value = qs.beta * f(scene, qs, to_cam, toward(qs, &light[s - 2]));
                if value.max_element() <= 0.0 {
                    continue;
                }
                let cos = if qs.n == Vec3A::ZERO { 1.0 } else { qs.n.dot(to_cam).abs() };
                let side = if qs.n.dot(to_cam) >= 0.0 { qs.n } else { -qs.n };
                if !scene.unoccluded(qs.p + side * epsilon(qs.p), qs.p, to_cam, link.dist) {
                    continue;
                }
                let camera_vertex = Vertex::point(Role::Camera, link.aperture, Vec3A::ZERO);
                let w = mis(scene, &[camera_vertex], &light[..s], 1, Some(&camera_vertex), None);
                splat(link.pixel, value * (cos * link.importance / (link.dist * link.dist) * w));
            }
            // The strategies t ≥ 2: the camera sample of this pass at the path's own pixel.
            let Some([x, y]) = pixel else { return Vec3A::ZERO };
            let (mut s, ray) =
                camera_path(scene, settings, x, y, (pass - settings.first_sample as u64) as u32);
            let Some(ray) = ray else { return Vec3A::ZERO };
            camera_subpath(scene, settings, ray, &mut s, camera);
            camera_strategies(scene, settings, camera, light, &mut s)
        })
    });
}

/// The strategies with t ≥ 2 for one camera sample: their weighted sum.
fn camera_strategies(
    scene: &Scene,
    settings: &Settings,
    z: &[Vertex],
    y: &[Vertex],
    s_: &mut Sampler,
) -> Vec3A {
    let mut l = Vec3A::ZERO;
    for t in 2..=z.len() {
        for s in 0..=y.len() {
            let segments = s + t - 1;
            if segments as u32 > settings.max_depth {
                break;
            }
            let pt = &z[t - 1];
            // A camera subpath that left the scene is joined to nothing.
            if pt.far && s > 0 {
                break;
            }
            let wo = toward(pt, &z[t - 2]);
            match s {
                0 => {
                    let le = emitted(scene, pt, wo);
                    if le.max_element() > 0.0 {
                        l += pt.beta * le * mis(scene, z, &y[..0], t, None, None);
                    }
                }
                1 => {
                    if is_delta_bsdf(scene, pt) {
                        continue;
                    }
                    let Some((light, pdf)) = sample_light_vertex(scene, s_.next(), s_.next2()) else {
                        continue;
                    };
                    let (wi, dist, g_light) = if light.far {
                        (-light.n, f32::INFINITY, 1.0)
                    } else {
                        let d = light.p - pt.p;
                        let dist = d.length();
                        let wi = d / dist;
                        let cos = if light.n == Vec3A::ZERO { 1.0 } else { light.n.dot(wi).abs() };
                        (wi, dist, cos / (dist * dist))
                    };
                    let le = emitted(scene, &light, -wi);
                    let fz = f(scene, pt, wo, wi);
                    if le.max_element() <= 0.0 || fz.max_element() <= 0.0 {
                        continue;
                    }
                    let g = pt.n.dot(wi).abs() * g_light;
                    let side = if pt.n.dot(wi) >= 0.0 { pt.n } else { -pt.n };
                    if !scene.unoccluded(pt.p + side * epsilon(pt.p), pt.p, wi, dist) {
                        continue;
                    }
                    let w = mis(scene, z, &[light], t, None, Some(&light));
                    l += pt.beta * fz * le * (g / pdf * w);
                }
                _ => {
                    let qs = &y[s - 1];
                    if is_delta_bsdf(scene, pt) || is_delta_bsdf(scene, qs) {
                        continue;
                    }
                    let d = pt.p - qs.p;
                    let dist = d.length();
                    let w_to_pt = d / dist;
                    let fq = f(scene, qs, w_to_pt, toward(qs, &y[s - 2]));
                    let fz = f(scene, pt, wo, -w_to_pt);
                    if fq.max_element() <= 0.0 || fz.max_element() <= 0.0 {
                        continue;
                    }
                    let g = qs.n.dot(w_to_pt).abs() * pt.n.dot(w_to_pt).abs() / (dist * dist);
                    let side = if qs.n.dot(w_to_pt) >= 0.0 { qs.n } else { -qs.n };
                    if !scene.unoccluded(qs.p + side * epsilon(qs.p), qs.p, w_to_pt, dist) {
                        continue;
                    }
                    l += qs.beta * fq * fz * pt.beta * (g * mis(scene, z, &y[..s], t, None, None));
                }
            }
        }
    }
    l
}

/// The camera subpath of a camera ray: the aperture point, then up to `max_depth` surfaces.
/// into `path`.
fn camera_subpath(scene: &Scene, settings: &Settings, ray: Ray, s: &mut Sampler, path: &mut Vec<Vertex>) {
    path.clear();
    path.push(Vertex::point(Role::Camera, ray.origin, Vec3A::ZERO));
    let pdf_dir = camera_pdf(scene, ray.origin, ray.origin + ray.dir);
    extend(scene, ray, Vec3A::ONE, pdf_dir, false, s, path, settings.max_depth as usize + 1);
}

/// The light subpath: a light's point, then up to `max_depth − 1` surfaces,
/// into `path` (empty where no light emits).
fn light_subpath(scene: &Scene, settings: &Settings, s: &mut Sampler, path: &mut Vec<Vertex>) {
    path.clear();
    let (u_pick, u_pos, u_dir) = (s.next(), s.next2(), s.next2());
    let Some(e) = scene.sample_emission(u_pick, u_pos, u_dir) else { return };
    let (pdf_pos, pdf_dir) = scene.emission_pdf(e.light, e.n, e.ray.dir);
    let far = matches!(scene.lights[e.light], Light::Directional { .. } | Light::Environment { .. });
    let (v, pdf_next) = if far {
        // Its direction is the vertex's density; the disk's point is the next vertex's.
        (far_light(scene, e.light, e.ray.dir).0, pdf_pos)
    } else {
        let mut v = Vertex::point(Role::Light(e.light), e.p, e.n);
        v.delta = matches!(scene.lights[e.light], Light::Point { .. } | Light::Spot { .. });
        v.pdf_fwd = scene.pick_probability(e.light) * pdf_pos;
        (v, pdf_dir)
    };
    path.push(v);
    extend(scene, e.ray, e.beta, pdf_next, true, s, path, settings.max_depth as usize);
}

/// A random walk from `path`'s last vertex along `ray` (drawn with solid-angle density
/// `pdf_dir`; from a light at infinity, the area density of the ray's origin across it),
/// pushing the surfaces it meets, each with its densities (module docs). A camera walk that
/// leaves a scene with an environment ends on its vertex at infinity.
#[allow(clippy::too_many_arguments)]
fn extend(
    scene: &Scene,
    mut ray: Ray,
    mut beta: Vec3A,
    mut pdf_dir: f32,
    light: bool,
    s: &mut Sampler,
    path: &mut Vec<Vertex>,
    max_vertices: usize,
) {
    while path.len() < max_vertices {
        let Some(hit) = scene.bvh.intersect(&ray, 0.0, f32::INFINITY) else {
            if let (false, Some(i)) = (light, scene.environment_light) {
                let mut v = Vertex::far(scene, i, -ray.dir);
                v.beta = beta;
                v.pdf_fwd = pdf_dir;
                path.push(v);
            }
            break;
        };
        let surf = scene.surface(&ray, &hit);
        let mat = &scene.materials[surf.material as usize];
        let prev = path.len() - 1;
        let mut v = Vertex::point(Role::Surface, surf.p, surf.n);
        v.beta = beta;
        v.hit = hit;
        v.material = surf.material;
        v.albedo = scene.albedo(surf.material, &hit, surf.p);
        v.pdf_fwd = to_area(pdf_dir, &path[prev], &v);
        path.push(v);
        if path.len() >= max_vertices {
            break;
        }
        let w_prev = -ray.dir;
        let front = surf.n.dot(w_prev) >= 0.0;
        if !front && mat.one_sided {
            break;
        }
        let n = if front { surf.n } else { -surf.n };
        let bsdf = shading(scene, mat, &hit, surf.p, front);
        let (u1, u2) = s.next2();
        let u3 = if bsdf.needs_third_number() { s.next() } else { 0.0 };
        let Some(b) = bsdf.sample(v.albedo, n, w_prev, u1, u2, u3) else { break };
        let (fwd, rev) = if b.delta {
            (0.0, 0.0)
        } else {
            (bsdf.pdf(v.albedo, n, w_prev, b.wi), pdf_dir_at(scene, &v, b.wi, w_prev))
        };
        beta *= b.weight * if light { adjoint(&bsdf, n, b.wi) } else { 1.0 };
        let last = path.len() - 1;
        path[last].delta = b.delta;
        path[prev].pdf_rev = to_area(rev, &path[last], &path[prev]);
        if last as u32 >= RR_START {
            let (killed, survivor) = transport::roulette(beta, s.next());
            if killed {
                break;
            }
            beta = survivor;
        }
        if !(beta.max_element() > 0.0) {
            break;
        }
        pdf_dir = fwd;
        ray = Ray { origin: transport::offset(surf.p, n, b.wi, epsilon(surf.p)), dir: b.wi };
    }
}

/// A point drawn on a light picked by power, as the vertex y₀ of the strategy s = 1, and the
/// area density it was drawn with (the pick's included; for a light at infinity, its
/// direction's solid-angle density, 1 for a directional light's single direction).
fn sample_light_vertex(scene: &Scene, u_pick: f32, u: (f32, f32)) -> Option<(Vertex, f32)> {
    let (i, p_pick, _) = scene.pick_light(u_pick)?;
    let (p, n, pdf_pos, delta) = match scene.lights[i] {
        Light::Area { prim, area, .. } => {
            let (p, n) = scene.area_light_point(prim, u);
            (p, n, 1.0 / area, false)
        }
        Light::Point { position, .. } | Light::Spot { position, .. } => (position, Vec3A::ZERO, 1.0, true),
        Light::Directional { to_light, .. } => return Some(far_light(scene, i, -to_light)),
        Light::Environment { .. } => return Some(far_light(scene, i, -scene.sample_environment(u)?.0)),
    };
    let mut v = Vertex::point(Role::Light(i), p, n);
    v.delta = delta;
    v.pdf_fwd = p_pick * pdf_pos;
    Some((v, p_pick * pdf_pos))
}

/// The light vertex at infinity of light `i` whose light travels along `travel`, as a light
/// subpath starts there: with its direction's density (`pdf_light_origin`), also returned.
fn far_light(scene: &Scene, i: usize, travel: Vec3A) -> (Vertex, f32) {
    let v = Vertex::far(scene, i, travel);
    let pdf = pdf_light_origin(scene, &v);
    (Vertex { pdf_fwd: pdf, ..v }, pdf)
}

/// Radiance (intensity, for a point or spot light; irradiance, for a directional light)
/// leaving the light or emitter at `v` along `dir`.
fn emitted(scene: &Scene, v: &Vertex, dir: Vec3A) -> Vec3A {
    match v.role {
        Role::Light(i) => match scene.lights[i] {
            Light::Environment { .. } => scene.environment(-v.n).map_or(Vec3A::ZERO, |(le, _)| le),
            Light::Directional { irradiance, .. } => irradiance,
            Light::Area { radiance, .. } if v.n.dot(dir) > 0.0 => radiance,
            Light::Point { intensity, .. } => intensity,
            Light::Spot { axis, intensity, cutoff, beam, .. } => {
                intensity * spot_falloff(axis.dot(dir).clamp(-1.0, 1.0).acos(), cutoff, beam)
            }
            _ => Vec3A::ZERO,
        },
        Role::Surface => match scene.materials[v.material as usize].emission {
            Some(le) if v.n.dot(dir) > 0.0 => le,
            _ => Vec3A::ZERO,
        },
        Role::Camera => Vec3A::ZERO,
    }
}

/// The light an emitter surface vertex belongs to.
fn light_of(scene: &Scene, v: &Vertex) -> Option<usize> {
    match v.role {
        Role::Light(i) => Some(i),
        Role::Surface => {
            let i = *scene.light_of_prim.get(v.hit.prim as usize)?;
            (i != u32::MAX).then_some(i as usize)
        }
        Role::Camera => None,
    }
}

fn is_delta_bsdf(scene: &Scene, v: &Vertex) -> bool {
    v.role == Role::Surface && scene.materials[v.material as usize].bsdf.is_delta()
}

/// f at the surface vertex `v` for light arriving from `wi` and leaving along `wo` (radiance
/// convention, as the path tracer evaluates it).
fn f(scene: &Scene, v: &Vertex, wo: Vec3A, wi: Vec3A) -> Vec3A {
    let mat = &scene.materials[v.material as usize];
    let front = v.n.dot(wo) >= 0.0;
    if !front && mat.one_sided {
        return Vec3A::ZERO;
    }
    let bsdf: Bsdf = shading(scene, mat, &v.hit, v.p, front);
    bsdf.eval(v.albedo, if front { v.n } else { -v.n }, wo, wi)
}

/// The solid-angle density with which the surface vertex `v`'s BSDF, reached from `w_from`,
/// draws `w_to`.
fn pdf_dir_at(scene: &Scene, v: &Vertex, w_from: Vec3A, w_to: Vec3A) -> f32 {
    let mat = &scene.materials[v.material as usize];
    let front = v.n.dot(w_from) >= 0.0;
    if !front && mat.one_sided {
        return 0.0;
    }
    let bsdf = shading(scene, mat, &v.hit, v.p, front);
    bsdf.pdf(v.albedo, if front { v.n } else { -v.n }, w_from, w_to)
}

/// A solid-angle density at `from` as an area density at `to`; towards a vertex at infinity it
/// stays a solid-angle density, and from one (then an area density across the light's
/// direction) it takes the cosine at `to` only.
fn to_area(pdf_dir: f32, from: &Vertex, to: &Vertex) -> f32 {
    if to.far {
        return pdf_dir;
    }
    if from.far {
        return pdf_dir * if to.n == Vec3A::ZERO { 1.0 } else { to.n.dot(from.n).abs() };
    }
    let d = to.p - from.p;
    let d2 = d.length_squared();
    if !(d2 > 0.0) {
        return 0.0;
    }
    let cos = if to.n == Vec3A::ZERO { 1.0 } else { to.n.dot(d).abs() / d2.sqrt() };
    pdf_dir * cos / d2
}

/// The camera's solid-angle density of the ray from the aperture point towards `p`: its
/// importance over the image's pixel count (module docs).
fn camera_pdf(scene: &Scene, aperture: Vec3A, p: Vec3A) -> f32 {
    importance(scene, aperture, p)
        .map_or(0.0, |(_, w)| w / (scene.camera.width as f32 * scene.camera.height as f32))
}

/// The area density with which `v` draws `next`, `prev` the vertex before it on its own
/// subpath (none at an endpoint).
fn pdf(scene: &Scene, v: &Vertex, prev: Option<&Vertex>, next: &Vertex) -> f32 {
    match (v.role, prev) {
        (Role::Camera, _) => to_area(camera_pdf(scene, v.p, v.p + toward(v, next)), v, next),
        (Role::Light(_), _) | (Role::Surface, None) => pdf_light(scene, v, next),
        (Role::Surface, Some(prev)) => {
            let (a, b) = (toward(v, prev), toward(v, next));
            to_area(pdf_dir_at(scene, v, a, b), v, next)
        }
    }
}

/// The area density with which the light at `v` emits towards `next` (from a light at
/// infinity: the density of the disk point its ray leaves, across its direction).
fn pdf_light(scene: &Scene, v: &Vertex, next: &Vertex) -> f32 {
    let Some(i) = light_of(scene, v) else { return 0.0 };
    let (pdf_pos, pdf_dir) = scene.emission_pdf(i, v.n, toward(v, next));
    to_area(if v.far { pdf_pos } else { pdf_dir }, v, next)
}

/// The area density with which light subpaths start at `v` (the pick's included; for a light
/// at infinity, the solid-angle density of its direction).
fn pdf_light_origin(scene: &Scene, v: &Vertex) -> f32 {
    let Some(i) = light_of(scene, v) else { return 0.0 };
    let p_pick = scene.pick_probability(i);
    match scene.lights[i] {
        Light::Environment { .. } => scene.environment(-v.n).map_or(0.0, |(_, pdf)| pdf),
        Light::Directional { .. } => p_pick,
        _ => p_pick * scene.emission_pdf(i, v.n, v.n).0,
    }
}

/// The power-heuristic weight of the strategy (s = y.len(), t) for the path z[..t] + y
/// (module docs); `camera` replaces z₀ for t = 1, `light` replaces y₀ for s = 1.
fn mis(
    scene: &Scene,
    z: &[Vertex],
    y: &[Vertex],
    t: usize,
    camera: Option<&Vertex>,
    light: Option<&Vertex>,
) -> f32 {
    let s = y.len();
    if s + t == 2 {
        return 1.0;
    }
    let zv = |i: usize| if i == 0 { camera.unwrap_or(&z[0]) } else { &z[i] };
    let yv = |i: usize| if i == 0 { light.unwrap_or(&y[0]) } else { &y[i] };
    let pt = zv(t - 1);
    let qs = (s > 0).then(|| yv(s - 1));
    let ptm = (t > 1).then(|| zv(t - 2));
    let qsm = (s > 1).then(|| yv(s - 2));
    // The densities the join changes.
    let pt_rev = match qs {
        Some(qs) => pdf(scene, qs, qsm, pt),
        None => pdf_light_origin(scene, pt),
    };
    let ptm_rev = ptm.map(|ptm| match qs {
        Some(qs) => pdf(scene, pt, Some(qs), ptm),
        None => pdf_light(scene, pt, ptm),
    });
    let qs_rev = qs.map(|qs| pdf(scene, pt, ptm, qs));
    let qsm_rev = qsm.map(|qsm| pdf(scene, qs.unwrap_or(pt), Some(pt), qsm));
    let remap = |p: f32| if p != 0.0 { p } else { 1.0 };
    let z_rev = |i: usize| {
        if i == t - 1 {
            pt_rev
        } else if i + 2 == t {
            ptm_rev.unwrap_or(0.0)
        } else {
            zv(i).pdf_rev
        }
    };
    // A delta BSDF lobe drawn at a vertex rules out joins there (not at the join itself).
    let z_delta = |i: usize| i != t - 1 && zv(i).role == Role::Surface && zv(i).delta;
    let mut sum = 0.0f32;
    let mut ri = 1.0f32;
    for i in (1..t).rev() {
        ri *= remap(z_rev(i)) / remap(zv(i).pdf_fwd);
        if !z_delta(i) && !z_delta(i - 1) {
            sum += ri * ri;
        }
    }
    let y_rev = |i: usize| {
        if i + 1 == s {
            qs_rev.unwrap_or(0.0)
        } else if i + 2 == s {
            qsm_rev.unwrap_or(0.0)
        } else {
            yv(i).pdf_rev
        }
    };
    let y_delta = |i: usize| i + 1 != s && yv(i).role == Role::Surface && yv(i).delta;
    ri = 1.0;
    for i in (0..s).rev() {
        ri *= remap(y_rev(i)) / remap(yv(i).pdf_fwd);
        // Before y₀: a light with a delta position, which no camera subpath can hit.
        let before = if i > 0 { y_delta(i - 1) } else { yv(0).delta };
        if !y_delta(i) && !before {
            sum += ri * ri;
        }
    }
    let w = 1.0 / (1.0 + sum);
    if w.is_finite() {
        w
    } else {
        0.0
    }
}
