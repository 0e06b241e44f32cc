//! Bounds on networks over boxes: interval bound propagation (IBP) and CROWN.
//!
//! CROWN computes, for a specification matrix `S`, linear functions with
//! `S f(y) ≤ Λ y + c` for every `y` in the input box. Pre-activation bounds of
//! every hidden layer are themselves computed by CROWN (and intersected with
//! IBP's), then each neuron is relaxed by [`relax`](super::relax). A ReLU
//! whose input IBP already proves non-positive is not back-substituted: it
//! outputs 0 whatever its bounds, so no bound changes; and once any bound
//! proves a ReLU inactive, back-substitution leaves it out of every product
//! (`Packed`). Skipping a bound only ever keeps interval arithmetic's
//! (valid) box in its place: every relaxation is still computed from the
//! box it has, so a skip can cost tightness, never soundness.
//!
//! All coefficient arithmetic is done in `f64`; the rounding error of every
//! matrix product is accounted for by widening the offset with
//! `γ(n)·|Λ|·(|W|·|h|max)` (see [`LinearUpper::through_affine`]), so the
//! returned bounds hold for the exact network.

use std::borrow::Cow;

use nalgebra::{DMatrix, DVector};

pub use super::dense::Rows;
use super::relax::{image, relax_in_mode, Relax};
use crate::issue::Issue;
use crate::sets::{IBox, Region};
use ravel_base::nn::{Activation, Layer, Network};
use ravel_base::num::{self, gamma, mul0, slack, term_lower, term_upper, Acc, TINY, U};

/// Rows of linear upper bounds: `sᵣ ≤ coefᵣ · z + offsetᵣ` for every feasible `z`.
///
/// Every operation works row by row on contiguous rows ([`Rows`]) and sums
/// each row's terms with one running [`Acc`], so a bound costs its
/// multiply-adds and a few allocations per layer, not per entry.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearUpper {
    /// `k × n` coefficients.
    pub coef: Rows,
    /// `k` offsets.
    pub offset: Vec<f64>,
}

impl LinearUpper {
    /// The identity bound `sᵣ ≤ Fᵣ z` for a specification matrix `F`.
    pub fn of_spec(f: impl Into<Rows>) -> LinearUpper {
        let coef = f.into();
        let k = coef.nrows();
        LinearUpper {
            coef,
            offset: vec![0.0; k],
        }
    }

    /// Substitute `z = W z' + b` (exactly), where `|z'| ≤ abs_in` element-wise.
    /// The product `coef · W` is rounded; its error is added to the offsets.
    pub fn through_affine(
        &self,
        w: &DMatrix<f64>,
        b: &DVector<f64>,
        abs_in: &[f64],
    ) -> LinearUpper {
        let mut out = self.through_affine_scaled(w, b, &weight_scale(w, abs_in));
        // the coefficient products' underflow (see `underflow_allowance`)
        let allow = underflow_of(abs_in);
        for o in &mut out.offset {
            *o = num::sum_upper([*o, allow]);
        }
        out
    }

    /// [`LinearUpper::through_affine`] with `|W|·|z'|max` precomputed (see [`weight_scale`]).
    pub fn through_affine_scaled(
        &self,
        w: &DMatrix<f64>,
        b: &DVector<f64>,
        wz: &[f64],
    ) -> LinearUpper {
        let mut coef = Rows::zeros(0, 0);
        let mut acc: Vec<Acc> = self.offset.iter().map(|&o| Acc::of(o)).collect();
        affine_into(
            &self.coef,
            &mut acc,
            &Packed::new(w, b, wz, None, None),
            wz,
            &mut coef,
        );
        LinearUpper {
            coef,
            offset: acc.into_iter().map(Acc::upper).collect(),
        }
    }

    /// The sum of two bounds on the same variables (`|z| ≤ abs_in`).
    pub fn add(&self, other: &LinearUpper, abs_in: &[f64]) -> LinearUpper {
        let coef = self.coef.plus(&other.coef);
        let offset = coef
            .iter_rows()
            .zip(self.offset.iter().zip(&other.offset))
            .map(|(row, (&a, &b))| {
                let mut acc = Acc::ZERO;
                acc.add(a);
                acc.add(b);
                acc.add(slack(2.0 * U, row, abs_in));
                acc.upper()
            })
            .collect();
        LinearUpper { coef, offset }
    }

    /// Keep the first `keep` variables and bound the rest over `tail` (added to
    /// the offsets): a bound on `(z, ζ)` becomes one on `z` valid for all `ζ ∈ tail`.
    pub fn split_concretize(&self, keep: usize, tail: &IBox) -> LinearUpper {
        let coef = self.coef.first_columns(keep);
        let offset = self
            .coef
            .iter_rows()
            .zip(&self.offset)
            .map(|(row, &o)| {
                let mut acc = Acc::ZERO;
                acc.add(o);
                for (&a, (&l, &h)) in row[keep..].iter().zip(tail.lo.iter().zip(&tail.hi)) {
                    acc.add(term_upper(a, l, h));
                }
                acc.upper()
            })
            .collect();
        LinearUpper { coef, offset }
    }

    /// Certified upper bounds of each row over a region, and the solver
    /// issues met (each bound is valid regardless; see [`crate::lp`]).
    pub fn concretize_region(&self, region: &Region) -> (Vec<f64>, Vec<Issue>) {
        if let Region::Box(b) = region {
            return (self.concretize(b), Vec::new());
        }
        let mut issues = Vec::new();
        let ub = self
            .coef
            .iter_rows()
            .zip(&self.offset)
            .map(|(row, &o)| {
                let s = region.support(row);
                issues.extend(s.issue);
                let mut acc = Acc::ZERO;
                acc.add(s.value);
                acc.add(o);
                acc.upper()
            })
            .collect();
        (ub, issues)
    }

    /// Certified upper bounds of each row over the box.
    pub fn concretize(&self, b: &IBox) -> Vec<f64> {
        self.coef
            .iter_rows()
            .zip(&self.offset)
            .map(|(row, &o)| {
                let mut acc = Acc::ZERO;
                for (&a, (&l, &h)) in row.iter().zip(b.lo.iter().zip(&b.hi)) {
                    acc.add(term_upper(a, l, h));
                }
                acc.add(o);
                acc.upper()
            })
            .collect()
    }
}

/// One affine layer of back-substitution: `out = coef · W`, and each offset
/// raised by `coefᵣ · b` and the product's rounding error `γ·|coefᵣ|·wz`.
/// The offsets are running sums ([`Acc`]) over every layer passed so far:
/// rounded once, at the end of the back-substitution, with the error bound
/// of all their terms (each term is one rounding from its value, as
/// [`Acc`] requires, whichever layer added it).
fn affine_into(coef: &Rows, offset: &mut [Acc], w: &Packed, wz: &[f64], out: &mut Rows) {
    if let Some(sign) = w.identity {
        // W = ±I (the clamp layers of control limits): the product is
        // exact, so it has no rounding error to account for
        out.clone_from(coef);
        if sign < 0.0 {
            out.negate();
        }
        for (row, acc) in coef.iter_rows().zip(offset.iter_mut()) {
            acc.add_products(row, &w.b);
        }
        return;
    }
    coef.mul_cols_into(&w.w, w.rows, w.cols, out);
    let k = gamma(w.rows + 2);
    for (row, acc) in coef.iter_rows().zip(offset.iter_mut()) {
        acc.add_products(row, &w.b);
        acc.add(slack(k, row, wz));
    }
}

