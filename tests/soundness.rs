//! Monte Carlo soundness: on many seeded random networks and plants, every
//! simulated trajectory stays inside every reachable set that every
//! propagator computes, with and without noise, limits and partitioning,
//! with box and polytope boundaries, box and ℓp-ball initial sets, and
//! time-varying plants.

mod common;

use common::random_network;
use nalgebra::{DMatrix, DVector};
use ravel_analysis::closed_loop::{Boundary, ClosedLoop, ModelError, Plant, Propagator};
use ravel_analysis::crown::{Mode, Relaxation};
use ravel_analysis::sets::{IBox, Norm, Region};
use ravel_base::nn::{Activation, Layer};
use ravel_base::rng::Rng;

const PROPAGATORS: [Propagator; 6] = Propagator::ALL;

struct Case {
    cl: ClosedLoop,
    x0: Region,
    horizon: usize,
    label: String,
}

fn random_case(seed: u64) -> Case {
    let mut rng = Rng::new(seed);
    let n = 1 + rng.below(3);
    let m = 1 + rng.below(2);
    let act = [Activation::Relu, Activation::Tanh, Activation::Sigmoid][seed as usize % 3];
    let noisy = seed % 2 == 1;
    let limited = (seed / 2) % 2 == 1;
    let observed = (seed / 4) % 2 == 1;
    let p = if observed { 1 + rng.below(n + 1) } else { n };
    let a = DMatrix::from_fn(
        n,
        n,
        |i, j| if i == j { 0.9 } else { 0.0 } + rng.normal() * 0.25,
    );
    let mut b = DMatrix::from_fn(n, m, |_, _| rng.normal() * 0.5);
    // one nonzero per row of B (as an Euler-discretised plant has): every
    // facet row of M·B then has one nonzero, the rows CROWN's homogeneity
    // lets Reach-LP scale from the control box's instead of
    // back-substituting them (for one control, every case is such)
    let sparse_b = m > 1 && seed % 3 == 2;
    if sparse_b {
        for i in 0..n {
            for j in 0..m {
                if j != i % m {
                    b[(i, j)] = 0.0;
                }
            }
        }
    }
    let c = DVector::from_fn(n, |_, _| rng.normal() * 0.1);
    let obs = if observed {
        DMatrix::from_fn(n, p, |_, _| rng.normal())
    } else {
        DMatrix::identity(n, n)
    };
    let noise = |rng: &mut Rng, k: usize| {
        if noisy {
            let lo: Vec<f64> = (0..k).map(|_| -rng.uniform(0.0, 0.05)).collect();
            let hi: Vec<f64> = (0..k).map(|_| rng.uniform(0.0, 0.05)).collect();
            IBox::new(lo, hi)
        } else {
            IBox::new(vec![0.0; k], vec![0.0; k])
        }
    };
    let w = noise(&mut rng, n);
    let v = noise(&mut rng, p);
    let mut net = random_network(&mut rng, p, m, act, (3, 7));
    if limited {
        let lo: Vec<f64> = (0..m).map(|_| -rng.uniform(0.2, 1.0)).collect();
        let hi: Vec<f64> = (0..m).map(|_| rng.uniform(0.2, 1.0)).collect();
        net = net.with_saturation(&lo, &hi);
    }
    let centre: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
    let radius: Vec<f64> = (0..n).map(|_| rng.uniform(0.01, 0.4)).collect();
    let ball = seed % 4 == 3;
    let x0 = if ball {
        let norm = [Norm::L1, Norm::L2, Norm::LInf][(seed / 4) as usize % 3];
        Region::Ball {
            center: centre,
            radius,
            norm,
        }
    } else {
        Region::Box(IBox::new(
            centre.iter().zip(&radius).map(|(c, r)| c - r).collect(),
            centre.iter().zip(&radius).map(|(c, r)| c + r).collect(),
        ))
    };
    let varying = seed % 5 == 2;
    // uncertain A, B, c (as a discretised continuous-time plant has)
    let uncertain = seed % 6 == 1;
    let err = uncertain.then(|| ModelError {
        a: a.map(|x| x.abs() * 0.05 + 0.01),
        b: b.map(|x| x.abs() * 0.05 + 0.01),
        c: c.map(|x| x.abs() * 0.05 + 0.01),
    });
    let horizon = 4;
    let plant = Plant {
        a,
        b,
        c,
        obs,
        w,
        v,
        err,
    };
    let plants: Vec<Plant> = if varying {
        (0..horizon)
            .map(|_| {
                let mut p = plant.clone();
                p.a = p.a.map(|x| x + rng.normal() * 0.1);
                p.b = p.b.map(|x| x + rng.normal() * 0.1);
                p.c = p.c.map(|x| x + rng.normal() * 0.1);
                p
            })
            .collect()
    } else {
        vec![plant]
    };
    let label = format!(
        "seed {seed}: n={n} m={m} p={p} {act:?} noise={noisy} limits={limited} ball={ball} varying={varying} uncertain={uncertain} sparse_b={sparse_b}"
    );
    Case {
        cl: ClosedLoop::time_varying(plants, net),
        x0,
        horizon,
        label,
    }
}

