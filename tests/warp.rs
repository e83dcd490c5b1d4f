//! Depth-based rendering (`ibr::warp`, `lumen warp`) against the renderer's truth: the
//! courtyard seen from three cameras on a line, the middle view made from the outer two and
//! compared with its own render; a view warped to itself; and bad input.

mod common;

use glam::DVec3;
use lumen::ibr::warp::{self, Config, Mode};
use lumen::ibr::{Source, View};
use lumen::image::Image;
use lumen::math::{CameraModel, CameraToWorld};
use lumen::render;

/// A render of the courtyard (diffuse, lit by distant lights only: a view's shading has no
/// Monte Carlo noise beyond the pixel's own average) and its depth.
struct Rendered {
    image: Image,
    depth: Image,
    view: View,
}

fn courtyard(origin: DVec3, target: DVec3, width: u32, height: u32, f: f64) -> Rendered {
    let mut scene = render::load(&common::root().join("pipelines/scenes/sfm-courtyard.toml")).unwrap();
    scene.camera = CameraModel::centred(width, height, f);
    scene.t_world_cam = CameraToWorld::look_at(origin, target, DVec3::Z).unwrap();
    let film = render::render(&scene, &common::settings(&scene, 16, 2));
    let depth = render::truth(&scene, None).depth;
    Rendered { image: film.mean, depth, view: View { camera: scene.camera, t_world_cam: scene.t_world_cam } }
}

fn source<'a>(name: &str, r: &'a Rendered) -> Source<'a> {
    Source { name: name.into(), image: &r.image, depth: &r.depth, view: r.view }
}

/// PSNR over the pixels the warp's mask and the truth's depth both have, the peak being the
/// truth's largest value there; and that share of the frame.
fn psnr(out: &warp::Output, truth: &Rendered) -> (f64, f64) {
    let c = truth.image.channels as usize;
    let (mut se, mut n, mut peak) = (0.0f64, 0usize, 0.0f32);
    for i in 0..out.mask.data.len() {
        if out.mask.data[i] == 0.0 || truth.depth.data[i] == 0.0 {
            continue;
        }
        for k in 0..c {
            let (a, b) = (out.image.data[i * c + k], truth.image.data[i * c + k]);
            se += ((a - b) as f64).powi(2);
            peak = peak.max(b);
        }
        n += 1;
    }
    let mse = se / (n * c) as f64;
    (10.0 * (peak as f64 * peak as f64 / mse).log10(), n as f64 / out.mask.data.len() as f64)
}

/// Share of the pixels that see the scene in the truth which the warp leaves empty.
fn holes(out: &warp::Output, truth: &Rendered) -> f64 {
    let seen = truth.depth.data.iter().filter(|&&z| z > 0.0).count();
    let empty =
        (0..out.mask.data.len()).filter(|&i| truth.depth.data[i] > 0.0 && out.mask.data[i] == 0.0).count();
    empty as f64 / seen as f64
}

/// The middle of three views 0.4 m apart (about 8° at the back wall), made from the outer two
/// by backward mapping, is within 30 dB PSNR of its own render over the pixels it fills
/// (the goal: the render's anti-aliasing against a bilinear lookup, on texture with detail
/// down to the pixel), and leaves fewer holes than forward mapping. A closer new view (the
/// target 1 m nearer: magnified 1.4×) is where forward splats crack.
#[test]
fn the_middle_view_is_made_from_its_neighbours() {
    let target = DVec3::new(0.0, 0.5, 0.6);
    let (w, h, f) = (256, 192, 240.0);
    let left = courtyard(DVec3::new(-0.4, -3.0, 1.3), target, w, h, f);
    let right = courtyard(DVec3::new(0.4, -3.0, 1.3), target, w, h, f);
    let sources = [source("left", &left), source("right", &right)];
    for (what, origin) in [("middle", DVec3::new(0.0, -3.0, 1.3)), ("nearer", DVec3::new(0.0, -2.0, 1.1))] {
        let truth = courtyard(origin, target, w, h, f);
        let run = |mode| warp::warp(&sources, &truth.view, &Config { mode, ..Config::default() }).unwrap();
        let (back, fwd) = (run(Mode::Backward), run(Mode::Forward));
        let (p_back, share) = psnr(&back, &truth);
        let (p_fwd, _) = psnr(&fwd, &truth);
        let (h_back, h_fwd) = (holes(&back, &truth), holes(&fwd, &truth));
        eprintln!(
            "{what}: backward {p_back:.2} dB over {:.1} % of the frame, holes {:.2} %; forward {p_fwd:.2} dB, holes {:.2} %",
            100.0 * share,
            100.0 * h_back,
            100.0 * h_fwd
        );
        assert!(p_back >= 30.0, "{what}: backward PSNR {p_back:.2} dB: expected ≥ 30 dB");
        assert!(h_back < h_fwd, "{what}: backward leaves {h_back} of the pixels empty, forward {h_fwd}");
        assert!(share > 0.9, "{what}: only {share} of the frame filled");
    }
}

