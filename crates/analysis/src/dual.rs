//! Lagrangian bounds of a ReLU network over an input box with some neurons'
//! phases fixed: the bounding step of branch and bound on ReLU activations.
//!
//! A network of affine layers `z_k = W_k h_{k−1} + b_k` (`h_{−1} = x`, the
//! input) with `h_k = max(z_k, 0)` between them, and a linear objective
//! `o·z_L` of its output. Over a *domain* (the input box, and bounds
//! `l_k ≤ z_k ≤ u_k` of every pre-activation that hold on it), each ReLU is
//! relaxed to its convex hull: the segment `h = 0` for `u ≤ 0`, the segment
//! `h = z` for `l ≥ 0`, else the triangle with vertices `(l, 0)`, `(0, 0)`,
//! `(u, u)`. A neuron split *inactive* has `u` clamped to `min(u, 0)`, one
//! split *active* `l` clamped to `max(l, 0)`: the split constraint is part
//! of the neuron's own set, so the bound below holds on the sub-domain
//! where the split holds (the part of the input box where `z_k` has that
//! sign), and two children cover their parent.
//!
//! Dualising the equalities `z_k = W_k h_{k−1} + b_k` with multipliers `ν_k`
//! (and `ν_L = o`, which cancels the objective's `z_L`) gives, for **any**
//! `ν`, a lower bound of `o·z_L` over the relaxed problem, hence over the
//! domain (weak duality; Dvijotham et al. 2018, Bunel et al. 2020):
//!
//! ```text
//! L(ν) = Σ_k ν_k·b_k + min_{x∈box} (W_0ᵀν_0)·x
//!      + Σ_{k<L} Σ_j min_{(z,h) ∈ relaxation_kj} (−ν_kj z + (W_{k+1}ᵀν_{k+1})_j h)
//! ```
//!
//! Each inner minimum is over a segment or triangle, so at one of its
//! vertices: every term is computed exactly up to rounding. CROWN's bound
//! is `L` at the multipliers of its back-substitution ([`Dual::crown`]),
//! at least as tight here since each neuron takes its hull, not CROWN's
//! lower line; [`optimise`] then climbs `L` by supergradient ascent (Adam):
//! the supergradient for `ν_k` is `W_k h*_{k−1} + b_k − z*_k` at the
//! minimisers.
//!
//! # Soundness
//! The ascent is plain floating point and trusts nothing: the bound
//! returned is [`certified`]'s, which evaluates `L` at the multipliers found
//! with every rounding accounted for: the products `Wᵀν` carry their
//! error bound `γ·|W|ᵀ|ν|` (any summation order), each vertex value is
//! rounded down term by term, and the sums are [`Acc`]'s lower bounds. A
//! non-finite number anywhere gives `−∞` (no bound). The pre-activation
//! bounds of the root come from [`Relaxation`]'s certified boxes.

use nalgebra::{DMatrix, DVector};

use crate::crown::{Mode, Relaxation};
use crate::sets::IBox;
use ravel_base::nn::{Activation, Layer, Network};
use ravel_base::num::{error_bound, Acc};

/// A network as alternating affine layers and ReLUs (at least one ReLU).
#[derive(Clone, Debug)]
pub struct ReluChain {
    w: Vec<DMatrix<f64>>,
    /// `W_kᵀ`, for the products `W_kᵀ ν_k`.
    wt: Vec<DMatrix<f64>>,
    /// `|W_k|ᵀ`, for their error bounds.
    abs_wt: Vec<DMatrix<f64>>,
    /// Per `W_k`, the largest magnitude of each column (for the cheap
    /// error bound of [`certified_cols`]).
    colmax: Vec<DVector<f64>>,
    /// `W_k` and `W_kᵀ` rounded to `f32`, for the ascent's products.
    w32: Vec<DMatrix<f32>>,
    wt32: Vec<DMatrix<f32>>,
    b: Vec<DVector<f64>>,
}

/// The precision of the ascent's matrix products. The ascent only
/// searches: [`Prec::F32`] halves the cost of its products (single
/// precision multiplies twice the numbers per instruction), and every
/// bound returned is still [`certified`] in `f64` at the multipliers
/// found, so the precision changes how good a bound is, never whether it
/// holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Prec {
    F64,
    F32,
}

/// The ascent's precision. Measured on MNIST-FC 256×4, property 13 at
/// ε = 0.03, 1 500 subproblems on one thread: the whole command took
/// 19.4 s of CPU in `f32` and 23.5 s in `f64` (6.6 s of either is the
/// attacks before and after the search), to margins −0.200 and −0.202.
const ASCENT: Prec = Prec::F32;

/// `net` with ReLUs between every two consecutive affine layers, or
/// `None` when it has another activation than ReLU: affine layers `A`
/// then `B` become `[A; −A]`, a ReLU, and `[B, −B]`, since
/// `z = max(z, 0) − max(−z, 0)` for every `z` (the rewritten network is
/// the same real function, its weights the stored ones up to sign). A
/// normalisation before the first `Gemm`, or a pooling before the last,
/// then leaves a chain [`ReluChain::of`] takes; the pairs' relaxation is
/// exact where `z` keeps its sign on the domain (a normalised pixel), and
/// a pair that changes sign is an unstable neuron like any other.
pub fn alternating(net: &Network) -> Option<Network> {
    let mut out: Vec<Layer> = Vec::with_capacity(net.layers.len());
    for layer in &net.layers {
        match layer {
            Layer::Act(Activation::Relu) => out.push(layer.clone()),
            Layer::Act(_) => return None,
            Layer::Affine { w, b } => {
                let (w, b) = (w.clone(), b.clone());
                match out.pop() {
                    Some(Layer::Affine { w: wa, b: ba }) => {
                        let (r, c) = wa.shape();
                        let mut w2 = DMatrix::zeros(2 * r, c);
                        w2.rows_mut(0, r).copy_from(&wa);
                        w2.rows_mut(r, r).copy_from(&(-&wa));
                        let mut b2 = DVector::zeros(2 * r);
                        b2.rows_mut(0, r).copy_from(&ba);
                        b2.rows_mut(r, r).copy_from(&(-&ba));
                        out.push(Layer::Affine { w: w2, b: b2 });
                        out.push(Layer::Act(Activation::Relu));
                        let mut wn = DMatrix::zeros(w.nrows(), 2 * r);
                        wn.columns_mut(0, r).copy_from(&w);
                        wn.columns_mut(r, r).copy_from(&(-&w));
                        out.push(Layer::Affine { w: wn, b });
                    }
                    Some(prev) => {
                        out.push(prev);
                        out.push(Layer::Affine { w, b });
                    }
                    None => out.push(Layer::Affine { w, b }),
                }
            }
        }
    }
    Some(Network::new(net.inputs, out).with_input_type(net.input_type))
}

