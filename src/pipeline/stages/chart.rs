//! The `chart` stage: finding the colour chart by itself (`color::detect`, the function
//! `lumen color detect` and `lumen color fit` without `--corners` call).
//!
//! On renders (`Config`): the colour stage's chart scene seen from `views` random poses, each
//! drawn from the case's seed: the chart turned by any angle in the frame, tilted 0–60° out of
//! plane (`tilt_deg`), its width a share of the image's (`share`, 5–80 %) as seen square-on,
//! moved off centre, and stepped back until the whole card is in the frame. Each view goes
//! through the scene's sensor (photon and read noise, quantisation) and the detector gets the
//! raw values as linear data. The truth is the cell grid's corners projected through the
//! camera.
//!
//! Metrics: `detection_rate` (views found, the right way round), `views_missed`,
//! `corner_error_px_max` and `corner_error_px_median` over the found views (the worst of a
//! view's four corners), `detect_s_median` (one view's detection).
//!
//! On photographs (`PhotoConfig`, `photos` instead of `scene`): every photograph in a folder,
//! with hand-checked corners in a CSV (`image,x1,y1,…,x4,y4`). Each is detected, sampled as
//! `lumen color fit` samples it (sRGB-decoded) and fitted with `model` against the chart's
//! published values; the report gives per photograph the corner error as a share of the
//! chart's diagonal and the fit's leave-one-out mean ΔE2000, with a peer's figure on the same
//! sampled values beside it (`peer`: colour-science's). Those ΔE measure the phone's
//! rendering of the colours (its tone curve and saturation), not a linear camera: the JPEGs
//! are not raw data.

use super::{apply_overrides, dataset_path, run_case, CaseResult, Context, Findings, Settings, SettingsKey};
use super::{StageError, Synthesis, MAX_RENDERS};
use crate::color::{self, detect};
use crate::image::Image;
use crate::math::{CameraModel, CameraToWorld};
use crate::pipeline::cache::{scene_digest, Pass};
use crate::pipeline::metric::{Better, Metric};
use crate::render;
use glam::DVec3;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// The chart scene (materials `patch-01` … `patch-24` on quads, as the colour stage's),
    /// relative to the pipeline file. Its camera's size and focal length are replaced by
    /// `image` and `focal_px`; its sensor is kept.
    pub scene: String,
    /// Number of views (default 8, 1 to 1000).
    #[serde(default = "default_views")]
    pub views: usize,
    /// The chart's width as a share of the image's when seen square-on, [smallest, largest]
    /// (default [0.05, 0.8]).
    #[serde(default = "default_share")]
    pub share: [f64; 2],
    /// Tilt away from the line of sight, degrees [lowest, highest] (default [0, 60]).
    #[serde(default = "default_tilt")]
    pub tilt_deg: [f64; 2],
    /// Image size in pixels (default [960, 720]) and focal length in pixels (default 1100).
    #[serde(default = "default_image")]
    pub image: [u32; 2],
    #[serde(default = "default_focal")]
    pub focal_px: f64,
    /// Samples per pixel (default: the scene's).
    pub spp: Option<u32>,
}

fn default_views() -> usize {
    8
}
fn default_share() -> [f64; 2] {
    [0.05, 0.8]
}
fn default_tilt() -> [f64; 2] {
    [0.0, 60.0]
}
fn default_image() -> [u32; 2] {
    [960, 720]
}
fn default_focal() -> f64 {
    1100.0
}

/// A case on photographs (module docs).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhotoConfig {
    /// Folder of chart photographs (.jpg, .jpeg, .png, .tif, .tiff), relative to the pipeline file.
    pub photos: String,
    /// CSV of hand-checked corners: `image,x1,y1,x2,y2,x3,y3,x4,y4`, one line per photograph.
    pub truth: String,
    /// The colour model fitted on each photograph (default root-poly-2).
    #[serde(default = "default_model")]
    pub model: String,
    /// A peer's leave-one-out mean ΔE2000 on the same sampled values, shown beside lumen's: CSV
    /// `image,model,loo_mean_de2000` (`#` comments), as `tools/color_vs_colour_science.py
    /// --photos … --csv` writes colour-science's. For a model the peer lacks, its best.
    pub peer: Option<String>,
}

