//! The `analysis` block: propagator, partitioner and budget, boundary (or,
//! in a network spec, the output shape), samples and seed.

use std::collections::BTreeMap;

use super::{partitioner_names, Ctx, BOUNDARIES, DEFAULT_SAMPLES, PLANNED_PROPAGATORS};
use crate::ir::{Guide, NetPropagator, Partitioner};
use ravel_analysis::closed_loop::{Boundary, Propagator};
use ravel_analysis::partition::Budget;
use ravel_analysis::shape::Shape;
use ravel_base::limits::{
    within, MAX_BOUNDARY_DIRECTIONS, MAX_CELLS, MAX_SAMPLES, MAX_SLOPE_STEPS,
};
use ravel_syntax::ast::*;
use ravel_syntax::diag::{did_you_mean, Code, Diagnostic};

/// Default budget of the guided partitioners.
pub const DEFAULT_BUDGET: Budget = Budget {
    calls: 256,
    min_size: 1.0 / 64.0,
    seconds: None,
};

/// Branch and bound's default smallest cell, as a fraction of the input
/// set's width along each input (2⁻³⁰: about 30 halvings of every input).
pub const BAB_MIN_SIZE: f64 = 1.0 / 1_073_741_824.0;

/// The checked analysis choices (each `None` when it had an error), with
/// the spans later checks point at.
pub(super) struct AnalysisPart {
    pub propagator: Option<Propagator>,
    pub partition: Option<Partitioner>,
    pub boundary: Option<Boundary>,
    pub hull_span: Option<Span>,
    pub guided_span: Option<(Guide, Span)>,
    pub sdp_span: Option<Span>,
    /// Where the propagator was named (absent: the default).
    pub propagator_span: Option<Span>,
    pub samples: usize,
    pub seed: u64,
    /// Slope-optimisation steps (0: CROWN's own slopes).
    pub slope_steps: usize,
    /// Where slope optimisation was asked for.
    slopes_span: Option<Span>,
    /// Network specs: the propagator and the output shape.
    pub net_propagator: Option<NetPropagator>,
    pub shape: Option<Shape>,
}

impl AnalysisPart {
    /// What an absent or empty analysis block means: a single cell over
    /// `state` (when it was declared without error).
    fn defaults(state: &Option<(String, usize)>) -> Self {
        AnalysisPart {
            propagator: Some(Propagator::ReachLp),
            partition: state
                .as_ref()
                .map(|(_, n)| Partitioner::Uniform(vec![1; *n])),
            boundary: Some(Boundary::Box),
            hull_span: None,
            guided_span: None,
            sdp_span: None,
            propagator_span: None,
            samples: DEFAULT_SAMPLES,
            seed: 0,
            slope_steps: 0,
            slopes_span: None,
            net_propagator: Some(NetPropagator::Crown),
            shape: Some(Shape::Box),
        }
    }
}

/// The output vector of a network spec (`None` in a system spec; `Some(None)`
/// when the network block declared it with an error).
type Output<'a> = Option<&'a Option<(String, usize)>>;

/// Check the (first) analysis block; defaults where it says nothing.
/// `state` is what a partition splits (the state, or a network's input);
/// `output` is present for network specs (the output vector shapes are over).
pub(super) fn analysis_block(
    cx: &mut Ctx,
    analyses: &[&Analysis],
    state: &Option<(String, usize)>,
    output: Output,
) -> AnalysisPart {
    let mut part = AnalysisPart::defaults(state);
    if let Some(an) = analyses.first() {
        let mut seen: BTreeMap<&str, Span> = BTreeMap::new();
        for st in &an.stmts {
            let key = statement_key(&st.node);
            if let Some(first) = seen.get(key) {
                cx.duplicate(&format!("`{key}`"), *first, st.span);
                continue;
            }
            seen.insert(key, st.span);
            statement(cx, st, state, output, &mut part);
        }
    }
    slopes_need_back_substitution(cx, &part, output.is_some());
    part
}

/// The key a statement is stated under (each at most once per block).
fn statement_key(st: &AnalysisStmt) -> &'static str {
    match st {
        AnalysisStmt::Propagator(_) => "propagator",
        AnalysisStmt::Partitioner(_) | AnalysisStmt::Uniform(_) | AnalysisStmt::Guided { .. } => {
            "partitioner"
        }
        AnalysisStmt::Boundary(_) | AnalysisStmt::BoundaryPolytope(_) => "boundary",
        AnalysisStmt::Shape(_) | AnalysisStmt::ShapePolytope(_) => "shape",
        AnalysisStmt::Samples(_) => "samples",
        AnalysisStmt::Seed(_) => "seed",
        AnalysisStmt::OptimiseSlopes(_) => "optimise_slopes",
    }
}

