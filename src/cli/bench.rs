//! `lumen bench`: renderer speed and convergence, photon lookups, and calibration time against
//! OpenCV.

use super::{expand_images, parse_board};
use anyhow::{bail, Context, Result};
use lumen::render;
use std::path::Path;

/// `lumen bench render`'s options.
pub struct BenchRender {
    pub integrator: Option<&'static render::integrators::Kind>,
    pub spp: u32,
    pub max_depth: u32,
    pub threads: Option<usize>,
    pub repeat: u32,
    pub sampler: Option<String>,
    pub one_path: bool,
}

pub fn bench_render(scene_path: &Path, o: &BenchRender) -> Result<()> {
    let scene = render::load(scene_path)?;
    let mut settings = render::Settings::from_scene(&scene);
    settings.integrator = o.integrator.unwrap_or(settings.integrator);
    settings.spp = o.spp.max(1);
    settings.max_depth = o.max_depth.max(1);
    settings.threads = o.threads;
    settings.lanes = !o.one_path;
    settings.sampler = match o.sampler.as_deref() {
        None => settings.sampler,
        Some("independent") => render::sampler::SamplerKind::Independent,
        Some("sobol") => render::sampler::SamplerKind::Sobol,
        Some(other) => bail!("--sampler {other}: expected independent or sobol"),
    };
    let paths = scene.camera.width as f64 * scene.camera.height as f64 * settings.spp as f64;
    let mut best = f64::INFINITY;
    for _ in 0..o.repeat.max(1) {
        let t = std::time::Instant::now();
        let film = render::render(&scene, &settings);
        best = best.min(t.elapsed().as_secs_f64());
        std::hint::black_box(film);
    }
    let path = settings.integrator.name == "path";
    let lanes = if path && settings.lanes && render::integrators::path::lanes_supported(&scene, &settings) {
        "8 lanes"
    } else {
        "one path"
    };
    println!(
        "lumen {} {}: {}x{} spp {} depth {} {:?} sampler, {lanes}, threads {}: {best:.3} s, {:.3} M paths/s",
        settings.integrator.name,
        scene_path.display(),
        scene.camera.width,
        scene.camera.height,
        settings.spp,
        settings.max_depth,
        settings.sampler,
        o.threads.map_or_else(|| rayon::current_num_threads().to_string(), |t| t.to_string()),
        paths / best / 1e6
    );
    Ok(())
}

pub fn bench_convergence(
    scene_path: &Path,
    reference: &Path,
    spp: &str,
    threads: Option<usize>,
) -> Result<()> {
    let counts: Vec<u32> = spp
        .split(',')
        .map(|t| t.trim().parse::<u32>().ok().filter(|&n| n > 0))
        .collect::<Option<_>>()
        .with_context(|| format!("--spp {spp}: expected positive sample counts separated by commas"))?;
    let scene = render::load(scene_path)?;
    let truth = lumen::image::io::read_exr(reference)?;
    if (truth.width, truth.height) != (scene.camera.width, scene.camera.height) || truth.channels != 3 {
        bail!(
            "{}: {}×{}×{}, but the scene renders {}×{}×3",
            reference.display(),
            truth.width,
            truth.height,
            truth.channels,
            scene.camera.width,
            scene.camera.height
        );
    }
    // The reference's own noise sets a floor under every RMSE: say how high, when its variance
    // image (NAME_variance.exr beside it) is there.
    let var_path = reference.with_file_name(format!(
        "{}_variance.exr",
        reference.file_stem().and_then(|s| s.to_str()).unwrap_or("reference")
    ));
    if let Ok(var) = lumen::image::io::read_exr(&var_path) {
        let mean_var = var.data.iter().map(|&v| v as f64).sum::<f64>() / var.data.len().max(1) as f64;
        println!("reference noise (from {}): RMS {:.5}\n", var_path.display(), mean_var.sqrt());
    }
    println!("| spp | independent RMSE | time (s) | Sobol RMSE | time (s) | independent / Sobol |");
    println!("|---:|---:|---:|---:|---:|---:|");
    for &n in &counts {
        let mut row = Vec::new();
        for kind in [render::sampler::SamplerKind::Independent, render::sampler::SamplerKind::Sobol] {
            let mut settings = render::Settings::from_scene(&scene);
            settings.spp = n;
            settings.sampler = kind;
            settings.threads = threads;
            let t = std::time::Instant::now();
            let film = render::render(&scene, &settings);
            let secs = t.elapsed().as_secs_f64();
            row.push((lumen::image::metrics::rmse(&film.mean, &truth), secs));
        }
        println!(
            "| {n} | {:.5} | {:.2} | {:.5} | {:.2} | {:.2} |",
            row[0].0,
            row[0].1,
            row[1].0,
            row[1].1,
            row[0].0 / row[1].0
        );
    }
    Ok(())
}

