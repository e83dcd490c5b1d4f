//! Command-line parsing and the commands (`bench` holds the benchmarks). anyhow lives only
//! here.

mod bench;
mod color;
mod denoise;
mod hdr;
mod pipeline_cmd;
mod render_cmd;
mod scene;
mod sfm;
mod surface;
mod texture;
mod warp;

use bench::{bench_calibrate, bench_convergence, bench_hdr, bench_render, BenchRender};
use pipeline_cmd::{merge_cmd, render_share, run_pipeline, slurm_cmd, SlurmArgs};
use render_cmd::{integrator_parser, render_cmd, RenderArgs};

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use lumen::{pipeline, render};
use std::path::{Path, PathBuf};

#[derive(Parser)]
#[command(
    name = "lumen",
    version,
    about = "Calibrate cameras and measure scenes, validated against a built-in path tracer"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a pipeline file; writes report.json and report.md to its output folder.
    Run {
        /// Pipeline file (TOML), e.g. pipelines/all.toml.
        pipeline: PathBuf,
        /// Output folder (default: out/<pipeline name>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Worker threads, 1 to 1024 (default: all cores).
        #[arg(long, value_parser = parse_threads)]
        threads: Option<usize>,
        /// Folder of the render cache, shared by runs and pipelines (default: out/cache).
        #[arg(long)]
        cache: Option<PathBuf>,
        /// Render everything afresh and store nothing.
        #[arg(long)]
        no_cache: bool,
        /// Run only shard K of N (case i goes to shard i mod N + 1) and write its fragment to
        /// OUT/shards/K-of-N; `lumen merge OUT` joins the fragments (default: every case).
        #[arg(long, value_name = "K/N", value_parser = lumen::pipeline::shard::Shard::parse)]
        shard: Option<lumen::pipeline::shard::Shard>,
        /// With --shard K/N: only make this shard's share of every case's renders in the cache
        /// (an entry goes to share K when its key is K − 1 mod N), so the views or lights of
        /// one large case are spread over all shards; then run the shards from the full cache.
        #[arg(long, requires = "shard", conflicts_with = "no_cache")]
        renders_only: bool,
        /// With --shard K/N, after every --renders-only share: only make this shard's share of
        /// the blocks of image pairs that structure-from-motion cases match and verify (the
        /// cases' features come from the renders shares), so that work is spread too.
        #[arg(long, requires = "shard", conflicts_with_all = ["no_cache", "renders_only"])]
        matches_only: bool,
    },
    /// Join the fragments in OUT/shards (from `lumen run --shard K/N --out OUT`) into one
    /// report.json, report.md and plots in OUT, checking that they are one pipeline's and cover
    /// every case once.
    Merge {
        /// The output folder the shards wrote to.
        out: PathBuf,
    },
    /// Write results pages from run reports: one Markdown file per stage (every case's
    /// outcome, errors, bounds and times, the sweeps' plots), with the commit, date and
    /// machine each report was measured on, and an index.md.
    Report {
        /// The report.json files of `lumen run` (or `lumen merge`).
        #[arg(required = true)]
        reports: Vec<PathBuf>,
        /// The folder to write the pages into (created if need be; other files there are
        /// left alone).
        #[arg(long)]
        docs: PathBuf,
    },
    /// Write the sbatch scripts that run a pipeline on Slurm: OUT/slurm/render.sbatch (a job
    /// array, each task making its share of every case's renders), OUT/slurm/match.sbatch (a
    /// job array after it, each task matching its share of the image pairs), OUT/slurm/run.sbatch
    /// (a job array after that, one task per shard of cases) and OUT/slurm/merge.sbatch
    /// (`lumen merge OUT` last); with --submit, submit all four and print the job ids; with --wait,
    /// also wait for the merge and exit as it does (0 all bounds met, 3 a bound missed, 1 a
    /// failure).
    Slurm {
        /// Pipeline file (TOML), e.g. pipelines/all.toml.
        pipeline: PathBuf,
        /// Number of shards, 1 to 1000: the array's tasks.
        #[arg(long)]
        shards: usize,
        /// Output folder on storage every node sees (default: out/<pipeline name>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Folder of the render cache the shards share (default: OUT/../cache).
        #[arg(long)]
        cache: Option<PathBuf>,
        /// Slurm partition (default: the cluster's default).
        #[arg(long)]
        partition: Option<String>,
        /// Time limit per task, as sbatch reads it, e.g. 1:00:00 (default: the partition's).
        #[arg(long)]
        time: Option<String>,
        /// CPUs per task, also the shard's threads.
        #[arg(long, default_value_t = 2)]
        cpus_per_task: usize,
        /// Submit the three scripts with sbatch, each after the one before (--dependency=afterok).
        #[arg(long)]
        submit: bool,
        /// With --submit: wait until the merge job ends (sbatch --wait) and exit with its code.
        #[arg(long, requires = "submit")]
        wait: bool,
    },
    /// Render a scene file to an image: .exr (linear float) or .png (sRGB, or raw sensor values
    /// when the scene has a [sensor]).
    Render(RenderArgs),
    /// Scene files: `lumen scene convert scene.xml --out scene.toml` writes the lumen scene a
    /// Mitsuba 3 scene reads as.
    Scene {
        #[command(subcommand)]
        what: scene::SceneCmd,
    },
    /// PNG previews of EXR images, written beside each as NAME.png: radiance tone-mapped,
    /// normals as (n + 1)/2, depth and scalars in colour with a labelled scale bar, ids in
    /// distinct colours.
    Preview {
        /// EXR files, e.g. box.exr box.depth.exr ps-ball/normals.exr.
        #[arg(required = true, num_args = 1..)]
        files: Vec<PathBuf>,
        /// radiance, normal, depth, id, albedo, position or scalar (default: from the file
        /// name as `lumen render --aov` and `lumen ps` write it, else one channel is a scalar
        /// and three are radiance).
        #[arg(long)]
        kind: Option<String>,
    },
    /// Calibrate a camera from chessboard images (Zhang's method).
    Calibrate {
        /// Image files: a glob pattern such as 'DIR/*.jpg' (quote it), or several paths.
        #[arg(long, required = true, num_args = 1..)]
        images: Vec<String>,
        /// Inner corners as COLSxROWS, e.g. 9x6.
        #[arg(long)]
        board: String,
        /// Side of a square, in the unit translations should come out in.
        #[arg(long, default_value_t = 1.0)]
        square: f64,
        /// Output: .yaml/.yml (OpenCV FileStorage) or .json.
        #[arg(long)]
        out: PathBuf,
        /// Keep fy/fx at its initial value (OpenCV's CALIB_FIX_ASPECT_RATIO).
        #[arg(long)]
        fix_aspect_ratio: bool,
        /// Keep the principal point at the image centre.
        #[arg(long)]
        fix_principal_point: bool,
        /// Set p1 = p2 = 0.
        #[arg(long)]
        zero_tangential: bool,
        /// Set k3 = 0.
        #[arg(long)]
        fix_k3: bool,
        /// The response the images' codes were written through, undone before the corners
        /// are refined: linear (the codes as they are, as OpenCV takes them), srgb (most
        /// JPEGs) or gamma:G. On the codes of a non-linear curve, edges move towards their
        /// dark side and corners are found biased.
        #[arg(long, default_value = "linear")]
        response: String,
        /// Write an overlay PNG per view into this folder: the detected corners, rows in
        /// colour, or the candidate corners of a view without a whole board.
        #[arg(long)]
        debug: Option<PathBuf>,
    },
    /// Photometric stereo on a dataset in DiLiGenT's layout: normals, albedo and (with
    /// ground truth) the angular error.
    Ps {
        /// Folder with filenames.txt, light_directions.txt, light_intensities.txt, mask.png
        /// and optionally Normal_gt.mat.
        #[arg(long)]
        dataset: PathBuf,
        /// lambertian (least squares over every light), robust (shadows, highlights and
        /// saturated values left out) or blinn-phong (normal, diffuse and specular albedo and
        /// shininess per pixel).
        #[arg(long, default_value = "robust")]
        model: String,
        /// blinn-phong: Gauss-Newton iterations from each start before the lowest cost goes
        /// on, 1 to 100 (default 8): fewer are faster and can choose a worse start.
        #[arg(long)]
        start_iterations: Option<u64>,
        /// Output folder: normals.exr/.png, albedo.exr/.png, error.png (with ground truth: the
        /// angular error in colour, its scale on a colour bar), depth.exr and surface.obj (the integrated surface), summary.json; with blinn-phong
        /// also specular.exr and shininess.exr.
        #[arg(long)]
        out: PathBuf,
    },
    /// Undistort an image with a calibration (.yaml/.yml or .json).
    Undistort {
        /// Calibration file written by `lumen calibrate` or OpenCV.
        #[arg(long)]
        camera: PathBuf,
        /// 0 keeps only valid pixels, 1 keeps every source pixel (OpenCV's
        /// getOptimalNewCameraMatrix).
        #[arg(long, default_value_t = 0.0)]
        alpha: f64,
        /// Input image (.png, .jpg or .exr).
        input: PathBuf,
        /// Output image: .png (8-bit, the input's code values) or .exr (float).
        output: PathBuf,
    },
    /// Colour calibration from a ColorChecker 24: fit a model, apply it, or compute a
    /// chart's camera RGB and XYZ from spectra.
    Color {
        #[command(subcommand)]
        what: color::Color,
    },
    /// HDR fusion of an exposure stack: the camera's response (Debevec & Malik or Robertson)
    /// and the merged radiance.
    Hdr(hdr::HdrArgs),
    /// Denoise a Monte Carlo render with weights from its own noise: bilateral, non-local
    /// means or feature-guided (albedo, normal, depth), strengths chosen per pixel by SURE.
    Denoise(denoise::DenoiseArgs),
    /// Structure from motion: cameras and sparse points from overlapping photographs (a
    /// COLMAP text model, a PLY point cloud and a summary).
    Sfm(sfm::SfmArgs),
    /// A closed mesh from a point cloud (PLY): point-set surfaces by algebraic spheres (APSS)
    /// or moving least squares, normals estimated and oriented when absent, meshed by
    /// marching tetrahedra near the points.
    Surface(surface::SurfaceArgs),
    /// A new view from views with depth and cameras (depth-based rendering): forward
    /// (splatting through a z-buffer) or backward mapping (filtered depth, colours looked up
    /// in the sources), with a mask of the pixels no source sees.
    Warp(warp::WarpArgs),
    /// A texture for a mesh from photographs with known cameras (a COLMAP text model): a UV
    /// atlas, each texel's colour from the views that see it (occlusion tested against the
    /// mesh), per-photograph gains, written as OBJ + MTL + PNG.
    Texture(texture::TextureArgs),
    /// Benchmarks.
    Bench {
        #[command(subcommand)]
        what: Bench,
    },
}

