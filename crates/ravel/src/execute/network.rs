//! Execution of a network spec: a [`NetworkPlan`] → a [`NetworkOutcome`]: the output
//! set in the chosen shape, a verdict per property, and the bracket of every
//! radius search.
//!
//! * Every bound is an upper bound of `d·f(x)` over (a cell of) the input set
//!   for a direction `d`: the shape's directions and each property's rows
//!   (`require` rows, the negated rows of `avoid` members, `y_j − y_K` for
//!   robustness) are bounded together, cell by cell. A cell's bounds are
//!   intersected with its parent's; the union's bound is the largest over
//!   the cells, which cover the input set.
//! * A property is VERIFIED when those bounds prove it (`require`: every row
//!   within its right-hand side; `avoid`: on every cell some row of every
//!   member strictly separates it; `robust`: `y_K − y_j > 0` for every
//!   `j ≠ K`), FALSIFIED when an input of the set provably violates it for
//!   the network as stored (`confirm`: the input is a value of the model's
//!   input type — float32 for a float32 model — inside the set, and the
//!   outward-rounded interval enclosure of the real-arithmetic `f(x)`, the
//!   fixed-order evaluation in the input type's precision and an enclosure
//!   of its evaluation in any summation order all violate it as a whole),
//!   and UNSURE otherwise (with, when the attack found one, an `f64` input
//!   that violates only the real-arithmetic network). A bound that is not
//!   finite, or a solver issue on the way, never proves anything.
//! * A radius search scales the input set about its centre by `s`: bisection
//!   on `s` with the plan's analysis gives the largest certified scale, and a
//!   gradient-free attack (samples, then coordinate search) the smallest
//!   scale with a confirmed violation. The true radius lies between them.

use nalgebra::DMatrix;

use crate::execute::{Control, Verdict};
use crate::ir::{Guide, NetPropagator, Partitioner};
use crate::ir::{NetPropertyKind, RadiusSpec};
use crate::lower::NetworkPlan;
use ravel_analysis::batch;
use ravel_analysis::crown::{Mode, Relaxation};
use ravel_analysis::issue::Issue;
use ravel_analysis::partition::{refine_parallel, Bisector, Stop, Strategy};
use ravel_analysis::sdp;
use ravel_analysis::sets::{IBox, Norm, Region};
use ravel_analysis::shape::{excess, extent_of_points, support_of_box, support_of_points};
use ravel_base::nn::{Activation, InputType, Layer, Network};
use ravel_base::num::{dot_box_upper, error_bound, gamma, sum_lower, sum_upper, Acc};
use ravel_base::rng::Rng;

mod bab;

/// The output set: certified offsets along the shape's directions.
#[derive(Clone, Debug)]
pub struct OutputBounds {
    /// The directions `D`, one per row.
    pub directions: DMatrix<f64>,
    /// Certified `max d·f(x)` over the input set (`+∞`: no bound).
    pub offsets: Vec<f64>,
    /// `max d·f(x)` over the sampled inputs (`−∞` without samples).
    pub sampled: Vec<f64>,
    /// The output's bounding box, when the shape has one.
    pub bbox: Option<IBox>,
    /// The sampled outputs' bounding box.
    pub sampled_bbox: Option<IBox>,
}

/// What kind of network property a result is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NetKind {
    /// Inequalities that must hold.
    Require,
    /// A set the outputs must avoid.
    Avoid,
    /// The label is the same on the whole input set.
    Robust,
}

impl NetKind {
    /// The keyword used in specs and reports.
    pub fn as_str(self) -> &'static str {
        match self {
            NetKind::Require => "require",
            NetKind::Avoid => "avoid",
            NetKind::Robust => "robust",
        }
    }
}

/// An input that violates a property, with its output.
#[derive(Clone, Debug, PartialEq)]
pub struct Witness {
    /// The input: a value of the network's input type (float32 for a
    /// float32 model), inside the input set.
    pub input: Vec<f64>,
    /// The network's output at it (f64 evaluation).
    pub output: Vec<f64>,
}

/// The result for one network property.
#[derive(Clone, Debug, PartialEq)]
pub struct NetPropertyResult {
    /// The property's name.
    pub name: String,
    /// Which kind.
    pub kind: NetKind,
    /// The verdict.
    pub status: Verdict,
    /// VERIFIED/UNSURE: the certified margin (negative when the proof
    /// failed, `−∞` without a finite bound). FALSIFIED: minus the violation.
    pub margin: f64,
    /// Robustness: the label, and the certified margin `min (y_K − y_j)`
    /// against every other label `j`.
    pub label: Option<usize>,
    /// Robustness: `(j, certified lower bound of y_K − y_j)` for every `j ≠ K`.
    pub label_margins: Vec<(usize, f64)>,
    /// FALSIFIED only: the violating input.
    pub counterexample: Option<Witness>,
    /// UNSURE only: an input of the set (an `f64` point) at which the
    /// real-arithmetic network provably violates the property, while no
    /// value of the model's input type that the attack tried violates it as
    /// stored: why the verdict is not FALSIFIED.
    pub real_only: Option<Vec<f64>>,
}

/// The bracket found by a radius search.
#[derive(Clone, Debug, PartialEq)]
pub struct RadiusResult {
    /// The search's name.
    pub name: String,
    /// The property's name.
    pub property: String,
    /// The largest scale at which the property was certified (`None`: not
    /// even at the centre).
    pub certified: Option<f64>,
    /// The smallest scale at which an attack found a confirmed violation
    /// (`None`: none up to `max`), with the violating input.
    pub attacked: Option<(f64, Witness)>,
    /// The largest scale tried.
    pub max: f64,
    /// The bisection tolerance.
    pub tolerance: f64,
    /// The input set's radius along each input at scale 1 (box half-widths
    /// or ball radii): scale `s` means radius `s·r`.
    pub unit: Vec<f64>,
    /// Analyses run.
    pub analyses: usize,
}

/// Everything the execution of a network spec found.
#[derive(Clone, Debug)]
pub struct NetworkOutcome {
    /// The output set.
    pub output: OutputBounds,
    /// Per-property results, in plan order.
    pub properties: Vec<NetPropertyResult>,
    /// Per-search results, in plan order.
    pub radii: Vec<RadiusResult>,
    /// FALSIFIED if any property is, VERIFIED if all are (vacuously with
    /// none), else UNSURE.
    pub verdict: Verdict,
    /// The final cells of the input set's partition (bounding boxes).
    pub partition: Vec<IBox>,
    /// Why partitioning stopped.
    pub partition_stop: Stop,
    /// Whether branch and bound split ReLU activations (then `partition`
    /// is the whole input box, bounded over the split subproblems).
    pub split_activations: bool,
    /// What a certificate needs of a search on activations (`None`
    /// without one): the root's tightening multipliers and the tree.
    pub split_record: Option<std::sync::Arc<SplitRecord>>,
    /// Cells bounded (parents included).
    pub calls: usize,
    /// Solver statuses that forced a fallback bound.
    pub solver_issues: Vec<Issue>,
    /// Whether some bound overflowed (it was then no bound at all).
    pub overflow: bool,
    /// Monte Carlo samples drawn.
    pub samples_drawn: usize,
    /// Per select block: the robust action selection of every observation.
    pub selections: Vec<Selection>,
}

/// What branch and bound on activations proved, as a certificate records
/// it (`certificate_writer`): kept while searching, within
/// [`SplitRecord::MAX_BYTES`] (past it the record is dropped, the search
/// goes on, and the certificate's evidence is unsupported).
#[derive(Clone, Default)]
pub struct SplitRecord {
    /// The multipliers of the root's tightened pre-activation bounds.
    pub neurons: Vec<ravel_analysis::dual::NeuronDual>,
    /// The split tree, the root first; children come after their parent.
    pub nodes: Vec<SplitNode>,
    /// Bytes held by the multipliers recorded.
    pub bytes: usize,
    /// Why the record is not usable, if it is not.
    pub dropped: Option<String>,
    /// Whether each child's later layers were re-bounded after its split
    /// ([`ravel_analysis::dual::rebound_after`]): the checker then derives
    /// every node's domain the same way.
    pub rebound: bool,
}

impl SplitRecord {
    /// The most bytes of multipliers kept (beyond: dropped).
    pub const MAX_BYTES: usize = 1 << 29;

    /// Account for `n` more numbers; past the limit, drop everything.
    pub fn charge(&mut self, n: usize) -> bool {
        if self.dropped.is_some() {
            return false;
        }
        self.bytes = self.bytes.saturating_add(n.saturating_mul(4));
        if self.bytes > Self::MAX_BYTES {
            self.dropped = Some(format!(
                "the proof's multipliers outgrew {} MiB while searching",
                Self::MAX_BYTES >> 20
            ));
            self.neurons = Vec::new();
            self.nodes = Vec::new();
            return false;
        }
        true
    }
}

impl std::fmt::Debug for SplitRecord {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "SplitRecord {{ {} neuron duals, {} nodes, {} bytes }}",
            self.neurons.len(),
            self.nodes.len(),
            self.bytes
        )
    }
}

/// A node of the split tree: its split (layer, neuron, the inactive
/// child's index, the active child's) or none (a leaf), and the rows of
/// the properties (indices over every property's rows, in order) that it
/// proved, each with its multipliers `ν` (one vector per hidden layer,
/// rounded to `f32`).
#[derive(Clone, Debug, Default)]
pub struct SplitNode {
    /// `(layer, neuron, inactive child, active child)`.
    pub split: Option<(usize, usize, usize, usize)>,
    /// `(row, ν)`.
    pub proofs: Vec<(usize, Vec<Vec<f32>>)>,
}

