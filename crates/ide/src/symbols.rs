//! The names a spec declares, where, and what they are: vectors with their
//! sizes, matrices with their shapes, constants with their values, sets
//! with their kind and dimension, properties. Read from the syntax tree
//! when the text parses; while it does not (as it often does not while
//! being typed), from the tokens after each declaring keyword, with less
//! detail.

use std::collections::BTreeMap;

use ravel_base::text::{compact, sanitize};
use ravel_syntax::ast::{
    AvoidDef, BinOp, BoxSet, Expr, Item, SetAtom, SetDef, SetExpr, Span, Spanned, SystemStmt, Value,
};

use crate::{TokKind, Token};

/// What kind of thing a declared name is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SymbolKind {
    /// A system or a network block's name.
    Block,
    /// A state, control, noise or network input/output vector.
    Vector,
    /// A plant matrix or vector (`A`, `B`, `c`, `C`).
    Matrix,
    /// A `const`.
    Constant,
    /// A set: initial, goal, avoid, input set, requirement.
    Set,
    /// A robustness, radius or selection property.
    Property,
}

/// One declared name.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Symbol {
    /// The name.
    pub name: String,
    /// Where it is declared (the name itself).
    pub span: Span,
    /// Its kind.
    pub kind: SymbolKind,
    /// A vector's number of components.
    pub dim: Option<u64>,
    /// What it is, in one line of Markdown (e.g. "state vector, 2 components").
    what: String,
    /// More lines of Markdown, if any.
    more: Vec<String>,
}

impl Symbol {
    fn new(name: &Spanned<String>, kind: SymbolKind, what: String) -> Symbol {
        Symbol {
            name: name.node.clone(),
            span: name.span,
            kind,
            dim: None,
            what,
            more: Vec::new(),
        }
    }

    /// One line: what the name is.
    pub fn summary(&self) -> String {
        self.what.clone()
    }

    /// The hover text: the name as code, what it is, and more.
    pub fn markdown(&self) -> String {
        let mut s = format!("```ravel\n{}\n```\n{}", self.name, self.what);
        for m in &self.more {
            s.push_str("\n\n");
            s.push_str(m);
        }
        s
    }
}

/// `ℝⁿ` written with a superscript size.
fn real_space(n: u64) -> String {
    const SUP: [char; 10] = ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'];
    let digits: String = n
        .to_string()
        .chars()
        .map(|c| SUP[c.to_digit(10).unwrap_or(0) as usize])
        .collect();
    format!("ℝ{digits}")
}

fn components(n: u64) -> String {
    if n == 1 {
        "1 component".to_string()
    } else {
        format!("{n} components")
    }
}

/// A value's shape, e.g. "2 × 3 matrix".
fn shape(v: &Value) -> String {
    match v {
        Value::Matrix(rows) => {
            let cols: Vec<usize> = rows.iter().map(|r| r.node.len()).collect();
            if cols.windows(2).all(|w| w[0] == w[1]) {
                format!(
                    "{} × {} matrix",
                    rows.len(),
                    cols.first().copied().unwrap_or(0)
                )
            } else {
                format!("ragged matrix of {} rows", rows.len())
            }
        }
        Value::Vector(v) => format!("vector of {}", v.len()),
        Value::Eye(n) => format!("{0} × {0} identity matrix", n.node),
        Value::Zeros(r, Some(c)) => format!("{} × {} zero matrix", r.node, c.node),
        Value::Zeros(r, None) => format!("zeros({})", r.node),
        Value::Scalar(x) => format!("scalar {}", compact(*x)),
        Value::PerStep(vs) => match vs.first() {
            Some(first) => format!(
                "per step: {} values, the first a {}",
                vs.len(),
                shape(&first.node)
            ),
            None => "per step: no values".to_string(),
        },
    }
}

/// A plant matrix's role in the closed loop.
fn role(name: &str) -> Option<&'static str> {
    match name {
        "A" => Some("state matrix: x' = A x + B u + c + w"),
        "B" => Some("input matrix: x' = A x + B u + c + w"),
        "c" => Some("constant input (e.g. gravity): x' = A x + B u + c + w"),
        "C" => Some("observation matrix: the controller sees y = Cᵀ x + v (one observation per column; default eye(n))"),
        _ => None,
    }
}

