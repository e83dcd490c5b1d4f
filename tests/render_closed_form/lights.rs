//! Point, area, directional, spot and sphere lights against their closed forms, and the χ²
//! test of light sampling.

use super::*;
use glam::{DVec2, DVec3};
use lumen::math::stats;
use lumen::render;

/// L = ρ/π · Φ cosθ / (4π r²), integrated over each pixel's footprint by 4×4 Gauss–Legendre.
#[test]
fn lambertian_plane_under_point_light() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene(PLANE, dir.path()).unwrap();
    let film = render::render(&scene, &common::settings(&scene, 64, 2));
    let light = DVec3::new(0.3, -0.2, 1.0);
    let rho = [0.8, 0.5, 0.2];
    let intensity = 50.0 / (4.0 * std::f64::consts::PI);
    let radiance_at = |px: DVec2| -> f64 {
        let (o, d) = scene.camera_ray(px).unwrap();
        let x = o + d * (-o.z / d.z); // the plane z = 0
        let to = light - x;
        let r2 = to.length_squared();
        intensity * (to.z / r2.sqrt()) / r2 / std::f64::consts::PI
    };
    let nodes =
        [-0.861_136_311_594_053, -0.339_981_043_584_856, 0.339_981_043_584_856, 0.861_136_311_594_053];
    let weights =
        [0.347_854_845_137_454, 0.652_145_154_862_546, 0.652_145_154_862_546, 0.347_854_845_137_454];
    let tests = (48 * 48 * 3) as usize;
    let alpha = stats::sidak_alpha(0.01, tests);
    let (mut within3, mut worst_p) = (0, 1.0f64);
    for j in 0..48u32 {
        for i in 0..48u32 {
            let mut e = 0.0;
            for (a, wa) in nodes.iter().zip(weights) {
                for (b, wb) in nodes.iter().zip(weights) {
                    e += wa * wb / 4.0 * radiance_at(DVec2::new(i as f64 + a / 2.0, j as f64 + b / 2.0));
                }
            }
            for c in 0..3 {
                let m = film.mean.pixel(i, j)[c] as f64;
                let se = (film.variance.pixel(i, j)[c] as f64).sqrt();
                let z = (m - rho[c] * e) / se;
                assert!(se > 0.0 && z.is_finite());
                if z.abs() <= 3.0 {
                    within3 += 1;
                }
                worst_p = worst_p.min(stats::two_sided_p(z));
            }
        }
    }
    let frac = within3 as f64 / tests as f64;
    assert!(frac >= 0.99, "only {frac} of pixel channels within 3 standard errors (expect 0.9973)");
    assert!(worst_p >= alpha, "a pixel channel is off by p = {worst_p:.2e} < Šidák α = {alpha:.2e}");
}

/// Irradiance on the axis of a uniformly emitting rectangle with half sides a, b at distance d:
/// E = 2L [X/√(1+X²)·atan(Y/√(1+X²)) + Y/√(1+Y²)·atan(X/√(1+Y²))], X = a/d, Y = b/d.
#[test]
fn emissive_quad_on_axis_irradiance() {
    let lamp =
        "type = \"quad\"\ncorner = [-0.5, -0.3, 1.0]\nedge_u = [0.0, 0.6, 0.0]\nedge_v = [1.0, 0.0, 0.0]";
    let (got, se) = floor_under_lamp(lamp, 1 << 18);
    let (x, y, l) = (0.5f64, 0.3f64, 2.0f64);
    let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
    let e = 2.0 * l * (x / sx * (y / sx).atan() + y / sy * (x / sy).atan());
    let expected = 0.9 / std::f64::consts::PI * e;
    assert!(((got - expected) / se).abs() < 4.0, "got {got}, expected {expected}, standard error {se}");
    assert!((got / expected - 1.0).abs() < 2e-3, "got {got}, expected {expected}");
}

