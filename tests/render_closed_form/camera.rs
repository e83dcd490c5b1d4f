//! The camera: projection against the f64 model, distortion round trips, the thin lens,
//! truth images.

use super::*;
use glam::{DVec2, DVec3};
use lumen::math::{CameraModel, Distortion};
use lumen::render;

/// The silhouette of a sphere (centre `c` in the camera frame, radius `r`) projected by the
/// forward camera model: a closed polygon in pixel coordinates.
fn projected_silhouette(cam: &CameraModel, c: DVec3, r: f64, n: usize) -> Vec<DVec2> {
    let d2 = c.length_squared();
    let centre = c * (1.0 - r * r / d2);
    let rho = r * (1.0 - r * r / d2).sqrt();
    let axis = c.normalize();
    let u = axis.any_orthonormal_vector();
    let v = axis.cross(u);
    (0..n)
        .map(|k| {
            let phi = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
            cam.project(centre + rho * (phi.cos() * u + phi.sin() * v)).unwrap()
        })
        .collect()
}

/// Area of a polygon clipped to the pixel square centred on (x, y) (Sutherland–Hodgman).
fn area_in_pixel(poly: &[DVec2], x: f64, y: f64) -> f64 {
    let mut pts = poly.to_vec();
    // Each half-plane as (axis, bound, keep-below).
    for (axis, bound, below) in
        [(0, x + 0.5, true), (0, x - 0.5, false), (1, y + 0.5, true), (1, y - 0.5, false)]
    {
        let inside = |p: DVec2| {
            if below {
                p[axis] <= bound
            } else {
                p[axis] >= bound
            }
        };
        let mut out = Vec::with_capacity(pts.len() + 4);
        for i in 0..pts.len() {
            let (a, b) = (pts[i], pts[(i + 1) % pts.len()]);
            if inside(a) {
                out.push(a);
            }
            if inside(a) != inside(b) {
                let t = (bound - a[axis]) / (b[axis] - a[axis]);
                out.push(a + (b - a) * t);
            }
        }
        pts = out;
        if pts.is_empty() {
            return 0.0;
        }
    }
    let mut area = 0.0;
    for i in 0..pts.len() {
        let (a, b) = (pts[i], pts[(i + 1) % pts.len()]);
        area += a.x * b.y - b.x * a.y;
    }
    area.abs() / 2.0
}

/// A small emissive sphere appears where the f64 camera model projects it, with and without
/// strong barrel distortion: the intensity centroid of the render matches, within 0.02 px, the
/// centroid of the same pixels filled by the sphere's silhouette as the forward model projects
/// it (area of the projected silhouette in each pixel). Comparing with the pixelated silhouette
/// rather than the projected centre removes the pixel-phase bias of centroiding a sharp disk
/// (up to 0.02 px for a 1.3 px radius), which is a property of sampling, not of the renderer.
#[test]
fn projection_matches_camera_model() {
    for distortion in [Distortion::default(), STRONG] {
        let cam = camera_640(distortion);
        let d = distortion.to_array();
        for p in [DVec3::new(0.0, 0.0, 1.0), DVec3::new(0.45, -0.3, 1.0), DVec3::new(-0.55, 0.4, 1.2)] {
            let radius = 0.003;
            let text = format!(
                r#"
[camera]
width = 640
height = 480
fx = 500.0
fy = 500.0
cx = 319.5
cy = 239.5
distortion = [{}, {}, {}, {}, {}]
t_world_cam = {{ translation = [0.0, 0.0, 0.0] }}
[[materials]]
name = "glow"
type = "lambertian"
albedo = [0.0, 0.0, 0.0]
emission = [1.0, 1.0, 1.0]
[[shapes]]
type = "sphere"
center = [{}, {}, {}]
radius = {radius}
material = "glow"
"#,
                d[0], d[1], d[2], d[3], d[4], p.x, p.y, p.z
            );
            let dir = tempfile::tempdir().unwrap();
            let scene = common::scene(&text, dir.path()).unwrap();
            let uv = cam.project(p).unwrap();
            let (x0, y0) = (uv.x.round() as u32 - 8, uv.y.round() as u32 - 8);
            let mut s = common::settings(&scene, 4096, 1);
            s.crop = Some([x0, y0, x0 + 16, y0 + 16]);
            let film = render::render(&scene, &s);
            let silhouette = projected_silhouette(&cam, p, radius, 4096);
            let (mut sum, mut var, mut c) = (0.0, 0.0, DVec2::ZERO);
            let (mut esum, mut e) = (0.0, DVec2::ZERO);
            for j in 0..16 {
                for i in 0..16 {
                    let at = DVec2::new((x0 + i) as f64, (y0 + j) as f64);
                    let v = film.mean.pixel(i, j)[0] as f64;
                    sum += v;
                    var += film.variance.pixel(i, j)[0] as f64;
                    c += v * at;
                    let a = area_in_pixel(&silhouette, at.x, at.y);
                    esum += a;
                    e += a * at;
                }
            }
            assert!(sum > 3.0, "the sphere is not in the window around {uv}");
            let (c, e) = (c / sum, e / esum);
            let err = (c - e).length();
            eprintln!("projection of {p} (k1 = {}): centroid off by {err:.4} px", distortion.k1);
            assert!(err < 0.02, "centroid {c} vs projected {e}: {err} px (distortion {distortion:?})");
            // The render's total is the silhouette's area, within 5 standard errors.
            assert!(
                (sum - esum).abs() < 5.0 * var.sqrt(),
                "render sum {sum} ± {} vs silhouette area {esum}",
                var.sqrt()
            );
        }
    }
}

