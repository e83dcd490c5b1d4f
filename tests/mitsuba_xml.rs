//! Mitsuba 3 XML scenes read as they are: what they read as (`lumen scene convert` renders
//! the same image), parameters from `-D`, and every malformed or unsupported input refused by
//! element and line. How the renders compare with Mitsuba's own is `tests/render_mitsuba.rs`.

mod common;

use common::{fault_in, lumen};
use lumen::render;
use std::path::Path;

fn xml(name: &str) -> std::path::PathBuf {
    common::root().join("tests/data/mitsuba").join(name)
}

/// The film of a scene file at 4 spp.
fn film(path: &Path) -> render::Film {
    let scene = render::load(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    render::render(&scene, &common::settings(&scene, 4, 8))
}

/// What `lumen scene convert` writes renders the very image the XML renders, in the XML's
/// folder (relative file names) and in another one (absolute file names).
#[test]
fn converted_scene_renders_the_same_image() {
    let dir = tempfile::tempdir().unwrap();
    for (name, out) in [
        ("cornell-box.xml", dir.path().join("cornell.toml")),
        ("envmap-spheres.xml", dir.path().join("envmap.toml")),
        ("media-smoke-grid.xml", dir.path().join("smoke.toml")),
        ("media-haze.xml", dir.path().join("haze.toml")),
    ] {
        let (code, err) =
            lumen(&["scene", "convert", xml(name).to_str().unwrap(), "--out", out.to_str().unwrap()]);
        assert_eq!(code, 0, "{err}");
        let (a, b) = (film(&xml(name)), film(&out));
        assert!(a.mean.data == b.mean.data && a.variance.data == b.variance.data, "{name}: images differ");
    }
    let (code, err) = lumen(&[
        "scene",
        "convert",
        common::root().join("pipelines/scenes/cornell-box.toml").to_str().unwrap(),
        "--out",
        dir.path().join("x.toml").to_str().unwrap(),
    ]);
    assert!(code != 0 && err.contains("expected a Mitsuba 3 scene"), "{err}");
}

/// `-D name=value` overrides a `<default>`; a TOML scene takes no `-D`.
#[test]
fn defines_override_defaults() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("small.exr");
    let (code, err) = lumen(&[
        "render",
        xml("cornell-box.xml").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "-D",
        "res=24",
        "-D",
        "spp=2",
    ]);
    assert_eq!(code, 0, "{err}");
    let img = lumen::image::io::read_exr(&out).unwrap();
    assert_eq!((img.width, img.height), (24, 24));
    let (code, err) = lumen(&[
        "render",
        common::root().join("pipelines/scenes/furnace.toml").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "-D",
        "res=24",
    ]);
    assert!(code != 0 && err.contains("parameters belong to Mitsuba scenes"), "{err}");
    let (code, err) =
        lumen(&["render", xml("cornell-box.xml").to_str().unwrap(), "--out", "x.exr", "-D", "=3"]);
    assert!(code != 0 && err.contains("expected NAME=VALUE"), "{err}");
}

/// A scene around one shape, with the camera of the comparison scenes.
fn scene_with(body: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/><rfilter type="box"/></film>
    </sensor>
{body}
</scene>
"#
    )
}

/// Loads XML text written as DIR/scene.xml (with other files beside it): the error's text and
/// fault kind.
fn refused(files: &[(&str, &str)]) -> (String, lumen::Fault) {
    let dir = tempfile::tempdir().unwrap();
    for (name, text) in files {
        std::fs::write(dir.path().join(name), text).unwrap();
    }
    match render::load(&dir.path().join("scene.xml")) {
        Ok(_) => panic!("accepted: {}", files[0].1),
        Err(e) => (e.to_string(), e.fault()),
    }
}

