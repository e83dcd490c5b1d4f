//! The scene file's schema: what a `[camera]`, `[render]`, `[[materials]]`, `[[shapes]]` and
//! `[[lights]]` entry may hold (every struct refuses unknown keys). `build` turns it into a
//! `Scene`, checking every value.

use super::super::texture::{RoughnessSpec, TextureSpec};
use serde::{Deserialize, Serialize};

// ---------------------------------------------------------------------------------------------
// File format
// ---------------------------------------------------------------------------------------------

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    pub camera: CameraSpec,
    #[serde(default)]
    pub render: RenderSpec,
    pub sensor: Option<super::super::sensor::Sensor>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub materials: Vec<MaterialSpec>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub shapes: Vec<ShapeSpec>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lights: Vec<LightSpec>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub media: Vec<MediumSpec>,
}

/// Camera: size, then either `fov_deg` (on the shorter side, centred principal point) or
/// `fx, fy, cx, cy` (OpenCV pixels), optional `distortion = [k1, k2, p1, p2, k3]`, and a pose:
/// `look_at = { origin, target, up }` or `t_world_cam = { rotation | rvec, translation }`.
impl SceneFile {
    /// Makes every relative file name (meshes, textures, environment maps) absolute, joined
    /// to `dir`: the scene can then be written to another folder.
    pub fn rebase(&mut self, dir: &std::path::Path) {
        let fix = |f: &mut String| {
            if std::path::Path::new(f.as_str()).is_relative() {
                *f = dir.join(&*f).to_string_lossy().into_owned();
            }
        };
        for m in &mut self.materials {
            if let Some(TextureSpec::Image { texture }) = &mut m.albedo {
                fix(texture);
            }
            if let Some(RoughnessSpec::Image { texture }) = &mut m.alpha {
                fix(texture);
            }
        }
        for s in &mut self.shapes {
            if let ShapeSpec::Mesh { file, .. } = s {
                fix(file);
            }
        }
        for l in &mut self.lights {
            if let LightSpec::Environment { map: Some(m), .. } = l {
                fix(m);
            }
        }
        for m in &mut self.media {
            if let Some(g) = &mut m.grid {
                fix(g);
            }
        }
    }
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    pub width: u32,
    pub height: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fov_deg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fx: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fy: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cx: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cy: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distortion: Option<[f64; 5]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub look_at: Option<LookAt>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub t_world_cam: Option<TransformSpec>,
    /// Thin lens (depth of field, as Mitsuba's `thinlens`): radius of the aperture in scene
    /// units (default 0, a pinhole) and the distance along the optical axis (camera z) of
    /// the plane in focus, which a lens needs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aperture_radius: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focus_distance: Option<f64>,
    /// The medium (`[[media]]` by name) the camera sits in: it fills space up to the first
    /// shape that bounds another (as Mitsuba's sensor `medium`). Default none (vacuum).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub medium: Option<String>,
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LookAt {
    pub origin: [f64; 3],
    pub target: [f64; 3],
    pub up: [f64; 3],
}

/// A rigid (plus optional scale, for shapes) transform: p' = R·(s ⊙ p) + t. `rotation` is a
/// 3×3 matrix given as rows; `rvec` a Rodrigues vector (radians), as OpenCV's. Shapes also
/// take any affine `matrix` (4×4, rows, last row [0, 0, 0, 1]: p' = M·[p, 1]) instead, as
/// Mitsuba's `to_world` holds it.
#[derive(Clone, Debug, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct TransformSpec {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub matrix: Option<[[f64; 4]; 4]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation: Option<[[f64; 3]; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rvec: Option<[f64; 3]>,
    #[serde(default)]
    pub translation: [f64; 3],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<Scale>,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(untagged)]
pub enum Scale {
    Uniform(f64),
    PerAxis([f64; 3]),
}

/// Render settings a scene may carry; the CLI and pipeline files override them.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RenderSpec {
    /// The light-transport algorithm by name (`render::integrators::REGISTRY`; default
    /// `"path"`).
    #[serde(default = "default_integrator")]
    pub integrator: &'static crate::render::integrators::Kind,
    /// Samples per pixel (default 16).
    #[serde(default = "default_spp")]
    pub spp: u32,
    /// Longest path in segments, Mitsuba's convention: 1 shows only emitters seen directly,
    /// 2 adds direct lighting, 8 allows 7 bounces (default 8).
    #[serde(default = "default_depth")]
    pub max_depth: u32,
    /// Seed of every random stream (default 1).
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// `"independent"` (default) or `"sobol"` (padded Owen-scrambled Sobol, see
    /// `render::sampler`; converges faster on pixel edges and soft shadows).
    #[serde(default)]
    pub sampler: super::super::sampler::SamplerKind,
    /// The pixel filter: `"box"` (default; each pixel averages its own square) or
    /// `"gaussian"` (Mitsuba's default rfilter, σ = 0.5 px; `render::filter`).
    #[serde(default)]
    pub filter: super::super::filter::PixelFilter,
    /// Photon mapping's settings, `[render.photon]` (`render::integrators::PhotonSettings`).
    #[serde(default)]
    pub photon: crate::render::integrators::PhotonSettings,
}