/// An affine layer `z = W h + b` as back-substitution reads it: restricted
/// to the outputs whose coefficients can be nonzero (the inputs of a ReLU
/// that interval arithmetic or CROWN does not prove inactive; all outputs
/// otherwise) and to the inputs that can be nonzero (the outputs of such a
/// ReLU). A ReLU proved inactive outputs exactly 0 and its relaxation is
/// `0 ≤ h ≤ 0`, so its coefficient is 0 after the relaxation and its
/// output's column contributes exactly 0 to every product: leaving both
/// out changes no coefficient, only shortens the sums (the rounding error
/// is then bounded with the shorter length).
#[derive(Clone, Debug)]
struct Packed<'a> {
    /// Column-major `rows × cols` weights (W itself when nothing is left out).
    w: Cow<'a, [f64]>,
    rows: usize,
    cols: usize,
    /// The kept outputs' biases.
    b: Cow<'a, [f64]>,
    /// `|W|·|h|max` of the kept outputs (see [`weight_scale`]), when some
    /// outputs are left out (otherwise the layer's own, which the caller has).
    wz: Option<Vec<f64>>,
    /// `Some(s)` when the packed matrix is `s·I`, `s = ±1`.
    identity: Option<f64>,
}

impl<'a> Packed<'a> {
    /// `W` and `b` restricted to `rows` (outputs) and `cols` (inputs),
    /// `None` meaning all; `wz` is `|W|·|h|max` of every output.
    fn new(
        w: &'a DMatrix<f64>,
        b: &'a DVector<f64>,
        wz: &[f64],
        rows: Option<&[usize]>,
        cols: Option<&[usize]>,
    ) -> Packed<'a> {
        let (nr, nc) = w.shape();
        let (data, b, wz) = match (rows, cols) {
            (None, None) => (
                Cow::Borrowed(w.as_slice()),
                Cow::Borrowed(b.as_slice()),
                None,
            ),
            (None, Some(cols)) => {
                let mut data = Vec::with_capacity(nr * cols.len());
                for &c in cols {
                    data.extend_from_slice(&w.as_slice()[c * nr..(c + 1) * nr]);
                }
                (Cow::Owned(data), Cow::Borrowed(b.as_slice()), None)
            }
            (Some(rows), cols) => {
                let all: Vec<usize>;
                let cols = match cols {
                    Some(c) => c,
                    None => {
                        all = (0..nc).collect();
                        &all
                    }
                };
                let mut data = Vec::with_capacity(rows.len() * cols.len());
                for &c in cols {
                    let col = &w.as_slice()[c * nr..(c + 1) * nr];
                    data.extend(rows.iter().map(|&r| col[r]));
                }
                (
                    Cow::Owned(data),
                    Cow::Owned(rows.iter().map(|&r| b[r]).collect()),
                    Some(rows.iter().map(|&r| wz[r]).collect::<Vec<f64>>()),
                )
            }
        };
        let (rows, cols) = (
            rows.map_or(nr, <[usize]>::len),
            cols.map_or(nc, <[usize]>::len),
        );
        let identity = signed_identity(&data, rows, cols);
        Packed {
            w: data,
            rows,
            cols,
            b,
            wz,
            identity,
        }
    }
}

/// `Some(s)` when the column-major `n × m` matrix `w` is `s·I` with `s = ±1`.
pub(crate) fn signed_identity(w: &[f64], n: usize, m: usize) -> Option<f64> {
    if n != m || n == 0 {
        return None;
    }
    let s = w[0];
    if s != 1.0 && s != -1.0 {
        return None;
    }
    for (j, col) in w.chunks_exact(n).enumerate() {
        for (i, &v) in col.iter().enumerate() {
            if v != if i == j { s } else { 0.0 } {
                return None;
            }
        }
    }
    Some(s)
}

/// One activation layer of back-substitution, in place: each coefficient
/// `l` of `h = σ(z)` becomes `l·a` with the upper relaxation's slope `a`
/// when `l ≥ 0` (the lower one's otherwise), and its intercept times `l` goes
/// into the offset, with the products' rounding error (`|z| ≤ abs_in`).
fn relaxation_in_place(coef: &mut Rows, offset: &mut [Acc], rel: &[Relax], abs_in: &[f64]) {
    for (r, acc) in offset.iter_mut().enumerate() {
        let row = coef.row_mut(r);
        for (c, rl) in row.iter_mut().zip(rel) {
            let l = *c;
            // selects, not branches: the coefficients' signs are data
            let up = l >= 0.0;
            let a = if up { rl.au } else { rl.al };
            let b = if up { rl.bu } else { rl.bl };
            *c = l * a;
            let nonzero = l != 0.0;
            acc.add_counted(if nonzero { l * b } else { 0.0 }, nonzero);
        }
        acc.add(slack(2.0 * U, row, abs_in));
    }
}

/// The underflow of one layer's coefficient products in back-substitution,
/// applied to the values of `b`: a product that underflows is off by up
/// to η/2 (η the smallest subnormal) however small the coefficients are,
/// so the relative error terms (`slack`) miss it; with at most 2⁵² products
/// per coefficient it is at most `TINY·Σ_j max|b_j|` over the coefficients
/// (rounded up; `+∞` if the sum overflows). Negligible unless values near
/// 10³⁰ meet coefficients near the subnormal range, where it is what keeps
/// a bound sound (found by review: a `require 2η·y ≤ b` on a network whose
/// hidden values reach 10³⁰ was VERIFIED while false).
fn underflow_allowance(b: &IBox) -> f64 {
    let s: f64 =
        b.lo.iter()
            .zip(&b.hi)
            .map(|(l, h)| l.abs().max(h.abs()))
            .sum();
    num::sat_upper((TINY * s * 1.0625).next_up())
}

/// `underflow_allowance` of values with magnitudes at most `m`.
pub fn underflow_of(m: &[f64]) -> f64 {
    let s: f64 = m.iter().map(|v| v.abs()).sum();
    num::sat_upper((TINY * s * 1.0625).next_up())
}

/// Whether a ReLU whose input is at most `hi` is proved inactive (its
/// output is exactly 0). NaN is not: it is kept, and the analysis that
/// produced it is rejected as not finite.
fn inactive(hi: f64) -> bool {
    hi <= 0.0
}

/// Whether every row of `w` has at most one nonzero entry (a one-column
/// matrix, or a diagonal one such as a clamp's `±I`).
pub(crate) fn one_per_row(w: &DMatrix<f64>) -> bool {
    if w.ncols() <= 1 {
        return true;
    }
    // row by row, stopping at a row's second nonzero: a dense matrix
    // answers within its first row
    let rows = w.nrows();
    (0..rows).all(|r| {
        w.as_slice()[r..]
            .iter()
            .step_by(rows)
            .filter(|v| **v != 0.0)
            .nth(1)
            .is_none()
    })
}

/// For rows whose columns are the neurons `cols` (`None`: all), when every
/// row has at most one nonzero, finite, on a neuron among `stored`
/// (ascending): per row, that neuron's position in `stored` and the
/// coefficient (`None` for a row of zeros). `None` when some row does not.
fn single_rows(
    coef: &Rows,
    cols: Option<&[usize]>,
    stored: &[usize],
) -> Option<Vec<Option<(usize, f64)>>> {
    coef.iter_rows()
        .map(|row| match one_nonzero(row)? {
            None => Some(None),
            Some((c, v)) => {
                let j = cols.map_or(c, |k| k[c]);
                stored.binary_search(&j).ok().map(|p| Some((p, v)))
            }
        })
        .collect()
}

