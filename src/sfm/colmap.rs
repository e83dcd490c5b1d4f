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
