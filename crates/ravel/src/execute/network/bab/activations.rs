//! Branch and bound on ReLU activations, for networks with many inputs
//! (more than [`LOOK_AHEAD_DIMS`](super::LOOK_AHEAD_DIMS)), where halving
//! one input of hundreds changes no bound: a subproblem is the whole input
//! box with some neurons' signs fixed, bounded by
//! [`ravel_analysis::dual`]'s optimised Lagrangian bound (the split signs
//! are constraints of the relaxation, as β-CROWN's split constraints; its
//! bound is certified whatever the ascent did). Each round splits the
//! unstable neuron whose relaxation weighs most in the decisive row's
//! bound ([`dual::branch`]); children start their ascent from their
//! parent's multipliers. The relaxation's worst input of each of a round's
//! [`ATTACKS_PER_ROUND`] open children with the lowest margins is tried as
//! a counterexample, then improved by a few gradient steps.
//!
//! The two children of a split cover their parent (every input has one
//! sign or the other), so the leaves cover the input box and the largest
//! bound of a row over the leaves bounds it over the box: that is the one
//! cell the search returns. Only for a box input set and a network of
//! affine layers and ReLUs (consecutive affine layers, a normalisation or
//! a pooling, get ReLU pairs between them: [`dual::alternating`]);
//! otherwise the caller splits inputs.
//!
//! The search keeps a [`SplitRecord`] for a certificate: the multipliers of
//! the root's tightened pre-activation bounds, the split tree, and at each
//! node the multipliers of every property row its bound proved there
//! (rounded to `f32`), within [`SplitRecord::MAX_BYTES`] (past it the record
//! is dropped; the search goes on unchanged). The certificate writer turns
//! it into evidence the checker re-evaluates (docs/certificates.md).

use std::ops::Not;

use nalgebra::DMatrix;

use super::{cell_margin, halt, proved, Bounded, Ctx, Searched, Witness, BATCH};
use crate::execute::network::{SplitNode, SplitRecord};
use crate::execute::{Phase as Stage, Progress};
use crate::ir::{ActivationPhases, NetPropertyKind};
use ravel_analysis::dual::{self, Domain, Phase, ReluChain, Slopes};
use ravel_analysis::issue::Issue;
use ravel_analysis::partition::{Budget, Stop};
use ravel_analysis::sets::{IBox, Region};
use ravel_base::nn::Network;

/// Ascent steps on the root.
const ROOT_STEPS: usize = 100;

/// Ascent steps per unstable neuron's bounds when the root's hidden-layer
/// bounds are tightened (measured on MNIST-FC 256×2, property 0: the
/// root's margin −0.30 untightened, −0.20 at 20 steps, −0.18 at 50).
const TIGHTEN_STEPS: usize = 50;

/// Candidates scored per split ([`dual::branch`]): with 8, property 5 of
/// MNIST-FC 256×2 at ε = 0.03 was proved with 223 subproblems, with 1
/// (the score alone) 2 047.
const BRANCH_TOP: usize = 8;

/// Ascent steps on each child (warm-started from its parent). Measured on
/// MNIST-FC 256×4, property 13 at ε = 0.03 (calls counted to the proof,
/// two threads, a busy machine): 8 steps did not prove it in 200 s
/// (60 659 subproblems), 12 steps took 12 097, 20 took 4 767, 30 took
/// 2 023; longer ascents cost more per child than they save in children.
const CHILD_STEPS: usize = 30;

/// Ascent steps on a subproblem with every neuron's sign fixed.
const LEAF_STEPS: usize = 1000;

/// Children bounded together in one pass.
const GROUP: usize = 32;

/// Gradient steps of the attack from an open child's worst input.
const ATTACK_STEPS: usize = 4;

/// Open children attacked per round (those with the lowest margins): on
/// MNIST-FC 256×4, property 13 at ε = 0.03 (unsat), an attack on every
/// child took a fifth of the search's time.
const ATTACKS_PER_ROUND: usize = 4;

/// An open subproblem: its domain, multipliers and property-row bounds,
/// and its node in the record's tree.
struct Sub {
    dom: Domain,
    slopes: Slopes,
    bounds: Vec<f64>,
    node: usize,
}

