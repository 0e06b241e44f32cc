//! Sets over the state space: axis-aligned boxes and polytopes `{x | H x ≤ h}`.

use crate::lp::{self, LpBound};
use ravel_base::num;

/// A closed axis-aligned box `lo ≤ x ≤ hi`. Bounds may be infinite.
#[derive(Clone, Debug, PartialEq)]
pub struct IBox {
    /// Lower bounds.
    pub lo: Vec<f64>,
    /// Upper bounds.
    pub hi: Vec<f64>,
}

impl IBox {
    /// A box from its bounds (same length, `lo ≤ hi`).
    pub fn new(lo: Vec<f64>, hi: Vec<f64>) -> IBox {
        debug_assert_eq!(lo.len(), hi.len());
        IBox { lo, hi }
    }

    /// The single point `x`.
    pub fn point(x: &[f64]) -> IBox {
        IBox::new(x.to_vec(), x.to_vec())
    }

    /// Dimension.
    pub fn dim(&self) -> usize {
        self.lo.len()
    }

    /// The whole space `ℝⁿ`: what a bound that overflowed is replaced by.
    pub fn whole(n: usize) -> IBox {
        IBox::new(vec![f64::NEG_INFINITY; n], vec![f64::INFINITY; n])
    }

    /// Whether every bound is a finite number (no NaN, no ±∞).
    pub fn is_finite(&self) -> bool {
        self.lo.iter().chain(&self.hi).all(|v| v.is_finite())
    }

    /// Largest absolute value of each coordinate.
    pub fn abs_max(&self) -> Vec<f64> {
        self.lo
            .iter()
            .zip(&self.hi)
            .map(|(l, h)| num::abs_max(*l, *h))
            .collect()
    }

    /// Whether `x` lies in the box.
    pub fn contains_point(&self, x: &[f64]) -> bool {
        x.iter()
            .zip(self.lo.iter().zip(&self.hi))
            .all(|(x, (l, h))| l <= x && x <= h)
    }

    /// Whether `other` lies inside this box.
    pub fn contains_box(&self, other: &IBox) -> bool {
        (0..self.dim()).all(|i| self.lo[i] <= other.lo[i] && other.hi[i] <= self.hi[i])
    }

    /// The smallest box containing both.
    pub fn hull(&self, other: &IBox) -> IBox {
        IBox::new(
            self.lo
                .iter()
                .zip(&other.lo)
                .map(|(a, b)| a.min(*b))
                .collect(),
            self.hi
                .iter()
                .zip(&other.hi)
                .map(|(a, b)| a.max(*b))
                .collect(),
        )
    }

    /// Grow this box to its hull with `other`, in place ([`IBox::hull`]'s
    /// numbers, without new vectors). The result does not depend on the
    /// order boxes are added in, to the bit: `−0` counts as below `+0`
    /// (`f64::min` may return either when both are zero), and a NaN bound is
    /// passed over as by `f64::min`/`max`. Threads grow parts of one hull
    /// and merge them (`ravel::execute`'s reach sets).
    pub fn hull_with(&mut self, other: &IBox) {
        for (a, b) in self.lo.iter_mut().zip(&other.lo) {
            *a = if *a == 0.0 && *b == 0.0 {
                if b.is_sign_negative() {
                    *b
                } else {
                    *a
                }
            } else {
                a.min(*b)
            };
        }
        for (a, b) in self.hi.iter_mut().zip(&other.hi) {
            *a = if *a == 0.0 && *b == 0.0 {
                if b.is_sign_positive() {
                    *b
                } else {
                    *a
                }
            } else {
                a.max(*b)
            };
        }
    }

    /// The intersection of two boxes (may be empty if they do not overlap).
    pub fn intersect(&self, other: &IBox) -> IBox {
        IBox::new(
            self.lo
                .iter()
                .zip(&other.lo)
                .map(|(a, b)| a.max(*b))
                .collect(),
            self.hi
                .iter()
                .zip(&other.hi)
                .map(|(a, b)| a.min(*b))
                .collect(),
        )
    }

    /// The concatenation `self × other`.
    pub fn product(&self, other: &IBox) -> IBox {
        let join = |a: &[f64], b: &[f64]| {
            let mut v = Vec::with_capacity(a.len() + b.len());
            v.extend_from_slice(a);
            v.extend_from_slice(b);
            v
        };
        IBox::new(join(&self.lo, &other.lo), join(&self.hi, &other.hi))
    }

