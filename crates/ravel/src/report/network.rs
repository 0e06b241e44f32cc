//! Reports of network specs: a [`NetworkOutcome`] as text or JSON (the same
//! schema family as closed-loop results: `spec`, `verdict`, `properties`
//! with `name`, `kind`, `status`, `margin`; see `docs/json-schema.md`).

use serde_json::{json, Value};

use super::{f, interval, num, partition_grid, partition_text, partitioner_name, vector};
use crate::execute::network::{NetworkOutcome, Witness};
use crate::execute::Verdict;
use crate::lower::NetworkPlan;
use ravel_analysis::sets::{IBox, Norm, Region};
use ravel_analysis::shape::Shape;

fn shape_text(s: &Shape) -> String {
    match s {
        Shape::LowerBounds => "lower bounds".into(),
        Shape::Box => "box".into(),
        Shape::Polytope(d) => format!("polytope ({} directions + box)", d.nrows()),
        Shape::Hull => "hull (edge normals of the sampled outputs' convex hull + box)".into(),
    }
}

fn shape_name(s: &Shape) -> &'static str {
    match s {
        Shape::LowerBounds => "lower_bounds",
        Shape::Box => "box",
        Shape::Polytope(_) => "polytope",
        Shape::Hull => "hull",
    }
}

fn region_text(name: &str, r: &Region) -> String {
    match r {
        Region::Box(b) => format!("box {}", box_text(name, b)),
        Region::Ball {
            center,
            radius,
            norm,
        } => format!(
            "ℓ{} ball, centre {}, radius {}",
            match norm {
                Norm::L1 => "1",
                Norm::L2 => "2",
                Norm::LInf => "∞",
            },
            vector(center),
            vector(radius)
        ),
        Region::Polytope { rows, bbox } => format!(
            "polytope of {} inequalities in the box {}",
            rows.len(),
            box_text(name, bbox)
        ),
    }
}

