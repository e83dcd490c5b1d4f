//! `lumen surface`: a closed mesh from a point cloud (`lumen::surface`).

use anyhow::{Context, Result};
use lumen::surface::{self, Config, Input, Method};
use std::path::PathBuf;

/// `lumen surface`'s flags.
#[derive(clap::Args)]
pub struct SurfaceArgs {
    /// Point cloud: PLY (ASCII or binary), vertices x y z with optional nx ny nz, such as
    /// `lumen sfm`'s points.ply; or OBJ, its vertices (such as `lumen ps`'s surface.obj, the
    /// depth its normals integrate to). Faces, if any, are ignored.
    #[arg(long)]
    pub points: PathBuf,
    /// The mesh: binary PLY. A summary (points, radius, vertices, triangles, watertight,
    /// components, genus, time) goes beside it as NAME.json.
    #[arg(long)]
    pub out: PathBuf,
    /// apss (algebraic spheres, Guennebaud & Gross 2007) or mls (a plane and a quadratic
    /// height field, Alexa et al. 2003).
    #[arg(long, default_value = "apss")]
    pub method: String,
    /// The fits' radius in the points' units (default: per point, 2.5 × the distance to its
    /// 8th nearest neighbour).
    #[arg(long)]
    pub radius: Option<f64>,
    /// Grid cells across the points' longest extent, 8 to 1024.
    #[arg(long, default_value_t = 128)]
    pub resolution: usize,
}

pub fn run(a: &SurfaceArgs) -> Result<()> {
    let method: Method =
        a.method.parse().map_err(|e: lumen::error::Invalid| anyhow::Error::new(e).context("--method"))?;
    let is_obj = a.points.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj"));
    let cloud =
        if is_obj { lumen::render::obj::read(&a.points)? } else { lumen::render::ply::read(&a.points)? };
    let input = Input { points: cloud.positions, normals: cloud.normals };
    let config = Config { method, radius: a.radius, resolution: a.resolution, ..Config::default() };
    let out = surface::run(&input, &config).with_context(|| a.points.display().to_string())?;
    let summary_path = a.out.with_extension("json");
    let json = serde_json::to_string_pretty(&out.summary)?;
    surface::write_ply(&a.out, &out.mesh)?;
    // The two go together: without its summary the mesh is removed again.
    if let Err(e) = lumen::image::io::write_atomically(&summary_path, |tmp| std::fs::write(tmp, &json)) {
        let _ = std::fs::remove_file(&a.out);
        return Err(e.into());
    }
    let s = &out.summary;
    eprintln!(
        "{}: {} points ({}), radius {:.4}: {} vertices, {} triangles, {}, {} component(s){} in {:.2} s; wrote {} and {}",
        a.points.display(),
        s.points,
        if s.normals_estimated { "normals estimated" } else { "normals given" },
        s.radius,
        s.vertices,
        s.triangles,
        if s.watertight { "watertight" } else { "open" },
        s.components,
        s.genus.map_or(String::new(), |g| format!(", genus {g}")),
        s.seconds,
        a.out.display(),
        summary_path.display()
    );
    Ok(())
}
