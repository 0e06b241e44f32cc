//! The checker's own interval evaluation of a set's constraint `g(x) ≤ 0`
//! (a tape of nodes as the certificate records it) over a claimed box.
//!
//! Nothing here comes from the analysis: `+ − × ÷` and integer powers are
//! rounded outward by one ulp at each end (IEEE 754 rounds them correctly
//! to nearest); `exp`, `log`, `sqrt`, `tanh`, `sin`, `cos` and `tan` take
//! the platform `libm`'s values widened by four ulps relative plus the
//! smallest subnormal (every maintained `libm` is within two ulps), `sin`
//! and `cos` also take ±1 wherever an extremum may lie in the argument and
//! `tan` has no enclosure when a pole may. A value that may be undefined on
//! the box (a divisor that may be 0, `log` or `sqrt` outside its domain, a
//! pole) or that is not finite gives no enclosure ([`None`]): the claim it
//! would support is not established.

use ravel_base::expr::{Func, Node, Tape};
use ravel_base::num::ETA;
use serde_json::Value;

/// A closed interval.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Iv {
    /// Lower end.
    pub lo: f64,
    /// Upper end.
    pub hi: f64,
}

/// `[lo, hi]` when both are finite and ordered.
fn iv(lo: f64, hi: f64) -> Option<Iv> {
    (lo.is_finite() && hi.is_finite() && lo <= hi).then_some(Iv { lo, hi })
}

/// `lo` and `hi` moved out by one ulp.
fn out(lo: f64, hi: f64) -> Option<Iv> {
    iv(lo.next_down(), hi.next_up())
}

/// A sum's (or difference's) ends rounded to nearest, moved out by one ulp
/// unless exactly 0: with gradual underflow a sum of two doubles rounds to
/// ±0 only when it is exactly 0, so a zero end is exact (and `x² + y²`
/// over a box around the origin stays non-negative, inside `√`'s domain).
fn out_sum(lo: f64, hi: f64) -> Option<Iv> {
    let lo = if lo == 0.0 { 0.0 } else { lo.next_down() };
    let hi = if hi == 0.0 { 0.0 } else { hi.next_up() };
    iv(lo, hi)
}

/// The relative widening of a `libm` value.
const LIBM_REL: f64 = 4.0 * f64::EPSILON;

fn down(v: f64) -> f64 {
    (v - (v.abs() * LIBM_REL + ETA)).next_down()
}

fn up(v: f64) -> f64 {
    (v + (v.abs() * LIBM_REL + ETA)).next_up()
}

/// An enclosure of π.
const PI_LO: f64 = std::f64::consts::PI;
const PI_HI: f64 = 3.141_592_653_589_793_6;

/// Whether `(q + period·k)·π` may lie in `x` for an integer `k` (a doubtful
/// case answers yes).
fn may_contain(x: Iv, q: f64, period: f64) -> bool {
    let k_lo = ((x.lo / PI_HI - q) / period).floor() - 1.0;
    let k_hi = ((x.hi / PI_LO - q) / period).ceil() + 1.0;
    if !(k_lo.is_finite() && k_hi.is_finite()) || k_hi - k_lo > 8.0 {
        return true;
    }
    let mut k = k_lo;
    while k <= k_hi {
        // c = q + period·k is exact (small integers and halves); c·π enclosed
        let c = q + period * k;
        let (a, b) = (c * PI_LO, c * PI_HI);
        let (p_lo, p_hi) = (a.min(b).next_down(), a.max(b).next_up());
        if p_lo <= x.hi && x.lo <= p_hi {
            return true;
        }
        k += 1.0;
    }
    false
}

/// The range of `sin` (or `cos`).
fn trig(x: Iv, cosine: bool) -> Option<Iv> {
    if x.lo.abs().max(x.hi.abs()) > 1_048_576.0 || x.hi - x.lo >= 6.0 {
        return iv(-1.0, 1.0);
    }
    let f = |v: f64| if cosine { v.cos() } else { v.sin() };
    let (a, b) = (f(x.lo), f(x.hi));
    let (mut lo, mut hi) = (down(a.min(b)), up(a.max(b)));
    let (q_max, q_min) = if cosine { (0.0, 1.0) } else { (0.5, 1.5) };
    if may_contain(x, q_max, 2.0) {
        hi = 1.0;
    }
    if may_contain(x, q_min, 2.0) {
        lo = -1.0;
    }
    iv(lo.max(-1.0), hi.min(1.0))
}

fn mul(a: Iv, b: Iv) -> Option<Iv> {
    let p = [a.lo * b.lo, a.lo * b.hi, a.hi * b.lo, a.hi * b.hi];
    if p.iter().any(|v| v.is_nan()) {
        return None;
    }
    let lo = p.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = p.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    out(lo, hi)
}

