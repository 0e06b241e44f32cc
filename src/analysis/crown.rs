//! Bounds on networks over boxes: interval bound propagation (IBP) and CROWN.
//!
//! CROWN computes, for a specification matrix `S`, linear functions with
//! `S f(y) ≤ Λ y + c` for every `y` in the input box. Pre-activation bounds of
//! every hidden layer are themselves computed by CROWN (and intersected with
//! IBP's), then each neuron is relaxed by [`relax`](super::relax).
//!
//! All coefficient arithmetic is done in `f64`; the rounding error of every
//! matrix product is accounted for by widening the offset with
//! `γ(n)·|Λ|·(|W|·|h|max)` (see [`LinearUpper::through_affine`]), so the
//! returned bounds hold for the exact network.

use nalgebra::{DMatrix, DVector};

use super::relax::{image, relax, Relax};
use crate::issue::Issue;
use crate::nn::{Layer, Network};
use crate::num::{dot_box_lower, dot_box_upper, gamma, sum_lower, sum_upper, U};
use crate::sets::{IBox, Region};

/// Rows of linear upper bounds: `sᵣ ≤ coefᵣ · z + offsetᵣ` for every feasible `z`.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearUpper {
    /// `k × n` coefficients.
    pub coef: DMatrix<f64>,
    /// `k` offsets.
    pub offset: Vec<f64>,
}

impl LinearUpper {
    /// The identity bound `sᵣ ≤ Fᵣ z` for a specification matrix `F`.
    pub fn of_spec(f: DMatrix<f64>) -> LinearUpper {
        let k = f.nrows();
        LinearUpper {
            coef: f,
            offset: vec![0.0; k],
        }
    }

    /// Substitute `z = W z' + b` (exactly), where `|z'| ≤ abs_in` element-wise.
    /// The product `coef · W` is rounded; its error is added to the offsets.
    pub fn through_affine(
        &self,
        w: &DMatrix<f64>,
        b: &DVector<f64>,
        abs_in: &[f64],
    ) -> LinearUpper {
        self.through_affine_scaled(w, b, &weight_scale(w, abs_in))
    }

    /// [`LinearUpper::through_affine`] with `|W|·|z'|max` precomputed (see [`weight_scale`]).
    pub fn through_affine_scaled(
        &self,
        w: &DMatrix<f64>,
        b: &DVector<f64>,
        wz: &[f64],
    ) -> LinearUpper {
        let coef = &self.coef * w;
        let k = gamma(w.nrows() + 2);
        let offset = (0..self.coef.nrows())
            .map(|r| {
                let row = self.coef.row(r);
                let err = slack_iter(k, row.iter().copied(), wz);
                let products = row.iter().zip(b.iter()).map(|(l, b)| l * b);
                sum_upper(products.chain([self.offset[r], err]))
            })
            .collect();
        LinearUpper { coef, offset }
    }

    /// The sum of two bounds on the same variables (`|z| ≤ abs_in`).
    pub fn add(&self, other: &LinearUpper, abs_in: &[f64]) -> LinearUpper {
        let coef = &self.coef + &other.coef;
        let offset = (0..coef.nrows())
            .map(|r| {
                sum_upper([
                    self.offset[r],
                    other.offset[r],
                    slack_iter(2.0 * U, coef.row(r).iter().copied(), abs_in),
                ])
            })
            .collect();
        LinearUpper { coef, offset }
    }

    /// Keep the first `keep` variables and bound the rest over `tail` (added to
    /// the offsets): a bound on `(z, ζ)` becomes one on `z` valid for all `ζ ∈ tail`.
    pub fn split_concretize(&self, keep: usize, tail: &IBox) -> LinearUpper {
        let k = self.coef.nrows();
        let coef = self.coef.columns(0, keep).into_owned();
        let offset = (0..k)
            .map(|r| {
                let row: Vec<f64> = (keep..self.coef.ncols())
                    .map(|c| self.coef[(r, c)])
                    .collect();
                sum_upper([self.offset[r], dot_box_upper(&row, &tail.lo, &tail.hi)])
            })
            .collect();
        LinearUpper { coef, offset }
    }

    /// Certified upper bounds of each row over a region, and the solver
    /// issues met (each bound is valid regardless; see [`crate::lp`]).
    pub fn concretize_region(&self, region: &Region) -> (Vec<f64>, Vec<Issue>) {
        if let Region::Box(b) = region {
            return (self.concretize(b), Vec::new());
        }
        let mut issues = Vec::new();
        let ub = (0..self.coef.nrows())
            .map(|r| {
                let row: Vec<f64> = self.coef.row(r).iter().copied().collect();
                let s = region.support(&row);
                issues.extend(s.issue);
                sum_upper([s.value, self.offset[r]])
            })
            .collect();
        (ub, issues)
    }

