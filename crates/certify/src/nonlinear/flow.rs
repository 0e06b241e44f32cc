//! The checker's validated integration of a nonlinear plant: its own
//! reading of the plant's expression tape, Taylor series in time by the
//! standard recurrences (generic over [`Num`]), and one control period of
//! the flow with its intersample enclosure.
//!
//! One substep of length `h` from the state `X` (controls and
//! disturbances held):
//! 1. an a-priori enclosure `E ⊇ x([0, h])` by Picard's operator: a box
//!    `E₀` with `box(X) + [0, h]·f(E₀) ⊆ E₀` (then the solution cannot
//!    leave `E₀` on `[0, h]` and lies in that image);
//! 2. `x(h) ∈ Σ_{i<K} Xᵢ hⁱ + x_[K](E)·h^K` (Lagrange's remainder), with
//!    the coefficients `Xᵢ` of the Taylor series at `X` in `Num` (affine
//!    forms keep the dependency on the symbols) and the `K`-th coefficient
//!    over `E` in intervals;
//! 3. between the ends, `x(τ) ∈ Σ_{i<K} range(Xᵢ)·[0, h]ⁱ + x_[K](E)·[0, h]^K`,
//!    intersected with `E`.
//!
//! A substep without an enclosure is halved (up to [`MAX_HALVINGS`] times).
//!
//! The states between the instants are kept per initial substep
//! ([`Period::between`]: the period cut into `substeps` equal pieces, each
//! piece the hull of its substep's halvings), so a property is checked on
//! boxes a `substeps`-th of the period long; the analysis cuts the period
//! into 8 pieces, and every try of [`SUBSTEPS`] cuts it at least as finely.

use super::arith::{Fail, Iv, Num};
use ravel_base::expr::Func;
use serde_json::Value;

/// Taylor order of the checker's integration.
pub const ORDER: usize = 6;

/// Substeps per control period before any halving, in the order the
/// checker tries them on a claim its first try does not prove.
pub const SUBSTEPS: [u32; 3] = [8, 32, 128];

/// How often a substep may be halved when no enclosure is found.
pub const MAX_HALVINGS: u32 = 12;

/// Exponents beyond this size are not read (they are expanded into products).
const MAX_EXPONENT: i64 = 1024;

/// One operation of the checker's tape; operands are earlier indices.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Op {
    Const(f64),
    /// `[x, u, w]`, concatenated.
    Var(usize),
    Neg(usize),
    Add(usize, usize),
    Sub(usize, usize),
    Mul(usize, usize),
    Div(usize, usize),
    Elem(Func, usize),
}

/// A plant as the checker reads it from a certificate.
#[derive(Clone, Debug)]
pub struct Field {
    /// States.
    pub n: usize,
    /// Controls.
    pub m: usize,
    /// Disturbances.
    pub d: usize,
    ops: Vec<Op>,
    /// The node giving each component's right-hand side.
    outputs: Vec<usize>,
    /// `Some(T)`: `ẋ = f` held over periods `T`; `None`: `x⁺ = f`.
    pub period: Option<f64>,
}

type R<T> = Result<T, String>;

fn index(v: Option<&Value>, below: usize, what: &str) -> R<usize> {
    v.and_then(Value::as_u64)
        .and_then(|i| usize::try_from(i).ok())
        .filter(|&i| i < below)
        .ok_or_else(|| format!("tape: {what} must be an index below {below}"))
}