/// One observation's robust action selection (CARRL).
#[derive(Clone, Debug, PartialEq)]
pub struct ActionChoice {
    /// Certified lower bound of every action's value over the ε-ball
    /// (`−∞`: no finite bound).
    pub lower: Vec<f64>,
    /// Certified upper bound of every action's value over the ball.
    pub upper: Vec<f64>,
    /// The action with the largest value at the observation itself.
    pub nominal: usize,
    /// The action with the largest certified lower bound (CARRL's choice).
    pub robust: usize,
    /// Whether the robust action's lower bound is at least every other
    /// action's upper bound: it is the best action for every observation of
    /// the ball (never with a solver issue on the way). Observations past
    /// the time limit get no bounds (`±∞`), the nominal action and `false`.
    pub robust_optimal: bool,
}

/// The results of one select block, in observation order.
#[derive(Clone, Debug, PartialEq)]
pub struct Selection {
    /// The block's name.
    pub name: String,
    /// The ball's radius per input.
    pub epsilon: Vec<f64>,
    /// The observations.
    pub observations: Vec<Vec<f64>>,
    /// One choice per observation.
    pub choices: Vec<ActionChoice>,
}

/// `f` applied to every item, on up to `threads` threads (contiguous
/// chunks), results in item order.
fn map_ordered<T: Sync, U: Send>(
    items: &[T],
    threads: usize,
    f: &(dyn Fn(&T) -> U + Sync),
) -> Vec<U> {
    let threads = ravel_analysis::pool::available(threads).clamp(1, items.len().max(1));
    if threads == 1 {
        return items.iter().map(f).collect();
    }
    let chunk = items.len().div_ceil(threads);
    let parts: Vec<&[T]> = items.chunks(chunk).collect();
    // the calling thread maps the first chunk
    ravel_analysis::pool::on_threads(parts.len(), &|i| parts[i].iter().map(f).collect::<Vec<U>>())
        .into_iter()
        .flatten()
        .collect()
}

/// The rows bounded for one analysis: the shape's, then each property's.
struct Rows {
    dirs: DMatrix<f64>,
    /// `ranges[p]`: the rows of property `p`.
    ranges: Vec<std::ops::Range<usize>>,
    /// How many rows belong to the shape.
    shape_rows: usize,
}

/// The rows of property `kind` (robustness for label `label`), over `m` outputs.
fn property_rows(kind: &NetPropertyKind, label: Option<usize>, m: usize) -> Vec<Vec<f64>> {
    match kind {
        NetPropertyKind::Require(p) => p.rows.iter().map(|(a, _)| a.clone()).collect(),
        NetPropertyKind::Avoid(members) => members
            .iter()
            .flat_map(|p| p.rows.iter().map(|(a, _)| a.iter().map(|v| -v).collect()))
            .collect(),
        NetPropertyKind::Robust(_) => {
            let k = label.unwrap_or(0);
            (0..m)
                .filter(|&j| j != k)
                .map(|j| {
                    let mut r = vec![0.0; m];
                    r[j] = 1.0;
                    r[k] = -1.0;
                    r
                })
                .collect()
        }
    }
}

fn stack(shape: &DMatrix<f64>, props: &[Vec<Vec<f64>>], m: usize) -> Rows {
    let total = shape.nrows() + props.iter().map(Vec::len).sum::<usize>();
    let mut dirs = DMatrix::zeros(total, m);
    dirs.view_mut((0, 0), (shape.nrows(), m)).copy_from(shape);
    let mut at = shape.nrows();
    let mut ranges = Vec::new();
    for rows in props {
        let start = at;
        for r in rows {
            for (j, v) in r.iter().enumerate() {
                dirs[(at, j)] = *v;
            }
            at += 1;
        }
        ranges.push(start..at);
    }
    Rows {
        dirs,
        ranges,
        shape_rows: shape.nrows(),
    }
}

/// Certified upper bounds of every row of `dirs` over `cell` (`+∞` where
/// there is none), and the solver issues met; CROWN's lower ReLU slopes are
/// optimised `slope_steps` times per row (0: CROWN's own).
pub fn cell_bounds(
    net: &Network,
    cell: &Region,
    prop: NetPropagator,
    slope_steps: usize,
    dirs: &DMatrix<f64>,
) -> (Vec<f64>, Vec<Issue>) {
    let none = || vec![f64::INFINITY; dirs.nrows()];
    let bbox = cell.bbox();
    if !bbox.is_finite() {
        return (none(), Vec::new());
    }
    let mode = match prop {
        NetPropagator::Ibp => Mode::Ibp,
        NetPropagator::FastLin => Mode::FastLin,
        NetPropagator::Crown | NetPropagator::Sdp => Mode::Crown,
    };
    // A box cell: the batched pass (`analysis::batch`), as fast as the
    // single-cell analysis on one cell of a narrow network and faster on a
    // wide one (its products are blocked matrix multiplies); the same
    // bounds up to rounding terms. It is the answer under CROWN's own
    // slopes and Fast-Lin; optimised slopes and the SDP are intersected
    // with it, so they are never looser than what CROWN reports.
    let batched = (mode != Mode::Ibp && matches!(cell, Region::Box(_)))
        .then(|| batch::crown_offsets(net, std::slice::from_ref(&bbox), dirs, mode))
        .flatten()
        .and_then(|mut all| all.pop());
    if let (Some(_), Some(b)) = (own_slopes(prop, slope_steps), &batched) {
        return (b.clone(), Vec::new());
    }
    let a = Relaxation::new(net, &bbox, mode);
    if !a.is_finite() {
        return (none(), Vec::new());
    }
    let out = a.output_box(mode);
    let mut b = support_of_box(dirs, &out.lo, &out.hi);
    let mut issues = Vec::new();
    if mode != Mode::Ibp {
        let (crown, iss) = a
            .upper_optimised(dirs.clone(), slope_steps, None)
            .concretize_region(cell);
        issues.extend(iss);
        for (v, c) in b.iter_mut().zip(crown) {
            if c.is_finite() {
                *v = v.min(c);
            }
        }
    }
    if prop == NetPropagator::Sdp {
        let (s, iss) = sdp_bounds(net, cell, &bbox, dirs);
        issues.extend(iss);
        for (v, c) in b.iter_mut().zip(s) {
            if c.is_finite() {
                *v = v.min(c);
            }
        }
    }
    for (v, c) in b.iter_mut().zip(batched.iter().flatten()) {
        *v = v.min(*c);
    }
    // a NaN is no bound
    for v in &mut b {
        if v.is_nan() {
            *v = f64::INFINITY;
        }
    }
    (b, issues)
}

/// The mode whose bounds [`batch::crown_offsets`] gives as they are, if
/// the propagator's are those: CROWN with its own slopes (no optimisation,
/// no SDP) or Fast-Lin.
fn own_slopes(prop: NetPropagator, slope_steps: usize) -> Option<Mode> {
    match prop {
        NetPropagator::Crown if slope_steps == 0 => Some(Mode::Crown),
        NetPropagator::FastLin => Some(Mode::FastLin),
        _ => None,
    }
}

/// SDP bounds of every row over `cell` (see [`ravel_analysis::sdp`]): the
/// output `W_L h_L + b_L` of the merged network, the merge error and the
/// rounding of the objective added.
fn sdp_bounds(
    net: &Network,
    cell: &Region,
    bbox: &IBox,
    dirs: &DMatrix<f64>,
) -> (Vec<f64>, Vec<Issue>) {
    let n = bbox.dim();
    let none = vec![f64::INFINITY; dirs.nrows()];
    let Some(merged) = sdp::merge(net, &DMatrix::identity(n, n), bbox) else {
        return (none, vec![Issue::SdpNeedsRelu]);
    };
    let Some((wl, bl)) = merged.layers.last() else {
        return (none, Vec::new());
    };
    if merged.layers.len() < 2 {
        // an affine network: CROWN is exact up to rounding already
        return (none, Vec::new());
    }
    let rows: Vec<(Vec<f64>, f64)> = match cell {
        Region::Polytope { rows, .. } => rows.clone(),
        _ => Vec::new(),
    };
    let prog = sdp::StepSdp::new(&merged, bbox, &rows);
    let h_max = prog.last_hidden_max();
    let h_off = prog.last_hidden();
    let mut out = Vec::with_capacity(dirs.nrows());
    let mut issues = Vec::new();
    for r in 0..dirs.nrows() {
        let d: Vec<f64> = dirs.row(r).iter().copied().collect();
        let mut phi = vec![0.0; prog.dim()];
        for k in 0..wl.ncols() {
            phi[h_off + k] = (0..wl.nrows()).map(|j| d[j] * wl[(j, k)]).sum();
        }
        // |φ_k − exact| ≤ γ(m)·Σ|d_j||W_jk|; the objective's error is that times |h_k|
        let size = sum_upper(
            (0..wl.ncols())
                .map(|k| sum_upper((0..wl.nrows()).map(|j| (d[j] * wl[(j, k)]).abs())) * h_max[k]),
        );
        let round = (gamma(wl.nrows() + wl.ncols() + 4) * size * 1.0625 + 1e-300).next_up();
        let konst = sum_upper(
            (0..wl.nrows())
                .map(|j| d[j] * bl[j])
                .chain((0..wl.nrows()).map(|j| d[j].abs() * merged.err[j]))
                .chain([
                    round,
                    gamma(wl.nrows() + 2)
                        * sum_upper((0..wl.nrows()).map(|j| (d[j] * bl[j]).abs())),
                ]),
        );
        let last = prog.dim() - 1;
        phi[last] = konst;
        let b = prog.bound(&phi);
        issues.extend(b.issue);
        out.push(b.value);
    }
    (out, issues)
}