fn default_integrator() -> &'static crate::render::integrators::Kind {
    crate::render::integrators::DEFAULT
}
fn default_spp() -> u32 {
    16
}
fn default_depth() -> u32 {
    8
}
fn default_seed() -> u64 {
    1
}

impl Default for RenderSpec {
    fn default() -> Self {
        RenderSpec {
            integrator: default_integrator(),
            spp: default_spp(),
            max_depth: default_depth(),
            seed: default_seed(),
            sampler: Default::default(),
            filter: Default::default(),
            photon: Default::default(),
        }
    }
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    pub name: String,
    /// `"lambertian"`, `"blinn-phong"` (f = kd/π + ks·(e + 8)/(8π)·cosᵉθh, see
    /// `render::bsdf`; kd is `albedo`), `"conductor"` (a rough metal, `render::microfacet`;
    /// `albedo` tints it, as Mitsuba's `specular_reflectance`), `"mirror"` (a smooth
    /// conductor, Mitsuba's `conductor`: a perfect mirror tinted by `albedo`, or with the
    /// Fresnel reflectance of `eta` and `k` when both are given) or `"dielectric"` (smooth
    /// glass or water, Mitsuba's `dielectric`; `albedo` tints reflection and transmission,
    /// [1, 1, 1] for clear glass; see `render::specular`), `"rough-dielectric"` (rough glass,
    /// Mitsuba's `roughdielectric`: `ior`, `distribution` and `alpha` as a conductor's,
    /// `render::rough_dielectric`), `"thin-dielectric"` (a pane of
    /// glass, Mitsuba's `thindielectric`: reflects or lets light through undeviated; `albedo`
    /// tints both), `"plastic"` (smooth plastic, Mitsuba's `plastic`: `albedo` is the diffuse
    /// base's colour under a clear coat, `render::plastic`), `"rough-plastic"` (the same
    /// under a rough coat, Mitsuba's `roughplastic`: `distribution` and a constant `alpha`) or
    /// `"null"` (no surface, only the
    /// boundary of a medium: paths go straight through; it takes no `albedo`).
    #[serde(rename = "type")]
    pub kind: String,
    /// The diffuse colour (kd), or a tint for the other types; every type but `"null"` needs it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub albedo: Option<TextureSpec>,
    /// Blinn-Phong: specular colour ks (kd + ks ≤ 1 conserves energy). Plastic: the tint of
    /// the coat's mirror reflection (default [1, 1, 1]).
    pub specular: Option<[f64; 3]>,
    /// Blinn-Phong only: the exponent e (shininess), > 0.
    pub exponent: Option<f64>,
    /// Conductor, rough dielectric and rough plastic only: `"ggx"` (default) or `"beckmann"`.
    pub distribution: Option<String>,
    /// Conductor, rough dielectric and rough plastic only: roughness α in [0.001, 1] (Mitsuba's `alpha`;
    /// default 0.1), a number
    /// or a texture (`render::texture::Texture::build_roughness`).
    pub alpha: Option<RoughnessSpec>,
    /// Conductor and mirror only: the real and imaginary parts of the complex index of
    /// refraction per channel (conductor default gold's at 650, 550, 450 nm:
    /// η = [0.143, 0.374, 1.442], k = [3.983, 2.385, 1.603]; mirror default none: F = 1).
    pub eta: Option<[f64; 3]>,
    pub k: Option<[f64; 3]>,
    /// Dielectric (smooth, rough, thin) and plastic: index of refraction of the inside (the glass,
    /// the pane, the coat) relative to the outside (the side the surface normal points to), in
    /// [1/4, 4]; default 1.5046 / 1.000277 (Mitsuba's BK7 glass in air), for plastic
    /// 1.49 / 1.000277 (polypropylene).
    pub ior: Option<f64>,
    /// Plastic (smooth or rough) only: the base's colour at every reflection inside the coat, ρ/(1 − ρ·F_dr)
    /// instead of ρ/(1 − F_dr) (Mitsuba's `nonlinear`; default false, see `render::plastic`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nonlinear: Option<bool>,
    /// Emitted radiance (linear RGB), one-sided along the surface normal: makes every shape
    /// with this material an area light.
    pub emission: Option<[f64; 3]>,
    /// `false`: the surface is black seen from behind (the side its normal points away from):
    /// it neither reflects nor lets a path go on there, as Mitsuba's diffuse and conductor
    /// BSDFs without `twosided`. Default `true` (both sides reflect alike). Not for a
    /// dielectric, which has two sides by nature.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub two_sided: Option<bool>,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum ShapeSpec {
    /// An OBJ or PLY file (by extension; `render::obj`, `render::ply`). `material` is used for faces whose `usemtl` names no scene material;
    /// `object_materials` maps OBJ object names (`o`) to scene materials, overriding both.
    Mesh {
        file: String,
        material: Option<String>,
        #[serde(default)]
        object_materials: std::collections::BTreeMap<String, String>,
        #[serde(default)]
        transform: TransformSpec,
        #[serde(default)]
        reverse_orientation: bool,
        /// The media (`[[media]]` by name) inside (behind the surface normal) and outside the
        /// shape, as Mitsuba's `interior` / `exterior`: crossing the surface changes medium.
        /// A shape with neither leaves the medium a path is in as it is.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        interior: Option<String>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        exterior: Option<String>,
    },
    Sphere {
        center: [f64; 3],
        radius: f64,
        material: String,
        #[serde(default)]
        reverse_orientation: bool,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        interior: Option<String>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        exterior: Option<String>,
    },
    /// A torus round its local z axis (`render::surfaces`): `radius` to the tube's centre
    /// line, `tube` the tube's radius, `segments` [round the axis, round the tube]
    /// (default [256, 128]).
    Torus {
        radius: f64,
        tube: f64,
        #[serde(default = "torus_segments")]
        segments: [u32; 2],
        material: String,
        #[serde(default)]
        transform: TransformSpec,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        interior: Option<String>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        exterior: Option<String>,
    },
    /// A sphere displaced along its normal, r = radius·(1 + amplitude·sin(k·x)·sin(k·y)·sin(k·z))
    /// on unit directions (`render::surfaces`); `lobes` is k; `segments` [θ, φ] (default
    /// [128, 256]).
    Blob {
        radius: f64,
        amplitude: f64,
        lobes: f64,
        #[serde(default = "blob_segments")]
        segments: [u32; 2],
        material: String,
        #[serde(default)]
        transform: TransformSpec,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        interior: Option<String>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        exterior: Option<String>,
    },
    /// A height field of bumps and dimples over the square of side `size` in the local z = 0
    /// plane, the tallest `height` high (`render::surfaces`); `segments` cells per side
    /// (default 256).
    Relief {
        size: f64,
        height: f64,
        #[serde(default = "relief_segments")]
        segments: u32,
        material: String,
        #[serde(default)]
        transform: TransformSpec,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        interior: Option<String>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        exterior: Option<String>,
    },
    /// Mitsuba's `cube`: the box [−1, 1]³ through `transform`, each face two triangles with
    /// texture coordinates [0, 1]², facing out.
    Cube {
        material: String,
        #[serde(default)]
        transform: TransformSpec,
        #[serde(default)]
        reverse_orientation: bool,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        interior: Option<String>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        exterior: Option<String>,
    },
    /// Mitsuba's `disk`: the unit disk in the plane z = 0 through `transform`, facing +z, with
    /// texture coordinates (r, φ/2π). Built as a fan of `DISK_SEGMENTS` triangles (its area
    /// within 6.3·10⁻⁶ of the disk's, its rim within 4.7·10⁻⁶ of the radius): an exact disk
    /// would need a primitive of its own in the BVH and light sampling for a difference no
    /// render can show.
    Disk {
        material: String,
        #[serde(default)]
        transform: TransformSpec,
        #[serde(default)]
        reverse_orientation: bool,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        interior: Option<String>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        exterior: Option<String>,
    },
    /// A parallelogram `corner + s·edge_u + t·edge_v`, s, t ∈ [0, 1] (the texture coordinates),
    /// facing edge_u × edge_v.
    Quad {
        corner: [f64; 3],
        edge_u: [f64; 3],
        edge_v: [f64; 3],
        material: String,
        #[serde(default)]
        reverse_orientation: bool,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        interior: Option<String>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        exterior: Option<String>,
    },
}

