//! Building a scene from its parsed file: every number checked (finite, in range), every
//! name resolved, errors naming the file and the field.

use super::super::bsdf::Bsdf;
use super::super::geometry::{Prim, PrimInfo};
use super::super::media::{noise, Density, Grid, Medium, Phase};
use super::super::texture::{RoughnessSpec, Texture};
use super::super::{bvh::Bvh, microfacet, obj, ply, surfaces, Error};
use super::file::*;
use super::{bounding_sphere, light_cdf, light_of_prim, Light, Material, Scene, ThinLens};
use crate::math::{CameraModel, CameraToWorld, Distortion, Intrinsics, Pose};
use glam::{DMat3, DVec3, Vec2, Vec3A};
use std::path::Path;

fn field_err(path: &Path, field: &str, message: impl Into<String>) -> Error {
    Error::Invalid { path: path.to_path_buf(), field: field.to_string(), message: message.into() }
}

/// Largest magnitude of any number in a scene file. The renderer works in float32 (up to
/// 3.4·10³⁸); 10³⁰ leaves room for the products it forms (squared distances, intensity over
/// distance squared, radiance times area) before they overflow, where a value of 10³⁹ became
/// infinity and rendered black.
pub const MAX_SCENE_VALUE: f64 = 1e30;

/// Triangles in a disk's fan (`ShapeSpec::Disk`): its area falls short of πr² by
/// 1 − N·sin(2π/N)/(2π) ≈ (2π/N)²/6 = 6.3·10⁻⁶ at N = 1024.
pub const DISK_SEGMENTS: u32 = 1024;

/// Finite and within ±`MAX_SCENE_VALUE`.
fn representable(v: f64) -> bool {
    v.is_finite() && v.abs() <= MAX_SCENE_VALUE
}

fn finite3(path: &Path, field: &str, v: [f64; 3]) -> Result<DVec3, Error> {
    if v.iter().all(|&c| representable(c)) {
        Ok(DVec3::from_array(v))
    } else {
        Err(field_err(path, field, format!("{v:?} must be finite numbers within ±{MAX_SCENE_VALUE:e}")))
    }
}

impl LookAt {
    /// The camera-to-world pose it describes, its points within the range a scene holds
    /// (±`MAX_SCENE_VALUE`); `None` where one is not, the target is the origin, or `up` lies
    /// along the line of sight.
    pub fn pose(&self) -> Option<CameraToWorld> {
        let points = [self.origin, self.target, self.up];
        points.iter().flatten().all(|&v| representable(v)).then(|| {
            let [o, t, u] = points.map(DVec3::from_array);
            CameraToWorld::look_at(o, t, u)
        })?
    }
}

fn non_negative3(path: &Path, field: &str, v: [f64; 3]) -> Result<Vec3A, Error> {
    let d = finite3(path, field, v)?;
    if d.min_element() < 0.0 {
        return Err(field_err(path, field, format!("{v:?} must not be negative")));
    }
    Ok(d.as_vec3().into())
}

/// A shape's transform as built: R·(s ⊙ p) + t, or a general affine matrix.
struct Placement {
    rotation: DMat3,
    translation: DVec3,
    scale: DVec3,
    matrix: Option<glam::DAffine3>,
}

impl Placement {
    fn apply(&self, p: DVec3) -> DVec3 {
        match &self.matrix {
            Some(m) => m.transform_point3(p),
            None => self.rotation * (self.scale * p) + self.translation,
        }
    }

    /// The transform as one affine map.
    fn affine(&self) -> glam::DAffine3 {
        self.matrix.unwrap_or_else(|| {
            glam::DAffine3::from_mat3_translation(
                self.rotation * DMat3::from_diagonal(self.scale),
                self.translation,
            )
        })
    }

    /// Whether the transform mirrors (and so flips a mesh's winding).
    fn mirrors(&self) -> bool {
        match &self.matrix {
            Some(m) => m.matrix3.determinant() < 0.0,
            None => self.scale.x * self.scale.y * self.scale.z < 0.0,
        }
    }
}

impl TransformSpec {
    /// Builds the transform, checking every number.
    fn build(&self, path: &Path, field: &str) -> Result<Placement, Error> {
        if let Some(rows) = &self.matrix {
            if self.rotation.is_some()
                || self.rvec.is_some()
                || self.scale.is_some()
                || self.translation != [0.0; 3]
            {
                return Err(field_err(
                    path,
                    field,
                    "give either `matrix` or `rotation`/`rvec`/`scale`/`translation`, not both",
                ));
            }
            if !rows.iter().flatten().all(|&v| representable(v)) {
                return Err(field_err(
                    path,
                    &format!("{field}.matrix"),
                    format!("must be finite numbers within ±{MAX_SCENE_VALUE:e}"),
                ));
            }
            if rows[3] != [0.0, 0.0, 0.0, 1.0] {
                return Err(field_err(
                    path,
                    &format!("{field}.matrix"),
                    format!("last row {:?}: expected [0, 0, 0, 1] (an affine transform)", rows[3]),
                ));
            }
            let m = glam::DMat4::from_cols_array_2d(rows).transpose();
            let a = glam::DAffine3::from_mat4(m);
            let det = a.matrix3.determinant();
            if !(det.is_finite() && det.abs() > 1e-300) {
                return Err(field_err(
                    path,
                    &format!("{field}.matrix"),
                    "is singular: it flattens the shape",
                ));
            }
            return Ok(Placement {
                rotation: DMat3::IDENTITY,
                translation: DVec3::ZERO,
                scale: DVec3::ONE,
                matrix: Some(a),
            });
        }
        let rotation = match (&self.rotation, &self.rvec) {
            (Some(_), Some(_)) => {
                return Err(field_err(path, field, "give either `rotation` or `rvec`, not both"))
            }
            (Some(rows), None) => {
                for (i, r) in rows.iter().enumerate() {
                    finite3(path, &format!("{field}.rotation[{i}]"), *r)?;
                }
                let m = DMat3::from_cols_array_2d(rows).transpose();
                let e = Pose::orthonormality_error(&m);
                if e > 1e-6 {
                    return Err(field_err(
                        path,
                        &format!("{field}.rotation"),
                        format!(
                            "is not a rotation matrix (orthonormality error {e:.2e}, det {:.6})",
                            m.determinant()
                        ),
                    ));
                }
                m
            }
            (None, Some(r)) => Pose::rotation_from_rvec(finite3(path, &format!("{field}.rvec"), *r)?),
            (None, None) => DMat3::IDENTITY,
        };
        let translation = finite3(path, &format!("{field}.translation"), self.translation)?;
        let scale = match self.scale {
            None => DVec3::ONE,
            Some(Scale::Uniform(s)) => DVec3::splat(s),
            Some(Scale::PerAxis(s)) => DVec3::from_array(s),
        };
        if !scale.to_array().iter().all(|&v| representable(v)) || scale.abs().min_element() == 0.0 {
            return Err(field_err(
                path,
                &format!("{field}.scale"),
                format!("{scale} must be finite, within ±{MAX_SCENE_VALUE:e}, and non-zero"),
            ));
        }
        Ok(Placement { rotation, translation, scale, matrix: None })
    }
}

