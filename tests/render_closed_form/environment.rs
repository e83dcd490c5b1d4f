//! Constant and image environments: closed forms, quadrature and the χ² test of their
//! sampling.

use super::*;
use lumen::render;

/// A constant environment of radiance L: a Lambertian sphere shows ρ·L (it is convex: no
/// light comes back from itself), the background L, and a glossy sphere, seen head-on at its
/// centre, L·∫ f cos dω — Blinn-Phong, where light and BSDF samples of the environment are
/// combined by MIS, the integral by quadrature.
#[test]
fn constant_environment() {
    for (material, kd) in [
        ("type = \"lambertian\"\nalbedo = [0.6, 0.4, 0.2]", [0.6f32, 0.4, 0.2]),
        (
            "type = \"blinn-phong\"\nalbedo = [0.3, 0.3, 0.3]\nspecular = [0.5, 0.5, 0.5]\nexponent = 20.0",
            [0.3; 3],
        ),
    ] {
        let text = format!(
            "[camera]\nwidth = 3\nheight = 3\nfx = 2000.0\nfy = 2000.0\ncx = 1.0\ncy = 1.0\nlook_at = {{ origin = [0.0, 0.0, 3.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }}\n[render]\nmax_depth = 4\n[[materials]]\nname = \"m\"\n{material}\n[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\nmaterial = \"m\"\n[[lights]]\ntype = \"environment\"\nradiance = [2.0, 2.0, 2.0]\n"
        );
        let dir = tempfile::tempdir().unwrap();
        let scene = common::scene(&text, dir.path()).unwrap();
        let mut s = common::settings(&scene, 1 << 16, 4);
        s.crop = Some([1, 1, 2, 2]);
        let film = render::render(&scene, &s);
        let bsdf = scene.materials[0].bsdf;
        let kd = glam::Vec3A::from(kd);
        // ∫ f(n, wi) cos θi dωi over the hemisphere around n = +z, wo = n.
        let (nt, np) = (2000, 400);
        let mut albedo = [0.0f64; 3];
        for i in 0..nt {
            let ct = (i as f64 + 0.5) / nt as f64;
            let st = (1.0 - ct * ct).sqrt();
            for j in 0..np {
                let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / np as f64;
                let wi = glam::Vec3A::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, ct as f32);
                let f = bsdf.eval(kd, glam::Vec3A::Z, glam::Vec3A::Z, wi);
                for c in 0..3 {
                    albedo[c] += f[c] as f64 * ct * 2.0 * std::f64::consts::PI / (nt * np) as f64;
                }
            }
        }
        for c in 0..3 {
            let want = 2.0 * albedo[c];
            let got = film.mean.data[c] as f64;
            let se = (film.variance.data[c] as f64).sqrt();
            eprintln!("{:?} channel {c}: {got:.5} vs {want:.5} (SE {se:.1e})", bsdf);
            assert!(
                ((got - want) / se).abs() < 4.0 && (got / want - 1.0).abs() < 0.01,
                "channel {c}: {got} vs {want}"
            );
        }
        // The background: the environment itself.
        let mut s = common::settings(&scene, 4, 4);
        s.crop = Some([0, 0, 1, 1]);
        let mut far = scene;
        far.camera.intrinsics.fx = 2.0;
        far.camera.intrinsics.fy = 2.0;
        let film = render::render(&far, &s);
        assert!((film.mean.data[0] - 2.0).abs() < 1e-6, "background {}", film.mean.data[0]);
    }
}

/// A 32 × 17 sky for the image-environment tests: a bluish gradient, a small bright sun
/// (about 2·10⁴ times the sky) and a dark ground, written as EXR into `dir`.
fn sky_map(dir: &std::path::Path) -> std::path::PathBuf {
    let (w, h) = (32u32, 17u32);
    let mut img = lumen::image::Image::new(w, h, 3);
    for y in 0..h {
        for x in 0..w {
            let c = if (x, y) == (9, 4) || (x, y) == (10, 4) {
                [4000.0, 3500.0, 3000.0]
            } else if y > 8 {
                [0.05, 0.04, 0.03]
            } else {
                [0.3 + 0.05 * y as f32, 0.4 + 0.02 * x as f32 / w as f32, 0.8]
            };
            img.pixel_mut(x, y).copy_from_slice(&c);
        }
    }
    let file = dir.join("sky.exr");
    lumen::image::io::write_exr(&file, &img).unwrap();
    file
}

