//! Camera calibration from chessboard images: detection (`detect`), Zhang's closed form
//! (`zhang`), joint refinement (`refine`), and the calibration file (`file`).
//!
//! `run(&Input, &Config)` is the stage function the CLI (`lumen calibrate`) and the pipeline
//! both call: it detects the board in every view (skipping, with the reason, views without a
//! whole board), then calibrates.

pub mod detect;
pub mod file;
pub mod linear;
pub mod overlay;
pub mod refine;
pub mod undistort;
pub mod zhang;

use crate::image::filter::Grey;
use detect::{BoardSize, DetectOptions};
use glam::{DVec2, DVec3};
use refine::Flags;
use serde::{Deserialize, Serialize};

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{0}")]
    BadInput(String),
    #[error("calibration failed: {0}")]
    Numerical(String),
    /// A calibration file that was read but whose content is wrong.
    #[error("{path}: {message}")]
    File { path: std::path::PathBuf, message: String },
    /// A file that could not be read or written.
    #[error("{path}: {message}")]
    Io { path: std::path::PathBuf, message: String },
}

impl Error {
    pub fn fault(&self) -> crate::Fault {
        use crate::Fault;
        match self {
            Error::BadInput(_) | Error::File { .. } => Fault::BadInput,
            Error::Numerical(_) => Fault::Numerical,
            Error::Io { .. } => Fault::Io,
        }
    }
}

/// What to calibrate with.
#[derive(Clone, Debug)]
pub struct Config {
    pub board: BoardSize,
    /// Side of a square in the user's unit (translations come out in it).
    pub square: f64,
    pub flags: Flags,
    pub detect: DetectOptions,
    /// Levenberg–Marquardt iteration limit (default 100).
    pub max_iterations: usize,
}

/// One view's outcome.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ViewResult {
    pub name: String,
    /// Rodrigues rotation (radians) and translation (square units) of the board in the camera.
    pub rvec: [f64; 3],
    pub tvec: [f64; 3],
    pub rms_px: f64,
    /// Standard deviations of rvec and tvec.
    pub std_rvec: [f64; 3],
    pub std_tvec: [f64; 3],
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StdDev {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// k1, k2, p1, p2, k3.
    pub distortion: [f64; 5],
}

/// A calibration: what `--out` writes and what is read back wherever a camera is expected.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Calibration {
    pub image_width: u32,
    pub image_height: u32,
    /// 3×3, row-major, OpenCV pixel convention.
    pub camera_matrix: [[f64; 3]; 3],
    /// k1, k2, p1, p2, k3.
    pub distortion_coefficients: [f64; 5],
    /// √(Σ‖r‖² / corners), as OpenCV's `calibrateCamera` returns.
    pub rms_px: f64,
    pub per_view_rms_px: Vec<f64>,
    pub std_dev: StdDev,
    pub views: Vec<ViewResult>,
    /// Views left out, each with the reason.
    #[serde(default)]
    pub skipped: Vec<Skipped>,
    /// Condition numbers of the linear systems the closed form solves (`zhang` docs); written
    /// for a person, not read back.
    #[serde(skip_deserializing)]
    pub conditioning: Conditioning,
    /// Views whose board is a window of a larger complete grid of corners: the board size
    /// given is likely wrong (written for a person, not read back).
    #[serde(skip_deserializing, skip_serializing_if = "Vec::is_empty")]
    pub larger_grids: Vec<LargerGrid>,
}

/// How well the closed form's linear systems determine their solutions: σ_max / σ₂ of each
/// system (σ₂ the second-smallest singular value). Above `zhang::CONDITION_WARNING` the
/// estimate may be poor and a warning is given.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Conditioning {
    /// Zhang's system for the image of the absolute conic.
    pub zhang: f64,
    /// The worst view's normalised homography DLT, and which view.
    pub homography_worst: f64,
    pub homography_worst_view: String,
}

impl Conditioning {
    /// Warnings for the systems above `zhang::CONDITION_WARNING`.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        if !(self.zhang <= zhang::CONDITION_WARNING) {
            w.push(format!(
                "Zhang's system has condition number {:.3e} (above {:.0e}): the views barely determine the intrinsics; tilt the board more, and differently between views",
                self.zhang,
                zhang::CONDITION_WARNING
            ));
        }
        if !(self.homography_worst <= zhang::CONDITION_WARNING) {
            w.push(format!(
                "{}: its homography's system has condition number {:.3e} (above {:.0e}): the board is nearly edge-on or too small in the image",
                self.homography_worst_view,
                self.homography_worst,
                zhang::CONDITION_WARNING
            ));
        }
        w
    }
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Skipped {
    pub name: String,
    pub reason: String,
}

