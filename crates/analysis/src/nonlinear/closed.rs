//! The nonlinear closed loop, step after step: the state as first-order
//! Taylor models over the initial cell, the controller's CROWN bounds over
//! the step's observation set composed with them, and the plant's
//! validated flow (or map) over one control period.
//!
//! Per step `t`, with the state `x(z) ∈ c + G z + R` (`z ∈ [−1, 1]ⁿ` the
//! cell's own coordinates):
//! 1. the observation `y = Cᵀ x + v` as Taylor models `c + G z + ρ`;
//! 2. CROWN over the observation set itself, not its box: the network
//!    preceded by the exact affine layer `(z, ρ) ↦ c + G z + ρ`, over the
//!    box `S` of `(z, ρ)` (`z ∈ [−1, 1]ᴺ`, `ρ` in the remainders), gives
//!    `L s + l ≤ u ≤ U s + ū` for every control (the saturation is part
//!    of the network); a thin set's box is far wider than the set, and
//!    CROWN over it lost the state's correlations (QUAD's altitude);
//! 3. `u ∈ M s + m + E` with `M`, `m` the middle of the two bounds (any
//!    floats: `E` is bounded in outward-rounded interval arithmetic over
//!    `S` from the two bounds themselves), so the control keeps its linear
//!    dependency on `z` (its part on `ρ` joins `E`);
//! 4. the plant over the period, controls and disturbances held:
//!    [`integrate::flow`] (continuous time, with the intersample
//!    enclosure) or [`integrate::image`] (discrete time).
//!
//! Every failure of the arithmetic (a bound that is not finite, a
//! right-hand side that may be undefined, a flow without an enclosure)
//! cuts the cell: that step and every later one are the whole space.

use super::integrate::{self, DomainError, FlowError, Interval, Tm};
use super::NonlinearLoop;
use crate::closed_loop::{Boundary, Cut, Step};
use crate::crown::{Mode, Relaxation};
use crate::sets::{Affine, IBox, Region};
use nalgebra::{DMatrix, DVector};
use ravel_base::expr::Time;
use ravel_base::nn::{Layer, Network};

/// One claimed set of a certificate: `{c + G s : s ∈ [−1, 1]ᵏ}`, the
/// columns named by symbol ids (see `ravel_certify::nonlinear`).
#[derive(Clone, Debug, PartialEq)]
pub struct Claim {
    /// The centre.
    pub c: Vec<f64>,
    /// One row per state, one entry per symbol.
    pub g: Vec<Vec<f64>>,
    /// The symbols' ids.
    pub ids: Vec<u64>,
}

impl Claim {
    /// The models (without remainders, as [`resymbolize`] leaves them).
    fn of(x: &[Tm], ids: &[u64]) -> Option<Claim> {
        if x.iter()
            .any(|t| t.r != Interval::ZERO || t.g.len() != ids.len())
        {
            return None;
        }
        Some(Claim {
            c: x.iter().map(|t| t.c).collect(),
            g: x.iter().map(|t| t.g.clone()).collect(),
            ids: ids.to_vec(),
        })
    }
}

/// How many symbols beyond the cell's own `n` the state may carry, per
/// state dimension (see [`resymbolize`]).
const EXTRA_SYMBOLS: usize = 4;

/// The state after one step, and the states in between.
struct Advanced {
    /// The state at the next sampling instant.
    next: Vec<Tm>,
    /// The states over the period (continuous time), including both ends,
    /// in the flow's pieces ([`integrate::FlowOut::pieces`]).
    pipe: Option<Vec<IBox>>,
    /// The pieces' models, where the flow kept them
    /// ([`integrate::FlowOut::piece_forms`]).
    pipe_forms: Vec<Option<Affine>>,
}

