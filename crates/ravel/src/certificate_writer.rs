//! The certificate writer: a `ravel-certificate/1` document for one
//! verified (spec, controller) pair, which [`ravel_certify`] re-checks
//! without trusting the analysis.
//!
//! The claimed sets are not the analysis's own sets: for every cell of the
//! partition the writer re-derives the chain of boxes with the checker's
//! one-step bound ([`ravel_certify::bounds::Loop::step`]) and records the
//! pre-activation bounds it used as the witness, so a correct certificate
//! checks exactly (no rounding differences between two implementations).
//! Where the checker's chain on a cell does not prove a VERIFIED property
//! (the analysis's method was tighter: Reach-SDP, unrolled CROWN, polytope
//! sets, a parent cell's intersection), the writer bisects the cell and
//! derives the halves instead, until every cell's chain proves it: the
//! finer partition is the witness, and the checker re-checks it as any
//! other (coverage included). When that fails within the refinement's
//! budget, or the evidence is of a kind the checker does not handle yet,
//! the evidence is marked `unsupported` with the reason, and `ravel
//! certify` answers UNSUPPORTED, never VALID. A nonlinear plant's evidence
//! is a chain of zonotopes per cell (`nonlinear_evidence`). See
//! `docs/certificates.md`.

use serde_json::{json, Value};

use nalgebra::DMatrix;
use ravel_analysis::closed_loop::{ClosedLoop, Propagator};
use ravel_analysis::feedback::Loop as AnyLoop;
use ravel_analysis::nonlinear::NonlinearLoop;

use crate::execute::{Run, SystemOutcome, Trajectory, Verdict};
use crate::lower::{GoalMode, Plan, PropertyKind, StateSet, SystemPlan, Window};
use ravel_analysis::lp;
use ravel_analysis::sets::{IBox, Region};
use ravel_base::nn::{Layer, Network};
use ravel_certify::bounds::{widen, Bx, Chain, Duals, Loop, PlantRows, Start, Trouble};
use ravel_certify::{self as certify, Answer, FORMAT};

/// Who made the certificate and from which files.
#[derive(Clone, Debug)]
pub struct Identity {
    /// The spec's path as recorded (the CLI records it relative to the
    /// certificate's folder, where `certify` reads it).
    pub spec_path: String,
    /// SHA-256 of the spec's bytes.
    pub spec_sha256: String,
}

fn rows_json(m: &nalgebra::DMatrix<f64>) -> Value {
    Value::Array(
        (0..m.nrows())
            .map(|i| json!(m.row(i).iter().copied().collect::<Vec<f64>>()))
            .collect(),
    )
}

fn box_json(b: &IBox) -> Value {
    json!({ "lo": b.lo, "hi": b.hi })
}

fn bx_json(b: &Bx) -> Value {
    json!({ "lo": b.lo, "hi": b.hi })
}

fn ineq_json(rows: &[(Vec<f64>, f64)]) -> Value {
    Value::Array(
        rows.iter()
            .map(|(a, b)| json!({ "a": a, "b": b }))
            .collect(),
    )
}

/// The problem as a certificate records it: what the checker reads, and
/// what `ravel certify` compares with the spec's own lowering.
pub fn system_problem_json(plan: &SystemPlan) -> Value {
    let cl = match &plan.closed_loop {
        AnyLoop::Linear(cl) => cl,
        AnyLoop::Nonlinear(nl) => return nonlinear_problem_json(plan, nl.as_ref()),
    };
    let plants: Vec<Value> = cl
        .plants()
        .into_iter()
        .map(|p| {
            let error = match &p.err {
                None => Value::Null,
                Some(e) => json!({ "A": rows_json(&e.a), "B": rows_json(&e.b), "c": e.c.as_slice() }),
            };
            json!({ "A": rows_json(&p.a), "B": rows_json(&p.b), "c": p.c.as_slice(), "error": error })
        })
        .collect();
    let mut problem = json!({
        "states": cl.states(),
        "controls": cl.plant.b.ncols(),
        "observations": cl.plant.obs.ncols(),
        "horizon": plan.horizon,
        "plants": plants,
        "observation": rows_json(&cl.plant.obs),
        "process_noise": box_json(&cl.plant.w),
        "sensor_noise": box_json(&cl.plant.v),
        "control_limits": plan.limits.as_ref().map(box_json),
        "initial": initial_json(&plan.initial),
        "properties": properties_json(plan),
    });
    // (only for continuous time: older certificates have no such field)
    if let Some(i) = &plan.intersample {
        problem["intersample"] = json!({
            "period": i.period,
            "plants": i.plants.iter().map(|p| json!({
                "A": rows_json(&p.a),
                "B": rows_json(&p.b),
                "c": p.c.as_slice(),
            })).collect::<Vec<_>>(),
        });
    }
    problem
}

