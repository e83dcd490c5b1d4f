//! The integrators against each other and against closed forms: pbrt-v4's analytic spheres
//! for every integrator, light tracing against the path tracer where both see everything
//! (no delta surface in view), the light tracer's determinism, and χ² tests of the rays drawn
//! from every kind of light.

use crate::common;
use glam::Vec3A;
use lumen::image::metrics;
use lumen::math::stats::{chi2_test, sidak_alpha};
use lumen::render::{self, integrators, Scene};

/// pbrt-v4's `integrators_test.cpp`: inside a unit sphere of albedo ½, a point light of
/// intensity π at the centre (direct ½, each bounce halving: L = 1), or the sphere's wall
/// emitting Lₑ = ½ inwards (L = Lₑ/(1 − ρ) = 1). Every integrator's image mean at 256 spp is
/// within 0.025 of 1 (pbrt's bound).
#[test]
fn every_integrator_sees_pbrts_analytic_spheres() {
    let wall = |emission: &str, light: &str| {
        format!(
            "[camera]\nwidth = 16\nheight = 16\nfov_deg = 60.0\nlook_at = {{ origin = [0.0, 0.0, 0.0], target = [0.0, 0.0, 1.0], up = [0.0, 1.0, 0.0] }}\n[[materials]]\nname = \"wall\"\ntype = \"lambertian\"\nalbedo = [0.5, 0.5, 0.5]\n{emission}\n[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\nmaterial = \"wall\"\nreverse_orientation = true\n{light}"
        )
    };
    let pi = std::f64::consts::PI;
    let cases = [
        ("point light", wall("", &format!("[[lights]]\ntype = \"point\"\nposition = [0.0, 0.0, 0.0]\nintensity = [{pi}, {pi}, {pi}]\n"))),
        ("glowing wall", wall("emission = [0.5, 0.5, 0.5]", "")),
    ];
    let dir = tempfile::tempdir().unwrap();
    for (what, text) in cases {
        let scene = common::scene(&text, dir.path()).unwrap();
        for kind in integrators::REGISTRY {
            let mut s = common::settings(&scene, 256, 1000);
            s.integrator = kind;
            let film = render::try_render(&scene, &s).unwrap();
            let mean = film.mean.channel_means();
            eprintln!("{what}, {}: {mean:?}", kind.name);
            for m in mean {
                assert!((m - 1.0).abs() < 0.025, "{what}, {}: image mean {m}", kind.name);
            }
        }
    }
}

/// Renders `scene` with the path tracer and with `light` at `spp`, and compares them by the
/// per-pixel z-test (both variances, Šidák at α = 0.01): ≥ 99.75 % of pixel channels pass
/// and the channel means agree within 1 %.
fn light_matches_path(name: &str, scene: &Scene, spp: u32, depth: u32) {
    matches_path("light", name, scene, spp, depth)
}

/// `light_matches_path` for the integrator `integrator`.
fn matches_path(integrator: &str, name: &str, scene: &Scene, spp: u32, depth: u32) {
    let mut s = common::settings(scene, spp, depth);
    let path = render::try_render(scene, &s).unwrap();
    s.integrator = integrators::find(integrator).unwrap();
    let light = render::try_render(scene, &s).unwrap();
    assert!(!light.mean.has_non_finite() && light.dropped_samples == 0, "{name}");
    let a = metrics::agreement(&light.mean, &light.variance, &path.mean, &path.variance, 0.01).unwrap();
    eprintln!("{name}: {a:?}");
    for (c, e) in a.mean_rel_err.iter().enumerate() {
        assert!(e.abs() < 0.01, "{name} channel {c}: means differ by {:.3} %", 100.0 * e);
    }
    assert!(a.pass_fraction >= 0.9975, "{name}: {} of {} pixel channels fail the z-test", a.failed, a.tested);
}

