//! The analysis back-end: network bounds, closed-loop propagators, simulation.
#![deny(unsafe_code)]

pub mod batch;
pub mod blas;
pub mod closed_loop;
pub mod crown;
pub mod dense;
pub mod dual;
pub mod expm;
pub mod feedback;
pub mod issue;
pub mod lp;
pub mod nonlinear;
pub mod open_loop;
pub mod partition;
pub mod pool;
pub mod relax;
pub mod sdp;
pub mod sdp_ipm;
pub mod sets;
pub mod shape;

/// Exact sums of `f64` values for the property tests of directed rounding
/// (the same file serves the integration tests; each crate uses part of it).
#[cfg(test)]
#[allow(dead_code)]
#[path = "../../../tests/common/exact.rs"]
mod exact;
