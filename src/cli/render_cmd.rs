//! `lumen render`: render a scene file (lumen's TOML or Mitsuba 3's XML), with its variance,
//! ground-truth AOVs and, with `--denoise`, the denoised image and its inputs.

use super::{parse_threads, scene, write_previews};
use anyhow::{bail, Context, Result};
use lumen::render;
use std::path::{Path, PathBuf};

/// `lumen render`'s flags.
#[derive(clap::Args)]
pub struct RenderArgs {
    /// Scene file: lumen's TOML (e.g. pipelines/scenes/cornell-box.toml) or Mitsuba 3's XML.
    pub scene: PathBuf,
    /// Output image: .exr or .png; truth images and the variance go beside it as
    /// NAME.<aov>.exr.
    #[arg(long)]
    pub out: PathBuf,
    /// Light-transport algorithm (default: the scene's [render] integrator).
    #[arg(long, value_parser = integrator_parser())]
    pub integrator: Option<&'static render::integrators::Kind>,
    /// Samples per pixel (default: the scene's [render] spp; with --time-budget, the most
    /// to render, unbounded by default). For light tracing, passes of one path per pixel.
    #[arg(long)]
    pub spp: Option<u32>,
    /// Render for this many seconds (over 0, at most 10⁷), in rounds of samples, and write
    /// what was reached: the sample count is printed. Each round is planned to fit in what is
    /// left, from the time the rounds before took, and is not cut short.
    #[arg(long, value_name = "SECONDS", value_parser = parse_time_budget)]
    pub time_budget: Option<f64>,
    /// Longest path in segments (default: the scene's max_depth).
    #[arg(long)]
    pub max_depth: Option<u32>,
    /// pm: photons traced in all (default 16 per pixel); sppm: per pass (default one per
    /// pixel). 1 to 10⁸.
    #[arg(long)]
    pub photons: Option<u64>,
    /// pm: the gather radius in scene units (default: the --k nearest photons); sppm: the
    /// initial radius (default: one pixel footprint).
    #[arg(long)]
    pub radius: Option<f32>,
    /// pm: photons per density estimate without a radius (default 50).
    #[arg(long)]
    pub k: Option<u32>,
    /// sppm: the share of new photons a pass keeps, between 0 and 1 (default 2/3).
    #[arg(long)]
    pub alpha: Option<f32>,
    /// pm: Jensen's final gather (direct light sampled, caustics from their map, one bounce
    /// into the global map).
    #[arg(long)]
    pub final_gather: bool,
    /// pm, sppm: how points are found, kdtree or grid (default: the integrator's choice).
    #[arg(long)]
    pub photon_index: Option<render::photons::IndexKind>,
    /// Seed of every random stream (default: the scene's [render] seed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Worker threads, 1 to 1024 (default: all cores).
    #[arg(long, value_parser = parse_threads)]
    pub threads: Option<usize>,
    /// Truth images to write beside the output, comma-separated: depth, normal,
    /// normal_camera, albedo, position, id, or variance (of the mean radiance).
    #[arg(long, value_delimiter = ',')]
    pub aov: Vec<String>,
    /// Also denoise (`lumen denoise`'s feature-guided filter): render the samples as two
    /// halves, trace the albedo, normal and depth of the same camera samples, and write
    /// NAME.denoised.exr beside the image with everything it was made from: NAME.variance.exr,
    /// NAME.half_a.exr, NAME.half_b.exr, NAME.feature_albedo.exr, NAME.feature_normal.exr,
    /// NAME.feature_depth.exr and each feature's .variance.exr. With --time-budget (or 1 spp)
    /// there are no halves: the filter's weights come from the image and its variance.
    #[arg(long)]
    pub denoise: bool,
    /// Also write a PNG preview of every EXR written (as `lumen preview` does).
    #[arg(long)]
    pub preview: bool,
    /// A value for a `$NAME` parameter of a Mitsuba scene (repeatable), as Mitsuba's -D.
    #[arg(short = 'D', long = "define", value_name = "NAME=VALUE", value_parser = scene::parse_define)]
    pub define: Vec<(String, String)>,
}