impl ReluChain {
    /// `net` as a chain, if it is one (affine, then ReLU and affine
    /// alternating) with finite weights.
    pub fn of(net: &Network) -> Option<ReluChain> {
        let mut w = Vec::new();
        let mut b = Vec::new();
        for (i, layer) in net.layers.iter().enumerate() {
            match (i % 2, layer) {
                (0, Layer::Affine { w: wi, b: bi }) => {
                    if !wi.iter().chain(bi.iter()).all(|v| v.is_finite()) {
                        return None;
                    }
                    w.push(wi.clone());
                    b.push(bi.clone());
                }
                (1, Layer::Act(Activation::Relu)) => {}
                _ => return None,
            }
        }
        if net.layers.len() % 2 == 0 || w.len() < 2 {
            return None;
        }
        let wt: Vec<DMatrix<f64>> = w.iter().map(|m| m.transpose()).collect();
        let abs_wt = w.iter().map(|m| m.transpose().abs()).collect();
        let colmax = w
            .iter()
            .map(|m| DVector::from_iterator(m.ncols(), m.column_iter().map(|c| c.amax())))
            .collect();
        let single = |m: &DMatrix<f64>| m.map(|v| v as f32);
        let w32 = w.iter().map(single).collect();
        let wt32 = wt.iter().map(single).collect();
        Some(ReluChain {
            w,
            wt,
            abs_wt,
            colmax,
            w32,
            wt32,
            b,
        })
    }

    /// `W_k m` (or `W_kᵀ m` when `transposed`) in precision `prec`.
    fn mul(&self, k: usize, transposed: bool, m: &DMatrix<f64>, prec: Prec) -> DMatrix<f64> {
        match (prec, transposed) {
            (Prec::F64, false) => &self.w[k] * m,
            (Prec::F64, true) => &self.wt[k] * m,
            (Prec::F32, t) => {
                let a = if t { &self.wt32[k] } else { &self.w32[k] };
                (a * m.map(|v| v as f32)).map(f64::from)
            }
        }
    }

    /// The number of affine layers (`L + 1`; the hidden layers are one fewer).
    fn depth(&self) -> usize {
        self.w.len()
    }

    /// The chain up to affine layer `k` (its output `z_k`).
    fn prefix(&self, k: usize) -> ReluChain {
        ReluChain {
            w: self.w[..=k].to_vec(),
            wt: self.wt[..=k].to_vec(),
            abs_wt: self.abs_wt[..=k].to_vec(),
            colmax: self.colmax[..=k].to_vec(),
            w32: self.w32[..=k].to_vec(),
            wt32: self.wt32[..=k].to_vec(),
            b: self.b[..=k].to_vec(),
        }
    }

    /// The number of outputs.
    pub fn outputs(&self) -> usize {
        self.w[self.depth() - 1].nrows()
    }
}

/// A neuron's split: the sign its pre-activation is constrained to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// `z ≤ 0`.
    Inactive,
    /// `z ≥ 0`.
    Active,
}

/// Bounds `lo ≤ z_k ≤ hi` of every hidden pre-activation that hold on a
/// domain (the splits made so far are in them as clamps).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Domain {
    /// Per hidden layer, lower bounds.
    pub lo: Vec<Vec<f64>>,
    /// Per hidden layer, upper bounds.
    pub hi: Vec<Vec<f64>>,
}

impl Domain {
    /// The root domain: CROWN's certified pre-activation bounds over `input`
    /// (`None` if any is not finite).
    pub fn root(net: &Network, input: &IBox) -> Option<Domain> {
        let r = Relaxation::new(net, input, Mode::Crown);
        if !r.is_finite() {
            return None;
        }
        let boxes = r.boxes();
        // boxes[i] bounds the value before layer i; layer 2k + 1 is the
        // k-th ReLU, so its input, z_k, is boxes[2k + 1]
        let hidden = (net.layers.len() - 1) / 2;
        let (lo, hi) = (0..hidden)
            .map(|k| (boxes[2 * k + 1].lo.clone(), boxes[2 * k + 1].hi.clone()))
            .unzip();
        Some(Domain { lo, hi })
    }

    /// Whether some bound crossed its other end (`lo > hi`): no input
    /// reaches this domain (its bounds are all valid on it).
    pub fn is_empty(&self) -> bool {
        self.lo
            .iter()
            .zip(&self.hi)
            .any(|(l, h)| l.iter().zip(h).any(|(l, h)| l > h))
    }

    /// Whether neuron `j` of hidden layer `k` is unstable (its sign unknown).
    pub fn unstable(&self, k: usize, j: usize) -> bool {
        self.lo[k][j] < 0.0 && self.hi[k][j] > 0.0
    }

    /// The number of unstable neurons.
    pub fn unstable_count(&self) -> usize {
        (0..self.lo.len())
            .map(|k| {
                (0..self.lo[k].len())
                    .filter(|&j| self.unstable(k, j))
                    .count()
            })
            .sum()
    }

    /// Tighten the bounds of every unstable neuron of the hidden layers
    /// after the first (whose bounds are its exact interval image) by
    /// [`optimise`] on the network up to that layer, for `steps` steps,
    /// layer by layer (each layer's relaxation uses the tightened bounds of
    /// the layers before it). A bound is kept only where it is tighter.
    ///
    /// A layer's neurons go through the ascent in groups of
    /// [`TIGHTEN_GROUP`] (fixed, so the bounds never depend on the thread
    /// count) on `threads` threads. `stop` is asked before each group: once
    /// it says so, the remaining neurons keep their bounds (each bound is
    /// valid on its own, so stopping anywhere is sound). Returns whether
    /// every layer was tightened.
    pub fn tighten(
        &mut self,
        chain: &ReluChain,
        input: &IBox,
        steps: usize,
        threads: usize,
        stop: &(dyn Fn() -> bool + Sync),
    ) -> bool {
        self.tighten_recorded(chain, input, steps, threads, stop, None)
    }