/// Best of `repeat` runs of `f`, in seconds, and its last result.
fn best_of<T>(repeat: u32, mut f: impl FnMut() -> Result<T>) -> Result<(f64, T)> {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..repeat.max(1) {
        let t = std::time::Instant::now();
        let r = f()?;
        best = best.min(t.elapsed().as_secs_f64());
        out = Some(r);
    }
    Ok((best, out.expect("at least one run")))
}

pub fn bench_calibrate(patterns: &[String], board: &str, repeat: u32) -> Result<()> {
    let board = parse_board(board)?;
    let files = expand_images(patterns)?;
    let mut images = Vec::new();
    for f in &files {
        let img = lumen::image::io::read(f)?;
        images.push((f.display().to_string(), lumen::image::filter::Grey::from_image(&img)));
    }
    let size = images.first().map_or((0, 0), |(_, g)| (g.width as u32, g.height as u32));
    let config = lumen::calib::Config {
        board,
        square: 1.0,
        flags: Default::default(),
        detect: Default::default(),
        max_iterations: 100,
    };
    let (detect_s, (views, _)) = best_of(repeat, || Ok(lumen::calib::detect_views(&images, &config)?))?;
    let (calib_s, cal) = best_of(repeat, || Ok(lumen::calib::calibrate(&views, size, &config)?))?;
    println!("| library | views | detect (ms) | calibrate (ms) | total (ms) | RMS (px) |");
    println!("|---|---:|---:|---:|---:|---:|");
    println!(
        "| lumen {} ({} threads) | {} | {:.1} | {:.1} | {:.1} | {:.4} |",
        env!("CARGO_PKG_VERSION"),
        rayon::current_num_threads(),
        views.len(),
        detect_s * 1e3,
        calib_s * 1e3,
        (detect_s + calib_s) * 1e3,
        cal.rms_px
    );
    #[cfg(feature = "opencv")]
    {
        use lumen::cv;
        let mats: Vec<_> =
            files.iter().map(|f| cv::read_grey(f)).collect::<Result<_, _>>().map_err(anyhow::Error::msg)?;
        let (detect_s, found) = best_of(repeat, || {
            let mut found = Vec::new();
            for m in &mats {
                if let Some(c) = cv::find_corners(m, board.cols, board.rows).map_err(anyhow::Error::msg)? {
                    found.push(c);
                }
            }
            Ok(found)
        })?;
        let pts = lumen::calib::board_points(board, 1.0);
        let (calib_s, cvc) = best_of(repeat, || {
            cv::calibrate(&pts, &found, size, 30, f64::EPSILON).map_err(anyhow::Error::msg)
        })?;
        println!(
            "| OpenCV {} | {} | {:.1} | {:.1} | {:.1} | {:.4} |",
            opencv::core::CV_VERSION,
            found.len(),
            detect_s * 1e3,
            calib_s * 1e3,
            (detect_s + calib_s) * 1e3,
            cvc.rms_px
        );
    }
    Ok(())
}

