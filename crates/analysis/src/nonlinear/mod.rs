//! Closed loops whose plant is nonlinear: `ẋ = f(x, u, w)` in continuous
//! time with the control held over each period, or `x⁺ = f(x, u, w)`.
//!
//! * [`integrate`]: validated arithmetic (outward-rounded intervals,
//!   first-order Taylor models) and the validated integrator of one control
//!   period, with its intersample enclosure; a float simulator for
//!   falsification.
//! * [`NonlinearLoop`]: the plant composed with the controller's CROWN
//!   bounds, step after step, keeping the dependency on the initial cell.

mod closed;
pub use closed::Claim;
pub mod integrate;
#[cfg(test)]
mod tests;

use crate::sets::IBox;
use nalgebra::DMatrix;
use ravel_base::expr::VectorField;
use ravel_base::nn::Network;

/// A nonlinear plant with bounded disturbances.
#[derive(Clone, Debug, PartialEq)]
pub struct NonlinearPlant {
    /// The right-hand side over `[x, u, w]`.
    pub field: VectorField,
    /// The disturbance box (`p`; held constant over each control period).
    pub w: IBox,
    /// Observation matrix `C` (`n × k`); the controller sees `Cᵀ x + v`
    /// (the convention of the linear plants).
    pub obs: DMatrix<f64>,
    /// Sensor noise box (`k`).
    pub v: IBox,
}

/// A nonlinear plant and its controller (saturation and output map already
/// part of the network).
#[derive(Clone, Debug)]
pub struct NonlinearLoop {
    /// The plant.
    pub plant: NonlinearPlant,
    /// The controller.
    pub net: Network,
    /// The validated integrator's settings.
    pub settings: integrate::Settings,
    /// Projected-gradient steps on CROWN's lower ReLU slopes of every
    /// control bound (0: CROWN's own slopes; see
    /// [`crate::crown::Relaxation::upper_optimised`]).
    pub slope_steps: usize,
    /// Whether each step keeps its Taylor models as affine forms
    /// ([`crate::closed_loop::Step::form`], `between_forms`): only a
    /// property with a nonlinear set uses them, and they cost about as much
    /// memory as the rest of a step.
    pub keep_forms: bool,
}

impl NonlinearLoop {
    /// Assemble a loop (dimensions must agree; `check` guarantees it).
    pub fn new(plant: NonlinearPlant, net: Network) -> NonlinearLoop {
        NonlinearLoop {
            plant,
            net,
            settings: integrate::Settings::default(),
            slope_steps: 0,
            keep_forms: false,
        }
    }

    /// The loop keeping (or not) each step's affine forms.
    pub fn with_forms(mut self, keep: bool) -> NonlinearLoop {
        self.keep_forms = keep;
        self
    }

    /// The loop with this many slope-optimisation steps per control bound.
    pub fn with_slope_steps(mut self, steps: usize) -> NonlinearLoop {
        self.slope_steps = steps;
        self
    }

    /// The state dimension.
    pub fn states(&self) -> usize {
        self.plant.field.states
    }
}

/// `ẋ = A x + B u + c` as a vector field over `[x, u]` (no disturbances),
/// the control held over periods `period`: what the intersample enclosure
/// of a linear plant in continuous time integrates (zero coefficients are
/// left out of the tape).
pub fn linear_field(a: &DMatrix<f64>, b: &DMatrix<f64>, c: &[f64], period: f64) -> VectorField {
    use ravel_base::expr::{Node, Tape, Time};
    let (n, m) = (a.nrows(), b.ncols());
    let mut tape = Tape::new();
    let vars: Vec<_> = (0..n + m).map(|i| tape.push(Node::Var(i as u32))).collect();
    let mut outputs = Vec::with_capacity(n);
    for i in 0..n {
        let mut acc = tape.push(Node::Const(c.get(i).copied().unwrap_or(0.0)));
        let coefs = (0..n).map(|j| a[(i, j)]).chain((0..m).map(|k| b[(i, k)]));
        for (coef, &v) in coefs.zip(&vars) {
            if coef != 0.0 {
                let k = tape.push(Node::Const(coef));
                let t = tape.push(Node::Mul(k, v));
                acc = tape.push(Node::Add(acc, t));
            }
        }
        outputs.push(acc);
    }
    VectorField {
        tape,
        outputs,
        states: n,
        controls: m,
        disturbances: 0,
        time: Time::Continuous { period },
    }
}
