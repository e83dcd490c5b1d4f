//! `lumen scene convert`: a Mitsuba 3 scene written out as the lumen scene file it reads as.

use anyhow::{bail, Context, Result};
use lumen::render;
use std::path::{Path, PathBuf};

/// `lumen scene`'s subcommands.
#[derive(clap::Subcommand)]
pub enum SceneCmd {
    /// Write the lumen scene (TOML) a Mitsuba 3 XML scene reads as, so what was read can be
    /// seen and edited; the scene is built first, so a scene that would not render is refused.
    Convert {
        /// Mitsuba 3 scene (.xml).
        scene: PathBuf,
        /// The lumen scene file to write (.toml).
        #[arg(long)]
        out: PathBuf,
        /// A value for a `$NAME` parameter of the scene (repeatable), as Mitsuba's -D.
        #[arg(short = 'D', long = "define", value_name = "NAME=VALUE", value_parser = parse_define)]
        define: Vec<(String, String)>,
    },
}

/// `NAME=VALUE`, as Mitsuba's `-D`.
pub fn parse_define(s: &str) -> Result<(String, String), String> {
    match s.split_once('=') {
        Some((n, v)) if !n.is_empty() && n.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') => {
            Ok((n.to_string(), v.to_string()))
        }
        _ => Err(format!("\"{s}\": expected NAME=VALUE, NAME of letters, digits and _")),
    }
}

/// Reads a scene: Mitsuba XML with its `-D` values, or lumen's TOML (which takes none).
pub fn load(path: &Path, define: &[(String, String)]) -> Result<render::Scene> {
    if render::scene::mitsuba::is_mitsuba(path) {
        return Ok(render::scene::load_mitsuba(path, define)?);
    }
    if let Some((n, _)) = define.first() {
        bail!("-D {n}=…: parameters belong to Mitsuba scenes (.xml); {} is a lumen scene", path.display());
    }
    Ok(render::load(path)?)
}

pub fn run(cmd: SceneCmd) -> Result<()> {
    match cmd {
        SceneCmd::Convert { scene, out, define } => convert(&scene, &out, &define),
    }
}

fn convert(scene: &Path, out: &Path, define: &[(String, String)]) -> Result<()> {
    if !render::scene::mitsuba::is_mitsuba(scene) {
        bail!("{}: expected a Mitsuba 3 scene (.xml); a lumen scene needs no converting", scene.display());
    }
    if out.extension().is_none_or(|e| e != "toml") {
        bail!("--out {}: expected a file name ending in .toml", out.display());
    }
    let mut read = render::scene::mitsuba::read(scene, define)?;
    // Built as `lumen render` would build it: a scene that cannot render is not written.
    render::scene::load_mitsuba(scene, define)?;
    let from = scene.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let to = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let same_dir = from.canonicalize().ok().zip(to.canonicalize().ok()).is_some_and(|(a, b)| a == b);
    if !same_dir {
        // Paths in the scene are relative to the XML's folder: written out absolute.
        read.scene.rebase(&std::path::absolute(from)?);
    }
    let text = toml::to_string(&read.scene).context("writing the scene as TOML")?;
    let header =
        format!("# lumen's reading of the Mitsuba 3 scene {} (lumen scene convert).\n\n", scene.display());
    // Written whole or not at all: a partial file is renamed into place.
    let partial = out.with_extension("toml.partial");
    std::fs::write(&partial, format!("{header}{text}"))
        .with_context(|| format!("writing {}", partial.display()))?;
    std::fs::rename(&partial, out).with_context(|| format!("writing {}", out.display()))?;
    eprintln!("wrote {}", out.display());
    Ok(())
}
