//! Mitsuba 3 scenes (`.xml`, version 2.x/3.x) read as they are, into the same `SceneFile` a
//! lumen TOML scene parses to, so both are checked and built by one `build` and
//! `lumen scene convert` can show what was read.
//!
//! How each part maps (Mitsuba 3's plugin reference names the parameters):
//! - `integrator`: `path`, `volpath` and `volpathmis` (lumen's volpath with media, its path
//!   tracer, the same image faster, without), `ptracer` (lumen's `light`; `samples_per_pass`
//!   accepted, it only splits the work) and `direct` (= `path` with `max_depth` 2), with `max_depth` (−1: unbounded) and
//!   `rr_depth`; `moment` renders its inner integrator (lumen writes the variance beside the
//!   mean anyway). lumen's roulette starts after 5 segments, Mitsuba's default `rr_depth`:
//!   another `rr_depth` changes the noise, not the expected image, and is accepted.
//! - `sensor`: `perspective` and `thinlens` (`fov` with `fov_axis` x, y, diagonal, smaller,
//!   larger; `to_world` rigid up to a uniform scale; `near_clip` / `far_clip` accepted when they
//!   cut no geometry, as lumen does not clip), Mitsuba's camera frame (x left, y up, z
//!   forward) turned into OpenCV's (x right, y down); its pixel i spans [i, i + 1), so the
//!   principal point is ((W − 1)/2, (H − 1)/2) in lumen's integer-centred pixels. `hdrfilm`
//!   (width, height, `box` or `gaussian` rfilter, gaussian by default as in Mitsuba); `sampler`: `independent` → independent, `stratified`,
//!   `multijitter`, `orthogonal`, `ldsampler` → lumen's Sobol sampler; `sample_count` → spp.
//! - `bsdf`: `diffuse` → lambertian; `conductor` → mirror, `roughconductor` → conductor (named
//!   `material`s in `named`, or `eta`/`k`; `specular_reflectance` tints); `dielectric`,
//!   `roughdielectric` and `thindielectric` (named or numeric `int_ior`/`ext_ior`); `plastic`
//!   and `roughplastic` (`diffuse_reflectance`, `specular_reflectance`, `nonlinear`; default
//!   coat polypropylene); `twosided` around one
//!   BSDF. As in Mitsuba, a diffuse, conductor or plastic material is one-sided
//!   (`two_sided = false`: black from behind) unless wrapped in `twosided`. Colours as `rgb`, `float`, `spectrum` (a constant or wavelength:value
//!   pairs, turned into RGB as Mitsuba's RGB variants do: `spectrum`), or a `checkerboard` /
//!   `bitmap` texture.
//! - `shape`: `obj`, `ply`, `sphere`, `rectangle`, `cube`, `disk` (a fan of 1024 triangles,
//!   `ShapeSpec::Disk`), with `to_world`, `flip_normals`, a `bsdf`,
//!   an `area` emitter (the shape's material then emits) and `interior` / `exterior` media (a
//!   shape without a BSDF is diffuse even where it bounds a medium, as Mitsuba 3.9 renders it).
//!   `emitter`: `point`, `spot`, `directional`, `constant`, `envmap` (turned by its
//!   `to_world`, a rotation up to a uniform scale).
//! - `medium`: `homogeneous` and `heterogeneous` (a `gridvolume` σt), in shapes and
//!   the sensor; the `null` BSDF for a medium's invisible boundary.
//!
//! Anything else, and any parameter a plugin does not read, is refused by name and line with
//! what lumen supports instead: nothing is dropped silently.

mod bsdf;
mod medium;
mod named;
mod props;
mod spectrum;
mod xml;

use super::super::filter::{PixelFilter, GAUSSIAN_STDDEV};
use super::super::texture::TextureSpec;
use super::super::Error;
use super::file::*;
use bsdf::{bsdf, copy_material, lambertian};
use glam::{DAffine3, DMat3, DVec3};
use props::{rows, Props};
use std::path::{Path, PathBuf};
use xml::Elem;

/// Whether a scene file is Mitsuba's (by its extension, `.xml`).
pub fn is_mitsuba(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("xml"))
}

/// What a Mitsuba scene file holds, as a lumen scene, and the clip planes its sensor asked
/// for (checked against the built scene: lumen does not clip).
pub struct Read {
    pub scene: SceneFile,
    pub clip: (f64, f64),
}

