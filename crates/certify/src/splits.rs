//! The checker of activation-split evidence: a network spec's VERIFIED
//! verdicts proved by branch and bound on ReLU activations.
//!
//! # What is checked
//!
//! The network as loaded is read as a *chain* of affine layers with a ReLU
//! between every two (consecutive affine layers `A`, `B` are rewritten, as
//! the analysis does, to `[A; −A]`, a ReLU and `[B, −B]`: the same real
//! function, since `z = max(z, 0) − max(−z, 0)`); any other activation is
//! not supported. Its hidden layers are numbered from 0.
//!
//! 1. **The root's claims.** Per hidden layer a box of pre-activation bounds
//!    over the input box. Layer by layer, each claimed neuron bound must
//!    contain what the checker proves from the earlier layers' claims: its
//!    own interval and back-substitution bound ([`NetBounds`]), intersected
//!    with the Lagrangian bound `L(ν)` of any multipliers the evidence gives
//!    for that neuron (below). Earlier claims are proved before a later
//!    layer uses them, so the induction is sound.
//! 2. **The split tree.** A flat array of nodes, the root first; a node
//!    either splits neuron `(k, j)` into an *inactive* child (`z ≤ 0`) and
//!    an *active* child (`z ≥ 0`), both present, each after its parent, or
//!    is a leaf. Every input of the box lies in some leaf's sub-domain (the
//!    two children of a split cover their parent). A node's domain is the
//!    root's claims with the clamps of its path (`hi ← min(hi, 0)` for an
//!    inactive child, `lo ← max(lo, 0)` for an active one); a clamp that
//!    empties a neuron's interval (inactive with a claimed `lo > 0`, active
//!    with `hi < 0`) makes the sub-domain empty, where every row holds.
//! 3. **Proofs.** A node may carry proofs `(row, ν)`: the property row
//!    (indexed over every property's rows, in order) is bounded over the
//!    node's sub-domain by `L(ν)`. At the root the checker's own bounds
//!    over the box prove rows too. A VERIFIED property holds when, on every
//!    leaf, its rows are proved at the leaf or one of its ancestors (a
//!    `require` row within its right-hand side, every robustness comparison
//!    negative, some row of every `avoid` member separating it).
//!
//! # The Lagrangian bound
//!
//! For the chain up to affine layer `K` and an objective `o·z_K`, with
//! multipliers `ν_i` of every hidden layer `i < K` and `ν_K = o`, weak
//! duality over the triangle relaxation of every ReLU (bounds `l ≤ z ≤ u`
//! of the domain) gives a lower bound over the domain for **any** `ν`:
//!
//! ```text
//! L(ν) = Σ_{i≤K} ν_i·b_i + min_{x∈box} (W_0ᵀν_0)·x
//!      + Σ_{i<K} Σ_j min over the relaxation of (−ν_ij z + (W_{i+1}ᵀν_{i+1})_j h)
//! ```
//!
//! each inner minimum at a vertex of a segment (`u ≤ 0`: `h = 0`; `l ≥ 0`:
//! `h = z`) or triangle (`(l, 0)`, `(0, 0)`, `(u, u)`). The checker computes
//! it with its own outward rounding: `W_{i+1}ᵀν_{i+1}` as an enclosure per
//! entry ([`Acc`]; only its lower end is needed since `h ≥ 0`), each vertex
//! value rounded down product by product, the sum's rounding bounded by
//! [`Acc::lower`]. A non-finite `ν`, or any overflow, gives `−∞`: it proves
//! nothing. So `ν` is not a claim: changing one can only make a true claim
//! unprovable.
//!
//! # Limits
//!
//! At most [`MAX_NODES`] nodes, a path no longer than the hidden neurons
//! (the most distinct splits), every `ν` of exactly the layers' widths, and
//! at most [`MAX_WORK`] multiply-adds in all evaluations: beyond any of
//! them the certificate is UNREADABLE, before the evaluations run.

use nalgebra::{DMatrix, DVector};
use serde_json::Value;

use super::bounds::{Bx, NetBounds};
use super::{get, uint, R};
use ravel_base::nn::{Activation, Layer, Network};
use ravel_base::num::Acc;

/// The most nodes of a split tree (more than any search makes).
pub const MAX_NODES: usize = 1 << 22;

/// The most multiply-adds of all the Lagrangian evaluations together.
pub const MAX_WORK: u64 = 1 << 37;

/// A property row as the splits prove it: its direction `d` over the
/// outputs (an upper bound `u` of `d·y` is sought) and its test on `u`.
#[derive(Clone, Debug)]
pub struct Row {
    /// The direction.
    pub d: Vec<f64>,
    /// The test.
    pub test: Test,
}

/// How an upper bound `u` of a row proves it.
#[derive(Clone, Copy, Debug)]
pub enum Test {
    /// `u ≤ b` (a `require` row).
    AtMost(f64),
    /// `u < b` (a robustness comparison, `b = 0`; an `avoid` row, `−a·y < −h`).
    Below(f64),
}

impl Test {
    /// Whether `u` proves the row (a NaN never does).
    pub fn holds(self, u: f64) -> bool {
        match self {
            Test::AtMost(b) => u <= b,
            Test::Below(b) => u < b,
        }
    }
}

/// What a VERIFIED property needs on every leaf, over the rows' indices:
/// all of `all`, and one of each group of `any`.
#[derive(Clone, Debug, Default)]
pub struct Need {
    /// Rows that must all be proved.
    pub all: Vec<usize>,
    /// Groups (avoid members) of which one row must be proved.
    pub any: Vec<Vec<usize>>,
    /// The property's name, for messages.
    pub name: String,
}