impl NonlinearLoop {
    /// Reachable sets of one cell over the horizon (step 0 is the cell).
    /// With `parent` (the sets of a cell containing this one) every set is
    /// intersected with the parent's; `stop` is asked before each step
    /// whether the time is up.
    pub fn reach(
        &self,
        cell: &Region,
        horizon: usize,
        boundary: &Boundary,
        parent: Option<&[Step]>,
        stop: &dyn Fn() -> bool,
    ) -> Vec<Step> {
        let n = self.states();
        let mut steps = Vec::with_capacity(horizon + 1);
        steps.push(Step::new(cell.clone(), Vec::new()));
        let mut state = symbols(&cell.bbox());
        let mut ids = Ids::cell(n, 0.0);
        for t in 0..horizon {
            let Some(x) = state.as_ref() else {
                let cut = steps.last().and_then(Step::cut).unwrap_or(Cut::Overflow);
                steps.push(Step::whole(n, cut));
                continue;
            };
            if stop() {
                state = None;
                steps.push(Step::whole(n, Cut::TimeLimit));
                continue;
            }
            match self.advance(x) {
                Ok(a) => {
                    let mut step = Step::new(region_of(&a.next, boundary, t + 1), Vec::new());
                    step.between = a.pipe;
                    if self.keep_forms {
                        step.form = affine_of(&a.next);
                        step.between_forms = a.pipe_forms;
                    }
                    if let Some(p) = parent.and_then(|p| p.get(t + 1)) {
                        if p.cut().is_none() && step.cut().is_none() {
                            step.set = step.set.intersect(&p.set);
                            step.between = match (step.between, &p.between) {
                                // the same pieces of the same period
                                (Some(a), Some(b)) if a.len() == b.len() => {
                                    Some(a.iter().zip(b).map(|(a, b)| a.intersect(b)).collect())
                                }
                                (a, _) => a,
                            };
                        }
                    }
                    if step.cut().is_some() {
                        state = None;
                    } else {
                        state = resymbolize(&a.next, n, EXTRA_SYMBOLS * n, &mut ids);
                        if state.is_none() {
                            step = Step::whole(n, Cut::Overflow);
                        }
                    }
                    steps.push(step);
                }
                Err(cut) => {
                    state = None;
                    steps.push(Step::whole(n, cut));
                }
            }
        }
        steps
    }

    /// The chain of claimed sets of one cell for a certificate: the states
    /// the analysis carries from step to step (`c + G s`, remainders made
    /// symbols), steps `0..=steps`, with every fresh remainder widened by
    /// the relative `inflate` (and an absolute floor) so that the checker's own arithmetic, which
    /// re-derives each claim from the previous one, has room. `None` when
    /// the cell is cut before `steps`.
    pub fn claims(&self, cell: &IBox, steps: usize, inflate: f64) -> Option<Vec<Claim>> {
        let n = self.states();
        let mut ids = Ids::cell(n, inflate);
        let mut state = symbols(cell)?;
        let mut out = Vec::with_capacity(steps + 1);
        out.push(Claim::of(&state, &ids.ids)?);
        for _ in 0..steps {
            let a = self.advance(&state).ok()?;
            state = resymbolize(&a.next, n, EXTRA_SYMBOLS * n, &mut ids)?;
            out.push(Claim::of(&state, &ids.ids)?);
        }
        Some(out)
    }

    /// A box holding every state over one control period from the box `x`
    /// (the controls composed with the state as in [`NonlinearLoop::reach`],
    /// so that they keep their dependency on it); `None` when the period
    /// cannot be enclosed or the plant is in discrete time.
    pub fn pipe(&self, x: &IBox) -> Option<IBox> {
        let state = symbols(x)?;
        let pieces = self.advance(&state).ok()?.pipe?;
        let mut it = pieces.iter();
        let first = it.next()?.clone();
        Some(it.fold(first, |h, b| h.hull(b))).filter(IBox::is_finite)
    }