    /// [`Domain::tighten`], pushing onto `record` (when given) the
    /// multipliers of every bound it keeps: a certificate's evidence that
    /// the bound holds (see [`NeuronDual`]).
    pub fn tighten_recorded(
        &mut self,
        chain: &ReluChain,
        input: &IBox,
        steps: usize,
        threads: usize,
        stop: &(dyn Fn() -> bool + Sync),
        mut record: Option<&mut Vec<NeuronDual>>,
    ) -> bool {
        for k in 1..self.lo.len() {
            let open: Vec<usize> = (0..self.lo[k].len())
                .filter(|&j| self.unstable(k, j))
                .collect();
            if open.is_empty() {
                continue;
            }
            let n = self.lo[k].len();
            let sub = chain.prefix(k);
            let dom = Domain {
                lo: self.lo[..k].to_vec(),
                hi: self.hi[..k].to_vec(),
            };
            let groups: Vec<&[usize]> = open.chunks(TIGHTEN_GROUP).collect();
            let parts = crate::pool::available(threads).clamp(1, groups.len());
            let per = groups.len().div_ceil(parts);
            let run = |i: usize| -> Vec<Option<Optimised>> {
                groups
                    .iter()
                    .skip(i * per)
                    .take(per)
                    .map(|g| {
                        if stop() {
                            return None;
                        }
                        let m = g.len();
                        let mut obj = DMatrix::zeros(n, 2 * m);
                        for (c, &j) in g.iter().enumerate() {
                            obj[(j, c)] = 1.0;
                            obj[(j, m + c)] = -1.0;
                        }
                        let start = Slopes::crown(&sub, &dom, 2 * m);
                        Some(optimise(&sub, input, &dom, &obj, start, steps))
                    })
                    .collect()
            };
            let got: Vec<Option<Optimised>> = crate::pool::on_threads(parts, &run)
                .into_iter()
                .flatten()
                .collect();
            let mut whole = true;
            for (g, o) in groups.iter().zip(got) {
                let Some(o) = o else {
                    whole = false;
                    continue;
                };
                let m = g.len();
                for (c, &j) in g.iter().enumerate() {
                    let (lo, hi) = (o.bounds[c], -o.bounds[m + c]);
                    let nu = |col: usize| -> Vec<Vec<f64>> {
                        o.dual
                            .nu
                            .iter()
                            .map(|n| n.column(col).iter().copied().collect())
                            .collect()
                    };
                    if lo.is_finite() && lo > self.lo[k][j] {
                        self.lo[k][j] = lo;
                        if let Some(r) = record.as_deref_mut() {
                            r.push(NeuronDual {
                                layer: k,
                                neuron: j,
                                upper: false,
                                nu: nu(c),
                            });
                        }
                    }
                    if hi.is_finite() && hi < self.hi[k][j] {
                        self.hi[k][j] = hi;
                        if let Some(r) = record.as_deref_mut() {
                            r.push(NeuronDual {
                                layer: k,
                                neuron: j,
                                upper: true,
                                nu: nu(m + c),
                            });
                        }
                    }
                }
            }
            if !whole {
                return false;
            }
        }
        true
    }

    /// The child where neuron `j` of layer `k` has phase `p`.
    pub fn split(&self, k: usize, j: usize, p: Phase) -> Domain {
        let mut d = self.clone();
        match p {
            Phase::Inactive => d.hi[k][j] = d.hi[k][j].min(0.0),
            Phase::Active => d.lo[k][j] = d.lo[k][j].max(0.0),
        }
        d
    }
}

/// The multipliers that proved one tightened bound of [`Domain::tighten`]:
/// `L(ν)` on the network up to hidden layer `layer`, over the domain of
/// the layers before it, with the objective `z_j` (a lower bound) or `−z_j`
/// (minus an upper bound).
#[derive(Clone, Debug)]
pub struct NeuronDual {
    /// The hidden layer.
    pub layer: usize,
    /// The neuron.
    pub neuron: usize,
    /// Whether it bounds `z_j` from above.
    pub upper: bool,
    /// `ν_i` of every hidden layer `i < layer`.
    pub nu: Vec<Vec<f64>>,
}

/// Neurons per ascent in [`Domain::tighten`] (each gives two objective
/// columns, its lower and its upper bound).
pub const TIGHTEN_GROUP: usize = 16;

/// Multipliers `ν_k` of every hidden layer, one column per objective.
#[derive(Clone, Debug)]
pub struct Dual {
    /// Per hidden layer `k`: `n_k × R`.
    pub nu: Vec<DMatrix<f64>>,
}

/// The domain of each objective column: several subproblems' objectives
/// go through one pass side by side (their products are one matrix
/// product each), every column read against its own domain.
/// The bounds are laid out as matrices (neuron × column) once per pass,
/// so the element-wise loops read them in order.
struct Cols {
    /// Per hidden layer, the lower bounds (`n_k × R`).
    lo: Vec<DMatrix<f64>>,
    /// Per hidden layer, the upper bounds.
    hi: Vec<DMatrix<f64>>,
}

impl Cols {
    /// Column `c` read against `doms[owner[c]]`.
    fn new(doms: &[&Domain], owner: &[usize]) -> Cols {
        let hidden = doms.first().map_or(0, |d| d.lo.len());
        let r = owner.len();
        let layer = |k: usize, hi: bool| {
            let n = doms.first().map_or(0, |d| d.lo[k].len());
            let mut m = DMatrix::zeros(n, r);
            for (c, &o) in owner.iter().enumerate() {
                let src = if hi { &doms[o].hi[k] } else { &doms[o].lo[k] };
                m.column_mut(c).copy_from_slice(src);
            }
            m
        };
        Cols {
            lo: (0..hidden).map(|k| layer(k, false)).collect(),
            hi: (0..hidden).map(|k| layer(k, true)).collect(),
        }
    }

    /// The bounds of neuron `j` of hidden layer `k` in column `c`'s domain.
    #[inline]
    fn at(&self, k: usize, j: usize, c: usize) -> (f64, f64) {
        (self.lo[k][(j, c)], self.hi[k][(j, c)])
    }
}

