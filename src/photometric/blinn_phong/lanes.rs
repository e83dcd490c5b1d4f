//! The fit's inner loop over a pixel's used observations, eight at a time: ‖r‖² alone (the
//! line search), with JᵀJ and Jᵀr (the Gauss-Newton step), or the residuals themselves (the
//! outlier rounds), for the model of the module above and its Jacobian (written out
//! observation by observation in its tests' `visit`, which these sums are checked against).
//!
//! Hand-written rather than through a SIMD crate: the loop body is plain scalar f64 code over
//! arrays of eight (structure of arrays), which LLVM turns into AVX-512 or AVX2 instructions
//! when the body is compiled with those features and FMA (`dispatch`, chosen per call by
//! `is_x86_feature_detected!`), and into SSE2 elsewhere. dᵉ is `exp(e·ln d)` with `ln` and
//! `exp` written here as polynomials on the float's bits, branch-free so that they vectorise
//! (libm's are calls, which do not): both agree with libm to 1.3·10⁻¹⁵ relative on (0, 1] and
//! [−708, 709] (`ln_and_exp_match_libm`), far below what the fit resolves, and exp is 0 below
//! −708 where libm gives subnormals. Products are summed with fused multiply-adds
//! (`f64::mul_add`, exactly rounded everywhere), so every variant gives the same bits; without
//! FMA in hardware (older than AVX2) the fallback computes them in software, slowly.

use super::Param;
use glam::DVec3;
use nalgebra::SMatrix;

/// Observations per lane group.
const W: usize = 8;
type Lane = [f64; W];

/// Eight observations: light and half-vector directions and the three channels (negated, so
/// that a residual is one fused multiply-add), each component an array of eight.
#[derive(Clone, Copy, Default)]
struct Group {
    l: [Lane; 3],
    h: [Lane; 3],
    minus_obs: [Lane; 3],
}

/// A pixel's used observations in groups of eight, the last padded with zero lights and zero
/// observations (c = n·l = 0 there, so a padding lane adds nothing to any sum).
pub(super) struct Observations {
    groups: Vec<Group>,
    len: usize,
}

impl Observations {
    pub(super) fn new(lights: &[DVec3], halves: &[DVec3], obs: &[[f32; 3]], used: &[usize]) -> Self {
        let mut groups = vec![Group::default(); used.len().div_ceil(W)];
        for (i, &j) in used.iter().enumerate() {
            let (g, k) = (&mut groups[i / W], i % W);
            for a in 0..3 {
                g.l[a][k] = lights[j][a];
                g.h[a][k] = halves[j][a];
                g.minus_obs[a][k] = -(obs[j][a] as f64);
            }
        }
        Observations { groups, len: used.len() }
    }
}

/// Where the model is evaluated: the normal n, its derivatives along the parameters a and b,
/// ρ per channel, σ, e, and whether ln e is inside its clamp (else ∂/∂ln e is 0).
pub(super) struct Point {
    pub n: DVec3,
    pub dna: DVec3,
    pub dnb: DVec3,
    pub rho: [f64; 3],
    pub sigma: f64,
    pub e: f64,
    pub ln_e_free: bool,
}

/// Calls `$body(args)` compiled for the best instruction set this processor has.
macro_rules! dispatch {
    ($body:ident($($arg:expr),*)) => {
        dispatch!($body($($arg),*) -> Sums)
    };
    ($body:ident($($arg:expr),*) -> $out:ty) => {{
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx512f,fma")]
            fn avx512(obs: &Observations, at: &Point) -> $out {
                $body(obs, at)
            }
            #[target_feature(enable = "avx2,fma")]
            fn avx2(obs: &Observations, at: &Point) -> $out {
                $body(obs, at)
            }
            if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("fma") {
                // SAFETY: the processor has AVX-512F and FMA.
                unsafe { avx512($($arg),*) }
            } else if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
                // SAFETY: the processor has AVX2 and FMA.
                unsafe { avx2($($arg),*) }
            } else {
                $body($($arg),*)
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            $body($($arg),*)
        }
    }};
}

/// Σ r² over the observations.
pub(super) fn squares(obs: &Observations, at: &Point) -> f64 {
    dispatch!(squares_body(obs, at))[SQ]
}

