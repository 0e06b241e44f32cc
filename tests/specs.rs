//! The spec corpus as tests: every file under `specs/` is parsed, checked and
//! (if valid) verified, and the results are compared with insta snapshots.
//!
//! Category guards run before any snapshot is taken, so a wrong snapshot
//! cannot be accepted by accident:
//! * `specs/*.ravel` must check without diagnostics, and the verdict must equal
//!   the `// expect: VERDICT` header;
//! * `specs/invalid/*.ravel` must fail with exactly the codes listed in the
//!   `// expect: E0xxx …` header.

use std::collections::BTreeSet;
use std::path::Path;

use ravel_syntax::diag::render;

mod common;

fn expect_header(source: &str) -> Vec<String> {
    let line = source.lines().next().unwrap_or_default();
    let rest = line
        .strip_prefix("// expect:")
        .unwrap_or_else(|| panic!("spec must start with `// expect: …`, found {line:?}"));
    rest.split_whitespace().map(str::to_string).collect()
}

fn display_name(path: &Path) -> String {
    let s = path.to_string_lossy().replace('\\', "/");
    let i = s
        .rfind("/specs/")
        .or_else(|| s.rfind("/benchmarks/"))
        .map_or(0, |i| i + 1);
    s[i..].to_string()
}

/// Every fixed-point number with 6 decimals, printed with 4 (rounded).
fn fewer_decimals(text: &str) -> String {
    let mut out = String::new();
    let mut token = String::new();
    let flush = |token: &mut String, out: &mut String| {
        let frac = token.split_once('.').map(|(_, f)| f.len());
        match (frac, token.parse::<f64>()) {
            (Some(6), Ok(v)) => out.push_str(&format!("{v:.4}")),
            _ => out.push_str(token),
        }
        token.clear();
    };
    for ch in text.chars() {
        if ch.is_ascii_digit() || ch == '.' || (ch == '-' && token.is_empty()) {
            token.push(ch);
        } else {
            if ch == 'e' && !token.is_empty() {
                // scientific notation: keep as printed
                out.push_str(&token);
                token.clear();
                out.push(ch);
                continue;
            }
            flush(&mut token, &mut out);
            out.push(ch);
        }
    }
    flush(&mut token, &mut out);
    out
}

fn parse_snapshot(name: &str, source: &str) -> String {
    match ravel_syntax::parse(source) {
        Ok(ast) => format!("{ast:#?}\n"),
        Err(d) => render(&d, name, source, 100, false),
    }
}

#[test]
fn valid_specs() {
    insta::glob!("../specs", "*.ravel", system_spec);
}

/// The benchmark suite (`benchmarks/`: ARCH-COMP AINNCS and ReachNN with
/// the project's own controllers), each as a shipped spec: the verdict of
/// its `// expect:` header, samples inside the reachable sets, snapshots.
#[test]
fn benchmark_specs() {
    insta::glob!("../benchmarks", "*.ravel", system_spec);
}

/// One closed-loop spec: front end, plan, execution; the verdict of the
/// `// expect:` header, every simulated state inside the reachable set's
/// bounding box; snapshots of the syntax tree, the report and the
/// certificate's check.
fn system_spec(path: &std::path::Path) {
    {
        let source = std::fs::read_to_string(path).expect("spec is readable");
        let name = display_name(path);
        let expect = expect_header(&source);
        let checked = match ravel::front_end(
            &source,
            path.parent().expect("spec has a folder"),
            &ravel_cli::read_request,
        ) {
            Ok(c) => c,
            Err(d) => panic!(
                "{name} is a valid spec but has diagnostics:\n{}",
                render(&d, &name, &source, 100, false)
            ),
        };
        let plan = ravel::lower::lower_system(&checked);
        let outcome = ravel::execute::execute_system(&plan, &ravel::execute::Control::unlimited());
        // every simulated state lies in the reachable set's bounding box
        for (t, (reach, sampled)) in outcome.reach.iter().zip(&outcome.sampled).enumerate() {
            if let Some(s) = sampled {
                assert!(
                    reach.contains_box(s),
                    "{name}: sampled states at step {t} leave the reachable set"
                );
            }
        }
        assert_eq!(
            vec![outcome.verdict.as_str().to_string()],
            expect,
            "{name}: verdict differs from its `// expect:` header"
        );
        insta::assert_snapshot!("parse", parse_snapshot(&name, &source));
        let mut report = ravel::report::system::text(&name, &plan, &outcome, None);
        if plan.propagator == ravel_analysis::closed_loop::Propagator::ReachSdp {
            // The SDP solver's LAPACK may round differently on another CPU:
            // its certified bounds are snapshotted at 4 decimals.
            report = fewer_decimals(&report);
        }
        insta::assert_snapshot!("result", report);
        insta::assert_snapshot!("certificate", certificate_summary(&name, &plan, &outcome));
    }
}