/// A plane under a directional light: L = ρ/π · E · cosθ, the same in every pixel; and a
/// checkerboard albedo shows its two values in its two kinds of squares.
#[test]
fn directional_light_and_checker_texture() {
    let text = r#"
[camera]
width = 16
height = 16
fx = 20.0
fy = 20.0
cx = 7.5
cy = 7.5
look_at = { origin = [0.0, 0.0, 2.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }
[[materials]]
name = "board"
type = "lambertian"
albedo = { checker = { squares = [2, 2], even = [0.8, 0.8, 0.8], odd = [0.2, 0.2, 0.2] } }
[[shapes]]
type = "quad"
corner = [-2.0, -2.0, 0.0]
edge_u = [4.0, 0.0, 0.0]
edge_v = [0.0, 4.0, 0.0]
material = "board"
[[lights]]
type = "directional"
to_light = [0.0, 0.6, 0.8]
irradiance = [3.0, 3.0, 3.0]
"#;
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene(text, dir.path()).unwrap();
    let film = render::render(&scene, &common::settings(&scene, 4, 2));
    let e = 3.0 * 0.8 / std::f64::consts::PI;
    // Quadrants: u < 0.5 ⇔ x < 0 (image left), v < 0.5 ⇔ y < 0 (image bottom, as y is down).
    for (i, j, rho) in [(2, 13, 0.8), (13, 2, 0.8), (2, 2, 0.2), (13, 13, 0.2)] {
        let got = film.mean.pixel(i, j)[1] as f64;
        assert!((got - rho * e).abs() < 1e-5 * e, "pixel ({i}, {j}): {got} vs {}", rho * e);
    }
}

/// A spot light (Mitsuba's falloff: full intensity to the beam width, linear in angle to 0 at
/// the cutoff) 2 units over a Lambertian floor: L = ρ/π · I·falloff(θ)·cos θ / r² in pixels
/// inside the beam, in the transition and outside, each averaged over its footprint (16×16
/// sub-pixel rays); the render within 0.5 %. Its power, 2π ∫ falloff sin θ dθ, against
/// quadrature.
#[test]
fn spot_light_falloff_and_power() {
    let text = r#"
[camera]
width = 32
height = 32
fov_deg = 60.0
look_at = { origin = [0.0, 0.0, 2.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }
[render]
max_depth = 2
sampler = "sobol"
[[materials]]
name = "floor"
type = "lambertian"
albedo = [0.5, 0.5, 0.5]
[[shapes]]
type = "quad"
corner = [-3.0, -3.0, 0.0]
edge_u = [6.0, 0.0, 0.0]
edge_v = [0.0, 6.0, 0.0]
material = "floor"
[[lights]]
type = "spot"
position = [0.0, 0.0, 2.0]
target = [0.0, 0.0, 0.0]
intensity = [4.0, 4.0, 4.0]
cutoff_deg = 25.0
beam_width_deg = 15.0
"#;
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene(text, dir.path()).unwrap();
    let film = render::render(&scene, &common::settings(&scene, 64, 2));
    let origin = scene.t_world_cam.translation;
    let (cutoff, beam) = (25f64.to_radians(), 15f64.to_radians());
    let radiance = |px: f64, py: f64| -> f64 {
        let d = scene.t_world_cam.rotation * scene.camera.pixel_ray(DVec2::new(px, py)).unwrap();
        let p = origin + d * (-origin.z / d.z);
        let r2 = (origin - p).length_squared();
        let cos = 2.0 / r2.sqrt();
        let theta = cos.acos();
        let falloff = if theta >= cutoff {
            0.0
        } else if theta <= beam {
            1.0
        } else {
            (cutoff - theta) / (cutoff - beam)
        };
        0.5 / std::f64::consts::PI * 4.0 * falloff * cos / r2
    };
    let mut seen = [0; 3];
    for (i, j) in [(15, 16), (20, 12), (23, 16), (25, 20), (26, 16), (31, 31), (16, 27)] {
        let n = 16;
        let mut want = 0.0;
        for a in 0..n {
            for b in 0..n {
                want += radiance(
                    i as f64 - 0.5 + (a as f64 + 0.5) / n as f64,
                    j as f64 - 0.5 + (b as f64 + 0.5) / n as f64,
                ) / (n * n) as f64;
            }
        }
        let got = film.mean.pixel(i, j)[0] as f64;
        // Which part of the beam the pixel centre is in: full, transition, outside.
        let d = scene.t_world_cam.rotation * scene.camera.pixel_ray(DVec2::new(i as f64, j as f64)).unwrap();
        let theta = (-d.z).acos();
        seen[if theta <= beam {
            0
        } else if theta < cutoff {
            1
        } else {
            2
        }] += 1;
        assert!((got - want).abs() <= 5e-3 * want + 1e-7, "pixel ({i}, {j}): {got} vs {want}");
    }
    assert!(seen.iter().all(|&n| n > 0), "beam, transition, outside: {seen:?} pixels");
    let steps = 100_000;
    let mut power = 0.0;
    for k in 0..steps {
        let theta = (k as f64 + 0.5) / steps as f64 * cutoff;
        let f = if theta <= beam { 1.0 } else { (cutoff - theta) / (cutoff - beam) };
        power += 2.0 * std::f64::consts::PI * f * theta.sin() * cutoff / steps as f64;
    }
    let closed = render::scene::spot_power_per_intensity(cutoff as f32, beam as f32) as f64;
    assert!((closed / power - 1.0).abs() < 1e-5, "{closed} vs {power}");
}

/// A sphere light facing a point: E = π·L·(R/d)², so a Lambertian floor shows
/// ρ·L·(R/d)² under it; the cone sampling of the sphere makes that exact to Monte Carlo noise.
#[test]
fn sphere_light_irradiance() {
    let (got, se) = floor_under_lamp("type = \"sphere\"\ncenter = [0.0, 0.0, 1.0]\nradius = 0.3", 1 << 14);
    let expected = 0.9 * 2.0 * 0.3f64.powi(2);
    eprintln!("sphere light: {got} vs {expected} (SE {se:.2e})");
    assert!(((got - expected) / se.max(1e-9)).abs() < 4.0 || (got / expected - 1.0).abs() < 1e-5);
    assert!((got / expected - 1.0).abs() < 1e-3, "got {got}, expected {expected}");
}

/// A disk light (Mitsuba's `disk`, turned to face down) over a point on its axis:
/// E = π·L·R²/(R² + d²), so the Lambertian floor shows ρ·L·R²/(R² + d²); the fan of triangles
/// the disk is built from falls short of it by about 10⁻⁵.
#[test]
fn disk_light_irradiance() {
    let lamp = "type = \"disk\"\ntransform = { scale = 0.3, rvec = [3.141592653589793, 0.0, 0.0], translation = [0.0, 0.0, 1.0] }";
    let (got, se) = floor_under_lamp(lamp, 1 << 14);
    let expected = 0.9 * 2.0 * 0.09 / (0.09 + 1.0);
    eprintln!("disk light: {got} vs {expected} (SE {se:.2e})");
    assert!(((got - expected) / se.max(1e-9)).abs() < 4.0, "got {got} ± {se}, expected {expected}");
}

/// Pearson's χ² test of light sampling, as for the BSDFs: 10⁶ directions sampled from a point
/// towards a sphere light (cone sampling), a square light (area sampling) and an emissive
/// mesh (a triangle picked by power, then a uniform point on it), binned
/// on a 16 × 32 grid over (cos θ ∈ [0.5, 1], φ); expected counts from the solid-angle density
/// the integrator's MIS uses (`area_light_pdf`), integrated over each cell (64 × 64 rays).
#[test]
fn chi_square_light_sampling() {
    use lumen::math::stats::{chi2_test, sidak_alpha};
    use lumen::render::geometry::Ray;
    use lumen::render::sampler::{Sampler, SamplerKind};
    let lights = [
        "type = \"sphere\"\ncenter = [0.2, 0.1, 2.0]\nradius = 0.9",
        "type = \"quad\"\ncorner = [-1.0, -0.8, 1.5]\nedge_u = [0.0, 1.6, 0.0]\nedge_v = [1.7, 0.0, 0.0]",
        // An emissive mesh: the four sides of a pyramid pointing its apex at the point, every
        // face in view (one light per triangle, picked by power, i.e. by area).
        "type = \"mesh\"\nfile = \"pyramid.obj\"",
    ];
    let pyramid = "v 0.1 0.05 1.5\nv -0.9 -0.8 2.2\nv 1.0 -0.7 2.2\nv 0.8 0.9 2.2\nv -0.7 1.0 2.2\nf 1 3 2\nf 1 4 3\nf 1 5 4\nf 1 2 5\n";
    let alpha = sidak_alpha(0.01, lights.len());
    for (case, shape) in lights.iter().enumerate() {
        let text = format!(
            "[camera]\nwidth = 4\nheight = 4\nfov_deg = 40.0\nlook_at = {{ origin = [0.0, 0.0, -1.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }}\n[[materials]]\nname = \"lamp\"\ntype = \"lambertian\"\nalbedo = [0.0, 0.0, 0.0]\nemission = [1.0, 1.0, 1.0]\n[[shapes]]\n{shape}\nmaterial = \"lamp\"\n"
        );
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("pyramid.obj"), pyramid).unwrap();
        let scene = common::scene(&text, dir.path()).unwrap();
        let p = glam::Vec3A::ZERO;
        let (nt, np, c0) = (16usize, 32usize, 0.5f32);
        let cell = |w: glam::Vec3A| {
            let t = (((w.z - c0) / (1.0 - c0) * nt as f32) as usize).min(nt - 1);
            let phi = w.y.atan2(w.x).rem_euclid(2.0 * std::f32::consts::PI);
            t * np + ((phi / (2.0 * std::f32::consts::PI) * np as f32) as usize).min(np - 1)
        };
        let samples = 1_000_000u64;
        let mut observed = vec![0.0f64; nt * np];
        for k in 0..samples {
            let mut s = Sampler::with_kind(SamplerKind::Independent, 7 + case as u64, k, 0);
            let (_, wi, _, pdf) = scene.sample_light(s.next2(), p).expect("the light faces the point");
            assert!(pdf.is_some_and(|v| v > 0.0) && wi.z >= c0);
            observed[cell(wi)] += 1.0;
        }
        let density = |w: glam::Vec3A| -> f64 {
            let ray = Ray { origin: p, dir: w };
            match scene.bvh.intersect(&ray, 0.0, f32::INFINITY) {
                Some(hit) => {
                    let surf = scene.surface(&ray, &hit);
                    scene.area_light_pdf(hit.prim, p, surf.p, surf.n) as f64
                }
                None => 0.0,
            }
        };
        // Fine enough that cells the light's edge barely clips still get their sliver.
        let sub = 64;
        let mut expected = vec![0.0f64; nt * np];
        for t in 0..nt {
            for q in 0..np {
                let mut sum = 0.0;
                for a in 0..sub {
                    let ct = c0 as f64
                        + (1.0 - c0 as f64) * (t as f64 + (a as f64 + 0.5) / sub as f64) / nt as f64;
                    let st = (1.0 - ct * ct).sqrt();
                    for b in 0..sub {
                        let phi = 2.0 * std::f64::consts::PI * (q as f64 + (b as f64 + 0.5) / sub as f64)
                            / np as f64;
                        sum += density(glam::Vec3A::new(
                            (st * phi.cos()) as f32,
                            (st * phi.sin()) as f32,
                            ct as f32,
                        ));
                    }
                }
                let area = (1.0 - c0 as f64) / nt as f64 * 2.0 * std::f64::consts::PI / np as f64;
                expected[t * np + q] = samples as f64 * sum / (sub * sub) as f64 * area;
            }
        }
        let total: f64 = expected.iter().sum();
        assert!(
            (total / samples as f64 - 1.0).abs() < 0.01,
            "case {case}: density integrates to {}",
            total / samples as f64
        );
        let pv = chi2_test(&observed, &expected).expect("enough cells");
        assert!(pv >= alpha, "case {case}: χ² p-value {pv:.3e} below {alpha:.3e}");
    }
}
