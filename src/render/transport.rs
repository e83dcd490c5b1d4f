//! The steps of a path's vertex, written once for every lane width (`lanes::Real`,
//! `lanes::Vector`): the one-path loop calls them on `f32` and `Vec3A`, the eight-lane loop on
//! registers of eight, and both compute the same bits because there is one definition.
//!
//! Here: the orthonormal basis round a normal, the unit circle and the cosine-weighted bounce,
//! the Lambertian BSDF, a point on a triangle, the way to a light point and the light samples
//! of area and point lights,
//! the shadow segment towards a light point, the ray offset off a surface and Russian roulette.

use super::lanes::{Real, Vector};

/// An orthonormal basis (t, b) completing n (Duff et al. 2017). As in the paper: a sign
/// copy, not a compare and a branch (n.z = −0 takes −1, also fine).
#[inline(always)]
pub fn basis<V: Vector>(n: V) -> (V, V) {
    let one = V::R::splat(1.0);
    let s = n.z().sign_one();
    let a = V::R::splat(-1.0) / (s + n.z());
    let b = n.x() * n.y() * a;
    (V::new(one + s * n.x() * n.x() * a, s * b, -s * n.x()), V::new(b, s + n.y() * n.y() * a, -n.y()))
}

/// (cos 2πu, sin 2πu) for u in [0, 1], within 1.5e-7 of the true values. The nearest quarter
/// turn q is split off with integer arithmetic and the rest, |θ| ≤ π/4, goes through Taylor
/// polynomials (to θ⁹ and θ⁸); the quarter turn swaps and negates the pair with bit operations
/// (`Real::quarter_turn`), not branches, since q is random. This is a few times cheaper than
/// libm's `sincosf`, which reduces arguments of any size.
#[inline(always)]
pub fn unit_circle<R: Real>(u: R) -> (R, R) {
    let c = R::splat;
    let v = c(4.0) * u;
    // Adding 2²³ rounds v to the nearest integer, which then sits in the low mantissa bits:
    // two additions instead of a saturating float-to-integer conversion. Only q's low two bits
    // are used.
    let shifted = v + c(8_388_608.0);
    let t = (v - (shifted - c(8_388_608.0))) * c(std::f32::consts::FRAC_PI_2);
    let t2 = t * t;
    let sin = t
        * (c(1.0)
            + t2 * (c(-1.0 / 6.0)
                + t2 * (c(1.0 / 120.0) + t2 * (c(-1.0 / 5040.0) + t2 * c(1.0 / 362_880.0)))));
    let cos =
        c(1.0) + t2 * (c(-0.5) + t2 * (c(1.0 / 24.0) + t2 * (c(-1.0 / 720.0) + t2 * c(1.0 / 40_320.0))));
    // Quarter turn q: (cos, sin) → (−sin, cos); so q odd swaps the pair, the cosine is
    // negated for q ≡ 1, 2 and the sine for q ≡ 2, 3 (mod 4).
    R::quarter_turn(shifted, cos, sin)
}

/// Cosine-weighted direction around `n` (Malley's method).
#[inline(always)]
pub fn cosine_hemisphere<V: Vector>(n: V, u1: V::R, u2: V::R) -> V {
    let r = u1.sqrt();
    let (cos, sin) = unit_circle(u2);
    let (t, b) = basis(n);
    let z = (V::R::splat(1.0) - u1).max(V::R::splat(0.0)).sqrt();
    // Unit up to rounding already (t, b, n orthonormal, r² + z² = 1): no normalisation.
    t.scale(r * cos).add(b.scale(r * sin)).add(n.scale(z))
}

/// The Lambertian BSDF kd/π where the normal `n` faces both `wo` and `wi`, 0 elsewhere.
#[inline(always)]
pub fn lambert<V: Vector>(kd: V, n: V, wo: V, wi: V) -> V {
    let zero = V::R::splat(0.0);
    let facing = n.dot(wo).gt(zero) & n.dot(wi).gt(zero);
    V::select(facing, kd.scale(V::R::splat(std::f32::consts::FRAC_1_PI)), V::new(zero, zero, zero))
}

/// The point v0 + b1·e1 + b2·e2 of a triangle with b1 = √u(1 − v), b2 = √u·v: uniform in area
/// for (u, v) uniform in the unit square.
#[inline(always)]
pub fn triangle_point<V: Vector>(v0: V, e1: V, e2: V, u: V::R, v: V::R) -> V {
    let su = u.sqrt();
    let (b1, b2) = (su * (V::R::splat(1.0) - v), su * v);
    v0.add(e1.scale(b1)).add(e2.scale(b2))
}

/// The way from `p` to a light point `y`: (unit direction, distance, squared distance).
#[inline(always)]
pub fn towards<V: Vector>(p: V, y: V) -> (V, V::R, V::R) {
    let d = y.sub(p);
    let r2 = d.dot(d);
    let r = r2.sqrt();
    (d.div(r), r, r2)
}

