//! First-order Taylor models: an affine function of `N` symbols
//! `z ∈ [−1, 1]ᴺ` plus an interval remainder.
//!
//! A [`Tm`] `{ c, g, r }` stands for the set `{ c + Σ gᵢ zᵢ + ρ : z ∈ [−1,
//! 1]ᴺ, ρ ∈ r }`, and, more precisely, for a function of `z`: a Taylor model
//! `T` encloses a real function `φ` when `φ(z) − c − g·z ∈ r` for every `z`.
//! Every operation keeps that property for the exact real result.
//!
//! The coefficients `c` and `gᵢ` are plain `f64`s, so each carries a
//! rounding error, and the errors go into the remainder: `|zᵢ| ≤ 1`, so an
//! error `eᵢ` in `gᵢ` moves the value by at most `eᵢ`.
//! * The constant (one per model) is computed as an outward-rounded
//!   interval, its midpoint kept and the distance to the ends absorbed
//!   ([`Absorb`]).
//! * The symbol coefficients (as many as the symbols: the hot loops) are
//!   computed in round-to-nearest, each a short sum of products of `f64`s,
//!   and the sum of their errors is bounded once by the standard a-priori
//!   bound ([`Lin`]; Higham, *Accuracy and Stability of Numerical
//!   Algorithms*, §3.1: a `k`-term dot product has error at most
//!   `γ(k)·Σ|xⱼyⱼ|`), through [`ravel_base::num::error_bound`], the bound
//!   every other rounded sum of ravel uses. It costs one absolute value and
//!   one addition per coefficient, where an interval per coefficient cost
//!   four products, their extremes and two directed roundings.
//!
//! Models with different symbol counts combine as if the shorter one had
//! zero coefficients for the missing symbols (all models of one analysis
//! share one `N`). Operations that can fail return a [`DomainError`];
//! every result is checked finite ([`DomainError::NotFinite`] otherwise).

use super::interval::{DomainError, Interval};
use ravel_base::num::{error_bound, sum_upper, Acc};

/// A first-order Taylor model (see the module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct Tm {
    /// The constant part.
    pub c: f64,
    /// The coefficient of each symbol.
    pub g: Vec<f64>,
    /// The remainder.
    pub r: Interval,
}

/// Rounding errors of chosen coefficients, summed upward.
pub(crate) struct Absorb {
    err: f64,
}

impl Absorb {
    /// No error yet.
    pub(crate) fn new() -> Absorb {
        Absorb { err: 0.0 }
    }

    /// The point kept for the coefficient enclosed by `iv`; its distance to
    /// the ends of `iv` is added to the error (a NaN stays NaN).
    pub(crate) fn take(&mut self, iv: Interval) -> f64 {
        if iv.lo == iv.hi {
            return iv.lo;
        }
        let m = iv.mid();
        let e = (iv.hi - m).max(m - iv.lo).next_up();
        self.err = (self.err + e).next_up();
        if e.is_nan() {
            self.err = f64::NAN;
        }
        m
    }

    /// The accumulated error as a symmetric interval.
    pub(crate) fn interval(&self) -> Interval {
        Interval::symmetric(self.err.next_up())
    }
}

/// Symbol coefficients computed in round-to-nearest and an upper bound of
/// the sum of their absolute rounding errors: `Σᵢ |gᵢ − ĝᵢ| ≤ err`, `ĝᵢ` the
/// exact value of the expression each `gᵢ` was computed from.
///
/// Every constructor computes each `gᵢ` as a dot product of at most `k`
/// terms `xⱼ·yⱼ` of `f64`s (an addend `x` is the term `x·1`, exact), so
/// `|gᵢ − ĝᵢ| ≤ γ(k)·Σⱼ|xⱼyⱼ| + k·η` (η the underflow error of a
/// product). `abs`, the rounded sum over every coefficient of the rounded
/// terms' magnitudes, is at most a relative `γ(N)` (N the number of terms)
/// and one rounding per term below the exact one, and
/// [`error_bound`]`(k, abs)` = `1.0625·γ(k + 2)·abs + TINY`, rounded up,
/// covers both (its factor covers `γ(N) ≤ 0.05`, N below 4·10¹⁴, and `TINY` up to 2⁵²
/// underflowing products). A term or a sum that is not finite makes `err`
/// infinite or NaN, and the model built from it is refused.
///
/// Invariant: a finite `err` means every `gᵢ` is finite (`abs` bounds each
/// `|gᵢ|` from above in the same rounding: a sum or product that
/// overflows makes `abs` overflow too, a NaN makes it NaN), so a model
/// checks its coefficients by checking its remainder ([`Tm::finish`]).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Lin {
    /// The coefficients.
    pub g: Vec<f64>,
    /// The bound of their summed errors.
    pub err: f64,
}

