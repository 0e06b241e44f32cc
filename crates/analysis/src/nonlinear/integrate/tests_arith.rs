//! Intervals and Taylor models against points.

use super::interval::{DomainError, Interval};
use super::tm::{combine, product_pass, quadratic, support, Lin, Tm};
use ravel_base::expr::Func;
use ravel_base::rng::Rng;

/// A random interval of magnitude about `scale`, and a point inside.
fn random_interval(g: &mut Rng, scale: f64) -> (Interval, f64) {
    let a = g.uniform(-scale, scale);
    let w = g.uniform(0.0, scale) * if g.below(4) == 0 { 1e-9 } else { 1.0 };
    let iv = Interval::new(a, a + w);
    let x = g.uniform(iv.lo, iv.hi);
    (iv, x)
}

/// The function at a point, as `libm` computes it (the enclosures assume
/// it within four ulps; the checks allow two).
fn point_value(f: Func, x: f64) -> f64 {
    f.apply(x)
}

fn contains_loosely(iv: Interval, v: f64) -> bool {
    let slack = 2.0 * f64::EPSILON * v.abs();
    iv.lo <= v + slack && v - slack <= iv.hi
}

#[test]
fn pi_enclosure_is_one_ulp_wide() {
    let p = Interval::point(1.0) * Interval::new(std::f64::consts::PI, 3.141_592_653_589_793_6);
    assert!(p.hi > p.lo);
    assert_eq!(3.141_592_653_589_793_6, std::f64::consts::PI.next_up());
}

#[test]
fn arithmetic_encloses_random_points() {
    let mut g = Rng::new(7);
    for round in 0..20_000 {
        let scale = [1e-3, 1.0, 1e3, 1e100][round % 4];
        let ((a, x), (b, y)) = (
            random_interval(&mut g, scale),
            random_interval(&mut g, scale),
        );
        assert!((a + b).contains(x + y));
        assert!((a - b).contains(x - y));
        assert!((a * b).contains(x * y));
        assert!(a.sqr().contains(x * x) && a.sqr().lo >= 0.0);
        if let Ok(q) = a.div(b) {
            assert!(q.contains(x / y), "{a:?} / {b:?}");
        } else {
            assert!(b.contains_zero());
        }
        for n in [-3, -2, -1, 0, 1, 2, 3, 4, 7] {
            if let Ok(p) = a.powi(n) {
                let v = x.powi(n);
                assert!(contains_loosely(p, v), "{a:?}^{n} = {p:?} ∌ {v}");
                if n % 2 == 0 {
                    assert!(p.lo >= 0.0);
                }
            }
        }
    }
}

#[test]
fn elementary_functions_enclose_random_points() {
    let mut g = Rng::new(11);
    for round in 0..20_000 {
        let scale = [0.1, 1.0, 3.0, 20.0, 700.0][round % 5];
        let (iv, x) = random_interval(&mut g, scale);
        for f in Func::ALL {
            let v = point_value(f, x);
            match iv.apply(f) {
                Ok(r) => assert!(r.contains(v), "{}({iv:?}) = {r:?} ∌ {v} at {x}", f.name()),
                Err(e) => {
                    let expected = match f {
                        Func::Log => e == DomainError::LogOfNonPositive && iv.lo <= 0.0,
                        Func::Sqrt => e == DomainError::SqrtOfNegative && iv.lo < 0.0,
                        Func::Tan => e == DomainError::TanPole,
                        Func::Exp => e == DomainError::NotFinite && iv.hi > 700.0,
                        _ => false,
                    };
                    assert!(expected, "{}({iv:?}): {e:?}", f.name());
                }
            }
        }
    }
}

#[test]
fn trigonometric_extrema_are_included() {
    let half_pi = std::f64::consts::FRAC_PI_2;
    let s = Interval::new(half_pi - 1e-3, half_pi + 1e-3).sin().unwrap();
    assert_eq!(s.hi, 1.0);
    let c = Interval::new(3.0, 3.3).cos().unwrap();
    assert_eq!(c.lo, -1.0);
    let m = Interval::new(0.1, 0.2).sin().unwrap();
    assert!(m.hi < 0.2 && m.lo > 0.09);
    assert_eq!(
        Interval::new(0.0, 100.0).sin().unwrap(),
        Interval::new(-1.0, 1.0)
    );
}

