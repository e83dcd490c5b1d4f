//! Sample streams keyed by (seed, pixel, sample, dimension): independent random numbers, or
//! Owen-scrambled Sobol points.
//!
//! **Independent.** //! Each (seed, pixel, sample) triple owns its own stream, started from a hash of the triple and
//! never shared with another pixel or thread; the dimension is the position in that stream. So
//! an image does not depend on how pixels are divided among threads: one thread and many give
//! bit-identical results. The hash is the SplitMix64 finaliser (Steele et al. 2014); the stream
//! is PCG32 (O'Neill 2014, XSH-RR output), one multiply-add per number.
//!
//! **Sobol** (padded, Owen-scrambled; Burley 2020, "Practical Hash-based Owen Scrambling", as
//! pbrt-v4's `PaddedSobolSampler`). Every request — one number or a pair — is its own
//! "dimension" d of the path. A pair is the first two Sobol dimensions (van der Corput and its
//! Pascal-matrix partner, together a (0, 2)-sequence in base 2) at a shuffled index, each
//! coordinate Owen-scrambled with its own seed hashed from (seed, pixel, d); a single number is
//! the scrambled van der Corput coordinate alone. The index shuffle is itself a nested uniform
//! scramble, which maps the first 2^m samples onto one aligned block of 2^m, so with a
//! power-of-two sample count the pixel's samples of every pair form a (0, m, 2)-net: each
//! elementary interval of area 2^−m holds exactly one. Pixel-edge coverage, soft shadows and
//! the first bounce then converge faster than N^(−½) where the integrand allows. Dimensions are
//! scrambled independently of each other, so a path's dimensions are not jointly stratified
//! (padding), but each is as random as an independent sample across pixels. The film's
//! per-sample variance ignores the stratification and overestimates the error of the mean.
//!
//! Only the first `SOBOL_DIMENSIONS` (5) requests of a path are Sobol points: the pixel
//! position, the light sample and BSDF sample of the first vertex and those of the second (a
//! thin lens's sample comes second and moves the rest one on; the light pick reuses the light
//! sample's first coordinate, and Russian roulette, which starts at the fifth vertex, draws
//! nothing before). Later requests come from the (seed, pixel, sample) PCG stream, as with the
//! independent sampler. Deeper vertices carry little of the error a stratified point removes.
//! Five keeps the second vertex's direct light stratified, and a thin lens's sample does not
//! push the first vertex's BSDF sample out; the error and instructions measured for three to
//! ten Sobol requests are in `docs/measurements.md` ("Renderer: samplers").

/// The (seed, pixel) hash every Sobol dimension's scramble seeds derive from.
#[inline]
fn sobol_key(seed: u64, pixel: u64) -> u64 {
    mix64(seed ^ mix64(pixel))
}

/// Scramble seeds (index shuffle, x, y) of dimension `dim` under `key`.
#[inline]
fn seeds_of(key: u64, dim: u64) -> (u32, u32, u32) {
    let h = mix64(key ^ dim.wrapping_mul(DIM_STRIDE));
    (h as u32, (h >> 32) as u32, mix64(h) as u32)
}

/// The scramble seeds (index shuffle, x, y) every sample of a pixel uses at each Sobol
/// dimension: they do not depend on the sample, so `render::lanes` computes them once per
/// pixel.
pub(super) fn sobol_seeds(seed: u64, pixel: u64) -> [(u32, u32, u32); SOBOL_DIMENSIONS as usize] {
    let key = sobol_key(seed, pixel);
    std::array::from_fn(|dim| seeds_of(key, dim as u64))
}

/// SplitMix64's finaliser: a bijective 64-bit mixer.
#[inline]
pub fn mix64(mut x: u64) -> u64 {
    x ^= x >> 30;
    x = x.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x ^= x >> 27;
    x = x.wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// Which sample stream a render draws from (scene files: `render.sampler`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SamplerKind {
    /// Independent uniform numbers (the default; its variance estimate is exact).
    #[default]
    Independent,
    /// Padded Owen-scrambled Sobol points for the first `SOBOL_DIMENSIONS` requests of a path,
    /// PCG numbers after; best with a power-of-two sample count.
    Sobol,
}

/// The random stream of one (pixel, sample) pair; `next` walks its dimensions.
pub struct Sampler {
    state: u64,
    /// Sobol requests left before the PCG stream takes over: 0 for independent numbers. A
    /// counter the hot path tests, rather than an `Option` and a dimension, costs half the
    /// instructions per request.
    sobol_left: u32,
    sobol: Sobol,
}