impl Calibration {
    /// What a person should be told: poorly conditioned systems (`Conditioning::warnings`)
    /// and a board that looks smaller than the one photographed.
    pub fn warnings(&self) -> Vec<String> {
        let mut w = self.conditioning.warnings();
        if let Some(first) = self.larger_grids.first() {
            let cols = self.larger_grids.iter().map(|g| g.cols).max().unwrap_or(first.cols);
            let rows = self.larger_grids.iter().map(|g| g.rows).max().unwrap_or(first.rows);
            w.push(format!(
                "{} of {} views ({}{}) hold a complete grid of up to {cols}×{rows} inner corners, larger than the board given: a part of it was fitted; is the board size right?",
                self.larger_grids.len(),
                self.views.len(),
                first.name,
                if self.larger_grids.len() > 1 { ", …" } else { "" }
            ));
        }
        w
    }

    pub fn camera(&self) -> crate::math::CameraModel {
        let k = &self.camera_matrix;
        crate::math::CameraModel {
            width: self.image_width,
            height: self.image_height,
            intrinsics: crate::math::Intrinsics { fx: k[0][0], fy: k[1][1], cx: k[0][2], cy: k[1][2] },
            distortion: crate::math::Distortion::from_array(self.distortion_coefficients),
        }
    }
}

/// Board corners in the board frame (Z = 0), in the order `detect` returns image corners.
pub fn board_points(board: BoardSize, square: f64) -> Vec<DVec3> {
    (0..board.rows)
        .flat_map(|j| (0..board.cols).map(move |i| DVec3::new(i as f64 * square, j as f64 * square, 0.0)))
        .collect()
}

/// Detected views (name and corners in `detect`'s order) and the views skipped, with reasons.
pub type Detections = (Vec<(String, Vec<DVec2>)>, Vec<Skipped>);

/// `Detections` and the views whose board lies inside a larger grid.
type Checked = (Vec<(String, Vec<DVec2>)>, Vec<Skipped>, Vec<LargerGrid>);

/// A view whose board is a window of a larger complete grid of corners (`detect::Found`).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct LargerGrid {
    pub name: String,
    pub cols: usize,
    pub rows: usize,
}

/// Detects the board in every image; all images must have the first one's size.
pub fn detect_views(images: &[(String, Grey)], config: &Config) -> Result<Detections, Error> {
    detect_views_checked(images, config).map(|(views, skipped, _)| (views, skipped))
}

/// `detect_views`, with the views whose board lies inside a larger grid.
fn detect_views_checked(images: &[(String, Grey)], config: &Config) -> Result<Checked, Error> {
    let Some((_, first)) = images.first() else {
        return Err(Error::BadInput("no images to calibrate from".into()));
    };
    let size = (first.width, first.height);
    if let Some((name, img)) = images.iter().find(|(_, img)| (img.width, img.height) != size) {
        return Err(Error::BadInput(format!(
            "{name} is {}×{}, the first image {}×{}: all views must come from one camera mode",
            img.width, img.height, size.0, size.1
        )));
    }
    // Views are independent: detect them in parallel, keeping the input order.
    let found: Vec<_> = {
        use rayon::prelude::*;
        images.par_iter().map(|(_, img)| detect::find(img, config.board, &config.detect)).collect()
    };
    let mut views = Vec::new();
    let mut skipped = Vec::new();
    let mut larger = Vec::new();
    for ((name, _), result) in images.iter().zip(found) {
        match result {
            Ok(found) => {
                if let Some((cols, rows)) = found.larger_grid {
                    larger.push(LargerGrid { name: name.clone(), cols, rows });
                }
                views.push((name.clone(), found.corners));
            }
            Err(reason) => skipped.push(Skipped { name: name.clone(), reason: reason.to_string() }),
        }
    }
    Ok((views, skipped, larger))
}

/// What calibration reads: named greyscale views of one camera.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Input {
    pub images: Vec<(String, Grey)>,
}

/// A calibration and the corners it was computed from.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Output {
    pub calibration: Calibration,
    /// Detected corners of every view used, in `detect`'s order (`Calibration::views`' order).
    pub corners: Vec<(String, Vec<DVec2>)>,
    /// The refinement's intrinsics at its start and after each accepted step, with the time.
    pub trace: Vec<refine::TraceStep>,
}

