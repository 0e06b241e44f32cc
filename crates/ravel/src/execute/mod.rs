//! Execution: a [`SystemPlan`] → an [`SystemOutcome`]: reachable sets, Monte Carlo
//! trajectories, and a verdict per property.
//!
//! * Every partition cell of the initial set is carried through the horizon
//!   by the chosen propagator; the reachable set at step `t` is the union of
//!   the cells' boxes (its bounding box is reported too).
//! * A property is VERIFIED when the certified margins prove it on every cell,
//!   FALSIFIED when a simulated trajectory (seeded samples of the initial set
//!   and of the noise, including extreme noise values) violates it by more
//!   than a floating-point tolerance, and UNSURE otherwise. A bound that an
//!   LP solver could not certify (see [`ravel_analysis::lp`]) never yields VERIFIED.
//! * Monte Carlo runs first, so the property-guided partitioner knows which
//!   properties are already decided before it spends any propagator call.
//! * A property still UNSURE after the analysis gets an optimising search
//!   for a counterexample (`search`); like a Monte Carlo one, it counts only
//!   when a validated enclosure of its trajectory confirms it.

mod cells;
mod constraints;
pub mod network;
mod sampling;
mod search;

use cells::{partition_guided, partition_uniform, Gathered};

pub use cells::{propagate_cell, propagate_cell_until};
pub use sampling::{certainly_violates, certainly_violates_between, simulate, simulate_states};
use sampling::{confirm, monte_carlo, resolve_boundary, sampled_shapes, MonteCarlo};

use crate::lower::{NetworkPlan, Partitioner, Plan, Property, PropertyKind, SystemPlan};
use ravel_analysis::closed_loop::Cut;
use ravel_analysis::issue::Issue;
use ravel_analysis::partition::Stop;
use ravel_analysis::sets::{IBox, Region};

/// A verdict.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Verdict {
    /// Proven for every trajectory.
    Verified,
    /// Neither proven nor refuted.
    Unsure,
    /// Refuted by a concrete trajectory.
    Falsified,
}

impl Verdict {
    /// The upper-case name used in reports.
    pub fn as_str(self) -> &'static str {
        match self {
            Verdict::Verified => "VERIFIED",
            Verdict::Unsure => "UNSURE",
            Verdict::Falsified => "FALSIFIED",
        }
    }
}

/// Which kind of property a result is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// A goal: the final reachable set lies in a set.
    Goal,
    /// An avoid set: no reachable set touches it at its steps.
    Avoid,
}

impl Kind {
    /// The keyword used in specs and reports.
    pub fn as_str(self) -> &'static str {
        match self {
            Kind::Goal => "goal",
            Kind::Avoid => "avoid",
        }
    }
}

/// A concrete closed-loop trajectory.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    /// States `x_0 … x_N`.
    pub states: Vec<Vec<f64>>,
    /// Controls `u_0 … u_{N-1}` (after saturation).
    pub controls: Vec<Vec<f64>>,
    /// Process noise `w_0 … w_{N-1}`.
    pub process_noise: Vec<Vec<f64>>,
    /// Sensor noise `v_0 … v_{N-1}`.
    pub sensor_noise: Vec<Vec<f64>>,
}

/// The result for one property.
#[derive(Clone, Debug, PartialEq)]
pub struct PropertyResult {
    /// The property's name.
    pub name: String,
    /// Goal or avoid.
    pub kind: Kind,
    /// The verdict.
    pub status: Verdict,
    /// VERIFIED/UNSURE: the certified margin (containment margin for a goal,
    /// separation for an avoid set; negative when the proof failed). FALSIFIED:
    /// how far the counterexample violates the property (negative).
    pub margin: f64,
    /// The step the margin refers to.
    pub step: usize,
    /// FALSIFIED only: the counterexample violates the property between the
    /// sampling instants, in the control period ending at `step` (a
    /// plant in continuous time, linear or nonlinear), rather than at `step`.
    pub between: bool,
    /// The counterexample (FALSIFIED only).
    pub counterexample: Option<Trajectory>,
    /// UNSURE only: the first step (at or before the property's last step)
    /// whose set is not a computed bound, and why (overflow or time limit).
    pub cut: Option<(usize, Cut)>,
}

