//! The cells of a closed loop's initial set: each carried through the
//! horizon, its margins per property, and the uniform and guided
//! partitions whose cells' shares of the report (`Gathered`) are merged in
//! cell order.

use crate::lower::{GoalMode, Guide, Property, PropertyKind, SystemPlan, Window};
use ravel_analysis::closed_loop::{ClosedLoop, Cut, Propagator, Step};
use ravel_analysis::feedback::Loop;
use ravel_analysis::issue::Issue;
use ravel_analysis::lp;
use ravel_analysis::partition::{refine_parallel, Bisector, Budget, Stop, Strategy};
use ravel_analysis::sets::{Affine, IBox, Polytope, Region};
use ravel_analysis::shape::excess;

use super::constraints;
use super::sampling::{offsets, Sampled};
use super::*;

/// Reachable sets of one cell over the horizon. With `parent` (the sets of a
/// cell containing this one), every set is intersected with the parent's, so
/// a partition is never looser than the cell it refines.
pub fn propagate_cell(plan: &SystemPlan, cell: &Region, parent: Option<&[Step]>) -> Vec<Step> {
    propagate_cell_until(plan, cell, parent, &|| false)
}

/// [`propagate_cell`], asking `stop` before each step whether the time is
/// up; the steps left are then [`Step::timed_out`] (the whole space).
pub fn propagate_cell_until(
    plan: &SystemPlan,
    cell: &Region,
    parent: Option<&[Step]>,
    stop: &dyn Fn() -> bool,
) -> Vec<Step> {
    let cl = match &plan.closed_loop {
        Loop::Linear(cl) => cl,
        Loop::Nonlinear(nl) => {
            return nl.reach(cell, plan.horizon, &plan.boundary, parent, stop);
        }
    };
    let n = cl.states();
    if plan.propagator == Propagator::CrownUnrolled {
        let parent: Option<Vec<Region>> = parent.map(|p| p.iter().map(|s| s.set.clone()).collect());
        let mut steps = cl.unrolled(cell, plan.horizon, &plan.boundary, parent.as_deref(), stop);
        intersample(plan, cl, &mut steps);
        return steps;
    }
    let mut steps = Vec::with_capacity(plan.horizon + 1);
    steps.push(Step::new(cell.clone(), Vec::new()));
    for t in 0..plan.horizon {
        match steps[t].cut() {
            // nothing bounded is left to propagate: every later set is ℝⁿ too
            Some(Cut::Overflow) => {
                steps.push(Step::overflowed(n, Vec::new()));
                continue;
            }
            Some(cut @ (Cut::TimeLimit | Cut::Undefined | Cut::NoEnclosure)) => {
                steps.push(Step::whole(n, cut));
                continue;
            }
            None if stop() => {
                steps.push(Step::timed_out(n));
                continue;
            }
            None => {}
        }
        let mut next = cl.step(t, &steps[t].set, plan.propagator, &plan.boundary);
        if let Some(p) = parent.and_then(|p| p.get(t + 1)) {
            if next.cut().is_none() {
                next.set = next.set.intersect(&p.set);
            }
        }
        steps.push(next);
    }
    intersample(plan, cl, &mut steps);
    steps
}

/// A linear plant in continuous time: the states over every control period
/// that a property's window covers (the period `t` ends at step `t`), one
/// box for the whole period, from
/// the box of step `t − 1` by the validated flow of `ẋ = A x + B u + c`,
/// the controls composed with the state through CROWN's linear bounds over
/// the observation set (`NonlinearLoop::pipe`). A period that cannot be enclosed is the whole
/// space (it proves nothing).
fn intersample(plan: &SystemPlan, cl: &ClosedLoop, steps: &mut [Step]) {
    let Some(loops) = plan.intersample.as_ref().map(|i| &i.loops) else {
        return;
    };
    // the periods some property constrains (the period `t` ends at step `t`)
    let windows: Vec<(usize, usize)> = plan.properties.iter().map(|p| p.window().periods).collect();
    let n = cl.states();
    for t in 1..steps.len() {
        if !windows.iter().any(|&(a, b)| a <= t && t <= b) {
            continue;
        }
        let Some(lp) = loops.get((t - 1).min(loops.len().saturating_sub(1))) else {
            continue;
        };
        let before = &steps[t - 1];
        let pipe = if before.cut().is_some() {
            None
        } else {
            lp.pipe(&before.set.bbox())
        };
        steps[t].between = Some(vec![pipe.unwrap_or_else(|| IBox::whole(n))]);
    }
}