/// A nonlinear loop's problem: the plant's tape instead of matrices.
fn nonlinear_problem_json(plan: &SystemPlan, nl: &NonlinearLoop) -> Value {
    use ravel_base::expr::Time;
    let f = &nl.plant.field;
    let nodes = tape_json(&f.tape);
    let time = match f.time {
        Time::Continuous { period } => json!({ "continuous": period }),
        Time::Discrete => json!("discrete"),
    };
    json!({
        "kind": "nonlinear",
        "states": f.states,
        "controls": f.controls,
        "disturbances": f.disturbances,
        "observations": nl.plant.obs.ncols(),
        "horizon": plan.horizon,
        "time": time,
        "tape": nodes,
        "outputs": f.outputs,
        "observation": rows_json(&nl.plant.obs),
        "disturbance": box_json(&nl.plant.w),
        "sensor_noise": box_json(&nl.plant.v),
        "control_limits": plan.limits.as_ref().map(box_json),
        "initial": initial_json(&plan.initial),
        "properties": properties_json(plan),
    })
}

/// The initial set as a certificate records it.
fn initial_json(initial: &Region) -> Value {
    match initial {
        Region::Box(b) => json!({ "box": box_json(b) }),
        Region::Ball {
            center,
            radius,
            norm,
        } => json!({ "ball": { "center": center, "radius": radius, "norm": norm.name() } }),
        Region::Polytope { bbox, rows } => {
            json!({ "polytope": { "bbox": box_json(bbox), "rows": ineq_json(rows) } })
        }
    }
}

/// A tape's nodes as a certificate records them: `["const", c]`,
/// `["var", i]`, `["neg", a]`, `["add", a, b]` (likewise `sub`, `mul`,
/// `div`), `["powi", a, k]`, `["sin", a]` (any function by its name).
fn tape_json(tape: &ravel_base::expr::Tape) -> Value {
    use ravel_base::expr::Node;
    Value::Array(
        tape.nodes
            .iter()
            .map(|n| match *n {
                Node::Const(c) => json!(["const", c]),
                Node::Var(i) => json!(["var", i]),
                Node::Neg(a) => json!(["neg", a]),
                Node::Add(a, b) => json!(["add", a, b]),
                Node::Sub(a, b) => json!(["sub", a, b]),
                Node::Mul(a, b) => json!(["mul", a, b]),
                Node::Div(a, b) => json!(["div", a, b]),
                Node::Powi(a, k) => json!(["powi", a, k]),
                Node::Func(g, a) => json!([g.name(), a]),
            })
            .collect(),
    )
}

/// A goal's or avoid member's set: its rows; with nonlinear constraints,
/// `{ "rows": …, "nonlinear": [tape, …] }` (each `g(x) ≤ 0`, `g` the
/// tape's last node).
fn set_json(set: &StateSet) -> Value {
    if set.nonlinear.is_empty() {
        ineq_json(&set.poly.rows)
    } else {
        json!({
            "rows": ineq_json(&set.poly.rows),
            "nonlinear": set.nonlinear.iter().map(tape_json).collect::<Vec<_>>(),
        })
    }
}

/// The properties as a certificate records them. A goal records its
/// steps and mode only when it is not the plain goal at the horizon, and
/// a property its periods (between instants, for continuous-time
/// nonlinear plants) only when they are not the ones between its steps.
fn properties_json(plan: &SystemPlan) -> Value {
    let properties: Vec<Value> = plan
        .properties
        .iter()
        .map(|p| {
            let window = p.window();
            let mut v = match &p.kind {
                PropertyKind::Goal { set, mode, .. } => {
                    let mut v = json!({ "name": p.name, "kind": "goal" });
                    v["rows"] = ineq_json(&set.poly.rows);
                    if !set.nonlinear.is_empty() {
                        v["nonlinear"] =
                            json!(set.nonlinear.iter().map(tape_json).collect::<Vec<_>>());
                    }
                    if window != Window::at(plan.horizon) {
                        v["steps"] = json!({ "first": window.steps.0, "last": window.steps.1 });
                    }
                    if *mode == GoalMode::Eventually {
                        v["mode"] = json!("eventually");
                    }
                    v
                }
                PropertyKind::Avoid { members, .. } => json!({
                    "name": p.name,
                    "kind": "avoid",
                    "steps": { "first": window.steps.0, "last": window.steps.1 },
                    "members": members.iter().map(set_json).collect::<Vec<_>>(),
                }),
            };
            if window.periods != Window::steps(window.steps.0, window.steps.1).periods {
                v["periods"] = json!({ "first": window.periods.0, "last": window.periods.1 });
            }
            v
        })
        .collect();
    Value::Array(properties)
}

/// SHA-256 of the network as analysed (every layer's numbers, saturation
/// included): it covers external-data files, which the controller file's
/// own hash does not.
pub fn network_sha256(net: &Network) -> String {
    let mut bytes = Vec::new();
    bytes.extend((net.inputs as u64).to_le_bytes());
    for layer in &net.layers {
        match layer {
            Layer::Affine { w, b } => {
                bytes.push(b'A');
                bytes.extend((w.nrows() as u64).to_le_bytes());
                bytes.extend((w.ncols() as u64).to_le_bytes());
                for i in 0..w.nrows() {
                    for j in 0..w.ncols() {
                        bytes.extend(w[(i, j)].to_bits().to_le_bytes());
                    }
                }
                for v in b.iter() {
                    bytes.extend(v.to_bits().to_le_bytes());
                }
            }
            Layer::Act(a) => {
                bytes.push(b'S');
                bytes.extend(a.name().as_bytes());
            }
        }
    }
    crate::check::sha256_hex(&bytes)
}

