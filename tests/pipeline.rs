//! `lumen run`: the report's shape, bounds and exit codes, and determinism of its numbers.

mod common;

use common::run::{case, numbers, read_json, run, run_with, small_pipeline};
use std::process::Command;

fn furnace(bound: f64, extra: &str) -> String {
    let scene = common::root().join("pipelines/scenes/furnace.toml");
    format!(
        "name = \"t\"\nseed = 7\n[[stages]]\nstage = \"render\"\ncase = \"furnace\"\nscene = \"{}\"\nspp = 64\nexpect_uniform = [1.0, 1.0, 1.0]\nbounds = {{ mean_rel_err = {bound}, nonfinite_samples = 0 }}\n{extra}",
        scene.display()
    )
}

#[test]
fn report_shape_and_determinism() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let (code, err) = run(&furnace(0.2, ""), &out);
    assert_eq!(code, 0, "{err}");
    let j: serde_json::Value = read_json(&out.join("report.json"));
    assert_eq!(j["pipeline"], "t");
    assert_eq!(j["seed"], 7);
    assert_eq!(j["passed"], true);
    let st = &j["stages"][0];
    assert_eq!(st["stage"], "render");
    assert_eq!(st["case"], "furnace");
    assert_eq!(st["mode"], "alone");
    assert!(st["timings_s"]["total"].as_f64().unwrap() > 0.0);
    let m = st["metrics"].as_array().unwrap().iter().find(|m| m["name"] == "mean_rel_err").unwrap();
    assert_eq!(m["bound"], serde_json::json!({ "max": 0.2 }));
    assert_eq!(m["pass"], true);
    assert_eq!(m["unit"], "");
    let v1 = m["value"].as_f64().unwrap();
    assert!(v1 > 0.0 && v1 < 0.2);
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("| mean_rel_err |") && md.contains("pass"), "{md}");
    // The same file and seed give the same numbers.
    let (code, _) = run(&furnace(0.2, ""), &out);
    assert_eq!(code, 0);
    let j2: serde_json::Value = read_json(&out.join("report.json"));
    let m2 = j2["stages"][0]["metrics"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["name"] == "mean_rel_err")
        .unwrap()
        .clone();
    assert_eq!(m2["value"].as_f64().unwrap(), v1);
}

/// `lumen report` writes a page per stage from a run's report, with the commit, date and
/// machine and the case's numbers as the report has them; a file that is not a report is
/// refused by name, and nothing is written.
#[test]
fn report_command_writes_results_pages() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let (code, err) = run(&furnace(0.2, ""), &out);
    assert_eq!(code, 0, "{err}");
    let j: serde_json::Value = read_json(&out.join("report.json"));
    let docs = dir.path().join("docs");
    let report = out.join("report.json");
    let (code, err) = common::lumen(&["report", report.to_str().unwrap(), "--docs", docs.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let page = std::fs::read_to_string(docs.join("render.md")).unwrap();
    let commit = j["git_commit"].as_str().unwrap();
    let machine = j["machine"].as_str().unwrap();
    assert!(page.contains(&format!("commit `{commit}`")) && page.contains(machine), "{page}");
    let m =
        j["stages"][0]["metrics"].as_array().unwrap().iter().find(|m| m["name"] == "mean_rel_err").unwrap();
    let value = lumen::pipeline::metric::fmt_value(m["value"].as_f64().unwrap());
    assert!(page.contains(&format!("| mean_rel_err | {value} |")), "{page}");
    let index = std::fs::read_to_string(docs.join("index.md")).unwrap();
    assert!(index.contains("[render](render.md) | 1 | yes"), "{index}");
    // Not a report: refused, naming the file, and nothing written.
    let bogus = dir.path().join("bogus.json");
    std::fs::write(&bogus, "{\"pipeline\": 3}").unwrap();
    let fresh = dir.path().join("fresh");
    let (code, err) = common::lumen(&["report", bogus.to_str().unwrap(), "--docs", fresh.to_str().unwrap()]);
    assert_eq!(code, 1, "{err}");
    assert_eq!(common::fault_in(&err), "bad-input", "{err}");
    assert!(err.contains("bogus.json") && err.contains("not a lumen report.json"), "{err}");
    assert!(!fresh.exists());
}

#[test]
fn missed_bound_exits_3_and_names_metric() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let (code, err) = run(&furnace(1e-9, ""), &out);
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("render/furnace/mean_rel_err"), "{err}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("**MISS**"));
    // Declared as an expected miss, the same bound no longer fails the run.
    let (code, err) =
        run(&furnace(1e-9, "expected_miss = { mean_rel_err = \"64 spp are too few\" }\n"), &out);
    assert_eq!(code, 0, "{err}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("expected miss: 64 spp are too few"), "{md}");
}

/// A declared miss whose bound is met fails the run, as a strict expected failure does, until
/// the declaration is removed.
#[test]
fn declared_miss_now_met_exits_3() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let (code, err) = run(&furnace(0.2, "expected_miss = { mean_rel_err = \"64 spp are too few\" }\n"), &out);
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("render/furnace/mean_rel_err") && err.contains("declared a miss, now met"), "{err}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("**DECLARED MISS NOW MET** (declared: 64 spp are too few)"), "{md}");
    // A miss declared on a metric without a bound is refused: there is nothing to miss.
    let text = furnace(0.2, "expected_miss = { max_rel_err = \"noisy\" }\n");
    let (code, err) = run(&text, &out);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("expected_miss.max_rel_err: `max_rel_err` has no bound"), "{err}");
}

