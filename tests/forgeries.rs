//! No overflow proves anything (issue 26): the forgeries that once passed
//! the certificate checker, and the analysis at magnitudes near `f64::MAX`.
//!
//! * A certificate of a FALSIFIED goal, flipped to VERIFIED, with one true
//!   claimed inequality at the last step and goal duals of 3.5e307 on it:
//!   the dual support's sum overflowed to `−∞` and was taken as an upper
//!   bound. It is INVALID.
//! * A loop whose states reach ±1.7e308 (finite) at the horizon: a goal
//!   every trajectory violates and an avoid set every trajectory enters were
//!   VERIFIED (margins `+∞` from a sum overflowing downward). They are not,
//!   and their certificates, forced to VERIFIED, are not VALID.
//! * A forged counterexample for a goal that holds, at those magnitudes:
//!   the replay's lower bound overflowed to `+∞`. It is INVALID.

use std::path::Path;

mod common;
#[allow(dead_code)] // each test crate uses some of it
#[path = "common/exact.rs"]
mod exact;

use ravel::execute::Verdict;
use ravel_certify::{check, Answer};
use serde_json::{json, Value};

/// SystemPlan and outcome of spec text whose files resolve against `dir`.
fn analyse(source: &str, dir: &Path) -> (ravel::lower::SystemPlan, ravel::execute::SystemOutcome) {
    let checked = ravel::front_end(source, dir, &ravel_cli::read_request).expect("the spec checks");
    let plan = ravel::lower::lower_system(&checked);
    let outcome = ravel::execute::execute_system(&plan, &ravel::execute::Control::unlimited());
    (plan, outcome)
}

fn certificate(plan: &ravel::lower::SystemPlan, outcome: &ravel::execute::SystemOutcome) -> Value {
    let id = ravel::certificate_writer::Identity {
        spec_path: String::new(),
        spec_sha256: String::new(),
    };
    ravel::certificate_writer::build_system(plan, outcome, &id)
}

fn answer(cert: &Value, plan: &ravel::lower::SystemPlan) -> Answer {
    check(cert, plan.closed_loop.net()).answer
}

/// Set property `name`'s verdict in the certificate (and drop its trajectory).
fn set_status(cert: &mut Value, name: &str, status: &str) {
    for v in cert["verdicts"].as_array_mut().expect("verdicts") {
        if v["property"] == name {
            v["status"] = json!(status);
            if let Some(o) = v.as_object_mut() {
                o.remove("step");
                o.remove("trajectory");
            }
        }
    }
}

/// The quadrotor with its goal narrowed to `x[0] ∈ [3.0, 3.4]`: every
/// trajectory ends near x[0] ≈ 3.5–3.65, so the goal is FALSIFIED.
fn narrowed_quadrotor() -> (ravel::lower::SystemPlan, ravel::execute::SystemOutcome) {
    let source = std::fs::read_to_string("specs/quadrotor.ravel").expect("spec");
    let narrowed = source.replace("x[0] in [3.0, 4.5]", "x[0] in [3.0, 3.4]");
    assert_ne!(narrowed, source, "the goal line moved");
    analyse(&narrowed, Path::new("specs"))
}