#[test]
fn malformed_scenes_are_refused_by_element_and_line() {
    use lumen::Fault::{BadInput, Unsupported};
    let sphere = |bsdf: &str| format!("<shape type=\"sphere\">\n{bsdf}\n</shape>");
    let cases: Vec<(Vec<(&str, String)>, &str, lumen::Fault)> = vec![
        (vec![("scene.xml", "<scene version=\"3.0.0\"><shape>".into())], "not well-formed XML", BadInput),
        (vec![("scene.xml", "<scene><sensor/></scene>".into())], "version (none)", Unsupported),
        (vec![("scene.xml", "<scene version=\"0.6.0\"></scene>".into())], "version \"0.6.0\"", Unsupported),
        (vec![("scene.xml", "<scene version=\"3.0.0\"></scene>".into())], "has no <sensor>", BadInput),
        (
            vec![("scene.xml", scene_with("<include filename=\"a.xml\"/>")), ("a.xml", "<scene version=\"3.0.0\"><include filename=\"scene.xml\"/></scene>".into())],
            "includes itself",
            BadInput,
        ),
        (vec![("scene.xml", scene_with("<include filename=\"missing.xml\"/>"))], "cannot find \"missing.xml\"", BadInput),
        (
            vec![("scene.xml", scene_with("<bsdf type=\"twosided\" id=\"a\"><ref id=\"b\"/></bsdf>\n<bsdf type=\"twosided\" id=\"b\"><ref id=\"a\"/></bsdf>\n<shape type=\"sphere\"><ref id=\"a\"/></shape>"))],
            "refs form a cycle",
            BadInput,
        ),
        (vec![("scene.xml", scene_with(&sphere("<ref id=\"nothing\"/>")))], "names id \"nothing\"", BadInput),
        (vec![("scene.xml", scene_with("<shape type=\"sphere\"><float name=\"radius\" value=\"$r\"/></shape>"))], "uses $r", BadInput),
        (vec![("scene.xml", scene_with("<shape type=\"sphere\"><float name=\"radius\" value=\"big\"/></shape>"))], "\"big\" is not a finite number", BadInput),
        (vec![("scene.xml", scene_with(&sphere("<bsdf type=\"roughplastic\"><float name=\"alpha_u\" value=\"0.1\"/><float name=\"alpha_v\" value=\"0.3\"/></bsdf>")))], "lumen's microfacets are isotropic", Unsupported),
        (vec![("scene.xml", scene_with(&sphere("<bsdf type=\"hair\"/>")))], "bsdf \"hair\": lumen reads diffuse", Unsupported),
        (
            vec![("scene.xml", scene_with("<shape type=\"sphere\"><emitter type=\"area\"><spectrum type=\"blackbody\" name=\"radiance\"><float name=\"temperature\" value=\"3000\"/></spectrum></emitter></shape>"))],
            "a blackbody is spectral only",
            Unsupported,
        ),
        (
            vec![("scene.xml", scene_with(&sphere("<bsdf type=\"plastic\"><rgb name=\"specular_reflectance\" value=\"2\"/></bsdf>")))],
            "more would create energy",
            BadInput,
        ),
        (
            vec![("scene.xml", scene_with(&sphere("<bsdf type=\"thindielectric\"><rgb name=\"specular_reflectance\" value=\"0.5\"/><rgb name=\"specular_transmittance\" value=\"0.9\"/></bsdf>")))],
            "tint both alike",
            Unsupported,
        ),
        (
            vec![("scene.xml", scene_with(&sphere("<bsdf type=\"diffuse\"><rgb name=\"reflectance\" value=\"0.5\"/><float name=\"shininess\" value=\"3\"/></bsdf>")))],
            "<float name=\"shininess\"> at",
            Unsupported,
        ),
        (vec![("scene.xml", scene_with("<shape type=\"cylinder\"/>"))], "shape \"cylinder\"", Unsupported),
        (
            vec![("scene.xml", scene_with("<shape type=\"sphere\"><transform name=\"to_world\"><scale value=\"1, 2, 1\"/></transform></shape>"))],
            "lumen's spheres stay round",
            Unsupported,
        ),
        (
            vec![("scene.xml", scene_with("<shape type=\"sphere\"><bsdf type=\"conductor\"><string name=\"material\" value=\"Unobtainium\"/></bsdf></shape>"))],
            "not a named conductor",
            BadInput,
        ),
        (
            vec![("scene.xml", scene_with("<shape type=\"sphere\"><bsdf type=\"dielectric\"><string name=\"int_ior\" value=\"glass-ish\"/></bsdf></shape>"))],
            "not a named index of refraction",
            BadInput,
        ),
        (vec![("scene.xml", scene_with("<shape type=\"sphere\"><ref name=\"interior\" id=\"fog\"/></shape><medium type=\"heterogeneous\" id=\"fog\"/>"))], "needs `sigma_t` as a <volume type=\"gridvolume\">", BadInput),
        (vec![("scene.xml", scene_with("<shape type=\"sphere\"><medium type=\"rayleigh\" name=\"interior\"/></shape>"))], "medium \"rayleigh\"", Unsupported),
        (vec![("scene.xml", scene_with("<shape type=\"sphere\"><medium type=\"homogeneous\" name=\"interior\"><float name=\"sigma_t\" value=\"-1\"/></medium></shape>"))], "must not be negative", BadInput),
        (vec![("scene.xml", scene_with("<shape type=\"sphere\"><medium type=\"homogeneous\" name=\"interior\"><phase type=\"hg\"><float name=\"g\" value=\"1\"/></phase></medium></shape>"))], "expected a number in (−1, 1)", BadInput),
        (vec![("scene.xml", scene_with("<shape type=\"sphere\"><medium type=\"homogeneous\"/></shape>"))], "needs name=\"interior\" or name=\"exterior\"", BadInput),
        (vec![("scene.xml", scene_with("<emitter type=\"area\"/>"))], "belongs inside a <shape>", BadInput),
        (vec![("scene.xml", scene_with("<integrator type=\"aov\"/>"))], "integrator \"aov\"", Unsupported),
        (vec![("scene.xml", scene_with("<shape type=\"sphere\"/><default name=\"x\" value=\"1\"/><shape type=\"cube\"><default name=\"y\" value=\"2\"/></shape>"))], "belongs directly in <scene>", BadInput),
        (
            vec![("scene.xml", scene_with("<shape type=\"sphere\"/><shape type=\"cube\"><transform name=\"to_world\"><rotate angle=\"30\"/></transform></shape>"))],
            "non-zero axis",
            BadInput,
        ),
    ];
    for (files, expected, fault) in cases {
        let named: Vec<(&str, &str)> = files.iter().map(|(n, t)| (*n, t.as_str())).collect();
        let (msg, f) = refused(&named);
        assert!(msg.contains(expected), "expected \"{expected}\" in: {msg}");
        assert_eq!(f, fault, "{msg}");
        if !msg.contains("not well-formed")
            && !msg.contains("includes itself")
            && !msg.contains("has no <sensor>")
        {
            assert!(msg.contains(".xml:"), "the message names no file and line: {msg}");
        }
    }
}