/// A bound says its direction when it is a table: `{ min = … }` on an error turns it into a
/// floor, `{ min, max }` a range; a range no value meets, or an unknown end, is refused.
#[test]
fn bounds_with_a_direction() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let with = |b: &str| furnace(0.2, "").replace("mean_rel_err = 0.2", &format!("mean_rel_err = {b}"));
    let (code, err) = run(&with("{ min = 0.0, max = 0.2 }"), &out);
    assert_eq!(code, 0, "{err}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("| 0 to 0.2 | pass |"), "{md}");
    let (code, err) = run(&with("{ min = 0.5 }"), &out);
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("render/furnace/mean_rel_err") && err.contains("bound ≥ 0.5"), "{err}");
    let (code, err) = run(&with("{ min = 0.5, max = 0.1 }"), &out);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("bounds.mean_rel_err = { min = 0.5, max = 0.1 }: min is above max"), "{err}");
    let (code, err) = run(&with("{ below = 0.5 }"), &out);
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains("bounds") && err.contains("expected a number, or a table with `min`, `max`"),
        "{err}"
    );
    let (code, err) = run(&with("{}"), &out);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("bounds.mean_rel_err = {}: expected a number, or `min`, `max` or both"), "{err}");
}

#[test]
fn missing_reference_is_skipped_with_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    // A bound on a reference metric: skipped with the missing file named, not failed.
    let extra = "reference = \"/nonexistent/ref.exr\"\nreference_variance = \"/nonexistent/var.exr\"\n";
    let text = furnace(0.2, extra)
        .replace("nonfinite_samples = 0 }", "nonfinite_samples = 0, mean_rel_err_r = 0.01 }");
    let (code, err) = run(&text, &out);
    assert_eq!(code, 0, "{err}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("/nonexistent/ref.exr not found: comparison skipped"), "{md}");
    assert!(
        md.contains("| mean_rel_err_r | — |  | ≤ 0.01 | skipped: /nonexistent/ref.exr not found |"),
        "{md}"
    );
    let j: serde_json::Value = read_json(&out.join("report.json"));
    let m = j["stages"][0]["metrics"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["name"] == "mean_rel_err_r")
        .unwrap()
        .clone();
    assert_eq!((m["value"].is_null(), m["pass"].is_null()), (true, true), "{m}");
}