/// A queued subproblem: its index in the store and its worst open margin
/// (the queue pops the lowest first).
struct Open {
    at: usize,
    worst: f64,
}

impl PartialEq for Open {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other).is_eq()
    }
}
impl Eq for Open {}
impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Open {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        other
            .worst
            .total_cmp(&self.worst)
            .then(other.at.cmp(&self.at))
    }
}

/// A child to bound: its domain, its parent's slopes (the ascent's start)
/// and bounds (which hold on it too), the rows still open, and its node.
type Kid = (Domain, Slopes, Vec<f64>, Vec<usize>, usize);

/// Whether the upper bound `v` of property row `r` (an index of `pdirs`)
/// proves that row: a `require` row within its right-hand side, a
/// robustness comparison negative, an `avoid` member's row separating it.
fn row_proves(cx: &Ctx, r: usize, v: f64) -> bool {
    for (k, p) in cx.props().iter().enumerate() {
        let range = cx.ranges[k].clone();
        if !range.contains(&r) {
            continue;
        }
        let i = r - range.start;
        return match &p.kind {
            NetPropertyKind::Require(poly) => poly.rows.get(i).is_some_and(|(_, h)| v <= *h),
            NetPropertyKind::Robust(_) => v < 0.0,
            NetPropertyKind::Avoid(members) => members
                .iter()
                .flat_map(|m| m.rows.iter())
                .nth(i)
                .is_some_and(|(_, h)| -v - h > 0.0),
        };
    }
    false
}

/// Record at `node` the multipliers of every objective column of `o`
/// (the rows `cols`) whose bound proves its row and that `node` has not
/// proved yet (rounded to `f32`, within the record's limit).
fn record_proofs(
    cx: &Ctx,
    record: &mut SplitRecord,
    node: usize,
    cols: &[usize],
    o: &dual::Optimised,
) {
    for (i, &c) in cols.iter().enumerate() {
        let v = -o.bounds[i];
        if !row_proves(cx, c, v) {
            continue;
        }
        if record
            .nodes
            .get(node)
            .is_none_or(|n| n.proofs.iter().any(|(r, _)| *r == c))
        {
            continue;
        }
        let nu: Vec<Vec<f32>> = o
            .dual
            .nu
            .iter()
            .map(|m| m.column(i).iter().map(|v| *v as f32).collect())
            .collect();
        if !record.charge(nu.iter().map(Vec::len).sum()) {
            return;
        }
        record.nodes[node].proofs.push((c, nu));
    }
}

/// The memory one subproblem holds, in bytes (for the queue's limit).
fn sub_bytes(dom: &Domain, rows: usize) -> usize {
    let neurons: usize = dom.lo.iter().map(Vec::len).sum();
    (2 * neurons + neurons * rows + rows) * 8 + 128
}

/// Whether the search splits activations for this run: a box input set
/// and a network of affine layers with ReLUs between them.
pub(super) fn applies(cx: &Ctx, region: &Region) -> Option<(ReluChain, Network, IBox)> {
    match region {
        Region::Box(b) if b.is_finite() => {
            let net = dual::alternating(&cx.plan.net)?;
            ReluChain::of(&net).map(|c| (c, net, b.clone()))
        }
        _ => None,
    }
}

/// The property rows (indices of `pdirs`) that still decide something on
/// a subproblem with row bounds `b`: every row of an open property,
/// except a `require` row already within its bound, a robustness row
/// already negative, and the rows of an `avoid` member already separated.
fn open_rows(cx: &Ctx, b: &[f64], settled: &[bool]) -> Vec<usize> {
    let mut out = Vec::new();
    for (k, p) in cx.props().iter().enumerate() {
        if settled[k] {
            continue;
        }
        let range = cx.ranges[k].clone();
        match &p.kind {
            NetPropertyKind::Require(poly) => {
                for ((_, h), r) in poly.rows.iter().zip(range) {
                    if (h - b[r] >= 0.0).not() {
                        out.push(r);
                    }
                }
            }
            NetPropertyKind::Robust(_) => out.extend(range.filter(|&r| (-b[r] > 0.0).not())),
            NetPropertyKind::Avoid(members) => {
                let mut at = range.start;
                for m in members {
                    let rows = at..at + m.rows.len();
                    let apart = m
                        .rows
                        .iter()
                        .zip(rows.clone())
                        .any(|((_, h), r)| -b[r] - h > 0.0);
                    if !apart {
                        out.extend(rows.clone());
                    }
                    at = rows.end;
                }
            }
        }
    }
    out
}

