//! Finding a ColorChecker Classic 24 in a photograph by itself: the four outer corners of its
//! 6 × 4 cell grid, in `color fit --corners`'s order (corner 0 by patch 1 "dark skin", then
//! along the row of six).
//!
//! The method, in four steps:
//! 1. `regions`: candidate squares, the flat regions an edge map leaves that are shaped like
//!    a patch in perspective, at a working scale of about a thousand pixels across (then at
//!    twice and four times that when no chart is found, for a chart small in a large frame).
//! 2. `lattice`: candidates grouped into a lattice of integer cells and a homography, grown
//!    outwards from each candidate and its neighbours so perspective is followed.
//! 3. `layout`: which placement of the chart on the lattice (four rotations, and offsets when
//!    rows or columns were missed) matches the chart's published colours through an affine
//!    map; the residual of that match says whether it is a ColorChecker at all.
//! 4. `edges`: the homography refined at full resolution on the patches' edges, to a fraction
//!    of a pixel.
//!
//! It answers with a clear refusal when there is no chart ("no chart found: N candidate
//! squares, best lattice M of 24"), when the chart is cut by the frame, when the grid's
//! colours are not a ColorChecker Classic's in any orientation, and when there are two charts.
//! There is no OpenCV code here: OpenCV's `mcc` detector and colour-checker-detection are
//! measured beside it (`tools/chart_detect_peers.py`), not used.

mod edges;
mod lattice;
mod layout;
pub mod overlay;
mod regions;

use crate::error::Invalid;
use crate::image::Image;
use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

/// Fewest lattice cells with a candidate square for a chart to be considered.
pub const MIN_CELLS: usize = 8;
/// Longest side of the first working scale (pixels).
const WORKING_SIDE: usize = 1000;
/// Patch half side as a share of the pitch, where the refinement starts: a ColorChecker
/// Classic's printed patch covers 88 % of its cell (0.440–0.442 on the ten shared photographs,
/// as their edges measure it).
const HALF_SIDE: f64 = 0.44;

/// A chart found in a photograph.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Detection {
    /// The outer corners of the 6 × 4 cell grid (full-resolution pixels, centres at integers):
    /// by patch 1 "dark skin", by patch 6 "bluish green", by patch 24 "black 2", by patch 19
    /// "white 9.5".
    pub corners: [[f64; 2]; 4],
    /// 0–1: the share of the 24 cells found as squares, times how much better the chosen
    /// orientation's colours match than the runner-up's (1 − ρ / ρ₂).
    pub confidence: f64,
    /// Cells of the lattice found as candidate squares (of 24).
    pub cells_found: usize,
    /// Candidate squares in the image at the scale the chart was found.
    pub candidates: usize,
    /// Relative residual ρ of the colour match of the chosen orientation, and of the next best.
    pub colour_residual: f64,
    pub runner_up_residual: Option<f64>,
    /// Whether the edges refined the homography (else it is the patch centroids').
    pub refined: bool,
    /// Edge points the refinement used, and their RMS distance from the fitted lines (px).
    pub edge_points: usize,
    pub edge_rms_px: Option<f64>,
    /// The patch's half side as a share of the pitch, per axis, as the edges measured it.
    pub patch_half_side: [f64; 2],
    /// Full-resolution pixels per working pixel at the scale the chart was found.
    pub working_factor: usize,
    /// Chart cell coordinates (u, v) ∈ [0, 6] × [0, 4] → undistorted image, row-major.
    pub homography: [[f64; 3]; 3],
    /// The radial term the edges measured (`edges::Lens`): an image point x is undistorted as
    /// c + (x − c)(1 + k·ρ²), ρ = |x − c| over the half diagonal, c the image centre. The
    /// corners are the homography's, distorted back into the image.
    pub radial_k: f64,
}

impl Detection {
    /// Chart cell coordinates → image pixels (the homography, then the lens).
    pub fn to_image(&self, width: u32, height: u32, u: f64, v: f64) -> [f64; 2] {
        let h = Matrix3::from_fn(|r, c| self.homography[r][c]);
        edges::Lens::new(width as usize, height as usize, self.radial_k).distort(lattice::apply(&h, [u, v]))
    }
}

/// Detects the chart. `linear` says the values are linear (EXR or raw-derived), to be scaled
/// and sRGB-encoded for the detector; otherwise they are taken as sRGB-encoded code values.
pub fn detect(image: &Image, linear: bool) -> Result<Detection, Invalid> {
    if image.channels < 3 {
        return Err(format!(
            "the image has {} channel(s): finding a colour chart needs a colour (RGB) image",
            image.channels
        )
        .into());
    }
    let (w, h) = (image.width as usize, image.height as usize);
    if w < 48 || h < 48 {
        return Err(
            format!("the image is {w}×{h} pixels: too small to hold a 6×4 chart (at least 48×48)").into()
        );
    }
    let reference: Vec<[f64; 3]> =
        super::spectra::chart_reference_d50().into_iter().map(|(_, xyz)| xyz).collect();
    let exposures: Vec<Option<f32>> =
        if linear { regions::exposures(image).into_iter().map(Some).collect() } else { vec![None] };
    let mut best_cells = 0;
    let mut most_candidates = 0;
    let mut nearest: Option<String> = None;
    for exposure in exposures {
        let enc = regions::Encoded::new(image, exposure);
        let mut factor = (w.max(h) as f64 / WORKING_SIDE as f64).round().max(1.0) as usize;
        loop {
            match attempt(&enc, factor, &reference)? {
                Attempt::Found(d) => return Ok(d),
                Attempt::Missed { candidates, cells, near } => {
                    most_candidates = most_candidates.max(candidates);
                    best_cells = best_cells.max(cells);
                    nearest = nearest.or(near);
                }
            }
            if factor == 1 {
                break;
            }
            factor = (factor / 2).max(1);
        }
    }
    Err(nearest
        .unwrap_or_else(|| {
            format!("no chart found: {most_candidates} candidate squares, best lattice {best_cells} of 24")
        })
        .into())
}

