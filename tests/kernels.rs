//! The fast bound kernels against a plain reference, bound for bound.
//!
//! `reference` below is back-substitution written the obvious way: nalgebra
//! matrices, one `sum_upper` per offset, rows copied out, every product from
//! nalgebra. The analysis's kernels (row-major rows, two buffers, interleaved
//! sums, the blocked product for wide layers, the exact path for the ±I
//! layers of control limits, no back-substitution for ReLUs that interval
//! arithmetic proves inactive, nor for a layer whose rows each read one
//! neuron of an activation, as a clamp's second half does; the neurons a
//! ReLU's bounds prove inactive left out of every product, also when the
//! network starts or ends with a ReLU) must give the
//! same bounds up to
//! rounding-error terms, on random ReLU, tanh and sigmoid networks from 2 to
//! 96 neurons wide (both product paths), and every sampled output must lie
//! inside both.

use nalgebra::{DMatrix, DVector};
use ravel_analysis::crown::{plus_minus_identity, Mode, Relaxation, Rows};
use ravel_analysis::relax::{image, relax, Relax};
use ravel_analysis::sets::IBox;
use ravel_base::nn::{Activation, Layer, Network};
use ravel_base::num::{dot_box_lower, dot_box_upper, gamma, slack, sum_lower, sum_upper, U};
use ravel_base::rng::Rng;

mod reference {
    use super::*;

    /// A linear upper bound `S f ≤ Λ z + c` in nalgebra's layout.
    pub struct Bound {
        pub coef: DMatrix<f64>,
        pub offset: Vec<f64>,
    }

    fn scale(w: &DMatrix<f64>, m: &[f64]) -> Vec<f64> {
        (0..w.nrows())
            .map(|j| sum_upper((0..w.ncols()).map(|i| w[(j, i)].abs() * m[i])))
            .collect()
    }

    fn image_affine(w: &DMatrix<f64>, b: &DVector<f64>, x: &IBox) -> IBox {
        let (mut lo, mut hi) = (Vec::new(), Vec::new());
        for j in 0..w.nrows() {
            let row: Vec<f64> = w.row(j).iter().copied().collect();
            lo.push(sum_lower([dot_box_lower(&row, &x.lo, &x.hi), b[j]]));
            hi.push(sum_upper([dot_box_upper(&row, &x.lo, &x.hi), b[j]]));
        }
        IBox::new(lo, hi)
    }

    fn affine(bound: &Bound, w: &DMatrix<f64>, b: &DVector<f64>, abs_in: &[f64]) -> Bound {
        let wz = scale(w, abs_in);
        let k = gamma(w.nrows() + 2);
        let offset = (0..bound.coef.nrows())
            .map(|r| {
                let row: Vec<f64> = bound.coef.row(r).iter().copied().collect();
                let err = slack(k, &row, &wz);
                sum_upper(
                    row.iter()
                        .zip(b.iter())
                        .map(|(l, b)| l * b)
                        .chain([bound.offset[r], err]),
                )
            })
            .collect();
        Bound {
            coef: &bound.coef * w,
            offset,
        }
    }

    fn activation(bound: &Bound, rel: &[Relax], abs_in: &[f64]) -> Bound {
        let mut coef = bound.coef.clone();
        let mut offset = Vec::new();
        for r in 0..coef.nrows() {
            let mut terms = vec![bound.offset[r]];
            for (j, rl) in rel.iter().enumerate() {
                let l = bound.coef[(r, j)];
                let (a, b) = if l >= 0.0 {
                    (rl.au, rl.bu)
                } else {
                    (rl.al, rl.bl)
                };
                coef[(r, j)] = l * a;
                terms.push(l * b);
            }
            let row: Vec<f64> = coef.row(r).iter().copied().collect();
            terms.push(slack(2.0 * U, &row, abs_in));
            offset.push(sum_upper(terms));
        }
        Bound { coef, offset }
    }

    /// Boxes before every layer, CROWN for every pre-activation.
    pub struct Reference {
        pub boxes: Vec<IBox>,
        rel: Vec<Vec<Relax>>,
    }