/// A network as a chain of affine layers with ReLUs between them.
pub struct Chain {
    /// The chain as a network (for [`NetBounds`]).
    pub net: Network,
    w: Vec<DMatrix<f64>>,
    b: Vec<DVector<f64>>,
}

impl Chain {
    /// `net` as a chain (see the module documentation), or why not.
    pub fn of(net: &Network) -> R<Chain> {
        let mut layers: Vec<Layer> = Vec::new();
        for layer in &net.layers {
            match layer {
                Layer::Act(Activation::Relu) => layers.push(layer.clone()),
                Layer::Act(a) => {
                    return Err(format!(
                        "the network has a {a:?} activation: only ReLU networks' splits are checked"
                    ))
                }
                Layer::Affine { w, b } => match layers.last() {
                    Some(Layer::Affine { w: wa, b: ba }) => {
                        let (wa, ba) = (wa.clone(), ba.clone());
                        layers.pop();
                        let r = wa.nrows();
                        // the entry at (i mod r, j), negated past r
                        let pm = |m: &DMatrix<f64>, i: usize, j: usize| {
                            let v = m.get((i % r, j)).copied().unwrap_or(f64::NAN);
                            if i < r {
                                v
                            } else {
                                -v
                            }
                        };
                        let top = DMatrix::from_fn(2 * r, wa.ncols(), |i, j| pm(&wa, i, j));
                        let tb = DVector::from_fn(2 * r, |i, _| {
                            let v = ba.get(i % r).copied().unwrap_or(f64::NAN);
                            if i < r {
                                v
                            } else {
                                -v
                            }
                        });
                        let wt = w.transpose();
                        let next = DMatrix::from_fn(w.nrows(), 2 * r, |i, j| pm(&wt, j, i));
                        layers.push(Layer::Affine { w: top, b: tb });
                        layers.push(Layer::Act(Activation::Relu));
                        layers.push(Layer::Affine {
                            w: next,
                            b: b.clone(),
                        });
                    }
                    _ => layers.push(layer.clone()),
                },
            }
        }
        let mut w = Vec::new();
        let mut b = Vec::new();
        for (i, layer) in layers.iter().enumerate() {
            match (i % 2, layer) {
                (0, Layer::Affine { w: wi, b: bi }) => {
                    if !wi.iter().chain(bi.iter()).all(|v| v.is_finite()) {
                        return Err("the network has a weight that is not finite".into());
                    }
                    w.push(wi.clone());
                    b.push(bi.clone());
                }
                (1, Layer::Act(Activation::Relu)) => {}
                _ => return Err("the network is not affine layers with ReLUs between".into()),
            }
        }
        if layers.len() % 2 == 0 || w.len() < 2 {
            return Err("the network has no hidden ReLU layer between affine layers".into());
        }
        Ok(Chain {
            net: Network::new(net.inputs, layers),
            w,
            b,
        })
    }

    /// The number of hidden layers.
    pub fn hidden(&self) -> usize {
        self.w.len() - 1
    }

    /// The width of affine layer `k`'s output.
    pub fn width(&self, k: usize) -> usize {
        self.w.get(k).map_or(0, |m| m.nrows())
    }

    /// Multiply-adds of one evaluation of `L` with the objective at layer `k`.
    fn work(&self, k: usize) -> u64 {
        self.w
            .iter()
            .take(k + 1)
            .map(|m| (m.nrows() as u64).saturating_mul(m.ncols() as u64))
            .fold(0u64, u64::saturating_add)
    }
}

/// `a·x` rounded down, zero when either is zero (an infinite `a` times 0
/// is 0 here: it multiplies a coordinate that is exactly 0).
fn mul_down(a: f64, x: f64) -> f64 {
    if a == 0.0 || x == 0.0 {
        0.0
    } else {
        (a * x).next_down()
    }
}

/// The smaller of two lower bounds; a NaN is no bound (`−∞`).
fn min_lower(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NEG_INFINITY
    } else {
        a.min(b)
    }
}

