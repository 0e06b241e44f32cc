//! The `analysis` block: propagator, partitioner and budget, boundary,
//! samples and seed.

use std::collections::BTreeMap;

use super::{partitioner_names, Ctx, BOUNDARIES, DEFAULT_SAMPLES, PLANNED_PROPAGATORS};
use crate::analysis::closed_loop::{Boundary, Propagator};
use crate::diag::{did_you_mean, Code, Diagnostic};
use crate::ir::{Guide, Partitioner};
use crate::limits::{within, MAX_CELLS, MAX_SAMPLES};
use crate::syntax::ast::*;

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
}

/// Check the (first) analysis block; defaults where it says nothing.
pub(super) fn analysis(
    cx: &mut Ctx,
    analyses: &[&Analysis],
    state: &Option<(String, usize)>,
) -> AnalysisPart {
    let mut propagator = Some(Propagator::ReachLp);
    let mut partition: Option<Partitioner> = state
        .as_ref()
        .map(|(_, n)| Partitioner::Uniform(vec![1; *n]));
    let mut boundary = Some(Boundary::Box);
    let mut hull_span = None;
    let mut guided_span = None;
    let mut sdp_span = None;
    let mut propagator_span = None;
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
                    propagator = match Propagator::from_name(&p.node) {
                        Some(prop) => {
                            if prop == Propagator::ReachSdp {
                                sdp_span = Some(p.span);
                            }
                            propagator_span = Some(p.span);
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
                            let names: Vec<&str> =
                                Propagator::ALL.iter().map(|p| p.name()).collect();
                            let list = names.join(", ");
                            d = match (planned, did_you_mean(other, names.iter().copied())) {
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
                    // the grammar admits exactly the guides' names
                    let g = Guide::from_name(&guide.node).unwrap_or(Guide::Property);
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

    AnalysisPart {
        propagator,
        partition,
        boundary,
        hull_span,
        guided_span,
        sdp_span,
        propagator_span,
        samples,
        seed,
    }
}