/// A view warped to itself is itself, exactly, in both modes: every pixel lands on its own
/// centre and the lookup is at integer coordinates. Pixels that see nothing stay holes.
#[test]
fn a_view_warped_to_itself_is_itself() {
    let r = courtyard(DVec3::new(0.3, -2.5, 1.6), DVec3::new(0.0, 2.0, 2.8), 96, 72, 60.0);
    let sky = r.depth.data.iter().filter(|&&z| z == 0.0).count();
    assert!(sky > 0, "the view should see some sky to test holes");
    for mode in [Mode::Forward, Mode::Backward] {
        let out = warp::warp(&[source("v", &r)], &r.view, &Config { mode, ..Config::default() }).unwrap();
        for i in 0..r.depth.data.len() {
            let c = 3;
            if r.depth.data[i] > 0.0 {
                for k in 0..c {
                    let (a, b) = (out.image.data[i * c + k], r.image.data[i * c + k]);
                    assert!((a - b).abs() <= 1e-6 * b.abs().max(1e-3), "{mode:?} pixel {i}: {a} vs {b}");
                }
            }
        }
        let expected = sky as f64 / r.depth.data.len() as f64;
        // Backward mapping's median fill may close an isolated sky pixel.
        assert!(
            out.hole_fraction <= expected + 1e-12,
            "{mode:?}: holes {} > sky {expected}",
            out.hole_fraction
        );
        assert!(
            out.hole_fraction >= 0.9 * expected,
            "{mode:?}: holes {} ≪ sky {expected}",
            out.hole_fraction
        );
    }
}

/// Bad input is refused with a message naming the view and the value.
#[test]
fn bad_input_is_named() {
    let r = courtyard(DVec3::new(0.0, -3.0, 1.3), DVec3::new(0.0, 0.5, 0.6), 32, 24, 30.0);
    let err = |sources: &[Source], target: &View| match warp::warp(sources, target, &Config::default()) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("accepted"),
    };
    assert!(err(&[], &r.view).contains("no source view"));
    let mut small = r.depth.clone();
    small.width = 16;
    small.data.truncate(16 * 24);
    let e = err(&[Source { depth: &small, ..source("v", &r) }], &r.view);
    assert!(e.contains("v: the depth is 16×24") && e.contains("32×24"), "{e}");
    let mut nan = r.depth.clone();
    nan.data[5] = f32::NAN;
    let e = err(&[Source { depth: &nan, ..source("v", &r) }], &r.view);
    assert!(e.contains("pixel (5, 0)") && e.contains("NaN"), "{e}");
    let rgb = Image::new(32, 24, 3);
    let e = err(&[Source { depth: &rgb, ..source("v", &r) }], &r.view);
    assert!(e.contains("3 channels"), "{e}");
    let zero = Image::new(32, 24, 1);
    let e = err(&[Source { depth: &zero, ..source("v", &r) }], &r.view);
    assert!(e.contains("sees nothing"), "{e}");
    let mut bad = r.view;
    bad.camera.intrinsics.fx = -1.0;
    let e = err(&[source("v", &r)], &bad);
    assert!(e.contains("target camera") && e.contains("fx"), "{e}");
    let e = match warp::warp(
        &[source("v", &r)],
        &r.view,
        &Config { depth_tolerance: 0.0, ..Config::default() },
    ) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("accepted"),
    };
    assert!(e.contains("depth tolerance 0"), "{e}");
}