fn trajectory_json(tr: &Trajectory) -> Value {
    json!({
        "initial": tr.states.first(),
        "process_noise": tr.process_noise,
        "sensor_noise": tr.sensor_noise,
        "controls": tr.controls,
        "states": tr.states,
    })
}

/// The linear closed loop of a plan (the checker's chain of boxes is for
/// linear plants).
fn linear(plan: &SystemPlan) -> Result<&ClosedLoop, String> {
    match &plan.closed_loop {
        AnyLoop::Linear(cl) => Ok(cl.as_ref()),
        AnyLoop::Nonlinear(_) => Err(NONLINEAR_UNSUPPORTED.into()),
    }
}

/// Why a linear plant's chain of boxes does not apply.
const NONLINEAR_UNSUPPORTED: &str =
    "a nonlinear plant's evidence is a chain of zonotopes, not of boxes";

/// The relative widenings of the analysis's remainders tried, in order
/// (each a full re-derivation and check),
/// for a nonlinear loop's claims: the checker re-derives every claim with
/// its own arithmetic, which needs some room beyond the analysis's.
const INFLATIONS: [f64; 5] = [0.01, 0.04, 0.1, 0.5, 2.0];

/// A nonlinear loop's evidence: per cell, the zonotope the analysis carries
/// at every step up to `steps` (with its remainders widened), checkable by
/// `ravel_certify::nonlinear`; the first widening the checker accepts, or
/// `unsupported` with the checker's reason.
fn nonlinear_evidence(
    plan: &SystemPlan,
    nl: &NonlinearLoop,
    outcome: &SystemOutcome,
    cert: &Value,
    steps: usize,
) -> Value {
    let boxes: Vec<IBox> = outcome
        .cells
        .iter()
        .filter_map(|sets| sets.first().map(Region::bbox))
        .collect();
    let mut failure = String::from("no cells");
    let mut failures: Vec<String> = Vec::new();
    for inflate in INFLATIONS {
        let mut cells = Vec::with_capacity(boxes.len());
        for (c, b) in boxes.iter().enumerate() {
            let Some(claims) = nl.claims(b, steps, inflate) else {
                // a wider chain would be cut too
                return json!({
                    "status": "unsupported",
                    "reason": format!(
                        "cell {c}: the analysis's chain of claims (remainders widened by {inflate}) is cut before step {steps}; the last failure of the checker: {failure}"
                    ),
                });
            };
            let claims: Vec<Value> = claims
                .iter()
                .map(|z| json!({ "c": z.c, "ids": z.ids, "g": z.g }))
                .collect();
            cells.push(json!({ "box": box_json(b), "claims": claims }));
        }
        let evidence = json!({
            "status": "checkable",
            "steps": steps,
            "slope_steps": nl.slope_steps,
            "inflation": inflate,
            "cells": cells,
        });
        let mut candidate = cert.clone();
        candidate["evidence"] = evidence;
        let report = certify::check(&candidate, plan.closed_loop.net());
        match (report.evidence_failure, report.answer) {
            (Some(why), _) => {
                failures.push(format!("widened by {inflate}: {why}"));
                failure = why;
            }
            (None, Answer::Unreadable(e)) => {
                return json!({ "status": "unsupported", "reason": format!("internal: {e}") })
            }
            (None, _) => return candidate["evidence"].take(),
        }
    }
    // the least and the most widened tries say most: the first where the
    // checker's image does not fit, the last where the claims are too wide
    let shown = match (failures.first(), failures.last()) {
        (Some(a), Some(b)) if failures.len() > 1 => format!("{a}; {b}"),
        (Some(a), _) => a.clone(),
        _ => String::from("no cells"),
    };
    json!({
        "status": "unsupported",
        "reason": format!(
            "the checker's own integration does not re-derive the analysis's claims ({shown})"
        ),
    })
}

/// The closed loop's plants and noise boxes in the checker's types.
pub fn loop_data(cl: &ClosedLoop) -> (Vec<PlantRows>, Bx, Bx) {
    let plants = cl
        .plants()
        .into_iter()
        .map(|p| PlantRows {
            a: p.a.clone(),
            b: p.b.clone(),
            c: p.c.as_slice().to_vec(),
            err: p
                .err
                .as_ref()
                .map(|e| (e.a.clone(), e.b.clone(), e.c.as_slice().to_vec())),
        })
        .collect();
    let boxed = |b: &IBox| Bx {
        lo: b.lo.clone(),
        hi: b.hi.clone(),
    };
    (plants, boxed(&cl.plant.w), boxed(&cl.plant.v))
}

/// The VERIFIED evidence's settings, without cells: `steps`, `mode`,
/// `slope_steps`.
fn evidence_header(plan: &SystemPlan, steps: usize) -> Value {
    // the unrolled chain costs quadratic time in the horizon: only when the
    // analysis itself unrolled
    let unrolled = plan.propagator == Propagator::CrownUnrolled;
    let mode = if unrolled { "unrolled" } else { "one_step" };
    json!({
        "status": "checkable",
        "mode": mode,
        "slope_steps": plan.closed_loop.slope_steps(),
        "steps": steps,
        "cells": [],
    })
}

