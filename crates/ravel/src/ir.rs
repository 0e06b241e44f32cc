//! Plain types shared by the phases after parsing: what `check` produces
//! and `lower` and `execute` consume — the properties of both kinds of spec,
//! radius searches, action selections, partitioners and propagators, in one
//! home. Keeping them here lets the phases stack (`check` → `lower` →
//! `execute`) without importing each other backwards.

use ravel_analysis::partition::Budget;
use ravel_analysis::sets::{Norm, Polytope};
use ravel_base::expr::Tape;

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
    /// Branch and bound (network specs): refine the subproblem with the
    /// worst unproven margin first, aim every split at the properties, try
    /// to falsify every subproblem, and stop as soon as every property is
    /// settled (see `execute::bab`).
    Bab,
}

impl Guide {
    /// Every guide, in the order of the documentation.
    pub const ALL: [Guide; 4] = [Guide::Sg, Guide::Gsg, Guide::Property, Guide::Bab];

    /// The spec-language name.
    pub fn name(self) -> &'static str {
        match self {
            Guide::Sg => "sg",
            Guide::Gsg => "gsg",
            Guide::Property => "property",
            Guide::Bab => "bab",
        }
    }

    /// The guide with this spec-language name.
    pub fn from_name(name: &str) -> Option<Guide> {
        Guide::ALL.into_iter().find(|g| g.name() == name)
    }
}

/// How branch and bound picks the input a cell is split along. Not part of
/// the language: [`lower`](crate::lower) always chooses the default,
/// [`Branching::LookAhead`]; the others exist so the rules can be measured
/// side by side on the same plan (`examples/bab_branching.rs`, figures in
/// docs/language.md) and tested alike.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Branching {
    /// The input with the largest first-order change of the deciding output
    /// row across the cell: `|∂(d·f)/∂xᵢ(centre)|·widthᵢ`.
    Smear,
    /// The widest input relative to the whole input set.
    Widest,
    /// Every input is tried (up to `bab::LOOK_AHEAD_DIMS` inputs; more:
    /// as `Smear`): all the children are bounded, and the split whose
    /// children's open margins sum highest (a proved child counting 0) is
    /// kept.
    #[default]
    LookAhead,
}

impl Branching {
    /// Every rule.
    pub const ALL: [Branching; 3] = [Branching::Smear, Branching::Widest, Branching::LookAhead];
}

/// How branch and bound on ReLU activations spends its budget. Not part of
/// the language: [`lower`](crate::lower) always chooses the default,
/// [`ActivationPhases::Portfolio`]; the others exist so each phase can be
/// tested and measured alone.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ActivationPhases {
    /// Splits anywhere (the best-scored neuron of any layer) for the first
    /// half of the budget (calls, and time when limited), then the search
    /// again from the root as [`ActivationPhases::Rebound`] for the rest.
    #[default]
    Portfolio,
    /// Splits anywhere, children keep their parent's bounds but the split.
    Split,
    /// Splits only in the first layer with an unstable neuron, and each
    /// child's later layers are re-bounded.
    Rebound,
}

impl ActivationPhases {
    /// Every schedule.
    pub const ALL: [ActivationPhases; 3] = [
        ActivationPhases::Portfolio,
        ActivationPhases::Split,
        ActivationPhases::Rebound,
    ];
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

/// A set of states a property refers to: the intersection of linear rows
/// `H x ≤ h` and nonlinear constraints `g(x) ≤ 0`.
#[derive(Clone, Debug, PartialEq)]
pub struct StateSet {
    /// The linear rows (every affine inequality of the spec).
    pub poly: Polytope,
    /// The constraints `g(x) ≤ 0`: `g` is the last node of each tape, over
    /// the state `x` (variables `0 … n−1`).
    pub nonlinear: Vec<Tape>,
}

impl StateSet {
    /// A set of linear rows only.
    pub fn linear(poly: Polytope) -> StateSet {
        StateSet {
            poly,
            nonlinear: Vec::new(),
        }
    }
}

/// When a property applies: sampling instants, and the control periods
/// between them where a plant has intersample enclosures (plants in
/// continuous time, linear or nonlinear; period `p` runs from step `p − 1`
/// to step `p`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    /// First and last step (inclusive, clipped to the horizon).
    pub steps: (usize, usize),
    /// First and last period (inclusive); empty when the first is larger.
    pub periods: (usize, usize),
}

