//! The light-transport algorithms, one file each, and the one table that names them.
//!
//! An integrator is a function that fills a film with its estimate of every pixel of the
//! settings' crop, querying the scene (intersections, surfaces, lights, materials) for what it
//! needs; the scene holds data and owns no loop. `REGISTRY` lists them by the name a scene
//! file's `[render] integrator`, `lumen render --integrator` and a pipeline case's
//! `integrator` use (pbrt-v4's `Integrator::Create` and Mitsuba 3's plugin names are the
//! model). Adding one is a file here and a line in `REGISTRY` (`docs/adding.md`).
//!
//! What integrators share lives here too: the row-parallel film loop for those that estimate
//! pixel by pixel (`render_rows`), the start of a camera path (`camera_path`) and Veach's power
//! heuristic.

pub mod bdpt;
pub mod light;
pub mod particle;
pub mod path;
pub mod photon;
pub mod sppm;
pub mod volpath;

use super::camera_ray::{camera_direction, camera_ray, needs_lens_sample};
use super::film::Film;
use super::geometry::Ray;
use super::sampler::Sampler;
use super::sampler::SamplerKind;
use super::scene::Scene;
use crate::image::Image;
use rayon::prelude::*;
use std::fmt;

/// One light-transport algorithm: its name and what it does (for `--help` and error
/// messages), and the function that renders with it.
pub struct Kind {
    pub name: &'static str,
    pub about: &'static str,
    /// Fills `film` (allocated for the settings' crop, zeroed) with the mean radiance and the
    /// variance of that mean of every pixel, and counts the samples it dropped.
    pub render: fn(&Scene, &Settings, &mut Film),
    /// Whether it renders participating media; scenes with media are refused otherwise
    /// (`refusal`).
    pub media: bool,
    /// Whether it keeps a time budget itself (its passes build on each other), rather than
    /// being called in rounds (`render_budgeted`).
    pub progressive: bool,
}

/// Every integrator lumen has, by name.
pub const REGISTRY: &[Kind] = &[
    Kind {
        name: "path",
        about: "unidirectional path tracing with next-event estimation and MIS",
        render: path::render,
        media: false,
        progressive: false,
    },
    Kind {
        name: "volpath",
        about: "path tracing through participating media (delta tracking, light sampling through media)",
        render: volpath::render,
        media: true,
        progressive: false,
    },
    Kind {
        name: "light",
        about: "light tracing: paths from the lights, every vertex joined to the camera (Mitsuba's ptracer)",
        render: light::render,
        media: false,
        progressive: false,
    },
    Kind {
        name: "pm",
        about: "photon mapping: photons from the lights in a kd-tree, density estimation where camera paths meet a diffuse surface",
        render: photon::render,
        media: false,
        progressive: false,
    },
    Kind {
        name: "sppm",
        about: "stochastic progressive photon mapping: per-pixel radii shrinking pass by pass, consistent",
        render: sppm::render,
        media: false,
        progressive: true,
    },
    Kind {
        name: "bdpt",
        about: "bidirectional path tracing: camera and light subpaths joined by every strategy, weighted by multiple importance sampling",
        render: bdpt::render,
        media: false,
        progressive: false,
    },
];

/// The integrator scenes use unless they name one.
pub const DEFAULT: &Kind = &REGISTRY[0];

impl fmt::Debug for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name)
    }
}

impl PartialEq for Kind {
    fn eq(&self, o: &Kind) -> bool {
        self.name == o.name
    }
}

/// What to render: samples, depth, seed, and which part of the image.
#[derive(Clone, Debug)]
pub struct Settings {
    /// The light-transport algorithm (`render::integrators`).
    pub integrator: &'static Kind,
    pub spp: u32,
    pub max_depth: u32,
    pub seed: u64,
    pub sampler: SamplerKind,
    /// Pixel window [x0, y0, x1, y1) to render; the whole image when `None`.
    pub crop: Option<[u32; 4]>,
    /// Worker threads; all available cores when `None`.
    pub threads: Option<usize>,
    pub progress: bool,
    /// Trace eight paths at once where the integrator and the scene allow it
    /// (`integrators::path::lanes`; the image is the same either way). False forces the one-path loop, for comparisons.
    pub lanes: bool,
    /// Index of the first sample (pass, for integrators that render in passes): a render of
    /// samples a..b followed by one of b..c draws what one of a..c draws.
    pub first_sample: u32,
    /// Seconds to render for (`render_budgeted`): samples are added in rounds until the next
    /// round would overrun the budget, or `spp` samples are reached. `None`: exactly `spp`.
    pub time_budget: Option<f64>,
    /// Photon mapping's settings (`pm`, `sppm`).
    pub photon: PhotonSettings,
}