#[derive(Subcommand)]
enum Bench {
    /// Million paths per second on a scene (default: the Cornell box, 256×256, depth 8).
    Render {
        /// Scene file (TOML).
        #[arg(long, default_value = "pipelines/scenes/cornell-box.toml")]
        scene: PathBuf,
        /// Light-transport algorithm (default: the scene's [render] integrator).
        #[arg(long, value_parser = integrator_parser())]
        integrator: Option<&'static render::integrators::Kind>,
        /// Samples per pixel.
        #[arg(long, default_value_t = 64)]
        spp: u32,
        /// Longest path in segments.
        #[arg(long, default_value_t = 8)]
        max_depth: u32,
        /// Worker threads, 1 to 1024 (default: all cores).
        #[arg(long, value_parser = parse_threads)]
        threads: Option<usize>,
        /// Repetitions; the best is reported.
        #[arg(long, default_value_t = 3)]
        repeat: u32,
        /// `independent` or `sobol` (default: the scene's `[render] sampler`).
        #[arg(long)]
        sampler: Option<String>,
        /// Trace one path at a time even where the scene allows eight at once, to compare.
        #[arg(long)]
        one_path: bool,
    },
    /// RMSE against a reference image as the sample count grows, for the independent and
    /// the Sobol sampler (default: the Cornell box against Mitsuba 3's 8192-spp reference).
    Convergence {
        /// Scene file (TOML).
        #[arg(long, default_value = "pipelines/scenes/cornell-box.toml")]
        scene: PathBuf,
        /// Reference image (.exr, linear) of the same scene, e.g. a high-spp Mitsuba 3 render.
        #[arg(long, default_value = "../shared/data/scenes/cornell-box/reference.exr")]
        reference: PathBuf,
        /// Sample counts, comma-separated.
        #[arg(long, default_value = "4,16,64,256")]
        spp: String,
        /// Worker threads, 1 to 1024 (default: all cores).
        #[arg(long, value_parser = parse_threads)]
        threads: Option<usize>,
    },
    /// Photons: the photon pass's speed (photons stored per second, all cores), and the
    /// photons of a scene (default: the Cornell box) found by kiddo's kd-tree, by the hashed
    /// grid and by a scan, at growing photon counts: build time, and fixed-radius queries
    /// (radius set so a query finds about `k` photons) and k-nearest queries per second on
    /// one thread, at camera-ray hit points.
    Photons {
        /// Scene file (TOML or Mitsuba XML).
        #[arg(long, default_value = "pipelines/scenes/cornell-box.toml")]
        scene: PathBuf,
        /// Photon paths traced, comma-separated (each stores about one photon per bounce).
        #[arg(long, default_value = "10000,100000,1000000,10000000")]
        counts: String,
        /// Photons a query should find.
        #[arg(long, default_value_t = 50)]
        k: u32,
        /// Queries per count (the scan does at most 1000).
        #[arg(long, default_value_t = 200000)]
        queries: u32,
    },
    /// Denoisers on one scene: relMSE against a converged reference and time (render,
    /// features and filter) of every method at each sample count n, beside the raw render at
    /// n, 4n and 16n.
    Denoise {
        /// Scene file (TOML or Mitsuba XML).
        #[arg(long, default_value = "pipelines/scenes/cornell-box.toml")]
        scene: PathBuf,
        /// Converged reference (.exr, linear) of the same scene.
        #[arg(long)]
        reference: PathBuf,
        /// Sample counts, comma-separated, each at least 2.
        #[arg(long, default_value = "4,16,64")]
        spp: String,
        /// Folder to write each sample count's inputs into (for other denoisers) and the rows
        /// as NAME-denoise.json.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Detection and calibration time on a set of photographs; with the `opencv` feature,
    /// OpenCV's findChessboardCorners + cornerSubPix + calibrateCamera on the same images in
    /// the same run. Images are decoded before timing.
    Calibrate {
        /// Image files (a quoted glob pattern or several paths).
        #[arg(long, required = true, num_args = 1..)]
        images: Vec<String>,
        /// Inner corners as COLSxROWS.
        #[arg(long, default_value = "9x6")]
        board: String,
        /// Repetitions; the best is reported.
        #[arg(long, default_value_t = 5)]
        repeat: u32,
    },
    /// Response fits (Debevec, Robertson), merge and Mertens fusion on an exposure stack; with
    /// the `opencv` feature, OpenCV's CalibrateDebevec, MergeDebevec and MergeMertens on the
    /// same files in the same run. Frames are decoded before timing.
    Hdr {
        /// A file with a frame name and an exposure time per line, as `lumen hdr --list`.
        #[arg(long, default_value = "../shared/data/hdr/memorial/exposure_times_seconds.txt")]
        list: PathBuf,
        /// Leave pixels of this colour (R,G,B code values) out of the fit, as `lumen hdr`
        /// (0,0,255: the Memorial stack's blue borders), or `none`.
        #[arg(long, default_value = "0,0,255")]
        exclude_color: String,
        /// Repetitions; the best is reported.
        #[arg(long, default_value_t = 5)]
        repeat: u32,
    },
}

pub fn main() -> i32 {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() { 2 } else { 0 };
        }
    };
    let result = match cli.command {
        Command::Run { pipeline, out, threads, cache, no_cache, shard, renders_only, matches_only } => {
            use lumen::pipeline::cache::Pass;
            let cache =
                if no_cache { None } else { Some(cache.unwrap_or_else(|| PathBuf::from("out/cache"))) };
            let pass = match (renders_only, matches_only) {
                (true, _) => Some(Pass::Renders),
                (_, true) => Some(Pass::Matches),
                _ => None,
            };
            match (pass, shard, cache) {
                (Some(pass), Some(share), Some(cache)) => {
                    render_share(&pipeline, cache, share, pass, threads)
                }
                (_, shard, cache) => run_pipeline(
                    &pipeline,
                    out,
                    pipeline::RunOptions { threads, progress: true, cache_dir: cache, shard },
                ),
            }
        }
        Command::Merge { out } => merge_cmd(&out),
        Command::Report { reports, docs } => lumen::pipeline::docs::write(&reports, &docs)
            .map(|written| {
                eprintln!("wrote {} pages and plots into {}", written.len(), docs.display());
                0
            })
            .map_err(anyhow::Error::new),
        Command::Slurm { pipeline, shards, out, cache, partition, time, cpus_per_task, submit, wait } => {
            let opts = SlurmArgs { shards, out, cache, partition, time, cpus_per_task, submit, wait };
            slurm_cmd(&pipeline, opts)
        }
        Command::Render(args) => render_cmd(&args).map(|_| 0),
        Command::Scene { what } => scene::run(what).map(|_| 0),
        Command::Preview { files, kind } => preview_cmd(&files, kind.as_deref()).map(|_| 0),
        Command::Calibrate {
            images,
            board,
            square,
            out,
            fix_aspect_ratio,
            fix_principal_point,
            zero_tangential,
            fix_k3,
            response,
            debug,
        } => {
            let flags = lumen::calib::refine::Flags {
                fix_aspect_ratio,
                fix_principal_point,
                zero_tangential,
                fix_k3,
            };
            calibrate_cmd(&images, &board, square, &out, flags, &response, debug.as_deref()).map(|_| 0)
        }
        Command::Ps { dataset, model, start_iterations, out } => {
            ps_cmd(&dataset, &model, start_iterations, &out).map(|_| 0)
        }
        Command::Undistort { camera, alpha, input, output } => {
            undistort_cmd(&camera, alpha, &input, &output).map(|_| 0)
        }
        Command::Color { what } => color::run(what).map(|_| 0),
        Command::Hdr(args) => hdr::run(&args).map(|_| 0),
        Command::Denoise(args) => denoise::run(&args).map(|_| 0),
        Command::Surface(args) => surface::run(&args).map(|_| 0),
        Command::Warp(args) => warp::run(&args).map(|_| 0),
        Command::Texture(args) => texture::run(&args).map(|_| 0),
        Command::Sfm(args) => sfm::run(&args).map(|_| 0),
        Command::Bench {
            what: Bench::Render { scene, integrator, spp, max_depth, threads, repeat, sampler, one_path },
        } => {
            let opts = BenchRender { integrator, spp, max_depth, threads, repeat, sampler, one_path };
            bench_render(&scene, &opts).map(|_| 0)
        }
        Command::Bench { what: Bench::Convergence { scene, reference, spp, threads } } => {
            bench_convergence(&scene, &reference, &spp, threads).map(|_| 0)
        }
        Command::Bench { what: Bench::Photons { scene, counts, k, queries } } => {
            bench::bench_photons(&scene, &counts, k, queries).map(|_| 0)
        }
        Command::Bench { what: Bench::Denoise { scene, reference, spp, out } } => {
            bench::bench_denoise(&scene, &reference, &spp, out.as_deref()).map(|_| 0)
        }
        Command::Bench { what: Bench::Calibrate { images, board, repeat } } => {
            bench_calibrate(&images, &board, repeat).map(|_| 0)
        }
        Command::Bench { what: Bench::Hdr { list, exclude_color, repeat } } => {
            let exclude = (exclude_color != "none").then(|| hdr::parse_color(&exclude_color)).transpose();
            exclude.and_then(|c| bench_hdr(&list, c, repeat)).map(|_| 0)
        }
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            match fault(&e) {
                Some(f) => eprintln!("error ({f}): {e:#}"),
                None => eprintln!("error: {e:#}"),
            }
            1
        }
    }
}

