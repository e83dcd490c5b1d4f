//! Bad input gets a clear error naming the file, field or value — never a panic, never a
//! half-written output.

mod common;

use common::lumen;

use lumen::render;

const CAMERA: &str = r#"
[camera]
width = 8
height = 8
fov_deg = 40.0
look_at = { origin = [0.0, 0.0, 3.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }
[[materials]]
name = "white"
type = "lambertian"
albedo = [0.5, 0.5, 0.5]
"#;

/// Writes `text` as `dir/p.toml` and runs it: `lumen run … --out dir/out --no-cache`.
fn run_pipeline(dir: &std::path::Path, text: &str) -> (i32, String) {
    let p = dir.join("p.toml");
    std::fs::write(&p, text).unwrap();
    lumen(&["run", p.to_str().unwrap(), "--out", dir.join("out").to_str().unwrap(), "--no-cache"])
}

/// The message of the error a scene with `extra` ends in, which must be the scene's fault.
fn scene_error(extra: &str, files: &[(&str, &str)]) -> String {
    let (fault, message) = scene_fault(extra, files);
    assert_eq!(fault, lumen::Fault::BadInput, "{message}");
    message
}

fn scene_fault(extra: &str, files: &[(&str, &str)]) -> (lumen::Fault, String) {
    let dir = tempfile::tempdir().unwrap();
    for (name, text) in files {
        std::fs::write(dir.path().join(name), text).unwrap();
    }
    match common::scene(&format!("{CAMERA}{extra}"), dir.path()) {
        Ok(_) => panic!("scene was accepted:\n{extra}"),
        Err(e) => (e.fault(), e.to_string()),
    }
}

#[test]
fn missing_scene_file() {
    let e = render::load(std::path::Path::new("/nonexistent/scene.toml")).err().unwrap();
    assert_eq!(e.fault(), lumen::Fault::Io, "{e}");
    assert!(e.to_string().contains("/nonexistent/scene.toml"), "{e}");
}

#[test]
fn missing_mesh_file() {
    let (fault, e) =
        scene_fault("[[shapes]]\ntype = \"mesh\"\nfile = \"nope.obj\"\nmaterial = \"white\"\n", &[]);
    assert_eq!(fault, lumen::Fault::Io, "{e}");
    assert!(e.contains("nope.obj") && e.contains("cannot read"), "{e}");
}

#[test]
fn unknown_key_names_key_and_line() {
    let e = scene_error("[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\nmaterial = \"white\"\ncolour = 3\n", &[]);
    assert!(e.contains("colour") && e.contains("line"), "{e}");
    let e = scene_error("[render]\nsamples = 4\n", &[]);
    assert!(e.contains("samples") && e.contains("line 12"), "{e}");
}

/// An integrator no one has, named in a scene file, on the command line and in a pipeline
/// case: refused with the name given and the names there are.
#[test]
fn unknown_integrator_is_refused_with_the_names_there_are() {
    let e = scene_error("[render]\nintegrator = \"photon-soup\"\n", &[]);
    assert!(e.contains("photon-soup") && e.contains("\"path\"") && e.contains("line 12"), "{e}");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.exr");
    let scene = common::root().join("pipelines/scenes/furnace.toml");
    let (code, err) =
        lumen(&["render", scene.to_str().unwrap(), "--out", out.to_str().unwrap(), "--integrator", "bdpt2"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("bdpt2") && err.contains("path"), "{err}");
    assert!(!out.exists());
    let text = format!(
        "seed = 1\n[[stages]]\nstage = \"render\"\ncase = \"f\"\nscene = \"{}\"\nintegrator = \"nope\"\n",
        scene.display()
    );
    refused_naming(dir.path(), &text, &["nope", "\"path\""]);
}

#[test]
fn nan_in_transform() {
    let e = scene_error(
        "[[shapes]]\ntype = \"mesh\"\nfile = \"t.obj\"\nmaterial = \"white\"\ntransform = { translation = [nan, 0.0, 0.0] }\n",
        &[("t.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")],
    );
    assert!(e.contains("shapes[0].transform.translation") && e.contains("finite"), "{e}");
    let e = scene_error(
        "[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, inf, 0.0]\nradius = 1.0\nmaterial = \"white\"\n",
        &[],
    );
    assert!(e.contains("shapes[0].center"), "{e}");
}

#[test]
fn not_a_rotation() {
    let e = scene_error(
        "[[shapes]]\ntype = \"mesh\"\nfile = \"t.obj\"\nmaterial = \"white\"\ntransform = { rotation = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]] }\n",
        &[("t.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")],
    );
    assert!(e.contains("rotation") && e.contains("not a rotation"), "{e}");
}

#[test]
fn empty_mesh() {
    let e = scene_error(
        "[[shapes]]\ntype = \"mesh\"\nfile = \"e.obj\"\nmaterial = \"white\"\n",
        &[("e.obj", "# nothing\nv 0 0 0\n")],
    );
    assert!(e.contains("e.obj") && e.contains("no faces"), "{e}");
}

#[test]
fn obj_with_bad_index() {
    let e = scene_error(
        "[[shapes]]\ntype = \"mesh\"\nfile = \"b.obj\"\nmaterial = \"white\"\n",
        &[("b.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n")],
    );
    assert!(e.contains("b.obj:4") && e.contains("index 4 is out of range"), "{e}");
    let e = scene_error(
        "[[shapes]]\ntype = \"mesh\"\nfile = \"c.obj\"\nmaterial = \"white\"\n",
        &[("c.obj", "v 0 0 x\n")],
    );
    assert!(e.contains("c.obj:1") && e.contains("'x'"), "{e}");
}

#[test]
fn bad_values() {
    let e =
        scene_error("[[materials]]\nname = \"hot\"\ntype = \"lambertian\"\nalbedo = [1.5, 0.0, 0.0]\n", &[]);
    assert!(e.contains("materials[1] (hot).albedo") && e.contains("[0, 1]"), "{e}");
    let e = scene_error(
        "[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\nradius = -1.0\nmaterial = \"white\"\n",
        &[],
    );
    assert!(e.contains("radius"), "{e}");
    let e = scene_error(
        "[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\nmaterial = \"gold\"\n",
        &[],
    );
    assert!(e.contains("gold"), "{e}");
    let e = scene_error("[[lights]]\ntype = \"point\"\nposition = [0.0, 0.0, 0.0]\n", &[]);
    assert!(e.contains("lights[0]") && e.contains("intensity"), "{e}");
    let spot = "[[lights]]\ntype = \"spot\"\nposition = [0.0, 0.0, 1.0]\ntarget = [0.0, 0.0, 0.0]\nintensity = [1.0, 1.0, 1.0]\n";
    let env = "[[lights]]\ntype = \"environment\"\nradiance = [1.0, 1.0, 1.0]\n";
    let e = scene_error(&format!("{env}{env}"), &[]);
    assert!(e.contains("lights[1]") && e.contains("one environment"), "{e}");
    let (fault, e) = scene_fault("[[lights]]\ntype = \"environment\"\nmap = \"sky.exr\"\n", &[]);
    assert_eq!(fault, lumen::Fault::Io, "{e}");
    assert!(e.contains("sky.exr"), "{e}");
    let e = scene_error("[[lights]]\ntype = \"environment\"\nmap = \"sky.png\"\n", &[("sky.png", "")]);
    assert!(e.contains("lights[0].map") && e.contains("EXR"), "{e}");
    let e =
        scene_error("[[lights]]\ntype = \"environment\"\nmap = \"sky.exr\"\n", &[("sky.exr", "not an exr")]);
    assert!(e.contains("sky.exr"), "{e}");
    let e = scene_error(&format!("{env}map = \"sky.exr\"\n"), &[]);
    assert!(e.contains("lights[0]") && e.contains("`radiance`") && e.contains("`map`"), "{e}");
    let e = scene_error("[[lights]]\ntype = \"environment\"\nmap = \"sky.exr\"\nscale = -2.0\n", &[]);
    assert!(e.contains("lights[0].scale") && e.contains("-2"), "{e}");
    let mirror = "rotation = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]\n";
    let e = scene_error(&format!("[[lights]]\ntype = \"environment\"\nmap = \"sky.exr\"\n{mirror}"), &[]);
    assert!(e.contains("lights[0].rotation") && e.contains("determinant +1"), "{e}");
    let e = scene_error(&format!("{env}{mirror}"), &[]);
    assert!(e.contains("lights[0]") && e.contains("`rotation`"), "{e}");
    let e = scene_error(&format!("{spot}cutoff_deg = 120.0\n"), &[]);
    assert!(e.contains("lights[0].cutoff_deg") && e.contains("120"), "{e}");
    let e = scene_error(&format!("{spot}cutoff_deg = 20.0\nbeam_width_deg = 30.0\n"), &[]);
    assert!(e.contains("lights[0].beam_width_deg") && e.contains("30"), "{e}");
    let e = scene_error("[[shapes]]\ntype = \"donut\"\n", &[]);
    assert!(e.contains("donut"), "{e}");
    let e = scene_error("[[shapes]]\ntype = \"torus\"\n", &[]);
    assert!(e.contains("radius"), "{e}");
    let e =
        scene_error("[[shapes]]\ntype = \"torus\"\nradius = 1.0\ntube = -0.2\nmaterial = \"white\"\n", &[]);
    assert!(e.contains("shapes[0].tube") && e.contains("-0.2"), "{e}");
    let e = scene_error(
        "[[shapes]]\ntype = \"blob\"\nradius = 1.0\namplitude = 1.5\nlobes = 3.0\nmaterial = \"white\"\n",
        &[],
    );
    assert!(e.contains("shapes[0].amplitude") && e.contains("1.5"), "{e}");
    let e = scene_error(
        "[[shapes]]\ntype = \"relief\"\nsize = 1.0\nheight = 0.2\nsegments = 1\nmaterial = \"white\"\n",
        &[],
    );
    assert!(e.contains("shapes[0].segments"), "{e}");
    let (fault, e) = scene_fault(
        "[[materials]]\nname = \"m\"\ntype = \"lambertian\"\nalbedo = { texture = \"missing.png\" }\n",
        &[],
    );
    assert_eq!(fault, lumen::Fault::Io, "{e}");
    assert!(e.contains("missing.png"), "{e}");
    let e = scene_error("[sensor]\nbits = 9\n", &[]);
    assert!(e.contains("sensor") && e.contains("bits"), "{e}");
    let glossy = |rest: &str| format!("[[materials]]\nname = \"g\"\nalbedo = [0.3, 0.3, 0.3]\n{rest}");
    let e = scene_error(&glossy("type = \"lambertian\"\nexponent = 10.0\n"), &[]);
    assert!(e.contains("materials[1] (g)") && e.contains("blinn-phong"), "{e}");
    let e = scene_error(&glossy("type = \"blinn-phong\"\nspecular = [0.2, 0.2, 0.2]\n"), &[]);
    assert!(e.contains("materials[1] (g)") && e.contains("exponent"), "{e}");
    let e =
        scene_error(&glossy("type = \"blinn-phong\"\nspecular = [0.2, 0.2, 0.2]\nexponent = -3.0\n"), &[]);
    assert!(e.contains("materials[1] (g).exponent") && e.contains("-3"), "{e}");
    let e = scene_error(&glossy("type = \"phong\"\n"), &[]);
    assert!(e.contains("'phong'") && e.contains("blinn-phong"), "{e}");
    let e = scene_error(&glossy("type = \"conductor\"\ndistribution = \"phong\"\n"), &[]);
    assert!(e.contains("materials[1] (g).distribution") && e.contains("ggx"), "{e}");
    let e = scene_error(&glossy("type = \"conductor\"\nalpha = 0.0\n"), &[]);
    assert!(e.contains("materials[1] (g).alpha") && e.contains("[0.001, 1]"), "{e}");
    let e = scene_error(&glossy("type = \"conductor\"\nexponent = 10.0\n"), &[]);
    assert!(e.contains("materials[1] (g)") && e.contains("blinn-phong"), "{e}");
    let e = scene_error(&glossy("type = \"conductor\"\neta = [0.2, -1.0, 0.5]\n"), &[]);
    assert!(e.contains("materials[1] (g).eta"), "{e}");
    let e = scene_error(
        &glossy("type = \"conductor\"\nalpha = { checker = { squares = [2, 2], even = 0.0, odd = 0.5 } }\n"),
        &[],
    );
    assert!(e.contains("materials[1] (g).alpha.checker.even") && e.contains("[0.001, 1]"), "{e}");
    let (fault, e) =
        scene_fault(&glossy("type = \"conductor\"\nalpha = { texture = \"missing.png\" }\n"), &[]);
    assert_eq!(fault, lumen::Fault::Io, "{e}");
    assert!(e.contains("missing.png"), "{e}");
    let e = scene_error(&glossy("type = \"mirror\"\neta = [0.2, 0.2, 0.5]\n"), &[]);
    assert!(e.contains("materials[1] (g)") && e.contains("both `eta` and `k`"), "{e}");
    let e = scene_error(&glossy("type = \"mirror\"\nalpha = 0.1\n"), &[]);
    assert!(e.contains("materials[1] (g)") && e.contains("smooth"), "{e}");
    let e = scene_error(&glossy("type = \"dielectric\"\nior = 7.0\n"), &[]);
    assert!(e.contains("materials[1] (g).ior") && e.contains("7") && e.contains("[0.25, 4]"), "{e}");
    let e = scene_error(&glossy("type = \"dielectric\"\nk = [1.0, 1.0, 1.0]\n"), &[]);
    assert!(e.contains("materials[1] (g)") && e.contains("dielectric"), "{e}");
    let e = scene_error(&glossy("type = \"lambertian\"\nior = 1.5\n"), &[]);
    assert!(e.contains("materials[1] (g).ior") && e.contains("dielectric"), "{e}");
    let e = scene_error(&glossy("type = \"plastic\"\nior = 0.1\n"), &[]);
    assert!(e.contains("materials[1] (g).ior") && e.contains("[0.25, 4]"), "{e}");
    let e = scene_error(&glossy("type = \"plastic\"\nspecular = [1.5, 1.0, 1.0]\n"), &[]);
    assert!(e.contains("materials[1] (g).specular") && e.contains("create energy"), "{e}");
    let e = scene_error(&glossy("type = \"plastic\"\nexponent = 10.0\n"), &[]);
    assert!(e.contains("materials[1] (g)") && e.contains("plastic material takes no"), "{e}");
    let e = scene_error(&glossy("type = \"lambertian\"\nnonlinear = true\n"), &[]);
    assert!(e.contains("materials[1] (g).nonlinear") && e.contains("only a plastic"), "{e}");
    let e = scene_error(&glossy("type = \"rough-dielectric\"\nk = [1.0, 1.0, 1.0]\n"), &[]);
    assert!(e.contains("materials[1] (g)") && e.contains("its index is `ior`"), "{e}");
    let e = scene_error(&glossy("type = \"rough-dielectric\"\nalpha = 0.0\n"), &[]);
    assert!(e.contains("materials[1] (g).alpha") && e.contains("[0.001, 1]"), "{e}");
    let e = scene_error(
        &glossy(
            "type = \"rough-plastic\"\nalpha = { checker = { squares = [2, 2], even = 0.1, odd = 0.5 } }\n",
        ),
        &[],
    );
    assert!(e.contains("materials[1] (g).alpha") && e.contains("one roughness"), "{e}");
    let e = scene_error(&glossy("type = \"rough-plastic\"\nior = 1.0\n"), &[]);
    assert!(e.contains("materials[1] (g).ior") && e.contains("no coat"), "{e}");
    let e = scene_error(&glossy("type = \"thin-dielectric\"\ntwo_sided = false\n"), &[]);
    assert!(e.contains("materials[1] (g).two_sided") && e.contains("two sides"), "{e}");
}

#[test]
fn bad_camera() {
    let dir = tempfile::tempdir().unwrap();
    let text = "[camera]\nwidth = 8\nheight = 8\nfx = -1.0\nfy = 1.0\ncx = 0.0\ncy = 0.0\nt_world_cam = { translation = [0.0, 0.0, 0.0] }\n";
    let e = common::scene(text, dir.path()).err().unwrap().to_string();
    assert!(e.contains("fx"), "{e}");
    let text = "[camera]\nwidth = 8\nheight = 8\nfov_deg = 40.0\nlook_at = { origin = [0.0, 0.0, 0.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }\n";
    let e = common::scene(text, dir.path()).err().unwrap().to_string();
    assert!(e.contains("look_at"), "{e}");
    let text = "[camera]\nwidth = 100000\nheight = 100000\nfov_deg = 40.0\nt_world_cam = { translation = [0.0, 0.0, 0.0] }\n";
    let e = common::scene(text, dir.path()).err().unwrap().to_string();
    assert!(e.contains("100000×100000"), "{e}");
    let lens = "[camera]\nwidth = 8\nheight = 8\nfov_deg = 40.0\nt_world_cam = { translation = [0.0, 0.0, 0.0] }\naperture_radius = 0.1\n";
    let e = common::scene(lens, dir.path()).err().unwrap().to_string();
    assert!(e.contains("camera") && e.contains("focus_distance"), "{e}");
    let e = common::scene(&format!("{lens}focus_distance = -2.0\n"), dir.path()).err().unwrap().to_string();
    assert!(e.contains("camera.focus_distance") && e.contains("-2"), "{e}");
    let e = common::scene(&lens.replace("0.1", "-0.1"), dir.path()).err().unwrap().to_string();
    assert!(e.contains("camera.aperture_radius") && e.contains("-0.1"), "{e}");
}

#[test]
fn cli_render_errors_leave_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.exr");
    let (code, err) = lumen(&["render", "/nonexistent/s.toml", "--out", out.to_str().unwrap()]);
    assert_eq!(code, 1, "{err}");
    assert_eq!(common::fault_in(&err), "io", "{err}");
    assert!(err.contains("/nonexistent/s.toml"), "{err}");
    assert!(!out.exists());
    let scene = common::root().join("pipelines/scenes/furnace.toml");
    let (code, err) =
        lumen(&["render", scene.to_str().unwrap(), "--out", dir.path().join("x.txt").to_str().unwrap()]);
    assert_eq!(code, 1);
    assert!(err.contains("x.txt") && err.contains(".exr"), "{err}");
    let (code, err) =
        lumen(&["render", scene.to_str().unwrap(), "--out", out.to_str().unwrap(), "--aov", "velocity"]);
    assert_eq!(code, 1);
    assert!(err.contains("velocity"), "{err}");
    let (code, err) =
        lumen(&["render", scene.to_str().unwrap(), "--out", out.to_str().unwrap(), "--spp", "zero"]);
    assert_eq!(code, 2, "{err}");
    for budget in ["0", "-1", "1e300", "NaN", "inf", "soon"] {
        let flag = format!("--time-budget={budget}");
        let (code, err) = lumen(&["render", scene.to_str().unwrap(), "--out", out.to_str().unwrap(), &flag]);
        assert_eq!(code, 2, "{budget}: {err}");
        assert!(err.contains("--time-budget") && err.contains(budget), "{budget}: {err}");
    }
    // Photon mapping's settings out of their ranges.
    for (flag, value, words) in [
        ("--photons", "0", "photon count 0"),
        ("--photons", "1000000000000000", "photon count"),
        ("--radius", "0", "photon radius 0"),
        ("--radius", "NaN", "photon radius NaN"),
        ("--radius", "1e300", "photon radius inf"),
        ("--alpha", "0", "photon alpha 0"),
        ("--alpha", "1.5", "photon alpha 1.5"),
        ("--k", "0", "photon k 0"),
    ] {
        let (code, err) = lumen(&[
            "render",
            scene.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--integrator",
            "sppm",
            &format!("{flag}={value}"),
        ]);
        assert_eq!(code, 1, "{flag} {value}: {err}");
        assert!(err.contains(words), "{flag} {value}: {err}");
    }
    let e = scene_error("[render.photon]\nalpha = 1.0\n", &[]);
    assert!(e.contains("render.photon") && e.contains("alpha"), "{e}");
    // An integrator that cannot render the scene's media is refused by name.
    let haze = common::root().join("pipelines/scenes/sfm-courtyard-haze.toml");
    let (code, err) =
        lumen(&["render", haze.to_str().unwrap(), "--out", out.to_str().unwrap(), "--integrator", "light"]);
    assert_eq!(code, 1, "{err}");
    assert_eq!(common::fault_in(&err), "unsupported", "{err}");
    assert!(err.contains("\"light\"") && err.contains("participating media"), "{err}");
    assert!(!out.exists());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "something was written");
}