/// Reads a Mitsuba 3 scene; `params` are `$name` values given by the caller.
pub fn read(path: &Path, params: &[(String, String)]) -> Result<Read, Error> {
    let (root, search) = xml::load(path, params)?;
    let mut c = Converter {
        main_dir: path.parent().map(Path::to_path_buf).unwrap_or_default(),
        search,
        materials: Vec::new(),
        bsdf_ids: Default::default(),
        shapes: Vec::new(),
        lights: Vec::new(),
        media: Vec::new(),
        medium_ids: Default::default(),
    };
    let mut camera = None;
    let mut render = RenderSpec::default();
    let mut integrator = None;
    for e in &root.children {
        match e.tag.as_str() {
            "sensor" => {
                if camera.is_some() {
                    return Err(e.unsupported("a second sensor: lumen renders one camera per scene"));
                }
                camera = Some((c.sensor(e, &mut render)?, e));
            }
            "integrator" => integrator = Some(e),
            "shape" => c.shape(e)?,
            "emitter" => c.emitter(e)?,
            // Declared for reference by id; converted where used.
            "bsdf" | "texture" | "spectrum" | "rgb" | "volume" | "phase" => {}
            // Declared for reference by id; converted where used.
            "medium" => {}
            _ => {
                return Err(e.unsupported(format!(
                    "<{}> in <scene>: lumen reads sensor, integrator, shape, emitter, bsdf, texture and medium here",
                    e.tag
                )))
            }
        }
    }
    if let Some(e) = integrator {
        c.integrator(e, &mut render)?;
    } else {
        // Mitsuba's default integrator: path, max_depth −1.
        render.max_depth = u32::MAX;
    }
    let Some(((camera, clip), _)) = camera else {
        return Err(root.error("has no <sensor>: lumen needs a camera to render"));
    };
    Ok(Read {
        scene: SceneFile {
            camera,
            render,
            sensor: None,
            materials: c.materials,
            shapes: c.shapes,
            lights: c.lights,
            media: c.media,
        },
        clip,
    })
}

struct Converter {
    main_dir: PathBuf,
    search: Vec<PathBuf>,
    materials: Vec<MaterialSpec>,
    /// The material each BSDF id became.
    bsdf_ids: std::collections::HashMap<String, String>,
    shapes: Vec<ShapeSpec>,
    lights: Vec<LightSpec>,
    media: Vec<MediumSpec>,
    /// The medium each medium id became.
    medium_ids: std::collections::HashMap<String, String>,
}

impl Converter {
    /// A file a plugin names: beside the element's file, beside the scene, or in a `<path>`;
    /// relative to the scene's folder where it lies below it.
    fn file(&self, e: &Elem, name: &str) -> Result<String, Error> {
        let found = [e.dir(), self.main_dir.clone()]
            .into_iter()
            .chain(self.search.iter().cloned())
            .map(|d| d.join(name))
            .find(|p| p.is_file())
            .ok_or_else(|| e.error(format!("cannot find \"{name}\" beside the scene or in a <path>")))?;
        let shown = found.strip_prefix(&self.main_dir).unwrap_or(&found);
        Ok(shown.to_string_lossy().into_owned())
    }

    fn integrator(&mut self, e: &Elem, render: &mut RenderSpec) -> Result<(), Error> {
        let p = Props::new(e);
        match e.plugin() {
            "moment" => {
                let inner = p.objects("integrator");
                p.finish("one nested integrator")?;
                return match inner.as_slice() {
                    [i] => self.integrator(i, render),
                    _ => Err(e.error("needs exactly one nested <integrator>")),
                };
            }
            "path" | "volpath" | "volpathmis" | "ptracer" => {
                // Without media the volume path tracers' image is the path tracer's, which
                // lumen renders faster; with media, lumen's volpath.
                let name = match e.plugin() {
                    "ptracer" => Some("light"),
                    "volpath" | "volpathmis" if !self.media.is_empty() => Some("volpath"),
                    _ => None,
                };
                if let Some(name) = name {
                    render.integrator =
                        crate::render::integrators::find(name).map_err(|err| e.unsupported(err.to_string()))?;
                }
                // How the particle tracer splits its work, not what it computes.
                if e.plugin() == "ptracer" {
                    p.int("samples_per_pass")?;
                }
                let depth = p.int("max_depth")?.unwrap_or(-1);
                render.max_depth = match depth {
                    -1 => u32::MAX,
                    d if d >= 1 && d <= u32::MAX as i64 => d as u32,
                    d => return Err(e.error(format!("max_depth {d}: expected −1 (unbounded) or at least 1"))),
                };
                if let Some(rr) = p.int("rr_depth")? {
                    if rr < 1 {
                        return Err(e.error(format!("rr_depth {rr}: expected at least 1")));
                    }
                }
            }
            "direct" => {
                p.accept(&["emitter_samples", "bsdf_samples", "shading_samples"]);
                render.max_depth = 2;
            }
            other => {
                return Err(e.unsupported(format!(
                    "integrator \"{other}\": lumen has {} (Mitsuba's path, direct and moment map to path, volpath and volpathmis to volpath, ptracer to light)",
                    crate::render::integrators::names()
                )))
            }
        }
        if p.boolean("hide_emitters")? == Some(true) {
            return Err(e.unsupported("hide_emitters = true: lumen shows emitters seen directly"));
        }
        p.finish("max_depth, rr_depth, hide_emitters, samples_per_pass")
    }

