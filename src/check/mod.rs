//! Checking: AST → [`Checked`] spec, or every problem found as diagnostics.
//!
//! `check` resolves names, evaluates matrix literals, checks every shape
//! against the declared state, control and observation sizes, loads the
//! controller from bytes the caller read (the library does no IO), and checks
//! the controller's sizes against the plant. It never stops at the first
//! problem: all diagnostics are collected and returned sorted by position.

use std::collections::BTreeMap;

use nalgebra::{DMatrix, DVector};

mod extra;

use crate::analysis::closed_loop::{Boundary, Plant, Propagator};
use crate::diag::{compact, did_you_mean, Code, Diagnostic};
use crate::limits::{
    within, MAX_CELLS, MAX_DIM, MAX_HORIZON, MAX_MAGNITUDE, MAX_SAMPLES, MAX_SIMULATED_STEPS,
    MAX_STORED_NUMBERS,
};
use crate::lower::{Guide, Partitioner};
use crate::onnx::{self, Controller, ExternalFiles, OnnxErrorKind};
use crate::sets::{IBox, Polytope, Region};
use crate::syntax::ast::*;
pub use extra::{zero_order_hold, DEFAULT_BUDGET};

/// The controller file as read by the caller.
#[derive(Clone, Debug)]
pub struct ControllerFile {
    /// The file's bytes, or the read error's message.
    pub bytes: Result<Vec<u8>, String>,
    /// External-data files referenced by the model (see [`onnx::external_requests`]).
    pub external: ExternalFiles,
}

/// Defaults of the analysis block.
pub const DEFAULT_SAMPLES: usize = 1000;

/// A goal property.
#[derive(Clone, Debug, PartialEq)]
pub struct GoalDef {
    /// Its name.
    pub name: String,
    /// The goal set.
    pub set: Polytope,
}

/// An avoid property.
#[derive(Clone, Debug, PartialEq)]
pub struct AvoidSpec {
    /// Its name.
    pub name: String,
    /// The union's members.
    pub members: Vec<Polytope>,
    /// First and last step at which it applies (inclusive).
    pub steps: (usize, usize),
}

/// A spec that passed every check: all names resolved, all shapes consistent.
#[derive(Clone, Debug)]
pub struct Checked {
    /// The system's name.
    pub system: String,
    /// The state vector's name and dimension.
    pub state: (String, usize),
    /// The control vector's name and dimension.
    pub control: (String, usize),
    /// The plant per step (one entry when time-invariant), discretised if
    /// the spec gave continuous time.
    pub plants: Vec<Plant>,
    /// The time step of a continuous-time plant.
    pub dt: Option<f64>,
    /// Control limits, if any.
    pub limits: Option<IBox>,
    /// The controller's path as written.
    pub controller_path: String,
    /// The loaded controller.
    pub controller: Controller,
    /// The initial set's name and region.
    pub initial: (String, Region),
    /// The goal, if any.
    pub goal: Option<GoalDef>,
    /// The avoid sets.
    pub avoids: Vec<AvoidSpec>,
    /// Number of steps.
    pub horizon: usize,
    /// The propagator.
    pub propagator: Propagator,
    /// How the initial set is split.
    pub partitioner: Partitioner,
    /// The shape of the reachable sets.
    pub boundary: Boundary,
    /// Monte Carlo samples.
    pub samples: usize,
    /// Monte Carlo seed.
    pub seed: u64,
}

/// The path of the spec's controller, for the caller to read before [`check`].
pub fn controller_path(spec: &Spec) -> Option<&Spanned<String>> {
    spec.items.iter().find_map(|i| match i {
        Item::Controller(p) => Some(p),
        _ => None,
    })
}

const PROPAGATORS: [&str; 6] = [
    "reach_lp",
    "reach_sdp",
    "crown_unrolled",
    "crown_separate",
    "ibp_separate",
    "sg_ibp_separate",
];
const PLANNED_PROPAGATORS: [&str; 1] = ["reach_sdp_unrolled"];
const PARTITIONERS: [&str; 5] = ["none", "uniform", "sg", "gsg", "property"];
const BOUNDARIES: [&str; 3] = ["box", "hull", "polytope"];

struct Ctx {
    diags: Vec<Diagnostic>,
}

/// A matrix literal, evaluated.
struct Mat {
    rows: usize,
    cols: usize,
    data: Vec<f64>,
    is_vector: bool,
}

impl Ctx {
    fn err(&mut self, d: Diagnostic) {
        self.diags.push(d);
    }

    fn finite(&mut self, x: &Spanned<f64>) -> f64 {
        if !x.node.is_finite() {
            self.err(
                Diagnostic::new(Code::NonFinite, x.span, "number is not finite")
                    .label("this overflows f64")
                    .hint("numbers must lie within about ±1.8e308"),
            );
            return 0.0;
        }
        if x.node.abs() > MAX_MAGNITUDE {
            self.err(
                Diagnostic::new(
                    Code::Limit,
                    x.span,
                    format!("{} is too large to analyse", compact(x.node)),
                )
                .label("beyond ±1e15")
                .hint("numbers in a spec must lie within ±1e15; rescale the units, or leave a set component out to leave it unbounded"),
            );
            return 0.0;
        }
        x.node
    }

    /// Report a second definition.
    fn duplicate(&mut self, what: &str, first: Span, again: Span) {
        self.err(
            Diagnostic::new(
                Code::Duplicate,
                again,
                format!("{what} is defined more than once"),
            )
            .label("defined again here")
            .related(first, "first defined here")
            .hint("remove one of the definitions"),
        );
    }

