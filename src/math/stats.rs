//! Small statistics helpers used by tests, reports and the robust fits.

/// The value at index n/2 of `v` in ascending order (the median for odd n, the upper of the
/// two middle values for even n), found by selection rather than a sort (`v` is reordered);
/// `None` when `v` is empty. The robust fits' residual scale (MAD) is taken this way.
pub fn upper_median(v: &mut [f64]) -> Option<f64> {
    let mid = v.len() / 2;
    (!v.is_empty()).then(|| *v.select_nth_unstable_by(mid, f64::total_cmp).1)
}

/// The median of `v` (the mean of the two middle values for even n; `v` is sorted), or
/// `None` when `v` is empty.
pub fn median(v: &mut [f64]) -> Option<f64> {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => Some(v[n / 2]),
        _ => Some(0.5 * (v[n / 2 - 1] + v[n / 2])),
    }
}

/// Standard normal CDF Φ(x).
pub fn normal_cdf(x: f64) -> f64 {
    0.5 * erfc(-x / std::f64::consts::SQRT_2)
}

/// Two-sided p-value of a standard normal z score.
pub fn two_sided_p(z: f64) -> f64 {
    erfc(z.abs() / std::f64::consts::SQRT_2)
}

/// Šidák-corrected per-test significance for `n` tests at family level `alpha`.
pub fn sidak_alpha(alpha: f64, n: usize) -> f64 {
    1.0 - (1.0 - alpha).powf(1.0 / n.max(1) as f64)
}

/// Complementary error function. Series for small |x|, Lentz continued fraction for large.
pub fn erfc(x: f64) -> f64 {
    if x < 0.0 {
        return 2.0 - erfc(-x);
    }
    if x < 2.0 {
        // erf(x) = 2/√π Σ (-1)^n x^(2n+1) / (n! (2n+1))
        let mut sum = 0.0f64;
        let mut term = x;
        let x2 = x * x;
        let mut n = 0.0;
        while term.abs() > 1e-17 * sum.abs().max(1e-300) {
            sum += term / (2.0 * n + 1.0);
            n += 1.0;
            term *= -x2 / n;
            if n > 200.0 {
                break;
            }
        }
        return 1.0 - 2.0 / std::f64::consts::PI.sqrt() * sum;
    }
    // erfc(x) = exp(-x²)/√π · 1/(x + 1/2/(x + 1/(x + 3/2/(x + …)))) (modified Lentz)
    let tiny = 1e-300;
    let mut f = x;
    let mut c = x;
    let mut d = 0.0;
    for k in 1..300 {
        let a = k as f64 / 2.0;
        d = x + a * d;
        d = if d.abs() < tiny { tiny } else { d };
        c = x + a / c;
        c = if c.abs() < tiny { tiny } else { c };
        d = 1.0 / d;
        let delta = c * d;
        f *= delta;
        if (delta - 1.0).abs() < 1e-16 {
            break;
        }
    }
    (-x * x).exp() / std::f64::consts::PI.sqrt() / f
}