    /// Split weights for the guided partitioners
    /// ([`crate::partition::Bisector::Weighted`]): for each dimension of
    /// `cell`, the share of the controller's relaxation slack at step 0
    /// that bisecting it removes. A control's slack is the width of the
    /// interval part of its model ([`NonlinearLoop::control`]: the gap
    /// between CROWN's two bounds, and the sensor noise's part); the share
    /// for one control is `(s(cell) − max(s(a), s(b))) / s(cell)` with `a`,
    /// `b` the halves, and the weight its mean over the controls with
    /// slack, clamped to `[0, 1]`, times how loose the bounds are: the
    /// largest share of a control's range that is slack (so a tight
    /// relaxation, whose slack is not the loop's trouble, leaves the choice
    /// to the widest dimension: ReachNN B4's share is below 10⁻³, QUAD's
    /// torques' 0.99). The slack of a smooth network's bounds
    /// shrinks with the square of the input's width along the inputs it
    /// depends on nonlinearly, and the loop carries it step after step, so
    /// those inputs are the ones to split (QUAD with the published
    /// controller: the altitude and its rate, not the positions). A
    /// heuristic only: it chooses cells, never a bound. `None` when the
    /// controls cannot be bounded.
    pub fn split_weights(&self, cell: &IBox) -> Option<Vec<f64>> {
        let controls = |b: &IBox| -> Option<Vec<Tm>> {
            let x = symbols(b)?;
            let syms = x.first().map_or(0, |t| t.g.len());
            let y = self.observe(&x, syms).ok()?;
            self.control(&y, syms).ok()
        };
        let slack = |b: &IBox| -> Option<Vec<f64>> {
            let s: Vec<f64> = controls(b)?.iter().map(|t| t.r.width()).collect();
            s.iter().all(|v| v.is_finite()).then_some(s)
        };
        let u = controls(cell)?;
        let whole: Vec<f64> = u.iter().map(|t| t.r.width()).collect();
        let loose = u
            .iter()
            .map(|t| t.r.width() / t.range().width())
            .filter(|l| l.is_finite())
            .fold(0.0f64, f64::max)
            .clamp(0.0, 1.0);
        if !whole.iter().all(|v| v.is_finite()) {
            return None;
        }
        let with_slack = whole.iter().filter(|s| **s > 0.0).count();
        (0..cell.dim())
            .map(|d| {
                let (lo, hi) = (cell.lo[d], cell.hi[d]);
                let mid = lo + 0.5 * (hi - lo);
                if with_slack == 0 || !(lo < mid && mid < hi) {
                    return Some(0.0);
                }
                let (mut a, mut b) = (cell.clone(), cell.clone());
                a.hi[d] = mid;
                b.lo[d] = mid;
                let (sa, sb) = (slack(&a)?, slack(&b)?);
                let removed: f64 = whole
                    .iter()
                    .zip(sa.iter().zip(&sb))
                    .filter(|(s, _)| **s > 0.0)
                    .map(|(s, (x, y))| (s - x.max(*y)) / s)
                    .sum();
                Some((loose * removed / with_slack as f64).clamp(0.0, 1.0))
            })
            .collect()
    }

    /// One closed-loop step of the Taylor-model state `x`.
    fn advance(&self, x: &[Tm]) -> Result<Advanced, Cut> {
        let syms = x.first().map_or(0, |t| t.g.len());
        let y = self.observe(x, syms).map_err(|_| Cut::Overflow)?;
        if !range_box(&y).is_finite() {
            return Err(Cut::Overflow);
        }
        let u = self.control(&y, syms)?;
        let w: Vec<Tm> = (0..self.plant.w.dim())
            .map(|i| Tm::from_interval(Interval::new(self.plant.w.lo[i], self.plant.w.hi[i]), syms))
            .collect();
        let field = &self.plant.field;
        match field.time {
            Time::Continuous { period } => {
                let out =
                    integrate::flow(field, x, &u, &w, period, &self.settings).map_err(cut_of)?;
                Ok(Advanced {
                    next: out.end,
                    pipe: Some(out.pieces.iter().map(|p| interval_box(p)).collect()),
                    pipe_forms: if self.keep_forms {
                        out.piece_forms
                            .iter()
                            .map(|f| f.as_deref().and_then(affine_of))
                            .collect()
                    } else {
                        Vec::new()
                    },
                })
            }
            Time::Discrete => Ok(Advanced {
                next: integrate::image(field, x, &u, &w).map_err(cut_of)?,
                pipe: None,
                pipe_forms: Vec::new(),
            }),
        }
    }

    /// `y = Cᵀ x + v` as Taylor models.
    fn observe(&self, x: &[Tm], syms: usize) -> Result<Vec<Tm>, DomainError> {
        let obs = &self.plant.obs;
        let refs: Vec<&Tm> = x.iter().collect();
        (0..obs.ncols())
            .map(|j| {
                let col: Vec<f64> = obs.column(j).iter().copied().collect();
                let mut y = integrate::combine(&col, &refs, 0.0)?;
                if let (Some(&lo), Some(&hi)) = (self.plant.v.lo.get(j), self.plant.v.hi.get(j)) {
                    y = y.add_interval(Interval::new(lo, hi))?;
                }
                debug_assert_eq!(y.g.len(), syms);
                Ok(y)
            })
            .collect()
    }

