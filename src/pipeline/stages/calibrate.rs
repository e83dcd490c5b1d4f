//! The `calibrate` stage: renders a chessboard scene from many camera poses through the
//! scene's camera (known intrinsics and distortion) and sensor, runs the same calibration the
//! CLI runs on the images, and compares with the truth.
//!
//! Poses: view k puts the board's centre on a point of a 4×4 grid spanning 12 %–88 % of the
//! image (`spread`; so boards reach the image corners, where distortion is strongest), tilted
//! by 30°–40° (`tilt_deg`) from the line of sight to its centre about an in-board axis that
//! turns from view to view, rolled by up to ±20°, drawn from the stage's seed, as close as the
//! whole board fits in the image.
//!
//! The solver is `calib::run`, the function `lumen calibrate` calls, with the entry's
//! `fix_*` and `max_iterations` settings.
//!
//! Metrics:
//! - `views_detected`: views where the whole board was found; `views_missed`: the others;
//! - `corner_rms_px`: detected corners against the projected true corners;
//! - `fx_rel_err`, `fy_rel_err`: |estimate − truth| / truth;
//! - `cx_err_px`, `cy_err_px`: |estimate − truth| in pixels;
//! - `fx_err_sigmas`, `cx_err_sigmas`: |estimate − truth| over the standard deviation the
//!   calibration reports for it (a bound of 3 checks that the reported uncertainty is honest);
//! - `distortion_field_max_px`: the largest difference between the true and estimated
//!   distortion displacement (pixel − K·undistort(pixel), each with its own K) over every
//!   detected corner position, that is over the part of the image the boards covered;
//! - `rms_px`: the calibration's own reprojection error (and a note with fx's error after each
//!   step of the refinement, from its trace);
//! - `zhang_condition_number`, `homography_condition_number_max`: how well the closed form's
//!   linear systems determine their solutions (`calib::Conditioning`; warned above 10³).
//!
//! A case with `images` instead of `scene` (`DataConfig`) calibrates real photographs, every
//! image file in a folder, as `lumen calibrate` does. They have no truth: such a case reports
//! the metrics that need none (`views_detected`, `views_missed`, `rms_px`, the condition
//! numbers) and the estimate, to be bounded by a peer's figure on the same photographs. When
//! the folder is absent (no `../shared` beside a fresh clone) the case is skipped.

