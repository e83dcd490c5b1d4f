//! OpenCV side by side (feature `opencv`): the same steps through OpenCV, for cross-checks and
//! benchmarks. Nothing in lumen's own stages calls this module.
//!
//! - `find_corners`: `findChessboardCorners` (default flags: adaptive threshold, normalised
//!   image) then `cornerSubPix` with an 11×11 window (`winSize` 5×5) stopping after 30
//!   iterations or a 1e-4 px step — the recipe that gives 0.195 px on OpenCV's sample
//!   photographs (its tutorial's 23×23 window gives 0.409 px);
//! - `calibrate`: `calibrateCamera` with k1, k2, p1, p2, k3 free and the stopping criteria
//!   given, returning what lumen's calibration returns.
//!
//! Corners cross the boundary as f32 (`Point2f`), which is what `calibrateCamera` takes.

use crate::math::{CameraModel, Distortion, Intrinsics};
use glam::{DVec2, DVec3};
use opencv::core::{Mat, Point2f, Point3f, Size, TermCriteria, TermCriteria_Type, Vector};
use opencv::prelude::*;

/// An OpenCV error as text (the module's callers are tests and benchmarks).
fn err(e: opencv::Error) -> String {
    format!("OpenCV: {e}")
}

/// Reads an image file as OpenCV's users do (`imread`, greyscale).
pub fn read_grey(path: &std::path::Path) -> Result<Mat, String> {
    let m = opencv::imgcodecs::imread(&path.to_string_lossy(), opencv::imgcodecs::IMREAD_GRAYSCALE)
        .map_err(err)?;
    if m.empty() {
        return Err(format!("{}: OpenCV cannot read it", path.display()));
    }
    Ok(m)
}

/// `findChessboardCorners` + `cornerSubPix` (module docs); `None` when OpenCV finds no board.
pub fn find_corners(img: &Mat, cols: usize, rows: usize) -> Result<Option<Vec<DVec2>>, String> {
    let mut corners = Vector::<Point2f>::new();
    let pattern = Size::new(cols as i32, rows as i32);
    let flags = opencv::calib3d::CALIB_CB_ADAPTIVE_THRESH | opencv::calib3d::CALIB_CB_NORMALIZE_IMAGE;
    if !opencv::calib3d::find_chessboard_corners(img, pattern, &mut corners, flags).map_err(err)? {
        return Ok(None);
    }
    let criteria =
        TermCriteria::new(TermCriteria_Type::COUNT as i32 + TermCriteria_Type::EPS as i32, 30, 1e-4)
            .map_err(err)?;
    opencv::imgproc::corner_sub_pix(img, &mut corners, Size::new(5, 5), Size::new(-1, -1), criteria)
        .map_err(err)?;
    Ok(Some(corners.iter().map(|p| DVec2::new(p.x as f64, p.y as f64)).collect()))
}

/// What `calibrateCamera` returns: the RMS reprojection error and the camera.
pub struct CvCalibration {
    pub rms_px: f64,
    pub camera: CameraModel,
}

/// `calibrateCamera` on given corners (`board`: the board points, the same for every view),
/// stopping after `max_iter` iterations or a relative change below `eps`.
pub fn calibrate(
    board: &[DVec3],
    views: &[Vec<DVec2>],
    size: (u32, u32),
    max_iter: i32,
    eps: f64,
) -> Result<CvCalibration, String> {
    let object: Vector<Point3f> =
        board.iter().map(|p| Point3f::new(p.x as f32, p.y as f32, p.z as f32)).collect();
    let mut objects = Vector::<Vector<Point3f>>::new();
    let mut images = Vector::<Vector<Point2f>>::new();
    for v in views {
        objects.push(object.clone());
        images.push(v.iter().map(|p| Point2f::new(p.x as f32, p.y as f32)).collect());
    }
    let mut k = Mat::default();
    let mut d = Mat::default();
    let mut rvecs = Vector::<Mat>::new();
    let mut tvecs = Vector::<Mat>::new();
    let criteria =
        TermCriteria::new(TermCriteria_Type::COUNT as i32 + TermCriteria_Type::EPS as i32, max_iter, eps)
            .map_err(err)?;
    let rms = opencv::calib3d::calibrate_camera(
        &objects,
        &images,
        Size::new(size.0 as i32, size.1 as i32),
        &mut k,
        &mut d,
        &mut rvecs,
        &mut tvecs,
        0,
        criteria,
    )
    .map_err(err)?;
    let at = |m: &Mat, r: i32, c: i32| m.at_2d::<f64>(r, c).copied().map_err(err);
    let dist: Vec<f64> = (0..5).map(|i| d.at::<f64>(i).copied().map_err(err)).collect::<Result<_, _>>()?;
    Ok(CvCalibration {
        rms_px: rms,
        camera: CameraModel {
            width: size.0,
            height: size.1,
            intrinsics: Intrinsics {
                fx: at(&k, 0, 0)?,
                fy: at(&k, 1, 1)?,
                cx: at(&k, 0, 2)?,
                cy: at(&k, 1, 2)?,
            },
            distortion: Distortion { k1: dist[0], k2: dist[1], p1: dist[2], p2: dist[3], k3: dist[4] },
        },
    })
}
