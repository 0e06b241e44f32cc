//! Golden tests of the `ravel` binary: exit codes, output formats, and the
//! commands shown in the README.

use std::process::Command;

#[path = "common/binary.rs"]
mod binary;
use binary::ravel;

#[test]
fn exit_codes_follow_the_verdict() {
    assert_eq!(ravel(&["verify", "specs/double_integrator.ravel"]).0, 0);
    assert_eq!(
        ravel(&["verify", "specs/double_integrator_falsified.ravel"]).0,
        1
    );
    assert_eq!(
        ravel(&["verify", "specs/double_integrator_hard.ravel"]).0,
        3
    );
    assert_eq!(ravel(&["verify", "specs/invalid/wrong_shape.ravel"]).0, 2);
    // FALSIFIED outranks UNSURE; input errors outrank both
    assert_eq!(
        ravel(&[
            "verify",
            "specs/double_integrator_hard.ravel",
            "specs/double_integrator_falsified.ravel"
        ])
        .0,
        1
    );
    assert_eq!(
        ravel(&[
            "verify",
            "specs/double_integrator_falsified.ravel",
            "specs/invalid/wrong_shape.ravel"
        ])
        .0,
        2
    );
    assert_eq!(ravel(&["verify", "specs/no_such_spec.ravel"]).0, 2);
    assert_eq!(ravel(&["frobnicate"]).0, 2);
    assert_eq!(ravel(&["verify"]).0, 2);
}

#[test]
fn check_reports_diagnostics_without_colour_when_piped() {
    let (code, out, err) = ravel(&[
        "check",
        "specs/double_integrator.ravel",
        "specs/invalid/many_errors.ravel",
    ]);
    assert_eq!(code, 2);
    assert!(out.contains("ok: specs/double_integrator.ravel"));
    for c in ["E0101", "E0201", "E0203", "E0206"] {
        assert!(err.contains(c), "missing {c} in\n{err}");
    }
    assert!(
        !err.contains('\u{1b}'),
        "no ANSI escapes when stderr is not a terminal"
    );
    assert_eq!(ravel(&["check", "specs/quadrotor.ravel"]).0, 0);
}

#[test]
fn text_report_shows_sets_properties_and_timing() {
    let (_, out, _) = ravel(&["verify", "specs/double_integrator.ravel"]);
    for needle in [
        "step   5",
        "goal G",
        "VERIFIED",
        "verdict: VERIFIED",
        "time:",
    ] {
        assert!(out.contains(needle), "missing {needle:?} in\n{out}");
    }
    let (_, out, _) = ravel(&["verify", "--no-timing", "specs/double_integrator.ravel"]);
    assert!(!out.contains("time:"));
}

#[test]
fn json_output_is_deterministic_and_follows_the_schema() {
    let args = [
        "verify",
        "--format",
        "json",
        "specs/double_integrator.ravel",
        "specs/double_integrator_falsified.ravel",
        "specs/invalid/wrong_shape.ravel",
    ];
    let (code, out, _) = ravel(&args);
    assert_eq!(code, 2);
    assert_eq!(out, ravel(&args).1, "same inputs, same bytes");
    let v: serde_json::Value = serde_json::from_str(&out).expect("valid JSON");
    assert_eq!(v["schema"], "ravel-report/1");
    assert_eq!(v["verdict"], "ERROR");
    let r = v["results"].as_array().expect("results");
    assert_eq!(r.len(), 3);
    assert_eq!(r[0]["verdict"], "VERIFIED");
    assert_eq!(r[0]["reachable"].as_array().expect("steps").len(), 6);
    assert_eq!(
        r[0]["reachable"][5]["box"]["lo"]
            .as_array()
            .expect("lo")
            .len(),
        2
    );
    assert_eq!(r[0]["properties"][0]["status"], "VERIFIED");
    assert!(r[0].get("time_ms").is_none());
    assert_eq!(r[1]["verdict"], "FALSIFIED");
    let cex = &r[1]["properties"][0]["counterexample"];
    assert_eq!(cex["states"].as_array().expect("states").len(), 6);
    assert_eq!(cex["controls"].as_array().expect("controls").len(), 5);
    assert_eq!(r[2]["verdict"], "ERROR");
    assert_eq!(r[2]["errors"][0]["code"], "E0201");
    assert!(r[2]["errors"][0]["line"].as_u64().expect("line") > 0);
    let (_, out, _) = ravel(&[
        "verify",
        "--format",
        "json",
        "--timing",
        "specs/double_integrator.ravel",
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).expect("valid JSON");
    assert!(v["results"][0]["time_ms"].as_f64().is_some());
}

#[test]
fn counterexamples_are_real_trajectories() {
    // Replay the reported counterexample through the plant and controller, independently of ravel's simulator.
    let (_, out, _) = ravel(&[
        "verify",
        "--format",
        "json",
        "specs/double_integrator_falsified.ravel",
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).expect("valid JSON");
    let cex = &v["results"][0]["properties"][0]["counterexample"];
    let xs: Vec<Vec<f64>> = serde_json::from_value(cex["states"].clone()).expect("states");
    let us: Vec<Vec<f64>> = serde_json::from_value(cex["controls"].clone()).expect("controls");
    let bytes = std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/models/double_integrator.onnx"
    ))
    .expect("model");
    let c = ravel::onnx::load(&bytes, &Default::default()).expect("loads");
    assert!(
        (2.5..=3.0).contains(&xs[0][0]) && (-0.25..=0.25).contains(&xs[0][1]),
        "starts in X0"
    );
    for t in 0..5 {
        let u = c.net.forward(&xs[t])[0].clamp(-1.0, 1.0);
        assert!((u - us[t][0]).abs() < 1e-12);
        let next = [xs[t][0] + xs[t][1] + 0.5 * u, xs[t][1] + u];
        assert!((next[0] - xs[t + 1][0]).abs() < 1e-12 && (next[1] - xs[t + 1][1]).abs() < 1e-12);
    }
    let last = &xs[5];
    assert!(
        !(0.1..=1.0).contains(&last[0]) || !(-1.0..=1.0).contains(&last[1]),
        "ends outside G: {last:?}"
    );
}

