//! One step of a neural feedback loop, exactly (simulation) and as a set
//! (the closed-loop propagators).
//!
//! The plant is `x⁺ = A x + B u + c + w`, `y = Cᵀ x + v`, `u = π(y)` where `π`
//! already contains the control saturation. Noise `w ∈ W`, `v ∈ V` is
//! adversarial: any value in its box at every step.
//!
//! Step-by-step propagators map a set of states to a set of next states.
//! The unrolled propagator ([`ClosedLoop::unrolled`]) instead bounds `x_t`
//! directly as a linear function of `x_0`, back-substituting through `t`
//! copies of the loop (CROWN on the unrolled computation graph); noise
//! enters each copy once and is bounded over its box where it enters, which
//! loses nothing because every noise variable is independent of all others.

use nalgebra::{DMatrix, DVector};

use super::crown::{affine_image, LinearUpper, Mode, Relaxation, Rows};
use super::open_loop;
use super::partition::{Budget, Strategy};
use super::sdp;
use super::shape::Shape;
use crate::issue::Issue;
use crate::sets::{Affine, IBox, Region};
use ravel_base::nn::{mat_batch_into, Network};
use ravel_base::num::{gamma, mul0, slack, sum_upper};

mod kernel;

/// A linear plant with bounded noise.
#[derive(Clone, Debug, PartialEq)]
pub struct Plant {
    /// `n × n` state matrix.
    pub a: DMatrix<f64>,
    /// `n × m` input matrix.
    pub b: DMatrix<f64>,
    /// Known exogenous input (`n`).
    pub c: DVector<f64>,
    /// Observation matrix `C` (`n × p`); the controller sees `Cᵀ x + v`.
    pub obs: DMatrix<f64>,
    /// Process noise box (`n`).
    pub w: IBox,
    /// Sensor noise box (`p`).
    pub v: IBox,
    /// How far the true `A`, `B`, `c` may be from the stored ones (a
    /// continuous-time plant's discretisation error); `None`: exact.
    pub err: Option<ModelError>,
}

/// Entrywise bounds `|A_true − A| ≤ a`, `|B_true − B| ≤ b`, `|c_true − c| ≤ c`.
/// Every propagator adds `Σ_j |f_j|·δ_j` to a facet `f`'s bound, with
/// `δ = a·|x|max + b·|u|max + c` over the step's state and control boxes.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelError {
    /// Bound on the state matrix's error (`n × n`).
    pub a: DMatrix<f64>,
    /// Bound on the input matrix's error (`n × m`).
    pub b: DMatrix<f64>,
    /// Bound on the constant input's error (`n`).
    pub c: DVector<f64>,
}

impl ModelError {
    /// The largest entry of the three bounds.
    pub fn max(&self) -> f64 {
        self.a
            .iter()
            .chain(self.b.iter())
            .chain(self.c.iter())
            .fold(0.0, |m, v| m.max(*v))
    }
}

/// How one closed-loop step is over-approximated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Propagator {
    /// Reach-LP: CROWN bounds of the controller folded into the dynamics per facet.
    ReachLp,
    /// CL-CROWN: a box of controls from CROWN, pushed through the dynamics.
    CrownSeparate,
    /// A box of controls from IBP, pushed through the dynamics.
    IbpSeparate,
    /// A box of controls from IBP with a simulation-guided partition of the
    /// observation box (CL-SG-IBP), pushed through the dynamics.
    SgIbpSeparate,
    /// CROWN through the whole unrolled loop: `x_t` bounded as a function of `x_0`.
    CrownUnrolled,
    /// Reach-SDP: a semidefinite program per facet (ReLU networks only),
    /// intersected with the Reach-LP bound.
    ReachSdp,
}

impl Propagator {
    /// Every propagator, in the order of the documentation.
    pub const ALL: [Propagator; 6] = [
        Propagator::ReachLp,
        Propagator::ReachSdp,
        Propagator::CrownUnrolled,
        Propagator::CrownSeparate,
        Propagator::IbpSeparate,
        Propagator::SgIbpSeparate,
    ];

    /// The propagator with this spec-language name.
    pub fn from_name(name: &str) -> Option<Propagator> {
        Propagator::ALL.into_iter().find(|p| p.name() == name)
    }

    /// The spec-language name.
    pub fn name(self) -> &'static str {
        match self {
            Propagator::ReachLp => "reach_lp",
            Propagator::CrownSeparate => "crown_separate",
            Propagator::IbpSeparate => "ibp_separate",
            Propagator::SgIbpSeparate => "sg_ibp_separate",
            Propagator::CrownUnrolled => "crown_unrolled",
            Propagator::ReachSdp => "reach_sdp",
        }
    }
}

/// The shape of the reachable sets.
#[derive(Clone, Debug, PartialEq)]
pub enum Boundary {
    /// Axis-aligned boxes.
    Box,
    /// Polytopes `{x | D x ≤ d}` with fixed directions `D` (`k × n`), each
    /// intersected with its bounding box (which is always computed too).
    Polytope(DMatrix<f64>),
    /// Polytopes whose directions are the edge normals of the convex hull of
    /// the simulated states at each step (2-D states). The directions depend
    /// on the samples, so `ravel::execute` resolves this to
    /// [`Boundary::PerStep`] after its Monte Carlo run; unresolved, it acts
    /// as [`Boundary::Box`].
    Hull,
    /// Polytopes with directions chosen per step: entry `t` is used for the
    /// set at step `t` (missing entries: the box alone). Whatever the
    /// directions, each offset is a sound bound.
    PerStep(Vec<DMatrix<f64>>),
}

impl Boundary {
    /// `k` directions evenly spread over the circle (2-D states).
    pub fn spread(k: usize) -> Boundary {
        let d = DMatrix::from_fn(k, 2, |r, c| {
            let a = std::f64::consts::TAU * r as f64 / k as f64;
            if c == 0 {
                a.cos()
            } else {
                a.sin()
            }
        });
        Boundary::Polytope(d)
    }

