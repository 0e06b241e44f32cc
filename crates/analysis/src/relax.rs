//! Sound linear relaxations of activation functions on an interval.
//!
//! For a neuron with pre-activation `z ∈ [l, u]` a relaxation is a pair of
//! lines `αᴸ z + βᴸ ≤ σ(z) ≤ αᵁ z + βᵁ`. The slopes are chosen by the usual
//! CROWN heuristics; the intercepts are then computed as certified bounds of
//! `sup/inf (σ(z) − α z)` over the interval, so the relaxation is valid for any
//! slope the heuristics pick, including slopes that carry rounding error.

use ravel_base::nn::{sigmoid, Activation};
use ravel_base::num::{gap_lower, gap_upper, sum_lower, sum_upper, U};

/// A linear relaxation of one neuron.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Relax {
    /// Lower slope.
    pub al: f64,
    /// Lower intercept.
    pub bl: f64,
    /// Upper slope.
    pub au: f64,
    /// Upper intercept.
    pub bu: f64,
}

/// The relaxation of `act` on `[l, u]`.
pub fn relax(act: Activation, l: f64, u: f64) -> Relax {
    match act {
        Activation::Relu => relax_relu(l, u),
        Activation::Tanh | Activation::Sigmoid => relax_smooth(act, l, u),
    }
}

/// [`relax`], with Fast-Lin's lower ReLU slope (equal to the upper one)
/// when `fast_lin` (the caller's: Fast-Lin mode and a ReLU).
#[inline]
pub(crate) fn relax_in_mode(act: Activation, l: f64, u: f64, fast_lin: bool) -> Relax {
    let r = relax(act, l, u);
    if fast_lin {
        // a·z ≤ relu(z) for every z when 0 ≤ a ≤ 1
        Relax {
            al: r.au,
            bl: 0.0,
            ..r
        }
    } else {
        r
    }
}

/// Interval image of `[l, u]` under a monotone activation, rounded outward.
pub fn image(act: Activation, l: f64, u: f64) -> (f64, f64) {
    match act {
        Activation::Relu => (l.max(0.0), u.max(0.0)),
        Activation::Tanh | Activation::Sigmoid => {
            let (fl, fu) = (act.eval(l), act.eval(u));
            let (min, max) = range(act);
            let lo = (fl - act.eval_error(fl)).next_down().max(min);
            let hi = (fu + act.eval_error(fu)).next_up().min(max);
            (lo, hi)
        }
    }
}

fn range(act: Activation) -> (f64, f64) {
    match act {
        Activation::Relu => (0.0, f64::INFINITY),
        Activation::Tanh => (-1.0, 1.0),
        Activation::Sigmoid => (0.0, 1.0),
    }
}

fn relax_relu(l: f64, u: f64) -> Relax {
    if u <= 0.0 {
        Relax {
            al: 0.0,
            bl: 0.0,
            au: 0.0,
            bu: 0.0,
        }
    } else if l >= 0.0 {
        Relax {
            al: 1.0,
            bl: 0.0,
            au: 1.0,
            bu: 0.0,
        }
    } else {
        // Upper: the chord through (l, 0) and (u, u). relu(z) − αz is convex, so its
        // supremum over [l, u] is at an endpoint, whatever rounding α carries.
        let a = u / (u - l);
        let a = if a.is_finite() {
            clamp_safe(a, 0.0, 1.0)
        } else {
            0.0
        };
        let bu = gap_upper(0.0, 0.0, a, l).max(gap_upper(u, 0.0, a, u));
        // Lower: the adaptive choice of CROWN (slope 1 if the positive side is larger).
        let al = if u >= -l { 1.0 } else { 0.0 };
        Relax {
            al,
            bl: 0.0,
            au: a,
            bu,
        }
    }
}

/// Derivative of a smooth activation and a bound on its evaluation error.
fn deriv(act: Activation, z: f64) -> (f64, f64) {
    match act {
        Activation::Tanh => {
            let t = z.tanh();
            (1.0 - t * t, 64.0 * U)
        }
        _ => {
            let s = sigmoid(z);
            (s * (1.0 - s), 64.0 * U)
        }
    }
}

/// The non-negative point where the derivative equals `a` (0 if `a` exceeds the peak
/// derivative, +∞ if `a ≤ 0`). Only an approximation: the bounds below are valid for
/// any point, and merely tightest near the true one.
fn stationary(act: Activation, a: f64) -> f64 {
    let peak = match act {
        Activation::Tanh => 1.0,
        _ => 0.25,
    };
    if a >= peak {
        return 0.0;
    }
    if a <= 0.0 {
        return f64::INFINITY;
    }
    let z = match act {
        Activation::Tanh => (1.0 - a).sqrt().atanh(),
        _ => {
            let s = 0.5 * (1.0 + (1.0 - 4.0 * a).sqrt());
            (s / (1.0 - s)).ln()
        }
    };
    if z.is_finite() {
        z
    } else {
        f64::INFINITY
    }
}

fn value(act: Activation, z: f64) -> (f64, f64) {
    let f = act.eval(z);
    (f, act.eval_error(f))
}

