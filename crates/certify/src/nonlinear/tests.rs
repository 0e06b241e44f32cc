//! The checker's own arithmetic against sampled points: every result of an
//! affine-form operation contains the operation applied to points of its
//! operands (same symbol values), every flow encloses an accurate
//! simulation, and a flow without its remainder fails these checks.

use super::arith::{Af, Iv, Num};
use super::flow::{period, Field};
use ravel_base::expr::Func;
use ravel_base::rng::Rng;
use serde_json::json;

/// A random form over `k` symbols with a random error interval.
fn form(rng: &mut Rng, k: usize, scale: f64) -> Af {
    let lo = -rng.uniform(0.0, 0.01 * scale);
    Af {
        c: rng.uniform(-scale, scale),
        g: (0..k).map(|_| rng.uniform(-0.1, 0.1) * scale).collect(),
        lo,
        hi: rng.uniform(0.0, 0.01 * scale),
    }
}

/// The form's value at the symbols `s` with error `e ∈ [0, 1]` of the way.
fn at(f: &Af, s: &[f64], e: f64) -> f64 {
    f.c + f.g.iter().zip(s).map(|(g, s)| g * s).sum::<f64>() + f.lo + e * (f.hi - f.lo)
}

/// Whether `v` is within the result form at `s` (any error in its interval),
/// up to the float evaluation's own rounding.
fn holds(r: &Af, s: &[f64], v: f64) -> bool {
    let base = r.c + r.g.iter().zip(s).map(|(g, s)| g * s).sum::<f64>();
    let slack = 1e-12 * (1.0 + v.abs() + base.abs());
    base + r.lo - slack <= v && v <= base + r.hi + slack
}

#[test]
fn affine_operations_contain_their_points() {
    let mut rng = Rng::new(7);
    let k = 4;
    for _ in 0..300 {
        let a = form(&mut rng, k, 1.0);
        let b = form(&mut rng, k, 1.0);
        let pos = Af {
            c: rng.uniform(0.5, 2.0),
            ..form(&mut rng, k, 1.0)
        };
        for _ in 0..30 {
            let s: Vec<f64> = (0..k).map(|_| rng.uniform(-1.0, 1.0)).collect();
            let (ea, eb, ep) = (rng.unit(), rng.unit(), rng.unit());
            let (x, y, p) = (at(&a, &s, ea), at(&b, &s, eb), at(&pos, &s, ep));
            assert!(holds(&a.add(&b), &s, x + y));
            assert!(holds(&a.sub(&b), &s, x - y));
            assert!(holds(&a.mul(&b), &s, x * y));
            assert!(holds(&a.mul(&a), &s, x * x));
            assert!(holds(&a.scale(-2.5), &s, -2.5 * x));
            assert!(holds(&a.div_int(3), &s, x / 3.0));
            assert!(holds(&pos.recip().expect("positive"), &s, 1.0 / p));
            for g in [Func::Sin, Func::Cos, Func::Exp, Func::Tanh, Func::Abs] {
                let r = a.elem(g).expect("defined everywhere");
                let v = match g {
                    Func::Sin => x.sin(),
                    Func::Cos => x.cos(),
                    Func::Exp => x.exp(),
                    Func::Tanh => x.tanh(),
                    _ => x.abs(),
                };
                assert!(holds(&r, &s, v), "{g:?}");
            }
            for g in [Func::Log, Func::Sqrt] {
                let r = pos.elem(g).expect("positive");
                let v = if g == Func::Log { p.ln() } else { p.sqrt() };
                assert!(holds(&r, &s, v), "{g:?}");
            }
        }
    }
}

#[test]
fn domains_are_failures_not_bounds() {
    let around_zero = Af {
        c: 0.0,
        g: vec![0.5],
        lo: 0.0,
        hi: 0.0,
    };
    assert!(around_zero.recip().is_err());
    assert!(around_zero.elem(Func::Log).is_err());
    assert!(around_zero.elem(Func::Sqrt).is_err());
    assert!(Iv::new(1.0, 2.0).elem(Func::Tan).is_err());
    assert!(Iv::new(-0.5, 0.5).elem(Func::Tan).is_ok());
    // sin and cos over their extrema reach ±1
    let s = Iv::new(1.0, 2.0).elem(Func::Sin).expect("sin");
    assert!(s.hi >= 1.0 && s.lo <= 1.0f64.sin());
    let c = Iv::new(3.0, 3.3).elem(Func::Cos).expect("cos");
    assert!(c.lo <= -1.0);
}