/// Light tracing against the path tracer on scenes without delta surfaces in view (which a
/// light path cannot reach the camera through): the Cornell box (area light in view,
/// interreflection), Mitsuba's Cornell box through its gaussian pixel filter, the glossy
/// spheres (rough conductors), the depth-of-field scene with its spheres made diffuse (the
/// thin lens; its copper sphere mirrors a small sun, which a light path reaches the camera
/// from only rarely and then with a large splat: at 256 passes their spread underestimates
/// that tail, and the test would measure the estimator's tail, not its mean) and a board seen
/// through strong barrel distortion.
#[test]
fn light_tracing_agrees_with_the_path_tracer() {
    let root = common::root();
    let scenes = root.join("pipelines/scenes");
    let cornell = render::load(&scenes.join("cornell-box.toml")).unwrap();
    light_matches_path("cornell-box", &cornell, 64, 8);
    let params = [("rfilter".to_string(), "gaussian".to_string()), ("res".to_string(), "64".to_string())];
    let gaussian =
        render::scene::load_mitsuba(&root.join("tests/data/mitsuba/cornell-box.xml"), &params).unwrap();
    assert_eq!(gaussian.render.filter, render::filter::PixelFilter::Gaussian);
    light_matches_path("cornell-box.xml (gaussian filter)", &gaussian, 256, 8);
    let glossy = render::load(&scenes.join("glossy-spheres.toml")).unwrap();
    light_matches_path("glossy-spheres", &glossy, 256, 6);
    let dof = std::fs::read_to_string(scenes.join("depth-of-field.toml")).unwrap();
    assert!(dof.contains("type = \"mirror\"") && dof.contains("type = \"conductor\""));
    let diffuse: String = dof
        .replace("type = \"mirror\"", "type = \"lambertian\"")
        .replace("type = \"conductor\"", "type = \"lambertian\"")
        .replace("../../", &format!("{}/", root.display()))
        .lines()
        .filter(|l| !["distribution", "alpha", "eta", "k "].iter().any(|k| l.starts_with(k)))
        .map(|l| format!("{l}\n"))
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let dof = common::scene(&diffuse, dir.path()).unwrap();
    assert!(dof.lens.is_some());
    light_matches_path("depth-of-field, spheres made diffuse", &dof, 256, 6);
    let board = render::load(&scenes.join("calib-board-strong-distortion.toml")).unwrap();
    assert!(!board.camera.distortion.is_zero());
    light_matches_path("calib-board-strong-distortion", &board, 16, 2);
}