fn default_model() -> String {
    "root-poly-2".into()
}

/// One view of the chart: where the camera is.
#[derive(Clone, Copy, Debug)]
pub struct ChartView {
    /// Turn of the chart in the frame (degrees), tilt out of plane (degrees), width share.
    pub turn_deg: f64,
    pub tilt_deg: f64,
    pub share: f64,
    /// Shift of the chart's centre from the image's, as a share of the room left (−1 to 1).
    pub shift: [f64; 2],
}

/// The chart's cell grid in the world: its corner (0, 0), one cell's steps along a row and
/// down a column, and the normal the patches face away from (the camera sits on −normal).
#[derive(Clone, Copy, Debug)]
pub struct Grid {
    pub origin: DVec3,
    pub step_u: DVec3,
    pub step_v: DVec3,
    pub normal: DVec3,
}

impl Grid {
    pub fn point(&self, u: f64, v: f64) -> DVec3 {
        self.origin + u * self.step_u + v * self.step_v
    }
}

/// A camera seeing the chart as `view` says, stepped back until the chart and a margin of 0.3
/// cells around it (the card) are inside the image, 3 px from its edges.
pub fn camera_for(camera: &CameraModel, grid: &Grid, view: &ChartView) -> CameraToWorld {
    let centre = grid.point(3.0, 2.0);
    let (eu, ev) = (grid.step_u.normalize(), grid.step_v.normalize());
    let f = camera.intrinsics.fx;
    let width = 6.0 * grid.step_u.length();
    let (t, a) = (view.tilt_deg.to_radians(), (view.turn_deg + 37.0).to_radians());
    let dir = t.sin() * (a.cos() * eu + a.sin() * ev) - t.cos() * grid.normal;
    let turn = view.turn_deg.to_radians();
    let up = turn.sin() * eu - turn.cos() * ev;
    let mut d = width * f / (view.share * camera.width as f64);
    let (w, h) = (camera.width as f64, camera.height as f64);
    loop {
        let eye = centre + d * dir;
        let room = (1.0 - view.share).max(0.0) * 0.5 * d * w / f;
        let pose = CameraToWorld::look_at(eye, centre, up).and_then(|base| {
            let (x, y) = (base.0.rotation.col(0), base.0.rotation.col(1));
            let target = centre + 0.8 * room * (view.shift[0] * x + view.shift[1] * (h / w) * y);
            CameraToWorld::look_at(eye, target, up)
        });
        if let Some(pose) = pose {
            let to_cam = pose.inverse();
            let card = [(-0.3, -0.3), (6.3, -0.3), (6.3, 4.3), (-0.3, 4.3)];
            let inside = card.iter().all(|&(u, v)| {
                camera
                    .project(to_cam.0.transform_point(grid.point(u, v)))
                    .is_some_and(|p| p.x > 3.0 && p.y > 3.0 && p.x < w - 4.0 && p.y < h - 4.0)
            });
            if inside || d > 1e6 {
                return pose;
            }
        }
        d *= 1.05;
    }
}

/// The views of a case, drawn from its seed; view k does not depend on the count.
pub fn views(c: &Config, seed: u64) -> Vec<ChartView> {
    (0..c.views)
        .map(|k| {
            let mut rng = rand_pcg::Pcg64::seed_from_u64(render::sampler::mix64(seed ^ (k as u64 + 1)));
            let mut u = || rng.gen::<f64>();
            ChartView {
                turn_deg: 360.0 * u(),
                tilt_deg: c.tilt_deg[0] + (c.tilt_deg[1] - c.tilt_deg[0]) * u(),
                share: c.share[0] + (c.share[1] - c.share[0]) * u(),
                shift: [2.0 * u() - 1.0, 2.0 * u() - 1.0],
            }
        })
        .collect()
}