/// A certified lower bound of `o·z_k` over the input box `input` and the
/// domain `dom` (one box per hidden layer `< k`), from the multipliers `nu`
/// (one vector per hidden layer `< k`): `L(ν)` of the module documentation,
/// `−∞` when a number is not finite or the shapes do not fit.
pub fn lagrangian(
    chain: &Chain,
    k: usize,
    o: &[f64],
    nu: &[Vec<f64>],
    input: &Bx,
    dom: &[Bx],
) -> f64 {
    let none = f64::NEG_INFINITY;
    if k > chain.hidden() || nu.len() != k || dom.len() < k || o.len() != chain.width(k) {
        return none;
    }
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    if !(finite(o) && nu.iter().all(|v| finite(v)) && input.is_proper()) {
        return none;
    }
    // ν_i for i ≤ k, ν_k = o
    let at = |i: usize| -> &[f64] {
        if i == k {
            o
        } else {
            nu.get(i).map_or(&[], Vec::as_slice)
        }
    };
    for i in 0..=k {
        if at(i).len() != chain.width(i) {
            return none;
        }
    }
    let mut acc = Acc::ZERO;
    // Σ ν_i·b_i
    for (i, b) in chain.b.iter().enumerate().take(k + 1) {
        acc.add_products(at(i), b.as_slice());
    }
    // an enclosure of (W_iᵀ ν_i)_j: column j of W_i against ν_i (no
    // such column: no bound)
    let column = |i: usize, j: usize| -> (f64, f64) {
        match chain.w.get(i).filter(|w| j < w.ncols()) {
            Some(w) => {
                let mut s = Acc::ZERO;
                s.add_products(w.column(j).as_slice(), at(i));
                (s.lower(), s.upper())
            }
            None => (f64::NEG_INFINITY, f64::INFINITY),
        }
    };
    // the input term
    if input.lo.len() != chain.net.inputs {
        return none;
    }
    for (j, (&xl, &xh)) in input.lo.iter().zip(&input.hi).enumerate() {
        let (dl, dh) = column(0, j);
        let m = [
            mul_down(dl, xl),
            mul_down(dl, xh),
            mul_down(dh, xl),
            mul_down(dh, xh),
        ]
        .into_iter()
        .fold(f64::INFINITY, min_lower);
        acc.add(m);
    }
    // the neurons' terms
    for (i, d) in dom.iter().enumerate().take(k) {
        let v = at(i);
        if d.lo.len() != v.len() || d.hi.len() != v.len() {
            return none;
        }
        for (j, (&vj, (&l, &u))) in v.iter().zip(d.lo.iter().zip(&d.hi)).enumerate() {
            let (gl, _) = column(i + 1, j);
            let a = -vj;
            // −ν z + g h at a vertex, rounded down (h ≥ 0: g's lower end)
            let vertex = |z: f64, h: f64| (mul_down(a, z) + mul_down(gl, h)).next_down();
            let m = if u <= 0.0 {
                min_lower(vertex(l, 0.0), vertex(u, 0.0))
            } else if l >= 0.0 {
                min_lower(vertex(l, l), vertex(u, u))
            } else {
                min_lower(min_lower(vertex(l, 0.0), 0.0), vertex(u, u))
            };
            acc.add(m);
        }
    }
    let v = acc.lower();
    if v.is_nan() {
        none
    } else {
        v
    }
}

/// Multipliers proving one neuron bound of the root: `L(ν)` of the chain
/// up to hidden layer `layer` with the objective `z_j` (a lower bound) or
/// `−z_j` (`upper`: minus an upper bound).
#[derive(Clone, Debug)]
pub struct NeuronNu {
    /// The hidden layer.
    pub layer: usize,
    /// The neuron.
    pub neuron: usize,
    /// Whether it bounds `z_j` from above.
    pub upper: bool,
    /// `ν` of every hidden layer before `layer`.
    pub nu: Vec<Vec<f64>>,
}

/// The upper bounds of layer `k`'s rows `[I; −I]` that `neurons`' proofs
/// give over `input` with the earlier layers' boxes `before`.
fn neuron_bounds(
    chain: &Chain,
    neurons: &[NeuronNu],
    input: &Bx,
    k: usize,
    before: &[Bx],
) -> Vec<f64> {
    let n = chain.width(k);
    let mut up = vec![f64::INFINITY; 2 * n];
    for p in neurons.iter().filter(|p| p.layer == k && p.neuron < n) {
        let sign = if p.upper { -1.0 } else { 1.0 };
        let o: Vec<f64> = (0..n)
            .map(|j| if j == p.neuron { sign } else { 0.0 })
            .collect();
        let l = lagrangian(chain, k, &o, &p.nu, input, before);
        // a lower bound l of ±z: +z ≤ −l (upper), −z ≤ −l (lower)
        let row = if p.upper { p.neuron } else { n + p.neuron };
        if let (Some(u), false) = (up.get_mut(row), l.is_nan()) {
            *u = u.min(-l);
        }
    }
    up
}

/// Whether some bound of `dom` crossed its other end: no input reaches it.
fn is_void(dom: &[Bx]) -> bool {
    dom.iter()
        .any(|b| b.lo.iter().zip(&b.hi).any(|(l, h)| l > h))
}

/// CROWN's multipliers for the objective `o·z_k` over `dom` (plain floating
/// point: any `ν` gives a valid [`lagrangian`], which certifies): from
/// `ν_k = o` back, `ν_i = D_i (W_{i+1}ᵀ ν_{i+1})` with `D` 0 for an inactive
/// neuron, 1 for an active one, and for an unstable one the upper line's
/// slope `u/(u − l)` where the coefficient is negative, else 1 when
/// `u ≥ −l` and 0 otherwise.
fn crown_nu(chain: &Chain, k: usize, o: &[f64], dom: &[Bx]) -> Vec<Vec<f64>> {
    let mut nu: Vec<Vec<f64>> = vec![Vec::new(); k];
    let mut next: Vec<f64> = o.to_vec();
    for i in (0..k).rev() {
        let (Some(w), Some(d)) = (chain.w.get(i + 1), dom.get(i)) else {
            return nu;
        };
        let g = w.tr_mul(&DVector::from_column_slice(&next));
        let v: Vec<f64> = g
            .iter()
            .zip(d.lo.iter().zip(&d.hi))
            .map(|(&gj, (&l, &u))| {
                if u <= 0.0 {
                    0.0
                } else if l >= 0.0 {
                    gj
                } else if gj < 0.0 {
                    u / (u - l) * gj
                } else if u >= -l {
                    gj
                } else {
                    0.0
                }
            })
            .collect();
        if let Some(slot) = nu.get_mut(i) {
            slot.clone_from(&v);
        }
        next = v;
    }
    nu
}

