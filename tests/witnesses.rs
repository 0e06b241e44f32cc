//! Every VERIFIED certifiable (issue 26): a verdict only Reach-SDP proves
//! certifies VALID (the writer refines the partition until the checker's
//! own chain proves it); network proofs that need the input set's own
//! shape — an ℓp ball (its dual norm) or a polytope (LP duals, recorded in
//! the certificate as witnesses) — certify VALID, and their witnesses
//! cannot prove a false claim.

mod common;

use ravel::execute::Verdict;
use ravel::ir::NetPropagator;
use ravel::ir::{NetProperty, NetPropertyKind};
use ravel::lower::NetworkPlan;
use ravel_analysis::sets::{IBox, Norm, Polytope, Region};
use ravel_base::nn::{Layer, Network};
use ravel_certify::Answer;
use serde_json::{json, Value};

/// The double integrator's goal narrowed to `x[1] ≤ 0.2` at step 5:
/// Reach-SDP proves it on one cell (its box reaches 0.158), Reach-LP does
/// not (0.257), nor does the checker's chain on the one cell. The writer
/// bisects the cell until the checker's chain proves it: VALID, with more
/// cells than the analysis used; a goal the analysis could not prove, made
/// VERIFIED by force, is not.
#[test]
fn a_verdict_only_reach_sdp_proves_certifies_valid() {
    let source = std::fs::read_to_string("specs/double_integrator_sdp.ravel").expect("spec");
    let narrowed = source.replace("x[1] in [-1.5, 0.5]", "x[1] in [-1.5, 0.2]");
    assert_ne!(narrowed, source);
    let analyse = |src: &str| {
        let checked =
            ravel::front_end(src, std::path::Path::new("specs"), &ravel_cli::read_request)
                .expect("the spec checks");
        let plan = ravel::lower::lower_system(&checked);
        let outcome = ravel::execute::execute_system(&plan, &ravel::execute::Control::unlimited());
        (plan, outcome)
    };
    let (lp_plan, lp_out) = analyse(&narrowed.replace("reach_sdp", "reach_lp"));
    assert_eq!(lp_plan.propagator.name(), "reach_lp");
    assert_ne!(
        lp_out.properties[0].status,
        Verdict::Verified,
        "Reach-LP proves it too"
    );
    let (plan, outcome) = analyse(&narrowed);
    assert_eq!(outcome.properties[0].status, Verdict::Verified);
    assert_eq!(outcome.cells.len(), 1);
    let id = ravel::certificate_writer::Identity {
        spec_path: String::new(),
        spec_sha256: String::new(),
    };
    let cert = ravel::certificate_writer::build_system(&plan, &outcome, &id);
    assert_eq!(
        cert["evidence"]["status"], "checkable",
        "{}",
        cert["evidence"]
    );
    let cells = cert["evidence"]["cells"].as_array().expect("cells").len();
    assert!(cells > 1, "{cells} cell(s)");
    assert_eq!(
        ravel_certify::check(&cert, plan.closed_loop.net()).answer,
        Answer::Valid
    );
    // dropping one refined cell leaves X0 uncovered: INVALID
    let mut dropped = cert.clone();
    dropped["evidence"]["cells"]
        .as_array_mut()
        .expect("cells")
        .pop();
    assert!(matches!(
        ravel_certify::check(&dropped, plan.closed_loop.net()).answer,
        Answer::Invalid(_)
    ));
    // a goal no analysis proves (x[1] ≤ −0.04 at step 5, while sampled
    // states reach −0.033), forced to VERIFIED: the refinement gives up
    let (plan, mut outcome) =
        analyse(&source.replace("x[1] in [-1.5, 0.5]", "x[1] in [-1.5, -0.04]"));
    assert_ne!(outcome.properties[0].status, Verdict::Verified);
    outcome.properties[0].status = Verdict::Verified;
    outcome.properties[0].counterexample = None;
    let cert = ravel::certificate_writer::build_system(&plan, &outcome, &id);
    assert_eq!(cert["evidence"]["status"], "unsupported");
    assert!(matches!(
        ravel_certify::check(&cert, plan.closed_loop.net()).answer,
        Answer::Unsupported(_)
    ));
}

/// `y = x₀ + x₁` through a ReLU layer that is active on the whole input
/// set (so the network is exactly linear there).
fn sum_network() -> Network {
    Network::new(
        2,
        vec![
            Layer::Affine {
                w: nalgebra::DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 1.0]),
                b: nalgebra::DVector::from_vec(vec![10.0, 10.0]),
            },
            Layer::Act(ravel_base::nn::Activation::Relu),
            Layer::Affine {
                w: nalgebra::DMatrix::from_row_slice(1, 2, &[1.0, 1.0]),
                b: nalgebra::DVector::from_vec(vec![-20.0]),
            },
        ],
    )
}

