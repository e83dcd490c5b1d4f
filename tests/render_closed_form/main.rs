//! The renderer against closed forms and invariants, one test binary with a module per topic:
//! lights, environments, the camera, materials, and the path loop itself. Helpers shared by
//! several topics live here.

#[path = "../common/mod.rs"]
mod common;

mod aim;
mod camera;
mod environment;
mod integrators;
mod lights;
mod materials;
mod media;
mod path_loop;

use lumen::math::{CameraModel, Distortion, Intrinsics};
use lumen::render;

pub const PLANE: &str = r#"
[camera]
width = 48
height = 48
fx = 40.0
fy = 40.0
cx = 23.5
cy = 23.5
look_at = { origin = [0.0, 0.0, 2.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }
[[materials]]
name = "paper"
type = "lambertian"
albedo = [0.8, 0.5, 0.2]
[[shapes]]
type = "quad"
corner = [-3.0, -3.0, 0.0]
edge_u = [6.0, 0.0, 0.0]
edge_v = [0.0, 6.0, 0.0]
material = "paper"
[[lights]]
type = "point"
position = [0.3, -0.2, 1.0]
power = [50.0, 50.0, 50.0]
"#;

/// A lamp shape (emitting radiance 2 from its front) over a 4×4 Lambertian floor of albedo 0.9
/// at z = 0, direct light only; a 3×3 camera at z = 0.5 looking straight down with a footprint
/// of 0.0005 rad per pixel: the centre pixel's mean and standard error after `spp` samples.
pub fn floor_under_lamp(lamp: &str, spp: u32) -> (f64, f64) {
    let text = format!(
        "[camera]\nwidth = 3\nheight = 3\nfx = 2000.0\nfy = 2000.0\ncx = 1.0\ncy = 1.0\nlook_at = {{ origin = [0.0, 0.0, 0.5], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }}\n[[materials]]\nname = \"lamp\"\ntype = \"lambertian\"\nalbedo = [0.0, 0.0, 0.0]\nemission = [2.0, 2.0, 2.0]\n[[materials]]\nname = \"floor\"\ntype = \"lambertian\"\nalbedo = [0.9, 0.9, 0.9]\n[[shapes]]\n{lamp}\nmaterial = \"lamp\"\n[[shapes]]\ntype = \"quad\"\ncorner = [-2.0, -2.0, 0.0]\nedge_u = [4.0, 0.0, 0.0]\nedge_v = [0.0, 4.0, 0.0]\nmaterial = \"floor\"\n"
    );
    let dir = tempfile::tempdir().unwrap();
    let scene = common::scene(&text, dir.path()).unwrap();
    let mut s = common::settings(&scene, spp, 2);
    s.crop = Some([1, 1, 2, 2]);
    let film = render::render(&scene, &s);
    (film.mean.data[0] as f64, (film.variance.data[0] as f64).sqrt())
}

pub fn camera_640(distortion: Distortion) -> CameraModel {
    CameraModel {
        width: 640,
        height: 480,
        intrinsics: Intrinsics { fx: 500.0, fy: 500.0, cx: 319.5, cy: 239.5 },
        distortion,
    }
}

pub const STRONG: Distortion = Distortion { k1: -0.3, k2: 0.1, p1: 0.001, p2: -0.0005, k3: 0.0 };