#[test]
fn a_huge_goal_dual_cannot_certify_a_false_goal() {
    let (plan, outcome) = narrowed_quadrotor();
    let goal = outcome
        .properties
        .iter()
        .find(|p| p.name == "G")
        .expect("G");
    assert_eq!(goal.status, Verdict::Falsified);
    let mut cert = certificate(&plan, &outcome);
    assert_eq!(
        answer(&cert, &plan),
        Answer::Valid,
        "the honest certificate"
    );
    set_status(&mut cert, "G", "VERIFIED");
    // one claimed inequality at the last step, true: x₀ + … + x₅ is at most
    // its bound over the last claimed box (the checker's own facet bound
    // in that direction is tighter)
    let cells = cert["evidence"]["cells"]
        .as_array_mut()
        .expect("the avoid property's evidence");
    assert!(!cells.is_empty());
    for cell in cells.iter_mut() {
        let steps = cell["steps"].as_array_mut().expect("steps");
        let last = steps.last_mut().expect("a last step");
        let lo: Vec<f64> = serde_json::from_value(last["set"]["lo"].clone()).expect("lo");
        let hi: Vec<f64> = serde_json::from_value(last["set"]["hi"].clone()).expect("hi");
        let ones = vec![1.0; lo.len()];
        let b = ravel_base::num::dot_box_upper(&ones, &lo, &hi);
        let b = b + 1e-9 * (1.0 + b.abs());
        last["rows"] = json!([{ "a": ones, "b": b }]);
        // a dual of 3.5e307 on that row for each of the goal's six rows
        cell["goal_duals"] = json!(vec![vec![3.5e307]; 6]);
    }
    match answer(&cert, &plan) {
        Answer::Invalid(m) => assert!(m.contains("goal `G`"), "{m}"),
        other => panic!("a false goal was certified: {other:?}"),
    }
    // the same forgery with an absurd goal, far from every trajectory
    let mut far = cert.clone();
    for p in far["problem"]["properties"].as_array_mut().expect("props") {
        if p["name"] == "G" {
            for row in p["rows"].as_array_mut().expect("rows") {
                let a: Vec<f64> = serde_json::from_value(row["a"].clone()).expect("a");
                if a[0] == 1.0 {
                    row["b"] = json!(101.0);
                } else if a[0] == -1.0 {
                    row["b"] = json!(-100.0);
                }
            }
        }
    }
    assert!(
        matches!(answer(&far, &plan), Answer::Invalid(_)),
        "x[0] in [100, 101] certified"
    );
}

/// Seven states: x₀, x₁ stay small (the controller sees them), x₂ … x₆ grow
/// by 10¹⁵ a step from ∓1.7e8 to ∓1.7e308 at step 20, all finite. x₂ and x₃
/// are negative, x₄ … x₆ positive: `x₂ + … + x₆` is about +1.7e308 for every
/// trajectory, though a running sum in this order overflows to `−∞`.
fn huge(goal: &str, avoid: &str) -> String {
    format!(
        r#"
system huge {{
    state   x[7]
    control u[1]
    A = [[0, 0, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 0, 0],
         [0, 0, 1e15, 0, 0, 0, 0], [0, 0, 0, 1e15, 0, 0, 0], [0, 0, 0, 0, 1e15, 0, 0],
         [0, 0, 0, 0, 0, 1e15, 0], [0, 0, 0, 0, 0, 0, 1e15]]
    B = [[0.5], [1], [0], [0], [0], [0], [0]]
    C = [[1, 0], [0, 1], [0, 0], [0, 0], [0, 0], [0, 0], [0, 0]]
    u in box([-1, 1])
}}
controller "models/double_integrator.onnx"
initial X0 = box(x[0] in [2.5, 3], x[1] in [-0.25, 0.25],
                 x[2] in [-1.70e8, -1.69e8], x[3] in [-1.70e8, -1.69e8],
                 x[4] in [1.69e8, 1.70e8], x[5] in [1.69e8, 1.70e8], x[6] in [1.69e8, 1.70e8])
goal G = {{ {goal} }}
avoid crossed = {{ {avoid} }} at steps [20, 20]
horizon 20
analysis {{
    propagator reach_lp
    samples 200
}}
"#
    )
}

const SUM: &str = "x[2] + x[3] + x[4] + x[5] + x[6]";

