//! Branch and bound (`partitioner bab`) on random small ReLU networks,
//! against the truth found by exhaustive enumeration of their linear
//! regions: VERIFIED only when the property holds, FALSIFIED only with a
//! real counterexample, and — with a margin between the threshold and the
//! true extreme — always one of the two (the search is complete given
//! time). Also: the certificate of every answer checks, and a search cut by
//! the time limit ends UNSURE.

mod common;

use common::{net_certificate, net_plan as plan, random_network, run_net as run};
use ravel::execute::network::execute_network;
use ravel::execute::{Control, Verdict};
use ravel::ir::{ActivationPhases, Branching, Guide, NetProperty, NetPropertyKind, Partitioner};
use ravel_analysis::partition::{Budget, Stop};
use ravel_analysis::sets::{IBox, Polytope, Region};
use ravel_base::nn::{Activation, Layer, Network};
use ravel_base::rng::Rng;

/// The pre-activations of every hidden layer at `x` (one vector per
/// activation layer, in order).
fn pre_activations(net: &Network, x: &[f64]) -> Vec<Vec<f64>> {
    let mut v = x.to_vec();
    let mut out = Vec::new();
    for layer in &net.layers {
        match layer {
            Layer::Affine { w, b } => {
                v = (0..w.nrows())
                    .map(|i| b[i] + (0..w.ncols()).map(|j| w[(i, j)] * v[j]).sum::<f64>())
                    .collect();
            }
            Layer::Act(Activation::Relu) => {
                out.push(v.clone());
                v.iter_mut().for_each(|a| *a = a.max(0.0));
            }
            other => panic!("ReLU networks only: {other:?}"),
        }
    }
    out
}

/// The part of the convex polygon `poly` where `f` (affine on it, given by
/// its values at the vertices) has the sign `s` (`f·s ≥ 0`), with the new
/// vertices where an edge crosses `f = 0`.
fn clip(poly: &[[f64; 2]], vals: &[f64], s: f64) -> Vec<[f64; 2]> {
    let mut out = Vec::new();
    for i in 0..poly.len() {
        let j = (i + 1) % poly.len();
        let (a, b) = (vals[i] * s, vals[j] * s);
        if a >= 0.0 {
            out.push(poly[i]);
        }
        if (a > 0.0 && b < 0.0) || (a < 0.0 && b > 0.0) {
            let t = a / (a - b);
            out.push([
                poly[i][0] + t * (poly[j][0] - poly[i][0]),
                poly[i][1] + t * (poly[j][1] - poly[i][1]),
            ]);
        }
    }
    out
}

/// The vertices of every linear region of `net` (two inputs) inside the
/// box: the box is cut by each neuron's zero set, layer by layer (on each
/// piece the neuron's pre-activation is affine). A continuous
/// piecewise-linear function of the output reaches its extremes over the
/// box at one of them.
fn region_vertices(net: &Network, lo: [f64; 2], hi: [f64; 2]) -> Vec<[f64; 2]> {
    let mut pieces = vec![vec![
        [lo[0], lo[1]],
        [hi[0], lo[1]],
        [hi[0], hi[1]],
        [lo[0], hi[1]],
    ]];
    let widths: Vec<usize> = pre_activations(net, &[lo[0], lo[1]])
        .iter()
        .map(Vec::len)
        .collect();
    for (l, &w) in widths.iter().enumerate() {
        for j in 0..w {
            let mut next = Vec::new();
            for p in &pieces {
                // the sign pattern of earlier neurons is fixed on the piece,
                // so this neuron's pre-activation is affine on it
                let vals: Vec<f64> = p.iter().map(|v| pre_activations(net, v)[l][j]).collect();
                for s in [1.0, -1.0] {
                    let q = clip(p, &vals, s);
                    if q.len() >= 3 {
                        next.push(q);
                    }
                }
            }
            pieces = next;
        }
    }
    pieces.into_iter().flatten().collect()
}

