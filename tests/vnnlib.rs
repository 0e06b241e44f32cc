//! VNN-LIB import: hand-written property files of every supported shape are
//! translated into network specs that check against the model, state the
//! same sets (compared row by row), and get the expected verdicts; files
//! outside the supported fragment are refused with their line.

use ravel::check::Task;
use ravel::ir::NetPropertyKind;
use ravel_analysis::sets::Region;
use std::path::Path;

#[path = "common/binary.rs"]
mod binary;
mod common;

const DIR: &str = "tests/data/vnnlib";

fn import_all(name: &str) -> Result<Vec<String>, ravel::vnnlib::ImportError> {
    let text =
        std::fs::read_to_string(Path::new(DIR).join(format!("{name}.vnnlib"))).expect("file");
    ravel::vnnlib::import(&text, "../../../models/classifier.onnx", name, name)
}

/// A property of one input region: its spec.
fn import(name: &str) -> Result<String, ravel::vnnlib::ImportError> {
    import_all(name).map(|mut v| {
        assert_eq!(v.len(), 1, "{name}: one region");
        v.remove(0)
    })
}

fn run(
    name: &str,
) -> (
    ravel::lower::NetworkPlan,
    ravel::execute::network::NetworkOutcome,
) {
    run_spec(name, &import(name).expect("imports"))
}

