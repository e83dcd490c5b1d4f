//! The reconstruction as COLMAP's text model (`cameras.txt`, `images.txt`, `points3D.txt`,
//! the format of COLMAP's `model_converter --output_type TXT`) and a PLY point cloud.
//!
//! COLMAP's conventions differ from lumen's in one place: its pixel centres are at +0.5 (the
//! image's corner is (0, 0)), so every pixel coordinate and principal point gets +0.5 on
//! the way out. Poses are world-to-camera, the rotation as a unit quaternion QW QX QY QZ
//! (QW ≥ 0) and the translation T, as lumen's. A camera without distortion is `PINHOLE`
//! (fx fy cx cy), one with it `FULL_OPENCV` (fx fy cx cy k1 k2 p1 p2 k3 0 0 0), with the
//! keypoints as detected (distorted). Unregistered images are left out of images.txt.

use super::{mapper::Reconstruction, Input, Output};
use std::fmt::Write;

/// The three files' texts: (cameras.txt, images.txt, points3D.txt).
pub fn text_model(input: &Input, out: &Output) -> (String, String, String) {
    let rec: &Reconstruction = &out.reconstruction;
    let mut cameras = String::from(
        "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n",
    );
    let _ = writeln!(cameras, "# Number of cameras: {}", input.images.len());
    for (i, c) in out.cameras.iter().enumerate() {
        let k = &c.intrinsics;
        let (cx, cy) = (k.cx + 0.5, k.cy + 0.5);
        if c.distortion.is_zero() {
            let _ = writeln!(
                cameras,
                "{} PINHOLE {} {} {} {} {} {}",
                i + 1,
                c.width,
                c.height,
                k.fx,
                k.fy,
                cx,
                cy
            );
        } else {
            let d = c.distortion.to_array();
            let _ = writeln!(
                cameras,
                "{} FULL_OPENCV {} {} {} {} {} {} {} {} {} {} {} 0 0 0",
                i + 1,
                c.width,
                c.height,
                k.fx,
                k.fy,
                cx,
                cy,
                d[0],
                d[1],
                d[2],
                d[3],
                d[4]
            );
        }
    }
    // Per image and keypoint: the point it belongs to (1-based ids), or −1.
    let mut point_id: Vec<Vec<i64>> = out.features.iter().map(|f| vec![-1; f.keypoints.len()]).collect();
    let mut track_len = 0usize;
    let mut kept_points = 0usize;
    for (p, _, obs) in rec.seen_points() {
        kept_points += 1;
        track_len += obs.len();
        for n in obs {
            point_id[n.image as usize][n.keypoint as usize] = p as i64 + 1;
        }
    }
    let registered = rec.registered_count();
    let mut images = String::from("# Image list with two lines of data per image:\n#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n#   POINTS2D[] as (X, Y, POINT3D_ID)\n");
    let _ = writeln!(
        images,
        "# Number of images: {registered}, mean observations per image: {}",
        if registered > 0 { track_len as f64 / registered as f64 } else { 0.0 }
    );
    for (i, pose) in rec.poses.iter().enumerate() {
        let Some(pose) = pose else { continue };
        let q = nalgebra::UnitQuaternion::from_matrix(&pose.r);
        let q = if q.w < 0.0 { -q.into_inner() } else { q.into_inner() };
        let _ = writeln!(
            images,
            "{} {} {} {} {} {} {} {} {} {}",
            i + 1,
            q.w,
            q.i,
            q.j,
            q.k,
            pose.t[0],
            pose.t[1],
            pose.t[2],
            i + 1,
            input.images[i].name
        );
        let line: Vec<String> = out.features[i]
            .keypoints
            .iter()
            .zip(&point_id[i])
            .map(|(kp, id)| format!("{} {} {id}", kp.x as f64 + 0.5, kp.y as f64 + 0.5))
            .collect();
        let _ = writeln!(images, "{}", line.join(" "));
    }
    let mut points = String::from("# 3D point list with one line of data per point:\n#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n");
    let _ = writeln!(
        points,
        "# Number of points: {kept_points}, mean track length: {}",
        if kept_points > 0 { track_len as f64 / kept_points as f64 } else { 0.0 }
    );
    for (p, point, obs) in rec.seen_points() {
        let c = out.colours[obs[0].image as usize][obs[0].keypoint as usize];
        let err = point_error(out, p);
        let track: Vec<String> = obs.iter().map(|n| format!("{} {}", n.image + 1, n.keypoint)).collect();
        let x = point.xyz;
        let _ = writeln!(
            points,
            "{} {} {} {} {} {} {} {} {}",
            p + 1,
            x[0],
            x[1],
            x[2],
            c[0],
            c[1],
            c[2],
            err,
            track.join(" ")
        );
    }
    (cameras, images, points)
}

