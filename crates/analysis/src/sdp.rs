//! Reach-SDP (after Hu et al. 2020): one closed-loop step bounded by a
//! semidefinite program over quadratic constraints, solved by ravel's own
//! Schur-complement interior-point method ([`super::sdp_ipm`]; Clarabel's
//! PSD cone when that stalls), and **re-certified** independently of the
//! solver.
//!
//! # The program
//! With `v = (ξ, h₁, …, h_L, 1)`, where `ξ = (x, v_noise)` is the step's
//! input and `h_k` the post-activations of the ReLU layers (only the
//! neurons the step's pre-activation bounds do not prove stable, and the
//! last hidden layer: stable neurons are substituted, see [`StepSdp`]),
//! every fact used
//! is a quadratic form `vᵀS v ≥ 0` (or `= 0`) that holds on every feasible `v`:
//! the input polytope's rows `rᵢ = gᵢ − Gᵢξ ≥ 0` and their pairwise products
//! `rᵢ rⱼ ≥ 0`; per neuron `h ≥ 0`, `h ≥ z`, `h (h − z) = 0`, and the triangle
//! `u(z − l) ≥ (u − l) h` from pre-activation bounds `[l, u]` (or `h = 0`,
//! `h = z` for stable neurons). For a facet `c`, the objective
//! `f(v) = cᵀ(A x + B u + c₀) + max_w cᵀw` is linear in `v`. If
//! `M = F − d·e eᵀ + Σ μᵢ Sᵢ + Σ λⱼ Eⱼ ⪯ 0` with `μ ≥ 0`, then
//! `f(v) − d ≤ vᵀ M v ≤ 0` on feasible points: `d` bounds the facet. The SDP
//! minimises `d` over the multipliers.
//!
//! # Soundness
//! The solver's answer is only a proposal. ravel rebuilds `M` from the
//! proposed multipliers (negative `μ` clipped to 0) in `f64` with an
//! entrywise error bound `E`, bounds its largest eigenvalue by
//! `λ̂ + ‖E‖_F + 100·N·u·‖M‖_F`, and uses `d + max(0, λ)·R²` with
//! `R² ≥ ‖v‖²` from the layer boxes: valid whatever the solver did. The SDP
//! is set up on a "merged" ReLU network (consecutive affine layers, and the
//! observation map `y = Cᵀx + v`, multiplied out in `f64`); the difference to
//! the exact network is bounded layer by layer (ReLU is 1-Lipschitz) and
//! added to the bound, and so is the rounding of substituting stable
//! neurons. The solver is only a proposer: the Schur-complement method's
//! multipliers are used when it converged; when it stalls Clarabel is
//! asked, and Clarabel statuses other than `Solved`/`AlmostSolved` give no
//! SDP bound: the caller keeps its Reach-LP bound and reports the issue.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettingsBuilder, DefaultSolver, IPSolver, SupportedConeT};
use nalgebra::{DMatrix, DVector, SymmetricEigen};

use super::crown::{Mode, Relaxation};
use super::sdp_ipm::{self, Con, Ipm};
use crate::issue::{Backend, Issue, Status};
use crate::sets::IBox;
use ravel_base::limits::{MAX_CLARABEL_SDP_DIM, MAX_SCHUR_MULTIPLIERS};
use ravel_base::nn::{Activation, Layer, Network};
use ravel_base::num::{gamma, sum_upper, U};

/// A ReLU network in the form `z₁ = W₀ξ + b₀, h_k = ReLU(z_k), z_{k+1} = W_k h_k + b_k`,
/// output `W_L h_L + b_L`, with a bound on how far its output may be from the
/// exact network's.
#[derive(Clone, Debug)]
pub struct MergedNet {
    /// `(W_k, b_k)` for k = 0 … L.
    pub layers: Vec<(DMatrix<f64>, DVector<f64>)>,
    /// `|u_exact − u_merged| ≤ err` per output, for inputs in the box it was built for.
    pub err: Vec<f64>,
    /// The merged network as a [`Network`] (for its layer bounds).
    pub net: Network,
}

/// Whether every activation of `net` is a ReLU (the only nonlinearity Reach-SDP encodes).
pub fn supports(net: &Network) -> bool {
    net.layers
        .iter()
        .all(|l| matches!(l, Layer::Affine { .. } | Layer::Act(Activation::Relu)))
}

