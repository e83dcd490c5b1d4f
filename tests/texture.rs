//! Textures from photographs (`ibr::texture`, `lumen texture`) against the renderer's truth:
//! a sphere painted with value noise, and a small sphere beside it that hides part of it from
//! some views, seen from 12 views under a uniform sky; the texture drawn into a held-out view
//! is compared with that view's albedo.

mod common;

use glam::DVec3;
use lumen::ibr::texture::{self, Config, Photo};
use lumen::ibr::View;
use lumen::image::Image;
use lumen::math::CameraToWorld;
use lumen::render;
use lumen::surface::march::Mesh;

/// A unit sky (radiance 1) and direct lighting only: a convex Lambertian surface's radiance is
/// its albedo times the share of the sky it sees (the small sphere hides at most 0.7 % of it).
const SCENE: &str = r#"
[camera]
width = 160
height = 160
fov_deg = 50.0
look_at = { origin = [0.0, -4.5, 0.0], target = [0.0, 0.0, 0.0], up = [0.0, 0.0, 1.0] }

[render]
spp = 64
max_depth = 2
seed = 1
sampler = "sobol"

[[materials]]
name = "painted"
type = "lambertian"
albedo = { noise = { seed = 3, octaves = 3, size = 256, low = [0.1, 0.1, 0.1], high = [0.8, 0.7, 0.6] } }

[[materials]]
name = "red"
type = "lambertian"
albedo = [0.8, 0.2, 0.2]

[[shapes]]
type = "sphere"
center = [0.0, 0.0, 0.0]
radius = 1.0
material = "painted"

[[shapes]]
type = "sphere"
center = [2.2, 0.0, 0.0]
radius = 0.3
material = "red"

[[lights]]
type = "environment"
radiance = [1.0, 1.0, 1.0]
"#;

/// An icosphere: the icosahedron subdivided `levels` times, its vertices on the sphere.
fn icosphere(centre: DVec3, radius: f64, levels: u32) -> Mesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<DVec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| DVec3::new(x, y, z).normalize())
    .collect();
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut mid = std::collections::HashMap::new();
        let mut m = |a: u32, b: u32, v: &mut Vec<DVec3>| -> u32 {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                v.push(((v[a as usize] + v[b as usize]) / 2.0).normalize());
                v.len() as u32 - 1
            })
        };
        let mut next = Vec::new();
        for [a, b, c] in f {
            let (ab, bc, ca) = (m(a, b, &mut v), m(b, c, &mut v), m(c, a, &mut v));
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        f = next;
    }
    Mesh { vertices: v.iter().map(|&p| centre + radius * p).collect(), triangles: f }
}

fn mesh() -> Mesh {
    let mut m = icosphere(DVec3::ZERO, 1.0, 4);
    let small = icosphere(DVec3::new(2.2, 0.0, 0.0), 0.3, 3);
    let base = m.vertices.len() as u32;
    m.vertices.extend(small.vertices);
    m.triangles.extend(small.triangles.iter().map(|t| t.map(|i| i + base)));
    m
}

/// A view on a ring about z of radius 4.5, at `deg` degrees and height `z`, looking at the
/// big sphere; its render (`gain` per channel applied: a photograph's exposure and white
/// balance) and albedo.
fn view(deg: f64, z: f64, gain: [f32; 3]) -> (Image, Image, View) {
    let dir = tempfile::tempdir().unwrap();
    let mut scene = common::scene(SCENE, dir.path()).unwrap();
    let a = deg.to_radians();
    let origin = DVec3::new(4.5 * a.cos(), 4.5 * a.sin(), z);
    scene.t_world_cam = CameraToWorld::look_at(origin, DVec3::ZERO, DVec3::Z).unwrap();
    let mut film = render::render(&scene, &common::settings(&scene, 64, 2));
    for px in film.mean.data.chunks_mut(3) {
        for k in 0..3 {
            px[k] *= gain[k];
        }
    }
    let albedo = render::truth(&scene, None).albedo;
    (film.mean, albedo, View { camera: scene.camera, t_world_cam: scene.t_world_cam })
}

/// PSNR (peak 1) of `drawn` against `albedo` over the pixels inside the drawn mask whose 3×3
/// neighbourhood is all inside it (a silhouette pixel mixes the sky in the render).
fn psnr(drawn: &Image, mask: &Image, albedo: &Image) -> (f64, usize) {
    let (w, h) = (mask.width as usize, mask.height as usize);
    let (mut se, mut n) = (0.0f64, 0usize);
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let inside = (0..9).all(|k| mask.data[(y + k / 3 - 1) * w + x + k % 3 - 1] > 0.0);
            if !inside {
                continue;
            }
            for c in 0..3 {
                let i = (y * w + x) * 3 + c;
                se += ((drawn.data[i] - albedo.data[i]) as f64).powi(2);
            }
            n += 1;
        }
    }
    (10.0 * (1.0 / (se / (3 * n) as f64)).log10(), n)
}