/// A row's nonzeros when it has at most one, finite: `Some(None)` for a
/// row of zeros, `Some(Some((column, value)))` for one; `None` otherwise
/// (two or more, or a non-finite one).
pub(crate) fn one_nonzero(row: &[f64]) -> Option<Option<(usize, f64)>> {
    let mut nz = row.iter().enumerate().filter(|(_, v)| **v != 0.0);
    match (nz.next(), nz.next()) {
        (None, _) => Some(None),
        (Some((c, &v)), None) if v.is_finite() => Some(Some((c, v))),
        _ => None,
    }
}

/// `|W|·m` rounded up, for `|z| ≤ m`: the scale of the rounding error of products with `W`.
pub fn weight_scale(w: &DMatrix<f64>, m: &[f64]) -> Vec<f64> {
    weight_scale_of(w, |i| m[i], None)
}

/// [`weight_scale`] over the columns `cols` only (all with `None`), with
/// `m(i)` the bound of input `i`: the others' must be 0 (their terms are
/// exactly 0).
///
/// The sums are kept as plain arrays (the terms are non-negative, so each
/// sum is its own absolute sum, and every row has the same count): the
/// same additions in the same order as one [`Acc`] per row, which the loop
/// over a column then vectorises.
fn weight_scale_of(w: &DMatrix<f64>, m: impl Fn(usize) -> f64, cols: Option<&[usize]>) -> Vec<f64> {
    let mut sum = vec![0.0; w.nrows()];
    weight_scale_into(w, m, cols, &mut sum);
    sum
}

/// [`weight_scale_of`] into `out` (`W`'s row count long).
pub(crate) fn weight_scale_into(
    w: &DMatrix<f64>,
    m: impl Fn(usize) -> f64,
    cols: Option<&[usize]>,
    out: &mut [f64],
) {
    let rows = w.nrows();
    out.fill(0.0);
    let mut terms = 0;
    if rows > 0 {
        let mut column = |i: usize| {
            let (col, mi) = (&w.as_slice()[i * rows..(i + 1) * rows], m(i));
            for (s, &wji) in out.iter_mut().zip(col) {
                *s += mul0(wji.abs(), mi);
            }
            terms += 1;
        };
        match cols {
            None => (0..w.ncols()).for_each(&mut column),
            Some(cols) => cols.iter().for_each(|&i| column(i)),
        }
    }
    for s in out.iter_mut() {
        *s = Acc::from_parts(*s, *s, terms).upper();
    }
}

/// The `2n × n` specification `[I; −I]`: upper bounds, then negated lower bounds.
pub fn plus_minus_identity(n: usize) -> Rows {
    let mut f = Rows::zeros(2 * n, n);
    for i in 0..n {
        f.row_mut(i)[i] = 1.0;
        f.row_mut(n + i)[i] = -1.0;
    }
    f
}

/// Certified interval image of a box under `z = W x + b`.
pub fn affine_image(w: &DMatrix<f64>, b: &DVector<f64>, x: &IBox) -> IBox {
    affine_image_of(w, b, x, None)
}

/// [`affine_image`] summing over the columns `cols` only (all with
/// `None`): the others' inputs must be exactly `[0, 0]`.
///
/// Each endpoint's running sum is kept as two plain arrays (the sum and
/// the absolute sum; every row has the same count): the same additions in
/// the same order as one [`Acc`] per row and endpoint, laid out so the loop
/// over a column vectorises.
pub(crate) fn affine_image_of(
    w: &DMatrix<f64>,
    b: &DVector<f64>,
    x: &IBox,
    cols: Option<&[usize]>,
) -> IBox {
    let rows = w.nrows();
    let mut sums = vec![0.0; 4 * rows];
    let (mut lo, mut hi) = (vec![0.0; rows], vec![0.0; rows]);
    affine_image_into(
        w,
        b.as_slice(),
        (&x.lo, &x.hi),
        cols,
        (&mut lo, &mut hi),
        &mut sums,
    );
    IBox::new(lo, hi)
}

/// [`affine_image_of`] of the box `[xl, xh]` into `lo`, `hi` (`W`'s row
/// count long), with `sums` (at least four times that) for the running sums.
pub(crate) fn affine_image_into(
    w: &DMatrix<f64>,
    b: &[f64],
    (xl, xh): (&[f64], &[f64]),
    cols: Option<&[usize]>,
    (lo, hi): (&mut [f64], &mut [f64]),
    sums: &mut [f64],
) {
    let rows = w.nrows();
    let (lo_s, rest) = sums[..4 * rows].split_at_mut(rows);
    let (lo_a, rest) = rest.split_at_mut(rows);
    let (hi_s, hi_a) = rest.split_at_mut(rows);
    for v in [&mut *lo_s, &mut *lo_a, &mut *hi_s, &mut *hi_a] {
        v.fill(0.0);
    }
    let mut terms = 0;
    if rows > 0 {
        // column by column: nalgebra stores columns contiguously
        let mut column = |i: usize| {
            let col = &w.as_slice()[i * rows..(i + 1) * rows];
            let (xl, xh) = (xl[i], xh[i]);
            for (((ls, la), (hs, ha)), &a) in lo_s
                .iter_mut()
                .zip(lo_a.iter_mut())
                .zip(hi_s.iter_mut().zip(hi_a.iter_mut()))
                .zip(col)
            {
                // term_lower and term_upper from the same two products:
                // min and max of a·xl and a·xh by the sign of a, 0 for
                // a = 0 (term_lower's −0 there adds the same to a sum that
                // starts at +0)
                let (pl, ph) = (a * xl, a * xh);
                let up = a > 0.0;
                let zero = a == 0.0;
                let th = if zero {
                    0.0
                } else if up {
                    ph
                } else {
                    pl
                };
                let tl = if zero {
                    0.0
                } else if up {
                    pl
                } else {
                    ph
                };
                *ls += tl;
                *la += tl.abs();
                *hs += th;
                *ha += th.abs();
            }
            terms += 1;
        };
        match cols {
            None => (0..w.ncols()).for_each(&mut column),
            Some(cols) => cols.iter().for_each(|&i| column(i)),
        }
    }
    for j in 0..rows {
        let bj = b[j];
        let n = terms + 1;
        lo[j] = Acc::from_parts(lo_s[j] + bj, lo_a[j] + bj.abs(), n).lower();
        hi[j] = Acc::from_parts(hi_s[j] + bj, hi_a[j] + bj.abs(), n).upper();
    }
}

/// Row `j` of [`affine_image_of`] alone: its lower and upper bound, the
/// same numbers bit for bit (the same terms added in the same column
/// order, with the same count).
pub(crate) fn affine_image_row(
    w: &DMatrix<f64>,
    b: &DVector<f64>,
    x: &IBox,
    cols: Option<&[usize]>,
    j: usize,
) -> (f64, f64) {
    let rows = w.nrows();
    let (mut ls, mut la, mut hs, mut ha) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let mut terms = 0;
    let mut column = |i: usize| {
        let a = w.as_slice()[i * rows + j];
        let (pl, ph) = (a * x.lo[i], a * x.hi[i]);
        let (th, tl) = if a == 0.0 {
            (0.0, 0.0)
        } else if a > 0.0 {
            (ph, pl)
        } else {
            (pl, ph)
        };
        ls += tl;
        la += tl.abs();
        hs += th;
        ha += th.abs();
        terms += 1;
    };
    match cols {
        None => (0..w.ncols()).for_each(&mut column),
        Some(cols) => cols.iter().for_each(|&i| column(i)),
    }
    let (bj, n) = (b[j], terms + 1);
    (
        Acc::from_parts(ls + bj, la + bj.abs(), n).lower(),
        Acc::from_parts(hs + bj, ha + bj.abs(), n).upper(),
    )
}

