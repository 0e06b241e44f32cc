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
//! * every FALSIFIED property is violated by the recorded input: it lies in
//!   the input set, and the outward-rounded interval enclosure of the
//!   network's output there violates the property as a whole (for a
//!   robustness property without a label, the enclosure at the centre also
//!   shows the recorded label is the centre's).
//!
//! Radius searches and robust action selections are not certified.

use nalgebra::DMatrix;
use serde_json::Value;

use super::bounds::{network_box, Bx, NetBounds};
use super::cover::covers;
use super::{decide, get, num, uint, vector, Answer, Report, R};
use crate::nn::Network;
use crate::num::{dot_box_upper, sum_lower, sum_upper};

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
        for i in 0..center.len() {
            let gap_lo = sum_lower([b.lo[i], -center[i]])
                .max(sum_lower([center[i], -b.hi[i]]))
                .max(0.0);
            let gap_hi = sum_upper([b.hi[i], -center[i]]).max(sum_upper([center[i], -b.lo[i]]));
            let r = radius[i];
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
    DMatrix::from_fn(others.len(), m, |r, c| {
        if c == others[r] {
            1.0
        } else if c == k {
            -1.0
        } else {
            0.0
        }
    })
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

/// Whether the checker's bounds over `cell` prove the property; `Err` with
/// the first failing row otherwise.
fn proves(
    net: &Network,
    cell: &Bx,
    p: &Prop,
    (label, m, slopes): (usize, usize, usize),
) -> Result<(), String> {
    let nb = NetBounds::new(net, cell, None).map_err(|t| t.to_string())?;
    match p {
        Prop::Require(rows) => {
            let spec = DMatrix::from_fn(rows.len(), m, |r, c| rows[r].0[c]);
            for (k, (u, (_, b))) in nb.rows_upper(&spec, slopes).iter().zip(rows).enumerate() {
                // a NaN bound proves nothing
                let holds = u <= b;
                if !holds {
                    return Err(format!("row {k}: bound {u} exceeds {b}"));
                }
            }
        }
        Prop::Avoid(members) => {
            for (k, rows) in members.iter().enumerate() {
                let spec = DMatrix::from_fn(rows.len(), m, |r, c| -rows[r].0[c]);
                let sep = nb
                    .rows_upper(&spec, slopes)
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
            for (k, u) in nb.rows_upper(&spec, slopes).iter().enumerate() {
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
    let mut report = Report::empty();
    match inner(cert, net, &mut report) {
        Ok(a) => report.answer = a,
        Err(e) => report.answer = Answer::Unreadable(e),
    }
    report
}

fn inner(cert: &Value, net: &Network, report: &mut Report) -> R<Answer> {
    let problem = get(cert, "problem")?;
    let n = uint(get(problem, "inputs")?, "inputs")?;
    let m = uint(get(problem, "outputs")?, "outputs")?;
    if n != net.inputs || m != net.outputs() {
        return Err(format!(
            "the problem is {n} → {m}, the network {} → {}",
            net.inputs,
            net.outputs()
        ));
    }
    let input = match get(problem, "input")? {
        // a spec that only selects actions: no input set, no properties
        Value::Null => None,
        v => Some(Input::read(v, n).map_err(|e| format!("input: {e}"))?),
    };
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
    let label_of = |p: &Prop, v: &Value| -> R<usize> {
        let k = match p {
            Prop::Robust(Some(k)) => *k,
            Prop::Robust(None) => uint(get(v, "label")?, "label")?,
            _ => 0,
        };
        if k >= m {
            return Err(format!("label {k} is out of range"));
        }
        Ok(k)
    };
    let mut invalid: Option<String> = None;
    let mut unsupported: Option<String> = None;
    let mut verified = Vec::new();
    for (i, (v, (name, p))) in verdicts.iter().zip(&props).enumerate() {
        if get(v, "property")?.as_str() != Some(name.as_str()) {
            return Err(format!(
                "verdict {i} is not about property `{}`",
                crate::diag::sanitize(name)
            ));
        }
        let shown = crate::diag::sanitize(name);
        let label = label_of(p, v)?;
        match get(v, "status")?.as_str() {
            Some("VERIFIED") => verified.push((i, label)),
            Some("UNSURE") => report
                .properties
                .push(format!("{shown}: UNSURE (no claim)")),
            Some("FALSIFIED") => {
                let x = vector(get(v, "input")?, n, "counterexample input")?;
                let inside = input.contains(&x);
                let y = network_box(net, &Bx::point(&x));
                let mut ok = inside && y.is_proper() && violates(p, label, &y);
                if let (Prop::Robust(None), true) = (p, ok) {
                    // the recorded label must be the centre's
                    ok = input.centre().is_some_and(|c| {
                        let yc = network_box(net, &Bx::point(&c));
                        yc.is_proper() && {
                            let r = robust_rows(label, m);
                            (0..r.nrows()).all(|k| {
                                let a: Vec<f64> = r.row(k).iter().copied().collect();
                                dot_box_upper(&a, &yc.lo, &yc.hi) < 0.0
                            })
                        }
                    });
                }
                if ok {
                    report
                        .properties
                        .push(format!("{shown}: FALSIFIED (input replayed)"));
                } else {
                    let why = if inside {
                        "its output does not certainly violate the property"
                    } else {
                        "the input is not in the input set"
                    };
                    report
                        .properties
                        .push(format!("{shown}: FALSIFIED — INVALID: {why}"));
                    invalid.get_or_insert(format!("property `{shown}`: the counterexample: {why}"));
                }
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
                // `optimise_slopes`: the checker's own slope search
                let slopes = super::slope_steps(ev)?;
                let cells: Vec<Bx> = get(ev, "cells")?
                    .as_array()
                    .ok_or("`cells` must be an array")?
                    .iter()
                    .map(|c| bx(c, n, "cell"))
                    .collect::<R<_>>()?;
                report.cells = cells.len();
                let failure = match covers(&cells, &input.bbox(), &|piece| input.misses(piece)) {
                    Err(Some(x)) => {
                        Some(format!("the cells do not cover the input set (near {x:?})"))
                    }
                    Err(None) => {
                        Some("the cells' coverage could not be decided in the work limit".into())
                    }
                    Ok(()) => verified.iter().find_map(|&(i, label)| {
                        cells.iter().enumerate().find_map(|(c, cell)| {
                            proves(net, cell, &props[i].1, (label, m, slopes))
                                .err()
                                .map(|e| {
                                    format!(
                                        "property `{}`, cell {c}: {e}",
                                        crate::diag::sanitize(&props[i].0)
                                    )
                                })
                        })
                    }),
                };
                for &(i, _) in &verified {
                    let shown = crate::diag::sanitize(&props[i].0);
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
                let why = crate::diag::sanitize_to(get(ev, "reason")?.as_str().unwrap_or(""), 600);
                for &(i, _) in &verified {
                    let shown = crate::diag::sanitize(&props[i].0);
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
