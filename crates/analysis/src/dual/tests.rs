//! Tests of the Lagrangian bounds: soundness against sampled inputs of
//! split domains, no looser than CROWN, tightened by the ascent, exact
//! once every neuron is split, batched as apart, no bound from non-finite
//! multipliers.

use super::*;
use ravel_base::rng::Rng;

/// A random ReLU network `sizes[0] → … → sizes[last]`.
fn net(rng: &mut Rng, sizes: &[usize]) -> Network {
    let mut layers = Vec::new();
    for (g, win) in sizes.windows(2).enumerate() {
        if g > 0 {
            layers.push(Layer::Act(Activation::Relu));
        }
        let w = DMatrix::from_fn(win[1], win[0], |_, _| rng.normal() / (win[0] as f64).sqrt());
        let b = DVector::from_fn(win[1], |_, _| 0.3 * rng.normal());
        layers.push(Layer::Affine { w, b });
    }
    Network::new(sizes[0], layers)
}

/// The pre-activations of every hidden layer at `x`.
fn pre_activations(net: &Network, x: &[f64]) -> Vec<Vec<f64>> {
    let mut h = DVector::from_column_slice(x);
    let mut out = Vec::new();
    for layer in &net.layers {
        match layer {
            Layer::Affine { w, b } => h = w * &h + b,
            Layer::Act(_) => {
                out.push(h.iter().copied().collect());
                h = h.map(|v| v.max(0.0));
            }
        }
    }
    out
}

/// Whether `x`'s pre-activations satisfy the domain's bounds (the splits).
fn inside(dom: &Domain, pre: &[Vec<f64>]) -> bool {
    pre.iter().enumerate().all(|(k, z)| {
        z.iter()
            .enumerate()
            .all(|(j, &v)| dom.lo[k][j] <= v && v <= dom.hi[k][j])
    })
}

struct Case {
    net: Network,
    input: IBox,
    obj: DMatrix<f64>,
}

fn case(seed: u64, sizes: &[usize]) -> Case {
    let mut rng = Rng::new(seed);
    let net = net(&mut rng, sizes);
    let n = sizes[0];
    let c: Vec<f64> = (0..n).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let r: Vec<f64> = (0..n).map(|_| rng.uniform(0.05, 0.5)).collect();
    let input = IBox::new(
        (0..n).map(|i| c[i] - r[i]).collect(),
        (0..n).map(|i| c[i] + r[i]).collect(),
    );
    let m = *sizes.last().unwrap();
    let obj = DMatrix::from_fn(m, 3, |_, _| rng.normal());
    Case { net, input, obj }
}

/// The smallest objective value over `samples` random inputs of the box
/// that satisfy the domain's splits (`+∞` if none does).
fn sampled_min(cs: &Case, dom: &Domain, seed: u64, samples: usize) -> Vec<f64> {
    let mut rng = Rng::new(seed);
    let mut best = vec![f64::INFINITY; cs.obj.ncols()];
    for _ in 0..samples {
        let x: Vec<f64> = (0..cs.input.dim())
            .map(|i| rng.uniform(cs.input.lo[i], cs.input.hi[i]))
            .collect();
        if !inside(dom, &pre_activations(&cs.net, &x)) {
            continue;
        }
        let y = DVector::from_vec(cs.net.forward(&x));
        for (c, b) in best.iter_mut().enumerate() {
            *b = b.min(cs.obj.column(c).dot(&y));
        }
    }
    best
}