#[test]
fn domain_errors() {
    let one = Interval::new(-1.0, 1.0);
    assert_eq!(one.log(), Err(DomainError::LogOfNonPositive));
    assert_eq!(one.recip(), Err(DomainError::DivisionByZero));
    assert_eq!(
        Interval::point(2.0).div(one),
        Err(DomainError::DivisionByZero)
    );
    assert_eq!(one.powi(-2), Err(DomainError::DivisionByZero));
    assert_eq!(
        Interval::new(-2.0, -1.0).sqrt(),
        Err(DomainError::SqrtOfNegative)
    );
    let half_pi = std::f64::consts::FRAC_PI_2;
    assert_eq!(Interval::new(1.5, 1.6).tan(), Err(DomainError::TanPole));
    assert_eq!(Interval::point(half_pi).tan(), Err(DomainError::TanPole));
    assert_eq!(Interval::new(-4.8, -4.7).tan(), Err(DomainError::TanPole));
    assert!(Interval::new(1.4, 1.5).tan().is_ok());
    for e in [
        DomainError::DivisionByZero,
        DomainError::LogOfNonPositive,
        DomainError::SqrtOfNegative,
        DomainError::TanPole,
        DomainError::AbsKink,
        DomainError::NotFinite,
    ] {
        assert!(!e.as_str().is_empty() && e.to_string() == e.as_str());
    }
}

#[test]
fn non_finite_inputs_are_errors_never_bounds() {
    let bad = [
        Interval::new(f64::NAN, 1.0),
        Interval::new(0.0, f64::NAN),
        Interval::new(0.0, f64::INFINITY),
        Interval::new(f64::NEG_INFINITY, 0.0),
        Interval::new(2.0, 1.0),
    ];
    let huge = Interval::new(1e308, 1.7e308);
    for b in bad {
        assert!(!b.is_finite());
        assert_eq!(b.checked(), Err(DomainError::NotFinite));
        for f in Func::ALL {
            assert!(b.apply(f).is_err(), "{}({b:?})", f.name());
        }
        assert!(!(b * Interval::point(0.0)).is_finite());
        assert!(!(b + Interval::point(1.0)).is_finite());
        assert!(b.recip().is_err() && b.powi(2).is_err() && b.div(huge).is_err());
        assert!(!b.hull(huge).is_finite());
        assert!(Tm::from_interval(b, 2).checked().is_err());
    }
    // overflow: an error, not a bound
    assert!(!(huge + huge).is_finite());
    assert!(!(huge * huge).is_finite());
    assert_eq!(huge.exp(), Err(DomainError::NotFinite));
    assert_eq!(huge.powi(2), Err(DomainError::NotFinite));
    let t = Tm::from_interval(huge, 1);
    assert!(t.mul(&t).is_err() && t.add(&t).is_err() && t.exp().is_err());
    assert_eq!(support(&[10.0], &[t]), f64::INFINITY);
}

/// A random Taylor model over `n` symbols and a random point of it
/// (`z` and a remainder value).
fn random_tm(g: &mut Rng, n: usize, scale: f64) -> Tm {
    let c = g.uniform(-scale, scale);
    let gv = (0..n).map(|_| g.uniform(-0.3, 0.3) * scale).collect();
    let r = g.uniform(0.0, 0.05 * scale);
    let off = g.uniform(-r, r);
    Tm {
        c,
        g: gv,
        r: Interval::new(off - r, off + r),
    }
}

/// The value of `t` at symbols `z` and remainder fraction `s ∈ [0, 1]`.
fn value(t: &Tm, z: &[f64], s: f64) -> f64 {
    t.c + t.g.iter().zip(z).map(|(g, z)| g * z).sum::<f64>() + t.r.lo + s * (t.r.hi - t.r.lo)
}

/// Whether the value `v` is in `t` at `z` (plain `f64` with a relative
/// slack of a few ulps of the terms for the evaluation of the check).
fn holds(t: &Tm, z: &[f64], v: f64) -> bool {
    let iv = t.eval_at(z);
    let mag = t.c.abs() + t.g.iter().map(|g| g.abs()).sum::<f64>() + t.r.mag() + v.abs();
    let slack = 8.0 * f64::EPSILON * mag;
    iv.lo - slack <= v && v <= iv.hi + slack
}

