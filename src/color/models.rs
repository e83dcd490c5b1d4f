//! Colour-correction models: camera RGB → XYZ as a matrix M applied to an expansion of RGB,
//! xyz = M·e(rgb), e(rgb) a list of terms. Fitted by least squares over the chart's patches
//! unless said otherwise.
//!
//! - `linear-3x3`: e = (R, G, B).
//! - `white-preserving`: e = (R, G, B), M constrained to map the white patch's RGB to its
//!   reference XYZ exactly (least squares with one linear equality per row, solved in
//!   closed form by its Lagrange multiplier).
//! - `affine`: e = (R, G, B, 1).
//! - `root-poly-2`, `root-poly-3`: Finlayson, Mackiewicz & Hurlbert, "Color correction using
//!   root-polynomial regression", IEEE TIP 24(5), 2015: every term of degree d is a d-th root
//!   of a monomial of degree d, e.g. (R, G, B, √(RG), √(GB), √(RB)), so e(k·rgb) = k·e(rgb):
//!   the fit does not change with exposure.
//! - `cheung-N`: the polynomial expansions of Cheung et al., "Characterization of trichromatic
//!   color cameras by using a new multispectral imaging technique", JOSA A 21(7), 2004, with N
//!   terms as colour-science's `matrix_augmented_Cheung2004` lists them (N = 3, 4, 5, 7, 8, 10,
//!   11, 14, 16, 17, 19, 20, 22, 35; the same terms in the same order).
//! - `de2000-opt`: a 3×3 matrix whose coefficients minimise the mean CIEDE2000 over the
//!   patches directly (as OpenCV's `ccm` with `DISTANCE_CIE2000`); `de2000-opt:BASE` the same
//!   for another model's terms (`de2000-opt:root-poly-2` …). Started from BASE's
//!   least-squares fit and solved by argmin's L-BFGS (Moré–Thuente line search) on the
//!   mean of √(ΔE00ᵢ² + ε²), ε = 10⁻³ (smooth where a patch's error reaches zero), in the
//!   orthonormal coordinates of the design matrix's QR factors; the gradient by the chain
//!   rule through the linear model, ∂ΔE00/∂XYZ by central differences.
//!
//! Least squares through nalgebra's SVD; a design matrix whose smallest singular value is
//! below 10⁻¹⁰ of its largest (too few distinct patches for the terms) is refused, never
//! solved into NaN.

use super::delta_e::{delta_e2000, lab};
use crate::error::Invalid;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// A term of the expansion: (R^i·G^j·B^k)^(1/root), with the sign kept for a negative product.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Term {
    pub exponents: [u8; 3],
    pub root: u8,
}

impl Term {
    const fn poly(r: u8, g: u8, b: u8) -> Term {
        Term { exponents: [r, g, b], root: 1 }
    }
    const fn root(r: u8, g: u8, b: u8) -> Term {
        Term { exponents: [r, g, b], root: r + g + b }
    }

    pub fn eval(&self, rgb: [f64; 3]) -> f64 {
        let p: f64 = (0..3).map(|c| rgb[c].powi(self.exponents[c] as i32)).product();
        self.root_of(p)
    }

    /// The term's root of its monomial's value.
    fn root_of(&self, p: f64) -> f64 {
        match self.root {
            0 | 1 => p,
            2 => p.signum() * p.abs().sqrt(),
            3 => p.cbrt(),
            d => p.signum() * p.abs().powf(1.0 / d as f64),
        }
    }

    /// E.g. `R`, `R·G²`, `√(R·G)`, `1`.
    pub fn name(&self) -> String {
        let mut parts = Vec::new();
        for (c, &e) in self.exponents.iter().enumerate() {
            let ch = ["R", "G", "B"][c];
            match e {
                0 => {}
                1 => parts.push(ch.to_string()),
                _ => parts.push(format!("{ch}^{e}")),
            }
        }
        let body = if parts.is_empty() { "1".to_string() } else { parts.join("·") };
        match self.root {
            0 | 1 => body,
            2 => format!("sqrt({body})"),
            3 => format!("cbrt({body})"),
            d => format!("({body})^(1/{d})"),
        }
    }
}