/// The certificate of a result, checked: the category guard (every shipped
/// spec's and benchmark's certificate is VALID, nonlinear plants' too),
/// then a summary for the snapshot.
fn certificate_summary(
    name: &str,
    plan: &ravel::lower::SystemPlan,
    outcome: &ravel::execute::SystemOutcome,
) -> String {
    use ravel_certify::Answer;
    let id = ravel::certificate_writer::Identity {
        spec_path: name.to_string(),
        spec_sha256: String::new(),
    };
    let cert = ravel::certificate_writer::build_system(plan, outcome, &id);
    // the document survives a round trip through its text exactly
    let text = serde_json::to_string(&cert).expect("serialisable");
    let back: serde_json::Value = serde_json::from_str(&text).expect("parses");
    assert_eq!(back, cert, "{name}: certificate does not round-trip");
    let report = ravel_certify::check(&back, plan.closed_loop.net());
    // linear and nonlinear plants alike: the checker re-derives every claim
    assert_eq!(
        report.answer,
        Answer::Valid,
        "{name}: certificate not VALID"
    );
    let mut s = format!("answer: {:?}\n", report.answer);
    s += &format!("evidence: {}\n", cert["evidence"]["status"]);
    s += &format!("cells × steps: {} × {}\n", report.cells, report.steps);
    for p in &report.properties {
        s += &format!("{p}\n");
    }
    s
}

/// Network specs (`specs/network/`): the verdict of the `// expect:` header,
/// every sampled output inside the certified output box, every robustness
/// and radius result consistent with its witnesses; snapshots of the syntax
/// tree and of the report.
#[test]
fn network_specs() {
    use ravel::execute::Verdict;
    insta::glob!("../specs/network", "*.ravel", |path| {
        let source = std::fs::read_to_string(path).expect("spec is readable");
        let name = display_name(path);
        let expect = expect_header(&source);
        let checked = match ravel::front_end_task(
            &source,
            path.parent().expect("spec has a folder"),
            &ravel_cli::read_request,
            None,
        ) {
            Ok(ravel::check::Task::Network(c)) => c,
            Ok(ravel::check::Task::System(_)) => panic!("{name} is not a network spec"),
            Err(d) => panic!(
                "{name} is a valid spec but has diagnostics:\n{}",
                render(&d, &name, &source, 100, false)
            ),
        };
        let plan = ravel::lower::lower_network(&checked);
        let out = common::run_net(&plan);
        if let (Some(b), Some(s)) = (&out.output.bbox, &out.output.sampled_bbox) {
            assert!(
                b.contains_box(s),
                "{name}: sampled outputs leave the output set"
            );
        }
        for (k, sampled) in out.output.sampled.iter().enumerate() {
            assert!(
                *sampled <= out.output.offsets[k],
                "{name}: facet {k} below a sampled output"
            );
        }
        for p in &out.properties {
            match p.status {
                Verdict::Verified => assert!(p.margin >= 0.0 && p.counterexample.is_none()),
                Verdict::Falsified => {
                    let w = p.counterexample.as_ref().expect("a witness");
                    assert!(
                        plan.input
                            .as_ref()
                            .is_some_and(|i| i.contains_point(&w.input)),
                        "{name}: witness outside"
                    );
                    assert_eq!(plan.net.forward(&w.input), w.output);
                }
                Verdict::Unsure => assert!(p.counterexample.is_none()),
            }
        }
        for r in &out.radii {
            if let (Some(c), Some((a, _))) = (r.certified, &r.attacked) {
                assert!(c <= *a, "{name}: certified radius above an attacked one");
            }
        }
        assert_eq!(
            vec![out.verdict.as_str().to_string()],
            expect,
            "{name}: verdict differs from its `// expect:` header"
        );
        // the category guard of certificates: every shipped network spec's is VALID
        let cert = ravel::certificate_writer::build_network(
            &plan,
            &out,
            &ravel::certificate_writer::Identity {
                spec_path: name.clone(),
                spec_sha256: String::new(),
            },
        );
        let text = serde_json::to_string(&cert).expect("serialisable");
        let back: serde_json::Value = serde_json::from_str(&text).expect("parses");
        assert_eq!(back, cert, "{name}: certificate does not round-trip");
        let checked = ravel_certify::check(&back, &plan.net);
        assert_eq!(
            checked.answer,
            ravel_certify::Answer::Valid,
            "{name}: certificate not VALID: {:?}",
            checked.properties
        );
        insta::assert_snapshot!("parse", parse_snapshot(&name, &source));
        let mut report = ravel::report::network::text(&name, &plan, &out, None);
        if plan.propagator == ravel::ir::NetPropagator::Sdp {
            report = fewer_decimals(&report);
        }
        insta::assert_snapshot!("result", report);
    });
}

