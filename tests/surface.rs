//! Point-set surfaces (`surface`, `lumen surface`) on analytic shapes sampled with known noise:
//! distance to the true surface, genus and watertightness; and bad input.

mod common;

use glam::DVec3;
use lumen::surface::{self, Config, Input, Method};
use rand::{Rng, SeedableRng};

/// n points spread evenly over the unit sphere (a Fibonacci lattice), with their normals.
fn sphere(n: usize) -> (Vec<DVec3>, Vec<DVec3>) {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let pts: Vec<DVec3> = (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - y * y).sqrt();
            let phi = golden * i as f64;
            DVec3::new(r * phi.cos(), y, r * phi.sin())
        })
        .collect();
    (pts.clone(), pts)
}

/// A torus of radii R = 1, r = 0.4 about z, sampled uniformly by area (rejection), with normals.
fn torus(n: usize, seed: u64) -> (Vec<DVec3>, Vec<DVec3>) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let (big, small) = (1.0, 0.4);
    let (mut p, mut nn) = (Vec::new(), Vec::new());
    while p.len() < n {
        let (u, v) = (rng.gen::<f64>() * std::f64::consts::TAU, rng.gen::<f64>() * std::f64::consts::TAU);
        // Accept by the area element (R + r cos v) / (R + r).
        if rng.gen::<f64>() > (big + small * v.cos()) / (big + small) {
            continue;
        }
        let c = DVec3::new(big * u.cos(), big * u.sin(), 0.0);
        let normal = DVec3::new(v.cos() * u.cos(), v.cos() * u.sin(), v.sin());
        p.push(c + small * normal);
        nn.push(normal);
    }
    (p, nn)
}

fn torus_distance(p: DVec3) -> f64 {
    let q = (p.x * p.x + p.y * p.y).sqrt() - 1.0;
    (q * q + p.z * p.z).sqrt() - 0.4
}

