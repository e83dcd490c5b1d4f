//! A render denoised: the samples rendered as two halves of disjoint samples, the feature
//! buffers (albedo, normal, depth) of the same camera samples, and `image::denoise` over
//! them. One function for `lumen render --denoise`, `lumen bench denoise` and the pipeline's
//! cases with `denoise`, so all three filter the same inputs the same way.
//!
//! A render of one sample per pixel (or under a time budget, whose sample count is not
//! known in advance) has no halves: the filter's weights then come from the image and its
//! variance alone.

use super::features::{self, Features};
use super::integrators::{try_render, try_render_halves, Settings};
use super::{Error, Film, Scene};
use crate::image::denoise::{self, Feature, Input, Method, Output};
use crate::image::Image;
use std::time::Instant;

pub struct Denoised {
    /// The raw render (all samples).
    pub film: Film,
    /// Each half's mean, when the render was split.
    pub halves: Option<[Image; 2]>,
    /// The feature buffers, traced when the method uses them.
    pub features: Option<Features>,
    pub output: Output,
    /// Seconds spent rendering the film, tracing the features and filtering.
    pub render_seconds: f64,
    pub feature_seconds: f64,
    pub filter_seconds: f64,
}

impl Denoised {
    /// Render, features and filter together: what the denoised image cost.
    pub fn seconds(&self) -> f64 {
        self.render_seconds + self.feature_seconds + self.filter_seconds
    }
}

/// Renders `scene` with `settings` and denoises it with `filter`. Features are traced only
/// when the method uses them (the feature method, which `filter.method = None` picks).
pub fn render_denoised(
    scene: &Scene,
    settings: &Settings,
    filter: &denoise::Settings,
) -> Result<Denoised, Error> {
    filter.validate().map_err(denoise::Error::from)?;
    let t = Instant::now();
    let (film, halves) = if settings.time_budget.is_none() && settings.spp >= 2 {
        let (film, halves) = try_render_halves(scene, settings)?;
        (film, Some(halves))
    } else {
        (try_render(scene, settings)?, None)
    };
    let render_seconds = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let guided = filter.method.is_none() || filter.method == Some(Method::Feature);
    let features =
        guided.then(|| features::features(scene, &Settings { spp: film.samples, ..settings.clone() }));
    let feature_seconds = t.elapsed().as_secs_f64();
    let (output, filter_seconds) = filter_film(&film, halves.as_ref(), features.as_ref(), filter)?;
    Ok(Denoised { film, halves, features, output, render_seconds, feature_seconds, filter_seconds })
}

/// `filter` over a film already rendered (with its halves and features), and the seconds the
/// filter took. Features are used by the feature method only; the others ignore them.
pub fn filter_film(
    film: &Film,
    halves: Option<&[Image; 2]>,
    features: Option<&Features>,
    filter: &denoise::Settings,
) -> Result<(Output, f64), Error> {
    let guided = filter.method.is_none() || filter.method == Some(Method::Feature);
    let input = Input {
        color: &film.mean,
        variance: Some(&film.variance),
        halves: halves.map(|[a, b]| [a, b]),
        features: features
            .filter(|_| guided)
            .map(|f| {
                f.named()
                    .into_iter()
                    .map(|(name, b)| Feature {
                        name: format!("the {name} feature"),
                        image: &b.mean,
                        variance: Some(&b.variance),
                    })
                    .collect()
            })
            .unwrap_or_default(),
    };
    let t = Instant::now();
    let output = denoise::denoise(&input, filter)?;
    Ok((output, t.elapsed().as_secs_f64()))
}