/// The model a user names (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Model {
    Linear3x3,
    WhitePreserving,
    Affine,
    RootPoly(u8),
    Cheung(u8),
    /// A least-squares model's terms with coefficients minimising the mean ΔE00.
    De2000Opt(Basis),
}

/// The terms `de2000-opt` starts from (its least-squares fit is the start).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Basis {
    Linear3x3,
    Affine,
    RootPoly(u8),
    Cheung(u8),
}

impl Basis {
    fn model(self) -> Model {
        match self {
            Basis::Linear3x3 => Model::Linear3x3,
            Basis::Affine => Model::Affine,
            Basis::RootPoly(d) => Model::RootPoly(d),
            Basis::Cheung(n) => Model::Cheung(n),
        }
    }
}

/// The term counts colour-science's Cheung 2004 expansions exist for.
pub const CHEUNG_TERMS: [u8; 14] = [3, 4, 5, 7, 8, 10, 11, 14, 16, 17, 19, 20, 22, 35];

/// Every model name, for messages.
pub const MODEL_NAMES: &str = "linear-3x3, white-preserving, affine, root-poly-2, root-poly-3, cheung-N (N = 3, 4, 5, 7, 8, 10, 11, 14, 16, 17, 19, 20, 22, 35), de2000-opt (3×3) or de2000-opt:BASE (BASE one of linear-3x3, affine, root-poly-2, root-poly-3, cheung-N)";

impl std::str::FromStr for Model {
    type Err = Invalid;
    fn from_str(s: &str) -> Result<Model, Invalid> {
        Ok(match s {
            "linear-3x3" => Model::Linear3x3,
            "white-preserving" => Model::WhitePreserving,
            "affine" => Model::Affine,
            "root-poly-2" => Model::RootPoly(2),
            "root-poly-3" => Model::RootPoly(3),
            "de2000-opt" => Model::De2000Opt(Basis::Linear3x3),
            _ if s.starts_with("de2000-opt:") => {
                let base: Model = s["de2000-opt:".len()..].parse()?;
                Model::De2000Opt(match base {
                    Model::Linear3x3 => Basis::Linear3x3,
                    Model::Affine => Basis::Affine,
                    Model::RootPoly(d) => Basis::RootPoly(d),
                    Model::Cheung(n) => Basis::Cheung(n),
                    _ => return Err(format!("model `{s}`: de2000-opt starts from linear-3x3, affine, root-poly-2, root-poly-3 or cheung-N").into()),
                })
            }
            _ => match s.strip_prefix("cheung-").map(str::parse::<u8>) {
                Some(Ok(n)) if CHEUNG_TERMS.contains(&n) => Model::Cheung(n),
                _ => return Err(format!("model `{s}`: expected one of {MODEL_NAMES}").into()),
            },
        })
    }
}

impl Model {
    pub fn name(&self) -> String {
        match self {
            Model::Linear3x3 => "linear-3x3".into(),
            Model::WhitePreserving => "white-preserving".into(),
            Model::Affine => "affine".into(),
            Model::RootPoly(d) => format!("root-poly-{d}"),
            Model::Cheung(n) => format!("cheung-{n}"),
            Model::De2000Opt(Basis::Linear3x3) => "de2000-opt".into(),
            Model::De2000Opt(b) => format!("de2000-opt:{}", b.model().name()),
        }
    }

    /// The expansion's terms, in colour-science's order.
    pub fn terms(&self) -> Vec<Term> {
        let p = Term::poly;
        let rgb = vec![p(1, 0, 0), p(0, 1, 0), p(0, 0, 1)];
        match *self {
            Model::Linear3x3 | Model::WhitePreserving => rgb,
            Model::De2000Opt(b) => b.model().terms(),
            Model::Affine => [rgb, vec![p(0, 0, 0)]].concat(),
            Model::RootPoly(d) => {
                let r = Term::root;
                let mut t = [rgb, vec![r(1, 1, 0), r(0, 1, 1), r(1, 0, 1)]].concat();
                if d >= 3 {
                    t.extend([
                        r(1, 2, 0),
                        r(0, 1, 2),
                        r(1, 0, 2),
                        r(2, 1, 0),
                        r(0, 2, 1),
                        r(2, 0, 1),
                        r(1, 1, 1),
                    ]);
                }
                t
            }
            Model::Cheung(n) => cheung_terms(n),
        }
    }
}

