//! The checker's own arithmetic: interval images, linear bounds through a
//! ReLU network (back-substitution with relaxations built from *claimed*
//! pre-activation bounds), and the bound of one closed-loop step on a facet.
//!
//! Nothing here calls the analysis: the only shared pieces are the
//! outward-rounded sums of [`ravel_base::num`] and the [`Network`] type the ONNX
//! loader fills. Every quantity is an upper (or lower) bound of the exact
//! real-arithmetic value; each rounded product and sum is covered by an
//! explicit error term (the model of [`ravel_base::num`]: a sum of `k` rounded
//! terms is off by at most `γ(k)·Σ|terms|`).

use nalgebra::{DMatrix, DVector};

use ravel_base::nn::{Activation, Layer, Network};
use ravel_base::num::{
    dot_box_lower, dot_box_upper, gamma, mul0, sum_lower, sum_upper, Acc, TINY, U,
};

/// A box `lo ≤ x ≤ hi`.
#[derive(Clone, Debug, PartialEq)]
pub struct Bx {
    /// Lower ends.
    pub lo: Vec<f64>,
    /// Upper ends.
    pub hi: Vec<f64>,
}

impl Bx {
    /// The box `[x, x]`.
    pub fn point(x: &[f64]) -> Bx {
        Bx {
            lo: x.to_vec(),
            hi: x.to_vec(),
        }
    }

    /// The box `center ± radius`, rounded outward (a ball's bounding box).
    pub fn around(center: &[f64], radius: &[f64]) -> Bx {
        Bx {
            lo: center
                .iter()
                .zip(radius)
                .map(|(c, r)| sum_lower([*c, -r]))
                .collect(),
            hi: center
                .iter()
                .zip(radius)
                .map(|(c, r)| sum_upper([*c, *r]))
                .collect(),
        }
    }

    /// `max |xᵢ|` per coordinate.
    pub fn abs_max(&self) -> Vec<f64> {
        self.lo
            .iter()
            .zip(&self.hi)
            .map(|(l, h)| l.abs().max(h.abs()))
            .collect()
    }

    /// Whether every end is finite and `lo ≤ hi`.
    pub fn is_proper(&self) -> bool {
        self.lo.len() == self.hi.len()
            && self
                .lo
                .iter()
                .zip(&self.hi)
                .all(|(l, h)| l.is_finite() && h.is_finite() && l <= h)
    }

    /// Whether `x` lies in the box (exact comparisons).
    pub fn contains(&self, x: &[f64]) -> bool {
        x.len() == self.lo.len()
            && x.iter()
                .zip(self.lo.iter().zip(&self.hi))
                .all(|(v, (l, h))| l <= v && v <= h)
    }
}

/// Why a bound could not be established.
#[derive(Clone, Debug, PartialEq)]
pub enum Trouble {
    /// A claimed pre-activation bound is tighter than the checker can prove.
    Neuron {
        /// Which activation layer (0-based, in network order).
        layer: usize,
        /// Which neuron.
        neuron: usize,
        /// The claimed interval.
        claimed: (f64, f64),
        /// The interval the checker proves.
        proven: (f64, f64),
    },
    /// The witness does not have the network's shape.
    Shape(String),
    /// A number came out non-finite.
    Overflow,
}

impl std::fmt::Display for Trouble {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Trouble::Neuron {
                layer,
                neuron,
                claimed,
                proven,
            } => write!(
                f,
                "pre-activation bound of neuron {neuron} of hidden layer {layer} is [{}, {}], the checker proves only [{}, {}]",
                claimed.0, claimed.1, proven.0, proven.1
            ),
            Trouble::Shape(s) => write!(f, "{s}"),
            Trouble::Overflow => write!(f, "a bound is not finite"),
        }
    }
}

/// Other proven upper bounds of a pre-activation bound's rows (see
/// [`NetBounds::with_hook`]).
type Hook<'h> = &'h dyn Fn(&Linear) -> Vec<f64>;

/// Other proven upper bounds of activation layer `k`'s rows `[I; −I]`
/// (`+∞` where none), from the boxes of the layers before it: the split
/// checker's Lagrangian bounds ([`super::splits`]).
pub type Extra<'h> = &'h dyn Fn(usize, &[Bx]) -> Vec<f64>;

/// Rows `sᵣ ≤ coefᵣ·z + offᵣ`, valid for every feasible `z`.
#[derive(Clone, Debug)]
struct Linear {
    coef: DMatrix<f64>,
    off: Vec<f64>,
}

/// `Σ aᵢ mᵢ` for non-negative terms, rounded up (with the error of the sum).
fn abs_dot(a: &[f64], m: &[f64]) -> f64 {
    sum_upper(a.iter().zip(m).map(|(a, m)| mul0(a.abs(), *m)))
}

/// `|M|·m` rounded up, row by row.
fn abs_times(m: &DMatrix<f64>, v: &[f64]) -> Vec<f64> {
    let mut acc = vec![Acc::ZERO; m.nrows()];
    for_columns(m, v, |a, x, y| a.add(mul0(x.abs(), y)), &mut acc);
    acc.into_iter().map(Acc::upper).collect()
}

/// `f(acc[r], m[r, i], v[i])` for every entry, each row's entries in
/// ascending `i` (as a loop along the row would give them), the loops
/// running down the columns of the column-major storage: the rows of a
/// wide matrix are far apart in memory, its columns contiguous. Columns
/// beyond `v` (or rows beyond `acc`) are left out, as a zip would.
fn for_columns<T>(m: &DMatrix<f64>, v: &[f64], mut f: impl FnMut(&mut T, f64, f64), acc: &mut [T]) {
    let rows = m.nrows();
    if rows == 0 {
        return;
    }
    for (col, &y) in m.as_slice().chunks_exact(rows).zip(v) {
        for (a, &x) in acc.iter_mut().zip(col) {
            f(a, x, y);
        }
    }
}

/// [`product_error`] of every row of `c`, with the same terms in the same
/// order per row (so the same bits), over the columns ([`for_columns`]).
fn product_errors(c: &DMatrix<f64>, mz: &[f64], zmax: &[f64], k: usize) -> Vec<f64> {
    let mut acc = vec![Acc::ZERO; c.nrows()];
    for_columns(c, mz, |a, x, m| a.add(mul0(x.abs(), m)), &mut acc);
    let under = sum_upper(zmax.iter().map(|z| TINY * z));
    acc.into_iter()
        .map(|a| sum_upper([(gamma(k + 1) * a.upper() * 1.0625 + TINY).next_up(), under]))
        .collect()
}

/// The error bound of a rounded row–matrix product `c·M` (`k` terms per
/// entry) applied to `|z| ≤ zmax`: `γ(k+1)·|c|·(|M|·zmax)`, with `mz = |M|·zmax`
/// precomputed; the factor 1.0625 covers the rounding of the bound itself.
fn product_error(c: impl Iterator<Item = f64>, mz: &[f64], zmax: &[f64], k: usize) -> f64 {
    let s = sum_upper(c.zip(mz).map(|(c, m)| mul0(c.abs(), *m)));
    // every coefficient of `c·M` may also be off by up to k·η/2 ≤ TINY
    // (products that underflow), times |zᵢ| ≤ zmaxᵢ
    let under = sum_upper(zmax.iter().map(|z| TINY * z));
    sum_upper([(gamma(k + 1) * s * 1.0625 + TINY).next_up(), under])
}

/// `A·B` with plain loops in a fixed order (each entry summed over `k`
/// ascending, no fused multiply-add): the same bits on every machine, so a
/// certificate written on one checks on another. (A BLAS-style product
/// picks its kernel by CPU, and kernels round differently.)
///
/// Each entry receives its terms one by one, `k` ascending, the zero
/// entries of `B` skipped, starting from 0: that fixes its bits, whatever
/// the order in which the entries are computed. The loops run over the
/// column-major storage as slices, in tiles of [`TILE_ROWS`] × [`TILE_COLS`]
/// entries kept in registers while `k` runs (one column of `A` loaded per
/// `k` for four columns of the result), the edges one column at a time;
/// `tests::the_product_keeps_its_order_bit_for_bit` compares it with the
/// plain triple loop.
// Every index is in range by the shapes alone, whatever the input: `B`'s
// columns are `kb` long, `p < min(k, kb)` (shapes that do not fit are
// multiplied over their common part, as zipped loops would),
// `i + TILE_ROWS ≤ full_rows ≤ m`, `j + t < n`. The iterator form of this
// kernel ran 17 % slower.
#[allow(clippy::indexing_slicing)]
fn mul(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    let (m, n, kb) = (a.nrows(), b.ncols(), b.nrows());
    let k = a.ncols().min(kb);
    let mut out = vec![0.0; m * n];
    if m == 0 || k == 0 {
        return DMatrix::from_vec(m, n, out);
    }
    let (ad, bd) = (a.as_slice(), b.as_slice());
    let full_rows = m - m % TILE_ROWS;
    let mut j = 0;
    while j + TILE_COLS <= n {
        let bcols: [&[f64]; TILE_COLS] =
            std::array::from_fn(|t| &bd[(j + t) * kb..(j + t) * kb + k]);
        for i in (0..full_rows).step_by(TILE_ROWS) {
            let mut acc = [[0.0f64; TILE_ROWS]; TILE_COLS];
            for (p, col) in ad.chunks_exact(m).take(k).enumerate() {
                let mut c = [0.0f64; TILE_ROWS];
                c.copy_from_slice(&col[i..i + TILE_ROWS]);
                for (acc_t, bcol) in acc.iter_mut().zip(&bcols) {
                    let bpj = bcol[p];
                    if bpj != 0.0 {
                        for (d, x) in acc_t.iter_mut().zip(&c) {
                            *d += x * bpj;
                        }
                    }
                }
            }
            for (t, acc_t) in acc.iter().enumerate() {
                let at = (j + t) * m + i;
                out[at..at + TILE_ROWS].copy_from_slice(acc_t);
            }
        }
        for (t, bcol) in bcols.iter().enumerate() {
            column_times(
                ad,
                m,
                full_rows,
                bcol,
                &mut out[(j + t) * m..(j + t + 1) * m],
            );
        }
        j += TILE_COLS;
    }
    // the columns after the last whole tile
    let rest = out
        .chunks_exact_mut(m)
        .skip(j)
        .zip(bd.chunks_exact(kb).skip(j));
    for (dst, bcol) in rest {
        column_times(ad, m, 0, bcol, dst);
    }
    DMatrix::from_vec(m, n, out)
}

