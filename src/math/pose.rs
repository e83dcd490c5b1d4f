//! Rigid transforms. `t_a_b` maps coordinates in frame b to frame a: p_a = R·p_b + t.
//!
//! A camera's pose carries its direction in its type, as rust-cv's `CameraToWorld` and
//! `WorldToCamera` do: the renderer places a camera by `CameraToWorld` (`t_world_cam`), while
//! calibration, structure from motion and the files they write (OpenCV's rvec/tvec, COLMAP's
//! images.txt) hold `WorldToCamera`. `inverse` turns one into the other, so a pose is never
//! read in the wrong direction. Both hand on `Pose`'s arithmetic.

use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub rotation: DMat3,
    pub translation: DVec3,
}

impl Pose {
    pub const IDENTITY: Pose = Pose { rotation: DMat3::IDENTITY, translation: DVec3::ZERO };

    pub fn transform_point(&self, p: DVec3) -> DVec3 {
        self.rotation * p + self.translation
    }

    pub fn transform_vector(&self, v: DVec3) -> DVec3 {
        self.rotation * v
    }

    pub fn inverse(&self) -> Pose {
        let rt = self.rotation.transpose();
        Pose { rotation: rt, translation: -(rt * self.translation) }
    }

    /// `self ∘ other`: first `other`, then `self`.
    pub fn compose(&self, other: &Pose) -> Pose {
        Pose {
            rotation: self.rotation * other.rotation,
            translation: self.rotation * other.translation + self.translation,
        }
    }

    /// Rotation from a Rodrigues vector (axis × angle in radians), as OpenCV's `Rodrigues`.
    pub fn rotation_from_rvec(rvec: DVec3) -> DMat3 {
        let angle = rvec.length();
        if angle < 1e-300 {
            return DMat3::IDENTITY;
        }
        DMat3::from_axis_angle(rvec / angle, angle)
    }

    /// Rodrigues vector of a rotation matrix (OpenCV's `Rodrigues`), stable near 0 and π: the
    /// inverse of `rotation_from_rvec`.
    pub fn rvec_from_rotation(r: &DMat3) -> DVec3 {
        let q = glam::DQuat::from_mat3(r).normalize();
        let q = if q.w < 0.0 { -q } else { q };
        // angle = 2·atan2(|v|, w) along v: atan2 keeps full precision at both ends, where
        // acos(w) loses half the digits of a tiny angle.
        let v = DVec3::new(q.x, q.y, q.z);
        let s = v.length();
        if s < 1e-300 {
            DVec3::ZERO
        } else {
            v * (2.0 * s.atan2(q.w) / s)
        }
    }

    /// Largest deviation of RᵀR from the identity and det(R) from 1.
    pub fn orthonormality_error(r: &DMat3) -> f64 {
        let d = r.transpose() * *r - DMat3::IDENTITY;
        let m = d.to_cols_array().iter().fold(0.0f64, |a, &b| a.max(b.abs()));
        m.max((r.determinant() - 1.0).abs())
    }
}

/// A camera's frame mapped to the world's, p_world = R·p_cam + t: t is the camera centre and
/// R's columns are the camera's axes (x right, y down, z forward) in the world.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct CameraToWorld(pub Pose);

/// The world's frame mapped to a camera's, p_cam = R·p_world + t (OpenCV's rvec and tvec,
/// COLMAP's images.txt).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct WorldToCamera(pub Pose);

impl CameraToWorld {
    /// A camera at `origin` looking at `target`, OpenCV axes (x right, y down, z forward),
    /// with `up` pointing up in the image.
    pub fn look_at(origin: DVec3, target: DVec3, up: DVec3) -> Option<CameraToWorld> {
        let z = (target - origin).normalize_or_zero();
        let x = z.cross(up).normalize_or_zero();
        if z == DVec3::ZERO || x == DVec3::ZERO {
            return None;
        }
        let y = z.cross(x);
        Some(CameraToWorld(Pose { rotation: DMat3::from_cols(x, y, z), translation: origin }))
    }

    pub fn inverse(&self) -> WorldToCamera {
        WorldToCamera(self.0.inverse())
    }

    /// The camera centre in the world.
    pub fn centre(&self) -> DVec3 {
        self.0.translation
    }
}

impl WorldToCamera {
    pub fn inverse(&self) -> CameraToWorld {
        CameraToWorld(self.0.inverse())
    }
}

impl std::ops::Deref for CameraToWorld {
    type Target = Pose;
    fn deref(&self) -> &Pose {
        &self.0
    }
}

impl std::ops::Deref for WorldToCamera {
    type Target = Pose;
    fn deref(&self) -> &Pose {
        &self.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverse_and_composition() {
        let p = Pose {
            rotation: Pose::rotation_from_rvec(DVec3::new(0.3, -0.2, 0.9)),
            translation: DVec3::new(1.0, -2.0, 0.5),
        };
        let q = p.compose(&p.inverse());
        assert!(Pose::orthonormality_error(&q.rotation) < 1e-12);
        assert!((q.rotation - DMat3::IDENTITY).to_cols_array().iter().all(|v| v.abs() < 1e-12));
        assert!(q.translation.length() < 1e-12);
        let x = DVec3::new(0.2, 0.7, -1.1);
        assert!((p.inverse().transform_point(p.transform_point(x)) - x).length() < 1e-12);
    }

    #[test]
    fn rvec_round_trip_near_zero_and_pi() {
        for r in [
            DVec3::ZERO,
            DVec3::new(1e-9, 0.0, -2e-9),
            DVec3::new(0.3, -0.2, 0.9),
            DVec3::new(0.0, 0.0, std::f64::consts::PI - 1e-7),
            DVec3::new(1.0, 1.0, 0.0).normalize() * (std::f64::consts::PI - 1e-6),
        ] {
            let back = Pose::rvec_from_rotation(&Pose::rotation_from_rvec(r));
            assert!((back - r).length() < 1e-9, "{r} -> {back}");
        }
    }

    #[test]
    fn look_at_uses_opencv_axes() {
        let p = CameraToWorld::look_at(DVec3::new(0.0, 0.0, 3.9), DVec3::ZERO, DVec3::Y).unwrap();
        assert!((p.rotation.x_axis - DVec3::X).length() < 1e-15);
        assert!((p.rotation.y_axis + DVec3::Y).length() < 1e-15);
        assert!((p.rotation.z_axis + DVec3::Z).length() < 1e-15);
    }
}