    /// `self.product(other).abs_max()`, without building the product.
    pub fn abs_max_with(&self, other: &IBox) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.dim() + other.dim());
        for b in [self, other] {
            out.extend(b.lo.iter().zip(&b.hi).map(|(l, h)| num::abs_max(*l, *h)));
        }
        out
    }

    /// Product of the side lengths (the area in 2-D).
    pub fn volume(&self) -> f64 {
        self.lo.iter().zip(&self.hi).map(|(l, h)| h - l).product()
    }

    /// Split into a uniform grid with `counts[i]` cells along dimension `i`,
    /// in row-major order (last dimension fastest). Cells share faces; their
    /// union is exactly the box (the last cell along each axis ends at `hi`).
    pub fn grid(&self, counts: &[usize]) -> Vec<IBox> {
        let n = self.dim();
        let total: usize = counts.iter().product();
        let mut cells = Vec::with_capacity(total);
        let mut index = vec![0usize; n];
        for _ in 0..total {
            let mut lo = Vec::with_capacity(n);
            let mut hi = Vec::with_capacity(n);
            for d in 0..n {
                let k = counts[d] as f64;
                let w = self.hi[d] - self.lo[d];
                let at = |j: usize| {
                    if j == 0 {
                        self.lo[d]
                    } else if j == counts[d] {
                        self.hi[d]
                    } else {
                        self.lo[d] + w * (j as f64 / k)
                    }
                };
                lo.push(at(index[d]));
                hi.push(at(index[d] + 1));
            }
            cells.push(IBox::new(lo, hi));
            for d in (0..n).rev() {
                index[d] += 1;
                if index[d] < counts[d] {
                    break;
                }
                index[d] = 0;
            }
        }
        cells
    }
}

/// A polytope `{x | H x ≤ h}` given by its rows (possibly unbounded).
#[derive(Clone, Debug, PartialEq)]
pub struct Polytope {
    /// The rows `(Hᵣ, hᵣ)`.
    pub rows: Vec<(Vec<f64>, f64)>,
}

impl Polytope {
    /// The box as a polytope; infinite sides give no row.
    pub fn from_box(b: &IBox) -> Polytope {
        let n = b.dim();
        let mut rows = Vec::new();
        for i in 0..n {
            let mut e = vec![0.0; n];
            if b.hi[i].is_finite() {
                e[i] = 1.0;
                rows.push((e.clone(), b.hi[i]));
            }
            if b.lo[i].is_finite() {
                e[i] = -1.0;
                rows.push((e, -b.lo[i]));
            }
        }
        Polytope { rows }
    }

    /// How far `x` is inside: `min_r (hᵣ − Hᵣ x)` (negative when outside).
    /// Evaluated in `f64`; used for simulated states only.
    pub fn depth(&self, x: &[f64]) -> f64 {
        self.rows
            .iter()
            .map(|(a, b)| b - a.iter().zip(x).map(|(a, x)| a * x).sum::<f64>())
            .fold(f64::INFINITY, f64::min)
    }

