//! Colour calibration: the fits against colour-science's figures, `lumen color fit` on the
//! pipeline's rendered chart giving the pipeline's numbers, `color apply`, and bad input.

mod common;

use common::lumen;
use common::run::read_json;

use lumen::color::{self, spectra, Model};
use std::path::Path;

/// The noise-free D5100/D65 chart: camera RGB and XYZ from the spectra.
fn spectral_input() -> color::Input {
    let cam = spectra::camera("nikon-d5100").unwrap();
    let ill = spectra::illuminant("d65").unwrap();
    color::Input {
        patches: spectra::chart()
            .into_iter()
            .map(|(name, r)| color::PatchInput {
                name,
                rgb: spectra::camera_rgb(&r, &ill, &cam),
                reference_xyz: spectra::xyz(&r, &ill),
                flag: None,
            })
            .collect(),
        white: spectra::white(&ill),
    }
}

/// colour-science 0.4.7's colour_correction on the same camera RGB and XYZ (measured with
/// tools/color_vs_colour_science.py): mean ΔE00 1.0093 / 0.5677 / 0.3724 and leave-one-out
/// 1.1530 / 0.7616 / 1.6603 for Cheung 2004 (3 terms) and Finlayson 2015 (degree 2, 3).
/// lumen's least squares must give the same to the figures' rounding.
#[test]
fn least_squares_fits_match_colour_science() {
    let input = spectral_input();
    for (model, mean, loo) in
        [("linear-3x3", 1.0093, 1.1530), ("root-poly-2", 0.5677, 0.7616), ("root-poly-3", 0.3724, 1.6603)]
    {
        let out = color::run(&input, &color::Config::new(model.parse().unwrap())).unwrap();
        assert!((out.mean_de2000 - mean).abs() < 1e-4, "{model}: mean {}", out.mean_de2000);
        let l = out.loo_mean_de2000.unwrap();
        assert!((l - loo).abs() < 1e-4, "{model}: leave-one-out {l}");
    }
}

/// The ΔE00-optimised root-polynomial predicts a left-out patch better than the best
/// colour-science model (root-poly-2's 0.7616), and fits the chart better than its own start;
/// the fit and its leave-one-out report take well under a second.
#[test]
fn de2000_optimised_beats_least_squares_out_of_sample() {
    let input = spectral_input();
    let ls = color::run(&input, &color::Config::new(Model::RootPoly(2))).unwrap();
    let opt = color::run(&input, &color::Config::new("de2000-opt:root-poly-2".parse().unwrap())).unwrap();
    assert!(opt.mean_de2000 < ls.mean_de2000, "{} vs {}", opt.mean_de2000, ls.mean_de2000);
    assert!(opt.loo_mean_de2000.unwrap() < 0.7616, "{:?}", opt.loo_mean_de2000);
    let three =
        color::run(&input, &color::Config::new(Model::De2000Opt(color::models::Basis::Linear3x3))).unwrap();
    let ls3 = color::run(&input, &color::Config::new(Model::Linear3x3)).unwrap();
    assert!(three.mean_de2000 < ls3.mean_de2000);
}