/// Check one statement (the first under its key) into `part`.
fn statement(
    cx: &mut Ctx,
    st: &Spanned<AnalysisStmt>,
    state: &Option<(String, usize)>,
    output: Output,
    part: &mut AnalysisPart,
) {
    let network = output.is_some();
    match &st.node {
        AnalysisStmt::Propagator(p) if network => network_propagator(cx, p, part),
        AnalysisStmt::Boundary(_) | AnalysisStmt::BoundaryPolytope(_) if network => {
            cx.err(
                Diagnostic::new(Code::SpecKind, st.span, "`boundary` shapes a system spec's reachable sets")
                    .label("in a network spec")
                    .hint("the output set of a network spec is shaped by `shape box`, `shape lower_bounds`, `shape hull` or `shape polytope …`"),
            );
        }
        AnalysisStmt::Shape(_) | AnalysisStmt::ShapePolytope(_) if !network => {
            cx.err(
                Diagnostic::new(Code::SpecKind, st.span, "`shape` shapes a network spec's output set")
                    .label("in a system spec")
                    .hint("the reachable sets of a system spec are shaped by `boundary box`, `boundary hull` or `boundary polytope …`"),
            );
        }
        AnalysisStmt::ShapePolytope(v) => {
            if let Some(Some((yn, m))) = output {
                part.shape = match cx.boundary_polytope(v, yn, *m) {
                    Some(Boundary::Polytope(d)) => Some(Shape::Polytope(d)),
                    _ => None,
                };
            }
        }
        AnalysisStmt::Shape(b) => shape(cx, b, output, part),
        AnalysisStmt::Propagator(p) => closed_loop_propagator(cx, p, part),
        // `none` is the default
        AnalysisStmt::Partitioner(p) if p.node != "none" => unknown_partitioner(cx, p),
        AnalysisStmt::Partitioner(_) => {}
        AnalysisStmt::Uniform(ks) => {
            if let Some((xn, n)) = state {
                part.partition = uniform(cx, st.span, ks, xn, *n);
            }
        }
        AnalysisStmt::Guided { guide, budget } => {
            // the grammar admits exactly the guides' names
            let g = Guide::from_name(&guide.node).unwrap_or(Guide::Property);
            part.guided_span = Some((g, st.span));
            if network && g == Guide::Property {
                cx.err(
                    Diagnostic::new(Code::SpecKind, guide.span, "the `property` partitioner refines a closed loop's initial set")
                        .label("in a network spec")
                        .hint("a network spec's properties are decided by branch and bound: `partitioner bab`"),
                );
            }
            if !network && g == Guide::Bab {
                cx.err(
                    Diagnostic::new(Code::SpecKind, guide.span, "branch and bound (`bab`) decides a network spec's properties")
                        .label("in a closed-loop spec")
                        .hint("a closed loop's initial set is refined towards its properties by `partitioner property`"),
                );
            }
            let given = |name: &str| budget.iter().any(|(k, _)| k.node == name);
            let (calls_given, size_given) = (given("calls"), given("min_size"));
            part.partition = cx.budget(budget).map(|mut budget| {
                if g == Guide::Bab {
                    // branch and bound stops when the properties are
                    // settled: by default its budget is the limit, and it
                    // splits as fine as it must (the time limit ends it)
                    if !calls_given {
                        budget.calls = ravel_base::limits::MAX_CALLS as usize;
                    }
                    if !size_given {
                        budget.min_size = BAB_MIN_SIZE;
                    }
                }
                Partitioner::Guided { guide: g, budget }
            });
        }
        AnalysisStmt::BoundaryPolytope(v) => {
            if let Some((xn, n)) = state {
                part.boundary = cx.boundary_polytope(v, xn, *n);
            }
        }
        AnalysisStmt::Boundary(b) => boundary(cx, b, state, part),
        AnalysisStmt::Samples(s) => {
            let what = format!("more than {MAX_SAMPLES} samples");
            if let Some(k) = at_most(cx, s, MAX_SAMPLES, what, "use fewer samples") {
                part.samples = k;
            }
        }
        AnalysisStmt::Seed(s) => part.seed = s.node,
        AnalysisStmt::OptimiseSlopes(s) => {
            let what = format!("more than {MAX_SLOPE_STEPS} slope-optimisation steps");
            let hint = "a few steps (3 to 20) give most of the gain";
            if let Some(k) = at_most(cx, s, MAX_SLOPE_STEPS, what, hint) {
                part.slope_steps = k;
                part.slopes_span = Some(st.span);
            }
        }
    }
}