/// Pearson's χ² test of image-environment sampling: 10⁶ directions drawn by the scene's light
/// sampling, binned on a 32 × 64 grid in the map's own (v, u) = (θ/π, φ/2π), each bin a
/// quarter of a map cell, so the density the integrator's MIS uses (`Scene::environment`) is
/// constant over it and the expected count is that density × the bin's solid angle. Each
/// sample's weight must be radiance / density.
#[test]
fn chi_square_environment_map_sampling() {
    use lumen::math::stats::chi2_test;
    use lumen::render::envmap::direction_to_uv;
    use lumen::render::sampler::{Sampler, SamplerKind};
    use std::f64::consts::PI;
    let dir = tempfile::tempdir().unwrap();
    sky_map(dir.path());
    let text = "[camera]\nwidth = 4\nheight = 4\nfov_deg = 40.0\nlook_at = { origin = [0.0, 0.0, -1.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }\n[[lights]]\ntype = \"environment\"\nmap = \"sky.exr\"\nscale = 0.5\n";
    let scene = common::scene(text, dir.path()).unwrap();
    let (nt, np) = (32usize, 64usize);
    let bin = |w: glam::Vec3A| {
        let (u, v) = direction_to_uv(w);
        ((v * nt as f32) as usize).min(nt - 1) * np + ((u * np as f32) as usize).min(np - 1)
    };
    let samples = 1_000_000u64;
    let mut observed = vec![0.0f64; nt * np];
    for k in 0..samples {
        let mut s = Sampler::with_kind(SamplerKind::Independent, 11, k, 0);
        let (li, wi, dist, pdf) =
            scene.sample_light(s.next2(), glam::Vec3A::ZERO).expect("the sky has light");
        let (le, p) = scene.environment(wi).unwrap();
        assert!(dist.is_infinite() && pdf == Some(p), "{pdf:?} vs {p}");
        assert!((li * p - le).abs().max_element() <= 1e-4 * le.max_element(), "{li} · {p} vs {le}");
        observed[bin(wi)] += 1.0;
    }
    let mut expected = vec![0.0f64; nt * np];
    for t in 0..nt {
        let (ta, tb) = (PI * t as f64 / nt as f64, PI * (t + 1) as f64 / nt as f64);
        let tm = 0.5 * (ta + tb);
        for q in 0..np {
            // The bin's centre direction, in the map's convention d = (sin θ sin φ, cos θ, −sin θ cos φ).
            let phi = 2.0 * PI * (q as f64 + 0.5) / np as f64;
            let d = glam::Vec3A::new(
                (tm.sin() * phi.sin()) as f32,
                tm.cos() as f32,
                (-tm.sin() * phi.cos()) as f32,
            );
            let omega = 2.0 * PI / np as f64 * (ta.cos() - tb.cos());
            expected[t * np + q] = samples as f64 * scene.environment(d).unwrap().1 as f64 * omega;
        }
    }
    let total: f64 = expected.iter().sum();
    assert!((total / samples as f64 - 1.0).abs() < 1e-3, "density integrates to {}", total / samples as f64);
    let pv = chi2_test(&observed, &expected).expect("enough cells");
    eprintln!("environment map χ² p-value {pv:.3}");
    assert!(pv >= 0.01, "χ² p-value {pv:.3e} below 0.01");
}

/// An image environment over a Lambertian plane facing up: every point of the plane sees the
/// upper hemisphere unoccluded, so it shows ρ/π·∫ L(ω) cos θ dω, the integral by quadrature of
/// the map's own (bilinear) radiance; a pixel looking at the sky shows the map there exactly.
#[test]
fn environment_map_lights_a_plane() {
    use std::f64::consts::PI;
    let dir = tempfile::tempdir().unwrap();
    sky_map(dir.path());
    let text = "[camera]\nwidth = 3\nheight = 3\nfx = 2000.0\nfy = 2000.0\ncx = 1.0\ncy = 1.0\nlook_at = { origin = [0.0, 1.0, 0.0], target = [0.0, 0.0, 0.0], up = [0.0, 0.0, -1.0] }\n[render]\nmax_depth = 2\n[[materials]]\nname = \"m\"\ntype = \"lambertian\"\nalbedo = [0.5, 0.6, 0.7]\n[[shapes]]\ntype = \"quad\"\ncorner = [-50.0, 0.0, -50.0]\nedge_u = [0.0, 0.0, 100.0]\nedge_v = [100.0, 0.0, 0.0]\nmaterial = \"m\"\n[[lights]]\ntype = \"environment\"\nmap = \"sky.exr\"\nscale = 0.5\n";
    let scene = common::scene(text, dir.path()).unwrap();
    let mut s = common::settings(&scene, 1 << 16, 2);
    s.crop = Some([1, 1, 2, 2]);
    let film = render::render(&scene, &s);
    // E = ∫ L cos θ dω over the upper hemisphere (about +y), midpoint rule in (cos θ, φ).
    let (nt, np) = (1000, 2000);
    let mut e = [0.0f64; 3];
    for a in 0..nt {
        let ct = (a as f64 + 0.5) / nt as f64;
        let st = (1.0 - ct * ct).sqrt();
        for b in 0..np {
            let phi = 2.0 * PI * (b as f64 + 0.5) / np as f64;
            let w = glam::Vec3A::new((st * phi.cos()) as f32, ct as f32, (st * phi.sin()) as f32);
            let l = scene.environment(w).unwrap().0;
            for c in 0..3 {
                e[c] += l[c] as f64 * ct * 2.0 * PI / (nt * np) as f64;
            }
        }
    }
    for (c, rho) in [0.5, 0.6, 0.7].into_iter().enumerate() {
        let want = rho / PI * e[c];
        let (got, se) = (film.mean.data[c] as f64, (film.variance.data[c] as f64).sqrt());
        eprintln!("environment map, channel {c}: {got:.5} vs {want:.5} (SE {se:.1e})");
        assert!(
            ((got - want) / se).abs() < 4.0 && (got / want - 1.0).abs() < 0.005,
            "channel {c}: {got} vs {want}"
        );
    }
    // Looking up from under the plane's edge: the sky itself, the pixel's box filter aside
    // (a narrow field of view, so the footprint is tiny).
    let text = text.replace(
        "origin = [0.0, 1.0, 0.0], target = [0.0, 0.0, 0.0], up = [0.0, 0.0, -1.0]",
        "origin = [0.0, 1.0, 0.0], target = [0.3, 1.5, -1.0], up = [0.0, 1.0, 0.0]",
    );
    let scene = common::scene(&text, dir.path()).unwrap();
    let mut s = common::settings(&scene, 16, 2);
    s.crop = Some([1, 1, 2, 2]);
    let film = render::render(&scene, &s);
    let want = scene.environment(glam::Vec3A::new(0.3, 0.5, -1.0).normalize()).unwrap().0;
    for c in 0..3 {
        assert!(
            (film.mean.data[c] - want[c]).abs() < 1e-3 * want[c],
            "sky {c}: {} vs {}",
            film.mean.data[c],
            want[c]
        );
    }
}
