//! The checker for network specs (`"kind": "network"` certificates).
//!
//! # What a VALID answer proves
//!
//! For the recorded input set and properties (`ravel certify` first checks
//! that they are exactly what the spec lowers to, and the model's hashes):
//!
//! * every VERIFIED property holds for **every** input of the set: the
//!   recorded cells (boxes) cover the input set (pieces of its bounding box
//!   that provably miss a ball or a polytope row are allowed), and on every
//!   cell the checker's own bounds (interval arithmetic and its own
//!   back-substitution, [`super::bounds::NetBounds`]) prove the property:
//!   every `require` row within its right-hand side; for every `avoid`
//!   member, some row separating it by a positive margin; for robustness to
//!   label `K`, `y_j − y_K < 0` for every `j ≠ K` (a label recorded in the
//!   verdict: proven on the whole set, it is the centre's label too);
//! * every FALSIFIED property is violated by the recorded input for the
//!   model as stored: it is a value of the model's input type (float32
//!   unless the ONNX input is `double`), it lies in the input set, and the
//!   property is violated as a whole by the outward-rounded interval
//!   enclosure of the real-arithmetic network's output, by the checker's
//!   own fixed-order evaluation in the input type's precision and by its
//!   own enclosure of every evaluation in that precision, in any summation
//!   order (for a robustness property without a label, the enclosure at the
//!   centre also shows the recorded label is the centre's).
//!
//! More than [`MAX_CELLS`] cells, or a coverage test that cannot decide
//! within its work limit, is UNREADABLE (not checkable), as in the
//! closed-loop checker. Radius searches and robust action selections are
//! not certified.

use nalgebra::DMatrix;
use serde_json::Value;

use super::bounds::{network_box, Bx, Duals, NetBounds, Start};
use super::cover::{covers_within, MAX_WORK};
use super::{decide, get, num, uint, vector, Answer, Report, R};
use ravel_base::limits::MAX_CELLS;
use ravel_base::nn::{Activation, InputType, Layer, Network};
use ravel_base::num::{dot_box_upper, sum_lower, sum_upper};

/// The input set as recorded.
enum Input {
    Box(Bx),
    Ball {
        center: Vec<f64>,
        radius: Vec<f64>,
        /// `1`, `2` or `0` for ∞.
        norm: u8,
    },
    Polytope {
        bbox: Bx,
        rows: Vec<(Vec<f64>, f64)>,
    },
}

impl Input {
    /// What the checker's supports know of the input set beyond a cell's
    /// box: the ball, or the polytope's rows with `duals` for their supports.
    fn start<'a>(&'a self, duals: &'a Duals<'a>) -> Start<'a> {
        match self {
            Input::Box(_) => Start::Box,
            Input::Ball {
                center,
                radius,
                norm,
            } => Start::Ball {
                center,
                radius,
                norm: match norm {
                    1 => "1",
                    2 => "2",
                    _ => "inf",
                },
            },
            Input::Polytope { rows, .. } => Start::Polytope { rows, duals },
        }
    }
}

/// A property as recorded.
enum Prop {
    Require(Vec<(Vec<f64>, f64)>),
    Avoid(Vec<Vec<(Vec<f64>, f64)>>),
    Robust(Option<usize>),
}

fn row_list(v: &Value, n: usize, what: &str) -> R<Vec<(Vec<f64>, f64)>> {
    v.as_array()
        .ok_or(format!("{what} must be an array"))?
        .iter()
        .map(|r| Ok((vector(get(r, "a")?, n, what)?, num(get(r, "b")?)?)))
        .collect()
}

fn bx(v: &Value, n: usize, what: &str) -> R<Bx> {
    let b = Bx {
        lo: vector(get(v, "lo")?, n, what)?,
        hi: vector(get(v, "hi")?, n, what)?,
    };
    if !b.is_proper() {
        return Err(format!("{what} is not a proper box"));
    }
    Ok(b)
}

impl Input {
    fn read(v: &Value, n: usize) -> R<Input> {
        if let Some(b) = v.get("box") {
            return Ok(Input::Box(bx(b, n, "input box")?));
        }
        if let Some(b) = v.get("ball") {
            let norm = match get(b, "norm")?.as_str() {
                Some("1") => 1,
                Some("2") => 2,
                Some("inf") => 0,
                _ => return Err("ball norm must be \"1\", \"2\" or \"inf\"".into()),
            };
            let radius = vector(get(b, "radius")?, n, "ball radius")?;
            if radius.iter().any(|r| !(r.is_finite() && *r >= 0.0)) {
                return Err("ball radius must be finite and ≥ 0".into());
            }
            return Ok(Input::Ball {
                center: vector(get(b, "center")?, n, "ball centre")?,
                radius,
                norm,
            });
        }
        let p = get(v, "polytope")?;
        Ok(Input::Polytope {
            bbox: bx(get(p, "bbox")?, n, "polytope box")?,
            rows: row_list(get(p, "rows")?, n, "polytope rows")?,
        })
    }

    /// A box containing the set.
    fn bbox(&self) -> Bx {
        match self {
            Input::Box(b) | Input::Polytope { bbox: b, .. } => b.clone(),
            Input::Ball { center, radius, .. } => Bx::around(center, radius),
        }
    }

