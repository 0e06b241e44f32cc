//! Tightness orders that hold by the mathematics of the methods (and that
//! ravel keeps by construction where floating point could break them):
//!
//! * a partitioned run is never looser than the same method on the cell's
//!   parent (each cell's sets lie in the parent's sets, step by step);
//! * Reach-LP is never looser than CL-CROWN on the same input set;
//! * Reach-SDP is never looser than Reach-LP;
//! * the final-step errors on the double integrator order as the tutorial's
//!   Table II says (IBP ≥ CL-CROWN ≥ Reach-LP ≥ partitioned Reach-LP), and
//!   unrolled CROWN beats step-by-step Reach-LP.

use std::path::Path;

use ravel::execute::{execute_system, propagate_cell, Control};
use ravel::lower::{lower_system, Partitioner, SystemPlan};
use ravel_analysis::closed_loop::{Boundary, Propagator};
use ravel_analysis::sets::{IBox, Region};

fn plan(spec: &str, prop: Propagator, partitioner: Partitioner, boundary: Boundary) -> SystemPlan {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(spec);
    let src = std::fs::read_to_string(&path).expect("spec");
    let mut c = ravel::front_end(&src, path.parent().expect("dir"), &ravel_cli::read_request)
        .expect("valid spec");
    c.propagator = prop;
    c.partitioner = partitioner;
    c.boundary = boundary;
    c.samples = 1000;
    lower_system(&c)
}

/// `inner ⊆ outer` for the sets ravel produces (boxes, or polytopes with the same rows).
fn within(inner: &Region, outer: &Region) -> bool {
    let (bi, bo) = (inner.bbox(), outer.bbox());
    if !bo.contains_box(&bi) {
        return false;
    }
    match (inner, outer) {
        (Region::Polytope { rows: ri, .. }, Region::Polytope { rows: ro, .. }) => {
            ri.iter().zip(ro).all(|(a, b)| a.1 <= b.1)
        }
        _ => true,
    }
}

fn sets(plan: &SystemPlan, cell: &Region) -> Vec<Region> {
    propagate_cell(plan, cell, None)
        .into_iter()
        .map(|s| s.set)
        .collect()
}

#[test]
fn partitioned_runs_are_never_looser_than_their_parent() {
    for spec in [
        "specs/double_integrator.ravel",
        "specs/double_integrator_noisy.ravel",
    ] {
        for prop in [
            Propagator::ReachLp,
            Propagator::CrownUnrolled,
            Propagator::CrownSeparate,
            Propagator::IbpSeparate,
        ] {
            for boundary in [Boundary::Box, Boundary::spread(8)] {
                let p = plan(
                    spec,
                    prop,
                    Partitioner::Uniform(vec![3, 2]),
                    boundary.clone(),
                );
                let parent = sets(&p, &p.initial);
                let out = execute_system(&p, &Control::unlimited());
                assert_eq!(out.cells.len(), 6);
                for (c, cell) in out.cells.iter().enumerate() {
                    for t in 0..=p.horizon {
                        assert!(
                            within(&cell[t], &parent[t]),
                            "{spec} {prop:?} {boundary:?}: cell {c} at step {t} is looser than X0's set"
                        );
                    }
                }
                // guided refinement: every leaf inside the root's sets
                let g = plan(
                    spec,
                    prop,
                    Partitioner::Guided {
                        guide: ravel::lower::Guide::Gsg,
                        budget: ravel_analysis::partition::Budget {
                            calls: 9,
                            min_size: 0.01,
                            seconds: None,
                        },
                    },
                    boundary,
                );
                let out = execute_system(&g, &Control::unlimited());
                for cell in &out.cells {
                    for t in 0..=g.horizon {
                        assert!(within(&cell[t], &parent[t]), "{spec} {prop:?} gsg step {t}");
                    }
                }
            }
        }
    }
}

#[test]
fn reach_lp_is_never_looser_than_cl_crown_and_sdp_never_looser_than_reach_lp() {
    let spec = "specs/double_integrator.ravel";
    let box_cells = IBox::new(vec![2.5, -0.25], vec![3.0, 0.25]).grid(&[2, 2]);
    for boundary in [Boundary::Box, Boundary::spread(6)] {
        let lp = plan(
            spec,
            Propagator::ReachLp,
            Partitioner::Uniform(vec![1, 1]),
            boundary.clone(),
        );
        for cell in box_cells.iter().map(|c| Region::Box(c.clone())) {
            // one step from the same input set, at every step of the loop
            let states = sets(&lp, &cell);
            for (t, x) in states.iter().enumerate().take(lp.horizon) {
                let cl_lp = lp.closed_loop.linear().expect("a linear plant");
                let a = cl_lp.step(t, x, Propagator::ReachLp, &boundary).set;
                let b = cl_lp.step(t, x, Propagator::CrownSeparate, &boundary).set;
                let s = cl_lp.step(t, x, Propagator::ReachSdp, &boundary).set;
                assert!(
                    within(&a, &b),
                    "{boundary:?} step {t}: Reach-LP looser than CL-CROWN"
                );
                assert!(
                    within(&s, &a),
                    "{boundary:?} step {t}: Reach-SDP looser than Reach-LP"
                );
            }
        }
    }
}

