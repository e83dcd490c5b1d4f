//! Primitives (triangles and spheres), rays and their intersection, in f32 (`Vec3A`).

use glam::{Vec2, Vec3A};

pub use super::transport::basis;

#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub origin: Vec3A,
    pub dir: Vec3A,
}

/// A primitive as the BVH stores it.
#[derive(Clone, Copy, Debug)]
pub enum Prim {
    /// Vertex 0 and the two edges to vertices 1 and 2 (Möller–Trumbore form).
    Triangle {
        v0: Vec3A,
        e1: Vec3A,
        e2: Vec3A,
    },
    Sphere {
        center: Vec3A,
        radius: f32,
    },
}

/// What the renderer needs to shade a primitive.
#[derive(Clone, Copy, Debug)]
pub struct PrimInfo {
    pub material: u32,
    /// Object id written to the `id` truth image (1-based; 0 is background).
    pub object_id: u32,
    /// Flip the geometric normal (and so the side an emitter emits from).
    pub reverse: bool,
    /// Texture coordinates of the three vertices (triangles only).
    pub uv: [Vec2; 3],
    /// Unit geometric normal, reversal applied (triangles only; spheres compute theirs).
    pub normal: Vec3A,
}

/// Closest hit: distance and the primitive's own surface parameters (barycentrics b1, b2).
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    pub t: f32,
    pub prim: u32,
    pub b1: f32,
    pub b2: f32,
}

impl Prim {
    pub fn bounds(&self) -> (Vec3A, Vec3A) {
        match *self {
            Prim::Triangle { v0, e1, e2 } => {
                let (v1, v2) = (v0 + e1, v0 + e2);
                (v0.min(v1).min(v2), v0.max(v1).max(v2))
            }
            Prim::Sphere { center, radius } => (center - radius, center + radius),
        }
    }

    pub fn centroid(&self) -> Vec3A {
        let (lo, hi) = self.bounds();
        (lo + hi) * 0.5
    }

    pub fn area(&self) -> f32 {
        match *self {
            Prim::Triangle { e1, e2, .. } => 0.5 * e1.cross(e2).length(),
            Prim::Sphere { radius, .. } => 4.0 * std::f32::consts::PI * radius * radius,
        }
    }

    /// Distance along the ray to the primitive within (t_min, t_max), with surface parameters.
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<(f32, f32, f32)> {
        match *self {
            Prim::Triangle { v0, e1, e2 } => {
                let p = ray.dir.cross(e2);
                let det = e1.dot(p);
                if det.abs() < 1e-12 {
                    return None;
                }
                let inv = 1.0 / det;
                let s = ray.origin - v0;
                let b1 = s.dot(p) * inv;
                if !(0.0..=1.0).contains(&b1) {
                    return None;
                }
                let q = s.cross(e1);
                let b2 = ray.dir.dot(q) * inv;
                if b2 < 0.0 || b1 + b2 > 1.0 {
                    return None;
                }
                let t = e2.dot(q) * inv;
                (t > t_min && t < t_max).then_some((t, b1, b2))
            }
            Prim::Sphere { center, radius } => {
                // Stable quadratic (Ray Tracing Gems, ch. 7): the discriminant comes from the
                // closest point on the ray to the centre, avoiding cancellation for small
                // spheres far away; the roots from q and c/q.
                let d = ray.dir;
                let a = d.length_squared();
                let f = ray.origin - center;
                let b = f.dot(d);
                let l = f - (b / a) * d;
                let disc = radius * radius - l.length_squared();
                if disc < 0.0 {
                    return None;
                }
                let q = -b - b.signum() * (a * disc).sqrt();
                if q == 0.0 {
                    return None;
                }
                let c = f.length_squared() - radius * radius;
                let (t0, t1) = {
                    let (x, y) = (c / q, q / a);
                    if x < y {
                        (x, y)
                    } else {
                        (y, x)
                    }
                };
                if t0 > t_min && t0 < t_max {
                    Some((t0, 0.0, 0.0))
                } else if t1 > t_min && t1 < t_max {
                    Some((t1, 0.0, 0.0))
                } else {
                    None
                }
            }
        }
    }

    /// Geometric unit normal at a hit point (triangles: e1 × e2, counter-clockwise front;
    /// spheres: outward).
    pub fn normal(&self, p: Vec3A) -> Vec3A {
        match *self {
            Prim::Triangle { e1, e2, .. } => e1.cross(e2).normalize(),
            Prim::Sphere { center, .. } => (p - center).normalize(),
        }
    }

    /// Point at barycentrics (b1, b2) of a triangle; for spheres, (u, v) ∈ [0,1)² → surface
    /// point by uniform area parametrisation (used by light sampling).
    pub fn sample_area(&self, u: f32, v: f32) -> (Vec3A, Vec3A) {
        match *self {
            Prim::Triangle { v0, e1, e2 } => {
                (super::transport::triangle_point(v0, e1, e2, u, v), e1.cross(e2).normalize())
            }
            Prim::Sphere { center, radius } => {
                let z = 1.0 - 2.0 * u;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let (cos, sin) = super::transport::unit_circle(v);
                let n = Vec3A::new(r * cos, r * sin, z);
                (center + radius * n, n)
            }
        }
    }
}