/// A set's kind: "box", "polytope of 3 constraints", "union of 2 sets (box, polytope)".
fn set_kind(set: &SetExpr) -> String {
    let one = |a: &SetAtom| match a {
        SetAtom::Box(BoxSet::Named(v)) => format!("box ({} bounded components)", v.len()),
        SetAtom::Box(BoxSet::Positional(v)) => format!("box of {} intervals", v.len()),
        SetAtom::Polytope(cs) => format!("polytope of {} constraints", cs.len()),
        SetAtom::Inequalities(rows) => format!("set of {} inequalities", rows.len()),
        SetAtom::Ball(b) => format!(
            "ℓ{} ball around a centre of {}",
            b.norm.as_ref().map_or("∞", |n| match n.node.as_str() {
                "inf" => "∞",
                "1" => "1",
                _ => "2",
            }),
            b.center.node.len()
        ),
    };
    match set.members.as_slice() {
        [m] => one(&m.node),
        ms => {
            let parts: Vec<String> = ms.iter().map(|m| one(&m.node)).collect();
            format!("union of {} sets: {}", ms.len(), parts.join("; "))
        }
    }
}

/// The value of a constant expression, when it is made of numbers, `pi`
/// and constants already known.
fn eval(e: &Expr, consts: &BTreeMap<String, f64>) -> Option<f64> {
    Some(match e {
        Expr::Number(x) => *x,
        Expr::Name(n) if n == "pi" => std::f64::consts::PI,
        Expr::Name(n) => *consts.get(n)?,
        Expr::Neg(a) => -eval(&a.node, consts)?,
        Expr::Chain { first, rest } => {
            let mut v = eval(&first.node, consts)?;
            for (op, b) in rest {
                let b = eval(&b.node, consts)?;
                v = match op {
                    BinOp::Add => v + b,
                    BinOp::Sub => v - b,
                    BinOp::Mul => v * b,
                    BinOp::Div => v / b,
                };
            }
            v
        }
        Expr::Pow { base, exp } => {
            let k = eval(&exp.node, consts)?;
            if k.fract() != 0.0 || k.abs() > 64.0 {
                return None;
            }
            eval(&base.node, consts)?.powi(k as i32)
        }
        Expr::Component(_) | Expr::Call { .. } => return None,
    })
    .filter(|v: &f64| v.is_finite())
}

/// The source text of a span, shown safely and briefly.
fn text_of(source: &str, span: Span) -> String {
    let s = source.get(span.start..span.end).unwrap_or("");
    sanitize(&s.split_whitespace().collect::<Vec<_>>().join(" "))
}

/// The names `source` declares, in order.
pub(crate) fn table(source: &str, tokens: &[Token]) -> Vec<Symbol> {
    match ravel_syntax::parse(source) {
        Ok(spec) => from_tree(source, &spec.items),
        Err(_) => from_tokens(source, tokens),
    }
}