#[test]
fn cli_pipeline_errors() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::root().join("pipelines/scenes/furnace.toml");
    let out = dir.path().join("out");
    let run = |text: &str| run_pipeline(dir.path(), text);
    let head = format!(
        "seed = 1\n[[stages]]\nstage = \"render\"\ncase = \"f\"\nscene = \"{}\"\nspp = 2\n",
        scene.display()
    );
    let (code, err) = run(&format!("{head}spf = 3\n"));
    assert_eq!(code, 1);
    assert_eq!(common::fault_in(&err), "bad-input", "{err}");
    assert!(err.contains("spf") && err.contains("line"), "{err}");
    let (code, err) =
        run(&format!("{head}bounds = {{ max_rel_eror = 0.1 }}\nexpect_uniform = [1.0, 1.0, 1.0]\n"));
    assert_eq!(code, 1);
    assert!(err.contains("max_rel_eror"), "{err}");
    let (code, err) = run("seed = 1\n[[stages]]\nstage = \"teleport\"\ncase = \"x\"\n");
    assert_eq!(code, 1);
    assert_eq!(common::fault_in(&err), "bad-input", "{err}");
    assert!(err.contains("teleport"), "{err}");
    assert!(!out.exists(), "a failed pipeline wrote output");
}

/// Counts of renders beyond their limit (found by `tests/mutations.rs`: `lights = 4294967296`
/// allocated 103 GB and aborted): refused before anything is rendered, naming the field.
#[test]
fn pipeline_counts_beyond_their_limit_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scenes = common::root().join("pipelines/scenes");
    for (stage, scene, field) in
        [("photometric", "ps-sphere", "lights = 4294967296"), ("calibrate", "calib-board", "views = 1001")]
    {
        let text = format!(
            "seed = 1\n[[stages]]\nstage = \"{stage}\"\ncase = \"c\"\nscene = \"{}/{scene}.toml\"\n{field}\n",
            scenes.display()
        );
        refused_naming(dir.path(), &text, &[field, "to 1000"]);
    }
}