/// Where a Sobol stream stands: its sample index (bit-reversed, the form the index shuffle
/// takes), the (seed, pixel) hash and the dimension.
struct Sobol {
    index_reversed: u32,
    key: u64,
    dim: u64,
}

/// The hash behind Burley's nested uniform scramble (Laine–Karras form, Vegdahl's improved
/// constants), applied to a bit-reversed fraction: every bit is flipped by a function of the
/// seed and of the bits below it, i.e. of the more significant digits of the fraction.
#[inline]
fn lk_hash(mut x: u32, seed: u32) -> u32 {
    x ^= x.wrapping_mul(LK_MUL[0]);
    x = x.wrapping_add(seed);
    x = x.wrapping_mul((seed >> 16) | 1);
    x ^= x.wrapping_mul(LK_MUL[1]);
    x ^= x.wrapping_mul(LK_MUL[2]);
    x
}

/// `lk_hash`'s multipliers.
pub(super) const LK_MUL: [u32; 3] = [0x3d20_adea, 0x0552_6c56, 0x53a2_2864];

/// Step between the dimensions' keys before `mix64` (the 64-bit golden ratio).
const DIM_STRIDE: u64 = 0x9e37_79b9_7f4a_7c15;

/// The second Sobol dimension at index i, bit-reversed (the form `lk_hash` takes). Its
/// generator matrix is Pascal's triangle mod 2: column k is (1 + x)^k, whose bit r is set when
/// C(k, r) is odd, that is (Lucas) when the bits of r are a subset of those of k. So bit r of
/// the result is the XOR of the bits i_k over every k ⊇ r: a superset sum over the five bits
/// of the position, one shift, mask and XOR per bit, without a table.
#[inline]
fn sobol_dim1_reversed(i: u32) -> u32 {
    let mut v = i;
    for (shift, mask) in SUPERSET_STEPS {
        v ^= (v >> shift) & mask;
    }
    v
}

/// `sobol_dim1_reversed`'s five steps: (s, the mask of the bit positions r with r & s = 0),
/// each adding the bit at r + s into the bit at r.
pub(super) const SUPERSET_STEPS: [(u32, u32); 5] =
    [(1, 0x5555_5555), (2, 0x3333_3333), (4, 0x0f0f_0f0f), (8, 0x00ff_00ff), (16, 0x0000_ffff)];

