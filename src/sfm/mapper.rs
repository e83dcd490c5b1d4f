//! Incremental reconstruction (as COLMAP's mapper, Schönberger & Frahm, "Structure-from-
//! motion revisited", CVPR 2016), from per-image features and known intrinsics:
//!
//! 1. every pair (or those `Options::pairs` selects) is matched (`matching`) and verified by
//!    its two-view geometry (`two_view`), pairs in parallel, each independent of the others
//!    (`verify_pair`); the inliers of E (general pairs) or of H (planar or rotation pairs)
//!    are the verified matches, joined into tracks (`tracks`);
//! 2. the first pair: among general pairs whose median triangulation angle is at least
//!    `init_min_angle_deg`, the one with the most inliers; its tracks are triangulated;
//! 3. then, repeatedly, the unregistered image that sees the most triangulated tracks is
//!    registered by PnP (`pnp`), the tracks it completes are triangulated, and the bundle is
//!    adjusted (`bundle`), dropping observations that reproject farther than the threshold:
//!    as COLMAP does, the whole model only when it has grown by `global_ratio` since the last
//!    whole adjustment (and once at the end), otherwise locally: the new image and the
//!    `local_images − 1` registered images that share the most points with it move, with the
//!    points they see, while the other cameras that see those points hold still (a whole
//!    adjustment after every image makes n adjustments of growing size, the mapping's
//!    largest cost at tens of images);
//! 4. images that cannot be registered (too few 2D–3D matches, PnP without enough inliers)
//!    are reported with the reason; what was reconstructed is kept.
//!
//! With `Options::refine` (intrinsics guessed, not calibrated), the intrinsics the images
//! share that it names (focal length, principal point, radial k1 and k2) are refined in every
//! bundle adjustment from the third registered image on, as COLMAP's `ba_refine_*` options on
//! one shared camera: two views barely determine them (the focal length trades against
//! depth), and the images registered after an adjustment use their latest values. The
//! keypoints keep the positions they were given (`Reconstruction::radial` is the distortion of
//! those positions); registration, triangulation and the filtering use them undistorted
//! through the latest (k1, k2), the bundle the positions themselves through the model.
//!
//! Frames: poses map world to camera (X_c = R X + t); the world is the first camera's frame
//! at the scale of a unit baseline between the first pair.

use super::bundle::{self, Observation, Pose, Problem};
use super::features::Features;
use super::tracks::{self, Node, PairMatches};
use super::{matching, pnp, two_view};
use crate::error::Invalid;
use nalgebra::{Matrix3, Vector3};

#[derive(Clone, Copy, Debug)]
pub struct Options {
    pub matching: matching::Options,
    /// Sampson threshold of the two-view geometry, pixels (COLMAP: 4).
    pub two_view_px: f64,
    /// Reprojection threshold of PnP, triangulation and the bundle's filtering with calibrated
    /// intrinsics, pixels (2: about four standard deviations of the keypoints' noise, whose
    /// reprojection RMS over both coordinates is 0.5–0.7 px on the renders and on Herz-Jesu;
    /// COLMAP's 4 keeps observations that cost accuracy, docs/measurements.md, "Structure from motion").
    pub reprojection_px: f64,
    /// The same while the focal length is refined (4, COLMAP's): the residuals then hold the
    /// guess's error as well as noise, and 2 px drops good observations before it is gone.
    pub guessed_reprojection_px: f64,
    /// Smallest median triangulation angle of the first pair (degrees).
    pub init_min_angle_deg: f64,
    /// Smallest angle between two rays of a triangulated point (degrees; COLMAP 1.5).
    pub min_angle_deg: f64,
    /// Fewest verified matches for a pair to count, and fewest 2D–3D matches and PnP
    /// inliers to register an image (COLMAP: 15 and 30... here one number, 30).
    pub min_matches: usize,
    pub bundle: bundle::Options,
    /// Images a local adjustment moves: the new one and its best-connected neighbours
    /// (COLMAP's `local_ba_num_images`, 6).
    pub local_images: usize,
    /// The whole model is adjusted when the registered images have grown by this factor since
    /// the last whole adjustment (COLMAP's `ba_global_images_ratio`, 1.1); 1 adjusts it after
    /// every image.
    pub global_ratio: f64,
    /// The shared intrinsics to refine (module docs; default none: the intrinsics are
    /// calibrated).
    pub refine: bundle::Refine,
    /// Match each pair verified as general again, guided by its geometry: among only the
    /// keypoints within `two_view_px` of each other's epipolar lines (`matching::match_guided`),
    /// keeping the new matches its pose explains (Sampson distance within 1 px, in front of
    /// both cameras) when they are more (COLMAP's `guided_matching`, off there by default).
    pub guided_matching: bool,
    /// Which pairs of images are matched (default all).
    pub pairs: PairSelection,
    pub seed: u64,
}

