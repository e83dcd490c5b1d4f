//! The `calibrate` stage: renders a chessboard scene from many camera poses through the
//! scene's camera (known intrinsics and distortion) and sensor, runs the same calibration the
//! CLI runs on the images, and compares with the truth.
//!
//! Poses: view k puts the board's centre on a point of a 4×4 grid spanning 12 %–88 % of the
//! image (so boards reach the image corners, where distortion is strongest), tilted by 30°–40°
//! about an in-board axis that turns from view to view, rolled by up to ±20°, drawn from the
//! stage's seed, as close as the whole board fits in the image.
//!
//! Metrics:
//! - `views_detected`: views where the whole board was found;
//! - `corner_rms_px`: detected corners against the projected true corners;
//! - `fx_rel_err`, `fy_rel_err`: |estimate − truth| / truth;
//! - `cx_err_px`, `cy_err_px`: |estimate − truth| in pixels;
//! - `distortion_field_max_px`: the largest difference between the true and estimated
//!   distortion displacement (pixel − K·undistort(pixel), each with its own K) over every
//!   detected corner position, that is over the part of the image the boards covered;
//! - `rms_px`: the calibration's own reprojection error.

use super::report::{Better, Metric};
use super::{Common, RunOptions, StageOutput};
use crate::calib::{self, detect::BoardSize};
use crate::image::filter::Grey;
use crate::math::{CameraModel, Pose};
use crate::render::{self, sampler::Sampler};
use glam::{DMat3, DVec2, DVec3};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrateStage {
    pub case: String,
    pub seed: Option<u64>,
    #[serde(default)]
    pub bounds: BTreeMap<String, f64>,
    #[serde(default)]
    pub expected_miss: BTreeMap<String, String>,
    /// Scene file with the board (its inner corner (0, 0) at `board_origin`, in the z = 0
    /// plane), relative to the pipeline file.
    pub scene: String,
    /// Number of views (default 16).
    #[serde(default = "default_views")]
    pub views: usize,
    /// Samples per pixel (default: the scene's).
    pub spp: Option<u32>,
    /// Inner corners [cols, rows] (default [9, 6]) and square side in scene units (default 0.025).
    #[serde(default = "default_board")]
    pub board: [usize; 2],
    #[serde(default = "default_square")]
    pub square: f64,
    /// World position of inner corner 0 (default [square, square, 0]).
    pub board_origin: Option<[f64; 3]>,
    /// Whether the scene's sensor adds noise and quantises (default true); without it the
    /// linear radiance image is used.
    #[serde(default = "yes")]
    pub sensor: bool,
}

fn default_views() -> usize {
    16
}
fn default_board() -> [usize; 2] {
    [9, 6]
}
fn default_square() -> f64 {
    0.025
}
fn yes() -> bool {
    true
}

impl CalibrateStage {
    pub fn common(&self) -> Common {
        Common {
            case: self.case.clone(),
            seed: self.seed,
            bounds: self.bounds.clone(),
            expected_miss: self.expected_miss.clone(),
        }
    }
}