/// colour-science's `matrix_augmented_Cheung2004` term lists.
fn cheung_terms(n: u8) -> Vec<Term> {
    let p = Term::poly;
    let one = p(0, 0, 0);
    let rgb = [p(1, 0, 0), p(0, 1, 0), p(0, 0, 1)];
    let cross = [p(1, 1, 0), p(1, 0, 1), p(0, 1, 1)];
    let squares = [p(2, 0, 0), p(0, 2, 0), p(0, 0, 2)];
    let rgb3 = p(1, 1, 1);
    let cubes = [p(3, 0, 0), p(0, 3, 0), p(0, 0, 3)];
    // R²G, G²B, B²R and R²B, G²R, B²G.
    let mixed_a = [p(2, 1, 0), p(0, 2, 1), p(1, 0, 2)];
    let mixed_b = [p(2, 0, 1), p(1, 2, 0), p(0, 1, 2)];
    let mut t: Vec<Term> = rgb.to_vec();
    let cat = |t: &mut Vec<Term>, more: &[Term]| t.extend_from_slice(more);
    match n {
        3 => {}
        4 => cat(&mut t, &[one]),
        5 => cat(&mut t, &[rgb3, one]),
        7 => cat(&mut t, &[cross.as_slice(), &[one]].concat()),
        8 => cat(&mut t, &[cross.as_slice(), &[rgb3, one]].concat()),
        10 => cat(&mut t, &[cross.as_slice(), &squares, &[one]].concat()),
        11 => cat(&mut t, &[cross.as_slice(), &squares, &[rgb3, one]].concat()),
        14 => cat(&mut t, &[cross.as_slice(), &squares, &[rgb3], &cubes, &[one]].concat()),
        16 | 17 => {
            cat(&mut t, &[cross.as_slice(), &squares, &[rgb3], &mixed_a, &cubes].concat());
            if n == 17 {
                t.push(one);
            }
        }
        19 | 20 | 22 | 35 => {
            cat(&mut t, &[cross.as_slice(), &squares, &[rgb3], &mixed_a, &mixed_b, &cubes].concat());
            match n {
                20 => t.push(one),
                22 => cat(&mut t, &[p(2, 1, 1), p(1, 2, 1), p(1, 1, 2)]),
                35 => cat(
                    &mut t,
                    &[
                        p(3, 1, 0),
                        p(3, 0, 1),
                        p(1, 3, 0),
                        p(0, 3, 1),
                        p(1, 0, 3),
                        p(0, 1, 3),
                        p(2, 1, 1),
                        p(1, 2, 1),
                        p(1, 1, 2),
                        p(2, 2, 0),
                        p(2, 0, 2),
                        p(0, 2, 2),
                        p(4, 0, 0),
                        p(0, 4, 0),
                        p(0, 0, 4),
                        one,
                    ],
                ),
                _ => {}
            }
        }
        _ => {}
    }
    t
}

/// A fitted model: xyz[c] = Σₖ matrix[c][k]·terms[k](rgb).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Fitted {
    pub model: String,
    pub terms: Vec<Term>,
    /// Three rows (X, Y, Z), one coefficient per term.
    pub matrix: [Vec<f64>; 3],
}

