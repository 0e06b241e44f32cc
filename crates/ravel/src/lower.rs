//! Lowering: a checked [`Task`] → its [`Plan`] (a [`SystemPlan`] for a
//! closed loop, a [`NetworkPlan`] for a network on its own). Cannot fail.
//!
//! Lowering decides *what* to compute: it appends the control saturation to
//! the network, assembles the closed loop, keeps the partitioner (the cells
//! themselves are made by [`crate::execute`], which may refine them), and
//! turns goal and avoid sets into properties over the steps they constrain.

use crate::check::{Checked, NetworkChecked, PlantSpec, Task};
pub use crate::ir::{GoalMode, Guide, Partitioner, Property, PropertyKind, StateSet, Window};
use nalgebra::DMatrix;
use ravel_analysis::closed_loop::{Boundary, ClosedLoop, Plant, Propagator};
use ravel_analysis::feedback::Loop;
use ravel_analysis::nonlinear::linear_field;
use ravel_analysis::nonlinear::{NonlinearLoop, NonlinearPlant};
use ravel_analysis::sets::{IBox, Region};
use ravel_base::nn::{Layer, Network};

/// Everything the executor needs to run a task, as plain data: one variant
/// per kind of spec (a third kind of plant is a third variant).
#[derive(Clone, Debug)]
pub enum Plan {
    /// A closed loop.
    System(Box<SystemPlan>),
    /// A network on its own.
    Network(Box<NetworkPlan>),
}

/// Lower a checked task to its plan.
pub fn lower(task: &Task) -> Plan {
    match task {
        Task::System(c) => Plan::System(Box::new(lower_system(c))),
        Task::Network(c) => Plan::Network(Box::new(lower_network(c))),
    }
}

impl Plan {
    /// The path the controller (or the network's model) was read from.
    pub fn controller_resolved(&self) -> &str {
        match self {
            Plan::System(p) => &p.controller_resolved,
            Plan::Network(p) => &p.model_resolved,
        }
    }

    /// SHA-256 of the controller (or model) file, in hex.
    pub fn controller_sha256(&self) -> &str {
        match self {
            Plan::System(p) => &p.controller_sha256,
            Plan::Network(p) => &p.model_sha256,
        }
    }

    /// The network the plan analyses (for a closed loop, with the control
    /// saturation appended).
    pub fn network(&self) -> &ravel_base::nn::Network {
        match self {
            Plan::System(p) => p.closed_loop.net(),
            Plan::Network(p) => &p.net,
        }
    }
}

/// Everything the executor needs for a closed loop, as plain data.
#[derive(Clone, Debug)]
pub struct SystemPlan {
    /// The system's name.
    pub system: String,
    /// The state vector's name.
    pub state_name: String,
    /// The control vector's name.
    pub control_name: String,
    /// The controller path: as written in the spec, or as given on the command line.
    pub controller_path: String,
    /// SHA-256 of the controller file, in hex.
    pub controller_sha256: String,
    /// The path the controller was read from.
    pub controller_resolved: String,
    /// A one-line description of the network, e.g. `2 → 5 relu → 5 relu → 1`.
    pub network_summary: String,
    /// The closed loop (saturation already part of the network).
    pub closed_loop: Loop,
    /// A linear plant in continuous time: its vector field per step
    /// (`ẋ = A x + B u + c`, the control held), whose validated flow
    /// encloses the states between the sampling instants (avoid windows
    /// are checked there too); `None` otherwise.
    pub intersample: Option<Intersample>,
    /// The time step when the spec's plant was continuous-time (already discretised).
    pub dt: Option<f64>,
    /// Control limits, if any (for reports).
    pub limits: Option<IBox>,
    /// The initial set.
    pub initial: Region,
    /// Its name.
    pub initial_name: String,
    /// How the initial set is split.
    pub partitioner: Partitioner,
    /// The shape of the reachable sets.
    pub boundary: Boundary,
    /// Number of steps.
    pub horizon: usize,
    /// The propagator.
    pub propagator: Propagator,
    /// The properties, goal first, then avoid sets in spec order.
    pub properties: Vec<Property>,
    /// Monte Carlo samples.
    pub samples: usize,
    /// Monte Carlo seed.
    pub seed: u64,
}

fn summary(c: &Checked) -> String {
    describe(&c.controller)
}

