//! OpenCV side by side (feature `opencv`): the same steps through OpenCV, for cross-checks and
//! benchmarks. Nothing in lumen's own stages calls this module.
//!
//! - `find_corners`: `findChessboardCorners` (default flags: adaptive threshold, normalised
//!   image) then `cornerSubPix` with an 11×11 window (`winSize` 5×5) stopping after 30
//!   iterations or a 1e-4 px step — the recipe that gives 0.195 px on OpenCV's sample
//!   photographs (its tutorial's 23×23 window gives 0.409 px);
//! - `calibrate`: `calibrateCamera` with k1, k2, p1, p2, k3 free and the stopping criteria
//!   given, returning what lumen's calibration returns;
//! - `CvStack`: an exposure stack through `CalibrateDebevec`, `MergeDebevec` and `MergeMertens`,
//!   one step at a time (for `lumen bench hdr`), and `hdr_stack`: the three in turn.
//!
//! Corners cross the boundary as f32 (`Point2f`), which is what `calibrateCamera` takes.

use crate::math::{CameraModel, Distortion, Intrinsics};
use glam::{DVec2, DVec3};
use opencv::core::{Mat, Point2f, Point3f, Size, TermCriteria, TermCriteria_Type, Vector};
use opencv::prelude::*;

/// What OpenCV reported, or why its answer could not be used (the module's callers are
/// tests and benchmarks).
#[derive(Debug, thiserror::Error)]
#[error("OpenCV: {0}")]
pub struct Error(pub String);

fn err(e: opencv::Error) -> Error {
    Error(e.to_string())
}

/// Reads an image file as OpenCV's users do (`imread`, greyscale).
pub fn read_grey(path: &std::path::Path) -> Result<Mat, Error> {
    let m = opencv::imgcodecs::imread(&path.to_string_lossy(), opencv::imgcodecs::IMREAD_GRAYSCALE)
        .map_err(err)?;
    if m.empty() {
        return Err(Error(format!("{}: cannot read it", path.display())));
    }
    Ok(m)
}