/// Re-bound, after a split in hidden layer `from − 1`, the unstable neurons
/// of hidden layers `from..` on `dom`, layer by layer: each bound of `z_j`
/// and of `−z_j` is [`lagrangian`] at CROWN's multipliers ([`crown_nu`]) over
/// the input box and the layers before it, kept where tighter. This is how
/// the analysis derives a child's domain (`rebound_after` there); the
/// checker's arithmetic is its own, and a bound it finds looser only makes
/// a proof fail. `work` counts the multiply-adds.
fn rebound(chain: &Chain, input: &Bx, dom: &mut [Bx], from: usize, work: &mut u64) {
    let hidden = chain.hidden();
    for m in from.max(1)..hidden {
        let n = chain.width(m);
        // the products of one back-substitution and one evaluation
        let cost: u64 = (0..=m)
            .filter_map(|i| chain.w.get(i))
            .map(|w| 2 * (w.nrows() * w.ncols()) as u64)
            .sum();
        for j in 0..n {
            for sign in [1.0, -1.0] {
                let Some(b) = dom.get(m) else {
                    return;
                };
                let (Some(&l), Some(&u)) = (b.lo.get(j), b.hi.get(j)) else {
                    return;
                };
                if !(l < 0.0 && u > 0.0) {
                    continue;
                }
                let mut o = vec![0.0; n];
                if let Some(x) = o.get_mut(j) {
                    *x = sign;
                }
                let (before, _) = dom.split_at(m);
                let nu = crown_nu(chain, m, &o, before);
                let v = lagrangian(chain, m, &o, &nu, input, before);
                *work = work.saturating_add(cost);
                if let Some(b) = dom.get_mut(m) {
                    if sign > 0.0 {
                        if let Some(lo) = b.lo.get_mut(j) {
                            if v.is_finite() && v > *lo {
                                *lo = v;
                            }
                        }
                    } else if let Some(hi) = b.hi.get_mut(j) {
                        if v.is_finite() && -v < *hi {
                            *hi = -v;
                        }
                    }
                }
            }
        }
    }
}

/// The root's pre-activation bounds the checker proves over `input` with
/// the neurons' multipliers (its own bounds, each intersected with theirs),
/// widened as a writer claims them (so that a checker elsewhere proves
/// them too): for the certificate writer.
pub fn derive_claims(net: &Network, input: &Bx, neurons: &[NeuronNu]) -> R<Vec<Bx>> {
    let chain = Chain::of(net)?;
    let extra = |k: usize, before: &[Bx]| neuron_bounds(&chain, neurons, input, k, before);
    let nb =
        NetBounds::with_extra(&chain.net, input, None, &extra, true).map_err(|t| t.to_string())?;
    Ok(nb.witness)
}

/// A node of the split tree as read.
struct Node {
    /// `(layer, neuron, inactive child, active child)`.
    split: Option<(usize, usize, usize, usize)>,
    /// `(row, ν)`.
    proofs: Vec<(usize, Vec<Vec<f64>>)>,
}

/// The splits' evidence as read.
pub struct Evidence {
    claims: Vec<Bx>,
    neurons: Vec<NeuronNu>,
    nodes: Vec<Node>,
    /// Whether each child's later layers are re-bounded after its split
    /// (`"rebound": true`; see [`rebound`]).
    rebound: bool,
}

/// Read a `ν`: one vector per hidden layer `< k`, each of its layer's width.
fn read_nu(v: &Value, chain: &Chain, k: usize, what: &str) -> R<Vec<Vec<f64>>> {
    let layers = v
        .as_array()
        .ok_or_else(|| format!("{what}: `nu` must be an array"))?;
    if layers.len() != k {
        return Err(format!(
            "{what}: `nu` has {} vectors, expected {k}",
            layers.len()
        ));
    }
    layers
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let a = l
                .as_array()
                .ok_or_else(|| format!("{what}: `nu[{i}]` must be an array"))?;
            if a.len() != chain.width(i) {
                return Err(format!(
                    "{what}: `nu[{i}]` has {} entries, expected {}",
                    a.len(),
                    chain.width(i)
                ));
            }
            a.iter()
                .map(|x| {
                    x.as_f64()
                        .ok_or_else(|| format!("{what}: `nu` entries must be numbers"))
                })
                .collect()
        })
        .collect()
}

impl Evidence {
    /// The number of nodes of the tree.
    pub fn nodes(&self) -> usize {
        self.nodes.len()
    }

    /// Read `evidence.splits` for `chain` with `rows` property rows; every
    /// limit (see the module documentation) is checked before any
    /// evaluation.
    pub fn read(v: &Value, chain: &Chain, rows: usize) -> R<Evidence> {
        Evidence::read_within(v, chain, rows, (MAX_NODES, MAX_WORK))
    }