/// [`weight_scale_of`] and [`affine_image_of`] of `z = s·x + b` (`s = ±1`,
/// all columns), without the sums over zeros: the same numbers bit for bit.
/// There, row `j`'s sums start at 0 and take `s·x_j`'s term and zeros
/// (`±0`, which leave a sum unchanged once it holds `0 + t`), with one
/// count per column.
fn identity_image(s: f64, b: &DVector<f64>, x: &IBox) -> (Vec<f64>, IBox) {
    let n = x.dim();
    let (mut scale, mut lo, mut hi) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    identity_image_into(
        s,
        b.as_slice(),
        (&x.lo, &x.hi),
        &mut scale,
        (&mut lo, &mut hi),
    );
    (scale, IBox::new(lo, hi))
}

/// [`identity_image`] of the box `[xl, xh]` into `scale`, `lo`, `hi`.
pub(crate) fn identity_image_into(
    s: f64,
    b: &[f64],
    (xl, xh): (&[f64], &[f64]),
    scale: &mut [f64],
    (lo, hi): (&mut [f64], &mut [f64]),
) {
    let n = xl.len();
    for j in 0..n {
        let (xl, xh, bj) = (xl[j], xh[j], b[j]);
        let m = 0.0 + mul0(s.abs(), ravel_base::num::abs_max(xl, xh));
        scale[j] = Acc::from_parts(m, m, n).upper();
        let (tl, th) = (0.0 + term_lower(s, xl, xh), 0.0 + term_upper(s, xl, xh));
        lo[j] = Acc::from_parts(tl + bj, (0.0 + tl.abs()) + bj.abs(), n + 1).lower();
        hi[j] = Acc::from_parts(th + bj, (0.0 + th.abs()) + bj.abs(), n + 1).upper();
    }
}

/// What [`Relaxation::upper_optimised`] minimises for row `r`, given that
/// row's one-row bound over the network input: its value (the smaller the
/// better; any measure, every candidate is sound) and the network input at
/// which it is attained (where the slope gradient is taken).
pub type Objective<'o> = dyn Fn(usize, &LinearUpper) -> (f64, Vec<f64>) + 'o;

/// Other certified upper bounds of a linear bound's rows (see [`Relaxation::with_hook`]).
pub type BoundHook<'h> = dyn Fn(&LinearUpper) -> Vec<f64> + 'h;

/// How hidden-layer bounds are computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Interval arithmetic only.
    Ibp,
    /// CROWN bounds for every pre-activation (intersected with IBP).
    Crown,
    /// Fast-Lin: CROWN with the lower ReLU slope equal to the upper one
    /// (Weng et al. 2018; the tutorial's special case of CROWN).
    FastLin,
}

/// What every layer of [`Relaxation::with_hook`]'s pass reads.
struct Pass<'p, 'h> {
    /// The network's input box.
    input: &'p IBox,
    /// How hidden-layer bounds are computed.
    mode: Mode,
    /// Other certified upper bounds of a pre-activation's linear bound.
    hook: Option<&'p BoundHook<'h>>,
    /// Which affine layers have at most one nonzero per row.
    opr: Vec<bool>,
    /// Which affine layers are `±I` (the halves of a control clamp): the sign.
    ident: Vec<Option<f64>>,
}

/// For each layer: whether it is affine with at most one nonzero per row
/// (asked for several layers at each step of a pass), and the sign of one
/// that is `±I` (the halves of a control clamp).
fn row_shapes(layers: &[Layer]) -> (Vec<bool>, Vec<Option<f64>>) {
    let opr: Vec<bool> = layers
        .iter()
        .map(|l| matches!(l, Layer::Affine { w, .. } if one_per_row(w)))
        .collect();
    let ident = layers
        .iter()
        .zip(&opr)
        .map(|(l, &one)| match l {
            Layer::Affine { w, .. } if one => signed_identity(w.as_slice(), w.nrows(), w.ncols()),
            _ => None,
        })
        .collect();
    (opr, ident)
}

/// Whether every row of affine layer `i` reads one neuron of an
/// activation's output (a one-neuron activation, as the clamp of a single
/// control; or an elementwise clamp's diagonal halves), through affine
/// layers that keep one nonzero per row (`opr`, per layer).
#[inline]
pub(crate) fn after_one_neuron(layers: &[Layer], opr: &[bool], i: usize) -> bool {
    let mut j = i + 1;
    while j >= 1 && opr[j - 1] {
        j -= 1;
    }
    j >= 2
        && matches!(layers[j - 1], Layer::Act(_))
        && matches!(layers[j - 2], Layer::Affine { .. })
}

/// Whether CROWN's bounds of affine layer `i`'s outputs can beat interval
/// arithmetic's (so the pass back-substitutes them).
fn crown_useful(layers: &[Layer], i: usize, pass: &Pass) -> bool {
    // On the network's first layer (an affine map of the input box) CROWN's
    // bound is interval arithmetic's with the product's rounding slack added:
    // never tighter, so without a hook (which may bound it otherwise) the
    // back-substitution is skipped (same bounds, bit for bit). Likewise when
    // every row of this layer reads one neuron of an activation's output (a
    // one-neuron activation, as the clamp of a single control; or an
    // elementwise clamp's diagonal halves), through affine layers that keep
    // one nonzero per row: the activation's input bounds are CROWN's already,
    // and CROWN of `w·σ(z_k) + b` substitutes a relaxation line of σ and then
    // the very linear bound of `z_k` (scaled; same signs, same relaxations)
    // that gave z_k's bound, so it comes to the line at z_k's bound, which is
    // never below σ's interval image: up to rounding, no tighter than interval
    // arithmetic from z_k's bounds.
    // (With a hook, unrolled CROWN's, the same holds: the rows reach z_k's own
    // bound expression and the hook maps it as it mapped z_k's, whose bound is
    // at least z_k's stored one; the first layer is bounded there, the hook
    // reaching further back than the box.)
    !after_one_neuron(layers, &pass.opr, i) && (pass.hook.is_some() || i > 0)
}

/// A network relaxed over one input box: the bounds of every intermediate
/// value (interval arithmetic's, or CROWN's or Fast-Lin's: [`Mode`]) and
/// the relaxation of every activation.
#[derive(Clone, Debug)]
pub struct Relaxation<'a> {
    net: &'a Network,
    /// `boxes[i]` bounds the value before layer `i` (`boxes[0]` is the input box).
    boxes: Vec<IBox>,
    /// For each ReLU layer with neurons proved inactive (input `≤ 0`,
    /// output exactly 0), the others, in order; `None` for every neuron
    /// (and for the other layers). Back-substitution carries coefficients
    /// on these neurons only.
    keep: Vec<Option<Vec<usize>>>,
    /// The relaxation of each activation layer's kept neurons (empty for
    /// affine layers).
    relax: Vec<Vec<Relax>>,
    /// `|W|·|h|max` of each affine layer (empty for activations), for error terms.
    scales: Vec<Vec<f64>>,
    /// `|h|max` of the kept neurons' inputs of each activation layer (empty
    /// for affine layers), for error terms.
    abs: Vec<Vec<f64>>,
    /// Each affine layer as back-substitution reads it (`None` for
    /// activations, and in interval mode, where it is built when asked).
    packed: Vec<Option<Packed<'a>>>,
    /// For an affine layer whose outputs' bounds were back-substituted:
    /// those outputs `z_j` (ascending) and the bounds of `z_j` and `−z_j`
    /// over the input (CROWN's own relaxations; the `2k` rows of
    /// [`Relaxation::backward_select`]) when the next affine layer keeps its
    /// rows apart (one nonzero per row) or there is none; `None` otherwise
    /// (a later pass reaches them only through that layer). A later
    /// back-substitution with CROWN's relaxations whose every row has
    /// reached one of these outputs alone finishes from them (see
    /// [`Relaxation::scaled`]).
    stored: Vec<Option<(Vec<usize>, LinearUpper)>>,
}

