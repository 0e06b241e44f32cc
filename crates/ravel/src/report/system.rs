//! The report of a closed loop: a [`SystemPlan`] and its [`SystemOutcome`]
//! as text for people or as JSON for machines.

use ravel_analysis::feedback::Loop;
use ravel_base::expr::Time;
use serde_json::{json, Value};

use super::{
    f, interval, num, partition_grid, partition_text, partitioner_name, slopes_text, vector,
};
use crate::execute::{Kind, PropertyResult, SystemOutcome, Trajectory, Verdict};
use crate::lower::{GoalMode, PropertyKind, SystemPlan, Window};
use ravel_analysis::closed_loop::{Boundary, Cut, ModelError};
use ravel_analysis::sets::{IBox, Region};

fn boundary_text(b: &Boundary) -> String {
    match b {
        Boundary::Box => "box boundary".into(),
        Boundary::Polytope(d) => format!("polytope boundary ({} directions + box)", d.nrows()),
        Boundary::Hull => "hull boundary (edge normals of the sampled convex hull + box)".into(),
        Boundary::PerStep(_) => "polytope boundary (directions per step + box)".into(),
    }
}

/// A human-readable report. `timing_ms` adds a timing line.
pub fn text(
    spec_name: &str,
    plan: &SystemPlan,
    out: &SystemOutcome,
    timing_ms: Option<f64>,
) -> String {
    let mut s = format!("ravel {}: {spec_name}\n", env!("CARGO_PKG_VERSION"));
    s += &header_text(plan, out);
    s += &reach_text(plan, out);
    s += &notes_text(plan, out);
    s += &properties_text(plan, out);
    s += &format!("\n  verdict: {}\n", out.verdict.as_str());
    if let Some(ms) = timing_ms {
        s += &format!(
            "  time: {ms:.3} ms ({} propagator calls, {} samples)\n",
            out.propagator_calls, plan.samples
        );
    }
    s
}

/// The system, controller and analysis lines.
fn header_text(plan: &SystemPlan, out: &SystemOutcome) -> String {
    let mut s = String::new();
    let x = &plan.state_name;
    let n = plan.closed_loop.states();
    let m = plan.closed_loop.controls();
    let mut timing = String::new();
    match (&plan.closed_loop, plan.dt) {
        (Loop::Linear(cl), Some(dt)) => {
            let err = cl.plant.err.as_ref().map_or(0.0, ModelError::max);
            timing += &format!(
                ", continuous time, dt {} (zero-order hold, entries enclosed to ±{})",
                num(dt),
                num(err)
            );
        }
        (Loop::Linear(_), None) => {}
        (Loop::Nonlinear(nl), _) => {
            timing += &match nl.plant.field.time {
                Time::Continuous { period } => format!(
                    ", nonlinear, continuous time, control period {} (zero-order hold, validated integration)",
                    num(period)
                ),
                Time::Discrete => ", nonlinear, discrete time".to_string(),
            };
        }
    }
    if plan.closed_loop.is_time_varying() {
        timing += ", time-varying";
    }
    s += &format!(
        "  system      {} (state {x}[{n}], control {}[{m}], horizon {}{timing})\n",
        plan.system, plan.control_name, plan.horizon
    );
    let sat = match &plan.limits {
        Some(l) => format!(
            ", saturated to {} ∈ {}",
            plan.control_name,
            (0..l.dim())
                .map(|i| format!("[{}, {}]", num(l.lo[i]), num(l.hi[i])))
                .collect::<Vec<_>>()
                .join(" × ")
        ),
        None => String::new(),
    };
    s += &format!(
        "  controller  {} ({}{sat})\n",
        ravel_syntax::diag::sanitize(&plan.controller_path),
        plan.network_summary
    );
    s += &format!(
        "  analysis    {}{}, {}, {}, {} Monte Carlo samples (seed {})\n\n",
        method_name(plan),
        slopes_text(plan.closed_loop.slope_steps()),
        partition_text(&plan.partitioner, out.partition.len(), out.partition_stop),
        boundary_text(&plan.boundary),
        plan.samples,
        plan.seed
    );
    s
}

/// The reachable sets per step (the cells' bounding box, the samples'
/// hull) and the final step's error.
fn reach_text(plan: &SystemPlan, out: &SystemOutcome) -> String {
    let mut s = String::new();
    let x = &plan.state_name;
    let n = plan.closed_loop.states();
    s += "  reachable sets (bounding box of all cells, then the hull of the sampled states)\n";
    for (t, b) in out.reach.iter().enumerate() {
        for i in 0..n {
            let lead = if i == 0 {
                format!("  step {t:>3}")
            } else {
                " ".repeat(10)
            };
            let sampled = match &out.sampled[t] {
                Some(sb) => format!("   sampled {}", interval(sb.lo[i], sb.hi[i])),
                None => String::new(),
            };
            s += &format!(
                "{lead}  {x}[{i}] ∈ {}{sampled}\n",
                interval(b.lo[i], b.hi[i])
            );
        }
    }
    if let Some(err) = final_error(out) {
        s += &format!(
            "  final-step error (box volume / sampled-hull volume − 1): {}\n",
            num(err)
        );
    }
    s
}