/// `max over the box of c·f(x)`, exactly up to the rounding of the region
/// vertices.
fn exact_max(net: &Network, verts: &[[f64; 2]], c: &[f64]) -> f64 {
    verts
        .iter()
        .map(|v| {
            let y = net.forward(v);
            c.iter().zip(&y).map(|(a, b)| a * b).sum::<f64>()
        })
        .fold(f64::NEG_INFINITY, f64::max)
}

fn bab_plan(net: Network, input: Region, props: Vec<NetProperty>) -> ravel::lower::NetworkPlan {
    let mut p = plan(net, input, props);
    p.partitioner = Partitioner::Guided {
        guide: Guide::Bab,
        budget: Budget {
            calls: 100_000,
            min_size: 1e-9,
            seconds: None,
        },
    };
    p
}

#[test]
fn bab_agrees_with_exhaustive_enumeration() {
    use ravel_certify::{check, Answer};
    let mut rng = Rng::new(29);
    let (mut verified, mut falsified) = (0, 0);
    for case in 0..40 {
        let m = 1 + rng.below(2);
        let net = random_network(&mut rng, 2, m, Activation::Relu, (2, 5));
        let c0 = [rng.normal(), rng.normal()];
        let r = [0.3 + rng.unit(), 0.3 + rng.unit()];
        let (lo, hi) = ([c0[0] - r[0], c0[1] - r[1]], [c0[0] + r[0], c0[1] + r[1]]);
        let verts = region_vertices(&net, lo, hi);
        let input = Region::Box(IBox::new(lo.to_vec(), hi.to_vec()));
        let dir: Vec<f64> = (0..m).map(|_| rng.normal()).collect();
        let top = exact_max(&net, &verts, &dir);
        let bottom = -exact_max(&net, &verts, &dir.iter().map(|v| -v).collect::<Vec<_>>());
        let delta = 0.02 * (1.0 + top.abs().max(bottom.abs()));
        // case by case: a `require` that holds or fails, an avoid set that is
        // missed or touched
        let holds = case % 2 == 0;
        let kind = if case % 4 < 2 {
            let h = if holds { top + delta } else { top - delta };
            NetPropertyKind::Require(Polytope {
                rows: vec![(dir.clone(), h)],
            })
        } else {
            // avoid { dir·y <= h }: touched iff the minimum is at most h
            let h = if holds {
                bottom - delta
            } else {
                bottom + delta
            };
            NetPropertyKind::Avoid(vec![Polytope {
                rows: vec![(dir.clone(), h)],
            }])
        };
        let p0 = bab_plan(
            net.clone(),
            input.clone(),
            vec![NetProperty {
                name: "p".into(),
                kind,
            }],
        );
        // every branching rule answers alike
        for rule in Branching::ALL {
            let mut p = p0.clone();
            p.branching = rule;
            let out = run(&p);
            let got = out.properties[0].status;
            let want = if holds {
                Verdict::Verified
            } else {
                Verdict::Falsified
            };
            assert_eq!(
            got, want,
            "case {case} {rule:?}: truth {want:?} (max {top}, min {bottom}), bab says {got:?} after {} calls, stop {:?}",
            out.calls, out.partition_stop
        );
            if let Some(w) = &out.properties[0].counterexample {
                assert!(input.contains_point(&w.input), "case {case} {rule:?}");
                let v: f64 = dir
                    .iter()
                    .zip(&net.forward(&w.input))
                    .map(|(a, b)| a * b)
                    .sum();
                match &p.properties[0].kind {
                    NetPropertyKind::Require(q) => assert!(v > q.rows[0].1, "case {case} {rule:?}"),
                    NetPropertyKind::Avoid(q) => {
                        assert!(v <= q[0].rows[0].1, "case {case} {rule:?}")
                    }
                    NetPropertyKind::Robust(_) => unreachable!(),
                }
            }
            // every answer is certifiable, and the search stopped as it should
            let cert = net_certificate(&p, &out);
            assert_eq!(
                check(&cert, &net).answer,
                Answer::Valid,
                "case {case} {rule:?}"
            );
            match got {
                Verdict::Verified => {
                    verified += 1;
                    assert_eq!(out.partition_stop, Stop::Done, "case {case} {rule:?}");
                }
                _ => {
                    falsified += 1;
                    assert!(
                        matches!(out.partition_stop, Stop::Decided | Stop::Done),
                        "case {case} {rule:?}: {:?}",
                        out.partition_stop
                    );
                }
            }
        }
    }
    assert!(
        verified >= 45 && falsified >= 45,
        "{verified} verified, {falsified} falsified"
    );
}

