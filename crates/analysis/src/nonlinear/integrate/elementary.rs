//! Elementary functions of an [`Interval`], enclosing the true range.
//!
//! # What is assumed of `libm`
//!
//! The platform's `sin`, `cos`, `tan`, `exp`, `ln` and `tanh` are not
//! correctly rounded, but every maintained `libm` (glibc, musl, the LLVM and
//! Apple ones) is accurate to within one or two ulps over the whole
//! domain. Each result is widened outward by four ulps relative
//! (`4·ε·|v|`, `ε = 2⁻⁵²`) plus the smallest subnormal before it becomes an
//! end of an enclosure: this is the one assumption on `libm`, and it leaves a
//! factor of two over the worst documented error. `sqrt` is correctly
//! rounded by IEEE 754 and is widened the same way anyway.
//!
//! Monotone functions are evaluated at the ends; `sin` and `cos` also take
//! the extreme values ±1 whenever an extremum `(k + m/2)·π` may lie in the
//! argument (decided with an outward enclosure of π, so a doubtful case is
//! counted in); `tan` is an error whenever a pole `(k + ½)·π` may lie in the
//! argument. Arguments beyond `2²⁰` in magnitude give `[−1, 1]` for `sin`
//! and `cos` and a pole error for `tan`.

use super::interval::{DomainError, Interval};
use ravel_base::num::ETA;

/// The relative widening of a `libm` result (see the module doc).
const LIBM_REL: f64 = 4.0 * f64::EPSILON;

/// `v` moved down by the `libm` allowance.
pub(crate) fn libm_down(v: f64) -> f64 {
    (v - (v.abs() * LIBM_REL + ETA)).next_down()
}

/// `v` moved up by the `libm` allowance.
pub(crate) fn libm_up(v: f64) -> f64 {
    (v + (v.abs() * LIBM_REL + ETA)).next_up()
}

/// The largest argument whose period analysis is attempted.
const TRIG_LIMIT: f64 = 1_048_576.0;

/// An enclosure of π: the double nearest π is below it.
const PI: Interval = Interval {
    lo: std::f64::consts::PI,
    hi: 3.141_592_653_589_793_6,
};

/// Whether some point `(q + period·k)·π` for an integer `k` may lie in `x`
/// (a doubtful case answers yes): `q ∈ {0, ½, 1, 1½}`, `period` 2 for the
/// extrema of `sin` and `cos`, 1 for the poles of `tan`.
fn may_contain(x: Interval, q: f64, period: f64) -> bool {
    // k ≈ (x/π − q) / period; check every integer near the range
    let k_lo = ((x.lo / PI.hi - q) / period).floor() - 1.0;
    let k_hi = ((x.hi / PI.lo - q) / period).ceil() + 1.0;
    if !(k_lo.is_finite() && k_hi.is_finite()) || k_hi - k_lo > 8.0 {
        return true;
    }
    let mut k = k_lo;
    while k <= k_hi {
        // (q + period·k) is exact: small integers and halves
        let p = Interval::point(q + period * k) * PI;
        if p.lo <= x.hi && x.lo <= p.hi {
            return true;
        }
        k += 1.0;
    }
    false
}

/// The range of `sin` or (`cosine`) `cos`: the hull of the values at the
/// ends, and ±1 where an extremum may lie inside.
fn trig(x: Interval, cosine: bool) -> Result<Interval, DomainError> {
    let x = x.checked()?;
    if x.mag() > TRIG_LIMIT || x.hi - x.lo >= 6.0 {
        return Ok(Interval::new(-1.0, 1.0));
    }
    let f = |v: f64| if cosine { v.cos() } else { v.sin() };
    let (a, b) = (f(x.lo), f(x.hi));
    let mut r = Interval::new(libm_down(a.min(b)), libm_up(a.max(b)));
    // maxima of sin at π/2 + 2kπ, minima at 3π/2 + 2kπ; of cos at 2kπ, π + 2kπ
    let (q_max, q_min) = if cosine { (0.0, 1.0) } else { (0.5, 1.5) };
    if may_contain(x, q_max, 2.0) {
        r.hi = 1.0;
    }
    if may_contain(x, q_min, 2.0) {
        r.lo = -1.0;
    }
    Ok(Interval::new(r.lo.max(-1.0), r.hi.min(1.0)))
}