#[test]
fn taylor_models_enclose_their_functions_at_random_points() {
    let mut g = Rng::new(3);
    let n = 3;
    for round in 0..3_000 {
        let scale = [0.1, 1.0, 4.0][round % 3];
        let (a, b) = (random_tm(&mut g, n, scale), random_tm(&mut g, n, scale));
        for _ in 0..5 {
            let z: Vec<f64> = (0..n).map(|_| g.uniform(-1.0, 1.0)).collect();
            let (sa, sb) = (g.unit(), g.unit());
            let (x, y) = (value(&a, &z, sa), value(&b, &z, sb));
            assert!(a.range().contains(x));
            assert!(holds(&a.add(&b).unwrap(), &z, x + y));
            assert!(holds(&a.sub(&b).unwrap(), &z, x - y));
            assert!(holds(&a.mul(&b).unwrap(), &z, x * y));
            assert!(holds(&a.scale(-1.7).unwrap(), &z, -1.7 * x));
            assert!(holds(
                &a.mul_interval(Interval::new(0.5, 0.7)).unwrap(),
                &z,
                0.5 * x
            ));
            if let Ok(q) = a.div(&b) {
                assert!(holds(&q, &z, x / y));
            }
            for p in [-2, 2, 3, 5] {
                if let Ok(t) = a.powi(p) {
                    assert!(holds(&t, &z, x.powi(p)), "{a:?}^{p}");
                }
            }
            for f in Func::ALL {
                if let Ok(t) = a.apply(f) {
                    assert!(holds(&t, &z, f.apply(x)), "{}({a:?}) at {z:?}", f.name());
                }
            }
            let comb = combine(&[2.0, -0.5], &[&a, &b], 0.25).unwrap();
            assert!(holds(&comb, &z, 2.0 * x - 0.5 * y + 0.25));
            assert!(support(&[2.0, -0.5], &[a.clone(), b.clone()]) >= 2.0 * x - 0.5 * y);
        }
    }
}

#[test]
fn a_symbol_keeps_its_dependency() {
    let x = Tm::symbol(0, 1.0, 0.1, 2);
    let d = x.sub(&x).unwrap();
    assert!(d.range().mag() < 1e-15);
    let sq = x.mul(&x).unwrap();
    // (1 + 0.1 z)² = 1 + 0.2 z + 0.01 z²: remainder within [0, 0.01]
    assert!((sq.g[0] - 0.2).abs() < 1e-15);
    assert!(sq.r.lo >= -1e-15 && sq.r.hi <= 0.01 + 1e-15);
    assert!(x.log().unwrap().range().width() < 0.21);
    assert_eq!(
        Tm::symbol(0, 1.0, 0.1, 1).powi(0).unwrap(),
        Tm::constant(1.0, 1)
    );
    assert!(Tm::symbol(0, 0.0, 1.0, 1).log().is_err());
    assert!(Tm::symbol(0, 0.0, 1.0, 1).recip().is_err());
    assert!(Tm::symbol(0, 0.0, 1.0, 1)
        .abs()
        .unwrap()
        .range()
        .contains(1.0));
    assert!(Tm::symbol(5, 0.0, 1.0, 1).range().contains(-1.0));
}

/// `a + b = s + e` exactly (Knuth's two-sum).
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

/// `a·b = p + e` exactly (no underflow in the tests' magnitudes).
fn two_prod(a: f64, b: f64) -> (f64, f64) {
    let p = a * b;
    (p, a.mul_add(b, -p))
}

/// A coefficient with a random mantissa, sign and magnitude `10^±12`, so
/// that nearly every product and sum of two rounds.
fn nasty(g: &mut Rng) -> f64 {
    let m = g.uniform(1.0, 2.0);
    let e = g.uniform(-12.0, 12.0);
    let s = if g.below(2) == 0 { -1.0 } else { 1.0 };
    s * m * 10f64.powf(e)
}

fn nasty_vec(g: &mut Rng, n: usize) -> Vec<f64> {
    (0..n).map(|_| nasty(g)).collect()
}

/// `Σ |gᵢ − ĝᵢ|` for coefficients `g` and the exact values `ĝᵢ = hᵢ + lᵢ`
/// (double-double; the error is evaluated in `f64`, relative error `u`
/// of itself, far inside the bounds' factors).
fn summed_error(g: &[f64], exact: &[(f64, f64)]) -> f64 {
    g.iter()
        .zip(exact)
        .map(|(&v, &(h, l))| ((h - v) + l).abs())
        .sum()
}

/// The exact dot product `Σ cⱼ·xⱼ` as a double-double.
fn exact_dot(c: &[f64], x: &[f64]) -> (f64, f64) {
    let (mut hi, mut lo) = (0.0, 0.0);
    for (&a, &b) in c.iter().zip(x) {
        let (p, pe) = two_prod(a, b);
        let (s, se) = two_sum(hi, p);
        hi = s;
        lo += se + pe;
    }
    (hi, lo)
}

