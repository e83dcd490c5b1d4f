//! lumen against an independent renderer: Mitsuba 3's 8192-spp Cornell box (in ../shared)
//! and the references in tests/data/mitsuba, rendered by tools/mitsuba_reference.py from the
//! same scenes written in Mitsuba's terms (the script says how each part was matched).

mod common;

use lumen::image::{io, metrics};
use lumen::render;

/// Per-channel image means within 1 % of Mitsuba's, and a per-pixel z-test (lumen's variance +
/// the reference's, Šidák-corrected at α = 0.01) accepting ≥ 99.75 % of pixel channels.
#[test]
fn cornell_box_matches_mitsuba() {
    let Some(data) = common::shared_data() else { return };
    let dir = data.join("scenes/cornell-box");
    let reference = io::read_exr(&dir.join("reference.exr")).unwrap();
    let ref_var = io::read_exr(&dir.join("reference_variance.exr")).unwrap();
    let scene = render::load(&common::root().join("pipelines/scenes/cornell-box.toml")).unwrap();
    let film = render::render(&scene, &common::settings(&scene, 256, 8));
    assert!(!film.mean.has_non_finite() && film.dropped_samples == 0);
    let a = metrics::agreement(&film.mean, &film.variance, &reference, &ref_var, 0.01).unwrap();
    eprintln!("{a:?}");
    for (c, e) in a.mean_rel_err.iter().enumerate() {
        assert!(e.abs() < 0.01, "channel {c}: mean differs by {:.3} %", 100.0 * e);
    }
    assert!(a.pass_fraction >= 0.9975, "{} of {} pixel channels fail the z-test", a.failed, a.tested);
}

/// Two rough metal spheres (GGX gold, Beckmann copper) on a diffuse floor under a small area
/// light: glossy reflection and multiple importance sampling against Mitsuba 3's
/// `roughconductor` (16384 spp). Means within 1 %, ≥ 99 % of pixel channels pass the z-test.
#[test]
fn glossy_spheres_match_mitsuba() {
    let dir = common::root().join("tests/data/mitsuba");
    let reference = io::read_exr(&dir.join("glossy-spheres.exr")).unwrap();
    let ref_var = io::read_exr(&dir.join("glossy-spheres_variance.exr")).unwrap();
    let scene = render::load(&common::root().join("pipelines/scenes/glossy-spheres.toml")).unwrap();
    let film = render::render(&scene, &common::settings(&scene, 256, 6));
    assert!(!film.mean.has_non_finite() && film.dropped_samples == 0);
    let a = metrics::agreement(&film.mean, &film.variance, &reference, &ref_var, 0.01).unwrap();
    eprintln!("{a:?}");
    for (c, e) in a.mean_rel_err.iter().enumerate() {
        assert!(e.abs() < 0.01, "channel {c}: mean differs by {:.3} %", 100.0 * e);
    }
    assert!(a.pass_fraction >= 0.99, "{} of {} pixel channels fail the z-test", a.failed, a.tested);
}
