//! Generated test objects as triangle meshes, for scenes that need known shapes more complex
//! than a sphere (photometric stereo's cast shadows, interreflections and concave regions):
//!
//! - `torus(R, r, [nu, nv])`: p(u, v) = ((R + r·cos v)·cos u, (R + r·cos v)·sin u, r·sin v),
//!   around the z axis;
//! - `blob(R, A, k, [nθ, nφ])`: the sphere of radius R displaced along its normal,
//!   p(d) = R·(1 + A·sin(k·dx)·sin(k·dy)·sin(k·dz))·d for unit directions d, smooth
//!   everywhere (the displacement is a function of d, not of the angles);
//! - `relief(size, h, n)`: the height field z = h·Σᵢ aᵢ·exp(−|p − cᵢ|²/(2wᵢ²)) over the square
//!   [−size/2, size/2]² (n×n cells): a tall bump in the middle, two smaller bumps and two
//!   dimples round it (centres, widths and signs in `RELIEF_BUMPS`), so it has slopes in every
//!   direction, concave parts and cast shadows under low light.
//!
//! Triangles wind counter-clockwise seen from outside (torus, blob) or from +z (relief).
//! Shading uses the facets' geometric normals, so the tessellation should be fine enough that
//! neighbouring facets differ by a degree or two.

use glam::DVec3;
use std::f64::consts::{PI, TAU};

/// Vertices and triangles (vertex indices).
pub struct Surface {
    pub positions: Vec<DVec3>,
    pub triangles: Vec<[u32; 3]>,
}

/// Quads of a (nu + 1) × (nv + 1) vertex grid, each split in two; vertex (i, j) at
/// index j·(nu + 1) + i.
fn grid(positions: Vec<DVec3>, nu: u32, nv: u32) -> Surface {
    let at = |i: u32, j: u32| j * (nu + 1) + i;
    let mut triangles = Vec::with_capacity(2 * (nu * nv) as usize);
    for j in 0..nv {
        for i in 0..nu {
            triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    Surface { positions, triangles }
}

/// Vertices p(i/nu, j/nv) of a parametrised surface over the unit square.
fn sample(nu: u32, nv: u32, p: impl Fn(f64, f64) -> DVec3) -> Vec<DVec3> {
    (0..=nv)
        .flat_map(|j| (0..=nu).map(move |i| (i, j)))
        .map(|(i, j)| p(i as f64 / nu as f64, j as f64 / nv as f64))
        .collect()
}

pub fn torus(radius: f64, tube: f64, [nu, nv]: [u32; 2]) -> Surface {
    let p = sample(nu, nv, |s, t| {
        let (u, v) = (TAU * s, TAU * t);
        let ring = radius + tube * v.cos();
        DVec3::new(ring * u.cos(), ring * u.sin(), tube * v.sin())
    });
    grid(p, nu, nv)
}

pub fn blob(radius: f64, amplitude: f64, lobes: f64, [ntheta, nphi]: [u32; 2]) -> Surface {
    // u runs round in φ, v from the north pole (θ = 0) down, so quads wind outwards.
    let p = sample(nphi, ntheta, |s, t| {
        let (phi, theta) = (TAU * s, PI * t);
        let d = DVec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
        let k = lobes;
        radius * (1.0 + amplitude * (k * d.x).sin() * (k * d.y).sin() * (k * d.z).sin()) * d
    });
    let mut s = grid(p, nphi, ntheta);
    // (u, v) = (φ, θ) gives ∂φ × ∂θ pointing inwards: flip.
    for t in &mut s.triangles {
        t.swap(1, 2);
    }
    s
}

/// (centre x, centre y, width, amplitude) in units of the relief's size and height.
pub const RELIEF_BUMPS: [(f64, f64, f64, f64); 5] = [
    (0.0, 0.0, 0.12, 1.0),
    (0.25, 0.2, 0.08, 0.6),
    (-0.22, -0.25, 0.07, 0.5),
    (-0.25, 0.22, 0.08, -0.5),
    (0.22, -0.22, 0.06, -0.4),
];

pub fn relief(size: f64, height: f64, n: u32) -> Surface {
    let p = sample(n, n, |s, t| {
        let (x, y) = ((s - 0.5) * size, (t - 0.5) * size);
        let z: f64 = RELIEF_BUMPS
            .iter()
            .map(|&(cx, cy, w, a)| {
                let (dx, dy, w) = (x - cx * size, y - cy * size, w * size);
                a * (-(dx * dx + dy * dy) / (2.0 * w * w)).exp()
            })
            .sum();
        DVec3::new(x, y, height * z)
    });
    grid(p, n, n)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn normal(s: &Surface, t: &[u32; 3]) -> DVec3 {
        let [a, b, c] = t.map(|k| s.positions[k as usize]);
        (b - a).cross(c - a)
    }

    /// Facets face outwards (torus: away from the tube's centre line; blob: away from the
    /// origin) and, for the relief, up.
    #[test]
    fn facets_face_outwards() {
        let t = torus(1.0, 0.3, [32, 16]);
        for tri in &t.triangles {
            let c = tri.iter().map(|&k| t.positions[k as usize]).sum::<DVec3>() / 3.0;
            let axis = DVec3::new(c.x, c.y, 0.0).normalize();
            assert!(normal(&t, tri).dot(c - axis) > 0.0);
        }
        let b = blob(1.0, 0.1, 3.0, [32, 64]);
        let mut faces = 0;
        for tri in &b.triangles {
            let n = normal(&b, tri);
            if n.length() > 1e-12 {
                let c = tri.iter().map(|&k| b.positions[k as usize]).sum::<DVec3>() / 3.0;
                assert!(n.dot(c) > 0.0);
                faces += 1;
            }
        }
        assert!(faces > 3900);
        let r = relief(2.0, 0.3, 16);
        assert!(r.triangles.iter().all(|tri| normal(&r, tri).z > 0.0));
    }

    /// The torus's area converges to 4π²Rr.
    #[test]
    fn torus_area() {
        let t = torus(1.0, 0.3, [256, 128]);
        let area: f64 = t.triangles.iter().map(|tri| 0.5 * normal(&t, tri).length()).sum();
        let exact = 4.0 * PI * PI * 0.3;
        assert!((area / exact - 1.0).abs() < 1e-3, "{area} vs {exact}");
    }
}