    fn eval(&mut self, v: &Spanned<Value>, name: &str) -> Option<Mat> {
        match &v.node {
            Value::Matrix(rows) => {
                let cols = rows[0].node.len();
                let mut ok = true;
                for r in rows.iter().skip(1) {
                    if r.node.len() != cols {
                        self.err(
                            Diagnostic::new(
                                Code::Ragged,
                                r.span,
                                format!("rows of `{name}` have different lengths"),
                            )
                            .label(format!("this row has {} entries", r.node.len()))
                            .related(rows[0].span, format!("the first row has {cols}"))
                            .hint("every row of a matrix needs the same number of entries"),
                        );
                        ok = false;
                    }
                }
                let data: Vec<f64> = rows
                    .iter()
                    .flat_map(|r| r.node.iter())
                    .map(|x| self.finite(x))
                    .collect();
                ok.then_some(Mat {
                    rows: rows.len(),
                    cols,
                    data,
                    is_vector: false,
                })
            }
            Value::Vector(xs) => {
                let data: Vec<f64> = xs.iter().map(|x| self.finite(x)).collect();
                Some(Mat {
                    rows: data.len(),
                    cols: 1,
                    data,
                    is_vector: true,
                })
            }
            Value::Eye(n) => {
                let n = self.positive(n, "the size of eye(…)")?;
                let data = (0..n * n)
                    .map(|k| if k / n == k % n { 1.0 } else { 0.0 })
                    .collect();
                Some(Mat {
                    rows: n,
                    cols: n,
                    data,
                    is_vector: false,
                })
            }
            Value::Zeros(n, m) => {
                let r = self.positive(n, "the size of zeros(…)")?;
                match m {
                    Some(m) => {
                        let c = self.positive(m, "the size of zeros(…)")?;
                        Some(Mat {
                            rows: r,
                            cols: c,
                            data: vec![0.0; r * c],
                            is_vector: false,
                        })
                    }
                    None => Some(Mat {
                        rows: r,
                        cols: 1,
                        data: vec![0.0; r],
                        is_vector: true,
                    }),
                }
            }
            Value::PerStep(_) => {
                self.err(
                    Diagnostic::new(
                        Code::WrongKind,
                        v.span,
                        format!("`{name}` cannot vary over time"),
                    )
                    .label("a per-step list")
                    .hint("per_step(…) is allowed for A, B and c only"),
                );
                None
            }
            Value::Scalar(_) => {
                self.err(
                    Diagnostic::new(
                        Code::WrongKind,
                        v.span,
                        format!("`{name}` must be a matrix or vector, not a number"),
                    )
                    .label("a bare number")
                    .hint(format!("write a 1 × 1 matrix as `{name} = [[…]]`")),
                );
                None
            }
        }
    }

    fn positive(&mut self, n: &Spanned<u64>, what: &str) -> Option<usize> {
        if n.node == 0 {
            self.err(
                Diagnostic::new(Code::Zero, n.span, format!("{what} must be at least 1"))
                    .label("zero")
                    .hint("use a positive size"),
            );
            return None;
        }
        if n.node > MAX_DIM {
            self.err(
                Diagnostic::new(
                    Code::Limit,
                    n.span,
                    format!("{what} exceeds the limit of {MAX_DIM}"),
                )
                .label(format!("more than {MAX_DIM}"))
                .hint("ravel analyses control systems with at most 1000 states, controls or observations"),
            );
            return None;
        }
        Some(n.node as usize)
    }

    /// A matrix of the given shape (vectors count as one column).
    fn matrix(
        &mut self,
        v: &Spanned<Value>,
        name: &str,
        rows: usize,
        cols: Option<usize>,
        why: &str,
    ) -> Option<DMatrix<f64>> {
        let m = self.eval(v, name)?;
        // `None`: any number of columns (C's column count defines the observation size)
        let cols = cols.unwrap_or(m.cols);
        if m.is_vector && !(cols == 1 && rows == m.rows) {
            self.err(
                Diagnostic::new(
                    Code::WrongKind,
                    v.span,
                    format!("`{name}` must be a {rows} × {cols} matrix, not a vector"),
                )
                .label("a vector")
                .hint(format!(
                    "write a matrix as rows: `{name} = [[…], …]` ({why})"
                )),
            );
            return None;
        }
        if m.rows != rows || m.cols != cols {
            self.err(
                Diagnostic::new(
                    Code::Shape,
                    v.span,
                    format!(
                        "`{name}` must be {rows} × {cols}, but it is {} × {}",
                        m.rows, m.cols
                    ),
                )
                .label(format!("{} × {}", m.rows, m.cols))
                .hint(why.to_string()),
            );
            return None;
        }
        Some(DMatrix::from_row_slice(rows, cols, &m.data))
    }

    fn vector(
        &mut self,
        v: &Spanned<Value>,
        name: &str,
        n: usize,
        why: &str,
    ) -> Option<DVector<f64>> {
        let m = self.eval(v, name)?;
        if !m.is_vector && m.cols != 1 {
            self.err(
                Diagnostic::new(
                    Code::WrongKind,
                    v.span,
                    format!(
                        "`{name}` must be a vector of length {n}, not a {} × {} matrix",
                        m.rows, m.cols
                    ),
                )
                .label("a matrix")
                .hint(format!("write a vector as `{name} = [a, b, …]` ({why})")),
            );
            return None;
        }
        if m.rows != n {
            self.err(
                Diagnostic::new(
                    Code::Shape,
                    v.span,
                    format!("`{name}` must have length {n}, but it has {}", m.rows),
                )
                .label(format!("length {}", m.rows))
                .hint(why.to_string()),
            );
            return None;
        }
        Some(DVector::from_column_slice(&m.data))
    }

    fn interval(&mut self, i: &Interval) -> Option<(f64, f64)> {
        let lo = self.finite(&i.lo);
        let hi = self.finite(&i.hi);
        if lo > hi {
            self.err(
                Diagnostic::new(
                    Code::EmptyInterval,
                    i.span,
                    format!(
                        "interval [{}, {}] is empty",
                        compact(i.lo.node),
                        compact(i.hi.node)
                    ),
                )
                .label("lower end exceeds upper end")
                .hint("write intervals as [lower, upper]"),
            );
            return None;
        }
        Some((lo, hi))
    }

