//! The sets: the initial set, the goal and the avoid sets with their steps.

use super::{AvoidSpec, Ctx, GoalDef};
use ravel_analysis::sets::{Polytope, Region};
use ravel_base::limits::MAX_POLYTOPE_DIM;
use ravel_syntax::ast::*;
use ravel_syntax::diag::{Code, Diagnostic};

/// The checked sets (each `None` or left out when it had an error).
pub(super) struct SetsPart {
    pub initial: Option<(String, Region)>,
    pub goal: Option<GoalDef>,
    pub avoids: Vec<AvoidSpec>,
}

/// Check the initial set, the goal and the avoid sets over the state.
pub(super) fn sets(
    cx: &mut Ctx,
    initials: &[&SetDef],
    goals: &[&SetDef],
    avoids: &[&AvoidDef],
    state: &Option<(String, usize)>,
    horizon: Option<usize>,
) -> SetsPart {
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
            } else if let Some(first) = members.first() {
                match &first.node {
                    SetAtom::Box(b) => {
                        let sb = Spanned {
                            node: b.clone(),
                            span: first.span,
                        };
                        initial = cx
                            .box_set(&sb, xn, *n, true, "the initial set")
                            .map(|b| (init.name.node.clone(), Region::Box(b)));
                    }
                    SetAtom::Polytope(_) if *n > MAX_POLYTOPE_DIM => {
                        cx.err(
                            Diagnostic::new(
                                Code::Limit,
                                first.span,
                                format!("a polytope initial set in {n} dimensions, beyond the limit of {MAX_POLYTOPE_DIM}"),
                            )
                            .label("too many dimensions for a polytope")
                            .hint("use a box or a ball, which are bounded in closed form"),
                        );
                    }
                    SetAtom::Polytope(cs) => {
                        initial = cx
                            .polytope(cs, xn, *n)
                            .and_then(|p| cx.bounded_polytope(p, first.span, "the initial set"))
                            .map(|r| (init.name.node.clone(), r));
                    }
                    SetAtom::Ball(b) => {
                        initial = cx
                            .ball(b, first.span, xn, *n)
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
            } else if let Some(p) = members
                .first()
                .and_then(|m| cx.set_atom(m, xn, *n, "the goal"))
            {
                goal = Some(GoalDef {
                    name: g.name.node.clone(),
                    set: p,
                });
            }
        }
        for a in avoids {
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

    SetsPart {
        initial,
        goal,
        avoids: avoid_specs,
    }
}
