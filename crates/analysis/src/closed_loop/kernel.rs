//! The fast path of a Reach-LP step from a box of states: the same bounds
//! as [`ClosedLoop::step`]'s general path, computed row by row in buffers
//! that are reused from step to step (one workspace per thread), with no
//! allocation per step but the answer (the facets' bounds and the control
//! box) and, for a plant with model error, its error vectors.
//!
//! The general path composes [`Relaxation`](super::Relaxation) and
//! [`LinearUpper`](super::LinearUpper) values, each a few vectors: on a
//! small controller (the double integrator's `2 → 5 → 5 → 1`) a step is a
//! few thousand floating-point operations, and the allocations, packing
//! and bookkeeping around them cost ten times that. This kernel does the
//! same analysis for a controller that is a chain (affine, then activation
//! and affine alternating) of at most [`MAX_WIDTH`] neurons a layer:
//!
//! 1. the observation box `y = Cᵀx + v` and the interval image of every
//!    layer, summed as [`affine_image`](super::affine_image) sums them;
//! 2. CROWN bounds of every pre-activation after the first layer (both
//!    signs of each row, back-substituted to `y` and bounded over its box),
//!    intersected with the interval ones; a ReLU that interval arithmetic
//!    proves inactive is not bounded, nor is a layer with one nonzero per
//!    row (a clamp's halves), exactly where the general path skips them;
//! 3. the output's rows `±e_j` back-substituted (the CROWN control box,
//!    intersected with interval arithmetic's), and each facet's control
//!    row `f B`: scaled from them when it has one nonzero (CROWN is
//!    positively homogeneous in its row), back-substituted otherwise;
//! 4. per facet `f`, `f (A x + c + w) + Λ(Cᵀx + v) + β` bounded over the
//!    boxes of `x`, `v`, `w` (Reach-LP) and, unless the step is asked
//!    alone, `f (A x + B u + c + w)` over `x`, the control box and `w`
//!    (CL-CROWN); the smaller of the two.
//!
//! Rounding is accounted for as in the general path, term for term: every
//! product of a row with a matrix adds `γ(rows + 2)·|row|·(|W|·|h|max)` to
//! its offset, every relaxation `2u·|row|·|z|max`, every sum is an [`Acc`]
//! rounded up once. The two paths sum in different orders, so their bounds
//! agree up to rounding terms, not bit for bit; `tests` compares them bound
//! for bound, and every propagator that this kernel serves (Reach-LP,
//! Reach-SDP's Reach-LP part, CL-CROWN's control box) uses it wherever it
//! applies, so the orders between them are exact.

use std::cell::RefCell;

use nalgebra::{DMatrix, DVector};

use super::{ClosedLoop, Dynamics};
use crate::crown::{
    affine_image_into, after_one_neuron, identity_image_into, one_nonzero, one_per_row,
    signed_identity, weight_scale_into,
};
use crate::relax::{image, relax, Relax};
use crate::sets::IBox;
use ravel_base::nn::{Activation, Layer};
use ravel_base::num::{abs_max, gamma, mul0, slack, slack_of_sum, term_upper, Acc, TINY, U};

/// The widest layer the kernel takes (neurons). Row-by-row products win
/// below it; wider controllers take the general path's blocked products.
pub const MAX_WIDTH: usize = 16;

/// The kernel's answer for one step.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Answer {
    /// Certified upper bounds of every facet row (finite), and the CROWN
    /// control box (intersected with interval arithmetic's; finite).
    Bounds { ub: Vec<f64>, control: IBox },
    /// Some bound was not finite: the step is an overflow.
    Overflow,
}

