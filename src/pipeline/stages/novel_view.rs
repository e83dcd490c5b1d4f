//! The `novel-view` stage: from photographs to a surface, its texture and a new view, each
//! checked against the renderer's truth.
//!
//! The scene is rendered from `views` cameras on a ring of `radius` around `target`, at the
//! two `heights` in turn, spaced evenly over `arc_deg`, and from one held-out camera (at
//! `held_out` = [place on the arc as a fraction, height]). Everything below runs as a user
//! would run it, on the photographs alone (8-bit sRGB, as `lumen sfm` reads them):
//!
//! 1. `sfm` on all the photographs (the held-out one registers too, so that its camera is
//!    known in the reconstruction's frame; it is not used further);
//! 2. `surface` (APSS) on the sparse points;
//! 3. `texture` from the training photographs and their registered cameras;
//! 4. the textured mesh drawn into the held-out camera, and `warp` (backward) from the two
//!    training views nearest it, their depth the mesh's.
//!
//! A chained case (`camera = "from:CASE"`) gives structure from motion the calibrated camera
//! as the photographs' intrinsics (`chain`).
//!
//! Validation aligns the reconstruction to the truth by the similarity of the camera centres
//! (`sfm::eval::similarity`), then measures:
//! - `chamfer_rel`: the mean of accuracy (mesh vertices to the nearest true surface point) and
//!   completeness (true points to the nearest vertex), over the true points' extent. The true
//!   surface is every training view's position AOV (one point per 4 × 4 pixels), so the figure
//!   has a floor of about two pixels' footprint;
//! - `normal_err_median_deg`: each triangle's normal against the true normal nearest its
//!   centre, either way round;
//! - `texture_psnr_db`: the drawn texture against the held-out view's albedo AOV, peak 1, over
//!   pixels inside both silhouettes by a pixel. A texture made from photographs holds
//!   radiance, the albedo times the shading; the scene is rendered with direct lighting only,
//!   where a Lambertian point's radiance is exactly its albedo times the radiance it has with
//!   albedo 1, so the drawing is divided by a render of the held-out view with every albedo 1,
//!   over the pixels lit by at least a quarter of the median (not in a shadow);
//! - `texture_psnr_true_cameras_db`: the same, with the texture made from the true cameras
//!   (carried into the reconstruction's frame by the similarity) on the same mesh: the gap to
//!   `texture_psnr_db` is what SfM's cameras cost;
//! - `view_psnr_db`: the same drawing against the held-out photograph (linearised);
//! - `warp_psnr_db` and `warp_hole_fraction`: the warped view against the held-out photograph
//!   over the pixels it fills, and the share of the pixels the truth sees that it leaves empty.

use super::{
    apply_overrides, run_case, CaseResult, Context, Findings, Settings, SettingsKey, StageError, Synthesis,
    ViewRecipe,
};
use crate::ibr::{self, texture, warp, View};
use crate::image::Image;
use crate::math::WorldToCamera;
use crate::pipeline::cache::{scene_digest, Pass};
use crate::pipeline::metric::{Better, Metric};
use crate::render;
use crate::sfm::{self, eval};
use glam::DVec3;
use nalgebra::Vector3;
use serde::Deserialize;

