//! Certificates of nonlinear plants: the checker re-derives every claimed
//! step with its own validated integration. A valid certificate is VALID;
//! any claim made smaller than the true reachable set needs (a fresh
//! symbol shrunk, a centre moved, a cell dropped, a symbol made
//! non-axis-aligned), a forged counterexample or a hostile number is
//! rejected — never VALID.

use ravel_certify::Answer;
use serde_json::Value;

mod common;
use common::{system_answer as answer, system_certificate as run};

fn not_valid(cert: &Value, plan: &ravel::lower::SystemPlan, what: &str) -> Answer {
    let a = answer(cert, plan);
    assert!(
        matches!(a, Answer::Invalid(_) | Answer::Unreadable(_)),
        "{what}: expected INVALID or UNREADABLE, got {a:?}"
    );
    a
}

/// The index of the certificate's (first) avoid property.
fn avoid_property(cert: &Value) -> usize {
    cert["problem"]["properties"]
        .as_array()
        .expect("properties")
        .iter()
        .position(|p| p["kind"] == "avoid")
        .expect("an avoid property")
}

/// The index of the certificate's (first) FALSIFIED verdict.
fn falsified(cert: &Value) -> usize {
    cert["verdicts"]
        .as_array()
        .expect("verdicts")
        .iter()
        .position(|v| v["status"] == "FALSIFIED")
        .expect("a falsified property")
}

/// The fresh columns of a claim (ids not in the previous step's claim),
/// with their one non-zero row.
fn fresh_columns(cert: &Value, cell: usize, step: usize) -> Vec<(usize, usize)> {
    let claims = &cert["evidence"]["cells"][cell]["claims"];
    let prev: Vec<u64> = if step == 0 {
        Vec::new()
    } else {
        claims[step - 1]["ids"]
            .as_array()
            .expect("ids")
            .iter()
            .map(|v| v.as_u64().expect("id"))
            .collect()
    };
    let claim = &claims[step];
    let mut out = Vec::new();
    for (j, id) in claim["ids"].as_array().expect("ids").iter().enumerate() {
        if prev.contains(&id.as_u64().expect("id")) {
            continue;
        }
        for (i, row) in claim["g"].as_array().expect("g").iter().enumerate() {
            if row[j].as_f64().expect("number") != 0.0 {
                out.push((i, j));
            }
        }
    }
    out
}

#[test]
fn valid_nonlinear_certificates_are_valid() {
    for spec in [
        "specs/damped_pendulum.ravel",
        "specs/double_integrator_ode.ravel",
        "benchmarks/reachnn_b2.ravel",
    ] {
        let (plan, cert) = run(spec);
        assert_eq!(cert["evidence"]["status"], "checkable", "{spec}");
        assert_eq!(answer(&cert, &plan), Answer::Valid, "{spec}");
    }
}

/// A state that stays exactly 0 has no scale for the writer's relative
/// widening, while the checker's roundings cost the smallest normal number
/// each: the writer's absolute floor makes its certificate VALID (without
/// it, UNSUPPORTED: QUAD's yaw rate).
#[test]
fn a_state_that_stays_zero_is_certified() {
    let (plan, cert) = run("tests/data/zero_state.ravel");
    assert_eq!(cert["evidence"]["status"], "checkable");
    assert_eq!(answer(&cert, &plan), Answer::Valid);
}

#[test]
fn shrunk_claims_are_rejected() {
    let (plan, cert) = run("specs/damped_pendulum.ravel");
    let steps = cert["evidence"]["steps"].as_u64().expect("steps") as usize;
    let mut tried = 0;
    for step in [1, steps / 2, steps] {
        // every fresh symbol of a claim is a remainder (or a merged box):
        // the room the next step needs; shrinking them all by a tenth of
        // the margin the writer added leaves no room for the true set
        let inflation = cert["evidence"]["inflation"].as_f64().expect("inflation");
        let mut bad = cert.clone();
        for (i, j) in fresh_columns(&cert, 0, step) {
            let v = &mut bad["evidence"]["cells"][0]["claims"][step]["g"][i][j];
            let x = v.as_f64().expect("number");
            *v = Value::from(x / (1.0 + inflation) * 0.5);
        }
        not_valid(&bad, &plan, &format!("fresh symbols of step {step} halved"));
        tried += 1;
    }
    assert_eq!(tried, 3);
}