impl Fitted {
    pub fn apply(&self, rgb: [f64; 3]) -> [f64; 3] {
        // Term by term from a table of powers, without a buffer: this runs once per pixel in
        // `lumen color apply` (`check` keeps exponents at most 8).
        let mut pow = [[1.0f64; 9]; 3];
        for c in 0..3 {
            for e in 1..9 {
                pow[c][e] = pow[c][e - 1] * rgb[c];
            }
        }
        let mut out = [0.0; 3];
        for (k, t) in self.terms.iter().enumerate() {
            let [i, j, l] = t.exponents.map(|e| (e as usize).min(8));
            let e = t.root_of(pow[0][i] * pow[1][j] * pow[2][l]);
            for c in 0..3 {
                out[c] += self.matrix[c][k] * e;
            }
        }
        out
    }

    /// The model read from a file is usable: three rows as long as its terms, every number
    /// finite, roots and exponents as the models use them.
    pub fn check(&self) -> Result<(), Invalid> {
        if self.terms.is_empty() || self.terms.len() > 64 {
            return Err(format!("{} terms: expected 1 to 64", self.terms.len()).into());
        }
        if let Some(t) = self.terms.iter().find(|t| t.exponents.iter().any(|&e| e > 8) || t.root > 8) {
            return Err(format!("term {t:?}: exponents and roots must be at most 8").into());
        }
        for (c, row) in self.matrix.iter().enumerate() {
            if row.len() != self.terms.len() {
                return Err(format!(
                    "matrix row {c} has {} coefficients for {} terms",
                    row.len(),
                    self.terms.len()
                )
                .into());
            }
            if let Some(v) = row.iter().find(|v| !v.is_finite()) {
                return Err(format!("matrix row {c} holds {v}: expected finite numbers").into());
            }
        }
        Ok(())
    }
}

/// Why a fit has no answer.
#[derive(Debug, Clone, PartialEq)]
pub enum FitError {
    /// Fewer patches than the model has coefficients per row.
    TooFew { patches: usize, needed: usize },
    /// The patches do not determine the coefficients (smallest/largest singular value).
    RankDeficient { ratio: f64 },
    /// The white patch, needed by `white-preserving`, is not among the usable patches.
    NoWhite,
    /// A term of some patch's RGB overflows f64.
    Overflow,
}

impl std::fmt::Display for FitError {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        match self {
            FitError::TooFew { patches, needed } => {
                write!(f, "{patches} usable patch(es), but the model needs at least {needed}")
            }
            FitError::RankDeficient { ratio } => write!(
                f,
                "the usable patches do not determine the model's coefficients (singular value ratio {ratio:.1e}, below 1e-10): too few distinct colours for its terms"
            ),
            FitError::NoWhite => write!(f, "the white patch is not usable, and white-preserving must map it exactly"),
            FitError::Overflow => write!(f, "a patch's RGB is so large that the model's terms overflow"),
        }
    }
}

/// Smallest over largest singular value below which a design matrix is refused.
const MIN_SINGULAR_RATIO: f64 = 1e-10;

/// The design matrix of an expansion over the patches.
fn design(terms: &[Term], rgb: &[[f64; 3]]) -> DMatrix<f64> {
    DMatrix::from_fn(rgb.len(), terms.len(), |i, k| terms[k].eval(rgb[i]))
}

