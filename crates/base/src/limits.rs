//! ravel's documented limits (docs/language.md, "Limits"), in one place.
//!
//! They are chosen so that an accepted spec fits in memory on a small
//! machine: the largest allocations of an accepted spec are a plant matrix
//! (at most `MAX_DIM²` numbers, 8 MB), the controller's weights (at most
//! `MAX_PARAMETERS` numbers, 128 MB, and as many bytes read from files), and
//! the stored reachable sets (at most `MAX_STORED_NUMBERS` numbers, 160 MB); together well under 1 GiB. Every size is checked with
//! overflow-safe arithmetic before anything of that size is allocated.
//! Magnitudes are limited so that sums and products of a few accepted
//! numbers stay far from the `f64` range; whatever still overflows during
//! an analysis is caught where it is produced and reported as UNSURE.

/// Largest absolute value of a number in a spec (matrices, sets, noise,
/// limits, `dt`) and of a controller weight.
pub const MAX_MAGNITUDE: f64 = 1e15;
/// Largest state, control or observation dimension, and `eye`/`zeros` size.
pub const MAX_DIM: u64 = 1000;
/// Largest horizon.
pub const MAX_HORIZON: u64 = 10_000;
/// Largest number of Monte Carlo samples.
pub const MAX_SAMPLES: u64 = 1_000_000;

/// The most slope-optimisation steps (`optimise_slopes N`): each step costs
/// about two back-substitutions per bounded row, and the step length decays
/// by 0.8 a step, so steps beyond a few dozen move nothing.
pub const MAX_SLOPE_STEPS: u64 = 100;
/// Largest number of simulated steps, `samples × horizon`.
pub const MAX_SIMULATED_STEPS: u64 = 50_000_000;
/// Largest number of cells of a uniform grid.
pub const MAX_CELLS: u64 = 100_000;
/// Largest call budget of a guided partitioner.
pub const MAX_CALLS: u64 = 100_000;
/// Largest number of stored set bounds, `cells × (horizon + 1) × numbers per
/// set`, where a set has `2n` box bounds and `n + 1` numbers per boundary
/// direction (for a guided partitioner, `calls` stands for `cells`).
pub const MAX_STORED_NUMBERS: u64 = 20_000_000;
/// Largest size of a spec file in bytes.
pub const MAX_SPEC_BYTES: u64 = 16 << 20;
/// Largest size of a controller file, and of all its external data together, in bytes.
pub const MAX_CONTROLLER_BYTES: u64 = 512 << 20;
/// Largest number of elements of one ONNX tensor.
pub const MAX_TENSOR_ELEMENTS: u64 = 1 << 24;
/// Largest number of weights of a controller, all tensors together.
pub const MAX_PARAMETERS: u64 = 1 << 24;
/// Largest number of matrix entries of a loaded network's layers together
/// (1 GiB of `f64`): each layer is stored dense, an element-wise constant op
/// (a normalisation) as a full `width × width` diagonal, so a chain of such
/// ops must not multiply its memory past what the machine holds.
pub const MAX_LAYER_ENTRIES: u64 = 1 << 27;
/// Largest width of a controller layer (its input included).
pub const MAX_WIDTH: u64 = 4096;
/// Largest number of nodes of an ONNX graph.
pub const MAX_NODES: usize = 4096;

/// Largest dimension of Reach-SDP's semidefinite program (observation and
/// state inputs, hidden and saturation neurons, plus one). The
/// Schur-complement method (`analysis::sdp_ipm`) holds a few `d × d`
/// matrices and one `m × m` (m multipliers, about four per neuron: 1200 at
/// 300, 12 MB) and factors it in `m³/3` operations an iteration: about 0.2 s
/// an iteration at 300 on the build machines.
pub const MAX_SDP_DIM: u64 = 300;
/// Largest dimension Clarabel (the SDP fallback, and the solver for
/// programs with many more multipliers than matrix entries) is given: its
/// factorisation of a PSD cone of dimension `d` holds about `(d²/2)²`
/// numbers, 1 GB at 150.
pub const MAX_CLARABEL_SDP_DIM: usize = 150;
/// Most multipliers the Schur-complement method is given: its `m × m`
/// matrix and factor hold `2m²` numbers, 256 MB at 4000. (The pairwise
/// products of many input rows can exceed it on a small matrix: Clarabel's
/// case.)
pub const MAX_SCHUR_MULTIPLIERS: usize = 4000;
/// Largest `horizon × neurons` of unrolled CROWN, which keeps every step's
/// neuron bounds and relaxations (about 60 bytes per neuron and step).
pub const MAX_UNROLLED_NEURON_STEPS: u64 = 5_000_000;

/// Largest number of numbers held by a spec's matrices and vectors together
/// (`per_step` entries count one by one).
pub const MAX_SPEC_NUMBERS: u64 = 10_000_000;
/// Largest `steps × n × (n + m + 1)` of a plant (one `A`, `B`, `c` per step of
/// a time-varying plant, and the analysis keeps block copies of each).
pub const MAX_PLANT_NUMBERS: u64 = 5_000_000;
/// Largest number of inequalities of one polytope.
pub const MAX_POLYTOPE_ROWS: usize = 1000;
/// Largest dimension of a polytope initial set (bounding it takes `4n`
/// linear programs in `n` variables).
pub const MAX_POLYTOPE_DIM: usize = 100;

/// Deepest nesting of brackets `(`, `[`, `{` in a spec (the parser
/// recurses once per level: the limit keeps its stack small).
pub const MAX_NESTING: usize = 32;
/// Deepest expression tree of a nonlinear plant, a constant, `observe` or
/// `actuate` (unary minus signs and powers count one level each).
pub const MAX_EXPR_DEPTH: usize = 64;
/// Most expression nodes in a spec, all expressions together (numbers,
/// names, components, operators and calls count one each).
pub const MAX_EXPR_NODES: usize = 100_000;

/// Most directions of `boundary polytope K`.
pub const MAX_BOUNDARY_DIRECTIONS: usize = 1000;
/// Largest scale a radius search may try (`radius … (max s)`).
pub const MAX_RADIUS_SCALE: f64 = 1e6;
/// Most plant evaluations of check's definedness test (E0225): the corners
/// of the initial set's box are evaluated only while `2ⁿ × expression
/// nodes` stays within it.
pub const MAX_CORNER_EVALUATIONS: usize = 10_000_000;

/// `a × b × …` if it does not overflow `u64`.
pub fn product(factors: &[u64]) -> Option<u64> {
    factors.iter().try_fold(1u64, |acc, f| acc.checked_mul(*f))
}

/// `product(factors) ≤ limit`, false on overflow.
pub fn within(factors: &[u64], limit: u64) -> bool {
    product(factors).is_some_and(|p| p <= limit)
}
