//! Float simulation of `ẋ = f(x, u, w)` over one control period (no
//! rounding control: for falsification and tests, never for a bound).
//!
//! Gragg–Bulirsch–Stoer extrapolation: each step of length `h` is taken by
//! the modified midpoint rule with `2, 4, 6, …` substeps, whose error has
//! an expansion in even powers of the substep, and the results are
//! extrapolated to a zero substep (Aitken–Neville in `h²`). The difference
//! between the last two diagonal entries of the table estimates the error
//! of the less accurate one; a step is accepted when it is below
//! `10⁻¹³·(1 + |x|)`, with at least three rows (order 6 or more), and the
//! step length adapts to the row that converged. On the smooth plants of
//! the benchmarks a control period takes one to a few steps of a few dozen
//! right-hand side evaluations, where fourth-order Runge–Kutta with step
//! doubling took hundreds at the same tolerance. Nothing is allocated per
//! step. A NaN or an infinity propagates to the result.

use ravel_base::expr::VectorField;

/// The local error tolerance, relative to `1 + |x|`.
const TOL: f64 = 1e-13;

/// The most steps (accepted or refused) one simulation of a period takes:
/// a trajectory that needs more (a stiff or blowing-up flow, a singularity
/// on the way) is not simulated at all (NaN), rather than simulated
/// inaccurately or for minutes.
const MAX_STEPS: usize = 1 << 14;

/// The substep counts of the table's rows.
const SEQ: [usize; 8] = [2, 4, 6, 8, 10, 12, 14, 16];

/// The fewest rows a step is accepted with (the error estimate compares
/// the last two diagonal entries).
const MIN_ROWS: usize = 3;

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
    let mut s = Stepper::new(field, x, u, w);
    let (mut t, mut h, mut steps) = (0.0f64, period, 0usize);
    while t < period {
        // the last step ends exactly at the period (t + h could round one
        // ulp short of it and leave a step too small to take)
        let finishing = h >= period - t;
        h = h.min(period - t);
        steps += 1;
        if h <= period * 1e-12 || steps > MAX_STEPS {
            return vec![f64::NAN; x.len()];
        }
        match s.step(h) {
            Outcome::NotFinite => return vec![f64::NAN; x.len()],
            Outcome::Accepted(rows) => {
                t = if finishing { period } else { t + h };
                h *= match rows {
                    0..=3 => 2.0,
                    4..=5 => 1.3,
                    _ => 0.9,
                };
            }
            Outcome::Refused => h *= 0.3,
        }
    }
    s.y
}

/// What one extrapolation step did.
enum Outcome {
    /// The step was taken; the rows it used.
    Accepted(usize),
    /// The table did not converge: the step must be shorter.
    Refused,
    /// A value was NaN or infinite.
    NotFinite,
}

/// The state and the scratch of one simulation.
struct Stepper<'a> {
    field: &'a VectorField,
    n: usize,
    /// The state.
    y: Vec<f64>,
    /// `(x, u, w)`, the tape's variables.
    vars: Vec<f64>,
    /// The tape's node values.
    values: Vec<f64>,
    /// `f(y)` at the step's start.
    f0: Vec<f64>,
    /// The midpoint rule's two last states and a derivative.
    z0: Vec<f64>,
    z1: Vec<f64>,
    dz: Vec<f64>,
    /// The extrapolation table's current row, `SEQ.len()` entries of `n`.
    table: Vec<f64>,
    /// The previous row's entries, each saved before it is overwritten.
    prev: Vec<f64>,
}

impl<'a> Stepper<'a> {
    fn new(field: &'a VectorField, x: &[f64], u: &[f64], w: &[f64]) -> Stepper<'a> {
        let n = x.len();
        Stepper {
            field,
            n,
            y: x.to_vec(),
            vars: x.iter().chain(u).chain(w).copied().collect(),
            values: Vec::with_capacity(field.tape.nodes.len()),
            f0: vec![0.0; n],
            z0: vec![0.0; n],
            z1: vec![0.0; n],
            dz: vec![0.0; n],
            table: vec![0.0; n * SEQ.len()],
            prev: vec![0.0; n],
        }
    }

    /// `out = f(z)`.
    fn eval(
        field: &VectorField,
        vars: &mut [f64],
        values: &mut Vec<f64>,
        z: &[f64],
        out: &mut [f64],
    ) {
        for (v, x) in vars.iter_mut().zip(z) {
            *v = *x;
        }
        field.tape.eval_into(vars, values);
        for (o, &id) in out.iter_mut().zip(&field.outputs) {
            *o = values.get(id as usize).copied().unwrap_or(f64::NAN);
        }
    }

    /// One step of length `h` from `y`; on acceptance `y` moves to its end.
    fn step(&mut self, h: f64) -> Outcome {
        let n = self.n;
        Self::eval(
            self.field,
            &mut self.vars,
            &mut self.values,
            &self.y,
            &mut self.f0,
        );
        for (j, &m) in SEQ.iter().enumerate() {
            // the modified midpoint rule with m substeps
            let hs = h / m as f64;
            for i in 0..n {
                self.z0[i] = self.y[i];
                self.z1[i] = self.y[i] + hs * self.f0[i];
            }
            // f at z1 after each substep; the last one is for the smoothing
            for step in 1..=m {
                Self::eval(
                    self.field,
                    &mut self.vars,
                    &mut self.values,
                    &self.z1,
                    &mut self.dz,
                );
                if step == m {
                    break;
                }
                for i in 0..n {
                    let next = self.z0[i] + 2.0 * hs * self.dz[i];
                    self.z0[i] = self.z1[i];
                    self.z1[i] = next;
                }
            }
            // row j of the table, in place: entry k from entries k − 1 of
            // rows j and j − 1 (the previous row's entry k − 1 is read
            // before it is overwritten)
            let mut err = 0.0f64;
            for i in 0..n {
                let t = 0.5 * (self.z1[i] + self.z0[i] + hs * self.dz[i]);
                self.prev[i] = self.table[i];
                self.table[i] = t;
            }
            for k in 1..=j {
                let ratio = (m as f64 / SEQ[j - k] as f64).powi(2) - 1.0;
                for i in 0..n {
                    let lower = self.table[(k - 1) * n + i];
                    let old = self.prev[i];
                    let next = lower + (lower - old) / ratio;
                    self.prev[i] = self.table[k * n + i];
                    self.table[k * n + i] = next;
                    if k == j {
                        let e = (next - lower).abs() / (1.0 + next.abs());
                        err = if e.is_nan() || err.is_nan() {
                            f64::NAN
                        } else {
                            err.max(e)
                        };
                    }
                }
            }
            if err.is_nan()
                || self.table[j * n..(j + 1) * n]
                    .iter()
                    .any(|v| !v.is_finite())
            {
                return Outcome::NotFinite;
            }
            if j + 1 >= MIN_ROWS && err <= TOL {
                self.y.copy_from_slice(&self.table[j * n..(j + 1) * n]);
                return Outcome::Accepted(j + 1);
            }
        }
        Outcome::Refused
    }
}