/// distort ∘ undistort = id to 1e-9 px over the whole image, and the converse.
#[test]
fn distortion_round_trip() {
    let strong = Distortion { k3: -0.02, ..STRONG };
    let cam = camera_640(strong);
    let mut worst = 0.0f64;
    for j in (0..=480).step_by(4) {
        for i in (0..=640).step_by(4) {
            let px = DVec2::new(i as f64 - 0.5, j as f64 - 0.5);
            let n = cam.undistort_pixel(px).unwrap_or_else(|| panic!("no undistortion at {px}"));
            let back = cam.normalized_to_pixel(cam.distortion.distort(n));
            worst = worst.max((back - px).length());
        }
    }
    assert!(worst < 1e-9, "distort(undistort(px)) is off by {worst} px");
    for j in -10..=10 {
        for i in -10..=10 {
            let n = DVec2::new(i as f64 * 0.06, j as f64 * 0.045);
            let back = strong.undistort(strong.distort(n)).unwrap();
            assert!((back - n).length() < 1e-12, "undistort(distort({n})) = {back}");
        }
    }
}

/// The thin lens: a small emitting sphere on the axis at depth D (a uniform disk of radius
/// s = fx·R/√(D² − R²) pixels in a pinhole image), seen through an aperture of radius r focused at F, spreads
/// over the disk of radius ρ = fx·r·|1/F − 1/D| pixels around its pinhole projection (every
/// lens point shifts the image by fx·a·(1/F − 1/D) for its offset a). The rendered spot's
/// centroid, flux and second moments (over pixel centres: each pixel integrates its box)
/// must match those of that disk-of-disks binned into pixels, by quadrature.
#[test]
fn thin_lens_defocus_blur() {
    let (fx, r, depth, radius) = (200.0f64, 0.05f64, 4.0f64, 0.06f64);
    let (x, y) = (0.0, 0.0);
    let (px, py) = (31.5, 31.5);
    let window = [20u32, 20, 44, 44];
    // (flux, centroid x, y, variance x, y) of an image window.
    let moments = |img: &dyn Fn(u32, u32) -> f64| {
        let (mut s0, mut sx, mut sy, mut sxx, mut syy) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
        for j in window[1]..window[3] {
            for i in window[0]..window[2] {
                let v = img(i, j);
                let (a, b) = (i as f64, j as f64);
                s0 += v;
                sx += v * a;
                sy += v * b;
                sxx += v * a * a;
                syy += v * b * b;
            }
        }
        let (mx, my) = (sx / s0, sy / s0);
        [s0, mx, my, sxx / s0 - mx * mx, syy / s0 - my * my]
    };
    let render_spot = |lens: &str| {
        let text = format!(
            "[camera]\nwidth = 64\nheight = 64\nfx = {fx}\nfy = {fx}\ncx = 31.5\ncy = 31.5\nt_world_cam = {{ translation = [0.0, 0.0, 0.0] }}\n{lens}\n[render]\nsampler = \"sobol\"\n[[materials]]\nname = \"lamp\"\ntype = \"lambertian\"\nalbedo = [0.0, 0.0, 0.0]\nemission = [1.0, 1.0, 1.0]\n[[shapes]]\ntype = \"sphere\"\ncenter = [{x}, {y}, {depth}]\nradius = {radius}\nmaterial = \"lamp\"\n"
        );
        let dir = tempfile::tempdir().unwrap();
        let scene = common::scene(&text, dir.path()).unwrap();
        let mut settings = common::settings(&scene, 4096, 1);
        settings.crop = Some(window);
        let film = render::render(&scene, &settings);
        assert_eq!(film.dropped_samples, 0);
        moments(&|i, j| film.mean.pixel(i - window[0], j - window[1])[0] as f64)
    };
    // The expected binned spot, per axis: the offset is the sum of independent offsets from
    // the lens disk (radius ρ) and the sphere's disk (radius s), each with the disk's
    // marginal density ∝ √(rad² − t²); binned into the pixel boxes [i − ½, i + ½) by a fine
    // 1D quadrature. Returns (centroid, variance) for a spot centred at c.
    let s = fx * radius / (depth * depth - radius * radius).sqrt();
    let marginal = |rad: f64| -> Vec<(f64, f64)> {
        if rad == 0.0 {
            return vec![(0.0, 1.0)];
        }
        let n = (rad / 0.002) as usize;
        (0..n)
            .map(|k| {
                let t = rad * (2.0 * (k as f64 + 0.5) / n as f64 - 1.0);
                (t, (rad * rad - t * t).sqrt())
            })
            .collect()
    };
    let expected = |rho: f64, c: f64| {
        let (lens, sphere) = (marginal(rho), marginal(s));
        let mut bins = vec![0.0f64; 64];
        for &(a, wa) in &lens {
            for &(b, wb) in &sphere {
                bins[(c + a + b).round() as usize] += wa * wb;
            }
        }
        let total: f64 = bins.iter().sum();
        let mean = bins.iter().enumerate().map(|(i, w)| i as f64 * w).sum::<f64>() / total;
        let var = bins.iter().enumerate().map(|(i, w)| (i as f64 - mean).powi(2) * w).sum::<f64>() / total;
        (mean, var)
    };
    let expected = |rho: f64| {
        let ((mx, vx), (my, vy)) = (expected(rho, px), expected(rho, py));
        [f64::NAN, mx, my, vx, vy]
    };
    let pinhole = render_spot("");
    let want = expected(0.0);
    eprintln!("pinhole: {pinhole:?}, expected {want:?}");
    for k in 1..5 {
        assert!((pinhole[k] - want[k]).abs() < 0.01, "pinhole moment {k}: {} vs {}", pinhole[k], want[k]);
    }
    for focus in [depth, 2.0, 1.2, 9.0] {
        let lens = render_spot(&format!("aperture_radius = {r}\nfocus_distance = {focus}"));
        let rho = fx * r * (1.0 / focus - 1.0 / depth).abs();
        let want = expected(rho);
        eprintln!("focus {focus} (ρ = {rho:.3} px): {lens:?}, expected {want:?}");
        assert!((lens[0] / pinhole[0] - 1.0).abs() < 0.005, "flux {} vs {}", lens[0], pinhole[0]);
        for k in 1..3 {
            assert!(
                (lens[k] - want[k]).abs() < 0.01,
                "focus {focus}: centroid {k}: {} vs {}",
                lens[k],
                want[k]
            );
        }
        for k in 3..5 {
            assert!(
                (lens[k] - want[k]).abs() < 0.01 * want[k].max(1.0),
                "focus {focus}: variance {k}: {} vs {}",
                lens[k],
                want[k]
            );
        }
    }
}

/// The truth images of the same plane: depth, normals and position are known exactly.
#[test]
fn truth_images_of_plane() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene(PLANE, dir.path()).unwrap();
    let t = render::truth(&scene, None);
    for j in 0..48 {
        for i in 0..48 {
            assert!((t.depth.pixel(i, j)[0] - 2.0).abs() < 1e-5);
            assert_eq!(t.normal.pixel(i, j), &[0.0, 0.0, 1.0]);
            let nc = t.normal_camera.pixel(i, j);
            assert!(nc[0].abs() < 1e-6 && nc[1].abs() < 1e-6 && (nc[2] + 1.0).abs() < 1e-6);
            assert!(t.position.pixel(i, j)[2].abs() < 1e-6);
            assert_eq!(t.albedo.pixel(i, j), &[0.8, 0.5, 0.2]);
            assert_eq!(t.id.pixel(i, j)[0], 1.0);
        }
    }
}