#[test]
fn states_near_the_top_of_f64_never_verify_a_false_claim() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    // every trajectory violates the goal and enters the avoid set
    let src = huge(
        &format!("{SUM} <= 0"),
        "-x[2] - x[3] - x[4] - x[5] - x[6] <= 0",
    );
    let (plan, outcome) = analyse(&src, dir);
    // the states themselves are representable: no step overflowed
    assert_eq!(outcome.cut, None, "{:?}", outcome.cut);
    let last = outcome.reach.last().expect("sets");
    assert!(last.hi[4] > 1.6e308 && last.hi[4].is_finite());
    for p in &outcome.properties {
        assert_ne!(p.status, Verdict::Verified, "{} verified", p.name);
        assert!(!p.margin.is_nan(), "{}", p.name);
    }
    // certificates forced to VERIFIED are never VALID
    let mut cert = certificate(&plan, &outcome);
    for name in ["G", "crossed"] {
        set_status(&mut cert, name, "VERIFIED");
    }
    let mut forced = outcome.clone();
    for p in &mut forced.properties {
        p.status = Verdict::Verified;
        p.counterexample = None;
    }
    let written = certificate(&plan, &forced);
    for c in [&cert, &written] {
        let a = answer(c, &plan);
        assert!(
            !matches!(a, Answer::Valid),
            "a false claim at 1.7e308 certified: {a:?}"
        );
    }
    // the sets are sound there: each coordinate's box holds the samples'
    // range, and a true goal at this magnitude is not refused for overflow
    // of its sum: it is at worst UNSURE
    let (_, fine) = analyse(&huge(&format!("{SUM} <= 1e15"), "x[0] <= -100"), dir);
    assert_ne!(fine.properties[1].status, Verdict::Falsified);
}

#[test]
fn a_forged_counterexample_at_the_top_of_f64_is_replayed_not_trusted() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    // the goal holds: x₂ + … + x₆ is about +1.7e308 > −1 for every trajectory
    let src = huge("-x[2] - x[3] - x[4] - x[5] - x[6] <= 1", "x[0] <= -100");
    let (plan, outcome) = analyse(&src, dir);
    assert_ne!(outcome.properties[0].status, Verdict::Falsified);
    // a counterexample: a trajectory from X0's corner with no noise; the
    // checker replays it and must not find the goal violated
    let mut cert = certificate(&plan, &outcome);
    let x0 = [2.75, 0.0, -1.7e8, -1.7e8, 1.7e8, 1.7e8, 1.7e8];
    let trajectory = json!({
        "initial": x0,
        "process_noise": vec![vec![0.0; 7]; 20],
        "sensor_noise": vec![vec![0.0; 2]; 20],
    });
    for v in cert["verdicts"].as_array_mut().expect("verdicts") {
        if v["property"] == "G" {
            v["status"] = json!("FALSIFIED");
            v["step"] = json!(20);
            v["trajectory"] = trajectory.clone();
        }
    }
    let a = answer(&cert, &plan);
    assert!(
        !matches!(a, Answer::Valid),
        "a counterexample to a true goal was accepted: {a:?}"
    );
}