/// One view's render, as the cache keys it.
#[derive(Serialize)]
struct ViewRecipe<'a> {
    product: &'static str,
    scene: &'a str,
    image: [u32; 2],
    focal_px: f64,
    t_world_cam: [f64; 12],
    settings: SettingsKey,
}

pub struct Truth {
    corners: Vec<[[f64; 2]; 4]>,
    views: Vec<ChartView>,
}

pub fn synthesize(c: &Config, ctx: &Context) -> Result<Synthesis<Vec<Image>, Truth>, StageError> {
    if !(1..=MAX_RENDERS).contains(&c.views) {
        return Err(StageError::Config(format!("views = {}: expected 1 to {MAX_RENDERS}", c.views)));
    }
    if !(c.share.iter().all(|s| (0.01..=0.95).contains(s)) && c.share[0] <= c.share[1]) {
        return Err(StageError::Config(format!(
            "share = {:?}: expected [smallest, largest] within 0.01 to 0.95",
            c.share
        )));
    }
    if !(c.tilt_deg.iter().all(|t| (0.0..=80.0).contains(t)) && c.tilt_deg[0] <= c.tilt_deg[1]) {
        return Err(StageError::Config(format!(
            "tilt_deg = {:?}: expected [lowest, highest] within 0° to 80°",
            c.tilt_deg
        )));
    }
    if !(c.image.iter().all(|&s| (48..=8192).contains(&s)) && c.focal_px.is_finite() && c.focal_px > 0.0) {
        return Err(StageError::Config(format!(
            "image = {:?}, focal_px = {}: expected sides of 48 to 8192 px and a positive focal length",
            c.image, c.focal_px
        )));
    }
    let scene_path = ctx.dir.join(&c.scene);
    let mut scene = render::load(&scene_path)?;
    let digest = scene_digest(&scene_path)?;
    let (origin, step_u, step_v, normal) = super::color::chart_grid(&scene_path)?;
    let grid = Grid { origin, step_u, step_v, normal };
    scene.camera = CameraModel::centred(c.image[0], c.image[1], c.focal_px);
    let mut settings = render::Settings::from_scene(&scene);
    apply_overrides(&mut settings, c.spp, None)?;
    let views = views(c, ctx.seed);
    let bar = render::progress_bar(c.views as u64, &format!("{} views", ctx.case), ctx.progress);
    let (mut images, mut corners) = (Vec::new(), Vec::new());
    for (k, view) in views.iter().enumerate() {
        scene.t_world_cam = camera_for(&scene.camera, &grid, view);
        settings.seed = render::sampler::mix64(ctx.seed ^ (k as u64 + 1));
        let pose = super::pose_key(&scene.t_world_cam);
        let recipe = ViewRecipe {
            product: "chart-view",
            scene: &digest,
            image: c.image,
            focal_px: c.focal_px,
            t_world_cam: pose,
            settings: SettingsKey::from(&settings),
        };
        let made = ctx.cache.images(ctx.case, &format!("view{k:02}"), &recipe, || {
            let radiance = render::try_render(&scene, &settings)?.mean;
            Ok::<_, StageError>(vec![match &scene.sensor {
                Some(sn) => {
                    let codes = sn.expose(&radiance, settings.seed);
                    let max = sn.max_code() as f32;
                    Image { data: codes.iter().map(|&v| v as f32 / max).collect(), ..radiance }
                }
                None => radiance,
            }])
        })?;
        bar.inc(1);
        let Some(mut made) = made else { continue };
        let image = made.pop().filter(|i| i.channels == 3 && i.width == c.image[0] && i.height == c.image[1]);
        let image = image
            .ok_or_else(|| StageError::Config(format!("view {k}: the cached render has the wrong size")))?;
        let to_cam = scene.t_world_cam.inverse();
        let mut truth = [[0.0; 2]; 4];
        for (i, (u, v)) in [(0.0, 0.0), (6.0, 0.0), (6.0, 4.0), (0.0, 4.0)].into_iter().enumerate() {
            let q = scene.camera.project(to_cam.0.transform_point(grid.point(u, v))).ok_or_else(|| {
                StageError::Config(format!("view {k}: a chart corner falls behind the camera"))
            })?;
            truth[i] = [q.x, q.y];
        }
        images.push(image);
        corners.push(truth);
    }
    bar.finish_and_clear();
    if ctx.renders_only() {
        return Ok(None);
    }
    let note = format!(
        "{} views of {} at {}×{} px (f = {} px), {} spp through the scene's sensor: chart width {:.0}–{:.0} % of the image seen square-on, tilt {:.0}°–{:.0}°, any turn in the frame.",
        c.views, c.scene, c.image[0], c.image[1], c.focal_px, settings.spp,
        100.0 * c.share[0], 100.0 * c.share[1], c.tilt_deg[0], c.tilt_deg[1]
    );
    Ok(Some((images, Truth { corners, views }, Findings { notes: vec![note], ..Default::default() })))
}