fn div(a: Iv, b: Iv) -> Option<Iv> {
    if b.lo <= 0.0 && b.hi >= 0.0 {
        return None;
    }
    let q = [a.lo / b.lo, a.lo / b.hi, a.hi / b.lo, a.hi / b.hi];
    if q.iter().any(|v| v.is_nan()) {
        return None;
    }
    let lo = q.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = q.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    out(lo, hi)
}

/// `xⁿ` by repeated outward multiplication (even powers from `|x|`).
fn powi(x: Iv, n: i32) -> Option<Iv> {
    let k = n.unsigned_abs();
    if k > 4096 {
        return None;
    }
    let base = if k % 2 == 0 {
        let (l, h) = (x.lo.abs(), x.hi.abs());
        let lo = if x.lo <= 0.0 && x.hi >= 0.0 {
            0.0
        } else {
            l.min(h)
        };
        Iv { lo, hi: l.max(h) }
    } else {
        x
    };
    let mut p = Iv { lo: 1.0, hi: 1.0 };
    for _ in 0..k {
        p = mul(p, base)?;
    }
    if k % 2 == 0 {
        p.lo = p.lo.max(0.0);
    }
    if n < 0 {
        div(Iv { lo: 1.0, hi: 1.0 }, p)
    } else {
        Some(p)
    }
}

fn apply(f: Func, x: Iv) -> Option<Iv> {
    match f {
        Func::Sin => trig(x, false),
        Func::Cos => trig(x, true),
        Func::Tan => {
            if x.lo.abs().max(x.hi.abs()) > 1_048_576.0
                || x.hi - x.lo >= 3.0
                || may_contain(x, 0.5, 1.0)
            {
                return None;
            }
            iv(down(x.lo.tan()), up(x.hi.tan()))
        }
        Func::Exp => iv(down(x.lo.exp()).max(0.0), up(x.hi.exp())),
        Func::Log => {
            if x.lo <= 0.0 {
                return None;
            }
            iv(down(x.lo.ln()), up(x.hi.ln()))
        }
        Func::Sqrt => {
            if x.lo < 0.0 {
                return None;
            }
            iv(down(x.lo.sqrt()).max(0.0), up(x.hi.sqrt()))
        }
        Func::Tanh => iv(down(x.lo.tanh()).max(-1.0), up(x.hi.tanh()).min(1.0)),
        Func::Abs => {
            let (l, h) = (x.lo.abs(), x.hi.abs());
            let lo = if x.lo <= 0.0 && x.hi >= 0.0 {
                0.0
            } else {
                l.min(h)
            };
            iv(lo, l.max(h))
        }
    }
}

/// An enclosure of the tape's last node over the box `lo … hi` (one
/// interval per variable), or `None` where it has none (see the module
/// doc).
pub fn range(tape: &Tape, lo: &[f64], hi: &[f64]) -> Option<Iv> {
    let mut values: Vec<Iv> = Vec::with_capacity(tape.nodes.len());
    for node in &tape.nodes {
        let at = |id: u32| values.get(id as usize).copied();
        let v = match *node {
            Node::Const(c) => iv(c, c)?,
            Node::Var(i) => iv(*lo.get(i as usize)?, *hi.get(i as usize)?)?,
            Node::Neg(a) => {
                let a = at(a)?;
                iv(-a.hi, -a.lo)?
            }
            Node::Add(a, b) => {
                let (a, b) = (at(a)?, at(b)?);
                out_sum(a.lo + b.lo, a.hi + b.hi)?
            }
            Node::Sub(a, b) => {
                let (a, b) = (at(a)?, at(b)?);
                out_sum(a.lo - b.hi, a.hi - b.lo)?
            }
            Node::Mul(a, b) => mul(at(a)?, at(b)?)?,
            Node::Div(a, b) => div(at(a)?, at(b)?)?,
            Node::Powi(a, n) => powi(at(a)?, n)?,
            Node::Func(f, a) => apply(f, at(a)?)?,
        };
        values.push(v);
    }
    values.last().copied()
}

