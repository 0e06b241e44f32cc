//! Overflow never decides a verdict: on plants whose true states (and so
//! every sound bound) leave the range of `f64`, every propagator × boundary
//! × partitioner answers UNSURE and names the step where bounds overflowed;
//! it never reports VERIFIED for a false goal nor FALSIFIED from a
//! trajectory whose states are not numbers.

use std::path::Path;

use ravel::execute::{execute_system, Control, Verdict};
use ravel::lower::lower_system;
use ravel_analysis::closed_loop::{Cut, Propagator};

/// `x⁺ = 1e9·x + B u`: from `x[0] ∈ [1, 2]` the true states pass 1e300 at
/// step 34 and stay positive, so the goal (near the origin, at the horizon)
/// is false and the avoid set (`x[0] ≤ −1`) is never entered.
fn spec(propagator: &str, boundary: &str, partitioner: &str, horizon: usize) -> String {
    format!(
        r#"
system blowup {{
    state x[2]
    control u[1]
    A = [[1e9, 0], [0, 1e9]]
    B = [[0.5], [1]]
    u in box([-1, 1])
}}
controller "models/double_integrator.onnx"
initial X0 = box(x[0] in [1, 2], x[1] in [-0.25, 0.25])
goal G = box(x[0] in [-1.5, 2.0], x[1] in [-1.5, 0.5])
avoid negative = {{ x[0] <= -1 }}
horizon {horizon}
analysis {{
    propagator {propagator}
    partitioner {partitioner}
    boundary {boundary}
    samples 64
}}
"#
    )
}

fn run(src: &str) -> ravel::execute::SystemOutcome {
    let checked = ravel::front_end(
        src,
        Path::new(env!("CARGO_MANIFEST_DIR")),
        &ravel_cli::read_request,
    )
    .unwrap_or_else(|d| panic!("spec does not check: {d:?}\n{src}"));
    let plan = lower_system(&checked);
    execute_system(&plan, &Control::unlimited())
}

#[test]
fn every_method_answers_unsure_with_the_overflow_step() {
    let boundaries = ["box", "polytope 8", "hull"];
    let partitioners = [
        "none",
        "uniform [2, 2]",
        "gsg (calls 6)",
        "sg (calls 6)",
        "property (calls 6)",
    ];
    for prop in Propagator::ALL {
        for boundary in boundaries {
            for part in partitioners {
                // Reach-SDP solves an SDP per facet and step until the
                // overflow: one cell is enough for it (every partitioner's
                // overflow handling is the same code for every propagator)
                if prop == Propagator::ReachSdp && part != "none" {
                    continue;
                }
                let src = spec(prop.name(), boundary, part, 40);
                let out = run(&src);
                let what = format!("{} / {boundary} / {part}", prop.name());
                let (overflow, cause) = out
                    .cut
                    .unwrap_or_else(|| panic!("{what}: no overflow reported"));
                assert_eq!(cause, Cut::Overflow, "{what}");
                assert!(overflow <= 40, "{what}: overflow step {overflow}");
                for p in &out.properties {
                    assert_eq!(
                        p.status,
                        Verdict::Unsure,
                        "{what}: {} is {:?}",
                        p.name,
                        p.status
                    );
                    assert!(p.cut.is_some(), "{what}: {} names no overflow", p.name);
                    assert!(!p.margin.is_nan(), "{what}: NaN margin");
                }
                for (t, b) in out.reach.iter().enumerate() {
                    assert!(
                        b.lo.iter().chain(&b.hi).all(|v| !v.is_nan()),
                        "{what}: NaN bound at step {t}"
                    );
                }
            }
        }
    }
}

/// Before the overflow the same loop is falsified by a real trajectory (the
/// goal is checked at the horizon, which is still representable).
#[test]
fn a_goal_missed_before_the_overflow_is_still_falsified() {
    for prop in ["reach_lp", "crown_unrolled", "ibp_separate"] {
        let out = run(&spec(prop, "box", "none", 3));
        assert_eq!(out.cut, None, "{prop}");
        assert_eq!(out.properties[0].status, Verdict::Falsified, "{prop}");
        let tr = out.properties[0]
            .counterexample
            .as_ref()
            .expect("trajectory");
        assert!(tr.states.iter().flatten().all(|v| v.is_finite()));
    }
}