fn plan(input: Region, bound: f64) -> NetworkPlan {
    let mut p = common::net_plan(
        sum_network(),
        input,
        vec![NetProperty {
            name: "bounded".into(),
            kind: NetPropertyKind::Require(Polytope {
                rows: vec![(vec![1.0], bound)],
            }),
        }],
    );
    p.samples = 100;
    p.seed = 5;
    p
}

fn answer(cert: &Value, p: &NetworkPlan) -> Answer {
    ravel_certify::network::check(cert, &p.net).answer
}

/// `x₀ + x₁ ≤ 1.5` on the unit ℓ2 ball (its maximum is √2 ≈ 1.414; over
/// the bounding box it is 2): the analysis proves it with the dual norm,
/// and so does the checker. The same on the ℓ1 ball (maximum 1).
#[test]
fn ball_input_proofs_certify_valid() {
    for (norm, bound, false_bound) in [(Norm::L2, 1.5, 1.4), (Norm::L1, 1.01, 0.99)] {
        let ball = Region::Ball {
            center: vec![0.0, 0.0],
            radius: vec![1.0, 1.0],
            norm,
        };
        let p = plan(ball.clone(), bound);
        let out = common::run_net(&p);
        assert_eq!(out.properties[0].status, Verdict::Verified, "{norm:?}");
        let cert = common::net_certificate(&p, &out);
        assert_eq!(cert["evidence"]["status"], "checkable", "{norm:?}: {cert}");
        assert_eq!(answer(&cert, &p), Answer::Valid, "{norm:?}");
        // a false claim with the same evidence: never VALID
        let mut forged = cert.clone();
        forged["problem"]["properties"][0]["rows"][0]["b"] = json!(false_bound);
        let false_plan = plan(ball, false_bound);
        assert!(
            matches!(answer(&forged, &false_plan), Answer::Invalid(_)),
            "{norm:?}: a false bound certified"
        );
    }
}

/// `x₀ + x₁ ≤ 1.01` on `{x ∈ [0, 1]² | x₀ + x₁ ≤ 1}`: the box alone gives 2,
/// the polytope 1. The certificate carries one LP dual per row; the checker
/// bounds the support with it. Duals of any size (negative, huge, wrong
/// length) cannot prove a false bound.
#[test]
fn polytope_input_proofs_certify_valid_with_dual_witnesses() {
    let poly = Region::Polytope {
        bbox: IBox::new(vec![0.0, 0.0], vec![1.0, 1.0]),
        rows: vec![(vec![1.0, 1.0], 1.0)],
    };
    let p = plan(poly.clone(), 1.01);
    let out = common::run_net(&p);
    assert_eq!(out.properties[0].status, Verdict::Verified);
    let cert = common::net_certificate(&p, &out);
    assert_eq!(cert["evidence"]["status"], "checkable", "{cert}");
    assert_eq!(answer(&cert, &p), Answer::Valid);
    // the claim made false (0.9 < 1): INVALID whatever the duals
    let false_plan = plan(poly, 0.9);
    assert_eq!(
        cert["evidence"]["cells"][0]["duals"]
            .as_array()
            .map(Vec::len),
        Some(1)
    );
    for duals in [
        json!([[1.0]]),
        json!([[3.5e307]]),
        json!([[-1.0]]),
        json!([[1e300, 1e300]]),
        json!([[]]),
        json!([]),
    ] {
        let mut forged = cert.clone();
        forged["problem"]["properties"][0]["rows"][0]["b"] = json!(0.9);
        forged["evidence"]["cells"][0]["duals"] = duals.clone();
        assert!(
            matches!(answer(&forged, &false_plan), Answer::Invalid(_)),
            "duals {duals} proved a false bound"
        );
    }
    // without its duals the true claim is not established (the box alone
    // gives 2)
    let mut bare = cert.clone();
    if let Some(c) = bare["evidence"]["cells"][0].as_object_mut() {
        c.remove("duals");
    }
    assert!(matches!(answer(&bare, &p), Answer::Invalid(_)));
}