impl Field {
    /// Read the plant (`tape`, `outputs`, `time`, dimensions) of a nonlinear
    /// problem. Powers are expanded into products here.
    pub fn read(p: &Value, n: usize, m: usize, d: usize) -> R<Field> {
        let nodes = p
            .get("tape")
            .and_then(Value::as_array)
            .ok_or("`tape` must be an array")?;
        if nodes.len() > ravel_base::limits::MAX_EXPR_NODES {
            return Err("the tape is longer than any spec makes".into());
        }
        let vars = n + m + d;
        let mut ops: Vec<Op> = Vec::with_capacity(nodes.len());
        // the checker's index of every tape node
        let mut at: Vec<usize> = Vec::with_capacity(nodes.len());
        for (i, node) in nodes.iter().enumerate() {
            let a = node.as_array().ok_or("a tape node must be an array")?;
            let tag = a
                .first()
                .and_then(Value::as_str)
                .ok_or("a tape node needs a tag")?;
            let arg = |k: usize| -> R<usize> {
                index(a.get(k), i, "an operand").and_then(|j| {
                    at.get(j)
                        .copied()
                        .ok_or_else(|| "tape: a bad operand".to_string())
                })
            };
            let op = match tag {
                "const" => Op::Const(
                    a.get(1)
                        .and_then(Value::as_f64)
                        .filter(|v| v.is_finite())
                        .ok_or("tape: a constant must be a finite number")?,
                ),
                "var" => Op::Var(index(a.get(1), vars, "a variable")?),
                "neg" => Op::Neg(arg(1)?),
                "add" => Op::Add(arg(1)?, arg(2)?),
                "sub" => Op::Sub(arg(1)?, arg(2)?),
                "mul" => Op::Mul(arg(1)?, arg(2)?),
                "div" => Op::Div(arg(1)?, arg(2)?),
                "powi" => {
                    let base = arg(1)?;
                    let k = a
                        .get(2)
                        .and_then(Value::as_i64)
                        .filter(|k| k.abs() <= MAX_EXPONENT)
                        .ok_or("tape: an exponent must be an integer of at most 1024 in size")?;
                    at.push(expand_power(&mut ops, base, k));
                    continue;
                }
                name => Op::Elem(
                    Func::from_name(name).ok_or("tape: an unknown operation")?,
                    arg(1)?,
                ),
            };
            ops.push(op);
            at.push(ops.len() - 1);
        }
        let outputs = p
            .get("outputs")
            .and_then(Value::as_array)
            .filter(|o| o.len() == n)
            .ok_or(format!("`outputs` must list {n} nodes"))?
            .iter()
            .map(|o| {
                index(Some(o), nodes.len(), "an output").and_then(|j| {
                    at.get(j)
                        .copied()
                        .ok_or_else(|| "tape: a bad output".to_string())
                })
            })
            .collect::<R<Vec<_>>>()?;
        let period = match p.get("time") {
            Some(Value::String(s)) if s == "discrete" => None,
            Some(t) => Some(
                t.get("continuous")
                    .and_then(Value::as_f64)
                    .filter(|v| v.is_finite() && *v > 0.0)
                    .ok_or("`time.continuous` must be a positive number")?,
            ),
            None => return Err("missing field `time`".into()),
        };
        Ok(Field {
            n,
            m,
            d,
            ops,
            outputs,
            period,
        })
    }

    /// `ẋ = A x + B u + c` over `[x, u]`, the control held over periods
    /// `period` (a linear plant in continuous time, for the states between
    /// its sampling instants).
    pub fn linear(
        a: &nalgebra::DMatrix<f64>,
        b: &nalgebra::DMatrix<f64>,
        c: &[f64],
        period: f64,
    ) -> Field {
        let (n, m) = (a.nrows(), b.ncols());
        let mut ops: Vec<Op> = (0..n + m).map(Op::Var).collect();
        let mut outputs = Vec::with_capacity(n);
        for i in 0..n {
            ops.push(Op::Const(c.get(i).copied().unwrap_or(0.0)));
            let mut acc = ops.len() - 1;
            let row = a
                .row(i)
                .iter()
                .copied()
                .chain(b.row(i).iter().copied())
                .collect::<Vec<_>>();
            for (v, coef) in row.into_iter().enumerate() {
                if coef != 0.0 {
                    ops.push(Op::Const(coef));
                    ops.push(Op::Mul(ops.len() - 1, v));
                    ops.push(Op::Add(acc, ops.len() - 1));
                    acc = ops.len() - 1;
                }
            }
            outputs.push(acc);
        }
        Field {
            n,
            m,
            d: 0,
            ops,
            outputs,
            period: Some(period),
        }
    }

    /// The right-hand side (or map) at `x`, `u`, `w`, order 0 only.
    pub fn eval<T: Num>(&self, x: &[T], u: &[T], w: &[T]) -> Result<Vec<T>, Fail> {
        let xs: Vec<Vec<T>> = x.iter().map(|v| vec![v.clone()]).collect();
        let mut s = Series::new(self.ops.len());
        s.order(self, 0, &xs, u, w)?;
        self.outputs
            .iter()
            .map(|&o| node(&s.v, o).and_then(|v| coef(v, 0)).cloned())
            .collect()
    }