/// Board-to-camera poses for `n` views (see the module docs).
pub fn poses(cam: &CameraModel, board: BoardSize, square: f64, n: usize, seed: u64) -> Vec<(DMat3, DVec3)> {
    let centre =
        DVec3::new((board.cols - 1) as f64 * square / 2.0, (board.rows - 1) as f64 * square / 2.0, 0.0);
    // The board's outline: its outer squares' far corners.
    let outline = [
        (-1.0, -1.0),
        (board.cols as f64, -1.0),
        (-1.0, board.rows as f64),
        (board.cols as f64, board.rows as f64),
    ]
    .map(|(i, j)| DVec3::new(i * square, j * square, 0.0));
    let (w, h) = (cam.width as f64, cam.height as f64);
    (0..n)
        .map(|k| {
            let mut s = Sampler::new(seed ^ 0xca1b, k as u64, 0);
            let mut u = || s.next() as f64 * 2.0 - 1.0;
            let (gx, gy) = ((k % 4) as f64, ((k / 4) % 4) as f64);
            let target = DVec2::new((0.12 + 0.76 * gx / 3.0) * w, (0.12 + 0.76 * gy / 3.0) * h);
            // A strong tilt (30°–40°) constrains the focal length through foreshortening,
            // where frontal views hardly do; its axis lies in the board and turns by 3/8 of a
            // turn from view to view, so the tilts point every way.
            let phi = 2.356 * k as f64 + 0.3 * u();
            let tilt = (35.0 + 5.0 * u()).to_radians();
            let r = Pose::rotation_from_rvec(DVec3::new(0.0, 0.0, 0.35 * u()))
                * Pose::rotation_from_rvec(DVec3::new(phi.cos(), phi.sin(), 0.0) * tilt);
            let ray = cam.pixel_ray(target).unwrap_or(DVec3::Z);
            let mut dist = 0.2;
            for _ in 0..60 {
                let t = ray * dist - r * centre;
                let inside = outline.iter().all(|x| {
                    cam.project(r * *x + t)
                        .is_some_and(|p| p.x > 4.0 && p.y > 4.0 && p.x < w - 5.0 && p.y < h - 5.0)
                });
                if inside {
                    break;
                }
                dist *= 1.04;
            }
            (r, ray * dist - r * centre)
        })
        .collect()
}

/// Distortion displacement of a model at pixel p: p − K·undistort(p).
fn displacement(cam: &CameraModel, p: DVec2) -> Option<DVec2> {
    cam.undistort_pixel(p).map(|n| p - cam.normalized_to_pixel(n))
}