fn from_tree(source: &str, items: &[Item]) -> Vec<Symbol> {
    let mut out: Vec<Symbol> = Vec::new();
    // the vector each kind of set is over: the state, the network's input or output
    let mut state: Option<(String, u64)> = None;
    let mut net_in: Option<(String, u64)> = None;
    let mut net_out: Option<(String, u64)> = None;
    let mut consts: BTreeMap<String, f64> = BTreeMap::new();
    for item in items {
        match item {
            Item::System(s) => {
                out.push(Symbol::new(&s.name, SymbolKind::Block, "system (a closed loop)".into()));
                let control = s.stmts.iter().find_map(|st| match st {
                    SystemStmt::Control { name, .. } => Some(name.node.clone()),
                    _ => None,
                });
                for st in &s.stmts {
                    match st {
                        SystemStmt::State { name, dim, .. } => {
                            state.get_or_insert((name.node.clone(), dim.node));
                            let mut sym = Symbol::new(
                                name,
                                SymbolKind::Vector,
                                format!(
                                    "state vector, {} (`{}` ∈ {})",
                                    components(dim.node),
                                    name.node,
                                    real_space(dim.node)
                                ),
                            );
                            sym.dim = Some(dim.node);
                            out.push(sym);
                        }
                        SystemStmt::Control { name, dim, .. } => {
                            let mut sym = Symbol::new(
                                name,
                                SymbolKind::Vector,
                                format!(
                                    "control vector, {} (`{}` ∈ {}): the controller's output",
                                    components(dim.node),
                                    name.node,
                                    real_space(dim.node)
                                ),
                            );
                            sym.dim = Some(dim.node);
                            out.push(sym);
                        }
                        SystemStmt::Bound { name, set, .. } => {
                            let n = match &set.node {
                                BoxSet::Named(v) => v.len(),
                                BoxSet::Positional(v) => v.len(),
                            } as u64;
                            if Some(&name.node) == control.as_ref() {
                                if let Some(c) = out.iter_mut().find(|x| x.name == name.node) {
                                    c.more.push(format!(
                                        "saturated to a box of {} (`{}`)",
                                        components(n),
                                        text_of(source, set.span)
                                    ));
                                }
                            } else if name.node == "w" || name.node == "v" {
                                let what = if name.node == "w" {
                                    "process noise"
                                } else {
                                    "sensor noise"
                                };
                                let mut sym = Symbol::new(
                                    name,
                                    SymbolKind::Vector,
                                    format!(
                                        "{what} vector, {} (`{}` ∈ {}): adversarial, any value in its box at every step",
                                        components(n),
                                        name.node,
                                        real_space(n)
                                    ),
                                );
                                sym.dim = Some(n);
                                out.push(sym);
                            }
                        }
                        SystemStmt::Assign { name, value, .. } => {
                            let mut sym = Symbol::new(
                                name,
                                SymbolKind::Matrix,
                                format!("{} `{}`", shape(&value.node), name.node),
                            );
                            if let Some(r) = role(&name.node) {
                                sym.more.push(r.to_string());
                            }
                            if name.node == "C" {
                                if let Value::Matrix(rows) = &value.node {
                                    let cols = rows.first().map_or(0, |r| r.node.len());
                                    sym.more.push(format!("{} observations", cols));
                                }
                            }
                            out.push(sym);
                        }
                        SystemStmt::Const { name, value, .. } => {
                            let v = eval(&value.node, &consts);
                            let shown = text_of(source, value.span);
                            let what = match v {
                                Some(x) if shown != compact(x) => {
                                    format!("constant `{}` = {shown} = {}", name.node, compact(x))
                                }
                                _ => format!("constant `{}` = {shown}", name.node),
                            };
                            if let Some(x) = v {
                                consts.insert(name.node.clone(), x);
                            }
                            out.push(Symbol::new(name, SymbolKind::Constant, what));
                        }
                        SystemStmt::Time { .. }
                        | SystemStmt::Equation { .. }
                        | SystemStmt::Observe { .. }
                        | SystemStmt::Actuate { .. } => {}
                    }
                }
            }
            Item::Network(n) => {
                out.push(Symbol::new(
                    &n.name,
                    SymbolKind::Block,
                    "network (a network on its own, without a plant)".into(),
                ));
                for (name, dim, what, slot) in n
                    .input
                    .iter()
                    .map(|(a, b)| (a, b, "network input vector", 0))
                    .chain(n.output.iter().map(|(a, b)| (a, b, "network output vector", 1)))
                {
                    let s = if slot == 0 { &mut net_in } else { &mut net_out };
                    s.get_or_insert((name.node.clone(), dim.node));
                    let mut sym = Symbol::new(
                        name,
                        SymbolKind::Vector,
                        format!(
                            "{what}, {} (`{}` ∈ {})",
                            components(dim.node),
                            name.node,
                            real_space(dim.node)
                        ),
                    );
                    sym.dim = Some(dim.node);
                    out.push(sym);
                }
            }
            Item::Initial(d) => out.push(set_symbol(d, "initial set", &state)),
            Item::Goal(d) => out.push(set_symbol(d, "goal set", &state)),
            Item::Avoid(a) => out.push(avoid_symbol(source, a, &state)),
            Item::Input(d) => out.push(set_symbol(d, "input set", &net_in)),
            Item::Require(d) => out.push(set_symbol(d, "required output set", &net_out)),
            Item::Robust(r) => {
                let what = match &r.label {
                    Some(l) => format!("robustness property: the output's arg-max is {} over the input set", l.node),
                    None => "robustness property: the output's arg-max stays the same over the input set".into(),
                };
                out.push(Symbol::new(&r.name, SymbolKind::Property, what));
            }
            Item::Radius(r) => out.push(Symbol::new(
                &r.name,
                SymbolKind::Property,
                format!("radius search: the largest input radius for which `{}` holds", r.property.node),
            )),
            Item::Select(s) => out.push(Symbol::new(
                &s.name,
                SymbolKind::Property,
                "robust action selection (CARRL): the action chosen over each perturbed observation".into(),
            )),
            Item::Controller(_) | Item::Model(_) | Item::Horizon(_) | Item::Analysis(_) => {}
        }
    }
    out
}

