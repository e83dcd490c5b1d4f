//! Participating media against their closed forms (`render::media`, `integrators::volpath`):
//! Beer–Lambert through a bounded slab and through a medium filling the scene, the furnace for
//! media, and `volpath` against `path` where there is no medium.

use super::*;
use glam::DVec2;
use lumen::math::stats;

/// Gauss–Legendre nodes and weights on [−1, 1], 4 points.
const NODES: [f64; 4] =
    [-0.861_136_311_594_053, -0.339_981_043_584_856, 0.339_981_043_584_856, 0.861_136_311_594_053];
const WEIGHTS: [f64; 4] =
    [0.347_854_845_137_454, 0.652_145_154_862_546, 0.652_145_154_862_546, 0.347_854_845_137_454];

/// Each pixel channel of `film` against `expected(pixel position) [channel]` integrated over the
/// pixel (4 × 4 Gauss–Legendre): ≥ 99 % within 3 standard errors, none beyond Šidák's α = 0.01,
/// and the sum over the image within 4 standard errors of the expected sum.
fn compare(film: &render::Film, w: u32, h: u32, expected: impl Fn(DVec2) -> [f64; 3]) {
    let tests = (w * h * 3) as usize;
    let alpha = stats::sidak_alpha(0.01, tests);
    let (mut within3, mut worst_p) = (0usize, 1.0f64);
    let (mut diff, mut var) = ([0.0f64; 3], [0.0f64; 3]);
    for j in 0..h {
        for i in 0..w {
            let mut e = [0.0f64; 3];
            for (a, wa) in NODES.iter().zip(WEIGHTS) {
                for (b, wb) in NODES.iter().zip(WEIGHTS) {
                    let v = expected(DVec2::new(i as f64 + a / 2.0, j as f64 + b / 2.0));
                    for c in 0..3 {
                        e[c] += wa * wb / 4.0 * v[c];
                    }
                }
            }
            for c in 0..3 {
                let m = film.mean.pixel(i, j)[c] as f64;
                let v = film.variance.pixel(i, j)[c] as f64;
                diff[c] += m - e[c];
                var[c] += v;
                let z = if v > 0.0 {
                    (m - e[c]) / v.sqrt()
                } else if (m - e[c]).abs() < 1e-6 * e[c].abs().max(1e-6) {
                    0.0
                } else {
                    f64::INFINITY
                };
                if z.abs() <= 3.0 {
                    within3 += 1;
                }
                worst_p = worst_p.min(stats::two_sided_p(z));
            }
        }
    }
    let frac = within3 as f64 / tests as f64;
    assert!(frac >= 0.99, "only {frac} of pixel channels within 3 standard errors (expect 0.9973)");
    assert!(worst_p >= alpha, "a pixel channel is off by p = {worst_p:.2e} < Šidák α = {alpha:.2e}");
    for c in 0..3 {
        let z = diff[c] / var[c].sqrt();
        assert!(
            z.abs() <= 4.0,
            "channel {c}: the image's sum is {z:.2} standard errors from the closed form"
        );
    }
}

const CAMERA_DOWN: &str = "[camera]\nwidth = 24\nheight = 24\nfx = 30.0\nfy = 30.0\ncx = 11.5\ncy = 11.5\n";

/// An emitting square at z = 0 (radiance `LE`, facing up) under a camera looking straight down.
const LE: [f64; 3] = [2.0, 3.0, 4.0];
const LAMP: &str = r#"
[[materials]]
name = "lamp"
type = "lambertian"
albedo = [0.0, 0.0, 0.0]
emission = [2.0, 3.0, 4.0]
[[shapes]]
type = "quad"
corner = [-4.0, -4.0, 0.0]
edge_u = [8.0, 0.0, 0.0]
edge_v = [0.0, 8.0, 0.0]
material = "lamp"
"#;