/// Each view's detection (or why not) and its time.
pub type Detections = Vec<(Result<detect::Detection, crate::error::Invalid>, f64)>;

pub fn solve(images: &[Image]) -> Detections {
    images
        .iter()
        .map(|img| {
            let t = std::time::Instant::now();
            let d = detect::detect(img, true);
            (d, t.elapsed().as_secs_f64())
        })
        .collect()
}

fn worst_corner(a: &[[f64; 2]; 4], b: &[[f64; 2]; 4]) -> f64 {
    a.iter().zip(b).map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1])).fold(0.0, f64::max)
}

pub fn validate(out: &Detections, truth: &Truth) -> Findings {
    let mut f = Findings::default();
    let mut errors = Vec::new();
    let mut times: Vec<f64> = out.iter().map(|(_, t)| *t).collect();
    for (k, ((d, _), (corners, view))) in out.iter().zip(truth.corners.iter().zip(&truth.views)).enumerate() {
        let pose = format!(
            "turn {:.0}°, tilt {:.0}°, width {:.0} %",
            view.turn_deg,
            view.tilt_deg,
            100.0 * view.share
        );
        match d {
            Ok(d) => {
                let e = worst_corner(&d.corners, corners);
                errors.push(e);
                if e > 2.0 {
                    f.notes.push(format!("view {k} ({pose}): found, but a corner {e:.1} px from the truth."));
                }
            }
            Err(e) => f.notes.push(format!("view {k} ({pose}): {e}")),
        }
    }
    let n = out.len().max(1) as f64;
    // A view counts as found when its corners are within 2 px: a chart found the wrong way
    // round has corners a whole chart width away.
    let found = errors.iter().filter(|&&e| e <= 2.0).count();
    let m = &mut f.metrics;
    m.push(Metric::new("detection_rate", found as f64 / n, "", Better::Higher));
    m.push(Metric::new("views_missed", (out.len() - found) as f64, "views", Better::Lower));
    let max = errors.iter().copied().reduce(f64::max);
    m.push(Metric::maybe("corner_error_px_max", max, "px", Better::Lower, "no view found"));
    m.push(Metric::maybe(
        "corner_error_px_median",
        crate::math::stats::median(&mut errors),
        "px",
        Better::Lower,
        "no view found",
    ));
    m.push(Metric::maybe(
        "detect_s_median",
        crate::math::stats::median(&mut times),
        "s",
        Better::Lower,
        "no view",
    ));
    f
}

impl Settings for Config {
    fn headline(&self) -> &'static str {
        "corner_error_px_max"
    }
    fn run(&self, ctx: &Context) -> Result<CaseResult, StageError> {
        run_case(|| synthesize(self, ctx), |i| Ok(solve(i)), validate)
    }
    fn share(&self, ctx: &Context, pass: Pass) -> Option<Result<(), StageError>> {
        (pass == Pass::Renders).then(|| synthesize(self, ctx).map(|_| ()))
    }
}

