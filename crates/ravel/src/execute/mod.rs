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

use nalgebra::DMatrix;

pub mod network;

use crate::lower::{Guide, NetworkPlan, Partitioner, Plan, Property, PropertyKind, SystemPlan};
use ravel_analysis::closed_loop::{Boundary, Cut, Propagator, Step};
use ravel_analysis::issue::Issue;
use ravel_analysis::lp;
use ravel_analysis::partition::{refine_parallel, Budget, Stop, Strategy};
use ravel_analysis::sets::{IBox, Polytope, Region};
use ravel_analysis::shape::{
    convex_hull, excess, extent_of_points, hull_directions, support_of_points, HULL_MIN_ANGLE,
};
use ravel_base::rng::Rng;

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

/// Reachable sets of one cell over the horizon. With `parent` (the sets of a
/// cell containing this one), every set is intersected with the parent's, so
/// a partition is never looser than the cell it refines.
pub fn propagate_cell(plan: &SystemPlan, cell: &Region, parent: Option<&[Step]>) -> Vec<Step> {
    propagate_cell_until(plan, cell, parent, &|| false)
}

/// [`propagate_cell`], asking `stop` before each step whether the time is
/// up; the steps left are then [`Step::timed_out`] (the whole space).
pub fn propagate_cell_until(
    plan: &SystemPlan,
    cell: &Region,
    parent: Option<&[Step]>,
    stop: &dyn Fn() -> bool,
) -> Vec<Step> {
    let cl = &plan.closed_loop;
    let n = cl.states();
    if plan.propagator == Propagator::CrownUnrolled {
        let parent: Option<Vec<Region>> = parent.map(|p| p.iter().map(|s| s.set.clone()).collect());
        return cl.unrolled(cell, plan.horizon, &plan.boundary, parent.as_deref(), stop);
    }
    let mut steps = Vec::with_capacity(plan.horizon + 1);
    steps.push(Step::new(cell.clone(), Vec::new()));
    for t in 0..plan.horizon {
        match steps[t].cut() {
            // nothing bounded is left to propagate: every later set is ℝⁿ too
            Some(Cut::Overflow) => {
                steps.push(Step::overflowed(n, Vec::new()));
                continue;
            }
            Some(Cut::TimeLimit) => {
                steps.push(Step::timed_out(n));
                continue;
            }
            None if stop() => {
                steps.push(Step::timed_out(n));
                continue;
            }
            None => {}
        }
        let mut next = cl.step(t, &steps[t].set, plan.propagator, &plan.boundary);
        if let Some(p) = parent.and_then(|p| p.get(t + 1)) {
            if next.cut().is_none() {
                next.set = next.set.intersect(&p.set);
            }
        }
        steps.push(next);
    }
    steps
}

/// The first step whose set is not a computed bound, and why.
fn first_cut(sets: &[Step]) -> Option<(usize, Cut)> {
    sets.iter()
        .enumerate()
        .find_map(|(t, s)| s.cut().map(|c| (t, c)))
}

/// A margin that is NaN (an overflow inside a margin computation) proves
/// nothing: it becomes `−∞`.
fn sane(m: f64) -> f64 {
    if m.is_nan() {
        f64::NEG_INFINITY
    } else {
        m
    }
}

/// Whether a cell is certainly empty (a polytope cell of a polytope initial set).
fn certainly_empty(cell: &Region) -> bool {
    match cell {
        Region::Polytope { bbox, rows } => {
            lp::separation(&[], rows, &bbox.lo, &bbox.hi).value > 0.0
        }
        Region::Box(_) | Region::Ball { .. } => false,
    }
}

/// A certified margin of one property on one cell's sets, with the step it
/// refers to and whether an LP solver issue weakened it. A set that
/// overflowed gives the margin `−∞` at its step (never a proof); so does a
/// margin computation that produced NaN.
fn cell_margin(prop: &Property, sets: &[Step]) -> Margin {
    match &prop.kind {
        PropertyKind::Goal(g) => {
            let t = sets.len() - 1;
            if sets[t].cut().is_some() {
                return (f64::NEG_INFINITY, t, false);
            }
            let (m, issue) = containment_margin(g, &sets[t].set);
            (sane(m), t, issue || !sets[t].issues.is_empty())
        }
        PropertyKind::Avoid { members, steps } => {
            let mut best = (f64::INFINITY, steps.0, false);
            for (t, step) in sets.iter().enumerate().take(steps.1 + 1).skip(steps.0) {
                if step.cut().is_some() {
                    if best.0 > f64::NEG_INFINITY {
                        best = (f64::NEG_INFINITY, t, best.2);
                    }
                    break;
                }
                for m in members {
                    let (s, issue) = separation_margin(m, &step.set);
                    let s = sane(s);
                    let issue = issue || !step.issues.is_empty();
                    if s < best.0 || (issue && !best.2 && s <= best.0) {
                        best = (s, t, issue || best.2);
                    } else if issue {
                        best.2 = true;
                    }
                }
            }
            best
        }
    }
}