/// A point's mean reprojection error (pixels) over its registered observations, measured
/// on the undistorted keypoints the mapper used.
fn point_error(out: &Output, p: usize) -> f64 {
    let rec = &out.reconstruction;
    let point = &rec.points[p];
    let (mut s, mut m) = (0.0, 0usize);
    for n in &point.track {
        let Some(pose) = &rec.poses[n.image as usize] else { continue };
        let cam = &out.cameras[n.image as usize];
        let xc = pose.r * point.xyz + pose.t;
        let kp = out.features[n.image as usize].keypoints[n.keypoint as usize];
        if let Some(px) = cam.project(glam::DVec3::new(xc[0], xc[1], xc[2])) {
            s += ((px.x - kp.x as f64).powi(2) + (px.y - kp.y as f64).powi(2)).sqrt();
            m += 1;
        }
    }
    if m == 0 {
        0.0
    } else {
        s / m as f64
    }
}

/// The points seen by two registered images, with colours, as ASCII PLY.
pub fn ply(out: &Output) -> String {
    let rec = &out.reconstruction;
    let pts: Vec<(nalgebra::Vector3<f64>, [u8; 3])> = rec
        .seen_points()
        .map(|(_, p, obs)| (p.xyz, out.colours[obs[0].image as usize][obs[0].keypoint as usize]))
        .collect();
    let mut s = format!("ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n", pts.len());
    for (x, c) in pts {
        let _ = writeln!(s, "{} {} {} {} {} {}", x[0] as f32, x[1] as f32, x[2] as f32, c[0], c[1], c[2]);
    }
    s
}

/// One registered image of a COLMAP text model: its file name, camera and pose.
#[derive(Clone, Debug)]
pub struct ModelImage {
    pub name: String,
    pub camera: crate::math::CameraModel,
    pub t_cam_world: crate::math::WorldToCamera,
}