/// What photon mapping (`pm`) and progressive photon mapping (`sppm`) take: a scene file's
/// `[render.photon]` table, `lumen render`'s photon flags, a pipeline case's `photon`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct PhotonSettings {
    /// Photons traced: in all for `pm` (default 16 per pixel), per pass for `sppm` (default
    /// one per pixel). At least 1, at most 10⁸: `pm` keeps about one photon of 64 bytes per
    /// bounce, so 10⁸ photon paths in a closed room take some 20 GB.
    pub count: Option<u64>,
    /// `pm`: the gather radius in scene units (default: none, the `k` nearest photons);
    /// `sppm`: the initial radius (default: one pixel footprint at each visible point).
    /// Finite, over 0, at most 10³⁰.
    pub radius: Option<f32>,
    /// `pm`: photons per density estimate when no radius is given (default 50, 1 to 10⁴).
    pub k: u32,
    /// `sppm`: the share of new photons a pass keeps, which shrinks the radius (default ⅔;
    /// Hachisuka & Jensen's α, strictly between 0 and 1).
    pub alpha: f32,
    /// `pm`: direct light by light sampling, caustics from their own map and the rest from one
    /// bounce into the global map (Jensen's final gather), instead of the global map seen
    /// directly (default false).
    pub final_gather: bool,
    /// How photons (`pm`) or visible points (`sppm`) are found: `kdtree` (kiddo's) or `grid`
    /// (default: each integrator's choice, in its module docs).
    pub index: Option<super::photons::IndexKind>,
}

impl Default for PhotonSettings {
    fn default() -> Self {
        PhotonSettings {
            count: None,
            radius: None,
            k: 50,
            alpha: 2.0 / 3.0,
            final_gather: false,
            index: Default::default(),
        }
    }
}

impl PhotonSettings {
    /// Checks every value against its range; the message names the setting.
    pub fn validate(&self) -> Result<(), crate::error::Invalid> {
        if let Some(n) = self.count {
            if !(1..=100_000_000).contains(&n) {
                return Err(crate::error::Invalid(format!("photon count {n}: expected 1 to 10⁸")));
            }
        }
        if let Some(r) = self.radius {
            if !(r > 0.0 && r <= 1e30) {
                return Err(crate::error::Invalid(format!(
                    "photon radius {r}: expected a finite length over 0 (at most 10³⁰)"
                )));
            }
        }
        if !(1..=10_000).contains(&self.k) {
            return Err(crate::error::Invalid(format!(
                "photon k {}: expected 1 to 10⁴ photons per estimate",
                self.k
            )));
        }
        if !(self.alpha > 0.0 && self.alpha < 1.0) {
            return Err(crate::error::Invalid(format!(
                "photon alpha {}: expected a number strictly between 0 and 1",
                self.alpha
            )));
        }
        Ok(())
    }
}

impl Settings {
    pub fn from_scene(scene: &Scene) -> Settings {
        Settings {
            integrator: scene.render.integrator,
            spp: scene.render.spp,
            max_depth: scene.render.max_depth,
            seed: scene.render.seed,
            sampler: scene.render.sampler,
            crop: None,
            threads: None,
            progress: false,
            lanes: true,
            first_sample: 0,
            time_budget: None,
            photon: scene.render.photon,
        }
    }
}

/// The integrator called `name`; the error lists the names there are.
pub fn find(name: &str) -> Result<&'static Kind, UnknownIntegrator> {
    REGISTRY.iter().find(|k| k.name == name).ok_or_else(|| UnknownIntegrator(name.to_string()))
}

/// A name no integrator has.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("unknown integrator `{0}`: expected one of {names}", names = names())]
pub struct UnknownIntegrator(pub String);