impl<'a> Relaxation<'a> {
    /// Bound every layer of `net` over `input`.
    pub fn new(net: &'a Network, input: &IBox, mode: Mode) -> Relaxation<'a> {
        Relaxation::with_hook(net, input, mode, None)
    }

    /// [`Relaxation::new`], where in CROWN mode the linear bound of every
    /// pre-activation (a [`LinearUpper`] over the network input) is also
    /// handed to `hook`, which returns other certified upper bounds of its
    /// rows; the tighter of the two is kept. The unrolled closed-loop
    /// propagator uses this to bound hidden neurons through earlier steps.
    pub fn with_hook(
        net: &'a Network,
        input: &IBox,
        mode: Mode,
        hook: Option<&BoundHook>,
    ) -> Relaxation<'a> {
        let layers = net.layers.len();
        let mut a = Relaxation {
            net,
            boxes: Vec::with_capacity(layers + 1),
            keep: Vec::with_capacity(layers),
            relax: Vec::with_capacity(layers),
            scales: Vec::with_capacity(layers),
            abs: Vec::with_capacity(layers),
            packed: Vec::with_capacity(layers),
            stored: vec![None; layers],
        };
        a.boxes.push(input.clone());
        let (opr, ident) = row_shapes(&net.layers);
        let pass = Pass {
            input,
            mode,
            hook,
            opr,
            ident,
        };
        for (i, layer) in net.layers.iter().enumerate() {
            match layer {
                Layer::Affine { w, b } => a.push_affine(i, w, b, &pass),
                Layer::Act(act) => a.push_activation(i, *act, mode),
            }
        }
        a
    }

    /// Layer `i` of [`Relaxation::with_hook`]'s pass, the affine `w·h + b`:
    /// the interval image of its input box, tightened by CROWN where that
    /// can beat it ([`Relaxation::crown_tighten`]), its scale and (unless a
    /// ReLU follows, which packs it) its packing.
    fn push_affine(&mut self, i: usize, w: &'a DMatrix<f64>, b: &'a DVector<f64>, pass: &Pass) {
        let net = self.net;
        let ins = self.ins(i);
        let current = &self.boxes[i];
        let m = |j: usize| ravel_base::num::abs_max(current.lo[j], current.hi[j]);
        let (scale, mut next) = match (pass.ident[i], ins) {
            (Some(sign), None) => identity_image(sign, b, current),
            _ => (
                weight_scale_of(w, m, ins),
                affine_image_of(w, b, current, ins),
            ),
        };
        let feeds_activation = matches!(net.layers.get(i + 1), Some(Layer::Act(_)));
        if pass.mode != Mode::Ibp && feeds_activation && crown_useful(&net.layers, i, pass) {
            self.crown_tighten(i, w.nrows(), &mut next, pass);
        }
        self.boxes.push(next);
        self.scales.push(scale);
        self.keep.push(None);
        self.relax.push(Vec::new());
        self.abs.push(Vec::new());
        // an affine layer before a ReLU is packed once the
        // ReLU's inactive neurons are known
        let before_relu = matches!(net.layers.get(i + 1), Some(Layer::Act(Activation::Relu)));
        let packed = (pass.mode != Mode::Ibp && !before_relu)
            .then(|| Packed::new(w, b, &self.scales[i], None, self.ins(i)));
        self.packed.push(packed);
    }

    /// The CROWN bounds of affine layer `i`'s outputs (`outputs` of them,
    /// an activation after them), intersected into their interval image
    /// `next`, with the hook's where there is one; the bounds are stored
    /// where a later pass can finish from them.
    fn crown_tighten(&mut self, i: usize, outputs: usize, next: &mut IBox, pass: &Pass) {
        let net = self.net;
        // A ReLU that interval arithmetic already proves inactive (z ≤ 0)
        // outputs exactly 0 whatever its bounds: it is not worth a
        // back-substitution, and skipping it changes no bound (its relaxation
        // is 0, its image [0, 0], and its bounds enter no error term: they
        // multiply zero coefficients). Active ones are bounded: their bounds
        // pass on to the next layer's interval image. Tanh and sigmoid relax
        // by their bounds: every neuron is bounded.
        let relu = matches!(net.layers.get(i + 1), Some(Layer::Act(Activation::Relu)));
        // With a hook (unrolled CROWN, where each bound runs back through
        // every earlier step), a ReLU that interval arithmetic proves active
        // is not bounded either when the layer after it mixes its neurons: its
        // relaxation is the identity whatever its bounds, so every later CROWN
        // bound is the same; its interval box enters only the next layer's
        // interval image (intersected with that layer's CROWN bound) and error
        // terms. Not where one neuron's box is read on (a clamp, whose second
        // half is interval arithmetic from it), nor without a hook: there
        // interval images win often enough for a looser box to show (measured
        // on the partitioned specs; unrolled sets are unchanged up to
        // rounding).
        let mixed_next = pass.hook.is_some()
            && matches!(net.layers.get(i + 2), Some(Layer::Affine { .. }))
            && !pass.opr[i + 2];
        let rows: Vec<usize> = (0..outputs)
            .filter(|&j| !(relu && (inactive(next.hi[j]) || (mixed_next && next.lo[j] >= 0.0))))
            .collect();
        let k = rows.len();
        if k == 0 {
            return;
        }
        let bound = self.backward_select(&rows, i);
        let mut both = bound.concretize(pass.input);
        if let Some(h) = pass.hook {
            for (b, o) in both.iter_mut().zip(h(&bound)) {
                *b = b.min(o);
            }
        }
        for (r, &j) in rows.iter().enumerate() {
            next.hi[j] = next.hi[j].min(both[r]);
            next.lo[j] = next.lo[j].max(-both[k + r]);
        }
        // kept only where a later pass can arrive with one nonzero per row:
        // when the next affine layer keeps rows apart (a clamp's halves) or
        // there is none; after a mixing layer rows arrive dense, and a wide
        // network's bounds need not outlive their use
        let next_affine = net.layers[i + 1..]
            .iter()
            .position(|l| matches!(l, Layer::Affine { .. }))
            .map(|d| i + 1 + d);
        if next_affine.is_none_or(|j| pass.opr[j]) {
            self.stored[i] = Some((rows, bound));
        }
    }

    /// Layer `i` of [`Relaxation::with_hook`]'s pass, the activation
    /// `act`: in one pass over the neurons the image of each, and the
    /// relaxation and input size of each neuron kept (a ReLU's neurons
    /// proved inactive are left out); then, before a ReLU, the affine
    /// layer `i − 1` is packed to the kept neurons.
    fn push_activation(&mut self, i: usize, act: Activation, mode: Mode) {
        let current = &self.boxes[i];
        let n = current.dim();
        let relu = act == Activation::Relu;
        let fast_lin = mode == Mode::FastLin && relu;
        // (the kept ReLU neurons, listed once one is left out)
        let mut live: Option<Vec<usize>> = None;
        let mut rel = Vec::with_capacity(n);
        let mut abs = Vec::with_capacity(n);
        let (mut lo, mut hi) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for j in 0..n {
            let (l, h) = (current.lo[j], current.hi[j]);
            let (il, ih) = image(act, l, h);
            lo.push(il);
            hi.push(ih);
            if relu {
                if inactive(h) {
                    live.get_or_insert_with(|| (0..j).collect());
                    continue;
                }
                if let Some(live) = live.as_mut() {
                    live.push(j);
                }
            }
            rel.push(relax_in_mode(act, l, h, fast_lin));
            abs.push(ravel_base::num::abs_max(l, h));
        }
        let keep = live;
        self.boxes.push(IBox::new(lo, hi));
        self.scales.push(Vec::new());
        self.keep.push(keep);
        self.relax.push(rel);
        self.abs.push(abs);
        self.packed.push(None);
        if relu && mode != Mode::Ibp && i >= 1 {
            if let Layer::Affine { w, b } = &self.net.layers[i - 1] {
                self.packed[i - 1] = Some(Packed::new(
                    w,
                    b,
                    &self.scales[i - 1],
                    self.keep[i].as_deref(),
                    self.ins(i - 1),
                ));
            }
        }
    }