fn rms(v: &[DVec3], d: impl Fn(DVec3) -> f64) -> f64 {
    (v.iter().map(|p| d(*p).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
}

/// A noiseless sphere is recovered to 1e-3 of its radius (RMS over the mesh's vertices), by
/// both fits, closed and of genus 0, with normals given and estimated.
#[test]
fn a_noiseless_sphere_is_recovered() {
    let (p, n) = sphere(4000);
    for method in [Method::Apss, Method::Mls] {
        for normals in [n.clone(), Vec::new()] {
            let estimated = normals.is_empty();
            let out =
                surface::run(&Input { points: p.clone(), normals }, &Config { method, ..Config::default() })
                    .unwrap();
            let e = rms(&out.mesh.vertices, |v| v.length() - 1.0);
            eprintln!("{method:?} (normals estimated: {estimated}): RMS {e:.2e}, {:?}", out.summary);
            assert!(e < 1e-3, "{method:?}: RMS distance {e}");
            assert!(
                out.summary.watertight && out.summary.genus == Some(0) && out.summary.components == 1,
                "{:?}",
                out.summary
            );
        }
    }
}

/// A torus with noise of 1 % of its tube radius: genus 1, closed, and the RMS distance below
/// the noise (the fit averages it).
#[test]
fn a_noisy_torus_keeps_its_hole() {
    let (mut p, n) = torus(20000, 3);
    let mut rng = rand::rngs::StdRng::seed_from_u64(4);
    let sigma = 0.004;
    for (q, nn) in p.iter_mut().zip(&n) {
        let g: f64 = (0..12).map(|_| rng.gen::<f64>()).sum::<f64>() - 6.0;
        *q += sigma * g * *nn;
    }
    for method in [Method::Apss, Method::Mls] {
        let out = surface::run(
            &Input { points: p.clone(), normals: Vec::new() },
            &Config { method, ..Config::default() },
        )
        .unwrap();
        let e = rms(&out.mesh.vertices, torus_distance);
        eprintln!("{method:?}: RMS {e:.2e} (noise {sigma}), {:?}", out.summary);
        assert!(e < sigma, "{method:?}: RMS distance {e}");
        assert!(out.summary.watertight && out.summary.genus == Some(1), "{:?}", out.summary);
    }
}

/// Writes an ASCII PLY of points.
fn ply(path: &std::path::Path, pts: &[DVec3]) {
    let mut s = format!("ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header\n", pts.len());
    for p in pts {
        s += &format!("{} {} {}\n", p.x, p.y, p.z);
    }
    std::fs::write(path, s).unwrap();
}

/// `lumen surface` writes the mesh and its summary; bad clouds and settings get a clear
/// error naming the file or value, and leave no output.
#[test]
fn lumen_surface_writes_a_mesh_and_refuses_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (p, _) = sphere(3000);
    let good = d.join("sphere.ply");
    ply(&good, &p);
    let out = d.join("mesh.ply");
    let (code, err) =
        common::lumen(&["surface", "--points", good.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let mesh = lumen::render::ply::read(&out).unwrap();
    assert!(mesh.triangles.len() > 1000);
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("mesh.json")).unwrap()).unwrap();
    assert_eq!(summary["watertight"], true);
    assert_eq!(summary["genus"], 0);
    // An OBJ's vertices (as `lumen ps` writes its integrated surface) are points too.
    let obj = d.join("sphere.obj");
    std::fs::write(&obj, p.iter().map(|q| format!("v {} {} {}\n", q.x, q.y, q.z)).collect::<String>())
        .unwrap();
    let (code, err) = common::lumen(&[
        "surface",
        "--points",
        obj.to_str().unwrap(),
        "--out",
        d.join("from-obj.ply").to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("watertight"), "{err}");
    let empty = d.join("empty.ply");
    ply(&empty, &[]);
    let one = d.join("one.ply");
    ply(&one, &[DVec3::ONE]);
    let nan = d.join("nan.ply");
    std::fs::write(&nan, "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\nnan 0 0\n").unwrap();
    let liar = d.join("liar.ply");
    std::fs::write(&liar, "ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n").unwrap();
    let same = d.join("same.ply");
    ply(&same, &vec![DVec3::ONE; 50]);
    let cases: [(&std::path::Path, &[&str], &str); 8] = [
        (&empty, &[], "0 point(s)"),
        (&one, &[], "1 point(s)"),
        (&nan, &[], "nan.ply"),
        (&liar, &[], "liar.ply"),
        (&same, &[], "not all in one place"),
        (&good, &["--radius", "0"], "radius 0"),
        (&good, &["--radius", "1e300"], "radius 1e300"),
        (&good, &["--resolution", "5000"], "resolution 5000"),
    ];
    for (file, extra, expected) in cases {
        let bad_out = d.join("bad.ply");
        let mut args =
            vec!["surface", "--points", file.to_str().unwrap(), "--out", bad_out.to_str().unwrap()];
        args.extend_from_slice(extra);
        let (code, err) = common::lumen(&args);
        assert_ne!(code, 0, "{args:?} was accepted");
        assert!(err.contains(expected), "{args:?}: {err}");
        assert!(!bad_out.exists() && !d.join("bad.json").exists(), "{args:?} left output behind");
    }
}

/// Density varying tenfold across the surface, and 5 % outliers scattered through the
/// sphere's box: still one closed sphere within 1 % of the radius (RMS), the outliers too
/// isolated for any fit to grow a surface around them.
#[test]
fn varying_density_and_outliers() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(9);
    let (all, _) = sphere(40000);
    // Keep every point on the upper half, one in ten below.
    let mut p: Vec<DVec3> = all.into_iter().filter(|q| q.y > 0.0 || rng.gen::<f64>() < 0.1).collect();
    let outliers = p.len() / 20;
    for _ in 0..outliers {
        p.push(DVec3::new(
            rng.gen::<f64>() * 3.0 - 1.5,
            rng.gen::<f64>() * 3.0 - 1.5,
            rng.gen::<f64>() * 3.0 - 1.5,
        ));
    }
    let out = surface::run(&Input { points: p, normals: Vec::new() }, &Config::default()).unwrap();
    let e = rms(&out.mesh.vertices, |v| v.length() - 1.0);
    eprintln!("RMS {e:.2e}, {:?}", out.summary);
    assert!(e < 0.01, "RMS distance {e}");
    assert!(
        out.summary.watertight && out.summary.components == 1 && out.summary.genus == Some(0),
        "{:?}",
        out.summary
    );
}

/// A thin slab (2 × 2 × 0.06) sampled on its faces with normals, the fits' radius (0.12) twice
/// its thickness: its two large faces stay two sheets, each near its own plane, not one sheet
/// between them.
#[test]
fn two_sheets_closer_than_the_radius_stay_apart() {
    let (mut p, mut n) = (Vec::new(), Vec::new());
    let h = 0.03;
    let steps = 80;
    for i in 0..=steps {
        for j in 0..=steps {
            let (x, y) = (-1.0 + 2.0 * i as f64 / steps as f64, -1.0 + 2.0 * j as f64 / steps as f64);
            for s in [-1.0, 1.0] {
                p.push(DVec3::new(x, y, s * h));
                n.push(DVec3::new(0.0, 0.0, s));
            }
        }
    }
    // The rim, so the slab is closed.
    for i in 0..=steps {
        let t = -1.0 + 2.0 * i as f64 / steps as f64;
        for z in [-h, 0.0, h] {
            for (q, m) in [
                (DVec3::new(t, -1.0, z), -DVec3::Y),
                (DVec3::new(t, 1.0, z), DVec3::Y),
                (DVec3::new(-1.0, t, z), -DVec3::X),
                (DVec3::new(1.0, t, z), DVec3::X),
            ] {
                p.push(q);
                n.push(m);
            }
        }
    }
    let config = Config { radius: Some(0.12), resolution: 160, ..Config::default() };
    let out = surface::run(&Input { points: p, normals: n }, &config).unwrap();
    // Away from the rim, every vertex lies near one of the two faces.
    let inner: Vec<&DVec3> =
        out.mesh.vertices.iter().filter(|v| v.x.abs() < 0.8 && v.y.abs() < 0.8).collect();
    let worst = inner.iter().map(|v| (v.z.abs() - h).abs()).fold(0.0, f64::max);
    eprintln!("{} inner vertices, worst distance from a face {worst:.4}, {:?}", inner.len(), out.summary);
    assert!(!inner.is_empty() && worst < 0.005, "worst distance from a face {worst}");
}