/// A network of 20 linear layers, each `10¹⁵·I`, on five inputs near
/// ∓1.7e8: its outputs are about ∓1.7e308 (finite). `require` that
/// `y₀ + … + y₄ ≤ 0` is false (the sum is about +1.7e308), though a running
/// sum in this order overflows to `−∞`. Neither the analysis nor a forged
/// certificate may call it proven.
#[test]
fn a_deep_linear_network_near_the_top_of_f64_proves_no_false_requirement() {
    use ravel::ir::NetPropagator;
    use ravel::ir::{NetProperty, NetPropertyKind};
    use ravel_analysis::sets::{IBox, Polytope, Region};
    use ravel_base::nn::{Layer, Network};
    let n = 5;
    let layers = (0..20)
        .map(|_| Layer::Affine {
            w: nalgebra::DMatrix::from_diagonal_element(n, n, 1e15),
            b: nalgebra::DVector::zeros(n),
        })
        .collect();
    let net = Network::new(n, layers);
    let y = net.forward(&[-1.7e8, -1.7e8, 1.7e8, 1.7e8, 1.7e8]);
    assert!(
        y.iter().all(|v| v.is_finite() && v.abs() > 1.6e308),
        "{y:?}"
    );
    let (lo, hi) = (1.69e8, 1.70e8);
    let input = IBox::new(vec![-hi, -hi, lo, lo, lo], vec![-lo, -lo, hi, hi, hi]);
    for propagator in [NetPropagator::Crown, NetPropagator::Ibp] {
        let mut plan = common::net_plan(
            net.clone(),
            Region::Box(input.clone()),
            vec![NetProperty {
                name: "sum".into(),
                kind: NetPropertyKind::Require(Polytope {
                    rows: vec![(vec![1.0; n], 0.0)],
                }),
            }],
        );
        plan.propagator = propagator;
        plan.samples = 50;
        plan.seed = 3;
        let mut out = common::run_net(&plan);
        assert_ne!(
            out.properties[0].status,
            Verdict::Verified,
            "{propagator:?}: a false requirement verified"
        );
        let id = ravel::certificate_writer::Identity {
            spec_path: String::new(),
            spec_sha256: String::new(),
        };
        out.properties[0].status = Verdict::Verified;
        out.properties[0].counterexample = None;
        let mut forced = ravel::certificate_writer::build_network(&plan, &out, &id);
        assert!(!matches!(
            ravel_certify::network::check(&forced, &net).answer,
            Answer::Valid
        ));
        forced["evidence"] = json!({
            "status": "checkable",
            "cells": [{ "lo": input.lo, "hi": input.hi }],
        });
        let a = ravel_certify::network::check(&forced, &net).answer;
        assert!(
            !matches!(a, Answer::Valid),
            "{propagator:?}: a false requirement certified: {a:?}"
        );
    }
}