fn torus_segments() -> [u32; 2] {
    [256, 128]
}
fn blob_segments() -> [u32; 2] {
    [128, 256]
}
fn relief_segments() -> u32 {
    256
}

impl ShapeSpec {
    /// The shape's `interior` and `exterior` media, by name.
    pub fn media(&self) -> (Option<&str>, Option<&str>) {
        match self {
            ShapeSpec::Mesh { interior, exterior, .. }
            | ShapeSpec::Sphere { interior, exterior, .. }
            | ShapeSpec::Torus { interior, exterior, .. }
            | ShapeSpec::Blob { interior, exterior, .. }
            | ShapeSpec::Relief { interior, exterior, .. }
            | ShapeSpec::Cube { interior, exterior, .. }
            | ShapeSpec::Disk { interior, exterior, .. }
            | ShapeSpec::Quad { interior, exterior, .. } => (interior.as_deref(), exterior.as_deref()),
        }
    }
}

/// A homogeneous participating medium (`render::media`): extinction `sigma_t` and single-
/// scattering `albedo`, or absorption `sigma_a` and scattering `sigma_s` (σt = σa + σs,
/// α = σs/σt), each per channel in inverse scene units and multiplied by `scale` (default 1),
/// as Mitsuba's `homogeneous`; `g` is the Henyey–Greenstein asymmetry in (−1, 1) (default 0,
/// isotropic; > 0 scatters forward).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MediumSpec {
    pub name: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_t: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub albedo: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_a: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_s: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub g: Option<f64>,
    /// A heterogeneous medium: a Mitsuba `.vol` grid (relative to the scene file) whose values
    /// multiply σt point by point (1 or 3 channels, trilinear, 0 outside the grid; see
    /// `render::media::grid`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grid: Option<String>,
    /// Where the grid lies: the transform taking its cube [0, 1]³ into the scene (default the
    /// identity), as Mitsuba's `gridvolume` `to_world`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grid_transform: Option<TransformSpec>,
    /// `true`: the grid's cube is first mapped onto the box its file gives (Mitsuba's
    /// `use_grid_bbox`). Default false.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grid_bbox: Option<bool>,
    /// A heterogeneous medium from procedural noise instead of a file (clouds, smoke), over
    /// the cube [0, 1]³ that `grid_transform` places (`render::media::noise`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<NoiseDensitySpec>,
}