/// Which pairs of images are matched and verified: every pair (COLMAP's exhaustive matcher),
/// or, for images taken in sequence (a path, a video), each image with the next `overlap` and
/// with those 2^k after it for k < `overlap` (COLMAP's sequential matcher with its quadratic
/// overlap, which also links images of a loop or a revisit further along). Exhaustive
/// matching grows as n²/2 pairs; sequential as about 2n·`overlap`, which is what lets the
/// mapper take thousands of images in sequence.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PairSelection {
    #[default]
    Exhaustive,
    Sequential {
        overlap: usize,
    },
}

impl PairSelection {
    /// Whether the pair (a, b), a < b, is matched.
    pub fn selects(&self, a: usize, b: usize) -> bool {
        match *self {
            PairSelection::Exhaustive => a < b,
            PairSelection::Sequential { overlap } => {
                let d = b.saturating_sub(a);
                a < b && (d <= overlap || (d.is_power_of_two() && d.trailing_zeros() < overlap as u32))
            }
        }
    }

    /// The pairs (a, b), a < b, of `n` images it selects, ordered by a, then b.
    pub fn pairs(&self, n: usize) -> Vec<(usize, usize)> {
        match *self {
            PairSelection::Exhaustive => (0..n).flat_map(|a| (a + 1..n).map(move |b| (a, b))).collect(),
            PairSelection::Sequential { overlap } => {
                let mut out = Vec::new();
                for a in 0..n {
                    let near = (a + 1..n).take_while(|&b| b - a <= overlap);
                    let far = (0..overlap.min(usize::BITS as usize - 1))
                        .map(|k| a.saturating_add(1 << k))
                        .filter(|&b| b - a > overlap && b < n);
                    out.extend(near.chain(far).map(|b| (a, b)));
                }
                out
            }
        }
    }
}

impl std::str::FromStr for PairSelection {
    type Err = Invalid;
    /// `exhaustive`, or `sequential:N` with N ≥ 1.
    fn from_str(s: &str) -> Result<PairSelection, Invalid> {
        let bad = || format!("\"{s}\": expected exhaustive or sequential:N with N at least 1");
        match s.split_once(':') {
            None if s == "exhaustive" => Ok(PairSelection::Exhaustive),
            Some(("sequential", n)) => match n.parse::<usize>() {
                Ok(overlap) if overlap >= 1 => Ok(PairSelection::Sequential { overlap }),
                _ => Err(bad().into()),
            },
            _ => Err(bad().into()),
        }
    }
}

impl Default for Options {
    fn default() -> Options {
        Options {
            matching: matching::Options::default(),
            two_view_px: 4.0,
            reprojection_px: 2.0,
            guessed_reprojection_px: 4.0,
            init_min_angle_deg: 2.0,
            min_angle_deg: 1.5,
            min_matches: 30,
            bundle: bundle::Options::default(),
            local_images: 6,
            global_ratio: 1.1,
            refine: bundle::Refine::NONE,
            guided_matching: false,
            pairs: PairSelection::Exhaustive,
            seed: 1,
        }
    }
}

/// A triangulated point: its position and the keypoints that see it.
#[derive(Clone, Debug)]
pub struct Point {
    pub xyz: Vector3<f64>,
    pub track: Vec<Node>,
}

/// What one pair's verification found.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PairReport {
    pub a: usize,
    pub b: usize,
    pub matches: usize,
    pub inliers: usize,
    pub configuration: Option<two_view::Configuration>,
}

/// The reconstruction.
#[derive(Clone, Debug, Default)]
pub struct Reconstruction {
    /// Per image: its pose, or None when it was not registered.
    pub poses: Vec<Option<Pose>>,
    pub points: Vec<Point>,
    /// Per image not registered: why.
    pub unregistered: Vec<(usize, String)>,
    pub pairs: Vec<PairReport>,
    /// Seconds spent matching, verifying, and mapping (registration, triangulation,
    /// bundle adjustment).
    pub matching_s: f64,
    pub verification_s: f64,
    pub mapping_s: f64,
    pub bundle_s: f64,
    pub rms_px: f64,
    /// Per image: the intrinsics the model ends with (the given ones, or with the refined
    /// focal length and principal point).
    pub intrinsics: Vec<Matrix3<f64>>,
    /// Per image: the radial distortion (k1, k2) of its keypoints' positions as given
    /// (zero unless refined).
    pub radial: Vec<[f64; 2]>,
}

impl Reconstruction {
    /// How many images have a pose.
    pub fn registered_count(&self) -> usize {
        self.poses.iter().filter(|p| p.is_some()).count()
    }

    /// The points two registered images see at least: (index, point, its observations in
    /// registered images), the points a model writes.
    pub fn seen_points(&self) -> impl Iterator<Item = (usize, &Point, Vec<Node>)> + '_ {
        self.points.iter().enumerate().filter_map(|(p, point)| {
            let obs: Vec<Node> =
                point.track.iter().copied().filter(|n| self.poses[n.image as usize].is_some()).collect();
            (obs.len() >= 2).then_some((p, point, obs))
        })
    }
}

