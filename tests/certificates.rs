//! Certificates: tampering is caught. Every single-number shrink of a
//! claimed set, a witness or a cell is rejected (the claims are exactly the
//! checker's bounds, so any shrink makes a claim unprovable); changed
//! plants, noise, goals, controller weights and dropped cells are rejected;
//! counterexamples that start outside X0, use noise outside its box or name
//! the wrong step are rejected. The command line: `verify --certificate`,
//! `certify` exit codes, changed files, hostile certificate files.

use std::path::Path;
use std::process::Command;

use ravel_base::nn::Layer;
use ravel_certify::{check, Answer};
use serde_json::Value;

#[path = "common/binary.rs"]
mod binary;
mod common;
use common::{system_answer as answer, system_certificate as run};

fn expect_invalid(cert: &Value, plan: &ravel::lower::SystemPlan, words: &str, what: &str) {
    match answer(cert, plan) {
        Answer::Invalid(m) => assert!(m.contains(words), "{what}: message `{m}` lacks `{words}`"),
        other => panic!("{what}: expected INVALID, got {other:?}"),
    }
}

/// Every number of the evidence, as a JSON pointer and whether it is an
/// upper end (`hi`) or a lower end (`lo`).
fn evidence_numbers(cert: &Value) -> Vec<(String, bool)> {
    let mut out = Vec::new();
    let cells = cert["evidence"]["cells"].as_array().expect("cells");
    for (c, cell) in cells.iter().enumerate() {
        let mut boxes = vec![format!("/evidence/cells/{c}/box")];
        for (k, st) in cell["steps"].as_array().expect("steps").iter().enumerate() {
            boxes.push(format!("/evidence/cells/{c}/steps/{k}/set"));
            let pre = st["preactivations"].as_array().expect("witness");
            for l in 0..pre.len() {
                boxes.push(format!("/evidence/cells/{c}/steps/{k}/preactivations/{l}"));
            }
        }
        for b in boxes {
            let v = cert.pointer(&b).expect("box");
            for (end, upper) in [("lo", false), ("hi", true)] {
                for i in 0..v[end].as_array().expect("array").len() {
                    out.push((format!("{b}/{end}/{i}"), upper));
                }
            }
        }
        // offsets of claimed polytope sets
        for (k, st) in cell["steps"].as_array().expect("steps").iter().enumerate() {
            for r in 0..st.get("rows").and_then(Value::as_array).map_or(0, Vec::len) {
                out.push((format!("/evidence/cells/{c}/steps/{k}/rows/{r}/b"), true));
            }
        }
    }
    out
}

#[test]
fn every_shrink_of_a_claim_is_rejected() {
    // one-step (box X0), unrolled (box X0), unrolled from a ball, hull
    // polytopes (offsets, with LP duals as witnesses)
    for spec in [
        "specs/double_integrator.ravel",
        "specs/double_integrator_unrolled.ravel",
        "specs/double_integrator_ball.ravel",
        "specs/double_integrator_hull.ravel",
    ] {
        every_shrink_rejected(spec);
    }
}

fn every_shrink_rejected(spec: &str) {
    let (plan, cert) = run(spec);
    assert_eq!(answer(&cert, &plan), Answer::Valid, "{spec}");
    let numbers = evidence_numbers(&cert);
    assert!(numbers.len() > 100, "{spec}: {} numbers", numbers.len());
    for (ptr, upper) in numbers {
        let mut bad = cert.clone();
        let v = bad.pointer(&ptr).and_then(Value::as_f64).expect("number");
        // claims are widened by 2⁻³⁶·(1 + |v|) for portability; a shrink by
        // twice that makes the claim tighter than the checker's bound
        let hair = 2.0 * (1.0 + v.abs()) / 68_719_476_736.0;
        let shrunk = if upper { v - hair } else { v + hair };
        *bad.pointer_mut(&ptr).expect("number") = serde_json::json!(shrunk);
        match answer(&bad, &plan) {
            Answer::Invalid(_) => {}
            other => panic!("{spec}: shrinking {ptr} ({v} → {shrunk}) was not rejected: {other:?}"),
        }
    }
}