/// Random loops whose four large states grow by `±2^k` a step (`k` up to
/// 49) to between 2¹⁰²² and 1.91·2¹⁰²³ at the horizon, with goal and avoid rows
/// of coefficients `±1` and small offsets: the true final states are
/// `a^T·x(0)` exactly, so every claim is decided exactly (in fixed point)
/// at X0's corners. A VERIFIED goal holds at every corner; a VERIFIED avoid
/// set is missed at every corner; a FALSIFIED one is violated at the
/// corner nearest the counterexample's start, or the run is refuted.
#[test]
fn random_loops_near_the_top_of_f64_decide_only_true_verdicts() {
    use exact::{Extreme, Fixed};
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut g = Extreme::new(1_700);
    let (mut verified, mut checked) = (0, 0);
    for round in 0..60 {
        let horizon = 21 + g.below(4) as u32;
        let big = 4usize;
        // per large state: growth ±2^k and an initial interval around ±2^m
        let mut growth = Vec::new();
        let mut init = Vec::new();
        for _ in 0..big {
            // k·T between 975 and 1012, k ≤ 49 (spec numbers lie within
            // ±1e15), the final states between 2¹⁰²² and 1.91·2¹⁰²³: a
            // state is representable, a sum of two often overflows
            let k = 975u32.div_ceil(horizon) + g.below(2) as u32;
            let sign = if g.below(2) == 0 { 1.0 } else { -1.0 };
            // (odd rounds: between 2¹⁰¹² and 2¹⁰²⁰, where sums of a few
            // terms stay finite and true claims are proven)
            let top = if round % 2 == 0 {
                1022
            } else {
                1012 + g.below(7) as i32
            };
            let m = top + g.below(2) as i32 - (k * horizon) as i32;
            let centre =
                2f64.powi(m) * (1.0 + 0.9 * g.unit()) * if g.below(2) == 0 { 1.0 } else { -1.0 };
            let half = centre.abs() * 0.005 * g.unit();
            growth.push((sign, k));
            init.push((centre - half, centre + half));
        }
        let n = 2 + big;
        let a_rows: Vec<String> = (0..n)
            .map(|i| {
                let row: Vec<String> = (0..n)
                    .map(|j| {
                        if i == j && i >= 2 {
                            let (s, k) = growth[i - 2];
                            format!("{:e}", s * 2f64.powi(k as i32))
                        } else {
                            "0".into()
                        }
                    })
                    .collect();
                format!("[{}]", row.join(", "))
            })
            .collect();
        // a row Σ ±2^j x[i] ≤ h over the large states, h small
        let row = |g: &mut Extreme| -> (Vec<(f64, u32)>, f64) {
            let coef = (0..big)
                .map(|_| {
                    let s = match g.below(3) {
                        0 => 0.0,
                        1 => 1.0,
                        _ => -1.0,
                    };
                    (s, 0)
                })
                .collect();
            (coef, (g.unit() - 0.5) * 2e15)
        };
        let text = |(coef, h): &(Vec<(f64, u32)>, f64)| -> String {
            let mut t: Vec<String> = coef
                .iter()
                .enumerate()
                .filter(|(_, (s, _))| *s != 0.0)
                .map(|(i, (s, k))| format!("{:+} x[{}]", s * f64::from(1u32 << k), i + 2))
                .collect();
            if t.is_empty() {
                t.push("0 x[2]".into());
            }
            format!("{} <= {h:e}", t.join(" "))
        };
        let (mut goal, mut avoid) = (row(&mut g), row(&mut g));
        if round % 2 == 0 {
            // the rows where a running sum overflows the wrong way: the
            // goal's terms (over X0's far corners) −, −, +, + and the avoid
            // set's +, +, −, −; whether the exact sum is positive is left to
            // the draw
            let sign_of = |i: usize| {
                let flips = growth[i].0 < 0.0 && horizon % 2 == 1;
                init[i].0.signum() * if flips { -1.0 } else { 1.0 }
            };
            for (i, c) in goal.0.iter_mut().enumerate() {
                *c = (if i < 2 { -sign_of(i) } else { sign_of(i) }, 0);
            }
            for (i, c) in avoid.0.iter_mut().enumerate() {
                *c = (if i < 2 { sign_of(i) } else { -sign_of(i) }, 0);
            }
        }
        let x0: Vec<String> = init
            .iter()
            .enumerate()
            .map(|(i, (l, h))| format!("x[{}] in [{l:e}, {h:e}]", i + 2))
            .collect();
        let src = format!(
            r#"
system top {{
    state   x[{n}]
    control u[1]
    A = [{a}]
    B = [[0.5], [1]{zeros}]
    C = [[1, 0], [0, 1]{czeros}]
    u in box([-1, 1])
}}
controller "models/double_integrator.onnx"
initial X0 = box(x[0] in [2.5, 3], x[1] in [-0.25, 0.25], {x0})
goal G = {{ {goal} }}
avoid A = {{ {avoid} }} at steps [{horizon}, {horizon}]
horizon {horizon}
analysis {{
    propagator {prop}
    samples 64
    seed {round}
}}
"#,
            a = a_rows.join(", "),
            zeros = ", [0]".repeat(big),
            czeros = ", [0, 0]".repeat(big),
            x0 = x0.join(", "),
            goal = text(&goal),
            avoid = text(&avoid),
            prop = [
                "reach_lp",
                "crown_unrolled",
                "ibp_separate",
                "sg_ibp_separate"
            ][round % 4],
        );
        let (_, outcome) = analyse(&src, dir);
        // exact a·x(T) at every corner of the large states' box
        let values = |(coef, _): &(Vec<(f64, u32)>, f64)| -> Vec<Fixed> {
            (0..1usize << big)
                .map(|corner| {
                    (0..big).fold(Fixed::ZERO, |acc, i| {
                        let (s, j) = coef[i];
                        if s == 0.0 {
                            return acc;
                        }
                        let (l, h) = init[i];
                        let x = if corner >> i & 1 == 1 { h } else { l };
                        let (gs, k) = growth[i];
                        // x(T) = (gs·2^k)^T · x(0)
                        let negative = (s < 0.0) ^ (gs < 0.0 && horizon % 2 == 1);
                        let t = Fixed::of_scaled(x, k * horizon + j);
                        acc.add(if negative { t.neg() } else { t })
                    })
                })
                .collect()
        };
        let holds = |r: &(Vec<(f64, u32)>, f64)| {
            let h = Fixed::of(r.1);
            values(r).iter().all(|v| v.le(h))
        };
        let crosses = |r: &(Vec<(f64, u32)>, f64)| {
            let h = Fixed::of(r.1);
            values(r).iter().any(|v| v.le(h))
        };
        let what = format!("round {round}:\n{src}");
        for p in &outcome.properties {
            checked += 1;
            match (p.name.as_str(), p.status) {
                ("G", Verdict::Verified) => {
                    verified += 1;
                    assert!(holds(&goal), "a false goal verified, {what}");
                }
                ("A", Verdict::Verified) => {
                    verified += 1;
                    // every corner strictly outside the half-space; linear
                    // in each state, so the whole box is outside
                    assert!(!crosses(&avoid), "an entered avoid set verified, {what}");
                }
                ("G", Verdict::Falsified) => {
                    assert!(!holds(&goal), "a true goal falsified, {what}")
                }
                ("A", Verdict::Falsified) => {
                    assert!(crosses(&avoid), "a missed avoid set falsified, {what}")
                }
                _ => {}
            }
        }
    }
    assert_eq!(checked, 120);
    // the test reaches verdicts, not only UNSURE
    assert!(verified > 10, "{verified}");
}