/// A random ReLU network on a box where the network SDP's bound of `y₀` is
/// tighter than CROWN's: `require y₀ ≤ b` with `b` between the two is
/// VERIFIED by the SDP only. The writer bisects the cell until the
/// checker's CROWN-style bounds prove it: VALID, with more cells than the
/// analysis used.
#[test]
fn a_network_verdict_only_the_sdp_proves_certifies_valid() {
    let mut rng = ravel_base::rng::Rng::new(11);
    let input = Region::Box(IBox::new(vec![-1.0, -1.0], vec![1.0, 1.0]));
    let mut found = false;
    for _ in 0..20 {
        let net = common::relu_network(&mut rng, &[2, 8, 8, 1], 1.5, 0.3);
        let bound_with = |prop: NetPropagator| {
            let mut p = plan(input.clone(), 1e9);
            p.net = net.clone();
            p.propagator = prop;
            1e9 - common::run_net(&p).properties[0].margin
        };
        let (sdp, crown) = (
            bound_with(NetPropagator::Sdp),
            bound_with(NetPropagator::Crown),
        );
        if !(sdp.is_finite() && crown - sdp > 1e-3 * (1.0 + crown.abs())) {
            continue;
        }
        let mut p = plan(input.clone(), (sdp + crown) / 2.0);
        p.net = net.clone();
        p.propagator = NetPropagator::Sdp;
        let out = common::run_net(&p);
        assert_eq!(out.properties[0].status, Verdict::Verified);
        let cert = common::net_certificate(&p, &out);
        assert_eq!(
            cert["evidence"]["status"], "checkable",
            "{}",
            cert["evidence"]
        );
        let cells = cert["evidence"]["cells"].as_array().map_or(0, Vec::len);
        assert!(cells > out.partition.len(), "{cells} cells");
        assert_eq!(answer(&cert, &p), Answer::Valid);
        found = true;
        break;
    }
    assert!(found, "no network where the SDP is tighter than CROWN");
}

/// Monte Carlo: the checker's rows concretised over a cell intersected with
/// an ℓp ball (dual norm) or a polytope (any nonnegative duals, here random
/// ones of every size) are never below `s·f(x)` at sampled points of the
/// intersection, on random ReLU networks.
#[test]
fn checker_rows_over_balls_and_polytopes_contain_samples() {
    use ravel_certify::bounds::{Bx, Duals, NetBounds, Start};
    let mut rng = ravel_base::rng::Rng::new(26);
    let mut checked = 0;
    for case in 0..60 {
        let net = common::relu_network(&mut rng, &[2, 6, 6, 2], 1.5, 0.3);
        let center = [rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)];
        let radius = [rng.uniform(0.05, 1.0), rng.uniform(0.05, 1.0)];
        let cell = Bx {
            lo: vec![center[0] - radius[0], center[1] - radius[1]],
            hi: vec![center[0] + radius[0], center[1] + radius[1]],
        };
        let spec = nalgebra::DMatrix::from_fn(3, 2, |_, _| rng.normal());
        let nb = NetBounds::new(&net, &cell, None).expect("finite");
        // the sets and their membership tests
        let norm = ["1", "2", "inf"][case % 3];
        let rows: Vec<(Vec<f64>, f64)> = (0..2)
            .map(|_| {
                let a = vec![rng.normal(), rng.normal()];
                let h = a[0] * center[0] + a[1] * center[1] + rng.uniform(0.0, 0.5);
                (a, h)
            })
            .collect();
        let duals: Vec<Vec<f64>> = (0..spec.nrows())
            .map(|_| (0..2).map(|_| rng.uniform(0.0, 3.0).powi(3)).collect())
            .collect();
        let given = Duals::given(&duals);
        let starts = [
            Start::Ball {
                center: &center,
                radius: &radius,
                norm,
            },
            Start::Polytope {
                rows: &rows,
                duals: &given,
            },
        ];
        for (k, start) in starts.iter().enumerate() {
            let bound = nb.rows_upper_in(&spec, 0, start);
            for _ in 0..400 {
                let x = [
                    rng.uniform(cell.lo[0], cell.hi[0]),
                    rng.uniform(cell.lo[1], cell.hi[1]),
                ];
                let inside = if k == 0 {
                    let d = [
                        (x[0] - center[0]) / radius[0],
                        (x[1] - center[1]) / radius[1],
                    ];
                    match norm {
                        "1" => d[0].abs() + d[1].abs() <= 1.0,
                        "2" => d[0] * d[0] + d[1] * d[1] <= 1.0,
                        _ => true,
                    }
                } else {
                    rows.iter().all(|(a, h)| a[0] * x[0] + a[1] * x[1] <= *h)
                };
                if !inside {
                    continue;
                }
                let y = net.forward(&x);
                for r in 0..spec.nrows() {
                    let v = spec[(r, 0)] * y[0] + spec[(r, 1)] * y[1];
                    assert!(
                        v <= bound[r] + 1e-9 * (1.0 + v.abs()),
                        "case {case}, set {k}, row {r}: {v} above {}",
                        bound[r]
                    );
                    checked += 1;
                }
            }
        }
    }
    assert!(checked > 20_000, "{checked}");
}