/// Whose fault an error is, as the library error in its chain says (`None` for the command
/// line's own glue).
fn fault(e: &anyhow::Error) -> Option<lumen::Fault> {
    e.chain().find_map(|c| {
        let c = c as &(dyn std::error::Error + 'static);
        None.or_else(|| c.downcast_ref::<lumen::Error>().map(|e| e.fault()))
            .or_else(|| c.downcast_ref::<lumen::pipeline::Error>().map(|e| e.fault()))
            .or_else(|| c.downcast_ref::<lumen::pipeline::file::Error>().map(|e| e.fault()))
            .or_else(|| c.downcast_ref::<lumen::pipeline::stages::StageError>().map(|e| e.fault()))
            .or_else(|| c.downcast_ref::<lumen::render::Error>().map(|e| e.fault()))
            .or_else(|| c.downcast_ref::<lumen::image::io::Error>().map(|e| e.fault()))
            .or_else(|| c.downcast_ref::<lumen::calib::Error>().map(|e| e.fault()))
            .or_else(|| c.downcast_ref::<lumen::photometric::Error>().map(|e| e.fault()))
            .or_else(|| c.downcast_ref::<lumen::fit::FitError>().map(|e| e.fault()))
            .or_else(|| c.downcast_ref::<lumen::sfm::Error>().map(|e| e.fault()))
            .or_else(|| c.downcast_ref::<lumen::surface::Error>().map(|e| e.fault()))
            .or_else(|| c.downcast_ref::<lumen::ibr::Error>().map(|e| e.fault()))
            .or_else(|| c.downcast_ref::<lumen::image::denoise::Error>().map(|e| e.fault()))
            .or_else(|| c.downcast_ref::<lumen::render::obj::ObjError>().map(|e| e.fault()))
            .or_else(|| c.downcast_ref::<lumen::render::ply::PlyError>().map(|e| e.fault()))
            .or_else(|| c.downcast_ref::<lumen::error::Invalid>().map(|e| e.fault()))
            .or_else(|| c.downcast_ref::<lumen::render::integrators::UnknownIntegrator>().map(|e| e.fault()))
    })
}

fn preview_cmd(files: &[PathBuf], kind: Option<&str>) -> Result<()> {
    let kind: Option<lumen::image::preview::Kind> = kind
        .map(|k| k.parse())
        .transpose()
        .map_err(|e: lumen::error::Invalid| anyhow::Error::new(e).context("--kind"))?;
    for (png, k) in write_previews(files, kind)? {
        eprintln!("wrote {} ({k:?})", png.display());
    }
    Ok(())
}

/// Writes a PNG preview beside each EXR of `files` (the kind from each name unless given),
/// reading every file before writing any: a bad file leaves no previews behind.
pub fn write_previews(
    files: &[PathBuf],
    kind: Option<lumen::image::preview::Kind>,
) -> Result<Vec<(PathBuf, lumen::image::preview::Kind)>> {
    use lumen::image::preview;
    let mut images = Vec::new();
    for file in files {
        if file.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() != Some("exr") {
            bail!("{}: expected an .exr file", file.display());
        }
        let img = lumen::image::io::read_exr(file)?;
        if !matches!(img.channels, 1 | 3 | 4) {
            bail!("{}: {} channels; a preview shows 1, 3 or 4", file.display(), img.channels);
        }
        images.push(img);
    }
    let mut written = Vec::new();
    for (file, img) in files.iter().zip(&images) {
        let k = kind.unwrap_or_else(|| preview::kind_of(file, img));
        let png = preview::png_path(file);
        preview::write(&png, img, k)?;
        written.push((png, k));
    }
    Ok(written)
}

/// Parses `--threads`: 1 to `pipeline::MAX_THREADS`.
pub fn parse_threads(text: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(n) if (1..=pipeline::MAX_THREADS).contains(&n) => Ok(n),
        _ => Err(format!("expected a number of threads from 1 to {}", pipeline::MAX_THREADS)),
    }
}