#[test]
fn changed_problems_are_rejected() {
    let (plan, cert) = run("specs/double_integrator.ravel");
    let edits: &[(&str, f64)] = &[
        ("/problem/plants/0/A/0/1", 1e-3),
        ("/problem/plants/0/A/1/1", -1e-3),
        ("/problem/plants/0/B/0/0", 1e-3),
        ("/problem/plants/0/c/1", 1e-4),
        ("/problem/process_noise/hi/0", 1e-6),
        ("/problem/sensor_noise/lo/1", -1e-6),
        ("/problem/initial/box/hi/0", 1e-9),
        ("/problem/initial/box/lo/1", -1e-9),
    ];
    for (ptr, delta) in edits {
        let mut bad = cert.clone();
        let v = bad.pointer(ptr).and_then(Value::as_f64).expect("number");
        *bad.pointer_mut(ptr).expect("number") = serde_json::json!(v + delta);
        match answer(&bad, &plan) {
            Answer::Invalid(_) => {}
            other => panic!("changing {ptr} by {delta} was not rejected: {other:?}"),
        }
    }
    // a goal the final sets leave
    let mut bad = cert.clone();
    let last = &cert["evidence"]["cells"][0]["steps"][4]["set"];
    let top = last["hi"][0].as_f64().expect("number");
    bad["problem"]["properties"][0]["rows"][0]["b"] = serde_json::json!(top - 1e-6);
    expect_invalid(&bad, &plan, "leaves goal row 0", "shrunk goal");
    // an avoid set the sets reach
    let mut bad = cert.clone();
    let low = last["lo"][0].as_f64().expect("number");
    bad["problem"]["properties"][1]["members"][0][0]["b"] = serde_json::json!(-low + 1e-6);
    expect_invalid(&bad, &plan, "no inequality of member 0", "grown avoid set");
}

#[test]
fn a_changed_controller_weight_is_rejected() {
    let (plan, cert) = run("specs/double_integrator.ravel");
    // (layer, row, column or bias): entries that matter on this X0 (the
    // first hidden neuron of the second layer is inactive there, so its
    // outgoing weight may change without making any claim false)
    for (layer, row, col, delta) in [
        (0usize, 0, Some(0), 1e-4),
        (2, 1, Some(1), -1e-4),
        (4, 0, None, 1e-4),
    ] {
        let mut net = plan.closed_loop.net().clone();
        let Some(Layer::Affine { w, b }) = net.layers.get_mut(layer) else {
            panic!("layer {layer} is affine");
        };
        match col {
            Some(c) => w[(row, c)] += delta,
            None => b[row] += delta,
        }
        match check(&cert, &net).answer {
            Answer::Invalid(_) => {}
            other => panic!("change in layer {layer} not rejected: {other:?}"),
        }
    }
}

#[test]
fn partitions_must_cover_and_every_cell_face_matters() {
    let (plan, cert) = run("specs/double_integrator_partitioned.ravel");
    assert_eq!(answer(&cert, &plan), Answer::Valid);
    let cells = cert["evidence"]["cells"].as_array().expect("cells").len();
    assert_eq!(cells, 16);
    let mut bad = cert.clone();
    bad["evidence"]["cells"]
        .as_array_mut()
        .expect("cells")
        .remove(5);
    expect_invalid(&bad, &plan, "do not cover", "dropped cell");
    // shrinking any face of any cell (and re-deriving nothing) is rejected
    for c in 0..cells {
        for (end, sign) in [("lo", 1.0), ("hi", -1.0)] {
            for i in 0..2 {
                let mut bad = cert.clone();
                let b = &mut bad["evidence"]["cells"][c]["box"];
                let (lo, hi) = (
                    b["lo"][i].as_f64().unwrap_or(0.0),
                    b["hi"][i].as_f64().unwrap_or(0.0),
                );
                let v = b[end][i].as_f64().expect("number");
                b[end][i] = serde_json::json!(v + sign * 0.01 * (hi - lo));
                match answer(&bad, &plan) {
                    Answer::Invalid(_) => {}
                    other => panic!("cell {c} {end}[{i}] shrink not rejected: {other:?}"),
                }
            }
        }
    }
}

#[test]
fn counterexamples_are_replayed_not_trusted() {
    let (plan, cert) = run("specs/double_integrator_falsified.ravel");
    assert_eq!(answer(&cert, &plan), Answer::Valid);
    let tr = "/verdicts/0/trajectory";
    let mut bad = cert.clone();
    let x0 = bad
        .pointer(&format!("{tr}/initial/0"))
        .and_then(Value::as_f64)
        .expect("x0");
    *bad.pointer_mut(&format!("{tr}/initial/0")).expect("x0") = serde_json::json!(x0 - 1e-9);
    expect_invalid(
        &bad,
        &plan,
        "starts outside the initial set",
        "x0 outside X0",
    );
    let mut bad = cert.clone();
    *bad.pointer_mut(&format!("{tr}/process_noise/2/1"))
        .expect("w") = serde_json::json!(1e-12);
    expect_invalid(
        &bad,
        &plan,
        "process noise outside its box at step 2",
        "noise",
    );
    let mut bad = cert.clone();
    bad["verdicts"][0]["step"] = serde_json::json!(4);
    expect_invalid(&bad, &plan, "does not certainly violate", "wrong step");
}