/// The first step whose set is not a computed bound, and why.
pub(super) fn first_cut(sets: &[Step]) -> Option<(usize, Cut)> {
    sets.iter()
        .enumerate()
        .find_map(|(t, s)| s.cut().map(|c| (t, c)))
}

/// A margin that is NaN (an overflow inside a margin computation) proves
/// nothing: it becomes `−∞`.
pub(super) fn sane(m: f64) -> f64 {
    if m.is_nan() {
        f64::NEG_INFINITY
    } else {
        m
    }
}

/// Whether a cell is certainly empty (a polytope cell of a polytope initial set).
pub(super) fn certainly_empty(cell: &Region) -> bool {
    match cell {
        Region::Polytope { bbox, rows } => {
            lp::separation(&[], rows, &bbox.lo, &bbox.hi).value > 0.0
        }
        Region::Box(_) | Region::Ball { .. } => false,
    }
}

/// A certified margin of one property on one cell's sets, with the step it
/// refers to and whether an LP solver issue weakened it. A set that
/// overflowed gives the margin `−∞` at its step (never a proof); so does a
/// margin computation that produced NaN.
///
/// A goal that must hold always and an avoid set take the least margin over
/// the window's instants and the periods between them (a continuous-time
/// plant's intersample enclosures, every piece of a period); a goal that must hold
/// eventually takes the largest containment margin over the window's
/// instants: one instant whose set lies inside proves it on the cell.
pub(super) fn cell_margin(prop: &Property, sets: &[Step]) -> Margin {
    match &prop.kind {
        PropertyKind::Goal {
            set,
            window,
            mode: GoalMode::Always,
        } => worst_over(window, sets, &|instant, pieces, out| {
            for (r, f) in instant
                .into_iter()
                .chain(pieces.iter().map(|(r, f)| (r, *f)))
            {
                out.push(constraints::containment(set, r, f));
            }
        }),
        PropertyKind::Goal {
            set,
            window,
            mode: GoalMode::Eventually,
        } => best_over(window, sets, &|r, f| constraints::containment(set, r, f)),
        PropertyKind::Avoid { members, window } => {
            worst_over(window, sets, &|instant, pieces, out| {
                for m in members {
                    for (r, f) in instant
                        .into_iter()
                        .chain(pieces.iter().map(|(r, f)| (r, *f)))
                    {
                        out.push(constraints::separation(m, r, f));
                    }
                }
            })
        }
    }
}

/// The margins of one step: the instant's set (when the step is one of
/// the window's instants) and the period's intersample enclosure, piece by
/// piece (when the period ending at the step is one of the window's),
/// pushed in order.
/// Each set comes with its affine enclosure, where the analysis kept one.
type StepMargins<'a> = dyn Fn(Option<(&Region, Option<&Affine>)>, &[(Region, Option<&Affine>)], &mut Vec<(f64, bool)>)
    + 'a;

/// The least margin over a window (see [`cell_margin`]): the first cut
/// step in the window ends the scan with `−∞`.
fn worst_over(window: &Window, sets: &[Step], margins: &StepMargins) -> Margin {
    let mut best = Margin {
        value: f64::INFINITY,
        step: window.steps.0,
        issue: false,
    };
    let first = if window.periods.0 <= window.periods.1 {
        window.steps.0.min(window.periods.0)
    } else {
        window.steps.0
    };
    let mut found = Vec::new();
    for (t, step) in sets.iter().enumerate().take(window.last() + 1).skip(first) {
        let at_instant = (window.steps.0..=window.steps.1).contains(&t);
        let at_period = window.has_period(t) && step.between.is_some();
        if !at_instant && !at_period {
            continue;
        }
        if step.cut().is_some() {
            if best.value > f64::NEG_INFINITY {
                best = Margin::cut(t, best.issue);
            }
            break;
        }
        // a continuous-time plant: the period that ends at step t lies in
        // the window too, its states in the union of the pieces
        let pieces: Vec<(Region, Option<&Affine>)> = step
            .between
            .iter()
            .filter(|_| at_period)
            .flatten()
            .enumerate()
            .map(|(j, b)| {
                let form = step.between_forms.get(j).and_then(Option::as_ref);
                (Region::Box(b.clone()), form)
            })
            .collect();
        found.clear();
        margins(
            at_instant.then_some((&step.set, step.form.as_ref())),
            &pieces,
            &mut found,
        );
        for &(s, issue) in &found {
            let s = sane(s);
            let issue = issue || !step.issues.is_empty();
            if s < best.value || (issue && !best.issue && s <= best.value) {
                best = Margin {
                    value: s,
                    step: t,
                    issue: issue || best.issue,
                };
            } else if issue {
                best.issue = true;
            }
        }
    }
    best
}