/// A `novel-view` case (module docs).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Scene file, relative to the pipeline file.
    pub scene: String,
    /// Training views (default 12, 3 to 200).
    #[serde(default = "default_views")]
    pub views: usize,
    /// The point every camera looks at.
    pub target: [f64; 3],
    /// Horizontal distance of the cameras from `target`.
    pub radius: f64,
    /// The two heights (z) the training views take in turn.
    pub heights: [f64; 2],
    /// The arc the training views span, in degrees, centred on the −y side of `target`
    /// (default 360: all round).
    #[serde(default = "default_arc")]
    pub arc_deg: f64,
    /// The held-out camera: its place on the arc (0 to 1, the training views at k/views of it)
    /// and its height.
    pub held_out: [f64; 2],
    /// Samples per pixel (default: the scene's).
    pub spp: Option<u32>,
    /// Texels per side of the texture (default 512).
    #[serde(default = "default_texture_size")]
    pub texture_size: u32,
    /// Grid cells across the surface's extent (default 96).
    #[serde(default = "default_resolution")]
    pub surface_resolution: usize,
    /// `"from:CASE"`: the camera an earlier calibrate case estimated, given to structure from
    /// motion as the photographs' intrinsics instead of the true camera (a chained case; the
    /// texture and the warp take the cameras SfM hands on). It runs alone too, with the true
    /// camera (`chain`). The calibrated camera must be this scene's.
    pub camera: Option<String>,
    /// A deliberate error added to the inherited camera (a chained case only): its focal
    /// lengths scaled by 1 + `focal_rel`, `k1` added to its k1 (default none).
    pub perturb: Option<super::chain::Perturb>,
}

fn default_views() -> usize {
    12
}
fn default_arc() -> f64 {
    360.0
}
fn default_texture_size() -> u32 {
    512
}
fn default_resolution() -> usize {
    96
}

pub struct Input {
    sfm: sfm::Input,
    /// Per view, its photograph linearised (what the texture and the warp read).
    linear: Vec<Image>,
    held_out: usize,
}

pub struct Truth {
    /// The case's name: its kept images go into a folder of that name.
    case: String,
    poses: Vec<WorldToCamera>,
    /// Sampled true surface: points and normals (world frame).
    points: Vec<DVec3>,
    normals: Vec<DVec3>,
    /// The held-out view's albedo, the depth it sees, and its photograph (linearised).
    albedo: Image,
    depth: Image,
    photo: Image,
    /// The held-out view rendered with every albedo 1.
    shading: Image,
    /// The true camera, and the training photographs (linearised): the texture made again with
    /// the true cameras tells the share of its error that SfM's cameras add.
    camera: crate::math::CameraModel,
    training: Vec<Image>,
}

pub struct Output {
    registered: usize,
    sfm_poses: Vec<Option<WorldToCamera>>,
    mesh: crate::surface::march::Mesh,
    drawn: (Image, Image),
    warped: warp::Output,
    seen_fraction: f64,
    texture_size: u32,
    seconds: [f64; 4],
}

fn check(c: &Config) -> Result<(), StageError> {
    let finite = c.target.iter().chain(&c.heights).chain(&c.held_out).all(|v| v.is_finite());
    if !(3..=200).contains(&c.views)
        || !finite
        || !(c.radius.is_finite() && c.radius > 0.0)
        || !(c.arc_deg > 0.0 && c.arc_deg <= 360.0)
        || !(0.0..=1.0).contains(&c.held_out[0])
    {
        return Err(StageError::Config(format!(
            "views = {}, radius = {}, heights = {:?}, arc_deg = {}, held_out = {:?}: expected 3 to 200 views, finite numbers, a positive radius, an arc of (0°, 360°] and a held-out place from 0 to 1",
            c.views, c.radius, c.heights, c.arc_deg, c.held_out
        )));
    }
    Ok(())
}

pub fn synthesize(c: &Config, ctx: &Context) -> Result<Synthesis<Input, Truth>, StageError> {
    synthesize_given(c, ctx, None)
}