/// Rows of a tile of [`mul`].
const TILE_ROWS: usize = 8;
/// Columns of a tile of [`mul`].
const TILE_COLS: usize = 4;

/// Rows `from..m` of `A·b` for one column `b` into `dst`, a column of the
/// result (its rows `from..` only): `A`'s columns one by one, `k`
/// ascending, zeros of `b` skipped.
fn column_times(ad: &[f64], m: usize, from: usize, bcol: &[f64], dst: &mut [f64]) {
    let Some(dst) = dst.get_mut(from..) else {
        return;
    };
    for (col, &bpj) in ad.chunks_exact(m).zip(bcol) {
        if bpj == 0.0 {
            continue;
        }
        for (d, c) in dst.iter_mut().zip(col.iter().skip(from)) {
            *d += c * bpj;
        }
    }
}

/// Intersect `b` with the bounds `up` of the rows `[I; −I]` over it (`k`
/// upper bounds, then `k` negated lower bounds, `k` the box's dimension).
fn tighten(b: &mut Bx, up: &[f64]) {
    let k = b.hi.len();
    for (hi, u) in b.hi.iter_mut().zip(up) {
        *hi = hi.min(*u);
    }
    for (lo, u) in b.lo.iter_mut().zip(up.iter().skip(k)) {
        *lo = lo.max(-u);
    }
}

/// The `2k × k` matrix `[I; −I]`.
fn plus_minus(k: usize) -> DMatrix<f64> {
    DMatrix::from_fn(2 * k, k, |r, c| {
        if r == c {
            1.0
        } else if r == k + c {
            -1.0
        } else {
            0.0
        }
    })
}

impl Linear {
    /// Substitute `z = W z' + b`, where `|z'| ≤ zmax`. Each new coefficient
    /// is a rounded `k`-term dot product, off from the exact one by at most
    /// `γ(k)·Σⱼ|cⱼ||Wⱼᵢ|`; times `|z'ᵢ|max` and summed over `i`, that is
    /// `γ(k)·|c|·(|W|·zmax)`, which goes into the offset.
    fn through_affine(&self, w: &DMatrix<f64>, b: &DVector<f64>, zmax: &[f64]) -> Linear {
        let wz = abs_times(w, zmax);
        let coef = mul(&self.coef, w);
        let errs = product_errors(&self.coef, &wz, zmax, w.nrows());
        // per row: `Σ cᵢ·bᵢ`, the offset and the error, in that order
        let mut acc = vec![Acc::ZERO; self.coef.nrows()];
        for_columns(
            &self.coef,
            b.as_slice(),
            |a, c, b| a.add(mul0(c, b)),
            &mut acc,
        );
        let off = acc
            .into_iter()
            .zip(&self.off)
            .zip(errs)
            .map(|((mut a, &off), err)| {
                a.add(off);
                a.add(err);
                a.upper()
            })
            .collect();
        Linear { coef, off }
    }

    /// Replace `h = σ(z)` by the relaxation lines (upper line for a
    /// non-negative coefficient, lower line otherwise); `|z| ≤ zmax`.
    ///
    /// Per row, the offset is the upper bound of the terms `off`, then for
    /// each neuron `j` ascending with `cⱼ ≠ 0`: `TINY·zmaxⱼ` and `cⱼ·b`, then
    /// the rounding error of the new coefficients; the loops run down the
    /// columns ([`for_columns`]' order), each row's terms still in that order.
    fn through_relax(&self, lines: &[Lines], zmax: &[f64]) -> Linear {
        let (rows, cols) = self.coef.shape();
        debug_assert_eq!(rows, self.off.len());
        let rows = rows.min(self.off.len());
        let mut coef = vec![0.0; rows * cols];
        let mut acc: Vec<(Acc, f64)> = self
            .off
            .iter()
            .take(rows)
            .map(|&o| {
                let mut a = Acc::ZERO;
                a.add(o);
                (a, 0.0)
            })
            .collect();
        if rows > 0 {
            let old = self.coef.as_slice().chunks_exact(self.coef.nrows());
            let per_neuron = old.zip(coef.chunks_exact_mut(rows)).zip(lines).zip(zmax);
            for (((col, new_col), l), &zm) in per_neuron {
                for ((&cj, new), (a, err)) in col.iter().zip(new_col).zip(acc.iter_mut()) {
                    if cj == 0.0 {
                        continue;
                    }
                    let (s, b) = if cj >= 0.0 {
                        (l.au, l.bu)
                    } else {
                        (l.al, l.bl)
                    };
                    let v = cj * s;
                    *new = v;
                    *err += v.abs() * zm;
                    a.add(TINY * zm);
                    a.add(mul0(cj, b));
                }
            }
        }
        let off = acc
            .into_iter()
            .map(|(mut a, err)| {
                a.add((2.0 * U * err * 1.0625 + TINY).next_up());
                a.upper()
            })
            .collect();
        Linear {
            coef: DMatrix::from_vec(rows, cols, coef),
            off,
        }
    }

    /// Upper bounds of the rows over the box.
    fn over(&self, b: &Bx) -> Vec<f64> {
        self.coef
            .row_iter()
            .zip(&self.off)
            .map(|(row, &off)| {
                let terms = row
                    .iter()
                    .zip(b.lo.iter().zip(&b.hi))
                    .map(
                        |(&a, (&l, &h))| {
                            if a >= 0.0 {
                                mul0(a, h)
                            } else {
                                mul0(a, l)
                            }
                        },
                    );
                sum_upper(terms.chain([off]))
            })
            .collect()
    }
}

/// What `NetBounds::linear_optimised` in the analysis minimises for row `r`: the
/// candidate row's value (any measure) and the network input attaining it.
type Measure<'m> = dyn Fn(usize, &Linear) -> (f64, Vec<f64>) + 'm;

/// The relaxation of one ReLU on `[l, u]`: `al·z + bl ≤ relu(z) ≤ au·z + bu`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Lines {
    al: f64,
    bl: f64,
    au: f64,
    bu: f64,
}

/// The checker's ReLU relaxation. Lower: `0` or `z` (each below `relu`
/// everywhere), `z` when the positive side is the larger. Upper: a line of
/// slope `a ≈ u/(u−l)` whose intercept is the certified maximum of
/// `relu(z) − a z` over `[l, u]` (a convex function: the maximum is at an
/// end), so the line is valid whatever rounding `a` carries.
fn relu_lines(l: f64, u: f64) -> Lines {
    if u <= 0.0 {
        return Lines {
            al: 0.0,
            bl: 0.0,
            au: 0.0,
            bu: 0.0,
        };
    }
    if l >= 0.0 {
        return Lines {
            al: 1.0,
            bl: 0.0,
            au: 1.0,
            bu: 0.0,
        };
    }
    let a = (u / (u - l)).clamp(0.0, 1.0);
    let at_l = sum_upper([-(a * l)]);
    let at_u = sum_upper([u, -(a * u)]);
    Lines {
        al: if u >= -l { 1.0 } else { 0.0 },
        bl: 0.0,
        au: a,
        bu: at_l.max(at_u),
    }
}

/// `v` pushed up by `k` relative roundings (and an underflow).
fn up(v: f64, k: f64) -> f64 {
    (v + v.abs() * k * U * 1.0625 + TINY).next_up()
}

/// `v` pushed down by `k` relative roundings (and an underflow).
fn down(v: f64, k: f64) -> f64 {
    -up(-v, k)
}

/// Bounds of `σ(z)` (the loader's evaluation error bound, as the analysis uses).
fn sigma_bounds(act: Activation, z: f64) -> (f64, f64) {
    let v = act.eval(z);
    let e = act.eval_error(v);
    ((v - e).next_down(), (v + e).next_up())
}

/// Bounds of `σ'(z)` from the bounds of `σ(z)`.
fn deriv_bounds(act: Activation, z: f64) -> (f64, f64) {
    let (lo, hi) = sigma_bounds(act, z);
    match act {
        Activation::Tanh => {
            // 1 − t² over t ∈ [lo, hi]
            let big = lo.abs().max(hi.abs()).min(1.0);
            let small = if lo <= 0.0 && hi >= 0.0 {
                0.0
            } else {
                lo.abs().min(hi.abs()).min(1.0)
            };
            (
                down(1.0 - up(big * big, 1.0), 1.0).max(0.0),
                up(1.0 - down(small * small, 1.0), 1.0),
            )
        }
        _ => {
            // s(1 − s) over s ∈ [lo, hi] ∩ [0, 1]: concave, peak ¼ at ½
            let (lo, hi) = (lo.max(0.0), hi.min(1.0));
            let f = |s: f64| s * (1.0 - s);
            let min = down(f(lo).min(f(hi)), 3.0).max(0.0);
            let max = if lo <= 0.5 && 0.5 <= hi {
                0.25
            } else {
                up(f(lo).max(f(hi)), 3.0)
            };
            (min, max)
        }
    }
}

/// Where `σ'(z) = a` on the side of `z ≥ 0` (`positive`) or `z ≤ 0`:
/// only an approximation (any point gives a valid bound below).
fn stationary(act: Activation, a: f64, positive: bool) -> f64 {
    let z = match act {
        Activation::Tanh => (1.0 - a).max(0.0).sqrt().atanh(),
        _ => {
            let s = 0.5 * (1.0 + (1.0 - 4.0 * a).max(0.0).sqrt());
            (s / (1.0 - s)).ln()
        }
    };
    let z = if z.is_finite() { z } else { 0.0 };
    if positive {
        z
    } else {
        -z
    }
}

