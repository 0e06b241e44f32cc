//! Linear programs with certified bounds (Clarabel as the solver).
//!
//! The solver's objective value is never used. A lower bound of
//! `min qᵀx s.t. A x ≤ b, lo ≤ x ≤ hi` is rebuilt from its dual vector `z`
//! alone, by weak duality: with `z` projected onto the dual cone (`z ≥ 0`) and
//! `r = q + Aᵀz` (box rows included in `A`), every feasible `x` satisfies
//! `qᵀx = rᵀx − zᵀA x ≥ rᵀx − zᵀb ≥ min_box rᵀx − bᵀz`. Every term is
//! evaluated with outward rounding (`r` with an error bound `γ·(|q| + |A|ᵀz)`),
//! so the bound holds for the exact problem whatever the solver's accuracy.
//!
//! Only the statuses `Solved` and `AlmostSolved` are trusted to carry a
//! useful dual; every other status gives the plain box bound `min_box qᵀx`
//! (still sound) together with the status name, which callers turn into an
//! UNSURE verdict.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettingsBuilder, DefaultSolver, IPSolver, SupportedConeT};

use crate::issue::{Backend, Issue};
use ravel_base::num::{dot_box_lower, gamma, sum_lower, sum_upper, TINY};

/// A certified bound from one LP.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LpBound {
    /// The bound (valid whatever `issue` says).
    pub value: f64,
    /// `None` when the solver certified an optimum; otherwise the solver
    /// status that made `value` fall back to the box bound.
    pub issue: Option<Issue>,
}

/// A certified lower bound of `min qᵀx` subject to `rows` (`aᵣ·x ≤ bᵣ`) and
/// the finite box `lo ≤ x ≤ hi`.
pub fn minimize(q: &[f64], rows: &[(Vec<f64>, f64)], lo: &[f64], hi: &[f64]) -> LpBound {
    let fallback = dot_box_lower(q, lo, hi);
    if rows.is_empty() || !fallback.is_finite() {
        return LpBound {
            value: fallback,
            issue: None,
        };
    }
    match solve(q, rows, lo, hi) {
        Err(issue) => LpBound {
            value: fallback,
            issue: Some(issue),
        },
        Ok(s) => {
            let dual = dual_bound(q, &s.b, (&s.ri, &s.ci, &s.vs), &s.z, lo, hi);
            LpBound {
                value: if dual.is_finite() {
                    dual.max(fallback)
                } else {
                    fallback
                },
                issue: None,
            }
        }
    }
}

/// A dual vector of `max gᵀx` subject to `rows` and the box, for the
/// rows only, projected onto `z ≥ 0` (`None` when the solver did not
/// certify an optimum). Any such vector `μ` gives the bound
/// `max gᵀx ≤ μᵀb + max_box (g − Hᵀμ)ᵀx`; the certificate writer records it
/// as a witness, and the checker evaluates that bound itself.
pub fn maximize_dual(
    g: &[f64],
    rows: &[(Vec<f64>, f64)],
    lo: &[f64],
    hi: &[f64],
) -> Option<Vec<f64>> {
    if rows.is_empty() {
        return Some(Vec::new());
    }
    let q: Vec<f64> = g.iter().map(|v| -v).collect();
    solve(&q, rows, lo, hi)
        .ok()
        .map(|s| s.z[..rows.len()].to_vec())
}

/// The constraint data and the projected dual of a solved LP.
struct Solved {
    ri: Vec<usize>,
    ci: Vec<usize>,
    vs: Vec<f64>,
    b: Vec<f64>,
    z: Vec<f64>,
}