    /// Certified upper bounds of each row over the box.
    pub fn concretize(&self, b: &IBox) -> Vec<f64> {
        (0..self.coef.nrows())
            .map(|r| {
                let row = self.coef.row(r);
                let terms = row
                    .iter()
                    .zip(b.lo.iter().zip(&b.hi))
                    .map(|(&a, (&l, &h))| {
                        if a == 0.0 {
                            0.0
                        } else if a > 0.0 {
                            a * h
                        } else {
                            a * l
                        }
                    });
                sum_upper(terms.chain([self.offset[r]]))
            })
            .collect()
    }
}

/// `|W|·m` rounded up, for `|z| ≤ m`: the scale of the rounding error of products with `W`.
pub fn weight_scale(w: &DMatrix<f64>, m: &[f64]) -> Vec<f64> {
    (0..w.nrows())
        .map(|j| sum_upper((0..w.ncols()).map(|i| w[(j, i)].abs() * m[i])))
        .collect()
}

/// `k · Σ|aᵢ|·mᵢ` rounded up: a bound on the error of rounded coefficients `a` applied to `|z| ≤ m`.
fn slack_iter(k: f64, a: impl Iterator<Item = f64>, m: &[f64]) -> f64 {
    let mut s = 0.0;
    let mut n = 0usize;
    for (a, m) in a.zip(m) {
        if a != 0.0 {
            s += a.abs() * m;
        }
        n += 1;
    }
    (k * s * 1.0625 + (n as f64 + 2.0) * crate::num::ETA).next_up()
}

/// The `2n × n` specification `[I; −I]`: upper bounds, then negated lower bounds.
pub fn plus_minus_identity(n: usize) -> DMatrix<f64> {
    DMatrix::from_fn(2 * n, n, |r, c| {
        if r == c {
            1.0
        } else if r == n + c {
            -1.0
        } else {
            0.0
        }
    })
}

/// Certified interval image of a box under `z = W x + b`.
pub fn affine_image(w: &DMatrix<f64>, b: &DVector<f64>, x: &IBox) -> IBox {
    let mut lo = Vec::with_capacity(w.nrows());
    let mut hi = Vec::with_capacity(w.nrows());
    for j in 0..w.nrows() {
        let row: Vec<f64> = w.row(j).iter().copied().collect();
        lo.push(sum_lower([dot_box_lower(&row, &x.lo, &x.hi), b[j]]));
        hi.push(sum_upper([dot_box_upper(&row, &x.lo, &x.hi), b[j]]));
    }
    IBox::new(lo, hi)
}

/// Other certified upper bounds of a linear bound's rows (see [`Analysis::with_hook`]).
pub type BoundHook<'h> = dyn Fn(&LinearUpper) -> Vec<f64> + 'h;

/// How hidden-layer bounds are computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Interval arithmetic only.
    Ibp,
    /// CROWN bounds for every pre-activation (intersected with IBP).
    Crown,
}

/// A network analysed over one input box: the bounds of every intermediate
/// value and the relaxation of every activation.
#[derive(Clone, Debug)]
pub struct Analysis<'a> {
    net: &'a Network,
    /// `boxes[i]` bounds the value before layer `i` (`boxes[0]` is the input box).
    boxes: Vec<IBox>,
    /// The relaxation of each activation layer (empty for affine layers).
    relax: Vec<Vec<Relax>>,
    /// `|W|·|h|max` of each affine layer (empty for activations), for error terms.
    scales: Vec<Vec<f64>>,
}

impl<'a> Analysis<'a> {
    /// Bound every layer of `net` over `input`.
    pub fn new(net: &'a Network, input: &IBox, mode: Mode) -> Analysis<'a> {
        Analysis::with_hook(net, input, mode, None)
    }

    /// [`Analysis::new`], where in CROWN mode the linear bound of every
    /// pre-activation (a [`LinearUpper`] over the network input) is also
    /// handed to `hook`, which returns other certified upper bounds of its
    /// rows; the tighter of the two is kept. The unrolled closed-loop
    /// propagator uses this to bound hidden neurons through earlier steps.
    pub fn with_hook(
        net: &'a Network,
        input: &IBox,
        mode: Mode,
        hook: Option<&BoundHook>,
    ) -> Analysis<'a> {
        let mut a = Analysis {
            net,
            boxes: vec![input.clone()],
            relax: Vec::with_capacity(net.layers.len()),
            scales: Vec::with_capacity(net.layers.len()),
        };
        for (i, layer) in net.layers.iter().enumerate() {
            let current = &a.boxes[i];
            a.scales.push(match layer {
                Layer::Affine { w, .. } => weight_scale(w, &current.abs_max()),
                Layer::Act(_) => Vec::new(),
            });
            let current = &a.boxes[i];
            let (next, rel) = match layer {
                Layer::Affine { w, b } => {
                    let mut next = affine_image(w, b, current);
                    let feeds_activation = matches!(net.layers.get(i + 1), Some(Layer::Act(_)));
                    if mode == Mode::Crown && feeds_activation {
                        let n = w.nrows();
                        let bound = a.backward(plus_minus_identity(n), i + 1);
                        let mut both = bound.concretize(input);
                        if let Some(h) = hook {
                            for (b, o) in both.iter_mut().zip(h(&bound)) {
                                *b = b.min(o);
                            }
                        }
                        for j in 0..n {
                            next.hi[j] = next.hi[j].min(both[j]);
                            next.lo[j] = next.lo[j].max(-both[n + j]);
                        }
                    }
                    (next, Vec::new())
                }
                Layer::Act(act) => {
                    let rel: Vec<Relax> = (0..current.dim())
                        .map(|j| relax(*act, current.lo[j], current.hi[j]))
                        .collect();
                    let (lo, hi) = (0..current.dim())
                        .map(|j| image(*act, current.lo[j], current.hi[j]))
                        .unzip();
                    (IBox::new(lo, hi), rel)
                }
            };
            a.boxes.push(next);
            a.relax.push(rel);
        }
        a
    }