/// Certified bounds of `g(z) = σ(z) − a z` over `[p, q]` on a piece where
/// `σ` is convex (`convex`) or concave. The extreme at an end is exact up to
/// rounding; the one inside is bounded by the tangent of `g` at an
/// approximate stationary point `ẑ` (a concave `g` lies below every tangent,
/// a convex one above), evaluated at both ends with `g'(ẑ)` as an interval.
fn gap_bounds(act: Activation, a: f64, p: f64, q: f64, convex: bool) -> (f64, f64) {
    let g_up = |z: f64| sum_upper([sigma_bounds(act, z).1, -(a * z)]);
    let g_lo = |z: f64| sum_lower([sigma_bounds(act, z).0, -(a * z)]);
    let ends_max = g_up(p).max(g_up(q));
    let ends_min = g_lo(p).min(g_lo(q));
    let zh = stationary(act, a, !convex).clamp(p, q);
    let (dl, dh) = deriv_bounds(act, zh);
    let (dl, dh) = (sum_lower([dl, -a]), sum_upper([dh, -a]));
    let tangent = |z: f64, upper: bool| {
        let (el, eh) = (sum_lower([z, -zh]), sum_upper([z, -zh]));
        let corners = [dl * el, dl * eh, dh * el, dh * eh];
        if upper {
            let m = corners.iter().fold(f64::NEG_INFINITY, |m, v| m.max(*v));
            sum_upper([g_up(zh), up(m, 1.0)])
        } else {
            let m = corners.iter().fold(f64::INFINITY, |m, v| m.min(*v));
            sum_lower([g_lo(zh), down(m, 1.0)])
        }
    };
    if convex {
        (tangent(p, false).min(tangent(q, false)), ends_max)
    } else {
        (ends_min, tangent(p, true).max(tangent(q, true)))
    }
}

/// The checker's relaxation of tanh or sigmoid on `[l, u]`: on a concave
/// interval (`l ≥ 0`) the upper line has the slope of the tangent at the
/// midpoint and the lower one the chord's; on a convex one (`u ≤ 0`) the
/// other way round; across 0 both have the chord's slope. Whatever the
/// slopes, the intercepts are the certified supremum and infimum of
/// `σ(z) − a z` over the interval (σ is convex for `z ≤ 0` and concave for
/// `z ≥ 0`, so the interval is split at 0), so the lines are sound for any
/// slope; the choice only makes them tight (CROWN's choice).
fn smooth_lines(act: Activation, l: f64, u: f64) -> Lines {
    let (fl, fu) = (act.eval(l), act.eval(u));
    let peak = if act == Activation::Tanh { 1.0 } else { 0.25 };
    let slope = |a: f64| {
        if a.is_finite() {
            a.clamp(0.0, peak)
        } else {
            0.0
        }
    };
    let chord = slope(if u > l { (fu - fl) / (u - l) } else { 0.0 });
    let tangent = {
        let (d_lo, d_hi) = deriv_bounds(act, 0.5 * l + 0.5 * u);
        slope(0.5 * d_lo + 0.5 * d_hi)
    };
    let (au, al) = if l >= 0.0 {
        (tangent, chord)
    } else if u <= 0.0 {
        (chord, tangent)
    } else {
        (chord, chord)
    };
    // the certified infimum and supremum of σ(z) − a z over [l, u]
    let gap = |a: f64| {
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        if l < 0.0 {
            let (a_lo, a_hi) = gap_bounds(act, a, l, u.min(0.0), true);
            lo = lo.min(a_lo);
            hi = hi.max(a_hi);
        }
        if u >= 0.0 {
            let (a_lo, a_hi) = gap_bounds(act, a, l.max(0.0), u, false);
            lo = lo.min(a_lo);
            hi = hi.max(a_hi);
        }
        (lo, hi)
    };
    Lines {
        al,
        bl: gap(al).0,
        au,
        bu: gap(au).1,
    }
}

/// `b` widened by `2⁻³⁶·(1 + |v|)` at each end `v`: far below any bound's
/// meaning, far above the last-bit differences between two machines' libm
/// (which the tanh and sigmoid relaxations go through). The certificate
/// writer claims widened bounds, so a checker elsewhere proves them too.
pub fn widen(b: &Bx) -> Bx {
    const HAIR: f64 = 1.0 / 68_719_476_736.0; // 2⁻³⁶
    Bx {
        lo: b
            .lo
            .iter()
            .map(|v| (v - HAIR * (1.0 + v.abs())).next_down())
            .collect(),
        hi: b
            .hi
            .iter()
            .map(|v| (v + HAIR * (1.0 + v.abs())).next_up())
            .collect(),
    }
}

/// Certified interval image of a box under `z = W x + b`.
pub fn affine_box(w: &DMatrix<f64>, b: &[f64], x: &Bx) -> Bx {
    let mut lo = Vec::with_capacity(w.nrows());
    let mut hi = Vec::with_capacity(w.nrows());
    for (j, bj) in b.iter().enumerate().take(w.nrows()) {
        let row: Vec<f64> = w.row(j).iter().copied().collect();
        lo.push(sum_lower([dot_box_lower(&row, &x.lo, &x.hi), *bj]));
        hi.push(sum_upper([dot_box_upper(&row, &x.lo, &x.hi), *bj]));
    }
    Bx { lo, hi }
}

/// Interval image of a monotone activation, rounded outward (tanh and
/// sigmoid through the loader's evaluation error bound).
fn act_box(act: Activation, x: &Bx) -> Bx {
    let f = |z: f64, up: bool| -> f64 {
        match act {
            Activation::Relu => z.max(0.0),
            Activation::Tanh | Activation::Sigmoid => {
                let v = act.eval(z);
                let e = act.eval_error(v);
                if up {
                    (v + e).next_up()
                } else {
                    (v - e).next_down()
                }
            }
        }
    };
    Bx {
        lo: x.lo.iter().map(|&z| f(z, false)).collect(),
        hi: x.hi.iter().map(|&z| f(z, true)).collect(),
    }
}

/// Interval evaluation of the network (IBP), for replaying a trajectory.
pub fn network_box(net: &Network, y: &Bx) -> Bx {
    let mut x = y.clone();
    for layer in &net.layers {
        x = match layer {
            Layer::Affine { w, b } => affine_box(w, b.as_slice(), &x),
            Layer::Act(a) => act_box(*a, &x),
        };
    }
    x
}

/// Pre-activation bounds of every activation layer, in network order.
pub type Witness = Vec<Bx>;

/// The network over one input box, as the checker bounds it.
pub struct NetBounds<'a> {
    net: &'a Network,
    /// `boxes[i]`: the value before layer `i` (`boxes[0]` is the input box).
    boxes: Vec<Bx>,
    /// Relaxations of activation layers (empty for affine layers).
    lines: Vec<Vec<Lines>>,
    /// The pre-activation bounds used (the witness).
    pub witness: Witness,
}

impl<'a> NetBounds<'a> {
    /// Bound `net` over `y`. With `claimed`, each activation layer's
    /// pre-activation box must contain what the checker proves from the
    /// previous claims (IBP intersected with back-substitution), and the
    /// claimed box is used from then on; without, the proven box is used.
    pub fn new(net: &'a Network, y: &Bx, claimed: Option<&[Bx]>) -> Result<NetBounds<'a>, Trouble> {
        NetBounds::with_hook(net, y, claimed, None, None, false)
    }

    /// [`NetBounds::new`] where every activation layer's bounds are also
    /// intersected with `extra`'s (when `widened`, and no claims are
    /// given, each proven box is widened as the writer claims it).
    pub fn with_extra(
        net: &'a Network,
        y: &Bx,
        claimed: Option<&[Bx]>,
        extra: Extra,
        widened: bool,
    ) -> Result<NetBounds<'a>, Trouble> {
        NetBounds::with_hook(net, y, claimed, None, Some(extra), widened)
    }