fn pixel(f: &Features, k: u32) -> [f64; 2] {
    let p = f.keypoints[k as usize];
    [p.x as f64, p.y as f64]
}

/// Per image and keypoint, a position in pixels.
type Pixels = Vec<Vec<[f64; 2]>>;

/// The keypoints' positions as given.
fn positions(features: &[Features]) -> Pixels {
    features.iter().map(|f| (0..f.keypoints.len() as u32).map(|k| pixel(f, k)).collect()).collect()
}

/// `raw` positions undistorted through each image's radial (k1, k2) and K, as a pinhole
/// camera K would see them (a position the model cannot undistort stays as it is).
fn undistorted(raw: &Pixels, k: &[Matrix3<f64>], radial: &[[f64; 2]]) -> Pixels {
    raw.iter()
        .zip(k.iter().zip(radial))
        .map(|(pxs, (k, r))| {
            let camera = crate::math::CameraModel {
                width: 0,
                height: 0,
                intrinsics: crate::math::Intrinsics {
                    fx: k[(0, 0)],
                    fy: k[(1, 1)],
                    cx: k[(0, 2)],
                    cy: k[(1, 2)],
                },
                distortion: crate::math::Distortion { k1: r[0], k2: r[1], ..Default::default() },
            };
            pxs.iter()
                .map(|p| {
                    let ideal = camera
                        .undistort_pixel(glam::DVec2::new(p[0], p[1]))
                        .map(|n| camera.normalized_to_pixel(n));
                    ideal.filter(|u| u.is_finite()).map_or(*p, |u| [u.x, u.y])
                })
                .collect()
        })
        .collect()
}

/// The multi-view DLT point of a track over its registered views, if it is in front of all,
/// reprojects within the threshold in all, and has two rays at least `min_angle` apart.
fn triangulate(
    track: &[Node],
    poses: &[Option<Pose>],
    k: &[Matrix3<f64>],
    k_inv: &[Matrix3<f64>],
    ideal: &Pixels,
    opts: &Options,
) -> Option<Vector3<f64>> {
    let views: Vec<(usize, [f64; 2], Pose)> = track
        .iter()
        .filter_map(|n| {
            poses[n.image as usize]
                .map(|p| (n.image as usize, ideal[n.image as usize][n.keypoint as usize], p))
        })
        .collect();
    if views.len() < 2 {
        return None;
    }
    let mut ata = nalgebra::Matrix4::<f64>::zeros();
    for (i, px, pose) in &views {
        let r = k_inv[*i] * Vector3::new(px[0], px[1], 1.0);
        let (u, v) = (r[0] / r[2], r[1] / r[2]);
        let mut p = nalgebra::Matrix3x4::<f64>::zeros();
        p.fixed_view_mut::<3, 3>(0, 0).copy_from(&pose.r);
        p.set_column(3, &pose.t);
        for row in [p.row(0) - u * p.row(2), p.row(1) - v * p.row(2)] {
            let a = row.transpose();
            ata += a * a.transpose();
        }
    }
    let h =
        crate::math::linear::least_eigenvector(nalgebra::DMatrix::from_column_slice(4, 4, ata.as_slice()))?;
    if h[3].abs() < 1e-12 {
        return None;
    }
    let x = Vector3::new(h[0] / h[3], h[1] / h[3], h[2] / h[3]);
    if !x.iter().all(|v| v.is_finite()) {
        return None;
    }
    for (i, px, pose) in &views {
        if pnp::reprojection_error(&k[*i], pose, &x, *px) > opts.reprojection_px {
            return None;
        }
    }
    let rays: Vec<Vector3<f64>> = views.iter().map(|(_, _, p)| (x - p.centre()).normalize()).collect();
    let cos_min = opts.min_angle_deg.to_radians().cos();
    let wide = (0..rays.len()).any(|a| (a + 1..rays.len()).any(|b| rays[a].dot(&rays[b]) < cos_min));
    wide.then_some(x)
}

/// One pair's matching and verification: the report, and where it was verified with at least
/// `Options::min_matches` inliers, what the mapper builds on.
#[derive(Clone, Debug, PartialEq)]
pub struct VerifiedPair {
    pub report: PairReport,
    pub geometry: Option<PairGeometry>,
    /// Seconds spent matching and verifying it (0 when read back from a cache).
    pub matching_s: f64,
    pub verification_s: f64,
}

/// A verified pair's inlier matches (keypoint in a, keypoint in b) and relative pose.
#[derive(Clone, Debug, PartialEq)]
pub struct PairGeometry {
    pub matches: Vec<(u32, u32)>,
    pub pose: two_view::RelativePose,
    pub median_triangulation_angle_deg: f64,
}