/// Every constructor of [`Lin`] bounds the summed rounding errors of its
/// coefficients against their exact values (computed with error-free
/// transformations), and the errors are real: a bound of 0 (no
/// accounting) fails here.
#[test]
fn symbol_coefficients_bound_their_exact_rounding_errors() {
    let mut g = Rng::new(29);
    let mut seen = 0.0;
    for round in 0..2_000 {
        let n = 1 + round % 40;
        let (a, b) = (nasty_vec(&mut g, n), nasty_vec(&mut g, n));
        let (p, q, d) = (nasty(&mut g), nasty(&mut g), nasty(&mut g));
        let mut check = |lin: &Lin, exact: Vec<(f64, f64)>, what: &str| {
            let e = summed_error(&lin.g, &exact);
            assert!(e <= lin.err, "{what}: errors {e:e} > bound {:e}", lin.err);
            seen += e;
        };
        for neg in [false, true] {
            let s = if neg { -1.0 } else { 1.0 };
            let exact = a.iter().zip(&b).map(|(&x, &y)| two_sum(x, s * y)).collect();
            check(&Lin::add(&a, &b, neg), exact, "add");
        }
        // a shorter operand: its missing coefficients are zero
        let short = &b[..n / 2];
        let exact = (0..n)
            .map(|i| two_sum(a[i], short.get(i).copied().unwrap_or(0.0)))
            .collect();
        check(&Lin::add(&a, short, false), exact, "add, ragged");
        let exact = a.iter().map(|&x| two_prod(p, x)).collect();
        check(&Lin::scale(&a, p), exact, "scale");
        // a/d = q + r/d with r = a − q·d exact
        let lin = Lin::div(&a, d);
        let exact = a
            .iter()
            .zip(&lin.g)
            .map(|(&x, &v)| (v, (-v).mul_add(d, x) / d))
            .collect();
        check(&lin, exact, "div");
        // a product's linear part `p·bᵢ + q·aᵢ`, and with a shorter `b`
        let tm = |c: f64, g: &[f64]| Tm {
            c,
            g: g.to_vec(),
            r: Interval::ZERO,
        };
        for m in [n, n / 2] {
            let exact = (0..n)
                .map(|i| exact_dot(&[p, q], &[b[..m].get(i).copied().unwrap_or(0.0), a[i]]))
                .collect();
            let both = product_pass(&tm(p, &a), &tm(q, &b[..m]));
            check(&both.lin, exact, "product");
        }
        let k = 1 + round % 7;
        let tms: Vec<Tm> = (0..k)
            .map(|_| Tm {
                c: 0.0,
                g: nasty_vec(&mut g, n),
                r: Interval::ZERO,
            })
            .collect();
        let refs: Vec<&Tm> = tms.iter().collect();
        let cs = nasty_vec(&mut g, k);
        let exact = (0..n)
            .map(|i| {
                let col: Vec<f64> = tms.iter().map(|t| t.g[i]).collect();
                exact_dot(&cs, &col)
            })
            .collect();
        check(&Lin::dot(&cs, &refs, n), exact, "dot");
    }
    assert!(
        seen > 0.0,
        "no rounding happened: the test would not see a missing bound"
    );
}

