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
//!
//! The matrix is balanced first by an exact diagonal similarity of powers
//! of two ([`balance`]), so the squarings work on entries of comparable
//! size. [`rounding_bound`] bounds the effect of rounding the product
//! `A·T` a caller exponentiates, through the logarithmic norm of the
//! balanced matrix rather than its norm (a stiff oscillator's bound was
//! `e^{ω²T}` times too large).

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
///
/// `M` is balanced first ([`balance`]): `e^M = D e^B D⁻¹` with
/// `B = D⁻¹ M D` and `D` a diagonal of powers of two, so `B` and the
/// scaling back are exact (checked, and the bound raised by [`up`] for a
/// result in the subnormal range). The squarings then work on entries of
/// comparable size, whose error bounds grow less. The plain enclosure is
/// computed too, and the one with the smaller largest radius is returned.
pub fn expm_enclosure(m: &DMatrix<f64>) -> Option<(DMatrix<f64>, DMatrix<f64>)> {
    let k = m.nrows();
    if m.ncols() != k {
        return None;
    }
    let ex = balance(m);
    // B = D⁻¹ M D, b_ij = m_ij 2^(e_j − e_i), exact or not used
    let b = DMatrix::from_fn(k, k, |i, j| m[(i, j)] * 2f64.powi(ex[j] - ex[i]));
    let exact = (0..k).all(|i| (0..k).all(|j| b[(i, j)] * 2f64.powi(ex[i] - ex[j]) == m[(i, j)]));
    if !exact || ex.iter().all(|&e| e == 0) {
        return enclosure(m);
    }
    let back =
        |x: &DMatrix<f64>| DMatrix::from_fn(k, k, |i, j| x[(i, j)] * 2f64.powi(ex[i] - ex[j]));
    let balanced = enclosure(&b)
        .map(|(phi, err)| (back(&phi), up(back(&err))))
        .filter(|(phi, err)| phi.iter().chain(err.iter()).all(|v| v.is_finite()));
    // both are enclosures: the one with the smaller largest radius
    match (balanced, enclosure(m)) {
        (Some(b), Some(p)) if p.1.max() < b.1.max() => Some(p),
        (Some(b), _) => Some(b),
        (None, p) => p,
    }
}

/// Entrywise bounds on `|e^{M−Δ} − e^M|` for a rounded product
/// `M = fl(A·T)`, whose rounding `Δ = M − A·T` is at most `u·|M|` (over
/// `1 − u`) per entry, or half the smallest subnormal where the product
/// underflows: the smaller of two bounds ([`perturbation_bound`]).
///
/// * `‖Δ‖∞·e^{‖M‖∞+‖Δ‖∞}`, for every entry.
/// * In the balanced coordinates `B = D⁻¹ M D` (`D = diag(2^e)`,
///   [`balance`], exact),
///   `e^{B−Δ_B} − e^B = ∫₀¹ e^{(1−s)(B−Δ_B)} (−Δ_B) e^{sB} ds`, so its
///   2-norm is at most `‖Δ_B‖₂·e^{μ₂(B)+‖Δ_B‖₂}` with the logarithmic norm
///   `μ₂(B)` bounded by Gershgorin's circles of the symmetric part
///   `(B + Bᵀ)/2` and `‖Δ_B‖₂ ≤ u‖|B|‖₂`; entry `(i, j)` of
///   `e^{M−Δ} − e^M = D (e^{B−Δ_B} − e^B) D⁻¹` is then at most
///   `2^{e_i−e_j}` times that. For a stiff oscillator `[[0, 1], [−ω², 0]]`
///   this replaces `e^{‖A T‖∞} = e^{ω²T}` by about 1 (`ω = 2π`, `T = 1`:
///   ±618 before, ±10⁻¹³).
///
/// Every sum and product is taken upward with a relative margin of 10⁻³,
/// far above their own rounding.
pub fn rounding_bound(m: &DMatrix<f64>) -> DMatrix<f64> {
    perturbation_bound(m, U * 1.0001)
}