/// `text` run as a pipeline is refused (exit 1) with a message holding every one of `words`,
/// and writes nothing.
fn refused_naming(dir: &std::path::Path, text: &str, words: &[&str]) {
    let (code, err) = run_pipeline(dir, text);
    assert_eq!(code, 1, "{err}");
    assert_eq!(common::fault_in(&err), "bad-input", "{err}");
    assert!(words.iter().all(|w| err.contains(w)), "{err}");
    assert!(!dir.join("out").exists(), "a refused pipeline wrote output");
}

/// A Blinn-Phong `start_iterations` outside 1 to 100: refused, naming the field (the stage
/// checks it before it renders the lights).
#[test]
fn pipeline_start_iterations_out_of_range_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::root().join("pipelines/scenes/ps-sphere-glossy.toml");
    for field in ["start_iterations = 0", "start_iterations = 101"] {
        let text = format!(
            "seed = 1\n[[stages]]\nstage = \"photometric\"\ncase = \"c\"\nscene = \"{}\"\nmodel = \"blinn-phong\"\n{field}\n",
            scene.display()
        );
        refused_naming(dir.path(), &text, &[field, "expected 1 to 100"]);
    }
}

/// The Cornell box with its light off: rendered black with a warning by `lumen render`,
/// `lumen bench render` and `lumen run`, never a crash (the eight-lane tracer once gathered
/// from an empty light table).
#[test]
fn a_scene_without_light_renders_black() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(common::root().join("pipelines/scenes/cornell-box.toml")).unwrap();
    let start = text.find("emission = [").unwrap();
    let end = start + text[start..].find(']').unwrap() + 1;
    let dark = format!("{}emission = [0.0, 0.0, 0.0]{}", &text[..start], &text[end..]);
    let scene = common::root().join("pipelines/scenes/dark-box-test.toml");
    // Beside the original, so its relative mesh paths resolve.
    std::fs::write(&scene, dark).unwrap();
    let out = dir.path().join("d.exr");
    let (code, err) =
        lumen(&["render", scene.to_str().unwrap(), "--spp", "2", "--out", out.to_str().unwrap()]);
    let (bench_code, bench_err) =
        lumen(&["bench", "render", "--scene", scene.to_str().unwrap(), "--spp", "1", "--repeat", "1"]);
    let (run_code, run_err) = run_pipeline(
        dir.path(),
        &format!("[[stages]]\nstage = \"render\"\ncase = \"dark\"\nscene = \"{}\"\nspp = 2\nbounds = {{ nonfinite_samples = 0 }}\n", scene.display()),
    );
    let _ = std::fs::remove_file(&scene);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("has no light"), "{err}");
    let img = lumen::image::io::read_exr(&out).unwrap();
    assert!(img.data.iter().all(|&v| v == 0.0));
    assert_eq!(bench_code, 0, "{bench_err}");
    assert_eq!(run_code, 0, "{run_err}");
    let md = std::fs::read_to_string(dir.path().join("out/report.md")).unwrap();
    assert!(md.contains("no light"), "{md}");
}

