//! Normal integration: a depth map from a normal map over a mask, by a Poisson solve (the
//! least-squares surface of Horn & Brooks 1986, discretised on the mask as in Queau, Durou &
//! Aujol 2018, "Normal integration: a survey").
//!
//! Orthographic projection, pixel units, the dataset's frame (x right, y up, z towards the
//! camera): the surface z(x, y) has gradients p = ∂z/∂x = −n_x/n_z and q = ∂z/∂y = −n_y/n_z.
//! Every pair of neighbouring mask pixels gives one equation, z(right) − z(left) = (p + p')/2
//! and z(above) − z(below) = (q + q')/2 (rows run downwards, so "above" is the row before);
//! the sum of their squared residuals is minimised by conjugate gradients on the normal
//! equations (a graph Laplacian, Jacobi-preconditioned), with the depth's mean fixed at 0.
//! Near-grazing normals would give unbounded slopes: |p| and |q| are capped at 20 (87° of
//! tilt). Conjugate gradients need no factorisation, so the solve stays linear in memory.

use glam::DVec3;

/// Largest slope taken from a normal.
const MAX_SLOPE: f64 = 20.0;

/// Depth (pixel units, mean 0) at each masked pixel; `pixels` are raster indices y·width + x,
/// `normals` their unit normals (`None`: unknown, such pixels take no part). Returns `None`
/// when fewer than two known pixels touch or the solve does not converge.
pub fn depth(width: usize, pixels: &[usize], normals: &[Option<DVec3>]) -> Option<Vec<f64>> {
    let n = pixels.len();
    // Raster index → position in `pixels`, for the known pixels.
    let index: std::collections::HashMap<usize, usize> =
        pixels.iter().enumerate().filter(|(k, _)| normals[*k].is_some()).map(|(k, &i)| (i, k)).collect();
    let slope = |k: usize| -> (f64, f64) {
        let nm = normals[k].unwrap_or(DVec3::Z);
        let nz = nm.z.max(1e-9);
        ((-nm.x / nz).clamp(-MAX_SLOPE, MAX_SLOPE), (-nm.y / nz).clamp(-MAX_SLOPE, MAX_SLOPE))
    };
    // Edges (a, b, target of z_b − z_a).
    let mut edges = Vec::new();
    for (k, &i) in pixels.iter().enumerate() {
        if normals[k].is_none() {
            continue;
        }
        let (p, q) = slope(k);
        if (i + 1) % width != 0 {
            if let Some(&r) = index.get(&(i + 1)) {
                edges.push((k, r, 0.5 * (p + slope(r).0)));
            }
        }
        if let Some(&d) = index.get(&(i + width)) {
            // The pixel below is lower in y: z(this) − z(below) = (q + q')/2.
            edges.push((d, k, 0.5 * (q + slope(d).1)));
        }
    }
    if edges.is_empty() {
        return None;
    }
    let mut degree = vec![0.0f64; n];
    let mut b = vec![0.0f64; n];
    for &(a, c, t) in &edges {
        degree[a] += 1.0;
        degree[c] += 1.0;
        b[c] += t;
        b[a] -= t;
    }
    // L·z = b with L the graph Laplacian; a tiny diagonal term fixes the free constant of each
    // connected piece without moving the solution measurably.
    let eps = 1e-9;
    let apply = |z: &[f64], out: &mut [f64]| {
        for (o, (zi, d)) in out.iter_mut().zip(z.iter().zip(&degree)) {
            *o = (d + eps) * zi;
        }
        for &(a, c, _) in &edges {
            out[a] -= z[c];
            out[c] -= z[a];
        }
    };
    let precond: Vec<f64> = degree.iter().map(|d| 1.0 / (d + eps).max(1.0)).collect();
    let mut z = vec![0.0f64; n];
    let mut r = b.clone();
    let mut y: Vec<f64> = r.iter().zip(&precond).map(|(r, m)| r * m).collect();
    let mut d = y.clone();
    let mut ad = vec![0.0f64; n];
    let mut ry: f64 = r.iter().zip(&y).map(|(a, b)| a * b).sum();
    let b_norm = b.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300);
    let mut converged = false;
    for _ in 0..20 * n.max(100) {
        apply(&d, &mut ad);
        let dad: f64 = d.iter().zip(&ad).map(|(a, b)| a * b).sum();
        if !(dad > 0.0) {
            break;
        }
        let alpha = ry / dad;
        for k in 0..n {
            z[k] += alpha * d[k];
            r[k] -= alpha * ad[k];
        }
        if r.iter().map(|v| v * v).sum::<f64>().sqrt() <= 1e-10 * b_norm {
            converged = true;
            break;
        }
        for k in 0..n {
            y[k] = r[k] * precond[k];
        }
        let ry_next: f64 = r.iter().zip(&y).map(|(a, b)| a * b).sum();
        let beta = ry_next / ry;
        ry = ry_next;
        for k in 0..n {
            d[k] = y[k] + beta * d[k];
        }
    }
    if !converged || z.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let known: Vec<usize> = (0..n).filter(|&k| normals[k].is_some()).collect();
    let mean = known.iter().map(|&k| z[k]).sum::<f64>() / known.len() as f64;
    Some((0..n).map(|k| if normals[k].is_some() { z[k] - mean } else { 0.0 }).collect())
}