    /// The kept neurons of layer `i` (an activation's; `None` for all).
    fn kept(&self, i: usize) -> Option<&[usize]> {
        self.keep.get(i).and_then(|k| k.as_deref())
    }

    /// The inputs of affine layer `i` that can be nonzero (`None` for all).
    fn ins(&self, i: usize) -> Option<&[usize]> {
        i.checked_sub(1).and_then(|p| self.kept(p))
    }

    /// Whether every intermediate bound is finite. An analysis that is not
    /// (its input or weights too large for `f64`) must not be used: the
    /// propagators check this and report an overflow instead.
    pub fn is_finite(&self) -> bool {
        self.boxes.iter().all(IBox::is_finite)
            && self.scales.iter().flatten().all(|v| v.is_finite())
    }

    /// The bounds of the value before every layer (`boxes()[0]` is the input box).
    pub fn boxes(&self) -> &[IBox] {
        &self.boxes
    }

    /// Bounds of the network output (IBP, or CROWN intersected with IBP).
    pub fn output_box(&self, mode: Mode) -> IBox {
        let ibp = self
            .boxes
            .last()
            .cloned()
            .unwrap_or_else(|| self.boxes[0].clone());
        if mode == Mode::Ibp {
            return ibp;
        }
        let m = ibp.dim();
        self.crown_box(ibp, &self.upper(plus_minus_identity(m)))
    }

    /// The output box from the bounds `pm` of `[I; −I]`, intersected with IBP's `ibp`.
    fn crown_box(&self, ibp: IBox, pm: &LinearUpper) -> IBox {
        let m = ibp.dim();
        let both = pm.concretize(&self.boxes[0]);
        let lo = (0..m).map(|j| ibp.lo[j].max(-both[m + j])).collect();
        let hi = (0..m).map(|j| ibp.hi[j].min(both[j])).collect();
        IBox::new(lo, hi)
    }

    /// [`Relaxation::upper_optimised`] of `spec` and the CROWN
    /// [`Relaxation::output_box`] together. With CROWN's own slopes both come
    /// from one back-substitution of the stacked rows `[I; −I; spec]`, at
    /// one pass's per-layer cost instead of two. Every row is
    /// back-substituted on its own, so each bound is the one the two calls
    /// give: bit for bit while products are per-row dot products, up to
    /// rounding where the blocked product of wide layers takes over (its
    /// summation order depends on the number of rows; sound either way).
    ///
    /// A row of `spec` with at most one nonzero, `c` at output `i` (every
    /// row for a one-output network; the facet rows `M B` of a plant whose
    /// `B` has one nonzero per row), is not back-substituted: CROWN is
    /// positively homogeneous in its row (scaling a row by `|c| > 0` keeps
    /// every coefficient's sign, hence every relaxation it selects), so its
    /// bound is `|c|` times the bound of `±z_i`, which the `[I; −I]` rows
    /// give. The scaled coefficients are rounded, and their error
    /// (`≤ 2u·|c·λⱼ|·|yⱼ|`) is added to the offset; the result equals the
    /// direct pass's up to rounding.
    pub fn upper_and_output_box(
        &self,
        spec: Rows,
        steps: usize,
        objective: Option<&Objective>,
    ) -> (LinearUpper, IBox) {
        let ibp = self
            .boxes
            .last()
            .cloned()
            .unwrap_or_else(|| self.boxes[0].clone());
        let m = ibp.dim();
        if steps > 0 || spec.ncols() != m {
            let u = self.crown_box(ibp, &self.upper(plus_minus_identity(m)));
            return (self.upper_optimised(spec, steps, objective), u);
        }
        // rows with at most one (finite) nonzero: scaled from [I; −I]
        let single: Vec<Option<Option<(usize, f64)>>> = spec.iter_rows().map(one_nonzero).collect();
        // the other rows go below [I; −I] in one pass
        let own: Vec<usize> = (0..spec.nrows()).filter(|&r| single[r].is_none()).collect();
        let mut stacked = plus_minus_identity(m);
        if !own.is_empty() {
            let data = own.iter().flat_map(|&r| spec.row(r)).copied().collect();
            stacked = stacked.stacked(&Rows::from_row_major(own.len(), m, data));
        }
        let all = self.upper(stacked);
        let (pm_coef, own_coef) = all.coef.split_rows(2 * m);
        let mut pm_offset = all.offset;
        let own_offset = pm_offset.split_off(2 * m);
        let pm = LinearUpper {
            coef: pm_coef,
            offset: pm_offset,
        };
        let picks: Vec<Option<(usize, f64)>> = single.iter().map(|s| s.flatten()).collect();
        let all_layers = self.allowance_before(self.net.layers.len());
        let mut out = self.scaled(vec![Acc::ZERO; spec.nrows()], &pm, &picks, all_layers);
        for (k, &r) in own.iter().enumerate() {
            out.coef.row_mut(r).copy_from_slice(own_coef.row(k));
            out.offset[r] = own_offset[k];
        }
        (out, self.crown_box(ibp, &pm))
    }

    /// CROWN: `S f(y) ≤ Λ y + c` over the input box, for a `k × outputs` matrix `S`.
    pub fn upper(&self, spec: impl Into<Rows>) -> LinearUpper {
        self.backward(spec.into(), self.net.layers.len())
    }

    /// Back-substitute a bound on the value at position `end` down to the input.
    fn backward(&self, spec: Rows, end: usize) -> LinearUpper {
        self.backward_with(spec, end, &self.relax, None)
    }

    /// Bounds of `z_j` and of `−z_j` for the outputs `rows` of affine layer
    /// `i` (the `2k` rows: upper bounds, then negated lower bounds), down to
    /// the input. The first layer is a selection of `W`'s rows, exact: no
    /// product, no rounding error.
    fn backward_select(&self, rows: &[usize], i: usize) -> LinearUpper {
        let Layer::Affine { w, b } = &self.net.layers[i] else {
            unreachable!("bounds are selected from affine layers only");
        };
        let ins = self.ins(i);
        let k = rows.len();
        let width = ins.map_or(w.ncols(), <[usize]>::len);
        let mut coef = Rows::zeros(2 * k, width);
        let mut offset = Vec::with_capacity(2 * k);
        for (r, &j) in rows.iter().enumerate() {
            let row = coef.row_mut(r);
            match ins {
                None => row.iter_mut().enumerate().for_each(|(c, v)| *v = w[(j, c)]),
                Some(ins) => row.iter_mut().zip(ins).for_each(|(v, &c)| *v = w[(j, c)]),
            }
            offset.push(Acc::of(b[j]));
        }
        for r in 0..k {
            let (upper, lower) = coef.rows_pair_mut(r, k + r);
            lower.iter_mut().zip(upper).for_each(|(l, u)| *l = -*u);
            offset.push(Acc::of(-b[rows[r]]));
        }
        self.substitute(coef, offset, ins, i, &self.relax, None)
    }