#[test]
fn the_bounds_hold_on_every_sampled_input_of_every_split_domain() {
    for seed in 0..12 {
        let cs = case(seed, &[3, 12, 10, 4]);
        let chain = ReluChain::of(&cs.net).expect("a ReLU chain");
        let root = Domain::root(&cs.net, &cs.input).expect("finite");
        // the root, then one child per phase of two successive splits
        let mut doms = vec![root.clone()];
        let mut d = root;
        for p in [Phase::Active, Phase::Inactive] {
            let start = Slopes::crown(&chain, &d, cs.obj.ncols());
            let Some((k, j)) = branch(&chain, &cs.input, &d, &cs.obj, &start, 0, 4, false) else {
                break;
            };
            let other = match p {
                Phase::Active => Phase::Inactive,
                Phase::Inactive => Phase::Active,
            };
            doms.push(d.split(k, j, other));
            d = d.split(k, j, p);
            doms.push(d.clone());
        }
        for (i, dom) in doms.iter().enumerate() {
            let crown = Dual::crown(&chain, dom, &cs.obj);
            let plain = certified(&chain, &cs.input, dom, &cs.obj, &crown);
            let opt = optimise(
                &chain,
                &cs.input,
                dom,
                &cs.obj,
                Slopes::crown(&chain, dom, 3),
                40,
            );
            let seen = sampled_min(&cs, dom, seed + 100, 4000);
            for c in 0..cs.obj.ncols() {
                assert!(
                    plain[c] <= seen[c],
                    "seed {seed} domain {i} col {c}: {} > {}",
                    plain[c],
                    seen[c]
                );
                assert!(
                    opt.bounds[c] <= seen[c],
                    "seed {seed} domain {i} col {c}: optimised {} > {}",
                    opt.bounds[c],
                    seen[c]
                );
                assert!(
                    opt.bounds[c] >= plain[c] - 1e-9 * plain[c].abs().max(1.0),
                    "optimising lost ground"
                );
            }
        }
    }
}

#[test]
fn the_crown_multipliers_bound_at_least_as_tightly_as_crown() {
    for seed in 0..8 {
        let cs = case(seed, &[4, 16, 16, 3]);
        let chain = ReluChain::of(&cs.net).unwrap();
        let root = Domain::root(&cs.net, &cs.input).unwrap();
        let dual = Dual::crown(&chain, &root, &cs.obj);
        let ours = certified(&chain, &cs.input, &root, &cs.obj, &dual);
        // CROWN's upper bound of −o·y is minus a lower bound of o·y
        let rel = Relaxation::new(&cs.net, &cs.input, Mode::Crown);
        let neg: DMatrix<f64> = -cs.obj.transpose();
        let theirs = rel.upper(neg).concretize(&cs.input);
        for c in 0..cs.obj.ncols() {
            let crown_lower = -theirs[c];
            assert!(
                ours[c] >= crown_lower - 1e-9 * crown_lower.abs().max(1.0),
                "seed {seed}: {} < CROWN's {crown_lower}",
                ours[c]
            );
        }
    }
}

#[test]
fn optimising_tightens_a_bound_crown_leaves_loose() {
    let mut gained = 0;
    for seed in 0..8 {
        let cs = case(seed, &[4, 20, 20, 3]);
        let chain = ReluChain::of(&cs.net).unwrap();
        let root = Domain::root(&cs.net, &cs.input).unwrap();
        let crown = Dual::crown(&chain, &root, &cs.obj);
        let plain = certified(&chain, &cs.input, &root, &cs.obj, &crown);
        let opt = optimise(
            &chain,
            &cs.input,
            &root,
            &cs.obj,
            Slopes::crown(&chain, &root, 3),
            60,
        );
        gained += (0..3).filter(|&c| opt.bounds[c] > plain[c] + 1e-6).count();
    }
    assert!(
        gained >= 8,
        "the ascent improved only {gained} of 24 bounds"
    );
}

#[test]
fn splitting_every_unstable_neuron_makes_the_bound_exact_on_a_one_layer_network() {
    // one hidden layer: with every neuron's phase fixed the relaxation is
    // the network on that region, and the optimised bound approaches the
    // sampled minimum over the region
    let cs = case(7, &[2, 6, 1]);
    let chain = ReluChain::of(&cs.net).unwrap();
    let mut leaves = vec![Domain::root(&cs.net, &cs.input).unwrap()];
    let mut done = Vec::new();
    while let Some(d) = leaves.pop() {
        match (0..6).find(|&j| d.unstable(0, j)) {
            Some(j) => {
                leaves.push(d.split(0, j, Phase::Active));
                leaves.push(d.split(0, j, Phase::Inactive));
            }
            None => done.push(d),
        }
    }
    let obj = cs.obj.columns(0, 1).into_owned();
    let cs = Case { obj, ..cs };
    let mut lowest = f64::INFINITY;
    for d in &done {
        let o = optimise(
            &chain,
            &cs.input,
            d,
            &cs.obj,
            Slopes::crown(&chain, d, 1),
            200,
        );
        lowest = lowest.min(o.bounds[0]);
    }
    let seen = sampled_min(&cs, &Domain::root(&cs.net, &cs.input).unwrap(), 3, 20000)[0];
    assert!(lowest <= seen);
    assert!(
        seen - lowest < 0.05 * seen.abs().max(1.0),
        "bound {lowest} vs sampled {seen}"
    );
}