use super::Synthesis;
use super::{apply_overrides, Context, Findings, Kept, SettingsKey, StageError, MAX_RENDERS};
use super::{run_case, CaseResult, Settings};
use crate::calib::{self, detect::BoardSize, detect::DetectOptions};
use crate::image::{filter::Grey, Image};
use crate::math::{CameraModel, Pose, WorldToCamera};
use crate::pipeline::cache::scene_digest;
use crate::pipeline::cache::Pass;
use crate::pipeline::metric::{Better, Metric};
use crate::render::{self, sampler::Sampler, sensor::Response};
use glam::{DMat3, DVec2, DVec3};
use serde::{Deserialize, Serialize};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Scene file with the board (its inner corner (0, 0) at `board_origin`, its rows along
    /// `board_axes`), relative to the pipeline file.
    pub scene: String,
    /// Number of views (default 16, 2 to 1000). View k's pose does not depend on the count,
    /// so a sweep over `views` renders each view once.
    #[serde(default = "default_views")]
    pub views: usize,
    /// Samples per pixel (default: the scene's).
    pub spp: Option<u32>,
    /// Denoise the truth renders (before the sensor; `stages::truth_render`): `true` or the
    /// filter's settings.
    #[serde(default)]
    pub denoise: super::Denoise,
    /// Range of the board's tilt away from the line of sight to its centre, in degrees
    /// (default [30, 40]); boards centred in the image (`spread = 0`) and tilted by less than a
    /// few degrees leave the focal length unobservable, boards beyond about 80° are nearly
    /// edge-on.
    #[serde(default = "default_tilt")]
    pub tilt_deg: [f64; 2],
    /// Fraction of the image's width and height over which the views' board centres are spread
    /// (default 0.76: centres from 12 % to 88 %, so boards reach the image corners, where
    /// distortion is strongest). A board whose centre is near a corner must be small to fit;
    /// steep boards, long in one direction, are better seen with a smaller spread.
    #[serde(default = "default_spread")]
    pub spread: f64,
    /// Inner corners [cols, rows] (default [9, 6]) and square side in scene units (default 0.025).
    #[serde(default = "default_board")]
    pub board: [usize; 2],
    #[serde(default = "default_square")]
    pub square: f64,
    /// World position of inner corner 0 (default [square, square, 0]).
    pub board_origin: Option<[f64; 3]>,
    /// World directions from corner (0, 0) to corner (1, 0) and to corner (0, 1), at right
    /// angles (default [[1, 0, 0], [0, 1, 0]]: the board in a plane z = constant). The camera
    /// sees the board's face from the side opposite to their cross product.
    pub board_axes: Option<[[f64; 3]; 2]>,
    /// Whether the scene's sensor adds noise and quantises (default true); without it the
    /// linear radiance image is used.
    #[serde(default = "yes")]
    pub sensor: bool,
    /// The response the views' codes are assumed to have been written through, undone before
    /// the corners are refined (`calib::linear`), written as the scene's `[sensor]` writes one
    /// (`{ type = "gamma", gamma = 2.2 }`, `{ type = "srgb" }` …); default linear: the codes
    /// as they are, as `lumen calibrate --response`. It is the user's assumption, not the
    /// truth: a case may assume a curve the sensor does not have. Needs `sensor = true`.
    pub response: Option<Response>,
    /// The solver's settings, as `lumen calibrate`'s flags of the same names (default false).
    #[serde(default)]
    pub fix_aspect_ratio: bool,
    #[serde(default)]
    pub fix_principal_point: bool,
    #[serde(default)]
    pub zero_tangential: bool,
    #[serde(default)]
    pub fix_k3: bool,
    /// Levenberg–Marquardt iteration limit (default 100, as `lumen calibrate`).
    #[serde(default = "default_iterations")]
    pub max_iterations: usize,
    /// Keep the views the solver reads, as `<case>/viewNN.exr` (one channel: the mean code
    /// over full scale, or the radiance without a sensor; the case name with characters other
    /// than letters, digits, `-`, `_`, `.` as `_`) in the output folder, so `lumen calibrate`
    /// (with the case's response as `--response`) can be run on exactly them (default false).
    #[serde(default)]
    pub save_views: bool,
}

/// A case on real photographs (module docs).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DataConfig {
    /// Folder of photographs (every .jpg, .jpeg, .png, .tif, .tiff or .exr file in it, in name
    /// order), relative to the pipeline file.
    pub images: String,
    /// Inner corners [cols, rows] (default [9, 6]) and square side (default 0.025; the unit of
    /// the poses only).
    #[serde(default = "default_board")]
    pub board: [usize; 2],
    #[serde(default = "default_square")]
    pub square: f64,
    /// The response the photographs' codes are undone through before the corners are refined
    /// (as the synthetic case's `response`; default linear).
    pub response: Option<Response>,
}

fn default_views() -> usize {
    16
}
fn default_tilt() -> [f64; 2] {
    [30.0, 40.0]
}

fn default_spread() -> f64 {
    0.76
}

fn default_board() -> [usize; 2] {
    [9, 6]
}
fn default_square() -> f64 {
    0.025
}
fn default_iterations() -> usize {
    100
}
fn yes() -> bool {
    true
}

impl DataConfig {
    /// What `lumen calibrate --board … --square …` runs with its other flags at their defaults.
    pub fn solver(&self) -> calib::Config {
        calib::Config {
            board: BoardSize { cols: self.board[0], rows: self.board[1] },
            square: self.square,
            flags: Default::default(),
            detect: DetectOptions { response: self.response.unwrap_or_default(), ..Default::default() },
            max_iterations: default_iterations(),
        }
    }
}