/// `lumen bench hdr`: the response fits, the merge and the exposure fusion on a stack (the
/// frames decoded before timing), best of `repeat`; with the `opencv` feature, OpenCV's
/// `CalibrateDebevec`, `MergeDebevec` and `MergeMertens` on the same files in the same run.
pub fn bench_hdr(list: &Path, exclude: Option<[u16; 3]>, repeat: u32) -> Result<()> {
    use lumen::hdr::{self, Method};
    let frames = hdr::input::read_list(list)?;
    let input = hdr::input::read_stack(&frames, exclude)?;
    let pixel_frames = (input.width * input.height * input.frames.len()) as f64 / 1e6;
    let best = |method: Method, fusion: bool| -> Result<hdr::Summary> {
        let config = hdr::Config {
            method,
            fusion: fusion.then(hdr::fusion::Mertens::default),
            ..hdr::Config::default()
        };
        let mut best: Option<hdr::Summary> = None;
        for _ in 0..repeat.max(1) {
            let s = hdr::run(&input, &config)?.summary;
            best = Some(match best {
                None => s,
                Some(b) => hdr::Summary {
                    response_s: b.response_s.min(s.response_s),
                    merge_s: b.merge_s.min(s.merge_s),
                    fusion_s: b.fusion_s.min(s.fusion_s),
                    ..b
                },
            });
        }
        Ok(best.expect("at least one run"))
    };
    let debevec = best(hdr::Config::default().method, true)?;
    let robertson = best(Method::Robertson { iterations: hdr::ROBERTSON_MAX_ITERATIONS }, false)?;
    println!(
        "{} frames of {}×{} ({:.1} Mpixel-frames), best of {}",
        input.frames.len(),
        input.width,
        input.height,
        pixel_frames,
        repeat.max(1)
    );
    println!("| library | Debevec fit (ms) | Robertson fit (ms) | merge (ms) | merge (Mpixel-frames/s) | Mertens fusion (ms) |");
    println!("|---|---:|---:|---:|---:|---:|");
    println!(
        "| lumen {} ({} threads) | {:.1} | {:.1} | {:.1} | {:.0} | {:.1} |",
        env!("CARGO_PKG_VERSION"),
        rayon::current_num_threads(),
        debevec.response_s * 1e3,
        robertson.response_s * 1e3,
        debevec.merge_s * 1e3,
        pixel_frames / debevec.merge_s.max(1e-9),
        debevec.fusion_s * 1e3
    );
    #[cfg(feature = "opencv")]
    {
        let (files, times): (Vec<_>, Vec<f64>) = frames.iter().cloned().unzip();
        let stack = lumen::cv::CvStack::read(&files, &times).map_err(anyhow::Error::msg)?;
        let (fit_s, response) = best_of(repeat, || stack.calibrate_debevec().map_err(anyhow::Error::msg))?;
        let (merge_s, _) = best_of(repeat, || stack.merge_debevec(&response).map_err(anyhow::Error::msg))?;
        let (fusion_s, _) = best_of(repeat, || stack.merge_mertens().map_err(anyhow::Error::msg))?;
        println!(
            "| OpenCV {} ({} threads) | {:.1} | | {:.1} | {:.0} | {:.1} |",
            opencv::core::CV_VERSION,
            opencv::core::get_num_threads().unwrap_or(0),
            fit_s * 1e3,
            merge_s * 1e3,
            pixel_frames / merge_s.max(1e-9),
            fusion_s * 1e3
        );
    }
    Ok(())
}