/// The bounds of one analysis of the whole input set.
struct Bounded {
    /// Per final cell: its box and its bounds.
    cells: Vec<(IBox, Vec<f64>)>,
    /// The largest bound over the cells, per row.
    union: Vec<f64>,
    calls: usize,
    stop: Stop,
    issues: Vec<Issue>,
}

/// Bound every row of `dirs` over `region` with the plan's propagator and
/// partitioner; `sampled`/`extent` guide SG and GSG.
fn bound_all(
    plan: &NetworkPlan,
    region: &Region,
    dirs: &DMatrix<f64>,
    sampled: &[f64],
    extent: &[f64],
    ctl: &Control,
) -> Bounded {
    let mut issues = Vec::new();
    let within = |b: Vec<f64>, parent: Option<&Vec<f64>>| -> Vec<f64> {
        match parent {
            Some(p) => b.iter().zip(p).map(|(a, q)| a.min(*q)).collect(),
            None => b,
        }
    };
    let (cells, calls, stop) = match &plan.partitioner {
        Partitioner::Uniform(grid) => {
            let (root, iss) =
                cell_bounds(&plan.net, region, plan.propagator, plan.slope_steps, dirs);
            issues.extend(iss);
            if grid.iter().all(|k| *k == 1) {
                (vec![(region.bbox(), root)], 1, Stop::Grid)
            } else {
                let parts = region.grid(grid);
                let n = parts.len() + 1;
                // past the time limit a cell keeps the whole set's bounds
                // (valid for any part of it)
                let one = |c: &Region| {
                    let (b, iss) =
                        cell_bounds(&plan.net, c, plan.propagator, plan.slope_steps, dirs);
                    (within(b, Some(&root)), iss)
                };
                // progress: the cells started so far (from any thread)
                let started = std::sync::atomic::AtomicUsize::new(0);
                let report = |count: usize| {
                    let k = started.fetch_add(count, std::sync::atomic::Ordering::Relaxed);
                    (ctl.progress)(crate::execute::Progress {
                        phase: crate::execute::Phase::Cells,
                        done: k,
                        total: Some(parts.len()),
                    });
                };
                let done: Vec<Option<(Vec<f64>, Vec<Issue>)>> =
                    if let (Some(mode), Region::Box(_)) =
                        (own_slopes(plan.propagator, plan.slope_steps), region)
                    {
                        // CROWN's own bounds of box cells: the cells of a group
                        // go through the network together (`analysis::batch`;
                        // the same bounds up to rounding terms), the groups on
                        // the threads; the groups depend on the cell count only,
                        // so the output does not depend on `--jobs`
                        let group = parts.len().div_ceil(8).clamp(4, 256);
                        let groups: Vec<&[Region]> = parts.chunks(group).collect();
                        map_ordered(&groups, ctl.threads, &|g: &&[Region]| {
                            report(g.len());
                            if ctl.out_of_time() {
                                return vec![None; g.len()];
                            }
                            let boxes: Vec<IBox> = g.iter().map(Region::bbox).collect();
                            match batch::crown_offsets(&plan.net, &boxes, dirs, mode) {
                                Some(all) => all
                                    .into_iter()
                                    .map(|b| Some((within(b, Some(&root)), Vec::new())))
                                    .collect(),
                                // not a chain of affine layers and
                                // activations, or a number overflowed:
                                // one by one
                                None => g.iter().map(|c| Some(one(c))).collect(),
                            }
                        })
                        .into_iter()
                        .flatten()
                        .collect()
                    } else {
                        map_ordered(&parts, ctl.threads, &|c: &Region| {
                            report(1);
                            if ctl.out_of_time() {
                                return None;
                            }
                            Some(one(c))
                        })
                    };
                let mut stop = Stop::Grid;
                let mut cells = Vec::with_capacity(parts.len());
                for (c, r) in parts.iter().zip(done) {
                    match r {
                        Some((b, iss)) => {
                            issues.extend(iss);
                            cells.push((c.bbox(), b));
                        }
                        None => {
                            stop = Stop::Time;
                            cells.push((c.bbox(), root.clone()));
                        }
                    }
                }
                (cells, n, stop)
            }
        }
        Partitioner::Guided { guide, budget } => {
            let strategy = match guide {
                Guide::Sg => Strategy::Sg,
                _ => Strategy::Gsg,
            };
            let mut budget = *budget;
            if let Some(limit) = ctl.time_limit {
                let left = (limit - (ctl.elapsed)()).max(0.0);
                budget.seconds = Some(budget.seconds.map_or(left, |s| s.min(left)));
            }
            let root = region.bbox();
            // the two children of every split on two threads (the same
            // cells and values as one thread); the issues are sorted below
            let found = std::sync::Mutex::new(Vec::new());
            let r = refine_parallel(
                &root,
                strategy,
                &budget,
                &|c: &IBox, parent: Option<&Vec<f64>>| {
                    let cell = match region {
                        Region::Polytope { rows, .. } => Region::Polytope {
                            bbox: c.clone(),
                            rows: rows.clone(),
                        },
                        // a ball's cell is covered by its box (an over-approximation)
                        Region::Ball { .. } if parent.is_some() => Region::Box(c.clone()),
                        _ if parent.is_none() => region.clone(),
                        _ => Region::Box(c.clone()),
                    };
                    let (b, iss) =
                        cell_bounds(&plan.net, &cell, plan.propagator, plan.slope_steps, dirs);
                    if !iss.is_empty() {
                        found.lock().unwrap_or_else(|e| e.into_inner()).extend(iss);
                    }
                    let b = within(b, parent);
                    let s = excess(&b, sampled, extent);
                    (b, s)
                },
                ctl.elapsed,
                ctl.threads,
                Bisector::Widest,
            );
            issues.extend(found.into_inner().unwrap_or_else(|e| e.into_inner()));
            let cells = r.leaves.into_iter().map(|l| (l.cell, l.value)).collect();
            (cells, r.calls, r.stop)
        }
    };
    let union = ravel_analysis::open_loop::union_offsets(&cells, dirs.nrows());
    issues.sort_by_key(|i| format!("{i:?}"));
    issues.dedup();
    Bounded {
        cells,
        union,
        calls,
        stop,
        issues,
    }
}

/// The certified margin of property `kind` from the bounds of its rows
/// (`rows` indexes them in each cell's bounds): positive proves it.
/// Robustness also gives the margin per other label.
fn certified_margin(
    kind: &NetPropertyKind,
    label: Option<usize>,
    m: usize,
    b: &Bounded,
    rows: &std::ops::Range<usize>,
) -> (f64, Vec<(usize, f64)>) {
    let clean = |v: f64| if v.is_nan() { f64::NEG_INFINITY } else { v };
    match kind {
        NetPropertyKind::Require(p) => {
            let margin = p
                .rows
                .iter()
                .zip(rows.clone())
                .map(|((_, h), k)| clean(h - b.union[k]))
                .fold(f64::INFINITY, f64::min);
            (margin, Vec::new())
        }
        NetPropertyKind::Avoid(members) => {
            // per cell and member: the best separating row, lower bound of a·y − h
            let mut margin = f64::INFINITY;
            for (_, cb) in &b.cells {
                let mut at = rows.start;
                for p in members {
                    let mut best = f64::NEG_INFINITY;
                    for (_, h) in &p.rows {
                        // cb[at] bounds −a·y from above: a·y ≥ −cb[at]
                        best = best.max(clean(-cb[at] - h));
                        at += 1;
                    }
                    margin = margin.min(best);
                }
            }
            (margin, Vec::new())
        }
        NetPropertyKind::Robust(_) => {
            let k = label.unwrap_or(0);
            let per: Vec<(usize, f64)> = (0..m)
                .filter(|&j| j != k)
                .zip(rows.clone())
                .map(|(j, r)| (j, clean(-b.union[r])))
                .collect();
            let margin = per.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
            (margin, per)
        }
    }
}

/// Whether the certified margin proves the property.
fn proves(kind: &NetPropertyKind, margin: f64) -> bool {
    margin.is_finite()
        && match kind {
            NetPropertyKind::Require(_) => margin >= 0.0,
            NetPropertyKind::Avoid(_) | NetPropertyKind::Robust(_) => margin > 0.0,
        }
}

/// How much `y` violates the property (positive: violated in f64).
fn violation(kind: &NetPropertyKind, label: Option<usize>, y: &[f64]) -> f64 {
    let dot = |a: &[f64]| a.iter().zip(y).map(|(a, b)| a * b).sum::<f64>();
    let v = match kind {
        NetPropertyKind::Require(p) => p
            .rows
            .iter()
            .map(|(a, h)| dot(a) - h)
            .fold(f64::NEG_INFINITY, f64::max),
        NetPropertyKind::Avoid(members) => members
            .iter()
            .map(|p| {
                -p.rows
                    .iter()
                    .map(|(a, h)| dot(a) - h)
                    .fold(f64::NEG_INFINITY, f64::max)
            })
            .fold(f64::NEG_INFINITY, f64::max),
        NetPropertyKind::Robust(_) => {
            let k = label.unwrap_or(0);
            (0..y.len())
                .filter(|&j| j != k)
                .map(|j| y[j] - y[k])
                .fold(f64::NEG_INFINITY, f64::max)
        }
    };
    if v.is_nan() {
        f64::NEG_INFINITY
    } else {
        v
    }
}

