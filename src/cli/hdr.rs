//! `lumen hdr`: recover a camera's response from an exposure stack and merge the radiance.

use anyhow::{bail, Context, Result};
use lumen::hdr::{self, input, merge, response, Method};
use lumen::image::{self, Image};
use std::path::{Path, PathBuf};

/// `lumen hdr`'s flags.
#[derive(clap::Args)]
pub struct HdrArgs {
    /// The frames: 8- or 16-bit PNG, TIFF or JPEG, all the same size.
    #[arg(long, num_args = 1..)]
    pub images: Vec<PathBuf>,
    /// Exposure time of each image in seconds, in the same order: 1/30, 0.5 or 6.1035e-05.
    #[arg(long, num_args = 1.., allow_negative_numbers = true)]
    pub times: Vec<String>,
    /// Instead of --images and --times: a file with a name and a time per line (names
    /// relative to the file's folder).
    #[arg(long)]
    pub list: Option<PathBuf>,
    /// debevec, robertson, or a response.csv to use as it is.
    #[arg(long, default_value = "debevec")]
    pub response: String,
    /// Debevec's smoothness weight λ (10⁴ suits the usual bracket of equal exposure
    /// ratios; a stack with unequal ratios and little noise fits better with 10 to 100).
    #[arg(long, default_value_t = lumen::hdr::DEFAULT_LAMBDA)]
    pub lambda: f64,
    /// Debevec's sample pixels per pixel value (chosen to cover every value, nearest the
    /// image centre first).
    #[arg(long, default_value_t = lumen::hdr::DEFAULT_SAMPLES_PER_VALUE)]
    pub samples_per_value: usize,
    /// Debevec's smoothness term: logit (g″ in ln(z/(N − z)), nearly straight for power
    /// laws, toes and shoulders) or even (g″ in z, as the paper and OpenCV).
    #[arg(long, default_value = "logit")]
    pub smoothness: String,
    /// noise (inverse variance under photon, read and quantisation noise, with the full
    /// well and read noise the stack itself shows, or --full-well and --read-noise),
    /// noise-from-stack (the stack's own, even with --full-well) or hat (Debevec & Malik's).
    #[arg(long, default_value = "noise")]
    pub weights: String,
    /// For --weights noise: the sensor's electrons at full scale, instead of the stack's
    /// estimate.
    #[arg(long)]
    pub full_well: Option<f64>,
    /// For --weights noise with --full-well: the sensor's read noise in electrons.
    #[arg(long, default_value_t = 0.0)]
    pub read_noise: f64,
    /// Leave pixels of this colour (R,G,B code values) in any frame out of the response
    /// fit, e.g. 0,0,255 for registration borders.
    #[arg(long)]
    pub exclude_color: Option<String>,
    /// Also write fusion.png: Mertens et al.'s exposure fusion, an LDR picture blended from
    /// the frames (no response, no radiance), in the frames' own encoding.
    #[arg(long)]
    pub fusion: bool,
    /// Output radiance (.exr); response.csv, response.svg, mask.png, preview.png and
    /// summary.json (and fusion.png with --fusion) go beside it.
    #[arg(long)]
    pub out: PathBuf,
}

/// `--exclude-color R,G,B`: three code values.
pub fn parse_color(s: &str) -> Result<[u16; 3]> {
    let v: Option<Vec<u16>> = s.split(',').map(|x| x.trim().parse::<u16>().ok()).collect();
    v.and_then(|v| <[u16; 3]>::try_from(v).ok())
        .ok_or_else(|| anyhow::anyhow!("--exclude-color {s}: expected three code values R,G,B"))
}

/// The frames and their times from `--images`/`--times` or `--list` (a name and a time per
/// line, names relative to the list's folder, `#` comments).
fn stack(a: &HdrArgs) -> Result<Vec<(PathBuf, f64)>> {
    match &a.list {
        Some(list) => {
            if !a.images.is_empty() || !a.times.is_empty() {
                bail!("give --list, or --images with --times, not both");
            }
            Ok(input::read_list(list)?)
        }
        None => {
            if a.images.len() != a.times.len() {
                bail!(
                    "{} image(s) but {} exposure time(s): give one time per image, in the same order",
                    a.images.len(),
                    a.times.len()
                );
            }
            let times: Vec<f64> = a
                .times
                .iter()
                .map(|t| input::parse_time(t))
                .collect::<Result<_, _>>()
                .map_err(anyhow::Error::msg)?;
            Ok(a.images.iter().cloned().zip(times).collect())
        }
    }
}