/// The parallelogram o + s·u + t·v (s, t ∈ [0, 1], the texture coordinates) as two triangles,
/// each with the `PrimInfo` `info_of` makes of its texture coordinates.
fn push_parallelogram(
    prims: &mut Vec<Prim>,
    info: &mut Vec<PrimInfo>,
    o: Vec3A,
    u: Vec3A,
    v: Vec3A,
    info_of: impl Fn([Vec2; 3]) -> PrimInfo,
) {
    for (e1, e2, uv) in
        [(u, u + v, [Vec2::ZERO, Vec2::X, Vec2::ONE]), (u + v, v, [Vec2::ZERO, Vec2::ONE, Vec2::Y])]
    {
        prims.push(Prim::Triangle { v0: o, e1, e2 });
        info.push(info_of(uv));
    }
}

/// The faces of the cube [−1, 1]³ as (corner, edge u, edge v), u × v pointing out.
fn cube_faces() -> [[DVec3; 3]; 6] {
    let d = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
    [
        [d(1.0, -1.0, -1.0), d(0.0, 2.0, 0.0), d(0.0, 0.0, 2.0)],
        [d(-1.0, -1.0, -1.0), d(0.0, 0.0, 2.0), d(0.0, 2.0, 0.0)],
        [d(-1.0, 1.0, -1.0), d(0.0, 0.0, 2.0), d(2.0, 0.0, 0.0)],
        [d(-1.0, -1.0, -1.0), d(2.0, 0.0, 0.0), d(0.0, 0.0, 2.0)],
        [d(-1.0, -1.0, 1.0), d(2.0, 0.0, 0.0), d(0.0, 2.0, 0.0)],
        [d(-1.0, -1.0, -1.0), d(0.0, 2.0, 0.0), d(2.0, 0.0, 0.0)],
    ]
}