    /// The directions (besides the bounding box) of the set at step `t`.
    pub fn directions(&self, t: usize) -> Option<&DMatrix<f64>> {
        match self {
            Boundary::Box | Boundary::Hull => None,
            Boundary::Polytope(d) => Some(d),
            Boundary::PerStep(v) => v.get(t).filter(|d| d.nrows() > 0),
        }
    }
}

/// Why a step's set is the whole space instead of a computed bound.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cut {
    /// A bound overflowed `f64` (or was NaN) at this step.
    Overflow,
    /// The run's time limit stopped the propagation before this step.
    TimeLimit,
    /// A nonlinear plant's right-hand side may be undefined on the step's
    /// set (a divisor that may be 0, the logarithm or square root of a
    /// possibly non-positive or negative number, a pole of `tan`, or `abs`
    /// at its kink inside a Taylor expansion).
    Undefined,
    /// The validated integrator found no enclosure of a nonlinear plant's
    /// flow over the control period (the flow may blow up).
    NoEnclosure,
}

impl Cut {
    /// The name used in the JSON report.
    pub fn as_str(self) -> &'static str {
        match self {
            Cut::Overflow => "overflow",
            Cut::TimeLimit => "time_limit",
            Cut::Undefined => "undefined",
            Cut::NoEnclosure => "no_enclosure",
        }
    }
}

/// One propagated set and the LP solver issues met computing it.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// The reachable set: the whole space when `cut` is set (and then for
    /// every later step too).
    pub set: Region,
    /// Solver statuses that forced a fallback bound (empty when all certified).
    pub issues: Vec<Issue>,
    /// Why the set is the whole space, if it is.
    pub cut: Option<Cut>,
    /// A continuous-time plant's states over the control period that ends
    /// at this step, both sampling instants included (the intersample
    /// enclosure): boxes whose union holds every state of the period, in
    /// time order — a nonlinear plant's one per eighth of the period
    /// ([`crate::nonlinear::integrate::FlowOut::pieces`]), a linear plant's
    /// one for the whole period; `None` for other plants and periods.
    pub between: Option<Vec<IBox>>,
    /// A nonlinear plant's affine enclosure of the set (the Taylor models
    /// it is the box of), for bounding nonlinear constraints with the
    /// states' correlations; `None` for other plants.
    pub form: Option<Affine>,
    /// The same for each piece of `between`, where the integrator had one
    /// (empty, or one entry per piece).
    pub between_forms: Vec<Option<Affine>>,
}

impl Step {
    /// A computed set.
    pub fn new(set: Region, issues: Vec<Issue>) -> Step {
        Step {
            set,
            issues,
            cut: None,
            between: None,
            form: None,
            between_forms: Vec::new(),
        }
    }

    /// The step of a set whose bounds overflowed: the whole space `ℝⁿ`
    /// (trivially sound).
    pub fn overflowed(n: usize, issues: Vec<Issue>) -> Step {
        Step {
            set: Region::Box(IBox::whole(n)),
            issues,
            cut: Some(Cut::Overflow),
            between: None,
            form: None,
            between_forms: Vec::new(),
        }
    }

    /// A step the time limit left uncomputed: the whole space `ℝⁿ`.
    pub fn timed_out(n: usize) -> Step {
        Step::whole(n, Cut::TimeLimit)
    }

    /// A step that is not a computed bound, for this reason: the whole space.
    pub fn whole(n: usize, cut: Cut) -> Step {
        Step {
            set: Region::Box(IBox::whole(n)),
            issues: Vec::new(),
            cut: Some(cut),
            between: None,
            form: None,
            between_forms: Vec::new(),
        }
    }

    /// Why this step's set is not a computed bound, if it is not. A set
    /// that is not finite counts as an overflow whatever produced it.
    pub fn cut(&self) -> Option<Cut> {
        self.cut
            .or_else(|| (!self.set.is_finite()).then_some(Cut::Overflow))
    }
}

/// Whether every entry is finite.
/// The corner of `b` where `coef · z` is largest (the upper end where a
/// coefficient is non-negative).
fn corner(coef: &[f64], b: &IBox) -> Vec<f64> {
    coef.iter()
        .zip(b.lo.iter().zip(&b.hi))
        .map(|(&c, (&l, &u))| if c >= 0.0 { u } else { l })
        .collect()
}

fn all_finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// Monte Carlo samples and cell budget of the SG-IBP control bound.
const SG_SAMPLES: usize = 64;
const SG_BUDGET: Budget = Budget {
    calls: 64,
    min_size: 1.0 / 16.0,
    seconds: None,
};

/// The dynamics of one step, with its block matrices.
#[derive(Clone, Debug)]
struct Dynamics {
    /// The step's plant.
    plant: Plant,
    /// `[A I]`: `(x, w) ↦ A x + w`.
    dyn_xw: DMatrix<f64>,
    /// `[A B I]`: `(x, u, w) ↦ A x + B u + w`.
    dyn_xuw: DMatrix<f64>,
    /// `|B|`, entry-wise (the scale of the rounding error of `M B`).
    b_abs: DMatrix<f64>,
}

/// A closed loop ready for analysis, with the block matrices precomputed.
/// A time-varying plant has one [`Plant`] per step (`A`, `B`, `c` vary; `C`
/// and the noise boxes are those of the first).
#[derive(Clone, Debug)]
pub struct ClosedLoop {
    /// The plant of step 0 (and of every step when time-invariant).
    pub plant: Plant,
    /// The controller, saturation included.
    pub net: Network,
    /// `[Cᵀ I]`: `(x, v) ↦ y`.
    obs_xv: DMatrix<f64>,
    /// The zero offset of `obs_xv` (a vector of `p` zeros).
    obs_zero: DVector<f64>,
    /// The dynamics per step (one entry: time-invariant).
    dynamics: Vec<Dynamics>,
    /// Projected-gradient steps on the lower ReLU slopes of each
    /// back-substitution through the controller (0: CROWN's own slopes;
    /// see [`Relaxation::upper_optimised`]).
    pub slope_steps: usize,
    /// Whether box states under CROWN's own slopes take the allocation-free
    /// kernel (`kernel`); off only to compare it with the general path.
    kernel: bool,
}