#[test]
fn malformed_certificates_are_unreadable_not_valid() {
    let (plan, cert) = run("specs/double_integrator.ravel");
    type Edit = Box<dyn Fn(&mut Value)>;
    let cases: Vec<(&str, Edit)> = vec![
        (
            "format",
            Box::new(|c| c["format"] = serde_json::json!("ravel-certificate/99")),
        ),
        (
            "no problem",
            Box::new(|c| {
                c.as_object_mut().map(|o| o.remove("problem"));
            }),
        ),
        (
            "huge states",
            Box::new(|c| c["problem"]["states"] = serde_json::json!(1u64 << 40)),
        ),
        (
            "huge horizon",
            Box::new(|c| c["problem"]["horizon"] = serde_json::json!(u64::MAX)),
        ),
        (
            "string number",
            Box::new(|c| c["problem"]["plants"][0]["A"][0][0] = serde_json::json!("1")),
        ),
        (
            "short row",
            Box::new(|c| c["problem"]["plants"][0]["A"][0] = serde_json::json!([1.0])),
        ),
        (
            "verdict count",
            Box::new(|c| {
                c["verdicts"].as_array_mut().map(Vec::pop);
            }),
        ),
        (
            "status",
            Box::new(|c| c["verdicts"][0]["status"] = serde_json::json!("PROVEN")),
        ),
        (
            "steps",
            Box::new(|c| c["evidence"]["steps"] = serde_json::json!(3)),
        ),
        (
            "witness layers",
            Box::new(|c| {
                c["evidence"]["cells"][0]["steps"][0]["preactivations"]
                    .as_array_mut()
                    .map(Vec::pop);
            }),
        ),
        (
            "evidence status",
            Box::new(|c| c["evidence"]["status"] = serde_json::json!("trust me")),
        ),
    ];
    for (what, edit) in cases {
        let mut bad = cert.clone();
        edit(&mut bad);
        match answer(&bad, &plan) {
            Answer::Unreadable(_) | Answer::Invalid(_) => {}
            other => panic!("{what}: expected UNREADABLE or INVALID, got {other:?}"),
        }
    }
    // an UNSURE verdict turned VERIFIED with no evidence behind it
    let (plan, cert) = run("specs/double_integrator_ibp.ravel");
    let mut bad = cert.clone();
    bad["verdicts"][0]["status"] = serde_json::json!("VERIFIED");
    assert!(!matches!(answer(&bad, &plan), Answer::Valid));
}

fn ravel() -> Command {
    Command::new(env!("CARGO_BIN_EXE_ravel"))
}

fn tmp(name: &str) -> std::path::PathBuf {
    binary::scratch("ravel-cert", name)
}

