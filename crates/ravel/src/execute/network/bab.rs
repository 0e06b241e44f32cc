//! Branch and bound over a network spec's input set (`partitioner bab`).
//!
//! The search keeps a queue of open subproblems (cells of the input set,
//! each with certified bounds of the properties' rows over it) and always
//! works on the cells whose worst property margin is lowest:
//!
//! 1. **Attack first.** Projected gradient ascent on each falsifiable
//!    property's violation, from the centre and the worst sampled inputs,
//!    before any bound is computed ([`pgd`]); a confirmed counterexample
//!    settles the property at once. When splitting inputs, once
//!    [`LOCAL_CALLS`] cells have been bounded, a seeded derivative-free
//!    local search ([`local`]: random samples of the cells still open,
//!    then shrinking-box random walks from the best of them), which finds
//!    the thin violating regions the gradient misses (ACAS Xu 5_3
//!    property 2 and 1_9 property 7, at the input box's faces); again with
//!    twice the samples each time the count of cells bounded doubles, so
//!    it costs about a fixed share of the time (10–20 % on ACAS Xu).
//! 2. **Bound in batches.** Up to [`BATCH`] cells are taken from the queue
//!    at a time, each is split in two along one input, and the children are
//!    bounded together (CROWN's batched pass over the threads, or the
//!    spec's propagator cell by cell). A child's bounds are intersected with
//!    its parent's (both hold on the child). Late in the search (from
//!    [`DUAL_MADE`] subproblems made), on a box input set and a network of
//!    affine layers and ReLUs, the children still open after CROWN are also
//!    bounded by the optimised Lagrangian dual of [`dual::optimise`] over
//!    their box ([`tighten`]; certified, [`DUAL_STEPS`] steps from CROWN's
//!    slopes), and each row keeps the smaller bound: on ACAS Xu it closes
//!    about a quarter of them, and proves 4_2 property 2 (71 s; not proved
//!    in 116 s without it) and 1_1 property 5 (2.5 s; 60 s without).
//! 3. **Aim the split.** With at most [`LOOK_AHEAD_DIMS`] inputs, every
//!    input is tried: both children of every candidate split are bounded
//!    in the batch, and the split kept is the one whose children's open
//!    margins sum highest (a proved child counts 0; ties: the better worse
//!    child), unless no candidate gains [`STALL`] of the parent's margin:
//!    then the widest input (rounding noise would otherwise keep halving
//!    one thin input). With more inputs, the input with the largest *smear* for the
//!    cell's worst property row: the gradient of that row at the cell's
//!    centre times the cell's width along the input. Measured on ACAS Xu
//!    (docs/language.md): look-ahead decided all 15 property-1 instances
//!    tried within 30 s where the smear decided 8 and the widest input 1.
//! 4. **Falsify every child.** A child that is not proved is attacked with
//!    a few gradient steps from its centre; a candidate becomes a
//!    counterexample only through [`confirm`](super::confirm), as every
//!    other counterexample of a network spec.
//! 5. **Stop as soon as every property is settled**: each one proved on
//!    every cell, or falsified. Otherwise at the call budget, the run's time
//!    limit, or when the queue reaches its memory limit ([`queue_limit`]);
//!    the open cells keep the bounds they have (valid on them), so the
//!    verdict is then UNSURE for the properties still open.
//!
//! The proved cells and the open ones together are the final partition:
//! the certificate's evidence is that partition, re-checked cell by cell as
//! for every other partitioner. Only the properties' rows are bounded per
//! cell; the output set's shape rows keep the whole input set's bounds.
//!
//! Splitting is on inputs only: complete for continuous networks on the
//! closure of the property (a violation with positive margin is found on a
//! small enough cell, a strict proof holds on small enough cells), which is
//! what input dimensions of a few (ACAS Xu's 5) make practical. Splitting
//! on ReLU activations, which high-dimensional inputs need, is not
//! implemented yet.

use std::collections::BinaryHeap;

mod activations;
mod local;

use nalgebra::DMatrix;

use super::{
    cell_bounds, confirm, map_ordered, own_slopes, project, representable, violates_real,
    violation, Bounded, Rows, Witness,
};
use crate::execute::Control;
use crate::ir::{Branching, NetProperty, NetPropertyKind};
use crate::lower::NetworkPlan;
use ravel_analysis::batch;
use ravel_analysis::dual;
use ravel_analysis::issue::Issue;
use ravel_analysis::partition::{Budget, Stop};
use ravel_analysis::sets::{IBox, Region};

/// Cells taken from the queue per round (their children are bounded together).
pub const BATCH: usize = 64;

/// Memory the queue of open cells may hold, in bytes.
pub const QUEUE_BYTES: usize = 1 << 30;

/// The most inputs for which [`Branching::LookAhead`] tries every split.
pub const LOOK_AHEAD_DIMS: usize = 8;

/// The least gain, relative to the parent's margin, that makes a
/// look-ahead option better than splitting the widest input.
const STALL: f64 = 1e-3;

/// Gradient steps per start of the opening attack.
const PGD_STEPS: usize = 50;

/// Gradient steps of the attack on each open child.
const CHILD_STEPS: usize = 4;

/// Samples of the first stage of the local search ([`local`]); each
/// later stage draws twice as many as the one before, up to
/// [`LOCAL_MAX_SAMPLES`].
const LOCAL_SAMPLES: usize = 4096;

/// The most samples of one stage of the local search.
const LOCAL_MAX_SAMPLES: usize = 1 << 18;

/// Starts walked by the first stage of the local search (the later ones:
/// [`LOCAL_STARTS`]).
const LOCAL_FIRST_STARTS: usize = 4;

/// Starts walked by every later stage of the local search.
const LOCAL_STARTS: usize = 16;

/// Subproblems made before the children still open after CROWN are
/// bounded by the optimised Lagrangian dual too ([`tighten`]).
const DUAL_MADE: usize = 2000;

/// Ascent steps of the dual bound of a late child.
const DUAL_STEPS: usize = 30;

/// Cells bounded before the first stage of the local search (an instance
/// decided sooner does not pay for it); each later stage starts when the
/// count has doubled again, so the search's share of the time stays about
/// constant.
const LOCAL_CALLS: usize = 1000;

/// The most open cells the queue may hold for inputs of dimension `n` and
/// `rows` bounded rows per cell (each cell's box, bounds and flags).
pub fn queue_limit(n: usize, rows: usize, properties: usize) -> usize {
    let bytes = 2 * n * 8 + rows * 8 + properties + 96;
    (QUEUE_BYTES / bytes).max(1)
}

