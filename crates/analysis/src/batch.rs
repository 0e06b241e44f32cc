//! Batched CROWN (and Fast-Lin): the bounds of many cells of a partition
//! through one network (affine layers with ReLU, tanh or sigmoid between
//! them) at once, with the back-substitutions of all cells done as
//! matrix–matrix products that share the network's weights. One cell goes
//! the same way: the products stay blocked matrix multiplies.
//!
//! [`Relaxation`](super::crown::Relaxation) bounds one cell: its
//! back-substitutions multiply that cell's coefficient rows by each weight
//! matrix, row by row, and through a wide network most of its time goes to
//! per-entry work on those rows. Here the cells of a partition go through
//! together, and every product is one blocked matrix multiply (nalgebra's,
//! i.e. `matrixmultiply`):
//!
//! * **The second layer's bounds, right-associated.** The bound of
//!   `±z₁ = ±(W₁ σ(z₀) + b₁)` substitutes, for each neuron `i` of the
//!   first activation, the upper line `aᵤ z₀ᵢ + bᵤ` where `W₁`'s entry is
//!   positive and the lower line `aₗ z₀ᵢ + bₗ` where it is negative, then
//!   `z₀ = W₀ x + b₀`. Written per cell with `T⁺ = [diag(aᵤ) W₀ | aᵤ b₀ + bᵤ]`
//!   and `T⁻ = [diag(aₗ) W₀ | aₗ b₀ + bₗ]`, the upper bound's
//!   coefficients are `W₁⁺ T⁺ + W₁⁻ T⁻ = W₁ S + |W₁| D` with
//!   `S = (T⁺ + T⁻)/2`, `D = (T⁺ − T⁻)/2`, and the lower bound's are
//!   `W₁ S − |W₁| D`: two products of the shared `W₁` and `|W₁|` with all
//!   cells' thin `S` and `D` side by side (the same choice of lines, hence
//!   CROWN's bound, as the row-by-row pass). The same holds for the output
//!   rows of a network with one hidden layer.
//! * **Deeper passes, stacked.** Other back-substitutions (the output
//!   rows of deeper networks, the bounds of the third layer on) start from
//!   rows shared by all cells, take each cell's relaxation entry by entry,
//!   and multiply all cells' rows, stacked (kept as rows), by the layer's
//!   `W` as it is stored; the offsets `λ·b` are summed row by row.
//! * Interval images of hidden layers are products of `W` and `|W|` with
//!   all cells' midpoints and radii; where CROWN's bound does not certainly
//!   beat them, a neuron's interval bound is the single-cell analysis's
//!   directed one (so no box is looser than interval arithmetic's), and
//!   the output's interval image is the single-cell analysis's.
//!
//! # Soundness
//! The relaxations are [`relax`](super::relax::relax)'s, as in the
//! single-cell analysis, and every bound is an upper bound of exact
//! arithmetic on the numbers used: a product of `n`-term sums has error at
//! most `γₙ·|A|·|B|` in any order of summation, with or without fused
//! multiply-adds (Higham, §3.5), plus `TINY` for underflow. The error
//! terms are:
//! * a stacked product `Λ·W` of rows on a layer's output, with the offsets
//!   `Λ·b`: `γ` times `|Λ|·s`, with `s = |W|·|h|max + |b|` the layer's
//!   scale per cell (as the single-cell analysis);
//! * the right-associated products: every rounding in forming `T⁺`, `T⁻`,
//!   `S`, `D`, the two products and their sum is at most
//!   `γ_{n+8}·Σᵢ|Wⱼᵢ|·(|T⁺ᵢₖ| + |T⁻ᵢₖ|)` per coefficient, bounded by the
//!   rank-one `γ_{n+8}·(Σᵢ|Wⱼᵢ|)·maxᵢ(|T⁺ᵢₖ| + |T⁻ᵢₖ|)` (looser by at most
//!   the width, i.e. ~10⁻¹⁰ relative for 1000 neurons; cheap);
//! * an activation step's products `λ·a`: `2u·|λ'|·|z|max`;
//! * a hidden interval image from midpoints `m` and radii `r`:
//!   `γ·|W|·(|m| + r)`, the radii rounded up.
//!
//! The bounds equal the single-cell analysis's up to these rounding terms
//! (the tests compare them bound for bound); a cell whose numbers are not
//! all finite makes the whole batch decline (`None`), and the caller takes
//! the single-cell path, as before.
use nalgebra::{DMatrix, DVector};

use super::crown::{affine_image, affine_image_of, affine_image_row, weight_scale, Mode};
use super::relax::{image, relax_in_mode, Relax};
use super::shape::support_of_box;
use crate::sets::IBox;
use ravel_base::nn::{Activation, Layer, Network};
use ravel_base::num::{dot_box_upper, gamma, mul0, Acc, TINY, U};

/// The most matrix entries one cell chunk's largest work matrix holds
/// (8 MB of `f64`): cells go through in chunks of at most this size.
const CHUNK_ENTRIES: usize = 1 << 20;

/// A network as affine maps `z_g = W_g h_{g−1} + b_g` (`h_{−1}` the input)
/// with an activation `h_g = σ_g(z_g)` between consecutive ones.
struct Chain<'a> {
    w: Vec<&'a DMatrix<f64>>,
    b: Vec<&'a DVector<f64>>,
    /// `σ_g`.
    act: Vec<Activation>,
    /// Fast-Lin: a ReLU's lower slope is its upper one.
    fast_lin: bool,
    /// `|W_g|` for `g ≥ 1` (empty for `g = 0`, whose interval image is
    /// the single-cell analysis's).
    abs_w: Vec<DMatrix<f64>>,
}