/// `min_r (hᵣ − max_{x∈S} Hᵣ x)`: non-negative means `S ⊆ P`.
fn containment_margin(p: &Polytope, set: &Region) -> (f64, bool) {
    if let Region::Box(b) = set {
        return (p.containment_margin(b), false);
    }
    let mut issue = false;
    let m = p
        .rows
        .iter()
        .map(|(a, h)| {
            let s = set.support(a);
            issue |= s.issue.is_some();
            ravel_base::num::sum_lower([*h, -s.value])
        })
        .fold(f64::INFINITY, f64::min);
    (m, issue)
}

/// A lower bound of `min_{x∈S} max_r (Hᵣ x − hᵣ)`: positive means `S ∩ P = ∅`.
/// A single separating row is tried first; an LP decides the rest exactly.
fn separation_margin(p: &Polytope, set: &Region) -> (f64, bool) {
    let bbox = set.bbox();
    let single = p.separation_margin(&bbox);
    if single > 0.0 && !matches!(set, Region::Polytope { .. }) {
        return (single, false);
    }
    let rows: &[(Vec<f64>, f64)] = match set {
        Region::Polytope { rows, .. } => rows,
        Region::Box(_) | Region::Ball { .. } => &[],
    };
    let lp = lp::separation(rows, &p.rows, &bbox.lo, &bbox.hi);
    (lp.value.max(single), lp.issue.is_some())
}

/// Per-sample random stream: sample `k` of seed `s` is reproducible on its own.
fn sample_rng(seed: u64, k: usize) -> Rng {
    let mut r = Rng::new(seed);
    let base = r.next_u64();
    Rng::new(base ^ (k as u64).wrapping_mul(0xD134_2543_DE82_EF95))
}

fn pick_noise(rng: &mut Rng, b: &IBox) -> Vec<f64> {
    let mut out = vec![0.0; b.dim()];
    pick_noise_into(rng, b, &mut out, 1);
    out
}

/// [`pick_noise`] into every `stride`-th entry of `out` (the same draws in the same order).
fn pick_noise_into(rng: &mut Rng, b: &IBox, out: &mut [f64], stride: usize) {
    for i in 0..b.dim() {
        out[i * stride] = match rng.below(4) {
            0 => b.lo[i],
            1 => b.hi[i],
            _ => rng.uniform(b.lo[i], b.hi[i]),
        };
    }
}

/// The states of samples `ks`, simulated side by side: entry `s` holds
/// sample `ks.start + s`'s states `x_0 … x_N` one after another (`None`
/// when no initial state could be drawn). Bit for bit the states of
/// [`simulate`] (the same random draws, the same sums in the same order;
/// `tests/soundness.rs` compares them), at a fraction of the cost: the
/// samples' arithmetic vectorises and nothing is allocated per step.
pub fn simulate_states(
    plan: &SystemPlan,
    ks: std::ops::Range<usize>,
    special: &[Vec<f64>],
) -> Vec<Option<Vec<f64>>> {
    let cl = &plan.closed_loop;
    let n = cl.states();
    let h = plan.horizon;
    let mut rngs = Vec::with_capacity(ks.len());
    let mut out: Vec<Option<Vec<f64>>> = Vec::with_capacity(ks.len());
    for k in ks {
        let mut rng = sample_rng(plan.seed, k);
        let start = match special.get(k) {
            Some(p) => Some(p.clone()),
            None => plan.initial.sample(&mut || rng.uniform(0.0, 1.0)),
        };
        out.push(start.map(|x0| {
            let mut states = Vec::with_capacity((h + 1) * n);
            states.extend_from_slice(&x0);
            states
        }));
        rngs.push(rng);
    }
    // the samples that have an initial state, side by side
    let live: Vec<usize> = (0..out.len()).filter(|&s| out[s].is_some()).collect();
    let count = live.len();
    if count == 0 {
        return out;
    }
    let p = cl.plant.v.dim();
    let mut x = vec![0.0; n * count];
    for (c, &s) in live.iter().enumerate() {
        if let Some(states) = &out[s] {
            for j in 0..n {
                x[j * count + c] = states[j];
            }
        }
    }
    let (mut w, mut v) = (vec![0.0; n * count], vec![0.0; p * count]);
    for t in 0..h {
        for (c, &s) in live.iter().enumerate() {
            pick_noise_into(&mut rngs[s], &cl.plant.w, &mut w[c..], count);
            pick_noise_into(&mut rngs[s], &cl.plant.v, &mut v[c..], count);
        }
        let (_, next) = cl.simulate_batch(t, &x, &w, &v, count);
        x = next;
        for (c, &s) in live.iter().enumerate() {
            if let Some(states) = &mut out[s] {
                states.extend((0..n).map(|j| x[j * count + c]));
            }
        }
    }
    out
}