/// Reachable sets of one propagator; with `alone`, its own bounds only,
/// before any intersection with another method's.
fn reach(
    cl: &ClosedLoop,
    x0: &Region,
    horizon: usize,
    prop: Propagator,
    boundary: &Boundary,
    alone: bool,
) -> Vec<Region> {
    if prop == Propagator::CrownUnrolled {
        let steps = if alone {
            cl.unrolled_alone(x0, horizon, boundary)
        } else {
            cl.unrolled(x0, horizon, boundary, None, &|| false)
        };
        return steps.into_iter().map(|s| s.set).collect();
    }
    let mut sets = vec![x0.clone()];
    for t in 0..horizon {
        let next = if alone {
            cl.step_alone(t, &sets[t], prop, boundary)
        } else {
            cl.step(t, &sets[t], prop, boundary)
        };
        sets.push(next.set);
    }
    sets
}

/// Membership with this test's own arithmetic (a hair of slack for the f64
/// simulation of rows; boxes are checked exactly).
fn inside(r: &Region, x: &[f64]) -> bool {
    let b = r.bbox();
    if !b.contains_point(x) {
        return false;
    }
    match r {
        Region::Polytope { rows, .. } => rows.iter().all(|(a, h)| {
            let ax: f64 = a.iter().zip(x).map(|(a, x)| a * x).sum();
            ax <= h + 1e-12 * (1.0 + h.abs())
        }),
        _ => true,
    }
}

/// A start state: box corners and interior points; for a ball, points of
/// its bounding box that pass this test's own norm check.
fn initial_point(rng: &mut Rng, x0: &Region) -> Vec<f64> {
    match x0 {
        Region::Ball {
            center,
            radius,
            norm,
        } => loop {
            let x: Vec<f64> = (0..center.len())
                .map(|i| rng.uniform(center[i] - radius[i], center[i] + radius[i]))
                .collect();
            let d: Vec<f64> = (0..x.len())
                .map(|i| ((x[i] - center[i]) / radius[i]).abs())
                .collect();
            let len = match norm {
                Norm::L1 => d.iter().sum(),
                Norm::L2 => d.iter().map(|v| v * v).sum::<f64>().sqrt(),
                Norm::LInf => d.iter().fold(0.0f64, |a, v| a.max(*v)),
            };
            if len <= 1.0 {
                return x;
            }
        },
        _ => sample_point(rng, &x0.bbox()),
    }
}

/// `next + ΔA x + ΔB u + Δc` for a random model error within `e` (each entry
/// at its lower or upper bound with probability ¼ each, else uniform).
fn perturbed(rng: &mut Rng, e: &ModelError, x: &[f64], u: &[f64], next: Vec<f64>) -> Vec<f64> {
    let mut pick = |r: f64| match rng.below(4) {
        0 => -r,
        1 => r,
        _ => rng.uniform(-r, r),
    };
    next.iter()
        .enumerate()
        .map(|(i, v)| {
            let mut s = *v + pick(e.c[i]);
            for (j, xj) in x.iter().enumerate() {
                s += pick(e.a[(i, j)]) * xj;
            }
            for (j, uj) in u.iter().enumerate() {
                s += pick(e.b[(i, j)]) * uj;
            }
            s
        })
        .collect()
}

/// One true step from `x`: random noise in its boxes and, for an uncertain
/// plant, random matrices within the model error.
fn advance(rng: &mut Rng, cl: &ClosedLoop, t: usize, x: &[f64]) -> Vec<f64> {
    let w = sample_point(rng, &cl.plant.w);
    let v = sample_point(rng, &cl.plant.v);
    let (u, next) = cl.simulate(t, x, &w, &v);
    match &cl.plant_at(t).err {
        Some(e) => perturbed(rng, e, x, &u, next),
        None => next,
    }
}

fn sample_point(rng: &mut Rng, b: &IBox) -> Vec<f64> {
    (0..b.dim())
        .map(|i| match rng.below(4) {
            0 => b.lo[i],
            1 => b.hi[i],
            _ => rng.uniform(b.lo[i], b.hi[i]),
        })
        .collect()
}

