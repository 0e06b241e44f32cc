//! Helpers shared by the integration tests (each test crate uses some).
#![allow(dead_code)]

use nalgebra::{DMatrix, DVector};
use ravel::nn::{Activation, Layer, Network};
use ravel::rng::Rng;

/// A ReLU network with the given widths (input first, output last),
/// weights uniform in `±scale/√fan-in`, biases in `±bias`.
pub fn relu_network(rng: &mut Rng, widths: &[usize], scale: f64, bias: f64) -> Network {
    let mut layers = Vec::new();
    for (k, pair) in widths.windows(2).enumerate() {
        let s = scale / (pair[0] as f64).sqrt();
        layers.push(Layer::Affine {
            w: DMatrix::from_fn(pair[1], pair[0], |_, _| rng.uniform(-s, s)),
            b: DVector::from_fn(pair[1], |_, _| rng.uniform(-bias, bias)),
        });
        if k + 2 < widths.len() {
            layers.push(Layer::Act(Activation::Relu));
        }
    }
    Network::new(widths[0], layers)
}

/// A random network with `1 + below(depths)` hidden layers of
/// `2 + below(widths)` neurons each, weights scaled by `1.5/√fan-in`.
pub fn random_network(
    rng: &mut Rng,
    inputs: usize,
    outputs: usize,
    act: Activation,
    (depths, widths): (usize, usize),
) -> Network {
    let depth = 1 + rng.below(depths);
    let mut layers = Vec::new();
    let mut width = inputs;
    for k in 0..=depth {
        let out = if k == depth {
            outputs
        } else {
            2 + rng.below(widths)
        };
        let scale = 1.5 / (width as f64).sqrt();
        layers.push(Layer::Affine {
            w: DMatrix::from_fn(out, width, |_, _| rng.normal() * scale),
            b: DVector::from_fn(out, |_, _| rng.normal() * 0.3),
        });
        if k < depth {
            layers.push(Layer::Act(act));
        }
        width = out;
    }
    Network::new(inputs, layers)
}