/// Whether the output box `y` violates the property as a whole (a NaN
/// bound violates nothing).
fn box_violates(kind: &NetPropertyKind, label: Option<usize>, y: &IBox) -> bool {
    let lower = |a: &[f64]| -dot_box_upper(&a.iter().map(|v| -v).collect::<Vec<_>>(), &y.lo, &y.hi);
    match kind {
        NetPropertyKind::Require(p) => p.rows.iter().any(|(a, h)| lower(a) > *h),
        NetPropertyKind::Avoid(members) => members.iter().any(|p| {
            p.rows
                .iter()
                .all(|(a, h)| dot_box_upper(a, &y.lo, &y.hi) <= *h)
        }),
        NetPropertyKind::Robust(_) => {
            let k = label.unwrap_or(0);
            (0..y.dim()).filter(|&j| j != k).any(|j| {
                let mut a = vec![0.0; y.dim()];
                a[j] = 1.0;
                a[k] = -1.0;
                lower(&a) >= 0.0
            })
        }
    }
}

/// Whether `x` certainly lies in `region` and the outward-rounded enclosure
/// of the real-arithmetic network's `f(x)` violates the property as a whole.
fn violates_real(
    net: &Network,
    region: &Region,
    kind: &NetPropertyKind,
    label: Option<usize>,
    x: &[f64],
) -> bool {
    if !region.contains_point(x) {
        return false;
    }
    let a = Relaxation::new(net, &IBox::point(x), Mode::Ibp);
    a.is_finite() && box_violates(kind, label, &a.output_box(Mode::Ibp))
}

/// `γ(k) = k·u / (1 − k·u)` for the unit roundoff `u` (a power of two),
/// rounded up; `None` when `k·u ≥ 1/2`.
fn gamma_of(k: usize, u: f64) -> Option<f64> {
    let ku = k as f64 * u;
    (ku < 0.5).then(|| (ku / (1.0 - ku).next_down()).next_up())
}

/// At most this many multiply-adds per affine layer for the generators of
/// [`stored_enclosure`]: a larger layer first folds its generators into
/// per-neuron radii (an interval step; sound, only coarser).
const ZONOTOPE_BUDGET: usize = 1 << 27;

/// An enclosure of every evaluation of the stored model at `x` (a value of
/// its input type) in the precision of that type, whatever order a runtime
/// sums in, as an affine form (a zonotope) per layer: every computed value
/// vector is `c + G·ε + δ` for some `ε ∈ [−1, 1]^m` shared by the neurons
/// and `|δᵢ| ≤ radᵢ`.
///
/// * An affine layer first turns every `radⱼ` into a symbol of its own (a
///   column of `G`), then maps `c ↦ W c + b`, `G ↦ W G` with the signed
///   weights and biases rounded to the type, so the errors of earlier
///   layers cancel as they do in the runtime. Its new `radᵢ` is the
///   rounding error of the runtime's output `i` — at most
///   `γ(n+1)·(Σ|w||h| + |b|) + n·η` for `n` inputs (products and sums
///   rounded to nearest in any order, with or without fused multiply-add;
///   `η` the smallest subnormal; `|h|` bounded by the enclosure) — plus the
///   `f64` rounding of `W c + b` (an interval from [`Acc`]) and of `W G`
///   (at most `γ₆₄(n)·Σⱼ|wᵢⱼ|·Σₖ|Gⱼₖ|` over the row, for any order).
/// * ReLU is exact: a neuron whose enclosure is `≥ 0` keeps its form, one
///   `≤ 0` becomes 0, one that straddles becomes the interval `[0, u]`.
/// * `tanh` and the sigmoid are within [`InputType::activation_error`] of
///   the exact function: the layer's enclosure becomes intervals (its ends'
///   values, widened by libm's error and the runtime's).
///
/// Every bound is rounded outward in `f64`. `None` when a value may overflow
/// the type (some partial sum of some order could reach infinity) or a
/// bound is not finite.
fn stored_enclosure(net: &Network, x: &[f64]) -> Option<IBox> {
    let t = net.input_type;
    let (u, eta, top) = (t.unit_roundoff(), t.min_positive(), t.max());
    let mut z = Zonotope {
        c: x.to_vec(),
        g: vec![Vec::new(); x.len()],
        rad: vec![0.0; x.len()],
    };
    for layer in &net.layers {
        match layer {
            Layer::Affine { w, b } => {
                let n = w.ncols();
                let gam = gamma_of(n + 1, u)?;
                let mag = z.magnitudes();
                let m = z.g.first().map_or(0, Vec::len);
                if w.nrows().saturating_mul(n).saturating_mul(m) > ZONOTOPE_BUDGET {
                    z.fold_generators();
                }
                z.fold_radii();
                let m = z.g.first().map_or(0, Vec::len);
                // Σₖ|Gⱼₖ|, an upper bound
                let gabs: Vec<f64> =
                    z.g.iter()
                        .map(|r| sum_upper(r.iter().map(|v| v.abs())))
                        .collect();
                let mut next = Zonotope {
                    c: Vec::with_capacity(w.nrows()),
                    g: Vec::with_capacity(w.nrows()),
                    rad: Vec::with_capacity(w.nrows()),
                };
                for i in 0..w.nrows() {
                    let row: Vec<f64> = (0..n).map(|j| t.round(w[(i, j)])).collect();
                    let bias = t.round(b[i]);
                    let abs_row: Vec<f64> = row.iter().map(|v| v.abs()).collect();
                    let abs_sum = sum_upper([dot_box_upper(&abs_row, &mag, &mag), bias.abs()]);
                    let err = sum_upper([(gam * abs_sum).next_up(), (n as f64 * eta).next_up()]);
                    // every product and partial sum of every order lies within
                    // abs_sum + err of zero: within range, nothing overflows
                    let reach = sum_upper([abs_sum, err]);
                    if reach.is_nan() || reach > top {
                        return None;
                    }
                    // W c + b: an interval around its rounded value
                    let mut acc = Acc::ZERO;
                    acc.add_products(&row, &z.c);
                    acc.add(bias);
                    let (lo, hi) = (acc.lower(), acc.upper());
                    let ci = lo + 0.5 * (hi - lo);
                    let c_err = sum_upper([hi, -ci]).max(sum_upper([ci, -lo]));
                    // W G, row i, summed in the order j for every k
                    let mut gi = vec![0.0; m];
                    for (wij, gj) in row.iter().zip(&z.g) {
                        if *wij != 0.0 {
                            for (a, g) in gi.iter_mut().zip(gj) {
                                *a += wij * g;
                            }
                        }
                    }
                    let g_err = error_bound(n, dot_box_upper(&abs_row, &gabs, &gabs));
                    let rad = sum_upper([err, c_err, g_err]);
                    if !(ci.is_finite() && rad.is_finite() && gi.iter().all(|v| v.is_finite())) {
                        return None;
                    }
                    next.c.push(ci);
                    next.g.push(gi);
                    next.rad.push(rad);
                }
                z = next;
            }
            Layer::Act(Activation::Relu) => {
                for i in 0..z.c.len() {
                    let (lo, hi) = z.bounds(i);
                    if lo >= 0.0 {
                        continue;
                    }
                    z.g[i].iter_mut().for_each(|v| *v = 0.0);
                    if hi <= 0.0 {
                        (z.c[i], z.rad[i]) = (0.0, 0.0);
                    } else {
                        // [0, hi] ⊆ [c − rad, c + rad]
                        let c = 0.5 * hi;
                        (z.c[i], z.rad[i]) = (c, sum_upper([hi, -c]).max(c));
                    }
                }
            }
            Layer::Act(a) => {
                // monotone: the ends' values, widened by libm's error and the runtime's
                let d = t.activation_error();
                for i in 0..z.c.len() {
                    let (lo, hi) = z.bounds(i);
                    let (el, eh) = (a.eval(lo), a.eval(hi));
                    let lo = sum_lower([el, -a.eval_error(el), -d]);
                    let hi = sum_upper([eh, a.eval_error(eh), d]);
                    if !(lo.is_finite() && hi.is_finite()) {
                        return None;
                    }
                    let c = lo + 0.5 * (hi - lo);
                    z.c[i] = c;
                    z.rad[i] = sum_upper([hi, -c]).max(sum_upper([c, -lo]));
                }
                z.g.iter_mut().for_each(Vec::clear);
            }
        }
    }
    let (lo, hi): (Vec<f64>, Vec<f64>) = (0..z.c.len()).map(|i| z.bounds(i)).unzip();
    lo.iter()
        .chain(&hi)
        .all(|v| v.is_finite())
        .then(|| IBox::new(lo, hi))
}

/// The affine form of [`stored_enclosure`]: value `i` is
/// `cᵢ + Σₖ Gᵢₖ εₖ + δᵢ` with `ε ∈ [−1, 1]^m` and `|δᵢ| ≤ radᵢ`.
struct Zonotope {
    c: Vec<f64>,
    /// `G`, one row per value.
    g: Vec<Vec<f64>>,
    rad: Vec<f64>,
}

impl Zonotope {
    /// An upper bound of `Σₖ|Gᵢₖ| + radᵢ`.
    fn spread(&self, i: usize) -> f64 {
        sum_upper(self.g[i].iter().map(|v| v.abs()).chain([self.rad[i]]))
    }

    /// Outward-rounded bounds of value `i`.
    fn bounds(&self, i: usize) -> (f64, f64) {
        let s = self.spread(i);
        (sum_lower([self.c[i], -s]), sum_upper([self.c[i], s]))
    }

    /// Upper bounds of `|value|`.
    fn magnitudes(&self) -> Vec<f64> {
        (0..self.c.len())
            .map(|i| sum_upper([self.c[i].abs(), self.spread(i)]))
            .collect()
    }

    /// Every `radⱼ > 0` becomes a symbol of its own.
    fn fold_radii(&mut self) {
        let fresh: Vec<usize> = (0..self.rad.len()).filter(|&j| self.rad[j] > 0.0).collect();
        for (i, row) in self.g.iter_mut().enumerate() {
            row.extend(
                fresh
                    .iter()
                    .map(|&j| if j == i { self.rad[i] } else { 0.0 }),
            );
        }
        self.rad.iter_mut().for_each(|r| *r = 0.0);
    }