impl Config {
    /// The solver's configuration: what `lumen calibrate` builds from its flags.
    pub fn solver(&self) -> calib::Config {
        calib::Config {
            board: BoardSize { cols: self.board[0], rows: self.board[1] },
            square: self.square,
            flags: calib::refine::Flags {
                fix_aspect_ratio: self.fix_aspect_ratio,
                fix_principal_point: self.fix_principal_point,
                zero_tangential: self.zero_tangential,
                fix_k3: self.fix_k3,
            },
            detect: DetectOptions { response: self.response.unwrap_or_default(), ..Default::default() },
            max_iterations: self.max_iterations,
        }
    }
}

/// What validation compares with: the scene's camera and each view's true corners.
pub struct Truth {
    camera: CameraModel,
    corners: Vec<(String, Vec<DVec2>)>,
}

/// Board-to-camera poses for `n` views (see the module docs).
pub fn poses(
    cam: &CameraModel,
    board: BoardSize,
    square: f64,
    n: usize,
    tilt_deg: [f64; 2],
    spread: f64,
    seed: u64,
) -> Vec<(DMat3, DVec3)> {
    let (tilt_mid, tilt_half) = ((tilt_deg[0] + tilt_deg[1]) / 2.0, (tilt_deg[1] - tilt_deg[0]) / 2.0);
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
            let (first, step) = (0.5 - spread / 2.0, spread / 3.0);
            let target = DVec2::new((first + step * gx) * w, (first + step * gy) * h);
            // A strong tilt (by default 30°–40°) constrains the focal length through
            // foreshortening, where frontal views hardly do; its axis lies in the board and
            // turns by 3/8 of a turn from view to view, so the tilts point every way.
            let phi = 2.356 * k as f64 + 0.3 * u();
            let tilt = (tilt_mid + tilt_half * u()).to_radians();
            let ray = cam.pixel_ray(target).unwrap_or(DVec3::Z);
            // The tilt is measured from the line of sight to the board's centre, not from the
            // optical axis: a board 70° from the axis at an image corner, where the line of
            // sight is itself 30° off the axis, would be seen edge-on or from behind.
            let across = DVec3::Z.cross(ray);
            let to_sight = if across.length() > 0.0 {
                Pose::rotation_from_rvec(across.normalize() * across.length().atan2(ray.z))
            } else {
                DMat3::IDENTITY
            };
            let r = to_sight
                * Pose::rotation_from_rvec(DVec3::new(0.0, 0.0, 0.35 * u()))
                * Pose::rotation_from_rvec(DVec3::new(phi.cos(), phi.sin(), 0.0) * tilt);
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

/// The board's frame in the world (`Config::board_axes`): its columns the directions to the
/// next corner along a row, down a column, and their cross product.
fn board_axes(axes: Option<[[f64; 3]; 2]>) -> Result<DMat3, StageError> {
    let Some([u, v]) = axes else { return Ok(DMat3::IDENTITY) };
    let [du, dv] = [u, v].map(DVec3::from_array);
    let (nu, nv) = (du.try_normalize(), dv.try_normalize());
    match (nu, nv) {
        (Some(a), Some(b)) if a.dot(b).abs() < 1e-9 => Ok(DMat3::from_cols(a, b, a.cross(b))),
        _ => Err(StageError::Config(format!(
            "board_axes = {axes:?}: expected two finite, nonzero directions at right angles",
            axes = [u, v]
        ))),
    }
}

/// A case's `response`, validated (default linear).
fn checked_response(r: Option<Response>) -> Result<Response, StageError> {
    let r = r.unwrap_or_default();
    r.validate().map_err(|e| StageError::Config(format!("response: {e}")))?;
    Ok(r)
}

/// Distortion displacement of a model at pixel p: p − K·undistort(p).
fn displacement(cam: &CameraModel, p: DVec2) -> Option<DVec2> {
    cam.undistort_pixel(p).map(|n| p - cam.normalized_to_pixel(n))
}

/// One view's render, as the cache keys it.
#[derive(Serialize)]
struct ViewRecipe<'a> {
    product: &'static str,
    scene: &'a str,
    t_world_cam: [f64; 12],
    settings: SettingsKey,
    sensor: bool,
}