/// Clip planes lumen cannot honour are refused; ones that cut nothing are accepted.
#[test]
fn clip_planes_that_would_cut_are_refused() {
    let body = |near: &str| {
        scene_with("<shape type=\"sphere\"/>").replace(
            "<float name=\"fov\" value=\"40\"/>",
            &format!("<float name=\"fov\" value=\"40\"/><float name=\"near_clip\" value=\"{near}\"/>"),
        )
    };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.xml");
    std::fs::write(&path, body("0.5")).unwrap();
    render::load(&path).expect("a sphere 3 units away is not cut by a near plane at 0.5");
    let (msg, fault) = refused(&[("scene.xml", &body("3.5"))]);
    assert!(msg.contains("near_clip 3.5") && msg.contains("does not clip"), "{msg}");
    assert_eq!(fault, lumen::Fault::Unsupported);
}

/// Refs that multiply (each id naming the one before twice) stop at the element limit
/// instead of exhausting memory.
#[test]
fn ref_expansion_is_bounded() {
    let mut body = String::from("<bsdf type=\"diffuse\" id=\"b0\"/>\n");
    for i in 1..40 {
        body += &format!(
            "<bsdf type=\"twosided\" id=\"b{i}\"><ref id=\"b{0}\"/><ref id=\"b{0}\"/></bsdf>\n",
            i - 1
        );
    }
    body += "<shape type=\"sphere\"><ref id=\"b39\"/></shape>";
    let (msg, _) = refused(&[("scene.xml", &scene_with(&body))]);
    assert!(msg.contains("past") && msg.contains("elements"), "{msg}");
}

/// The CLI names the fault of a refused scene.
#[test]
fn cli_names_the_fault() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.xml");
    std::fs::write(&path, scene_with("<shape type=\"cylinder\"/>")).unwrap();
    let (code, err) =
        lumen(&["render", path.to_str().unwrap(), "--out", dir.path().join("o.exr").to_str().unwrap()]);
    assert!(code != 0 && err.contains("shape \"cylinder\"") && err.contains("scene.xml:7"), "{err}");
    assert_eq!(fault_in(&err), "unsupported", "{err}");
    assert!(!dir.path().join("o.exr").exists());
}

