//! The `sfm` stage on real photographs with ground-truth cameras: reads a photograph folder
//! and its camera as `lumen sfm` does (`sfm::input`), runs the same `sfm::run`, and compares
//! the registered cameras with the truth, free of gauge: pairwise relative rotation errors
//! over every pair of registered images, and camera-centre errors after the similarity that
//! best maps the estimated centres onto the true ones (`sfm::eval`), relative to the largest
//! distance between two true centres. Truth: one file per image in the Strecha et al. format,
//! `<truth>/<image file name>.camera` (`sfm::input::read_strecha_camera`). When the folder is
//! absent (no `../shared` beside a fresh clone) the case is skipped with the reason.
//!
//! Metrics: `registered_images`, `unregistered_images`, `points`, `mean_track_length`,
//! `reprojection_rms_px`, `rotation_err_median_deg`, `rotation_err_max_deg`,
//! `centre_err_max_rel`; and the phases' times as a note.

use super::{Context, Findings, StageError};
use crate::pipeline::metric::{Better, Metric};
use crate::sfm::{self, bundle::Pose, eval};
use serde::Deserialize;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Folder of photographs, relative to the pipeline file (`sfm::input::EXTENSIONS`).
    pub images: String,
    /// The camera file, as `lumen sfm --camera` (calibration YAML/JSON, or K as text),
    /// relative to the pipeline file.
    pub camera: String,
    /// Folder of ground-truth cameras, `<image file name>.camera` each.
    pub truth: String,
    /// Keypoints per image at most (default 8192, COLMAP's).
    #[serde(default = "default_features")]
    pub max_features: usize,
}

fn default_features() -> usize {
    8192
}

/// The true world-to-camera pose of every image, in the input's order.
pub struct Truth {
    poses: Vec<Pose>,
}

pub fn read(c: &Config, ctx: &Context) -> Result<(sfm::Input, Truth, Findings), StageError> {
    if c.max_features < 16 {
        return Err(StageError::Config(format!("max_features = {}: expected at least 16", c.max_features)));
    }
    let dir = super::dataset_path(ctx, &c.images)?;
    let camera_path = super::dataset_path(ctx, &c.camera)?;
    let camera = sfm::input::read_camera(&camera_path)?;
    let truth_dir = super::dataset_path(ctx, &c.truth)?;
    let files = sfm::input::photographs(&dir)?;
    let input = sfm::input::read_images(&files, Some(camera), |_, _, _| {})?;
    let mut poses = Vec::new();
    for im in &input.images {
        let (_, r, centre) = sfm::input::read_strecha_camera(&truth_dir.join(format!("{}.camera", im.name)))?;
        // World to camera: R_wc = Rᵀ, t = −Rᵀ C.
        poses.push(Pose { r: r.transpose(), t: -(r.transpose() * centre) });
    }
    let notes = vec![format!(
        "Real data: {} photographs in {} ({}×{} px), the camera {}, the truth from {}.",
        input.images.len(),
        dir.display(),
        input.images[0].grey.width,
        input.images[0].grey.height,
        camera_path.display(),
        truth_dir.display()
    )];
    Ok((input, Truth { poses }, Findings { notes, ..Default::default() }))
}

pub fn solve(c: &Config, input: &sfm::Input) -> Result<sfm::Output, StageError> {
    let config = sfm::Config {
        features: sfm::features::Options { max_features: c.max_features, ..Default::default() },
        ..Default::default()
    };
    Ok(sfm::run(input, &config)?)
}

pub fn validate(out: &sfm::Output, truth: &Truth) -> Findings {
    let rec = &out.reconstruction;
    let mut f = Findings::default();
    let m = &mut f.metrics;
    let registered = rec.registered_count();
    let (points, observations) = rec.seen_points().fold((0, 0), |(k, o), (_, _, obs)| (k + 1, o + obs.len()));
    m.push(Metric::new("registered_images", registered as f64, "images", Better::Higher));
    m.push(Metric::new("unregistered_images", rec.unregistered.len() as f64, "images", Better::Lower));
    m.push(Metric::new("points", points as f64, "points", Better::Higher));
    let track = (points > 0).then(|| observations as f64 / points as f64);
    m.push(Metric::maybe("mean_track_length", track, "images", Better::Higher, "no point"));
    let rms = (points > 0).then_some(rec.rms_px);
    m.push(Metric::maybe("reprojection_rms_px", rms, "px", Better::Lower, "no point"));
    let mut rot = eval::pairwise_rotation_errors(&rec.poses, &truth.poses);
    rot.sort_by(f64::total_cmp);
    let none = "fewer than 2 images registered";
    m.push(Metric::maybe(
        "rotation_err_median_deg",
        rot.get(rot.len() / 2).copied(),
        "°",
        Better::Lower,
        none,
    ));
    m.push(Metric::maybe("rotation_err_max_deg", rot.last().copied(), "°", Better::Lower, none));
    let extent = truth
        .poses
        .iter()
        .flat_map(|a| truth.poses.iter().map(move |b| (a.centre() - b.centre()).norm()))
        .fold(0.0, f64::max);
    let centre = eval::centre_errors(&rec.poses, &truth.poses)
        .filter(|_| extent > 0.0)
        .map(|e| e.iter().cloned().fold(0.0, f64::max) / extent);
    m.push(Metric::maybe(
        "centre_err_max_rel",
        centre,
        "",
        Better::Lower,
        "fewer than 3 images registered, or their centres are collinear",
    ));
    for (i, why) in &rec.unregistered {
        f.notes.push(format!("image {i} not registered: {why}"));
    }
    f.notes.push(format!(
        "Phases: extraction {:.2} s, matching {:.2} s, geometric verification {:.2} s, mapping {:.2} s, bundle adjustment {:.2} s.",
        out.extraction_s, rec.matching_s, rec.verification_s, rec.mapping_s, rec.bundle_s
    ));
    f
}
