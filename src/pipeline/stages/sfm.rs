//! The `sfm` stage, on renders or on real photographs with ground-truth cameras.
//!
//! Renders (an entry with `scene`): the scene is rendered from `views` cameras spaced evenly
//! along a horizontal arc of `arc_deg` around `target`, at `radius` from it (less `forward` as
//! the sequence advances) and `height` above the ground, each looking at `target` (the
//! scene's own camera gives the intrinsics); the solver gets the images and the true
//! intrinsics, as it gets K.txt on photographs, or with `guess_intrinsics = true` what
//! `lumen sfm` assumes without `--camera` (focal length 1.2 × the longer side, principal point
//! at the centre, no distortion), refining in bundle adjustment what `refine` names (default
//! `sfm::GUESSED_REFINE`: the focal length and k1).
//! Photographs (an entry with `images`): reads the folder and its camera as `lumen sfm` does
//! (`sfm::input`; without `camera`, the same guess as above, refined). Both run the same
//! `sfm::run` and compare the registered cameras with the
//! truth, free of gauge: pairwise relative rotation errors
//! over every pair of registered images, and camera-centre errors after the similarity that
//! best maps the estimated centres onto the true ones (`sfm::eval`), relative to the largest
//! distance between two true centres. Truth: one file per image in the Strecha et al. format,
//! `<truth>/<image file name>.camera` (`sfm::input::read_strecha_camera`). When the folder is
//! absent (no `../shared` beside a fresh clone) the case is skipped with the reason.
//!
//! Over a pipeline's shares (`pipeline::cache` module docs) the work splits inside a case: the
//! renders pass extracts the features of the views, or photographs, each share owns; the
//! matches pass verifies the blocks of `PAIR_BLOCK` × `PAIR_BLOCK` image pairs each owns; the
//! case then reads both from the cache (`prepare`, `sfm::Prepared`) and only maps.
//!
//! Metrics: `registered_images`, `unregistered_images`, `points`, `planar_pairs` and
//! `pure_rotation_pairs` (verified pairs a homography explains, and of those the ones without
//! parallax: no baseline to start from), `mean_track_length`,
//! `reprojection_rms_px`, `rotation_err_median_deg`, `rotation_err_max_deg`,
//! `centre_err_max_rel`; with guessed intrinsics `focal_err_rel`, |f − f_true|/f_true against
//! the true fx, and on renders `k1_err`, |k1 − k1_true|; and the phases' times as a note.
//!
//! A chained case (`camera = "from:CASE"`, `chain`) is given the calibrated camera as its
//! intrinsics; it runs alone too, and once per camera parameter for the sensitivity of
//! `rotation_err_median_deg` (`chain::run_chained`). The prediction is meaningful where the
//! inherited error is above the solver's own noise: a calibration as good as the session's
//! gives both at the noise's scale.

use super::Synthesis;
use super::{apply_overrides, Context, Findings, SettingsKey, StageError, ViewRecipe, MAX_RENDERS};
use super::{run_case, CaseResult, Settings};
use crate::math::{CameraToWorld, WorldToCamera};
use crate::pipeline::cache::{scene_digest, Pass};
use crate::pipeline::metric::{Better, Metric};
use crate::render;
use crate::sfm::{self, eval};
use glam::DVec3;
use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