/// `Σ|vᵢ|` in four interleaved partial sums (the error bounds hold for any
/// order of summation, Higham §4.2; the lanes let the adds overlap).
fn abs_sum(v: &[f64]) -> f64 {
    let mut lane = [0.0f64; 4];
    let chunks = v.chunks_exact(4);
    let rest = chunks.remainder();
    for c in chunks {
        for l in 0..4 {
            lane[l] += c[l].abs();
        }
    }
    for (l, x) in rest.iter().enumerate() {
        lane[l] += x.abs();
    }
    (lane[0] + lane[1]) + (lane[2] + lane[3])
}

impl Lin {
    /// `g` copied exactly (no rounding): `err` is 0, or NaN when a
    /// coefficient is not finite (the invariant above).
    pub(crate) fn exact(g: &[f64]) -> Lin {
        let err = if g.iter().all(|x| x.is_finite()) {
            0.0
        } else {
            f64::NAN
        };
        Lin { g: g.to_vec(), err }
    }

    /// `gᵢ = aᵢ + s·bᵢ` for `s = ±1` (a missing coefficient is 0): one
    /// rounding each, relative to the exact sum, so `k = 1` with the
    /// result's magnitudes (`|ĝ| ≤ |g|/(1 − u)`, which the factor covers).
    pub(crate) fn add(a: &[f64], b: &[f64], negate_b: bool) -> Lin {
        let n = a.len().max(b.len());
        let g: Vec<f64> = if a.len() == b.len() && negate_b {
            a.iter().zip(b).map(|(x, y)| x - y).collect()
        } else if a.len() == b.len() {
            a.iter().zip(b).map(|(x, y)| x + y).collect()
        } else {
            let s = if negate_b { -1.0 } else { 1.0 };
            (0..n)
                .map(|i| a.get(i).copied().unwrap_or(0.0) + s * b.get(i).copied().unwrap_or(0.0))
                .collect()
        };
        let abs = abs_sum(&g);
        Lin {
            g,
            err: error_bound(1, abs),
        }
    }

    /// `gᵢ = s·aᵢ`: one rounded product each (`k = 1`).
    pub(crate) fn scale(a: &[f64], s: f64) -> Lin {
        let g: Vec<f64> = a.iter().map(|x| s * x).collect();
        let abs = abs_sum(&g);
        Lin {
            g,
            err: error_bound(1, abs),
        }
    }

    /// `gᵢ = aᵢ / d`: one rounded quotient each, relative to the exact
    /// quotient like a product's (`k = 1`, the result's magnitudes).
    pub(crate) fn div(a: &[f64], d: f64) -> Lin {
        let g: Vec<f64> = a.iter().map(|x| x / d).collect();
        let abs = abs_sum(&g);
        Lin {
            g,
            err: error_bound(1, abs),
        }
    }

    /// `gᵢ = Σⱼ cⱼ·(Tⱼ)ᵢ` over `n` symbols (a missing coefficient is 0),
    /// summed in the order of `tms` from 0 (`k` = the number of models).
    pub(crate) fn dot(coeffs: &[f64], tms: &[&Tm], n: usize) -> Lin {
        let mut g = vec![0.0; n];
        let mut abs = 0.0;
        let mut k = 0;
        for (&a, t) in coeffs.iter().zip(tms) {
            k += 1;
            for (gi, &ti) in g.iter_mut().zip(&t.g) {
                let p = a * ti;
                abs += p.abs();
                *gi += p;
            }
        }
        Lin {
            g,
            err: error_bound(k.max(1), abs),
        }
    }
}

/// `Interval::point`.
fn pt(x: f64) -> Interval {
    Interval::point(x)
}

impl Tm {
    /// The constant `c` over `n` symbols.
    pub fn constant(c: f64, n: usize) -> Tm {
        Tm {
            c,
            g: vec![0.0; n],
            r: Interval::ZERO,
        }
    }

    /// `centre + radius·z_i` over `n` symbols. With `i ≥ n` (no such
    /// symbol) the model is `centre + [−|radius|, |radius|]`, still
    /// covering the same values.
    pub fn symbol(i: usize, centre: f64, radius: f64, n: usize) -> Tm {
        let mut t = Tm::constant(centre, n);
        match t.g.get_mut(i) {
            Some(gi) => *gi = radius,
            None => t.r = Interval::symmetric(radius.abs()),
        }
        t
    }

