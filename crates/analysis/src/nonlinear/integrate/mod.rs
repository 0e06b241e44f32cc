//! Validated integration of a nonlinear plant over one control period.
//!
//! # The method
//!
//! The set of states is a vector of first-order Taylor models ([`Tm`]): an
//! affine function of `N` symbols `z ∈ [−1, 1]ᴺ` (the initial cell, and
//! whatever else the analysis names) plus an interval remainder. Over one
//! control period `ẋ = f(x, u, w)` is integrated in substeps ([`flow`]):
//! an a-priori enclosure by Picard iteration, then a Taylor expansion in
//! time of order `k` whose coefficients are computed by Taylor-mode
//! automatic differentiation of the plant's expression tape ([`taylor`]) in
//! Taylor-model arithmetic, and whose Lagrange remainder is evaluated in
//! interval arithmetic over the a-priori enclosure. The same tape
//! evaluation gives the discrete-time image ([`image`]). The hull of the
//! enclosures of all substeps is the intersample enclosure (`pipe`).
//!
//! # Why first-order Taylor models
//!
//! * The dependency on the initial cell is kept linearly: a cell that
//!   rotates or shears stays thin instead of becoming its bounding box
//!   (the wrapping effect of plain intervals), and only the nonlinear part
//!   goes to the remainder.
//! * They are cheap: `O(N)` per operation, where higher-order models need
//!   `O(N^order)` monomials.
//! * They compose with the controller's CROWN bounds, which are linear in
//!   the same inputs: [`combine`] turns `u ≤ A·x + b` into a model over the
//!   same symbols, and [`support`] bounds linear functions of the result.
//!
//! # Soundness
//!
//! Every enclosure contains every real solution: `+ − × ÷` round outward,
//! every rounding of a coefficient of a model goes into its remainder, the
//! step sizes are intervals, and the elementary functions rely on `libm`
//! being within four ulps (see [`elementary`]). A NaN or an infinity
//! anywhere is an error ([`FlowError::Overflow`], [`DomainError::NotFinite`]),
//! never a bound.

pub mod elementary;
pub mod flow;
pub mod interval;
pub mod simulate;
pub mod taylor;
mod taylor_func;
pub mod tm;
mod tm_func;

#[cfg(test)]
mod tests_arith;
#[cfg(test)]
mod tests_flow;

pub use elementary::{tape_gradient, tape_range, tape_range_affine};
pub use flow::{flow, image, FlowError, FlowOut, Settings};
pub use interval::{DomainError, Interval};
pub use simulate::simulate;
pub use tm::{combine, support, Tm};