impl ClosedLoop {
    /// Assemble a time-invariant closed loop (dimensions must agree; `check` guarantees it).
    pub fn new(plant: Plant, net: Network) -> ClosedLoop {
        ClosedLoop::time_varying(vec![plant], net)
    }

    /// Assemble a closed loop whose step `t` uses `plants[t]` (the last one
    /// for later steps); `plants` must not be empty.
    pub fn time_varying(plants: Vec<Plant>, net: Network) -> ClosedLoop {
        let plant = plants[0].clone();
        let n = plant.a.nrows();
        let m = plant.b.ncols();
        let p = plant.obs.ncols();
        let ct = plant.obs.transpose();
        let mut obs_xv = DMatrix::zeros(p, n + p);
        obs_xv.view_mut((0, 0), (p, n)).copy_from(&ct);
        obs_xv.view_mut((0, n), (p, p)).fill_with_identity();
        let dynamics = plants
            .into_iter()
            .map(|pl| {
                let mut dyn_xw = DMatrix::zeros(n, 2 * n);
                dyn_xw.view_mut((0, 0), (n, n)).copy_from(&pl.a);
                dyn_xw.view_mut((0, n), (n, n)).fill_with_identity();
                let mut dyn_xuw = DMatrix::zeros(n, n + m + n);
                dyn_xuw.view_mut((0, 0), (n, n)).copy_from(&pl.a);
                dyn_xuw.view_mut((0, n), (n, m)).copy_from(&pl.b);
                dyn_xuw.view_mut((0, n + m), (n, n)).fill_with_identity();
                Dynamics {
                    b_abs: pl.b.abs(),
                    plant: pl,
                    dyn_xw,
                    dyn_xuw,
                }
            })
            .collect();
        ClosedLoop {
            plant,
            net,
            obs_zero: DVector::zeros(obs_xv.nrows()),
            obs_xv,
            dynamics,
            slope_steps: 0,
            kernel: true,
        }
    }

    /// The same loop with `steps` slope-optimisation steps per back-substitution.
    pub fn with_slope_steps(mut self, steps: usize) -> ClosedLoop {
        self.slope_steps = steps;
        self
    }

    /// The same loop with the allocation-free kernel for box states on
    /// (the default) or off (every step by the general path: for tests and
    /// benchmarks that compare the two).
    pub fn with_kernel(mut self, on: bool) -> ClosedLoop {
        self.kernel = on;
        self
    }

    /// Whether a box of states takes the kernel: CROWN's own slopes, and a
    /// controller the kernel takes.
    fn kernel_applies(&self) -> bool {
        self.kernel && self.slope_steps == 0 && kernel::applies(self)
    }

    /// The dynamics of step `t`.
    fn at(&self, t: usize) -> &Dynamics {
        &self.dynamics[t.min(self.dynamics.len() - 1)]
    }

    /// The plant used at step `t`.
    pub fn plant_at(&self, t: usize) -> &Plant {
        &self.at(t).plant
    }

    /// The plants of steps `0, 1, …` (the last one is used for every later
    /// step; a single one when time-invariant).
    pub fn plants(&self) -> Vec<&Plant> {
        self.dynamics.iter().map(|d| &d.plant).collect()
    }

    /// Whether `A`, `B` or `c` change over time.
    pub fn is_time_varying(&self) -> bool {
        self.dynamics.len() > 1
    }

    /// State dimension.
    pub fn states(&self) -> usize {
        self.plant.a.nrows()
    }

    /// One exact step `t`: returns `(u, x⁺)` for state `x` and noise `w`, `v`
    /// (in `f64`; a batch of one, see [`ClosedLoop::simulate_batch`]).
    pub fn simulate(&self, t: usize, x: &[f64], w: &[f64], v: &[f64]) -> (Vec<f64>, Vec<f64>) {
        self.simulate_batch(t, x, w, v, 1)
    }

    /// One exact step `t` of `count` samples at once, stored
    /// coordinate-major (`x[j·count + s]` is coordinate `j` of sample `s`;
    /// `w`, `v` and the results likewise): `(u, x⁺)`. The sums run in the
    /// order of nalgebra's products (`y = Cᵀx + v`, `x⁺ = ((A x + B u) + c) + w`,
    /// each product column by column) for every `count`, so a sample's bits
    /// do not depend on its batch (`tests/soundness.rs` checks both against
    /// nalgebra's own products).
    pub fn simulate_batch(
        &self,
        t: usize,
        x: &[f64],
        w: &[f64],
        v: &[f64],
        count: usize,
    ) -> (Vec<f64>, Vec<f64>) {
        let n = self.states();
        let p = self.plant.obs.ncols();
        // y = Cᵀ x (the first n columns of [Cᵀ I]) + v
        let ct = self.obs_xv.columns(0, n).into_owned();
        let mut y = Vec::new();
        mat_batch_into(&ct, x, count, &mut y);
        for (o, vi) in y.iter_mut().zip(v) {
            *o += vi;
        }
        debug_assert_eq!(y.len(), p * count);
        let u = self.net.forward_batch(&y, count);
        let pl = self.plant_at(t);
        let mut next = Vec::new();
        mat_batch_into(&pl.a, x, count, &mut next);
        let mut bu = Vec::new();
        mat_batch_into(&pl.b, &u, count, &mut bu);
        for (i, o) in next.chunks_exact_mut(count.max(1)).enumerate() {
            let (ci, bui, wi) = (pl.c[i], &bu[i * count..], &w[i * count..]);
            for (s, o) in o.iter_mut().enumerate() {
                *o = ((*o + bui[s]) + ci) + wi[s];
            }
        }
        (u, next)
    }