#[test]
fn a_non_finite_multiplier_gives_no_bound() {
    let cs = case(1, &[3, 5, 2]);
    let chain = ReluChain::of(&cs.net).unwrap();
    let root = Domain::root(&cs.net, &cs.input).unwrap();
    let mut dual = Dual::crown(&chain, &root, &cs.obj);
    dual.nu[0][(0, 1)] = f64::NAN;
    let b = certified(&chain, &cs.input, &root, &cs.obj, &dual);
    assert_eq!(b[1], f64::NEG_INFINITY);
    dual.nu[0][(0, 1)] = 1e308;
    dual.nu[0][(1, 1)] = -1e308;
    let b = certified(&chain, &cs.input, &root, &cs.obj, &dual);
    assert!(b[1] == f64::NEG_INFINITY || b[1] < -1e300, "{}", b[1]);
}

#[test]
fn only_relu_chains_are_taken() {
    let mut rng = Rng::new(3);
    let mut n = net(&mut rng, &[2, 3, 2]);
    assert!(ReluChain::of(&n).is_some());
    n.layers[1] = Layer::Act(Activation::Tanh);
    assert!(ReluChain::of(&n).is_none());
    let lin = net(&mut rng, &[2, 2]);
    assert!(ReluChain::of(&lin).is_none());
}

#[test]
fn subproblems_optimised_together_get_the_bounds_they_get_apart() {
    let cs = case(5, &[4, 12, 12, 3]);
    let chain = ReluChain::of(&cs.net).unwrap();
    let root = Domain::root(&cs.net, &cs.input).unwrap();
    let start = Slopes::crown(&chain, &root, 3);
    let (k, j) =
        branch(&chain, &cs.input, &root, &cs.obj, &start, 1, 4, false).expect("an unstable neuron");
    let kids = [
        root.split(k, j, Phase::Inactive),
        root.split(k, j, Phase::Active),
    ];
    let apart: Vec<Vec<f64>> = kids
        .iter()
        .map(|d| optimise(&chain, &cs.input, d, &cs.obj, start.clone(), 30).bounds)
        .collect();
    let jobs = kids
        .iter()
        .map(|d| (d, cs.obj.clone(), start.clone()))
        .collect();
    let together = optimise_many(&chain, &cs.input, jobs, 30);
    // the ascent multiplies in f32, whose products may round differently
    // with the number of columns: the same ascent up to that rounding
    for (a, t) in apart.iter().zip(&together) {
        for (x, y) in a.iter().zip(&t.bounds) {
            assert!((x - y).abs() <= 1e-6 * x.abs().max(1.0), "{x} vs {y}");
        }
    }
}

#[test]
fn any_multipliers_give_a_sound_bound() {
    // weak duality holds for every ν, not only the back-substitution's:
    // optimised multipliers perturbed at random, on the root and on split
    // domains
    for seed in 0..10 {
        let cs = case(seed, &[3, 8, 8, 2]);
        let chain = ReluChain::of(&cs.net).unwrap();
        let root = Domain::root(&cs.net, &cs.input).unwrap();
        let mut doms = vec![root.clone()];
        for k in 0..2 {
            if let Some(j) = (0..8).find(|&j| root.unstable(k, j)) {
                doms.push(root.split(k, j, Phase::Active));
                doms.push(root.split(k, j, Phase::Inactive));
            }
        }
        let mut rng = Rng::new(seed + 7);
        for (i, dom) in doms.iter().enumerate() {
            let seen = sampled_min(&cs, dom, seed + 50, 3000);
            // near the optimum, where a vertex left out would show
            let best = optimise(
                &chain,
                &cs.input,
                dom,
                &cs.obj,
                Slopes::crown(&chain, dom, 3),
                60,
            )
            .dual;
            for t in 0..20 {
                let size = 0.02 * t as f64;
                let dual = Dual {
                    nu: best
                        .nu
                        .iter()
                        .map(|m| m.map(|v| v + size * rng.normal()))
                        .collect(),
                };
                let b = certified(&chain, &cs.input, dom, &cs.obj, &dual);
                for c in 0..3 {
                    assert!(
                        b[c] <= seen[c],
                        "seed {seed} domain {i}: {} > {}",
                        b[c],
                        seen[c]
                    );
                }
            }
        }
    }
}