/// Upper bounds of the property rows (`pdirs`) from lower bounds of their
/// negations.
fn uppers(lower_of_neg: &[f64]) -> Vec<f64> {
    lower_of_neg.iter().map(|v| -v).collect()
}

/// The search (see the module documentation). `root_b` are the property
/// rows' bounds over the box from the spec's propagator, `settled`,
/// `witnesses` and `real_only` what the opening attack found.
#[allow(clippy::too_many_arguments)]
pub(super) fn search(
    cx: &Ctx,
    chain: &ReluChain,
    net: &Network,
    rootbox: &IBox,
    root_b: Vec<f64>,
    full: &dyn Fn(&[f64]) -> Vec<f64>,
    mut issues: Vec<Issue>,
    budget: &Budget,
    mut settled: Vec<bool>,
    mut witnesses: Vec<Option<Witness>>,
    mut real_only: Vec<Option<Vec<f64>>>,
) -> Searched {
    let ctl = cx.ctl;
    let out_of_time = || ctl.out_of_time() || budget.seconds.is_some_and(|s| (ctl.elapsed)() > s);
    // objectives: −d for every property row d (a lower bound of −d·y is
    // minus an upper bound of d·y)
    let obj: DMatrix<f64> = -cx.pdirs.transpose();
    let rows = obj.ncols();
    let mut calls = 1;
    let mut made = 1;
    let mut stop = Stop::Done;
    // the largest bound per row over the leaves proved so far
    let mut proved_union = vec![f64::NEG_INFINITY; rows];
    let absorb = |union: &mut Vec<f64>, b: &[f64]| {
        for (u, v) in union.iter_mut().zip(b) {
            *u = u.max(*v);
        }
    };
    let Some(mut root_dom) = Domain::root(net, rootbox) else {
        // no finite pre-activation bounds: the root's bounds stand
        let cells = vec![(rootbox.clone(), full(&root_b))];
        let union = full(&root_b);
        return finish(
            cells,
            union,
            calls,
            made,
            Stop::Done,
            issues,
            witnesses,
            real_only,
            None,
        );
    };
    // what a certificate needs: the root's tightening multipliers, the
    // tree, and each node's proofs
    let mut record = SplitRecord {
        nodes: vec![SplitNode::default()],
        ..SplitRecord::default()
    };
    let all_rows: Vec<usize> = (0..rows).collect();
    // the root's bounds from the ascent alone first: when they settle
    // everything, the tightening (most of an easy instance's time) is not
    // needed
    let rows_bounds = |o: &dual::Optimised| -> Vec<f64> {
        uppers(&o.bounds)
            .iter()
            .zip(&root_b)
            .map(|(a, b)| if a.is_nan() { *b } else { a.min(*b) })
            .collect()
    };
    let start = Slopes::crown(chain, &root_dom, rows);
    let mut opt = dual::optimise(chain, rootbox, &root_dom, &obj, start, ROOT_STEPS);
    calls += 1;
    record_proofs(cx, &mut record, 0, &all_rows, &opt);
    let mut root_bounds = rows_bounds(&opt);
    // the relaxation's worst inputs, as counterexample candidates
    attack(
        cx,
        &opt.worst_inputs,
        &root_bounds,
        &mut settled,
        &mut witnesses,
        &mut real_only,
    );
    if cx.worst(&root_bounds, &settled).0 < f64::INFINITY && !out_of_time() {
        let mut neurons = Vec::new();
        root_dom.tighten_recorded(
            chain,
            rootbox,
            TIGHTEN_STEPS,
            ctl.threads,
            &out_of_time,
            Some(&mut neurons),
        );
        // (kept in f64: twice an f32's bytes)
        let numbers: usize = neurons.iter().flat_map(|n| &n.nu).map(Vec::len).sum();
        if record.charge(2 * numbers) {
            record.neurons = neurons;
        }
        // the slopes found stay a valid start on the tightened domain
        let again = dual::optimise(
            chain,
            rootbox,
            &root_dom,
            &obj,
            opt.slopes.clone(),
            ROOT_STEPS,
        );
        calls += 1;
        record_proofs(cx, &mut record, 0, &all_rows, &again);
        let b = rows_bounds(&again);
        // the tighter domain's bounds hold too (every domain bound is
        // valid): keep the better of the two per row
        root_bounds = root_bounds.iter().zip(&b).map(|(a, b)| a.min(*b)).collect();
        attack(
            cx,
            &again.worst_inputs,
            &root_bounds,
            &mut settled,
            &mut witnesses,
            &mut real_only,
        );
        opt = again;
    }
    let mut queue: std::collections::BinaryHeap<Open> = std::collections::BinaryHeap::new();
    let mut subs: Vec<Option<Sub>> = Vec::new();
    let (w0, _) = cx.worst(&root_bounds, &settled);
    let limit = (super::QUEUE_BYTES / sub_bytes(&root_dom, rows)).max(1);
    let root_slopes = opt.slopes;
    // the root as the one open subproblem (each phase starts from it)
    let root_sub = || Sub {
        dom: root_dom.clone(),
        slopes: root_slopes.clone(),
        bounds: root_bounds.clone(),
        node: 0,
    };
    if w0 < f64::INFINITY {
        subs.push(Some(root_sub()));
        queue.push(Open { at: 0, worst: w0 });
    } else {
        absorb(&mut proved_union, &root_bounds);
    }
    // open subproblems kept when the search stops with no split left
    let mut stuck: Vec<Vec<f64>> = Vec::new();
    // the first phase's end: half the calls, and half the time left
    let started = (ctl.elapsed)();
    let limit_s = match (ctl.time_limit, budget.seconds) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    };
    let phases = cx.plan.phases;
    let switch_due = |made: usize| {
        phases == ActivationPhases::Portfolio
            && (made >= budget.calls / 2
                || limit_s.is_some_and(|t| (ctl.elapsed)() >= started + (t - started) / 2.0))
    };
    let mut rebound = phases == ActivationPhases::Rebound;
    record.rebound = rebound;
    while !queue.is_empty() {
        if !rebound && switch_due(made) {
            // the second phase: the search again from the root, splitting
            // in the first unstable layer and re-bounding the later ones
            rebound = true;
            queue.clear();
            subs.clear();
            stuck.clear();
            proved_union = vec![f64::NEG_INFINITY; rows];
            if record.dropped.is_none() {
                record.nodes.truncate(1);
                if let Some(n) = record.nodes.first_mut() {
                    n.split = None;
                }
            }
            record.rebound = true;
            subs.push(Some(root_sub()));
            queue.push(Open { at: 0, worst: w0 });
            continue;
        }
        if let Some(why) = halt(&settled, out_of_time(), made, budget, queue.len(), limit) {
            stop = why;
            break;
        }
        let room = (budget.calls - made) / 2;
        let take = BATCH.min(room.max(1));
        // the children: their domain, their parent's multipliers (the
        // ascent's start) and bounds (which hold on them too)
        let mut kids: Vec<Kid> = Vec::with_capacity(2 * take);
        // the layer each child's split is in
        let mut kids_layer: Vec<usize> = Vec::with_capacity(2 * take);
        let mut popped: Vec<(Sub, usize)> = Vec::with_capacity(take);
        while popped.len() < take {
            let Some(node) = queue.pop() else { break };
            let sub = subs[node.at].take().expect("a queued subproblem");
            let (_, row) = cx.worst(&sub.bounds, &settled);
            let Some(row) = row else {
                absorb(&mut proved_union, &sub.bounds);
                continue;
            };
            popped.push((sub, row));
        }
        // the branching decisions on the threads (each parent's own: the
        // same whatever the thread count)
        let choices = super::super::map_ordered(&popped, ctl.threads, &|(sub, row)| {
            dual::branch(
                chain,
                rootbox,
                &sub.dom,
                &obj,
                &sub.slopes,
                *row,
                BRANCH_TOP,
                rebound,
            )
        });
        for ((sub, _), choice) in popped.into_iter().zip(choices) {
            match choice {
                Some((k, j)) => {
                    let cols = open_rows(cx, &sub.bounds, &settled);
                    let bounds = sub.bounds;
                    let first = record.nodes.len();
                    if record.dropped.is_none() {
                        record.nodes[sub.node].split = Some((k, j, first, first + 1));
                        record.nodes.push(SplitNode::default());
                        record.nodes.push(SplitNode::default());
                    }
                    for (i, p) in [Phase::Inactive, Phase::Active].into_iter().enumerate() {
                        kids_layer.push(k);
                        kids.push((
                            sub.dom.split(k, j, p),
                            sub.slopes.clone(),
                            bounds.clone(),
                            cols.clone(),
                            first + i,
                        ));
                    }
                }
                None => {
                    // every neuron's sign is fixed: the relaxation is the
                    // network on this piece, and a longer ascent reaches
                    // its exact extreme; if that does not prove it, it
                    // stays open
                    let cols = open_rows(cx, &sub.bounds, &settled);
                    let part = obj.select_columns(cols.iter());
                    let o = dual::optimise(
                        chain,
                        rootbox,
                        &sub.dom,
                        &part,
                        sub.slopes.columns(&cols),
                        LEAF_STEPS,
                    );
                    calls += 1;
                    record_proofs(cx, &mut record, sub.node, &cols, &o);
                    let mut b = sub.bounds;
                    for (i, &c) in cols.iter().enumerate() {
                        let v = -o.bounds[i];
                        if !v.is_nan() {
                            b[c] = b[c].min(v);
                        }
                    }
                    if cx.worst(&b, &settled).0 == f64::INFINITY {
                        absorb(&mut proved_union, &b);
                    } else {
                        stuck.push(b);
                    }
                }
            }
        }
        if kids.is_empty() {
            continue;
        }
        // the children's later layers re-bounded, in the fixed groups
        // below (so the bounds never depend on the thread count)
        let mut layers: Vec<usize> = kids_layer;
        let packed: Vec<Vec<(Domain, usize)>> = {
            let mut out = Vec::new();
            let mut it = kids.iter_mut().zip(layers.drain(..));
            loop {
                let g: Vec<(Domain, usize)> = it
                    .by_ref()
                    .take(GROUP)
                    .map(|(kid, k)| (std::mem::take(&mut kid.0), k))
                    .collect();
                if g.is_empty() {
                    break;
                }
                out.push(g);
            }
            out
        };
        let rebounded = super::super::map_ordered(&packed, ctl.threads, &|g| {
            let mut g = g.clone();
            if rebound {
                dual::rebound_after(chain, rootbox, &mut g);
            }
            g
        });
        for (kid, (d, _)) in kids.iter_mut().zip(rebounded.into_iter().flatten()) {
            kid.0 = d;
        }
        // a child no input reaches holds every row: a leaf (the checker
        // finds it empty the same way)
        kids.retain(|kid| !kid.0.is_empty());
        let late = &out_of_time;
        // groups of a fixed size (never set by the threads: a group's
        // columns share products, so its bounds may depend on it)
        let groups: Vec<&[Kid]> = kids.chunks(GROUP).collect();
        let bounded: Vec<Option<dual::Optimised>> =
            super::super::map_ordered(&groups, ctl.threads, &|g| {
                if late() {
                    return vec![None; g.len()];
                }
                let jobs = g
                    .iter()
                    .map(|(dom, start, _, cols, _)| {
                        (dom, obj.select_columns(cols.iter()), start.columns(cols))
                    })
                    .collect();
                dual::optimise_many(chain, rootbox, jobs, CHILD_STEPS)
                    .into_iter()
                    .map(Some)
                    .collect::<Vec<_>>()
            })
            .into_iter()
            .flatten()
            .collect();
        calls += bounded.iter().filter(|b| b.is_some()).count();
        made += kids.len();
        (ctl.progress)(Progress {
            phase: Stage::Cells,
            done: made,
            total: Some(budget.calls),
        });
        // the open children's relaxed worst inputs, attacked after the
        // round: only the [`ATTACKS_PER_ROUND`] worst
        let mut targets: Vec<(f64, Vec<f64>, Vec<f64>)> = Vec::new();
        for ((dom, start, parent, cols, node), got) in kids.into_iter().zip(bounded) {
            let (b, slopes, worst_inputs) = match got {
                Some(o) => {
                    record_proofs(cx, &mut record, node, &cols, &o);
                    let mut b = parent.clone();
                    for (i, &c) in cols.iter().enumerate() {
                        let v = -o.bounds[i];
                        if !v.is_nan() {
                            b[c] = b[c].min(v);
                        }
                    }
                    let mut slopes = start;
                    slopes.set_columns(&cols, &o.slopes);
                    (b, slopes, o.worst_inputs)
                }
                None => (parent, start, Vec::new()),
            };
            let (w, decisive) = cx.worst(&b, &settled);
            if w == f64::INFINITY {
                absorb(&mut proved_union, &b);
                continue;
            }
            // from the decisive row's worst input only (an attack per
            // row and child would cost more than the bounds)
            if let Some(x) = decisive
                .and_then(|r| cols.iter().position(|&c| c == r))
                .and_then(|i| worst_inputs.get(i).cloned())
            {
                targets.push((w, x, b.clone()));
            }
            subs.push(Some(Sub {
                dom,
                slopes,
                bounds: b,
                node,
            }));
            queue.push(Open {
                at: subs.len() - 1,
                worst: w,
            });
        }
        // worst margin first; ties keep the children's order
        targets.sort_by(|a, b| a.0.total_cmp(&b.0));
        for (_, x, b) in targets.into_iter().take(ATTACKS_PER_ROUND) {
            if out_of_time() {
                break;
            }
            attack(cx, &[x], &b, &mut settled, &mut witnesses, &mut real_only);
        }
    }
    let mut union = proved_union;
    for n in queue.into_iter() {
        if let Some(s) = subs[n.at].as_ref() {
            absorb(&mut union, &s.bounds);
        }
    }
    for b in &stuck {
        absorb(&mut union, b);
    }
    // a row no leaf bounded (every leaf proved before it was bounded) keeps
    // the root's
    for (u, r) in union.iter_mut().zip(&root_bounds) {
        if *u == f64::NEG_INFINITY {
            *u = *r;
        }
    }
    let union = full(&union);
    let cells = vec![(rootbox.clone(), union.clone())];
    issues.sort_by_key(|i| format!("{i:?}"));
    issues.dedup();
    finish(
        cells,
        union,
        calls,
        made,
        stop,
        issues,
        witnesses,
        real_only,
        Some(record),
    )
}