    /// `δ = err.a·|x|max + err.b·|u|max + err.c` for step `t`, rounded up
    /// (`None` for an exact plant).
    fn model_delta(&self, t: usize, x: &IBox, u_abs: &[f64]) -> Option<Vec<f64>> {
        let e = self.plant_at(t).err.as_ref()?;
        let x_abs = x.abs_max();
        Some(
            (0..e.a.nrows())
                .map(|i| {
                    sum_upper(
                        (0..e.a.ncols())
                            .map(|j| mul0(e.a[(i, j)], x_abs[j]))
                            .chain((0..e.b.ncols()).map(|j| mul0(e.b[(i, j)], u_abs[j])))
                            .chain([e.c[i]]),
                    )
                })
                .collect(),
        )
    }

    /// Raise each row `r`'s offset by `Σ_j |rows_rj|·δ_j` (the model error).
    fn add_model_error(offsets: &mut [f64], rows: &Rows, delta: &[f64]) {
        for (o, row) in offsets.iter_mut().zip(rows.iter_rows()) {
            let extra = sum_upper(row.iter().zip(delta).map(|(r, d)| mul0(r.abs(), *d)));
            *o = sum_upper([*o, extra]);
        }
    }

    /// A rigorous enclosure of the true next state from every state in `x`
    /// at step `t` with the given noise values (outward-rounded interval
    /// arithmetic through the network and the plant, plus the plant's model
    /// error); `None` when a bound is not finite. Used to confirm that a
    /// simulated counterexample is a real one.
    pub fn enclose_step(&self, t: usize, x: &IBox, w: &[f64], v: &[f64]) -> Option<IBox> {
        let y = affine_image(&self.obs_xv, &self.obs_zero, &x.product(&IBox::point(v)));
        let a = Relaxation::new(&self.net, &y, Mode::Ibp);
        if !(y.is_finite() && a.is_finite()) {
            return None;
        }
        let u = a.output_box(Mode::Ibp);
        let d = self.at(t);
        let mut next = affine_image(
            &d.dyn_xuw,
            &d.plant.c,
            &x.product(&u).product(&IBox::point(w)),
        );
        if let Some(delta) = self.model_delta(t, x, &u.abs_max()) {
            for ((lo, hi), e) in next.lo.iter_mut().zip(next.hi.iter_mut()).zip(delta) {
                *lo = ravel_base::num::sum_lower([*lo, -e]);
                *hi = sum_upper([*hi, e]);
            }
        }
        next.is_finite().then_some(next)
    }

    /// The box of possible observations for states in `x`.
    pub fn observation_box(&self, x: &IBox) -> IBox {
        affine_image(&self.obs_xv, &self.obs_zero, &x.product(&self.plant.v))
    }

    /// The facet matrix of a boundary at step `t`: `[I; −I]` (the bounding
    /// box), then its directions.
    pub fn facets(&self, boundary: &Boundary, t: usize) -> DMatrix<f64> {
        facets(self.states(), boundary, t)
    }

    /// The set `{x | F x ≤ ub}` for the facets of `boundary` at step `t`.
    fn region_of(&self, boundary: &Boundary, t: usize, ub: &[f64]) -> Region {
        let n = self.states();
        let bbox = IBox::new(ub[n..2 * n].iter().map(|v| -v).collect(), ub[..n].to_vec());
        match boundary.directions(t) {
            None => Region::Box(bbox),
            Some(d) => Region::Polytope {
                bbox,
                rows: (0..d.nrows())
                    .map(|r| (d.row(r).iter().copied().collect(), ub[2 * n + r]))
                    .collect(),
            },
        }
    }

    /// An over-approximation of the set of states at step `t + 1` for states
    /// in `x` at step `t`.
    pub fn step(&self, t: usize, x: &Region, prop: Propagator, boundary: &Boundary) -> Step {
        self.step_with(t, x, prop, boundary, false)
    }

    /// The propagator's own bound of one step, before it is intersected
    /// with another method's (Reach-LP without CL-CROWN, Reach-SDP without
    /// Reach-LP; facets the SDP could not bound are `+∞`). For soundness
    /// tests: no error term of one method can hide behind another's bound.
    pub fn step_alone(&self, t: usize, x: &Region, prop: Propagator, boundary: &Boundary) -> Step {
        self.step_with(t, x, prop, boundary, true)
    }

    fn step_with(
        &self,
        t: usize,
        x: &Region,
        prop: Propagator,
        boundary: &Boundary,
        alone: bool,
    ) -> Step {
        let n = self.states();
        // Every intermediate result is checked for finiteness before it is
        // used: a NaN that met `min`/`max` could otherwise turn into a finite,
        // wrong bound. Any non-finite value makes the whole step an overflow.
        if !x.is_finite() {
            return Step::overflowed(n, Vec::new());
        }
        let facets = self.facets(boundary, t + 1);
        let (mut ub, mut issues) = match (prop, x) {
            // a box of states under CROWN's own slopes takes the kernel
            // (the same bounds up to rounding terms, no allocation per step)
            (Propagator::ReachLp | Propagator::ReachSdp, Region::Box(b))
                if self.kernel_applies() =>
            {
                match kernel::reach_lp(self, t, b, &facets, alone) {
                    Some(kernel::Answer::Bounds { ub, .. }) => (ub, Vec::new()),
                    _ => return Step::overflowed(n, Vec::new()),
                }
            }
            _ => match self.general_bounds(t, x, &facets, prop, alone) {
                Ok(both) => both,
                Err(issues) => return Step::overflowed(n, issues),
            },
        };
        if !all_finite(&ub) {
            return Step::overflowed(n, issues);
        }
        if prop == Propagator::ReachSdp {
            let (sdp, more) = self.reach_sdp(t, x, &facets);
            issues.extend(more);
            // +∞ is a facet the SDP could not bound (reported as an issue); NaN is an overflow
            if sdp.iter().any(|v| v.is_nan()) {
                return Step::overflowed(n, issues);
            }
            if alone {
                ub = sdp;
            } else {
                for (u, s) in ub.iter_mut().zip(sdp) {
                    *u = u.min(s);
                }
            }
        }
        Step::new(self.region_of(boundary, t + 1, &ub), issues)
    }

