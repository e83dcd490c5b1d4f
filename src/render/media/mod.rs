//! Participating media: fog, smoke, murky water, the inside of a translucent object.
//!
//! A medium absorbs and scatters light everywhere along a ray, not only at surfaces. Per unit
//! length it has an extinction coefficient σt (per channel) of which the share α (the single-
//! scattering albedo) scatters, σs = α·σt, and the rest, σa = σt − σs, is absorbed; where light
//! scatters, the phase function (`phase`) says where to. Light crossing a length d of it keeps
//! the fraction T = exp(−σt·d) (Beer–Lambert).
//!
//! Where a medium is lies in the scene, not here: shapes bound media (their `interior` and
//! `exterior`, as Mitsuba 3's), and the camera may sit in one (`[camera] medium`), which then
//! fills space up to the first boundary. `integrators::volpath` walks the boundaries.
//!
//! Distances are drawn in proportion to the transmittance of one channel, the path's hero,
//! picked at random when the path starts; the estimate is combined over the three choices of
//! hero by the balance heuristic on whole paths (single-sample spectral MIS, as pbrt-v4's and
//! Mitsuba's `volpathmis`): a path of throughput f per channel, which hero c would have drawn
//! with density p_c, counts f / mean_c(p_c). The integrator keeps that ratio as the throughput β
//! and the densities' ratios r = p_c / mean(p) (mean 1); a collision at t multiplies f by
//! σs·e^(−σt·t) and p by σt·e^(−σt·t), going through a length d multiplies both by e^(−σt·d).
//! Each channel's weight stays below 3α however the channels' σt differ (drawing by one channel
//! alone, as Mitsuba's `volpath`, weights the others by transmittance ratios, without bound),
//! and is exactly α per collision in a grey medium. Transmittance along a shadow ray is
//! Beer–Lambert's closed form.
//!
//! A heterogeneous medium's σt is scaled point by point by a density grid (`grid`, Mitsuba's
//! `.vol`, or procedural noise evaluated into one, `noise`). There the flight is delta tracking
//! (Woodcock et al. 1965) with a majorant μ̄ = max σt · max density (the maximum taken per
//! brick, below): tentative collisions at rate μ̄, each real with the hero's
//! probability σt_h(x)/μ̄ (f = σs(x), p = σt(x) per channel) or null (f = p = μ̄ − σt(x)),
//! weighed by the same spectral MIS; shadow rays take ratio tracking's transmittance,
//! Π(1 − σt(xᵢ)/μ̄) over the tentative collisions (Novák et al. 2014). Both only walk the part
//! of the ray inside the grid's cube, brick by brick: the majorant is the largest density
//! within each brick of 8³ voxels (`Grid::brick_maxima`), walked by a 3D DDA, so thin and
//! empty parts of a sparse grid cost few or no null collisions (free flight being memoryless,
//! sampling starts afresh at each brick's entry).

pub mod grid;
pub mod noise;
pub mod phase;

pub use grid::Grid;
pub use phase::Phase;

use super::geometry::Ray;
use super::sampler::Sampler;

use glam::Vec3A;

/// A medium: homogeneous, or heterogeneous where a density grid scales σt point by point.
#[derive(Clone, Debug)]
pub struct Medium {
    pub name: String,
    /// σt per unit of scene length, per channel, ≥ 0 (times the density, where there is one).
    pub sigma_t: Vec3A,
    /// The single-scattering albedo α = σs/σt per channel, in [0, 1].
    pub albedo: Vec3A,
    pub phase: Phase,
    pub density: Option<Density>,
}

/// A heterogeneous medium's density: σt(x) = σt · grid(to_grid(x)).
#[derive(Clone, Debug)]
pub struct Density {
    pub grid: Grid,
    /// From the scene to the grid's [0, 1]³.
    pub to_grid: glam::Affine3A,
    /// Bricks per axis and each brick's largest density (`Grid::brick_maxima`): the
    /// majorant is kept per brick, so thin and empty parts cost few or no null collisions.
    bricks: [usize; 3],
    brick_max: Vec<f32>,
}

/// Bricks are walked only where their maxima average below this share of the grid's largest
/// density (fewer null collisions by half at least); otherwise one majorant serves the grid.
const WORTH_BRICKS: f32 = 0.5;

/// Tentative collisions one flight or shadow ray may take through a grid before it is cut
/// short (a majorant times a length beyond any scene lumen renders in reasonable time).
const MAX_STEPS: u32 = 1 << 20;