    /// The symbols become per-value radii (the interval hull).
    fn fold_generators(&mut self) {
        for i in 0..self.c.len() {
            self.rad[i] = self.spread(i);
            self.g[i].clear();
        }
    }
}

/// Whether the input `x` of `region` provably violates the property for
/// the network as stored: `x` is a value of the network's input type and
/// certainly lies in the region; the outward-rounded enclosure of the
/// real-arithmetic `f(x)` violates the property as a whole; and so do the
/// fixed-order evaluation in the input type's precision
/// ([`Network::forward_stored`]) and the enclosure of every evaluation in
/// that precision, in any summation order ([`stored_enclosure`]).
fn confirm(
    net: &Network,
    region: &Region,
    kind: &NetPropertyKind,
    label: Option<usize>,
    x: &[f64],
) -> bool {
    let t = net.input_type;
    if !x.iter().all(|v| t.represents(*v)) || !violates_real(net, region, kind, label, x) {
        return false;
    }
    let y = net.forward_stored(x);
    y.iter().all(|v| v.is_finite())
        && box_violates(kind, label, &IBox::point(&y))
        && stored_enclosure(net, x).is_some_and(|e| box_violates(kind, label, &e))
}

/// The candidate `x` as an input of the stored model: every coordinate
/// rounded to the nearest value of the input type, and moved to the nearest
/// such value inside the set's bounding box when rounding left it; a ball
/// point still outside steps towards the (rounded) centre, one unit in the
/// last place per coordinate at a time, at most 16 times. `None` when no
/// such point lies in the set (membership tested rigorously, as every
/// confirmed input's is).
fn representable(region: &Region, t: InputType, x: &[f64]) -> Option<Vec<f64>> {
    let b = region.bbox();
    let mut r = Vec::with_capacity(x.len());
    for (i, v) in x.iter().enumerate() {
        let (lo, hi) = (t.ceil(b.lo[i]), t.floor(b.hi[i]));
        // no value of the type in [lo, hi] (or a NaN): nothing to report
        if !(lo <= hi && v.is_finite()) {
            return None;
        }
        r.push(t.round(*v).clamp(lo, hi));
    }
    if region.contains_point(&r) {
        return Some(r);
    }
    if let Region::Ball { center, .. } = region {
        let c: Vec<f64> = center.iter().map(|v| t.round(*v)).collect();
        for _ in 0..16 {
            for (ri, ci) in r.iter_mut().zip(&c) {
                *ri = t.step_towards(*ri, *ci);
            }
            if region.contains_point(&r) {
                return Some(r);
            }
        }
    }
    None
}

/// The centre of a box or ball (`None` for a polytope).
fn centre(region: &Region) -> Option<Vec<f64>> {
    match region {
        Region::Box(b) => Some(
            b.lo.iter()
                .zip(&b.hi)
                .map(|(l, h)| l + 0.5 * (h - l))
                .collect(),
        ),
        Region::Ball { center, .. } => Some(center.clone()),
        Region::Polytope { .. } => None,
    }
}

/// The radius at scale 1 along each input: box half-widths or ball radii.
fn unit_radius(region: &Region) -> Vec<f64> {
    match region {
        Region::Box(b) => b.lo.iter().zip(&b.hi).map(|(l, h)| 0.5 * (h - l)).collect(),
        Region::Ball { radius, .. } => radius.clone(),
        Region::Polytope { bbox, .. } => vec![0.0; bbox.dim()],
    }
}

/// The input set scaled about its centre by `s`, rounded outward.
fn scaled(region: &Region, s: f64) -> Region {
    match region {
        Region::Box(b) => {
            let c = centre(region).unwrap_or_default();
            let r = unit_radius(region);
            Region::Box(IBox::new(
                (0..b.dim())
                    .map(|i| ravel_base::num::sum_lower([c[i], -(s * r[i]).next_up()]))
                    .collect(),
                (0..b.dim())
                    .map(|i| sum_upper([c[i], (s * r[i]).next_up()]))
                    .collect(),
            ))
        }
        Region::Ball {
            center,
            radius,
            norm,
        } => Region::Ball {
            center: center.clone(),
            radius: radius.iter().map(|r| (s * r).next_up()).collect(),
            norm: *norm,
        },
        Region::Polytope { .. } => region.clone(),
    }
}

/// The smallest scale whose set holds `x` (its gauge about the centre),
/// rounded up.
fn gauge(region: &Region, x: &[f64]) -> f64 {
    let (c, r) = (centre(region).unwrap_or_default(), unit_radius(region));
    let d: Vec<f64> = (0..x.len())
        .map(|i| {
            let gap = (x[i] - c[i]).abs();
            if r[i] > 0.0 {
                gap / r[i]
            } else if gap > 0.0 {
                f64::INFINITY
            } else {
                0.0
            }
        })
        .collect();
    let len = match region {
        Region::Ball { norm: Norm::L1, .. } => d.iter().sum(),
        Region::Ball { norm: Norm::L2, .. } => d.iter().map(|v| v * v).sum::<f64>().sqrt(),
        _ => d.iter().fold(0.0f64, |a, v| a.max(*v)),
    };
    (len * (1.0 + 1e-12)).next_up()
}

/// Pull `x` into the region (a box: clamp; a ball: clamp, then towards the
/// centre); `None` for a polytope point outside.
fn project(region: &Region, x: Vec<f64>) -> Option<Vec<f64>> {
    let b = region.bbox();
    let mut x: Vec<f64> = x
        .iter()
        .enumerate()
        .map(|(i, v)| v.clamp(b.lo[i], b.hi[i]))
        .collect();
    if let Region::Ball { center, .. } = region {
        let g = gauge(region, &x);
        if g > 1.0 {
            let f = (1.0 - 1e-9) / g;
            for (xi, ci) in x.iter_mut().zip(center) {
                *xi = ci + (*xi - ci) * f;
            }
        }
    }
    region.contains_point(&x).then_some(x)
}

/// What an attack found.
struct Attack {
    /// A confirmed violation ([`confirm`]): an input of the stored model's
    /// type, in the set, violating the property as stored and in real
    /// arithmetic.
    witness: Option<Witness>,
    /// Without one: the first input tried (an `f64` point) that violates the
    /// real-arithmetic network rigorously but had no value of the input
    /// type near it that [`confirm`] accepts.
    real_only: Option<Vec<f64>>,
}

/// Search `region` for a confirmed violation: the sampled inputs first (the
/// worst ones start a coordinate search with halving steps). Every
/// candidate is first made a value of the network's input type inside the
/// region ([`representable`]). Deterministic.
fn attack(
    net: &Network,
    region: &Region,
    kind: &NetPropertyKind,
    label: Option<usize>,
    starts: &[Vec<f64>],
    evaluations: usize,
) -> Attack {
    let score = |x: &[f64]| violation(kind, label, &net.forward(x));
    let mut ranked: Vec<(f64, &Vec<f64>)> = starts.iter().map(|x| (score(x), x)).collect();
    ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
    let real_only = std::cell::RefCell::new(None);
    let found = |x: &[f64]| -> Option<Witness> {
        let stored = representable(region, net.input_type, x)
            .filter(|r| confirm(net, region, kind, label, r));
        if stored.is_none()
            && real_only.borrow().is_none()
            && violates_real(net, region, kind, label, x)
        {
            *real_only.borrow_mut() = Some(x.to_vec());
        }
        stored.map(|input| Witness {
            output: net.forward(&input),
            input,
        })
    };
    let done = |w: Witness| Attack {
        witness: Some(w),
        real_only: None,
    };
    for (v, x) in ranked.iter().take(8) {
        if *v >= 0.0 {
            if let Some(w) = found(x) {
                return done(w);
            }
        }
    }
    let b = region.bbox();
    let per_start = evaluations / ranked.len().clamp(1, 4);
    for (v0, x0) in ranked.iter().take(4) {
        let (mut x, mut v) = ((*x0).clone(), *v0);
        let mut step: Vec<f64> = (0..b.dim()).map(|i| 0.25 * (b.hi[i] - b.lo[i])).collect();
        let mut spent = 0;
        while spent < per_start && step.iter().any(|s| *s > 1e-12) {
            let mut improved = false;
            for i in 0..x.len() {
                for sign in [1.0, -1.0] {
                    let mut y = x.clone();
                    y[i] += sign * step[i];
                    let Some(y) = project(region, y) else {
                        continue;
                    };
                    spent += 1;
                    let w = score(&y);
                    if w > v {
                        (x, v) = (y, w);
                        improved = true;
                    }
                }
            }
            if v >= 0.0 {
                if let Some(w) = found(&x) {
                    return done(w);
                }
            }
            if !improved {
                for s in &mut step {
                    *s *= 0.5;
                }
            }
        }
    }
    Attack {
        witness: None,
        real_only: real_only.into_inner(),
    }
}

/// Sampled inputs of a region: its special points, then seeded random points.
fn sample_region(region: &Region, n: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = Rng::new(seed);
    let mut pts = region.special_points();
    pts.truncate(n);
    let mut tries = 0;
    while pts.len() < n && tries < 4 * n + 16 {
        tries += 1;
        if let Some(p) = region.sample(&mut || rng.unit()) {
            pts.push(p);
        }
    }
    pts
}

