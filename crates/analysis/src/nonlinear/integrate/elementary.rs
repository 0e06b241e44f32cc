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

/// An enclosure of the gradient of a tape's last node with respect to the
/// first `n` variables over the box `vars` (forward differentiation in
/// outward-rounded interval arithmetic). `None` where the tape is not
/// smooth on the box: a domain error, an overflow, `√` or `log` of an
/// argument that may reach 0 (an unbounded derivative), `abs` of one that
/// may change sign (a kink).
pub fn tape_gradient(
    tape: &ravel_base::expr::Tape,
    vars: &[Interval],
    n: usize,
) -> Option<Vec<Interval>> {
    use ravel_base::expr::{Func, Node};
    let zero = || vec![Interval::ZERO; n];
    let mut vals: Vec<Interval> = Vec::with_capacity(tape.nodes.len());
    let mut grads: Vec<Vec<Interval>> = Vec::with_capacity(tape.nodes.len());
    // `d·a` for an interval factor and a gradient
    let times =
        |f: Interval, a: &[Interval]| -> Vec<Interval> { a.iter().map(|&d| f * d).collect() };
    let plus = |a: &[Interval], b: &[Interval]| -> Vec<Interval> {
        a.iter().zip(b).map(|(&x, &y)| x + y).collect()
    };
    for node in &tape.nodes {
        let at = |id: u32| -> Option<(Interval, &Vec<Interval>)> {
            Some((*vals.get(id as usize)?, grads.get(id as usize)?))
        };
        let (v, d) = match *node {
            Node::Const(c) => (Interval::point(c), zero()),
            Node::Var(i) => {
                let mut d = zero();
                if let Some(e) = d.get_mut(i as usize) {
                    *e = Interval::point(1.0);
                }
                (*vars.get(i as usize)?, d)
            }
            Node::Neg(a) => {
                let (x, da) = at(a)?;
                (-x, da.iter().map(|&e| -e).collect())
            }
            Node::Add(a, b) => {
                let ((x, da), (y, db)) = (at(a)?, at(b)?);
                (x + y, plus(da, db))
            }
            Node::Sub(a, b) => {
                let ((x, da), (y, db)) = (at(a)?, at(b)?);
                let nb: Vec<Interval> = db.iter().map(|&e| -e).collect();
                (x - y, plus(da, &nb))
            }
            Node::Mul(a, b) => {
                let ((x, da), (y, db)) = (at(a)?, at(b)?);
                (x * y, plus(&times(y, da), &times(x, db)))
            }
            Node::Div(a, b) => {
                // (x / y)' = (x' − (x / y)·y') / y
                let ((x, da), (y, db)) = (at(a)?, at(b)?);
                let q = x.div(y).ok()?;
                let num: Vec<Interval> = da.iter().zip(db).map(|(&dx, &dy)| dx - q * dy).collect();
                let d = num
                    .iter()
                    .map(|&e| e.div(y))
                    .collect::<Result<Vec<_>, _>>()
                    .ok()?;
                (q, d)
            }
            Node::Powi(a, k) => {
                let (x, da) = at(a)?;
                let v = x.powi(k).ok()?;
                let f = if k == 0 {
                    Interval::ZERO
                } else {
                    x.powi(k.checked_sub(1)?).ok()? * Interval::point(f64::from(k))
                };
                (v, times(f, da))
            }
            Node::Func(func, a) => {
                let (x, da) = at(a)?;
                let v = x.apply(func).ok()?;
                let f = match func {
                    Func::Sin => x.cos().ok()?,
                    Func::Cos => -x.sin().ok()?,
                    Func::Tan => Interval::point(1.0) + v.sqr(),
                    Func::Exp => v,
                    Func::Log => x.recip().ok()?,
                    Func::Sqrt => {
                        if v.lo <= 0.0 {
                            return None;
                        }
                        (v * Interval::point(2.0)).recip().ok()?
                    }
                    Func::Tanh => Interval::point(1.0) - v.sqr(),
                    Func::Abs => {
                        if x.contains_zero() {
                            return None;
                        }
                        Interval::point(if x.lo > 0.0 { 1.0 } else { -1.0 })
                    }
                };
                (v, times(f, da))
            }
        };
        if !(v.checked().is_ok() && d.iter().all(|e| e.checked().is_ok())) {
            return None;
        }
        vals.push(v);
        grads.push(d);
    }
    grads.pop()
}