/// ln Γ(x) for x > 0 (Lanczos, g = 7, 9 terms; ~1e-15 relative).
pub fn ln_gamma(x: f64) -> f64 {
    const G: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection: Γ(x)Γ(1 − x) = π / sin(πx).
        return (std::f64::consts::PI / (std::f64::consts::PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let t = x + 7.5;
    let sum = G[1..].iter().enumerate().fold(G[0], |s, (i, g)| s + g / (x + i as f64 + 1.0));
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + sum.ln()
}

/// Regularised upper incomplete gamma Q(a, x) = Γ(a, x)/Γ(a): the series for x < a + 1, the
/// Lentz continued fraction beyond (Numerical Recipes §6.2).
pub fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let log_prefactor = a * x.ln() - x - ln_gamma(a);
    if x < a + 1.0 {
        let (mut term, mut sum, mut n) = (1.0 / a, 1.0 / a, a);
        for _ in 0..1000 {
            n += 1.0;
            term *= x / n;
            sum += term;
            if term.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        return (1.0 - sum * log_prefactor.exp()).clamp(0.0, 1.0);
    }
    let tiny = 1e-300;
    let mut b = x + 1.0 - a;
    let mut c = 1.0 / tiny;
    let mut d = 1.0 / b;
    let mut h = d;
    for i in 1..1000 {
        let an = -(i as f64) * (i as f64 - a);
        b += 2.0;
        d = an * d + b;
        d = if d.abs() < tiny { tiny } else { d };
        c = b + an / c;
        c = if c.abs() < tiny { tiny } else { c };
        d = 1.0 / d;
        let delta = d * c;
        h *= delta;
        if (delta - 1.0).abs() < 1e-16 {
            break;
        }
    }
    (log_prefactor.exp() * h).clamp(0.0, 1.0)
}

/// Survival function of the χ² distribution with `dof` degrees of freedom: P(X ≥ x).
pub fn chi2_sf(x: f64, dof: f64) -> f64 {
    gamma_q(dof / 2.0, x / 2.0)
}

/// Pearson's χ² goodness-of-fit test of observed counts against expected counts, as pbrt-v4
/// and Mitsuba 3 run it on sampling routines: cells expecting fewer than 5 are pooled (the
/// pool joins the test if it then expects 5 or more). Returns the p-value, or `None` when fewer
/// than two cells remain. A cell with no expectation but observations makes the p-value 0.
pub fn chi2_test(observed: &[f64], expected: &[f64]) -> Option<f64> {
    let (mut chi2, mut cells) = (0.0, 0usize);
    let (mut pool_o, mut pool_e) = (0.0, 0.0);
    for (&o, &e) in observed.iter().zip(expected) {
        if e <= 0.0 {
            if o > 0.0 {
                return Some(0.0);
            }
            continue;
        }
        if e < 5.0 {
            pool_o += o;
            pool_e += e;
        } else {
            chi2 += (o - e) * (o - e) / e;
            cells += 1;
        }
    }
    if pool_e >= 5.0 {
        chi2 += (pool_o - pool_e) * (pool_o - pool_e) / pool_e;
        cells += 1;
    }
    (cells >= 2).then(|| chi2_sf(chi2, (cells - 1) as f64))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erfc_known_values() {
        assert!((erfc(0.0) - 1.0).abs() < 1e-15);
        assert!((erfc(1.0) - 0.157_299_207_050_285_13).abs() < 1e-14);
        assert!((erfc(2.5) - 4.069_520_174_449_589_7e-4).abs() < 1e-16);
        assert!((normal_cdf(1.959_963_984_540_054) - 0.975).abs() < 1e-12);
    }

    /// Known values: Γ(5) = 24, Γ(½) = √π; χ² survival at textbook points (dof 1: 3.841 → 0.05;
    /// dof 10: 18.307 → 0.05; dof 100: 124.342 → 0.05) and Q(1, x) = e^(−x).
    #[test]
    fn gamma_and_chi_square() {
        assert!((ln_gamma(5.0) - 24f64.ln()).abs() < 1e-12);
        assert!((ln_gamma(0.5) - std::f64::consts::PI.sqrt().ln()).abs() < 1e-12);
        for (x, dof) in
            [(3.841_458_820_694_124, 1.0), (18.307_038_053_275_14, 10.0), (124.342_113_404_047_6, 100.0)]
        {
            assert!((chi2_sf(x, dof) - 0.05).abs() < 1e-9, "χ²({x}, {dof}) = {}", chi2_sf(x, dof));
        }
        for x in [0.1, 1.0, 3.0, 30.0] {
            assert!((gamma_q(1.0, x) - (-x as f64).exp()).abs() < 1e-13);
        }
        // Counts equal to their expectations pass; a cell with no expectation fails.
        assert!((chi2_test(&[10.0, 20.0, 30.0], &[10.0, 20.0, 30.0]).unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(chi2_test(&[10.0, 1.0], &[11.0, 0.0]), Some(0.0));
        assert!(chi2_test(&[100.0, 100.0], &[150.0, 50.0]).unwrap() < 1e-10);
    }
}