/// The CARRL choice for one observation `o`: certified bounds of every
/// action's value over the ball around `o` (the plan's propagator and
/// partitioner), the nominal and the robust action.
pub fn choose(
    plan: &NetworkPlan,
    o: &[f64],
    epsilon: &[f64],
    norm: Norm,
    ctl: &Control,
) -> ActionChoice {
    let m = plan.net.outputs();
    let region = Region::Ball {
        center: o.to_vec(),
        radius: epsilon.to_vec(),
        norm,
    };
    let dirs = ravel_analysis::shape::Shape::Box.directions(m, &[]);
    // samples only guide refinement: drawn only for a guided partitioner
    let (sampled, extent) = match plan.partitioner {
        Partitioner::Guided { .. } => {
            let pts = sample_region(&region, plan.samples, plan.seed);
            let outs: Vec<Vec<f64>> = pts.iter().map(|x| plan.net.forward(x)).collect();
            (
                support_of_points(&dirs, &outs),
                extent_of_points(&dirs, &outs),
            )
        }
        Partitioner::Uniform(_) => (vec![f64::NEG_INFINITY; 2 * m], vec![0.0; 2 * m]),
    };
    let b = bound_all(plan, &region, &dirs, &sampled, &extent, ctl);
    let upper: Vec<f64> = b.union[..m].to_vec();
    let lower: Vec<f64> = b.union[m..].iter().map(|v| -v).collect();
    let robust = argmax(&lower);
    let robust_optimal = b.issues.is_empty()
        && lower[robust].is_finite()
        && (0..m)
            .filter(|&j| j != robust)
            .all(|j| upper[j].is_finite() && lower[robust] >= upper[j]);
    ActionChoice {
        nominal: argmax(&plan.net.forward(o)),
        lower,
        upper,
        robust,
        robust_optimal,
    }
}

/// Execute a network plan: the robust action selections, then (with an
/// input set) Monte Carlo, the bounds of every shape and property row, the
/// verdicts and the radius searches.
pub fn execute_network(plan: &NetworkPlan, ctl: &Control) -> NetworkOutcome {
    let m = plan.net.outputs();
    let selections = select_actions(plan, ctl);
    let Some(input) = &plan.input else {
        // a spec that only selects actions: no input set, no properties
        return NetworkOutcome {
            output: OutputBounds {
                directions: DMatrix::zeros(0, m),
                offsets: Vec::new(),
                sampled: Vec::new(),
                bbox: None,
                sampled_bbox: None,
            },
            properties: Vec::new(),
            radii: Vec::new(),
            verdict: Verdict::Verified,
            partition: Vec::new(),
            partition_stop: Stop::Grid,
            split_activations: false,
            split_record: None,
            calls: 0,
            solver_issues: Vec::new(),
            overflow: false,
            samples_drawn: 0,
            selections,
        };
    };
    let mc = monte_carlo(plan, input);
    let shape_dirs = plan.shape.directions(m, &mc.outputs);
    let prop_rows: Vec<Vec<Vec<f64>>> = plan
        .properties
        .iter()
        .zip(&mc.labels)
        .map(|(p, l)| property_rows(&p.kind, *l, m))
        .collect();
    let rows = stack(&shape_dirs, &prop_rows, m);
    let sampled = support_of_points(&rows.dirs, &mc.outputs);
    let extent = extent_of_points(&rows.dirs, &mc.outputs);
    let (b, found, split_activations, split_record) = match &plan.partitioner {
        Partitioner::Guided {
            guide: Guide::Bab,
            budget,
        } => {
            let (root, issues) = cell_bounds(
                &plan.net,
                input,
                plan.propagator,
                plan.slope_steps,
                &rows.dirs,
            );
            let starts = attack_starts(plan, input, &mc);
            let s = bab::search(
                plan,
                input,
                &rows,
                root,
                issues,
                &starts,
                &mc.labels,
                &mc.may_falsify,
                budget,
                ctl,
                bab::queue_limit(
                    input.dim(),
                    rows.dirs.nrows() - rows.shape_rows,
                    plan.properties.len(),
                ),
            );
            (
                s.bounded,
                Some((s.witnesses, s.real_only)),
                s.activations,
                s.record.map(std::sync::Arc::new),
            )
        }
        _ => (
            bound_all(plan, input, &rows.dirs, &sampled, &extent, ctl),
            None,
            false,
            None,
        ),
    };
    let overflow = b.union.iter().any(|v| !v.is_finite());
    // past the time limit the closing attack does not start (on wide
    // inputs it alone can take seconds)
    let late = ctl.out_of_time();
    let properties = property_verdicts(plan, input, &mc, &b, &rows, found, late);
    let radii = plan
        .radii
        .iter()
        .map(|r| radius_search(plan, input, r, &mc.labels, mc.may_falsify[r.property], ctl))
        .collect();
    let verdict = if properties.iter().any(|p| p.status == Verdict::Falsified) {
        Verdict::Falsified
    } else if properties.iter().all(|p| p.status == Verdict::Verified) {
        Verdict::Verified
    } else {
        Verdict::Unsure
    };
    let shape_rows = 0..rows.shape_rows;
    let offsets: Vec<f64> = b.union[shape_rows.clone()].to_vec();
    let sampled_shape: Vec<f64> = sampled[shape_rows].to_vec();
    let bbox = bbox_of(&shape_dirs, &offsets);
    let sampled_bbox = bbox_of(&shape_dirs, &sampled_shape).filter(|_| !mc.outputs.is_empty());
    NetworkOutcome {
        output: OutputBounds {
            directions: shape_dirs,
            offsets,
            sampled: sampled_shape,
            bbox,
            sampled_bbox,
        },
        properties,
        radii,
        verdict,
        partition: b.cells.iter().map(|c| c.0.clone()).collect(),
        partition_stop: b.stop,
        split_activations,
        split_record,
        calls: b.calls,
        solver_issues: b.issues,
        overflow,
        samples_drawn: mc.inputs.len(),
        selections,
    }
}

/// Every select block's robust action choice per observation (past the
/// time limit: no bound, no claim). Progress counts the observations done
/// over every block (from any thread: only the count is shared).
fn select_actions(plan: &NetworkPlan, ctl: &Control) -> Vec<Selection> {
    let total: usize = plan.selects.iter().map(|s| s.observations.len()).sum();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let report = || {
        let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        (ctl.progress)(crate::execute::Progress {
            phase: crate::execute::Phase::Observations,
            done: k,
            total: Some(total),
        });
    };
    plan.selects
        .iter()
        .map(|s| Selection {
            name: s.name.clone(),
            epsilon: s.epsilon.clone(),
            observations: s.observations.clone(),
            choices: map_ordered(&s.observations, ctl.threads, &|o: &Vec<f64>| {
                report();
                if ctl.out_of_time() {
                    let m = plan.net.outputs();
                    let nominal = argmax(&plan.net.forward(o));
                    ActionChoice {
                        lower: vec![f64::NEG_INFINITY; m],
                        upper: vec![f64::INFINITY; m],
                        nominal,
                        robust: nominal,
                        robust_optimal: false,
                    }
                } else {
                    choose(plan, o, &s.epsilon, s.norm, ctl)
                }
            }),
        })
        .collect()
}

/// What Monte Carlo of the input set gives the rest of the execution.
struct MonteCarlo {
    /// The sampled inputs.
    inputs: Vec<Vec<f64>>,
    /// Their outputs.
    outputs: Vec<Vec<f64>>,
    /// Per property: the robustness label (given, or the centre's).
    labels: Vec<Option<usize>>,
    /// Per property: whether a violation can be a counterexample (a
    /// violation of "the centre's label" only when that label is certain).
    may_falsify: Vec<bool>,
}

/// Sample the input set; the properties' labels and which may be falsified.
fn monte_carlo(plan: &NetworkPlan, input: &Region) -> MonteCarlo {
    let inputs = sample_region(input, plan.samples, plan.seed);
    let outputs: Vec<Vec<f64>> = inputs.iter().map(|x| plan.net.forward(x)).collect();
    // robustness labels: the centre's when not given
    let nominal = centre(input).map(|c| argmax(&plan.net.forward(&c)));
    // A violation of "the centre's label" only counts when the centre's label
    // is certain: an outward-rounded enclosure of f(centre) has it strictly
    // largest (an f64 argmax of nearly tied outputs may not be the exact one).
    let centre_certain = match (centre(input), nominal) {
        (Some(c), Some(k)) => strictly_largest(&plan.net, &c, k),
        _ => false,
    };
    let may_falsify: Vec<bool> = plan
        .properties
        .iter()
        .map(|p| !matches!(p.kind, NetPropertyKind::Robust(None)) || centre_certain)
        .collect();
    let labels: Vec<Option<usize>> = plan
        .properties
        .iter()
        .map(|p| match p.kind {
            NetPropertyKind::Robust(Some(k)) => Some(k),
            NetPropertyKind::Robust(None) => nominal,
            _ => None,
        })
        .collect();
    MonteCarlo {
        inputs,
        outputs,
        labels,
        may_falsify,
    }
}

/// A search's findings per property: confirmed counterexamples and
/// real-arithmetic-only violations.
type Found = (Vec<Option<Witness>>, Vec<Option<Vec<f64>>>);