/// Buffers reused from step to step. Every slice of position `i` (the
/// value before layer `i`; position 0 is the controller's input `y`)
/// starts at `pos[i]`.
#[derive(Default)]
struct Workspace {
    pos: Vec<usize>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    /// At an activation's input position: each neuron's relaxation.
    rel: Vec<Relax>,
    /// At an activation's input position: `|z|max` of each neuron.
    absm: Vec<f64>,
    /// At an affine layer's output position: `|W|·|h|max` of each row.
    wz: Vec<f64>,
    /// At an affine layer's output position, for each row CROWN bounded:
    /// the rows `z_j` and `−z_j` over `y` (`2p` entries from `2p·(pos + j)`)
    /// and their offsets (from `2·(pos + j)`); `stored[pos + j]` says which.
    st_coef: Vec<f64>,
    st_off: Vec<f64>,
    stored: Vec<bool>,
    /// Per layer: whether any of its rows' bounds are stored.
    layer_stored: Vec<bool>,
    /// Per layer: whether it is affine with at most one nonzero per row.
    opr: Vec<bool>,
    /// Per layer: `Some(±1)` for an affine layer that is `±I`.
    ident: Vec<Option<f64>>,
    cur: Vec<f64>,
    spare: Vec<f64>,
    /// The interval images' running sums.
    sums: Vec<f64>,
    /// The output's `[I; −I]` rows over `y` (`2m × p`, row-major) and their offsets.
    pm: Vec<f64>,
    pm_off: Vec<f64>,
    /// One facet's rows and products.
    f: Vec<f64>,
    s: Vec<f64>,
    mb: Vec<f64>,
    fa: Vec<f64>,
    lam: Vec<f64>,
    tot: Vec<f64>,
    /// `|·|max` vectors and the scales of the plant's block matrices.
    abs_y: Vec<f64>,
    abs_u: Vec<f64>,
    abs_xv: Vec<f64>,
    abs_xw: Vec<f64>,
    abs_xuw: Vec<f64>,
    wz_obs: Vec<f64>,
    wz_xw: Vec<f64>,
    wz_xuw: Vec<f64>,
    xv_lo: Vec<f64>,
    xv_hi: Vec<f64>,
}

thread_local! {
    static WORKSPACE: RefCell<Workspace> = RefCell::new(Workspace::default());
}

/// Whether the kernel takes this controller: no layer wider than
/// [`MAX_WIDTH`] neurons.
pub(super) fn applies(cl: &ClosedLoop) -> bool {
    cl.net.layers.iter().all(|l| match l {
        Layer::Affine { w, .. } => w.nrows() <= MAX_WIDTH && w.ncols() <= MAX_WIDTH,
        Layer::Act(_) => true,
    }) && cl.plant.v.dim() <= MAX_WIDTH
}

/// The Reach-LP bounds of the facet rows `facets` at step `t + 1` for
/// states in the box `x` at step `t` (with CL-CROWN's unless `alone`), and
/// the CROWN control box; `None` when the kernel does not apply.
pub(super) fn reach_lp(
    cl: &ClosedLoop,
    t: usize,
    x: &IBox,
    facets: &DMatrix<f64>,
    alone: bool,
) -> Option<Answer> {
    if !applies(cl) {
        return None;
    }
    Some(WORKSPACE.with(|ws| {
        let ws = &mut *ws.borrow_mut();
        if !forward(cl, x, ws) {
            return Answer::Overflow;
        }
        facets_bound(cl, t, x, facets, alone, ws)
    }))
}

/// The CROWN control box (intersected with interval arithmetic's) for
/// states in `x`; `None` when the kernel does not apply.
pub(super) fn control_box(cl: &ClosedLoop, x: &IBox) -> Option<Option<IBox>> {
    if !applies(cl) {
        return None;
    }
    Some(WORKSPACE.with(|ws| {
        let ws = &mut *ws.borrow_mut();
        if !forward(cl, x, ws) {
            return None;
        }
        let u = output_rows(cl, ws);
        u.is_finite().then_some(u)
    }))
}

/// `v` as `n` copies of `value`, in its own memory once it has grown.
fn refill<T: Clone>(v: &mut Vec<T>, n: usize, value: T) {
    v.clear();
    v.resize(n, value);
}

/// `out` as `|W|·m` rounded up ([`weight_scale_into`] of all columns).
fn scale_into(w: &DMatrix<f64>, m: &[f64], out: &mut Vec<f64>) {
    refill(out, w.nrows(), 0.0);
    weight_scale_into(w, |i| m[i], None, out);
}

/// `Σ aᵢ bᵢ` in four interleaved partial sums (any order: every caller
/// bounds the error of any order).
#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let mut s = [0.0f64; 4];
    let (ac, bc) = (a[..n].chunks_exact(4), b[..n].chunks_exact(4));
    let (ar, br) = (ac.remainder(), bc.remainder());
    for (a4, b4) in ac.zip(bc) {
        for l in 0..4 {
            s[l] += a4[l] * b4[l];
        }
    }
    for (l, (x, y)) in ar.iter().zip(br).enumerate() {
        s[l] += x * y;
    }
    (s[0] + s[1]) + (s[2] + s[3])
}

