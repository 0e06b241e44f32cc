//! An optimising falsifier for the properties left UNSURE: a pattern
//! search over the initial state and noise values (each held constant over
//! the trajectory) for the deepest violation, from the initial set's
//! corners and the first Monte Carlo samples, then a greedy search over
//! the noise of single steps from the best trajectory it found
//! ([`vary_noise`]). A violation it finds counts
//! only when [`certainly_violates`] confirms it with a validated enclosure
//! of the trajectory, as for Monte Carlo.
//!
//! For a plant in continuous time the trajectories at each start and
//! at the end of its search are also looked at between the instants
//! ([`between_violations`]; the search itself climbs on the instants, so
//! this costs two trajectories per start): a violation there counts when
//! [`certainly_violates_between`] confirms it on a piece of the period's
//! validated enclosure.
//!
//! It runs after the analysis and only on UNSURE properties, so a VERIFIED
//! property costs nothing more; its budget is fixed ([`STARTS`] starting
//! points, [`BUDGET`] simulations each for the pattern search and
//! [`SEQUENCE_BUDGET`] for the noise of single steps), so its cost is
//! bounded, and it is deterministic.

use super::constraints;
use super::sampling::{
    certainly_violates, certainly_violates_between, has_between, period_flow, simulate,
};
use super::{tolerance, Control, Property, PropertyKind, SystemPlan, Trajectory};
use crate::lower::GoalMode;
use ravel_analysis::sets::IBox;

/// Starting points per property.
const STARTS: usize = 8;

/// Simulations per starting point.
const BUDGET: usize = 120;

/// The search's coordinates: the initial state, then the process noise and
/// the sensor noise (held over the whole trajectory).
struct Space {
    /// The box of all coordinates.
    bounds: IBox,
    /// State, process-noise and sensor-noise dimensions.
    dims: (usize, usize, usize),
}

impl Space {
    fn of(plan: &SystemPlan) -> Space {
        let cl = &plan.closed_loop;
        let x = plan.initial.bbox();
        let (w, v) = (cl.w(), cl.v());
        let lo = [x.lo.as_slice(), &w.lo, &v.lo].concat();
        let hi = [x.hi.as_slice(), &w.hi, &v.hi].concat();
        Space {
            bounds: IBox::new(lo, hi),
            dims: (x.dim(), w.dim(), v.dim()),
        }
    }

    /// The trajectory from a point of the space.
    fn trajectory(&self, plan: &SystemPlan, p: &[f64]) -> Option<Trajectory> {
        let (n, q, _) = self.dims;
        let (x0, rest) = p.split_at(n);
        let (w, v) = rest.split_at(q);
        if !plan.initial.contains_point(x0) {
            return None;
        }
        let cl = &plan.closed_loop;
        let mut tr = Trajectory {
            states: vec![x0.to_vec()],
            controls: Vec::new(),
            process_noise: Vec::new(),
            sensor_noise: Vec::new(),
        };
        for t in 0..plan.horizon {
            let x = tr.states.last()?;
            let (u, next) = cl.simulate(t, x, w, v);
            tr.controls.push(u);
            tr.process_noise.push(w.to_vec());
            tr.sensor_noise.push(v.to_vec());
            tr.states.push(next);
        }
        Some(tr)
    }
}

/// Instants simulated inside each control period by [`between_violations`].
const INSIDE: usize = 32;