/// Matches images `a` < `b` of `n` and verifies them by their two-view geometry (step 1 of
/// the module docs). Its RANSAC is seeded by (`opts.seed`, a, b, n) only, so a pair gives the
/// same result whichever process verifies it and whatever else it verifies.
pub fn verify_pair(
    features: &[Features],
    k: &[Matrix3<f64>],
    (a, b): (usize, usize),
    opts: &Options,
) -> VerifiedPair {
    let n = features.len();
    let t = std::time::Instant::now();
    let m = matching::match_descriptors(&features[a].descriptors, &features[b].descriptors, &opts.matching);
    let mut matching_s = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let p1: Vec<[f64; 2]> = m.iter().map(|x| pixel(&features[a], x.a)).collect();
    let p2: Vec<[f64; 2]> = m.iter().map(|x| pixel(&features[b], x.b)).collect();
    let tv = if m.len() >= opts.min_matches {
        two_view::estimate(&p1, &p2, &k[a], &k[b], opts.two_view_px, opts.seed ^ (a * n + b) as u64)
    } else {
        None
    };
    let mut report = PairReport {
        a,
        b,
        matches: m.len(),
        inliers: tv.as_ref().map_or(0, |t| t.inliers.len()),
        configuration: tv.as_ref().map(|t| t.configuration),
    };
    let mut geometry = tv.filter(|tv| tv.inliers.len() >= opts.min_matches).map(|tv| PairGeometry {
        matches: tv.inliers.iter().map(|&i| (m[i].a, m[i].b)).collect(),
        pose: tv.pose,
        median_triangulation_angle_deg: tv.median_triangulation_angle_deg,
    });
    let verification_s = t.elapsed().as_secs_f64();
    if let (Some(g), Some(two_view::Configuration::General), true) =
        (&mut geometry, report.configuration, opts.guided_matching)
    {
        let t = std::time::Instant::now();
        let guided = guided_matches(&features[a], &features[b], &k[a], &k[b], &g.pose, opts);
        let p1: Vec<[f64; 2]> = guided.iter().map(|x| pixel(&features[a], x.a)).collect();
        let p2: Vec<[f64; 2]> = guided.iter().map(|x| pixel(&features[b], x.b)).collect();
        let inliers = two_view::consistent(&g.pose, &p1, &p2, &k[a], &k[b], 1.0);
        if inliers.len() > g.matches.len() {
            g.matches = inliers.iter().map(|&i| (guided[i].a, guided[i].b)).collect();
            (report.matches, report.inliers) = (guided.len(), inliers.len());
        }
        matching_s += t.elapsed().as_secs_f64();
    }
    VerifiedPair { report, geometry, matching_s, verification_s }
}

/// The matches of two images' features among keypoints within `opts.two_view_px` of each
/// other's epipolar line under `pose` (`Options::guided_matching`).
fn guided_matches(
    fa: &Features,
    fb: &Features,
    ka: &Matrix3<f64>,
    kb: &Matrix3<f64>,
    pose: &two_view::RelativePose,
    opts: &Options,
) -> Vec<matching::Match> {
    let (Some(kai), Some(kbi)) = (ka.try_inverse(), kb.try_inverse()) else {
        return Vec::new();
    };
    let f = kbi.transpose() * two_view::essential_of(pose) * kai;
    // Each keypoint's epipolar line in the other image, scaled so that l·(x, y, 1) is the
    // distance in pixels (f32: at 10⁴ px its rounding is 10⁻³ px).
    let lines = |m: &Matrix3<f64>, kps: &[super::features::Keypoint]| -> Vec<[f32; 3]> {
        kps.iter()
            .map(|kp| {
                let l = m * Vector3::new(kp.x as f64, kp.y as f64, 1.0);
                let n = l[0].hypot(l[1]).max(1e-300);
                [(l[0] / n) as f32, (l[1] / n) as f32, (l[2] / n) as f32]
            })
            .collect()
    };
    let (in_b, in_a) = (lines(&f, &fa.keypoints), lines(&f.transpose(), &fb.keypoints));
    let t = opts.two_view_px as f32;
    let near = |l: &[f32; 3], kp: &super::features::Keypoint| (l[0] * kp.x + l[1] * kp.y + l[2]).abs() <= t;
    matching::match_guided(&fa.descriptors, &fb.descriptors, &opts.matching, |i, j| {
        near(&in_b[i], &fb.keypoints[j]) && near(&in_a[j], &fa.keypoints[i])
    })
}

/// `verify_pair` over `pairs`, in parallel, results in their order, `progress` advanced by one
/// per pair. The pairs' matching and verification times are scaled so that together they add
/// up to the wall time spent, split between the two in the proportion of their times on the
/// threads.
pub fn verify_pairs(
    features: &[Features],
    k: &[Matrix3<f64>],
    pairs: &[(usize, usize)],
    opts: &Options,
    progress: &indicatif::ProgressBar,
) -> Vec<VerifiedPair> {
    use rayon::prelude::*;
    let t = std::time::Instant::now();
    let mut out: Vec<VerifiedPair> = pairs
        .par_iter()
        .map(|&p| {
            let v = verify_pair(features, k, p, opts);
            progress.inc(1);
            v
        })
        .collect();
    let threads: f64 = out.iter().map(|p| p.matching_s + p.verification_s).sum();
    if threads > 0.0 {
        let scale = t.elapsed().as_secs_f64() / threads;
        for p in &mut out {
            p.matching_s *= scale;
            p.verification_s *= scale;
        }
    }
    out
}