/// The intermediate bounds of the controller over the observation box of
/// `x` (position 0 is `y`): `false` when a bound or scale is not finite.
fn forward(cl: &ClosedLoop, x: &IBox, ws: &mut Workspace) -> bool {
    let layers = &cl.net.layers;
    layout(layers, cl.plant.v.dim(), ws);
    if !observation_box(cl, x, ws) {
        return false;
    }
    let mut cur = std::mem::take(&mut ws.cur);
    let mut spare = std::mem::take(&mut ws.spare);
    for (i, layer) in layers.iter().enumerate() {
        match layer {
            Layer::Affine { w, b } => {
                affine_forward(i, w, b, ws);
                let next_act = match layers.get(i + 1) {
                    Some(Layer::Act(act)) => Some(*act),
                    _ => None,
                };
                // CROWN where the general path bounds (`Relaxation::with_hook`
                // without a hook): a layer that feeds an activation, not
                // the first, nor one whose rows each read one neuron of an
                // activation through layers with one nonzero per row
                let crown = i > 0 && next_act.is_some() && !after_one_neuron(layers, &ws.opr, i);
                if crown {
                    let relu = next_act == Some(Activation::Relu);
                    crown_forward(layers, i, relu, ws, &mut cur, &mut spare);
                }
            }
            Layer::Act(act) => activation_forward(*act, ws.pos[i], ws.pos[i + 1], ws),
        }
    }
    ws.cur = cur;
    ws.spare = spare;
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    finite(&ws.lo) && finite(&ws.hi) && finite(&ws.wz)
}

/// Lay `ws` out for the controller `layers` on an input of `p` values:
/// the positions, every per-position buffer sized and cleared, which
/// layers have one nonzero per row or are `±I`, and the interval images'
/// running sums sized for the widest layer.
fn layout(layers: &[Layer], p: usize, ws: &mut Workspace) {
    // positions: the value before layer `i` starts at `pos[i]`
    ws.pos.clear();
    let (mut start, mut size) = (0, p);
    for l in layers {
        ws.pos.push(start);
        start += size;
        if let Layer::Affine { w, .. } = l {
            size = w.nrows();
        }
    }
    ws.pos.push(start);
    let total = start + size;
    let zero = Relax {
        al: 0.0,
        bl: 0.0,
        au: 0.0,
        bu: 0.0,
    };
    for v in [&mut ws.lo, &mut ws.hi, &mut ws.absm, &mut ws.wz] {
        refill(v, total, 0.0);
    }
    refill(&mut ws.rel, total, zero);
    refill(&mut ws.stored, total, false);
    refill(&mut ws.layer_stored, layers.len(), false);
    refill(&mut ws.st_off, 2 * total, 0.0);
    refill(&mut ws.st_coef, 2 * p * total, 0.0);
    ws.opr.clear();
    ws.opr.extend(
        layers
            .iter()
            .map(|l| matches!(l, Layer::Affine { w, .. } if one_per_row(w))),
    );
    ws.ident.clear();
    ws.ident
        .extend(layers.iter().zip(&ws.opr).map(|(l, &one)| match l {
            Layer::Affine { w, .. } if one => signed_identity(w.as_slice(), w.nrows(), w.ncols()),
            _ => None,
        }));
    let widest = layers
        .iter()
        .map(|l| match l {
            Layer::Affine { w, .. } => w.nrows(),
            Layer::Act(_) => 0,
        })
        .max()
        .unwrap_or(0)
        .max(p);
    ws.sums.clear();
    ws.sums.resize(4 * widest, 0.0);
}