/// Simulate sample `k`: the first samples are the initial set's special
/// points (box corners, up to 2^12 of them; ball extremes), the rest random;
/// noise is extreme half of the time. `None` when no initial state could be
/// drawn (rejection sampling of a thin polytope).
pub fn simulate(plan: &SystemPlan, k: usize) -> Option<Trajectory> {
    simulate_from(plan, k, &plan.initial.special_points())
}

/// [`simulate`] with the initial set's special points computed once by the caller.
fn simulate_from(plan: &SystemPlan, k: usize, special: &[Vec<f64>]) -> Option<Trajectory> {
    let cl = &plan.closed_loop;
    let mut rng = sample_rng(plan.seed, k);
    let start = match special.get(k) {
        Some(p) => p.clone(),
        None => plan.initial.sample(&mut || rng.uniform(0.0, 1.0))?,
    };
    let h = plan.horizon;
    let mut states = Vec::with_capacity(h + 1);
    states.push(start);
    let mut tr = Trajectory {
        states,
        controls: Vec::with_capacity(h),
        process_noise: Vec::with_capacity(h),
        sensor_noise: Vec::with_capacity(h),
    };
    for t in 0..plan.horizon {
        let w = pick_noise(&mut rng, &cl.plant.w);
        let v = pick_noise(&mut rng, &cl.plant.v);
        let (u, next) = cl.simulate(t, &tr.states[t], &w, &v);
        tr.controls.push(u);
        tr.process_noise.push(w);
        tr.sensor_noise.push(v);
        tr.states.push(next);
    }
    Some(tr)
}

/// What the Monte Carlo pass found.
struct MonteCarlo {
    sampled: Vec<Option<IBox>>,
    /// (depth of violation, sample index, step) per property
    worst: Vec<Option<(f64, usize, usize)>>,
    /// the simulated 2-D states per step (only their convex hull once there
    /// are many), kept for a hull boundary
    points: Vec<Vec<[f64; 2]>>,
    /// for a polytope boundary: per step, the largest and smallest value of
    /// each facet direction (box rows first) over the simulated states
    facet_range: Vec<(Vec<f64>, Vec<f64>)>,
    /// samples drawn (fewer than planned when the time limit stopped sampling)
    drawn: usize,
}

/// The Monte Carlo pass. Samples are independent (each has its own random
/// stream), so with several threads each takes a contiguous range of sample
/// indices and the partial results are merged in index order: the outcome is
/// the one thread's, bit for bit (boxes and facet ranges are maxima and
/// minima; the deepest violation keeps the earliest sample on ties). A 2-D
/// hull boundary keeps its samples' points in one pass, sequentially (its
/// point set is pruned as it grows, which depends on the order).
fn monte_carlo(plan: &SystemPlan, ctl: &Control) -> MonteCarlo {
    let keep = plan.boundary == Boundary::Hull && plan.closed_loop.states() == 2;
    let special = plan.initial.special_points();
    let counter = std::sync::atomic::AtomicUsize::new(0);
    // below a few hundred samples a thread costs more than it saves
    let threads = if keep {
        1
    } else {
        ravel_analysis::pool::available(ctl.threads).clamp(1, (plan.samples / 256).max(1))
    };
    if threads == 1 {
        return sample_range(plan, ctl, 0..plan.samples, &special, &counter);
    }
    let chunk = plan.samples.div_ceil(threads);
    let range = |i: usize| (i * chunk).min(plan.samples)..((i + 1) * chunk).min(plan.samples);
    // the calling thread samples the first range
    let parts = ravel_analysis::pool::on_threads(threads, &|i| {
        sample_range(plan, ctl, range(i), &special, &counter)
    });
    let mut parts = parts.into_iter();
    let mut all = parts.next().expect("at least one part");
    for part in parts {
        all.absorb(part);
    }
    all
}

impl MonteCarlo {
    /// Merge the results of later samples into these (see [`monte_carlo`]).
    fn absorb(&mut self, later: MonteCarlo) {
        // a hull boundary's points are order-dependent: sampled on one thread only
        debug_assert!(later.points.iter().all(Vec::is_empty));
        for (mine, theirs) in self.sampled.iter_mut().zip(later.sampled) {
            *mine = match (mine.take(), theirs) {
                (Some(a), Some(b)) => Some(a.hull(&b)),
                (a, b) => a.or(b),
            };
        }
        for (mine, theirs) in self.worst.iter_mut().zip(later.worst) {
            if let Some(t) = theirs {
                if mine.is_none_or(|m| t.0 > m.0) {
                    *mine = Some(t);
                }
            }
        }
        for ((hi, lo), (thi, tlo)) in self.facet_range.iter_mut().zip(later.facet_range) {
            for (h, t) in hi.iter_mut().zip(thi) {
                *h = h.max(t);
            }
            for (l, t) in lo.iter_mut().zip(tlo) {
                *l = l.min(t);
            }
        }
        self.drawn += later.drawn;
    }
}

