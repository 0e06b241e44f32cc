//! Checking: AST → [`Checked`] spec, or every problem found as diagnostics.
//!
//! `check` resolves names, evaluates matrix literals, checks every shape
//! against the declared state, control and observation sizes, loads the
//! controller from bytes the caller read (the library does no IO), and checks
//! the controller's sizes against the plant. It never stops at the first
//! problem: all diagnostics are collected and returned sorted by position.

// Untrusted data flows through here: no unwraps, no panicking indexing.
#![deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use std::collections::BTreeMap;

use nalgebra::{DMatrix, DVector};

mod analysis_block;
mod controller;
mod network;
mod nonlinear;
mod regions;
mod select;
mod sets;
mod system;
mod time;

use crate::ir::SelectSpec;
use crate::ir::{GoalMode, Guide, Partitioner, StateSet, Window};
use crate::onnx::{Controller, ExternalFiles, OnnxErrorKind};
use analysis_block::AnalysisPart;
pub use analysis_block::DEFAULT_BUDGET;
pub use network::{is_network_spec, NetworkChecked, MAX_OBSERVATIONS};
use ravel_analysis::closed_loop::{Boundary, Plant, Propagator};
use ravel_analysis::nonlinear::NonlinearPlant;
use ravel_analysis::sets::{IBox, Polytope, Region};
use ravel_base::limits::{
    within, MAX_DIM, MAX_HORIZON, MAX_MAGNITUDE, MAX_POLYTOPE_ROWS, MAX_SDP_DIM,
    MAX_SIMULATED_STEPS, MAX_SPEC_NUMBERS, MAX_STORED_NUMBERS, MAX_UNROLLED_NEURON_STEPS,
};
use ravel_syntax::ast::*;
use ravel_syntax::diag::{compact, Code, Diagnostic};
pub use sets::TIME_TOLERANCE;
pub use time::zero_order_hold;

/// Data files a spec names (observation CSVs), as read by the caller:
/// the path as written in the spec → the bytes or the read error.
pub type DataFiles = BTreeMap<String, Result<Vec<u8>, String>>;

/// The data files a spec names, for the caller to read before [`check_task`]
/// (paths as written, relative to the spec's folder).
pub fn data_paths(spec: &Spec) -> Vec<String> {
    let mut v: Vec<String> = spec
        .items
        .iter()
        .filter_map(|i| match i {
            Item::Select(d) => Some(d),
            _ => None,
        })
        .flat_map(|d| d.stmts.iter())
        .filter_map(|st| match &st.node {
            SelectStmt::File(p) => Some(p.node.clone()),
            _ => None,
        })
        .collect();
    v.sort();
    v.dedup();
    v
}

/// A checked spec of either kind.
#[derive(Clone, Debug)]
pub enum Task {
    /// A closed loop (`system` spec).
    System(Box<Checked>),
    /// A network on its own (`network` spec).
    Network(Box<NetworkChecked>),
}

/// Check a parsed spec of either kind (see [`is_network_spec`]).
pub fn check_task(
    spec: &Spec,
    controller: Option<&ControllerFile>,
    data: &DataFiles,
) -> Result<Task, Vec<Diagnostic>> {
    if !is_network_spec(spec) {
        return check(spec, controller).map(|c| Task::System(Box::new(c)));
    }
    let mut cx = Ctx::new();
    let checked = network::check_network(&mut cx, spec, controller, data);
    match checked {
        Some(c) if cx.diags.is_empty() => Ok(Task::Network(Box::new(c))),
        _ => {
            if cx.diags.is_empty() {
                cx.err(incomplete());
            }
            Err(cx.sorted_diags())
        }
    }
}

/// The controller file as read by the caller.
#[derive(Clone, Debug)]
pub struct ControllerFile {
    /// The path given on the command line instead of the spec's, if any
    /// (`ravel verify SPEC --controller PATH`); reports name this path.
    pub path_override: Option<String>,
    /// The path the file was read from (the spec's folder joined with the
    /// spec's path, or the command line's path).
    pub resolved: String,
    /// The file's bytes, or the read error's message.
    pub bytes: Result<Vec<u8>, String>,
    /// External-data files referenced by the model (see [`crate::onnx::external_requests`]).
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
    pub set: StateSet,
    /// When it applies (a plain goal: the horizon).
    pub window: Window,
    /// At every step of the window, or at some step.
    pub mode: GoalMode,
}

