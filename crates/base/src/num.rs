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

/// The smallest positive normal number, `2⁵²·ETA`: it bounds the underflow
/// error of up to 2⁵² products (`n·ETA ≤ TINY`), and every error term uses it
/// instead of `n·ETA`. Arithmetic on subnormal numbers takes a microcode
/// assist on x86 (about a hundred cycles an operation): with `n·ETA` every
/// rounded sum paid it; with a normal constant none does, and the bound
/// grows by at most 2.3·10⁻³⁰⁸.
pub const TINY: f64 = f64::MIN_POSITIVE;

/// An upper bound of `γ(n) = n·u / (1 − n·u)`, the relative error factor of an
/// `n`-term sum: `1.01·n·u`, valid while `n·u ≤ 0.0099` (n below 4·10¹³), and
/// free of the division.
pub fn gamma(n: usize) -> f64 {
    debug_assert!((n as f64) * U <= 0.0099);
    n as f64 * (U * 1.01)
}

/// The error bound for `count` rounded operations on terms with absolute sum `abs_sum`,
/// itself rounded upward with a safety factor.
pub fn error_bound(count: usize, abs_sum: f64) -> f64 {
    (gamma(count + 2) * abs_sum * 1.0625 + TINY).next_up()
}

/// An upper bound on the exact sum of the exact values whose rounded values
/// are `terms` (each term is itself at most one rounding away from its exact value).
///
/// # Saturation
///
/// The answer is finite or `+∞`, never `−∞` nor NaN: whenever the rounded
/// sum or the sum of magnitudes is not finite (an infinite or NaN term, or a
/// running sum that overflowed, in either direction), the only bound the
/// terms give is `+∞`. A running sum that overflows to `−∞` says nothing
/// about the exact sum: `−1.7e308 − 1.7e308 + 1.7e308 + 1.7e308 + 1.7e308`
/// overflows to `−∞` at its second term while the exact sum is `+1.7e308`.
/// Taking `−∞` (or NaN, which `min` and `max` silently drop) as an upper
/// bound would prove anything. [`sum_lower`] saturates to `−∞` the same way.
pub fn sum_upper<I: IntoIterator<Item = f64>>(terms: I) -> f64 {
    let (mut s, mut a, mut n) = (0.0f64, 0.0f64, 0usize);
    for t in terms {
        s += t;
        a += t.abs();
        n += 1;
    }
    Acc { s, a, n }.upper()
}

/// A running sum for [`sum_upper`]/[`sum_lower`] built term by term in a
/// loop (no iterator, no allocation): the same bound as `sum_upper` over the
/// same terms in the same order.
#[derive(Clone, Copy, Debug, Default)]
pub struct Acc {
    s: f64,
    a: f64,
    n: usize,
}

impl Acc {
    /// An empty sum.
    pub const ZERO: Acc = Acc {
        s: 0.0,
        a: 0.0,
        n: 0,
    };

    /// A sum of one term.
    #[inline]
    pub fn of(t: f64) -> Acc {
        let mut a = Acc::ZERO;
        a.add(t);
        a
    }

    /// Add one term (a value at most one rounding away from its exact value).
    #[inline]
    pub fn add(&mut self, t: f64) {
        self.s += t;
        self.a += t.abs();
        self.n += 1;
    }

    /// Add `t` as a term when `counted` (then `t` is at most one rounding
    /// from its value); otherwise `t` must be `0.0` and nothing is counted.
    /// Without a branch: callers in hot loops pass the condition they would
    /// have branched on, so the sum and its bound are those of the branching
    /// loop (a sum that is exactly zero may change the sign of its zero).
    #[inline]
    pub fn add_counted(&mut self, t: f64, counted: bool) {
        debug_assert!(counted || t == 0.0);
        self.s += t;
        self.a += t.abs();
        self.n += usize::from(counted);
    }