/// Reconstructs cameras and points from `features` of images with intrinsics `k`, matching
/// the pairs `opts.pairs` selects.
pub fn reconstruct(features: &[Features], k: &[Matrix3<f64>], opts: &Options) -> Reconstruction {
    let pairs = opts.pairs.pairs(features.len());
    let verified = verify_pairs(features, k, &pairs, opts, &indicatif::ProgressBar::hidden());
    reconstruct_verified(features, k, verified, opts)
}

/// Steps 2–4 of the module docs, from every pair's `verify_pair` (in any order; a pair
/// missing from `pairs` counts as unmatched).
pub fn reconstruct_verified(
    features: &[Features],
    k: &[Matrix3<f64>],
    mut pairs: Vec<VerifiedPair>,
    opts: &Options,
) -> Reconstruction {
    let threshold = if opts.refine.any() { opts.guessed_reprojection_px } else { opts.reprojection_px };
    let opts = &Options { reprojection_px: threshold, ..*opts };
    let n = features.len();
    let mut out = Reconstruction {
        poses: vec![None; n],
        intrinsics: k.to_vec(),
        radial: vec![[0.0; 2]; n],
        ..Default::default()
    };
    // The keypoints as given (the bundle's observations) and undistorted (module docs).
    let raw = positions(features);
    let mut ideal = raw.clone();
    pairs.sort_by_key(|p| (p.report.a, p.report.b));
    let mut verified: Vec<PairMatches> = Vec::new();
    let mut geometry: Vec<(usize, usize, PairGeometry, two_view::Configuration)> = Vec::new();
    for p in pairs {
        out.matching_s += p.matching_s;
        out.verification_s += p.verification_s;
        let (a, b) = (p.report.a, p.report.b);
        if let (Some(g), Some(c)) = (p.geometry, p.report.configuration) {
            verified.push(PairMatches { a: a as u32, b: b as u32, matches: g.matches.clone() });
            geometry.push((a, b, g, c));
        }
        out.pairs.push(p.report);
    }
    let t_map = std::time::Instant::now();
    let counts: Vec<usize> = features.iter().map(|f| f.keypoints.len()).collect();
    let tracks = tracks::build(&counts, &verified);
    // 2. The first pair.
    let first = geometry
        .iter()
        .filter(|(_, _, g, c)| {
            *c == two_view::Configuration::General
                && g.median_triangulation_angle_deg >= opts.init_min_angle_deg
        })
        .max_by_key(|(_, _, g, _)| g.matches.len());
    let Some((a, b, tv, _)) = first else {
        let why = no_first_pair(&out.pairs, opts.init_min_angle_deg);
        out.unregistered = (0..n).map(|i| (i, why.clone())).collect();
        return out;
    };
    out.poses[*a] = Some(Pose { r: Matrix3::identity(), t: Vector3::zeros() });
    out.poses[*b] = Some(Pose { r: tv.pose.r, t: tv.pose.t });
    // Track index → point index.
    let mut point_of: Vec<Option<usize>> = vec![None; tracks.len()];
    // Per image: (keypoint → track), in keypoint order: a keypoint with several orientations
    // gives several correspondences at one pixel, which the sort by pixel below leaves in
    // this order (a HashMap's would change from run to run, and with it RANSAC's samples).
    let mut track_of: Vec<std::collections::BTreeMap<u32, usize>> = vec![Default::default(); n];
    for (t, track) in tracks.iter().enumerate() {
        for node in track {
            track_of[node.image as usize].insert(node.keypoint, t);
        }
    }
    let triangulate_new = |out: &mut Reconstruction, point_of: &mut Vec<Option<usize>>, ideal: &Pixels| {
        let k = &out.intrinsics;
        let k_inv: Vec<Matrix3<f64>> =
            k.iter().map(|m| m.try_inverse().unwrap_or_else(Matrix3::zeros)).collect();
        for (t, track) in tracks.iter().enumerate() {
            if point_of[t].is_some() {
                continue;
            }
            if let Some(x) = triangulate(track, &out.poses, k, &k_inv, ideal, opts) {
                point_of[t] = Some(out.points.len());
                out.points.push(Point { xyz: x, track: track.clone() });
            }
        }
    };
    triangulate_new(&mut out, &mut point_of, &ideal);
    let mut bundle_s = 0.0;
    let iterations = opts.bundle.max_iterations;
    let mut adjust =
        |out: &mut Reconstruction, ideal: &mut Pixels, local: Option<usize>, iterations: usize| {
            let t = std::time::Instant::now();
            adjust_bundle(out, &raw, ideal, *a, local, opts, iterations);
            bundle_s += t.elapsed().as_secs_f64();
        };
    adjust(&mut out, &mut ideal, None, iterations);
    // Registered images at the last whole adjustment.
    let mut whole_at = 2usize;
    // 3. Register the others, most 2D–3D matches first.
    loop {
        let mut best: Option<(usize, Vec<(Vector3<f64>, [f64; 2])>)> = None;
        for i in 0..n {
            if out.poses[i].is_some() || out.unregistered.iter().any(|u| u.0 == i) {
                continue;
            }
            let corr: Vec<(Vector3<f64>, [f64; 2])> = track_of[i]
                .iter()
                .filter_map(|(&kp, &t)| point_of[t].map(|p| (out.points[p].xyz, ideal[i][kp as usize])))
                .collect();
            if best.as_ref().is_none_or(|b| corr.len() > b.1.len()) {
                best = Some((i, corr));
            }
        }
        let Some((i, mut corr)) = best else { break };
        // A deterministic order for RANSAC.
        corr.sort_by(|p, q| p.1[0].total_cmp(&q.1[0]).then(p.1[1].total_cmp(&q.1[1])));
        if corr.len() < opts.min_matches {
            out.unregistered.push((
                i,
                format!("{} matches to reconstructed points, fewer than {}", corr.len(), opts.min_matches),
            ));
            continue;
        }
        let pts: Vec<Vector3<f64>> = corr.iter().map(|c| c.0).collect();
        let pxs: Vec<[f64; 2]> = corr.iter().map(|c| c.1).collect();
        match pnp::estimate(&out.intrinsics[i], &pts, &pxs, opts.reprojection_px, opts.seed ^ i as u64) {
            Some(reg) if reg.inliers.len() >= opts.min_matches => {
                out.poses[i] = Some(reg.pose);
                triangulate_new(&mut out, &mut point_of, &ideal);
                let registered = out.registered_count();
                if registered as f64 >= opts.global_ratio * whole_at as f64 {
                    adjust(&mut out, &mut ideal, None, iterations);
                    whole_at = registered;
                } else {
                    adjust(&mut out, &mut ideal, Some(i), iterations);
                }
            }
            Some(reg) => out.unregistered.push((
                i,
                format!(
                    "PnP kept {} of {} matches to reconstructed points, fewer than {}",
                    reg.inliers.len(),
                    corr.len(),
                    opts.min_matches
                ),
            )),
            None => out
                .unregistered
                .push((i, format!("PnP found no pose from {} matches to reconstructed points", corr.len()))),
        }
    }
    if out.registered_count() > whole_at {
        adjust(&mut out, &mut ideal, None, iterations);
    }
    // Refined intrinsics converge slowly along the focal length's valley with depth: a last
    // whole adjustment continues where the others stopped, with `FINAL_ROUNDS` times the
    // iterations (Herz-Jesu without K, f and k1: the focal length −0.19 % short after the
    // usual rounds, −0.04 % after this one).
    if opts.refine.any() && out.registered_count() >= 3 {
        adjust(&mut out, &mut ideal, None, FINAL_ROUNDS * iterations);
    }
    out.unregistered.sort_by_key(|u| u.0);
    out.bundle_s = bundle_s;
    out.mapping_s = t_map.elapsed().as_secs_f64() - bundle_s;
    out.rms_px = rms(&out, &raw);
    out
}