/// Solver issues, cuts and a Monte Carlo stopped by the time limit.
fn notes_text(plan: &SystemPlan, out: &SystemOutcome) -> String {
    let mut s = String::new();
    if !out.solver_issues.is_empty() {
        let list: Vec<String> = out
            .solver_issues
            .iter()
            .map(|(t, i)| format!("{i} at step {t}"))
            .collect();
        s += &format!(
            "  LP solver: {}; those bounds fell back to bounding boxes and no property is reported VERIFIED\n",
            list.join(", ")
        );
    }
    match out.cut {
        Some((t, Cut::Overflow)) => {
            s += &format!(
                "  bounds overflowed at step {t}: from there on the reachable sets are the whole space (shown as ±inf)\n"
            );
        }
        Some((t, Cut::TimeLimit)) => {
            s += &format!(
                "  the time limit stopped the analysis at step {t}: from there on the reachable sets are the whole space (shown as ±inf)\n"
            );
        }
        Some((t, cut @ (Cut::Undefined | Cut::NoEnclosure))) => {
            s += &format!(
                "  {} at step {t}: from there on the reachable sets are the whole space (shown as ±inf)\n",
                cut_reason(cut)
            );
        }
        None => {}
    }
    if out.samples_drawn < plan.samples {
        s += &format!(
            "  the time limit stopped Monte Carlo after {} of {} samples\n",
            out.samples_drawn, plan.samples
        );
    }
    s
}

/// One line per property, each with its counterexample.
fn properties_text(plan: &SystemPlan, out: &SystemOutcome) -> String {
    let mut s = String::new();
    s += "\n  properties\n";
    let width = out
        .properties
        .iter()
        .map(|p| p.name.len() + p.kind.as_str().len() + 1)
        .max()
        .unwrap_or(0);
    for p in &out.properties {
        let label = format!("{} {}", p.kind.as_str(), p.name);
        let why = property_why(plan, p);
        s += &format!("  {label:<width$}  {:<9}  {why}\n", p.status.as_str());
        if let Some(tr) = &p.counterexample {
            s += &counterexample_text(plan, tr);
        }
    }
    s
}

/// Whether the plant is in continuous time, linear or not (its properties
/// hold between the sampling instants too).
fn continuous(plan: &SystemPlan) -> bool {
    plan.intersample.is_some()
        || matches!(&plan.closed_loop, Loop::Nonlinear(nl) if matches!(nl.plant.field.time, Time::Continuous { .. }))
}