#[test]
fn every_trajectory_stays_inside_every_reachable_set() {
    let mut checked = 0usize;
    for seed in 0..60u64 {
        let case = random_case(seed);
        let n = case.x0.dim();
        let cells = case.x0.grid(&vec![2; n]);
        let mut boundaries = vec![Boundary::Box];
        if n == 2 {
            boundaries.push(Boundary::spread(6));
            // directions that change from step to step, as a hull boundary's do
            let mut rng = Rng::new(1000 + seed);
            boundaries.push(Boundary::PerStep(
                (0..=case.horizon)
                    .map(|_| {
                        let pts: Vec<[f64; 2]> =
                            (0..12).map(|_| [rng.normal(), rng.normal()]).collect();
                        ravel_analysis::shape::hull_directions(&pts, 0.2)
                    })
                    .collect(),
            ));
        } else if seed % 3 == 0 {
            boundaries.push(Boundary::Polytope(DMatrix::from_fn(3, n, |r, c| {
                ((r * 7 + c * 3 + seed as usize) % 5) as f64 - 2.0 + 0.5
            })));
        }
        for boundary in &boundaries {
            for prop in PROPAGATORS {
                let whole = reach(&case.cl, &case.x0, case.horizon, prop, boundary, false);
                let own = reach(&case.cl, &case.x0, case.horizon, prop, boundary, true);
                // Reach-SDP solves one SDP per facet and step: its partitioned
                // runs are left to the spec tests to keep this suite fast.
                let parts: Vec<Vec<Region>> = if prop == Propagator::ReachSdp {
                    vec![whole.clone(); cells.len()]
                } else {
                    cells
                        .iter()
                        .map(|c| reach(&case.cl, c, case.horizon, prop, boundary, false))
                        .collect()
                };
                let mut rng = Rng::new(seed * 7919 + 1);
                for _ in 0..100 {
                    let mut x = initial_point(&mut rng, &case.x0);
                    let cell = cells
                        .iter()
                        .position(|c| c.bbox().contains_point(&x))
                        .expect("the grid covers X0");
                    for t in 0..=case.horizon {
                        assert!(
                            inside(&whole[t], &x),
                            "{} {prop:?} {boundary:?}: step {t} state {x:?} outside {:?}",
                            case.label,
                            whole[t]
                        );
                        assert!(
                            inside(&own[t], &x),
                            "{} {prop:?} {boundary:?} own bounds: step {t} state {x:?} outside {:?}",
                            case.label,
                            own[t]
                        );
                        assert!(
                            inside(&parts[cell][t], &x),
                            "{} {prop:?} {boundary:?} partitioned: step {t} state {x:?} outside {:?}",
                            case.label,
                            parts[cell][t]
                        );
                        checked += 1;
                        if t < case.horizon {
                            x = advance(&mut rng, &case.cl, t, &x);
                        }
                    }
                }
            }
        }
    }
    assert!(checked > 150_000, "only {checked} states were checked");
}

#[test]
fn network_bounds_contain_network_outputs() {
    for seed in 0..60u64 {
        let mut rng = Rng::new(1000 + seed);
        let act = [Activation::Relu, Activation::Tanh, Activation::Sigmoid][seed as usize % 3];
        let inputs = 1 + rng.below(4);
        let outputs = 1 + rng.below(3);
        let net = random_network(&mut rng, inputs, outputs, act, (3, 7));
        let c: Vec<f64> = (0..inputs).map(|_| rng.normal()).collect();
        let r = rng.uniform(0.01, 1.5);
        let input = IBox::new(
            c.iter().map(|v| v - r).collect(),
            c.iter().map(|v| v + r).collect(),
        );
        let crown = Relaxation::new(&net, &input, Mode::Crown).output_box(Mode::Crown);
        let ibp = Relaxation::new(&net, &input, Mode::Ibp).output_box(Mode::Ibp);
        assert!(
            ibp.contains_box(&crown),
            "CROWN (intersected with IBP) must lie within IBP"
        );
        for _ in 0..500 {
            let x = sample_point(&mut rng, &input);
            let y = net.forward(&x);
            assert!(
                crown.contains_point(&y),
                "seed {seed} {act:?}: {y:?} outside {crown:?}"
            );
        }
    }
}

#[test]
fn linear_bounds_hold_pointwise() {
    // CROWN's linear functions (not only their concretisation) must bound the network.
    for seed in 0..30u64 {
        let mut rng = Rng::new(5000 + seed);
        let act = [Activation::Relu, Activation::Tanh, Activation::Sigmoid][seed as usize % 3];
        let net = random_network(&mut rng, 2, 2, act, (3, 7));
        let input = IBox::new(vec![-0.7, -0.2], vec![0.4, 0.9]);
        let a = Relaxation::new(&net, &input, Mode::Crown);
        let spec = DMatrix::from_row_slice(2, 2, &[1.0, -0.5, -1.0, 0.25]);
        let bound = a.upper(spec.clone());
        for _ in 0..500 {
            let x = sample_point(&mut rng, &input);
            let y = DVector::from_vec(net.forward(&x));
            let s = &spec * y;
            for r in 0..2 {
                let lin: f64 =
                    (0..2).map(|i| bound.coef.get(r, i) * x[i]).sum::<f64>() + bound.offset[r];
                assert!(s[r] <= lin + 1e-12, "seed {seed} row {r}: {} > {lin}", s[r]);
            }
        }
    }
}

