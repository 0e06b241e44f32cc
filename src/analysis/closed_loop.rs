//! One step of a neural feedback loop, exactly (simulation) and as a set
//! (the closed-loop propagators).
//!
//! The plant is `x⁺ = A x + B u + c + w`, `y = Cᵀ x + v`, `u = π(y)` where `π`
//! already contains the control saturation. Noise `w ∈ W`, `v ∈ V` is
//! adversarial: any value in its box at every step.

use nalgebra::{DMatrix, DVector};

use super::crown::{affine_image, Analysis, LinearUpper, Mode};
use crate::nn::Network;
use crate::num::{gamma, slack, sum_upper};
use crate::sets::IBox;

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
}

impl Propagator {
    /// The spec-language name.
    pub fn name(self) -> &'static str {
        match self {
            Propagator::ReachLp => "reach_lp",
            Propagator::CrownSeparate => "crown_separate",
            Propagator::IbpSeparate => "ibp_separate",
        }
    }
}

/// A closed loop ready for analysis, with the block matrices precomputed.
#[derive(Clone, Debug)]
pub struct ClosedLoop {
    /// The plant.
    pub plant: Plant,
    /// The controller, saturation included.
    pub net: Network,
    /// `[Cᵀ I]`: `(x, v) ↦ y`.
    obs_xv: DMatrix<f64>,
    /// `[Cᵀ I 0]`: `(x, v, w) ↦ y`.
    obs_xvw: DMatrix<f64>,
    /// `[A 0 I]`: `(x, v, w) ↦ A x + w`.
    dyn_xvw: DMatrix<f64>,
    /// `[A B I]`: `(x, u, w) ↦ A x + B u + w`.
    dyn_xuw: DMatrix<f64>,
    /// Box facets `[I; −I]`.
    facets: DMatrix<f64>,
}

impl ClosedLoop {
    /// Assemble a closed loop (dimensions must agree; `check` guarantees it).
    pub fn new(plant: Plant, net: Network) -> ClosedLoop {
        let n = plant.a.nrows();
        let m = plant.b.ncols();
        let p = plant.obs.ncols();
        let ct = plant.obs.transpose();
        let mut obs_xv = DMatrix::zeros(p, n + p);
        obs_xv.view_mut((0, 0), (p, n)).copy_from(&ct);
        obs_xv.view_mut((0, n), (p, p)).fill_with_identity();
        let mut obs_xvw = DMatrix::zeros(p, n + p + n);
        obs_xvw.view_mut((0, 0), (p, n + p)).copy_from(&obs_xv);
        let mut dyn_xvw = DMatrix::zeros(n, n + p + n);
        dyn_xvw.view_mut((0, 0), (n, n)).copy_from(&plant.a);
        dyn_xvw.view_mut((0, n + p), (n, n)).fill_with_identity();
        let mut dyn_xuw = DMatrix::zeros(n, n + m + n);
        dyn_xuw.view_mut((0, 0), (n, n)).copy_from(&plant.a);
        dyn_xuw.view_mut((0, n), (n, m)).copy_from(&plant.b);
        dyn_xuw.view_mut((0, n + m), (n, n)).fill_with_identity();
        let mut facets = DMatrix::zeros(2 * n, n);
        for i in 0..n {
            facets[(i, i)] = 1.0;
            facets[(n + i, i)] = -1.0;
        }
        ClosedLoop {
            plant,
            net,
            obs_xv,
            obs_xvw,
            dyn_xvw,
            dyn_xuw,
            facets,
        }
    }

    /// State dimension.
    pub fn states(&self) -> usize {
        self.plant.a.nrows()
    }

    /// One exact step: returns `(u, x⁺)` for state `x` and noise `w`, `v` (in `f64`).
    pub fn simulate(&self, x: &[f64], w: &[f64], v: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let xv = DVector::from_column_slice(x);
        let y = self.plant.obs.transpose() * &xv + DVector::from_column_slice(v);
        let u = self.net.forward(y.as_slice());
        let uv = DVector::from_column_slice(&u);
        let next = &self.plant.a * &xv
            + &self.plant.b * uv
            + &self.plant.c
            + DVector::from_column_slice(w);
        (u, next.as_slice().to_vec())
    }

    /// The box of possible observations for states in `x`.
    pub fn observation_box(&self, x: &IBox) -> IBox {
        let p = self.plant.obs.ncols();
        affine_image(&self.obs_xv, &DVector::zeros(p), &x.product(&self.plant.v))
    }

    /// An over-approximation of the set of next states for states in `x`.
    pub fn step(&self, x: &IBox, prop: Propagator) -> IBox {
        let y = self.observation_box(x);
        match prop {
            Propagator::IbpSeparate => {
                let u = Analysis::new(&self.net, &y, Mode::Ibp).output_box(Mode::Ibp);
                self.push_control_box(x, &u)
            }
            Propagator::CrownSeparate => {
                let u = Analysis::new(&self.net, &y, Mode::Crown).output_box(Mode::Crown);
                self.push_control_box(x, &u)
            }
            Propagator::ReachLp => self.reach_lp(x, &y),
        }
    }

    /// `A X + B U + c + W` in interval arithmetic.
    fn push_control_box(&self, x: &IBox, u: &IBox) -> IBox {
        affine_image(
            &self.dyn_xuw,
            &self.plant.c,
            &x.product(u).product(&self.plant.w),
        )
    }

    /// Reach-LP with box facets (the closed form of the tutorial's Lemma on
    /// bounds of `x_{t+1}`): for each facet `a`, CROWN bounds `aᵀB π(y)` by a
    /// linear function of `y` (choosing the upper or lower relaxation per
    /// control by the sign of `aᵀB`, which CROWN with specification `aᵀB`
    /// does per neuron), `y = Cᵀx + v` is substituted, the dynamics are
    /// added, and the result is maximised over `x × V × W`.
    fn reach_lp(&self, x: &IBox, y: &IBox) -> IBox {
        let n = self.states();
        let analysis = Analysis::new(&self.net, y, Mode::Crown);
        // Only the size of u is needed here (for a rounding-error term), so the
        // cheap IBP-propagated box suffices.
        let u_box = analysis.output_box(Mode::Ibp);
        let xi = x.product(&self.plant.v).product(&self.plant.w);
        let abs_xi = xi.abs_max();
        let spec = &self.facets * &self.plant.b;
        // rounding error of F·B, times the size of u
        let k = gamma(n + 2);
        let fb_abs = self.facets.abs() * self.plant.b.abs();
        let u_abs = u_box.abs_max();
        let spec_slack: Vec<f64> = (0..spec.nrows())
            .map(|r| {
                let row: Vec<f64> = fb_abs.row(r).iter().copied().collect();
                slack(k, &row, &u_abs)
            })
            .collect();
        let p = self.plant.obs.ncols();
        let control =
            analysis
                .upper(spec)
                .through_affine(&self.obs_xvw, &DVector::zeros(p), &abs_xi);
        let direct = LinearUpper::of_spec(self.facets.clone()).through_affine(
            &self.dyn_xvw,
            &self.plant.c,
            &abs_xi,
        );
        let total = direct.add(&control, &abs_xi);
        let ub: Vec<f64> = total
            .concretize(&xi)
            .into_iter()
            .zip(&spec_slack)
            .map(|(b, s)| sum_upper([b, *s]))
            .collect();
        let hi = ub[..n].to_vec();
        let lo = ub[n..].iter().map(|v| -v).collect();
        IBox::new(lo, hi)
    }
}