    impl Reference {
        pub fn new(net: &Network, input: &IBox) -> Reference {
            let mut a = Reference {
                boxes: vec![input.clone()],
                rel: Vec::new(),
            };
            for (i, layer) in net.layers.iter().enumerate() {
                let cur = a.boxes[i].clone();
                match layer {
                    Layer::Affine { w, b } => {
                        let mut next = image_affine(w, b, &cur);
                        if matches!(net.layers.get(i + 1), Some(Layer::Act(_))) {
                            let n = w.nrows();
                            let spec = plus_minus_identity(n).to_dmatrix();
                            let both = a.concretize(&a.backward(net, spec, i + 1), input);
                            for j in 0..n {
                                next.hi[j] = next.hi[j].min(both[j]);
                                next.lo[j] = next.lo[j].max(-both[n + j]);
                            }
                        }
                        a.rel.push(Vec::new());
                        a.boxes.push(next);
                    }
                    Layer::Act(act) => {
                        let rel = (0..cur.dim())
                            .map(|j| relax(*act, cur.lo[j], cur.hi[j]))
                            .collect();
                        let (lo, hi) = (0..cur.dim())
                            .map(|j| image(*act, cur.lo[j], cur.hi[j]))
                            .unzip();
                        a.rel.push(rel);
                        a.boxes.push(IBox::new(lo, hi));
                    }
                }
            }
            a
        }

        pub fn backward(&self, net: &Network, spec: DMatrix<f64>, end: usize) -> Bound {
            let mut bound = Bound {
                offset: vec![0.0; spec.nrows()],
                coef: spec,
            };
            for i in (0..end).rev() {
                let abs = self.boxes[i].abs_max();
                bound = match &net.layers[i] {
                    Layer::Affine { w, b } => affine(&bound, w, b, &abs),
                    Layer::Act(_) => activation(&bound, &self.rel[i], &abs),
                };
            }
            bound
        }

        pub fn concretize(&self, bound: &Bound, b: &IBox) -> Vec<f64> {
            (0..bound.coef.nrows())
                .map(|r| {
                    let row: Vec<f64> = bound.coef.row(r).iter().copied().collect();
                    sum_upper([dot_box_upper(&row, &b.lo, &b.hi), bound.offset[r]])
                })
                .collect()
        }
    }
}

fn random_network(rng: &mut Rng, widths: &[usize], act: Activation) -> Network {
    let mut layers = Vec::new();
    for (k, pair) in widths.windows(2).enumerate() {
        let (n_in, n_out) = (pair[0], pair[1]);
        let s = 1.5 / (n_in as f64).sqrt();
        layers.push(Layer::Affine {
            w: DMatrix::from_fn(n_out, n_in, |_, _| rng.uniform(-s, s)),
            b: DVector::from_fn(n_out, |_, _| rng.uniform(-0.3, 0.3)),
        });
        if k + 2 < widths.len() {
            layers.push(Layer::Act(act));
        }
    }
    Network::new(widths[0], layers)
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * (1.0 + a.abs().max(b.abs()))
}