#[test]
fn open_loop_output_sets_contain_every_output_and_partitions_only_tighten() {
    use ravel_analysis::open_loop::{output_set, sample_inputs, Partitioner};
    use ravel_analysis::partition::{Budget, Strategy};
    use ravel_analysis::shape::Shape;
    let guided = |strategy, calls| Partitioner::Guided {
        strategy,
        budget: Budget {
            calls,
            min_size: 1.0 / 64.0,
            seconds: None,
        },
    };
    for seed in 0..24u64 {
        let mut rng = Rng::new(7000 + seed);
        let act = [Activation::Relu, Activation::Tanh, Activation::Sigmoid][seed as usize % 3];
        let n = 1 + rng.below(3);
        let m = 1 + rng.below(3);
        let net = random_network(&mut rng, n, m, act, (3, 7));
        let lo: Vec<f64> = (0..n).map(|_| rng.uniform(-1.0, 0.0)).collect();
        let hi: Vec<f64> = lo.iter().map(|l| l + rng.uniform(0.2, 1.5)).collect();
        let input = IBox::new(lo, hi);
        let inputs = sample_inputs(&input, 64, seed);
        let mut shapes = vec![Shape::LowerBounds, Shape::Box, Shape::Hull];
        shapes.push(Shape::Polytope(DMatrix::from_fn(3, m, |_, _| rng.normal())));
        let points: Vec<Vec<f64>> = (0..400).map(|_| sample_point(&mut rng, &input)).collect();
        for mode in [Mode::Ibp, Mode::Crown] {
            for shape in &shapes {
                let whole = output_set(
                    &net,
                    &input,
                    mode,
                    shape,
                    &Partitioner::Uniform(vec![1; n]),
                    &inputs,
                    &|| 0.0,
                );
                let few = output_set(
                    &net,
                    &input,
                    mode,
                    shape,
                    &guided(Strategy::Gsg, 6),
                    &inputs,
                    &|| 0.0,
                );
                for part in [
                    Partitioner::Uniform(vec![3; n]),
                    guided(Strategy::Sg, 24),
                    guided(Strategy::Gsg, 24),
                ] {
                    let out = output_set(&net, &input, mode, shape, &part, &inputs, &|| 0.0);
                    let label = format!("seed {seed} {mode:?} {shape:?} {part:?}");
                    assert_eq!(out.directions, whole.directions, "{label}");
                    // every output inside the union and inside its own cell's set
                    for x in &points {
                        let y = DVector::from_vec(net.forward(x));
                        let d = &out.directions * &y;
                        for k in 0..d.len() {
                            let tol = 1e-12 * (1.0 + d[k].abs());
                            assert!(d[k] <= out.offsets[k] + tol, "{label}: row {k}");
                            assert!(d[k] <= whole.offsets[k] + tol, "{label}: row {k} (whole)");
                        }
                        let cell = out
                            .cells
                            .iter()
                            .find(|(c, _)| c.contains_point(x))
                            .expect("cells cover the input");
                        for k in 0..d.len() {
                            assert!(d[k] <= cell.1[k] + 1e-12 * (1.0 + d[k].abs()), "{label}");
                        }
                    }
                    // never looser than no partition; the sampled offsets are below
                    for k in 0..out.offsets.len() {
                        assert!(out.offsets[k] <= whole.offsets[k], "{label}: row {k}");
                        assert!(out.sampled[k] <= out.offsets[k], "{label}: row {k}");
                    }
                    // a larger GSG budget never loosens the union
                    if part == guided(Strategy::Gsg, 24) {
                        for k in 0..out.offsets.len() {
                            assert!(out.offsets[k] <= few.offsets[k], "{label}: row {k}");
                        }
                    }
                }
                if *shape == Shape::LowerBounds {
                    assert!(whole.bbox().is_none());
                    let lb = whole.lower_bounds();
                    for x in &points {
                        let y = net.forward(x);
                        assert!(y
                            .iter()
                            .zip(&lb)
                            .all(|(y, l)| *y >= *l - 1e-12 * (1.0 + y.abs())));
                    }
                } else {
                    let b = whole.bbox().expect("box rows");
                    assert_eq!(whole.lower_bounds(), b.lo);
                }
            }
        }
    }
}

