//! Functions of one Taylor model: a first-order expansion around the
//! constant part with a Lagrange remainder.
//!
//! For `T = c + δ` (`δ = g·z + ρ`, `δ ∈ D = [−Σ|gᵢ|, Σ|gᵢ|] + r`) and `f`
//! twice differentiable on the range `I` of `T`,
//!
//! `f(T) = f(c) + f'(c)·δ + ½ f''(ξ)·δ²`, `ξ ∈ I`,
//!
//! so with `s` the midpoint of an enclosure `F₁ ∋ f'(c)` and `F₂ ⊇ f''(I)`:
//! `f(T) ∈ f(c) + s·g·z + [s·r + (F₁ − s)·D + ½·F₂·D²]`. Domain errors come
//! from evaluating `F₂` over `I` (a pole, a logarithm of a non-positive
//! number, a division by a range containing zero).

use super::interval::{DomainError, Interval};
use super::tm::{Absorb, Lin, Tm};
use ravel_base::expr::Func;

fn pt(x: f64) -> Interval {
    Interval::point(x)
}

impl Tm {
    /// `f(T)` from `F₀ ∋ f(c)`, `F₁ ∋ f'(c)` and `F₂ ⊇ f''(range)`.
    fn expand(&self, f0: Interval, f1: Interval, f2: Interval) -> Result<Tm, DomainError> {
        let (f0, f1, f2) = (f0.checked()?, f1.checked()?, f2.checked()?);
        let d = self.deviation().checked()?;
        let s = f1.mid();
        let mut ab = Absorb::new();
        let c = ab.take(f0);
        let lin = Lin::scale(&self.g, s);
        let rem = pt(s) * self.r
            + (f1 - pt(s)) * d
            + f2 * pt(0.5) * d.sqr()
            + ab.interval()
            + Interval::symmetric(lin.err);
        Tm {
            c,
            g: lin.g,
            r: rem,
        }
        .checked()
    }

    /// The range, checked finite.
    fn checked_range(&self) -> Result<Interval, DomainError> {
        self.range().checked()
    }

    /// `sin T`.
    pub fn sin(&self) -> Result<Tm, DomainError> {
        let (c, i) = (pt(self.c), self.checked_range()?);
        self.expand(c.sin()?, c.cos()?, -i.sin()?)
    }

    /// `cos T`.
    pub fn cos(&self) -> Result<Tm, DomainError> {
        let (c, i) = (pt(self.c), self.checked_range()?);
        self.expand(c.cos()?, -c.sin()?, -i.cos()?)
    }

    /// `tan T` (an error when a pole may lie in the range).
    pub fn tan(&self) -> Result<Tm, DomainError> {
        let (c, i) = (pt(self.c), self.checked_range()?);
        let (tc, ti) = (c.tan()?, i.tan()?);
        let one = pt(1.0);
        self.expand(tc, one + tc.sqr(), pt(2.0) * ti * (one + ti.sqr()))
    }

    /// `exp T`.
    pub fn exp(&self) -> Result<Tm, DomainError> {
        let (c, i) = (pt(self.c), self.checked_range()?);
        let ec = c.exp()?;
        self.expand(ec, ec, i.exp()?)
    }

    /// `ln T` (an error when the range may reach zero or below).
    pub fn log(&self) -> Result<Tm, DomainError> {
        let (c, i) = (pt(self.c), self.checked_range()?);
        if i.lo <= 0.0 {
            return Err(DomainError::LogOfNonPositive);
        }
        self.expand(c.log()?, c.recip()?, -(i.sqr().recip()?))
    }

    /// `√T` (an error when the range may be negative; a range touching
    /// zero, where `√` is not differentiable, gives the interval hull).
    pub fn sqrt(&self) -> Result<Tm, DomainError> {
        let (c, i) = (pt(self.c), self.checked_range()?);
        if i.lo < 0.0 {
            return Err(DomainError::SqrtOfNegative);
        }
        if i.lo == 0.0 {
            return Tm::from_interval(i.sqrt()?, self.symbols()).checked();
        }
        let sc = c.sqrt()?;
        let f1 = (pt(2.0) * sc).recip()?;
        // f'' = −1 / (4 x √x)
        let f2 = -((pt(4.0) * i * i.sqrt()?).recip()?);
        self.expand(sc, f1, f2)
    }

    /// `tanh T`.
    pub fn tanh(&self) -> Result<Tm, DomainError> {
        let (c, i) = (pt(self.c), self.checked_range()?);
        let (tc, ti) = (c.tanh()?, i.tanh()?);
        let one = pt(1.0);
        self.expand(tc, one - tc.sqr(), pt(-2.0) * ti * (one - ti.sqr()))
    }

    /// `|T|`: `±T` when the range keeps one sign, otherwise the hull of
    /// `|range|` (no dependence on the symbols).
    pub fn abs(&self) -> Result<Tm, DomainError> {
        let i = self.checked_range()?;
        if i.lo >= 0.0 {
            Ok(self.clone())
        } else if i.hi <= 0.0 {
            Ok(self.neg())
        } else {
            Tm::from_interval(i.abs(), self.symbols()).checked()
        }
    }

    /// `1 / T` (an error when the range may contain zero).
    pub fn recip(&self) -> Result<Tm, DomainError> {
        let (c, i) = (pt(self.c), self.checked_range()?);
        if i.contains_zero() {
            return Err(DomainError::DivisionByZero);
        }
        let rc = c.recip()?;
        self.expand(rc, -rc.sqr(), pt(2.0) * i.powi(-3)?)
    }

    /// `self / o` (an error when the range of `o` may contain zero).
    pub fn div(&self, o: &Tm) -> Result<Tm, DomainError> {
        self.mul(&o.recip()?)
    }

    /// `Tⁿ` for an integer `n` (negative: the range must exclude zero).
    pub fn powi(&self, n: i32) -> Result<Tm, DomainError> {
        match n {
            0 => return Tm::constant(1.0, self.symbols()).checked(),
            1 => return self.clone().checked(),
            _ => {}
        }
        // |n| beyond 2³⁰ only ever overflows or underflows: refuse it
        if n.unsigned_abs() > 1 << 30 {
            return Err(DomainError::NotFinite);
        }
        let (c, i) = (pt(self.c), self.checked_range()?);
        if n < 0 && i.contains_zero() {
            return Err(DomainError::DivisionByZero);
        }
        let nf = pt(f64::from(n));
        let f0 = c.powi(n)?;
        let f1 = nf * c.powi(n - 1)?;
        let f2 = nf * pt(f64::from(n - 1)) * i.powi(n - 2)?;
        self.expand(f0, f1, f2)
    }

    /// `f(T)` for a tape function.
    pub fn apply(&self, f: Func) -> Result<Tm, DomainError> {
        match f {
            Func::Sin => self.sin(),
            Func::Cos => self.cos(),
            Func::Tan => self.tan(),
            Func::Exp => self.exp(),
            Func::Log => self.log(),
            Func::Sqrt => self.sqrt(),
            Func::Tanh => self.tanh(),
            Func::Abs => self.abs(),
        }
    }
}
