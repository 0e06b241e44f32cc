//! The sets: the initial set, the goal and the avoid sets with their steps
//! or time windows (seconds of the plant's time, mapped to sampling
//! instants and the control periods between them).

use std::collections::BTreeMap;

use super::{AvoidSpec, Ctx, GoalDef};
use crate::ir::{GoalMode, StateSet, Window};
use ravel_analysis::sets::Region;
use ravel_syntax::ast::*;
use ravel_syntax::diag::{compact, Code, Diagnostic};

/// The checked sets (each `None` or left out when it had an error).
pub(super) struct SetsPart {
    pub initial: Option<(String, Region)>,
    pub goal: Option<GoalDef>,
    pub avoids: Vec<AvoidSpec>,
}

/// What the goal and avoid sets may refer to: the named constants and the
/// plant's time (`Ok(Some(dt))` for continuous time, `Ok(None)` for
/// discrete time, `Err` when the time declaration had an error).
pub(super) struct SetScope<'a> {
    pub consts: &'a BTreeMap<String, f64>,
    pub time: Result<Option<f64>, ()>,
}

/// Check the initial set, the goal and the avoid sets over the state.
pub(super) fn sets(
    cx: &mut Ctx,
    initials: &[&SetDef],
    goals: &[&SetDef],
    avoids: &[&AvoidDef],
    state: &Option<(String, usize)>,
    horizon: Option<usize>,
    scope: &SetScope,
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
        part.goal = goal(cx, g, xn, *n, horizon, scope);
    }
    for a in avoids {
        if let Some(spec) = avoid(cx, a, xn, *n, horizon, scope) {
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

/// A goal or avoid set's member over the state: a box, or inequalities
/// (linear rows and nonlinear constraints `g(x) ≤ 0`).
fn member(
    cx: &mut Ctx,
    a: &Spanned<SetAtom>,
    xn: &str,
    n: usize,
    role: &str,
    scope: &SetScope,
) -> Option<StateSet> {
    match &a.node {
        SetAtom::Inequalities(rows) => {
            let (poly, nonlinear) = cx.set_rows(rows, xn, n, scope.consts)?;
            Some(StateSet {
                poly,
                nonlinear: nonlinear.into_iter().map(|(t, _)| t).collect(),
            })
        }
        _ => cx.set_atom(a, xn, n, role).map(StateSet::linear),
    }
}

/// The goal: one box or set of inequalities over the state, at the
/// horizon or at the times its clause gives.
fn goal(
    cx: &mut Ctx,
    g: &SetDef,
    xn: &str,
    n: usize,
    horizon: Option<usize>,
    scope: &SetScope,
) -> Option<GoalDef> {
    let members = &g.set.node.members;
    if members.len() > 1 {
        cx.err(
            Diagnostic::new(Code::SetKind, g.set.span, "the goal cannot be a union")
                .label("a union")
                .hint("the reachable set must lie in one box or set of inequalities"),
        );
        return None;
    }
    let set = members
        .first()
        .and_then(|m| member(cx, m, xn, n, "the goal", scope));
    let (window, mode) = match &g.when {
        None => (horizon.map(Window::at), GoalMode::Always),
        Some(w) => match &w.node {
            GoalWhen::AtTime(t) => (at_time(cx, t, horizon, scope), GoalMode::Always),
            GoalWhen::Always(win) => (window(cx, win, horizon, scope), GoalMode::Always),
            GoalWhen::Eventually(win) => (window(cx, win, horizon, scope), GoalMode::Eventually),
        },
    };
    Some(GoalDef {
        name: g.name.node.clone(),
        set: set?,
        window: window?,
        mode,
    })
}

/// An avoid set: a union of boxes and sets of inequalities over the
/// state, at the steps or in the time window given (every step up to the
/// horizon when none is).
fn avoid(
    cx: &mut Ctx,
    a: &AvoidDef,
    xn: &str,
    n: usize,
    horizon: Option<usize>,
    scope: &SetScope,
) -> Option<AvoidSpec> {
    let members: Vec<Option<StateSet>> = a
        .set
        .node
        .members
        .iter()
        .map(|m| member(cx, m, xn, n, "the avoid set", scope))
        .collect();
    let window = match (&a.steps, &a.during, horizon) {
        (_, Some(w), h) => window(cx, w, h, scope),
        (None, None, Some(h)) => Some(Window::steps(0, h)),
        (Some(s), None, h) => step_range(cx, s, h).map(|(a, b)| Window::steps(a, b)),
        (None, None, None) => None,
    };
    if !members.iter().all(Option::is_some) {
        return None;
    }
    Some(AvoidSpec {
        name: a.name.node.clone(),
        members: members.into_iter().flatten().collect(),
        window: window?,
    })
}

/// Two times closer than this (relative to the larger of the time and the
/// time step) are the same instant.
pub const TIME_TOLERANCE: f64 = 1e-9;

/// The plant's time step for a time clause at `span`, or E0229 (none when
/// the time declaration itself was wrong: reported there).
fn time_step(cx: &mut Ctx, span: Span, scope: &SetScope) -> Option<f64> {
    match scope.time {
        Ok(Some(dt)) => Some(dt),
        Ok(None) => {
            cx.err(
                Diagnostic::new(
                    Code::TimeWindow,
                    span,
                    "a time in seconds needs a plant with a time step",
                )
                .label("the plant is in discrete time")
                .hint("declare `time continuous dt …`, or count steps: `avoid … at steps [a, b]`"),
            );
            None
        }
        Err(()) => None,
    }
}

/// A time of a clause: finite, within the limits, not negative.
fn time_value(cx: &mut Ctx, t: &Spanned<f64>) -> Option<f64> {
    let before = cx.diags.len();
    let v = cx.finite(t);
    if cx.diags.len() != before {
        return None;
    }
    if v < 0.0 {
        cx.err(
            Diagnostic::new(
                Code::TimeWindow,
                t.span,
                format!("the time {} is before the start", compact(v)),
            )
            .label("negative")
            .hint("times are seconds from the initial set, at 0"),
        );
        return None;
    }
    Some(v)
}

/// The last time of the horizon `h` steps of `dt`, or E0229 at `span`
/// when `t` is beyond it.
fn within_horizon(cx: &mut Ctx, t: f64, span: Span, dt: f64, h: usize) -> bool {
    let end = h as f64 * dt;
    if t <= end + TIME_TOLERANCE * end.max(dt) {
        return true;
    }
    cx.err(
        Diagnostic::new(
            Code::TimeWindow,
            span,
            format!(
                "the time {} is beyond the horizon, {h} steps of {} s = {} s",
                compact(t),
                compact(dt),
                compact(end)
            ),
        )
        .label("after the last step")
        .hint(format!("times run from 0 to {} s", compact(end))),
    );
    false
}

/// `at time T`: the step `T / dt`, which must be a whole number of steps
/// (up to [`TIME_TOLERANCE`]) within the horizon.
fn at_time(
    cx: &mut Ctx,
    t: &Spanned<f64>,
    horizon: Option<usize>,
    scope: &SetScope,
) -> Option<Window> {
    let v = time_value(cx, t);
    let dt = time_step(cx, t.span, scope)?;
    let (v, h) = (v?, horizon?);
    if !within_horizon(cx, v, t.span, dt, h) {
        return None;
    }
    let k = (v / dt).round();
    if (k * dt - v).abs() > TIME_TOLERANCE * v.max(dt) {
        let below = (v / dt).floor();
        cx.err(
            Diagnostic::new(
                Code::TimeWindow,
                t.span,
                format!(
                    "{} s is not a sampling instant (every {} s)",
                    compact(v),
                    compact(dt)
                ),
            )
            .label("between two instants")
            .hint(format!(
                "the nearest instants are {} s and {} s",
                compact(below * dt),
                compact((below + 1.0) * dt)
            )),
        );
        return None;
    }
    Some(Window::at((k as usize).min(h)))
}

/// `during [t0, t1]`: every sampling instant in the window (an end within
/// [`TIME_TOLERANCE`] of an instant counts as that instant) and every
/// control period that overlaps it.
fn window(
    cx: &mut Ctx,
    w: &ravel_syntax::ast::Window,
    horizon: Option<usize>,
    scope: &SetScope,
) -> Option<Window> {
    let (t0, t1) = (time_value(cx, &w.t0), time_value(cx, &w.t1));
    let dt = time_step(cx, w.span, scope)?;
    let (t0, t1, h) = (t0?, t1?, horizon?);
    if t0 > t1 {
        cx.err(
            Diagnostic::new(
                Code::TimeWindow,
                w.span,
                format!("the window [{}, {}] is empty", compact(t0), compact(t1)),
            )
            .label("start after end")
            .hint("write `during [first, last]` in seconds"),
        );
        return None;
    }
    if !within_horizon(cx, t1, w.t1.span, dt, h) {
        return None;
    }
    let tol = |t: f64| TIME_TOLERANCE * t.max(dt);
    // every quotient is at most about h (t1 is within the horizon)
    let a = ((t0 - tol(t0)) / dt).ceil().max(0.0) as usize;
    let b = (((t1 + tol(t1)) / dt).floor().max(0.0) as usize).min(h);
    if a > b {
        cx.err(
            Diagnostic::new(
                Code::TimeWindow,
                w.span,
                format!(
                    "no sampling instant (every {} s) lies in [{}, {}]",
                    compact(dt),
                    compact(t0),
                    compact(t1)
                ),
            )
            .label("between two instants")
            .hint(format!(
                "widen the window to an instant, e.g. [{}, {}]",
                compact(b as f64 * dt),
                compact(a as f64 * dt)
            )),
        );
        return None;
    }
    let p0 = ((t0 + tol(t0)) / dt).floor().max(0.0) as usize + 1;
    let p1 = ((((t1 - tol(t1)) / dt).ceil().max(0.0)) as usize).min(h);
    Some(Window {
        steps: (a, b),
        periods: (p0, p1),
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