/// Parses `COLSxROWS`.
fn parse_board(text: &str) -> Result<lumen::calib::detect::BoardSize> {
    let parts: Vec<&str> = text.split(['x', 'X', '×']).collect();
    match parts.as_slice() {
        [c, r] => match (c.trim().parse::<usize>(), r.trim().parse::<usize>()) {
            (Ok(cols), Ok(rows)) if cols >= 2 && rows >= 2 => {
                Ok(lumen::calib::detect::BoardSize { cols, rows })
            }
            _ => bail!("--board {text}: expected inner-corner counts of at least 2, as COLSxROWS (e.g. 9x6)"),
        },
        _ => bail!("--board {text}: expected inner-corner counts as COLSxROWS (e.g. 9x6)"),
    }
}

/// Expands glob patterns and plain paths, sorted, without duplicates.
fn expand_images(patterns: &[String]) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for p in patterns {
        let matches: Vec<PathBuf> = glob::glob(p)
            .with_context(|| format!("--images {p}: not a valid pattern"))?
            .filter_map(|m| m.ok())
            .filter(|m| m.is_file())
            .collect();
        if matches.is_empty() {
            bail!("--images {p}: no file matches");
        }
        files.extend(matches);
    }
    files.sort();
    files.dedup();
    Ok(files)
}