/// Builds a scene from its parsed file; `path` resolves relative paths and names errors.
pub fn build(file: &SceneFile, path: &Path) -> Result<Scene, Error> {
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let (camera, t_world_cam) = build_camera(&file.camera, path)?;
    let lens = build_lens(&file.camera, path)?;
    if file.render.spp == 0 {
        return Err(field_err(path, "render.spp", "must be at least 1"));
    }
    if let Err(e) = file.render.photon.validate() {
        return Err(field_err(path, "render.photon", &e.to_string()));
    }
    if file.render.max_depth == 0 {
        return Err(field_err(path, "render.max_depth", "must be at least 1"));
    }
    if let Some(s) = &file.sensor {
        s.validate().map_err(|m| field_err(path, "sensor", m.0))?;
    }

    let mut materials = Vec::new();
    for (i, m) in file.materials.iter().enumerate() {
        let field = format!("materials[{i}] ({})", m.name);
        let bsdf = build_bsdf(m, path, &field)?;
        if materials.iter().any(|x: &Material| x.name == m.name) {
            return Err(field_err(path, &format!("{field}.name"), "is used by an earlier material"));
        }
        let albedo = match (&m.albedo, bsdf) {
            (None, Bsdf::Null) => Texture::Constant(Vec3A::ONE),
            (Some(_), Bsdf::Null) => {
                return Err(field_err(
                    path,
                    &format!("{field}.albedo"),
                    "a null material has no colour: leave it out",
                ))
            }
            (Some(a), _) => Texture::build(a, &dir, path, &format!("{field}.albedo"))?,
            (None, _) => {
                return Err(field_err(
                    path,
                    &format!("{field}.albedo"),
                    "is missing: give [r, g, b] or a texture",
                ))
            }
        };
        let emission =
            m.emission.map(|e| non_negative3(path, &format!("{field}.emission"), e)).transpose()?;
        let roughness = match &m.alpha {
            Some(spec @ (RoughnessSpec::Image { .. } | RoughnessSpec::Checker { .. })) => {
                Some(Texture::build_roughness(spec, &dir, path, &format!("{field}.alpha"))?)
            }
            _ => None,
        };
        let one_sided = m.two_sided == Some(false);
        if one_sided
            && matches!(
                bsdf,
                Bsdf::Dielectric { .. }
                    | Bsdf::RoughDielectric { .. }
                    | Bsdf::ThinDielectric { .. }
                    | Bsdf::Null
            )
        {
            return Err(field_err(
                path,
                &format!("{field}.two_sided"),
                "a dielectric or null surface has two sides by nature (light passes through): leave two_sided out",
            ));
        }
        materials.push(Material { name: m.name.clone(), albedo, emission, bsdf, roughness, one_sided });
    }
    let material_index = |name: &str, field: &str| -> Result<u32, Error> {
        materials.iter().position(|m| m.name == name).map(|i| i as u32).ok_or_else(|| {
            field_err(path, field, format!("names material '{name}', which the scene does not define"))
        })
    };

    let mut prims = Vec::new();
    let mut info = Vec::new();
    let mut object_names = vec!["background".to_string()];
    let media = build_media(&file.media, path, &dir)?;
    let medium_index = |name: Option<&str>, field: &str| -> Result<Option<u32>, Error> {
        name.map(|name| {
            media.iter().position(|m| m.name == name).map(|i| i as u32).ok_or_else(|| {
                field_err(
                    path,
                    field,
                    format!("names medium '{name}', which the scene's [[media]] do not define"),
                )
            })
        })
        .transpose()
    };
    let camera_medium = medium_index(file.camera.medium.as_deref(), "camera.medium")?;
    // Per primitive (file order), the media it bounds: `None` where its shape bounds none.
    let mut boundaries: Vec<Option<[Option<u32>; 2]>> = Vec::new();
    for (i, shape) in file.shapes.iter().enumerate() {
        let field = format!("shapes[{i}]");
        let boundary = match shape.media() {
            (None, None) => None,
            (inside, outside) => Some([
                medium_index(inside, &format!("{field}.interior"))?,
                medium_index(outside, &format!("{field}.exterior"))?,
            ]),
        };
        match shape {
            ShapeSpec::Mesh {
                file: f, material, object_materials, transform, reverse_orientation, ..
            } => {
                let mesh_path = dir.join(f);
                let mesh = if mesh_path.extension().is_some_and(|e| e.eq_ignore_ascii_case("ply")) {
                    ply::read(&mesh_path)?
                } else {
                    obj::read(&mesh_path)?
                };
                if mesh.triangles.is_empty() {
                    return Err(Error::EmptyMesh { path: mesh_path });
                }
                let place = transform.build(path, &format!("{field}.transform"))?;
                let default = material
                    .as_deref()
                    .map(|m| material_index(m, &format!("{field}.material")))
                    .transpose()?;
                for (obj_name, mat) in object_materials {
                    if !mesh.objects.contains(obj_name) {
                        return Err(field_err(
                            path,
                            &format!("{field}.object_materials"),
                            format!("'{obj_name}' is not an object of {}", mesh_path.display()),
                        ));
                    }
                    material_index(mat, &format!("{field}.object_materials.{obj_name}"))?;
                }
                let first_id = object_names.len() as u32;
                object_names.extend(mesh.objects.iter().cloned());
                let positions: Vec<Vec3A> =
                    mesh.positions.iter().map(|&p| place.apply(p).as_vec3().into()).collect();
                // A negative determinant mirrors the mesh and so flips its winding.
                let mirrored = place.mirrors();
                for tri in &mesh.triangles {
                    let obj_name = &mesh.objects[tri.object as usize];
                    let mtl = if let Some(m) = object_materials.get(obj_name) {
                        material_index(m, "")?
                    } else {
                        let by_usemtl = tri.material.and_then(|m| {
                            let n = &mesh.materials[m as usize];
                            materials.iter().position(|x| &x.name == n).map(|i| i as u32)
                        });
                        match by_usemtl.or(default) {
                            Some(m) => m,
                            None => {
                                let what = tri
                                    .material
                                    .map(|m| mesh.materials[m as usize].clone())
                                    .unwrap_or_else(|| "(none)".into());
                                return Err(field_err(
                                    path,
                                    &format!("{field}.material"),
                                    format!(
                                        "is not set, and the OBJ's usemtl {what} names no scene material"
                                    ),
                                ));
                            }
                        }
                    };
                    let [a, b, c] = tri.v.map(|k| positions[k as usize]);
                    let (e1, e2) = (b - a, c - a);
                    if e1.cross(e2).length_squared() == 0.0 {
                        continue; // degenerate triangle: no area, never hit
                    }
                    let uv = match tri.vt {
                        Some(vt) => vt.map(|k| mesh.uvs[k as usize].as_vec2()),
                        None => [Vec2::ZERO, Vec2::X, Vec2::Y],
                    };
                    prims.push(Prim::Triangle { v0: a, e1, e2 });
                    info.push(PrimInfo {
                        material: mtl,
                        object_id: first_id + tri.object,
                        reverse: *reverse_orientation ^ mirrored,
                        uv,
                        normal: Vec3A::ZERO,
                    });
                }
            }
            ShapeSpec::Sphere { center, radius, material, reverse_orientation, .. } => {
                let c = finite3(path, &format!("{field}.center"), *center)?;
                if !(representable(*radius) && *radius > 0.0) {
                    return Err(field_err(
                        path,
                        &format!("{field}.radius"),
                        format!("{radius} must be positive, at most {MAX_SCENE_VALUE:e}"),
                    ));
                }
                let mtl = material_index(material, &format!("{field}.material"))?;
                object_names.push(format!("sphere{i}"));
                prims.push(Prim::Sphere { center: c.as_vec3().into(), radius: *radius as f32 });
                info.push(PrimInfo {
                    material: mtl,
                    object_id: object_names.len() as u32 - 1,
                    reverse: *reverse_orientation,
                    uv: [Vec2::ZERO; 3],
                    normal: Vec3A::ZERO,
                });
            }
            ShapeSpec::Quad { corner, edge_u, edge_v, material, reverse_orientation, .. } => {
                let o = finite3(path, &format!("{field}.corner"), *corner)?;
                let u = finite3(path, &format!("{field}.edge_u"), *edge_u)?;
                let v = finite3(path, &format!("{field}.edge_v"), *edge_v)?;
                if u.cross(v).length() == 0.0 {
                    return Err(field_err(
                        path,
                        &field,
                        "edge_u and edge_v are parallel: the quad has no area",
                    ));
                }
                let mtl = material_index(material, &format!("{field}.material"))?;
                object_names.push(format!("quad{i}"));
                let id = object_names.len() as u32 - 1;
                let [o, u, v] = [o, u, v].map(|x| Vec3A::from(x.as_vec3()));
                let info_of = |uv| PrimInfo {
                    material: mtl,
                    object_id: id,
                    reverse: *reverse_orientation,
                    uv,
                    normal: Vec3A::ZERO,
                };
                push_parallelogram(&mut prims, &mut info, o, u, v, info_of);
            }
            ShapeSpec::Cube { material, transform, reverse_orientation, .. } => {
                let place = transform.build(path, &format!("{field}.transform"))?;
                let mtl = material_index(material, &format!("{field}.material"))?;
                object_names.push(format!("cube{i}"));
                let id = object_names.len() as u32 - 1;
                let reverse = *reverse_orientation ^ place.mirrors();
                for [o, u, v] in cube_faces() {
                    let [o, u, v] = [o, o + u, o + v].map(|p| Vec3A::from(place.apply(p).as_vec3()));
                    let info_of =
                        |uv| PrimInfo { material: mtl, object_id: id, reverse, uv, normal: Vec3A::ZERO };
                    push_parallelogram(&mut prims, &mut info, o, u - o, v - o, info_of);
                }
            }
            ShapeSpec::Disk { material, transform, reverse_orientation, .. } => {
                let place = transform.build(path, &format!("{field}.transform"))?;
                let mtl = material_index(material, &format!("{field}.material"))?;
                object_names.push(format!("disk{i}"));
                let id = object_names.len() as u32 - 1;
                let reverse = *reverse_orientation ^ place.mirrors();
                let centre = Vec3A::from(place.apply(DVec3::ZERO).as_vec3());
                let rim = |k: u32| {
                    let phi = std::f64::consts::TAU * k as f64 / DISK_SEGMENTS as f64;
                    Vec3A::from(place.apply(DVec3::new(phi.cos(), phi.sin(), 0.0)).as_vec3())
                };
                for k in 0..DISK_SEGMENTS {
                    let (a, b) = (rim(k), rim(k + 1));
                    let (e1, e2) = (a - centre, b - centre);
                    if e1.cross(e2).length_squared() == 0.0 {
                        continue; // a transform that flattens the disk to a line
                    }
                    prims.push(Prim::Triangle { v0: centre, e1, e2 });
                    let (va, vb) = (k as f32 / DISK_SEGMENTS as f32, (k + 1) as f32 / DISK_SEGMENTS as f32);
                    let uv = [Vec2::new(0.0, 0.5 * (va + vb)), Vec2::new(1.0, va), Vec2::new(1.0, vb)];
                    info.push(PrimInfo { material: mtl, object_id: id, reverse, uv, normal: Vec3A::ZERO });
                }
            }
            ShapeSpec::Torus { .. } | ShapeSpec::Blob { .. } | ShapeSpec::Relief { .. } => {
                let Some((surface, material, transform)) = generated_surface(shape, path, &field)? else {
                    continue;
                };
                let place = transform.build(path, &format!("{field}.transform"))?;
                let mtl = material_index(material, &format!("{field}.material"))?;
                let kind = match shape {
                    ShapeSpec::Torus { .. } => "torus",
                    ShapeSpec::Blob { .. } => "blob",
                    _ => "relief",
                };
                object_names.push(format!("{kind}{i}"));
                let id = object_names.len() as u32 - 1;
                let positions: Vec<Vec3A> =
                    surface.positions.iter().map(|&p| place.apply(p).as_vec3().into()).collect();
                let mirrored = place.mirrors();
                for tri in &surface.triangles {
                    let [a, b, c] = tri.map(|k| positions[k as usize]);
                    let (e1, e2) = (b - a, c - a);
                    if e1.cross(e2).length_squared() == 0.0 {
                        continue; // the blob's poles
                    }
                    prims.push(Prim::Triangle { v0: a, e1, e2 });
                    info.push(PrimInfo {
                        material: mtl,
                        object_id: id,
                        reverse: mirrored,
                        uv: [Vec2::ZERO, Vec2::X, Vec2::Y],
                        normal: Vec3A::ZERO,
                    });
                }
            }
        }
        boundaries.resize(prims.len(), boundary);
    }

    let bvh = Bvh::build(&prims);
    // In the BVH's order, and none at all where no shape bounds a medium.
    let boundaries: Vec<Option<[Option<u32>; 2]>> = if boundaries.iter().all(Option::is_none) {
        Vec::new()
    } else {
        bvh.order.iter().map(|&i| boundaries[i as usize]).collect()
    };
    // A medium no shape bounds and the camera is not in can never be entered.
    for (i, m) in media.iter().enumerate() {
        let used = camera_medium == Some(i as u32)
            || file.shapes.iter().any(|s| {
                let (a, b) = s.media();
                a == Some(m.name.as_str()) || b == Some(m.name.as_str())
            });
        if !used {
            return Err(field_err(
                path,
                &format!("media[{i}] ({})", m.name),
                "is not the camera's medium and no shape's interior or exterior: nothing could enter it (give a shape `interior = \"NAME\"`, or the camera `medium`)",
            ));
        }
    }
    if let Some(why) = super::super::integrators::refusal(file.render.integrator, !media.is_empty()) {
        return Err(field_err(path, "render.integrator", &why));
    }
    let info: Vec<PrimInfo> = bvh
        .order
        .iter()
        .zip(&bvh.prims)
        .map(|(&i, prim)| {
            let mut inf = info[i as usize];
            let n = prim.normal(prim.centroid());
            inf.normal = if inf.reverse { -n } else { n };
            inf
        })
        .collect();
    let (bounds_center, bounds_radius) = bounding_sphere(&bvh.prims, t_world_cam.translation);

    let mut lights = Vec::new();
    let mut environment_map = None;
    for (i, l) in file.lights.iter().enumerate() {
        let field = format!("lights[{i}]");
        lights.push(match l {
            LightSpec::Point { position, intensity, power } => {
                let intensity = match (intensity, power) {
                    (Some(i), None) => non_negative3(path, &format!("{field}.intensity"), *i)?,
                    (None, Some(p)) => {
                        non_negative3(path, &format!("{field}.power"), *p)? / (4.0 * std::f32::consts::PI)
                    }
                    _ => {
                        return Err(field_err(
                            path,
                            &field,
                            "give exactly one of `intensity` (W/sr) or `power` (W)",
                        ))
                    }
                };
                Light::Point {
                    position: finite3(path, &format!("{field}.position"), *position)?.as_vec3().into(),
                    intensity,
                }
            }
            LightSpec::Environment { radiance, map, scale, rotation } => {
                if lights.iter().any(|l| matches!(l, Light::Environment { .. })) {
                    return Err(field_err(path, &field, "a scene takes one environment light"));
                }
                match (radiance, map) {
                    (Some(r), None) if scale.is_none() && rotation.is_none() => {
                        let radiance = non_negative3(path, &format!("{field}.radiance"), *r)?;
                        Light::Environment { radiance, mean: radiance }
                    }
                    (None, Some(m)) => {
                        let scale = scale.unwrap_or(1.0);
                        if !(representable(scale) && scale >= 0.0) {
                            return Err(field_err(
                                path,
                                &format!("{field}.scale"),
                                format!("{scale}: expected a finite number ≥ 0"),
                            ));
                        }
                        let turn = rotation
                            .map(|r| rotation_matrix(path, &format!("{field}.rotation"), &r))
                            .transpose()?;
                        let file = dir.join(m);
                        if !file.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr")) {
                            return Err(field_err(
                                path,
                                &format!("{field}.map"),
                                format!("{}: an environment map must be a linear EXR file", file.display()),
                            ));
                        }
                        let img = crate::image::io::read(&file)?;
                        let mut env = super::super::envmap::EnvMap::new(&img).map_err(|e| {
                            field_err(path, &format!("{field}.map"), format!("{}: {e}", file.display()))
                        })?;
                        if let Some(r) = turn {
                            env = env.rotated(r);
                        }
                        let radiance = Vec3A::splat(scale as f32);
                        let mean = radiance * env.mean_radiance;
                        environment_map = Some(env);
                        Light::Environment { radiance, mean }
                    }
                    _ => {
                        return Err(field_err(
                            path,
                            &field,
                            "an environment light takes `radiance` = [r, g, b], or `map` = \"file.exr\" with an optional `scale` and `rotation`",
                        ))
                    }
                }
            }
            LightSpec::Spot { position, target, intensity, cutoff_deg, beam_width_deg } => {
                let p = finite3(path, &format!("{field}.position"), *position)?;
                let t = finite3(path, &format!("{field}.target"), *target)?;
                if (t - p).length() == 0.0 {
                    return Err(field_err(path, &format!("{field}.target"), "must differ from `position`"));
                }
                let cutoff = cutoff_deg.unwrap_or(20.0);
                if !(cutoff > 0.0 && cutoff <= 90.0) {
                    return Err(field_err(
                        path,
                        &format!("{field}.cutoff_deg"),
                        format!("{cutoff}: expected (0, 90]"),
                    ));
                }
                let beam = beam_width_deg.unwrap_or(0.75 * cutoff);
                if !(beam > 0.0 && beam <= cutoff) {
                    return Err(field_err(
                        path,
                        &format!("{field}.beam_width_deg"),
                        format!("{beam}: expected (0, cutoff_deg = {cutoff}]"),
                    ));
                }
                Light::Spot {
                    position: p.as_vec3().into(),
                    axis: (t - p).normalize().as_vec3().into(),
                    intensity: non_negative3(path, &format!("{field}.intensity"), *intensity)?,
                    cutoff: cutoff.to_radians() as f32,
                    beam: beam.to_radians() as f32,
                }
            }
            LightSpec::Directional { to_light, irradiance } => {
                let d = finite3(path, &format!("{field}.to_light"), *to_light)?;
                if d.length() == 0.0 {
                    return Err(field_err(path, &format!("{field}.to_light"), "must not be the zero vector"));
                }
                Light::Directional {
                    to_light: d.normalize().as_vec3().into(),
                    irradiance: non_negative3(path, &format!("{field}.irradiance"), *irradiance)?,
                }
            }
        });
    }
    for (k, (p, inf)) in bvh.prims.iter().zip(&info).enumerate() {
        if let Some(e) = materials[inf.material as usize].emission {
            if e.max_element() > 0.0 {
                lights.push(Light::Area { prim: k as u32, radiance: e, area: p.area() });
            }
        }
    }
    let light_cdf = light_cdf(&lights, bounds_radius);
    let light_of_prim = light_of_prim(&lights, bvh.prims.len());
    let environment_light = lights.iter().position(|l| matches!(l, Light::Environment { .. }));

    Ok(Scene {
        camera,
        t_world_cam,
        lens,
        render: file.render.clone(),
        sensor: file.sensor.clone(),
        materials,
        bvh,
        info,
        lights,
        light_cdf,
        light_of_prim,
        environment_light,
        environment_map,
        object_names,
        media,
        boundaries,
        camera_medium,
        bounds_center,
        bounds_radius,
    })
}