/// The most cells the writer's refinement may make: sixteen times the
/// analysis's partition, at least 256, within the checker's cell limit.
fn refinement_cap(cells: usize) -> usize {
    (cells.saturating_mul(16))
        .max(256)
        .min(ravel_base::limits::MAX_CELLS as usize)
}

/// Cells of the VERIFIED evidence, each with the chain of boxes and the
/// witness of every step up to `steps`, derived with the checker's own
/// step. With `refine`, a cell whose chain does not prove every VERIFIED property
/// ([`certify::CellCheck`]) is bisected along its widest side (relative to
/// X0's box) and its halves derived in its place, depth first, until every
/// cell proves them or the cells would exceed [`refinement_cap`]: the
/// analysis may have proved the verdict with tighter sets than the
/// checker's boxes (Reach-SDP, hull or polytope boundaries, unrolled
/// CROWN, a parent cell's intersection), and smaller cells tighten the
/// checker's boxes. The error says why the evidence is not checkable.
fn derive(
    plan: &SystemPlan,
    outcome: &SystemOutcome,
    header: &Value,
    cert: &Value,
    refine: bool,
) -> Result<Value, String> {
    let cl = linear(plan)?;
    let (plants, w, v) = loop_data(cl);
    let steps = header["steps"].as_u64().unwrap_or(0) as usize;
    let unrolled = header["mode"] == "unrolled";
    let checker = certify::CellCheck::new(cert, &cl.net).map_err(|e| format!("internal: {e}"))?;
    let x0 = plan.initial.bbox();
    let cap = refinement_cap(outcome.cells.len());
    // (the cell's box, the analysis's sets for it when it is its cell)
    let mut todo: Vec<(IBox, Option<&[Region]>)> = Vec::with_capacity(outcome.cells.len());
    for (c, sets) in outcome.cells.iter().enumerate() {
        let start = sets
            .first()
            .map(Region::bbox)
            .ok_or_else(|| format!("cell {c} has no sets"))?;
        todo.push((start, Some(sets.as_slice())));
    }
    todo.reverse();
    let mut cells = Vec::with_capacity(todo.len());
    while let Some((start, sets)) = todo.pop() {
        let derived = derive_cell(plan, &plants, (&w, &v), &start, sets, steps, unrolled);
        let failure = match derived {
            Ok(cell) if !refine => {
                cells.push(cell);
                continue;
            }
            Err(e) if !refine => return Err(e),
            Ok(cell) => match checker.check(&cell) {
                Ok(()) => {
                    cells.push(cell);
                    continue;
                }
                Err(e) => e.to_string(),
            },
            Err(e) => e,
        };
        // split in place: the halves come next, so the order is fixed
        if cells.len() + todo.len() + 2 > cap {
            return Err(format!(
                "the checker's own bounds do not prove the verdict ({failure}), not on the analysis's cells nor on up to {cap} cells bisected from them: either the analysis ({}) used bounds tighter than the checker re-derives, or its verdict is wrong",
                plan.propagator.name()
            ));
        }
        let (a, b) = bisect(&start, &x0);
        todo.push((b, None));
        todo.push((a, None));
    }
    let mut ev = header.clone();
    ev["cells"] = json!(cells);
    Ok(ev)
}

/// Halves of `b` across its widest side relative to `whole`'s (the
/// midpoint rounded to a double; the halves share it, so they cover `b`).
fn bisect(b: &IBox, whole: &IBox) -> (IBox, IBox) {
    let rel = |i: usize| {
        let w = whole.hi[i] - whole.lo[i];
        let d = b.hi[i] - b.lo[i];
        if w > 0.0 {
            d / w
        } else {
            d
        }
    };
    let k = (0..b.dim())
        .max_by(|&i, &j| rel(i).total_cmp(&rel(j)))
        .unwrap_or(0);
    // halves first: `hi − lo` may overflow where both ends are finite
    let mid = b.lo[k] / 2.0 + b.hi[k] / 2.0;
    let (mut lo, mut hi) = (b.clone(), b.clone());
    lo.hi[k] = mid;
    hi.lo[k] = mid;
    (lo, hi)
}

