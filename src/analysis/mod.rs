//! The analysis back-end: network bounds, closed-loop propagators, simulation.

pub mod batch;
pub mod closed_loop;
pub mod crown;
pub mod dense;
pub mod open_loop;
pub mod partition;
pub mod relax;
pub mod sdp;
pub mod sdp_ipm;
pub mod shape;