/// The minimum of `a z + g h` over neuron `(l, u)`'s relaxation, and the
/// minimiser `(z, h)`. Floating point (the ascent's; see [`certified`]).
fn vertex_min(a: f64, g: f64, l: f64, u: f64) -> (f64, f64, f64) {
    if u <= 0.0 {
        // h = 0, z in [l, u]
        if a * l <= a * u {
            (a * l, l, 0.0)
        } else {
            (a * u, u, 0.0)
        }
    } else if l >= 0.0 {
        let c = a + g;
        if c * l <= c * u {
            (c * l, l, l)
        } else {
            (c * u, u, u)
        }
    } else {
        let (v1, v3) = (a * l, (a + g) * u);
        if v1 <= 0.0 && v1 <= v3 {
            (v1, l, 0.0)
        } else if v3 <= 0.0 {
            (v3, u, u)
        } else {
            (0.0, 0.0, 0.0)
        }
    }
}

/// The ascent's parameters (as α-β-CROWN's): per hidden layer and
/// objective, the lower-line slope `α ∈ [0, 1]` of each unstable neuron,
/// and a multiplier `β ≥ 0` of each split neuron's sign constraint. The
/// multipliers `ν` follow by back-substitution ([`Slopes::multipliers`]).
#[derive(Clone, Debug)]
pub struct Slopes {
    /// Per hidden layer `k`: `n_k × R`, in `[0, 1]`.
    pub alpha: Vec<DMatrix<f64>>,
    /// Per hidden layer `k`: `n_k × R`, `≥ 0` (used at split neurons).
    pub beta: Vec<DMatrix<f64>>,
}

/// Whether neuron `(l, u)` was split (a bound clamped to exactly 0).
fn split_active(l: f64) -> bool {
    l == 0.0
}
fn split_inactive(u: f64) -> bool {
    u == 0.0
}

impl Slopes {
    /// The slopes of objectives `cols` only (in that order).
    pub fn columns(&self, cols: &[usize]) -> Slopes {
        let pick = |m: &DMatrix<f64>| m.select_columns(cols.iter());
        Slopes {
            alpha: self.alpha.iter().map(pick).collect(),
            beta: self.beta.iter().map(pick).collect(),
        }
    }

    /// Put `part`'s columns (of objectives `cols`, as from
    /// [`Slopes::columns`]) back in place.
    pub fn set_columns(&mut self, cols: &[usize], part: &Slopes) {
        for (into, from) in [(&mut self.alpha, &part.alpha), (&mut self.beta, &part.beta)] {
            for (m, p) in into.iter_mut().zip(from) {
                for (i, &c) in cols.iter().enumerate() {
                    m.set_column(c, &p.column(i));
                }
            }
        }
    }

    /// CROWN's slopes: the lower line `z` or `0`, the larger side; no `β`.
    pub fn crown(chain: &ReluChain, dom: &Domain, r: usize) -> Slopes {
        let hidden = chain.depth() - 1;
        let alpha = (0..hidden)
            .map(|k| {
                let n = dom.lo[k].len();
                DMatrix::from_fn(n, r, |j, _| {
                    if dom.hi[k][j] >= -dom.lo[k][j] {
                        1.0
                    } else {
                        0.0
                    }
                })
            })
            .collect();
        let beta = (0..hidden)
            .map(|k| DMatrix::zeros(dom.lo[k].len(), r))
            .collect();
        Slopes { alpha, beta }
    }

    /// The multipliers of these slopes by back-substitution from `obj`:
    /// `ν_k = D_k(W_{k+1}ᵀ ν_{k+1})` entry by entry (an unstable neuron's
    /// upper-line slope `u/(u − l)` where its coefficient is negative, its
    /// `α` where not; `1` for an active neuron, `0` for an inactive one),
    /// shifted by `β` at split neurons. With the derivatives `∂ν_k/∂g_k`
    /// and the products `g_k = W_{k+1}ᵀ ν_{k+1}` themselves (which
    /// [`evaluate`] and the ascent reuse rather than multiply again).
    fn multipliers(&self, chain: &ReluChain, cols: &Cols, obj: &DMatrix<f64>, prec: Prec) -> Back {
        let hidden = chain.depth() - 1;
        let mut nu: Vec<DMatrix<f64>> = vec![DMatrix::zeros(0, 0); hidden];
        let mut deriv: Vec<DMatrix<f64>> = vec![DMatrix::zeros(0, 0); hidden];
        let mut gs: Vec<DMatrix<f64>> = vec![DMatrix::zeros(0, 0); hidden];
        for k in (0..hidden).rev() {
            let next = if k + 1 == hidden { obj } else { &nu[k + 1] };
            let g = chain.mul(k + 1, true, next, prec);
            let mut v = g.clone();
            let mut d = g.clone();
            for c in 0..g.ncols() {
                for j in 0..g.nrows() {
                    let (l, u) = cols.at(k, j, c);
                    let gj = g[(j, c)];
                    let (slope, shift) = if u <= 0.0 {
                        (
                            0.0,
                            if split_inactive(u) {
                                self.beta[k][(j, c)]
                            } else {
                                0.0
                            },
                        )
                    } else if l >= 0.0 {
                        (
                            1.0,
                            if split_active(l) {
                                -self.beta[k][(j, c)]
                            } else {
                                0.0
                            },
                        )
                    } else if gj < 0.0 {
                        (u / (u - l), 0.0)
                    } else {
                        (self.alpha[k][(j, c)], 0.0)
                    };
                    v[(j, c)] = slope * gj + shift;
                    d[(j, c)] = slope;
                }
            }
            nu[k] = v;
            deriv[k] = d;
            gs[k] = g;
        }
        Back {
            dual: Dual { nu },
            deriv,
            g: gs,
        }
    }
}

/// What [`Slopes::multipliers`] computes: the multipliers, their
/// derivatives `∂ν_k/∂g_k`, and the products `g_k = W_{k+1}ᵀ ν_{k+1}`.
struct Back {
    dual: Dual,
    deriv: Vec<DMatrix<f64>>,
    g: Vec<DMatrix<f64>>,
}