/// Cases on real data whose folder is absent are skipped with the folder named, for every
/// stage that reads real data; the run passes, and nothing is judged. A key of the rendered
/// variant given beside `dataset` is refused by name.
#[test]
fn absent_real_data_is_skipped_and_dataset_keys_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let text = "name = \"t\"\n\
        [[stages]]\nstage = \"calibrate\"\ncase = \"c\"\nimages = \"/nonexistent/boards\"\nbounds = { rms_px = 0.2 }\n\
        [[stages]]\nstage = \"photometric\"\ncase = \"p\"\ndataset = \"/nonexistent/ball\"\nbounds = { mean_angular_error_deg = 2 }\n\
        [[stages]]\nstage = \"sfm\"\ncase = \"s\"\nimages = \"/nonexistent/photos\"\ncamera = \"/nonexistent/K.txt\"\ntruth = \"/nonexistent/gt\"\n\
        [[stages]]\nstage = \"hdr\"\ncase = \"h\"\nlist = \"/nonexistent/times.txt\"\n";
    let (code, err) = run(text, &out);
    assert_eq!(code, 0, "{err}");
    for path in ["/nonexistent/boards", "/nonexistent/ball", "/nonexistent/photos", "/nonexistent/times.txt"]
    {
        assert!(err.contains(&format!("skipped: {path} is absent")), "{path}: {err}");
    }
    let j: serde_json::Value = read_json(&out.join("report.json"));
    assert_eq!(j["passed"], true, "{j}");
    for st in j["stages"].as_array().unwrap() {
        assert!(st["skipped"].as_str().is_some_and(|s| s.contains("is absent")), "{st}");
        assert_eq!(st["metrics"].as_array().map(Vec::len), Some(0), "{st}");
    }
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("| photometric | p | skipped (/nonexistent/ball is absent"), "{md}");
    // A path missing inside a folder that is there is a typo: refused by name, not skipped.
    let typo = dir.path().join("data/bal");
    std::fs::create_dir_all(dir.path().join("data")).unwrap();
    let text = format!(
        "[[stages]]\nstage = \"hdr\"\ncase = \"h\"\nlist = \"{}\"\nbounds = {{ loo_median_abs_ln = 0.1 }}\n",
        typo.join("list.txt").display()
    );
    let (code, err) = run(&text, &out);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("does not exist, though") && err.contains("a mistyped path?"), "{err}");
    let text = "[[stages]]\nstage = \"photometric\"\ncase = \"p\"\ndataset = \"/x\"\nlights = 12\n";
    let (code, err) = run(text, &out);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("unknown field `lights`") && err.contains("case p"), "{err}");
    // A rendered sfm case (an entry with `scene`) checks its own keys and settings.
    let sfm = |extra: &str| {
        let scene = common::root().join("pipelines/scenes/sfm-courtyard.toml");
        format!(
            "[[stages]]\nstage = \"sfm\"\ncase = \"r\"\nscene = \"{}\"\ntarget = [0.0, 0.5, 0.6]\nradius = 3.5\nheight = 1.3\narc_deg = 40\n{extra}",
            scene.display()
        )
    };
    let (code, err) = run(&sfm("images = \"/x\"\n"), &out);
    assert!(code == 1 && err.contains("`images` and `scene` are both given"), "{err}");
    let (code, err) = run(&sfm("views = 1\nexpect_error = \"bad-input\"\n"), &out);
    assert_eq!(code, 0, "a one-view case is refused as bad input: {err}");
    let (code, err) = run(&sfm("radius = -1\n").replace("radius = 3.5\n", ""), &out);
    assert!(code == 1 && err.contains("positive radius"), "{err}");
    let (code, err) = run(&sfm("forward = 3.5\n"), &out);
    assert!(code == 1 && err.contains("forward = 3.5") && err.contains("less than the radius"), "{err}");
    let (code, err) = run(&sfm("guess_intrinsics = true\nrefine = [\"focal\", \"skew\"]\n"), &out);
    assert!(code == 1 && err.contains("refine: \"skew\": expected focal"), "{err}");
    let (code, err) = run(&sfm("pairs = \"sequential:0\"\n"), &out);
    assert!(
        code == 1 && err.contains("pairs = \"sequential:0\": expected exhaustive or sequential:N"),
        "{err}"
    );
    let (code, err) = run(&sfm("refine = [\"k1\"]\n"), &out);
    assert!(code == 1 && err.contains("refine: only with guessed intrinsics"), "{err}");
    // A novel-view case checks its ring and its held-out place.
    let novel = |extra: &str| {
        let scene = common::root().join("pipelines/scenes/sfm-courtyard.toml");
        format!(
            "[[stages]]\nstage = \"novel-view\"\ncase = \"n\"\nscene = \"{}\"\ntarget = [0.0, 0.5, 0.6]\nradius = 3.5\nheights = [1.3, 1.5]\narc_deg = 40\n{extra}",
            scene.display()
        )
    };
    let (code, err) = run(&novel("held_out = [1.5, 1.4]\n"), &out);
    assert!(
        code == 1 && err.contains("held_out = [1.5, 1.4]") && err.contains("held-out place from 0 to 1"),
        "{err}"
    );
    let (code, err) = run(&novel("held_out = [0.5, 1.4]\nviews = 2\n"), &out);
    assert!(code == 1 && err.contains("views = 2") && err.contains("3 to 200 views"), "{err}");
    let (code, err) =
        run(&novel("held_out = [0.5, 1.4]\narc_deg = 400\n").replace("arc_deg = 40\n", ""), &out);
    assert!(code == 1 && err.contains("arc_deg = 400"), "{err}");
    let (code, err) = run(&novel(""), &out);
    assert!(code == 1 && err.contains("missing field `held_out`"), "{err}");
}

