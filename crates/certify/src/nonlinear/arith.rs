//! The checker's own arithmetic for nonlinear plants: outward-rounded
//! intervals ([`Iv`]) and affine forms ([`Af`], a value `c + Σⱼ gⱼ sⱼ + ε`
//! over symbols `sⱼ ∈ [−1, 1]` with `|ε| ≤ e`), both behind [`Num`] so that
//! one Taylor-series evaluator serves both.
//!
//! Written for this crate, independently of the analysis's Taylor models;
//! it shares nothing with them but the error model of `ravel_base::num`.
//!
//! * Every `+ − ×` of floats is followed by an outward step (`next_up` /
//!   `next_down`) in intervals, and by a bound of its rounding error
//!   (`|z|·ε + TINY`, `ε` the machine epsilon, twice the unit roundoff)
//!   added to an affine form's `e`.
//! * Elementary functions are taken from the platform's `libm`, assumed
//!   within [`LIBM_ULPS`] units in the last place of the exact value (the
//!   assumption the analysis documents too), and widened by that. `sin` and
//!   `cos` find their extrema with a margin; arguments beyond
//!   [`TRIG_MAX`] give `[−1, 1]` (`tan`: a failure).
//! * An affine form's elementary function is its mean-value form around the
//!   centre: `φ(x) ∈ φ(c) + d·(x − c) + [−δ, δ]·|x − c|`, with
//!   `[d − δ, d + δ] ⊇ φ'(X)` over the form's range `X`.
//! * A divisor that may be 0, `log`/`sqrt` of a range reaching 0 or below,
//!   a pole of `tan` that may be in range: [`Fail::Domain`]. A number that
//!   is not finite is caught by the callers ([`Num::finite`]).

use ravel_base::expr::Func;
use ravel_base::num::{sum_upper, TINY};

/// How many units in the last place `libm`'s results are assumed within.
pub const LIBM_ULPS: u32 = 4;

/// Beyond this magnitude `sin`/`cos` are bounded by `[−1, 1]` and `tan`
/// fails (the extremum search's margin is not worth trusting there).
pub const TRIG_MAX: f64 = 1e5;

/// Why the arithmetic gives no bound.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fail {
    /// A function applied where it may be undefined.
    Domain(Func),
    /// A division by a range that may contain 0.
    Division,
    /// A bound that is not finite.
    Overflow,
    /// No a-priori enclosure of the flow was found.
    NoEnclosure,
}

impl std::fmt::Display for Fail {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Fail::Domain(g) => write!(f, "`{}` may be undefined on the range", g.name()),
            Fail::Division => f.write_str("a divisor may be 0"),
            Fail::Overflow => f.write_str("a bound is not finite"),
            Fail::NoEnclosure => f.write_str("no a-priori enclosure of the flow"),
        }
    }
}

fn dn(x: f64) -> f64 {
    x.next_down()
}

fn up(x: f64) -> f64 {
    x.next_up()
}

fn dn_k(mut x: f64, k: u32) -> f64 {
    for _ in 0..k {
        x = x.next_down();
    }
    x
}

fn up_k(mut x: f64, k: u32) -> f64 {
    for _ in 0..k {
        x = x.next_up();
    }
    x
}

/// A bound of the rounding error of one operation whose rounded result is `z`.
fn rounding(z: f64) -> f64 {
    up(z.abs() * f64::EPSILON + TINY)
}

/// A closed interval `[lo, hi]` with outward-rounded operations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Iv {
    /// Lower end.
    pub lo: f64,
    /// Upper end.
    pub hi: f64,
}

impl Iv {
    /// `[lo, hi]` as given (callers keep `lo ≤ hi`).
    pub fn new(lo: f64, hi: f64) -> Iv {
        Iv { lo, hi }
    }

    /// `[x, x]`.
    pub fn point(x: f64) -> Iv {
        Iv { lo: x, hi: x }
    }

    /// The whole line (what an undefined operation gives; not finite).
    fn entire() -> Iv {
        Iv {
            lo: f64::NEG_INFINITY,
            hi: f64::INFINITY,
        }
    }

    /// Both ends finite and in order.
    pub fn is_finite(&self) -> bool {
        self.lo.is_finite() && self.hi.is_finite() && self.lo <= self.hi
    }

