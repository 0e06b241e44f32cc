//! The certificate checker: re-checks a verdict from a `ravel-certificate/1`
//! file without trusting the analysis that produced it.
//!
//! # What a VALID answer proves
//!
//! For the problem recorded in the certificate (plants, noise boxes, initial
//! set, goal and avoid sets, horizon; `ravel certify` first checks that it
//! is exactly the problem its spec lowers to, and that the spec and
//! controller files have the recorded SHA-256) and the controller as loaded
//! (saturation included):
//!
//! * every VERIFIED property holds for **every** trajectory: the cells cover
//!   the initial set; every claimed set of every cell contains the checker's
//!   own one-step bound of the previous claimed set, computed with the
//!   witness (pre-activation bounds of every hidden layer, each checked
//!   against the checker's own bound from the earlier ones); the final sets
//!   lie in the goal; and at every constrained step one inequality of each
//!   avoid-set member separates the set from it;
//! * every FALSIFIED property is violated by the recorded trajectory: its
//!   initial state and noise values lie in their sets, and the
//!   outward-rounded interval enclosure of the true trajectory from them
//!   violates the property at the recorded step as a whole (or, in
//!   continuous time, on a piece of the period ending at it: `between`;
//!   an eventually goal also on every period of its window).
//!
//! UNSURE properties claim nothing and are not checked.
//!
//! # What it trusts
//!
//! This module (its arithmetic is its own: interval images, ReLU
//! relaxations, back-substitution, box coverage), the outward-rounded sums
//! of [`ravel_base::num`], the ONNX loader and the front end that maps a spec to
//! its problem (parse, check, lower), and `serde_json`. It does not call
//! the propagators, the partitioners, the LP or SDP solvers or the Monte
//! Carlo simulation; nothing it uses was computed by them except the
//! numbers in the certificate, which it checks. With `slope_steps` in the
//! evidence it searches its own lower ReLU slopes (`bounds.rs`); any slope
//! in [0, 1] is sound, so the search is not trusted either.
//!
//! Nonlinear plants are checked by [`nonlinear`]: claimed zonotopes,
//! re-derived step by step with the checker's own validated integration.
//!
//! # What it does not check yet
//!
//! Claimed sets of linear plants are boxes. When the checker's box chain does not prove a
//! verdict that the analysis proved with tighter sets (polytope or hull
//! boundaries, unrolled CROWN), the certificate says so and the answer is
//! UNSUPPORTED (never VALID).

#![forbid(unsafe_code)]
// the checker reads untrusted certificates: no panicking shortcuts
#![deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

pub mod bounds;
mod cover;
pub mod network;
pub mod nonlinear;
pub mod splits;
pub mod tape;

/// Exact sums of `f64` values for the property tests of directed rounding
/// (the same file serves the integration tests; each crate uses part of it).
#[cfg(test)]
#[allow(dead_code, clippy::indexing_slicing)]
#[path = "../../../tests/common/exact.rs"]
mod exact;

use serde_json::Value;

use bounds::{Bx, Chain, Duals, Loop, PlantRows, Start, Trouble};
use ravel_base::nn::Network;
use ravel_base::num::{dot_box_lower, dot_box_upper, sum_lower, sum_upper};

/// The certificate format this module reads and `ravel::certificate_writer` writes.
pub const FORMAT: &str = "ravel-certificate/1";

/// The answer about one certificate.
#[derive(Clone, Debug, PartialEq)]
pub enum Answer {
    /// Every claim holds.
    Valid,
    /// A claim is false: the first failing item, for people.
    Invalid(String),
    /// Some claim cannot be checked (and none was found false): why.
    Unsupported(String),
    /// The certificate is not a readable `ravel-certificate/1`: why.
    Unreadable(String),
}

/// The checker's report: the answer and one line per property.
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    /// The answer.
    pub answer: Answer,
    /// `name: STATUS (checked | not checked: why | no claim)` per property.
    pub properties: Vec<String>,
    /// Cells and steps of the VERIFIED evidence that were checked.
    pub cells: usize,
    /// Steps per cell.
    pub steps: usize,
    /// Nodes of an activation-split tree that were checked (network
    /// certificates whose evidence is a split tree; `cells` is then 0).
    pub subproblems: usize,
    /// The first false claim of the VERIFIED evidence, if one was found
    /// (the certificate writer uses it to tell a checkable certificate from
    /// one the checker's bounds cannot establish).
    pub evidence_failure: Option<String>,
    /// Network certificates with a polytope input set: per cell, the dual
    /// vectors its supports used, in the order they were asked for (what
    /// the writer records; see [`network::check_solving`]).
    pub duals: Vec<Vec<Vec<f64>>>,
}

/// Why the checker does not accept a certificate, or one cell of it (what
/// [`CellCheck`] answers; its text is the message users see).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Error {
    /// The certificate (or the cell) is not a readable
    /// `ravel-certificate/1`: a field missing or malformed, a limit
    /// exceeded, or a coverage the work limit could not decide.
    Unreadable(String),
    /// A claim is false, or the evidence cannot serve the VERIFIED
    /// properties: the first failing item.
    Invalid(String),
}

impl std::fmt::Display for Error {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Error::Unreadable(m) | Error::Invalid(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for Error {}

/// A reading failure: why the certificate is not readable.
type R<T> = Result<T, String>;

impl Report {
    /// A report with nothing checked yet.
    fn empty() -> Report {
        Report {
            answer: Answer::Valid,
            properties: Vec::new(),
            cells: 0,
            steps: 0,
            subproblems: 0,
            evidence_failure: None,
            duals: Vec::new(),
        }
    }
}

/// The answer from the first false claim and the first claim that could
/// not be checked.
fn decide(invalid: Option<String>, unsupported: Option<String>) -> Answer {
    match (invalid, unsupported) {
        (Some(m), _) => Answer::Invalid(m),
        (None, Some(m)) => Answer::Unsupported(m),
        (None, None) => Answer::Valid,
    }
}

fn get<'a>(v: &'a Value, key: &str) -> R<&'a Value> {
    v.get(key).ok_or_else(|| format!("missing field `{key}`"))
}

fn num(v: &Value) -> R<f64> {
    v.as_f64()
        .filter(|x| x.is_finite())
        .ok_or_else(|| "expected a finite number".to_string())
}

fn uint(v: &Value, what: &str) -> R<usize> {
    v.as_u64()
        .and_then(|x| usize::try_from(x).ok())
        .ok_or_else(|| format!("`{what}` must be a non-negative integer"))
}

fn vector(v: &Value, len: usize, what: &str) -> R<Vec<f64>> {
    let a = v
        .as_array()
        .ok_or_else(|| format!("`{what}` must be an array"))?;
    if a.len() != len {
        return Err(format!("`{what}` has {} entries, expected {len}", a.len()));
    }
    a.iter()
        .map(|x| num(x).map_err(|e| format!("`{what}`: {e}")))
        .collect()
}

fn matrix(v: &Value, rows: usize, cols: usize, what: &str) -> R<nalgebra::DMatrix<f64>> {
    let a = v
        .as_array()
        .ok_or_else(|| format!("`{what}` must be an array of rows"))?;
    if a.len() != rows {
        return Err(format!("`{what}` has {} rows, expected {rows}", a.len()));
    }
    let mut entries = Vec::new();
    for r in a {
        entries.extend(vector(r, cols, what)?);
    }
    Ok(nalgebra::DMatrix::from_row_slice(rows, cols, &entries))
}

fn boxed(v: &Value, n: usize, what: &str) -> R<Bx> {
    let b = Bx {
        lo: vector(get(v, "lo")?, n, what)?,
        hi: vector(get(v, "hi")?, n, what)?,
    };
    if !b.is_proper() {
        return Err(format!("`{what}` is not a box (lo > hi somewhere)"));
    }
    Ok(b)
}