/// Samples `range` of the Monte Carlo pass; `counter` counts samples drawn
/// by every thread (for progress).
fn sample_range(
    plan: &SystemPlan,
    ctl: &Control,
    range: std::ops::Range<usize>,
    special: &[Vec<f64>],
    counter: &std::sync::atomic::AtomicUsize,
) -> MonteCarlo {
    let mut sampled: Vec<Option<IBox>> = vec![None; plan.horizon + 1];
    let mut worst: Vec<Option<(f64, usize, usize)>> = vec![None; plan.properties.len()];
    let keep = plan.boundary == Boundary::Hull && plan.closed_loop.states() == 2;
    let fixed = matches!(plan.boundary, Boundary::Polytope(_))
        .then(|| plan.closed_loop.facets(&plan.boundary, 0));
    let mut facet_range: Vec<(Vec<f64>, Vec<f64>)> = match &fixed {
        Some(f) => vec![
            (
                vec![f64::NEG_INFINITY; f.nrows()],
                vec![f64::INFINITY; f.nrows()]
            );
            plan.horizon + 1
        ],
        None => Vec::new(),
    };
    let mut points: Vec<Vec<[f64; 2]>> = vec![Vec::new(); if keep { plan.horizon + 1 } else { 0 }];
    let mut drawn = 0;
    let n = plan.closed_loop.states();
    let first = range.start;
    let mut batch: Vec<Option<Vec<f64>>> = Vec::new();
    for k in range.clone() {
        // every 64 samples from the range's start, the first one included:
        // the time limit, progress, and the next 64 samples simulated together
        if (k - first) % 64 == 0 {
            if ctl.out_of_time() {
                break;
            }
            (ctl.progress)(Progress {
                phase: Phase::Sampling,
                done: counter.load(std::sync::atomic::Ordering::Relaxed),
                total: Some(plan.samples),
            });
            batch = simulate_states(plan, k..(k + 64).min(range.end), special);
        }
        counter.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        drawn += 1;
        let Some(flat) = batch[(k - first) % 64].take() else {
            continue;
        };
        let states: Vec<&[f64]> = flat.chunks_exact(n.max(1)).collect();
        // states from the first non-finite one on are not real states (the
        // simulation overflowed): they neither shape sets nor falsify anything
        let valid = states
            .iter()
            .position(|x| !x.iter().all(|v| v.is_finite()))
            .unwrap_or(states.len());
        for (t, x) in states.iter().enumerate().take(valid) {
            let x: &[f64] = x;
            if keep {
                points[t].push([x[0], x[1]]);
                // supports of a point set are those of its hull: memory stays
                // within 512 points per step (8 KB; 80 MB over 10000 steps)
                if points[t].len() > 512 {
                    points[t] = convex_hull(&points[t]);
                }
            }
            if let Some(f) = &fixed {
                let (hi, lo) = &mut facet_range[t];
                for k in 0..f.nrows() {
                    let v: f64 = f.row(k).iter().zip(x).map(|(a, b)| a * b).sum();
                    hi[k] = hi[k].max(v);
                    lo[k] = lo[k].min(v);
                }
            }
            match &mut sampled[t] {
                Some(b) => {
                    for ((lo, hi), v) in b.lo.iter_mut().zip(b.hi.iter_mut()).zip(x) {
                        *lo = lo.min(*v);
                        *hi = hi.max(*v);
                    }
                }
                None => sampled[t] = Some(IBox::point(x)),
            }
        }
        for (i, prop) in plan.properties.iter().enumerate() {
            let found = match &prop.kind {
                PropertyKind::Goal(_) if valid <= plan.horizon => None,
                PropertyKind::Goal(g) => {
                    let x = states[plan.horizon];
                    let rhs = g.rows.iter().fold(0.0f64, |a, r| a.max(r.1.abs()));
                    let outside = -g.depth(x);
                    (outside.is_finite() && outside > tolerance(x, rhs))
                        .then_some((outside, plan.horizon))
                }
                PropertyKind::Avoid { members, steps } => {
                    let mut best: Option<(f64, usize)> = None;
                    let window = states
                        .iter()
                        .enumerate()
                        .take(valid)
                        .take(steps.1 + 1)
                        .skip(steps.0);
                    for (t, &x) in window {
                        for m in members {
                            let rhs = m.rows.iter().fold(0.0f64, |a, r| a.max(r.1.abs()));
                            let inside = m.depth(x);
                            if inside.is_finite()
                                && inside > tolerance(x, rhs)
                                && best.is_none_or(|b| inside > b.0)
                            {
                                best = Some((inside, t));
                            }
                        }
                    }
                    best
                }
            };
            if let Some((d, t)) = found {
                if worst[i].is_none_or(|w| d > w.0) {
                    worst[i] = Some((d, k, t));
                }
            }
        }
    }
    MonteCarlo {
        sampled,
        worst,
        points,
        facet_range,
        drawn,
    }
}