    /// A float inside (the midpoint, for finite intervals).
    pub fn mid(&self) -> f64 {
        0.5 * self.lo + 0.5 * self.hi
    }

    /// A radius around [`Iv::mid`], rounded up.
    pub fn rad(&self) -> f64 {
        let m = self.mid();
        up(self.hi - m).max(up(m - self.lo))
    }

    /// Whether `o` lies inside.
    pub fn contains(&self, o: &Iv) -> bool {
        self.lo <= o.lo && o.hi <= self.hi
    }

    /// The smallest interval holding both.
    pub fn hull(&self, o: &Iv) -> Iv {
        Iv::new(self.lo.min(o.lo), self.hi.max(o.hi))
    }

    /// The intersection (callers check that it is not empty when it matters).
    pub fn meet(&self, o: &Iv) -> Iv {
        Iv::new(self.lo.max(o.lo), self.hi.min(o.hi))
    }

    /// `self ± r` for `r ≥ 0`.
    pub fn widen(&self, r: f64) -> Iv {
        Iv::new(dn(self.lo - r), up(self.hi + r))
    }

    fn iadd(&self, o: &Iv) -> Iv {
        Iv::new(dn(self.lo + o.lo), up(self.hi + o.hi))
    }

    fn isub(&self, o: &Iv) -> Iv {
        Iv::new(dn(self.lo - o.hi), up(self.hi - o.lo))
    }

    fn imul(&self, o: &Iv) -> Iv {
        let p = [
            self.lo * o.lo,
            self.lo * o.hi,
            self.hi * o.lo,
            self.hi * o.hi,
        ];
        if p.iter().any(|v| v.is_nan()) {
            return Iv::entire();
        }
        let lo = p.iter().fold(f64::INFINITY, |m, v| m.min(*v));
        let hi = p.iter().fold(f64::NEG_INFINITY, |m, v| m.max(*v));
        Iv::new(dn(lo), up(hi))
    }

    /// `x²` (never below 0).
    pub fn sqr(&self) -> Iv {
        let (a, b) = (self.lo.abs(), self.hi.abs());
        let lo = if self.lo <= 0.0 && self.hi >= 0.0 {
            0.0
        } else {
            dn(a.min(b) * a.min(b)).max(0.0)
        };
        Iv::new(lo, up(a.max(b) * a.max(b)))
    }

    /// `1/x`: [`Fail::Division`] when the range may contain 0.
    pub fn recip(&self) -> Result<Iv, Fail> {
        if !(self.lo > 0.0 || self.hi < 0.0) {
            return Err(Fail::Division);
        }
        Ok(Iv::new(dn(1.0 / self.hi), up(1.0 / self.lo)))
    }

    /// A `libm` value widened by [`LIBM_ULPS`] each way.
    fn libm(lo: f64, hi: f64) -> Iv {
        Iv::new(dn_k(lo, LIBM_ULPS), up_k(hi, LIBM_ULPS))
    }

    /// Whether `[lo, hi]`, widened by a margin, may contain a point
    /// `p + k·period` for an integer `k`.
    fn may_contain(&self, p: f64, period: f64) -> bool {
        let margin = 1e-9 * (1.0 + self.lo.abs().max(self.hi.abs()));
        let k_lo = ((self.lo - margin - p) / period).ceil();
        let k_hi = ((self.hi + margin - p) / period).floor();
        k_lo <= k_hi || k_lo.is_nan() || k_hi.is_nan()
    }

    fn sin_cos(&self, cosine: bool) -> Iv {
        if !(self.is_finite() && self.lo.abs() <= TRIG_MAX && self.hi.abs() <= TRIG_MAX)
            || self.hi - self.lo >= 6.0
        {
            return Iv::new(-1.0, 1.0);
        }
        let tau = 2.0 * std::f64::consts::PI;
        let half = std::f64::consts::FRAC_PI_2;
        let (f, peak, trough): (fn(f64) -> f64, f64, f64) = if cosine {
            (f64::cos, 0.0, std::f64::consts::PI)
        } else {
            (f64::sin, half, -half)
        };
        let (a, b) = (f(self.lo), f(self.hi));
        let mut r = Iv::libm(a.min(b), a.max(b));
        if self.may_contain(peak, tau) {
            r.hi = 1.0;
        }
        if self.may_contain(trough, tau) {
            r.lo = -1.0;
        }
        Iv::new(r.lo.max(-1.0), r.hi.min(1.0))
    }