/// Numbers finite in f64 but beyond what the float32 renderer holds, and generated surfaces
/// too fine for memory: refused when the scene is read, naming the field.
#[test]
fn values_beyond_float32_and_huge_surfaces() {
    let sphere = |c: &str, r: &str| {
        format!("[[shapes]]\ntype = \"sphere\"\ncenter = {c}\nradius = {r}\nmaterial = \"white\"\n")
    };
    let e = scene_error(&sphere("[0.0, 0.0, 0.0]", "1e39"), &[]);
    assert!(e.contains("shapes[0].radius") && e.contains("1e30"), "{e}");
    let e = scene_error(&sphere("[1e39, 0.0, 0.0]", "1.0"), &[]);
    assert!(e.contains("shapes[0].center") && e.contains("1e30"), "{e}");
    let e = scene_error(
        "[[lights]]\ntype = \"point\"\nposition = [0.0, 0.0, 0.0]\nintensity = [1e39, 1.0, 1.0]\n",
        &[],
    );
    assert!(e.contains("lights[0]") && e.contains("1e30"), "{e}");
    let e = scene_error(
        "[[shapes]]\ntype = \"torus\"\nradius = 1.0\ntube = 0.2\nsegments = [4096, 4096]\nmaterial = \"white\"\n",
        &[],
    );
    assert!(e.contains("shapes[0].segments") && e.contains("16777216 quads"), "{e}");
}

