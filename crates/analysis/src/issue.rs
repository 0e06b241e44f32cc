//! Why a bound is weaker than it could be: solver statuses that forced a
//! fallback bound. Plain data shared by the LP and SDP back-ends, the
//! propagators, the executor and the reports.

use clarabel::solver::SolverStatus;

/// Which back-end met the issue.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Backend {
    /// A linear program (`crate::lp`).
    Lp,
    /// A semidefinite program (Reach-SDP).
    Sdp,
}

/// Why a solver's answer was not used; the bound then fell back to a sound
/// but looser one, and no property depending on it is reported VERIFIED.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Issue {
    /// The solver settings were refused.
    BadSettings(Backend),
    /// The solver refused the problem data.
    RejectedData(Backend),
    /// A solver status other than solved (exhaustive mapping in [`Issue::from_status`]).
    Status(Backend, Status),
    /// The SDP's primal solution held a non-finite number.
    NonFiniteSolution,
    /// The re-certification's eigenvalues were not finite.
    NonFiniteEigenvalues,
    /// Reach-SDP was asked to encode a network that is not ReLU-only.
    SdpNeedsRelu,
    /// The BLAS/LAPACK library the SDP solver calls could not be loaded.
    NoBlas,
    /// The SDP has more multipliers than the Schur-complement method takes
    /// ([`ravel_base::limits::MAX_SCHUR_MULTIPLIERS`]) on a matrix larger than
    /// Clarabel takes ([`ravel_base::limits::MAX_CLARABEL_SDP_DIM`]).
    SdpTooLarge,
}

/// An untrusted solver status.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Status {
    /// Not solved.
    Unsolved,
    /// Claimed primal infeasible.
    PrimalInfeasible,
    /// Claimed dual infeasible.
    DualInfeasible,
    /// Claimed almost primal infeasible.
    AlmostPrimalInfeasible,
    /// Claimed almost dual infeasible.
    AlmostDualInfeasible,
    /// Iteration limit reached.
    IterationLimit,
    /// Time limit reached.
    TimeLimit,
    /// Numerical error.
    NumericalError,
    /// Insufficient progress.
    InsufficientProgress,
    /// Terminated by a callback.
    Terminated,
}

impl Issue {
    /// `None` for a status whose dual is trusted, the issue otherwise.
    /// Exhaustive on purpose: a new status in a new clarabel must be classified here.
    pub fn from_status(backend: Backend, status: SolverStatus) -> Option<Issue> {
        let s = match status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => return None,
            SolverStatus::Unsolved => Status::Unsolved,
            SolverStatus::PrimalInfeasible => Status::PrimalInfeasible,
            SolverStatus::DualInfeasible => Status::DualInfeasible,
            SolverStatus::AlmostPrimalInfeasible => Status::AlmostPrimalInfeasible,
            SolverStatus::AlmostDualInfeasible => Status::AlmostDualInfeasible,
            SolverStatus::MaxIterations => Status::IterationLimit,
            SolverStatus::MaxTime => Status::TimeLimit,
            SolverStatus::NumericalError => Status::NumericalError,
            SolverStatus::InsufficientProgress => Status::InsufficientProgress,
            SolverStatus::CallbackTerminated => Status::Terminated,
        };
        Some(Issue::Status(backend, s))
    }

    /// The text used in reports (stable: the JSON report carries it).
    pub fn as_str(self) -> &'static str {
        use Backend::{Lp, Sdp};
        match self {
            Issue::BadSettings(_) => "bad solver settings",
            Issue::RejectedData(_) => "rejected problem data",
            Issue::NonFiniteSolution => "non-finite solution",
            Issue::NonFiniteEigenvalues => "eigenvalues not finite",
            Issue::SdpNeedsRelu => "SDP needs a ReLU network",
            Issue::NoBlas => "SDP solver's BLAS/LAPACK (libopenblas.so.0) not loadable",
            Issue::SdpTooLarge => "SDP too large for its solvers",
            Issue::Status(Lp, s) => s.as_str(),
            Issue::Status(Sdp, s) => match s {
                Status::Unsolved => "SDP unsolved",
                Status::PrimalInfeasible => "SDP primal infeasible",
                Status::DualInfeasible => "SDP dual infeasible",
                Status::AlmostPrimalInfeasible => "SDP almost primal infeasible",
                Status::AlmostDualInfeasible => "SDP almost dual infeasible",
                Status::IterationLimit => "SDP iteration limit",
                Status::TimeLimit => "SDP time limit",
                Status::NumericalError => "SDP numerical error",
                Status::InsufficientProgress => "SDP insufficient progress",
                Status::Terminated => "SDP terminated",
            },
        }
    }
}

impl Status {
    /// The status's name in reports.
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Unsolved => "unsolved",
            Status::PrimalInfeasible => "primal infeasible",
            Status::DualInfeasible => "dual infeasible",
            Status::AlmostPrimalInfeasible => "almost primal infeasible",
            Status::AlmostDualInfeasible => "almost dual infeasible",
            Status::IterationLimit => "iteration limit",
            Status::TimeLimit => "time limit",
            Status::NumericalError => "numerical error",
            Status::InsufficientProgress => "insufficient progress",
            Status::Terminated => "terminated",
        }
    }
}

impl std::fmt::Display for Issue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}