    /// Resolve `x[i]` against a vector `name` of dimension `dim`.
    fn component(&mut self, c: &Component, name: &str, dim: usize) -> Option<usize> {
        if c.name.node != name {
            let mut d = Diagnostic::new(
                Code::UnknownName,
                c.name.span,
                format!("unknown vector `{}`", c.name.node),
            )
            .label("not defined");
            d = d.hint(format!(
                "components here refer to `{name}` (`{name}[0]` … `{name}[{}]`)",
                dim - 1
            ));
            self.err(d);
            return None;
        }
        if c.index.node >= dim as u64 {
            self.err(
                Diagnostic::new(
                    Code::IndexOutOfRange,
                    c.span,
                    format!("`{}[{}]` is out of range", c.name.node, c.index.node),
                )
                .label(format!("`{name}` has {dim} components"))
                .hint(format!("indices run from 0 to {}", dim - 1)),
            );
            return None;
        }
        Some(c.index.node as usize)
    }

    /// A box over vector `name` of dimension `dim`. With `complete`, every component must be bounded.
    fn box_set(
        &mut self,
        b: &Spanned<BoxSet>,
        name: &str,
        dim: usize,
        complete: bool,
        role: &str,
    ) -> Option<IBox> {
        let mut lo = vec![f64::NEG_INFINITY; dim];
        let mut hi = vec![f64::INFINITY; dim];
        let mut seen: Vec<Option<Span>> = vec![None; dim];
        let mut ok = true;
        match &b.node {
            BoxSet::Positional(ivs) => {
                if ivs.len() != dim {
                    self.err(
                        Diagnostic::new(Code::Shape, b.span, format!("{role} needs {dim} intervals, one per component of `{name}`, but has {}", ivs.len()))
                            .label(format!("{} interval(s)", ivs.len()))
                            .hint(format!("`{name}` has dimension {dim}")),
                    );
                    ok = false;
                }
                for (k, iv) in ivs.iter().enumerate().take(dim) {
                    match self.interval(iv) {
                        Some((l, h)) => {
                            lo[k] = l;
                            hi[k] = h;
                            seen[k] = Some(iv.span);
                        }
                        None => ok = false,
                    }
                }
            }
            BoxSet::Named(items) => {
                for (c, iv) in items {
                    let k = self.component(c, name, dim);
                    let v = self.interval(iv);
                    match (k, v) {
                        (Some(k), Some((l, h))) => {
                            if let Some(first) = seen[k] {
                                self.duplicate(
                                    &format!("the interval of `{name}[{k}]`"),
                                    first,
                                    c.span,
                                );
                                ok = false;
                            }
                            lo[k] = l;
                            hi[k] = h;
                            seen[k] = Some(c.span);
                        }
                        _ => ok = false,
                    }
                }
                if complete && ok {
                    let missing: Vec<String> = (0..dim)
                        .filter(|k| seen[*k].is_none())
                        .map(|k| format!("{name}[{k}]"))
                        .collect();
                    if !missing.is_empty() {
                        self.err(
                            Diagnostic::new(
                                Code::SetKind,
                                b.span,
                                format!("{role} leaves {} unbounded", missing.join(", ")),
                            )
                            .label("every component needs an interval")
                            .hint(format!("add `{} in [lo, hi]`", missing[0])),
                        );
                        ok = false;
                    }
                }
            }
        }
        ok.then(|| IBox::new(lo, hi))
    }

    fn polytope(&mut self, cs: &[Constraint], name: &str, dim: usize) -> Option<Polytope> {
        let mut rows = Vec::new();
        let mut ok = true;
        for c in cs {
            let mut row = vec![0.0; dim];
            for (coef, comp) in &c.terms {
                let coef_s = Spanned {
                    node: *coef,
                    span: comp.span,
                };
                let coef = self.finite(&coef_s);
                match self.component(comp, name, dim) {
                    Some(k) => row[k] += coef,
                    None => ok = false,
                }
            }
            let rhs = self.finite(&c.rhs);
            match c.cmp {
                Cmp::Le => rows.push((row, rhs)),
                Cmp::Ge => rows.push((row.iter().map(|v| -v).collect(), -rhs)),
            }
        }
        ok.then_some(Polytope { rows })
    }

    fn set_atom(
        &mut self,
        a: &Spanned<SetAtom>,
        name: &str,
        dim: usize,
        role: &str,
    ) -> Option<Polytope> {
        match &a.node {
            SetAtom::Box(b) => {
                let sb = Spanned {
                    node: b.clone(),
                    span: a.span,
                };
                self.box_set(&sb, name, dim, false, role)
                    .map(|b| Polytope::from_box(&b))
            }
            SetAtom::Polytope(cs) => self.polytope(cs, name, dim),
            SetAtom::Ball(_) => {
                self.err(
                    Diagnostic::new(Code::SetKind, a.span, format!("{role} cannot be a ball"))
                        .label("a ball")
                        .hint("balls are initial sets only; use a box or a polytope"),
                );
                None
            }
        }
    }
}

/// Evaluate a value that may be a `per_step(…)` list: the values, and the
/// list's span when it is one.
fn per_step<T>(
    cx: &mut Ctx,
    v: &Spanned<Value>,
    one: &mut dyn FnMut(&mut Ctx, &Spanned<Value>) -> Option<T>,
) -> Option<(Vec<T>, Option<Span>)> {
    match &v.node {
        Value::PerStep(items) => {
            let vals: Vec<Option<T>> = items.iter().map(|x| one(cx, x)).collect();
            if vals.iter().all(Option::is_some) {
                Some((vals.into_iter().flatten().collect(), Some(v.span)))
            } else {
                None
            }
        }
        _ => one(cx, v).map(|x| (vec![x], None)),
    }
}

fn onnx_code(kind: OnnxErrorKind) -> Code {
    match kind {
        OnnxErrorKind::Decode => Code::NotOnnx,
        OnnxErrorKind::Unsupported => Code::UnsupportedOnnx,
        OnnxErrorKind::NonFinite => Code::NonFiniteWeights,
        OnnxErrorKind::Malformed => Code::MalformedOnnx,
        OnnxErrorKind::ExternalData => Code::ExternalData,
    }
}