/// The whole pipeline from a plan: `execute` with every partitioner (uniform,
/// SG, GSG, property-guided), box / polytope / hull boundaries, box, polytope
/// and ball initial sets, time-varying and uncertain (continuous-time-like)
/// plants. Every simulated trajectory (this test's own sampling and
/// simulation) lies, at every step, in the union of the cells' sets.
#[test]
fn every_trajectory_stays_inside_what_execute_reports() {
    use ravel::execute::{execute_system, Control};
    use ravel::lower::{
        GoalMode, Guide, Partitioner, Property, PropertyKind, StateSet, SystemPlan, Window,
    };
    use ravel_analysis::partition::Budget;
    use ravel_analysis::sets::Polytope;

    let mut checked = 0usize;
    let mut certified = 0usize;
    let mut claimed = 0usize;
    for seed in 0..36u64 {
        let case = random_case(seed);
        let n = case.x0.dim();
        // every third box case becomes a polytope: the box cut through its centre
        let x0 = match &case.x0 {
            Region::Box(b) if seed % 3 == 0 => {
                let mut a = vec![0.0; n];
                a[0] = 1.0;
                if n > 1 {
                    a[1] = 0.5;
                }
                let c: Vec<f64> = b.lo.iter().zip(&b.hi).map(|(l, h)| 0.5 * (l + h)).collect();
                let h = a.iter().zip(&c).map(|(a, c)| a * c).sum::<f64>() + 0.05;
                let mut rows = Polytope::from_box(b).rows;
                rows.push((a, h));
                Region::Polytope {
                    bbox: b.clone(),
                    rows,
                }
            }
            other => other.clone(),
        };
        let budget = Budget {
            calls: 7,
            min_size: 0.05,
            seconds: None,
        };
        let partitioner = match seed % 4 {
            0 => Partitioner::Uniform(vec![2; n]),
            1 => Partitioner::Guided {
                guide: Guide::Sg,
                budget,
            },
            2 => Partitioner::Guided {
                guide: Guide::Gsg,
                budget,
            },
            _ => Partitioner::Guided {
                guide: Guide::Property,
                budget,
            },
        };
        let boundary = match (n, seed % 3) {
            (2, 0) => Boundary::Hull,
            (2, 1) => Boundary::spread(8),
            _ => Boundary::Box,
        };
        let b0 = x0.bbox();
        // a goal the loop may or may not meet: the property-guided partitioner has work
        let goal = Polytope::from_box(&IBox::new(
            b0.lo.iter().map(|l| l - 0.5).collect(),
            b0.hi.iter().map(|h| h + 0.5).collect(),
        ));
        let mut toward = vec![0.0; n];
        toward[0] = -1.0;
        let far = Polytope {
            rows: vec![(toward, -(b0.hi[0] + 100.0))],
        };
        for prop in PROPAGATORS {
            if prop == Propagator::ReachSdp && seed % 6 != 0 {
                continue;
            }
            let plan = SystemPlan {
                system: "random".into(),
                state_name: "x".into(),
                control_name: "u".into(),
                controller_path: String::new(),
                controller_sha256: String::new(),
                controller_resolved: String::new(),
                network_summary: String::new(),
                closed_loop: ravel_analysis::feedback::Loop::Linear(Box::new(case.cl.clone())),
                dt: None,
                intersample: None,
                limits: None,
                initial: x0.clone(),
                initial_name: "X0".into(),
                partitioner: partitioner.clone(),
                boundary: boundary.clone(),
                horizon: case.horizon,
                propagator: prop,
                properties: vec![
                    Property {
                        name: "G".into(),
                        kind: PropertyKind::Goal {
                            set: StateSet::linear(goal.clone()),
                            window: Window::at(case.horizon),
                            mode: GoalMode::Always,
                        },
                    },
                    // far away: usually VERIFIED, so certificates have evidence
                    Property {
                        name: "far".into(),
                        kind: PropertyKind::Avoid {
                            members: vec![StateSet::linear(far.clone())],
                            window: Window::steps(0, case.horizon),
                        },
                    },
                ],
                samples: 200,
                seed,
            };
            let out = execute_system(&plan, &Control::unlimited());
            let what = format!(
                "{} {prop:?} {:?} {:?}",
                case.label, plan.partitioner, plan.boundary
            );
            // the certificate of the result: VALID (every VERIFIED verdict
            // re-checked), never INVALID
            let id = ravel::certificate_writer::Identity {
                spec_path: String::new(),
                spec_sha256: String::new(),
            };
            let cert = ravel::certificate_writer::build_system(&plan, &out, &id);
            let report = ravel_certify::check(&cert, plan.closed_loop.net());
            match &report.answer {
                ravel_certify::Answer::Valid => {
                    if out
                        .properties
                        .iter()
                        .any(|p| p.status == ravel::execute::Verdict::Verified)
                    {
                        certified += 1;
                    }
                }
                // only a verdict that Reach-SDP's tightness alone proves may
                // lack checkable evidence (its multipliers are no witness yet)
                ravel_certify::Answer::Unsupported(m) if prop == Propagator::ReachSdp => {
                    let _ = m;
                }
                other => panic!("{what}: certificate {other:?}"),
            }
            // the claims of a checkable certificate: (steps, per cell the claims)
            let claims = (cert["evidence"]["status"] == "checkable").then(|| {
                let steps = cert["evidence"]["steps"].as_u64().unwrap_or(0) as usize;
                let cells: Vec<Vec<serde_json::Value>> = cert["evidence"]["cells"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .map(|c| c["steps"].as_array().cloned().unwrap_or_default())
                    .collect();
                (steps, cells)
            });
            let mut rng = Rng::new(seed * 104_729 + 17);
            let mut tried = 0;
            while tried < 60 {
                let mut x = initial_point(&mut rng, &case.x0);
                if !x0.contains_point(&x) {
                    continue; // outside the polytope cut
                }
                tried += 1;
                for t in 0..=case.horizon {
                    assert!(
                        out.cells.iter().any(|c| inside(&c[t], &x)),
                        "{what}: step {t} state {x:?} outside every cell (bounding box {:?})",
                        out.reach[t]
                    );
                    checked += 1;
                    // and inside the certificate's claims (boxes cut by their
                    // inequalities), whose supports use LP duals and balls
                    if let Some(claims) = claims.as_ref().filter(|c| t >= 1 && t <= c.0) {
                        assert!(
                            claims.1.iter().any(|cell| claim_holds(&cell[t - 1], &x)),
                            "{what}: step {t} state {x:?} outside every certificate claim"
                        );
                        claimed += 1;
                    }
                    if t < case.horizon {
                        x = advance(&mut rng, &case.cl, t, &x);
                    }
                }
            }
        }
    }
    assert!(checked > 30_000, "only {checked} states were checked");
    assert!(
        claimed > 10_000,
        "only {claimed} states met certificate claims"
    );
    assert!(
        certified >= 5,
        "only {certified} VERIFIED results were certified"
    );
}

/// The certificate checker's own one-step bounds (what a certificate's
/// claims are derived from) contain every simulated trajectory on the
/// random loops (ReLU, tanh, sigmoid) with box initial sets: noise, limits, observation matrices, time-varying and
/// uncertain plants.
#[test]
fn trajectories_stay_inside_the_checkers_own_bounds() {
    use ravel_certify::bounds::{Bx, Chain, Loop, Start};
    let mut checked = 0usize;
    for seed in 0..90u64 {
        let case = random_case(seed);
        let Region::Box(x0) = &case.x0 else { continue };
        let (plants, w, v) = ravel::certificate_writer::loop_data(&case.cl);
        let pl = &case.cl.plant;
        let x0b = Bx {
            lo: x0.lo.clone(),
            hi: x0.hi.clone(),
        };
        // one-step chains and unrolled chains
        let mut chains = Vec::new();
        // (with the checker's own slope search: every candidate must be sound)
        for (unrolled, slopes) in [(false, 0), (true, 0), (false, 3), (true, 3)] {
            let mut links = Chain::new(Start::Box, unrolled);
            let mut chain = vec![x0b.clone()];
            for t in 0..case.horizon {
                let lp = Loop {
                    plant: &plants[t.min(plants.len() - 1)],
                    obs: &pl.obs,
                    w: &w,
                    v: &v,
                    net: &case.cl.net,
                    slopes,
                };
                let st = links
                    .step(lp, &chain[t], Start::Box, None, None)
                    .expect("finite bounds");
                chain.push(st.next);
            }
            chains.push(chain);
        }
        // the witness a one-step chain reports checks against itself
        let lp0 = Loop {
            plant: &plants[0],
            obs: &pl.obs,
            w: &w,
            v: &v,
            net: &case.cl.net,
            slopes: 0,
        };
        let (first, witness) = lp0.step(&x0b, &Start::Box, None).expect("finite");
        assert_eq!(
            lp0.step(&x0b, &Start::Box, Some(&witness)).map(|r| r.0),
            Ok(first)
        );
        let mut rng = Rng::new(seed * 7_919 + 3);
        for _ in 0..300 {
            let mut x = initial_point(&mut rng, &case.x0);
            for t in 0..=case.horizon {
                for chain in &chains {
                    let b = &chain[t];
                    assert!(
                        b.contains(&x),
                        "{}: step {t} state {x:?} outside the checker's box {b:?}",
                        case.label
                    );
                    checked += 1;
                }
                if t < case.horizon {
                    x = advance(&mut rng, &case.cl, t, &x);
                }
            }
        }
    }
    assert!(checked > 20_000, "only {checked} states were checked");
}

/// Whether `x` satisfies one claim of a certificate: inside its box and
/// below every claimed inequality.
fn claim_holds(claim: &serde_json::Value, x: &[f64]) -> bool {
    let num = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let set = &claim["set"];
    let in_box = x
        .iter()
        .enumerate()
        .all(|(i, v)| num(&set["lo"][i]) <= *v && *v <= num(&set["hi"][i]));
    let rows = claim["rows"].as_array().map_or(&[][..], Vec::as_slice);
    in_box
        && rows.iter().all(|r| {
            let a = r["a"].as_array().map_or(&[][..], Vec::as_slice);
            let dot: f64 = a.iter().zip(x).map(|(a, x)| num(a) * x).sum();
            dot <= num(&r["b"]) + 1e-12 * (1.0 + num(&r["b"]).abs())
        })
}

/// The rigorous replay that confirms counterexamples encloses the true
/// trajectory: on random loops (noise, limits, uncertain plants), the
/// interval enclosure from a start state with given noise values contains
/// every simulated state, and stays narrow.
#[test]
fn interval_replay_encloses_simulated_trajectories() {
    for seed in 0..60u64 {
        let case = random_case(seed);
        let mut rng = Rng::new(seed * 31 + 5);
        for _ in 0..20 {
            let mut x = initial_point(&mut rng, &case.x0);
            let mut enclosure = IBox::point(&x);
            for t in 0..case.horizon {
                let w = sample_point(&mut rng, &case.cl.plant.w);
                let v = sample_point(&mut rng, &case.cl.plant.v);
                let (u, next) = case.cl.simulate(t, &x, &w, &v);
                x = match &case.cl.plant_at(t).err {
                    Some(e) => perturbed(&mut rng, e, &x, &u, next),
                    None => next,
                };
                enclosure = case
                    .cl
                    .enclose_step(t, &enclosure, &w, &v)
                    .unwrap_or_else(|| panic!("{}: no enclosure at step {t}", case.label));
                assert!(
                    enclosure.contains_point(&x),
                    "{}: step {} state {x:?} outside {enclosure:?}",
                    case.label,
                    t + 1
                );
                if case.cl.plant_at(t).err.is_none() {
                    let width = enclosure
                        .lo
                        .iter()
                        .zip(&enclosure.hi)
                        .fold(0.0f64, |m, (l, h)| m.max(h - l));
                    assert!(width < 1e-6, "{}: enclosure width {width}", case.label);
                }
            }
        }
    }
}

/// Threads for the cells of a uniform partition, or for the two children
/// of each split of a guided one, change nothing: the same outcome, bound
/// for bound, for 1, 2 and 3 threads.
#[test]
fn cell_threads_give_the_same_outcome() {
    use ravel::execute::{execute_system, Control};
    for spec in [
        "specs/double_integrator_partitioned.ravel",
        "specs/double_integrator_noisy.ravel",
        "specs/double_integrator_polytope.ravel",
        // guided partitions: a split's two children on two threads
        "specs/double_integrator_gsg.ravel",
        "specs/double_integrator_sg.ravel",
        "specs/double_integrator_property_guided.ravel",
        "specs/quadrotor_gsg.ravel",
    ] {
        let source = std::fs::read_to_string(spec).expect("spec");
        let checked = ravel::front_end(
            &source,
            std::path::Path::new("specs"),
            &ravel_cli::read_request,
        )
        .expect("valid");
        let plan = ravel::lower::lower_system(&checked);
        let run = |threads: usize| {
            let out = execute_system(
                &plan,
                &Control {
                    elapsed: &|| 0.0,
                    time_limit: None,
                    progress: &|_| {},
                    threads,
                },
            );
            ravel::report::system::json(spec, &plan, &out, None)
        };
        let one = run(1);
        assert_eq!(one, run(2), "{spec}");
        assert_eq!(one, run(3), "{spec}");
    }
}

/// Each step of a one-sample simulation, redone with nalgebra's own
/// matrix-vector products (the order simulations have always used): the same
/// controls and states, bit for bit.
fn nalgebra_replays(plan: &ravel::lower::SystemPlan, tr: &ravel::execute::Trajectory, spec: &str) {
    let cl = plan.closed_loop.linear().expect("a linear plant");
    for t in 0..tr.controls.len() {
        let x = DVector::from_column_slice(&tr.states[t]);
        let mut h = cl.plant.obs.transpose() * &x + DVector::from_column_slice(&tr.sensor_noise[t]);
        for layer in &cl.net.layers {
            match layer {
                Layer::Affine { w, b } => h = w * h + b,
                Layer::Act(a) => h.apply(|z| *z = a.eval(*z)),
            }
        }
        let pl = cl.plant_at(t);
        let next =
            &pl.a * &x + &pl.b * &h + &pl.c + DVector::from_column_slice(&tr.process_noise[t]);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(
            bits(h.as_slice()),
            bits(&tr.controls[t]),
            "{spec}: control at step {t}"
        );
        assert_eq!(
            bits(next.as_slice()),
            bits(&tr.states[t + 1]),
            "{spec}: state at step {t}"
        );
    }
}

/// The Monte Carlo pass simulates 64 samples side by side; every state must
/// be bit for bit the one-sample simulation's (which replays
/// counterexamples), and that one nalgebra's, on every shipped spec: noise,
/// observation matrices, time-varying and continuous-time plants, tanh
/// controllers, ball and polytope initial sets (rejection sampling).
#[test]
fn batched_simulation_matches_the_scalar_one_bit_for_bit() {
    let mut specs: Vec<_> = std::fs::read_dir("specs")
        .expect("specs")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "ravel"))
        .collect();
    specs.sort();
    assert!(specs.len() >= 25);
    let mut compared = 0usize;
    for path in specs {
        let source = std::fs::read_to_string(&path).expect("spec");
        let checked = ravel::front_end(
            &source,
            path.parent().expect("dir"),
            &ravel_cli::read_request,
        )
        .expect("valid");
        let plan = ravel::lower::lower_system(&checked);
        let special = plan.initial.special_points();
        // a range that starts inside the special points and runs past them
        let ks = 1..(special.len() + 70).min(200);
        let batch = ravel::execute::simulate_states(&plan, ks.clone(), &special);
        for (k, got) in ks.zip(batch) {
            let want = ravel::execute::simulate(&plan, k);
            // (nalgebra's products replay linear plants; a nonlinear one's
            // batch is its scalar simulation, compared below)
            if let (Some(tr), Some(_)) = (&want, plan.closed_loop.linear()) {
                nalgebra_replays(&plan, tr, &path.display().to_string());
            }
            match (want, got) {
                (None, None) => {}
                (Some(tr), Some(flat)) => {
                    let want: Vec<u64> = tr.states.iter().flatten().map(|v| v.to_bits()).collect();
                    let got: Vec<u64> = flat.iter().map(|v| v.to_bits()).collect();
                    assert_eq!(want, got, "{}: sample {k}", path.display());
                    compared += got.len();
                }
                (w, g) => panic!(
                    "{}: sample {k}: {} vs {}",
                    path.display(),
                    w.is_some(),
                    g.is_some()
                ),
            }
        }
    }
    assert!(compared > 10_000, "{compared}");
}

