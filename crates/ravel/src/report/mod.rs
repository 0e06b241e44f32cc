//! Reports: a [`Run`] as text for people or as JSON for machines; the
//! report of each kind of spec is in its own module ([`system`],
//! [`network`]), the number formats and partition descriptions they share
//! are here.
//!
//! The JSON schema is documented in `docs/json-schema.md`; its identifier is
//! [`SCHEMA`]. Output is deterministic: timing appears only when the caller
//! passes it.

use serde_json::{json, Value};

use crate::execute::Run;
use crate::lower::Partitioner;
use ravel_analysis::partition::Stop;

/// The identifier of the JSON result schema.
pub const SCHEMA: &str = "ravel-report/1";

pub mod network;
pub mod system;

/// The report of a run for people: the spec's name first, `timing_ms` adds
/// a timing line.
pub fn text(spec_name: &str, run: &Run, timing_ms: Option<f64>) -> String {
    match run {
        Run::System { plan, outcome } => system::text(spec_name, plan, outcome, timing_ms),
        Run::Network { plan, outcome } => network::text(spec_name, plan, outcome, timing_ms),
    }
}

/// The report of a run for machines (schema [`SCHEMA`]); `timing_ms` adds
/// the timing.
pub fn json(spec_name: &str, run: &Run, timing_ms: Option<f64>) -> Value {
    match run {
        Run::System { plan, outcome } => system::json(spec_name, plan, outcome, timing_ms),
        Run::Network { plan, outcome } => network::json(spec_name, plan, outcome, timing_ms),
    }
}

/// Format a number in ravel's one float format: fixed with 6 decimals for
/// ordinary magnitudes, scientific otherwise.
pub fn num(x: f64) -> String {
    if x == 0.0 {
        "0.000000".into()
    } else if x.is_nan() {
        "nan".into()
    } else if x.is_infinite() {
        if x > 0.0 { "inf" } else { "-inf" }.into()
    } else if (1e-4..1e7).contains(&x.abs()) {
        format!("{x:.6}")
    } else {
        format!("{x:.6e}")
    }
}

pub(crate) fn interval(lo: f64, hi: f64) -> String {
    format!("[{:>10}, {:>10}]", num(lo), num(hi))
}

pub(crate) fn vector(v: &[f64]) -> String {
    format!(
        "[{}]",
        v.iter().map(|x| num(*x)).collect::<Vec<_>>().join(", ")
    )
}

/// How the set was partitioned, for people (`cells` final cells, why it stopped).
pub(crate) fn partition_text(partitioner: &Partitioner, cells: usize, stop: Stop) -> String {
    match partitioner {
        Partitioner::Uniform(grid) if grid.iter().all(|k| *k == 1) => {
            "no partition (1 cell)".into()
        }
        Partitioner::Uniform(grid) if stop == Stop::Time => format!(
            "uniform partition {grid:?} ({cells} cells; the time limit left some with the whole set's bounds)"
        ),
        Partitioner::Uniform(grid) => format!("uniform partition {grid:?} ({cells} cells)"),
        Partitioner::Guided { guide, budget } => {
            let why = match stop {
                Stop::Done | Stop::Grid => "every cell settled".to_string(),
                Stop::Calls if budget.calls == 1 => "budget of 1 cell evaluation spent".to_string(),
                Stop::Calls => format!("budget of {} cell evaluations spent", budget.calls),
                Stop::Time => "time budget spent".to_string(),
                Stop::Decided => "every property settled".to_string(),
                Stop::Queue => "the queue of open subproblems reached its memory limit".to_string(),
            };
            let noun = if cells == 1 { "cell" } else { "cells" };
            format!("{} partition ({cells} {noun}, {why})", guide.name())
        }
    }
}

/// ` (slopes optimised, N steps)` after the propagator's name, when they are.
pub fn slopes_text(steps: usize) -> String {
    match steps {
        0 => String::new(),
        1 => " (slopes optimised, 1 step)".to_string(),
        k => format!(" (slopes optimised, {k} steps)"),
    }
}

/// The partitioner's name in JSON reports.
pub(crate) fn partitioner_name(p: &Partitioner) -> &'static str {
    match p {
        Partitioner::Uniform(_) => "uniform",
        Partitioner::Guided { guide, .. } => guide.name(),
    }
}

/// A uniform partition's grid in JSON reports (`null` for guided ones).
pub(crate) fn partition_grid(p: &Partitioner) -> Value {
    match p {
        Partitioner::Uniform(grid) => json!(grid),
        Partitioner::Guided { .. } => Value::Null,
    }
}

pub(crate) fn f(x: f64) -> Value {
    if x.is_finite() {
        json!(x)
    } else {
        Value::Null
    }
}