/// A coefficient product that underflows loses up to η/2 (η = 4.9e-324),
/// and the loss is multiplied by the values it applies to. A forged row
/// `α·x₀ ≤ b` at the last step, with `α·1e-15` rounding from 1.49η to η and
/// `x₀` up to 9e14, passed the checker as true, and a goal dual of `1/α`
/// then certified the false goal `x₀ ≤ 7e14` (found by review).
#[test]
fn an_underflowing_coefficient_times_a_large_state_proves_nothing() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let spec = |goal: &str| {
        format!(
            r#"
system under {{
    state   x[2]
    control u[1]
    A = [[0, 1e-15], [0, 1e15]]
    B = [[0], [0]]
    C = [[0, 0], [0, 0]]
    u in box([-1, 1])
}}
controller "models/double_integrator.onnx"
initial X0 = box(x[0] in [0, 0], x[1] in [1e14, 9e14])
goal G = {{ {goal} }}
horizon 2
analysis {{
    propagator reach_lp
    samples 100
}}
"#
        )
    };
    let (plan_true, out_true) = analyse(&spec("x[0] <= 1e15"), dir);
    let honest = certificate(&plan_true, &out_true);
    assert_eq!(answer(&honest, &plan_true), Answer::Valid);
    let (plan, out) = analyse(&spec("x[0] <= 7e14"), dir);
    assert_ne!(out.properties[0].status, Verdict::Verified);
    let mut forged = certificate(&plan, &out);
    forged["evidence"] = honest["evidence"].clone();
    set_status(&mut forged, "G", "VERIFIED");
    // α·1e-15 is 1.49η exactly enough, and rounds to η
    let alpha = 7.361578123034574e-309;
    assert_eq!(alpha * 1e-15, f64::from_bits(1));
    let cell = &mut forged["evidence"]["cells"][0];
    cell["steps"][1]["rows"] = json!([{ "a": [alpha, 0.0], "b": 4.4466e-294 }]);
    cell["goal_duals"] = json!([[1.0 / alpha]]);
    let a = answer(&forged, &plan);
    assert!(!matches!(a, Answer::Valid), "a false goal certified: {a:?}");
}