/// Bidirectional path tracing against the path tracer by the same z-test: the Cornell box,
/// through the gaussian filter, the glossy spheres (rough conductors, a small area light),
/// the Cornell box through a thin lens, and the caustic, where the light tracer's strategies
/// carry the caustic (against Mitsuba's particle tracer, outside the glass), and scenes lit
/// from infinity.
#[test]
fn bdpt_agrees_with_the_path_tracer() {
    let root = common::root();
    let scenes = root.join("pipelines/scenes");
    let cornell = render::load(&scenes.join("cornell-box.toml")).unwrap();
    matches_path("bdpt", "cornell-box", &cornell, 32, 8);
    let params = [("rfilter".to_string(), "gaussian".to_string()), ("res".to_string(), "64".to_string())];
    let gaussian =
        render::scene::load_mitsuba(&root.join("tests/data/mitsuba/cornell-box.xml"), &params).unwrap();
    matches_path("bdpt", "cornell-box.xml (gaussian filter)", &gaussian, 256, 8);
    let glossy = render::load(&scenes.join("glossy-spheres.toml")).unwrap();
    matches_path("bdpt", "glossy-spheres", &glossy, 256, 6);
    let text = std::fs::read_to_string(scenes.join("cornell-box.toml")).unwrap();
    let lens = text
        .replace("[camera]\n", "[camera]\naperture_radius = 0.1\nfocus_distance = 3.0\n")
        .replace("width = 256\nheight = 256", "width = 64\nheight = 64")
        .replace("../../", &format!("{}/", root.display()));
    assert!(lens.contains("aperture_radius") && lens.contains("width = 64"));
    let dir = tempfile::tempdir().unwrap();
    let lens = common::scene(&lens, dir.path()).unwrap();
    assert!(lens.lens.is_some());
    matches_path("bdpt", "cornell-box through a thin lens", &lens, 256, 8);
    // The caustic against Mitsuba's particle tracer, outside the pixels that see the glass:
    // there light goes light → glass → floor → glass → camera, a path with a diffuse vertex
    // between two delta ones, which no join can make, so only the camera subpath finds it (as
    // a path tracer does, with a tail both variance estimates miss).
    let mitsuba = root.join("tests/data/mitsuba");
    let caustic = render::load(&mitsuba.join("caustic.xml")).unwrap();
    let mut s = common::settings(&caustic, 1024, 8);
    s.integrator = integrators::find("bdpt").unwrap();
    let mut film = render::try_render(&caustic, &s).unwrap();
    let read = |name: &str| lumen::image::io::read_exr(&mitsuba.join(name)).unwrap();
    let (full, ptracer, full_var) =
        (read("caustic-full.exr"), read("caustic.exr"), read("caustic-full_variance.exr"));
    let mut var = full_var.clone();
    let mut glass = 0;
    for px in 0..full.data.len() / 3 {
        // caustic-full.exr takes the path tracer's pixels where the glass is seen.
        if (0..3).any(|c| full.data[3 * px + c] != ptracer.data[3 * px + c]) {
            glass += 1;
            for c in 3 * px..3 * px + 3 {
                film.mean.data[c] = full.data[c];
                film.variance.data[c] = 0.0;
                var.data[c] = 0.0;
            }
        }
    }
    assert!(glass > 500, "{glass} pixels see the glass");
    let a = metrics::agreement(&film.mean, &film.variance, &full, &var, 0.01).unwrap();
    let pass = 1.0 - a.failed as f64 / (a.tested - 3 * glass) as f64;
    eprintln!("caustic, outside the glass: {a:?}, {pass:.5} pass");
    assert!(a.mean_rel_err.iter().all(|e| e.abs() < 0.01), "caustic: {a:?}");
    assert!(pass >= 0.9975, "caustic: {} of {} pixel channels fail", a.failed, a.tested - 3 * glass);
    // Lights at infinity: an image sky with a small sun (a mirror sphere seen directly), a
    // constant sky seen through glass and lighting the floor through it, and a board under a
    // directional light seen through strong distortion.
    let envmap = render::load(&scenes.join("envmap-spheres.toml")).unwrap();
    matches_path("bdpt", "envmap-spheres", &envmap, 256, 6);
    let glass = render::load(&scenes.join("glass-environment.toml")).unwrap();
    matches_path("bdpt", "glass-environment", &glass, 256, 8);
    let board = render::load(&scenes.join("calib-board-strong-distortion.toml")).unwrap();
    assert!(matches!(board.lights[..], [render::scene::Light::Directional { .. }, ..]));
    matches_path("bdpt", "calib-board-strong-distortion", &board, 16, 2);
}

/// The light tracer's and the bidirectional path tracer's images do not depend on the thread
/// count, and a crop holds exactly the full image's pixels (every pass traces the whole
/// image's light paths; bdpt's camera samples ride on those of the crop's pixels).
#[test]
fn light_tracing_is_deterministic_and_crops_exactly() {
    let scene = render::load(&common::root().join("pipelines/scenes/cornell-box.toml")).unwrap();
    for name in ["light", "bdpt"] {
        let (mut s, one, two) = on_one_and_two_threads(&scene, name);
        assert!(one.mean.data == two.mean.data && one.variance.data == two.variance.data, "{name}");
        s.crop = Some([100, 30, 160, 90]);
        let crop = render::render(&scene, &s);
        for y in 0..60 {
            for x in 0..60 {
                for c in 0..3 {
                    let i = 3 * ((y + 30) * 256 + x + 100) + c;
                    let j = 3 * (y * 60 + x) + c;
                    assert_eq!(crop.mean.data[j], one.mean.data[i], "{name} ({x}, {y})");
                    assert_eq!(crop.variance.data[j], one.variance.data[i], "{name} ({x}, {y})");
                }
            }
        }
    }
}