/// Each property's verdict: VERIFIED from the certified margin (no solver
/// issue), FALSIFIED from a confirmed counterexample of the search (`found`)
/// or of the closing attack (not started when `late`: past the time
/// limit), UNSURE otherwise.
fn property_verdicts(
    plan: &NetworkPlan,
    input: &Region,
    mc: &MonteCarlo,
    b: &Bounded,
    rows: &Rows,
    found: Option<Found>,
    late: bool,
) -> Vec<NetPropertyResult> {
    let (mut witnesses, mut real) = found.unwrap_or_default();
    let m = plan.net.outputs();
    let mut properties = Vec::new();
    for (k, p) in plan.properties.iter().enumerate() {
        let kind = match p.kind {
            NetPropertyKind::Require(_) => NetKind::Require,
            NetPropertyKind::Avoid(_) => NetKind::Avoid,
            NetPropertyKind::Robust(_) => NetKind::Robust,
        };
        let label = mc.labels[k];
        let (margin, label_margins) = certified_margin(&p.kind, label, m, b, &rows.ranges[k]);
        let mut result = NetPropertyResult {
            name: p.name.clone(),
            kind,
            status: Verdict::Unsure,
            margin,
            label,
            label_margins,
            counterexample: None,
            real_only: None,
        };
        let searched = witnesses.get_mut(k).and_then(Option::take);
        if proves(&p.kind, margin) && b.issues.is_empty() {
            result.status = Verdict::Verified;
        } else if let Some(w) = searched {
            // confirmed by the search (`confirm`, as every counterexample)
            result.status = Verdict::Falsified;
            result.margin = -violation(&p.kind, label, &w.output).max(0.0);
            result.counterexample = Some(w);
        } else if mc.may_falsify[k] && !late {
            let found = attack(&plan.net, input, &p.kind, label, &mc.inputs, 2000);
            if let Some(w) = found.witness {
                result.status = Verdict::Falsified;
                result.margin = -violation(&p.kind, label, &w.output).max(0.0);
                result.counterexample = Some(w);
            } else {
                result.real_only = found
                    .real_only
                    .or_else(|| real.get_mut(k).and_then(Option::take));
            }
        }
        properties.push(result);
    }
    properties
}

