//! The path loop itself: the furnace, thread-count and eight-lane bit identity.

use super::*;
use lumen::render;

/// pbrt-v4's furnace: Kd 0.5, Le 0.5 inside a closed sphere gives L = Le/(1−ρ) = 1.
#[test]
fn furnace_is_one_everywhere() {
    let scene = render::load(&common::root().join("pipelines/scenes/furnace.toml")).unwrap();
    let film = render::render(&scene, &common::settings(&scene, 16384, 1000));
    let worst = film.mean.data.iter().map(|&v| (v as f64 - 1.0).abs()).fold(0.0, f64::max);
    assert!(worst < 0.01, "worst pixel differs from 1 by {worst}");
    assert_eq!(film.dropped_samples, 0);
}

/// One thread and two give bit-identical images (random streams are keyed by pixel and sample).
#[test]
fn one_and_two_threads_are_bit_identical() {
    let scene = render::load(&common::root().join("pipelines/scenes/cornell-box.toml")).unwrap();
    let mut s = common::settings(&scene, 8, 8);
    s.crop = Some([96, 96, 160, 160]);
    s.threads = Some(1);
    let a = render::render(&scene, &s);
    s.threads = Some(2);
    let b = render::render(&scene, &s);
    assert!(a.mean.data.iter().zip(&b.mean.data).all(|(x, y)| x.to_bits() == y.to_bits()));
    assert!(a.variance.data.iter().zip(&b.variance.data).all(|(x, y)| x.to_bits() == y.to_bits()));
    assert!(a.mean.data.iter().any(|&v| v > 0.0));
}

/// Lambertian surfaces, textured or not, spheres and triangles, under area lights (a quad, and
/// a torus of 144 triangles, so the light pick searches), point and directional lights
/// together.
const MIXED_LIGHTS: &str = r#"
[camera]
width = 40
height = 32
fov_deg = 50.0
look_at = { origin = [0.0, 1.2, 3.5], target = [0.0, 0.4, 0.0], up = [0.0, 1.0, 0.0] }
[[materials]]
name = "floor"
type = "lambertian"
albedo = { checker = { squares = [6, 6], even = [0.7, 0.6, 0.5], odd = [0.1, 0.2, 0.3] } }
[[materials]]
name = "ball"
type = "lambertian"
albedo = [0.5, 0.7, 0.4]
[[materials]]
name = "lamp"
type = "lambertian"
albedo = [0.0, 0.0, 0.0]
emission = [6.0, 5.0, 4.0]
[[shapes]]
type = "quad"
corner = [-1.0, 0.0, 1.0]
edge_u = [2.0, 0.0, 0.0]
edge_v = [0.0, 0.0, -2.0]
material = "floor"
[[shapes]]
type = "sphere"
center = [0.2, 0.5, 0.0]
radius = 0.5
material = "ball"
[[shapes]]
type = "quad"
corner = [-0.95, 1.6, 0.15]
edge_u = [0.3, 0.0, 0.0]
edge_v = [0.0, 0.0, 0.3]
material = "lamp"
[[shapes]]
type = "torus"
radius = 0.25
tube = 0.04
segments = [12, 6]
material = "lamp"
transform = { rvec = [1.5708, 0.0, 0.0], translation = [0.8, 1.2, -0.4] }
[[lights]]
type = "point"
position = [1.0, 1.5, 1.0]
power = [20.0, 20.0, 20.0]
[[lights]]
type = "directional"
to_light = [-0.3, 1.0, 0.4]
irradiance = [0.5, 0.6, 0.7]
"#;

/// The eight-lane path loop (`render::integrators::path::lanes`) gives the one-path loop's image bit for bit,
/// with either sampler, with a pinhole or a thin lens, on every kind of scene it takes.
#[test]
fn eight_lanes_match_the_scalar_loop_bit_for_bit() {
    // Without AVX2 the lanes never run, and the comparison would set the one-path loop
    // against itself.
    if !is_x86_feature_detected!("avx2") {
        common::skip_needing("AVX2", "the eight-lane loop runs only on processors with AVX2");
        return;
    }
    let root = common::root();
    let dir = tempfile::tempdir().unwrap();
    let mixed = common::scene(MIXED_LIGHTS, dir.path()).unwrap();
    let lens =
        MIXED_LIGHTS.replace("fov_deg = 50.0", "fov_deg = 50.0\naperture_radius = 0.1\nfocus_distance = 3.0");
    let lens = common::scene(&lens, dir.path()).unwrap();
    assert!(lens.lens.is_some());
    let cornell = render::load(&root.join("pipelines/scenes/cornell-box.toml")).unwrap();
    let board = render::load(&root.join("pipelines/scenes/calib-board.toml")).unwrap();
    // Mitsuba's Cornell box read from XML: one-sided walls (the light's back is hit from the
    // ceiling's side) and the gaussian pixel filter.
    let xml = root.join("tests/data/mitsuba/cornell-box.xml");
    let params = [("rfilter".to_string(), "gaussian".to_string()), ("res".to_string(), "48".to_string())];
    let one_sided = render::scene::load_mitsuba(&xml, &params).unwrap();
    assert!(one_sided.materials.iter().all(|m| m.one_sided));
    let cases = [
        ("mixed lights", &mixed, render::sampler::SamplerKind::Independent, None),
        ("mixed lights, Sobol", &mixed, render::sampler::SamplerKind::Sobol, None),
        ("thin lens, Sobol", &lens, render::sampler::SamplerKind::Sobol, None),
        ("Cornell box", &cornell, render::sampler::SamplerKind::Independent, Some([100, 20, 140, 200])),
        ("Cornell box, Sobol", &cornell, render::sampler::SamplerKind::Sobol, Some([100, 20, 140, 200])),
        ("calibration board", &board, render::sampler::SamplerKind::Independent, Some([200, 150, 260, 190])),
        (
            "one-sided Cornell box, gaussian filter",
            &one_sided,
            render::sampler::SamplerKind::Independent,
            None,
        ),
    ];
    for (name, scene, sampler, crop) in cases {
        let mut s = common::settings(scene, 8, 8);
        s.sampler = sampler;
        s.crop = crop;
        assert!(render::integrators::path::lanes_supported(scene, &s), "{name}: not taken");
        let a = render::render(scene, &s);
        s.lanes = false;
        let b = render::render(scene, &s);
        let same = |x: &[f32], y: &[f32]| x.iter().zip(y).all(|(x, y)| x.to_bits() == y.to_bits());
        assert!(same(&a.mean.data, &b.mean.data), "{name}: means differ");
        assert!(same(&a.variance.data, &b.variance.data), "{name}: variances differ");
        assert!(a.mean.data.iter().any(|&v| v > 0.0), "{name}: black");
    }
}