/// Fits a model. `white` is the white of L*a*b* (for `de2000-opt`); `white_patch` the index
/// into `rgb` of the patch `white-preserving` maps exactly.
pub fn fit(
    model: Model,
    rgb: &[[f64; 3]],
    xyz: &[[f64; 3]],
    white: [f64; 3],
    white_patch: Option<usize>,
) -> Result<Fitted, FitError> {
    let terms = model.terms();
    let needed = terms.len();
    if rgb.len() < needed {
        return Err(FitError::TooFew { patches: rgb.len(), needed });
    }
    let a = design(&terms, rgb);
    if a.iter().any(|v| !v.is_finite()) {
        return Err(FitError::Overflow);
    }
    // Bounded iterations: an SVD that does not converge is a refusal, not a hang.
    let svd =
        a.clone().try_svd(true, true, f64::EPSILON, 10_000).ok_or(FitError::RankDeficient { ratio: 0.0 })?;
    let (smax, smin) =
        svd.singular_values.iter().fold((0.0f64, f64::INFINITY), |(hi, lo), &s| (hi.max(s), lo.min(s)));
    let ratio = if smax > 0.0 { smin / smax } else { 0.0 };
    if !(ratio >= MIN_SINGULAR_RATIO) {
        return Err(FitError::RankDeficient { ratio });
    }
    let b = DMatrix::from_fn(rgb.len(), 3, |i, c| xyz[i][c]);
    let mut m = svd.solve(&b, 0.0).map_err(|_| FitError::RankDeficient { ratio })?; // terms × 3
    if model == Model::WhitePreserving {
        let w = white_patch.filter(|&i| i < rgb.len()).ok_or(FitError::NoWhite)?;
        // min ‖A·m − y‖² subject to eᵀ·m = x: m = m_ls − G⁻¹e·(eᵀm_ls − x)/(eᵀG⁻¹e), G = AᵀA.
        let e = DVector::from_iterator(needed, terms.iter().map(|t| t.eval(rgb[w])));
        let g = a.transpose() * &a;
        let ginv_e = g.lu().solve(&e).ok_or(FitError::RankDeficient { ratio })?;
        let denom = e.dot(&ginv_e);
        for c in 0..3 {
            let mc = m.column(c).clone_owned();
            let excess = e.dot(&mc) - xyz[w][c];
            m.set_column(c, &(mc - &ginv_e * (excess / denom)));
        }
    }
    let mut fitted = Fitted {
        model: model.name(),
        matrix: [0, 1, 2].map(|c| m.column(c).iter().copied().collect()),
        terms,
    };
    if let Model::De2000Opt(_) = model {
        fitted = minimise_de2000(fitted, rgb, xyz, white);
    }
    Ok(fitted)
}

/// Mean CIEDE2000 of a model over patches.
pub fn mean_de2000(f: &Fitted, rgb: &[[f64; 3]], xyz: &[[f64; 3]], white: [f64; 3]) -> f64 {
    let n = rgb.len().max(1) as f64;
    rgb.iter().zip(xyz).map(|(&c, &x)| delta_e2000(lab(f.apply(c), white), lab(x, white))).sum::<f64>() / n
}

/// The mean ΔE00 of the patches as a function of the coefficients, for argmin, made smooth
/// where a patch's ΔE00 reaches 0 by √(ΔE² + ε²) with ε = 10⁻³ (a thousandth of a just
/// noticeable difference). The terms of each patch and its reference L*a*b* are computed
/// once.
struct MeanDe2000 {
    /// Per patch: the expansion's terms, and the reference L*a*b*.
    terms: Vec<Vec<f64>>,
    target: Vec<[f64; 3]>,
    white: [f64; 3],
}

const SMOOTHING: f64 = 1e-3;

impl MeanDe2000 {
    fn new(start: &Fitted, rgb: &[[f64; 3]], xyz: &[[f64; 3]], white: [f64; 3]) -> MeanDe2000 {
        MeanDe2000 {
            terms: rgb.iter().map(|&c| start.terms.iter().map(|t| t.eval(c)).collect()).collect(),
            target: xyz.iter().map(|&x| lab(x, white)).collect(),
            white,
        }
    }

    /// The patch's predicted XYZ under the coefficients p (rows X, Y, Z of k terms each).
    fn xyz(&self, p: &DVector<f64>, i: usize) -> [f64; 3] {
        let (e, k) = (&self.terms[i], self.terms[i].len());
        [0, 1, 2].map(|c| p.as_slice()[c * k..(c + 1) * k].iter().zip(e).map(|(m, x)| m * x).sum())
    }

    fn smoothed(&self, xyz: [f64; 3], i: usize) -> f64 {
        (delta_e2000(lab(xyz, self.white), self.target[i]).powi(2) + SMOOTHING * SMOOTHING).sqrt()
    }

    fn value(&self, p: &DVector<f64>) -> f64 {
        let sum: f64 = (0..self.terms.len()).map(|i| self.smoothed(self.xyz(p, i), i)).sum();
        // An overflowing candidate is pushed back by the line search.
        if sum.is_finite() {
            sum / self.terms.len().max(1) as f64
        } else {
            f64::MAX
        }
    }
}