#[test]
fn moved_centres_and_tilted_symbols_are_rejected() {
    let (plan, cert) = run("specs/damped_pendulum.ravel");
    // a centre moved by a whole radius of its component
    let mut bad = cert.clone();
    let claim = &cert["evidence"]["cells"][0]["claims"][2];
    let radius: f64 = claim["g"][0]
        .as_array()
        .expect("row")
        .iter()
        .map(|v| v.as_f64().expect("number").abs())
        .sum();
    let c = claim["c"][0].as_f64().expect("number");
    bad["evidence"]["cells"][0]["claims"][2]["c"][0] = Value::from(c + radius);
    not_valid(&bad, &plan, "centre moved");
    // a fresh symbol made to act on two components
    let mut bad = cert.clone();
    let (i, j) = fresh_columns(&cert, 0, 3)[0];
    let other = 1 - i;
    bad["evidence"]["cells"][0]["claims"][3]["g"][other][j] = Value::from(1e-3);
    match not_valid(&bad, &plan, "tilted fresh symbol") {
        Answer::Invalid(m) => assert!(m.contains("axis-aligned"), "{m}"),
        other => panic!("{other:?}"),
    }
    // a kept symbol's coefficient changed
    let mut bad = cert.clone();
    let g = &mut bad["evidence"]["cells"][0]["claims"][3]["g"][0][0];
    let x = g.as_f64().expect("number");
    *g = Value::from(x + 0.5 * (x.abs() + 0.01));
    not_valid(&bad, &plan, "kept coefficient changed");
    // an id named twice is unreadable
    let mut bad = cert.clone();
    let ids = bad["evidence"]["cells"][0]["claims"][1]["ids"]
        .as_array_mut()
        .expect("ids");
    let first = ids[0].clone();
    ids[1] = first;
    assert!(matches!(answer(&bad, &plan), Answer::Unreadable(_)));
}

#[test]
fn dropped_cells_and_short_chains_are_rejected() {
    let (plan, cert) = run("benchmarks/reachnn_b2.ravel");
    let mut bad = cert.clone();
    bad["evidence"]["cells"]
        .as_array_mut()
        .expect("cells")
        .pop();
    match not_valid(&bad, &plan, "a cell dropped") {
        Answer::Invalid(m) => assert!(m.contains("cover"), "{m}"),
        other => panic!("{other:?}"),
    }
    let mut bad = cert.clone();
    bad["evidence"]["steps"] = Value::from(3);
    not_valid(&bad, &plan, "fewer steps than the goal needs");
}

#[test]
fn hostile_numbers_are_unreadable() {
    let (plan, cert) = run("specs/damped_pendulum.ravel");
    for (pointer, v) in [
        ("/evidence/cells/0/claims/1/c/0", Value::from(f64::MAX)),
        ("/evidence/cells/0/claims/1/g/0/0", Value::from("NaN")),
        ("/evidence/cells/0/claims/1/ids/0", Value::from(-1)),
        ("/problem/tape/0", Value::from("bogus")),
        ("/evidence/cells/0/claims/1/g", Value::from(vec![1.0])),
    ] {
        let mut bad = cert.clone();
        *bad.pointer_mut(pointer).expect("pointer") = v;
        not_valid(&bad, &plan, pointer);
    }
    // a huge claim is readable and proves nothing it should not: it is
    // VALID only if every property still holds on it, which a goal cannot
    let mut bad = cert.clone();
    let steps = bad["evidence"]["steps"].as_u64().expect("steps") as usize;
    for (i, j) in fresh_columns(&cert, 0, steps) {
        bad["evidence"]["cells"][0]["claims"][steps]["g"][i][j] = Value::from(1e300);
    }
    not_valid(&bad, &plan, "a huge final claim");
}

