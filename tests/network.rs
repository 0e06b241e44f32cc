//! Network specs: Monte Carlo soundness of every output bound (random ReLU,
//! tanh and sigmoid networks; every propagator, partitioner, shape and input
//! set kind), verdicts that agree with sampled outputs, and radius searches
//! whose bracket contains a radius known in closed form.

mod common;

use common::{net_plan as plan, random_network, run_net as run};
use nalgebra::{DMatrix, DVector};
use ravel::execute::network::execute_network;
use ravel::execute::Control;
use ravel::execute::Verdict;
use ravel::ir::{Guide, NetPropagator, Partitioner};
use ravel::ir::{NetProperty, NetPropertyKind, RadiusSpec};
use ravel::lower::NetworkPlan;
use ravel_analysis::partition::Budget;
use ravel_analysis::sets::{IBox, Norm, Polytope, Region};
use ravel_analysis::shape::Shape;
use ravel_base::nn::{Activation, Layer, Network};
use ravel_base::rng::Rng;

/// Points of the region other than the executor's samples (another seed).
fn probe(region: &Region, n: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = Rng::new(seed);
    let mut pts = region.special_points();
    while pts.len() < n {
        if let Some(p) = region.sample(&mut || rng.unit()) {
            pts.push(p);
        }
    }
    pts
}

#[test]
fn output_bounds_contain_every_sampled_output() {
    let mut rng = Rng::new(2026);
    let mut checked = 0;
    for case in 0..48 {
        let act = [Activation::Relu, Activation::Tanh, Activation::Sigmoid][case % 3];
        let m = 1 + rng.below(3);
        let net = random_network(&mut rng, 2, m, act, (2, 6));
        let c = [rng.normal(), rng.normal()];
        let r = [0.2 + rng.unit(), 0.2 + rng.unit()];
        let input = match case / 3 % 3 {
            0 => Region::Box(IBox::new(
                vec![c[0] - r[0], c[1] - r[1]],
                vec![c[0] + r[0], c[1] + r[1]],
            )),
            1 => Region::Ball {
                center: c.to_vec(),
                radius: r.to_vec(),
                norm: [Norm::L1, Norm::L2, Norm::LInf][case % 3],
            },
            _ => {
                let bbox = IBox::new(
                    vec![c[0] - r[0], c[1] - r[1]],
                    vec![c[0] + r[0], c[1] + r[1]],
                );
                Region::Polytope {
                    bbox,
                    rows: vec![(vec![1.0, 1.0], c[0] + c[1] + 0.5 * (r[0] + r[1]))],
                }
            }
        };
        let props = vec![NetProperty {
            name: "p".into(),
            kind: NetPropertyKind::Require(Polytope {
                rows: vec![(vec![1.0; m], 0.3)],
            }),
        }];
        for (k, propagator) in NetPropagator::ALL.into_iter().enumerate() {
            if propagator == NetPropagator::Sdp && (act != Activation::Relu || case % 2 == 1) {
                continue; // ReLU only; and every other case, to keep the suite short
            }
            let mut p = plan(net.clone(), input.clone(), props.clone());
            p.propagator = propagator;
            // optimised slopes on every other CROWN case
            if propagator == NetPropagator::Crown && case % 2 == 0 {
                p.slope_steps = 4;
            }
            p.partitioner = match (case + k) % 4 {
                0 => Partitioner::Uniform(vec![1, 1]),
                1 => Partitioner::Uniform(vec![3, 2]),
                g => Partitioner::Guided {
                    guide: if g == 2 { Guide::Sg } else { Guide::Gsg },
                    budget: Budget {
                        calls: 9,
                        min_size: 0.01,
                        seconds: None,
                    },
                },
            };
            p.shape = match (case + 2 * k) % 4 {
                0 => Shape::Box,
                1 => Shape::LowerBounds,
                2 => Shape::Polytope(DMatrix::from_fn(2, m, |i, j| {
                    if (i + j) % 2 == 0 {
                        1.0
                    } else {
                        -0.5
                    }
                })),
                _ => Shape::Hull,
            };
            let out = run(&p);
            let d = &out.output.directions;
            for x in probe(&input, 300, case as u64) {
                let y = net.forward(&x);
                for row in 0..d.nrows() {
                    let v: f64 = (0..m).map(|j| d[(row, j)] * y[j]).sum();
                    assert!(
                        v <= out.output.offsets[row] + 1e-9 * (1.0 + v.abs()),
                        "case {case} {propagator:?}: facet {row} bound {} below sampled {v}",
                        out.output.offsets[row]
                    );
                }
                let pv: f64 = y.iter().sum::<f64>() - 0.3;
                if pv > 1e-9 {
                    assert_ne!(
                        out.properties[0].status,
                        Verdict::Verified,
                        "case {case} {propagator:?}: VERIFIED but x = {x:?} violates it"
                    );
                }
            }
            if let Some(w) = &out.properties[0].counterexample {
                assert!(input.contains_point(&w.input));
                assert!(w.output.iter().sum::<f64>() > 0.3);
            }
            checked += 1;
        }
    }
    assert!(checked >= 150, "only {checked} cases ran");
}