/// One cell of the evidence: the chain of boxes from `start` with the
/// witness of every step. With the analysis's `sets` for the cell, a step
/// whose set is a polytope claims its directions too.
fn derive_cell(
    plan: &SystemPlan,
    plants: &[PlantRows],
    (w, v): (&Bx, &Bx),
    start: &IBox,
    sets: Option<&[Region]>,
    steps: usize,
    unrolled: bool,
) -> Result<Value, String> {
    let cl = linear(plan)?;
    let mut set = Bx {
        lo: start.lo.clone(),
        hi: start.hi.clone(),
    };
    let mut claims = Vec::with_capacity(steps);
    let first = match &plan.initial {
        Region::Ball {
            center,
            radius,
            norm,
        } => Start::Ball {
            center,
            radius,
            norm: norm.name(),
        },
        Region::Box(_) | Region::Polytope { .. } => Start::Box,
    };
    let mut chain = Chain::new(first, unrolled);
    // the previous set's inequalities (step 0: a polytope X0's)
    let mut prev_rows: Vec<(Vec<f64>, f64)> = match &plan.initial {
        Region::Polytope { rows, .. } => rows.clone(),
        Region::Box(_) | Region::Ball { .. } => Vec::new(),
    };
    for t in 0..steps {
        let lp = Loop {
            plant: &plants[t.min(plants.len() - 1)],
            obs: &cl.plant.obs,
            w,
            v,
            net: &cl.net,
            slopes: cl.slope_steps,
        };
        let fail = |e: Trouble| format!("the checker's bound of a cell at step {}: {e}", t + 1);
        // the analysis's directions for the next set, if it is a polytope
        let directions = match sets.and_then(|s| s.get(t + 1)) {
            Some(Region::Polytope { rows, .. }) if !rows.is_empty() => {
                let n = set.lo.len();
                Some(DMatrix::from_fn(rows.len(), n, |r, j| rows[r].0[j]))
            }
            _ => None,
        };
        let (lo, hi) = (set.lo.clone(), set.hi.clone());
        let solve = |g: &[f64]| lp::maximize_dual(g, &prev_rows, &lo, &hi);
        let duals = Duals::solved(&solve);
        let start = if !prev_rows.is_empty() {
            Start::Polytope {
                rows: &prev_rows,
                duals: &duals,
            }
        } else if t == 0 {
            first
        } else {
            Start::Box
        };
        // claims are widened by a hair, so that a checker on another
        // machine (whose libm may round tanh, exp, … differently) proves
        // them too; the next step starts from the widened claims
        let witness = chain.witness(&lp, &set).map_err(fail)?;
        let stepped = chain
            .step(lp, &set, start, directions.as_ref(), Some(&witness))
            .map_err(fail)?;
        let next = widen(&stepped.next);
        let rows_next: Vec<(Vec<f64>, f64)> = match &directions {
            Some(d) => (0..d.nrows())
                .map(|r| {
                    let o = stepped.offsets[r];
                    let o = widen(&Bx {
                        lo: vec![o],
                        hi: vec![o],
                    })
                    .hi[0];
                    (d.row(r).iter().copied().collect(), o)
                })
                .collect(),
            None => Vec::new(),
        };
        let mut claim = json!({
            "set": bx_json(&next),
            "preactivations": witness.iter().map(bx_json).collect::<Vec<_>>(),
        });
        if !rows_next.is_empty() {
            claim["rows"] = ineq_json(&rows_next);
        }
        if !prev_rows.is_empty() {
            claim["duals"] = json!(duals.used());
        }
        claims.push(claim);
        set = next;
        prev_rows = rows_next;
    }
    let mut cell = json!({ "box": box_json(start), "steps": claims });
    if !prev_rows.is_empty() {
        // duals of the goal rows over the last set
        let goal_duals: Vec<Vec<f64>> = plan
            .properties
            .iter()
            .filter_map(|p| match &p.kind {
                PropertyKind::Goal { set, .. } => Some(set),
                PropertyKind::Avoid { .. } => None,
            })
            .flat_map(|g| g.poly.rows.iter())
            .map(|(a, _)| lp::maximize_dual(a, &prev_rows, &set.lo, &set.hi).unwrap_or_default())
            .collect();
        cell["goal_duals"] = json!(goal_duals);
    }
    Ok(cell)
}

/// The certificate of one (spec, controller) result.
pub fn build_system(plan: &SystemPlan, outcome: &SystemOutcome, id: &Identity) -> Value {
    let verdicts: Vec<Value> = plan
        .properties
        .iter()
        .zip(&outcome.properties)
        .map(|(p, r)| {
            let mut v =
                json!({ "property": p.name, "kind": r.kind.as_str(), "status": r.status.as_str() });
            if r.status == Verdict::Falsified {
                v["step"] = json!(r.step);
                if r.between {
                    // violated in the period ending at `step`
                    v["between"] = json!(true);
                }
                v["trajectory"] = r
                    .counterexample
                    .as_ref()
                    .map_or(Value::Null, trajectory_json);
            }
            v
        })
        .collect();
    let needed = plan
        .properties
        .iter()
        .zip(&outcome.properties)
        .filter(|(_, r)| r.status == Verdict::Verified)
        .map(|(p, _)| p.last_step().min(plan.horizon))
        .max();
    let mut cert = json!({
        "format": FORMAT,
        "tool": { "name": "ravel", "version": env!("CARGO_PKG_VERSION") },
        "spec": { "path": id.spec_path, "sha256": id.spec_sha256 },
        "controller": {
            "path": plan.controller_resolved,
            "sha256": plan.controller_sha256,
            "network_sha256": network_sha256(plan.closed_loop.net()),
        },
        "analysis": {
            "propagator": plan.propagator.name(),
            "cells": outcome.partition.len(),
        },
        "problem": system_problem_json(plan),
        "verdicts": verdicts,
        "evidence": json!({ "status": "none" }),
    });
    let Some(steps) = needed else {
        return cert;
    };
    if let AnyLoop::Nonlinear(nl) = &plan.closed_loop {
        cert["evidence"] = nonlinear_evidence(plan, nl, outcome, &cert, steps);
        return cert;
    }
    let header = evidence_header(plan, steps);
    cert["evidence"] = header.clone();
    // the analysis's cells first; the refinement only where the checker's
    // chain on them does not prove the verdicts (each cell then checked on
    // its own, which costs a second chain per cell)
    let mut failure = None;
    for refine in [false, true] {
        let evidence = match derive(plan, outcome, &header, &cert, refine) {
            Ok(ev) => ev,
            Err(why) if refine => {
                cert["evidence"] = json!({ "status": "unsupported", "reason": why });
                return cert;
            }
            Err(why) => {
                failure = Some(why);
                continue;
            }
        };
        let mut candidate = cert.clone();
        candidate["evidence"] = evidence;
        // the checker's own sets may not prove what the analysis proved
        let report = certify::check(&candidate, plan.closed_loop.net());
        match (report.evidence_failure, report.answer) {
            (Some(why), _) => failure = Some(why),
            (None, Answer::Unreadable(e)) => {
                cert["evidence"] =
                    json!({ "status": "unsupported", "reason": format!("internal: {e}") });
                return cert;
            }
            (None, _) => return candidate,
        }
    }
    cert["evidence"] = json!({
        "status": "unsupported",
        "reason": format!(
            "the checker's own bounds do not prove the verdict ({}): either the analysis ({}) used bounds tighter than the checker re-derives, or its verdict is wrong",
            failure.unwrap_or_default(),
            plan.propagator.name()
        ),
    });
    cert
}

