//! Outward-rounded interval arithmetic on `f64`.
//!
//! Every operation returns an interval that contains the exact real result
//! for every pair of real operands in the operand intervals. `+ − × ÷` are
//! correctly rounded in IEEE 754, so one `next_down`/`next_up` of each end
//! is enough; the elementary functions (in [`super::elementary`]) widen the
//! platform `libm`'s results by a relative margin.
//!
//! The operators `+`, `−`, `×` never fail: a non-finite operand or an
//! overflow gives a non-finite interval (NaN propagates; no `min`/`max` is
//! ever allowed to drop a NaN), which [`Interval::checked`] turns into
//! [`DomainError::NotFinite`]. Everything that can fail for another reason
//! (division, roots, logarithms, poles) returns a `Result`.

use std::fmt;

/// Why a validated operation has no enclosure.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DomainError {
    /// A divisor (or a negative power's base) may be zero.
    DivisionByZero,
    /// The argument of `log` may be zero or negative.
    LogOfNonPositive,
    /// The argument of `sqrt` may be negative.
    SqrtOfNegative,
    /// The argument of `tan` may contain a pole.
    TanPole,
    /// The argument of `abs` may be zero where a smooth expansion is needed.
    AbsKink,
    /// A value is NaN or infinite (or overflowed).
    NotFinite,
}

impl DomainError {
    /// A human reason.
    pub fn as_str(self) -> &'static str {
        match self {
            DomainError::DivisionByZero => "a divisor may be zero",
            DomainError::LogOfNonPositive => "the argument of log may be zero or negative",
            DomainError::SqrtOfNegative => "the argument of sqrt may be negative",
            DomainError::TanPole => "the argument of tan may contain a pole",
            DomainError::AbsKink => {
                "the argument of abs may be zero, where the solution may not be smooth"
            }
            DomainError::NotFinite => "a value is not finite (NaN, infinite or overflowed)",
        }
    }
}

impl fmt::Display for DomainError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::error::Error for DomainError {}

/// A closed interval `[lo, hi]` of reals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    /// The lower end.
    pub lo: f64,
    /// The upper end.
    pub hi: f64,
}

/// The interval whose ends are NaN: the result of any operation on a
/// non-finite operand.
pub(crate) const NAN: Interval = Interval {
    lo: f64::NAN,
    hi: f64::NAN,
};

impl Interval {
    /// `[lo, hi]` as given (no check; see [`Interval::checked`]).
    pub fn new(lo: f64, hi: f64) -> Interval {
        Interval { lo, hi }
    }

    /// The single point `x`.
    pub fn point(x: f64) -> Interval {
        Interval { lo: x, hi: x }
    }

    /// `[−r, r]`.
    pub fn symmetric(r: f64) -> Interval {
        Interval { lo: -r, hi: r }
    }

    /// `[0, 0]`.
    pub const ZERO: Interval = Interval { lo: 0.0, hi: 0.0 };

    /// Both ends finite and `lo ≤ hi`.
    pub fn is_finite(self) -> bool {
        self.lo.is_finite() && self.hi.is_finite() && self.lo <= self.hi
    }

    /// `self` when it is a finite interval, otherwise
    /// [`DomainError::NotFinite`].
    pub fn checked(self) -> Result<Interval, DomainError> {
        if self.is_finite() {
            Ok(self)
        } else {
            Err(DomainError::NotFinite)
        }
    }

    /// The midpoint (rounded; the interval contains it). NaN for a
    /// non-finite interval.
    pub fn mid(self) -> f64 {
        if !self.is_finite() {
            return f64::NAN;
        }
        let m = 0.5 * self.lo + 0.5 * self.hi;
        m.clamp(self.lo, self.hi)
    }

    /// An upper bound of the radius: `max(hi − m, m − lo)` for `m =`
    /// [`Interval::mid`], rounded up. NaN for a non-finite interval.
    pub fn rad(self) -> f64 {
        let m = self.mid();
        (self.hi - m).max(m - self.lo).next_up()
    }