    /// The Taylor coefficients `0..=order` in time of the solution through
    /// `x` (controls and disturbances constant).
    pub fn taylor<T: Num>(
        &self,
        x: &[T],
        u: &[T],
        w: &[T],
        order: usize,
    ) -> Result<Vec<Vec<T>>, Fail> {
        let mut xs: Vec<Vec<T>> = x.iter().map(|v| vec![v.clone()]).collect();
        let mut s = Series::new(self.ops.len());
        for k in 0..order {
            s.order(self, k, &xs, u, w)?;
            for (series, &o) in xs.iter_mut().zip(&self.outputs) {
                let c = coef(node(&s.v, o)?, k)?.div_int(k as u32 + 1);
                if !c.finite() {
                    return Err(Fail::Overflow);
                }
                series.push(c);
            }
        }
        Ok(xs)
    }
}

/// `base^k` appended to `ops` as products (square and multiply); the index
/// of the result.
fn expand_power(ops: &mut Vec<Op>, base: usize, k: i64) -> usize {
    if k == 0 {
        ops.push(Op::Const(1.0));
        return ops.len() - 1;
    }
    let mut e = k.unsigned_abs();
    let mut square = base;
    let mut acc: Option<usize> = None;
    loop {
        if e & 1 == 1 {
            acc = Some(match acc {
                None => square,
                Some(a) => {
                    ops.push(Op::Mul(a, square));
                    ops.len() - 1
                }
            });
        }
        e >>= 1;
        if e == 0 {
            break;
        }
        ops.push(Op::Mul(square, square));
        square = ops.len() - 1;
    }
    let pos = acc.unwrap_or(base);
    if k > 0 {
        return pos;
    }
    ops.push(Op::Const(1.0));
    ops.push(Op::Div(ops.len() - 1, pos));
    ops.len() - 1
}

/// Every node's Taylor coefficients computed so far, and each node's
/// companion series (`cos` beside `sin`, `1 ∓ t²` beside `tanh`/`tan`,
/// `1/b₀` beside a division, …).
struct Series<T> {
    v: Vec<Vec<T>>,
    aux: Vec<Vec<T>>,
    /// `abs` nodes: the sign of the argument's range (`None`: it may be 0).
    sign: Vec<Option<bool>>,
}

fn node<T>(s: &[Vec<T>], i: usize) -> Result<&[T], Fail> {
    s.get(i).map(Vec::as_slice).ok_or(Fail::Overflow)
}

fn coef<T>(s: &[T], k: usize) -> Result<&T, Fail> {
    s.get(k).ok_or(Fail::Overflow)
}

/// `Σ_{j=lo}^{k} weight(j)·a_j·b_{k−j}` (weights are small integers).
fn conv<T: Num>(a: &[T], b: &[T], k: usize, lo: usize, weighted: bool) -> Result<T, Fail> {
    let mut acc: Option<T> = None;
    for j in lo..=k {
        let mut t = coef(a, j)?.mul(coef(b, k - j)?);
        if weighted {
            t = t.scale(j as f64);
        }
        acc = Some(match acc {
            None => t,
            Some(s) => s.add(&t),
        });
    }
    acc.ok_or(Fail::Overflow)
}

impl<T: Num> Series<T> {
    fn new(nodes: usize) -> Series<T> {
        Series {
            v: (0..nodes).map(|_| Vec::new()).collect(),
            aux: (0..nodes).map(|_| Vec::new()).collect(),
            sign: vec![None; nodes],
        }
    }

