//! A small primal–dual interior-point method for Reach-SDP's programs:
//! proposes multipliers, which [`super::sdp`] re-certifies exactly as it
//! does Clarabel's.
//!
//! # Why not only Clarabel
//! Clarabel keeps the PSD cone's slack in its KKT system: for an `n × n`
//! cone that is a dense block of `n(n+1)/2` rows, factored at every
//! iteration in `O(n⁶)`. Reach-SDP has few multipliers (a handful per
//! neuron) and every constraint matrix is of rank two, so the classical
//! route is far cheaper: eliminate everything but the `m` multipliers and
//! factor the `m × m` Schur complement (Helmberg–Rendl–Vanderbei–Wolkowicz /
//! Kojima–Shindoh–Hara / Monteiro direction, Mehrotra's predictor–corrector).
//! With constraint matrices `Aₖ = cₖ·sym(v_a v_bᵀ)` its entries are products
//! of the Gram matrices `VᵀXV` and `VᵀZ⁻¹V` over the distinct vectors `V`,
//! so an iteration is a few `n × n` and `n × |V|` products, no `n⁴` term.
//! For a 2 → 32 → 32 → 3 controller (`n` = 65) this is about 10× less
//! work per iteration than the dense KKT factorisation.
//!
//! # Contract
//! Soundness never rests on this solver: it returns a proposal `y` only
//! when its residuals and duality gap are small ([`Ipm::Solved`]), and the
//! caller rebuilds the matrix from `y` in `f64`, bounds its largest
//! eigenvalue and pays for it in the bound, as for any solver. When it
//! stalls (a step too short, a Schur matrix that will not factor, a
//! non-finite number, the iteration limit) it says so
//! ([`Ipm::NotSolved`]) and the caller asks Clarabel.
//!
//! # The program (SDPT3's "dual" form)
//! maximise `bᵀy` subject to `Z = C − Σₖ yₖ Aₖ ⪰ 0` and `yₖ ≥ 0` for the
//! multipliers marked nonnegative (a linear block `z = (yₖ)`). Its primal
//! is `min ⟨C, X⟩` over `X ⪰ 0`, `x ≥ 0` with `⟨Aₖ, X⟩ − xₖ = bₖ`.

use dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::{
    cholesky_in_place, cholesky_in_place_scratch, LltRegularization,
};
use faer::linalg::cholesky::llt::solve::solve_in_place;
use faer::Par;
use nalgebra::{Cholesky, DMatrix};

/// One constraint matrix `coef · sym(v_a v_bᵀ)` (`sym(M) = (M + Mᵀ)/2`),
/// with `a`, `b` indices into [`Problem::vecs`].
#[derive(Clone, Copy, Debug)]
pub struct Con {
    /// The factor `coef`.
    pub coef: f64,
    /// Index of `v_a`.
    pub a: usize,
    /// Index of `v_b`.
    pub b: usize,
    /// Whether its multiplier must be nonnegative (else it is free).
    pub nonneg: bool,
}

/// A program in the form above.
pub struct Problem {
    /// Side of the matrices.
    pub n: usize,
    /// `C` (symmetric).
    pub c: DMatrix<f64>,
    /// The distinct sparse vectors the constraints are built of.
    pub vecs: Vec<Vec<(usize, f64)>>,
    /// One per multiplier `yₖ`.
    pub cons: Vec<Con>,
    /// The objective `bᵀy` to maximise.
    pub b: Vec<f64>,
}

