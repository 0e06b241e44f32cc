//! A closed loop of either plant kind: what execution asks of a loop
//! (its dimensions, its noise, one simulated step, one validated step of a
//! single trajectory) without knowing which kind it has.
//!
//! The two kinds keep their own propagators: the linear plant's closed form
//! ([`ClosedLoop`]) never passes through the nonlinear integrator, and the
//! nonlinear plant ([`NonlinearLoop`]) is carried across steps as Taylor
//! models by its own [`NonlinearLoop::reach`].

use crate::closed_loop::{Boundary, ClosedLoop};
use crate::nonlinear::NonlinearLoop;
use crate::sets::IBox;
use nalgebra::DMatrix;
use ravel_base::nn::Network;

/// A plant and its controller.
#[derive(Clone, Debug)]
pub enum Loop {
    /// `x⁺ = A x + B u + c + w`, possibly time-varying.
    Linear(Box<ClosedLoop>),
    /// `ẋ = f(x, u, w)` over a control period, or `x⁺ = f(x, u, w)`.
    Nonlinear(Box<NonlinearLoop>),
}

impl Loop {
    /// The linear loop, if the plant is linear.
    pub fn linear(&self) -> Option<&ClosedLoop> {
        match self {
            Loop::Linear(cl) => Some(cl),
            Loop::Nonlinear(_) => None,
        }
    }

    /// The linear loop, mutably, if the plant is linear.
    pub fn linear_mut(&mut self) -> Option<&mut ClosedLoop> {
        match self {
            Loop::Linear(cl) => Some(cl),
            Loop::Nonlinear(_) => None,
        }
    }

    /// The state dimension.
    pub fn states(&self) -> usize {
        match self {
            Loop::Linear(cl) => cl.states(),
            Loop::Nonlinear(nl) => nl.states(),
        }
    }

    /// The control dimension.
    pub fn controls(&self) -> usize {
        match self {
            Loop::Linear(cl) => cl.plant.b.ncols(),
            Loop::Nonlinear(nl) => nl.plant.field.controls,
        }
    }

    /// The controller (saturation included).
    pub fn net(&self) -> &Network {
        match self {
            Loop::Linear(cl) => &cl.net,
            Loop::Nonlinear(nl) => &nl.net,
        }
    }

    /// The observation matrix `C` (the controller sees `Cᵀ x + v`).
    pub fn obs(&self) -> &DMatrix<f64> {
        match self {
            Loop::Linear(cl) => &cl.plant.obs,
            Loop::Nonlinear(nl) => &nl.plant.obs,
        }
    }

    /// The process noise (linear) or disturbance (nonlinear) box.
    pub fn w(&self) -> &IBox {
        match self {
            Loop::Linear(cl) => &cl.plant.w,
            Loop::Nonlinear(nl) => &nl.plant.w,
        }
    }

    /// The sensor noise box.
    pub fn v(&self) -> &IBox {
        match self {
            Loop::Linear(cl) => &cl.plant.v,
            Loop::Nonlinear(nl) => &nl.plant.v,
        }
    }

    /// Projected-gradient steps on CROWN's lower ReLU slopes.
    pub fn slope_steps(&self) -> usize {
        match self {
            Loop::Linear(cl) => cl.slope_steps,
            Loop::Nonlinear(nl) => nl.slope_steps,
        }
    }

    /// Whether the plant changes with the step (linear plants only).
    pub fn is_time_varying(&self) -> bool {
        match self {
            Loop::Linear(cl) => cl.is_time_varying(),
            Loop::Nonlinear(_) => false,
        }
    }

    /// One simulated step `t` of `count` samples stored coordinate-major
    /// (see [`ClosedLoop::simulate_batch`]): `(u, x⁺)`.
    pub fn simulate_batch(
        &self,
        t: usize,
        x: &[f64],
        w: &[f64],
        v: &[f64],
        count: usize,
    ) -> (Vec<f64>, Vec<f64>) {
        match self {
            Loop::Linear(cl) => cl.simulate_batch(t, x, w, v, count),
            Loop::Nonlinear(nl) => nl.simulate_batch(x, w, v, count),
        }
    }

    /// One simulated step `t`: `(u, x⁺)`.
    pub fn simulate(&self, t: usize, x: &[f64], w: &[f64], v: &[f64]) -> (Vec<f64>, Vec<f64>) {
        self.simulate_batch(t, x, w, v, 1)
    }

    /// A rigorous enclosure of the next state from every state in `x` at
    /// step `t` with the given noise values; `None` when it cannot be
    /// bounded. Confirms simulated counterexamples.
    pub fn enclose_step(&self, t: usize, x: &IBox, w: &[f64], v: &[f64]) -> Option<IBox> {
        match self {
            Loop::Linear(cl) => cl.enclose_step(t, x, w, v),
            Loop::Nonlinear(nl) => nl.enclose_step(x, w, v),
        }
    }

    /// The facet matrix of a boundary at step `t`: `[I; −I]`, then its directions.
    pub fn facets(&self, boundary: &Boundary, t: usize) -> DMatrix<f64> {
        crate::closed_loop::facets(self.states(), boundary, t)
    }
}
