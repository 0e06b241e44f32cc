//! Counterexamples for the network as stored: a network spec's FALSIFIED
//! input is a value of the model's input type (float32 for a float32 model)
//! inside the input set, and the property is violated both by the model
//! evaluated in that precision and by the real-arithmetic network; when only
//! inputs between float32 values violate, the verdict is UNSURE. The
//! certificate checker replays inputs under the same rule with its own
//! float32 evaluation, and applies its documented limits (cells, coverage
//! work) as UNREADABLE. Closed-loop counterexamples are reported as the very
//! numbers that were confirmed: printed as JSON and read back, they are the
//! same bits and confirm again.

mod common;

use common::{net_certificate, run_net};
use nalgebra::{DMatrix, DVector};
use ravel::execute::network::Witness;
use ravel::execute::Verdict;
use ravel::ir::Partitioner;
use ravel::ir::{NetProperty, NetPropertyKind};
use ravel::lower::NetworkPlan;
use ravel_analysis::sets::{IBox, Polytope, Region};
use ravel_base::nn::{Activation, InputType, Layer, Network};
use ravel_certify::{check, Answer};
use serde_json::Value;

/// `y = w·x` on one input.
fn scale(w: f64) -> Network {
    Network::new(
        1,
        vec![Layer::Affine {
            w: DMatrix::from_row_slice(1, 1, &[w]),
            b: DVector::from_column_slice(&[0.0]),
        }],
    )
}

/// `require y <= h` over `x ∈ [lo, hi]`.
fn plan(net: Network, lo: f64, hi: f64, h: f64) -> NetworkPlan {
    let mut p = common::net_plan(
        net,
        Region::Box(IBox::new(vec![lo], vec![hi])),
        vec![NetProperty {
            name: "bounded".into(),
            kind: NetPropertyKind::Require(Polytope {
                rows: vec![(vec![1.0], h)],
            }),
        }],
    );
    p.seed = 3;
    p
}

fn invalid_because(answer: Answer, words: &str) {
    match answer {
        Answer::Invalid(m) => assert!(m.contains(words), "message `{m}` lacks `{words}`"),
        other => panic!("expected INVALID ({words}), got {other:?}"),
    }
}

/// The box's upper bound 0.3000003 is no float32: the nearest float32,
/// 0.30000030994…, lies above it. The property `y ≤ 0.3` is violated only
/// near the upper face. The f64 attack finds the face itself; the reported
/// input must be the largest float32 inside the box, 0.30000028014…, and
/// the float32 evaluation violates there by more than its error bound.
#[test]
fn a_counterexample_is_a_float32_input_inside_the_box() {
    let hi = 0.3000003;
    assert!(
        f64::from(hi as f32) > hi,
        "the upper bound rounds out of the box"
    );
    let p = plan(scale(1.0), 0.1, hi, 0.3);
    let out = run_net(&p);
    let r = &out.properties[0];
    assert_eq!(r.status, Verdict::Falsified);
    let x = r.counterexample.as_ref().expect("a counterexample").input[0];
    assert_eq!(
        x,
        f64::from((hi as f32).next_down()),
        "the float32 below the face"
    );
    assert!(InputType::F32.represents(x) && (0.1..=hi).contains(&x));
    let y = p.net.forward_stored(&[x]);
    assert!(y[0] > 0.3, "the float32 evaluation violates: {y:?}");
    // the checker replays it with its own float32 evaluation
    let cert = net_certificate(&p, &out);
    assert_eq!(check(&cert, &p.net).answer, Answer::Valid);
    // the face itself, in the box in f64 but not once cast to float32: INVALID
    let mut face = cert.clone();
    face["verdicts"][0]["input"] = serde_json::json!([hi]);
    invalid_because(check(&face, &p.net).answer, "not a float32 value");
    // a float64 model takes the face as it is
    let p64 = plan(scale(1.0).with_input_type(InputType::F64), 0.1, hi, 0.3);
    let mut face64 = face.clone();
    face64["verdicts"][0]["input"] = serde_json::json!([hi]);
    assert_eq!(check(&face64, &p64.net).answer, Answer::Valid);
}

