//! The renderer against closed forms: furnace, a point light over a plane, an emissive quad's
//! irradiance, projection of a small sphere, the distortion round trip, and determinism.

mod common;

use glam::{DVec2, DVec3};
use lumen::math::stats;
use lumen::math::{CameraModel, Distortion, Intrinsics};
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

const PLANE: &str = r#"
[camera]
width = 48
height = 48
fx = 40.0
fy = 40.0
cx = 23.5
cy = 23.5
look_at = { origin = [0.0, 0.0, 2.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }
[[materials]]
name = "paper"
type = "lambertian"
albedo = [0.8, 0.5, 0.2]
[[shapes]]
type = "quad"
corner = [-3.0, -3.0, 0.0]
edge_u = [6.0, 0.0, 0.0]
edge_v = [0.0, 6.0, 0.0]
material = "paper"
[[lights]]
type = "point"
position = [0.3, -0.2, 1.0]
power = [50.0, 50.0, 50.0]
"#;

/// L = ρ/π · Φ cosθ / (4π r²), integrated over each pixel's footprint by 4×4 Gauss–Legendre.
#[test]
fn lambertian_plane_under_point_light() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene(PLANE, dir.path()).unwrap();
    let film = render::render(&scene, &common::settings(&scene, 64, 2));
    let light = DVec3::new(0.3, -0.2, 1.0);
    let rho = [0.8, 0.5, 0.2];
    let intensity = 50.0 / (4.0 * std::f64::consts::PI);
    let radiance_at = |px: DVec2| -> f64 {
        let (o, d) = scene.camera_ray(px).unwrap();
        let x = o + d * (-o.z / d.z); // the plane z = 0
        let to = light - x;
        let r2 = to.length_squared();
        intensity * (to.z / r2.sqrt()) / r2 / std::f64::consts::PI
    };
    let nodes =
        [-0.861_136_311_594_053, -0.339_981_043_584_856, 0.339_981_043_584_856, 0.861_136_311_594_053];
    let weights =
        [0.347_854_845_137_454, 0.652_145_154_862_546, 0.652_145_154_862_546, 0.347_854_845_137_454];
    let tests = (48 * 48 * 3) as usize;
    let alpha = stats::sidak_alpha(0.01, tests);
    let (mut within3, mut worst_p) = (0, 1.0f64);
    for j in 0..48u32 {
        for i in 0..48u32 {
            let mut e = 0.0;
            for (a, wa) in nodes.iter().zip(weights) {
                for (b, wb) in nodes.iter().zip(weights) {
                    e += wa * wb / 4.0 * radiance_at(DVec2::new(i as f64 + a / 2.0, j as f64 + b / 2.0));
                }
            }
            for c in 0..3 {
                let m = film.mean.pixel(i, j)[c] as f64;
                let se = (film.variance.pixel(i, j)[c] as f64).sqrt();
                let z = (m - rho[c] * e) / se;
                assert!(se > 0.0 && z.is_finite());
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
}

/// The truth images of the same plane: depth, normals and position are known exactly.
#[test]
fn truth_images_of_plane() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene(PLANE, dir.path()).unwrap();
    let t = render::truth(&scene, None);
    for j in 0..48 {
        for i in 0..48 {
            assert!((t.depth.pixel(i, j)[0] - 2.0).abs() < 1e-5);
            assert_eq!(t.normal.pixel(i, j), &[0.0, 0.0, 1.0]);
            let nc = t.normal_camera.pixel(i, j);
            assert!(nc[0].abs() < 1e-6 && nc[1].abs() < 1e-6 && (nc[2] + 1.0).abs() < 1e-6);
            assert!(t.position.pixel(i, j)[2].abs() < 1e-6);
            assert_eq!(t.albedo.pixel(i, j), &[0.8, 0.5, 0.2]);
            assert_eq!(t.id.pixel(i, j)[0], 1.0);
        }
    }
}

/// A lamp shape (emitting radiance 2 from its front) over a 4×4 Lambertian floor of albedo 0.9
/// at z = 0, direct light only; a 3×3 camera at z = 0.5 looking straight down with a footprint
/// of 0.0005 rad per pixel: the centre pixel's mean and standard error after `spp` samples.
fn floor_under_lamp(lamp: &str, spp: u32) -> (f64, f64) {
    let text = format!(
        "[camera]\nwidth = 3\nheight = 3\nfx = 2000.0\nfy = 2000.0\ncx = 1.0\ncy = 1.0\nlook_at = {{ origin = [0.0, 0.0, 0.5], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }}\n[[materials]]\nname = \"lamp\"\ntype = \"lambertian\"\nalbedo = [0.0, 0.0, 0.0]\nemission = [2.0, 2.0, 2.0]\n[[materials]]\nname = \"floor\"\ntype = \"lambertian\"\nalbedo = [0.9, 0.9, 0.9]\n[[shapes]]\n{lamp}\nmaterial = \"lamp\"\n[[shapes]]\ntype = \"quad\"\ncorner = [-2.0, -2.0, 0.0]\nedge_u = [4.0, 0.0, 0.0]\nedge_v = [0.0, 4.0, 0.0]\nmaterial = \"floor\"\n"
    );
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene(&text, dir.path()).unwrap();
    let mut s = common::settings(&scene, spp, 2);
    s.crop = Some([1, 1, 2, 2]);
    let film = render::render(&scene, &s);
    (film.mean.data[0] as f64, (film.variance.data[0] as f64).sqrt())
}

/// Irradiance on the axis of a uniformly emitting rectangle with half sides a, b at distance d:
/// E = 2L [X/√(1+X²)·atan(Y/√(1+X²)) + Y/√(1+Y²)·atan(X/√(1+Y²))], X = a/d, Y = b/d.
#[test]
fn emissive_quad_on_axis_irradiance() {
    let lamp =
        "type = \"quad\"\ncorner = [-0.5, -0.3, 1.0]\nedge_u = [0.0, 0.6, 0.0]\nedge_v = [1.0, 0.0, 0.0]";
    let (got, se) = floor_under_lamp(lamp, 1 << 18);
    let (x, y, l) = (0.5f64, 0.3f64, 2.0f64);
    let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
    let e = 2.0 * l * (x / sx * (y / sx).atan() + y / sy * (x / sy).atan());
    let expected = 0.9 / std::f64::consts::PI * e;
    assert!(((got - expected) / se).abs() < 4.0, "got {got}, expected {expected}, standard error {se}");
    assert!((got / expected - 1.0).abs() < 2e-3, "got {got}, expected {expected}");
}

fn camera_640(distortion: Distortion) -> CameraModel {
    CameraModel {
        width: 640,
        height: 480,
        intrinsics: Intrinsics { fx: 500.0, fy: 500.0, cx: 319.5, cy: 239.5 },
        distortion,
    }
}

const STRONG: Distortion = Distortion { k1: -0.3, k2: 0.1, p1: 0.001, p2: -0.0005, k3: 0.0 };

/// The silhouette of a sphere (centre `c` in the camera frame, radius `r`) projected by the
/// forward camera model: a closed polygon in pixel coordinates.
fn projected_silhouette(cam: &CameraModel, c: DVec3, r: f64, n: usize) -> Vec<DVec2> {
    let d2 = c.length_squared();
    let centre = c * (1.0 - r * r / d2);
    let rho = r * (1.0 - r * r / d2).sqrt();
    let axis = c.normalize();
    let u = axis.any_orthonormal_vector();
    let v = axis.cross(u);
    (0..n)
        .map(|k| {
            let phi = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
            cam.project(centre + rho * (phi.cos() * u + phi.sin() * v)).unwrap()
        })
        .collect()
}

/// Area of a polygon clipped to the pixel square centred on (x, y) (Sutherland–Hodgman).
fn area_in_pixel(poly: &[DVec2], x: f64, y: f64) -> f64 {
    let mut pts = poly.to_vec();
    // Each half-plane as (axis, bound, keep-below).
    for (axis, bound, below) in
        [(0, x + 0.5, true), (0, x - 0.5, false), (1, y + 0.5, true), (1, y - 0.5, false)]
    {
        let inside = |p: DVec2| {
            if below {
                p[axis] <= bound
            } else {
                p[axis] >= bound
            }
        };
        let mut out = Vec::with_capacity(pts.len() + 4);
        for i in 0..pts.len() {
            let (a, b) = (pts[i], pts[(i + 1) % pts.len()]);
            if inside(a) {
                out.push(a);
            }
            if inside(a) != inside(b) {
                let t = (bound - a[axis]) / (b[axis] - a[axis]);
                out.push(a + (b - a) * t);
            }
        }
        pts = out;
        if pts.is_empty() {
            return 0.0;
        }
    }
    let mut area = 0.0;
    for i in 0..pts.len() {
        let (a, b) = (pts[i], pts[(i + 1) % pts.len()]);
        area += a.x * b.y - b.x * a.y;
    }
    area.abs() / 2.0
}

/// A small emissive sphere appears where the f64 camera model projects it, with and without
/// strong barrel distortion: the intensity centroid of the render matches, within 0.02 px, the
/// centroid of the same pixels filled by the sphere's silhouette as the forward model projects
/// it (area of the projected silhouette in each pixel). Comparing with the pixelated silhouette
/// rather than the projected centre removes the pixel-phase bias of centroiding a sharp disk
/// (up to 0.02 px for a 1.3 px radius), which is a property of sampling, not of the renderer.
#[test]
fn projection_matches_camera_model() {
    for distortion in [Distortion::default(), STRONG] {
        let cam = camera_640(distortion);
        let d = distortion.to_array();
        for p in [DVec3::new(0.0, 0.0, 1.0), DVec3::new(0.45, -0.3, 1.0), DVec3::new(-0.55, 0.4, 1.2)] {
            let radius = 0.003;
            let text = format!(
                r#"
[camera]
width = 640
height = 480
fx = 500.0
fy = 500.0
cx = 319.5
cy = 239.5
distortion = [{}, {}, {}, {}, {}]
t_world_cam = {{ translation = [0.0, 0.0, 0.0] }}
[[materials]]
name = "glow"
type = "lambertian"
albedo = [0.0, 0.0, 0.0]
emission = [1.0, 1.0, 1.0]
[[shapes]]
type = "sphere"
center = [{}, {}, {}]
radius = {radius}
material = "glow"
"#,
                d[0], d[1], d[2], d[3], d[4], p.x, p.y, p.z
            );
            let dir = tempfile::tempdir().unwrap();
            let scene = common::scene(&text, dir.path()).unwrap();
            let uv = cam.project(p).unwrap();
            let (x0, y0) = (uv.x.round() as u32 - 8, uv.y.round() as u32 - 8);
            let mut s = common::settings(&scene, 4096, 1);
            s.crop = Some([x0, y0, x0 + 16, y0 + 16]);
            let film = render::render(&scene, &s);
            let silhouette = projected_silhouette(&cam, p, radius, 4096);
            let (mut sum, mut var, mut c) = (0.0, 0.0, DVec2::ZERO);
            let (mut esum, mut e) = (0.0, DVec2::ZERO);
            for j in 0..16 {
                for i in 0..16 {
                    let at = DVec2::new((x0 + i) as f64, (y0 + j) as f64);
                    let v = film.mean.pixel(i, j)[0] as f64;
                    sum += v;
                    var += film.variance.pixel(i, j)[0] as f64;
                    c += v * at;
                    let a = area_in_pixel(&silhouette, at.x, at.y);
                    esum += a;
                    e += a * at;
                }
            }
            assert!(sum > 3.0, "the sphere is not in the window around {uv}");
            let (c, e) = (c / sum, e / esum);
            let err = (c - e).length();
            eprintln!("projection of {p} (k1 = {}): centroid off by {err:.4} px", distortion.k1);
            assert!(err < 0.02, "centroid {c} vs projected {e}: {err} px (distortion {distortion:?})");
            // The render's total is the silhouette's area, within 5 standard errors.
            assert!(
                (sum - esum).abs() < 5.0 * var.sqrt(),
                "render sum {sum} ± {} vs silhouette area {esum}",
                var.sqrt()
            );
        }
    }
}

/// distort ∘ undistort = id to 1e-9 px over the whole image, and the converse.
#[test]
fn distortion_round_trip() {
    let strong = Distortion { k3: -0.02, ..STRONG };
    let cam = camera_640(strong);
    let mut worst = 0.0f64;
    for j in (0..=480).step_by(4) {
        for i in (0..=640).step_by(4) {
            let px = DVec2::new(i as f64 - 0.5, j as f64 - 0.5);
            let n = cam.undistort_pixel(px).unwrap_or_else(|| panic!("no undistortion at {px}"));
            let back = cam.normalized_to_pixel(cam.distortion.distort(n));
            worst = worst.max((back - px).length());
        }
    }
    assert!(worst < 1e-9, "distort(undistort(px)) is off by {worst} px");
    for j in -10..=10 {
        for i in -10..=10 {
            let n = DVec2::new(i as f64 * 0.06, j as f64 * 0.045);
            let back = strong.undistort(strong.distort(n)).unwrap();
            assert!((back - n).length() < 1e-12, "undistort(distort({n})) = {back}");
        }
    }
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

/// The eight-lane path loop (`render::lanes`) gives the one-path loop's image bit for bit,
/// with either sampler, with a pinhole or a thin lens, on every kind of scene it takes.
#[test]
fn eight_lanes_match_the_scalar_loop_bit_for_bit() {
    let root = common::root();
    let dir = tempfile::tempdir().unwrap();
    let mixed = common::scene(MIXED_LIGHTS, dir.path()).unwrap();
    let lens =
        MIXED_LIGHTS.replace("fov_deg = 50.0", "fov_deg = 50.0\naperture_radius = 0.1\nfocus_distance = 3.0");
    let lens = common::scene(&lens, dir.path()).unwrap();
    assert!(lens.lens.is_some());
    let cornell = render::load(&root.join("pipelines/scenes/cornell-box.toml")).unwrap();
    let board = render::load(&root.join("pipelines/scenes/calib-board.toml")).unwrap();
    let cases = [
        ("mixed lights", &mixed, render::sampler::SamplerKind::Independent, None),
        ("mixed lights, Sobol", &mixed, render::sampler::SamplerKind::Sobol, None),
        ("thin lens, Sobol", &lens, render::sampler::SamplerKind::Sobol, None),
        ("Cornell box", &cornell, render::sampler::SamplerKind::Independent, Some([100, 20, 140, 200])),
        ("Cornell box, Sobol", &cornell, render::sampler::SamplerKind::Sobol, Some([100, 20, 140, 200])),
        ("calibration board", &board, render::sampler::SamplerKind::Independent, Some([200, 150, 260, 190])),
    ];
    for (name, scene, sampler, crop) in cases {
        let mut s = common::settings(scene, 8, 8);
        s.sampler = sampler;
        s.crop = crop;
        assert!(
            render::lanes::supported(scene, &s) || !is_x86_feature_detected!("avx2"),
            "{name}: not taken"
        );
        let a = render::render(scene, &s);
        s.lanes = false;
        let b = render::render(scene, &s);
        let same = |x: &[f32], y: &[f32]| x.iter().zip(y).all(|(x, y)| x.to_bits() == y.to_bits());
        assert!(same(&a.mean.data, &b.mean.data), "{name}: means differ");
        assert!(same(&a.variance.data, &b.variance.data), "{name}: variances differ");
        assert!(a.mean.data.iter().any(|&v| v > 0.0), "{name}: black");
    }
}

/// A plane under a directional light: L = ρ/π · E · cosθ, the same in every pixel; and a
/// checkerboard albedo shows its two values in its two kinds of squares.
#[test]
fn directional_light_and_checker_texture() {
    let text = r#"
[camera]
width = 16
height = 16
fx = 20.0
fy = 20.0
cx = 7.5
cy = 7.5
look_at = { origin = [0.0, 0.0, 2.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }
[[materials]]
name = "board"
type = "lambertian"
albedo = { checker = { squares = [2, 2], even = [0.8, 0.8, 0.8], odd = [0.2, 0.2, 0.2] } }
[[shapes]]
type = "quad"
corner = [-2.0, -2.0, 0.0]
edge_u = [4.0, 0.0, 0.0]
edge_v = [0.0, 4.0, 0.0]
material = "board"
[[lights]]
type = "directional"
to_light = [0.0, 0.6, 0.8]
irradiance = [3.0, 3.0, 3.0]
"#;
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene(text, dir.path()).unwrap();
    let film = render::render(&scene, &common::settings(&scene, 4, 2));
    let e = 3.0 * 0.8 / std::f64::consts::PI;
    // Quadrants: u < 0.5 ⇔ x < 0 (image left), v < 0.5 ⇔ y < 0 (image bottom, as y is down).
    for (i, j, rho) in [(2, 13, 0.8), (13, 2, 0.8), (2, 2, 0.2), (13, 13, 0.2)] {
        let got = film.mean.pixel(i, j)[1] as f64;
        assert!((got - rho * e).abs() < 1e-5 * e, "pixel ({i}, {j}): {got} vs {}", rho * e);
    }
}

/// A spot light (Mitsuba's falloff: full intensity to the beam width, linear in angle to 0 at
/// the cutoff) 2 units over a Lambertian floor: L = ρ/π · I·falloff(θ)·cos θ / r² in pixels
/// inside the beam, in the transition and outside, each averaged over its footprint (16×16
/// sub-pixel rays); the render within 0.5 %. Its power, 2π ∫ falloff sin θ dθ, against
/// quadrature.
#[test]
fn spot_light_falloff_and_power() {
    let text = r#"
[camera]
width = 32
height = 32
fov_deg = 60.0
look_at = { origin = [0.0, 0.0, 2.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }
[render]
max_depth = 2
sampler = "sobol"
[[materials]]
name = "floor"
type = "lambertian"
albedo = [0.5, 0.5, 0.5]
[[shapes]]
type = "quad"
corner = [-3.0, -3.0, 0.0]
edge_u = [6.0, 0.0, 0.0]
edge_v = [0.0, 6.0, 0.0]
material = "floor"
[[lights]]
type = "spot"
position = [0.0, 0.0, 2.0]
target = [0.0, 0.0, 0.0]
intensity = [4.0, 4.0, 4.0]
cutoff_deg = 25.0
beam_width_deg = 15.0
"#;
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene(text, dir.path()).unwrap();
    let film = render::render(&scene, &common::settings(&scene, 64, 2));
    let origin = scene.t_world_cam.translation;
    let (cutoff, beam) = (25f64.to_radians(), 15f64.to_radians());
    let radiance = |px: f64, py: f64| -> f64 {
        let d = scene.t_world_cam.rotation * scene.camera.pixel_ray(DVec2::new(px, py)).unwrap();
        let p = origin + d * (-origin.z / d.z);
        let r2 = (origin - p).length_squared();
        let cos = 2.0 / r2.sqrt();
        let theta = cos.acos();
        let falloff = if theta >= cutoff {
            0.0
        } else if theta <= beam {
            1.0
        } else {
            (cutoff - theta) / (cutoff - beam)
        };
        0.5 / std::f64::consts::PI * 4.0 * falloff * cos / r2
    };
    let mut seen = [0; 3];
    for (i, j) in [(15, 16), (20, 12), (23, 16), (25, 20), (26, 16), (31, 31), (16, 27)] {
        let n = 16;
        let mut want = 0.0;
        for a in 0..n {
            for b in 0..n {
                want += radiance(
                    i as f64 - 0.5 + (a as f64 + 0.5) / n as f64,
                    j as f64 - 0.5 + (b as f64 + 0.5) / n as f64,
                ) / (n * n) as f64;
            }
        }
        let got = film.mean.pixel(i, j)[0] as f64;
        // Which part of the beam the pixel centre is in: full, transition, outside.
        let d = scene.t_world_cam.rotation * scene.camera.pixel_ray(DVec2::new(i as f64, j as f64)).unwrap();
        let theta = (-d.z).acos();
        seen[if theta <= beam {
            0
        } else if theta < cutoff {
            1
        } else {
            2
        }] += 1;
        assert!((got - want).abs() <= 5e-3 * want + 1e-7, "pixel ({i}, {j}): {got} vs {want}");
    }
    assert!(seen.iter().all(|&n| n > 0), "beam, transition, outside: {seen:?} pixels");
    let steps = 100_000;
    let mut power = 0.0;
    for k in 0..steps {
        let theta = (k as f64 + 0.5) / steps as f64 * cutoff;
        let f = if theta <= beam { 1.0 } else { (cutoff - theta) / (cutoff - beam) };
        power += 2.0 * std::f64::consts::PI * f * theta.sin() * cutoff / steps as f64;
    }
    let closed = render::scene::spot_power_per_intensity(cutoff as f32, beam as f32) as f64;
    assert!((closed / power - 1.0).abs() < 1e-5, "{closed} vs {power}");
}

/// A constant environment of radiance L: a Lambertian sphere shows ρ·L (it is convex: no
/// light comes back from itself), the background L, and a glossy sphere, seen head-on at its
/// centre, L·∫ f cos dω — Blinn-Phong, where light and BSDF samples of the environment are
/// combined by MIS, the integral by quadrature.
#[test]
fn constant_environment() {
    for (material, kd) in [
        ("type = \"lambertian\"\nalbedo = [0.6, 0.4, 0.2]", [0.6f32, 0.4, 0.2]),
        (
            "type = \"blinn-phong\"\nalbedo = [0.3, 0.3, 0.3]\nspecular = [0.5, 0.5, 0.5]\nexponent = 20.0",
            [0.3; 3],
        ),
    ] {
        let text = format!(
            "[camera]\nwidth = 3\nheight = 3\nfx = 2000.0\nfy = 2000.0\ncx = 1.0\ncy = 1.0\nlook_at = {{ origin = [0.0, 0.0, 3.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }}\n[render]\nmax_depth = 4\n[[materials]]\nname = \"m\"\n{material}\n[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\nmaterial = \"m\"\n[[lights]]\ntype = \"environment\"\nradiance = [2.0, 2.0, 2.0]\n"
        );
        let dir = tempfile::tempdir().unwrap();
        let scene = common::scene(&text, dir.path()).unwrap();
        let mut s = common::settings(&scene, 1 << 16, 4);
        s.crop = Some([1, 1, 2, 2]);
        let film = render::render(&scene, &s);
        let bsdf = scene.materials[0].bsdf;
        let kd = glam::Vec3A::from(kd);
        // ∫ f(n, wi) cos θi dωi over the hemisphere around n = +z, wo = n.
        let (nt, np) = (2000, 400);
        let mut albedo = [0.0f64; 3];
        for i in 0..nt {
            let ct = (i as f64 + 0.5) / nt as f64;
            let st = (1.0 - ct * ct).sqrt();
            for j in 0..np {
                let phi = 2.0 * std::f64::consts::PI * (j as f64 + 0.5) / np as f64;
                let wi = glam::Vec3A::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, ct as f32);
                let f = bsdf.eval(kd, glam::Vec3A::Z, glam::Vec3A::Z, wi);
                for c in 0..3 {
                    albedo[c] += f[c] as f64 * ct * 2.0 * std::f64::consts::PI / (nt * np) as f64;
                }
            }
        }
        for c in 0..3 {
            let want = 2.0 * albedo[c];
            let got = film.mean.data[c] as f64;
            let se = (film.variance.data[c] as f64).sqrt();
            eprintln!("{:?} channel {c}: {got:.5} vs {want:.5} (SE {se:.1e})", bsdf);
            assert!(
                ((got - want) / se).abs() < 4.0 && (got / want - 1.0).abs() < 0.01,
                "channel {c}: {got} vs {want}"
            );
        }
        // The background: the environment itself.
        let mut s = common::settings(&scene, 4, 4);
        s.crop = Some([0, 0, 1, 1]);
        let mut far = scene;
        far.camera.intrinsics.fx = 2.0;
        far.camera.intrinsics.fy = 2.0;
        let film = render::render(&far, &s);
        assert!((film.mean.data[0] - 2.0).abs() < 1e-6, "background {}", film.mean.data[0]);
    }
}

/// A sphere light facing a point: E = π·L·(R/d)², so a Lambertian floor shows
/// ρ·L·(R/d)² under it; the cone sampling of the sphere makes that exact to Monte Carlo noise.
#[test]
fn sphere_light_irradiance() {
    let (got, se) = floor_under_lamp("type = \"sphere\"\ncenter = [0.0, 0.0, 1.0]\nradius = 0.3", 1 << 14);
    let expected = 0.9 * 2.0 * 0.3f64.powi(2);
    eprintln!("sphere light: {got} vs {expected} (SE {se:.2e})");
    assert!(((got - expected) / se.max(1e-9)).abs() < 4.0 || (got / expected - 1.0).abs() < 1e-5);
    assert!((got / expected - 1.0).abs() < 1e-3, "got {got}, expected {expected}");
}

/// Pearson's χ² test of light sampling, as for the BSDFs: 10⁶ directions sampled from a point
/// towards a sphere light (cone sampling), a square light (area sampling) and an emissive
/// mesh (a triangle picked by power, then a uniform point on it), binned
/// on a 16 × 32 grid over (cos θ ∈ [0.5, 1], φ); expected counts from the solid-angle density
/// the integrator's MIS uses (`area_light_pdf`), integrated over each cell (64 × 64 rays).
#[test]
fn chi_square_light_sampling() {
    use lumen::math::stats::{chi2_test, sidak_alpha};
    use lumen::render::geometry::Ray;
    use lumen::render::sampler::{Sampler, SamplerKind};
    let lights = [
        "type = \"sphere\"\ncenter = [0.2, 0.1, 2.0]\nradius = 0.9",
        "type = \"quad\"\ncorner = [-1.0, -0.8, 1.5]\nedge_u = [0.0, 1.6, 0.0]\nedge_v = [1.7, 0.0, 0.0]",
        // An emissive mesh: the four sides of a pyramid pointing its apex at the point, every
        // face in view (one light per triangle, picked by power, i.e. by area).
        "type = \"mesh\"\nfile = \"pyramid.obj\"",
    ];
    let pyramid = "v 0.1 0.05 1.5\nv -0.9 -0.8 2.2\nv 1.0 -0.7 2.2\nv 0.8 0.9 2.2\nv -0.7 1.0 2.2\nf 1 3 2\nf 1 4 3\nf 1 5 4\nf 1 2 5\n";
    let alpha = sidak_alpha(0.01, lights.len());
    for (case, shape) in lights.iter().enumerate() {
        let text = format!(
            "[camera]\nwidth = 4\nheight = 4\nfov_deg = 40.0\nlook_at = {{ origin = [0.0, 0.0, -1.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }}\n[[materials]]\nname = \"lamp\"\ntype = \"lambertian\"\nalbedo = [0.0, 0.0, 0.0]\nemission = [1.0, 1.0, 1.0]\n[[shapes]]\n{shape}\nmaterial = \"lamp\"\n"
        );
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("pyramid.obj"), pyramid).unwrap();
        let scene = common::scene(&text, dir.path()).unwrap();
        let p = glam::Vec3A::ZERO;
        let (nt, np, c0) = (16usize, 32usize, 0.5f32);
        let cell = |w: glam::Vec3A| {
            let t = (((w.z - c0) / (1.0 - c0) * nt as f32) as usize).min(nt - 1);
            let phi = w.y.atan2(w.x).rem_euclid(2.0 * std::f32::consts::PI);
            t * np + ((phi / (2.0 * std::f32::consts::PI) * np as f32) as usize).min(np - 1)
        };
        let samples = 1_000_000u64;
        let mut observed = vec![0.0f64; nt * np];
        for k in 0..samples {
            let mut s = Sampler::with_kind(SamplerKind::Independent, 7 + case as u64, k, 0);
            let (_, wi, _, pdf) = scene.sample_light(s.next2(), p).expect("the light faces the point");
            assert!(pdf.is_some_and(|v| v > 0.0) && wi.z >= c0);
            observed[cell(wi)] += 1.0;
        }
        let density = |w: glam::Vec3A| -> f64 {
            let ray = Ray { origin: p, dir: w };
            match scene.bvh.intersect(&ray, 0.0, f32::INFINITY) {
                Some(hit) => {
                    let surf = scene.surface(&ray, &hit);
                    scene.area_light_pdf(hit.prim, p, surf.p, surf.n) as f64
                }
                None => 0.0,
            }
        };
        // Fine enough that cells the light's edge barely clips still get their sliver.
        let sub = 64;
        let mut expected = vec![0.0f64; nt * np];
        for t in 0..nt {
            for q in 0..np {
                let mut sum = 0.0;
                for a in 0..sub {
                    let ct = c0 as f64
                        + (1.0 - c0 as f64) * (t as f64 + (a as f64 + 0.5) / sub as f64) / nt as f64;
                    let st = (1.0 - ct * ct).sqrt();
                    for b in 0..sub {
                        let phi = 2.0 * std::f64::consts::PI * (q as f64 + (b as f64 + 0.5) / sub as f64)
                            / np as f64;
                        sum += density(glam::Vec3A::new(
                            (st * phi.cos()) as f32,
                            (st * phi.sin()) as f32,
                            ct as f32,
                        ));
                    }
                }
                let area = (1.0 - c0 as f64) / nt as f64 * 2.0 * std::f64::consts::PI / np as f64;
                expected[t * np + q] = samples as f64 * sum / (sub * sub) as f64 * area;
            }
        }
        let total: f64 = expected.iter().sum();
        assert!(
            (total / samples as f64 - 1.0).abs() < 0.01,
            "case {case}: density integrates to {}",
            total / samples as f64
        );
        let pv = chi2_test(&observed, &expected).expect("enough cells");
        assert!(pv >= alpha, "case {case}: χ² p-value {pv:.3e} below {alpha:.3e}");
    }
}

/// Glossy surfaces under a small area light, direct light only, where multiple importance
/// sampling combines light and BSDF samples: the centre pixel (a footprint of 0.0005 rad)
/// against ∫ f(wo, wi)·Lₑ·cos θi·cos θl / r² dA over the light by a 400×400 midpoint rule. The
/// light sits at the mirror direction, in the highlight. Cases: GGX and Beckmann gold, and
/// Blinn-Phong.
#[test]
fn glossy_plane_under_area_light_with_mis() {
    let materials = [
        ("type = \"conductor\"\ndistribution = \"ggx\"\nalpha = 0.2\nalbedo = [1.0, 1.0, 1.0]", "ggx"),
        (
            "type = \"conductor\"\ndistribution = \"beckmann\"\nalpha = 0.1\nalbedo = [1.0, 1.0, 1.0]",
            "beckmann",
        ),
        (
            "type = \"blinn-phong\"\nalbedo = [0.2, 0.2, 0.2]\nspecular = [0.6, 0.6, 0.6]\nexponent = 60.0",
            "blinn-phong",
        ),
    ];
    for (material, name) in materials {
        let text = format!(
            r#"
[camera]
width = 3
height = 3
fx = 2000.0
fy = 2000.0
cx = 1.0
cy = 1.0
look_at = {{ origin = [0.0, -1.0, 1.0], target = [0.0, 0.0, 0.0], up = [0.0, 0.0, 1.0] }}
[render]
max_depth = 2
[[materials]]
name = "lamp"
type = "lambertian"
albedo = [0.0, 0.0, 0.0]
emission = [5.0, 5.0, 5.0]
[[materials]]
name = "metal"
{material}
[[shapes]]
type = "quad"
corner = [-0.1, 0.929289, 1.070711]
edge_u = [0.0, 0.141421, -0.141421]
edge_v = [0.2, 0.0, 0.0]
material = "lamp"
[[shapes]]
type = "quad"
corner = [-2.0, -2.0, 0.0]
edge_u = [4.0, 0.0, 0.0]
edge_v = [0.0, 4.0, 0.0]
material = "metal"
"#
        );
        let dir = tempfile::tempdir().unwrap();
        let scene = common::scene(&text, dir.path()).unwrap();
        let mut s = common::settings(&scene, 1 << 16, 2);
        s.crop = Some([1, 1, 2, 2]);
        let film = render::render(&scene, &s);
        let bsdf = scene.materials[1].bsdf;
        let kd = match name {
            "blinn-phong" => glam::Vec3A::splat(0.2),
            _ => glam::Vec3A::ONE,
        };
        let wo = DVec3::new(0.0, -1.0, 1.0).normalize();
        let (corner, eu, ev) = (
            DVec3::new(-0.1, 0.929289, 1.070711),
            DVec3::new(0.0, 0.141421, -0.141421),
            DVec3::new(0.2, 0.0, 0.0),
        );
        let nl = eu.cross(ev).normalize();
        let n = 400;
        let da = eu.cross(ev).length() / (n * n) as f64;
        let mut want = [0.0f64; 3];
        for a in 0..n {
            for b in 0..n {
                let y = corner + eu * ((a as f64 + 0.5) / n as f64) + ev * ((b as f64 + 0.5) / n as f64);
                let r2 = y.length_squared();
                let wi = y / r2.sqrt();
                let (ci, cl) = (wi.z, -nl.dot(wi));
                if ci > 0.0 && cl > 0.0 {
                    let f = bsdf.eval(kd, glam::Vec3A::Z, wo.as_vec3().into(), wi.as_vec3().into());
                    for c in 0..3 {
                        want[c] += f[c] as f64 * 5.0 * ci * cl / r2 * da;
                    }
                }
            }
        }
        for c in 0..3 {
            let got = film.mean.data[c] as f64;
            let se = (film.variance.data[c] as f64).sqrt();
            eprintln!("{name} channel {c}: {got:.5} vs {:.5} (SE {se:.2e})", want[c]);
            assert!(((got - want[c]) / se).abs() < 4.0, "{name} channel {c}: {got} vs {} (SE {se})", want[c]);
            assert!((got / want[c] - 1.0).abs() < 0.01, "{name} channel {c}: {got} vs {}", want[c]);
        }
        assert_eq!(film.dropped_samples, 0);
    }
}

/// A Blinn-Phong plane under a directional light, direct light only: each pixel is the mean
/// over its footprint of f(wo, wi)·cos θi·E with f = kd/π + ks·(e + 8)/(8π)·cosᵉθh, computed
/// here on a 32×32 grid of sub-pixel rays; the render (256 Sobol spp) within 0.5 %.
#[test]
fn blinn_phong_plane_under_directional_light() {
    let text = r#"
[camera]
width = 16
height = 16
fx = 20.0
fy = 20.0
cx = 7.5
cy = 7.5
look_at = { origin = [0.0, 0.0, 2.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }
[render]
sampler = "sobol"
[[materials]]
name = "glossy"
type = "blinn-phong"
albedo = [0.3, 0.2, 0.1]
specular = [0.5, 0.5, 0.5]
exponent = 20.0
[[shapes]]
type = "quad"
corner = [-2.0, -2.0, 0.0]
edge_u = [4.0, 0.0, 0.0]
edge_v = [0.0, 4.0, 0.0]
material = "glossy"
[[lights]]
type = "directional"
to_light = [0.0, -0.6, 0.8]
irradiance = [3.0, 3.0, 3.0]
"#;
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene(text, dir.path()).unwrap();
    let film = render::render(&scene, &common::settings(&scene, 256, 2));
    let wi = DVec3::new(0.0, -0.6, 0.8);
    let origin = scene.t_world_cam.translation;
    let radiance = |px: f64, py: f64| -> [f64; 3] {
        let d = scene.t_world_cam.rotation * scene.camera.pixel_ray(DVec2::new(px, py)).unwrap();
        let p = origin + d * (-origin.z / d.z);
        let wo = (origin - p).normalize();
        let h = (wo + wi).normalize();
        let spec = 0.5 * 28.0 / (8.0 * std::f64::consts::PI) * h.z.powf(20.0);
        [0.3, 0.2, 0.1].map(|kd| (kd / std::f64::consts::PI + spec) * wi.z * 3.0)
    };
    let mut worst = 0.0f64;
    for (i, j) in [(7, 7), (8, 3), (7, 12), (2, 2), (14, 9)] {
        let n = 32;
        let mut want = [0.0; 3];
        for a in 0..n {
            for b in 0..n {
                let l = radiance(
                    i as f64 - 0.5 + (a as f64 + 0.5) / n as f64,
                    j as f64 - 0.5 + (b as f64 + 0.5) / n as f64,
                );
                for c in 0..3 {
                    want[c] += l[c] / (n * n) as f64;
                }
            }
        }
        for c in 0..3 {
            let got = film.mean.pixel(i, j)[c] as f64;
            worst = worst.max((got - want[c]).abs() / want[c]);
            assert!(
                (got - want[c]).abs() < 5e-3 * want[c],
                "pixel ({i}, {j}) channel {c}: {got} vs {}",
                want[c]
            );
        }
    }
    eprintln!("Blinn-Phong plane: worst relative error {worst:.2e}");
}

/// An image texture: an 8-bit PNG is sRGB-decoded, and texture coordinate v = 0 is the image's
/// bottom row, as in OBJ.
#[test]
fn image_texture_is_decoded_and_oriented() {
    let dir = tempfile::tempdir().unwrap();
    // 2×2 texture: top row red (255, 0, 0) and grey 128; bottom row black and white.
    let px: Vec<u8> = vec![255, 0, 0, 128, 128, 128, 0, 0, 0, 255, 255, 255];
    image::save_buffer(dir.path().join("t.png"), &px, 2, 2, image::ExtendedColorType::Rgb8).unwrap();
    let text = r#"
[camera]
width = 2
height = 2
fx = 2.0
fy = 2.0
cx = 0.5
cy = 0.5
look_at = { origin = [0.5, 0.5, 1.0], target = [0.5, 0.5, 0.0], up = [0.0, 1.0, 0.0] }
[[materials]]
name = "tex"
type = "lambertian"
albedo = { texture = "t.png" }
[[shapes]]
type = "quad"
corner = [0.0, 0.0, 0.0]
edge_u = [1.0, 0.0, 0.0]
edge_v = [0.0, 1.0, 0.0]
material = "tex"
"#;
    let scene = common::scene(text, dir.path()).unwrap();
    let t = render::truth(&scene, None);
    // Pixel centres land on texel centres: (0, 0) top-left is red, (1, 1) bottom-right white.
    let grey = lumen::image::srgb_decode(128.0 / 255.0);
    for (i, j, want) in [(0, 0, [1.0, 0.0, 0.0]), (1, 0, [grey; 3]), (0, 1, [0.0; 3]), (1, 1, [1.0; 3])] {
        let got = t.albedo.pixel(i, j);
        assert!(
            got.iter().zip(want).all(|(g, w)| (g - w).abs() < 1e-6),
            "pixel ({i}, {j}): {got:?} vs {want:?}"
        );
    }
}

/// The white furnace per BSDF: a sphere of each material inside a constant environment of
/// radiance L, the whole 8 × 8 image (sphere and background). Whatever a lossless material
/// does with the light, every path ends in the environment with weight 1, so the image is L
/// (Lambertian of albedo 1, perfect mirror, clear glass — the glass also checks that refracted
/// rays leave from the right side and that the η² factors of entering and leaving cancel);
/// a lossy one (rough conductors, Blinn-Phong within its energy bound, a gold mirror) never
/// shows more than L. No sample may be NaN or infinite.
#[test]
fn white_furnace_per_bsdf() {
    let lossless = [
        "type = \"lambertian\"\nalbedo = [1.0, 1.0, 1.0]",
        "type = \"mirror\"\nalbedo = [1.0, 1.0, 1.0]",
        "type = \"dielectric\"\nalbedo = [1.0, 1.0, 1.0]\nior = 1.5",
        "type = \"dielectric\"\nalbedo = [1.0, 1.0, 1.0]\nior = 0.7",
    ];
    let lossy = [
        "type = \"conductor\"\nalbedo = [1.0, 1.0, 1.0]\nalpha = 0.5\neta = [0.2, 0.2, 0.2]\nk = [5.0, 5.0, 5.0]",
        "type = \"conductor\"\nalbedo = [1.0, 1.0, 1.0]\ndistribution = \"beckmann\"\nalpha = 1.0\neta = [0.2, 0.2, 0.2]\nk = [5.0, 5.0, 5.0]",
        "type = \"blinn-phong\"\nalbedo = [0.4, 0.4, 0.4]\nspecular = [0.55, 0.55, 0.55]\nexponent = 10.0",
        "type = \"mirror\"\nalbedo = [1.0, 1.0, 1.0]\neta = [0.143, 0.374, 1.442]\nk = [3.983, 2.385, 1.603]",
    ];
    let l = 2.0;
    for (material, is_lossless) in lossless.iter().map(|m| (m, true)).chain(lossy.iter().map(|m| (m, false)))
    {
        let text = format!(
            "[camera]\nwidth = 8\nheight = 8\nfx = 12.0\nfy = 12.0\ncx = 3.5\ncy = 3.5\nlook_at = {{ origin = [0.0, 0.0, 3.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }}\n[[materials]]\nname = \"m\"\n{material}\n[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\nmaterial = \"m\"\n[[lights]]\ntype = \"environment\"\nradiance = [{l}, {l}, {l}]\n"
        );
        let dir = tempfile::tempdir().unwrap();
        let scene = common::scene(&text, dir.path()).unwrap();
        let film = render::render(&scene, &common::settings(&scene, 1024, 64));
        assert_eq!(film.dropped_samples, 0, "{material}: non-finite samples");
        let n = (film.mean.data.len() / 3) as f64;
        for c in 0..3 {
            let (mut sum, mut var, mut worst) = (0.0f64, 0.0f64, 0.0f64);
            for (m, v) in film.mean.data.iter().zip(&film.variance.data).skip(c).step_by(3) {
                sum += *m as f64;
                var += *v as f64;
                let z = (*m as f64 - l) / (*v as f64).sqrt().max(1e-6 * l);
                worst = worst.max(if is_lossless { z.abs() } else { z });
            }
            let (mean, se) = (sum / n, var.sqrt() / n);
            eprintln!("{material:?} channel {c}: {mean:.5} (SE {se:.1e}, worst pixel z {worst:.2})");
            if is_lossless {
                assert!((mean - l).abs() < 4.0 * se + 1e-5 * l, "{material}: {mean} vs {l}");
                assert!(worst < 5.0, "{material}: a pixel is {worst} standard errors from L");
            } else {
                assert!(mean < l + 4.0 * se && worst < 5.0, "{material}: reflects more than it receives");
                assert!(mean > 0.25 * l, "{material}: {mean} — the sphere renders nearly black");
            }
        }
    }
}

/// A 32 × 17 sky for the image-environment tests: a bluish gradient, a small bright sun
/// (about 2·10⁴ times the sky) and a dark ground, written as EXR into `dir`.
fn sky_map(dir: &std::path::Path) -> std::path::PathBuf {
    let (w, h) = (32u32, 17u32);
    let mut img = lumen::image::Image::new(w, h, 3);
    for y in 0..h {
        for x in 0..w {
            let c = if (x, y) == (9, 4) || (x, y) == (10, 4) {
                [4000.0, 3500.0, 3000.0]
            } else if y > 8 {
                [0.05, 0.04, 0.03]
            } else {
                [0.3 + 0.05 * y as f32, 0.4 + 0.02 * x as f32 / w as f32, 0.8]
            };
            img.pixel_mut(x, y).copy_from_slice(&c);
        }
    }
    let file = dir.join("sky.exr");
    lumen::image::io::write_exr(&file, &img).unwrap();
    file
}

/// Pearson's χ² test of image-environment sampling: 10⁶ directions drawn by the scene's light
/// sampling, binned on a 32 × 64 grid in the map's own (v, u) = (θ/π, φ/2π), each bin a
/// quarter of a map cell, so the density the integrator's MIS uses (`Scene::environment`) is
/// constant over it and the expected count is that density × the bin's solid angle. Each
/// sample's weight must be radiance / density.
#[test]
fn chi_square_environment_map_sampling() {
    use lumen::math::stats::chi2_test;
    use lumen::render::envmap::direction_to_uv;
    use lumen::render::sampler::{Sampler, SamplerKind};
    use std::f64::consts::PI;
    let dir = tempfile::tempdir().unwrap();
    sky_map(dir.path());
    let text = "[camera]\nwidth = 4\nheight = 4\nfov_deg = 40.0\nlook_at = { origin = [0.0, 0.0, -1.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }\n[[lights]]\ntype = \"environment\"\nmap = \"sky.exr\"\nscale = 0.5\n";
    let scene = common::scene(text, dir.path()).unwrap();
    let (nt, np) = (32usize, 64usize);
    let bin = |w: glam::Vec3A| {
        let (u, v) = direction_to_uv(w);
        ((v * nt as f32) as usize).min(nt - 1) * np + ((u * np as f32) as usize).min(np - 1)
    };
    let samples = 1_000_000u64;
    let mut observed = vec![0.0f64; nt * np];
    for k in 0..samples {
        let mut s = Sampler::with_kind(SamplerKind::Independent, 11, k, 0);
        let (li, wi, dist, pdf) =
            scene.sample_light(s.next2(), glam::Vec3A::ZERO).expect("the sky has light");
        let (le, p) = scene.environment(wi).unwrap();
        assert!(dist.is_infinite() && pdf == Some(p), "{pdf:?} vs {p}");
        assert!((li * p - le).abs().max_element() <= 1e-4 * le.max_element(), "{li} · {p} vs {le}");
        observed[bin(wi)] += 1.0;
    }
    let mut expected = vec![0.0f64; nt * np];
    for t in 0..nt {
        let (ta, tb) = (PI * t as f64 / nt as f64, PI * (t + 1) as f64 / nt as f64);
        let tm = 0.5 * (ta + tb);
        for q in 0..np {
            // The bin's centre direction, in the map's convention d = (sin θ sin φ, cos θ, −sin θ cos φ).
            let phi = 2.0 * PI * (q as f64 + 0.5) / np as f64;
            let d = glam::Vec3A::new(
                (tm.sin() * phi.sin()) as f32,
                tm.cos() as f32,
                (-tm.sin() * phi.cos()) as f32,
            );
            let omega = 2.0 * PI / np as f64 * (ta.cos() - tb.cos());
            expected[t * np + q] = samples as f64 * scene.environment(d).unwrap().1 as f64 * omega;
        }
    }
    let total: f64 = expected.iter().sum();
    assert!((total / samples as f64 - 1.0).abs() < 1e-3, "density integrates to {}", total / samples as f64);
    let pv = chi2_test(&observed, &expected).expect("enough cells");
    eprintln!("environment map χ² p-value {pv:.3}");
    assert!(pv >= 0.01, "χ² p-value {pv:.3e} below 0.01");
}

/// An image environment over a Lambertian plane facing up: every point of the plane sees the
/// upper hemisphere unoccluded, so it shows ρ/π·∫ L(ω) cos θ dω, the integral by quadrature of
/// the map's own (bilinear) radiance; a pixel looking at the sky shows the map there exactly.
#[test]
fn environment_map_lights_a_plane() {
    use std::f64::consts::PI;
    let dir = tempfile::tempdir().unwrap();
    sky_map(dir.path());
    let text = "[camera]\nwidth = 3\nheight = 3\nfx = 2000.0\nfy = 2000.0\ncx = 1.0\ncy = 1.0\nlook_at = { origin = [0.0, 1.0, 0.0], target = [0.0, 0.0, 0.0], up = [0.0, 0.0, -1.0] }\n[render]\nmax_depth = 2\n[[materials]]\nname = \"m\"\ntype = \"lambertian\"\nalbedo = [0.5, 0.6, 0.7]\n[[shapes]]\ntype = \"quad\"\ncorner = [-50.0, 0.0, -50.0]\nedge_u = [0.0, 0.0, 100.0]\nedge_v = [100.0, 0.0, 0.0]\nmaterial = \"m\"\n[[lights]]\ntype = \"environment\"\nmap = \"sky.exr\"\nscale = 0.5\n";
    let scene = common::scene(text, dir.path()).unwrap();
    let mut s = common::settings(&scene, 1 << 16, 2);
    s.crop = Some([1, 1, 2, 2]);
    let film = render::render(&scene, &s);
    // E = ∫ L cos θ dω over the upper hemisphere (about +y), midpoint rule in (cos θ, φ).
    let (nt, np) = (1000, 2000);
    let mut e = [0.0f64; 3];
    for a in 0..nt {
        let ct = (a as f64 + 0.5) / nt as f64;
        let st = (1.0 - ct * ct).sqrt();
        for b in 0..np {
            let phi = 2.0 * PI * (b as f64 + 0.5) / np as f64;
            let w = glam::Vec3A::new((st * phi.cos()) as f32, ct as f32, (st * phi.sin()) as f32);
            let l = scene.environment(w).unwrap().0;
            for c in 0..3 {
                e[c] += l[c] as f64 * ct * 2.0 * PI / (nt * np) as f64;
            }
        }
    }
    for (c, rho) in [0.5, 0.6, 0.7].into_iter().enumerate() {
        let want = rho / PI * e[c];
        let (got, se) = (film.mean.data[c] as f64, (film.variance.data[c] as f64).sqrt());
        eprintln!("environment map, channel {c}: {got:.5} vs {want:.5} (SE {se:.1e})");
        assert!(
            ((got - want) / se).abs() < 4.0 && (got / want - 1.0).abs() < 0.005,
            "channel {c}: {got} vs {want}"
        );
    }
    // Looking up from under the plane's edge: the sky itself, the pixel's box filter aside
    // (a narrow field of view, so the footprint is tiny).
    let text = text.replace(
        "origin = [0.0, 1.0, 0.0], target = [0.0, 0.0, 0.0], up = [0.0, 0.0, -1.0]",
        "origin = [0.0, 1.0, 0.0], target = [0.3, 1.5, -1.0], up = [0.0, 1.0, 0.0]",
    );
    let scene = common::scene(&text, dir.path()).unwrap();
    let mut s = common::settings(&scene, 16, 2);
    s.crop = Some([1, 1, 2, 2]);
    let film = render::render(&scene, &s);
    let want = scene.environment(glam::Vec3A::new(0.3, 0.5, -1.0).normalize()).unwrap().0;
    for c in 0..3 {
        assert!(
            (film.mean.data[c] - want[c]).abs() < 1e-3 * want[c],
            "sky {c}: {} vs {}",
            film.mean.data[c],
            want[c]
        );
    }
}

/// The thin lens: a small emitting sphere on the axis at depth D (a uniform disk of radius
/// s = fx·R/√(D² − R²) pixels in a pinhole image), seen through an aperture of radius r focused at F, spreads
/// over the disk of radius ρ = fx·r·|1/F − 1/D| pixels around its pinhole projection (every
/// lens point shifts the image by fx·a·(1/F − 1/D) for its offset a). The rendered spot's
/// centroid, flux and second moments (over pixel centres: each pixel integrates its box)
/// must match those of that disk-of-disks binned into pixels, by quadrature.
#[test]
fn thin_lens_defocus_blur() {
    let (fx, r, depth, radius) = (200.0f64, 0.05f64, 4.0f64, 0.06f64);
    let (x, y) = (0.0, 0.0);
    let (px, py) = (31.5, 31.5);
    let window = [20u32, 20, 44, 44];
    // (flux, centroid x, y, variance x, y) of an image window.
    let moments = |img: &dyn Fn(u32, u32) -> f64| {
        let (mut s0, mut sx, mut sy, mut sxx, mut syy) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
        for j in window[1]..window[3] {
            for i in window[0]..window[2] {
                let v = img(i, j);
                let (a, b) = (i as f64, j as f64);
                s0 += v;
                sx += v * a;
                sy += v * b;
                sxx += v * a * a;
                syy += v * b * b;
            }
        }
        let (mx, my) = (sx / s0, sy / s0);
        [s0, mx, my, sxx / s0 - mx * mx, syy / s0 - my * my]
    };
    let render_spot = |lens: &str| {
        let text = format!(
            "[camera]\nwidth = 64\nheight = 64\nfx = {fx}\nfy = {fx}\ncx = 31.5\ncy = 31.5\nt_world_cam = {{ translation = [0.0, 0.0, 0.0] }}\n{lens}\n[render]\nsampler = \"sobol\"\n[[materials]]\nname = \"lamp\"\ntype = \"lambertian\"\nalbedo = [0.0, 0.0, 0.0]\nemission = [1.0, 1.0, 1.0]\n[[shapes]]\ntype = \"sphere\"\ncenter = [{x}, {y}, {depth}]\nradius = {radius}\nmaterial = \"lamp\"\n"
        );
        let dir = tempfile::tempdir().unwrap();
        let scene = common::scene(&text, dir.path()).unwrap();
        let mut settings = common::settings(&scene, 4096, 1);
        settings.crop = Some(window);
        let film = render::render(&scene, &settings);
        assert_eq!(film.dropped_samples, 0);
        moments(&|i, j| film.mean.pixel(i - window[0], j - window[1])[0] as f64)
    };
    // The expected binned spot, per axis: the offset is the sum of independent offsets from
    // the lens disk (radius ρ) and the sphere's disk (radius s), each with the disk's
    // marginal density ∝ √(rad² − t²); binned into the pixel boxes [i − ½, i + ½) by a fine
    // 1D quadrature. Returns (centroid, variance) for a spot centred at c.
    let s = fx * radius / (depth * depth - radius * radius).sqrt();
    let marginal = |rad: f64| -> Vec<(f64, f64)> {
        if rad == 0.0 {
            return vec![(0.0, 1.0)];
        }
        let n = (rad / 0.002) as usize;
        (0..n)
            .map(|k| {
                let t = rad * (2.0 * (k as f64 + 0.5) / n as f64 - 1.0);
                (t, (rad * rad - t * t).sqrt())
            })
            .collect()
    };
    let expected = |rho: f64, c: f64| {
        let (lens, sphere) = (marginal(rho), marginal(s));
        let mut bins = vec![0.0f64; 64];
        for &(a, wa) in &lens {
            for &(b, wb) in &sphere {
                bins[(c + a + b).round() as usize] += wa * wb;
            }
        }
        let total: f64 = bins.iter().sum();
        let mean = bins.iter().enumerate().map(|(i, w)| i as f64 * w).sum::<f64>() / total;
        let var = bins.iter().enumerate().map(|(i, w)| (i as f64 - mean).powi(2) * w).sum::<f64>() / total;
        (mean, var)
    };
    let expected = |rho: f64| {
        let ((mx, vx), (my, vy)) = (expected(rho, px), expected(rho, py));
        [f64::NAN, mx, my, vx, vy]
    };
    let pinhole = render_spot("");
    let want = expected(0.0);
    eprintln!("pinhole: {pinhole:?}, expected {want:?}");
    for k in 1..5 {
        assert!((pinhole[k] - want[k]).abs() < 0.01, "pinhole moment {k}: {} vs {}", pinhole[k], want[k]);
    }
    for focus in [depth, 2.0, 1.2, 9.0] {
        let lens = render_spot(&format!("aperture_radius = {r}\nfocus_distance = {focus}"));
        let rho = fx * r * (1.0 / focus - 1.0 / depth).abs();
        let want = expected(rho);
        eprintln!("focus {focus} (ρ = {rho:.3} px): {lens:?}, expected {want:?}");
        assert!((lens[0] / pinhole[0] - 1.0).abs() < 0.005, "flux {} vs {}", lens[0], pinhole[0]);
        for k in 1..3 {
            assert!(
                (lens[k] - want[k]).abs() < 0.01,
                "focus {focus}: centroid {k}: {} vs {}",
                lens[k],
                want[k]
            );
        }
        for k in 3..5 {
            assert!(
                (lens[k] - want[k]).abs() < 0.01 * want[k].max(1.0),
                "focus {focus}: variance {k}: {} vs {}",
                lens[k],
                want[k]
            );
        }
    }
}

/// A conductor floor whose roughness is a checkerboard (α = 0.05 and 0.5) under an area light,
/// direct light only: every pixel whose footprint lies inside one square is bit for bit the
/// pixel of the same floor with that α as a constant (same random streams, same path), and the
/// two constants render differently.
#[test]
fn textured_roughness_is_looked_up_per_hit() {
    let scene_with = |alpha: &str| {
        let text = format!(
            "[camera]\nwidth = 16\nheight = 16\nfx = 20.0\nfy = 20.0\ncx = 7.5\ncy = 7.5\nlook_at = {{ origin = [0.0, -1.0, 2.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }}\n[[materials]]\nname = \"metal\"\ntype = \"conductor\"\nalbedo = [1.0, 1.0, 1.0]\nalpha = {alpha}\n[[materials]]\nname = \"lamp\"\ntype = \"lambertian\"\nalbedo = [0.0, 0.0, 0.0]\nemission = [5.0, 5.0, 5.0]\n[[shapes]]\ntype = \"quad\"\ncorner = [-2.0, -2.0, 0.0]\nedge_u = [4.0, 0.0, 0.0]\nedge_v = [0.0, 4.0, 0.0]\nmaterial = \"metal\"\n[[shapes]]\ntype = \"quad\"\ncorner = [-0.5, 0.5, 2.0]\nedge_u = [0.0, 1.0, 0.0]\nedge_v = [1.0, 0.0, 0.0]\nmaterial = \"lamp\"\n"
        );
        let dir = tempfile::tempdir().unwrap();
        let scene = common::scene(&text, dir.path()).unwrap();
        render::render(&scene, &common::settings(&scene, 16, 2)).mean
    };
    let checker = scene_with("{ checker = { squares = [2, 2], even = 0.05, odd = 0.5 } }");
    let smooth = scene_with("0.05");
    let rough = scene_with("0.5");
    let (mut compared, mut differ) = (0, 0);
    // Square boundaries fall between pixels 7 and 8 only near the image centre; keep away
    // from them (the floor is tilted, so stay two pixels clear).
    for j in (0..16u32).filter(|j| !(5..=10).contains(j)) {
        for i in (0..16u32).filter(|i| !(6..=9).contains(i)) {
            let (left, top) = (i < 8, j < 8);
            // Even squares (u < ½, v < ½ and u ≥ ½, v ≥ ½) have α = 0.05; image up is +v.
            let even = left != top;
            let want = if even { smooth.pixel(i, j) } else { rough.pixel(i, j) };
            assert_eq!(checker.pixel(i, j), want, "pixel ({i}, {j}), even = {even}");
            compared += 1;
            differ += (smooth.pixel(i, j) != rough.pixel(i, j)) as u32;
        }
    }
    assert!(compared > 50 && differ > compared / 2, "{compared} pixels compared, {differ} differ");
}

/// No NaN or infinity from degenerate geometry and extreme materials: a zero-area triangle,
/// a 10⁻⁷-sized one and one seen edge-on, spheres of radius 10⁻⁵, a floor seen at 89.9° from
/// its normal, an area light in the floor's plane, a point light on the floor and a spot on
/// it, under each material at its extremes (Blinn-Phong e = 10⁵, GGX and Beckmann α = 0.001,
/// mirror, glass of index 4 and 1/4). Every sample must be finite (none dropped) and so every
/// pixel.
#[test]
fn no_nan_from_degenerate_geometry() {
    let materials = [
        "type = \"lambertian\"\nalbedo = [0.5, 0.5, 0.5]",
        "type = \"blinn-phong\"\nalbedo = [0.2, 0.2, 0.2]\nspecular = [0.7, 0.7, 0.7]\nexponent = 100000.0",
        "type = \"conductor\"\nalbedo = [1.0, 1.0, 1.0]\nalpha = 0.001",
        "type = \"conductor\"\nalbedo = [1.0, 1.0, 1.0]\ndistribution = \"beckmann\"\nalpha = 0.001",
        "type = \"mirror\"\nalbedo = [1.0, 1.0, 1.0]",
        "type = \"dielectric\"\nalbedo = [1.0, 1.0, 1.0]\nior = 4.0",
        "type = \"dielectric\"\nalbedo = [1.0, 1.0, 1.0]\nior = 0.25",
    ];
    let obj = "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 0.5 0\nv 1e-7 0.5 0\nv 0 0.5000001 0\nv -1 0 -1\nv -1 1 -1\nv -1 0 1\nf 1 2 3\nf 4 5 6\nf 7 8 9\n";
    for material in materials {
        let text = format!(
            "[camera]\nwidth = 32\nheight = 32\nfov_deg = 60.0\nlook_at = {{ origin = [-1.0, 0.002, 0.0], target = [3.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }}\n[[materials]]\nname = \"m\"\n{material}\n[[materials]]\nname = \"lamp\"\ntype = \"lambertian\"\nalbedo = [0.0, 0.0, 0.0]\nemission = [4.0, 4.0, 4.0]\n[[shapes]]\ntype = \"quad\"\ncorner = [-5.0, 0.0, -5.0]\nedge_u = [0.0, 0.0, 10.0]\nedge_v = [10.0, 0.0, 0.0]\nmaterial = \"m\"\n[[shapes]]\ntype = \"mesh\"\nfile = \"degenerate.obj\"\nmaterial = \"m\"\n[[shapes]]\ntype = \"sphere\"\ncenter = [1.0, 0.00001, 0.0]\nradius = 0.00001\nmaterial = \"m\"\n[[shapes]]\ntype = \"sphere\"\ncenter = [2.0, 0.3, 0.1]\nradius = 0.3\nmaterial = \"m\"\n[[shapes]]\ntype = \"quad\"\ncorner = [3.0, 0.0, -1.0]\nedge_u = [0.0, 0.0, 2.0]\nedge_v = [1.0, 0.0, 0.0]\nmaterial = \"lamp\"\n[[lights]]\ntype = \"point\"\nposition = [1.5, 0.0, 0.5]\nintensity = [1.0, 1.0, 1.0]\n[[lights]]\ntype = \"spot\"\nposition = [0.5, 2.0, 0.0]\ntarget = [0.5, 0.0, 0.0]\nintensity = [3.0, 3.0, 3.0]\n[[lights]]\ntype = \"environment\"\nradiance = [0.2, 0.2, 0.2]\n"
        );
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("degenerate.obj"), obj).unwrap();
        let scene = common::scene(&text, dir.path()).unwrap();
        let film = render::render(&scene, &common::settings(&scene, 64, 12));
        assert_eq!(film.dropped_samples, 0, "{material}: non-finite samples");
        assert!(!film.mean.has_non_finite() && !film.variance.has_non_finite(), "{material}");
    }
}