/// A claimed box: finite numbers of the right count; `lo > hi` is allowed
/// (an empty claim is a false claim, caught by the checks that use it).
fn claimed_box(v: &Value, n: usize, what: &str) -> R<Bx> {
    Ok(Bx {
        lo: vector(get(v, "lo")?, n, what)?,
        hi: vector(get(v, "hi")?, n, what)?,
    })
}

/// Rows `(a, b)` of `a·x ≤ b`.
fn rows(v: &Value, n: usize, what: &str) -> R<Vec<(Vec<f64>, f64)>> {
    v.as_array()
        .ok_or_else(|| format!("`{what}` must be an array"))?
        .iter()
        .map(|r| Ok((vector(get(r, "a")?, n, what)?, num(get(r, "b")?)?)))
        .collect()
}

/// A property as the checker reads it.
enum Prop {
    /// The claimed sets lie in the goal at every step of `steps` (a plain
    /// goal: the horizon alone), or at some step (`eventually`).
    Goal {
        set: CSet,
        steps: (usize, usize),
        eventually: bool,
        /// The control periods (the period `p` ends at step `p`) a plant in
        /// continuous time must spend in the goal too (an always goal).
        periods: (usize, usize),
    },
    Avoid {
        members: Vec<CSet>,
        steps: (usize, usize),
        /// The control periods that must miss the set too (continuous time).
        periods: (usize, usize),
    },
}

/// A goal's or avoid member's set: rows `a·x ≤ b` and constraints
/// `g(x) ≤ 0` (evaluated by [`tape::range`]).
struct CSet {
    rows: Rows,
    nonlinear: Vec<ravel_base::expr::Tape>,
}

impl CSet {
    /// Read `{ "rows": …, "nonlinear": [tape, …] }` or a bare array of rows.
    fn read(v: &Value, n: usize, what: &str) -> R<CSet> {
        if v.is_array() {
            return Ok(CSet {
                rows: rows(v, n, what)?,
                nonlinear: Vec::new(),
            });
        }
        CSet::read_fields(v, n, what)
    }

    /// Read the fields `rows` and (optional) `nonlinear` of an object.
    fn read_fields(v: &Value, n: usize, what: &str) -> R<CSet> {
        let nonlinear = match v.get("nonlinear") {
            None => Vec::new(),
            Some(t) => t
                .as_array()
                .ok_or("`nonlinear` must be an array of tapes")?
                .iter()
                .map(|t| tape::read(t, n))
                .collect::<R<Vec<_>>>()?,
        };
        Ok(CSet {
            rows: rows(get(v, "rows")?, n, what)?,
            nonlinear,
        })
    }

    /// Whether the box certainly lies in the set (every row's and every
    /// constraint's upper bound at most 0; a constraint without an
    /// enclosure proves nothing).
    fn holds_on(&self, b: &Bx) -> bool {
        self.rows
            .iter()
            .all(|(a, c)| sum_upper([dot_box_upper(a, &b.lo, &b.hi), -c]) <= 0.0)
            && self.constraints_hold_on(b)
    }

    /// Whether every constraint's upper bound over the box is at most 0.
    fn constraints_hold_on(&self, b: &Bx) -> bool {
        self.constraints_hold_on_form(b, None)
    }

    /// An enclosure of `g` over the box, tightened by the mean value form
    /// over `form` (an affine set of the same states inside the box) when
    /// given.
    fn constraint_range(
        g: &ravel_base::expr::Tape,
        b: &Bx,
        form: Option<&Form>,
    ) -> Option<tape::Iv> {
        let plain = tape::range(g, &b.lo, &b.hi);
        let mean =
            form.and_then(|f| tape::range_affine(g, f.c, f.g, &f.e_lo, &f.e_hi, &b.lo, &b.hi));
        match (plain, mean) {
            (Some(p), Some(m)) => Some(tape::Iv {
                lo: p.lo.max(m.lo),
                hi: p.hi.min(m.hi),
            }),
            (p, m) => p.or(m),
        }
    }

    /// [`CSet::constraints_hold_on`] with the states' affine form.
    fn constraints_hold_on_form(&self, b: &Bx, form: Option<&Form>) -> bool {
        self.nonlinear
            .iter()
            .all(|g| Self::constraint_range(g, b, form).is_some_and(|r| r.hi <= 0.0))
    }

    /// Whether one constraint has a positive lower bound over the box
    /// (with the states' affine form when given).
    fn constraint_missed_by(&self, b: &Bx, form: Option<&Form>) -> bool {
        self.nonlinear
            .iter()
            .any(|g| Self::constraint_range(g, b, form).is_some_and(|r| r.lo > 0.0))
    }

    /// Whether the box certainly misses the set (one row or one
    /// constraint has a positive lower bound over it).
    fn missed_by(&self, b: &Bx) -> bool {
        self.missed_by_form(b, None)
    }

    /// [`CSet::missed_by`] with the states' affine form.
    fn missed_by_form(&self, b: &Bx, form: Option<&Form>) -> bool {
        self.rows
            .iter()
            .any(|(a, c)| sum_lower([dot_box_lower(a, &b.lo, &b.hi), -c]) > 0.0)
            || self.constraint_missed_by(b, form)
    }

    /// [`CSet::holds_on`] with the states' affine form.
    fn holds_on_form(&self, b: &Bx, form: Option<&Form>) -> bool {
        self.rows
            .iter()
            .all(|(a, c)| sum_upper([dot_box_upper(a, &b.lo, &b.hi), -c]) <= 0.0)
            && self.constraints_hold_on_form(b, form)
    }
}

/// An affine set `{c + G s + e : s ∈ [−1, 1]ᵏ, e ∈ [e_lo, e_hi]}` of
/// states, for the mean value bound of a set's constraints
/// ([`tape::range_affine`]).
struct Form<'a> {
    c: &'a [f64],
    g: &'a [Vec<f64>],
    e_lo: Vec<f64>,
    e_hi: Vec<f64>,
}

/// Inequalities `a·x ≤ b`.
type Rows = Vec<(Vec<f64>, f64)>;

/// The initial set as the checker reads it.
enum Initial {
    Box(Bx),
    Polytope {
        bbox: Bx,
        rows: Vec<(Vec<f64>, f64)>,
    },
    /// `{c + diag(r) δ | ‖δ‖ₚ ≤ 1}`; the norm is `1`, `2` or `inf`.
    Ball {
        center: Vec<f64>,
        radius: Vec<f64>,
        norm: String,
    },
}

impl Initial {
    /// A box containing the set (part of a polytope's definition; the
    /// ball's, rounded outward).
    fn bbox(&self) -> Bx {
        match self {
            Initial::Box(b) | Initial::Polytope { bbox: b, .. } => b.clone(),
            Initial::Ball { center, radius, .. } => Bx::around(center, radius),
        }
    }