/// Position 0: the observation box `y = [Cᵀ I] (x, v)`, and `|y|max`;
/// `false` when `x` or `y` is not finite.
fn observation_box(cl: &ClosedLoop, x: &IBox, ws: &mut Workspace) -> bool {
    let v = &cl.plant.v;
    let p = v.dim();
    ws.xv_lo.clear();
    ws.xv_lo.extend_from_slice(&x.lo);
    ws.xv_lo.extend_from_slice(&v.lo);
    ws.xv_hi.clear();
    ws.xv_hi.extend_from_slice(&x.hi);
    ws.xv_hi.extend_from_slice(&v.hi);
    affine_image_into(
        &cl.obs_xv,
        cl.obs_zero.as_slice(),
        (&ws.xv_lo, &ws.xv_hi),
        None,
        (&mut ws.lo[..p], &mut ws.hi[..p]),
        &mut ws.sums,
    );
    if !(x.is_finite() && ws.lo[..p].iter().chain(&ws.hi[..p]).all(|v| v.is_finite())) {
        return false;
    }
    ws.abs_y.clear();
    ws.abs_y.extend((0..p).map(|j| abs_max(ws.lo[j], ws.hi[j])));
    true
}

/// Affine layer `i`, `w·h + b`: the interval image of its input and the
/// scale `|W|·|h|max` of its products (none for `±I`, whose are exact).
fn affine_forward(i: usize, w: &DMatrix<f64>, b: &DVector<f64>, ws: &mut Workspace) {
    let (a, z) = (ws.pos[i], ws.pos[i + 1]);
    let rows = w.nrows();
    let (before, after) = ws.lo.split_at_mut(z);
    let (hbefore, hafter) = ws.hi.split_at_mut(z);
    if let Some(sign) = ws.ident[i] {
        // z = ±h + b: the general path's numbers, without sums over zeros
        identity_image_into(
            sign,
            b.as_slice(),
            (&before[a..z], &hbefore[a..z]),
            &mut ws.wz[z..z + rows],
            (&mut after[..rows], &mut hafter[..rows]),
        );
    } else {
        // |W|·|h|max, for the error terms of products with W
        weight_scale_into(
            w,
            |k| abs_max(before[a + k], hbefore[a + k]),
            None,
            &mut ws.wz[z..z + rows],
        );
        affine_image_into(
            w,
            b.as_slice(),
            (&before[a..z], &hbefore[a..z]),
            None,
            (&mut after[..rows], &mut hafter[..rows]),
            &mut ws.sums,
        );
    }
}

/// The CROWN bounds of affine layer `i`'s outputs (both signs of each row,
/// back-substituted to `y` and stored), intersected with their interval
/// ones; before a ReLU (`relu`), not those it proves inactive.
fn crown_forward(
    layers: &[Layer],
    i: usize,
    relu: bool,
    ws: &mut Workspace,
    cur: &mut Vec<f64>,
    spare: &mut Vec<f64>,
) {
    let Layer::Affine { w, b } = &layers[i] else {
        unreachable!("CROWN bounds affine layers only");
    };
    let p = ws.abs_y.len();
    let z = ws.pos[i + 1];
    for j in 0..w.nrows() {
        if relu && ws.hi[z + j] <= 0.0 {
            continue;
        }
        let mut both = [0.0; 2];
        for (side, sign) in [(0, 1.0), (1, -1.0)] {
            cur.clear();
            cur.extend((0..w.ncols()).map(|k| sign * w[(j, k)]));
            let mut acc = Acc::of(sign * b[j]);
            back(layers, ws, i, cur, spare, &mut acc);
            let off = acc.upper();
            let at = 2 * (z + j) + side;
            ws.st_off[at] = off;
            ws.st_coef[at * p..(at + 1) * p].copy_from_slice(&cur[..p]);
            both[side] = concretize(cur, &ws.lo[..p], &ws.hi[..p], Acc::of(off));
        }
        ws.stored[z + j] = true;
        ws.layer_stored[i] = true;
        ws.hi[z + j] = ws.hi[z + j].min(both[0]);
        ws.lo[z + j] = ws.lo[z + j].max(-both[1]);
    }
}

/// The activation `act` from position `a` to `z`: each neuron's interval
/// image, relaxation and input size.
fn activation_forward(act: Activation, a: usize, z: usize, ws: &mut Workspace) {
    for j in 0..z - a {
        let (l, h) = (ws.lo[a + j], ws.hi[a + j]);
        let (il, ih) = image(act, l, h);
        ws.lo[z + j] = il;
        ws.hi[z + j] = ih;
        ws.rel[a + j] = relax(act, l, h);
        ws.absm[a + j] = abs_max(l, h);
    }
}