/// Robustness of the centre's class: true exactly when no other output
/// reaches the label's anywhere on the box (enumeration decides it); cases
/// too close to call are skipped.
#[test]
fn bab_robustness_agrees_with_exhaustive_enumeration() {
    let mut rng = Rng::new(30);
    let mut decided = 0;
    for case in 0..60 {
        let m = 2 + rng.below(2);
        let net = random_network(&mut rng, 2, m, Activation::Relu, (2, 5));
        let c0 = [rng.normal(), rng.normal()];
        let r = 0.05 + 0.5 * rng.unit();
        let (lo, hi) = ([c0[0] - r, c0[1] - r], [c0[0] + r, c0[1] + r]);
        let y0 = net.forward(&c0);
        let label = (0..m).max_by(|&a, &b| y0[a].total_cmp(&y0[b])).unwrap();
        let verts = region_vertices(&net, lo, hi);
        // the largest lead of another output over the label's
        let worst = (0..m)
            .filter(|&j| j != label)
            .map(|j| {
                let mut d = vec![0.0; m];
                d[j] = 1.0;
                d[label] = -1.0;
                exact_max(&net, &verts, &d)
            })
            .fold(f64::NEG_INFINITY, f64::max);
        if worst.abs() < 0.02 {
            continue;
        }
        let input = Region::Box(IBox::new(lo.to_vec(), hi.to_vec()));
        let p = bab_plan(
            net.clone(),
            input.clone(),
            vec![NetProperty {
                name: "robust".into(),
                kind: NetPropertyKind::Robust(Some(label)),
            }],
        );
        let out = run(&p);
        let want = if worst < 0.0 {
            Verdict::Verified
        } else {
            Verdict::Falsified
        };
        assert_eq!(
            out.properties[0].status, want,
            "case {case}: largest lead {worst}"
        );
        if let Some(w) = &out.properties[0].counterexample {
            let y = net.forward(&w.input);
            assert!(input.contains_point(&w.input));
            assert!(
                (0..m).any(|j| j != label && y[j] >= y[label]),
                "case {case}"
            );
        }
        decided += 1;
    }
    assert!(decided >= 40, "only {decided} cases were clear");
}

/// A search cut by the time limit (a clock that is late after a few
/// looks, so nothing depends on timing) ends UNSURE and says why; its
/// bounds stay sound.
#[test]
fn bab_past_the_time_limit_is_unsure() {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let mut rng = Rng::new(31);
    let net = random_network(&mut rng, 2, 1, Activation::Relu, (3, 6));
    let (lo, hi) = ([-1.0, -1.0], [1.0, 1.0]);
    let verts = region_vertices(&net, lo, hi);
    let top = exact_max(&net, &verts, &[1.0]);
    // exactly the maximum: it holds, but no rounded bound can prove it and
    // no point violates it, so only the limits end the search
    let p = bab_plan(
        net.clone(),
        Region::Box(IBox::new(lo.to_vec(), hi.to_vec())),
        vec![NetProperty {
            name: "tight".into(),
            kind: NetPropertyKind::Require(Polytope {
                rows: vec![(vec![1.0], top)],
            }),
        }],
    );
    let looks = AtomicUsize::new(0);
    let clock = || looks.fetch_add(1, Ordering::Relaxed) as f64;
    let out = execute_network(
        &p,
        &Control {
            elapsed: &clock,
            time_limit: Some(40.0),
            progress: &|_| {},
            threads: 1,
        },
    );
    assert_eq!(out.properties[0].status, Verdict::Unsure);
    assert_eq!(out.partition_stop, Stop::Time);
    for x in [[0.0, 0.0], [0.5, -0.5], [-1.0, 1.0]] {
        assert!(net.forward(&x)[0] <= out.output.offsets[0] + 1e-12);
    }
}

