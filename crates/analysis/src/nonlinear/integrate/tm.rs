//! First-order Taylor models: an affine function of `N` symbols
//! `z ∈ [−1, 1]ᴺ` plus an interval remainder.
//!
//! A [`Tm`] `{ c, g, r }` stands for the set `{ c + Σ gᵢ zᵢ + ρ : z ∈ [−1,
//! 1]ᴺ, ρ ∈ r }`, and, more precisely, for a function of `z`: a Taylor model
//! `T` encloses a real function `φ` when `φ(z) − c − g·z ∈ r` for every `z`.
//! Every operation keeps that property for the exact real result.
//!
//! The coefficients `c` and `gᵢ` are plain `f64`s, so each is computed as an
//! outward-rounded interval, the midpoint is kept, and the distance to the
//! interval's ends (the rounding error) goes into the remainder: `|zᵢ| ≤ 1`,
//! so an error `eᵢ` in `gᵢ` moves the value by at most `eᵢ` ([`Absorb`]).
//!
//! Models with different symbol counts combine as if the shorter one had
//! zero coefficients for the missing symbols (all models of one analysis
//! share one `N`). Operations that can fail return a [`DomainError`];
//! every result is checked finite ([`DomainError::NotFinite`] otherwise).

use super::interval::{DomainError, Interval};
use ravel_base::num::sum_upper;

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

    /// A model from coefficient enclosures: `c ∈ c_iv`, `gᵢ ∈ g_iv(i)`,
    /// plus `rem`; the rounding of every coefficient is absorbed.
    fn build(
        c_iv: Interval,
        n: usize,
        mut g_iv: impl FnMut(usize) -> Interval,
        rem: Interval,
    ) -> Result<Tm, DomainError> {
        let mut ab = Absorb::new();
        let c = ab.take(c_iv);
        let g = (0..n).map(|i| ab.take(g_iv(i))).collect();
        Tm {
            c,
            g,
            r: rem + ab.interval(),
        }
        .checked()
    }

    /// Coefficient `i`, zero beyond the end.
    fn gi(&self, i: usize) -> f64 {
        self.g.get(i).copied().unwrap_or(0.0)
    }

    /// `self + o`.
    pub fn add(&self, o: &Tm) -> Result<Tm, DomainError> {
        let n = self.symbols().max(o.symbols());
        Tm::build(
            pt(self.c) + pt(o.c),
            n,
            |i| pt(self.gi(i)) + pt(o.gi(i)),
            self.r + o.r,
        )
    }

    /// `self − o`.
    pub fn sub(&self, o: &Tm) -> Result<Tm, DomainError> {
        self.add(&o.neg())
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
        let s = pt(s);
        Tm::build(
            pt(self.c) * s,
            self.symbols(),
            |i| pt(self.gi(i)) * s,
            self.r * s,
        )
    }

    /// `self / d` for a real `d ≠ 0`.
    pub fn div_scalar(&self, d: f64) -> Result<Tm, DomainError> {
        let d = pt(d);
        let mut err = None;
        let mut q = |x: Interval| {
            x.div(d).unwrap_or_else(|e| {
                err = Some(e);
                super::interval::NAN
            })
        };
        let c_iv = q(pt(self.c));
        let g: Vec<Interval> = self.g.iter().map(|&g| q(pt(g))).collect();
        let r = q(self.r);
        if let Some(e) = err {
            return Err(e);
        }
        Tm::build(
            c_iv,
            g.len(),
            |i| g.get(i).copied().unwrap_or(Interval::ZERO),
            r,
        )
    }

    /// `self + iv`.
    pub fn add_interval(&self, iv: Interval) -> Result<Tm, DomainError> {
        let m = iv.mid();
        Tm::build(
            pt(self.c) + pt(m),
            self.symbols(),
            |i| pt(self.gi(i)),
            self.r + (iv - pt(m)),
        )
    }

    /// `self · s` for every real `s ∈ iv`: the midpoint scales the model,
    /// the rest multiplies its range into the remainder.
    pub fn mul_interval(&self, iv: Interval) -> Result<Tm, DomainError> {
        let iv = iv.checked()?;
        let m = iv.mid();
        let rest = self.range() * (iv - pt(m));
        Tm::build(
            pt(self.c) * pt(m),
            self.symbols(),
            |i| pt(self.gi(i)) * pt(m),
            self.r * pt(m) + rest,
        )
    }

    /// `self · o`: the product of the linear parts goes to the remainder,
    /// bounded with the squares `zᵢ² ∈ [0, 1]` apart from the cross terms.
    pub fn mul(&self, o: &Tm) -> Result<Tm, DomainError> {
        let n = self.symbols().max(o.symbols());
        let (la, lb) = (
            Interval::symmetric(self.linear_radius()),
            Interval::symmetric(o.linear_radius()),
        );
        let rem = quadratic(self, o, n)
            + pt(self.c) * o.r
            + pt(o.c) * self.r
            + la * o.r
            + lb * self.r
            + self.r * o.r;
        Tm::build(
            pt(self.c) * pt(o.c),
            n,
            |i| pt(self.c) * pt(o.gi(i)) + pt(o.c) * pt(self.gi(i)),
            rem,
        )
    }
}

/// An enclosure of `(Σ aᵢ zᵢ)(Σ bⱼ zⱼ)` over the cube: the diagonal terms
/// `aᵢbᵢzᵢ²` lie between `min(0, aᵢbᵢ)` and `max(0, aᵢbᵢ)`, the cross terms
/// within `±(Σ|aᵢ|·Σ|bⱼ| − Σ|aᵢbᵢ|)`.
fn quadratic(a: &Tm, b: &Tm, n: usize) -> Interval {
    let (mut neg, mut pos, mut diag_abs) = (Interval::ZERO, Interval::ZERO, Interval::ZERO);
    for i in 0..n {
        let (ai, bi) = (a.gi(i), b.gi(i));
        if ai == 0.0 || bi == 0.0 {
            continue;
        }
        let p = pt(ai) * pt(bi);
        neg = neg + pt(p.lo.min(0.0));
        pos = pos + pt(p.hi.max(0.0));
        diag_abs = diag_abs + pt(p.mig());
    }
    let full = pt(a.linear_radius()) * pt(b.linear_radius());
    let cross = (full.hi - diag_abs.lo).next_up().max(0.0);
    if cross.is_nan() || !(neg.is_finite() && pos.is_finite()) {
        return super::interval::NAN;
    }
    Interval::new((neg.lo - cross).next_down(), (pos.hi + cross).next_up())
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
    Tm::build(
        c,
        n,
        |i| {
            pairs()
                .filter(|(&a, t)| a != 0.0 && t.gi(i) != 0.0)
                .fold(Interval::ZERO, |s, (&a, t)| s + pt(a) * pt(t.gi(i)))
        },
        r,
    )
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