/// Merge `net ∘ pre` (with `pre` the affine input map) into [`MergedNet`];
/// `input` bounds the input of `pre`. `None` for a non-ReLU network.
pub fn merge(net: &Network, pre: &DMatrix<f64>, input: &IBox) -> Option<MergedNet> {
    if !supports(net) {
        return None;
    }
    let mut layers = Vec::new();
    let mut w = pre.clone();
    let mut b = DVector::<f64>::zeros(pre.nrows());
    // error of the current composed value (vs exact) and magnitude of the block input
    let mut err = vec![0.0; pre.nrows()];
    let mut mag = input.abs_max();
    let mut cur_box = input.clone();
    for layer in &net.layers {
        match layer {
            Layer::Affine { w: wl, b: bl } => {
                // value before this layer is within `err` of exact and within |W||mag|+|b| in size
                let size: Vec<f64> = (0..w.nrows())
                    .map(|r| {
                        sum_upper(
                            (0..w.ncols())
                                .map(|c| w[(r, c)].abs() * mag[c])
                                .chain([b[r].abs(), err[r]]),
                        )
                    })
                    .collect();
                let k = gamma(wl.ncols() + 2);
                let new_w = wl * &w;
                let new_b = wl * &b + bl;
                let new_err: Vec<f64> = (0..wl.nrows())
                    .map(|r| {
                        let prop = sum_upper((0..wl.ncols()).map(|c| wl[(r, c)].abs() * err[c]));
                        let round = sum_upper(
                            (0..wl.ncols())
                                .map(|c| wl[(r, c)].abs() * size[c])
                                .chain([bl[r].abs()]),
                        );
                        sum_upper([prop, (k * round * 1.0625 + 1e-300).next_up()])
                    })
                    .collect();
                w = new_w;
                b = new_b;
                err = new_err;
            }
            Layer::Act(_) => {
                layers.push((w.clone(), b.clone()));
                // post-activation magnitudes: ReLU of the composed value's box
                let z = crate::crown::affine_image(&w, &b, &cur_box);
                let h_box = IBox::new(
                    z.lo.iter().map(|l| l.max(0.0)).collect(),
                    z.hi.iter()
                        .zip(&err)
                        .map(|(h, e)| sum_upper([h.max(0.0), *e]))
                        .collect(),
                );
                mag = h_box.abs_max();
                cur_box = h_box;
                // ReLU is 1-Lipschitz: the post-activation error is the pre-activation one
                w = DMatrix::identity(mag.len(), mag.len());
                b = DVector::zeros(mag.len());
            }
        }
    }
    layers.push((w, b));
    let mut net_layers = Vec::new();
    for (i, (w, b)) in layers.iter().enumerate() {
        net_layers.push(Layer::Affine {
            w: w.clone(),
            b: b.clone(),
        });
        if i + 1 < layers.len() {
            net_layers.push(Layer::Act(Activation::Relu));
        }
    }
    let merged = Network::new(pre.ncols(), net_layers);
    Some(MergedNet {
        layers,
        err,
        net: merged,
    })
}

/// A sparse symmetric quadratic form, accumulated as triplets `(i, j, value)` with `i ≤ j`.
#[derive(Default)]
struct Form {
    entries: Vec<(usize, usize, f64)>,
}

impl Form {
    /// `+ coef · sym(α βᵀ)` for sparse vectors α, β.
    fn outer(&mut self, coef: f64, a: &[(usize, f64)], b: &[(usize, f64)]) {
        for &(i, x) in a {
            for &(j, y) in b {
                // a stored (i, j) with i < j stands for both S_ij and S_ji
                let v = if i == j {
                    coef * x * y
                } else {
                    0.5 * coef * x * y
                };
                if v != 0.0 {
                    self.entries.push((i.min(j), i.max(j), v));
                }
            }
        }
    }
}

/// Position of `(i, j)`, `i ≤ j`, in the upper-triangle column-major vector.
fn tri(i: usize, j: usize) -> usize {
    j * (j + 1) / 2 + i
}

/// Which solver proposes the multipliers [`StepSdp::bound_using`] re-certifies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Solver {
    /// The Schur-complement interior-point method ([`super::sdp_ipm`]),
    /// and Clarabel when it stalls: what ravel uses.
    Auto,
    /// Only the Schur-complement method (a stall is an issue): for tests.
    Schur,
    /// Only Clarabel (the reference the fast path is compared with).
    Clarabel,
}

/// A neuron of the last hidden layer, as the SDP sees it.
#[derive(Clone, Debug)]
enum LastNeuron {
    /// A coordinate of v (its index).
    Kept(usize),
    /// Stable: `h = formᵀv` in the folded network (a zero form when
    /// inactive), within `err` of the merged network's value, at most `max`
    /// in magnitude.
    Affine {
        form: Vec<(usize, f64)>,
        err: f64,
        max: f64,
    },
}

/// What one facet bound came to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SdpBound {
    /// A certified upper bound of the facet (`+∞` when there is none).
    pub value: f64,
    /// The solver status when it was not trusted.
    pub issue: Option<Issue>,
}

/// A neuron the SDP keeps as a coordinate of `v`.
struct Kept {
    /// Its coordinate in `v`.
    h: usize,
    /// Its pre-activation as a sparse affine form over `v` (the constant on
    /// the last coordinate).
    z: Vec<(usize, f64)>,
    /// Bounds of that form on the step's input set.
    l: f64,
    u: f64,
}