fn build_lens(c: &CameraSpec, path: &Path) -> Result<Option<ThinLens>, Error> {
    let radius = c.aperture_radius.unwrap_or(0.0);
    if !(radius.is_finite() && radius >= 0.0) {
        return Err(field_err(
            path,
            "camera.aperture_radius",
            format!("{radius}: expected a finite number ≥ 0"),
        ));
    }
    match c.focus_distance {
        _ if radius == 0.0 => Ok(None),
        Some(f) if f.is_finite() && f > 0.0 => {
            Ok(Some(ThinLens { aperture_radius: radius, focus_distance: f }))
        }
        Some(f) => {
            Err(field_err(path, "camera.focus_distance", format!("{f}: expected a positive distance")))
        }
        None => Err(field_err(path, "camera", "a lens (aperture_radius > 0) needs `focus_distance`")),
    }
}

pub(super) fn build_camera(c: &CameraSpec, path: &Path) -> Result<(CameraModel, CameraToWorld), Error> {
    let mut camera = match (c.fov_deg, c.fx, c.fy, c.cx, c.cy) {
        (Some(fov), None, None, None, None) => {
            if !(fov > 0.0 && fov < 180.0) {
                return Err(field_err(path, "camera.fov_deg", format!("{fov} must be in (0, 180) degrees")));
            }
            CameraModel::from_fov(c.width, c.height, fov)
        }
        (None, Some(fx), Some(fy), Some(cx), Some(cy)) => CameraModel {
            width: c.width,
            height: c.height,
            intrinsics: Intrinsics { fx, fy, cx, cy },
            distortion: Distortion::default(),
        },
        _ => return Err(field_err(path, "camera", "give either `fov_deg` or all of `fx`, `fy`, `cx`, `cy`")),
    };
    if let Some(d) = c.distortion {
        camera.distortion = Distortion::from_array(d);
    }
    camera.validate().map_err(|m| field_err(path, "camera", m.0))?;
    if c.width as u64 * c.height as u64 > 1 << 28 {
        return Err(field_err(
            path,
            "camera",
            format!("{}×{} pixels is more than the 2^28 lumen renders", c.width, c.height),
        ));
    }
    let pose = match (&c.look_at, &c.t_world_cam) {
        (Some(l), None) => {
            finite3(path, "camera.look_at.origin", l.origin)?;
            finite3(path, "camera.look_at.target", l.target)?;
            finite3(path, "camera.look_at.up", l.up)?;
            l.pose().ok_or_else(|| {
                field_err(
                    path,
                    "camera.look_at",
                    "origin equals target, or up is parallel to the view direction",
                )
            })?
        }
        (None, Some(t)) => {
            if t.scale.is_some() || t.matrix.is_some() {
                return Err(field_err(
                    path,
                    "camera.t_world_cam",
                    "a camera pose is rigid: `rotation` or `rvec` and `translation`, no `scale` or `matrix`",
                ));
            }
            let p = t.build(path, "camera.t_world_cam")?;
            CameraToWorld(Pose { rotation: p.rotation, translation: p.translation })
        }
        _ => return Err(field_err(path, "camera", "give exactly one of `look_at` or `t_world_cam`")),
    };
    Ok((camera, pose))
}