fn box_text(name: &str, b: &IBox) -> String {
    (0..b.dim())
        .map(|i| format!("{name}[{i}] ∈ [{}, {}]", num(b.lo[i]), num(b.hi[i])))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The tutorial's error figure for an output set: the bounding box's volume
/// over the sampled outputs' bounding box volume, minus 1 (`None` without a
/// box or when the samples are flat).
pub fn output_error(out: &NetworkOutcome) -> Option<f64> {
    let (b, s) = (out.output.bbox.as_ref()?, out.output.sampled_bbox.as_ref()?);
    let v = s.volume();
    (v > 0.0 && b.is_finite()).then(|| b.volume() / v - 1.0)
}

fn output_text(plan: &NetworkPlan, out: &NetworkOutcome) -> String {
    let mut s = String::new();
    s += "  output set (certified, then the sampled outputs)\n";
    let m = plan.net.outputs();
    let y = &plan.output_name;
    match (&out.output.bbox, &plan.shape) {
        (Some(b), _) => {
            for i in 0..m {
                let sampled = out
                    .output
                    .sampled_bbox
                    .as_ref()
                    .map(|sb| format!("   sampled {}", interval(sb.lo[i], sb.hi[i])))
                    .unwrap_or_default();
                s += &format!("  {y}[{i}] ∈ {}{sampled}\n", interval(b.lo[i], b.hi[i]));
            }
            let d = &out.output.directions;
            for k in 2 * m..d.nrows() {
                let dir: Vec<f64> = d.row(k).iter().copied().collect();
                s += &format!(
                    "  {} · {y} ≤ {:>10}   sampled {:>10}\n",
                    vector(&dir),
                    num(out.output.offsets[k]),
                    num(out.output.sampled[k])
                );
            }
        }
        (None, _) => {
            for i in 0..m {
                let lo = -out.output.offsets[i];
                let sampled = -out.output.sampled[i];
                s += &format!(
                    "  {y}[{i}] ≥ {:>10}   sampled minimum {:>10}\n",
                    num(lo),
                    num(sampled)
                );
            }
        }
    }
    if let Some(e) = output_error(out) {
        s += &format!(
            "  error (box volume / sampled box volume − 1): {}\n",
            num(e)
        );
    }
    if out.overflow {
        s += "  some bounds overflowed f64: they bound nothing and prove nothing\n";
    }
    for i in &out.solver_issues {
        s += &format!(
            "  solver issue: {} (a fallback bound was used; no property is VERIFIED on it)\n",
            i.as_str()
        );
    }
    s
}

/// The robust action selections: per observation, the nominal and CARRL
/// actions and every action's certified value interval (text shows at most
/// 20 observations per block; JSON and CSV have all).
fn selections_text(plan: &NetworkPlan, out: &NetworkOutcome) -> String {
    let mut s = String::new();
    for sel in &out.selections {
        let certified = sel.choices.iter().filter(|c| c.robust_optimal).count();
        let changed = sel.choices.iter().filter(|c| c.robust != c.nominal).count();
        if plan.input.is_some() || !std::ptr::eq(sel, &out.selections[0]) {
            s += "\n";
        }
        s += &format!(
            "  select {} (ε = {}): {} observations, {certified} certified robust-optimal, {changed} where CARRL's action differs from the nominal one\n",
            sel.name,
            vector(&sel.epsilon),
            sel.choices.len()
        );
        let unbounded = sel
            .choices
            .iter()
            .filter(|c| c.lower.iter().all(|v| !v.is_finite()))
            .count();
        if unbounded > 0 {
            s += &format!(
                "  {unbounded} observations without finite bounds (time limit or overflow): no claim about them\n"
            );
        }
        for (k, (o, c)) in sel
            .observations
            .iter()
            .zip(&sel.choices)
            .enumerate()
            .take(20)
        {
            let bounds: Vec<String> = (0..c.lower.len())
                .map(|j| format!("{j}: {}", interval(c.lower[j], c.upper[j])))
                .collect();
            s += &format!(
                "  {k:>4}  {} = {}  nominal {}  robust {}{}\n        {}\n",
                plan.input_name,
                vector(o),
                c.nominal,
                c.robust,
                if c.robust_optimal {
                    " (certified optimal)"
                } else {
                    ""
                },
                bounds.join("  ")
            );
        }
        if sel.choices.len() > 20 {
            s += &format!(
                "  … {} more (see the JSON or CSV output)\n",
                sel.choices.len() - 20
            );
        }
    }
    s
}

/// The robust action selections as CSV rows (no header): one row per
/// observation and action.
pub fn csv_rows(spec_name: &str, out: &NetworkOutcome) -> String {
    let mut s = String::new();
    let name = spec_name.replace([',', '"', '\n', '\r'], "_");
    for sel in &out.selections {
        for (k, c) in sel.choices.iter().enumerate() {
            for j in 0..c.lower.len() {
                s += &format!(
                    "{name},{},{k},{j},{},{},{},{},{}\n",
                    sel.name,
                    num(c.lower[j]),
                    num(c.upper[j]),
                    u8::from(j == c.nominal),
                    u8::from(j == c.robust),
                    u8::from(c.robust_optimal)
                );
            }
        }
    }
    s
}

/// The header of [`csv_rows`].
pub const CSV_HEADER: &str =
    "spec,select,observation,action,lower,upper,nominal,robust,robust_optimal";

fn witness_text(plan: &NetworkPlan, w: &Witness) -> String {
    format!(
        "{} = {} gives {} = {}",
        plan.input_name,
        vector(&w.input),
        plan.output_name,
        vector(&w.output)
    )
}

/// A human-readable report of a network spec. `timing_ms` adds a timing line.
pub fn text(
    spec_name: &str,
    plan: &NetworkPlan,
    out: &NetworkOutcome,
    timing_ms: Option<f64>,
) -> String {
    let mut s = format!("ravel {}: {spec_name}\n", env!("CARGO_PKG_VERSION"));
    s += &format!(
        "  network     {} (input {}[{}], output {}[{}])\n",
        plan.name,
        plan.input_name,
        plan.net.inputs,
        plan.output_name,
        plan.net.outputs()
    );
    s += &format!(
        "  model       {} ({})\n",
        plan.model_path, plan.network_summary
    );
    if let Some(input) = &plan.input {
        s += &format!(
            "  input       {} = {}\n",
            plan.input_set_name,
            region_text(&plan.input_name, input)
        );
    }
    s += &format!(
        "  analysis    {}{}, {}, {} output shape, {} Monte Carlo samples (seed {})\n\n",
        plan.propagator.name(),
        super::slopes_text(plan.slope_steps),
        partition_text(&plan.partitioner, out.partition.len(), out.partition_stop),
        shape_text(&plan.shape),
        plan.samples,
        plan.seed
    );
    if plan.input.is_some() {
        s += &output_text(plan, out);
    }
    s += &selections_text(plan, out);
    if !out.properties.is_empty() {
        s += "\n  properties\n";
        let width = out
            .properties
            .iter()
            .map(|p| p.name.chars().count() + p.kind.as_str().len() + 1)
            .max()
            .unwrap_or(0);
        for p in &out.properties {
            let head = format!("{} {}", p.kind.as_str(), p.name);
            let what = match (p.status, &p.counterexample) {
                (Verdict::Falsified, Some(w)) => format!(
                    "{}violated by {}: {}",
                    p.label.map(|k| format!("label {k} ")).unwrap_or_default(),
                    num(-p.margin),
                    witness_text(plan, w)
                ),
                (Verdict::Verified, _) => match p.label {
                    Some(k) => {
                        format!("label {k} on the whole input set, margin {}", num(p.margin))
                    }
                    None => format!("holds on the whole input set, margin {}", num(p.margin)),
                },
                _ => match p.label {
                    Some(k) => format!("label {k} not proven, certified margin {}", num(p.margin)),
                    None => format!("not proven, certified margin {}", num(p.margin)),
                },
            };
            s += &format!("  {head:<width$}  {:<9}  {what}\n", p.status.as_str());
            if p.status != Verdict::Falsified && !p.label_margins.is_empty() {
                let list: Vec<String> = p
                    .label_margins
                    .iter()
                    .map(|(j, v)| format!("vs {j}: {}", num(*v)))
                    .collect();
                s += &format!("  {:width$}             {}\n", "", list.join(", "));
            }
            if let Some(x) = &p.real_only {
                s += &format!(
                    "  {:width$}             not falsified: {} = {} violates it in real arithmetic, but no {} input tried violates it as stored\n",
                    "",
                    plan.input_name,
                    vector(x),
                    plan.net.input_type.name()
                );
            }
        }
    }
    if !out.radii.is_empty() {
        s += "\n  radius searches (input set scaled about its centre by s)\n";
        for r in &out.radii {
            let cert = match r.certified {
                Some(c) if c >= r.max => format!("certified up to the maximum s = {}", num(c)),
                Some(c) => format!("certified for s ≤ {}", num(c)),
                None => "not certified even at the centre".to_string(),
            };
            let att = match &r.attacked {
                Some((g, w)) => format!("violated at s = {} ({})", num(*g), witness_text(plan, w)),
                None if r.certified.is_some_and(|c| c >= r.max) => String::new(),
                None => format!("no violation found up to s = {}", num(r.max)),
            };
            s += &format!("  radius {} for {}: {cert}", r.name, r.property);
            if !att.is_empty() {
                s += &format!("; {att}");
            }
            s += "\n";
            let rad: Vec<f64> = r
                .unit
                .iter()
                .map(|u| u * r.certified.unwrap_or(0.0))
                .collect();
            s += &format!(
                "    certified radius per input {} (tolerance {}, {} analyses)\n",
                vector(&rad),
                num(r.tolerance),
                r.analyses
            );
        }
    }
    s += &format!(
        "\n  verdict: {}{}\n",
        out.verdict.as_str(),
        if out.properties.is_empty() {
            " (no properties to check)"
        } else {
            ""
        }
    );
    if let Some(ms) = timing_ms {
        s += &format!(
            "  time: {ms:.3} ms ({} cell bounds, {} samples)\n",
            out.calls, out.samples_drawn
        );
    }
    s
}

fn witness_json(w: &Witness) -> Value {
    json!({ "input": w.input, "output": w.output })
}

/// The JSON result of a network spec (see `docs/json-schema.md`).
pub fn json(
    spec_name: &str,
    plan: &NetworkPlan,
    out: &NetworkOutcome,
    timing_ms: Option<f64>,
) -> Value {
    let props: Vec<Value> = out
        .properties
        .iter()
        .map(|p| {
            json!({
                "name": p.name,
                "kind": p.kind.as_str(),
                "status": p.status.as_str(),
                "margin": f(p.margin),
                "label": p.label,
                "label_margins": p.label_margins.iter().map(|(j, v)| json!({ "label": j, "margin": f(*v) })).collect::<Vec<_>>(),
                "counterexample": p.counterexample.as_ref().map(witness_json),
            })
        })
        .collect();
    let radii: Vec<Value> = out
        .radii
        .iter()
        .map(|r| {
            json!({
                "name": r.name,
                "property": r.property,
                "certified": r.certified.map(f),
                "attacked": r.attacked.as_ref().map(|(g, _)| f(*g)),
                "witness": r.attacked.as_ref().map(|(_, w)| witness_json(w)),
                "max": f(r.max),
                "tolerance": f(r.tolerance),
                "unit_radius": r.unit.iter().map(|v| f(*v)).collect::<Vec<_>>(),
                "analyses": r.analyses,
            })
        })
        .collect();
    let dirs = &out.output.directions;
    let facets: Vec<Value> = (0..dirs.nrows())
        .map(|k| {
            json!({
                "direction": dirs.row(k).iter().map(|v| f(*v)).collect::<Vec<_>>(),
                "offset": f(out.output.offsets[k]),
                "sampled": f(out.output.sampled[k]),
            })
        })
        .collect();
    let bx = |b: &IBox| json!({ "lo": b.lo.iter().map(|v| f(*v)).collect::<Vec<_>>(), "hi": b.hi.iter().map(|v| f(*v)).collect::<Vec<_>>() });
    let mut v = json!({
        "spec": spec_name,
        "kind": "network",
        "verdict": out.verdict.as_str(),
        "network": plan.name,
        "input": { "name": plan.input_name, "dim": plan.net.inputs, "set": plan.input.is_some().then(|| plan.input_set_name.clone()) },
        "output": { "name": plan.output_name, "dim": plan.net.outputs() },
        "model": { "path": plan.model_path, "resolved": plan.model_resolved, "sha256": plan.model_sha256, "network": plan.network_summary },
        "analysis": {
            "propagator": plan.propagator.name(),
            "partitioner": partitioner_name(&plan.partitioner),
            "partition": partition_grid(&plan.partitioner),
            "partition_stop": out.partition_stop.as_str(),
            "cells": out.partition.len(),
            "shape": shape_name(&plan.shape),
            "samples": plan.samples,
            "seed": plan.seed,
            "slope_steps": plan.slope_steps,
        },
        "output_set": {
            "facets": facets,
            "box": out.output.bbox.as_ref().map(bx),
            "sampled_box": out.output.sampled_bbox.as_ref().map(bx),
            "error": output_error(out).map(f),
        },
        "properties": props,
        "radii": radii,
        "cell_bounds": out.calls,
        "overflow": out.overflow,
        "solver_issues": out.solver_issues.iter().map(|i| json!({ "status": i.as_str() })).collect::<Vec<_>>(),
        "samples_drawn": out.samples_drawn,
        "selections": out.selections.iter().map(|sel| json!({
            "name": sel.name,
            "epsilon": sel.epsilon.iter().map(|v| f(*v)).collect::<Vec<_>>(),
            "choices": sel.observations.iter().zip(&sel.choices).map(|(o, c)| json!({
                "observation": o.iter().map(|v| f(*v)).collect::<Vec<_>>(),
                "lower": c.lower.iter().map(|v| f(*v)).collect::<Vec<_>>(),
                "upper": c.upper.iter().map(|v| f(*v)).collect::<Vec<_>>(),
                "nominal": c.nominal,
                "robust": c.robust,
                "robust_optimal": c.robust_optimal,
            })).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
    });
    if let Some(ms) = timing_ms {
        v["time_ms"] = json!(ms);
    }
    v
}