/// The data of one step's SDPs, shared by all facets.
///
/// # Stable neurons are not variables
/// A neuron whose pre-activation bounds (of the merged network, on the
/// step's input box) prove it inactive (`u ≤ 0`) outputs 0 there, and an
/// active one (`l ≥ 0`) outputs its pre-activation: both are affine in the
/// layer's input, so they are substituted into the next layer instead of
/// becoming coordinates of `v`. In the last hidden layer, over which callers
/// write the objective, a stable neuron is an affine form over `v` that
/// [`StepSdp::bound`] substitutes into the objective (callers still give
/// a coefficient for every neuron of that layer). `v = (ξ, kept neurons, 1)`
/// and every kept neuron's pre-activation is an affine form over the
/// coordinates before it. On the quadrotor every neuron of a step can be
/// stable: `v` then has 1 + 12 coordinates instead of 83. Substituting
/// matters beyond size: a stable neuron kept as a coordinate is pinned by
/// two opposite inequalities (`h ≥ 0` and `−h ≥ 0`), so no moment matrix
/// is strictly feasible, and interior-point methods then stall or diverge.
/// Likewise a coordinate of ξ that its box pins to a point (noise that is
/// exactly zero) is a constant, not a coordinate of `v`: its rows' terms
/// move to the right-hand side (rounded up) and `φ`'s coefficient on it to
/// a constant of the bound.
///
/// The forms are computed in `f64`; the network they define (the "folded"
/// one: stable neurons substituted, kept ones `relu` of their form) differs
/// from the merged network by at most `err[i]` at each coordinate `i`
/// (rounding of the substituted coefficients, carried through every later
/// layer; ReLU is 1-Lipschitz). The SDP's facts are facts of the folded
/// network (its pre-activation bounds are the merged ones widened by that
/// error), and [`StepSdp::bound`] adds `Σ |φᵢ|·err[i]`, so the bound holds
/// for the merged network's values, exactly as before.
pub struct StepSdp {
    /// Input rows `G ξ ≤ g` over the free coordinates of ξ (the extra rows,
    /// then ξ's box).
    rows: Vec<(Vec<f64>, f64)>,
    /// The kept neurons, layer by layer.
    kept: Vec<Kept>,
    /// Each coordinate of ξ: its coordinate in v, or its value when ξ's box
    /// pins it to a point (a noise input that is exactly known, say): such
    /// a coordinate is a constant, not a variable.
    xi_at: Vec<Result<usize, f64>>,
    /// The last hidden layer's neurons: coordinates of v, or (when their
    /// bounds prove them stable) affine forms over v.
    last: Vec<LastNeuron>,
    /// Kept neurons before the last hidden layer.
    kept_before_last: usize,
    /// `|vᵢ|` bounds (the folded network's values).
    vmax: Vec<f64>,
    /// `|vᵢ(folded) − vᵢ(merged)|` bounds.
    err: Vec<f64>,
    /// Dimension of v.
    dim: usize,
    /// `R² ≥ ‖v‖²`.
    radius2: f64,
}

impl StepSdp {
    /// Prepare the SDPs of one step: `xi` bounds ξ, `rows` are extra input rows on ξ.
    pub fn new(net: &MergedNet, xi: &IBox, rows: &[(Vec<f64>, f64)]) -> StepSdp {
        let d0 = xi.dim();
        let relaxation = Relaxation::new(&net.net, xi, Mode::Crown);
        let boxes = relaxation_boxes(&relaxation);
        let folded = Folded::of(net, xi, &boxes);
        let used = folded.used;
        // v = (free coordinates of ξ, kept neurons, 1)
        let (xi_at, free) = xi_coordinates(xi);
        let dim = free + (used - 1 - d0) + 1;
        let one = dim - 1;
        // slots of pinned coordinates never occur in a form
        let index = |s: usize| match s {
            0 => one,
            s if s <= d0 => xi_at[s - 1].unwrap_or(one),
            s => free + (s - 1 - d0),
        };
        // a dense form over slots as a sparse one over v
        let sparse = |f: &[f64]| -> Vec<(usize, f64)> {
            (0..used)
                .filter(|&s| f[s] != 0.0)
                .map(|s| (index(s), f[s]))
                .collect()
        };
        let mut vmax = vec![0.0; dim];
        let mut err = vec![0.0; dim];
        vmax[one] = 1.0;
        for s in (1..used).filter(|&s| s > d0 || xi_at[s - 1].is_ok()) {
            vmax[index(s)] = folded.smax[s];
        }
        let kept: Vec<Kept> = folded
            .kept
            .into_iter()
            .map(|(slot, f, l, u, e)| {
                err[index(slot)] = e;
                Kept {
                    h: index(slot),
                    z: sparse(&f),
                    l,
                    u,
                }
            })
            .collect();
        let radius2 = sum_upper(vmax.iter().map(|m| m * m));
        // (no hidden layer: an affine network, nothing in the last layer)
        let last = folded
            .last
            .into_iter()
            .map(|s| match s {
                Ok(slot) => LastNeuron::Kept(index(slot)),
                Err((f, err, max)) => LastNeuron::Affine {
                    form: sparse(&f),
                    err,
                    max,
                },
            })
            .collect();
        StepSdp {
            rows: free_rows(rows, xi, &xi_at, free),
            kept,
            xi_at,
            last,
            kept_before_last: folded.kept_before_last,
            vmax,
            err,
            dim,
            radius2: radius2 * (1.0 + 1e-12),
        }
    }