pub fn run(s: &CalibrateStage, dir: &Path, seed: u64, opts: &RunOptions) -> Result<StageOutput, String> {
    let mut scene = render::load(&dir.join(&s.scene)).map_err(|e| e.to_string())?;
    if s.views < 2 {
        return Err(format!("views = {}: calibration needs at least 2", s.views));
    }
    let board = BoardSize { cols: s.board[0], rows: s.board[1] };
    if board.cols < 2 || board.rows < 2 || !(s.square > 0.0) {
        return Err(format!(
            "board = {:?}, square = {}: need ≥ 2×2 corners and a positive square",
            s.board, s.square
        ));
    }
    let origin = DVec3::from_array(s.board_origin.unwrap_or([s.square, s.square, 0.0]));
    let truth = scene.camera;
    let mut settings = render::Settings::from_scene(&scene);
    settings.threads = opts.threads;
    if let Some(n) = s.spp {
        settings.spp = n.max(1);
    }
    let sensor = if s.sensor { scene.sensor.clone() } else { None };
    let board_pts = calib::board_points(board, s.square);
    let t0 = std::time::Instant::now();
    let bar = render::progress_bar(s.views as u64, "views", opts.progress);
    let mut images = Vec::new();
    let mut true_corners = Vec::new();
    for (k, (r, t)) in poses(&truth, board, s.square, s.views, seed).into_iter().enumerate() {
        // Camera from world: X_cam = R (X_world − origin) + t.
        let cam_from_world = Pose { rotation: r, translation: t - r * origin };
        scene.t_world_cam = cam_from_world.inverse();
        settings.seed = render::sampler::mix64(seed ^ (k as u64 + 1));
        let film = render::render(&scene, &settings);
        let grey = match &sensor {
            Some(sn) => {
                let codes = sn.expose(&film.mean, settings.seed);
                let max = sn.max_code() as f32;
                let data = codes
                    .chunks_exact(3)
                    .map(|c| (c[0] as f32 + c[1] as f32 + c[2] as f32) / (3.0 * max))
                    .collect();
                Grey { width: film.mean.width as usize, height: film.mean.height as usize, data }
            }
            None => Grey::from_image(&film.mean),
        };
        images.push((format!("view{k:02}"), grey));
        true_corners.push(
            board_pts
                .iter()
                .map(|x| truth.project(r * *x + t))
                .collect::<Option<Vec<_>>>()
                .ok_or("a corner is behind the camera")?,
        );
        bar.inc(1);
    }
    bar.finish_and_clear();
    let render_s = t0.elapsed().as_secs_f64();

    let config = calib::Config {
        board,
        square: s.square,
        flags: Default::default(),
        detect: Default::default(),
        max_iterations: 100,
    };
    // The CLI's path (`calib::run`), in its two steps, so the detected corners can be compared
    // with the truth without detecting twice.
    let t1 = std::time::Instant::now();
    let (views, skipped) = calib::detect_views(&images, &config).map_err(|e| e.to_string())?;
    let mut cal = calib::calibrate(&views, (truth.width, truth.height), &config)
        .map_err(|e| format!("calibration failed on the rendered views: {e}"))?;
    cal.skipped = skipped;
    let calib_s = t1.elapsed().as_secs_f64();
    let mut notes = vec![format!(
        "{} views of {}×{} corners, {}x{} px, {} spp, sensor {}.",
        s.views,
        board.cols,
        board.rows,
        truth.width,
        truth.height,
        settings.spp,
        if sensor.is_some() { "on" } else { "off" }
    )];
    let mut m = Vec::new();
    for sk in &cal.skipped {
        notes.push(format!("{} skipped: {}", sk.name, sk.reason));
    }
    m.push(Metric::new("views_detected", cal.views.len() as f64, "views", Better::Higher));
    // Detected corners against the projected true corners.
    let (mut sq, mut count) = (0.0, 0usize);
    let mut covered = Vec::new();
    for (name, found) in &views {
        let k = images.iter().position(|(n, _)| n == name).ok_or("a detected view has no image")?;
        for (a, b) in found.iter().zip(&true_corners[k]) {
            sq += a.distance_squared(*b);
            count += 1;
        }
        covered.extend(found.iter().copied());
    }
    m.push(Metric::new("corner_rms_px", (sq / count.max(1) as f64).sqrt(), "px", Better::Lower));
    let est = cal.camera();
    let (kt, ke) = (truth.intrinsics, est.intrinsics);
    m.push(Metric::new("fx_rel_err", (ke.fx - kt.fx).abs() / kt.fx, "", Better::Lower));
    m.push(Metric::new("fy_rel_err", (ke.fy - kt.fy).abs() / kt.fy, "", Better::Lower));
    m.push(Metric::new("cx_err_px", (ke.cx - kt.cx).abs(), "px", Better::Lower));
    m.push(Metric::new("cy_err_px", (ke.cy - kt.cy).abs(), "px", Better::Lower));
    let mut worst = 0.0f64;
    for p in &covered {
        match (displacement(&truth, *p), displacement(&est, *p)) {
            (Some(a), Some(b)) => worst = worst.max(a.distance(b)),
            _ => worst = f64::INFINITY,
        }
    }
    m.push(Metric::new("distortion_field_max_px", worst, "px", Better::Lower));
    m.push(Metric::new("rms_px", cal.rms_px, "px", Better::Lower));
    let sd = &cal.std_dev;
    notes.push(format!(
        "estimate (± standard deviation) fx {:.3} ± {:.3}, fy {:.3} ± {:.3}, cx {:.3} ± {:.3}, cy {:.3} ± {:.3}, d {:?}; \
         truth fx {} fy {} cx {} cy {}, d {:?}.",
        ke.fx, sd.fx, ke.fy, sd.fy, ke.cx, sd.cx, ke.cy, sd.cy,
        est.distortion.to_array().map(|v| (v * 1e5).round() / 1e5),
        kt.fx, kt.fy, kt.cx, kt.cy, truth.distortion.to_array()
    ));
    let mut timings = BTreeMap::new();
    timings.insert("render".into(), render_s);
    timings.insert("calibrate".into(), calib_s);
    Ok(StageOutput { metrics: m, timings_s: timings, notes })
}
