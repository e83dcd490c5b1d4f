//! Features and verified pairs as bytes, for the pipeline's cache (work one process does for
//! another: `pipeline::stages::sfm`). Little-endian, every float stored bit for bit, so a
//! reconstruction from decoded values is the one from the values themselves. Decoding checks
//! every length and returns `None` for bytes that are not a whole encoding.
//!
//! - Features: count (u32), then per keypoint x, y, σ, angle, response (f32) and the 128
//!   descriptor bytes.
//! - Pairs: count (u32), then per pair a, b, matches, inliers (u32), the configuration (u8:
//!   0 none, 1 general, 2 planar, 3 pure rotation), 1 when it has a geometry and then R (9
//!   f64, row-major), t (3 f64), the median triangulation angle (f64) and its inlier matches
//!   (count u32, pairs of u32), else 0.

use super::features::{Features, Keypoint};
use super::mapper::{PairGeometry, PairReport, VerifiedPair};
use super::two_view::{Configuration, RelativePose};
use nalgebra::{Matrix3, Vector3};

pub fn encode_features(f: &Features) -> Vec<u8> {
    let mut out = Vec::with_capacity(4 + f.keypoints.len() * (20 + 128));
    put_u32(&mut out, f.keypoints.len());
    for (k, d) in f.keypoints.iter().zip(&f.descriptors) {
        for v in [k.x, k.y, k.sigma, k.angle, k.response] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        out.extend_from_slice(d);
    }
    out
}

pub fn decode_features(bytes: &[u8]) -> Option<Features> {
    let mut r = Reader(bytes);
    let n = r.u32()? as usize;
    // Refuse a count the bytes cannot hold before reserving for it.
    if n.checked_mul(20 + 128)? != r.0.len() {
        return None;
    }
    let mut f = Features { keypoints: Vec::with_capacity(n), descriptors: Vec::with_capacity(n) };
    for _ in 0..n {
        let [x, y, sigma, angle, response] = [r.f32()?, r.f32()?, r.f32()?, r.f32()?, r.f32()?];
        f.keypoints.push(Keypoint { x, y, sigma, angle, response });
        f.descriptors.push(r.take(128)?.try_into().ok()?);
    }
    r.0.is_empty().then_some(f)
}

pub fn encode_pairs(pairs: &[VerifiedPair]) -> Vec<u8> {
    let mut out = Vec::new();
    put_u32(&mut out, pairs.len());
    for p in pairs {
        let r = &p.report;
        for v in [r.a, r.b, r.matches, r.inliers] {
            put_u32(&mut out, v);
        }
        out.push(match r.configuration {
            None => 0,
            Some(Configuration::General) => 1,
            Some(Configuration::Planar) => 2,
            Some(Configuration::PureRotation) => 3,
        });
        match &p.geometry {
            None => out.push(0),
            Some(g) => {
                out.push(1);
                let rows = (0..3).flat_map(|i| (0..3).map(move |j| (i, j)));
                let numbers = rows
                    .map(|(i, j)| g.pose.r[(i, j)])
                    .chain(g.pose.t.iter().copied())
                    .chain([g.median_triangulation_angle_deg]);
                for v in numbers {
                    out.extend_from_slice(&v.to_le_bytes());
                }
                put_u32(&mut out, g.matches.len());
                for &(a, b) in &g.matches {
                    out.extend_from_slice(&a.to_le_bytes());
                    out.extend_from_slice(&b.to_le_bytes());
                }
            }
        }
    }
    out
}

