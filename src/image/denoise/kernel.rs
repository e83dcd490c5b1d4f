//! The one weighted average all three methods are: every pixel p becomes
//!
//!   F(p) = Σ_q w(p, q) · y(q) / Σ_q w(p, q),   q over the (2r+1)² window around p,
//!
//! with weights computed from a *guide* (a colour image with the variance of each pixel, and
//! optionally feature buffers with theirs) and applied to a *data* image, which is the guide's
//! colour itself or, for cross-filtering, the other half buffer.
//!
//! Colour weight (Rousselle, Knaus & Zwicker 2012), per channel i and averaged over channels
//! and over the (2f+1)² patch around p (f = 0 for the bilateral filter):
//!
//!   d²ᵢ(p, q) = ((uᵢ(p) − uᵢ(q))² − (Varᵢ(p) + min(Varᵢ(p), Varᵢ(q)))) / (ε + k²·(Varᵢ(p) + Varᵢ(q)))
//!   w_c = exp(−max(0, d²))
//!
//! The subtracted variance cancels the expected squared difference two noisy pixels of equal
//! mean have, so the distance measures the difference of their means, not their noise.
//!
//! Feature weight (Rousselle, Manzi & Zwicker 2013), per feature j, with no patch:
//!
//!   Φⱼ(p, q) = (|fⱼ(p) − fⱼ(q)|² − (Varⱼ(p) + min(Varⱼ(p), Varⱼ(q)))) / (k_f² · max(τ, Varⱼ(p), |∇fⱼ(p)|²))
//!   w_f = exp(−max_j Φⱼ),   w = min(w_c, w_f)
//!
//! The bilateral filter adds a spatial Gaussian exp(−|p − q|² / 2σ_s²).
//!
//! **Strengths.** Scaling k and k_f by s divides every distance by s² (ε is negligible beside
//! k²·Var wherever there is noise), so the filters of several strengths share one distance
//! computation and differ only in the exponential: SURE then picks among them per pixel.
//!
//! **Layout.** The loop is offset-major (Buades et al.'s fast NL-means): for each offset o of
//! the window, the per-pixel distance to p + o is computed over a tile and summed over the
//! patch with a separable box sum, so a patch costs O(1) per pixel and offset rather than
//! O(f²). Tiles run in parallel with rayon; each copies its neighbourhood (clamped at the
//! image border) into planar buffers, so the inner loops are plain slices the compiler
//! vectorises. Neighbours q outside the image take no part (their weight is 0).

use rayon::prelude::*;

/// One image as separate planes: `data[c * w * h + y * w + x]`.
#[derive(Clone, Debug)]
pub struct Planes {
    pub w: usize,
    pub h: usize,
    pub c: usize,
    pub data: Vec<f32>,
}

impl Planes {
    pub fn plane(&self, c: usize) -> &[f32] {
        &self.data[c * self.w * self.h..(c + 1) * self.w * self.h]
    }
}

/// A feature buffer as the feature weight reads it: its planes, their variance (per channel),
/// and 1 / (k_f² · max(τ, Var(p), |∇f(p)|²)) per pixel, variance and gradient averaged over
/// channels.
pub struct FeatureGuide {
    pub value: Planes,
    pub variance: Planes,
    pub inv_norm: Vec<f32>,
}

/// What the weights are computed from.
pub struct Guide<'a> {
    pub color: &'a Planes,
    pub variance: &'a Planes,
    pub features: &'a [FeatureGuide],
}

/// The filter's settings as the kernel reads them (validated by the caller).
#[derive(Clone, Debug)]
pub struct Params {
    /// Patch radius f (0: pixel to pixel).
    pub patch: usize,
    /// Window radius r.
    pub window: usize,
    /// Colour sensitivity k (larger: more smoothing).
    pub k: f32,
    /// Spatial σ_s in pixels (the bilateral filter), or none.
    pub spatial_sigma: Option<f32>,
    /// Strength multipliers s of k and k_f: one filtered image per strength.
    pub strengths: Vec<f32>,
}

/// ε of the colour distance: keeps the division finite where both variances are 0.
const EPSILON: f32 = 1e-10;

/// Tile side in pixels.
const TILE: usize = 32;

