//! Expressions of a system block: named constants, a nonlinear plant's
//! `der`/`next` equations (→ a [`VectorField`] tape), and the affine maps
//! `observe` (state → the controller's inputs) and `actuate` (the
//! network's outputs → the control).
//!
//! Every expression is built into a [`Tape`] over the vectors its context
//! allows, folding constants as it goes: a constant divisor 0, a
//! non-integer exponent, an unknown function or name, a wrong arity or a
//! constant that overflows is reported at its span. `observe` and `actuate`
//! entries are then read back from their tape as affine forms (the first
//! node that is not affine is reported). A plant's tape is also evaluated
//! in `f64` at the centre and the corners of the initial set's bounding box
//! ([`defined_at_points`]): a division by 0, `sqrt` of a negative or `log`
//! of a non-positive number there is an error (the plant is not defined).

use std::collections::BTreeMap;

use nalgebra::{DMatrix, DVector};

use super::Ctx;
use ravel_analysis::sets::IBox;
use ravel_base::expr::{Func, Id, Node, Tape, Time, VectorField};
use ravel_base::limits::{MAX_CORNER_EVALUATIONS, MAX_MAGNITUDE};
use ravel_syntax::ast::*;
use ravel_syntax::diag::{compact, did_you_mean, Code, Diagnostic};

/// The names an expression may use: constants, and vectors at offsets of
/// the tape's variable vector.
pub(super) struct Scope<'a> {
    /// Named constants (with `pi`).
    pub consts: &'a BTreeMap<String, f64>,
    /// `(name, dimension, first variable)` of each vector allowed here.
    pub vectors: Vec<(&'a str, usize, u32)>,
    /// Vectors known to the system but not allowed here, with the reason.
    pub forbidden: Vec<(&'a str, &'a str)>,
}

/// The value of a sub-expression while a tape is built.
#[derive(Clone, Copy)]
enum Val {
    /// Folded to a constant.
    Const(f64),
    /// A node of the tape.
    Node(Id),
}

/// A tape under construction with the span of each node.
pub(super) struct Builder {
    /// The nodes.
    pub tape: Tape,
    /// `spans[id]`: where node `id` was written.
    pub spans: Vec<Span>,
}

impl Builder {
    pub(super) fn new() -> Builder {
        Builder {
            tape: Tape::new(),
            spans: Vec::new(),
        }
    }

    fn push(&mut self, node: Node, span: Span) -> Id {
        self.spans.push(span);
        self.tape.push(node)
    }

    /// The node of a value (a constant gets its own node).
    fn node(&mut self, v: Val, span: Span) -> Id {
        match v {
            Val::Node(id) => id,
            Val::Const(c) => self.push(Node::Const(c), span),
        }
    }

    /// Build `e` into the tape: its node id, or `None` after reporting.
    pub(super) fn root(&mut self, cx: &mut Ctx, scope: &Scope, e: &Spanned<Expr>) -> Option<Id> {
        let v = self.build(cx, scope, e)?;
        Some(self.node(v, e.span))
    }