pub fn run(a: &HdrArgs) -> Result<()> {
    if a.out.extension().and_then(|e| e.to_str()).map(str::to_lowercase).as_deref() != Some("exr") {
        bail!("--out {}: the radiance is written as .exr", a.out.display());
    }
    let frames_in = stack(a)?;
    let weights = a
        .weights
        .parse::<hdr::WeightsName>()
        .and_then(|w| w.resolve(a.full_well, a.read_noise))
        .map_err(|e| anyhow::Error::new(e).context("--weights, --full-well, --read-noise"))?;
    let smoothness: response::Smoothness =
        a.smoothness.parse().map_err(|e: lumen::error::Invalid| anyhow::anyhow!("--{e}"))?;
    if !(a.lambda.is_finite() && (0.0..=hdr::MAX_LAMBDA).contains(&a.lambda)) {
        bail!("--lambda {:e}: expected 0 to {:e}", a.lambda, hdr::MAX_LAMBDA);
    }
    if !(1..=hdr::MAX_SAMPLES_PER_VALUE).contains(&a.samples_per_value) {
        bail!("--samples-per-value {}: expected 1 to {}", a.samples_per_value, hdr::MAX_SAMPLES_PER_VALUE);
    }
    let exclude = a.exclude_color.as_deref().map(parse_color).transpose()?;
    let t = std::time::Instant::now();
    let input = input::read_stack(&frames_in, exclude)?;
    let read_s = t.elapsed().as_secs_f64();
    let (w, h) = (input.width as u32, input.height as u32);
    let method = match a.response.parse::<hdr::Fit>() {
        Ok(fit) => fit.method(a.lambda, a.samples_per_value, smoothness),
        Err(_) => {
            let file = a.response.as_str();
            let text = std::fs::read_to_string(file)
                .with_context(|| format!("--response {file}: not debevec, robertson or a readable file"))?;
            Method::Given(response::from_csv(&text).map_err(|m| anyhow::anyhow!("--response {file}: {m}"))?)
        }
    };
    let fusion = a.fusion.then(hdr::fusion::Mertens::default);
    let out = hdr::run(&input, &hdr::Config { method, weights, fusion })?;

    // Everything written together: on an error none of it is left beside --out.
    let target = a.out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let Some(file_name) = a.out.file_name() else { bail!("--out {}: expected a file name", a.out.display()) };
    image::io::write_together(target, |dir| -> Result<()> {
        let exr = dir.join(file_name);
        let radiance = Image { width: w, height: h, channels: 3, data: out.radiance.clone() };
        image::io::write_exr(&exr, &radiance)?;
        let write = |name: &str, bytes: Vec<u8>| -> Result<()> {
            let p = dir.join(name);
            image::io::write_atomically(&p, |tmp| std::fs::write(tmp, &bytes))?;
            Ok(())
        };
        write("response.csv", response::to_csv(&out.response).into_bytes())?;
        write(
            "response.svg",
            response::plot_svg(&out.response, &format!("response ({})", out.summary.method)).into_bytes(),
        )?;
        let mut mask = Image::new(w, h, 3);
        for (i, m) in out.mask.iter().enumerate() {
            let v: [f32; 3] = match *m {
                merge::SATURATED => [1.0, 0.0, 0.0],
                merge::DARK => [0.0, 0.0, 1.0],
                _ => [0.0, 0.0, 0.0],
            };
            mask.data[3 * i..3 * i + 3].copy_from_slice(&v);
        }
        image::io::write_png_srgb(&dir.join("mask.png"), &mask)?;
        image::io::write_png_srgb(&dir.join("preview.png"), &hdr::tonemap::reinhard(&radiance))?;
        if let Some(f) = &out.fusion {
            // Already in the frames' encoding: written as it is, not sRGB-encoded again.
            let codes: Vec<u16> = f.iter().map(|v| (v * 255.0 + 0.5) as u16).collect();
            image::io::write_png_raw(&dir.join("fusion.png"), w, h, 3, &codes, 8)?;
        }
        write("summary.json", serde_json::to_string_pretty(&out.summary)?.into_bytes())?;
        Ok(())
    })?;
    let s = &out.summary;
    eprintln!(
        "{} frames {w}×{h} ({} levels): response by {} in {:.3} s ({} samples), weights {}, merged in {:.3} s ({:.0} Mpixel-frames/s); {:.1} stops well exposed; {} pixels saturated in every frame (lower bounds), {} dark in every frame (upper bounds); read {read_s:.2} s; wrote {} and response.csv, response.svg, mask.png (red: saturated, blue: dark), preview.png, summary.json{} beside it",
        s.frames,
        s.levels,
        s.method,
        s.response_s,
        s.samples,
        s.weights,
        s.merge_s,
        s.merge_megapixel_frames_per_s,
        s.dynamic_range_stops,
        s.saturated_pixels,
        s.dark_pixels,
        a.out.display(),
        if out.fusion.is_some() { format!(", fusion.png (in {:.2} s)", s.fusion_s) } else { String::new() }
    );
    Ok(())
}