    /// `φ(x)` over the interval.
    pub fn elem(&self, g: Func) -> Result<Iv, Fail> {
        let (lo, hi) = (self.lo, self.hi);
        Ok(match g {
            Func::Exp => {
                let r = Iv::libm(lo.exp(), hi.exp());
                Iv::new(r.lo.max(0.0), r.hi)
            }
            Func::Log => {
                if lo.is_nan() || lo <= 0.0 {
                    return Err(Fail::Domain(g));
                }
                Iv::libm(lo.ln(), hi.ln())
            }
            Func::Sqrt => {
                if lo.is_nan() || lo < 0.0 {
                    return Err(Fail::Domain(g));
                }
                Iv::new(dn(lo.sqrt()).max(0.0), up(hi.sqrt()))
            }
            Func::Tanh => {
                let r = Iv::libm(lo.tanh(), hi.tanh());
                Iv::new(r.lo.max(-1.0), r.hi.min(1.0))
            }
            Func::Sin => self.sin_cos(false),
            Func::Cos => self.sin_cos(true),
            Func::Tan => {
                if !(self.is_finite() && lo.abs() <= TRIG_MAX && hi.abs() <= TRIG_MAX)
                    || self.may_contain(std::f64::consts::FRAC_PI_2, std::f64::consts::PI)
                {
                    return Err(Fail::Domain(g));
                }
                Iv::libm(lo.tan(), hi.tan())
            }
            Func::Abs => {
                let (a, b) = (lo.abs(), hi.abs());
                if lo <= 0.0 && hi >= 0.0 {
                    Iv::new(0.0, a.max(b))
                } else {
                    Iv::new(a.min(b), a.max(b))
                }
            }
        })
    }

    /// An enclosure of `φ'` over the interval (`abs`: its subgradients).
    pub fn deriv(&self, g: Func) -> Result<Iv, Fail> {
        let one = Iv::point(1.0);
        Ok(match g {
            Func::Exp => self.elem(Func::Exp)?,
            Func::Log => {
                if self.lo.is_nan() || self.lo <= 0.0 {
                    return Err(Fail::Domain(g));
                }
                self.recip()?
            }
            Func::Sqrt => {
                if self.lo.is_nan() || self.lo <= 0.0 {
                    return Err(Fail::Domain(g));
                }
                let s = self.elem(Func::Sqrt)?;
                s.iadd(&s).recip()?
            }
            Func::Tanh => one.isub(&self.elem(Func::Tanh)?.sqr()),
            Func::Sin => self.elem(Func::Cos)?,
            Func::Cos => {
                let s = self.elem(Func::Sin)?;
                Iv::new(-s.hi, -s.lo)
            }
            Func::Tan => one.iadd(&self.elem(Func::Tan)?.sqr()),
            Func::Abs => {
                if self.lo >= 0.0 {
                    one
                } else if self.hi <= 0.0 {
                    Iv::point(-1.0)
                } else {
                    Iv::new(-1.0, 1.0)
                }
            }
        })
    }
}

/// The arithmetic the Taylor-series evaluator needs.
pub trait Num: Clone + Sized {
    /// The constant `v` with `self`'s shape (an affine form's symbols).
    fn cst(&self, v: f64) -> Self;
    /// `self + o`.
    fn add(&self, o: &Self) -> Self;
    /// `self − o`.
    fn sub(&self, o: &Self) -> Self;
    /// `−self`.
    fn neg(&self) -> Self;
    /// `self · o`.
    fn mul(&self, o: &Self) -> Self;
    /// `self · s` for a float `s`.
    fn scale(&self, s: f64) -> Self;
    /// `self / k` for an integer `k ≥ 1`.
    fn div_int(&self, k: u32) -> Self;
    /// `self + i` for an interval `i`.
    fn add_iv(&self, i: &Iv) -> Self;
    /// `φ(self)`.
    fn elem(&self, g: Func) -> Result<Self, Fail>;
    /// `1 / self`.
    fn recip(&self) -> Result<Self, Fail>;
    /// An interval holding every value.
    fn range(&self) -> Iv;
    /// Every number finite.
    fn finite(&self) -> bool {
        self.range().is_finite()
    }
}