/// Why a property has its verdict, for people.
fn property_why(plan: &SystemPlan, p: &PropertyResult) -> String {
    let no_witness = |what: &str| {
        if plan.samples == 0 {
            "no Monte Carlo samples were drawn".to_string()
        } else {
            format!("no sampled trajectory {what}")
        }
    };
    let prop = plan.properties.iter().find(|q| q.name == p.name);
    let window = prop.map(|q| q.window()).unwrap_or(Window::at(plan.horizon));
    let (a, b) = window.steps;
    let eventually = matches!(
        prop.map(|q| &q.kind),
        Some(PropertyKind::Goal {
            mode: GoalMode::Eventually,
            ..
        })
    );
    let nonlinear = prop.is_some_and(|q| match &q.kind {
        PropertyKind::Goal { set, .. } => !set.nonlinear.is_empty(),
        PropertyKind::Avoid { members, .. } => members.iter().any(|m| !m.nonlinear.is_empty()),
    });
    // a margin of −∞ without a cut: a constraint had no enclosure
    let unbounded = if nonlinear && p.margin == f64::NEG_INFINITY && p.cut.is_none() {
        " (a nonlinear constraint could not be bounded there: it may be undefined on the box, or overflow)"
    } else {
        ""
    };
    let windowed = p.kind == Kind::Goal && window != Window::at(plan.horizon);
    // a violation between two instants, in the period ending at the step
    let when = if p.between {
        format!("between steps {} and {}", p.step.saturating_sub(1), p.step)
    } else {
        format!("at step {}", p.step)
    };
    match (p.status, p.kind) {
        (Verdict::Verified, Kind::Goal) if eventually => format!(
            "on every cell a reachable box at some step of {a}..={b} is inside, least margin {}",
            num(p.margin)
        ),
        (Verdict::Verified, Kind::Goal) if windowed && a == b => format!(
            "every reachable box at step {a} is inside, margin {}",
            num(p.margin)
        ),
        (Verdict::Verified, Kind::Goal) if windowed => format!(
            "every reachable box at steps {a}..={b} is inside, least margin {} at step {}",
            num(p.margin),
            p.step
        ),
        (Verdict::Unsure, Kind::Goal) if eventually && p.cut.is_none() => format!(
            "on some cell no reachable box at steps {a}..={b} is shown inside (its best margin {} at step {}){unbounded}; {}",
            num(p.margin),
            p.step,
            if plan.samples == 0 {
                "no Monte Carlo samples were drawn".to_string()
            } else if continuous(plan) {
                "no sampled trajectory is shown outside at every step and between them".to_string()
            } else {
                "no sampled trajectory stays outside at every step".to_string()
            }
        ),
        (Verdict::Falsified, Kind::Goal) if eventually && continuous(plan) => format!(
            "a trajectory is at least {} outside at every step of {a}..={b}, and outside between them",
            num(-p.margin)
        ),
        (Verdict::Falsified, Kind::Goal) if eventually => format!(
            "a trajectory is at least {} outside at every step of {a}..={b}",
            num(-p.margin)
        ),
        (Verdict::Falsified, Kind::Goal) if windowed || p.between => {
            format!("a trajectory is {} outside {when}", num(-p.margin))
        }
        (Verdict::Verified, Kind::Goal) => format!(
            "every reachable box at step {} is inside, margin {}",
            p.step,
            num(p.margin)
        ),
        (Verdict::Verified, _) => format!(
            "reachable boxes stay clear, smallest separation {} at step {}",
            num(p.margin),
            p.step
        ),
        (Verdict::Unsure, _) if p.cut.is_some() => {
            let (t, cut) = p.cut.unwrap_or((0, Cut::Overflow));
            let what = match cut {
                    Cut::Overflow => format!("bounds overflowed at step {t}: the reachable set no longer fits in f64 numbers"),
                    Cut::TimeLimit => format!("the time limit stopped the analysis at step {t}"),
                    Cut::Undefined | Cut::NoEnclosure => format!("{} at step {t}", cut_reason(cut)),
                };
            format!(
                "{what}, so nothing is proven from there on; {}",
                no_witness(if p.kind == Kind::Goal {
                    "misses"
                } else {
                    "enters"
                })
            )
        }
        (Verdict::Unsure, Kind::Goal) => format!(
            "the reachable box at step {} sticks out by {}{unbounded}; {}",
            p.step,
            num(-p.margin),
            no_witness("misses")
        ),
        (Verdict::Unsure, _) => format!(
            "a reachable box at step {} may touch it (separation {}){unbounded}; {}",
            p.step,
            num(p.margin),
            no_witness("enters")
        ),
        (Verdict::Falsified, Kind::Goal) => format!(
            "a trajectory ends {} outside at step {}",
            num(-p.margin),
            p.step
        ),
        (Verdict::Falsified, _) => format!("a trajectory is {} inside {when}", num(-p.margin)),
    }
}

fn counterexample_text(plan: &SystemPlan, tr: &Trajectory) -> String {
    let mut s = format!(
        "      counterexample (x = {}, u = {}, w = process noise, v = sensor noise):\n",
        plan.state_name, plan.control_name
    );
    for (t, x) in tr.states.iter().enumerate() {
        s += &format!("        t={t:<3} x = {}", vector(x));
        if t < tr.controls.len() {
            s += &format!(
                "  u = {}  w = {}  v = {}",
                vector(&tr.controls[t]),
                vector(&tr.process_noise[t]),
                vector(&tr.sensor_noise[t])
            );
        }
        s += "\n";
    }
    s
}

/// The tutorial's error measure at the final step: the volume of the reachable
/// bounding box over the volume of the sampled states' bounding box, minus 1
/// (`None` without samples or when the sampled hull is flat).
pub fn final_error(out: &SystemOutcome) -> Option<f64> {
    let last = out.reach.last()?;
    let sb = out.sampled.last()?.as_ref()?;
    let v = sb.volume();
    (v > 0.0).then(|| last.volume() / v - 1.0)
}

fn region_json(r: &Region) -> Value {
    let mut v = box_json(&r.bbox());
    if let Region::Polytope { rows, .. } = r {
        v["rows"] = rows
            .iter()
            .map(|(a, b)| json!({ "a": a.iter().map(|x| f(*x)).collect::<Vec<_>>(), "b": f(*b) }))
            .collect();
    }
    v
}

fn box_json(b: &IBox) -> Value {
    json!({ "lo": b.lo.iter().map(|v| f(*v)).collect::<Vec<_>>(), "hi": b.hi.iter().map(|v| f(*v)).collect::<Vec<_>>() })
}

