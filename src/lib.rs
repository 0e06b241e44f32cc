//! ravel: a Reach-Avoid Verification Language and its compiler.
#![forbid(unsafe_code)]

pub mod analysis;
pub mod diag;
pub mod nn;
pub mod num;
pub mod onnx;
pub mod rng;
pub mod sets;
pub mod syntax;
