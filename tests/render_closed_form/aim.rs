//! Light paths aimed at the delta objects (`render::scene::Aim`, photon mapping's light
//! paths) against the lights' own emission sampling.

use crate::common;
use glam::Vec3A;
use lumen::math::stats::chi2_sf;
use lumen::render::sampler::Sampler;
use lumen::render::scene::{Aim, Light};

/// Aimed emission keeps every direction's share of each light's power. For a point, a spot,
/// a sphere and a quad light beside a glass and a mirror sphere, the flux weights β of
/// 2·10⁵ rays, summed per cell of 12 × 16 cells (sin(θ/2), φ) about the direction from the
/// light to the glass, estimate the flux leaving through each cell, once with aimed rays and
/// once with `sample_emission`'s. The two estimates agree cell by cell: Σ z² against χ² with
/// one degree of freedom per cell, at α = 0.01 (Šidák over the lights). And from the point
/// light at least the aimed half's share, ½ · ½ for two spheres, of the aimed rays leave
/// towards the glass, where about 2 % of plain ones do.
#[test]
fn aimed_emission_keeps_each_directions_power() {
    let head = "[camera]\nwidth = 4\nheight = 4\nfov_deg = 40.0\nlook_at = { origin = [0.0, 1.0, -5.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }\n[[materials]]\nname = \"glass\"\ntype = \"dielectric\"\nior = 1.5\nalbedo = [1.0, 1.0, 1.0]\n[[materials]]\nname = \"mirror\"\ntype = \"mirror\"\nalbedo = [1.0, 1.0, 1.0]\n[[materials]]\nname = \"grey\"\ntype = \"lambertian\"\nalbedo = [0.5, 0.5, 0.5]\n[[materials]]\nname = \"lamp\"\ntype = \"lambertian\"\nalbedo = [0.0, 0.0, 0.0]\nemission = [1.0, 2.0, 3.0]\n[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, 0.5, 0.0]\nradius = 0.5\nmaterial = \"glass\"\n[[shapes]]\ntype = \"sphere\"\ncenter = [2.0, 0.4, 1.0]\nradius = 0.4\nmaterial = \"mirror\"\n[[shapes]]\ntype = \"quad\"\ncorner = [-4.0, 0.0, -4.0]\nedge_u = [0.0, 0.0, 8.0]\nedge_v = [8.0, 0.0, 0.0]\nmaterial = \"grey\"\n";
    let glass = Vec3A::new(0.0, 0.5, 0.0);
    let at = Vec3A::new(-1.8, 1.6, -0.4);
    let lights = [
        ("point", "[[lights]]\ntype = \"point\"\nposition = [-1.8, 1.6, -0.4]\nintensity = [1.0, 2.0, 3.0]\n".to_string()),
        ("spot", "[[lights]]\ntype = \"spot\"\nposition = [-1.8, 1.6, -0.4]\ntarget = [0.0, 0.5, 0.0]\nintensity = [1.0, 2.0, 3.0]\ncutoff_deg = 40.0\nbeam_width_deg = 25.0\n".to_string()),
        ("sphere", "[[shapes]]\ntype = \"sphere\"\ncenter = [-1.8, 1.6, -0.4]\nradius = 0.05\nmaterial = \"lamp\"\n".to_string()),
        ("quad", "[[shapes]]\ntype = \"quad\"\ncorner = [-1.9, 1.6, -0.5]\nedge_u = [0.2, 0.0, 0.0]\nedge_v = [0.0, 0.0, 0.2]\nmaterial = \"lamp\"\n".to_string()),
    ];
    let dir = tempfile::tempdir().unwrap();
    let (nt, np) = (12usize, 16usize);
    let samples = 200_000u64;
    let alpha = lumen::math::stats::sidak_alpha(0.01, lights.len());
    let axis = (glass - at).normalize();
    let (t, b) = lumen::render::transport::basis(axis);
    let tau = 2.0 * std::f64::consts::PI;
    let cell = |w: Vec3A| {
        let half = (((1.0 - w.dot(axis).clamp(-1.0, 1.0)) / 2.0).sqrt() as f64).min(1.0);
        let phi = (w.dot(b) as f64).atan2(w.dot(t) as f64).rem_euclid(tau);
        ((half * nt as f64) as usize).min(nt - 1) * np + ((phi / tau * np as f64) as usize).min(np - 1)
    };
    for (name, text) in lights {
        let scene = common::scene(&format!("{head}{text}"), dir.path()).unwrap();
        let aim = Aim::of(&scene).expect("two delta objects");
        // Per cell, the sums of β and β² over all rays (a ray adds to its cell only).
        let mut sums = [vec![(0.0f64, 0.0f64); nt * np], vec![(0.0, 0.0); nt * np]];
        let mut towards_glass = 0u64;
        for k in 0..samples {
            // Independent streams, so that the two estimates' variances add.
            let (mut s, mut o) = (Sampler::new(5, k, 0), Sampler::new(6, k, 0));
            let (u_pick, u_pos, u_dir, u_aim) = (s.next(), s.next2(), s.next2(), s.next());
            let aimed = aim.sample_emission(&scene, u_pick, u_pos, u_dir, u_aim);
            let plain = scene.sample_emission(o.next(), o.next2(), o.next2());
            for (sum, e) in sums.iter_mut().zip([aimed, plain]) {
                let Some(e) = e else { continue };
                assert!(e.beta.is_finite() && e.beta.min_element() >= 0.0, "{name}: β {}", e.beta);
                let c = &mut sum[cell(e.ray.dir)];
                c.0 += e.beta.x as f64;
                c.1 += (e.beta.x as f64).powi(2);
            }
            if let Some(e) = aimed {
                let to = glass - e.ray.origin;
                let d = to.length();
                towards_glass += (e.ray.dir.dot(to / d) >= (1.0 - 0.25 / (d * d)).sqrt()) as u64;
            }
        }
        let n = samples as f64;
        let (mut z2, mut cells) = (0.0, 0usize);
        for (a, p) in sums[0].iter().zip(&sums[1]) {
            let (ma, mp) = (a.0 / n, p.0 / n);
            let var = (a.1 / n - ma * ma).max(0.0) / n + (p.1 / n - mp * mp).max(0.0) / n;
            if var > 0.0 {
                z2 += (ma - mp).powi(2) / var;
                cells += 1;
            }
        }
        let p = chi2_sf(z2, cells as f64);
        eprintln!("{name}: Σz² {z2:.1} over {cells} cells, p {p:.3}; {towards_glass} of {samples} aimed rays towards the glass");
        assert!(cells >= 40, "{name}: only {cells} cells hold flux");
        assert!(
            p >= alpha,
            "{name}: aimed and plain emission differ, Σz² {z2:.1} over {cells} cells (p {p:.2e})"
        );
        if name == "point" {
            assert!(
                towards_glass as f64 >= 0.25 * n,
                "{name}: {towards_glass} of {samples} towards the glass"
            );
        }
        assert!(scene
            .lights
            .iter()
            .all(|l| matches!(l, Light::Point { .. } | Light::Spot { .. } | Light::Area { .. })));
    }
}