    /// `hi − lo`, rounded up.
    pub fn width(self) -> f64 {
        (self.hi - self.lo).next_up()
    }

    /// The largest absolute value in the interval.
    pub fn mag(self) -> f64 {
        if self.lo.is_nan() || self.hi.is_nan() {
            return f64::NAN;
        }
        self.lo.abs().max(self.hi.abs())
    }

    /// The smallest absolute value in the interval.
    pub fn mig(self) -> f64 {
        if self.lo.is_nan() || self.hi.is_nan() {
            return f64::NAN;
        }
        if self.lo <= 0.0 && self.hi >= 0.0 {
            0.0
        } else {
            self.lo.abs().min(self.hi.abs())
        }
    }

    /// Whether `x` lies in the interval.
    pub fn contains(self, x: f64) -> bool {
        self.lo <= x && x <= self.hi
    }

    /// Whether `0` lies in the interval.
    pub fn contains_zero(self) -> bool {
        self.contains(0.0)
    }

    /// Whether `other` lies in the interior of `self`.
    pub fn strictly_contains(self, other: Interval) -> bool {
        self.lo < other.lo && other.hi < self.hi
    }

    /// The smallest interval containing both (NaN if either is).
    pub fn hull(self, other: Interval) -> Interval {
        if !(self.is_finite() && other.is_finite()) {
            return NAN;
        }
        Interval {
            lo: self.lo.min(other.lo),
            hi: self.hi.max(other.hi),
        }
    }

    /// The intersection, `None` when empty or not finite.
    pub fn intersect(self, other: Interval) -> Option<Interval> {
        if !(self.is_finite() && other.is_finite()) {
            return None;
        }
        let r = Interval {
            lo: self.lo.max(other.lo),
            hi: self.hi.min(other.hi),
        };
        (r.lo <= r.hi).then_some(r)
    }

    /// `[lo, hi]` widened outward by one ulp at each end.
    pub fn widen_ulp(self) -> Interval {
        Interval {
            lo: self.lo.next_down(),
            hi: self.hi.next_up(),
        }
    }

    /// `x²` (non-negative).
    pub fn sqr(self) -> Interval {
        if !self.is_finite() {
            return NAN;
        }
        let (a, b) = (self.mig(), self.mag());
        Interval {
            lo: (a * a).next_down().max(0.0),
            hi: (b * b).next_up(),
        }
    }

    /// `1 / x`; an error when the interval may contain zero.
    pub fn recip(self) -> Result<Interval, DomainError> {
        let x = self.checked()?;
        if x.contains_zero() {
            return Err(DomainError::DivisionByZero);
        }
        Interval {
            lo: (1.0 / x.hi).next_down(),
            hi: (1.0 / x.lo).next_up(),
        }
        .checked()
    }

    /// `self / other`; an error when `other` may contain zero (fallible,
    /// hence not `std::ops::Div`).
    #[allow(clippy::should_implement_trait)]
    pub fn div(self, other: Interval) -> Result<Interval, DomainError> {
        let (a, b) = (self.checked()?, other.checked()?);
        if b.contains_zero() {
            return Err(DomainError::DivisionByZero);
        }
        let q = [a.lo / b.lo, a.lo / b.hi, a.hi / b.lo, a.hi / b.hi];
        min_max_outward(q).checked()
    }

    /// `|x|` (exact).
    pub fn abs(self) -> Interval {
        if !self.is_finite() {
            return NAN;
        }
        if self.lo >= 0.0 {
            self
        } else if self.hi <= 0.0 {
            Interval {
                lo: -self.hi,
                hi: -self.lo,
            }
        } else {
            Interval {
                lo: 0.0,
                hi: self.mag(),
            }
        }
    }

    /// `x·s` for a point `s`.
    pub fn scale(self, s: f64) -> Interval {
        self * Interval::point(s)
    }
}