/// A rotation given as rows: orthonormal to 10⁻⁶ with determinant +1.
fn rotation_matrix(path: &Path, field: &str, rows: &[[f64; 3]; 3]) -> Result<glam::Mat3A, Error> {
    let m = DMat3::from_cols_array_2d(rows).transpose();
    let orthonormal = (m.transpose() * m).abs_diff_eq(DMat3::IDENTITY, 1e-6);
    if !(rows.iter().flatten().all(|v| v.is_finite()) && orthonormal && m.determinant() > 0.0) {
        return Err(field_err(
            path,
            field,
            format!("{rows:?}: expected a rotation (orthonormal rows, determinant +1)"),
        ));
    }
    Ok(glam::Mat3A::from(m.as_mat3()))
}

/// The reflectance model a material names, each field checked.
fn build_bsdf(m: &MaterialSpec, path: &Path, field: &str) -> Result<Bsdf, Error> {
    let coated = matches!(m.kind.as_str(), "plastic" | "rough-plastic");
    let blinn_phong = (m.specular.is_some() && !coated) || m.exponent.is_some();
    let rough = m.distribution.is_some() || m.alpha.is_some();
    let conductor = rough || m.eta.is_some() || m.k.is_some();
    let foreign = |kind: &str, other: &str| {
        field_err(path, field, format!("a {kind} material takes no {other} fields (check `type`)"))
    };
    if m.ior.is_some()
        && !(coated || matches!(m.kind.as_str(), "dielectric" | "rough-dielectric" | "thin-dielectric"))
    {
        return Err(field_err(
            path,
            &format!("{field}.ior"),
            "only a dielectric (smooth, rough or thin) or plastic (smooth or rough) material takes `ior`",
        ));
    }
    if m.nonlinear.is_some() && !coated {
        return Err(field_err(
            path,
            &format!("{field}.nonlinear"),
            "only a plastic material takes `nonlinear`",
        ));
    }
    // A rough model's distribution (default GGX) and α; a textured α is looked up per hit
    // (Material::roughness) and the model keeps 0.1.
    let microfacets = || {
        let distribution = match m.distribution.as_deref().unwrap_or("ggx") {
            "ggx" => microfacet::Distribution::Ggx,
            "beckmann" => microfacet::Distribution::Beckmann,
            other => {
                return Err(field_err(
                    path,
                    &format!("{field}.distribution"),
                    format!("'{other}': expected \"ggx\" or \"beckmann\""),
                ))
            }
        };
        let alpha = match m.alpha {
            Some(RoughnessSpec::Constant(a)) => a,
            _ => 0.1,
        };
        if !(0.001..=1.0).contains(&alpha) {
            return Err(field_err(path, &format!("{field}.alpha"), format!("{alpha}: expected [0.001, 1]")));
        }
        Ok((distribution, alpha as f32))
    };
    let index = |default: f64| {
        let ior = m.ior.unwrap_or(default);
        if (0.25..=4.0).contains(&ior) {
            Ok(ior)
        } else {
            Err(field_err(
                path,
                &format!("{field}.ior"),
                format!("{ior}: expected a relative index in [0.25, 4]"),
            ))
        }
    };
    let complex_index = |eta: [f64; 3], k: [f64; 3]| {
        let eta = non_negative3(path, &format!("{field}.eta"), eta)?;
        let k = non_negative3(path, &format!("{field}.k"), k)?;
        // η = 0 with k > 0 is a perfect conductor (F = 1; Mitsuba's `material = "none"` is
        // η = 0, k = 1); η = k = 0 has no meaning.
        if (0..3).any(|c| eta[c] == 0.0 && k[c] == 0.0) {
            return Err(field_err(path, &format!("{field}.eta"), "must be positive where k is 0"));
        }
        Ok((eta, k))
    };
    match m.kind.as_str() {
        "lambertian" if blinn_phong => Err(field_err(
            path,
            field,
            "a lambertian material takes no `specular` or `exponent` (use type = \"blinn-phong\")",
        )),
        "lambertian" if conductor => Err(foreign("lambertian", "conductor")),
        "lambertian" => Ok(Bsdf::Lambertian),
        "blinn-phong" if conductor => Err(foreign("blinn-phong", "conductor")),
        "blinn-phong" => {
            let (Some(ks), Some(e)) = (m.specular, m.exponent) else {
                return Err(field_err(
                    path,
                    field,
                    "a blinn-phong material needs `specular` = [r, g, b] and `exponent`",
                ));
            };
            let specular = non_negative3(path, &format!("{field}.specular"), ks)?;
            if specular.max_element() > 1.0 {
                // ks is the lobe's reflectance, bounded as an albedo is.
                return Err(field_err(
                    path,
                    &format!("{field}.specular"),
                    format!("{ks:?}: each value must be in [0, 1] (more would create energy)"),
                ));
            }
            if !(e.is_finite() && e > 0.0 && e <= 1e5) {
                return Err(field_err(
                    path,
                    &format!("{field}.exponent"),
                    format!("{e}: expected a number in (0, 100000]"),
                ));
            }
            Ok(Bsdf::BlinnPhong { specular, exponent: e as f32 })
        }
        "conductor" if blinn_phong => Err(foreign("conductor", "blinn-phong")),
        "conductor" => {
            let (distribution, alpha) = microfacets()?;
            let (eta, k) = complex_index(
                m.eta.unwrap_or([0.143, 0.374, 1.442]),
                m.k.unwrap_or([3.983, 2.385, 1.603]),
            )?;
            Ok(Bsdf::Conductor { distribution, alpha, eta, k })
        }
        "mirror" if blinn_phong => Err(foreign("mirror", "blinn-phong")),
        "mirror" if rough => Err(field_err(
            path,
            field,
            "a mirror is smooth: it takes no `alpha` or `distribution` (use type = \"conductor\")",
        )),
        "mirror" => match (m.eta, m.k) {
            (None, None) => Ok(Bsdf::Mirror { fresnel: None }),
            (Some(eta), Some(k)) => Ok(Bsdf::Mirror { fresnel: Some(complex_index(eta, k)?) }),
            _ => Err(field_err(path, field, "a mirror takes both `eta` and `k` or neither (a perfect mirror)")),
        },
        "dielectric" if blinn_phong || conductor => Err(foreign("dielectric", "blinn-phong or conductor")),
        "dielectric" => Ok(Bsdf::Dielectric { eta: index(1.5046 / 1.000277)? as f32 }),
        "rough-dielectric" if blinn_phong || m.eta.is_some() || m.k.is_some() => {
            Err(foreign("rough-dielectric", "blinn-phong or `eta`/`k` (its index is `ior`)"))
        }
        "rough-dielectric" => {
            let (distribution, alpha) = microfacets()?;
            Ok(Bsdf::RoughDielectric { distribution, alpha, eta: index(1.5046 / 1.000277)? as f32 })
        }
        "thin-dielectric" if blinn_phong || conductor => {
            Err(foreign("thin-dielectric", "blinn-phong or conductor"))
        }
        "thin-dielectric" => Ok(Bsdf::ThinDielectric { eta: index(1.5046 / 1.000277)? as f32 }),
        "plastic" if blinn_phong || conductor => Err(foreign("plastic", "blinn-phong or conductor")),
        "rough-plastic" if blinn_phong || m.eta.is_some() || m.k.is_some() => {
            Err(foreign("rough-plastic", "blinn-phong or `eta`/`k` (its coat's index is `ior`)"))
        }
        "plastic" | "rough-plastic" => {
            let eta = index(1.49 / 1.000277)?;
            let specular = non_negative3(path, &format!("{field}.specular"), m.specular.unwrap_or([1.0; 3]))?;
            if specular.max_element() > 1.0 {
                return Err(field_err(
                    path,
                    &format!("{field}.specular"),
                    format!("{:?}: each value must be in [0, 1] (more would create energy)", m.specular),
                ));
            }
            let nonlinear = m.nonlinear.unwrap_or(false);
            if m.kind == "plastic" {
                return Ok(Bsdf::Plastic {
                    eta: eta as f32,
                    fdr_int: crate::render::plastic::diffuse_reflectance_inside(eta) as f32,
                    specular,
                    nonlinear,
                });
            }
            if !matches!(m.alpha, None | Some(RoughnessSpec::Constant(_))) {
                return Err(field_err(
                    path,
                    &format!("{field}.alpha"),
                    "a rough plastic's coat is tabulated for one roughness: give a number",
                ));
            }
            if (eta - 1.0).abs() < 1e-6 {
                return Err(field_err(path, &format!("{field}.ior"), "a coat of index 1 is no coat: it must differ from 1"));
            }
            let (distribution, alpha) = microfacets()?;
            let eta = eta as f32;
            Ok(Bsdf::RoughPlastic {
                distribution,
                alpha,
                eta,
                specular,
                nonlinear,
                coat: crate::render::plastic::RoughCoat::of(distribution, alpha, eta),
            })
        }
        "null" if blinn_phong || conductor => Err(foreign("null", "blinn-phong or conductor")),
        "null" => Ok(Bsdf::Null),
        other => Err(field_err(
            path,
            &format!("{field}.type"),
            format!(
                "'{other}' is not a known material (expected \"lambertian\", \"blinn-phong\", \"conductor\", \"mirror\", \"dielectric\", \"rough-dielectric\", \"thin-dielectric\", \"plastic\", \"rough-plastic\" or \"null\")"
            ),
        )),
    }
}