impl UnknownIntegrator {
    pub fn fault(&self) -> crate::Fault {
        crate::Fault::Unsupported
    }
}

/// The registry's names, as `"a", "b"` for messages.
pub fn names() -> String {
    REGISTRY.iter().map(|k| format!("\"{}\"", k.name)).collect::<Vec<_>>().join(", ")
}

impl std::str::FromStr for &'static Kind {
    type Err = UnknownIntegrator;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        find(s)
    }
}

impl<'de> serde::Deserialize<'de> for &'static Kind {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        find(&name).map_err(serde::de::Error::custom)
    }
}

impl serde::Serialize for Kind {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name)
    }
}

/// Why `kind` cannot render a scene (with participating media when `media`), if it cannot:
/// the message follows the integrator's name in an error.
pub fn refusal(kind: &Kind, media: bool) -> Option<String> {
    (media && !kind.media).then(|| {
        format!(
            "is \"{}\", which does not render participating media: a scene with media takes the volpath integrator ([render] integrator = \"volpath\"; in Mitsuba XML, <integrator type=\"volpath\">)",
            kind.name
        )
    })
}

/// The integrator a scene needs, and why, for a pipeline render case that names none: the
/// scene's own, unless that is the path tracer and the scene has a caustic a camera path
/// would find only by chance: a delta surface (mirror, glass) with a small light (a point or
/// spot light, or emitters whose area is below 1 % of the cross-section of the scene's
/// bounding sphere) and a diffuse surface to receive it. Such scenes take `sppm`, which
/// renders the caustic and what the glass shows of it.
pub fn choose(scene: &Scene) -> (&'static Kind, String) {
    use super::scene::Light;
    let own = scene.render.integrator;
    if own != DEFAULT {
        return (own, format!("the scene's own integrator, `{}`", own.name));
    }
    let material = |i: usize| &scene.materials[scene.info[i].material as usize];
    let delta = (0..scene.info.len()).find(|&i| {
        let b = &material(i).bsdf;
        b.is_delta() && !matches!(b, super::bsdf::Bsdf::Null)
    });
    let diffuse =
        (0..scene.info.len()).any(|i| !material(i).bsdf.is_delta() && material(i).emission.is_none());
    let emitting: f32 =
        scene.lights.iter().map(|l| if let Light::Area { area, .. } = l { *area } else { 0.0 }).sum();
    let cross = std::f32::consts::PI * scene.bounds_radius * scene.bounds_radius;
    let point = scene.lights.iter().any(|l| matches!(l, Light::Point { .. } | Light::Spot { .. }));
    let small = point || (emitting > 0.0 && emitting < 0.01 * cross);
    match delta {
        Some(i) if small && diffuse => {
            let sppm = find("sppm").unwrap_or(DEFAULT);
            let light = if point {
                "a point or spot light".to_string()
            } else {
                format!("emitters of {:.2} % of the scene's cross-section", 100.0 * emitting / cross)
            };
            (
                sppm,
                format!(
                    "`sppm`: {light} and a delta surface (material `{}`) before diffuse ones make a caustic, which a camera path finds only by chance",
                    material(i).name
                ),
            )
        }
        Some(_) if !small => (
            own,
            "`path`: the scene's lights are large, so a camera path finds them through its delta surfaces"
                .into(),
        ),
        Some(_) => (own, "`path`: no diffuse surface receives what the delta surfaces focus".into()),
        None => (own, "`path`: no delta surface (mirror, glass) to focus light into caustics".into()),
    }
}

/// Renders the scene into a film with the settings' integrator (which `refusal` must
/// accept for the scene; `try_render` checks).
pub fn render(scene: &Scene, settings: &Settings) -> Film {
    let (fw, fh) = film_size(scene, settings);
    render_into(scene, settings, Image::new(fw, fh, 3), Image::new(fw, fh, 3))
}