/// Σ r², JᵀJ (upper triangle and lower) and Jᵀr over the observations, without the prior.
pub(super) fn normal_equations(obs: &Observations, at: &Point) -> (f64, SMatrix<f64, 7, 7>, Param) {
    let s = dispatch!(normal_equations_body(obs, at));
    let mut jtj = SMatrix::<f64, 7, 7>::zeros();
    let mut set = |i: usize, k: usize, v: f64| {
        jtj[(i, k)] = v;
        jtj[(k, i)] = v;
    };
    set(0, 0, s[S00]);
    set(0, 1, s[S01]);
    set(1, 1, s[S11]);
    for ch in 0..3 {
        set(0, 2 + ch, s[S0C + ch]);
        set(1, 2 + ch, s[S1C + ch]);
        set(2 + ch, 2 + ch, s[SCC]);
        set(2 + ch, 5, s[SC5]);
        set(2 + ch, 6, s[SC6]);
    }
    set(0, 5, s[S05]);
    set(0, 6, s[S06]);
    set(1, 5, s[S15]);
    set(1, 6, s[S16]);
    set(5, 5, s[S55]);
    set(5, 6, s[S56]);
    set(6, 6, s[S66]);
    let jtr = Param::from([s[G0], s[G1], s[GC], s[GC + 1], s[GC + 2], s[G5], s[G6]]);
    (s[SQ], jtj, jtr)
}

/// The residuals, three per observation (r, g, b) in the order `Observations::new` was given.
pub(super) fn residuals(obs: &Observations, at: &Point) -> Vec<f64> {
    dispatch!(residuals_body(obs, at) -> Vec<f64>)
}

/// The sums of the linear least squares for (ρ_r, ρ_g, ρ_b, σ) at `at.n` and `at.e` (`start_at`),
/// with c = max(0, n·l) and g = c·(e + 8)/8·dᵉ: [Σc², Σc·g, Σg², Σc·I_r, Σc·I_g, Σc·I_b,
/// Σg·(I_r + I_g + I_b)]. The other fields of `at` are not read.
pub(super) fn linear_sums(obs: &Observations, at: &Point) -> [f64; 7] {
    let s = dispatch!(linear_sums_body(obs, at));
    std::array::from_fn(|i| s[i])
}

/// What a pass returns: its sums, indexed by the constants below.
type Sums = [f64; SUMS];
const SQ: usize = 0; // Σ r²
const S00: usize = 1; // JᵀJ (a, a), (a, b), (b, b)
const S01: usize = 2;
const S11: usize = 3;
const S05: usize = 4; // (a, σ), (a, ln e), (b, σ), (b, ln e)
const S06: usize = 5;
const S15: usize = 6;
const S16: usize = 7;
const S55: usize = 8; // (σ, σ), (σ, ln e), (ln e, ln e)
const S56: usize = 9;
const S66: usize = 10;
const S0C: usize = 11; // (a, ρ_c) for c = 0, 1, 2
const S1C: usize = 14; // (b, ρ_c)
const SCC: usize = 17; // (ρ_c, ρ_c), (ρ_c, σ), (ρ_c, ln e): the same for every channel
const SC5: usize = 18;
const SC6: usize = 19;
const G0: usize = 20; // Jᵀr: a, b, ρ_c, σ, ln e
const G1: usize = 21;
const GC: usize = 22;
const G5: usize = 25;
const G6: usize = 26;
const SUMS: usize = 27;

/// Eight f64 lanes. Each operator is a loop over the eight, which LLVM turns into one vector
/// instruction (or two, or four, by the instruction set the body is compiled for).
#[derive(Clone, Copy)]
struct V([f64; W]);

/// A lane mask: all bits set where true.
#[derive(Clone, Copy)]
struct Mask([u64; W]);

macro_rules! lanewise {
    ($trait:ident, $f:ident, $op:tt) => {
        impl std::ops::$trait for V {
            type Output = V;
            #[inline(always)]
            fn $f(self, o: V) -> V {
                V(std::array::from_fn(|i| self.0[i] $op o.0[i]))
            }
        }
        impl std::ops::$trait<f64> for V {
            type Output = V;
            #[inline(always)]
            fn $f(self, o: f64) -> V {
                V(std::array::from_fn(|i| self.0[i] $op o))
            }
        }
    };
}
lanewise!(Add, add, +);
lanewise!(Sub, sub, -);
lanewise!(Mul, mul, *);
lanewise!(Div, div, /);

impl std::ops::AddAssign for V {
    #[inline(always)]
    fn add_assign(&mut self, o: V) {
        *self = *self + o;
    }
}