fn calibrate_cmd(
    patterns: &[String],
    board: &str,
    square: f64,
    out: &Path,
    flags: lumen::calib::refine::Flags,
    response: &str,
    debug: Option<&Path>,
) -> Result<()> {
    let board = parse_board(board)?;
    let response =
        lumen::calib::linear::parse_response(response).map_err(|e| anyhow::anyhow!("--response: {e}"))?;
    lumen::calib::check_square(square).map_err(|e| anyhow::anyhow!("--square: {e}"))?;
    let ext = out.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if !["yaml", "yml", "json"].contains(&ext.as_str()) {
        bail!("--out {}: expected a file name ending in .yaml, .yml or .json", out.display());
    }
    let files = expand_images(patterns)?;
    let mut images = Vec::new();
    for f in &files {
        lumen::calib::linear::check_codes(f, &response).map_err(|e| anyhow::anyhow!("--response: {e}"))?;
        let img = lumen::image::io::read(f)?;
        images.push((f.display().to_string(), lumen::image::filter::Grey::from_image(&img)));
    }
    let detect = lumen::calib::detect::DetectOptions { response, ..Default::default() };
    let config = lumen::calib::Config { board, square, flags, detect, max_iterations: 100 };
    let input = lumen::calib::Input { images };
    let t = std::time::Instant::now();
    let calibrated = lumen::calib::run(&input, &config);
    let secs = t.elapsed().as_secs_f64();
    // Overlays first: they show why a calibration failed as much as what it used.
    if let Some(dir) = debug {
        let views = match &calibrated {
            Ok(o) => o.corners.clone(),
            Err(_) => lumen::calib::detect_views(&input.images, &config).map(|(v, _)| v).unwrap_or_default(),
        };
        write_overlays(dir, &input.images, &views, board)?;
    }
    let cal = calibrated?.calibration;
    lumen::calib::file::write(out, &cal)?;
    for s in &cal.skipped {
        eprintln!("skipped {}: {}", s.name, s.reason);
    }
    for w in cal.warnings() {
        eprintln!("warning: {w}");
    }
    let k = &cal.camera_matrix;
    let d = &cal.distortion_coefficients;
    eprintln!(
        "{} of {} views; RMS reprojection error {:.4} px; fx {:.3} fy {:.3} cx {:.3} cy {:.3}; k1 {:.5} k2 {:.5} p1 {:.6} p2 {:.6} k3 {:.5}; {:.0} ms; wrote {}",
        cal.views.len(),
        files.len(),
        cal.rms_px,
        k[0][0],
        k[1][1],
        k[0][2],
        k[1][2],
        d[0],
        d[1],
        d[2],
        d[3],
        d[4],
        secs * 1e3,
        out.display()
    );
    Ok(())
}