/// Propagators are ordered: CROWN is never looser than IBP, CROWN with
/// optimised slopes never looser than CROWN, and SDP (intersected with
/// CROWN) never looser than CROWN; on one cell and on a uniform grid
/// (whose CROWN cells go through the batched pass).
#[test]
fn propagators_are_ordered() {
    let mut rng = Rng::new(11);
    for case in 0..16 {
        let net = random_network(&mut rng, 2, 2, Activation::Relu, (2, 6));
        let input = Region::Box(IBox::new(vec![-0.5, -0.3], vec![0.4, 0.6]));
        let grid = if case % 2 == 0 {
            vec![1, 1]
        } else {
            vec![3, 2]
        };
        let bound = |prop, slope_steps| {
            let mut p = plan(net.clone(), input.clone(), Vec::new());
            p.propagator = prop;
            p.slope_steps = slope_steps;
            p.partitioner = Partitioner::Uniform(grid.clone());
            run(&p).output.offsets
        };
        let (ibp, crown, alpha, sdp) = (
            bound(NetPropagator::Ibp, 0),
            bound(NetPropagator::Crown, 0),
            bound(NetPropagator::Crown, 6),
            bound(NetPropagator::Sdp, 0),
        );
        for k in 0..ibp.len() {
            assert!(crown[k] <= ibp[k], "case {case}: CROWN looser than IBP");
            assert!(
                alpha[k] <= crown[k],
                "case {case}: optimised slopes looser than CROWN"
            );
            assert!(sdp[k] <= crown[k], "case {case}: SDP looser than CROWN");
        }
    }
}

/// `y = w·x + b` on the box `c ± s·r`: `max y = w·c + b + s·Σ|w_i| r_i`, so
/// `y ≤ t` holds exactly up to `s* = (t − w·c − b) / Σ|w_i| r_i`. The
/// certified scale must lie below `s*` and the attacked one above it, each
/// within a few tolerances; the same for a ReLU of it (same `s*`).
#[test]
fn radius_bracket_contains_the_true_radius() {
    let mut rng = Rng::new(5);
    for case in 0..8 {
        let w = [rng.normal(), rng.normal()];
        let b = rng.normal() * 0.1;
        let c = [rng.normal() * 0.2, rng.normal() * 0.2];
        let r = [0.1 + rng.unit() * 0.2, 0.1 + rng.unit() * 0.2];
        let t = w[0] * c[0] + w[1] * c[1] + b + 0.5 + rng.unit();
        let s_true = (t - w[0] * c[0] - w[1] * c[1] - b) / (w[0].abs() * r[0] + w[1].abs() * r[1]);
        let affine = Layer::Affine {
            w: DMatrix::from_row_slice(1, 2, &w),
            b: DVector::from_element(1, b),
        };
        // the ReLU variant: relu(y) ≤ t with t > 0 is y ≤ t
        let net = if case % 2 == 0 {
            Network::new(2, vec![affine])
        } else {
            Network::new(2, vec![affine, Layer::Act(Activation::Relu)])
        };
        let input = Region::Box(IBox::new(
            vec![c[0] - r[0], c[1] - r[1]],
            vec![c[0] + r[0], c[1] + r[1]],
        ));
        let mut p = plan(
            net,
            input,
            vec![NetProperty {
                name: "below".into(),
                kind: NetPropertyKind::Require(Polytope {
                    rows: vec![(vec![1.0], t)],
                }),
            }],
        );
        let tol = 1e-3 * s_true.max(1.0);
        p.radii = vec![RadiusSpec {
            name: "eps".into(),
            property: 0,
            max: 4.0 * s_true,
            tolerance: tol,
        }];
        let out = run(&p);
        let rr = &out.radii[0];
        let cert = rr.certified.expect("certified near the centre");
        let (att, wit) = rr.attacked.as_ref().expect("an attack beyond s*");
        assert!(
            cert <= s_true * (1.0 + 1e-9),
            "case {case}: certified {cert} above the true radius {s_true}"
        );
        assert!(
            *att >= s_true * (1.0 - 1e-9),
            "case {case}: attacked {att} below the true radius {s_true}"
        );
        assert!(
            cert >= s_true - 2.0 * tol,
            "case {case}: certified {cert} far below {s_true}"
        );
        assert!(
            *att <= s_true * 1.05 + tol,
            "case {case}: attacked {att} far above {s_true}"
        );
        assert!(
            wit.output[0] > t,
            "case {case}: the witness does not violate"
        );
    }
}