/// An `hdr` case on a stack of files (`list`): on a stack exposed exactly as its list says,
/// the response is increasing and each frame left out is predicted from the others within
/// 8-bit quantisation; when one frame's stated time is twice its real one, that frame's bias
/// shows (ln 2 ≈ 0.69 before the fit absorbs part of it).
#[test]
fn hdr_case_on_files_checks_the_stack_against_itself() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (w, h) = (96u32, 64u32);
    let real = [1.0, 0.25, 0.0625, 0.015625];
    for (k, t) in real.iter().enumerate() {
        let img = ::image::RgbImage::from_fn(w, h, |x, y| {
            // Radiance from 10⁻³ to 1 over the image, a little different per channel.
            let l = (-(6.9 * (x + w * y) as f64) / (w * h) as f64).exp();
            let code = |s: f64| (255.0 * (l * s * t * 8.0).clamp(0.0, 1.0).powf(1.0 / 2.2)).round() as u8;
            ::image::Rgb([code(1.0), code(0.8), code(0.6)])
        });
        img.save(d.join(format!("f{k}.png"))).unwrap();
    }
    std::fs::write(d.join("right.txt"), "f0.png 1\nf1.png 1/4\nf2.png 1/16\nf3.png 1/64\n").unwrap();
    std::fs::write(d.join("wrong.txt"), "f0.png 1\nf1.png 1/4\nf2.png 1/8\nf3.png 1/64\n").unwrap();
    let mut text = String::from("name = \"t\"\n");
    for list in ["right", "wrong"] {
        let path = d.join(format!("{list}.txt"));
        text += &format!(
            "[[stages]]\nstage = \"hdr\"\ncase = \"{list}\"\nlist = \"{}\"\nbounds = {{ non_monotone_values = 0, non_finite_values = 0 }}\n",
            path.display()
        );
    }
    let out = d.join("out");
    let (code, err) = run(&text, &out);
    assert_eq!(code, 0, "{err}");
    let j: serde_json::Value = read_json(&out.join("report.json"));
    let metric = |case: usize, name: &str| {
        j["stages"][case]["metrics"]
            .as_array()
            .and_then(|m| m.iter().find(|m| m["name"] == name))
            .and_then(|m| m["value"].as_f64())
            .unwrap_or_else(|| panic!("{name} of case {case}: {j}"))
    };
    assert_eq!(metric(0, "non_monotone_values"), 0.0);
    let (right, wrong) = (metric(0, "loo_worst_frame_bias_ln"), metric(1, "loo_worst_frame_bias_ln"));
    // Half a code of rounding at the middle of a gamma-2.2 curve is about 0.01 in ln.
    assert!(right < 0.02, "exact times: worst frame bias {right}");
    assert!(wrong > 0.2, "one time wrong by 2×: worst frame bias {wrong}");
}