/// Every model on the same data: finite, and a model with more terms than patches refused.
#[test]
fn every_model_is_finite_or_refused() {
    let input = spectral_input();
    for n in color::models::CHEUNG_TERMS {
        let r = color::run(&input, &color::Config::new(Model::Cheung(n)));
        if n as usize > 24 {
            assert!(
                matches!(r, Err(color::Error::BadInput(ref m)) if m.contains("needs at least 35")),
                "{n}"
            );
        } else {
            let out = r.unwrap();
            assert!(
                out.mean_de2000.is_finite() && out.patches.iter().all(|p| p.de2000.is_finite()),
                "cheung-{n}"
            );
        }
    }
    // Values near f64's end: a clear refusal, never a hang in the SVD or NaN.
    let mut huge = spectral_input();
    huge.patches[3].rgb = [1e300, 1.0, 1.0];
    let err = color::run(&huge, &color::Config::new(Model::RootPoly(2))).unwrap_err();
    assert_eq!(err.fault(), lumen::Fault::BadInput, "{err}");
    assert!(err.to_string().contains("patch 4") && err.to_string().contains("1e30"), "{err}");
    let mut big = spectral_input();
    big.patches.iter_mut().enumerate().for_each(|(i, p)| p.rgb = [1e29 * (i + 1) as f64, 1e28, 1e-30]);
    for model in ["cheung-22", "root-poly-3", "de2000-opt:root-poly-2"] {
        let r = color::run(&big, &color::Config::new(model.parse().unwrap()));
        assert!(r.as_ref().map_or(true, |o| o.patches.iter().all(|p| p.de2000.is_finite())), "{model}");
    }

    // Patches flagged by the sampler are left out, with a warning naming them.
    let mut few = spectral_input();
    few.patches.iter_mut().skip(4).for_each(|p| p.flag = Some(color::Flag::Clipped));
    let err = color::run(&few, &color::Config::new(Model::RootPoly(2))).unwrap_err();
    assert_eq!(err.fault(), lumen::Fault::BadInput, "{err}");
    assert!(err.to_string().contains("4 usable patch(es), but the model needs at least 6"), "{err}");
    let ok = color::run(&few, &color::Config::new(Model::Linear3x3)).unwrap();
    assert_eq!(ok.used_patches, 4);
    assert!(ok.warnings.iter().any(|w| w.contains("patch 5") && w.contains("clipped")));
}

fn write(path: &Path, text: &str) {
    std::fs::write(path, text).unwrap();
}

