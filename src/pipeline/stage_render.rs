//! The `render` stage: renders a scene and checks the image against what is known of it —
//! a reference render with its variance (Mitsuba 3's Cornell box), or a closed-form uniform
//! radiance (the furnace).
//!
//! Metrics:
//! - `mean_rel_err_{r,g,b}`: |mean of render − mean of reference| / mean of reference;
//! - `z_test_pass_fraction`: pixel channels passing the per-pixel z-test against the reference
//!   (Šidák-corrected, α = 0.01; see `image::metrics::agreement`);
//! - `max_rel_err`, `mean_rel_err`: against a uniform expected radiance;
//! - `nonfinite_samples`: samples that came out NaN or infinite (must be 0);
//! - `mpaths_per_s`: million camera paths per second (no bound: speed is for benchmarks).

use super::report::{Better, Metric};
use super::{Common, RunOptions, StageOutput};

impl RenderStage {
    pub fn common(&self) -> Common {
        Common {
            case: self.case.clone(),
            seed: self.seed,
            bounds: self.bounds.clone(),
            expected_miss: self.expected_miss.clone(),
        }
    }
}
use crate::image::{io, metrics};
use crate::render;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderStage {
    /// The case's name in the report.
    pub case: String,
    /// Seed (default: the pipeline's).
    pub seed: Option<u64>,
    /// Bound per metric name (see the module docs for the metrics).
    #[serde(default)]
    pub bounds: BTreeMap<String, f64>,
    /// Metric name → why its bound is not met yet.
    #[serde(default)]
    pub expected_miss: BTreeMap<String, String>,
    /// Scene file, relative to the pipeline file.
    pub scene: String,
    /// Samples per pixel (default: the scene's).
    pub spp: Option<u32>,
    /// Longest path in segments (default: the scene's).
    pub max_depth: Option<u32>,
    /// Reference render (EXR) and the variance of its mean (EXR), relative to the pipeline
    /// file. When the files are absent the comparison is skipped with a note.
    pub reference: Option<String>,
    pub reference_variance: Option<String>,
    /// Closed-form radiance every pixel must have (linear RGB).
    pub expect_uniform: Option<[f64; 3]>,
    /// File name (.exr or .png) to save the rendered image under, in the output folder.
    pub save: Option<String>,
}

pub fn run(s: &RenderStage, dir: &Path, seed: u64, opts: &RunOptions) -> Result<StageOutput, String> {
    let scene = render::load(&dir.join(&s.scene)).map_err(|e| e.to_string())?;
    let mut settings = render::Settings::from_scene(&scene);
    settings.seed = seed;
    settings.threads = opts.threads;
    settings.progress = opts.progress;
    if let Some(n) = s.spp {
        settings.spp = n.max(1);
    }
    if let Some(d) = s.max_depth {
        settings.max_depth = d.max(1);
    }
    let mut timings = BTreeMap::new();
    let mut notes = Vec::new();
    let t = std::time::Instant::now();
    let film = render::render(&scene, &settings);
    let secs = t.elapsed().as_secs_f64();
    timings.insert("render".into(), secs);
    let paths = film.mean.width as f64 * film.mean.height as f64 * settings.spp as f64;
    let mut m = vec![
        Metric::new("nonfinite_samples", film.dropped_samples as f64, "samples", Better::Lower),
        Metric::new("mpaths_per_s", paths / secs / 1e6, "M/s", Better::Higher),
    ];
    notes.push(format!(
        "{}x{} pixels, {} spp, max depth {}.",
        film.mean.width, film.mean.height, settings.spp, settings.max_depth
    ));

    match (&s.reference, &s.reference_variance) {
        (Some(r), Some(rv)) => {
            let (rp, rvp) = (dir.join(r), dir.join(rv));
            if rp.exists() && rvp.exists() {
                let t = std::time::Instant::now();
                let reference = io::read_exr(&rp).map_err(|e| e.to_string())?;
                let ref_var = io::read_exr(&rvp).map_err(|e| e.to_string())?;
                let a = metrics::agreement(&film.mean, &film.variance, &reference, &ref_var, 0.01)
                    .map_err(|e| format!("reference {}: {e}", rp.display()))?;
                for (c, name) in ["r", "g", "b"].iter().enumerate() {
                    m.push(Metric::new(
                        &format!("mean_rel_err_{name}"),
                        a.mean_rel_err[c].abs(),
                        "",
                        Better::Lower,
                    ));
                }
                m.push(Metric::new("z_test_pass_fraction", a.pass_fraction, "", Better::Higher));
                notes.push(format!(
                    "z-test against {}: {} of {} pixel channels beyond |z| = {:.2} (Šidák α = {:.2e}).",
                    rp.display(),
                    a.failed,
                    a.tested,
                    a.z_critical,
                    a.alpha_sidak
                ));
                timings.insert("compare".into(), t.elapsed().as_secs_f64());
            } else {
                notes.push(format!("reference {} not found: comparison skipped.", rp.display()));
            }
        }
        (None, None) => {}
        _ => return Err("give both `reference` and `reference_variance`, or neither".into()),
    }
    if let Some(e) = s.expect_uniform {
        let mut max_rel = 0.0f64;
        let mut sum_rel = 0.0f64;
        for px in film.mean.data.chunks_exact(3) {
            for c in 0..3 {
                let rel = (px[c] as f64 - e[c]).abs() / e[c].abs().max(1e-30);
                max_rel = max_rel.max(rel);
                sum_rel += rel;
            }
        }
        m.push(Metric::new("max_rel_err", max_rel, "", Better::Lower));
        m.push(Metric::new("mean_rel_err", sum_rel / film.mean.data.len().max(1) as f64, "", Better::Lower));
    }
    if let Some(name) = &s.save {
        let path = opts.out_dir.join(name);
        io::write(&path, &film.mean).map_err(|e| e.to_string())?;
        notes.push(format!("image saved as {}.", path.display()));
    }
    Ok(StageOutput { metrics: m, timings_s: timings, notes })
}
