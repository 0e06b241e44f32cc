//! The nonlinear closed loop against simulation: every simulated state
//! inside its step's set, every intersample state inside the period's
//! piece for its time; and the linear double integrator run through the integrator
//! against its closed form.

use super::integrate;
use super::{NonlinearLoop, NonlinearPlant};
use crate::closed_loop::{Boundary, ClosedLoop, Cut, Plant, Propagator};
use crate::sets::{IBox, Region};
use nalgebra::{DMatrix, DVector};
use ravel_base::expr::{Func, Node, Tape, Time, VectorField};
use ravel_base::nn::{Activation, Layer, Network};
use ravel_base::rng::Rng;

/// A random `inputs → 8 tanh → 8 relu → 1` network, saturated to `[−1, 1]`.
fn controller(inputs: usize, seed: u64, gain: f64) -> Network {
    let mut rng = Rng::new(seed);
    let mut m = |r: usize, c: usize, s: f64| DMatrix::from_fn(r, c, |_, _| rng.uniform(-s, s));
    let layers = vec![
        Layer::Affine {
            w: m(8, inputs, 1.0),
            b: DVector::from_element(8, 0.05),
        },
        Layer::Act(Activation::Tanh),
        Layer::Affine {
            w: m(8, 8, 0.6),
            b: DVector::from_element(8, 0.1),
        },
        Layer::Act(Activation::Relu),
        Layer::Affine {
            w: m(1, 8, gain),
            b: DVector::from_element(1, 0.0),
        },
    ];
    Network::new(inputs, layers).with_saturation(&[-1.0], &[1.0])
}

/// `ẋ0 = x1`, `ẋ1 = u − sin(x0) − 0.2 x1 + w0` (a damped pendulum), or
/// the double integrator `ẋ0 = x1`, `ẋ1 = u`.
fn field(pendulum: bool, time: Time) -> VectorField {
    let mut t = Tape::new();
    let x0 = t.push(Node::Var(0));
    let x1 = t.push(Node::Var(1));
    let u = t.push(Node::Var(2));
    let out1 = if pendulum {
        let w = t.push(Node::Var(3));
        let s = t.push(Node::Func(Func::Sin, x0));
        let c = t.push(Node::Const(0.2));
        let d = t.push(Node::Mul(c, x1));
        let a = t.push(Node::Sub(u, s));
        let b = t.push(Node::Sub(a, d));
        t.push(Node::Add(b, w))
    } else {
        u
    };
    VectorField {
        tape: t,
        outputs: vec![x1, out1],
        states: 2,
        controls: 1,
        disturbances: usize::from(pendulum),
        time,
    }
}

fn pendulum_loop(time: Time) -> NonlinearLoop {
    NonlinearLoop::new(
        NonlinearPlant {
            field: field(true, time),
            w: IBox::new(vec![-0.02], vec![0.02]),
            obs: DMatrix::identity(2, 2),
            v: IBox::new(vec![-0.01, 0.0], vec![0.01, 0.0]),
        },
        controller(2, 7, 0.8),
    )
}