pub fn synthesize(c: &Config, ctx: &Context) -> Result<Synthesis<calib::Input, Truth>, StageError> {
    let scene_path = ctx.dir.join(&c.scene);
    let mut scene = render::load(&scene_path)?;
    let digest = scene_digest(&scene_path)?;
    if !(2..=MAX_RENDERS).contains(&c.views) {
        return Err(StageError::Config(format!(
            "views = {}: expected 2 to {MAX_RENDERS} (calibration needs at least 2; each is a render)",
            c.views
        )));
    }
    let board = BoardSize { cols: c.board[0], rows: c.board[1] };
    if board.cols < 2 || board.rows < 2 || !(c.square.is_finite() && c.square > 0.0) {
        return Err(StageError::Config(format!(
            "board = {:?}, square = {}: need ≥ 2×2 corners and a finite positive square",
            c.board, c.square
        )));
    }
    if !c.tilt_deg.iter().all(|t| (0.0..=89.0).contains(t)) || c.tilt_deg[0] > c.tilt_deg[1] {
        return Err(StageError::Config(format!(
            "tilt_deg = {:?}: expected [lowest, highest] within 0° to 89°",
            c.tilt_deg
        )));
    }
    if !(0.0..=0.9).contains(&c.spread) {
        return Err(StageError::Config(format!(
            "spread = {}: expected a fraction of the image from 0 to 0.9",
            c.spread
        )));
    }
    let origin = DVec3::from_array(c.board_origin.unwrap_or([c.square, c.square, 0.0]));
    if !origin.is_finite() {
        return Err(StageError::Config(format!("board_origin = {origin}: expected finite numbers")));
    }
    let axes = board_axes(c.board_axes)?;
    let camera = scene.camera;
    let mut settings = render::Settings::from_scene(&scene);
    apply_overrides(&mut settings, c.spp, None)?;
    let sensor = if c.sensor { scene.sensor.clone() } else { None };
    let response = checked_response(c.response)?;
    if sensor.is_none() && response != Response::Linear {
        return Err(StageError::Config(format!(
            "response = {response:?}: the views are linear radiance without a sensor (sensor = false, or no [sensor] in {}); a response applies to code values",
            c.scene
        )));
    }
    let board_pts = calib::board_points(board, c.square);
    let bar = render::progress_bar(c.views as u64, &format!("{} views", ctx.case), ctx.progress);
    let mut images = Vec::new();
    let mut corners = Vec::new();
    for (k, (r, t)) in
        poses(&camera, board, c.square, c.views, c.tilt_deg, c.spread, ctx.seed).into_iter().enumerate()
    {
        let name = format!("view{k:02}");
        let true_corners = board_pts.iter().map(|x| camera.project(r * *x + t)).collect::<Option<Vec<_>>>();
        let Some(true_corners) = true_corners else {
            return Err(StageError::Config(format!(
                "{name}: a board corner falls behind the camera (square = {} may not suit the scene)",
                c.square
            )));
        };
        // Camera from world: X_cam = R Bᵀ (X_world − origin) + t, B the board's axes.
        let rotation = r * axes.transpose();
        let cam_from_world = WorldToCamera(Pose { rotation, translation: t - rotation * origin });
        scene.t_world_cam = cam_from_world.inverse();
        settings.seed = render::sampler::mix64(ctx.seed ^ (k as u64 + 1));
        let pose = super::pose_key(&scene.t_world_cam);
        let recipe = ViewRecipe {
            product: "calibrate-grey",
            scene: &digest,
            t_world_cam: pose,
            settings: SettingsKey::denoised(&settings, &c.denoise),
            sensor: sensor.is_some(),
        };
        let grey = ctx.cache.images(ctx.case, &name, &recipe, || {
            let radiance = super::truth_render(&scene, &settings, &c.denoise)?;
            let grey = match &sensor {
                Some(sn) => {
                    let codes = sn.expose(&radiance, settings.seed);
                    let max = sn.max_code() as f32;
                    codes
                        .chunks_exact(3)
                        .map(|c| (c[0] as f32 + c[1] as f32 + c[2] as f32) / (3.0 * max))
                        .collect()
                }
                None => Grey::from_image(&radiance).data,
            };
            Ok::<_, StageError>(vec![Image {
                width: camera.width,
                height: camera.height,
                channels: 1,
                data: grey,
            }])
        })?;
        let Some(mut grey) = grey else { continue };
        let img =
            grey.pop().filter(|g| g.channels == 1 && g.data.len() == (camera.width * camera.height) as usize);
        let img =
            img.ok_or_else(|| StageError::Config(format!("{name}: the cached render has the wrong size")))?;
        images.push((
            name.clone(),
            Grey { width: img.width as usize, height: img.height as usize, data: img.data },
        ));
        corners.push((name, true_corners));
        bar.inc(1);
    }
    bar.finish_and_clear();
    if ctx.renders_only() {
        return Ok(None);
    }
    let mut found = Findings::default();
    if c.save_views {
        for (name, g) in &images {
            let img =
                Image { width: g.width as u32, height: g.height as u32, channels: 1, data: g.data.clone() };
            let folder = crate::pipeline::names::file_stem(ctx.case);
            found.files.push((std::path::Path::new(&folder).join(format!("{name}.exr")), Kept::Image(img)));
        }
    }
    found.notes.push(format!(
        "{} views of {}×{} corners, {}x{} px, {} spp, sensor {}.",
        c.views,
        board.cols,
        board.rows,
        camera.width,
        camera.height,
        settings.spp,
        match (&sensor, response) {
            (None, _) => "off".to_string(),
            (Some(_), Response::Linear) => "on, corners refined on the codes as they are".to_string(),
            (Some(_), r) => format!("on, corners refined on the codes made linear through the assumed {r:?}"),
        }
    ));
    found.notes.extend(super::denoise_note(&c.denoise, settings.spp));
    Ok(Some((calib::Input { images }, Truth { camera, corners }, found)))
}