fn over(vector: &Option<(String, u64)>) -> String {
    match vector {
        Some((name, n)) => format!(", over `{name}` ∈ {}", real_space(*n)),
        None => String::new(),
    }
}

fn set_symbol(d: &SetDef, role: &str, vector: &Option<(String, u64)>) -> Symbol {
    Symbol::new(
        &d.name,
        SymbolKind::Set,
        format!("{role}: {}{}", set_kind(&d.set.node), over(vector)),
    )
}

fn avoid_symbol(source: &str, a: &AvoidDef, state: &Option<(String, u64)>) -> Symbol {
    let mut sym = Symbol::new(
        &a.name,
        SymbolKind::Set,
        format!("avoid set: {}{}", set_kind(&a.set.node), over(state)),
    );
    if let Some(s) = &a.steps {
        sym.more
            .push(format!("at steps {} … {}", s.node.0, s.node.1));
    }
    if let Some(w) = &a.during {
        sym.more.push(format!("during {}", text_of(source, w.span)));
    }
    sym
}

/// The names after declaring keywords, for a text that does not parse.
fn from_tokens(source: &str, tokens: &[Token]) -> Vec<Symbol> {
    let mut out: Vec<Symbol> = Vec::new();
    let text = |t: &Token| &source[t.start..t.end];
    for w in tokens.windows(2) {
        let (k, n) = (&w[0], &w[1]);
        if k.kind != TokKind::Word || n.kind != TokKind::Word {
            continue;
        }
        let (kind, what) = match text(k) {
            "state" => (SymbolKind::Vector, "state vector"),
            "control" => (SymbolKind::Vector, "control vector"),
            "input" => (SymbolKind::Vector, "network input (vector or set)"),
            "output" => (SymbolKind::Vector, "network output vector"),
            "const" => (SymbolKind::Constant, "constant"),
            "initial" => (SymbolKind::Set, "initial set"),
            "goal" => (SymbolKind::Set, "goal set"),
            "avoid" => (SymbolKind::Set, "avoid set"),
            "require" => (SymbolKind::Set, "required output set"),
            "robust" => (SymbolKind::Property, "robustness property"),
            "radius" => (SymbolKind::Property, "radius search"),
            "select" => (SymbolKind::Property, "robust action selection"),
            "system" => (SymbolKind::Block, "system"),
            "network" => (SymbolKind::Block, "network"),
            _ => continue,
        };
        let name = text(n).to_string();
        if out.iter().any(|s| s.name == name) {
            continue;
        }
        out.push(Symbol {
            name,
            span: Span::new(n.start, n.end),
            kind,
            dim: None,
            what: format!("{what} (sizes are shown once the spec parses)"),
            more: Vec::new(),
        });
    }
    out
}