/// Robustness: a verified label holds at every sampled input, a falsified
/// one comes with an input whose label differs.
#[test]
fn robustness_verdicts_agree_with_samples() {
    let mut rng = Rng::new(99);
    let mut seen = [0usize; 3];
    for case in 0..40 {
        let net = random_network(&mut rng, 2, 3, Activation::Relu, (2, 6));
        let c = vec![rng.normal(), rng.normal()];
        let input = Region::Ball {
            center: c.clone(),
            radius: vec![0.02 + 0.3 * rng.unit(); 2],
            norm: Norm::LInf,
        };
        let mut p = plan(
            net.clone(),
            input.clone(),
            vec![NetProperty {
                name: "r".into(),
                kind: NetPropertyKind::Robust(None),
            }],
        );
        p.partitioner = Partitioner::Uniform(vec![2, 2]);
        let out = run(&p);
        let res = &out.properties[0];
        let k = res.label.expect("a label");
        let label = |y: &[f64]| (0..y.len()).filter(|&j| j != k).all(|j| y[k] > y[j]);
        match res.status {
            Verdict::Verified => {
                seen[0] += 1;
                for x in probe(&input, 300, case) {
                    assert!(
                        label(&net.forward(&x)),
                        "case {case}: verified but {x:?} differs"
                    );
                }
            }
            Verdict::Falsified => {
                seen[1] += 1;
                let w = res.counterexample.as_ref().expect("witness");
                assert!(input.contains_point(&w.input));
                assert!(!label(&w.output), "case {case}: witness keeps the label");
            }
            Verdict::Unsure => seen[2] += 1,
        }
    }
    assert!(seen[0] > 0 && seen[1] > 0, "verdicts seen: {seen:?}");
}

/// CARRL: every sampled Q-value of the ε-ball lies within the certified
/// bounds, the robust action has the largest lower bound, and where it is
/// certified optimal no sampled observation of the ball prefers another
/// action; with and without partitioning, for every ball norm.
#[test]
fn carrl_bounds_contain_sampled_values() {
    use ravel::ir::SelectSpec;
    let mut rng = Rng::new(31);
    let mut optimal = 0;
    for case in 0..30 {
        let net = random_network(&mut rng, 2, 3, Activation::Relu, (2, 6));
        let observations: Vec<Vec<f64>> =
            (0..5).map(|_| vec![rng.normal(), rng.normal()]).collect();
        let eps = vec![0.01 + 0.1 * rng.unit(), 0.01 + 0.1 * rng.unit()];
        let norm = [Norm::L1, Norm::L2, Norm::LInf][case % 3];
        let mut p = plan(
            net.clone(),
            Region::Box(IBox::point(&[0.0, 0.0])),
            Vec::new(),
        );
        p.input = None;
        p.selects = vec![SelectSpec {
            name: "s".into(),
            epsilon: eps.clone(),
            norm,
            observations: observations.clone(),
        }];
        if case % 2 == 1 {
            p.partitioner = Partitioner::Guided {
                guide: Guide::Gsg,
                budget: Budget {
                    calls: 7,
                    min_size: 0.01,
                    seconds: None,
                },
            };
        }
        let out = run(&p);
        let sel = &out.selections[0];
        for (o, c) in observations.iter().zip(&sel.choices) {
            let ball = Region::Ball {
                center: o.clone(),
                radius: eps.clone(),
                norm,
            };
            assert!(c.lower.iter().all(|l| *l <= c.lower[c.robust]));
            for x in probe(&ball, 200, case as u64) {
                let q = net.forward(&x);
                for (j, qj) in q.iter().enumerate() {
                    assert!(
                        c.lower[j] <= *qj && *qj <= c.upper[j],
                        "case {case}: Q[{j}] = {qj} outside [{}, {}]",
                        c.lower[j],
                        c.upper[j]
                    );
                }
                if c.robust_optimal {
                    assert!(
                        (0..3).all(|j| q[c.robust] >= q[j]),
                        "case {case}: not optimal at {x:?}"
                    );
                }
            }
            optimal += usize::from(c.robust_optimal);
        }
    }
    assert!(
        optimal > 0,
        "no observation certified optimal: the test checks nothing"
    );
}