/// Beer–Lambert through a slab 1 thick of purely absorbing medium (σt = 0.3, 0.7, 1.2 per
/// channel), bounded by a `null` box, seen from outside: L = Lₑ·exp(−σt·1/cos θ) for a ray at θ
/// from the slab's normal.
#[test]
fn beer_lambert_through_a_slab() {
    let sigma = [0.3, 0.7, 1.2];
    let text = format!(
        "{CAMERA_DOWN}look_at = {{ origin = [0.0, 0.0, 3.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }}\n[render]\nintegrator = \"volpath\"\n{LAMP}\n[[materials]]\nname = \"boundary\"\ntype = \"null\"\n[[shapes]]\ntype = \"cube\"\nmaterial = \"boundary\"\ninterior = \"ink\"\ntransform = {{ scale = [3.0, 3.0, 0.5], translation = [0.0, 0.0, 1.0] }}\n[[media]]\nname = \"ink\"\nsigma_t = {sigma:?}\nalbedo = [0.0, 0.0, 0.0]\n"
    );
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene(&text, dir.path()).unwrap();
    let film = render::render(&scene, &common::settings(&scene, 64, 8));
    compare(&film, 24, 24, |px| {
        let (_, d) = scene.camera_ray(px).unwrap();
        let path = 1.0 / -d.z;
        [0, 1, 2].map(|c| LE[c] * (-sigma[c] * path).exp())
    });
}

/// An absorbing medium filling the scene, the camera and the emitter inside it: L = Lₑ·e^(−σt·d)
/// with d the ray's length to the emitter.
#[test]
fn absorbing_medium_in_front_of_emitter() {
    let sigma = [0.2, 0.5, 0.9];
    let text = format!(
        "{CAMERA_DOWN}medium = \"ink\"\nlook_at = {{ origin = [0.0, 0.0, 1.5], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }}\n[render]\nintegrator = \"volpath\"\n{LAMP}\n[[media]]\nname = \"ink\"\nsigma_a = {sigma:?}\nsigma_s = [0.0, 0.0, 0.0]\n"
    );
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene(&text, dir.path()).unwrap();
    let film = render::render(&scene, &common::settings(&scene, 64, 8));
    compare(&film, 24, 24, |px| {
        let (o, d) = scene.camera_ray(px).unwrap();
        let dist = o.z / -d.z;
        [0, 1, 2].map(|c| LE[c] * (-sigma[c] * dist).exp())
    });
}

/// The furnace for media: inside a closed sphere whose black wall emits Lₑ inwards, a medium
/// that only scatters (albedo 1; chromatic σt, forward-scattering HG) leaves L = Lₑ in every
/// direction at every point, however often light scatters on the way. The camera sits in it.
#[test]
fn scattering_medium_in_an_emitting_sphere() {
    for (g, sigma) in [(0.0, [0.5, 1.0, 2.0]), (0.6, [2.0, 1.0, 0.5])] {
        let text = format!(
            "{CAMERA_DOWN}medium = \"fog\"\nlook_at = {{ origin = [0.2, 0.1, 0.3], target = [0.0, 0.0, -1.0], up = [0.0, 1.0, 0.0] }}\n[render]\nintegrator = \"volpath\"\n[[materials]]\nname = \"wall\"\ntype = \"lambertian\"\nalbedo = [0.0, 0.0, 0.0]\nemission = {LE:?}\n[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\nmaterial = \"wall\"\nreverse_orientation = true\n[[media]]\nname = \"fog\"\nsigma_t = {sigma:?}\nalbedo = [1.0, 1.0, 1.0]\ng = {g}\n"
        );
        let dir = tempfile::tempdir().unwrap();
        let scene = common::scene(&text, dir.path()).unwrap();
        let film = render::render(&scene, &common::settings(&scene, 128, 1000));
        compare(&film, 24, 24, |_| LE);
    }
}

/// Where there is no medium, `volpath` is `path`: the Cornell box from both, pixel by pixel
/// within the two renders' noise.
#[test]
fn volpath_without_media_is_path() {
    let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("pipelines/scenes/cornell-box.toml");
    let scene = render::load(&file).unwrap();
    let mut s = common::settings(&scene, 16, 8);
    s.crop = Some([100, 100, 132, 132]);
    let path = render::render(&scene, &s);
    s.integrator = render::integrators::find("volpath").unwrap();
    let vol = render::render(&scene, &s);
    let n = path.mean.data.len();
    let alpha = stats::sidak_alpha(0.01, n);
    let (mut within3, mut worst_p, mut diff, mut var) = (0, 1.0f64, 0.0f64, 0.0f64);
    for k in 0..n {
        let d = (vol.mean.data[k] - path.mean.data[k]) as f64;
        let v = (vol.variance.data[k] + path.variance.data[k]) as f64;
        let z = if v > 0.0 { d / v.sqrt() } else { 0.0 };
        within3 += (z.abs() <= 3.0) as usize;
        worst_p = worst_p.min(stats::two_sided_p(z));
        diff += d;
        var += v;
    }
    assert!(within3 as f64 / n as f64 >= 0.99, "only {within3} of {n} pixel channels agree within 3σ");
    assert!(worst_p >= alpha, "a pixel channel differs by p = {worst_p:.2e} < {alpha:.2e}");
    assert!((diff / var.sqrt()).abs() <= 4.0, "the crop's sums differ by {:.2}σ", diff / var.sqrt());
}