/// An `sfm` case on renders (module docs).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderConfig {
    /// Scene file, relative to the pipeline file.
    pub scene: String,
    /// Number of views (default 8, at least 2).
    #[serde(default = "default_views")]
    pub views: usize,
    /// The point every camera looks at, in the scene's frame (z up).
    pub target: [f64; 3],
    /// Horizontal distance of the cameras from `target`, and their height (z).
    pub radius: f64,
    pub height: f64,
    /// The arc the cameras span, in degrees, centred on the −y side of `target`.
    pub arc_deg: f64,
    /// Metres the cameras advance towards `target` over the sequence: view k of n is
    /// `forward`·k/(n − 1) closer to it than `radius`, along its horizontal line of sight
    /// (default 0; with `arc_deg = 0` a pure forward motion, the epipole in the image).
    #[serde(default)]
    pub forward: f64,
    /// Keypoints per image at most (default 8192, COLMAP's).
    #[serde(default = "default_features")]
    pub max_features: usize,
    /// Samples per pixel (default: the scene's).
    pub spp: Option<u32>,
    /// Give the solver the guess of `lumen sfm` without `--camera` instead of the true
    /// intrinsics, and let it refine them (default false).
    #[serde(default)]
    pub guess_intrinsics: bool,
    /// The shared intrinsics refined from the guess: any of "focal", "principal-point",
    /// "k1", "k2" (default `sfm::GUESSED_REFINE`: focal and k1); only with guessed intrinsics.
    pub refine: Option<Vec<String>>,
    /// Match verified pairs again guided by their geometry (`mapper::Options::guided_matching`,
    /// default false).
    #[serde(default)]
    pub guided_matching: bool,
    /// Which pairs are matched: "exhaustive" (default) or "sequential:N", the views in order
    /// along the arc (`mapper::PairSelection`).
    pub pairs: Option<String>,
    /// `"from:CASE"`: give the solver the camera an earlier calibrate case estimated instead of
    /// the true one (a chained case). It runs alone too, with the true camera, and reports
    /// both: the chained metrics under their names, the alone ones as `alone_<metric>`, and
    /// the error the case inherits as `inherited_<metric>` (chained − alone). The calibrated
    /// camera must be this scene's: same size, true intrinsics and distortion.
    pub camera: Option<String>,
    /// A deliberate error added to the inherited camera (a chained case only): its focal
    /// lengths scaled by 1 + `focal_rel`, `k1` added to its k1 (default none).
    pub perturb: Option<super::chain::Perturb>,
}

fn default_views() -> usize {
    8
}

/// A view's features (a derived cache entry): its render and the detector's settings.
#[derive(Serialize)]
struct FeaturesRecipe<'a> {
    product: &'static str,
    view: ViewRecipe<'a>,
    /// `features::Options` as Debug prints it (every field, floats exactly).
    options: String,
}

/// A photograph's features (a derived cache entry): its file's content and the detector's
/// settings.
#[derive(Serialize)]
struct PhotoFeaturesRecipe {
    product: &'static str,
    /// FNV-1a 128 of the file's bytes.
    file: String,
    options: String,
}

/// A block of verified pairs (a derived cache entry): the features and given cameras of its
/// images, their number (the pairs' RANSAC seeds depend on it), where the block starts, and the
/// mapper's settings.
#[derive(Serialize)]
struct PairsRecipe<'a, R> {
    product: &'static str,
    views: usize,
    first: [usize; 2],
    features: Vec<&'a R>,
    cameras: Vec<crate::math::CameraModel>,
    /// `mapper::Options` as Debug prints it.
    options: &'a str,
}

/// View `k`'s camera at place `f` (0 to 1) on a horizontal arc of `arc_deg` centred on the −y
/// side of `target`, at distance `radius` from it and height `height`, looking at it.
pub(super) fn arc_camera(
    k: usize,
    target: DVec3,
    radius: f64,
    height: f64,
    arc_deg: f64,
    f: f64,
) -> Result<CameraToWorld, StageError> {
    let phi = (-90.0 + arc_deg * (f - 0.5)).to_radians();
    let origin = DVec3::new(target.x + radius * phi.cos(), target.y + radius * phi.sin(), height);
    CameraToWorld::look_at(origin, target, DVec3::Z).ok_or_else(|| {
        StageError::Config(format!("view {k}: the camera at {origin} cannot look at {target}"))
    })
}

/// Images on each side of a block of pairs the matches pass hands out: 8 × 8 pairs, under a
/// second of matching and verification on one thread at 1024×768 px, small enough to spread
/// a case's pairs over the shares (`docs/scale.md`).
const PAIR_BLOCK: usize = 8;