/// Certified upper bound of the tangent-line term `g'(s)·e` for `g(z) = σ(z) − a z`,
/// maximised over the two offsets `e` to the ends of a piece.
fn tangent_term(act: Activation, a: f64, s: f64, offsets: [f64; 2], upper: bool) -> f64 {
    let (ds, ds_err) = deriv(act, s);
    let d = ds - a;
    let d_err = ds_err + 2.0 * U * (ds.abs() + a.abs());
    let terms = offsets.map(|e| {
        let slack = d_err * e.abs() + 4.0 * U * e.abs() * (d.abs() + d_err);
        if upper {
            sum_upper([d * e, slack])
        } else {
            sum_lower([d * e, -slack])
        }
    });
    if upper {
        terms[0].max(terms[1])
    } else {
        terms[0].min(terms[1])
    }
}

/// Certified upper bound of `sup_{z∈[l,u]} σ(z) − a z` for tanh or sigmoid
/// (convex on z ≤ 0, concave on z ≥ 0).
fn sup_gap(act: Activation, a: f64, l: f64, u: f64) -> f64 {
    let mut best = f64::NEG_INFINITY;
    if l < 0.0 || u <= 0.0 {
        // convex piece: maximum at an end
        let q = u.min(0.0);
        for z in [l, q] {
            let (f, e) = value(act, z);
            best = best.max(gap_upper(f, e, a, z));
        }
    }
    if u > 0.0 {
        // concave piece: g(z) ≤ g(s) + g'(s)(z − s) for every s in the piece
        let p = l.max(0.0);
        let s = clamp_safe(stationary(act, a), p, u);
        let (f, e) = value(act, s);
        let g = gap_upper(f, e, a, s);
        let t = tangent_term(act, a, s, [p - s, u - s], true);
        best = best.max(sum_upper([g, t]));
    }
    best
}

/// Certified lower bound of `inf_{z∈[l,u]} σ(z) − a z`.
fn inf_gap(act: Activation, a: f64, l: f64, u: f64) -> f64 {
    let mut best = f64::INFINITY;
    if u > 0.0 || l >= 0.0 {
        // concave piece: minimum at an end
        let p = l.max(0.0);
        for z in [p, u] {
            let (f, e) = value(act, z);
            best = best.min(gap_lower(f, e, a, z));
        }
    }
    if l < 0.0 {
        // convex piece: g(z) ≥ g(s) + g'(s)(z − s)
        let q = u.min(0.0);
        let s = clamp_safe(-stationary(act, a), l, q);
        let (f, e) = value(act, s);
        let g = gap_lower(f, e, a, s);
        let t = tangent_term(act, a, s, [l - s, q - s], false);
        best = best.min(sum_lower([g, t]));
    }
    best
}

fn relax_smooth(act: Activation, l: f64, u: f64) -> Relax {
    let (min, max) = range(act);
    if !(l.is_finite() && u.is_finite()) {
        return Relax {
            al: 0.0,
            bl: min,
            au: 0.0,
            bu: max,
        };
    }
    let (fl, _) = value(act, l);
    let (fu, _) = value(act, u);
    let chord = {
        let c = (fu - fl) / (u - l);
        if c.is_finite() {
            c.max(0.0)
        } else {
            0.0
        }
    };
    let m = 0.5 * (l + u);
    let tangent = deriv(act, m).0.max(0.0);
    let (au, al) = if l >= 0.0 {
        (tangent, chord) // concave
    } else if u <= 0.0 {
        (chord, tangent) // convex
    } else {
        (chord, chord) // mixed: parallel chords
    };
    let bu = sup_gap(act, au, l, u);
    let bl = inf_gap(act, al, l, u);
    Relax { al, bl, au, bu }
}

/// `x` clamped to `[lo, hi]` without `f64::clamp`'s panic on NaN ends or
/// `lo > hi` (possible only for bounds that overflowed, which the callers
/// of the propagators detect and refuse to use).
fn clamp_safe(x: f64, lo: f64, hi: f64) -> f64 {
    if x < lo {
        lo
    } else if x > hi {
        hi
    } else {
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Dense check of the relaxation on many intervals: the lines must enclose the
    /// function at every grid point (evaluated in f64 with a small tolerance for the
    /// evaluation of the activation itself).
    #[test]
    fn relaxations_enclose_the_function() {
        let acts = [Activation::Relu, Activation::Tanh, Activation::Sigmoid];
        let ends = [-8.0, -3.0, -1.0, -0.3, -1e-3, 0.0, 1e-3, 0.2, 1.0, 2.5, 9.0];
        for act in acts {
            for &l in &ends {
                for &u in &ends {
                    if u < l {
                        continue;
                    }
                    let r = relax(act, l, u);
                    for k in 0..=400 {
                        let z = l + (u - l) * (k as f64 / 400.0);
                        let f = act.eval(z);
                        let tol = 1e-14;
                        assert!(
                            r.al * z + r.bl <= f + tol,
                            "{act:?} lower at {z} on [{l},{u}]: {r:?}"
                        );
                        assert!(
                            r.au * z + r.bu >= f - tol,
                            "{act:?} upper at {z} on [{l},{u}]: {r:?}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn relaxations_are_reasonably_tight() {
        // On a small interval the two lines must be close to each other.
        for act in [Activation::Tanh, Activation::Sigmoid] {
            let r = relax(act, 0.1, 0.2);
            let gap = (r.au * 0.15 + r.bu) - (r.al * 0.15 + r.bl);
            assert!(gap < 1e-3, "{act:?} {gap}");
        }
        let r = relax(Activation::Relu, -1.0, 3.0);
        assert!((r.au - 0.75).abs() < 1e-15 && (r.bu - 0.75).abs() < 1e-12);
    }
}