/// The `[[media]]`, each value checked: names unique, coefficients finite and ≥ 0, albedo in
/// [0, 1], g in (−1, 1).
fn build_media(specs: &[MediumSpec], path: &Path, dir: &Path) -> Result<Vec<Medium>, Error> {
    let mut media: Vec<Medium> = Vec::new();
    for (i, m) in specs.iter().enumerate() {
        let field = format!("media[{i}] ({})", m.name);
        if media.iter().any(|x| x.name == m.name) {
            return Err(field_err(path, &format!("{field}.name"), "is used by an earlier medium"));
        }
        let scale = m.scale.unwrap_or(1.0);
        if !(representable(scale) && scale >= 0.0) {
            return Err(field_err(
                path,
                &format!("{field}.scale"),
                format!("{scale}: expected a finite number ≥ 0"),
            ));
        }
        let (sigma_t, albedo) =
            match (m.sigma_t, m.albedo, m.sigma_a, m.sigma_s) {
                (Some(t), a, None, None) => {
                    let t = non_negative3(path, &format!("{field}.sigma_t"), t)?;
                    let a = a.map(|a| non_negative3(path, &format!("{field}.albedo"), a)).transpose()?;
                    let a = a.unwrap_or(Vec3A::ONE);
                    if a.max_element() > 1.0 {
                        return Err(field_err(
                            path,
                            &format!("{field}.albedo"),
                            format!("{a}: each value must be in [0, 1] (the share of σt that scatters)"),
                        ));
                    }
                    (t, a)
                }
                (None, None, Some(a), Some(s)) => {
                    let a = non_negative3(path, &format!("{field}.sigma_a"), a)?;
                    let s = non_negative3(path, &format!("{field}.sigma_s"), s)?;
                    let t = a + s;
                    (t, Vec3A::select(t.cmpgt(Vec3A::ZERO), s / t, Vec3A::ZERO))
                }
                _ => return Err(field_err(
                    path,
                    &field,
                    "give `sigma_t` (with an optional `albedo`, default 1) or both `sigma_a` and `sigma_s`",
                )),
            };
        let g = m.g.unwrap_or(0.0);
        if !(g.is_finite() && g > -1.0 && g < 1.0) {
            return Err(field_err(path, &format!("{field}.g"), format!("{g}: expected a number in (−1, 1)")));
        }
        let sigma_t = sigma_t * scale as f32;
        if !sigma_t.is_finite() {
            return Err(field_err(path, &field, "σt times scale overflows single precision"));
        }
        let density = match (&m.grid, &m.noise) {
            (Some(_), Some(_)) => {
                return Err(field_err(path, &field, "give a `grid` file or a `noise`, not both"));
            }
            (None, None) if m.grid_transform.is_some() || m.grid_bbox.is_some() => {
                return Err(field_err(
                    path,
                    &field,
                    "`grid_transform` and `grid_bbox` place a `grid` or `noise`, and neither is given",
                ))
            }
            (None, None) => None,
            (None, Some(_)) if m.grid_bbox.is_some() => {
                return Err(field_err(
                    path,
                    &format!("{field}.grid_bbox"),
                    "a noise has no box of its own: place it by `grid_transform`",
                ));
            }
            (None, Some(n)) => {
                let f = format!("{field}.noise");
                let check = |ok: bool, key: &str, what: String| {
                    if ok {
                        Ok(())
                    } else {
                        Err(field_err(path, &format!("{f}.{key}"), what))
                    }
                };
                check((1..=8).contains(&n.octaves), "octaves", format!("{}: expected 1 to 8", n.octaves))?;
                check((1..=64).contains(&n.cells), "cells", format!("{}: expected 1 to 64", n.cells))?;
                check(
                    (0.0..1.0).contains(&n.threshold),
                    "threshold",
                    format!("{}: expected a number in [0, 1)", n.threshold),
                )?;
                check(
                    (2..=noise::MAX_RESOLUTION).contains(&n.resolution),
                    "resolution",
                    format!("{}: expected 2 to {}", n.resolution, noise::MAX_RESOLUTION),
                )?;
                let grid = noise::density_grid(n.seed, n.octaves, n.cells, n.threshold as f32, n.resolution);
                let place = m
                    .grid_transform
                    .clone()
                    .unwrap_or_default()
                    .build(path, &format!("{field}.grid_transform"))?;
                let to_grid = place.affine().inverse();
                let to_grid = glam::Affine3A::from_mat3_translation(
                    to_grid.matrix3.as_mat3(),
                    to_grid.translation.as_vec3(),
                );
                Some(Density::new(grid, to_grid))
            }
            (Some(file), None) => {
                let grid = Grid::read(&dir.join(file))?;
                let place = m
                    .grid_transform
                    .clone()
                    .unwrap_or_default()
                    .build(path, &format!("{field}.grid_transform"))?;
                let mut to_world = place.affine();
                if m.grid_bbox == Some(true) {
                    let (lo, hi) = grid.bbox;
                    let extent = hi - lo;
                    if !(extent.min_element() > 0.0 && extent.is_finite() && lo.is_finite()) {
                        return Err(field_err(
                            path,
                            &format!("{field}.grid_bbox"),
                            format!("{file}'s box {lo} to {hi} is empty or not finite"),
                        ));
                    }
                    to_world = to_world
                        * glam::DAffine3::from_scale_rotation_translation(
                            extent.as_dvec3(),
                            glam::DQuat::IDENTITY,
                            lo.as_dvec3(),
                        );
                }
                let to_grid = to_world.inverse();
                let to_grid = glam::Affine3A::from_mat3_translation(
                    to_grid.matrix3.as_mat3(),
                    to_grid.translation.as_vec3(),
                );
                Some(Density::new(grid, to_grid))
            }
        };
        media.push(Medium { name: m.name.clone(), sigma_t, albedo, phase: Phase { g: g as f32 }, density });
    }
    Ok(media)
}