    /// The camera, and its clip planes.
    fn sensor(&mut self, e: &Elem, render: &mut RenderSpec) -> Result<(CameraSpec, (f64, f64)), Error> {
        let p = Props::new(e);
        let thin = match e.plugin() {
            "perspective" => false,
            "thinlens" => true,
            other => {
                return Err(e.unsupported(format!("sensor \"{other}\": lumen reads perspective and thinlens")))
            }
        };
        let films = p.objects("film");
        let (width, height, filter) = match films.as_slice() {
            [] => (768, 576, PixelFilter::Gaussian),
            [f] => film(f)?,
            _ => return Err(e.error("has more than one <film>")),
        };
        render.filter = filter;
        for s in p.objects("sampler") {
            sampler(s, render)?;
        }
        if p.find("focal_length").is_some() {
            return Err(e.unsupported("focal_length: give `fov` (degrees) and `fov_axis`"));
        }
        let fov = p.float("fov")?.ok_or_else(|| e.error("needs `fov` (degrees)"))?;
        if !(fov > 0.0 && fov < 180.0) {
            return Err(e.error(format!("fov {fov}: expected degrees in (0, 180)")));
        }
        let (w, h) = (width as f64, height as f64);
        let span = match p.string("fov_axis")?.as_deref().unwrap_or("x") {
            "x" => w,
            "y" => h,
            "diagonal" => w.hypot(h),
            "smaller" => w.min(h),
            "larger" => w.max(h),
            o => return Err(e.error(format!("fov_axis \"{o}\": expected x, y, diagonal, smaller or larger"))),
        };
        let f = 0.5 * span / (0.5 * fov.to_radians()).tan();
        for k in ["principal_point_offset_x", "principal_point_offset_y"] {
            if p.float(k)?.is_some_and(|v| v != 0.0) {
                return Err(
                    e.unsupported(format!("{k}: lumen's Mitsuba reader takes a centred principal point"))
                );
            }
        }
        let near = p.float("near_clip")?.unwrap_or(1e-2);
        let far = p.float("far_clip")?.unwrap_or(1e4);
        if !(near > 0.0 && far > near) {
            return Err(e.error(format!("near_clip {near}, far_clip {far}: expected 0 < near < far")));
        }
        let m = p.transform("to_world")?.unwrap_or(DAffine3::IDENTITY);
        let l = m.matrix3;
        let s = l.x_axis.length();
        let (ux, uy, uz) = (l.x_axis / s, l.y_axis / s, l.z_axis / s);
        let tol = 1e-6;
        if (l.y_axis.length() - s).abs() > tol * s
            || (l.z_axis.length() - s).abs() > tol * s
            || ux.dot(uy).abs() > tol
            || ux.dot(uz).abs() > tol
            || uy.dot(uz).abs() > tol
        {
            return Err(
                e.unsupported("a sensor to_world with shear or unequal scales: lumen's cameras are rigid")
            );
        }
        if l.determinant() < 0.0 {
            return Err(e.unsupported(
                "a mirroring sensor to_world (negative determinant): lumen's cameras do not mirror the image",
            ));
        }
        // Mitsuba's camera looks along +z with x left and y up; OpenCV's x is right, y down.
        let r = DMat3::from_cols(-ux, -uy, uz);
        let (aperture_radius, focus_distance) = if thin {
            let a =
                p.float("aperture_radius")?.ok_or_else(|| e.error("a thinlens needs `aperture_radius`"))?;
            let d = p.float("focus_distance")?.ok_or_else(|| e.error("a thinlens needs `focus_distance`"))?;
            (Some(a), Some(d))
        } else {
            // A pinhole has no plane of focus; Mitsuba's perspective ignores it.
            p.accept(&["focus_distance"]);
            (None, None)
        };
        let medium = match p.objects("medium").as_slice() {
            [] => None,
            [m] => Some(self.medium(m, "camera")?),
            _ => return Err(e.error("has more than one <medium>")),
        };
        p.accept(&["shutter_open", "shutter_close", "srf"]);
        p.finish(
            "fov, fov_axis, near_clip, far_clip, to_world, film, sampler, medium, aperture_radius, focus_distance",
        )?;
        let rows = r.transpose().to_cols_array_2d();
        Ok((
            CameraSpec {
                width,
                height,
                fov_deg: None,
                fx: Some(f),
                fy: Some(f),
                cx: Some(0.5 * (w - 1.0)),
                cy: Some(0.5 * (h - 1.0)),
                distortion: None,
                look_at: None,
                t_world_cam: Some(TransformSpec {
                    matrix: None,
                    rotation: Some(rows),
                    rvec: None,
                    translation: m.translation.to_array(),
                    scale: None,
                }),
                aperture_radius,
                focus_distance,
                medium,
            },
            (near, far),
        ))
    }