/// Everything execution found.
#[derive(Clone, Debug)]
pub struct SystemOutcome {
    /// The partition cells of the initial set (as boxes: the cell's bounding box).
    pub partition: Vec<IBox>,
    /// How the partitioner stopped.
    pub partition_stop: Stop,
    /// `cells[c][t]`: the set of cell `c` at step `t`.
    pub cells: Vec<Vec<Region>>,
    /// `between[c][t]`: cell `c`'s states over the control period ending at
    /// step `t` (continuous-time plants; `None` otherwise): the hull of the
    /// pieces the properties were checked on.
    pub between: Vec<Vec<Option<IBox>>>,
    /// LP solver statuses that forced a fallback bound, with the step (sorted, unique).
    pub solver_issues: Vec<(usize, Issue)>,
    /// The bounding box of all cells per step.
    pub reach: Vec<IBox>,
    /// The bounding box of the simulated states per step (if any samples).
    pub sampled: Vec<Option<IBox>>,
    /// Per-property results, in plan order.
    pub properties: Vec<PropertyResult>,
    /// The overall verdict: FALSIFIED if any property is, VERIFIED if all are, else UNSURE.
    pub verdict: Verdict,
    /// Number of closed-loop propagator calls.
    pub propagator_calls: usize,
    /// The first step at which some cell's set is not a computed bound
    /// (its bounds overflowed, or the time limit stopped the analysis): that
    /// set and every later one of the cell are the whole space.
    pub cut: Option<(usize, Cut)>,
    /// Monte Carlo samples actually drawn (fewer than planned only when the
    /// time limit stopped sampling).
    pub samples_drawn: usize,
}

/// Tolerance for calling a simulated violation genuine: simulations run in
/// f64 and differ from exact arithmetic by far less than this.
fn tolerance(x: &[f64], rhs_scale: f64) -> f64 {
    let m = x.iter().fold(rhs_scale.abs(), |a, v| a.max(v.abs()));
    1e-9 * (1.0 + m)
}

/// Whether a margin proves the property.
fn proves(prop: &Property, margin: f64) -> bool {
    match &prop.kind {
        PropertyKind::Goal { .. } => margin >= 0.0,
        PropertyKind::Avoid { .. } => margin > 0.0,
    }
}

/// What the caller lets execution know and do while it runs (the library
/// has no clock and no terminal of its own).
pub struct Control<'a> {
    /// Seconds since the run started.
    pub elapsed: &'a (dyn Fn() -> f64 + Sync),
    /// Stop after this many seconds, soundly: samples not drawn are not
    /// drawn, steps not propagated are the whole space ([`Cut::TimeLimit`]),
    /// and every property depending on them is UNSURE.
    pub time_limit: Option<f64>,
    /// Told now and then what is being done (for a progress line); may be
    /// called from several threads.
    pub progress: &'a (dyn Fn(Progress) + Sync),
    /// Threads for the cells of a uniform partition (1: none). The outcome
    /// is the same for every number: cells are independent and their sets
    /// are collected in cell order.
    pub threads: usize,
}

/// The clock of [`Control::new`]: always 0 s.
fn no_time() -> f64 {
    0.0
}

impl<'a> Control<'a> {
    /// No time limit, no progress reports, one thread; `elapsed` is
    /// consulted only by a partitioner with a time budget.
    pub fn new(elapsed: &'a (dyn Fn() -> f64 + Sync)) -> Control<'a> {
        Control {
            elapsed,
            time_limit: None,
            progress: &|_| {},
            threads: 1,
        }
    }

    /// [`Control::new`] with a clock that always says 0 s: nothing ever
    /// runs out of time.
    pub fn unlimited() -> Control<'static> {
        Control::new(&no_time)
    }

    /// Whether the time limit has passed.
    pub(crate) fn out_of_time(&self) -> bool {
        self.time_limit.is_some_and(|l| (self.elapsed)() >= l)
    }
}

/// What execution is doing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// Monte Carlo simulation.
    Sampling,
    /// Propagating partition cells.
    Cells,
    /// Robust action selection: observations whose ε-balls are bounded.
    Observations,
}

/// A progress report: `done` of `total` items of a phase.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Progress {
    /// The phase.
    pub phase: Phase,
    /// Items finished.
    pub done: usize,
    /// Items planned, when known (a guided partitioner's is its call budget at most).
    pub total: Option<usize>,
}

