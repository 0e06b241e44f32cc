//! Monte Carlo for closed loops: seeded samples of the initial set and the
//! noise simulated side by side, the worst trajectory per property, its
//! rigorous confirmation, and the sampled shapes the guided partitioner
//! and the hull boundary use.

use nalgebra::DMatrix;

use crate::lower::{GoalMode, Property, PropertyKind, SystemPlan};
use ravel_analysis::closed_loop::Boundary;
use ravel_analysis::sets::{IBox, Region};
use ravel_analysis::shape::{
    convex_hull, extent_of_points, hull_directions, support_of_points, HULL_MIN_ANGLE,
};
use ravel_base::rng::Rng;

use super::constraints;
use super::*;

/// Per-sample random stream: sample `k` of seed `s` is reproducible on its own.
pub(super) fn sample_rng(seed: u64, k: usize) -> Rng {
    let mut r = Rng::new(seed);
    let base = r.next_u64();
    Rng::new(base ^ (k as u64).wrapping_mul(0xD134_2543_DE82_EF95))
}

pub(super) fn pick_noise(rng: &mut Rng, b: &IBox) -> Vec<f64> {
    let mut out = vec![0.0; b.dim()];
    pick_noise_into(rng, b, &mut out, 1);
    out
}

/// [`pick_noise`] into every `stride`-th entry of `out` (the same draws in the same order).
pub(super) fn pick_noise_into(rng: &mut Rng, b: &IBox, out: &mut [f64], stride: usize) {
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
    let p = cl.v().dim();
    let mut x = vec![0.0; n * count];
    for (c, &s) in live.iter().enumerate() {
        if let Some(states) = &out[s] {
            for j in 0..n {
                x[j * count + c] = states[j];
            }
        }
    }
    let q = cl.w().dim();
    let (mut w, mut v) = (vec![0.0; q * count], vec![0.0; p * count]);
    for t in 0..h {
        for (c, &s) in live.iter().enumerate() {
            // (a nonlinear plant may have no disturbance: an empty buffer)
            pick_noise_into(
                &mut rngs[s],
                cl.w(),
                w.get_mut(c..).unwrap_or_default(),
                count,
            );
            pick_noise_into(
                &mut rngs[s],
                cl.v(),
                v.get_mut(c..).unwrap_or_default(),
                count,
            );
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
pub(super) fn simulate_from(
    plan: &SystemPlan,
    k: usize,
    special: &[Vec<f64>],
) -> Option<Trajectory> {
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
        let w = pick_noise(&mut rng, cl.w());
        let v = pick_noise(&mut rng, cl.v());
        let (u, next) = cl.simulate(t, &tr.states[t], &w, &v);
        tr.controls.push(u);
        tr.process_noise.push(w);
        tr.sensor_noise.push(v);
        tr.states.push(next);
    }
    Some(tr)
}

/// What the Monte Carlo pass found.
pub(super) struct MonteCarlo {
    pub(super) sampled: Vec<Option<IBox>>,
    /// (depth of violation, sample index, step) per property
    pub(super) worst: Vec<Option<(f64, usize, usize)>>,
    /// the simulated 2-D states per step (only their convex hull once there
    /// are many), kept for a hull boundary
    pub(super) points: Vec<Vec<[f64; 2]>>,
    /// for a polytope boundary: per step, the largest and smallest value of
    /// each facet direction (box rows first) over the simulated states
    pub(super) facet_range: Vec<(Vec<f64>, Vec<f64>)>,
    /// samples drawn (fewer than planned when the time limit stopped sampling)
    pub(super) drawn: usize,
}

/// The Monte Carlo pass. Samples are independent (each has its own random
/// stream), so with several threads each takes a contiguous range of sample
/// indices and the partial results are merged in index order: the outcome is
/// the one thread's, bit for bit (boxes and facet ranges are maxima and
/// minima; the deepest violation keeps the earliest sample on ties). A 2-D
/// hull boundary keeps its samples' points in one pass, sequentially (its
/// point set is pruned as it grows, which depends on the order).
pub(super) fn monte_carlo(plan: &SystemPlan, ctl: &Control) -> MonteCarlo {
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
    pub(super) fn absorb(&mut self, later: MonteCarlo) {
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
pub(super) fn sample_range(
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
            let found = violation_of(prop, &states[..valid]);
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

/// One step's sampled shape, the reference of the SG/GSG scores.
#[derive(Clone, Debug)]
pub(super) struct Sampled {
    /// The step's facets (rows).
    pub(super) facets: DMatrix<f64>,
    /// The sampled states' largest value along each facet.
    pub(super) support: Vec<f64>,
    /// The samples' extent along each facet.
    pub(super) extent: Vec<f64>,
}

/// The offsets of a set along its facets: `[hi, −lo]` of the bounding box,
/// then a polytope's rows.
pub(super) fn offsets(r: &Region) -> Vec<f64> {
    let b = r.bbox();
    let mut v = b.hi.clone();
    v.extend(b.lo.iter().map(|l| -l));
    if let Region::Polytope { rows, .. } = r {
        v.extend(rows.iter().map(|(_, h)| *h));
    }
    v
}

/// How deeply the simulated states `x_0 …` (finite ones only: a
/// trajectory cut short overflowed) violate `prop`, beyond the simulation
/// tolerance, and the step: the deepest instant outside an "always" goal or
/// inside an avoid member; for an "eventually" goal, every instant of the
/// window outside (the shallowest of them; for a plant in continuous
/// time, whose trajectory may enter the goal between the instants, only
/// a candidate that [`certainly_violates`] checks over the periods too).
/// Instants only: a violation between them is not seen.
pub(super) fn violation_of(prop: &Property, states: &[&[f64]]) -> Option<(f64, usize)> {
    let w = prop.window();
    let window = || {
        states
            .iter()
            .enumerate()
            .take(w.steps.1 + 1)
            .skip(w.steps.0)
    };
    match &prop.kind {
        PropertyKind::Goal { set, mode, .. } => {
            let rhs = constraints::rhs_scale(set);
            let outside = |x: &[f64]| {
                let d = -constraints::depth(set, x);
                (d.is_finite() && d > tolerance(x, rhs)).then_some(d)
            };
            match mode {
                GoalMode::Always => {
                    let mut best: Option<(f64, usize)> = None;
                    for (t, &x) in window() {
                        if let Some(d) = outside(x) {
                            if best.is_none_or(|b| d > b.0) {
                                best = Some((d, t));
                            }
                        }
                    }
                    best
                }
                GoalMode::Eventually => {
                    // a continuous-time plant may enter the goal between
                    // the instants: the candidate is confirmed (or not) on
                    // the periods too, by `certainly_violates`
                    if states.len() <= w.last() {
                        return None;
                    }
                    let mut least: Option<(f64, usize)> = None;
                    for (t, &x) in window() {
                        let d = outside(x)?;
                        if least.is_none_or(|b| d < b.0) {
                            least = Some((d, t));
                        }
                    }
                    least
                }
            }
        }
        PropertyKind::Avoid { members, .. } => {
            let mut best: Option<(f64, usize)> = None;
            for (t, &x) in window() {
                for m in members {
                    let rhs = constraints::rhs_scale(m);
                    let inside = constraints::depth(m, x);
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
    }
}

/// The flow of a continuous-time plant over one control period, for the
/// states between two instants: a nonlinear plant's loop, or a linear
/// plant's loop `ẋ = A x + B u + c` ([`crate::lower::Intersample`]), whose
/// process noise arrives at the next instant and is not part of the flow.
pub(super) struct PeriodFlow<'a> {
    lp: &'a ravel_analysis::nonlinear::NonlinearLoop,
    /// A linear plant: the next instant's state is the discretised step's
    /// (with its noise), not the flow's end.
    linear: bool,
}

impl PeriodFlow<'_> {
    /// The period's length in seconds.
    pub(super) fn period(&self) -> f64 {
        match self.lp.plant.field.time {
            ravel_base::expr::Time::Continuous { period } => period,
            ravel_base::expr::Time::Discrete => 0.0,
        }
    }

    /// The process noise the flow takes (none for a linear plant).
    fn noise<'w>(&self, w: &'w [f64]) -> &'w [f64] {
        if self.linear {
            &[]
        } else {
            w
        }
    }

    /// The validated flow from the box `x` with the sensor noise `v` (and,
    /// for a nonlinear plant, the disturbance `w`): the end's box and one
    /// box per `1/substeps` of the period
    /// ([`ravel_analysis::nonlinear::NonlinearLoop::enclose_period`]).
    fn enclose(
        &self,
        x: &IBox,
        w: &[f64],
        v: &[f64],
        substeps: usize,
    ) -> Option<(IBox, Vec<IBox>)> {
        self.lp.enclose_period(x, self.noise(w), v, substeps)
    }

    /// The float flow from `x` over `h` seconds with the control `u` held.
    pub(super) fn simulate(&self, x: &[f64], u: &[f64], w: &[f64], h: f64) -> Vec<f64> {
        ravel_analysis::nonlinear::integrate::simulate(&self.lp.plant.field, x, u, self.noise(w), h)
    }
}

/// The flow of the period after step `t` of a plant in continuous time;
/// `None` in discrete time.
pub(super) fn period_flow(plan: &SystemPlan, t: usize) -> Option<PeriodFlow<'_>> {
    match &plan.closed_loop {
        ravel_analysis::feedback::Loop::Nonlinear(nl) => matches!(
            nl.plant.field.time,
            ravel_base::expr::Time::Continuous { .. }
        )
        .then_some(PeriodFlow {
            lp: nl,
            linear: false,
        }),
        ravel_analysis::feedback::Loop::Linear(_) => {
            let loops = &plan.intersample.as_ref()?.loops;
            let lp = loops.get(t.min(loops.len().checked_sub(1)?))?;
            Some(PeriodFlow { lp, linear: true })
        }
    }
}

/// Whether the plant is in continuous time: its properties then cover the
/// periods between instants, and its counterexamples may lie there.
pub(super) fn has_between(plan: &SystemPlan) -> bool {
    period_flow(plan, 0).is_some()
}

/// Whether a simulated trajectory certainly violates `prop` at `step`: its
/// initial state and noise values lie in their sets, and the rigorous
/// enclosure of the true trajectory from them (outward-rounded interval
/// arithmetic, [`ravel_analysis::closed_loop::ClosedLoop::enclose_step`])
/// lies outside the goal (some goal row or constraint is violated by every
/// point of the enclosure) or inside an avoid member (every row and every
/// constraint holds on all of it) at that step. An "eventually" goal is
/// violated only when the enclosure lies outside at every instant of its
/// window (and, for a plant in continuous time, linear or not, over every
/// period that meets the window too: [`eventually_missed`]). The f64 simulation
/// alone could be off by more than
/// any fixed tolerance in an unstable or high-gain loop; this check makes
/// FALSIFIED independent of it.
pub fn certainly_violates(
    plan: &SystemPlan,
    tr: &Trajectory,
    prop: &Property,
    step: usize,
) -> bool {
    let cl = &plan.closed_loop;
    let w = prop.window();
    let eventually = matches!(
        prop.kind,
        PropertyKind::Goal {
            mode: GoalMode::Eventually,
            ..
        }
    );
    if !(w.steps.0..=w.steps.1).contains(&step) {
        return false;
    }
    if eventually && has_between(plan) {
        return eventually_missed(plan, tr, prop);
    }
    let last = if eventually { w.steps.1 } else { step };
    let Some(x0) = tr.states.first() else {
        return false;
    };
    if !plan.initial.contains_point(x0) {
        return false;
    }
    let mut x = IBox::point(x0);
    // the enclosures at the window's instants up to `last`
    let mut at = Vec::new();
    for t in 0..=last {
        if t >= w.steps.0 {
            at.push(x.clone());
        }
        if t == last {
            break;
        }
        let (Some(wn), Some(v)) = (tr.process_noise.get(t), tr.sensor_noise.get(t)) else {
            return false;
        };
        if !(cl.w().contains_point(wn) && cl.v().contains_point(v)) {
            return false;
        }
        match cl.enclose_step(t, &x, wn, v) {
            Some(next) => x = next,
            None => return false,
        }
    }
    match &prop.kind {
        PropertyKind::Goal {
            set,
            mode: GoalMode::Always,
            ..
        } => constraints::box_outside(set, &x),
        PropertyKind::Goal {
            set,
            mode: GoalMode::Eventually,
            ..
        } => at.iter().all(|b| constraints::box_outside(set, b)),
        PropertyKind::Avoid { members, .. } => {
            members.iter().any(|m| constraints::box_inside(m, &x))
        }
    }
}

/// An "eventually" goal of a plant in continuous time, certainly
/// never reached by a simulated trajectory during its window: its initial
/// state and noise values lie in their sets, and the rigorous enclosure of
/// the true trajectory lies outside the goal at every instant of the
/// window and on every piece of every period that meets the window (the
/// period cut into eighths, or finer, as the certificate checker cuts it:
/// [`CONFIRM_PIECES`]) — the first and the last period may reach past the
/// window's ends, which only asks more. Each period is enclosed with every
/// cut ([`PeriodFlow::enclose`]); the state carried to the next instant is
/// the intersection of their ends (nonlinear plants) or the discretised
/// step's enclosure (linear plants, whose noise arrives at the instant).
fn eventually_missed(plan: &SystemPlan, tr: &Trajectory, prop: &Property) -> bool {
    let cl = &plan.closed_loop;
    let PropertyKind::Goal { set, .. } = &prop.kind else {
        return false;
    };
    let w = prop.window();
    let last = w.last();
    let Some(x0) = tr.states.first() else {
        return false;
    };
    if !plan.initial.contains_point(x0) {
        return false;
    }
    let mut x = IBox::point(x0);
    for t in 0..=last {
        if (w.steps.0..=w.steps.1).contains(&t) && !constraints::box_outside(set, &x) {
            return false;
        }
        if t == last {
            break;
        }
        let (Some(wn), Some(v), Some(flow)) = (
            tr.process_noise.get(t),
            tr.sensor_noise.get(t),
            period_flow(plan, t),
        ) else {
            return false;
        };
        if !(cl.w().contains_point(wn) && cl.v().contains_point(v)) {
            return false;
        }
        // the period cut as the checker cuts it, each cut an enclosure of
        // the same states: the pieces of one cut must all miss the goal (a
        // linear plant's flow is needed only for the window's periods)
        let needed = w.has_period(t + 1) || !flow.linear;
        let tries: Vec<(IBox, Vec<IBox>)> = CONFIRM_PIECES
            .iter()
            .filter(|_| needed)
            .filter_map(|&s| flow.enclose(&x, wn, v, s))
            .collect();
        let missed = |pieces: &[IBox]| pieces.iter().all(|b| constraints::box_outside(set, b));
        if (needed && tries.len() != CONFIRM_PIECES.len())
            || (w.has_period(t + 1) && !tries.iter().any(|(_, p)| missed(p)))
        {
            return false;
        }
        // the next state: a nonlinear plant's is the intersection of the
        // cuts' ends (a fast state's end wraps far less with short
        // substeps); a linear plant's is its discretised step's, noise
        // included
        x = if flow.linear {
            match cl.enclose_step(t, &x, wn, v) {
                Some(next) => next,
                None => return false,
            }
        } else {
            let mut ends = tries.into_iter().map(|(end, _)| end);
            let Some(first) = ends.next() else {
                return false;
            };
            ends.fold(first, |a, b| a.intersect(&b))
        };
        if x.lo
            .iter()
            .zip(&x.hi)
            .any(|(l, h)| l.partial_cmp(h).is_none_or(|o| o.is_gt()))
        {
            return false;
        }
    }
    true
}

/// The pieces a period is cut into to confirm a violation between the
/// instants, tried in turn (shorter pieces for a trajectory that only
/// passes through the set): the certificate checker's substeps.
const CONFIRM_PIECES: [usize; 3] = [8, 32, 128];

/// Whether a simulated trajectory certainly violates an "always" goal or an
/// avoid set between two instants, in the period ending at `step` (a
/// plant in continuous time, linear or not, the whole period in the
/// property's window: both its instants are the window's):
/// its initial state and noise values lie in their sets, the rigorous
/// enclosure of the trajectory up to step `step − 1` is
/// [`certainly_violates`]'s, and the validated flow of that period, cut into
/// pieces of `1/s` of it for each `s` of [`CONFIRM_PIECES`] in turn, has a
/// piece lying wholly outside the goal (or inside an avoid member): every
/// true state over that part of the period violates the property.
pub fn certainly_violates_between(
    plan: &SystemPlan,
    tr: &Trajectory,
    prop: &Property,
    step: usize,
) -> bool {
    let cl = &plan.closed_loop;
    let w = prop.window();
    let eventually = matches!(
        prop.kind,
        PropertyKind::Goal {
            mode: GoalMode::Eventually,
            ..
        }
    );
    // the whole period in the window: a window in seconds may end inside a
    // period it covers, and a violation after its end is none
    let inside = step > w.steps.0 && step <= w.steps.1 && w.has_period(step);
    let Some(flow) = period_flow(plan, step.saturating_sub(1)) else {
        return false;
    };
    if eventually || !inside {
        return false;
    }
    let Some(x0) = tr.states.first() else {
        return false;
    };
    if !plan.initial.contains_point(x0) {
        return false;
    }
    let violated = |b: &IBox| match &prop.kind {
        PropertyKind::Goal { set, .. } => constraints::box_outside(set, b),
        PropertyKind::Avoid { members, .. } => {
            members.iter().any(|m| constraints::box_inside(m, b))
        }
    };
    let mut x = IBox::point(x0);
    for t in 0..step {
        let (Some(wn), Some(v)) = (tr.process_noise.get(t), tr.sensor_noise.get(t)) else {
            return false;
        };
        if !(cl.w().contains_point(wn) && cl.v().contains_point(v)) {
            return false;
        }
        if t + 1 < step {
            match cl.enclose_step(t, &x, wn, v) {
                Some(next) => x = next,
                None => return false,
            }
            continue;
        }
        for substeps in CONFIRM_PIECES {
            if let Some((_, pieces)) = flow.enclose(&x, wn, v, substeps) {
                if pieces.iter().any(violated) {
                    return true;
                }
            }
        }
    }
    false
}

/// Keep only the sampled violations that [`certainly_violates`] confirms
/// (before any partitioning, so a property-guided partitioner still works on
/// a property whose violation was not confirmed).
pub(super) fn confirm(plan: &SystemPlan, mc: &mut MonteCarlo) {
    for (prop, worst) in plan.properties.iter().zip(mc.worst.iter_mut()) {
        if let Some((_, k, t)) = *worst {
            let real = simulate(plan, k).is_some_and(|tr| certainly_violates(plan, &tr, prop, t));
            if !real {
                *worst = None;
            }
        }
    }
}

/// A hull boundary takes its directions from the samples of each step;
/// every other boundary is used as it is.
pub(super) fn resolve_boundary<'p>(
    plan: &'p SystemPlan,
    mc: &MonteCarlo,
) -> std::borrow::Cow<'p, SystemPlan> {
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
pub(super) fn sampled_shapes(plan: &SystemPlan, mc: &MonteCarlo) -> Vec<Option<Sampled>> {
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
            Some(Sampled {
                facets: f,
                support: s,
                extent: w,
            })
        })
        .collect()
}