    fn shape(&mut self, e: &Elem) -> Result<(), Error> {
        let p = Props::new(e);
        let index = self.shapes.len();
        let name = e.attr("id").map_or_else(|| format!("shape{index}"), str::to_string);
        let bsdfs = p.objects("bsdf");
        let emitters = p.objects("emitter");
        let mut side = |which: &str| -> Result<Option<String>, Error> {
            match p.find(which) {
                Some(m) if m.tag == "medium" => self.medium(m, &format!("{name}-{which}")).map(Some),
                Some(m) => Err(m.error(format!("`{which}` must be a <medium>"))),
                None => Ok(None),
            }
        };
        let (interior, exterior) = (side("interior")?, side("exterior")?);
        if let Some(m) =
            p.objects("medium").iter().find(|m| !matches!(m.attr("name"), Some("interior" | "exterior")))
        {
            return Err(m.error("a shape's <medium> needs name=\"interior\" or name=\"exterior\""));
        }
        // A shape without a BSDF is diffuse, also where it bounds a medium (as Mitsuba 3.9
        // renders it): a medium's invisible boundary takes <bsdf type="null"/>.
        let mut material = match bsdfs.as_slice() {
            [] => None,
            [b] => Some(self.material(b, &name)?),
            _ => return Err(e.error("has more than one <bsdf>")),
        };
        let emission = match emitters.as_slice() {
            [] => None,
            [em] => {
                let q = Props::new(em);
                if em.plugin() != "area" {
                    return Err(em.unsupported("only an `area` emitter belongs in a shape"));
                }
                let le =
                    q.color("radiance")?.ok_or_else(|| em.error("needs `radiance`"))?.rgb(em, "radiance")?;
                q.finish("radiance")?;
                Some(le)
            }
            _ => return Err(e.error("has more than one <emitter>")),
        };
        let default_name = "mitsuba-default-diffuse";
        if material.is_none() && !self.materials.iter().any(|m| m.name == default_name) {
            // A shape without a BSDF is Mitsuba's default diffuse, reflectance 0.5.
            self.materials.push(lambertian(default_name, TextureSpec::Constant([0.5; 3])));
        }
        if let Some(le) = emission {
            // The material is shared by name: an emitting shape gets its own copy.
            let base = material.clone().unwrap_or_else(|| default_name.to_string());
            let i = self.materials.iter().position(|m| m.name == base).expect("material just added");
            let copy = copy_material(&self.materials[i], self.unused_name(&format!("{name}-emitter")), le);
            material = Some(copy.name.clone());
            self.materials.push(copy);
        }
        let material = material.unwrap_or_else(|| default_name.to_string());
        let flip = p.boolean("flip_normals")?.unwrap_or(false);
        let m = p.transform("to_world")?.unwrap_or(DAffine3::IDENTITY);
        let mirrored = m.matrix3.determinant() < 0.0;
        if m.matrix3.determinant() == 0.0 {
            return Err(e.error("to_world is singular: it flattens the shape"));
        }
        let shape = match e.plugin() {
            "obj" | "ply" => {
                let f = p.string("filename")?.ok_or_else(|| e.error("needs `filename`"))?;
                let file = self.file(e, &f)?;
                let face_normals = p.boolean("face_normals")?.unwrap_or(false);
                let full = self.main_dir.join(&file);
                let normals = if e.plugin() == "obj" {
                    has_vertex_normals(&full)
                } else {
                    super::super::ply::has_normals(&full)
                };
                if !face_normals && normals {
                    return Err(e.unsupported(format!(
                        "\"{f}\" has vertex normals, which Mitsuba interpolates: lumen shades with face normals; add <boolean name=\"face_normals\" value=\"true\"/>"
                    )));
                }
                p.accept(&["flip_tex_coords"]);
                ShapeSpec::Mesh {
                    file,
                    material: Some(material),
                    object_materials: Default::default(),
                    transform: TransformSpec { matrix: Some(rows(&m)), ..Default::default() },
                    reverse_orientation: flip,
                    interior: interior.clone(),
                    exterior: exterior.clone(),
                }
            }
            "sphere" => {
                let c = p.point("center")?.unwrap_or(DVec3::ZERO);
                let r = p.float("radius")?.unwrap_or(1.0);
                let l = m.matrix3;
                let s = l.x_axis.length();
                let similar = (l.transpose() * l - DMat3::from_diagonal(DVec3::splat(s * s)))
                    .to_cols_array()
                    .iter()
                    .all(|v| v.abs() <= 1e-6 * s * s);
                if !similar {
                    return Err(e.unsupported("a sphere to_world with shear or unequal scales: lumen's spheres stay round (use an obj mesh)"));
                }
                ShapeSpec::Sphere {
                    center: m.transform_point3(c).to_array(),
                    radius: r * s,
                    material,
                    // Mitsuba's sphere faces out, mirrored or not.
                    reverse_orientation: flip,
                    interior: interior.clone(),
                    exterior: exterior.clone(),
                }
            }
            "rectangle" => {
                let corner = m.transform_point3(DVec3::new(-1.0, -1.0, 0.0));
                ShapeSpec::Quad {
                    corner: corner.to_array(),
                    edge_u: m.transform_vector3(DVec3::new(2.0, 0.0, 0.0)).to_array(),
                    edge_v: m.transform_vector3(DVec3::new(0.0, 2.0, 0.0)).to_array(),
                    material,
                    // Mitsuba's rectangle faces its normal transformed as a normal; edge_u ×
                    // edge_v points the other way under a mirroring transform.
                    reverse_orientation: flip ^ mirrored,
                    interior: interior.clone(),
                    exterior: exterior.clone(),
                }
            }
            "cube" => ShapeSpec::Cube {
                material,
                transform: TransformSpec { matrix: Some(rows(&m)), ..Default::default() },
                reverse_orientation: flip,
                interior: interior.clone(),
                exterior: exterior.clone(),
            },
            "disk" => ShapeSpec::Disk {
                material,
                transform: TransformSpec { matrix: Some(rows(&m)), ..Default::default() },
                reverse_orientation: flip,
                interior: interior.clone(),
                exterior: exterior.clone(),
            },
            other => {
                return Err(e.unsupported(format!(
                    "shape \"{other}\": lumen reads obj, ply, sphere, rectangle, cube and disk"
                )))
            }
        };
        p.finish("filename, face_normals, flip_tex_coords (obj, ply); center, radius (sphere); to_world, flip_normals, bsdf, emitter, interior, exterior")?;
        self.shapes.push(shape);
        Ok(())
    }