/// Sampled trajectories (corners of X0 and random points, extreme and
/// random noise) stay inside every step's set and every period's enclosure.
#[test]
fn simulated_trajectories_stay_inside_the_reachable_sets() {
    for (time, horizon) in [(Time::Continuous { period: 0.2 }, 8), (Time::Discrete, 6)] {
        let nl = pendulum_loop(time);
        let x0 = IBox::new(vec![0.4, -0.2], vec![0.6, 0.0]);
        let boundary = Boundary::Polytope(DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, -1.0]));
        let steps = nl.reach(&Region::Box(x0.clone()), horizon, &boundary, None, &|| {
            false
        });
        assert_eq!(steps.len(), horizon + 1);
        assert!(
            steps.iter().all(|s| s.cut().is_none()),
            "{time:?}: a step was cut"
        );
        let mut rng = Rng::new(3);
        for k in 0..300 {
            let mut x: Vec<f64> = (0..2)
                .map(|i| match k {
                    0..=3 => [x0.lo[i], x0.hi[i]][(k >> i) & 1],
                    _ => rng.uniform(x0.lo[i], x0.hi[i]),
                })
                .collect();
            for (t, step) in steps.iter().enumerate().skip(1) {
                let w = [if k % 2 == 0 {
                    0.02
                } else {
                    rng.uniform(-0.02, 0.02)
                }];
                let v = [rng.uniform(-0.01, 0.01), 0.0];
                let y = [x[0] + v[0], x[1]];
                let u = nl.net.forward(&y);
                if let Time::Continuous { period } = time {
                    let pieces = step.between.as_ref().expect("continuous time has pieces");
                    assert_eq!(pieces.len(), 8);
                    // 40 instants per period, each against the piece of its
                    // eighth (both pieces at their common end)
                    for j in 1..40usize {
                        let at = integrate::simulate(
                            &nl.plant.field,
                            &x,
                            &u,
                            &w,
                            period * j as f64 / 40.0,
                        );
                        // at an edge (j a multiple of 5), the two pieces it ends and starts
                        let first = (j - 1) / 5;
                        for (k, piece) in pieces.iter().enumerate().take(j / 5 + 1).skip(first) {
                            assert!(
                                piece.contains_point(&at),
                                "{time:?} step {t}: {at:?} at {j}/40 leaves piece {k} {piece:?}"
                            );
                        }
                    }
                }
                let (_, next) = nl.simulate_batch(&x, &w, &v, 1);
                x = next;
                assert!(
                    step.set.contains_point(&x),
                    "{time:?} step {t}: {x:?} leaves {:?}",
                    step.set
                );
            }
        }
    }
}

/// The continuous double integrator with dt = 1 is the discrete plant
/// `A = [[1, 1], [0, 1]]`, `B = [0.5, 1]`: through the integrator, its sets
/// hold every sample and are not much wider than the closed form's.
#[test]
fn the_double_integrator_through_the_integrator_is_close_to_its_closed_form() {
    let net = controller(2, 11, 0.5);
    let nl = NonlinearLoop::new(
        NonlinearPlant {
            field: field(false, Time::Continuous { period: 1.0 }),
            w: IBox::new(vec![], vec![]),
            obs: DMatrix::identity(2, 2),
            v: IBox::new(vec![0.0, 0.0], vec![0.0, 0.0]),
        },
        net.clone(),
    );
    let plant = Plant {
        a: DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 0.0, 1.0]),
        b: DMatrix::from_row_slice(2, 1, &[0.5, 1.0]),
        c: DVector::zeros(2),
        obs: DMatrix::identity(2, 2),
        w: IBox::new(vec![0.0, 0.0], vec![0.0, 0.0]),
        v: IBox::new(vec![0.0, 0.0], vec![0.0, 0.0]),
        err: None,
    };
    let cl = ClosedLoop::new(plant, net);
    let x0 = Region::Box(IBox::new(vec![2.5, -0.25], vec![3.0, 0.25]));
    let ours = nl.reach(&x0, 5, &Boundary::Box, None, &|| false);
    let mut theirs = x0.clone();
    for (t, step) in ours.iter().enumerate().skip(1) {
        theirs = cl
            .step(t - 1, &theirs, Propagator::ReachLp, &Boundary::Box)
            .set;
        let (a, b) = (step.set.bbox(), theirs.bbox());
        for i in 0..2 {
            let (wa, wb) = (a.hi[i] - a.lo[i], b.hi[i] - b.lo[i]);
            assert!(
                wa <= 1.5 * wb + 1e-9,
                "step {t}, x[{i}]: width {wa} against the closed form's {wb}"
            );
        }
    }
}