    /// Rows `c_r·z_{j_r} + offset_r`, each on one output of an affine
    /// layer whose bounds `pm` are stored (`picks[r]`: the stored row of
    /// `z_{j_r}` and `c_r`; `None` for a row of zeros), bounded over the
    /// input: `c·z = |c|·(±z)` is at most `|c|` times the bound of `±z`,
    /// the scaled coefficients rounded and their error `≤ 2u·|c·λⱼ|·|yⱼ|`
    /// added; a zero row stays zero (the rest of its pass would add only
    /// zero terms). Equal to back-substituting the rows on through the
    /// network up to rounding: CROWN is positively homogeneous in its row
    /// (scaling by `|c|` keeps every coefficient's sign, hence every
    /// relaxation it selects), and one neuron's row is the row its bound
    /// was back-substituted from.
    /// The underflow allowance of rows scaled from stored bounds of the
    /// value at position `end`: every layer before it, unscaled (a stored
    /// bound's own allowance is scaled with it), and the scaling's own
    /// products over the input.
    fn allowance_before(&self, end: usize) -> f64 {
        let layers: f64 = (0..end.min(self.boxes.len()))
            .map(|l| underflow_allowance(&self.boxes[l]))
            .sum();
        num::sat_upper((layers + underflow_allowance(&self.boxes[0])) * (1.0 + 4.0 * U))
    }

    fn scaled(
        &self,
        offset: Vec<Acc>,
        pm: &LinearUpper,
        picks: &[Option<(usize, f64)>],
        allow: f64,
    ) -> LinearUpper {
        let abs_in = self.boxes[0].abs_max();
        let width = pm.coef.ncols();
        let k = pm.coef.nrows() / 2;
        let mut out = Rows::zeros(picks.len(), width);
        let offset = offset
            .into_iter()
            .zip(picks)
            .enumerate()
            .map(|(r, (mut acc, pick))| {
                if let Some((p, c)) = *pick {
                    let src = if c < 0.0 { k + p } else { p };
                    let a = c.abs();
                    let row = out.row_mut(r);
                    for (o, &l) in row.iter_mut().zip(pm.coef.row(src)) {
                        *o = mul0(a, l);
                    }
                    acc.add(mul0(a, pm.offset[src]));
                    acc.add(slack(2.0 * U, row, &abs_in));
                    acc.add(allow);
                }
                acc.upper()
            })
            .collect();
        LinearUpper { coef: out, offset }
    }

    /// [`Relaxation::backward`] with the given relaxations (any sound ones:
    /// the optimised slopes of [`Relaxation::upper_optimised`]); with `trace`,
    /// the first row's coefficients on each activation's output are
    /// recorded (`trace[i]` for activation layer `i`).
    fn backward_with(
        &self,
        spec: Rows,
        end: usize,
        relax: &[Vec<Relax>],
        trace: Option<&mut [Vec<f64>]>,
    ) -> LinearUpper {
        let offset = vec![Acc::ZERO; spec.nrows()];
        self.substitute(spec, offset, None, end, relax, trace)
    }