/// An enclosure of a tape's last node over an affine set
/// `{c + G s + r : s ∈ [−1, 1]ᵏ, r ∈ [r_lo, r_hi]}` whose box is `bbox`
/// (which must hold the set and `c`), by the mean value theorem:
/// `g(x) ∈ g(c) + J·(x − c)` with `J` the gradient's enclosure over the
/// box (convex, so it holds the segment from `c` to `x`). Writing
/// `J = m + [−ρ, ρ]`, `J·(x − c) ⊆ (mᵀG) s + mᵀr + Σᵢ ρᵢ |x − c|ᵢ`, so the
/// set's correlations (a speed that grows with the distance) are kept in
/// `mᵀG`, where the box alone would pair the largest speed with the
/// smallest distance. Intersected with the plain interval range. `None`
/// when neither exists (see [`tape_range`] and [`tape_gradient`]).
pub fn tape_range_affine(
    tape: &ravel_base::expr::Tape,
    form: &crate::sets::Affine,
    bbox: &[Interval],
) -> Option<Interval> {
    let plain = tape_range(tape, bbox).ok();
    let mean = mean_value(tape, form, bbox);
    match (plain, mean) {
        (Some(p), Some(m)) => Some(p.intersect(m).unwrap_or(p)),
        (p, m) => p.or(m),
    }
}