#[test]
fn fast_kernels_match_the_reference_bound_for_bound() {
    let mut rng = Rng::new(0xC0FFEE);
    let shapes: [&[usize]; 6] = [
        &[2, 5, 5, 1],
        &[3, 8, 2],
        &[6, 32, 32, 3],
        &[4, 96, 3],
        &[5, 64, 48, 16, 4],
        &[1, 1, 1],
    ];
    let mut compared = 0;
    let mut left_out = 0;
    for (case, widths) in shapes.iter().cycle().take(36).enumerate() {
        let act = [Activation::Relu, Activation::Tanh, Activation::Sigmoid][case % 3];
        let mut net = random_network(&mut rng, widths, act);
        if case % 4 == 1 {
            // control limits: clamp layers with W = ±I (the exact-product path)
            let m = net.outputs();
            net = net.with_saturation(&vec![-0.3; m], &vec![0.4; m]);
        }
        if case % 5 == 3 {
            // a ReLU first and last: back-substitution starts from a ReLU's
            // output and ends on one, both with neurons left out
            let mut layers = vec![Layer::Act(Activation::Relu)];
            layers.extend(net.layers.iter().cloned());
            layers.push(Layer::Act(Activation::Relu));
            net = Network::new(widths[0], layers);
        }
        let n = widths[0];
        let centre: Vec<f64> = (0..n).map(|_| rng.uniform(-1.0, 1.0)).collect();
        let radius = rng.uniform(0.01, 0.8);
        let input = IBox::new(
            centre.iter().map(|c| c - radius).collect(),
            centre.iter().map(|c| c + radius).collect(),
        );
        let fast = Relaxation::new(&net, &input, Mode::Crown);
        let slow = reference::Reference::new(&net, &input);
        for (i, (f, s)) in fast.boxes().iter().zip(&slow.boxes).enumerate() {
            // the value before layer i; a ReLU's input that interval
            // arithmetic proves inactive is not back-substituted (it outputs
            // 0 whatever its bounds): only its sign must agree
            let before_relu = matches!(net.layers.get(i), Some(Layer::Act(Activation::Relu)));
            for j in 0..f.dim() {
                if before_relu && f.hi[j] <= 0.0 {
                    assert!(s.hi[j] <= 0.0, "case {case}: layer {i} neuron {j}");
                    // proved inactive: back-substitution leaves it out
                    left_out += 1;
                    continue;
                }
                assert!(
                    close(f.lo[j], s.lo[j]) && close(f.hi[j], s.hi[j]),
                    "case {case}: {f:?} vs {s:?}"
                );
                compared += 2;
            }
        }
        let m = net.outputs();
        let spec = DMatrix::from_fn(m + 2, m, |_, _| rng.uniform(-1.0, 1.0));
        let fast_ub = fast.upper(Rows::from(&spec)).concretize(&input);
        let slow_ub = slow.concretize(&slow.backward(&net, spec.clone(), net.layers.len()), &input);
        for (f, s) in fast_ub.iter().zip(&slow_ub) {
            assert!(close(*f, *s), "case {case}: {f} vs {s}");
            compared += 1;
        }
        // and both hold on sampled inputs
        for _ in 0..200 {
            let x: Vec<f64> = (0..n)
                .map(|i| rng.uniform(input.lo[i], input.hi[i]))
                .collect();
            let y = DVector::from_vec(net.forward(&x));
            let sy = &spec * y;
            for r in 0..sy.len() {
                assert!(
                    sy[r] <= fast_ub[r] && sy[r] <= slow_ub[r],
                    "case {case}: sample above a bound"
                );
            }
        }
    }
    assert!(compared > 1000);

    assert!(
        left_out > 50,
        "only {left_out} inactive neurons: the left-out path is barely tested"
    );
}