    /// The interval `iv` as a model with no symbol dependence: its midpoint
    /// plus the rest as remainder.
    pub fn from_interval(iv: Interval, n: usize) -> Tm {
        let m = iv.mid();
        Tm {
            c: m,
            g: vec![0.0; n],
            r: iv - pt(m),
        }
    }

    /// The number of symbols.
    pub fn symbols(&self) -> usize {
        self.g.len()
    }

    /// `c`, every `gᵢ` and the remainder finite.
    pub fn is_finite(&self) -> bool {
        self.c.is_finite() && self.g.iter().all(|g| g.is_finite()) && self.r.is_finite()
    }

    /// `self` when finite, otherwise [`DomainError::NotFinite`].
    pub fn checked(self) -> Result<Tm, DomainError> {
        if self.is_finite() {
            Ok(self)
        } else {
            Err(DomainError::NotFinite)
        }
    }

    /// An upper bound of `Σ |gᵢ|` (`+∞` if not finite).
    pub fn linear_radius(&self) -> f64 {
        sum_upper(self.g.iter().map(|g| g.abs()))
    }

    /// The range of the non-constant part: `[−Σ|gᵢ|, Σ|gᵢ|] + r`.
    pub fn deviation(&self) -> Interval {
        Interval::symmetric(self.linear_radius()) + self.r
    }

    /// A sound enclosure of every value of the model (non-finite if the
    /// model is).
    pub fn range(&self) -> Interval {
        pt(self.c) + self.deviation()
    }

    /// The value of the linear part at `z` in plain `f64` plus the
    /// remainder (for tests and diagnostics: no rounding control).
    pub fn eval_at(&self, z: &[f64]) -> Interval {
        let lin: f64 = self.g.iter().zip(z).map(|(g, z)| g * z).sum();
        Interval::new(self.c + lin + self.r.lo, self.c + lin + self.r.hi)
    }

    /// A model from an enclosure of the constant, symbol coefficients with
    /// their error bound, and `rem`: both errors join the remainder.
    ///
    /// The symbol coefficients are not scanned: a finite remainder holds
    /// `lin.err`, and a finite `lin.err` means finite coefficients
    /// ([`Lin`]'s invariant).
    fn finish(c_iv: Interval, lin: Lin, rem: Interval) -> Result<Tm, DomainError> {
        let mut ab = Absorb::new();
        let c = ab.take(c_iv);
        let r = rem + ab.interval() + Interval::symmetric(lin.err);
        if !(c.is_finite() && r.is_finite() && lin.err.is_finite()) {
            return Err(DomainError::NotFinite);
        }
        debug_assert!(lin.g.iter().all(|g| g.is_finite()));
        Ok(Tm { c, g: lin.g, r })
    }

    /// `self + o`.
    pub fn add(&self, o: &Tm) -> Result<Tm, DomainError> {
        Tm::finish(
            pt(self.c) + pt(o.c),
            Lin::add(&self.g, &o.g, false),
            self.r + o.r,
        )
    }

    /// `self − o`.
    pub fn sub(&self, o: &Tm) -> Result<Tm, DomainError> {
        Tm::finish(
            pt(self.c) - pt(o.c),
            Lin::add(&self.g, &o.g, true),
            self.r - o.r,
        )
    }

    /// `−self` (exact).
    pub fn neg(&self) -> Tm {
        Tm {
            c: -self.c,
            g: self.g.iter().map(|g| -g).collect(),
            r: -self.r,
        }
    }

    /// `self · s` for a real `s`.
    pub fn scale(&self, s: f64) -> Result<Tm, DomainError> {
        Tm::finish(pt(self.c) * pt(s), Lin::scale(&self.g, s), self.r * pt(s))
    }

    /// `self / d` for a real `d ≠ 0`.
    pub fn div_scalar(&self, d: f64) -> Result<Tm, DomainError> {
        let dv = pt(d);
        // the interval division refuses a divisor that may be 0 (or is
        // not finite); the coefficients are then divided by the same `d`
        let c_iv = pt(self.c).div(dv)?;
        let r = self.r.div(dv)?;
        Tm::finish(c_iv, Lin::div(&self.g, d), r)
    }

    /// `self + iv`.
    pub fn add_interval(&self, iv: Interval) -> Result<Tm, DomainError> {
        let m = iv.mid();
        // the symbol coefficients are copied exactly
        Tm::finish(
            pt(self.c) + pt(m),
            Lin::exact(&self.g),
            self.r + (iv - pt(m)),
        )
    }

