//! The samplers of eight lanes: PCG32 and Owen-scrambled Sobol points, bit-identical to
//! `render::sampler` lane by lane.

use super::super::sampler::{self, Sampler, SamplerKind};
use super::vector::*;
use std::arch::x86_64::*;

/// `sampler::lk_hash`, lane by lane.
#[inline(always)]
pub(crate) fn lk_hash(x: __m256i, seed: __m256i) -> __m256i {
    // SAFETY: as in `binop`.
    unsafe {
        let mul = |a, c: u32| _mm256_mullo_epi32(a, _mm256_set1_epi32(c as i32));
        let x = _mm256_xor_si256(x, mul(x, sampler::LK_MUL[0]));
        let x = _mm256_add_epi32(x, seed);
        let x = _mm256_mullo_epi32(x, _mm256_or_si256(_mm256_srli_epi32::<16>(seed), _mm256_set1_epi32(1)));
        let x = _mm256_xor_si256(x, mul(x, sampler::LK_MUL[1]));
        _mm256_xor_si256(x, mul(x, sampler::LK_MUL[2]))
    }
}

/// `u32::reverse_bits`, lane by lane: the bytes swapped, then each byte's nibbles looked up
/// reversed and swapped.
#[inline(always)]
pub(crate) fn reverse_bits(x: __m256i) -> __m256i {
    // SAFETY: as in `binop`.
    unsafe {
        let bytes = _mm256_setr_epi8(
            3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12, 3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15,
            14, 13, 12,
        );
        let x = _mm256_shuffle_epi8(x, bytes);
        let nibble = _mm256_setr_epi8(
            0, 8, 4, 12, 2, 10, 6, 14, 1, 9, 5, 13, 3, 11, 7, 15, 0, 8, 4, 12, 2, 10, 6, 14, 1, 9, 5, 13, 3,
            11, 7, 15,
        );
        let low = _mm256_set1_epi8(0x0f);
        let lo = _mm256_shuffle_epi8(nibble, _mm256_and_si256(x, low));
        let hi = _mm256_shuffle_epi8(nibble, _mm256_and_si256(_mm256_srli_epi16::<4>(x), low));
        _mm256_or_si256(_mm256_slli_epi16::<4>(lo), hi)
    }
}

/// `sampler::sobol_dim1_reversed`, lane by lane.
#[inline(always)]
pub(crate) fn sobol_dim1_reversed(i: __m256i) -> __m256i {
    let mut v = i;
    for (shift, mask) in sampler::SUPERSET_STEPS {
        // SAFETY: as in `binop`.
        v = unsafe {
            let shifted = _mm256_srl_epi32(v, _mm_cvtsi32_si128(shift as i32));
            _mm256_xor_si256(v, _mm256_and_si256(shifted, _mm256_set1_epi32(mask as i32)))
        };
    }
    v
}

/// `sampler::to_unit` (the top 24 bits as a float in [0, 1)), lane by lane.
#[inline(always)]
pub(crate) fn to_unit(bits: __m256i) -> F {
    // SAFETY: as in `binop`.
    let value = unsafe { F(_mm256_cvtepi32_ps(_mm256_srli_epi32::<8>(bits))) };
    value * F::splat(1.0 / (1u32 << 24) as f32)
}

/// The eight lanes' `Sampler`s, structure of arrays, drawn from together, and the Sobol
/// scramble seeds of the group's pixels.
#[derive(Default)]
pub(crate) struct Samplers {
    pub(crate) pcg: [u64; 8],
    pub(crate) sobol_left: [u32; 8],
    pub(crate) index_reversed: [u32; 8],
    pub(crate) dim: [u32; 8],
    /// Per lane, where its pixel's rows of `seeds` start.
    pub(crate) seed_row: [u32; 8],
    /// (index shuffle, x, y) seeds per pixel of the group and Sobol dimension
    /// (`sampler::sobol_seeds`), pixel-major; empty without Sobol points.
    pub(crate) seeds: [Vec<u32>; 3],
}

const DIMS: u32 = sampler::SOBOL_DIMENSIONS as u32;