/// A model whose remainder is 0 and whose coefficients were rounded:
/// the result's remainder holds every value of the rounding error
/// `(ĉ − c) + Σ (ĝᵢ − gᵢ) zᵢ` over the cube, for each operation whose exact
/// result is affine (no quadratic part).
#[test]
fn taylor_model_operations_keep_their_rounding_in_the_remainder() {
    let mut g = Rng::new(31);
    let exact_tm = |c: (f64, f64), gs: Vec<(f64, f64)>, t: &Tm| {
        let e_c = (c.0 - t.c) + c.1;
        let e = summed_error(&t.g, &gs);
        assert!(
            t.r.lo <= e_c - e && e_c + e <= t.r.hi,
            "remainder {:?} misses [{:e}, {:e}]",
            t.r,
            e_c - e,
            e_c + e
        );
        e
    };
    let mut seen = 0.0;
    for round in 0..1_000 {
        let n = 1 + round % 30;
        let tm = |g: &mut Rng| Tm {
            c: nasty(g),
            g: nasty_vec(g, n),
            r: Interval::ZERO,
        };
        let (a, b, s) = (tm(&mut g), tm(&mut g), nasty(&mut g));
        let sum = a.add(&b).unwrap();
        let gs = a.g.iter().zip(&b.g).map(|(&x, &y)| two_sum(x, y)).collect();
        seen += exact_tm(two_sum(a.c, b.c), gs, &sum);
        let diff = a.sub(&b).unwrap();
        let gs =
            a.g.iter()
                .zip(&b.g)
                .map(|(&x, &y)| two_sum(x, -y))
                .collect();
        seen += exact_tm(two_sum(a.c, -b.c), gs, &diff);
        let scaled = a.scale(s).unwrap();
        let gs = a.g.iter().map(|&x| two_prod(s, x)).collect();
        seen += exact_tm(two_prod(s, a.c), gs, &scaled);
        let by_point = a.mul_interval(Interval::point(s)).unwrap();
        let gs = a.g.iter().map(|&x| two_prod(s, x)).collect();
        seen += exact_tm(two_prod(s, a.c), gs, &by_point);
        // times a constant model: the quadratic part is 0
        let k = Tm::constant(s, n);
        let prod = a.mul(&k).unwrap();
        let gs = a.g.iter().map(|&x| two_prod(s, x)).collect();
        seen += exact_tm(two_prod(s, a.c), gs, &prod);
        let quot = a.div_scalar(s).unwrap();
        let gs =
            a.g.iter()
                .zip(&quot.g)
                .map(|(&x, &v)| (v, (-v).mul_add(s, x) / s))
                .collect();
        let qc = a.c / s;
        seen += exact_tm((qc, (-qc).mul_add(s, a.c) / s), gs, &quot);
        let comb = combine(&[s, 0.5], &[&a, &b], 0.0).unwrap();
        let gs =
            a.g.iter()
                .zip(&b.g)
                .map(|(&x, &y)| exact_dot(&[s, 0.5], &[x, y]))
                .collect();
        seen += exact_tm(exact_dot(&[s, 0.5], &[a.c, b.c]), gs, &comb);
    }
    assert!(seen > 0.0);
}

/// The product's one pass agrees with the separate sums it replaces
/// (the same terms in another order: equal to a relative 10⁻¹²), on
/// models of different lengths too, and its product encloses the values.
#[test]
fn the_product_pass_agrees_with_the_separate_sums() {
    let mut g = Rng::new(37);
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-12 * (x.abs() + y.abs()) + 1e-300;
    for round in 0..2_000 {
        let (n, m) = (round % 23, (round / 23) % 17);
        let scale = [0.1, 1.0, 4.0][round % 3];
        let a = random_tm(&mut g, n, scale);
        let b = random_tm(&mut g, m, scale);
        let p = product_pass(&a, &b);
        let q = quadratic(&a, &b);
        // the ends to a relative 10⁻¹² of the enclosure's magnitude (an
        // end near 0 differs by the error terms, which differ in order)
        let near = |x: f64, y: f64| (x - y).abs() <= 1e-12 * q.mag() + 1e-300;
        assert!(
            near(p.quadratic.lo, q.lo) && near(p.quadratic.hi, q.hi),
            "{:?} against {q:?}",
            p.quadratic
        );
        assert!(close(p.radius_a, a.linear_radius()) && close(p.radius_b, b.linear_radius()));
        assert_eq!(p.lin.g.len(), n.max(m));
        for (i, &v) in p.lin.g.iter().enumerate() {
            let (x, y) = (
                a.g.get(i).copied().unwrap_or(0.0),
                b.g.get(i).copied().unwrap_or(0.0),
            );
            assert_eq!(v, a.c * y + b.c * x);
        }
        let prod = a.mul(&b).unwrap();
        for _ in 0..3 {
            let z: Vec<f64> = (0..n.max(m)).map(|_| g.uniform(-1.0, 1.0)).collect();
            let (sa, sb) = (g.unit(), g.unit());
            let (x, y) = (value(&a, &z, sa), value(&b, &z, sb));
            assert!(holds(&prod, &z, x * y), "{a:?} · {b:?} at {z:?}");
        }
    }
}

/// Coefficients whose magnitudes overflow when summed: the linear radius
/// is infinite, and the product's enclosure is refused (a NaN cross term
/// once became 0 through `max`, dropping the cross terms).
#[test]
fn an_overflowing_radius_refuses_the_product() {
    let a = Tm {
        c: 0.0,
        g: vec![1e308, 1e308],
        r: Interval::ZERO,
    };
    let b = Tm {
        c: 0.0,
        g: vec![0.0, 1e-300],
        r: Interval::ZERO,
    };
    let q = quadratic(&a, &b);
    assert!(q.lo.is_nan() && q.hi.is_nan(), "{q:?}");
    assert!(!product_pass(&a, &b).quadratic.is_finite());
    assert!(a.mul(&b).is_err());
}
