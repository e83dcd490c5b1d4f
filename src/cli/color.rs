//! `lumen color`: fit a colour-correction model to a chart photograph, apply it to images,
//! and compute a chart's camera RGB and XYZ from spectra.

use anyhow::{bail, Context, Result};
use clap::Subcommand;
use lumen::color::{self, spectra, CcmFile, Input, PatchInput};
use lumen::image::{self, Image};
use std::path::{Path, PathBuf};

#[derive(Subcommand)]
pub enum Color {
    /// Fit a model mapping camera RGB to XYZ from a photograph of a ColorChecker 24 (or from
    /// patch values in a CSV); writes the model and its report (per-patch ΔE2000, mean, max,
    /// leave-one-out mean) as JSON.
    Fit(FitArgs),
    /// Find a ColorChecker Classic 24 in a photograph by itself: writes the four outer corners
    /// of its 6×4 cell grid (in --corners's order: corner 0 by patch 1 "dark skin"), the 24
    /// patches' values sampled as `color fit` samples them, and a confidence, as JSON.
    Detect(DetectArgs),
    /// Apply a fitted model to an image: camera RGB to linear sRGB (D65, Bradford-adapted
    /// from the model's white) or to XYZ.
    Apply {
        /// JSON written by `lumen color fit`.
        #[arg(long)]
        ccm: PathBuf,
        /// `srgb` (linear in .exr, sRGB-encoded in .png) or `xyz` (relative to the model's
        /// white, .exr).
        #[arg(long, default_value = "srgb")]
        space: String,
        /// Read a PNG/TIFF's code values as linear (raw sensor data), not sRGB-encoded.
        #[arg(long)]
        linear: bool,
        /// Input image: .exr, .png or .tif.
        input: PathBuf,
        /// Output image: .exr or .png.
        output: PathBuf,
    },
    /// A ColorChecker 24's camera RGB and XYZ computed from spectra: the reflectances
    /// (BabelColor average), a CIE illuminant and a camera's measured sensitivities; writes
    /// rgb.csv (patch,R,G,B, a perfect white's strongest channel = 1), xyz.csv (patch,X,Y,Z,
    /// Y = 1 for a perfect white) and white.csv (the illuminant's white).
    Spectral {
        /// nikon-d5100 or sigma-sd-merrill.
        #[arg(long, default_value = "nikon-d5100")]
        camera: String,
        /// d65, d50, a or fl2.
        #[arg(long, default_value = "d65")]
        illuminant: String,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
}

pub fn run(cmd: Color) -> Result<()> {
    match cmd {
        Color::Fit(args) => fit(&args),
        Color::Detect(args) => detect(&args),
        Color::Apply { ccm, space, linear, input, output } => apply(&ccm, &space, linear, &input, &output),
        Color::Spectral { camera, illuminant, out } => spectral(&camera, &illuminant, &out),
    }
}

/// `lumen color fit`'s flags.
#[derive(clap::Args)]
pub struct FitArgs {
    /// Chart image: .exr (linear) or 8/16-bit .png/.tif (sRGB-decoded unless --linear).
    #[arg(long, conflicts_with = "patches", required_unless_present = "patches")]
    image: Option<PathBuf>,
    /// The outer corners of the 6×4 cell grid, x1,y1,x2,y2,x3,y3,x4,y4: top-left,
    /// top-right, bottom-right, bottom-left (the corner by patch 1 "dark skin" first),
    /// pixel centres at integer coordinates. Without it the chart is found in the image
    /// (as `lumen color detect` finds it).
    #[arg(long, allow_hyphen_values = true)]
    corners: Option<String>,
    /// Patch values instead of an image: CSV with the header patch,R,G,B (linear).
    #[arg(long)]
    patches: Option<PathBuf>,
    /// linear-3x3, white-preserving, affine, root-poly-2, root-poly-3, cheung-N (N = 3,
    /// 4, 5, 7, 8, 10, 11, 14, 16, 17, 19, 20, 22, 35) or de2000-opt.
    #[arg(long, default_value = "root-poly-2")]
    model: String,
    /// Reference values: CSV with the header patch,X,Y,Z (Y = 1 for a perfect white);
    /// default: the published ColorChecker 24 values (X-Rite, after Nov. 2014) under D50.
    #[arg(long)]
    reference: Option<PathBuf>,
    /// The white of L*a*b* and ΔE as X,Y,Z (Y = 1); default D50 with the published
    /// values, required with --reference.
    #[arg(long, allow_hyphen_values = true)]
    white: Option<String>,
    /// Read a PNG/TIFF's code values as linear (raw sensor data), not sRGB-encoded.
    #[arg(long)]
    linear: bool,
    /// The level at which a channel clips, in the image's units (1 is the full scale of a
    /// PNG/TIFF, or of an EXR scaled to it).
    #[arg(long, default_value_t = 1.0)]
    saturation: f64,
    /// The patch white-preserving maps exactly, 1 to 24 (19 is "white 9.5").
    #[arg(long, default_value_t = 19)]
    white_patch: usize,
    /// Output JSON: the model, its white and the report.
    #[arg(long)]
    out: PathBuf,
}

/// `lumen color detect`'s flags.
#[derive(clap::Args)]
pub struct DetectArgs {
    /// Photograph: .jpg/.png/.tif (sRGB-encoded unless --linear; EXIF orientation honoured)
    /// or .exr (linear).
    #[arg(long)]
    image: PathBuf,
    /// Read a PNG/TIFF's code values as linear (raw sensor data), not sRGB-encoded.
    #[arg(long)]
    linear: bool,
    /// The level at which a channel clips, in the image's units (flags clipped patches).
    #[arg(long, default_value_t = 1.0)]
    saturation: f64,
    /// Also write an overlay PNG: the found grid, the sampled squares and the patch numbers.
    #[arg(long)]
    debug: Option<PathBuf>,
    /// Output JSON.
    #[arg(long)]
    out: PathBuf,
}

/// What `lumen color detect` writes.
#[derive(serde::Serialize)]
struct DetectFile {
    image: String,
    /// How the values were read: a JPEG or PNG is the camera's sRGB-encoded rendering.
    encoding: String,
    corners: [[f64; 2]; 4],
    confidence: f64,
    patches: Vec<DetectedPatch>,
    detection: color::detect::Detection,
    /// The detection's time, decoding the file excluded.
    seconds: f64,
}

#[derive(serde::Serialize)]
struct DetectedPatch {
    name: String,
    /// Linear RGB, sampled as `color fit` samples it.
    rgb: [f64; 3],
    flag: Option<color::Flag>,
}

fn detect(a: &DetectArgs) -> Result<()> {
    if !(a.saturation.is_finite() && a.saturation > 0.0) {
        bail!("--saturation {}: expected a positive number", a.saturation);
    }
    let (img, d, how, seconds) = read_and_detect_timed(&a.image, a.linear)?;
    let samples = color::chart::sample(&img, d.corners, a.saturation)
        .map_err(|m| anyhow::anyhow!("{}: {m}", a.image.display()))?;
    let names = spectra::chart().into_iter().map(|(n, _)| n);
    let patches =
        samples.iter().zip(names).map(|(s, name)| DetectedPatch { name, rgb: s.rgb, flag: s.flag }).collect();
    let file = DetectFile {
        image: a.image.display().to_string(),
        encoding: how.to_string(),
        corners: d.corners,
        confidence: d.confidence,
        patches,
        detection: d.clone(),
        seconds,
    };
    if let Some(path) = &a.debug {
        let (w, h, rgb) = color::detect::overlay::draw(&img, true, &d);
        image::io::write_png_bytes(path, w, h, 3, &rgb)?;
    }
    let json = serde_json::to_string_pretty(&file)?;
    image::io::write_atomically(&a.out, |tmp| std::fs::write(tmp, json))?;
    let c: Vec<String> = d.corners.iter().map(|p| format!("({:.1}, {:.1})", p[0], p[1])).collect();
    eprintln!(
        "{}: chart found in {:.3} s, corners {}, confidence {:.2} ({} of 24 cells seen as squares, colour residual {:.3}{}); {how}; wrote {}",
        a.image.display(),
        seconds,
        c.join(" "),
        d.confidence,
        d.cells_found,
        d.colour_residual,
        if d.refined { format!(", edges {:.2} px RMS", d.edge_rms_px.unwrap_or(f64::NAN)) } else { ", edges not refined".into() },
        a.out.display()
    );
    Ok(())
}

/// Reads an image as linear RGB: EXR as stored, PNG/TIFF sRGB-decoded unless `linear`.
/// Returns the image and how it was read.
fn read_linear(path: &Path, linear: bool) -> Result<(Image, &'static str)> {
    let (img, _, how) = read_both(path, linear)?;
    Ok((img, how))
}

/// Reads an image as linear RGB (as `read_linear`), finds the chart in it and returns both;
/// an sRGB-encoded file is searched in its own code values, with no decoding and re-encoding.
fn read_and_detect(path: &Path, linear: bool) -> Result<(Image, color::detect::Detection, &'static str)> {
    let (img, found, how, _) = read_and_detect_timed(path, linear)?;
    Ok((img, found, how))
}

/// `read_and_detect`, with the detection's own time (decoding excluded) in seconds.
fn read_and_detect_timed(
    path: &Path,
    linear: bool,
) -> Result<(Image, color::detect::Detection, &'static str, f64)> {
    let (img, encoded, how) = read_both(path, linear)?;
    let t = std::time::Instant::now();
    let found = match &encoded {
        Some(codes) => color::detect::detect(codes, false),
        None => color::detect::detect(&img, true),
    };
    let seconds = t.elapsed().as_secs_f64();
    let found = found.map_err(|m| anyhow::anyhow!("{}: {m}", path.display()))?;
    Ok((img, found, how, seconds))
}

/// The linear image, the code values when the file is sRGB-encoded, and how it was read.
fn read_both(path: &Path, linear: bool) -> Result<(Image, Option<Image>, &'static str)> {
    let img = image::io::read(path)?;
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_lowercase();
    if ext == "exr" {
        return Ok((img, None, "linear (EXR)"));
    }
    if linear {
        return Ok((img, None, "code values read as linear (--linear)"));
    }
    let mut lin = img.clone();
    lin.data.iter_mut().for_each(|v| *v = image::srgb_decode(*v));
    Ok((
        lin,
        Some(img),
        "sRGB-decoded: a JPEG or PNG is the camera's rendering, not linear sensor data, so ΔE measures that rendering (pass --linear for raw-derived files)",
    ))
}

fn fit(a: &FitArgs) -> Result<()> {
    let out = &a.out;
    let model: color::Model =
        a.model.parse().map_err(|e: lumen::error::Invalid| anyhow::Error::new(e).context("--model"))?;
    if !(1..=24).contains(&a.white_patch) {
        bail!("--white-patch {}: expected a patch number 1 to 24", a.white_patch);
    }
    if !(a.saturation.is_finite() && a.saturation > 0.0) {
        bail!("--saturation {}: expected a positive number", a.saturation);
    }
    let (names, reference, white) = match (&a.reference, &a.white) {
        (Some(path), Some(w)) => {
            let white = color::parse_numbers::<3>(w, "--white").map_err(anyhow::Error::msg)?;
            let names = spectra::chart().into_iter().map(|(n, _)| n).collect::<Vec<_>>();
            (names, color::read_reference(path).context("--reference")?, white)
        }
        (Some(_), None) => bail!("--reference needs --white X,Y,Z: the white its values are relative to"),
        (None, w) => {
            let (published, d50) = color::published_reference();
            let white = match w {
                Some(w) => color::parse_numbers::<3>(w, "--white").map_err(anyhow::Error::msg)?,
                None => d50,
            };
            let (names, xyz) = published.into_iter().unzip();
            (names, xyz, white)
        }
    };
    if !white.iter().all(|&v| v > 0.0) {
        bail!("--white {white:?}: expected three positive numbers (X,Y,Z)");
    }
    let (samples, how): (Vec<([f64; 3], Option<color::Flag>)>, String) = match (&a.image, &a.patches) {
        (Some(path), _) => {
            let (img, corners, found, how) = match &a.corners {
                Some(text) => {
                    let c = color::parse_numbers::<8>(text, "--corners").map_err(anyhow::Error::msg)?;
                    let (img, how) = read_linear(path, a.linear)?;
                    (
                        img,
                        [[c[0], c[1]], [c[2], c[3]], [c[4], c[5]], [c[6], c[7]]],
                        "corners given".to_string(),
                        how,
                    )
                }
                None => {
                    let (img, d, how) = read_and_detect(path, a.linear)?;
                    let c: Vec<String> =
                        d.corners.iter().map(|p| format!("{:.1},{:.1}", p[0], p[1])).collect();
                    (
                        img,
                        d.corners,
                        format!(
                            "corners found in the image: {} (confidence {:.2})",
                            c.join(","),
                            d.confidence
                        ),
                        how,
                    )
                }
            };
            let s = color::chart::sample(&img, corners, a.saturation)
                .map_err(|m| anyhow::anyhow!("{}: {m}", path.display()))?;
            (s.into_iter().map(|p| (p.rgb, p.flag)).collect(), format!("{}: {how}; {found}", path.display()))
        }
        (None, Some(path)) => {
            let rgb = color::read_patch_rgb(path).context("--patches")?;
            (rgb.into_iter().map(|c| (c, None)).collect(), format!("{}: patch values", path.display()))
        }
        (None, None) => bail!("give --image (with --corners, or without to find the chart), or --patches"),
    };
    let input = Input {
        patches: samples
            .iter()
            .zip(&reference)
            .zip(&names)
            .map(|(((rgb, flag), xyz), name)| PatchInput {
                name: name.clone(),
                rgb: *rgb,
                reference_xyz: *xyz,
                flag: *flag,
            })
            .collect(),
        white,
    };
    let config = color::Config { model, white_patch: a.white_patch - 1, leave_one_out: true };
    let result = color::run(&input, &config)?;
    for w in &result.warnings {
        eprintln!("warning: {w}");
    }
    let file = CcmFile {
        format: color::CCM_FORMAT.into(),
        fitted: result.fitted.clone(),
        white,
        report: Some(result.clone()),
        source: Some(how.clone()),
    };
    let json = serde_json::to_string_pretty(&file)?;
    image::io::write_atomically(out, |tmp| std::fs::write(tmp, json))?;
    let loo = result.loo_mean_de2000.map_or("none".to_string(), |v| format!("{v:.3}"));
    eprintln!(
        "{how}; {}: {} patches used, mean ΔE2000 {:.3}, max {:.3}, leave-one-out mean {loo} (fit {:.1} ms, leave-one-out {:.1} ms); wrote {}",
        model.name(),
        result.used_patches,
        result.mean_de2000,
        result.max_de2000,
        1e3 * result.fit_s,
        1e3 * result.loo_s,
        out.display()
    );
    Ok(())
}

fn apply(ccm: &Path, space: &str, linear: bool, input: &Path, output: &Path) -> Result<()> {
    let file = color::read_ccm(ccm).context("--ccm")?;
    let to_srgb = match space {
        "srgb" => Some(color::xyz_to_linear_srgb(file.white)),
        "xyz" => None,
        other => bail!("--space {other}: expected srgb or xyz"),
    };
    let out_ext = output.extension().and_then(|e| e.to_str()).unwrap_or("").to_lowercase();
    if !["exr", "png"].contains(&out_ext.as_str()) {
        bail!("{}: expected an .exr or .png output", output.display());
    }
    if to_srgb.is_none() && out_ext != "exr" {
        bail!("{}: XYZ is written as .exr (a PNG would clip and sRGB-encode it)", output.display());
    }
    let t = std::time::Instant::now();
    let (img, how) = read_linear(input, linear)?;
    if img.channels < 3 {
        bail!("{}: {} channel(s), expected RGB", input.display(), img.channels);
    }
    let read_s = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let c = img.channels as usize;
    let mut out = Image::new(img.width, img.height, 3);
    use rayon::prelude::*;
    let non_finite = std::sync::atomic::AtomicUsize::new(0);
    out.data
        .par_chunks_mut(3 * img.width as usize)
        .zip(img.data.par_chunks(c * img.width as usize))
        .for_each(|(dst, src)| {
            for (d, s) in dst.chunks_exact_mut(3).zip(src.chunks_exact(c)) {
                let xyz = file.fitted.apply([s[0] as f64, s[1] as f64, s[2] as f64]);
                let v = match &to_srgb {
                    Some(m) => m.map(|row| row[0] * xyz[0] + row[1] * xyz[1] + row[2] * xyz[2]),
                    None => xyz,
                };
                if v.iter().all(|x| (*x as f32).is_finite()) {
                    for k in 0..3 {
                        d[k] = v[k] as f32;
                    }
                } else {
                    // Written as 0 and counted, rather than poisoning the file with NaN.
                    d.fill(0.0);
                    non_finite.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                }
            }
        });
    let apply_s = t.elapsed().as_secs_f64();
    let non_finite = non_finite.into_inner();
    if non_finite > 0 {
        eprintln!(
            "warning: {non_finite} pixel(s) gave a colour that is not a finite float (a non-finite input or an overflowing term): written as 0"
        );
    }
    let t = std::time::Instant::now();
    image::io::write(output, &out)?;
    eprintln!(
        "{}: {how}; {} ({}×{}, {:.1} Mpixel) to {space}: read {read_s:.2} s, applied in {apply_s:.3} s ({:.0} Mpixel/s), written in {:.2} s to {}",
        input.display(),
        file.fitted.model,
        img.width,
        img.height,
        (img.width as f64 * img.height as f64) / 1e6,
        (img.width as f64 * img.height as f64) / 1e6 / apply_s.max(1e-9),
        t.elapsed().as_secs_f64(),
        output.display()
    );
    Ok(())
}

fn spectral(camera: &str, illuminant: &str, out: &Path) -> Result<()> {
    let cam = spectra::camera(camera)
        .with_context(|| format!("--camera {camera}: expected one of {}", spectra::CAMERAS.join(", ")))?;
    let ill = spectra::illuminant(illuminant).with_context(|| {
        format!("--illuminant {illuminant}: expected one of {}", spectra::ILLUMINANTS.join(", "))
    })?;
    let chart = spectra::chart();
    let rgb: Vec<[f64; 3]> = chart.iter().map(|(_, r)| spectra::camera_rgb(r, &ill, &cam)).collect();
    let xyz: Vec<[f64; 3]> = chart.iter().map(|(_, r)| spectra::xyz(r, &ill)).collect();
    let white = spectra::white(&ill);
    let what = format!("ColorChecker 24 (BabelColor average) under {illuminant}, camera {camera}");
    // The three tables are written together: on an error none is left behind.
    image::io::write_together(out, |dir| -> Result<()> {
        color::write_table(
            &dir.join("rgb.csv"),
            ["R", "G", "B"],
            &rgb,
            &format!("{what}: camera RGB, a perfect white's strongest channel = 1"),
        )?;
        color::write_table(
            &dir.join("xyz.csv"),
            ["X", "Y", "Z"],
            &xyz,
            &format!("{what}: CIE 1931 2° XYZ, Y = 1 for a perfect white"),
        )?;
        let text = format!(
            "# the white of {illuminant} (CIE 1931 2°)\nX,Y,Z\n{:e},{:e},{:e}\n",
            white[0], white[1], white[2]
        );
        image::io::write_atomically(&dir.join("white.csv"), |tmp| std::fs::write(tmp, text))?;
        Ok(())
    })?;
    eprintln!(
        "{what}: wrote rgb.csv, xyz.csv and white.csv to {}; white {:.6},{:.6},{:.6}",
        out.display(),
        white[0],
        white[1],
        white[2]
    );
    Ok(())
}