/// `ẋ₀ = x₁, ẋ₁ = −sin x₀ − 0.1 x₁ + u₀` (a damped pendulum), period 0.5.
fn pendulum() -> Field {
    let p = json!({
        "tape": [
            ["var", 0], ["var", 1], ["var", 2],
            ["sin", 0], ["neg", 3], ["const", 0.1], ["mul", 5, 1],
            ["sub", 4, 6], ["add", 7, 2], ["powi", 0, 2]
        ],
        "outputs": [1, 8],
        "time": { "continuous": 0.5 }
    });
    Field::read(&p, 2, 1, 0).expect("a valid tape")
}

/// RK4 with many steps (far more accurate than the bounds' widths).
fn simulate(x: [f64; 2], u: f64, t: f64) -> [f64; 2] {
    let f = |x: [f64; 2]| [x[1], -x[0].sin() - 0.1 * x[1] + u];
    let n = 2000;
    let h = t / f64::from(n);
    let mut x = x;
    for _ in 0..n {
        let k1 = f(x);
        let k2 = f([x[0] + 0.5 * h * k1[0], x[1] + 0.5 * h * k1[1]]);
        let k3 = f([x[0] + 0.5 * h * k2[0], x[1] + 0.5 * h * k2[1]]);
        let k4 = f([x[0] + h * k3[0], x[1] + h * k3[1]]);
        for i in 0..2 {
            x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
    }
    x
}

#[test]
fn the_flow_encloses_simulations_and_is_wrong_without_its_remainder() {
    let f = pendulum();
    // x₀ = 0.5 + 0.05 s₀, x₁ = −0.2 + 0.05 s₁, u = 0.3
    let x = vec![
        Af::exact(0.5, vec![0.05, 0.0]),
        Af::exact(-0.2, vec![0.0, 0.05]),
    ];
    let u = vec![Af::constant(0.3, 2)];
    let out = period(&f, &x, &u, &[], 8).expect("an enclosure");
    let between = out.between.expect("continuous time");
    let mut rng = Rng::new(3);
    let mut worst = 0.0f64;
    for _ in 0..200 {
        let s = [rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)];
        let x0 = [0.5 + 0.05 * s[0], -0.2 + 0.05 * s[1]];
        let end = simulate(x0, 0.3, 0.5);
        for i in 0..2 {
            assert!(holds(&out.end[i], &s, end[i]), "component {i}");
            let base = out.end[i].c + out.end[i].g.iter().zip(&s).map(|(g, s)| g * s).sum::<f64>();
            worst = worst.max((end[i] - base).abs());
        }
        // 32 instants of the period, each in the piece (an eighth) of its
        // time, and at a piece's end in the next one too
        assert_eq!(between.len(), 8);
        for k in 1..=32usize {
            let mid = simulate(x0, 0.3, 0.5 * k as f64 / 32.0);
            for piece in (k - 1) / 4..=(k / 4).min(7) {
                for i in 0..2 {
                    let b = &between[piece][i];
                    assert!(
                        b.lo <= mid[i] && mid[i] <= b.hi,
                        "instant {k}/32, piece {piece}"
                    );
                }
            }
        }
    }
    // the error interval matters: without it some simulation falls outside
    let mut shrunk = out.end.clone();
    let mut caught = false;
    for f in &mut shrunk {
        f.lo = 0.0;
        f.hi = 0.0;
    }
    let mut rng = Rng::new(5);
    for _ in 0..4000 {
        let s = [rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)];
        let s = s.map(|v| if v.abs() > 0.9 { v.signum() } else { v });
        let end = simulate([0.5 + 0.05 * s[0], -0.2 + 0.05 * s[1]], 0.3, 0.5);
        if (0..2).any(|i| !holds(&shrunk[i], &s, end[i])) {
            caught = true;
            break;
        }
    }
    assert!(worst > 0.0);
    assert!(caught, "a flow without its remainder is not caught");
}

#[test]
fn powers_are_products() {
    let p = json!({
        "tape": [["var", 0], ["powi", 0, 3], ["powi", 0, -2], ["add", 1, 2]],
        "outputs": [3],
        "time": "discrete"
    });
    let g = Field::read(&p, 1, 0, 0).expect("valid");
    let x = vec![Iv::new(2.0, 2.0)];
    let v = g.eval(&x, &[], &[]).expect("defined");
    assert!(v[0].lo <= 8.25 && 8.25 <= v[0].hi && v[0].hi - v[0].lo < 1e-12);
    // bad tapes are refused
    for bad in [
        json!({"tape": [["var", 5]], "outputs": [0], "time": "discrete"}),
        json!({"tape": [["add", 0, 0]], "outputs": [0], "time": "discrete"}),
        json!({"tape": [["var", 0], ["powi", 0, 100000]], "outputs": [1], "time": "discrete"}),
        json!({"tape": [["const", 1.0]], "outputs": [0], "time": {"continuous": -1.0}}),
        json!({"tape": [["nope", 0]], "outputs": [0], "time": "discrete"}),
    ] {
        assert!(Field::read(&bad, 1, 0, 0).is_err(), "{bad}");
    }
}