/// `propagator …` in a network spec.
fn network_propagator(cx: &mut Ctx, p: &Spanned<String>, part: &mut AnalysisPart) {
    part.net_propagator = NetPropagator::from_name(&p.node);
    part.propagator_span = Some(p.span);
    if part.net_propagator == Some(NetPropagator::Sdp) {
        part.sdp_span = Some(p.span);
    }
    if part.net_propagator.is_none() {
        let names: Vec<&str> = NetPropagator::ALL.iter().map(|p| p.name()).collect();
        let list = names.join(", ");
        let mut d = Diagnostic::new(
            Code::UnknownName,
            p.span,
            format!("unknown network propagator `{}`", p.node),
        )
        .label("not a network propagator");
        d = match (
            Propagator::from_name(&p.node),
            did_you_mean(&p.node, names.iter().copied()),
        ) {
            (Some(_), _) => d.hint(format!(
                "`{}` bounds a closed loop; a network spec takes one of: {list}",
                p.node
            )),
            (None, Some(s)) => d.hint(format!("did you mean `{s}`? Available: {list}")),
            (None, None) => d.hint(format!("available: {list}")),
        };
        cx.err(d);
    }
}

/// `propagator …` in a system spec.
fn closed_loop_propagator(cx: &mut Ctx, p: &Spanned<String>, part: &mut AnalysisPart) {
    part.propagator = match Propagator::from_name(&p.node) {
        Some(prop) => {
            if prop == Propagator::ReachSdp {
                part.sdp_span = Some(p.span);
            }
            part.propagator_span = Some(p.span);
            Some(prop)
        }
        None => {
            let other = p.node.as_str();
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
            let names: Vec<&str> = Propagator::ALL.iter().map(|p| p.name()).collect();
            let list = names.join(", ");
            d = match (planned, did_you_mean(other, names.iter().copied())) {
                (true, _) => d.hint(format!(
                    "`{other}` is planned but not implemented yet; available: {list}"
                )),
                (false, Some(s)) => d.hint(format!("did you mean `{s}`? Available: {list}")),
                (false, None) => d.hint(format!("available: {list}")),
            };
            cx.err(d);
            None
        }
    }
}

/// `shape …` (a network spec's output set) other than `shape polytope …`.
fn shape(cx: &mut Ctx, b: &Spanned<String>, output: Output, part: &mut AnalysisPart) {
    part.shape = match b.node.as_str() {
        "box" => Some(Shape::Box),
        "lower_bounds" => Some(Shape::LowerBounds),
        "hull" => {
            part.hull_span = Some(b.span);
            match output {
                Some(Some((_, 2))) | Some(None) | None => Some(Shape::Hull),
                Some(Some((yn, m))) => {
                    cx.err(
                        Diagnostic::new(Code::Boundary, b.span, format!("a convex-hull shape needs a 2-D output, but `{yn}` has {m} components"))
                            .label("2-D only")
                            .hint("use `shape box` or `shape polytope [[…], …]` with explicit directions"),
                    );
                    None
                }
            }
        }
        "polytope" => {
            cx.err(
                Diagnostic::new(Code::Boundary, b.span, "a polytope shape needs its directions")
                    .label("no directions")
                    .hint("write `shape polytope 8` (evenly spread, 2-D outputs) or `shape polytope [[1, 1], [1, -1]]`"),
            );
            None
        }
        other => {
            let names = ["box", "lower_bounds", "hull", "polytope"];
            let mut d = Diagnostic::new(
                Code::UnknownName,
                b.span,
                format!("unknown output shape `{other}`"),
            )
            .label("not a shape");
            d = match did_you_mean(other, names) {
                Some(s) => d.hint(format!("did you mean `{s}`?")),
                None => d.hint("available: box, lower_bounds, hull, polytope K, polytope [[…], …]"),
            };
            cx.err(d);
            None
        }
    };
}

