//! `lumen denoise`: filter a Monte Carlo render with weights from its own noise
//! (`lumen::image::denoise`).

use anyhow::{bail, Context, Result};
use lumen::image::denoise::{self, Feature, Input, Method, Settings};
use lumen::image::{io, Image};
use std::path::{Path, PathBuf};

/// `lumen denoise`'s flags.
#[derive(clap::Args)]
pub struct DenoiseArgs {
    /// The noisy image (EXR): the mean of each pixel's samples.
    pub image: PathBuf,
    /// Where to write the denoised image (EXR).
    #[arg(long)]
    pub out: PathBuf,
    /// The variance of each pixel's *mean* (not of one sample), per channel, as `lumen render
    /// --aov variance` writes it. For a per-sample variance, add --variance-per-sample SPP.
    #[arg(long)]
    pub variance: Option<PathBuf>,
    /// The --variance image is the variance of one sample; the mean is over SPP samples, so
    /// it is divided by SPP.
    #[arg(long, value_name = "SPP", requires = "variance")]
    pub variance_per_sample: Option<u32>,
    /// Two half buffers, each the mean of half the samples (`lumen render --denoise` writes
    /// NAME.half_a.exr and NAME.half_b.exr): the variance is made robust from their
    /// difference, and each is filtered with the other's weights.
    #[arg(long, num_args = 2, value_names = ["A", "B"])]
    pub halves: Vec<PathBuf>,
    /// Albedo feature buffer.
    #[arg(long)]
    pub albedo: Option<PathBuf>,
    /// Variance of the albedo's pixel means.
    #[arg(long, requires = "albedo")]
    pub albedo_variance: Option<PathBuf>,
    /// Normal feature buffer.
    #[arg(long)]
    pub normal: Option<PathBuf>,
    /// Variance of the normal's pixel means.
    #[arg(long, requires = "normal")]
    pub normal_variance: Option<PathBuf>,
    /// Depth feature buffer.
    #[arg(long)]
    pub depth: Option<PathBuf>,
    /// Variance of the depth's pixel means.
    #[arg(long, requires = "depth")]
    pub depth_variance: Option<PathBuf>,
    /// bilateral, nlmeans or feature (default: feature when a feature buffer is given,
    /// nlmeans otherwise).
    #[arg(long)]
    pub method: Option<Method>,
    /// Patch radius f in pixels, 0 to 10 (default 3; the bilateral filter's is 0).
    #[arg(long)]
    pub patch_radius: Option<u32>,
    /// Window radius r in pixels, 0 to 50 (default 10).
    #[arg(long)]
    pub window_radius: Option<u32>,
    /// Colour sensitivity k: larger smooths more (default 0.45).
    #[arg(long, allow_negative_numbers = true)]
    pub k: Option<f32>,
    /// Feature sensitivity k_f (default 0.6).
    #[arg(long, allow_negative_numbers = true)]
    pub k_feature: Option<f32>,
    /// Strength multipliers of k and k_f tried per pixel and chosen by SURE, comma-separated
    /// (default 0.5,1,2; one value: no choice).
    #[arg(long, value_delimiter = ',')]
    pub strengths: Vec<f32>,
}

pub fn run(a: &DenoiseArgs) -> Result<()> {
    if io_extension(&a.out) != "exr" {
        bail!("--out {}: expected a file name ending in .exr", a.out.display());
    }
    let mut settings = Settings { method: a.method, patch_radius: a.patch_radius, ..Settings::default() };
    settings.window_radius = a.window_radius.unwrap_or(settings.window_radius);
    settings.k = a.k.unwrap_or(settings.k);
    settings.k_feature = a.k_feature.unwrap_or(settings.k_feature);
    if !a.strengths.is_empty() {
        settings.strengths = a.strengths.clone();
    }
    settings.validate().context("--patch-radius, --window-radius, --k, --k-feature, --strengths")?;

    let read = |path: &Path| io::read_exr(path).with_context(|| format!("cannot read {}", path.display()));
    let color = read(&a.image)?;
    let mut variance = a.variance.as_deref().map(read).transpose()?;
    if let (Some(v), Some(spp)) = (variance.as_mut(), a.variance_per_sample) {
        if spp == 0 {
            bail!("--variance-per-sample 0: expected the number of samples per pixel, at least 1");
        }
        for x in &mut v.data {
            *x /= spp as f32;
        }
    }
    let halves: Vec<Image> = a.halves.iter().map(|p| read(p)).collect::<Result<_>>()?;
    let mut buffers: Vec<(&str, Image, Option<Image>)> = Vec::new();
    for (name, image, var) in [
        ("--albedo", &a.albedo, &a.albedo_variance),
        ("--normal", &a.normal, &a.normal_variance),
        ("--depth", &a.depth, &a.depth_variance),
    ] {
        if let Some(path) = image {
            buffers.push((name, read(path)?, var.as_deref().map(read).transpose()?));
        }
    }
    let features = buffers
        .iter()
        .map(|(name, image, var)| Feature { name: name.to_string(), image, variance: var.as_ref() })
        .collect();
    let input = Input {
        color: &color,
        variance: variance.as_ref(),
        halves: match halves.as_slice() {
            [x, y] => Some([x, y]),
            _ => None,
        },
        features,
    };
    let t = std::time::Instant::now();
    let out = denoise::denoise(&input, &settings)
        .with_context(|| format!("cannot denoise {}", a.image.display()))?;
    let secs = t.elapsed().as_secs_f64();
    io::write_exr(&a.out, &out.image)?;
    eprintln!("{}", summary(&out, secs, &a.out));
    Ok(())
}

/// One line on what the denoiser did.
pub fn summary(out: &denoise::Output, secs: f64, path: &Path) -> String {
    let shares: Vec<String> =
        out.strengths.iter().zip(&out.chosen).map(|(s, c)| format!("{s}: {:.0} %", 100.0 * c)).collect();
    let mp = out.image.width as f64 * out.image.height as f64 / 1e6;
    format!(
        "denoised {} ({}×{}, {}{}) in {secs:.2} s ({:.2} s per megapixel); strengths chosen by SURE: {}{}",
        path.display(),
        out.image.width,
        out.image.height,
        out.method,
        if out.halves { ", half buffers cross-filtered" } else { "" },
        secs / mp.max(1e-12),
        shares.join(", "),
        if out.unchanged {
            "; the variance is 0 everywhere: the image is unchanged".to_string()
        } else {
            String::new()
        }
    )
}

fn io_extension(path: &Path) -> String {
    path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase()
}