    /// What step 0 knows beyond a cell's box.
    fn start(&self) -> Start<'_> {
        match self {
            Initial::Ball {
                center,
                radius,
                norm,
            } => Start::Ball {
                center,
                radius,
                norm,
            },
            Initial::Box(_) | Initial::Polytope { .. } => Start::Box,
        }
    }

    /// Whether the box `b` certainly misses the set: one inequality of a
    /// polytope separates it, or its point nearest a ball's centre is
    /// farther than the radius (rounded toward the centre).
    fn misses(&self, b: &Bx) -> bool {
        match self {
            Initial::Box(_) => false,
            Initial::Polytope { rows, .. } => rows
                .iter()
                .any(|(a, h)| sum_lower([dot_box_lower(a, &b.lo, &b.hi), -h]) > 0.0),
            Initial::Ball {
                center,
                radius,
                norm,
            } => {
                let mut scaled = Vec::with_capacity(center.len());
                let ends = b.lo.iter().zip(&b.hi);
                for ((&c, &r), (&lo, &hi)) in center.iter().zip(radius).zip(ends) {
                    let gap = sum_lower([lo, -c]).max(sum_lower([c, -hi]));
                    if gap <= 0.0 {
                        scaled.push(0.0);
                    } else if r > 0.0 {
                        scaled.push((gap / r).next_down());
                    } else {
                        return true;
                    }
                }
                let len = match norm.as_str() {
                    "inf" => scaled.iter().fold(0.0f64, |m, v| m.max(*v)),
                    "1" => sum_lower(scaled.iter().copied()),
                    _ => sum_lower(scaled.iter().map(|v| (v * v).next_down())),
                };
                len > 1.0
            }
        }
    }

    /// Whether `x` certainly lies in the set (outward-rounded tests).
    fn contains(&self, x: &[f64]) -> bool {
        match self {
            Initial::Box(b) => b.contains(x),
            Initial::Polytope { bbox, rows } => {
                bbox.contains(x)
                    && rows.iter().all(|(a, b)| {
                        sum_upper(a.iter().zip(x).map(|(a, x)| a * x).chain([-b])) <= 0.0
                    })
            }
            Initial::Ball {
                center,
                radius,
                norm,
            } => {
                if x.len() != center.len() {
                    return false;
                }
                // |xᵢ − cᵢ| / rᵢ, rounded up (0 where rᵢ = 0 and xᵢ = cᵢ)
                let mut scaled = Vec::with_capacity(x.len());
                for ((x, c), r) in x.iter().zip(center).zip(radius) {
                    let d = sum_upper([*x, -c]).abs().max(sum_lower([*x, -c]).abs());
                    if d == 0.0 {
                        scaled.push(0.0);
                    } else if *r > 0.0 {
                        scaled.push((d / r).next_up());
                    } else {
                        return false;
                    }
                }
                let total = match norm.as_str() {
                    "inf" => scaled.iter().fold(0.0f64, |m, v| m.max(*v)),
                    "1" => sum_upper(scaled.iter().copied()),
                    "2" => sum_upper(scaled.iter().map(|v| (v * v).next_up())),
                    _ => return false,
                };
                total <= 1.0
            }
        }
    }
}

/// The problem as the checker reads it.
struct Problem {
    n: usize,
    horizon: usize,
    plants: Vec<PlantRows>,
    obs: nalgebra::DMatrix<f64>,
    w: Bx,
    v: Bx,
    initial: Initial,
    props: Vec<(String, Prop)>,
    /// A linear plant in continuous time: its flow per step, for the
    /// states between the sampling instants.
    intersample: Option<Vec<nonlinear::flow::Field>>,
}

impl Problem {
    fn read(p: &Value, net: &Network) -> R<Problem> {
        let n = uint(get(p, "states")?, "states")?;
        let m = uint(get(p, "controls")?, "controls")?;
        let q = uint(get(p, "observations")?, "observations")?;
        let horizon = uint(get(p, "horizon")?, "horizon")?;
        let max = ravel_base::limits::MAX_DIM as usize;
        if n == 0 || n > max || m > max || q > max {
            return Err("dimensions out of range".into());
        }
        if horizon > ravel_base::limits::MAX_HORIZON as usize {
            return Err("horizon out of range".into());
        }
        if net.inputs != q || net.outputs() != m {
            return Err(format!(
                "the controller maps {} inputs to {} outputs; the problem needs {q} → {m}",
                net.inputs,
                net.outputs()
            ));
        }
        let plants = get(p, "plants")?
            .as_array()
            .filter(|a| !a.is_empty())
            .ok_or("`plants` must be a non-empty array")?
            .iter()
            .map(|pl| {
                let err = match get(pl, "error")? {
                    Value::Null => None,
                    e => Some((
                        matrix(get(e, "A")?, n, n, "error.A")?,
                        matrix(get(e, "B")?, n, m, "error.B")?,
                        vector(get(e, "c")?, n, "error.c")?,
                    )),
                };
                Ok(PlantRows {
                    a: matrix(get(pl, "A")?, n, n, "A")?,
                    b: matrix(get(pl, "B")?, n, m, "B")?,
                    c: vector(get(pl, "c")?, n, "c")?,
                    err,
                })
            })
            .collect::<R<Vec<_>>>()?;
        let initial = read_initial(p, n)?;
        let props = read_properties(p, n, horizon)?;
        let intersample = match p.get("intersample") {
            None | Some(Value::Null) => None,
            Some(v) => {
                let period = num(get(v, "period")?)?;
                if period <= 0.0 {
                    return Err("`intersample.period` must be positive".into());
                }
                let fields = get(v, "plants")?
                    .as_array()
                    .filter(|a| !a.is_empty())
                    .ok_or("`intersample.plants` must be a non-empty array")?
                    .iter()
                    .map(|pl| {
                        Ok(nonlinear::flow::Field::linear(
                            &matrix(get(pl, "A")?, n, n, "intersample A")?,
                            &matrix(get(pl, "B")?, n, m, "intersample B")?,
                            &vector(get(pl, "c")?, n, "intersample c")?,
                            period,
                        ))
                    })
                    .collect::<R<Vec<_>>>()?;
                Some(fields)
            }
        };
        Ok(Problem {
            n,
            horizon,
            plants,
            obs: matrix(get(p, "observation")?, n, q, "observation")?,
            w: boxed(get(p, "process_noise")?, n, "process_noise")?,
            v: boxed(get(p, "sensor_noise")?, q, "sensor_noise")?,
            initial,
            props,
            intersample,
        })
    }

    /// The loop at step `t` (its plant, or the last one past the list).
    fn at<'a>(&'a self, t: usize, net: &'a Network, slopes: usize) -> Loop<'a> {
        #[allow(clippy::indexing_slicing)] // `Problem::read` refuses an empty list of plants
        let plant = &self.plants[t.min(self.plants.len() - 1)];
        Loop {
            plant,
            obs: &self.obs,
            w: &self.w,
            v: &self.v,
            net,
            slopes,
        }
    }

    /// The last step a property constrains.
    fn last_step(&self, p: &Prop) -> usize {
        match p {
            Prop::Goal { steps, .. } | Prop::Avoid { steps, .. } => steps.1.min(self.horizon),
        }
    }
}

/// The last step the evidence must reach for a property: its last
/// instant, or the end of its last control period when that is later (a
/// window in seconds may end inside a period).
fn needed_step(p: &Prop, horizon: usize) -> usize {
    match p {
        // proven at an instant of its window
        Prop::Goal {
            steps,
            eventually: true,
            ..
        } => steps.1.min(horizon),
        Prop::Goal { steps, periods, .. } | Prop::Avoid { steps, periods, .. } => {
            let last = if periods.0 <= periods.1 {
                steps.1.max(periods.1)
            } else {
                steps.1
            };
            last.min(horizon)
        }
    }
}

/// The initial set of a problem over `n` states.
fn read_initial(p: &Value, n: usize) -> R<Initial> {
    let init = get(p, "initial")?;
    let initial = if let Some(b) = init.get("box") {
        Initial::Box(boxed(b, n, "initial")?)
    } else if let Some(p) = init.get("polytope") {
        Initial::Polytope {
            bbox: boxed(get(p, "bbox")?, n, "initial bbox")?,
            rows: rows(get(p, "rows")?, n, "initial rows")?,
        }
    } else if let Some(b) = init.get("ball") {
        let norm = get(b, "norm")?.as_str().unwrap_or("").to_string();
        if !matches!(norm.as_str(), "1" | "2" | "inf") {
            return Err("the ball's norm must be \"1\", \"2\" or \"inf\"".into());
        }
        let radius = vector(get(b, "radius")?, n, "initial radius")?;
        if radius.iter().any(|r| *r < 0.0) {
            return Err("a ball radius is negative".into());
        }
        Initial::Ball {
            center: vector(get(b, "center")?, n, "initial center")?,
            radius,
            norm,
        }
    } else {
        return Err("`initial` must be a box, a polytope or a ball".into());
    };
    Ok(initial)
}

