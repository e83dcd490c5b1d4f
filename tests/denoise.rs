//! `lumen render --denoise` and `lumen denoise`: the files one writes are what the other
//! reads, and bad input gets a clear error with nothing written.

mod common;

use common::{lumen, root};
use std::path::Path;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `lumen denoise` on the inputs `lumen render --denoise` wrote beside its image gives the
/// image it wrote, bit for bit; and the denoised image is closer to a 16× longer render than
/// the raw one is.
#[test]
fn render_denoise_and_denoise_agree() {
    let dir = tempfile::tempdir().unwrap();
    let scene = root().join("pipelines/scenes/cornell-box.toml");
    let out = dir.path().join("cb.exr");
    let (code, err) = lumen(&["render", s(&scene), "--spp", "8", "--denoise", "--out", s(&out)]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("half buffers cross-filtered"), "{err}");
    let f = |suffix: &str| dir.path().join(format!("cb.{suffix}.exr"));
    let again = dir.path().join("again.exr");
    let (code, err) = lumen(&[
        "denoise",
        s(&out),
        "--out",
        s(&again),
        "--variance",
        s(&f("variance")),
        "--halves",
        s(&f("half_a")),
        s(&f("half_b")),
        "--albedo",
        s(&f("feature_albedo")),
        "--albedo-variance",
        s(&f("feature_albedo.variance")),
        "--normal",
        s(&f("feature_normal")),
        "--normal-variance",
        s(&f("feature_normal.variance")),
        "--depth",
        s(&f("feature_depth")),
        "--depth-variance",
        s(&f("feature_depth.variance")),
    ]);
    assert_eq!(code, 0, "{err}");
    let read = |p: &Path| lumen::image::io::read_exr(p).unwrap();
    let (denoised, raw) = (read(&f("denoised")), read(&out));
    assert_eq!(read(&again), denoised);
    let long = dir.path().join("long.exr");
    let (code, err) = lumen(&["render", s(&scene), "--spp", "128", "--seed", "77", "--out", s(&long)]);
    assert_eq!(code, 0, "{err}");
    let long = read(&long);
    let (e_raw, e_denoised) = (
        lumen::image::metrics::relmse(&raw, &long, None),
        lumen::image::metrics::relmse(&denoised, &long, None),
    );
    // The 128-spp render's own noise is a sixteenth of the raw image's: the denoised image
    // must come below the raw error by more than that floor.
    assert!(e_denoised < 0.5 * e_raw, "relMSE {e_denoised} denoised, {e_raw} raw");
}

#[test]
fn bad_denoise_input_is_named_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, w: u32, h: u32, v: f32| {
        let mut img = lumen::image::Image::new(w, h, 3);
        img.data.fill(v);
        let p = dir.path().join(name);
        lumen::image::io::write_exr(&p, &img).unwrap();
        p
    };
    let img = write("img.exr", 16, 12, 0.5);
    let var = write("var.exr", 16, 12, 0.01);
    let small = write("small.exr", 8, 12, 0.01);
    let neg = write("neg.exr", 16, 12, -0.01);
    let out = dir.path().join("out.exr");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["--variance", s(&small)], "the variance is 8×12, the image 16×12"),
        (vec!["--variance", s(&neg)], "the variance is negative (-0.01) at pixel (0, 0)"),
        (vec![], "no noise level given"),
        (vec!["--variance", s(&var), "--window-radius", "1000000"], "window radius 1000000 is above"),
        (vec!["--variance", s(&var), "--patch-radius", "1000000"], "patch radius 1000000 is above"),
        (vec!["--variance", s(&var), "--variance-per-sample", "0"], "--variance-per-sample 0"),
        (vec!["--variance", s(&var), "--method", "feature"], "needs at least one feature"),
        (vec!["--variance", s(&var), "--method", "median"], "not a denoising method"),
        (vec!["--variance", s(&var), "--albedo", s(&small)], "--albedo is 8×12"),
        (vec!["--variance", s(&var), "--k", "-1"], "k = -1"),
        (vec!["--variance", "/nonexistent/v.exr"], "/nonexistent/v.exr"),
    ];
    for (extra, want) in cases {
        let mut args = vec!["denoise", s(&img), "--out", s(&out)];
        args.extend(extra.iter().copied());
        let (code, err) = lumen(&args);
        assert_ne!(code, 0, "{args:?} was accepted");
        assert!(err.contains(want), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }
    let (code, err) =
        lumen(&["denoise", s(&img), "--out", s(&dir.path().join("o.png")), "--variance", s(&var)]);
    assert_ne!(code, 0);
    assert!(err.contains("expected a file name ending in .exr"), "{err}");
    // A variance of 0 everywhere: the image comes back unchanged.
    let zero = write("zero.exr", 16, 12, 0.0);
    let (code, err) = lumen(&["denoise", s(&img), "--out", s(&out), "--variance", s(&zero)]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("the image is unchanged"), "{err}");
    assert_eq!(lumen::image::io::read_exr(&out).unwrap(), lumen::image::io::read_exr(&img).unwrap());
}