/// Entrywise bounds on `|e^{M−Δ} − e^M|` for any `Δ` with
/// `|Δ| ≤ rel·|M| + η/2` entrywise (`η` the smallest subnormal: a product
/// rounded into the subnormal range is off by an absolute amount), as
/// [`rounding_bound`] describes; `‖Δ_B‖₂ ≤ ‖|Δ_B|‖₂ ≤ rel·‖|B|‖₂ +
/// k·η·2^{max e − min e}`, with `‖|B|‖₂ ≤ (‖B‖₁‖B‖∞)^{1/2}` (sums of
/// magnitudes, which do not underflow as squares would). Balanced sums
/// below `10⁻²⁹⁰` leave the crude bound.
fn perturbation_bound(m: &DMatrix<f64>, rel: f64) -> DMatrix<f64> {
    let k = m.nrows();
    let kf = k as f64;
    let delta = (norm_inf(m) * rel + kf * ETA).next_up();
    let crude = delta * (norm_inf(m) + delta).exp() * 1.0001;
    let ex = balance(m);
    let b = DMatrix::from_fn(k, k, |i, j| m[(i, j)] * 2f64.powi(ex[j] - ex[i]));
    // (the argument needs B = D⁻¹ M D exactly: no entry scaled into the
    // subnormal range)
    let exact = (0..k).all(|i| (0..k).all(|j| b[(i, j)] * 2f64.powi(ex[i] - ex[j]) == m[(i, j)]));
    let (n1, ninf) = (norm_inf(&b.transpose()), norm_inf(&b));
    let tiny = |v: f64| v != 0.0 && v < 1e-290;
    if !exact || tiny(n1) || tiny(ninf) {
        return DMatrix::from_element(k, k, crude);
    }
    let spread = match (ex.iter().max(), ex.iter().min()) {
        (Some(hi), Some(lo)) => 2f64.powi(hi - lo),
        _ => 1.0,
    };
    let delta_b = ((n1.sqrt() * ninf.sqrt() * rel + kf * ETA * spread) * 1.001).next_up();
    // μ₂(B) ≤ max_i b_ii + Σ_{j≠i} |b_ij + b_ji|/2, each row's sum raised
    // by 10⁻¹⁰ of its terms' magnitudes (its rounding is below k·u of them)
    let mu = (0..k)
        .map(|i| {
            let off = (0..k)
                .filter(|&j| j != i)
                .map(|j| 0.5 * (b[(i, j)] + b[(j, i)]).abs())
                .sum::<f64>();
            b[(i, i)] + off + 1e-10 * (b[(i, i)].abs() + off)
        })
        .fold(f64::NEG_INFINITY, f64::max);
    let mu = if mu.is_finite() { mu } else { f64::INFINITY };
    // an `exp` that underflows loses a positive amount that the large
    // factors could make matter: the crude bound then (∞ here picks it)
    let grow = (mu + delta_b).exp();
    let norm2 = if grow >= f64::MIN_POSITIVE {
        delta_b * grow * 1.001
    } else {
        f64::INFINITY
    };
    DMatrix::from_fn(k, k, |i, j| {
        // (`next_up`: a product scaled into the subnormal range rounds)
        let balanced = (norm2 * 2f64.powi(ex[i] - ex[j]) * 1.001).next_up();
        // an overflow (or a NaN crude bound) leaves the crude bound
        if balanced.is_finite() && balanced < crude {
            balanced
        } else {
            crude
        }
    })
}

/// Largest power-of-two exponent [`balance`] gives one coordinate.
const MAX_BALANCE: i32 = 100;

/// Exponents `e` of a diagonal `D = diag(2^e)` balancing `M`
/// (Parlett–Reinsch, radix 2): each coordinate's off-diagonal column and
/// row sums of `D⁻¹ M D` are brought within a factor of 4 of each other,
/// as long as that lowers their total by 5 %; a coordinate whose column
/// or row is zero off the diagonal is left alone. At most 64 sweeps, and
/// `|e_i| ≤ MAX_BALANCE`.
pub fn balance(m: &DMatrix<f64>) -> Vec<i32> {
    let k = m.nrows();
    let mut ex = vec![0i32; k];
    if m.iter().any(|v| !v.is_finite()) {
        return ex;
    }
    for _ in 0..64 {
        let mut done = true;
        for i in 0..k {
            let scale = |j: usize, i: usize| 2f64.powi(ex[j] - ex[i]);
            // column i and row i of D⁻¹ M D, off the diagonal
            let c: f64 = (0..k)
                .filter(|&j| j != i)
                .map(|j| (m[(j, i)] * scale(i, j)).abs())
                .sum();
            let r: f64 = (0..k)
                .filter(|&j| j != i)
                .map(|j| (m[(i, j)] * scale(j, i)).abs())
                .sum();
            if !(c > 0.0 && r > 0.0 && c.is_finite() && r.is_finite()) {
                continue;
            }
            let (mut cc, mut rr, mut f) = (c, r, 0i32);
            while cc < rr / 2.0 && ex[i] + f < MAX_BALANCE {
                cc *= 2.0;
                rr /= 2.0;
                f += 1;
            }
            while cc >= rr * 2.0 && ex[i] + f > -MAX_BALANCE {
                cc /= 2.0;
                rr *= 2.0;
                f -= 1;
            }
            if f != 0 && cc + rr < 0.95 * (c + r) {
                ex[i] += f;
                done = false;
            }
        }
        if done {
            break;
        }
    }
    ex
}

