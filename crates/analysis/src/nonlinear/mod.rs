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
}

impl NonlinearLoop {
    /// Assemble a loop (dimensions must agree; `check` guarantees it).
    pub fn new(plant: NonlinearPlant, net: Network) -> NonlinearLoop {
        NonlinearLoop {
            plant,
            net,
            settings: integrate::Settings::default(),
            slope_steps: 0,
        }
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
