//! Chained cases (`from:CASE`): each is given its source's output, never the truth, runs
//! alone too, and reports the error it inherits with the sensitivity's prediction of it.

mod common;

use common::run::{read_json, run};

/// Colour cases chained to an hdr case: one fits the chart in the merged radiance, one
/// photographs it through the stack's camera and makes it linear through the recovered
/// response. With the hdr case's seed changed (its frames' noise) the chained fits change and
/// the alone ones (on the true radiance, through the true response) do not. With what they
/// inherit raised to the power 1.02, the error that adds shows and the sensitivity predicts it
/// within a factor of 2. A source of another chart, or of RGB radiance, or seen from another
/// pose, and sensor settings on a chained case are named.
#[test]
fn chained_colour_cases_take_the_merged_radiance_and_the_response() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let chart = common::root().join("pipelines/scenes/color-chart.toml");
    let session = |seed: u64, colour: &str| {
        format!(
            "[[stages]]\nstage = \"hdr\"\ncase = \"h\"\nseed = {seed}\nscene = \"{0}\"\nspectral = {{ camera = \"nikon-d5100\", illuminant = \"d65\" }}\nexposure = 8.0\nspp = 1\n\
             [[stages]]\nstage = \"color\"\ncase = \"k\"\nscene = \"{0}\"\nimage = \"from:h/radiance\"\n{colour}\
             [[stages]]\nstage = \"color\"\ncase = \"r\"\nscene = \"{0}\"\nspp = 1\nresponse = \"from:h\"\n{colour}",
            chart.display()
        )
    };
    // Per chained case: chained, alone, inherited and predicted inherited headline errors.
    let metrics = |text: &str| {
        let (code, err) = run(text, &out);
        assert_eq!(code, 0, "{err}");
        let j: serde_json::Value = read_json(&out.join("report.json"));
        [1, 2].map(|k| {
            assert_eq!(j["stages"][k]["mode"], "chained");
            let value = |name: &str| {
                j["stages"][k]["metrics"].as_array().unwrap().iter().find(|m| m["name"] == name).unwrap()
                    ["value"]
                    .as_f64()
                    .unwrap_or_else(|| panic!("{name} is missing"))
            };
            [
                "loo_mean_de2000",
                "alone_loo_mean_de2000",
                "inherited_loo_mean_de2000",
                "predicted_inherited_loo_mean_de2000",
            ]
            .map(value)
        })
    };
    let m1 = metrics(&session(1, ""));
    let m2 = metrics(&session(2, ""));
    for (a, b) in m1.iter().zip(&m2) {
        assert_eq!(a[1], b[1], "the alone run does not depend on the upstream");
        assert_ne!(a[0], b[0], "the chained run takes the upstream's estimate");
    }
    // The error each link inherits, from the merge's and the response's own errors at the
    // patches, is predicted within a factor of 2 (the goal), in sign as in size.
    for (case, m) in ["radiance", "response"].iter().cycle().zip(m1.iter().chain(&m2)) {
        let (inherited, predicted) = (m[2], m[3]);
        assert!(inherited.abs() > 0.005, "{case}: inherited {inherited}, too little to predict");
        let ratio = predicted / inherited;
        assert!((0.5..2.0).contains(&ratio), "{case}: inherited {inherited}, predicted {predicted}");
    }
    // A power of 1.02 bends the patches' chromaticities by up to 2 % of their log ratios,
    // against the merge's and the response's own errors of about 0.2 % per patch. What it
    // adds to the inherited error is what the slopes predict.
    let wrong = metrics(&session(1, "perturb = { slope = 0.02 }\n"));
    for (case, (w, m)) in ["radiance", "response"].iter().zip(wrong.iter().zip(&m1)) {
        let (added, predicted) = (w[2] - m[2], w[3] - m[3]);
        assert!(added > 0.05, "{case}, slope +2 %: inherited {} (unperturbed {})", w[2], m[2]);
        assert!(
            predicted > 0.5 * added && predicted < 2.0 * added,
            "{case}: the slope adds {added}, predicted {predicted}"
        );
    }
    // Bad input: another chart, RGB radiance, a sensor setting on a chained case, perturb
    // without a source.
    let other = session(1, "").replace("illuminant = \"d65\" }", "illuminant = \"a\" }");
    let (code, err) = run(&other, &out);
    assert!(code == 1 && err.contains("a chained colour case must fit the chart its source merged"), "{err}");
    let moved = session(1, "").replacen(
        "image = \"from:h/radiance\"\n",
        "image = \"from:h/radiance\"\nlook_at = { origin = [0.12, 0.08, -0.9], target = [0.12, 0.08, 0.0], up = [0.0, -1.0, 0.0] }\n",
        1,
    );
    let (code, err) = run(&moved, &out);
    assert!(
        code == 1 && err.contains("must look at the chart its source merged from the same pose"),
        "{err}"
    );
    let rgb = session(1, "").replace("spectral = { camera = \"nikon-d5100\", illuminant = \"d65\" }\n", "");
    let (code, err) = run(&rgb, &out);
    assert!(code == 1 && err.contains("RGB radiance, not spectral"), "{err}");
    let (code, err) = run(&session(1, "bits = 8\n"), &out);
    assert!(code == 1 && err.contains("image = \"from:h/radiance\" and bits"), "{err}");
    let (code, err) = run(&session(1, "").replace("spp = 1\nresponse", "full_well = 100.0\nresponse"), &out);
    assert!(code == 1 && err.contains("response = \"from:h\" and full_well"), "{err}");
    let (code, err) = run(
        &session(1, "perturb = { slope = 0.02 }\n")
            .replace("image = \"from:h/radiance\"\n", "")
            .replace("response = \"from:h\"\n", ""),
        &out,
    );
    assert!(code == 1 && err.contains("perturb: only on a chained case"), "{err}");
}