    /// The facet bounds of one step by the general path (any region, any
    /// slopes; the SDP's own part is added by the caller) and the issues
    /// met, or (`Err`) the issues met before a bound overflowed. A box of
    /// states under CROWN's own slopes takes CL-CROWN's control box from
    /// the kernel, as Reach-LP does there: one control box for both, so
    /// Reach-LP is never looser than CL-CROWN, exactly.
    fn general_bounds(
        &self,
        t: usize,
        x: &Region,
        facets: &DMatrix<f64>,
        prop: Propagator,
        alone: bool,
    ) -> Result<(Vec<f64>, Vec<Issue>), Vec<Issue>> {
        let bbox = x.bbox();
        let y = &self.observation_box(&bbox);
        if !y.is_finite() {
            return Err(Vec::new());
        }
        let mut extra = None;
        let bound = match prop {
            Propagator::ReachLp | Propagator::CrownUnrolled | Propagator::ReachSdp => {
                // Reach-LP, intersected with CL-CROWN from the same analysis:
                // never looser than CL-CROWN (CL-CROWN's control box is also
                // intersected with IBP, which Reach-LP's per-facet bound is not)
                let analysis = Relaxation::new(&self.net, y, Mode::Crown);
                if !analysis.is_finite() {
                    return Err(Vec::new());
                }
                // the facets' bound and CL-CROWN's control box, from one
                // back-substitution through the controller
                let spec = LinearUpper::of_spec(facets);
                let (bound, u) = self.back_step_with(t, &spec, &analysis, &bbox, true);
                let Some(u) = u.filter(IBox::is_finite) else {
                    return Err(Vec::new());
                };
                if !alone {
                    let (separate, more) = self
                        .push_control_box(t, &spec, &bbox, &u)
                        .concretize_region(x);
                    extra = Some((separate, more));
                }
                bound
            }
            Propagator::IbpSeparate | Propagator::CrownSeparate | Propagator::SgIbpSeparate => {
                let u = match (prop, x) {
                    (Propagator::IbpSeparate, _) => {
                        let a = Relaxation::new(&self.net, y, Mode::Ibp);
                        a.is_finite().then(|| a.output_box(Mode::Ibp))
                    }
                    (Propagator::CrownSeparate, Region::Box(b)) if self.kernel_applies() => {
                        kernel::control_box(self, b).flatten()
                    }
                    (Propagator::CrownSeparate, _) => {
                        let a = Relaxation::new(&self.net, y, Mode::Crown);
                        a.is_finite().then(|| a.output_box(Mode::Crown))
                    }
                    _ => self.sg_ibp_control(y),
                };
                match u.filter(IBox::is_finite) {
                    Some(u) => self.push_control_box(t, &LinearUpper::of_spec(facets), &bbox, &u),
                    None => return Err(Vec::new()),
                }
            }
        };
        let (mut ub, mut issues) = bound.concretize_region(x);
        if !all_finite(&ub) {
            return Err(issues);
        }
        if let Some((other, more)) = extra {
            issues.extend(more);
            if !all_finite(&other) {
                return Err(issues);
            }
            for (u, o) in ub.iter_mut().zip(other) {
                *u = u.min(o);
            }
        }
        Ok((ub, issues))
    }

    /// Reach-SDP bounds of every facet for states in `x` at step `t` (see
    /// [`super::sdp`]); `+∞` where the solver's answer was not usable, and the
    /// issue is reported. A network that is not ReLU-only gives `+∞` everywhere
    /// (`check` rejects that combination), and so does an affine one (no
    /// hidden layer: Reach-LP, which the step intersects with, is exact).
    fn reach_sdp(&self, t: usize, x: &Region, facets: &DMatrix<f64>) -> (Vec<f64>, Vec<Issue>) {
        let n = self.states();
        let p = self.plant.obs.ncols();
        let bbox = x.bbox();
        let xi = bbox.product(&self.plant.v);
        let Some(merged) = sdp::merge(&self.net, &self.obs_xv, &xi) else {
            return (
                vec![f64::INFINITY; facets.nrows()],
                vec![Issue::SdpNeedsRelu],
            );
        };
        if merged.layers.len() < 2 {
            // an affine controller: Reach-LP is exact up to rounding already,
            // and the SDP has no neuron to encode
            return (vec![f64::INFINITY; facets.nrows()], Vec::new());
        }
        let rows: Vec<(Vec<f64>, f64)> = match x {
            Region::Polytope { rows, .. } => rows
                .iter()
                .map(|(a, h)| {
                    let mut a = a.clone();
                    a.extend(std::iter::repeat_n(0.0, p));
                    (a, *h)
                })
                .collect(),
            Region::Box(_) | Region::Ball { .. } => Vec::new(),
        };
        let prog = sdp::StepSdp::new(&merged, &xi, &rows);
        let d = self.at(t);
        let (wl, bl) = merged
            .layers
            .last()
            .expect("a merged network has an output layer");
        let h_max = prog.last_hidden_max();
        let x_max = bbox.abs_max();
        let h_off = prog.last_hidden();
        let model_delta = self.plant_at(t).err.as_ref().and_then(|_| {
            let u = Relaxation::new(&self.net, &self.observation_box(&bbox), Mode::Ibp)
                .output_box(Mode::Ibp);
            self.model_delta(t, &bbox, &u.abs_max())
        });
        let mut out = Vec::with_capacity(facets.nrows());
        let mut issues = Vec::new();
        for r in 0..facets.nrows() {
            let c: Vec<f64> = facets.row(r).iter().copied().collect();
            let ca: Vec<f64> = (0..n)
                .map(|j| (0..n).map(|i| c[i] * d.plant.a[(i, j)]).sum())
                .collect();
            let cb: Vec<f64> = (0..d.plant.b.ncols())
                .map(|j| (0..n).map(|i| c[i] * d.plant.b[(i, j)]).sum())
                .collect();
            let mut phi = vec![0.0; prog.dim()];
            phi[..n].copy_from_slice(&ca);
            for k in 0..wl.ncols() {
                phi[h_off + k] = (0..wl.nrows()).map(|j| cb[j] * wl[(j, k)]).sum();
            }
            // constant: cᵀB b_L + cᵀc + max_w cᵀw + |cᵀB|·(merge error) + rounding of φ
            let cab: Vec<f64> = (0..n)
                .map(|j| (0..n).map(|i| (c[i] * d.plant.a[(i, j)]).abs()).sum())
                .collect();
            let cbb: Vec<f64> = cb.iter().map(|v| v.abs()).collect();
            let cbb_abs: Vec<f64> = (0..d.plant.b.ncols())
                .map(|j| (0..n).map(|i| (c[i] * d.plant.b[(i, j)]).abs()).sum())
                .collect();
            let size = sum_upper((0..n).map(|j| cab[j] * x_max[j]).chain((0..wl.nrows()).map(
                |j| {
                    cbb_abs[j]
                        * sum_upper(
                            (0..wl.ncols())
                                .map(|k| wl[(j, k)].abs() * h_max[k])
                                .chain([bl[j].abs()]),
                        )
                },
            )));
            let round = (gamma(n + wl.ncols() + 4) * size * 1.0625 + 1e-300).next_up();
            let konst = sum_upper(
                (0..wl.nrows())
                    .map(|j| cb[j] * bl[j])
                    .chain((0..n).map(|i| c[i] * d.plant.c[i]))
                    .chain([
                        ravel_base::num::dot_box_upper(&c, &self.plant.w.lo, &self.plant.w.hi),
                        sum_upper(cbb.iter().zip(&merged.err).map(|(a, e)| a * e)),
                        round,
                        slack(
                            gamma(n + 2),
                            &c.iter().map(|v| v.abs()).collect::<Vec<_>>(),
                            &d.plant.c.iter().map(|v| v.abs()).collect::<Vec<_>>(),
                        ),
                    ]),
            );
            let konst = match &model_delta {
                Some(delta) => sum_upper([
                    konst,
                    sum_upper(c.iter().zip(delta).map(|(f, d)| mul0(f.abs(), *d))),
                ]),
                None => konst,
            };
            let last = prog.dim() - 1;
            phi[last] = konst;
            let b = prog.bound(&phi);
            issues.extend(b.issue);
            out.push(b.value);
        }
        (out, issues)
    }