/// Threads never change a result: the same cells, bounds and verdicts on
/// one thread as on three.
#[test]
fn bab_threads_never_change_a_result() {
    let mut rng = Rng::new(32);
    for case in 0..6 {
        let net = random_network(&mut rng, 2, 2, Activation::Relu, (2, 6));
        let input = Region::Box(IBox::new(vec![-0.8, -0.6], vec![0.7, 0.9]));
        let y = net.forward(&[0.0, 0.0]);
        let p = bab_plan(
            net,
            input,
            vec![NetProperty {
                name: "p".into(),
                kind: NetPropertyKind::Require(Polytope {
                    rows: vec![(vec![1.0, -1.0], y[0] - y[1] + 0.2 + 0.1 * case as f64)],
                }),
            }],
        );
        let one = run(&p);
        let three = execute_network(
            &p,
            &Control {
                elapsed: &|| 0.0,
                time_limit: None,
                progress: &|_| {},
                threads: 3,
            },
        );
        assert_eq!(one.partition, three.partition, "case {case}");
        assert_eq!(one.output.offsets, three.output.offsets, "case {case}");
        assert_eq!(one.calls, three.calls, "case {case}");
        assert_eq!(
            format!("{:?}", one.properties),
            format!("{:?}", three.properties),
            "case {case}"
        );
    }
}

/// `net` (two inputs) as a network of `n` inputs that reads inputs `a`
/// and `b` only (the others' weights are zero).
fn widen(net: &Network, n: usize, a: usize, b: usize) -> Network {
    let mut layers = net.layers.clone();
    if let Layer::Affine { w, .. } = &mut layers[0] {
        let mut wide = nalgebra::DMatrix::zeros(w.nrows(), n);
        wide.set_column(a, &w.column(0));
        wide.set_column(b, &w.column(1));
        *w = wide;
    }
    Network::new(n, layers)
}

/// One case of [`bab_on_activations_agrees_with_exhaustive_enumeration`]: a
/// random two-input ReLU network widened to 10 inputs (every third behind a
/// normalisation), a `require` row 2 % of the range above (case even) or
/// below (odd) its true maximum over the box; with the plan, the network
/// and the threshold on the other side of the maximum.
struct Case {
    p: ravel::lower::NetworkPlan,
    net: Network,
    holds: bool,
    top: f64,
    h: f64,
    other: f64,
    dir: Vec<f64>,
    input: Region,
}

