//! Photometric stereo: the DiLiGenT "ball" photographs, closed-form hard cases, bad input.

mod common;

use common::lumen;

use glam::DVec3;
use lumen::photometric::{self, dataset::Dataset, Input, Model, Observations};

/// DiLiGenT's ball: least squares within 0.1° of the plain recipe's 4.29° (the folder's
/// README), the robust model and the Blinn-Phong fit ≤ 2.0° (the best non-learning methods
/// report about 1.7°), every masked pixel solved, every output written.
#[test]
fn diligent_ball() {
    let Some(data) = common::shared_data() else { return };
    let ds = photometric::dataset::read(&data.join("photometric/diligent-ball")).unwrap();
    assert_eq!(ds.input.lights.len(), 96);
    assert!(ds.truth.is_some());
    let plain = solve(&ds, Model::Lambertian);
    let robust = solve(&ds, Model::Robust);
    let (p, r) =
        (accuracy(&ds, &plain).mean_angular_error_deg, accuracy(&ds, &robust).mean_angular_error_deg);
    eprintln!(
        "ball: least squares {p:.3}°, robust {r:.3}° (median {:.3}°)",
        accuracy(&ds, &robust).median_angular_error_deg
    );
    assert!((p - 4.29).abs() <= 0.1, "least squares {p}°");
    assert!(r <= 2.0, "robust {r}°");
    assert_eq!(robust.summary.masked_pixels, 0);
    let glossy = solve(&ds, Model::BlinnPhong);
    let b = accuracy(&ds, &glossy).mean_angular_error_deg;
    eprintln!("ball: Blinn-Phong {b:.3}° (median {:.3}°)", accuracy(&ds, &glossy).median_angular_error_deg);
    assert!(b <= 2.0 && b < r, "Blinn-Phong {b}°, robust {r}°");
    assert_eq!(glossy.summary.masked_pixels, 0);
    let curve = accuracy(&ds, &glossy).mean_angular_error_by_iteration_deg.unwrap();
    assert_eq!(curve[0], r, "the curve starts from the robust Lambertian solution");
    assert!((curve[curve.len() - 1] - b).abs() < 1e-9, "and ends at the final error");
    let dir = tempfile::tempdir().unwrap();
    photometric::write(dir.path(), &ds.input, &glossy, ds.truth.as_deref()).unwrap();
    for f in ["specular.exr", "shininess.exr"] {
        assert!(dir.path().join(f).is_file(), "{f} missing");
    }
    assert!(!robust.summary.lights_nearly_coplanar);
    let dir = tempfile::tempdir().unwrap();
    photometric::write(dir.path(), &ds.input, &robust, ds.truth.as_deref()).unwrap();
    for f in common::PS_OUTPUTS {
        assert!(dir.path().join(f).is_file(), "{f} missing");
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["model"], "robust");
    assert_eq!(summary["pixels"], 15791);
    // Normals in the dataset's frame (y up): the ball's top rim points up.
    let n = lumen::image::io::read_exr(&dir.path().join("normals.exr")).unwrap();
    let top = ds.input.pixels[0];
    assert!(n.data[3 * top + 1] > 0.5, "top pixel normal {:?}", &n.data[3 * top..3 * top + 3]);
}

/// A Lambertian sphere seen orthographically, rendered in closed form: pixel (x, y) of a
/// size×size image, normal (x, −y, z) in DiLiGenT's frame; lights at the given elevations
/// (degrees) and azimuths spread round.
fn sphere(size: usize, lights: &[DVec3], albedo: f64) -> Dataset {
    glossy_sphere(size, lights, albedo, 0.0, 1.0)
}