    /// Coefficient `k` of every node, from the state's coefficients `0..=k`
    /// and every node's coefficients below `k`.
    fn order(&mut self, f: &Field, k: usize, xs: &[Vec<T>], u: &[T], w: &[T]) -> Result<(), Fail> {
        let like = coef(xs.first().map(Vec::as_slice).unwrap_or(&[]), 0)?.clone();
        let zero = like.cst(0.0);
        for (i, op) in f.ops.iter().enumerate() {
            let (value, aux) = match *op {
                Op::Const(c) => (if k == 0 { like.cst(c) } else { zero.clone() }, None),
                Op::Var(j) => {
                    let v = if j < f.n {
                        coef(node(xs, j)?, k)?.clone()
                    } else if k > 0 {
                        zero.clone()
                    } else if j < f.n + f.m {
                        coef(u, j - f.n)?.clone()
                    } else {
                        coef(w, j - f.n - f.m)?.clone()
                    };
                    (v, None)
                }
                Op::Neg(a) => (coef(node(&self.v, a)?, k)?.neg(), None),
                Op::Add(a, b) => (
                    coef(node(&self.v, a)?, k)?.add(coef(node(&self.v, b)?, k)?),
                    None,
                ),
                Op::Sub(a, b) => (
                    coef(node(&self.v, a)?, k)?.sub(coef(node(&self.v, b)?, k)?),
                    None,
                ),
                Op::Mul(a, b) => (
                    conv(node(&self.v, a)?, node(&self.v, b)?, k, 0, false)?,
                    None,
                ),
                Op::Div(a, b) => {
                    // q_k = (a_k − Σ_{j=1}^{k} b_j q_{k−j}) / b₀
                    let inv = if k == 0 {
                        coef(node(&self.v, b)?, 0)?.recip()?
                    } else {
                        coef(node(&self.aux, i)?, 0)?.clone()
                    };
                    let mut num = coef(node(&self.v, a)?, k)?.clone();
                    if k > 0 {
                        num = num.sub(&conv_shift(node(&self.v, b)?, node(&self.v, i)?, k)?);
                    }
                    (num.mul(&inv), (k == 0).then_some(inv))
                }
                Op::Elem(g, a) => self.elem(g, a, i, k)?,
            };
            if !value.finite() {
                return Err(Fail::Overflow);
            }
            if let Some(v) = self.v.get_mut(i) {
                v.push(value);
            }
            if let (Some(x), Some(a)) = (aux, self.aux.get_mut(i)) {
                a.push(x);
            }
        }
        Ok(())
    }

    /// Coefficient `k` of `g(a)` (node `i`), and its companion's.
    fn elem(&mut self, g: Func, a: usize, i: usize, k: usize) -> Result<(T, Option<T>), Fail> {
        let av = node(&self.v, a)?;
        let a0 = coef(av, 0)?;
        if k == 0 {
            let v = a0.elem(g)?;
            let aux = match g {
                Func::Sin => Some(a0.elem(Func::Cos)?),
                Func::Cos => Some(a0.elem(Func::Sin)?),
                Func::Tanh => Some(v.cst(1.0).sub(&v.mul(&v))),
                Func::Tan => Some(v.cst(1.0).add(&v.mul(&v))),
                Func::Log => Some(a0.recip()?),
                Func::Sqrt => Some(v.add(&v).recip()?),
                Func::Exp => None,
                Func::Abs => {
                    let r = a0.range();
                    let sign = if r.lo > 0.0 {
                        Some(true)
                    } else if r.hi < 0.0 {
                        Some(false)
                    } else {
                        None
                    };
                    if let Some(s) = self.sign.get_mut(i) {
                        *s = sign;
                    }
                    None
                }
            };
            return Ok((v, aux));
        }
        let kk = k as u32;
        let own = node(&self.v, i)?;
        let aux = node(&self.aux, i)?;
        Ok(match g {
            // e_k = (1/k) Σ_{j=1}^{k} j a_j e_{k−j}
            Func::Exp => (conv(av, own, k, 1, true)?.div_int(kk), None),
            // s_k = (1/k) Σ j a_j c_{k−j};  c_k = −(1/k) Σ j a_j s_{k−j}
            Func::Sin => (
                conv(av, aux, k, 1, true)?.div_int(kk),
                Some(conv(av, own, k, 1, true)?.div_int(kk).neg()),
            ),
            Func::Cos => (
                conv(av, aux, k, 1, true)?.div_int(kk).neg(),
                Some(conv(av, own, k, 1, true)?.div_int(kk)),
            ),
            // t_k = (1/k) Σ j a_j d_{k−j},  d = 1 ∓ t²
            Func::Tanh | Func::Tan => {
                let t = conv(av, aux, k, 1, true)?.div_int(kk);
                let mut own2 = own.to_vec();
                own2.push(t.clone());
                let sq = conv(&own2, &own2, k, 0, false)?;
                let d = if g == Func::Tanh { sq.neg() } else { sq };
                (t, Some(d))
            }
            // l_k = (a_k − (1/k) Σ_{j=1}^{k−1} j l_j a_{k−j}) / a₀
            Func::Log => {
                let mut num = coef(av, k)?.clone();
                if k > 1 {
                    let s = conv_range(own, av, k, 1, k - 1, true)?.div_int(kk);
                    num = num.sub(&s);
                }
                (num.mul(coef(aux, 0)?), None)
            }
            // r_k = (a_k − Σ_{j=1}^{k−1} r_j r_{k−j}) / (2 r₀)
            Func::Sqrt => {
                let mut num = coef(av, k)?.clone();
                if k > 1 {
                    num = num.sub(&conv_range(own, own, k, 1, k - 1, false)?);
                }
                (num.mul(coef(aux, 0)?), None)
            }
            Func::Abs => match self.sign.get(i).copied().flatten() {
                Some(true) => (coef(av, k)?.clone(), None),
                Some(false) => (coef(av, k)?.neg(), None),
                None => return Err(Fail::Domain(Func::Abs)),
            },
        })
    }
}