/// Back-substitute the row `cur` (coefficients on the value before layer
/// `from`) with offset `acc` down to the controller's input, in place:
/// each affine layer `cur ← cur·W`, its offset `cur·b` and the product's
/// error `γ(rows + 2)·|cur|·(|W|·|h|max)` (none for `±I`, whose product is
/// exact); each activation the relaxation line its coefficient's sign
/// selects, and the error `2u·|cur|·|z|max` of the scaled coefficients.
/// A row that reaches an affine layer's output as `c·z_j`, one nonzero on
/// a row whose CROWN bounds are stored, finishes from them: `c·z_j` is at
/// most `|c|` times the stored bound of `sign(c)·z_j` (over `y`, valid on
/// the whole box); the scaled coefficients are rounded, and their error
/// `2u·|c·λ|·|y|max` is added. The general path finishes such rows the
/// same way (CROWN is positively homogeneous in its row, so this is the
/// bound the rest of the pass would give, up to rounding).
fn back(
    layers: &[Layer],
    ws: &Workspace,
    from: usize,
    cur: &mut Vec<f64>,
    spare: &mut Vec<f64>,
    acc: &mut Acc,
) {
    for i in (0..from).rev() {
        match &layers[i] {
            Layer::Affine { w, b } => {
                let rows = w.nrows();
                let z = ws.pos[i + 1];
                if ws.layer_stored[i] {
                    if let Some(Some((j, c))) = one_nonzero(cur) {
                        if ws.stored[z + j] {
                            finish_stored(ws, z + j, c, cur, acc);
                            return;
                        }
                    }
                }
                // the offset's terms `cur·b` and the product's error scale
                // `|cur|·(|W|·|h|max)` in one pass
                let (mut s, mut a, mut e) = (0.0, 0.0, 0.0);
                for ((&l, &bj), &m) in cur.iter().zip(b.as_slice()).zip(&ws.wz[z..z + rows]) {
                    let t = mul0(l, bj);
                    s += t;
                    a += t.abs();
                    e += mul0(l.abs(), m);
                }
                acc.merge(Acc::from_parts(s, a, rows));
                if let Some(s) = ws.ident[i] {
                    if s < 0.0 {
                        cur.iter_mut().for_each(|c| *c = -*c);
                    }
                    continue;
                }
                acc.add(slack_of_sum(gamma(rows + 2), e));
                let cols = w.ncols();
                spare.clear();
                spare.resize(cols, 0.0);
                if rows > 0 {
                    for (o, col) in spare.iter_mut().zip(w.as_slice().chunks_exact(rows)) {
                        *o = dot(cur, col);
                    }
                }
                std::mem::swap(cur, spare);
            }
            Layer::Act(_) => {
                // each coefficient times the line its sign selects, the
                // intercepts' terms, and the scaled coefficients' error
                // scale `|cur|·|z|max`, in one pass
                let a0 = ws.pos[i];
                let k = cur.len();
                let (mut s, mut a, mut e, mut count) = (0.0, 0.0, 0.0, 0usize);
                for ((c, r), &m) in cur
                    .iter_mut()
                    .zip(&ws.rel[a0..a0 + k])
                    .zip(&ws.absm[a0..a0 + k])
                {
                    let l = *c;
                    let up = l >= 0.0;
                    let (slope, intercept) = if up { (r.au, r.bu) } else { (r.al, r.bl) };
                    let scaled = l * slope;
                    *c = scaled;
                    let nonzero = l != 0.0;
                    let t = if nonzero { l * intercept } else { 0.0 };
                    s += t;
                    a += t.abs();
                    count += usize::from(nonzero);
                    e += mul0(scaled.abs(), m);
                }
                acc.merge(Acc::from_parts(s, a, count));
                acc.add(slack_of_sum(2.0 * U, e));
            }
        }
    }
}

/// The end of [`back`] for the row `c·z_at` whose bounds are stored: `cur`
/// becomes `|c|·λ` over `y`, `acc` takes `|c|·β` and the rounding error.
fn finish_stored(ws: &Workspace, at: usize, c: f64, cur: &mut Vec<f64>, acc: &mut Acc) {
    let p = ws.abs_y.len();
    let side = usize::from(c < 0.0);
    let k = 2 * at + side;
    let scale = c.abs();
    cur.clear();
    cur.extend(
        ws.st_coef[k * p..(k + 1) * p]
            .iter()
            .map(|&l| mul0(scale, l)),
    );
    acc.add(mul0(scale, ws.st_off[k]));
    acc.add(slack(2.0 * U, cur, &ws.abs_y));
}

