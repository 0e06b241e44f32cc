//! Every VERIFIED certifiable (issue 26): a verdict only Reach-SDP proves
//! certifies VALID (the writer refines the partition until the checker's
//! own chain proves it); network proofs that need the input set's own
//! shape — an ℓp ball (its dual norm) or a polytope (LP duals, recorded in
//! the certificate as witnesses) — certify VALID, and their witnesses
//! cannot prove a false claim.

use ravel::certify::Answer;
use ravel::execute::Status;

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
        let checked = ravel::front_end(
            src,
            std::path::Path::new("specs"),
            &ravel::cli::read_request,
        )
        .expect("the spec checks");
        let plan = ravel::lower::lower(&checked);
        let outcome = ravel::execute::execute(&plan, &|| 0.0);
        (plan, outcome)
    };
    let (lp_plan, lp_out) = analyse(&narrowed.replace("reach_sdp", "reach_lp"));
    assert_eq!(lp_plan.propagator.name(), "reach_lp");
    assert_ne!(
        lp_out.properties[0].status,
        Status::Verified,
        "Reach-LP proves it too"
    );
    let (plan, outcome) = analyse(&narrowed);
    assert_eq!(outcome.properties[0].status, Status::Verified);
    assert_eq!(outcome.cells.len(), 1);
    let id = ravel::certificate::Identity {
        spec_path: String::new(),
        spec_sha256: String::new(),
    };
    let cert = ravel::certificate::build(&plan, &outcome, &id);
    assert_eq!(
        cert["evidence"]["status"], "checkable",
        "{}",
        cert["evidence"]
    );
    let cells = cert["evidence"]["cells"].as_array().expect("cells").len();
    assert!(cells > 1, "{cells} cell(s)");
    assert_eq!(
        ravel::certify::check(&cert, &plan.closed_loop.net).answer,
        Answer::Valid
    );
    // dropping one refined cell leaves X0 uncovered: INVALID
    let mut dropped = cert.clone();
    dropped["evidence"]["cells"]
        .as_array_mut()
        .expect("cells")
        .pop();
    assert!(matches!(
        ravel::certify::check(&dropped, &plan.closed_loop.net).answer,
        Answer::Invalid(_)
    ));
    // a goal no analysis proves (x[1] ≤ −0.04 at step 5, while sampled
    // states reach −0.033), forced to VERIFIED: the refinement gives up
    let (plan, mut outcome) =
        analyse(&source.replace("x[1] in [-1.5, 0.5]", "x[1] in [-1.5, -0.04]"));
    assert_ne!(outcome.properties[0].status, Status::Verified);
    outcome.properties[0].status = Status::Verified;
    outcome.properties[0].counterexample = None;
    let cert = ravel::certificate::build(&plan, &outcome, &id);
    assert_eq!(cert["evidence"]["status"], "unsupported");
    assert!(matches!(
        ravel::certify::check(&cert, &plan.closed_loop.net).answer,
        Answer::Unsupported(_)
    ));
}