/// Network certificates: a wrong VERIFIED forced through the writer is
/// marked unsupported (the checker's own bounds do not prove it), and the
/// same claim with checkable evidence is INVALID; a forged counterexample
/// outside the input set, or one that does not violate, is INVALID too.
#[test]
fn network_certificates_catch_false_claims() {
    use ravel_certify::{check, Answer};
    let mut rng = Rng::new(8);
    let net = random_network(&mut rng, 2, 1, Activation::Relu, (2, 6));
    let input = Region::Box(IBox::new(vec![-1.0, -1.0], vec![1.0, 1.0]));
    let y = net.forward(&[0.0, 0.0])[0];
    // false: the output at the centre is above y − 1
    let p = plan(
        net.clone(),
        input,
        vec![NetProperty {
            name: "false".into(),
            kind: NetPropertyKind::Require(Polytope {
                rows: vec![(vec![1.0], y - 1.0)],
            }),
        }],
    );
    let mut out = run(&p);
    assert_eq!(out.properties[0].status, Verdict::Falsified);
    let id = ravel::certificate_writer::Identity {
        spec_path: "t".into(),
        spec_sha256: String::new(),
    };
    let honest = ravel::certificate_writer::build_network(&p, &out, &id);
    assert_eq!(check(&honest, &net).answer, Answer::Valid);
    // a counterexample moved outside the input set
    let mut moved = honest.clone();
    moved["verdicts"][0]["input"] = serde_json::json!([3.0, 0.0]);
    assert!(matches!(check(&moved, &net).answer, Answer::Invalid(_)));
    // the verdict forced to VERIFIED
    out.properties[0].status = Verdict::Verified;
    out.properties[0].counterexample = None;
    let forced = ravel::certificate_writer::build_network(&p, &out, &id);
    assert_eq!(forced["evidence"]["status"], "unsupported");
    assert!(matches!(
        check(&forced, &net).answer,
        Answer::Unsupported(_)
    ));
    let mut forged = forced.clone();
    forged["evidence"] = serde_json::json!({
        "status": "checkable",
        "cells": [{ "lo": [-1.0, -1.0], "hi": [1.0, 1.0] }],
    });
    assert!(matches!(check(&forged, &net).answer, Answer::Invalid(_)));
    // junk never panics
    for junk in [
        serde_json::json!({}),
        serde_json::json!({ "format": "ravel-certificate/1", "problem": { "kind": "network" } }),
        serde_json::json!({ "format": "ravel-certificate/1", "problem": { "kind": "network", "inputs": 2, "outputs": 1, "input": { "ball": { "center": [0, 0], "radius": [-1, 1], "norm": "2" } }, "properties": [] }, "verdicts": [] }),
    ] {
        assert!(matches!(check(&junk, &net).answer, Answer::Unreadable(_)));
    }
}

/// Past the time limit (a clock that is always late, so nothing depends on
/// timing): grid cells keep the whole set's bounds (valid for any part), so
/// the output set is the unpartitioned one, and CARRL observations get no
/// bounds and no claim.
#[test]
fn time_limit_keeps_every_bound_sound() {
    use ravel::ir::SelectSpec;
    let mut rng = Rng::new(4);
    let net = random_network(&mut rng, 2, 3, Activation::Relu, (2, 6));
    let input = Region::Box(IBox::new(vec![-0.5, -0.5], vec![0.5, 0.5]));
    let mut p = plan(net, input, Vec::new());
    let whole = run(&p).output.offsets;
    p.partitioner = Partitioner::Uniform(vec![4, 4]);
    p.selects = vec![SelectSpec {
        name: "s".into(),
        epsilon: vec![0.1, 0.1],
        norm: Norm::LInf,
        observations: vec![vec![0.0, 0.0]],
    }];
    let late = execute_network(
        &p,
        &Control {
            elapsed: &|| 10.0,
            time_limit: Some(1.0),
            progress: &|_| {},
            threads: 1,
        },
    );
    assert_eq!(late.partition_stop, ravel_analysis::partition::Stop::Time);
    assert_eq!(late.output.offsets, whole);
    let c = &late.selections[0].choices[0];
    assert!(c.lower.iter().all(|v| *v == f64::NEG_INFINITY) && !c.robust_optimal);
}