    /// The constraints as rank-two forms `coef·sym(α βᵀ)` over distinct
    /// sparse vectors (the unit vector of the constant is vector 0), each
    /// with whether its multiplier is nonnegative (else it is an equality's).
    fn constraints(&self) -> (Vec<Vec<(usize, f64)>>, Vec<Con>) {
        let one = self.dim - 1;
        let mut vecs: Vec<Vec<(usize, f64)>> = vec![vec![(one, 1.0)]];
        let mut cons = Vec::new();
        let add = |vecs: &mut Vec<Vec<(usize, f64)>>, v: Vec<(usize, f64)>| {
            vecs.push(v);
            vecs.len() - 1
        };
        let con = |coef: f64, a: usize, b: usize, nonneg: bool| Con { coef, a, b, nonneg };
        // input rows r_i = g_i − G_i ξ as sparse vectors over v: r_i ≥ 0, r_i r_j ≥ 0
        let r: Vec<usize> = self
            .rows
            .iter()
            .map(|(a, g)| {
                let mut v: Vec<(usize, f64)> = a
                    .iter()
                    .enumerate()
                    .filter(|(_, x)| **x != 0.0)
                    .map(|(i, x)| (i, -x))
                    .collect();
                v.push((one, *g));
                add(&mut vecs, v)
            })
            .collect();
        for (i, &ri) in r.iter().enumerate() {
            cons.push(con(1.0, ri, 0, true));
            for &rj in r.iter().skip(i + 1) {
                cons.push(con(1.0, ri, rj, true));
            }
        }
        // kept neurons
        for n in &self.kept {
            let z = &n.z;
            let h = add(&mut vecs, vec![(n.h, 1.0)]);
            let mut h_minus_z: Vec<(usize, f64)> = z.iter().map(|(i, x)| (*i, -x)).collect();
            h_minus_z.push((n.h, 1.0));
            let hz = add(&mut vecs, h_minus_z);
            let (l, u) = (n.l, n.u);
            cons.push(con(1.0, h, 0, true));
            cons.push(con(1.0, hz, 0, true));
            cons.push(con(1.0, h, hz, false));
            if u <= 0.0 {
                cons.push(con(-1.0, h, 0, true));
            } else if l >= 0.0 {
                cons.push(con(-1.0, hz, 0, true));
            } else if u.is_finite() && l.is_finite() {
                // u (z − l) − (u − l) h ≥ 0
                let mut t: Vec<(usize, f64)> = z.iter().map(|(i, x)| (*i, u * x)).collect();
                t.push((one, -u * l));
                t.push((n.h, -(u - l)));
                let t = add(&mut vecs, t);
                cons.push(con(1.0, t, 0, true));
            }
        }
        (vecs, cons)
    }

    /// A certified upper bound of `φᵀv`, with `φ` over the coordinates of
    /// [`StepSdp::dim`]: ξ, then the kept neurons before the last hidden
    /// layer, every neuron of that layer ([`StepSdp::last_hidden`] is where
    /// it starts), the constant last. The substitution of the last layer's
    /// stable neurons into `φ` is paid for: `|φ_k|·err_k` per neuron and the
    /// rounding of the substituted coefficients times the coordinates'
    /// magnitudes.
    pub fn bound(&self, phi_full: &[f64]) -> SdpBound {
        self.bound_using(phi_full, Solver::Auto)
    }

    /// [`StepSdp::bound`] with the multipliers proposed by `solver` (the
    /// re-certification is the same for all).
    pub fn bound_using(&self, phi_full: &[f64], solver: Solver) -> SdpBound {
        let (phi, pinned) = self.objective(phi_full);
        let phi = &phi[..];
        let n = self.dim;
        let one = n - 1;
        let (vecs, rank2) = self.constraints();
        let cons: Vec<(Form, bool)> = rank2
            .iter()
            .map(|c| {
                let mut f = Form::default();
                f.outer(c.coef, &vecs[c.a], &vecs[c.b]);
                (f, c.nonneg)
            })
            .collect();
        // objective form F = sym(φ eᵀ)
        let phi_sparse: Vec<(usize, f64)> = phi
            .iter()
            .enumerate()
            .filter(|(_, x)| **x != 0.0)
            .map(|(i, x)| (i, *x))
            .collect();
        let mut fobj = Form::default();
        fobj.outer(1.0, &phi_sparse, &[(one, 1.0)]);
        let x = match multipliers(n, &fobj, vecs, &rank2, &cons, solver) {
            Ok(x) => x,
            Err(issue) => return none(issue),
        };
        let lam_bound = match max_eigenvalue_bound(n, &fobj, &cons, &x) {
            Ok(lam) => lam,
            Err(issue) => return none(issue),
        };
        let d = x[0];
        // the folded network's values differ from the merged one's by `err`
        let folding = sum_upper(phi.iter().zip(&self.err).map(|(p, e)| p.abs() * e));
        let value = sum_upper([
            d,
            lam_bound.max(0.0) * self.radius2 * (1.0 + 1e-12),
            folding,
            pinned,
        ]);
        SdpBound { value, issue: None }
    }

