//! `lumen sfm`: cameras and sparse points from overlapping photographs, written as a COLMAP
//! text model, a PLY point cloud and a summary.

use anyhow::{bail, Context, Result};
use lumen::image;
use lumen::sfm::{self, colmap};
use std::path::PathBuf;

/// `lumen sfm`'s flags.
#[derive(clap::Args)]
pub struct SfmArgs {
    /// A folder of photographs (.jpg, .jpeg, .png, .tif, .tiff), taken in name order.
    #[arg(long)]
    pub images: PathBuf,
    /// The camera: a calibration from `lumen calibrate` or OpenCV (.yaml/.yml/.json), or a
    /// text file holding the 3×3 camera matrix K (no distortion). Without it: the focal
    /// length the file's EXIF gives (FocalLengthIn35mmFilm, or FocalLength with the focal
    /// plane's resolution), else 1.2 × the longer side (COLMAP's guess), a centred principal
    /// point and no distortion, refined by bundle adjustment (`--refine`; images of one size
    /// share one camera).
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// Keypoints per image at most (COLMAP: 8192).
    #[arg(long, default_value_t = 8192)]
    pub max_features: usize,
    /// Without --camera: the intrinsics the images share that bundle adjustment refines from
    /// the guess, comma-separated, of focal, principal-point, k1, k2 (default focal,k1, as
    /// COLMAP's SIMPLE_RADIAL camera).
    #[arg(long, value_delimiter = ',')]
    pub refine: Option<Vec<String>>,
    /// Which pairs of images are matched: exhaustive (every pair, the default) or
    /// sequential:N, for images taken in sequence (name order): each with the next N and with
    /// those 2^k after it for k < N (COLMAP's sequential matcher with quadratic overlap).
    #[arg(long, default_value = "exhaustive")]
    pub pairs: String,
    /// Match each verified pair again among only the keypoints near each other's epipolar
    /// lines (COLMAP's guided matching; off by default, as there: on the renders and
    /// Herz-Jesu it adds matches and costs accuracy, docs/measurements.md, "Structure from motion").
    #[arg(long)]
    pub guided_matching: bool,
    /// Output folder: cameras.txt, images.txt, points3D.txt, points.ply, summary.json.
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(a: &SfmArgs) -> Result<()> {
    let files = sfm::input::photographs(&a.images).with_context(|| "--images".to_string())?;
    if a.max_features < 16 {
        bail!("--max-features {}: expected at least 16", a.max_features);
    }
    let given = a
        .camera
        .as_deref()
        .map(sfm::input::read_camera)
        .transpose()
        .with_context(|| "--camera".to_string())?;
    let input = sfm::input::read_images(&files, given, |n, total, f| {
        eprintln!("reading {}/{total}: {}", n + 1, f.display())
    })?;
    let pairs: sfm::mapper::PairSelection = a.pairs.parse().map_err(|e| anyhow::anyhow!("--pairs {e}"))?;
    let refine = match (&given, &a.refine) {
        (Some(_), Some(_)) => bail!("--refine: only without --camera (a given camera is kept as it is)"),
        (Some(_), None) => sfm::bundle::Refine::NONE,
        (None, None) => sfm::GUESSED_REFINE,
        (None, Some(names)) => {
            sfm::bundle::Refine::from_names(names).map_err(|e| anyhow::anyhow!("--refine {e}"))?
        }
    };
    if given.is_none() {
        // Each way a focal length was guessed, with how many images it was guessed for.
        let mut sources: Vec<(&str, usize)> = Vec::new();
        for s in input.images.iter().filter_map(|im| im.guess.as_deref()) {
            match sources.iter_mut().find(|e| e.0 == s) {
                Some(e) => e.1 += 1,
                None => sources.push((s, 1)),
            }
        }
        let sources: Vec<String> = sources.iter().map(|(s, n)| format!("{s} for {n} image(s)")).collect();
        eprintln!(
            "no --camera: focal length from {}; principal point at the centre, no distortion; refined by bundle adjustment ({refine:?})",
            sources.join(", ")
        );
    }
    let config = sfm::Config {
        features: sfm::features::Options { max_features: a.max_features, ..Default::default() },
        mapper: sfm::mapper::Options {
            refine,
            guided_matching: a.guided_matching,
            pairs,
            ..Default::default()
        },
        progress: true,
    };
    eprintln!("extracting features and matching {} images …", input.images.len());
    let out = sfm::run(&input, &config)?;
    let rec = &out.reconstruction;
    let (cameras, images_txt, points) = colmap::text_model(&input, &out);
    let registered = rec.registered_count();
    let (kept, observations) = rec.seen_points().fold((0, 0), |(k, o), (_, _, obs)| (k + 1, o + obs.len()));
    let summary = serde_json::json!({
        "images": input.images.len(),
        "registered_images": registered,
        "points": kept,
        // Quantities without a point or an image to measure are null, with the reason in
        // `missing`, never a 0 that reads as a perfect result.
        "mean_track_length": (kept > 0).then(|| observations as f64 / kept as f64),
        "mean_observations_per_image": (registered > 0).then(|| observations as f64 / registered as f64),
        "reprojection_rms_px": (kept > 0).then_some(rec.rms_px),
        "missing": if kept > 0 { serde_json::json!({}) } else {
            serde_json::json!({
                "mean_track_length": "no point was triangulated",
                "mean_observations_per_image": if registered > 0 { "no point was triangulated" } else { "no image was registered" },
                "reprojection_rms_px": "no point was triangulated",
            })
        },
        "cameras": out.cameras.iter().zip(&input.images).map(|(c, im)| serde_json::json!({"image": im.name, "fx": c.intrinsics.fx, "fy": c.intrinsics.fy, "cx": c.intrinsics.cx, "cy": c.intrinsics.cy, "k1": c.distortion.k1, "k2": c.distortion.k2, "refined": c != &im.camera, "guess": im.guess})).collect::<Vec<_>>(),
        "unregistered": rec.unregistered.iter().map(|(i, why)| serde_json::json!({"image": input.images[*i].name, "reason": why})).collect::<Vec<_>>(),
        "pairs": rec.pairs.iter().map(|p| serde_json::json!({"a": input.images[p.a].name, "b": input.images[p.b].name, "matches": p.matches, "inliers": p.inliers, "configuration": p.configuration})).collect::<Vec<_>>(),
        "time_s": {
            "extraction": out.extraction_s,
            "matching": rec.matching_s,
            "geometric_verification": rec.verification_s,
            "mapping": rec.mapping_s,
            "bundle_adjustment": rec.bundle_s,
        },
    });
    let files = [
        ("cameras.txt", cameras),
        ("images.txt", images_txt),
        ("points3D.txt", points),
        ("points.ply", colmap::ply(&out)),
        ("summary.json", serde_json::to_string_pretty(&summary)? + "\n"),
    ];
    image::io::write_together(&a.out, |dir| -> Result<()> {
        for (name, text) in files {
            let p = dir.join(name);
            image::io::write_atomically(&p, |tmp| std::fs::write(tmp, &text))?;
        }
        Ok(())
    })?;
    let rms = if kept > 0 {
        format!("reprojection RMS {:.3} px", rec.rms_px)
    } else {
        "no reprojection error (no point)".into()
    };
    println!(
        "registered {registered} of {} images, {kept} points, {rms}; wrote {}",
        input.images.len(),
        a.out.display()
    );
    if let (None, Some(c)) = (given, out.cameras.first()) {
        let start = &input.images[0].camera;
        let (k, k0, d) = (&c.intrinsics, &start.intrinsics, &c.distortion);
        if c == start {
            println!("  intrinsics kept at the guess (focal length {:.1} px): they are refined only where the images share one camera (one size and one guess), once three are registered", k0.fx);
        }
        if k.fx != k0.fx {
            println!("  focal length refined from {:.1} to {:.1} px", k0.fx, k.fx);
        }
        if (k.cx, k.cy) != (k0.cx, k0.cy) {
            println!(
                "  principal point refined from ({:.2}, {:.2}) to ({:.2}, {:.2}) px",
                k0.cx, k0.cy, k.cx, k.cy
            );
        }
        if d.k1 != 0.0 || d.k2 != 0.0 {
            println!("  radial distortion refined: k1 = {:.5}, k2 = {:.5}", d.k1, d.k2);
        }
    }
    for (i, why) in &rec.unregistered {
        println!("  not registered: {}: {why}", input.images[*i].name);
    }
    Ok(())
}