/// The pipeline's rendered chart (kept with `save_image`) through `lumen color fit` gives the
/// pipeline's numbers; `color apply` maps the chart's pixels as the model does.
#[test]
fn cli_fit_on_the_rendered_chart_gives_the_pipelines_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = common::root().join("pipelines/scenes/color-chart.toml");
    write(
        &d.join("p.toml"),
        &format!(
            "[[stages]]\nstage = \"color\"\ncase = \"chart\"\nscene = \"{}\"\nmodel = \"root-poly-2\"\nsave_image = true\n",
            scene.display()
        ),
    );
    let out = d.join("out");
    let (code, err) =
        lumen(&["run", d.join("p.toml").to_str().unwrap(), "--out", out.to_str().unwrap(), "--no-cache"]);
    assert_eq!(code, 0, "{err}");
    let report: serde_json::Value = read_json(&out.join("report.json"));
    let stage = &report["stages"][0];
    let metric = |name: &str| {
        stage["metrics"].as_array().unwrap().iter().find(|m| m["name"] == name).unwrap()["value"]
            .as_f64()
            .unwrap()
    };
    let notes: Vec<&str> = stage["notes"].as_array().unwrap().iter().filter_map(|n| n.as_str()).collect();
    let corners = notes
        .iter()
        .find_map(|n| n.split("--corners ").nth(1))
        .map(|s| s.trim_end_matches(['`', '.']).to_string())
        .expect("the note gives the corners");

    let spec = d.join("spectral");
    let (code, err) = lumen(&["color", "spectral", "--out", spec.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let white = std::fs::read_to_string(spec.join("white.csv")).unwrap().lines().last().unwrap().to_string();
    let ccm = d.join("ccm.json");
    let image = out.join("chart.exr");
    let (code, err) = lumen(&[
        "color",
        "fit",
        "--image",
        image.to_str().unwrap(),
        "--corners",
        &corners,
        "--model",
        "root-poly-2",
        "--reference",
        spec.join("xyz.csv").to_str().unwrap(),
        "--white",
        &white,
        "--out",
        ccm.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let file = color::read_ccm(&ccm).unwrap();
    let rep = file.report.unwrap();
    assert!(
        (rep.mean_de2000 - metric("mean_de2000")).abs() < 1e-9,
        "{} vs {}",
        rep.mean_de2000,
        metric("mean_de2000")
    );
    assert!((rep.loo_mean_de2000.unwrap() - metric("loo_mean_de2000")).abs() < 1e-9);

    // The same chart as a 16-bit TIFF of linear code values: with --linear the same fit to
    // the 16-bit quantisation (a step of 1.5e-5 of full scale; the darkest patch is at 0.025),
    // and the message says how the file was read; without it, sRGB-decoded, a worse fit.
    let exr = lumen::image::io::read_exr(&image).unwrap();
    let codes: Vec<u16> = exr.data.iter().map(|&v| (v.clamp(0.0, 1.0) * 65535.0).round() as u16).collect();
    let tif = d.join("chart.tif");
    image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(exr.width, exr.height, codes)
        .unwrap()
        .save(&tif)
        .unwrap();
    let ccm16 = d.join("ccm16.json");
    let xyz_csv = spec.join("xyz.csv");
    let fit16 = |linear: bool| {
        let mut args = vec![
            "color",
            "fit",
            "--image",
            tif.to_str().unwrap(),
            "--corners",
            &corners,
            "--model",
            "root-poly-2",
            "--reference",
            xyz_csv.to_str().unwrap(),
            "--white",
            &white,
            "--out",
            ccm16.to_str().unwrap(),
        ];
        if linear {
            args.push("--linear");
        }
        let (code, err) = lumen(&args);
        assert_eq!(code, 0, "{err}");
        (color::read_ccm(&ccm16).unwrap().report.unwrap().mean_de2000, err)
    };
    let (linear, msg) = fit16(true);
    assert!((linear - rep.mean_de2000).abs() < 0.01, "{linear} vs {}", rep.mean_de2000);
    assert!(msg.contains("code values read as linear (--linear)"), "{msg}");
    let (decoded, msg) = fit16(false);
    assert!(msg.contains("sRGB-decoded"), "{msg}");
    assert!(decoded > rep.mean_de2000, "{decoded}");

    // apply: the patches' own values through the model, pixel by pixel.
    let rgb: Vec<[f64; 3]> = rep.patches.iter().map(|p| p.rgb).collect();
    let img = lumen::image::Image {
        width: 24,
        height: 1,
        channels: 3,
        data: rgb.iter().flatten().map(|&v| v as f32).collect(),
    };
    let (src, dst) = (d.join("patches.exr"), d.join("xyz.exr"));
    lumen::image::io::write_exr(&src, &img).unwrap();
    let (code, err) = lumen(&[
        "color",
        "apply",
        "--ccm",
        ccm.to_str().unwrap(),
        "--space",
        "xyz",
        src.to_str().unwrap(),
        dst.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let xyz = lumen::image::io::read_exr(&dst).unwrap();
    for (k, p) in rep.patches.iter().enumerate() {
        let want = file.fitted.apply(rgb[k].map(|v| v as f32 as f64));
        for c in 0..3 {
            assert!(
                (xyz.pixel(k as u32, 0)[c] as f64 - want[c]).abs() < 1e-5 * want[c].abs().max(1e-3),
                "patch {k}"
            );
            assert!((want[c] - p.predicted_xyz[c]).abs() < 1e-5);
        }
    }
    // And to sRGB: each pixel is the model's XYZ through the Bradford-adapted sRGB matrix,
    // which maps the model's white to (1, 1, 1).
    let srgb = d.join("srgb.exr");
    let (code, err) = lumen(&[
        "color",
        "apply",
        "--ccm",
        ccm.to_str().unwrap(),
        src.to_str().unwrap(),
        srgb.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let s = lumen::image::io::read_exr(&srgb).unwrap();
    let m = color::xyz_to_linear_srgb(file.white);
    let to = |x: [f64; 3]| m.map(|row| row[0] * x[0] + row[1] * x[1] + row[2] * x[2]);
    for (k, p) in rep.patches.iter().enumerate() {
        let want = to(p.predicted_xyz);
        for c in 0..3 {
            assert!((s.pixel(k as u32, 0)[c] as f64 - want[c]).abs() < 1e-5, "patch {k}");
        }
    }
    for white in [file.white, spectra::d50_white(), spectra::white(&spectra::illuminant("a").unwrap())] {
        let w = color::xyz_to_linear_srgb(white);
        let one = w.map(|row| row[0] * white[0] + row[1] * white[1] + row[2] * white[2]);
        assert!(one.iter().all(|v| (v - 1.0).abs() < 1e-3), "{white:?} → {one:?}");
    }
}

/// Malformed input to every `lumen color` command: exit 1 or 2, a message naming the
/// problem, and no output file.
#[test]
fn cli_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("ccm.json");
    let o = out.to_str().unwrap();
    let spec = d.join("spec");
    assert_eq!(lumen(&["color", "spectral", "--out", spec.to_str().unwrap()]).0, 0);
    let rgb = spec.join("rgb.csv");
    let r = rgb.to_str().unwrap();
    let img = d.join("chart.exr");
    lumen::image::io::write_exr(&img, &lumen::image::Image::new(120, 80, 3)).unwrap();
    let im = img.to_str().unwrap();
    let bad_csv = |name: &str, text: &str| {
        let p = d.join(name);
        write(&p, text);
        p.to_str().unwrap().to_string()
    };
    let dup = bad_csv("dup.csv", "patch,X,Y,Z\n1,0.1,0.1,0.1\n1,0.2,0.2,0.2\n");
    let neg = bad_csv("neg.csv", "patch,X,Y,Z\n1,-0.1,0.1,0.1\n");
    let header = bad_csv("header.csv", "patch,L,a,b\n");
    let short = bad_csv("short.csv", "patch,X,Y,Z\n1,0.1,0.1,0.1\n");
    let words = bad_csv("words.csv", "patch,R,G,B\n1,red,0.1,0.1\n");
    let zero_text: String = (1..=24).map(|k| format!("{k},0,0,0\n")).collect();
    let zero = bad_csv("zero.csv", &format!("patch,X,Y,Z\n{zero_text}"));
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["--patches", r, "--model", "poly-9"], "--model"),
        (vec!["--patches", r, "--model", "cheung-6"], "cheung-N"),
        (vec!["--image", im, "--corners", "1,2,3"], "3 numbers, expected 8"),
        (vec!["--image", im, "--corners", "1,2,3,4,5,6,7,nan"], "finite"),
        (vec!["--image", im, "--corners", "5,5,115,5,115,75,500,75"], "corner 4"),
        (vec!["--image", im, "--corners", "115,5,5,5,5,75,115,75"], "convex"),
        (vec!["--image", im, "--corners", "5,5,15,5,15,10,5,10"], "expected at least 9"),
        (vec!["--image", "/nonexistent/c.exr", "--corners", "5,5,115,5,115,75,5,75"], "/nonexistent/c.exr"),
        // A black chart: every patch flagged, and the flags go with the refusal.
        (vec!["--image", im, "--corners", "5,5,115,5,115,75,5,75"], "is too dark"),
        // References that would make every ΔE small without saying anything.
        (
            vec!["--patches", r, "--reference", &zero, "--white", "0.95,1,1.09"],
            "every patch's reference Y is 0",
        ),
        (vec!["--patches", r, "--white", "1e-300,1e-300,1e-300"], "but the white's Y is 1e-300"),
        (vec!["--patches", r, "--reference", &dup], "--white"),
        (vec!["--patches", r, "--reference", &dup, "--white", "0.95,1,1.09"], "patch 1 is given twice"),
        (vec!["--patches", r, "--reference", &neg, "--white", "0.95,1,1.09"], "non-negative"),
        (vec!["--patches", r, "--reference", &header, "--white", "0.95,1,1.09"], "patch,X,Y,Z"),
        (vec!["--patches", r, "--reference", &short, "--white", "0.95,1,1.09"], "no values for patch 2"),
        (vec!["--patches", &words], "`red`: expected a number"),
        (vec!["--patches", r, "--white", "0,1,1"], "positive"),
        (vec!["--patches", r, "--white-patch", "25"], "1 to 24"),
        (vec!["--patches", r, "--saturation", "0"], "--saturation"),
    ];
    for (args, want) in cases {
        let mut all = vec!["color", "fit", "--out", o];
        all.extend(&args);
        let (code, err) = lumen(&all);
        assert!(code == 1 || code == 2, "{args:?}: exit {code}: {err}");
        assert!(want.split('|').any(|w| err.contains(w)), "{args:?}: {err}");
        assert!(!out.exists(), "{args:?} left {o}");
    }

    // apply: a bad model file, a bad space, a bad output.
    assert_eq!(lumen(&["color", "fit", "--patches", r, "--model", "linear-3x3", "--out", o]).0, 0);
    let good = std::fs::read_to_string(&out).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
    v["fitted"]["matrix"][1] = serde_json::json!([1.0, 2.0]);
    let rows = bad_csv("rows.json", &v.to_string());
    let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
    v["format"] = serde_json::json!("opencv");
    let format = bad_csv("format.json", &v.to_string());
    let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
    v["extra"] = serde_json::json!(1);
    let extra = bad_csv("extra.json", &v.to_string());
    let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
    v["fitted"]["matrix"] = serde_json::json!([[1e300, 0.0, 0.0], [0.0, 1e300, 0.0], [0.0, 0.0, 1e300]]);
    let huge = bad_csv("huge.json", &v.to_string());
    let grey = d.join("grey.png");
    image::GrayImage::new(4, 4).save(&grey).unwrap();
    let res = d.join("res.exr");
    let rs = res.to_str().unwrap();
    let (jpg, png) = (d.join("x.jpg"), d.join("x.png"));
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["--ccm", &rows, im, rs], "2 coefficients for 3 terms"),
        (vec!["--ccm", &format, im, rs], "format `opencv`"),
        (vec!["--ccm", &extra, im, rs], "extra"),
        (vec!["--ccm", &huge, im, rs], "maps to XYZ [1e300, 0.0, 0.0]: expected finite values within ±1e6"),
        (vec!["--ccm", "/nonexistent/m.json", im, rs], "/nonexistent/m.json"),
        (vec!["--ccm", o, "--space", "lab", im, rs], "--space lab"),
        (vec!["--ccm", o, im, jpg.to_str().unwrap()], ".exr or .png"),
        (vec!["--ccm", o, "--space", "xyz", im, png.to_str().unwrap()], "XYZ is written as .exr"),
        (vec!["--ccm", o, grey.to_str().unwrap(), rs], "channel"),
    ];
    for (args, want) in cases {
        let mut all = vec!["color", "apply"];
        all.extend(&args);
        let (code, err) = lumen(&all);
        assert!(code == 1 || code == 2, "{args:?}: exit {code}: {err}");
        assert!(err.contains(want), "{args:?}: {err}");
        assert!(!res.exists(), "{args:?} left {rs}");
    }
    // spectral: unknown names.
    let (code, err) =
        lumen(&["color", "spectral", "--camera", "canon", "--out", d.join("s2").to_str().unwrap()]);
    assert_eq!(code, 1);
    assert!(err.contains("nikon-d5100"), "{err}");
    let (code, err) =
        lumen(&["color", "spectral", "--illuminant", "d75", "--out", d.join("s3").to_str().unwrap()]);
    assert_eq!(code, 1);
    assert!(err.contains("fl2"), "{err}");
}

/// The hard cases of `pipelines/stress.toml`'s colour section, each with its declared outcome
/// (illuminant A, low exposure with read noise, a nearly black 8-bit chart, an overexposed
/// one, too few usable patches for root-poly-3, another camera against the published values,
/// malformed settings):
/// `lumen run` exits 0 only when every case ends as declared and meets its bounds.
#[test]
fn stress_cases_end_as_declared() {
    let stress = std::fs::read_to_string(common::root().join("pipelines/stress.toml")).unwrap();
    let colour = stress
        .split("# ---------------------------------------------------------------- colour")
        .nth(1)
        .unwrap();
    let colour =
        colour.split("# ----------------------------------------------------------------").next().unwrap();
    let scenes = common::root().join("pipelines/scenes");
    let text = format!("seed = 11\n{}", colour.replace("\"scenes/", &format!("\"{}/", scenes.display())));
    assert_eq!(text.matches("[[stages]]").count(), 12, "the colour section's cases");
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("stress-color.toml");
    write(&file, &text);
    let out = dir.path().join("out");
    let (code, err) = lumen(&["run", file.to_str().unwrap(), "--out", out.to_str().unwrap(), "--no-cache"]);
    assert_eq!(code, 0, "{err}");
    let report = std::fs::read_to_string(out.join("report.json")).unwrap();
    assert!(
        report.contains("1 usable patch(es), but the model needs at least 13"),
        "the refusal names the numbers"
    );
    // Every metric of every case that ran has a finite value (JSON writes NaN as null).
    let v: serde_json::Value = serde_json::from_str(&report).unwrap();
    for stage in v["stages"].as_array().unwrap() {
        for m in stage["metrics"].as_array().into_iter().flatten() {
            assert!(m["value"].as_f64().is_some_and(f64::is_finite), "{}: {m}", stage["case"]);
        }
    }
}
