//! A rigorous enclosure of the matrix exponential: `Φ` and `E ≥ 0` with
//! `|e^M − Φ| ≤ E` entrywise, for the exact exponential of the exact matrix.
//!
//! Scaling and squaring with a Taylor polynomial (Higham, *Functions of
//! Matrices*, §10): `N = M / 2^s` with `‖N‖∞ ≤ 1/2` (exact: a power-of-two
//! scaling), `T = Σ_{j≤K} N^j / j!` with `K = 20`, then `s` squarings. Three
//! errors are tracked as entrywise bounds, each propagated through every
//! later operation:
//!
//! * truncation: `‖Σ_{j>K} N^j/j!‖∞ ≤ ‖N‖^{K+1}/(K+1)! · 1/(1 − ‖N‖/(K+2))`,
//!   which bounds every entry;
//! * rounding of each product and sum: `|fl(AB) − AB| ≤ γ_k |A||B|` and
//!   `|fl(Σ) − Σ| ≤ γ_n Σ|·|` (any summation order, with or without FMA),
//!   plus an absolute term for underflow;
//! * squaring an enclosure: `|(Φ+Δ)² − Φ²| ≤ |Φ|E + E|Φ| + E²`.
//!
//! The error matrices are themselves computed in `f64`; each is multiplied by
//! `1 + 10⁻⁸` and raised by `10⁻³⁰⁰`, which covers their own rounding by a
//! wide margin.

use nalgebra::DMatrix;

use ravel_base::num::{gamma, ETA, U};

/// Taylor degree after scaling to `‖N‖∞ ≤ 1/2`: truncation below `10⁻²⁶`.
const DEGREE: usize = 20;

/// The largest absolute row sum.
pub fn norm_inf(m: &DMatrix<f64>) -> f64 {
    (0..m.nrows())
        .map(|i| m.row(i).iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

/// Push an error bound up to cover its own rounding.
fn up(e: DMatrix<f64>) -> DMatrix<f64> {
    e.map(|v| v * (1.0 + 1e-8) + 1e-300)
}

/// `Φ ≈ e^M` and `E` with `|e^M − Φ| ≤ E` entrywise, for the exact
/// exponential of the exact `M`; `None` if anything overflows or `M` is too
/// large to scale (`‖M‖∞ > 2¹⁰⁰⁰`).
pub fn expm_enclosure(m: &DMatrix<f64>) -> Option<(DMatrix<f64>, DMatrix<f64>)> {
    let k = m.nrows();
    let norm = norm_inf(m);
    if !norm.is_finite() || m.ncols() != k {
        return None;
    }
    let mut s: i32 = 0;
    while norm * 2f64.powi(-s) > 0.5 {
        s += 1;
        if s > 1000 {
            return None;
        }
    }
    // exact unless an entry underflows: then off by at most the smallest subnormal
    let n = m * 2f64.powi(-s);
    let n_err = DMatrix::from_fn(k, k, |i, j| {
        if m[(i, j)] != 0.0 && n[(i, j)].abs() < f64::MIN_POSITIVE {
            ETA
        } else {
            0.0
        }
    });
    let n_abs = n.abs() + &n_err;
    let nn = norm_inf(&n_abs);
    let g = gamma(k + 2);

    // Taylor terms P_j ≈ N^j / j!, with error bounds E_j
    let mut p = DMatrix::<f64>::identity(k, k);
    let mut e = DMatrix::<f64>::zeros(k, k);
    let mut sum = p.clone();
    let mut sum_err = DMatrix::<f64>::zeros(k, k);
    let mut abs_terms = p.abs();
    for j in 1..=DEGREE {
        let jf = j as f64;
        let prod = &p * &n;
        // |P N − Q N| ≤ E|N| + |P| n_err; rounding of the product γ|P||N|;
        // the division by j adds a relative u
        let p_abs = p.abs();
        let next = prod / jf;
        e = up(
            (&e * &n_abs + (&p_abs + &e) * &n_err + (&p_abs * &n_abs) * g) / jf + next.abs() * U,
        );
        p = next;
        sum += &p;
        sum_err += &e;
        abs_terms += p.abs();
    }
    // truncation and the rounding of the sum
    let trunc = {
        // nn^(K+1)/(K+1)!, over 1 − nn/(K+2)
        let mut pow = 1.0f64;
        let mut fact = 1.0f64;
        for j in 1..=DEGREE + 1 {
            pow *= nn;
            fact *= j as f64;
        }
        (pow / fact) / (1.0 - nn / (DEGREE as f64 + 2.0))
    };
    let mut phi = sum;
    let mut err = up(sum_err + abs_terms * gamma(DEGREE + 2)).add_scalar(trunc * 1.01);

    // squaring
    for _ in 0..s {
        let a = phi.abs();
        let next = &phi * &phi;
        err = up(&a * &err + &err * &a + &err * &err + (&a * &a) * g);
        phi = next;
        if phi.iter().chain(err.iter()).any(|v| !v.is_finite()) {
            return None;
        }
    }
    if phi.iter().chain(err.iter()).any(|v| !v.is_finite()) {
        return None;
    }
    Some((phi, err))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encloses_known_exponentials() {
        // nilpotent: e^[[0, t], [0, 0]] = [[1, t], [0, 1]] exactly
        let m = DMatrix::from_row_slice(2, 2, &[0.0, 0.75, 0.0, 0.0]);
        let (phi, err) = expm_enclosure(&m).expect("finite");
        let exact = DMatrix::from_row_slice(2, 2, &[1.0, 0.75, 0.0, 1.0]);
        for i in 0..4 {
            assert!((phi[i] - exact[i]).abs() <= err[i], "{i}");
            assert!(err[i] < 1e-14, "{}", err[i]);
        }
        // diagonal: e^diag(a) = diag(e^a); a large entry needs squarings
        for a in [-3.0f64, 0.1, 2.5, 12.0] {
            let m = DMatrix::from_row_slice(1, 1, &[a]);
            let (phi, err) = expm_enclosure(&m).expect("finite");
            let want = a.exp();
            // e^a in f64 is within 1 ulp of the exact value
            let ulp = want * f64::EPSILON;
            assert!(
                (phi[0] - want).abs() <= err[0] + ulp,
                "{a}: {} vs {want} ± {}",
                phi[0],
                err[0]
            );
            assert!(
                err[0] < 1e-12 * want,
                "{a}: error bound {} too loose",
                err[0]
            );
        }
        // a rotation: e^[[0, θ], [−θ, 0]] = [[cos, sin], [−sin, cos]]
        let th = 1.3f64;
        let m = DMatrix::from_row_slice(2, 2, &[0.0, th, -th, 0.0]);
        let (phi, err) = expm_enclosure(&m).expect("finite");
        let want = [th.cos(), -th.sin(), th.sin(), th.cos()]; // column-major
        for i in 0..4 {
            assert!(
                (phi[i] - want[i]).abs() <= err[i] + 2.0 * f64::EPSILON,
                "{i}"
            );
            assert!(err[i] < 1e-13);
        }
    }

    #[test]
    fn refuses_what_it_cannot_bound() {
        assert!(expm_enclosure(&DMatrix::from_row_slice(1, 1, &[f64::NAN])).is_none());
        assert!(expm_enclosure(&DMatrix::from_row_slice(1, 1, &[1000.0])).is_none());
    }
}