/// A chained case is given its source's output, never the truth: with the calibration's seed
/// changed, the chained sfm case's errors change and its alone ones do not. With the inherited
/// focal length made 2 % long, the inherited error shows in the sfm and the photometric case,
/// and the sensitivity predicts it
/// within a factor of 2. The report marks the case chained; a source that hands on nothing
/// usable, and `perturb` on a case that inherits nothing, are named.
#[test]
fn chained_case_takes_the_upstream_output() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    // The room of pipelines/session.toml: the board on the ground, the courtyard around it,
    // the object on its cloth seen from above. Twelve views of 8 spp give the principal point
    // to a standard deviation of about 0.6 px in x and 0.45 in y (the calibration's own
    // figures in its notes): its bounds are three of those. The room's sensor writes through a
    // gamma of 2.2, which the calibration assumes (`response`), as session.toml's does.
    let room = common::root().join("pipelines/scenes/session-room.toml");
    let session = |seed: u64| {
        format!(
            "[[stages]]\nstage = \"calibrate\"\ncase = \"cal\"\nseed = {seed}\nscene = \"{0}\"\nboard_origin = [0.875, -1.225, 0.002]\nboard_axes = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]\nresponse = {{ type = \"gamma\", gamma = 2.2 }}\nviews = 12\nspp = 8\nbounds = {{ views_missed = 0, fx_rel_err = 0.001, cx_err_px = 1.8, cy_err_px = 1.3 }}\n\
             [[stages]]\nstage = \"sfm\"\ncase = \"s\"\nscene = \"{0}\"\ncamera = \"from:cal\"\ntarget = [0.0, 0.5, 0.6]\nradius = 3.5\nheight = 1.3\narc_deg = 40\nviews = 4\nbounds = {{ unregistered_images = 0 }}\n\
             [[stages]]\nstage = \"photometric\"\ncase = \"p\"\nscene = \"{0}\"\nlook_at = {{ origin = [-0.6, -3.85, 4.52], target = [-0.6, -3.85, 0.52], up = [0.0, 1.0, 0.0] }}\nobject = \"glossy\"\ncamera = \"from:cal\"\nlights = 8\nspp = 1\ndiffuse_only = true\n",
            room.display()
        )
    };
    let metrics = |seed: u64| {
        let (code, err) = run(&session(seed), &out);
        assert_eq!(code, 0, "{err}");
        let j: serde_json::Value = read_json(&out.join("report.json"));
        assert_eq!(j["stages"][0]["mode"], "alone");
        [(1, "rotation_err_median_deg"), (2, "mean_angular_error_deg")].map(|(k, headline)| {
            let case = &j["stages"][k];
            assert_eq!(case["mode"], "chained");
            let value = |name: String| {
                case["metrics"].as_array().unwrap().iter().find(|m| m["name"] == name).unwrap()["value"]
                    .as_f64()
                    .unwrap()
            };
            (
                value(headline.to_string()),
                value(format!("alone_{headline}")),
                value(format!("inherited_{headline}")),
            )
        })
    };
    let m1 = metrics(1);
    let m2 = metrics(2);
    for ((c1, a1, i1), (c2, a2, i2)) in m1.iter().zip(&m2) {
        assert_eq!(a1, a2, "the alone run does not depend on the upstream");
        assert_ne!(c1, c2, "the chained run takes the upstream's estimate");
        assert!((i1 - (c1 - a1)).abs() < 1e-12 && (i2 - (c2 - a2)).abs() < 1e-12);
    }
    // A deliberately wrong upstream (the focal length 2 % long) in both chained cases: its
    // inherited error shows, and the sensitivity's prediction is within a factor of 2 of it.
    // It moves the courtyard's reprojections by up to 2 % of 640 px and the object's pixels
    // by 2 % of their 130 to 380 px from the principal point, against the calibration's own
    // error of under half a pixel (its bounds).
    let wrong = session(1)
        .replace("views = 4\n", "views = 4\nperturb = { focal_rel = 0.02 }\n")
        .replace("lights = 8\n", "lights = 8\nperturb = { focal_rel = 0.02 }\n");
    let (code, err) = run(&wrong, &out);
    assert_eq!(code, 0, "{err}");
    let j: serde_json::Value = read_json(&out.join("report.json"));
    for (k, headline, floor) in [(1, "rotation_err_median_deg", 0.05), (2, "mean_angular_error_deg", 0.5)] {
        let value = |name: String| {
            j["stages"][k]["metrics"].as_array().unwrap().iter().find(|m| m["name"] == name).unwrap()["value"]
                .as_f64()
                .unwrap()
        };
        let inherited = value(format!("inherited_{headline}"));
        let predicted = value(format!("predicted_inherited_{headline}"));
        let unperturbed = m1[k - 1].2;
        assert!(
            inherited > floor && inherited > 5.0 * unperturbed.abs(),
            "{headline}, fx +2 %: inherited {inherited}° (unperturbed {unperturbed}°)"
        );
        assert!(
            predicted > 0.5 * inherited && predicted < 2.0 * inherited,
            "{headline}: predicted {predicted}°, measured {inherited}°"
        );
    }
    let (code, err) = run(&session(1).replace("camera = \"from:cal\"\n", "perturb = { k1 = 0.1 }\n"), &out);
    assert!(code == 1 && err.contains("perturb: only on a chained case"), "{err}");
    // A source of another camera, and a source that ended in a declared error.
    let board = common::root().join("pipelines/scenes/calib-board.toml");
    let other = session(1).replacen(&room.display().to_string(), &board.display().to_string(), 1).replacen(
        "board_origin = [0.875, -1.225, 0.002]\nboard_axes = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]\n",
        "",
        1,
    );
    let (code, err) = run(&other, &out);
    assert!(
        code == 1 && err.contains("a chained case must see through the camera its source calibrated"),
        "{err}"
    );
    let failed = session(1)
        .replace("views = 12\n", "views = 1\nexpect_error = \"bad-input\"\n")
        .replace("bounds = { views_missed = 0, fx_rel_err = 0.001, cx_err_px = 1.8, cy_err_px = 1.3 }\n", "");
    let (code, err) = run(&failed, &out);
    assert!(code == 1 && err.contains("case `cal` handed on no camera"), "{err}");
}