/// Fractal value noise as a medium's density (`render::media::noise`).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseDensitySpec {
    pub seed: u64,
    /// Layers of noise, 1 to 8 (default 4), each on a lattice twice as fine as the last.
    #[serde(default = "default_noise_octaves")]
    pub octaves: u32,
    /// Lattice nodes across the cube in the coarsest layer, 1 to 64 (default 4).
    #[serde(default = "default_noise_cells")]
    pub cells: u32,
    /// The noise value below which the air is clear, in [0, 1) (default 0.4).
    #[serde(default = "default_noise_threshold")]
    pub threshold: f64,
    /// Cells per side of the grid the noise is evaluated into, 2 to 512 (default 64).
    #[serde(default = "default_noise_resolution")]
    pub resolution: u32,
}

fn default_noise_octaves() -> u32 {
    4
}
fn default_noise_cells() -> u32 {
    4
}
fn default_noise_threshold() -> f64 {
    0.4
}
fn default_noise_resolution() -> u32 {
    64
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum LightSpec {
    /// Isotropic point light: `intensity` (W/sr) or `power` (W, = 4π·intensity).
    Point { position: [f64; 3], intensity: Option<[f64; 3]>, power: Option<[f64; 3]> },
    /// Distant light from direction `to_light` (towards the light), `irradiance` in W/m² on a
    /// surface facing it.
    Directional { to_light: [f64; 3], irradiance: [f64; 3] },
    /// Light from every direction, what a ray leaving the scene sees: uniform `radiance` in
    /// W/(m²·sr), as Mitsuba's `constant`, or a latitude-longitude `map` (a linear RGB EXR
    /// file, relative to the scene file; y up, see `render::envmap`) times `scale` (default 1),
    /// as Mitsuba's `envmap`; `rotation` (3×3 rows, the map's frame → world, a rotation)
    /// turns the map, as Mitsuba's `to_world`.
    Environment {
        radiance: Option<[f64; 3]>,
        map: Option<String>,
        scale: Option<f64>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        rotation: Option<[[f64; 3]; 3]>,
    },
    /// Spot light at `position` aimed at `target`, as Mitsuba's `spot`: `intensity` (W/sr) on
    /// the axis and out to `beam_width_deg`, falling linearly in angle to 0 at `cutoff_deg`
    /// (defaults 20° and ¾ of the cutoff).
    Spot {
        position: [f64; 3],
        target: [f64; 3],
        intensity: [f64; 3],
        cutoff_deg: Option<f64>,
        beam_width_deg: Option<f64>,
    },
}