#[test]
fn counterexamples_are_replayed_by_the_checkers_own_integration() {
    let (plan, cert) = run("specs/pendulum_discrete_falsified.ravel");
    assert_eq!(answer(&cert, &plan), Answer::Valid);
    let i = falsified(&cert);
    // another step: the trajectory does not violate there
    let mut bad = cert.clone();
    bad["verdicts"][i]["step"] = Value::from(0);
    not_valid(&bad, &plan, "step 0 named");
    // an initial state outside X0
    let mut bad = cert.clone();
    bad["verdicts"][i]["trajectory"]["initial"][0] = Value::from(1e3);
    not_valid(&bad, &plan, "initial state outside X0");
}

/// A counterexample that violates its avoid set only between two instants
/// is replayed on the checker's own pieces of that period: VALID as
/// written, never VALID when it claims another period, the instant instead
/// of the period, or a start outside X0.
#[test]
fn counterexamples_between_the_instants_are_replayed_on_pieces() {
    let (plan, cert) = run("specs/oscillator_between_falsified.ravel");
    let i = falsified(&cert);
    assert_eq!(cert["verdicts"][i]["between"], true);
    assert_eq!(answer(&cert, &plan), Answer::Valid);
    let step = cert["verdicts"][i]["step"].as_u64().expect("step");
    let j = avoid_property(&cert);
    // the instant that ends the period: x0 is back near 0 there
    let mut bad = cert.clone();
    bad["verdicts"][i]["between"] = Value::from(false);
    not_valid(&bad, &plan, "the instant instead of the period");
    // step 0 ends no period
    let mut bad = cert.clone();
    bad["verdicts"][i]["step"] = Value::from(0);
    not_valid(&bad, &plan, "period 0 named");
    // a period after the window (horizon 3)
    let mut bad = cert.clone();
    bad["verdicts"][i]["step"] = Value::from(step + 10);
    not_valid(&bad, &plan, "a period past the horizon");
    // a start outside X0
    let mut bad = cert.clone();
    bad["verdicts"][i]["trajectory"]["initial"][1] = Value::from(1.0);
    not_valid(&bad, &plan, "initial state outside X0");
    // a window in seconds ending inside the period (`during [0, 0.5]`:
    // instant 0, period 1): the violation may lie after its end
    let mut bad = cert.clone();
    bad["problem"]["properties"][j]["steps"] = serde_json::json!({ "first": 0, "last": 0 });
    bad["problem"]["properties"][j]["periods"] = serde_json::json!({ "first": 1, "last": 1 });
    bad["verdicts"][i]["step"] = Value::from(1);
    not_valid(&bad, &plan, "a period the window ends inside");
    // x0 ≥ 0.9: the swing (about 0.8) never reaches it
    let mut bad = cert.clone();
    bad["problem"]["properties"][j]["members"][0] =
        serde_json::json!([{ "a": [-1.0, 0.0], "b": -0.9 }]);
    not_valid(&bad, &plan, "a set the trajectory does not reach");
    // `between` must be a boolean
    let mut bad = cert.clone();
    bad["verdicts"][i]["between"] = Value::from(1);
    assert!(matches!(answer(&bad, &plan), Answer::Unreadable(_)));
}