/// The problem of a network spec as a certificate records it (and `ravel
/// certify` compares it with the spec's, number for number).
pub fn network_problem_json(plan: &crate::lower::NetworkPlan) -> Value {
    use crate::ir::NetPropertyKind;
    use ravel_analysis::sets::Region;
    let rows = |r: &[(Vec<f64>, f64)]| -> Value {
        r.iter().map(|(a, b)| json!({ "a": a, "b": b })).collect()
    };
    let bx = |b: &ravel_analysis::sets::IBox| json!({ "lo": b.lo, "hi": b.hi });
    let input = match &plan.input {
        Some(Region::Box(b)) => json!({ "box": bx(b) }),
        Some(Region::Ball {
            center,
            radius,
            norm,
        }) => json!({ "ball": { "center": center, "radius": radius, "norm": norm.name() } }),
        Some(Region::Polytope { bbox, rows: r }) => {
            json!({ "polytope": { "bbox": bx(bbox), "rows": rows(r) } })
        }
        None => Value::Null,
    };
    let props: Vec<Value> = plan
        .properties
        .iter()
        .map(|p| match &p.kind {
            NetPropertyKind::Require(poly) => {
                json!({ "name": p.name, "kind": "require", "rows": rows(&poly.rows) })
            }
            NetPropertyKind::Avoid(members) => json!({
                "name": p.name,
                "kind": "avoid",
                "members": members.iter().map(|m| rows(&m.rows)).collect::<Vec<_>>(),
            }),
            NetPropertyKind::Robust(label) => {
                json!({ "name": p.name, "kind": "robust", "label": label })
            }
        })
        .collect();
    json!({
        "kind": "network",
        "inputs": plan.net.inputs,
        "outputs": plan.net.outputs(),
        "input": input,
        "properties": props,
    })
}

/// The most pieces the refinement of a network spec's evidence bisects
/// from one cell of the analysis. A cell whose bound the analysis took
/// from its optimised dual (input splitting's late cells) may need far
/// more than the checker's bounds can reach: without this limit, ACAS Xu
/// 1_1 property 5 spent 7 minutes bisecting before it gave up.
const PIECES_PER_CELL: usize = 64;