/// Detects the board in every image and calibrates from the views where it was found.
pub fn run(input: &Input, config: &Config) -> Result<Output, Error> {
    check_square(config.square)?;
    let (views, skipped, larger) = detect_views_checked(&input.images, config)?;
    if views.len() < 2 {
        // Why each view was left out: the user's next step depends on it.
        let why: Vec<String> = skipped.iter().take(5).map(|s| format!("{}: {}", s.name, s.reason)).collect();
        return Err(Error::BadInput(format!(
            "the board was found in {} view(s); calibration needs at least 2 (3 or more for a reliable principal point). {}{}",
            views.len(),
            why.join("; "),
            if skipped.len() > 5 { format!("; and {} more", skipped.len() - 5) } else { String::new() }
        )));
    }
    let size = input.images.first().map_or((0, 0), |(_, g)| (g.width as u32, g.height as u32));
    let (mut calibration, trace) = calibrate_traced(&views, size, config)?;
    calibration.skipped = skipped;
    calibration.larger_grids = larger;
    Ok(Output { calibration, corners: views, trace })
}

/// The side of a square, in any unit from micrometres to kilometres (in metres: 10⁻⁶ to 10³;
/// in millimetres up to 10⁶): beyond that the board's coordinates lose the precision the
/// homographies need, or overflow.
pub fn check_square(square: f64) -> Result<(), Error> {
    if square.is_finite() && (1e-6..=1e6).contains(&square) {
        Ok(())
    } else {
        Err(Error::BadInput(format!(
            "square size {square:?}: expected a length from 1e-6 to 1e6 (in the unit translations should come out in)"
        )))
    }
}

/// Calibrates from detected corners (`views`: name and corners in `detect`'s order).
pub fn calibrate(
    views: &[(String, Vec<DVec2>)],
    size: (u32, u32),
    config: &Config,
) -> Result<Calibration, Error> {
    calibrate_traced(views, size, config).map(|(c, _)| c)
}

/// `calibrate`, with the refinement's trace.
pub fn calibrate_traced(
    views: &[(String, Vec<DVec2>)],
    size: (u32, u32),
    config: &Config,
) -> Result<(Calibration, Vec<refine::TraceStep>), Error> {
    if views.len() < 2 {
        return Err(Error::BadInput(format!(
            "the board was found in {} view(s); calibration needs at least 2 (3 or more for a reliable principal point)",
            views.len()
        )));
    }
    check_square(config.square)?;
    let board = board_points(config.board, config.square);
    let plane: Vec<DVec2> = board.iter().map(|p| p.truncate()).collect();
    let mut hs = Vec::new();
    let mut conditioning = Conditioning::default();
    for (name, corners) in views {
        if corners.len() != board.len() {
            return Err(Error::BadInput(format!(
                "{name}: {} corners, the board has {}",
                corners.len(),
                board.len()
            )));
        }
        let (h, cond) = zhang::homography_conditioned(&plane, corners)
            .ok_or_else(|| Error::Numerical(format!("{name}: no homography")))?;
        if !(cond <= conditioning.homography_worst) {
            conditioning.homography_worst = cond;
            conditioning.homography_worst_view = name.clone();
        }
        hs.push(h);
    }
    let (k, zhang_cond) = zhang::intrinsics_conditioned(&hs, size)?;
    conditioning.zhang = zhang_cond;
    let mut poses = Vec::new();
    for (h, (name, _)) in hs.iter().zip(views) {
        poses.push(zhang::extrinsics(h, &k).ok_or_else(|| Error::Numerical(format!("{name}: no pose")))?);
    }
    let mut camera = crate::math::CameraModel {
        width: size.0,
        height: size.1,
        intrinsics: crate::math::Intrinsics {
            fx: k.x_axis.x,
            fy: k.y_axis.y,
            cx: k.z_axis.x,
            cy: k.z_axis.y,
        },
        distortion: Default::default(),
    };
    if config.flags.fix_principal_point {
        camera.intrinsics.cx = (size.0 as f64 - 1.0) / 2.0;
        camera.intrinsics.cy = (size.1 as f64 - 1.0) / 2.0;
    }
    let (k1, k2) = linear_radial(&camera, &poses, &board, views);
    camera.distortion.k1 = k1;
    camera.distortion.k2 = k2;
    let image: Vec<Vec<DVec2>> = views.iter().map(|(_, c)| c.clone()).collect();
    let problem = refine::Problem { board: &board, image: &image };
    let sol = refine::refine(&problem, camera, poses, config.flags, config.max_iterations)?;

    let total: f64 = sol.residuals.iter().flatten().map(|r| r.length_squared()).sum();
    let count: usize = sol.residuals.iter().map(|v| v.len()).sum();
    let per_view: Vec<f64> = sol
        .residuals
        .iter()
        .map(|v| (v.iter().map(|r| r.length_squared()).sum::<f64>() / v.len() as f64).sqrt())
        .collect();
    let c = sol.camera;
    let (ki, d) = (c.intrinsics, c.distortion);
    let s = sol.std_intrinsics;
    let out = Calibration {
        image_width: size.0,
        image_height: size.1,
        camera_matrix: [[ki.fx, 0.0, ki.cx], [0.0, ki.fy, ki.cy], [0.0, 0.0, 1.0]],
        distortion_coefficients: d.to_array(),
        rms_px: (total / count as f64).sqrt(),
        per_view_rms_px: per_view.clone(),
        std_dev: StdDev {
            fx: s[0],
            fy: s[1],
            cx: s[2],
            cy: s[3],
            distortion: [s[4], s[5], s[6], s[7], s[8]],
        },
        views: views
            .iter()
            .zip(&sol.poses)
            .zip(&sol.std_views)
            .zip(&per_view)
            .map(|((((name, _), (r, t)), sd), rms)| ViewResult {
                name: name.clone(),
                rvec: crate::math::Pose::rvec_from_rotation(r).to_array(),
                tvec: t.to_array(),
                rms_px: *rms,
                std_rvec: [sd[0], sd[1], sd[2]],
                std_tvec: [sd[3], sd[4], sd[5]],
            })
            .collect(),
        skipped: Vec::new(),
        conditioning,
        larger_grids: Vec::new(),
    };
    let finite =
        out.camera_matrix.iter().flatten().chain(&out.distortion_coefficients).all(|v| v.is_finite());
    if !finite || !out.rms_px.is_finite() {
        return Err(Error::Numerical("the refinement diverged".into()));
    }
    // A focal length known to worse than this fraction (one standard deviation) is not a
    // calibration: boards (nearly) parallel to the image plane leave it unobservable, and
    // the refinement then returns a number with an uncertainty as large as itself. Checked
    // for the residuals measured, and for corners good to 0.1 px (a sharp image and a good
    // detector), so that noise-free data from a degenerate set of views are refused too.
    const MAX_FOCAL_REL_SD: f64 = 0.1;
    let (fx, fy) = (out.camera_matrix[0][0], out.camera_matrix[1][1]);
    let u = sol.unit_std_intrinsics;
    let determined =
        |sd: f64, unit_sd: f64, f: f64| sd <= MAX_FOCAL_REL_SD * f && 0.1 * unit_sd <= MAX_FOCAL_REL_SD * f;
    if !(determined(out.std_dev.fx, u[0], fx) && determined(out.std_dev.fy, u[1], fy)) {
        return Err(Error::Numerical(format!(
            "the views do not determine the focal length (fx {fx:.1} ± {:.1}, fy {fy:.1} ± {:.1} px): the boards are (nearly) parallel to the image plane; tilt the board by 10° or more, differently between views",
            out.std_dev.fx, out.std_dev.fy
        )));
    }
    Ok((out, sol.trace))
}

