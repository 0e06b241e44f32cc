//! Helpers shared by the integration tests.

use nalgebra::{DMatrix, DVector};
use ravel::nn::{Activation, Layer, Network};
use ravel::rng::Rng;

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