/// Filters `data` with the weights of `guide`, once per strength. Returns, per strength, the
/// filtered image and the centre weight's share w(p, p) / Σ_q w(p, q) of every pixel (the
/// derivative ∂F(p)/∂y(p) SURE needs; w(p, p) = 1 always, as every distance of a pixel to
/// itself is ≤ 0).
pub fn filter(guide: &Guide, data: &Planes, params: &Params) -> Vec<(Planes, Vec<f32>)> {
    let (w, h) = (data.w, data.h);
    let tiles: Vec<(usize, usize)> = (0..h.div_ceil(TILE))
        .flat_map(|ty| (0..w.div_ceil(TILE)).map(move |tx| (tx * TILE, ty * TILE)))
        .collect();
    let results: Vec<TileOut> =
        tiles.par_iter().map(|&(x0, y0)| filter_tile(guide, data, params, x0, y0)).collect();
    let ns = params.strengths.len();
    let mut out: Vec<(Planes, Vec<f32>)> = (0..ns)
        .map(|_| (Planes { w, h, c: data.c, data: vec![0.0; w * h * data.c] }, vec![0.0; w * h]))
        .collect();
    for ((x0, y0), t) in tiles.iter().zip(results) {
        let (tw, th) = (t.w, t.h);
        for (s, (img, centre)) in out.iter_mut().enumerate() {
            for y in 0..th {
                let row = (y0 + y) * w + x0;
                let local = y * tw;
                let wsum = &t.weight[s][local..local + tw];
                for (k, &ws) in wsum.iter().enumerate() {
                    centre[row + k] = 1.0 / ws;
                }
                for c in 0..data.c {
                    let acc = &t.sum[s][c][local..local + tw];
                    let dst = &mut img.data[c * w * h + row..c * w * h + row + tw];
                    for ((d, &a), &ws) in dst.iter_mut().zip(acc).zip(wsum) {
                        *d = a / ws;
                    }
                }
            }
        }
    }
    out
}

/// One tile's weighted sums: per strength, per channel Σ w·y, and Σ w.
struct TileOut {
    w: usize,
    h: usize,
    sum: Vec<Vec<Vec<f32>>>,
    weight: Vec<Vec<f32>>,
}

/// A neighbourhood of planes copied with clamped coordinates: local (i, j) is image
/// (x0 + i − pad, y0 + j − pad), clamped.
struct Local {
    data: Vec<f32>,
}

fn local(p: &Planes, x0: usize, y0: usize, lw: usize, lh: usize, pad: usize) -> Local {
    local_plane_set(p.w, p.h, p.c, |c| p.plane(c), x0, y0, lw, lh, pad)
}

fn local_plane_set<'a>(
    w: usize,
    h: usize,
    channels: usize,
    plane: impl Fn(usize) -> &'a [f32],
    x0: usize,
    y0: usize,
    lw: usize,
    lh: usize,
    pad: usize,
) -> Local {
    let mut data = Vec::with_capacity(channels * lw * lh);
    for c in 0..channels {
        let src = plane(c);
        for j in 0..lh {
            let y = (y0 as isize + j as isize - pad as isize).clamp(0, h as isize - 1) as usize;
            for i in 0..lw {
                let x = (x0 as isize + i as isize - pad as isize).clamp(0, w as isize - 1) as usize;
                data.push(src[y * w + x]);
            }
        }
    }
    Local { data }
}

/// `tile` compiled for the widest vector instructions the processor has, chosen at run time
/// (AVX-512 or AVX2 with FMA; the baseline x86-64 build has SSE2 only, where `floor` in
/// `exp_neg` is a library call per element).
fn filter_tile(guide: &Guide, data: &Planes, params: &Params, x0: usize, y0: usize) -> TileOut {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx512f,fma")]
        fn avx512(guide: &Guide, data: &Planes, params: &Params, x0: usize, y0: usize) -> TileOut {
            tile(guide, data, params, x0, y0)
        }
        #[target_feature(enable = "avx2,fma")]
        fn avx2(guide: &Guide, data: &Planes, params: &Params, x0: usize, y0: usize) -> TileOut {
            tile(guide, data, params, x0, y0)
        }
        if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the processor has AVX-512F and FMA.
            return unsafe { avx512(guide, data, params, x0, y0) };
        }
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the processor has AVX2 and FMA.
            return unsafe { avx2(guide, data, params, x0, y0) };
        }
    }
    tile(guide, data, params, x0, y0)
}