/// The properties of a problem over `n` states and `horizon` steps.
fn read_properties(p: &Value, n: usize, horizon: usize) -> R<Vec<(String, Prop)>> {
    get(p, "properties")?
        .as_array()
        .ok_or("`properties` must be an array")?
        .iter()
        .map(|pr| {
            let name = get(pr, "name")?
                .as_str()
                .ok_or("`name` must be a string")?
                .to_string();
            let steps_of = |s: &Value| -> R<(usize, usize)> {
                let steps = (
                    uint(get(s, "first")?, "steps.first")?,
                    uint(get(s, "last")?, "steps.last")?,
                );
                if steps.0 > steps.1 {
                    return Err("`steps.first` is after `steps.last`".into());
                }
                Ok(steps)
            };
            // the periods: recorded when not those between the first and
            // the last step
            let periods = |steps: (usize, usize)| -> R<(usize, usize)> {
                match pr.get("periods") {
                    None => Ok((steps.0 + 1, steps.1)),
                    Some(s) => Ok((
                        uint(get(s, "first")?, "periods.first")?,
                        uint(get(s, "last")?, "periods.last")?,
                    )),
                }
            };
            let kind = match get(pr, "kind")?.as_str() {
                Some("goal") => Prop::Goal {
                    set: CSet::read_fields(pr, n, "goal rows")?,
                    steps: match pr.get("steps") {
                        None => (horizon, horizon),
                        Some(s) => {
                            let steps = steps_of(s)?;
                            if steps.1 > horizon {
                                return Err("a goal's steps go beyond the horizon".into());
                            }
                            steps
                        }
                    },
                    eventually: match pr.get("mode").map(Value::as_str) {
                        None | Some(Some("always")) => false,
                        Some(Some("eventually")) => true,
                        _ => return Err("`mode` must be \"always\" or \"eventually\"".into()),
                    },
                    periods: (0, 0),
                },
                Some("avoid") => {
                    let steps = steps_of(get(pr, "steps")?)?;
                    let members = get(pr, "members")?
                        .as_array()
                        .ok_or("`members` must be an array")?
                        .iter()
                        .map(|mb| CSet::read(mb, n, "avoid rows"))
                        .collect::<R<Vec<_>>>()?;
                    Prop::Avoid {
                        members,
                        steps,
                        periods: periods(steps)?,
                    }
                }
                _ => return Err("`kind` must be \"goal\" or \"avoid\"".to_string()),
            };
            // a goal's periods follow its steps
            let kind = match kind {
                Prop::Goal {
                    set,
                    steps,
                    eventually,
                    ..
                } => Prop::Goal {
                    set,
                    steps,
                    eventually,
                    // an eventually goal's periods matter only to a
                    // counterexample (every period that meets the window
                    // must miss the goal); a proof is at the instants
                    periods: if pr.get("steps").is_none() {
                        (1, 0)
                    } else {
                        periods(steps)?
                    },
                },
                avoid => avoid,
            };
            Ok((name, kind))
        })
        .collect::<R<Vec<_>>>()
}

/// The name of coordinate `i`'s upper or lower facet, for messages.
fn facet(i: usize, upper: bool) -> String {
    format!(
        "x[{i}] {}",
        if upper { "upper bound" } else { "lower bound" }
    )
}

/// Check one certificate against the controller `net` (saturation
/// included), or, for a network spec's certificate, against its model.
pub fn check(cert: &Value, net: &Network) -> Report {
    if cert
        .get("problem")
        .and_then(|p| p.get("kind"))
        .and_then(Value::as_str)
        == Some("network")
        && cert.get("format").and_then(Value::as_str) == Some(FORMAT)
    {
        return network::check(cert, net);
    }
    if cert
        .get("problem")
        .and_then(|p| p.get("kind"))
        .and_then(Value::as_str)
        == Some("nonlinear")
    {
        return nonlinear::check(cert, net);
    }
    let mut report = Report::empty();
    match check_inner(cert, net, &mut report) {
        Ok(answer) => report.answer = answer,
        Err(e) => report.answer = Answer::Unreadable(e),
    }
    report
}

fn check_inner(cert: &Value, net: &Network, report: &mut Report) -> R<Answer> {
    match get(cert, "format")?.as_str() {
        Some(FORMAT) => {}
        Some(other) => {
            return Err(format!(
                "format `{}` is not {FORMAT}",
                ravel_base::text::sanitize(other)
            ))
        }
        None => return Err("`format` must be a string".into()),
    }
    let problem = Problem::read(get(cert, "problem")?, net).map_err(|e| format!("problem: {e}"))?;
    let verdicts = get(cert, "verdicts")?
        .as_array()
        .ok_or("`verdicts` must be an array")?;
    if verdicts.len() != problem.props.len() {
        return Err(format!(
            "{} verdicts for {} properties",
            verdicts.len(),
            problem.props.len()
        ));
    }
    let mut invalid: Option<String> = None;
    let mut unsupported: Option<String> = None;
    let mut verified = Vec::new();
    for (i, (v, named)) in verdicts.iter().zip(&problem.props).enumerate() {
        let (name, prop) = named;
        if get(v, "property")?.as_str() != Some(name.as_str()) {
            return Err(format!(
                "verdict {i} is not about property `{}`",
                ravel_base::text::sanitize(name)
            ));
        }
        let shown = ravel_base::text::sanitize(name);
        match get(v, "status")?.as_str() {
            Some("VERIFIED") => verified.push(named),
            Some("UNSURE") => report
                .properties
                .push(format!("{shown}: UNSURE (no claim)")),
            Some("FALSIFIED") => {
                let (step, between) = falsified_claim(v, i)?;
                let replayed = if between {
                    replay_between(&problem, net, prop, step, get(v, "trajectory")?)?
                } else {
                    replay(&problem, net, prop, step, get(v, "trajectory")?)?
                };
                record_replay(report, &mut invalid, &shown, step, between, replayed);
            }
            _ => {
                return Err(format!(
                    "verdict {i}: `status` must be VERIFIED, FALSIFIED or UNSURE"
                ))
            }
        }
    }
    if !verified.is_empty() {
        let ev = get(cert, "evidence")?;
        match get(ev, "status")?.as_str() {
            Some("checkable") => {
                let needed = verified
                    .iter()
                    .map(|(_, p)| needed_step(p, problem.horizon))
                    .max()
                    .unwrap_or(0);
                match evidence(&problem, net, ev, needed, &verified, report) {
                    Ok(()) => {
                        for (name, _) in &verified {
                            let shown = ravel_base::text::sanitize(name);
                            report
                                .properties
                                .push(format!("{shown}: VERIFIED (checked)"));
                        }
                    }
                    Err(Error::Invalid(msg)) => {
                        for (name, _) in &verified {
                            let shown = ravel_base::text::sanitize(name);
                            report
                                .properties
                                .push(format!("{shown}: VERIFIED — not established"));
                        }
                        report.evidence_failure = Some(msg.clone());
                        invalid.get_or_insert(msg);
                    }
                    Err(Error::Unreadable(e)) => return Err(e),
                }
            }
            Some("unsupported") => {
                let why = get(ev, "reason")?.as_str().unwrap_or("no reason given");
                let why = ravel_base::text::sanitize_to(why, 600);
                for (name, _) in &verified {
                    let shown = ravel_base::text::sanitize(name);
                    report
                        .properties
                        .push(format!("{shown}: VERIFIED — not checkable: {why}"));
                }
                unsupported.get_or_insert(why);
            }
            _ => return Err("`evidence.status` must be \"checkable\" or \"unsupported\"".into()),
        }
    }
    Ok(decide(invalid, unsupported))
}

