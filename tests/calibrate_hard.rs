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
    let mut text = std::fs::read_to_string(common::root().join("pipelines/scenes/calib-board.toml")).unwrap();
    for (a, b) in replace {
        assert!(text.contains(a), "the scene has no `{a}`");
        text = text.replace(a, b);
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene(&text, dir.path()).unwrap();
    let film = render::render(&scene, &common::settings(&scene, 16, 2));
    let sensor = scene.sensor.clone().unwrap();
    let codes = sensor.expose(&film.mean, 3);
    let max = sensor.max_code() as f32;
    let data = codes.chunks_exact(3).map(|c| c[0] as f32 / max).collect();
    let grey = Grey { width: 640, height: 480, data };
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
    assert!(e.contains("not the 9×6 board") || e.contains("fewer than"), "{e}");
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