impl Num for Iv {
    fn cst(&self, v: f64) -> Iv {
        Iv::point(v)
    }
    fn add(&self, o: &Iv) -> Iv {
        self.iadd(o)
    }
    fn sub(&self, o: &Iv) -> Iv {
        self.isub(o)
    }
    fn neg(&self) -> Iv {
        Iv::new(-self.hi, -self.lo)
    }
    fn mul(&self, o: &Iv) -> Iv {
        self.imul(o)
    }
    fn scale(&self, s: f64) -> Iv {
        self.imul(&Iv::point(s))
    }
    fn div_int(&self, k: u32) -> Iv {
        let k = f64::from(k.max(1));
        Iv::new(dn(self.lo / k), up(self.hi / k))
    }
    fn add_iv(&self, i: &Iv) -> Iv {
        self.iadd(i)
    }
    fn elem(&self, g: Func) -> Result<Iv, Fail> {
        Iv::elem(self, g)
    }
    fn recip(&self) -> Result<Iv, Fail> {
        Iv::recip(self)
    }
    fn range(&self) -> Iv {
        *self
    }
}

/// An affine form `c + Σⱼ gⱼ sⱼ + ε`, `sⱼ ∈ [−1, 1]`, `ε ∈ [lo, hi]`
/// (the error interval need not hold 0 nor be centred: a square's
/// quadratic part is never negative, and keeping that halves its cost).
#[derive(Clone, Debug, PartialEq)]
pub struct Af {
    /// The centre.
    pub c: f64,
    /// The coefficients of the symbols.
    pub g: Vec<f64>,
    /// The error interval's lower end.
    pub lo: f64,
    /// The error interval's upper end.
    pub hi: f64,
}

/// `[a, b] + [c, d]`, outward.
fn iv_add(a: (f64, f64), b: (f64, f64)) -> (f64, f64) {
    (dn(a.0 + b.0), up(a.1 + b.1))
}

/// `s · [a, b]`, outward.
fn iv_scale(s: f64, a: (f64, f64)) -> (f64, f64) {
    let (p, q) = (s * a.0, s * a.1);
    (dn(p.min(q)), up(p.max(q)))
}

impl Af {
    /// The constant `v` over `k` symbols.
    pub fn constant(v: f64, k: usize) -> Af {
        Af {
            c: v,
            g: vec![0.0; k],
            lo: 0.0,
            hi: 0.0,
        }
    }

    /// The form `c + Σ gⱼ sⱼ` exactly.
    pub fn exact(c: f64, g: Vec<f64>) -> Af {
        Af {
            c,
            g,
            lo: 0.0,
            hi: 0.0,
        }
    }

    /// An interval as a form over `k` symbols (its midpoint, the rest as error).
    pub fn of_iv(i: &Iv, k: usize) -> Af {
        let c = i.mid();
        Af {
            c,
            g: vec![0.0; k],
            lo: dn(i.lo - c).min(0.0),
            hi: up(i.hi - c).max(0.0),
        }
    }

    /// `Σⱼ |gⱼ|`, rounded up.
    fn spread(&self) -> f64 {
        sum_upper(self.g.iter().map(|v| v.abs()))
    }

    /// `Σⱼ |gⱼ| + max|ε|`, rounded up: `|x − c|` never exceeds it.
    pub fn radius(&self) -> f64 {
        sum_upper([self.spread(), self.lo.abs().max(self.hi.abs())])
    }

    /// The error interval.
    fn err(&self) -> (f64, f64) {
        (self.lo, self.hi)
    }

    /// The rounding-error bound of a freshly computed centre and coefficients.
    fn rounding_of(c: f64, g: &[f64]) -> f64 {
        sum_upper(g.iter().map(|v| rounding(*v)).chain([rounding(c)]))
    }

    /// A form with error `e` widened by `±r`.
    fn with_err(c: f64, g: Vec<f64>, e: (f64, f64), r: f64) -> Af {
        Af {
            c,
            g,
            lo: dn(e.0 - r),
            hi: up(e.1 + r),
        }
    }

    /// Combine coefficient-wise: `f(a, b)` for the centre and every
    /// coefficient (missing coefficients are 0), with the error `e`.
    fn zip(&self, o: &Af, f: impl Fn(f64, f64) -> f64, e: (f64, f64)) -> Af {
        let k = self.g.len().max(o.g.len());
        let at = |v: &[f64], j: usize| v.get(j).copied().unwrap_or(0.0);
        let c = f(self.c, o.c);
        let g: Vec<f64> = (0..k).map(|j| f(at(&self.g, j), at(&o.g, j))).collect();
        let r = Af::rounding_of(c, &g);
        Af::with_err(c, g, e, r)
    }