/// Photon mapping (with and without the final gather, by the k nearest and by a fixed radius
/// in the grid and in the kd-tree) and progressive photon mapping against the path tracer on
/// the Cornell box at their default photon counts: channel means within 1 % (at those counts
/// the kernel's blur is what the z-test would catch at the box's edges; the z-test across
/// seeds follows).
#[test]
fn photon_mapping_agrees_with_the_path_tracer_on_average() {
    use lumen::render::photons::IndexKind;
    let scene = render::load(&common::root().join("pipelines/scenes/cornell-box.toml")).unwrap();
    let mut s = common::settings(&scene, 64, 8);
    s.crop = None;
    let path = render::render(&scene, &s);
    let reference = path.mean.channel_means();
    let base = s.photon;
    let cases = [
        ("pm, k nearest", "pm", lumen::render::integrators::PhotonSettings { ..base }, 4),
        (
            "pm, final gather",
            "pm",
            lumen::render::integrators::PhotonSettings { final_gather: true, ..base },
            4,
        ),
        (
            "pm, radius, grid",
            "pm",
            lumen::render::integrators::PhotonSettings {
                radius: Some(0.03),
                index: Some(IndexKind::Grid),
                ..base
            },
            4,
        ),
        (
            "pm, radius, kd-tree",
            "pm",
            lumen::render::integrators::PhotonSettings {
                radius: Some(0.03),
                index: Some(IndexKind::Kdtree),
                ..base
            },
            4,
        ),
        ("sppm", "sppm", base, 64),
    ];
    for (what, name, photon, spp) in cases {
        let mut s = common::settings(&scene, spp, 8);
        s.integrator = integrators::find(name).unwrap();
        s.photon = photon;
        let film = render::try_render(&scene, &s).unwrap();
        assert!(!film.mean.has_non_finite() && film.dropped_samples == 0, "{what}");
        for (c, (m, r)) in film.mean.channel_means().iter().zip(&reference).enumerate() {
            assert!((m / r - 1.0).abs() < 0.01, "{what} channel {c}: mean {m} against the path tracer's {r}");
        }
    }
}

/// Photon mapping and progressive photon mapping pass the per-pixel z-test against the path
/// tracer on the Cornell box (64 × 64), their variance of the mean taken across 8 renders
/// with different seeds (one render's photons are shared by all its pixels' samples, so its
/// own variance leaves them out; SPPM's passes give none): ≥ 99.75 % of pixel channels at
/// α = 0.01 (Šidák) and means within 1 %, as the other integrators.
#[test]
fn photon_mapping_passes_the_z_test_across_seeds() {
    let root = common::root();
    let text = std::fs::read_to_string(root.join("pipelines/scenes/cornell-box.toml"))
        .unwrap()
        .replace("width = 256\nheight = 256", "width = 64\nheight = 64")
        .replace("../../", &format!("{}/", root.display()));
    assert!(text.contains("width = 64"));
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene(&text, dir.path()).unwrap();
    let path = render::try_render(&scene, &common::settings(&scene, 1024, 8)).unwrap();
    // pm with 2·10⁶ photons (500 per pixel), so that the blur of its 50 nearest stays below
    // the noise; SPPM's radii shrink by themselves.
    for (name, spp, photons) in [("pm", 16, Some(2_000_000)), ("sppm", 256, None)] {
        let seeds = 8;
        let films: Vec<_> = (0..seeds)
            .map(|k| {
                let mut s = common::settings(&scene, spp, 8);
                s.integrator = integrators::find(name).unwrap();
                s.photon.count = photons;
                s.seed = 100 + k;
                render::try_render(&scene, &s).unwrap()
            })
            .collect();
        let mut mean = films[0].mean.clone();
        let mut var = films[0].variance.clone();
        for i in 0..mean.data.len() {
            let xs: Vec<f64> = films.iter().map(|f| f.mean.data[i] as f64).collect();
            let m = xs.iter().sum::<f64>() / seeds as f64;
            let v = xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (seeds - 1) as f64;
            mean.data[i] = m as f32;
            var.data[i] = (v / seeds as f64) as f32;
        }
        let a = metrics::agreement(&mean, &var, &path.mean, &path.variance, 0.01).unwrap();
        eprintln!("{name} across {seeds} seeds: {a:?}");
        assert!(a.mean_rel_err.iter().all(|e| e.abs() < 0.01), "{name}: {a:?}");
        assert!(
            a.pass_fraction >= 0.9975,
            "{name}: {} of {} pixel channels fail the z-test",
            a.failed,
            a.tested
        );
    }
}