pub fn synthesize(c: &RenderConfig, ctx: &Context) -> Result<Synthesis<sfm::Input, Truth>, StageError> {
    synthesize_given(c, ctx, None)
}

/// `synthesize`, the solver given `inherited`'s estimate (an upstream case's camera and the
/// truth it had) instead of the true camera.
fn synthesize_given(
    c: &RenderConfig,
    ctx: &Context,
    inherited: Option<(crate::math::CameraModel, crate::math::CameraModel)>,
) -> Result<Synthesis<sfm::Input, Truth>, StageError> {
    if !(2..=MAX_RENDERS).contains(&c.views) {
        return Err(StageError::Config(format!("views = {}: expected 2 to {MAX_RENDERS}", c.views)));
    }
    if c.max_features < 16 {
        return Err(StageError::Config(format!("max_features = {}: expected at least 16", c.max_features)));
    }
    let numbers = [c.radius, c.height, c.arc_deg, c.forward, c.target[0], c.target[1], c.target[2]];
    if !numbers.iter().all(|v| v.is_finite())
        || c.radius <= 0.0
        || !(0.0..=360.0).contains(&c.arc_deg)
        || !(0.0..c.radius).contains(&c.forward)
    {
        return Err(StageError::Config(format!(
            "radius = {}, height = {}, arc_deg = {}, forward = {}, target = {:?}: expected finite numbers, a positive radius, an arc of 0° to 360° and a forward advance from 0 to less than the radius",
            c.radius, c.height, c.arc_deg, c.forward, c.target
        )));
    }
    let scene_path = ctx.dir.join(&c.scene);
    let mut scene = render::load(&scene_path)?;
    let digest = scene_digest(&scene_path)?;
    let mut settings = render::Settings::from_scene(&scene);
    apply_overrides(&mut settings, c.spp, None)?;
    let camera = scene.camera;
    if let Some((_, upstream_truth)) = &inherited {
        super::chain::check_same_camera(c.camera.as_deref().unwrap_or(""), upstream_truth, &camera)?;
    }
    let cfg = config(c.max_features, c.guess_intrinsics, &c.refine, c.guided_matching, &c.pairs)?;
    let mut recipes = Vec::new();
    let target = DVec3::from_array(c.target);
    let bar = render::progress_bar(c.views as u64, &format!("{} views", ctx.case), ctx.progress);
    let mut images = Vec::new();
    let mut poses = Vec::new();
    for k in 0..c.views {
        let f = k as f64 / (c.views - 1) as f64;
        let world_from_cam = arc_camera(k, target, c.radius - c.forward * f, c.height, c.arc_deg, f)?;
        scene.t_world_cam = world_from_cam;
        settings.seed = render::sampler::mix64(ctx.seed ^ (k as u64 + 1));
        let pose = super::pose_key(&world_from_cam);
        let name = format!("view{k:03}.png");
        let recipe = FeaturesRecipe {
            product: "sfm-features",
            view: ViewRecipe {
                product: "sfm-rgb",
                scene: &digest,
                t_world_cam: pose,
                settings: SettingsKey::from(&settings),
            },
            options: format!("{:?}", cfg.features),
        };
        let rendered = ctx.cache.images(ctx.case, &name, &recipe.view, || {
            Ok::<_, StageError>(vec![render::try_render(&scene, &settings)?.mean])
        })?;
        let given = match inherited {
            Some((estimate, _)) => estimate,
            None if c.guess_intrinsics => sfm::input::assumed_camera(camera.width, camera.height),
            None => camera,
        };
        let Some(rendered) = rendered else {
            // A share of the renders pass: the owner of a view extracts its features.
            if ctx.cache.owns(&recipe.view) && ctx.cache.bytes(&recipe).is_none() {
                if let Some(img) = ctx.cache.stored_images(&recipe.view) {
                    let im = photograph(name, img, &camera, given)?;
                    let f = sfm::features::detect(&im.grey, &cfg.features);
                    ctx.cache.store_bytes(&recipe, &sfm::bytes::encode_features(&f));
                }
            }
            recipes.push(recipe);
            continue;
        };
        images.push(photograph(name, rendered, &camera, given)?);
        recipes.push(recipe);
        poses.push(world_from_cam.inverse());
        bar.inc(1);
    }
    bar.finish_and_clear();
    let prepared = match ctx.cache.pass() {
        Some(Pass::Renders) => sfm::Prepared::default(),
        _ => prepare(ctx, &images, &recipes, &cfg),
    };
    if ctx.renders_only() {
        return Ok(None);
    }
    let advance =
        if c.forward > 0.0 { format!(", advancing {} towards it", c.forward) } else { String::new() };
    let notes = vec![format!(
        "{}: {} views of {}×{} px at {} spp along a {}° arc, {} from {:?} at height {}{advance}.",
        c.scene, c.views, camera.width, camera.height, settings.spp, c.arc_deg, c.radius, c.target, c.height
    )];
    let focal = c.guess_intrinsics.then_some(camera.intrinsics.fx);
    let k1 = c.guess_intrinsics.then_some(camera.distortion.k1);
    Ok(Some((
        sfm::Input { images, prepared },
        Truth { poses, focal, k1 },
        Findings { notes, ..Default::default() },
    )))
}