/// A closed standard output ends the run quietly: no panic message, exit
/// code 141 (or 0 if everything was written before the pipe closed).
#[test]
fn a_closed_pipe_ends_the_run_quietly() {
    use std::process::Stdio;
    let mut child = Command::new(env!("CARGO_BIN_EXE_ravel"))
        .args([
            "verify",
            "specs/quadrotor_partitioned.ravel",
            "--format",
            "json",
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the binary runs");
    drop(child.stdout.take());
    let out = child.wait_with_output().expect("exits");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        matches!(out.status.code(), Some(141) | Some(0)),
        "{:?}",
        out.status
    );
}

#[test]
fn a_time_limit_stops_soundly() {
    let (code, out, _) = ravel(&[
        "verify",
        "specs/double_integrator.ravel",
        "--time-limit",
        "0",
        "--no-timing",
    ]);
    assert_eq!(code, 3, "{out}");
    assert!(
        out.contains("the time limit stopped the analysis at step 1"),
        "{out}"
    );
    assert!(out.contains("after 0 of 2000 samples"), "{out}");
    for bad in ["-1", "nan", "inf", "soon"] {
        assert_eq!(
            ravel(&[
                "verify",
                "specs/double_integrator.ravel",
                "--time-limit",
                bad
            ])
            .0,
            2,
            "{bad}"
        );
    }
    let (code, out, _) = ravel(&[
        "verify",
        "specs/double_integrator.ravel",
        "--time-limit",
        "0",
        "--format",
        "json",
    ]);
    assert_eq!(code, 3);
    let v: serde_json::Value = serde_json::from_str(&out).expect("JSON");
    let r = &v["results"][0];
    assert_eq!(r["unfinished"]["cause"], "time_limit");
    assert_eq!(r["properties"][0]["unfinished"]["step"], 1);
    assert_eq!(r["samples_drawn"], 0);
}

/// One spec, many controllers: every (spec, controller) pair is a result
/// named by both, with the controller's resolved path and SHA-256; a
/// controller that does not fit is one ERROR result among the others; a
/// folder of specs is searched recursively; a summary line closes the text.
#[test]
fn one_spec_many_controllers_and_folders() {
    let (code, out, _) = ravel(&[
        "verify",
        "specs/double_integrator.ravel",
        "--controller",
        "models/double_integrator.onnx",
        "--controller",
        "models/double_integrator_tanh.onnx",
        "--controller",
        "models/quadrotor.onnx",
        "--format",
        "json",
    ]);
    assert_eq!(code, 2, "a controller that does not fit is an input error");
    let v: serde_json::Value = serde_json::from_str(&out).expect("JSON");
    let results = v["results"].as_array().expect("results");
    assert_eq!(results.len(), 3);
    let hashes: Vec<&str> = results
        .iter()
        .take(2)
        .map(|r| r["controller"]["sha256"].as_str().expect("sha256"))
        .collect();
    assert!(hashes.iter().all(|h| h.len() == 64), "{hashes:?}");
    assert_ne!(hashes[0], hashes[1]);
    assert_eq!(
        results[0]["controller"]["resolved"],
        "models/double_integrator.onnx"
    );
    assert_eq!(results[0]["verdict"], "VERIFIED");
    assert_eq!(results[2]["verdict"], "ERROR");
    assert_eq!(results[2]["controller"], "models/quadrotor.onnx");
    // the same file gives the same hash, whichever way it is named
    let (_, own, _) = ravel(&[
        "verify",
        "specs/double_integrator.ravel",
        "--format",
        "json",
    ]);
    let own: serde_json::Value = serde_json::from_str(&own).expect("JSON");
    assert_eq!(own["results"][0]["controller"]["sha256"], hashes[0]);
    assert_eq!(
        own["results"][0]["controller"]["resolved"],
        "specs/../models/double_integrator.onnx"
    );

    // text: a summary line counts every pair
    let (code, out, err) = ravel(&[
        "verify",
        "specs/double_integrator.ravel",
        "--controller",
        "models/double_integrator.onnx",
        "--controller",
        "models/double_integrator_tanh.onnx",
        "--no-timing",
    ]);
    assert_eq!(code, 3, "{err}");
    assert!(out.contains("summary: 1 VERIFIED, 1 UNSURE\n"), "{out}");
    assert!(
        out.contains("with controller models/double_integrator_tanh.onnx"),
        "{out}"
    );

    // a folder of specs (the invalid ones: every one an ERROR, none lost)
    let (code, out, _) = ravel(&["verify", "specs/invalid", "--no-timing"]);
    assert_eq!(code, 2);
    let ravel_files = |d: std::fs::ReadDir| {
        d.filter(|e| {
            e.as_ref()
                .is_ok_and(|e| e.path().extension().is_some_and(|x| x == "ravel"))
        })
        .count()
    };
    let n = std::fs::read_dir("specs/invalid")
        .map(ravel_files)
        .unwrap_or_else(|_| {
            ravel_files(
                std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/specs/invalid"))
                    .expect("folder"),
            )
        });
    assert!(out.contains(&format!("summary: {n} ERROR")), "{out}");

    // an empty folder and a missing controller are input errors, with a message
    let empty = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("empty_folder");
    std::fs::create_dir_all(&empty).expect("folder");
    let (code, _, err) = ravel(&["verify", empty.to_str().expect("utf-8")]);
    assert_eq!(code, 2);
    assert!(err.contains("no .ravel file in folder"), "{err}");
    let (code, _, err) = ravel(&[
        "check",
        "specs/double_integrator.ravel",
        "--controller",
        "models/no_such.onnx",
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("E0301"), "{err}");
}

fn bin() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_ravel"))
}

/// Several specs with every verdict, one broken spec and a missing file.
fn batch_args() -> Vec<&'static str> {
    vec![
        "verify",
        "specs/double_integrator.ravel",
        "specs/double_integrator_falsified.ravel",
        "specs/double_integrator_hard.ravel",
        "specs/invalid/index_out_of_range.ravel",
        "specs/no_such_spec.ravel",
        "specs/double_integrator_partitioned.ravel",
    ]
}