/// Grid cells, CARRL observations and guided refinement on several threads:
/// the same outcome, number for number, as on one.
#[test]
fn threads_never_change_a_network_result() {
    use ravel::ir::SelectSpec;
    let mut rng = Rng::new(12);
    let net = random_network(&mut rng, 2, 3, Activation::Relu, (2, 6));
    let input = Region::Ball {
        center: vec![0.1, -0.2],
        radius: vec![0.4, 0.3],
        norm: Norm::L2,
    };
    let mut p = plan(
        net,
        input,
        vec![NetProperty {
            name: "r".into(),
            kind: NetPropertyKind::Robust(None),
        }],
    );
    p.partitioner = Partitioner::Uniform(vec![5, 3]);
    p.selects = vec![SelectSpec {
        name: "s".into(),
        epsilon: vec![0.05, 0.02],
        norm: Norm::LInf,
        observations: (0..23).map(|k| vec![0.1 * k as f64 - 1.0, 0.5]).collect(),
    }];
    let with_plan = |p: &NetworkPlan, threads| {
        execute_network(
            p,
            &Control {
                elapsed: &|| 0.0,
                time_limit: None,
                progress: &|_| {},
                threads,
            },
        )
    };
    let with = |threads| with_plan(&p, threads);
    let one = with(1);
    for threads in [2, 3, 8] {
        let many = with(threads);
        assert_eq!(many.output.offsets, one.output.offsets, "{threads} threads");
        assert_eq!(many.partition, one.partition);
        assert_eq!(many.properties, one.properties);
        assert_eq!(many.selections, one.selections);
    }
    // box cells go through the network in groups (analysis::batch)
    let mut p = p.clone();
    p.input = Some(Region::Box(IBox::new(vec![-0.3, -0.5], vec![0.5, 0.1])));
    p.partitioner = Partitioner::Uniform(vec![7, 5]);
    // the output, partition and properties of `p` on these thread counts
    // against one thread's; the outcome on one thread
    let same = |p: &NetworkPlan, counts: &[usize], what: &str| {
        let one = with_plan(p, 1);
        for &threads in counts {
            let many = with_plan(p, threads);
            assert_eq!(
                many.output.offsets, one.output.offsets,
                "{what}, {threads} threads"
            );
            assert_eq!(many.partition, one.partition, "{what}");
            assert_eq!(many.properties, one.properties, "{what}");
        }
        one
    };
    same(&p, &[2, 3, 8], "box");
    // guided refinement: each split's two children on two threads
    for guide in [Guide::Gsg, Guide::Sg] {
        p.partitioner = Partitioner::Guided {
            guide,
            budget: Budget {
                calls: 25,
                min_size: 1.0 / 64.0,
                seconds: None,
            },
        };
        let one = same(&p, &[2, 3], &format!("{guide:?}"));
        assert!(one.partition.len() > 1, "{guide:?} refines");
    }
}

/// "The label of the centre" when the centre's outputs tie: no label is
/// certain there, so no input can refute it (UNSURE, no radius attack),
/// while a named label is refuted as usual.
#[test]
fn a_tied_centre_refutes_nothing() {
    // y = (x0, −x0): tied at the centre x0 = 0
    let net = Network::new(
        1,
        vec![Layer::Affine {
            w: DMatrix::from_row_slice(2, 1, &[1.0, -1.0]),
            b: DVector::zeros(2),
        }],
    );
    let input = Region::Box(IBox::new(vec![-1.0], vec![1.0]));
    let prop = |label| NetProperty {
        name: "r".into(),
        kind: NetPropertyKind::Robust(label),
    };
    let mut p = plan(net.clone(), input.clone(), vec![prop(None)]);
    p.partitioner = Partitioner::Uniform(vec![1]);
    p.radii = vec![RadiusSpec {
        name: "e".into(),
        property: 0,
        max: 1.0,
        tolerance: 0.01,
    }];
    let out = run(&p);
    assert_eq!(out.properties[0].status, Verdict::Unsure);
    assert!(out.radii[0].attacked.is_none());
    let mut q = plan(net, input, vec![prop(Some(0))]);
    q.partitioner = Partitioner::Uniform(vec![1]);
    assert_eq!(run(&q).properties[0].status, Verdict::Falsified);
}