    /// The name of the material a `bsdf` element converts to, added once per id.
    fn material(&mut self, b: &Elem, shape: &str) -> Result<String, Error> {
        if let Some(name) = b.attr("id").and_then(|id| self.bsdf_ids.get(id)) {
            return Ok(name.clone());
        }
        // Named by its id, or after its shape when written inside it; apart from every
        // material made before.
        let name = self.unused_name(b.attr("id").unwrap_or(shape));
        let spec = bsdf(b, name.clone())?;
        self.materials.push(spec);
        if let Some(id) = b.attr("id") {
            self.bsdf_ids.insert(id.to_string(), name.clone());
        }
        Ok(name)
    }

    /// The name of the medium a `medium` element converts to, added once per id; `owner`
    /// names it when it has no id.
    fn medium(&mut self, m: &Elem, owner: &str) -> Result<String, Error> {
        if let Some(name) = m.attr("id").and_then(|id| self.medium_ids.get(id)) {
            return Ok(name.clone());
        }
        let base = m.attr("id").unwrap_or(owner);
        let taken = |n: &str| self.media.iter().any(|x| x.name == n);
        let name = std::iter::once(base.to_string())
            .chain((2..).map(|k| format!("{base}-{k}")))
            .find(|n| !taken(n))
            .unwrap_or_default();
        let spec = medium::medium(m, name.clone(), &|e: &Elem, f: &str| self.file(e, f))?;
        self.media.push(spec);
        if let Some(id) = m.attr("id") {
            self.medium_ids.insert(id.to_string(), name.clone());
        }
        Ok(name)
    }

