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

fn add(a: Iv, b: Iv) -> Option<Iv> {
    out_sum(a.lo + b.lo, a.hi + b.hi)
}

fn sub(a: Iv, b: Iv) -> Option<Iv> {
    out_sum(a.lo - b.hi, a.hi - b.lo)
}

fn neg(a: Iv) -> Iv {
    Iv {
        lo: -a.hi,
        hi: -a.lo,
    }
}

/// The derivative of `f` over `x`, given `v = f(x)` enclosed; `None`
/// where it is unbounded or undefined (`√` and `log` near 0, `abs` where
/// its argument may change sign).
fn derivative(f: Func, x: Iv, v: Iv) -> Option<Iv> {
    let one = Iv { lo: 1.0, hi: 1.0 };
    match f {
        Func::Sin => trig(x, true),
        Func::Cos => trig(x, false).map(neg),
        Func::Tan => add(one, mul(v, v)?),
        Func::Exp => Some(v),
        Func::Log => div(one, x),
        Func::Sqrt => {
            if v.lo <= 0.0 {
                return None;
            }
            div(one, add(v, v)?)
        }
        Func::Tanh => sub(one, mul(v, v)?),
        Func::Abs => {
            if x.lo <= 0.0 && x.hi >= 0.0 {
                return None;
            }
            let s = if x.lo > 0.0 { 1.0 } else { -1.0 };
            iv(s, s)
        }
    }
}

/// An enclosure of the gradient of the tape's last node with respect to
/// the first `n` variables over the box `lo … hi`, by forward
/// differentiation in this module's outward arithmetic; `None` where the
/// tape is not smooth on the box (see [`derivative`]) or anything is not
/// finite.
pub fn gradient(tape: &Tape, lo: &[f64], hi: &[f64], n: usize) -> Option<Vec<Iv>> {
    let zero = Iv { lo: 0.0, hi: 0.0 };
    let mut nodes: Vec<(Iv, Vec<Iv>)> = Vec::with_capacity(tape.nodes.len());
    for node in &tape.nodes {
        let at = |id: u32| nodes.get(id as usize);
        let entry = match *node {
            Node::Const(c) => (iv(c, c)?, vec![zero; n]),
            Node::Var(i) => {
                let i = i as usize;
                let d = (0..n)
                    .map(|j| {
                        if j == i {
                            Iv { lo: 1.0, hi: 1.0 }
                        } else {
                            zero
                        }
                    })
                    .collect();
                (iv(*lo.get(i)?, *hi.get(i)?)?, d)
            }
            Node::Neg(a) => {
                let (x, dx) = at(a)?;
                (neg(*x), dx.iter().map(|d| neg(*d)).collect())
            }
            Node::Add(a, b) | Node::Sub(a, b) => {
                let ((x, dx), (y, dy)) = (at(a)?, at(b)?);
                let minus = matches!(node, Node::Sub(..));
                let op = |p: Iv, q: Iv| if minus { sub(p, q) } else { add(p, q) };
                let d = dx
                    .iter()
                    .zip(dy)
                    .map(|(p, q)| op(*p, *q))
                    .collect::<Option<Vec<_>>>()?;
                (op(*x, *y)?, d)
            }
            Node::Mul(a, b) => {
                let ((x, dx), (y, dy)) = (at(a)?, at(b)?);
                let d = dx
                    .iter()
                    .zip(dy)
                    .map(|(p, q)| add(mul(*p, *y)?, mul(*x, *q)?))
                    .collect::<Option<Vec<_>>>()?;
                (mul(*x, *y)?, d)
            }
            Node::Div(a, b) => {
                // (x / y)' = (x' − q·y') / y with q = x / y
                let ((x, dx), (y, dy)) = (at(a)?, at(b)?);
                let q = div(*x, *y)?;
                let d = dx
                    .iter()
                    .zip(dy)
                    .map(|(p, r)| div(sub(*p, mul(q, *r)?)?, *y))
                    .collect::<Option<Vec<_>>>()?;
                (q, d)
            }
            Node::Powi(a, k) => {
                let (x, dx) = at(a)?;
                let v = powi(*x, k)?;
                let f = if k == 0 {
                    zero
                } else {
                    mul(
                        powi(*x, k.checked_sub(1)?)?,
                        iv(f64::from(k), f64::from(k))?,
                    )?
                };
                (
                    v,
                    dx.iter().map(|d| mul(f, *d)).collect::<Option<Vec<_>>>()?,
                )
            }
            Node::Func(f, a) => {
                let (x, dx) = at(a)?;
                let v = apply(f, *x)?;
                let fd = derivative(f, *x, v)?;
                (
                    v,
                    dx.iter().map(|d| mul(fd, *d)).collect::<Option<Vec<_>>>()?,
                )
            }
        };
        nodes.push(entry);
    }
    nodes.pop().map(|(_, d)| d)
}