/// `NAME.ext` → `NAME.<suffix>.exr`.
pub fn sibling(out: &Path, suffix: &str) -> PathBuf {
    let stem = out.file_stem().and_then(|s| s.to_str()).unwrap_or("render");
    out.with_file_name(format!("{stem}.{suffix}.exr"))
}

/// `--time-budget`: seconds over 0, at most 10⁷ (about 16 weeks).
pub fn parse_time_budget(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(t) if t > 0.0 && t <= 1e7 => Ok(t),
        Ok(_) => Err(format!("{s} s: expected a number of seconds over 0 and at most 10⁷")),
        Err(_) => Err(format!("`{s}`: expected a number of seconds")),
    }
}

/// `--integrator`: one of `render::integrators::REGISTRY`'s names, listed in the help.
pub fn integrator_parser() -> impl clap::builder::TypedValueParser<Value = &'static render::integrators::Kind>
{
    use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
    let names = render::integrators::REGISTRY.iter().map(|k| PossibleValue::new(k.name).help(k.about));
    PossibleValuesParser::new(names).try_map(|name| render::integrators::find(&name))
}

pub fn render_cmd(a: &RenderArgs) -> Result<()> {
    let RenderArgs {
        scene: scene_path,
        out,
        integrator,
        spp,
        time_budget,
        max_depth,
        photons,
        radius,
        k,
        alpha,
        final_gather,
        photon_index,
        seed,
        threads,
        aov,
        denoise,
        preview,
        define,
    } = a;
    let (spp, max_depth, seed, threads) = (*spp, *max_depth, *seed, *threads);
    let ext = out.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if ext != "exr" && ext != "png" {
        bail!("--out {}: expected a file name ending in .exr or .png", out.display());
    }
    for a in aov {
        if a != "variance" && !render::truth::AOV_NAMES.contains(&a.as_str()) {
            bail!("--aov {a}: expected one of variance, {}", render::truth::AOV_NAMES.join(", "));
        }
    }
    let scene = scene::load(scene_path, define)?;
    if scene.lights.is_empty() {
        eprintln!(
            "warning: {} has no light (or only black emitters): the image is black",
            scene_path.display()
        );
    }
    let mut settings = render::Settings::from_scene(&scene);
    settings.integrator = integrator.unwrap_or(settings.integrator);
    if let Some(s) = spp {
        if s == 0 {
            bail!("--spp must be at least 1");
        }
        settings.spp = s;
    }
    let p = &mut settings.photon;
    p.count = photons.or(p.count);
    p.radius = radius.or(p.radius);
    p.k = k.unwrap_or(p.k);
    p.alpha = alpha.unwrap_or(p.alpha);
    p.final_gather |= *final_gather;
    p.index = photon_index.or(p.index);
    if let Err(e) = p.validate() {
        bail!("{e} (--photons, --radius, --k, --alpha)");
    }
    if let Some(t) = time_budget {
        settings.time_budget = Some(*t);
        if spp.is_none() {
            settings.spp = u32::MAX;
        }
    }
    if let Some(d) = max_depth {
        if d == 0 {
            bail!("--max-depth must be at least 1");
        }
        settings.max_depth = d;
    }
    settings.seed = seed.unwrap_or(settings.seed);
    settings.threads = threads;
    settings.progress = true;
    // A time budget renders until it is spent: its sample count is not known in advance,
    // so it has no halves (`render::denoised`).
    let (film, halves, denoised, secs) = if *denoise {
        let d = render::denoised::render_denoised(
            &scene,
            &settings,
            &lumen::image::denoise::Settings::default(),
        )?;
        let (secs, filter_secs) = (d.render_seconds, d.feature_seconds + d.filter_seconds);
        (d.film, d.halves, Some((d.output, d.features, filter_secs)), secs)
    } else {
        let t = std::time::Instant::now();
        let film = render::try_render(&scene, &settings)?;
        (film, None, None, t.elapsed().as_secs_f64())
    };
    // Everything this command writes appears together or not at all.
    let dir = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let Some(file_name) = out.file_name() else {
        bail!("--out {}: expected a file name", out.display());
    };
    lumen::image::io::write_together(dir, |staged| -> Result<()> {
        let out = &staged.join(file_name);
        match (&scene.sensor, ext.as_str()) {
            (Some(sensor), "png") => {
                let codes = sensor.expose(&film.mean, settings.seed);
                lumen::image::io::write_png_raw(
                    out,
                    film.mean.width,
                    film.mean.height,
                    3,
                    &codes,
                    sensor.bits,
                )?;
            }
            _ => lumen::image::io::write(out, &film.mean)?,
        }
        let mut written: Vec<PathBuf> = Vec::new();
        if ext == "exr" {
            written.push(out.to_path_buf());
        }
        if let Some((d, features, _)) = &denoised {
            let mut images: Vec<(String, &lumen::image::Image)> = vec![("denoised".into(), &d.image)];
            if let Some([a, b]) = &halves {
                images.push(("half_a".into(), a));
                images.push(("half_b".into(), b));
            }
            for (name, buffer) in features.iter().flat_map(|f| f.named()) {
                images.push((format!("feature_{name}"), &buffer.mean));
                images.push((format!("feature_{name}.variance"), &buffer.variance));
            }
            for (suffix, img) in images {
                let path = sibling(out, &suffix);
                lumen::image::io::write_exr(&path, img)?;
                written.push(path);
            }
        }
        if *denoise || aov.iter().any(|a| a == "variance") {
            let path = sibling(out, "variance");
            lumen::image::io::write_exr(&path, &film.variance)?;
            written.push(path);
        }
        let truth_names: Vec<&String> = aov.iter().filter(|a| *a != "variance").collect();
        if !truth_names.is_empty() {
            let truth = render::truth(&scene, None);
            for name in truth_names {
                if let Some(img) = truth.get(name) {
                    let path = sibling(out, name);
                    lumen::image::io::write_exr(&path, img)?;
                    written.push(path);
                }
            }
            // The camera the truth images were seen through (`render::scene::load_camera`):
            // what `lumen warp` needs beside a depth.
            let camera = sibling(out, "camera").with_extension("json");
            let spec = render::scene::camera_spec(&scene.camera, &scene.t_world_cam);
            let json = serde_json::to_string_pretty(&spec)?;
            lumen::image::io::write_atomically(&camera, |tmp| std::fs::write(tmp, &json))?;
            if aov.iter().any(|a| a == "id") {
                let ids = out.with_file_name(format!(
                    "{}.ids.json",
                    out.file_stem().and_then(|s| s.to_str()).unwrap_or("render")
                ));
                std::fs::write(&ids, serde_json::to_string_pretty(&scene.object_names)?)
                    .with_context(|| format!("cannot write {}", ids.display()))?;
            }
        }
        if *preview {
            write_previews(&written, None)?;
        }
        Ok(())
    })?;
    let paths = film.mean.width as f64 * film.mean.height as f64 * film.samples as f64;
    let budget = match settings.time_budget {
        Some(t) if film.samples < settings.spp => format!(", reached in a time budget of {t} s"),
        Some(t) => format!(", all of them within a time budget of {t} s"),
        None => String::new(),
    };
    eprintln!(
        "rendered {} ({}x{}, {} spp{budget}, max depth {}, integrator {}) in {secs:.2} s: {:.2} M paths/s",
        out.display(),
        film.mean.width,
        film.mean.height,
        film.samples,
        settings.max_depth,
        settings.integrator.name,
        paths / secs / 1e6
    );
    if let Some((d, _, secs)) = &denoised {
        eprintln!("{}", super::denoise::summary(d, *secs, &sibling(out, "denoised")));
    }
    if film.dropped_samples > 0 {
        eprintln!("warning: {} non-finite samples were dropped", film.dropped_samples);
    }
    if *preview {
        eprintln!("wrote a PNG preview beside each EXR");
    }
    Ok(())
}