/// The generated surface a `torus`, `blob` or `relief` shape describes, with its material and
/// transform; `None` for other shapes.
fn generated_surface<'a>(
    shape: &'a ShapeSpec,
    path: &Path,
    field: &str,
) -> Result<Option<(surfaces::Surface, &'a str, &'a TransformSpec)>, Error> {
    let positive = |name: &str, v: f64| {
        if representable(v) && v > 0.0 {
            Ok(())
        } else {
            Err(field_err(
                path,
                &format!("{field}.{name}"),
                format!("{v} must be positive, at most {MAX_SCENE_VALUE:e}"),
            ))
        }
    };
    // 2²⁰ quads (2²¹ triangles) take about 0.7 GB with the BVH; 4096 × 4096 took 11.7 GB.
    const MAX_QUADS: u64 = 1 << 20;
    let counts = |n: &[u32], quads: u64| {
        if !n.iter().all(|&k| (3..=4096).contains(&k)) {
            Err(field_err(path, &format!("{field}.segments"), format!("{n:?}: expected 3 to 4096")))
        } else if quads > MAX_QUADS {
            Err(field_err(
                path,
                &format!("{field}.segments"),
                format!("{n:?} makes {quads} quads, more than the {MAX_QUADS} a generated surface may have"),
            ))
        } else {
            Ok(())
        }
    };
    Ok(Some(match shape {
        ShapeSpec::Torus { radius, tube, segments, material, transform, .. } => {
            positive("radius", *radius)?;
            positive("tube", *tube)?;
            counts(segments, segments[0] as u64 * segments[1] as u64)?;
            (surfaces::torus(*radius, *tube, *segments), material, transform)
        }
        ShapeSpec::Blob { radius, amplitude, lobes, segments, material, transform, .. } => {
            positive("radius", *radius)?;
            positive("lobes", *lobes)?;
            if !(0.0..1.0).contains(amplitude) {
                return Err(field_err(
                    path,
                    &format!("{field}.amplitude"),
                    format!("{amplitude}: expected [0, 1)"),
                ));
            }
            counts(segments, segments[0] as u64 * segments[1] as u64)?;
            (surfaces::blob(*radius, *amplitude, *lobes, *segments), material, transform)
        }
        ShapeSpec::Relief { size, height, segments, material, transform, .. } => {
            positive("size", *size)?;
            positive("height", *height)?;
            counts(&[*segments], *segments as u64 * *segments as u64)?;
            (surfaces::relief(*size, *height, *segments), material, transform)
        }
        _ => return Ok(None),
    }))
}