/// The mean value form of [`tape_range_affine`] alone.
fn mean_value(
    tape: &ravel_base::expr::Tape,
    form: &crate::sets::Affine,
    bbox: &[Interval],
) -> Option<Interval> {
    let n = form.c.len();
    if form.g.len() != n || form.r_lo.len() != n || form.r_hi.len() != n || bbox.len() != n {
        return None;
    }
    // every row over the same symbols (a ragged row's extra columns would
    // be left out of the linear part's bound)
    let k = form.g.first().map_or(0, Vec::len);
    if form.g.iter().any(|row| row.len() != k) {
        return None;
    }
    // the centre moved to the remainder's middle (any float will do: the
    // remainder is re-enclosed around it), and it must lie in the box, so
    // that the box holds every segment from it to a state
    let mut centre = Vec::with_capacity(n);
    let mut rem = Vec::with_capacity(n);
    for (((&c, &lo), &hi), b) in form.c.iter().zip(&form.r_lo).zip(&form.r_hi).zip(bbox) {
        let r = Interval::new(lo, hi);
        let c2 = c + r.mid();
        if !(c2.is_finite() && b.contains(c2)) {
            return None;
        }
        centre.push(c2);
        rem.push(
            (Interval::point(c) + r - Interval::point(c2))
                .checked()
                .ok()?,
        );
    }
    let jac = tape_gradient(tape, bbox, n)?;
    let centre_iv: Vec<Interval> = centre.iter().map(|&c| Interval::point(c)).collect();
    let mut acc = tape_range(tape, &centre_iv).ok()?;
    let mids: Vec<f64> = jac.iter().map(|j| j.mid()).collect();
    // (mᵀG)ⱼ, each enclosed, then Σⱼ |(mᵀG)ⱼ|·[−1, 1]
    let mut lin = 0.0f64;
    for col in 0..k {
        let mut a = Interval::ZERO;
        for (row, m) in form.g.iter().zip(&mids) {
            a = a + Interval::point(*m) * Interval::point(*row.get(col)?);
        }
        lin = (lin + a.mag()).next_up();
    }
    acc = acc + Interval::symmetric(lin);
    for i in 0..n {
        let (m, j, r) = (mids[i], jac[i], rem[i]);
        // mᵢ rᵢ, and ρᵢ |x − c|ᵢ with |x − c|ᵢ ≤ Σⱼ |Gᵢⱼ| + |rᵢ|
        acc = acc + Interval::point(m) * r;
        let rho = (j - Interval::point(m)).mag();
        let dev = form.g[i]
            .iter()
            .fold(Interval::ZERO, |s, v| s + Interval::point(v.abs()))
            + Interval::point(r.mag());
        acc = acc + Interval::symmetric((Interval::point(rho) * dev).hi);
    }
    acc.checked().ok()
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

    /// `√(x0² + x1²)`.
    fn norm_nodes() -> Vec<Node> {
        vec![
            Node::Var(0),
            Node::Powi(0, 2),
            Node::Var(1),
            Node::Powi(2, 2),
            Node::Add(1, 3),
            Node::Func(Func::Sqrt, 4),
        ]
    }

    /// Tapes over two variables: `√(x0² + x1²) − 0.5·x1`,
    /// `sin(x0)·x1 + exp(x1 / 3)`, `(x0 − 1) / (x1 + 3)`, `tanh(x0 − x1)`.
    fn smooth_tapes() -> Vec<Tape> {
        let mut first = norm_nodes();
        first.extend([Node::Const(0.5), Node::Mul(6, 2), Node::Sub(5, 7)]);
        vec![
            tape(&first),
            tape(&[
                Node::Var(0),
                Node::Func(Func::Sin, 0),
                Node::Var(1),
                Node::Mul(1, 2),
                Node::Const(3.0),
                Node::Div(2, 4),
                Node::Func(Func::Exp, 5),
                Node::Add(3, 6),
            ]),
            tape(&[
                Node::Var(0),
                Node::Const(1.0),
                Node::Sub(0, 1),
                Node::Var(1),
                Node::Const(3.0),
                Node::Add(3, 4),
                Node::Div(2, 5),
            ]),
            tape(&[
                Node::Var(0),
                Node::Var(1),
                Node::Sub(0, 1),
                Node::Func(Func::Tanh, 2),
            ]),
        ]
    }

    /// Random affine sets `c + G s + r` (3 symbols, thin and correlated
    /// or not) and sampled points of them: every value of every tape lies
    /// in its enclosure; on a perfectly correlated set the mean value form
    /// is far tighter than the box.
    #[test]
    fn the_mean_value_form_holds_every_sampled_point() {
        use crate::sets::Affine;
        let mut rng = ravel_base::rng::Rng::new(11);
        let mut vals = Vec::new();
        for case in 0..60 {
            let c = vec![rng.uniform(0.5, 2.0), rng.uniform(0.5, 2.0)];
            let g: Vec<Vec<f64>> = (0..2)
                .map(|_| (0..3).map(|_| rng.uniform(-0.3, 0.3)).collect())
                .collect();
            let (r_lo, r_hi): (Vec<f64>, Vec<f64>) = (0..2)
                .map(|_| {
                    let a = rng.uniform(-0.02, 0.02);
                    (a - 0.01 * f64::from(case % 3), a + 0.01)
                })
                .unzip();
            let form = Affine { c, g, r_lo, r_hi };
            let bbox: Vec<Interval> = (0..2)
                .map(|i| {
                    let spread: f64 = form.g[i].iter().map(|v| v.abs()).sum();
                    Interval::new(
                        form.c[i] - spread + form.r_lo[i] - 1e-9,
                        form.c[i] + spread + form.r_hi[i] + 1e-9,
                    )
                })
                .collect();
            for t in smooth_tapes() {
                let Some(r) = tape_range_affine(&t, &form, &bbox) else {
                    panic!("case {case}: no enclosure");
                };
                for _ in 0..200 {
                    // one point s of the symbols' cube for both states
                    let sym: Vec<f64> = (0..3).map(|_| rng.uniform(-1.0, 1.0)).collect();
                    let x: Vec<f64> = (0..2)
                        .map(|i| {
                            let lin: f64 = form.g[i].iter().zip(&sym).map(|(v, s)| v * s).sum();
                            form.c[i] + lin + rng.uniform(form.r_lo[i], form.r_hi[i])
                        })
                        .collect();
                    t.eval_into(&x, &mut vals);
                    let v = *vals.last().expect("value");
                    assert!(r.lo <= v && v <= r.hi, "case {case}: {v} ∉ {r:?}");
                }
            }
        }
        // x0 = x1 = 1 + 0.5 s: x0 − x1 is 0 where the box says [−1, 1];
        // x0² − x1² is 0, the mean value form [−1, 1] (the gradient
        // (2x0, −2x1) over the box), the box [−2, 2]
        let same = Affine {
            c: vec![1.0, 1.0],
            g: vec![vec![0.5], vec![0.5]],
            r_lo: vec![0.0, 0.0],
            r_hi: vec![0.0, 0.0],
        };
        let b = [Interval::new(0.5, 1.5), Interval::new(0.5, 1.5)];
        let diff = tape(&[Node::Var(0), Node::Var(1), Node::Sub(0, 1)]);
        let r = tape_range_affine(&diff, &same, &b).expect("enclosed");
        assert!(r.lo <= 0.0 && r.hi >= 0.0 && r.hi - r.lo < 1e-9, "{r:?}");
        let squares = tape(&[
            Node::Var(0),
            Node::Powi(0, 2),
            Node::Var(1),
            Node::Powi(2, 2),
            Node::Sub(1, 3),
        ]);
        let r = tape_range_affine(&squares, &same, &b).expect("enclosed");
        assert!(
            r.lo < -0.99 && r.lo > -1.01 && r.hi > 0.99 && r.hi < 1.01,
            "{r:?}"
        );
        // a centre outside the box, or a kink of abs in it: the box alone
        let abs = tape(&[Node::Var(0), Node::Func(Func::Abs, 0)]);
        assert!(tape_gradient(&abs, &[Interval::new(-1.0, 1.0)], 1).is_none());
        let far = Affine {
            c: vec![5.0, 5.0],
            ..same
        };
        let r = tape_range_affine(&diff, &far, &b).expect("the box's range");
        assert!(r.lo < -0.4 && r.hi > 0.4);
        // rows over different numbers of symbols: no mean value form
        let ragged = Affine {
            c: vec![1.0, 1.0],
            g: vec![vec![0.5], vec![0.5, 0.1]],
            r_lo: vec![0.0, 0.0],
            r_hi: vec![0.0, 0.0],
        };
        assert!(mean_value(&squares, &ragged, &b).is_none());
    }

    #[test]
    fn a_norm_around_the_origin_is_defined() {
        // √(x0² + x1²) over a box around 0: the sum's lower end is an exact
        // 0 (not moved below it by outward rounding), so √ is defined there
        let norm = tape(&norm_nodes());
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
