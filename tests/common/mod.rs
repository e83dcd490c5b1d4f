//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod run;

use lumen::render::{self, Scene};
use std::path::{Path, PathBuf};

/// Builds a scene from TOML text as if it were a file in `dir`.
pub fn scene(toml_text: &str, dir: &Path) -> Result<Scene, render::Error> {
    let path = dir.join("scene.toml");
    std::fs::write(&path, toml_text).expect("temp dir is writable");
    render::load(&path)
}

/// What `lumen ps` writes for a Lambertian model on a dataset with ground truth.
pub const PS_OUTPUTS: [&str; 8] = [
    "normals.exr",
    "normals.png",
    "albedo.exr",
    "albedo.png",
    "error.png",
    "depth.exr",
    "surface.obj",
    "summary.json",
];

/// Runs the lumen binary with `args`: its exit code (−1 when killed) and its stderr.
pub fn lumen(args: &[&str]) -> (i32, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_lumen")).args(args).output().expect("runs");
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// The kind of fault a `lumen` error message declares (`error (bad-input): …` → `bad-input`),
/// or "" when it declares none.
pub fn fault_in(stderr: &str) -> &str {
    stderr
        .lines()
        .find_map(|l| l.strip_prefix("error ("))
        .and_then(|rest| rest.split_once("):"))
        .map_or("", |(kind, _)| kind)
}

/// The project root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Where skipped tests are listed: the test harness hides what a passing test prints, so a
/// skip is also written here, one line per test, for `.ci/run` to count and show.
pub fn skip_list() -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join("skipped-tests.txt")
}

/// Records that the running test skipped its comparison for want of `../shared`, and why.
pub fn skip(reason: &str) {
    skip_needing("../shared", reason);
}

/// Records that the running test skipped its comparison for want of `what` (`../shared`, or
/// something the machine lacks, such as a running Slurm), and why: one line
/// `TEST: needs WHAT: REASON`, which `.ci/run` counts by what was missing.
pub fn skip_needing(what: &str, reason: &str) {
    let test = std::thread::current().name().unwrap_or("?").to_string();
    eprintln!("skipped (needs {what}): {reason}");
    let line = format!("{test}: needs {what}: {reason}\n");
    let _ = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(skip_list())
        .and_then(|mut f| std::io::Write::write_all(&mut f, line.as_bytes()));
}

/// `../shared/data`, or `None` (the skip recorded with its reason) when it is absent.
pub fn shared_data() -> Option<PathBuf> {
    let p = root().join("../shared/data");
    if p.is_dir() {
        Some(p)
    } else {
        skip(&format!("{} is absent (the reference data lives beside the project)", p.display()));
        None
    }
}

/// OpenCV's 13 sample chessboard photographs (`../shared/data/calibration/opencv-left`),
/// sorted, or `None` (with a printed reason) without `../shared`.
pub fn calibration_photographs() -> Option<Vec<PathBuf>> {
    let dir = shared_data()?.join("calibration/opencv-left");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("the calibration folder is readable")
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "jpg"))
        .collect();
    files.sort();
    Some(files)
}

/// An image file as lumen's detectors see it.
pub fn grey(path: &Path) -> lumen::image::filter::Grey {
    lumen::image::filter::Grey::from_image(&lumen::image::io::read(path).expect("a readable image"))
}

pub fn settings(scene: &Scene, spp: u32, max_depth: u32) -> render::Settings {
    let mut s = render::Settings::from_scene(scene);
    s.spp = spp;
    s.max_depth = max_depth;
    s
}

/// Writes an 8-bit RGB PNG of `w × h` whose pixel (x, y) is `f(x, y)`.
pub fn png(path: &Path, w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 3]) {
    let mut img = image::RgbImage::new(w, h);
    for (x, y, p) in img.enumerate_pixels_mut() {
        *p = image::Rgb(f(x, y));
    }
    img.save(path).unwrap();
}