    /// The controls as Taylor models: CROWN's two linear bounds of the
    /// controller over the observation's own parametrisation
    /// `y = c + G z + ρ` (`z ∈ [−1, 1]ᴺ` the state's symbols, `ρ` in `y`'s
    /// remainder box), not over its box: the network is preceded by the
    /// exact affine layer `(z, ρ) ↦ c + G z + ρ`, so every neuron is bounded
    /// over the set itself (a thin set's box is far wider than the set),
    /// and the bounds come out linear in `z`. The control is their middle,
    /// plus an interval holding the distance to either bound over the box
    /// of `(z, ρ)` and the middle's part on `ρ`.
    pub(super) fn control(&self, y: &[Tm], syms: usize) -> Result<Vec<Tm>, Cut> {
        let m = self.plant.field.controls;
        let k = y.len();
        let (net, sbox) = over_symbols(&self.net, y, syms).ok_or(Cut::Overflow)?;
        let rel = Relaxation::new(&net, &sbox, Mode::Crown);
        if !rel.is_finite() {
            return Err(Cut::Overflow);
        }
        // rows 2i: u_i ≤ …, rows 2i+1: −u_i ≤ …
        let spec = DMatrix::from_fn(2 * m, m, |r, c| match (r / 2 == c, r % 2) {
            (true, 0) => 1.0,
            (true, _) => -1.0,
            _ => 0.0,
        });
        let b = rel.upper_optimised(&spec, self.slope_steps, None);
        let siv: Vec<Interval> = (0..sbox.dim())
            .map(|j| Interval::new(sbox.lo[j], sbox.hi[j]))
            .collect();
        let mut out = Vec::with_capacity(m);
        for i in 0..m {
            let up: Vec<f64> = b.coef.row(2 * i).to_vec();
            let low: Vec<f64> = b.coef.row(2 * i + 1).iter().map(|v| -v).collect();
            let (ou, ol) = (b.offset[2 * i], -b.offset[2 * i + 1]);
            let mid: Vec<f64> = up
                .iter()
                .zip(&low)
                .map(|(a, c)| 0.5 * a + 0.5 * c)
                .collect();
            let m0 = 0.5 * ou + 0.5 * ol;
            // u − (M s + m) ∈ [(L − M) s + l − m, (U − M) s + ū − m] over S
            let hi = gap(&up, &mid, &siv, ou, m0).hi;
            let lo = gap(&low, &mid, &siv, ol, m0).lo;
            if !(lo.is_finite() && hi.is_finite()) || lo > hi || mid.len() != syms + k {
                return Err(Cut::Overflow);
            }
            // M s = M_z z + M_ρ ρ: the first part kept, the second an interval
            let mut rest = Interval::new(lo, hi);
            for (a, r) in mid[syms..].iter().zip(&siv[syms..]) {
                rest = rest + Interval::point(*a) * *r;
            }
            let u = Tm {
                c: m0,
                g: mid[..syms].to_vec(),
                r: Interval::ZERO,
            }
            .add_interval(rest)
            .map_err(|_| Cut::Overflow)?;
            out.push(u);
        }
        Ok(out)
    }