impl std::ops::BitAnd for Mask {
    type Output = Mask;
    #[inline(always)]
    fn bitand(self, o: Mask) -> Mask {
        Mask(std::array::from_fn(|i| self.0[i] & o.0[i]))
    }
}

impl V {
    #[inline(always)]
    fn splat(x: f64) -> V {
        V([x; W])
    }
    #[inline(always)]
    fn bits(self) -> [u64; W] {
        self.0.map(f64::to_bits)
    }
    #[inline(always)]
    fn from_bits(b: [u64; W]) -> V {
        V(b.map(f64::from_bits))
    }
    #[inline(always)]
    fn gt(self, o: f64) -> Mask {
        Mask(std::array::from_fn(|i| if self.0[i] > o { u64::MAX } else { 0 }))
    }
    #[inline(always)]
    fn lt(self, o: f64) -> Mask {
        Mask(std::array::from_fn(|i| if self.0[i] < o { u64::MAX } else { 0 }))
    }
    /// The larger of each lane and `o` (`o` where a lane is NaN).
    #[inline(always)]
    fn max(self, o: f64) -> V {
        V(self.0.map(|x| if x > o { x } else { o }))
    }
    /// The lane clamped to [lo, hi] (`lo` where a lane is NaN).
    #[inline(always)]
    fn clamp(self, lo: f64, hi: f64) -> V {
        V(self.0.map(|x| if x < hi { x } else { hi })).max(lo)
    }
    /// `self` where `m`, else 0.
    #[inline(always)]
    fn and(self, m: Mask) -> V {
        let b = self.bits();
        V::from_bits(std::array::from_fn(|i| b[i] & m.0[i]))
    }
    /// `a` where `m`, else `self`.
    #[inline(always)]
    fn or_where(self, m: Mask, a: V) -> V {
        let (b, a) = (self.bits(), a.bits());
        V::from_bits(std::array::from_fn(|i| (a[i] & m.0[i]) | (b[i] & !m.0[i])))
    }
    /// self·a + b, fused (one rounding).
    #[inline(always)]
    fn fma(self, a: V, b: V) -> V {
        V(std::array::from_fn(|i| self.0[i].mul_add(a.0[i], b.0[i])))
    }
    #[inline(always)]
    fn sum(self) -> f64 {
        self.0.iter().sum()
    }
}

#[inline(always)]
fn dot(v: DVec3, a: &[Lane; 3]) -> V {
    V(a[2]).fma(V::splat(v.z), V(a[1]).fma(V::splat(v.y), V(a[0]) * v.x))
}

/// acc + Σ x·y over the pairs, fused.
#[inline(always)]
fn accumulate<const N: usize>(acc: &mut V, pairs: [(V, V); N]) {
    for (x, y) in pairs {
        *acc = x.fma(y, *acc);
    }
}

/// Eight observations' model terms.
struct Terms {
    /// n·l, 0 where unlit.
    c: V,
    d: V,
    ln_d: V,
    /// dᵉ, 0 where n·l or n·h is not positive.
    de: V,
    spec: V,
    r: [V; 3],
}

#[inline(always)]
fn model(g: &Group, at: &Point, lobe: f64) -> Terms {
    let c = dot(at.n, &g.l);
    let d = dot(at.n, &g.h);
    let lit = c.gt(0.0) & d.gt(0.0);
    let ln_d = ln(d.max(f64::MIN_POSITIVE));
    let de = exp(ln_d * at.e).and(lit);
    let spec = de * (at.sigma * lobe);
    let c = c.max(0.0);
    let r = |ch: usize| (spec + at.rho[ch]).fma(c, V(g.minus_obs[ch]));
    let r = [r(0), r(1), r(2)];
    Terms { c, d, ln_d, de, spec, r }
}

