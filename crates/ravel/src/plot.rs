//! Plots: one SVG per result, the reachable sets in a 2-D projection.
//!
//! Drawn (back to front): the avoid sets (red) and the goal (green), the
//! initial set (grey), every cell's set at every step (blue outlines; a
//! polytope set is drawn as its box) and the bounding box of each step
//! (dashed), the simulated trajectories (thin grey lines), and the
//! falsifying trajectory (red, with dots) when there is one. Goal and avoid
//! polytopes are drawn exactly when their inequalities involve only the two
//! plotted coordinates; an inequality that involves others is left out of
//! the drawing (the caption says so). Plain SVG written by hand: no
//! plotting library, no system dependency, the same bytes every run.

use crate::execute::{SystemOutcome, Trajectory};
use crate::lower::{PropertyKind, SystemPlan};
use ravel_analysis::sets::{IBox, Region};

/// Width and height of the drawing area in pixels.
const SIZE: f64 = 640.0;
/// Margin around it.
const PAD: f64 = 48.0;

/// A 2-D window `[x0, x1] × [y0, y1]` and its mapping to pixels.
struct View {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
}

impl View {
    fn px(&self, x: f64) -> f64 {
        PAD + (x - self.x0) / (self.x1 - self.x0) * SIZE
    }

    fn py(&self, y: f64) -> f64 {
        PAD + (self.y1 - y) / (self.y1 - self.y0) * SIZE
    }
}

/// A number for SVG attributes: two decimals, finite.
fn f(v: f64) -> String {
    if v.is_finite() {
        format!("{:.2}", v.clamp(-1e6, 1e6))
    } else {
        "0".to_string()
    }
}

fn xml(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .chars()
        .map(|c| if c.is_control() { '?' } else { c })
        .collect()
}

/// The polygon `{p ∈ window | aᵣ·p ≤ bᵣ}` (Sutherland–Hodgman clipping of
/// the window by each half-plane).
fn clip(window: &[(f64, f64)], rows: &[([f64; 2], f64)]) -> Vec<(f64, f64)> {
    let mut poly = window.to_vec();
    for (a, b) in rows {
        let inside = |p: &(f64, f64)| a[0] * p.0 + a[1] * p.1 <= *b;
        let mut out = Vec::new();
        for k in 0..poly.len() {
            let (p, q) = (poly[k], poly[(k + 1) % poly.len()]);
            let (ip, iq) = (inside(&p), inside(&q));
            if ip {
                out.push(p);
            }
            if ip != iq {
                let (fp, fq) = (a[0] * p.0 + a[1] * p.1 - b, a[0] * q.0 + a[1] * q.1 - b);
                let t = fp / (fp - fq);
                if t.is_finite() {
                    out.push((p.0 + t * (q.0 - p.0), p.1 + t * (q.1 - p.1)));
                }
            }
        }
        // points on the line are met twice: keep one
        out.dedup();
        if out.len() > 1 && out.first() == out.last() {
            out.pop();
        }
        poly = out;
        if poly.is_empty() {
            break;
        }
    }
    poly
}

/// The rows of a polytope that involve only coordinates `i` and `j`, and
/// whether any row was left out.
fn planar(rows: &[(Vec<f64>, f64)], i: usize, j: usize) -> (Vec<([f64; 2], f64)>, bool) {
    let mut out = Vec::new();
    let mut dropped = false;
    for (a, b) in rows {
        let others = a
            .iter()
            .enumerate()
            .any(|(k, v)| k != i && k != j && *v != 0.0);
        if others {
            dropped = true;
        } else {
            out.push(([a[i], a[j]], *b));
        }
    }
    (out, dropped)
}

fn rect(v: &View, b: &IBox, i: usize, j: usize, style: &str) -> String {
    let (x, y) = (v.px(b.lo[i]), v.py(b.hi[j]));
    let (w, h) = (v.px(b.hi[i]) - x, v.py(b.lo[j]) - y);
    format!(
        "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" {style}/>\n",
        f(x),
        f(y),
        f(w.max(0.5)),
        f(h.max(0.5))
    )
}

fn polygon(v: &View, pts: &[(f64, f64)], style: &str) -> String {
    let p: Vec<String> = pts
        .iter()
        .map(|(x, y)| format!("{},{}", f(v.px(*x)), f(v.py(*y))))
        .collect();
    format!("<polygon points=\"{}\" {style}/>\n", p.join(" "))
}

