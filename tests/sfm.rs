//! Structure from motion on real photographs: Herz-Jesu-P8 (`../shared/data/sfm`).

mod common;

use lumen::image::filter::Grey;
use lumen::sfm::{bundle::Pose, eval, features, mapper, matching, two_view};
use nalgebra::{Matrix3, Vector3};
use std::path::Path;
use std::sync::OnceLock;

/// A ground-truth camera of the Strecha et al. format (the folder's README): K, camera-to-
/// world R and the centre C.
fn camera(path: &Path) -> (Matrix3<f64>, Matrix3<f64>, Vector3<f64>) {
    let v: Vec<f64> =
        std::fs::read_to_string(path).unwrap().split_whitespace().map(|s| s.parse().unwrap()).collect();
    (
        Matrix3::from_row_slice(&v[0..9]),
        Matrix3::from_row_slice(&v[12..21]),
        Vector3::new(v[21], v[22], v[23]),
    )
}

/// The features of the eight images, detected once for every test.
fn herz_jesu_features(dir: &Path) -> &'static [features::Features] {
    static FEATURES: OnceLock<Vec<features::Features>> = OnceLock::new();
    FEATURES.get_or_init(|| {
        (0..8)
            .map(|k| {
                let img = lumen::image::io::read(&dir.join(format!("images/{k:04}.jpg"))).unwrap();
                features::detect(&Grey::from_image(&img), &features::Options::default())
            })
            .collect()
    })
}

/// The seven consecutive pairs of Herz-Jesu-P8, each on its own: SIFT features (8192 per
/// image), mutual ratio-test matches, E by RANSAC (4 px, COLMAP's two-view threshold) and
/// the refined pose. Each pair is recognised as general (not planar, not a rotation), keeps
/// more than 90 % of its matches, and its relative rotation is within the bounds for
/// a whole reconstruction, median ≤ 0.1° and max ≤ 0.3° of the ground truth (COLMAP 4.2 after
/// bundle adjustment: median 0.040°, max 0.078° over all pairs), with the translation's
/// direction within 1°.
#[test]
fn herz_jesu_consecutive_pairs() {
    let Some(data) = common::shared_data() else { return };
    let dir = data.join("sfm/herz-jesu-p8");
    let feats = herz_jesu_features(&dir);
    let mut errors = Vec::new();
    for i in 0..7 {
        let (a, b) = (&feats[i], &feats[i + 1]);
        assert_eq!(a.keypoints.len(), 8192);
        let m = matching::match_descriptors(&a.descriptors, &b.descriptors, &matching::Options::default());
        let pos = |f: &features::Features, k: u32| {
            let p = f.keypoints[k as usize];
            [p.x as f64, p.y as f64]
        };
        let p1: Vec<[f64; 2]> = m.iter().map(|x| pos(a, x.a)).collect();
        let p2: Vec<[f64; 2]> = m.iter().map(|x| pos(b, x.b)).collect();
        let (k1, r1, c1) = camera(&dir.join(format!("gt_dense_cameras/{i:04}.jpg.camera")));
        let (k2, r2, c2) = camera(&dir.join(format!("gt_dense_cameras/{:04}.jpg.camera", i + 1)));
        let tv = two_view::estimate(&p1, &p2, &k1, &k2, 4.0, 1).unwrap();
        assert_eq!(tv.configuration, two_view::Configuration::General, "pair {i}-{}", i + 1);
        assert!(
            tv.inliers.len() as f64 > 0.9 * m.len() as f64,
            "pair {i}: {} of {}",
            tv.inliers.len(),
            m.len()
        );
        // X₂ = R₂ᵀR₁·X₁ + R₂ᵀ(C₁ − C₂).
        let r_true = r2.transpose() * r1;
        let t_true = (r2.transpose() * (c1 - c2)).normalize();
        let dr = two_view::rotation_angle_deg(&(tv.pose.r * r_true.transpose()));
        let dt = tv.pose.t.dot(&t_true).clamp(-1.0, 1.0).acos().to_degrees();
        eprintln!(
            "pair {i}-{}: {} matches, {} inliers, rotation {dr:.4}°, direction {dt:.3}°",
            i + 1,
            m.len(),
            tv.inliers.len()
        );
        assert!(dt < 1.0, "pair {i}: translation direction off by {dt}°");
        errors.push(dr);
    }
    errors.sort_by(f64::total_cmp);
    assert!(errors[3] <= 0.1 && errors[6] <= 0.3, "rotation errors {errors:?}");
}

/// The whole set, incrementally (`sfm::mapper` with its defaults, the known K): all 8 images
/// registered, pairwise relative rotation errors over all 28 pairs within the bounds
/// (median ≤ 0.1°, max ≤ 0.3°; COLMAP 4.2: 0.040° and 0.078°), camera centres within 1 % of
/// the camera path's extent after a similarity, reprojection RMS ≤ 1 px (these are real
/// photographs: the 0.5 px holds for renders).
#[test]
fn herz_jesu_reconstruction() {
    let Some(data) = common::shared_data() else { return };
    let dir = data.join("sfm/herz-jesu-p8");
    let feats = herz_jesu_features(&dir);
    let cams: Vec<(Matrix3<f64>, Matrix3<f64>, Vector3<f64>)> =
        (0..8).map(|i| camera(&dir.join(format!("gt_dense_cameras/{i:04}.jpg.camera")))).collect();
    let k: Vec<Matrix3<f64>> = cams.iter().map(|c| c.0).collect();
    // Ground truth as world-to-camera poses: R_wc = Rᵀ, t = −Rᵀ C.
    let truth: Vec<Pose> =
        cams.iter().map(|c| Pose { r: c.1.transpose(), t: -(c.1.transpose() * c.2) }).collect();
    let rec = mapper::reconstruct(feats, &k, &mapper::Options::default());
    eprintln!(
        "registered {}, points {}, rms {:.3} px, unregistered {:?}; matching {:.2} s, verification {:.2} s, mapping {:.2} s, bundle {:.2} s",
        rec.poses.iter().filter(|p| p.is_some()).count(),
        rec.points.len(),
        rec.rms_px,
        rec.unregistered,
        rec.matching_s,
        rec.verification_s,
        rec.mapping_s,
        rec.bundle_s
    );
    assert!(rec.poses.iter().all(|p| p.is_some()), "{:?}", rec.unregistered);
    let mut rot = eval::pairwise_rotation_errors(&rec.poses, &truth);
    rot.sort_by(f64::total_cmp);
    let centres = eval::centre_errors(&rec.poses, &truth).unwrap();
    let extent = (0..8)
        .flat_map(|i| (0..8).map(move |j| (i, j)))
        .map(|(i, j)| (truth[i].centre() - truth[j].centre()).norm())
        .fold(0.0, f64::max);
    let worst_centre = centres.iter().cloned().fold(0.0, f64::max) / extent;
    eprintln!(
        "rotation median {:.4}°, max {:.4}°; centre max {:.4} % of {extent:.2}",
        rot[rot.len() / 2],
        rot[rot.len() - 1],
        100.0 * worst_centre
    );
    assert!(rot[rot.len() / 2] <= 0.1 && rot[rot.len() - 1] <= 0.3, "{rot:?}");
    assert!(worst_centre <= 0.01, "{centres:?}");
    assert!(rec.rms_px <= 1.0, "{}", rec.rms_px);
}