/// Where the search's opening attack starts: the set's centre, then the
/// sampled inputs, most violating (of any property) first, at most 16.
fn attack_starts(plan: &NetworkPlan, input: &Region, mc: &MonteCarlo) -> Vec<Vec<f64>> {
    let score = |y: &Vec<f64>| {
        plan.properties
            .iter()
            .zip(&mc.labels)
            .map(|(p, l)| violation(&p.kind, *l, y))
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let mut ranked: Vec<(f64, &Vec<f64>)> = mc.outputs.iter().map(score).zip(&mc.inputs).collect();
    ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
    centre(input)
        .into_iter()
        .chain(ranked.into_iter().take(15).map(|(_, x)| x.clone()))
        .collect()
}

/// Whether an outward-rounded enclosure of `f(x)` has output `k` strictly
/// larger than every other output.
fn strictly_largest(net: &Network, x: &[f64], k: usize) -> bool {
    let a = Relaxation::new(net, &IBox::point(x), Mode::Ibp);
    if !a.is_finite() {
        return false;
    }
    let y = a.output_box(Mode::Ibp);
    (0..y.dim()).filter(|&j| j != k).all(|j| {
        let mut d = vec![0.0; y.dim()];
        d[j] = 1.0;
        d[k] = -1.0;
        dot_box_upper(&d, &y.lo, &y.hi) < 0.0
    })
}

/// The first index of the largest value.
fn argmax(y: &[f64]) -> usize {
    let mut best = 0;
    for (j, v) in y.iter().enumerate() {
        if *v > y[best] {
            best = j;
        }
    }
    best
}

/// The box described by the first `2m` offsets when the directions start with `±e_i`.
fn bbox_of(dirs: &DMatrix<f64>, offsets: &[f64]) -> Option<IBox> {
    let m = dirs.ncols();
    let is_box = dirs.nrows() >= 2 * m
        && (0..m).all(|i| {
            (0..m).all(|j| {
                dirs[(i, j)] == if i == j { 1.0 } else { 0.0 }
                    && dirs[(m + i, j)] == if i == j { -1.0 } else { 0.0 }
            })
        });
    is_box.then(|| {
        IBox::new(
            offsets[m..2 * m].iter().map(|v| -v).collect(),
            offsets[..m].to_vec(),
        )
    })
}

/// The certified/attacked bracket of one radius search.
fn radius_search(
    plan: &NetworkPlan,
    input: &Region,
    r: &RadiusSpec,
    labels: &[Option<usize>],
    may_falsify: bool,
    ctl: &Control,
) -> RadiusResult {
    let m = plan.net.outputs();
    let p = &plan.properties[r.property];
    let label = labels[r.property];
    let rows = stack(
        &DMatrix::zeros(0, m),
        &[property_rows(&p.kind, label, m)],
        m,
    );
    let mut analyses = 0;
    let out_of_time = || ctl.out_of_time();
    let mut certifies = |s: f64| -> bool {
        analyses += 1;
        let region = scaled(input, s);
        let pts = sample_region(&region, plan.samples.min(1000), plan.seed);
        let outs: Vec<Vec<f64>> = pts.iter().map(|x| plan.net.forward(x)).collect();
        let sampled = support_of_points(&rows.dirs, &outs);
        let extent = extent_of_points(&rows.dirs, &outs);
        let b = bound_all(plan, &region, &rows.dirs, &sampled, &extent, ctl);
        let (margin, _) = certified_margin(&p.kind, label, m, &b, &rows.ranges[0]);
        proves(&p.kind, margin) && b.issues.is_empty()
    };
    // certified: bisection on the largest proven scale
    let certified = if certifies(r.max) {
        Some(r.max)
    } else if !certifies(0.0) {
        None
    } else {
        let (mut lo, mut hi) = (0.0, r.max);
        // at most 64 halvings: a tolerance below f64's spacing ends when
        // the midpoint can no longer be told from an end
        for _ in 0..64 {
            let mid = lo + 0.5 * (hi - lo);
            if hi - lo <= r.tolerance || mid <= lo || mid >= hi || out_of_time() {
                break;
            }
            if certifies(mid) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Some(lo)
    };
    // attacked: the smallest gauge of a confirmed violation
    let attack_at = |s: f64, seed: u64| -> Option<Witness> {
        let region = scaled(input, s);
        let pts = sample_region(&region, plan.samples.clamp(64, 1000), seed);
        attack(&plan.net, &region, &p.kind, label, &pts, 2000).witness
    };
    let mut attacked: Option<(f64, Witness)> = None;
    if certified != Some(r.max) && may_falsify {
        if let Some(w) = attack_at(r.max, plan.seed) {
            attacked = Some((gauge(input, &w.input), w));
            let mut lo = certified.unwrap_or(0.0);
            let mut round = 1;
            while let Some((hi, _)) = &attacked {
                let mid = lo + 0.5 * (hi - lo);
                if hi - lo <= r.tolerance || mid <= lo || mid >= *hi || round > 64 || out_of_time()
                {
                    break;
                }
                match attack_at(mid, plan.seed.wrapping_add(round)) {
                    Some(w) => {
                        let g = gauge(input, &w.input);
                        if g < *hi {
                            attacked = Some((g, w));
                        } else {
                            lo = mid;
                        }
                    }
                    None => lo = mid,
                }
                round += 1;
            }
        }
    }
    RadiusResult {
        name: r.name.clone(),
        property: p.name.clone(),
        certified,
        attacked,
        max: r.max,
        tolerance: r.tolerance,
        unit: unit_radius(input),
        analyses,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DVector;
    use ravel_base::num::dot_box_lower;

    /// Past its byte limit the split record drops everything it holds and
    /// takes nothing more: a certificate's evidence is then unsupported,
    /// and the memory it held is freed.
    #[test]
    fn the_split_record_is_dropped_past_its_limit() {
        let mut r = SplitRecord {
            nodes: vec![SplitNode::default(); 3],
            ..SplitRecord::default()
        };
        let quarter = SplitRecord::MAX_BYTES / 16;
        for _ in 0..4 {
            assert!(r.charge(quarter));
        }
        assert!(r.dropped.is_none() && r.nodes.len() == 3);
        assert!(!r.charge(1));
        assert!(r.dropped.is_some() && r.nodes.is_empty() && r.neurons.is_empty());
        assert!(!r.charge(0));
        assert!(!r.charge(usize::MAX));
    }

    #[test]
    fn candidates_become_float32_values_inside_the_set() {
        let t = InputType::F32;
        // the upper face 0.30000003 rounds to a float32 above it: moved down
        let b = Region::Box(IBox::new(vec![0.1], vec![0.30000003]));
        assert_eq!(
            representable(&b, t, &[0.30000003]),
            Some(vec![f64::from(0.3f32)])
        );
        // no float32 in [0.30000002, 0.30000004]: nothing
        let none = Region::Box(IBox::new(vec![0.30000002], vec![0.30000004]));
        assert_eq!(representable(&none, t, &[0.30000003]), None);
        // float64: unchanged
        assert_eq!(
            representable(&b, InputType::F64, &[0.30000003]),
            Some(vec![0.30000003])
        );
        // a ball point just inside in f64 whose rounding leaves the ball
        // steps towards the centre
        let ball = Region::Ball {
            center: vec![0.0, 0.0],
            radius: vec![0.1, 0.1],
            norm: Norm::L2,
        };
        let edge = 0.1 / 2f64.sqrt() * (1.0 - 1e-15);
        let r = representable(&ball, t, &[edge, edge]).expect("a float32 inside");
        assert!(ball.contains_point(&r) && r.iter().all(|v| t.represents(*v)));
    }

    /// The fixed-order float32 evaluation lies in the enclosure of every
    /// order, and so does the reverse order, on random networks.
    #[test]
    fn the_stored_enclosure_holds_every_summation_order() {
        let mut rng = Rng::new(9);
        for case in 0..300 {
            let act = [Activation::Relu, Activation::Tanh, Activation::Sigmoid][case % 3];
            let widths = [2, 1 + rng.below(10), 1 + rng.below(10), 3];
            let mut layers = Vec::new();
            for (k, pair) in widths.windows(2).enumerate() {
                let s = 10f64.powi(rng.below(7) as i32 - 3);
                layers.push(Layer::Affine {
                    w: DMatrix::from_fn(pair[1], pair[0], |_, _| s * rng.normal()),
                    b: DVector::from_fn(pair[1], |_, _| s * rng.normal()),
                });
                if k + 2 < widths.len() {
                    layers.push(Layer::Act(act));
                }
            }
            let net = Network::new(2, layers);
            let x: Vec<f64> = (0..2).map(|_| f64::from(rng.normal() as f32)).collect();
            let e = stored_enclosure(&net, &x).expect("no overflow at these sizes");
            let mut rev: Vec<f32> = x.iter().map(|v| *v as f32).collect();
            for layer in &net.layers {
                match layer {
                    Layer::Affine { w, b } => {
                        rev = (0..w.nrows())
                            .map(|i| {
                                let mut s = b[i] as f32;
                                for j in (0..w.ncols()).rev() {
                                    s = (w[(i, j)] as f32).mul_add(rev[j], s);
                                }
                                s
                            })
                            .collect();
                    }
                    Layer::Act(a) => rev
                        .iter_mut()
                        .for_each(|v| *v = a.eval(f64::from(*v)) as f32),
                }
            }
            let rev: Vec<f64> = rev.into_iter().map(f64::from).collect();
            for y in [net.forward_stored(&x), rev] {
                assert!(e.contains_point(&y), "case {case}: {y:?} outside {e:?}");
            }
        }
    }
    /// The interval enclosure `stored_enclosure` used before the affine
    /// forms: a reference for their width (ReLU networks only).
    fn interval_enclosure(net: &Network, x: &[f64]) -> IBox {
        let t = net.input_type;
        let (u, eta) = (t.unit_roundoff(), t.min_positive());
        let (mut lo, mut hi) = (x.to_vec(), x.to_vec());
        for layer in &net.layers {
            match layer {
                Layer::Affine { w, b } => {
                    let n = w.ncols();
                    let g = gamma_of(n + 1, u).expect("small layers");
                    let mag: Vec<f64> = lo
                        .iter()
                        .zip(&hi)
                        .map(|(l, h)| l.abs().max(h.abs()))
                        .collect();
                    let (mut nl, mut nh) = (Vec::new(), Vec::new());
                    for i in 0..w.nrows() {
                        let row: Vec<f64> = (0..n).map(|j| t.round(w[(i, j)])).collect();
                        let bias = t.round(b[i]);
                        let abs_row: Vec<f64> = row.iter().map(|v| v.abs()).collect();
                        let abs_sum = sum_upper([dot_box_upper(&abs_row, &mag, &mag), bias.abs()]);
                        let err = sum_upper([(g * abs_sum).next_up(), (n as f64 * eta).next_up()]);
                        nh.push(sum_upper([dot_box_upper(&row, &lo, &hi), bias, err]));
                        nl.push(sum_lower([dot_box_lower(&row, &lo, &hi), bias, -err]));
                    }
                    (lo, hi) = (nl, nh);
                }
                Layer::Act(a) => {
                    assert_eq!(*a, Activation::Relu);
                    lo.iter_mut().for_each(|v| *v = v.max(0.0));
                    hi.iter_mut().for_each(|v| *v = v.max(0.0));
                }
            }
        }
        IBox::new(lo, hi)
    }

    /// How a float32 runtime may sum a dot product with its bias.
    #[derive(Clone, Copy)]
    enum Order {
        /// Left to right, the bias last.
        Ascending,
        /// A random binary tree over the rounded products and the bias.
        Tree,
        /// A random sequence of fused multiply-adds, the bias at a random place.
        Fma,
    }

    /// The network in float32, each dot product summed in `order`.
    fn eval_f32(net: &Network, x: &[f64], order: Order, rng: &mut Rng) -> Vec<f64> {
        let mut h: Vec<f32> = x.iter().map(|v| *v as f32).collect();
        for layer in &net.layers {
            match layer {
                Layer::Affine { w, b } => {
                    h = (0..w.nrows())
                        .map(|i| {
                            let bias = b[i] as f32;
                            let wi = |j: usize| w[(i, j)] as f32;
                            match order {
                                Order::Ascending => {
                                    (0..w.ncols()).fold(0.0f32, |s, j| s + wi(j) * h[j]) + bias
                                }
                                Order::Tree => {
                                    let mut terms: Vec<f32> =
                                        (0..w.ncols()).map(|j| wi(j) * h[j]).collect();
                                    terms.push(bias);
                                    while terms.len() > 1 {
                                        let a = terms.swap_remove(rng.below(terms.len()));
                                        let k = rng.below(terms.len());
                                        terms[k] += a;
                                    }
                                    terms[0]
                                }
                                Order::Fma => {
                                    let mut idx: Vec<usize> = (0..=w.ncols()).collect();
                                    for k in (1..idx.len()).rev() {
                                        idx.swap(k, rng.below(k + 1));
                                    }
                                    idx.iter().fold(0.0f32, |s, &j| {
                                        if j == w.ncols() {
                                            s + bias
                                        } else {
                                            wi(j).mul_add(h[j], s)
                                        }
                                    })
                                }
                            }
                        })
                        .collect();
                }
                Layer::Act(a) => h.iter_mut().for_each(|v| *v = a.eval(f64::from(*v)) as f32),
            }
        }
        h.into_iter().map(f64::from).collect()
    }

    /// A random ReLU network of the given widths with float32 weights of
    /// scale about `1/√fan-in`.
    fn relu_net(widths: &[usize], rng: &mut Rng) -> Network {
        let mut layers = Vec::new();
        for (k, pair) in widths.windows(2).enumerate() {
            let s = 1.5 / (pair[0] as f64).sqrt();
            let f = |v: f64| f64::from(v as f32);
            layers.push(Layer::Affine {
                w: DMatrix::from_fn(pair[1], pair[0], |_, _| f(s * rng.normal())),
                b: DVector::from_fn(pair[1], |_, _| f(0.1 * rng.normal())),
            });
            if k + 2 < widths.len() {
                layers.push(Layer::Act(Activation::Relu));
            }
        }
        Network::new(widths[0], layers)
    }

    /// Every float32 evaluation tried — random summation trees, random
    /// orders of fused multiply-adds, left to right — lies in the affine
    /// enclosure, on random ReLU networks.
    #[test]
    fn the_affine_enclosure_holds_random_summation_orders() {
        let mut rng = Rng::new(17);
        for case in 0..60 {
            let widths = [
                3,
                2 + rng.below(12),
                2 + rng.below(12),
                2 + rng.below(12),
                2,
            ];
            let net = relu_net(&widths, &mut rng);
            let x: Vec<f64> = (0..3).map(|_| f64::from(rng.normal() as f32)).collect();
            let e = stored_enclosure(&net, &x).expect("no overflow at these sizes");
            for k in 0..60 {
                let order = [Order::Ascending, Order::Tree, Order::Fma][k % 3];
                let y = eval_f32(&net, &x, order, &mut rng);
                assert!(e.contains_point(&y), "case {case}: {y:?} outside {e:?}");
            }
        }
    }

    /// A network whose float32 evaluation left to right reaches nearly
    /// the worst case of the error bound in both affine layers: `1` plus
    /// `k` halves of its unit in the last place, each rounded away. The
    /// enclosure must hold it (a layer's error halved, or its symbol
    /// dropped, would not).
    #[test]
    fn the_affine_enclosure_holds_the_worst_case_order() {
        let k = 40;
        let tiny = 2f64.powi(-24);
        let mut x = vec![tiny; k + 1];
        x[0] = 1.0;
        // layer 1: h₀ = Σ xⱼ, hⱼ = xⱼ; layer 2: Σ hⱼ
        let w1 = DMatrix::from_fn(
            k + 1,
            k + 1,
            |i, j| {
                if i == 0 || i == j {
                    1.0
                } else {
                    0.0
                }
            },
        );
        let layers = vec![
            Layer::Affine {
                w: w1,
                b: DVector::zeros(k + 1),
            },
            Layer::Act(Activation::Relu),
            Layer::Affine {
                w: DMatrix::from_element(1, k + 1, 1.0),
                b: DVector::zeros(1),
            },
        ];
        let net = Network::new(k + 1, layers);
        let e = stored_enclosure(&net, &x).expect("finite");
        let y = eval_f32(&net, &x, Order::Ascending, &mut Rng::new(1));
        assert_eq!(y, vec![1.0]);
        assert!(e.contains_point(&y), "{y:?} outside {e:?}");
        // the exact value is 1 + 2k·tiny, the bound of each layer's error
        // about (k + 2)·tiny: the enclosure reaches barely below 1
        assert!(e.lo[0] > 1.0 - 8.0 * tiny, "{e:?}");
    }

    /// On a 5 → 6×50 → 5 ReLU network the affine enclosure is at least ten
    /// times narrower than the interval one.
    #[test]
    fn the_affine_enclosure_is_tighter_than_intervals() {
        let mut rng = Rng::new(5);
        let mut widths = vec![5];
        widths.extend([50; 6]);
        widths.push(5);
        for _ in 0..5 {
            let net = relu_net(&widths, &mut rng);
            let x: Vec<f64> = (0..5).map(|_| f64::from(rng.normal() as f32)).collect();
            let e = stored_enclosure(&net, &x).expect("finite");
            let old = interval_enclosure(&net, &x);
            let width = |b: &IBox| (0..5).map(|i| b.hi[i] - b.lo[i]).fold(0.0, f64::max);
            let (new_w, old_w) = (width(&e), width(&old));
            assert!(10.0 * new_w <= old_w, "{new_w} vs {old_w}");
        }
    }
}
