//! VNN-LIB import: hand-written property files of every supported shape are
//! translated into network specs that check against the model, state the
//! same sets (compared row by row), and get the expected verdicts; files
//! outside the supported fragment are refused with their line.

use ravel::check::Task;
use ravel::execute::network::execute_network;
use ravel::execute::Control;
use ravel::ir::NetPropertyKind;
use ravel_analysis::sets::Region;
use std::path::Path;

const DIR: &str = "tests/data/vnnlib";

fn import(name: &str) -> Result<String, ravel::vnnlib::ImportError> {
    let text =
        std::fs::read_to_string(Path::new(DIR).join(format!("{name}.vnnlib"))).expect("file");
    ravel::vnnlib::import(&text, "../../../models/classifier.onnx", name, name)
}

fn run(
    name: &str,
) -> (
    ravel::lower::NetworkPlan,
    ravel::execute::network::NetworkOutcome,
) {
    let spec = import(name).expect("imports");
    let task = ravel::front_end_task(&spec, Path::new(DIR), &ravel_cli::read_request, None)
        .unwrap_or_else(|d| panic!("{name}: the imported spec does not check: {d:?}\n{spec}"));
    let Task::Network(c) = task else {
        panic!("{name}: not a network spec")
    };
    let plan = ravel::lower::lower_network(&c);
    let out = execute_network(
        &plan,
        &Control {
            elapsed: &|| 0.0,
            time_limit: None,
            progress: &|_| {},
            threads: 1,
        },
    );
    (plan, out)
}

/// The avoid members as (row, rhs) lists.
fn members(plan: &ravel::lower::NetworkPlan) -> Vec<Vec<(Vec<f64>, f64)>> {
    match &plan.properties[0].kind {
        NetPropertyKind::Avoid(m) => m.iter().map(|p| p.rows.clone()).collect(),
        other => panic!("not an avoid set: {other:?}"),
    }
}

#[test]
fn robustness_disjunction_becomes_a_union() {
    let (plan, out) = run("robust_box");
    assert_eq!(
        members(&plan),
        vec![
            vec![(vec![1.0, -1.0, 0.0], 0.0)],
            vec![(vec![1.0, 0.0, -1.0], 0.0)],
        ]
    );
    assert_eq!(
        plan.input,
        Some(Region::Box(ravel_analysis::sets::IBox::new(
            vec![0.55, 0.25],
            vec![0.65, 0.35]
        )))
    );
    assert_eq!(out.verdict.as_str(), "VERIFIED");
}

#[test]
fn conjunction_with_coefficients_and_strict_comparisons() {
    let spec = import("threshold_conjunction").expect("imports");
    assert!(spec.contains("read as non-strict"), "{spec}");
    let (plan, out) = run("threshold_conjunction");
    assert_eq!(
        members(&plan),
        vec![vec![
            (vec![0.0, -1.0, 1.0], -0.5),
            (vec![1.0, -2.0, 0.0], -1.5)
        ]]
    );
    // the box lies in sector 1, where both unsafe inequalities hold
    assert_eq!(out.verdict.as_str(), "FALSIFIED");
    let w = out.properties[0].counterexample.as_ref().expect("witness");
    assert!(-w.output[1] + w.output[2] <= -0.5 && w.output[0] - 2.0 * w.output[1] <= -1.5);
}

#[test]
fn polytope_inputs_stay_a_polytope() {
    let (plan, out) = run("polytope_input");
    let Some(Region::Polytope { rows, bbox }) = &plan.input else {
        panic!("not a polytope: {:?}", plan.input)
    };
    // the row x0 + x1 <= 0.9, possibly scaled
    assert!(
        rows.iter()
            .any(|(a, h)| a[0] > 0.0 && a[0] == a[1] && (h / a[0] - 0.9).abs() < 1e-12),
        "{rows:?}"
    );
    assert!(
        bbox.contains_point(&[0.5, 0.1]) && bbox.contains_point(&[0.8, 0.1]),
        "{bbox:?}"
    );
    assert_eq!(members(&plan).len(), 2);
    assert_ne!(out.verdict.as_str(), "FALSIFIED");
}