/// `lumen warp` end to end from `lumen render --aov depth`'s files, and its refusals: a camera
/// file with a lens, with an unknown field, counts that differ, a missing file. Nothing is
/// written when it refuses.
#[test]
fn lumen_warp_from_renders() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let base = std::fs::read_to_string(common::root().join("pipelines/scenes/sfm-courtyard.toml")).unwrap();
    let small = base
        .replace("width = 1024", "width = 128")
        .replace("height = 768", "height = 96")
        .replace("fx = 960.0", "fx = 120.0")
        .replace("fy = 960.0", "fy = 120.0")
        .replace("cx = 511.5", "cx = 63.5")
        .replace("cy = 383.5", "cy = 47.5");
    for (name, x) in [("a", "-0.3"), ("b", "0.0"), ("c", "0.3")] {
        let text = small.replace("origin = [0.0, -3.0, 1.3]", &format!("origin = [{x}, -3.0, 1.3]"));
        assert!(text.contains(&format!("origin = [{x}, -3.0, 1.3]")), "the pose line is in the scene");
        std::fs::write(d.join(format!("{name}.toml")), text).unwrap();
        let p = |s: &str| d.join(s).display().to_string();
        let (code, err) = common::lumen(&[
            "render",
            &p(&format!("{name}.toml")),
            "--out",
            &p(&format!("{name}.exr")),
            "--aov",
            "depth",
            "--spp",
            "4",
        ]);
        assert_eq!(code, 0, "{err}");
        assert!(d.join(format!("{name}.camera.json")).is_file());
    }
    let p = |s: &str| d.join(s).display().to_string();
    let args = |out: &str, to: &str| -> Vec<String> {
        [
            "warp",
            "--image",
            &p("a.exr"),
            "--depth",
            &p("a.depth.exr"),
            "--camera",
            &p("a.camera.json"),
            "--image",
            &p("c.exr"),
            "--depth",
            &p("c.depth.exr"),
            "--camera",
            &p("c.camera.json"),
            "--to",
            to,
            "--out",
            &p(out),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect()
    };
    let run = |a: &[String]| common::lumen(&a.iter().map(String::as_str).collect::<Vec<_>>());
    let (code, err) = run(&args("b_new.exr", &p("b.camera.json")));
    assert_eq!(code, 0, "{err}");
    for f in ["b_new.exr", "b_new.mask.png", "b_new.json"] {
        assert!(d.join(f).is_file(), "{f} missing: {err}");
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("b_new.json")).unwrap()).unwrap();
    let holes = summary["hole_fraction"].as_f64().unwrap();
    assert!(holes < 0.05, "{holes}");
    // A whole scene file names the target too.
    let (code, err) = run(&args("b_scene.exr", &p("b.toml")));
    assert_eq!(code, 0, "{err}");
    let a = lumen::image::io::read_exr(&d.join("b_new.exr")).unwrap();
    let b = lumen::image::io::read_exr(&d.join("b_scene.exr")).unwrap();
    assert_eq!(a, b);

    let camera = std::fs::read_to_string(d.join("b.camera.json")).unwrap();
    let lens = camera.replacen('{', "{\"aperture_radius\": 0.1, \"focus_distance\": 3.0,", 1);
    std::fs::write(d.join("lens.json"), lens).unwrap();
    let unknown = camera.replacen('{', "{\"fov\": 40,", 1);
    std::fs::write(d.join("unknown.json"), unknown).unwrap();
    for (to, expect) in [
        ("lens.json", "aperture_radius"),
        ("unknown.json", "unknown field `fov`"),
        ("missing.json", "missing.json"),
    ] {
        let (code, err) = run(&args("refused.exr", &p(to)));
        assert_ne!(code, 0);
        assert!(err.contains(expect) && err.contains(to), "{to}: {err}");
        assert!(!d.join("refused.exr").exists() && !d.join("refused.mask.png").exists());
    }
    let mut fewer = args("refused.exr", &p("b.camera.json"));
    fewer.truncate(fewer.len() - 6);
    fewer.extend(["--to", &p("b.camera.json"), "--out", &p("refused.exr")].map(String::from));
    let (code, err) = run(&fewer);
    assert_ne!(code, 0);
    assert!(err.contains("2 --image, 2 --depth and 1 --camera"), "{err}");
    let mut wrong_depth = args("refused.exr", &p("b.camera.json"));
    wrong_depth[4] = p("a.exr");
    let (code, err) = run(&wrong_depth);
    assert_ne!(code, 0);
    assert!(err.contains("a.exr") && err.contains("3 channels"), "{err}");
}