/// The light sample of an area light's point at squared distance `r2` along `wi`, its unit
/// normal `ny`, the light of `area` and `radiance` picked with probability `p_pick`: (radiance
/// divided by the solid-angle density, the density, whether it carries light — the light
/// faces the way back and the point is not the shading point). The density is the area
/// measure's 1/A converted to solid angle: p_pick·r² / (A·cos θ_light).
#[inline(always)]
pub fn area_light<V: Vector>(
    wi: V,
    r2: V::R,
    ny: V,
    radiance: V,
    area: V::R,
    p_pick: V::R,
) -> (V, V::R, <V::R as Real>::Mask) {
    let zero = V::R::splat(0.0);
    let cos_light = -ny.dot(wi);
    let pdf = p_pick * r2 / (area * cos_light);
    (radiance.div(pdf), pdf, !(cos_light.le(zero) | r2.eq(zero)))
}

/// A point light's `intensity` arriving from squared distance `r2`, the light picked with
/// probability `p_pick`: intensity / (r²·p_pick).
#[inline(always)]
pub fn point_light<V: Vector>(intensity: V, r2: V::R, p_pick: V::R) -> V {
    intensity.div(r2 * p_pick)
}

/// Offset for spawning rays off a surface at `p`, scaled with the coordinates' magnitude.
#[inline(always)]
pub fn epsilon<V: Vector>(p: V) -> V::R {
    V::R::splat(1e-4) * (V::R::splat(1.0) + p.abs().max_element())
}

/// The origin of a ray leaving the surface point `p` (normal `n`, offset `eps`) along `dir`:
/// off the side `dir` goes to, so refracted rays leave from the far side.
#[inline(always)]
pub fn offset<V: Vector>(p: V, n: V, dir: V, eps: V::R) -> V {
    let off = n.scale(eps);
    p.add(V::select(n.dot(dir).ge(V::R::splat(0.0)), off, off.neg()))
}

/// The shadow ray from the offset origin `origin` to the light point `p + wi·dist`: (unit
/// direction, the distance it must be clear for, whether it has a length). It aims at the point
/// itself rather than along wi: near a sphere light's silhouette, moving the origin by the
/// offset moves where a grazing ray enters the sphere by many times that offset. It stops
/// short of the point by the point's own offset.
#[inline(always)]
pub fn shadow_segment<V: Vector>(origin: V, p: V, wi: V, dist: V::R) -> (V, V::R, <V::R as Real>::Mask) {
    let to = p.add(wi.scale(dist)).sub(origin);
    let len = to.dot(to).sqrt();
    (to.div(len), len * V::R::splat(1.0 - 1e-4) - epsilon(p), len.gt(V::R::splat(0.0)))
}

/// Russian roulette on the throughput `beta` with the uniform number `u`: the path survives
/// with q = min(max β, 0.95) and then carries β/q. Returns (killed, β/q).
#[inline(always)]
pub fn roulette<V: Vector>(beta: V, u: V::R) -> (<V::R as Real>::Mask, V) {
    let q = beta.max_element().min(V::R::splat(0.95));
    (u.ge(q), beta.div(q))
}