/// `acc + max over [lo, hi] of coef · z`, rounded up.
fn concretize(coef: &[f64], lo: &[f64], hi: &[f64], mut acc: Acc) -> f64 {
    for ((&c, &l), &h) in coef.iter().zip(lo).zip(hi) {
        acc.add(term_upper(c, l, h));
    }
    acc.upper()
}

/// The output's rows `±e_j` back-substituted into `ws.pm`, `ws.pm_off`,
/// and the CROWN control box (intersected with interval arithmetic's).
fn output_rows(cl: &ClosedLoop, ws: &mut Workspace) -> IBox {
    let layers = &cl.net.layers;
    let end = layers.len();
    let p = cl.plant.v.dim();
    let o = ws.pos[end];
    let m = cl.net.outputs();
    let mut cur = std::mem::take(&mut ws.cur);
    let mut spare = std::mem::take(&mut ws.spare);
    ws.pm.clear();
    ws.pm_off.clear();
    let mut u = IBox::new(ws.lo[o..o + m].to_vec(), ws.hi[o..o + m].to_vec());
    for sign in [1.0, -1.0] {
        for j in 0..m {
            cur.clear();
            cur.resize(m, 0.0);
            cur[j] = sign;
            let mut acc = Acc::ZERO;
            back(layers, ws, end, &mut cur, &mut spare, &mut acc);
            let off = acc.upper();
            ws.pm.extend_from_slice(&cur[..p]);
            ws.pm_off.push(off);
            let ub = concretize(&cur, &ws.lo[..p], &ws.hi[..p], Acc::of(off));
            if sign > 0.0 {
                u.hi[j] = u.hi[j].min(ub);
            } else {
                u.lo[j] = u.lo[j].max(-ub);
            }
        }
    }
    ws.cur = cur;
    ws.spare = spare;
    u
}

/// What every facet of one step reads in step 4 (after [`plant_sizes`]).
struct StepTerms<'s> {
    /// The step's dynamics.
    d: &'s Dynamics,
    /// The states' box.
    x: &'s IBox,
    /// The CROWN control box (intersected with interval arithmetic's).
    u: IBox,
    /// The plant's model error over `x` and the interval control box.
    delta: Option<Vec<f64>>,
    /// The plant's model error over `x` and `u` (CL-CROWN's; `None` alone).
    delta_u: Option<Vec<f64>>,
    /// The underflow allowance of every facet.
    allow: f64,
    /// `γ(n + 2)` and `γ(p + 2)`: products over states and observations.
    k_n: f64,
    k_p: f64,
}

/// Step 4 of the module documentation, after [`forward`].
fn facets_bound(
    cl: &ClosedLoop,
    t: usize,
    x: &IBox,
    facets: &DMatrix<f64>,
    alone: bool,
    ws: &mut Workspace,
) -> Answer {
    let u = output_rows(cl, ws);
    if !u.is_finite() {
        return Answer::Overflow;
    }
    let d = cl.at(t);
    let (n, p) = (x.dim(), cl.plant.v.dim());
    plant_sizes(cl, d, x, &u, ws);
    let delta = cl.model_delta(t, x, &ws.abs_u);
    let delta_u = if alone {
        None
    } else {
        cl.model_delta(t, x, &u.abs_max())
    };
    let st = StepTerms {
        d,
        x,
        u,
        delta,
        delta_u,
        allow: underflow_allowance(ws),
        k_n: gamma(n + 2),
        k_p: gamma(p + 2),
    };
    let mut cur = std::mem::take(&mut ws.cur);
    let mut spare = std::mem::take(&mut ws.spare);
    let mut ub = Vec::with_capacity(facets.nrows());
    for r in 0..facets.nrows() {
        facet_products(facets, r, n, d, ws);
        let beta = control_row(cl, ws, &mut cur, &mut spare);
        let mut bound = reach_lp_facet(cl, &st, beta, ws);
        if !alone {
            let other = cl_crown_facet(cl, &st, ws);
            if !other.is_finite() {
                bound = f64::NAN;
            } else {
                bound = bound.min(other);
            }
        }
        ub.push(bound);
    }
    ws.cur = cur;
    ws.spare = spare;
    if ub.iter().all(|b| b.is_finite()) {
        Answer::Bounds { ub, control: st.u }
    } else {
        Answer::Overflow
    }
}