    /// [`Evidence::read`] within other limits (tests reach them cheaply).
    fn read_within(
        v: &Value,
        chain: &Chain,
        rows: usize,
        (max_nodes, max_work): (usize, u64),
    ) -> R<Evidence> {
        let hidden = chain.hidden();
        let layers = get(v, "layers")?
            .as_array()
            .ok_or("`splits.layers` must be an array")?;
        if layers.len() != hidden {
            return Err(format!(
                "`splits.layers` has {} boxes for {hidden} hidden layers",
                layers.len()
            ));
        }
        let mut claims = Vec::with_capacity(hidden);
        for (k, l) in layers.iter().enumerate() {
            let n = chain.width(k);
            let b = Bx {
                lo: super::vector(get(l, "lo")?, n, "splits.layers lo")?,
                hi: super::vector(get(l, "hi")?, n, "splits.layers hi")?,
            };
            if !b.is_proper() {
                return Err(format!("`splits.layers[{k}]` is not a proper box"));
            }
            claims.push(b);
        }
        let mut work: u64 = 0;
        let mut spend = |w: u64| -> R<()> {
            work = work.saturating_add(w);
            if work > max_work {
                return Err(format!(
                    "the splits' proofs need more than {max_work} multiply-adds to check"
                ));
            }
            Ok(())
        };
        let mut neurons = Vec::new();
        let mut seen = std::collections::BTreeSet::new();
        for (i, p) in get(v, "neurons")?
            .as_array()
            .ok_or("`splits.neurons` must be an array")?
            .iter()
            .enumerate()
        {
            let what = format!("splits.neurons[{i}]");
            let layer = uint(get(p, "layer")?, "layer")?;
            let neuron = uint(get(p, "neuron")?, "neuron")?;
            if layer >= hidden || neuron >= chain.width(layer) {
                return Err(format!("{what}: no neuron ({layer}, {neuron})"));
            }
            let upper = match get(p, "bound")?.as_str() {
                Some("lo") => false,
                Some("hi") => true,
                _ => return Err(format!("{what}: `bound` must be \"lo\" or \"hi\"")),
            };
            // one proof per bound: a repeated entry would only cost work
            if !seen.insert((layer, neuron, upper)) {
                return Err(format!(
                    "{what}: a second proof of the {} bound of neuron ({layer}, {neuron})",
                    if upper { "upper" } else { "lower" }
                ));
            }
            spend(chain.work(layer))?;
            let nu = read_nu(get(p, "nu")?, chain, layer, &what)?;
            neurons.push(NeuronNu {
                layer,
                neuron,
                upper,
                nu,
            });
        }
        let list = get(v, "nodes")?
            .as_array()
            .ok_or("`splits.nodes` must be an array")?;
        if list.is_empty() || list.len() > max_nodes {
            return Err(format!(
                "`splits.nodes` has {} nodes (1 to {max_nodes})",
                list.len()
            ));
        }
        if (list.len() as u64).saturating_mul(rows as u64) > 1 << 31 {
            return Err("`splits.nodes` × the property rows is too large".into());
        }
        let mut nodes = Vec::with_capacity(list.len());
        for (i, n) in list.iter().enumerate() {
            let what = format!("splits.nodes[{i}]");
            let split = match n.get("split") {
                None | Some(Value::Null) => None,
                Some(s) => {
                    let a = s.as_array().filter(|a| a.len() == 4).ok_or_else(|| {
                        format!("{what}: `split` must be [layer, neuron, inactive, active]")
                    })?;
                    let f = |x: Option<&Value>| -> R<usize> {
                        x.map_or(Err(format!("{what}: bad `split`")), |v| uint(v, "split"))
                    };
                    let (k, j, c0, c1) = (f(a.first())?, f(a.get(1))?, f(a.get(2))?, f(a.get(3))?);
                    if k >= hidden || j >= chain.width(k) {
                        return Err(format!("{what}: no neuron ({k}, {j}) to split"));
                    }
                    if c0 <= i || c1 <= i || c0 == c1 || c0 >= list.len() || c1 >= list.len() {
                        return Err(format!("{what}: children must be two distinct later nodes"));
                    }
                    Some((k, j, c0, c1))
                }
            };
            let mut proofs = Vec::new();
            if let Some(ps) = n.get("proofs") {
                for (q, p) in ps
                    .as_array()
                    .ok_or_else(|| format!("{what}: `proofs` must be an array"))?
                    .iter()
                    .enumerate()
                {
                    let row = uint(get(p, "row")?, "row")?;
                    if row >= rows {
                        return Err(format!("{what}: proof {q}: no row {row}"));
                    }
                    spend(chain.work(hidden))?;
                    let nu = read_nu(get(p, "nu")?, chain, hidden, &format!("{what}.proofs[{q}]"))?;
                    proofs.push((row, nu));
                }
            }
            nodes.push(Node { split, proofs });
        }
        // every node but the root has exactly one parent, earlier than it;
        // no path is longer than the hidden neurons
        let neurons_total: usize = (0..hidden).map(|k| chain.width(k)).sum();
        // (per node: its parent's index and its depth; children come
        // after their parent, so both are known when a node is reached)
        let mut up: Vec<Option<(usize, usize)>> = vec![None; nodes.len()];
        for (i, n) in nodes.iter().enumerate() {
            let d = match up.get(i).copied().flatten() {
                Some((_, d)) => d,
                None if i == 0 => 0,
                None => return Err(format!("splits.nodes[{i}] has no parent")),
            };
            if let Some((_, _, c0, c1)) = n.split {
                for c in [c0, c1] {
                    let slot = up
                        .get_mut(c)
                        .ok_or_else(|| format!("splits.nodes[{i}]: no child {c}"))?;
                    if slot.is_some() {
                        return Err(format!("splits.nodes[{c}] has two parents"));
                    }
                    if d + 1 > neurons_total {
                        return Err(format!(
                            "splits.nodes[{c}] is deeper than the {neurons_total} hidden neurons"
                        ));
                    }
                    *slot = Some((i, d + 1));
                }
            }
        }
        let rebound = match v.get("rebound") {
            None => false,
            Some(b) => b
                .as_bool()
                .ok_or("`splits.rebound` must be true or false")?,
        };
        Ok(Evidence {
            claims,
            neurons,
            nodes,
            rebound,
        })
    }
}

