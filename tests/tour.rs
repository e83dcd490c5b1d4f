//! The README's tour of the command line, run as written (with a small sample count and the
//! reference data's photographs standing in for `photos/*.jpg` and `in.jpg`) in a temporary
//! folder: each command must succeed and write what the README says it writes, under `out/`.

mod common;

use std::path::Path;
use std::process::Command;

/// The tour's `lumen render|preview|calibrate|ps|undistort|color|hdr|sfm|surface|texture|warp` lines, from the README's tour block.
fn tour_commands() -> Vec<String> {
    let readme = std::fs::read_to_string(common::root().join("README.md")).unwrap();
    let tour = readme.split("## A tour of the command line").nth(1).expect("the README has a tour");
    let block =
        tour.split("```sh").nth(1).and_then(|b| b.split("```").next()).expect("the tour's shell block");
    block
        .lines()
        .filter(|l| {
            [
                "lumen render ",
                "lumen preview ",
                "lumen calibrate ",
                "lumen ps ",
                "lumen undistort ",
                "lumen color ",
                "lumen hdr ",
                "lumen sfm ",
                "lumen surface ",
                "lumen texture ",
                "lumen warp ",
            ]
            .iter()
            .any(|p| l.starts_with(p))
        })
        .map(str::to_string)
        .collect()
}

/// Runs one tour line in `dir`, with repository paths made absolute and optional `[...]`
/// arguments left out.
fn run(line: &str, dir: &Path, photos: &Path) -> (bool, String) {
    let root = common::root();
    let line = line
        .replace("--spp 256", "--spp 4")
        .replace("../shared/", &format!("{}/../shared/", root.display()))
        .replace(" pipelines/", &format!(" {}/pipelines/", root.display()))
        .replace("'photos/*.jpg'", &format!("'{}'", photos.join("*.jpg").display()))
        .replace(" in.jpg ", &format!(" {} ", photos.join("left01.jpg").display()));
    let line = match line.find(" [") {
        Some(k) => line[..k].to_string(),
        None => line,
    };
    let args: Vec<String> =
        line.split_whitespace().skip(1).map(|a| a.trim_matches('\'').to_string()).collect();
    let o = Command::new(env!("CARGO_BIN_EXE_lumen")).args(&args).current_dir(dir).output().unwrap();
    (o.status.success(), format!("{line}\n{}", String::from_utf8_lossy(&o.stderr)))
}

#[test]
fn readme_tour_writes_what_it_says() {
    let lines = tour_commands();
    assert_eq!(lines.len(), 14, "the tour's commands: {lines:?}");
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let shared = common::root().join("../shared/data");
    let photos = shared.join("calibration/opencv-left");
    // Rendering needs nothing beside the project.
    let (ok, err) = run(&lines[0], d, &photos);
    assert!(ok, "{err}");
    for f in [
        "box.exr",
        "box.depth.exr",
        "box.normal.exr",
        "box.albedo.exr",
        "box.id.exr",
        "box.ids.json",
        "box.camera.json",
        "box.variance.exr",
    ] {
        assert!(d.join("out").join(f).is_file(), "{f} missing after: {err}");
    }
    let (ok, err) = run(&lines[1], d, &photos);
    assert!(ok, "{err}");
    for f in ["box.png", "box.depth.png", "box.normal.png", "box.id.png"] {
        assert!(d.join("out").join(f).is_file(), "{f} missing after: {err}");
    }
    let (ok, err) = run(&lines[13], d, &photos);
    assert!(ok, "{err}");
    for f in ["box-left.exr", "box-left.mask.png", "box-left.json"] {
        assert!(d.join("out").join(f).is_file(), "{f} missing after: {err}");
    }
    // Colour: the chart the README's pipeline run keeps (its case chart-d65-root-poly-2),
    // made here by that one case, then the tour's three colour commands.
    let pipeline = d.join("out/chart.toml");
    std::fs::create_dir_all(d.join("out")).unwrap();
    let all = std::fs::read_to_string(common::root().join("pipelines/all.toml")).unwrap();
    let entry = all.split("[[stages]]").find(|e| e.contains("case = \"chart-d65-root-poly-2\"")).unwrap();
    let entry = entry.replace("\"scenes/", &format!("\"{}/pipelines/scenes/", common::root().display()));
    std::fs::write(&pipeline, format!("[[stages]]{entry}")).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_lumen"))
        .args(["run", "out/chart.toml", "--out", "out/all", "--no-cache"])
        .current_dir(d)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for line in &lines[5..8] {
        let (ok, err) = run(line, d, &photos);
        assert!(ok, "{err}");
    }
    for f in [
        "spectral-d65/rgb.csv",
        "spectral-d65/xyz.csv",
        "spectral-d65/white.csv",
        "ccm.json",
        "chart-srgb.png",
    ] {
        assert!(d.join("out").join(f).is_file(), "{f} missing");
    }
    if common::shared_data().is_none() {
        return;
    }
    for line in &lines[2..5] {
        let (ok, err) = run(line, d, &photos);
        assert!(ok, "{err}");
    }
    assert!(d.join("out/camera.yaml").is_file());
    for f in common::PS_OUTPUTS {
        assert!(d.join("out/ps-ball").join(f).is_file(), "ps-ball/{f} missing");
    }
    assert!(d.join("out/undistorted.png").is_file());
    let (ok, err) = run(&lines[8], d, &photos);
    assert!(ok, "{err}");
    for f in ["chart.json", "chart.png"] {
        assert!(d.join("out").join(f).is_file(), "{f} missing after: {err}");
    }
    let (ok, err) = run(&lines[9], d, &photos);
    assert!(ok, "{err}");
    for f in ["radiance.exr", "response.csv", "response.svg", "mask.png", "preview.png", "summary.json"] {
        assert!(d.join("out/memorial").join(f).is_file(), "memorial/{f} missing");
    }
    let (ok, err) = run(&lines[10], d, &photos);
    assert!(ok, "{err}");
    for f in ["cameras.txt", "images.txt", "points3D.txt", "points.ply", "summary.json"] {
        assert!(d.join("out/herz-jesu").join(f).is_file(), "herz-jesu/{f} missing");
    }
    let (ok, err) = run(&lines[11], d, &photos);
    assert!(ok, "{err}");
    for f in ["surface.ply", "surface.json"] {
        assert!(d.join("out/herz-jesu").join(f).is_file(), "herz-jesu/{f} missing");
    }
    let (ok, err) = run(&lines[12], d, &photos);
    assert!(ok, "{err}");
    for f in ["mesh.obj", "mesh.mtl", "texture.png", "summary.json"] {
        assert!(d.join("out/herz-jesu/textured").join(f).is_file(), "herz-jesu/textured/{f} missing");
    }
    // Nothing outside out/.
    let top: Vec<_> = std::fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(top, vec![std::ffi::OsString::from("out")], "the tour wrote outside out/");
}