/// What one exposure at one working scale gave.
enum Attempt {
    Found(Detection),
    /// No chart: the candidates, the largest lattice, and why the nearest grid was refused.
    Missed {
        candidates: usize,
        cells: usize,
        near: Option<String>,
    },
}

/// Looks for the chart at one working scale; an error for a finding that ends the search (two
/// charts, a chart cut by the frame).
fn attempt(enc: &regions::Encoded, factor: usize, reference: &[[f64; 3]]) -> Result<Attempt, Invalid> {
    let work = regions::Work::new(enc, factor);
    let candidates = regions::find(&work);
    let lattices = lattice::find(&candidates);
    let cells = lattices.first().map_or(0, |l| l.members.len());
    let mut near = None;
    let mut charts = Vec::new();
    for l in lattices.iter().filter(|l| l.members.len() >= MIN_CELLS).take(4) {
        let placed = layout::placements(&work, l, reference);
        let Some(best) = placed.first() else { continue };
        if best.residual <= layout::MAX_RESIDUAL {
            let runner_up = placed.get(1).map(|p| p.residual).filter(|r| r.is_finite());
            charts.push((l, best.clone(), runner_up));
        } else if near.is_none() {
            near = Some(format!(
                "a grid of {} squares was found, but its colours match a ColorChecker Classic's in no orientation (colour residual {:.2}, at most {} for a chart)",
                l.members.len(),
                best.residual,
                layout::MAX_RESIDUAL
            ));
        }
    }
    if charts.len() >= 2 {
        let at = |p: &layout::Placement| {
            let c = work.to_full(lattice::apply(&p.h, [3.0, 2.0]));
            format!("({:.0}, {:.0})", c[0], c[1])
        };
        return Err(format!(
            "{} charts found, centred at {}: crop the image to the one to use",
            charts.len(),
            charts.iter().map(|c| at(&c.1)).collect::<Vec<_>>().join(" and ")
        )
        .into());
    }
    let Some((l, placed, runner_up)) = charts.pop() else {
        return Ok(Attempt::Missed { candidates: candidates.len(), cells, near });
    };
    if !placed.outside.is_empty() {
        let names: Vec<String> = placed.outside.iter().map(|k| (k + 1).to_string()).collect();
        return Err(format!(
            "the chart is cut by the frame: patch(es) {} lie outside the image; take the photograph with the whole chart in view",
            names.join(", ")
        )
        .into());
    }
    let f = factor as f64;
    let scale = Matrix3::new(f, 0.0, 0.5 * (f - 1.0), 0.0, f, 0.5 * (f - 1.0), 0.0, 0.0, 1.0);
    let coarse = scale * placed.h;
    let refined = edges::refine(enc, &coarse, [HALF_SIDE; 2]);
    let hm = refined.as_ref().map_or(coarse, |r| r.h);
    let hm = hm / hm[(2, 2)];
    let lens = refined.as_ref().map_or(edges::Lens::new(enc.width, enc.height, 0.0), |r| r.lens);
    let corners = [(0.0, 0.0), (6.0, 0.0), (6.0, 4.0), (0.0, 4.0)]
        .map(|(u, v)| lens.distort(lattice::apply(&hm, [u, v])));
    if corners.iter().flatten().any(|v| !v.is_finite()) {
        return Err("the chart's grid maps to no finite corners".into());
    }
    let share = (l.members.len() as f64 / 24.0).min(1.0);
    let margin = runner_up.map_or(1.0, |r| (1.0 - placed.residual / r).clamp(0.0, 1.0));
    Ok(Attempt::Found(Detection {
        corners,
        confidence: share * margin,
        cells_found: l.members.len(),
        candidates: candidates.len(),
        colour_residual: placed.residual,
        runner_up_residual: runner_up,
        refined: refined.is_some(),
        edge_points: refined.as_ref().map_or(0, |r| r.points),
        edge_rms_px: refined.as_ref().map(|r| r.rms_px),
        patch_half_side: refined.as_ref().map_or([HALF_SIDE; 2], |r| r.half),
        working_factor: factor,
        homography: [0, 1, 2].map(|r| [0, 1, 2].map(|c| hm[(r, c)])),
        radial_k: lens.k,
    }))
}