/// What the search found: the final cells with their bounds, and per
/// property a confirmed counterexample or a real-arithmetic-only violation.
pub(super) struct Searched {
    pub bounded: Bounded,
    /// The subproblems made: the root, then two per split (what the
    /// budget `calls` counts; `bounded.calls` counts every cell bounded).
    /// Read by the tests, which check the budget by it.
    #[cfg_attr(not(test), allow(dead_code))]
    pub made: usize,
    pub witnesses: Vec<Option<Witness>>,
    pub real_only: Vec<Option<Vec<f64>>>,
    /// Whether the search split ReLU activations ([`activations`]).
    pub activations: bool,
    /// What it proved, for a certificate (a search on activations only).
    pub record: Option<super::SplitRecord>,
}

/// A child of a split: its box, its bounds, the issues met bounding it,
/// and whether it was bounded (not: the time ran out, it has its parent's).
type Child = (IBox, Vec<f64>, Vec<Issue>, bool);

/// An open cell: its box, the bounds of the properties' rows over it, and
/// its worst open margin (the queue's key: lowest first).
struct Node {
    cell: IBox,
    bounds: Vec<f64>,
    worst: f64,
}

impl PartialEq for Node {
    fn eq(&self, other: &Self) -> bool {
        self.worst.total_cmp(&other.worst).is_eq()
    }
}
impl Eq for Node {}
impl PartialOrd for Node {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Node {
    /// The max-heap pops the lowest margin first.
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        other.worst.total_cmp(&self.worst)
    }
}

/// The certified margin of property `kind` on one cell from the bounds `b`
/// of its rows (`range` indexes them), and the row that decides it (the
/// one a split should improve). Positive proves it on the cell (`≥ 0` for
/// `require`). NaN counts as no bound.
pub(super) fn cell_margin(
    kind: &NetPropertyKind,
    b: &[f64],
    range: &std::ops::Range<usize>,
) -> (f64, usize) {
    let clean = |v: f64| if v.is_nan() { f64::NEG_INFINITY } else { v };
    match kind {
        NetPropertyKind::Require(p) => {
            let mut worst = (f64::INFINITY, range.start);
            for ((_, h), k) in p.rows.iter().zip(range.clone()) {
                let v = clean(h - b[k]);
                if v < worst.0 {
                    worst = (v, k);
                }
            }
            worst
        }
        NetPropertyKind::Avoid(members) => {
            let mut worst = (f64::INFINITY, range.start);
            let mut at = range.start;
            for p in members {
                let mut best = (f64::NEG_INFINITY, at);
                for (_, h) in &p.rows {
                    let v = clean(-b[at] - h);
                    if v > best.0 {
                        best = (v, at);
                    }
                    at += 1;
                }
                if best.0 < worst.0 {
                    worst = best;
                }
            }
            worst
        }
        NetPropertyKind::Robust(_) => {
            let mut worst = (f64::INFINITY, range.start);
            for k in range.clone() {
                let v = clean(-b[k]);
                if v < worst.0 {
                    worst = (v, k);
                }
            }
            worst
        }
    }
}

/// Why a search with `queued` open subproblems stops before its next
/// round, if it does: every property settled, the time limit, the call
/// budget (`made` subproblems so far), or the queue's memory `limit`.
fn halt(
    settled: &[bool],
    late: bool,
    made: usize,
    budget: &Budget,
    queued: usize,
    limit: usize,
) -> Option<Stop> {
    if settled.iter().all(|s| *s) {
        Some(Stop::Decided)
    } else if late {
        Some(Stop::Time)
    } else if made >= budget.calls {
        Some(Stop::Calls)
    } else if queued >= limit {
        Some(Stop::Queue)
    } else {
        None
    }
}

/// A look-ahead option's score: whether both children were bounded, the
/// sum of their open margins (a proved child counts 0), the worse one.
type Score = (bool, f64, f64);

/// The look-ahead option to keep among `options` (each its [`Score`] and
/// the split input's width relative to the input set) for a parent of
/// margin `parent`: the best score (lexicographic, NaN never wins); but
/// when that gains no more than [`STALL`] of the parent's margin over the
/// parent (the scores then differ by rounding noise, and following it
/// keeps halving one thin input around a cell where two `avoid` rows
/// cross), the widest input among the options bounded on both sides.
fn pick(options: &[(Score, f64)], parent: f64) -> usize {
    let mut at = 0;
    let Some(&(mut best, _)) = options.first() else {
        return 0;
    };
    for (o, &(s, _)) in options.iter().enumerate().skip(1) {
        if (s.0, s.1, s.2) > (best.0, best.1, best.2) && !(s.1.is_nan() || s.2.is_nan()) {
            (at, best) = (o, s);
        }
    }
    let pw = parent.min(0.0);
    if options.len() > 1 && best.0 && best.1 - 2.0 * pw <= STALL * -pw {
        let mut widest = (at, options[at].1);
        for (o, &(s, r)) in options.iter().enumerate() {
            if s.0 && r > widest.1 {
                widest = (o, r);
            }
        }
        at = widest.0;
    }
    at
}

/// Whether margin `v` proves `kind` on a cell.
fn proved(kind: &NetPropertyKind, v: f64) -> bool {
    super::proves(kind, v)
}

/// The part of `region` inside the box `c` (a box cell of a box, the
/// polytope's rows kept; a ball's cell is covered by its box).
fn cell_region(region: &Region, c: &IBox) -> Region {
    match region {
        Region::Polytope { rows, .. } => Region::Polytope {
            bbox: c.clone(),
            rows: rows.clone(),
        },
        _ => Region::Box(c.clone()),
    }
}

/// What the search reads, fixed for the run.
struct Ctx<'a> {
    plan: &'a NetworkPlan,
    region: &'a Region,
    /// The property rows only (the stacked rows past the shape's).
    pdirs: DMatrix<f64>,
    /// Per property: its rows, shifted to index `pdirs`.
    ranges: Vec<std::ops::Range<usize>>,
    labels: &'a [Option<usize>],
    may_falsify: &'a [bool],
    ctl: &'a Control<'a>,
}