/// A tape as a certificate records it (see the writer's `tape_json`):
/// at most [`ravel_base::limits::MAX_EXPR_NODES`] nodes, every operand an
/// earlier node and every variable below `vars`.
pub fn read(v: &Value, vars: usize) -> Result<Tape, String> {
    let nodes = v.as_array().ok_or("a tape must be an array of nodes")?;
    if nodes.is_empty() || nodes.len() > ravel_base::limits::MAX_EXPR_NODES {
        return Err(format!(
            "a tape of {} nodes (1 to {} allowed)",
            nodes.len(),
            ravel_base::limits::MAX_EXPR_NODES
        ));
    }
    let mut tape = Tape::new();
    for (i, n) in nodes.iter().enumerate() {
        let parts = n.as_array().ok_or("a tape node must be an array")?;
        let name = parts
            .first()
            .and_then(Value::as_str)
            .ok_or("a tape node starts with its operation's name")?;
        let id = |k: usize| -> Result<u32, String> {
            parts
                .get(k)
                .and_then(Value::as_u64)
                .and_then(|x| u32::try_from(x).ok())
                .filter(|x| (*x as usize) < i)
                .ok_or_else(|| format!("tape node {i}: operand {k} must be an earlier node"))
        };
        let node = match name {
            "const" => Node::Const(
                parts
                    .get(1)
                    .and_then(Value::as_f64)
                    .ok_or_else(|| format!("tape node {i}: a constant must be a number"))?,
            ),
            "var" => Node::Var(
                parts
                    .get(1)
                    .and_then(Value::as_u64)
                    .and_then(|x| u32::try_from(x).ok())
                    .filter(|x| (*x as usize) < vars)
                    .ok_or_else(|| format!("tape node {i}: a variable must be below {vars}"))?,
            ),
            "neg" => Node::Neg(id(1)?),
            "add" => Node::Add(id(1)?, id(2)?),
            "sub" => Node::Sub(id(1)?, id(2)?),
            "mul" => Node::Mul(id(1)?, id(2)?),
            "div" => Node::Div(id(1)?, id(2)?),
            "powi" => Node::Powi(
                id(1)?,
                parts
                    .get(2)
                    .and_then(Value::as_i64)
                    .and_then(|x| i32::try_from(x).ok())
                    .ok_or_else(|| format!("tape node {i}: a power must be an integer"))?,
            ),
            other => match Func::from_name(other) {
                Some(f) => Node::Func(f, id(1)?),
                None => {
                    return Err(format!(
                        "tape node {i}: unknown operation `{}`",
                        ravel_base::text::sanitize(other)
                    ))
                }
            },
        };
        tape.push(node);
    }
    Ok(tape)
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn a_disc_constraint_is_enclosed_and_undefined_values_give_nothing() {
        // (x0 − 1)² + x1² − 0.25
        let t = read(
            &json!([
                ["var", 0],
                ["const", 1.0],
                ["sub", 0, 1],
                ["powi", 2, 2],
                ["var", 1],
                ["powi", 4, 2],
                ["add", 3, 5],
                ["const", 0.25],
                ["sub", 6, 7]
            ]),
            2,
        )
        .unwrap();
        let r = range(&t, &[0.0, -0.5], &[0.5, 0.5]).unwrap();
        // exact range: 0.25 + 0 − 0.25 = 0 … 1 + 0.25 − 0.25 = 1
        assert!(r.lo <= 0.0 && r.hi >= 1.0 && r.lo > -1e-12 && r.hi < 1.0 + 1e-12);
        let log = read(&json!([["var", 0], ["log", 0]]), 1).unwrap();
        assert!(range(&log, &[-1.0], &[1.0]).is_none());
        assert!(range(&log, &[0.5], &[1.0]).is_some());
        let inv = read(&json!([["const", 1.0], ["var", 0], ["div", 0, 1]]), 1).unwrap();
        assert!(range(&inv, &[-1.0], &[1.0]).is_none());
        let sin = read(&json!([["var", 0], ["sin", 0]]), 1).unwrap();
        let s = range(&sin, &[1.0], &[2.0]).unwrap();
        assert!(s.hi == 1.0 && s.lo <= 1.0f64.sin());
        // √(x0² + x1²) over a box around the origin: the sum's lower end is
        // an exact 0, not moved below it, so the root is defined
        let norm = read(
            &json!([
                ["var", 0],
                ["powi", 0, 2],
                ["var", 1],
                ["powi", 2, 2],
                ["add", 1, 3],
                ["sqrt", 4]
            ]),
            2,
        )
        .unwrap();
        let n = range(&norm, &[-0.14, -0.14], &[0.14, 0.14]).unwrap();
        assert!(n.lo == 0.0 && n.hi >= 0.14 * 2f64.sqrt() && n.hi < 0.1981);
        // a sum that only rounds to a tiny number is still moved out
        let shifted = read(&json!([["var", 0], ["const", 1e-300], ["sub", 0, 1]]), 1).unwrap();
        let z = range(&shifted, &[2e-300], &[2e-300]).unwrap();
        assert!(z.lo < 1e-300 && z.hi > 1e-300);
        // malformed tapes are refused
        assert!(read(&json!([["add", 0, 1]]), 1).is_err());
        assert!(read(&json!([["var", 3]]), 2).is_err());
        assert!(read(&json!([["frobnicate", 0]]), 1).is_err());
        assert!(read(&json!([]), 1).is_err());
    }
}