    /// [`NetBounds::new`], where every pre-activation bound (a linear bound
    /// over the input `y`) is also handed to `hook`, which returns other
    /// proven upper bounds of its rows (the unrolled chain bounds them
    /// through earlier steps); the smaller is kept.
    fn with_hook(
        net: &'a Network,
        y: &Bx,
        claimed: Option<&[Bx]>,
        hook: Option<Hook>,
        extra: Option<Extra>,
        widened: bool,
    ) -> Result<NetBounds<'a>, Trouble> {
        let mut s = NetBounds {
            net,
            boxes: vec![y.clone()],
            lines: Vec::with_capacity(net.layers.len()),
            witness: Vec::new(),
        };
        if !y.is_proper() {
            return Err(Trouble::Overflow);
        }
        let acts = net
            .layers
            .windows(2)
            .filter(|w| matches!(w, [Layer::Affine { .. }, Layer::Act(_)]))
            .count();
        if let Some(c) = claimed {
            if c.len() != acts {
                return Err(Trouble::Shape(format!(
                    "{} pre-activation boxes for {} activation layers",
                    c.len(),
                    acts
                )));
            }
        }
        // the value before layer `i` (`s.boxes[i]`)
        let mut cur = y.clone();
        for (i, layer) in net.layers.iter().enumerate() {
            let next = match layer {
                Layer::Affine { w, b } => {
                    // an affine layer has no relaxation lines; its entry
                    // comes first, so `backward` sees every layer to here
                    s.lines.push(Vec::new());
                    let mut next = affine_box(w, b.as_slice(), &cur);
                    if matches!(net.layers.get(i + 1), Some(Layer::Act(_))) {
                        let k = w.nrows();
                        let spec = Linear {
                            coef: plus_minus(k),
                            off: vec![0.0; 2 * k],
                        };
                        let back = s.backward(spec, i + 1);
                        let mut up = back.over(y);
                        if let Some(h) = hook {
                            for (u, o) in up.iter_mut().zip(h(&back)) {
                                if !o.is_nan() {
                                    *u = u.min(o);
                                }
                            }
                        }
                        if let Some(e) = extra {
                            let more = e(s.witness.len(), &s.witness);
                            for (u, o) in up.iter_mut().zip(more) {
                                if !o.is_nan() {
                                    *u = u.min(o);
                                }
                            }
                        }
                        tighten(&mut next, &up);
                        if !next.is_proper() {
                            return Err(Trouble::Overflow);
                        }
                        let layer_no = s.witness.len();
                        if let Some(c) = claimed.and_then(|c| c.get(layer_no)) {
                            if c.lo.len() != k || c.hi.len() != k {
                                return Err(Trouble::Shape(format!(
                                    "activation layer {layer_no}: {} bounds for {k} neurons",
                                    c.lo.len()
                                )));
                            }
                            let claims = c.lo.iter().zip(&c.hi);
                            let proven = next.lo.iter().zip(&next.hi);
                            for (j, ((&c_lo, &c_hi), (&p_lo, &p_hi))) in
                                claims.zip(proven).enumerate()
                            {
                                // NaN claims fail this test too
                                let ok = c_lo <= p_lo && c_hi >= p_hi;
                                if !ok || !c_lo.is_finite() || !c_hi.is_finite() {
                                    return Err(Trouble::Neuron {
                                        layer: layer_no,
                                        neuron: j,
                                        claimed: (c_lo, c_hi),
                                        proven: (p_lo, p_hi),
                                    });
                                }
                            }
                            next = c.clone();
                        } else if widened {
                            next = widen(&next);
                        }
                        s.witness.push(next.clone());
                    }
                    next
                }
                Layer::Act(Activation::Relu) => {
                    let lines = cur
                        .lo
                        .iter()
                        .zip(&cur.hi)
                        .map(|(&l, &u)| relu_lines(l, u))
                        .collect();
                    s.lines.push(lines);
                    act_box(Activation::Relu, &cur)
                }
                Layer::Act(a) => {
                    let lines = cur
                        .lo
                        .iter()
                        .zip(&cur.hi)
                        .map(|(&l, &u)| smooth_lines(*a, l, u))
                        .collect();
                    s.lines.push(lines);
                    act_box(*a, &cur)
                }
            };
            if !next.is_proper() {
                return Err(Trouble::Overflow);
            }
            s.boxes.push(next.clone());
            cur = next;
        }
        Ok(s)
    }

    /// Back-substitute a bound on the value before layer `end` to the input.
    fn backward(&self, mut bound: Linear, end: usize) -> Linear {
        // (`boxes` and `lines` have an entry for every layer before `end`)
        let layers = self.boxes.iter().zip(&self.net.layers).zip(&self.lines);
        for ((before, layer), lines) in layers.take(end).rev() {
            let zmax = before.abs_max();
            bound = match layer {
                Layer::Affine { w, b } => bound.through_affine(w, b, &zmax),
                Layer::Act(_) => bound.through_relax(lines, &zmax),
            };
        }
        bound
    }

    /// The output box: IBP intersected with back-substitution of `±I`.
    pub fn output(&self) -> Bx {
        // `boxes` starts with the input box: never empty
        let (Some(input), Some(last)) = (self.boxes.first(), self.boxes.last()) else {
            let m = self.net.outputs();
            return Bx {
                lo: vec![f64::NEG_INFINITY; m],
                hi: vec![f64::INFINITY; m],
            };
        };
        let mut out = last.clone();
        let m = out.lo.len();
        let spec = Linear {
            coef: plus_minus(m),
            off: vec![0.0; 2 * m],
        };
        let up = self.backward(spec, self.net.layers.len()).over(input);
        tighten(&mut out, &up);
        out
    }

    /// Linear bounds of every output over the input box, `L y + l ≤ f(y) ≤
    /// U y + ū` for every `y` in it: `(U, ū, L, l)`, by back-substitution
    /// (with `slopes` steps of the checker's own slope search).
    pub fn output_lines(&self, slopes: usize) -> (DMatrix<f64>, Vec<f64>, DMatrix<f64>, Vec<f64>) {
        let m = self.net.outputs();
        let spec = plus_minus(m);
        let lin = match self.boxes.first() {
            Some(input) if slopes > 0 => {
                let input = input.clone();
                let measure = move |_: usize, cand: &Linear| -> (f64, Vec<f64>) {
                    let corner = cand
                        .coef
                        .row(0)
                        .iter()
                        .zip(input.lo.iter().zip(&input.hi))
                        .map(|(c, (&lo, &hi))| if *c >= 0.0 { hi } else { lo })
                        .collect();
                    let value = cand.over(&input).first().copied().unwrap_or(f64::NAN);
                    (value, corner)
                };
                self.linear_optimised(spec, slopes, &measure)
            }
            _ => self.linear(spec),
        };
        let upper = lin.coef.rows(0, m).into_owned();
        let lower = -lin.coef.rows(m, m).into_owned();
        let up_off = lin.off.iter().take(m).copied().collect();
        let low_off = lin.off.iter().skip(m).map(|v| -v).collect();
        (upper, up_off, lower, low_off)
    }

    /// Upper bounds of `s·f(y)` over the input box for every row `s` of
    /// `spec`: back-substitution (with `slopes` steps of the checker's own
    /// slope search, measured over the input box), intersected with the
    /// output box's support.
    pub fn rows_upper(&self, spec: &DMatrix<f64>, slopes: usize) -> Vec<f64> {
        self.rows_upper_in(spec, slopes, &Start::Box)
    }

    /// [`NetBounds::rows_upper`] with the back-substituted rows concretised
    /// over the input box intersected with what `start` knows of the inputs
    /// (an ℓp ball: its dual norm; a polytope: the dual vectors `start`
    /// gives, one per row in order), each the smaller of the box's and the
    /// other's support ([`Start::support`]). The slope search measures its
    /// candidates over the box (any slopes give a sound line).
    pub fn rows_upper_in(&self, spec: &DMatrix<f64>, slopes: usize, start: &Start) -> Vec<f64> {
        // `boxes` starts with the input box: never empty (no bound without)
        let (Some(input), Some(out)) = (self.boxes.first(), self.boxes.last()) else {
            return vec![f64::INFINITY; spec.nrows()];
        };
        let concretise = |lin: Linear| -> Vec<f64> {
            match start {
                Start::Box => lin.over(input),
                _ => lin
                    .coef
                    .row_iter()
                    .zip(&lin.off)
                    .map(|(row, &off)| {
                        let row: Vec<f64> = row.iter().copied().collect();
                        sum_upper([start.support(&row, input), off])
                    })
                    .collect(),
            }
        };
        let back = if slopes == 0 {
            concretise(self.linear(spec.clone()))
        } else {
            // (a measure only ranks sound candidates: any value is safe)
            let measure = |_: usize, cand: &Linear| -> (f64, Vec<f64>) {
                let corner = cand
                    .coef
                    .row(0)
                    .iter()
                    .zip(input.lo.iter().zip(&input.hi))
                    .map(|(c, (&lo, &hi))| if *c >= 0.0 { hi } else { lo })
                    .collect();
                let value = cand.over(input).first().copied().unwrap_or(f64::NAN);
                (value, corner)
            };
            concretise(self.linear_optimised(spec.clone(), slopes, &measure))
        };
        spec.row_iter()
            .zip(&back)
            .map(|(row, &back)| {
                let row: Vec<f64> = row.iter().copied().collect();
                let ibp = ravel_base::num::dot_box_upper(&row, &out.lo, &out.hi);
                if back.is_nan() {
                    ibp
                } else {
                    ibp.min(back)
                }
            })
            .collect()
    }

    /// [`NetBounds::backward`] of one row with the given relaxation
    /// lines, recording the row's coefficients on each activation's output.
    fn backward_traced(
        &self,
        mut bound: Linear,
        lines: &[Vec<Lines>],
        trace: &mut [Vec<f64>],
    ) -> Linear {
        // one box before, one set of lines and one trace per layer
        let layers = self.boxes.iter().zip(&self.net.layers).zip(lines);
        for (((before, layer), lines), trace) in layers.zip(trace.iter_mut()).rev() {
            let zmax = before.abs_max();
            bound = match layer {
                Layer::Affine { w, b } => bound.through_affine(w, b, &zmax),
                Layer::Act(_) => {
                    *trace = bound.coef.row(0).iter().copied().collect();
                    bound.through_relax(lines, &zmax)
                }
            };
        }
        bound
    }

    /// [`NetBounds::linear`] with the lower slopes of the unstable ReLUs
    /// searched per row: `steps` steps of projected gradient on
    /// `measure(row, candidate) = (value, input where it is attained)`,
    /// the best candidate kept (CROWN's own lines to begin with). The
    /// checker's own search: a lower line `a·z` with `a ∈ [0, 1]` lies
    /// below `relu` everywhere, so every candidate is a sound bound
    /// whatever the search does; only how tight it is depends on it.
    fn linear_optimised(&self, spec: DMatrix<f64>, steps: usize, measure: &Measure) -> Linear {
        let mut best = self.linear(spec.clone());
        for (r, best_off) in best.off.iter_mut().enumerate() {
            let row = Linear {
                coef: spec.rows(r, 1).into_owned(),
                off: vec![0.0],
            };
            let own = Linear {
                coef: best.coef.rows(r, 1).into_owned(),
                off: vec![*best_off],
            };
            if let Some(better) = self.search_slopes(r, row, &own, steps, measure) {
                // a row's bound has one offset
                if let Some(&off) = better.off.first() {
                    best.coef.set_row(r, &better.coef.row(0));
                    *best_off = off;
                }
            }
        }
        best
    }

    /// The slope search of [`NetBounds::linear_optimised`] for row `r` of
    /// the spec (`row`, as a one-row bound): the best candidate measured
    /// below `own` (CROWN's own lines' bound), if any.
    fn search_slopes(
        &self,
        r: usize,
        row: Linear,
        own: &Linear,
        steps: usize,
        measure: &Measure,
    ) -> Option<Linear> {
        let layers = self.net.layers.len();
        let mut lines = self.lines.clone();
        let mut trace = vec![Vec::new(); layers];
        let mut cand = self.backward_traced(row.clone(), &lines, &mut trace);
        let mut at = measure(r, &cand).1;
        let mut best_value = measure(r, own).0;
        let mut best = None;
        for k in 0..steps {
            let grad = self.slope_gradient(&at, &lines, &trace);
            let gmax = grad.iter().flatten().fold(0.0f64, |m, g| m.max(g.abs()));
            if !(gmax > 0.0 && gmax.is_finite()) {
                break;
            }
            let rate = 0.5 * 0.8f64.powi(k as i32) / gmax;
            let mut moved = false;
            for (g, lines) in grad.iter().zip(lines.iter_mut()) {
                for (gj, l) in g.iter().zip(lines.iter_mut()) {
                    if *gj != 0.0 {
                        let al = (l.al - rate * gj).clamp(0.0, 1.0);
                        moved |= al != l.al;
                        l.al = al;
                        l.bl = 0.0;
                    }
                }
            }
            if !moved {
                break;
            }
            cand = self.backward_traced(row.clone(), &lines, &mut trace);
            let (v, point) = measure(r, &cand);
            at = point;
            if v < best_value {
                best_value = v;
                best = Some(cand.clone());
            }
        }
        best
    }

    /// The gradient of a traced row's bound in the lower slopes of the
    /// unstable ReLUs, at the network input `at`: forward from `at` through
    /// the lines the row's signs chose (`trace`: its coefficients on each
    /// activation's output), per layer (empty for affine layers).
    fn slope_gradient(
        &self,
        at: &[f64],
        lines: &[Vec<Lines>],
        trace: &[Vec<f64>],
    ) -> Vec<Vec<f64>> {
        let mut h = at.to_vec();
        let mut grad: Vec<Vec<f64>> = vec![Vec::new(); self.net.layers.len()];
        let layers = self.net.layers.iter().zip(lines).zip(trace);
        for (((layer, lines), trace), grad) in layers.zip(grad.iter_mut()) {
            match layer {
                Layer::Affine { w, b } => {
                    h = w
                        .row_iter()
                        .zip(b.iter())
                        .map(|(w_row, bj)| {
                            w_row.iter().zip(&h).map(|(a, x)| a * x).sum::<f64>() + bj
                        })
                        .collect();
                }
                Layer::Act(act) => {
                    *grad = vec![0.0; h.len()];
                    let relu = matches!(act, Activation::Relu);
                    let per_neuron = h.iter_mut().zip(lines).zip(grad.iter_mut());
                    for (j, ((z, &l), g)) in per_neuron.enumerate() {
                        let c = trace.get(j).copied().unwrap_or(0.0);
                        if c >= 0.0 {
                            *z = l.au * *z + l.bu;
                        } else {
                            // an unstable ReLU's lower slope is free
                            if relu && l.au > 0.0 && l.au < 1.0 {
                                *g = c * *z;
                            }
                            *z = l.al * *z + l.bl;
                        }
                    }
                }
            }
        }
        grad
    }

    /// `S π(y) ≤ G y + h` over the input box, for specification rows `S`.
    fn linear(&self, spec: DMatrix<f64>) -> Linear {
        let rows = spec.nrows();
        self.backward(
            Linear {
                coef: spec,
                off: vec![0.0; rows],
            },
            self.net.layers.len(),
        )
    }
}