    /// `φ` on `v` from `φ` over [`StepSdp::dim`]'s coordinates, and the
    /// constant it adds to the bound: pinned coordinates of ξ move into
    /// that constant, and a stable neuron of the last hidden layer puts its
    /// coefficient onto its form's coordinates (`|φ|·err` for the form's
    /// error, and the rounding of these sums, are added to the constant).
    fn objective(&self, phi_full: &[f64]) -> (Vec<f64>, f64) {
        let mut phi = vec![0.0; self.dim];
        let mut pinned = Vec::new();
        for (i, at) in self.xi_at.iter().enumerate() {
            match at {
                Ok(j) => phi[*j] = phi_full[i],
                Err(c) => pinned.push(phi_full[i] * c),
            }
        }
        let (d0, free, kb) = (self.input_dim(), self.free(), self.kept_before_last);
        phi[free..free + kb].copy_from_slice(&phi_full[d0..d0 + kb]);
        let one = self.dim - 1;
        phi[one] = phi_full[d0 + kb + self.last.len()];
        let mut phi_abs: Vec<f64> = phi.iter().map(|x| x.abs()).collect();
        let mut substituted = Vec::new();
        for (k, neuron) in self.last.iter().enumerate() {
            let p = phi_full[d0 + kb + k];
            match neuron {
                LastNeuron::Kept(i) => {
                    phi[*i] += p;
                    phi_abs[*i] += p.abs();
                }
                LastNeuron::Affine { form, err, .. } => {
                    for &(i, x) in form {
                        phi[i] += p * x;
                        phi_abs[i] += (p * x).abs();
                    }
                    substituted.push(p.abs() * err);
                }
            }
        }
        let g = gamma(self.last.len() + 2);
        let phi_round = sum_upper(
            phi_abs
                .iter()
                .zip(&self.vmax)
                .map(|(a, m)| (g * a * m * 1.0625).next_up()),
        );
        let pinned = sum_upper(pinned.into_iter().chain(substituted).chain([phi_round]));
        (phi, pinned)
    }

    /// Dimension of ξ.
    pub fn input_dim(&self) -> usize {
        self.xi_at.len()
    }

    /// Largest magnitude of each neuron of the last hidden layer.
    pub fn last_hidden_max(&self) -> Vec<f64> {
        self.last
            .iter()
            .map(|n| match n {
                LastNeuron::Kept(i) => self.vmax[*i],
                LastNeuron::Affine { max, .. } => *max,
            })
            .collect()
    }

    /// Where the last hidden layer starts among φ's coordinates (all its
    /// neurons have one, kept or substituted).
    pub fn last_hidden(&self) -> usize {
        self.input_dim() + self.kept_before_last
    }

    /// The free coordinates of ξ (the ones not pinned to a point).
    fn free(&self) -> usize {
        self.xi_at.iter().filter(|a| a.is_ok()).count()
    }

    /// How many coordinates `v` has beyond ξ and the constant: the neurons
    /// the SDP could not substitute away.
    pub fn kept_neurons(&self) -> usize {
        self.kept.len()
    }

    /// Number of φ's coordinates ([`StepSdp::bound`]): ξ, the kept
    /// neurons before the last hidden layer, every neuron of the last
    /// hidden layer, the constant.
    pub fn dim(&self) -> usize {
        self.input_dim() + self.kept_before_last + self.last.len() + 1
    }
}

/// A stable neuron of the last hidden layer: its form (dense over
/// slots), its error and its magnitude.
type Stable = (Vec<f64>, f64, f64);

/// The folded network of a step over "slots": 0 the constant, `1..=d0`
/// the coordinates of ξ, then the kept neurons in order (see [`StepSdp`]).
struct Folded {
    /// How many slots are used.
    used: usize,
    /// A bound of `|·|` of each slot's value.
    smax: Vec<f64>,
    /// The kept neurons: slot, pre-activation form (dense over slots),
    /// bounds of the form (the merged ones widened by its error), error.
    kept: Vec<(usize, Vec<f64>, f64, f64, f64)>,
    /// The last hidden layer: kept slots, or stable forms.
    last: Vec<Result<usize, Stable>>,
    /// Kept neurons before the last hidden layer.
    kept_before_last: usize,
}