#[inline(always)]
fn tile(guide: &Guide, data: &Planes, params: &Params, x0: usize, y0: usize) -> TileOut {
    let (w, h) = (data.w, data.h);
    let (tw, th) = (TILE.min(w - x0), TILE.min(h - y0));
    let (f, r) = (params.patch, params.window);
    let pad = f + r;
    let (lw, lh) = (tw + 2 * pad, th + 2 * pad);
    let plane_len = lw * lh;
    let color = local(guide.color, x0, y0, lw, lh, pad);
    let var = local(guide.variance, x0, y0, lw, lh, pad);
    let values = local(data, x0, y0, lw, lh, pad);
    let features: Vec<(Local, Local, Local, usize)> = guide
        .features
        .iter()
        .map(|g| {
            let grad = local_plane_set(w, h, 1, |_| &g.inv_norm[..], x0, y0, lw, lh, pad);
            (local(&g.value, x0, y0, lw, lh, pad), local(&g.variance, x0, y0, lw, lh, pad), grad, g.value.c)
        })
        .collect();
    let nc = guide.color.c;
    let ns = params.strengths.len();
    let mut sum = vec![vec![vec![0.0f32; tw * th]; data.c]; ns];
    let mut weight = vec![vec![0.0f32; tw * th]; ns];

    // Per-pixel colour distance over the tile grown by f, its horizontal box sum, the patch
    // distance, the feature distance.
    let (pw, ph) = (tw + 2 * f, th + 2 * f);
    let mut dist = vec![0.0f32; pw * ph];
    let mut hsum = vec![0.0f32; tw * ph];
    let mut patch = vec![0.0f64; tw];
    let mut vsum = vec![0.0f32; tw * th];
    let mut fdist = vec![0.0f32; tw];
    let mut facc = vec![0.0f32; tw];
    let patch_norm = 1.0 / ((2 * f + 1) * (2 * f + 1) * nc) as f32;
    let k2 = params.k * params.k;
    let inv_s2: Vec<f32> = params.strengths.iter().map(|s| 1.0 / (s * s)).collect();
    let r_i = r as isize;
    for dy in -r_i..=r_i {
        // Rows of the tile whose neighbour row y + dy is inside the image.
        let ya = (-(y0 as isize) - dy).max(0) as usize;
        let yb = ((h as isize - y0 as isize - dy).min(th as isize)).max(0) as usize;
        if ya >= yb {
            continue;
        }
        for dx in -r_i..=r_i {
            let xa = (-(x0 as isize) - dx).max(0) as usize;
            let xb = ((w as isize - x0 as isize - dx).min(tw as isize)).max(0) as usize;
            if xa >= xb {
                continue;
            }
            let spatial = match params.spatial_sigma {
                Some(s) => (-((dx * dx + dy * dy) as f32) / (2.0 * s * s)).exp(),
                None => 1.0,
            };
            let offset = dy * lw as isize + dx;
            // Colour distance at every pixel of the tile grown by f (local row j + r, col i + r).
            dist.fill(0.0);
            for c in 0..nc {
                let u = &color.data[c * plane_len..(c + 1) * plane_len];
                let v = &var.data[c * plane_len..(c + 1) * plane_len];
                for j in 0..ph {
                    let p0 = (j + r) * lw + r;
                    let q0 = (p0 as isize + offset) as usize;
                    let (up, uq) = (&u[p0..p0 + pw], &u[q0..q0 + pw]);
                    let (vp, vq) = (&v[p0..p0 + pw], &v[q0..q0 + pw]);
                    let d = &mut dist[j * pw..(j + 1) * pw];
                    for i in 0..pw {
                        let diff = up[i] - uq[i];
                        let num = diff * diff - (vp[i] + vp[i].min(vq[i]));
                        d[i] += num / (EPSILON + k2 * (vp[i] + vq[i]));
                    }
                }
            }
            // Horizontal box sums of width 2f + 1.
            for j in 0..ph {
                let d = &dist[j * pw..(j + 1) * pw];
                let hs = &mut hsum[j * tw..(j + 1) * tw];
                let mut acc: f64 = d[..2 * f].iter().map(|&x| x as f64).sum();
                for i in 0..tw {
                    acc += d[i + 2 * f] as f64;
                    hs[i] = acc as f32;
                    acc -= d[i] as f64;
                }
            }
            // Vertical box sums of height 2f + 1, one running sum down the rows: patch
            // distance of row y in vsum[y·tw..], clamped at 0. Both running sums are kept in
            // f64: where the variance is near zero a distance across an edge reaches 10⁸ and
            // more, and an f32 sum that adds and later subtracts it would leave a residue
            // larger than the distances of the flat patches after it.
            let vacc = &mut patch;
            vacc.fill(0.0);
            for j in ya..ya + 2 * f {
                for (p, &s) in vacc.iter_mut().zip(&hsum[j * tw..(j + 1) * tw]) {
                    *p += s as f64;
                }
            }
            for y in ya..yb {
                let (add, sub) = (&hsum[(y + 2 * f) * tw..(y + 2 * f + 1) * tw], &hsum[y * tw..(y + 1) * tw]);
                let out = &mut vsum[y * tw..(y + 1) * tw];
                for (((o, p), &a), &b) in out.iter_mut().zip(vacc.iter_mut()).zip(add).zip(sub) {
                    *p += a as f64;
                    *o = (*p as f32 * patch_norm).max(0.0);
                    *p -= b as f64;
                }
            }
            for y in ya..yb {
                let patch = &vsum[y * tw..(y + 1) * tw];
                // Feature distance, the largest over features.
                fdist.fill(0.0);
                for (value, fvar, norm, fc) in &features {
                    let p0 = (y + pad) * lw + pad;
                    let q0 = (p0 as isize + offset) as usize;
                    facc.fill(0.0);
                    for c in 0..*fc {
                        let u = &value.data[c * plane_len..(c + 1) * plane_len];
                        let v = &fvar.data[c * plane_len..(c + 1) * plane_len];
                        let (up, uq, vp, vq) =
                            (&u[p0..p0 + tw], &u[q0..q0 + tw], &v[p0..p0 + tw], &v[q0..q0 + tw]);
                        for i in 0..tw {
                            let diff = up[i] - uq[i];
                            facc[i] += diff * diff - (vp[i] + vp[i].min(vq[i]));
                        }
                    }
                    let inv_c = 1.0 / *fc as f32;
                    for ((d, &a), &n) in fdist.iter_mut().zip(&facc).zip(&norm.data[p0..p0 + tw]) {
                        *d = d.max(a * inv_c * n);
                    }
                }
                let q0 = ((y + pad) * lw + pad) as isize + offset;
                let row = y * tw;
                let n = xb - xa;
                let (patch, fdist) = (&patch[xa..xb], &fdist[xa..xb]);
                let guided = !features.is_empty();
                for (s, &inv) in inv_s2.iter().enumerate() {
                    let wsum = &mut weight[s][row + xa..row + xb];
                    let mut wrow = [0.0f32; TILE];
                    let wrow = &mut wrow[..n];
                    for (((wt, ws), &pd), &fd) in wrow.iter_mut().zip(wsum.iter_mut()).zip(patch).zip(fdist) {
                        let e = if guided { pd.max(fd) } else { pd };
                        *wt = spatial * exp_neg(e * inv);
                        *ws += *wt;
                    }
                    for c in 0..data.c {
                        let start = (c * plane_len) as isize + q0 + xa as isize;
                        let yq = &values.data[start as usize..start as usize + n];
                        let dst = &mut sum[s][c][row + xa..row + xb];
                        for ((d, &wt), &v) in dst.iter_mut().zip(wrow.iter()).zip(yq) {
                            *d += wt * v;
                        }
                    }
                }
            }
        }
    }
    TileOut { w: tw, h: th, sum, weight }
}

