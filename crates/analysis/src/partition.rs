//! Partitioners: split an input box into cells, guided by a score per cell.
//!
//! One engine serves the open-loop analysis of a network (the control box of
//! `sg_ibp_separate`) and the closed-loop partitioners over `X0`:
//!
//! * **SG** (simulation-guided, after Xiang et al.): cells are taken depth
//!   first; a cell whose bound lies inside the Monte Carlo hull (score ≤ 0) is
//!   final, any other is bisected until the budget or the minimum size stops it.
//! * **GSG** (greedy SG, after Everett et al.): the cell with the largest
//!   score is refined first, so a limited budget is spent where the bound is
//!   worst; refinement stops when every cell scores ≤ 0 or the budget is spent.
//!
//! A cell is bisected along the dimension that is widest relative to the
//! root box (two children per split, so the cost stays linear in the state
//! dimension), or, with a [`Bisector::Weighted`], along the dimension whose
//! relative width times `FLOOR + w` is largest, `w ∈ [0, 1]` the caller's
//! estimate of how much of a cell's trouble a split there removes (the
//! nonlinear loops' controller slack, [`crate::nonlinear::NonlinearLoop::split_weights`]). The score function decides what "worst" means: how far a
//! bound leaves the sampled outputs for SG/GSG ([`super::shape::excess`]),
//! the negative property margin for the property-guided closed-loop
//! partitioner.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use crate::sets::IBox;

/// Which cell to refine next.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Strategy {
    /// Depth first; stop refining cells that score ≤ 0.
    Sg,
    /// The cell with the largest score first.
    Gsg,
}

/// When refinement stops.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Budget {
    /// Most evaluations of a cell (the root counts).
    pub calls: usize,
    /// Cells narrower than this fraction of the root along every dimension are not split.
    pub min_size: f64,
    /// Wall-clock limit in seconds (checked between evaluations), if any.
    pub seconds: Option<f64>,
}

/// Why a partition has the cells it has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stop {
    /// A uniform grid: the cells were fixed in advance.
    Grid,
    /// Refinement ended: every cell settled (nothing left to gain, or too small to split).
    Done,
    /// The call budget was spent.
    Calls,
    /// The time budget (or the run's time limit) was spent.
    Time,
    /// Branch and bound: every property was settled (proved, or a
    /// counterexample confirmed) before every cell was.
    Decided,
    /// Branch and bound: the queue of open subproblems reached its memory
    /// limit.
    Queue,
}

impl Stop {
    /// The name used in the JSON report.
    pub fn as_str(self) -> &'static str {
        match self {
            Stop::Grid => "grid",
            Stop::Done => "done",
            Stop::Calls => "calls",
            Stop::Time => "time",
            Stop::Decided => "decided",
            Stop::Queue => "queue",
        }
    }
}

/// A final cell with its evaluation and score.
#[derive(Clone, Debug)]
pub struct Leaf<T> {
    /// The cell.
    pub cell: IBox,
    /// What the evaluation returned.
    pub value: T,
    /// Its score (≤ 0: nothing left to gain).
    pub score: f64,
}

/// What a refinement did.
#[derive(Clone, Debug)]
pub struct Refined<T> {
    /// The final cells; their union is the root box.
    pub leaves: Vec<Leaf<T>>,
    /// Evaluations made.
    pub calls: usize,
    /// Why it stopped: [`Stop::Done`], [`Stop::Calls`] or [`Stop::Time`].
    pub stop: Stop,
}

struct Queued<T> {
    score: f64,
    order: usize,
    leaf: Leaf<T>,
}