/// The checker's verdict on the splits' evidence: `Ok(None)` when every
/// VERIFIED property (`needs`) is proved on every leaf, `Ok(Some(why))`
/// with the first failure (a claim not proven, a leaf path missing a row).
/// `proved`, when given, receives per node per proof whether it proved
/// its row (for the writer, which drops the others).
pub fn check(
    chain: &Chain,
    ev: &Evidence,
    input: &Bx,
    rows: &[Option<Row>],
    needs: &[Need],
    slopes: usize,
    mut proved: Option<&mut Vec<Vec<bool>>>,
) -> Option<String> {
    let hidden = chain.hidden();
    // 1. the root's claims, layer by layer
    let extra = |k: usize, before: &[Bx]| neuron_bounds(chain, &ev.neurons, input, k, before);
    let nb = match NetBounds::with_extra(&chain.net, input, Some(&ev.claims), &extra, false) {
        Ok(nb) => nb,
        Err(t) => return Some(format!("the root's pre-activation claims: {t}")),
    };
    // the rows the checker's own bounds prove over the whole box
    let m = chain.width(hidden);
    let wanted: Vec<(usize, &Row)> = rows
        .iter()
        .enumerate()
        .filter_map(|(r, row)| row.as_ref().map(|row| (r, row)))
        .collect();
    let spec = DMatrix::from_fn(wanted.len(), m, |i, j| {
        wanted
            .get(i)
            .and_then(|(_, r)| r.d.get(j))
            .copied()
            .unwrap_or(0.0)
    });
    let own: Vec<usize> = nb
        .rows_upper(&spec, slopes)
        .iter()
        .zip(&wanted)
        .filter(|(u, (_, row))| row.test.holds(**u))
        .map(|(_, (r, _))| *r)
        .collect();
    // 2. each node's proofs over its domain
    let n = ev.nodes.len();
    let mut parent: Vec<Option<(usize, usize, usize, bool)>> = vec![None; n];
    for (i, node) in ev.nodes.iter().enumerate() {
        if let Some((k, j, c0, c1)) = node.split {
            if let Some(p) = parent.get_mut(c0) {
                *p = Some((i, k, j, false));
            }
            if let Some(p) = parent.get_mut(c1) {
                *p = Some((i, k, j, true));
            }
        }
    }
    // per node: its own proved rows, and whether its own clamp empties it
    let mut own_rows: Vec<Vec<usize>> = vec![Vec::new(); n];
    let mut empty = vec![false; n];
    if let Some(r) = own_rows.first_mut() {
        r.extend(own.iter().copied());
    }
    let prove = |node: &Node, dom: &[Bx]| -> Vec<(usize, bool)> {
        node.proofs
            .iter()
            .map(|(row, nu)| {
                let ok = rows.get(*row).and_then(Option::as_ref).is_some_and(|r| {
                    let o: Vec<f64> = r.d.iter().map(|v| -v).collect();
                    let l = lagrangian(chain, hidden, &o, nu, input, dom);
                    r.test.holds(-l)
                });
                (*row, ok)
            })
            .collect()
    };
    if ev.rebound {
        // every node's domain from its parent's: the clamp, then the later
        // layers re-bounded; depth first, so only a path's domains are held
        let mut flags_of: Vec<Vec<(usize, bool)>> = vec![Vec::new(); n];
        let mut work = 0u64;
        let mut stack: Vec<(usize, Vec<Bx>)> = vec![(0, ev.claims.clone())];
        while let Some((i, dom)) = stack.pop() {
            let Some(node) = ev.nodes.get(i) else {
                continue;
            };
            if is_void(&dom) {
                if let Some(e) = empty.get_mut(i) {
                    *e = true;
                }
                continue;
            }
            if let Some(f) = flags_of.get_mut(i) {
                *f = prove(node, &dom);
            }
            if let Some((k, j, c0, c1)) = node.split {
                for (c, active) in [(c0, false), (c1, true)] {
                    let mut d = dom.clone();
                    if let Some(b) = d.get_mut(k) {
                        if active {
                            if let Some(lo) = b.lo.get_mut(j) {
                                *lo = lo.max(0.0);
                            }
                        } else if let Some(hi) = b.hi.get_mut(j) {
                            *hi = hi.min(0.0);
                        }
                    }
                    if !is_void(&d) {
                        rebound(chain, input, &mut d, k + 1, &mut work);
                    }
                    if work > MAX_WORK {
                        return Some(format!(
                            "re-bounding the split tree's domains needs more than {MAX_WORK} multiply-adds"
                        ));
                    }
                    stack.push((c, d));
                }
            }
        }
        for (i, flags) in flags_of.into_iter().enumerate() {
            if let Some(mine) = own_rows.get_mut(i) {
                mine.extend(flags.iter().filter(|f| f.1).map(|f| f.0));
            }
            if let Some(p) = proved.as_deref_mut() {
                // (a void node's proofs are not needed: they count as not proved)
                let len = ev.nodes.get(i).map_or(0, |x| x.proofs.len());
                let mut v: Vec<bool> = flags.iter().map(|f| f.1).collect();
                v.resize(len, false);
                p.push(v);
            }
        }
    }
    for (i, node) in ev.nodes.iter().enumerate() {
        if ev.rebound {
            break;
        }
        if let (Some(&Some((_, k, j, active))), Some(e)) = (parent.get(i), empty.get_mut(i)) {
            // (a neuron the reader found in range)
            let c = ev.claims.get(k);
            let (lo, hi) = c.map_or((0.0, 0.0), |c| {
                (
                    c.lo.get(j).copied().unwrap_or(0.0),
                    c.hi.get(j).copied().unwrap_or(0.0),
                )
            });
            *e = if active { hi < 0.0 } else { lo > 0.0 };
        }
        if node.proofs.is_empty() {
            if let Some(p) = proved.as_deref_mut() {
                p.push(Vec::new());
            }
            continue;
        }
        // the domain: the claims with the path's clamps
        let mut dom = ev.claims.clone();
        let mut at = i;
        while let Some(&Some((p, k, j, active))) = parent.get(at) {
            if let Some(b) = dom.get_mut(k) {
                if active {
                    if let Some(lo) = b.lo.get_mut(j) {
                        *lo = lo.max(0.0);
                    }
                } else if let Some(hi) = b.hi.get_mut(j) {
                    *hi = hi.min(0.0);
                }
            }
            at = p;
        }
        let mut flags = Vec::with_capacity(node.proofs.len());
        for (row, nu) in &node.proofs {
            let ok = rows.get(*row).and_then(Option::as_ref).is_some_and(|r| {
                let o: Vec<f64> = r.d.iter().map(|v| -v).collect();
                let l = lagrangian(chain, hidden, &o, nu, input, &dom);
                r.test.holds(-l)
            });
            if let (true, Some(mine)) = (ok, own_rows.get_mut(i)) {
                mine.push(*row);
            }
            flags.push(ok);
        }
        if let Some(p) = proved.as_deref_mut() {
            p.push(flags);
        }
    }
    // 3. every leaf's path proves every VERIFIED property: a depth-first
    // walk keeping, per row, how many nodes of the path prove it
    let mut count = vec![0usize; rows.len()];
    let mut voids = 0usize;
    // (node, entering)
    let mut stack = vec![(0usize, true)];
    while let Some((i, entering)) = stack.pop() {
        let (Some(node), Some(mine)) = (ev.nodes.get(i), own_rows.get(i)) else {
            continue;
        };
        let void = empty.get(i).copied().unwrap_or(false);
        if entering {
            for r in mine {
                if let Some(c) = count.get_mut(*r) {
                    *c += 1;
                }
            }
            voids += usize::from(void);
            stack.push((i, false));
            match node.split {
                Some((_, _, c0, c1)) => {
                    stack.push((c1, true));
                    stack.push((c0, true));
                }
                None if voids == 0 => {
                    let has = |r: &usize| count.get(*r).is_some_and(|c| *c > 0);
                    for need in needs {
                        let missing = need
                            .all
                            .iter()
                            .find(|r| !has(r))
                            .map(|r| format!("row {r}"))
                            .or_else(|| {
                                need.any
                                    .iter()
                                    .position(|g| !g.iter().any(has))
                                    .map(|g| format!("avoid member {g}"))
                            });
                        if let Some(what) = missing {
                            return Some(format!(
                                "property `{}`: {what} is not proved on the leaf splits.nodes[{i}] nor on its path",
                                ravel_base::text::sanitize(&need.name)
                            ));
                        }
                    }
                }
                None => {}
            }
        } else {
            for r in mine {
                if let Some(c) = count.get_mut(*r) {
                    *c -= 1;
                }
            }
            voids -= usize::from(void);
        }
    }
    None
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    /// `y = relu(x) − relu(−x)·0 + …`: a 1 → 2 → 1 chain.
    fn chain() -> Chain {
        let net = Network::new(
            1,
            vec![
                Layer::Affine {
                    w: DMatrix::from_row_slice(2, 1, &[1.0, -1.0]),
                    b: DVector::from_column_slice(&[0.0, 0.0]),
                },
                Layer::Act(Activation::Relu),
                Layer::Affine {
                    w: DMatrix::from_row_slice(1, 2, &[1.0, 1.0]),
                    b: DVector::from_column_slice(&[0.0]),
                },
            ],
        );
        Chain::of(&net).unwrap()
    }

    /// `|x|` over `[−1, 2]` is at least 0 and at most 2: the Lagrangian
    /// bounds hold, and a NaN or infinite multiplier proves nothing.
    #[test]
    fn lagrangian_bounds_hold_and_nan_proves_nothing() {
        let c = chain();
        let input = Bx {
            lo: vec![-1.0],
            hi: vec![2.0],
        };
        let dom = vec![Bx {
            lo: vec![-1.0, -2.0],
            hi: vec![2.0, 1.0],
        }];
        // lower bound of y with ν = the slopes of CROWN's lower line 0…1
        let l = lagrangian(&c, 1, &[1.0], &[vec![0.0, 0.0]], &input, &dom);
        assert!(l <= 0.0 && l > -1e-9, "{l}");
        // upper bound of y: −L(−y) ≥ 2, with any ν
        for nu in [vec![-0.6, -0.4], vec![-2.0, 3.0], vec![1e300, -1e300]] {
            let l = lagrangian(&c, 1, &[-1.0], std::slice::from_ref(&nu), &input, &dom);
            assert!(-l >= 2.0, "{nu:?}: {l}");
        }
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let l = lagrangian(&c, 1, &[-1.0], &[vec![bad, 0.5]], &input, &dom);
            assert_eq!(l, f64::NEG_INFINITY);
        }
        // a clamp (the neuron x split inactive): y = relu(−x) ≤ 1 there
        let clamped = vec![Bx {
            lo: vec![-1.0, -2.0],
            hi: vec![0.0, 1.0],
        }];
        let l = lagrangian(&c, 1, &[-1.0], &[vec![0.0, 0.0]], &input, &clamped);
        assert!(-l >= 1.0 && -l < 1.0 + 1e-9, "{l}");
    }

    /// Hostile trees are refused before any evaluation: too many nodes,
    /// too much work, a path longer than the hidden neurons, nonsense.
    #[test]
    fn hostile_trees_are_unreadable() {
        use serde_json::json;
        let c = chain();
        let layers = json!([{ "lo": [-1.0, -2.0], "hi": [2.0, 1.0] }]);
        let nu = json!([[0.0, 0.0]]);
        let ev =
            |nodes: serde_json::Value| json!({ "layers": layers, "neurons": [], "nodes": nodes });
        let ok = ev(json!([{ "split": [0, 0, 1, 2] }, { "proofs": [{ "row": 0, "nu": nu }] }, {}]));
        assert!(Evidence::read(&ok, &c, 1).is_ok());
        let err =
            |v: &serde_json::Value, limits: (usize, u64), want: &str| match Evidence::read_within(
                v, &c, 1, limits,
            ) {
                Err(e) => assert!(e.contains(want), "{e}"),
                Ok(_) => panic!("accepted: {want}"),
            };
        err(&ok, (2, MAX_WORK), "nodes");
        err(&ok, (MAX_NODES, 3), "multiply-adds");
        let deep = ev(json!([
            { "split": [0, 0, 1, 2] }, { "split": [0, 1, 3, 4] }, {},
            { "split": [0, 0, 5, 6] }, {}, {}, {}
        ]));
        err(&deep, (MAX_NODES, MAX_WORK), "deeper");
        err(&ev(json!([])), (MAX_NODES, MAX_WORK), "nodes");
        err(
            &ev(json!([{ "split": [0, 0, 0, 1] }, {}])),
            (MAX_NODES, MAX_WORK),
            "later",
        );
        err(
            &ev(json!([{ "split": [0, 2, 1, 2] }, {}, {}])),
            (MAX_NODES, MAX_WORK),
            "no neuron",
        );
        let short_nu = json!([{ "proofs": [{ "row": 0, "nu": [[0.0]] }] }]);
        err(&ev(short_nu), (MAX_NODES, MAX_WORK), "entries");
        let no_row = json!([{ "proofs": [{ "row": 1, "nu": nu }] }]);
        err(&ev(no_row), (MAX_NODES, MAX_WORK), "no row");
        // a tree larger than the limit, refused before its nodes are read
        let huge = ev(serde_json::Value::Array(vec![
            serde_json::Value::Null;
            1001
        ]));
        err(&huge, (1000, MAX_WORK), "nodes");
        // a neuron bound proved twice: refused (each entry costs work)
        let entry = json!({ "layer": 0, "neuron": 0, "bound": "lo", "nu": [] });
        let with = |neurons: serde_json::Value| json!({ "layers": layers, "neurons": neurons, "nodes": [{}] });
        assert!(Evidence::read(&with(json!([entry])), &c, 1).is_ok());
        err(
            &with(json!([entry, entry])),
            (MAX_NODES, MAX_WORK),
            "second proof",
        );
    }

    /// The checker's re-bounding of a child's later layers keeps every
    /// sampled input of the child inside (its bounds hold), tightens some
    /// bounds, and never loosens one.
    #[test]
    fn rebounded_domains_hold_every_sampled_input() {
        use ravel_base::rng::Rng;
        let mut tightened = 0;
        for seed in 0..8 {
            let mut rng = Rng::new(seed);
            let sizes = [3usize, 10, 8, 6, 2];
            let mut layers = Vec::new();
            for (g, win) in sizes.windows(2).enumerate() {
                if g > 0 {
                    layers.push(Layer::Act(Activation::Relu));
                }
                let s = 1.0 / (win[0] as f64).sqrt();
                layers.push(Layer::Affine {
                    w: DMatrix::from_fn(win[1], win[0], |_, _| rng.normal() * s),
                    b: DVector::from_fn(win[1], |_, _| 0.3 * rng.normal()),
                });
            }
            let net = Network::new(3, layers);
            let c = Chain::of(&net).unwrap();
            let centre: Vec<f64> = (0..3).map(|_| rng.uniform(-1.0, 1.0)).collect();
            let input = Bx {
                lo: centre.iter().map(|v| v - 0.4).collect(),
                hi: centre.iter().map(|v| v + 0.4).collect(),
            };
            let root = derive_claims(&net, &input, &[]).unwrap();
            let Some(j) =
                (0..root[0].lo.len()).find(|&j| root[0].lo[j] < 0.0 && root[0].hi[j] > 0.0)
            else {
                continue;
            };
            for active in [false, true] {
                let mut plain = root.clone();
                if active {
                    plain[0].lo[j] = 0.0;
                } else {
                    plain[0].hi[j] = 0.0;
                }
                let mut re = plain.clone();
                let mut work = 0;
                rebound(&c, &input, &mut re, 1, &mut work);
                assert!(work > 0);
                for (p, r) in plain.iter().zip(&re) {
                    for n in 0..p.lo.len() {
                        assert!(r.lo[n] >= p.lo[n] && r.hi[n] <= p.hi[n]);
                        tightened += usize::from(r.lo[n] > p.lo[n] || r.hi[n] < p.hi[n]);
                    }
                }
                for _ in 0..3000 {
                    let x: Vec<f64> = (0..3)
                        .map(|d| rng.uniform(input.lo[d], input.hi[d]))
                        .collect();
                    // the pre-activations at x
                    let mut h = DVector::from_column_slice(&x);
                    let mut pre = Vec::new();
                    for layer in &net.layers {
                        match layer {
                            Layer::Affine { w, b } => h = w * &h + b,
                            Layer::Act(_) => {
                                pre.push(h.clone());
                                h = h.map(|v| v.max(0.0));
                            }
                        }
                    }
                    let within = |d: &[Bx]| {
                        d.iter().zip(&pre).all(|(b, z)| {
                            z.iter()
                                .enumerate()
                                .all(|(n, &v)| b.lo[n] <= v && v <= b.hi[n])
                        })
                    };
                    if within(&plain) {
                        assert!(within(&re), "seed {seed}: {x:?} left the re-bounded domain");
                    }
                }
            }
        }
        assert!(tightened > 10, "only {tightened} bounds tightened");
    }
}