    /// Lower and upper bounds of the ball gauge `‖(x − c)/r‖` over a box.
    fn gauge(center: &[f64], radius: &[f64], norm: u8, b: &Bx) -> (f64, f64) {
        let mut lo_parts = Vec::new();
        let mut hi_parts = Vec::new();
        for ((&c, &r), (&lo, &hi)) in center.iter().zip(radius).zip(b.lo.iter().zip(&b.hi)) {
            let gap_lo = sum_lower([lo, -c]).max(sum_lower([c, -hi])).max(0.0);
            let gap_hi = sum_upper([hi, -c]).max(sum_upper([c, -lo]));
            let (l, h) = if r > 0.0 {
                ((gap_lo / r).next_down().max(0.0), (gap_hi / r).next_up())
            } else if gap_lo > 0.0 {
                (f64::INFINITY, f64::INFINITY)
            } else if gap_hi > 0.0 {
                (0.0, f64::INFINITY)
            } else {
                (0.0, 0.0)
            };
            lo_parts.push(l);
            hi_parts.push(h);
        }
        match norm {
            1 => (
                sum_lower(lo_parts.iter().copied()),
                sum_upper(hi_parts.iter().copied()),
            ),
            2 => (
                sum_lower(lo_parts.iter().map(|v| (v * v).next_down().max(0.0)))
                    .sqrt()
                    .next_down()
                    .max(0.0),
                sum_upper(hi_parts.iter().map(|v| (v * v).next_up()))
                    .sqrt()
                    .next_up(),
            ),
            _ => (
                lo_parts.iter().fold(0.0f64, |a, v| a.max(*v)),
                hi_parts.iter().fold(0.0f64, |a, v| a.max(*v)),
            ),
        }
    }

    /// Whether the piece certainly contains no point of the set.
    fn misses(&self, piece: &Bx) -> bool {
        match self {
            Input::Box(_) => false,
            Input::Ball {
                center,
                radius,
                norm,
            } => Input::gauge(center, radius, *norm, piece).0 > 1.0,
            Input::Polytope { rows, .. } => rows.iter().any(|(a, h)| {
                let neg: Vec<f64> = a.iter().map(|v| -v).collect();
                -dot_box_upper(&neg, &piece.lo, &piece.hi) > *h
            }),
        }
    }

    /// Whether `x` certainly lies in the set.
    fn contains(&self, x: &[f64]) -> bool {
        match self {
            Input::Box(b) => b.contains(x),
            Input::Ball {
                center,
                radius,
                norm,
            } => Input::gauge(center, radius, *norm, &Bx::point(x)).1 <= 1.0,
            Input::Polytope { bbox, rows } => {
                bbox.contains(x) && rows.iter().all(|(a, h)| dot_box_upper(a, x, x) <= *h)
            }
        }
    }

    /// The centre of a box or ball.
    fn centre(&self) -> Option<Vec<f64>> {
        match self {
            Input::Box(b) => Some(
                b.lo.iter()
                    .zip(&b.hi)
                    .map(|(l, h)| l + 0.5 * (h - l))
                    .collect(),
            ),
            Input::Ball { center, .. } => Some(center.clone()),
            Input::Polytope { .. } => None,
        }
    }
}

fn robust_rows(k: usize, m: usize) -> DMatrix<f64> {
    let others: Vec<usize> = (0..m).filter(|&j| j != k).collect();
    let entries = others.iter().flat_map(|&j| {
        (0..m).map(move |c| {
            if c == j {
                1.0
            } else if c == k {
                -1.0
            } else {
                0.0
            }
        })
    });
    DMatrix::from_row_iterator(others.len(), m, entries)
}

/// Whether the output box `y` certainly violates the property.
fn violates(p: &Prop, label: usize, y: &Bx) -> bool {
    let lower = |a: &[f64]| {
        let neg: Vec<f64> = a.iter().map(|v| -v).collect();
        -dot_box_upper(&neg, &y.lo, &y.hi)
    };
    match p {
        Prop::Require(rows) => rows.iter().any(|(a, b)| lower(a) > *b),
        Prop::Avoid(members) => members.iter().any(|rows| {
            rows.iter()
                .all(|(a, b)| dot_box_upper(a, &y.lo, &y.hi) <= *b)
        }),
        Prop::Robust(_) => {
            let r = robust_rows(label, y.lo.len());
            (0..r.nrows()).any(|i| {
                let a: Vec<f64> = r.row(i).iter().copied().collect();
                lower(&a) >= 0.0
            })
        }
    }
}

/// The checker's own evaluation of the model as stored, in its input type's
/// precision (its own code and its own order, not the analysis's): per
/// affine output the bias first, then `w_j·h_j` in index order, every
/// product and sum rounded to the type (weights and biases rounded to it),
/// ReLU exact, `tanh` and the sigmoid computed in `f64` and rounded.
fn stored_forward(net: &Network, x: &[f64]) -> Vec<f64> {
    match net.input_type {
        InputType::F32 => {
            let mut h: Vec<f32> = x.iter().map(|v| *v as f32).collect();
            for layer in &net.layers {
                h = match layer {
                    Layer::Affine { w, b } => b
                        .iter()
                        .enumerate()
                        .map(|(i, bi)| {
                            let mut s = *bi as f32;
                            for (j, hj) in h.iter().enumerate().take(w.ncols()) {
                                s += w[(i, j)] as f32 * hj;
                            }
                            s
                        })
                        .collect(),
                    Layer::Act(Activation::Relu) => h.iter().map(|v| v.max(0.0)).collect(),
                    Layer::Act(a) => h.iter().map(|v| a.eval(f64::from(*v)) as f32).collect(),
                };
            }
            h.into_iter().map(f64::from).collect()
        }
        InputType::F64 => {
            let mut h = x.to_vec();
            for layer in &net.layers {
                h = match layer {
                    Layer::Affine { w, b } => b
                        .iter()
                        .enumerate()
                        .map(|(i, bi)| {
                            let mut s = *bi;
                            for (j, hj) in h.iter().enumerate().take(w.ncols()) {
                                s += w[(i, j)] * hj;
                            }
                            s
                        })
                        .collect(),
                    Layer::Act(a) => h.iter().map(|v| a.eval(*v)).collect(),
                };
            }
            h
        }
    }
}