/// The facets of one step (rows), the sampled states' largest value along
/// each, and the samples' extent along each.
type Sampled = (DMatrix<f64>, Vec<f64>, Vec<f64>);

/// The offsets of a set along its facets: `[hi, −lo]` of the bounding box,
/// then a polytope's rows.
fn offsets(r: &Region) -> Vec<f64> {
    let b = r.bbox();
    let mut v = b.hi.clone();
    v.extend(b.lo.iter().map(|l| -l));
    if let Region::Polytope { rows, .. } = r {
        v.extend(rows.iter().map(|(_, h)| *h));
    }
    v
}

/// Whether a simulated trajectory certainly violates `prop` at `step`: its
/// initial state and noise values lie in their sets, and the rigorous
/// enclosure of the true trajectory from them (outward-rounded interval
/// arithmetic, [`ravel_analysis::closed_loop::ClosedLoop::enclose_step`])
/// lies outside the goal (some goal row is violated by every point of the
/// enclosure) or inside the avoid set at that step. The f64 simulation
/// alone could be off by more than any fixed tolerance in an unstable or
/// high-gain loop; this check makes FALSIFIED independent of it.
pub fn certainly_violates(
    plan: &SystemPlan,
    tr: &Trajectory,
    prop: &Property,
    step: usize,
) -> bool {
    let cl = &plan.closed_loop;
    let Some(x0) = tr.states.first() else {
        return false;
    };
    if !plan.initial.contains_point(x0) {
        return false;
    }
    let mut x = IBox::point(x0);
    for t in 0..step {
        let (Some(w), Some(v)) = (tr.process_noise.get(t), tr.sensor_noise.get(t)) else {
            return false;
        };
        if !(cl.plant.w.contains_point(w) && cl.plant.v.contains_point(v)) {
            return false;
        }
        match cl.enclose_step(t, &x, w, v) {
            Some(next) => x = next,
            None => return false,
        }
    }
    match &prop.kind {
        PropertyKind::Goal(g) => g.separation_margin(&x) > 0.0,
        PropertyKind::Avoid { members, .. } => {
            members.iter().any(|m| m.containment_margin(&x) >= 0.0)
        }
    }
}

/// Keep only the sampled violations that [`certainly_violates`] confirms
/// (before any partitioning, so a property-guided partitioner still works on
/// a property whose violation was not confirmed).
fn confirm(plan: &SystemPlan, mc: &mut MonteCarlo) {
    for (prop, worst) in plan.properties.iter().zip(mc.worst.iter_mut()) {
        if let Some((_, k, t)) = *worst {
            let real = simulate(plan, k).is_some_and(|tr| certainly_violates(plan, &tr, prop, t));
            if !real {
                *worst = None;
            }
        }
    }
}

/// Whether a margin proves the property.
fn proves(prop: &Property, margin: f64) -> bool {
    match &prop.kind {
        PropertyKind::Goal(_) => margin >= 0.0,
        PropertyKind::Avoid { .. } => margin > 0.0,
    }
}