    fn build(&mut self, cx: &mut Ctx, scope: &Scope, e: &Spanned<Expr>) -> Option<Val> {
        match &e.node {
            Expr::Number(v) => literal(cx, *v, e.span).map(Val::Const),
            Expr::Name(name) => constant(cx, scope, name, e.span).map(Val::Const),
            Expr::Component(c) => {
                let var = variable(cx, scope, c)?;
                Some(Val::Node(self.push(Node::Var(var), e.span)))
            }
            Expr::Neg(a) => match self.build(cx, scope, a)? {
                Val::Const(c) => Some(Val::Const(-c)),
                Val::Node(id) => Some(Val::Node(self.push(Node::Neg(id), e.span))),
            },
            Expr::Chain { first, rest } => {
                let mut acc = self.build(cx, scope, first);
                for (op, rhs) in rest {
                    let r = self.build(cx, scope, rhs);
                    if let (BinOp::Div, Some(Val::Const(d))) = (op, r) {
                        if d == 0.0 {
                            zero_divisor(cx, rhs.span);
                            acc = None;
                            continue;
                        }
                    }
                    let span = Span::new(first.span.start, rhs.span.end);
                    acc = match (acc, r) {
                        (Some(Val::Const(a)), Some(Val::Const(b))) => {
                            let v = match op {
                                BinOp::Add => a + b,
                                BinOp::Sub => a - b,
                                BinOp::Mul => a * b,
                                BinOp::Div => a / b,
                            };
                            folded(cx, v, span).map(Val::Const)
                        }
                        (Some(a), Some(b)) => {
                            let (a, b) = (self.node(a, first.span), self.node(b, rhs.span));
                            let node = match op {
                                BinOp::Add => Node::Add(a, b),
                                BinOp::Sub => Node::Sub(a, b),
                                BinOp::Mul => Node::Mul(a, b),
                                BinOp::Div => Node::Div(a, b),
                            };
                            Some(Val::Node(self.push(node, span)))
                        }
                        _ => None,
                    };
                }
                acc
            }
            Expr::Pow { base, exp } => {
                let b = self.build(cx, scope, base);
                let n = self
                    .build(cx, scope, exp)
                    .and_then(|x| exponent(cx, x, exp.span));
                let (b, n) = (b?, n?);
                match b {
                    Val::Const(c) => {
                        if c == 0.0 && n < 0 {
                            zero_divisor(cx, base.span);
                            return None;
                        }
                        folded(cx, c.powi(n), e.span).map(Val::Const)
                    }
                    Val::Node(id) => Some(Val::Node(self.push(Node::Powi(id, n), e.span))),
                }
            }
            Expr::Call { func, args } => {
                let f = function(cx, func);
                if args.len() != 1 {
                    if let Some(f) = f {
                        cx.err(
                            Diagnostic::new(
                                Code::Arity,
                                e.span,
                                format!("`{}` takes one argument, not {}", f.name(), args.len()),
                            )
                            .label(format!("{} argument(s)", args.len()))
                            .hint(format!("write `{}(…)` with one expression", f.name())),
                        );
                    }
                    for a in args {
                        self.build(cx, scope, a);
                    }
                    return None;
                }
                let arg = args.first()?;
                let a = self.build(cx, scope, arg);
                let (f, a) = (f?, a?);
                match a {
                    Val::Const(c) => {
                        let v = f.apply(c);
                        if v.is_nan() || (f == Func::Log && c == 0.0) {
                            undefined_constant(cx, f, c, arg.span);
                            return None;
                        }
                        folded(cx, v, e.span).map(Val::Const)
                    }
                    Val::Node(id) => Some(Val::Node(self.push(Node::Func(f, id), e.span))),
                }
            }
        }
    }
}

/// A literal: finite and within ±[`MAX_MAGNITUDE`].
fn literal(cx: &mut Ctx, v: f64, span: Span) -> Option<f64> {
    let before = cx.diags.len();
    let x = cx.finite(&Spanned { node: v, span });
    (cx.diags.len() == before).then_some(x)
}

/// A folded constant: finite (an overflow is reported at `span`).
fn folded(cx: &mut Ctx, v: f64, span: Span) -> Option<f64> {
    if v.is_finite() {
        return Some(v);
    }
    cx.err(
        Diagnostic::new(
            Code::NonFinite,
            span,
            format!("this constant expression is {}", compact(v)),
        )
        .label("not a finite number")
        .hint("constant parts of an expression must evaluate to finite numbers"),
    );
    None
}

fn zero_divisor(cx: &mut Ctx, span: Span) {
    cx.err(
        Diagnostic::new(Code::ZeroDivisor, span, "division by zero")
            .label("this divisor is the constant 0")
            .hint("a divisor must not be 0; check the constants it is made of"),
    );
}

fn undefined_constant(cx: &mut Ctx, f: Func, c: f64, span: Span) {
    cx.err(
        Diagnostic::new(
            Code::Undefined,
            span,
            format!("`{}` is not defined at {}", f.name(), compact(c)),
        )
        .label("outside the function's domain")
        .hint(domain_hint(f)),
    );
}