/// The analysis's `optimise_slopes` from the evidence (the checker then
/// searches its own slopes; absent in certificates written before the
/// setting existed: 0), within the analysis's own limit.
fn slope_steps(ev: &Value) -> R<usize> {
    let slopes = match ev.get("slope_steps") {
        None => 0,
        Some(v) => uint(v, "evidence.slope_steps")?,
    };
    if slopes as u64 > ravel_base::limits::MAX_SLOPE_STEPS {
        return Err(format!(
            "{slopes} slope-optimisation steps: more than the {} any analysis makes",
            ravel_base::limits::MAX_SLOPE_STEPS
        ));
    }
    Ok(slopes)
}

/// One cell's checked chain: its box, the claimed sets from step 0 (the
/// box) to the last step, the last set's inequalities and the goal rows'
/// duals over them.
struct CellChain {
    start: Bx,
    sets: Vec<Bx>,
    last_rows: Rows,
    goal_duals: Vec<Vec<f64>>,
}

/// The evidence's settings every cell is checked with.
#[derive(Clone, Copy)]
struct Mode {
    steps: usize,
    unrolled: bool,
    slopes: usize,
}

/// Read the evidence's settings; [`Error::Invalid`] when they cannot serve
/// the verified properties (steps up to `needed`).
fn mode(problem: &Problem, ev: &Value, needed: usize) -> Result<Mode, Error> {
    let steps = get(ev, "steps")
        .and_then(|s| uint(s, "evidence.steps"))
        .map_err(Error::Unreadable)?;
    if steps < needed || steps > problem.horizon {
        return Err(Error::Invalid(format!(
            "the evidence covers steps 0..={steps}, the verified properties need 0..={needed}"
        )));
    }
    let unrolled = match ev.get("mode").and_then(Value::as_str) {
        Some("unrolled") => true,
        Some("one_step") => false,
        _ => {
            return Err(Error::Unreadable(
                "`evidence.mode` must be \"one_step\" or \"unrolled\"".into(),
            ))
        }
    };
    Ok(Mode {
        steps,
        unrolled,
        slopes: slope_steps(ev).map_err(Error::Unreadable)?,
    })
}

/// Check the VERIFIED evidence for the `verified` properties: every cell's
/// chain, the cells' coverage of the initial set, and every cell's proof of
/// every property. [`Error::Invalid`] is the first false claim.
fn evidence(
    problem: &Problem,
    net: &Network,
    ev: &Value,
    needed: usize,
    verified: &[&(String, Prop)],
    report: &mut Report,
) -> Result<(), Error> {
    let mode = mode(problem, ev, needed)?;
    let cells_json = evidence_cells(ev).map_err(Error::Unreadable)?;
    let mut chains = Vec::with_capacity(cells_json.len());
    for (c, cell) in cells_json.iter().enumerate() {
        chains.push(cell_chain(problem, net, cell, mode, c)?);
    }
    let cells: Vec<Bx> = chains.iter().map(|ch| ch.start.clone()).collect();
    let x0 = &problem.initial;
    match cover::covers(&cells, &x0.bbox(), &|b| x0.misses(b)) {
        Ok(()) => {}
        Err(Some(p)) => {
            return Err(Error::Invalid(format!(
                "the cells do not cover the initial set: {p:?} is in no cell"
            )))
        }
        // undecided is not false: the certificate is not checkable
        Err(None) => {
            return Err(Error::Unreadable(
                "the cells' coverage of the initial set could not be decided within the work limit"
                    .into(),
            ))
        }
    }
    for property in verified {
        for (c, chain) in chains.iter().enumerate() {
            cell_proves(problem, net, property, chain, c)?;
        }
    }
    report.cells = cells.len();
    report.steps = mode.steps;
    Ok(())
}

/// The evidence's cells, at most as many as any analysis makes (the
/// checker's work grows with cells × steps).
fn evidence_cells(ev: &Value) -> R<&Vec<Value>> {
    let cells = get(ev, "cells")?
        .as_array()
        .ok_or("`evidence.cells` must be an array")?;
    if cells.len() as u64 > ravel_base::limits::MAX_CELLS {
        return Err(format!(
            "{} cells: more than the {} any analysis makes",
            cells.len(),
            ravel_base::limits::MAX_CELLS
        ));
    }
    Ok(cells)
}

/// Check one cell's chain of claimed sets (`c` names it in messages):
/// [`Error::Unreadable`] for a malformed cell, [`Error::Invalid`] for the
/// first false claim.
fn cell_chain(
    problem: &Problem,
    net: &Network,
    cell: &Value,
    mode: Mode,
    c: usize,
) -> Result<CellChain, Error> {
    let n = problem.n;
    let start = get(cell, "box")
        .and_then(|b| claimed_box(b, n, "cell box"))
        .map_err(Error::Unreadable)?;
    if !start.is_proper() {
        return Err(Error::Invalid(format!("cell {c}'s box is empty")));
    }
    let claims = claimed_steps(cell, mode.steps, c).map_err(Error::Unreadable)?;
    let mut walk = Walk {
        problem,
        net,
        slopes: mode.slopes,
        c,
        links: Chain::new(problem.initial.start(), mode.unrolled),
        sets: Vec::with_capacity(claims.len() + 1),
        last: start.clone(),
        last_rows: match &problem.initial {
            Initial::Polytope { rows, .. } => rows.clone(),
            Initial::Box(_) | Initial::Ball { .. } => Vec::new(),
        },
    };
    for (k, claim) in claims.iter().enumerate() {
        let claim = Claim::read(claim, n).map_err(Error::Unreadable)?;
        walk.step(k, claim)?;
    }
    let goal_duals = vectors(cell.get("goal_duals"), "goal_duals").map_err(Error::Unreadable)?;
    let Walk {
        mut sets,
        last,
        last_rows,
        ..
    } = walk;
    sets.push(last);
    Ok(CellChain {
        start,
        sets,
        last_rows,
        goal_duals,
    })
}

/// Cell `c`'s claimed steps, exactly `steps` of them.
fn claimed_steps(cell: &Value, steps: usize, c: usize) -> R<&Vec<Value>> {
    let claims = get(cell, "steps")?
        .as_array()
        .ok_or("`steps` must be an array")?;
    if claims.len() != steps {
        return Err(format!(
            "cell {c} has {} steps, expected {steps}",
            claims.len()
        ));
    }
    Ok(claims)
}

/// One claimed step of a cell as read: the claimed set, its inequalities
/// (none: the set is its box), their dual witnesses and the claimed
/// pre-activation bounds of every hidden layer.
struct Claim {
    set: Bx,
    rows: Rows,
    duals: Vec<Vec<f64>>,
    witness: Vec<Bx>,
}

impl Claim {
    /// Read one entry of a cell's `steps` over `n` states.
    fn read(claim: &Value, n: usize) -> R<Claim> {
        let set = claimed_box(get(claim, "set")?, n, "claimed set")?;
        let claimed_rows = match claim.get("rows") {
            None => Vec::new(),
            Some(r) => rows(r, n, "claimed rows")?,
        };
        let duals = vectors(claim.get("duals"), "duals")?;
        let witness = get(claim, "preactivations")?
            .as_array()
            .ok_or("`preactivations` must be an array")?
            .iter()
            .map(|b| {
                let len = b.get("lo").and_then(Value::as_array).map_or(0, Vec::len);
                claimed_box(b, len, "pre-activation bounds")
            })
            .collect::<R<Vec<_>>>()?;
        Ok(Claim {
            set,
            rows: claimed_rows,
            duals,
            witness,
        })
    }
}

