//! Floating-point arithmetic with rigorous outward rounding.
//!
//! Every bound that ravel reports is computed in `f64` and then pushed
//! outward by a proven bound on the rounding error, so that a bound is valid
//! for the *exact* real-arithmetic quantity it describes.
//!
//! The error model is the standard one (Higham, *Accuracy and Stability of
//! Numerical Algorithms*, §2–3): a sum of `n` floating-point numbers computed
//! in any order with round-to-nearest has absolute error at most
//! `γ(n-1) · Σ|tᵢ|`, where `γ(n) = n·u / (1 − n·u)` and `u = 2⁻⁵³`; a product
//! has relative error at most `u`, plus an absolute error below the smallest
//! subnormal if it underflows. The helpers here add such bounds (with a
//! generous factor for the rounding of the error bound itself) and finish
//! with one `next_up`/`next_down`.

/// Unit roundoff of `f64` with round-to-nearest.
pub const U: f64 = f64::EPSILON / 2.0;

/// Smallest positive subnormal: bounds the absolute error of an underflowing product.
pub const ETA: f64 = f64::from_bits(1);

/// An upper bound of `γ(n) = n·u / (1 − n·u)`, the relative error factor of an
/// `n`-term sum: `1.01·n·u`, valid while `n·u ≤ 0.0099` (n below 4·10¹³), and
/// free of the division.
pub fn gamma(n: usize) -> f64 {
    debug_assert!((n as f64) * U <= 0.0099);
    n as f64 * (U * 1.01)
}

/// The error bound for `count` rounded operations on terms with absolute sum `abs_sum`,
/// itself rounded upward with a safety factor.
fn error_bound(count: usize, abs_sum: f64) -> f64 {
    (gamma(count + 2) * abs_sum * 1.0625 + (count as f64 + 2.0) * ETA).next_up()
}

/// An upper bound on the exact sum of the exact values whose rounded values
/// are `terms` (each term is itself at most one rounding away from its exact value).
///
/// Infinite terms give an infinite result; NaN propagates.
pub fn sum_upper<I: IntoIterator<Item = f64>>(terms: I) -> f64 {
    let (mut s, mut a, mut n) = (0.0f64, 0.0f64, 0usize);
    for t in terms {
        s += t;
        a += t.abs();
        n += 1;
    }
    if !s.is_finite() || !a.is_finite() {
        return s;
    }
    (s + error_bound(n, a)).next_up()
}

/// A lower bound on the exact sum; see [`sum_upper`].
pub fn sum_lower<I: IntoIterator<Item = f64>>(terms: I) -> f64 {
    -sum_upper(terms.into_iter().map(|t| -t))
}

/// `a·x` where `x` may be infinite and `a` may be zero: zero times anything is zero.
pub fn mul0(a: f64, x: f64) -> f64 {
    if a == 0.0 {
        0.0
    } else {
        a * x
    }
}

/// Upper bound of `Σ aᵢ xᵢ` over the box `lo ≤ x ≤ hi` (exact coefficients `a`).
pub fn dot_box_upper(a: &[f64], lo: &[f64], hi: &[f64]) -> f64 {
    sum_upper(
        a.iter()
            .zip(lo.iter().zip(hi))
            .map(|(&a, (&l, &h))| if a >= 0.0 { mul0(a, h) } else { mul0(a, l) }),
    )
}

/// Lower bound of `Σ aᵢ xᵢ` over the box `lo ≤ x ≤ hi` (exact coefficients `a`).
pub fn dot_box_lower(a: &[f64], lo: &[f64], hi: &[f64]) -> f64 {
    sum_lower(
        a.iter()
            .zip(lo.iter().zip(hi))
            .map(|(&a, (&l, &h))| if a >= 0.0 { mul0(a, l) } else { mul0(a, h) }),
    )
}

/// Upper bound of the error `|Σ aᵢ xᵢ − fl(...)|`-style slack: `k · Σ|aᵢ|·mᵢ`, rounded up,
/// where `k` is a relative error factor and `m` bounds `|x|`.
pub fn slack(k: f64, a: &[f64], m: &[f64]) -> f64 {
    let s: f64 = a.iter().zip(m).map(|(a, m)| mul0(a.abs(), *m)).sum();
    (k * s * 1.0625 + (a.len() as f64 + 2.0) * ETA).next_up()
}

/// The largest absolute value in `[lo, hi]`.
pub fn abs_max(lo: f64, hi: f64) -> f64 {
    lo.abs().max(hi.abs())
}

/// Upper bound of `f − a·z` where `f` approximates an exact value with absolute error at most `f_err`.
pub fn gap_upper(f: f64, f_err: f64, a: f64, z: f64) -> f64 {
    let p = mul0(a, z);
    let t = f - p;
    (t + f_err + 3.0 * U * (f.abs() + p.abs()) + 4.0 * ETA).next_up()
}

/// Lower bound of `f − a·z`; see [`gap_upper`].
pub fn gap_lower(f: f64, f_err: f64, a: f64, z: f64) -> f64 {
    -gap_upper(-f, f_err, -a, z)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gamma_bounds_the_textbook_factor() {
        for n in [1usize, 2, 10, 1000, 1 << 30] {
            let nu = n as f64 * U;
            assert!(gamma(n) >= nu / (1.0 - nu));
        }
    }

    #[test]
    fn sum_upper_bounds_a_cancelling_sum() {
        // 0.1 + 0.2 - 0.3 is 5.55e-17 in f64 but 0 exactly (for the decimal values);
        // the f64 inputs themselves are exact, so the exact sum of the f64 values is
        // what must be bounded.
        let terms = [0.1f64, 0.2, -0.3];
        let up = sum_upper(terms);
        let lo = sum_lower(terms);
        assert!(lo <= up);
        // exact sum of the three doubles, computed with an error-free transformation
        let (s, e) = two_sum(0.1 + 0.2, -0.3);
        let (s1, e1) = two_sum(0.1, 0.2);
        let exact_hi = s + e + e1;
        assert!(
            lo <= exact_hi && exact_hi <= up,
            "{lo} {exact_hi} {up} {s1}"
        );
    }

    fn two_sum(a: f64, b: f64) -> (f64, f64) {
        let s = a + b;
        let bb = s - a;
        (s, (a - (s - bb)) + (b - bb))
    }

    #[test]
    fn dot_box_handles_zero_times_infinity() {
        let a = [0.0, 2.0];
        let lo = [f64::NEG_INFINITY, -1.0];
        let hi = [f64::INFINITY, 3.0];
        assert!(dot_box_upper(&a, &lo, &hi) >= 6.0);
        assert!(dot_box_lower(&a, &lo, &hi) <= -2.0);
    }

    #[test]
    fn bounds_are_strictly_outward_on_exact_values() {
        assert!(sum_upper([1.0, 2.0]) > 3.0);
        assert!(sum_lower([1.0, 2.0]) < 3.0);
    }
}