/// An enclosure of the tape's last node over the affine set
/// `{c + G s + e : s ∈ [−1, 1]ᵏ, eᵢ ∈ [e_loᵢ, e_hiᵢ]}` lying in the box
/// `lo … hi`, by the mean value theorem around a centre `p` in the box:
/// `g(x) ∈ g(p) + Σᵢ Jᵢ (xᵢ − pᵢ)`, `J` the gradient over the box.
/// Splitting `Jᵢ = mᵢ + [−ρᵢ, ρᵢ]` keeps the set's correlations in
/// `Σⱼ (Σᵢ mᵢ Gᵢⱼ) sⱼ`. `None` where the gradient has no enclosure or `p`
/// is outside the box.
pub fn range_affine(
    tape: &Tape,
    c: &[f64],
    g: &[Vec<f64>],
    e_lo: &[f64],
    e_hi: &[f64],
    lo: &[f64],
    hi: &[f64],
) -> Option<Iv> {
    let n = c.len();
    if [g.len(), e_lo.len(), e_hi.len(), lo.len(), hi.len()]
        .iter()
        .any(|&l| l != n)
    {
        return None;
    }
    // p = c + mid(e); x − p = G s + (c + e − p), the last enclosed
    let mut p = Vec::with_capacity(n);
    let mut rest = Vec::with_capacity(n);
    for i in 0..n {
        let (ci, l, h) = (*c.get(i)?, *e_lo.get(i)?, *e_hi.get(i)?);
        let pi = ci + (0.5 * l + 0.5 * h);
        if !(pi.is_finite() && *lo.get(i)? <= pi && pi <= *hi.get(i)?) {
            return None;
        }
        p.push(pi);
        rest.push(sub(add(iv(ci, ci)?, iv(l, h)?)?, iv(pi, pi)?)?);
    }
    // every row over the same k symbols
    let k = g.first().map_or(0, Vec::len);
    if g.iter().any(|row| row.len() != k) {
        return None;
    }
    let jac = gradient(tape, lo, hi, n)?;
    let mut acc = range(tape, &p, &p)?;
    let mids: Vec<f64> = jac.iter().map(|j| 0.5 * j.lo + 0.5 * j.hi).collect();
    // Σⱼ |Σᵢ mᵢ Gᵢⱼ|
    let mut spread = 0.0f64;
    for j in 0..k {
        let mut col = iv(0.0, 0.0)?;
        for (row, m) in g.iter().zip(&mids) {
            col = add(col, mul(iv(*m, *m)?, iv(*row.get(j)?, *row.get(j)?)?)?)?;
        }
        spread = (spread + col.lo.abs().max(col.hi.abs())).next_up();
    }
    acc = add(acc, iv(-spread, spread)?)?;
    for i in 0..n {
        let (m, j, r) = (*mids.get(i)?, *jac.get(i)?, *rest.get(i)?);
        acc = add(acc, mul(iv(m, m)?, r)?)?;
        // ρᵢ·|x − p|ᵢ, |x − p|ᵢ ≤ Σⱼ |Gᵢⱼ| + |restᵢ|
        let rho = (j.hi - m).max(m - j.lo).next_up();
        let mut dev = r.lo.abs().max(r.hi.abs());
        for v in g.get(i)? {
            dev = (dev + v.abs()).next_up();
        }
        let t = (rho * dev).next_up();
        acc = add(acc, iv(-t, t)?)?;
    }
    Some(acc)
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

    /// Random affine sets `c + G s + e` and sampled points of them: every
    /// value of every tape lies in the mean value enclosure; a correlated
    /// set is bounded tighter than its box; a kink gives nothing.
    #[test]
    fn the_mean_value_form_holds_every_sampled_point() {
        let tapes = [
            json!([
                ["var", 0],
                ["powi", 0, 2],
                ["var", 1],
                ["powi", 2, 2],
                ["add", 1, 3],
                ["sqrt", 4],
                ["const", 0.5],
                ["mul", 6, 2],
                ["sub", 5, 7]
            ]),
            json!([
                ["var", 0],
                ["sin", 0],
                ["var", 1],
                ["mul", 1, 2],
                ["const", 3.0],
                ["div", 2, 4],
                ["exp", 5],
                ["add", 3, 6]
            ]),
            json!([
                ["var", 0],
                ["const", 1.0],
                ["sub", 0, 1],
                ["var", 1],
                ["const", 3.0],
                ["add", 3, 4],
                ["div", 2, 5]
            ]),
            json!([
                ["var", 0],
                ["var", 1],
                ["sub", 0, 1],
                ["tanh", 2],
                ["cos", 0],
                ["mul", 3, 4]
            ]),
        ]
        .map(|t| read(&t, 2).unwrap());
        let mut rng = ravel_base::rng::Rng::new(23);
        let mut vals = Vec::new();
        for case in 0..60 {
            let c = [rng.uniform(0.5, 2.0), rng.uniform(0.5, 2.0)];
            let g: Vec<Vec<f64>> = (0..2)
                .map(|_| (0..3).map(|_| rng.uniform(-0.3, 0.3)).collect())
                .collect();
            let e_lo = [rng.uniform(-0.03, 0.0), rng.uniform(-0.03, 0.0)];
            let e_hi = [e_lo[0] + 0.02, e_lo[1] + 0.01 * f64::from(case % 3)];
            let spread = |i: usize| g[i].iter().map(|v| v.abs()).sum::<f64>();
            let lo = [c[0] - spread(0) + e_lo[0], c[1] - spread(1) + e_lo[1]];
            let hi = [c[0] + spread(0) + e_hi[0], c[1] + spread(1) + e_hi[1]];
            for t in &tapes {
                let r = range_affine(t, &c, &g, &e_lo, &e_hi, &lo, &hi).unwrap();
                for k in 0..232 {
                    // the 32 corners of (s, e), then random points
                    let corner = |bit: usize| if k >> bit & 1 == 1 { 1.0 } else { -1.0 };
                    let s: Vec<f64> = (0..3)
                        .map(|j| {
                            if k < 32 {
                                corner(j)
                            } else {
                                rng.uniform(-1.0, 1.0)
                            }
                        })
                        .collect();
                    let x: Vec<f64> = (0..2)
                        .map(|i| {
                            let lin: f64 = g[i].iter().zip(&s).map(|(a, b)| a * b).sum();
                            let e = if k < 32 {
                                if corner(3 + i) > 0.0 {
                                    e_hi[i]
                                } else {
                                    e_lo[i]
                                }
                            } else {
                                rng.uniform(e_lo[i], e_hi[i])
                            };
                            c[i] + lin + e
                        })
                        .collect();
                    t.eval_into(&x, &mut vals);
                    let v = *vals.last().unwrap();
                    assert!(r.lo <= v && v <= r.hi, "case {case}: {v} ∉ {r:?}");
                }
            }
        }
        // x0 = x1 = 1 + 0.5 s: x0² − x1² is 0; the mean value form gives
        // about [−1, 1], the box [−2, 2]
        let sq = read(
            &json!([
                ["var", 0],
                ["powi", 0, 2],
                ["var", 1],
                ["powi", 2, 2],
                ["sub", 1, 3]
            ]),
            2,
        )
        .unwrap();
        let g = vec![vec![0.5], vec![0.5]];
        let r = range_affine(
            &sq,
            &[1.0, 1.0],
            &g,
            &[0.0; 2],
            &[0.0; 2],
            &[0.5; 2],
            &[1.5; 2],
        )
        .unwrap();
        assert!(
            r.lo < -0.99 && r.lo > -1.01 && r.hi > 0.99 && r.hi < 1.01,
            "{r:?}"
        );
        let b = range(&sq, &[0.5; 2], &[1.5; 2]).unwrap();
        assert!(b.lo < -1.99 && b.hi > 1.99);
        // abs at its kink, and a centre outside the box: nothing
        let abs = read(&json!([["var", 0], ["abs", 0]]), 1).unwrap();
        assert!(gradient(&abs, &[-1.0], &[1.0], 1).is_none());
        assert!(range_affine(
            &sq,
            &[3.0, 3.0],
            &g,
            &[0.0; 2],
            &[0.0; 2],
            &[0.5; 2],
            &[1.5; 2]
        )
        .is_none());
        // rows over different numbers of symbols: nothing
        let ragged = vec![vec![0.5], vec![0.5, 0.1]];
        let r = range_affine(
            &sq,
            &[1.0, 1.0],
            &ragged,
            &[0.0; 2],
            &[0.0; 2],
            &[0.5; 2],
            &[1.5; 2],
        );
        assert!(r.is_none());
    }

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
