//! `lumen run`: the report's shape, bounds and exit codes, and determinism of its numbers.

mod common;

use std::process::Command;

fn run(pipeline: &str, out: &std::path::Path) -> (i32, String) {
    let dir = out.parent().unwrap();
    let p = dir.join("p.toml");
    std::fs::write(&p, pipeline).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_lumen"))
        .args([
            "run",
            p.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--cache",
            dir.join("cache").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    (o.status.code().unwrap_or(-1), String::from_utf8_lossy(&o.stderr).into_owned())
}

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
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(j["pipeline"], "t");
    assert_eq!(j["seed"], 7);
    assert_eq!(j["passed"], true);
    let st = &j["stages"][0];
    assert_eq!(st["stage"], "render");
    assert_eq!(st["case"], "furnace");
    assert_eq!(st["mode"], "alone");
    assert!(st["timings_s"]["total"].as_f64().unwrap() > 0.0);
    let m = st["metrics"].as_array().unwrap().iter().find(|m| m["name"] == "mean_rel_err").unwrap();
    assert_eq!(m["bound"], 0.2);
    assert_eq!(m["pass"], true);
    assert_eq!(m["unit"], "");
    let v1 = m["value"].as_f64().unwrap();
    assert!(v1 > 0.0 && v1 < 0.2);
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("| mean_rel_err |") && md.contains("pass"), "{md}");
    // The same file and seed give the same numbers.
    let (code, _) = run(&furnace(0.2, ""), &out);
    assert_eq!(code, 0);
    let j2: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let m2 = j2["stages"][0]["metrics"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["name"] == "mean_rel_err")
        .unwrap()
        .clone();
    assert_eq!(m2["value"].as_f64().unwrap(), v1);
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

#[test]
fn missing_reference_is_skipped_with_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let extra = "reference = \"/nonexistent/ref.exr\"\nreference_variance = \"/nonexistent/var.exr\"\n";
    let (code, err) = run(&furnace(0.2, extra), &out);
    assert_eq!(code, 0, "{err}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("/nonexistent/ref.exr not found: comparison skipped"), "{md}");
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
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let img = lumen::image::io::read_exr(&out).unwrap();
    assert_eq!((img.width, img.height, img.channels), (16, 16, 3));
    for name in ["f.depth.exr", "f.normal.exr", "f.id.exr", "f.variance.exr", "f.ids.json"] {
        assert!(dir.path().join(name).exists(), "{name} missing");
    }
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
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
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