/// The region of a partition cell: polytope cells keep the initial set's
/// rows; ball cells are boxes (their union covers the ball); the root is the
/// initial set itself.
fn cell_region(initial: &Region, cell: &IBox) -> Region {
    if *cell == initial.bbox() {
        return initial.clone();
    }
    match initial {
        Region::Polytope { rows, .. } => Region::Polytope {
            bbox: cell.clone(),
            rows: rows.clone(),
        },
        Region::Box(_) | Region::Ball { .. } => Region::Box(cell.clone()),
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

/// The cells of a partition and their sets over the horizon.
struct Partitioned {
    /// Each cell's bounding box.
    cells: Vec<IBox>,
    /// `sets[c][t]`: the set of cell `c` at step `t`.
    sets: Vec<Vec<Step>>,
    /// Why the partition has these cells.
    stop: Stop,
    /// Cells propagated (a refinement's parents and a grid's root included).
    calls: usize,
    /// What the outcome needs of every cell (gathered where the cell was,
    /// by the thread that propagated it).
    gathered: Gathered,
}

/// A property's margin on one cell, the step it refers to, and whether an
/// LP solver issue weakened it (see [`cell_margin`]).
type Margin = (f64, usize, bool);

/// What the outcome needs of the cells: the reach hull, the solver issues,
/// the first cut and each property's least margin. Cells are added in any
/// order, by any thread, and parts merged in any order: the result is the
/// one of adding every cell in cell order (ties go to the lower cell index;
/// the hull is order-free, see [`IBox::hull_with`]). A thread gathers its own
/// cells while their sets are in its cache; summing them up afterwards on
/// one thread, from the other core's caches, took 1.7 ms of a 25 ms run of
/// 4096 cells on two threads.
#[derive(Clone, Debug)]
struct Gathered {
    /// Cells added.
    cells: usize,
    /// `reach[t]`: the hull of every cell's box at step `t` (empty before the
    /// first cell).
    reach: Vec<IBox>,
    /// Every `(step, issue)` of every cell (sorted and deduplicated by
    /// [`Gathered::finish`]).
    issues: Vec<(usize, Issue)>,
    /// The earliest cut step over the cells: `(step, cell, cut)`.
    cut: Option<(usize, usize, Cut)>,
    /// Per property.
    least: Vec<Least>,
}

/// One property's margins over the cells (see [`Gathered`]).
#[derive(Clone, Copy, Debug, Default)]
struct Least {
    /// The least margin below `+∞` that is not NaN, its cell and step (the
    /// lowest cell among equal margins).
    min: Option<(f64, usize, usize)>,
    /// The highest cell whose margin is NaN, and its step.
    nan: Option<(usize, usize)>,
    /// A solver issue on some cell's path to the margin.
    issue: bool,
    /// The earliest cut step on the property's steps: `(step, cell, cut)`.
    cut: Option<(usize, usize, Cut)>,
}

/// The earlier of two cuts, `(step, cell, cut)`: lower step, then lower cell.
fn earlier(
    a: Option<(usize, usize, Cut)>,
    b: Option<(usize, usize, Cut)>,
) -> Option<(usize, usize, Cut)> {
    match (a, b) {
        (Some(x), Some(y)) => Some(if (y.0, y.1) < (x.0, x.1) { y } else { x }),
        (x, y) => x.or(y),
    }
}

impl Least {
    fn merge(self, other: Least) -> Least {
        Least {
            min: match (self.min, other.min) {
                (Some(a), Some(b)) => Some(if b.0 < a.0 || (b.0 == a.0 && b.1 < a.1) {
                    b
                } else {
                    a
                }),
                (a, b) => a.or(b),
            },
            nan: self.nan.max(other.nan),
            issue: self.issue || other.issue,
            cut: earlier(self.cut, other.cut),
        }
    }

    /// The margin and its step, as a scan of the cells in order gives them:
    /// the first least margin; `−∞` at the last NaN's step when a margin is
    /// NaN (NaN proves nothing); `+∞` at `step` when no cell has a margin
    /// below `+∞`.
    fn margin(&self, step: usize) -> (f64, usize) {
        match (self.nan, self.min) {
            (Some((_, t)), _) => (f64::NEG_INFINITY, t),
            (None, Some((m, _, t))) => (m, t),
            (None, None) => (f64::INFINITY, step),
        }
    }
}

impl Gathered {
    /// No cell yet.
    fn new(plan: &SystemPlan) -> Gathered {
        Gathered {
            cells: 0,
            reach: Vec::new(),
            issues: Vec::new(),
            cut: None,
            least: vec![Least::default(); plan.properties.len()],
        }
    }

    /// Adds cell `cell`'s sets.
    fn add(&mut self, plan: &SystemPlan, cell: usize, sets: &[Step]) {
        self.cells += 1;
        if self.reach.is_empty() {
            self.reach = sets.iter().map(|s| s.set.bbox()).collect();
        } else {
            for (h, s) in self.reach.iter_mut().zip(sets) {
                h.hull_with(&s.set.bbox_ref());
            }
        }
        for (t, s) in sets.iter().enumerate() {
            self.issues.extend(s.issues.iter().map(|i| (t, *i)));
        }
        let cut = first_cut(sets).map(|(t, c)| (t, cell, c));
        self.cut = earlier(self.cut, cut);
        for (l, prop) in self.least.iter_mut().zip(&plan.properties) {
            let (m, t, issue) = cell_margin(prop, sets);
            let mine = Least {
                min: (m < f64::INFINITY).then_some((m, cell, t)),
                nan: m.is_nan().then_some((cell, t)),
                issue,
                cut: cut.filter(|c| c.0 <= prop.last_step()),
            };
            *l = l.merge(mine);
        }
    }

    /// The cells of both.
    fn merge(mut self, other: Gathered) -> Gathered {
        self.cells += other.cells;
        if self.reach.is_empty() {
            self.reach = other.reach;
        } else {
            for (h, o) in self.reach.iter_mut().zip(&other.reach) {
                h.hull_with(o);
            }
        }
        self.issues.extend(other.issues);
        self.cut = earlier(self.cut, other.cut);
        for (l, o) in self.least.iter_mut().zip(other.least) {
            *l = l.merge(o);
        }
        self
    }

    /// The issues sorted and deduplicated.
    fn finish(mut self) -> Gathered {
        self.issues.sort_unstable();
        self.issues.dedup();
        self
    }
}

/// A hull boundary takes its directions from the samples of each step;
/// every other boundary is used as it is.
fn resolve_boundary<'p>(plan: &'p SystemPlan, mc: &MonteCarlo) -> std::borrow::Cow<'p, SystemPlan> {
    if plan.boundary != Boundary::Hull {
        return std::borrow::Cow::Borrowed(plan);
    }
    std::borrow::Cow::Owned(SystemPlan {
        boundary: Boundary::PerStep(
            mc.points
                .iter()
                .map(|p| hull_directions(p, HULL_MIN_ANGLE))
                .collect(),
        ),
        ..plan.clone()
    })
}

