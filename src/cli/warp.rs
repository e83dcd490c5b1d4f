//! `lumen warp`: a new view from views with depth (`lumen::ibr::warp`).

use anyhow::{bail, Context, Result};
use lumen::ibr::warp::{self, Config, Mode};
use lumen::ibr::{Source, View};
use lumen::image::{io, Image};
use std::path::{Path, PathBuf};

/// `lumen warp`'s flags.
#[derive(clap::Args)]
pub struct WarpArgs {
    /// A source view's colour (EXR, or PNG/JPEG as code values). Repeat --image, --depth and
    /// --camera together for several sources: they are blended by visibility and angle.
    #[arg(long, required = true)]
    pub image: Vec<PathBuf>,
    /// The source's depth (EXR, one channel): camera-frame z per pixel, 0 where nothing was
    /// seen, as `lumen render --aov depth` writes NAME.depth.exr.
    #[arg(long, required = true)]
    pub depth: Vec<PathBuf>,
    /// The source's camera: a scene file's `[camera]` table on its own (JSON or TOML; `lumen
    /// render --aov depth` writes NAME.camera.json), or a scene file (its camera).
    #[arg(long, required = true)]
    pub camera: Vec<PathBuf>,
    /// The new view's camera, in the same form.
    #[arg(long)]
    pub to: PathBuf,
    /// The new view (EXR, or PNG). Beside it: NAME.mask.png (white where a source is seen,
    /// black in the holes) and NAME.json (sources, mode, hole fraction, time).
    #[arg(long)]
    pub out: PathBuf,
    /// forward (splat the colours through a z-buffer) or backward (splat and filter the
    /// depth, then look the colours up in the sources).
    #[arg(long, default_value = "backward")]
    pub mode: String,
    /// Backward mapping: the relative depth difference under which two depths are one surface.
    #[arg(long, default_value_t = 0.02)]
    pub depth_tolerance: f64,
}

#[derive(serde::Serialize)]
struct Summary {
    sources: Vec<String>,
    target: String,
    mode: String,
    width: u32,
    height: u32,
    hole_fraction: f64,
    seconds: f64,
    /// Source pixels warped per second, in millions.
    source_megapixels_per_second: f64,
}

fn view(path: &Path) -> Result<View> {
    let (camera, t_world_cam) = lumen::render::scene::load_camera(path)?;
    Ok(View { camera, t_world_cam })
}

pub fn run(a: &WarpArgs) -> Result<()> {
    let mode: Mode =
        a.mode.parse().map_err(|e: lumen::error::Invalid| anyhow::Error::new(e).context("--mode"))?;
    if a.image.len() != a.depth.len() || a.image.len() != a.camera.len() {
        bail!(
            "{} --image, {} --depth and {} --camera: expected one of each per source view",
            a.image.len(),
            a.depth.len(),
            a.camera.len()
        );
    }
    let out_ext = a.out.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if out_ext != "exr" && out_ext != "png" {
        bail!("--out {}: expected a .exr or .png file", a.out.display());
    }
    let mut read = Vec::new();
    for ((image, depth), camera) in a.image.iter().zip(&a.depth).zip(&a.camera) {
        let img = io::read(image)?;
        let d = io::read(depth)?;
        let v = view(camera)?;
        let linear = image.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr"));
        let name = format!("source {} ({}, depth {})", read.len() + 1, image.display(), depth.display());
        read.push((name, img, d, v, linear));
    }
    let target = view(&a.to)?;
    let sources: Vec<Source> = read
        .iter()
        .map(|(name, image, depth, view, _)| Source { name: name.clone(), image, depth, view: *view })
        .collect();
    let config = Config { mode, depth_tolerance: a.depth_tolerance, ..Config::default() };
    let start = std::time::Instant::now();
    let out = warp::warp(&sources, &target, &config)?;
    let seconds = start.elapsed().as_secs_f64();
    let source_pixels: f64 = sources.iter().map(|s| s.depth.data.len() as f64).sum();
    let summary = Summary {
        sources: a.image.iter().map(|p| p.display().to_string()).collect(),
        target: a.to.display().to_string(),
        mode: a.mode.clone(),
        width: out.image.width,
        height: out.image.height,
        hole_fraction: out.hole_fraction,
        seconds,
        source_megapixels_per_second: source_pixels / seconds.max(1e-9) / 1e6,
    };
    let all_linear = read.iter().all(|r| r.4);
    let name = a.out.file_stem().and_then(|s| s.to_str()).unwrap_or("warp").to_string();
    let file = a.out.file_name().and_then(|s| s.to_str()).unwrap_or("warp.exr").to_string();
    let dir = a.out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new(".")).to_path_buf();
    let json = serde_json::to_string_pretty(&summary)?;
    io::write_together(&dir, |stage: &Path| -> Result<()> {
        write_image(&stage.join(&file), &out.image, all_linear)?;
        // The mask holds 0 or 1: black and white.
        io::write_png_codes(&stage.join(format!("{name}.mask.png")), &out.mask)?;
        std::fs::write(stage.join(format!("{name}.json")), &json).context("cannot write the summary")?;
        Ok(())
    })?;
    eprintln!(
        "warped {} source view(s) to {} ({}×{}, {}): {:.1} % holes, {:.3} s ({:.0} source Mpx/s); wrote {}, {name}.mask.png and {name}.json",
        sources.len(),
        a.to.display(),
        out.image.width,
        out.image.height,
        a.mode,
        100.0 * out.hole_fraction,
        seconds,
        summary.source_megapixels_per_second,
        a.out.display()
    );
    Ok(())
}

/// EXR as is; PNG sRGB-encoded from linear sources, or as the code values PNG and JPEG
/// sources were read as.
fn write_image(path: &Path, img: &Image, linear: bool) -> Result<()> {
    let is_png = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if !is_png || linear {
        return Ok(io::write(path, img)?);
    }
    Ok(io::write_png_codes(path, img)?)
}