/// Textures are held to the range of the constant they stand for: an albedo or roughness
/// texture with a NaN, a negative or a value above 1 is refused naming the file (it used to
/// be clamped in silence), and a Blinn-Phong specular above 1 is refused as an albedo is.
#[test]
fn textures_and_specular_are_held_to_their_constants_range() {
    let dir = tempfile::tempdir().unwrap();
    for (name, bad) in [("nan.exr", f32::NAN), ("negative.exr", -0.1), ("bright.exr", 3.0)] {
        let mut img = lumen::image::Image::new(4, 4, 3);
        img.data.iter_mut().for_each(|v| *v = 0.5);
        img.data[5] = bad;
        lumen::image::io::write_exr(&dir.path().join(name), &img).unwrap();
        for material in [
            format!("type = \"lambertian\"\nalbedo = {{ texture = \"{name}\" }}"),
            format!("type = \"conductor\"\nalbedo = [0.9, 0.9, 0.9]\nalpha = {{ texture = \"{name}\" }}"),
        ] {
            let text = format!("{CAMERA}[[materials]]\nname = \"t\"\n{material}\n");
            let e = match common::scene(&text, dir.path()) {
                Ok(_) => panic!("accepted: {material}"),
                Err(e) => e.to_string(),
            };
            assert!(
                e.contains(name) && e.contains("outside [0, 1]") && e.contains("materials[1] (t)"),
                "{e}"
            );
        }
    }
    let e = scene_error(
        "[[materials]]\nname = \"g\"\nalbedo = [0.3, 0.3, 0.3]\ntype = \"blinn-phong\"\nspecular = [1e30, 0.2, 0.2]\nexponent = 10.0\n",
        &[],
    );
    assert!(e.contains("materials[1] (g).specular") && e.contains("[0, 1]"), "{e}");
}