fn views(gains: bool) -> Vec<(Image, Image, View)> {
    (0..12)
        .map(|k| {
            let g = if gains && k % 3 == 1 {
                [1.3, 1.1, 0.9]
            } else if gains && k % 3 == 2 {
                [0.8, 0.85, 1.0]
            } else {
                [1.0; 3]
            };
            view(30.0 * k as f64, if k % 2 == 0 { 1.5 } else { -1.0 }, g)
        })
        .collect()
}

/// The texture made from 12 views with their true cameras, drawn into a held-out view, is
/// within 30 dB PSNR of that view's albedo; and with a third of the photographs brighter and
/// warmer and a third darker and cooler, the fitted gains bring it back.
#[test]
fn texture_from_twelve_views_matches_the_albedo() {
    let m = mesh();
    let (_, held_albedo, held) = view(45.0, 0.4, [1.0; 3]);
    for gains in [false, true] {
        let v = views(gains);
        let photos: Vec<Photo> = v
            .iter()
            .enumerate()
            .map(|(k, (img, _, view))| Photo { name: format!("view {k}"), image: img, view: *view })
            .collect();
        let out = texture::run(&m, &photos, &Config { size: 512, ..Config::default() }).unwrap();
        let (drawn, mask) = texture::draw(&m, &out.atlas, &out.texture, &held);
        let (p, n) = psnr(&drawn, &mask, &held_albedo);
        let s = &out.summary;
        eprintln!(
            "gains {gains}: PSNR {p:.2} dB over {n} pixels; {} charts, {} texels, {:.1} % seen, {:.2} s; gains {:?}",
            s.charts,
            s.texels,
            100.0 * s.seen_fraction,
            s.seconds,
            s.photos.iter().map(|p| p.gain.iter().map(|g| (g * 1000.0).round() / 1000.0).collect::<Vec<_>>()).collect::<Vec<_>>()
        );
        assert!(n > 3000, "{n} pixels compared");
        assert!(p >= 30.0, "gains {gains}: PSNR {p:.2} dB: expected ≥ 30 dB");
        assert!(s.seen_fraction > 0.95, "{}", s.seen_fraction);
    }
}

/// The small sphere hides part of the big one from the views near +x: the texels it hides
/// are not painted red from those views. Without the occlusion test the big sphere's side
/// facing +x would take the small sphere's red.
#[test]
fn an_occluder_does_not_paint_what_it_hides() {
    let m = mesh();
    // Views straight along +x see the small sphere in front of the big one's +x pole.
    let v: Vec<_> = [(0.0, 0.0), (120.0, 1.0), (240.0, -1.0), (8.0, 0.3), (-8.0, -0.3)]
        .iter()
        .map(|&(d, z)| view(d, z, [1.0; 3]))
        .collect();
    let photos: Vec<Photo> = v
        .iter()
        .enumerate()
        .map(|(k, (img, _, view))| Photo { name: format!("{k}"), image: img, view: *view })
        .collect();
    let out = texture::run(&m, &photos, &Config { size: 256, equalise: false, ..Config::default() }).unwrap();
    // Seen from just above the +x pole, past the small sphere: red would show there.
    let (_, albedo, above) = view(0.0, 3.5, [1.0; 3]);
    let (drawn, mask) = texture::draw(&m, &out.atlas, &out.texture, &above);
    let mut red = 0;
    let mut compared = 0;
    for i in 0..mask.data.len() {
        if mask.data[i] == 0.0 || albedo.data[i * 3 + 1] < 0.05 {
            continue;
        }
        compared += 1;
        // The painted sphere's albedo has r ≈ g; the small sphere's r = 4 g.
        let (r, g) = (drawn.data[i * 3], drawn.data[i * 3 + 1]);
        let (tr, tg) = (albedo.data[i * 3], albedo.data[i * 3 + 1]);
        if r > 2.0 * g && tr < 1.5 * tg {
            red += 1;
        }
    }
    eprintln!("{red} of {compared} pixels of the big sphere painted red");
    assert!(compared > 1000);
    assert!(red * 1000 < compared, "{red} of {compared} pixels painted with the occluder's red");
}