impl Interval {
    /// `sin x`.
    pub fn sin(self) -> Result<Interval, DomainError> {
        trig(self, false)
    }

    /// `cos x`.
    pub fn cos(self) -> Result<Interval, DomainError> {
        trig(self, true)
    }

    /// `tan x`; an error when a pole may lie in the interval.
    pub fn tan(self) -> Result<Interval, DomainError> {
        let x = self.checked()?;
        if x.mag() > TRIG_LIMIT || x.hi - x.lo >= 3.0 || may_contain(x, 0.5, 1.0) {
            return Err(DomainError::TanPole);
        }
        Interval::new(libm_down(x.lo.tan()), libm_up(x.hi.tan())).checked()
    }

    /// `exp x` (non-negative; an overflow is an error).
    pub fn exp(self) -> Result<Interval, DomainError> {
        let x = self.checked()?;
        Interval::new(libm_down(x.lo.exp()).max(0.0), libm_up(x.hi.exp())).checked()
    }

    /// `ln x`; an error when the interval may contain zero or negatives.
    pub fn log(self) -> Result<Interval, DomainError> {
        let x = self.checked()?;
        if x.lo <= 0.0 {
            return Err(DomainError::LogOfNonPositive);
        }
        Interval::new(libm_down(x.lo.ln()), libm_up(x.hi.ln())).checked()
    }

    /// `√x`; an error when the interval may contain negatives.
    pub fn sqrt(self) -> Result<Interval, DomainError> {
        let x = self.checked()?;
        if x.lo < 0.0 {
            return Err(DomainError::SqrtOfNegative);
        }
        Interval::new(libm_down(x.lo.sqrt()).max(0.0), libm_up(x.hi.sqrt())).checked()
    }

    /// `tanh x` (within `[−1, 1]`).
    pub fn tanh(self) -> Result<Interval, DomainError> {
        let x = self.checked()?;
        let lo = libm_down(x.lo.tanh()).max(-1.0);
        let hi = libm_up(x.hi.tanh()).min(1.0);
        Interval::new(lo, hi).checked()
    }

    /// `f(x)` for a tape function (`abs` exact).
    pub fn apply(self, f: ravel_base::expr::Func) -> Result<Interval, DomainError> {
        use ravel_base::expr::Func;
        match f {
            Func::Sin => self.sin(),
            Func::Cos => self.cos(),
            Func::Tan => self.tan(),
            Func::Exp => self.exp(),
            Func::Log => self.log(),
            Func::Sqrt => self.sqrt(),
            Func::Tanh => self.tanh(),
            Func::Abs => self.abs().checked(),
        }
    }
}

/// An enclosure of the range of a tape's last node over the box of
/// variables `vars` (every node in outward-rounded interval arithmetic):
/// how a set's constraint `g(x) ≤ 0` is bounded over a reachable set. A
/// node that may be undefined on the box (a divisor that may be 0, `log` or
/// `sqrt` outside its domain, a pole of `tan`) or that overflows is an
/// error, never a bound; so is an empty tape or a malformed one.
pub fn tape_range(
    tape: &ravel_base::expr::Tape,
    vars: &[Interval],
) -> Result<Interval, DomainError> {
    use ravel_base::expr::Node;
    let mut values: Vec<Interval> = Vec::with_capacity(tape.nodes.len());
    let at = |values: &[Interval], id: u32| {
        values
            .get(id as usize)
            .copied()
            .ok_or(DomainError::NotFinite)
    };
    for node in &tape.nodes {
        let v = match *node {
            Node::Const(c) => Interval::point(c),
            Node::Var(i) => vars
                .get(i as usize)
                .copied()
                .ok_or(DomainError::NotFinite)?,
            Node::Neg(a) => -at(&values, a)?,
            Node::Add(a, b) => at(&values, a)? + at(&values, b)?,
            Node::Sub(a, b) => at(&values, a)? - at(&values, b)?,
            Node::Mul(a, b) => at(&values, a)? * at(&values, b)?,
            Node::Div(a, b) => at(&values, a)?.div(at(&values, b)?)?,
            Node::Powi(a, n) => at(&values, a)?.powi(n)?,
            Node::Func(f, a) => at(&values, a)?.apply(f)?,
        };
        values.push(v.checked()?);
    }
    values.last().copied().ok_or(DomainError::NotFinite)
}

