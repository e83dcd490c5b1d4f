//! Helpers shared by the integration tests.
#![allow(dead_code)]

use lumen::render::{self, Scene};
use std::path::{Path, PathBuf};

/// Builds a scene from TOML text as if it were a file in `dir`.
pub fn scene(toml_text: &str, dir: &Path) -> Result<Scene, render::Error> {
    let path = dir.join("scene.toml");
    std::fs::write(&path, toml_text).expect("temp dir is writable");
    render::load(&path)
}

/// The project root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `../shared/data`, or `None` (with a printed reason) when it is absent.
pub fn shared_data() -> Option<PathBuf> {
    let p = root().join("../shared/data");
    if p.is_dir() {
        Some(p)
    } else {
        eprintln!("skipped: {} is absent (the reference data lives beside the project)", p.display());
        None
    }
}

pub fn settings(scene: &Scene, spp: u32, max_depth: u32) -> render::Settings {
    let mut s = render::Settings::from_scene(scene);
    s.spp = spp;
    s.max_depth = max_depth;
    s
}