/// A render as the photograph `lumen sfm` would read: 8-bit sRGB codes, read back as
/// `sfm::input` reads them, with the camera the solver is `given`.
pub(super) fn photograph(
    name: String,
    rendered: Vec<crate::image::Image>,
    camera: &crate::math::CameraModel,
    given: crate::math::CameraModel,
) -> Result<sfm::Image, StageError> {
    let Some(img) = rendered
        .into_iter()
        .next()
        .filter(|i| i.channels == 3 && (i.width, i.height) == (camera.width, camera.height))
    else {
        return Err(StageError::Config(format!("{name}: the cached render has the wrong size")));
    };
    let code = |v: f32| (crate::image::srgb_encode(v.max(0.0)) * 255.0).round().clamp(0.0, 255.0) / 255.0;
    let coded = crate::image::Image { data: img.data.iter().map(|&v| code(v)).collect(), ..img };
    Ok(sfm::input::image(name, &coded, given))
}

/// What shares made for the case (`cache` module docs): every view's features and every block
/// of verified pairs the cache holds. In the matches pass, also makes the blocks this share
/// owns (detecting, and storing, the features of their images where the renders pass left
/// none). Outside the passes, only reads: a run of cases stores none of this, so its phase
/// times stay those of the work it does.
fn prepare<R: Serialize>(
    ctx: &Context,
    images: &[sfm::Image],
    recipes: &[R],
    cfg: &sfm::Config,
) -> sfm::Prepared {
    let making = ctx.cache.pass() == Some(Pass::Matches);
    let mut features: Vec<Option<sfm::features::Features>> =
        recipes.iter().map(|r| ctx.cache.bytes(r).and_then(|b| sfm::bytes::decode_features(&b))).collect();
    let n = images.len();
    let k: Vec<Matrix3<f64>> = images.iter().map(|im| sfm::intrinsics(&im.camera)).collect();
    let options = format!("{:?}", cfg.mapper);
    let mut pairs = Vec::new();
    for i0 in (0..n).step_by(PAIR_BLOCK) {
        for j0 in (i0..n).step_by(PAIR_BLOCK) {
            let block: Vec<(usize, usize)> = (i0..n.min(i0 + PAIR_BLOCK))
                .flat_map(|a| (j0.max(a + 1)..n.min(j0 + PAIR_BLOCK)).map(move |b| (a, b)))
                .filter(|&(a, b)| cfg.mapper.pairs.selects(a, b))
                .collect();
            if block.is_empty() {
                continue;
            }
            let mut members: Vec<usize> = (i0..n.min(i0 + PAIR_BLOCK)).collect();
            if j0 != i0 {
                members.extend(j0..n.min(j0 + PAIR_BLOCK));
            }
            let recipe = PairsRecipe {
                product: "sfm-pairs",
                views: n,
                first: [i0, j0],
                features: members.iter().map(|&m| &recipes[m]).collect(),
                cameras: members.iter().map(|&m| images[m].camera.clone()).collect(),
                options: &options,
            };
            let owned = ctx.cache.owns(&recipe);
            if let Some(p) = ctx.cache.bytes(&recipe).and_then(|b| sfm::bytes::decode_pairs(&b)) {
                ctx.cache.count(owned, false);
                pairs.extend(p);
                continue;
            }
            if !making {
                continue;
            }
            ctx.cache.count(owned, owned);
            if !owned {
                continue;
            }
            // Only the block's images need features: the others stay empty.
            let mut ideal = vec![sfm::features::Features::default(); n];
            for &m in &members {
                let f = features[m].get_or_insert_with(|| {
                    let f = sfm::features::detect(&images[m].grey, &cfg.features);
                    ctx.cache.store_bytes(&recipes[m], &sfm::bytes::encode_features(&f));
                    f
                });
                ideal[m] = sfm::ideal_features(&images[m], f).ideal;
            }
            let block =
                sfm::mapper::verify_pairs(&ideal, &k, &block, &cfg.mapper, &indicatif::ProgressBar::hidden());
            ctx.cache.store_bytes(&recipe, &sfm::bytes::encode_pairs(&block));
        }
    }
    sfm::Prepared { features, pairs }
}