#[inline]
fn to_unit(bits: u32) -> f32 {
    (bits >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

/// Requests of a path served by Sobol points; later ones come from the PCG stream (module
/// docs).
pub const SOBOL_DIMENSIONS: u64 = 5;

pub(super) const PCG_MUL: u64 = 6_364_136_223_846_793_005;
pub(super) const PCG_INC: u64 = 1_442_695_040_888_963_407;

impl Sampler {
    pub fn new(seed: u64, pixel: u64, sample: u64) -> Sampler {
        Sampler {
            state: mix64(seed ^ mix64(pixel ^ mix64(sample.wrapping_add(0x5851_f42d)))),
            sobol_left: 0,
            sobol: Sobol { index_reversed: 0, key: 0, dim: 0 },
        }
    }

    /// Sample `sample` of pixel `pixel` from the chosen kind of stream.
    pub fn with_kind(kind: SamplerKind, seed: u64, pixel: u64, sample: u64) -> Sampler {
        match kind {
            SamplerKind::Independent => Sampler::new(seed, pixel, sample),
            SamplerKind::Sobol => Sampler {
                state: Sampler::new(seed, pixel, sample).state,
                sobol_left: SOBOL_DIMENSIONS as u32,
                sobol: Sobol {
                    index_reversed: (sample as u32).reverse_bits(),
                    key: sobol_key(seed, pixel),
                    dim: 0,
                },
            },
        }
    }

    /// The state `render::lanes` needs to draw eight samplers' numbers at once: (PCG state,
    /// Sobol requests left, bit-reversed sample index, Sobol dimension). The scramble seeds it
    /// looks up per pixel (`sobol_seeds`).
    pub(super) fn parts(&self) -> (u64, u32, u32, u64) {
        (self.state, self.sobol_left, self.sobol.index_reversed, self.sobol.dim)
    }

    /// A uniform number in [0, 1) with 24 random bits. PCG inlines into its callers; a Sobol
    /// point is a call.
    #[inline(always)]
    pub fn next(&mut self) -> f32 {
        if self.sobol_left > 0 {
            self.sobol_left -= 1;
            self.sobol.next()
        } else {
            self.pcg()
        }
    }

    #[inline(always)]
    pub fn next2(&mut self) -> (f32, f32) {
        if self.sobol_left > 0 {
            self.sobol_left -= 1;
            self.sobol.next2()
        } else {
            (self.pcg(), self.pcg())
        }
    }

    #[inline(always)]
    fn pcg(&mut self) -> f32 {
        let old = self.state;
        self.state = old.wrapping_mul(PCG_MUL).wrapping_add(PCG_INC);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let out = xorshifted.rotate_right((old >> 59) as u32);
        (out >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }
}

impl Sobol {
    /// The next dimension's scramble seeds: index shuffle, x and y.
    #[inline]
    fn seeds(&mut self) -> (u32, u32, u32) {
        self.dim += 1;
        seeds_of(self.key, self.dim - 1)
    }

    #[inline(never)]
    fn next(&mut self) -> f32 {
        let (hi, hx, _) = self.seeds();
        // The shuffled index (a nested uniform scramble of the index's digits), then the
        // scrambled van der Corput point, whose reversed form is the index itself.
        let i = lk_hash(self.index_reversed, hi).reverse_bits();
        to_unit(lk_hash(i, hx).reverse_bits())
    }

    #[inline(never)]
    fn next2(&mut self) -> (f32, f32) {
        let (hi, hx, hy) = self.seeds();
        let i = lk_hash(self.index_reversed, hi).reverse_bits();
        (to_unit(lk_hash(i, hx).reverse_bits()), to_unit(lk_hash(sobol_dim1_reversed(i), hy).reverse_bits()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The superset sum equals the generator matrix applied column by column.
    #[test]
    fn sobol_dim1_matches_pascal_columns() {
        let mut cols = [0u32; 32];
        let mut v = 1u32;
        for c in cols.iter_mut() {
            *c = v;
            v ^= v << 1;
        }
        let mut s = Sampler::new(3, 1, 4);
        for n in 0..100_000u32 {
            let i = if n < 1000 { n } else { (s.next() * 16_777_216.0) as u32 ^ (n << 24) };
            let direct = (0..32).filter(|k| (i >> k) & 1 == 1).fold(0, |acc, k| acc ^ cols[k]);
            assert_eq!(sobol_dim1_reversed(i), direct, "index {i}");
        }
    }

    #[test]
    fn uniform_mean_and_range() {
        let mut s = Sampler::new(7, 3, 1);
        let n = 100_000;
        let mut sum = 0.0f64;
        for _ in 0..n {
            let u = s.next();
            assert!((0.0..1.0).contains(&u));
            sum += u as f64;
        }
        // Mean of n uniforms: σ = 1/√(12n) ≈ 0.0009; allow 5σ.
        assert!((sum / n as f64 - 0.5).abs() < 0.0046);
    }

    /// Mean of the first stream's numbers and the correlation between two streams' numbers
    /// at dimension `dim`, over `n` pairs of streams made by `pair(i)`.
    fn mean_and_correlation(n: u64, dim: usize, pair: impl Fn(u64) -> (Sampler, Sampler)) -> (f64, f64) {
        let (mut sx, mut sy, mut sxy, mut sxx, mut syy) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
        for i in 0..n {
            let (mut a, mut b) = pair(i);
            let (mut x, mut y) = (0.0, 0.0);
            for _ in 0..=dim {
                x = a.next() as f64;
                y = b.next() as f64;
            }
            sx += x;
            sy += y;
            sxy += x * y;
            sxx += x * x;
            syy += y * y;
        }
        let nf = n as f64;
        let cov = sxy / nf - sx * sy / nf / nf;
        (sx / nf, cov / ((sxx / nf - (sx / nf).powi(2)) * (syy / nf - (sy / nf).powi(2))).sqrt())
    }

    /// Neighbouring pixels' and samples' streams are uncorrelated in every early dimension
    /// (the ones a path uses most): |corr| < 5/√n.
    #[test]
    fn neighbouring_streams_are_uncorrelated() {
        let n = 20_000;
        for dim in 0..8 {
            for (dp, ds) in [(1u64, 0u64), (0, 1)] {
                let (_, corr) = mean_and_correlation(n, dim, |i| {
                    (Sampler::new(5, i, 3), Sampler::new(5, i + dp, 3 + ds))
                });
                assert!(
                    corr.abs() < 5.0 / (n as f64).sqrt(),
                    "dimension {dim}, offset {dp}/{ds}: correlation {corr}"
                );
            }
        }
    }

    #[test]
    fn sobol_pairs_are_nets() {
        let m = 6u32;
        let n = 1usize << m;
        for pixel in [0u64, 1, 77, 123_456] {
            let mut samplers: Vec<Sampler> =
                (0..n as u64).map(|k| Sampler::with_kind(SamplerKind::Sobol, 9, pixel, k)).collect();
            // Every Sobol request, as pairs and singles.
            for dim in 0..SOBOL_DIMENSIONS as usize {
                let pts: Vec<(f32, f32)> = samplers
                    .iter_mut()
                    .map(|s| if dim % 3 == 2 { (s.next(), 0.5) } else { s.next2() })
                    .collect();
                let shapes = if dim % 3 == 2 { vec![m] } else { (0..=m).collect() };
                for k in shapes {
                    let (nx, ny) = (1usize << k, 1usize << (m - k));
                    let mut count = vec![0; n];
                    for &(x, y) in &pts {
                        assert!((0.0..1.0).contains(&x) && (0.0..1.0).contains(&y));
                        let cell = (x * nx as f32) as usize + nx * (y * ny as f32) as usize;
                        count[cell.min(n - 1)] += 1;
                    }
                    assert!(
                        count.iter().all(|&c| c == 1),
                        "pixel {pixel}, dimension {dim}, {nx}×{ny} intervals: {count:?}"
                    );
                }
            }
        }
    }

    /// Sobol streams of neighbouring pixels are uncorrelated in every early dimension, and the
    /// numbers are uniform over many pixels, on both sides of the switch to PCG numbers.
    #[test]
    fn sobol_pixels_are_uncorrelated() {
        let n = 20_000u64;
        let sobol = |pixel| Sampler::with_kind(SamplerKind::Sobol, 5, pixel, 3);
        for dim in 0..2 * SOBOL_DIMENSIONS as usize {
            let (mean, corr) = mean_and_correlation(n, dim, |i| (sobol(i), sobol(i + 1)));
            let nf = n as f64;
            assert!((mean - 0.5).abs() < 5.0 / (12.0 * nf).sqrt(), "dimension {dim}: mean {mean}");
            assert!(corr.abs() < 5.0 / nf.sqrt(), "dimension {dim}: correlation {corr}");
        }
    }

    /// RMS error, over `pixels` pixels, of the covered fraction of a pixel cut by the edge
    /// y = 0.31 + 0.27·x (the integral of a step, as at a chessboard corner), from `spp` samples.
    fn edge_rms(kind: SamplerKind, spp: u64, pixels: u64) -> f64 {
        let (a, b) = (0.31f64, 0.27f64);
        let truth = a + b / 2.0;
        let mut err2 = 0.0;
        for pixel in 0..pixels {
            let mut hits = 0u64;
            for k in 0..spp {
                let (x, y) = Sampler::with_kind(kind, 3, pixel, k).next2();
                hits += ((y as f64) < a + b * x as f64) as u64;
            }
            err2 += (hits as f64 / spp as f64 - truth).powi(2);
        }
        (err2 / pixels as f64).sqrt()
    }

    /// The point of the sampler: independent samples estimate an edge pixel with RMS error
    /// √(p(1−p)/N) (0.031 at N = 256), a scrambled (0, m, 2)-net's error decays as N^(−3/4)
    /// for a straight edge. Measured: the exponent between 64 and 1024 samples, and the gain
    /// at 256.
    #[test]
    fn sobol_converges_faster_on_an_edge() {
        let independent = edge_rms(SamplerKind::Independent, 256, 400);
        assert!((0.025..0.037).contains(&independent), "independent RMS {independent}");
        let sobol = edge_rms(SamplerKind::Sobol, 256, 400);
        assert!(sobol < independent / 3.0, "Sobol RMS {sobol} vs independent {independent}");
        let rate = (edge_rms(SamplerKind::Sobol, 64, 400) / edge_rms(SamplerKind::Sobol, 1024, 400)).ln()
            / 16f64.ln();
        assert!(rate > 0.65, "Sobol error decays as N^-{rate:.3}, expected N^-0.75");
    }
}