impl Folded {
    /// Fold the hidden layers of `net` over the box `xi`, with `boxes` the
    /// merged network's layer bounds there: a stable neuron substituted
    /// into the next layer, an unstable one kept as a slot.
    fn of(net: &MergedNet, xi: &IBox, boxes: &[IBox]) -> Folded {
        let d0 = xi.dim();
        let hidden = net.layers.len() - 1;
        let total: usize = net.layers[..hidden].iter().map(|(w, _)| w.nrows()).sum();
        let slots = 1 + d0 + total;
        let mut smax = vec![0.0; slots];
        smax[0] = 1.0;
        smax[1..=d0].copy_from_slice(&xi.abs_max());
        let mut used = 1 + d0;
        // the current layer's outputs: (dense form over slots, error vs
        // merged); a coordinate of ξ pinned to a point is that constant
        let mut prev: Vec<(Vec<f64>, f64)> = (0..d0)
            .map(|i| {
                let mut f = vec![0.0; slots];
                if xi.lo[i] == xi.hi[i] {
                    f[0] = xi.lo[i];
                } else {
                    f[1 + i] = 1.0;
                }
                (f, 0.0)
            })
            .collect();
        let mut kept = Vec::new();
        let mut last = Vec::new();
        let mut kept_before_last = 0;
        for (k, (w, b)) in net.layers[..hidden].iter().enumerate() {
            let z_box = &boxes[2 * k + 1];
            let is_last = k + 1 == hidden;
            if is_last {
                kept_before_last = kept.len();
            }
            let gam = gamma(w.ncols() + 2);
            let mut next = Vec::with_capacity(w.nrows());
            for j in 0..w.nrows() {
                let (f, err_z) = neuron_form(w, b, j, &prev, used, &smax, gam);
                let (l, u) = (z_box.lo[j], z_box.hi[j]);
                if is_last && u <= 0.0 {
                    last.push(Err((vec![0.0; slots], 0.0, 0.0)));
                } else if is_last && l >= 0.0 {
                    let max = (u + err_z).next_up();
                    last.push(Err((f, err_z, max)));
                } else if u <= 0.0 {
                    next.push((vec![0.0; slots], 0.0));
                } else if l >= 0.0 {
                    next.push((f, err_z));
                } else {
                    let (lw, uw) = ((l - err_z).next_down(), (u + err_z).next_up());
                    let slot = used;
                    used += 1;
                    smax[slot] = uw.max(0.0);
                    kept.push((slot, f, lw, uw, err_z));
                    if is_last {
                        last.push(Ok(slot));
                    }
                    let mut unit = vec![0.0; slots];
                    unit[slot] = 1.0;
                    next.push((unit, err_z));
                }
            }
            prev = next;
        }
        Folded {
            used,
            smax,
            kept,
            last,
            kept_before_last,
        }
    }
}

/// Neuron `j`'s pre-activation `W_j·prev + b_j` as a form dense over the
/// slots (`prev` the previous layer's forms and errors, over the first
/// `used` slots, whose values are at most `smax`), and its error against
/// the merged network: the previous errors through `|W_j|` and the
/// rounding of the form (`gam` = `γ(columns + 2)`).
#[inline]
fn neuron_form(
    w: &DMatrix<f64>,
    b: &DVector<f64>,
    j: usize,
    prev: &[(Vec<f64>, f64)],
    used: usize,
    smax: &[f64],
    gam: f64,
) -> (Vec<f64>, f64) {
    let slots = smax.len();
    let mut f = vec![0.0; slots];
    let mut fabs = vec![0.0; slots];
    f[0] = b[j];
    fabs[0] = b[j].abs();
    let mut prop = Vec::with_capacity(w.ncols());
    for (c, (pf, pe)) in prev.iter().enumerate() {
        let wc = w[(j, c)];
        if wc == 0.0 {
            continue;
        }
        for s in 0..used {
            if pf[s] != 0.0 {
                f[s] += wc * pf[s];
                fabs[s] += (wc * pf[s]).abs();
            }
        }
        prop.push(wc.abs() * pe);
    }
    // |computed form − exact composition| · |v| over the box
    let size = sum_upper((0..used).map(|s| fabs[s] * smax[s]));
    let round = (gam * size * 1.0625 + 1e-300).next_up();
    let err_z = sum_upper(prop.into_iter().chain([round]));
    (f, err_z)
}

/// Where each coordinate of the box `xi` goes in `v`: its index among the
/// free coordinates, or its value when the box pins it to a point; and
/// how many are free.
fn xi_coordinates(xi: &IBox) -> (Vec<Result<usize, f64>>, usize) {
    let d0 = xi.dim();
    let mut xi_at = Vec::with_capacity(d0);
    let mut free = 0;
    for i in 0..d0 {
        if xi.lo[i] == xi.hi[i] {
            xi_at.push(Err(xi.lo[i]));
        } else {
            xi_at.push(Ok(free));
            free += 1;
        }
    }
    (xi_at, free)
}

/// The input rows over the `free` coordinates of ξ (`xi_at` says where
/// each goes): the extra `rows`, a pinned coordinate's term moved to the
/// right-hand side, rounded up (the row stays valid); then the box's rows
/// of each free coordinate.
fn free_rows(
    rows: &[(Vec<f64>, f64)],
    xi: &IBox,
    xi_at: &[Result<usize, f64>],
    free: usize,
) -> Vec<(Vec<f64>, f64)> {
    let mut all_rows: Vec<(Vec<f64>, f64)> = rows
        .iter()
        .map(|(a, g)| {
            let mut a_free = vec![0.0; free];
            let mut rhs = vec![*g];
            for (&ai, at) in a.iter().zip(xi_at) {
                match at {
                    Ok(j) => a_free[*j] = ai,
                    Err(c) => rhs.push(-(ai * c)),
                }
            }
            (a_free, sum_upper(rhs))
        })
        .collect();
    for (i, at) in xi_at.iter().enumerate() {
        if let Ok(j) = at {
            let mut e = vec![0.0; free];
            e[*j] = 1.0;
            all_rows.push((e.clone(), xi.hi[i]));
            e[*j] = -1.0;
            all_rows.push((e, -xi.lo[i]));
        }
    }
    all_rows
}