/// The same loss in a network certificate: `require 2η·y ≤ 5e-294` with
/// `y = 0.7·relu(1e15·x)` on `x ∈ [1e14, 9e14]` (its true maximum is
/// 6.2e-294), forced to VERIFIED, is not VALID.
#[test]
fn an_underflowing_coefficient_in_a_network_certificate_proves_nothing() {
    use ravel::ir::{NetProperty, NetPropertyKind};
    use ravel_analysis::sets::{IBox, Polytope, Region};
    use ravel_base::nn::{Activation, Layer, Network};
    let net = Network::new(
        1,
        vec![
            Layer::Affine {
                w: nalgebra::DMatrix::from_element(1, 1, 1e15),
                b: nalgebra::DVector::zeros(1),
            },
            Layer::Act(Activation::Relu),
            Layer::Affine {
                w: nalgebra::DMatrix::from_element(1, 1, 0.7),
                b: nalgebra::DVector::zeros(1),
            },
        ],
    );
    let eta = f64::from_bits(1);
    let input = IBox::new(vec![1e14], vec![9e14]);
    let plan = common::net_plan(
        net.clone(),
        Region::Box(input.clone()),
        vec![NetProperty {
            name: "r".into(),
            kind: NetPropertyKind::Require(Polytope {
                rows: vec![(vec![2.0 * eta], 5e-294)],
            }),
        }],
    );
    let mut out = common::run_net(&plan);
    assert_ne!(out.properties[0].status, Verdict::Verified);
    out.properties[0].status = Verdict::Verified;
    out.properties[0].counterexample = None;
    let mut cert = common::net_certificate(&plan, &out);
    cert["evidence"] =
        json!({ "status": "checkable", "cells": [{ "lo": input.lo, "hi": input.hi }] });
    let a = ravel_certify::network::check(&cert, &net).answer;
    assert!(
        !matches!(a, Answer::Valid),
        "a false requirement certified: {a:?}"
    );
}

/// The analysis side of the same loss: `y = 0.7·relu(1e15·relu(1e15 −
/// 1e15·|x|))` peaks at 7e29 at `x = 0`; `require 2η·y ≤ b` with `b` just
/// below `2η·7e29` is false only for |x| < 3e-14, where no sample lands.
/// CROWN's back-substitution rounded `2η·0.7` down to η and proved it
/// (found by review); every slope setting must now leave it unproven.
#[test]
fn an_underflowing_coefficient_times_a_huge_hidden_value_is_no_proof() {
    use ravel::ir::{NetProperty, NetPropertyKind};
    use ravel_analysis::sets::{IBox, Polytope, Region};
    use ravel_base::nn::{Activation, InputType, Layer, Network};
    let m = |r: usize, c: usize, v: &[f64]| nalgebra::DMatrix::from_row_slice(r, c, v);
    let relu = || Layer::Act(Activation::Relu);
    let net = Network::new(
        1,
        vec![
            Layer::Affine {
                w: m(2, 1, &[1.0, -1.0]),
                b: nalgebra::DVector::zeros(2),
            },
            relu(),
            Layer::Affine {
                w: m(1, 2, &[-1e15, -1e15]),
                b: nalgebra::DVector::from_element(1, 1e15),
            },
            relu(),
            Layer::Affine {
                w: m(1, 1, &[1e15]),
                b: nalgebra::DVector::zeros(1),
            },
            relu(),
            Layer::Affine {
                w: m(1, 1, &[0.7]),
                b: nalgebra::DVector::zeros(1),
            },
        ],
    )
    .with_input_type(InputType::F64);
    let eta = f64::from_bits(1);
    let b = 2.0 * eta * 0.7e30 * (1.0 - 1e-12);
    for steps in [0, 3, 20] {
        let mut plan = common::net_plan(
            net.clone(),
            Region::Box(IBox::new(vec![-1.0], vec![1.0])),
            vec![NetProperty {
                name: "r".into(),
                kind: NetPropertyKind::Require(Polytope {
                    rows: vec![(vec![2.0 * eta], b)],
                }),
            }],
        );
        plan.samples = 1000;
        plan.seed = 3;
        plan.slope_steps = steps;
        let out = common::run_net(&plan);
        assert_ne!(
            out.properties[0].status,
            Verdict::Verified,
            "{steps} slope steps: a false requirement verified"
        );
        let cert = common::net_certificate(&plan, &out);
        let a = ravel_certify::network::check(&cert, &net).answer;
        assert!(!matches!(a, Answer::Valid) || out.properties[0].status != Verdict::Verified);
    }
}