/// A cell's chain being checked one claimed step at a time.
struct Walk<'a> {
    problem: &'a Problem,
    net: &'a Network,
    /// The evidence's slope-search steps.
    slopes: usize,
    /// The cell's index, for messages.
    c: usize,
    /// The checker's own steps so far (for unrolled bounds).
    links: Chain<'a>,
    /// The claimed sets before the last one, from the cell's box.
    sets: Vec<Bx>,
    /// The last claimed set (at first the cell's box).
    last: Bx,
    /// The last claimed set's inequalities (step 0: a polytope X0's).
    last_rows: Rows,
}

impl Walk<'_> {
    /// Check claimed step `k + 1` against the checker's own one-step bound
    /// of the last claimed set, along its inequalities and its box facets;
    /// it becomes the last claimed set.
    fn step(&mut self, k: usize, claim: Claim) -> Result<(), Error> {
        let (problem, c, t) = (self.problem, self.c, k + 1);
        let duals = Duals::given(&claim.duals);
        let start = if !self.last_rows.is_empty() {
            Start::Polytope {
                rows: &self.last_rows,
                duals: &duals,
            }
        } else if k == 0 {
            problem.initial.start()
        } else {
            Start::Box
        };
        // every row has `n` entries (read by `rows`)
        let directions = (!claim.rows.is_empty()).then(|| {
            nalgebra::DMatrix::from_row_iterator(
                claim.rows.len(),
                problem.n,
                claim.rows.iter().flat_map(|(a, _)| a.iter().copied()),
            )
        });
        let stepped = self.links.step(
            problem.at(k, self.net, self.slopes),
            &self.last,
            start,
            directions.as_ref(),
            Some(&claim.witness),
        );
        let proven = match stepped {
            Ok(st) => {
                offsets_hold(&claim.rows, &st.offsets, c, t)?;
                st.next
            }
            Err(trouble) => return Err(step_trouble(trouble, c, t)),
        };
        facets_hold(&claim.set, &proven, c, t)?;
        self.sets.push(std::mem::replace(&mut self.last, claim.set));
        self.last_rows = claim.rows;
        Ok(())
    }
}

/// Whether every claimed inequality of cell `c`'s step `t` has an offset
/// at least the checker's `proven` one.
fn offsets_hold(claimed: &Rows, proven: &[f64], c: usize, t: usize) -> Result<(), Error> {
    for (r, ((_, b), o)) in claimed.iter().zip(proven).enumerate() {
        // a claim holds only against a number (NaN proves nothing)
        if b.is_nan() || o.is_nan() || b < o {
            return Err(Error::Invalid(format!(
                "cell {c}, step {t}, inequality {r}: claimed offset {b}, the checker proves only {o} (short by {})",
                ravel_base::text::compact(o - b)
            )));
        }
    }
    Ok(())
}

/// Whether cell `c`'s claimed set at step `t` contains the checker's
/// `proven` box, facet by facet.
fn facets_hold(set: &Bx, proven: &Bx, c: usize, t: usize) -> Result<(), Error> {
    let claimed = set.lo.iter().zip(&set.hi);
    let own = proven.lo.iter().zip(&proven.hi);
    for (i, ((&lo, &hi), (&p_lo, &p_hi))) in claimed.zip(own).enumerate() {
        if p_hi.is_nan() || hi < p_hi {
            return Err(Error::Invalid(format!(
                "cell {c}, step {t}, {}: claimed {}, the checker proves only {} (short by {})",
                facet(i, true),
                hi,
                p_hi,
                ravel_base::text::compact(p_hi - hi)
            )));
        }
        if p_lo.is_nan() || lo > p_lo {
            return Err(Error::Invalid(format!(
                "cell {c}, step {t}, {}: claimed {}, the checker proves only {} (short by {})",
                facet(i, false),
                lo,
                p_lo,
                ravel_base::text::compact(lo - p_lo)
            )));
        }
    }
    Ok(())
}

/// Why the checker's step from cell `c`'s set at step `t − 1` failed, as
/// the checker's answer: a witness of the wrong shape is unreadable; a
/// neuron bound it cannot prove, or an overflow, is a false claim.
fn step_trouble(trouble: Trouble, c: usize, t: usize) -> Error {
    match trouble {
        Trouble::Neuron {
            layer,
            neuron,
            claimed,
            proven,
        } => Error::Invalid(format!(
            "cell {c}, step {t}: pre-activation bound of neuron {neuron} of hidden layer {layer} is [{}, {}], the checker proves only [{}, {}]",
            claimed.0, claimed.1, proven.0, proven.1
        )),
        Trouble::Shape(s) => Error::Unreadable(format!("cell {c}, step {t}: {s}")),
        Trouble::Overflow => Error::Invalid(format!(
            "cell {c}, step {t}: the checker's bound overflows"
        )),
    }
}

/// A list of number vectors of any lengths (absent: none).
fn vectors(v: Option<&Value>, what: &str) -> R<Vec<Vec<f64>>> {
    match v {
        None => Ok(Vec::new()),
        Some(d) => d
            .as_array()
            .ok_or_else(|| format!("`{what}` must be an array"))?
            .iter()
            .map(|v| {
                let len = v.as_array().map_or(0, Vec::len);
                vector(v, len, what)
            })
            .collect(),
    }
}