/// A plant in continuous time: per period wholly inside the window (in
/// time order), the deepest violation of an "always" goal or an avoid set
/// strictly between its two instants, from the trajectory's state, control
/// and disturbance at the period's start simulated to `INSIDE − 1` instants
/// inside it ([`PeriodFlow`](super::sampling::PeriodFlow): a linear
/// plant's noise arrives at the next instant), with the period (ending at
/// that step); empty for other plants and properties, and from the first
/// state that is not finite on.
fn between_violations(plan: &SystemPlan, prop: &Property, tr: &Trajectory) -> Vec<(f64, usize)> {
    let mut out = Vec::new();
    if !has_between(plan) {
        return out;
    }
    let depth = |x: &[f64]| -> f64 {
        match &prop.kind {
            PropertyKind::Goal {
                set,
                mode: GoalMode::Always,
                ..
            } => -constraints::depth(set, x),
            PropertyKind::Goal { .. } => f64::NAN,
            PropertyKind::Avoid { members, .. } => members
                .iter()
                .map(|m| constraints::depth(m, x))
                .fold(f64::NEG_INFINITY, f64::max),
        }
    };
    // the periods wholly inside the window (both instants in it)
    let w = prop.window();
    let (first, last) = (w.periods.0.max(w.steps.0 + 1), w.periods.1.min(w.steps.1));
    for p in first..=last.min(tr.states.len().saturating_sub(1)) {
        let (Some(x), Some(u), Some(wn), Some(flow)) = (
            tr.states.get(p - 1),
            tr.controls.get(p - 1),
            tr.process_noise.get(p - 1),
            period_flow(plan, p - 1),
        ) else {
            break;
        };
        let h = flow.period() / INSIDE as f64;
        let mut y = x.clone();
        let mut best: Option<f64> = None;
        for _ in 1..INSIDE {
            y = flow.simulate(&y, u, wn, h);
            if !y.iter().all(|v| v.is_finite()) {
                out.extend(best.map(|d| (d, p)));
                return out;
            }
            let d = depth(&y);
            if !d.is_nan() && best.is_none_or(|b| d > b) {
                best = Some(d);
            }
        }
        out.extend(best.map(|d| (d, p)));
    }
    out
}

/// How deeply a trajectory violates the property at its instants
/// (positive: violated), and at which step; `None` when no state in the
/// window is finite (for an "eventually" goal: when some state of the
/// window is not; see [`super::sampling::violation_of`]).
fn violation(prop: &Property, tr: &Trajectory) -> Option<(f64, usize)> {
    let finite = |x: &Vec<f64>| x.iter().all(|v| v.is_finite());
    let w = prop.window();
    let window = || {
        tr.states
            .iter()
            .enumerate()
            .take(w.steps.1 + 1)
            .skip(w.steps.0)
            .take_while(|(_, x)| finite(x))
    };
    let deepest = |it: &mut dyn Iterator<Item = (f64, usize)>| {
        it.filter(|(d, _)| !d.is_nan())
            .max_by(|a, b| a.0.total_cmp(&b.0))
    };
    match &prop.kind {
        PropertyKind::Goal {
            set,
            mode: GoalMode::Always,
            ..
        } => deepest(&mut window().map(|(t, x)| (-constraints::depth(set, x), t))),
        PropertyKind::Goal {
            set,
            mode: GoalMode::Eventually,
            ..
        } => {
            // a continuous-time plant's candidate is confirmed (or not) on
            // the periods too, by `certainly_violates`
            if tr.states.len() <= w.last() || window().count() != w.steps.1 + 1 - w.steps.0 {
                return None;
            }
            let mut least: Option<(f64, usize)> = None;
            for (t, x) in window() {
                let d = -constraints::depth(set, x);
                if d.is_nan() {
                    return None;
                }
                if least.is_none_or(|b| d < b.0) {
                    least = Some((d, t));
                }
            }
            least
        }
        PropertyKind::Avoid { members, .. } => deepest(
            &mut window()
                .flat_map(|(t, x)| members.iter().map(move |m| (constraints::depth(m, x), t))),
        ),
    }
}