/// [`expm_enclosure`] without the balancing.
fn enclosure(m: &DMatrix<f64>) -> Option<(DMatrix<f64>, DMatrix<f64>)> {
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

    /// Balancing changes the enclosure, never what it contains: on badly
    /// scaled random matrices the balanced and the plain enclosures
    /// overlap entrywise (both hold the exact exponential), and for the
    /// stiff oscillator the balanced one is the tighter.
    #[test]
    fn balanced_and_plain_enclosures_agree() {
        let mut rng = ravel_base::rng::Rng::new(5);
        for case in 0..200 {
            let k = 2 + case % 3;
            let scales: Vec<f64> = (0..k)
                .map(|_| 10f64.powi(rng.below(7) as i32 - 3))
                .collect();
            let mut m = DMatrix::from_fn(k, k, |i, j| rng.normal() * scales[i] / scales[j]);
            let norm = norm_inf(&m);
            if norm > 6.0 {
                m *= 6.0 / norm;
            }
            let (pb, eb) = expm_enclosure(&m).expect("balanced");
            let (pu, eu) = enclosure(&m).expect("plain");
            for i in 0..k * k {
                assert!(
                    (pb[i] - pu[i]).abs() <= eb[i] + eu[i],
                    "case {case}, entry {i}: {} vs {} (± {}, ± {})",
                    pb[i],
                    pu[i],
                    eb[i],
                    eu[i]
                );
            }
        }
        let w2 = 39.47841760435743;
        let m = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -w2, 0.0]);
        assert_ne!(balance(&m), vec![0, 0]);
        let (_, eb) = expm_enclosure(&m).expect("balanced");
        let (_, eu) = enclosure(&m).expect("plain");
        assert!(eb.max() < eu.max(), "{} vs {}", eb.max(), eu.max());
    }

    /// The bound on the rounding of `A·T` is not below the first-order
    /// effect it bounds: for `M = [a]`, `|e^{a(1+u)} − e^a| ≈ u·|a|·e^a`.
    #[test]
    fn the_rounding_of_the_product_is_bounded_from_above() {
        for a in [0.7, 3.0, -2.0, 25.0, -700.0] {
            let m = DMatrix::from_row_slice(1, 1, &[a]);
            let r = rounding_bound(&m)[(0, 0)];
            let first_order = U * a.abs() * a.exp();
            assert!(r >= first_order, "{a}: {r} < {first_order}");
            assert!(r <= 1.1 * first_order, "{a}: {r} far above {first_order}");
        }
        // a diagonal 2 × 2: the larger exponential counts
        let m = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 4.0]);
        let r = rounding_bound(&m);
        let first_order = U * 4.0 * 4f64.exp();
        assert!(r[(1, 1)] >= first_order, "{} < {first_order}", r[(1, 1)]);
    }

    /// [`perturbation_bound`] bounds a perturbation large enough to see:
    /// for `M′ = M − rel·S∘M` (`S` random signs, `rel = 2⁻²⁰`, so `M′` is
    /// within `1.01·rel·|M|` of `M` after its own rounding), both
    /// enclosures hold the exact exponentials, so `|Φ′ − Φ| − E − E′` is a
    /// lower bound on `|e^{M′} − e^M|` that the bound must not be below.
    /// Cases: badly scaled random matrices, stiff oscillators, a non-normal
    /// rotation, and matrices whose balanced sums of squares would
    /// underflow.
    #[test]
    fn the_perturbation_bound_is_not_below_a_seen_perturbation() {
        let rel = 2f64.powi(-20);
        let mut rng = ravel_base::rng::Rng::new(9);
        let mut cases: Vec<DMatrix<f64>> = vec![
            DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -39.47841760435743, 0.0]),
            DMatrix::from_row_slice(2, 2, &[0.0, 0.3, -400.0 * 0.3, -0.1]),
            DMatrix::from_row_slice(2, 2, &[0.0, 2f64.powi(40), -(2f64.powi(-30)), 0.0]),
            DMatrix::from_row_slice(2, 2, &[0.0, 1e-105, 1e-225, 0.0]),
            DMatrix::from_row_slice(2, 2, &[0.0, 1e-140, 1e-190, 0.0]),
        ];
        for case in 0..100 {
            let k = 2 + case % 3;
            let scales: Vec<f64> = (0..k)
                .map(|_| 10f64.powi(rng.below(9) as i32 - 4))
                .collect();
            let mut m = DMatrix::from_fn(k, k, |i, j| rng.normal() * scales[i] / scales[j]);
            let norm = norm_inf(&m);
            if norm > 8.0 {
                m *= 8.0 / norm;
            }
            cases.push(m);
        }
        let mut seen = 0;
        for (c, m) in cases.iter().enumerate() {
            let k = m.nrows();
            let signs = DMatrix::from_fn(k, k, |_, _| if rng.below(2) == 0 { 1.0 } else { -1.0 });
            let m2 = DMatrix::from_fn(k, k, |i, j| m[(i, j)] - rel * signs[(i, j)] * m[(i, j)]);
            let (p, e) = expm_enclosure(m).expect("finite");
            let (p2, e2) = expm_enclosure(&m2).expect("finite");
            let bound = perturbation_bound(m, rel * 1.01);
            for i in 0..k * k {
                let lower = (p2[i] - p[i]).abs() - e[i] - e2[i];
                assert!(
                    lower <= bound[i] * (1.0 + 1e-9),
                    "case {c}, entry {i}: {lower} > bound {}",
                    bound[i]
                );
                if lower > 0.0 {
                    seen += 1;
                }
            }
        }
        assert!(seen > 100, "the perturbations are visible: {seen}");
    }
}