impl argmin::core::CostFunction for MeanDe2000 {
    type Param = DVector<f64>;
    type Output = f64;
    fn cost(&self, p: &DVector<f64>) -> Result<f64, argmin::core::Error> {
        Ok(self.value(p))
    }
}

impl argmin::core::Gradient for MeanDe2000 {
    type Param = DVector<f64>;
    type Gradient = DVector<f64>;
    /// By the chain rule: ∂/∂M[c][k] = ∂ΔE/∂XYZ_c · e_k, with ∂ΔE/∂XYZ by central
    /// differences (ΔE00's closed-form derivative is long and buys nothing here).
    fn gradient(&self, p: &DVector<f64>) -> Result<DVector<f64>, argmin::core::Error> {
        let mut g = DVector::zeros(p.len());
        let n = self.terms.len().max(1) as f64;
        for (i, e) in self.terms.iter().enumerate() {
            let xyz = self.xyz(p, i);
            let k = e.len();
            for c in 0..3 {
                let h = 1e-7 * xyz[c].abs().max(1e-4);
                let (mut a, mut b) = (xyz, xyz);
                a[c] += h;
                b[c] -= h;
                let d = (self.smoothed(a, i) - self.smoothed(b, i)) / (2.0 * h) / n;
                for (t, &x) in e.iter().enumerate() {
                    g[c * k + t] += d * x;
                }
            }
        }
        Ok(g)
    }
}

/// L-BFGS with a Moré–Thuente line search (argmin) on the mean ΔE00 from a least-squares
/// fit (module docs). Keeps the start when the search finds nothing better.
fn minimise_de2000(start: Fitted, rgb: &[[f64; 3]], xyz: &[[f64; 3]], white: [f64; 3]) -> Fitted {
    use argmin::core::{Executor, State};
    use argmin::solver::linesearch::MoreThuenteLineSearch;
    use argmin::solver::quasinewton::LBFGS;
    // Searched in orthonormal coordinates: with the design matrix A = Q·R (thin QR), the
    // prediction A·m = Q·(R·m), so the search runs over q = R·m with the patches' terms the
    // rows of Q. Root-polynomial terms are strongly correlated; in q they are not, and the
    // search converges in tens of iterations instead of hundreds.
    let k = start.terms.len();
    let qr = design(&start.terms, rgb).qr();
    let (q, r) = (qr.q(), qr.r());
    let Some(r_inv) = r.clone().try_inverse() else { return start };
    let mut problem = MeanDe2000::new(&start, rgb, xyz, white);
    problem.terms = q.row_iter().map(|row| row.iter().copied().collect()).collect();
    let mut p0 = DVector::zeros(3 * k);
    for c in 0..3 {
        let qc = &r * DVector::from_column_slice(&start.matrix[c]);
        p0.rows_mut(c * k, k).copy_from(&qc);
    }
    let cost0 = problem.value(&p0);
    let best = (|| {
        let solver = LBFGS::new(MoreThuenteLineSearch::new(), 10).with_tolerance_cost(1e-9).ok()?;
        let result = Executor::new(problem, solver)
            .configure(|s| s.param(p0.clone()).max_iters(DE2000_ITERATIONS))
            .timer(false)
            .run()
            .ok()?;
        let state = result.state();
        let p = state.get_best_param()?.clone();
        (state.get_best_cost() < cost0 && p.iter().all(|v| v.is_finite())).then_some(p)
    })();
    let Some(p) = best else { return start };
    let mut fitted = start;
    for c in 0..3 {
        let m = &r_inv * p.rows(c * k, k);
        fitted.matrix[c] = m.iter().copied().collect();
    }
    fitted
}

/// Most L-BFGS iterations of `de2000-opt` (on the ColorChecker it converges in 100 to 300).
const DE2000_ITERATIONS: u64 = 500;

#[cfg(test)]
mod tests {
    use super::*;

