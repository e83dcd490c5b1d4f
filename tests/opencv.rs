//! Cross-checks against OpenCV (`cargo test --release --features opencv --test opencv`; needs
//! libopencv-dev, clang and libclang-dev). Skipped, with a printed reason, without
//! `../shared`.
#![cfg(feature = "opencv")]

mod common;

use glam::DVec2;
use lumen::calib::{self, detect::BoardSize, Config};
use lumen::cv;

const BOARD: BoardSize = BoardSize { cols: 9, rows: 6 };

/// lumen's calibration settings for these tests: unit squares, free distortion.
fn config(max_iterations: usize) -> Config {
    Config {
        board: BOARD,
        square: 1.0,
        flags: Default::default(),
        detect: Default::default(),
        max_iterations,
    }
}

/// Displacement p − K·undistort(p) of a camera model at p.
fn displacement(cam: &lumen::math::CameraModel, p: DVec2) -> DVec2 {
    p - cam.normalized_to_pixel(cam.undistort_pixel(p).unwrap())
}

/// Fed the same corners (lumen's, on OpenCV's sample photographs, as f32 since that is what
/// `calibrateCamera` takes), lumen's refinement and `calibrateCamera` with tightened stopping
/// criteria reach the same optimum: fx, fy, cx, cy within 1e-6 relative and the distortion
/// field within 1e-4 px over every corner.
#[test]
fn same_corners_same_calibration() {
    let Some(files) = common::calibration_photographs() else { return };
    let images: Vec<_> = files.iter().map(|f| (f.display().to_string(), common::grey(f))).collect();
    let config = config(1000);
    let (views, _) = calib::detect_views(&images, &config).unwrap();
    assert_eq!(views.len(), 13);
    let views: Vec<(String, Vec<DVec2>)> = views
        .into_iter()
        .map(|(n, c)| (n, c.iter().map(|p| DVec2::new(p.x as f32 as f64, p.y as f32 as f64)).collect()))
        .collect();
    let ours = calib::calibrate(&views, (640, 480), &config).unwrap().camera();
    let corners: Vec<Vec<DVec2>> = views.iter().map(|(_, c)| c.clone()).collect();
    let board = calib::board_points(BOARD, 1.0);
    let theirs = cv::calibrate(&board, &corners, (640, 480), 1000, f64::EPSILON).unwrap();
    let (a, b) = (ours.intrinsics, theirs.camera.intrinsics);
    eprintln!(
        "lumen {a:?} {:?}\nOpenCV {b:?} {:?} (RMS {})",
        ours.distortion, theirs.camera.distortion, theirs.rms_px
    );
    for (name, x, y) in [("fx", a.fx, b.fx), ("fy", a.fy, b.fy), ("cx", a.cx, b.cx), ("cy", a.cy, b.cy)] {
        assert!(((x - y) / y).abs() <= 1e-6, "{name}: lumen {x}, OpenCV {y}");
    }
    let worst = corners
        .iter()
        .flatten()
        .map(|&p| displacement(&ours, p).distance(displacement(&theirs.camera, p)))
        .fold(0.0, f64::max);
    eprintln!("distortion fields differ by at most {worst:.2e} px");
    assert!(worst <= 1e-4, "distortion fields differ by {worst} px");
}

/// lumen's detector against OpenCV's best recipe (`findChessboardCorners` + 11×11
/// `cornerSubPix`), view by view. OpenCV starts a 9×6 board at either end; lumen's order is
/// fixed, so OpenCV's corners are compared in whichever direction matches. Two detectors of
/// the same corners should differ by less than either's reprojection error (OpenCV's recipe:
/// 0.195 px RMS) on average in every view, and no corner by more than 0.5 px; and each set of
/// corners, calibrated by its own library, gives lumen the lower RMS.
#[test]
fn corners_compared_per_view() {
    let Some(files) = common::calibration_photographs() else { return };
    let mut all = Vec::new();
    let mut cv_views = Vec::new();
    for f in &files {
        let ours = calib::detect::detect(&common::grey(f), BOARD, &Default::default()).unwrap();
        let theirs = cv::find_corners(&cv::read_grey(f).unwrap(), 9, 6).unwrap();
        let theirs = theirs.unwrap_or_else(|| panic!("{}: OpenCV found no board", f.display()));
        let dist = |t: &[DVec2]| ours.iter().zip(t).map(|(a, b)| a.distance(*b)).collect::<Vec<f64>>();
        let forward = dist(&theirs);
        let reversed: Vec<DVec2> = theirs.iter().rev().copied().collect();
        let backward = dist(&reversed);
        let mean = |d: &[f64]| d.iter().sum::<f64>() / d.len() as f64;
        let (d, flipped) =
            if mean(&forward) <= mean(&backward) { (forward, false) } else { (backward, true) };
        let max = d.iter().copied().fold(0.0, f64::max);
        eprintln!(
            "{}: mean {:.3} px, max {:.3} px{}",
            f.file_name().unwrap().to_string_lossy(),
            mean(&d),
            max,
            if flipped { " (OpenCV's order reversed)" } else { "" }
        );
        assert!(mean(&d) <= 0.195 && max <= 0.5, "{}: the detectors disagree", f.display());
        all.extend(d);
        cv_views.push(theirs);
    }
    let rms = (all.iter().map(|d| d * d).sum::<f64>() / all.len() as f64).sqrt();
    eprintln!("all {} corners: RMS distance {rms:.3} px", all.len());
    let board = calib::board_points(BOARD, 1.0);
    // calibrateCamera's default criteria (30 iterations or a change below machine epsilon).
    let theirs = cv::calibrate(&board, &cv_views, (640, 480), 30, f64::EPSILON).unwrap();
    let images: Vec<_> = files.iter().map(|f| (f.display().to_string(), common::grey(f))).collect();
    let config = config(100);
    let ours = calib::run(&calib::Input { images }, &config).unwrap().calibration;
    eprintln!("RMS reprojection error: lumen {:.4} px, OpenCV {:.4} px", ours.rms_px, theirs.rms_px);
    assert!(ours.rms_px < theirs.rms_px);
}

/// OpenCV's own FileStorage reads the YAML `lumen calibrate` writes: the camera matrix and
/// distortion as matrices, and `view_names` as the sequence of image names, one per row of
/// `extrinsic_parameters`.
#[test]
fn filestorage_reads_the_calibration_yaml() {
    use opencv::core::{FileStorage, FileStorage_Mode, Mat, MatTraitConst};
    use opencv::prelude::{FileNodeTraitConst, FileStorageTraitConst};
    let Some(files) = common::calibration_photographs() else { return };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("camera.yaml");
    let pattern = files[0].parent().unwrap().join("*.jpg");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_lumen"))
        .args([
            "calibrate",
            "--images",
            pattern.to_str().unwrap(),
            "--board",
            "9x6",
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let fs = FileStorage::new(out.to_str().unwrap(), FileStorage_Mode::READ as i32, "").unwrap();
    let k: Mat = fs.get("camera_matrix").unwrap().mat().unwrap();
    assert_eq!((k.rows(), k.cols()), (3, 3));
    let ext: Mat = fs.get("extrinsic_parameters").unwrap().mat().unwrap();
    let names = fs.get("view_names").unwrap();
    assert!(names.is_seq().unwrap());
    assert_eq!(names.size().unwrap() as i32, ext.rows());
    let first = names.at(0).unwrap().to_string().unwrap();
    assert!(first.ends_with("left01.jpg"), "{first}");
}