impl<T> PartialEq for Queued<T> {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl<T> Eq for Queued<T> {}
impl<T> PartialOrd for Queued<T> {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl<T> Ord for Queued<T> {
    fn cmp(&self, o: &Self) -> Ordering {
        // largest score first; ties: earlier cell first (deterministic)
        self.score
            .total_cmp(&o.score)
            .then_with(|| o.order.cmp(&self.order))
    }
}

/// Evaluates a cell (given its parent's value): the value and its score.
pub type CellEval<'e, T> = dyn FnMut(&IBox, Option<&T>) -> (T, f64) + 'e;

/// How a cell chooses the dimension it is split along.
#[derive(Clone, Copy)]
pub enum Bisector<'w> {
    /// The widest relative to the root ([`bisect`]).
    Widest,
    /// Relative width times `FLOOR + wᵢ`, the weights `wᵢ ∈ [0, 1]` given
    /// per cell (`None`, or weights that are not finite, count as 0: the
    /// widest dimension then wins).
    Weighted(&'w (dyn Fn(&IBox) -> Option<Vec<f64>> + Sync)),
}

/// The part of a dimension's score that does not depend on its weight: a
/// dimension that a split helps most (`w = 1`) still yields to one three
/// times wider relative to the root that it does not help (`w = 0`). A
/// smaller floor follows the weights further: with 0.25 (and weights not
/// yet scaled by the bounds' looseness), ReachNN B4's property-guided
/// partition needed 68 cells instead of 58 (47 along the widest
/// dimension: its difficulty is the plant, not the controller), while
/// QUAD's published controller verifies with 8 cells with either (and
/// with none along the widest dimension).
const FLOOR: f64 = 0.5;

/// Bisect `cell` along its widest dimension relative to `root`, or `None`
/// when every dimension is already below `min_size` of the root.
pub fn bisect(cell: &IBox, root: &IBox, min_size: f64) -> Option<(IBox, IBox)> {
    bisect_weighted(cell, root, min_size, None)
}

/// [`bisect`] with the dimension's relative width multiplied by
/// `FLOOR + wᵢ` (`wᵢ` clamped to `[0, 1]`, 0 when not finite).
pub fn bisect_weighted(
    cell: &IBox,
    root: &IBox,
    min_size: f64,
    weights: Option<&[f64]>,
) -> Option<(IBox, IBox)> {
    let mut best: Option<(usize, f64)> = None;
    for d in 0..cell.dim() {
        let rw = root.hi[d] - root.lo[d];
        if rw <= 0.0 {
            continue;
        }
        let rel = (cell.hi[d] - cell.lo[d]) / rw;
        let w = weights
            .and_then(|w| w.get(d))
            .copied()
            .filter(|w| w.is_finite())
            .map_or(0.0, |w| w.clamp(0.0, 1.0));
        let score = if weights.is_some() {
            rel * (FLOOR + w)
        } else {
            rel
        };
        if rel > min_size && best.is_none_or(|b| score > b.1) {
            best = Some((d, score));
        }
    }
    let (d, _) = best?;
    let mid = cell.lo[d] + 0.5 * (cell.hi[d] - cell.lo[d]);
    if !(cell.lo[d] < mid && mid < cell.hi[d]) {
        return None;
    }
    let mut a = cell.clone();
    a.hi[d] = mid;
    let mut b = cell.clone();
    b.lo[d] = mid;
    Some((a, b))
}

/// Refine `root` with `eval` (which returns a value and its score; it is
/// handed the parent cell's value, so a child can be kept inside its parent),
/// the split dimensions chosen by `bisector`.
/// `elapsed` returns seconds since the start (only called with a time budget).
pub fn refine<T>(
    root: &IBox,
    strategy: Strategy,
    budget: &Budget,
    eval: &mut CellEval<T>,
    elapsed: &dyn Fn() -> f64,
    bisector: Bisector,
) -> Refined<T> {
    let first = eval(root, None);
    refine_from(
        root,
        strategy,
        budget,
        first,
        &mut |b, a, parent| {
            let vb = eval(b, Some(parent));
            let va = eval(a, Some(parent));
            (vb, va)
        },
        elapsed,
        bisector,
    )
}

/// [`refine`] with the two children of every split evaluated at once,
/// one on a helper thread (when `threads ≥ 2`). The cells chosen (the
/// split dimensions on the calling thread), their values and the result
/// are exactly those of [`refine`]: only the wall-clock time changes
/// (each split's children are independent).
pub fn refine_parallel<T: Send + Clone>(
    root: &IBox,
    strategy: Strategy,
    budget: &Budget,
    eval: &SharedCellEval<T>,
    elapsed: &dyn Fn() -> f64,
    threads: usize,
    bisector: Bisector,
) -> Refined<T> {
    let Some(helper) = crate::pool::Helper::new(threads) else {
        return refine(
            root,
            strategy,
            budget,
            &mut |c, p| eval(c, p),
            elapsed,
            bisector,
        );
    };
    let (jobs, job_rx) = std::sync::mpsc::channel::<(IBox, T)>();
    let (res_tx, results) = std::sync::mpsc::channel::<(T, f64)>();
    let evaluate = move || {
        while let Some((cell, parent)) = recv_soon(&job_rx) {
            if res_tx.send(eval(&cell, Some(&parent))).is_err() {
                break;
            }
        }
    };
    helper.beside(evaluate, || {
        let first = eval(root, None);
        let r = refine_from(
            root,
            strategy,
            budget,
            first,
            &mut |b, a, parent| {
                let sent = jobs.send((a.clone(), parent.clone())).is_ok();
                let vb = eval(b, Some(parent));
                // a helper that failed (it panicked; the scope re-raises it
                // when it ends) leaves the child to this thread
                let va = match sent.then(|| recv_soon(&results)).flatten() {
                    Some(v) => v,
                    None => eval(a, Some(parent)),
                };
                (vb, va)
            },
            elapsed,
            bisector,
        );
        drop(jobs);
        r
    })
}

/// How long a thread of [`refine_parallel`] polls for the other's message
/// before it sleeps on the channel. Waking a sleeping thread took tens of
/// microseconds on the build machines (a virtual machine), at every split,
/// twice: a cell's evaluation takes about as long. Polling yields the
/// processor each time, so on a machine with fewer cores than threads the
/// other thread still runs.
const SPIN: std::time::Duration = std::time::Duration::from_micros(300);

/// The next message, polled for up to [`SPIN`] and then waited for; `None`
/// once the sender is gone.
fn recv_soon<T>(rx: &std::sync::mpsc::Receiver<T>) -> Option<T> {
    let start = std::time::Instant::now();
    loop {
        match rx.try_recv() {
            Ok(v) => return Some(v),
            Err(std::sync::mpsc::TryRecvError::Disconnected) => return None,
            Err(std::sync::mpsc::TryRecvError::Empty) => {
                if start.elapsed() > SPIN {
                    return rx.recv().ok();
                }
                std::thread::yield_now();
            }
        }
    }
}

/// A [`CellEval`] that threads can share.
pub type SharedCellEval<'e, T> = dyn Fn(&IBox, Option<&T>) -> (T, f64) + Sync + 'e;

/// Evaluates the two children of a split (`b` first, then `a`) given their parent's value.
type PairEval<'e, T> = dyn FnMut(&IBox, &IBox, &T) -> ((T, f64), (T, f64)) + 'e;

/// The refinement loop, from the root's evaluation `first`.
fn refine_from<T>(
    root: &IBox,
    strategy: Strategy,
    budget: &Budget,
    first: (T, f64),
    pair: &mut PairEval<T>,
    elapsed: &dyn Fn() -> f64,
    bisector: Bisector,
) -> Refined<T> {
    let mut calls = 1usize;
    let mut order = 0usize;
    let mut done: Vec<Leaf<T>> = Vec::new();
    let mut stop = Stop::Done;
    let (v, score) = first;
    let first = Leaf {
        cell: root.clone(),
        value: v,
        score,
    };
    let mut heap = BinaryHeap::new();
    let mut stack = Vec::new();
    match strategy {
        Strategy::Gsg => heap.push(Queued {
            score,
            order,
            leaf: first,
        }),
        Strategy::Sg => stack.push(first),
    }
    loop {
        let leaf = match strategy {
            Strategy::Gsg => match heap.pop() {
                Some(q) => q.leaf,
                None => break,
            },
            Strategy::Sg => match stack.pop() {
                Some(l) => l,
                None => break,
            },
        };
        if leaf.score <= 0.0 {
            done.push(leaf);
            if strategy == Strategy::Gsg {
                // the best remaining cell has nothing to gain: neither has any other
                break;
            }
            continue;
        }
        if calls + 2 > budget.calls {
            stop = Stop::Calls;
            done.push(leaf);
            break;
        }
        if budget.seconds.is_some_and(|s| elapsed() >= s) {
            stop = Stop::Time;
            done.push(leaf);
            break;
        }
        let split = match bisector {
            Bisector::Widest => bisect(&leaf.cell, root, budget.min_size),
            Bisector::Weighted(weights) => {
                let w = weights(&leaf.cell);
                bisect_weighted(&leaf.cell, root, budget.min_size, w.as_deref())
            }
        };
        let Some((a, b)) = split else {
            done.push(leaf);
            continue;
        };
        let ((vb, sb), (va, sa)) = pair(&b, &a, &leaf.value);
        for (c, value, score) in [(b, vb, sb), (a, va, sa)] {
            calls += 1;
            order += 1;
            let l = Leaf {
                cell: c,
                value,
                score,
            };
            match strategy {
                Strategy::Gsg => heap.push(Queued {
                    score,
                    order,
                    leaf: l,
                }),
                Strategy::Sg => stack.push(l),
            }
        }
    }
    done.extend(stack);
    done.extend(heap.into_iter().map(|q| q.leaf));
    Refined {
        leaves: done,
        calls,
        stop,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cover_check(leaves: &[IBox], root: &IBox) {
        let vol: f64 = leaves.iter().map(IBox::volume).sum();
        assert!((vol - root.volume()).abs() < 1e-12 * root.volume().max(1.0));
        for l in leaves {
            assert!(root.contains_box(l));
        }
    }

    #[test]
    fn both_strategies_cover_the_root_and_respect_the_budget() {
        let root = IBox::new(vec![-1.0, -1.0], vec![1.0, 1.0]);
        for strategy in [Strategy::Sg, Strategy::Gsg] {
            let budget = Budget {
                calls: 21,
                min_size: 0.01,
                seconds: None,
            };
            // score: how far the cell reaches beyond x ≤ 0.3
            let r = refine(
                &root,
                strategy,
                &budget,
                &mut |c, _| ((), c.hi[0] - 0.3),
                &|| 0.0,
                Bisector::Widest,
            );
            assert!(r.calls <= 21, "{strategy:?}: {}", r.calls);
            let cells: Vec<IBox> = r.leaves.iter().map(|l| l.cell.clone()).collect();
            cover_check(&cells, &root);
            // the same cells, values and order with the children on two threads
            let eval = |c: &IBox, _: Option<&f64>| (c.lo[1], c.hi[0] - 0.3);
            let on = |threads| {
                let widest = Bisector::Widest;
                refine_parallel(&root, strategy, &budget, &eval, &|| 0.0, threads, widest)
            };
            let (one, two) = (on(1), on(2));
            assert_eq!((one.calls, one.stop), (two.calls, two.stop));
            let key = |r: &Refined<f64>| -> Vec<(Vec<f64>, Vec<f64>, f64, f64)> {
                r.leaves
                    .iter()
                    .map(|l| (l.cell.lo.clone(), l.cell.hi.clone(), l.value, l.score))
                    .collect()
            };
            assert_eq!(key(&one), key(&two));
        }
    }

    #[test]
    fn refinement_stops_when_every_cell_is_good() {
        let root = IBox::new(vec![0.0], vec![1.0]);
        let budget = Budget {
            calls: 1000,
            min_size: 1e-6,
            seconds: None,
        };
        let r = refine(
            &root,
            Strategy::Gsg,
            &budget,
            &mut |c, _| ((), c.hi[0] - c.lo[0] - 0.25),
            &|| 0.0,
            Bisector::Widest,
        );
        assert_eq!(r.stop, Stop::Done);
        assert_eq!(r.leaves.len(), 4);
        assert!(r.leaves.iter().all(|l| l.score <= 0.0));
    }

    /// Weights steer the split until a dimension is `1/FLOOR + 1` times
    /// narrower; weights that are not finite count as 0; the cells on two
    /// threads are those on one.
    #[test]
    fn weights_choose_the_split_dimension() {
        let root = IBox::new(vec![0.0, 0.0], vec![1.0, 1.0]);
        let toward_1 = [0.0, 1.0];
        let (a, _) = bisect_weighted(&root, &root, 0.0, Some(&toward_1)).unwrap();
        assert_eq!((a.hi[0], a.hi[1]), (1.0, 0.5));
        // without weights, the first of the widest
        let (a, _) = bisect(&root, &root, 0.0).unwrap();
        assert_eq!((a.hi[0], a.hi[1]), (0.5, 1.0));
        // dimension 1 at a quarter of dimension 0: 0.25·1.5 < 1·0.5
        let thin = IBox::new(vec![0.0, 0.0], vec![1.0, 0.25]);
        let (a, _) = bisect_weighted(&thin, &root, 0.0, Some(&toward_1)).unwrap();
        assert_eq!((a.hi[0], a.hi[1]), (0.5, 0.25));
        let nan = [0.0, f64::NAN];
        let (a, _) = bisect_weighted(&root, &root, 0.0, Some(&nan)).unwrap();
        assert_eq!((a.hi[0], a.hi[1]), (0.5, 1.0));
        let budget = Budget {
            calls: 15,
            min_size: 0.01,
            seconds: None,
        };
        let weights = |_: &IBox| Some(vec![0.0, 1.0]);
        let eval = |c: &IBox, _: Option<&f64>| (c.lo[1], 1.0 + c.hi[0]);
        let run = |threads| {
            refine_parallel(
                &root,
                Strategy::Gsg,
                &budget,
                &eval,
                &|| 0.0,
                threads,
                Bisector::Weighted(&weights),
            )
        };
        let (one, two) = (run(1), run(2));
        let key = |r: &Refined<f64>| -> Vec<(Vec<f64>, Vec<f64>)> {
            r.leaves
                .iter()
                .map(|l| (l.cell.lo.clone(), l.cell.hi.clone()))
                .collect()
        };
        assert_eq!(key(&one), key(&two));
        // the weighted dimension is cut finer than the other
        let finest = |d: usize| {
            one.leaves
                .iter()
                .map(|l| l.cell.hi[d] - l.cell.lo[d])
                .fold(f64::INFINITY, f64::min)
        };
        assert!(finest(1) < finest(0), "{:?}", key(&one));
    }
}