    /// Every model name parses back to itself; the Cheung lists have the length they name.
    #[test]
    fn names_and_term_counts() {
        for n in CHEUNG_TERMS {
            let m: Model = format!("cheung-{n}").parse().unwrap();
            assert_eq!(m.terms().len(), n as usize, "cheung-{n}");
            assert_eq!(m.name(), format!("cheung-{n}"));
        }
        for name in [
            "linear-3x3",
            "white-preserving",
            "affine",
            "root-poly-2",
            "root-poly-3",
            "de2000-opt",
            "de2000-opt:root-poly-2",
            "de2000-opt:cheung-7",
        ] {
            assert_eq!(name.parse::<Model>().unwrap().name(), name);
        }
        assert_eq!(Model::RootPoly(2).terms().len(), 6);
        assert_eq!(Model::RootPoly(3).terms().len(), 13);
        assert!("cheung-6".parse::<Model>().is_err());
        assert!("de2000-opt:white-preserving".parse::<Model>().is_err());
        assert_eq!("de2000-opt:root-poly-2".parse::<Model>().unwrap().terms().len(), 6);
        assert!("poly".parse::<Model>().unwrap_err().0.contains("root-poly-2"));
    }

    /// Root-polynomial terms scale with the exposure: e(k·rgb) = k·e(rgb).
    #[test]
    fn root_polynomial_terms_are_homogeneous() {
        let rgb = [0.3, 0.5, 0.2];
        for t in Model::RootPoly(3).terms() {
            assert!((t.eval(rgb.map(|v| 4.0 * v)) - 4.0 * t.eval(rgb)).abs() < 1e-12, "{}", t.name());
        }
    }

    /// A model fitted to data it can represent exactly recovers it; the white-preserving
    /// fit maps the white exactly even when the data are not exact.
    #[test]
    fn exact_recovery_and_white_constraint() {
        let m = [[0.6, 0.3, 0.1], [0.2, 0.7, 0.1], [0.05, 0.1, 0.9]];
        let rgb: Vec<[f64; 3]> = (0..24)
            .map(|i| {
                let f = i as f64;
                [
                    (0.1 + 0.37 * f).fract() + 0.02,
                    (0.3 + 0.61 * f).fract() + 0.02,
                    (0.7 + 0.23 * f).fract() + 0.02,
                ]
            })
            .collect();
        let xyz: Vec<[f64; 3]> =
            rgb.iter().map(|c| m.map(|row| row[0] * c[0] + row[1] * c[1] + row[2] * c[2])).collect();
        let f = fit(Model::Linear3x3, &rgb, &xyz, [0.95, 1.0, 1.09], None).unwrap();
        for c in 0..3 {
            for k in 0..3 {
                assert!((f.matrix[c][k] - m[c][k]).abs() < 1e-12);
            }
        }
        let bent: Vec<[f64; 3]> =
            xyz.iter().map(|x| [x[0] * 1.02, x[1], x[2] * 0.97 + 0.01 * x[0]]).collect();
        let w = fit(Model::WhitePreserving, &rgb, &bent, [0.95, 1.0, 1.09], Some(5)).unwrap();
        let mapped = w.apply(rgb[5]);
        assert!((0..3).all(|c| (mapped[c] - bent[5][c]).abs() < 1e-12), "{mapped:?} vs {:?}", bent[5]);
    }

    /// Too few patches, or patches that are all one colour: a clear refusal, never NaN.
    #[test]
    fn refusals() {
        let rgb = vec![[0.2, 0.3, 0.4]; 10];
        let xyz = vec![[0.3, 0.3, 0.3]; 10];
        assert_eq!(
            fit(Model::RootPoly(3), &rgb, &xyz, [1.0; 3], None),
            Err(FitError::TooFew { patches: 10, needed: 13 })
        );
        assert!(matches!(
            fit(Model::Linear3x3, &rgb, &xyz, [1.0; 3], None),
            Err(FitError::RankDeficient { .. })
        ));
        assert!(matches!(
            fit(Model::WhitePreserving, &rgb[..2], &xyz[..2], [1.0; 3], Some(0)),
            Err(FitError::TooFew { .. })
        ));
    }
}