/// Solve `min qᵀx` s.t. `rows`, `lo ≤ x ≤ hi` with Clarabel.
fn solve(q: &[f64], rows: &[(Vec<f64>, f64)], lo: &[f64], hi: &[f64]) -> Result<Solved, Issue> {
    let n = q.len();
    // A = [rows; I; −I], b = [b; hi; −lo]
    let m = rows.len() + 2 * n;
    let (mut ri, mut ci, mut vs) = (Vec::new(), Vec::new(), Vec::new());
    let mut b = Vec::with_capacity(m);
    for (r, (a, rhs)) in rows.iter().enumerate() {
        for (j, &v) in a.iter().enumerate() {
            if v != 0.0 {
                ri.push(r);
                ci.push(j);
                vs.push(v);
            }
        }
        b.push(*rhs);
    }
    for (j, h) in hi.iter().enumerate() {
        ri.push(rows.len() + j);
        ci.push(j);
        vs.push(1.0);
        b.push(*h);
    }
    for (j, l) in lo.iter().enumerate() {
        ri.push(rows.len() + n + j);
        ci.push(j);
        vs.push(-1.0);
        b.push(-l);
    }
    let a = CscMatrix::new_from_triplets(m, n, ri.clone(), ci.clone(), vs.clone());
    let p = CscMatrix::<f64>::zeros((n, n));
    let settings = DefaultSettingsBuilder::default()
        .verbose(false)
        .max_iter(200)
        .build()
        .map_err(|_| Issue::BadSettings(Backend::Lp))?;
    let cones = [SupportedConeT::NonnegativeConeT(m)];
    let mut solver = DefaultSolver::new(&p, q, &a, &b, &cones, settings)
        .map_err(|_| Issue::RejectedData(Backend::Lp))?;
    solver.solve();
    if let Some(issue) = Issue::from_status(Backend::Lp, solver.solution.status) {
        return Err(issue);
    }
    let z: Vec<f64> = solver
        .solution
        .z
        .iter()
        .map(|&v| if v.is_finite() && v > 0.0 { v } else { 0.0 })
        .collect();
    Ok(Solved { ri, ci, vs, b, z })
}

/// `−bᵀz + min_box (q + Aᵀz)ᵀx`, rounded downward, for `z ≥ 0`; `A` as triplets.
fn dual_bound(
    q: &[f64],
    b: &[f64],
    (ri, ci, vs): (&[usize], &[usize], &[f64]),
    z: &[f64],
    lo: &[f64],
    hi: &[f64],
) -> f64 {
    let n = q.len();
    let mut r = q.to_vec();
    let mut mag: Vec<f64> = q.iter().map(|v| v.abs()).collect();
    let mut terms = vec![0usize; n];
    for k in 0..vs.len() {
        let (i, j) = (ri[k], ci[k]);
        let t = vs[k] * z[i];
        r[j] += t;
        mag[j] += t.abs();
        terms[j] += 1;
    }
    // error of each computed rᵢ: γ(terms + 2)·Σ|terms|, plus underflow
    let err: Vec<f64> = (0..n)
        .map(|j| (gamma(terms[j] + 2) * mag[j] * 1.0625 + TINY).next_up())
        .collect();
    let box_part = dot_box_lower(&r, lo, hi);
    let err_part = sum_upper((0..n).map(|j| err[j] * ravel_base::num::abs_max(lo[j], hi[j])));
    let bz = sum_upper(
        b.iter()
            .zip(z)
            .map(|(b, z)| b * z)
            .chain([slack_products(b, z)]),
    );
    sum_lower([box_part, -err_part, -bz])
}

/// Rounding error of the products `bᵢ zᵢ` (each within one rounding of exact).
fn slack_products(b: &[f64], z: &[f64]) -> f64 {
    let s: f64 = b.iter().zip(z).map(|(b, z)| (b * z).abs()).sum();
    (ravel_base::num::U * s * 1.0625 + TINY).next_up()
}

/// A certified upper bound of `max gᵀx` subject to `rows` and the box.
pub fn maximize(g: &[f64], rows: &[(Vec<f64>, f64)], lo: &[f64], hi: &[f64]) -> LpBound {
    let q: Vec<f64> = g.iter().map(|v| -v).collect();
    let b = minimize(&q, rows, lo, hi);
    LpBound {
        value: -b.value,
        issue: b.issue,
    }
}