    /// Add the products `xᵢ·yᵢ` (each product a term; zero times an
    /// infinity is zero). The terms are summed in four interleaved partial
    /// sums, which keeps the adder busy: the error bound holds for any order
    /// of summation (Higham, §4.2), so the bound is that of the same terms
    /// added one by one, only the rounded value may differ.
    #[inline]
    pub fn add_products(&mut self, x: &[f64], y: &[f64]) {
        let n = x.len().min(y.len());
        if n < 4 {
            // fewer terms than lanes: each lane holds at most one term, and
            // the lanes combine as below, `(s₀ + s₁) + (s₂ + s₃)` with the
            // missing ones 0, the same additions without the lane set-up
            let t = |i: usize| if i < n { mul0(x[i], y[i]) } else { 0.0 };
            let (t0, t1, t2) = (t(0), t(1), t(2));
            let (s0, s1, s2) = (0.0 + t0, 0.0 + t1, 0.0 + t2);
            let (a0, a1, a2) = (0.0 + t0.abs(), 0.0 + t1.abs(), 0.0 + t2.abs());
            self.s += (s0 + s1) + (s2 + 0.0);
            self.a += (a0 + a1) + (a2 + 0.0);
            self.n += n;
            return;
        }
        let (mut s, mut a) = ([0.0f64; 4], [0.0f64; 4]);
        let (xc, yc) = (x[..n].chunks_exact(4), y[..n].chunks_exact(4));
        let (xr, yr) = (xc.remainder(), yc.remainder());
        for (x4, y4) in xc.zip(yc) {
            for l in 0..4 {
                let t = mul0(x4[l], y4[l]);
                s[l] += t;
                a[l] += t.abs();
            }
        }
        for (l, (x, y)) in xr.iter().zip(yr).enumerate() {
            let t = mul0(*x, *y);
            s[l] += t;
            a[l] += t.abs();
        }
        self.s += (s[0] + s[1]) + (s[2] + s[3]);
        self.a += (a[0] + a[1]) + (a[2] + a[3]);
        self.n += n;
    }

    /// Add the terms of another running sum: the same terms summed in
    /// another order, which the error bound covers (it holds for any
    /// order of summation).
    #[inline]
    pub fn merge(&mut self, other: Acc) {
        self.s += other.s;
        self.a += other.a;
        self.n += other.n;
    }

    /// The running sum of `n` terms whose rounded sum is `s` and whose
    /// absolute values' rounded sum is `a`, both summed term by term in
    /// the same order as [`Acc::add`] would: for loops that keep the three
    /// apart (one count for many sums, the sums in arrays that vectorise).
    #[inline]
    pub fn from_parts(s: f64, a: f64, n: usize) -> Acc {
        Acc { s, a, n }
    }

    /// An upper bound on the exact sum of the terms: finite or `+∞`, never
    /// `−∞` nor NaN (see [`sum_upper`]).
    #[inline]
    pub fn upper(self) -> f64 {
        // `a` is a sum of magnitudes: finite `a` means every term and every
        // partial sum is finite, so `s` is too; the final addition can only
        // overflow upward, to `+∞`
        if !(self.a.is_finite() && self.s.is_finite()) {
            return f64::INFINITY;
        }
        (self.s + error_bound(self.n, self.a)).next_up()
    }

    /// A lower bound on the exact sum of the terms: finite or `−∞`, never
    /// `+∞` nor NaN (see [`sum_lower`]).
    #[inline]
    pub fn lower(self) -> f64 {
        if !(self.a.is_finite() && self.s.is_finite()) {
            return f64::NEG_INFINITY;
        }
        (self.s - error_bound(self.n, self.a)).next_down()
    }
}

/// A lower bound on the exact sum: finite or `−∞`, never `+∞` nor NaN; see
/// [`sum_upper`].
pub fn sum_lower<I: IntoIterator<Item = f64>>(terms: I) -> f64 {
    -sum_upper(terms.into_iter().map(|t| -t))
}

/// `a·x` where `x` may be infinite and `a` may be zero: zero times anything is zero.
#[inline]
pub fn mul0(a: f64, x: f64) -> f64 {
    // computed first and then selected: a select, not a branch, so that
    // loops over it vectorise
    let p = a * x;
    if a == 0.0 {
        0.0
    } else {
        p
    }
}

/// `max(a·l, a·h)` as a term of an upper bound of `a·x` over `l ≤ x ≤ h`
/// (zero when `a = 0`, whatever the bounds); branch-free.
#[inline]
pub fn term_upper(a: f64, l: f64, h: f64) -> f64 {
    let (pl, ph) = (a * l, a * h);
    let t = if a > 0.0 { ph } else { pl };
    if a == 0.0 {
        0.0
    } else {
        t
    }
}