pub fn decode_pairs(bytes: &[u8]) -> Option<Vec<VerifiedPair>> {
    let mut r = Reader(bytes);
    let n = r.u32()? as usize;
    let mut pairs = Vec::with_capacity(n.min(r.0.len() / 18));
    for _ in 0..n {
        let [a, b, matches, inliers] = [r.u32()?, r.u32()?, r.u32()?, r.u32()?].map(|v| v as usize);
        let configuration = match r.take(1)?[0] {
            0 => None,
            1 => Some(Configuration::General),
            2 => Some(Configuration::Planar),
            3 => Some(Configuration::PureRotation),
            _ => return None,
        };
        let geometry = match r.take(1)?[0] {
            0 => None,
            1 => {
                let mut v = [0.0; 13];
                for x in &mut v {
                    *x = f64::from_le_bytes(r.take(8)?.try_into().ok()?);
                }
                let count = r.u32()? as usize;
                if count.checked_mul(8)? > r.0.len() {
                    return None;
                }
                let matches = (0..count).map(|_| Some((r.u32()?, r.u32()?))).collect::<Option<Vec<_>>>()?;
                Some(PairGeometry {
                    matches,
                    pose: RelativePose {
                        r: Matrix3::from_row_slice(&v[..9]),
                        t: Vector3::new(v[9], v[10], v[11]),
                    },
                    median_triangulation_angle_deg: v[12],
                })
            }
            _ => return None,
        };
        let report = PairReport { a, b, matches, inliers, configuration };
        pairs.push(VerifiedPair { report, geometry, matching_s: 0.0, verification_s: 0.0 });
    }
    r.0.is_empty().then_some(pairs)
}

fn put_u32(out: &mut Vec<u8>, v: usize) {
    // Counts and indices of one image's keypoints or one reconstruction's images.
    out.extend_from_slice(&(v as u32).to_le_bytes());
}

struct Reader<'a>(&'a [u8]);

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let (head, rest) = (self.0.get(..n)?, self.0.get(n..)?);
        self.0 = rest;
        Some(head)
    }
    fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }
    fn f32(&mut self) -> Option<f32> {
        Some(f32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_bit_for_bit_and_refuses_damage() {
        let f = Features {
            keypoints: vec![
                Keypoint { x: 1.5, y: -0.0, sigma: 1.6, angle: -3.1, response: f32::MIN_POSITIVE },
                Keypoint { x: 1e7, y: 0.1, sigma: 12.0, angle: 0.0, response: 0.5 },
            ],
            descriptors: vec![[7u8; 128], std::array::from_fn(|i| i as u8)],
        };
        let e = encode_features(&f);
        let d = decode_features(&e).unwrap();
        assert_eq!(d.descriptors, f.descriptors);
        for (a, b) in d.keypoints.iter().zip(&f.keypoints) {
            assert_eq!([a.x, a.y, a.angle].map(f32::to_bits), [b.x, b.y, b.angle].map(f32::to_bits));
            assert_eq!((a.sigma, a.response), (b.sigma, b.response));
        }
        assert!(decode_features(&e[..e.len() - 1]).is_none());
        assert!(decode_features(&[e.as_slice(), &[0]].concat()).is_none());
        assert!(decode_features(&[255, 255, 255, 255]).is_none());

        let g = PairGeometry {
            matches: vec![(0, 3), (u32::MAX, 9)],
            pose: RelativePose {
                r: Matrix3::from_fn(|i, j| (i * 3 + j) as f64 / 7.0),
                t: Vector3::new(0.1, -0.2, 1e-300),
            },
            median_triangulation_angle_deg: 4.25,
        };
        let pairs = vec![
            VerifiedPair {
                report: PairReport {
                    a: 0,
                    b: 5,
                    matches: 80,
                    inliers: 2,
                    configuration: Some(Configuration::General),
                },
                geometry: Some(g),
                matching_s: 0.0,
                verification_s: 0.0,
            },
            VerifiedPair {
                report: PairReport { a: 1, b: 2, matches: 3, inliers: 0, configuration: None },
                geometry: None,
                matching_s: 0.0,
                verification_s: 0.0,
            },
        ];
        let e = encode_pairs(&pairs);
        assert_eq!(decode_pairs(&e).unwrap(), pairs);
        for cut in [1, 8, e.len() - 1] {
            assert!(decode_pairs(&e[..cut]).is_none(), "{cut}");
        }
        let mut bad = e.clone();
        bad[4 + 16] = 9; // the first pair's configuration
        assert!(decode_pairs(&bad).is_none());
    }
}