fn path(v: &View, tr: &Trajectory, i: usize, j: usize, style: &str) -> String {
    let p: Vec<String> = tr
        .states
        .iter()
        .take_while(|x| x.iter().all(|z| z.is_finite()))
        .map(|x| format!("{},{}", f(v.px(x[i])), f(v.py(x[j]))))
        .collect();
    format!(
        "<polyline points=\"{}\" fill=\"none\" {style}/>\n",
        p.join(" ")
    )
}

/// The SVG of one result, projected on coordinates `(i, j)`, with the
/// simulated trajectories `samples` (drawn thin).
pub fn svg(
    title: &str,
    plan: &SystemPlan,
    outcome: &SystemOutcome,
    dims: (usize, usize),
    samples: &[Trajectory],
) -> String {
    let (i, j) = dims;
    let v = window(plan, outcome, dims, samples);
    let total = SIZE + 2.0 * PAD;
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{t}\" height=\"{t}\" viewBox=\"0 0 {t} {t}\" font-family=\"sans-serif\" font-size=\"12\">\n<title>{}</title>\n<rect width=\"{t}\" height=\"{t}\" fill=\"white\"/>\n",
        xml(title),
        t = f(total)
    );
    s += "<g id=\"properties\">\n";
    let (properties, dropped_goal) = properties(&v, plan, dims);
    s += &properties;
    s += "</g>\n<g id=\"initial\">\n";
    let (initial, dropped_initial) = initial(&v, plan, dims);
    s += &initial;
    s += "</g>\n<g id=\"cells\">\n";
    for cell in &outcome.cells {
        for set in cell.iter().skip(1) {
            let b = set.bbox();
            if b.is_finite() {
                s += &rect(
                    &v,
                    &b,
                    i,
                    j,
                    "fill=\"none\" stroke=\"#1565c0\" stroke-width=\"0.6\"",
                );
            }
        }
    }
    s += "</g>\n<g id=\"reach\">\n";
    for b in outcome.reach.iter().skip(1) {
        if b.is_finite() {
            s += &rect(
                &v,
                b,
                i,
                j,
                "fill=\"none\" stroke=\"#0d47a1\" stroke-dasharray=\"4 3\"",
            );
        }
    }
    s += "</g>\n<g id=\"samples\">\n";
    for tr in samples {
        s += &path(&v, tr, i, j, "stroke=\"#757575\" stroke-width=\"0.4\"");
    }
    s += "</g>\n";
    if let Some(tr) = outcome
        .properties
        .iter()
        .find_map(|p| p.counterexample.as_ref())
    {
        s += &counterexample(&v, tr, dims);
    }
    s += &caption(
        &v,
        title,
        plan,
        outcome,
        dims,
        dropped_goal || dropped_initial,
    );
    s += "</svg>\n";
    s
}

/// The window: every finite set and state of the plotted coordinates
/// `(i, j)`, with a 5 % margin (`[-1, 1]²` when there is none).
fn window(
    plan: &SystemPlan,
    outcome: &SystemOutcome,
    (i, j): (usize, usize),
    samples: &[Trajectory],
) -> View {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    let mut grow = |x: f64, y: f64| {
        if x.is_finite() && y.is_finite() {
            lo = [lo[0].min(x), lo[1].min(y)];
            hi = [hi[0].max(x), hi[1].max(y)];
        }
    };
    for b in &outcome.reach {
        if b.is_finite() {
            grow(b.lo[i], b.lo[j]);
            grow(b.hi[i], b.hi[j]);
        }
    }
    for tr in samples {
        for x in &tr.states {
            grow(x[i], x[j]);
        }
    }
    let x0 = plan.initial.bbox();
    grow(x0.lo[i], x0.lo[j]);
    grow(x0.hi[i], x0.hi[j]);
    if !(lo[0].is_finite() && lo[1].is_finite()) {
        lo = [-1.0, -1.0];
        hi = [1.0, 1.0];
    }
    let span = |a: f64, b: f64| (b - a).max(1e-9);
    let (mx, my) = (0.05 * span(lo[0], hi[0]), 0.05 * span(lo[1], hi[1]));
    View {
        x0: lo[0] - mx,
        x1: hi[0] + mx,
        y0: lo[1] - my,
        y1: hi[1] + my,
    }
}