impl<'a> Chain<'a> {
    /// The chain of `net`, if it is one (affine, then activation and
    /// affine alternating, at least one activation), with finite weights.
    fn of(net: &'a Network, fast_lin: bool) -> Option<Chain<'a>> {
        let mut w = Vec::new();
        let mut b = Vec::new();
        let mut act = Vec::new();
        for (i, layer) in net.layers.iter().enumerate() {
            match (i % 2, layer) {
                (0, Layer::Affine { w: wi, b: bi }) => {
                    if !wi.iter().chain(bi.iter()).all(|v| v.is_finite()) {
                        return None;
                    }
                    w.push(wi);
                    b.push(bi);
                }
                (1, Layer::Act(a)) => act.push(*a),
                _ => return None,
            }
        }
        if net.layers.len() % 2 == 0 || w.len() < 2 {
            return None;
        }
        let abs_w = w
            .iter()
            .enumerate()
            .map(|(g, m)| {
                if g == 0 {
                    DMatrix::zeros(0, 0)
                } else {
                    m.abs()
                }
            })
            .collect();
        Some(Chain {
            w,
            b,
            act,
            fast_lin,
            abs_w,
        })
    }

    /// The number of affine layers.
    fn len(&self) -> usize {
        self.w.len()
    }
}

/// One cell's bounds, filled layer by layer.
struct Cell {
    /// The input box.
    x: IBox,
    /// `|x|max` per input.
    x_abs: Vec<f64>,
    /// Bounds of each `z_g`.
    z: Vec<IBox>,
    /// The relaxation of each ReLU `h_g = relu(z_g)`.
    relax: Vec<Vec<Relax>>,
    /// `|z_g|max` per neuron (the relaxation products' error terms).
    z_abs: Vec<Vec<f64>>,
    /// Bounds of each `h_g = σ_g(z_g)`.
    h: Vec<IBox>,
    /// `|h_g|max` per neuron.
    h_abs: Vec<Vec<f64>>,
    /// `|W_g|·|h_{g−1}|max + |b_g|`, rounded up (a product's error terms).
    scale: Vec<Vec<f64>>,
    /// Per neuron of the last interval image: how far the exact image's
    /// bounds can lie inside the computed ones (see [`interval_step`]).
    gap: Vec<f64>,
}

/// Certified upper bounds of `d·f(x)` over each cell for every row `d` of
/// `dirs`, in CROWN or Fast-Lin `mode` (`None` in interval mode): the
/// smaller of the support of the output box (the mode's bounds of `±f`,
/// intersected with interval arithmetic's) and the mode's bound of `d·f`,
/// as the single-cell analysis gives them
/// ([`Relaxation::output_box`](super::crown::Relaxation::output_box), then
/// [`Relaxation::upper`](super::crown::Relaxation::upper) of `dirs`), equal up
/// to rounding terms (see the module documentation). `None` when `net` is
/// not a chain of affine layers and activations (at least two affine
/// layers), or a number on the way is not finite: the caller bounds the
/// cells one by one.
pub fn crown_offsets(
    net: &Network,
    cells: &[IBox],
    dirs: &DMatrix<f64>,
    mode: Mode,
) -> Option<Vec<Vec<f64>>> {
    let chain = Chain::of(net, mode == Mode::FastLin)?;
    if mode == Mode::Ibp {
        return None;
    }
    if dirs.ncols() != net.outputs() || !dirs.iter().all(|v| v.is_finite()) {
        return None;
    }
    // the rows bounded: [I; −I] (the output box), then those of `dirs`
    // that are not ±eⱼ (whose bound is the box's side)
    let out_m = net.outputs();
    let own: Vec<usize> = (0..dirs.nrows())
        .filter(|&r| unit_row(dirs, r).is_none())
        .collect();
    let mut all = DMatrix::zeros(2 * out_m + own.len(), out_m);
    for j in 0..out_m {
        all[(j, j)] = 1.0;
        all[(out_m + j, j)] = -1.0;
    }
    for (k, &r) in own.iter().enumerate() {
        all.row_mut(2 * out_m + k).copy_from(&dirs.row(r));
    }
    // the entries per cell of the largest work matrix: the
    // right-associated factors and products, the interval products, the
    // stacked rows of deeper bounds and of the output
    let last = chain.len() - 1;
    let n0 = net.inputs + 1;
    let (m0, m1) = (chain.w[0].nrows(), chain.w[1].nrows());
    let mut per_cell = (m0 * n0).max(m1.max(all.nrows()) * n0);
    for g in 1..=last {
        let (out, inp) = chain.w[g].shape();
        per_cell = per_cell.max(3 * out.max(inp));
        if g >= 2 && g < last {
            per_cell = per_cell.max(2 * out * (inp + 1));
        }
    }
    per_cell = per_cell.max(all.nrows() * (chain.w[last].ncols() + 1));
    let chunk = (CHUNK_ENTRIES / per_cell).max(1);
    let mut out = Vec::with_capacity(cells.len());
    for part in cells.chunks(chunk) {
        out.extend(chunk_offsets(&chain, part, &all, dirs, &own)?);
    }
    Some(out)
}

/// The output index and sign of row `r` of `dirs` if it is `±eⱼ`.
fn unit_row(dirs: &DMatrix<f64>, r: usize) -> Option<(usize, bool)> {
    let mut nonzero = (0..dirs.ncols()).filter(|&j| dirs[(r, j)] != 0.0);
    match (nonzero.next(), nonzero.next()) {
        (Some(j), None) if dirs[(r, j)] == 1.0 => Some((j, true)),
        (Some(j), None) if dirs[(r, j)] == -1.0 => Some((j, false)),
        _ => None,
    }
}

/// [`crown_offsets`] of one chunk of cells: `dirs` the rows bounded
/// (`[I; −I]` then the rows `own` of `given`).
fn chunk_offsets(
    chain: &Chain,
    cells: &[IBox],
    dirs: &DMatrix<f64>,
    given: &DMatrix<f64>,
    own: &[usize],
) -> Option<Vec<Vec<f64>>> {
    let last = chain.len() - 1;
    let mut cs = first_cells(chain, cells)?;
    for g in 1..=last {
        act_step(chain, &mut cs, g - 1);
        if g == last {
            output_interval(chain, &mut cs, g);
            break;
        }
        interval_step(chain, &mut cs, g)?;
        let bounds = hidden_bounds(chain, &cs, g);
        let relu = chain.act[g - 1] == Activation::Relu;
        for (c, up) in cs.iter_mut().zip(bounds) {
            if !tighten_hidden(chain, c, g, &up, relu) {
                return None;
            }
        }
    }
    let bounds = output_bounds(chain, &cs, dirs);
    let out_m = chain.w[last].nrows();
    let mut out = Vec::with_capacity(cs.len());
    for (c, up) in cs.iter().zip(bounds) {
        out.push(offsets_of(&c.z[last], &up, out_m, given, own)?);
    }
    Some(out)
}

/// Each cell of `cells` with its first layer's interval image and scale;
/// `None` when a cell does not fit the chain's input or is not finite.
fn first_cells(chain: &Chain, cells: &[IBox]) -> Option<Vec<Cell>> {
    let mut cs: Vec<Cell> = Vec::with_capacity(cells.len());
    for x in cells {
        if x.dim() != chain.w[0].ncols() || !x.is_finite() {
            return None;
        }
        let x_abs = x.abs_max();
        let z0 = affine_image(chain.w[0], chain.b[0], x);
        let s0 = with_bias(weight_scale(chain.w[0], &x_abs), chain.b[0]);
        cs.push(Cell {
            x: x.clone(),
            x_abs,
            z: vec![z0],
            relax: Vec::new(),
            z_abs: Vec::new(),
            h: Vec::new(),
            h_abs: Vec::new(),
            scale: vec![s0],
            gap: Vec::new(),
        });
    }
    Some(cs)
}

/// The output's (layer `g`'s) interval image as the single-cell analysis
/// computes it (directed rounding, over the neurons a ReLU does not prove
/// inactive): few rows, and the box every CROWN row is intersected with.
fn output_interval(chain: &Chain, cs: &mut [Cell], g: usize) {
    let relu = chain.act[g - 1] == Activation::Relu;
    for c in cs.iter_mut() {
        let z = &c.z[g - 1];
        let kept: Vec<usize> = (0..z.dim()).filter(|&i| z.hi[i] > 0.0).collect();
        let cols = (relu && kept.len() < z.dim()).then_some(kept.as_slice());
        let out = affine_image_of(chain.w[g], chain.b[g], &c.h[g - 1], cols);
        c.z.push(out);
    }
}

/// CROWN's upper bounds, per cell, of hidden layer `g`'s outputs and of
/// their negations (`2m` each): right-associated for the second layer,
/// stacked deeper.
fn hidden_bounds(chain: &Chain, cs: &[Cell], g: usize) -> Vec<Vec<f64>> {
    if g == 1 {
        return right_associated(
            chain,
            cs,
            chain.w[1],
            &chain.abs_w[1],
            chain.b[1],
            None,
            true,
        );
    }
    // the rows [W | b; −W | −b] on h_{g−1}
    let m = chain.w[g].nrows();
    let inp = chain.w[g].ncols();
    let rows = DMatrix::from_fn(2 * m, inp + 1, |r, i| {
        let (j, sign) = if r < m { (r, 1.0) } else { (r - m, -1.0) };
        sign * if i < inp {
            chain.w[g][(j, i)]
        } else {
            chain.b[g][j]
        }
    });
    stacked(chain, cs, &rows, None, g - 1)
}

/// Cell `c`'s bounds of hidden layer `g` intersected with CROWN's `up`
/// ([`hidden_bounds`]; `relu`: the activation before the layer is a
/// ReLU); `false` when they are not finite.
///
/// Where CROWN's bound does not certainly beat the exact interval image
/// (the computed one from midpoints and radii can exceed it by `gap`),
/// the interval bound is computed as the single-cell analysis does
/// (directed rounding): so no bound is looser than interval arithmetic's
/// from the same boxes.
#[inline]
fn tighten_hidden(chain: &Chain, c: &mut Cell, g: usize, up: &[f64], relu: bool) -> bool {
    let m = chain.w[g].nrows();
    let mut kept: Option<Vec<usize>> = None;
    for j in 0..m {
        let (hi, lo, gap) = (c.z[g].hi[j], c.z[g].lo[j], c.gap[j]);
        let (u, l) = (up[j], -up[m + j]);
        let (mut new_hi, mut new_lo) = (hi.min(u), lo.max(l));
        if u > hi - gap || l < lo + gap {
            let z = &c.z[g - 1];
            let cols = kept
                .get_or_insert_with(|| (0..z.dim()).filter(|&i| !relu || z.hi[i] > 0.0).collect());
            let cols = (cols.len() < z.dim()).then_some(cols.as_slice());
            let (dl, dh) = affine_image_row(chain.w[g], chain.b[g], &c.h[g - 1], cols, j);
            new_hi = new_hi.min(dh);
            new_lo = new_lo.max(dl);
        }
        c.z[g].hi[j] = new_hi;
        c.z[g].lo[j] = new_lo;
    }
    c.z[g].is_finite()
}

/// CROWN's upper bounds, per cell, of the output rows `dirs · z_last`, as
/// rows on h_{last−1}: `dirs·[W | b]` with its rounding error bounded
/// entry by entry.
fn output_bounds(chain: &Chain, cs: &[Cell], dirs: &DMatrix<f64>) -> Vec<Vec<f64>> {
    let last = chain.len() - 1;
    let (w, b) = (chain.w[last], chain.b[last]);
    let (k, m) = (dirs.nrows(), w.ncols());
    let wb = DMatrix::from_fn(
        w.nrows(),
        m + 1,
        |j, i| if i < m { w[(j, i)] } else { b[j] },
    );
    let rows = dirs * &wb;
    let abs_wb = wb.abs();
    let terms = w.nrows() + 2;
    let err = (dirs.abs() * abs_wb).map(|v| (gamma(terms) * v * 1.0625 + TINY).next_up());
    if last == 1 {
        let r = rows.columns(0, m).into_owned();
        let off: Vec<f64> = (0..k).map(|j| rows[(j, m)]).collect();
        let off = DVector::from_vec(off);
        right_associated(chain, cs, &r, &r.abs(), &off, Some(&err), false)
    } else {
        stacked(chain, cs, &rows, Some(&err), last - 1)
    }
}

/// One cell's answer from its output's interval box `z` (`out_m`
/// outputs) and CROWN's bounds `up` of `[I; −I]` and of the rows `own`:
/// the support of the output box (interval arithmetic's and CROWN's
/// bounds of ±f) in every row of `given`, an own row's the smaller of
/// that and its CROWN bound; `None` when a number is not finite.
fn offsets_of(
    z: &IBox,
    up: &[f64],
    out_m: usize,
    given: &DMatrix<f64>,
    own: &[usize],
) -> Option<Vec<f64>> {
    if !z.is_finite() || !up.iter().all(|v| v.is_finite()) {
        return None;
    }
    let hi: Vec<f64> = (0..out_m).map(|j| z.hi[j].min(up[j])).collect();
    let lo: Vec<f64> = (0..out_m).map(|j| z.lo[j].max(-up[out_m + j])).collect();
    let mut s = support_of_box(given, &lo, &hi);
    for (&r, u) in own.iter().zip(&up[2 * out_m..]) {
        s[r] = s[r].min(*u);
    }
    // every value is finite here (a unit row's is a finite side of the
    // box, another's is at most its finite CROWN bound); kept as the
    // guard of this function's promise, never to return a non-finite
    // number
    if !s.iter().all(|v| v.is_finite()) {
        return None;
    }
    Some(s)
}

/// `s + |b|`, rounded up.
fn with_bias(mut s: Vec<f64>, b: &DVector<f64>) -> Vec<f64> {
    for (v, bj) in s.iter_mut().zip(b.iter()) {
        *v = Acc::from_parts(*v + bj.abs(), *v + bj.abs(), 2).upper();
    }
    s
}

/// The activation after affine layer `g`: each cell's relaxation (as the
/// single-cell analysis takes it: [`relax_in_mode`], with Fast-Lin's
/// lower ReLU slope), output bounds and sizes.
fn act_step(chain: &Chain, cs: &mut [Cell], g: usize) {
    let act = chain.act[g];
    let fast_lin = chain.fast_lin && act == Activation::Relu;
    for c in cs.iter_mut() {
        let z = &c.z[g];
        let n = z.dim();
        let mut rel = Vec::with_capacity(n);
        let mut za = Vec::with_capacity(n);
        let (mut lo, mut hi, mut ha) = (
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        );
        for j in 0..n {
            let (l, h) = (z.lo[j], z.hi[j]);
            rel.push(relax_in_mode(act, l, h, fast_lin));
            za.push(l.abs().max(h.abs()));
            let (il, ih) = image(act, l, h);
            lo.push(il);
            hi.push(ih);
            ha.push(il.abs().max(ih.abs()));
        }
        c.relax.push(rel);
        c.z_abs.push(za);
        c.h.push(IBox::new(lo, hi));
        c.h_abs.push(ha);
    }
}

/// The interval image of `z_g = W_g h_{g−1} + b_g` for every cell, and the
/// layer's scale: products of `W_g` with the midpoints and `|W_g|` with
/// the radii and the midpoints' sizes.
fn interval_step(chain: &Chain, cs: &mut [Cell], g: usize) -> Option<()> {
    let (w, b) = (chain.w[g], chain.b[g]);
    let (m, n) = w.shape();
    let cells = cs.len();
    let mut mid = DMatrix::zeros(n, cells);
    let mut both = DMatrix::zeros(n, 2 * cells);
    for (c, cell) in cs.iter().enumerate() {
        let x = &cell.h[g - 1];
        for i in 0..n {
            let (l, h) = (x.lo[i], x.hi[i]);
            let md = 0.5 * l + 0.5 * h;
            // [l, h] ⊆ [md − r, md + r]: each difference rounded, then up
            let r = (h - md).next_up().max((md - l).next_up()).max(0.0);
            mid[(i, c)] = md;
            both[(i, c)] = r;
            both[(i, cells + c)] = md.abs();
        }
    }
    let p = w * &mid;
    let q = &chain.abs_w[g] * &both;
    let k = gamma(n + 2) * 1.0625;
    for (c, cell) in cs.iter_mut().enumerate() {
        let mut lo = Vec::with_capacity(m);
        let mut hi = Vec::with_capacity(m);
        let mut scale = Vec::with_capacity(m);
        let mut gap = Vec::with_capacity(m);
        for j in 0..m {
            let (pm, qr, qm) = (p[(j, c)], q[(j, c)], q[(j, cells + c)]);
            // |W·md − P| ≤ γ|W|·|md|, |W|·r ≤ Q_r + γ|W|·r
            let err = (k * (qr + qm) + TINY).next_up();
            let mut up = Acc::of(pm);
            up.add(qr);
            up.add(b[j]);
            up.add(err);
            hi.push(up.upper());
            // the exact image's bounds lie inside the computed ones by at
            // most the error terms twice over, the radius's rounding and
            // the sums' rounding: generously
            gap.push((4.0 * err + 16.0 * U * (pm.abs() + qr + qm + b[j].abs()) + TINY).next_up());
            let mut down = Acc::of(pm);
            down.add(-qr);
            down.add(b[j]);
            down.add(-err);
            lo.push(down.lower());
            // |W|·|h|max + |b| ≤ |W|·(|md| + r) + |b|
            let mut s = Acc::of(qr);
            s.add(qm);
            s.add(b[j].abs());
            s.add(err);
            scale.push(s.upper());
        }
        let z = IBox::new(lo, hi);
        if !z.is_finite() || !scale.iter().all(|v| v.is_finite()) {
            return None;
        }
        cell.z.push(z);
        cell.scale.push(scale);
        cell.gap = gap;
    }
    Some(())
}

/// Upper bounds, per cell, of `r·h₀ + o_r` for the rows `r` of `rows` on
/// the first ReLU's output `h₀` (and, with `both`, of `−r·h₀ − o_r`
/// after them), right-associated (see the module documentation). `err`
/// bounds the rounding error of `rows` and `offset` entry by entry (its
/// last column the offset's).
fn right_associated(
    chain: &Chain,
    cs: &[Cell],
    rows: &DMatrix<f64>,
    abs_rows: &DMatrix<f64>,
    offset: &DVector<f64>,
    err: Option<&DMatrix<f64>>,
    both: bool,
) -> Vec<Vec<f64>> {
    let (w0, b0) = (chain.w[0], chain.b[0]);
    let (m0, n) = w0.shape();
    let width = n + 1;
    let cells = cs.len();
    let mut s = DMatrix::zeros(m0, width * cells);
    let mut d = DMatrix::zeros(m0, width * cells);
    // per cell: Σₖ maxᵢ(|T⁺ᵢₖ| + |T⁻ᵢₖ|)·|xₖ|max + the offset column's
    let mut tau = Vec::with_capacity(cells);
    for (c, cell) in cs.iter().enumerate() {
        let mut cmax = vec![0.0f64; width];
        let rel = &cell.relax[0];
        // column by column (contiguous in S, D and W₀)
        for (k, cm) in cmax.iter_mut().enumerate() {
            let at = (c * width + k) * m0;
            let (sc, dc) = (
                &mut s.as_mut_slice()[at..at + m0],
                &mut d.as_mut_slice()[at..at + m0],
            );
            if k < n {
                let wc = &w0.as_slice()[k * m0..(k + 1) * m0];
                for i in 0..m0 {
                    let (tu, tl) = (mul0(rel[i].au, wc[i]), mul0(rel[i].al, wc[i]));
                    sc[i] = 0.5 * (tu + tl);
                    dc[i] = 0.5 * (tu - tl);
                    *cm = cm.max(tu.abs() + tl.abs());
                }
            } else {
                for i in 0..m0 {
                    let r = rel[i];
                    let (pu, pl) = (mul0(r.au, b0[i]), mul0(r.al, b0[i]));
                    let (tu, tl) = (pu + r.bu, pl + r.bl);
                    sc[i] = 0.5 * (tu + tl);
                    dc[i] = 0.5 * (tu - tl);
                    *cm = cm.max(pu.abs() + r.bu.abs() + pl.abs() + r.bl.abs());
                }
            }
        }
        let mut t = Acc::ZERO;
        t.add_products(&cmax[..n], &cell.x_abs);
        t.add(cmax[n]);
        tau.push((t.upper() * 1.0625).next_up());
    }
    let p = rows * &s;
    let q = abs_rows * &d;
    let k = rows.nrows();
    let n_h = rows.ncols();
    let kappa = gamma(m0 + 8) * 1.0625;
    let row_abs: Vec<f64> = (0..k)
        .map(|j| {
            let sum: f64 = abs_rows.row(j).iter().sum();
            (sum * (1.0 + gamma(m0 + 2))).next_up()
        })
        .collect();
    // the rows' own rounding error, per cell: Σᵢ eᵢ·|h₀ᵢ|max + e_offset
    let err_rows: Option<Vec<Vec<f64>>> =
        err.map(|e| (0..k).map(|j| e.row(j).iter().copied().collect()).collect());
    let mut out = Vec::with_capacity(cells);
    let mut coef = vec![0.0; n];
    for (c, cell) in cs.iter().enumerate() {
        // underflow: at most `TINY` per entry of each product (`m₀·η`) and
        // `η` per halved entry of S and D, each times `|x|max` (or 1)
        let x_sum = cell.x_abs.iter().fold(1.0, |a, v| a + v) * 1.0625;
        let mut up = Vec::with_capacity(if both { 2 * k } else { k });
        for sign in [1.0, -1.0] {
            if sign < 0.0 && !both {
                break;
            }
            for j in 0..k {
                // upper: W S + |W| D; of the negated row: |W| D − W S
                for (kk, v) in coef.iter_mut().enumerate() {
                    let (pv, qv) = (p[(j, c * width + kk)], q[(j, c * width + kk)]);
                    *v = sign * pv + qv;
                }
                let off_p = p[(j, c * width + n)];
                let off_q = q[(j, c * width + n)];
                let mut acc = Acc::of(dot_box_upper(&coef, &cell.x.lo, &cell.x.hi));
                acc.add(sign * off_p + off_q);
                acc.add(sign * offset[j]);
                acc.add((kappa * row_abs[j] * tau[c] * 1.0625 + TINY).next_up());
                acc.add((TINY * (2.0 + row_abs[j]) * x_sum * 1.0625).next_up());
                if let Some(e) = &err_rows {
                    let mut t = Acc::ZERO;
                    t.add_products(&e[j][..n_h], &cell.h_abs[0]);
                    t.add(e[j][n_h]);
                    acc.add(t.upper());
                }
                up.push(acc.upper());
            }
        }
        out.push(up);
    }
    out
}

/// Upper bounds, per cell, of the rows on `h_g` (`rows`, `k × (width + 1)`,
/// the last column the offset) back-substituted through the activations
/// and affine layers `g, …, 0` cell by cell, all cells' rows stacked in
/// one matrix (row `c·k + r`: cell `c`'s row `r`) multiplied by each
/// layer's `W` as it is stored. `err` bounds the rounding error of `rows`
/// entry by entry (same shape).
fn stacked(
    chain: &Chain,
    cs: &[Cell],
    rows: &DMatrix<f64>,
    err: Option<&DMatrix<f64>>,
    g: usize,
) -> Vec<Vec<f64>> {
    let k = rows.nrows();
    let (mut lam, mut acc) = stacked_start(cs, rows, err, g);
    // per row: Σᵢ |λᵢ|·mᵢ for the current error term
    let mut abs_sum = vec![0.0f64; acc.len()];
    let mut layer = g;
    loop {
        stacked_activation(cs, layer, k, &mut lam, &mut acc, &mut abs_sum);
        let next = stacked_affine(chain, cs, layer, k, &lam, &mut acc, &mut abs_sum);
        if layer == 0 {
            return stacked_finish(cs, k, &next, &acc);
        }
        lam = next;
        layer -= 1;
    }
}

/// The start of [`stacked`]: the coefficients of every cell's rows, one
/// row each, and their offsets with the rows' rounding error over `h_g`.
fn stacked_start(
    cs: &[Cell],
    rows: &DMatrix<f64>,
    err: Option<&DMatrix<f64>>,
    g: usize,
) -> (DMatrix<f64>, Vec<Acc>) {
    let k = rows.nrows();
    let width = rows.ncols() - 1;
    let cells = cs.len();
    let total = k * cells;
    // lam: the coefficients of every cell's rows, one row each
    let mut lam = DMatrix::zeros(total, width);
    for i in 0..width {
        let src = &rows.as_slice()[i * k..(i + 1) * k];
        let dst = &mut lam.as_mut_slice()[i * total..(i + 1) * total];
        for c in 0..cells {
            dst[c * k..(c + 1) * k].copy_from_slice(src);
        }
    }
    let mut acc = vec![Acc::ZERO; total];
    for (c, cell) in cs.iter().enumerate() {
        for r in 0..k {
            let a = &mut acc[c * k + r];
            a.add(rows[(r, width)]);
            if let Some(e) = err {
                // Σᵢ eᵢ·|hᵢ|max + e_offset
                let mut t = Acc::ZERO;
                for i in 0..width {
                    t.add(mul0(e[(r, i)], cell.h_abs[g][i]));
                }
                t.add(e[(r, width)]);
                a.add(t.upper());
            }
        }
    }
    (lam, acc)
}

/// A step of [`stacked`] through the activation `h_layer = σ(z_layer)`:
/// each cell's `k` rows `lam` onto `z_layer` (the line each coefficient's
/// sign selects), the intercepts into the offsets `acc`, column by column,
/// and the products' error `2u·Σ|λ'ᵢ|·|zᵢ|max` (`abs_sum` the scratch).
fn stacked_activation(
    cs: &[Cell],
    layer: usize,
    k: usize,
    lam: &mut DMatrix<f64>,
    acc: &mut [Acc],
    abs_sum: &mut [f64],
) {
    let (total, m) = lam.shape();
    abs_sum.iter_mut().for_each(|v| *v = 0.0);
    for i in 0..m {
        let column = &mut lam.as_mut_slice()[i * total..(i + 1) * total];
        for (c, cell) in cs.iter().enumerate() {
            let r = cell.relax[layer][i];
            let za = cell.z_abs[layer][i];
            for (j, l) in column[c * k..(c + 1) * k].iter_mut().enumerate() {
                let idx = c * k + j;
                let (slope, icpt) = if *l >= 0.0 {
                    (r.au, r.bu)
                } else {
                    (r.al, r.bl)
                };
                let t = mul0(*l, icpt);
                *l = mul0(*l, slope);
                if t != 0.0 {
                    acc[idx].add(t);
                }
                abs_sum[idx] += mul0(l.abs(), za);
            }
        }
    }
    // the products λ·a: at most 2u·Σ|λ'ᵢ|·|zᵢ|max (as `slack`)
    for (a, v) in acc.iter_mut().zip(abs_sum.iter()) {
        a.add((2.0 * U * v * 1.0625 + TINY).next_up());
    }
}

/// A step of [`stacked`] through the affine layer
/// `z_layer = W h_{layer−1} + b` (`x` for layer 0): the coefficients `λ W`
/// for all rows at once (returned), the offsets `λ·b` into `acc`, and the
/// error, at most `γ·Σ|λᵢ|·scaleᵢ` (scale = `|W|·|h|max + |b|`), and the
/// product's underflow (`abs_sum` the scratch).
fn stacked_affine(
    chain: &Chain,
    cs: &[Cell],
    layer: usize,
    k: usize,
    lam: &DMatrix<f64>,
    acc: &mut [Acc],
    abs_sum: &mut [f64],
) -> DMatrix<f64> {
    let (total, m) = lam.shape();
    let (w, b) = (chain.w[layer], chain.b[layer]);
    abs_sum.iter_mut().for_each(|v| *v = 0.0);
    for i in 0..m {
        let column = &lam.as_slice()[i * total..(i + 1) * total];
        let bi = b[i];
        for (c, cell) in cs.iter().enumerate() {
            let si = cell.scale[layer][i];
            for (j, &l) in column[c * k..(c + 1) * k].iter().enumerate() {
                let idx = c * k + j;
                let t = mul0(l, bi);
                if t != 0.0 {
                    acc[idx].add(t);
                }
                abs_sum[idx] += mul0(l.abs(), si);
            }
        }
    }
    let next = lam * w;
    let terms = m + 2;
    for (c, cell) in cs.iter().enumerate() {
        // underflow: at most `m·η ≤ TINY` per entry of the product,
        // each times its input's `|h|max`
        let h_abs = if layer == 0 {
            &cell.x_abs
        } else {
            &cell.h_abs[layer - 1]
        };
        let under = (TINY * h_abs.iter().fold(1.0, |a, v| a + v) * 1.0625).next_up();
        for r in 0..k {
            let idx = c * k + r;
            let a = &mut acc[idx];
            a.add((gamma(terms) * abs_sum[idx] * 1.0625 + TINY).next_up());
            a.add(under);
        }
    }
    next
}

/// The end of [`stacked`]: each cell's `k` rows `coef` on the input, with
/// offsets `acc`, bounded over the cell's box.
fn stacked_finish(cs: &[Cell], k: usize, coef_all: &DMatrix<f64>, acc: &[Acc]) -> Vec<Vec<f64>> {
    let inner = coef_all.ncols();
    let mut coef = vec![0.0; inner];
    let mut out = Vec::with_capacity(cs.len());
    for (c, cell) in cs.iter().enumerate() {
        let ups = (0..k)
            .map(|r| {
                let idx = c * k + r;
                for (q, v) in coef.iter_mut().enumerate() {
                    *v = coef_all[(idx, q)];
                }
                let mut a = acc[idx];
                a.add(dot_box_upper(&coef, &cell.x.lo, &cell.x.hi));
                a.upper()
            })
            .collect();
        out.push(ups);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crown::Mode;
    use crate::crown::Relaxation;

    /// The single-cell bounds: the support of the mode's output box, and
    /// the mode's bound of each row.
    fn cell_offsets(net: &Network, cell: &IBox, dirs: &DMatrix<f64>, mode: Mode) -> Vec<f64> {
        let a = Relaxation::new(net, cell, mode);
        let out = a.output_box(mode);
        let mut b = support_of_box(dirs, &out.lo, &out.hi);
        for (v, c) in b.iter_mut().zip(a.upper(dirs.clone()).concretize(cell)) {
            *v = v.min(c);
        }
        b
    }
    use ravel_base::rng::Rng;

    fn network(rng: &mut Rng, widths: &[usize], act: Activation) -> Network {
        let mut layers = Vec::new();
        for (k, pair) in widths.windows(2).enumerate() {
            let s = 1.5 / (pair[0] as f64).sqrt();
            layers.push(Layer::Affine {
                w: DMatrix::from_fn(pair[1], pair[0], |_, _| rng.uniform(-s, s)),
                b: DVector::from_fn(pair[1], |_, _| rng.uniform(-0.3, 0.3)),
            });
            if k + 2 < widths.len() {
                layers.push(Layer::Act(act));
            }
        }
        Network::new(widths[0], layers)
    }

    fn directions(rng: &mut Rng, m: usize) -> DMatrix<f64> {
        // [I; −I] and three random directions
        DMatrix::from_fn(2 * m + 3, m, |r, c| {
            if r < m {
                f64::from(u8::from(r == c))
            } else if r < 2 * m {
                -f64::from(u8::from(r - m == c))
            } else {
                0.0
            }
        })
        .map_with_location(|r, _, v| {
            if r >= 2 * m {
                rng.uniform(-1.0, 1.0)
            } else {
                v
            }
        })
    }

    /// Asserts that `count` uniform points of `cell` have every `dᵣ·f(x)`
    /// at most `bounds[r]`; returns the number of checks.
    fn above_samples(
        net: &Network,
        cell: &IBox,
        dirs: &DMatrix<f64>,
        bounds: &[f64],
        rng: &mut Rng,
        count: usize,
    ) -> usize {
        for _ in 0..count {
            let x: Vec<f64> = (0..cell.dim())
                .map(|i| rng.uniform(cell.lo[i], cell.hi[i]))
                .collect();
            let y = net.forward(&x);
            for (r, b) in bounds.iter().enumerate() {
                let v: f64 = dirs.row(r).iter().zip(&y).map(|(d, y)| d * y).sum();
                assert!(
                    v <= *b + 1e-12 * (1.0 + v.abs()),
                    "{v} above {b} on {cell:?}"
                );
            }
        }
        count * bounds.len()
    }

    /// Every batched offset is the single-cell analysis's up to rounding
    /// terms, and above every sampled output of its cell: ReLU, tanh and
    /// sigmoid networks (and mixed), CROWN and Fast-Lin.
    #[test]
    fn batched_offsets_match_the_single_cell_analysis_and_contain_samples() {
        let shapes: [&[usize]; 6] = [
            &[2, 8, 3],
            &[3, 16, 16, 2],
            &[2, 12, 10, 8, 3],
            &[6, 48, 48, 3],
            &[1, 5, 1],
            &[4, 7, 9, 6, 5, 2],
        ];
        let mut rng = Rng::new(11);
        let mut compared = 0;
        let acts = [Activation::Relu, Activation::Tanh, Activation::Sigmoid];
        for widths in shapes {
            for t in 0..6 {
                let mode = if t % 2 == 0 {
                    Mode::Crown
                } else {
                    Mode::FastLin
                };
                let mut net = network(&mut rng, widths, acts[(t / 2) % 3]);
                if t == 5 {
                    // mixed activations: the first one a ReLU
                    if let Some(Layer::Act(a)) = net.layers.get_mut(1) {
                        *a = Activation::Relu;
                    }
                }
                let n = widths[0];
                let m = *widths.last().unwrap();
                let dirs = directions(&mut rng, m);
                let lo: Vec<f64> = (0..n).map(|_| rng.uniform(-1.0, 0.0)).collect();
                let hi: Vec<f64> = lo.iter().map(|l| l + rng.uniform(0.1, 1.5)).collect();
                let input = IBox::new(lo, hi);
                let counts: Vec<usize> = (0..n).map(|i| if i < 3 { 3 } else { 1 }).collect();
                let cells = input.grid(&counts);
                let batched = crown_offsets(&net, &cells, &dirs, mode).expect("a chain");
                assert_eq!(batched.len(), cells.len());
                for (cell, got) in cells.iter().zip(&batched) {
                    let want = cell_offsets(&net, cell, &dirs, mode);
                    for (g, w) in got.iter().zip(&want) {
                        assert!(
                            (g - w).abs() <= 1e-9 * (1.0 + w.abs()),
                            "{widths:?} {mode:?}: batched {g} against {w}"
                        );
                        compared += 1;
                    }
                    above_samples(&net, cell, &dirs, got, &mut rng, 40);
                }
            }
        }
        assert!(compared > 4000, "{compared}");
    }

    /// Networks that are not chains, interval mode, and cells that are not
    /// finite are left to the single-cell path.
    #[test]
    fn other_networks_and_non_finite_cells_decline() {
        let mut rng = Rng::new(3);
        let dirs = directions(&mut rng, 2);
        let cell = IBox::new(vec![-1.0, -1.0], vec![1.0, 1.0]);
        let one = std::slice::from_ref(&cell);
        let crown = Mode::Crown;
        let affine = network(&mut rng, &[2, 2], Activation::Relu);
        assert!(crown_offsets(&affine, one, &dirs, crown).is_none());
        let relu = network(&mut rng, &[2, 5, 2], Activation::Relu);
        assert!(crown_offsets(&relu, one, &dirs, crown).is_some());
        assert!(crown_offsets(&relu, one, &dirs, Mode::Ibp).is_none());
        let mut two_acts = relu.clone();
        two_acts.layers.insert(2, Layer::Act(Activation::Tanh));
        assert!(crown_offsets(&two_acts, one, &dirs, crown).is_none());
        // a direction near the top of f64: finite, and above the samples
        let huge = DMatrix::from_row_slice(1, 2, &[1e308, 1e308]);
        let near = crown_offsets(&relu, one, &huge, crown).expect("finite");
        above_samples(&relu, &cell, &huge, &near[0], &mut rng, 2000);
        // ... and past it, on outputs a hundred times larger: declined
        let mut loud = relu.clone();
        if let Some(Layer::Affine { w, b }) = loud.layers.last_mut() {
            *w *= 100.0;
            *b *= 100.0;
        }
        assert!(crown_offsets(&loud, one, &huge, crown).is_none());
        let nan = IBox::new(vec![f64::NAN, -1.0], vec![1.0, 1.0]);
        assert!(crown_offsets(&relu, &[cell.clone(), nan], &dirs, crown).is_none());
        let huge = IBox::new(vec![-1e300, -1.0], vec![1e300, 1.0]);
        let big = network(&mut rng, &[2, 5, 5, 2], Activation::Relu);
        let big = Network::new(
            2,
            big.layers
                .into_iter()
                .map(|l| match l {
                    Layer::Affine { w, b } => Layer::Affine { w: w * 1e10, b },
                    a => a,
                })
                .collect(),
        );
        assert!(crown_offsets(&big, &[cell, huge], &dirs, crown).is_none());
    }

    /// The propagators' order on every cell of a grid: the batched CROWN
    /// output box is never looser than interval arithmetic's (run on 400
    /// networks while writing this: none of 10 800 sides was).
    #[test]
    fn batched_boxes_are_never_looser_than_interval_arithmetic() {
        let mut rng = Rng::new(77);
        let mut sides = 0;
        for t in 0..100 {
            let widths: &[usize] = match t % 4 {
                0 => &[2, 8, 3],
                1 => &[3, 16, 16, 2],
                2 => &[2, 12, 10, 8, 3],
                _ => &[4, 32, 32, 4],
            };
            let net = network(&mut rng, widths, Activation::Relu);
            let (n, m) = (widths[0], widths[widths.len() - 1]);
            let pm = DMatrix::from_fn(2 * m, m, |r, c| {
                if r == c {
                    1.0
                } else if r == m + c {
                    -1.0
                } else {
                    0.0
                }
            });
            let lo: Vec<f64> = (0..n).map(|_| rng.uniform(-1.0, 0.0)).collect();
            let hi: Vec<f64> = lo.iter().map(|l| l + rng.uniform(0.1, 1.5)).collect();
            let counts: Vec<usize> = (0..n).map(|i| if i < 2 { 3 } else { 1 }).collect();
            let cells = IBox::new(lo, hi).grid(&counts);
            let got = crown_offsets(&net, &cells, &pm, Mode::Crown).expect("a ReLU chain");
            for (cell, g) in cells.iter().zip(&got) {
                let ibp = Relaxation::new(&net, cell, Mode::Ibp).output_box(Mode::Ibp);
                for j in 0..m {
                    assert!(g[j] <= ibp.hi[j] && -g[m + j] >= ibp.lo[j], "case {t}");
                    sides += 2;
                }
            }
        }
        assert!(sides > 2000, "{sides}");
    }

    /// Degenerate widths (a hidden layer of one neuron or of none, one
    /// output, one input) neither panic nor differ from the single-cell
    /// analysis.
    #[test]
    fn degenerate_widths_match_the_single_cell_analysis() {
        let mut rng = Rng::new(8);
        let shapes: [&[usize]; 5] = [
            &[2, 0, 3],
            &[2, 1, 1],
            &[1, 1, 1, 1],
            &[3, 0, 0, 2],
            &[1, 6, 1, 6, 1],
        ];
        for widths in shapes {
            let net = network(&mut rng, widths, Activation::Relu);
            let m = widths[widths.len() - 1];
            let dirs = directions(&mut rng, m);
            let n = widths[0];
            let input = IBox::new(vec![-0.5; n], vec![0.7; n]);
            let cells = input.grid(&vec![2; n]);
            for mode in [Mode::Crown, Mode::FastLin] {
                let got = crown_offsets(&net, &cells, &dirs, mode).expect("a chain");
                for (cell, g) in cells.iter().zip(&got) {
                    let want = cell_offsets(&net, cell, &dirs, mode);
                    for (g, w) in g.iter().zip(&want) {
                        assert!(
                            (g - w).abs() <= 1e-9 * (1.0 + w.abs()),
                            "{widths:?}: {g} against {w}"
                        );
                    }
                }
            }
        }
    }

    /// An opt-in campaign (`cargo test --release -- --ignored
    /// batched_bounds_campaign`, `RAVEL_BATCH_CASES` networks, 2000 by
    /// default): random depths, widths, activations (mixed), modes and
    /// grids; every batched bound equal to the single-cell analysis's up
    /// to rounding terms, above every sampled output, and the output box
    /// never looser than interval arithmetic's.
    #[test]
    #[ignore]
    fn batched_bounds_campaign() {
        let cases: usize = std::env::var("RAVEL_BATCH_CASES")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(2000);
        let mut rng = Rng::new(0xBA7C);
        let acts = [Activation::Relu, Activation::Tanh, Activation::Sigmoid];
        let (mut bounds, mut samples) = (0usize, 0usize);
        let mut worst = 0.0f64;
        for case in 0..cases {
            let depth = 1 + rng.below(4);
            let n = 1 + rng.below(6);
            let m = 1 + rng.below(4);
            let mut widths = vec![n];
            widths.extend((0..depth).map(|_| 1 + rng.below(48)));
            widths.push(m);
            let mut net = network(&mut rng, &widths, Activation::Relu);
            for l in net.layers.iter_mut() {
                if let Layer::Act(a) = l {
                    *a = acts[rng.below(3)];
                }
            }
            let mode = if case % 3 == 2 {
                Mode::FastLin
            } else {
                Mode::Crown
            };
            let dirs = directions(&mut rng, m);
            let lo: Vec<f64> = (0..n).map(|_| rng.uniform(-2.0, 1.0)).collect();
            let hi: Vec<f64> = lo.iter().map(|l| l + rng.uniform(1e-6, 2.0)).collect();
            let counts: Vec<usize> = (0..n).map(|_| 1 + rng.below(3)).collect();
            let cells = IBox::new(lo, hi).grid(&counts);
            let got = crown_offsets(&net, &cells, &dirs, mode).expect("a chain");
            for (cell, g) in cells.iter().zip(&got) {
                let want = cell_offsets(&net, cell, &dirs, mode);
                for (g, w) in g.iter().zip(&want) {
                    let rel = (g - w).abs() / (1.0 + w.abs());
                    worst = worst.max(rel);
                    assert!(
                        rel <= 1e-9,
                        "case {case} {widths:?} {mode:?}: {g} against {w}"
                    );
                    bounds += 1;
                }
                let ibp = Relaxation::new(&net, cell, Mode::Ibp).output_box(Mode::Ibp);
                for j in 0..m {
                    assert!(
                        g[j] <= ibp.hi[j] && -g[m + j] >= ibp.lo[j],
                        "case {case}: IBP"
                    );
                }
                samples += above_samples(&net, cell, &dirs, g, &mut rng, 50);
            }
        }
        eprintln!("{cases} networks: {bounds} bounds, {samples} sampled checks, largest relative difference {worst:.2e}");
    }
}
