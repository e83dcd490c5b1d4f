//! The path loop over eight lanes (`lanes` docs).

use super::*;
use crate::render::lanes::{samplers::*, vector::*, Vector};
use crate::render::transport;
use std::arch::x86_64::*;

/// The state of the eight lanes' paths, structure of arrays.
pub(super) struct Lanes {
    pub(super) origin: [[f32; 8]; 3],
    pub(super) dir: [[f32; 8]; 3],
    pub(super) beta: [[f32; 8]; 3],
    pub(super) l: [[f32; 8]; 3],
    pub(super) depth: [u32; 8],
    /// Index of the lane's sample in the group's radiance buffer, and its pixel's column.
    pub(super) slot: [usize; 8],
    pub(super) x: [u32; 8],
    pub(super) samplers: Samplers,
    pub(super) active: u32,
}

/// What a vertex's shading needs from the hit and the sampler, per lane.
#[derive(Default)]
pub(super) struct Vertex {
    pub(super) p: [[f32; 8]; 3],
    pub(super) n: [[f32; 8]; 3],
    pub(super) albedo: [[f32; 8]; 3],
}

#[inline(always)]
pub(super) fn put(a: &mut [[f32; 8]; 3], lane: usize, v: Vec3A) {
    a[0][lane] = v.x;
    a[1][lane] = v.y;
    a[2][lane] = v.z;
}

#[inline(always)]
pub(super) fn get(a: &[[f32; 8]; 3], lane: usize) -> Vec3A {
    Vec3A::new(a[0][lane], a[1][lane], a[2][lane])
}