fn run_spec(
    name: &str,
    spec: &str,
) -> (
    ravel::lower::NetworkPlan,
    ravel::execute::network::NetworkOutcome,
) {
    let task = ravel::front_end_task(spec, Path::new(DIR), &ravel_cli::read_request, None)
        .unwrap_or_else(|d| panic!("{name}: the imported spec does not check: {d:?}\n{spec}"));
    let Task::Network(c) = task else {
        panic!("{name}: not a network spec")
    };
    let plan = ravel::lower::lower_network(&c);
    let out = common::run_net(&plan);
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
            .expect("imports")
            .remove(0);
        let task = ravel::front_end_task(&spec, Path::new(DIR), &ravel_cli::read_request, None)
            .unwrap_or_else(|d| panic!("the imported spec does not check: {d:?}\n{spec}"));
        let Task::Network(c) = task else {
            panic!("not a network spec")
        };
        common::run_net(&ravel::lower::lower_network(&c))
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

/// An input disjunction is a union of input regions, one spec each (the
/// property holds only if every one is VERIFIED): here the first region is
/// safe (label 0) and the second is not (label 1 wins at 135°).
#[test]
fn input_disjunctions_become_one_spec_per_region() {
    let specs = import_all("input_disjunction").expect("imports");
    assert_eq!(specs.len(), 2);
    let boxes = [
        (vec![0.55, 0.25], vec![0.65, 0.35]),
        (vec![-0.35, 0.25], vec![-0.25, 0.35]),
    ];
    let mut verdicts = Vec::new();
    for (k, (spec, (lo, hi))) in specs.iter().zip(boxes).enumerate() {
        assert!(
            spec.contains(&format!("Input region {} of 2", k + 1)),
            "{spec}"
        );
        assert!(spec.contains("partitioner bab"), "{spec}");
        let (plan, out) = run_spec("input_disjunction", spec);
        assert_eq!(
            plan.input,
            Some(Region::Box(ravel_analysis::sets::IBox::new(
                lo.clone(),
                hi.clone()
            )))
        );
        assert_eq!(members(&plan), vec![vec![(vec![1.0, -1.0, 0.0], 0.0)]]);
        if let Some(w) = &out.properties[0].counterexample {
            assert!(w.input.iter().zip(&lo).all(|(x, l)| x >= l));
            assert!(w.input.iter().zip(&hi).all(|(x, h)| x <= h));
            assert!(w.output[1] >= w.output[0]);
        }
        verdicts.push(out.verdict.as_str());
    }
    assert_eq!(verdicts, ["VERIFIED", "FALSIFIED"]);
}

const DECLARE: &str = "(declare-const X_0 Real)\n(declare-const X_1 Real)\n\
     (declare-const Y_0 Real)\n(declare-const Y_1 Real)\n(declare-const Y_2 Real)\n";

fn import_text(body: &str) -> Result<Vec<String>, ravel::vnnlib::ImportError> {
    ravel::vnnlib::import(
        &format!("{DECLARE}{body}"),
        "../../../models/classifier.onnx",
        "p",
        "p",
    )
}

/// The form of VNN-COMP 2022 and later: one `or` of `and`s, each with the
/// input box and output constraints. Disjuncts with the same input
/// constraints are one region (its avoid set the union of their output
/// parts); a single disjunct is the plain property.
#[test]
fn disjuncts_with_inputs_and_outputs_group_by_region() {
    let boxed =
        |y: &str| format!("(and (>= X_0 0.55) (<= X_0 0.65) (>= X_1 0.25) (<= X_1 0.35) {y})");
    // the robustness property of robust_box.vnnlib, written as two disjuncts
    let specs = import_text(&format!(
        "(assert (or {} {}))",
        boxed("(>= Y_1 Y_0)"),
        boxed("(>= Y_2 Y_0)")
    ))
    .expect("imports");
    assert_eq!(specs.len(), 1);
    let (plan, out) = run_spec("grouped", &specs[0]);
    let (reference, _) = run("robust_box");
    assert_eq!(plan.input, reference.input);
    assert_eq!(members(&plan), members(&reference));
    assert_eq!(out.verdict.as_str(), "VERIFIED");
    assert!(!specs[0].contains("Input region"), "{}", specs[0]);

    // a single disjunct
    let specs = import_text(&format!("(assert (or {}))", boxed("(>= Y_1 Y_0)"))).expect("imports");
    assert_eq!(specs.len(), 1);
    let (plan, _) = run_spec("single", &specs[0]);
    assert_eq!(plan.input, reference.input);
    assert_eq!(members(&plan), vec![vec![(vec![1.0, -1.0, 0.0], 0.0)]]);

    // three disjuncts over two regions: the first two share their box
    let other = "(and (>= X_0 -0.35) (<= X_0 -0.25) (>= X_1 0.25) (<= X_1 0.35) (>= Y_2 Y_1))";
    let specs = import_text(&format!(
        "(assert (or {} {other} {}))",
        boxed("(>= Y_1 Y_0)"),
        boxed("(>= Y_2 Y_0)")
    ))
    .expect("imports");
    assert_eq!(specs.len(), 2);
    let (first, out) = run_spec("first", &specs[0]);
    assert_eq!(first.input, reference.input);
    assert_eq!(members(&first), members(&reference));
    assert_eq!(out.verdict.as_str(), "VERIFIED");
    let (second, out) = run_spec("second", &specs[1]);
    assert_eq!(members(&second), vec![vec![(vec![0.0, 1.0, -1.0], 0.0)]]);
    // at 135° label 1 wins over label 2: never reached
    assert_ne!(out.verdict.as_str(), "FALSIFIED");

    // a disjunct without output constraints would make every input of
    // its region a counterexample: refused
    let e = import_text(&format!(
        "(assert (or {} (and (>= X_0 0) (<= X_0 1) (>= X_1 0) (<= X_1 1))))",
        boxed("(>= Y_1 Y_0)")
    ))
    .expect_err("no outputs");
    assert!(e.message.contains("no constraint on the outputs"), "{e:?}");
}

/// A bound with a coefficient other than ±1 stays a polytope row (its
/// quotient would round and could lose a sliver of the region).
#[test]
fn scaled_bounds_stay_rows() {
    let specs = import_text(
        "(assert (and (>= X_0 0.5) (<= (* 3 X_0) 2) (>= X_1 0.25) (<= X_1 0.35)))\n\
         (assert (>= Y_1 Y_0))",
    )
    .expect("imports");
    let (plan, _) = run_spec("scaled", &specs[0]);
    let Some(Region::Polytope { rows, .. }) = &plan.input else {
        panic!("not a polytope: {:?}", plan.input)
    };
    assert!(
        rows.iter()
            .any(|(a, h)| a[0] > 0.0 && a[1] == 0.0 && *h / a[0] > 0.66),
        "{rows:?}"
    );
}

/// Through the binary: `import-vnnlib` writes one spec per region
/// (`FILE.1.ravel` …) and lists them; to standard output several specs
/// need `--output`; an unsupported construct is E0401 at its place.
#[test]
fn import_vnnlib_writes_one_file_per_region() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let classifier = root.join("models/classifier.onnx");
    let p = root.join("tests/data/vnnlib/input_disjunction.vnnlib");
    let d = binary::scratch("vnnlib", "regions");
    let s = |p: &Path| p.to_str().expect("utf-8 path").to_string();
    let ravel = |args: &[String]| {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        binary::ravel(&args)
    };
    let spec = d.join("prop.ravel");
    // import-vnnlib writes one spec per region and says so
    let (code, stdout, stderr) = ravel(&[
        "import-vnnlib".into(),
        s(&p),
        "--network".into(),
        s(&classifier),
        "--output".into(),
        s(&spec),
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("union of 2 regions"), "{stdout}");
    assert!(!spec.exists());
    for k in [1, 2] {
        let f = d.join(format!("prop.{k}.ravel"));
        let text = std::fs::read_to_string(&f).expect("region spec");
        assert!(text.contains("partitioner bab"), "{text}");
        let (code, _, stderr) = ravel(&["check".into(), s(&f)]);
        assert_eq!(code, 0, "{stderr}");
    }
    // to standard output, several specs need --output
    let (code, _, stderr) = ravel(&[
        "import-vnnlib".into(),
        s(&p),
        "--network".into(),
        s(&classifier),
    ]);
    assert_eq!(code, 2);
    assert!(stderr.contains("--output"), "{stderr}");

    // an unsupported construct: E0401 at its line and column
    let (code, _, stderr) = ravel(&[
        "import-vnnlib".into(),
        s(&root.join("tests/data/vnnlib/mixed.vnnlib")),
        "--network".into(),
        s(&classifier),
    ]);
    assert_eq!(code, 2);
    assert!(
        stderr.contains("E0401") && stderr.contains("mixed.vnnlib:7:9"),
        "{stderr}"
    );
}