/// A certified lower bound of `min_{x ∈ P} max_r (mᵣ·x − cᵣ)` where
/// `P = {rows} ∩ box` and `(mᵣ, cᵣ)` are the rows of `other`: positive means
/// `P` and `{x | mᵣ·x ≤ cᵣ ∀r}` are disjoint. With `other` empty it is −∞.
pub fn separation(
    rows: &[(Vec<f64>, f64)],
    other: &[(Vec<f64>, f64)],
    lo: &[f64],
    hi: &[f64],
) -> LpBound {
    if other.is_empty() {
        return LpBound {
            value: f64::NEG_INFINITY,
            issue: None,
        };
    }
    let n = lo.len();
    // t is bracketed by the single-row bound below and the box maximum above
    let t_lo = other
        .iter()
        .map(|(m, c)| sum_lower([dot_box_lower(m, lo, hi), -c]))
        .fold(f64::NEG_INFINITY, f64::max);
    let t_hi = other
        .iter()
        .map(|(m, c)| sum_upper([ravel_base::num::dot_box_upper(m, lo, hi), -c]))
        .fold(f64::NEG_INFINITY, f64::max);
    if !(t_lo.is_finite() && t_hi.is_finite()) {
        return LpBound {
            value: t_lo,
            issue: None,
        };
    }
    // variables (x, t): minimise t s.t. rows, m·x − t ≤ c
    let mut all: Vec<(Vec<f64>, f64)> = rows
        .iter()
        .map(|(a, b)| {
            let mut a = a.clone();
            a.push(0.0);
            (a, *b)
        })
        .collect();
    for (m, c) in other {
        let mut a = m.clone();
        a.push(-1.0);
        all.push((a, *c));
    }
    let mut q = vec![0.0; n];
    q.push(1.0);
    let mut l = lo.to_vec();
    l.push(t_lo);
    let mut h = hi.to_vec();
    h.push(t_hi.max(t_lo));
    let b = minimize(&q, &all, &l, &h);
    LpBound {
        value: b.value.max(t_lo),
        issue: b.issue,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diamond_maximum_is_bounded_tightly_and_soundly() {
        // |x| + |y| ≤ 1 inside the box [-2, 2]²; max x + 0.5 y = 1
        let rows = vec![
            (vec![1.0, 1.0], 1.0),
            (vec![1.0, -1.0], 1.0),
            (vec![-1.0, 1.0], 1.0),
            (vec![-1.0, -1.0], 1.0),
        ];
        let b = maximize(&[1.0, 0.5], &rows, &[-2.0, -2.0], &[2.0, 2.0]);
        assert_eq!(b.issue, None);
        assert!(b.value >= 1.0 && b.value < 1.0 + 1e-6, "{}", b.value);
    }

    #[test]
    fn any_nonnegative_dual_gives_a_valid_bound() {
        // min x s.t. x ≥ 0.3 (as −x ≤ −0.3), box [−1, 1]: optimum 0.3
        let q = [1.0];
        let b = [-0.3, 1.0, 1.0];
        let trip = (
            &[0usize, 1, 2][..],
            &[0usize, 0, 0][..],
            &[-1.0, 1.0, -1.0][..],
        );
        for z in [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.7, 0.2, 0.1],
            [5.0, 3.0, 0.0],
        ] {
            let v = dual_bound(&q, &b, trip, &z, &[-1.0], &[1.0]);
            assert!(v <= 0.3, "{z:?} gave {v}");
        }
        let exact = dual_bound(&q, &b, trip, &[1.0, 0.0, 0.0], &[-1.0], &[1.0]);
        assert!((exact - 0.3).abs() < 1e-12);
    }

    #[test]
    fn separation_detects_disjoint_and_touching_sets() {
        let tri = vec![(vec![1.0, 1.0], 1.0)]; // x + y ≤ 1 in [0, 1]²
        let far = vec![(vec![-1.0, 0.0], -0.8), (vec![0.0, -1.0], -0.8)]; // x, y ≥ 0.8
        let s = separation(&tri, &far, &[0.0, 0.0], &[1.0, 1.0]);
        assert!(s.value > 0.29 && s.value <= 0.3 + 1e-9, "{}", s.value);
        let near = vec![(vec![-1.0, 0.0], -0.4), (vec![0.0, -1.0], -0.4)];
        assert!(separation(&tri, &near, &[0.0, 0.0], &[1.0, 1.0]).value <= 0.0);
    }
}