/// Execute a plan: its kind's executor under `ctl`, and the plan with what
/// it found.
pub fn execute(plan: Plan, ctl: &Control) -> Run {
    match plan {
        Plan::System(plan) => {
            let outcome = execute_system(&plan, ctl);
            Run::System {
                plan,
                outcome: Box::new(outcome),
            }
        }
        Plan::Network(plan) => {
            let outcome = network::execute_network(&plan, ctl);
            Run::Network {
                plan,
                outcome: Box::new(outcome),
            }
        }
    }
}

/// An executed plan: the plan and what its execution found, one variant per
/// kind of spec. This is what reports and certificates are made from.
#[derive(Clone, Debug)]
pub enum Run {
    /// A closed loop.
    System {
        /// The plan executed.
        plan: Box<SystemPlan>,
        /// What it found.
        outcome: Box<SystemOutcome>,
    },
    /// A network on its own.
    Network {
        /// The plan executed.
        plan: Box<NetworkPlan>,
        /// What it found.
        outcome: Box<network::NetworkOutcome>,
    },
}

impl Run {
    /// The verdict over every property.
    pub fn verdict(&self) -> Verdict {
        match self {
            Run::System { outcome, .. } => outcome.verdict,
            Run::Network { outcome, .. } => outcome.verdict,
        }
    }

    /// The path the controller (or the network's model) was read from.
    pub fn controller_resolved(&self) -> &str {
        match self {
            Run::System { plan, .. } => &plan.controller_resolved,
            Run::Network { plan, .. } => &plan.model_resolved,
        }
    }
}

/// The verdict of every property: FALSIFIED by a sampled counterexample,
/// VERIFIED by certified margins on every cell (no solver issue, no cut
/// step), UNSURE otherwise.
fn verdicts(plan: &SystemPlan, gathered: &Gathered, mc: &MonteCarlo) -> Vec<PropertyResult> {
    plan.properties
        .iter()
        .zip(&mc.worst)
        .zip(&gathered.least)
        .map(|((prop, worst), l)| {
            let kind = match prop.kind {
                PropertyKind::Goal { .. } => Kind::Goal,
                PropertyKind::Avoid { .. } => Kind::Avoid,
            };
            let (margin, step) = l.margin(prop.window().steps.0);
            let (issue, cut) = (l.issue, l.cut.map(|(t, _, c)| (t, c)));
            // no cell proves nothing
            let proven = gathered.cells > 0 && proves(prop, margin) && !issue && cut.is_none();
            // `confirm` kept only violations the rigorous replay confirms
            let confirmed = worst.and_then(|(depth, k, t)| Some((depth, simulate(plan, k)?, t)));
            match confirmed {
                // A genuine counterexample always wins; a proof next to one would be a soundness bug.
                Some((depth, tr, t)) => {
                    debug_assert!(!proven, "property {} proven and falsified", prop.name);
                    PropertyResult {
                        name: prop.name.clone(),
                        kind,
                        status: Verdict::Falsified,
                        margin: -depth,
                        step: t,
                        between: false,
                        counterexample: Some(tr),
                        cut: None,
                    }
                }
                None => PropertyResult {
                    name: prop.name.clone(),
                    kind,
                    status: if proven {
                        Verdict::Verified
                    } else {
                        Verdict::Unsure
                    },
                    margin,
                    step,
                    between: false,
                    counterexample: None,
                    cut,
                },
            }
        })
        .collect()
}

/// Search for a counterexample to every UNSURE property ([`search`]); a
/// confirmed one makes it FALSIFIED. Not with `samples 0` (no simulation
/// asked for).
fn falsify_unsure(plan: &SystemPlan, properties: &mut [PropertyResult], ctl: &Control) {
    if plan.samples == 0 {
        return;
    }
    for (prop, r) in plan.properties.iter().zip(properties.iter_mut()) {
        if r.status != Verdict::Unsure {
            continue;
        }
        if let Some((depth, tr, t, between)) = search::search(plan, prop, ctl) {
            *r = PropertyResult {
                name: r.name.clone(),
                kind: r.kind,
                status: Verdict::Falsified,
                margin: -depth,
                step: t,
                between,
                counterexample: Some(tr),
                cut: None,
            };
        }
    }
}

/// The hull of a period's pieces (`None` for none).
fn hull_of(pieces: &[IBox]) -> Option<IBox> {
    let (first, rest) = pieces.split_first()?;
    Some(rest.iter().fold(first.clone(), |h, b| h.hull(b)))
}

