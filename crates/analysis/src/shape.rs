//! Output shapes: how a set is described, and how far a bound of it sticks
//! out beyond a sampled under-approximation.
//!
//! Every shape is a list of directions `d_k`; a set `S` is described by its
//! offsets `b_k ≥ max_{y∈S} d_k·y`, so `S ⊆ {y | D y ≤ b}`. The same
//! directions applied to sampled points give the sampled offsets, an
//! under-approximation of the true ones; the difference, relative to the
//! samples' extent along each direction, is what the SG and GSG partitioners
//! try to shrink ([`excess`]). Both the open-loop analysis of a network
//! ([`super::open_loop`]) and the closed-loop boundaries use these.

use nalgebra::DMatrix;

use ravel_base::num;

/// The shape of an output set.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// A lower bound per component (directions `−e_i`): what robust action
    /// selection needs.
    LowerBounds,
    /// A box (directions `±e_i`).
    Box,
    /// A box and the given directions (one per row).
    Polytope(DMatrix<f64>),
    /// A box and the edge normals of the convex hull of the samples (2-D
    /// only; other dimensions get the box).
    Hull,
}

/// The smallest angle between two hull directions (7.5°): at most 48.
pub const HULL_MIN_ANGLE: f64 = std::f64::consts::TAU / 48.0;

impl Shape {
    /// The directions of this shape in `n` dimensions (samples decide a
    /// hull's): `−e_i` for lower bounds, else `e_i`, then `−e_i`, then the
    /// extra directions.
    pub fn directions(&self, n: usize, samples: &[Vec<f64>]) -> DMatrix<f64> {
        if *self == Shape::LowerBounds {
            return DMatrix::from_fn(n, n, |r, c| if r == c { -1.0 } else { 0.0 });
        }
        let extra = match self {
            Shape::Polytope(d) => d.clone(),
            Shape::Hull if n == 2 => {
                let pts: Vec<[f64; 2]> = samples.iter().map(|p| [p[0], p[1]]).collect();
                hull_directions(&pts, HULL_MIN_ANGLE)
            }
            _ => DMatrix::zeros(0, n),
        };
        let mut d = DMatrix::zeros(2 * n + extra.nrows(), n);
        for i in 0..n {
            d[(i, i)] = 1.0;
            d[(n + i, i)] = -1.0;
        }
        d.view_mut((2 * n, 0), (extra.nrows(), n)).copy_from(&extra);
        d
    }
}

/// `max_p d_k·p` over the points, per direction (`−∞` without points).
pub fn support_of_points(dirs: &DMatrix<f64>, points: &[Vec<f64>]) -> Vec<f64> {
    (0..dirs.nrows())
        .map(|k| {
            points
                .iter()
                .map(|p| dirs.row(k).iter().zip(p).map(|(a, x)| a * x).sum::<f64>())
                .fold(f64::NEG_INFINITY, f64::max)
        })
        .collect()
}

/// The samples' extent along each direction: `max d·p − min d·p`.
pub fn extent_of_points(dirs: &DMatrix<f64>, points: &[Vec<f64>]) -> Vec<f64> {
    let neg = -dirs;
    support_of_points(dirs, points)
        .iter()
        .zip(support_of_points(&neg, points))
        .map(|(a, b)| a + b)
        .collect()
}

/// How far bound offsets exceed the sampled offsets, relative to the
/// samples' extent along the same direction (widths below `1e-12` count as
/// `1e-12`): 0 when the bound lies within the sampled offsets everywhere.
pub fn excess(bound: &[f64], sampled: &[f64], extent: &[f64]) -> f64 {
    bound
        .iter()
        .zip(sampled)
        .zip(extent)
        .map(|((b, s), w)| ((b - s) / w.max(1e-12)).max(0.0))
        .fold(0.0, f64::max)
}

/// Sound offsets of a box along directions: `max_{y ∈ [lo, hi]} d·y`,
/// rounded outward (exact for the axis directions `±e_i`).
pub fn support_of_box(dirs: &DMatrix<f64>, lo: &[f64], hi: &[f64]) -> Vec<f64> {
    (0..dirs.nrows())
        .map(|k| {
            let d: Vec<f64> = dirs.row(k).iter().copied().collect();
            let mut nonzero = d.iter().enumerate().filter(|(_, v)| **v != 0.0);
            match (nonzero.next(), nonzero.next()) {
                (Some((i, &1.0)), None) => hi[i],
                (Some((i, &-1.0)), None) => -lo[i],
                _ => num::dot_box_upper(&d, lo, hi),
            }
        })
        .collect()
}