/// One plant as the checker reads it (rows of matrices).
#[derive(Clone, Debug, PartialEq)]
pub struct PlantRows {
    /// `A` (`n × n`).
    pub a: DMatrix<f64>,
    /// `B` (`n × m`).
    pub b: DMatrix<f64>,
    /// `c` (`n`).
    pub c: Vec<f64>,
    /// Entrywise error bounds of `A`, `B`, `c` (continuous-time plants).
    pub err: Option<(DMatrix<f64>, DMatrix<f64>, Vec<f64>)>,
}

/// Finds a dual vector for the support of a direction (the writer's LP).
pub type Solver<'a> = &'a dyn Fn(&[f64]) -> Option<Vec<f64>>;

/// Dual vectors for supports over a polytope, in the order the supports
/// are asked for: read from a certificate (the checker), or obtained from
/// `solve` and recorded (the writer, which may use an LP solver; the
/// checker never does). Any vector is sound: it only decides how tight
/// the support is.
pub struct Duals<'a> {
    given: &'a [Vec<f64>],
    solve: Option<Solver<'a>>,
    used: std::cell::RefCell<Vec<Vec<f64>>>,
}

impl<'a> Duals<'a> {
    /// Duals read from a certificate.
    pub fn given(given: &'a [Vec<f64>]) -> Duals<'a> {
        Duals {
            given,
            solve: None,
            used: std::cell::RefCell::new(Vec::new()),
        }
    }

    /// Duals found by `solve(c)` for each support of `c`.
    pub fn solved(solve: Solver<'a>) -> Duals<'a> {
        Duals {
            given: &[],
            solve: Some(solve),
            used: std::cell::RefCell::new(Vec::new()),
        }
    }

    /// The duals used so far, in order.
    pub fn used(&self) -> Vec<Vec<f64>> {
        self.used.borrow().clone()
    }

    fn next(&self, c: &[f64]) -> Vec<f64> {
        let k = self.used.borrow().len();
        let mu = match self.solve {
            Some(f) => f(c).unwrap_or_default(),
            None => self.given.get(k).cloned().unwrap_or_default(),
        };
        self.used.borrow_mut().push(mu.clone());
        mu
    }
}

impl std::fmt::Debug for Duals<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Duals({} used)", self.used.borrow().len())
    }
}

/// `max c·x` over `{x ∈ box | H x ≤ h}` bounded with a dual `μ ≥ 0` (entries
/// below zero or NaN count as 0): `μ·h + max_box (c − Hᵀμ)·x`, every
/// rounding covered; `+∞` when `μ` does not fit the rows.
fn dual_support(c: &[f64], rows: &[(Vec<f64>, f64)], mu: &[f64], x: &Bx) -> f64 {
    if mu.len() != rows.len() {
        return f64::INFINITY;
    }
    let mu: Vec<f64> = mu.iter().map(|m| if *m > 0.0 { *m } else { 0.0 }).collect();
    let mut r = c.to_vec();
    let mut mag: Vec<f64> = c.iter().map(|v| v.abs()).collect();
    for ((a, _), m) in rows.iter().zip(&mu) {
        if *m == 0.0 {
            continue;
        }
        // every row has one coefficient per coordinate of `c`
        for ((rj, mag_j), aj) in r.iter_mut().zip(mag.iter_mut()).zip(a) {
            let t = aj * m;
            *rj -= t;
            *mag_j += t.abs();
        }
    }
    let xmax = x.abs_max();
    let k = rows.len() + 2;
    let err = sum_upper(
        mag.iter()
            .zip(&xmax)
            .map(|(mag_j, xm)| mul0((gamma(k) * mag_j * 1.0625 + TINY).next_up(), *xm)),
    );
    let mh = sum_upper(rows.iter().zip(&mu).map(|((_, h), m)| mul0(*m, *h)));
    sum_upper([dot_box_upper(&r, &x.lo, &x.hi), err, mh])
}

/// What is known of the states a step starts from beyond their box: at
/// step 0 of an ℓp-ball initial set, the ball; for a polytope initial set or
/// a polytope reachable set, its inequalities (with dual witnesses for the
/// supports). Supports are the smaller of the box's and the other's.
#[derive(Clone, Copy, Debug)]
pub enum Start<'a> {
    /// `{x ∈ box | H x ≤ h}`, supports bounded with the duals.
    Polytope {
        /// The rows `(H_r, h_r)`.
        rows: &'a [(Vec<f64>, f64)],
        /// Where the dual vectors come from.
        duals: &'a Duals<'a>,
    },
    /// The box is all that is known.
    Box,
    /// `{c + diag(r) δ | ‖δ‖ₚ ≤ 1}`, `norm` one of `1`, `2`, `inf`.
    Ball {
        /// Centre.
        center: &'a [f64],
        /// Radius per coordinate.
        radius: &'a [f64],
        /// The norm's name.
        norm: &'a str,
    },
}

impl Start<'_> {
    /// An upper bound of `max c·x` over the box `x` intersected with what is known.
    pub fn support(&self, c: &[f64], x: &Bx) -> f64 {
        let boxed = dot_box_upper(c, &x.lo, &x.hi);
        match self {
            Start::Box => boxed,
            Start::Polytope { rows, duals } => {
                let mu = duals.next(c);
                let b = dual_support(c, rows, &mu, x);
                if b.is_nan() {
                    boxed
                } else {
                    boxed.min(b)
                }
            }
            Start::Ball {
                center,
                radius,
                norm,
            } => {
                // c·centre + ‖diag(r) c‖ in the dual norm
                let scaled: Vec<f64> = c
                    .iter()
                    .zip(*radius)
                    .map(|(c, r)| (c.abs() * r).next_up())
                    .collect();
                let dual = match *norm {
                    "inf" => sum_upper(scaled.iter().copied()),
                    "1" => scaled.iter().fold(0.0f64, |m, v| m.max(*v)),
                    _ => sum_upper(scaled.iter().map(|v| (v * v).next_up()))
                        .sqrt()
                        .next_up(),
                };
                let ball = sum_upper(
                    c.iter()
                        .zip(*center)
                        .map(|(c, z)| mul0(*c, *z))
                        .chain([dual]),
                );
                if ball.is_nan() {
                    boxed
                } else {
                    boxed.min(ball)
                }
            }
        }
    }
}