/// Execute a plan under a [`Control`]: Monte Carlo, then the partition and
/// propagation, then the verdicts.
pub fn execute_system(plan: &SystemPlan, ctl: &Control) -> SystemOutcome {
    let mut mc = monte_carlo(plan, ctl);
    confirm(plan, &mut mc);
    let plan = &*resolve_boundary(plan, &mc);
    let part = match &plan.partitioner {
        Partitioner::Uniform(grid) => partition_uniform(plan, grid, ctl),
        Partitioner::Guided { guide, budget } => {
            let shaped = sampled_shapes(plan, &mc);
            let undecided: Vec<bool> = mc.worst.iter().map(Option::is_none).collect();
            partition_guided(plan, *guide, *budget, &shaped, &undecided, ctl)
        }
    };
    let (cells, between): (Vec<Vec<Region>>, Vec<Vec<Option<IBox>>>) = part
        .sets
        .into_iter()
        .map(|c| {
            c.into_iter()
                .map(|s| (s.set, s.between.as_deref().and_then(hull_of)))
                .unzip()
        })
        .unzip();
    let mut properties = verdicts(plan, &part.gathered, &mc);
    falsify_unsure(plan, &mut properties, ctl);
    let Gathered {
        reach,
        issues: solver_issues,
        cut,
        ..
    } = part.gathered;
    let cut = cut.map(|(t, _, c)| (t, c));
    let verdict = properties
        .iter()
        .map(|p| p.status)
        .max()
        .unwrap_or(Verdict::Verified);
    SystemOutcome {
        partition: part.cells,
        partition_stop: part.stop,
        cells,
        between,
        solver_issues,
        reach,
        sampled: mc.sampled,
        properties,
        verdict,
        propagator_calls: part.calls * plan.horizon,
        cut,
        samples_drawn: mc.drawn,
    }
}

#[cfg(test)]
mod tests {
    use super::cells::*;
    use super::*;
    use ravel_base::rng::Rng;

    /// One cell as the scan sees it: margin, step, issue, first cut.
    type Cell = (f64, usize, bool, Option<(usize, Cut)>);

    /// The scan over the cells in order that [`Least`] stands for: what the
    /// verdicts computed before threads gathered their own cells.
    fn scan(cells: &[Cell], step: usize) -> Cell {
        let (mut margin, mut at, mut issue, mut cut) = (f64::INFINITY, step, false, None);
        for &(m, t, i, c) in cells {
            issue |= i;
            if m < margin || m.is_nan() {
                margin = sane(m);
                at = t;
            }
            if let Some(o) = c {
                if cut.is_none_or(|p: (usize, Cut)| o.0 < p.0) {
                    cut = Some(o);
                }
            }
        }
        (margin, at, issue, cut)
    }

    #[test]
    fn least_margins_gathered_in_any_order_are_the_in_order_scan() {
        let mut rng = Rng::new(11);
        let values = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.5,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        let cuts = [Cut::Overflow, Cut::TimeLimit];
        for _ in 0..3000 {
            let n = 1 + rng.below(7);
            let cells: Vec<_> = (0..n)
                .map(|_| {
                    let c = (rng.below(4) == 0).then(|| (rng.below(3), cuts[rng.below(2)]));
                    (
                        values[rng.below(values.len())],
                        rng.below(4),
                        rng.below(5) == 0,
                        c,
                    )
                })
                .collect();
            let want = scan(&cells, 9);
            // cells added in a shuffled order, split among up to three parts
            let mut order: Vec<usize> = (0..n).collect();
            for i in (1..n).rev() {
                order.swap(i, rng.below(i + 1));
            }
            let mut parts = vec![Least::default(); 1 + rng.below(3)];
            for &c in &order {
                let (m, t, issue, cut) = cells[c];
                let k = rng.below(parts.len());
                parts[k] = parts[k].merge(Least {
                    min: (m < f64::INFINITY).then_some((m, c, t)),
                    nan: m.is_nan().then_some((c, t)),
                    issue,
                    cut: cut.map(|(t, x)| (t, c, x)),
                });
            }
            let got = parts.into_iter().fold(Least::default(), Least::merge);
            let (m, t) = got.margin(9);
            assert_eq!(
                (m.to_bits(), t, got.issue, got.cut.map(|(t, _, c)| (t, c))),
                (want.0.to_bits(), want.1, want.2, want.3),
                "{cells:?} in order {order:?}"
            );
        }
    }
}