/// Outputs a command writes together appear together or not at all: an output path late in
/// the set that cannot be written (a folder where a file goes) leaves none of the others
/// behind, for `lumen hdr`, `lumen color spectral` and `lumen sfm`, and the error names it.
#[test]
fn a_late_output_that_is_a_folder_leaves_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let s = |p: &std::path::Path| p.to_str().unwrap().to_string();
    let blocked = |out: &std::path::Path, name: &str| {
        std::fs::create_dir_all(out.join(name)).unwrap();
    };
    let only = |out: &std::path::Path, name: &str| {
        let left: Vec<String> = std::fs::read_dir(out)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n != name)
            .collect();
        assert!(left.is_empty(), "left behind beside {name}: {left:?}");
    };
    // hdr: summary.json is the last file written.
    common::png(&d.join("a.png"), 40, 30, |x, y| [(x * 5 + y) as u8, 80, 90]);
    common::png(&d.join("b.png"), 40, 30, |x, y| [(x * 2 + y) as u8, 30, 40]);
    let hdr_out = d.join("hdr");
    blocked(&hdr_out, "summary.json");
    let (a, b) = (s(&d.join("a.png")), s(&d.join("b.png")));
    let (code, err) = lumen(&[
        "hdr",
        "--images",
        &a,
        &b,
        "--times",
        "1",
        "0.25",
        "--out",
        &s(&hdr_out.join("radiance.exr")),
    ]);
    assert_eq!(code, 1, "{err}");
    assert_eq!(common::fault_in(&err), "io", "{err}");
    assert!(err.contains("summary.json") && err.contains("is a folder"), "{err}");
    only(&hdr_out, "summary.json");
    // color spectral: white.csv is the last.
    let color_out = d.join("color");
    blocked(&color_out, "white.csv");
    let (code, err) = lumen(&["color", "spectral", "--out", &s(&color_out)]);
    assert_eq!(code, 1, "{err}");
    assert_eq!(common::fault_in(&err), "io", "{err}");
    assert!(err.contains("white.csv") && err.contains("is a folder"), "{err}");
    only(&color_out, "white.csv");
    // sfm on two unrelated images (nothing registered, the files still written): summary.json.
    let photos = d.join("photos");
    std::fs::create_dir(&photos).unwrap();
    let noise = |seed: u64| {
        move |x: u32, y: u32| {
            let v = lumen::render::sampler::mix64(seed ^ (x as u64 * 7919 + y as u64 * 104729));
            [(v >> 56) as u8, (v >> 48) as u8, (v >> 40) as u8]
        }
    };
    common::png(&photos.join("a.png"), 160, 120, noise(1));
    common::png(&photos.join("b.png"), 160, 120, noise(2));
    let sfm_out = d.join("sfm");
    blocked(&sfm_out, "summary.json");
    let (code, err) = lumen(&["sfm", "--images", &s(&photos), "--out", &s(&sfm_out)]);
    assert_eq!(code, 1, "{err}");
    assert_eq!(common::fault_in(&err), "io", "{err}");
    assert!(err.contains("summary.json") && err.contains("is a folder"), "{err}");
    only(&sfm_out, "summary.json");
}