pub fn solve(c: &Config, input: &calib::Input) -> Result<calib::Output, StageError> {
    Ok(calib::run(input, &c.solver())?)
}

/// Image files a photograph folder holds, by extension.
const PHOTO_EXTENSIONS: [&str; 6] = ["jpg", "jpeg", "png", "tif", "tiff", "exr"];

/// Reads the photographs of a `DataConfig` case, named by file name.
pub fn read(c: &DataConfig, ctx: &Context) -> Result<(calib::Input, (), Findings), StageError> {
    let board = BoardSize { cols: c.board[0], rows: c.board[1] };
    if board.cols < 2 || board.rows < 2 || !(c.square.is_finite() && c.square > 0.0) {
        return Err(StageError::Config(format!(
            "board = {:?}, square = {}: need ≥ 2×2 corners and a finite positive square",
            c.board, c.square
        )));
    }
    let response = checked_response(c.response)?;
    let dir = super::dataset_path(ctx, &c.images)?;
    let files = crate::image::io::files_with_extensions(&dir, &PHOTO_EXTENSIONS)
        .map_err(|e| StageError::Config(format!("images = \"{}\": {}: {e}", c.images, dir.display())))?;
    if files.len() < 2 {
        return Err(StageError::Config(format!(
            "images = \"{}\": {} holds {} image file(s) ({}); calibration needs at least 2",
            c.images,
            dir.display(),
            files.len(),
            PHOTO_EXTENSIONS.join(", ")
        )));
    }
    let mut images = Vec::new();
    for f in &files {
        calib::linear::check_codes(f, &response).map_err(|e| StageError::Config(format!("response: {e}")))?;
        let img = crate::image::io::read(f)?;
        let name = f.file_name().map_or_else(|| f.display().to_string(), |n| n.to_string_lossy().into());
        images.push((name, Grey::from_image(&img)));
    }
    let mut found = Findings::default();
    found.notes.push(format!(
        "Real data: {} photographs in {}, {}×{} corners; no truth, so only the metrics that need none.",
        images.len(),
        dir.display(),
        board.cols,
        board.rows
    ));
    Ok((calib::Input { images }, (), found))
}