/// The features recipe of each photograph: its file's digest and the detector's settings.
fn photo_recipes(
    files: &[std::path::PathBuf],
    cfg: &sfm::Config,
) -> Result<Vec<PhotoFeaturesRecipe>, StageError> {
    files
        .iter()
        .map(|f| {
            let bytes =
                std::fs::read(f).map_err(|e| sfm::Error::File { path: f.clone(), message: e.to_string() })?;
            Ok(PhotoFeaturesRecipe {
                product: "sfm-photo-features",
                file: format!("{:032x}", crate::pipeline::cache::fnv128(&bytes)),
                options: format!("{:?}", cfg.features),
            })
        })
        .collect()
}

/// The solver's settings for a case: its keypoints per image, what it refines of guessed
/// intrinsics (`refine` names, or none when they are given), whether verified pairs are
/// matched again guided by their geometry, and which pairs are matched.
pub(super) fn config(
    max_features: usize,
    guessed: bool,
    refine: &Option<Vec<String>>,
    guided_matching: bool,
    pairs: &Option<String>,
) -> Result<sfm::Config, StageError> {
    let pairs = match pairs {
        None => sfm::mapper::PairSelection::Exhaustive,
        Some(p) => p.parse().map_err(|e| StageError::Config(format!("pairs = {e}")))?,
    };
    let refine = match (guessed, refine) {
        (false, None) => sfm::bundle::Refine::NONE,
        (false, Some(_)) => {
            return Err(StageError::Config(
                "refine: only with guessed intrinsics (guess_intrinsics = true, or no camera)".into(),
            ))
        }
        (true, None) => sfm::GUESSED_REFINE,
        (true, Some(names)) => {
            sfm::bundle::Refine::from_names(names).map_err(|e| StageError::Config(format!("refine: {e}")))?
        }
    };
    Ok(sfm::Config {
        features: sfm::features::Options { max_features, ..Default::default() },
        mapper: sfm::mapper::Options { refine, guided_matching, pairs, ..Default::default() },
        progress: false,
    })
}

