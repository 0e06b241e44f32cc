//! The sets: the initial set, the goal and the avoid sets with their steps.

use super::{AvoidSpec, Ctx, GoalDef};
use ravel_analysis::sets::{Polytope, Region};
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
    let mut part = SetsPart {
        initial: None,
        goal: None,
        avoids: Vec::new(),
    };
    let Some((xn, n)) = state else {
        return part;
    };
    if let Some(init) = initials.first() {
        part.initial = initial(cx, init, xn, *n);
    }
    if let Some(g) = goals.first() {
        part.goal = goal(cx, g, xn, *n);
    }
    for a in avoids {
        if let Some(spec) = avoid(cx, a, xn, *n, horizon) {
            part.avoids.push(spec);
        }
    }
    part
}

/// The initial set over the state `xn` of dimension `n`: one box, polytope or ball.
fn initial(cx: &mut Ctx, init: &SetDef, xn: &str, n: usize) -> Option<(String, Region)> {
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
        return None;
    }
    let region = cx.region(members.first()?, xn, n, "initial set")?;
    Some((init.name.node.clone(), region))
}

/// The goal: one box or polytope over the state.
fn goal(cx: &mut Ctx, g: &SetDef, xn: &str, n: usize) -> Option<GoalDef> {
    let members = &g.set.node.members;
    if members.len() > 1 {
        cx.err(
            Diagnostic::new(Code::SetKind, g.set.span, "the goal cannot be a union")
                .label("a union")
                .hint("the final reachable set must lie in one box or polytope"),
        );
        return None;
    }
    let set = cx.set_atom(members.first()?, xn, n, "the goal")?;
    Some(GoalDef {
        name: g.name.node.clone(),
        set,
    })
}

/// An avoid set: a union of boxes and polytopes over the state, at the steps
/// given (every step up to the horizon when none are).
fn avoid(
    cx: &mut Ctx,
    a: &AvoidDef,
    xn: &str,
    n: usize,
    horizon: Option<usize>,
) -> Option<AvoidSpec> {
    let members: Vec<Option<Polytope>> = a
        .set
        .node
        .members
        .iter()
        .map(|m| cx.set_atom(m, xn, n, "the avoid set"))
        .collect();
    let steps = match (&a.steps, horizon) {
        (None, Some(h)) => Some((0, h)),
        (Some(s), h) => step_range(cx, s, h),
        (None, None) => None,
    };
    if !members.iter().all(Option::is_some) {
        return None;
    }
    Some(AvoidSpec {
        name: a.name.node.clone(),
        members: members.into_iter().flatten().collect(),
        steps: steps?,
    })
}

/// `at steps [lo, hi]`: not empty, and within the horizon `h` (when known).
fn step_range(cx: &mut Ctx, s: &Spanned<(u64, u64)>, h: Option<usize>) -> Option<(usize, usize)> {
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
        return None;
    }
    if let Some(h) = h.filter(|h| hi as usize > *h) {
        cx.err(
            Diagnostic::new(
                Code::StepRange,
                s.span,
                format!("step {hi} is beyond the horizon {h}"),
            )
            .label("beyond the horizon")
            .hint(format!("steps run from 0 (the initial set) to {h}")),
        );
        return None;
    }
    Some((lo as usize, hi as usize))
}