impl Dual {
    /// CROWN's multipliers for the objectives `obj` (`outputs × R`, one
    /// column each).
    pub fn crown(chain: &ReluChain, dom: &Domain, obj: &DMatrix<f64>) -> Dual {
        let owner = vec![0; obj.ncols()];
        let cols = Cols::new(&[dom], &owner);
        Slopes::crown(chain, dom, obj.ncols())
            .multipliers(chain, &cols, obj, Prec::F64)
            .dual
    }
}

/// `L(ν)` per objective in floating point, with a supergradient per
/// hidden layer and the input minimiser per objective (columns), from
/// the multipliers and products of [`Slopes::multipliers`].
fn evaluate(
    chain: &ReluChain,
    input: &IBox,
    cols: &Cols,
    obj: &DMatrix<f64>,
    back: &Back,
    prec: Prec,
) -> (Vec<f64>, Vec<DMatrix<f64>>, DMatrix<f64>) {
    let dual = &back.dual;
    let depth = chain.depth();
    let hidden = depth - 1;
    let r = obj.ncols();
    let nu = |k: usize| if k == hidden { obj } else { &dual.nu[k] };
    let mut value = vec![0.0; r];
    for k in 0..depth {
        let v = nu(k);
        for (c, val) in value.iter_mut().enumerate() {
            *val += v.column(c).dot(&chain.b[k]);
        }
    }
    // the input term
    let d = chain.mul(0, true, nu(0), prec);
    let n0 = input.dim();
    let mut xs = DMatrix::zeros(n0, r);
    for c in 0..r {
        for i in 0..n0 {
            let di = d[(i, c)];
            let x = if di >= 0.0 { input.lo[i] } else { input.hi[i] };
            xs[(i, c)] = x;
            value[c] += di * x;
        }
    }
    // the neurons' terms, with the minimisers
    let mut zs: Vec<DMatrix<f64>> = Vec::with_capacity(hidden);
    let mut hs: Vec<DMatrix<f64>> = Vec::with_capacity(hidden);
    for k in 0..hidden {
        let g = &back.g[k];
        let v = nu(k);
        let n = g.nrows();
        let (mut z, mut h) = (DMatrix::zeros(n, r), DMatrix::zeros(n, r));
        for c in 0..r {
            for j in 0..n {
                let (l, u) = cols.at(k, j, c);
                let (m, zz, hh) = vertex_min(-v[(j, c)], g[(j, c)], l, u);
                value[c] += m;
                z[(j, c)] = zz;
                h[(j, c)] = hh;
            }
        }
        zs.push(z);
        hs.push(h);
    }
    // supergradients: W_k h*_{k−1} + b_k − z*_k
    let mut grads = Vec::with_capacity(hidden);
    for k in 0..hidden {
        let prev = if k == 0 { &xs } else { &hs[k - 1] };
        let mut gk = chain.mul(k, false, prev, prec) - &zs[k];
        for c in 0..r {
            let mut col = gk.column_mut(c);
            col += &chain.b[k];
        }
        grads.push(gk);
    }
    (value, grads, xs)
}

/// How [`certified_cols`] bounds the rounding of `W_kᵀ ν`.
#[derive(Clone, Copy, PartialEq, Eq)]
enum ErrorBound {
    /// From `|W_k|ᵀ|ν|` (a second product).
    Product,
    /// From `max_i |W_ij| · Σ_i |ν_i|` per entry `j` (no second product;
    /// larger by at most the layer's width, on an error of about 10⁻¹⁶ of
    /// the terms: for the many bounds of [`rebound_after`]).
    Norms,
}

/// `W_kᵀ ν` (columns) and a bound on its rounding error per entry.
fn product_with_error(
    chain: &ReluChain,
    k: usize,
    nu: &DMatrix<f64>,
    how: ErrorBound,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let g = &chain.wt[k] * nu;
    let s = match how {
        ErrorBound::Product => &chain.abs_wt[k] * nu.abs(),
        ErrorBound::Norms => {
            // Σ_i |ν_i| per column, then the column maxima of W_k
            let l1: Vec<f64> = nu
                .column_iter()
                .map(|c| c.iter().map(|v| v.abs()).sum())
                .collect();
            // a zero column's products are exactly 0 (and 0·∞ would be
            // NaN); an overflowed sum gives an infinite error: no bound
            DMatrix::from_fn(g.nrows(), g.ncols(), |j, c| {
                let m = chain.colmax[k][j];
                if m == 0.0 {
                    0.0
                } else {
                    m * l1[c]
                }
            })
        }
    };
    let terms = chain.wt[k].ncols();
    let e = s.map(|a| error_bound(terms, a));
    (g, e)
}

/// A certified lower bound of `objective c` over the domain from the
/// multipliers `dual` (see the module's soundness note): `−∞` where any
/// number is not finite.
pub fn certified(
    chain: &ReluChain,
    input: &IBox,
    dom: &Domain,
    obj: &DMatrix<f64>,
    dual: &Dual,
) -> Vec<f64> {
    let owner = vec![0; obj.ncols()];
    let cols = Cols::new(&[dom], &owner);
    certified_cols(chain, input, &cols, obj, dual, ErrorBound::Product)
}