#[inline(always)]
fn linear_sums_body(obs: &Observations, at: &Point) -> Sums {
    let lobe = (at.e + 8.0) / 8.0;
    let mut a = [V::splat(0.0); 7];
    for grp in &obs.groups {
        let c = dot(at.n, &grp.l);
        let d = dot(at.n, &grp.h);
        let lit = c.gt(0.0) & d.gt(0.0);
        let c = c.max(0.0);
        let g = exp(ln(d.max(f64::MIN_POSITIVE)) * at.e).and(lit) * c * lobe;
        // −I: the sums that hold it are negated at the end (exactly).
        let o = [V(grp.minus_obs[0]), V(grp.minus_obs[1]), V(grp.minus_obs[2])];
        accumulate(&mut a[0], [(c, c)]);
        accumulate(&mut a[1], [(c, g)]);
        accumulate(&mut a[2], [(g, g)]);
        for ch in 0..3 {
            accumulate(&mut a[3 + ch], [(c, o[ch])]);
        }
        accumulate(&mut a[6], [(g, o[0] + o[1] + o[2])]);
    }
    let mut s = [0.0; SUMS];
    for (k, (s, a)) in s.iter_mut().zip(a).enumerate() {
        *s = if k < 3 { a.sum() } else { -a.sum() };
    }
    s
}

#[inline(always)]
fn squares_body(obs: &Observations, at: &Point) -> Sums {
    let lobe = (at.e + 8.0) / 8.0;
    let mut acc = V::splat(0.0);
    for g in &obs.groups {
        let r = model(g, at, lobe).r;
        accumulate(&mut acc, [(r[0], r[0]), (r[1], r[1]), (r[2], r[2])]);
    }
    let mut s = [0.0; SUMS];
    s[SQ] = acc.sum();
    s
}

#[inline(always)]
fn residuals_body(obs: &Observations, at: &Point) -> Vec<f64> {
    let lobe = (at.e + 8.0) / 8.0;
    let mut out = Vec::with_capacity(3 * W * obs.groups.len());
    for g in &obs.groups {
        let r = model(g, at, lobe).r;
        for k in 0..W {
            out.extend([r[0].0[k], r[1].0[k], r[2].0[k]]);
        }
    }
    out.truncate(3 * obs.len);
    out
}

#[inline(always)]
fn normal_equations_body(obs: &Observations, at: &Point) -> Sums {
    let lobe = (at.e + 8.0) / 8.0;
    let (dna, dnb) = (at.dna, at.dnb);
    let mut a = [V::splat(0.0); SUMS];
    for g in &obs.groups {
        let Terms { c, d, ln_d, de, spec, r } = model(g, at, lobe);
        let on = c.gt(0.0);
        // ∂spec/∂n = σ·lobe·e·dᵉ⁻¹·h (0 where dᵉ is); ∂spec/∂ln e = e·σ·dᵉ·(1/8 + lobe·ln d).
        let kh = de / d.max(f64::MIN_POSITIVE) * c * (at.sigma * lobe * at.e);
        let dt = if at.ln_e_free { de * (ln_d * lobe + 0.125) * (at.e * at.sigma) } else { V::splat(0.0) };
        // Row of channel ch: [la·(ρ_ch + spec) + ha, lb·(ρ_ch + spec) + hb, c, r5, r6].
        let (la, lb) = (dot(dna, &g.l).and(on), dot(dnb, &g.l).and(on));
        let (ha, hb) = (dot(dna, &g.h) * kh, dot(dnb, &g.h) * kh);
        let (r5, r6) = (de * c * lobe, dt * c);
        let rs = [spec + at.rho[0], spec + at.rho[1], spec + at.rho[2]];
        let row0 = [la.fma(rs[0], ha), la.fma(rs[1], ha), la.fma(rs[2], ha)];
        let row1 = [lb.fma(rs[0], hb), lb.fma(rs[1], hb), lb.fma(rs[2], hb)];
        let (sum0, sum1, sum_r) =
            (row0[0] + row0[1] + row0[2], row1[0] + row1[1] + row1[2], r[0] + r[1] + r[2]);
        accumulate(&mut a[SQ], [(r[0], r[0]), (r[1], r[1]), (r[2], r[2])]);
        accumulate(&mut a[S00], [(row0[0], row0[0]), (row0[1], row0[1]), (row0[2], row0[2])]);
        accumulate(&mut a[S01], [(row0[0], row1[0]), (row0[1], row1[1]), (row0[2], row1[2])]);
        accumulate(&mut a[S11], [(row1[0], row1[0]), (row1[1], row1[1]), (row1[2], row1[2])]);
        accumulate(&mut a[S05], [(sum0, r5)]);
        accumulate(&mut a[S06], [(sum0, r6)]);
        accumulate(&mut a[S15], [(sum1, r5)]);
        accumulate(&mut a[S16], [(sum1, r6)]);
        accumulate(&mut a[S55], [(r5 * 3.0, r5)]);
        accumulate(&mut a[S56], [(r5 * 3.0, r6)]);
        accumulate(&mut a[S66], [(r6 * 3.0, r6)]);
        for ch in 0..3 {
            accumulate(&mut a[S0C + ch], [(row0[ch], c)]);
            accumulate(&mut a[S1C + ch], [(row1[ch], c)]);
            accumulate(&mut a[GC + ch], [(c, r[ch])]);
        }
        accumulate(&mut a[SCC], [(c, c)]);
        accumulate(&mut a[SC5], [(c, r5)]);
        accumulate(&mut a[SC6], [(c, r6)]);
        accumulate(&mut a[G0], [(row0[0], r[0]), (row0[1], r[1]), (row0[2], r[2])]);
        accumulate(&mut a[G1], [(row1[0], r[0]), (row1[1], r[1]), (row1[2], r[2])]);
        accumulate(&mut a[G5], [(r5, sum_r)]);
        accumulate(&mut a[G6], [(r6, sum_r)]);
    }
    a.map(V::sum)
}