/// One overlay PNG per image in `dir`, named after the image (made unique when two images
/// share a name).
fn write_overlays(
    dir: &Path,
    images: &[(String, lumen::image::filter::Grey)],
    views: &[(String, Vec<glam::DVec2>)],
    board: lumen::calib::detect::BoardSize,
) -> Result<()> {
    // The overlays are written together: on an error none is left behind.
    lumen::image::io::write_together(dir, |staged| -> Result<()> {
        let mut used = std::collections::HashSet::new();
        for (k, (name, img)) in images.iter().enumerate() {
            let corners = views.iter().find(|(n, _)| n == name).map(|(_, c)| c.as_slice());
            let canvas = lumen::calib::overlay::draw(img, board, corners);
            let stem = Path::new(name).file_stem().and_then(|s| s.to_str()).unwrap_or("view").to_string();
            let file =
                if used.insert(stem.clone()) { format!("{stem}.png") } else { format!("{stem}-{k}.png") };
            let values: Vec<u16> = canvas.rgb.iter().map(|&v| v as u16).collect();
            lumen::image::io::write_png_raw(&staged.join(file), canvas.width, canvas.height, 3, &values, 8)?;
        }
        Ok(())
    })
    .with_context(|| format!("--debug {}", dir.display()))
}

fn ps_cmd(dir: &Path, model: &str, start_iterations: Option<u64>, out: &Path) -> Result<()> {
    let model: lumen::photometric::Model =
        model.parse().map_err(|e: lumen::error::Invalid| anyhow::Error::new(e).context("--model"))?;
    let mut config = lumen::photometric::Config::new(model);
    if let Some(k) = start_iterations {
        config.start_iterations = lumen::photometric::check_start_iterations(k)
            .map_err(|e| anyhow::anyhow!("--start-iterations {e}"))?;
    }
    let t = std::time::Instant::now();
    let data = lumen::photometric::dataset::read(dir)?;
    let read_s = t.elapsed().as_secs_f64();
    let result = lumen::photometric::run(&data.input, &config)
        .with_context(|| format!("--dataset {}", dir.display()))?;
    let truth = data.truth.as_deref();
    lumen::photometric::write(out, &data.input, &result, truth)?;
    let s = &result.summary;
    let err = match truth.map(|t| lumen::photometric::accuracy(&result, t)) {
        Some(Some(a)) => format!(
            "mean angular error {:.3}°, median {:.3}° (error.png from 0 to {}°); ",
            a.mean_angular_error_deg,
            a.median_angular_error_deg,
            truth.map_or(0.0, |t| lumen::photometric::error_scale_deg(&result, t))
        ),
        Some(None) => "no solved pixel has a ground-truth normal; ".to_string(),
        None => String::new(),
    };
    eprintln!(
        "{}: {} pixels solved, {} masked; {err}{} lights, condition number {:.2}{}; read {read_s:.2} s, solved in {:.3} s ({:.1} M pixel-lights/s); wrote {}",
        s.model.name(),
        s.pixels,
        s.masked_pixels,
        s.lights,
        s.light_condition_number,
        if s.lights_nearly_coplanar { " (lights nearly coplanar)" } else { "" },
        s.time_s,
        s.pixel_lights_per_s / 1e6,
        out.display()
    );
    Ok(())
}

