//! Materials: glossy MIS against quadrature, Blinn-Phong, textures, white furnaces,
//! degenerate geometry.

use super::*;
use glam::{DVec2, DVec3};
use lumen::render;

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
/// rays leave from the right side and that the η² factors of entering and leaving cancel —, a
/// thin pane, white plastic, whose coat and base together lose nothing);
/// a lossy one (rough conductors, Blinn-Phong within its energy bound, a gold mirror, rough
/// glass and rough plastic, whose microfacets lose what they send to the wrong side) never
/// shows more than L. No sample may be NaN or infinite.
#[test]
fn white_furnace_per_bsdf() {
    let lossless = [
        "type = \"lambertian\"\nalbedo = [1.0, 1.0, 1.0]",
        "type = \"mirror\"\nalbedo = [1.0, 1.0, 1.0]",
        "type = \"dielectric\"\nalbedo = [1.0, 1.0, 1.0]\nior = 1.5",
        "type = \"dielectric\"\nalbedo = [1.0, 1.0, 1.0]\nior = 0.7",
        "type = \"thin-dielectric\"\nalbedo = [1.0, 1.0, 1.0]\nior = 1.5",
        "type = \"plastic\"\nalbedo = [1.0, 1.0, 1.0]\nior = 1.5",
        "type = \"plastic\"\nalbedo = [1.0, 1.0, 1.0]\nior = 1.33\nnonlinear = true",
    ];
    let lossy = [
        "type = \"conductor\"\nalbedo = [1.0, 1.0, 1.0]\nalpha = 0.5\neta = [0.2, 0.2, 0.2]\nk = [5.0, 5.0, 5.0]",
        "type = \"conductor\"\nalbedo = [1.0, 1.0, 1.0]\ndistribution = \"beckmann\"\nalpha = 1.0\neta = [0.2, 0.2, 0.2]\nk = [5.0, 5.0, 5.0]",
        "type = \"blinn-phong\"\nalbedo = [0.4, 0.4, 0.4]\nspecular = [0.55, 0.55, 0.55]\nexponent = 10.0",
        "type = \"mirror\"\nalbedo = [1.0, 1.0, 1.0]\neta = [0.143, 0.374, 1.442]\nk = [3.983, 2.385, 1.603]",
        "type = \"plastic\"\nalbedo = [0.5, 0.5, 0.5]\nnonlinear = true",
        "type = \"rough-dielectric\"\nalbedo = [1.0, 1.0, 1.0]\nalpha = 0.3\nior = 1.5",
        "type = \"rough-dielectric\"\nalbedo = [1.0, 1.0, 1.0]\ndistribution = \"beckmann\"\nalpha = 0.8\nior = 1.33",
        "type = \"rough-plastic\"\nalbedo = [1.0, 1.0, 1.0]\nalpha = 0.3",
        "type = \"rough-plastic\"\nalbedo = [1.0, 1.0, 1.0]\ndistribution = \"beckmann\"\nalpha = 0.05\nnonlinear = true",
    ];
    let l = 2.0;
    for (material, is_lossless) in lossless.iter().map(|m| (m, true)).chain(lossy.iter().map(|m| (m, false)))
    {
        let text = format!(
            "[camera]\nwidth = 8\nheight = 8\nfx = 12.0\nfy = 12.0\ncx = 3.5\ncy = 3.5\nlook_at = {{ origin = [0.0, 0.0, 3.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }}\n[[materials]]\nname = \"m\"\n{material}\n[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\nmaterial = \"m\"\n[[lights]]\ntype = \"environment\"\nradiance = [{l}, {l}, {l}]\n"
        );
        let dir = tempfile::tempdir().unwrap();
        let scene = common::scene(&text, dir.path()).unwrap();
        let film = render::render(&scene, &common::settings(&scene, 8192, 64));
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