/// `synthesize`, the photographs' intrinsics `given`'s first camera (an upstream case's
/// estimate, or the truth it had, which is the second) instead of the scene's.
fn synthesize_given(
    c: &Config,
    ctx: &Context,
    given: Option<(crate::math::CameraModel, crate::math::CameraModel)>,
) -> Result<Synthesis<Input, Truth>, StageError> {
    check(c)?;
    let scene_path = ctx.dir.join(&c.scene);
    let mut scene = render::load(&scene_path)?;
    let digest = scene_digest(&scene_path)?;
    let mut settings = render::Settings::from_scene(&scene);
    apply_overrides(&mut settings, c.spp, None)?;
    let camera = scene.camera;
    if let Some((_, upstream_truth)) = &given {
        super::chain::check_same_camera(c.camera.as_deref().unwrap_or(""), upstream_truth, &camera)?;
    }
    let intrinsics = given.map_or(camera, |(g, _)| g);
    // Training views over the arc (all round, the last does not repeat the first), then the
    // held-out one.
    let span = if c.arc_deg >= 360.0 { c.views } else { c.views - 1 };
    let mut places: Vec<(f64, f64)> =
        (0..c.views).map(|k| (k as f64 / span as f64, c.heights[k % 2])).collect();
    places.push((c.held_out[0], c.held_out[1]));
    let bar = render::progress_bar(places.len() as u64, &format!("{} views", ctx.case), ctx.progress);
    let (mut images, mut linear, mut poses) = (Vec::new(), Vec::new(), Vec::new());
    let (mut points, mut normals) = (Vec::new(), Vec::new());
    let mut held = None;
    for (k, &(f, z)) in places.iter().enumerate() {
        scene.t_world_cam =
            super::sfm::arc_camera(k, DVec3::from_array(c.target), c.radius, z, c.arc_deg, f)?;
        settings.seed = render::sampler::mix64(ctx.seed ^ (k as u64 + 1));
        let recipe = ViewRecipe {
            product: "novel-view-rgb",
            scene: &digest,
            t_world_cam: super::pose_key(&scene.t_world_cam),
            settings: SettingsKey::from(&settings),
        };
        let name = format!("view{k:03}.png");
        let rendered = ctx.cache.images(ctx.case, &name, &recipe, || {
            Ok::<_, StageError>(vec![render::try_render(&scene, &settings)?.mean])
        })?;
        bar.inc(1);
        let Some(rendered) = rendered else { continue };
        let photo = super::sfm::photograph(name, rendered, &camera, intrinsics)?;
        // The photograph as the texture reads it: its 8-bit codes, decoded.
        let lin = Image {
            width: camera.width,
            height: camera.height,
            channels: 3,
            data: photo
                .rgb8
                .iter()
                .flat_map(|p| p.map(|v| crate::image::srgb_decode(v as f32 / 255.0)))
                .collect(),
        };
        let truth = render::truth(&scene, None);
        if k < c.views {
            // One true point per 4×4 pixels keeps the kd-tree small.
            for j in (0..camera.height).step_by(4) {
                for i in (0..camera.width).step_by(4) {
                    if truth.depth.pixel(i, j)[0] > 0.0 {
                        let q = truth.position.pixel(i, j);
                        let n = truth.normal.pixel(i, j);
                        points.push(DVec3::new(q[0] as f64, q[1] as f64, q[2] as f64));
                        normals.push(DVec3::new(n[0] as f64, n[1] as f64, n[2] as f64));
                    }
                }
            }
        } else {
            // The held-out view's shading: the same render with every albedo 1. With direct
            // lighting only, a Lambertian point's radiance is its albedo times this.
            for m in scene.materials.iter_mut() {
                m.albedo = render::texture::Texture::Constant(glam::Vec3A::ONE);
            }
            let white = ViewRecipe { product: "novel-view-shading", ..recipe };
            let shading = ctx.cache.images(ctx.case, "shading.exr", &white, || {
                Ok::<_, StageError>(vec![render::try_render(&scene, &settings)?.mean])
            })?;
            let Some(mut shading) = shading else { continue };
            let Some(shading) = shading.pop().filter(|i| i.channels == 3 && i.data.len() == lin.data.len())
            else {
                return Err(StageError::Config("the cached shading render has the wrong size".into()));
            };
            held = Some((truth.albedo, truth.depth, lin.clone(), shading));
        }
        images.push(photo);
        linear.push(lin);
        poses.push(scene.t_world_cam.inverse());
    }
    bar.finish_and_clear();
    if ctx.renders_only() {
        return Ok(None);
    }
    let Some((albedo, depth, photo, shading)) = held else {
        return Err(StageError::Config("the held-out view was not rendered".into()));
    };
    let note = format!(
        "{}: {} training views of {}×{} px at {} spp on a {}° ring of radius {} about {:?} at heights {:?}; held out at {:.2} of the arc, height {}.",
        c.scene, c.views, camera.width, camera.height, settings.spp, c.arc_deg, c.radius, c.target, c.heights, c.held_out[0], c.held_out[1]
    );
    let training = linear[..c.views].to_vec();
    Ok(Some((
        Input { sfm: sfm::Input { images, prepared: sfm::Prepared::default() }, linear, held_out: c.views },
        Truth {
            case: ctx.case.to_string(),
            poses,
            points,
            normals,
            albedo,
            depth,
            photo,
            shading,
            camera,
            training,
        },
        Findings { notes: vec![note], ..Default::default() },
    )))
}