/// The margin of one instant's set (with its affine enclosure, where the
/// analysis kept one) and whether an LP solver issue weakened it.
type InstantMargin<'a> = dyn Fn(&Region, Option<&Affine>) -> (f64, bool) + 'a;

/// The largest margin over a window's instants (see [`cell_margin`]); a
/// solver issue at any instant of the window weakens it; the scan stops at
/// the first cut step.
fn best_over(window: &Window, sets: &[Step], margin: &InstantMargin) -> Margin {
    let mut best = Margin {
        value: f64::NEG_INFINITY,
        step: window.steps.0,
        issue: false,
    };
    for (t, step) in sets
        .iter()
        .enumerate()
        .take(window.steps.1 + 1)
        .skip(window.steps.0)
    {
        if step.cut().is_some() {
            break;
        }
        let (m, issue) = margin(&step.set, step.form.as_ref());
        let m = sane(m);
        best.issue |= issue || !step.issues.is_empty();
        if m > best.value {
            best.value = m;
            best.step = t;
        }
    }
    best
}

/// `min_r (hᵣ − max_{x∈S} Hᵣ x)`: non-negative means `S ⊆ P`.
pub(super) fn containment_margin(p: &Polytope, set: &Region) -> (f64, bool) {
    if let Region::Box(b) = set {
        return (p.containment_margin(b), false);
    }
    let mut issue = false;
    let m = p
        .rows
        .iter()
        .map(|(a, h)| {
            let s = set.support(a);
            issue |= s.issue.is_some();
            ravel_base::num::sum_lower([*h, -s.value])
        })
        .fold(f64::INFINITY, f64::min);
    (m, issue)
}

/// A lower bound of `min_{x∈S} max_r (Hᵣ x − hᵣ)`: positive means `S ∩ P = ∅`.
/// A single separating row is tried first; an LP decides the rest exactly.
pub(super) fn separation_margin(p: &Polytope, set: &Region) -> (f64, bool) {
    let bbox = set.bbox();
    let single = p.separation_margin(&bbox);
    if single > 0.0 && !matches!(set, Region::Polytope { .. }) {
        return (single, false);
    }
    let rows: &[(Vec<f64>, f64)] = match set {
        Region::Polytope { rows, .. } => rows,
        Region::Box(_) | Region::Ball { .. } => &[],
    };
    let lp = lp::separation(rows, &p.rows, &bbox.lo, &bbox.hi);
    (lp.value.max(single), lp.issue.is_some())
}

/// The region of a partition cell: polytope cells keep the initial set's
/// rows; ball cells are boxes (their union covers the ball); the root is the
/// initial set itself.
pub(super) fn cell_region(initial: &Region, cell: &IBox) -> Region {
    if *cell == initial.bbox() {
        return initial.clone();
    }
    match initial {
        Region::Polytope { rows, .. } => Region::Polytope {
            bbox: cell.clone(),
            rows: rows.clone(),
        },
        Region::Box(_) | Region::Ball { .. } => Region::Box(cell.clone()),
    }
}

/// The cells of a partition and their sets over the horizon.
pub(super) struct Partitioned {
    /// Each cell's bounding box.
    pub(super) cells: Vec<IBox>,
    /// `sets[c][t]`: the set of cell `c` at step `t`.
    pub(super) sets: Vec<Vec<Step>>,
    /// Why the partition has these cells.
    pub(super) stop: Stop,
    /// Cells propagated (a refinement's parents and a grid's root included).
    pub(super) calls: usize,
    /// What the outcome needs of every cell (gathered where the cell was,
    /// by the thread that propagated it).
    pub(super) gathered: Gathered,
}

/// A property's certified margin on one cell (see [`cell_margin`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Margin {
    /// The margin: non-negative proves the property on the cell.
    pub(super) value: f64,
    /// The step it refers to.
    pub(super) step: usize,
    /// Whether an LP solver issue weakened it.
    pub(super) issue: bool,
}