pub fn solve_data(c: &DataConfig, input: &calib::Input) -> Result<calib::Output, StageError> {
    Ok(calib::run(input, &c.solver())?)
}

/// The metrics of a calibration that need no truth, and the estimate as a note.
pub fn validate_data(out: &calib::Output, _truth: &()) -> Findings {
    let cal = &out.calibration;
    let mut f = Findings::default();
    views_found(cal, &mut f);
    fit_quality(cal, &mut f);
    f.notes.push(format!("{}.", estimate(cal)));
    f
}

/// Why views were skipped (notes), `views_detected` and `views_missed`.
fn views_found(cal: &calib::Calibration, f: &mut Findings) {
    for sk in &cal.skipped {
        f.notes.push(format!("{} skipped: {}", sk.name, sk.reason));
    }
    f.metrics.push(Metric::new("views_detected", cal.views.len() as f64, "views", Better::Higher));
    f.metrics.push(Metric::new("views_missed", cal.skipped.len() as f64, "views", Better::Lower));
}

/// `rms_px` and the closed form's condition numbers, with their warnings as notes.
fn fit_quality(cal: &calib::Calibration, f: &mut Findings) {
    let m = &mut f.metrics;
    m.push(Metric::new("rms_px", cal.rms_px, "px", Better::Lower));
    m.push(Metric::new("zhang_condition_number", cal.conditioning.zhang, "", Better::Lower));
    m.push(Metric::new(
        "homography_condition_number_max",
        cal.conditioning.homography_worst,
        "",
        Better::Lower,
    ));
    for w in cal.warnings() {
        f.notes.push(format!("warning: {w}"));
    }
}

/// The estimate with its standard deviations, for a note.
fn estimate(cal: &calib::Calibration) -> String {
    let (cam, sd) = (cal.camera(), &cal.std_dev);
    let k = cam.intrinsics;
    format!(
        "estimate (± standard deviation) fx {:.3} ± {:.3}, fy {:.3} ± {:.3}, cx {:.3} ± {:.3}, cy {:.3} ± {:.3}, d {:?}",
        k.fx, sd.fx, k.fy, sd.fy, k.cx, sd.cx, k.cy, sd.cy,
        cam.distortion.to_array().map(|v| (v * 1e5).round() / 1e5),
    )
}