    /// `f + d·(x − c) + q` with `f ∋ φ(c)`, `d ∋ φ'(c)` and `q` the
    /// remainder's interval.
    fn linearised(&self, f: Iv, d: Iv, q: (f64, f64)) -> Af {
        let (fc, dm) = (f.mid(), d.mid());
        let g: Vec<f64> = self.g.iter().map(|v| dm * v).collect();
        // d·ε, φ(c) − fc, (d − dm)·(x − c), roundings
        let mut e = iv_add(iv_scale(dm, self.err()), (dn(f.lo - fc), up(f.hi - fc)));
        e = iv_add(e, q);
        let r = sum_upper([up(d.rad() * self.radius()), Af::rounding_of(0.0, &g)]);
        Af::with_err(fc, g, e, r)
    }

    /// `φ` by Taylor's formula of order 2 around the centre (`abs`: the
    /// mean-value form): `φ(c) + φ'(c)(x − c) + φ''(X)/2·[0, r²]`.
    fn second_order(&self, g: Func) -> Result<Af, Fail> {
        let r = self.radius();
        let x = Iv::new(dn(self.c - r), up(self.c + r));
        if !x.is_finite() {
            return Err(Fail::Overflow);
        }
        let at = Iv::point(self.c);
        let f = at.elem(g)?;
        if g == Func::Abs {
            let d = x.deriv(g)?;
            let delta = up(d.rad() * r);
            return Ok(self.linearised(f, Iv::point(d.mid()), (-delta, delta)));
        }
        let d = at.deriv(g)?;
        let dd = x.deriv2(g)?;
        let r2 = up(r * r);
        let q = iv_scale(0.5, (dd.lo.min(0.0) * r2, dd.hi.max(0.0) * r2));
        let q = (dn(q.0), up(q.1));
        if !(f.is_finite() && d.is_finite() && dd.is_finite()) {
            return Err(Fail::Overflow);
        }
        Ok(self.linearised(f, d, q))
    }
}

impl Iv {
    /// An enclosure of `φ''` over the interval (not for `abs`).
    pub fn deriv2(&self, g: Func) -> Result<Iv, Fail> {
        let two = Iv::point(2.0);
        Ok(match g {
            Func::Exp => self.elem(Func::Exp)?,
            Func::Log => {
                let r = self.recip()?;
                r.sqr().neg()
            }
            Func::Sqrt => {
                // −1 / (4 x^{3/2})
                if self.lo.is_nan() || self.lo <= 0.0 {
                    return Err(Fail::Domain(g));
                }
                let s = self.elem(Func::Sqrt)?;
                let den = s.imul(self).imul(&Iv::point(4.0));
                den.recip()?.neg()
            }
            Func::Tanh => {
                // −2 t (1 − t²)
                let t = self.elem(Func::Tanh)?;
                let one = Iv::point(1.0);
                two.imul(&t).imul(&one.isub(&t.sqr())).neg()
            }
            Func::Tan => {
                let t = self.elem(Func::Tan)?;
                let one = Iv::point(1.0);
                two.imul(&t).imul(&one.iadd(&t.sqr()))
            }
            Func::Sin => self.elem(Func::Sin)?.neg(),
            Func::Cos => self.elem(Func::Cos)?.neg(),
            Func::Abs => Iv::new(f64::NEG_INFINITY, f64::INFINITY),
        })
    }
}