impl Margin {
    /// The margin of a set cut at `step` (the whole space): `−∞`, never a proof.
    fn cut(step: usize, issue: bool) -> Margin {
        Margin {
            value: f64::NEG_INFINITY,
            step,
            issue,
        }
    }
}

/// What the outcome needs of the cells: the reach hull, the solver issues,
/// the first cut and each property's least margin. Cells are added in any
/// order, by any thread, and parts merged in any order: the result is the
/// one of adding every cell in cell order (ties go to the lower cell index;
/// the hull is order-free, see [`IBox::hull_with`]). A thread gathers its own
/// cells while their sets are in its cache; summing them up afterwards on
/// one thread, from the other core's caches, took 1.7 ms of a 25 ms run of
/// 4096 cells on two threads.
#[derive(Clone, Debug)]
pub(super) struct Gathered {
    /// Cells added.
    pub(super) cells: usize,
    /// `reach[t]`: the hull of every cell's box at step `t` (empty before the
    /// first cell).
    pub(super) reach: Vec<IBox>,
    /// Every `(step, issue)` of every cell (sorted and deduplicated by
    /// [`Gathered::finish`]).
    pub(super) issues: Vec<(usize, Issue)>,
    /// The earliest cut step over the cells: `(step, cell, cut)`.
    pub(super) cut: Option<(usize, usize, Cut)>,
    /// Per property.
    pub(super) least: Vec<Least>,
}

/// One property's margins over the cells (see [`Gathered`]).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Least {
    /// The least margin below `+∞` that is not NaN, its cell and step (the
    /// lowest cell among equal margins).
    pub(super) min: Option<(f64, usize, usize)>,
    /// The highest cell whose margin is NaN, and its step.
    pub(super) nan: Option<(usize, usize)>,
    /// A solver issue on some cell's path to the margin.
    pub(super) issue: bool,
    /// The earliest cut step on the property's steps: `(step, cell, cut)`.
    pub(super) cut: Option<(usize, usize, Cut)>,
}

/// The earlier of two cuts, `(step, cell, cut)`: lower step, then lower cell.
pub(super) fn earlier(
    a: Option<(usize, usize, Cut)>,
    b: Option<(usize, usize, Cut)>,
) -> Option<(usize, usize, Cut)> {
    match (a, b) {
        (Some(x), Some(y)) => Some(if (y.0, y.1) < (x.0, x.1) { y } else { x }),
        (x, y) => x.or(y),
    }
}

impl Least {
    pub(super) fn merge(self, other: Least) -> Least {
        Least {
            min: match (self.min, other.min) {
                (Some(a), Some(b)) => Some(if b.0 < a.0 || (b.0 == a.0 && b.1 < a.1) {
                    b
                } else {
                    a
                }),
                (a, b) => a.or(b),
            },
            nan: self.nan.max(other.nan),
            issue: self.issue || other.issue,
            cut: earlier(self.cut, other.cut),
        }
    }

    /// The margin and its step, as a scan of the cells in order gives them:
    /// the first least margin; `−∞` at the last NaN's step when a margin is
    /// NaN (NaN proves nothing); `+∞` at `step` when no cell has a margin
    /// below `+∞`.
    pub(super) fn margin(&self, step: usize) -> (f64, usize) {
        match (self.nan, self.min) {
            (Some((_, t)), _) => (f64::NEG_INFINITY, t),
            (None, Some((m, _, t))) => (m, t),
            (None, None) => (f64::INFINITY, step),
        }
    }
}

impl Gathered {
    /// No cell yet.
    pub(super) fn new(plan: &SystemPlan) -> Gathered {
        Gathered {
            cells: 0,
            reach: Vec::new(),
            issues: Vec::new(),
            cut: None,
            least: vec![Least::default(); plan.properties.len()],
        }
    }