    /// The control box over `y` by IBP on a simulation-guided partition of
    /// `y`; `None` when a bound overflowed.
    fn sg_ibp_control(&self, y: &IBox) -> Option<IBox> {
        let inputs = open_loop::sample_inputs(y, SG_SAMPLES, 0x5EED);
        let out = open_loop::output_set(
            &self.net,
            y,
            Mode::Ibp,
            &Shape::Box,
            &open_loop::Partitioner::Guided {
                strategy: Strategy::Sg,
                budget: SG_BUDGET,
            },
            &inputs,
            &|| 0.0,
        );
        match out.bbox() {
            Some(b) => Some(b),
            None => {
                let a = Relaxation::new(&self.net, y, Mode::Ibp);
                a.is_finite().then(|| a.output_box(Mode::Ibp))
            }
        }
    }

    /// `F (A x + B u + c + w)` bounded linearly in `x`, over `u ∈ U`, `w ∈ W`,
    /// for the facet rows `F` of `spec` (an identity bound, offsets 0).
    fn push_control_box(&self, t: usize, spec: &LinearUpper, x: &IBox, u: &IBox) -> LinearUpper {
        let n = self.states();
        let xuw = x.product(u).product(&self.plant.w);
        let d = self.at(t);
        let mut bound = spec
            .through_affine(&d.dyn_xuw, &d.plant.c, &xuw.abs_max())
            .split_concretize(n, &u.product(&self.plant.w));
        if let Some(delta) = self.model_delta(t, x, &u.abs_max()) {
            Self::add_model_error(&mut bound.offset, &spec.coef, &delta);
        }
        bound
    }

    /// One step of back-substitution (the tutorial's Lemma on bounds of
    /// `x_{t+1}`): a bound `M x_{t+1} ≤ …` becomes one linear in `x_t`, for
    /// `x_t ∈ x` (a box containing the reachable states). CROWN with
    /// specification `M B` bounds `M B π(y)` by a linear function of `y`
    /// (choosing the upper or lower relaxation per control by the sign of
    /// each row, per neuron), `y = Cᵀx + v` is substituted, and the noise
    /// `v`, `w` is bounded over its boxes.
    fn back_step(
        &self,
        t: usize,
        bound: &LinearUpper,
        analysis: &Relaxation,
        x: &IBox,
    ) -> LinearUpper {
        self.back_step_with(t, bound, analysis, x, false).0
    }

