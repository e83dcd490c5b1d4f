//! `lumen sfm`: cameras and sparse points from overlapping photographs, written as a COLMAP
//! text model, a PLY point cloud and a summary.

use anyhow::{bail, Context, Result};
use lumen::image::{self, filter::Grey};
use lumen::math::{CameraModel, Distortion, Intrinsics};
use lumen::sfm::{self, colmap};
use std::path::{Path, PathBuf};

/// `lumen sfm`'s flags.
#[derive(clap::Args)]
pub struct SfmArgs {
    /// A folder of photographs (.jpg, .jpeg, .png, .tif, .tiff), taken in name order.
    #[arg(long)]
    pub images: PathBuf,
    /// The camera: a calibration from `lumen calibrate` or OpenCV (.yaml/.yml/.json), or a
    /// text file holding the 3×3 camera matrix K (no distortion). Without it: a focal length
    /// of 1.2 × the longer side and a centred principal point (not refined yet).
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// Keypoints per image at most (COLMAP: 8192).
    #[arg(long, default_value_t = 8192)]
    pub max_features: usize,
    /// Output folder: cameras.txt, images.txt, points3D.txt, points.ply, summary.json.
    #[arg(long)]
    pub out: PathBuf,
}

fn read_camera(path: &Path) -> Result<CameraModel> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if ext == "txt" {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("--camera {}: cannot read", path.display()))?;
        let v: Result<Vec<f64>, _> = text.split_whitespace().map(str::parse::<f64>).collect();
        let v = v.map_err(|_| {
            anyhow::anyhow!("--camera {}: expected 9 numbers (K, row by row)", path.display())
        })?;
        if v.len() != 9 || v.iter().any(|x| !x.is_finite()) || v[6] != 0.0 || v[7] != 0.0 || v[8] != 1.0 {
            bail!(
                "--camera {}: expected a 3×3 camera matrix [fx s cx; 0 fy cy; 0 0 1], 9 numbers",
                path.display()
            );
        }
        if v[0] <= 0.0 || v[4] <= 0.0 {
            bail!("--camera {}: focal lengths {} and {} must be positive", path.display(), v[0], v[4]);
        }
        // Width and height come from the images.
        return Ok(CameraModel {
            width: 0,
            height: 0,
            intrinsics: Intrinsics { fx: v[0], fy: v[4], cx: v[2], cy: v[5] },
            distortion: Distortion::default(),
        });
    }
    let c = lumen::calib::file::read(path).with_context(|| format!("--camera {}", path.display()))?;
    Ok(c.camera())
}

pub fn run(a: &SfmArgs) -> Result<()> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(&a.images)
        .with_context(|| format!("--images {}: not a readable folder", a.images.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            let e = p.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
            matches!(e.as_str(), "jpg" | "jpeg" | "png" | "tif" | "tiff")
        })
        .collect();
    files.sort();
    if files.len() < 2 {
        bail!(
            "--images {}: {} photograph(s) (.jpg, .png, .tif), at least 2 needed",
            a.images.display(),
            files.len()
        );
    }
    if a.max_features < 16 {
        bail!("--max-features {}: expected at least 16", a.max_features);
    }
    let given = a.camera.as_deref().map(read_camera).transpose()?;
    let mut images = Vec::new();
    for (n, f) in files.iter().enumerate() {
        eprintln!("reading {}/{}: {}", n + 1, files.len(), f.display());
        let img = image::io::read(f).with_context(|| format!("{}", f.display()))?;
        let grey = Grey::from_image(&img);
        let c = img.channels as usize;
        let rgb8 = img
            .data
            .chunks_exact(c)
            .map(|p| {
                let q = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
                if c >= 3 {
                    [q(p[0]), q(p[1]), q(p[2])]
                } else {
                    [q(p[0]); 3]
                }
            })
            .collect();
        let camera = match given {
            Some(mut cam) if cam.width == 0 => {
                cam.width = img.width;
                cam.height = img.height;
                cam
            }
            Some(cam) => cam,
            None => {
                let f = 1.2 * img.width.max(img.height) as f64;
                CameraModel {
                    width: img.width,
                    height: img.height,
                    intrinsics: Intrinsics {
                        fx: f,
                        fy: f,
                        cx: (img.width as f64 - 1.0) / 2.0,
                        cy: (img.height as f64 - 1.0) / 2.0,
                    },
                    distortion: Distortion::default(),
                }
            }
        };
        let name = f.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        images.push(sfm::Image { name, grey, rgb8, camera });
    }
    if given.is_none() {
        eprintln!("warning: no --camera: a focal length of 1.2 × the longer side is assumed and not refined");
    }
    let input = sfm::Input { images };
    let config = sfm::Config {
        features: sfm::features::Options { max_features: a.max_features, ..Default::default() },
        ..Default::default()
    };
    eprintln!("extracting features and matching {} images …", input.images.len());
    let out = sfm::run(&input, &config)?;
    let rec = &out.reconstruction;
    std::fs::create_dir_all(&a.out).with_context(|| format!("--out {}: cannot create", a.out.display()))?;
    let (cameras, images_txt, points) = colmap::text_model(&input, &out);
    let registered = rec.registered_count();
    let (kept, observations) = rec.seen_points().fold((0, 0), |(k, o), (_, _, obs)| (k + 1, o + obs.len()));
    let summary = serde_json::json!({
        "images": input.images.len(),
        "registered_images": registered,
        "points": kept,
        "mean_track_length": if kept > 0 { observations as f64 / kept as f64 } else { 0.0 },
        "mean_observations_per_image": if registered > 0 { observations as f64 / registered as f64 } else { 0.0 },
        "reprojection_rms_px": rec.rms_px,
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
    for (name, text) in files {
        let p = a.out.join(name);
        image::io::write_atomically(&p, |tmp| std::fs::write(tmp, &text).map_err(|e| e.to_string()))?;
    }
    println!(
        "registered {registered} of {} images, {kept} points, reprojection RMS {:.3} px; wrote {}",
        input.images.len(),
        rec.rms_px,
        a.out.display()
    );
    for (i, why) in &rec.unregistered {
        println!("  not registered: {}: {why}", input.images[*i].name);
    }
    Ok(())
}