#[test]
fn table_two_errors_come_in_the_tutorials_order() {
    let spec = "specs/double_integrator.ravel";
    let error = |prop, grid: Vec<usize>| {
        let p = plan(spec, prop, Partitioner::Uniform(grid), Boundary::Box);
        let out = execute_system(&p, &Control::unlimited());
        ravel::report::system::final_error(&out).expect("samples were drawn")
    };
    let ibp = error(Propagator::IbpSeparate, vec![1, 1]);
    let sg_ibp = error(Propagator::SgIbpSeparate, vec![1, 1]);
    let cl_crown = error(Propagator::CrownSeparate, vec![1, 1]);
    let reach_lp = error(Propagator::ReachLp, vec![1, 1]);
    let reach_lp_16 = error(Propagator::ReachLp, vec![4, 4]);
    let reach_sdp = error(Propagator::ReachSdp, vec![1, 1]);
    let unrolled = error(Propagator::CrownUnrolled, vec![1, 1]);
    assert!(sg_ibp <= ibp, "SG-IBP {sg_ibp} vs IBP {ibp}");
    assert!(
        reach_lp <= cl_crown,
        "Reach-LP {reach_lp} vs CL-CROWN {cl_crown}"
    );
    assert!(
        reach_lp_16 <= reach_lp,
        "partitioned {reach_lp_16} vs {reach_lp}"
    );
    assert!(
        reach_sdp <= reach_lp,
        "Reach-SDP {reach_sdp} vs Reach-LP {reach_lp}"
    );
    assert!(
        unrolled < reach_lp,
        "unrolled {unrolled} vs Reach-LP {reach_lp}"
    );
    assert!(unrolled < 2.0, "unrolled CROWN final-step error {unrolled}");
}

/// A ball initial set without partition is bounded in closed form (its
/// support function), not as its bounding box: every method's sets are
/// inside those of the bounding box, and strictly tighter at the end.
#[test]
fn balls_without_partition_beat_their_bounding_box() {
    for prop in [Propagator::ReachLp, Propagator::CrownUnrolled] {
        let p = plan(
            "specs/double_integrator_ball.ravel",
            prop,
            Partitioner::Uniform(vec![1, 1]),
            Boundary::Box,
        );
        assert!(matches!(p.initial, Region::Ball { .. }));
        let boxed = SystemPlan {
            initial: Region::Box(p.initial.bbox()),
            ..p.clone()
        };
        let ball = execute_system(&p, &Control::unlimited());
        let bbox = execute_system(&boxed, &Control::unlimited());
        for t in 1..ball.reach.len() {
            assert!(
                bbox.reach[t].contains_box(&ball.reach[t]),
                "{prop:?} step {t}: {:?} not inside {:?}",
                ball.reach[t],
                bbox.reach[t]
            );
        }
        let last = ball.reach.len() - 1;
        assert!(
            ball.reach[last].volume() < bbox.reach[last].volume() * 0.99,
            "{prop:?}: the ball's final box {:?} is no tighter than the bounding box's {:?}",
            ball.reach[last],
            bbox.reach[last]
        );
    }
}

/// Optimised slopes on the double integrator: Reach-LP's final box shrinks
/// (its x[1] upper end from 0.257 to 0.209, the shipped spec's snapshot),
/// enough to prove a goal `x[1] ≤ 0.23` that CROWN's own slopes leave
/// UNSURE; unrolled CROWN's final box becomes that of the sampled states
/// (error below 1e-6, against 0.53).
#[test]
fn optimised_slopes_tighten_the_double_integrator() {
    use ravel::execute::Verdict;
    use ravel::lower::PropertyKind;
    let run = |spec, prop, steps: usize, goal_x1: Option<f64>| {
        let mut p = plan(spec, prop, Partitioner::Uniform(vec![1, 1]), Boundary::Box);
        p.closed_loop
            .linear_mut()
            .expect("a linear plant")
            .slope_steps = steps;
        if let Some(h) = goal_x1 {
            for q in &mut p.properties {
                if let PropertyKind::Goal { set: g, .. } = &mut q.kind {
                    for (a, b) in &mut g.poly.rows {
                        if a[..] == [0.0, 1.0] {
                            *b = h;
                        }
                    }
                }
            }
        }
        execute_system(&p, &Control::unlimited())
    };
    let spec = "specs/double_integrator.ravel";
    let (plain, slopes) = (
        run(spec, Propagator::ReachLp, 0, Some(0.23)),
        run(spec, Propagator::ReachLp, 5, Some(0.23)),
    );
    let (a, b) = (
        plain.reach.last().expect("steps"),
        slopes.reach.last().expect("steps"),
    );
    assert!(a.contains_box(b), "optimised slopes loosened the final box");
    assert!(
        b.hi[1] < 0.22 && a.hi[1] > 0.25,
        "x[1] upper end {} vs {}",
        b.hi[1],
        a.hi[1]
    );
    assert_eq!(plain.verdict, Verdict::Unsure);
    assert_eq!(slopes.verdict, Verdict::Verified);
    let spec = "specs/double_integrator_unrolled.ravel";
    let (plain, slopes) = (
        run(spec, Propagator::CrownUnrolled, 0, None),
        run(spec, Propagator::CrownUnrolled, 3, None),
    );
    let err = |o| ravel::report::system::final_error(o).expect("sampled");
    assert!(err(&plain) > 0.4, "unrolled error {}", err(&plain));
    assert!(
        err(&slopes) < 1e-6,
        "unrolled error with optimised slopes {}",
        err(&slopes)
    );
}