    /// Adds cell `cell`'s sets.
    pub(super) fn add(&mut self, plan: &SystemPlan, cell: usize, sets: &[Step]) {
        self.cells += 1;
        if self.reach.is_empty() {
            self.reach = sets.iter().map(|s| s.set.bbox()).collect();
        } else {
            for (h, s) in self.reach.iter_mut().zip(sets) {
                h.hull_with(&s.set.bbox_ref());
            }
        }
        for (t, s) in sets.iter().enumerate() {
            self.issues.extend(s.issues.iter().map(|i| (t, *i)));
        }
        let cut = first_cut(sets).map(|(t, c)| (t, cell, c));
        self.cut = earlier(self.cut, cut);
        for (l, prop) in self.least.iter_mut().zip(&plan.properties) {
            let Margin {
                value: m,
                step: t,
                issue,
            } = cell_margin(prop, sets);
            let mine = Least {
                min: (m < f64::INFINITY).then_some((m, cell, t)),
                nan: m.is_nan().then_some((cell, t)),
                issue,
                cut: cut.filter(|c| c.0 <= prop.last_step()),
            };
            *l = l.merge(mine);
        }
    }

    /// The cells of both.
    pub(super) fn merge(mut self, other: Gathered) -> Gathered {
        self.cells += other.cells;
        if self.reach.is_empty() {
            self.reach = other.reach;
        } else {
            for (h, o) in self.reach.iter_mut().zip(&other.reach) {
                h.hull_with(o);
            }
        }
        self.issues.extend(other.issues);
        self.cut = earlier(self.cut, other.cut);
        for (l, o) in self.least.iter_mut().zip(other.least) {
            *l = l.merge(o);
        }
        self
    }

    /// The issues sorted and deduplicated.
    pub(super) fn finish(mut self) -> Gathered {
        self.issues.sort_unstable();
        self.issues.dedup();
        self
    }
}

/// A uniform grid over the initial set, each cell propagated (inside the
/// whole set's sets when there are several).
pub(super) fn partition_uniform(plan: &SystemPlan, grid: &[usize], ctl: &Control) -> Partitioned {
    let stop = || ctl.out_of_time();
    // one cell is the initial set itself (a ball keeps its
    // closed-form support function instead of its bounding box)
    let regions: Vec<Region> = if grid.iter().all(|k| *k == 1) {
        vec![plan.initial.clone()]
    } else {
        plan.initial
            .grid(grid)
            .into_iter()
            .filter(|c| !certainly_empty(c))
            .collect()
    };
    let regions = if regions.is_empty() {
        vec![plan.initial.clone()]
    } else {
        regions
    };
    // the whole initial set first: every cell is kept inside it
    let root = (regions.len() > 1).then(|| propagate_cell_until(plan, &plan.initial, None, &stop));
    let calls = regions.len() + usize::from(root.is_some());
    let one = |i: usize| {
        (ctl.progress)(Progress {
            phase: Phase::Cells,
            done: i,
            total: Some(regions.len()),
        });
        propagate_cell_until(plan, &regions[i], root.as_deref(), &stop)
    };
    let threads = ravel_analysis::pool::available(ctl.threads).clamp(1, regions.len().max(1));
    let (sets, gathered) = if threads == 1 {
        let mut gathered = Gathered::new(plan);
        let sets: Vec<Vec<Step>> = (0..regions.len())
            .map(|i| {
                let sets = one(i);
                gathered.add(plan, i, &sets);
                sets
            })
            .collect();
        (sets, gathered)
    } else {
        // cells are independent: threads take the next index, and the
        // sets are put back in cell order
        let next = std::sync::atomic::AtomicUsize::new(0);
        let mut slots: Vec<Option<Vec<Step>>> = vec![None; regions.len()];
        let work = || {
            let mut mine = Vec::new();
            let mut gathered = Gathered::new(plan);
            loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if i >= regions.len() {
                    break (mine, gathered);
                }
                let sets = one(i);
                gathered.add(plan, i, &sets);
                mine.push((i, sets));
            }
        };
        // the calling thread is one of the workers: its warm caches and
        // heap take a share of the cells
        let mut gathered = Gathered::new(plan);
        for (mine, g) in ravel_analysis::pool::on_threads(threads, &|_| work()) {
            gathered = gathered.merge(g);
            for (i, sets) in mine {
                slots[i] = Some(sets);
            }
        }
        (slots.into_iter().flatten().collect(), gathered)
    };
    Partitioned {
        // the cells' own boxes, moved (a grid's cells are boxes)
        cells: regions
            .into_iter()
            .map(|r| match r {
                Region::Box(b) => b,
                other => other.bbox(),
            })
            .collect(),
        sets,
        stop: Stop::Grid,
        calls,
        gathered: gathered.finish(),
    }
}