impl Samplers {
    /// The samplers of row `y`'s pixels `gx0..gx1` (of a `width`-pixel image) under `kind`
    /// seeded by `seed`.
    pub(crate) fn new(kind: SamplerKind, seed: u64, y: u32, gx0: u32, gx1: u32, width: u32) -> Samplers {
        let mut s = Samplers::default();
        if kind == SamplerKind::Sobol {
            for x in gx0..gx1 {
                let pixel = y as u64 * width as u64 + x as u64;
                for (hi, hx, hy) in sampler::sobol_seeds(seed, pixel) {
                    s.seeds[0].push(hi);
                    s.seeds[1].push(hx);
                    s.seeds[2].push(hy);
                }
            }
        }
        s
    }

    /// Lane `lane` continues `s`, a sampler of the group's pixel `x_local`.
    pub(crate) fn set(&mut self, lane: usize, s: &Sampler, x_local: u32) {
        let dim;
        (self.pcg[lane], self.sobol_left[lane], self.index_reversed[lane], dim) = s.parts();
        self.dim[lane] = dim.min(DIMS as u64) as u32;
        self.seed_row[lane] = x_local * DIMS;
    }

    /// `Sampler::next2` (or `next` when `two` is false, the second number then 0) for the
    /// lanes of `want`; the other lanes' streams do not move.
    #[inline(always)]
    pub(crate) fn next(&mut self, want: u32, two: bool) -> (F, F) {
        let zero = F::splat(0.0);
        if want == 0 {
            return (zero, zero);
        }
        // SAFETY: as in `binop`.
        unsafe {
            let want_m = M::from_bits(want);
            let left = _mm256_loadu_si256(self.sobol_left.as_ptr().cast());
            let sobol_m = _mm256_and_si256(
                _mm256_cmpgt_epi32(left, _mm256_setzero_si256()),
                _mm256_castps_si256(want_m.0),
            );
            let sobol = _mm256_movemask_ps(_mm256_castsi256_ps(sobol_m)) as u32;
            let (mut x, mut y) = (zero, zero);
            let pcg = want & !sobol;
            if pcg != 0 {
                let old = U64::load(&self.pcg);
                let (a, state) = pcg_step(old);
                let (b, state) = if two { pcg_step(state) } else { (zero, state) };
                let m = _mm256_castps_si256(M::from_bits(pcg).0);
                U64::select(m, state, old).store(&mut self.pcg);
                (x, y) = (a, b);
            }
            if sobol != 0 {
                // `Sobol::seeds` (looked up), then `Sobol::next2` / `next`. A lane with
                // Sobol requests left is at a dimension below DIMS; the others' look-ups
                // are clamped into the table and not used.
                let dim = _mm256_loadu_si256(self.dim.as_ptr().cast());
                let row = _mm256_add_epi32(
                    _mm256_loadu_si256(self.seed_row.as_ptr().cast()),
                    _mm256_min_epu32(dim, _mm256_set1_epi32(DIMS as i32 - 1)),
                );
                let seed = |k: usize| _mm256_i32gather_epi32::<4>(self.seeds[k].as_ptr().cast(), row);
                _mm256_storeu_si256(self.dim.as_mut_ptr().cast(), _mm256_sub_epi32(dim, sobol_m));
                _mm256_storeu_si256(self.sobol_left.as_mut_ptr().cast(), _mm256_add_epi32(left, sobol_m));
                let (hi, hx) = (seed(0), seed(1));
                let index = _mm256_loadu_si256(self.index_reversed.as_ptr().cast());
                let i = reverse_bits(lk_hash(index, hi));
                let sm = M(_mm256_castsi256_ps(sobol_m));
                x = sm.select(to_unit(reverse_bits(lk_hash(i, hx))), x);
                if two {
                    let hy = seed(2);
                    y = sm.select(to_unit(reverse_bits(lk_hash(sobol_dim1_reversed(i), hy))), y);
                }
            }
            (x, y)
        }
    }
}

/// One PCG32 step (`Sampler::pcg`) on eight streams: the number and the next state.
#[inline(always)]
pub(crate) fn pcg_step(old: U64) -> (F, U64) {
    let state = old.mul(sampler::PCG_MUL).add(sampler::PCG_INC);
    let xorshifted = old.shr::<18>().xor(old).shr::<27>().low_halves();
    let rot = old.shr::<59>().low_halves();
    // SAFETY: as in `binop`.
    unsafe {
        // Rotate right by rot (a left shift by 32 gives 0, so rot = 0 is the value itself).
        let left = _mm256_sub_epi32(_mm256_set1_epi32(32), rot);
        let out = _mm256_or_si256(_mm256_srlv_epi32(xorshifted, rot), _mm256_sllv_epi32(xorshifted, left));
        (to_unit(out), state)
    }
}