/// An avoid property.
#[derive(Clone, Debug, PartialEq)]
pub struct AvoidSpec {
    /// Its name.
    pub name: String,
    /// The union's members.
    pub members: Vec<StateSet>,
    /// When it applies.
    pub window: Window,
}

/// A checked plant: linear (one per step) or nonlinear.
#[derive(Clone, Debug)]
pub enum PlantSpec {
    /// `A`, `B`, `c`: the plant per step (one entry when time-invariant),
    /// discretised if the spec gave continuous time.
    Linear(Vec<Plant>),
    /// `der`/`next` lines: the vector field, its disturbance, observation
    /// and sensor noise.
    Nonlinear(NonlinearPlant),
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
    /// The plant. Its observation matrix already folds `observe`'s matrix
    /// `M` (as `Mᵀ`: the controller sees `Mᵀᵀ x + v`).
    pub plant: PlantSpec,
    /// A linear plant in continuous time: its plants before the
    /// discretisation (`ẋ = A x + B u + c` per step), for the enclosures
    /// between the sampling instants.
    pub continuous: Option<Vec<Plant>>,
    /// `observe`'s offsets `d` (the controller sees `M x + d + v`): lowering
    /// prepends the layer `h ↦ h + d` to the network; `None` without
    /// `observe` or when `d = 0`.
    pub observe_offset: Option<DVector<f64>>,
    /// `actuate`: the control is `S · net + o` (`S` is `m × outputs`);
    /// lowering appends this affine layer before the saturation.
    pub actuate: Option<(DMatrix<f64>, DVector<f64>)>,
    /// The time step (the control period) of a continuous-time plant.
    pub dt: Option<f64>,
    /// Control limits, if any.
    pub limits: Option<IBox>,
    /// The controller's path: as written in the spec, or as given on the
    /// command line when it overrides the spec's.
    pub controller_path: String,
    /// SHA-256 of the controller file's bytes, in hex.
    pub controller_sha256: String,
    /// The path the controller was read from.
    pub controller_resolved: String,
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
    /// Projected-gradient steps on the lower ReLU slopes (0: CROWN's own).
    pub slope_steps: usize,
}

/// The path of the spec's controller (or a network spec's model), for the
/// caller to read before [`check`].
pub fn controller_path(spec: &Spec) -> Option<&Spanned<String>> {
    let network = is_network_spec(spec);
    spec.items.iter().find_map(|i| match i {
        Item::Controller(p) if !network => Some(p),
        Item::Model(p) if network => Some(p),
        _ => None,
    })
}

const PLANNED_PROPAGATORS: [&str; 1] = ["reach_sdp_unrolled"];
/// Every partitioner keyword: `none`, `uniform`, then the guides.
fn partitioner_names() -> Vec<&'static str> {
    let mut v = vec!["none", "uniform"];
    v.extend(Guide::ALL.iter().map(|g| g.name()));
    v
}
pub(super) const BOUNDARIES: [&str; 3] = ["box", "hull", "polytope"];

struct Ctx {
    diags: Vec<Diagnostic>,
    /// Numbers held by the matrices and vectors evaluated so far (see
    /// [`MAX_SPEC_NUMBERS`]): `per_step(eye(1000), …)` is a few bytes of
    /// text but 8 MB per entry.
    numbers: u64,
}

/// A matrix literal, evaluated.
struct Mat {
    rows: usize,
    cols: usize,
    data: Vec<f64>,
    is_vector: bool,
}

/// The whole spec: where a missing item is reported.
const WHOLE: Span = Span { start: 0, end: 0 };

/// "the spec is incomplete": a part is missing although no diagnostic says why.
fn incomplete() -> Diagnostic {
    Diagnostic::new(Code::Missing, WHOLE, "the spec is incomplete")
        .label("here")
        .hint("see docs/language.md")
}

/// The controller (or model) analysed: the command line's path, pointed at
/// where the spec names its own (`written`) or at the whole spec; else the spec's.
fn effective_path(
    file: Option<&ControllerFile>,
    written: Option<&Spanned<String>>,
) -> Option<Spanned<String>> {
    match file.and_then(|f| f.path_override.as_ref()) {
        Some(p) => Some(Spanned {
            node: p.clone(),
            span: written.map_or(WHOLE, |c| c.span),
        }),
        None => written.cloned(),
    }
}