#[test]
fn the_hull_vertex_at_the_upper_bound_counts() {
    // y = relu(x) on [−1, 1], objective −y (minimum −1 at x = 1): with
    // ν = 0 the bound is the neuron's term alone, min over the triangle
    // of −h, attained at its vertex (u, u) = (1, 1); leaving that vertex
    // out would claim 0
    let net = Network::new(
        1,
        vec![
            Layer::Affine {
                w: DMatrix::from_element(1, 1, 1.0),
                b: DVector::from_element(1, 0.0),
            },
            Layer::Act(Activation::Relu),
            Layer::Affine {
                w: DMatrix::from_element(1, 1, 1.0),
                b: DVector::from_element(1, 0.0),
            },
        ],
    );
    let chain = ReluChain::of(&net).unwrap();
    let input = IBox::new(vec![-1.0], vec![1.0]);
    let dom = Domain::root(&net, &input).unwrap();
    let obj = DMatrix::from_element(1, 1, -1.0);
    let dual = Dual {
        nu: vec![DMatrix::zeros(1, 1)],
    };
    let b = certified(&chain, &input, &dom, &obj, &dual)[0];
    assert!(b <= -1.0 && b > -1.0 - 1e-12, "{b}");
}

#[test]
fn tightened_bounds_hold_do_not_depend_on_threads_and_stop_when_asked() {
    // 40 neurons per layer: more than one group of TIGHTEN_GROUP
    let cs = case(11, &[5, 40, 40, 40, 2]);
    let chain = ReluChain::of(&cs.net).unwrap();
    let root = Domain::root(&cs.net, &cs.input).unwrap();
    let mut one = root.clone();
    assert!(one.tighten(&chain, &cs.input, 30, 1, &|| false));
    let mut two = root.clone();
    assert!(two.tighten(&chain, &cs.input, 30, 2, &|| false));
    assert_eq!(one.lo, two.lo);
    assert_eq!(one.hi, two.hi);
    // tighter somewhere, never looser
    let mut gained = 0;
    for k in 0..root.lo.len() {
        for j in 0..root.lo[k].len() {
            assert!(one.lo[k][j] >= root.lo[k][j] && one.hi[k][j] <= root.hi[k][j]);
            gained += usize::from(one.lo[k][j] > root.lo[k][j] || one.hi[k][j] < root.hi[k][j]);
        }
    }
    assert!(gained > 10, "only {gained} bounds tightened");
    // every sampled input's pre-activations lie within the tightened bounds
    let mut rng = Rng::new(5);
    for _ in 0..4000 {
        let x: Vec<f64> = (0..cs.input.dim())
            .map(|i| rng.uniform(cs.input.lo[i], cs.input.hi[i]))
            .collect();
        assert!(inside(&one, &pre_activations(&cs.net, &x)), "x = {x:?}");
    }
    // asked to stop at once: nothing changes, and it says so
    let mut stopped = root.clone();
    assert!(!stopped.tighten(&chain, &cs.input, 30, 2, &|| true));
    assert_eq!(stopped.lo, root.lo);
    assert_eq!(stopped.hi, root.hi);
}