/// Guided refinement of the initial set (SG, GSG or property-guided).
pub(super) fn partition_guided(
    plan: &SystemPlan,
    guide: Guide,
    budget: Budget,
    shaped: &[Option<Sampled>],
    undecided: &[bool],
    ctl: &Control,
) -> Partitioned {
    let stop = || ctl.out_of_time();
    // `check` refuses `bab` in a closed loop; were it here, it would refine
    // as the property guide does (its closed-loop counterpart)
    let guide = if guide == Guide::Bab {
        Guide::Property
    } else {
        guide
    };
    let strategy = match guide {
        Guide::Sg => Strategy::Sg,
        Guide::Gsg | Guide::Property | Guide::Bab => Strategy::Gsg,
    };
    // nothing left to decide: one call for the report's sets
    let mut budget = if guide == Guide::Property && !undecided.iter().any(|u| *u) {
        Budget { calls: 1, ..budget }
    } else {
        budget
    };
    // the run's time limit bounds the refinement too
    if let Some(limit) = ctl.time_limit {
        budget.seconds = Some(budget.seconds.map_or(limit, |s| s.min(limit)));
    }
    let evaluated = std::sync::atomic::AtomicUsize::new(0);
    let root = plan.initial.bbox();
    // a nonlinear loop splits where the controller's slack shrinks most
    // (its bounds compose with the plant step after step); a linear one,
    // along the widest dimension
    let weights = |c: &IBox| match &plan.closed_loop {
        Loop::Nonlinear(nl) => nl.split_weights(c),
        Loop::Linear(_) => None,
    };
    let bisector = match &plan.closed_loop {
        Loop::Nonlinear(_) => Bisector::Weighted(&weights),
        Loop::Linear(_) => Bisector::Widest,
    };
    let r = refine_parallel(
        &root,
        strategy,
        &budget,
        &|c, parent: Option<&Option<Vec<Step>>>| {
            let region = cell_region(&plan.initial, c);
            if certainly_empty(&region) {
                let sets = vec![Step::new(region, Vec::new()); plan.horizon + 1];
                return (Some(sets), f64::NEG_INFINITY);
            }
            (ctl.progress)(Progress {
                phase: Phase::Cells,
                done: evaluated.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
                total: Some(budget.calls),
            });
            let sets =
                propagate_cell_until(plan, &region, parent.and_then(|p| p.as_deref()), &stop);
            let score = match guide {
                Guide::Sg | Guide::Gsg => (0..=plan.horizon)
                    .map(|t| match &shaped[t] {
                        Some(Sampled {
                            facets: f,
                            support: s,
                            extent: w,
                        }) => {
                            let b = offsets(&sets[t].set);
                            // step 0 is the cell itself, not a boundary shape
                            if t > 0 && b.len() == f.nrows() {
                                excess(&b, s, w)
                            } else {
                                let k = 2 * f.ncols();
                                excess(&b[..k], &s[..k], &w[..k])
                            }
                        }
                        None => f64::INFINITY,
                    })
                    .fold(0.0, f64::max),
                Guide::Property | Guide::Bab => plan
                    .properties
                    .iter()
                    .zip(undecided)
                    .filter(|(_, u)| **u)
                    .map(|(p, _)| {
                        let Margin {
                            value: m, issue, ..
                        } = cell_margin(p, &sets);
                        if proves(p, m) && !issue {
                            -1.0
                        } else {
                            (-m).max(0.0) + f64::MIN_POSITIVE
                        }
                    })
                    .fold(-1.0, f64::max),
            };
            (Some(sets), score)
        },
        ctl.elapsed,
        ctl.threads,
        bisector,
    );
    let mut leaves = r.leaves;
    // deterministic order: by cell position
    leaves.sort_by(|a, b| {
        a.cell
            .lo
            .iter()
            .zip(&b.cell.lo)
            .map(|(x, y)| x.total_cmp(y))
            .find(|o| o.is_ne())
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let part = leaves.iter().map(|l| l.cell.clone()).collect();
    let sets: Vec<Vec<Step>> = leaves.into_iter().filter_map(|l| l.value).collect();
    let mut gathered = Gathered::new(plan);
    for (i, c) in sets.iter().enumerate() {
        gathered.add(plan, i, c);
    }
    Partitioned {
        cells: part,
        sets,
        stop: r.stop,
        calls: r.calls,
        gathered: gathered.finish(),
    }
}