/// SG/GSG scores' reference: per step, the facets, how far the sampled
/// states reach along each (box rows first) and their extent.
fn sampled_shapes(plan: &SystemPlan, mc: &MonteCarlo) -> Vec<Option<Sampled>> {
    (0..=plan.horizon)
        .map(|t| {
            let sampled = mc.sampled[t].as_ref()?;
            let f = plan.closed_loop.facets(&plan.boundary, t);
            let (s, w) = if let Some(p) = mc.points.get(t) {
                let pts: Vec<Vec<f64>> = p.iter().map(|q| q.to_vec()).collect();
                (support_of_points(&f, &pts), extent_of_points(&f, &pts))
            } else if let Some((hi, lo)) = mc.facet_range.get(t) {
                (hi.clone(), hi.iter().zip(lo).map(|(h, l)| h - l).collect())
            } else {
                let width: Vec<f64> = sampled
                    .hi
                    .iter()
                    .zip(&sampled.lo)
                    .map(|(h, l)| h - l)
                    .collect();
                let mut s = sampled.hi.clone();
                s.extend(sampled.lo.iter().map(|l| -l));
                (s, [width.clone(), width].concat())
            };
            Some((f, s, w))
        })
        .collect()
}

/// A uniform grid over the initial set, each cell propagated (inside the
/// whole set's sets when there are several).
fn partition_uniform(plan: &SystemPlan, grid: &[usize], ctl: &Control) -> Partitioned {
    let stop = || ctl.out_of_time();
    // one cell is the initial set itself (a ball keeps its
    // closed-form support function instead of its bounding box)
    let regions: Vec<Region> = if grid.iter().all(|k| *k == 1) {
        vec![plan.initial.clone()]
    } else {
        plan.initial
            .grid(grid)
            .into_iter()
            .filter(|c| !certainly_empty(c))
            .collect()
    };
    let regions = if regions.is_empty() {
        vec![plan.initial.clone()]
    } else {
        regions
    };
    // the whole initial set first: every cell is kept inside it
    let root = (regions.len() > 1).then(|| propagate_cell_until(plan, &plan.initial, None, &stop));
    let calls = regions.len() + usize::from(root.is_some());
    let one = |i: usize| {
        (ctl.progress)(Progress {
            phase: Phase::Cells,
            done: i,
            total: Some(regions.len()),
        });
        propagate_cell_until(plan, &regions[i], root.as_deref(), &stop)
    };
    let threads = ravel_analysis::pool::available(ctl.threads).clamp(1, regions.len().max(1));
    let (sets, gathered) = if threads == 1 {
        let mut gathered = Gathered::new(plan);
        let sets: Vec<Vec<Step>> = (0..regions.len())
            .map(|i| {
                let sets = one(i);
                gathered.add(plan, i, &sets);
                sets
            })
            .collect();
        (sets, gathered)
    } else {
        // cells are independent: threads take the next index, and the
        // sets are put back in cell order
        let next = std::sync::atomic::AtomicUsize::new(0);
        let mut slots: Vec<Option<Vec<Step>>> = vec![None; regions.len()];
        let work = || {
            let mut mine = Vec::new();
            let mut gathered = Gathered::new(plan);
            loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if i >= regions.len() {
                    break (mine, gathered);
                }
                let sets = one(i);
                gathered.add(plan, i, &sets);
                mine.push((i, sets));
            }
        };
        // the calling thread is one of the workers: its warm caches and
        // heap take a share of the cells
        let mut gathered = Gathered::new(plan);
        for (mine, g) in ravel_analysis::pool::on_threads(threads, &|_| work()) {
            gathered = gathered.merge(g);
            for (i, sets) in mine {
                slots[i] = Some(sets);
            }
        }
        (slots.into_iter().flatten().collect(), gathered)
    };
    Partitioned {
        // the cells' own boxes, moved (a grid's cells are boxes)
        cells: regions
            .into_iter()
            .map(|r| match r {
                Region::Box(b) => b,
                other => other.bbox(),
            })
            .collect(),
        sets,
        stop: Stop::Grid,
        calls,
        gathered: gathered.finish(),
    }
}