fn view_of(out: &sfm::Output, k: usize) -> Option<View> {
    let pose = out.reconstruction.poses[k].as_ref()?;
    Some(View { camera: out.cameras[k], t_world_cam: WorldToCamera::from(pose).inverse() })
}

pub fn solve(c: &Config, input: &Input) -> Result<Output, StageError> {
    let t = std::time::Instant::now();
    let out = sfm::run(&input.sfm, &super::sfm::config(8192, false, &None, false, &None)?)?;
    let sfm_s = t.elapsed().as_secs_f64();
    let Some(held) = view_of(&out, input.held_out) else {
        return Err(StageError::Ibr(ibr::Error::BadInput(
            "the held-out view was not registered: no camera to draw into".into(),
        )));
    };
    let t = std::time::Instant::now();
    let points: Vec<DVec3> =
        out.reconstruction.seen_points().map(|(_, p, _)| DVec3::new(p.xyz.x, p.xyz.y, p.xyz.z)).collect();
    let surface = crate::surface::run(
        &crate::surface::Input { points, normals: Vec::new() },
        &crate::surface::Config { resolution: c.surface_resolution, ..Default::default() },
    )?;
    let surface_s = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let training: Vec<(usize, View)> =
        (0..input.held_out).filter_map(|k| view_of(&out, k).map(|v| (k, v))).collect();
    let photos: Vec<texture::Photo> = training
        .iter()
        .map(|&(k, view)| texture::Photo { name: format!("view {k}"), image: &input.linear[k], view })
        .collect();
    let mesh = surface.mesh;
    let tex = texture::run(&mesh, &photos, &texture::Config { size: c.texture_size, ..Default::default() })?;
    let drawn = texture::draw(&mesh, &tex.atlas, &tex.texture, &held);
    let texture_s = t.elapsed().as_secs_f64();
    // Backward warping from the two training views nearest the held-out camera.
    let t = std::time::Instant::now();
    let centre = held.t_world_cam.centre();
    let mut nearest = training.clone();
    nearest.sort_by(|a, b| {
        a.1.t_world_cam.centre().distance(centre).total_cmp(&b.1.t_world_cam.centre().distance(centre))
    });
    nearest.truncate(2);
    let depths: Vec<Image> = nearest
        .iter()
        .map(|(_, v)| {
            let r = ibr::raster::rasterise(&mesh, v);
            Image {
                width: r.width,
                height: r.height,
                channels: 1,
                data: r.depth.iter().map(|&z| if z.is_finite() { z } else { 0.0 }).collect(),
            }
        })
        .collect();
    let sources: Vec<ibr::Source> = nearest
        .iter()
        .zip(&depths)
        .map(|(&(k, view), depth)| ibr::Source {
            name: format!("view {k}"),
            image: &input.linear[k],
            depth,
            view,
        })
        .collect();
    let warped = warp::warp(&sources, &held, &warp::Config::default())?;
    let warp_s = t.elapsed().as_secs_f64();
    Ok(Output {
        registered: out.reconstruction.registered_count(),
        sfm_poses: out.reconstruction.poses.iter().map(|p| p.as_ref().map(WorldToCamera::from)).collect(),
        mesh,
        drawn,
        warped,
        seen_fraction: tex.summary.seen_fraction,
        texture_size: c.texture_size,
        seconds: [sfm_s, surface_s, texture_s, warp_s],
    })
}