/// How many times the usual iterations the last whole adjustment gets when intrinsics are
/// refined (`reconstruct_verified`).
const FINAL_ROUNDS: usize = 4;

/// RMS reprojection error over every observation of every point, pixels of the keypoints as
/// given.
fn rms(out: &Reconstruction, raw: &Pixels) -> f64 {
    let (mut s, mut m) = (0.0, 0usize);
    for p in &out.points {
        for node in &p.track {
            let i = node.image as usize;
            if let Some(pose) = &out.poses[i] {
                let e = bundle::reprojection_error(
                    &out.intrinsics[i],
                    out.radial[i],
                    pose,
                    &p.xyz,
                    raw[i][node.keypoint as usize],
                );
                s += e * e;
                m += 1;
            }
        }
    }
    if m == 0 {
        0.0
    } else {
        (s / m as f64).sqrt()
    }
}

/// Adjusts the bundle, then drops the observations that reproject beyond the threshold.
/// Whole (`local` None): every registered pose (the first fixed; the scale held by the
/// damping) and every point two registered cameras see. Local (`local` the new image): the
/// poses of the window (module docs) and the points its images see; the other registered
/// cameras that see those points enter fixed, and hold the gauge.
fn adjust_bundle(
    out: &mut Reconstruction,
    raw: &Pixels,
    ideal: &mut Pixels,
    first: usize,
    local: Option<usize>,
    opts: &Options,
    max_iterations: usize,
) {
    let registered = |i: usize| out.poses.get(i).is_some_and(|p| p.is_some());
    let window: Option<Vec<usize>> = local.map(|i| {
        // Registered images by the points they share with image i, most first.
        let mut shared = std::collections::BTreeMap::<usize, usize>::new();
        for point in out.points.iter().filter(|p| p.track.iter().any(|n| n.image as usize == i)) {
            for n in point.track.iter().map(|n| n.image as usize).filter(|&j| j != i && registered(j)) {
                *shared.entry(n).or_default() += 1;
            }
        }
        let mut by_count: Vec<(usize, usize)> = shared.into_iter().collect();
        by_count.sort_by(|x, y| y.1.cmp(&x.1).then(x.0.cmp(&y.0)));
        std::iter::once(i)
            .chain(by_count.into_iter().take(opts.local_images.saturating_sub(1)).map(|e| e.0))
            .collect()
    });
    let moves = |c: usize| window.as_ref().is_none_or(|w| w.contains(&c));
    // Points seen by two registered cameras at least (and, locally, by one of the window).
    let seen = |point: &Point| point.track.iter().filter(|n| registered(n.image as usize)).count();
    let included: Vec<usize> = (0..out.points.len())
        .filter(|&p| {
            let point = &out.points[p];
            seen(point) >= 2 && (window.is_none() || point.track.iter().any(|n| moves(n.image as usize)))
        })
        .collect();
    // The cameras that see them.
    let mut cams: Vec<usize> = included
        .iter()
        .flat_map(|&p| out.points[p].track.iter().map(|n| n.image as usize))
        .filter(|&c| registered(c))
        .collect();
    cams.sort_unstable();
    cams.dedup();
    let slot: std::collections::HashMap<usize, usize> =
        cams.iter().enumerate().map(|(s, &c)| (c, s)).collect();
    let mut observations = Vec::new();
    for (q, &p) in included.iter().enumerate() {
        for node in &out.points[p].track {
            if let Some(&c) = slot.get(&(node.image as usize)) {
                observations.push(Observation {
                    camera: c,
                    point: q,
                    xy: raw[node.image as usize][node.keypoint as usize],
                });
            }
        }
    }
    let mut problem = Problem {
        intrinsics: cams.iter().map(|&c| out.intrinsics[c]).collect(),
        radial: cams.iter().map(|&c| out.radial[c]).collect(),
        poses: cams.iter().filter_map(|&c| out.poses[c]).collect(),
        fixed: cams.iter().map(|&c| c == first || !moves(c)).collect(),
        points: included.iter().map(|&p| out.points[p].xyz).collect(),
        observations,
    };
    // The intrinsics are refined where every image shares one camera (images of one size),
    // and then become every image's.
    let shared = out.intrinsics.iter().all(|k| *k == out.intrinsics[0]);
    let refine = if shared && out.registered_count() >= 3 { opts.refine } else { bundle::Refine::NONE };
    bundle::adjust(&mut problem, &bundle::Options { refine, max_iterations, ..opts.bundle });
    for (s, &c) in cams.iter().enumerate() {
        out.poses[c] = Some(problem.poses[s]);
    }
    if let (Some(k), Some(r)) = (problem.intrinsics.first(), problem.radial.first()) {
        if refine.any() && (*k != out.intrinsics[0] || *r != out.radial[0]) {
            out.intrinsics.fill(*k);
            out.radial.fill(*r);
            if *r != [0.0; 2] {
                *ideal = undistorted(raw, &out.intrinsics, &out.radial);
            }
        }
    }
    for (q, &p) in included.iter().enumerate() {
        out.points[p].xyz = problem.points[q];
    }
    // Observations beyond the threshold leave their tracks (a track keeps its unregistered
    // nodes for later images).
    for point in out.points.iter_mut() {
        let x = point.xyz;
        point.track.retain(|node| {
            let i = node.image as usize;
            out.poses[i].as_ref().is_none_or(|pose| {
                let px = raw[i][node.keypoint as usize];
                bundle::reprojection_error(&out.intrinsics[i], out.radial[i], pose, &x, px)
                    <= opts.reprojection_px
            })
        });
    }
}