/// Guided refinement of the initial set (SG, GSG or property-guided).
fn partition_guided(
    plan: &SystemPlan,
    guide: Guide,
    budget: Budget,
    shaped: &[Option<Sampled>],
    undecided: &[bool],
    ctl: &Control,
) -> Partitioned {
    let stop = || ctl.out_of_time();
    let strategy = match guide {
        Guide::Sg => Strategy::Sg,
        Guide::Gsg | Guide::Property => Strategy::Gsg,
    };
    // nothing left to decide: one call for the report's sets
    let mut budget = if guide == Guide::Property && !undecided.iter().any(|u| *u) {
        Budget { calls: 1, ..budget }
    } else {
        budget
    };
    // the run's time limit bounds the refinement too
    if let Some(limit) = ctl.time_limit {
        budget.seconds = Some(budget.seconds.map_or(limit, |s| s.min(limit)));
    }
    let evaluated = std::sync::atomic::AtomicUsize::new(0);
    let root = plan.initial.bbox();
    let r = refine_parallel(
        &root,
        strategy,
        &budget,
        &|c, parent: Option<&Option<Vec<Step>>>| {
            let region = cell_region(&plan.initial, c);
            if certainly_empty(&region) {
                let sets = vec![Step::new(region, Vec::new()); plan.horizon + 1];
                return (Some(sets), f64::NEG_INFINITY);
            }
            (ctl.progress)(Progress {
                phase: Phase::Cells,
                done: evaluated.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
                total: Some(budget.calls),
            });
            let sets =
                propagate_cell_until(plan, &region, parent.and_then(|p| p.as_deref()), &stop);
            let score = match guide {
                Guide::Sg | Guide::Gsg => (0..=plan.horizon)
                    .map(|t| match &shaped[t] {
                        Some((f, s, w)) => {
                            let b = offsets(&sets[t].set);
                            // step 0 is the cell itself, not a boundary shape
                            if t > 0 && b.len() == f.nrows() {
                                excess(&b, s, w)
                            } else {
                                let k = 2 * f.ncols();
                                excess(&b[..k], &s[..k], &w[..k])
                            }
                        }
                        None => f64::INFINITY,
                    })
                    .fold(0.0, f64::max),
                Guide::Property => plan
                    .properties
                    .iter()
                    .zip(undecided)
                    .filter(|(_, u)| **u)
                    .map(|(p, _)| {
                        let (m, _, issue) = cell_margin(p, &sets);
                        if proves(p, m) && !issue {
                            -1.0
                        } else {
                            (-m).max(0.0) + f64::MIN_POSITIVE
                        }
                    })
                    .fold(-1.0, f64::max),
            };
            (Some(sets), score)
        },
        ctl.elapsed,
        ctl.threads,
    );
    let mut leaves = r.leaves;
    // deterministic order: by cell position
    leaves.sort_by(|a, b| {
        a.cell
            .lo
            .iter()
            .zip(&b.cell.lo)
            .map(|(x, y)| x.total_cmp(y))
            .find(|o| o.is_ne())
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let part = leaves.iter().map(|l| l.cell.clone()).collect();
    let sets: Vec<Vec<Step>> = leaves.into_iter().filter_map(|l| l.value).collect();
    let mut gathered = Gathered::new(plan);
    for (i, c) in sets.iter().enumerate() {
        gathered.add(plan, i, c);
    }
    Partitioned {
        cells: part,
        sets,
        stop: r.stop,
        calls: r.calls,
        gathered: gathered.finish(),
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
                PropertyKind::Goal(_) => Kind::Goal,
                PropertyKind::Avoid { .. } => Kind::Avoid,
            };
            let (margin, step) = l.margin(match &prop.kind {
                PropertyKind::Goal(_) => plan.horizon,
                PropertyKind::Avoid { steps, .. } => steps.0,
            });
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
                    counterexample: None,
                    cut,
                },
            }
        })
        .collect()
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
    let cells = part.sets;
    let properties = verdicts(plan, &part.gathered, &mc);
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
        cells: cells
            .into_iter()
            .map(|c| c.into_iter().map(|s| s.set).collect())
            .collect(),
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