/// Optimised slopes (`optimise_slopes`): Reach-LP and unrolled CROWN with
/// 4 projected-gradient steps per back-substitution keep every simulated
/// trajectory inside (their own bounds and the intersected ones, whole and
/// partitioned X0); one step from the same box is never looser than with
/// CROWN's own slopes, and on some ReLU loops strictly tighter.
#[test]
fn optimised_slopes_keep_every_trajectory_inside() {
    let mut checked = 0usize;
    let mut tighter = 0usize;
    for seed in 0..45u64 {
        let case = random_case(seed);
        let cl = case.cl.clone().with_slope_steps(4);
        let n = case.x0.dim();
        let cells = case.x0.grid(&vec![2; n]);
        let mut boundaries = vec![Boundary::Box];
        if n == 2 {
            boundaries.push(Boundary::spread(6));
        }
        if let Region::Box(_) = case.x0 {
            let plain = case
                .cl
                .step_alone(0, &case.x0, Propagator::ReachLp, &Boundary::Box);
            let slopes = cl.step_alone(0, &case.x0, Propagator::ReachLp, &Boundary::Box);
            let (p, s) = (plain.set.bbox(), slopes.set.bbox());
            for i in 0..n {
                let tol = |v: f64| 1e-12 * (1.0 + v.abs());
                assert!(
                    s.hi[i] <= p.hi[i] + tol(p.hi[i]) && s.lo[i] >= p.lo[i] - tol(p.lo[i]),
                    "{}: optimised slopes looser in x[{i}]: {s:?} vs {p:?}",
                    case.label
                );
                if s.hi[i] < p.hi[i] - 1e-9 || s.lo[i] > p.lo[i] + 1e-9 {
                    tighter += 1;
                }
            }
        }
        for boundary in &boundaries {
            for prop in [Propagator::ReachLp, Propagator::CrownUnrolled] {
                let whole = reach(&cl, &case.x0, case.horizon, prop, boundary, false);
                let own = reach(&cl, &case.x0, case.horizon, prop, boundary, true);
                let parts: Vec<Vec<Region>> = cells
                    .iter()
                    .map(|c| reach(&cl, c, case.horizon, prop, boundary, false))
                    .collect();
                let mut rng = Rng::new(seed * 7919 + 3);
                for _ in 0..60 {
                    let mut x = initial_point(&mut rng, &case.x0);
                    let cell = cells
                        .iter()
                        .position(|c| c.bbox().contains_point(&x))
                        .expect("the grid covers X0");
                    for t in 0..=case.horizon {
                        for (sets, what) in
                            [(&whole, "whole"), (&own, "own"), (&parts[cell], "cell")]
                        {
                            assert!(
                                inside(&sets[t], &x),
                                "{} {prop:?} {boundary:?} {what} with optimised slopes: step {t} state {x:?} outside {:?}",
                                case.label,
                                sets[t]
                            );
                        }
                        checked += 1;
                        if t < case.horizon {
                            x = advance(&mut rng, &cl, t, &x);
                        }
                    }
                }
            }
        }
    }
    assert!(checked > 20_000, "only {checked} states were checked");
    assert!(tighter > 0, "optimised slopes never tightened a step");
}