    /// [`ClosedLoop::back_step`], and with `control_box` also the CROWN
    /// control box (`analysis.output_box(Mode::Crown)`), from the same
    /// back-substitution through the controller (see
    /// [`Relaxation::upper_and_output_box`]).
    fn back_step_with(
        &self,
        t: usize,
        bound: &LinearUpper,
        analysis: &Relaxation,
        x: &IBox,
        control_box: bool,
    ) -> (LinearUpper, Option<IBox>) {
        let n = self.states();
        let (w, v) = (&self.plant.w, &self.plant.v);
        let d = self.at(t);
        let abs_x = x.abs_max();
        let direct = bound
            .through_affine(&d.dyn_xw, &d.plant.c, &x.abs_max_with(w))
            .split_concretize(n, w);
        // S = M B in f64; its rounding error times the size of u goes into the offsets
        let spec = bound.coef.mul(&d.plant.b);
        let k = gamma(n + 2);
        let mb_abs = bound.coef.abs().mul(&d.b_abs);
        let u_abs = analysis
            .boxes()
            .last()
            .expect("an analysis has its input box")
            .abs_max();
        let xv_abs = x.abs_max_with(v);
        // with optimised slopes, each row's measure is what this step makes
        // of it: the control part composed with y = Cᵀx + v and added to the
        // direct part, over the box of x (and its maximiser, mapped to y)
        let objective = |r: usize, cand: &LinearUpper| -> (f64, Vec<f64>) {
            let over_xv = cand.through_affine(&self.obs_xv, &self.obs_zero, &xv_abs);
            let v_star = corner(&over_xv.coef.row(0)[n..], v);
            let direct_r = LinearUpper {
                coef: Rows::from_row_major(1, n, direct.coef.row(r).to_vec()),
                offset: vec![direct.offset[r]],
            };
            let total = direct_r.add(&over_xv.split_concretize(n, v), &abs_x);
            let mut xv_star = corner(total.coef.row(0), x);
            xv_star.extend(v_star);
            let y_star = &self.obs_xv * DVector::from_vec(xv_star);
            (total.concretize(x)[0], y_star.as_slice().to_vec())
        };
        let (over_y, u) = if control_box {
            let (over_y, u) =
                analysis.upper_and_output_box(spec, self.slope_steps, Some(&objective));
            (over_y, Some(u))
        } else {
            let over_y = analysis.upper_optimised(spec, self.slope_steps, Some(&objective));
            (over_y, None)
        };
        let mut control = over_y
            .through_affine(&self.obs_xv, &self.obs_zero, &xv_abs)
            .split_concretize(n, v);
        let under = crate::crown::underflow_of(&u_abs);
        for (o, row) in control.offset.iter_mut().zip(mb_abs.iter_rows()) {
            *o = sum_upper([*o, slack(k, row, &u_abs), under]);
        }
        let mut out = direct.add(&control, &abs_x);
        if let Some(delta) = self.model_delta(t, x, &u_abs) {
            Self::add_model_error(&mut out.offset, &bound.coef, &delta);
        }
        (out, u)
    }

    /// The unrolled propagator: reachable sets of steps `0..=horizon` from
    /// `x0`, each bounded through all earlier copies of the loop back to `x0`
    /// and intersected with the one-step Reach-LP bound from the previous set.
    /// Hidden-neuron bounds of copy `t` are themselves unrolled (the
    /// [`Relaxation::with_hook`] hook), and kept for later steps, so the cost is
    /// quadratic in the horizon, not exponential.
    /// With `parent` (the sets of a cell containing `x0`, same boundary), each
    /// set is also intersected with the parent's set of the same step.
    /// `stop` is asked before each step whether to stop (a time limit); the
    /// remaining steps are then [`Step::timed_out`].
    pub fn unrolled(
        &self,
        x0: &Region,
        horizon: usize,
        boundary: &Boundary,
        parent: Option<&[Region]>,
        stop: &dyn Fn() -> bool,
    ) -> Vec<Step> {
        self.unrolled_with(x0, horizon, boundary, parent, stop, false)
    }

    /// The unrolled propagator's own bounds: every set bounded through the
    /// unrolled loop back to `x0` only, never intersected with a one-step
    /// Reach-LP bound (for soundness tests).
    pub fn unrolled_alone(&self, x0: &Region, horizon: usize, boundary: &Boundary) -> Vec<Step> {
        self.unrolled_with(x0, horizon, boundary, None, &|| false, true)
    }

    fn unrolled_with(
        &self,
        x0: &Region,
        horizon: usize,
        boundary: &Boundary,
        parent: Option<&[Region]>,
        stop: &dyn Fn() -> bool,
        alone: bool,
    ) -> Vec<Step> {
        let n = self.states();
        let mut steps = vec![Step::new(x0.clone(), Vec::new())];
        let mut boxes = vec![x0.bbox()];
        let mut analyses: Vec<Relaxation> = Vec::with_capacity(horizon);
        for t in 0..horizon {
            if stop() {
                while steps.len() <= horizon {
                    steps.push(Step::timed_out(n));
                }
                break;
            }
            let y = self.observation_box(&boxes[t]);
            let hook_issues = std::cell::RefCell::new(Vec::new());
            let analysis = {
                let hook = |over_y: &LinearUpper| -> Vec<f64> {
                    let over_x = over_y
                        .through_affine(
                            &self.obs_xv,
                            &self.obs_zero,
                            &boxes[t].abs_max_with(&self.plant.v),
                        )
                        .split_concretize(n, &self.plant.v);
                    let over_x0 = self.back_to_start(over_x, &analyses, &boxes, t);
                    let (ub, issues) = over_x0.concretize_region(x0);
                    hook_issues.borrow_mut().extend(issues);
                    ub
                };
                Relaxation::with_hook(&self.net, &y, Mode::Crown, Some(&hook))
            };
            if !(y.is_finite() && analysis.is_finite()) {
                break;
            }
            let over_xt = self.back_step(
                t,
                &LinearUpper::of_spec(self.facets(boundary, t + 1)),
                &analysis,
                &boxes[t],
            );
            analyses.push(analysis);
            let (one_step, mut issues) = over_xt.concretize_region(&steps[t].set);
            let over_x0 = self.back_to_start(over_xt, &analyses[..t], &boxes, t);
            let (through, more) = over_x0.concretize_region(x0);
            issues.extend(more);
            issues.extend(hook_issues.into_inner());
            // an overflow in either bound makes this step and all later ones unbounded
            if !(all_finite(&one_step) && all_finite(&through)) {
                steps.push(Step::overflowed(n, issues));
                break;
            }
            let ub: Vec<f64> = if alone {
                through
            } else {
                one_step
                    .iter()
                    .zip(&through)
                    .map(|(a, b)| a.min(*b))
                    .collect()
            };
            let mut set = self.region_of(boundary, t + 1, &ub);
            if let Some(p) = parent.and_then(|p| p.get(t + 1)) {
                set = set.intersect(p);
            }
            boxes.push(set.bbox());
            steps.push(Step::new(set, issues));
        }
        while steps.len() <= horizon {
            steps.push(Step::overflowed(n, Vec::new()));
        }
        steps
    }