#[test]
fn relu_pairs_between_affine_layers_keep_the_function_and_its_bounds() {
    // a normalisation (diagonal) before the first layer, and a pooling-like
    // averaging before the last: consecutive affine layers
    let mut rng = Rng::new(21);
    let inner = net(&mut rng, &[6, 12, 12, 3]);
    let diag = Layer::Affine {
        w: DMatrix::from_diagonal(&DVector::from_fn(6, |_, _| rng.uniform(0.5, 3.0))),
        b: DVector::from_fn(6, |_, _| rng.uniform(-1.0, 1.0)),
    };
    let pool = Layer::Affine {
        w: DMatrix::from_fn(2, 3, |_, _| rng.uniform(-1.0, 1.0)),
        b: DVector::from_fn(2, |_, _| rng.normal()),
    };
    let mut layers = vec![diag];
    layers.extend(inner.layers.iter().cloned());
    layers.push(pool);
    let original = Network::new(6, layers);
    assert!(ReluChain::of(&original).is_none());
    let paired = alternating(&original).unwrap();
    assert_eq!(paired.layers.len(), original.layers.len() + 2);
    let chain = ReluChain::of(&paired).unwrap();
    let input = IBox::new(vec![-0.4; 6], vec![0.3; 6]);
    let root = Domain::root(&paired, &input).unwrap();
    let obj = DMatrix::from_fn(2, 2, |_, _| rng.normal());
    let o = optimise(
        &chain,
        &input,
        &root,
        &obj,
        Slopes::crown(&chain, &root, 2),
        40,
    );
    for _ in 0..3000 {
        let x: Vec<f64> = (0..6).map(|_| rng.uniform(-0.4, 0.3)).collect();
        let (a, b) = (original.forward(&x), paired.forward(&x));
        for (u, v) in a.iter().zip(&b) {
            assert!((u - v).abs() <= 1e-12 * (1.0 + u.abs()), "{a:?} vs {b:?}");
        }
        for c in 0..2 {
            let value: f64 = (0..2).map(|i| obj[(i, c)] * a[i]).sum();
            assert!(
                o.bounds[c] <= value + 1e-9,
                "bound {} above {value}",
                o.bounds[c]
            );
        }
    }
    // another activation than ReLU: no rewriting
    let tanh = Network::new(
        1,
        vec![
            Layer::Affine {
                w: DMatrix::from_element(1, 1, 1.0),
                b: DVector::zeros(1),
            },
            Layer::Act(Activation::Tanh),
            Layer::Affine {
                w: DMatrix::from_element(1, 1, 1.0),
                b: DVector::zeros(1),
            },
        ],
    );
    assert!(alternating(&tanh).is_none());
}

/// After a split in the first hidden layer, re-bounding the later layers
/// keeps every sampled input of the child inside the child's domain
/// (every bound certified), tightens some bounds, never loosens one, and
/// gives the same domains in one batch as apart (up to single-precision
/// rounding).
#[test]
fn rebounded_children_hold_every_sampled_input_and_tighten() {
    let mut tightened = 0;
    for seed in 0..10 {
        let cs = case(seed, &[3, 12, 10, 8, 4]);
        let chain = ReluChain::of(&cs.net).expect("a ReLU chain");
        let root = Domain::root(&cs.net, &cs.input).expect("finite");
        let Some(j) = (0..root.lo[0].len()).find(|&j| root.unstable(0, j)) else {
            continue;
        };
        let kids: Vec<(Domain, usize)> = [Phase::Inactive, Phase::Active]
            .into_iter()
            .map(|p| (root.split(0, j, p), 0))
            .collect();
        let mut together = kids.clone();
        rebound_after(&chain, &cs.input, &mut together);
        for (i, (plain, _)) in kids.iter().enumerate() {
            let mut alone = vec![kids[i].clone()];
            rebound_after(&chain, &cs.input, &mut alone);
            // (the multipliers are found with single-precision products,
            // whose summation order depends on the columns)
            let near = |a: &[Vec<f64>], b: &[Vec<f64>]| {
                a.iter()
                    .flatten()
                    .zip(b.iter().flatten())
                    .all(|(x, y)| (x - y).abs() <= 1e-5 * x.abs().max(1.0))
            };
            assert!(
                near(&alone[0].0.lo, &together[i].0.lo) && near(&alone[0].0.hi, &together[i].0.hi),
                "seed {seed}: batched as apart"
            );
            let re = &together[i].0;
            for k in 0..re.lo.len() {
                for n in 0..re.lo[k].len() {
                    assert!(re.lo[k][n] >= plain.lo[k][n] && re.hi[k][n] <= plain.hi[k][n]);
                    if re.lo[k][n] > plain.lo[k][n] || re.hi[k][n] < plain.hi[k][n] {
                        tightened += 1;
                    }
                }
            }
            let mut rng = Rng::new(seed + 7);
            for _ in 0..3000 {
                let x: Vec<f64> = (0..cs.input.dim())
                    .map(|d| rng.uniform(cs.input.lo[d], cs.input.hi[d]))
                    .collect();
                let pre = pre_activations(&cs.net, &x);
                if inside(plain, &pre) {
                    assert!(
                        inside(re, &pre),
                        "seed {seed} child {i}: {x:?} left the domain"
                    );
                }
            }
        }
    }
    assert!(tightened > 20, "only {tightened} bounds tightened");
}