/// A true camera pose carried into the reconstruction's frame, given the similarity
/// (s, R, t) with X_true = s·R·X_rec + t: p_cam = R_c·(s·R·X + t) + t_c, divided by s (a
/// pinhole sees a scaled world the same).
fn into_reconstruction(
    p: &WorldToCamera,
    (s, r, t): (f64, nalgebra::Matrix3<f64>, Vector3<f64>),
) -> WorldToCamera {
    let rc = nalgebra::Matrix3::from_fn(|i, j| p.rotation.col(j)[i]);
    let tc = Vector3::new(p.translation.x, p.translation.y, p.translation.z);
    let rot = rc * r;
    let tr = (rc * t + tc) / s;
    WorldToCamera(crate::math::Pose {
        rotation: glam::DMat3::from_cols(
            DVec3::new(rot[(0, 0)], rot[(1, 0)], rot[(2, 0)]),
            DVec3::new(rot[(0, 1)], rot[(1, 1)], rot[(2, 1)]),
            DVec3::new(rot[(0, 2)], rot[(1, 2)], rot[(2, 2)]),
        ),
        translation: DVec3::new(tr.x, tr.y, tr.z),
    })
}

/// PSNR (peak 1) of `a` against `b` over the pixels `keep` holds, and their number.
fn psnr(a: &Image, b: &Image, keep: &[bool]) -> (Option<f64>, usize) {
    let c = a.channels as usize;
    let (mut se, mut n) = (0.0f64, 0usize);
    for (i, _) in keep.iter().enumerate().filter(|(_, &k)| k) {
        for ch in 0..c {
            se += ((a.data[i * c + ch] - b.data[i * c + ch]) as f64).powi(2);
        }
        n += 1;
    }
    let mse = se / (n * c).max(1) as f64;
    ((n > 0 && mse > 0.0).then(|| 10.0 * (1.0 / mse).log10()), n)
}

/// The pixels whose 3×3 neighbourhood `inside` holds throughout.
fn eroded(inside: &[bool], w: usize, h: usize) -> Vec<bool> {
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            x > 0
                && y > 0
                && x + 1 < w
                && y + 1 < h
                && (0..9).all(|k| inside[(y + k / 3 - 1) * w + x + k % 3 - 1])
        })
        .collect()
}