    /// Back-substitute a bound on `x_s` to one on `x_0` through `analyses[..s]`.
    fn back_to_start(
        &self,
        mut bound: LinearUpper,
        analyses: &[Relaxation],
        boxes: &[IBox],
        s: usize,
    ) -> LinearUpper {
        for r in (0..s).rev() {
            bound = self.back_step(r, &bound, &analyses[r], &boxes[r]);
        }
        bound
    }
}

/// The facet matrix of a boundary at step `t` for `n` states: `[I; −I]`
/// (the bounding box), then its directions.
pub fn facets(n: usize, boundary: &Boundary, t: usize) -> DMatrix<f64> {
    let dirs = boundary.directions(t);
    let extra = dirs.map_or(0, DMatrix::nrows);
    let mut f = DMatrix::zeros(2 * n + extra, n);
    for i in 0..n {
        f[(i, i)] = 1.0;
        f[(n + i, i)] = -1.0;
    }
    if let Some(d) = dirs {
        f.view_mut((2 * n, 0), (extra, n)).copy_from(d);
    }
    f
}

#[cfg(test)]
mod tests {
    use super::*;
    use ravel_base::nn::{Activation, Layer};
    use ravel_base::rng::Rng;

    /// The Reach-SDP facet bounds alone (before they meet Reach-LP's) must
    /// cover a plant whose matrices are only known up to a model error.
    #[test]
    fn reach_sdp_on_an_affine_controller_does_not_fail() {
        // no hidden layer at all (no ReLU, no control limits): the SDP has
        // no neuron to encode; the step must still be bounded
        let net = Network::new(
            2,
            vec![Layer::Affine {
                w: DMatrix::from_row_slice(1, 2, &[-0.4, -0.9]),
                b: DVector::from_column_slice(&[0.1]),
            }],
        );
        let zero = IBox::new(vec![0.0; 2], vec![0.0; 2]);
        let plant = Plant {
            a: DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 0.0, 1.0]),
            b: DMatrix::from_row_slice(2, 1, &[0.5, 1.0]),
            c: DVector::zeros(2),
            obs: DMatrix::identity(2, 2),
            w: zero.clone(),
            v: IBox::new(vec![-0.01, 0.0], vec![0.01, 0.0]),
            err: None,
        };
        let cl = ClosedLoop::new(plant, net);
        let x = Region::Box(IBox::new(vec![1.0, -1.0], vec![2.0, 0.5]));
        let lp = cl.step(0, &x, Propagator::ReachLp, &Boundary::Box);
        let sdp = cl.step(0, &x, Propagator::ReachSdp, &Boundary::Box);
        let (a, b) = (lp.set.bbox(), sdp.set.bbox());
        assert!(b.is_finite() && a.contains_box(&b), "{b:?} vs {a:?}");
    }

    #[test]
    fn reach_sdp_bounds_cover_the_model_error() {
        let net = Network::new(
            2,
            vec![
                Layer::Affine {
                    w: DMatrix::from_row_slice(3, 2, &[1.0, -0.5, 0.3, 0.8, -0.7, 0.2]),
                    b: DVector::from_column_slice(&[0.1, -0.2, 0.05]),
                },
                Layer::Act(Activation::Relu),
                Layer::Affine {
                    w: DMatrix::from_row_slice(1, 3, &[0.6, -0.9, 0.4]),
                    b: DVector::from_column_slice(&[0.0]),
                },
            ],
        );
        let a = DMatrix::from_row_slice(2, 2, &[1.0, 0.5, 0.0, 1.0]);
        let b = DMatrix::from_row_slice(2, 1, &[0.1, 0.5]);
        let err = ModelError {
            a: DMatrix::from_element(2, 2, 0.05),
            b: DMatrix::from_element(2, 1, 0.05),
            c: DVector::from_element(2, 0.05),
        };
        let zero = IBox::new(vec![0.0; 2], vec![0.0; 2]);
        let plant = Plant {
            a,
            b,
            c: DVector::zeros(2),
            obs: DMatrix::identity(2, 2),
            w: zero.clone(),
            v: zero,
            err: Some(err.clone()),
        };
        let cl = ClosedLoop::new(plant, net);
        let x = IBox::new(vec![1.0, -1.0], vec![2.0, 0.5]);
        let facets = cl.facets(&Boundary::spread(6), 1);
        let (ub, issues) = cl.reach_sdp(0, &Region::Box(x.clone()), &facets);
        assert!(issues.is_empty(), "{issues:?}");
        let mut rng = Rng::new(3);
        let mut worst = vec![f64::NEG_INFINITY; facets.nrows()];
        for _ in 0..4000 {
            let s: Vec<f64> = (0..2).map(|i| rng.uniform(x.lo[i], x.hi[i])).collect();
            let (u, next) = cl.simulate(0, &s, &[0.0, 0.0], &[0.0, 0.0]);
            // the model error at its worst for a random sign pattern
            let sign = |rng: &mut Rng| if rng.below(2) == 0 { -1.0 } else { 1.0 };
            let y: Vec<f64> = (0..2)
                .map(|i| {
                    next[i]
                        + sign(&mut rng) * err.c[i]
                        + (0..2)
                            .map(|j| sign(&mut rng) * err.a[(i, j)] * s[j])
                            .sum::<f64>()
                        + sign(&mut rng) * err.b[(i, 0)] * u[0]
                })
                .collect();
            for (k, w) in worst.iter_mut().enumerate() {
                let v = facets[(k, 0)] * y[0] + facets[(k, 1)] * y[1];
                assert!(v <= ub[k], "facet {k}: {v} > {}", ub[k]);
                *w = w.max(v);
            }
        }
        // the term matters here: without it, some facet would be violated
        let nominal = ClosedLoop::new(
            Plant {
                err: None,
                ..cl.plant.clone()
            },
            cl.net.clone(),
        );
        let (plain, _) = nominal.reach_sdp(0, &Region::Box(x), &facets);
        assert!(
            plain.iter().zip(&worst).any(|(p, w)| w > p),
            "the sampled model errors should exceed the nominal bound somewhere"
        );
    }
}