/// Directions from points of a 2-D set: the outward unit normals of the edges
/// of their convex hull, counter-clockwise, leaving out an edge whose normal
/// is within `min_angle` radians of the last (or first) one kept. Fewer than
/// three points in general position give no directions.
pub fn hull_directions(points: &[[f64; 2]], min_angle: f64) -> DMatrix<f64> {
    let hull = convex_hull(points);
    let mut kept: Vec<[f64; 2]> = Vec::new();
    if hull.len() >= 3 {
        for i in 0..hull.len() {
            let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
            let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
            let len = ex.hypot(ey);
            if len.is_nan() || len <= 0.0 {
                continue;
            }
            // counter-clockwise polygon: the outward normal is (ey, −ex)
            let nrm = [ey / len, -ex / len];
            let far = |m: &[f64; 2]| {
                let cos = (m[0] * nrm[0] + m[1] * nrm[1]).clamp(-1.0, 1.0);
                cos.acos() >= min_angle
            };
            if kept.last().is_none_or(far) && kept.first().is_none_or(far) {
                kept.push(nrm);
            }
        }
    }
    DMatrix::from_fn(kept.len(), 2, |r, c| kept[r][c])
}

/// The convex hull of 2-D points, counter-clockwise, without collinear points
/// (Andrew's monotone chain). Non-finite points are ignored.
pub fn convex_hull(points: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p: Vec<[f64; 2]> = points
        .iter()
        .copied()
        .filter(|q| q[0].is_finite() && q[1].is_finite())
        .collect();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        let order: Vec<[f64; 2]> = if pass == 0 {
            p.clone()
        } else {
            p.iter().rev().copied().collect()
        };
        for q in order {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn convex_hull_of_a_square_with_inner_and_edge_points() {
        let pts = [
            [0.0, 0.0],
            [1.0, 0.0],
            [0.5, 0.0],
            [1.0, 1.0],
            [0.0, 1.0],
            [0.5, 0.5],
            [1.0, 1.0],
        ];
        let h = convex_hull(&pts);
        assert_eq!(h, vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]);
        let d = hull_directions(&pts, 0.1);
        let rows: Vec<[f64; 2]> = (0..d.nrows()).map(|r| [d[(r, 0)], d[(r, 1)]]).collect();
        assert_eq!(rows, vec![[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]]);
    }

    #[test]
    fn hull_directions_are_thinned_and_degenerate_hulls_give_none() {
        // a regular 100-gon: normals 3.6° apart, kept at least 10° apart
        let pts: Vec<[f64; 2]> = (0..100)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / 100.0;
                [a.cos(), a.sin()]
            })
            .collect();
        let d = hull_directions(&pts, 10f64.to_radians());
        assert!(d.nrows() >= 30 && d.nrows() <= 36, "{}", d.nrows());
        for r in 0..d.nrows() {
            let next = (r + 1) % d.nrows();
            let cos = d.row(r).dot(&d.row(next));
            assert!(cos.acos() >= 10f64.to_radians() - 1e-12);
        }
        // collinear points and a single point have no area
        let line = [[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]];
        assert_eq!(hull_directions(&line, 0.1).nrows(), 0);
        assert_eq!(hull_directions(&[[1.0, 2.0]], 0.1).nrows(), 0);
        assert_eq!(hull_directions(&[], 0.1).nrows(), 0);
    }

    #[test]
    fn shapes_have_their_directions_and_excess_is_relative() {
        let pts = vec![vec![0.0, 0.0], vec![2.0, 0.0], vec![0.0, 1.0]];
        assert_eq!(Shape::LowerBounds.directions(2, &pts).nrows(), 2);
        assert_eq!(Shape::Box.directions(2, &pts).nrows(), 4);
        // the triangle: 3 edges, two of them axis-aligned (repeated) and the diagonal
        let hull = Shape::Hull.directions(2, &pts);
        assert_eq!(hull.nrows(), 7);
        let d = Shape::Box.directions(2, &pts);
        let s = support_of_points(&d, &pts);
        assert_eq!(s, vec![2.0, 1.0, 0.0, 0.0]);
        let w = extent_of_points(&d, &pts);
        assert_eq!(w, vec![2.0, 1.0, 2.0, 1.0]);
        // a bound 1 beyond the samples along x (extent 2) and 0.5 along −y (extent 1)
        assert_eq!(excess(&[3.0, 1.0, 0.0, 0.5], &s, &w), 0.5);
        assert_eq!(excess(&[2.0, 1.0, 0.0, 0.0], &s, &w), 0.0);
        let b = support_of_box(&d, &[0.0, 0.0], &[2.0, 1.0]);
        assert!(b.iter().zip(&s).all(|(b, s)| b >= s));
    }
}