fn activation_case(rng: &mut Rng, case: usize) -> Case {
    let m = 1 + rng.below(2);
    let small = random_network(rng, 2, m, Activation::Relu, (2, 5));
    let c0 = [rng.normal(), rng.normal()];
    let r = [0.3 + rng.unit(), 0.3 + rng.unit()];
    let (lo, hi) = ([c0[0] - r[0], c0[1] - r[1]], [c0[0] + r[0], c0[1] + r[1]]);
    let verts = region_vertices(&small, lo, hi);
    let dir: Vec<f64> = (0..m).map(|_| rng.normal()).collect();
    let top = exact_max(&small, &verts, &dir);
    let delta = 0.02 * (1.0 + top.abs());
    let holds = case % 2 == 0;
    let (h, other) = if holds {
        (top + delta, top - delta)
    } else {
        (top - delta, top + delta)
    };
    let net = widen(&small, 10, 3, 7);
    let (mut blo, mut bhi) = (vec![-1.0; 10], vec![1.0; 10]);
    (blo[3], bhi[3], blo[7], bhi[7]) = (lo[0], hi[0], lo[1], hi[1]);
    // every third case behind a normalisation x ↦ 4x − 1 (consecutive
    // affine layers: searched on activations through ReLU pairs), on
    // the box that it maps onto the same one (up to rounding, far
    // inside the cases' 2 % margins)
    let normalised = case % 3 == 0;
    let net = if normalised {
        let mut layers = vec![Layer::Affine {
            w: nalgebra::DMatrix::from_diagonal_element(10, 10, 4.0),
            b: nalgebra::DVector::from_element(10, -1.0),
        }];
        layers.extend(net.layers.iter().cloned());
        blo.iter_mut().for_each(|v| *v = (*v + 1.0) / 4.0);
        bhi.iter_mut().for_each(|v| *v = (*v + 1.0) / 4.0);
        Network::new(10, layers)
    } else {
        net
    };
    let input = Region::Box(IBox::new(blo, bhi));
    let p = bab_plan(
        net.clone(),
        input.clone(),
        vec![NetProperty {
            name: "p".into(),
            kind: NetPropertyKind::Require(Polytope {
                rows: vec![(dir.clone(), h)],
            }),
        }],
    );
    Case {
        p,
        net,
        holds,
        top,
        h,
        other,
        dir,
        input,
    }
}

/// With more than 8 inputs branch and bound splits ReLU activations: on
/// random two-input networks widened to 10 inputs (8 of them ignored),
/// its answers agree with the exhaustive enumeration of the two-input
/// network's linear regions, counterexamples are real, and every
/// certificate is VALID (a VERIFIED one's evidence the split tree with its
/// multipliers, or input cells where the checker's bounds over the box
/// prove it).
#[test]
fn bab_on_activations_agrees_with_exhaustive_enumeration() {
    for phases in ActivationPhases::ALL {
        activations_agree_with_enumeration(phases);
    }
}

fn activations_agree_with_enumeration(phases: ActivationPhases) {
    use ravel_certify::{check, Answer};
    let mut rng = Rng::new(41);
    let (mut verified, mut falsified, mut trees) = (0, 0, 0);
    for case in 0..24 {
        let Case {
            mut p,
            net,
            holds,
            top,
            h,
            dir,
            input,
            ..
        } = activation_case(&mut rng, case);
        p.phases = phases;
        let out = run(&p);
        let got = out.properties[0].status;
        let want = if holds {
            Verdict::Verified
        } else {
            Verdict::Falsified
        };
        assert_eq!(
            got, want,
            "{phases:?} case {case}: truth {want:?} (max {top}, threshold {h}), bab says {got:?} after {} calls, stop {:?}",
            out.calls, out.partition_stop
        );
        if let Some(w) = &out.properties[0].counterexample {
            assert_real_witness(&net, &input, &dir, h, &w.input, case);
        }
        let cert = net_certificate(&p, &out);
        let answer = check(&cert, &net).answer;
        match got {
            Verdict::Verified => {
                verified += 1;
                assert!(out.split_activations, "case {case}: inputs were split");
                assert_eq!(
                    answer,
                    Answer::Valid,
                    "{phases:?} case {case}: {}",
                    cert["evidence"]
                );
                trees += usize::from(cert["evidence"].get("splits").is_some());
            }
            _ => {
                falsified += 1;
                assert_eq!(answer, Answer::Valid, "case {case}");
            }
        }
    }
    assert!(
        verified >= 10 && falsified >= 10 && trees >= 3,
        "{phases:?}: {verified} verified ({trees} by split trees), {falsified} falsified"
    );
}

/// A counterexample of `dir·f(x) ≤ h` is real: in the input set, above `h`.
fn assert_real_witness(net: &Network, input: &Region, dir: &[f64], h: f64, x: &[f64], case: usize) {
    assert!(input.contains_point(x), "case {case}");
    let v: f64 = dir.iter().zip(&net.forward(x)).map(|(a, b)| a * b).sum();
    assert!(v > h, "case {case}");
}