/// SHA-256 of the file's bytes in hex (empty when it was not read).
fn file_sha256(file: Option<&ControllerFile>) -> String {
    file.and_then(|f| f.bytes.as_ref().ok())
        .map(|b| sha256_hex(b))
        .unwrap_or_default()
}

impl Ctx {
    fn new() -> Self {
        Ctx {
            diags: Vec::new(),
            numbers: 0,
        }
    }

    fn err(&mut self, d: Diagnostic) {
        self.diags.push(d);
    }

    /// The diagnostics so far, taken out sorted by position (and by code at
    /// one position; otherwise in the order found).
    fn sorted_diags(&mut self) -> Vec<Diagnostic> {
        self.diags
            .sort_by_key(|d| (d.span.map_or(0, |s| s.start), d.code));
        std::mem::take(&mut self.diags)
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

    /// Report every definition of `what` after the first (`spans` in source order).
    fn duplicates(&mut self, what: &str, spans: &[Span]) {
        if let Some((first, rest)) = spans.split_first() {
            for s in rest {
                self.duplicate(what, *first, *s);
            }
        }
    }

    fn eval(&mut self, v: &Spanned<Value>, name: &str) -> Option<Mat> {
        // every size is at most MAX_DIM², so this product cannot overflow
        let size = match &v.node {
            Value::Eye(n) => n.node.min(MAX_DIM).pow(2),
            Value::Zeros(n, m) => {
                n.node.min(MAX_DIM) * m.as_ref().map_or(1, |m| m.node.min(MAX_DIM))
            }
            Value::Matrix(rows) => rows.iter().map(|r| r.node.len() as u64).sum(),
            Value::Vector(xs) => xs.len() as u64,
            Value::Scalar(_) | Value::PerStep(_) => 0,
        };
        let before = self.numbers;
        self.numbers = self.numbers.saturating_add(size);
        if self.numbers > MAX_SPEC_NUMBERS {
            if before > MAX_SPEC_NUMBERS {
                return None; // reported once, where the limit was passed
            }
            self.err(
                Diagnostic::new(
                    Code::Limit,
                    v.span,
                    format!("the spec's matrices hold more than {MAX_SPEC_NUMBERS} numbers"),
                )
                .label("the limit is passed here")
                .hint("use fewer or smaller matrices (each per_step entry counts)"),
            );
            return None;
        }
        self.eval_unchecked(v, name)
    }

    fn eval_unchecked(&mut self, v: &Spanned<Value>, name: &str) -> Option<Mat> {
        match &v.node {
            Value::Matrix(rows) => {
                // the grammar admits no empty matrix; an empty one is a 0 × 0 matrix
                let (cols, first_span) =
                    rows.first().map_or((0, v.span), |r| (r.node.len(), r.span));
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
                            .related(first_span, format!("the first row has {cols}"))
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
        let free_cols = cols.is_none();
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
            // with free columns (C), only the rows are wrong: `rows × p`
            let expected = if free_cols {
                format!("{rows} × p")
            } else {
                format!("{rows} × {cols}")
            };
            // its transpose would fit: say so, with the shape to write
            let transposed = m.cols == rows && m.rows != rows && (free_cols || m.rows == cols);
            let hint = if transposed {
                format!(
                    "it looks transposed: write its transpose, a {} × {} matrix ({why})",
                    m.cols, m.rows
                )
            } else {
                why.to_string()
            };
            self.err(
                Diagnostic::new(
                    Code::Shape,
                    v.span,
                    format!(
                        "`{name}` must be {expected}, but it is {} × {}",
                        m.rows, m.cols
                    ),
                )
                .label(format!("{} × {}", m.rows, m.cols))
                .hint(hint),
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
                for (((iv, l), h), s) in ivs.iter().zip(&mut lo).zip(&mut hi).zip(&mut seen) {
                    match self.interval(iv) {
                        Some(v) => {
                            (*l, *h) = v;
                            *s = Some(iv.span);
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
                            // `component` returned k < dim
                            if let (Some(sk), Some(lk), Some(hk)) =
                                (seen.get_mut(k), lo.get_mut(k), hi.get_mut(k))
                            {
                                if let Some(first) = *sk {
                                    self.duplicate(
                                        &format!("the interval of `{name}[{k}]`"),
                                        first,
                                        c.span,
                                    );
                                    ok = false;
                                }
                                (*lk, *hk) = (l, h);
                                *sk = Some(c.span);
                            }
                        }
                        _ => ok = false,
                    }
                }
                if complete && ok {
                    let missing: Vec<String> = seen
                        .iter()
                        .enumerate()
                        .filter(|(_, s)| s.is_none())
                        .map(|(k, _)| format!("{name}[{k}]"))
                        .collect();
                    if let Some(first) = missing.first() {
                        self.err(
                            Diagnostic::new(
                                Code::SetKind,
                                b.span,
                                format!("{role} leaves {} unbounded", name_list(&missing)),
                            )
                            .label("every component needs an interval")
                            .hint(format!("add `{first} in [lo, hi]`")),
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
        if cs.len() > MAX_POLYTOPE_ROWS {
            if let (Some(first), Some(last)) = (cs.first(), cs.last()) {
                self.err(
                    Diagnostic::new(
                        Code::Limit,
                        Span::new(first.span.start, last.span.end),
                        format!(
                            "a polytope of {} inequalities, beyond the limit of {MAX_POLYTOPE_ROWS}",
                            cs.len()
                        ),
                    )
                    .label("too many inequalities")
                    .hint("describe the set with fewer inequalities"),
                );
            }
            return None;
        }
        for c in cs {
            let mut row = vec![0.0; dim];
            for (coef, comp) in &c.terms {
                let coef_s = Spanned {
                    node: *coef,
                    span: comp.span,
                };
                let coef = self.finite(&coef_s);
                match self.component(comp, name, dim).and_then(|k| row.get_mut(k)) {
                    Some(r) => *r += coef,
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
            SetAtom::Inequalities(rows) => self.linear_rows(rows, name, dim, role),
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

impl Ctx {
    /// The inequalities of a set over `name` (dimension `dim`): linear
    /// rows, and nonlinear constraints `g ≤ 0` (each with the span of its
    /// first non-affine node). `consts`: the named constants in scope.
    fn set_rows(
        &mut self,
        rows: &[SetRow],
        name: &str,
        dim: usize,
        consts: &BTreeMap<String, f64>,
    ) -> Option<(Polytope, Vec<(ravel_base::expr::Tape, Span)>)> {
        if rows.len() > MAX_POLYTOPE_ROWS {
            let span = match (rows.first(), rows.last()) {
                (Some(a), Some(b)) => Span::new(row_span(a).start, row_span(b).end),
                _ => WHOLE,
            };
            self.err(
                Diagnostic::new(
                    Code::Limit,
                    span,
                    format!(
                        "a set of {} inequalities, beyond the limit of {MAX_POLYTOPE_ROWS}",
                        rows.len()
                    ),
                )
                .label("too many inequalities")
                .hint("describe the set with fewer inequalities"),
            );
            return None;
        }
        let mut poly = Polytope { rows: Vec::new() };
        let mut nonlinear = Vec::new();
        let mut ok = true;
        for r in rows {
            match r {
                SetRow::Linear(c) => match self.polytope(std::slice::from_ref(c), name, dim) {
                    Some(p) => poly.rows.extend(p.rows),
                    None => ok = false,
                },
                SetRow::General(ineq) => {
                    match nonlinear::set_inequality(self, ineq, consts, (name, dim)) {
                        Some(nonlinear::SetIneq::Row(a, b)) => {
                            let fits = |v: &f64| v.is_finite() && v.abs() <= MAX_MAGNITUDE;
                            if fits(&b) && a.iter().all(fits) {
                                poly.rows.push((a, b));
                            } else {
                                self.err(
                                    Diagnostic::new(
                                        Code::Limit,
                                        ineq.span,
                                        "the inequality's coefficients or constant are beyond ±1e15",
                                    )
                                    .label("too large to analyse")
                                    .hint("the numbers of an affine inequality, once its constants are folded, must lie within ±1e15; rescale the units"),
                                );
                                ok = false;
                            }
                        }
                        Some(nonlinear::SetIneq::Nonlinear(tape, span)) => {
                            nonlinear.push((tape, span))
                        }
                        None => ok = false,
                    }
                }
            }
        }
        ok.then_some((poly, nonlinear))
    }

    /// A set `{ … }` that must be linear (`role`: "the initial set", "the
    /// input set", …): its rows, or E0228 at the first nonlinear one.
    fn linear_rows(
        &mut self,
        rows: &[SetRow],
        name: &str,
        dim: usize,
        role: &str,
    ) -> Option<Polytope> {
        let consts = BTreeMap::from([("pi".to_string(), std::f64::consts::PI)]);
        let (poly, nonlinear) = self.set_rows(rows, name, dim, &consts)?;
        if let Some((_, span)) = nonlinear.first() {
            self.err(
                Diagnostic::new(
                    Code::NonlinearSet,
                    *span,
                    format!("{role} must be given by linear inequalities"),
                )
                .label("not affine")
                .hint(if role.contains("initial") {
                    "use a box, a polytope or a ball enclosing the set; nonlinear inequalities are for goal and avoid sets of systems"
                } else {
                    "nonlinear inequalities are for goal and avoid sets of systems; write this set with linear inequalities"
                }),
            );
            return None;
        }
        Some(poly)
    }
}

/// The span of a set's inequality.
fn row_span(r: &SetRow) -> Span {
    match r {
        SetRow::Linear(c) => c.span,
        SetRow::General(i) => i.span,
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

/// The horizon: at least 1, at most [`MAX_HORIZON`].
fn horizon(cx: &mut Ctx, h: Option<&Spanned<u64>>) -> Option<usize> {
    let mut horizon = None;
    if let Some(h) = h {
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

    horizon
}

/// The top-level items of a spec, by kind (duplicates and missing
/// required items are reported while collecting).
struct Items<'a> {
    systems: Vec<&'a System>,
    controllers: Vec<&'a Spanned<String>>,
    initials: Vec<&'a SetDef>,
    goals: Vec<&'a SetDef>,
    avoids: Vec<&'a AvoidDef>,
    horizons: Vec<&'a Spanned<u64>>,
    analyses: Vec<&'a Analysis>,
}

fn items<'a>(cx: &mut Ctx, spec: &'a Spec, has_override: bool) -> Items<'a> {
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
            Item::Network(_)
            | Item::Model(_)
            | Item::Input(_)
            | Item::Require(_)
            | Item::Robust(_)
            | Item::Radius(_)
            | Item::Select(_) => {}
        }
    }
    network::network_items_in_system(cx, spec);
    let spans: Vec<Span> = systems.iter().map(|s| s.name.span).collect();
    cx.duplicates("the system", &spans);
    let spans: Vec<Span> = controllers.iter().map(|c| c.span).collect();
    cx.duplicates("the controller", &spans);
    let spans: Vec<Span> = initials.iter().map(|s| s.name.span).collect();
    cx.duplicates("the initial set", &spans);
    let spans: Vec<Span> = goals.iter().map(|s| s.name.span).collect();
    cx.duplicates("the goal", &spans);
    let spans: Vec<Span> = horizons.iter().map(|h| h.span).collect();
    cx.duplicates("the horizon", &spans);
    let spans: Vec<Span> = analyses.iter().map(|a| a.span).collect();
    cx.duplicates("the analysis block", &spans);
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
            span: Some(WHOLE),
            label: "required item missing".into(),
            hint: Some(format!("add {example}")),
            related: vec![],
        })
    };
    if systems.is_empty() {
        missing(
            cx,
            "system",
            "`system NAME { state x[n] control u[m] A = … B = … }`",
        );
    }
    if controllers.is_empty() && !has_override {
        missing(cx, "controller", "`controller \"path/to/policy.onnx\"`");
    }
    if initials.is_empty() {
        missing(cx, "initial set", "`initial X0 = box(x[0] in [lo, hi], …)`");
    }
    if horizons.is_empty() {
        missing(cx, "horizon", "`horizon N`");
    }
    if goals.is_empty() && avoids.is_empty() {
        missing(
            cx,
            "property to verify (goal or avoid set)",
            "`goal G = box(…)` or `avoid A = { … }`",
        );
    }

    Items {
        systems,
        controllers,
        initials,
        goals,
        avoids,
        horizons,
        analyses,
    }
}

/// Check a parsed spec. `controller` is the controller file as read by the caller
/// (`None` if the spec names none or it was not read).
pub fn check(spec: &Spec, controller: Option<&ControllerFile>) -> Result<Checked, Vec<Diagnostic>> {
    let mut cx = Ctx::new();
    let cx = &mut cx;
    let has_override = controller.is_some_and(|f| f.path_override.is_some());
    let it = items(cx, spec, has_override);
    let path = effective_path(controller, it.controllers.first().copied());
    let controller_sha256 = file_sha256(controller);
    let sp = system::system(cx, &it.systems);
    let mut pp = system::plant(cx, &sp);
    let observed = match (sp.observe, sp.assigns.contains_key("C")) {
        (Some((_, span)), _) => controller::Observed::Observe(span),
        (None, true) => controller::Observed::C,
        (None, false) => controller::Observed::State,
    };
    let ctrl = controller::controller(
        cx,
        path.as_ref(),
        controller,
        (pp.p_dim, observed),
        sp.actuate.is_some(),
        &sp.control,
    );
    let actuate = actuate(cx, &sp, &pp, ctrl.as_ref());
    let horizon = horizon(cx, it.horizons.first().copied());
    let scope = sets::SetScope {
        consts: &pp.consts,
        time: sp.time,
    };
    let sets = sets::sets(
        cx,
        &it.initials,
        &it.goals,
        &it.avoids,
        &sp.state,
        horizon,
        &scope,
    );
    let an = analysis_block::analysis_block(cx, &it.analyses, &sp.state, None);

    // ---- checks that combine sections ----
    if let Some(c) = &ctrl {
        propagator_fits_controller(cx, &an, c, &sp.state, pp.p_dim, horizon);
    }
    samples_drawn(cx, &an);
    if let Some(h) = horizon {
        per_step_lengths(cx, &pp.per_step_lists, h);
    }
    let mut continuous = None;
    if let (Ok(Some(dt)), Some(plants), true) = (sp.time, pp.plant.as_mut(), pp.nonlinear.is_none())
    {
        continuous = Some(plants.clone());
        discretise(cx, plants, dt, sp.time_span.unwrap_or(WHOLE));
    }
    if let (Some(h), Some((_, n))) = (horizon, &sp.state) {
        let span = it.horizons.first().map_or(WHOLE, |h| h.span);
        let directions = match &an.boundary {
            Some(Boundary::Polytope(d)) => d.nrows(),
            Some(Boundary::Hull) => 48,
            _ => 0,
        };
        sizes(
            cx,
            span,
            h,
            *n,
            directions,
            an.samples,
            an.partition.as_ref(),
        );
    }

    // a nonlinear plant is defined where the analysis starts
    if let (Some(nl), Some((_, init)), true) = (&pp.nonlinear, &sets.initial, cx.diags.is_empty()) {
        let names = (
            sp.state.as_ref().map_or("x", |s| s.0.as_str()),
            sp.control.as_ref().map_or("u", |c| c.0.as_str()),
        );
        nonlinear::defined_at_points(
            cx,
            &nl.field,
            &init.bbox(),
            pp.limits.as_ref(),
            &nl.w,
            names,
        );
    }

    if !cx.diags.is_empty() {
        return Err(cx.sorted_diags());
    }
    let plant = match pp.nonlinear {
        Some(nl) => Some(PlantSpec::Nonlinear(NonlinearPlant {
            field: nl.field.field,
            w: nl.w,
            obs: nl.obs,
            v: nl.v,
        })),
        None => pp.plant.map(PlantSpec::Linear),
    };
    // Every part was produced without diagnostics, so each one is present;
    // a missing one here would be a checker bug, reported rather than a panic.
    let assembled = (|| {
        Some(Checked {
            system: sp.sys?.name.node.clone(),
            state: sp.state?,
            control: sp.control?,
            plant: plant?,
            continuous,
            observe_offset: pp.observe_offset,
            actuate,
            dt: sp.time.ok().flatten(),
            limits: pp.limits,
            controller_path: path?.node,
            controller_sha256,
            controller_resolved: controller.map(|f| f.resolved.clone()).unwrap_or_default(),
            controller: ctrl?,
            initial: sets.initial?,
            goal: sets.goal,
            avoids: sets.avoids,
            horizon: horizon?,
            propagator: an.propagator?,
            partitioner: an.partition?,
            boundary: an.boundary?,
            samples: an.samples,
            seed: an.seed,
            slope_steps: an.slope_steps,
        })
    })();
    assembled.ok_or_else(|| vec![incomplete()])
}

/// `actuate […]`: affine in the network's outputs `net[j]`, one entry per
/// control component; `None` without `actuate` or on an error.
fn actuate(
    cx: &mut Ctx,
    sp: &system::SystemPart,
    pp: &system::PlantPart,
    ctrl: Option<&Controller>,
) -> Option<(DMatrix<f64>, DVector<f64>)> {
    let (exprs, span) = sp.actuate?;
    let ((xn, _), (un, m), c) = (sp.state.as_ref()?, sp.control.as_ref()?, ctrl?);
    if exprs.len() != *m {
        cx.err(
            Diagnostic::new(
                Code::Shape,
                span,
                format!(
                    "`actuate` lists {} entries but `{un}` has {m} components",
                    exprs.len()
                ),
            )
            .label(format!("{} entries", exprs.len()))
            .hint(format!("write one `actuate` entry per component of `{un}`")),
        );
    }
    let why = "the control is computed from the network's outputs `net[j]` only";
    let forbidden = vec![
        (xn.as_str(), why),
        (un.as_str(), why),
        ("w", why),
        ("v", why),
    ];
    let map = nonlinear::affine(
        cx,
        exprs,
        &pp.consts,
        ("net", c.outputs),
        forbidden,
        "an `actuate` entry",
    );
    map.filter(|_| exprs.len() == *m)
}

/// The propagator can take the controller: Reach-SDP needs a ReLU network
/// and a semidefinite program within [`MAX_SDP_DIM`]; unrolled CROWN keeps
/// every neuron's bounds for every step.
fn propagator_fits_controller(
    cx: &mut Ctx,
    an: &AnalysisPart,
    c: &Controller,
    state: &Option<(String, usize)>,
    p_dim: Option<usize>,
    horizon: Option<usize>,
) {
    if let Some(span) = an.sdp_span {
        controller::sdp_needs_relu(cx, span, c, controller::Sdp::Reach);
    }
    let neurons = c.net.activation_neurons() as u64;
    let span = an.propagator_span.unwrap_or(WHOLE);
    if let (Some(Propagator::ReachSdp), Some((_, n)), Some(p)) = (an.propagator, state, p_dim) {
        // ξ = (x, v), the hidden neurons, the two saturation layers, and 1
        let m = c.outputs as u64;
        let dim = *n as u64 + p as u64 + neurons + 2 * m + 1;
        if dim > MAX_SDP_DIM {
            cx.err(
                Diagnostic::new(
                    Code::Limit,
                    span,
                    format!("Reach-SDP would solve semidefinite programs of dimension {dim}, beyond the limit of {MAX_SDP_DIM}"),
                )
                .label("too large for Reach-SDP")
                .hint("use `reach_lp` or `crown_unrolled`, or a smaller controller"),
            );
        }
    }
    if let (Some(Propagator::CrownUnrolled), Some(h)) = (an.propagator, horizon) {
        if !within(&[h as u64, neurons.max(1)], MAX_UNROLLED_NEURON_STEPS) {
            cx.err(
                Diagnostic::new(
                    Code::Limit,
                    span,
                    format!("unrolled CROWN would keep {neurons} neurons' bounds for each of {h} steps, beyond the limit of {MAX_UNROLLED_NEURON_STEPS}"),
                )
                .label("too much to keep")
                .hint("use a shorter horizon or `reach_lp`"),
            );
        }
    }
}

/// A hull boundary and a sample-guided partitioner take their directions or
/// their guidance from Monte Carlo samples.
fn samples_drawn(cx: &mut Ctx, an: &AnalysisPart) {
    if let (Some(span), true) = (an.hull_span, an.samples == 0) {
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
    if let (Some((g, span)), true) = (an.guided_span, an.samples == 0) {
        if !matches!(g, Guide::Property | Guide::Bab) {
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
}

/// Every `per_step(…)` list gives a value for each of the `h` steps.
fn per_step_lengths(cx: &mut Ctx, lists: &[(usize, Span)], h: usize) {
    for (len, span) in lists {
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

/// Discretise a continuous-time plant over the time step `dt` (declared at
/// `span`) by zero-order hold; an exponential that overflows is reported.
fn discretise(cx: &mut Ctx, plants: &mut [Plant], dt: f64, span: Span) {
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
                span,
                format!("e^(A·{}) overflows", compact(dt)),
            )
            .label("time step too large for these dynamics")
            .hint("use a smaller dt"),
        );
    }
}

/// The limits on products of sizes (see [`ravel_base::limits`]): simulated steps
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

/// SHA-256 of `bytes` as lower-case hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Names for a message: all of them up to six, else the first five and a count.
fn name_list(names: &[String]) -> String {
    if names.len() <= 6 {
        names.join(", ")
    } else {
        let shown = names.iter().take(5).cloned().collect::<Vec<_>>().join(", ");
        format!("{shown} and {} more", names.len() - 5)
    }
}