/// `y ≤ 0.300000012` over `[0.1, 0.30000002]`: every violating input lies
/// in `(0.300000012, 0.30000002]`, which holds no float32 (0.30000001192…
/// is below it, 0.30000004172… above). Not VERIFIED (the real network
/// violates), not FALSIFIED (no float32 input does): UNSURE, and the report
/// says why.
#[test]
fn violations_only_between_float32_values_are_unsure() {
    let p = plan(scale(1.0), 0.1, 0.30000002, 0.300000012);
    let out = run_net(&p);
    let r = &out.properties[0];
    assert_eq!(r.status, Verdict::Unsure);
    assert!(r.counterexample.is_none());
    let real = r
        .real_only
        .as_ref()
        .expect("the real-only violation is named");
    assert!(real[0] > 0.300000012 && !InputType::F32.represents(real[0]));
    let text = ravel::report::network::text("t", &p, &out, None);
    assert!(
        text.contains("violates it in real arithmetic, but no float32 input"),
        "{text}"
    );
    // with a float64 input the same spec is FALSIFIED
    let p64 = plan(
        scale(1.0).with_input_type(InputType::F64),
        0.1,
        0.30000002,
        0.300000012,
    );
    assert_eq!(run_net(&p64).properties[0].status, Verdict::Falsified);
}

/// `y = (1 + 2⁻³⁰)·x` over `[0.5, 1]`, `y ≤ 1`: the real network violates at
/// `x = 1` (and only above `1 − 2⁻³⁰`, where 1 is the only float32), but
/// stored as float32 the weight is 1 and `y = x ≤ 1`. UNSURE for float32,
/// FALSIFIED for float64; a forged float32 certificate naming `x = 1` is
/// INVALID because the float32 evaluation does not violate.
#[test]
fn the_model_in_its_own_precision_must_violate() {
    let w = 1.0 + 2f64.powi(-30);
    let p = plan(scale(w), 0.5, 1.0, 1.0);
    let out = run_net(&p);
    assert_eq!(out.properties[0].status, Verdict::Unsure);
    assert_eq!(out.properties[0].real_only.as_deref(), Some(&[1.0][..]));
    let p64 = plan(scale(w).with_input_type(InputType::F64), 0.5, 1.0, 1.0);
    let out64 = run_net(&p64);
    assert_eq!(out64.properties[0].status, Verdict::Falsified);
    assert_eq!(
        out64.properties[0]
            .counterexample
            .as_ref()
            .map(|w| w.input.clone()),
        Some(vec![1.0])
    );
    // forge the float32 certificate: FALSIFIED at x = 1
    let mut forged = out.clone();
    forged.properties[0].status = Verdict::Falsified;
    forged.properties[0].counterexample = Some(Witness {
        input: vec![1.0],
        output: p.net.forward(&[1.0]),
    });
    let cert = net_certificate(&p, &forged);
    invalid_because(check(&cert, &p.net).answer, "evaluated in float32");
    // the same verdict for the float64 model replays
    assert_eq!(
        check(&net_certificate(&p64, &out64), &p64.net).answer,
        Answer::Valid
    );
}

/// The float32 evaluation's error bound matters, not only the fixed-order
/// result: `y = 2²⁴·x₀ − 2²⁴·x₁ + x₂` at `x = (1, 1, 1)` is 1 exactly and in
/// float32 in the fixed order (`2²⁴ − 2²⁴` first), but a runtime that adds
/// `2²⁴ + 1` first gets 0. `y ≤ 0.5` is violated by the real network and by
/// the fixed-order float32 evaluation, yet not by every float32
/// evaluation: not FALSIFIED.
#[test]
fn a_violation_within_the_float32_error_is_not_confirmed() {
    let big = 2f64.powi(24);
    let net = Network::new(
        3,
        vec![Layer::Affine {
            w: DMatrix::from_row_slice(1, 3, &[big, -big, 1.0]),
            b: DVector::from_column_slice(&[0.0]),
        }],
    );
    assert_eq!(net.forward_stored(&[1.0, 1.0, 1.0]), vec![1.0]);
    // another order, as a runtime may sum: (2²⁴ + 1) − 2²⁴ in float32
    let other = ((big as f32 + 1.0f32) - big as f32) as f64;
    assert_eq!(other, 0.0);
    let mut p = plan(net, 0.0, 0.0, 0.5);
    p.input = Some(Region::Box(IBox::new(vec![1.0; 3], vec![1.0; 3])));
    p.partitioner = Partitioner::Uniform(vec![1, 1, 1]);
    assert_eq!(run_net(&p).properties[0].status, Verdict::Unsure);
    // stored as float64 the error bound is far below the violation
    p.net = p.net.clone().with_input_type(InputType::F64);
    assert_eq!(run_net(&p).properties[0].status, Verdict::Falsified);
}