    /// `self · s` for every real `s ∈ iv`: the midpoint scales the model,
    /// the rest multiplies its range into the remainder.
    pub fn mul_interval(&self, iv: Interval) -> Result<Tm, DomainError> {
        let iv = iv.checked()?;
        let m = iv.mid();
        let rest = self.range() * (iv - pt(m));
        Tm::finish(
            pt(self.c) * pt(m),
            Lin::scale(&self.g, m),
            self.r * pt(m) + rest,
        )
    }

    /// `self · o`: the product of the linear parts goes to the remainder,
    /// bounded with the squares `zᵢ² ∈ [0, 1]` apart from the cross terms.
    pub fn mul(&self, o: &Tm) -> Result<Tm, DomainError> {
        let p = product_pass(self, o);
        let (la, lb) = (
            Interval::symmetric(p.radius_a),
            Interval::symmetric(p.radius_b),
        );
        let rem = p.quadratic
            + pt(self.c) * o.r
            + pt(o.c) * self.r
            + la * o.r
            + lb * self.r
            + self.r * o.r;
        Tm::finish(pt(self.c) * pt(o.c), p.lin, rem)
    }
}

/// What [`Tm::mul`] needs from the symbol coefficients of its operands,
/// gathered in one pass (see [`product_pass`]).
pub(crate) struct Product {
    /// `c_b·aᵢ + c_a·bᵢ`: two rounded products and their rounded sum, a
    /// 2-term dot product (`k = 2`, the products' magnitudes).
    pub lin: Lin,
    /// [`quadratic`]'s enclosure.
    pub quadratic: Interval,
    /// Upper bounds of `Σ|aᵢ|` and `Σ|bᵢ|` ([`Tm::linear_radius`]).
    pub radius_a: f64,
    pub radius_b: f64,
}

/// The linear part of a product, [`quadratic`] and both [`Tm::linear_radius`]es in one pass
/// over the coefficients, each sum in four interleaved partial sums (any
/// order of summation has the same error bound, Higham §4.2). Each result
/// is the one of those functions, computed with the same terms (only the
/// order of the sums differs: the tests compare them).
pub(crate) fn product_pass(a: &Tm, b: &Tm) -> Product {
    let (ca, cb) = (a.c, b.c);
    let common = a.g.len().min(b.g.len());
    let n = a.g.len().max(b.g.len());
    let mut g = vec![0.0; n];
    // lanes of Σ|aᵢ|, Σ|bᵢ|, Σ min(0, pᵢ), Σ max(0, pᵢ), Σ|pᵢ|, Σ(|sᵢ| + |tᵢ|)
    let mut lane = [[0.0f64; 4]; 6];
    let mut one = |l: usize, x: f64, y: f64, gi: &mut f64| {
        let d = x * y;
        lane[0][l] += x.abs();
        lane[1][l] += y.abs();
        lane[2][l] += d.min(0.0);
        lane[3][l] += d.max(0.0);
        lane[4][l] += d.abs();
        let (s, t) = (ca * y, cb * x);
        lane[5][l] += s.abs() + t.abs();
        *gi = s + t;
    };
    let (ga, gb) = (&a.g[..common], &b.g[..common]);
    let mut it = g[..common].chunks_exact_mut(4);
    for ((g4, a4), b4) in (&mut it).zip(ga.chunks_exact(4)).zip(gb.chunks_exact(4)) {
        for l in 0..4 {
            one(l, a4[l], b4[l], &mut g4[l]);
        }
    }
    let done = common - it.into_remainder().len();
    for i in done..common {
        one(i - done, ga[i], gb[i], &mut g[i]);
    }
    // beyond the shorter model its coefficients are 0: `pᵢ = 0`, and one
    // product `cᵦ·aᵢ` (or `cₐ·bᵢ`) is the coefficient, exactly the sum
    // `0 + t` of the loop above
    let (longer, c, k) = if a.g.len() > common {
        (&a.g, cb, 0)
    } else {
        (&b.g, ca, 1)
    };
    for i in common..n {
        let x = longer[i];
        lane[k][0] += x.abs();
        let t = c * x;
        lane[5][0] += t.abs();
        g[i] = t;
    }
    let sum = |l: &[f64; 4]| (l[0] + l[1]) + (l[2] + l[3]);
    let (ra, rb, neg, pos, dabs, labs) = (
        sum(&lane[0]),
        sum(&lane[1]),
        sum(&lane[2]),
        sum(&lane[3]),
        sum(&lane[4]),
        sum(&lane[5]),
    );
    let radius_a = Acc::from_parts(ra, ra, a.g.len()).upper();
    let radius_b = Acc::from_parts(rb, rb, b.g.len()).upper();
    // Σ|pᵢ| bounds the magnitudes of the terms of all three sums
    let (neg, pos, diag) = (
        Acc::from_parts(neg, dabs, common).lower(),
        Acc::from_parts(pos, dabs, common).upper(),
        Acc::from_parts(dabs, dabs, common).lower(),
    );
    Product {
        lin: Lin {
            g,
            err: error_bound(2, labs),
        },
        quadratic: quadratic_of(neg, pos, diag, radius_a, radius_b),
        radius_a,
        radius_b,
    }
}