/// The loop data one step needs.
pub struct Loop<'a> {
    /// The plant of this step.
    pub plant: &'a PlantRows,
    /// `C` (`n × p`): `y = Cᵀx + v`.
    pub obs: &'a DMatrix<f64>,
    /// Process noise box.
    pub w: &'a Bx,
    /// Sensor noise box.
    pub v: &'a Bx,
    /// The controller, saturation included.
    pub net: &'a Network,
    /// Slope-optimisation steps of every back-substitution through the
    /// controller (the analysis's `optimise_slopes`; see
    /// `NetBounds::linear_optimised` in the analysis).
    pub slopes: usize,
}

impl Loop<'_> {
    /// The box of `Cᵀx + v` for `x ∈ x`.
    pub fn observation(&self, x: &Bx) -> Bx {
        let p = self.obs.ncols();
        let mut lo = Vec::with_capacity(p);
        let mut hi = Vec::with_capacity(p);
        // (the sensor noise box has one entry per observation)
        let noise = self.v.lo.iter().zip(&self.v.hi);
        for (col, (&v_lo, &v_hi)) in self.obs.column_iter().zip(noise) {
            let col: Vec<f64> = col.iter().copied().collect();
            lo.push(sum_lower([dot_box_lower(&col, &x.lo, &x.hi), v_lo]));
            hi.push(sum_upper([dot_box_upper(&col, &x.lo, &x.hi), v_hi]));
        }
        Bx { lo, hi }
    }

    /// `δᵢ = Σⱼ E_A,ij |xⱼ|max + Σⱼ E_B,ij |uⱼ|max + E_c,i`, rounded up (zero for an exact plant).
    fn model_delta(&self, xmax: &[f64], umax: &[f64]) -> Vec<f64> {
        match &self.plant.err {
            None => vec![0.0; self.plant.a.nrows()],
            Some((ea, eb, ec)) => ea
                .row_iter()
                .zip(eb.row_iter())
                .zip(ec)
                .map(|((ra, rb), &ec_i)| {
                    let ra: Vec<f64> = ra.iter().copied().collect();
                    let rb: Vec<f64> = rb.iter().copied().collect();
                    sum_upper([abs_dot(&ra, xmax), abs_dot(&rb, umax), ec_i])
                })
                .collect(),
        }
    }

    /// Upper bounds of `fᵣ·x⁺` for the rows `fᵣ` of `facets`, over
    /// `x ∈ x` (and what `start` knows), `w ∈ W`, `v ∈ V`, with the network
    /// bounded over the observation box: per row the smaller of
    /// (a) back-substitution of `fᵣᵀB` through the network (Reach-LP) and
    /// (b) `fᵣᵀB` over the control box `u` (the separate bound), each plus
    /// the exact-plant terms, the model error and every rounding error.
    pub fn facet_bounds(
        &self,
        facets: &DMatrix<f64>,
        x: &Bx,
        start: &Start,
        nb: &NetBounds,
        u: &Bx,
    ) -> Vec<f64> {
        let n = x.lo.len();
        let xmax = x.abs_max();
        let umax = u.abs_max();
        let delta = self.model_delta(&xmax, &umax);
        let fa = mul(facets, &self.plant.a);
        let fb = mul(facets, &self.plant.b);
        let ax = abs_times(&self.plant.a, &xmax);
        let bu = abs_times(&self.plant.b, &umax);
        // (a): F x⁺ bounded linearly in x
        let lin = self.back_step(
            &Linear {
                coef: facets.clone(),
                off: vec![0.0; facets.nrows()],
            },
            x,
            nb,
            u,
        );
        (0..facets.nrows())
            .zip(&lin.off)
            .map(|(r, &lin_off)| {
                let f: Vec<f64> = facets.row(r).iter().copied().collect();
                let fa_r: Vec<f64> = fa.row(r).iter().copied().collect();
                let fb_r: Vec<f64> = fb.row(r).iter().copied().collect();
                let common = sum_upper([
                    sum_upper(f.iter().zip(&self.plant.c).map(|(a, b)| mul0(*a, *b))),
                    dot_box_upper(&f, &self.w.lo, &self.w.hi),
                    product_error(f.iter().copied(), &ax, &xmax, n),
                    product_error(f.iter().copied(), &bu, &umax, n),
                    abs_dot(&f, &delta),
                ]);
                let separate = sum_upper([
                    start.support(&fa_r, x),
                    dot_box_upper(&fb_r, &u.lo, &u.hi),
                    common,
                ]);
                let row: Vec<f64> = lin.coef.row(r).iter().copied().collect();
                let reach_lp = sum_upper([start.support(&row, x), lin_off]);
                if reach_lp.is_nan() || separate.is_nan() {
                    f64::NAN
                } else {
                    reach_lp.min(separate)
                }
            })
            .collect()
    }

    /// One step of back-substitution: rows `L x⁺ ≤ …` (`lin`, over the
    /// next state) become rows linear in the state `x ∈ x`: `L A x` exactly
    /// up to rounding, `L B π(y)` through the network (CROWN with the
    /// witness's relaxations), `y = Cᵀx + v` substituted, `v` and `w`
    /// bounded over their boxes, plus `L c`, the model error and every
    /// rounding error. The tutorial's lemma for Reach-LP, and one link of
    /// the unrolled chain.
    fn back_step(&self, lin: &Linear, x: &Bx, nb: &NetBounds, u: &Bx) -> Linear {
        let n = x.lo.len();
        let xmax = x.abs_max();
        let umax = u.abs_max();
        let delta = self.model_delta(&xmax, &umax);
        let la = mul(&lin.coef, &self.plant.a);
        let lb = mul(&lin.coef, &self.plant.b);
        let ax = abs_times(&self.plant.a, &xmax);
        let bu = abs_times(&self.plant.b, &umax);
        let ct = self.obs.transpose();
        let net = if self.slopes == 0 {
            nb.linear(lb)
        } else {
            // a candidate row over y, measured by what this step makes of
            // it: L A x + G Cᵀx over x's box, G v over v's box, offsets
            // (a measure only ranks sound candidates: any value is safe)
            let measure = |r: usize, cand: &Linear| -> (f64, Vec<f64>) {
                let g: Vec<f64> = cand.coef.row(0).iter().copied().collect();
                // (L A)ᵣ + g Cᵀ, one entry per state
                let total: Vec<f64> = la
                    .row(r)
                    .iter()
                    .zip(ct.column_iter())
                    .map(|(a, ct_j)| a + g.iter().zip(ct_j.iter()).map(|(g, c)| g * c).sum::<f64>())
                    .collect();
                let xs: Vec<f64> = total
                    .iter()
                    .zip(x.lo.iter().zip(&x.hi))
                    .map(|(t, (&lo, &hi))| if *t >= 0.0 { hi } else { lo })
                    .collect();
                let vs: Vec<f64> = g
                    .iter()
                    .zip(self.v.lo.iter().zip(&self.v.hi))
                    .map(|(g, (&lo, &hi))| if *g >= 0.0 { hi } else { lo })
                    .collect();
                let value = sum_upper(
                    total
                        .iter()
                        .zip(&xs)
                        .map(|(t, x)| mul0(*t, *x))
                        .chain(g.iter().zip(&vs).map(|(g, v)| mul0(*g, *v)))
                        .chain(cand.off.first().copied()),
                );
                let ys = ct
                    .row_iter()
                    .zip(&vs)
                    .map(|(ct_k, v)| ct_k.iter().zip(&xs).map(|(c, x)| c * x).sum::<f64>() + v)
                    .collect();
                (value, ys)
            };
            nb.linear_optimised(lb, self.slopes, &measure)
        };
        let gc = mul(&net.coef, &ct);
        let cx = abs_times(&ct, &xmax);
        let coef = la + gc;
        let off = (0..lin.coef.nrows())
            .zip(lin.off.iter().zip(&net.off))
            .map(|(r, (&lin_off, &net_off))| {
                let l: Vec<f64> = lin.coef.row(r).iter().copied().collect();
                let g: Vec<f64> = net.coef.row(r).iter().copied().collect();
                // the sum LA + GC is one more rounding per entry
                let sum_err = sum_upper(
                    coef.row(r)
                        .iter()
                        .zip(&xmax)
                        .map(|(c, m)| mul0((c.abs() * U).next_up(), *m)),
                );
                sum_upper([
                    lin_off,
                    net_off,
                    sum_upper(l.iter().zip(&self.plant.c).map(|(a, b)| mul0(*a, *b))),
                    dot_box_upper(&l, &self.w.lo, &self.w.hi),
                    dot_box_upper(&g, &self.v.lo, &self.v.hi),
                    product_error(l.iter().copied(), &ax, &xmax, n),
                    product_error(l.iter().copied(), &bu, &umax, n),
                    product_error(g.iter().copied(), &cx, &xmax, g.len()),
                    sum_err,
                    abs_dot(&l, &delta),
                ])
            })
            .collect();
        Linear { coef, off }
    }

    /// The checker's bound of the next state's box from the box `x`, with
    /// the network witness (`claimed`) or without (then the witness used is
    /// returned, for the certificate writer).
    pub fn step(
        &self,
        x: &Bx,
        start: &Start,
        claimed: Option<&[Bx]>,
    ) -> Result<(Bx, Witness), Trouble> {
        if !x.is_proper() {
            return Err(Trouble::Overflow);
        }
        let y = self.observation(x);
        let nb = NetBounds::new(self.net, &y, claimed)?;
        let u = nb.output();
        if !u.is_proper() {
            return Err(Trouble::Overflow);
        }
        let n = x.lo.len();
        // the bounds of `x⁺` and of `−x⁺`
        let ub = self.facet_bounds(&plus_minus(n), x, start, &nb, &u);
        let next = Bx {
            lo: ub.iter().skip(n).map(|v| -v).collect(),
            hi: ub.iter().take(n).copied().collect(),
        };
        if !next.is_proper() {
            return Err(Trouble::Overflow);
        }
        Ok((next, nb.witness))
    }

    /// A rigorous enclosure of the next state from every state in `x` with
    /// fixed noise values (interval arithmetic through network and plant,
    /// plus the model error): for replaying a counterexample.
    pub fn enclose(&self, x: &Bx, w: &[f64], v: &[f64]) -> Option<Bx> {
        let vb = Bx::point(v);
        let y = Loop { v: &vb, ..*self }.observation(x);
        let u = network_box(self.net, &y);
        if !(y.is_proper() && u.is_proper()) {
            return None;
        }
        let n = x.lo.len();
        let delta = self.model_delta(&x.abs_max(), &u.abs_max());
        let mut lo = Vec::with_capacity(n);
        let mut hi = Vec::with_capacity(n);
        // (`c`, `w` and `delta` have one entry per state)
        let per_state = self.plant.c.iter().zip(w).zip(&delta);
        for (i, ((&c, &w_i), &delta_i)) in (0..n).zip(per_state) {
            let ra: Vec<f64> = self.plant.a.row(i).iter().copied().collect();
            let rb: Vec<f64> = self.plant.b.row(i).iter().copied().collect();
            lo.push(sum_lower([
                dot_box_lower(&ra, &x.lo, &x.hi),
                dot_box_lower(&rb, &u.lo, &u.hi),
                c,
                w_i,
                -delta_i,
            ]));
            hi.push(sum_upper([
                dot_box_upper(&ra, &x.lo, &x.hi),
                dot_box_upper(&rb, &u.lo, &u.hi),
                c,
                w_i,
                delta_i,
            ]));
        }
        let b = Bx { lo, hi };
        b.is_proper().then_some(b)
    }
}