/// One back-substitution of the stacked rows `[I; −I; S]` gives the bounds
/// of `S` and the CROWN output box that two separate passes give: bit for
/// bit while the products are per-row dot products (narrow layers), and
/// equal up to rounding where the blocked product takes over (its summation
/// order depends on the number of rows; every bound is sound either way).
/// Rows of `S` with at most one nonzero are scaled from the `[I; −I]` rows
/// instead: equal to the direct pass up to rounding, and above every
/// sampled output.
#[test]
fn stacked_rows_give_the_separate_passes() {
    let mut rng = Rng::new(77);
    let mut scaled = 0;
    for case in 0..24 {
        let act = [Activation::Relu, Activation::Tanh, Activation::Sigmoid][case % 3];
        let width = [3, 8, 40, 96][case % 4];
        let outs = 1 + case % 3;
        let net = random_network(&mut rng, &[2, width, width, outs], act);
        let input = IBox::new(vec![-0.6, -0.1], vec![0.3, 0.8]);
        let a = Relaxation::new(&net, &input, Mode::Crown);
        // dense rows, rows with one nonzero (either sign), a zero row
        let mut data: Vec<f64> = (0..4 * outs).map(|_| rng.normal()).collect();
        let one = case % outs;
        for (r, v) in data.chunks_exact_mut(outs).enumerate() {
            if r == 1 || r == 2 {
                v.iter_mut().enumerate().for_each(|(j, x)| {
                    if j != one {
                        *x = 0.0
                    }
                });
            }
            if r == 3 && case % 2 == 0 {
                v.iter_mut().for_each(|x| *x = 0.0);
            }
        }
        let spec = Rows::from_row_major(4, outs, data);
        let (both, u) = a.upper_and_output_box(spec.clone(), 0, None);
        let apart = a.upper(spec.clone());
        let ob = a.output_box(Mode::Crown);
        let same = |x: &[f64], y: &[f64]| {
            x.len() == y.len()
                && x.iter().zip(y).all(|(p, q)| {
                    if width < 40 {
                        p.to_bits() == q.to_bits()
                    } else {
                        close(*p, *q)
                    }
                })
        };
        let ub_both = both.concretize(&input);
        let ub_apart = apart.concretize(&input);
        for r in 0..4 {
            let nonzeros = spec.row(r).iter().filter(|v| **v != 0.0).count();
            if nonzeros <= 1 {
                scaled += 1;
                assert!(
                    close(ub_both[r], ub_apart[r]),
                    "case {case}: row {r} scaled"
                );
                for (p, q) in both.coef.row(r).iter().zip(apart.coef.row(r)) {
                    assert!(close(*p, *q), "case {case}: row {r} scaled coefficients");
                }
                for _ in 0..200 {
                    let y = [rng.uniform(-0.6, 0.3), rng.uniform(-0.1, 0.8)];
                    let f = net.forward(&y);
                    let v: f64 = spec.row(r).iter().zip(&f).map(|(s, f)| s * f).sum();
                    assert!(
                        v <= ub_both[r],
                        "case {case}: row {r}: sample above the bound"
                    );
                }
            } else {
                assert!(
                    same(&[both.offset[r]], &[apart.offset[r]]),
                    "case {case}: offset {r}"
                );
                assert!(
                    same(both.coef.row(r), apart.coef.row(r)),
                    "case {case}: row {r}"
                );
            }
        }
        assert!(
            same(&u.lo, &ob.lo) && same(&u.hi, &ob.hi),
            "case {case}: box"
        );
    }
    assert!(scaled > 40, "only {scaled} scaled rows");
}

mod common;

/// The closed-loop kernel (a box of states under CROWN's own slopes: no
/// allocation per step) against the general path of `ClosedLoop::step`,
/// bound for bound, on random loops: 1–3 states, 1–2 controls, ReLU, tanh
/// and sigmoid controllers with and without control limits, observed or
/// full-state, with and without noise, model error and time variation,
/// box and polytope boundaries; Reach-LP with and without CL-CROWN's
/// intersection, and CL-CROWN. Every true next state of sampled states and
/// noise lies in the kernel's set.
#[test]
fn closed_loop_kernel_matches_the_general_path() {
    let (mut compared, mut worst) = (0usize, 0.0f64);
    for seed in 0..150u64 {
        let (c, w) = kernel_case(seed);
        compared += c;
        worst = worst.max(w);
    }
    assert!(compared > 1000, "{compared} steps compared");
    assert!(worst <= 1e-9, "largest relative difference {worst:e}");
}