/// [`certified`], each column against its own domain.
fn certified_cols(
    chain: &ReluChain,
    input: &IBox,
    cols: &Cols,
    obj: &DMatrix<f64>,
    dual: &Dual,
    how: ErrorBound,
) -> Vec<f64> {
    let depth = chain.depth();
    let hidden = depth - 1;
    let r = obj.ncols();
    let nu = |k: usize| if k == hidden { obj } else { &dual.nu[k] };
    let finite = |m: &DMatrix<f64>| m.iter().all(|v| v.is_finite());
    if !(0..depth).all(|k| finite(nu(k))) || !input.is_finite() {
        return vec![f64::NEG_INFINITY; r];
    }
    let mut acc = vec![Acc::ZERO; r];
    for k in 0..depth {
        let v = nu(k);
        for (c, a) in acc.iter_mut().enumerate() {
            a.add_products(v.column(c).as_slice(), chain.b[k].as_slice());
        }
    }
    // each term below is a lower bound already (rounded down), added as a
    // term of the sum: Acc bounds the sum's own rounding
    let down = |v: f64| v.next_down();
    let (d, e) = product_with_error(chain, 0, nu(0), how);
    for (c, a) in acc.iter_mut().enumerate() {
        for i in 0..input.dim() {
            let (dl, dh) = (
                down(d[(i, c)] - e[(i, c)]),
                (d[(i, c)] + e[(i, c)]).next_up(),
            );
            let (xl, xh) = (input.lo[i], input.hi[i]);
            let m = down(dl * xl)
                .min(down(dl * xh))
                .min(down(dh * xl))
                .min(down(dh * xh));
            a.add(m);
        }
    }
    for k in 0..hidden {
        let (g, e) = product_with_error(chain, k + 1, nu(k + 1), how);
        let v = nu(k);
        for (c, acc) in acc.iter_mut().enumerate() {
            for j in 0..g.nrows() {
                let a = -v[(j, c)];
                // h ≥ 0 at every vertex: g's lowest value gives the minimum
                let gl = down(g[(j, c)] - e[(j, c)]);
                let (l, u) = cols.at(k, j, c);
                let at = |z: f64, h: f64| {
                    let t = if h == 0.0 { 0.0 } else { down(gl * h) };
                    down(down(a * z) + t)
                };
                let m = if u <= 0.0 {
                    at(l, 0.0).min(at(u, 0.0))
                } else if l >= 0.0 {
                    at(l, l).min(at(u, u))
                } else {
                    at(l, 0.0).min(0.0).min(at(u, u))
                };
                acc.add(m);
            }
        }
    }
    acc.into_iter()
        .map(|a| {
            let v = a.lower();
            if v.is_nan() {
                f64::NEG_INFINITY
            } else {
                v
            }
        })
        .collect()
}

/// Re-bound, after a split at hidden layer `k`, the unstable neurons of the
/// hidden layers after `k` on each domain: `L` at CROWN's multipliers
/// ([`Slopes::crown`], no ascent) for `z_j` and `−z_j`, [`certified`], layer
/// by layer (each layer's relaxation uses the re-bounded layers before
/// it); a bound is kept only where tighter. A split fixes one neuron's
/// relaxation, and the layers after it see a smaller set: this is where a
/// split pays off (VeriNet's and β-CROWN's children re-bound their later
/// layers too). Measured on MNIST-FC 256×4, property 5 at ε = 0.03 with
/// the splits in the first unstable layer: the worst open margin went
/// from −0.196 to proved in 603 subproblems, where without re-bounding it
/// was still −0.18 after 3 000.
///
/// The domains go through one pass per layer together (their columns
/// share the products); the result does not depend on how the caller
/// groups them only if it groups them the same way, so callers use fixed
/// groups. A bound may cross its other end (`lo > hi`): no input reaches
/// that domain ([`Domain::is_empty`]).
pub fn rebound_after(chain: &ReluChain, input: &IBox, doms: &mut [(Domain, usize)]) {
    let hidden = chain.depth() - 1;
    let first = doms.iter().map(|d| d.1 + 1).min().unwrap_or(hidden).max(1);
    for m in first..hidden {
        // per domain, its open neurons of layer m
        let open: Vec<Vec<usize>> = doms
            .iter()
            .map(|(d, k)| {
                if *k >= m || d.is_empty() {
                    Vec::new()
                } else {
                    (0..d.lo[m].len()).filter(|&j| d.unstable(m, j)).collect()
                }
            })
            .collect();
        let r: usize = open.iter().map(|o| 2 * o.len()).sum();
        if r == 0 {
            continue;
        }
        let sub = chain.prefix(m);
        let n = chain.w[m].nrows();
        let prefixes: Vec<Domain> = doms
            .iter()
            .map(|(d, _)| Domain {
                lo: d.lo[..m].to_vec(),
                hi: d.hi[..m].to_vec(),
            })
            .collect();
        let refs: Vec<&Domain> = prefixes.iter().collect();
        let mut owner = Vec::with_capacity(r);
        let mut obj = DMatrix::zeros(n, r);
        let mut alpha: Vec<DMatrix<f64>> = (0..m)
            .map(|i| DMatrix::zeros(chain.w[i].nrows(), r))
            .collect();
        let mut c = 0;
        for (i, o) in open.iter().enumerate() {
            for (sign, &j) in o
                .iter()
                .map(|j| (1.0, j))
                .chain(o.iter().map(|j| (-1.0, j)))
            {
                obj[(j, c)] = sign;
                owner.push(i);
                for (a, (lo, hi)) in alpha
                    .iter_mut()
                    .zip(prefixes[i].lo.iter().zip(&prefixes[i].hi))
                {
                    for (t, (l, u)) in lo.iter().zip(hi).enumerate() {
                        a[(t, c)] = if *u >= -*l { 1.0 } else { 0.0 };
                    }
                }
                c += 1;
            }
        }
        let cols = Cols::new(&refs, &owner);
        let slopes = Slopes {
            beta: alpha.iter().map(|a| DMatrix::zeros(a.nrows(), r)).collect(),
            alpha,
        };
        // (any multipliers give a valid bound: single-precision products
        // find them, the certification is in f64)
        let dual = slopes.multipliers(&sub, &cols, &obj, Prec::F32).dual;
        let bounds = certified_cols(&sub, input, &cols, &obj, &dual, ErrorBound::Norms);
        let mut c = 0;
        for (i, o) in open.iter().enumerate() {
            let w = o.len();
            let d = &mut doms[i].0;
            for (t, &j) in o.iter().enumerate() {
                let (lo, hi) = (bounds[c + t], -bounds[c + w + t]);
                if lo.is_finite() && lo > d.lo[m][j] {
                    d.lo[m][j] = lo;
                }
                if hi.is_finite() && hi < d.hi[m][j] {
                    d.hi[m][j] = hi;
                }
            }
            c += 2 * w;
        }
    }
}

/// What [`optimise`] found per objective: the certified lower bound, the
/// parameters and multipliers that give it, and the input minimising
/// their relaxed objective (where the relaxation expects the worst output:
/// a start for an attack).
#[derive(Clone, Debug)]
pub struct Optimised {
    /// Certified lower bounds, one per objective.
    pub bounds: Vec<f64>,
    /// The parameters of the bounds.
    pub slopes: Slopes,
    /// Their multipliers.
    pub dual: Dual,
    /// Per objective, the input minimising the relaxed objective.
    pub worst_inputs: Vec<Vec<f64>>,
}