/// The `|·|max` of the boxes step 4's products read (the interval
/// control box's into `ws.abs_u`; `(x, v)`, `(x, w)` and `(x, u, w)` with
/// `u` the CROWN control box), and the scales of the plant's block
/// matrices over them.
fn plant_sizes(cl: &ClosedLoop, d: &Dynamics, x: &IBox, u: &IBox, ws: &mut Workspace) {
    let (w, v) = (&cl.plant.w, &cl.plant.v);
    let m = d.plant.b.ncols();
    let o = ws.pos[cl.net.layers.len()];
    let am = |b: &IBox, out: &mut Vec<f64>| {
        out.extend(b.lo.iter().zip(&b.hi).map(|(l, h)| abs_max(*l, *h)));
    };
    ws.abs_u.clear();
    ws.abs_u
        .extend((0..m).map(|j| abs_max(ws.lo[o + j], ws.hi[o + j])));
    ws.abs_xv.clear();
    am(x, &mut ws.abs_xv);
    am(v, &mut ws.abs_xv);
    ws.abs_xw.clear();
    am(x, &mut ws.abs_xw);
    am(w, &mut ws.abs_xw);
    ws.abs_xuw.clear();
    am(x, &mut ws.abs_xuw);
    am(u, &mut ws.abs_xuw);
    am(w, &mut ws.abs_xuw);
    scale_into(&cl.obs_xv, &ws.abs_xv, &mut ws.wz_obs);
    scale_into(&d.dyn_xw, &ws.abs_xw, &mut ws.wz_xw);
    scale_into(&d.dyn_xuw, &ws.abs_xuw, &mut ws.wz_xuw);
}

/// Coefficient products that underflow are off by up to η/2 each,
/// however small the coefficients: TINY times the magnitudes of every
/// value a product stage reads (the controller's layers, twice for the
/// affine and the relaxation stage; the plant's inputs), unscaled, for
/// every facet (as the general path's `underflow_allowance`).
fn underflow_allowance(ws: &Workspace) -> f64 {
    let mut s = 0.0;
    for (l, h) in ws.lo.iter().zip(&ws.hi) {
        s += 2.0 * abs_max(*l, *h);
    }
    for v in [&ws.abs_xv, &ws.abs_xw, &ws.abs_xuw, &ws.abs_u] {
        s += v.iter().sum::<f64>();
    }
    ravel_base::num::sat_upper((TINY * s * 1.0625).next_up())
}

/// Facet row `r` of `facets` (over `n` states) into `ws.f`, with `f A`,
/// `f B` and `|f|·|B|` (the products' error terms are added by the bounds).
#[inline]
fn facet_products(facets: &DMatrix<f64>, r: usize, n: usize, d: &Dynamics, ws: &mut Workspace) {
    let (a_mat, b_mat) = (&d.plant.a, &d.plant.b);
    let m = b_mat.ncols();
    ws.f.clear();
    ws.f.extend((0..n).map(|i| facets[(r, i)]));
    let f = &ws.f;
    ws.fa.clear();
    ws.fa
        .extend((0..n).map(|k| dot(f, &a_mat.as_slice()[k * n..(k + 1) * n])));
    ws.s.clear();
    ws.s.extend((0..m).map(|j| dot(f, &b_mat.as_slice()[j * n..(j + 1) * n])));
    ws.mb.clear();
    ws.mb.extend((0..m).map(|j| {
        let col = &d.b_abs.as_slice()[j * n..(j + 1) * n];
        f.iter().zip(col).map(|(a, b)| a.abs() * b).sum::<f64>()
    }));
}