pub fn validate(out: &Output, truth: &Truth) -> Findings {
    let mut f = Findings::default();
    let m = &mut f.metrics;
    m.push(Metric::new("registered_images", out.registered as f64, "images", Better::Higher));
    // The similarity taking the reconstruction's frame to the truth's.
    let (src, dst): (Vec<Vector3<f64>>, Vec<Vector3<f64>>) = out
        .sfm_poses
        .iter()
        .zip(&truth.poses)
        .filter_map(|(e, t)| {
            let e = e.as_ref()?.inverse().centre();
            let t = t.inverse().centre();
            Some((Vector3::new(e.x, e.y, e.z), Vector3::new(t.x, t.y, t.z)))
        })
        .unzip();
    let similarity = eval::similarity(&src, &dst);
    let aligned = similarity.map(|(s, r, t)| {
        let to = |p: DVec3| {
            let q = s * r * Vector3::new(p.x, p.y, p.z) + t;
            DVec3::new(q.x, q.y, q.z)
        };
        let turn = |n: DVec3| {
            let q = r * Vector3::new(n.x, n.y, n.z);
            DVec3::new(q.x, q.y, q.z)
        };
        let vertices: Vec<DVec3> = out.mesh.vertices.iter().map(|&p| to(p)).collect();
        let normals: Vec<DVec3> = crate::ibr::atlas::face_normals(&out.mesh).into_iter().map(turn).collect();
        (vertices, normals)
    });
    match &aligned {
        Some((vertices, normals)) if !vertices.is_empty() && !truth.points.is_empty() => {
            let (lo, hi) = truth
                .points
                .iter()
                .fold((DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)), |(l, h), p| {
                    (l.min(*p), h.max(*p))
                });
            let extent = (hi - lo).length();
            let (Ok(tree_truth), Ok(tree_mesh)) = (
                crate::surface::Cloud::new(truth.points.clone()),
                crate::surface::Cloud::new(vertices.clone()),
            ) else {
                f.notes.push("the surface could not be indexed: no surface metrics".into());
                return f;
            };
            // The nearest point of `tree` to `p`: its distance and index.
            let near = |tree: &crate::surface::Cloud, p: DVec3| {
                let j = tree.nearest(p, 1).first().copied().unwrap_or(0) as usize;
                (tree.points[j].distance(p), j)
            };
            let accuracy =
                vertices.iter().map(|&p| near(&tree_truth, p).0).sum::<f64>() / vertices.len() as f64;
            let completeness =
                truth.points.iter().map(|&p| near(&tree_mesh, p).0).sum::<f64>() / truth.points.len() as f64;
            m.push(Metric::new("chamfer_rel", 0.5 * (accuracy + completeness) / extent, "", Better::Lower));
            m.push(Metric::new("surface_accuracy_rel", accuracy / extent, "", Better::Lower));
            m.push(Metric::new("surface_completeness_rel", completeness / extent, "", Better::Lower));
            let mut angles: Vec<f64> = out
                .mesh
                .triangles
                .iter()
                .zip(normals)
                .filter(|(_, n)| n.length_squared() > 0.0)
                .map(|(t, n)| {
                    let centre = t.iter().map(|&i| vertices[i as usize]).sum::<DVec3>() / 3.0;
                    let (_, j) = near(&tree_truth, centre);
                    n.dot(truth.normals[j]).abs().min(1.0).acos().to_degrees()
                })
                .collect();
            m.push(Metric::maybe(
                "normal_err_median_deg",
                crate::math::stats::median(&mut angles),
                "°",
                Better::Lower,
                "no triangle",
            ));
        }
        _ => {
            for name in ["chamfer_rel", "surface_accuracy_rel", "surface_completeness_rel"] {
                m.push(Metric::missing(name, "", Better::Lower, "the reconstruction could not be aligned to the truth (fewer than 3 registered cameras, or all on a line)"));
            }
            m.push(Metric::missing("normal_err_median_deg", "°", Better::Lower, "no alignment"));
        }
    }
    let (w, h) = (truth.depth.width as usize, truth.depth.height as usize);
    let sees: Vec<bool> = truth.depth.data.iter().map(|&z| z > 0.0).collect();
    let (drawn, mask) = &out.drawn;
    let both: Vec<bool> = sees.iter().zip(&mask.data).map(|(&s, &m)| s && m > 0.0).collect();
    let keep = eroded(&both, w, h);
    // The texture holds radiance, albedo times shading: divided by the true shading, over the
    // pixels lit by at least a quarter of the median (out of the sun's shadows).
    let lum = |img: &Image, i: usize| crate::image::luminance(&img.data[i * 3..i * 3 + 3]);
    let mut lit: Vec<f64> = (0..keep.len()).filter(|&i| keep[i]).map(|i| lum(&truth.shading, i)).collect();
    let floor = 0.25 * crate::math::stats::median(&mut lit).unwrap_or(0.0);
    let lit: Vec<bool> =
        (0..keep.len()).map(|i| keep[i] && lum(&truth.shading, i) > floor && floor > 0.0).collect();
    let albedo_psnr = |drawn: &Image| {
        let est = Image {
            data: drawn
                .data
                .iter()
                .zip(&truth.shading.data)
                .map(|(&d, &s)| if s > 0.0 { d / s } else { 0.0 })
                .collect(),
            ..drawn.clone()
        };
        psnr(&est, &truth.albedo, &lit)
    };
    let (tex, n) = albedo_psnr(drawn);
    m.push(Metric::maybe(
        "texture_psnr_db",
        tex,
        "dB",
        Better::Higher,
        "no pixel drawn inside the true silhouette",
    ));
    // The same texture from the true cameras, carried into the reconstruction's frame, on the
    // same mesh: what is left is the mesh's and the texture's own error.
    let true_cameras = similarity.and_then(|sim| {
        let into = |p: &WorldToCamera| View {
            camera: truth.camera,
            t_world_cam: into_reconstruction(p, sim).inverse(),
        };
        let photos: Vec<texture::Photo> = truth
            .training
            .iter()
            .zip(&truth.poses)
            .enumerate()
            .map(|(k, (image, p))| texture::Photo { name: format!("view {k}"), image, view: into(p) })
            .collect();
        let held = into(truth.poses.last()?);
        let tex = texture::run(
            &out.mesh,
            &photos,
            &texture::Config { size: out.texture_size, ..Default::default() },
        )
        .ok()?;
        let (drawn, _) = texture::draw(&out.mesh, &tex.atlas, &tex.texture, &held);
        albedo_psnr(&drawn).0
    });
    m.push(Metric::maybe(
        "texture_psnr_true_cameras_db",
        true_cameras,
        "dB",
        Better::Higher,
        "no alignment of the reconstruction to the truth, or no texture from the true cameras",
    ));
    let (view, _) = psnr(drawn, &truth.photo, &keep);
    m.push(Metric::maybe(
        "view_psnr_db",
        view,
        "dB",
        Better::Higher,
        "no pixel drawn inside the true silhouette",
    ));
    let filled: Vec<bool> = sees.iter().zip(&out.warped.mask.data).map(|(&s, &m)| s && m > 0.0).collect();
    let (wp, wn) = psnr(&out.warped.image, &truth.photo, &eroded(&filled, w, h));
    m.push(Metric::maybe(
        "warp_psnr_db",
        wp,
        "dB",
        Better::Higher,
        "the warp filled no pixel the truth sees",
    ));
    let seen = sees.iter().filter(|&&s| s).count().max(1);
    let holes = sees.iter().zip(&filled).filter(|(&s, &f)| s && !f).count();
    m.push(Metric::new("warp_hole_fraction", holes as f64 / seen as f64, "", Better::Lower));
    m.push(Metric::new("texture_seen_fraction", out.seen_fraction, "", Better::Higher));
    let [a, b, c, d] = out.seconds;
    f.notes.push(format!(
        "{} of {} views registered; mesh of {} triangles; texture PSNR over {n} pixels, warp over {wn}; sfm {a:.2} s, surface {b:.2} s, texture and drawing {c:.2} s, warp {d:.3} s.",
        out.registered,
        truth.poses.len(),
        out.mesh.triangles.len()
    ));
    let folder = std::path::Path::new(&truth.case);
    f.files.push((folder.join("textured.png"), super::Kept::Image(drawn.clone())));
    f.files.push((folder.join("warped.png"), super::Kept::Image(out.warped.image.clone())));
    f
}

impl Settings for Config {
    fn headline(&self) -> &'static str {
        "texture_psnr_db"
    }
    fn run(&self, ctx: &Context) -> Result<CaseResult, StageError> {
        let chain = super::chain::Chain {
            headline: "texture_psnr_db",
            unit: "dB",
            errors: &[
                "texture_psnr_db",
                "view_psnr_db",
                "warp_psnr_db",
                "chamfer_rel",
                "normal_err_median_deg",
            ],
        };
        super::chain::run_on_camera(&self.camera, self.perturb, ctx, &chain, |given| {
            run_case(|| synthesize_given(self, ctx, given), |i| solve(self, i), validate)
        })
    }
    fn share(&self, ctx: &Context, pass: Pass) -> Option<Result<(), StageError>> {
        (pass == Pass::Renders).then(|| synthesize(self, ctx).map(|_| ()))
    }
    fn upstream(&self) -> Vec<(&'static str, String, &'static str)> {
        super::chain::camera_upstream(&self.camera)
    }
}