/// Why no pair can start the reconstruction, counted over the pairs matched (their reports):
/// how many were classified planar or a pure rotation (a pure rotation keeps no geometry, so
/// it is counted from the report), how many verified as general but too narrow, the rest
/// having too few matches to be verified.
fn no_first_pair(pairs: &[PairReport], min_angle_deg: f64) -> String {
    let count = |c: Option<two_view::Configuration>| pairs.iter().filter(|p| p.configuration == c).count();
    let planar = count(Some(two_view::Configuration::Planar));
    let rotation = count(Some(two_view::Configuration::PureRotation));
    let narrow = count(Some(two_view::Configuration::General));
    format!(
        "no pair of images with a baseline: of {} pair(s), {planar} planar (a homography explains them), \
         {rotation} a pure rotation, {narrow} with a median triangulation angle below {min_angle_deg}°, \
         {} with too few matches",
        pairs.len(),
        count(None)
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sfm::features::Keypoint;

    /// 16 cameras on an arc 8 m from 400 points, each point a keypoint in every image with
    /// 0.3 px of noise and its own random descriptor (so matching is exact).
    fn arc_features() -> (Vec<Features>, Vec<Matrix3<f64>>) {
        let mut s = 11u64;
        let mut next = || {
            s = crate::render::sampler::mix64(s);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let k = Matrix3::new(1000.0, 0.0, 639.5, 0.0, 1000.0, 479.5, 0.0, 0.0, 1.0);
        let points: Vec<Vector3<f64>> = (0..400)
            .map(|_| Vector3::new(next() * 4.0 - 2.0, next() * 3.0 - 1.5, next() * 2.0 - 1.0))
            .collect();
        let descriptors: Vec<[u8; 128]> =
            points.iter().map(|_| std::array::from_fn(|_| (next() * 90.0) as u8)).collect();
        let poses: Vec<Pose> = (0..16)
            .map(|i| {
                let a = -0.5 + i as f64 / 15.0;
                let r = nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), a).into_inner();
                let centre = Vector3::new(8.0 * a.sin(), 0.0, -8.0 * a.cos());
                Pose { r, t: -(r * centre) }
            })
            .collect();
        let noise = 0.3 * 12f64.sqrt();
        let features = poses
            .iter()
            .map(|pose| {
                let mut f = Features::default();
                for (x, d) in points.iter().zip(&descriptors) {
                    let px = k * (pose.r * x + pose.t);
                    f.keypoints.push(Keypoint {
                        x: (px[0] / px[2] + (next() - 0.5) * noise) as f32,
                        y: (px[1] / px[2] + (next() - 0.5) * noise) as f32,
                        sigma: 2.0,
                        angle: 0.0,
                        response: 1.0,
                    });
                    f.descriptors.push(*d);
                }
                f
            })
            .collect();
        (features, vec![k; 16])
    }

    /// Sequential pairs are COLMAP's: the next `overlap` images and those 2^k after, k <
    /// `overlap`; `selects` agrees with `pairs`; exhaustive is every pair; bad names refused.
    #[test]
    fn pair_selections() {
        let seq = PairSelection::Sequential { overlap: 3 };
        let from_0: Vec<usize> = seq.pairs(20).iter().filter(|p| p.0 == 0).map(|p| p.1).collect();
        assert_eq!(from_0, vec![1, 2, 3, 4]);
        let from_15: Vec<usize> = seq.pairs(20).iter().filter(|p| p.0 == 15).map(|p| p.1).collect();
        assert_eq!(from_15, vec![16, 17, 18, 19]);
        for sel in [seq, PairSelection::Sequential { overlap: 1 }, PairSelection::Exhaustive] {
            let listed = sel.pairs(40);
            let mut all: Vec<(usize, usize)> = (0..40)
                .flat_map(|a| (0..40).map(move |b| (a, b)))
                .filter(|&(a, b)| sel.selects(a, b))
                .collect();
            all.sort_unstable();
            assert_eq!(listed, all, "{sel:?}");
        }
        assert_eq!(PairSelection::Exhaustive.pairs(40).len(), 780);
        assert_eq!(PairSelection::Sequential { overlap: 1 }.pairs(40).len(), 39);
        // Large overlaps neither overflow nor repeat a pair.
        assert_eq!(PairSelection::Sequential { overlap: 200 }.pairs(40).len(), 780);
        assert_eq!("sequential:10".parse(), Ok(PairSelection::Sequential { overlap: 10 }));
        assert_eq!("exhaustive".parse(), Ok(PairSelection::Exhaustive));
        for bad in ["sequential:0", "sequential:", "sequential", "vocab-tree", "sequential:x"] {
            assert!(bad.parse::<PairSelection>().unwrap_err().0.contains("expected exhaustive"), "{bad}");
        }
    }

    /// Local adjustments between whole ones (here after images 12 and 14 of 16) end at the
    /// minimum that a whole adjustment after every image reaches (the same data, ending in a
    /// whole adjustment): the same points, the poses within 10⁻⁴° of each other, the same
    /// RMS error, below the noise's 0.3·√2 ≈ 0.42 px.
    #[test]
    fn local_adjustments_end_where_whole_ones_do() {
        let (features, k) = arc_features();
        let local = reconstruct(&features, &k, &Options::default());
        let whole = reconstruct(&features, &k, &Options { global_ratio: 1.0, ..Options::default() });
        for rec in [&local, &whole] {
            assert_eq!(rec.registered_count(), 16, "{:?}", rec.unregistered);
            assert!(rec.rms_px < 0.42, "{}", rec.rms_px);
        }
        assert_eq!(local.points.len(), whole.points.len());
        let whole_poses: Vec<crate::math::WorldToCamera> =
            whole.poses.iter().flatten().map(Into::into).collect();
        let apart = crate::sfm::eval::pairwise_rotation_errors(&local.poses, &whole_poses);
        assert!(apart.iter().all(|&e| e < 1e-4), "{apart:?}");
        assert!(
            (local.rms_px - whole.rms_px).abs() < 1e-6 * whole.rms_px,
            "{} {}",
            local.rms_px,
            whole.rms_px
        );
    }
}