/// Writes `mesh` as OBJ text.
fn obj(mesh: &Mesh) -> String {
    let mut s = String::new();
    for v in &mesh.vertices {
        s += &format!("v {} {} {}\n", v.x, v.y, v.z);
    }
    for t in &mesh.triangles {
        s += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    s
}

/// A COLMAP text model of `views` (PINHOLE, principal points +0.5), named view0.png ….
fn colmap_model(views: &[View]) -> (String, String) {
    let mut cameras = String::from("# CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n");
    let mut images = String::from("# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n");
    for (k, v) in views.iter().enumerate() {
        let c = &v.camera;
        let i = &c.intrinsics;
        cameras += &format!(
            "{} PINHOLE {} {} {} {} {} {}\n",
            k + 1,
            c.width,
            c.height,
            i.fx,
            i.fy,
            i.cx + 0.5,
            i.cy + 0.5
        );
        let p = v.t_world_cam.inverse();
        let r = p.rotation;
        let m = nalgebra::Matrix3::new(
            r.x_axis.x, r.y_axis.x, r.z_axis.x, r.x_axis.y, r.y_axis.y, r.z_axis.y, r.x_axis.z, r.y_axis.z,
            r.z_axis.z,
        );
        let q = nalgebra::UnitQuaternion::from_matrix(&m);
        let t = p.translation;
        images += &format!(
            "{} {} {} {} {} {} {} {} {} view{k}.png\n\n",
            k + 1,
            q.w,
            q.i,
            q.j,
            q.k,
            t.x,
            t.y,
            t.z,
            k + 1
        );
    }
    (cameras, images)
}

/// `lumen texture` end to end from PNG photographs and a COLMAP model, and its refusals, each
/// naming the file and the value, with nothing written: a mesh without faces, a camera model
/// lumen does not read, a photograph missing, cameras that look away from the mesh.
#[test]
fn lumen_texture_from_a_colmap_model() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let v: Vec<_> =
        (0..6).map(|k| view(60.0 * k as f64, if k % 2 == 0 { 1.2 } else { -0.8 }, [1.0; 3])).collect();
    std::fs::create_dir_all(d.join("images")).unwrap();
    for (k, (img, _, _)) in v.iter().enumerate() {
        lumen::image::io::write_png_srgb(&d.join(format!("images/view{k}.png")), img).unwrap();
    }
    let views: Vec<View> = v.iter().map(|x| x.2).collect();
    let (cameras, images) = colmap_model(&views);
    std::fs::create_dir_all(d.join("model")).unwrap();
    std::fs::write(d.join("model/cameras.txt"), &cameras).unwrap();
    std::fs::write(d.join("model/images.txt"), &images).unwrap();
    std::fs::write(d.join("mesh.obj"), obj(&mesh())).unwrap();
    let p = |s: &str| d.join(s).display().to_string();
    let run = |mesh: &str, model: &str, out: &str| {
        common::lumen(&[
            "texture",
            "--mesh",
            &p(mesh),
            "--model",
            &p(model),
            "--images",
            &p("images"),
            "--out",
            &p(out),
            "--size",
            "256",
        ])
    };
    let (code, err) = run("mesh.obj", "model", "out");
    assert_eq!(code, 0, "{err}");
    for f in ["mesh.obj", "mesh.mtl", "texture.png", "summary.json"] {
        assert!(d.join("out").join(f).is_file(), "{f}: {err}");
    }
    let textured = lumen::render::obj::read(&d.join("out/mesh.obj")).unwrap();
    assert_eq!(textured.triangles.len(), mesh().triangles.len());
    assert!(
        textured.triangles.iter().all(|t| t.vt.is_some())
            && textured.uvs.iter().all(|uv| uv.x >= 0.0 && uv.x <= 1.0 && uv.y >= 0.0 && uv.y <= 1.0)
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("out/summary.json")).unwrap()).unwrap();
    // Six views on two rings leave the poles and the small sphere's far side unseen (about 11 %).
    assert!(summary["seen_fraction"].as_f64().unwrap() > 0.8, "{summary}");

    std::fs::write(d.join("points.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\n").unwrap();
    std::fs::create_dir_all(d.join("fisheye")).unwrap();
    std::fs::write(d.join("fisheye/cameras.txt"), cameras.replacen("PINHOLE", "OPENCV_FISHEYE", 1)).unwrap();
    std::fs::write(d.join("fisheye/images.txt"), &images).unwrap();
    std::fs::create_dir_all(d.join("missing")).unwrap();
    std::fs::write(d.join("missing/cameras.txt"), &cameras).unwrap();
    std::fs::write(d.join("missing/images.txt"), images.replace("view3.png", "view9.png")).unwrap();
    // Every camera turned to look away: its pose's rotation by 180° about its own y axis.
    let away: Vec<View> = views
        .iter()
        .map(|v| {
            let mut v = *v;
            v.t_world_cam.0.rotation =
                v.t_world_cam.rotation * glam::DMat3::from_diagonal(DVec3::new(-1.0, 1.0, -1.0));
            v
        })
        .collect();
    let (c2, i2) = colmap_model(&away);
    std::fs::create_dir_all(d.join("away")).unwrap();
    std::fs::write(d.join("away/cameras.txt"), c2).unwrap();
    std::fs::write(d.join("away/images.txt"), i2).unwrap();
    for (mesh, model, expect) in [
        ("points.obj", "model", "no faces"),
        ("mesh.obj", "fisheye", "OPENCV_FISHEYE"),
        ("mesh.obj", "missing", "view9.png"),
        ("mesh.obj", "away", "no photograph sees the mesh"),
    ] {
        let (code, err) = run(mesh, model, "refused");
        assert_ne!(code, 0, "{model}");
        assert!(err.contains(expect), "{mesh} {model}: {err}");
        assert!(!d.join("refused").exists(), "{model}: something was written");
    }
}