/// The same with a Blinn-Phong lobe of specular albedo σ and shininess e (the renderer's
/// form, ρ = kd/π, σ = ks/π), seen from +z.
fn glossy_sphere(size: usize, lights: &[DVec3], albedo: f64, sigma: f64, e: f64) -> Dataset {
    let mut pixels = Vec::new();
    let mut normals = Vec::new();
    let c = (size as f64 - 1.0) / 2.0;
    for y in 0..size {
        for x in 0..size {
            let (u, v) = ((x as f64 - c) / (0.45 * size as f64), -(y as f64 - c) / (0.45 * size as f64));
            if u * u + v * v < 0.95 {
                pixels.push(y * size + x);
                normals.push(DVec3::new(u, v, (1.0 - u * u - v * v).sqrt()));
            }
        }
    }
    let mut obs = Observations::new(pixels.len(), lights.len());
    for (p, n) in normals.iter().enumerate() {
        for (j, l) in lights.iter().enumerate() {
            let d = n.dot((*l + DVec3::Z).normalize()).max(0.0);
            let f = albedo + sigma * (e + 8.0) / 8.0 * d.powf(e);
            obs.set_raw(p, j, [(f * l.dot(*n).max(0.0)) as f32; 3], [1.0; 3]);
        }
    }
    Dataset {
        input: Input {
            width: size,
            height: size,
            lights: lights.to_vec(),
            intensities: vec![[1.0; 3]; lights.len()],
            pixels,
            obs,
            views: None,
        },
        truth: Some(normals),
    }
}

/// The solver as the CLI and the pipeline call it, with the iteration trace kept.
fn solve(ds: &Dataset, model: Model) -> photometric::Output {
    photometric::run(&ds.input, &photometric::Config { trace: true, ..photometric::Config::new(model) })
        .unwrap()
}

/// The output against the dataset's truth, computed outside the solver.
fn accuracy(ds: &Dataset, out: &photometric::Output) -> photometric::Accuracy {
    photometric::accuracy(out, ds.truth.as_ref().unwrap()).unwrap()
}

/// Lights spread by the golden angle over elevations 20°–80°.
fn spread(n: usize) -> Vec<DVec3> {
    (0..n)
        .map(|k| {
            let e = (20.0 + 60.0 * (k as f64 + 0.5) / n as f64).to_radians();
            let a = k as f64 * 2.399_963_229_728_653;
            DVec3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin())
        })
        .collect()
}

fn mean_error(ds: &Dataset, out: &photometric::Output) -> f64 {
    let errs = photometric::angular_errors(&out.normals, ds.truth.as_ref().unwrap());
    assert!(out.normals.iter().flatten().all(|n| n.is_finite()));
    errs.iter().sum::<f64>() / errs.len() as f64
}

/// Noiseless glossy spheres of several shininess values under 12, 24 and 96 lights: the
/// Blinn-Phong fit is exact to 0.05° where the Lambertian models are degrees off.
#[test]
fn blinn_phong_spheres() {
    for (lights, e) in [(12, 10.0), (24, 30.0), (96, 100.0), (48, 300.0)] {
        let ds = glossy_sphere(48, &spread(lights), 0.12, 0.1, e);
        let robust = mean_error(&ds, &solve(&ds, Model::Robust));
        let out = solve(&ds, Model::BlinnPhong);
        let fit = mean_error(&ds, &out);
        eprintln!("{lights} lights, e = {e}: Blinn-Phong {fit:.4}°, robust {robust:.3}°");
        assert!(fit < 0.05 && fit * 3.0 < robust, "Blinn-Phong {fit}°, robust {robust}°");
        assert_eq!(out.summary.masked_pixels, 0);
    }
}

fn ring(n: usize, elevation_deg: f64) -> Vec<DVec3> {
    let e = elevation_deg.to_radians();
    (0..n)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            DVec3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin())
        })
        .collect()
}