/// Traces every sample of the pixels gx0..gx1 of row y into `radiance` (pixel-major,
/// sample order within a pixel).
///
/// # Safety
/// The processor must have AVX2 (`render::lanes::available()`).
#[target_feature(enable = "avx2")]
pub unsafe fn trace_group(
    scene: &Scene,
    lights: &LightTable,
    settings: &Settings,
    y: u32,
    gx0: u32,
    gx1: u32,
    radiance: &mut [Vec3A],
) {
    let spp = settings.spp;
    let max_depth = settings.max_depth;
    let jobs = (gx1 - gx0) as usize * spp as usize;
    let mut next_job = 0;
    let mut lanes = Lanes {
        origin: [[0.0; 8]; 3],
        dir: [[0.0; 8]; 3],
        beta: [[0.0; 8]; 3],
        l: [[0.0; 8]; 3],
        depth: [0; 8],
        slot: [0; 8],
        x: [0; 8],
        samplers: Samplers::new(settings.sampler, settings.seed, y, gx0, gx1, scene.camera.width),
        active: 0,
    };
    let mut v = Vertex::default();
    loop {
        // Empty lanes take the next samples (`integrators::camera_path`, with the pixel
        // position and a thin lens's sample drawn for the new lanes together).
        let mut fresh = 0u32;
        let mut empty = !lanes.active & 0xff;
        while empty != 0 && next_job < jobs {
            let lane = empty.trailing_zeros() as usize;
            empty &= empty - 1;
            let slot = next_job;
            next_job += 1;
            let (x, k) = (gx0 + (slot / spp as usize) as u32, (slot % spp as usize) as u32);
            let pixel = y as u64 * scene.camera.width as u64 + x as u64;
            let s = Sampler::with_kind(
                settings.sampler,
                settings.seed,
                pixel,
                settings.first_sample as u64 + k as u64,
            );
            lanes.samplers.set(lane, &s, x - gx0);
            lanes.slot[lane] = slot;
            lanes.x[lane] = x;
            fresh |= 1 << lane;
        }
        if lanes.active == 0 && fresh == 0 {
            return;
        }
        if fresh != 0 {
            let mut jitter = ([0.0f32; 8], [0.0f32; 8]);
            let (jx, jy) = lanes.samplers.next(fresh, true);
            jx.store(&mut jitter.0);
            jy.store(&mut jitter.1);
            let mut dirs = [glam::DVec3::ZERO; 8];
            let (mut seen, mut lens) = (0u32, 0u32);
            let mut mask = fresh;
            while mask != 0 {
                let lane = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                // Beyond the fold of the distortion the sample is black, as the buffer is.
                if let Some(d) = camera_direction(scene, lanes.x[lane], y, (jitter.0[lane], jitter.1[lane])) {
                    dirs[lane] = d;
                    seen |= 1 << lane;
                    lens |= (needs_lens_sample(scene, d) as u32) << lane;
                }
            }
            let mut lens_u = ([0.0f32; 8], [0.0f32; 8]);
            if lens != 0 {
                let (lx, ly) = lanes.samplers.next(lens, true);
                lx.store(&mut lens_u.0);
                ly.store(&mut lens_u.1);
            }
            let mut mask = seen;
            while mask != 0 {
                let lane = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let u = (lens & (1 << lane) != 0).then_some((lens_u.0[lane], lens_u.1[lane]));
                let ray = camera_ray(scene, dirs[lane], u);
                lanes.depth[lane] = 1;
                put(&mut lanes.origin, lane, ray.origin);
                put(&mut lanes.dir, lane, ray.dir);
                put(&mut lanes.beta, lane, Vec3A::ONE);
                put(&mut lanes.l, lane, Vec3A::ZERO);
            }
            lanes.active |= seen;
            if lanes.active == 0 {
                continue;
            }
        }
        // Hits, emission seen from the camera, and what shading needs, lane by lane.
        let mut shade = 0u32;
        let mut mask = lanes.active;
        while mask != 0 {
            let lane = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            let ray = Ray { origin: get(&lanes.origin, lane), dir: get(&lanes.dir, lane) };
            let depth = lanes.depth[lane];
            let Some(hit) = scene.bvh.intersect(&ray, 0.0, f32::INFINITY) else {
                radiance[lanes.slot[lane]] = get(&lanes.l, lane);
                lanes.active &= !(1 << lane);
                continue;
            };
            let surf = scene.surface(&ray, &hit);
            let mat = &scene.materials[surf.material as usize];
            if let Some(le) = mat.emission {
                if depth == 1 && surf.n.dot(-ray.dir) > 0.0 {
                    let l = get(&lanes.l, lane) + get(&lanes.beta, lane) * le;
                    put(&mut lanes.l, lane, l);
                }
            }
            // As the one-path loop: the last vertex, or the back of a one-sided surface.
            if depth == max_depth || (mat.one_sided && !(surf.n.dot(-ray.dir) >= 0.0)) {
                radiance[lanes.slot[lane]] = get(&lanes.l, lane);
                lanes.active &= !(1 << lane);
                continue;
            }
            shade |= 1 << lane;
            put(&mut v.p, lane, surf.p);
            put(&mut v.n, lane, surf.n);
            put(&mut v.albedo, lane, scene.albedo(surf.material, &hit, surf.p));
        }
        if shade == 0 {
            continue;
        }
        let shading = M::from_bits(shade);
        // The vertex's numbers, in the scalar loop's order: light, bounce, roulette.
        let roulette: u32 = (0..8).filter(|&i| lanes.depth[i] >= RR_START).fold(0, |m, i| m | 1 << i);
        let u_light = lanes.samplers.next(shade, true);
        let u_bsdf = lanes.samplers.next(shade, true);
        let u_rr = lanes.samplers.next(shade & roulette, false).0;

        // The light sample and its shadow ray (`Scene::sample_light`, `unoccluded`).
        let p = V::load(&v.p);
        let wo = V::load(&lanes.dir).neg();
        let surf_n = V::load(&v.n);
        let front = surf_n.dot(wo).ge(F::splat(0.0));
        let n = V::select(front, surf_n, surf_n.neg());
        let eps = transport::epsilon(p);
        let zero = F::splat(0.0);
        let (light, p_pick, u_pick) = pick_light(&scene.light_cdf, u_light.0);
        let kind = gather_i(&lights.kind, light);
        let is = |k: i32| M(_mm256_castsi256_ps(_mm256_cmpeq_epi32(kind, _mm256_set1_epi32(k))));
        let (point, directional) = (is(POINT), is(DIRECTIONAL));
        // A triangle's point, or the point light itself; a directional light's direction.
        let v0 = V::gather(&lights.v0, light);
        let power = V::gather(&lights.power, light);
        let (e1, e2) = (V::gather(&lights.e1, light), V::gather(&lights.e2, light));
        let tri_y = transport::triangle_point(v0, e1, e2, u_pick, u_light.1);
        let (to_y, r, r2) = transport::towards(p, V::select(point, v0, tri_y));
        let wi = V::select(directional, v0, to_y);
        let area = F::gather(&lights.area, light);
        let (li_tri, _, tri_ok) =
            transport::area_light(wi, r2, V::gather(&lights.n, light), power, area, p_pick);
        let li_point = transport::point_light(power, r2, p_pick);
        // Directional: irradiance / p_pick, along the direction itself.
        let li = V::select(point, li_point, V::select(directional, power.div(p_pick), li_tri));
        let cos = n.dot(wi);
        let origin = p.add(n.scale(eps));
        let (to_light, t_light, has_length) = transport::shadow_segment(origin, p, wi, r);
        let sdir = V::select(directional, wi, to_light);
        let t_max = directional.select(F::splat(f32::INFINITY), t_light);
        let lit = shading
            & p_pick.gt(zero)
            & (point | directional | tri_ok)
            & cos.gt(zero)
            & (directional | has_length);
        let mut ray_o = [[0.0f32; 8]; 3];
        let mut ray_d = [[0.0f32; 8]; 3];
        let mut ray_t = [0.0f32; 8];
        origin.store(&mut ray_o);
        sdir.store(&mut ray_d);
        t_max.store(&mut ray_t);
        let mut visible = 0u32;
        let mut mask = lit.bits();
        while mask != 0 {
            let lane = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            let ray = Ray { origin: get(&ray_o, lane), dir: get(&ray_d, lane) };
            if !scene.bvh.occluded(&ray, 0.0, ray_t[lane]) {
                visible |= 1 << lane;
            }
        }

        let albedo = V::load(&v.albedo);
        let beta = V::load(&lanes.beta);
        let f = transport::lambert(albedo, n, wo, wi);
        let l = V::load(&lanes.l);
        let l = V::select(M::from_bits(visible), l.add(beta.mul(f).scale(cos).mul(li)), l);
        l.store(&mut lanes.l);

        // The bounce: cosine-weighted, weight kd; roulette after RR_START segments.
        let wi = transport::cosine_hemisphere(n, u_bsdf.0, u_bsdf.1);
        let mut beta = beta.mul(albedo);
        let roulette = M::from_bits(roulette);
        let (killed, survivor) = transport::roulette(beta, u_rr);
        let killed = roulette & killed;
        beta = V::select(roulette, survivor, beta);
        let black = beta.x.eq(zero) & beta.y.eq(zero) & beta.z.eq(zero);
        let alive = shading & !killed & !black;
        let origin = transport::offset(p, n, wi, eps);
        beta.store(&mut lanes.beta);
        origin.store(&mut lanes.origin);
        wi.store(&mut lanes.dir);
        let alive = alive.bits();
        let mut ended = shade & !alive;
        while ended != 0 {
            let lane = ended.trailing_zeros() as usize;
            ended &= ended - 1;
            radiance[lanes.slot[lane]] = get(&lanes.l, lane);
            lanes.active &= !(1 << lane);
        }
        for lane in 0..8 {
            lanes.depth[lane] += (alive >> lane) & 1;
        }
    }
}