pub fn solve_render(c: &RenderConfig, input: &sfm::Input) -> Result<sfm::Output, StageError> {
    Ok(sfm::run(input, &config(c.max_features, c.guess_intrinsics, &c.refine, c.guided_matching, &c.pairs)?)?)
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Folder of photographs, relative to the pipeline file (`sfm::input::EXTENSIONS`).
    pub images: String,
    /// The camera file, as `lumen sfm --camera` (calibration YAML/JSON, or K as text),
    /// relative to the pipeline file; without it, `lumen sfm`'s guess, refined (module docs).
    pub camera: Option<String>,
    /// Folder of ground-truth cameras, `<image file name>.camera` each.
    pub truth: String,
    /// Keypoints per image at most (default 8192, COLMAP's).
    #[serde(default = "default_features")]
    pub max_features: usize,
    /// As the render entry's `guided_matching`.
    #[serde(default)]
    pub guided_matching: bool,
    /// As the render entry's `refine`; only without `camera`.
    pub refine: Option<Vec<String>>,
    /// As the render entry's `pairs`, the photographs in name order.
    pub pairs: Option<String>,
}

fn default_features() -> usize {
    8192
}

/// The true world-to-camera pose of every image, in the input's order, and the true focal
/// length (fx) and k1 where the solver starts from a guess (k1 of renders only).
pub struct Truth {
    poses: Vec<WorldToCamera>,
    focal: Option<f64>,
    k1: Option<f64>,
}

/// The photographs of a real-data entry, its camera (with the file it came from), the
/// mapper's settings and each photograph's cache recipe.
struct Photos {
    dir: std::path::PathBuf,
    files: Vec<std::path::PathBuf>,
    camera: Option<crate::math::CameraModel>,
    camera_path: Option<std::path::PathBuf>,
    cfg: sfm::Config,
    recipes: Vec<PhotoFeaturesRecipe>,
}

fn photos(c: &Config, ctx: &Context) -> Result<Photos, StageError> {
    if c.max_features < 16 {
        return Err(StageError::Config(format!("max_features = {}: expected at least 16", c.max_features)));
    }
    let dir = super::dataset_path(ctx, &c.images)?;
    let camera_path = c.camera.as_deref().map(|p| super::dataset_path(ctx, p)).transpose()?;
    let camera = camera_path.as_deref().map(sfm::input::read_camera).transpose()?;
    let files = sfm::input::photographs(&dir)?;
    let cfg = config(c.max_features, c.camera.is_none(), &c.refine, c.guided_matching, &c.pairs)?;
    let recipes = photo_recipes(&files, &cfg)?;
    Ok(Photos { dir, files, camera, camera_path, cfg, recipes })
}

/// A real-data entry's part of the shard passes: in the renders pass, the features of the
/// photographs this share owns; in the matches pass, its blocks of pairs.
fn share_photos(c: &Config, ctx: &Context, pass: Pass) -> Result<(), StageError> {
    let p = photos(c, ctx)?;
    match pass {
        Pass::Renders => {
            for (file, recipe) in p.files.iter().zip(&p.recipes) {
                if ctx.cache.owns(recipe) && ctx.cache.bytes(recipe).is_none() {
                    let input = sfm::input::read_images(std::slice::from_ref(file), p.camera, |_, _, _| {})?;
                    for im in &input.images {
                        let f = sfm::features::detect(&im.grey, &p.cfg.features);
                        ctx.cache.store_bytes(recipe, &sfm::bytes::encode_features(&f));
                    }
                }
            }
        }
        Pass::Matches => {
            let input = sfm::input::read_images(&p.files, p.camera, |_, _, _| {})?;
            prepare(ctx, &input.images, &p.recipes, &p.cfg);
        }
    }
    Ok(())
}