fn domain_hint(f: Func) -> &'static str {
    match f {
        Func::Sqrt => "`sqrt` needs an argument ≥ 0",
        Func::Log => "`log` needs an argument > 0",
        _ => "the argument must lie in the function's domain",
    }
}

/// The integer an exponent folds to.
fn exponent(cx: &mut Ctx, v: Val, span: Span) -> Option<i32> {
    let (msg, label) = match v {
        Val::Const(c) if c.fract() == 0.0 && c.abs() <= f64::from(i32::MAX) => {
            return Some(c as i32)
        }
        Val::Const(c) if c.fract() == 0.0 => (
            format!("the exponent {} is too large", compact(c)),
            "beyond ±2147483647",
        ),
        Val::Const(c) => (
            format!("the exponent {} is not an integer", compact(c)),
            "not an integer",
        ),
        Val::Node(_) => (
            "the exponent is not a constant".to_string(),
            "depends on a variable",
        ),
    };
    cx.err(
        Diagnostic::new(Code::Exponent, span, msg)
            .label(label)
            .hint("`^` takes a constant integer exponent (e.g. `x[0]^2`, `x[0]^-1`); write `sqrt(…)` or `exp(b * log(a))` otherwise"),
    );
    None
}

/// The function named `func`, or an unknown-function diagnostic.
fn function(cx: &mut Ctx, func: &Spanned<String>) -> Option<Func> {
    if let Some(f) = Func::from_name(&func.node) {
        return Some(f);
    }
    let names: Vec<&str> = Func::ALL.iter().map(|f| f.name()).collect();
    let list = names.join(", ");
    let hint = match did_you_mean(&func.node, names.iter().copied()) {
        Some(s) => format!("did you mean `{s}`? The functions are {list}"),
        None => format!("the functions are {list}"),
    };
    cx.err(
        Diagnostic::new(
            Code::UnknownFunction,
            func.span,
            format!("unknown function `{}`", func.node),
        )
        .label("not a function")
        .hint(hint),
    );
    None
}

/// A constant's value (`pi` or a `const`), or an unknown-name diagnostic.
fn constant(cx: &mut Ctx, scope: &Scope, name: &str, span: Span) -> Option<f64> {
    if let Some(v) = scope.consts.get(name) {
        return Some(*v);
    }
    let vector = scope
        .vectors
        .iter()
        .map(|(v, _, _)| *v)
        .chain(scope.forbidden.iter().map(|(v, _)| *v))
        .find(|v| *v == name);
    let mut d = Diagnostic::new(Code::UnknownName, span, format!("unknown name `{name}`"))
        .label("not defined");
    d = if let Some(v) = vector {
        d.hint(format!("`{v}` is a vector: write a component, `{v}[0]`"))
    } else {
        let known: Vec<&str> = scope
            .consts
            .keys()
            .map(String::as_str)
            .chain(scope.vectors.iter().map(|(v, _, _)| *v))
            .collect();
        match did_you_mean(name, known.iter().copied()) {
            Some(s) => d.hint(format!("did you mean `{s}`?")),
            None => d.hint(format!(
                "expressions use numbers, `pi`, the constants defined with `const`, and components such as `{}[0]`",
                scope.vectors.first().map_or("x", |v| v.0)
            )),
        }
    };
    cx.err(d);
    None
}