/// The certificate of a network spec's result: the problem, the verdicts
/// (a counterexample's input; robustness labels) and, when some property is
/// VERIFIED, the final cells of the input set's partition as evidence (with
/// a polytope input's dual vectors) — checked here by the checker itself;
/// where its bounds on a cell fall short, the cell is bisected until they
/// prove the verdicts (as for closed loops), and the evidence is marked
/// unsupported when that fails within the budget.
pub fn build_network(
    plan: &crate::lower::NetworkPlan,
    outcome: &crate::execute::network::NetworkOutcome,
    id: &Identity,
) -> Value {
    let verdicts: Vec<Value> = outcome
        .properties
        .iter()
        .map(|r| {
            let mut v = json!({ "property": r.name, "kind": r.kind.as_str(), "status": r.status.as_str(), "label": r.label });
            if let (Verdict::Falsified, Some(w)) = (r.status, &r.counterexample) {
                v["input"] = json!(w.input);
            }
            v
        })
        .collect();
    let any_verified = outcome
        .properties
        .iter()
        .any(|r| r.status == Verdict::Verified);
    let mut cert = json!({
        "format": FORMAT,
        "tool": { "name": "ravel", "version": env!("CARGO_PKG_VERSION") },
        "spec": { "path": id.spec_path, "sha256": id.spec_sha256 },
        "controller": {
            "path": plan.model_resolved,
            "sha256": plan.model_sha256,
            "network_sha256": network_sha256(&plan.net),
        },
        "analysis": { "propagator": plan.propagator.name(), "cells": outcome.partition.len() },
        "problem": network_problem_json(plan),
        "verdicts": verdicts,
        "evidence": json!({ "status": "none" }),
    });
    if !any_verified {
        return cert;
    }
    let header = json!({ "status": "checkable", "slope_steps": plan.slope_steps, "cells": [] });
    // a polytope input set: the supports' dual vectors, found by an LP
    // over each cell's box and recorded per cell as witnesses
    let rows = match &plan.input {
        Some(Region::Polytope { rows, .. }) => Some(rows),
        _ => None,
    };
    let lp_duals =
        |g: &[f64], cell: &Bx| rows.and_then(|r| lp::maximize_dual(g, r, &cell.lo, &cell.hi));
    let solve: Option<certify::network::CellSolver> = rows.map(|_| &lp_duals as _);
    // cells with their duals, and whether they prove the verdicts
    let prove = |cells: &[IBox], coverage: bool| -> (Vec<Value>, certify::Report) {
        let mut candidate = cert.clone();
        candidate["evidence"] = header.clone();
        candidate["evidence"]["cells"] = cells
            .iter()
            .map(|c| json!({ "lo": c.lo, "hi": c.hi }))
            .collect();
        let report = certify::network::check_cells(&candidate, &plan.net, solve, coverage);
        let mut out: Vec<Value> = candidate["evidence"]["cells"]
            .as_array()
            .cloned()
            .unwrap_or_default();
        if rows.is_some() {
            for (cell, duals) in out.iter_mut().zip(&report.duals) {
                cell["duals"] = json!(duals);
            }
        }
        (out, report)
    };
    let (mut cells, first) = prove(&outcome.partition, true);
    let mut failure = first.evidence_failure;
    if let (Some(why), true) = (&failure, outcome.split_activations) {
        // bisecting inputs does not reach bounds proved by splitting
        // activations (and would bisect hundreds of inputs in vain): the
        // evidence is the split tree with its multipliers
        cert["evidence"] = match split_evidence(plan, outcome, &cert) {
            Ok(ev) => ev,
            Err(e) => json!({
                "status": "unsupported",
                "reason": format!(
                    "the analysis proved it by branch and bound on ReLU activations; the checker's bounds over the whole input box fall short ({why}), and the split tree is no evidence: {e}"
                ),
            }),
        };
        return cert;
    }
    if failure.is_some() {
        // the refinement: every cell whose bounds fall short is bisected
        // until they prove the verdicts (depth first, in order), within
        // the budget; the finer partition is the witness
        let whole = plan
            .input
            .as_ref()
            .map_or_else(|| IBox::new(Vec::new(), Vec::new()), Region::bbox);
        let cap = refinement_cap(outcome.partition.len());
        // each cell of the analysis with the number of pieces made of it
        let mut todo: Vec<(IBox, usize)> = outcome
            .partition
            .iter()
            .cloned()
            .enumerate()
            .rev()
            .map(|(i, c)| (c, i))
            .collect();
        let mut pieces = vec![0usize; outcome.partition.len()];
        let mut refined = Vec::new();
        failure = None;
        while let Some((cell, origin)) = todo.pop() {
            let (one, report) = prove(std::slice::from_ref(&cell), false);
            match report.evidence_failure {
                None => {
                    if let Answer::Unreadable(e) = report.answer {
                        failure = Some(format!("internal: {e}"));
                        break;
                    }
                    refined.extend(one);
                }
                Some(why) if refined.len() + todo.len() + 2 > cap => {
                    failure = Some(format!(
                        "{why}; not on up to {cap} cells bisected from the analysis's either"
                    ));
                    break;
                }
                Some(why) if pieces.get(origin).is_none_or(|&n| n + 2 > PIECES_PER_CELL) => {
                    failure = Some(format!(
                        "{why}; not on up to {PIECES_PER_CELL} pieces bisected from one of the analysis's cells either"
                    ));
                    break;
                }
                Some(_) => {
                    if let Some(n) = pieces.get_mut(origin) {
                        *n += 2;
                    }
                    let (a, b) = bisect(&cell, &whole);
                    todo.push((b, origin));
                    todo.push((a, origin));
                }
            }
        }
        if failure.is_none() {
            cells = refined;
        }
    }
    cert["evidence"] = header;
    cert["evidence"]["cells"] = json!(cells);
    if failure.is_none() {
        let report = certify::check(&cert, &plan.net);
        failure = report.evidence_failure;
        if let (None, Answer::Unreadable(e)) = (&failure, report.answer) {
            cert["evidence"] =
                json!({ "status": "unsupported", "reason": format!("internal: {e}") });
            return cert;
        }
    }
    if let Some(why) = failure {
        cert["evidence"] = json!({
            "status": "unsupported",
            "reason": format!(
                "the checker's own bounds do not prove the verdict ({why}): the analysis ({}) used bounds tighter than the checker re-derives (the SDP, or the optimised dual bounds of input splitting's late cells), or its verdict is wrong",
                plan.propagator.name()
            ),
        });
    }
    cert
}

/// `v` rounded to the nearest `f32` and written in that type's shortest
/// decimal form (a smaller file; a multiplier is no claim, any value is
/// sound), as the `f64` that form reads back as.
fn short(v: f32) -> f64 {
    if v.is_finite() {
        format!("{v}").parse::<f64>().unwrap_or(f64::from(v))
    } else {
        0.0
    }
}