/// The minimum of 3 lights: exact where all three light the pixel; pixels some light does
/// not reach are solved by least squares (wrong but finite) or left out by the robust model,
/// never NaN.
#[test]
fn three_lights() {
    let lights = ring(3, 50.0);
    let ds = sphere(64, &lights, 0.6);
    let out = solve(&ds, Model::Lambertian);
    let truth = ds.truth.as_ref().unwrap();
    let mut lit_errors = Vec::new();
    for (k, n) in out.normals.iter().enumerate() {
        let n = n.expect("three independent lights always give a least-squares normal");
        assert!(n.is_finite());
        if lights.iter().all(|l| l.dot(truth[k]) > 0.0) {
            lit_errors.push(n.angle_between(truth[k]).to_degrees());
        }
    }
    assert!(lit_errors.len() > 1000);
    assert!(lit_errors.iter().all(|&e| e < 1e-4), "max {}", lit_errors.iter().fold(0.0f64, |a, &b| a.max(b)));
    for model in [Model::Robust, Model::BlinnPhong] {
        let out = solve(&ds, model);
        assert!(out.normals.iter().flatten().all(|n| n.is_finite()));
        assert!(out.albedo.iter().flatten().all(|a| a.is_finite()));
        assert_eq!(out.summary.masked_pixels + out.summary.pixels, ds.input.pixels.len());
    }
}

/// Grazing lights (elevation 5°): the light matrix is ill-conditioned in z, which the summary
/// says, yet noiseless data are still solved where every light reaches.
#[test]
fn grazing_lights() {
    let mut lights = ring(12, 5.0);
    lights.push(DVec3::Z);
    let ds = sphere(64, &lights, 0.5);
    for model in [Model::Robust, Model::BlinnPhong] {
        let out = solve(&ds, model);
        assert!(out.summary.light_condition_number > 1.0);
        let mean = mean_error(&ds, &out);
        assert!(mean < 0.01, "{model:?}: mean error {mean}°");
    }
    // Only the ring, all at 5°: nearly coplanar, flagged.
    let ds = sphere(32, &ring(12, 5.0), 0.5);
    let out = solve(&ds, Model::Lambertian);
    assert!(out.summary.lights_nearly_coplanar, "condition number {}", out.summary.light_condition_number);
}

/// Exactly coplanar lights: detected, and no pixel gets a made-up normal: with every pixel
/// unsolvable the solver says so instead of returning an empty answer.
#[test]
fn coplanar_lights() {
    let ds = sphere(32, &ring(8, 0.0), 0.5);
    assert!(photometric::light_condition_number(&ds.input.lights) > 1e12);
    for model in [Model::Lambertian, Model::Robust, Model::BlinnPhong] {
        let e = photometric::run(&ds.input, &photometric::Config::new(model)).err().expect("an error");
        assert_eq!(e.fault(), lumen::Fault::Numerical, "{e}");
        assert!(e.to_string().contains("lights in one plane"), "{e}");
    }
}

/// A very dark albedo (0.002 of white) and saturation (a bright albedo's values clipped at the
/// largest code on its brightest lights): still solved, never NaN; the robust model leaves the
/// saturated observations out.
#[test]
fn dark_albedo_and_saturation() {
    let lights = [ring(8, 30.0), ring(8, 60.0), vec![DVec3::Z]].concat();
    let dark = sphere(48, &lights, 0.002);
    for model in [Model::Robust, Model::BlinnPhong] {
        let mean = mean_error(&dark, &solve(&dark, model));
        assert!(mean < 0.01, "{model:?}: mean error {mean}°");
    }
    let mut bright = sphere(48, &lights, 1.6);
    let n = bright.input.pixels.len();
    let mut clipped = 0;
    for p in 0..n {
        let obs: Vec<[f32; 3]> = bright.input.obs.pixel(p).to_vec();
        for (j, o) in obs.iter().enumerate() {
            if o[0] > 1.0 {
                clipped += 1;
            }
            // What a sensor records: clipped at its largest code.
            bright.input.obs.set_raw(p, j, o.map(|v| v.min(1.0)), [1.0; 3]);
        }
    }
    assert!(clipped > 1000);
    let plain = accuracy(&bright, &solve(&bright, Model::Lambertian)).mean_angular_error_deg;
    let robust = solve(&bright, Model::Robust);
    let r = accuracy(&bright, &robust).mean_angular_error_deg;
    eprintln!("saturated: least squares {plain:.2}°, robust {r:.3}°");
    assert!(r < 0.5 && r < plain / 3.0, "robust {r}°, least squares {plain}°");
}

