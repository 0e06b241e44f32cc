//! Execution: a [`Plan`] → an [`Outcome`]: reachable sets, Monte Carlo
//! trajectories, and a verdict per property.
//!
//! * Every partition cell of the initial set is carried through the horizon
//!   by the chosen propagator; the reachable set at step `t` is the union of
//!   the cells' boxes (its bounding box is reported too).
//! * A property is VERIFIED when the certified margins prove it on every cell,
//!   FALSIFIED when a simulated trajectory (seeded samples of the initial set
//!   and of the noise, including extreme noise values) violates it by more
//!   than a floating-point tolerance, and UNSURE otherwise.

use crate::analysis::closed_loop::ClosedLoop;
use crate::lower::{Plan, PropertyKind};
use crate::rng::Rng;
use crate::sets::IBox;

/// A verdict.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Status {
    /// Proven for every trajectory.
    Verified,
    /// Neither proven nor refuted.
    Unsure,
    /// Refuted by a concrete trajectory.
    Falsified,
}

impl Status {
    /// The upper-case name used in reports.
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Verified => "VERIFIED",
            Status::Unsure => "UNSURE",
            Status::Falsified => "FALSIFIED",
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
    /// `goal` or `avoid`.
    pub kind: &'static str,
    /// The verdict.
    pub status: Status,
    /// VERIFIED/UNSURE: the certified margin (containment margin for a goal,
    /// separation for an avoid set; negative when the proof failed). FALSIFIED:
    /// how far the counterexample violates the property (negative).
    pub margin: f64,
    /// The step the margin refers to.
    pub step: usize,
    /// The counterexample (FALSIFIED only).
    pub counterexample: Option<Trajectory>,
}

/// Everything execution found.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// `cells[c][t]`: the box of cell `c` at step `t`.
    pub cells: Vec<Vec<IBox>>,
    /// The bounding box of all cells per step.
    pub reach: Vec<IBox>,
    /// The bounding box of the simulated states per step (if any samples).
    pub sampled: Vec<Option<IBox>>,
    /// Per-property results, in plan order.
    pub properties: Vec<PropertyResult>,
    /// The overall verdict: FALSIFIED if any property is, VERIFIED if all are, else UNSURE.
    pub verdict: Status,
    /// Number of closed-loop propagator calls.
    pub propagator_calls: usize,
}

/// Tolerance for calling a simulated violation genuine: simulations run in
/// f64 and differ from exact arithmetic by far less than this.
fn tolerance(x: &[f64], rhs_scale: f64) -> f64 {
    let m = x.iter().fold(rhs_scale.abs(), |a, v| a.max(v.abs()));
    1e-9 * (1.0 + m)
}

/// Reachable boxes of one cell over the horizon.
pub fn propagate_cell(cl: &ClosedLoop, plan: &Plan, cell: &IBox) -> Vec<IBox> {
    let mut sets = Vec::with_capacity(plan.horizon + 1);
    sets.push(cell.clone());
    for t in 0..plan.horizon {
        let next = cl.step(&sets[t], plan.propagator);
        sets.push(next);
    }
    sets
}

/// Per-sample random stream: sample `k` of seed `s` is reproducible on its own.
fn sample_rng(seed: u64, k: usize) -> Rng {
    let mut r = Rng::new(seed);
    let base = r.next_u64();
    Rng::new(base ^ (k as u64).wrapping_mul(0xD134_2543_DE82_EF95))
}

fn pick_noise(rng: &mut Rng, b: &IBox) -> Vec<f64> {
    (0..b.dim())
        .map(|i| match rng.below(4) {
            0 => b.lo[i],
            1 => b.hi[i],
            _ => rng.uniform(b.lo[i], b.hi[i]),
        })
        .collect()
}

/// Simulate sample `k`: the first samples are the corners of the initial box
/// (up to 2^12 of them), the rest uniform; noise is extreme half of the time.
pub fn simulate(plan: &Plan, k: usize) -> Trajectory {
    let cl = &plan.closed_loop;
    let mut rng = sample_rng(plan.seed, k);
    let x0 = &plan.initial;
    let n = x0.dim();
    let corners = if n <= 12 { 1usize << n } else { 0 };
    let start: Vec<f64> = if k < corners {
        (0..n)
            .map(|i| if k >> i & 1 == 1 { x0.hi[i] } else { x0.lo[i] })
            .collect()
    } else {
        (0..n).map(|i| rng.uniform(x0.lo[i], x0.hi[i])).collect()
    };
    let mut tr = Trajectory {
        states: vec![start],
        controls: vec![],
        process_noise: vec![],
        sensor_noise: vec![],
    };
    for t in 0..plan.horizon {
        let w = pick_noise(&mut rng, &cl.plant.w);
        let v = pick_noise(&mut rng, &cl.plant.v);
        let (u, next) = cl.simulate(&tr.states[t], &w, &v);
        tr.controls.push(u);
        tr.process_noise.push(w);
        tr.sensor_noise.push(v);
        tr.states.push(next);
    }
    tr
}