pub fn read(c: &Config, ctx: &Context) -> Result<(sfm::Input, Truth, Findings), StageError> {
    let Photos { dir, files, camera, camera_path, cfg, recipes } = photos(c, ctx)?;
    let truth_dir = super::dataset_path(ctx, &c.truth)?;
    let mut input = sfm::input::read_images(&files, camera, |_, _, _| {})?;
    input.prepared = prepare(ctx, &input.images, &recipes, &cfg);
    let mut poses = Vec::new();
    let mut focal = None;
    for im in &input.images {
        let (k, r, centre) = sfm::input::read_strecha_camera(&truth_dir.join(format!("{}.camera", im.name)))?;
        if camera.is_none() {
            focal = focal.or(Some(k[(0, 0)]));
        }
        // Strecha's R holds the camera's axes in the world, C its centre.
        let axis = |j: usize| DVec3::new(r[(0, j)], r[(1, j)], r[(2, j)]);
        let rotation = glam::DMat3::from_cols(axis(0), axis(1), axis(2));
        let translation = DVec3::new(centre.x, centre.y, centre.z);
        poses.push(CameraToWorld(crate::math::Pose { rotation, translation }).inverse());
    }
    let camera_note = match &camera_path {
        Some(p) => format!("the camera {}", p.display()),
        None => "no camera (focal length guessed, then refined)".to_string(),
    };
    let notes = vec![format!(
        "Real data: {} photographs in {} ({}×{} px), {camera_note}, the truth from {}.",
        input.images.len(),
        dir.display(),
        input.images[0].grey.width,
        input.images[0].grey.height,
        truth_dir.display()
    )];
    Ok((input, Truth { poses, focal, k1: None }, Findings { notes, ..Default::default() }))
}

pub fn solve(c: &Config, input: &sfm::Input) -> Result<sfm::Output, StageError> {
    // `read` took the same settings for the prepared features and pairs.
    Ok(sfm::run(input, &config(c.max_features, c.camera.is_none(), &c.refine, c.guided_matching, &c.pairs)?)?)
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
    // How the verified pairs were classified: the reason a reconstruction without a baseline
    // gives for registering nothing.
    let count =
        |c: sfm::two_view::Configuration| rec.pairs.iter().filter(|p| p.configuration == Some(c)).count();
    let planar = count(sfm::two_view::Configuration::Planar);
    m.push(Metric::new("planar_pairs", planar as f64, "pairs", Better::Lower));
    let rotation = count(sfm::two_view::Configuration::PureRotation);
    m.push(Metric::new("pure_rotation_pairs", rotation as f64, "pairs", Better::Lower));
    let track = (points > 0).then(|| observations as f64 / points as f64);
    m.push(Metric::maybe("mean_track_length", track, "images", Better::Higher, "no point"));
    let rms = (points > 0).then_some(rec.rms_px);
    m.push(Metric::maybe("reprojection_rms_px", rms, "px", Better::Lower, "no point"));
    let mut rot = eval::pairwise_rotation_errors(&rec.poses, &truth.poses);
    rot.sort_by(f64::total_cmp);
    // The same errors as rotation vectors, for a chained case's prediction.
    let items = eval::pairwise_rotation_error_vectors(&rec.poses, &truth.poses)
        .into_iter()
        .map(|((i, j), v)| (((i as u64) << 32) | j as u64, v.to_vec()))
        .collect();
    f.linear = Some(super::chain::Linear { items, headline: median_rotation_error_deg });
    let none = "fewer than 2 images registered";
    m.push(Metric::maybe(
        "rotation_err_median_deg",
        rot.get(rot.len() / 2).copied(),
        "°",
        Better::Lower,
        none,
    ));
    m.push(Metric::maybe("rotation_err_max_deg", rot.last().copied(), "°", Better::Lower, none));
    let extent = eval::centre_spread(&truth.poses);
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
    if let Some(true_f) = truth.focal {
        let focal = out.cameras.first().map(|c| c.intrinsics.fx);
        let err = focal.map(|v| (v / true_f - 1.0).abs());
        m.push(Metric::maybe("focal_err_rel", err, "", Better::Lower, "no image"));
        if let Some(v) = focal {
            f.notes.push(format!(
                "Focal length {v:.2} px refined from the guess, against the true {true_f:.2} px."
            ));
        }
        if let Some(c) = out.cameras.first().filter(|c| c.distortion.k1 != 0.0 || c.distortion.k2 != 0.0) {
            f.notes.push(format!(
                "Radial distortion refined: k1 = {:.5}, k2 = {:.5}.",
                c.distortion.k1, c.distortion.k2
            ));
        }
    }
    if let Some(true_k1) = truth.k1 {
        let k1 = out.cameras.first().map(|c| (c.distortion.k1 - true_k1).abs());
        m.push(Metric::maybe("k1_err", k1, "", Better::Lower, "no image"));
    }
    for (i, why) in &rec.unregistered {
        f.notes.push(format!("image {i} not registered: {why}"));
    }
    if out.prepared_images + out.prepared_pairs > 0 {
        let n = out.features.len();
        f.notes.push(format!(
            "Made beforehand by the pipeline's shares and read from the cache: the features of {} of {n} images, the matches and two-view geometry of {} of {} pairs (the phase times below leave that work out).",
            out.prepared_images,
            out.prepared_pairs,
            rec.pairs.len()
        ));
    }
    f.notes.push(format!(
        "Phases: extraction {:.2} s, matching {:.2} s, geometric verification {:.2} s, mapping {:.2} s, bundle adjustment {:.2} s.",
        out.extraction_s, rec.matching_s, rec.verification_s, rec.mapping_s, rec.bundle_s
    ));
    f
}