/// One photograph: its name, its code values (sRGB-encoded, what the detector reads), the
/// linear image (what is sampled and fitted), its truth corners.
pub struct Photo {
    name: String,
    codes: Image,
    image: Image,
    truth: [[f64; 2]; 4],
}

fn read_truth(path: &std::path::Path) -> Result<Vec<(String, [[f64; 2]; 4])>, StageError> {
    let text =
        std::fs::read_to_string(path).map_err(|e| StageError::Config(format!("{}: {e}", path.display())))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate().skip(1).filter(|(_, l)| !l.trim().is_empty()) {
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        let v: Vec<f64> = f.iter().skip(1).filter_map(|s| s.parse().ok()).collect();
        if f.len() != 9 || v.len() != 8 || v.iter().any(|x| !x.is_finite()) {
            return Err(StageError::Config(format!(
                "{} line {}: expected image,x1,y1,x2,y2,x3,y3,x4,y4 with eight finite numbers",
                path.display(),
                i + 1
            )));
        }
        out.push((f[0].to_string(), [[v[0], v[1]], [v[2], v[3]], [v[4], v[5]], [v[6], v[7]]]));
    }
    if out.is_empty() {
        return Err(StageError::Config(format!("{}: no photograph listed", path.display())));
    }
    Ok(out)
}

/// A peer's figures per photograph: (model, leave-one-out mean ΔE2000).
pub type Peer = std::collections::BTreeMap<String, Vec<(String, f64)>>;

fn read_peer(path: &std::path::Path) -> Result<Peer, StageError> {
    let text =
        std::fs::read_to_string(path).map_err(|e| StageError::Config(format!("{}: {e}", path.display())))?;
    let mut out = Peer::new();
    for (i, line) in
        text.lines().enumerate().filter(|(_, l)| !l.starts_with('#') && !l.trim().is_empty()).skip(1)
    {
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        match (f.as_slice(), f.get(2).and_then(|v| v.parse::<f64>().ok())) {
            ([image, model, _], Some(v)) if v.is_finite() => {
                out.entry(image.to_string()).or_default().push((model.to_string(), v))
            }
            _ => {
                return Err(StageError::Config(format!(
                    "{} line {}: expected image,model,loo_mean_de2000",
                    path.display(),
                    i + 1
                )))
            }
        }
    }
    Ok(out)
}

pub fn read(c: &PhotoConfig, ctx: &Context) -> Result<(Vec<Photo>, Peer, Findings), StageError> {
    let dir = dataset_path(ctx, &c.photos)?;
    let truth_path = ctx.dir.join(&c.truth);
    let mut photos = Vec::new();
    for (name, truth) in read_truth(&truth_path)? {
        let codes = crate::image::io::read(&dir.join(&name))?;
        let mut image = codes.clone();
        image.data.iter_mut().for_each(|v| *v = crate::image::srgb_decode(*v));
        photos.push(Photo { name, codes, image, truth });
    }
    let note = format!(
        "{} photographs in {} (sRGB JPEGs: the camera's rendering, not linear data, so ΔE measures that rendering); corners checked by hand in {}.",
        photos.len(),
        c.photos,
        c.truth
    );
    let peer = match &c.peer {
        Some(p) => read_peer(&ctx.dir.join(p))?,
        None => Peer::new(),
    };
    Ok((photos, peer, Findings { notes: vec![note], ..Default::default() }))
}

/// Per photograph: the detection (or why not), its time, and the fit on its sampled patches.
pub struct PhotoResults {
    model: String,
    photos: Vec<(String, [[f64; 2]; 4], Result<(detect::Detection, color::Output), StageError>, f64)>,
}