/// Climb `L` from `start` for `steps` Adam steps on the slopes (projected
/// to `α ∈ [0, 1]`, `β ≥ 0`) and certify the best multipliers met per
/// objective (see the module documentation).
pub fn optimise(
    chain: &ReluChain,
    input: &IBox,
    dom: &Domain,
    obj: &DMatrix<f64>,
    start: Slopes,
    steps: usize,
) -> Optimised {
    optimise_many(chain, input, vec![(dom, obj.clone(), start)], steps)
        .pop()
        .expect("one job")
}

/// [`optimise`] for several subproblems at once (each its domain, its
/// objectives and its start): their columns go through every product
/// together, which multiplies larger matrices (faster per column), and
/// each column is read against its own domain. Results in order.
pub fn optimise_many(
    chain: &ReluChain,
    input: &IBox,
    jobs: Vec<(&Domain, DMatrix<f64>, Slopes)>,
    steps: usize,
) -> Vec<Optimised> {
    let hidden = chain.depth() - 1;
    let widths: Vec<usize> = jobs.iter().map(|j| j.1.ncols()).collect();
    let r: usize = widths.iter().sum();
    let doms: Vec<&Domain> = jobs.iter().map(|j| j.0).collect();
    let owner: Vec<usize> = widths
        .iter()
        .enumerate()
        .flat_map(|(i, &w)| std::iter::repeat_n(i, w))
        .collect();
    let cols = Cols::new(&doms, &owner);
    let m = chain.outputs();
    let mut obj = DMatrix::zeros(m, r);
    let mut cur = Slopes {
        alpha: (0..hidden)
            .map(|k| DMatrix::zeros(chain.w[k].nrows(), r))
            .collect(),
        beta: (0..hidden)
            .map(|k| DMatrix::zeros(chain.w[k].nrows(), r))
            .collect(),
    };
    let mut at = 0;
    for (_, o, s) in &jobs {
        let w = o.ncols();
        obj.columns_mut(at, w).copy_from(o);
        for k in 0..hidden {
            cur.alpha[k].columns_mut(at, w).copy_from(&s.alpha[k]);
            cur.beta[k].columns_mut(at, w).copy_from(&s.beta[k]);
        }
        at += w;
    }
    let back0 = cur.multipliers(chain, &cols, &obj, ASCENT);
    let (mut best_v, _, mut best_x) = evaluate(chain, input, &cols, &obj, &back0, ASCENT);
    let mut best = cur.clone();
    let (b1, b2, eps) = (0.9, 0.999, 1e-12);
    let zeros =
        |m: &Vec<DMatrix<f64>>| -> Vec<DMatrix<f64>> { m.iter().map(|m| m.map(|_| 0.0)).collect() };
    let (mut ma, mut va) = (zeros(&cur.alpha), zeros(&cur.alpha));
    let (mut mb, mut vb) = (zeros(&cur.beta), zeros(&cur.beta));
    let keep = |best: &mut Slopes,
                cur: &Slopes,
                best_x: &mut DMatrix<f64>,
                xs: &DMatrix<f64>,
                c: usize| {
        for k in 0..hidden {
            best.alpha[k].set_column(c, &cur.alpha[k].column(c));
            best.beta[k].set_column(c, &cur.beta[k].column(c));
        }
        best_x.set_column(c, &xs.column(c));
    };
    for t in 1..=steps {
        let back = cur.multipliers(chain, &cols, &obj, ASCENT);
        let (v, partial, xs) = evaluate(chain, input, &cols, &obj, &back, ASCENT);
        let deriv = &back.deriv;
        for c in 0..r {
            if v[c] > best_v[c] {
                best_v[c] = v[c];
                keep(&mut best, &cur, &mut best_x, &xs, c);
            }
        }
        // total derivatives T_k = ∂L/∂ν_k through the later ν's dependence:
        // T_{k+1} = partial_{k+1} + W_{k+1}(D_k ⊙ T_k)
        let mut total: Vec<DMatrix<f64>> = Vec::with_capacity(hidden);
        for k in 0..hidden {
            let mut tk = partial[k].clone();
            if k > 0 {
                tk += chain.mul(k, false, &deriv[k - 1].component_mul(&total[k - 1]), ASCENT);
            }
            total.push(tk);
        }
        let lr = 0.1 * (1.0 - t as f64 / (steps as f64 + 1.0));
        let (c1, c2) = (1.0 - f64::powi(b1, t as i32), 1.0 - f64::powi(b2, t as i32));
        for k in 0..hidden {
            let g = &back.g[k];
            let n = g.nrows();
            let mut ga = DMatrix::zeros(n, r);
            let mut gb = DMatrix::zeros(n, r);
            for c in 0..r {
                for j in 0..n {
                    let (l, u) = cols.at(k, j, c);
                    let tkj = total[k][(j, c)];
                    if l < 0.0 && u > 0.0 && g[(j, c)] >= 0.0 {
                        ga[(j, c)] = tkj * g[(j, c)];
                    } else if u <= 0.0 && split_inactive(u) {
                        gb[(j, c)] = tkj;
                    } else if l >= 0.0 && split_active(l) {
                        gb[(j, c)] = -tkj;
                    }
                }
            }
            let adam = |m: &mut DMatrix<f64>, v: &mut DMatrix<f64>, g: &DMatrix<f64>| {
                *m = &*m * b1 + g * (1.0 - b1);
                *v = &*v * b2 + g.component_mul(g) * (1.0 - b2);
                m.zip_map(v, |a, b| (a / c1) / ((b / c2).sqrt() + eps))
            };
            let sa = adam(&mut ma[k], &mut va[k], &ga);
            cur.alpha[k] += sa * lr;
            cur.alpha[k].apply(|a| *a = a.clamp(0.0, 1.0));
            let sb = adam(&mut mb[k], &mut vb[k], &gb);
            // β in the units of the coefficients it shifts, per column
            let mut sb = sb;
            for c in 0..r {
                let scale = g.column(c).amax().max(1e-12);
                sb.column_mut(c).scale_mut(lr * 0.5 * scale);
            }
            cur.beta[k] += sb;
            cur.beta[k].apply(|b| *b = b.max(0.0));
        }
    }
    let back = cur.multipliers(chain, &cols, &obj, ASCENT);
    let (last, _, xs) = evaluate(chain, input, &cols, &obj, &back, ASCENT);
    for c in 0..r {
        if last[c] > best_v[c] {
            keep(&mut best, &cur, &mut best_x, &xs, c);
        }
    }
    let dual = best.multipliers(chain, &cols, &obj, Prec::F64).dual;
    let bounds = certified_cols(chain, input, &cols, &obj, &dual, ErrorBound::Product);
    let mut out = Vec::with_capacity(jobs.len());
    let mut at = 0;
    for w in widths {
        let range: Vec<usize> = (at..at + w).collect();
        out.push(Optimised {
            bounds: bounds[at..at + w].to_vec(),
            slopes: best.columns(&range),
            dual: Dual {
                nu: dual
                    .nu
                    .iter()
                    .map(|m| m.columns(at, w).into_owned())
                    .collect(),
            },
            worst_inputs: range
                .iter()
                .map(|&c| best_x.column(c).iter().copied().collect())
                .collect(),
        });
        at += w;
    }
    out
}