/// The goal (green) and avoid sets (red) clipped to the window, and
/// whether an inequality on other coordinates was left out.
fn properties(v: &View, plan: &SystemPlan, (i, j): (usize, usize)) -> (String, bool) {
    let window = [(v.x0, v.y0), (v.x1, v.y0), (v.x1, v.y1), (v.x0, v.y1)];
    let mut s = String::new();
    let mut dropped = false;
    for p in &plan.properties {
        let (members, style) = match &p.kind {
            PropertyKind::Goal { set, .. } => (
                vec![set],
                "fill=\"#2e7d32\" fill-opacity=\"0.15\" stroke=\"#2e7d32\"",
            ),
            PropertyKind::Avoid { members, .. } => (
                members.iter().collect(),
                "fill=\"#c62828\" fill-opacity=\"0.15\" stroke=\"#c62828\"",
            ),
        };
        for m in members {
            let (rows, d) = planar(&m.poly.rows, i, j);
            // nonlinear constraints are not drawn: the shape shown contains the set
            dropped |= d || !m.nonlinear.is_empty();
            let poly = clip(&window, &rows);
            if poly.len() >= 3 {
                s += &format!("<!-- {} -->\n", xml(&p.name));
                s += &polygon(v, &poly, style);
            }
        }
    }
    (s, dropped)
}

/// The initial set (grey): a polytope's planar rows clipped to its box,
/// else its box; and whether an inequality on other coordinates was left
/// out.
fn initial(v: &View, plan: &SystemPlan, (i, j): (usize, usize)) -> (String, bool) {
    let style = "fill=\"#9e9e9e\" fill-opacity=\"0.4\" stroke=\"#616161\"";
    match &plan.initial {
        Region::Polytope { bbox, rows } => {
            let (rows, dropped) = planar(rows, i, j);
            let b = [
                (bbox.lo[i], bbox.lo[j]),
                (bbox.hi[i], bbox.lo[j]),
                (bbox.hi[i], bbox.hi[j]),
                (bbox.lo[i], bbox.hi[j]),
            ];
            (polygon(v, &clip(&b, &rows), style), dropped)
        }
        _ => (rect(v, &plan.initial.bbox(), i, j, style), false),
    }
}

/// The falsifying trajectory's group (red, with a dot per finite state).
fn counterexample(v: &View, tr: &Trajectory, (i, j): (usize, usize)) -> String {
    let mut s = "<g id=\"counterexample\">\n".to_string();
    s += &path(v, tr, i, j, "stroke=\"#b71c1c\" stroke-width=\"2\"");
    for x in &tr.states {
        if x[i].is_finite() && x[j].is_finite() {
            s += &format!(
                "<circle cx=\"{}\" cy=\"{}\" r=\"3\" fill=\"#b71c1c\"/>\n",
                f(v.px(x[i])),
                f(v.py(x[j]))
            );
        }
    }
    s += "</g>\n";
    s
}

/// The frame, the axes' labels and the caption (the title, the verdict,
/// and a note when inequalities were left out of the drawing).
fn caption(
    v: &View,
    title: &str,
    plan: &SystemPlan,
    outcome: &SystemOutcome,
    (i, j): (usize, usize),
    dropped: bool,
) -> String {
    let total = SIZE + 2.0 * PAD;
    let mut s = format!(
        "<rect x=\"{p}\" y=\"{p}\" width=\"{w}\" height=\"{w}\" fill=\"none\" stroke=\"black\"/>\n",
        p = f(PAD),
        w = f(SIZE)
    );
    let name = &plan.state_name;
    s += &format!(
        "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}[{i}]: {} … {}</text>\n",
        f(PAD + SIZE / 2.0),
        f(total - 14.0),
        xml(name),
        f(v.x0),
        f(v.x1)
    );
    s += &format!(
        "<text x=\"14\" y=\"{}\" transform=\"rotate(-90 14 {})\" text-anchor=\"middle\">{}[{j}]: {} … {}</text>\n",
        f(PAD + SIZE / 2.0),
        f(PAD + SIZE / 2.0),
        xml(name),
        f(v.y0),
        f(v.y1)
    );
    let note = if dropped {
        " (goal/avoid inequalities on other coordinates not drawn)"
    } else {
        ""
    };
    s += &format!(
        "<text x=\"{}\" y=\"20\">{} — {}{}</text>\n",
        f(PAD),
        xml(title),
        outcome.verdict.as_str(),
        note
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clipping_a_square_by_a_diagonal_gives_a_triangle() {
        let sq = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)];
        let tri = clip(&sq, &[([1.0, 1.0], 1.0)]);
        assert_eq!(tri.len(), 3);
        assert!(clip(&sq, &[([1.0, 0.0], -1.0)]).is_empty());
    }
}
