//! The analysis back-end: network bounds, closed-loop propagators, simulation.

pub mod crown;
pub mod relax;