/// What the solver came to.
#[derive(Clone, Debug, PartialEq)]
pub enum Ipm {
    /// Residuals and gap below tolerance: the multipliers `y`, and the
    /// iterations it took.
    Solved {
        /// The multipliers.
        y: Vec<f64>,
        /// Predictor–corrector steps taken.
        iterations: usize,
    },
    /// It stopped without converging (the reason, for tests and profiles).
    NotSolved(&'static str),
}

/// Converged: relative duality gap, dual and primal residuals below these.
/// Only `y` is used, so the dual residual (which the re-certification pays
/// for) is held tightest; the primal one measures how near `y` is to
/// optimal, and on programs without a strictly feasible `X` (a neuron that
/// is stable is pinned by two inequalities) it stalls near 1e-8.
const TOL: (f64, f64, f64) = (1e-9, 1e-9, 1e-7);
/// Good enough to return when the method stalls afterwards.
const ACCEPT: (f64, f64, f64) = (1e-6, 1e-8, 1e-5);
/// Iteration limit.
const MAX_ITER: usize = 100;

/// The current iterate and the data's dense forms.
struct State<'p> {
    p: &'p Problem,
    /// The vectors as a dense `n × |V|` matrix.
    v: DMatrix<f64>,
    /// For each constraint, its linear-block index (nonnegative ones).
    lp: Vec<Option<usize>>,
    x: DMatrix<f64>,
    z: DMatrix<f64>,
    xl: Vec<f64>,
    zl: Vec<f64>,
    y: Vec<f64>,
    /// Whether the iterate [`State::iterate`] last started from was within ACCEPT.
    acceptable: bool,
}

/// `Σₖ wₖ Aₖ` as a dense symmetric matrix.
fn combine(p: &Problem, w: &[f64]) -> DMatrix<f64> {
    let mut out = DMatrix::<f64>::zeros(p.n, p.n);
    for (con, &wk) in p.cons.iter().zip(w) {
        let s = 0.5 * con.coef * wk;
        if s == 0.0 {
            continue;
        }
        for &(i, x) in &p.vecs[con.a] {
            for &(j, y) in &p.vecs[con.b] {
                let t = s * x * y;
                out[(i, j)] += t;
                out[(j, i)] += t;
            }
        }
    }
    out
}

/// `⟨Aₖ, S⟩` for every constraint, from `G = Vᵀ S V` (any `S`; the
/// constraint matrices are symmetric, so only `sym(S)` counts).
fn inner(p: &Problem, g: &DMatrix<f64>) -> Vec<f64> {
    p.cons
        .iter()
        .map(|c| c.coef * 0.5 * (g[(c.a, c.b)] + g[(c.b, c.a)]))
        .collect()
}

/// The largest `α ≤ cap` with `S + α·D ⪰ 0` (for `S ≻ 0`); `None` when `S`
/// will not factor.
fn max_step(s: &DMatrix<f64>, d: &DMatrix<f64>, cap: f64) -> Option<f64> {
    let l = Cholesky::new(s.clone())?.l();
    // L⁻¹ D L⁻ᵀ
    let li_d = l.solve_lower_triangular(d)?;
    let t = l.solve_lower_triangular(&li_d.transpose())?;
    let t = (&t + t.transpose()) * 0.5;
    let eig = t.symmetric_eigenvalues();
    if eig.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let lmin = eig.min();
    Some(if lmin >= 0.0 {
        cap
    } else {
        cap.min(-1.0 / lmin)
    })
}

fn max_step_lp(s: &[f64], d: &[f64], cap: f64) -> f64 {
    s.iter()
        .zip(d)
        .filter(|(_, dv)| **dv < 0.0)
        .fold(cap, |a, (sv, dv)| a.min(-sv / dv))
}