/// Whether one cell's checked chain proves the VERIFIED property `(name,
/// prop)`; [`Error::Invalid`] names the first row that fails.
fn cell_proves(
    problem: &Problem,
    net: &Network,
    (name, prop): &(String, Prop),
    chain: &CellChain,
    c: usize,
) -> Result<(), Error> {
    let shown = ravel_base::text::sanitize(name);
    let sets = &chain.sets;
    match prop {
        Prop::Goal {
            set,
            steps,
            eventually: false,
            ..
        } if *steps == (problem.horizon, problem.horizon) => {
            // the evidence covers the horizon when a goal is verified
            let Some(last) = sets.get(problem.horizon) else {
                return Err(Error::Invalid(format!(
                    "goal `{shown}`: cell {c} has no set at step {}",
                    problem.horizon
                )));
            };
            let duals = Duals::given(&chain.goal_duals);
            let support = Start::Polytope {
                rows: &chain.last_rows,
                duals: &duals,
            };
            for (r, (a, b)) in set.rows.iter().enumerate() {
                let top = if chain.last_rows.is_empty() {
                    dot_box_upper(a, &last.lo, &last.hi)
                } else {
                    support.support(a, last)
                };
                let worst = sum_upper([top, -b]);
                if worst.is_nan() || worst > 0.0 {
                    return Err(Error::Invalid(format!(
                        "goal `{shown}`: cell {c}'s set at step {} leaves goal row {r} by {}",
                        problem.horizon,
                        ravel_base::text::compact(worst)
                    )));
                }
            }
            if !set.constraints_hold_on(last) {
                return Err(Error::Invalid(format!(
                    "goal `{shown}`: the checker cannot show that a nonlinear constraint holds on cell {c}'s set at step {}",
                    problem.horizon
                )));
            }
        }
        Prop::Goal {
            set,
            steps: s,
            eventually,
            ..
        } => {
            let window = || {
                sets.iter()
                    .enumerate()
                    .take(problem.last_step(prop) + 1)
                    .skip(s.0)
            };
            if window().count() != s.1.min(problem.horizon) + 1 - s.0.min(s.1) {
                return Err(Error::Invalid(format!(
                    "goal `{shown}`: cell {c} has no set at some step of {}..={}",
                    s.0, s.1
                )));
            }
            if *eventually {
                if !window().any(|(_, b)| set.holds_on(b)) {
                    return Err(Error::Invalid(format!(
                        "goal `{shown}`: no set of cell {c} at steps {}..={} lies in the goal",
                        s.0, s.1
                    )));
                }
            } else if let Some((t, _)) = window().find(|(_, b)| !set.holds_on(b)) {
                return Err(Error::Invalid(format!(
                    "goal `{shown}`: cell {c}'s set at step {t} is not shown to lie in the goal"
                )));
            }
        }
        Prop::Avoid {
            members, steps: s, ..
        } => {
            for (t, set) in sets
                .iter()
                .enumerate()
                .take(problem.last_step(prop) + 1)
                .skip(s.0)
            {
                for (k, mb) in members.iter().enumerate() {
                    if !mb.missed_by(set) {
                        return Err(Error::Invalid(format!(
                            "avoid `{shown}`: no inequality of member {k} separates cell {c}'s set at step {t} from it"
                        )));
                    }
                }
            }
        }
    }
    // continuous time: the control periods of the window, by the
    // checker's own flow from the claimed box before each
    let (Some(flows), Prop::Goal { periods, .. } | Prop::Avoid { periods, .. }) =
        (&problem.intersample, prop)
    else {
        return Ok(());
    };
    // an eventually goal is proven at an instant (above)
    if matches!(
        prop,
        Prop::Goal {
            eventually: true,
            ..
        }
    ) {
        return Ok(());
    }
    for p in periods.0.max(1)..=periods.1.min(problem.horizon) {
        // (the evidence reaches every period's end: `needed_step`)
        let Some(before) = sets.get(p - 1) else {
            return Err(Error::Invalid(format!(
                "`{shown}`: cell {c} has no set at step {} for the period ending at step {p}",
                p - 1
            )));
        };
        let pipe = nonlinear::intersample(flows, p - 1, &problem.obs, &problem.v, net, before)
            .ok_or_else(|| {
                Error::Invalid(format!(
                    "`{shown}`: the checker cannot enclose cell {c}'s states between steps {} and {p}",
                    p - 1
                ))
            })?;
        let fine = match prop {
            Prop::Goal { set, .. } => set.holds_on(&pipe),
            Prop::Avoid { members, .. } => members.iter().all(|mb| mb.missed_by(&pipe)),
        };
        if !fine {
            return Err(Error::Invalid(format!(
                "`{shown}`: cell {c}'s states between steps {} and {p} are not shown to satisfy it",
                p - 1
            )));
        }
    }
    Ok(())
}

/// The certificate writer's view of the checker: one cell at a time.
///
/// The writer may refine the analysis's partition until every cell's
/// chain proves the VERIFIED properties (a witness the checker re-checks as
/// a whole: coverage included). `CellCheck` reads the problem, the
/// verdicts and the evidence's settings once and checks single cells with
/// the same code as [`check`].
pub struct CellCheck<'a> {
    problem: Problem,
    net: &'a Network,
    /// The VERIFIED properties' indices (each within the problem's).
    verified: Vec<usize>,
    mode: Mode,
}

impl<'a> CellCheck<'a> {
    /// From a certificate whose evidence has its settings (`steps`, `mode`,
    /// `slope_steps`; the cells are not read).
    pub fn new(cert: &Value, net: &'a Network) -> Result<CellCheck<'a>, Error> {
        let problem = get(cert, "problem")
            .and_then(|p| Problem::read(p, net).map_err(|e| format!("problem: {e}")))
            .map_err(Error::Unreadable)?;
        let verdicts = get(cert, "verdicts")
            .and_then(|v| {
                v.as_array()
                    .ok_or_else(|| "`verdicts` must be an array".to_string())
            })
            .map_err(Error::Unreadable)?;
        let verified: Vec<usize> = verdicts
            .iter()
            .enumerate()
            .filter(|(_, v)| v.get("status").and_then(Value::as_str) == Some("VERIFIED"))
            .map(|(i, _)| i)
            .filter(|&i| i < problem.props.len())
            .collect();
        let needed = verified
            .iter()
            .filter_map(|&i| problem.props.get(i))
            .map(|(_, p)| needed_step(p, problem.horizon))
            .max()
            .unwrap_or(0);
        let ev = get(cert, "evidence").map_err(Error::Unreadable)?;
        let mode = mode(&problem, ev, needed)?;
        Ok(CellCheck {
            problem,
            net,
            verified,
            mode,
        })
    }

    /// Whether `cell` (a certificate cell: its box, its claimed steps)
    /// proves every VERIFIED property on its own; the first failure.
    pub fn check(&self, cell: &Value) -> Result<(), Error> {
        let chain = cell_chain(&self.problem, self.net, cell, self.mode, 0)?;
        for property in self
            .verified
            .iter()
            .filter_map(|&i| self.problem.props.get(i))
        {
            cell_proves(&self.problem, self.net, property, &chain, 0)?;
        }
        Ok(())
    }
}

/// A recorded trajectory's start, process noise and sensor noise (linear
/// and nonlinear certificates alike).
type TrajectoryStart<'a> = (Vec<f64>, &'a Vec<Value>, &'a Vec<Value>);

/// A recorded trajectory's start (`n` states) and its noise sequences, at
/// least `steps` long; `Ok(Err(why))` when it starts outside `initial`.
fn trajectory_start<'a>(
    initial: &Initial,
    n: usize,
    tr: &'a Value,
    steps: usize,
) -> R<Result<TrajectoryStart<'a>, String>> {
    let x0 = vector(get(tr, "initial")?, n, "trajectory.initial")?;
    let ws = get(tr, "process_noise")?
        .as_array()
        .ok_or("`process_noise` must be an array")?;
    let vs = get(tr, "sensor_noise")?
        .as_array()
        .ok_or("`sensor_noise` must be an array")?;
    if ws.len() < steps || vs.len() < steps {
        return Err(format!(
            "the trajectory has noise for fewer than {steps} steps"
        ));
    }
    if !initial.contains(&x0) {
        return Ok(Err("starts outside the initial set".into()));
    }
    Ok(Ok((x0, ws, vs)))
}

/// A FALSIFIED verdict's claim (linear and nonlinear certificates alike):
/// its step, and whether the violation lies between the instants, in the
/// period ending at that step (`between`, false when absent).
fn falsified_claim(v: &Value, i: usize) -> R<(usize, bool)> {
    let step = uint(get(v, "step")?, "step")?;
    let between = match v.get("between") {
        None => false,
        Some(Value::Bool(b)) => *b,
        Some(_) => return Err(format!("verdict {i}: `between` must be a boolean")),
    };
    Ok((step, between))
}

/// A replayed counterexample's line in the report; the first one that is
/// no counterexample (`Err(why)`) also makes the answer INVALID.
fn record_replay(
    report: &mut Report,
    invalid: &mut Option<String>,
    shown: &str,
    step: usize,
    between: bool,
    replayed: Result<(), String>,
) {
    match replayed {
        Ok(()) if between => report.properties.push(format!(
            "{shown}: FALSIFIED (trajectory replayed, violates between steps {} and {step})",
            step.saturating_sub(1)
        )),
        Ok(()) => report.properties.push(format!(
            "{shown}: FALSIFIED (trajectory replayed, violates at step {step})"
        )),
        Err(why) => {
            report
                .properties
                .push(format!("{shown}: FALSIFIED — INVALID: {why}"));
            invalid.get_or_insert(format!("property `{shown}`: the counterexample {why}"));
        }
    }
}