#[test]
fn jobs_do_not_change_a_single_byte() {
    let run = |jobs: &str| {
        let o = bin()
            .args(batch_args())
            .args(["--format", "json", "--jobs", jobs])
            .output()
            .expect("runs");
        assert_eq!(o.status.code(), Some(2));
        o.stdout
    };
    let one = run("1");
    assert_eq!(one, run("2"));
    assert_eq!(one, run("5"));
    let v: serde_json::Value = serde_json::from_slice(&one).expect("JSON");
    let r = v["results"].as_array().expect("results");
    assert_eq!(r.len(), 6);
    let verdicts: Vec<&str> = r
        .iter()
        .map(|x| x["verdict"].as_str().unwrap_or(""))
        .collect();
    // the pairs in argument order, a missing file an ERROR in its place
    assert_eq!(
        verdicts,
        [
            "VERIFIED",
            "FALSIFIED",
            "UNSURE",
            "ERROR",
            "ERROR",
            "VERIFIED"
        ]
    );
    for (i, x) in r.iter().enumerate() {
        assert_eq!(x["index"], i);
    }
}

#[test]
fn shards_merge_into_the_unsharded_report() {
    let whole = bin()
        .args(batch_args())
        .args(["--format", "json"])
        .output()
        .expect("runs")
        .stdout;
    let dir = std::env::temp_dir().join(format!("ravel-shards-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let mut files = Vec::new();
    let mut seen = 0;
    for k in 1..=3 {
        let o = bin()
            .args(batch_args())
            .args(["--format", "json", "--shard", &format!("{k}/3")])
            .output()
            .expect("runs");
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
        seen += v["results"].as_array().map_or(0, Vec::len);
        assert_eq!(v["shard"], format!("{k}/3"));
        let f = dir.join(format!("{k}.json"));
        std::fs::write(&f, &o.stdout).expect("write");
        files.push(f);
    }
    assert_eq!(seen, 6, "every pair in exactly one shard");
    let merged = bin().arg("merge").args(&files).output().expect("runs");
    assert_eq!(merged.status.code(), Some(2), "the batch has an ERROR");
    assert_eq!(merged.stdout, whole);
    // a missing or doubled shard is an error, never a silent partial report
    let missing = bin().arg("merge").args(&files[..2]).output().expect("runs");
    assert_eq!(missing.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&missing.stderr).contains("is in no shard"));
    let doubled = bin()
        .arg("merge")
        .args(&files)
        .arg(&files[0])
        .output()
        .expect("runs");
    assert_eq!(doubled.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&doubled.stderr).contains("appears twice"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_batch_options_are_usage_errors() {
    for args in [
        ["--shard", "0/2"],
        ["--shard", "3/2"],
        ["--shard", "1/0"],
        ["--shard", "half"],
        ["--jobs", "0"],
        ["--fail-on", "never"],
    ] {
        let o = bin()
            .args(["verify", "specs/double_integrator.ravel"])
            .args(args)
            .output()
            .expect("runs");
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(!o.stderr.is_empty());
    }
    let empty = std::env::temp_dir().join(format!("ravel-empty-{}", std::process::id()));
    std::fs::create_dir_all(&empty).expect("dir");
    let o = bin().arg("verify").arg(&empty).output().expect("runs");
    assert_eq!(o.status.code(), Some(2));
    let _ = std::fs::remove_dir_all(&empty);
}

#[test]
fn junit_reports_parse_and_follow_the_gate() {
    let run = |fail_on: &str| {
        bin()
            .args(batch_args())
            .args(["--format", "junit", "--fail-on", fail_on])
            .output()
            .expect("runs")
    };
    let o = run("unsure");
    assert_eq!(o.status.code(), Some(2));
    let text = String::from_utf8(o.stdout).expect("UTF-8");
    let doc = roxmltree::Document::parse(&text).expect("well-formed XML");
    let root = doc.root_element();
    assert_eq!(root.tag_name().name(), "testsuites");
    let suites: Vec<_> = root
        .children()
        .filter(|n| n.has_tag_name("testsuite"))
        .collect();
    assert_eq!(suites.len(), 6);
    let cases = root
        .descendants()
        .filter(|n| n.has_tag_name("testcase"))
        .count();
    // 2 properties in each of the 4 loaded specs, one case per error
    assert_eq!(cases, 4 * 2 + 2);
    let failures: Vec<_> = root
        .descendants()
        .filter(|n| n.has_tag_name("failure"))
        .collect();
    assert!(failures
        .iter()
        .any(|f| f.attribute("type") == Some("FALSIFIED")
            && f.text().is_some_and(|t| t.contains("counterexample"))));
    assert!(failures
        .iter()
        .any(|f| f.attribute("type") == Some("UNSURE")));
    assert_eq!(
        root.descendants()
            .filter(|n| n.has_tag_name("error"))
            .count(),
        2
    );
    assert_eq!(root.attribute("errors"), Some("2"));
    // --fail-on falsified: UNSURE is skipped, and a batch with only
    // VERIFIED and UNSURE passes
    let o = run("falsified");
    let text = String::from_utf8(o.stdout).expect("UTF-8");
    let doc = roxmltree::Document::parse(&text).expect("well-formed XML");
    assert!(doc.descendants().any(|n| n.has_tag_name("skipped")));
    let gate = |fail_on: &str| {
        bin()
            .args([
                "verify",
                "specs/double_integrator.ravel",
                "specs/double_integrator_hard.ravel",
                "--fail-on",
                fail_on,
            ])
            .output()
            .expect("runs")
            .status
            .code()
    };
    assert_eq!(gate("falsified"), Some(0));
    assert_eq!(gate("unsure"), Some(3));
}

#[test]
fn jsonl_is_one_result_per_line_then_a_summary() {
    let o = bin()
        .args(batch_args())
        .args(["--format", "jsonl"])
        .output()
        .expect("runs");
    let text = String::from_utf8(o.stdout).expect("UTF-8");
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).expect("a JSON object per line"))
        .collect();
    assert_eq!(lines.len(), 7);
    assert_eq!(lines[6]["verdict"], "ERROR");
    assert_eq!(lines[1]["verdict"], "FALSIFIED");
    assert_eq!(lines[4]["verdict"], "ERROR");
}

/// Network specs go through the same commands: exit codes by verdict, JSON
/// of the same family (`kind: network`), JUnit cases per property,
/// certificates and plots.
#[test]
fn network_specs_through_the_binary() {
    let (code, stdout, _) = ravel(&["verify", "specs/network/classifier_robust.ravel"]);
    assert_eq!(code, 0, "{stdout}");
    assert!(stdout.contains("robust sector  VERIFIED"), "{stdout}");
    let (code, stdout, _) = ravel(&[
        "verify",
        "--format",
        "json",
        "specs/network/classifier_falsified.ravel",
    ]);
    assert_eq!(code, 1);
    let v: serde_json::Value = serde_json::from_str(&stdout).expect("json");
    let r = &v["results"][0];
    assert_eq!(r["kind"], "network");
    assert_eq!(r["verdict"], "FALSIFIED");
    let x = r["properties"][0]["counterexample"]["input"]
        .as_array()
        .expect("a witness");
    assert_eq!(x.len(), 2);
    let (code, stdout, _) = ravel(&[
        "verify",
        "--format",
        "junit",
        "specs/network/policy_output_set.ravel",
    ]);
    assert_eq!(code, 0);
    assert!(stdout.contains("name=\"require bounded\""), "{stdout}");
    let (code, _, stderr) = ravel(&["check", "specs/network/policy_output_set.ravel"]);
    assert_eq!(code, 0, "{stderr}");
    let dir = std::env::temp_dir().join(format!("ravel-net-cert-{}", std::process::id()));
    let cert = dir.join("c.json");
    std::fs::create_dir_all(&dir).expect("dir");
    let (code, _, stderr) = ravel(&[
        "verify",
        "--certificate",
        cert.to_str().expect("utf-8"),
        "specs/network/policy_output_set.ravel",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let (code, stdout, _) = ravel(&["certify", cert.to_str().expect("utf-8")]);
    assert_eq!(code, 0, "{stdout}");
    assert!(stdout.starts_with("VALID"), "{stdout}");
    assert!(stdout.contains("bounded: VERIFIED (checked)"), "{stdout}");
    let (code, _, stderr) = ravel(&[
        "verify",
        "--plot",
        dir.to_str().expect("utf-8"),
        "specs/network/policy_output_set.ravel",
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(dir.join("policy_output_set.svg").is_file());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `import-vnnlib` prints a spec that verifies, writes one whose model path
/// is relative to its folder with `--output`, and exits 2 on what it does
/// not support or a network whose sizes differ.
#[test]
fn import_vnnlib_through_the_binary() {
    let (code, stdout, stderr) = ravel(&[
        "import-vnnlib",
        "tests/data/vnnlib/robust_box.vnnlib",
        "--network",
        "models/classifier.onnx",
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("avoid unsafe ="), "{stdout}");
    let dir = std::env::temp_dir().join(format!("ravel-vnnlib-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let spec = dir.join("robust_box.ravel");
    let (code, _, stderr) = ravel(&[
        "import-vnnlib",
        "tests/data/vnnlib/robust_box.vnnlib",
        "--network",
        "models/classifier.onnx",
        "--output",
        spec.to_str().expect("utf-8"),
    ]);
    assert_eq!(code, 0, "{stderr}");
    let (code, stdout, _) = ravel(&["verify", spec.to_str().expect("utf-8")]);
    assert_eq!(code, 0, "{stdout}");
    assert!(stdout.contains("avoid unsafe  VERIFIED"), "{stdout}");
    let _ = std::fs::remove_dir_all(&dir);
    let (code, _, stderr) = ravel(&[
        "import-vnnlib",
        "tests/data/vnnlib/mixed.vnnlib",
        "--network",
        "models/classifier.onnx",
    ]);
    assert_eq!(code, 2);
    assert!(stderr.contains("mixed.vnnlib:7:9"), "{stderr}");
    // the property declares 3 outputs; the double integrator's controller has 1
    let (code, _, stderr) = ravel(&[
        "import-vnnlib",
        "tests/data/vnnlib/robust_box.vnnlib",
        "--network",
        "models/double_integrator.onnx",
    ]);
    assert_eq!(code, 2);
    assert!(stderr.contains("E0305"), "{stderr}");
    // an output into a folder that does not exist names the folder (issue
    // 30: it used to report the network as unreadable, E0301)
    let missing = std::env::temp_dir().join(format!("ravel-no-such-{}", std::process::id()));
    let target = missing.join("x.ravel");
    let (code, _, stderr) = ravel(&[
        "import-vnnlib",
        "tests/data/vnnlib/robust_box.vnnlib",
        "--network",
        "models/classifier.onnx",
        "--output",
        target.to_str().expect("utf-8"),
    ]);
    assert_eq!(code, 2);
    assert!(stderr.contains("no such folder"), "{stderr}");
    assert!(!stderr.contains("E0301"), "{stderr}");
    assert!(!missing.exists());
}

/// The CARRL demonstration runs at a small size: a table of average returns
/// for the nominal policy and CARRL at three radii, five adversary strengths.
#[test]
fn carrl_demonstration_runs() {
    let out = Command::new(env!("CARGO_BIN_EXE_ravel-carrl-demo"))
        .args(["--episodes", "2", "--steps", "15"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let rows: Vec<&str> = text.lines().collect();
    assert_eq!(rows.len(), 6, "{text}");
    for row in &rows[2..] {
        let values: Vec<f64> = row
            .split_whitespace()
            .rev()
            .take(5)
            .map(|v| v.parse().expect("a number"))
            .collect();
        // 15 steps of reward at most 1, or a crash (−5) earlier
        assert!(values.iter().all(|v| (-5.0..=15.0).contains(v)), "{row}");
    }
    let bad = Command::new(env!("CARGO_BIN_EXE_ravel-carrl-demo"))
        .args(["--episodes", "0"])
        .output()
        .expect("runs");
    assert_eq!(bad.status.code(), Some(2));
}

/// `--format csv` on a spec without a `select` block is a coded diagnostic
/// (E0403, at the spec's name, with a hint; exit 2), not a lone header
/// (issue 30).
#[test]
fn csv_output_without_selections_is_an_error() {
    for (spec, name_line) in [
        ("specs/double_integrator.ravel", "6:8]"),
        ("specs/network/classifier_robust.ravel", "7:9]"),
    ] {
        let (code, stdout, stderr) = ravel(&["verify", "--format", "csv", spec]);
        assert_eq!(code, 2, "{spec}: {stderr}");
        assert!(stderr.contains("E0403"), "{stderr}");
        assert!(stderr.contains("no `select` block"), "{stderr}");
        assert!(stderr.contains("help: use --format text"), "{stderr}");
        assert!(stderr.contains(&format!("{spec}:{name_line}")), "{stderr}");
        assert!(
            !stderr.contains("\nerror:"),
            "no plain error line: {stderr}"
        );
        assert_eq!(stdout, "", "{spec}: no header without rows");
    }
    // in a batch, the pairs with selections give their rows under one
    // header, the others are refused on standard error: exit 2
    let (code, stdout, stderr) = ravel(&[
        "verify",
        "--format",
        "csv",
        "specs/double_integrator.ravel",
        "specs/network/lane_carrl.ravel",
    ]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("no `select` block"), "{stderr}");
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines[0], ravel::report::network::CSV_HEADER);
    assert_eq!(lines.len(), 1 + 9 * 3, "{stdout}");
    assert!(
        lines[1..]
            .iter()
            .all(|l| l.starts_with("specs/network/lane_carrl.ravel,")),
        "{stdout}"
    );
}

/// `--format csv` prints the robust action selections of network specs.
#[test]
fn carrl_csv_output() {
    let (code, stdout, _) = ravel(&[
        "verify",
        "--format",
        "csv",
        "specs/network/lane_carrl.ravel",
    ]);
    assert_eq!(code, 0);
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(
        lines[0],
        "spec,select,observation,action,lower,upper,nominal,robust,robust_optimal"
    );
    // 3 inline and 6 file observations, 3 actions each
    assert_eq!(lines.len(), 1 + 9 * 3, "{stdout}");
    for l in &lines[1..] {
        let cells: Vec<&str> = l.split(',').collect();
        assert_eq!(cells.len(), 9, "{l}");
        let (lo, hi): (f64, f64) = (
            cells[4].parse().expect("lower"),
            cells[5].parse().expect("upper"),
        );
        assert!(lo <= hi, "{l}");
    }
}

/// Every file in `dir`, sorted (names only).
fn listing(dir: &std::path::Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// One result, one file: specs that share a file name (in two folders)
/// get distinct certificates and plots, named alike for any `--jobs` and
/// under `--shard`; each certificate is VALID for its own spec only; no
/// temporary file is left behind. A pair given twice is refused before
/// anything runs.
#[test]
fn a_batch_never_writes_two_results_to_one_file() {
    let root = std::env::temp_dir().join(format!("ravel-names-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    for d in ["a", "b", "models"] {
        std::fs::create_dir_all(root.join(d)).expect("dir");
    }
    let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    std::fs::copy(
        here.join("models/double_integrator.onnx"),
        root.join("models/double_integrator.onnx"),
    )
    .expect("model");
    // same file name, different problems (the second's goal is missed)
    std::fs::copy(
        here.join("specs/double_integrator.ravel"),
        root.join("a/di.ravel"),
    )
    .expect("spec");
    std::fs::copy(
        here.join("specs/double_integrator_falsified.ravel"),
        root.join("b/di.ravel"),
    )
    .expect("spec");
    let run = |extra: &[&str], out: &str, code: i32| {
        let o = bin()
            .current_dir(&root)
            .args([
                "verify",
                "a/di.ravel",
                "b/di.ravel",
                "--quiet",
                "--no-timing",
            ])
            .args(["--certificate", &format!("{out}/certs")])
            .args(["--plot", &format!("{out}/plots")])
            .args(extra)
            .output()
            .expect("runs");
        assert_eq!(
            o.status.code(),
            Some(code),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
    };
    run(&["--jobs", "1"], "one", 1);
    run(&["--jobs", "2"], "two", 1);
    // a's shard is VERIFIED, b's FALSIFIED
    run(&["--shard", "1/2"], "shards", 0);
    run(&["--shard", "2/2"], "shards", 1);
    for out in ["one", "two", "shards"] {
        assert_eq!(
            listing(&root.join(out).join("certs")),
            ["a~di.cert.json", "b~di.cert.json"],
            "{out}"
        );
        assert_eq!(
            listing(&root.join(out).join("plots")),
            ["a~di.svg", "b~di.svg"],
            "{out}"
        );
    }
    for (own, other) in [("a", "b"), ("b", "a")] {
        let cert = format!("one/certs/{own}~di.cert.json");
        let o = bin()
            .current_dir(&root)
            .args(["certify", &cert])
            .output()
            .expect("runs");
        let text = String::from_utf8_lossy(&o.stdout);
        assert_eq!(o.status.code(), Some(0), "{text}");
        assert!(text.starts_with("VALID"), "{text}");
        assert!(text.contains(&format!("{own}/di.ravel")), "{text}");
        // and not for the other spec of the same name
        let o = bin()
            .current_dir(&root)
            .args(["certify", &cert, "--spec", &format!("{other}/di.ravel")])
            .output()
            .expect("runs");
        assert_eq!(o.status.code(), Some(1), "{own} with {other}");
        // the plots are the pairs' own: only b's has a counterexample
        let svg =
            std::fs::read_to_string(root.join(format!("one/plots/{own}~di.svg"))).expect("plot");
        assert_eq!(svg.contains("counterexample of"), own == "b", "{own}");
    }
    // the same pair twice cannot be told apart: exit 2, nothing run or written
    let o = bin()
        .current_dir(&root)
        .args([
            "verify",
            "a/di.ravel",
            "./a/di.ravel",
            "--certificate",
            "twice",
        ])
        .output()
        .expect("runs");
    assert_eq!(o.status.code(), Some(2));
    assert!(o.stdout.is_empty());
    let msg = String::from_utf8_lossy(&o.stderr);
    assert!(msg.contains("given twice"), "{msg}");
    assert!(!root.join("twice").exists());
    let _ = std::fs::remove_dir_all(&root);
}

/// A spec named without its folder (run inside that folder) reads its
/// observation file from there, as `./name.ravel` does (issue 30: it used
/// to be E0219).
#[test]
fn a_bare_spec_name_reads_files_beside_it() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("specs/network");
    for name in ["lane_carrl.ravel", "./lane_carrl.ravel"] {
        let out = Command::new(env!("CARGO_BIN_EXE_ravel"))
            .args(["check", name])
            .current_dir(&dir)
            .output()
            .expect("runs");
        assert_eq!(
            out.status.code(),
            Some(0),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

/// Failing pairs of one spec keep their controllers apart in JUnit: each
/// suite is named after its spec and controller, like a pair that ran
/// (issue 30: two identical suite names).
#[test]
fn junit_suites_of_failing_pairs_name_their_controller() {
    let (code, stdout, _) = ravel(&[
        "verify",
        "--format",
        "junit",
        "specs/double_integrator.ravel",
        "--controller",
        "models/classifier.onnx",
        "--controller",
        "models/no_such_model.onnx",
    ]);
    assert_eq!(code, 2);
    let names: Vec<&str> = stdout
        .lines()
        .filter_map(|l| l.trim().strip_prefix("<testsuite name=\""))
        .filter_map(|l| l.split('"').next())
        .collect();
    assert_eq!(
        names,
        [
            "specs/double_integrator.ravel with controller models/classifier.onnx",
            "specs/double_integrator.ravel with controller models/no_such_model.onnx",
        ],
        "{stdout}"
    );
}

/// Pairs of one spec that ran with two controllers are two suites named
/// after their controllers too, never two identical `<testsuite name=…>`.
#[test]
fn junit_suites_of_pairs_that_ran_name_their_controller() {
    let (code, stdout, stderr) = ravel(&[
        "verify",
        "--format",
        "junit",
        "--fail-on",
        "falsified",
        "specs/double_integrator.ravel",
        "--controller",
        "models/double_integrator.onnx",
        "--controller",
        "models/double_integrator_tanh.onnx",
    ]);
    assert!(code == 0 || code == 1, "{stderr}");
    let doc = roxmltree::Document::parse(&stdout).expect("well-formed XML");
    let names: Vec<&str> = doc
        .descendants()
        .filter(|n| n.has_tag_name("testsuite"))
        .filter_map(|n| n.attribute("name"))
        .collect();
    assert_eq!(
        names,
        [
            "specs/double_integrator.ravel with controller models/double_integrator.onnx",
            "specs/double_integrator.ravel with controller models/double_integrator_tanh.onnx",
        ],
        "{stdout}"
    );
    // without --controller, the suite is the spec's path alone
    let (_, stdout, _) = ravel(&[
        "verify",
        "--format",
        "junit",
        "specs/double_integrator.ravel",
    ]);
    assert!(
        stdout.contains("<testsuite name=\"specs/double_integrator.ravel\" "),
        "{stdout}"
    );
    // a name longer than a message's 80 characters is kept whole (cut in
    // the middle, two pairs of long paths could share one suite)
    let (_, stdout, _) = ravel(&[
        "verify",
        "--format",
        "junit",
        "specs/double_integrator_falsified.ravel",
        "--controller",
        "models/double_integrator_tanh.onnx",
    ]);
    let long = "specs/double_integrator_falsified.ravel with controller models/double_integrator_tanh.onnx";
    assert!(long.chars().count() > 80);
    assert!(
        stdout.contains(&format!("<testsuite name=\"{long}\" ")),
        "{stdout}"
    );
}

/// A sharded run ends in JUnit: `merge --format junit` writes the unsharded
/// run's JUnit document byte for byte, for either gate; shards run with
/// another `--fail-on`, or whose suites were tampered with, are refused.
#[test]
fn shards_merge_into_the_unsharded_junit_report() {
    let dir = std::env::temp_dir().join(format!("ravel-junit-shards-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    for fail_on in ["unsure", "falsified"] {
        let whole = bin()
            .args(batch_args())
            .args(["--format", "junit", "--fail-on", fail_on])
            .output()
            .expect("runs");
        let mut files = Vec::new();
        for k in 1..=2 {
            let o = bin()
                .args(batch_args())
                .args(["--format", "json", "--fail-on", fail_on])
                .args(["--shard", &format!("{k}/2")])
                .output()
                .expect("runs");
            let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
            assert_eq!(v["fail_on"], fail_on);
            let f = dir.join(format!("{fail_on}-{k}.json"));
            std::fs::write(&f, &o.stdout).expect("write");
            files.push(f);
        }
        let merged = bin()
            .args(["merge", "--format", "junit", "--fail-on", fail_on])
            .args(&files)
            .output()
            .expect("runs");
        assert_eq!(merged.status.code(), whole.status.code(), "{fail_on}");
        assert_eq!(
            String::from_utf8_lossy(&merged.stdout),
            String::from_utf8_lossy(&whole.stdout),
            "{fail_on}"
        );
        let text = String::from_utf8(merged.stdout).expect("UTF-8");
        let doc = roxmltree::Document::parse(&text).expect("well-formed XML");
        assert_eq!(
            doc.descendants()
                .filter(|n| n.has_tag_name("testsuite"))
                .count(),
            6
        );
        // the merged JSON is still the unsharded JSON (no JUnit inside)
        let json = bin()
            .args(["merge", "--fail-on", fail_on])
            .args(&files)
            .output()
            .expect("runs");
        let whole_json = bin()
            .args(batch_args())
            .args(["--format", "json", "--fail-on", fail_on])
            .output()
            .expect("runs");
        assert_eq!(json.stdout, whole_json.stdout);
        // another gate than the shards': refused, not a JUnit report that
        // disagrees with the exit code
        let other = if fail_on == "unsure" {
            "falsified"
        } else {
            "unsure"
        };
        let o = bin()
            .args(["merge", "--format", "junit", "--fail-on", other])
            .args(&files)
            .output()
            .expect("runs");
        assert_eq!(o.status.code(), Some(2));
        assert!(
            String::from_utf8_lossy(&o.stderr).contains(&format!("--fail-on {fail_on}")),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(o.stdout.is_empty());
        if fail_on == "unsure" {
            // a suite replaced by something else is refused
            let text = std::fs::read_to_string(&files[0]).expect("read");
            let mut v: serde_json::Value = serde_json::from_str(&text).expect("JSON");
            v["results"][0]["junit"] = serde_json::json!("</testsuites><evil/>");
            let forged = dir.join("forged.json");
            std::fs::write(&forged, v.to_string()).expect("write");
            let o = bin()
                .args(["merge", "--format", "junit"])
                .arg(&forged)
                .arg(&files[1])
                .output()
                .expect("runs");
            assert_eq!(o.status.code(), Some(2));
            assert!(
                String::from_utf8_lossy(&o.stderr).contains("has no JUnit suite"),
                "{}",
                String::from_utf8_lossy(&o.stderr)
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// An unreadable `--controller` path is reported as such, with the rule
/// that holds for it (relative to the working folder), not the spec's own
/// path rule (issue 30).
#[test]
fn an_unreadable_controller_override_says_where_it_was_looked_for() {
    let (code, _, stderr) = ravel(&[
        "check",
        "specs/double_integrator.ravel",
        "--controller",
        "models/no_such_model.onnx",
    ]);
    assert_eq!(code, 2);
    assert!(stderr.contains("E0301"), "{stderr}");
    assert!(stderr.contains("given with --controller"), "{stderr}");
    assert!(
        stderr.contains("relative to the working folder"),
        "{stderr}"
    );
    assert!(
        !stderr.contains("relative to the spec file's folder"),
        "{stderr}"
    );
}

/// A `--controller` that loads but does not fit the spec, or is not ONNX,
/// is named as the command line's file: the spec's own `controller` line is
/// only where it stands in, not the cause (issue 30).
#[test]
fn a_controller_override_that_does_not_fit_is_named_as_the_override() {
    let (code, _, stderr) = ravel(&[
        "check",
        "specs/double_integrator.ravel",
        "--controller",
        "models/classifier.onnx",
    ]);
    assert_eq!(code, 2);
    assert!(stderr.contains("E0305"), "{stderr}");
    assert!(
        stderr.contains(
            "the controller `models/classifier.onnx` (given with --controller) has 3 outputs"
        ),
        "{stderr}"
    );
    assert!(
        stderr.contains("3 outputs: the --controller file, not the spec's controller"),
        "{stderr}"
    );
    // without the override, the spec's own controller is the one named
    let (code, _, stderr) = ravel(&["check", "specs/invalid/controller_outputs.ravel"]);
    assert_eq!(code, 2);
    assert!(stderr.contains("the controller has"), "{stderr}");
    assert!(!stderr.contains("--controller"), "{stderr}");
    // a file that is not ONNX
    let (code, _, stderr) = ravel(&[
        "check",
        "specs/double_integrator.ravel",
        "--controller",
        "specs/double_integrator.ravel",
    ]);
    assert_eq!(code, 2);
    assert!(stderr.contains("E0302"), "{stderr}");
    assert!(
        stderr.contains("(given with --controller)")
            && stderr.contains("in the --controller file, not the spec's controller"),
        "{stderr}"
    );
}
