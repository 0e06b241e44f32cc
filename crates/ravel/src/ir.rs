//! Plain types shared by the phases after parsing: what `check` produces
//! and `lower` and `execute` consume. Keeping them here lets the phases stack
//! (`check` → `lower` → `execute`) without importing each other backwards.

use ravel_analysis::partition::Budget;

/// What guides a refining partitioner.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Guide {
    /// Simulation-guided: refine cells whose sets leave the sampled hull, depth first.
    Sg,
    /// Greedy simulation-guided: refine the cell that sticks out furthest first.
    Gsg,
    /// Property-guided: refine the cell with the worst unproven property margin
    /// first; stop when every cell is proven or the verdict is decided.
    Property,
}

impl Guide {
    /// Every guide, in the order of the documentation.
    pub const ALL: [Guide; 3] = [Guide::Sg, Guide::Gsg, Guide::Property];

    /// The spec-language name.
    pub fn name(self) -> &'static str {
        match self {
            Guide::Sg => "sg",
            Guide::Gsg => "gsg",
            Guide::Property => "property",
        }
    }

    /// The guide with this spec-language name.
    pub fn from_name(name: &str) -> Option<Guide> {
        Guide::ALL.into_iter().find(|g| g.name() == name)
    }
}

/// How the initial set is split.
#[derive(Clone, Debug, PartialEq)]
pub enum Partitioner {
    /// A uniform grid (all ones: no partition).
    Uniform(Vec<usize>),
    /// Refinement by bisection, guided and budgeted.
    Guided {
        /// What decides which cell to split.
        guide: Guide,
        /// When to stop.
        budget: Budget,
    },
}

/// How a network spec bounds its network (the tutorial's Table I propagators).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NetPropagator {
    /// Interval bound propagation.
    Ibp,
    /// Fast-Lin: CROWN with the lower ReLU slope equal to the upper one.
    FastLin,
    /// CROWN (adaptive lower ReLU slopes).
    Crown,
    /// The quadratic-constraint SDP relaxation (ReLU networks only).
    Sdp,
}

impl NetPropagator {
    /// Every network propagator, in the order of the documentation.
    pub const ALL: [NetPropagator; 4] = [
        NetPropagator::Ibp,
        NetPropagator::FastLin,
        NetPropagator::Crown,
        NetPropagator::Sdp,
    ];

    /// The spec-language name.
    pub fn name(self) -> &'static str {
        match self {
            NetPropagator::Ibp => "ibp",
            NetPropagator::FastLin => "fast_lin",
            NetPropagator::Crown => "crown",
            NetPropagator::Sdp => "sdp",
        }
    }

    /// The propagator with this spec-language name.
    pub fn from_name(name: &str) -> Option<NetPropagator> {
        NetPropagator::ALL.into_iter().find(|p| p.name() == name)
    }
}