/// A heterogeneous absorbing slab from a voxel grid, 1 thick (z from 0.5 to 1.5) and 6 wide
/// (x from −3 to 3), over a Lambertian floor lit straight down by a directional light. The grid
/// is 2 × 1 × 1 cells of three channels, a then b along x: trilinear between the cell centres,
/// so where the camera sees (grid x in (0.25, 0.75)) the density is linear in x, and a ray's
/// optical depth through the slab is σt·ρ(x at the slab's middle)/cos θ. The floor then shows
/// ρ/π·E·e^(−τ_light)·e^(−τ_view): the light's way down through ratio tracking, the camera's
/// way through delta tracking, and the grid's placement and orientation with them.
#[test]
fn heterogeneous_slab_over_a_lit_floor() {
    let (a, b) = ([0.2f64, 0.5, 1.0], [1.0f64, 0.6, 0.0]);
    let dir = tempfile::tempdir().unwrap();
    let values: Vec<f32> = a.iter().chain(&b).map(|&v| v as f32).collect();
    render::media::grid::write(&dir.path().join("ramp.vol"), [2, 1, 1], 3, ([0.0; 3], [1.0; 3]), &values)
        .unwrap();
    let sigma = 1.2;
    let text = format!(
        "{CAMERA_DOWN}look_at = {{ origin = [0.0, 0.0, 3.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }}\n[render]\nintegrator = \"volpath\"\n[[materials]]\nname = \"floor\"\ntype = \"lambertian\"\nalbedo = [0.8, 0.8, 0.8]\n[[materials]]\nname = \"boundary\"\ntype = \"null\"\n[[shapes]]\ntype = \"quad\"\ncorner = [-4.0, -4.0, 0.0]\nedge_u = [8.0, 0.0, 0.0]\nedge_v = [0.0, 8.0, 0.0]\nmaterial = \"floor\"\n[[shapes]]\ntype = \"cube\"\nmaterial = \"boundary\"\ninterior = \"ramp\"\ntransform = {{ scale = [3.0, 3.0, 0.5], translation = [0.0, 0.0, 1.0] }}\n[[lights]]\ntype = \"directional\"\nto_light = [0.0, 0.0, 1.0]\nirradiance = [3.0, 3.0, 3.0]\n[[media]]\nname = \"ramp\"\nsigma_t = [{sigma}, {sigma}, {sigma}]\nalbedo = [0.0, 0.0, 0.0]\ngrid = \"ramp.vol\"\ngrid_transform = {{ scale = [6.0, 6.0, 1.0], translation = [-3.0, -3.0, 0.5] }}\n"
    );
    let scene = common::scene(&text, dir.path()).unwrap();
    let film = render::render(&scene, &common::settings(&scene, 256, 8));
    // The density at scene x, in the linear part of the grid (x within ±1.5).
    let rho = |c: usize, x: f64| {
        let u = (x + 3.0) / 6.0;
        assert!((0.25..=0.75).contains(&u), "x {x} is outside the grid's linear part");
        a[c] + (b[c] - a[c]) * (u - 0.25) / 0.5
    };
    compare(&film, 24, 24, |px| {
        let (o, d) = scene.camera_ray(px).unwrap();
        let at = |z: f64| o.x + d.x * (z - o.z) / d.z;
        [0, 1, 2].map(|c| {
            let view = sigma * rho(c, at(1.0)) / -d.z;
            let light = sigma * rho(c, at(0.0));
            0.8 / std::f64::consts::PI * 3.0 * (-light).exp() * (-view).exp()
        })
    });
}