/// The deepest confirmed violation of `prop` the search finds: its depth,
/// the trajectory, the step, and whether the violation lies between the
/// instants (in the period ending at the step).
pub(super) fn search(
    plan: &SystemPlan,
    prop: &Property,
    ctl: &Control,
) -> Option<(f64, Trajectory, usize, bool)> {
    let space = Space::of(plan);
    let (n, _, _) = space.dims;
    let centre: Vec<f64> = space
        .bounds
        .lo
        .iter()
        .zip(&space.bounds.hi)
        .map(|(l, h)| 0.5 * l + 0.5 * h)
        .collect();
    // starts: the first Monte Carlo samples' initial states (corners first),
    // the noise at the centre of its box
    let starts: Vec<Vec<f64>> = (0..STARTS)
        .filter_map(|k| simulate(plan, k))
        .filter_map(|tr| tr.states.first().cloned())
        .map(|x0| [x0.as_slice(), &centre[n..]].concat())
        .collect();
    let mut best: Option<(f64, Trajectory, usize, bool)> = None;
    for start in starts {
        if ctl.out_of_time() {
            break;
        }
        let at_start = if has_between(plan) {
            space.trajectory(plan, &start)
        } else {
            None
        };
        // the climbed trajectory and its noise varied step by step: both are
        // candidates (the varied one is deeper at the instants, which can
        // cost a violation between them or confirmation)
        let climbed = climb(plan, prop, &space, start, ctl);
        let varied = climbed
            .clone()
            .map(|c| vary_noise(plan, prop, c, ctl))
            .filter(|v| climbed.as_ref().is_some_and(|c| v.0 > c.0));
        for (depth, tr, t) in climbed.iter().chain(&varied) {
            let x = tr.states.get(*t).cloned().unwrap_or_default();
            if *depth > tolerance(&x, 0.0)
                && best.as_ref().is_none_or(|b| *depth > b.0)
                && certainly_violates(plan, tr, prop, *t)
            {
                best = Some((*depth, tr.clone(), *t, false));
            }
        }
        let ends = climbed.iter().chain(&varied).map(|c| &c.1);
        for tr in at_start.iter().chain(ends) {
            if let Some(found) = confirmed_between(plan, prop, tr) {
                if best.as_ref().is_none_or(|b| found.0 > b.0) {
                    best = Some((found.0, tr.clone(), found.1, true));
                }
            }
        }
    }
    best
}

/// Evaluations per start of [`vary_noise`].
const SEQUENCE_BUDGET: usize = 240;

/// Re-simulate `tr` from step `from` on with its own noise sequences
/// (edited by the caller): the states and controls before are kept;
/// `None` when `from` lies past its end.
fn resimulate(plan: &SystemPlan, tr: &mut Trajectory, from: usize) -> Option<()> {
    let cl = &plan.closed_loop;
    tr.states.truncate(from + 1);
    tr.controls.truncate(from);
    for t in from..plan.horizon {
        let (x, w, v) = (
            tr.states.last()?,
            tr.process_noise.get(t)?,
            tr.sensor_noise.get(t)?,
        );
        let (u, next) = cl.simulate(t, x, w, v);
        tr.controls.push(u);
        tr.states.push(next);
    }
    Some(())
}