/// Each step on eight lanes against the same step on `f32`, lane by lane, bit for bit, on
/// random inputs with the edge cases the path loop meets (zero distance, a light seen from
/// behind, normals at the poles, roulette's 0.95 cap).
#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;
    use crate::render::lanes::vector::{F, V};
    use crate::render::sampler::Sampler;
    use glam::Vec3A;

    struct Lanes8 {
        s: Sampler,
    }

    impl Lanes8 {
        fn reals(&mut self, lo: f32, hi: f32) -> [f32; 8] {
            let mut a = [0.0; 8];
            for (i, x) in a.iter_mut().enumerate() {
                // Lanes 0 and 1 take the interval's ends: the edges go through every step.
                *x = match i {
                    0 => lo,
                    1 => hi,
                    _ => lo + (hi - lo) * self.s.next(),
                };
            }
            a
        }
        fn unit(&mut self) -> [[f32; 8]; 3] {
            let mut v = [[0.0; 8]; 3];
            for lane in 0..8 {
                let d = match lane {
                    0 => Vec3A::Z,
                    1 => -Vec3A::Z,
                    _ => {
                        cosine_hemisphere(Vec3A::Z, self.s.next(), self.s.next())
                            * (self.s.next() - 0.5).signum()
                    }
                };
                for c in 0..3 {
                    v[c][lane] = d[c];
                }
            }
            v
        }
        fn vector(&mut self, scale: f32) -> [[f32; 8]; 3] {
            [0, 1, 2].map(|_| self.reals(-scale, scale))
        }
    }

    fn lane(v: &[[f32; 8]; 3], i: usize) -> Vec3A {
        Vec3A::new(v[0][i], v[1][i], v[2][i])
    }

    fn store(v: V) -> [[f32; 8]; 3] {
        let mut a = [[0.0; 8]; 3];
        v.store(&mut a);
        a
    }

    fn store_f(x: F) -> [f32; 8] {
        let mut a = [0.0; 8];
        x.store(&mut a);
        a
    }

    fn same_v(what: &str, wide: V, narrow: impl Fn(usize) -> Vec3A) {
        let w = store(wide);
        for i in 0..8 {
            let (a, b) = (lane(&w, i), narrow(i));
            let same = (0..3).all(|c| a[c].to_bits() == b[c].to_bits() || (a[c].is_nan() && b[c].is_nan()));
            assert!(same, "{what}, lane {i}: eight lanes {a:?}, one path {b:?}");
        }
    }

    fn same_f(what: &str, wide: F, narrow: impl Fn(usize) -> f32) {
        let w = store_f(wide);
        for (i, &a) in w.iter().enumerate() {
            let b = narrow(i);
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "{what}, lane {i}: {a} against {b}"
            );
        }
    }

    #[test]
    fn eight_lanes_compute_the_one_path_bits() {
        if !crate::render::lanes::available() {
            eprintln!("skipped: this processor has no AVX2");
            return;
        }
        let mut g = Lanes8 { s: Sampler::new(7, 1, 2) };
        for _ in 0..2000 {
            let (n, wo, wi) = (g.unit(), g.unit(), g.unit());
            let (p, y, kd) = (g.vector(10.0), g.vector(10.0), g.vector(1.0));
            let (u1, u2, area, pick) =
                (g.reals(0.0, 1.0), g.reals(0.0, 1.0), g.reals(0.0, 2.0), g.reals(0.0, 1.0));
            let (nv, wov, wiv, pv, yv, kdv) =
                (V::load(&n), V::load(&wo), V::load(&wi), V::load(&p), V::load(&y), V::load(&kd));
            let (u1v, u2v, areav, pickv) = (F::load(&u1), F::load(&u2), F::load(&area), F::load(&pick));

            let (t, b) = basis(nv);
            same_v("basis t", t, |i| basis(lane(&n, i)).0);
            same_v("basis b", b, |i| basis(lane(&n, i)).1);
            let (c, s) = unit_circle(u1v);
            same_f("cos", c, |i| unit_circle(u1[i]).0);
            same_f("sin", s, |i| unit_circle(u1[i]).1);
            same_v("cosine_hemisphere", cosine_hemisphere(nv, u1v, u2v), |i| {
                cosine_hemisphere(lane(&n, i), u1[i], u2[i])
            });
            same_v("lambert", lambert(kdv, nv, wov, wiv), |i| {
                lambert(lane(&kd, i), lane(&n, i), lane(&wo, i), lane(&wi, i))
            });
            same_v("triangle_point", triangle_point(pv, yv, kdv, u1v, u2v), |i| {
                triangle_point(lane(&p, i), lane(&y, i), lane(&kd, i), u1[i], u2[i])
            });
            let (w, r, r2) = towards(pv, yv);
            let one = |i: usize| towards(lane(&p, i), lane(&y, i));
            same_v("towards wi", w, |i| one(i).0);
            same_f("towards r", r, |i| one(i).1);
            same_f("towards r2", r2, |i| one(i).2);
            let (li, pdf, ok) = area_light(w, r2, nv, kdv, areav, pickv);
            let one = |i: usize| {
                let (w, _, r2) = towards(lane(&p, i), lane(&y, i));
                area_light(w, r2, lane(&n, i), lane(&kd, i), area[i], pick[i])
            };
            same_v("area_light li", li, |i| one(i).0);
            same_f("area_light pdf", pdf, |i| one(i).1);
            let ok = ok.bits();
            (0..8).for_each(|i| assert_eq!(ok >> i & 1 == 1, one(i).2, "area_light lit, lane {i}"));
            same_v("point_light", point_light(kdv, r2, pickv), |i| {
                point_light(lane(&kd, i), towards(lane(&p, i), lane(&y, i)).2, pick[i])
            });
            let eps = epsilon(pv);
            same_f("epsilon", eps, |i| epsilon(lane(&p, i)));
            same_v("offset", offset(pv, nv, wiv, eps), |i| {
                offset(lane(&p, i), lane(&n, i), lane(&wi, i), epsilon(lane(&p, i)))
            });
            let (d, t_max, has) = shadow_segment(pv, yv, wiv, areav);
            let one = |i: usize| shadow_segment(lane(&p, i), lane(&y, i), lane(&wi, i), area[i]);
            same_v("shadow_segment dir", d, |i| one(i).0);
            same_f("shadow_segment t", t_max, |i| one(i).1);
            let has = has.bits();
            (0..8).for_each(|i| assert_eq!(has >> i & 1 == 1, one(i).2, "shadow_segment length, lane {i}"));
            let (killed, beta) = roulette(kdv, u1v);
            same_v("roulette beta", beta, |i| roulette(lane(&kd, i), u1[i]).1);
            let killed = killed.bits();
            (0..8).for_each(|i| {
                assert_eq!(killed >> i & 1 == 1, roulette(lane(&kd, i), u1[i]).0, "roulette, lane {i}")
            });
        }
    }
}