/// How a walk through a grid's tentative collisions (`Medium::walk`) ended.
enum Walk<R> {
    /// At the end of the ray's span.
    End,
    /// Where the caller's test returned this.
    Stopped(R),
    /// Cut short after `MAX_STEPS` collisions.
    TooLong,
}

/// Where a ray's flight through a medium ends.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Flight {
    /// Scattered at distance t along the ray.
    Scatter(f32),
    /// Reached the end of the segment.
    Through,
    /// Absorbed: nothing comes back along the path.
    Absorbed,
}

fn mean(v: Vec3A) -> f32 {
    (v.x + v.y + v.z) / 3.0
}

impl Medium {
    /// σs per channel.
    pub fn sigma_s(&self) -> Vec3A {
        self.sigma_t * self.albedo
    }

    /// Samples where a ray first collides within [0, t_max) by the transmittance of channel
    /// `hero` (the path's, module docs); updates the path's throughput `beta` and its channels'
    /// relative densities `r` (mean 1).
    pub fn sample_flight(
        &self,
        ray: &Ray,
        t_max: f32,
        hero: usize,
        s: &mut Sampler,
        beta: &mut Vec3A,
        r: &mut Vec3A,
    ) -> Flight {
        if let Some(d) = &self.density {
            return self.track(d, ray, t_max, hero, s, beta, r);
        }
        let sigma_t = self.sigma_t;
        if sigma_t.max_element() <= 0.0 {
            return Flight::Through;
        }
        // 1 − u lies in (0, 1]: the logarithm is finite; a channel with σt = 0 never collides.
        let h = sigma_t[hero];
        let u = s.next();
        let t = if h > 0.0 { -(1.0 - u).ln() / h } else { f32::INFINITY };
        let (flight, f, p) = if t < t_max {
            let tr = self.transmittance_over(t);
            (Flight::Scatter(t), self.sigma_s() * tr, sigma_t * tr)
        } else {
            let tr = self.transmittance_over(t_max);
            (Flight::Through, tr, tr)
        };
        weigh(flight, f, p, beta, r)
    }

    /// Delta tracking through a grid (module docs): tentative collisions at the majorant's
    /// rate, each real with the hero's probability σt/μ̄, null otherwise.
    #[allow(clippy::too_many_arguments)]
    fn track(
        &self,
        d: &Density,
        ray: &Ray,
        t_max: f32,
        hero: usize,
        s: &mut Sampler,
        beta: &mut Vec3A,
        r: &mut Vec3A,
    ) -> Flight {
        let collision = |t: f32, sigma_t: Vec3A, mu: f32, s: &mut Sampler| {
            if s.next() * mu < sigma_t[hero] {
                return Some(weigh(Flight::Scatter(t), sigma_t * self.albedo, sigma_t, beta, r));
            }
            let sigma_n = (Vec3A::splat(mu) - sigma_t).max(Vec3A::ZERO);
            (weigh(Flight::Through, sigma_n, sigma_n, beta, r) == Flight::Absorbed)
                .then_some(Flight::Absorbed)
        };
        match self.walk(d, ray, t_max, s, collision) {
            Walk::End => Flight::Through,
            Walk::Stopped(flight) => flight,
            Walk::TooLong => Flight::Absorbed,
        }
    }

    /// Tentative collisions along the ray's [0, t_max) through a grid, brick by brick, at each
    /// brick's majorant μ (free flight is memoryless: sampling starts afresh where a brick
    /// begins); `at(t, σt(t), μ, s)` decides each, and the walk stops where it returns a value.
    fn walk<R>(
        &self,
        d: &Density,
        ray: &Ray,
        t_max: f32,
        s: &mut Sampler,
        mut at: impl FnMut(f32, Vec3A, f32, &mut Sampler) -> Option<R>,
    ) -> Walk<R> {
        let scale = self.sigma_t.max_element();
        let Some((t0, t1)) = d.span(ray, t_max).filter(|_| scale > 0.0) else { return Walk::End };
        let mut steps = 0;
        for (enter, exit, brick_max) in d.bricks(ray, t0, t1) {
            let mu = scale * brick_max;
            if mu <= 0.0 {
                continue;
            }
            let mut t = enter;
            loop {
                steps += 1;
                if steps > MAX_STEPS {
                    return Walk::TooLong;
                }
                t -= (1.0 - s.next()).ln() / mu;
                if !(t < exit) {
                    break;
                }
                let sigma_t =
                    self.sigma_t * d.grid.eval(d.to_grid.transform_point3a(ray.origin + ray.dir * t));
                if let Some(v) = at(t, sigma_t, mu, s) {
                    return Walk::Stopped(v);
                }
            }
        }
        Walk::End
    }