#[test]
fn command_line_writes_and_checks_certificates() {
    let dir = tmp("cli");
    let cert = dir.join("di.cert.json");
    let st = ravel()
        .args([
            "verify",
            "specs/double_integrator.ravel",
            "--no-timing",
            "--certificate",
        ])
        .arg(&cert)
        .output()
        .expect("runs");
    assert_eq!(st.status.code(), Some(0));
    let ok = ravel().arg("certify").arg(&cert).output().expect("runs");
    let text = String::from_utf8_lossy(&ok.stdout);
    assert_eq!(ok.status.code(), Some(0), "{text}");
    assert!(text.starts_with("VALID"), "{text}");

    // a copy of the spec with one plant entry changed: the re-derived
    // problem differs, and the message names the first number that does
    let spec = std::fs::read_to_string("specs/double_integrator.ravel").expect("spec");
    let changed = spec.replacen("[0, 1]", "[0, 1.001]", 1);
    assert_ne!(changed, spec);
    let copy = Path::new("specs").join(format!("tmp-cert-{}.ravel", std::process::id()));
    std::fs::write(&copy, changed).expect("write");
    let bad = ravel()
        .arg("certify")
        .arg(&cert)
        .arg("--spec")
        .arg(&copy)
        .output()
        .expect("runs");
    let _ = std::fs::remove_file(&copy);
    assert_eq!(bad.status.code(), Some(1));
    let text = String::from_utf8_lossy(&bad.stdout);
    assert!(text.starts_with("INVALID"), "{text}");
    assert!(
        text.contains("`problem.plants[0].A[1][1]` differs"),
        "{text}"
    );
    assert!(text.contains("the spec's text differs"), "{text}");
    assert!(!text.contains("its problem is identical"), "{text}");

    // a different controller
    let other = ravel()
        .arg("certify")
        .arg(&cert)
        .args(["--controller", "models/double_integrator_tanh.onnx"])
        .output()
        .expect("runs");
    assert_ne!(other.status.code(), Some(0));

    // many results: a folder of certificates, one per pair
    let folder = dir.join("many");
    let st = ravel()
        .args([
            "verify",
            "specs/double_integrator.ravel",
            "specs/double_integrator_falsified.ravel",
            "--no-timing",
            "--certificate",
        ])
        .arg(&folder)
        .output()
        .expect("runs");
    assert_eq!(st.status.code(), Some(1));
    let all = ravel()
        .arg("certify")
        .arg(folder.join("double_integrator.cert.json"))
        .arg(folder.join("double_integrator_falsified.cert.json"))
        .output()
        .expect("runs");
    let text = String::from_utf8_lossy(&all.stdout);
    assert_eq!(all.status.code(), Some(0), "{text}");
    assert_eq!(text.matches("VALID").count(), 2, "{text}");

    // unsupported evidence: exit 2, never VALID
    let text = std::fs::read_to_string(&cert).expect("certificate");
    let mut v: Value = serde_json::from_str(&text).expect("json");
    v["evidence"] =
        serde_json::json!({ "status": "unsupported", "reason": "multipliers not recorded" });
    let un_path = dir.join("unsupported.cert.json");
    std::fs::write(&un_path, v.to_string()).expect("write");
    let un = ravel().arg("certify").arg(&un_path).output().expect("runs");
    assert_eq!(un.status.code(), Some(2));
    let text = String::from_utf8_lossy(&un.stdout);
    assert!(text.starts_with("UNSUPPORTED"), "{text}");
    assert!(text.contains("multipliers not recorded"), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn hostile_certificate_files_end_with_exit_2() {
    let dir = tmp("hostile");
    let not_json = dir.join("x.json");
    std::fs::write(&not_json, "{\"format\": ").expect("write");
    let deep = dir.join("deep.json");
    std::fs::write(&deep, "[".repeat(100_000)).expect("write");
    let empty = dir.join("empty.json");
    std::fs::write(&empty, "").expect("write");
    let wrong = dir.join("wrong.json");
    std::fs::write(&wrong, "{\"format\": \"ravel-certificate/1\", \"spec\": {\"path\": \"/dev/zero\"}, \"controller\": {\"path\": \"x\"}}").expect("write");
    for f in [
        not_json.as_path(),
        deep.as_path(),
        empty.as_path(),
        wrong.as_path(),
        Path::new("/dev/zero"),
        Path::new("/nonexistent/cert.json"),
        dir.as_path(),
    ] {
        let o = ravel().arg("certify").arg(f).output().expect("runs");
        assert_eq!(o.status.code(), Some(2), "{}", f.display());
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(text.starts_with("UNREADABLE"), "{}: {text}", f.display());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn dual_witnesses_cannot_prove_false_claims() {
    // duals only decide how tight a support is: replacing them with
    // nonsense (negative, huge, wrong length) keeps true claims or loses
    // them, but a claim shrunk below the checker's bound is never accepted
    let (plan, cert) = run("specs/double_integrator_hull.ravel");
    assert_eq!(answer(&cert, &plan), Answer::Valid);
    let garbage = [
        serde_json::json!([-1.0, 1e300, 0.0]),
        serde_json::json!([]),
        serde_json::json!([1e308, 1e308, 1e308, 1e308, 1e308, 1e308, 1e308, 1e308]),
    ];
    let steps = cert["evidence"]["cells"][0]["steps"]
        .as_array()
        .expect("steps")
        .len();
    for g in &garbage {
        for k in 1..steps {
            let mut bad = cert.clone();
            let st = &mut bad["evidence"]["cells"][0]["steps"][k];
            if let Some(d) = st.get_mut("duals").and_then(Value::as_array_mut) {
                for x in d.iter_mut() {
                    *x = g.clone();
                }
            }
            // and the set's first offset shrunk by a tenth of its size
            let b = st["rows"][0]["b"].as_f64().expect("offset");
            st["rows"][0]["b"] = serde_json::json!(b - 0.1 * (1.0 + b.abs()));
            assert!(
                matches!(answer(&bad, &plan), Answer::Invalid(_)),
                "step {k} with duals {g}"
            );
        }
    }
}

#[test]
fn a_wrong_verified_verdict_never_gets_a_valid_certificate() {
    // an analysis bug that reports VERIFIED for a property a real trajectory
    // violates: the writer's claims are the checker's own bounds, so the
    // evidence cannot establish the verdict and is marked unsupported
    let source = std::fs::read_to_string("specs/double_integrator_falsified.ravel").expect("spec");
    let checked =
        ravel::front_end(&source, Path::new("specs"), &ravel_cli::read_request).expect("valid");
    let plan = ravel::lower::lower_system(&checked);
    let mut outcome = ravel::execute::execute_system(&plan, &ravel::execute::Control::unlimited());
    assert_eq!(
        outcome.properties[0].status,
        ravel::execute::Verdict::Falsified
    );
    outcome.properties[0].status = ravel::execute::Verdict::Verified;
    outcome.properties[0].counterexample = None;
    let id = ravel::certificate_writer::Identity {
        spec_path: String::new(),
        spec_sha256: String::new(),
    };
    let cert = ravel::certificate_writer::build_system(&plan, &outcome, &id);
    assert_eq!(cert["evidence"]["status"], "unsupported");
    match answer(&cert, &plan) {
        Answer::Unsupported(m) => assert!(m.contains("or its verdict is wrong"), "{m}"),
        other => panic!("{other:?}"),
    }
    // and forcing the evidence to "checkable" with the honest chain is INVALID
    let mut forced = cert.clone();
    let (_, honest) = run("specs/double_integrator_falsified.ravel");
    forced["evidence"] = honest["evidence"].clone();
    match answer(&forced, &plan) {
        Answer::Invalid(m) => assert!(m.contains("leaves goal row"), "{m}"),
        other => panic!("{other:?}"),
    }
}

/// Random junk (nulls, 1e308, huge integers, strings, empty or nested
/// arrays, inverted boxes, subnormals) in random places of real
/// certificates: the checker answers, it never panics.
#[test]
fn mutated_certificates_never_panic() {
    // a small deterministic generator (no dependency)
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let junk = [
        serde_json::json!(null),
        serde_json::json!(1e308),
        serde_json::json!(-1e308),
        serde_json::json!(0),
        serde_json::json!(-0.0),
        serde_json::json!(u64::MAX),
        serde_json::json!("x"),
        serde_json::json!([]),
        serde_json::json!([[[]]]),
        serde_json::json!({}),
        serde_json::json!([1e-320, -5e-324]),
        serde_json::json!({"lo": [1.0], "hi": [0.0]}),
    ];
    for spec in [
        "specs/double_integrator.ravel",
        "specs/double_integrator_hull.ravel",
        "specs/double_integrator_falsified.ravel",
        "specs/double_integrator_unrolled.ravel",
    ] {
        let (plan, cert) = run(spec);
        // every node's JSON pointer
        fn pointers(v: &Value, at: String, out: &mut Vec<String>) {
            out.push(at.clone());
            match v {
                Value::Array(a) => {
                    for (i, x) in a.iter().enumerate() {
                        pointers(x, format!("{at}/{i}"), out);
                    }
                }
                Value::Object(o) => {
                    for (k, x) in o {
                        pointers(x, format!("{at}/{k}"), out);
                    }
                }
                _ => {}
            }
        }
        let mut all = Vec::new();
        pointers(&cert, String::new(), &mut all);
        for _ in 0..400 {
            let mut bad = cert.clone();
            let ptr = &all[(next() % all.len() as u64) as usize];
            let value = junk[(next() % junk.len() as u64) as usize].clone();
            if let Some(slot) = bad.pointer_mut(ptr) {
                *slot = value;
            }
            let net = plan.closed_loop.net().clone();
            let got = std::panic::catch_unwind(move || check(&bad, &net).answer);
            assert!(got.is_ok(), "{spec}: a mutation at {ptr} panicked");
        }
    }
}

/// Optimised slopes: a goal (`x[1] ≤ 0.23` at the double integrator's last
/// step) that Reach-LP proves only with `optimise_slopes 5`; its certificate
/// is VALID because the checker runs its own slope search (the number of
/// steps is in the evidence). The same certificate with the search switched
/// off is INVALID (its claims are tighter than CROWN's own slopes prove),
/// and an absurd step count is unreadable, never VALID. Unrolled too.
#[test]
fn optimised_slopes_are_checked_by_the_checkers_own_search() {
    use ravel::lower::PropertyKind;
    for (spec, steps) in [
        ("specs/double_integrator.ravel", 5),
        ("specs/double_integrator_unrolled.ravel", 3),
    ] {
        let source = std::fs::read_to_string(spec).expect("spec readable");
        let dir = Path::new(spec).parent().expect("folder");
        let checked = ravel::front_end(&source, dir, &ravel_cli::read_request).expect("valid");
        let mut plan = ravel::lower::lower_system(&checked);
        plan.closed_loop
            .linear_mut()
            .expect("a linear plant")
            .slope_steps = steps;
        for q in &mut plan.properties {
            if let PropertyKind::Goal { set: g, .. } = &mut q.kind {
                for (a, b) in &mut g.poly.rows {
                    if a[..] == [0.0, 1.0] {
                        *b = if steps == 5 { 0.23 } else { -0.03 };
                    }
                }
            }
        }
        let outcome = ravel::execute::execute_system(&plan, &ravel::execute::Control::unlimited());
        assert_eq!(outcome.verdict, ravel::execute::Verdict::Verified, "{spec}");
        let id = ravel::certificate_writer::Identity {
            spec_path: spec.to_string(),
            spec_sha256: String::new(),
        };
        let cert = ravel::certificate_writer::build_system(&plan, &outcome, &id);
        assert_eq!(cert["evidence"]["slope_steps"], steps, "{spec}");
        assert_eq!(answer(&cert, &plan), Answer::Valid, "{spec}");
        let mut off = cert.clone();
        off["evidence"]["slope_steps"] = 0.into();
        assert!(
            matches!(answer(&off, &plan), Answer::Invalid(_)),
            "{spec}: claims proven only by optimised slopes must fail without them"
        );
        let mut absurd = cert.clone();
        absurd["evidence"]["slope_steps"] = 1_000_000.into();
        assert!(
            matches!(answer(&absurd, &plan), Answer::Unreadable(_)),
            "{spec}: an absurd step count is unreadable"
        );
    }
}

/// `ravel` run in the folder `dir`: exit code and standard output.
fn ravel_in(dir: &Path, args: &[&str]) -> (i32, String) {
    let o = ravel().current_dir(dir).args(args).output().expect("runs");
    assert!(o.status.code().is_some(), "ended by a signal");
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into_owned(),
    )
}

/// The first 12 hex digits of a file's SHA-256, as `certify` prints them.
fn sha_prefix(file: &Path) -> String {
    let bytes = std::fs::read(file).expect("readable");
    ravel::check::sha256_hex(&bytes)[..12].to_string()
}

/// A project folder `p` holding `specs/di.ravel` (the double integrator,
/// with a non-canonical layout that `ravel fmt` changes) and
/// `models/double_integrator.onnx`, certified into `p/certs/di.cert.json` by
/// `verify` run in `p` with relative paths. Returns (`p`, the spec's text).
fn certified_project(root: &Path) -> (std::path::PathBuf, String) {
    let p = root.join("p");
    std::fs::create_dir_all(p.join("specs")).expect("dir");
    std::fs::create_dir_all(p.join("models")).expect("dir");
    std::fs::create_dir_all(p.join("certs")).expect("dir");
    std::fs::copy(
        "models/double_integrator.onnx",
        p.join("models/double_integrator.onnx"),
    )
    .expect("copy model");
    let spec = std::fs::read_to_string("specs/double_integrator.ravel")
        .expect("spec")
        .replace("horizon 5", "horizon      5");
    std::fs::write(p.join("specs/di.ravel"), &spec).expect("write spec");
    let (code, out) = ravel_in(
        &p,
        &[
            "verify",
            "specs/di.ravel",
            "--quiet",
            "--no-timing",
            "--certificate",
            "certs/di.cert.json",
        ],
    );
    assert_eq!(code, 0, "{out}");
    (p, spec)
}

/// A certificate records its files relative to its own folder: `certify`
/// works from any working folder, and after the spec, the model and the
/// certificate are moved together; it names the spec and the controller it
/// checked, with their hashes.
#[test]
fn certificates_travel_with_their_files() {
    let root = tmp("travel");
    let (p, _) = certified_project(&root);
    let cert: Value = serde_json::from_str(
        &std::fs::read_to_string(p.join("certs/di.cert.json")).expect("certificate"),
    )
    .expect("json");
    assert_eq!(cert["spec"]["path"], "../specs/di.ravel");
    assert_eq!(
        cert["controller"]["path"],
        "../models/double_integrator.onnx"
    );
    // from another working folder, the certificate named by its full path
    let elsewhere = root.join("elsewhere");
    std::fs::create_dir_all(&elsewhere).expect("dir");
    let file = p.join("certs/di.cert.json");
    let (code, out) = ravel_in(&elsewhere, &["certify", file.to_str().expect("utf-8")]);
    assert_eq!(code, 0, "{out}");
    assert!(out.starts_with("VALID"), "{out}");
    // the files checked: paths and SHA-256 prefixes
    let model_sha = sha_prefix(&p.join("models/double_integrator.onnx"));
    let spec_sha = sha_prefix(&p.join("specs/di.ravel"));
    assert!(
        out.lines().any(|l| l.trim_start().starts_with("controller")
            && l.contains("models/double_integrator.onnx")
            && l.contains(&format!("SHA-256 {model_sha})"))),
        "{out}"
    );
    assert!(
        out.lines().any(|l| l.trim_start().starts_with("spec")
            && l.contains("specs/di.ravel")
            && l.contains(&format!("SHA-256 {spec_sha})"))),
        "{out}"
    );
    assert!(!out.contains("note:"), "{out}");
    // the whole folder moved; certified from its new place and from the
    // certificate's own folder
    let q = root.join("moved").join("q");
    std::fs::create_dir_all(q.parent().expect("parent")).expect("dir");
    std::fs::rename(&p, &q).expect("move");
    let (code, out) = ravel_in(&root, &["certify", "moved/q/certs/di.cert.json"]);
    assert_eq!(code, 0, "{out}");
    assert!(out.starts_with("VALID"), "{out}");
    let (code, out) = ravel_in(&q.join("certs"), &["certify", "di.cert.json"]);
    assert_eq!(code, 0, "{out}");
    // an explicit --spec stays relative to the working folder
    let (code, out) = ravel_in(
        &q,
        &["certify", "certs/di.cert.json", "--spec", "specs/di.ravel"],
    );
    assert_eq!(code, 0, "{out}");
    let _ = std::fs::remove_dir_all(&root);
}

/// VALID depends on the problem, not on the spec's text: a comment or `ravel
/// fmt` leaves it VALID with a note; a changed number makes it INVALID,
/// naming the number.
#[test]
fn a_changed_text_with_the_same_problem_stays_valid() {
    let root = tmp("text");
    let (p, spec) = certified_project(&root);
    let spec_file = p.join("specs/di.ravel");
    let certify = || ravel_in(&root, &["certify", "p/certs/di.cert.json"]);
    // a comment
    std::fs::write(&spec_file, format!("// reviewed\n{spec}")).expect("write");
    let (code, out) = certify();
    assert_eq!(code, 0, "{out}");
    assert!(out.starts_with("VALID"), "{out}");
    let note = out
        .lines()
        .find(|l| l.contains("note:"))
        .unwrap_or_else(|| panic!("no note: {out}"));
    assert!(note.contains("text differs"), "{out}");
    assert!(note.contains("its problem is identical"), "{out}");
    assert!(
        note.contains(&sha_prefix(&spec_file)),
        "the note names the hash read: {out}"
    );
    // `ravel fmt` rewrites the layout
    let before = std::fs::read_to_string(&spec_file).expect("spec");
    let (code, out) = ravel_in(&p, &["fmt", "specs/di.ravel"]);
    assert_eq!(code, 0, "{out}");
    let after = std::fs::read_to_string(&spec_file).expect("spec");
    assert_ne!(
        before, after,
        "fmt changed nothing: the test proves nothing"
    );
    let (code, out) = certify();
    assert_eq!(code, 0, "{out}");
    assert!(out.contains("its problem is identical"), "{out}");
    // a number of the problem: INVALID, the number named
    std::fs::write(&spec_file, after.replacen("[[1, 1]", "[[1, 1.5]", 1)).expect("write");
    let (code, out) = certify();
    assert_eq!(code, 1, "{out}");
    assert!(out.starts_with("INVALID"), "{out}");
    assert!(out.contains("`problem.plants[0].A[0][1]` differs"), "{out}");
    assert!(!out.contains("its problem is identical"), "{out}");
    let _ = std::fs::remove_dir_all(&root);
}

/// `certify` names the controller it checked: a certificate of `verify S
/// --controller C` shows C, not the controller S names itself.
#[test]
fn certify_names_the_controller_it_checked() {
    let root = tmp("controller");
    std::fs::copy("models/double_integrator.onnx", root.join("good.onnx")).expect("copy");
    let spec = std::fs::canonicalize("specs/double_integrator.ravel").expect("spec");
    let (code, out) = ravel_in(
        &root,
        &[
            "verify",
            spec.to_str().expect("utf-8"),
            "--controller",
            "good.onnx",
            "--quiet",
            "--certificate",
            "c.cert.json",
        ],
    );
    assert_eq!(code, 0, "{out}");
    let (code, out) = ravel_in(&root, &["certify", "c.cert.json"]);
    assert_eq!(code, 0, "{out}");
    let line = out
        .lines()
        .find(|l| l.trim_start().starts_with("controller"))
        .unwrap_or_else(|| panic!("no controller line: {out}"));
    assert!(line.contains("good.onnx"), "{out}");
    assert!(!line.contains("models/double_integrator.onnx"), "{out}");
    assert!(line.contains(&sha_prefix(&root.join("good.onnx"))), "{out}");
    // also when the answer is INVALID: the file read is named
    std::fs::copy(
        "models/double_integrator_tanh.onnx",
        root.join("other.onnx"),
    )
    .expect("copy");
    let (code, out) = ravel_in(
        &root,
        &["certify", "c.cert.json", "--controller", "other.onnx"],
    );
    assert_eq!(code, 1, "{out}");
    assert!(out.contains("SHA-256 differs"), "{out}");
    assert!(
        out.lines()
            .any(|l| l.contains("other.onnx") && l.contains(&sha_prefix(&root.join("other.onnx")))),
        "{out}"
    );
    let _ = std::fs::remove_dir_all(&root);
}

/// Certificates written before paths were recorded relative to the
/// certificate hold paths relative to `verify`'s working folder: a path not
/// found beside the certificate is read from the working folder, with a
/// note; the hashes and the problem are checked as always.
#[test]
fn older_certificates_read_paths_from_the_working_folder() {
    let root = tmp("older");
    let (p, _) = certified_project(&root);
    let file = p.join("certs/di.cert.json");
    let mut cert: Value =
        serde_json::from_str(&std::fs::read_to_string(&file).expect("certificate")).expect("json");
    cert["spec"]["path"] = serde_json::json!("specs/di.ravel");
    cert["controller"]["path"] = serde_json::json!("models/double_integrator.onnx");
    std::fs::write(&file, cert.to_string()).expect("write");
    let (code, out) = ravel_in(&p, &["certify", "certs/di.cert.json"]);
    assert_eq!(code, 0, "{out}");
    assert!(out.starts_with("VALID"), "{out}");
    assert!(out.contains("not beside the certificate"), "{out}");
    // from elsewhere, neither rule finds it: UNREADABLE, never VALID
    let (code, out) = ravel_in(&root, &["certify", "p/certs/di.cert.json"]);
    assert_eq!(code, 2, "{out}");
    assert!(out.starts_with("UNREADABLE"), "{out}");
    // a recorded path with control characters is shown escaped
    cert["spec"]["path"] = serde_json::json!("specs/\u{1b}[2Jdi.ravel");
    std::fs::write(&file, cert.to_string()).expect("write");
    let (code, out) = ravel_in(&p, &["certify", "certs/di.cert.json"]);
    assert_eq!(code, 2, "{out}");
    assert!(!out.contains('\u{1b}'), "{out:?}");
    assert!(out.contains("\\u{1b}[2Jdi.ravel"), "{out}");
    let _ = std::fs::remove_dir_all(&root);
}

/// A certificate whose nonlinear set claim is false is never VALID: the
/// checker bounds each constraint `g(x) ≤ 0` with its own interval
/// arithmetic over its claimed boxes.
#[test]
fn a_false_nonlinear_set_claim_is_never_valid() {
    let spec = "specs/double_integrator_disc_obstacle.ravel";
    let (plan, cert) = run(spec);
    assert_eq!(
        answer(&cert, &plan),
        Answer::Valid,
        "the honest certificate"
    );
    let props = cert["problem"]["properties"]
        .as_array()
        .expect("properties");
    assert!(
        props[0]["nonlinear"].is_array(),
        "the goal's constraint is recorded"
    );
    assert!(props[1]["members"][0]["nonlinear"].is_array());
    // the obstacle moved onto the final reachable set (a disc of radius 5
    // around the origin): the avoid claim is false
    let mut moved = cert.clone();
    let g = &mut moved["problem"]["properties"][1]["members"][0]["nonlinear"][0];
    let last = g.as_array().expect("tape").len() - 2;
    g[last] = serde_json::json!(["const", 25.0]);
    let g = &mut moved["problem"]["properties"][1]["members"][0]["nonlinear"][0];
    for node in g.as_array_mut().expect("tape") {
        if node[0] == "const" && node[1] == 1.0 {
            node[1] = serde_json::json!(0.0);
        }
    }
    match answer(&moved, &plan) {
        Answer::Invalid(m) => assert!(m.contains("member 0"), "{m}"),
        other => panic!("a false avoid claim: {other:?}"),
    }
    // the goal disc shrunk to radius 0.1 around the origin: the goal claim is false
    let mut shrunk = cert.clone();
    let g = &mut shrunk["problem"]["properties"][0]["nonlinear"][0];
    let n = g.as_array().expect("tape").len();
    g[n - 2] = serde_json::json!(["const", 0.01]);
    match answer(&shrunk, &plan) {
        Answer::Invalid(m) => assert!(m.contains("nonlinear constraint"), "{m}"),
        other => panic!("a false goal claim: {other:?}"),
    }
    // a constraint undefined on the boxes (log of a range through 0) proves nothing
    let mut undefined = cert.clone();
    undefined["problem"]["properties"][0]["nonlinear"][0] =
        serde_json::json!([["var", 1], ["log", 0]]);
    assert!(
        matches!(answer(&undefined, &plan), Answer::Invalid(_)),
        "an undefined constraint"
    );
    // a malformed tape is unreadable, not valid
    let mut malformed = cert;
    malformed["problem"]["properties"][0]["nonlinear"][0] = serde_json::json!([["add", 3, 4]]);
    assert!(matches!(answer(&malformed, &plan), Answer::Unreadable(_)));
}