/// The variable of `x[i]` in the scope's variable vector.
fn variable(cx: &mut Ctx, scope: &Scope, c: &Component) -> Option<u32> {
    let name = c.name.node.as_str();
    if let Some((v, dim, at)) = scope.vectors.iter().find(|(v, _, _)| *v == name) {
        if c.index.node >= *dim as u64 {
            let hint = if *dim == 0 {
                format!(
                    "`{v}` has no components here{}",
                    if *v == "w" {
                        ": declare the disturbance with `w in box([lo, hi], …)`"
                    } else {
                        ""
                    }
                )
            } else {
                format!("indices run from 0 to {}", dim - 1)
            };
            cx.err(
                Diagnostic::new(
                    Code::IndexOutOfRange,
                    c.span,
                    format!("`{}[{}]` is out of range", name, c.index.node),
                )
                .label(format!("`{v}` has {dim} components"))
                .hint(hint),
            );
            return None;
        }
        return Some(at + c.index.node as u32);
    }
    if let Some((_, why)) = scope.forbidden.iter().find(|(v, _)| *v == name) {
        cx.err(
            Diagnostic::new(
                Code::NotAffine,
                c.span,
                format!("`{}` cannot appear here", c.name.node),
            )
            .label("not allowed in this expression")
            .hint(*why),
        );
        return None;
    }
    let known: Vec<&str> = scope.vectors.iter().map(|(v, _, _)| *v).collect();
    let list = known
        .iter()
        .map(|v| format!("`{v}`"))
        .collect::<Vec<_>>()
        .join(", ");
    let hint = match did_you_mean(name, known.iter().copied()) {
        Some(s) => format!("did you mean `{s}`? Components here refer to {list}"),
        None => format!("components here refer to {list}"),
    };
    cx.err(
        Diagnostic::new(
            Code::UnknownName,
            c.name.span,
            format!("unknown vector `{name}`"),
        )
        .label("not defined")
        .hint(hint),
    );
    None
}

/// The named constants, in order (each may use the ones before it), with
/// `pi`; a name defined twice or naming a vector is reported.
pub(super) fn constants(
    cx: &mut Ctx,
    consts: &[(&Spanned<String>, &Spanned<Expr>)],
    vectors: &[(&str, Option<Span>)],
) -> BTreeMap<String, f64> {
    let mut values = BTreeMap::new();
    values.insert("pi".to_string(), std::f64::consts::PI);
    let mut seen: BTreeMap<&str, Span> = BTreeMap::new();
    for (name, value) in consts {
        let key = name.node.as_str();
        if key == "pi" {
            cx.err(
                Diagnostic::new(Code::Duplicate, name.span, "`pi` is built in")
                    .label("defined again here")
                    .hint("choose another name for this constant"),
            );
            continue;
        }
        if let Some((v, at)) = vectors.iter().find(|(v, _)| *v == key) {
            let mut d = Diagnostic::new(
                Code::Duplicate,
                name.span,
                format!("the constant `{key}` shadows the vector `{v}`"),
            )
            .label("a vector's name")
            .hint("choose another name for this constant");
            if let Some(at) = at {
                d = d.related(*at, "the vector is declared here");
            }
            cx.err(d);
            continue;
        }
        if let Some(first) = seen.get(key) {
            cx.duplicate(&format!("the constant `{key}`"), *first, name.span);
            continue;
        }
        seen.insert(key, name.span);
        let scope = Scope {
            consts: &values,
            vectors: Vec::new(),
            forbidden: vectors
                .iter()
                .map(|(v, _)| (*v, "a constant is a number: it cannot depend on a vector"))
                .collect(),
        };
        let mut b = Builder::new();
        let before = cx.diags.len();
        let v = b.build(cx, &scope, value);
        match v {
            Some(Val::Const(c)) => {
                if c.abs() > MAX_MAGNITUDE {
                    cx.err(
                        Diagnostic::new(
                            Code::Limit,
                            value.span,
                            format!("{} is too large to analyse", compact(c)),
                        )
                        .label("beyond ±1e15")
                        .hint("constants must lie within ±1e15; rescale the units"),
                    );
                } else {
                    values.insert(key.to_string(), c);
                }
            }
            Some(Val::Node(_)) | None => {
                if cx.diags.len() == before {
                    cx.err(
                        Diagnostic::new(
                            Code::WrongKind,
                            value.span,
                            format!("`{key}` is not a constant"),
                        )
                        .label("not a number")
                        .hint("a constant is a number: it cannot depend on a vector"),
                    );
                }
            }
        }
    }
    values
}

/// The equations of a nonlinear plant, as written.
pub(super) type Equations<'a> = [(&'a Spanned<EquationKind>, &'a Component, &'a Spanned<Expr>)];

/// A checked nonlinear right-hand side and the span of each tape node.
pub(super) struct Field {
    pub field: VectorField,
    pub spans: Vec<Span>,
}

