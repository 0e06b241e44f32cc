//! Helpers shared by the benchmarks and the profiling examples.
#![allow(dead_code)]

use nalgebra::{DMatrix, DVector};
use ravel_base::nn::{Activation, Layer, Network};
use ravel_base::rng::Rng;

/// The CPU model and the hardware threads available.
pub fn machine() -> String {
    let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let model = info
        .lines()
        .find_map(|l| l.strip_prefix("model name"))
        .map(|l| l.trim_start_matches([' ', '\t', ':']).to_string())
        .unwrap_or_else(|| "unknown CPU".into());
    let threads = std::thread::available_parallelism().map_or(0, |n| n.get());
    format!("{model}, {threads} hardware threads available")
}

/// A random ReLU network with the given widths (input first), weights
/// scaled by `1.5/√fan-in`.
pub fn random_relu(rng: &mut Rng, widths: &[usize]) -> Network {
    let mut layers = Vec::new();
    for (k, pair) in widths.windows(2).enumerate() {
        let s = 1.5 / (pair[0] as f64).sqrt();
        layers.push(Layer::Affine {
            w: DMatrix::from_fn(pair[1], pair[0], |_, _| rng.uniform(-s, s)),
            b: DVector::from_fn(pair[1], |_, _| rng.uniform(-0.2, 0.2)),
        });
        if k + 2 < widths.len() {
            layers.push(Layer::Act(Activation::Relu));
        }
    }
    Network::new(widths[0], layers)
}

/// The benchmark's arguments: a filter (the first argument that is not a
/// flag) and whether `--slow` was given.
pub fn args() -> (Option<String>, bool) {
    let filter = std::env::args()
        .skip(1)
        .find(|a| !a.starts_with('-'))
        .filter(|a| !a.is_empty());
    (filter, std::env::args().any(|a| a == "--slow"))
}

/// Greedy simulation-guided refinement with 32 calls (the GSG rows).
pub fn gsg32() -> ravel::ir::Partitioner {
    ravel::ir::Partitioner::Guided {
        guide: ravel::ir::Guide::Gsg,
        budget: ravel_analysis::partition::Budget {
            calls: 32,
            min_size: 1.0 / 64.0,
            seconds: None,
        },
    }
}