    /// The fraction of light that gets through the first `d` of the ray (an infinite `d`
    /// allowed), per channel: Beer–Lambert's exp(−σt·d) in a homogeneous medium, ratio
    /// tracking's estimate Π(1 − σt(xᵢ)/μ̄) in a grid.
    pub fn transmittance(&self, ray: &Ray, d: f32, s: &mut Sampler) -> Vec3A {
        let Some(g) = &self.density else { return self.transmittance_over(d) };
        let mut tr = Vec3A::ONE;
        let collision = |_t: f32, sigma_t: Vec3A, mu: f32, _s: &mut Sampler| {
            tr *= (Vec3A::ONE - sigma_t / mu).max(Vec3A::ZERO);
            (tr.max_element() <= 0.0).then_some(())
        };
        match self.walk(g, ray, d, s, collision) {
            Walk::End => tr,
            Walk::Stopped(()) | Walk::TooLong => Vec3A::ZERO,
        }
    }

    /// A homogeneous medium's transmittance over a length `d`: exp(−σt·d), 1 where σt = 0
    /// (also for an infinite d).
    pub fn transmittance_over(&self, d: f32) -> Vec3A {
        let f = |s: f32| if s > 0.0 { (-s * d).exp() } else { 1.0 };
        Vec3A::new(f(self.sigma_t.x), f(self.sigma_t.y), f(self.sigma_t.z))
    }
}

/// Multiplies the throughput by an event's f and the relative densities by its p per channel,
/// both divided by mean(r·p) (module docs); absorbed where nothing can go on.
fn weigh(flight: Flight, f: Vec3A, p: Vec3A, beta: &mut Vec3A, r: &mut Vec3A) -> Flight {
    let k = mean(*r * p);
    if !(k > 0.0) || f == Vec3A::ZERO {
        return Flight::Absorbed;
    }
    *beta *= f / k;
    *r *= p / k;
    flight
}

impl Density {
    /// A density from its grid and placement, with the grid's brick maxima.
    pub fn new(grid: Grid, to_grid: glam::Affine3A) -> Density {
        let (bricks, brick_max) = grid.brick_maxima();
        // Where the bricks' maxima are mostly near the grid's (a dense or small grid), walking
        // them costs more than the null collisions they save: one brick, the whole grid.
        let mean = brick_max.iter().sum::<f32>() / brick_max.len().max(1) as f32;
        if !(mean < WORTH_BRICKS * grid.max) {
            let max = grid.max;
            return Density { grid, to_grid, bricks: [1, 1, 1], brick_max: vec![max] };
        }
        Density { grid, to_grid, bricks, brick_max }
    }