/// `boundary …` (a system spec's reachable sets) other than `boundary polytope …`.
fn boundary(
    cx: &mut Ctx,
    b: &Spanned<String>,
    state: &Option<(String, usize)>,
    part: &mut AnalysisPart,
) {
    if b.node == "polytope" {
        cx.err(
            Diagnostic::new(Code::Boundary, b.span, "a polytope boundary needs its directions")
                .label("no directions")
                .hint("write `boundary polytope 8` (evenly spread, 2-D states) or `boundary polytope [[1, 1], [1, -1]]`"),
        );
        part.boundary = None;
    } else if b.node == "hull" {
        match state.as_ref().map(|(_, n)| *n) {
            Some(2) | None => {
                part.boundary = Some(Boundary::Hull);
                part.hull_span = Some(b.span);
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
                part.boundary = None;
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
        part.boundary = None;
    }
}

/// `partitioner NAME` with a name that is no partitioner.
fn unknown_partitioner(cx: &mut Ctx, p: &Spanned<String>) {
    let mut d = Diagnostic::new(
        Code::UnknownName,
        p.span,
        format!("unknown partitioner `{}`", p.node),
    )
    .label("not a partitioner");
    d = match did_you_mean(&p.node, partitioner_names()) {
        Some(s) => d.hint(format!(
            "did you mean `{s}`? Available: none, uniform [k, …], sg, gsg, property"
        )),
        None => d.hint(
            "available: none, uniform [k, …], sg, gsg, property (each with an optional budget)",
        ),
    };
    cx.err(d);
}

/// `partitioner uniform [k, …]` over the vector `xn` of dimension `n`.
fn uniform(
    cx: &mut Ctx,
    span: Span,
    ks: &[Spanned<u64>],
    xn: &str,
    n: usize,
) -> Option<Partitioner> {
    if ks.len() != n {
        cx.err(
            Diagnostic::new(
                Code::Partition,
                span,
                format!(
                    "the grid has {} counts but `{xn}` has {n} components",
                    ks.len()
                ),
            )
            .label(format!("{} count(s)", ks.len()))
            .hint(format!(
                "give one cell count per state component, e.g. uniform [{}]",
                vec!["2"; n].join(", ")
            )),
        );
        return None;
    }
    if let Some(k) = ks.iter().find(|k| k.node == 0) {
        cx.err(
            Diagnostic::new(
                Code::Partition,
                k.span,
                "a grid needs at least one cell per dimension",
            )
            .label("zero cells")
            .hint("use 1 to leave a dimension unsplit"),
        );
        return None;
    }
    let counts: Vec<u64> = ks.iter().map(|k| k.node).collect();
    if !within(&counts, MAX_CELLS) {
        cx.err(
            Diagnostic::new(
                Code::Limit,
                span,
                format!("the grid has more than {MAX_CELLS} cells"),
            )
            .label("too many cells")
            .hint("use fewer cells per dimension"),
        );
        return None;
    }
    Some(Partitioner::Uniform(
        ks.iter().map(|k| k.node as usize).collect(),
    ))
}

/// Optimised slopes need a propagator that back-substitutes through the
/// controller's ReLU relaxations.
fn slopes_need_back_substitution(cx: &mut Ctx, part: &AnalysisPart, network: bool) {
    let Some(span) = part.slopes_span.filter(|_| part.slope_steps > 0) else {
        return;
    };
    let refused = if network {
        part.net_propagator
            .filter(|p| !matches!(p, NetPropagator::Crown | NetPropagator::Sdp))
            .map(|p| (p.name(), "crown, sdp"))
    } else {
        part.propagator
            .filter(|p| {
                !matches!(
                    p,
                    Propagator::ReachLp | Propagator::CrownUnrolled | Propagator::ReachSdp
                )
            })
            .map(|p| (p.name(), "reach_lp, crown_unrolled, reach_sdp"))
    };
    if let Some((name, takes)) = refused {
        cx.err(
            Diagnostic::new(
                Code::SlopeSteps,
                span,
                format!("propagator `{name}` has no slopes to optimise"),
            )
            .label("no effect with this propagator")
            .hint(format!(
                "slopes are optimised by the propagators {takes}; remove this line or change the propagator"
            )),
        );
    }
}

/// `Some(count)` when `count ≤ max`; otherwise an E0216 limit diagnostic.
fn at_most(
    cx: &mut Ctx,
    count: &Spanned<u64>,
    max: u64,
    what: String,
    hint: &str,
) -> Option<usize> {
    if count.node > max {
        cx.err(
            Diagnostic::new(Code::Limit, count.span, what)
                .label("too many")
                .hint(hint.to_string()),
        );
        return None;
    }
    usize::try_from(count.node).ok()
}

impl Ctx {
    /// `boundary polytope K` or `boundary polytope [[…], …]`.
    pub(super) fn boundary_polytope(
        &mut self,
        v: &Spanned<Value>,
        name: &str,
        n: usize,
    ) -> Option<Boundary> {
        match &v.node {
            Value::Scalar(k) => {
                let k = *k as usize;
                if n != 2 {
                    self.err(
                        Diagnostic::new(Code::Boundary, v.span, format!("evenly spread directions need a 2-D state, but `{name}` has {n} components"))
                            .label("a count of directions")
                            .hint(format!("give the directions as a matrix with {n} columns: `boundary polytope [[…], …]`")),
                    );
                    return None;
                }
                if k == 0 || k > MAX_BOUNDARY_DIRECTIONS {
                    self.err(
                        Diagnostic::new(
                            Code::Boundary,
                            v.span,
                            format!("{k} directions: a polytope boundary needs between 1 and {MAX_BOUNDARY_DIRECTIONS}"),
                        )
                        .label("bad count")
                        .hint("8 or 16 directions are typical"),
                    );
                    return None;
                }
                Some(Boundary::spread(k))
            }
            Value::Matrix(rows) => {
                let m = self.matrix(
                    v,
                    "the boundary directions",
                    rows.len(),
                    Some(n),
                    &format!("one direction per row, {n} columns (one per component of `{name}`)"),
                )?;
                for (r, row) in rows.iter().enumerate() {
                    if m.row(r).iter().all(|v| *v == 0.0) {
                        self.err(
                            Diagnostic::new(
                                Code::Boundary,
                                row.span,
                                "a zero direction bounds nothing",
                            )
                            .label("all zeros")
                            .hint("remove the row or give it a non-zero entry"),
                        );
                        return None;
                    }
                }
                Some(Boundary::Polytope(m))
            }
            _ => None,
        }
    }

    /// The budget of a guided partitioner.
    pub(super) fn budget(&mut self, items: &[(Spanned<String>, Spanned<f64>)]) -> Option<Budget> {
        const NAMES: [&str; 3] = ["calls", "min_size", "time"];
        let mut b = DEFAULT_BUDGET;
        let mut ok = true;
        let mut seen: Vec<(&str, Span)> = Vec::new();
        for (k, v) in items {
            if let Some((_, first)) = seen.iter().find(|(s, _)| *s == k.node) {
                self.duplicate(&format!("the budget item `{}`", k.node), *first, k.span);
                ok = false;
                continue;
            }
            seen.push((&k.node, k.span));
            let x = self.finite(v);
            let bad = |cx: &mut Ctx, what: &str, hint: &str| {
                cx.err(
                    Diagnostic::new(Code::Budget, v.span, format!("`{}` {what}", k.node))
                        .label("invalid budget")
                        .hint(hint.to_string()),
                );
            };
            match k.node.as_str() {
                "calls" => {
                    if !((1.0..=ravel_base::limits::MAX_CALLS as f64).contains(&x)
                        && x.fract() == 0.0)
                    {
                        bad(
                            self,
                            "must be a whole number of cell evaluations from 1 to 100000",
                            "e.g. `calls 200`",
                        );
                        ok = false;
                    } else {
                        b.calls = x as usize;
                    }
                }
                "min_size" => {
                    if !(x > 0.0 && x <= 1.0) {
                        bad(
                            self,
                            "must be a fraction of the initial set's width in (0, 1]",
                            "e.g. `min_size 0.01`: cells narrower than 1 % are not split",
                        );
                        ok = false;
                    } else {
                        b.min_size = x;
                    }
                }
                "time" => {
                    if !(x > 0.0 && x.is_finite()) {
                        bad(
                            self,
                            "must be a positive number of seconds",
                            "e.g. `time 2.5`",
                        );
                        ok = false;
                    } else {
                        b.seconds = Some(x);
                    }
                }
                other => {
                    let mut d = Diagnostic::new(
                        Code::UnknownName,
                        k.span,
                        format!("unknown budget item `{other}`"),
                    )
                    .label("not a budget item");
                    d = match did_you_mean(other, NAMES) {
                        Some(s) => d.hint(format!(
                            "did you mean `{s}`? Budget items: calls, min_size, time"
                        )),
                        None => d.hint("budget items: calls N, min_size r, time s"),
                    };
                    self.err(d);
                    ok = false;
                }
            }
        }
        ok.then_some(b)
    }
}