/// Progressive photon mapping is consistent: on the caustic its relMSE over the caustic
/// against Mitsuba's particle tracer falls from 4 to 16 to 64 passes, and its whole-image
/// relMSE against the whole-image reference too (the glass seen directly included).
#[test]
fn sppm_error_falls_as_passes_grow() {
    let dir = common::root().join("tests/data/mitsuba");
    let scene = render::load(&dir.join("caustic.xml")).unwrap();
    let caustic = lumen::image::io::read_exr(&dir.join("caustic.exr")).unwrap();
    let full = lumen::image::io::read_exr(&dir.join("caustic-full.exr")).unwrap();
    let mut last = (f64::INFINITY, f64::INFINITY);
    for passes in [4, 16, 64] {
        let mut s = common::settings(&scene, passes, 8);
        s.integrator = integrators::find("sppm").unwrap();
        let film = render::try_render(&scene, &s).unwrap();
        assert_eq!(film.samples, passes);
        let e = (
            metrics::relmse(&film.mean, &caustic, Some([58, 48, 90, 66])),
            metrics::relmse(&film.mean, &full, None),
        );
        eprintln!("sppm, {passes} passes: relMSE over the caustic {:.3e}, whole image {:.3e}", e.0, e.1);
        assert!(e.0 < last.0 && e.1 < last.1, "{passes} passes: {e:?} after {last:?}");
        last = e;
    }
}

/// Photon mapping's and bidirectional path tracing's images do not depend on the thread
/// count.
#[test]
fn photon_mapping_and_bdpt_are_deterministic() {
    let scene = render::load(&common::root().join("tests/data/mitsuba/caustic.xml")).unwrap();
    for name in ["pm", "sppm", "bdpt"] {
        let (_, one, two) = on_one_and_two_threads(&scene, name);
        assert!(one.mean.data == two.mean.data, "{name}");
    }
}

/// The integrator `name`'s render of `scene` (4 samples, depth 8) on one thread and on two,
/// with the settings of the second.
fn on_one_and_two_threads(scene: &Scene, name: &str) -> (render::Settings, render::Film, render::Film) {
    let mut s = common::settings(scene, 4, 8);
    s.integrator = integrators::find(name).unwrap();
    s.threads = Some(1);
    let one = render::render(scene, &s);
    s.threads = Some(2);
    let two = render::render(scene, &s);
    (s, one, two)
}

/// A time budget renders in rounds (1, 2, 4, … samples, `first_sample` moving on) whose
/// merged film is the film of one render of all the samples: with a budget no render can
/// spend and an 11-sample cap, the same means (to float rounding) and variances, for the path
/// tracer and the light tracer, and the same means for bdpt (whose variance is the sum of its
/// camera samples' and its splats' variances, which pooled rounds cannot take apart); a budget
/// too small for a second round keeps the first.
#[test]
fn time_budget_rounds_merge_into_one_render() {
    let scene = render::load(&common::root().join("pipelines/scenes/cornell-box.toml")).unwrap();
    for name in ["path", "light", "bdpt"] {
        let mut s = common::settings(&scene, 11, 8);
        s.integrator = integrators::find(name).unwrap();
        s.crop = Some([96, 40, 160, 104]);
        let once = render::render(&scene, &s);
        s.time_budget = Some(1e6);
        let rounds = render::render(&scene, &s);
        assert_eq!((once.samples, rounds.samples), (11, 11));
        let close = |a: &[f32], b: &[f32], tol: f32| {
            a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol * x.abs().max(y.abs()) + 1e-12)
        };
        assert!(close(&once.mean.data, &rounds.mean.data, 1e-5), "{name}: means differ");
        assert!(
            name == "bdpt" || close(&once.variance.data, &rounds.variance.data, 1e-3),
            "{name}: variances differ"
        );
        s.time_budget = Some(1e-9);
        let first = render::render(&scene, &s);
        assert_eq!(first.samples, 1, "{name}");
    }
}

/// A scene with media is refused by the integrators that do not render them, naming the
/// integrator.
#[test]
fn integrators_without_media_refuse_media() {
    let scene = render::load(&common::root().join("pipelines/scenes/sfm-courtyard-haze.toml")).unwrap();
    assert!(!scene.media.is_empty());
    for name in ["path", "light"] {
        let mut s = common::settings(&scene, 1, 4);
        s.integrator = integrators::find(name).unwrap();
        let e = render::try_render(&scene, &s).err().expect("refused");
        let msg = e.to_string();
        assert!(msg.contains(&format!("\"{name}\"")) && msg.contains("volpath"), "{msg}");
    }
}