/// Reads `cameras.txt` and `images.txt` of a COLMAP text model folder (lumen's or COLMAP's
/// own): the registered images in file order. Camera models SIMPLE_PINHOLE, PINHOLE,
/// SIMPLE_RADIAL, RADIAL, OPENCV and FULL_OPENCV (its k4–k6 zero) are read, their principal
/// points moved by −0.5 to lumen's pixel centres; any other model is refused by name.
pub fn read_text_model(dir: &std::path::Path) -> Result<Vec<ModelImage>, super::Error> {
    use super::Error;
    use crate::math::{CameraModel, Distortion, Intrinsics, Pose, WorldToCamera};
    let read = |name: &str| {
        let path = dir.join(name);
        std::fs::read_to_string(&path).map(|t| (path.clone(), t)).map_err(|e| Error::Io {
            path,
            message: format!("cannot read ({e}): expected a COLMAP text model folder"),
        })
    };
    let (cameras_path, cameras_text) = read("cameras.txt")?;
    let bad = |path: &std::path::Path, line: usize, message: String| Error::File {
        path: path.to_path_buf(),
        message: format!("line {}: {message}", line + 1),
    };
    let numbers = |path: &std::path::Path, line: usize, fields: &[&str]| -> Result<Vec<f64>, Error> {
        fields
            .iter()
            .map(|f| {
                f.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| bad(path, line, format!("`{f}`: expected a finite number")))
            })
            .collect()
    };
    let mut cameras = std::collections::HashMap::new();
    for (n, line) in cameras_text.lines().enumerate() {
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.is_empty() || f[0].starts_with('#') {
            continue;
        }
        if f.len() < 5 {
            return Err(bad(&cameras_path, n, "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS…".into()));
        }
        let size = |s: &str| s.parse::<u32>().ok().filter(|&v| v > 0);
        let (Some(width), Some(height)) = (size(f[2]), size(f[3])) else {
            return Err(bad(&cameras_path, n, format!("size {}×{}: expected positive integers", f[2], f[3])));
        };
        let p = numbers(&cameras_path, n, &f[4..])?;
        let expected = match f[1] {
            "SIMPLE_PINHOLE" => 3,
            "PINHOLE" | "SIMPLE_RADIAL" => 4,
            "RADIAL" => 5,
            "OPENCV" => 8,
            "FULL_OPENCV" => 12,
            other => {
                return Err(bad(
                    &cameras_path,
                    n,
                    format!("camera model {other}: expected SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV or FULL_OPENCV"),
                ))
            }
        };
        if p.len() != expected {
            return Err(bad(
                &cameras_path,
                n,
                format!("{} has {} parameters: expected {expected}", f[1], p.len()),
            ));
        }
        let (k, d) = match f[1] {
            "SIMPLE_PINHOLE" => ([p[0], p[0], p[1], p[2]], [0.0; 5]),
            "PINHOLE" => ([p[0], p[1], p[2], p[3]], [0.0; 5]),
            "SIMPLE_RADIAL" => ([p[0], p[0], p[1], p[2]], [p[3], 0.0, 0.0, 0.0, 0.0]),
            "RADIAL" => ([p[0], p[0], p[1], p[2]], [p[3], p[4], 0.0, 0.0, 0.0]),
            "OPENCV" => ([p[0], p[1], p[2], p[3]], [p[4], p[5], p[6], p[7], 0.0]),
            _ => {
                if p[9..].iter().any(|&v| v != 0.0) {
                    return Err(bad(
                        &cameras_path,
                        n,
                        "FULL_OPENCV with k4–k6 not zero: lumen's model stops at k3".into(),
                    ));
                }
                ([p[0], p[1], p[2], p[3]], [p[4], p[5], p[6], p[7], p[8]])
            }
        };
        let camera = CameraModel {
            width,
            height,
            intrinsics: Intrinsics { fx: k[0], fy: k[1], cx: k[2] - 0.5, cy: k[3] - 0.5 },
            distortion: Distortion::from_array(d),
        };
        camera.validate().map_err(|e| bad(&cameras_path, n, e.0))?;
        cameras.insert(f[0].to_string(), camera);
    }
    let (images_path, images_text) = read("images.txt")?;
    let mut images = Vec::new();
    let mut header = true;
    for (n, line) in images_text.lines().enumerate() {
        let t = line.trim();
        if t.starts_with('#') {
            continue;
        }
        // Two lines per image: the pose line, then its keypoints (possibly empty).
        if !header {
            header = true;
            continue;
        }
        if t.is_empty() {
            continue;
        }
        header = false;
        let f: Vec<&str> = t.split_whitespace().collect();
        if f.len() < 10 {
            return Err(bad(&images_path, n, "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME".into()));
        }
        let v = numbers(&images_path, n, &f[1..8])?;
        let q = nalgebra::Quaternion::new(v[0], v[1], v[2], v[3]);
        if !((q.norm() - 1.0).abs() < 1e-3) {
            return Err(bad(
                &images_path,
                n,
                format!("quaternion of norm {}: expected a unit quaternion", q.norm()),
            ));
        }
        let r = nalgebra::UnitQuaternion::from_quaternion(q).to_rotation_matrix();
        let m = r.matrix();
        let rotation = glam::DMat3::from_cols_array(&[
            m[(0, 0)],
            m[(1, 0)],
            m[(2, 0)],
            m[(0, 1)],
            m[(1, 1)],
            m[(2, 1)],
            m[(0, 2)],
            m[(1, 2)],
            m[(2, 2)],
        ]);
        let Some(camera) = cameras.get(f[8]) else {
            return Err(bad(&images_path, n, format!("camera {} is not in cameras.txt", f[8])));
        };
        images.push(ModelImage {
            name: f[9..].join(" "),
            camera: *camera,
            t_cam_world: WorldToCamera(Pose { rotation, translation: glam::DVec3::new(v[4], v[5], v[6]) }),
        });
    }
    if images.is_empty() {
        return Err(Error::File { path: images_path, message: "no registered image".into() });
    }
    Ok(images)
}