/// `min(a·l, a·h)` as a term of a lower bound of `a·x` over `l ≤ x ≤ h`
/// (zero when `a = 0`); branch-free.
#[inline]
pub fn term_lower(a: f64, l: f64, h: f64) -> f64 {
    // min(a·l, a·h) = −max((−a)·l, (−a)·h); negation is exact
    -term_upper(-a, l, h)
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

/// `Σ |aᵢ|·mᵢ` in `f64` (zero where `aᵢ = 0`, whatever `mᵢ`), in four
/// interleaved partial sums; not rounded up: callers scale it by a safety
/// factor that covers its own rounding.
#[inline]
pub fn abs_dot(a: &[f64], m: &[f64]) -> f64 {
    let n = a.len().min(m.len());
    if n < 4 {
        // one term per lane at most: the lanes' sum below without the set-up
        let t = |i: usize| {
            if i < n {
                0.0 + mul0(a[i].abs(), m[i])
            } else {
                0.0
            }
        };
        return (t(0) + t(1)) + (t(2) + 0.0);
    }
    let mut s = [0.0f64; 4];
    let (ac, mc) = (a[..n].chunks_exact(4), m[..n].chunks_exact(4));
    let (ar, mr) = (ac.remainder(), mc.remainder());
    for (a4, m4) in ac.zip(mc) {
        for l in 0..4 {
            s[l] += mul0(a4[l].abs(), m4[l]);
        }
    }
    for (l, (a, m)) in ar.iter().zip(mr).enumerate() {
        s[l] += mul0(a.abs(), *m);
    }
    (s[0] + s[1]) + (s[2] + s[3])
}

/// Upper bound of the error `|Σ aᵢ xᵢ − fl(...)|`-style slack: `k · Σ|aᵢ|·mᵢ`, rounded up,
/// where `k` is a relative error factor and `m` bounds `|x|`.
#[inline]
pub fn slack(k: f64, a: &[f64], m: &[f64]) -> f64 {
    slack_of_sum(k, abs_dot(a, m))
}

/// [`slack`] from `Σ|aᵢ|·mᵢ` summed in `f64` by the caller (any order).
/// An error bound: finite or `+∞`, never NaN.
#[inline]
pub fn slack_of_sum(k: f64, abs_dot: f64) -> f64 {
    // the factor 1.0625 also covers the rounding of the sum itself
    sat_upper((k * abs_dot * 1.0625 + TINY).next_up())
}

/// `v` as an upper bound that saturates soundly: `v` itself when it is
/// finite or `+∞`; `+∞` when it is NaN or `−∞`. A computed upper bound is
/// `−∞` only when some step overflowed in the wrong direction (the exact
/// quantity is a real number), and NaN only when an infinity met its
/// opposite; in both cases the computation bounds nothing.
#[inline]
pub fn sat_upper(v: f64) -> f64 {
    if v > f64::NEG_INFINITY {
        v
    } else {
        f64::INFINITY
    }
}

/// `v` as a lower bound that saturates soundly: `v` when it is finite or
/// `−∞`; `−∞` when it is NaN or `+∞` (see [`sat_upper`]).
#[inline]
pub fn sat_lower(v: f64) -> f64 {
    if v < f64::INFINITY {
        v
    } else {
        f64::NEG_INFINITY
    }
}

/// The largest absolute value in `[lo, hi]`.
pub fn abs_max(lo: f64, hi: f64) -> f64 {
    lo.abs().max(hi.abs())
}

/// Upper bound of `f − a·z` where `f` approximates an exact value with
/// absolute error at most `f_err`: finite or `+∞`, never `−∞` nor NaN.
pub fn gap_upper(f: f64, f_err: f64, a: f64, z: f64) -> f64 {
    let p = mul0(a, z);
    let t = f - p;
    let e = f_err + 3.0 * U * (f.abs() + p.abs()) + TINY;
    if !(t.is_finite() && e.is_finite()) {
        // an infinite operand, or `f − a·z` overflowed (possibly downward,
        // where the exact value is a real number): no finite bound
        return f64::INFINITY;
    }
    (t + e).next_up()
}

/// Lower bound of `f − a·z`: finite or `−∞`; see [`gap_upper`].
pub fn gap_lower(f: f64, f_err: f64, a: f64, z: f64) -> f64 {
    -gap_upper(-f, f_err, -a, z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exact::{is_lower, is_upper, Extreme, Fixed};

    /// Sums near `f64::MAX`, of subnormals and of mixed signs: every upper
    /// bound is `+∞` or a finite number at least the exact sum (never `−∞`
    /// nor NaN), every lower bound likewise; through `sum_upper`,
    /// `sum_lower`, `Acc` (one by one, merged, products with powers of
    /// two) and the box dot products.
    #[test]
    fn directed_sums_saturate_soundly_at_every_magnitude() {
        let mut g = Extreme::new(26);
        let mut finite_seen = 0;
        for round in 0..20_000 {
            let n = 1 + g.below(if round % 2 == 0 { 6 } else { 40 });
            let terms: Vec<f64> = (0..n).map(|_| g.value()).collect();
            let exact = Fixed::sum(terms.iter().copied());
            let (up, lo) = (
                sum_upper(terms.iter().copied()),
                sum_lower(terms.iter().copied()),
            );
            assert!(is_upper(up, exact), "upper {up:e} of {terms:?}");
            assert!(is_lower(lo, exact), "lower {lo:e} of {terms:?}");
            finite_seen += usize::from(up.is_finite());
            // a running sum in two parts, merged
            let cut = g.below(n + 1);
            let (mut a, mut b) = (Acc::ZERO, Acc::ZERO);
            terms[..cut].iter().for_each(|&t| a.add(t));
            terms[cut..].iter().for_each(|&t| b.add(t));
            a.merge(b);
            assert!(is_upper(a.upper(), exact) && is_lower(a.lower(), exact));
            // products with powers of two: each term one rounding (or an
            // overflow) away from its exact value
            let k: Vec<u32> = (0..n).map(|_| g.below(3) as u32).collect();
            let scale: Vec<f64> = k.iter().map(|&k| f64::from(1u32 << k)).collect();
            let exact_products = terms
                .iter()
                .zip(&k)
                .fold(Fixed::ZERO, |s, (&t, &k)| s.add(Fixed::of_scaled(t, k)));
            let mut p = Acc::ZERO;
            p.add_products(&scale, &terms);
            assert!(is_upper(p.upper(), exact_products), "{terms:?} × {scale:?}");
            assert!(is_lower(p.lower(), exact_products), "{terms:?} × {scale:?}");
            // Σ aᵢ xᵢ over a box whose sides are single points
            let up_box = dot_box_upper(&scale, &terms, &terms);
            let lo_box = dot_box_lower(&scale, &terms, &terms);
            assert!(is_upper(up_box, exact_products) && is_lower(lo_box, exact_products));
        }
        // the test also reaches finite answers, not only saturated ones
        assert!(finite_seen > 5_000, "{finite_seen}");
    }

    /// The forgery of issue 26: a running sum that overflows to `−∞` while
    /// the exact sum is `+1.7e308` is not an upper bound of anything.
    #[test]
    fn a_sum_overflowing_downward_is_no_upper_bound() {
        let terms = [-1.7e308, -1.7e308, 1.7e308, 1.7e308, 1.7e308];
        assert_eq!(sum_upper(terms), f64::INFINITY);
        assert_eq!(sum_lower(terms.map(|t| -t)), f64::NEG_INFINITY);
        // a dual term of 3.5e307 on a row of the goal, as in the forged
        // certificate: the support overflows; its bound is +∞
        let mut acc = Acc::of(-3.5e307 * 6.0);
        acc.add(-3.5e307 * 6.0);
        acc.add(1.0);
        assert!(acc.upper().is_finite() || acc.upper() == f64::INFINITY);
        assert!(acc.upper() > f64::NEG_INFINITY);
        assert_eq!(gap_upper(-1.7e308, 0.0, 1.0, 1.7e308), f64::INFINITY);
        assert_eq!(gap_lower(1.7e308, 0.0, 1.0, -1.7e308), f64::NEG_INFINITY);
        assert_eq!(gap_upper(f64::NAN, 0.0, 1.0, 1.0), f64::INFINITY);
        assert_eq!(slack_of_sum(1.0, f64::NAN), f64::INFINITY);
        assert_eq!(sat_upper(f64::NEG_INFINITY), f64::INFINITY);
        assert_eq!(sat_lower(f64::NAN), f64::NEG_INFINITY);
        assert_eq!(sat_upper(-2.0), -2.0);
    }

    #[test]
    fn counted_terms_sum_as_the_branching_loop_does() {
        let terms = [0.1, 0.0, -2.5e-3, 0.0, 7.0, -0.0, 1e-300];
        let (mut branching, mut selecting) = (Acc::ZERO, Acc::ZERO);
        for &t in &terms {
            if t != 0.0 {
                branching.add(t);
            }
            selecting.add_counted(if t != 0.0 { t } else { 0.0 }, t != 0.0);
        }
        assert_eq!(branching.upper(), selecting.upper());
        assert_eq!(branching.lower(), selecting.lower());
        // the count matters: the same terms with the zeros counted give a
        // strictly wider bound, so an uncounted zero is really left out
        let mut more = Acc::ZERO;
        for &t in &terms {
            more.add(t);
        }
        assert!(more.upper() > selecting.upper());
        assert!(more.lower() < selecting.lower());
    }

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
    fn acc_matches_sum_upper_and_sum_lower() {
        let terms = [0.1f64, -3.5e-17, 2.0, -0.3, 1e-300, 7.0];
        let mut acc = Acc::ZERO;
        for t in terms {
            acc.add(t);
        }
        assert_eq!(acc.upper().to_bits(), sum_upper(terms).to_bits());
        assert_eq!(acc.lower().to_bits(), sum_lower(terms).to_bits());
        let mut inf = Acc::ZERO;
        inf.add(f64::INFINITY);
        inf.add(1.0);
        assert_eq!(inf.upper(), f64::INFINITY);
        let mut nan = Acc::ZERO;
        nan.add(f64::INFINITY);
        nan.add(f64::NEG_INFINITY);
        assert_eq!(nan.upper(), f64::INFINITY);
        assert_eq!(nan.lower(), f64::NEG_INFINITY);
    }

    #[test]
    fn interleaved_products_bound_the_exact_sum() {
        let mut rng = crate::rng::Rng::new(3);
        for n in 0..40 {
            let x: Vec<f64> = (0..n).map(|_| rng.uniform(-1.0, 1.0)).collect();
            let y: Vec<f64> = (0..n).map(|_| rng.uniform(-1e3, 1e3)).collect();
            let mut acc = Acc::ZERO;
            acc.add(0.25);
            acc.add_products(&x, &y);
            let one_by_one =
                sum_upper(std::iter::once(0.25).chain(x.iter().zip(&y).map(|(a, b)| a * b)));
            let lower_one_by_one =
                sum_lower(std::iter::once(0.25).chain(x.iter().zip(&y).map(|(a, b)| a * b)));
            // both are bounds on the same exact sum: their intervals overlap,
            // and each is within a few ulps of the other's
            assert!(acc.upper() >= lower_one_by_one && acc.lower() <= one_by_one);
            assert!((acc.upper() - one_by_one).abs() <= 1e-12 * (1.0 + one_by_one.abs()));
            let m: Vec<f64> = y.iter().map(|v| v.abs()).collect();
            let plain: f64 = x.iter().zip(&m).map(|(a, b)| a.abs() * b).sum();
            assert!((abs_dot(&x, &m) - plain).abs() <= 1e-12 * (1.0 + plain));
        }
        assert_eq!(abs_dot(&[0.0], &[f64::INFINITY]), 0.0);
    }

    /// The four-lane sums of `add_products` and `abs_dot` as written for
    /// long vectors, for any length.
    fn lanes(x: &[f64], y: &[f64]) -> (f64, f64, f64) {
        let (mut s, mut a, mut d) = ([0.0f64; 4], [0.0f64; 4], [0.0f64; 4]);
        for (i, (&x, &y)) in x.iter().zip(y).enumerate() {
            let t = mul0(x, y);
            s[i % 4] += t;
            a[i % 4] += t.abs();
            d[i % 4] += mul0(x.abs(), y);
        }
        let sum = |v: [f64; 4]| (v[0] + v[1]) + (v[2] + v[3]);
        (sum(s), sum(a), sum(d))
    }

    #[test]
    fn short_products_are_the_lane_sums_bit_for_bit() {
        let mut rng = crate::rng::Rng::new(11);
        let pick = [0.0, -0.0, 1.0, -3.5, 1e-300, f64::INFINITY, 0.1];
        for round in 0..400 {
            let n = round % 4;
            let gen = |rng: &mut crate::rng::Rng| -> f64 {
                let k = (rng.uniform(0.0, 1.0) * 10.0) as usize;
                pick.get(k)
                    .copied()
                    .unwrap_or_else(|| rng.uniform(-5.0, 5.0))
            };
            let x: Vec<f64> = (0..n).map(|_| gen(&mut rng)).collect();
            let y: Vec<f64> = (0..n).map(|_| gen(&mut rng).abs()).collect();
            let (s, a, d) = lanes(&x, &y);
            let mut acc = Acc::of(0.5);
            acc.add_products(&x, &y);
            let mut want = Acc::of(0.5);
            want.s += s;
            want.a += a;
            want.n += n;
            assert_eq!(acc.s.to_bits(), want.s.to_bits(), "{x:?} {y:?}");
            assert_eq!(acc.a.to_bits(), want.a.to_bits(), "{x:?} {y:?}");
            assert_eq!(acc.n, want.n);
            assert_eq!(abs_dot(&x, &y).to_bits(), d.to_bits(), "{x:?} {y:?}");
        }
    }

    #[test]
    fn bounds_are_strictly_outward_on_exact_values() {
        assert!(sum_upper([1.0, 2.0]) > 3.0);
        assert!(sum_lower([1.0, 2.0]) < 3.0);
    }
}