/// `lumen bench photons`: the photon pass's speed, and the photons of `scene_path` found by
/// the kd-tree, the grid and a scan (module docs of `render::photons`). Queries run on one
/// thread; the photon pass on all.
pub fn bench_photons(scene_path: &Path, counts: &str, k: u32, queries: u32) -> Result<()> {
    use lumen::render::integrators::photon::trace_photons;
    use lumen::render::photons::{Index, IndexKind};
    use std::time::Instant;
    let scene = render::load(scene_path)?;
    let settings = render::Settings::from_scene(&scene);
    let counts: Vec<u64> = counts
        .split(',')
        .map(|c| c.trim().parse::<u64>().ok().filter(|n| (1..=100_000_000).contains(n)))
        .collect::<Option<_>>()
        .with_context(|| {
            format!("--counts {counts}: expected photon path counts 1 to 10⁸, comma-separated")
        })?;
    if !(1..=10_000).contains(&k) || queries == 0 {
        bail!("--k {k} / --queries {queries}: expected k from 1 to 10⁴ and at least one query");
    }
    // Query points: where camera rays through pixel centres (cycling) first hit.
    let (w, h) = (scene.camera.width, scene.camera.height);
    let mut at = Vec::new();
    for i in 0..(w as u64 * h as u64) {
        let px = glam::DVec2::new((i % w as u64) as f64, (i / w as u64) as f64);
        if let Some((o, d)) = scene.camera_ray(px) {
            let ray = render::geometry::Ray {
                origin: glam::Vec3A::from(o.as_vec3()),
                dir: glam::Vec3A::from(d.as_vec3()),
            };
            if let Some(hit) = scene.bvh.intersect(&ray, 0.0, f32::INFINITY) {
                at.push(ray.origin + ray.dir * hit.t);
            }
        }
    }
    if at.is_empty() {
        bail!("{}: no camera ray meets a surface", scene_path.display());
    }
    println!("paths  photons  |  photons/s traced  |  build s (kd-tree, grid)  |  radius queries/s (kd-tree, grid, scan)  |  k-nearest queries/s (kd-tree)  |  found per query");
    for &count in &counts {
        let t = Instant::now();
        let (photons, _) = trace_photons(&scene, &settings, count, 0);
        let traced = photons.len() as f64 / t.elapsed().as_secs_f64();
        let points: Vec<[f32; 3]> = photons.iter().map(|p| p.p.to_array()).collect();
        let n = points.len();
        // A radius finding about k photons: the median k-th nearest distance at 256 of the
        // query points, spread over the image.
        let tree = Index::build(IndexKind::Kdtree, &points, 1.0).context("indexing the photons")?;
        let mut r2: Vec<f32> = at
            .iter()
            .step_by((at.len() / 256).max(1))
            .filter_map(|&q| tree.nearest(q, k as usize, f32::MAX).last().map(|x| x.1))
            .collect();
        r2.sort_by(f32::total_cmp);
        let radius = r2.get(r2.len() / 2).copied().unwrap_or(1.0).sqrt();
        let build = |kind| {
            let t = Instant::now();
            let index = Index::build(kind, &points, radius);
            (index, t.elapsed().as_secs_f64())
        };
        let ((Some(kd), kd_build), (Some(grid), grid_build)) =
            (build(IndexKind::Kdtree), build(IndexKind::Grid))
        else {
            bail!("{n} photons: more than an index holds");
        };
        let rate = |index: &Index, m: usize| {
            let t = Instant::now();
            let mut found = 0u64;
            for i in 0..m {
                index.within(at[i % at.len()], radius, |_, _| found += 1);
            }
            (m as f64 / t.elapsed().as_secs_f64(), found as f64 / m as f64)
        };
        let (kd_rate, per) = rate(&kd, queries as usize);
        let (grid_rate, _) = rate(&grid, queries as usize);
        let m = (queries as usize).min(1000);
        let t = Instant::now();
        let mut found = 0u64;
        for i in 0..m {
            let q = at[i % at.len()];
            found += points
                .iter()
                .filter(|p| glam::Vec3A::from(**p).distance_squared(q) <= radius * radius)
                .count() as u64;
        }
        let scan_rate = m as f64 / t.elapsed().as_secs_f64();
        std::hint::black_box(found);
        let t = Instant::now();
        for i in 0..queries as usize {
            std::hint::black_box(kd.nearest(at[i % at.len()], k as usize, f32::MAX));
        }
        let knn_rate = queries as f64 / t.elapsed().as_secs_f64();
        println!(
            "{count:>9} {n:>9}  |  {traced:.3e}  |  {kd_build:.4} {grid_build:.4}  |  {kd_rate:.3e} {grid_rate:.3e} {scan_rate:.3e}  |  {knn_rate:.3e}  |  {per:.1}"
        );
    }
    Ok(())
}