#[test]
fn invalid_specs() {
    insta::glob!("../specs/invalid", "*.ravel", |path| {
        let source = std::fs::read_to_string(path).expect("spec is readable");
        let name = display_name(path);
        let expect: BTreeSet<String> = expect_header(&source).into_iter().collect();
        let diags = match ravel::front_end_task(
            &source,
            path.parent().expect("spec has a folder"),
            &ravel_cli::read_request,
            None,
        ) {
            Ok(_) => panic!("{name} is an invalid spec but checks without diagnostics"),
            Err(d) => d,
        };
        let codes: BTreeSet<String> = diags.iter().map(|d| d.code.as_str().to_string()).collect();
        assert_eq!(
            codes, expect,
            "{name}: diagnostic codes differ from its `// expect:` header"
        );
        for d in &diags {
            assert!(d.hint.is_some(), "{name}: {} has no hint", d.code.as_str());
            assert!(d.span.is_some(), "{name}: {} has no span", d.code.as_str());
        }
        insta::assert_snapshot!("parse", parse_snapshot(&name, &source));
        insta::assert_snapshot!("diagnostics", render(&diags, &name, &source, 100, false));
    });
}

/// Valid specs with nonlinear plants, `observe` and `actuate`
/// (`tests/nonlinear/`; not under `specs/`, whose specs are all executed,
/// while the analysis of nonlinear plants is not built yet): they check
/// and lower; snapshots of the syntax tree and of what check and lowering
/// made of them (the tape, the observation, the folded network's layers).
#[test]
fn nonlinear_fixtures() {
    use ravel::check::PlantSpec;
    insta::glob!("nonlinear", "*.ravel", |path| {
        let source = std::fs::read_to_string(path).expect("spec is readable");
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let checked = match ravel::front_end(
            &source,
            path.parent().expect("spec has a folder"),
            &ravel_cli::read_request,
        ) {
            Ok(c) => c,
            Err(d) => panic!(
                "{name} has diagnostics:\n{}",
                render(&d, &name, &source, 100, false)
            ),
        };
        // formatting keeps the meaning and is idempotent
        let once = ravel_syntax::fmt::format(&source).expect("formats");
        assert_eq!(ravel_syntax::fmt::format(&once).expect("formats"), once);
        insta::assert_snapshot!("parse", parse_snapshot(&name, &source));
        let net = ravel::lower::folded_network(&checked);
        let mut s = String::new();
        match &checked.plant {
            PlantSpec::Nonlinear(p) => {
                let l = ravel::lower::nonlinear_loop(&checked).expect("a nonlinear loop");
                assert_eq!(l.net, net);
                assert_eq!(l.states(), checked.state.1);
                assert!(p.field.tape.is_well_formed(p.field.vars()));
                s += &format!("field: {:?}\n", p.field.time);
                s += &format!(
                    "n m p: {} {} {}\n",
                    p.field.states, p.field.controls, p.field.disturbances
                );
                for (i, node) in p.field.tape.nodes.iter().enumerate() {
                    s += &format!("  {i}: {node:?}\n");
                }
                s += &format!("outputs: {:?}\n", p.field.outputs);
                s += &format!("w: {:?} .. {:?}\n", p.w.lo, p.w.hi);
                s += &format!(
                    "obs (n × k): {:?}\n",
                    p.obs
                        .row_iter()
                        .map(|r| r.iter().copied().collect::<Vec<_>>())
                        .collect::<Vec<_>>()
                );
                s += &format!("v: {:?} .. {:?}\n", p.v.lo, p.v.hi);
            }
            PlantSpec::Linear(plants) => {
                assert!(ravel::lower::nonlinear_loop(&checked).is_none());
                let plan = ravel::lower::lower_system(&checked);
                assert_eq!(plan.closed_loop.net(), &net);
                let obs = &plants[0].obs;
                s += &format!("linear, {} plant(s)\n", plants.len());
                s += &format!(
                    "obs (n × k): {:?}\n",
                    obs.row_iter()
                        .map(|r| r.iter().copied().collect::<Vec<_>>())
                        .collect::<Vec<_>>()
                );
                s += &format!("v: {:?} .. {:?}\n", plants[0].v.lo, plants[0].v.hi);
            }
        }
        s += &format!(
            "observe offset: {:?}\n",
            checked
                .observe_offset
                .as_ref()
                .map(|d| d.iter().copied().collect::<Vec<_>>())
        );
        s += &format!(
            "network: {} inputs, {} layers, {} outputs\n",
            net.inputs,
            net.layers.len(),
            net.outputs()
        );
        for layer in &net.layers {
            match layer {
                ravel_base::nn::Layer::Affine { w, b } => {
                    s += &format!("  affine {} × {}", w.nrows(), w.ncols());
                    if w.nrows() * w.ncols() <= 4 {
                        s += &format!(
                            " w {:?} b {:?}",
                            w.iter().collect::<Vec<_>>(),
                            b.iter().collect::<Vec<_>>()
                        );
                    }
                    s += "\n";
                }
                ravel_base::nn::Layer::Act(a) => s += &format!("  {}\n", a.name()),
            }
        }
        insta::assert_snapshot!("checked", s);
    });
}