    /// One simulated step of `count` samples stored coordinate-major
    /// (`x[j·count + s]`): `(u, x⁺)`, in `f64`.
    pub fn simulate_batch(
        &self,
        x: &[f64],
        w: &[f64],
        v: &[f64],
        count: usize,
    ) -> (Vec<f64>, Vec<f64>) {
        let (n, m) = (self.states(), self.plant.field.controls);
        let (p, k) = (self.plant.w.dim(), self.plant.obs.ncols());
        let mut u_all = vec![0.0; m * count];
        let mut next_all = vec![0.0; n * count];
        let pick = |a: &[f64], dim: usize, s: usize| -> Vec<f64> {
            (0..dim)
                .map(|j| a.get(j * count + s).copied().unwrap_or(0.0))
                .collect()
        };
        let mut scratch = Vec::new();
        // every sample's observation, then the network over all of them at
        // once: the same bits as one sample at a time (`mat_batch_into`
        // sums each entry in the same order whatever the count), with the
        // products vectorised across the samples
        let mut y_all = vec![0.0; k * count];
        for s in 0..count {
            let (xs, vs) = (pick(x, n, s), pick(v, k, s));
            for j in 0..k {
                let dot: f64 = (0..n).map(|i| self.plant.obs[(i, j)] * xs[i]).sum();
                y_all[j * count + s] = dot + vs[j];
            }
        }
        let u_batch = self.net.forward_batch(&y_all, count);
        for s in 0..count {
            let (xs, ws) = (pick(x, n, s), pick(w, p, s));
            let u = pick(&u_batch, m, s);
            let next = match self.plant.field.time {
                Time::Continuous { period } => {
                    integrate::simulate(&self.plant.field, &xs, &u, &ws, period)
                }
                Time::Discrete => self.plant.field.eval(&xs, &u, &ws, &mut scratch),
            };
            for (j, &ui) in u.iter().enumerate().take(m) {
                u_all[j * count + s] = ui;
            }
            for (j, &xi) in next.iter().enumerate().take(n) {
                next_all[j * count + s] = xi;
            }
        }
        (u_all, next_all)
    }

    /// A rigorous enclosure of the next state from every state in `x`
    /// with these noise values (interval bounds of the controller, the
    /// validated flow of the plant); `None` when it cannot be bounded.
    pub fn enclose_step(&self, x: &IBox, w: &[f64], v: &[f64]) -> Option<IBox> {
        self.enclose_period(x, w, v, self.settings.substeps)
            .map(|(end, _)| end)
    }

    /// [`NonlinearLoop::enclose_step`] with the states in between: the
    /// next state's box and, in continuous time, one box per
    /// `1/substeps` of the period (in time order; see
    /// [`integrate::FlowOut::pieces`]), each containing every state from
    /// `x` over its part of the period. More substeps give shorter pieces,
    /// which a single trajectory needs to be shown inside a set it only
    /// passes through. In discrete time the pieces are empty.
    pub fn enclose_period(
        &self,
        x: &IBox,
        w: &[f64],
        v: &[f64],
        substeps: usize,
    ) -> Option<(IBox, Vec<IBox>)> {
        let syms = 0;
        let xs: Vec<Tm> = (0..x.dim())
            .map(|i| Tm::from_interval(Interval::new(x.lo[i], x.hi[i]), syms))
            .collect();
        let obs = &self.plant.obs;
        let refs: Vec<&Tm> = xs.iter().collect();
        let y: Vec<Tm> = (0..obs.ncols())
            .map(|j| {
                let col: Vec<f64> = obs.column(j).iter().copied().collect();
                let vj = v.get(j).copied().unwrap_or(0.0);
                integrate::combine(&col, &refs, 0.0)?.add_interval(Interval::new(vj, vj))
            })
            .collect::<Result<_, DomainError>>()
            .ok()?;
        let ybox = range_box(&y);
        let rel = Relaxation::new(&self.net, &ybox, Mode::Crown);
        if !(ybox.is_finite() && rel.is_finite()) {
            return None;
        }
        let ubox = rel.output_box(Mode::Crown);
        let u: Vec<Tm> = (0..ubox.dim())
            .map(|i| Tm::from_interval(Interval::new(ubox.lo[i], ubox.hi[i]), syms))
            .collect();
        let ws: Vec<Tm> = w
            .iter()
            .map(|&wi| Tm::from_interval(Interval::new(wi, wi), syms))
            .collect();
        let field = &self.plant.field;
        let (next, pieces) = match field.time {
            Time::Continuous { period } => {
                let s = integrate::Settings {
                    substeps,
                    ..self.settings
                };
                let out = integrate::flow(field, &xs, &u, &ws, period, &s).ok()?;
                let pieces: Vec<IBox> = out.pieces.iter().map(|p| interval_box(p)).collect();
                (out.end, pieces)
            }
            Time::Discrete => (integrate::image(field, &xs, &u, &ws).ok()?, Vec::new()),
        };
        let b = range_box(&next);
        (b.is_finite() && pieces.iter().all(IBox::is_finite)).then_some((b, pieces))
    }
}