/// At most this many multiply-adds per affine layer for the symbols of
/// [`stored_enclosure`]; a larger layer first turns them into intervals.
const SYMBOL_WORK: usize = 1 << 27;

/// The checker's own enclosure of every evaluation of the model as stored
/// at `x`, in its input type's precision and any summation order, as an
/// affine form: value `i` is `cᵢ + Σₖ gₖ[i]·εₖ ± rᵢ` with one `ε ∈ [−1, 1]^m`
/// shared by all values. An affine layer (weights rounded to the type)
/// first gives every `rⱼ` a symbol of its own, then maps the centre and
/// every symbol's column with the signed weights (each entry an outward-
/// rounded interval whose half-width joins `rᵢ`); its runtime's rounding
/// error, at most `γ(n+1)·(Σ|w||h| + |b|) + n·η` for `n` inputs (`u` the
/// type's unit roundoff, `η` its smallest subnormal, `|h|` bounded by the
/// enclosure), is the new `rᵢ`. ReLU is exact: a value `≥ 0` keeps its
/// form, one `≤ 0` is 0, one that straddles becomes `[0, hi]`. `tanh` and
/// the sigmoid become intervals, within the runtime's assumed error
/// ([`InputType::activation_error`]) and libm's. `None` when a value may
/// overflow the type or a bound is not finite.
fn stored_enclosure(net: &Network, x: &[f64]) -> Option<Bx> {
    let t = net.input_type;
    let u = t.unit_roundoff();
    let mut c = x.to_vec();
    // one column per symbol
    let mut cols: Vec<Vec<f64>> = Vec::new();
    let mut r = vec![0.0; x.len()];
    // upper bounds of Σₖ|gₖ[i]| + rᵢ (a missing entry: no bound)
    let spreads = |cols: &[Vec<f64>], r: &[f64]| -> Vec<f64> {
        r.iter()
            .enumerate()
            .map(|(i, ri)| {
                let g = cols
                    .iter()
                    .map(|g| g.get(i).map_or(f64::INFINITY, |v| v.abs()));
                sum_upper(g.chain([*ri]))
            })
            .collect()
    };
    let ends = |cols: &[Vec<f64>], c: &[f64], r: &[f64]| {
        let s = spreads(cols, r);
        Bx {
            lo: c.iter().zip(&s).map(|(c, s)| sum_lower([*c, -s])).collect(),
            hi: c.iter().zip(&s).map(|(c, s)| sum_upper([*c, *s])).collect(),
        }
    };
    for layer in &net.layers {
        match layer {
            Layer::Affine { w, b } => {
                let n = w.ncols();
                // γ(n+1), rounded up; k·u < 1/2 or nothing is claimed
                let ku = (n + 1) as f64 * u;
                if ku >= 0.5 {
                    return None;
                }
                let g = (ku / (1.0 - ku).next_down()).next_up();
                let size = ends(&cols, &c, &r).abs_max();
                if w.nrows().saturating_mul(n).saturating_mul(cols.len()) > SYMBOL_WORK {
                    r = spreads(&cols, &r);
                    cols.clear();
                }
                for (j, rj) in r.iter().enumerate() {
                    if *rj > 0.0 {
                        let col = (0..c.len()).map(|i| if i == j { *rj } else { 0.0 });
                        cols.push(col.collect());
                    }
                }
                let mut next_c = Vec::with_capacity(w.nrows());
                let mut next_r = Vec::with_capacity(w.nrows());
                let mut next_cols = vec![Vec::with_capacity(w.nrows()); cols.len()];
                for (i, bi) in b.iter().enumerate() {
                    let row: Vec<f64> = (0..n).map(|j| t.round(w[(i, j)])).collect();
                    let bias = t.round(*bi);
                    let abs_sum = sum_upper(
                        row.iter()
                            .zip(&size)
                            .map(|(a, m)| (a.abs() * m).next_up())
                            .chain([bias.abs()]),
                    );
                    let err = sum_upper([
                        (g * abs_sum).next_up(),
                        (n as f64 * t.min_positive()).next_up(),
                    ]);
                    if !(abs_sum.is_finite() && sum_upper([abs_sum, err]) <= t.max()) {
                        return None;
                    }
                    // an outward interval of Σ aⱼ vⱼ (+ bias), as midpoint and half-width
                    let mid_half = |v: &[f64], bias: f64| {
                        let hi = sum_upper(row.iter().zip(v).map(|(a, x)| a * x).chain([bias]));
                        let lo = sum_lower(row.iter().zip(v).map(|(a, x)| a * x).chain([bias]));
                        let m = lo + 0.5 * (hi - lo);
                        (m, sum_upper([hi, -m]).max(sum_upper([m, -lo])))
                    };
                    let mut extra = vec![err];
                    let (ci, h) = mid_half(&c, bias);
                    next_c.push(ci);
                    extra.push(h);
                    for (col, next) in cols.iter().zip(next_cols.iter_mut()) {
                        let (gi, h) = mid_half(col, 0.0);
                        next.push(gi);
                        extra.push(h);
                    }
                    next_r.push(sum_upper(extra));
                }
                (c, cols, r) = (next_c, next_cols, next_r);
            }
            Layer::Act(Activation::Relu) => {
                let y = ends(&cols, &c, &r);
                let values = c.iter_mut().zip(r.iter_mut()).zip(y.lo.iter().zip(&y.hi));
                for (i, ((ci, ri), (lo, hi))) in values.enumerate() {
                    if *lo >= 0.0 {
                        continue;
                    }
                    cols.iter_mut()
                        .filter_map(|g| g.get_mut(i))
                        .for_each(|v| *v = 0.0);
                    let top = hi.max(0.0);
                    *ci = 0.5 * top;
                    *ri = sum_upper([top, -*ci]).max(*ci);
                }
            }
            Layer::Act(a) => {
                let d = t.activation_error();
                let y = ends(&cols, &c, &r);
                let values = c.iter_mut().zip(r.iter_mut()).zip(y.lo.iter().zip(&y.hi));
                for ((ci, ri), (lo, hi)) in values {
                    let (el, eh) = (a.eval(*lo), a.eval(*hi));
                    let lo = sum_lower([el, -a.eval_error(el), -d]);
                    let hi = sum_upper([eh, a.eval_error(eh), d]);
                    *ci = lo + 0.5 * (hi - lo);
                    *ri = sum_upper([hi, -*ci]).max(sum_upper([*ci, -lo]));
                }
                cols.clear();
            }
        }
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !(finite(&c) && finite(&r) && cols.iter().all(|g| finite(g))) {
            return None;
        }
    }
    let y = ends(&cols, &c, &r);
    y.is_proper().then_some(y)
}