#[test]
fn render_command_writes_exr_png_and_truth() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::root().join("pipelines/scenes/furnace.toml");
    let out = dir.path().join("f.exr");
    let o = Command::new(env!("CARGO_BIN_EXE_lumen"))
        .args([
            "render",
            scene.to_str().unwrap(),
            "--spp",
            "4",
            "--out",
            out.to_str().unwrap(),
            "--aov",
            "depth,normal,id,variance",
            "--preview",
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let img = lumen::image::io::read_exr(&out).unwrap();
    assert_eq!((img.width, img.height, img.channels), (16, 16, 3));
    for name in ["f.depth.exr", "f.normal.exr", "f.id.exr", "f.variance.exr", "f.ids.json"] {
        assert!(dir.path().join(name).exists(), "{name} missing");
    }
    // --preview: a PNG beside every EXR; depth and variance carry a scale bar, so are wider.
    for name in ["f.png", "f.normal.png", "f.id.png"] {
        let png = image::open(dir.path().join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!((png.width(), png.height()), (16, 16), "{name}");
    }
    for name in ["f.depth.png", "f.variance.png"] {
        let png = image::open(dir.path().join(name)).unwrap();
        assert!(png.width() > 16 && png.height() >= 64, "{name}");
    }
    // `lumen preview` reads everything before it writes: one bad file, no preview written.
    let again = dir.path().join("again.exr");
    std::fs::copy(&out, &again).unwrap();
    let (code, err) =
        common::lumen(&["preview", again.to_str().unwrap(), dir.path().join("f.png").to_str().unwrap()]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("f.png: expected an .exr file"), "{err}");
    assert!(!dir.path().join("again.png").exists());
    let (code, err) = common::lumen(&["preview", again.to_str().unwrap(), "--kind", "shiny"]);
    assert!(code == 1 && err.contains("--kind: kind `shiny`"), "{err}");
    let depth = lumen::image::io::read_exr(&dir.path().join("f.depth.exr")).unwrap();
    assert_eq!(depth.channels, 1);
    // The camera is at the centre of a unit sphere: the centre pixel's depth is ~1.
    assert!((depth.pixel(8, 8)[0] - 1.0).abs() < 0.01);
    let png = dir.path().join("f.png");
    let o = Command::new(env!("CARGO_BIN_EXE_lumen"))
        .args(["render", scene.to_str().unwrap(), "--spp", "4", "--out", png.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success());
    assert_eq!(image::open(&png).unwrap().width(), 16);
}

/// A scene with a [sensor] renders to a PNG of raw code values at its bit depth.
#[test]
fn sensor_png_has_raw_codes() {
    let dir = tempfile::tempdir().unwrap();
    let furnace = std::fs::read_to_string(common::root().join("pipelines/scenes/furnace.toml")).unwrap();
    // Radiance 1 at exposure 0.5 is half of full scale: code ≈ 32767 of 65535, with photon noise.
    let text =
        furnace.replace("[render]", "[sensor]\nexposure = 0.5\nfull_well = 40000.0\nbits = 16\n\n[render]");
    let scene = dir.path().join("s.toml");
    std::fs::write(&scene, text).unwrap();
    let png = dir.path().join("s.png");
    let o = Command::new(env!("CARGO_BIN_EXE_lumen"))
        .args(["render", scene.to_str().unwrap(), "--spp", "256", "--out", png.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let img = image::open(&png).unwrap().into_rgb16();
    let mean = img.iter().map(|&v| v as f64).sum::<f64>() / img.len() as f64;
    // Photon noise alone: σ = √20000 e⁻ ≈ 232 codes per sample; the mean of 768 is within ±30.
    assert!((mean - 32767.5).abs() < 60.0, "mean code {mean}");
}

#[test]
fn bench_names_a_missing_scene() {
    let o = Command::new(env!("CARGO_BIN_EXE_lumen"))
        .args(["bench", "render", "--scene", "/nonexistent/b.toml"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("/nonexistent/b.toml"));
}

#[test]
fn bench_names_an_unknown_sampler() {
    let o = Command::new(env!("CARGO_BIN_EXE_lumen"))
        .args(["bench", "render", "--sampler", "halton", "--spp", "1", "--repeat", "1"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--sampler halton: expected independent or sobol"));
}

/// The photometric stage on a small Lambertian sphere (12 lights, 8 spp): the robust model
/// within 0.2° of the truth normals; a bad setting is refused naming it.
#[test]
fn photometric_stage() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let scene = common::root().join("pipelines/scenes/ps-sphere.toml");
    let stage = |extra: &str| {
        format!(
            "name = \"ps\"\nseed = 3\n[[stages]]\nstage = \"photometric\"\ncase = \"sphere\"\nscene = \"{}\"\nspp = 8\n{extra}",
            scene.display()
        )
    };
    let (code, err) =
        run(&stage("lights = 12\nbounds = { mean_angular_error_deg = 0.2, masked_pixels = 0 }\n"), &out);
    assert_eq!(code, 0, "{err}");
    let report: serde_json::Value = read_json(&out.join("report.json"));
    let metrics = report["stages"][0]["metrics"].as_array().unwrap();
    let err_deg =
        metrics.iter().find(|m| m["name"] == "mean_angular_error_deg").unwrap()["value"].as_f64().unwrap();
    assert!(err_deg > 0.0 && err_deg <= 0.2, "{err_deg}");
    let (code, err) = run(&stage("lights = 2\n"), &out);
    assert_eq!(code, 1);
    assert!(err.contains("lights = 2"), "{err}");
    let (code, err) = run(&stage("model = \"phong\"\n"), &out);
    assert_eq!(code, 1);
    assert!(err.contains("phong"), "{err}");
    let (code, err) = run(&stage("shininess = -5.0\n"), &out);
    assert_eq!(code, 1);
    assert!(err.contains("shininess = -5"), "{err}");
}

/// A small pipeline of every stage, two of them swept: the sweep's cases share renders
/// through the cache, the report plots them, and the numbers are the same on 1 and 2 threads,
/// with a fresh cache or a full one.
#[test]
fn sweeps_share_renders_and_numbers_do_not_depend_on_threads() {
    let dir = tempfile::tempdir().unwrap();
    let text = small_pipeline();
    let cache = dir.path().join("cache");
    let c = cache.to_str().unwrap();
    let (code, err, one) = run_with(&text, dir.path(), "one", &["--threads", "1", "--cache", c]);
    assert_eq!(code, 0, "{err}");
    // Line-per-case progress, also when stderr is not a terminal.
    assert!(
        err.contains("[1/5] render furnace[spp=4] ...") && err.contains("[5/5] photometric sphere: ok"),
        "{err}"
    );
    assert_eq!(one["threads"], 1);
    // View k's pose does not depend on the count: the 5-view case renders one view more.
    let (a, b) = (case(&one, "board[views=4]"), case(&one, "board[views=5]"));
    assert_eq!((a["renders"]["rendered"].as_u64(), a["renders"]["reused"].as_u64()), (Some(4), Some(0)));
    assert_eq!((b["renders"]["rendered"].as_u64(), b["renders"]["reused"].as_u64()), (Some(1), Some(4)));
    assert!(b["timings_s"]["solve"].as_f64().unwrap() > 0.0 && b["timings_s"]["render"].as_f64().is_some());
    assert_eq!(b["sweep"]["views"], "5");
    assert_eq!(b["group"], "board");
    for plot in ["furnace.svg", "board.svg"] {
        let svg = std::fs::read_to_string(dir.path().join("one/plots").join(plot)).unwrap();
        assert!(svg.contains("<svg") && svg.contains("circle"), "{plot}");
    }
    let md = std::fs::read_to_string(dir.path().join("one/report.md")).unwrap();
    assert!(md.contains("## Error against time") && md.contains("![board](plots/board.svg)"), "{md}");
    // Two threads, nothing cached: the same numbers.
    let (code, err, two) = run_with(&text, dir.path(), "two", &["--threads", "2", "--no-cache"]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(two["threads"], 2);
    assert_eq!(numbers(&one), numbers(&two));
    assert_eq!(
        case(&two, "board[views=5]")["renders"]["rendered"],
        5,
        "without a cache every view is rendered"
    );
    // Again with the full cache: nothing is rendered, the numbers stay.
    let (code, err, again) = run_with(&text, dir.path(), "again", &["--threads", "2", "--cache", c]);
    assert_eq!(code, 0, "{err}");
    for name in ["board[views=4]", "board[views=5]", "sphere"] {
        assert_eq!(case(&again, name)["renders"]["rendered"], 0, "{name} rendered again");
    }
    assert_eq!(case(&again, "sphere")["renders"]["reused"], 8);
    assert_eq!(numbers(&one), numbers(&again));
}

/// A stiff case can declare the error it must end with; a case that ends otherwise fails the
/// run (exit 3) with both outcomes in the report; an undeclared error stops the run (exit 1)
/// naming the case, the kind and the field.
#[test]
fn declared_errors_are_outcomes() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::root().join("pipelines/scenes/calib-board.toml");
    let entry = |extra: &str| {
        format!(
            "[[stages]]\nstage = \"calibrate\"\ncase = \"one-view\"\nscene = \"{}\"\nviews = 1\n{extra}",
            scene.display()
        )
    };
    let (code, err, r) = run_with(&entry("expect_error = \"bad-input\"\n"), dir.path(), "a", &["--no-cache"]);
    assert_eq!(code, 0, "{err}");
    let st = &r["stages"][0];
    assert_eq!(st["outcome"]["declared"], "error: bad-input");
    assert_eq!(st["outcome"]["actual"], "error: bad-input");
    assert!(st["error"]["message"].as_str().unwrap().contains("views = 1"), "{st}");
    let (code, err, r) = run_with(&entry("expect_error = \"numerical\"\n"), dir.path(), "b", &["--no-cache"]);
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("declared error: numerical, ended with error: bad-input"), "{err}");
    assert_eq!(r["passed"], false);
    let (code, err, _) = run_with(&entry(""), dir.path(), "c", &["--no-cache"]);
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains("case one-view") && err.contains("bad-input error") && err.contains("views = 1"),
        "{err}"
    );
    assert!(!dir.path().join("c").exists(), "a stopped run wrote output");
    let (code, err, _) = run_with(&entry("expect_error = \"flood\"\n"), dir.path(), "d", &["--no-cache"]);
    assert_eq!(code, 1);
    assert!(err.contains("expect_error = \"flood\""), "{err}");
    for bad in ["100000", "0"] {
        let (code, err, _) = run_with(&entry(""), dir.path(), "e", &["--threads", bad]);
        assert_eq!(code, 2, "{err}");
        assert!(err.contains(&format!("'{bad}'")) && err.contains("from 1 to 1024"), "{err}");
    }
}

/// `lumen calibrate` and `lumen ps` on the inputs a pipeline kept give the pipeline's numbers:
/// both call the same solver function with the same settings.
#[test]
fn cli_on_the_pipelines_inputs_gives_its_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let root = common::root().join("pipelines/scenes");
    let text = format!(
        "[[stages]]\nstage = \"calibrate\"\ncase = \"board\"\nscene = \"{0}/calib-board.toml\"\nspp = 4\nviews = 5\nsave_views = true\n\
         [[stages]]\nstage = \"photometric\"\ncase = \"sphere\"\nscene = \"{0}/ps-sphere.toml\"\nspp = 4\nlights = 8\nsave_dataset = true\n",
        root.display()
    );
    let (code, err, r) = run_with(&text, dir.path(), "out", &["--no-cache"]);
    assert_eq!(code, 0, "{err}");
    let metric = |case_name: &str, name: &str| {
        case(&r, case_name)["metrics"].as_array().unwrap().iter().find(|m| m["name"] == name).unwrap()
            ["value"]
            .as_f64()
            .unwrap()
    };
    let out = dir.path().join("out");
    let cam = dir.path().join("cam.json");
    let views = out.join("board/*.exr");
    let o = Command::new(env!("CARGO_BIN_EXE_lumen"))
        .args(["calibrate", "--images", views.to_str().unwrap(), "--board", "9x6", "--square", "0.025"])
        .args(["--out", cam.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cal: serde_json::Value = read_json(&cam);
    assert_eq!(cal["views"].as_array().unwrap().len(), 5);
    let (cli, pipe) = (cal["rms_px"].as_f64().unwrap(), metric("board", "rms_px"));
    assert!(cli == pipe, "lumen calibrate RMS {cli} px, the pipeline's {pipe} px");
    let ps = dir.path().join("ps");
    let o = Command::new(env!("CARGO_BIN_EXE_lumen"))
        .args(["ps", "--dataset", out.join("sphere").to_str().unwrap(), "--model", "robust"])
        .args(["--out", ps.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value = read_json(&ps.join("summary.json"));
    let (cli, pipe) =
        (s["mean_angular_error_deg"].as_f64().unwrap(), metric("sphere", "mean_angular_error_deg"));
    // Light directions pass through text and are normalised again on reading: equal to
    // rounding, far below the error itself.
    assert!((cli - pipe).abs() <= 1e-9 * pipe, "lumen ps {cli}°, the pipeline's {pipe}°");
    assert_eq!(s["masked_pixels"].as_f64().unwrap(), metric("sphere", "masked_pixels"));
}

/// `pipelines/stress.toml`: at least 30 cases, each declaring its outcome: an error kind, or
/// a result with at least one bound not declared a miss (a case whose claim sits only in
/// declared misses checks nothing). In both pipeline files, a photometric result bounds the
/// share of the mask it refuses (else an error could fall by refusing pixels) and an sfm
/// result bounds how many images it registers.
#[test]
fn stress_suite_declares_every_outcome() {
    let path = common::root().join("pipelines/stress.toml");
    let file = lumen::pipeline::load(&path).unwrap();
    assert!(file.cases.len() >= 30, "{} cases", file.cases.len());
    let all = lumen::pipeline::load(&common::root().join("pipelines/all.toml")).unwrap();
    for c in file.cases.iter().chain(&all.cases) {
        let cm = &c.common;
        if cm.expect_error.is_some() {
            continue;
        }
        let checked = cm.bounds.keys().any(|k| !cm.expected_miss.contains_key(k));
        assert!(checked, "{} declares no outcome a bound checks (only misses, or no bound)", cm.case);
        let bounds = |names: &[&str]| names.iter().any(|n| cm.bounds.contains_key(*n));
        match c.stage.name() {
            "photometric" => assert!(bounds(&["masked_share"]), "{} does not bound masked_share", cm.case),
            "sfm" => assert!(
                bounds(&["registered_images", "unregistered_images"]),
                "{} bounds neither registered_images nor unregistered_images",
                cm.case
            ),
            _ => {}
        }
    }
    for stage in ["render", "calibrate", "photometric"] {
        assert!(
            all.cases.iter().any(|c| c.stage.name() == stage && !c.sweep.is_empty()),
            "no {stage} sweep in all.toml"
        );
    }
}

/// A case with `denoise`: the furnace's denoised image keeps its mean (within 4 standard
/// errors of the render's mean, which noise alone passes but once in 16 000) and is closer
/// to the closed form than the render; a malformed `denoise` is refused by name.
#[test]
fn denoised_case_keeps_the_mean_and_bad_settings_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let text = furnace(0.2, "denoise = true\n")
        .replace("nonfinite_samples = 0 }", "nonfinite_samples = 0, mean_err_sigmas = 4 }");
    let (code, err) = run(&text, &out);
    assert_eq!(code, 0, "{err}");
    let j: serde_json::Value = read_json(&out.join("report.json"));
    let value = |j: &serde_json::Value, name: &str| {
        j["stages"][0]["metrics"].as_array().unwrap().iter().find(|m| m["name"] == name).unwrap()["value"]
            .as_f64()
            .unwrap()
    };
    let denoised = value(&j, "mean_rel_err");
    // What has no meaning for a denoised image is n/a, not a skipped comparison: CI refuses
    // skips while ../shared is present.
    let json = std::fs::read_to_string(out.join("report.json")).unwrap();
    assert!(!json.contains("\"skipped\""), "{json}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("denoised (feature, half buffers cross-filtered)"), "{md}");
    let (code, err) = run(&furnace(0.2, ""), &out);
    assert_eq!(code, 0, "{err}");
    let raw = value(&read_json(&out.join("report.json")), "mean_rel_err");
    assert!(denoised < raw / 2.0, "denoised mean |error| {denoised} against the render's {raw}");
    for (bad, says) in [
        ("denoise = \"yes\"", "expected true, false, or a table of the filter's settings"),
        ("denoise = { window_radius = 1000 }", "window radius 1000 is above the largest accepted, 50"),
        ("denoise = { method = \"median\" }", "unknown variant `median`"),
        ("denoise = { radius = 3 }", "unknown field `radius`"),
    ] {
        let (code, err) = run(&furnace(0.2, &format!("{bad}\n")), &out);
        assert_eq!(code, 1, "{bad}: {err}");
        assert!(err.contains("denoise") && err.contains(says), "{bad}: {err}");
    }
}

/// Truth renders made at few samples and denoised must not bias what a stage measures. Each
/// stage runs on the same renders unfiltered and denoised (same seed, same samples), so any
/// difference is the filter's; it must stay within three standard errors of the stage's own
/// headline error: the mean angular error over the mask's n pixels (relative standard error
/// at most 1/√n: a Rayleigh-like error has a coefficient of variation near 0.5), the corner
/// RMS over n corners (1/√(2n)), and the colour patches' χ² per degree of freedom (√(2/dof)).
#[test]
fn denoised_truth_renders_leave_stage_metrics_unbiased() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let scenes = common::root().join("pipelines/scenes");
    let text = format!(
        r#"name = "t"
seed = 1
[[stages]]
stage = "photometric"
case = "blob"
scene = "{0}/ps-blob.toml"
lights = 24
model = "blinn-phong"
spp = 16
sweep = {{ denoise = [false, true] }}
[[stages]]
stage = "calibrate"
case = "board"
scene = "{0}/calib-board.toml"
views = 4
spp = 4
sweep = {{ denoise = [false, true] }}
[[stages]]
stage = "color"
case = "chart"
scene = "{0}/color-chart.toml"
model = "root-poly-2"
spp = 2
sweep = {{ denoise = [false, true] }}
"#,
        scenes.display()
    );
    let (code, err) = run(&text, &out);
    assert_eq!(code, 0, "{err}");
    let j: serde_json::Value = read_json(&out.join("report.json"));
    let value = |s: &serde_json::Value, name: &str| {
        s["metrics"].as_array().unwrap().iter().find(|m| m["name"] == name).unwrap()["value"]
            .as_f64()
            .unwrap()
    };
    let notes = |s: &serde_json::Value| {
        s["notes"].as_array().unwrap().iter().map(|n| n.as_str().unwrap().to_string()).collect::<Vec<_>>()
    };
    // The number just before `marker` in the stage's first note.
    let count_before = |s: &serde_json::Value, marker: &str| -> f64 {
        let n = &notes(s)[0];
        let head = &n[..n.find(marker).unwrap_or_else(|| panic!("{marker} in {n}"))];
        head.split_whitespace().last().unwrap().parse().unwrap()
    };
    for name in ["blob", "board", "chart"] {
        let raw = case(&j, &format!("{name}[denoise=false]"));
        let dn = case(&j, &format!("{name}[denoise=true]"));
        assert!(notes(dn).iter().any(|n| n.contains("denoised (feature filter")), "{name}: {:?}", notes(dn));
        assert!(!notes(raw).iter().any(|n| n.contains("denoised")), "{name}");
        let (metric, a, b, allowed) = match name {
            "blob" => {
                let n = count_before(raw, " object pixels in the mask");
                let m = value(raw, "mean_angular_error_deg");
                ("mean_angular_error_deg", m, value(dn, "mean_angular_error_deg"), 3.0 * m / n.sqrt())
            }
            "board" => {
                // The default board: 9 × 6 inner corners per view.
                let n = count_before(raw, " views of") * 54.0;
                let m = value(raw, "corner_rms_px");
                ("corner_rms_px", m, value(dn, "corner_rms_px"), 3.0 * m / (2.0 * n).sqrt())
            }
            _ => {
                let dof = 3.0 * value(raw, "used_patches");
                (
                    "patch_rgb_chi2",
                    value(raw, "patch_rgb_chi2"),
                    value(dn, "patch_rgb_chi2"),
                    3.0 * (2.0 / dof).sqrt(),
                )
            }
        };
        assert!(
            b - a <= allowed,
            "{name}: {metric} {b} denoised against {a} unfiltered (allowed +{allowed})"
        );
        assert!(b.is_finite() && b >= 0.0, "{name}: {metric} {b}");
    }
}