/// A plant `ẋ0 = first, ẋ1 = second` over `[x0, x1, u]`.
fn plant_with(
    first: impl Fn(&mut Tape, u32, u32, u32) -> u32,
    second: impl Fn(&mut Tape, u32, u32, u32) -> u32,
) -> NonlinearLoop {
    let mut t = Tape::new();
    let x0 = t.push(Node::Var(0));
    let x1 = t.push(Node::Var(1));
    let u = t.push(Node::Var(2));
    let out0 = first(&mut t, x0, x1, u);
    let out1 = second(&mut t, x0, x1, u);
    NonlinearLoop::new(
        NonlinearPlant {
            field: VectorField {
                tape: t,
                outputs: vec![out0, out1],
                states: 2,
                controls: 1,
                disturbances: 0,
                time: Time::Continuous { period: 1.0 },
            },
            w: IBox::new(vec![], vec![]),
            obs: DMatrix::identity(2, 2),
            v: IBox::new(vec![0.0, 0.0], vec![0.0, 0.0]),
        },
        controller(2, 5, 0.5),
    )
}

/// A flow that blows up within the period (`ẋ0 = x0²` from `x0 ≥ 1`
/// escapes before t = 1) and a right-hand side that becomes undefined
/// (`ẋ0 = −1`, `ẋ1 = 10⁻⁶ / x0`: `x0` reaches 0 in the first period) cut
/// the cell: that step and every later one are the whole space, never a
/// bound.
#[test]
fn blow_up_and_undefined_plants_cut_the_cell() {
    let x0 = Region::Box(IBox::new(vec![1.0, -0.1], vec![1.1, 0.1]));
    let blow = plant_with(|t, x0, _, _| t.push(Node::Powi(x0, 2)), |_, _, _, u| u);
    let steps = blow.reach(&x0, 3, &Boundary::Box, None, &|| false);
    assert!(steps
        .iter()
        .skip(1)
        .all(|s| s.cut().is_some() && !s.set.is_finite()));

    let x0 = Region::Box(IBox::new(vec![0.5, -0.1], vec![0.6, 0.1]));
    let undefined = plant_with(
        |t, _, _, _| t.push(Node::Const(-1.0)),
        |t, x0, _, _| {
            let r = t.push(Node::Powi(x0, -1));
            let c = t.push(Node::Const(1e-6));
            t.push(Node::Mul(c, r))
        },
    );
    let steps = undefined.reach(&x0, 3, &Boundary::Box, None, &|| false);
    assert!(steps
        .iter()
        .skip(1)
        .all(|s| s.cut().is_some() && !s.set.is_finite()));
    assert!(
        matches!(steps[1].cut(), Some(Cut::Undefined | Cut::NoEnclosure)),
        "{:?}",
        steps[1].cut()
    );
}