/// Why a recorded counterexample input does not falsify the property for
/// the model as stored (`None`: it does).
fn replay_input(net: &Network, input: &Input, p: &Prop, label: usize, x: &[f64]) -> Option<String> {
    let t = net.input_type;
    if let Some((i, v)) = x.iter().enumerate().find(|(_, v)| !t.represents(**v)) {
        return Some(format!(
            "input {i} ({v}) is not a {} value (the model's input type; the nearest is {})",
            t.name(),
            t.round(*v)
        ));
    }
    if !input.contains(x) {
        return Some("the input is not in the input set".into());
    }
    let y = network_box(net, &Bx::point(x));
    if !(y.is_proper() && violates(p, label, &y)) {
        return Some(
            "the real-arithmetic network's output there does not certainly violate the property"
                .into(),
        );
    }
    let fixed = stored_forward(net, x);
    let any_order = stored_enclosure(net, x);
    let stored = Bx::point(&fixed).is_proper()
        && violates(p, label, &Bx::point(&fixed))
        && any_order.is_some_and(|e| violates(p, label, &e));
    if !stored {
        return Some(format!(
            "the model evaluated in {} does not certainly violate the property (in every summation order)",
            t.name()
        ));
    }
    None
}

/// Whether the checker's bounds over `cell` prove the property; `Err` with
/// the first failing row otherwise.
///
/// The back-substituted rows are concretised over the cell intersected with
/// what `start` knows of the input set: an ℓp ball's dual norm, or a
/// polytope's rows with dual vectors (one per row, in order).
fn proves(
    net: &Network,
    cell: &Bx,
    p: &Prop,
    (label, m, slopes): (usize, usize, usize),
    start: &Start,
) -> Result<(), String> {
    let nb = NetBounds::new(net, cell, None).map_err(|t| t.to_string())?;
    match p {
        Prop::Require(rows) => {
            // (every row has `m` coefficients, read by `row_list`)
            let entries = rows.iter().flat_map(|(a, _)| a.iter().copied());
            let spec = DMatrix::from_row_iterator(rows.len(), m, entries);
            for (k, (u, (_, b))) in nb
                .rows_upper_in(&spec, slopes, start)
                .iter()
                .zip(rows)
                .enumerate()
            {
                // a NaN bound proves nothing
                let holds = u <= b;
                if !holds {
                    return Err(format!("row {k}: bound {u} exceeds {b}"));
                }
            }
        }
        Prop::Avoid(members) => {
            for (k, rows) in members.iter().enumerate() {
                let entries = rows.iter().flat_map(|(a, _)| a.iter().map(|v| -v));
                let spec = DMatrix::from_row_iterator(rows.len(), m, entries);
                let sep = nb
                    .rows_upper_in(&spec, slopes, start)
                    .iter()
                    .zip(rows)
                    .map(|(u, (_, b))| -u - b)
                    .fold(f64::NEG_INFINITY, f64::max);
                let separated = sep > 0.0;
                if !separated {
                    return Err(format!("member {k}: no row separates it (best {sep})"));
                }
            }
        }
        Prop::Robust(_) => {
            let spec = robust_rows(label, m);
            for (k, u) in nb.rows_upper_in(&spec, slopes, start).iter().enumerate() {
                let below = *u < 0.0;
                if !below {
                    return Err(format!(
                        "label {label} vs comparison {k}: bound {u} is not negative"
                    ));
                }
            }
        }
    }
    Ok(())
}

/// Check a network certificate against the model `net`.
pub fn check(cert: &Value, net: &Network) -> Report {
    check_within(cert, net, MAX_WORK)
}