impl Window {
    /// Steps `a` to `b` and the periods between them (`a + 1 … b`).
    pub fn steps(a: usize, b: usize) -> Window {
        Window {
            steps: (a, b),
            periods: (a + 1, b),
        }
    }

    /// Step `k` alone (no period).
    pub fn at(k: usize) -> Window {
        Window {
            steps: (k, k),
            periods: (k + 1, k),
        }
    }

    /// Whether period `p` (ending at step `p`) lies in the window.
    pub fn has_period(&self, p: usize) -> bool {
        self.periods.0 <= p && p <= self.periods.1
    }

    /// The last step the window needs (a period ends at its step).
    pub fn last(&self) -> usize {
        if self.periods.0 <= self.periods.1 {
            self.steps.1.max(self.periods.1)
        } else {
            self.steps.1
        }
    }
}

/// Whether a goal holds at every instant of its window or at some instant.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GoalMode {
    /// `goal` (at the horizon), `at time T`, `always during […]`.
    Always,
    /// `eventually during […]`.
    Eventually,
}

/// What a property demands.
#[derive(Clone, Debug, PartialEq)]
pub enum PropertyKind {
    /// The reachable set lies in this set at every step of the window
    /// (and over every period of it), or at some step of it.
    Goal {
        /// The goal set.
        set: StateSet,
        /// When (a plain goal: the horizon alone).
        window: Window,
        /// Always or eventually.
        mode: GoalMode,
    },
    /// No reachable set in the window touches any member.
    Avoid {
        /// The union's members.
        members: Vec<StateSet>,
        /// When.
        window: Window,
    },
}

/// A named property.
#[derive(Clone, Debug, PartialEq)]
pub struct Property {
    /// The set's name from the spec.
    pub name: String,
    /// What it demands.
    pub kind: PropertyKind,
}

impl Property {
    /// The last step the property constrains.
    pub fn last_step(&self) -> usize {
        self.window().last()
    }

    /// When the property applies.
    pub fn window(&self) -> Window {
        match &self.kind {
            PropertyKind::Goal { window, .. } | PropertyKind::Avoid { window, .. } => *window,
        }
    }
}

/// What a network property demands of the outputs `y = f(x)` on the whole input set.
#[derive(Clone, Debug, PartialEq)]
pub enum NetPropertyKind {
    /// Every inequality holds: `y` lies in the polytope.
    Require(Polytope),
    /// `y` lies in no member of the union.
    Avoid(Vec<Polytope>),
    /// `y[label] > y[j]` for every other `j`; without a label, the label of
    /// the input set's centre (decided by `execute`).
    Robust(Option<usize>),
}

/// A named network property.
#[derive(Clone, Debug, PartialEq)]
pub struct NetProperty {
    /// Its name.
    pub name: String,
    /// What it demands.
    pub kind: NetPropertyKind,
}

/// A minimal-adversarial-perturbation search: the input set scaled about its
/// centre by `s ∈ [0, max]`.
#[derive(Clone, Debug, PartialEq)]
pub struct RadiusSpec {
    /// Its name.
    pub name: String,
    /// The index of the property in `NetworkChecked::properties`.
    pub property: usize,
    /// The largest scale tried.
    pub max: f64,
    /// Bisection stops when the bracket is narrower than this.
    pub tolerance: f64,
}

/// Robust action selection (CARRL): every observation's ε-ball.
#[derive(Clone, Debug, PartialEq)]
pub struct SelectSpec {
    /// Its name.
    pub name: String,
    /// The ball's radius per input.
    pub epsilon: Vec<f64>,
    /// The ball's norm.
    pub norm: Norm,
    /// The observations (each of the input size).
    pub observations: Vec<Vec<f64>>,
}