/// A box from a PLY file (binary, quads) renders as Mitsuba's `cube` with the same transform.
#[test]
fn ply_mesh_renders_as_the_cube_it_describes() {
    let dir = tempfile::tempdir().unwrap();
    let corners: Vec<[f32; 3]> = (0..8)
        .map(|i| [(i & 1) as f32 * 2.0 - 1.0, (i >> 1 & 1) as f32 * 2.0 - 1.0, (i >> 2) as f32 * 2.0 - 1.0])
        .collect();
    // Each face's corners counter-clockwise seen from outside.
    let faces = [[0u32, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    let mut ply = b"ply\nformat binary_little_endian 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\nelement face 6\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    for c in &corners {
        c.iter().for_each(|v| ply.extend(v.to_le_bytes()));
    }
    for f in &faces {
        ply.push(4);
        f.iter().for_each(|v| ply.extend((*v as i32).to_le_bytes()));
    }
    std::fs::write(dir.path().join("box.ply"), ply).unwrap();
    let scene = |shape: &str| {
        scene_with(&format!(
            "<shape type=\"{shape}\"><transform name=\"to_world\"><scale value=\"0.5, 0.8, 0.6\"/><rotate y=\"1\" angle=\"30\"/></transform><bsdf type=\"diffuse\"/></shape>\n<emitter type=\"constant\"><rgb name=\"radiance\" value=\"1\"/></emitter>"
        ))
        .replace("<shape type=\"ply\">", "<shape type=\"ply\"><string name=\"filename\" value=\"box.ply\"/>")
    };
    let mut films = Vec::new();
    for shape in ["cube", "ply"] {
        let path = dir.path().join(format!("{shape}.xml"));
        std::fs::write(&path, scene(shape)).unwrap();
        films.push(film(&path));
    }
    let (a, b) = (&films[0].mean, &films[1].mean);
    let differ =
        a.data.iter().zip(&b.data).filter(|(x, y)| (*x - *y).abs() > 1e-4 * x.abs().max(1.0)).count();
    // The same box, split into triangles along other diagonals: equal but for rounding.
    assert!(differ <= a.data.len() / 100, "{differ} of {} values differ", a.data.len());
    let lit = a.data.iter().filter(|v| **v > 0.0 && **v < 0.99).count();
    assert!(lit > 10, "the box is not in view");
}

/// As in Mitsuba, a diffuse surface seen from behind is black unless its BSDF is wrapped in
/// `twosided`: a square facing away from the camera under a uniform sky of 1 (reflectance
/// 0.5) shows 0 one-sided and 0.5 two-sided (ρ·Le, every direction seeing the sky).
#[test]
fn bsdfs_are_one_sided_unless_twosided() {
    let dir = tempfile::tempdir().unwrap();
    let square = |bsdf: &str| {
        scene_with(&format!(
            "<shape type=\"rectangle\"><transform name=\"to_world\"><rotate y=\"1\" angle=\"180\"/></transform>{bsdf}</shape>\n<emitter type=\"constant\"><rgb name=\"radiance\" value=\"1\"/></emitter>"
        ))
    };
    let diffuse = "<bsdf type=\"diffuse\"><rgb name=\"reflectance\" value=\"0.5\"/></bsdf>";
    let mut centre = Vec::new();
    let mut se = Vec::new();
    for (name, bsdf) in
        [("one", diffuse.to_string()), ("two", format!("<bsdf type=\"twosided\">{diffuse}</bsdf>"))]
    {
        let path = dir.path().join(format!("{name}.xml"));
        std::fs::write(&path, square(&bsdf)).unwrap();
        let scene = render::load(&path).unwrap();
        let film = render::render(&scene, &common::settings(&scene, 256, 8));
        let (w, h) = (film.mean.width as usize, film.mean.height as usize);
        let i = 3 * (h / 2 * w + w / 2);
        centre.push(film.mean.data[i]);
        se.push(film.variance.data[i].sqrt());
    }
    assert_eq!(centre[0], 0.0, "the back of a one-sided diffuse square");
    // Within 5 standard errors of the pixel's mean (Mitsuba 3.9 shows 0 and 0.54 at 64 spp).
    assert!(
        (centre[1] - 0.5).abs() < 5.0 * se[1],
        "the back of a two-sided square: {} ± {}",
        centre[1],
        se[1]
    );
}