/// [`check`] with the coverage test's work limit `cover_work` (tests use a
/// small one to reach it cheaply).
/// For the certificate writer: check `cert` as [`check`] does, but find the
/// dual vectors of a polytope input set's supports with `solve` (the
/// writer's LP: a direction and the cell's box to a dual vector) instead of
/// reading them; the report's `duals` holds the ones used, per cell. The
/// writer records them, and the checker then re-checks them as given.
pub fn check_solving(cert: &Value, net: &Network, solve: CellSolver) -> Report {
    check_cells(cert, net, Some(solve), true)
}

/// For the certificate writer's refinement: [`check_solving`] (or, without
/// `solve`, [`check`]), and without `coverage`, whether the cells prove
/// every VERIFIED property whether or not they cover the input set. Never
/// the answer about a certificate: the writer's last check is [`check`].
pub fn check_cells(
    cert: &Value,
    net: &Network,
    solve: Option<CellSolver>,
    coverage: bool,
) -> Report {
    let mut report = Report::empty();
    let work = coverage.then_some(MAX_WORK);
    match inner(cert, net, &mut report, work, solve, None) {
        Ok(a) => report.answer = a,
        Err(e) => report.answer = Answer::Unreadable(e),
    }
    report
}

/// The writer's dual solver: `max gᵀx` over a cell's box and the input
/// polytope's rows, to a dual vector of the rows (`None`: no certified one).
pub type CellSolver<'a> = &'a dyn Fn(&[f64], &Bx) -> Option<Vec<f64>>;

fn check_within(cert: &Value, net: &Network, cover_work: usize) -> Report {
    let mut report = Report::empty();
    match inner(cert, net, &mut report, Some(cover_work), None, None) {
        Ok(a) => report.answer = a,
        Err(e) => report.answer = Answer::Unreadable(e),
    }
    report
}

/// For the certificate writer: check `cert` (activation-split evidence)
/// as [`check`] does, and say per node of the split tree and per proof
/// whether the proof proved its row.
pub fn check_split_proofs(cert: &Value, net: &Network) -> (Report, Vec<Vec<bool>>) {
    let mut report = Report::empty();
    let mut proved = Vec::new();
    match inner(cert, net, &mut report, None, None, Some(&mut proved)) {
        Ok(a) => report.answer = a,
        Err(e) => report.answer = Answer::Unreadable(e),
    }
    (report, proved)
}

/// A network certificate's problem as read: the input and output sizes,
/// the input set and the properties.
struct Problem {
    n: usize,
    m: usize,
    input: Input,
    props: Vec<(String, Prop)>,
}

/// The VERIFIED properties, each with the label its checks use.
type Verified<'p> = Vec<(&'p (String, Prop), usize)>;