impl Ctx<'_> {
    fn props(&self) -> &[NetProperty] {
        &self.plan.properties
    }

    /// The worst margin over the properties still open on a cell with
    /// bounds `b` (`+∞`: nothing open), and the decisive row of it.
    fn worst(&self, b: &[f64], settled: &[bool]) -> (f64, Option<usize>) {
        let mut w = (f64::INFINITY, None);
        for (k, p) in self.props().iter().enumerate() {
            if settled[k] {
                continue;
            }
            let (v, row) = cell_margin(&p.kind, b, &self.ranges[k]);
            if !proved(&p.kind, v) && v < w.0 {
                w = (v, Some(row));
            }
        }
        if w.1.is_none() {
            w.0 = f64::INFINITY;
        }
        w
    }

    /// Certified bounds of the property rows over each cell (`+∞` where
    /// none), and the solver issues met; `None` for the cells not bounded
    /// because `late()` said the time was up before their group started
    /// (so a round of slow bounds does not overshoot the time limit by
    /// more than one group per thread).
    #[allow(clippy::type_complexity)]
    fn bound(
        &self,
        cells: &[IBox],
        late: &(dyn Fn() -> bool + Sync),
    ) -> Vec<Option<(Vec<f64>, Vec<Issue>)>> {
        let plan = self.plan;
        let threads = self.ctl.threads;
        let one = |c: &IBox| {
            cell_bounds(
                &plan.net,
                &cell_region(self.region, c),
                plan.propagator,
                plan.slope_steps,
                &self.pdirs,
            )
        };
        if let (Some(mode), Region::Box(_)) =
            (own_slopes(plan.propagator, plan.slope_steps), self.region)
        {
            // groups fixed by the cell count, never by the threads: a
            // batched pass's bounds may depend on its group (threads never
            // change a result)
            let per = cells.len().div_ceil(8).clamp(4, 256);
            let groups: Vec<&[IBox]> = cells.chunks(per).collect();
            return map_ordered(&groups, threads, &|g: &&[IBox]| {
                if late() {
                    return vec![None; g.len()];
                }
                match batch::crown_offsets(&plan.net, g, &self.pdirs, mode) {
                    Some(all) => all.into_iter().map(|b| Some((b, Vec::new()))).collect(),
                    None => g.iter().map(|c| Some(one(c))).collect::<Vec<_>>(),
                }
            })
            .into_iter()
            .flatten()
            .collect();
        }
        map_ordered(cells, threads, &|c: &IBox| (!late()).then(|| one(c)))
    }

    /// The inputs along which splitting `cell` is tried: every input still
    /// wider than `min_width` under [`Branching::LookAhead`] (up to
    /// [`LOOK_AHEAD_DIMS`] inputs, else as [`Branching::Smear`]), otherwise
    /// the one [`Ctx::split_dim`] picks; empty when none may be split.
    fn split_dims(&self, cell: &IBox, row: usize, min_width: &[f64], root: &IBox) -> Vec<usize> {
        let n = cell.dim();
        if self.plan.branching == Branching::LookAhead && n <= LOOK_AHEAD_DIMS {
            return (0..n)
                .filter(|&i| cell.hi[i] - cell.lo[i] > min_width[i])
                .collect();
        }
        self.split_dim(cell, row, min_width, root)
            .into_iter()
            .collect()
    }

    /// The input along which to split `cell` for the decisive row `row`:
    /// the largest smear `|∂(d·f)/∂xᵢ(centre)|·widthᵢ` among the inputs
    /// still wider than `min_width`; the widest (relative to `root`) when
    /// every gradient entry is 0; `None` when no input may be split.
    fn split_dim(&self, cell: &IBox, row: usize, min_width: &[f64], root: &IBox) -> Option<usize> {
        let n = cell.dim();
        let splittable: Vec<usize> = (0..n)
            .filter(|&i| cell.hi[i] - cell.lo[i] > min_width[i])
            .collect();
        if splittable.is_empty() {
            return None;
        }
        let widest = || {
            splittable.iter().copied().max_by(|&a, &b| {
                let rel = |i: usize| {
                    (cell.hi[i] - cell.lo[i]) / (root.hi[i] - root.lo[i]).max(f64::MIN_POSITIVE)
                };
                rel(a).total_cmp(&rel(b))
            })
        };
        if self.plan.branching == Branching::Widest {
            return widest();
        }
        let centre: Vec<f64> = (0..n)
            .map(|i| cell.lo[i] + 0.5 * (cell.hi[i] - cell.lo[i]))
            .collect();
        let d: Vec<f64> = self.pdirs.row(row).iter().copied().collect();
        let (_, g) = self.plan.net.gradient(&centre, &d);
        let smear = |i: usize| (g[i] * (cell.hi[i] - cell.lo[i])).abs();
        let best = splittable
            .iter()
            .copied()
            .filter(|&i| smear(i).is_finite())
            .max_by(|&a, &b| smear(a).total_cmp(&smear(b)));
        match best {
            Some(i) if smear(i) > 0.0 => Some(i),
            _ => widest(),
        }
    }

    /// Try to falsify property `k` from `starts` by projected gradient
    /// ascent inside `within` (a cell of the input set, or the set), with
    /// steps of `scale` times the cell's half-width, halved when a step does
    /// not improve. A candidate is confirmed against the whole input set.
    fn pgd(
        &self,
        k: usize,
        within: &Region,
        starts: &[Vec<f64>],
        steps: usize,
        real_only: &mut Option<Vec<f64>>,
    ) -> Option<Witness> {
        let net = &self.plan.net;
        let kind = &self.props()[k].kind;
        let label = self.labels[k];
        let b = within.bbox();
        let n = b.dim();
        let half: Vec<f64> = (0..n).map(|i| 0.5 * (b.hi[i] - b.lo[i])).collect();
        for x0 in starts {
            let Some(mut x) = project(within, x0.clone()) else {
                continue;
            };
            let mut alpha = 0.5;
            let mut v = f64::NEG_INFINITY;
            for _ in 0..=steps {
                let y = net.forward(&x);
                let now = violation(kind, label, &y);
                if now >= 0.0 {
                    if let Some(w) = self.confirmed(k, &x, real_only) {
                        return Some(w);
                    }
                }
                if now <= v {
                    alpha *= 0.5;
                }
                v = v.max(now);
                let c = ascent_row(kind, label, &y);
                let (_, g) = net.gradient(&x, &c);
                let next: Vec<f64> = (0..n)
                    .map(|i| {
                        x[i] + alpha * half[i] * g[i].signum() * f64::from(u8::from(g[i] != 0.0))
                    })
                    .collect();
                match project(within, next) {
                    Some(p) => x = p,
                    None => break,
                }
            }
        }
        None
    }

    /// `x` as a confirmed counterexample of property `k` (made a value of
    /// the model's input type inside the input set, then confirmed), or
    /// `None`; the first real-arithmetic-only violation is kept.
    fn confirmed(&self, k: usize, x: &[f64], real_only: &mut Option<Vec<f64>>) -> Option<Witness> {
        let net = &self.plan.net;
        let kind = &self.props()[k].kind;
        let label = self.labels[k];
        let stored = representable(self.region, net.input_type, x)
            .filter(|r| confirm(net, self.region, kind, label, r));
        if stored.is_none()
            && real_only.is_none()
            && violates_real(net, self.region, kind, label, x)
        {
            *real_only = Some(x.to_vec());
        }
        stored.map(|input| Witness {
            output: net.forward(&input),
            input,
        })
    }
}