    /// `base`, or `base-2`, `base-3` … whichever no material has yet.
    fn unused_name(&self, base: &str) -> String {
        let taken = |n: &str| self.materials.iter().any(|m| m.name == n);
        if !taken(base) {
            return base.to_string();
        }
        (2..).map(|k| format!("{base}-{k}")).find(|n| !taken(n)).unwrap_or_default()
    }

    fn emitter(&mut self, e: &Elem) -> Result<(), Error> {
        let p = Props::new(e);
        let rgb = |k: &str| -> Result<[f64; 3], Error> {
            p.color(k)?.ok_or_else(|| e.error(format!("needs `{k}`")))?.rgb(e, k)
        };
        let m = p.transform("to_world")?;
        let light = match e.plugin() {
            "point" => {
                let at = match (p.point("position")?, m) {
                    (Some(_), Some(_)) => return Err(e.error("give `position` or `to_world`, not both")),
                    (Some(x), None) => x,
                    (None, m) => m.unwrap_or(DAffine3::IDENTITY).translation,
                };
                LightSpec::Point { position: at.to_array(), intensity: Some(rgb("intensity")?), power: None }
            }
            "spot" => {
                let m = m.unwrap_or(DAffine3::IDENTITY);
                let at = m.translation;
                let axis = m.transform_vector3(DVec3::Z).normalize();
                let cutoff = p.float("cutoff_angle")?.unwrap_or(20.0);
                let beam = p.float("beam_width")?.unwrap_or(0.75 * cutoff);
                LightSpec::Spot {
                    position: at.to_array(),
                    target: (at + axis).to_array(),
                    intensity: rgb("intensity")?,
                    cutoff_deg: Some(cutoff),
                    beam_width_deg: Some(beam),
                }
            }
            "directional" => {
                let d = match (p.point("direction")?, m) {
                    (Some(_), Some(_)) => return Err(e.error("give `direction` or `to_world`, not both")),
                    (Some(d), None) => d,
                    (None, m) => m.unwrap_or(DAffine3::IDENTITY).transform_vector3(DVec3::Z),
                };
                if d.length() == 0.0 {
                    return Err(e.error("needs a non-zero `direction`"));
                }
                LightSpec::Directional {
                    to_light: (-d.normalize()).to_array(),
                    irradiance: rgb("irradiance")?,
                }
            }
            // A uniform environment looks the same under any to_world.
            "constant" => LightSpec::Environment {
                radiance: Some(rgb("radiance")?),
                map: None,
                scale: None,
                rotation: None,
            },
            "envmap" => {
                // A rotation, up to a uniform scale (directions are normalised); anything else
                // would bend the map.
                let rotation = match m {
                    Some(m) if !m.matrix3.abs_diff_eq(DMat3::IDENTITY, 1e-9) => {
                        let s = m.matrix3.determinant().cbrt();
                        let r = m.matrix3 * (1.0 / s);
                        if !(s > 0.0 && (r.transpose() * r).abs_diff_eq(DMat3::IDENTITY, 1e-6)) {
                            return Err(e.unsupported(
                                "an envmap to_world that is not a rotation (mirrored, sheared or scaled unevenly): lumen turns environment maps, nothing more",
                            ));
                        }
                        Some(r.transpose().to_cols_array_2d())
                    }
                    _ => None,
                };
                let f = p.string("filename")?.ok_or_else(|| e.error("needs `filename`"))?;
                LightSpec::Environment {
                    radiance: None,
                    map: Some(self.file(e, &f)?),
                    scale: p.float("scale")?,
                    rotation,
                }
            }
            "area" => return Err(e.error("an `area` emitter belongs inside a <shape>")),
            other => {
                return Err(e.unsupported(format!(
                    "emitter \"{other}\": lumen reads area, point, spot, directional, constant and envmap"
                )))
            }
        };
        p.finish("intensity, position (point); intensity, cutoff_angle, beam_width (spot); irradiance, direction (directional); radiance (constant); filename, scale (envmap); to_world")?;
        self.lights.push(light);
        Ok(())
    }
}