/// `findChessboardCorners` + `cornerSubPix` (module docs); `None` when OpenCV finds no board.
pub fn find_corners(img: &Mat, cols: usize, rows: usize) -> Result<Option<Vec<DVec2>>, Error> {
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
) -> Result<CvCalibration, Error> {
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

/// What OpenCV's photo module makes of an exposure stack, as its users call it: frames read
/// by `imread` (8-bit BGR), times as f32 seconds. Channels are returned in RGB order.
pub struct CvHdr {
    /// `CalibrateDebevec` with its defaults (70 random samples, λ = 10): ln of its exposure
    /// per value and channel (NaN where OpenCV's value is not positive).
    pub response_ln: [Vec<f64>; 3],
    /// `MergeDebevec` of the stack through `merge_response` (ln exposure per channel and
    /// value), or through OpenCV's own curve: interleaved RGB.
    pub radiance: Vec<f32>,
    /// `MergeMertens` with Mertens et al.'s exponents (1, 1, 1; OpenCV's default exposure
    /// exponent is 0): interleaved RGB, not clipped.
    pub fusion: Vec<f32>,
    pub width: usize,
    pub height: usize,
}

/// Interleaved 3-channel f32 values of a CV_32FC3 image, BGR swapped to RGB.
fn rgb_f32(m: &Mat) -> Result<Vec<f32>, Error> {
    let data = m.data_typed::<opencv::core::Vec3f>().map_err(err)?;
    Ok(data.iter().flat_map(|p| [p[2], p[1], p[0]]).collect())
}

/// An exposure stack as OpenCV's photo module takes it: frames read by `imread` (8-bit BGR),
/// times as f32 seconds.
pub struct CvStack {
    images: Vector<Mat>,
    times: Mat,
    pub width: usize,
    pub height: usize,
}

impl CvStack {
    pub fn read(frames: &[std::path::PathBuf], times: &[f64]) -> Result<CvStack, Error> {
        let mut images = Vector::<Mat>::new();
        for p in frames {
            let m = opencv::imgcodecs::imread(&p.to_string_lossy(), opencv::imgcodecs::IMREAD_COLOR)
                .map_err(err)?;
            if m.empty() {
                return Err(Error(format!("{}: cannot read it", p.display())));
            }
            images.push(m);
        }
        let (width, height) = {
            let s = images.get(0).map_err(err)?.size().map_err(err)?;
            (s.width as usize, s.height as usize)
        };
        let t: Vec<f32> = times.iter().map(|&t| t as f32).collect();
        let times = Mat::from_slice(&t).map_err(err)?.try_clone().map_err(err)?;
        Ok(CvStack { images, times, width, height })
    }

    /// `CalibrateDebevec` with its defaults (70 random samples, λ = 10): exposure per value.
    pub fn calibrate_debevec(&self) -> Result<Mat, Error> {
        use opencv::photo::CalibrateCRFTrait;
        let mut response = Mat::default();
        opencv::photo::create_calibrate_debevec(70, 10.0, false)
            .map_err(err)?
            .process(&self.images, &mut response, &self.times)
            .map_err(err)?;
        Ok(response)
    }

    /// `MergeDebevec` through the given response (exposure per value, as OpenCV's fits give).
    pub fn merge_debevec(&self, response: &Mat) -> Result<Mat, Error> {
        use opencv::photo::MergeDebevecTrait;
        let mut radiance = Mat::default();
        opencv::photo::create_merge_debevec()
            .map_err(err)?
            .process_with_response(&self.images, &mut radiance, &self.times, response)
            .map_err(err)?;
        Ok(radiance)
    }

    /// `MergeMertens` with Mertens et al.'s exponents (1, 1, 1; OpenCV's default exposure
    /// exponent is 0).
    pub fn merge_mertens(&self) -> Result<Mat, Error> {
        use opencv::photo::MergeMertensTrait;
        let mut fusion = Mat::default();
        let mut mertens = opencv::photo::create_merge_mertens(1.0, 1.0, 1.0).map_err(err)?;
        MergeMertensTrait::process(&mut mertens, &self.images, &mut fusion).map_err(err)?;
        Ok(fusion)
    }
}

/// OpenCV's Debevec calibration, Debevec merge and Mertens fusion of the frames (`CvHdr`).
pub fn hdr_stack(
    frames: &[std::path::PathBuf],
    times: &[f64],
    merge_response: Option<&[Vec<f64>]>,
) -> Result<CvHdr, Error> {
    let stack = CvStack::read(frames, times)?;
    let (width, height) = (stack.width, stack.height);
    let response = stack.calibrate_debevec()?;
    let curve = response.data_typed::<opencv::core::Vec3f>().map_err(err)?.to_vec();
    let ln = |c: usize| -> Vec<f64> {
        curve.iter().map(|p| if p[2 - c] > 0.0 { (p[2 - c] as f64).ln() } else { f64::NAN }).collect()
    };
    let response_ln = [ln(0), ln(1), ln(2)];
    let given;
    let merge_with = match merge_response {
        Some(g) if g.len() != 3 || g.iter().any(|c| c.len() != 256) => {
            return Err(Error("the merge's response needs 3 channels of 256 values (8-bit frames)".into()));
        }
        Some(g) => {
            let values: Vec<opencv::core::Vec3f> = (0..256)
                .map(|z| {
                    opencv::core::Vec3f::from([
                        g[2][z].exp() as f32,
                        g[1][z].exp() as f32,
                        g[0][z].exp() as f32,
                    ])
                })
                .collect();
            given = Mat::from_slice(&values)
                .map_err(err)?
                .reshape(3, 256)
                .map_err(err)?
                .try_clone()
                .map_err(err)?;
            &given
        }
        None => &response,
    };
    let radiance = stack.merge_debevec(merge_with)?;
    let fusion = stack.merge_mertens()?;
    Ok(CvHdr { response_ln, radiance: rgb_f32(&radiance)?, fusion: rgb_f32(&fusion)?, width, height })
}