/// The portfolio's switch: with a call budget too small for the first
/// phase (half of it) to settle the harder cases, the search starts again
/// from the root with the second phase's rules. Its answers stay true
/// (VERIFIED only when the property holds, counterexamples real, UNSURE
/// allowed), and at least one case is proven by the second phase, its
/// certificate (a split tree marked `rebound`) VALID.
#[test]
fn the_portfolio_switches_phases_soundly() {
    use ravel_certify::{check, Answer};
    let mut rng = Rng::new(41);
    let (mut second, mut answered) = (0, 0);
    for case in 0..24 {
        let Case {
            mut p,
            net,
            holds,
            h,
            dir,
            input,
            ..
        } = activation_case(&mut rng, case);
        p.phases = ActivationPhases::Portfolio;
        // three calls: the first phase has one (half, rounded down), so
        // any case it does not settle at once goes to the second
        if let Partitioner::Guided { budget, .. } = &mut p.partitioner {
            budget.calls = 3;
        }
        let out = run(&p);
        let got = out.properties[0].status;
        match got {
            Verdict::Verified => assert!(holds, "case {case}: VERIFIED a false property"),
            Verdict::Falsified => {
                assert!(!holds, "case {case}: FALSIFIED a true property");
                let w = out.properties[0]
                    .counterexample
                    .as_ref()
                    .expect("a witness");
                assert_real_witness(&net, &input, &dir, h, &w.input, case);
            }
            _ => continue,
        }
        answered += 1;
        let cert = net_certificate(&p, &out);
        assert_eq!(check(&cert, &net).answer, Answer::Valid, "case {case}");
        if got == Verdict::Verified && cert["evidence"]["splits"]["rebound"] == true {
            second += 1;
        }
    }
    assert!(
        second >= 1 && answered >= 12,
        "{second} proven by the second phase, {answered} answered"
    );
}

/// The split tree `nodes` without the strict descendants of node `at`,
/// which becomes a leaf (children renumbered).
fn drop_subtree(nodes: &[serde_json::Value], at: usize) -> Vec<serde_json::Value> {
    let mut gone = vec![false; nodes.len()];
    let mut todo = vec![at];
    while let Some(i) = todo.pop() {
        if let Some(s) = nodes[i].get("split") {
            for c in [s[2].as_u64().unwrap(), s[3].as_u64().unwrap()] {
                gone[c as usize] = true;
                todo.push(c as usize);
            }
        }
    }
    let mut index = vec![0; nodes.len()];
    let mut n = 0;
    for (i, g) in gone.iter().enumerate() {
        index[i] = n;
        n += usize::from(!g);
    }
    let mut out = Vec::new();
    for (i, node) in nodes.iter().enumerate() {
        if gone[i] {
            continue;
        }
        let mut node = node.clone();
        if i == at {
            node.as_object_mut().unwrap().remove("split");
        } else if let Some(s) = node.get("split").cloned() {
            let c = |k: usize| index[s[k].as_u64().unwrap() as usize];
            node["split"] = serde_json::json!([s[0], s[1], c(2), c(3)]);
        }
        out.push(node);
    }
    out
}