/// The SDP's own bound of `d·y` for a two-output merged network (not
/// intersected with CROWN's): φ over the last hidden layer, the output
/// layer's bias and the merge error in the constant, a generous 1e-9 for
/// the rounding of φ.
fn sdp_output_bound(
    prog: &ravel_analysis::sdp::StepSdp,
    merged: &ravel_analysis::sdp::MergedNet,
    d: [f64; 2],
) -> ravel_analysis::sdp::SdpBound {
    sdp_output_bound_using(prog, merged, d, ravel_analysis::sdp::Solver::Auto)
}

/// [`sdp_output_bound`] with the multipliers of `solver`.
fn sdp_output_bound_using(
    prog: &ravel_analysis::sdp::StepSdp,
    merged: &ravel_analysis::sdp::MergedNet,
    d: [f64; 2],
    solver: ravel_analysis::sdp::Solver,
) -> ravel_analysis::sdp::SdpBound {
    let (wl, bl) = merged.layers.last().expect("output layer");
    let mut phi = vec![0.0; prog.dim()];
    for k in 0..wl.ncols() {
        phi[prog.last_hidden() + k] = (0..2).map(|j| d[j] * wl[(j, k)]).sum();
    }
    phi[prog.dim() - 1] = (0..2)
        .map(|j| d[j] * bl[j] + d[j].abs() * merged.err[j])
        .sum::<f64>()
        + 1e-9;
    prog.bound_using(&phi, solver)
}

/// The fast path against the reference, bound for bound: the
/// Schur-complement method's multipliers and Clarabel's, each re-certified
/// the same way, give the same facet bounds on random networks (small boxes
/// where most neurons are stable, large ones where most are not, deeper and
/// wider ones): the fast one never needs the fallback, is never looser by
/// more than 1e-6 (relative), and contains every sampled output. (Measured:
/// it is tighter by 1e-10 to 1e-7, and by up to 1e-3 on the widest case,
/// where Clarabel stops earlier.)
#[test]
fn sdp_solvers_agree_bound_for_bound() {
    use ravel_analysis::sdp::{merge, Solver, StepSdp};
    let mut rng = Rng::new(977);
    let mut compared = 0;
    for case in 0..12 {
        let (depth, width) = [(2, (3, 8)), (3, (6, 12))][case % 2];
        let net = random_network(&mut rng, 2, depth, Activation::Relu, width);
        let c = [rng.normal(), rng.normal()];
        let r = [0.05, 0.5, 2.0][case % 3];
        let b = IBox::new(vec![c[0] - r, c[1] - r], vec![c[0] + r, c[1] + r]);
        let merged = merge(&net, &DMatrix::identity(2, 2), &b).expect("ReLU network");
        let prog = StepSdp::new(&merged, &b, &[]);
        let samples = probe(&Region::Box(b.clone()), 300, case as u64);
        for d in [[1.0, 0.0], [-0.4, 1.0], [0.7, -0.7]] {
            let fast = sdp_output_bound_using(&prog, &merged, d, Solver::Schur);
            let reference = sdp_output_bound_using(&prog, &merged, d, Solver::Clarabel);
            assert_eq!(fast.issue, None, "case {case} {d:?}: the fast path stalled");
            assert_eq!(reference.issue, None, "case {case} {d:?}");
            let scale = 1.0 + reference.value.abs();
            assert!(
                fast.value <= reference.value + 1e-6 * scale,
                "case {case} {d:?}: Schur {} looser than Clarabel {}",
                fast.value,
                reference.value
            );
            // and sound: above every sampled output
            for x in &samples {
                let y = net.forward(x);
                let v = d[0] * y[0] + d[1] * y[1];
                assert!(
                    v <= fast.value,
                    "case {case} {d:?}: {} below {v}",
                    fast.value
                );
            }
            compared += 1;
        }
    }
    assert_eq!(compared, 36);
}