/// `rotation_err_median_deg` from pairs' rotation-error vectors (`chain::Linear`): the norms'
/// upper median, as the metric takes it.
fn median_rotation_error_deg(items: &mut dyn Iterator<Item = &[f64]>) -> Option<f64> {
    let mut norms: Vec<f64> = items.map(|v| v.iter().map(|x| x * x).sum::<f64>().sqrt()).collect();
    norms.sort_by(f64::total_cmp);
    norms.get(norms.len() / 2).copied()
}

impl Settings for RenderConfig {
    fn headline(&self) -> &'static str {
        "rotation_err_median_deg"
    }
    fn run(&self, ctx: &Context) -> Result<CaseResult, StageError> {
        if let (Some(source), true) = (super::from_case(&self.camera), self.guess_intrinsics) {
            return Err(StageError::Config(format!(
                "camera = \"from:{source}\" and guess_intrinsics = true: a chained case is given its source's camera, not a guess"
            )));
        }
        let chain = super::chain::Chain {
            headline: "rotation_err_median_deg",
            unit: "°",
            errors: &[
                "rotation_err_median_deg",
                "rotation_err_max_deg",
                "centre_err_max_rel",
                "reprojection_rms_px",
            ],
        };
        super::chain::run_on_camera(&self.camera, self.perturb, ctx, &chain, |given| {
            run_case(|| synthesize_given(self, ctx, given), |i| solve_render(self, i), validate)
        })
    }
    fn upstream(&self) -> Vec<(&'static str, String, &'static str)> {
        super::chain::camera_upstream(&self.camera)
    }
    /// Both passes: the views' renders and features, then the pairs (`synthesize`).
    fn share(&self, ctx: &Context, _pass: Pass) -> Option<Result<(), StageError>> {
        Some(synthesize(self, ctx).map(|_| ()))
    }
}

impl Settings for Config {
    fn headline(&self) -> &'static str {
        "rotation_err_median_deg"
    }
    fn run(&self, ctx: &Context) -> Result<CaseResult, StageError> {
        run_case(|| read(self, ctx).map(Some), |i| solve(self, i), validate)
    }
    /// Both passes: the photographs' features, then the pairs.
    fn share(&self, ctx: &Context, pass: Pass) -> Option<Result<(), StageError>> {
        Some(share_photos(self, ctx, pass))
    }
}