/// Zhang's linear estimate of k1, k2 from the distortion-free model's residuals:
/// [(u−cx)r², (u−cx)r⁴; (v−cy)r², (v−cy)r⁴]·[k1, k2]ᵀ = [ŭ − u; v̆ − v].
fn linear_radial(
    cam: &crate::math::CameraModel,
    poses: &[(glam::DMat3, DVec3)],
    board: &[DVec3],
    views: &[(String, Vec<DVec2>)],
) -> (f64, f64) {
    let (mut a00, mut a01, mut a11, mut b0, mut b1) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let k = cam.intrinsics;
    for ((r, t), (_, obs)) in poses.iter().zip(views) {
        for (x, o) in board.iter().zip(obs) {
            let pc = *r * *x + *t;
            let (xn, yn) = (pc.x / pc.z, pc.y / pc.z);
            let r2 = xn * xn + yn * yn;
            let (u, v) = (k.fx * xn + k.cx, k.fy * yn + k.cy);
            for (row, rhs) in [
                ([(u - k.cx) * r2, (u - k.cx) * r2 * r2], o.x - u),
                ([(v - k.cy) * r2, (v - k.cy) * r2 * r2], o.y - v),
            ] {
                a00 += row[0] * row[0];
                a01 += row[0] * row[1];
                a11 += row[1] * row[1];
                b0 += row[0] * rhs;
                b1 += row[1] * rhs;
            }
        }
    }
    let det = a00 * a11 - a01 * a01;
    if det.abs() < 1e-300 {
        return (0.0, 0.0);
    }
    let (k1, k2) = ((a11 * b0 - a01 * b1) / det, (a00 * b1 - a01 * b0) / det);
    if k1.is_finite() && k2.is_finite() {
        (k1, k2)
    } else {
        (0.0, 0.0)
    }
}