/// A counterexample to an "eventually" goal of a continuous-time plant is
/// replayed over every period of the window, not only at the instants:
/// VALID as written (x0 never reaches 0.9), never VALID for a goal the
/// trajectory reaches only between the instants (x0 ≥ 0.5: near 0 at every
/// instant, about 0.8 inside every period).
#[test]
fn eventually_counterexamples_are_replayed_between_the_instants() {
    let (plan, cert) = run("specs/oscillator_eventually_falsified.ravel");
    let i = falsified(&cert);
    assert_eq!(answer(&cert, &plan), Answer::Valid);
    assert_eq!(cert["problem"]["properties"][0]["mode"], "eventually");
    let mut bad = cert.clone();
    bad["problem"]["properties"][0]["rows"] = serde_json::json!([{ "a": [-1.0, 0.0], "b": -0.5 }]);
    not_valid(&bad, &plan, "a goal reached only between the instants");
    // the same goal, only the last period's second half in the window
    // (`during [0, 2.5]`: instants 0 … 2, periods 1 … 3): still reached
    let mut bad = bad.clone();
    bad["problem"]["properties"][0]["steps"] = serde_json::json!({ "first": 0, "last": 2 });
    bad["problem"]["properties"][0]["periods"] = serde_json::json!({ "first": 3, "last": 3 });
    bad["verdicts"][i]["step"] = Value::from(2);
    not_valid(
        &bad,
        &plan,
        "a goal reached in a period past the last instant",
    );
}

#[test]
fn linear_plants_in_continuous_time_are_checked_between_samples() {
    let (plan, cert) = run("specs/double_integrator_continuous.ravel");
    assert!(cert["problem"]["intersample"].is_object());
    assert_eq!(answer(&cert, &plan), Answer::Valid);
    let i = avoid_property(&cert);
    // x[0] ≤ −0.56: clear of every set at the instants (they reach −0.538),
    // not of the states between the instants (they reach −0.579)
    let mut bad = cert.clone();
    bad["problem"]["properties"][i]["members"][0] =
        serde_json::json!([{ "a": [1.0, 0.0], "b": -0.56 }]);
    match answer(&bad, &plan) {
        Answer::Invalid(m) => assert!(m.contains("between steps"), "{m}"),
        other => panic!("expected INVALID, got {other:?}"),
    }
    // x[0] ≤ −1 is clear of both (the checker's own enclosures are a little
    // wider than the analysis's)
    let mut ok = cert.clone();
    ok["problem"]["properties"][i]["members"][0] =
        serde_json::json!([{ "a": [1.0, 0.0], "b": -1.0 }]);
    assert_eq!(answer(&ok, &plan), Answer::Valid);
}

/// A linear plant in continuous time: a counterexample that crosses its
/// avoid band only between two instants is replayed on the checker's own
/// pieces of that period (the linear plant's flow, its noise arriving at
/// the next instant): VALID as written, never VALID when it claims the
/// instant instead of the period, another period, a start outside X0, a
/// band the trajectory does not reach, or a plant in discrete time.
#[test]
fn linear_counterexamples_between_the_instants_are_replayed_on_pieces() {
    let (plan, cert) = run("specs/double_integrator_continuous_between.ravel");
    let i = falsified(&cert);
    assert_eq!(cert["verdicts"][i]["between"], true);
    assert_eq!(cert["verdicts"][i]["step"], 2);
    assert_eq!(answer(&cert, &plan), Answer::Valid);
    let j = avoid_property(&cert);
    let mut bad = cert.clone();
    bad["verdicts"][i]["between"] = Value::from(false);
    not_valid(&bad, &plan, "the instant instead of the period");
    for step in [0, 1, 3, 6] {
        let mut bad = cert.clone();
        bad["verdicts"][i]["step"] = Value::from(step);
        not_valid(&bad, &plan, &format!("period {step} named"));
    }
    let mut bad = cert.clone();
    bad["verdicts"][i]["trajectory"]["initial"][0] = Value::from(2.5);
    not_valid(&bad, &plan, "initial state outside X0");
    // the plant has no noise: any is outside its box, in the period's step
    // (the flow's sensor noise) or before it
    for (key, t) in [
        ("process_noise", 0),
        ("sensor_noise", 0),
        ("sensor_noise", 1),
    ] {
        let mut bad = cert.clone();
        bad["verdicts"][i]["trajectory"][key][t][1] = Value::from(0.01);
        not_valid(&bad, &plan, &format!("{key} at step {t} outside its box"));
    }
    // x0 in [3.0, 3.1]: never reached
    let mut bad = cert.clone();
    bad["problem"]["properties"][j]["members"][0] = serde_json::json!([
        { "a": [-1.0, 0.0], "b": -3.0 },
        { "a": [1.0, 0.0], "b": 3.1 }
    ]);
    not_valid(&bad, &plan, "a band the trajectory does not reach");
    // without its flow the problem is in discrete time: no period to
    // violate
    let mut bad = cert.clone();
    bad["problem"]
        .as_object_mut()
        .expect("problem")
        .remove("intersample");
    not_valid(&bad, &plan, "a plant in discrete time");
    let mut bad = cert.clone();
    bad["verdicts"][i]["between"] = Value::from("yes");
    assert!(matches!(answer(&bad, &plan), Answer::Unreadable(_)));
}