/// Check a parsed spec. `controller` is the controller file as read by the caller
/// (`None` if the spec names none or it was not read).
pub fn check(spec: &Spec, controller: Option<&ControllerFile>) -> Result<Checked, Vec<Diagnostic>> {
    let mut cx = Ctx { diags: Vec::new() };
    let whole = Span::new(0, 0);

    // ---- collect top-level items, reporting duplicates ----
    let mut systems: Vec<&System> = Vec::new();
    let mut controllers: Vec<&Spanned<String>> = Vec::new();
    let mut initials: Vec<&SetDef> = Vec::new();
    let mut goals: Vec<&SetDef> = Vec::new();
    let mut avoids: Vec<&AvoidDef> = Vec::new();
    let mut horizons: Vec<&Spanned<u64>> = Vec::new();
    let mut analyses: Vec<&Analysis> = Vec::new();
    for item in &spec.items {
        match item {
            Item::System(s) => systems.push(s),
            Item::Controller(c) => controllers.push(c),
            Item::Initial(s) => initials.push(s),
            Item::Goal(s) => goals.push(s),
            Item::Avoid(a) => avoids.push(a),
            Item::Horizon(h) => horizons.push(h),
            Item::Analysis(a) => analyses.push(a),
        }
    }
    for (what, spans) in [
        (
            "the system",
            systems.iter().map(|s| s.name.span).collect::<Vec<_>>(),
        ),
        (
            "the controller",
            controllers.iter().map(|c| c.span).collect(),
        ),
        (
            "the initial set",
            initials.iter().map(|s| s.name.span).collect(),
        ),
        ("the goal", goals.iter().map(|s| s.name.span).collect()),
        ("the horizon", horizons.iter().map(|h| h.span).collect()),
        (
            "the analysis block",
            analyses.iter().map(|a| a.span).collect(),
        ),
    ] {
        for s in spans.iter().skip(1) {
            cx.duplicate(what, spans[0], *s);
        }
    }
    // set names are unique across initial, goal and avoid sets
    let mut set_names: BTreeMap<&str, Span> = BTreeMap::new();
    let named = initials
        .iter()
        .map(|s| &s.name)
        .chain(goals.iter().map(|s| &s.name))
        .chain(avoids.iter().map(|a| &a.name));
    for n in named {
        if let Some(first) = set_names.get(n.node.as_str()) {
            if *first != n.span {
                cx.duplicate(&format!("the set `{}`", n.node), *first, n.span);
            }
        } else {
            set_names.insert(&n.node, n.span);
        }
    }
    let missing = |cx: &mut Ctx, what: &str, example: &str| {
        cx.err(Diagnostic {
            code: Code::Missing,
            message: format!("the spec has no {what}"),
            span: Some(whole),
            label: "required item missing".into(),
            hint: Some(format!("add {example}")),
            related: vec![],
        })
    };
    if systems.is_empty() {
        missing(
            &mut cx,
            "system",
            "`system NAME { state x[n] control u[m] A = … B = … }`",
        );
    }
    if controllers.is_empty() {
        missing(
            &mut cx,
            "controller",
            "`controller \"path/to/policy.onnx\"`",
        );
    }
    if initials.is_empty() {
        missing(
            &mut cx,
            "initial set",
            "`initial X0 = box(x[0] in [lo, hi], …)`",
        );
    }
    if horizons.is_empty() {
        missing(&mut cx, "horizon", "`horizon N`");
    }
    if goals.is_empty() && avoids.is_empty() {
        missing(
            &mut cx,
            "property to verify (goal or avoid set)",
            "`goal G = box(…)` or `avoid A = { … }`",
        );
    }

    // ---- the system ----
    let sys = systems.first().copied();
    let mut state: Option<(String, usize)> = None;
    let mut control: Option<(String, usize)> = None;
    let mut assigns: BTreeMap<&str, (&Spanned<Value>, Span)> = BTreeMap::new();
    let mut bounds: Vec<(&Spanned<String>, &Spanned<BoxSet>)> = Vec::new();
    let mut time_span = None;
    let mut time: Result<Option<f64>, ()> = Ok(None);
    if let Some(sys) = sys {
        let mut state_span = None;
        let mut control_span = None;
        for st in &sys.stmts {
            match st {
                SystemStmt::State { name, dim, span } => {
                    if let Some(first) = state_span {
                        cx.duplicate("the state", first, *span);
                    } else {
                        state_span = Some(*span);
                        state = cx
                            .positive(dim, "the state dimension")
                            .map(|d| (name.node.clone(), d));
                    }
                }
                SystemStmt::Control { name, dim, span } => {
                    if let Some(first) = control_span {
                        cx.duplicate("the control", first, *span);
                    } else {
                        control_span = Some(*span);
                        control = cx
                            .positive(dim, "the control dimension")
                            .map(|d| (name.node.clone(), d));
                    }
                }
                SystemStmt::Assign { name, value, .. } => {
                    const KNOWN: [&str; 4] = ["A", "B", "C", "c"];
                    if !KNOWN.contains(&name.node.as_str()) {
                        let mut d = Diagnostic::new(
                            Code::UnknownName,
                            name.span,
                            format!("unknown plant parameter `{}`", name.node),
                        )
                        .label("not a plant parameter");
                        d = match did_you_mean(&name.node, KNOWN) {
                            Some(s) => d.hint(format!("did you mean `{s}`? The plant is x' = A x + B u + c + w, y = Cᵀ x + v")),
                            None => d.hint("the plant is x' = A x + B u + c + w, y = Cᵀ x + v: define A, B and optionally c and C"),
                        };
                        cx.err(d);
                    } else if let Some((_, first)) = assigns.get(name.node.as_str()) {
                        cx.duplicate(&format!("`{}`", name.node), *first, name.span);
                    } else {
                        assigns.insert(&name.node, (value, name.span));
                    }
                }
                SystemStmt::Bound { name, set, .. } => bounds.push((name, set)),
                SystemStmt::Time { kind, dt, span } => {
                    if let Some(first) = time_span {
                        cx.duplicate("the time declaration", first, *span);
                    } else {
                        time_span = Some(*span);
                        time = cx.time_decl(kind, dt, *span);
                    }
                }
            }
        }
        if let (Some((xn, _)), Some((un, _)), Some(ss), Some(cs)) =
            (&state, &control, state_span, control_span)
        {
            if xn == un {
                cx.duplicate(&format!("the name `{xn}`"), ss, cs);
            }
        }
        for (decl, span) in [(&state, state_span), (&control, control_span)] {
            if let (Some((name, _)), Some(span)) = (decl, span) {
                if name == "w" || name == "v" {
                    cx.err(
                        Diagnostic::new(
                            Code::Duplicate,
                            span,
                            format!(
                                "the name `{name}` is reserved for {} noise",
                                if name == "w" { "process" } else { "sensor" }
                            ),
                        )
                        .label("reserved name")
                        .hint("`w` and `v` name the process and sensor noise; choose another name"),
                    );
                }
            }
        }
        if state_span.is_none() {
            cx.err(
                Diagnostic::new(Code::Missing, sys.name.span, "the system declares no state")
                    .label("in this system")
                    .hint("add `state x[n]`"),
            );
        }
        if control_span.is_none() {
            cx.err(
                Diagnostic::new(
                    Code::Missing,
                    sys.name.span,
                    "the system declares no control",
                )
                .label("in this system")
                .hint("add `control u[m]`"),
            );
        }
        for req in ["A", "B"] {
            if !assigns.contains_key(req) {
                cx.err(
                    Diagnostic::new(
                        Code::Missing,
                        sys.name.span,
                        format!("the system does not define `{req}`"),
                    )
                    .label("in this system")
                    .hint(format!("add `{req} = [[…], …]`")),
                );
            }
        }
    }

    let mut plant: Option<Vec<Plant>> = None;
    let mut per_step_lists: Vec<(usize, Span)> = Vec::new();
    let mut limits = None;
    let mut p_dim = None;
    if let (Some((xn, n)), Some((un, m))) = (&state, &control) {
        let (n, m) = (*n, *m);
        let a = assigns.get("A").and_then(|(v, _)| {
            per_step(&mut cx, v, &mut |cx, v| {
                cx.matrix(
                    v,
                    "A",
                    n,
                    Some(n),
                    &format!("A is n × n with n = {n}, the dimension of `{xn}`"),
                )
            })
        });
        let b = assigns.get("B").and_then(|(v, _)| {
            per_step(&mut cx, v, &mut |cx, v| {
                cx.matrix(
                    v,
                    "B",
                    n,
                    Some(m),
                    &format!("B is n × m: {n} states by {m} controls"),
                )
            })
        });
        let c = match assigns.get("c") {
            Some((v, _)) => per_step(&mut cx, v, &mut |cx, v| {
                cx.vector(v, "c", n, &format!("c has one entry per state ({n})"))
            }),
            None => Some((vec![DVector::zeros(n)], None)),
        };
        let obs = match assigns.get("C") {
            Some((v, _)) => cx.matrix(
                v,
                "C",
                n,
                None,
                &format!("C is n × p with n = {n}: the controller sees y = Cᵀ x + v"),
            ),
            None => Some(DMatrix::identity(n, n)),
        };
        let p = obs.as_ref().map(|o| o.ncols());
        p_dim = p;
        let mut w = Some(IBox::new(vec![0.0; n], vec![0.0; n]));
        let mut v = p.map(|p| IBox::new(vec![0.0; p], vec![0.0; p]));
        let mut seen: BTreeMap<&str, Span> = BTreeMap::new();
        for (name, set) in &bounds {
            let key = name.node.as_str();
            if let Some(first) = seen.get(key) {
                cx.duplicate(&format!("the bound on `{key}`"), *first, name.span);
                continue;
            }
            seen.insert(key, name.span);
            if key == "w" {
                w = cx.box_set(set, "w", n, true, "the process noise box");
            } else if key == "v" {
                match p {
                    Some(p) => v = cx.box_set(set, "v", p, true, "the sensor noise box"),
                    None => v = None,
                }
            } else if key == un {
                limits = cx.box_set(set, un, m, true, "the control limit box");
            } else {
                let cands = ["w", "v", un.as_str()];
                let mut d = Diagnostic::new(
                    Code::UnknownName,
                    name.span,
                    format!("unknown bounded quantity `{key}`"),
                )
                .label("not a noise or control name");
                d = match did_you_mean(key, cands) {
                    Some(s) => d.hint(format!("did you mean `{s}`? Bounds apply to `w` (process noise), `v` (sensor noise) or `{un}` (control limits)")),
                    None => d.hint(format!("bounds apply to `w` (process noise), `v` (sensor noise) or `{un}` (control limits)")),
                };
                cx.err(d);
            }
        }
        if let (Some(a), Some(b), Some(c), Some(obs), Some(w), Some(v)) = (a, b, c, obs, w, v) {
            for (list, span) in [(a.0.len(), a.1), (b.0.len(), b.1), (c.0.len(), c.1)] {
                if let Some(span) = span {
                    per_step_lists.push((list, span));
                }
            }
            let len = a.0.len().max(b.0.len()).max(c.0.len());
            let pick = |k: usize, l: usize| k.min(l - 1);
            plant = Some(
                (0..len)
                    .map(|k| Plant {
                        a: a.0[pick(k, a.0.len())].clone(),
                        b: b.0[pick(k, b.0.len())].clone(),
                        c: c.0[pick(k, c.0.len())].clone(),
                        obs: obs.clone(),
                        w: w.clone(),
                        v: v.clone(),
                        err: None,
                    })
                    .collect::<Vec<Plant>>(),
            );
        }
    }

    // ---- the controller ----
    let mut ctrl = None;
    if let Some(path) = controllers.first() {
        match controller {
            None => cx.err(
                Diagnostic::new(
                    Code::ControllerUnreadable,
                    path.span,
                    format!(
                        "controller `{}` was not read",
                        crate::diag::sanitize(&path.node)
                    ),
                )
                .label("not available")
                .hint("the controller file must be readable next to the spec"),
            ),
            Some(file) => match &file.bytes {
                Err(msg) => cx.err(
                    Diagnostic::new(
                        Code::ControllerUnreadable,
                        path.span,
                        format!(
                            "cannot read controller `{}`: {}",
                            crate::diag::sanitize(&path.node),
                            crate::diag::sanitize(msg)
                        ),
                    )
                    .label("this file")
                    .hint("paths are relative to the spec file's folder"),
                ),
                Ok(bytes) => match onnx::load(bytes, &file.external) {
                    Err(e) => cx.err(
                        Diagnostic::new(onnx_code(e.kind), path.span, e.message)
                            .label("in this controller")
                            .hint(e.hint),
                    ),
                    Ok(c) => {
                        if let Some(p) = p_dim {
                            if c.inputs != p {
                                let what = if assigns.contains_key("C") {
                                    format!("C has {p} columns")
                                } else {
                                    format!("without C the controller sees the full state ({p})")
                                };
                                cx.err(
                                    Diagnostic::new(Code::ControllerInputs, path.span, format!("the controller takes {} inputs but observations have {p} components", c.inputs))
                                        .label(format!("{} inputs", c.inputs))
                                        .hint(format!("{what}; the controller's input size must match")),
                                );
                            }
                        }
                        if let Some((un, m)) = &control {
                            if c.outputs != *m {
                                cx.err(
                                    Diagnostic::new(Code::ControllerOutputs, path.span, format!("the controller has {} outputs but `{un}` has {m} components", c.outputs))
                                        .label(format!("{} outputs", c.outputs))
                                        .hint(format!("declare `control {un}[{}]` or use a controller with {m} outputs", c.outputs)),
                                );
                            }
                        }
                        ctrl = Some(c);
                    }
                },
            },
        }
    }

    // ---- horizon ----
    let mut horizon = None;
    if let Some(h) = horizons.first() {
        if h.node < 1 {
            cx.err(
                Diagnostic::new(Code::Horizon, h.span, "the horizon must be at least 1")
                    .label("zero steps")
                    .hint("write `horizon N` with N ≥ 1"),
            );
        } else if h.node > MAX_HORIZON {
            cx.err(
                Diagnostic::new(
                    Code::Horizon,
                    h.span,
                    format!("the horizon exceeds {MAX_HORIZON}"),
                )
                .label("too many steps")
                .hint("use a shorter horizon"),
            );
        } else {
            horizon = Some(h.node as usize);
        }
    }

    // ---- sets ----
    let mut initial = None;
    let mut goal = None;
    let mut avoid_specs = Vec::new();
    if let Some((xn, n)) = &state {
        if let Some(init) = initials.first() {
            let members = &init.set.node.members;
            if members.len() > 1 {
                cx.err(
                    Diagnostic::new(
                        Code::SetKind,
                        init.set.span,
                        "the initial set cannot be a union",
                    )
                    .label("a union")
                    .hint("verify each part in its own spec, or use the bounding box"),
                );
            } else {
                match &members[0].node {
                    SetAtom::Box(b) => {
                        let sb = Spanned {
                            node: b.clone(),
                            span: members[0].span,
                        };
                        initial = cx
                            .box_set(&sb, xn, *n, true, "the initial set")
                            .map(|b| (init.name.node.clone(), Region::Box(b)));
                    }
                    SetAtom::Polytope(cs) => {
                        initial = cx
                            .polytope(cs, xn, *n)
                            .and_then(|p| {
                                cx.bounded_polytope(p, members[0].span, "the initial set")
                            })
                            .map(|r| (init.name.node.clone(), r));
                    }
                    SetAtom::Ball(b) => {
                        initial = cx
                            .ball(b, members[0].span, xn, *n)
                            .map(|r| (init.name.node.clone(), r));
                    }
                }
            }
        }
        if let Some(g) = goals.first() {
            let members = &g.set.node.members;
            if members.len() > 1 {
                cx.err(
                    Diagnostic::new(Code::SetKind, g.set.span, "the goal cannot be a union")
                        .label("a union")
                        .hint("the final reachable set must lie in one box or polytope"),
                );
            } else if let Some(p) = cx.set_atom(&members[0], xn, *n, "the goal") {
                goal = Some(GoalDef {
                    name: g.name.node.clone(),
                    set: p,
                });
            }
        }
        for a in &avoids {
            let members: Vec<Option<Polytope>> = a
                .set
                .node
                .members
                .iter()
                .map(|m| cx.set_atom(m, xn, *n, "the avoid set"))
                .collect();
            let steps = match (&a.steps, horizon) {
                (None, Some(h)) => Some((0, h)),
                (Some(s), h) => {
                    let (lo, hi) = s.node;
                    if lo > hi {
                        cx.err(
                            Diagnostic::new(
                                Code::StepRange,
                                s.span,
                                format!("step range [{lo}, {hi}] is empty"),
                            )
                            .label("first step after last")
                            .hint("write `at steps [first, last]`"),
                        );
                        None
                    } else if h.is_some_and(|h| hi as usize > h) {
                        let h = h.unwrap_or(0);
                        cx.err(
                            Diagnostic::new(
                                Code::StepRange,
                                s.span,
                                format!("step {hi} is beyond the horizon {h}"),
                            )
                            .label("beyond the horizon")
                            .hint(format!("steps run from 0 (the initial set) to {h}")),
                        );
                        None
                    } else {
                        Some((lo as usize, hi as usize))
                    }
                }
                (None, None) => None,
            };
            if members.iter().all(Option::is_some) {
                if let Some(steps) = steps {
                    avoid_specs.push(AvoidSpec {
                        name: a.name.node.clone(),
                        members: members.into_iter().flatten().collect(),
                        steps,
                    });
                }
            }
        }
    }

    // ---- analysis ----
    let mut propagator = Some(Propagator::ReachLp);
    let mut partition: Option<Partitioner> = state
        .as_ref()
        .map(|(_, n)| Partitioner::Uniform(vec![1; *n]));
    let mut boundary = Some(Boundary::Box);
    let mut hull_span = None;
    let mut guided_span = None;
    let mut sdp_span = None;
    let mut samples = DEFAULT_SAMPLES;
    let mut seed = 0u64;
    if let Some(an) = analyses.first() {
        let mut seen: BTreeMap<&str, Span> = BTreeMap::new();
        for st in &an.stmts {
            let key = match &st.node {
                AnalysisStmt::Propagator(_) => "propagator",
                AnalysisStmt::Partitioner(_)
                | AnalysisStmt::Uniform(_)
                | AnalysisStmt::Guided { .. } => "partitioner",
                AnalysisStmt::Boundary(_) | AnalysisStmt::BoundaryPolytope(_) => "boundary",
                AnalysisStmt::Samples(_) => "samples",
                AnalysisStmt::Seed(_) => "seed",
            };
            if let Some(first) = seen.get(key) {
                cx.duplicate(&format!("`{key}`"), *first, st.span);
                continue;
            }
            seen.insert(key, st.span);
            match &st.node {
                AnalysisStmt::Propagator(p) => {
                    propagator = match p.node.as_str() {
                        "reach_lp" => Some(Propagator::ReachLp),
                        "crown_unrolled" => Some(Propagator::CrownUnrolled),
                        "crown_separate" => Some(Propagator::CrownSeparate),
                        "ibp_separate" => Some(Propagator::IbpSeparate),
                        "sg_ibp_separate" => Some(Propagator::SgIbpSeparate),
                        "reach_sdp" => {
                            sdp_span = Some(p.span);
                            Some(Propagator::ReachSdp)
                        }
                        other => {
                            let planned = PLANNED_PROPAGATORS.contains(&other);
                            let mut d = Diagnostic::new(
                                Code::UnknownName,
                                p.span,
                                format!("unknown propagator `{other}`"),
                            )
                            .label(if planned {
                                "not available in this version"
                            } else {
                                "not a propagator"
                            });
                            let list = PROPAGATORS.join(", ");
                            d = match (planned, did_you_mean(other, PROPAGATORS)) {
                                (true, _) => d.hint(format!("`{other}` is planned but not implemented yet; available: {list}")),
                                (false, Some(s)) => d.hint(format!("did you mean `{s}`? Available: {list}")),
                                (false, None) => d.hint(format!("available: {list}")),
                            };
                            cx.err(d);
                            None
                        }
                    }
                }
                AnalysisStmt::Partitioner(p) => {
                    if p.node != "none" {
                        let mut d = Diagnostic::new(
                            Code::UnknownName,
                            p.span,
                            format!("unknown partitioner `{}`", p.node),
                        )
                        .label("not a partitioner");
                        d = match did_you_mean(&p.node, PARTITIONERS) {
                            Some(s) => d.hint(format!(
                                "did you mean `{s}`? Available: none, uniform [k, …], sg, gsg, property"
                            )),
                            None => d.hint(
                                "available: none, uniform [k, …], sg, gsg, property (each with an optional budget)",
                            ),
                        };
                        cx.err(d);
                    }
                }
                AnalysisStmt::Uniform(ks) => {
                    if let Some((xn, n)) = &state {
                        if ks.len() != *n {
                            cx.err(
                                Diagnostic::new(
                                    Code::Partition,
                                    st.span,
                                    format!(
                                        "the grid has {} counts but `{xn}` has {n} components",
                                        ks.len()
                                    ),
                                )
                                .label(format!("{} count(s)", ks.len()))
                                .hint(format!(
                                    "give one cell count per state component, e.g. uniform [{}]",
                                    vec!["2"; *n].join(", ")
                                )),
                            );
                            partition = None;
                        } else if let Some(k) = ks.iter().find(|k| k.node == 0) {
                            cx.err(
                                Diagnostic::new(
                                    Code::Partition,
                                    k.span,
                                    "a grid needs at least one cell per dimension",
                                )
                                .label("zero cells")
                                .hint("use 1 to leave a dimension unsplit"),
                            );
                            partition = None;
                        } else {
                            let counts: Vec<u64> = ks.iter().map(|k| k.node).collect();
                            match within(&counts, MAX_CELLS) {
                                true => {
                                    partition = Some(Partitioner::Uniform(
                                        ks.iter().map(|k| k.node as usize).collect(),
                                    ))
                                }
                                false => {
                                    cx.err(
                                        Diagnostic::new(
                                            Code::Limit,
                                            st.span,
                                            format!("the grid has more than {MAX_CELLS} cells"),
                                        )
                                        .label("too many cells")
                                        .hint("use fewer cells per dimension"),
                                    );
                                    partition = None;
                                }
                            }
                        }
                    }
                }
                AnalysisStmt::Guided { guide, budget } => {
                    let g = match guide.node.as_str() {
                        "sg" => Guide::Sg,
                        "gsg" => Guide::Gsg,
                        _ => Guide::Property,
                    };
                    guided_span = Some((g, st.span));
                    partition = cx
                        .budget(budget)
                        .map(|budget| Partitioner::Guided { guide: g, budget });
                }
                AnalysisStmt::BoundaryPolytope(v) => {
                    if let Some((xn, n)) = &state {
                        boundary = cx.boundary_polytope(v, xn, *n);
                    }
                }
                AnalysisStmt::Boundary(b) => {
                    if b.node == "polytope" {
                        cx.err(
                            Diagnostic::new(Code::Boundary, b.span, "a polytope boundary needs its directions")
                                .label("no directions")
                                .hint("write `boundary polytope 8` (evenly spread, 2-D states) or `boundary polytope [[1, 1], [1, -1]]`"),
                        );
                        boundary = None;
                    } else if b.node == "hull" {
                        match state.as_ref().map(|(_, n)| *n) {
                            Some(2) | None => {
                                boundary = Some(Boundary::Hull);
                                hull_span = Some(b.span);
                            }
                            Some(n) => {
                                cx.err(
                                    Diagnostic::new(
                                        Code::Boundary,
                                        b.span,
                                        format!("a convex-hull boundary needs a 2-D state, but the state has {n} components"),
                                    )
                                    .label("2-D only")
                                    .hint("use `boundary box` or `boundary polytope [[…], …]` with explicit directions"),
                                );
                                boundary = None;
                            }
                        }
                    } else if b.node != "box" {
                        let mut d = Diagnostic::new(
                            Code::UnknownName,
                            b.span,
                            format!("unknown boundary `{}`", b.node),
                        )
                        .label("not a boundary shape");
                        d = match did_you_mean(&b.node, BOUNDARIES) {
                            Some(s) => d.hint(format!("did you mean `{s}`?")),
                            None => d.hint("available: box, hull, polytope K, polytope [[…], …]"),
                        };
                        cx.err(d);
                        boundary = None;
                    }
                }
                AnalysisStmt::Samples(s) => {
                    if s.node > MAX_SAMPLES {
                        cx.err(
                            Diagnostic::new(
                                Code::Limit,
                                s.span,
                                format!("more than {MAX_SAMPLES} samples"),
                            )
                            .label("too many")
                            .hint("use fewer samples"),
                        );
                    } else {
                        samples = s.node as usize;
                    }
                }
                AnalysisStmt::Seed(s) => seed = s.node,
            }
        }
    }

    if let (Some(span), Some(c)) = (sdp_span, &ctrl) {
        if let Some(act) = c.net.layers.iter().find_map(|l| match l {
            crate::nn::Layer::Act(a) if *a != crate::nn::Activation::Relu => Some(*a),
            _ => None,
        }) {
            cx.err(
                Diagnostic::new(
                    Code::SdpActivation,
                    span,
                    format!(
                        "Reach-SDP encodes ReLU networks only, but the controller uses {}",
                        act.name()
                    ),
                )
                .label("needs a ReLU network")
                .hint("use `reach_lp` or `crown_unrolled`, which handle tanh and sigmoid"),
            );
        }
    }
    if let (Some(span), true) = (hull_span, samples == 0) {
        cx.err(
            Diagnostic::new(
                Code::Boundary,
                span,
                "a convex-hull boundary takes its directions from Monte Carlo samples, but `samples` is 0",
            )
            .label("no samples to shape it")
            .hint("draw samples (e.g. `samples 1000`) or use `boundary polytope 8`"),
        );
    }
    if let (Some((g, span)), true) = (guided_span, samples == 0) {
        if g != Guide::Property {
            cx.err(
                Diagnostic::new(
                    Code::Partition,
                    span,
                    format!(
                        "the `{}` partitioner is guided by Monte Carlo samples, but `samples` is 0",
                        g.name()
                    ),
                )
                .label("no samples to guide it")
                .hint("draw samples (e.g. `samples 1000`) or use `partitioner property`"),
            );
        }
    }
    if let Some(h) = horizon {
        for (len, span) in &per_step_lists {
            if *len < h {
                cx.err(
                    Diagnostic::new(
                        Code::PerStepLength,
                        *span,
                        format!("the list has {len} values but the horizon is {h}"),
                    )
                    .label(format!("{len} value(s)"))
                    .hint(format!(
                        "give one value per step 0 … {}: at least {h}",
                        h - 1
                    )),
                );
            }
        }
    }
    if let (Ok(Some(dt)), Some(plants)) = (time, plant.as_mut()) {
        let mut ok = true;
        for p in plants.iter_mut() {
            match zero_order_hold(p, dt) {
                Some(d) => *p = d,
                None => ok = false,
            }
        }
        if !ok {
            cx.err(
                Diagnostic::new(
                    Code::TimeStep,
                    time_span.unwrap_or(whole),
                    format!("e^(A·{}) overflows", compact(dt)),
                )
                .label("time step too large for these dynamics")
                .hint("use a smaller dt"),
            );
        }
    }
    let dt = time.ok().flatten();
    if let (Some(h), Some((_, n))) = (horizon, &state) {
        let span = horizons.first().map_or(whole, |h| h.span);
        let directions = match &boundary {
            Some(Boundary::Polytope(d)) => d.nrows(),
            Some(Boundary::Hull) => 48,
            _ => 0,
        };
        sizes(
            &mut cx,
            span,
            h,
            *n,
            directions,
            samples,
            partition.as_ref(),
        );
    }

    if !cx.diags.is_empty() {
        cx.diags
            .sort_by_key(|d| (d.span.map_or(0, |s| s.start), d.code));
        return Err(cx.diags);
    }
    // Everything below was produced without diagnostics, so each value is present.
    match (
        sys,
        state,
        control,
        plant,
        ctrl,
        initial,
        horizon,
        propagator,
        partition,
        boundary,
        controllers.first(),
    ) {
        (
            Some(sys),
            Some(state),
            Some(control),
            Some(plant),
            Some(controller),
            Some(initial),
            Some(horizon),
            Some(propagator),
            Some(partitioner),
            Some(boundary),
            Some(path),
        ) => Ok(Checked {
            system: sys.name.node.clone(),
            state,
            control,
            plants: plant,
            dt,
            limits,
            controller_path: path.node.clone(),
            controller,
            initial,
            goal,
            avoids: avoid_specs,
            horizon,
            propagator,
            partitioner,
            boundary,
            samples,
            seed,
        }),
        _ => Err(vec![Diagnostic::new(
            Code::Missing,
            whole,
            "the spec is incomplete",
        )
        .label("here")
        .hint("see docs/language.md")]),
    }
}