/// The controls' models hold the network's output at every point of a
/// thin, tilted observation set with remainders (`y = c + G z + ρ`, three
/// symbols over two observations, so the set is much smaller than its
/// box): at every corner of `(z, ρ)` and at random points,
/// `net(y) ∈ m + M z + E`. The last networks are one unstable ReLU, where
/// CROWN's upper bound is met at a corner, so the check is tight: leaving
/// out the part of the middle on `ρ`, bounding over a box of `z` a tenth
/// too small, or making `E` a tenth narrower, each makes this fail.
#[test]
fn the_controls_hold_the_network_over_the_observation_set() {
    use integrate::{Interval, Tm};
    let relu = |w: [f64; 2]| {
        Network::new(
            2,
            vec![
                Layer::Affine {
                    w: DMatrix::from_row_slice(1, 2, &w),
                    b: DVector::from_element(1, 0.1),
                },
                Layer::Act(Activation::Relu),
            ],
        )
    };
    let nets = (0..6u64).map(|seed| controller(2, 11 + seed, 2.0)).chain([
        relu([1.0, 0.5]),
        relu([-0.7, 1.3]),
        relu([0.4, -1.1]),
    ]);
    for (seed, net) in (0u64..).zip(nets) {
        let nl = NonlinearLoop::new(
            NonlinearPlant {
                field: field(false, Time::Discrete),
                w: IBox::new(vec![], vec![]),
                obs: DMatrix::identity(2, 2),
                v: IBox::new(vec![0.0, 0.0], vec![0.0, 0.0]),
            },
            net,
        );
        let mut rng = Rng::new(seed);
        let y: Vec<Tm> = (0..2)
            .map(|j| Tm {
                c: rng.uniform(-0.3, 0.3),
                g: vec![
                    0.8 * if j == 0 { 1.0 } else { -1.0 },
                    rng.uniform(-0.3, 0.3),
                    0.02,
                ],
                r: Interval::new(-0.15, 0.05 + 0.1 * j as f64),
            })
            .collect();
        let u = nl.control(&y, 3).expect("the controls are bounded");
        let u0 = &u[0];
        let mut worst = f64::INFINITY;
        for k in 0..4000 {
            // the first 32: every corner of (z, ρ)
            let z: Vec<f64> = (0..3)
                .map(|i| match k {
                    0..=31 => [-1.0, 1.0][(k >> i) & 1],
                    _ => rng.uniform(-1.0, 1.0),
                })
                .collect();
            let rho: Vec<f64> = y
                .iter()
                .enumerate()
                .map(|(j, t)| match k {
                    0..=31 => [t.r.lo, t.r.hi][(k >> (3 + j)) & 1],
                    _ => rng.uniform(t.r.lo, t.r.hi),
                })
                .collect();
            let yv: Vec<f64> = y
                .iter()
                .zip(&rho)
                .map(|(t, r)| t.c + t.g.iter().zip(&z).map(|(g, zi)| g * zi).sum::<f64>() + r)
                .collect();
            let out = nl.net.forward(&yv)[0];
            let lin = u0.c + u0.g.iter().zip(&z).map(|(g, zi)| g * zi).sum::<f64>();
            let slack = (out - lin - u0.r.lo).min(u0.r.hi - (out - lin));
            assert!(
                slack >= -1e-12,
                "network {seed}: {out} at z = {z:?}, ρ = {rho:?} leaves {lin} + {:?}",
                u0.r
            );
            worst = worst.min(slack);
        }
        assert!(worst.is_finite());
    }
}

/// The split weights point at the inputs the controller's slack depends
/// on: a controller that sees only `x0` gets nothing from splitting `x1`,
/// and a split of `x0` removes a real share of its slack.
#[test]
fn split_weights_point_at_the_controllers_inputs() {
    let nl = NonlinearLoop::new(
        NonlinearPlant {
            field: field(false, Time::Continuous { period: 0.1 }),
            w: IBox::new(vec![], vec![]),
            obs: DMatrix::from_column_slice(2, 1, &[1.0, 0.0]),
            v: IBox::new(vec![0.0], vec![0.0]),
        },
        controller(1, 7, 0.8),
    );
    let cell = IBox::new(vec![-1.0, -1.0], vec![1.0, 1.0]);
    let w = nl.split_weights(&cell).unwrap();
    assert_eq!(w.len(), 2);
    assert!(w[0] > 0.1 && w[0] <= 1.0, "{w:?}");
    assert_eq!(w[1], 0.0, "{w:?}");
    // a flat dimension is never a split
    let flat = IBox::new(vec![-1.0, 0.5], vec![1.0, 0.5]);
    assert_eq!(nl.split_weights(&flat).unwrap()[1], 0.0);
    // over a tiny cell the bounds are tight (their slack a tiny share of
    // the controls' range), so the weights leave the choice to the width,
    // however much of that slack a split would remove
    let tiny = IBox::new(vec![-1e-4, -1e-4], vec![1e-4, 1e-4]);
    let w = nl.split_weights(&tiny).unwrap();
    assert!(w[0] < 0.01, "{w:?}");
}
