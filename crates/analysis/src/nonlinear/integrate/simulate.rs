//! Float simulation of `ẋ = f(x, u, w)` over one control period (no
//! rounding control: for falsification and tests, never for a bound).
//!
//! The classical fourth-order Runge–Kutta method with step doubling: each
//! step is taken once whole and once as two halves, their difference
//! estimates the local error (kept below `10⁻¹³·(1 + |x|)`), and the two
//! are combined by Richardson extrapolation (a fifth-order step). A NaN or
//! an infinity propagates to the result.

use ravel_base::expr::VectorField;

/// The local error tolerance, relative to `1 + |x|`.
const TOL: f64 = 1e-13;

/// The most steps one simulation of a period takes: a trajectory that
/// needs more (a stiff or blowing-up flow, a singularity on the way) is not
/// simulated at all (NaN), rather than simulated inaccurately or for
/// minutes.
const MAX_STEPS: usize = 1 << 16;

/// `x(period)` from `x` with `u` and `w` held constant, in `f64`. A field
/// that does not fit the vectors, a negative or non-finite period, or a
/// flow that needs more than [`MAX_STEPS`] steps or a step below
/// `10⁻¹²·period` gives NaN in every component.
pub fn simulate(field: &VectorField, x: &[f64], u: &[f64], w: &[f64], period: f64) -> Vec<f64> {
    let fits = field.states == x.len()
        && field.outputs.len() == x.len()
        && field.controls == u.len()
        && field.disturbances == w.len()
        && field.tape.is_well_formed(field.vars());
    if !(fits && period.is_finite() && period >= 0.0) {
        return vec![f64::NAN; x.len()];
    }
    let mut scratch = Vec::new();
    let mut f = |y: &[f64]| field.eval(y, u, w, &mut scratch);
    let mut y = x.to_vec();
    let (mut t, mut h, mut steps) = (0.0f64, period / 16.0, 0usize);
    while t < period {
        h = h.min(period - t);
        let whole = rk4(&mut f, &y, h);
        let half = rk4(&mut f, &y, 0.5 * h);
        let two = rk4(&mut f, &half, 0.5 * h);
        let err = whole
            .iter()
            .zip(&two)
            .map(|(a, b)| (a - b).abs() / (1.0 + b.abs()))
            .fold(0.0f64, |m, e| {
                if e.is_nan() || m.is_nan() {
                    f64::NAN
                } else {
                    m.max(e)
                }
            });
        if err.is_nan() {
            return two.iter().map(|_| f64::NAN).collect();
        }
        steps += 1;
        if h <= period * 1e-12 || steps >= MAX_STEPS {
            return vec![f64::NAN; x.len()];
        }
        if err <= TOL {
            y = two
                .iter()
                .zip(&whole)
                .map(|(b, a)| b + (b - a) / 15.0)
                .collect();
            t += h;
        }
        let factor = if err == 0.0 {
            2.0
        } else {
            0.9 * (TOL / err).powf(0.2)
        };
        h *= factor.clamp(0.2, 2.0);
    }
    y
}

/// One classical Runge–Kutta step.
fn rk4(f: &mut impl FnMut(&[f64]) -> Vec<f64>, y: &[f64], h: f64) -> Vec<f64> {
    let axpy =
        |a: f64, k: &[f64]| -> Vec<f64> { y.iter().zip(k).map(|(y, k)| y + a * k).collect() };
    let k1 = f(y);
    let k2 = f(&axpy(0.5 * h, &k1));
    let k3 = f(&axpy(0.5 * h, &k2));
    let k4 = f(&axpy(h, &k3));
    y.iter()
        .enumerate()
        .map(|(i, yi)| {
            let k = |v: &Vec<f64>| v.get(i).copied().unwrap_or(f64::NAN);
            yi + h / 6.0 * (k(&k1) + 2.0 * k(&k2) + 2.0 * k(&k3) + k(&k4))
        })
        .collect()
}