/// ln x for positive normal x: x = 2ᵐ·f with f in [√½, √2), ln f = 2·atanh s with
/// s = (f − 1)/(f + 1), |s| ≤ 0.172, as its series to s¹⁷ (truncation below 10⁻¹⁷).
#[inline(always)]
fn ln(x: V) -> V {
    const LN2_HI: f64 = 6.931_471_803_691_238_2e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    const TWO52: f64 = 4_503_599_627_370_496.0;
    // m + 1023 = the exponent of x/√½ (x's bits less √½'s, plus the bias), in integer
    // arithmetic; f = x·2⁻ᵐ by subtracting m from x's exponent.
    const SQRT_HALF: u64 = 0x3FE6_A09E_667F_3BCD;
    const BIAS: u64 = 1023 << 52;
    let bits = x.bits();
    let biased = bits.map(|b| (b + (BIAS - SQRT_HALF)) >> 52);
    // m as a float, through the 2⁵² trick (no integer conversion).
    let m = V::from_bits(biased.map(|e| 0x4330_0000_0000_0000 | e)) - (TWO52 + 1023.0);
    let f = V::from_bits(std::array::from_fn(|i| bits[i] + BIAS - (biased[i] << 52)));
    let s = (f - 1.0) / (f + 1.0);
    let z = s * s;
    // Σ 2·z^k/(2k + 1) for k = 0 … 8, by Estrin's scheme (`estrin9`).
    const TWO_OVER_ODD: [f64; 9] = {
        let mut a = [0.0; 9];
        let mut k = 0;
        while k < 9 {
            a[k] = 2.0 / (2 * k + 1) as f64;
            k += 1;
        }
        a
    };
    let p = estrin9(z, TWO_OVER_ODD);
    m.fma(V::splat(LN2_HI), m.fma(V::splat(LN2_LO), s * p))
}

/// eˣ: x = k·ln 2 + r with |r| ≤ ½ ln 2, eʳ as its Taylor series to r¹³ (truncation below
/// 10⁻¹⁷), 2ᵏ written into the exponent bits; 0 below −708 (where libm gives subnormals).
#[inline(always)]
fn exp(x: V) -> V {
    const LN2_HI: f64 = 6.931_471_803_691_238_2e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    const ROUND: f64 = 6_755_399_441_055_744.0; // 1.5·2⁵²: adding it rounds to an integer
    const TWO52: f64 = 4_503_599_627_370_496.0;
    // 1/n! for n = 0 … 13.
    const INV_FACTORIAL: [f64; 14] = {
        let mut a = [1.0; 14];
        let mut n = 1;
        while n < 14 {
            a[n] = a[n - 1] / n as f64;
            n += 1;
        }
        a
    };
    let y = x.clamp(-708.0, 709.0);
    let k = y.fma(V::splat(std::f64::consts::LOG2_E), V::splat(ROUND)) - ROUND;
    let r = k.fma(V::splat(-LN2_LO), k.fma(V::splat(-LN2_HI), y));
    let p = estrin14(r, INV_FACTORIAL);
    // 2ᵏ: k + 1023 in [1, 2046] sits in the low bits of k + 1023 + 2⁵², shifted to the exponent.
    let scale = V::from_bits((k + (1023.0 + TWO52)).bits().map(|b| b << 52));
    (p * scale).or_where(x.lt(-708.0), V::splat(0.0))
}