/// Try each worst input as a counterexample of every open property whose
/// margin `b` does not prove it, then a few gradient steps from it.
fn attack(
    cx: &Ctx,
    starts: &[Vec<f64>],
    b: &[f64],
    settled: &mut [bool],
    witnesses: &mut [Option<Witness>],
    real_only: &mut [Option<Vec<f64>>],
) {
    if starts.is_empty() {
        return;
    }
    for k in 0..cx.props().len() {
        if settled[k] || !cx.may_falsify[k] {
            continue;
        }
        let (v, _) = cell_margin(&cx.props()[k].kind, b, &cx.ranges[k]);
        if proved(&cx.props()[k].kind, v) {
            continue;
        }
        if let Some(w) = cx.pgd(k, cx.region, starts, ATTACK_STEPS, &mut real_only[k]) {
            witnesses[k] = Some(w);
            settled[k] = true;
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn finish(
    cells: Vec<(IBox, Vec<f64>)>,
    union: Vec<f64>,
    calls: usize,
    made: usize,
    stop: Stop,
    issues: Vec<Issue>,
    witnesses: Vec<Option<Witness>>,
    real_only: Vec<Option<Vec<f64>>>,
    record: Option<SplitRecord>,
) -> Searched {
    Searched {
        bounded: Bounded {
            cells,
            union,
            calls,
            stop,
            issues,
        },
        made,
        witnesses,
        real_only,
        activations: true,
        record,
    }
}