/// `lumen bench denoise`: error against time of the denoisers on one scene. At each sample
/// count n: the raw render and each method on it (rendered as two halves, with the feature
/// buffers of the same samples; bilateral and nlmeans use the colour only), and the raw
/// render at 4n and 16n; relMSE against `reference`, and the time of the render plus the
/// features and the filter. With `out`, writes each n's inputs there (NAME-nSPP.exr, its
/// .variance, .half_a, .half_b, .feature_*) for other denoisers to run on, and the rows as
/// denoise.json.
pub fn bench_denoise(scene_path: &Path, reference: &Path, spp: &str, out: Option<&Path>) -> Result<()> {
    use lumen::image::denoise::{Method, Settings};
    use lumen::image::metrics::relmse;
    let counts: Vec<u32> = spp
        .split(',')
        .map(|t| t.trim().parse::<u32>().ok().filter(|&n| n >= 2))
        .collect::<Option<_>>()
        .with_context(|| format!("--spp {spp}: expected sample counts of at least 2 separated by commas"))?;
    let scene = super::scene::load(scene_path, &[])?;
    let truth = lumen::image::io::read_exr(reference)?;
    if (truth.width, truth.height, truth.channels) != (scene.camera.width, scene.camera.height, 3) {
        bail!(
            "{}: {}×{}×{}, but the scene renders {}×{}×3",
            reference.display(),
            truth.width,
            truth.height,
            truth.channels,
            scene.camera.width,
            scene.camera.height
        );
    }
    let name = scene_path.file_stem().and_then(|s| s.to_str()).unwrap_or("scene");
    let mut rows: Vec<serde_json::Value> = Vec::new();
    let mut row = |spp: u32, what: &str, err: f64, secs: f64| {
        println!("| {spp} | {what} | {err:.3e} | {secs:.2} |");
        rows.push(serde_json::json!({"spp": spp, "what": what, "relmse": err, "seconds": secs}));
    };
    println!(
        "{name}, {}×{}: relMSE against {}\n",
        scene.camera.width,
        scene.camera.height,
        reference.display()
    );
    println!("| spp | image | relMSE | time (s) |");
    println!("|---:|---|---:|---:|");
    for &n in &counts {
        let mut settings = render::Settings::from_scene(&scene);
        settings.spp = n;
        let d = render::denoised::render_denoised(
            &scene,
            &settings,
            &Settings { method: Some(Method::Feature), ..Settings::default() },
        )?;
        let (film, halves) = (&d.film, d.halves.as_ref().context("a render of at least 2 spp has halves")?);
        let features = d.features.as_ref().context("the feature method traces features")?;
        row(n, "raw", relmse(&film.mean, &truth, None), d.render_seconds);
        for method in Method::ALL {
            let (err, secs) = if method == Method::Feature {
                (relmse(&d.output.image, &truth, None), d.seconds())
            } else {
                let filter = Settings { method: Some(method), ..Settings::default() };
                let (o, secs) = render::denoised::filter_film(film, Some(halves), None, &filter)?;
                (relmse(&o.image, &truth, None), d.render_seconds + secs)
            };
            row(n, method.name(), err, secs);
        }
        if let Some(dir) = out {
            std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
            let base = dir.join(format!("{name}-{n}spp.exr"));
            let mut images = vec![
                (base.clone(), &film.mean),
                (super::render_cmd::sibling(&base, "variance"), &film.variance),
                (super::render_cmd::sibling(&base, "half_a"), &halves[0]),
                (super::render_cmd::sibling(&base, "half_b"), &halves[1]),
            ];
            for (f, b) in features.named() {
                images.push((super::render_cmd::sibling(&base, &format!("feature_{f}")), &b.mean));
                images
                    .push((super::render_cmd::sibling(&base, &format!("feature_{f}.variance")), &b.variance));
            }
            for (path, img) in images {
                lumen::image::io::write_exr(&path, img)?;
            }
        }
        for more in [4, 16] {
            settings.spp = n * more;
            let t = std::time::Instant::now();
            let film = render::try_render(&scene, &settings)?;
            row(n * more, "raw", relmse(&film.mean, &truth, None), t.elapsed().as_secs_f64());
        }
    }
    if let Some(dir) = out {
        let path = dir.join(format!("{name}-denoise.json"));
        std::fs::write(&path, serde_json::to_string_pretty(&rows)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}