/// `Σ_{j=1}^{k} b_j q_{k−j}` where `q` has coefficients `0..k`.
fn conv_shift<T: Num>(b: &[T], q: &[T], k: usize) -> Result<T, Fail> {
    conv_range(b, q, k, 1, k, false)
}

/// `Σ_{j=lo}^{hi} weight(j)·a_j·b_{k−j}`.
fn conv_range<T: Num>(
    a: &[T],
    b: &[T],
    k: usize,
    lo: usize,
    hi: usize,
    weighted: bool,
) -> Result<T, Fail> {
    let mut acc: Option<T> = None;
    for j in lo..=hi {
        let mut t = coef(a, j)?.mul(coef(b, k - j)?);
        if weighted {
            t = t.scale(j as f64);
        }
        acc = Some(match acc {
            None => t,
            Some(s) => s.add(&t),
        });
    }
    acc.ok_or(Fail::Overflow)
}

/// The state after one period and the boxes of the states in between.
pub struct Period<T> {
    /// The state at the end of the period.
    pub end: Vec<T>,
    /// Every state over the period, ends included (continuous time): one
    /// box per substep, `between[j]` holding the states over
    /// `[j·T/substeps, (j+1)·T/substeps]`.
    pub between: Option<Vec<Vec<Iv>>>,
    /// Per piece of `between`, forms holding its states (the form at the
    /// substep's start plus an interval of the motion over it), where the
    /// piece is one substep (no halving); empty in discrete time.
    pub forms: Vec<Option<Vec<T>>>,
}

/// The hull of a period's pieces.
pub fn hull(pieces: &[Vec<Iv>]) -> Option<Vec<Iv>> {
    let (first, rest) = pieces.split_first()?;
    Some(rest.iter().fold(first.clone(), |h, b| {
        h.iter().zip(b).map(|(a, b)| a.hull(b)).collect()
    }))
}

/// One period of the plant from `x` with controls `u` and disturbances `w`
/// held: the flow over `T` (continuous time) or the map (discrete time).
pub fn period<T: Num>(
    f: &Field,
    x: &[T],
    u: &[T],
    w: &[T],
    substeps: u32,
) -> Result<Period<T>, Fail> {
    let Some(t) = f.period else {
        return Ok(Period {
            end: f.eval(x, u, w)?,
            between: None,
            forms: Vec::new(),
        });
    };
    let substeps = substeps.max(1);
    let h = t / f64::from(substeps);
    let mut state = x.to_vec();
    let mut pieces = Vec::with_capacity(substeps as usize);
    let mut forms = Vec::with_capacity(substeps as usize);
    for _ in 0..substeps {
        let mut piece: Option<Vec<Iv>> = None;
        let mut form: Option<Vec<T>> = None;
        state = substep(f, &state, u, w, h, 0, &mut piece, &mut form)?;
        pieces.push(piece.ok_or(Fail::NoEnclosure)?);
        forms.push(form);
    }
    Ok(Period {
        end: state,
        between: Some(pieces),
        forms,
    })
}

/// `h` from `x`, halved when no enclosure is found; the states in between
/// are added to `pipe`, and their forms set in `form` when the substep is
/// not halved.
#[allow(clippy::too_many_arguments)]
fn substep<T: Num>(
    f: &Field,
    x: &[T],
    u: &[T],
    w: &[T],
    h: f64,
    halvings: u32,
    pipe: &mut Option<Vec<Iv>>,
    form: &mut Option<Vec<T>>,
) -> Result<Vec<T>, Fail> {
    match one_substep(f, x, u, w, h) {
        Ok((end, between, forms)) => {
            *pipe = Some(match pipe.take() {
                None => between,
                Some(p) => p.iter().zip(&between).map(|(a, b)| a.hull(b)).collect(),
            });
            *form = (halvings == 0).then_some(forms);
            Ok(end)
        }
        Err(Fail::NoEnclosure) if halvings < MAX_HALVINGS => {
            let mid = substep(f, x, u, w, 0.5 * h, halvings + 1, pipe, form)?;
            substep(f, &mid, u, w, 0.5 * h, halvings + 1, pipe, form)
        }
        Err(e) => Err(e),
    }
}