/// The network preceded by the affine layer `(z, ρ) ↦ c + G z + ρ` of the
/// models `y` over `syms` symbols, and the box of its inputs: `z ∈ [−1, 1]`,
/// `ρ` in each model's remainder. `None` when a bound is not finite.
fn over_symbols(net: &Network, y: &[Tm], syms: usize) -> Option<(Network, IBox)> {
    let k = y.len();
    let w = DMatrix::from_fn(k, syms + k, |j, i| {
        if i < syms {
            y[j].g.get(i).copied().unwrap_or(0.0)
        } else if i - syms == j {
            1.0
        } else {
            0.0
        }
    });
    let b = DVector::from_iterator(k, y.iter().map(|t| t.c));
    let mut layers = Vec::with_capacity(net.layers.len() + 1);
    layers.push(Layer::Affine { w, b });
    layers.extend(net.layers.iter().cloned());
    let lo = (0..syms).map(|_| -1.0).chain(y.iter().map(|t| t.r.lo));
    let hi = (0..syms).map(|_| 1.0).chain(y.iter().map(|t| t.r.hi));
    let sbox = IBox::new(lo.collect(), hi.collect());
    let finite = sbox.is_finite() && y.iter().all(Tm::is_finite);
    finite.then(|| {
        (
            Network::new(syms + k, layers).with_input_type(net.input_type),
            sbox,
        )
    })
}

/// The bound `a − mid` applied to `y`, plus `off − m0`, in outward-rounded
/// interval arithmetic over the box `y`.
fn gap(a: &[f64], mid: &[f64], y: &[Interval], off: f64, m0: f64) -> Interval {
    let mut s = Interval::point(off) - Interval::point(m0);
    for ((&ai, &mi), &yi) in a.iter().zip(mid).zip(y) {
        s = s + (Interval::point(ai) - Interval::point(mi)) * yi;
    }
    s
}

/// The cell's box as Taylor models: `x_i = centre_i + radius_i · z_i`,
/// the radius rounded up so that the models contain the box; `None` when
/// the box is not finite.
fn symbols(b: &IBox) -> Option<Vec<Tm>> {
    if !b.is_finite() {
        return None;
    }
    let n = b.dim();
    Some(
        (0..n)
            .map(|i| {
                let (lo, hi) = (b.lo[i], b.hi[i]);
                let c = 0.5 * lo + 0.5 * hi;
                let r = (hi - c).max(c - lo).max(0.0).next_up();
                Tm::symbol(i, c, r, n)
            })
            .collect(),
    )
}

/// The box of the models' ranges.
fn range_box(x: &[Tm]) -> IBox {
    let r: Vec<Interval> = x.iter().map(Tm::range).collect();
    interval_box(&r)
}

/// The models as an affine set `c + G s + r` (`None` when one is not
/// finite).
fn affine_of(x: &[Tm]) -> Option<Affine> {
    let k = x.iter().map(|t| t.g.len()).max().unwrap_or(0);
    if !x.iter().all(Tm::is_finite) {
        return None;
    }
    Some(Affine {
        c: x.iter().map(|t| t.c).collect(),
        g: x.iter()
            .map(|t| {
                let mut g = t.g.clone();
                g.resize(k, 0.0);
                g
            })
            .collect(),
        r_lo: x.iter().map(|t| t.r.lo).collect(),
        r_hi: x.iter().map(|t| t.r.hi).collect(),
    })
}

/// Intervals as a box (NaN ends become infinite: never a bound).
fn interval_box(r: &[Interval]) -> IBox {
    let lo = r
        .iter()
        .map(|i| {
            if i.lo.is_nan() {
                f64::NEG_INFINITY
            } else {
                i.lo
            }
        })
        .collect();
    let hi = r
        .iter()
        .map(|i| if i.hi.is_nan() { f64::INFINITY } else { i.hi })
        .collect();
    IBox::new(lo, hi)
}

/// The set of the models as a region of the boundary's shape: their box,
/// and a sound support in each of the boundary's directions.
fn region_of(x: &[Tm], boundary: &Boundary, t: usize) -> Region {
    let bbox = range_box(x);
    match boundary.directions(t) {
        None => Region::Box(bbox),
        Some(d) => Region::Polytope {
            bbox,
            rows: (0..d.nrows())
                .map(|r| {
                    let dir: Vec<f64> = d.row(r).iter().copied().collect();
                    let s = integrate::support(&dir, x);
                    (dir, s)
                })
                .collect(),
        },
    }
}