/// [`closed_loop_kernel_matches_the_general_path`] on more loops
/// (`RAVEL_KERNEL_CASES`, default 5000): `cargo test --release --test
/// kernels -- --ignored closed_loop_kernel_campaign --nocapture`.
#[test]
#[ignore = "opt-in campaign"]
fn closed_loop_kernel_campaign() {
    let cases: u64 = std::env::var("RAVEL_KERNEL_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(5000);
    let (mut compared, mut worst) = (0usize, 0.0f64);
    for seed in 0..cases {
        let (c, w) = kernel_case(1_000_000 + seed);
        compared += c;
        worst = worst.max(w);
    }
    println!("{cases} loops, {compared} steps compared, largest relative difference {worst:e}");
}

/// One random loop of [`closed_loop_kernel_matches_the_general_path`]:
/// the steps compared and the largest relative difference between the
/// kernel's bounds and the general path's (each within 10⁻⁹, asserted,
/// with sampled true next states inside the kernel's set).
fn kernel_case(seed: u64) -> (usize, f64) {
    use ravel_analysis::closed_loop::{Boundary, ClosedLoop, ModelError, Plant, Propagator};
    use ravel_analysis::sets::Region;
    let mut worst = 0.0f64;
    let mut close = |a: f64, b: f64| {
        let d = (a - b).abs() / (1.0 + a.abs().max(b.abs()));
        worst = worst.max(d);
        d <= 1e-9
    };
    let mut compared = 0usize;
    {
        let mut rng = Rng::new(seed.wrapping_mul(0x9E37_79B9) ^ 0xC105);
        let n = 1 + rng.below(3);
        let m = 1 + rng.below(2);
        let act = [Activation::Relu, Activation::Tanh, Activation::Sigmoid][seed as usize % 3];
        let observed = seed % 4 == 1;
        let p = if observed { 1 + rng.below(n + 1) } else { n };
        let a = DMatrix::from_fn(n, n, |i, j| {
            if i == j {
                0.9
            } else {
                0.0
            }
        } + rng.normal() * 0.25);
        let mut b = DMatrix::from_fn(n, m, |_, _| rng.normal() * 0.5);
        if seed % 5 == 3 {
            // dense control rows of the facets: back-substituted, not scaled
            b = b.map(|v| v + 0.3);
        }
        let c = DVector::from_fn(n, |_, _| rng.normal() * 0.1);
        let obs = if observed {
            DMatrix::from_fn(n, p, |_, _| rng.normal())
        } else {
            DMatrix::identity(n, n)
        };
        let noisy = seed % 2 == 1;
        let mut noise = |k: usize| {
            let r = if noisy { 0.05 } else { 0.0 };
            let lo: Vec<f64> = (0..k).map(|_| -rng.uniform(0.0, r)).collect();
            let hi: Vec<f64> = (0..k).map(|_| rng.uniform(0.0, r)).collect();
            IBox::new(lo, hi)
        };
        let (w, v) = (noise(n), noise(p));
        let err = (seed % 6 == 1).then(|| ModelError {
            a: a.map(|x| x.abs() * 0.05 + 0.01),
            b: b.map(|x| x.abs() * 0.05 + 0.01),
            c: c.map(|x| x.abs() * 0.05 + 0.01),
        });
        let plant = Plant {
            a,
            b,
            c,
            obs,
            w,
            v,
            err,
        };
        let plants = if seed % 7 == 2 {
            (0..3)
                .map(|_| {
                    let mut q = plant.clone();
                    q.a = q.a.map(|x| x + rng.normal() * 0.1);
                    q.b = q.b.map(|x| x + rng.normal() * 0.1);
                    q
                })
                .collect()
        } else {
            vec![plant]
        };
        let mut net = common::random_network(&mut rng, p, m, act, (3, 9));
        if (seed / 2) % 2 == 1 {
            let lo: Vec<f64> = (0..m).map(|_| -rng.uniform(0.2, 1.0)).collect();
            let hi: Vec<f64> = (0..m).map(|_| rng.uniform(0.2, 1.0)).collect();
            net = net.with_saturation(&lo, &hi);
        }
        let fast = ClosedLoop::time_varying(plants, net);
        let general = fast.clone().with_kernel(false);
        let centre: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
        let radius: Vec<f64> = (0..n).map(|_| rng.uniform(0.01, 0.5)).collect();
        let x = IBox::new(
            centre.iter().zip(&radius).map(|(c, r)| c - r).collect(),
            centre.iter().zip(&radius).map(|(c, r)| c + r).collect(),
        );
        let region = Region::Box(x.clone());
        let mut boundaries = vec![Boundary::Box];
        if n == 2 {
            boundaries.push(Boundary::spread(5));
        }
        for t in 0..3 {
            for boundary in &boundaries {
                for prop in [Propagator::ReachLp, Propagator::CrownSeparate] {
                    for alone in [false, true] {
                        let step = |cl: &ClosedLoop| {
                            if alone {
                                cl.step_alone(t, &region, prop, boundary)
                            } else {
                                cl.step(t, &region, prop, boundary)
                            }
                        };
                        let (k, g) = (step(&fast), step(&general));
                        assert_eq!(k.cut, g.cut, "seed {seed} t {t} {prop:?}");
                        let (kb, gb) = (k.set.bbox(), g.set.bbox());
                        for i in 0..n {
                            assert!(
                                close(kb.lo[i], gb.lo[i]) && close(kb.hi[i], gb.hi[i]),
                                "seed {seed} t {t} {prop:?} alone {alone}: x[{i}] kernel {kb:?} general {gb:?}"
                            );
                        }
                        if let (
                            Region::Polytope { rows: kr, .. },
                            Region::Polytope { rows: gr, .. },
                        ) = (&k.set, &g.set)
                        {
                            for (a, b) in kr.iter().zip(gr) {
                                assert!(close(a.1, b.1), "seed {seed} t {t}: facet {a:?} vs {b:?}");
                            }
                        }
                        compared += 1;
                        if prop == Propagator::ReachLp && !alone {
                            for _ in 0..50 {
                                let xs: Vec<f64> =
                                    (0..n).map(|i| rng.uniform(x.lo[i], x.hi[i])).collect();
                                let pl = fast.plant_at(t);
                                let ws: Vec<f64> = (0..n)
                                    .map(|i| rng.uniform(pl.w.lo[i], pl.w.hi[i]))
                                    .collect();
                                let vs: Vec<f64> = (0..p)
                                    .map(|j| rng.uniform(pl.v.lo[j], pl.v.hi[j]))
                                    .collect();
                                let (_, next) = fast.simulate(t, &xs, &ws, &vs);
                                assert!(
                                    k.set.contains_point(&next),
                                    "seed {seed} t {t}: {next:?} outside {:?}",
                                    k.set
                                );
                            }
                        }
                    }
                }
            }
        }
    }
    (compared, worst)
}

/// Hostile boxes take the kernel's overflow path as the general path's:
/// a state near the top of `f64` or a NaN gives the whole space, flagged.
#[test]
fn closed_loop_kernel_overflows_as_the_general_path_does() {
    use ravel_analysis::closed_loop::{Boundary, ClosedLoop, Plant, Propagator};
    use ravel_analysis::sets::Region;
    let mut rng = Rng::new(7);
    let net = common::random_network(&mut rng, 2, 1, Activation::Relu, (2, 5));
    let plant = Plant {
        a: DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 0.0, 1.0]),
        b: DMatrix::from_row_slice(2, 1, &[0.5, 1.0]),
        c: DVector::zeros(2),
        obs: DMatrix::identity(2, 2),
        w: IBox::new(vec![0.0; 2], vec![0.0; 2]),
        v: IBox::new(vec![0.0; 2], vec![0.0; 2]),
        err: None,
    };
    let fast = ClosedLoop::new(plant, net);
    let general = fast.clone().with_kernel(false);
    for (lo, hi) in [
        (vec![1e307, 0.0], vec![1.7e308, 1.0]),
        (vec![-1.7e308, -1.7e308], vec![1.7e308, 1.7e308]),
        (vec![f64::NAN, 0.0], vec![1.0, 1.0]),
        (vec![0.0, 0.0], vec![f64::INFINITY, 1.0]),
    ] {
        let x = Region::Box(IBox::new(lo, hi));
        for prop in [Propagator::ReachLp, Propagator::CrownSeparate] {
            let (k, g) = (
                fast.step(0, &x, prop, &Boundary::Box),
                general.step(0, &x, prop, &Boundary::Box),
            );
            assert!(k.cut.is_some(), "{x:?} {prop:?}: {k:?}");
            assert_eq!(k.cut, g.cut);
            assert_eq!(k.set, g.set);
        }
    }
}