/// The share of the best split score a neuron of an earlier layer needs
/// for [`candidates`]' first-layer rule to take its layer.
const FIRST_LAYER_SHARE: f64 = 1e-3;

/// The unstable neurons most worth splitting for objective column `c`
/// under `slopes`, best first, at most `top` of them (with `first_layer`,
/// all from the first hidden layer that has an unstable neuron worth a
/// split, [`FIRST_LAYER_SHARE`]: splitting
/// there lets [`rebound_after`] tighten every later layer; measured on
/// MNIST-FC 256×4, property 5 at ε = 0.03: neither the first-layer rule
/// alone nor re-bounding alone moved the worst margin, both together
/// proved it): the largest
/// `|g|·(−l·u)/(u − l)`, the area a neuron's relaxation adds times the
/// weight its output carries (`g = (W_{k+1}ᵀ ν_{k+1})_j`; BaBSR's score).
#[allow(clippy::too_many_arguments)]
pub fn candidates(
    chain: &ReluChain,
    dom: &Domain,
    obj: &DMatrix<f64>,
    slopes: &Slopes,
    c: usize,
    top: usize,
    first_layer: bool,
) -> Vec<(usize, usize)> {
    let hidden = chain.depth() - 1;
    let one = obj.columns(c, 1).into_owned();
    let owner = [0];
    let cols = Cols::new(&[dom], &owner);
    let back = slopes
        .columns(&[c])
        .multipliers(chain, &cols, &one, Prec::F64);
    let mut scored: Vec<(f64, usize, usize)> = Vec::new();
    for k in 0..hidden {
        let g = &back.g[k];
        for j in 0..g.nrows() {
            if !dom.unstable(k, j) {
                continue;
            }
            let (l, u) = (dom.lo[k][j], dom.hi[k][j]);
            let s = g[j].abs() * (-l * u) / (u - l);
            scored.push((if s.is_finite() { s } else { 0.0 }, k, j));
        }
    }
    if first_layer {
        // only the first layer with a neuron scoring at least
        // [`FIRST_LAYER_SHARE`] of the best score (a neuron whose output
        // weighs nothing, an input the network ignores, is never worth a
        // split): its split re-bounds every later layer ([`rebound_after`])
        let best = scored.iter().map(|s| s.0).fold(0.0, f64::max);
        let floor = best * FIRST_LAYER_SHARE;
        if let Some(k) = scored
            .iter()
            .filter(|s| s.0 > 0.0 && s.0 >= floor)
            .map(|s| s.1)
            .min()
        {
            scored.retain(|s| s.1 == k && s.0 > 0.0 && s.0 >= floor);
        } else {
            // no unstable neuron weighs anything under these multipliers
            // (those left feed nothing, as an ignored input's): the
            // subproblem is a leaf, and its long ascent decides it
            scored.clear();
        }
    }
    // best first; ties by position, so the order is fixed
    scored.sort_by(|a, b| b.0.total_cmp(&a.0).then((a.1, a.2).cmp(&(b.1, b.2))));
    scored.truncate(top);
    scored.into_iter().map(|(_, k, j)| (k, j)).collect()
}

/// The neuron to split next for objective column `c`: of the best `top`
/// [`candidates`], the one whose worse child bounds highest with the
/// parent's slopes re-substituted (one pass per child, no ascent; as
/// filtered smart branching); `None` when no neuron is unstable.
/// `first_layer` as for [`candidates`].
#[allow(clippy::too_many_arguments)]
pub fn branch(
    chain: &ReluChain,
    input: &IBox,
    dom: &Domain,
    obj: &DMatrix<f64>,
    slopes: &Slopes,
    c: usize,
    top: usize,
    first_layer: bool,
) -> Option<(usize, usize)> {
    let list = candidates(chain, dom, obj, slopes, c, top, first_layer);
    if list.len() <= 1 {
        return list.first().copied();
    }
    // every candidate's two children in one pass, a column each against
    // its own domain (the same values as one pass per child)
    let children: Vec<Domain> = list
        .iter()
        .flat_map(|&(k, j)| {
            [
                dom.split(k, j, Phase::Inactive),
                dom.split(k, j, Phase::Active),
            ]
        })
        .collect();
    let doms: Vec<&Domain> = children.iter().collect();
    let owner: Vec<usize> = (0..children.len()).collect();
    let cols = Cols::new(&doms, &owner);
    let r = children.len();
    let objs = DMatrix::from_fn(obj.nrows(), r, |i, _| obj[(i, c)]);
    let start = slopes.columns(&vec![c; r]);
    let back = start.multipliers(chain, &cols, &objs, Prec::F64);
    let (v, _, _) = evaluate(chain, input, &cols, &objs, &back, Prec::F64);
    let mut best: Option<(f64, (usize, usize))> = None;
    for (i, &(k, j)) in list.iter().enumerate() {
        let worse = v[2 * i].min(v[2 * i + 1]);
        if worse.is_finite() && best.is_none_or(|b| worse > b.0) {
            best = Some((worse, (k, j)));
        }
    }
    best.map(|b| b.1).or(list.first().copied())
}

#[cfg(test)]
mod tests;