/// `render`, refusing an integrator that cannot render the scene (`refusal`), and with
/// `Error::OutOfMemory` (nothing allocated) a film whose memory cannot be had, where
/// `render` would abort: for films of a size a user chose.
pub fn try_render(scene: &Scene, settings: &Settings) -> Result<Film, super::Error> {
    if let Some(message) = refusal(settings.integrator, !scene.media.is_empty()) {
        return Err(super::Error::Unsupported { what: "the integrator".into(), message });
    }
    let (fw, fh) = film_size(scene, settings);
    let oom = || super::Error::OutOfMemory {
        what: format!("a {fw}×{fh} film (mean and variance, 3 float32 channels each)"),
        bytes: 2 * 3 * 4 * fw as u64 * fh as u64,
    };
    let mean = Image::try_new(fw, fh, 3).ok_or_else(oom)?;
    let variance = Image::try_new(fw, fh, 3).ok_or_else(oom)?;
    Ok(render_into(scene, settings, mean, variance))
}

fn film_size(scene: &Scene, settings: &Settings) -> (u32, u32) {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let [x0, y0, x1, y1] = settings.crop.unwrap_or([0, 0, w, h]);
    (x1.saturating_sub(x0), y1.saturating_sub(y0))
}

fn render_into(scene: &Scene, settings: &Settings, mean: Image, variance: Image) -> Film {
    match settings.time_budget {
        Some(seconds) if !settings.integrator.progressive => {
            render_budgeted(scene, settings, seconds, mean, variance)
        }
        _ => render_once(scene, settings, mean, variance),
    }
}

fn render_once(scene: &Scene, settings: &Settings, mean: Image, variance: Image) -> Film {
    let origin = settings.crop.map_or([0, 0], |c| [c[0], c[1]]);
    let mut film = Film { mean, variance, origin, dropped_samples: 0, samples: settings.spp };
    let mut work = || (settings.integrator.render)(scene, settings, &mut film);
    match settings.threads.and_then(|n| rayon::ThreadPoolBuilder::new().num_threads(n.max(1)).build().ok()) {
        Some(pool) => pool.install(work),
        None => work(),
    }
    film
}

/// Renders in rounds for about `seconds` of wall time: a first round of one sample (pass),
/// then rounds that double while the time measured per sample says the next fits in what is
/// left, stopping at `settings.spp`. The rounds' films are pooled as one render of all their
/// samples (`Pool`). The film says how many samples it reached.
fn render_budgeted(scene: &Scene, settings: &Settings, seconds: f64, mean: Image, variance: Image) -> Film {
    let start = std::time::Instant::now();
    let mut pool = Pool::new(mean.data.len());
    let mut round = 1u32;
    let (mut mean, mut variance) = (mean, variance);
    while pool.samples < settings.spp {
        let part = Settings {
            spp: round.min(settings.spp - pool.samples),
            first_sample: settings.first_sample + pool.samples,
            time_budget: None,
            ..settings.clone()
        };
        let film = render_once(scene, &part, mean, variance);
        pool.add(&film);
        (mean, variance) = (film.mean, film.variance);
        let elapsed = start.elapsed().as_secs_f64();
        let per_sample = elapsed / pool.samples as f64;
        let fits = ((seconds - elapsed) / per_sample).floor();
        if !(fits >= 1.0) {
            break;
        }
        round = (2 * part.spp).min(fits.min(u32::MAX as f64) as u32);
    }
    let origin = settings.crop.map_or([0, 0], |c| [c[0], c[1]]);
    pool.finish(mean, variance, origin)
}

/// Films of disjoint sample ranges of one render, pooled as one render of all their samples:
/// the means weighted by their sample counts, and each pixel's sum of squares recovered from
/// its mean and variance of the mean ((n − 1)·n·v + n·m²), so the pooled variance is that of
/// all the samples.
struct Pool {
    sum: Vec<f64>,
    sum_sq: Vec<f64>,
    samples: u32,
    dropped: u64,
}

impl Pool {
    fn new(len: usize) -> Pool {
        Pool { sum: vec![0.0; len], sum_sq: vec![0.0; len], samples: 0, dropped: 0 }
    }

    fn add(&mut self, film: &Film) {
        let n = film.samples as f64;
        for i in 0..self.sum.len() {
            let (m, v) = (film.mean.data[i] as f64, film.variance.data[i] as f64);
            self.sum[i] += n * m;
            self.sum_sq[i] += (n - 1.0) * n * v + n * m * m;
        }
        self.samples += film.samples;
        self.dropped += film.dropped_samples;
    }