#[cfg(test)]
mod tape_range_tests {
    use super::*;
    use ravel_base::expr::{Func, Node, Tape};

    fn tape(nodes: &[Node]) -> Tape {
        let mut t = Tape::new();
        for n in nodes {
            t.push(*n);
        }
        t
    }

    #[test]
    fn a_disc_is_bounded_outward_and_contains_every_sampled_value() {
        // g = (x0 − 1)² + (x1 − 1)² − 0.25
        let t = tape(&[
            Node::Var(0),
            Node::Const(1.0),
            Node::Sub(0, 1),
            Node::Powi(2, 2),
            Node::Var(1),
            Node::Sub(4, 1),
            Node::Powi(5, 2),
            Node::Add(3, 6),
            Node::Const(0.25),
            Node::Sub(7, 8),
        ]);
        let b = [Interval::new(0.1, 0.3), Interval::new(-0.2, 0.4)];
        let r = tape_range(&t, &b).expect("defined");
        // exact range: (0.7² + 0.6²) − 0.25 = 0.6 … (0.9² + 1.2²) − 0.25 = 2.0
        assert!(
            r.lo <= 0.6 && r.hi >= 2.0 && r.lo > 0.59 && r.hi < 2.01,
            "{r:?}"
        );
        let mut vals = Vec::new();
        for i in 0..=20 {
            for j in 0..=20 {
                let x = [0.1 + 0.01 * f64::from(i), -0.2 + 0.03 * f64::from(j)];
                t.eval_into(&x, &mut vals);
                let g = *vals.last().expect("value");
                assert!(r.lo <= g && g <= r.hi);
            }
        }
    }

    #[test]
    fn a_norm_around_the_origin_is_defined() {
        // √(x0² + x1²) over a box around 0: the sum's lower end is an exact
        // 0 (not moved below it by outward rounding), so √ is defined there
        let norm = tape(&[
            Node::Var(0),
            Node::Powi(0, 2),
            Node::Var(1),
            Node::Powi(2, 2),
            Node::Add(1, 3),
            Node::Func(Func::Sqrt, 4),
        ]);
        let b = [Interval::new(-0.14, 0.14), Interval::new(-0.14, 0.14)];
        let r = tape_range(&norm, &b).expect("defined");
        assert!(
            r.lo == 0.0 && r.hi >= 0.14 * 2f64.sqrt() && r.hi < 0.1981,
            "{r:?}"
        );
        // a difference that cancels exactly is 0; one that does not is moved
        let d = Interval::point(0.3) - Interval::point(0.3);
        assert!(d.lo == 0.0 && d.hi == 0.0);
        let e = Interval::point(0.3) - Interval::point(0.1);
        assert!(e.lo < 0.3 - 0.1 && e.hi > 0.3 - 0.1);
    }

    #[test]
    fn domain_errors_are_not_bounds() {
        // 1 / x0 over a box containing 0; log(x0) and sqrt(x0) over negatives
        let div = tape(&[Node::Const(1.0), Node::Var(0), Node::Div(0, 1)]);
        let b = [Interval::new(-1.0, 1.0)];
        assert_eq!(tape_range(&div, &b), Err(DomainError::DivisionByZero));
        let log = tape(&[Node::Var(0), Node::Func(Func::Log, 0)]);
        assert_eq!(tape_range(&log, &b), Err(DomainError::LogOfNonPositive));
        let sqrt = tape(&[Node::Var(0), Node::Func(Func::Sqrt, 0)]);
        assert_eq!(tape_range(&sqrt, &b), Err(DomainError::SqrtOfNegative));
        // an overflow, a missing variable and an empty tape are errors too
        let big = tape(&[Node::Var(0), Node::Func(Func::Exp, 0)]);
        assert!(tape_range(&big, &[Interval::new(0.0, 1e6)]).is_err());
        assert!(tape_range(&big, &[]).is_err());
        assert!(tape_range(&Tape::new(), &b).is_err());
        let nan = tape(&[Node::Var(0)]);
        assert!(tape_range(&nan, &[Interval::new(f64::NAN, 1.0)]).is_err());
    }
}