fn undistort_cmd(camera: &Path, alpha: f64, input: &Path, output: &Path) -> Result<()> {
    let ext = output.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if ext != "png" && ext != "exr" {
        bail!("{}: expected an output file name ending in .png or .exr", output.display());
    }
    let cal = lumen::calib::file::read(camera)?;
    let cam = cal.camera();
    let img = lumen::image::io::read(input)?;
    if (img.width, img.height) != (cam.width, cam.height) {
        bail!(
            "{} is {}×{}, but {} describes a {}×{} camera",
            input.display(),
            img.width,
            img.height,
            camera.display(),
            cam.width,
            cam.height
        );
    }
    if !(0.0..=1.0).contains(&alpha) {
        bail!("--alpha {alpha}: expected a value in [0, 1]");
    }
    // Past the range check, what fails is the camera's: its distortion or its image size.
    let new = lumen::calib::undistort::new_camera_matrix(&cam, alpha)
        .map_err(|e| anyhow::anyhow!("--camera {}: {e}", camera.display()))?;
    let out = lumen::calib::undistort::undistort_image(&img, &cam, &new);
    if ext == "exr" {
        lumen::image::io::write_exr(output, &out)?;
    } else {
        let codes: Vec<u16> = out.data.iter().map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u16).collect();
        lumen::image::io::write_png_raw(output, out.width, out.height, out.channels, &codes, 8)?;
    }
    eprintln!(
        "wrote {}; new camera matrix fx {:.3} fy {:.3} cx {:.3} cy {:.3}",
        output.display(),
        new.fx,
        new.fy,
        new.cx,
        new.cy
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::Cli;
    use clap::CommandFactory;

    /// Every argument of every command says what it is, and its default once: either clap's
    /// `[default: …]` or a "(default …)" in the text, never both.
    #[test]
    fn every_argument_is_described_with_its_default_once() {
        fn visit(cmd: &clap::Command, path: &str, bad: &mut Vec<String>) {
            for arg in cmd.get_arguments() {
                let id = arg.get_id().as_str();
                if id == "help" || id == "version" {
                    continue;
                }
                let help = arg.get_help().map(|h| h.to_string()).unwrap_or_default();
                if help.trim().is_empty() {
                    bad.push(format!("{path} {id}: no description"));
                }
                if !arg.get_default_values().is_empty() && help.contains("(default") {
                    bad.push(format!("{path} {id}: default given twice"));
                }
            }
            for sub in cmd.get_subcommands() {
                visit(sub, &format!("{path} {}", sub.get_name()), bad);
            }
        }
        let mut bad = Vec::new();
        visit(&Cli::command(), "lumen", &mut bad);
        assert!(bad.is_empty(), "{bad:#?}");
    }
}