    /// Back-substitute `coef · v + offset` from the value `v` at position
    /// `end` through layers `end − 1, …, 0`: `coef`'s columns are the
    /// neurons `cols` of that value (`None` for all of them).
    fn substitute<'s>(
        &'s self,
        mut coef: Rows,
        mut offset: Vec<Acc>,
        mut cols: Option<&'s [usize]>,
        end: usize,
        relax: &[Vec<Relax>],
        mut trace: Option<&mut [Vec<f64>]>,
    ) -> LinearUpper {
        // two buffers in turn: an affine layer writes the other one, an
        // activation rewrites its rows in place; both sized once for the
        // widest product (a product's width is at most its layer's inputs:
        // sizing by the outputs too cost a wide network's interior bounds
        // tens of megabytes of fresh pages each)
        let widest = self.net.layers[..end]
            .iter()
            .map(|l| match l {
                Layer::Affine { w, .. } => w.ncols(),
                Layer::Act(_) => 0,
            })
            .max()
            .unwrap_or(0)
            .max(coef.ncols());
        let room = coef.nrows() * widest;
        coef.reserve_total(room);
        let mut spare = Rows::with_capacity(room);
        // with CROWN's own relaxations, rows that have each reached one
        // neuron whose bounds are stored finish from them
        let own_relax = trace.is_none() && std::ptr::eq(relax, self.relax.as_slice());
        // the underflow of the coefficient products of every layer passed
        // (added to every row at the end; see `underflow_allowance`)
        let mut allow = 0.0;
        for i in (0..end).rev() {
            match &self.net.layers[i] {
                Layer::Affine { w, b } => {
                    if own_relax {
                        if let Some((rows, pm)) = &self.stored[i] {
                            if let Some(picks) = single_rows(&coef, cols, rows) {
                                // the stored bound scaled by |c| scales its
                                // own allowance too: every earlier layer's
                                // allowance is added again, unscaled
                                let extra = num::sat_upper(
                                    (allow + self.allowance_before(i + 1)) * (1.0 + 4.0 * U),
                                );
                                return self.scaled(offset, pm, &picks, extra);
                            }
                        }
                    }
                    allow += underflow_allowance(&self.boxes[i]);
                    let ins = self.ins(i);
                    let built;
                    let packed = match &self.packed[i] {
                        Some(p) if cols == self.kept(i + 1) => p,
                        _ => {
                            built = Packed::new(w, b, &self.scales[i], cols, ins);
                            &built
                        }
                    };
                    let wz = packed.wz.as_deref().unwrap_or(&self.scales[i]);
                    affine_into(&coef, &mut offset, packed, wz, &mut spare);
                    std::mem::swap(&mut coef, &mut spare);
                    cols = ins;
                }
                Layer::Act(_) => {
                    let keep = self.kept(i);
                    if cols != keep {
                        coef = coef.columns_moved(cols, keep, self.boxes[i + 1].dim());
                        cols = keep;
                    }
                    if let Some(t) = trace.as_deref_mut() {
                        t[i].clear();
                        t[i].resize(self.boxes[i].dim(), 0.0);
                        for (c, &v) in coef.row(0).iter().enumerate() {
                            t[i][cols.map_or(c, |k| k[c])] = v;
                        }
                    }
                    relaxation_in_place(&mut coef, &mut offset, &relax[i], &self.abs[i]);
                    allow += underflow_allowance(&self.boxes[i]);
                }
            }
        }
        if cols.is_some() {
            // a network that starts with a ReLU: back to every input
            coef = coef.columns_moved(cols, None, self.boxes[0].dim());
        }
        let allow = num::sat_upper(allow * (1.0 + 4.0 * U));
        LinearUpper {
            coef,
            offset: offset
                .into_iter()
                .map(|mut acc| {
                    acc.add(allow);
                    acc.upper()
                })
                .collect(),
        }
    }

    /// [`Relaxation::upper`] with the lower slopes of unstable ReLUs optimised
    /// per row (α-CROWN-style, Xu et al. 2021): `steps` steps of projected
    /// gradient descent on the row's `objective` (by default its bound over
    /// the input box; a caller that composes the bound further passes the
    /// measure it cares about), each slope
    /// kept in `[0, 1]`. Any slope in `[0, 1]` gives a sound lower line
    /// (`a·z ≤ relu(z)`, intercept 0), and every iterate is evaluated with
    /// the same certified arithmetic as [`Relaxation::upper`]; each row keeps
    /// the iterate with the smallest objective, starting from CROWN's own
    /// slopes, so by that measure the result is never looser than
    /// [`Relaxation::upper`]'s. Intermediate bounds are not re-optimised.
    ///
    /// The gradient: CROWN's bound is the maximum of the objective over the
    /// relaxed network (every `h` between its two lines); at the maximiser
    /// (the input box's corner the final coefficients point to, pushed
    /// forward through the lines each coefficient's sign selected), the
    /// derivative in a lower slope `a` is `c·ẑ`, with `c < 0` the
    /// coefficient on the neuron's output and `ẑ` its pre-activation value.
    pub fn upper_optimised(
        &self,
        spec: impl Into<Rows>,
        steps: usize,
        objective: Option<&Objective>,
    ) -> LinearUpper {
        let spec = spec.into();
        let mut best = self.upper(spec.clone());
        let end = self.net.layers.len();
        let unstable = |r: &Relax| r.au > 0.0 && r.au < 1.0;
        if steps == 0 || !self.relax.iter().flatten().any(unstable) {
            return best;
        }
        let input = &self.boxes[0];
        let own = |_: usize, cand: &LinearUpper| -> (f64, Vec<f64>) {
            let corner = cand
                .coef
                .row(0)
                .iter()
                .zip(input.lo.iter().zip(&input.hi))
                .map(|(&c, (&l, &u))| if c >= 0.0 { u } else { l })
                .collect();
            (cand.concretize(input)[0], corner)
        };
        let objective = objective.unwrap_or(&own);
        let mut trace = vec![Vec::new(); end];
        for r in 0..spec.nrows() {
            let row = Rows::from_row_major(1, spec.ncols(), spec.row(r).to_vec());
            let mut relax = self.relax.clone();
            let mut cand = self.backward_with(row.clone(), end, &relax, Some(&mut trace));
            let mut at = objective(r, &cand).1;
            // measured against the row `upper` gave, so never worse than it
            let mut best_value = objective(
                r,
                &LinearUpper {
                    coef: Rows::from_row_major(1, best.coef.ncols(), best.coef.row(r).to_vec()),
                    offset: vec![best.offset[r]],
                },
            )
            .0;
            for k in 0..steps {
                let grad = self.slope_gradient(&at, &relax, &trace);
                let gmax = grad.iter().flatten().fold(0.0f64, |m, g| m.max(g.abs()));
                if !(gmax > 0.0 && gmax.is_finite()) {
                    break;
                }
                let rate = 0.5 * 0.8f64.powi(k as i32) / gmax;
                let mut moved = false;
                for (rel, g) in relax.iter_mut().zip(&grad) {
                    for (rl, gj) in rel.iter_mut().zip(g) {
                        if *gj != 0.0 {
                            let al = (rl.al - rate * gj).clamp(0.0, 1.0);
                            moved |= al != rl.al;
                            rl.al = al;
                        }
                    }
                }
                if !moved {
                    // every slope the gradient pushes is at its bound
                    break;
                }
                cand = self.backward_with(row.clone(), end, &relax, Some(&mut trace));
                let (v, point) = objective(r, &cand);
                at = point;
                if v < best_value {
                    best_value = v;
                    best.coef.row_mut(r).copy_from_slice(cand.coef.row(0));
                    best.offset[r] = cand.offset[0];
                }
            }
        }
        best
    }

    /// The derivative of a one-row bound at the network input `at` (its
    /// maximiser; the bound was computed with `relax`, and its coefficients
    /// on each activation's output are in `trace`) in
    /// the lower slope of every unstable ReLU (0 elsewhere); plain `f64`,
    /// it only steers the search.
    fn slope_gradient(
        &self,
        at: &[f64],
        relax: &[Vec<Relax>],
        trace: &[Vec<f64>],
    ) -> Vec<Vec<f64>> {
        let mut h = at.to_vec();
        let mut grad = vec![Vec::new(); relax.len()];
        for (i, layer) in self.net.layers.iter().enumerate() {
            match layer {
                Layer::Affine { w, b } => {
                    h = (w * DVector::from_column_slice(&h) + b).as_slice().to_vec()
                }
                Layer::Act(act) => {
                    let relu = *act == Activation::Relu;
                    let keep = self.kept(i);
                    // a neuron left out is an inactive ReLU: its output is 0
                    let mut next = vec![0.0; h.len()];
                    grad[i] = vec![0.0; relax[i].len()];
                    for (c, rl) in relax[i].iter().enumerate() {
                        let j = keep.map_or(c, |k| k[c]);
                        let (z, coef) = (h[j], trace[i][j]);
                        next[j] = if coef >= 0.0 {
                            rl.au * z + rl.bu
                        } else {
                            if relu && rl.au > 0.0 && rl.au < 1.0 {
                                grad[i][c] = coef * z;
                            }
                            rl.al * z + rl.bl
                        };
                    }
                    h = next;
                }
            }
        }
        grad
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ravel_base::nn::Activation;

    /// One row of the interval image alone is the whole image's row, bit
    /// for bit, over all columns and over a subset.
    #[test]
    fn one_row_of_the_interval_image_is_its_row_bit_for_bit() {
        let mut rng = ravel_base::rng::Rng::new(4);
        for (rows, cols) in [(1, 1), (3, 7), (9, 4), (16, 33)] {
            let w = DMatrix::from_fn(rows, cols, |_, _| {
                if rng.uniform(0.0, 1.0) < 0.2 {
                    0.0
                } else {
                    rng.uniform(-2.0, 2.0)
                }
            });
            let b = DVector::from_fn(rows, |_, _| rng.uniform(-1.0, 1.0));
            let lo: Vec<f64> = (0..cols).map(|_| rng.uniform(-1.0, 0.5)).collect();
            let hi: Vec<f64> = lo.iter().map(|l| l + rng.uniform(0.0, 1.0)).collect();
            let x = IBox::new(lo, hi);
            let some: Vec<usize> = (0..cols).filter(|i| i % 3 != 1).collect();
            for sel in [None, Some(some.as_slice())] {
                let whole = affine_image_of(&w, &b, &x, sel);
                for j in 0..rows {
                    let (l, h) = affine_image_row(&w, &b, &x, sel, j);
                    assert_eq!(l.to_bits(), whole.lo[j].to_bits());
                    assert_eq!(h.to_bits(), whole.hi[j].to_bits());
                }
            }
        }
    }

    fn net() -> Network {
        Network::new(
            2,
            vec![
                Layer::Affine {
                    w: DMatrix::from_row_slice(3, 2, &[1.0, -1.0, 0.5, 2.0, -1.5, 0.3]),
                    b: DVector::from_column_slice(&[0.1, -0.2, 0.3]),
                },
                Layer::Act(Activation::Relu),
                Layer::Affine {
                    w: DMatrix::from_row_slice(1, 3, &[1.0, -2.0, 0.7]),
                    b: DVector::from_column_slice(&[0.05]),
                },
            ],
        )
    }

    #[test]
    fn crown_is_no_looser_than_ibp_and_contains_samples() {
        let n = net();
        let input = IBox::new(vec![-1.0, -0.5], vec![0.5, 1.0]);
        let a = Relaxation::new(&n, &input, Mode::Crown);
        let crown = a.output_box(Mode::Crown);
        let ibp = Relaxation::new(&n, &input, Mode::Ibp).output_box(Mode::Ibp);
        assert!(ibp.contains_box(&crown));
        for i in 0..=20 {
            for j in 0..=20 {
                let x = [-1.0 + 1.5 * i as f64 / 20.0, -0.5 + 1.5 * j as f64 / 20.0];
                assert!(crown.contains_point(&n.forward(&x)));
            }
        }
    }
}