pub fn solve_photos(c: &PhotoConfig, photos: &[Photo]) -> Result<PhotoResults, StageError> {
    let model: color::Model = c.model.parse()?;
    let (reference, white) = color::published_reference();
    let photos = photos
        .iter()
        .map(|p| {
            let t = std::time::Instant::now();
            let found = detect::detect(&p.codes, false);
            let secs = t.elapsed().as_secs_f64();
            let result = found.map_err(StageError::from).and_then(|d| {
                let samples = color::chart::sample(&p.image, d.corners, 1.0)?;
                let input = color::Input::from_samples(
                    &samples,
                    reference.iter().map(|(n, xyz)| (n.as_str(), *xyz)),
                    white,
                );
                let config = color::Config { model, white_patch: 18, leave_one_out: true };
                let fit = color::run(&input, &config)?;
                Ok((d, fit))
            });
            (p.name.clone(), p.truth, result, secs)
        })
        .collect();
    Ok(PhotoResults { model: c.model.clone(), photos })
}

pub fn validate_photos(out: &PhotoResults, peer: &Peer) -> Findings {
    let mut f = Findings::default();
    let mut shares = Vec::new();
    let mut loo = Vec::new();
    let mut times: Vec<f64> = out.photos.iter().map(|r| r.3).collect();
    // The peer's figure for this model, or its best where it lacks the model.
    let beside = |name: &str| {
        let rows = peer.get(name)?;
        let same = rows.iter().find(|(m, _)| *m == out.model);
        let (m, v) = same.or_else(|| rows.iter().min_by(|a, b| a.1.total_cmp(&b.1)))?;
        Some(format!("; peer {m}: {v:.2}"))
    };
    for (name, truth, result, secs) in &out.photos {
        let diagonal = (truth[0][0] - truth[2][0]).hypot(truth[0][1] - truth[2][1]);
        match result {
            Ok((d, fit)) => {
                let e = worst_corner(&d.corners, truth);
                shares.push(e / diagonal);
                if let Some(l) = fit.loo_mean_de2000 {
                    loo.push(l);
                }
                f.notes.push(format!(
                    "{name}: found in {secs:.3} s, worst corner {e:.1} px ({:.2} % of the diagonal), confidence {:.2}; mean ΔE00 {:.2}, leave-one-out {}{}.",
                    100.0 * e / diagonal,
                    d.confidence,
                    fit.mean_de2000,
                    fit.loo_mean_de2000.map_or("none".into(), |v| format!("{v:.2}")),
                    beside(name).unwrap_or_default()
                ));
            }
            Err(e) => f.notes.push(format!("{name}: {e}")),
        }
    }
    let n = out.photos.len();
    let found = shares.iter().filter(|&&s| s <= 0.015).count();
    let m = &mut f.metrics;
    m.push(Metric::new("photos_found", found as f64, "photos", Better::Higher));
    m.push(Metric::new("photos_missed", (n - found) as f64, "photos", Better::Lower));
    let max = shares.iter().copied().reduce(f64::max);
    m.push(Metric::maybe("corner_error_share_max", max, "", Better::Lower, "no photograph found"));
    m.push(Metric::maybe(
        "loo_mean_de2000_median",
        crate::math::stats::median(&mut loo.clone()),
        "ΔE00",
        Better::Lower,
        "no fit",
    ));
    m.push(Metric::maybe(
        "loo_mean_de2000_max",
        loo.iter().copied().reduce(f64::max),
        "ΔE00",
        Better::Lower,
        "no fit",
    ));
    m.push(Metric::maybe(
        "detect_s_median",
        crate::math::stats::median(&mut times),
        "s",
        Better::Lower,
        "no photograph",
    ));
    f
}

impl Settings for PhotoConfig {
    fn headline(&self) -> &'static str {
        "corner_error_share_max"
    }
    fn run(&self, ctx: &Context) -> Result<CaseResult, StageError> {
        run_case(|| read(self, ctx).map(Some), |p| solve_photos(self, p), validate_photos)
    }
}