/// What one step of a chain proves.
#[derive(Clone, Debug, PartialEq)]
pub struct Stepped {
    /// The box of the next states.
    pub next: Bx,
    /// Upper bounds of the next states along the extra directions.
    pub offsets: Vec<f64>,
    /// The pre-activation bounds used.
    pub witness: Witness,
}

/// One step of a cell's chain, kept for back-substitution by later steps.
struct Link<'a> {
    lp: Loop<'a>,
    x: Bx,
    nb: NetBounds<'a>,
    u: Bx,
}

/// A cell's chain of steps as the checker builds it: step by step from the
/// cell's box, each next box the checker's one-step bound of the previous
/// one; with `unrolled`, also the bound of `x_t` back-substituted through
/// every earlier step to the cell (CROWN on the unrolled loop), and every
/// hidden neuron's bound likewise (the smaller is kept).
pub struct Chain<'a> {
    start: Start<'a>,
    unrolled: bool,
    links: Vec<Link<'a>>,
}

impl<'a> Chain<'a> {
    /// An empty chain; `start` is what the unrolled bounds know of the cell
    /// beyond its box (a ball; polytope rows are used by the first step only).
    pub fn new(start: Start<'a>, unrolled: bool) -> Chain<'a> {
        Chain {
            start,
            unrolled,
            links: Vec::new(),
        }
    }

    /// Upper bounds of the rows of `lin` (linear in `x_s`, `s` the number
    /// of links) over every state reachable from the cell: substituted
    /// back through every link and bounded over the cell.
    fn unroll(&self, mut lin: Linear) -> Vec<f64> {
        for link in self.links.iter().rev() {
            lin = link.lp.back_step(&lin, &link.x, &link.nb, &link.u);
        }
        let Some(first) = self.links.first() else {
            return vec![f64::INFINITY; lin.coef.nrows()];
        };
        lin.coef
            .row_iter()
            .zip(&lin.off)
            .map(|(row, &off)| {
                let row: Vec<f64> = row.iter().copied().collect();
                sum_upper([self.start.support(&row, &first.x), off])
            })
            .collect()
    }

    /// The network over the observation box of `x` for the next step, with
    /// every neuron also bounded through the earlier steps when unrolled.
    fn net_bounds(
        &self,
        lp: &Loop<'a>,
        x: &Bx,
        claimed: Option<&[Bx]>,
        widened: bool,
    ) -> Result<NetBounds<'a>, Trouble> {
        let s = self.links.len();
        let y = lp.observation(x);
        let ct = lp.obs.transpose();
        let xmax = x.abs_max();
        let cx = abs_times(&ct, &xmax);
        // a bound linear in y_s becomes one linear in x_s, then is unrolled
        let through = |back: &Linear| -> Vec<f64> {
            let coef = mul(&back.coef, &ct);
            let off = back
                .coef
                .row_iter()
                .zip(&back.off)
                .map(|(g, &back_off)| {
                    let g: Vec<f64> = g.iter().copied().collect();
                    sum_upper([
                        back_off,
                        dot_box_upper(&g, &lp.v.lo, &lp.v.hi),
                        product_error(g.iter().copied(), &cx, &xmax, g.len()),
                    ])
                })
                .collect();
            self.unroll(Linear { coef, off })
        };
        let hook: Option<Hook> = if self.unrolled && s > 0 {
            Some(&through)
        } else {
            None
        };
        NetBounds::with_hook(lp.net, &y, claimed, hook, None, widened)
    }

    /// Pre-activation bounds for the next step from `x` as the certificate
    /// writer claims them: each layer's proven bound, computed from the
    /// earlier layers' claims, [`widen`]ed.
    pub fn witness(&self, lp: &Loop<'a>, x: &Bx) -> Result<Witness, Trouble> {
        if !x.is_proper() {
            return Err(Trouble::Overflow);
        }
        Ok(self.net_bounds(lp, x, None, true)?.witness)
    }