/// `2 → 5 relu → 5 relu → 1`, with the loader's notes.
fn describe(c: &crate::onnx::Controller) -> String {
    let net = &c.net;
    let mut parts = vec![net.inputs.to_string()];
    for (i, layer) in net.layers.iter().enumerate() {
        if let Layer::Act(a) = layer {
            parts.push(format!("{} {}", net.width_at(i), a.name()));
        }
    }
    parts.push(net.outputs().to_string());
    let chain = parts.join(" → ");
    if c.notes.is_empty() {
        chain
    } else {
        format!("{chain}; {}", c.notes.join(", "))
    }
}

/// The network of the closed loop, for either kind of plant: the
/// controller with `observe`'s offsets prepended (`h ↦ h + d`, an identity
/// affine layer; none when `d = 0`), `actuate`'s map appended
/// (`u = S · net + o`), then the control saturation.
pub fn folded_network(c: &Checked) -> Network {
    let net = &c.controller.net;
    let mut layers = Vec::with_capacity(net.layers.len() + 6);
    if let Some(d) = &c.observe_offset {
        layers.push(Layer::Affine {
            w: DMatrix::identity(net.inputs, net.inputs),
            b: d.clone(),
        });
    }
    layers.extend(net.layers.iter().cloned());
    if let Some((w, b)) = &c.actuate {
        layers.push(Layer::Affine {
            w: w.clone(),
            b: b.clone(),
        });
    }
    let folded = if c.observe_offset.is_none() && c.actuate.is_none() {
        net.clone()
    } else {
        Network::new(net.inputs, layers).with_input_type(net.input_type)
    };
    match &c.limits {
        Some(l) => folded.with_saturation(&l.lo, &l.hi),
        None => folded,
    }
}

/// The closed loop of a nonlinear plant: the plant and the
/// [`folded_network`]; `None` for a linear plant.
pub fn nonlinear_loop(c: &Checked) -> Option<NonlinearLoop> {
    match &c.plant {
        PlantSpec::Nonlinear(p) => Some(NonlinearLoop::new(p.clone(), folded_network(c))),
        PlantSpec::Linear(_) => None,
    }
}

/// A linear plant in continuous time, kept beside its discretisation for
/// the states between the sampling instants.
#[derive(Clone, Debug)]
pub struct Intersample {
    /// The sampling period.
    pub period: f64,
    /// The plants before discretisation (one per step, or one).
    pub plants: Vec<Plant>,
    /// Their loops `ẋ = A x + B u + c` with the controller (no
    /// disturbance: the noise `w` arrives at the next instant).
    pub loops: Vec<NonlinearLoop>,
}

/// Whether a goal or avoid set has a nonlinear constraint (bounded with
/// the steps' affine forms, which the loop then keeps).
fn has_nonlinear_sets(c: &Checked) -> bool {
    c.goal.iter().any(|g| !g.set.nonlinear.is_empty())
        || c.avoids
            .iter()
            .any(|a| a.members.iter().any(|m| !m.nonlinear.is_empty()))
}

/// Lower a checked closed-loop spec to its plan.
pub fn lower_system(c: &Checked) -> SystemPlan {
    let net = folded_network(c);
    let closed_loop = match &c.plant {
        PlantSpec::Linear(plants) => Loop::Linear(Box::new(
            ClosedLoop::time_varying(plants.clone(), net.clone()).with_slope_steps(c.slope_steps),
        )),
        PlantSpec::Nonlinear(p) => Loop::Nonlinear(Box::new(
            NonlinearLoop::new(p.clone(), net.clone())
                .with_slope_steps(c.slope_steps)
                .with_forms(has_nonlinear_sets(c)),
        )),
    };
    let mut properties = Vec::new();
    if let Some(g) = &c.goal {
        properties.push(Property {
            name: g.name.clone(),
            kind: PropertyKind::Goal {
                set: g.set.clone(),
                window: clipped(g.window, c.horizon),
                mode: g.mode,
            },
        });
    }
    for a in &c.avoids {
        properties.push(Property {
            name: a.name.clone(),
            kind: PropertyKind::Avoid {
                members: a.members.clone(),
                window: clipped(a.window, c.horizon),
            },
        });
    }
    let intersample = match (&c.continuous, c.dt) {
        (Some(plants), Some(dt)) => Some(Intersample {
            period: dt,
            loops: plants
                .iter()
                .map(|p| {
                    let plant = NonlinearPlant {
                        field: linear_field(&p.a, &p.b, p.c.as_slice(), dt),
                        w: IBox::new(Vec::new(), Vec::new()),
                        obs: p.obs.clone(),
                        v: p.v.clone(),
                    };
                    NonlinearLoop::new(plant, net.clone()).with_slope_steps(c.slope_steps)
                })
                .collect(),
            plants: plants.clone(),
        }),
        _ => None,
    };
    SystemPlan {
        intersample,
        system: c.system.clone(),
        state_name: c.state.0.clone(),
        control_name: c.control.0.clone(),
        controller_path: c.controller_path.clone(),
        controller_sha256: c.controller_sha256.clone(),
        controller_resolved: c.controller_resolved.clone(),
        network_summary: summary(c),
        closed_loop,
        dt: c.dt,
        limits: c.limits.clone(),
        initial: c.initial.1.clone(),
        initial_name: c.initial.0.clone(),
        partitioner: c.partitioner.clone(),
        boundary: c.boundary.clone(),
        horizon: c.horizon,
        propagator: c.propagator,
        properties,
        samples: c.samples,
        seed: c.seed,
    }
}