/// `[min, max]` of four rounded results, each widened by one ulp; NaN if
/// any is NaN.
fn min_max_outward(v: [f64; 4]) -> Interval {
    if v.iter().any(|x| x.is_nan()) {
        return NAN;
    }
    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Interval {
        lo: lo.next_down(),
        hi: hi.next_up(),
    }
}

/// A sum or difference rounded to nearest, moved down by one ulp unless it
/// is exactly 0: with gradual underflow, `a ± b` rounds to ±0 only when it
/// *is* 0 (a non-zero sum of two doubles below the normal range is exactly
/// representable), so a zero result is exact. Keeping it lets a sum of
/// non-negative terms that may be 0 (`x² + y²` over a box around the
/// origin) stay non-negative, so `√` and `log` of it are not refused.
fn sum_down(s: f64) -> f64 {
    if s == 0.0 {
        0.0
    } else {
        s.next_down()
    }
}

/// [`sum_down`] upwards.
fn sum_up(s: f64) -> f64 {
    if s == 0.0 {
        0.0
    } else {
        s.next_up()
    }
}

impl std::ops::Add for Interval {
    type Output = Interval;
    fn add(self, o: Interval) -> Interval {
        Interval {
            lo: sum_down(self.lo + o.lo),
            hi: sum_up(self.hi + o.hi),
        }
    }
}

impl std::ops::Sub for Interval {
    type Output = Interval;
    fn sub(self, o: Interval) -> Interval {
        Interval {
            lo: sum_down(self.lo - o.hi),
            hi: sum_up(self.hi - o.lo),
        }
    }
}

impl std::ops::Neg for Interval {
    type Output = Interval;
    fn neg(self) -> Interval {
        Interval {
            lo: -self.hi,
            hi: -self.lo,
        }
    }
}

impl std::ops::Mul for Interval {
    type Output = Interval;
    fn mul(self, o: Interval) -> Interval {
        // a non-finite operand would make 0·∞ = NaN, which min/max drop
        if !(self.is_finite() && o.is_finite()) {
            return NAN;
        }
        min_max_outward([
            self.lo * o.lo,
            self.lo * o.hi,
            self.hi * o.lo,
            self.hi * o.hi,
        ])
    }
}

/// `x^n` for a non-negative point `x`, enclosed by binary powering with
/// outward rounding.
fn pow_nonneg(x: f64, n: u32) -> Interval {
    let mut result = Interval::point(1.0);
    let mut base = Interval::point(x);
    let mut e = n;
    while e > 0 {
        if e & 1 == 1 {
            result = result * base;
        }
        e >>= 1;
        if e > 0 {
            base = base * base;
        }
    }
    // the base is non-negative: so is every power
    Interval {
        lo: result.lo.max(0.0),
        hi: result.hi,
    }
}

impl Interval {
    /// `xⁿ` for a non-negative exponent (`x⁰ = 1`): the exact range, even
    /// powers non-negative.
    fn powu(self, n: u32) -> Interval {
        if !self.is_finite() {
            return NAN;
        }
        if n == 0 {
            return Interval::point(1.0);
        }
        if n % 2 == 1 {
            // odd: increasing; x^n = sign(x)·|x|^n
            let at = |x: f64| {
                let p = pow_nonneg(x.abs(), n);
                if x < 0.0 {
                    -p
                } else {
                    p
                }
            };
            return Interval {
                lo: at(self.lo).lo,
                hi: at(self.hi).hi,
            };
        }
        Interval {
            lo: pow_nonneg(self.mig(), n).lo,
            hi: pow_nonneg(self.mag(), n).hi,
        }
    }

    /// `xⁿ` for any integer `n` (negative: `1 / x⁻ⁿ`, an error when the
    /// interval may contain zero).
    pub fn powi(self, n: i32) -> Result<Interval, DomainError> {
        let x = self.checked()?;
        let p = x.powu(n.unsigned_abs()).checked()?;
        if n < 0 {
            p.recip()
        } else {
            Ok(p)
        }
    }
}
