//! Taylor-mode automatic differentiation of the solution of `ẋ = f(x, p)`.
//!
//! The Taylor coefficients `x_[k] = x⁽ᵏ⁾(0)/k!` of the solution through
//! `x(0) = x₀` (the parameters `p`, controls then disturbances, constant in
//! time) follow from `x_[k+1] = f_[k] / (k + 1)`, where `f_[k]` is the
//! `k`-th coefficient of `f(x(t), p)`, computed node by node in topological
//! order from the coefficients `0..k` of the operands by the standard
//! recurrences (Griewank & Walther, *Evaluating Derivatives*, ch. 13):
//!
//! * `a ± b`, `c·a`: termwise; `a·b`: the Cauchy product `Σⱼ aⱼ b_{k−j}`;
//! * `q = a/b`: `q_k = (a_k − Σ_{j≥1} bⱼ q_{k−j}) / b₀`;
//! * `e = exp a`: `e_k = (1/k) Σ_{j≥1} j aⱼ e_{k−j}`;
//! * `l = ln a`: `l_k = (a_k − (1/k) Σ_{1≤j<k} j lⱼ a_{k−j}) / a₀`;
//! * `s = √a`: `s_k = (a_k − Σ_{1≤j<k} sⱼ s_{k−j}) / (2 s₀)`;
//! * `sin`/`cos` as a pair: `s_k = (1/k) Σ j aⱼ c_{k−j}`, `c_k = −(1/k) Σ j aⱼ s_{k−j}`;
//! * `tan`, `tanh`: `t' = (1 ± t²)·a'`, with `w = 1 ± t²` kept as a series;
//! * `aⁿ`: binary powering by Cauchy products (a negative `n` then one
//!   reciprocal), which needs no division by `a₀`;
//! * `|a|`: `sign(a₀)·a` when the range of `a₀` keeps one sign, otherwise
//!   [`DomainError::AbsKink`] (the solution need not be smooth).
//!
//! It is written once over [`Coeff`], which both [`Interval`] (for the
//! Lagrange remainder over an a-priori enclosure) and [`Tm`] (for the
//! polynomial part, keeping the dependency on the initial set) implement.

use super::flow::FlowError;
use super::interval::{DomainError, Interval};
use super::tm::Tm;
use ravel_base::expr::{Func, Node, VectorField};

/// The arithmetic the recurrences need: implemented by [`Interval`] and
/// [`Tm`]. Every fallible result is checked finite.
pub trait Coeff: Clone + Sized {
    /// The constant `v`, shaped like `self` (the same symbol count).
    fn lift(&self, v: f64) -> Self;
    /// `self + o`.
    fn add(&self, o: &Self) -> Result<Self, DomainError>;
    /// `self − o`.
    fn sub(&self, o: &Self) -> Result<Self, DomainError>;
    /// `−self`.
    fn neg(&self) -> Self;
    /// `self · o`.
    fn mul(&self, o: &Self) -> Result<Self, DomainError>;
    /// `self / o`.
    fn div(&self, o: &Self) -> Result<Self, DomainError>;
    /// `self · s` for a real `s`.
    fn scale(&self, s: f64) -> Result<Self, DomainError>;
    /// `self / d` for a real `d ≠ 0`.
    fn div_scalar(&self, d: f64) -> Result<Self, DomainError>;
    /// `f(self)`.
    fn apply(&self, f: Func) -> Result<Self, DomainError>;
    /// A sound enclosure of every value.
    fn range(&self) -> Interval;
    /// Whether the value is exactly zero (a term that may be skipped).
    fn is_zero(&self) -> bool;
}

impl Coeff for Interval {
    fn lift(&self, v: f64) -> Interval {
        Interval::point(v)
    }
    fn add(&self, o: &Interval) -> Result<Interval, DomainError> {
        (*self + *o).checked()
    }
    fn sub(&self, o: &Interval) -> Result<Interval, DomainError> {
        (*self - *o).checked()
    }
    fn neg(&self) -> Interval {
        -*self
    }
    fn mul(&self, o: &Interval) -> Result<Interval, DomainError> {
        if self == o {
            return self.sqr().checked();
        }
        (*self * *o).checked()
    }
    fn div(&self, o: &Interval) -> Result<Interval, DomainError> {
        Interval::div(*self, *o)
    }
    fn scale(&self, s: f64) -> Result<Interval, DomainError> {
        Interval::scale(*self, s).checked()
    }
    fn div_scalar(&self, d: f64) -> Result<Interval, DomainError> {
        Interval::div(*self, Interval::point(d))
    }
    fn apply(&self, f: Func) -> Result<Interval, DomainError> {
        Interval::apply(*self, f)
    }
    fn range(&self) -> Interval {
        *self
    }
    fn is_zero(&self) -> bool {
        self.lo == 0.0 && self.hi == 0.0
    }
}