/// A greedy search over the noise of single steps, from the climbed
/// trajectory (its noise held constant): each process- and sensor-noise
/// coordinate of each step, moved to either end of its interval, the move
/// kept when the violation deepens; the steps before the violation's are
/// tried first, latest first (they move it most directly), then the later
/// ones; passes until none helps or [`SEQUENCE_BUDGET`] evaluations are
/// spent. Noise that changes from step to step (a push in phase with an
/// oscillation) reaches violations no constant noise reaches. Every
/// candidate is still confirmed by [`certainly_violates`].
fn vary_noise(
    plan: &SystemPlan,
    prop: &Property,
    climbed: (f64, Trajectory, usize),
    ctl: &Control,
) -> (f64, Trajectory, usize) {
    let cl = &plan.closed_loop;
    let (w, v) = (cl.w(), cl.v());
    if w.dim() + v.dim() == 0 {
        return climbed;
    }
    let mut best = climbed;
    let last = prop.window().last().min(plan.horizon);
    let mut spent = 0;
    loop {
        let mut improved = false;
        let t = best.2.min(last);
        let order: Vec<usize> = (0..t).rev().chain(t..last).collect();
        for s in order {
            for j in 0..w.dim() + v.dim() {
                let (lo, hi) = if j < w.dim() {
                    (w.lo[j], w.hi[j])
                } else {
                    (v.lo[j - w.dim()], v.hi[j - w.dim()])
                };
                for end in [lo, hi] {
                    if spent >= SEQUENCE_BUDGET || ctl.out_of_time() {
                        return best;
                    }
                    let mut tr = best.1.clone();
                    let slot = if j < w.dim() {
                        tr.process_noise.get_mut(s).and_then(|n| n.get_mut(j))
                    } else {
                        tr.sensor_noise
                            .get_mut(s)
                            .and_then(|n| n.get_mut(j - w.dim()))
                    };
                    match slot {
                        Some(x) if *x != end => *x = end,
                        _ => continue,
                    }
                    spent += 1;
                    if resimulate(plan, &mut tr, s).is_none() {
                        continue;
                    }
                    if let Some((d, at)) = violation(prop, &tr) {
                        if d > best.0 {
                            best = (d, tr, at);
                            improved = true;
                            break;
                        }
                    }
                }
            }
        }
        if !improved {
            return best;
        }
    }
}

/// The deepest violation of a trajectory between two instants that
/// [`certainly_violates_between`] confirms: its depth and period. The
/// periods are tried deepest first, then in time order (the trajectory's
/// enclosure is tightest early), until one is confirmed.
fn confirmed_between(plan: &SystemPlan, prop: &Property, tr: &Trajectory) -> Option<(f64, usize)> {
    let mut periods: Vec<(f64, usize)> = between_violations(plan, prop, tr)
        .into_iter()
        .filter(|&(d, p)| d > tolerance(tr.states.get(p).map_or(&[], |x| x), 0.0))
        .collect();
    let deepest = periods
        .iter()
        .enumerate()
        .max_by(|a, b| a.1 .0.total_cmp(&b.1 .0))
        .map(|(i, _)| i)?;
    let first = periods.remove(deepest);
    std::iter::once(first)
        .chain(periods)
        .find(|&(_, p)| certainly_violates_between(plan, tr, prop, p))
}

/// A pattern search from `start`: each coordinate moved by its step both
/// ways, the best move kept; the steps halve when no move helps.
fn climb(
    plan: &SystemPlan,
    prop: &Property,
    space: &Space,
    start: Vec<f64>,
    ctl: &Control,
) -> Option<(f64, Trajectory, usize)> {
    let eval = |p: &[f64]| {
        let tr = space.trajectory(plan, p)?;
        let (d, t) = violation(prop, &tr)?;
        Some((d, tr, t))
    };
    let mut here = start;
    let mut best = eval(&here)?;
    let mut step: Vec<f64> = space
        .bounds
        .lo
        .iter()
        .zip(&space.bounds.hi)
        .map(|(l, h)| 0.25 * (h - l))
        .collect();
    let mut spent = 1;
    while spent < BUDGET && step.iter().any(|s| *s > 1e-9) && !ctl.out_of_time() {
        let mut moved = false;
        for i in 0..here.len() {
            if step[i] <= 0.0 {
                continue;
            }
            for sign in [1.0, -1.0] {
                let mut p = here.clone();
                p[i] = (p[i] + sign * step[i]).clamp(space.bounds.lo[i], space.bounds.hi[i]);
                spent += 1;
                if let Some(c) = eval(&p) {
                    if c.0 > best.0 {
                        best = c;
                        here = p;
                        moved = true;
                        break;
                    }
                }
            }
        }
        if !moved {
            step.iter_mut().for_each(|s| *s *= 0.5);
        }
    }
    Some(best)
}