/// Everything the executor needs for a network spec, as plain data.
#[derive(Clone, Debug)]
pub struct NetworkPlan {
    /// The network's name.
    pub name: String,
    /// The input vector's name.
    pub input_name: String,
    /// The output vector's name.
    pub output_name: String,
    /// The model path: as written, or as given on the command line.
    pub model_path: String,
    /// SHA-256 of the model file, in hex.
    pub model_sha256: String,
    /// The path the model was read from.
    pub model_resolved: String,
    /// A one-line description of the network.
    pub network_summary: String,
    /// The network.
    pub net: ravel_base::nn::Network,
    /// The input set (absent in a spec that only selects actions).
    pub input: Option<Region>,
    /// Its name.
    pub input_set_name: String,
    /// The robust action selections, in spec order.
    pub selects: Vec<crate::ir::SelectSpec>,
    /// The properties, in spec order.
    pub properties: Vec<crate::ir::NetProperty>,
    /// The radius searches, in spec order.
    pub radii: Vec<crate::ir::RadiusSpec>,
    /// The propagator.
    pub propagator: crate::ir::NetPropagator,
    /// How the input set is split.
    pub partitioner: Partitioner,
    /// The output set's shape.
    pub shape: ravel_analysis::shape::Shape,
    /// Monte Carlo samples.
    pub samples: usize,
    /// Monte Carlo seed.
    pub seed: u64,
    /// Projected-gradient steps on the lower ReLU slopes of CROWN (0: CROWN's own).
    pub slope_steps: usize,
    /// How `partitioner bab` picks a split (always the default from a spec).
    pub branching: crate::ir::Branching,
    /// How `partitioner bab` on activations spends its budget (always the
    /// default from a spec).
    pub phases: crate::ir::ActivationPhases,
}

/// Lower a checked network spec to its plan.
pub fn lower_network(c: &NetworkChecked) -> NetworkPlan {
    NetworkPlan {
        name: c.name.clone(),
        input_name: c.input.0.clone(),
        output_name: c.output.0.clone(),
        model_path: c.model_path.clone(),
        model_sha256: c.model_sha256.clone(),
        model_resolved: c.model_resolved.clone(),
        network_summary: describe(&c.model),
        net: c.model.net.clone(),
        input: c.input_set.as_ref().map(|i| i.1.clone()),
        input_set_name: c
            .input_set
            .as_ref()
            .map(|i| i.0.clone())
            .unwrap_or_default(),
        selects: c.selects.clone(),
        properties: c.properties.clone(),
        radii: c.radii.clone(),
        propagator: c.propagator,
        partitioner: c.partitioner.clone(),
        shape: c.shape.clone(),
        samples: c.samples,
        seed: c.seed,
        slope_steps: c.slope_steps,
        branching: crate::ir::Branching::default(),
        phases: crate::ir::ActivationPhases::default(),
    }
}

/// A window clipped to the horizon `h`.
fn clipped(w: Window, h: usize) -> Window {
    Window {
        steps: (w.steps.0.min(h), w.steps.1.min(h)),
        periods: (w.periods.0, w.periods.1.min(h)),
    }
}