fn cut_json((step, cut): (usize, Cut)) -> Value {
    json!({ "step": step, "cause": cut.as_str() })
}

fn traj_json(t: &Trajectory) -> Value {
    json!({
        "states": t.states,
        "controls": t.controls,
        "process_noise": t.process_noise,
        "sensor_noise": t.sensor_noise,
    })
}

/// The JSON result for one spec (see `docs/json-schema.md`).
pub fn json(
    spec_name: &str,
    plan: &SystemPlan,
    out: &SystemOutcome,
    timing_ms: Option<f64>,
) -> Value {
    let steps: Vec<Value> = out
        .reach
        .iter()
        .enumerate()
        .map(|(t, b)| {
            json!({
                "step": t,
                "box": box_json(b),
                "sampled": out.sampled[t].as_ref().map(box_json),
                "cells": out.cells.iter().map(|c| region_json(&c[t])).collect::<Vec<_>>(),
            })
        })
        .collect();
    let props: Vec<Value> = out
        .properties
        .iter()
        .map(|p| {
            let mut v = json!({
                "name": p.name,
                "kind": p.kind.as_str(),
                "status": p.status.as_str(),
                "margin": f(p.margin),
                "step": p.step,
                "counterexample": p.counterexample.as_ref().map(traj_json),
                "unfinished": p.cut.map(cut_json),
            });
            // a counterexample that violates the property between instants
            if p.between {
                v["between"] = json!(true);
            }
            // a goal not at the horizon alone: its steps and mode
            if let Some(PropertyKind::Goal { window, mode, .. }) = plan
                .properties
                .iter()
                .find(|q| q.name == p.name)
                .map(|q| &q.kind)
            {
                if *window != Window::at(plan.horizon) {
                    v["window"] = json!({
                        "first": window.steps.0,
                        "last": window.steps.1,
                        "mode": match mode {
                            GoalMode::Always => "always",
                            GoalMode::Eventually => "eventually",
                        },
                    });
                }
            }
            v
        })
        .collect();
    let mut v = json!({
        "spec": spec_name,
        "verdict": out.verdict.as_str(),
        "system": plan.system,
        "state": { "name": plan.state_name, "dim": plan.closed_loop.states() },
        "control": { "name": plan.control_name, "dim": plan.closed_loop.controls() },
        "controller": { "path": plan.controller_path, "resolved": plan.controller_resolved, "sha256": plan.controller_sha256, "network": plan.network_summary },
        "horizon": plan.horizon,
        "dt": plan.dt.map(f),
        "model_error": match &plan.closed_loop {
            Loop::Linear(cl) => cl.plant.err.as_ref().map(|e| f(e.max())),
            Loop::Nonlinear(_) => None,
        },
        "analysis": {
            "propagator": method_name(plan),
            "partitioner": partitioner_name(&plan.partitioner),
            "partition": partition_grid(&plan.partitioner),
            "partition_stop": out.partition_stop.as_str(),
            "cells": out.partition.len(),
            "boundary": match &plan.boundary {
                Boundary::Box => "box",
                Boundary::Polytope(_) => "polytope",
                Boundary::Hull => "hull",
                Boundary::PerStep(_) => "per_step",
            },
            "samples": plan.samples,
            "seed": plan.seed,
            "slope_steps": plan.closed_loop.slope_steps(),
        },
        "reachable": steps,
        "final_error": final_error(out).map(f),
        "properties": props,
        "propagator_calls": out.propagator_calls,
        "solver_issues": out.solver_issues.iter().map(|(t, i)| json!({ "step": t, "status": i.as_str() })).collect::<Vec<_>>(),
        "unfinished": out.cut.map(cut_json),
        "samples_drawn": out.samples_drawn,
    });
    if let Some(ms) = timing_ms {
        v["time_ms"] = json!(ms);
    }
    v
}

/// Why a nonlinear plant's step is not bounded, for a person.
fn cut_reason(cut: Cut) -> &'static str {
    match cut {
        Cut::Undefined => "the plant's right-hand side may be undefined on the reachable set (a divisor that may be 0, log or sqrt of a possibly non-positive number, a pole of tan, or abs at its kink)",
        Cut::NoEnclosure => "the validated integrator found no enclosure of the flow over the control period",
        Cut::Overflow => "bounds overflowed",
        Cut::TimeLimit => "the time limit stopped the analysis",
    }
}

/// The analysis method's name: the propagator of a linear plant;
/// `taylor_crown` (first-order Taylor models composed with CROWN, validated
/// integration) for a nonlinear one, which has no other.
fn method_name(plan: &SystemPlan) -> &'static str {
    match &plan.closed_loop {
        Loop::Linear(_) => plan.propagator.name(),
        Loop::Nonlinear(_) => "taylor_crown",
    }
}