fn film(f: &Elem) -> Result<(u32, u32, PixelFilter), Error> {
    let p = Props::new(f);
    if f.plugin() != "hdrfilm" {
        return Err(f.unsupported(format!("film \"{}\": lumen reads hdrfilm", f.plugin())));
    }
    let size = |k: &str, d: i64| -> Result<u32, Error> {
        let v = p.int(k)?.unwrap_or(d);
        if !(1..=1 << 16).contains(&v) {
            return Err(f.error(format!("{k} {v}: expected 1 to 65536 pixels")));
        }
        Ok(v as u32)
    };
    let (w, h) = (size("width", 768)?, size("height", 576)?);
    // Mitsuba's default reconstruction filter is its gaussian.
    let mut filter = PixelFilter::Gaussian;
    for r in p.objects("rfilter") {
        let q = Props::new(r);
        filter = match r.plugin() {
            "box" => PixelFilter::Box,
            "gaussian" => {
                if let Some(s) = q.float("stddev")?.filter(|&s| s != GAUSSIAN_STDDEV) {
                    return Err(r.unsupported(format!(
                        "stddev {s}: lumen's gaussian filter has Mitsuba's default, 0.5"
                    )));
                }
                PixelFilter::Gaussian
            }
            other => return Err(r.unsupported(format!("rfilter \"{other}\": lumen has box and gaussian"))),
        };
        q.finish("stddev (gaussian)")?;
    }
    for k in ["crop_offset_x", "crop_offset_y", "crop_width", "crop_height"] {
        if p.find(k).is_some() {
            return Err(
                f.unsupported(format!("{k}: lumen renders the whole film (lumen render --crop crops)"))
            );
        }
    }
    if p.boolean("sample_border")? == Some(true) {
        return Err(f.unsupported("sample_border = true: lumen's pixels take only their own samples"));
    }
    // How the image is stored, not what it holds: lumen writes linear RGB float EXR.
    p.accept(&["file_format", "pixel_format", "component_format", "compensate", "banner"]);
    p.finish("width, height, rfilter, file_format, pixel_format, component_format")?;
    Ok((w, h, filter))
}

fn sampler(s: &Elem, render: &mut RenderSpec) -> Result<(), Error> {
    let p = Props::new(s);
    render.sampler = match s.plugin() {
        "independent" => super::super::sampler::SamplerKind::Independent,
        "stratified" | "multijitter" | "orthogonal" | "ldsampler" => {
            super::super::sampler::SamplerKind::Sobol
        }
        other => {
            return Err(s.unsupported(format!(
            "sampler \"{other}\": lumen reads independent, stratified, multijitter, orthogonal and ldsampler"
        )))
        }
    };
    if let Some(n) = p.int("sample_count")? {
        if !(1..=u32::MAX as i64).contains(&n) {
            return Err(s.error(format!("sample_count {n}: expected at least 1")));
        }
        render.spp = n as u32;
    } else {
        render.spp = 4;
    }
    if let Some(seed) = p.int("seed")? {
        render.seed = u64::try_from(seed)
            .map_err(|_| s.error(format!("seed {seed}: expected a non-negative integer")))?;
    }
    // The strata's jitter and the shuffling are how the points are made, not what they estimate.
    p.accept(&["jitter", "strength"]);
    p.finish("sample_count, seed")
}

/// Whether an OBJ file has `vn` lines (an unreadable file is left to the mesh reader to report).
fn has_vertex_normals(path: &Path) -> bool {
    std::fs::read_to_string(path).is_ok_and(|t| t.lines().any(|l| l.trim_start().starts_with("vn ")))
}