fn sym(m: &DMatrix<f64>) -> DMatrix<f64> {
    (m + m.transpose()) * 0.5
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

/// Solve the program (see the module documentation).
pub fn solve(p: &Problem) -> Ipm {
    let n = p.n;
    let m = p.cons.len();
    if n == 0 || m == 0 || p.b.len() != m {
        return Ipm::NotSolved("empty program");
    }
    let mut v = DMatrix::<f64>::zeros(n, p.vecs.len());
    for (k, vec) in p.vecs.iter().enumerate() {
        for &(i, x) in vec {
            v[(i, k)] += x;
        }
    }
    let mut lp = Vec::with_capacity(m);
    let mut nl = 0;
    for c in &p.cons {
        lp.push(c.nonneg.then(|| {
            nl += 1;
            nl - 1
        }));
    }
    // starting point (after SDPT3): scaled identities, y = 0
    let a_norms: Vec<f64> = p
        .cons
        .iter()
        .map(|c| {
            let na = norm(&p.vecs[c.a].iter().map(|e| e.1).collect::<Vec<_>>());
            let nb = norm(&p.vecs[c.b].iter().map(|e| e.1).collect::<Vec<_>>());
            c.coef.abs() * na * nb
        })
        .collect();
    let sn = (n as f64).sqrt();
    let xi = a_norms
        .iter()
        .zip(&p.b)
        .map(|(a, b)| sn * (1.0 + b.abs()) / (1.0 + a))
        .fold(10f64.max(sn), f64::max);
    let eta = a_norms
        .iter()
        .copied()
        .fold(10f64.max(sn).max(p.c.norm()), f64::max);
    let mut st = State {
        p,
        v,
        lp,
        x: DMatrix::identity(n, n) * xi,
        z: DMatrix::identity(n, n) * eta,
        xl: vec![xi; nl],
        zl: vec![eta; nl],
        y: vec![0.0; m],
        acceptable: false,
    };
    let b_norm = norm(&p.b);
    let c_norm = p.c.norm();
    // the last iterate within ACCEPT, for when the method stalls later
    let mut best: Option<(Vec<f64>, usize)> = None;
    let mut why = "iteration limit";
    for it in 0..MAX_ITER {
        let y = st.y.clone();
        let step = st.iterate(b_norm, c_norm);
        if st.acceptable {
            best = Some((y, it));
        }
        match step {
            Step::Converged => {
                return Ipm::Solved {
                    y: st.y,
                    iterations: it,
                }
            }
            Step::Continue => {}
            Step::Stuck(w) => {
                why = w;
                break;
            }
        }
    }
    match best {
        Some((y, iterations)) => Ipm::Solved { y, iterations },
        None => Ipm::NotSolved(why),
    }
}

enum Step {
    Converged,
    Continue,
    Stuck(&'static str),
}

impl State<'_> {
    /// `Vᵀ S V`.
    fn gram(&self, s: &DMatrix<f64>) -> DMatrix<f64> {
        self.v.transpose() * (s * &self.v)
    }

    /// One predictor–corrector step.
    fn iterate(&mut self, b_norm: f64, c_norm: f64) -> Step {
        // set once this iterate's residuals are known
        self.acceptable = false;
        let Some(zc) = Cholesky::new(self.z.clone()) else {
            return Step::Stuck("Z lost definiteness");
        };
        let zi = zc.inverse();
        let gx = self.gram(&self.x);
        let gz = self.gram(&zi);
        let res = match self.residuals(&gx, b_norm, c_norm) {
            Ok(res) => res,
            Err(step) => return step,
        };
        let Some(chol) = factor(&self.schur(&gx, &gz)) else {
            return Step::Stuck("Schur complement would not factor");
        };
        let xrd = &self.x * &res.rd;
        let newton = Newton { zi, chol, xrd, res };
        // predictor
        let pred = self.direction(&newton, 0.0, None);
        let Some((ap, ad)) = self.steps(&pred) else {
            return Step::Stuck("step length");
        };
        let (ap, ad) = (ap.min(1.0), ad.min(1.0));
        let mu = newton.res.mu;
        let sigma = self.centering(mu, ap, ad, &pred);
        // corrector
        let corr = &pred.dx * &pred.dz;
        let corr_l: Vec<f64> = pred.dxl.iter().zip(&pred.dzl).map(|(a, b)| a * b).collect();
        let dir = self.direction(&newton, sigma * mu, Some((&corr, &corr_l)));
        let Some((ap2, ad2)) = self.steps(&dir) else {
            return Step::Stuck("step length");
        };
        let tau = 0.9 + 0.09 * ap.min(ad);
        let (ap, ad) = ((tau * ap2).min(1.0), (tau * ad2).min(1.0));
        if ap < 1e-10 && ad < 1e-10 {
            return Step::Stuck("steps too short");
        }
        self.advance(ap, ad, dir)
    }

    /// The residuals of the current iterate (from `gx = Vᵀ X V`), and
    /// whether it is within ACCEPT; the step's end instead when they are
    /// not finite or within TOL.
    fn residuals(
        &mut self,
        gx: &DMatrix<f64>,
        b_norm: f64,
        c_norm: f64,
    ) -> Result<Residuals, Step> {
        let p = self.p;
        let n = p.n;
        let m = p.cons.len();
        let nl = self.xl.len();
        let ax = inner(p, gx);
        let rp: Vec<f64> = (0..m)
            .map(|k| {
                let lin = self.lp[k].map_or(0.0, |r| self.xl[r]);
                p.b[k] - ax[k] + lin
            })
            .collect();
        let rd = &p.c - &self.z - combine(p, &self.y);
        let mut rdl = vec![0.0; nl];
        for (k, r) in self.lp.iter().enumerate() {
            if let Some(r) = *r {
                rdl[r] = self.y[k] - self.zl[r];
            }
        }
        let gap = self.x.dot(&self.z) + dot(&self.xl, &self.zl);
        let mu = gap / (n + nl) as f64;
        let pobj = p.c.dot(&self.x);
        let dobj = dot(&p.b, &self.y);
        let pinf = norm(&rp) / (1.0 + b_norm);
        let dinf = (rd.norm() + norm(&rdl)) / (1.0 + c_norm);
        let rel_gap = gap / (1.0 + pobj.abs() + dobj.abs());
        if ![pinf, dinf, rel_gap].iter().all(|v| v.is_finite()) {
            return Err(Step::Stuck("non-finite residual"));
        }
        if rel_gap < TOL.0 && dinf < TOL.1 && pinf < TOL.2 {
            return Err(Step::Converged);
        }
        self.acceptable = rel_gap < ACCEPT.0 && dinf < ACCEPT.1 && pinf < ACCEPT.2;
        Ok(Residuals { rp, rd, rdl, mu })
    }

    /// The Schur complement `M_ij = ⟨A_i, X A_j Z⁻¹⟩` (+ x/z on the linear
    /// block), from `gx = Vᵀ X V` and `gz = Vᵀ Z⁻¹ V`.
    fn schur(&self, gx: &DMatrix<f64>, gz: &DMatrix<f64>) -> DMatrix<f64> {
        let p = self.p;
        let m = p.cons.len();
        let mut schur = DMatrix::<f64>::zeros(m, m);
        for i in 0..m {
            let ci = p.cons[i];
            for j in i..m {
                let cj = p.cons[j];
                let t = gx[(ci.b, cj.a)] * gz[(cj.b, ci.a)]
                    + gx[(ci.b, cj.b)] * gz[(cj.a, ci.a)]
                    + gx[(ci.a, cj.a)] * gz[(cj.b, ci.b)]
                    + gx[(ci.a, cj.b)] * gz[(cj.a, ci.b)];
                let t = 0.25 * ci.coef * cj.coef * t;
                schur[(i, j)] = t;
                schur[(j, i)] = t;
            }
            if let Some(r) = self.lp[i] {
                schur[(i, i)] += self.xl[r] / self.zl[r];
            }
        }
        schur
    }

    /// The direction for a target `σμ` (`sigma_mu`) and a corrector
    /// `(ΔX_a ΔZ_a, Δx_a∘Δz_a)`.
    fn direction(
        &self,
        newton: &Newton,
        sigma_mu: f64,
        corr: Option<(&DMatrix<f64>, &[f64])>,
    ) -> Direction {
        let p = self.p;
        let m = p.cons.len();
        let nl = self.xl.len();
        let (zi, res) = (&newton.zi, &newton.res);
        // K = σμZ⁻¹ − X − (X R_d + corr) Z⁻¹
        let mut num = newton.xrd.clone();
        if let Some((c, _)) = corr {
            num += c;
        }
        let k = zi * sigma_mu - &self.x - &num * zi;
        let kl: Vec<f64> = (0..nl)
            .map(|r| {
                let c = corr.map_or(0.0, |(_, cl)| cl[r]);
                (sigma_mu - self.xl[r] * res.rdl[r] - c) / self.zl[r] - self.xl[r]
            })
            .collect();
        let ak = inner(p, &self.gram(&k));
        let rhs: Vec<f64> = (0..m)
            .map(|i| res.rp[i] - ak[i] + self.lp[i].map_or(0.0, |r| kl[r]))
            .collect();
        let dy = newton.chol.solve(&rhs);
        let dz = &res.rd - combine(p, &dy);
        let mut dzl = res.rdl.clone();
        for (i, r) in self.lp.iter().enumerate() {
            if let Some(r) = *r {
                dzl[r] += dy[i];
            }
        }
        let mut num = &self.x * &dz;
        if let Some((c, _)) = corr {
            num += c;
        }
        let dx = sym(&(zi * sigma_mu - &self.x - &num * zi));
        let dxl: Vec<f64> = (0..nl)
            .map(|r| {
                let c = corr.map_or(0.0, |(_, cl)| cl[r]);
                (sigma_mu - self.xl[r] * dzl[r] - c) / self.zl[r] - self.xl[r]
            })
            .collect();
        Direction {
            dx,
            dxl,
            dy,
            dz,
            dzl,
        }
    }

    /// The longest steps along `dir` to the cones' boundaries (uncapped),
    /// primal and dual.
    fn steps(&self, dir: &Direction) -> Option<(f64, f64)> {
        let ap =
            max_step(&self.x, &dir.dx, f64::INFINITY).map(|a| max_step_lp(&self.xl, &dir.dxl, a));
        let ad =
            max_step(&self.z, &dir.dz, f64::INFINITY).map(|a| max_step_lp(&self.zl, &dir.dzl, a));
        ap.zip(ad)
    }

    /// Mehrotra's centering `σ` from the predictor `pred`, its step
    /// lengths `ap`, `ad` and the current `μ`.
    fn centering(&self, mu: f64, ap: f64, ad: f64, pred: &Direction) -> f64 {
        let n = self.p.n;
        let nl = self.xl.len();
        let gap_aff = (&self.x + &pred.dx * ap).dot(&(&self.z + &pred.dz * ad))
            + (0..nl)
                .map(|r| (self.xl[r] + ap * pred.dxl[r]) * (self.zl[r] + ad * pred.dzl[r]))
                .sum::<f64>();
        let mu_aff = gap_aff / (n + nl) as f64;
        let expon = 1f64.max(3.0 * ap.min(ad).powi(2));
        if mu > 0.0 {
            (mu_aff.max(0.0) / mu).powf(expon).min(1.0)
        } else {
            0.0
        }
    }

    /// Move the iterate along `dir`, by `ap` (primal) and `ad` (dual).
    fn advance(&mut self, ap: f64, ad: f64, dir: Direction) -> Step {
        let nl = self.xl.len();
        self.x += dir.dx * ap;
        self.x = sym(&self.x);
        for r in 0..nl {
            self.xl[r] += ap * dir.dxl[r];
            self.zl[r] += ad * dir.dzl[r];
        }
        self.z += dir.dz * ad;
        self.z = sym(&self.z);
        for (y, d) in self.y.iter_mut().zip(&dir.dy) {
            *y += ad * d;
        }
        let finite = |v: &f64| v.is_finite();
        if !(self.y.iter().all(finite)
            && self.x.iter().all(finite)
            && self.z.iter().all(finite)
            && self.xl.iter().all(finite)
            && self.zl.iter().all(finite))
        {
            return Step::Stuck("non-finite iterate");
        }
        Step::Continue
    }
}

/// The residuals of an iterate.
struct Residuals {
    /// Primal: `b − ⟨A, X⟩ + x` per multiplier.
    rp: Vec<f64>,
    /// Dual: `C − Z − Σ yₖ Aₖ`.
    rd: DMatrix<f64>,
    /// Dual, linear block: `y − z` per nonnegative multiplier.
    rdl: Vec<f64>,
    /// The duality gap per coordinate.
    mu: f64,
}

/// What the predictor's and the corrector's directions share.
struct Newton {
    /// `Z⁻¹`.
    zi: DMatrix<f64>,
    /// The Schur complement's Cholesky factor.
    chol: Factor,
    /// `X R_d`.
    xrd: DMatrix<f64>,
    /// The iterate's residuals.
    res: Residuals,
}

/// A search direction.
struct Direction {
    /// The step of `X`.
    dx: DMatrix<f64>,
    /// The step of the linear block's `x`.
    dxl: Vec<f64>,
    /// The step of `y`.
    dy: Vec<f64>,
    /// The step of `Z`.
    dz: DMatrix<f64>,
    /// The step of the linear block's `z`.
    dzl: Vec<f64>,
}

/// A Cholesky factor `L` (faer's blocked factorisation, one thread).
struct Factor {
    l: faer::Mat<f64>,
}

impl Factor {
    fn solve(&self, rhs: &[f64]) -> Vec<f64> {
        let mut r = faer::Mat::<f64>::from_fn(rhs.len(), 1, |i, _| rhs[i]);
        let mut buf = MemBuffer::new(StackReq::EMPTY);
        solve_in_place(
            self.l.as_ref(),
            r.as_mut(),
            Par::Seq,
            MemStack::new(&mut buf),
        );
        (0..rhs.len()).map(|i| r[(i, 0)]).collect()
    }
}

/// Cholesky of the Schur complement, with a growing diagonal shift when it
/// is numerically singular (the direction is then inexact, which only
/// slows convergence: the iterate's residuals are recomputed exactly).
fn factor(s: &DMatrix<f64>) -> Option<Factor> {
    let m = s.nrows();
    let scale = s.diagonal().iter().fold(0.0f64, |a, v| a.max(v.abs()));
    if !scale.is_finite() || scale == 0.0 {
        return None;
    }
    let mut buf = MemBuffer::new(cholesky_in_place_scratch::<f64>(
        m,
        Par::Seq,
        Default::default(),
    ));
    let mut shift = 0.0;
    for _ in 0..6 {
        let mut l =
            faer::Mat::<f64>::from_fn(
                m,
                m,
                |i, j| {
                    if i == j {
                        s[(i, j)] + shift
                    } else {
                        s[(i, j)]
                    }
                },
            );
        let ok = cholesky_in_place(
            l.as_mut(),
            LltRegularization::default(),
            Par::Seq,
            MemStack::new(&mut buf),
            Default::default(),
        );
        if ok.is_ok() {
            return Some(Factor { l });
        }
        shift = if shift == 0.0 {
            1e-14 * scale
        } else {
            shift * 100.0
        };
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `max −d − t` s.t. `diag(c₀₀ + d, 1 + t − 2μ) ⪰ 0`, `μ ≥ 0`.
    fn small(c00: f64) -> Problem {
        let c = DMatrix::from_row_slice(2, 2, &[c00, 0.0, 0.0, 1.0]);
        Problem {
            n: 2,
            c,
            vecs: vec![vec![(0, 1.0)], vec![(1, 1.0)], vec![(0, 1.0), (1, 1.0)]],
            cons: vec![
                // A₀ = −e₀e₀ᵀ for d, A₁ = −e₁e₁ᵀ for a free t, A₂ = 2 e₁e₁ᵀ for μ ≥ 0
                Con {
                    coef: -1.0,
                    a: 0,
                    b: 0,
                    nonneg: false,
                },
                Con {
                    coef: -1.0,
                    a: 1,
                    b: 1,
                    nonneg: false,
                },
                Con {
                    coef: 2.0,
                    a: 1,
                    b: 1,
                    nonneg: true,
                },
            ],
            b: vec![-1.0, -1.0, 0.0],
        }
    }

    #[test]
    fn a_small_program_is_solved_to_its_optimum() {
        // Z = diag(−3 + d, 1 + t − 2μ): max −d − t ⇒ d = 3, t = 2μ − 1 with μ = 0 ⇒ t = −1
        match solve(&small(-3.0)) {
            Ipm::Solved { y, .. } => {
                assert!((y[0] - 3.0).abs() < 1e-6, "{y:?}");
                assert!((y[1] + 1.0).abs() < 1e-6, "{y:?}");
                assert!(y[2].abs() < 1e-6, "{y:?}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn non_finite_or_empty_data_is_not_solved() {
        assert!(matches!(solve(&small(f64::NAN)), Ipm::NotSolved(_)));
        assert!(matches!(solve(&small(f64::INFINITY)), Ipm::NotSolved(_)));
        // data near the top of f64: either no proposal or a finite one
        if let Ipm::Solved { y, .. } = solve(&small(1e308)) {
            assert!(y.iter().all(|v| v.is_finite()), "{y:?}");
        }
        let mut p = small(-3.0);
        p.cons.clear();
        p.b.clear();
        assert_eq!(solve(&p), Ipm::NotSolved("empty program"));
    }
}