/// A certificate with one cell more than any analysis makes (100 000) is
/// UNREADABLE before its cells are looked at; 100 000 cells are checked.
#[test]
fn network_certificates_have_the_documented_cell_limit() {
    let p = plan(scale(1.0), 0.0, 1.0, 2.0);
    let out = run_net(&p);
    assert_eq!(out.properties[0].status, Verdict::Verified);
    let cert = net_certificate(&p, &out);
    assert_eq!(check(&cert, &p.net).answer, Answer::Valid);
    let cell = serde_json::json!({ "lo": [0.0], "hi": [1.0] });
    let mut at_limit = cert.clone();
    at_limit["evidence"]["cells"] = Value::Array(vec![cell.clone(); 100_000]);
    assert_eq!(check(&at_limit, &p.net).answer, Answer::Valid);
    let mut over = cert.clone();
    over["evidence"]["cells"] = Value::Array(vec![cell; 100_001]);
    match check(&over, &p.net).answer {
        Answer::Unreadable(m) => assert!(m.contains("100001 cells"), "{m}"),
        other => panic!("expected UNREADABLE, got {other:?}"),
    }
}

/// A closed-loop counterexample is reported as the numbers that were
/// confirmed: the JSON report's initial state and noise values, read back,
/// are the outcome's bit for bit, lie in their sets, and the trajectory
/// they start confirms again (the controller evaluated in exact real
/// arithmetic, enclosed).
#[test]
fn closed_loop_counterexamples_survive_json() {
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/specs/double_integrator_falsified.ravel"
    );
    let source = std::fs::read_to_string(spec).expect("spec readable");
    let dir = std::path::Path::new(spec).parent().expect("folder");
    let checked = ravel::front_end(&source, dir, &ravel_cli::read_request).expect("valid spec");
    let plan = ravel::lower::lower_system(&checked);
    let out = ravel::execute::execute_system(&plan, &ravel::execute::Control::unlimited());
    let json = ravel::report::system::json("s", &plan, &out, None);
    let text = serde_json::to_string(&json).expect("serialises");
    let back: Value = serde_json::from_str(&text).expect("parses");
    let mut falsified = 0;
    for (k, r) in out.properties.iter().enumerate() {
        let Some(tr) = &r.counterexample else {
            continue;
        };
        falsified += 1;
        let cex = &back["properties"][k]["counterexample"];
        let read = |key: &str| -> Vec<Vec<f64>> {
            serde_json::from_value(cex[key].clone()).expect("numbers")
        };
        let again = ravel::execute::Trajectory {
            states: read("states"),
            controls: read("controls"),
            process_noise: read("process_noise"),
            sensor_noise: read("sensor_noise"),
        };
        let bits =
            |v: &[Vec<f64>]| -> Vec<u64> { v.iter().flatten().map(|x| x.to_bits()).collect() };
        assert_eq!(bits(&again.states[..1]), bits(&tr.states[..1]));
        assert_eq!(bits(&again.process_noise), bits(&tr.process_noise));
        assert_eq!(bits(&again.sensor_noise), bits(&tr.sensor_noise));
        assert!(plan.initial.contains_point(&again.states[0]));
        assert!(ravel::execute::certainly_violates(
            &plan,
            &again,
            &plan.properties[k],
            r.step
        ));
    }
    assert!(falsified > 0, "the spec has a counterexample to check");
}

/// Every activation kind: the model's float32 evaluation (fixed order) of
/// random networks at float32 inputs satisfies what a FALSIFIED verdict
/// relies on — a property violated by the confirmed input is violated by
/// this evaluation (checked through the verdict: a FALSIFIED input's float32
/// output violates).
#[test]
fn falsified_inputs_violate_in_float32_for_every_activation() {
    let mut rng = ravel_base::rng::Rng::new(11);
    let mut seen = 0;
    for act in [Activation::Relu, Activation::Tanh, Activation::Sigmoid] {
        for case in 0..6 {
            let mut layers = Vec::new();
            let widths = [2, 5, 4, 1];
            for (k, pair) in widths.windows(2).enumerate() {
                layers.push(Layer::Affine {
                    w: DMatrix::from_fn(pair[1], pair[0], |_, _| rng.normal()),
                    b: DVector::from_fn(pair[1], |_, _| 0.3 * rng.normal()),
                });
                if k + 2 < widths.len() {
                    layers.push(Layer::Act(act));
                }
            }
            let net = Network::new(2, layers);
            let y0 = net.forward(&[0.0, 0.0])[0];
            let mut p = plan(net.clone(), 0.0, 0.0, y0);
            p.input = Some(Region::Box(IBox::new(vec![-1.0, -1.0], vec![1.0, 1.0])));
            p.partitioner = Partitioner::Uniform(vec![1, 1]);
            let out = run_net(&p);
            if let Some(w) = &out.properties[0].counterexample {
                seen += 1;
                assert!(w.input.iter().all(|v| InputType::F32.represents(*v)));
                let y = net.forward_stored(&w.input);
                assert!(
                    y[0] > y0,
                    "{act:?} case {case}: float32 output {y:?} ≤ {y0}"
                );
                assert_eq!(
                    check(&net_certificate(&p, &out), &net).answer,
                    Answer::Valid
                );
            }
        }
    }
    assert!(
        seen >= 10,
        "only {seen} counterexamples: the test checks little"
    );
}

