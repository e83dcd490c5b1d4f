//! Hard cases for board detection, on rendered views of the calibration board scene.

mod common;

use glam::DVec3;
use lumen::calib::{self, detect::BoardSize};
use lumen::image::filter::Grey;
use lumen::render;

const BOARD: BoardSize = BoardSize { cols: 9, rows: 6 };

/// Renders `pipelines/scenes/calib-board.toml` with text replacements, through its sensor
/// (8-bit), and returns the image with the true corner projections.
fn view(replace: &[(&str, &str)]) -> (Grey, Vec<glam::DVec2>) {
    render_view(replace, 16, true)
}

/// `view` at `spp` samples per pixel, through the sensor or (`sensor` false) as the linear
/// radiance image.
fn render_view(replace: &[(&str, &str)], spp: u32, sensor: bool) -> (Grey, Vec<glam::DVec2>) {
    let mut text = std::fs::read_to_string(common::root().join("pipelines/scenes/calib-board.toml")).unwrap();
    for (a, b) in replace {
        assert!(text.contains(a), "the scene has no `{a}`");
        text = text.replace(a, b);
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene(&text, dir.path()).unwrap();
    let film = render::render(&scene, &common::settings(&scene, spp, 2));
    let grey = if sensor {
        let sensor = scene.sensor.clone().unwrap();
        let codes = sensor.expose(&film.mean, 3);
        let max = sensor.max_code() as f32;
        let data = codes.chunks_exact(3).map(|c| c[0] as f32 / max).collect();
        Grey { width: 640, height: 480, data }
    } else {
        Grey::from_image(&film.mean)
    };
    let cam_from_world = scene.t_world_cam.inverse();
    let truth = calib::board_points(BOARD, 0.025)
        .iter()
        .map(|p| {
            scene
                .camera
                .project(cam_from_world.transform_point(*p + DVec3::new(0.025, 0.025, 0.0)))
                .unwrap_or_default()
        })
        .collect();
    (grey, truth)
}

/// The board seen from `tilt_deg` away from its normal, turned about the in-board axis at
/// `axis_deg` from the board's rows, from 0.35 m, centred in the image: the scene's `look_at`.
fn tilted(tilt_deg: f64, axis_deg: f64) -> String {
    let centre = DVec3::new(0.125, 0.0875, 0.0);
    let (a, t) = (axis_deg.to_radians(), tilt_deg.to_radians());
    let turn = glam::DMat3::from_axis_angle(DVec3::new(a.cos(), a.sin(), 0.0), t);
    let origin = centre + turn * DVec3::new(0.0, 0.0, -0.35);
    let up = turn * DVec3::new(0.0, -1.0, 0.0);
    format!(
        "look_at = {{ origin = [{}, {}, {}], target = [0.125, 0.0875, 0.0], up = [{}, {}, {}] }}",
        origin.x, origin.y, origin.z, up.x, up.y, up.z
    )
}

fn corner_rms(found: &[glam::DVec2], truth: &[glam::DVec2]) -> f64 {
    (found.iter().zip(truth).map(|(a, b)| a.distance_squared(*b)).sum::<f64>() / found.len() as f64).sqrt()
}

/// Part of the board outside the image: the view is refused with the reason.
#[test]
fn partly_hidden_board_is_skipped_with_reason() {
    let (img, _) = view(&[
        ("target = [0.125, 0.0875, 0.0]", "target = [0.32, 0.0875, 0.0]"),
        ("origin = [0.125, 0.0875, -0.5]", "origin = [0.32, 0.0875, -0.35]"),
    ]);
    let e = calib::detect::detect(&img, BOARD, &Default::default()).unwrap_err();
    assert_eq!(e.fault(), lumen::Fault::BadInput, "{e}");
    assert!(e.0.contains("not a whole 9×6 board") || e.0.contains("fewer than"), "{e}");
}

/// Dark squares at 30 % and light at 40 % reflectance: still found, corners still accurate.
#[test]
fn low_contrast_board() {
    let (img, truth) = view(&[(
        "even = [0.04, 0.04, 0.04], odd = [0.8, 0.8, 0.8]",
        "even = [0.3, 0.3, 0.3], odd = [0.4, 0.4, 0.4]",
    )]);
    let found = calib::detect::detect(&img, BOARD, &Default::default()).unwrap();
    let rms = corner_rms(&found, &truth);
    eprintln!("low contrast: corner RMS {rms:.3} px");
    assert!(rms < 0.2, "corner RMS {rms} px");
}

/// A board covering about 8 % of the image (squares of about 19 px).
#[test]
fn small_board() {
    let (img, truth) = view(&[("origin = [0.125, 0.0875, -0.5]", "origin = [0.125, 0.0875, -0.68]")]);
    let found = calib::detect::detect(&img, BOARD, &Default::default()).unwrap();
    let rms = corner_rms(&found, &truth);
    eprintln!("small board: corner RMS {rms:.3} px");
    assert!(rms < 0.1, "corner RMS {rms} px");
}

/// Heavy noise (500 e⁻ full well, 20 e⁻ read noise): found, with a larger but bounded error.
#[test]
fn heavy_noise() {
    let (img, truth) =
        view(&[("full_well = 8000.0", "full_well = 500.0"), ("read_noise = 4.0", "read_noise = 20.0")]);
    let found = calib::detect::detect(&img, BOARD, &Default::default()).unwrap();
    let rms = corner_rms(&found, &truth);
    eprintln!("heavy noise: corner RMS {rms:.3} px");
    assert!(rms < 0.5, "corner RMS {rms} px");
}

/// A wrong, smaller `--board`: a part of the 9×6 board is fitted, but the detection says the
/// complete grid is larger (9×6 in the board's orientation, or 6×9 when the smaller size is
/// given the other way round); the right size finds no larger grid.
#[test]
fn a_smaller_board_than_photographed_is_noticed() {
    let (img, _) = view(&[]);
    let right = calib::detect::find(&img, BOARD, &Default::default()).unwrap();
    assert_eq!(right.larger_grid, None);
    let small = calib::detect::find(&img, BoardSize { cols: 7, rows: 5 }, &Default::default()).unwrap();
    assert_eq!(small.corners.len(), 35);
    assert_eq!(small.larger_grid, Some((9, 6)));
    let turned = calib::detect::find(&img, BoardSize { cols: 4, rows: 8 }, &Default::default()).unwrap();
    assert_eq!(turned.larger_grid, Some((6, 9)));
}

/// Steep boards, noise-free (64 spp, linear radiance): at 70° from the line of sight, turned
/// about a row and about a diagonal (where the squares' corners become 37° and 143° in the
/// image), the corners are within 2× the frontal board's RMS error; at 80° the board is found
/// with corners within 0.1 px RMS or refused with the reason.
#[test]
fn steep_boards_keep_their_corners() {
    let look_at =
        "look_at = { origin = [0.125, 0.0875, -0.5], target = [0.125, 0.0875, 0.0], up = [0.0, -1.0, 0.0] }";
    let rms_at = |tilt: f64, axis: f64| {
        let (img, truth) = render_view(&[(look_at, &tilted(tilt, axis))], 64, false);
        calib::detect::detect(&img, BOARD, &Default::default()).map(|found| corner_rms(&found, &truth))
    };
    let frontal = rms_at(0.0, 0.0).unwrap();
    eprintln!("frontal: corner RMS {frontal:.4} px");
    for axis in [0.0, 45.0] {
        let steep = rms_at(70.0, axis).unwrap_or_else(|e| panic!("70° about {axis}°: {e}"));
        eprintln!("70° about {axis}°: corner RMS {steep:.4} px");
        assert!(steep <= 2.0 * frontal, "70° about {axis}°: {steep} px against {frontal} px frontal");
    }
    match rms_at(80.0, 0.0) {
        Ok(rms) => {
            eprintln!("80°: corner RMS {rms:.4} px");
            assert!(rms <= 0.1, "80°: {rms} px");
        }
        Err(reason) => {
            eprintln!("80°: skipped: {reason}");
            assert!(reason.0.contains("9×6"), "{reason}");
        }
    }
}

/// On the codes of a gamma-2.2 sensor a steep board's corners are found biased: a partly
/// covered edge pixel reads brighter than its share of light, so every edge moves towards its
/// dark side. Refined on the codes made linear through that response (`--response
/// gamma:2.2`), they are where a linear sensor puts them. Noise-free (no photon or read
/// noise, 64 spp), 8 bits, so the two sensors' codes differ only by rounding: a gamma code
/// made linear is off by at most half of its largest step, 2.2/255/2 = 0.0043 of full scale
/// (0.002 for the linear codes), and an edge of contrast 0.76 rising over about 2.5 px (the
/// pixel and the σ = 1 px blur) moves by at most (0.0043 + 0.002)·2.5/0.76 = 0.02 px if every
/// pixel across it rounded the same way. Made linear, the corners are within that of the
/// linear sensor's; as they are, they are further.
#[test]
fn gamma_codes_are_refined_where_light_is_linear() {
    let look_at =
        "look_at = { origin = [0.125, 0.0875, -0.5], target = [0.125, 0.0875, 0.0], up = [0.0, -1.0, 0.0] }";
    let steep = tilted(50.0, 30.0);
    let noiseless =
        [("read_noise = 4.0", "read_noise = 0.0\nphoton_noise = false"), (look_at, steep.as_str())];
    let (linear_codes, truth) = render_view(&noiseless, 64, true);
    let gamma = "bits = 8\nresponse = { type = \"gamma\", gamma = 2.2 }";
    let (gamma_codes, _) = render_view(&[noiseless[0], noiseless[1], ("bits = 8", gamma)], 64, true);
    let detect = |img: &Grey, response| {
        let opts = calib::detect::DetectOptions { response, ..Default::default() };
        calib::detect::detect(img, BOARD, &opts).unwrap()
    };
    let linear = detect(&linear_codes, render::sensor::Response::Linear);
    let as_they_are = detect(&gamma_codes, render::sensor::Response::Linear);
    let made_linear = detect(&gamma_codes, render::sensor::Response::Gamma { gamma: 2.2 });
    let [a, b, c] = [&linear, &as_they_are, &made_linear].map(|f| corner_rms(f, &truth));
    let (d_codes, d_linear) = (corner_rms(&as_they_are, &linear), corner_rms(&made_linear, &linear));
    eprintln!(
        "corner RMS: linear sensor {a:.4}, gamma codes {b:.4}, made linear {c:.4} px; from the linear sensor's corners: {d_codes:.4} and {d_linear:.4} px"
    );
    assert!(d_linear < 0.02, "made linear: {d_linear} px from the linear sensor's corners");
    assert!(d_codes > 0.02, "as they are: {d_codes} px from the linear sensor's corners");
}