/// The control row `f B` (in `ws.s`) over `y`: its coefficients `Λ` into
/// `ws.lam` and its offset `β` (returned): scaled from the output's rows
/// when it has one nonzero, back-substituted otherwise.
#[inline]
fn control_row(
    cl: &ClosedLoop,
    ws: &mut Workspace,
    cur: &mut Vec<f64>,
    spare: &mut Vec<f64>,
) -> Acc {
    let p = cl.plant.v.dim();
    let m = ws.s.len();
    let mut beta = Acc::ZERO;
    ws.lam.clear();
    match one_nonzero(&ws.s) {
        Some(None) => ws.lam.resize(p, 0.0),
        Some(Some((c, val))) => {
            let src = if val < 0.0 { m + c } else { c };
            let scale = val.abs();
            ws.lam.extend(
                ws.pm[src * p..(src + 1) * p]
                    .iter()
                    .map(|&l| mul0(scale, l)),
            );
            beta.add(mul0(scale, ws.pm_off[src]));
            beta.add(slack(2.0 * U, &ws.lam, &ws.abs_y));
        }
        None => {
            cur.clear();
            cur.extend_from_slice(&ws.s);
            back(
                &cl.net.layers,
                ws,
                cl.net.layers.len(),
                cur,
                spare,
                &mut beta,
            );
            ws.lam.extend_from_slice(&cur[..p]);
        }
    }
    beta
}

/// Reach-LP's bound of the facet in `ws.f`: `f (A x + c + w) + Λ (Cᵀ x +
/// v) + β` over the boxes of `x`, `v` and `w`, with the plant's model
/// error.
#[inline]
fn reach_lp_facet(cl: &ClosedLoop, st: &StepTerms, beta: Acc, ws: &mut Workspace) -> f64 {
    let (w, v) = (&cl.plant.w, &cl.plant.v);
    let (x, n, p) = (st.x, st.x.dim(), v.dim());
    let f = &ws.f;
    let mut acc = Acc::of(beta.upper());
    acc.add(st.allow);
    // Λ·[Cᵀ I]: its error, then v's terms (Λ·I is Λ, exactly)
    acc.add(slack(st.k_p, &ws.lam, &ws.wz_obs));
    for (j, &l) in ws.lam.iter().enumerate() {
        acc.add(term_upper(l, v.lo[j], v.hi[j]));
    }
    // the rounding of f B, times the size of u
    acc.add(slack(st.k_n, &ws.mb, &ws.abs_u));
    // f·[A I]: its error, c's and w's terms (f·I is f, exactly)
    acc.add_products(f, st.d.plant.c.as_slice());
    acc.add(slack(st.k_n, f, &ws.wz_xw));
    for (i, &fi) in f.iter().enumerate() {
        acc.add(term_upper(fi, w.lo[i], w.hi[i]));
    }
    // x's coefficients: f A + Λ Cᵀ, their sum rounded
    ws.tot.clear();
    for k in 0..n {
        let col = &cl.obs_xv.as_slice()[k * p..(k + 1) * p];
        ws.tot.push(ws.fa[k] + dot(&ws.lam, col));
    }
    acc.add(slack(2.0 * U, &ws.tot, &ws.abs_xv[..n]));
    let bound = concretize(&ws.tot, &x.lo, &x.hi, acc);
    match &st.delta {
        Some(delta) => with_model_error(bound, f, delta),
        None => bound,
    }
}

/// CL-CROWN's bound of the facet in `ws.f`: `f (A x + B u + c + w)` over
/// the boxes of `x`, the control `u` and `w`, with the plant's model error.
#[inline]
fn cl_crown_facet(cl: &ClosedLoop, st: &StepTerms, ws: &Workspace) -> f64 {
    let w = &cl.plant.w;
    let f = &ws.f;
    let mut acc = Acc::of(st.allow);
    acc.add_products(f, st.d.plant.c.as_slice());
    acc.add(slack(st.k_n, f, &ws.wz_xuw));
    for (j, &s) in ws.s.iter().enumerate() {
        acc.add(term_upper(s, st.u.lo[j], st.u.hi[j]));
    }
    for (i, &fi) in f.iter().enumerate() {
        acc.add(term_upper(fi, w.lo[i], w.hi[i]));
    }
    let other = concretize(&ws.fa, &st.x.lo, &st.x.hi, acc);
    match &st.delta_u {
        Some(delta) => with_model_error(other, f, delta),
        None => other,
    }
}

/// `bound + Σ_j |f_j|·δ_j`, rounded up (the plant's model error).
fn with_model_error(bound: f64, f: &[f64], delta: &[f64]) -> f64 {
    let extra = ravel_base::num::sum_upper(f.iter().zip(delta).map(|(r, d)| mul0(r.abs(), *d)));
    ravel_base::num::sum_upper([bound, extra])
}