/// Tampering with activation-split evidence is caught: the true
/// threshold's evidence for a false one, every claimed pre-activation bound
/// shrunk by twice the writer's margin, the root's subtree dropped,
/// multipliers perturbed or overflowing, never give VALID; swapped
/// children (a leaf's phase flipped) give VALID only where the proofs hold
/// on both sides, and some do not; malformed trees are UNREADABLE; a
/// search record dropped past its memory limit, or without its proofs,
/// makes the writer's evidence UNSUPPORTED; random junk in the tree of a
/// false threshold is never VALID and never panics.
#[test]
fn activation_split_certificates_catch_tampering() {
    use ravel_certify::{check, Answer};
    use serde_json::{json, Value};
    let mut rng = Rng::new(41);
    // the tampering's own random numbers (the cases stay those of the
    // test above, and more)
    let mut noise = Rng::new(7);
    let (mut tried, mut swaps_caught, mut drops_caught, mut deep) = (0, 0, 0, 0);
    for case in 0..40 {
        let c = activation_case(&mut rng, case);
        if !c.holds {
            continue;
        }
        let out = run(&c.p);
        let cert = net_certificate(&c.p, &out);
        if cert["evidence"].get("splits").is_none() {
            continue;
        }
        assert_eq!(check(&cert, &c.net).answer, Answer::Valid, "case {case}");
        tried += 1;
        // (claims proved by multipliers past the first hidden layer)
        let splits = &cert["evidence"]["splits"];
        deep += usize::from(splits["neurons"].as_array().is_some_and(|n| !n.is_empty()));
        // a record dropped past its memory limit, or one whose proofs are
        // lost: the writer says UNSUPPORTED, never VALID
        let mut dropped = out.clone();
        let mut bare = (**out.split_record.as_ref().unwrap()).clone();
        bare.nodes.iter_mut().for_each(|n| n.proofs.clear());
        let mut gone = bare.clone();
        gone.dropped = Some("outgrew".into());
        for r in [bare, gone] {
            dropped.split_record = Some(std::sync::Arc::new(r));
            let a = check(&net_certificate(&c.p, &dropped), &c.net).answer;
            assert!(matches!(a, Answer::Unsupported(_)), "case {case}: {a:?}");
        }
        let answer = |v: &Value| check(v, &c.net).answer;
        let invalid = |v: &Value, what: &str| {
            let a = answer(v);
            assert!(
                matches!(a, Answer::Invalid(_)),
                "case {case}: {what}: {a:?}"
            );
        };
        let unreadable = |v: &Value, what: &str| {
            let a = answer(v);
            assert!(
                matches!(a, Answer::Unreadable(_)),
                "case {case}: {what}: {a:?}"
            );
        };
        // the evidence of the true threshold does not prove a false one
        let mut lie = cert.clone();
        lie["problem"]["properties"][0]["rows"][0]["b"] = json!(c.other);
        invalid(&lie, "a false threshold");
        // every claimed pre-activation bound shrunk by twice the margin
        let hair = |v: f64| 2.0 * (1.0 + v.abs()) / 68_719_476_736.0;
        let layers = cert["evidence"]["splits"]["layers"]
            .as_array()
            .unwrap()
            .len();
        for k in 0..layers {
            let n = cert["evidence"]["splits"]["layers"][k]["lo"]
                .as_array()
                .unwrap()
                .len();
            for j in 0..n {
                for (side, sign) in [("lo", 1.0), ("hi", -1.0)] {
                    let mut t = cert.clone();
                    let at = &mut t["evidence"]["splits"]["layers"][k][side][j];
                    let v = at.as_f64().unwrap();
                    *at = json!(v + sign * hair(v));
                    invalid(&t, &format!("layer {k} neuron {j} {side} shrunk"));
                }
            }
        }
        let nodes = cert["evidence"]["splits"]["nodes"]
            .as_array()
            .unwrap()
            .clone();
        let with_nodes = |nodes: Vec<Value>| {
            let mut t = cert.clone();
            t["evidence"]["splits"]["nodes"] = json!(nodes);
            t
        };
        // the whole tree dropped: the root proves nothing on its own (else
        // the search would not have split it); any other subtree dropped
        // gives VALID only where its root's path proves the row
        if nodes[0].get("split").is_some() {
            invalid(
                &with_nodes(drop_subtree(&nodes, 0)),
                "the root's subtree dropped",
            );
        }
        for (i, node) in nodes.iter().enumerate().skip(1) {
            if node.get("split").is_some() {
                let a = answer(&with_nodes(drop_subtree(&nodes, i)));
                assert!(matches!(a, Answer::Invalid(_) | Answer::Valid), "{a:?}");
                drops_caught += usize::from(matches!(a, Answer::Invalid(_)));
            }
        }
        // children swapped: each leaf's proofs evaluated on the other phase
        for (i, node) in nodes.iter().enumerate() {
            if let Some(s) = node.get("split") {
                let mut t = nodes.clone();
                t[i]["split"] = json!([s[0], s[1], s[3], s[2]]);
                let a = answer(&with_nodes(t));
                assert!(matches!(a, Answer::Invalid(_) | Answer::Valid), "{a:?}");
                swaps_caught += usize::from(matches!(a, Answer::Invalid(_)));
            }
        }
        // multipliers perturbed: never VALID for the false threshold;
        // overflowing ones (1e308) prove nothing
        let mut noisy = lie.clone();
        let mut huge = cert.clone();
        for (t, big) in [(&mut noisy, false), (&mut huge, true)] {
            for node in t["evidence"]["splits"]["nodes"].as_array_mut().unwrap() {
                for p in node
                    .get_mut("proofs")
                    .and_then(Value::as_array_mut)
                    .into_iter()
                    .flatten()
                {
                    for layer in p["nu"].as_array_mut().unwrap() {
                        for v in layer.as_array_mut().unwrap() {
                            let x = v.as_f64().unwrap();
                            *v = json!(if big {
                                1e308
                            } else {
                                x * (1.0 + 0.5 * noise.normal())
                            });
                        }
                    }
                }
            }
        }
        invalid(&noisy, "perturbed multipliers for a false threshold");
        invalid(&huge, "multipliers of 1e308");
        // malformed trees
        let mut t = nodes.clone();
        if let Some(i) = nodes.iter().position(|n| n.get("split").is_some()) {
            let s = nodes[i]["split"].clone();
            t[i]["split"] = json!([s[0], s[1], i, s[3]]);
            unreadable(&with_nodes(t.clone()), "a child before its parent");
            t[i]["split"] = json!([s[0], s[1], nodes.len(), s[3]]);
            unreadable(&with_nodes(t.clone()), "a child out of range");
            t[i]["split"] = json!([s[0], s[1], s[2], s[2]]);
            unreadable(&with_nodes(t.clone()), "one child twice");
            t[i]["split"] = json!([99, s[1], s[2], s[3]]);
            unreadable(&with_nodes(t.clone()), "no such layer");
        }
        let mut t = nodes.clone();
        t.push(json!({}));
        unreadable(&with_nodes(t), "an orphan node");
        // random junk in the false threshold's evidence: never VALID, no panic
        let mut leaves = Vec::new();
        pointers(
            &lie["evidence"]["splits"],
            "/evidence/splits".into(),
            &mut leaves,
        );
        let junk = [
            json!(null),
            json!("x"),
            json!(-1),
            json!(1e308),
            json!(-1e308),
            json!(0),
            json!(u64::MAX),
            json!([]),
            json!({}),
            json!([[1e308]]),
        ];
        for _ in 0..100 {
            let mut t = lie.clone();
            for _ in 0..1 + noise.below(3) {
                let at = &leaves[noise.below(leaves.len())];
                // (a pointer under a value replaced before: gone)
                if let Some(x) = t.pointer_mut(at) {
                    *x = junk[noise.below(junk.len())].clone();
                }
            }
            let a = answer(&t);
            assert!(!matches!(a, Answer::Valid), "case {case}: junk gave VALID");
        }
    }
    assert!(
        tried >= 6 && deep >= 2,
        "{tried} certificates with split trees, {deep} with neurons' multipliers"
    );
    assert!(
        swaps_caught > 0 && drops_caught > 0,
        "{swaps_caught} swaps, {drops_caught} drops caught"
    );
}

/// The JSON pointers of every value under `v` (arrays and objects too).
fn pointers(v: &serde_json::Value, at: String, out: &mut Vec<String>) {
    out.push(at.clone());
    match v {
        serde_json::Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                pointers(x, format!("{at}/{i}"), out);
            }
        }
        serde_json::Value::Object(o) => {
            for (k, x) in o {
                pointers(x, format!("{at}/{k}"), out);
            }
        }
        _ => {}
    }
}