/// Picard's a-priori enclosure of the flow from the box `b` over `[0, h]`.
fn enclosure(f: &Field, b: &[Iv], u: &[Iv], w: &[Iv], h: f64) -> Result<Vec<Iv>, Fail> {
    let span = Iv::new(0.0, h);
    let step = |e: &[Iv]| -> Result<Vec<Iv>, Fail> {
        let fe = f.eval(e, u, w)?;
        Ok(b.iter()
            .zip(&fe)
            .map(|(b, d)| b.add(&d.mul(&span)))
            .collect())
    };
    let mut e0 = step(b)?;
    for _ in 0..12 {
        let grown: Vec<Iv> = e0
            .iter()
            .zip(b)
            .map(|(e, b)| {
                let e = e.hull(b);
                e.widen(0.1 * (e.hi - e.lo) + 1e-12 * (1.0 + e.lo.abs().max(e.hi.abs())))
            })
            .collect();
        if !grown.iter().all(Iv::is_finite) {
            return Err(Fail::Overflow);
        }
        let e1 = match step(&grown) {
            Ok(e) => e,
            Err(Fail::Domain(_) | Fail::Division) => return Err(Fail::NoEnclosure),
            Err(e) => return Err(e),
        };
        if grown.iter().zip(&e1).all(|(g, e)| g.contains(e)) {
            return Ok(e1);
        }
        e0 = grown.iter().zip(&e1).map(|(g, e)| g.hull(e)).collect();
    }
    Err(Fail::NoEnclosure)
}

/// One substep of length `h` (see the module's doc): the end state, the
/// box of the states in between and forms holding them,
/// `x(τ) ∈ X₀ + Σ_{0<i<K} range(Xᵢ)·[0, h]ⁱ + x_[K](E)·[0, h]^K`.
#[allow(clippy::type_complexity)]
fn one_substep<T: Num>(
    f: &Field,
    x: &[T],
    u: &[T],
    w: &[T],
    h: f64,
) -> Result<(Vec<T>, Vec<Iv>, Vec<T>), Fail> {
    let b: Vec<Iv> = x.iter().map(Num::range).collect();
    let ui: Vec<Iv> = u.iter().map(Num::range).collect();
    let wi: Vec<Iv> = w.iter().map(Num::range).collect();
    let e = enclosure(f, &b, &ui, &wi, h)?;
    let rem = f.taylor(&e, &ui, &wi, ORDER)?;
    let series = f.taylor(x, u, w, ORDER - 1)?;
    // hᴷ and [0, h]ⁱ, outward
    let hk = (0..ORDER).fold(Iv::point(1.0), |p, _| p.mul(&Iv::point(h)));
    let span = Iv::new(0.0, h);
    let mut end = Vec::with_capacity(x.len());
    let mut between = Vec::with_capacity(x.len());
    let mut forms = Vec::with_capacity(x.len());
    for ((s, rem), e) in series.iter().zip(&rem).zip(&e) {
        let r = coef(rem, ORDER)?.mul(&hk);
        // Horner in h over the forms
        let mut acc = coef(s, ORDER - 1)?.clone();
        for j in (0..ORDER - 1).rev() {
            acc = acc.scale(h).add(coef(s, j)?);
        }
        let acc = acc.add_iv(&r);
        if !acc.finite() {
            return Err(Fail::Overflow);
        }
        end.push(acc);
        // the states in between: Horner in τ ∈ [0, h]
        let mut poly = *coef(rem, ORDER)?;
        for j in (0..ORDER).rev() {
            poly = poly.mul(&span).add(&coef(s, j)?.range());
        }
        let inside = poly.meet(e);
        between.push(if inside.lo <= inside.hi { inside } else { *e });
        // the motion away from X₀ over the substep, Horner in τ ∈ [0, h]
        let mut motion = *coef(rem, ORDER)?;
        for j in (1..ORDER).rev() {
            motion = motion.mul(&span).add(&coef(s, j)?.range());
        }
        let form = coef(s, 0)?.add_iv(&motion.mul(&span));
        forms.push(form);
    }
    Ok((end, between, forms))
}