impl Num for Af {
    fn cst(&self, v: f64) -> Af {
        Af::constant(v, self.g.len())
    }
    fn add(&self, o: &Af) -> Af {
        self.zip(o, |a, b| a + b, iv_add(self.err(), o.err()))
    }
    fn sub(&self, o: &Af) -> Af {
        self.zip(o, |a, b| a - b, iv_add(self.err(), (-o.hi, -o.lo)))
    }
    fn neg(&self) -> Af {
        Af {
            c: -self.c,
            g: self.g.iter().map(|v| -v).collect(),
            lo: -self.hi,
            hi: -self.lo,
        }
    }
    fn mul(&self, o: &Af) -> Af {
        let k = self.g.len().max(o.g.len());
        let at = |v: &[f64], j: usize| v.get(j).copied().unwrap_or(0.0);
        let c = self.c * o.c;
        let mut round = Vec::with_capacity(k + 2);
        // (Σ aⱼsⱼ)(Σ bⱼsⱼ): the diagonal aⱼbⱼsⱼ² has the sign of aⱼbⱼ, the
        // rest is within ±(Σ|a|·Σ|b| − Σ|aⱼbⱼ|)
        let (mut dlo, mut dhi, mut dabs) = (Vec::new(), Vec::new(), Vec::new());
        let g: Vec<f64> = (0..k)
            .map(|j| {
                let (aj, bj) = (at(&self.g, j), at(&o.g, j));
                let (t1, t2) = (self.c * bj, o.c * aj);
                round.push(up(2.0 * f64::EPSILON * (t1.abs() + t2.abs()) + 2.0 * TINY));
                let p = aj * bj;
                if p < 0.0 {
                    dlo.push(dn(p));
                } else if p > 0.0 {
                    dhi.push(up(p));
                }
                dabs.push(dn(p.abs()));
                t1 + t2
            })
            .collect();
        round.push(rounding(c));
        let (sa, sb) = (self.spread(), o.spread());
        let cross = up(up(sa * sb) - ravel_base::num::sum_lower(dabs)).max(0.0);
        let diag = (
            ravel_base::num::sum_lower(dlo.iter().copied()),
            sum_upper(dhi.iter().copied()),
        );
        // the error parts: c_a ε_b + c_b ε_a + (Σ a s) ε_b + (Σ b s) ε_a + ε_a ε_b
        let mut e = iv_add(iv_scale(self.c, o.err()), iv_scale(o.c, self.err()));
        e = iv_add(e, diag);
        let (ea, eb) = (self.lo.abs().max(self.hi.abs()), o.lo.abs().max(o.hi.abs()));
        let rest = sum_upper([cross, up(sa * eb), up(sb * ea), up(ea * eb)]);
        Af::with_err(c, g, e, sum_upper([rest, sum_upper(round)]))
    }
    fn scale(&self, s: f64) -> Af {
        let c = self.c * s;
        let g: Vec<f64> = self.g.iter().map(|v| v * s).collect();
        let r = Af::rounding_of(c, &g);
        Af::with_err(c, g, iv_scale(s, self.err()), r)
    }
    fn div_int(&self, k: u32) -> Af {
        let k = f64::from(k.max(1));
        let c = self.c / k;
        let g: Vec<f64> = self.g.iter().map(|v| v / k).collect();
        let r = Af::rounding_of(c, &g);
        Af::with_err(c, g, (dn(self.lo / k), up(self.hi / k)), r)
    }
    fn add_iv(&self, i: &Iv) -> Af {
        let c = self.c + i.mid();
        let e = iv_add(self.err(), (dn(i.lo - i.mid()), up(i.hi - i.mid())));
        Af::with_err(c, self.g.clone(), e, rounding(c))
    }
    fn elem(&self, g: Func) -> Result<Af, Fail> {
        self.second_order(g)
    }
    fn recip(&self) -> Result<Af, Fail> {
        let r = self.radius();
        let x = Iv::new(dn(self.c - r), up(self.c + r));
        let inv = x.recip()?;
        let at = Iv::point(self.c);
        let f = at.recip()?;
        let d = f.sqr().neg();
        // (1/x)'' = 2/x³
        let dd = Iv::point(2.0).imul(&inv.imul(&inv).imul(&inv));
        let r2 = up(r * r);
        let q = iv_scale(0.5, (dd.lo.min(0.0) * r2, dd.hi.max(0.0) * r2));
        let q = (dn(q.0), up(q.1));
        if !(f.is_finite() && d.is_finite() && dd.is_finite()) {
            return Err(Fail::Overflow);
        }
        Ok(self.linearised(f, d, q))
    }
    fn range(&self) -> Iv {
        let s = self.spread();
        if !(self.c.is_finite() && s.is_finite() && self.lo.is_finite() && self.hi.is_finite()) {
            return Iv::entire();
        }
        Iv::new(dn(dn(self.c - s) + self.lo), up(up(self.c + s) + self.hi))
    }
}