/// A Wavefront OBJ of the surface: one vertex (x, −y, z) per known pixel (pixel units, the
/// dataset's frame), two triangles per 2×2 block of known pixels, facing the camera.
pub fn to_obj(width: usize, pixels: &[usize], normals: &[Option<DVec3>], z: &[f64]) -> String {
    let mut vertex = std::collections::HashMap::new();
    let mut out = String::from("# lumen ps: surface from integrated normals (pixel units)\n");
    for (k, &i) in pixels.iter().enumerate() {
        if normals[k].is_some() {
            vertex.insert(i, vertex.len() + 1);
            out += &format!("v {} {} {:.6}\n", i % width, -((i / width) as f64), z[k]);
        }
    }
    for &i in pixels {
        if (i + 1) % width == 0 {
            continue;
        }
        let quad = [i, i + 1, i + width, i + width + 1].map(|j| vertex.get(&j).copied());
        if let [Some(a), Some(b), Some(c), Some(d)] = quad {
            // Counter-clockwise seen from +z (x right, y up): a (top left), c (below), d, b.
            out += &format!("f {a} {c} {d}\nf {a} {d} {b}\n");
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hemisphere of radius 40 px from its exact normals: depth within 0.1 px RMS of the
    /// truth (after removing the mean) over the inner 90 % of the radius; a plane exactly.
    #[test]
    fn sphere_and_plane() {
        let (w, h, r) = (101usize, 101usize, 40.0f64);
        let (mut pixels, mut normals, mut truth) = (Vec::new(), Vec::new(), Vec::new());
        for y in 0..h {
            for x in 0..w {
                let (u, v) = (x as f64 - 50.0, 50.0 - y as f64);
                if u * u + v * v < (0.95 * r) * (0.95 * r) {
                    let zz = (r * r - u * u - v * v).sqrt();
                    pixels.push(y * w + x);
                    normals.push(Some(DVec3::new(u, v, zz) / r));
                    truth.push(zz);
                }
            }
        }
        let z = depth(w, &pixels, &normals).unwrap();
        let inner: Vec<usize> = (0..pixels.len())
            .filter(|&k| {
                let (x, y) = ((pixels[k] % w) as f64 - 50.0, 50.0 - (pixels[k] / w) as f64);
                x * x + y * y < (0.9 * r) * (0.9 * r)
            })
            .collect();
        let offset = inner.iter().map(|&k| truth[k] - z[k]).sum::<f64>() / inner.len() as f64;
        let rms = (inner.iter().map(|&k| (z[k] + offset - truth[k]).powi(2)).sum::<f64>()
            / inner.len() as f64)
            .sqrt();
        assert!(rms < 0.1, "sphere depth RMS {rms} px");

        // A tilted plane z = 0.3x − 0.2y: exact up to the solver's tolerance.
        let n = DVec3::new(-0.3, 0.2, 1.0).normalize();
        let pixels: Vec<usize> = (0..20 * 20).collect();
        let normals = vec![Some(n); pixels.len()];
        let z = depth(20, &pixels, &normals).unwrap();
        for (k, &i) in pixels.iter().enumerate() {
            let (x, y) = ((i % 20) as f64 - 9.5, 9.5 - (i / 20) as f64);
            assert!((z[k] - (0.3 * x - 0.2 * y)).abs() < 1e-6, "plane at ({x}, {y}): {}", z[k]);
        }
        let obj = to_obj(20, &pixels, &normals, &z);
        assert_eq!(obj.lines().filter(|l| l.starts_with("v ")).count(), 400);
        assert_eq!(obj.lines().filter(|l| l.starts_with("f ")).count(), 2 * 19 * 19);
        // Nothing known: no surface.
        assert!(depth(20, &pixels, &vec![None; 400]).is_none());
    }
}
