//! Sets over the state space: axis-aligned boxes and polytopes `{x | H x ≤ h}`.

use crate::num;

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
        let mut lo = self.lo.clone();
        lo.extend_from_slice(&other.lo);
        let mut hi = self.hi.clone();
        hi.extend_from_slice(&other.hi);
        IBox::new(lo, hi)
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

#[cfg(test)]
mod tests {
    use super::*;

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