    /// The pooled film, written into `mean` and `variance` (of the pooled size).
    fn finish(self, mut mean: Image, mut variance: Image, origin: [u32; 2]) -> Film {
        let n = self.samples as f64;
        for i in 0..self.sum.len() {
            let m = self.sum[i] / n;
            mean.data[i] = m as f32;
            variance.data[i] =
                if n > 1.0 { ((self.sum_sq[i] - n * m * m).max(0.0) / (n - 1.0) / n) as f32 } else { 0.0 };
        }
        Film { mean, variance, origin, dropped_samples: self.dropped, samples: self.samples }
    }
}

/// A render of `settings.spp` ≥ 2 samples as two halves of disjoint samples (the first
/// ⌊spp/2⌋, then the rest): the pooled film, equal to one render of all the samples up to
/// float rounding, and each half's mean, which the denoiser cross-filters
/// (`image::denoise`). Refused like `try_render`.
pub fn try_render_halves(scene: &Scene, settings: &Settings) -> Result<(Film, [Image; 2]), super::Error> {
    if settings.spp < 2 {
        return Err(super::Error::Unsupported {
            what: "half buffers".into(),
            message: format!(
                "{} sample per pixel cannot be split in two halves: expected at least 2",
                settings.spp
            ),
        });
    }
    let first = settings.spp / 2;
    let a = try_render(scene, &Settings { spp: first, time_budget: None, ..settings.clone() })?;
    let b = try_render(
        scene,
        &Settings {
            spp: settings.spp - first,
            first_sample: settings.first_sample + first,
            time_budget: None,
            ..settings.clone()
        },
    )?;
    let mut pool = Pool::new(a.mean.data.len());
    pool.add(&a);
    pool.add(&b);
    let film = pool.finish(a.mean.clone(), a.variance.clone(), a.origin);
    Ok((film, [a.mean, b.mean]))
}

/// Fills the film row by row, rows in parallel: `row(y, x0, x1)` gives the pixels x0..x1 of
/// image row y as (mean, variance of the mean, samples dropped), in order.
pub fn render_rows<R>(settings: &Settings, film: &mut Film, row: R)
where
    R: Fn(u32, u32, u32) -> Vec<([f32; 3], [f32; 3], u64)> + Sync,
{
    let [x0, y0] = film.origin;
    let fw = film.mean.width;
    let bar = super::progress_bar(film.mean.height as u64, "render", settings.progress);
    let dropped = std::sync::atomic::AtomicU64::new(0);
    film.mean
        .data
        .par_chunks_mut(3 * fw as usize)
        .zip(film.variance.data.par_chunks_mut(3 * fw as usize))
        .enumerate()
        .for_each(|(r, (mrow, vrow))| {
            let mut lost = 0;
            for (i, (m, v, d)) in row(y0 + r as u32, x0, x0 + fw).into_iter().enumerate() {
                mrow[3 * i..3 * i + 3].copy_from_slice(&m);
                vrow[3 * i..3 * i + 3].copy_from_slice(&v);
                lost += d;
            }
            if lost > 0 {
                dropped.fetch_add(lost, std::sync::atomic::Ordering::Relaxed);
            }
            bar.inc(1);
        });
    bar.finish_and_clear();
    film.dropped_samples += dropped.into_inner();
}

/// The start of sample `k` of pixel (x, y): its sampler, after the pixel position (and a thin
/// lens's sample) were drawn, and the camera ray, `None` beyond the fold of the distortion
/// (no scene ray maps there; the sample is black).
pub fn camera_path(scene: &Scene, settings: &Settings, x: u32, y: u32, k: u32) -> (Sampler, Option<Ray>) {
    let pixel_index = y as u64 * scene.camera.width as u64 + x as u64;
    let k = settings.first_sample as u64 + k as u64;
    let mut s = Sampler::with_kind(settings.sampler, settings.seed, pixel_index, k);
    let ray = camera_direction(scene, x, y, s.next2()).map(|d| {
        let lens_u = needs_lens_sample(scene, d).then(|| s.next2());
        camera_ray(scene, d, lens_u)
    });
    (s, ray)
}

/// Veach's power heuristic (β = 2) weight of strategy a against b.
#[inline]
pub fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 > 0.0 && a2.is_finite() {
        a2 / (a2 + b2)
    } else if a.is_infinite() {
        1.0
    } else {
        0.0
    }
}