pub fn validate(_c: &Config, out: &calib::Output, truth: &Truth) -> Findings {
    let cal = &out.calibration;
    let mut f = Findings::default();
    views_found(cal, &mut f);
    let m = &mut f.metrics;
    // Detected corners against the projected true corners.
    let (mut sq, mut count) = (0.0, 0usize);
    for (name, found) in &out.corners {
        if let Some((_, true_corners)) = truth.corners.iter().find(|(n, _)| n == name) {
            for (a, b) in found.iter().zip(true_corners) {
                sq += a.distance_squared(*b);
                count += 1;
            }
        }
    }
    let rms = (count > 0).then(|| (sq / count as f64).sqrt());
    m.push(Metric::maybe("corner_rms_px", rms, "px", Better::Lower, "no corner was detected"));
    let est = cal.camera();
    let (kt, ke) = (truth.camera.intrinsics, est.intrinsics);
    m.push(Metric::new("fx_rel_err", (ke.fx - kt.fx).abs() / kt.fx, "", Better::Lower));
    m.push(Metric::new("fy_rel_err", (ke.fy - kt.fy).abs() / kt.fy, "", Better::Lower));
    m.push(Metric::new("cx_err_px", (ke.cx - kt.cx).abs(), "px", Better::Lower));
    m.push(Metric::new("cy_err_px", (ke.cy - kt.cy).abs(), "px", Better::Lower));
    // The error in units of the standard deviation the solver itself reports: with an honest
    // covariance, beyond 3 happens 0.3 % of the time.
    let sd = &cal.std_dev;
    let sigmas = |err: f64, sd: f64| if sd > 0.0 { err / sd } else { f64::INFINITY };
    m.push(Metric::new("fx_err_sigmas", sigmas((ke.fx - kt.fx).abs(), sd.fx), "σ", Better::Lower));
    m.push(Metric::new("cx_err_sigmas", sigmas((ke.cx - kt.cx).abs(), sd.cx), "σ", Better::Lower));
    // Over every detected corner position, that is over the part of the image the boards covered.
    let mut worst = Some(0.0f64);
    for p in out.corners.iter().flat_map(|(_, c)| c) {
        worst = match (worst, displacement(&truth.camera, *p), displacement(&est, *p)) {
            (Some(w), Some(a), Some(b)) => Some(w.max(a.distance(b))),
            _ => None,
        };
    }
    m.push(Metric::maybe(
        "distortion_field_max_px",
        worst,
        "px",
        Better::Lower,
        "a detected corner lies where a distortion model cannot be inverted",
    ));
    fit_quality(cal, &mut f);
    let kt = truth.camera.intrinsics;
    if out.trace.len() > 1 {
        let shown: Vec<String> = out
            .trace
            .iter()
            .enumerate()
            .filter(|&(k, _)| k <= 4 || k.is_power_of_two() || k + 1 == out.trace.len())
            .map(|(_, t)| {
                format!(
                    "{}: {:.3e} ({:.3} s)",
                    t.iteration,
                    (t.intrinsics[0] - kt.fx).abs() / kt.fx,
                    t.seconds
                )
            })
            .collect();
        f.notes.push(format!(
            "fx relative error after k Levenberg–Marquardt steps (k = 0: Zhang's closed form): {}.",
            shown.join(", ")
        ));
    }
    f.notes.push(format!(
        "{}; truth fx {} fy {} cx {} cy {}, d {:?}.",
        estimate(cal),
        kt.fx,
        kt.fy,
        kt.cx,
        kt.cy,
        truth.camera.distortion.to_array()
    ));
    f
}

impl Settings for Config {
    fn headline(&self) -> &'static str {
        "fx_rel_err"
    }
    fn run(&self, ctx: &Context) -> Result<CaseResult, StageError> {
        super::run_case_exporting(
            || synthesize(self, ctx),
            |i| solve(self, i),
            |o, t| validate(self, o, t),
            |o, t| super::Exports { camera: Some((o.calibration.camera(), t.camera)), ..Default::default() },
        )
    }
    fn share(&self, ctx: &Context, pass: Pass) -> Option<Result<(), StageError>> {
        (pass == Pass::Renders).then(|| synthesize(self, ctx).map(|_| ()))
    }
    fn provides(&self) -> &'static [&'static str] {
        &["camera"]
    }
}

impl Settings for DataConfig {
    fn headline(&self) -> &'static str {
        "rms_px"
    }
    fn run(&self, ctx: &Context) -> Result<CaseResult, StageError> {
        run_case(|| read(self, ctx).map(Some), |i| solve_data(self, i), validate_data)
    }
}
