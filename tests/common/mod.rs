//! Helpers shared by the integration tests (each test crate uses some).
#![allow(dead_code)]

use nalgebra::{DMatrix, DVector};
use ravel::execute::network::{execute_network, NetworkOutcome};
use ravel::execute::Control;
use ravel::ir::NetProperty;
use ravel::ir::{NetPropagator, Partitioner};
use ravel::lower::NetworkPlan;
use ravel_analysis::sets::Region;
use ravel_analysis::shape::Shape;
use ravel_base::nn::{Activation, Layer, Network};
use ravel_base::rng::Rng;
use serde_json::Value;

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

/// A network spec's plan without a spec: CROWN on one cell, box shape, 200
/// samples, seed 7 (callers change what they test).
pub fn net_plan(net: Network, input: Region, properties: Vec<NetProperty>) -> NetworkPlan {
    let cells = vec![1; net.inputs];
    NetworkPlan {
        name: "test".into(),
        input_name: "x".into(),
        output_name: "y".into(),
        model_path: String::new(),
        model_sha256: String::new(),
        model_resolved: String::new(),
        network_summary: String::new(),
        net,
        input: Some(input),
        input_set_name: "X".into(),
        selects: Vec::new(),
        properties,
        radii: Vec::new(),
        propagator: NetPropagator::Crown,
        partitioner: Partitioner::Uniform(cells),
        shape: Shape::Box,
        samples: 200,
        seed: 7,
        slope_steps: 0,
        branching: Default::default(),
        phases: Default::default(),
    }
}

/// Execute a network plan on one thread, without a time limit.
pub fn run_net(p: &NetworkPlan) -> NetworkOutcome {
    execute_network(
        p,
        &Control {
            elapsed: &|| 0.0,
            time_limit: None,
            progress: &|_| {},
            threads: 1,
        },
    )
}

/// The certificate of a network result, with an empty identity.
pub fn net_certificate(p: &NetworkPlan, out: &NetworkOutcome) -> Value {
    let id = ravel::certificate_writer::Identity {
        spec_path: "t".into(),
        spec_sha256: String::new(),
    };
    ravel::certificate_writer::build_network(p, out, &id)
}

/// A closed-loop spec (a path from the repository's root) run from its
/// file, and the certificate of its result (its identity: that path and
/// the spec's hash).
pub fn system_certificate(spec: &str) -> (ravel::lower::SystemPlan, Value) {
    let source = std::fs::read_to_string(spec).expect("spec readable");
    let dir = std::path::Path::new(spec).parent().expect("folder");
    let checked = ravel::front_end(&source, dir, &ravel_cli::read_request).expect("valid spec");
    let plan = ravel::lower::lower_system(&checked);
    let outcome = ravel::execute::execute_system(&plan, &Control::unlimited());
    let id = ravel::certificate_writer::Identity {
        spec_path: spec.to_string(),
        spec_sha256: ravel::check::sha256_hex(source.as_bytes()),
    };
    let cert = ravel::certificate_writer::build_system(&plan, &outcome, &id);
    (plan, cert)
}

/// The independent checker's answer on a closed loop's certificate.
pub fn system_answer(cert: &Value, plan: &ravel::lower::SystemPlan) -> ravel_certify::Answer {
    ravel_certify::check(cert, plan.closed_loop.net()).answer
}