/// Reach-SDP substitutes the neurons its bounds prove stable: over small
/// boxes most are, and the bounds (with the substitution's rounding added)
/// still contain every sampled output; over one box the SDP keeps every
/// neuron it cannot prove stable. Non-vacuous: some programs keep no
/// neuron at all (the last hidden layer's stable neurons are substituted
/// into the objective too), some keep some.
#[test]
fn sdp_with_stable_neurons_substituted_contains_every_output() {
    use ravel_analysis::sdp::{merge, StepSdp};
    let mut rng = Rng::new(4242);
    let (mut folded_all, mut kept_some) = (0, 0);
    for case in 0..16 {
        let net = random_network(&mut rng, 2, 2, Activation::Relu, (3, 8));
        let c = [rng.normal(), rng.normal()];
        let r = [0.02, 0.3][case % 2];
        let b = IBox::new(vec![c[0] - r, c[1] - r], vec![c[0] + r, c[1] + r]);
        let merged = merge(&net, &DMatrix::identity(2, 2), &b).expect("ReLU network");
        let prog = StepSdp::new(&merged, &b, &[]);
        if prog.kept_neurons() == 0 {
            folded_all += 1;
        } else {
            kept_some += 1;
        }
        // the SDP's own bound of d·y for four directions
        let samples = probe(&Region::Box(b.clone()), 300, case as u64);
        for d in [[1.0, 0.0], [0.0, 1.0], [-1.0, 0.5], [0.3, -1.0]] {
            let bound = sdp_output_bound(&prog, &merged, d);
            assert!(bound.issue.is_none(), "case {case}: {:?}", bound.issue);
            for x in &samples {
                let y = net.forward(x);
                let v = d[0] * y[0] + d[1] * y[1];
                assert!(
                    v <= bound.value,
                    "case {case} {d:?}: SDP bound {} below sampled {v}",
                    bound.value
                );
            }
        }
    }
    assert!(
        folded_all > 0 && kept_some > 0,
        "{folded_all} all-stable, {kept_some} with unstable neurons"
    );
}

/// Beyond the matrix size Clarabel is given (its PSD block would not fit
/// in memory), the Schur-complement method alone bounds the program: a
/// 2 → 90 → 90 → 2 network over a box where most neurons are unstable
/// keeps more than 150 coordinates; its bound holds on samples, and asking
/// Clarabel for it is refused as too large (no attempt, no memory).
#[test]
fn sdp_beyond_clarabels_size_is_the_schur_methods() {
    use ravel_analysis::issue::Issue;
    use ravel_analysis::sdp::{merge, Solver, StepSdp};
    let net = common::relu_network(&mut Rng::new(8), &[2, 90, 90, 2], 1.5, 0.2);
    let b = IBox::new(vec![-1.0, -1.0], vec![1.0, 1.0]);
    let merged = merge(&net, &DMatrix::identity(2, 2), &b).expect("ReLU network");
    let prog = StepSdp::new(&merged, &b, &[]);
    assert!(
        prog.kept_neurons() + 3 > ravel_base::limits::MAX_CLARABEL_SDP_DIM,
        "only {} neurons kept",
        prog.kept_neurons()
    );
    let d = [1.0, -0.5];
    let fast = sdp_output_bound_using(&prog, &merged, d, Solver::Auto);
    assert_eq!(fast.issue, None);
    assert!(fast.value.is_finite());
    for x in &probe(&Region::Box(b.clone()), 300, 8) {
        let y = net.forward(x);
        assert!(d[0] * y[0] + d[1] * y[1] <= fast.value);
    }
    let refused = sdp_output_bound_using(&prog, &merged, d, Solver::Clarabel);
    assert_eq!(refused.issue, Some(Issue::SdpTooLarge));
    assert_eq!(refused.value, f64::INFINITY);
}

/// Many input rows on a small program (their pairwise products are
/// multipliers: 45 rows give over a thousand) are Clarabel's case: the
/// default solver choice gives Clarabel's bound exactly there, and the bound
/// contains the samples.
#[test]
fn sdp_with_many_input_rows_goes_to_clarabel() {
    use ravel_analysis::sdp::{merge, Solver, StepSdp};
    let mut rng = Rng::new(31);
    let net = random_network(&mut rng, 2, 2, Activation::Relu, (3, 5));
    let b = IBox::new(vec![-0.5, -0.5], vec![0.5, 0.5]);
    // tangent rows of the disc of radius 0.6 (all contain the box)
    let rows: Vec<(Vec<f64>, f64)> = (0..45)
        .map(|k| {
            let a = k as f64 * std::f64::consts::TAU / 45.0;
            (vec![a.cos(), a.sin()], 0.75)
        })
        .collect();
    let merged = merge(&net, &DMatrix::identity(2, 2), &b).expect("ReLU network");
    let prog = StepSdp::new(&merged, &b, &rows);
    let samples = probe(&Region::Box(b.clone()), 200, 5);
    for d in [[1.0, 0.0], [0.0, -1.0]] {
        let auto = sdp_output_bound_using(&prog, &merged, d, Solver::Auto);
        let reference = sdp_output_bound_using(&prog, &merged, d, Solver::Clarabel);
        assert_eq!(auto, reference);
        assert!(auto.issue.is_none() && auto.value.is_finite());
        for x in &samples {
            let y = net.forward(x);
            assert!(d[0] * y[0] + d[1] * y[1] <= auto.value);
        }
    }
}