    /// Whether every intermediate bound is finite. An analysis that is not
    /// (its input or weights too large for `f64`) must not be used: the
    /// propagators check this and report an overflow instead.
    pub fn is_finite(&self) -> bool {
        self.boxes.iter().all(IBox::is_finite)
            && self.scales.iter().flatten().all(|v| v.is_finite())
    }

    /// The bounds of the value before every layer (`boxes()[0]` is the input box).
    pub fn boxes(&self) -> &[IBox] {
        &self.boxes
    }

    /// Bounds of the network output (IBP, or CROWN intersected with IBP).
    pub fn output_box(&self, mode: Mode) -> IBox {
        let ibp = self
            .boxes
            .last()
            .cloned()
            .unwrap_or_else(|| self.boxes[0].clone());
        if mode == Mode::Ibp {
            return ibp;
        }
        let m = ibp.dim();
        let both = self
            .upper(plus_minus_identity(m))
            .concretize(&self.boxes[0]);
        let lo = (0..m).map(|j| ibp.lo[j].max(-both[m + j])).collect();
        let hi = (0..m).map(|j| ibp.hi[j].min(both[j])).collect();
        IBox::new(lo, hi)
    }

    /// CROWN: `S f(y) ≤ Λ y + c` over the input box, for a `k × outputs` matrix `S`.
    pub fn upper(&self, spec: DMatrix<f64>) -> LinearUpper {
        self.backward(spec, self.net.layers.len())
    }

    /// Back-substitute a bound on the value at position `end` down to the input.
    fn backward(&self, spec: DMatrix<f64>, end: usize) -> LinearUpper {
        let mut bound = LinearUpper::of_spec(spec);
        for i in (0..end).rev() {
            bound = match &self.net.layers[i] {
                Layer::Affine { w, b } => bound.through_affine_scaled(w, b, &self.scales[i]),
                Layer::Act(_) => {
                    through_relaxation(&bound, &self.relax[i], &self.boxes[i].abs_max())
                }
            };
        }
        bound
    }
}

/// Replace `Λ h` by its relaxation in terms of `z` (`h = σ(z)`).
fn through_relaxation(bound: &LinearUpper, rel: &[Relax], abs_in: &[f64]) -> LinearUpper {
    let k = bound.coef.nrows();
    let mut coef = DMatrix::<f64>::zeros(k, rel.len());
    let mut offset = Vec::with_capacity(k);
    for r in 0..k {
        let mut terms = Vec::with_capacity(rel.len() + 2);
        terms.push(bound.offset[r]);
        for (j, rl) in rel.iter().enumerate() {
            let l = bound.coef[(r, j)];
            let (a, b) = if l >= 0.0 {
                (rl.au, rl.bu)
            } else {
                (rl.al, rl.bl)
            };
            coef[(r, j)] = l * a;
            if l != 0.0 {
                terms.push(l * b);
            }
        }
        terms.push(slack_iter(2.0 * U, coef.row(r).iter().copied(), abs_in));
        offset.push(sum_upper(terms));
    }
    LinearUpper { coef, offset }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::Activation;

    fn net() -> Network {
        Network::new(
            2,
            vec![
                Layer::Affine {
                    w: DMatrix::from_row_slice(3, 2, &[1.0, -1.0, 0.5, 2.0, -1.5, 0.3]),
                    b: DVector::from_column_slice(&[0.1, -0.2, 0.3]),
                },
                Layer::Act(Activation::Relu),
                Layer::Affine {
                    w: DMatrix::from_row_slice(1, 3, &[1.0, -2.0, 0.7]),
                    b: DVector::from_column_slice(&[0.05]),
                },
            ],
        )
    }

    #[test]
    fn crown_is_no_looser_than_ibp_and_contains_samples() {
        let n = net();
        let input = IBox::new(vec![-1.0, -0.5], vec![0.5, 1.0]);
        let a = Analysis::new(&n, &input, Mode::Crown);
        let crown = a.output_box(Mode::Crown);
        let ibp = Analysis::new(&n, &input, Mode::Ibp).output_box(Mode::Ibp);
        assert!(ibp.contains_box(&crown));
        for i in 0..=20 {
            for j in 0..=20 {
                let x = [-1.0 + 1.5 * i as f64 / 20.0, -0.5 + 1.5 * j as f64 / 20.0];
                assert!(crown.contains_point(&n.forward(&x)));
            }
        }
    }
}