/// Pearson's χ² test of `sample_emission` for every kind of light, on directions and on
/// positions: 2·10⁵ rays per light binned on 16 × 32 cells of (cos θ, φ) about a frame, the
/// expected counts from `emission_pdf` (directions, integrated over each cell on 16 × 16
/// points, 64 × 64 for the sky's sun) or from the area a position is uniform over; point and spot lights leave from
/// their point and a directional light along its direction, exactly. The mean flux weight β
/// is the lights' power (`light_power`, the pick's weights) within 4 standard errors.
#[test]
fn chi_square_emission_sampling() {
    use lumen::render::scene::Light;
    let lamp = "[[materials]]\nname = \"lamp\"\ntype = \"lambertian\"\nalbedo = [0.0, 0.0, 0.0]\nemission = [1.0, 2.0, 3.0]\n";
    let head = "[camera]\nwidth = 4\nheight = 4\nfov_deg = 40.0\nlook_at = { origin = [0.0, 0.0, -5.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }\n[[materials]]\nname = \"grey\"\ntype = \"lambertian\"\nalbedo = [0.5, 0.5, 0.5]\n[[shapes]]\ntype = \"sphere\"\ncenter = [0.3, -0.2, 0.5]\nradius = 1.0\nmaterial = \"grey\"\n";
    let map = common::root().join("data/envmaps/sky.exr");
    let lights = [
        ("quad", format!("{lamp}[[shapes]]\ntype = \"quad\"\ncorner = [-1.0, -0.8, 1.5]\nedge_u = [0.0, 1.6, 0.0]\nedge_v = [1.7, 0.0, 0.3]\nmaterial = \"lamp\"\n")),
        ("sphere", format!("{lamp}[[shapes]]\ntype = \"sphere\"\ncenter = [0.2, 0.1, 2.0]\nradius = 0.7\nmaterial = \"lamp\"\n")),
        ("point", "[[lights]]\ntype = \"point\"\nposition = [0.1, 0.2, 0.3]\nintensity = [1.0, 2.0, 3.0]\n".to_string()),
        ("spot", "[[lights]]\ntype = \"spot\"\nposition = [0.1, 2.0, 0.3]\ntarget = [0.4, 0.0, 0.0]\nintensity = [1.0, 2.0, 3.0]\ncutoff_deg = 40.0\nbeam_width_deg = 25.0\n".to_string()),
        ("directional", "[[lights]]\ntype = \"directional\"\nto_light = [0.3, 1.0, -0.2]\nirradiance = [1.0, 2.0, 3.0]\n".to_string()),
        ("environment", format!("[[lights]]\ntype = \"environment\"\nmap = \"{}\"\nrotation = [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]\n", map.display())),
    ];
    let dir = tempfile::tempdir().unwrap();
    let (nt, np) = (16usize, 32usize);
    let samples = 200_000u64;
    let alpha = sidak_alpha(0.01, 2 * lights.len());
    let tau = 2.0 * std::f64::consts::PI;
    // The cell of unit vector w in the frame (t, b, axis): cos θ over [−1, 1], φ.
    let cell = |w: Vec3A, (t, b, axis): (Vec3A, Vec3A, Vec3A)| {
        let c = w.dot(axis).clamp(-1.0, 1.0) as f64;
        let phi = (w.dot(b) as f64).atan2(w.dot(t) as f64).rem_euclid(tau);
        (((c + 1.0) / 2.0 * nt as f64) as usize).min(nt - 1) * np
            + ((phi / tau * np as f64) as usize).min(np - 1)
    };
    let frame = |axis: Vec3A| {
        let (t, b) = lumen::render::transport::basis(axis);
        (t, b, axis)
    };
    // Expected counts of a density over directions in a frame, integrated per cell.
    let expected = |density: &dyn Fn(Vec3A) -> f64, (t, b, axis): (Vec3A, Vec3A, Vec3A), sub: usize| {
        let mut e = vec![0.0; nt * np];
        for i in 0..nt {
            for j in 0..np {
                let mut sum = 0.0;
                for a in 0..sub {
                    let c = -1.0 + 2.0 * (i as f64 + (a as f64 + 0.5) / sub as f64) / nt as f64;
                    let s = (1.0 - c * c).sqrt();
                    for q in 0..sub {
                        let phi = tau * (j as f64 + (q as f64 + 0.5) / sub as f64) / np as f64;
                        let w = t * (s * phi.cos()) as f32 + b * (s * phi.sin()) as f32 + axis * c as f32;
                        sum += density(w);
                    }
                }
                e[i * np + j] =
                    samples as f64 * sum / (sub * sub) as f64 * (2.0 / nt as f64) * (tau / np as f64);
            }
        }
        e
    };
    for (name, text) in lights {
        let scene = common::scene(&format!("{head}{text}"), dir.path()).unwrap();
        let (i, light) = scene
            .lights
            .iter()
            .enumerate()
            .find(|(_, l)| !matches!(l, Light::Area { .. }) || name == "quad" || name == "sphere")
            .map(|(i, l)| (i, *l))
            .expect("the light");
        // The emitters' red channel is 1 (the colour is (1, 2, 3): ½ of the channels' mean
        // that `light_power` counts); the sky's is its own.
        let power: f64 = scene
            .lights
            .iter()
            .map(|l| lumen::render::scene::light_power(l, scene.bounds_radius) as f64)
            .sum();
        let red_power = match light {
            Light::Environment { mean, .. } => {
                let r = scene.bounds_radius as f64;
                4.0 * std::f64::consts::PI.powi(2) * r * r * mean.x as f64
            }
            _ => power / 2.0,
        };
        let (mut dirs, mut places) = (vec![0.0; nt * np], vec![0.0; nt * np]);
        let (mut sum, mut sum2, mut n) = (0.0, 0.0, 0.0);
        // The frame directions are binned in, and the one positions are.
        let (dir_frame, pos_frame) = match light {
            Light::Spot { axis, .. } => (frame(axis), None),
            Light::Directional { to_light, .. } => (frame(-to_light), Some(frame(to_light))),
            Light::Environment { .. } => (frame(Vec3A::Y), None),
            _ => (frame(Vec3A::Z), None),
        };
        let quad_normal = scene
            .info
            .iter()
            .find(|f| scene.materials[f.material as usize].emission.is_some())
            .map(|f| f.normal);
        for k in 0..samples {
            let mut s = lumen::render::sampler::Sampler::new(3, k, 0);
            let Some(e) = scene.sample_emission(s.next(), s.next2(), s.next2()) else { continue };
            let b = e.beta.x as f64;
            sum += b;
            sum2 += b * b;
            n += 1.0;
            let d = e.ray.dir;
            let o = e.ray.origin;
            match light {
                Light::Area { .. } if name == "sphere" => {
                    // Directions about the point's own normal; positions over the sphere.
                    let ny = (o - Vec3A::new(0.2, 0.1, 2.0)).normalize();
                    dirs[cell(d, frame(ny))] += 1.0;
                    places[cell(ny, frame(Vec3A::Z))] += 1.0;
                }
                Light::Area { .. } => {
                    dirs[cell(d, frame(quad_normal.unwrap()))] += 1.0;
                    // The quad's (u, v), binned as a 16 × 32 grid via the same cells.
                    let rel = o - Vec3A::new(-1.0, -0.8, 1.5);
                    let (eu, ev) = (Vec3A::new(0.0, 1.6, 0.0), Vec3A::new(1.7, 0.0, 0.3));
                    let (u, v) = (rel.dot(eu) / eu.length_squared(), rel.dot(ev) / ev.length_squared());
                    let iu = ((u * nt as f32) as usize).min(nt - 1);
                    let iv = ((v * np as f32) as usize).min(np - 1);
                    places[iu * np + iv] += 1.0;
                }
                Light::Point { position, .. } | Light::Spot { position, .. } => {
                    assert_eq!(o, position, "{name}: leaves its point");
                    dirs[cell(d, dir_frame)] += 1.0;
                }
                Light::Directional { to_light, .. } => {
                    assert!((d + to_light).length() < 1e-6, "{name}: {d} along the light");
                    places[disk_cell(o, &scene, pos_frame.unwrap(), nt, np)] += 1.0;
                }
                Light::Environment { .. } => {
                    dirs[cell(d, dir_frame)] += 1.0;
                    places[disk_cell(o, &scene, frame(-d), nt, np)] += 1.0;
                }
            }
        }
        let mean = sum / n;
        let se = ((sum2 / n - mean * mean).max(0.0) / n).sqrt();
        assert!(
            (mean - red_power).abs() <= 4.0 * se + 1e-5 * red_power,
            "{name}: mean β {mean} ± {se}, power {red_power}"
        );
        if !matches!(light, Light::Directional { .. }) {
            let density = |w: Vec3A| -> f64 {
                let axis = match light {
                    Light::Area { .. } if name == "sphere" => Vec3A::Z,
                    Light::Area { .. } => quad_normal.unwrap(),
                    _ => Vec3A::Z,
                };
                scene.emission_pdf(i, axis, w).1 as f64
            };
            let frame_for_expected = match light {
                Light::Area { .. } if name == "sphere" => frame(Vec3A::Z),
                Light::Area { .. } => frame(quad_normal.unwrap()),
                _ => dir_frame,
            };
            // The sky's sun spans two texels: finer integration for its piecewise-constant density.
            let e = expected(&density, frame_for_expected, if name == "environment" { 64 } else { 16 });
            let total: f64 = e.iter().sum();
            assert!(
                (total / samples as f64 - 1.0).abs() < 0.01,
                "{name}: direction density integrates to {}",
                total / samples as f64
            );
            let pv = chi2_test(&dirs, &e).expect("enough cells");
            assert!(pv >= alpha, "{name}: directions' χ² p-value {pv:.3e} below {alpha:.3e}");
        }
        if places.iter().sum::<f64>() > 0.0 {
            // Uniform in area: over the quad's (u, v) grid, over the sphere's (cos θ, φ) cells,
            // and over the disk's (ρ², φ) cells: every cell equally likely.
            let e = vec![samples as f64 / (nt * np) as f64; nt * np];
            let pv = chi2_test(&places, &e).expect("enough cells");
            assert!(pv >= alpha, "{name}: positions' χ² p-value {pv:.3e} below {alpha:.3e}");
        }
    }
}