impl Coeff for Tm {
    fn lift(&self, v: f64) -> Tm {
        Tm::constant(v, self.symbols())
    }
    fn add(&self, o: &Tm) -> Result<Tm, DomainError> {
        Tm::add(self, o)
    }
    fn sub(&self, o: &Tm) -> Result<Tm, DomainError> {
        Tm::sub(self, o)
    }
    fn neg(&self) -> Tm {
        Tm::neg(self)
    }
    fn mul(&self, o: &Tm) -> Result<Tm, DomainError> {
        Tm::mul(self, o)
    }
    fn div(&self, o: &Tm) -> Result<Tm, DomainError> {
        Tm::div(self, o)
    }
    fn scale(&self, s: f64) -> Result<Tm, DomainError> {
        Tm::scale(self, s)
    }
    fn div_scalar(&self, d: f64) -> Result<Tm, DomainError> {
        Tm::div_scalar(self, d)
    }
    fn apply(&self, f: Func) -> Result<Tm, DomainError> {
        Tm::apply(self, f)
    }
    fn range(&self) -> Interval {
        Tm::range(self)
    }
    fn is_zero(&self) -> bool {
        self.c == 0.0 && self.g.iter().all(|&g| g == 0.0) && self.r == Interval::ZERO
    }
}

/// Whether `field` can be evaluated over `states` states and `params`
/// parameters: a well-formed tape, one output per state, every output a
/// node of the tape.
pub(crate) fn check_field(
    field: &VectorField,
    states: usize,
    params: usize,
) -> Result<(), FlowError> {
    let ok = field.states == states
        && field.outputs.len() == states
        && field.controls.checked_add(field.disturbances) == Some(params)
        && field.tape.is_well_formed(field.vars())
        && field
            .outputs
            .iter()
            .all(|&o| (o as usize) < field.tape.nodes.len());
    if ok {
        Ok(())
    } else {
        Err(FlowError::Malformed)
    }
}

/// The Taylor coefficients `x_[0..=order]` of the solution of `ẋ = f(x, p)`
/// through `x` (one vector of coefficients per state).
pub fn taylor_coefficients<T: Coeff>(
    field: &VectorField,
    x: &[T],
    params: &[T],
    order: usize,
) -> Result<Vec<Vec<T>>, FlowError> {
    check_field(field, x.len(), params.len())?;
    let mut e = Engine::new(field, x, params);
    for k in 0..order {
        e.node_coefficients(k)?;
        let next: Vec<T> = field
            .outputs
            .iter()
            .map(|&o| {
                let fk = e.coef(o, k)?;
                Ok(fk.div_scalar(k as f64 + 1.0)?)
            })
            .collect::<Result<_, FlowError>>()?;
        for (xi, v) in e.xs.iter_mut().zip(next) {
            xi.push(v);
        }
    }
    Ok(e.xs)
}

/// `f(x, p)` evaluated in `T` arithmetic (one value per state).
pub fn eval_field<T: Coeff>(
    field: &VectorField,
    x: &[T],
    params: &[T],
) -> Result<Vec<T>, FlowError> {
    check_field(field, x.len(), params.len())?;
    let mut e = Engine::new(field, x, params);
    e.smooth = false;
    e.node_coefficients(0)?;
    field.outputs.iter().map(|&o| e.coef(o, 0)).collect()
}

/// The series of every node, built one order at a time.
pub(super) struct Engine<'a, T> {
    field: &'a VectorField,
    /// The state series.
    xs: Vec<Vec<T>>,
    params: &'a [T],
    /// Each node's coefficients so far.
    nodes: Vec<Vec<T>>,
    /// Auxiliary series of a node (the companion of sin/cos, `1 ± t²`, the
    /// powers of a powi).
    aux: Vec<Vec<Vec<T>>>,
    /// A zero of the right shape (`None` with no state and no parameter).
    zero: Option<T>,
    /// Whether the node functions must be smooth (a Taylor expansion in
    /// time) or only evaluated (`abs` over a range through zero allowed).
    pub(super) smooth: bool,
}

impl<'a, T: Coeff> Engine<'a, T> {
    fn new(field: &'a VectorField, x: &[T], params: &'a [T]) -> Self {
        let len = field.tape.nodes.len();
        let zero = x.first().or(params.first()).map(|t| t.lift(0.0));
        Engine {
            field,
            xs: x.iter().map(|v| vec![v.clone()]).collect(),
            params,
            nodes: vec![Vec::new(); len],
            aux: vec![Vec::new(); len],
            zero,
            smooth: true,
        }
    }

    /// Coefficient `k` of node `id`.
    pub(super) fn coef(&self, id: u32, k: usize) -> Result<T, FlowError> {
        self.nodes
            .get(id as usize)
            .and_then(|s| s.get(k))
            .cloned()
            .ok_or(FlowError::Malformed)
    }

    /// The series of node `id` (coefficients computed so far).
    pub(super) fn series(&self, id: u32) -> Result<&[T], FlowError> {
        self.nodes
            .get(id as usize)
            .map(|s| s.as_slice())
            .ok_or(FlowError::Malformed)
    }

    pub(super) fn zero(&self) -> Result<T, FlowError> {
        self.zero.clone().ok_or(FlowError::Malformed)
    }