/// A film larger than the memory the process may have is refused by name, with what it
/// needs, rather than aborting the process (here under a 4 GB address-space limit).
#[cfg(unix)]
#[test]
fn a_film_beyond_memory_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("big.toml");
    let text = CAMERA.replace("width = 8", "width = 16384").replace("height = 8", "height = 16384");
    std::fs::write(&scene, format!("{text}[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\nmaterial = \"white\"\n")).unwrap();
    let out = dir.path().join("big.exr");
    let o = std::process::Command::new("sh")
        .arg("-c")
        .arg(format!(
            "ulimit -v 4000000 && exec \"{}\" render \"{}\" --out \"{}\" --spp 1",
            env!("CARGO_BIN_EXE_lumen"),
            scene.display(),
            out.display()
        ))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert_eq!(common::fault_in(&err), "bad-input", "{err}");
    assert!(
        err.contains("a 16384×16384 film") && err.contains("6.00 GiB), which could not be allocated"),
        "{err}"
    );
    assert!(!out.exists());
}

/// Media: coefficients negative, NaN or mixed in the wrong pairs, an albedo above 1, an HG g
/// outside (−1, 1), a name no medium has (on a shape or the camera), a medium nothing bounds,
/// a missing grid file, a scene with media left to the surface path tracer, and a null
/// material given a colour. (Lying `.vol` headers: `render::media::grid`'s tests.)
#[test]
fn bad_media() {
    let medium =
        |body: &str| format!("[render]\nintegrator = \"volpath\"\n[[media]]\nname = \"fog\"\n{body}");
    let cases = [
        (medium("sigma_t = [-1.0, 0.0, 0.0]\n"), "media[0] (fog).sigma_t"),
        (medium("sigma_t = [nan, 0.0, 0.0]\n"), "media[0] (fog).sigma_t"),
        (medium("sigma_t = [1.0, 1.0, 1.0]\nalbedo = [1.2, 0.5, 0.5]\n"), "media[0] (fog).albedo"),
        (medium("sigma_t = [1.0, 1.0, 1.0]\nsigma_s = [1.0, 1.0, 1.0]\n"), "`sigma_t`"),
        (medium("sigma_a = [1.0, 1.0, 1.0]\n"), "`sigma_a` and `sigma_s`"),
        (medium("sigma_t = [1.0, 1.0, 1.0]\ng = 1.0\n"), "media[0] (fog).g"),
        (medium("sigma_t = [1.0, 1.0, 1.0]\ng = -1.5\n"), "media[0] (fog).g"),
        (medium("sigma_t = [1.0, 1.0, 1.0]\nscale = -1.0\n"), "media[0] (fog).scale"),
        (medium("sigma_t = [1e30, 1.0, 1.0]\nscale = 1e30\n"), "overflows"),
        (
            format!("{}[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\nmaterial = \"white\"\ninterior = \"smoke\"\n", medium("sigma_t = [1.0, 1.0, 1.0]\n")),
            "shapes[0].interior",
        ),
        (
            "[[media]]\nname = \"fog\"\nsigma_t = [1.0, 1.0, 1.0]\n[[shapes]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\nmaterial = \"white\"\ninterior = \"fog\"\n".to_string(),
            "render.integrator",
        ),
        (medium("sigma_t = [1.0, 1.0, 1.0]\n"), "nothing could enter it"),
        (medium("sigma_t = [1.0, 1.0, 1.0]\ngrid = \"missing.vol\"\n"), "missing.vol"),
        (medium("sigma_t = [1.0, 1.0, 1.0]\ngrid = \"a.vol\"\nnoise = { seed = 1 }\n"), "not both"),
        (medium("sigma_t = [1.0, 1.0, 1.0]\nnoise = { seed = 1, resolution = 100000 }\n"), "media[0] (fog).noise.resolution"),
        (medium("sigma_t = [1.0, 1.0, 1.0]\nnoise = { seed = 1, threshold = 1.0 }\n"), "media[0] (fog).noise.threshold"),
        (medium("sigma_t = [1.0, 1.0, 1.0]\nnoise = { seed = 1, octaves = 0 }\n"), "media[0] (fog).noise.octaves"),
        (medium("sigma_t = [1.0, 1.0, 1.0]\nnoise = { seed = 1 }\ngrid_bbox = true\n"), "media[0] (fog).grid_bbox"),
        (medium("sigma_t = [1.0, 1.0, 1.0]\nnoise = { seed = 1, size = 3 }\n"), "size"),
        (
            "[[materials]]\nname = \"edge\"\ntype = \"null\"\nalbedo = [1.0, 1.0, 1.0]\n".to_string(),
            "materials[1] (edge).albedo",
        ),
        ("[[materials]]\nname = \"grey\"\ntype = \"lambertian\"\n".to_string(), "materials[1] (grey).albedo"),
    ];
    for (text, expected) in cases {
        let (fault, e) = scene_fault(&text, &[]);
        let whose = if expected == "missing.vol" { lumen::Fault::Io } else { lumen::Fault::BadInput };
        assert_eq!(fault, whose, "{e}");
        assert!(e.contains(expected), "expected `{expected}` in: {e}");
    }
    let dir = tempfile::tempdir().unwrap();
    let text = "[camera]\nwidth = 8\nheight = 8\nfov_deg = 40.0\nmedium = \"fog\"\nlook_at = { origin = [0.0, 0.0, 3.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }\n[render]\nintegrator = \"volpath\"\n";
    let e = common::scene(text, dir.path()).err().expect("an unknown camera medium is refused");
    assert!(e.to_string().contains("camera.medium") && e.to_string().contains("'fog'"), "{e}");
}