/// Saturated highlights on a glossy sphere: clipped observations are left out of the
/// Blinn-Phong fit, which stays accurate; never NaN.
#[test]
fn saturated_highlights() {
    let mut ds = glossy_sphere(48, &spread(48), 0.15, 0.3, 40.0);
    let mut clipped = 0;
    for p in 0..ds.input.pixels.len() {
        let obs: Vec<[f32; 3]> = ds.input.obs.pixel(p).to_vec();
        for (j, o) in obs.iter().enumerate() {
            clipped += (o[0] > 0.6) as usize;
            ds.input.obs.set_raw(p, j, o.map(|v| (v / 0.6).min(1.0)), [1.0 / 0.6; 3]);
        }
    }
    assert!(clipped > 500, "{clipped} clipped");
    let robust = mean_error(&ds, &solve(&ds, Model::Robust));
    let fit = mean_error(&ds, &solve(&ds, Model::BlinnPhong));
    eprintln!("saturated highlights: Blinn-Phong {fit:.4}°, robust {robust:.3}°");
    assert!(fit < 0.1 && fit * 3.0 < robust, "Blinn-Phong {fit}°, robust {robust}°");
}

/// Broken datasets: each error names the file and what was expected; nothing is written.
#[test]
fn bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("out");
    let run = || lumen(&["ps", "--dataset", d.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    let (code, err) = run();
    assert_eq!(code, 1);
    assert!(err.contains("filenames.txt"), "{err}");
    std::fs::write(d.join("filenames.txt"), "a.png\nb.png\nc.png\n").unwrap();
    std::fs::write(d.join("light_directions.txt"), "0 0 1\n0 1 0\n").unwrap();
    std::fs::write(d.join("light_intensities.txt"), "1 1 1\n1 1 1\n1 1 1\n").unwrap();
    let (code, err) = run();
    assert_eq!(code, 1);
    assert!(err.contains("light_directions.txt") && err.contains("2 rows"), "{err}");
    std::fs::write(d.join("light_directions.txt"), "0 0 1\n0 1 0\n0 0.5 x\n").unwrap();
    let (_, err) = run();
    assert!(err.contains("light_directions.txt") && err.contains("line 3"), "{err}");
    std::fs::write(d.join("light_directions.txt"), "0 0 1\n0 1 0\n0 0.5 0.5\n").unwrap();
    let (_, err) = run();
    assert!(err.contains("line 3") && err.contains("unit vector"), "{err}");
    std::fs::write(d.join("light_directions.txt"), "0 0 1\n0 1 0\n1 0 0\n").unwrap();
    let (_, err) = run();
    assert!(err.contains("mask.png"), "{err}");
    image::save_buffer(d.join("mask.png"), &[255u8; 16], 4, 4, image::ExtendedColorType::L8).unwrap();
    image::save_buffer(d.join("a.png"), &[9u8; 16], 4, 4, image::ExtendedColorType::L8).unwrap();
    image::save_buffer(d.join("b.png"), &[9u8; 25], 5, 5, image::ExtendedColorType::L8).unwrap();
    let (_, err) = run();
    assert!(err.contains("b.png") || err.contains("c.png"), "{err}");
    let (code, err) = lumen(&["ps", "--dataset", d.to_str().unwrap(), "--model", "phong", "--out", "x"]);
    assert_eq!(code, 1);
    assert!(err.contains("--model") && err.contains("phong"), "{err}");
    for k in ["0", "101"] {
        let args =
            ["ps", "--dataset", d.to_str().unwrap(), "--model", "blinn-phong", "--start-iterations", k];
        let (code, err) = lumen(&[&args[..], &["--out", "x"]].concat());
        assert_eq!(code, 1, "{err}");
        assert!(err.contains("--start-iterations") && err.contains("1 to 100"), "{err}");
    }
    assert!(!out.exists());
}

/// Fewer than 3 lights (none at all included) or a mask that selects nothing: a clear error
/// from `lumen ps`, never a panic or "0 pixels solved".
#[test]
fn too_few_lights_or_an_empty_mask() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("out");
    let run = || lumen(&["ps", "--dataset", d.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    for f in ["filenames.txt", "light_directions.txt", "light_intensities.txt"] {
        std::fs::write(d.join(f), "").unwrap();
    }
    image::save_buffer(d.join("mask.png"), &[255u8; 16], 4, 4, image::ExtendedColorType::L8).unwrap();
    let (code, err) = run();
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("0 light(s): photometric stereo needs at least 3"), "{err}");
    std::fs::write(d.join("filenames.txt"), "a.png\nb.png\n").unwrap();
    std::fs::write(d.join("light_directions.txt"), "0 0 1\n0 1 0\n").unwrap();
    std::fs::write(d.join("light_intensities.txt"), "1 1 1\n1 1 1\n").unwrap();
    for f in ["a.png", "b.png", "c.png"] {
        image::save_buffer(d.join(f), &[9u8; 16], 4, 4, image::ExtendedColorType::L8).unwrap();
    }
    let (code, err) = run();
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("2 light(s)"), "{err}");
    std::fs::write(d.join("filenames.txt"), "a.png\nb.png\nc.png\n").unwrap();
    std::fs::write(d.join("light_directions.txt"), "0 0 1\n0 1 0\n1 0 0\n").unwrap();
    std::fs::write(d.join("light_intensities.txt"), "1 1 1\n1 1 1\n1 1 1\n").unwrap();
    image::save_buffer(d.join("mask.png"), &[0u8; 16], 4, 4, image::ExtendedColorType::L8).unwrap();
    let (code, err) = run();
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("the mask selects no pixel"), "{err}");
    assert!(!out.exists());
}