/// The optimised linear functions themselves (not only their bound over the
/// box) hold at every sampled input, and their bound over the box is never
/// above CROWN's own.
#[test]
fn optimised_linear_bounds_hold_pointwise() {
    let mut tighter = 0;
    for seed in 0..30u64 {
        let mut rng = Rng::new(7000 + seed);
        let net = random_network(&mut rng, 2, 2, Activation::Relu, (3, 7));
        let input = IBox::new(vec![-0.7, -0.2], vec![0.4, 0.9]);
        let a = Relaxation::new(&net, &input, Mode::Crown);
        let spec = DMatrix::from_row_slice(2, 2, &[1.0, -0.5, -1.0, 0.25]);
        let plain = a.upper(spec.clone()).concretize(&input);
        let bound = a.upper_optimised(spec.clone(), 8, None);
        for (r, (o, p)) in bound.concretize(&input).iter().zip(&plain).enumerate() {
            assert!(
                *o <= *p,
                "seed {seed} row {r}: optimised {o} above CROWN's {p}"
            );
            tighter += usize::from(*o < *p - 1e-9);
        }
        for _ in 0..500 {
            let x = sample_point(&mut rng, &input);
            let y = DVector::from_vec(net.forward(&x));
            let s = &spec * y;
            for r in 0..2 {
                let lin: f64 =
                    (0..2).map(|i| bound.coef.get(r, i) * x[i]).sum::<f64>() + bound.offset[r];
                assert!(s[r] <= lin + 1e-12, "seed {seed} row {r}: {} > {lin}", s[r]);
            }
        }
    }
    assert!(
        tighter > 5,
        "optimised slopes tightened only {tighter} rows"
    );
}