/// The multipliers `x = (d, …)` that `solver` proposes for the program of
/// [`StepSdp::bound`] (objective form `fobj` over `n` coordinates, the
/// constraints `rank2` over `vecs`, and as forms `cons`); finite.
fn multipliers(
    n: usize,
    fobj: &Form,
    vecs: Vec<Vec<(usize, f64)>>,
    rank2: &[Con],
    cons: &[(Form, bool)],
    solver: Solver,
) -> Result<Vec<f64>, Issue> {
    // the Schur-complement interior-point method where it is the cheaper
    // one (or the only one: Clarabel's PSD block outgrows memory beyond
    // MAX_CLARABEL_SDP_DIM); Clarabel otherwise, and when it stalls
    let m = rank2.len() + 1;
    let clarabel_fits = n <= MAX_CLARABEL_SDP_DIM;
    let use_schur = match solver {
        Solver::Schur => true,
        Solver::Clarabel => false,
        Solver::Auto => schur_pays(m, n) || !clarabel_fits,
    };
    let tried_schur = use_schur && m <= MAX_SCHUR_MULTIPLIERS;
    let schur = if tried_schur {
        propose(n, fobj, vecs, rank2)
    } else {
        None
    };
    let may_clarabel = clarabel_fits && solver != Solver::Schur;
    let x = match schur {
        Some(y) => y,
        None if may_clarabel => clarabel_solve(n, fobj, cons)?,
        None if tried_schur => {
            return Err(Issue::Status(Backend::Sdp, Status::InsufficientProgress))
        }
        None => return Err(Issue::SdpTooLarge),
    };
    // whichever solver proposed it, a non-finite multiplier is no proposal
    if x.iter().any(|v| !v.is_finite()) {
        return Err(Issue::NonFiniteSolution);
    }
    Ok(x)
}

/// The re-certification of the multipliers `x`: a certified upper bound
/// of the largest eigenvalue of `M = F − d eeᵀ + Σ μ S + Σ λ E` (`F` =
/// `fobj`, the forms `cons`, `d = x[0]`, negative `μ` clipped to 0), built
/// in `f64` with `|·|` accounting.
fn max_eigenvalue_bound(
    n: usize,
    fobj: &Form,
    cons: &[(Form, bool)],
    x: &[f64],
) -> Result<f64, Issue> {
    let one = n - 1;
    let d = x[0];
    let mut m = DMatrix::<f64>::zeros(n, n);
    let mut mabs = DMatrix::<f64>::zeros(n, n);
    let mut terms = 0usize;
    let add = |m: &mut DMatrix<f64>, mabs: &mut DMatrix<f64>, i: usize, j: usize, v: f64| {
        m[(i, j)] += v;
        mabs[(i, j)] += v.abs();
    };
    for (i, j, v) in &fobj.entries {
        add(&mut m, &mut mabs, *i, *j, *v);
    }
    add(&mut m, &mut mabs, one, one, -d);
    for (c, (form, nonneg)) in cons.iter().enumerate() {
        let mult = if *nonneg { x[1 + c].max(0.0) } else { x[1 + c] };
        if mult == 0.0 {
            continue;
        }
        terms += 1;
        for (i, j, v) in &form.entries {
            add(&mut m, &mut mabs, *i, *j, mult * v);
        }
    }
    // symmetrise (entries were stored with i ≤ j; off-diagonal ones carry half the sum each side)
    let mut sym = DMatrix::<f64>::zeros(n, n);
    let mut err = 0.0f64;
    let k = gamma(terms + fobj.entries.len() + 8);
    for j in 0..n {
        for i in 0..=j {
            let (v, a) = (m[(i, j)], mabs[(i, j)]);
            sym[(i, j)] = v;
            sym[(j, i)] = v;
            let e = k * a * 1.0625;
            err += if i == j { e * e } else { 2.0 * e * e };
        }
    }
    let err_f = (err.sqrt() * (1.0 + 1e-10)).next_up();
    let norm_f = sym.norm();
    let eig = SymmetricEigen::new(sym);
    let lam = eig
        .eigenvalues
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    if !lam.is_finite() {
        return Err(Issue::NonFiniteEigenvalues);
    }
    Ok(sum_upper([lam, err_f, 100.0 * n as f64 * U * norm_f]))
}