/// Execute a plan.
pub fn execute(plan: &Plan) -> Outcome {
    let cl = &plan.closed_loop;
    let cells: Vec<Vec<IBox>> = plan
        .cells
        .iter()
        .map(|c| propagate_cell(cl, plan, c))
        .collect();
    let reach: Vec<IBox> = (0..=plan.horizon)
        .map(|t| {
            cells
                .iter()
                .skip(1)
                .fold(cells[0][t].clone(), |h, c| h.hull(&c[t]))
        })
        .collect();

    // Monte Carlo: sample hulls and the worst violation of each property.
    let mut sampled: Vec<Option<IBox>> = vec![None; plan.horizon + 1];
    // (depth of violation, sample index, step) per property; depth > 0 means violated
    let mut worst: Vec<Option<(f64, usize, usize)>> = vec![None; plan.properties.len()];
    for k in 0..plan.samples {
        let tr = simulate(plan, k);
        for (t, x) in tr.states.iter().enumerate() {
            let p = IBox::point(x);
            sampled[t] = Some(match &sampled[t] {
                Some(b) => b.hull(&p),
                None => p,
            });
        }
        for (i, prop) in plan.properties.iter().enumerate() {
            let found = match &prop.kind {
                PropertyKind::Goal(g) => {
                    let x = &tr.states[plan.horizon];
                    let rhs = g.rows.iter().fold(0.0f64, |a, r| a.max(r.1.abs()));
                    let outside = -g.depth(x);
                    (outside > tolerance(x, rhs)).then_some((outside, plan.horizon))
                }
                PropertyKind::Avoid { members, steps } => {
                    let mut best: Option<(f64, usize)> = None;
                    for t in steps.0..=steps.1 {
                        let x = &tr.states[t];
                        for m in members {
                            let rhs = m.rows.iter().fold(0.0f64, |a, r| a.max(r.1.abs()));
                            let inside = m.depth(x);
                            if inside > tolerance(x, rhs) && best.is_none_or(|b| inside > b.0) {
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

    let properties: Vec<PropertyResult> = plan
        .properties
        .iter()
        .zip(&worst)
        .map(|(prop, worst)| {
            let (kind, margin, step) = match &prop.kind {
                PropertyKind::Goal(g) => {
                    let m = cells
                        .iter()
                        .map(|c| g.containment_margin(&c[plan.horizon]))
                        .fold(f64::INFINITY, f64::min);
                    ("goal", m, plan.horizon)
                }
                PropertyKind::Avoid { members, steps } => {
                    let mut best = (f64::INFINITY, steps.0);
                    for t in steps.0..=steps.1 {
                        for c in &cells {
                            for m in members {
                                let s = m.separation_margin(&c[t]);
                                if s < best.0 {
                                    best = (s, t);
                                }
                            }
                        }
                    }
                    ("avoid", best.0, best.1)
                }
            };
            let proven = match &prop.kind {
                PropertyKind::Goal(_) => margin >= 0.0,
                PropertyKind::Avoid { .. } => margin > 0.0,
            };
            match worst {
                // A genuine counterexample always wins; a proof next to one would be a soundness bug.
                Some((depth, k, t)) => {
                    debug_assert!(!proven, "property {} proven and falsified", prop.name);
                    PropertyResult {
                        name: prop.name.clone(),
                        kind,
                        status: Status::Falsified,
                        margin: -depth,
                        step: *t,
                        counterexample: Some(simulate(plan, *k)),
                    }
                }
                None => PropertyResult {
                    name: prop.name.clone(),
                    kind,
                    status: if proven {
                        Status::Verified
                    } else {
                        Status::Unsure
                    },
                    margin,
                    step,
                    counterexample: None,
                },
            }
        })
        .collect();
    let verdict = properties
        .iter()
        .map(|p| p.status)
        .max()
        .unwrap_or(Status::Verified);
    Outcome {
        cells,
        reach,
        sampled,
        properties,
        verdict,
        propagator_calls: plan.cells.len() * plan.horizon,
    }
}