/// An avoid property whose steps all come before the overflow is still
/// proven; the goal at the horizon, after it, is not.
#[test]
fn properties_before_the_overflow_are_still_proven() {
    let src = spec("reach_lp", "box", "none", 40).replace(
        "avoid negative = { x[0] <= -1 }",
        "avoid negative = { x[0] <= -1 } at steps [1, 5]",
    );
    let out = run(&src);
    assert!(out.cut.is_some());
    let goal = &out.properties[0];
    let avoid = &out.properties[1];
    assert_eq!(goal.status, Verdict::Unsure);
    assert_eq!(avoid.status, Verdict::Verified, "{avoid:?}");
    assert_eq!(avoid.cut, None);
}

/// A time limit that is already spent stops every method soundly: no
/// samples, every step after the initial set is the whole space, every
/// property UNSURE naming the time limit.
#[test]
fn a_spent_time_limit_leaves_everything_unsure() {
    use ravel::execute::{execute_system, Control};
    let src = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("specs/double_integrator.ravel"),
    )
    .expect("spec")
    .replace("\"../models/", "\"models/");
    for prop in Propagator::ALL {
        for part in [
            "none",
            "uniform [2, 2]",
            "gsg (calls 6)",
            "property (calls 6)",
        ] {
            let src = src
                .replace(
                    "propagator  reach_lp",
                    &format!("propagator {}", prop.name()),
                )
                .replace("partitioner none", &format!("partitioner {part}"));
            let checked = ravel::front_end(
                &src,
                Path::new(env!("CARGO_MANIFEST_DIR")),
                &ravel_cli::read_request,
            )
            .expect("valid");
            let plan = lower_system(&checked);
            let out = execute_system(
                &plan,
                &Control {
                    elapsed: &|| 1.0,
                    time_limit: Some(0.5),
                    progress: &|_| {},
                    threads: 2,
                },
            );
            let what = format!("{} / {part}", prop.name());
            assert_eq!(out.samples_drawn, 0, "{what}");
            assert_eq!(out.cut, Some((1, Cut::TimeLimit)), "{what}");
            for p in &out.properties {
                assert_eq!(p.status, Verdict::Unsure, "{what}: {}", p.name);
                assert_eq!(p.cut.map(|c| c.1), Some(Cut::TimeLimit), "{what}");
            }
            let text = ravel::report::system::text("s", &plan, &out, None);
            assert!(text.contains("time limit"), "{text}");
        }
    }
}

/// The rigorous replay behind FALSIFIED refuses what is not a real
/// counterexample: the counterexample of the falsified spec is confirmed,
/// but not once its initial state leaves X0 or a noise value leaves its box,
/// and never for a property the trajectory satisfies.
#[test]
fn counterexamples_are_confirmed_only_when_real() {
    use ravel::execute::certainly_violates;
    let src = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("specs/double_integrator_falsified.ravel"),
    )
    .expect("spec")
    .replace("\"../models/", "\"models/");
    let checked = ravel::front_end(
        &src,
        Path::new(env!("CARGO_MANIFEST_DIR")),
        &ravel_cli::read_request,
    )
    .expect("valid");
    let plan = lower_system(&checked);
    let out = execute_system(&plan, &Control::unlimited());
    let goal = &out.properties[0];
    assert_eq!(goal.status, Verdict::Falsified);
    let tr = goal.counterexample.clone().expect("trajectory");
    let prop = &plan.properties[0];
    assert!(certainly_violates(&plan, &tr, prop, goal.step));
    // the start moved just outside X0 (x[0] ∈ [2.5, 3])
    let mut outside = tr.clone();
    outside.states[0][0] = 3.5;
    assert!(!certainly_violates(&plan, &outside, prop, goal.step));
    // a process-noise value outside W = {0}
    let mut noisy = tr.clone();
    noisy.process_noise[0][0] = 1e-3;
    assert!(!certainly_violates(&plan, &noisy, prop, goal.step));
    // the avoid set is never entered by this trajectory
    let avoid = &plan.properties[1];
    for t in 1..=plan.horizon {
        assert!(
            !certainly_violates(&plan, &tr, avoid, t),
            "avoid at step {t}"
        );
    }
}