/// A network property only optimised slopes prove: its certificate records
/// the step count and is VALID through the checker's own slope search, and
/// INVALID with the search switched off.
#[test]
fn network_certificates_check_optimised_slopes() {
    use ravel::execute::network::cell_bounds;
    use ravel_certify::{check, Answer};
    let mut rng = Rng::new(31);
    let mut found = 0;
    for case in 0..40 {
        let net = random_network(&mut rng, 2, 1, Activation::Relu, (4, 8));
        let input = Region::Box(IBox::new(vec![-1.0, -0.5], vec![0.5, 1.0]));
        let dirs = DMatrix::from_row_slice(1, 1, &[1.0]);
        let crown = cell_bounds(&net, &input, NetPropagator::Crown, 0, &dirs).0[0];
        let alpha = cell_bounds(&net, &input, NetPropagator::Crown, 8, &dirs).0[0];
        assert!(alpha <= crown, "case {case}: optimised slopes looser");
        if alpha >= crown - 1e-3 {
            continue;
        }
        let t = 0.5 * (alpha + crown);
        let mut p = plan(
            net.clone(),
            input,
            vec![NetProperty {
                name: "needs_slopes".into(),
                kind: NetPropertyKind::Require(Polytope {
                    rows: vec![(vec![1.0], t)],
                }),
            }],
        );
        p.samples = 0;
        p.slope_steps = 8;
        let out = run(&p);
        assert_eq!(out.properties[0].status, Verdict::Verified, "case {case}");
        let id = ravel::certificate_writer::Identity {
            spec_path: "t".into(),
            spec_sha256: String::new(),
        };
        let cert = ravel::certificate_writer::build_network(&p, &out, &id);
        assert_eq!(cert["evidence"]["slope_steps"], 8);
        assert_eq!(check(&cert, &net).answer, Answer::Valid, "case {case}");
        let mut off = cert.clone();
        off["evidence"]["slope_steps"] = 0.into();
        assert!(
            matches!(check(&off, &net).answer, Answer::Invalid(_)),
            "case {case}: only the slopes prove it"
        );
        found += 1;
    }
    assert!(found >= 3, "only {found} cases needed the slopes");
}

/// An input pinned to a point (lo = hi, as exactly known noise is) is a
/// constant of the SDP, not a variable; a polytope row through it moves its
/// term to the right-hand side. The bound still contains every output of
/// the inputs that satisfy the row.
#[test]
fn sdp_with_a_pinned_input_contains_every_output() {
    use ravel_analysis::sdp::{merge, StepSdp};
    let mut rng = Rng::new(777);
    for case in 0..8 {
        let net = random_network(&mut rng, 2, 2, Activation::Relu, (3, 6));
        let b = IBox::new(vec![-0.5, 0.3], vec![0.5, 0.3]);
        let rows = vec![(vec![1.0, 1.0], 0.5)]; // x0 + x1 ≤ 0.5, so x0 ≤ 0.2
        let merged = merge(&net, &DMatrix::identity(2, 2), &b).expect("ReLU network");
        let prog = StepSdp::new(&merged, &b, &rows);
        for d in [[1.0, 0.0], [0.0, -1.0], [0.7, 0.7]] {
            let bound = sdp_output_bound(&prog, &merged, d);
            assert!(bound.issue.is_none(), "case {case}: {:?}", bound.issue);
            for k in 0..=200 {
                let x = [-0.5 + 0.7 * k as f64 / 200.0, 0.3];
                let y = net.forward(&x);
                let v = d[0] * y[0] + d[1] * y[1];
                assert!(
                    v <= bound.value,
                    "case {case} {d:?}: bound {} below {v}",
                    bound.value
                );
            }
        }
    }
}