/// Whether the Schur-complement method is the cheaper solver for `m`
/// multipliers and an `n × n` matrix: an iteration of it factors a dense
/// `m × m` matrix; one of Clarabel's factors a KKT system whose PSD block
/// is dense with `n(n+1)/2` rows and whose multiplier columns are sparse.
/// Many multipliers on a small matrix (the pairwise products of a polytope
/// with many rows) are Clarabel's case; below 400 multipliers the Schur
/// matrix costs little either way, and it was the faster on every shipped
/// program (the quadrotor's 300 multipliers on 13 coordinates included).
fn schur_pays(m: usize, n: usize) -> bool {
    m <= 400 || m <= n * (n + 1)
}

/// The Schur-complement method's proposal for the program of
/// [`StepSdp::bound`], `(d, multipliers)`, when it converged.
fn propose(n: usize, fobj: &Form, vecs: Vec<Vec<(usize, f64)>>, rank2: &[Con]) -> Option<Vec<f64>> {
    // Z = C − Σ yₖ Aₖ = −M: C = −F, A₀ = −e eᵀ (the multiplier d), Aₖ = Sₖ
    let mut c = DMatrix::<f64>::zeros(n, n);
    for &(i, j, v) in &fobj.entries {
        c[(i, j)] -= v;
        if i != j {
            c[(j, i)] -= v;
        }
    }
    let mut cons = Vec::with_capacity(rank2.len() + 1);
    cons.push(Con {
        coef: -1.0,
        a: 0,
        b: 0,
        nonneg: false,
    });
    cons.extend_from_slice(rank2);
    let mut b = vec![0.0; cons.len()];
    b[0] = -1.0;
    let problem = sdp_ipm::Problem {
        n,
        c,
        vecs,
        cons,
        b,
    };
    match sdp_ipm::solve(&problem) {
        Ipm::Solved { y, .. } => Some(y),
        Ipm::NotSolved(_) => None,
    }
}

/// Clarabel's proposal for the program of [`StepSdp::bound`]: `x = (d, multipliers)`.
fn clarabel_solve(n: usize, fobj: &Form, cons: &[(Form, bool)]) -> Result<Vec<f64>, Issue> {
    // Clarabel's PSD cone calls BLAS/LAPACK, loaded on first use
    if crate::blas::load().is_err() {
        return Err(Issue::NoBlas);
    }
    let one = n - 1;
    let nvar = 1 + cons.len();
    let nnon = cons.iter().filter(|c| c.1).count();
    let tdim = n * (n + 1) / 2;
    let sq2 = std::f64::consts::SQRT_2;
    let svec_scale = |i: usize, j: usize| if i == j { 1.0 } else { sq2 };
    // A, b: rows 0..nnon are μ ≥ 0; then the PSD block s = svec(−M)
    let (mut ri, mut ci, mut vs) = (Vec::new(), Vec::new(), Vec::new());
    let mut bvec = vec![0.0; nnon + tdim];
    for (i, j, v) in &fobj.entries {
        bvec[nnon + tri(*i, *j)] -= v * svec_scale(*i, *j);
    }
    // d: s gets +d·svec(e eᵀ) → A column −svec(e eᵀ)
    ri.push(nnon + tri(one, one));
    ci.push(0);
    vs.push(-1.0);
    let mut k_non = 0;
    for (c, (form, nonneg)) in cons.iter().enumerate() {
        let col = 1 + c;
        if *nonneg {
            ri.push(k_non);
            ci.push(col);
            vs.push(-1.0);
            k_non += 1;
        }
        for (i, j, v) in &form.entries {
            ri.push(nnon + tri(*i, *j));
            ci.push(col);
            vs.push(v * svec_scale(*i, *j));
        }
    }
    let a = CscMatrix::new_from_triplets(nnon + tdim, nvar, ri, ci, vs);
    let p = CscMatrix::<f64>::zeros((nvar, nvar));
    let mut q = vec![0.0; nvar];
    q[0] = 1.0;
    let cones = [
        SupportedConeT::NonnegativeConeT(nnon),
        SupportedConeT::PSDTriangleConeT(n),
    ];
    let settings = match DefaultSettingsBuilder::default()
        .verbose(false)
        .max_iter(100)
        // faer's supernodal LDL: about 5× faster than QDLDL on the dense
        // KKT blocks of larger PSD cones; one thread keeps it deterministic
        .direct_solve_method("faer".into())
        .max_threads(1)
        .build()
    {
        Ok(s) => s,
        Err(_) => return Err(Issue::BadSettings(Backend::Sdp)),
    };
    let mut solver = match DefaultSolver::new(&p, &q, &a, &bvec, &cones, settings) {
        Ok(s) => s,
        Err(_) => return Err(Issue::RejectedData(Backend::Sdp)),
    };
    solver.solve();
    if let Some(issue) = Issue::from_status(Backend::Sdp, solver.solution.status) {
        return Err(issue);
    }
    Ok(solver.solution.x.clone())
}

fn none(issue: Issue) -> SdpBound {
    SdpBound {
        value: f64::INFINITY,
        issue: Some(issue),
    }
}

/// The boxes of a relaxation (before every layer).
fn relaxation_boxes(a: &Relaxation) -> Vec<IBox> {
    a.boxes().to_vec()
}
