//! What the analysis and the certificate checker share, and nothing else:
//! feed-forward networks ([`nn`]), plant expressions ([`expr`]), outward-rounded numerics ([`num`]), the
//! resource limits every phase obeys ([`limits`]), a seeded random number
//! generator ([`rng`]) and text made safe to show ([`text`]).
//!
//! The certificate checker depends on this crate alone, so everything here
//! is part of what a VALID answer trusts; keep it small.
#![forbid(unsafe_code)]

pub mod expr;
pub mod limits;
pub mod nn;
pub mod num;
pub mod rng;
pub mod text;

/// Exact sums of `f64` values for the property tests of directed rounding
/// (the same file serves the integration tests; each crate uses part of it).
#[cfg(test)]
#[allow(dead_code)]
#[path = "../../../tests/common/exact.rs"]
mod exact;