    /// A certified lower bound of `min_r (hᵣ − max_{x∈B} Hᵣ x)`: non-negative means `B ⊆ P`.
    pub fn containment_margin(&self, b: &IBox) -> f64 {
        self.rows
            .iter()
            .map(|(a, h)| {
                let up = num::dot_box_upper(a, &b.lo, &b.hi);
                num::sum_lower([*h, -up])
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// A certified lower bound of `max_r (min_{x∈B} Hᵣ x − hᵣ)`: positive means `B ∩ P = ∅`
    /// (a single row separates them). This is a sufficient test for disjointness: a box
    /// can miss a polytope without any single row separating them, which gives a
    /// non-positive margin and an UNSURE verdict, never a wrong one.
    pub fn separation_margin(&self, b: &IBox) -> f64 {
        self.rows
            .iter()
            .map(|(a, h)| {
                let lo = num::dot_box_lower(a, &b.lo, &b.hi);
                num::sum_lower([lo, -*h])
            })
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

/// The norm of an ℓp ball.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Norm {
    /// ℓ1: the sum of absolute values.
    L1,
    /// ℓ2: the Euclidean norm.
    L2,
    /// ℓ∞: the largest absolute value.
    LInf,
}

impl Norm {
    /// The spec-language name (`1`, `2`, `inf`).
    pub fn name(self) -> &'static str {
        match self {
            Norm::L1 => "1",
            Norm::L2 => "2",
            Norm::LInf => "inf",
        }
    }
}

/// An affine enclosure of a reachable set, kept beside its box by the
/// nonlinear closed loop: every state is `c + G s + r` for some
/// `s ∈ [−1, 1]ᵏ` and `r ∈ [r_lo, r_hi]`. Nonlinear constraints are
/// bounded over it by a mean value form
/// ([`crate::nonlinear::integrate::tape_range_affine`]), which keeps the
/// correlations between the states that the box loses.
#[derive(Clone, Debug, PartialEq)]
pub struct Affine {
    /// The centre.
    pub c: Vec<f64>,
    /// One row of `k` coefficients per state.
    pub g: Vec<Vec<f64>>,
    /// The remainder's lower ends.
    pub r_lo: Vec<f64>,
    /// The remainder's upper ends.
    pub r_hi: Vec<f64>,
}

/// A set of states: a box, a bounded polytope (rows plus a bounding box that
/// contains it), or an ℓp ball `{c + diag(r) δ | ‖δ‖ₚ ≤ 1}` with per-dimension radii.
#[derive(Clone, Debug, PartialEq)]
pub enum Region {
    /// An axis-aligned box.
    Box(IBox),
    /// `{x ∈ bbox | H x ≤ h}`; `bbox` is part of the set's definition.
    Polytope {
        /// A box containing the set (the set is intersected with it).
        bbox: IBox,
        /// The rows `(Hᵣ, hᵣ)`.
        rows: Vec<(Vec<f64>, f64)>,
    },
    /// An ℓp ball with per-dimension radii.
    Ball {
        /// The centre.
        center: Vec<f64>,
        /// The radius along each dimension (non-negative).
        radius: Vec<f64>,
        /// Which norm.
        norm: Norm,
    },
}

impl Region {
    /// A box containing the set (exact for boxes and balls, rounded outward).
    pub fn bbox(&self) -> IBox {
        self.bbox_ref().into_owned()
    }

    /// [`Region::bbox`], borrowed where the region stores it (boxes and
    /// polytopes; a ball's is computed).
    pub fn bbox_ref(&self) -> std::borrow::Cow<'_, IBox> {
        use std::borrow::Cow;
        match self {
            Region::Box(b) => Cow::Borrowed(b),
            Region::Polytope { bbox, .. } => Cow::Borrowed(bbox),
            Region::Ball { center, radius, .. } => Cow::Owned(IBox::new(
                center
                    .iter()
                    .zip(radius)
                    .map(|(c, r)| num::sum_lower([*c, -r]))
                    .collect(),
                center
                    .iter()
                    .zip(radius)
                    .map(|(c, r)| num::sum_upper([*c, *r]))
                    .collect(),
            )),
        }
    }

    /// Whether every number defining the set is finite. Reachable sets
    /// that are not were produced by an overflow (see `ravel::execute`).
    pub fn is_finite(&self) -> bool {
        match self {
            Region::Box(b) => b.is_finite(),
            Region::Polytope { bbox, rows } => {
                bbox.is_finite()
                    && rows
                        .iter()
                        .all(|(a, h)| h.is_finite() && a.iter().all(|v| v.is_finite()))
            }
            Region::Ball { center, radius, .. } => {
                center.iter().chain(radius).all(|v| v.is_finite())
            }
        }
    }

    /// Dimension.
    pub fn dim(&self) -> usize {
        match self {
            Region::Box(b) | Region::Polytope { bbox: b, .. } => b.dim(),
            Region::Ball { center, .. } => center.len(),
        }
    }

    /// A certified upper bound of `max_{x ∈ self} gᵀx` (the support function).
    /// Polytopes need an LP; see [`crate::lp`] for why the bound is sound even
    /// when the solver is inexact.
    pub fn support(&self, g: &[f64]) -> LpBound {
        let value = match self {
            Region::Box(b) => num::dot_box_upper(g, &b.lo, &b.hi),
            Region::Polytope { bbox, rows } => return lp::maximize(g, rows, &bbox.lo, &bbox.hi),
            Region::Ball {
                center,
                radius,
                norm,
            } => {
                // gᵀc + ‖diag(r) g‖_q with q the dual norm of p
                let scaled: Vec<f64> = g.iter().zip(radius).map(|(g, r)| (g * r).abs()).collect();
                let dual = match norm {
                    Norm::LInf => num::sum_upper(scaled.iter().copied()),
                    Norm::L1 => scaled.iter().copied().fold(0.0, f64::max),
                    Norm::L2 => {
                        let sq = num::sum_upper(scaled.iter().map(|s| s * s));
                        (sq * (1.0 + 8.0 * num::U)).sqrt() * (1.0 + 4.0 * num::U)
                    }
                };
                // each |gᵢ rᵢ| is within one rounding of exact
                let dual = (dual * (1.0 + 4.0 * num::U) + num::TINY).next_up();
                num::sum_upper([num::dot_box_upper(g, center, center), dual])
            }
        };
        LpBound { value, issue: None }
    }

    /// The intersection with a set of the same shape (boxes, or polytopes with
    /// the same row directions): both contain the true states, so does this.
    /// Other combinations keep `self`.
    pub fn intersect(&self, other: &Region) -> Region {
        match (self, other) {
            (Region::Box(a), Region::Box(b)) => Region::Box(a.intersect(b)),
            (Region::Polytope { bbox: a, rows: ra }, Region::Polytope { bbox: b, rows: rb })
                if ra.len() == rb.len() && ra.iter().zip(rb).all(|(x, y)| x.0 == y.0) =>
            {
                Region::Polytope {
                    bbox: a.intersect(b),
                    rows: ra
                        .iter()
                        .zip(rb)
                        .map(|(x, y)| (x.0.clone(), x.1.min(y.1)))
                        .collect(),
                }
            }
            _ => self.clone(),
        }
    }

    /// Whether `x` certainly lies in the set (a conservative test: points on
    /// the boundary may be refused, points outside never pass).
    pub fn contains_point(&self, x: &[f64]) -> bool {
        match self {
            Region::Box(b) => b.contains_point(x),
            Region::Polytope { bbox, rows } => {
                bbox.contains_point(x)
                    && rows.iter().all(|(a, h)| num::dot_box_upper(a, x, x) <= *h)
            }
            Region::Ball {
                center,
                radius,
                norm,
            } => {
                let mut parts = Vec::with_capacity(x.len());
                for i in 0..x.len() {
                    let d = (x[i] - center[i]).abs();
                    if radius[i] == 0.0 {
                        if d != 0.0 {
                            return false;
                        }
                        parts.push(0.0);
                    } else {
                        parts.push(d / radius[i]);
                    }
                }
                let slack = 1.0 - 16.0 * (x.len() as f64 + 2.0) * num::U;
                match norm {
                    Norm::LInf => parts.iter().all(|p| *p <= slack),
                    Norm::L1 => parts.iter().sum::<f64>() <= slack,
                    Norm::L2 => parts.iter().map(|p| p * p).sum::<f64>() <= slack,
                }
            }
        }
    }

    /// The states the sampler tries first: the box corners, the ball's axis
    /// extremes pulled slightly inward, nothing for polytopes.
    pub fn special_points(&self) -> Vec<Vec<f64>> {
        let n = self.dim();
        match self {
            Region::Box(b) if n <= 12 => (0..1usize << n)
                .map(|k| {
                    (0..n)
                        .map(|i| if k >> i & 1 == 1 { b.hi[i] } else { b.lo[i] })
                        .collect()
                })
                .collect(),
            Region::Ball { center, radius, .. } => {
                let mut pts = vec![center.clone()];
                for i in 0..n {
                    for s in [-1.0, 1.0] {
                        let mut p = center.clone();
                        p[i] += s * radius[i] * (1.0 - 1e-9);
                        pts.push(p);
                    }
                }
                pts.retain(|p| self.contains_point(p));
                pts
            }
            _ => Vec::new(),
        }
    }

    /// One random point of the set from uniform numbers in `[0, 1)` drawn by
    /// `next`, or `None` when rejection sampling of a polytope failed.
    pub fn sample(&self, next: &mut dyn FnMut() -> f64) -> Option<Vec<f64>> {
        match self {
            Region::Box(b) => Some(
                (0..b.dim())
                    .map(|i| b.lo[i] + (b.hi[i] - b.lo[i]) * next())
                    .collect(),
            ),
            Region::Polytope { bbox, .. } => (0..1000).find_map(|_| {
                let x: Vec<f64> = (0..bbox.dim())
                    .map(|i| bbox.lo[i] + (bbox.hi[i] - bbox.lo[i]) * next())
                    .collect();
                self.contains_point(&x).then_some(x)
            }),
            Region::Ball {
                center,
                radius,
                norm,
            } => {
                // a point of the unit cube, pulled into the unit ball radially
                let n = center.len();
                let d: Vec<f64> = (0..n).map(|_| 2.0 * next() - 1.0).collect();
                let len = match norm {
                    Norm::LInf => d.iter().fold(0.0f64, |a, v| a.max(v.abs())),
                    Norm::L1 => d.iter().map(|v| v.abs()).sum(),
                    Norm::L2 => d.iter().map(|v| v * v).sum::<f64>().sqrt(),
                };
                let scale = if len > 1.0 { next() / len } else { 1.0 } * (1.0 - 1e-9);
                let x: Vec<f64> = (0..n)
                    .map(|i| center[i] + radius[i] * d[i] * scale)
                    .collect();
                self.contains_point(&x).then_some(x)
            }
        }
    }

    /// Split into cells whose union contains the set: a grid over the bounding
    /// box. Polytope cells keep the set's rows (their union is the set); a
    /// ball's cells are boxes, those that certainly miss the ball dropped
    /// (their union covers the ball, an over-approximation).
    pub fn grid(&self, counts: &[usize]) -> Vec<Region> {
        match self {
            Region::Box(b) => b.grid(counts).into_iter().map(Region::Box).collect(),
            Region::Polytope { bbox, rows } => bbox
                .grid(counts)
                .into_iter()
                .map(|c| Region::Polytope {
                    bbox: c,
                    rows: rows.clone(),
                })
                .collect(),
            Region::Ball {
                center,
                radius,
                norm,
            } => self
                .bbox()
                .grid(counts)
                .into_iter()
                .filter(|c| {
                    // the cell's point nearest the centre, in ball units
                    let d: Vec<f64> = (0..c.dim())
                        .map(|i| {
                            let gap = (c.lo[i] - center[i]).max(center[i] - c.hi[i]).max(0.0);
                            if radius[i] > 0.0 {
                                gap / radius[i]
                            } else if gap > 0.0 {
                                f64::INFINITY
                            } else {
                                0.0
                            }
                        })
                        .collect();
                    let len = match norm {
                        Norm::LInf => d.iter().fold(0.0f64, |a, v| a.max(*v)),
                        Norm::L1 => d.iter().sum(),
                        Norm::L2 => d.iter().map(|v| v * v).sum::<f64>().sqrt(),
                    };
                    len <= 1.0 + 1e-9
                })
                .map(Region::Box)
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exact::{is_lower, is_upper, Extreme, Fixed};

    /// The exact `max_{x ∈ B} a·x` for coefficients `±2^k`: `Σ max(aᵢlᵢ, aᵢhᵢ)`.
    fn exact_max(a: &[(f64, u32)], b: &IBox) -> Fixed {
        a.iter()
            .enumerate()
            .fold(Fixed::ZERO, |s, (i, &(sign, k))| {
                let end = if sign > 0.0 { b.hi[i] } else { b.lo[i] };
                let t = Fixed::of_scaled(end, k);
                s.add(if sign > 0.0 { t } else { t.neg() })
            })
    }

    /// The margins that decide goal and avoid verdicts, and box supports, at
    /// magnitudes near `f64::MAX`, subnormals and mixed signs: each is a
    /// sound bound of its exact value (compared in exact fixed point), or
    /// saturates to the infinity that proves nothing.
    #[test]
    fn margins_and_supports_are_sound_near_the_top_of_f64() {
        let mut g = Extreme::new(4);
        let mut decided = 0;
        for _ in 0..4_000 {
            let n = 1 + g.below(7);
            let (mut lo, mut hi) = (Vec::new(), Vec::new());
            for _ in 0..n {
                let (p, q) = (g.value(), g.value());
                lo.push(p.min(q));
                hi.push(p.max(q));
            }
            let b = IBox::new(lo, hi);
            let rows: Vec<(Vec<(f64, u32)>, f64)> = (0..1 + g.below(3))
                .map(|_| {
                    let a = (0..n)
                        .map(|_| {
                            let sign = if g.below(2) == 0 { 1.0 } else { -1.0 };
                            (sign, g.below(3) as u32)
                        })
                        .collect();
                    (a, g.value())
                })
                .collect();
            let coef = |a: &[(f64, u32)]| -> Vec<f64> {
                a.iter().map(|&(s, k)| s * f64::from(1u32 << k)).collect()
            };
            let p = Polytope {
                rows: rows.iter().map(|(a, h)| (coef(a), *h)).collect(),
            };
            // containment: min_r (h_r − max a_r·x), exactly
            let mut least: Option<Fixed> = None;
            // separation: max_r (min a_r·x − h_r) = max_r (−max (−a_r)·x − h_r)
            let mut most: Option<Fixed> = None;
            for (a, h) in &rows {
                let c = Fixed::of(*h).add(exact_max(a, &b).neg());
                least = Some(match least {
                    Some(l) if l.le(c) => l,
                    _ => c,
                });
                let neg: Vec<(f64, u32)> = a.iter().map(|&(s, k)| (-s, k)).collect();
                let m = exact_max(&neg, &b).neg().add(Fixed::of(*h).neg());
                most = Some(match most {
                    Some(l) if m.le(l) => l,
                    _ => m,
                });
                let up = Region::Box(b.clone()).support(&coef(a)).value;
                assert!(
                    is_upper(up, exact_max(a, &b)),
                    "support {up:e} of {a:?} over {b:?}"
                );
            }
            let (least, most) = (least.expect("rows"), most.expect("rows"));
            let cm = p.containment_margin(&b);
            let sm = p.separation_margin(&b);
            assert!(
                is_lower(cm, least),
                "containment {cm:e} over {b:?} {rows:?}"
            );
            assert!(is_lower(sm, most), "separation {sm:e} over {b:?} {rows:?}");
            decided += usize::from(cm >= 0.0) + usize::from(sm > 0.0);
        }
        // the test reaches margins that decide verdicts, not only saturated ones
        assert!(decided > 500, "{decided}");
    }

    #[test]
    fn a_hull_grown_in_place_does_not_depend_on_the_order() {
        let boxes = [
            IBox::new(vec![0.0, f64::NAN, 1.0], vec![-0.0, 2.0, 3.0]),
            IBox::new(vec![-0.0, -1.0, 1.0], vec![0.0, f64::NAN, 3.0]),
            IBox::new(vec![0.0, -1.0, -0.5], vec![-0.0, 2.5, 3.0]),
        ];
        let bits = |b: &IBox| {
            let f = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            (f(&b.lo), f(&b.hi))
        };
        let mut seen = Vec::new();
        for order in [
            [0, 1, 2],
            [0, 2, 1],
            [1, 0, 2],
            [1, 2, 0],
            [2, 0, 1],
            [2, 1, 0],
        ] {
            let mut h = boxes[order[0]].clone();
            // as two threads would: one part grown, then another merged in
            let mut tail = boxes[order[2]].clone();
            tail.hull_with(&boxes[order[1]]);
            h.hull_with(&tail);
            seen.push(bits(&h));
        }
        assert!(seen.iter().all(|b| *b == seen[0]), "{seen:?}");
        let want = IBox::new(vec![-0.0, -1.0, -0.5], vec![0.0, 2.5, 3.0]);
        assert_eq!(seen[0], bits(&want));
    }

    #[test]
    fn grid_covers_box_exactly() {
        let b = IBox::new(vec![0.0, -1.0], vec![3.0, 1.0]);
        let cells = b.grid(&[3, 2]);
        assert_eq!(cells.len(), 6);
        let hull = cells
            .iter()
            .skip(1)
            .fold(cells[0].clone(), |h, c| h.hull(c));
        assert_eq!(hull, b);
        assert_eq!(cells[1], IBox::new(vec![0.0, 0.0], vec![1.0, 1.0]));
    }

    #[test]
    fn margins_have_the_right_sign() {
        let p = Polytope::from_box(&IBox::new(vec![-1.0, -1.0], vec![1.0, 1.0]));
        assert!(p.containment_margin(&IBox::new(vec![-0.5, -0.5], vec![0.5, 0.5])) > 0.49);
        assert!(p.containment_margin(&IBox::new(vec![-0.5, -0.5], vec![1.5, 0.5])) < -0.49);
        assert!(p.separation_margin(&IBox::new(vec![2.0, 0.0], vec![3.0, 0.5])) > 0.99);
        assert!(p.separation_margin(&IBox::new(vec![0.0, 0.0], vec![3.0, 0.5])) < 0.0);
    }
}