/// The settings that let cases share one scene, each looking at its own part: a degenerate
/// `look_at`, an `object` no material names, board axes not at right angles, the scene's
/// sensor asked for beside sensor settings or where the scene has none, and a chart lit from
/// behind or by a light that is not distant, refused before anything is rendered, naming the
/// field or the light.
#[test]
fn one_scene_settings_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let scenes = common::root().join("pipelines/scenes");
    let case = |stage: &str, scene: &str, fields: &str| {
        format!("seed = 1\n[[stages]]\nstage = \"{stage}\"\ncase = \"c\"\nscene = \"{scene}\"\n{fields}\n")
    };
    let sphere = scenes.join("ps-sphere.toml").display().to_string();
    refused_naming(
        dir.path(),
        &case(
            "photometric",
            &sphere,
            "look_at = { origin = [0.0, 0.0, 1.0], target = [0.0, 0.0, 1.0], up = [0.0, 1.0, 0.0] }",
        ),
        &["look_at = { origin = [0.0, 0.0, 1.0]", "the target apart from the origin"],
    );
    refused_naming(
        dir.path(),
        &case(
            "photometric",
            &sphere,
            "look_at = { origin = [0.0, 0.0, 3.0], target = [0.0, 0.0, 0.0], up = [0.0, 0.0, 1.0] }",
        ),
        &["`up` not along the line of sight"],
    );
    refused_naming(
        dir.path(),
        &case(
            "photometric",
            &sphere,
            "look_at = { origin = [1e31, 0.0, 3.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }",
        ),
        &["expected finite points within ±1e30"],
    );
    refused_naming(
        dir.path(),
        &case("photometric", &sphere, "object = \"teapot\""),
        &["object = \"teapot\"", "no material of that name"],
    );
    let board = scenes.join("calib-board.toml").display().to_string();
    refused_naming(
        dir.path(),
        &case("calibrate", &board, "board_axes = [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0]]"),
        &["board_axes = [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0]]", "at right angles"],
    );
    refused_naming(
        dir.path(),
        &case("calibrate", &board, "sensor = false\nresponse = { type = \"srgb\" }"),
        &["response = Srgb", "a response applies to code values"],
    );
    refused_naming(
        dir.path(),
        &case("calibrate", &board, "response = { type = \"gamma\", gamma = 0.0 }"),
        &["response: response gamma = 0: expected 0.1 to 10"],
    );
    // Photographs as OpenEXR files are linear already: a response on them is refused.
    let photos = dir.path().join("photos");
    std::fs::create_dir(&photos).unwrap();
    for name in ["a.exr", "b.exr"] {
        lumen::image::io::write(&photos.join(name), &lumen::image::Image::new(8, 8, 1)).unwrap();
    }
    refused_naming(
        dir.path(),
        &format!(
            "seed = 1\n[[stages]]\nstage = \"calibrate\"\ncase = \"c\"\nimages = \"{}\"\nresponse = {{ type = \"srgb\" }}\n",
            photos.display()
        ),
        &["a.exr: an OpenEXR image holds linear values, not codes"],
    );
    let chart_file = scenes.join("color-chart.toml").display().to_string();
    refused_naming(
        dir.path(),
        &case("hdr", &chart_file, "scene_sensor = true\nbits = 12\nread_noise = 2.0"),
        &["scene_sensor = true and bits, read_noise: the scene's sensor sets them"],
    );
    let box_file = scenes.join("cornell-box.toml").display().to_string();
    refused_naming(
        dir.path(),
        &case("hdr", &box_file, "scene_sensor = true"),
        &["cornell-box.toml has no [sensor]"],
    );
    let chart = std::fs::read_to_string(scenes.join("color-chart.toml")).unwrap();
    for (light, words) in [
        (
            "[[lights]]\ntype = \"directional\"\nto_light = [0.0, 0.0, 1.0]\nirradiance = [1.0, 1.0, 1.0]\n",
            &["light 2 does not reach the chart's face the camera sees"][..],
        ),
        (
            "[[lights]]\ntype = \"point\"\nposition = [0.0, 0.0, -1.0]\nintensity = [1.0, 1.0, 1.0]\n",
            &["directional lights only"][..],
        ),
    ] {
        let file = dir.path().join("chart.toml");
        std::fs::write(&file, format!("{chart}\n{light}")).unwrap();
        refused_naming(dir.path(), &case("color", &file.display().to_string(), ""), words);
    }
}