    /// The next step from the box `x` (the cell's box for the first step,
    /// else the previous claimed box; `start` says what else is known of
    /// it) with loop `lp`: its proven box, the proven offsets along the
    /// extra `directions` (rows), and the witness used (checked against
    /// `claimed` when given).
    pub fn step(
        &mut self,
        lp: Loop<'a>,
        x: &Bx,
        start: Start,
        directions: Option<&DMatrix<f64>>,
        claimed: Option<&[Bx]>,
    ) -> Result<Stepped, Trouble> {
        if !x.is_proper() {
            return Err(Trouble::Overflow);
        }
        let s = self.links.len();
        let nb = self.net_bounds(&lp, x, claimed, false)?;
        let u = nb.output();
        if !u.is_proper() {
            return Err(Trouble::Overflow);
        }
        let n = x.lo.len();
        let extra = directions.map_or(0, DMatrix::nrows);
        let mut facets = DMatrix::zeros(2 * n + extra, n);
        facets
            .view_mut((0, 0), (2 * n, n))
            .copy_from(&plus_minus(n));
        if let Some(d) = directions {
            if d.ncols() != n {
                return Err(Trouble::Shape(format!(
                    "directions of width {} for {n} states",
                    d.ncols()
                )));
            }
            facets.view_mut((2 * n, 0), (extra, n)).copy_from(d);
        }
        let mut ub = lp.facet_bounds(&facets, x, &start, &nb, &u);
        if self.unrolled && s > 0 {
            let rows = facets.nrows();
            let lin = lp.back_step(
                &Linear {
                    coef: facets.clone(),
                    off: vec![0.0; rows],
                },
                x,
                &nb,
                &u,
            );
            for (b, o) in ub.iter_mut().zip(self.unroll(lin)) {
                if !o.is_nan() {
                    *b = b.min(o);
                }
            }
        }
        // the bounds of `x⁺`, of `−x⁺`, then along the directions
        let next = Bx {
            lo: ub.iter().skip(n).take(n).map(|v| -v).collect(),
            hi: ub.iter().take(n).copied().collect(),
        };
        let offsets = ub.iter().skip(2 * n).copied().collect::<Vec<_>>();
        if !next.is_proper() || offsets.iter().any(|v| !v.is_finite()) {
            return Err(Trouble::Overflow);
        }
        let witness = nb.witness.clone();
        self.links.push(Link {
            lp,
            x: x.clone(),
            nb,
            u,
        });
        Ok(Stepped {
            next,
            offsets,
            witness,
        })
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use crate::exact::{is_upper, Extreme, Fixed};
    use nalgebra::{DMatrix, DVector};

    /// The exact `a·v` for coefficients `±2^k`.
    fn exact_dot(a: &[(f64, u32)], v: &[f64]) -> Fixed {
        a.iter().zip(v).fold(Fixed::ZERO, |s, (&(sign, k), &x)| {
            let t = Fixed::of_scaled(x, k);
            s.add(if sign > 0.0 { t } else { t.neg() })
        })
    }

    /// The checker's supports over a box and a polytope with given duals
    /// (the goal check of a closed-loop certificate, and a polytope start),
    /// with duals of any size (3.5e307 among them) and boxes near
    /// `f64::MAX`: never below `c·v` at a box vertex `v` that satisfies the
    /// rows (exactly), so no dual makes a false containment pass.
    #[test]
    fn dual_supports_bound_every_feasible_vertex_at_any_magnitude() {
        let mut g = Extreme::new(77);
        let mut feasible = 0;
        for _ in 0..3_000 {
            let n = 1 + g.below(3);
            let (mut lo, mut hi) = (Vec::new(), Vec::new());
            for _ in 0..n {
                let (p, q) = (g.value(), g.value());
                lo.push(p.min(q));
                hi.push(p.max(q));
            }
            let x = Bx { lo, hi };
            let signed = |g: &mut Extreme| -> Vec<(f64, u32)> {
                (0..n)
                    .map(|_| {
                        let sign = if g.below(2) == 0 { 1.0 } else { -1.0 };
                        (sign, g.below(3) as u32)
                    })
                    .collect()
            };
            let coef = |a: &[(f64, u32)]| -> Vec<f64> {
                a.iter().map(|&(s, k)| s * f64::from(1u32 << k)).collect()
            };
            let c = signed(&mut g);
            let raw: Vec<Vec<(f64, u32)>> = (0..1 + g.below(2)).map(|_| signed(&mut g)).collect();
            let rows: Vec<(Vec<f64>, f64)> = raw.iter().map(|a| (coef(a), g.value())).collect();
            let mu: Vec<f64> = rows
                .iter()
                .map(|_| match g.below(4) {
                    0 => 3.5e307,
                    1 => g.value().abs(),
                    2 => g.unit() * 4.0,
                    _ => 1e300,
                })
                .collect();
            let given = [mu];
            let duals = Duals::given(&given);
            let start = Start::Polytope {
                rows: &rows,
                duals: &duals,
            };
            let bound = start.support(&coef(&c), &x);
            for corner in 0..1usize << n {
                let v: Vec<f64> = (0..n)
                    .map(|j| {
                        if corner >> j & 1 == 1 {
                            x.hi[j]
                        } else {
                            x.lo[j]
                        }
                    })
                    .collect();
                let inside = raw
                    .iter()
                    .zip(&rows)
                    .all(|(a, (_, h))| exact_dot(a, &v).le(Fixed::of(*h)));
                if inside {
                    feasible += 1;
                    assert!(
                        is_upper(bound, exact_dot(&c, &v)),
                        "support {bound:e} below c·v at {v:?} (c {c:?}, rows {rows:?}, duals {given:?})"
                    );
                }
            }
        }
        assert!(feasible > 1_000, "{feasible}");
    }

    #[test]
    fn relu_lines_bound_relu_on_their_interval() {
        for (l, u) in [(-1.0, 2.0), (-3.0, 0.5), (-1e-300, 1e-300), (-0.1, 0.3)] {
            let r = relu_lines(l, u);
            for k in 0..=100 {
                let z: f64 = l + (u - l) * k as f64 / 100.0;
                let relu = z.max(0.0);
                assert!(r.al * z + r.bl <= relu + 1e-15);
                assert!(r.au * z + r.bu >= relu);
            }
        }
    }

    #[test]
    fn smooth_lines_bound_tanh_and_sigmoid_on_their_interval() {
        let cases = [
            (-3.0, 2.0),
            (-0.5, -0.1),
            (0.2, 4.0),
            (-1e-9, 1e-9),
            (-40.0, 40.0),
            (1.5, 1.5),
            (-0.3, 0.0),
            (0.0, 0.3),
        ];
        for act in [Activation::Tanh, Activation::Sigmoid] {
            for (l, u) in cases {
                let r = smooth_lines(act, l, u);
                for k in 0..=2000 {
                    let z: f64 = l + (u - l) * k as f64 / 2000.0;
                    let v = act.eval(z);
                    assert!(r.al * z + r.bl <= v + 1e-15, "{act:?} [{l}, {u}] at {z}");
                    assert!(r.au * z + r.bu >= v - 1e-15, "{act:?} [{l}, {u}] at {z}");
                }
                // and not loose: the lines are within the interval's image width
                let w = act.eval(u) - act.eval(l);
                assert!(
                    r.bu - r.bl <= w + 1e-9,
                    "{act:?} [{l}, {u}]: gap {}",
                    r.bu - r.bl
                );
            }
        }
    }

    #[test]
    fn network_bounds_contain_samples() {
        let net = Network::new(
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
        );
        let y = Bx {
            lo: vec![-1.0, -0.5],
            hi: vec![0.5, 1.0],
        };
        let nb = NetBounds::new(&net, &y, None).expect("finite");
        let out = nb.output();
        let lin = nb.linear(DMatrix::from_element(1, 1, 1.0));
        let (g, h) = (
            lin.coef.row(0).iter().copied().collect::<Vec<f64>>(),
            lin.off[0],
        );
        for i in 0..=20 {
            for j in 0..=20 {
                let x = [-1.0 + 1.5 * i as f64 / 20.0, -0.5 + 1.5 * j as f64 / 20.0];
                let v = net.forward(&x)[0];
                assert!(out.lo[0] <= v && v <= out.hi[0]);
                assert!(v <= g[0] * x[0] + g[1] * x[1] + h + 1e-12);
            }
        }
        // the witness checks against itself, and a tightened one does not
        let w = nb.witness.clone();
        assert!(NetBounds::new(&net, &y, Some(&w)).is_ok());
        let mut bad = w.clone();
        bad[0].hi[1] -= 0.01;
        assert!(matches!(
            NetBounds::new(&net, &y, Some(&bad)),
            Err(Trouble::Neuron {
                layer: 0,
                neuron: 1,
                ..
            })
        ));
    }

    /// The slice product gives the bits of the plain triple loop it
    /// stands for (each entry's terms added `k` ascending, zero entries of
    /// `B` skipped), signed zeros and every shape included, the empty ones
    /// too.
    #[test]
    fn the_product_keeps_its_order_bit_for_bit() {
        let mut g = Extreme::new(5);
        // shapes below, at and beyond a tile's, on both edges
        for round in 0..1_200 {
            let (m, k, n) = (round % 21, (round / 21) % 6, (round / 126) % 10 + 1);
            let pick = |g: &mut Extreme| match g.below(4) {
                0 => 0.0,
                1 => -0.0,
                _ => g.value() * 1e-300,
            };
            // an infinite entry of `A` meets the zeros of `B` that are skipped
            let a = DMatrix::from_fn(m, k, |_, _| {
                if g.below(40) == 0 {
                    f64::INFINITY
                } else {
                    pick(&mut g)
                }
            });
            // `B` with one row more or fewer than `A` has columns (a shape
            // that does not fit is multiplied over the common part)
            let kb = match round % 3 {
                0 => k,
                1 => k + 1,
                _ => k.saturating_sub(1),
            };
            let b = DMatrix::from_fn(kb, n, |_, _| pick(&mut g));
            let got = mul(&a, &b);
            assert_eq!(got.shape(), (m, n));
            for i in 0..m {
                for j in 0..n {
                    let mut want = 0.0f64;
                    for p in 0..k.min(kb) {
                        if b[(p, j)] != 0.0 {
                            want += a[(i, p)] * b[(p, j)];
                        }
                    }
                    assert_eq!(
                        got[(i, j)].to_bits(),
                        want.to_bits(),
                        "{m}×{k}·{k}×{n} at ({i}, {j})"
                    );
                }
            }
        }
    }

    /// The column-order loops of `through_affine`, `through_relax` and
    /// `abs_times` give the bits of the row-by-row loops they replaced
    /// (written out here as the reference): each row's terms are the same,
    /// in the same order.
    #[test]
    fn column_loops_give_the_row_loops_bits() {
        let row_affine = |lin: &Linear, w: &DMatrix<f64>, b: &DVector<f64>, zmax: &[f64]| {
            let wz: Vec<f64> = w
                .row_iter()
                .map(|row| sum_upper(row.iter().zip(zmax).map(|(a, x)| mul0(a.abs(), *x))))
                .collect();
            let off: Vec<f64> = lin
                .coef
                .row_iter()
                .zip(&lin.off)
                .map(|(row, &off)| {
                    let err = product_error(row.iter().copied(), &wz, zmax, w.nrows());
                    let consts = row.iter().zip(b.iter()).map(|(c, b)| mul0(*c, *b));
                    sum_upper(consts.chain([off, err]))
                })
                .collect();
            (wz, off)
        };
        let row_relax = |lin: &Linear, lines: &[Lines], zmax: &[f64]| {
            let (rows, cols) = lin.coef.shape();
            let mut coef = DMatrix::zeros(rows, cols);
            let mut off = Vec::new();
            for (r, row) in lin.coef.row_iter().enumerate() {
                let mut terms = vec![lin.off[r]];
                let mut err = 0.0;
                for (j, &cj) in row.iter().enumerate() {
                    if cj == 0.0 {
                        continue;
                    }
                    let l = lines[j];
                    let (a, b) = if cj >= 0.0 {
                        (l.au, l.bu)
                    } else {
                        (l.al, l.bl)
                    };
                    let v = cj * a;
                    coef[(r, j)] = v;
                    err += v.abs() * zmax[j];
                    terms.push(TINY * zmax[j]);
                    terms.push(mul0(cj, b));
                }
                terms.push((2.0 * U * err * 1.0625 + TINY).next_up());
                off.push(sum_upper(terms));
            }
            (coef, off)
        };
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let mut g = Extreme::new(9);
        for round in 0..300 {
            let (rows, k, n) = (round % 6, 1 + (round / 6) % 5, 1 + (round / 30) % 4);
            let pick = |g: &mut Extreme| match g.below(5) {
                0 => 0.0,
                1 => -0.0,
                _ => g.value() * 1e-290,
            };
            let coef = DMatrix::from_fn(rows, k, |_, _| pick(&mut g));
            let off: Vec<f64> = (0..rows).map(|_| pick(&mut g)).collect();
            let lin = Linear { coef, off };
            let w = DMatrix::from_fn(k, n, |_, _| pick(&mut g));
            let b = DVector::from_fn(k, |_, _| pick(&mut g));
            let zmax: Vec<f64> = (0..n).map(|_| pick(&mut g).abs()).collect();
            let (wz, off) = row_affine(&lin, &w, &b, &zmax);
            assert_eq!(bits(&abs_times(&w, &zmax)), bits(&wz));
            let got = lin.through_affine(&w, &b, &zmax);
            assert_eq!(bits(&got.off), bits(&off), "through_affine, round {round}");
            assert_eq!(
                bits(got.coef.as_slice()),
                bits(mul(&lin.coef, &w).as_slice())
            );
            let lines: Vec<Lines> = (0..k)
                .map(|_| Lines {
                    al: pick(&mut g),
                    bl: pick(&mut g),
                    au: pick(&mut g),
                    bu: pick(&mut g),
                })
                .collect();
            let zk: Vec<f64> = (0..k).map(|_| pick(&mut g).abs()).collect();
            let (coef, off) = row_relax(&lin, &lines, &zk);
            let got = lin.through_relax(&lines, &zk);
            assert_eq!(bits(&got.off), bits(&off), "through_relax, round {round}");
            assert_eq!(bits(got.coef.as_slice()), bits(coef.as_slice()));
        }
    }
}