/// The limits on products of sizes (see [`crate::limits`]): simulated steps
/// and stored set bounds (a set has `2n` box bounds and `n + 1` numbers per
/// boundary direction), reported at the horizon.
fn sizes(
    cx: &mut Ctx,
    span: Span,
    h: usize,
    n: usize,
    directions: usize,
    samples: usize,
    part: Option<&Partitioner>,
) {
    let (h, samples) = (h as u64, samples as u64);
    let n = 2 * n as u64 + directions as u64 * (n as u64 + 1);
    if !within(&[samples, h], MAX_SIMULATED_STEPS) {
        cx.err(
            Diagnostic::new(
                Code::Limit,
                span,
                format!("{samples} samples over {h} steps exceed the limit of {MAX_SIMULATED_STEPS} simulated steps"),
            )
            .label("too many simulated steps")
            .hint("draw fewer samples or use a shorter horizon"),
        );
    }
    let cells = match part {
        Some(Partitioner::Uniform(grid)) => grid.iter().map(|k| *k as u64).collect::<Vec<_>>(),
        Some(Partitioner::Guided { budget, .. }) => vec![budget.calls as u64],
        None => vec![1],
    };
    let mut factors = cells;
    factors.extend([h + 1, n]);
    if !within(&factors, MAX_STORED_NUMBERS) {
        cx.err(
            Diagnostic::new(
                Code::Limit,
                span,
                format!("the partition's cells over {h} steps would store more than {MAX_STORED_NUMBERS} bounds"),
            )
            .label("too many cells × steps")
            .hint("use fewer cells (or a smaller call budget) or a shorter horizon"),
        );
    }
}