    pub(super) fn lift(&self, v: f64) -> Result<T, FlowError> {
        Ok(self.zero()?.lift(v))
    }

    /// Computes coefficient `k` of every node (coefficients `0..k` are there).
    fn node_coefficients(&mut self, k: usize) -> Result<(), FlowError> {
        for id in 0..self.field.tape.nodes.len() {
            let node = *self.field.tape.nodes.get(id).ok_or(FlowError::Malformed)?;
            let v = self.one(id, node, k)?;
            self.nodes.get_mut(id).ok_or(FlowError::Malformed)?.push(v);
        }
        Ok(())
    }

    /// Coefficient `k` of one node.
    fn one(&mut self, id: usize, node: Node, k: usize) -> Result<T, FlowError> {
        let n = self.xs.len();
        Ok(match node {
            Node::Const(c) if k == 0 => self.lift(c)?,
            Node::Const(_) => self.zero()?,
            Node::Var(v) if (v as usize) < n => self
                .xs
                .get(v as usize)
                .and_then(|s| s.get(k))
                .cloned()
                .ok_or(FlowError::Malformed)?,
            Node::Var(v) if k == 0 => self
                .params
                .get(v as usize - n)
                .cloned()
                .ok_or(FlowError::Malformed)?,
            Node::Var(_) => self.zero()?,
            Node::Neg(a) => self.coef(a, k)?.neg(),
            Node::Add(a, b) => self.coef(a, k)?.add(&self.coef(b, k)?)?,
            Node::Sub(a, b) => self.coef(a, k)?.sub(&self.coef(b, k)?)?,
            Node::Mul(a, b) => cauchy(self.series(a)?, self.series(b)?, k, (0, k), &self.zero()?)?,
            Node::Div(a, b) => {
                let q = self.series(id as u32)?;
                divide(&self.coef(a, k)?, self.series(b)?, q, k, &self.zero()?)?
            }
            Node::Powi(a, p) => self.powi(id, a, p, k)?,
            Node::Func(f, a) => self.func(id, f, a, k)?,
        })
    }

    /// Auxiliary series `slot` of node `id`, created on first use.
    pub(super) fn aux_mut(&mut self, id: usize, slot: usize) -> Result<&mut Vec<T>, FlowError> {
        let a = self.aux.get_mut(id).ok_or(FlowError::Malformed)?;
        while a.len() <= slot {
            a.push(Vec::new());
        }
        a.get_mut(slot).ok_or(FlowError::Malformed)
    }

    pub(super) fn aux(&self, id: usize, slot: usize) -> Result<&[T], FlowError> {
        self.aux
            .get(id)
            .and_then(|a| a.get(slot))
            .map(|s| s.as_slice())
            .ok_or(FlowError::Malformed)
    }
}

/// `Σ_{j=from}^{to} a_j b_{k−j}` (`to ≤ k`; exact zeros skipped; `zero`
/// if empty).
pub(crate) fn cauchy<T: Coeff>(
    a: &[T],
    b: &[T],
    k: usize,
    (from, to): (usize, usize),
    zero: &T,
) -> Result<T, FlowError> {
    let mut s: Option<T> = None;
    for j in from..=to.min(k) {
        let (Some(aj), Some(bk)) = (a.get(j), b.get(k - j)) else {
            return Err(FlowError::Malformed);
        };
        if aj.is_zero() || bk.is_zero() {
            continue;
        }
        let p = aj.mul(bk)?;
        s = Some(match s {
            None => p,
            Some(s) => s.add(&p)?,
        });
    }
    Ok(s.unwrap_or_else(|| zero.clone()))
}

/// `Σ_{j=1}^{k} j·a_j·b_{k−j}` (the sum of the exp and sin/cos recurrences;
/// `upto` may stop it at `k − 1`).
pub(crate) fn weighted<T: Coeff>(
    a: &[T],
    b: &[T],
    k: usize,
    upto: usize,
    zero: &T,
) -> Result<T, FlowError> {
    let mut s: Option<T> = None;
    for j in 1..=upto.min(k) {
        let (Some(aj), Some(bk)) = (a.get(j), b.get(k - j)) else {
            return Err(FlowError::Malformed);
        };
        if aj.is_zero() || bk.is_zero() {
            continue;
        }
        let p = aj.mul(bk)?.scale(j as f64)?;
        s = Some(match s {
            None => p,
            Some(s) => s.add(&p)?,
        });
    }
    Ok(s.unwrap_or_else(|| zero.clone()))
}

/// Coefficient `k` of `q = a/b` given `a_k`, `b` and `q_0..q_{k−1}`.
pub(crate) fn divide<T: Coeff>(
    ak: &T,
    b: &[T],
    q: &[T],
    k: usize,
    zero: &T,
) -> Result<T, FlowError> {
    let b0 = b.first().ok_or(FlowError::Malformed)?;
    if k == 0 {
        return Ok(ak.div(b0)?);
    }
    let s = cauchy(b, q, k, (1, k), zero)?;
    Ok(ak.sub(&s)?.div(b0)?)
}