    /// The bricks the ray crosses within [t0, t1) (inside the grid's cube), in order: each
    /// one's entry and exit distance and largest density (3D DDA, Amanatides & Woo 1987, in
    /// the grid's voxel coordinates, where t is the ray's own).
    fn bricks(&self, ray: &Ray, t0: f32, t1: f32) -> impl Iterator<Item = (f32, f32, f32)> + '_ {
        let res = self.bricks;
        // One brick (`WORTH_BRICKS`): the whole span at once, without setting up the walk.
        let mut single = (res == [1, 1, 1]).then_some((t0, t1, self.brick_max[0]));
        let mut walk: Option<([i64; 3], [f32; 3], [f32; 3], [i64; 3])> = None;
        let (origin, direction) = (ray.origin, ray.dir);
        let mut t = t0;
        std::iter::from_fn(move || {
            if res == [1, 1, 1] {
                return single.take();
            }
            let (cell, next, delta, step) = walk.get_or_insert_with(|| {
                // Positions in brick units: P(t) = o + d·t.
                let per_unit =
                    Vec3A::new(self.grid.size[0] as f32, self.grid.size[1] as f32, self.grid.size[2] as f32)
                        / grid::BRICK as f32;
                let o = self.to_grid.transform_point3a(origin) * per_unit;
                let d = self.to_grid.transform_vector3a(direction) * per_unit;
                let start = o + d * t0;
                let mut cell = [0i64; 3];
                let (mut next, mut delta, mut step) = ([f32::INFINITY; 3], [f32::INFINITY; 3], [0i64; 3]);
                for a in 0..3 {
                    cell[a] = (start[a].floor() as i64).clamp(0, res[a] as i64 - 1);
                    if d[a] > 0.0 {
                        step[a] = 1;
                        delta[a] = 1.0 / d[a];
                        next[a] = ((cell[a] + 1) as f32 - o[a]) / d[a];
                    } else if d[a] < 0.0 {
                        step[a] = -1;
                        delta[a] = -1.0 / d[a];
                        next[a] = (cell[a] as f32 - o[a]) / d[a];
                    }
                }
                (cell, next, delta, step)
            });
            if !(t < t1) || cell.iter().zip(res).any(|(&c, n)| c < 0 || c >= n as i64) {
                return None;
            }
            let a = (0..3).min_by(|&i, &j| next[i].total_cmp(&next[j])).unwrap_or(0);
            let exit = next[a].min(t1).max(t);
            let m =
                self.brick_max[(cell[2] as usize * res[1] + cell[1] as usize) * res[0] + cell[0] as usize];
            let seg = (t, exit, m);
            t = exit;
            cell[a] += step[a];
            next[a] += delta[a];
            Some(seg)
        })
    }

    /// The part [t0, t1) of the ray's [0, t_max) inside the grid's cube (outside it the
    /// density is 0), by the slab test in the grid's coordinates (an affine map keeps t).
    fn span(&self, ray: &Ray, t_max: f32) -> Option<(f32, f32)> {
        let o = self.to_grid.transform_point3a(ray.origin);
        let d = self.to_grid.transform_vector3a(ray.dir);
        let inv = d.recip();
        let (a, b) = (-o * inv, (Vec3A::ONE - o) * inv);
        // NaN (0 · ∞, a ray along a face) falls to the other operand in min/max.
        let t0 = a.min(b).max_element().max(0.0);
        let t1 = a.max(b).min_element().min(t_max);
        (t0 < t1).then_some((t0, t1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::sampler::Sampler;

    /// The mean weight of getting through a length d is exp(−σt·d) per channel, in a
    /// chromatic medium (heroes picked at random) as in a grey one.
    /// The bricks a ray crosses tile its span inside the grid without gap or overlap, and the
    /// density anywhere inside a brick stays within that brick's maximum, for rays in every
    /// direction through a turned, stretched grid (a sparse noise: many empty bricks).
    #[test]
    fn bricks_tile_the_span_and_bound_the_density() {
        let grid = noise::density_grid(11, 4, 4, 0.7, 40);
        let to_world = glam::Affine3A::from_scale_rotation_translation(
            glam::Vec3::new(2.0, 1.0, 0.5),
            glam::Quat::from_rotation_y(0.4),
            glam::Vec3::new(-1.0, 0.2, 0.3),
        );
        let d = Density::new(grid, to_world.inverse());
        assert_eq!(d.bricks, [5, 5, 5], "a sparse grid is walked brick by brick");
        let mut s = Sampler::new(2, 0, 0);
        let mut checked = 0;
        for _ in 0..2000 {
            let origin = Vec3A::new(s.next() * 6.0 - 3.0, s.next() * 4.0 - 2.0, s.next() * 4.0 - 2.0);
            // Aimed at a point of the grid's box, so that most rays cross it.
            let target = to_world.transform_point3a(Vec3A::new(s.next(), s.next(), s.next()));
            let dir = (target - origin).normalize();
            let ray = Ray { origin, dir };
            let Some((t0, t1)) = d.span(&ray, 10.0) else { continue };
            let mut t = t0;
            for (enter, exit, m) in d.bricks(&ray, t0, t1) {
                assert_eq!(enter, t, "a gap or overlap between bricks");
                assert!(exit >= enter);
                for k in 0..4 {
                    let x = enter + (exit - enter) * (k as f32 + 0.5) / 4.0;
                    let v = d.grid.eval(d.to_grid.transform_point3a(ray.origin + ray.dir * x)).x;
                    assert!(v <= m * (1.0 + 1e-5) + 1e-6, "density {v} above its brick's maximum {m}");
                    checked += 1;
                }
                t = exit;
            }
            assert!((t - t1).abs() <= 1e-5 * t1.max(1.0), "the bricks end at {t}, the span at {t1}");
        }
        assert!(checked > 10_000, "{checked} points checked");
    }

    /// Through procedural noise (`noise`): ratio tracking's transmittance and delta tracking's
    /// chance of passing both average to exp(−σt·∫ρ) along the ray, the optical depth taken
    /// by quadrature of the same density (4 SE, 2·10⁵ rays each).
    #[test]
    fn noise_medium_transmittance_matches_quadrature() {
        let grid = noise::density_grid(3, 4, 4, 0.3, 32);
        let m = Medium {
            name: "cloud".into(),
            sigma_t: Vec3A::splat(4.0),
            albedo: Vec3A::splat(0.8),
            phase: Phase { g: 0.0 },
            density: Some(Density::new(grid, glam::Affine3A::IDENTITY)),
        };
        let ray = Ray { origin: Vec3A::new(-0.5, 0.37, 0.61), dir: Vec3A::new(1.0, 0.1, -0.05).normalize() };
        let d = 2.0f32;
        let g = m.density.as_ref().unwrap();
        let steps = 200_000;
        let depth: f64 = (0..steps)
            .map(|k| {
                let t = (k as f32 + 0.5) / steps as f32 * d;
                m.sigma_t.x as f64
                    * g.grid.eval(ray.origin + ray.dir * t).x as f64
                    * (d / steps as f32) as f64
            })
            .sum();
        let want = (-depth).exp();
        assert!(depth > 0.3 && want > 0.05, "the ray must cross some cloud: optical depth {depth}");
        let n = 200_000u64;
        let (mut ratio, mut ratio2, mut pass) = (0.0f64, 0.0f64, 0u64);
        for k in 0..n {
            let mut s = Sampler::new(9, k, 0);
            let tr = m.transmittance(&ray, d, &mut s).x as f64;
            ratio += tr;
            ratio2 += tr * tr;
            let (mut beta, mut r) = (Vec3A::ONE, Vec3A::ONE);
            if m.sample_flight(&ray, d, 0, &mut s, &mut beta, &mut r) == Flight::Through {
                assert!((beta.x - 1.0).abs() < 1e-5, "a grey medium passes with weight 1: {beta}");
                pass += 1;
            }
        }
        let mean = ratio / n as f64;
        let se = ((ratio2 / n as f64 - mean * mean).max(0.0) / n as f64).sqrt();
        assert!((mean - want).abs() < 4.0 * se, "ratio tracking {mean} ± {se} vs exp(−τ) {want}");
        let p = pass as f64 / n as f64;
        let se = (want * (1.0 - want) / n as f64).sqrt();
        assert!((p - want).abs() < 4.0 * se, "delta tracking passes {p} vs exp(−τ) {want} (SE {se})");
    }

    #[test]
    fn flight_passes_with_beer_lambert_probability() {
        for sigma_t in [Vec3A::splat(1.5), Vec3A::new(0.2, 1.0, 3.0), Vec3A::new(0.0, 0.5, 4.0)] {
            let m = Medium {
                name: "m".into(),
                sigma_t,
                albedo: Vec3A::splat(0.5),
                phase: Phase { g: 0.0 },
                density: None,
            };
            let (d, n) = (0.8f32, 400_000u64);
            let mut sum = [0.0f64; 3];
            let mut sq = [0.0f64; 3];
            for k in 0..n {
                let mut s = Sampler::new(5, k, 0);
                let (mut beta, mut r) = (Vec3A::ONE, Vec3A::ONE);
                let hero = ((s.next() * 3.0) as usize).min(2);
                let ray = Ray { origin: Vec3A::ZERO, dir: Vec3A::X };
                if m.sample_flight(&ray, d, hero, &mut s, &mut beta, &mut r) == Flight::Through {
                    assert!((r.x + r.y + r.z - 3.0).abs() < 1e-5, "r = {r} has mean 1");
                    for c in 0..3 {
                        sum[c] += beta[c] as f64;
                        sq[c] += (beta[c] as f64).powi(2);
                    }
                }
            }
            let truth = m.transmittance_over(d);
            for c in 0..3 {
                let mean = sum[c] / n as f64;
                let se = ((sq[c] / n as f64 - mean * mean) / n as f64).sqrt();
                assert!(
                    (mean - truth[c] as f64).abs() < 4.0 * se + 1e-6,
                    "σt {sigma_t:?}, channel {c}: {mean} ± {se} against exp(−σt·d) = {}",
                    truth[c]
                );
            }
        }
    }
}