/// Σ c_k·x^k (k = 0 … 8 and k = 0 … 13, for ln and exp) by Estrin's scheme: pairs
/// c_2i + c_2i+1·x, then pairs of those with x², x⁴, x⁸. The operations of Horner's rule, but
/// a dependency chain of four fused multiply-adds instead of 9 and 14: chains that long, one
/// after the other for each group of eight observations, left the core waiting on their
/// latency. Written out for the two lengths, so that it unrolls with no multiply-add by a zero.
#[inline(always)]
fn estrin9(x: V, c: [f64; 9]) -> V {
    let k = |i: usize| V::splat(c[i]);
    let (x2, x4) = (x * x, x * x * (x * x));
    let q = [k(1).fma(x, k(0)), k(3).fma(x, k(2)), k(5).fma(x, k(4)), k(7).fma(x, k(6))];
    let s = [q[1].fma(x2, q[0]), q[3].fma(x2, q[2])];
    k(8).fma(x4 * x4, s[1].fma(x4, s[0]))
}

#[inline(always)]
fn estrin14(x: V, c: [f64; 14]) -> V {
    let k = |i: usize| V::splat(c[i]);
    let (x2, x4) = (x * x, x * x * (x * x));
    let q: [V; 7] = std::array::from_fn(|i| k(2 * i + 1).fma(x, k(2 * i)));
    let s = [q[1].fma(x2, q[0]), q[3].fma(x2, q[2]), q[5].fma(x2, q[4])];
    let t = [s[1].fma(x4, s[0]), q[6].fma(x4, s[2])];
    t[1].fma(x4 * x4, t[0])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ln_and_exp_match_libm() {
        let mut worst = (0.0f64, 0.0f64);
        for i in 0..200_000 {
            let x = (i as f64 / 200_000.0).powi(3) * 0.999_999 + 1e-12 * (i % 7) as f64 + 1e-300;
            let ours = ln(V::splat(x)).0[0];
            worst.0 = worst.0.max(if x.ln() == 0.0 { ours.abs() } else { ((ours - x.ln()) / x.ln()).abs() });
            let y = -708.0 + 1417.0 * i as f64 / 200_000.0;
            worst.1 = worst.1.max(((exp(V::splat(y)).0[0] - y.exp()) / y.exp()).abs());
        }
        // 10⁻¹⁴: a few ulp of rounding (ln is worst near x = ½, where m·ln 2 and ln f cancel),
        // while a wrong coefficient or a series cut short shows as 10⁻¹² or worse.
        assert!(worst.0 < 1e-14 && worst.1 < 1e-14, "{worst:?}");
        assert_eq!(exp(V::splat(-750.0)).0[0], 0.0);
        assert_eq!(exp(V::splat(f64::NEG_INFINITY)).0[0], 0.0);
        assert_eq!(exp(V::splat(0.0)).0[0], 1.0);
        assert_eq!(ln(V::splat(1.0)).0[0], 0.0);
    }

    /// The variant this processor runs gives the same bits as the plain one.
    #[test]
    fn every_variant_gives_the_same_sums() {
        let lights: Vec<DVec3> =
            (0..21).map(|k| DVec3::new((k as f64).sin(), (k as f64 * 0.7).cos(), 1.0).normalize()).collect();
        let halves: Vec<DVec3> = lights.iter().map(|&l| (l + DVec3::Z).normalize()).collect();
        let obs: Vec<[f32; 3]> =
            (0..21).map(|k| [0.1 + 0.01 * k as f32, 0.2, 0.05 * (k % 3) as f32]).collect();
        let used: Vec<usize> = (0..21).collect();
        let o = Observations::new(&lights, &halves, &obs, &used);
        let n = DVec3::new(0.1, 0.2, 1.0).normalize();
        let at = Point {
            n,
            dna: DVec3::X,
            dnb: DVec3::Y,
            rho: [0.2, 0.1, 0.05],
            sigma: 0.3,
            e: 40.0,
            ln_e_free: true,
        };
        let (a, b) = (dispatch!(normal_equations_body(&o, &at)), normal_equations_body(&o, &at));
        assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
        assert!(a.iter().all(|v| v.is_finite()) && a[SQ] > 0.0);
        let (a, b) = (dispatch!(linear_sums_body(&o, &at)), linear_sums_body(&o, &at));
        assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
        assert!(a[..7].iter().all(|v| v.is_finite() && *v > 0.0));
    }
}