/// The output combination whose increase increases the violation of
/// `kind` at output `y` (a subgradient of [`violation`]).
fn ascent_row(kind: &NetPropertyKind, label: Option<usize>, y: &[f64]) -> Vec<f64> {
    let m = y.len();
    let dot = |a: &[f64]| a.iter().zip(y).map(|(a, b)| a * b).sum::<f64>();
    match kind {
        NetPropertyKind::Require(p) => p
            .rows
            .iter()
            .max_by(|a, b| (dot(&a.0) - a.1).total_cmp(&(dot(&b.0) - b.1)))
            .map(|r| r.0.clone())
            .unwrap_or_else(|| vec![0.0; m]),
        NetPropertyKind::Avoid(members) => {
            // the member closest to containing y, and its most violated row
            let row_of = |p: &ravel_analysis::sets::Polytope| {
                p.rows
                    .iter()
                    .max_by(|a, b| (dot(&a.0) - a.1).total_cmp(&(dot(&b.0) - b.1)))
                    .map(|r| (dot(&r.0) - r.1, r.0.clone()))
            };
            members
                .iter()
                .filter_map(row_of)
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .map(|(_, a)| a.iter().map(|v| -v).collect())
                .unwrap_or_else(|| vec![0.0; m])
        }
        NetPropertyKind::Robust(_) => {
            let k = label.unwrap_or(0);
            let j = (0..m)
                .filter(|&j| j != k)
                .max_by(|&a, &b| y[a].total_cmp(&y[b]))
                .unwrap_or(k);
            let mut c = vec![0.0; m];
            if j != k {
                c[j] = 1.0;
                c[k] = -1.0;
            }
            c
        }
    }
}

/// The children in `kids` still open on some property get the bounds of
/// [`dual::optimise`] over their box (the network as the ReLU chain
/// `chain` of `anet`, its pre-activation bounds CROWN's over the box, the
/// Lagrangian's slopes optimised from CROWN's for [`DUAL_STEPS`] steps;
/// certified, see [`dual::certified`]); each row keeps the smaller of its
/// two bounds. Children not bounded (the time ran out) are left alone, and
/// so is every child once `late()` says the time is up.
fn tighten(
    cx: &Ctx,
    chain: &dual::ReluChain,
    anet: &ravel_base::nn::Network,
    kids: &mut [Child],
    settled: &[bool],
    late: &(dyn Fn() -> bool + Sync),
) {
    let open: Vec<usize> = (0..kids.len())
        .filter(|&i| kids[i].3 && cx.worst(&kids[i].1, settled).0 < f64::INFINITY)
        .collect();
    if open.is_empty() {
        return;
    }
    let obj: DMatrix<f64> = -cx.pdirs.transpose();
    let rows = obj.ncols();
    let cells: Vec<&IBox> = open.iter().map(|&i| &kids[i].0).collect();
    let got = map_ordered(&cells, cx.ctl.threads, &|c: &&IBox| {
        if late() {
            return None;
        }
        let dom = dual::Domain::root(anet, c)?;
        let start = dual::Slopes::crown(chain, &dom, rows);
        let o = dual::optimise(chain, c, &dom, &obj, start, DUAL_STEPS);
        // upper bounds of the rows from lower bounds of their negations
        Some(o.bounds.iter().map(|v| -v).collect::<Vec<f64>>())
    });
    for (&i, g) in open.iter().zip(got) {
        let Some(g) = g else { continue };
        for (b, u) in kids[i].1.iter_mut().zip(g) {
            if u < *b {
                *b = u;
            }
        }
    }
}

/// Stage `stage` of the local search ([`local`]) for every property
/// still open that may be falsified, over the cells `cells(k)` where
/// property `k` is open; a confirmed counterexample settles it.
#[allow(clippy::too_many_arguments)]
fn local_stage(
    cx: &Ctx,
    stage: usize,
    cells: &dyn Fn(usize) -> Vec<IBox>,
    settled: &mut [bool],
    witnesses: &mut [Option<Witness>],
    real_only: &mut [Option<Vec<f64>>],
    late: &(dyn Fn() -> bool + Sync),
) {
    for k in 0..settled.len() {
        if settled[k] || !cx.may_falsify[k] || late() {
            continue;
        }
        let cells = cells(k);
        let st = local::Stage {
            k,
            cells: &cells,
            samples: LOCAL_SAMPLES
                .saturating_mul(1 << stage.min(20))
                .min(LOCAL_MAX_SAMPLES),
            starts: if stage == 0 {
                LOCAL_FIRST_STARTS
            } else {
                LOCAL_STARTS
            },
            seed: local::stage_seed(cx.plan.seed, stage, k),
        };
        if let Some(w) = cx.local_search(&st, late, &mut real_only[k]) {
            witnesses[k] = Some(w);
            settled[k] = true;
        }
    }
}

