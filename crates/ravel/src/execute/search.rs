//! An optimising falsifier for the properties left UNSURE: a pattern
//! search over the initial state and noise values (each held constant over
//! the trajectory) for the deepest violation, from the initial set's
//! corners and the first Monte Carlo samples. A violation it finds counts
//! only when [`certainly_violates`] confirms it with a validated enclosure
//! of the trajectory, as for Monte Carlo.
//!
//! It runs after the analysis and only on UNSURE properties, so a VERIFIED
//! property costs nothing more; its budget is fixed ([`STARTS`] starting
//! points, [`BUDGET`] simulations each), so its cost is bounded, and it is
//! deterministic.

use super::constraints;
use super::sampling::{certainly_violates, has_between, simulate};
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

/// How deeply a trajectory violates the property (positive: violated),
/// and at which step; `None` when no state in the window is finite (for
/// an "eventually" goal: when some state of the window is not, or the
/// plant is a continuous-time nonlinear one, see
/// [`super::sampling::violation_of`]).
fn violation(plan: &SystemPlan, prop: &Property, tr: &Trajectory) -> Option<(f64, usize)> {
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
            if has_between(plan) || window().count() != w.steps.1 + 1 - w.steps.0 {
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
/// the trajectory and the step.
pub(super) fn search(
    plan: &SystemPlan,
    prop: &Property,
    ctl: &Control,
) -> Option<(f64, Trajectory, usize)> {
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
    let mut best: Option<(f64, Trajectory, usize)> = None;
    for start in starts {
        if ctl.out_of_time() {
            break;
        }
        let Some(found) = climb(plan, prop, &space, start, ctl) else {
            continue;
        };
        let (depth, tr, t) = found;
        let rhs = 0.0f64;
        let x = tr.states.get(t).cloned().unwrap_or_default();
        if depth > tolerance(&x, rhs)
            && best.as_ref().is_none_or(|b| depth > b.0)
            && certainly_violates(plan, &tr, prop, t)
        {
            best = Some((depth, tr, t));
        }
    }
    best
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
        let (d, t) = violation(plan, prop, &tr)?;
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