/// The loader records the graph input's element type: float32 for a
/// `float` input (and when none is declared), float64 for `double`.
#[test]
fn the_loader_records_the_input_type() {
    use prost::Message;
    use ravel::onnx::build::{GraphBuilder, Storage};
    use ravel::onnx::proto::{dtype, ModelProto};
    let mut g = GraphBuilder::new(1, Storage::RawF64);
    g.network(&scale(0.5), false);
    let (bytes, _) = g.finish(1);
    let load = |bytes: &[u8]| {
        ravel::onnx::load(bytes, &Default::default())
            .expect("loads")
            .net
            .input_type
    };
    assert_eq!(load(&bytes), InputType::F32);
    let retyped = |t: Option<i32>| {
        let mut m = ModelProto::decode(bytes.as_slice()).expect("decodes");
        let graph = m.graph.as_mut().expect("graph");
        let tensor = graph.input[0]
            .r#type
            .as_mut()
            .and_then(|t| t.tensor_type.as_mut())
            .expect("a tensor input");
        tensor.elem_type = t;
        m.encode_to_vec()
    };
    assert_eq!(load(&retyped(Some(dtype::DOUBLE))), InputType::F64);
    assert_eq!(load(&retyped(None)), InputType::F32);
}

/// Through the command line: a float32 ONNX model, a spec whose box bound
/// is no float32, `verify --format json` reports the float32 input inside
/// the box, and `verify --certificate` then `certify` answer VALID.
#[test]
fn the_command_line_reports_float32_inputs() {
    use ravel::onnx::build::{GraphBuilder, Storage};
    let dir = std::env::temp_dir().join(format!("ravel-cex-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    let mut g = GraphBuilder::new(1, Storage::RawF32);
    g.network(&scale(1.0), false);
    std::fs::write(dir.join("model.onnx"), g.finish(1).0).expect("model written");
    let spec = dir.join("face.ravel");
    std::fs::write(
        &spec,
        "network face {\n    input  x[1]\n    output y[1]\n}\n\nmodel \"model.onnx\"\n\n\
         input X = box(x[0] in [0.1, 0.3000003])\n\nrequire low = { y[0] <= 0.3 }\n\n\
         analysis {\n    propagator  crown\n    partitioner uniform [1]\n    samples     100\n}\n",
    )
    .expect("spec written");
    let cert = dir.join("face.cert.json");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_ravel"))
        .args(["verify", "--format", "json", "--certificate"])
        .arg(&cert)
        .arg(&spec)
        .output()
        .expect("ravel runs");
    let v: Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let p = &v["results"][0]["properties"][0];
    assert_eq!(p["status"], "FALSIFIED", "{v}");
    let x = p["counterexample"]["input"][0].as_f64().expect("an input");
    assert_eq!(x, f64::from((0.3000003f64 as f32).next_down()));
    let check = std::process::Command::new(env!("CARGO_BIN_EXE_ravel"))
        .arg("certify")
        .arg(&cert)
        .output()
        .expect("ravel runs");
    let text = String::from_utf8_lossy(&check.stdout);
    assert!(check.status.success() && text.contains("VALID"), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The closed loop of a spec text (in `specs/`), executed.
fn run_system_text(text: &str) -> (ravel::lower::SystemPlan, ravel::execute::SystemOutcome) {
    let checked = ravel::front_end(
        text,
        std::path::Path::new("specs"),
        &ravel_cli::read_request,
    )
    .expect("valid spec");
    let plan = ravel::lower::lower_system(&checked);
    let outcome = ravel::execute::execute_system(&plan, &ravel::execute::Control::unlimited());
    (plan, outcome)
}

/// A simulated state inside a nonlinear avoid set falsifies it only
/// through confirmation: the validated enclosure of its trajectory must lie
/// wholly inside the set. A set that contains the simulated state but no
/// enclosure of it (a constraint defined at that one value only) is UNSURE,
/// never FALSIFIED; a tiny disc around the same state is FALSIFIED.
#[test]
fn a_nonlinear_avoid_set_is_entered_only_through_confirmation() {
    let text =
        std::fs::read_to_string("specs/double_integrator_disc_falsified.ravel").expect("spec");
    let (_, out) = run_system_text(&text);
    let p = &out.properties[0];
    assert_eq!(p.status, Verdict::Falsified);
    let tr = p.counterexample.as_ref().expect("a counterexample");
    let x = &tr.states[p.step];
    let (a, b) = (format!("{:?}", x[0]), format!("{:?}", x[1]));
    let avoid_line = text
        .lines()
        .find(|l| l.starts_with("avoid"))
        .expect("an avoid line");
    // defined only where x[0] equals the simulated value exactly: the f64
    // simulation is deep inside (depth 1), no enclosure of positive width is
    let only_there = format!(
        "avoid   puck = {{ sqrt(x[0] - {a}) + sqrt({a} - x[0]) <= 1 }} at step {}",
        p.step
    );
    let (_, out) = run_system_text(&text.replace(avoid_line, &only_there));
    assert_eq!(
        out.properties[0].status,
        Verdict::Unsure,
        "{:?}",
        out.properties[0]
    );
    // a disc of radius 10⁻³ around the simulated state: confirmed
    let tiny = format!(
        "avoid   puck = {{ (x[0] - {a})^2 + (x[1] - {b})^2 <= 1e-6 }} at step {}",
        p.step
    );
    let (plan, out) = run_system_text(&text.replace(avoid_line, &tiny));
    assert_eq!(out.properties[0].status, Verdict::Falsified);
    let tr = out.properties[0]
        .counterexample
        .as_ref()
        .expect("trajectory");
    assert!(ravel::execute::certainly_violates(
        &plan,
        tr,
        &plan.properties[0],
        out.properties[0].step
    ));
}

/// The search's counterexample with noise varied step by step (its second
/// stage re-simulates the trajectory's tail after each change) is a whole,
/// consistent trajectory: the loop simulated from its initial state with
/// its noise gives its states and controls bit for bit, every noise value
/// lies in its box, and the noise does change from step to step (constant
/// noise cannot reach this violation).
#[test]
fn searched_counterexamples_with_varying_noise_are_whole_trajectories() {
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/specs/rotation_noise_falsified.ravel"
    );
    let source = std::fs::read_to_string(spec).expect("spec readable");
    let dir = std::path::Path::new(spec).parent().expect("folder");
    let checked = ravel::front_end(&source, dir, &ravel_cli::read_request).expect("valid spec");
    let plan = ravel::lower::lower_system(&checked);
    let out = ravel::execute::execute_system(&plan, &ravel::execute::Control::unlimited());
    let r = &out.properties[0];
    assert_eq!(r.status, Verdict::Falsified);
    let tr = r.counterexample.as_ref().expect("a counterexample");
    let cl = &plan.closed_loop;
    assert_eq!(tr.states.len(), plan.horizon + 1);
    assert_eq!(tr.controls.len(), plan.horizon);
    assert_eq!(tr.process_noise.len(), plan.horizon);
    assert_eq!(tr.sensor_noise.len(), plan.horizon);
    let bits = |v: &[f64]| -> Vec<u64> { v.iter().map(|x| x.to_bits()).collect() };
    let mut x = tr.states[0].clone();
    for t in 0..plan.horizon {
        let (w, v) = (&tr.process_noise[t], &tr.sensor_noise[t]);
        assert!(
            cl.w().contains_point(w) && cl.v().contains_point(v),
            "step {t}"
        );
        let (u, next) = cl.simulate(t, &x, w, v);
        assert_eq!(bits(&u), bits(&tr.controls[t]), "control {t}");
        assert_eq!(bits(&next), bits(&tr.states[t + 1]), "state {}", t + 1);
        x = next;
    }
    assert!(tr.process_noise.windows(2).any(|p| p[0] != p[1]));
    assert!(ravel::execute::certainly_violates(
        &plan,
        tr,
        &plan.properties[0],
        r.step
    ));
}
