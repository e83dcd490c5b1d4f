//! `lumen texture`: a texture for a mesh from photographs with known cameras
//! (`lumen::ibr::texture`).

use anyhow::{bail, Context, Result};
use lumen::ibr::texture::{self, Config, Photo};
use lumen::ibr::View;
use lumen::image::io;
use lumen::surface::march::Mesh;
use std::path::{Path, PathBuf};

/// `lumen texture`'s flags.
#[derive(clap::Args)]
pub struct TextureArgs {
    /// The mesh: OBJ or PLY (ASCII or binary) with faces, such as `lumen surface`'s output, in
    /// the cameras' frame and units.
    #[arg(long)]
    pub mesh: PathBuf,
    /// The cameras: a COLMAP text model folder (cameras.txt, images.txt), lumen's (`lumen
    /// sfm`) or COLMAP's.
    #[arg(long)]
    pub model: PathBuf,
    /// The folder of the photographs images.txt names.
    #[arg(long)]
    pub images: PathBuf,
    /// Output folder: mesh.obj with mesh.mtl, texture.png (and texture.exr from EXR
    /// photographs, linear), summary.json.
    #[arg(long)]
    pub out: PathBuf,
    /// Texels per side of the square texture, 64 to 16384.
    #[arg(long, default_value_t = 1024)]
    pub size: u32,
    /// λ, the smoothness weight against a data weight of 1.
    #[arg(long, default_value_t = 0.02)]
    pub smoothness: f64,
    /// Keep each photograph's exposure and white balance as they are (no gains fitted).
    #[arg(long)]
    pub no_equalise: bool,
}

fn read_mesh(path: &Path) -> Result<Mesh> {
    let is_obj = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj"));
    let m = if is_obj { lumen::render::obj::read(path)? } else { lumen::render::ply::read(path)? };
    if m.triangles.is_empty() {
        bail!(
            "{}: {} vertices and no faces: expected a mesh with triangles",
            path.display(),
            m.positions.len()
        );
    }
    Ok(Mesh { vertices: m.positions, triangles: m.triangles.iter().map(|t| t.v).collect() })
}

pub fn run(a: &TextureArgs) -> Result<()> {
    let mesh = read_mesh(&a.mesh)?;
    let model = lumen::sfm::colmap::read_text_model(&a.model)?;
    let mut images = Vec::new();
    for m in &model {
        let path = a.images.join(&m.name);
        let img = io::read(&path)
            .with_context(|| format!("{} names {}", a.model.join("images.txt").display(), m.name))?;
        images.push((path, img));
    }
    let linear = images.iter().all(|(p, _)| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr")));
    let photos: Vec<Photo> = model
        .iter()
        .zip(&images)
        .map(|(m, (path, img))| Photo {
            name: path.display().to_string(),
            image: img,
            view: View { camera: m.camera, t_world_cam: m.t_cam_world.inverse() },
        })
        .collect();
    let config =
        Config { size: a.size, smoothness: a.smoothness, equalise: !a.no_equalise, ..Config::default() };
    let out = texture::run(&mesh, &photos, &config).with_context(|| a.mesh.display().to_string())?;
    let json = serde_json::to_string_pretty(&out.summary)?;
    io::write_together(&a.out, |dir: &Path| -> Result<()> {
        std::fs::write(dir.join("mesh.obj"), texture::obj_text(&mesh, &out.atlas, "mesh.mtl"))?;
        std::fs::write(dir.join("mesh.mtl"), texture::mtl_text("texture.png"))?;
        if linear {
            io::write_exr(&dir.join("texture.exr"), &out.texture)?;
            io::write_png_srgb(&dir.join("texture.png"), &out.texture)?;
        } else {
            // PNG and JPEG photographs were read as code values: written back as such.
            io::write_png_codes(&dir.join("texture.png"), &out.texture)?;
        }
        std::fs::write(dir.join("summary.json"), &json)?;
        Ok(())
    })?;
    let s = &out.summary;
    eprintln!(
        "{}: {} triangles in {} charts, {}² texels ({:.1} per unit), {:.1} % of the surface seen by {} photographs, in {:.2} s; wrote {}",
        a.mesh.display(),
        s.triangles,
        s.charts,
        s.size,
        s.texels_per_unit,
        100.0 * s.seen_fraction,
        s.photos.len(),
        s.seconds,
        a.out.display()
    );
    Ok(())
}