/// The sizes of a nonlinear plant: the state `(name, n)`, the control
/// `(name, m)` and the disturbance dimension `p`.
pub(super) struct Dims<'a> {
    pub state: (&'a str, usize),
    pub control: (&'a str, usize),
    pub p: usize,
}

/// Build the vector field of `der`/`next` lines: one line per state
/// component, of one kind, matching the time declaration (`dt`: `Some` for
/// continuous time; `time_ok`: whether the declaration itself was valid).
pub(super) fn field(
    cx: &mut Ctx,
    eqs: &Equations,
    consts: &BTreeMap<String, f64>,
    dims: &Dims,
    (dt, time_ok, time_span): (Option<f64>, bool, Option<Span>),
    sys_span: Span,
) -> Option<Field> {
    let ((xn, n), (un, m), p) = (dims.state, dims.control, dims.p);
    let mut ok = true;
    // one kind of equation, matching the time
    let first_kind = eqs.first().map(|(k, _, _)| k.node)?;
    if let Some((k, _, _)) = eqs.iter().find(|(k, _, _)| k.node != first_kind) {
        let (first, other) = if first_kind == EquationKind::Der {
            ("der", "next")
        } else {
            ("next", "der")
        };
        cx.err(
            Diagnostic::new(
                Code::PlantKind,
                k.span,
                format!("`{other}` after `{first}`: a plant is either continuous-time (`der`) or discrete-time (`next`)"),
            )
            .label(format!("a `{other}` line"))
            .related(eqs.first().map_or(k.span, |(k, _, _)| k.span), format!("the first line is `{first}`"))
            .hint("write every state component's line with the same keyword"),
        );
        ok = false;
    } else if time_ok {
        let at = eqs.first().map_or(sys_span, |(k, _, _)| k.span);
        match (first_kind, dt) {
            (EquationKind::Der, None) => {
                let mut d = Diagnostic::new(
                    Code::PlantKind,
                    at,
                    "`der` defines a continuous-time plant, but the time is discrete",
                )
                .label("a derivative")
                .hint("declare `time continuous dt …` (dt: the control period), or write `next x[i] = …` for a discrete-time plant");
                if let Some(t) = time_span {
                    d = d.related(t, "the time is declared here");
                }
                cx.err(d);
                ok = false;
            }
            (EquationKind::Next, Some(_)) => {
                let mut d = Diagnostic::new(
                    Code::PlantKind,
                    at,
                    "`next` defines a discrete-time plant, but the time is continuous",
                )
                .label("a next-step value")
                .hint("declare `time discrete` (or no time), or write `der x[i] = …` for a continuous-time plant");
                if let Some(t) = time_span {
                    d = d.related(t, "the time is declared here");
                }
                cx.err(d);
                ok = false;
            }
            _ => {}
        }
    } else {
        ok = false;
    }
    // exactly one line per state component
    let mut line: Vec<Option<(Span, &Spanned<Expr>)>> = vec![None; n];
    for (_, target, expr) in eqs {
        let Some(k) = cx.component(target, xn, n) else {
            ok = false;
            continue;
        };
        match line.get_mut(k) {
            Some(Some((first, _))) => {
                cx.duplicate(&format!("the equation of `{xn}[{k}]`"), *first, target.span);
                ok = false;
            }
            Some(slot) => *slot = Some((target.span, *expr)),
            None => ok = false,
        }
    }
    let missing: Vec<String> = line
        .iter()
        .enumerate()
        .filter(|(_, l)| l.is_none())
        .map(|(k, _)| format!("{xn}[{k}]"))
        .collect();
    if let Some(first) = missing.first() {
        let kw = if first_kind == EquationKind::Der {
            "der"
        } else {
            "next"
        };
        cx.err(
            Diagnostic::new(
                Code::Missing,
                sys_span,
                format!("no equation defines {}", super::name_list(&missing)),
            )
            .label("in this system")
            .hint(format!(
                "add `{kw} {first} = …`: every state component needs one line"
            )),
        );
        ok = false;
    }
    let scope = Scope {
        consts,
        vectors: vec![(xn, n, 0), (un, m, n as u32), ("w", p, (n + m) as u32)],
        forbidden: Vec::new(),
    };
    let mut b = Builder::new();
    let mut outputs = Vec::with_capacity(n);
    for l in &line {
        let out = l.and_then(|(_, e)| b.root(cx, &scope, e));
        match out {
            Some(id) => outputs.push(id),
            None => ok = false,
        }
    }
    // the lines were built in component order: the tape stays topological
    let time = match dt {
        Some(period) => Time::Continuous { period },
        None => Time::Discrete,
    };
    ok.then_some(Field {
        field: VectorField {
            tape: b.tape,
            outputs,
            states: n,
            controls: m,
            disturbances: p,
            time,
        },
        spans: b.spans,
    })
}

/// An affine map `y = M z + d` read from a list of expressions over one
/// vector `(name, dim)`: `M` is `entries × dim`.
pub(super) fn affine(
    cx: &mut Ctx,
    exprs: &[Spanned<Expr>],
    consts: &BTreeMap<String, f64>,
    (name, dim): (&str, usize),
    forbidden: Vec<(&str, &str)>,
    what: &str,
) -> Option<(DMatrix<f64>, DVector<f64>)> {
    let scope = Scope {
        consts,
        vectors: vec![(name, dim, 0)],
        forbidden,
    };
    let mut m = DMatrix::zeros(exprs.len(), dim);
    let mut d = DVector::zeros(exprs.len());
    let mut ok = true;
    for (k, e) in exprs.iter().enumerate() {
        let mut b = Builder::new();
        let Some(root) = b.root(cx, &scope, e) else {
            ok = false;
            continue;
        };
        match affine_form(cx, &b, root, what, name) {
            Some((coef, c)) => {
                for (j, v) in coef {
                    if let Some(x) = m.get_mut((k, j)) {
                        *x = v;
                    }
                }
                if let Some(x) = d.get_mut(k) {
                    *x = c;
                }
            }
            None => ok = false,
        }
    }
    ok.then_some((m, d))
}

/// An affine form: sparse coefficients and a constant.
type Aff = (BTreeMap<usize, f64>, f64);

/// The affine form of node `root` of a tape whose constants are folded,
/// or a diagnostic at the first node that is not affine.
fn affine_form(cx: &mut Ctx, b: &Builder, root: Id, what: &str, var: &str) -> Option<Aff> {
    let mut forms: Vec<Aff> = Vec::with_capacity(b.tape.nodes.len());
    let take = |forms: &mut Vec<Aff>, id: Id| -> Aff {
        forms
            .get_mut(id as usize)
            .map(std::mem::take)
            .unwrap_or_default()
    };
    let is_const = |a: &Aff| a.0.values().all(|v| *v == 0.0);
    for (i, node) in b.tape.nodes.iter().enumerate() {
        let span = b.spans.get(i).copied().unwrap_or_default();
        let not_affine = |cx: &mut Ctx, why: &str| {
            cx.err(
                Diagnostic::new(
                    Code::NotAffine,
                    span,
                    format!("{what} must be affine in `{var}`, but this is {why}"),
                )
                .label("not affine")
                .hint(format!("use sums of constants times components of `{var}`, and constants (a linear map plus an offset)")),
            );
        };
        let f: Aff = match *node {
            Node::Const(c) => (BTreeMap::new(), c),
            Node::Var(v) => (BTreeMap::from([(v as usize, 1.0)]), 0.0),
            Node::Neg(a) => {
                let (mut co, c) = take(&mut forms, a);
                co.values_mut().for_each(|v| *v = -*v);
                (co, -c)
            }
            Node::Add(a, b2) | Node::Sub(a, b2) => {
                let sign = if matches!(node, Node::Add(..)) {
                    1.0
                } else {
                    -1.0
                };
                let (mut co, c) = take(&mut forms, a);
                let (co2, c2) = take(&mut forms, b2);
                for (j, v) in co2 {
                    *co.entry(j).or_insert(0.0) += sign * v;
                }
                (co, c + sign * c2)
            }
            Node::Mul(a, b2) => {
                let (fa, fb) = (take(&mut forms, a), take(&mut forms, b2));
                let (k, mut other) = if is_const(&fa) {
                    (fa.1, fb)
                } else if is_const(&fb) {
                    (fb.1, fa)
                } else {
                    not_affine(cx, "a product of two variable terms");
                    return None;
                };
                other.0.values_mut().for_each(|v| *v *= k);
                (other.0, other.1 * k)
            }
            Node::Div(a, b2) => {
                let (mut fa, fb) = (take(&mut forms, a), take(&mut forms, b2));
                if !is_const(&fb) {
                    not_affine(cx, "a division by a variable term");
                    return None;
                }
                if fb.1 == 0.0 {
                    zero_divisor(cx, b.spans.get(b2 as usize).copied().unwrap_or(span));
                    return None;
                }
                fa.0.values_mut().for_each(|v| *v /= fb.1);
                (fa.0, fa.1 / fb.1)
            }
            Node::Powi(a, 1) => take(&mut forms, a),
            Node::Powi(..) => {
                not_affine(cx, "a power of a variable term");
                return None;
            }
            Node::Func(f, _) => {
                not_affine(cx, &format!("`{}` of a variable term", f.name()));
                return None;
            }
        };
        if !f.1.is_finite() || f.0.values().any(|v| !v.is_finite()) {
            folded(cx, f64::INFINITY, span);
            return None;
        }
        forms.push(f);
    }
    Some(take(&mut forms, root))
}

/// The points at which a nonlinear plant must be defined: the centre and
/// (when there are few enough) the corners of `x0` (the initial set's
/// bounding box), with the control at the centre of `limits` (0 without)
/// and the disturbance at the centre of `w`.
fn sample_points(
    x0: &IBox,
    limits: Option<&IBox>,
    m: usize,
    w: &IBox,
    nodes: usize,
) -> Vec<Vec<f64>> {
    let mid = |lo: f64, hi: f64| {
        let c = 0.5 * lo + 0.5 * hi;
        if c.is_finite() {
            c
        } else {
            0.0
        }
    };
    let u: Vec<f64> = match limits {
        Some(l) => l.lo.iter().zip(&l.hi).map(|(a, b)| mid(*a, *b)).collect(),
        None => vec![0.0; m],
    };
    let wc: Vec<f64> = w.lo.iter().zip(&w.hi).map(|(a, b)| mid(*a, *b)).collect();
    let n = x0.dim();
    let centre: Vec<f64> = x0.lo.iter().zip(&x0.hi).map(|(a, b)| mid(*a, *b)).collect();
    let mut xs = vec![centre];
    // corners while 2^n × nodes stays within 10^7 evaluations
    if n < 24 && (1usize << n).saturating_mul(nodes.max(1)) <= MAX_CORNER_EVALUATIONS {
        for k in 0..(1usize << n) {
            xs.push(
                (0..n)
                    .map(|i| {
                        let (lo, hi) = (x0.lo.get(i), x0.hi.get(i));
                        let pick = if k >> i & 1 == 1 { hi } else { lo };
                        pick.copied().unwrap_or(0.0)
                    })
                    .collect(),
            );
        }
    }
    xs.into_iter()
        .map(|x| {
            x.into_iter()
                .chain(u.iter().copied())
                .chain(wc.iter().copied())
                .collect()
        })
        .collect()
}

/// The plant is defined at the points of [`sample_points`]: no division
/// by 0, `sqrt` of a negative, `log` of a non-positive number or negative
/// power of 0 there (each node reported once, at its first such point).
pub(super) fn defined_at_points(
    cx: &mut Ctx,
    f: &Field,
    x0: &IBox,
    limits: Option<&IBox>,
    w: &IBox,
    names: (&str, &str),
) {
    let tape = &f.field.tape;
    let points = sample_points(x0, limits, f.field.controls, w, tape.nodes.len());
    let mut reported = vec![false; tape.nodes.len()];
    let mut values = Vec::new();
    let n = f.field.states;
    for (k, point) in points.iter().enumerate() {
        tape.eval_into(point, &mut values);
        let at = |id: Id| values.get(id as usize).copied().unwrap_or(f64::NAN);
        for (i, node) in tape.nodes.iter().enumerate() {
            let problem = match *node {
                Node::Div(_, b) if at(b) == 0.0 => Some((b, "a divisor is 0", "division by 0")),
                Node::Powi(a, e) if e < 0 && at(a) == 0.0 => {
                    Some((a, "a negative power of 0", "0 to a negative power"))
                }
                Node::Func(Func::Sqrt, a) if at(a) < 0.0 => {
                    Some((a, "`sqrt` of a negative number", "negative here"))
                }
                Node::Func(Func::Log, a) if at(a) <= 0.0 => {
                    Some((a, "`log` of a non-positive number", "≤ 0 here"))
                }
                _ => None,
            };
            let Some((arg, what, label)) = problem else {
                continue;
            };
            if reported.get(i).copied().unwrap_or(true) {
                continue;
            }
            if let Some(r) = reported.get_mut(i) {
                *r = true;
            }
            let x: Vec<String> = point.iter().take(n).map(|v| compact(*v)).collect();
            let u: Vec<String> = point
                .iter()
                .skip(n)
                .take(f.field.controls)
                .map(|v| compact(*v))
                .collect();
            let place = if k == 0 {
                "the centre of the initial set"
            } else {
                "a corner of the initial set's bounding box"
            };
            let span = f.spans.get(arg as usize).copied().unwrap_or_default();
            cx.err(
                Diagnostic::new(
                    Code::Undefined,
                    span,
                    format!(
                        "the plant is not defined at {place}: {what} at {} = [{}], {} = [{}]",
                        names.0,
                        super::name_list(&x),
                        names.1,
                        super::name_list(&u)
                    ),
                )
                .label(label)
                .hint("the right-hand side must be defined on the whole initial set (and along the trajectories): guard the divisor or the argument, or change the initial set"),
            );
        }
    }
}

/// One inequality of a set, checked: a linear row `a·z ≤ b`, or a
/// constraint `g(z) ≤ 0` (the last node of its tape) that is not affine,
/// with the span of its first non-affine node.
pub(super) enum SetIneq {
    /// `a·z ≤ b`.
    Row(Vec<f64>, f64),
    /// `g(z) ≤ 0`.
    Nonlinear(Tape, Span),
}

/// An inequality `lhs ≤ rhs` (or `≥`) over the vector `(name, dim)`, as
/// `lhs − rhs ≤ 0` (or `rhs − lhs ≤ 0`): a row when it is affine (its
/// constants folded in `f64`, as in a plant's expressions), else a
/// nonlinear constraint. Names, arities, exponents and constants are
/// checked exactly as in a plant's expressions.
pub(super) fn set_inequality(
    cx: &mut Ctx,
    ineq: &Inequality,
    consts: &BTreeMap<String, f64>,
    (name, dim): (&str, usize),
) -> Option<SetIneq> {
    let scope = Scope {
        consts,
        vectors: vec![(name, dim, 0)],
        forbidden: Vec::new(),
    };
    let mut b = Builder::new();
    let lhs = b.root(cx, &scope, &ineq.lhs);
    let rhs = b.root(cx, &scope, &ineq.rhs);
    let (lhs, rhs) = (lhs?, rhs?);
    let g = match ineq.cmp {
        Cmp::Le => b.push(Node::Sub(lhs, rhs), ineq.span),
        Cmp::Ge => b.push(Node::Sub(rhs, lhs), ineq.span),
    };
    // affine? (asked quietly: a non-affine inequality is not an error here)
    let mut quiet = Ctx::new();
    if let Some((coef, c)) = affine_form(&mut quiet, &b, g, "an inequality", name) {
        let mut row = vec![0.0; dim];
        for (j, v) in coef {
            if let Some(x) = row.get_mut(j) {
                *x = v;
            }
        }
        // a·z + c ≤ 0  ⇔  a·z ≤ −c
        return Some(SetIneq::Row(row, -c));
    }
    let span = quiet
        .diags
        .iter()
        .find(|d| d.code == Code::NotAffine)
        .and_then(|d| d.span)
        .unwrap_or(ineq.span);
    // the tape ends in `g`
    Some(SetIneq::Nonlinear(b.tape, span))
}