/// The cell of a point on the disk of the bounding sphere facing `axis`: (ρ²/R², φ), which
/// is uniform for a point uniform on the disk.
fn disk_cell(o: Vec3A, scene: &Scene, (t, b, axis): (Vec3A, Vec3A, Vec3A), nt: usize, np: usize) -> usize {
    let r = scene.bounds_radius;
    let rel = o - scene.bounds_center - axis * r;
    assert!(rel.dot(axis).abs() < 1e-3 * r, "the point lies on the disk");
    let rho2 = (rel.length_squared() / (r * r)) as f64;
    assert!(rho2 <= 1.0 + 1e-4);
    let phi = (rel.dot(b) as f64).atan2(rel.dot(t) as f64).rem_euclid(2.0 * std::f64::consts::PI);
    ((rho2 * nt as f64) as usize).min(nt - 1) * np
        + ((phi / (2.0 * std::f64::consts::PI) * np as f64) as usize).min(np - 1)
}

/// The integrator a render case gets when it names none: `sppm` where a delta surface, a
/// small light and a diffuse receiver make a caustic, the path tracer elsewhere (no delta
/// surface; glass under a sky, a light too large to need a caustic-capable integrator).
#[test]
fn caustic_scenes_choose_a_caustic_capable_integrator() {
    let scenes = common::root().join("pipelines/scenes");
    for (file, expected) in [
        ("cornell-glass.toml", "sppm"),
        ("cornell-box.toml", "path"),
        ("glass-environment.toml", "path"),
        ("glossy-spheres.toml", "path"),
    ] {
        let scene = render::load(&scenes.join(file)).unwrap();
        let (kind, why) = integrators::choose(&scene);
        assert_eq!(kind.name, expected, "{file}: {why}");
        assert!(why.contains(expected), "{file}: {why}");
    }
}