/// Branch and bound over `region` for the plan's properties (see the
/// module documentation). `rows` are the stacked rows of the run
/// (`root` their bounds over the whole set, one call), `starts` the inputs
/// the opening attack starts from (best first), `labels` and `may_falsify`
/// per property as Monte Carlo decided them; `limit` the most open cells
/// the queue may hold ([`queue_limit`]).
#[allow(clippy::too_many_arguments)]
pub(super) fn search(
    plan: &NetworkPlan,
    region: &Region,
    rows: &Rows,
    root: Vec<f64>,
    root_issues: Vec<Issue>,
    starts: &[Vec<f64>],
    labels: &[Option<usize>],
    may_falsify: &[bool],
    budget: &Budget,
    ctl: &Control,
    limit: usize,
) -> Searched {
    let total = rows.dirs.nrows();
    let k0 = rows.shape_rows;
    let np = plan.properties.len();
    let cx = Ctx {
        plan,
        region,
        pdirs: rows.dirs.rows(k0, total - k0).into_owned(),
        ranges: rows
            .ranges
            .iter()
            .map(|r| r.start - k0..r.end - k0)
            .collect(),
        labels,
        may_falsify,
        ctl,
    };
    let full = |b: &[f64]| -> Vec<f64> { root[..k0].iter().chain(b).copied().collect() };
    let mut issues = root_issues;
    let mut witnesses: Vec<Option<Witness>> = vec![None; np];
    let mut real_only: Vec<Option<Vec<f64>>> = vec![None; np];
    let mut settled = vec![false; np];
    let rootbox = region.bbox();
    let mut leaves: Vec<(IBox, Vec<f64>)> = Vec::new();
    // cells bounded (the look-ahead's rejected candidates included), and
    // subproblems made (the root, then two per split): the budget `calls`
    // counts the latter, so trying every input does not spend it faster
    let mut calls = 1;
    let mut made = 1;
    let out_of_time = || ctl.out_of_time() || budget.seconds.is_some_and(|s| (ctl.elapsed)() > s);

    // 1. the opening attack
    let root_b = root[k0..].to_vec();
    for k in 0..np {
        if !cx.may_falsify[k] || out_of_time() {
            continue;
        }
        let (v, _) = cell_margin(&plan.properties[k].kind, &root_b, &cx.ranges[k]);
        if proved(&plan.properties[k].kind, v) {
            continue;
        }
        if let Some(w) = cx.pgd(k, region, starts, PGD_STEPS, &mut real_only[k]) {
            witnesses[k] = Some(w);
            settled[k] = true;
        }
    }

    // many inputs: split activations instead (where the network allows)
    if rootbox.dim() > LOOK_AHEAD_DIMS && !settled.iter().all(|s| *s) {
        if let Some((chain, net, bx)) = activations::applies(&cx, region) {
            return activations::search(
                &cx, &chain, &net, &bx, root_b, &full, issues, budget, settled, witnesses,
                real_only,
            );
        }
    }
    // the local search's stages: the next one when `calls` reaches this
    let mut stage = 0;
    let mut next_stage = LOCAL_CALLS;
    // the network as a ReLU chain, for the late cells' dual bounds
    let tight = match region {
        Region::Box(_) => activations::applies(&cx, region).map(|(c, n, _)| (c, n)),
        _ => None,
    };
    let min_width: Vec<f64> = (0..rootbox.dim())
        .map(|i| budget.min_size * (rootbox.hi[i] - rootbox.lo[i]))
        .collect();
    let mut queue: BinaryHeap<Node> = BinaryHeap::new();
    let (w0, _) = cx.worst(&root_b, &settled);
    let mut stop = Stop::Done;
    if w0 < f64::INFINITY {
        queue.push(Node {
            cell: rootbox.clone(),
            bounds: root_b,
            worst: w0,
        });
    } else {
        leaves.push((rootbox.clone(), full(&root_b)));
        if settled.iter().any(|s| *s) {
            // the opening attack settled what the root's bounds did not
            stop = Stop::Decided;
        }
    }
    while !queue.is_empty() {
        if let Some(why) = halt(&settled, out_of_time(), made, budget, queue.len(), limit) {
            stop = why;
            break;
        }
        // the next stage of the local search, over the open cells
        if calls >= next_stage {
            next_stage = next_stage.saturating_mul(2).max(calls.saturating_add(1));
            local_stage(
                &cx,
                stage,
                &|k| cx.open_for(k, queue.iter().map(|n| (&n.cell, &n.bounds[..]))),
                &mut settled,
                &mut witnesses,
                &mut real_only,
                &out_of_time,
            );
            stage += 1;
            continue;
        }
        // take a batch; split each (along each candidate input: one, but
        // every splittable one under look-ahead branching)
        let room = (budget.calls - made) / 2;
        let take = BATCH.min(room.max(1));
        let mut parents: Vec<Node> = Vec::with_capacity(take);
        let mut options: Vec<usize> = Vec::with_capacity(take);
        let mut kids: Vec<IBox> = Vec::with_capacity(2 * take);
        while parents.len() < take {
            let Some(node) = queue.pop() else { break };
            let (_, row) = cx.worst(&node.bounds, &settled);
            let Some(row) = row else {
                // settled since it was queued
                leaves.push((node.cell.clone(), full(&node.bounds)));
                continue;
            };
            let dims = cx.split_dims(&node.cell, row, &min_width, &rootbox);
            if dims.is_empty() {
                // too small to split: it stays open
                leaves.push((node.cell.clone(), full(&node.bounds)));
                continue;
            }
            for &i in &dims {
                let mid = node.cell.lo[i] + 0.5 * (node.cell.hi[i] - node.cell.lo[i]);
                let (mut a, mut b) = (node.cell.clone(), node.cell.clone());
                a.hi[i] = mid;
                b.lo[i] = mid;
                kids.push(a);
                kids.push(b);
            }
            options.push(dims.len());
            parents.push(node);
        }
        if kids.is_empty() {
            continue;
        }
        let bounded = cx.bound(&kids, &out_of_time);
        let fresh = bounded.iter().filter(|b| b.is_some()).count();
        calls += fresh;
        (ctl.progress)(crate::execute::Progress {
            phase: crate::execute::Phase::Cells,
            done: made + 2 * parents.len(),
            total: Some(budget.calls),
        });
        let mut pending = kids.into_iter().zip(bounded);
        let mut picked: Vec<Child> = Vec::with_capacity(2 * parents.len());
        for (node, &n_opts) in parents.iter().zip(&options) {
            let parent = &node.bounds;
            // each child's bounds: its own intersected with its parent's
            // (both hold on it), or the parent's when it was not bounded
            // (the time ran out; the next round stops)
            let mut pairs: Vec<[Child; 2]> = (0..n_opts)
                .map(|_| {
                    [(); 2].map(|_| {
                        let (cell, got) = pending.next().expect("two children per option");
                        match got {
                            Some((b, iss)) => {
                                let b: Vec<f64> = b
                                    .iter()
                                    .zip(parent)
                                    .map(|(c, p)| if c.is_nan() { *p } else { c.min(*p) })
                                    .collect();
                                (cell, b, iss, true)
                            }
                            None => (cell, parent.clone(), Vec::new(), false),
                        }
                    })
                })
                .collect();
            // the option whose children's open margins sum highest (a proved
            // child counts 0), then whose worse child is best, among those
            // whose children were both bounded (measured against the worse
            // child alone on ACAS Xu: docs/language.md)
            let score = |p: &[Child; 2]| {
                let (a, b) = (cx.worst(&p[0].1, &settled).0, cx.worst(&p[1].1, &settled).0);
                (p[0].3 && p[1].3, a.min(0.0) + b.min(0.0), a.min(b))
            };
            let rel = |p: &[Child; 2]| {
                (0..node.cell.dim())
                    .find(|&i| p[0].0.hi[i] != node.cell.hi[i])
                    .map_or(0.0, |i| {
                        (node.cell.hi[i] - node.cell.lo[i])
                            / (rootbox.hi[i] - rootbox.lo[i]).max(f64::MIN_POSITIVE)
                    })
            };
            let scores: Vec<(Score, f64)> = pairs.iter().map(|p| (score(p), rel(p))).collect();
            let at = pick(&scores, cx.worst(parent, &settled).0);
            picked.extend(pairs.swap_remove(at));
            made += 2;
        }
        // late in the search, the children still open get the optimised
        // dual's bounds too (both certified: each row keeps the smaller)
        if let Some((chain, anet)) = &tight {
            if made >= DUAL_MADE && !out_of_time() {
                tighten(&cx, chain, anet, &mut picked, &settled, &out_of_time);
            }
        }
        for (cell, b, iss, _) in picked {
            issues.extend(iss);
            let (w, _) = cx.worst(&b, &settled);
            if w == f64::INFINITY {
                leaves.push((cell, full(&b)));
                continue;
            }
            if out_of_time() {
                queue.push(Node {
                    cell,
                    bounds: b,
                    worst: w,
                });
                continue;
            }
            // attack the child
            let centre: Vec<f64> = (0..cell.dim())
                .map(|i| cell.lo[i] + 0.5 * (cell.hi[i] - cell.lo[i]))
                .collect();
            for k in 0..np {
                if settled[k] || !cx.may_falsify[k] {
                    continue;
                }
                let (v, _) = cell_margin(&plan.properties[k].kind, &b, &cx.ranges[k]);
                if proved(&plan.properties[k].kind, v) {
                    continue;
                }
                let within = cell_region(region, &cell);
                if let Some(wit) = cx.pgd(
                    k,
                    &within,
                    std::slice::from_ref(&centre),
                    CHILD_STEPS,
                    &mut real_only[k],
                ) {
                    witnesses[k] = Some(wit);
                    settled[k] = true;
                }
            }
            queue.push(Node {
                cell,
                bounds: b,
                worst: w,
            });
        }
    }
    leaves.extend(queue.into_iter().map(|n| {
        let b = full(&n.bounds);
        (n.cell, b)
    }));
    let union = ravel_analysis::open_loop::union_offsets(&leaves, total);
    issues.sort_by_key(|i| format!("{i:?}"));
    issues.dedup();
    Searched {
        bounded: Bounded {
            cells: leaves,
            union,
            calls,
            stop,
            issues,
        },
        made,
        witnesses,
        real_only,
        activations: false,
        record: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ir::{NetPropagator, Partitioner};
    use ravel_analysis::sets::Polytope;
    use ravel_analysis::shape::Shape;
    use ravel_base::nn::{Activation, Layer, Network};

    /// `y = |z| − |2z| = −|z|` with `z = x₀ − ⅓`, on `[−1, 1]²`: `y ≤ 0`
    /// holds, tightly along a line no bisection of the box reaches; neither
    /// interval arithmetic nor CROWN proves it on a cell crossing the line
    /// (each bounds `|z|` and `−|2z|` apart), and no input violates it, so
    /// only a limit ends the search.
    fn tight_plan() -> NetworkPlan {
        let third = 1.0 / 3.0;
        let net = Network::new(
            2,
            vec![
                Layer::Affine {
                    w: DMatrix::from_row_slice(4, 2, &[1.0, 0.0, -1.0, 0.0, 2.0, 0.0, -2.0, 0.0]),
                    b: nalgebra::DVector::from_vec(vec![-third, third, -2.0 * third, 2.0 * third]),
                },
                Layer::Act(Activation::Relu),
                Layer::Affine {
                    w: DMatrix::from_row_slice(1, 4, &[1.0, 1.0, -1.0, -1.0]),
                    b: nalgebra::DVector::from_vec(vec![0.0]),
                },
            ],
        );
        NetworkPlan {
            name: "t".into(),
            input_name: "x".into(),
            output_name: "y".into(),
            model_path: String::new(),
            model_sha256: String::new(),
            model_resolved: String::new(),
            network_summary: String::new(),
            net,
            input: Some(Region::Box(IBox::new(vec![-1.0, -1.0], vec![1.0, 1.0]))),
            input_set_name: "X".into(),
            selects: Vec::new(),
            properties: vec![NetProperty {
                name: "p".into(),
                kind: NetPropertyKind::Require(Polytope {
                    rows: vec![(vec![1.0], 0.0)],
                }),
            }],
            radii: Vec::new(),
            propagator: NetPropagator::Crown,
            partitioner: Partitioner::Uniform(vec![1, 1]),
            shape: Shape::Box,
            samples: 0,
            seed: 0,
            slope_steps: 0,
            branching: Default::default(),
            phases: Default::default(),
        }
    }

    fn run(limit: usize, calls: usize) -> Searched {
        run_with(limit, calls, &Control::unlimited())
    }

    /// The tight plan's search under `ctl`.
    fn run_with(limit: usize, calls: usize, ctl: &Control) -> Searched {
        let plan = tight_plan();
        let region = plan.input.clone().unwrap();
        let shape = DMatrix::from_row_slice(2, 1, &[1.0, -1.0]);
        let rows = super::super::stack(&shape, &[vec![vec![1.0]]], 1);
        let (root, issues) = cell_bounds(&plan.net, &region, plan.propagator, 0, &rows.dirs);
        let budget = Budget {
            calls,
            min_size: 1e-9,
            seconds: None,
        };
        search(
            &plan,
            &region,
            &rows,
            root,
            issues,
            &[vec![0.0, 0.0]],
            &[None],
            &[true],
            &budget,
            ctl,
            limit,
        )
    }

    /// `y = relu(1 − |x − p|₁/0.3) − 0.999` on `[−1, 1]²` with `p` away
    /// from the centre: `y ≤ 0` fails only within `|x − p|₁ < 3·10⁻⁴`, a
    /// region no sample of a few thousand hits, on a tent whose gradient is
    /// zero at the centre and off its base (so the gradient attack from the
    /// centre does not move). Its plan and `p`.
    fn tent_plan() -> (NetworkPlan, [f64; 2]) {
        let p = [0.71, -0.62];
        let net = Network::new(
            2,
            vec![
                Layer::Affine {
                    w: DMatrix::from_row_slice(4, 2, &[1.0, 0.0, -1.0, 0.0, 0.0, 1.0, 0.0, -1.0]),
                    b: nalgebra::DVector::from_vec(vec![-p[0], p[0], -p[1], p[1]]),
                },
                Layer::Act(Activation::Relu),
                Layer::Affine {
                    w: DMatrix::from_row_slice(1, 4, &[-1.0 / 0.3; 4]),
                    b: nalgebra::DVector::from_vec(vec![1.0]),
                },
                Layer::Act(Activation::Relu),
                Layer::Affine {
                    w: DMatrix::from_row_slice(1, 1, &[1.0]),
                    b: nalgebra::DVector::from_vec(vec![-0.999]),
                },
            ],
        );
        let mut plan = tight_plan();
        plan.net = net;
        (plan, p)
    }

    /// The local search's first stage over the whole set finds the tent's
    /// thin violating region, where the gradient attack from the centre
    /// finds nothing; the same point whatever the thread count. The search
    /// settles the property too (its splits alone would reach the region
    /// as well, later).
    #[test]
    fn the_local_search_finds_a_thin_violation_the_gradient_misses() {
        let (plan, p) = tent_plan();
        let region = plan.input.clone().unwrap();
        let whole = [region.bbox()];
        let found = |threads: usize, pgd: bool| {
            let mut ctl = Control::unlimited();
            ctl.threads = threads;
            let cx = Ctx {
                plan: &plan,
                region: &region,
                pdirs: DMatrix::from_row_slice(1, 1, &[1.0]),
                ranges: std::iter::once(0..1).collect(),
                labels: &[None],
                may_falsify: &[true],
                ctl: &ctl,
            };
            let mut real = None;
            if pgd {
                return cx.pgd(0, &region, &[vec![0.0, 0.0]], PGD_STEPS, &mut real);
            }
            let st = local::Stage {
                k: 0,
                cells: &whole,
                samples: LOCAL_SAMPLES,
                starts: LOCAL_FIRST_STARTS,
                seed: local::stage_seed(plan.seed, 0, 0),
            };
            cx.local_search(&st, &|| false, &mut real)
        };
        assert_eq!(found(1, true), None);
        let w = found(1, false).expect("a counterexample");
        assert!(w.output[0] > 0.0, "{w:?}");
        let dist = (w.input[0] - p[0]).abs() + (w.input[1] - p[1]).abs();
        assert!(dist < 3e-4, "{w:?}");
        // float32 inputs (the model's type), confirmed
        assert!(w.input.iter().all(|v| f64::from(*v as f32) == *v));
        assert_eq!(found(3, false), Some(w));
        // the search
        let rows = super::super::stack(&DMatrix::zeros(0, 1), &[vec![vec![1.0]]], 1);
        let (root, issues) = cell_bounds(&plan.net, &region, plan.propagator, 0, &rows.dirs);
        let budget = Budget {
            calls: 100_000,
            min_size: 1e-9,
            seconds: None,
        };
        let s = search(
            &plan,
            &region,
            &rows,
            root,
            issues,
            &[vec![0.0, 0.0]],
            &[None],
            &[true],
            &budget,
            &Control::unlimited(),
            usize::MAX,
        );
        assert_eq!(s.bounded.stop, Stop::Decided);
        assert!(s.witnesses[0].is_some());
    }

    /// The late cells' dual bounds ([`tighten`]) hold on their cells: on
    /// random ReLU networks (every third with two consecutive affine
    /// layers, which get a ReLU pair) and random cells, every sampled
    /// output's row value lies below its cell's bound, and some bounds are
    /// tighter than CROWN's.
    #[test]
    fn the_late_cells_dual_bounds_contain_their_sampled_outputs() {
        let mut rng = ravel_base::rng::Rng::new(29);
        let mut tighter = 0;
        for case in 0..12 {
            let widths = [3, 4 + rng.below(5), 4 + rng.below(5), 2];
            let mut layers = Vec::new();
            if case % 3 == 0 {
                layers.push(Layer::Affine {
                    w: DMatrix::from_fn(3, 3, |i, j| if i == j { 1.5 } else { 0.0 }),
                    b: nalgebra::DVector::from_fn(3, |_, _| rng.normal() * 0.2),
                });
            }
            for (k, w) in widths.windows(2).enumerate() {
                let s = 1.5 / (w[0] as f64).sqrt();
                layers.push(Layer::Affine {
                    w: DMatrix::from_fn(w[1], w[0], |_, _| rng.normal() * s),
                    b: nalgebra::DVector::from_fn(w[1], |_, _| rng.normal() * 0.3),
                });
                if k + 2 < widths.len() {
                    layers.push(Layer::Act(Activation::Relu));
                }
            }
            let mut plan = tight_plan();
            plan.net = Network::new(3, layers);
            plan.input = Some(Region::Box(IBox::new(vec![-1.0; 3], vec![1.0; 3])));
            let d = DMatrix::from_fn(2, 2, |_, _| rng.normal());
            plan.properties[0].kind = NetPropertyKind::Require(Polytope {
                rows: (0..2)
                    .map(|r| (d.row(r).iter().copied().collect(), 0.0))
                    .collect(),
            });
            let region = plan.input.clone().unwrap();
            let ctl = Control::unlimited();
            let cx = Ctx {
                plan: &plan,
                region: &region,
                pdirs: d.clone(),
                ranges: std::iter::once(0..2).collect(),
                labels: &[None],
                may_falsify: &[false],
                ctl: &ctl,
            };
            let (chain, anet, _) = activations::applies(&cx, &region).expect("a ReLU chain");
            let mut kids: Vec<Child> = (0..6)
                .map(|_| {
                    let (mut lo, mut hi) = (Vec::new(), Vec::new());
                    for _ in 0..3 {
                        let w = rng.uniform(0.05, 1.0);
                        let l = rng.uniform(-1.0, 1.0 - w);
                        lo.push(l);
                        hi.push(l + w);
                    }
                    (IBox::new(lo, hi), vec![f64::INFINITY; 2], Vec::new(), true)
                })
                .collect();
            tighten(&cx, &chain, &anet, &mut kids, &[false], &|| false);
            for (c, b, _, _) in &kids {
                assert!(b.iter().all(|v| v.is_finite()), "case {case}: {b:?}");
                let (crown, _) =
                    cell_bounds(&plan.net, &Region::Box(c.clone()), plan.propagator, 0, &d);
                tighter += (0..2).filter(|&r| b[r] < crown[r] - 1e-9).count();
                for _ in 0..200 {
                    let x: Vec<f64> = (0..3).map(|i| rng.uniform(c.lo[i], c.hi[i])).collect();
                    let y = plan.net.forward(&x);
                    for r in 0..2 {
                        let v = d[(r, 0)] * y[0] + d[(r, 1)] * y[1];
                        assert!(
                            v <= b[r] + 1e-9 * (1.0 + v.abs()),
                            "case {case}: {c:?} row {r}: bound {} below {v}",
                            b[r]
                        );
                    }
                }
            }
        }
        assert!(tighter > 0, "the dual never beat CROWN");
    }

    /// Every final cell's bounds contain the outputs sampled on that cell
    /// (parents' bounds intersected with the children's, batched CROWN),
    /// on random ReLU networks with a property the search cannot settle
    /// (the attack is off, the threshold is the centre's value).
    #[test]
    fn every_cells_bounds_contain_its_sampled_outputs() {
        let mut rng = ravel_base::rng::Rng::new(17);
        for case in 0..16 {
            let widths = [2, 3 + rng.below(4), 3 + rng.below(4), 2];
            let mut layers = Vec::new();
            for (k, w) in widths.windows(2).enumerate() {
                let s = 1.5 / (w[0] as f64).sqrt();
                layers.push(Layer::Affine {
                    w: DMatrix::from_fn(w[1], w[0], |_, _| rng.normal() * s),
                    b: nalgebra::DVector::from_fn(w[1], |_, _| rng.normal() * 0.3),
                });
                if k + 2 < widths.len() {
                    layers.push(Layer::Act(Activation::Relu));
                }
            }
            let mut plan = tight_plan();
            plan.net = Network::new(2, layers);
            let d = vec![rng.normal(), rng.normal()];
            let y0 = plan.net.forward(&[0.0, 0.0]);
            let h = d[0] * y0[0] + d[1] * y0[1];
            plan.properties[0].kind = NetPropertyKind::Require(Polytope {
                rows: vec![(d.clone(), h)],
            });
            let region = plan.input.clone().unwrap();
            let rows = super::super::stack(&DMatrix::zeros(0, 2), &[vec![d.clone()]], 2);
            let (root, issues) = cell_bounds(&plan.net, &region, plan.propagator, 0, &rows.dirs);
            let budget = Budget {
                calls: 300,
                min_size: 1e-9,
                seconds: None,
            };
            let s = search(
                &plan,
                &region,
                &rows,
                root,
                issues,
                &[],
                &[None],
                &[false],
                &budget,
                &Control::unlimited(),
                usize::MAX,
            );
            assert!(s.bounded.cells.len() > 1, "case {case}: nothing was split");
            for (c, b) in &s.bounded.cells {
                for _ in 0..20 {
                    let x: Vec<f64> = (0..2).map(|i| rng.uniform(c.lo[i], c.hi[i])).collect();
                    let y = plan.net.forward(&x);
                    let v = d[0] * y[0] + d[1] * y[1];
                    assert!(
                        v <= b[0] + 1e-9 * (1.0 + v.abs()),
                        "case {case}: {c:?} bounds {} below {v}",
                        b[0]
                    );
                }
            }
        }
    }

    /// The look-ahead keeps the best-scoring split when it gains, and the
    /// widest input when no option gains more than `STALL` of the parent's
    /// margin (rounding noise), never an option with a child not bounded.
    #[test]
    fn the_look_ahead_splits_the_widest_input_when_nothing_gains() {
        let p = -0.0165;
        // a real gain on the thin input (index 1): kept
        let gains = [((true, 2.0 * p, p), 1.0), ((true, 2.0 * p + 1e-4, p), 1e-6)];
        assert_eq!(pick(&gains, p), 1);
        // noise (a gain of 1e-5 of the margin) on the thin input: the widest
        let noise = [
            ((true, 2.0 * p, p), 0.5),
            ((true, 2.0 * p + 3e-7, p), 1e-6),
            ((true, 2.0 * p + 1e-9, p), 1.0),
            ((false, 2.0 * p, p), 2.0),
        ];
        assert_eq!(pick(&noise, p), 2);
        // a proved child is a gain
        let proved = [((true, 2.0 * p, p), 1.0), ((true, p, p), 1e-3)];
        assert_eq!(pick(&proved, p), 1);
        // one option: it
        assert_eq!(pick(&noise[..1], p), 0);
    }

    #[test]
    fn a_full_queue_stops_the_search_soundly() {
        let s = run(1, 1000);
        assert_eq!(s.bounded.stop, Stop::Queue);
        assert!(s.witnesses[0].is_none());
        // the open cell keeps bounds valid on it: the root's, here
        assert_eq!(s.bounded.cells.len(), 1);
        let (_, b) = &s.bounded.cells[0];
        assert!(
            b[2] >= 0.0,
            "the open cell's bound of y proves nothing: {b:?}"
        );
    }

    #[test]
    fn the_call_budget_stops_the_search_and_the_cells_cover_the_box() {
        let s = run(usize::MAX, 200);
        assert_eq!(s.bounded.stop, Stop::Calls);
        assert!(s.made <= 200 + 2 * BATCH);
        // two inputs: the look-ahead bounds four children per split
        assert!(s.bounded.calls <= 2 * s.made);
        assert!(s.witnesses[0].is_none());
        // the final cells tile the box: their areas add up to its area
        let area: f64 = s
            .bounded
            .cells
            .iter()
            .map(|(c, _)| (c.hi[0] - c.lo[0]) * (c.hi[1] - c.lo[1]))
            .sum();
        assert_eq!(area, 4.0);
        // the cells on the line stay open, every other cell is proved
        for (c, b) in &s.bounded.cells {
            let on_line = c.lo[0] <= 1.0 / 3.0 && 1.0 / 3.0 <= c.hi[0];
            assert_eq!(b[2] > 0.0, on_line, "{c:?}: {b:?}");
        }
    }

    /// A time limit that passes in the middle of a round stops the search
    /// there: the children not bounded keep their parent's bounds (valid on
    /// them), the cells still tile the box, and the stop says `time`.
    #[test]
    fn the_time_limit_is_checked_between_the_groups_of_a_round() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let mut partial = 0;
        for ticks in 3..40 {
            // a clock that advances one second each time it is read
            let reads = AtomicUsize::new(0);
            let clock = || reads.fetch_add(1, Ordering::SeqCst) as f64;
            let mut ctl = Control::new(&clock);
            ctl.time_limit = Some(ticks as f64);
            let s = run_with(usize::MAX, 100_000, &ctl);
            assert_eq!(s.bounded.stop, Stop::Time, "{ticks}");
            // each split adds one cell and, when bounded, four calls (both
            // inputs tried): fewer calls means children were left with
            // their parent's bounds
            if s.bounded.calls < 1 + 4 * (s.made - 1) / 2 {
                partial += 1;
            }
            let area: f64 = s
                .bounded
                .cells
                .iter()
                .map(|(c, _)| (c.hi[0] - c.lo[0]) * (c.hi[1] - c.lo[1]))
                .sum();
            assert_eq!(area, 4.0, "{ticks}");
            // y = −|x₀ − ⅓| ≤ 0 everywhere: every bound of y is above the
            // true maximum over its cell
            for (c, b) in &s.bounded.cells {
                let x0 = (1.0f64 / 3.0).clamp(c.lo[0], c.hi[0]);
                assert!(b[2] >= -(x0 - 1.0 / 3.0).abs() - 1e-12, "{c:?}: {b:?}");
            }
        }
        assert!(partial > 0, "no time limit fell inside a round");
    }
}