/// An enclosure of `(Σ aᵢ zᵢ)(Σ bⱼ zⱼ)` over the cube: the diagonal terms
/// `aᵢbᵢzᵢ²` lie between `min(0, aᵢbᵢ)` and `max(0, aᵢbᵢ)`, the cross terms
/// within `±(Σ|aᵢ|·Σ|bⱼ| − Σ|aᵢbᵢ|)`. The three sums are of rounded
/// products `pᵢ = aᵢ·bᵢ`: `min(0, pᵢ)`, `max(0, pᵢ)` and `|pᵢ|` are each one
/// rounding from the same function of the exact product (a product keeps
/// its sign when rounded), so [`Acc`] bounds each exact sum (symbols
/// beyond the shorter model have a zero coefficient in it: no term).
#[cfg(test)]
pub(crate) fn quadratic(a: &Tm, b: &Tm) -> Interval {
    let (mut neg, mut pos, mut diag_abs) = (Acc::ZERO, Acc::ZERO, Acc::ZERO);
    for (ai, bi) in a.g.iter().zip(&b.g) {
        let p = ai * bi;
        // `min`/`max` would drop a NaN: the magnitude's sum keeps it
        neg.add(p.min(0.0));
        pos.add(p.max(0.0));
        diag_abs.add(p.abs());
    }
    let (neg, pos, diag) = (neg.lower(), pos.upper(), diag_abs.lower());
    quadratic_of(neg, pos, diag, a.linear_radius(), b.linear_radius())
}

/// The enclosure from a lower bound of `Σ min(0, aᵢbᵢ)`, an upper bound of
/// `Σ max(0, aᵢbᵢ)`, a lower bound of `Σ|aᵢbᵢ|` and upper bounds of `Σ|aᵢ|`
/// and `Σ|bᵢ|` ([`quadratic`]); NaN ends when any is not finite.
fn quadratic_of(neg: f64, pos: f64, diag: f64, ra: f64, rb: f64) -> Interval {
    let full = pt(ra) * pt(rb);
    // checked before `max`, which would turn a NaN (a radius that is not
    // finite) into 0 and drop the cross terms
    let cross = (full.hi - diag).next_up();
    if !(cross.is_finite() && neg.is_finite() && pos.is_finite() && diag.is_finite()) {
        return super::interval::NAN;
    }
    let cross = cross.max(0.0);
    Interval::new((neg - cross).next_down(), (pos + cross).next_up())
}

/// The linear combination `Σ aⱼ Tⱼ + offset` (coefficients and offset
/// exact reals; rounding absorbed). Extra coefficients or models beyond
/// the shorter list are ignored.
pub fn combine(coeffs: &[f64], tms: &[&Tm], offset: f64) -> Result<Tm, DomainError> {
    let n = tms.iter().map(|t| t.symbols()).max().unwrap_or(0);
    let pairs = || coeffs.iter().zip(tms.iter());
    let mut c = pt(offset);
    let mut r = Interval::ZERO;
    for (&a, t) in pairs() {
        c = c + pt(a) * pt(t.c);
        r = r + pt(a) * t.r;
    }
    Tm::finish(c, Lin::dot(coeffs, tms, n), r)
}

/// A sound upper bound of `max dir·x` over every `z` of the models `x`
/// (the linear part exactly, the remainders added): `+∞` when the
/// combination is not finite.
pub fn support(dir: &[f64], x: &[Tm]) -> f64 {
    let refs: Vec<&Tm> = x.iter().collect();
    match combine(dir, &refs, 0.0) {
        Ok(t) => {
            let hi = t.range().hi;
            if hi.is_nan() {
                f64::INFINITY
            } else {
                hi
            }
        }
        Err(_) => f64::INFINITY,
    }
}