/// The activation-split evidence of a search on activations
/// (`docs/certificates.md`): the root's pre-activation bounds as the
/// checker proves them with the search's tightening multipliers (widened
/// as every claim), and the split tree with each node's proofs, their
/// multipliers rounded to `f32`. Every proof is evaluated by the checker's
/// own code; the ones that do not prove their row (rounding, or the
/// checker's domain a hair looser than the analysis's) are dropped, and
/// the whole certificate must then check VALID, else the reason is the
/// error.
fn split_evidence(
    plan: &crate::lower::NetworkPlan,
    outcome: &crate::execute::network::NetworkOutcome,
    cert: &Value,
) -> Result<Value, String> {
    let record = outcome
        .split_record
        .as_ref()
        .ok_or("the search kept no record (no finite pre-activation bounds)")?;
    let rebound = record.rebound;
    if let Some(why) = &record.dropped {
        return Err(why.clone());
    }
    let Some(Region::Box(b)) = &plan.input else {
        return Err("the input set is not a box".into());
    };
    let input = Bx {
        lo: b.lo.clone(),
        hi: b.hi.clone(),
    };
    let round = |nu: &[Vec<f64>]| -> Vec<Vec<f64>> {
        nu.iter()
            .map(|v| v.iter().map(|x| short(*x as f32)).collect())
            .collect()
    };
    let neurons: Vec<certify::splits::NeuronNu> = record
        .neurons
        .iter()
        .map(|n| certify::splits::NeuronNu {
            layer: n.layer,
            neuron: n.neuron,
            upper: n.upper,
            nu: round(&n.nu),
        })
        .collect();
    let claims = certify::splits::derive_claims(&plan.net, &input, &neurons)?;
    // (built once and moved into the candidate: a large tree's JSON is
    // the writer's largest memory)
    let nodes: Vec<Value> = record
        .nodes
        .iter()
        .map(|n| {
            let mut v = json!({});
            if let Some((k, j, a, b)) = n.split {
                v["split"] = json!([k, j, a, b]);
            }
            if !n.proofs.is_empty() {
                v["proofs"] = n
                    .proofs
                    .iter()
                    .map(|(row, nu)| {
                        let nu: Vec<Vec<f64>> = nu
                            .iter()
                            .map(|v| v.iter().map(|x| short(*x)).collect())
                            .collect();
                        json!({ "row": row, "nu": nu })
                    })
                    .collect();
            }
            v
        })
        .collect();
    let count = nodes.len();
    let splits = json!({
        "layers": claims.iter().map(|c| json!({ "lo": c.lo, "hi": c.hi })).collect::<Vec<_>>(),
        "neurons": neurons
            .iter()
            .map(|n| json!({
                "layer": n.layer,
                "neuron": n.neuron,
                "bound": if n.upper { "hi" } else { "lo" },
                "nu": n.nu,
            }))
            .collect::<Vec<_>>(),
        "nodes": Value::Array(nodes),
        "rebound": rebound,
    });
    let mut candidate = cert.clone();
    candidate["evidence"] =
        json!({ "status": "checkable", "slope_steps": plan.slope_steps, "splits": splits });
    // the checker's whole check, saying which proofs proved their rows
    let (report, proved) = certify::network::check_split_proofs(&candidate, &plan.net);
    if let Answer::Unreadable(e) = &report.answer {
        return Err(format!("internal: {e}"));
    }
    let failed = proved.iter().flatten().any(|ok| !ok);
    let report = if failed && proved.len() == count {
        // a proof that proves nothing adds nothing: dropped, and the
        // lighter certificate checked again
        let list = candidate["evidence"]["splits"]["nodes"].as_array_mut();
        for (node, flags) in list.into_iter().flatten().zip(&proved) {
            if let Some(proofs) = node.get_mut("proofs").and_then(Value::as_array_mut) {
                let mut keep = flags.iter();
                proofs.retain(|_| keep.next().copied().unwrap_or(false));
                if proofs.is_empty() {
                    if let Some(o) = node.as_object_mut() {
                        o.remove("proofs");
                    }
                }
            }
        }
        certify::check(&candidate, &plan.net)
    } else {
        report
    };
    match (report.evidence_failure, report.answer) {
        (Some(why), _) => Err(why),
        (None, Answer::Unreadable(e)) => Err(format!("internal: {e}")),
        (None, _) => Ok(candidate["evidence"].take()),
    }
}

/// The certificate of a run: its problem, its verdicts and the evidence a
/// checker needs (see [`build_system`] and [`build_network`]).
pub fn build(run: &Run, id: &Identity) -> Value {
    match run {
        Run::System { plan, outcome } => build_system(plan, outcome, id),
        Run::Network { plan, outcome } => build_network(plan, outcome, id),
    }
}

/// The problem a plan states, as a certificate records it (compared number
/// for number by `ravel certify`).
pub fn problem_json(plan: &Plan) -> Value {
    match plan {
        Plan::System(p) => system_problem_json(p),
        Plan::Network(p) => network_problem_json(p),
    }
}