/// The cut a failed flow stands for.
fn cut_of(e: FlowError) -> Cut {
    match e {
        FlowError::Domain(_) => Cut::Undefined,
        FlowError::NoEnclosure => Cut::NoEnclosure,
        FlowError::Overflow | FlowError::Malformed => Cut::Overflow,
    }
}

/// The ids of the state's symbols (what a certificate's claims name them
/// by) and the widening of fresh remainders for certificates.
#[derive(Clone, Debug, Default)]
struct Ids {
    ids: Vec<u64>,
    next: u64,
    /// Relative widening of every remainder made a symbol (0 in the analysis).
    inflate: f64,
}

impl Ids {
    /// The cell's own `n` symbols.
    fn cell(n: usize, inflate: f64) -> Ids {
        Ids {
            ids: (0..n as u64).collect(),
            next: n as u64,
            inflate,
        }
    }

    /// `n` new symbols after the others.
    fn fresh(&mut self, n: usize) {
        let first = self.next;
        self.ids.extend(first..first + n as u64);
        self.next = first + n as u64;
    }

    /// Forget the symbols marked `gone`.
    fn drop_where(&mut self, gone: &[bool]) {
        let mut k = 0;
        self.ids.retain(|_| {
            let keep = !gone.get(k).copied().unwrap_or(false);
            k += 1;
            keep
        });
    }
}

/// The same set with the remainders turned into symbols of their own, so
/// that later steps carry them linearly instead of as boxes (whose
/// wrapping would grow them every step): component `i`'s remainder becomes
/// a new symbol on component `i` alone. When more than `cap` symbols follow
/// the cell's own `keep`, the smallest of them (by `Σᵢ |gᵢⱼ|`) are merged
/// into one new symbol per component with the sum of their magnitudes (a
/// box around their zonotope, as in Girard's order reduction). `None` when
/// a bound is not finite.
fn resymbolize(x: &[Tm], keep: usize, cap: usize, ids: &mut Ids) -> Option<Vec<Tm>> {
    let n = x.len();
    let syms = x.iter().map(|t| t.g.len()).max().unwrap_or(0);
    let mut out: Vec<Tm> = x
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let lo = (t.c + t.r.lo).next_down();
            let hi = (t.c + t.r.hi).next_up();
            let c = 0.5 * lo + 0.5 * hi;
            let r = (hi - c).max(c - lo).next_up();
            let r = if ids.inflate > 0.0 {
                let scale = t.c.abs() + t.g.iter().map(|v| v.abs()).sum::<f64>();
                // the floor: a state that stays 0 (QUAD's yaw rate) has no
                // scale, while the checker's every rounding costs `TINY`
                let floor = ids.inflate * 1e8 * ravel_base::num::TINY;
                (r * (1.0 + ids.inflate) + ids.inflate * 1e-9 * scale + floor).next_up()
            } else {
                r
            };
            let mut g = t.g.clone();
            g.resize(syms + n, 0.0);
            g[syms + i] = r;
            Tm {
                c,
                g,
                r: Interval::ZERO,
            }
        })
        .collect();
    let total = syms + n;
    ids.fresh(n);
    if total > keep + cap {
        // the extra symbols by size, smallest first; merge all but the largest `cap − n`
        let mut extra: Vec<(f64, usize)> = (keep..total)
            .map(|j| (out.iter().map(|t| t.g[j].abs()).sum::<f64>(), j))
            .collect();
        extra.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let merge = extra.len() - (cap.saturating_sub(n));
        let mut gone = vec![false; total];
        for &(_, j) in extra.iter().take(merge) {
            gone[j] = true;
        }
        ids.drop_where(&gone);
        ids.fresh(n);
        for (i, t) in out.iter_mut().enumerate() {
            let s =
                ravel_base::num::sum_upper((0..total).filter(|&j| gone[j]).map(|j| t.g[j].abs()));
            let mut g: Vec<f64> = (0..total).filter(|&j| !gone[j]).map(|j| t.g[j]).collect();
            g.resize(g.len() + n, 0.0);
            let at = g.len() - n + i;
            g[at] = s;
            t.g = g;
        }
    }
    let finite = out
        .iter()
        .all(|t| t.c.is_finite() && t.g.iter().all(|v| v.is_finite()));
    finite.then_some(out)
}