/// `error.png` shows the angular error in viridis on a scale fitted to it, with a colour bar:
/// a glossy sphere solved as Lambertian (errors of a few degrees) gets a scale that rounds its
/// 99th percentile up to 1, 2 or 5 × 10^k, each solved pixel the colour of its error on it,
/// and a bar beside the image from viridis(0) at the bottom to viridis(1) at the top.
#[test]
fn error_png_is_coloured_on_a_fitted_scale() {
    use lumen::image::colormap::viridis;
    let ds = glossy_sphere(48, &spread(24), 0.5, 0.3, 20.0);
    let out = solve(&ds, Model::Lambertian);
    let truth = ds.truth.as_ref().unwrap();
    let scale = photometric::error_scale_deg(&out, truth);
    let mut errs = photometric::angular_errors(&out.normals, truth);
    errs.sort_by(f64::total_cmp);
    let p99 = errs[(errs.len() - 1) * 99 / 100];
    assert!(scale >= p99 && scale <= 2.5 * p99 && p99 > 0.5, "scale {scale}°, 99th percentile {p99}°");
    let dir = tempfile::tempdir().unwrap();
    photometric::write(dir.path(), &ds.input, &out, Some(truth)).unwrap();
    let png = image::open(dir.path().join("error.png")).unwrap().into_rgb8();
    assert!(png.width() > 48 && png.height() >= 64, "{}×{}", png.width(), png.height());
    for (k, &i) in ds.input.pixels.iter().enumerate().step_by(37) {
        let n = out.normals[k].unwrap();
        let want = viridis(n.angle_between(truth[k]).to_degrees() / scale);
        let got = png.get_pixel((i % 48) as u32, (i / 48) as u32).0;
        assert!(got.iter().zip(want).all(|(a, b)| a.abs_diff(b) <= 1), "pixel {i}: {got:?} vs {want:?}");
    }
    let bar: Vec<[u8; 3]> = (0..png.height()).map(|y| png.get_pixel(48 + 4, y).0).collect();
    assert!(bar.contains(&viridis(0.0)) && bar.contains(&viridis(1.0)));
    let (bottom, top) =
        (bar.iter().rposition(|c| *c == viridis(0.0)), bar.iter().position(|c| *c == viridis(1.0)));
    assert!(top < bottom, "the high end is at the top");
}