/// A linear plant in continuous time: a counterexample to an "eventually"
/// goal is replayed over every period of the window too. The recorded
/// trajectory's x0 is about 1.84, 0.91 and 0.34 at the window's instants
/// 1 to 3: a goal x0 ∈ [1.2, 1.4], which it crosses between instants 1
/// and 2, is missed at every instant and still not VALID; x0 ∈ [2.0, 2.2],
/// crossed before the window (between instants 0 and 1), is VALID.
#[test]
fn linear_eventually_counterexamples_are_replayed_between_the_instants() {
    let (plan, cert) = run("specs/double_integrator_eventually_falsified.ravel");
    assert!(cert["problem"]["intersample"].is_object());
    assert_eq!(answer(&cert, &plan), Answer::Valid);
    assert_eq!(cert["problem"]["properties"][0]["mode"], "eventually");
    let band = |lo: f64, hi: f64| serde_json::json!([{ "a": [1.0, 0.0], "b": hi }, { "a": [-1.0, 0.0], "b": -lo }]);
    let mut bad = cert.clone();
    bad["problem"]["properties"][0]["rows"] = band(1.2, 1.4);
    match answer(&bad, &plan) {
        Answer::Invalid(m) => assert!(m.contains("between steps 1 and 2"), "{m}"),
        other => panic!("expected INVALID, got {other:?}"),
    }
    let mut ok = cert.clone();
    ok["problem"]["properties"][0]["rows"] = band(2.0, 2.2);
    assert_eq!(answer(&ok, &plan), Answer::Valid);
    // the same band with the window from 0 s: its first period now counts
    ok["problem"]["properties"][0]["steps"] = serde_json::json!({ "first": 0, "last": 3 });
    ok["verdicts"][0]["step"] = Value::from(0);
    match answer(&ok, &plan) {
        Answer::Invalid(m) => assert!(m.contains("between steps 0 and 1"), "{m}"),
        other => panic!("expected INVALID, got {other:?}"),
    }
}

/// A window whose last control period ends after its last instant (a
/// window in seconds ending inside a period) needs evidence up to that
/// period's end: a chain that stops at the last instant is not VALID.
#[test]
fn evidence_must_reach_the_end_of_the_last_period() {
    let (plan, cert) = run("specs/double_integrator_continuous.ravel");
    let i = avoid_property(&cert);
    let mut bad = cert.clone();
    // instants 1..=4, periods 2..=5; the chain cut after step 4
    bad["problem"]["properties"][i]["steps"] = serde_json::json!({ "first": 1, "last": 4 });
    bad["problem"]["properties"][i]["periods"] = serde_json::json!({ "first": 2, "last": 5 });
    // the goal needs the horizon too: keep only the avoid property's claim
    let goal = cert["problem"]["properties"]
        .as_array()
        .expect("properties")
        .iter()
        .position(|p| p["kind"] == "goal")
        .expect("a goal");
    bad["verdicts"][goal]["status"] = serde_json::json!("UNSURE");
    bad["evidence"]["steps"] = serde_json::json!(4);
    for cell in bad["evidence"]["cells"].as_array_mut().expect("cells") {
        cell["steps"].as_array_mut().expect("steps").truncate(4);
    }
    let a = answer(&bad, &plan);
    assert!(
        matches!(a, Answer::Invalid(ref m) if m.contains("0..=5")),
        "{a:?}"
    );
}