#[test]
fn unsupported_constructs_are_refused_with_their_line() {
    for (name, line, what) in [
        ("mixed", 7, "inputs and outputs"),
        ("input_disjunction", 6, "disjunctions involving inputs"),
        ("nonlinear", 7, "not linear"),
        ("gap", 2, "without gaps"),
    ] {
        let e = import(name).expect_err(name);
        assert_eq!(e.line, line, "{name}: {e:?}");
        assert!(e.message.contains(what), "{name}: {e:?}");
    }
    for (text, what) in [
        ("(declare-const X_0 Int)", "only Real"),
        (
            "(declare-const X_0 Real) (assert (<= X_0 1)",
            "never closed",
        ),
        ("(declare-const X_0 Real))", "without a matching"),
        ("(check-sat)", "not supported"),
        (
            "(declare-const X_0 Real)(declare-const Y_0 Real)(assert (<= X_0 1))",
            "no constraint on the outputs",
        ),
        (
            "(declare-const X_0 Real)(declare-const Y_0 Real)(assert (<= Y_0 1))",
            "not bounded",
        ),
        (
            "(declare-const X_0 Real)(declare-const Y_0 Real)(assert (<= X_0 1e999))",
            "neither a number",
        ),
    ] {
        let e = ravel::vnnlib::import(text, "m.onnx", "n", "t").expect_err(text);
        assert!(e.message.contains(what), "{text}: {e:?}");
    }
    // deep nesting and control characters: refused, printed safely
    let deep = format!("{}{}", "(".repeat(200), ")".repeat(200));
    assert!(ravel::vnnlib::import(&deep, "m", "n", "t").is_err());
    let e = ravel::vnnlib::import("(declare-const \u{1b}[31mX Real)", "m", "n", "t")
        .expect_err("escape");
    assert!(!e.message.contains('\u{1b}'), "{e:?}");
}

/// VNN-LIB bounds are decimals that float32 models cannot take as they are
/// (as in VNN-COMP 2021, where some counterexamples in the box in float64
/// left it once cast to float32): the counterexample is a float32 input
/// inside the box; a box holding no float32 is never FALSIFIED.
#[test]
fn counterexamples_are_float32_inputs_of_the_box() {
    let property = |lo: &str, hi: &str| {
        format!(
            "(declare-const X_0 Real)\n(declare-const X_1 Real)\n(declare-const Y_0 Real)\n\
             (declare-const Y_1 Real)\n(declare-const Y_2 Real)\n\
             (assert (and (<= X_0 {hi}) (>= X_0 {lo}) (<= X_1 {hi}) (>= X_1 {lo})))\n\
             (assert (> (+ Y_1 (* -1.0 Y_2)) 0.5))\n(assert (< (- Y_0 (* 2 Y_1)) -1.5))\n"
        )
    };
    let verify = |text: &str| {
        let spec = ravel::vnnlib::import(text, "../../../models/classifier.onnx", "f", "f")
            .expect("imports");
        let task = ravel::front_end_task(&spec, Path::new(DIR), &ravel_cli::read_request, None)
            .unwrap_or_else(|d| panic!("the imported spec does not check: {d:?}\n{spec}"));
        let Task::Network(c) = task else {
            panic!("not a network spec")
        };
        let plan = ravel::lower::lower_network(&c);
        let ctl = Control {
            elapsed: &|| 0.0,
            time_limit: None,
            progress: &|_| {},
            threads: 1,
        };
        execute_network(&plan, &ctl)
    };
    // [-0.30000003, -0.30000001] holds one float32, -0.30000001192…
    let out = verify(&property("-0.30000003", "-0.30000001"));
    assert_eq!(out.verdict.as_str(), "FALSIFIED");
    let w = out.properties[0].counterexample.as_ref().expect("witness");
    let only = f64::from(-0.3f32);
    assert_eq!(w.input, vec![only, only]);
    // [-0.30000004, -0.30000002] holds none: violated in real arithmetic only
    let out = verify(&property("-0.30000004", "-0.30000002"));
    assert_eq!(out.verdict.as_str(), "UNSURE");
    assert!(out.properties[0].real_only.is_some());
}