/// Check a network certificate against `net` (coverage within `cover_work`
/// steps, none without; polytope duals from `solve` when given); the error
/// says why the certificate is unreadable.
fn inner(
    cert: &Value,
    net: &Network,
    report: &mut Report,
    cover_work: Option<usize>,
    solve: Option<CellSolver>,
    proved: Option<&mut Vec<Vec<bool>>>,
) -> R<Answer> {
    let problem = get(cert, "problem")?;
    let (n, m) = sizes(problem, net)?;
    let input = match get(problem, "input")? {
        // a spec that only selects actions: no input set, no properties
        Value::Null => None,
        v => Some(Input::read(v, n).map_err(|e| format!("input: {e}"))?),
    };
    let props = read_props(problem, m)?;
    let verdicts = get(cert, "verdicts")?
        .as_array()
        .ok_or("`verdicts` must be an array")?;
    if verdicts.len() != props.len() {
        return Err(format!(
            "{} verdicts for {} properties",
            verdicts.len(),
            props.len()
        ));
    }
    let Some(input) = input else {
        if props.is_empty() {
            return Ok(Answer::Valid);
        }
        return Err("properties without an input set".into());
    };
    let problem = Problem { n, m, input, props };
    let (verified, mut invalid) = problem.verdicts(net, verdicts, report)?;
    let mut unsupported: Option<String> = None;
    if !verified.is_empty() {
        let ev = get(cert, "evidence")?;
        match get(ev, "status")?.as_str() {
            Some("checkable") => {
                let failure = if ev.get("splits").is_some() {
                    problem.split_evidence(net, ev, &verified, report, proved)?
                } else {
                    problem.evidence(net, ev, &verified, report, (cover_work, solve))?
                };
                for ((name, _), _) in &verified {
                    let shown = ravel_base::text::sanitize(name);
                    report.properties.push(match failure {
                        None => format!("{shown}: VERIFIED (checked)"),
                        Some(_) => format!("{shown}: VERIFIED — not established"),
                    });
                }
                if let Some(msg) = failure {
                    report.evidence_failure = Some(msg.clone());
                    invalid.get_or_insert(msg);
                }
            }
            Some("unsupported") => {
                let why =
                    ravel_base::text::sanitize_to(get(ev, "reason")?.as_str().unwrap_or(""), 600);
                for ((name, _), _) in &verified {
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

/// The problem's input and output sizes, which must be the network's.
fn sizes(problem: &Value, net: &Network) -> R<(usize, usize)> {
    let n = uint(get(problem, "inputs")?, "inputs")?;
    let m = uint(get(problem, "outputs")?, "outputs")?;
    if n != net.inputs || m != net.outputs() {
        return Err(format!(
            "the problem is {n} → {m}, the network {} → {}",
            net.inputs,
            net.outputs()
        ));
    }
    Ok((n, m))
}

/// The recorded properties over `m` outputs, with their names.
fn read_props(problem: &Value, m: usize) -> R<Vec<(String, Prop)>> {
    let mut props = Vec::new();
    for p in get(problem, "properties")?
        .as_array()
        .ok_or("`properties` must be an array")?
    {
        let name = get(p, "name")?.as_str().unwrap_or("").to_string();
        let prop = match get(p, "kind")?.as_str() {
            Some("require") => Prop::Require(row_list(get(p, "rows")?, m, "require rows")?),
            Some("avoid") => Prop::Avoid(
                get(p, "members")?
                    .as_array()
                    .ok_or("`members` must be an array")?
                    .iter()
                    .map(|mm| row_list(mm, m, "avoid rows"))
                    .collect::<R<_>>()?,
            ),
            Some("robust") => Prop::Robust(match get(p, "label")? {
                Value::Null => None,
                v => Some(uint(v, "label")?),
            }),
            _ => return Err("property kind must be require, avoid or robust".into()),
        };
        props.push((name, prop));
    }
    Ok(props)
}

impl Problem {
    /// Check activation-split evidence ([`super::splits`]) for the
    /// `verified` properties; `proved` receives, per node and proof,
    /// whether it proved its row (for the writer).
    fn split_evidence(
        &self,
        net: &Network,
        ev: &Value,
        verified: &Verified,
        report: &mut Report,
        proved: Option<&mut Vec<Vec<bool>>>,
    ) -> R<Option<String>> {
        use super::splits::{Chain, Evidence, Need, Row, Test};
        let slopes = super::slope_steps(ev)?;
        let Input::Box(input) = &self.input else {
            return Err("activation splits are checked over a box input set only".into());
        };
        let chain = Chain::of(net)?;
        // every property's rows, in order (the VERIFIED ones' directions
        // and tests; the others only hold their places)
        let mut rows: Vec<Option<Row>> = Vec::new();
        let mut needs: Vec<Need> = Vec::new();
        for named in &self.props {
            let (name, p) = named;
            let label = verified
                .iter()
                .find(|(q, _)| std::ptr::eq(*q, named))
                .map(|(_, l)| *l);
            let mut need = Need {
                name: name.clone(),
                ..Need::default()
            };
            let push = |row: Option<Row>, rows: &mut Vec<Option<Row>>| -> usize {
                rows.push(row);
                rows.len() - 1
            };
            match p {
                Prop::Require(list) => {
                    for (a, b) in list {
                        let row = label.map(|_| Row {
                            d: a.clone(),
                            test: Test::AtMost(*b),
                        });
                        need.all.push(push(row, &mut rows));
                    }
                }
                Prop::Avoid(members) => {
                    for list in members {
                        let mut group = Vec::new();
                        for (a, b) in list {
                            // separated: a·y > b, i.e. (−a)·y < −b
                            let row = label.map(|_| Row {
                                d: a.iter().map(|v| -v).collect(),
                                test: Test::Below(-b),
                            });
                            group.push(push(row, &mut rows));
                        }
                        need.any.push(group);
                    }
                }
                Prop::Robust(_) => {
                    let k = label.unwrap_or(0);
                    let r = robust_rows(k, self.m);
                    for i in 0..r.nrows() {
                        let row = label.map(|_| Row {
                            d: r.row(i).iter().copied().collect(),
                            test: Test::Below(0.0),
                        });
                        need.all.push(push(row, &mut rows));
                    }
                }
            }
            if label.is_some() {
                needs.push(need);
            }
        }
        let ev = Evidence::read(get(ev, "splits")?, &chain, rows.len())?;
        report.subproblems = ev.nodes();
        Ok(super::splits::check(
            &chain, &ev, input, &rows, &needs, slopes, proved,
        ))
    }

    /// Read the verdicts (one per property, in order) into the report,
    /// replaying every FALSIFIED one: the VERIFIED properties with their
    /// labels, and the first invalid counterexample's message.
    fn verdicts<'p>(
        &'p self,
        net: &Network,
        verdicts: &[Value],
        report: &mut Report,
    ) -> R<(Verified<'p>, Option<String>)> {
        let mut invalid: Option<String> = None;
        let mut verified = Vec::new();
        for (i, (v, named)) in verdicts.iter().zip(&self.props).enumerate() {
            let (name, p) = named;
            if get(v, "property")?.as_str() != Some(name.as_str()) {
                return Err(format!(
                    "verdict {i} is not about property `{}`",
                    ravel_base::text::sanitize(name)
                ));
            }
            let shown = ravel_base::text::sanitize(name);
            let label = self.label(p, v)?;
            match get(v, "status")?.as_str() {
                Some("VERIFIED") => verified.push((named, label)),
                Some("UNSURE") => report
                    .properties
                    .push(format!("{shown}: UNSURE (no claim)")),
                Some("FALSIFIED") => {
                    let x = vector(get(v, "input")?, self.n, "counterexample input")?;
                    match self.refutation(net, p, label, &x) {
                        None => report
                            .properties
                            .push(format!("{shown}: FALSIFIED (input replayed)")),
                        Some(why) => {
                            report
                                .properties
                                .push(format!("{shown}: FALSIFIED — INVALID: {why}"));
                            invalid.get_or_insert(format!(
                                "property `{shown}`: the counterexample: {why}"
                            ));
                        }
                    }
                }
                _ => {
                    return Err(format!(
                        "verdict {i}: `status` must be VERIFIED, FALSIFIED or UNSURE"
                    ))
                }
            }
        }
        Ok((verified, invalid))
    }

    /// The label property `p`'s checks use: a robustness property's own or
    /// its verdict's (0 for the other kinds), within the outputs.
    fn label(&self, p: &Prop, v: &Value) -> R<usize> {
        let k = match p {
            Prop::Robust(Some(k)) => *k,
            Prop::Robust(None) => uint(get(v, "label")?, "label")?,
            _ => 0,
        };
        if k >= self.m {
            return Err(format!("label {k} is out of range"));
        }
        Ok(k)
    }

    /// Why the recorded input `x` does not falsify property `p`
    /// ([`replay_input`]; for a robustness property without a label, the
    /// recorded label must also be the centre's); `None`: it does.
    fn refutation(&self, net: &Network, p: &Prop, label: usize, x: &[f64]) -> Option<String> {
        let why = replay_input(net, &self.input, p, label, x);
        if let (Prop::Robust(None), None) = (p, &why) {
            if !self.centre_has(net, label) {
                return Some(format!("label {label} is not certainly the centre's"));
            }
        }
        why
    }

    /// Whether `label` is certainly the network's label at the input set's
    /// centre (a polytope has none).
    fn centre_has(&self, net: &Network, label: usize) -> bool {
        self.input.centre().is_some_and(|c| {
            let yc = network_box(net, &Bx::point(&c));
            yc.is_proper() && {
                let r = robust_rows(label, self.m);
                (0..r.nrows()).all(|k| {
                    let a: Vec<f64> = r.row(k).iter().copied().collect();
                    dot_box_upper(&a, &yc.lo, &yc.hi) < 0.0
                })
            }
        })
    }

    /// Check the VERIFIED evidence `ev` (coverage within `cover_work`
    /// steps, none without; a polytope input's duals from `solve` when
    /// given, else from the cells): the first failure (a gap in the
    /// coverage, or cell by cell the first property that its bounds do not
    /// prove); the error says why the evidence is unreadable.
    fn evidence(
        &self,
        net: &Network,
        ev: &Value,
        verified: &Verified,
        report: &mut Report,
        (cover_work, solve): (Option<usize>, Option<CellSolver>),
    ) -> R<Option<String>> {
        // `optimise_slopes`: the checker's own slope search
        let slopes = super::slope_steps(ev)?;
        let cells_json = get(ev, "cells")?
            .as_array()
            .ok_or("`cells` must be an array")?;
        // before any work per cell: the analysis's own limit
        if cells_json.len() as u64 > MAX_CELLS {
            return Err(format!(
                "{} cells: more than the {MAX_CELLS} any analysis makes",
                cells_json.len()
            ));
        }
        let cells: Vec<Bx> = cells_json
            .iter()
            .map(|c| bx(c, self.n, "cell"))
            .collect::<R<_>>()?;
        // a polytope input's dual witnesses, per cell (absent: none)
        let given: Vec<Vec<Vec<f64>>> = match (&self.input, solve) {
            (Input::Polytope { .. }, None) => cells_json
                .iter()
                .map(|c| super::vectors(c.get("duals"), "cell duals"))
                .collect::<R<_>>()?,
            _ => vec![Vec::new(); cells.len()],
        };
        report.cells = cells.len();
        // (no work limit: the writer's per-cell check, which does
        // not ask for coverage)
        let input = &self.input;
        let covered = match cover_work {
            None => Ok(()),
            Some(work) => covers_within(&cells, &input.bbox(), &|piece| input.misses(piece), work),
        };
        match covered {
            Err(Some(x)) => Ok(Some(format!(
                "the cells do not cover the input set (near {x:?})"
            ))),
            // undecided is not false: the certificate is not checkable
            Err(None) => Err(
                "the cells' coverage of the input set could not be decided within the work limit"
                    .into(),
            ),
            // cell by cell, each cell's properties in order (the
            // order its dual vectors are used in)
            Ok(()) => Ok(cells
                .iter()
                .zip(&given)
                .enumerate()
                .find_map(|(c, (cell, given))| {
                    let per_cell = |g: &[f64]| solve.and_then(|f| f(g, cell));
                    let duals = match solve {
                        Some(_) => Duals::solved(&per_cell),
                        None => Duals::given(given),
                    };
                    let failed = self.first_unproven(net, cell, c, verified, slopes, &duals);
                    report.duals.push(duals.used());
                    failed
                })),
        }
    }

    /// The first of the `verified` properties that the checker's bounds over
    /// cell `c` do not prove (with `slopes` steps of slope search and the
    /// polytope input's `duals`), as the message naming it.
    fn first_unproven(
        &self,
        net: &Network,
        cell: &Bx,
        c: usize,
        verified: &Verified,
        slopes: usize,
        duals: &Duals,
    ) -> Option<String> {
        let start = self.input.start(duals);
        verified.iter().find_map(|&((name, p), label)| {
            proves(net, cell, p, (label, self.m, slopes), &start)
                .err()
                .map(|e| {
                    format!(
                        "property `{}`, cell {c}: {e}",
                        ravel_base::text::sanitize(name)
                    )
                })
        })
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use nalgebra::DVector;
    use serde_json::json;

    /// A VERIFIED `y ≤ 2` for `y = x` over `[0, 1]`, with two cells.
    fn cert() -> (Value, Network) {
        let net = Network::new(
            1,
            vec![Layer::Affine {
                w: DMatrix::from_row_slice(1, 1, &[1.0]),
                b: DVector::from_column_slice(&[0.0]),
            }],
        );
        let cert = json!({
            "problem": { "kind": "network", "inputs": 1, "outputs": 1,
                "input": { "box": { "lo": [0.0], "hi": [1.0] } },
                "properties": [{ "name": "p", "kind": "require", "rows": [{ "a": [1.0], "b": 2.0 }] }] },
            "verdicts": [{ "property": "p", "kind": "require", "status": "VERIFIED", "label": null }],
            "evidence": { "status": "checkable",
                "cells": [{ "lo": [0.0], "hi": [0.5] }, { "lo": [0.5], "hi": [1.0] }] },
        });
        (cert, net)
    }

    #[test]
    fn undecided_coverage_is_unreadable_not_invalid() {
        let (cert, net) = cert();
        assert_eq!(check(&cert, &net).answer, Answer::Valid);
        match check_within(&cert, &net, 1).answer {
            Answer::Unreadable(m) => assert!(m.contains("could not be decided"), "{m}"),
            other => panic!("expected UNREADABLE, got {other:?}"),
        }
    }

    /// Left to right in float32, `1` plus `k` halves of its unit in the
    /// last place loses every half, in both affine layers: nearly the worst
    /// case of the error bound, which the checker's enclosure must hold (a
    /// layer's error halved or forgotten would not).
    #[test]
    fn the_stored_enclosure_holds_the_worst_case_order() {
        let k = 40;
        let tiny = 2f64.powi(-24);
        let mut x = vec![tiny; k + 1];
        x[0] = 1.0;
        let w1 = DMatrix::from_fn(k + 1, k + 1, |i, j| f64::from(u8::from(i == 0 || i == j)));
        let net = Network::new(
            k + 1,
            vec![
                Layer::Affine {
                    w: w1,
                    b: DVector::zeros(k + 1),
                },
                Layer::Act(Activation::Relu),
                Layer::Affine {
                    w: DMatrix::from_element(1, k + 1, 1.0),
                    b: DVector::zeros(1),
                },
            ],
        );
        assert_eq!(stored_forward(&net, &x), vec![1.0]);
        let e = stored_enclosure(&net, &x).expect("finite");
        assert!(e.lo[0] <= 1.0 && e.lo[0] > 1.0 - 8.0 * tiny, "{e:?}");
    }

    /// The float32 evaluations of random networks in other orders (the
    /// analysis's column order, the reverse order, one rounding of the
    /// exact sum) lie in the checker's enclosure of every order.
    #[test]
    fn the_stored_enclosure_holds_every_summation_order() {
        // the checker imports nothing of the analysis, not even its
        // random numbers: a xorshift of its own
        struct Xs(u64);
        impl Xs {
            fn unit(&mut self) -> f64 {
                self.0 ^= self.0 << 13;
                self.0 ^= self.0 >> 7;
                self.0 ^= self.0 << 17;
                (self.0 >> 11) as f64 / (1u64 << 53) as f64
            }
            fn normal(&mut self) -> f64 {
                let (a, b) = (self.unit().max(1e-300), self.unit());
                (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
            }
            fn below(&mut self, k: usize) -> usize {
                ((self.unit() * k as f64) as usize).min(k - 1)
            }
        }
        let mut rng = Xs(0x9e37_79b9_7f4a_7c15);
        for case in 0..300 {
            let act = [Activation::Relu, Activation::Tanh, Activation::Sigmoid][case % 3];
            let widths = [3, 1 + rng.below(12), 1 + rng.below(12), 2];
            let mut layers = Vec::new();
            for (k, pair) in widths.windows(2).enumerate() {
                let s = 10f64.powi(rng.below(7) as i32 - 3);
                layers.push(Layer::Affine {
                    w: DMatrix::from_fn(pair[1], pair[0], |_, _| s * rng.normal()),
                    b: DVector::from_fn(pair[1], |_, _| s * rng.normal()),
                });
                if k + 2 < widths.len() {
                    layers.push(Layer::Act(act));
                }
            }
            let net = Network::new(3, layers);
            let x: Vec<f64> = (0..3).map(|_| f64::from(rng.normal() as f32)).collect();
            let e = stored_enclosure(&net, &x).expect("no overflow at these sizes");
            // reverse order and one rounding per output, in float32
            let mut rev: Vec<f32> = x.iter().map(|v| *v as f32).collect();
            let mut once: Vec<f32> = rev.clone();
            for layer in &net.layers {
                match layer {
                    Layer::Affine { w, b } => {
                        rev = (0..w.nrows())
                            .map(|i| {
                                let mut s = 0.0f32;
                                for j in (0..w.ncols()).rev() {
                                    s += w[(i, j)] as f32 * rev[j];
                                }
                                s + b[i] as f32
                            })
                            .collect();
                        once = (0..w.nrows())
                            .map(|i| {
                                let exact: f64 = (0..w.ncols())
                                    .map(|j| f64::from(w[(i, j)] as f32) * f64::from(once[j]))
                                    .sum::<f64>()
                                    + f64::from(b[i] as f32);
                                exact as f32
                            })
                            .collect();
                    }
                    Layer::Act(a) => {
                        for v in rev.iter_mut().chain(once.iter_mut()) {
                            *v = a.eval(f64::from(*v)) as f32;
                        }
                    }
                }
            }
            for y in [
                net.forward_stored(&x),
                stored_forward(&net, &x),
                rev.iter().map(|v| f64::from(*v)).collect(),
                once.iter().map(|v| f64::from(*v)).collect(),
            ] {
                assert!(e.contains(&y), "case {case}: {y:?} outside {e:?}");
            }
        }
    }
}