/// exp(−x) for x ≥ 0 to about 1e-6·(1 + x) relative (the f32 argument's rounding grows with x), branch-free so that the weight loop vectorises
/// (the library `exp` is a call per element, and this loop runs (2r+1)² times per pixel per
/// strength): 2^(−x·log₂e) split into an integer power, set in the exponent bits, and a
/// fraction, a degree-7 polynomial on [0, 1).
#[inline(always)]
pub fn exp_neg(x: f32) -> f32 {
    let t = (-x * std::f32::consts::LOG2_E).max(-125.0);
    let n = t.floor();
    let fr = t - n;
    // 2^fr on [0, 1): Taylor series of exp(fr·ln 2), ln 2 powers folded in.
    let p = 1.0
        + fr * (0.693_147_2
            + fr * (0.240_226_5
                + fr * (0.055_504_11
                    + fr * (0.009_618_129
                        + fr * (0.001_333_355_8 + fr * (0.000_154_035_3 + fr * 0.000_015_252_73))))));
    f32::from_bits(((n as i32 + 127) as u32) << 23) * p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_neg_matches_exp() {
        let mut worst = 0.0f64;
        for i in 0..16000 {
            let x = i as f32 * 0.005;
            let want = (-(x as f64)).exp();
            let got = exp_neg(x) as f64;
            // The f32 argument's own rounding: about 6e-8·x relative.
            worst = worst.max((got - want).abs() / want / (1.0 + x as f64));
        }
        assert!(worst < 2e-6, "relative error {worst}");
        assert_eq!(exp_neg(0.0), 1.0);
        // Beyond x ≈ 86 it stays at 2⁻¹²⁵: a weight of 0 for every purpose.
        assert!(exp_neg(1e30) >= 0.0 && exp_neg(1e30) < 1e-37);
        assert!(exp_neg(100.0) < 1e-37);
    }
}