/// Whether a violation between the instants, in the period ending at
/// `step`, can violate `prop`: an "always" goal or an avoid set whose
/// window holds the whole period (both its instants are the window's: a
/// window in seconds may end inside a period it covers), within the
/// horizon; why not otherwise.
fn period_in_window(prop: &Prop, step: usize, horizon: usize) -> Result<(), String> {
    let (steps, periods) = match prop {
        Prop::Goal {
            eventually: true, ..
        } => return Err("claims to violate an eventually goal between the instants".into()),
        Prop::Goal { steps, periods, .. } | Prop::Avoid { steps, periods, .. } => {
            (*steps, *periods)
        }
    };
    if step == 0
        || step > horizon
        || !(periods.0..=periods.1).contains(&step)
        || !(steps.0 < step && step <= steps.1)
    {
        return Err(format!(
            "does not certainly violate the property between steps {} and {step}: the property does not apply there",
            step.saturating_sub(1)
        ));
    }
    Ok(())
}

/// A step's process and sensor noise.
type Noise = (Vec<f64>, Vec<f64>);

/// A trajectory's noise at step `t` read and checked against its boxes
/// (`Ok(Err(why))` when outside).
fn step_noise(problem: &Problem, w: &Value, v: &Value, t: usize) -> R<Result<Noise, String>> {
    let w = vector(w, problem.n, "process_noise")?;
    let v = vector(v, problem.obs.ncols(), "sensor_noise")?;
    if !problem.w.contains(&w) {
        return Ok(Err(format!(
            "has process noise outside its box at step {t}"
        )));
    }
    if !problem.v.contains(&v) {
        return Ok(Err(format!("has sensor noise outside its box at step {t}")));
    }
    Ok(Ok((w, v)))
}

/// Replay a counterexample rigorously; the outer error is an unreadable
/// trajectory, the inner one why it does not violate the property. An
/// eventually goal of a plant in continuous time is violated only when the
/// enclosure also misses it between the instants, on every piece of every
/// period that meets the window, with one of the cuts of
/// [`nonlinear::flow::SUBSTEPS`] (the last period may end after the
/// window's last instant).
fn replay(
    problem: &Problem,
    net: &Network,
    prop: &Prop,
    step: usize,
    tr: &Value,
) -> R<Result<(), String>> {
    let n = problem.n;
    if step > problem.horizon {
        return Ok(Err(format!(
            "names step {step}, beyond the horizon {}",
            problem.horizon
        )));
    }
    let (x0, ws, vs) = match trajectory_start(&problem.initial, n, tr, step)? {
        Ok(t) => t,
        Err(e) => return Ok(Err(e)),
    };
    let (first, eventually, periods) = match prop {
        Prop::Goal {
            steps,
            eventually,
            periods,
            ..
        } => (steps.0, *eventually, *periods),
        Prop::Avoid { steps, periods, .. } => (steps.0, false, *periods),
    };
    let last_step = problem.last_step(prop);
    // an eventually goal in continuous time: the periods that meet the
    // window must miss it too
    let between = match (prop, &problem.intersample) {
        (Prop::Goal { set, .. }, Some(flows)) if eventually => Some((set, flows)),
        _ => None,
    };
    // an "eventually" goal is violated only outside at every step of its window
    let last = match between {
        Some(_) if periods.0 <= periods.1 => last_step.max(periods.1.min(problem.horizon)),
        Some(_) => last_step,
        None if eventually => last_step,
        None => step,
    };
    if !(first <= step && step <= last_step) {
        return Ok(Err(format!(
            "does not certainly violate the property at step {step}: the property does not apply there"
        )));
    }
    if ws.len() < last || vs.len() < last {
        return Err(format!(
            "the trajectory has noise for fewer than {last} steps"
        ));
    }
    let mut x = Bx::point(&x0);
    let mut window = Vec::new();
    // (both lists have at least `last` entries)
    for (t, (w, v)) in ws.iter().zip(vs).enumerate().take(last) {
        if t >= first && t <= last_step {
            window.push(x.clone());
        }
        let (w, v) = match step_noise(problem, w, v, t)? {
            Ok(wv) => wv,
            Err(e) => return Ok(Err(e)),
        };
        if let Some((set, flows)) = between {
            if (periods.0..=periods.1).contains(&(t + 1)) {
                let missed = nonlinear::flow::SUBSTEPS.iter().any(|&s| {
                    nonlinear::intersample_pieces(
                        flows,
                        t,
                        &problem.obs,
                        &Bx::point(&v),
                        net,
                        &x,
                        s,
                    )
                    .is_some_and(|pieces| pieces.iter().all(|b| set.missed_by(b)))
                });
                if !missed {
                    return Ok(Err(format!(
                        "is not shown outside the goal between steps {t} and {}",
                        t + 1
                    )));
                }
            }
        }
        match problem.at(t, net, 0).enclose(&x, &w, &v) {
            Some(next) => x = next,
            None => return Ok(Err(format!("overflows at step {}", t + 1))),
        }
    }
    if last <= last_step {
        window.push(x.clone());
    }
    let violated = match prop {
        Prop::Goal { set, .. } if eventually => window.iter().all(|b| set.missed_by(b)),
        Prop::Goal { set, .. } => set.missed_by(&x),
        Prop::Avoid { members, .. } => members.iter().any(|mb| mb.holds_on(&x)),
    };
    Ok(if violated {
        Ok(())
    } else {
        Err(format!(
            "does not certainly violate the property at step {step} (enclosure {:?} … {:?})",
            x.lo, x.hi
        ))
    })
}

/// Replay a recorded trajectory that violates an "always" goal or an avoid
/// set between the instants, in the period ending at `step` (a linear
/// plant in continuous time; the whole period inside the window): the
/// checker's own enclosure of the trajectory up to step `step − 1`, then
/// the validated flow of that period (its noise arrives at the next
/// instant) in pieces of `1/s` of it for each `s` of
/// [`nonlinear::flow::SUBSTEPS`] in turn; some piece must lie wholly
/// outside the goal (or inside an avoid member).
fn replay_between(
    problem: &Problem,
    net: &Network,
    prop: &Prop,
    step: usize,
    tr: &Value,
) -> R<Result<(), String>> {
    let n = problem.n;
    let Some(flows) = &problem.intersample else {
        return Ok(Err(
            "claims a violation between the instants of a plant in discrete time".into(),
        ));
    };
    if let Err(why) = period_in_window(prop, step, problem.horizon) {
        return Ok(Err(why));
    }
    let (x0, ws, vs) = match trajectory_start(&problem.initial, n, tr, step)? {
        Ok(t) => t,
        Err(e) => return Ok(Err(e)),
    };
    let mut x = Bx::point(&x0);
    for (t, (w, v)) in ws.iter().zip(vs).enumerate().take(step) {
        let (w, v) = match step_noise(problem, w, v, t)? {
            Ok(wv) => wv,
            Err(e) => return Ok(Err(e)),
        };
        if t + 1 < step {
            match problem.at(t, net, 0).enclose(&x, &w, &v) {
                Some(next) => x = next,
                None => return Ok(Err(format!("overflows at step {}", t + 1))),
            }
            continue;
        }
        // the period ending at `step`, in ever shorter pieces
        for s in nonlinear::flow::SUBSTEPS {
            let Some(pieces) =
                nonlinear::intersample_pieces(flows, t, &problem.obs, &Bx::point(&v), net, &x, s)
            else {
                continue;
            };
            let violated = pieces.iter().any(|b| match prop {
                Prop::Goal { set, .. } => set.missed_by(b),
                Prop::Avoid { members, .. } => members.iter().any(|m| m.holds_on(b)),
            });
            if violated {
                return Ok(Ok(()));
            }
        }
    }
    Ok(Err(format!(
        "does not certainly violate the property between steps {} and {step}: no piece of the checker's enclosure of that period lies wholly in the violation",
        step - 1
    )))
}
