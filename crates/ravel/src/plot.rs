//! Plots: one SVG per result, drawn with `plotters` (its SVG backend only:
//! no system fonts, the same bytes every run).
//!
//! A closed loop is one panel, two state coordinates `(i, j)`; a network
//! spec two: the input set over inputs 0 and 1, and the output set over
//! outputs `(i, j)`. Every panel has axes with ticks and their labels, and
//! the figure a title (the spec and its verdict) and a legend beside the
//! panels, which also holds the notes (what is not drawn, and why).
//!
//! What is drawn, back to front:
//! * goal (green) and avoid sets (red): filled where their inequalities
//!   involve only the plotted coordinates; a set that also constrains other
//!   coordinates is hatched with a dashed outline (its shadow on these axes
//!   is larger than the set), and the legend names those inequalities; a
//!   set constraining only other coordinates is not drawn but listed (its
//!   projection is the whole plane, which would look like every state were
//!   inside it). Sets that miss the view are listed as outside it;
//! * the initial set (grey) and its partition cells (thin black);
//! * every cell's set at every step, filled lightly in the colour of its
//!   step (a ramp from dark blue at step 1 to orange at the last step,
//!   shown in the legend), with the step's number at its bounding box;
//!   polytope and hull sets are polygons, balls ellipses or diamonds;
//! * for a plant in continuous time, behind the steps' sets, each cell's
//!   intersample enclosure (its states over the control period ending at
//!   a step, where the analysis enclosed it): very light, dashed, in that
//!   step's colour, with a legend entry;
//! * the bounding box of all cells of a step (dashed, in the step's colour)
//!   when it differs from the one cell's set;
//! * simulated trajectories (thin grey lines) and a falsifying trajectory
//!   (red, thick, with a dot per state).
//!
//! A network spec's radius search draws, on the input panel, the input set
//! scaled to the certified scale (green) and to the attacked one (red,
//! dashed) with the attack's input: the true radius lies between them.
//!
//! A set with more coordinates than two is drawn as a polygon that
//! contains its projection: each inequality with the other coordinates
//! replaced by their bounds over the set's box (exact for boxes, balls and
//! sets of two coordinates).

use crate::execute::network::NetworkOutcome;
use crate::execute::{SystemOutcome, Trajectory, Verdict};
use crate::ir::{NetPropertyKind, PropertyKind, StateSet};
use crate::lower::{NetworkPlan, SystemPlan};
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use ravel_analysis::sets::{IBox, Norm, Region};
use ravel_base::text::compact;

/// A point of a panel, in data coordinates.
type P = (f64, f64);

/// Pixels of one panel (square) and of the legend's width.
const PANEL: u32 = 600;
const LEGEND: u32 = 360;
const TITLE: u32 = 44;
const FONT: &str = "sans-serif";

const GREY: RGBColor = RGBColor(97, 97, 97);
const GOAL: RGBColor = RGBColor(46, 125, 50);
const AVOID: RGBColor = RGBColor(198, 40, 40);
const SAMPLE: RGBColor = RGBColor(117, 117, 117);
const CEX: RGBColor = RGBColor(183, 28, 28);

/// Step colours: dark blue → blue → purple → orange.
const RAMP: [(f64, f64, f64); 4] = [
    (8.0, 48.0, 107.0),
    (33.0, 113.0, 181.0),
    (128.0, 90.0, 190.0),
    (230.0, 97.0, 1.0),
];

/// The colour of step `t` of `1 ..= last`.
fn step_colour(t: usize, last: usize) -> RGBColor {
    let s = if last <= 1 {
        0.0
    } else {
        (t.saturating_sub(1)) as f64 / (last - 1) as f64
    };
    let x = s * (RAMP.len() - 1) as f64;
    let k = (x.floor() as usize).min(RAMP.len() - 2);
    let f = x - k as f64;
    let (a, b) = (RAMP[k], RAMP[k + 1]);
    let mix = |p: f64, q: f64| (p + (q - p) * f).round().clamp(0.0, 255.0) as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// How one shape is drawn.
#[derive(Clone)]
struct Style {
    fill: Option<RGBAColor>,
    stroke: Option<(RGBAColor, u32)>,
    dashed: bool,
    hatch: Option<RGBAColor>,
}

impl Style {
    fn filled(c: RGBColor, alpha: f64, width: u32) -> Style {
        Style {
            fill: Some(c.mix(alpha)),
            stroke: Some((c.to_rgba(), width)),
            dashed: false,
            hatch: None,
        }
    }

    fn outline(c: RGBColor, width: u32, dashed: bool) -> Style {
        Style {
            fill: None,
            stroke: Some((c.to_rgba(), width)),
            dashed,
            hatch: None,
        }
    }

    fn hatched(c: RGBColor) -> Style {
        Style {
            fill: None,
            stroke: Some((c.to_rgba(), 1)),
            dashed: true,
            hatch: Some(c.mix(0.55)),
        }
    }
}

/// One panel's content, in data coordinates.
struct Panel {
    x_desc: String,
    y_desc: String,
    window: [f64; 4],
    shapes: Vec<(Vec<P>, Style)>,
    lines: Vec<(Vec<P>, RGBAColor, u32)>,
    dots: Vec<(P, RGBAColor, u32)>,
    labels: Vec<(P, String, RGBColor)>,
}

impl Panel {
    fn new(x_desc: String, y_desc: String, window: [f64; 4]) -> Panel {
        Panel {
            x_desc,
            y_desc,
            window,
            shapes: Vec::new(),
            lines: Vec::new(),
            dots: Vec::new(),
            labels: Vec::new(),
        }
    }

    fn rect(&self) -> Vec<P> {
        let [x0, x1, y0, y1] = self.window;
        vec![(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    }

    /// A polygon clipped to the window (nothing when it misses it).
    fn shape(&mut self, pts: &[P], style: Style) -> bool {
        let clipped = clip_convex(pts, &self.rect());
        if clipped.len() < 2 {
            return false;
        }
        self.shapes.push((clipped, style));
        true
    }

    /// The half-planes `rows` clipped to the window.
    fn region(&mut self, rows: &[([f64; 2], f64)], style: Style) -> bool {
        let poly = clip(&self.rect(), rows);
        if poly.len() < 3 {
            return false;
        }
        self.shapes.push((poly, style));
        true
    }
}

/// What a legend entry shows.
enum Swatch {
    Fill(RGBColor),
    Outline(RGBColor, bool),
    Hatch(RGBColor),
    Line(RGBColor, u32),
    Dot(RGBColor),
    /// The step ramp, steps `1 ..= last`.
    Ramp(usize),
    /// A light fill with a dashed outline (an intersample enclosure).
    Light(RGBColor),
}

#[derive(Default)]
struct Legend {
    entries: Vec<(Swatch, String)>,
    notes: Vec<String>,
}

/// A tick label on an axis spanning `span`: as many decimals as the ticks'
/// spacing needs (about `span / 8`), a rounding error at 0 written `0`.
fn tick(v: f64, span: f64) -> String {
    if !v.is_finite() || !span.is_finite() || span <= 0.0 {
        return compact(v);
    }
    if v.abs() <= span * 1e-9 {
        return "0".into();
    }
    let step = span / 8.0;
    if v.abs() >= 1e6 || step < 1e-6 {
        return compact(v);
    }
    let d = (1.0 - step.log10().floor()).clamp(0.0, 9.0) as usize;
    let s = format!("{v:.d$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// A number for tick labels and notes: short, no trailing zeros.
fn num(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if (1e-3..1e5).contains(&a) {
        let digits = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
        let s = format!("{v:.digits$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        compact(v)
    }
}

/// Sutherland–Hodgman: the polygon `window` cut by each half-plane
/// `a·p ≤ b` (the window convex, or any polygon).
fn clip(window: &[P], rows: &[([f64; 2], f64)]) -> Vec<P> {
    let mut poly = window.to_vec();
    for (a, b) in rows {
        // a row that says nothing; one that no point meets
        if !(a[0].is_finite() && a[1].is_finite()) || b.is_nan() || *b == f64::INFINITY {
            continue;
        }
        if *b == f64::NEG_INFINITY {
            return Vec::new();
        }
        let val = |p: &P| a[0] * p.0 + a[1] * p.1 - b;
        let mut out = Vec::new();
        for k in 0..poly.len() {
            let (p, q) = (poly[k], poly[(k + 1) % poly.len()]);
            let (fp, fq) = (val(&p), val(&q));
            if fp <= 0.0 {
                out.push(p);
            }
            if (fp <= 0.0) != (fq <= 0.0) {
                // from the end inside, so that a far-off end costs no precision
                let (a, b, fa, fb) = if fp <= 0.0 {
                    (p, q, fp, fq)
                } else {
                    (q, p, fq, fp)
                };
                let t = fa / (fa - fb);
                if t.is_finite() {
                    out.push((a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1)));
                }
            }
        }
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

/// A convex polygon clipped to a convex window (its edges as half-planes).
fn clip_convex(pts: &[P], window: &[P]) -> Vec<P> {
    let rows: Vec<([f64; 2], f64)> = (0..window.len())
        .map(|k| {
            let (p, q) = (window[k], window[(k + 1) % window.len()]);
            // counter-clockwise window: inside is on the left of p → q
            let a = [q.1 - p.1, p.0 - q.0];
            (a, a[0] * p.0 + a[1] * p.1)
        })
        .collect();
    clip(pts, &rows)
}

/// The segment `p → q` inside the convex polygon `poly` (Cyrus–Beck).
fn clip_segment(p: P, q: P, poly: &[P]) -> Option<(P, P)> {
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    let n = poly.len();
    // orientation of the polygon
    let area: f64 = (0..n)
        .map(|k| {
            let (a, b) = (poly[k], poly[(k + 1) % n]);
            a.0 * b.1 - b.0 * a.1
        })
        .sum();
    let s = if area >= 0.0 { 1.0 } else { -1.0 };
    for k in 0..n {
        let (a, b) = (poly[k], poly[(k + 1) % n]);
        // inside: s·cross(b − a, x − a) ≥ 0
        let e = (b.0 - a.0, b.1 - a.1);
        let at = |x: P| s * (e.0 * (x.1 - a.1) - e.1 * (x.0 - a.0));
        let (fp, fq) = (at(p), at(q));
        if fp < 0.0 && fq < 0.0 {
            return None;
        }
        if fp < 0.0 || fq < 0.0 {
            let t = fp / (fp - fq);
            if fp < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
        }
    }
    (t0 < t1).then(|| {
        let at = |t: f64| (p.0 + t * (q.0 - p.0), p.1 + t * (q.1 - p.1));
        (at(t0), at(t1))
    })
}

/// `min` of `Σ_{k ∉ {i, j}} a_k x_k` over the box (`−∞` when unbounded).
fn hidden_min(a: &[f64], b: &IBox, (i, j): (usize, usize)) -> f64 {
    let mut s = 0.0;
    for (k, &c) in a.iter().enumerate() {
        if k == i || k == j || c == 0.0 {
            continue;
        }
        let (lo, hi) = (b.lo.get(k).copied(), b.hi.get(k).copied());
        let (Some(lo), Some(hi)) = (lo, hi) else {
            return f64::NEG_INFINITY;
        };
        s += if c > 0.0 { c * lo } else { c * hi };
    }
    if s.is_nan() {
        f64::NEG_INFINITY
    } else {
        s
    }
}

/// A polygon containing the projection of `{x ∈ bbox | a·x ≤ b}` onto
/// `(i, j)`: the box's rectangle cut by each row, its other coordinates
/// replaced by their smallest value over the box.
fn shadow(bbox: &IBox, rows: &[(Vec<f64>, f64)], (i, j): (usize, usize)) -> Vec<P> {
    let rect = vec![
        (bbox.lo[i], bbox.lo[j]),
        (bbox.hi[i], bbox.lo[j]),
        (bbox.hi[i], bbox.hi[j]),
        (bbox.lo[i], bbox.hi[j]),
    ];
    let planar: Vec<([f64; 2], f64)> = rows
        .iter()
        .map(|(a, b)| {
            let c = |k: usize| a.get(k).copied().unwrap_or(0.0);
            ([c(i), c(j)], b - hidden_min(a, bbox, (i, j)))
        })
        .collect();
    clip(&rect, &planar)
}

/// A polygon containing the projection of a region onto `(i, j)`; `None`
/// when its box is not finite there.
fn project(r: &Region, (i, j): (usize, usize)) -> Option<Vec<P>> {
    let b = r.bbox_ref();
    let finite = [b.lo[i], b.hi[i], b.lo[j], b.hi[j]]
        .iter()
        .all(|v| v.is_finite());
    if !finite {
        return None;
    }
    Some(match r {
        Region::Box(b) => shadow(b, &[], (i, j)),
        Region::Polytope { bbox, rows } => shadow(bbox, rows, (i, j)),
        Region::Ball {
            center,
            radius,
            norm,
        } => {
            let (cx, cy, rx, ry) = (center[i], center[j], radius[i], radius[j]);
            match norm {
                Norm::LInf => shadow(&b, &[], (i, j)),
                Norm::L1 => vec![(cx + rx, cy), (cx, cy + ry), (cx - rx, cy), (cx, cy - ry)],
                Norm::L2 => {
                    // a circumscribed 48-gon (it contains the ellipse)
                    let n = 48;
                    let grow = 1.0 / (std::f64::consts::PI / n as f64).cos();
                    (0..n)
                        .map(|k| {
                            let t = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
                            (cx + grow * rx * t.cos(), cy + grow * ry * t.sin())
                        })
                        .collect()
                }
            }
        }
    })
}

fn bounds_of(pts: &[P]) -> Option<[f64; 4]> {
    let mut w = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    for p in pts {
        // beyond 1e150 a window says nothing: such points are clipped
        if p.0.abs() <= 1e150 && p.1.abs() <= 1e150 {
            w = [w[0].min(p.0), w[1].max(p.0), w[2].min(p.1), w[3].max(p.1)];
        }
    }
    (w[0] <= w[1] && w[2] <= w[3]).then_some(w)
}

/// The window around these points with a 5 % margin (`[-1, 1]²` when
/// there are none).
fn window_of(pts: &[P]) -> [f64; 4] {
    let [x0, x1, y0, y1] = bounds_of(pts).unwrap_or([-1.0, 1.0, -1.0, 1.0]);
    let margin = |a: f64, b: f64| {
        let s = b - a;
        if s > 1e-9 * (1.0 + a.abs().max(b.abs())) {
            0.05 * s
        } else {
            0.5 * (1.0 + a.abs().max(b.abs())) * 1e-3
        }
    };
    let (mx, my) = (margin(x0, x1), margin(y0, y1));
    [x0 - mx, x1 + mx, y0 - my, y1 + my]
}

/// An inequality `Σ a_k v[k] ≤ b` as text (`≥` when every coefficient is
/// negative; positive terms first).
fn row_text(a: &[f64], b: f64, name: &str) -> String {
    let flip = a.iter().all(|c| *c <= 0.0);
    let s = if flip { -1.0 } else { 1.0 };
    let mut t = String::new();
    let mut order: Vec<(usize, f64)> = a.iter().copied().enumerate().collect();
    order.sort_by_key(|(_, c)| s * c < 0.0);
    for (k, c) in order {
        let c = s * c;
        if c == 0.0 {
            continue;
        }
        let sign = if c < 0.0 { "-" } else { "+" };
        if t.is_empty() {
            if c < 0.0 {
                t.push('-');
            }
        } else {
            t += &format!(" {sign} ");
        }
        if c.abs() != 1.0 {
            t += &format!("{} ", num(c.abs()));
        }
        t += &format!("{name}[{k}]");
    }
    if t.is_empty() {
        t.push('0');
    }
    format!("{t} {} {}", if flip { ">=" } else { "<=" }, num(s * b))
}

/// A set of linear rows (and possibly nonlinear constraints) on the panel:
/// drawn filled, hatched, or not at all, with the legend's notes.
#[allow(clippy::too_many_arguments)]
fn draw_set(
    panel: &mut Panel,
    legend: &mut Legend,
    label: &str,
    rows: &[(Vec<f64>, f64)],
    nonlinear: bool,
    colour: RGBColor,
    var: &str,
    (i, j): (usize, usize),
) -> bool {
    let mut planar = Vec::new();
    let mut hidden = Vec::new();
    for (a, b) in rows {
        let other = a
            .iter()
            .enumerate()
            .any(|(k, c)| k != i && k != j && *c != 0.0);
        if other {
            hidden.push(row_text(a, *b, var));
        } else {
            let c = |k: usize| a.get(k).copied().unwrap_or(0.0);
            planar.push(([c(i), c(j)], *b));
        }
    }
    let shown = |h: &[String]| {
        let mut s = h.iter().take(3).cloned().collect::<Vec<_>>().join(", ");
        if h.len() > 3 {
            s += &format!(" and {} more", h.len() - 3);
        }
        s
    };
    if planar.is_empty() {
        let why = if hidden.is_empty() {
            "a nonlinear constraint, not drawn".to_string()
        } else {
            format!(
                "constrains only coordinates not shown ({}), not drawn",
                shown(&hidden)
            )
        };
        legend.notes.push(format!("{label}: {why}"));
        return false;
    }
    let exact = hidden.is_empty() && !nonlinear;
    let style = if exact {
        Style::filled(colour, 0.15, 1)
    } else {
        Style::hatched(colour)
    };
    let drawn = panel.region(&planar, style);
    if !drawn {
        legend.notes.push(format!("{label}: outside the view"));
    }
    if !hidden.is_empty() {
        legend
            .notes
            .push(format!("{label}: also constrains {}", shown(&hidden)));
    }
    if nonlinear {
        legend.notes.push(format!(
            "{label}: its nonlinear constraint is not drawn (the shape contains the set)"
        ));
    }
    let swatch = if exact {
        Swatch::Fill(colour)
    } else {
        Swatch::Hatch(colour)
    };
    legend.entries.push((swatch, label.to_string()));
    drawn
}

/// The intersample enclosures of a plant in continuous time (the states of
/// each cell over the control period ending at step `t`, as the analysis
/// enclosed them for its properties): drawn lightly, dashed, in the colour
/// of the period's last step, with a legend entry; periods that could not
/// be enclosed are noted. Nothing for plants without them.
fn intersample(
    panel: &mut Panel,
    legend: &mut Legend,
    outcome: &SystemOutcome,
    (i, j): (usize, usize),
) {
    let last = outcome.reach.len().saturating_sub(1);
    let (mut drawn, mut skipped, mut whole) = (0, 0, None);
    for t in 1..=last {
        let colour = step_colour(t, last);
        let mut any = false;
        for b in outcome.between.iter().filter_map(|c| c.get(t)?.as_ref()) {
            any = true;
            let finite = [b.lo[i], b.hi[i], b.lo[j], b.hi[j]]
                .iter()
                .all(|v| v.is_finite() && v.abs() <= 1e150);
            if !finite {
                whole.get_or_insert(t);
                continue;
            }
            panel.shape(&shadow(b, &[], (i, j)), light(colour));
            drawn += 1;
        }
        if !any {
            skipped += 1;
        }
    }
    if drawn > 0 {
        let which = if skipped > 0 {
            " (the periods a property's window covers)"
        } else {
            ""
        };
        legend.entries.push((
            Swatch::Light(step_colour(last, last)),
            format!("states between the sampling instants: each cell's enclosure over a control period{which}, in its last step's colour"),
        ));
    }
    if let Some(t) = whole {
        legend.notes.push(format!(
            "the period ending at step {t} has no finite enclosure: not drawn"
        ));
    }
}

/// The lighter, dashed style of an intersample enclosure.
fn light(c: RGBColor) -> Style {
    Style {
        fill: Some(c.mix(0.04)),
        stroke: Some((c.mix(0.5), 1)),
        dashed: true,
        hatch: None,
    }
}

/// A trajectory's states on coordinates `(i, j)`, up to its first
/// non-finite state.
fn trace(tr: &Trajectory, (i, j): (usize, usize)) -> Vec<P> {
    tr.states
        .iter()
        .take_while(|x| x.iter().all(|z| z.is_finite()))
        .map(|x| (x[i], x[j]))
        .collect()
}

/// The set an analysis starts from (a closed loop's initial set, a
/// network's input set), filled grey at `alpha`, and the cells it was
/// partitioned into, outlined in black when there are several, each with
/// its legend entry.
fn start(
    (panel, legend): (&mut Panel, &mut Legend),
    (set, alpha, label): (&Region, f64, String),
    (cells, cells_word): (&[IBox], &str),
    d: (usize, usize),
) {
    if let Some(poly) = project(set, d) {
        panel.shape(&poly, Style::filled(GREY, alpha, 1));
        legend.entries.push((Swatch::Fill(GREY), label));
    }
    if cells.len() > 1 {
        for c in cells {
            if let Some(p) = project(&Region::Box(c.clone()), d) {
                panel.shape(&p, Style::outline(BLACK, 1, false));
            }
        }
        legend.entries.push((
            Swatch::Outline(BLACK, false),
            format!("{} {cells_word}", cells.len()),
        ));
    }
}

fn verdict_word(v: Verdict) -> &'static str {
    v.as_str()
}

/// The SVG of one closed-loop result, projected on state coordinates
/// `(i, j)`, with the simulated trajectories `samples` (drawn thin).
pub fn svg(
    title: &str,
    plan: &SystemPlan,
    outcome: &SystemOutcome,
    dims: (usize, usize),
    samples: &[Trajectory],
) -> Result<String, String> {
    let (i, j) = dims;
    let n = plan.closed_loop.states();
    if i >= n || j >= n || i == j {
        return Err(format!(
            "--plot-dims {i},{j}: the state has {n} coordinates (0 to {})",
            n.saturating_sub(1)
        ));
    }
    let name = &plan.state_name;
    let cex = outcome
        .properties
        .iter()
        .find_map(|p| p.counterexample.as_ref().map(|c| (p, c)));
    // the window: reachable sets, samples, X0, the counterexample
    let mut pts: Vec<P> = Vec::new();
    for b in &outcome.reach {
        if b.is_finite() {
            pts.push((b.lo[i], b.lo[j]));
            pts.push((b.hi[i], b.hi[j]));
        }
    }
    for tr in samples.iter().chain(cex.map(|c| c.1)) {
        pts.extend(tr.states.iter().map(|x| (x[i], x[j])));
    }
    for b in outcome.between.iter().flatten().flatten() {
        if b.is_finite() {
            pts.push((b.lo[i], b.lo[j]));
            pts.push((b.hi[i], b.hi[j]));
        }
    }
    let x0 = plan.initial.bbox();
    pts.push((x0.lo[i], x0.lo[j]));
    pts.push((x0.hi[i], x0.hi[j]));
    let window = window_of(&pts);
    let mut panel = Panel::new(format!("{name}[{i}]"), format!("{name}[{j}]"), window);
    let mut legend = Legend::default();

    // goal and avoid sets
    for (p, r) in plan.properties.iter().zip(&outcome.properties) {
        let status = verdict_word(r.status);
        let (members, colour, kind): (Vec<&StateSet>, _, _) = match &p.kind {
            PropertyKind::Goal { set, .. } => (vec![set], GOAL, "goal"),
            PropertyKind::Avoid { members, .. } => (members.iter().collect(), AVOID, "avoid"),
        };
        let many = members.len() > 1;
        for (k, m) in members.iter().enumerate() {
            let label = if many {
                format!("{kind} {} (part {}): {status}", p.name, k + 1)
            } else {
                format!("{kind} {}: {status}", p.name)
            };
            draw_set(
                &mut panel,
                &mut legend,
                &label,
                &m.poly.rows,
                !m.nonlinear.is_empty(),
                colour,
                name,
                dims,
            );
        }
    }

    // the initial set and its partition
    start(
        (&mut panel, &mut legend),
        (
            &plan.initial,
            0.35,
            format!("initial set {} (step 0)", plan.initial_name),
        ),
        (&outcome.partition, "partition cells"),
        dims,
    );

    // the reachable sets, step by step, each period's enclosure behind them
    let last = outcome.reach.len().saturating_sub(1);
    intersample(&mut panel, &mut legend, outcome, dims);
    let mut not_finite = Vec::new();
    let every = last.div_ceil(12).max(1);
    let mut boxes = false;
    for t in 1..=last {
        let colour = step_colour(t, last);
        let mut single: Option<Vec<P>> = None;
        for cell in &outcome.cells {
            let Some(set) = cell.get(t) else { continue };
            match project(set, dims) {
                Some(poly) => {
                    panel.shape(
                        &poly,
                        Style {
                            fill: Some(colour.mix(0.10)),
                            stroke: Some((colour.to_rgba(), 1)),
                            dashed: false,
                            hatch: None,
                        },
                    );
                    single = Some(poly);
                }
                None => not_finite.push(t),
            }
        }
        let reach = &outcome.reach[t];
        if !reach.is_finite() {
            continue;
        }
        let rect = shadow(reach, &[], dims);
        let same = outcome.cells.len() == 1
            && single
                .as_ref()
                .is_some_and(|s| bounds_of(s) == bounds_of(&rect));
        if !same {
            panel.shape(&rect, Style::outline(colour, 1, true));
            boxes = true;
        }
        if t % every == 0 || t == last {
            panel
                .labels
                .push(((reach.hi[i], reach.hi[j]), format!("{t}"), colour));
        }
    }
    not_finite.dedup();
    let far = outcome.reach.iter().skip(1).position(|b| {
        b.is_finite()
            && [b.lo[i], b.hi[i], b.lo[j], b.hi[j]]
                .iter()
                .any(|v| v.abs() > 1e150)
    });
    if let Some(k) = far {
        legend.notes.push(format!(
            "from step {} on, sets reach beyond 1e150: outside the view",
            k + 1
        ));
    }
    if last >= 1 {
        legend.entries.push((
            Swatch::Ramp(last),
            format!(
                "reachable set per step (cells{}), step number at its corner",
                if plan.boundary == ravel_analysis::closed_loop::Boundary::Box {
                    ""
                } else {
                    ": polygons"
                }
            ),
        ));
        if boxes {
            legend.entries.push((
                Swatch::Outline(step_colour(last, last), true),
                "bounding box of a step's sets".into(),
            ));
        }
    }
    if let Some(&t) = not_finite.first() {
        legend.notes.push(format!(
            "from step {t} on, some sets are the whole space (bounds overflowed or time ran out): not drawn"
        ));
    }

    // trajectories
    for tr in samples {
        panel.lines.push((trace(tr, dims), SAMPLE.mix(0.45), 1));
    }
    if !samples.is_empty() {
        legend.entries.push((
            Swatch::Line(SAMPLE, 1),
            format!("{} simulated trajectories", samples.len()),
        ));
    }
    if let Some((p, tr)) = cex {
        let pts = trace(tr, dims);
        for q in &pts {
            panel.dots.push((*q, CEX.to_rgba(), 3));
        }
        panel.lines.push((pts, CEX.to_rgba(), 2));
        legend.entries.push((
            Swatch::Line(CEX, 2),
            format!("counterexample of {} {}", p.kind.as_str(), p.name),
        ));
    }
    if n > 2 {
        legend.notes.push(
            "sets of more than two coordinates: a polygon containing their projection".into(),
        );
    }
    render(
        &format!("{title} — {}", verdict_word(outcome.verdict)),
        &[panel],
        &legend,
    )
}

/// Inputs sampled for a network plot (deterministic: the spec's seed).
fn net_samples(plan: &NetworkPlan, count: usize) -> Vec<(Vec<f64>, Vec<f64>)> {
    let Some(input) = &plan.input else {
        return Vec::new();
    };
    let mut rng = ravel_base::rng::Rng::new(plan.seed ^ 0x706c_6f74);
    let mut out = Vec::new();
    for _ in 0..count {
        if let Some(x) = input.sample(&mut || rng.unit()) {
            let y = plan.net.forward(&x);
            if y.iter().all(|v| v.is_finite()) {
                out.push((x, y));
            }
        }
    }
    out
}

/// The input set scaled about its centre by `s` (a radius search's scale:
/// radius `s·unit` along each input); `None` for a polytope, which a radius
/// search does not take.
fn scaled(input: &Region, unit: &[f64], s: f64) -> Option<Region> {
    let radius: Vec<f64> = unit.iter().map(|u| s * u).collect();
    match input {
        Region::Box(b) => {
            let c: Vec<f64> = b.lo.iter().zip(&b.hi).map(|(l, h)| 0.5 * (l + h)).collect();
            Some(Region::Box(IBox::new(
                c.iter().zip(&radius).map(|(c, r)| c - r).collect(),
                c.iter().zip(&radius).map(|(c, r)| c + r).collect(),
            )))
        }
        Region::Ball { center, norm, .. } => Some(Region::Ball {
            center: center.clone(),
            radius,
            norm: *norm,
        }),
        Region::Polytope { .. } => None,
    }
}

/// A radius search on the input panel: the input set scaled to the largest
/// certified scale (green, solid) and to the smallest attacked one (red,
/// dashed), with the attack's input as a red dot: the true radius lies
/// between the two outlines.
fn radius_searches(
    panel: &mut Panel,
    legend: &mut Legend,
    input: &Region,
    outcome: &NetworkOutcome,
    d: (usize, usize),
) {
    for r in &outcome.radii {
        let radius = |s: f64| {
            let v: Vec<String> = r.unit.iter().take(2).map(|u| num(s * u)).collect();
            v.join(", ")
        };
        match r.certified {
            Some(s) => {
                if let Some(p) = scaled(input, &r.unit, s).and_then(|g| project(&g, d)) {
                    panel.shape(&p, Style::outline(GOAL, 2, false));
                }
                legend.entries.push((
                    Swatch::Line(GOAL, 2),
                    format!(
                        "radius {} for {}: certified up to scale {} (radius {} on inputs 0, 1)",
                        r.name,
                        r.property,
                        num(s),
                        radius(s)
                    ),
                ));
            }
            None => legend.notes.push(format!(
                "radius {} for {}: not certified even at the centre",
                r.name, r.property
            )),
        }
        match &r.attacked {
            Some((s, w)) => {
                if let Some(p) = scaled(input, &r.unit, *s).and_then(|g| project(&g, d)) {
                    panel.shape(&p, Style::outline(AVOID, 1, true));
                }
                panel
                    .dots
                    .push(((w.input[0], w.input[1]), CEX.to_rgba(), 4));
                legend.entries.push((
                    Swatch::Outline(AVOID, true),
                    format!(
                        "radius {}: violated at scale {} (radius {}), by the input at the red dot",
                        r.name,
                        num(*s),
                        radius(*s)
                    ),
                ));
            }
            None => legend.notes.push(format!(
                "radius {}: no violation found up to scale {}",
                r.name,
                num(r.max)
            )),
        }
    }
}

/// The SVG of one network-spec result: the input set over inputs 0 and 1
/// (with the partition, sampled inputs and a counterexample), and the
/// output set over outputs `(i, j)` with the properties' sets.
pub fn network_svg(
    title: &str,
    plan: &NetworkPlan,
    outcome: &NetworkOutcome,
    dims: (usize, usize),
) -> Result<String, String> {
    let (i, j) = dims;
    let m = plan.net.outputs();
    if m >= 2 && (i >= m || j >= m || i == j) {
        return Err(format!(
            "--plot-dims {i},{j}: a network spec's plot shows two outputs, and the output has {m} coordinate{} (0 to {})",
            if m == 1 { "" } else { "s" },
            m.saturating_sub(1)
        ));
    }
    let (xn, yn) = (&plan.input_name, &plan.output_name);
    let samples = net_samples(plan, 400);
    let mut legend = Legend::default();
    let cex = outcome
        .properties
        .iter()
        .find_map(|p| p.counterexample.as_ref().map(|c| (p, c)));
    let mut panels = Vec::new();

    // the input panel
    let inputs = plan.net.inputs;
    if inputs >= 2 {
        let d = (0, 1);
        let mut pts: Vec<P> = samples.iter().map(|(x, _)| (x[0], x[1])).collect();
        if let Some(r) = &plan.input {
            pts.extend(project(r, d).unwrap_or_default());
        }
        for s in &plan.selects {
            for o in &s.observations {
                pts.push((o[0] - s.epsilon[0], o[1] - s.epsilon[1]));
                pts.push((o[0] + s.epsilon[0], o[1] + s.epsilon[1]));
            }
        }
        if let Some((_, w)) = cex {
            pts.push((w.input[0], w.input[1]));
        }
        for r in &outcome.radii {
            let scales = r
                .certified
                .into_iter()
                .chain(r.attacked.as_ref().map(|a| a.0));
            for s in scales {
                if let Some(region) = plan.input.as_ref().and_then(|i| scaled(i, &r.unit, s)) {
                    pts.extend(project(&region, d).unwrap_or_default());
                }
            }
            if let Some((_, w)) = &r.attacked {
                pts.push((w.input[0], w.input[1]));
            }
        }
        let mut panel = Panel::new(format!("{xn}[0]"), format!("{xn}[1]"), window_of(&pts));
        if let Some(r) = &plan.input {
            start(
                (&mut panel, &mut legend),
                (r, 0.3, format!("input set {} (left)", plan.input_set_name)),
                (&outcome.partition, "input cells"),
                d,
            );
        }
        for (x, _) in &samples {
            panel.dots.push(((x[0], x[1]), SAMPLE.mix(0.8), 2));
        }
        for (k, s) in plan.selects.iter().enumerate() {
            let colour = step_colour(k + 1, plan.selects.len().max(2));
            for o in s.observations.iter().take(200) {
                let ball = Region::Ball {
                    center: o.clone(),
                    radius: s.epsilon.clone(),
                    norm: s.norm,
                };
                if let Some(p) = project(&ball, d) {
                    panel.shape(&p, Style::outline(colour, 1, false));
                }
            }
            legend.entries.push((
                Swatch::Outline(colour, false),
                format!(
                    "select {}: {} observations' balls (left), their certified output boxes (right)",
                    s.name,
                    s.observations.len()
                ),
            ));
            if s.observations.len() > 200 {
                legend.notes.push(format!(
                    "select {}: the first 200 observations drawn",
                    s.name
                ));
            }
        }
        if let Some((_, w)) = cex {
            panel
                .dots
                .push(((w.input[0], w.input[1]), CEX.to_rgba(), 4));
        }
        if let Some(input) = &plan.input {
            radius_searches(&mut panel, &mut legend, input, outcome, d);
        }
        if inputs > 2 {
            legend
                .notes
                .push(format!("the input has {inputs} coordinates: 0 and 1 shown"));
        }
        panels.push(panel);
    } else {
        legend.notes.push("one input: no input panel".to_string());
    }

    if m < 2 {
        panels.push(one_output(plan, outcome, &samples, &mut legend));
        return render(
            &format!("{title} — {}", verdict_word(outcome.verdict)),
            &panels,
            &legend,
        );
    }

    // the output panel
    let bounds = &outcome.output;
    let rows: Vec<(Vec<f64>, f64)> = (0..bounds.directions.nrows())
        .map(|r| {
            (
                bounds.directions.row(r).iter().copied().collect(),
                bounds.offsets.get(r).copied().unwrap_or(f64::INFINITY),
            )
        })
        .collect();
    let bbox = bounds.bbox.clone().unwrap_or_else(|| IBox::whole(m));
    // the output polygon over the directions' plotted parts
    let finite = [bbox.lo[i], bbox.hi[i], bbox.lo[j], bbox.hi[j]]
        .iter()
        .all(|v| v.is_finite());
    let out_poly = if finite {
        Some(shadow(&bbox, &rows, dims))
    } else if !rows.is_empty() {
        // no box: the rows of the plotted outputs alone
        let planar: Vec<([f64; 2], f64)> = rows
            .iter()
            .filter(|(a, _)| {
                a.iter()
                    .enumerate()
                    .all(|(k, c)| k == i || k == j || *c == 0.0)
            })
            .map(|(a, b)| ([a[i], a[j]], *b))
            .collect();
        let big = 1e6;
        let p = clip(
            &[(-big, -big), (big, -big), (big, big), (-big, big)],
            &planar,
        );
        (p.len() >= 3 && p.iter().all(|q| q.0.abs() < big && q.1.abs() < big)).then_some(p)
    } else {
        None
    };
    let mut pts: Vec<P> = samples.iter().map(|(_, y)| (y[i], y[j])).collect();
    pts.extend(out_poly.iter().flatten().copied());
    if let Some((_, w)) = cex {
        pts.push((w.output[i], w.output[j]));
    }
    for s in &outcome.selections {
        for c in s.choices.iter().take(200) {
            for v in [(c.lower[i], c.lower[j]), (c.upper[i], c.upper[j])] {
                pts.push(v);
            }
        }
    }
    let mut panel = Panel::new(format!("{yn}[{i}]"), format!("{yn}[{j}]"), window_of(&pts));
    for (p, r) in plan.properties.iter().zip(&outcome.properties) {
        let status = verdict_word(r.status);
        match &p.kind {
            NetPropertyKind::Require(poly) => {
                draw_set(
                    &mut panel,
                    &mut legend,
                    &format!("require {}: {status}", p.name),
                    &poly.rows,
                    false,
                    GOAL,
                    yn,
                    dims,
                );
            }
            NetPropertyKind::Avoid(members) => {
                let many = members.len() > 1;
                for (k, poly) in members.iter().enumerate() {
                    let label = if many {
                        format!("avoid {} (part {}): {status}", p.name, k + 1)
                    } else {
                        format!("avoid {}: {status}", p.name)
                    };
                    draw_set(
                        &mut panel,
                        &mut legend,
                        &label,
                        &poly.rows,
                        false,
                        AVOID,
                        yn,
                        dims,
                    );
                }
            }
            NetPropertyKind::Robust(_) => {
                let Some(label) = r.label else {
                    legend
                        .notes
                        .push(format!("robust {}: {status}, no label", p.name));
                    continue;
                };
                // y[label] ≥ y[k] for every other k
                let rows: Vec<(Vec<f64>, f64)> = (0..m)
                    .filter(|k| *k != label)
                    .map(|k| {
                        let mut a = vec![0.0; m];
                        a[k] = 1.0;
                        a[label] = -1.0;
                        (a, 0.0)
                    })
                    .collect();
                draw_set(
                    &mut panel,
                    &mut legend,
                    &format!("robust {} (label {label} wins): {status}", p.name),
                    &rows,
                    false,
                    GOAL,
                    yn,
                    dims,
                );
            }
        }
    }
    match &out_poly {
        Some(poly) if poly.len() >= 3 => {
            panel.shape(poly, Style::filled(step_colour(1, 2), 0.15, 2));
            legend.entries.push((
                Swatch::Fill(step_colour(1, 2)),
                "certified output set (right)".into(),
            ));
        }
        _ if plan.input.is_none() => {}
        _ => legend
            .notes
            .push("the output set has no finite bound on these outputs: not drawn".into()),
    }
    for (k, s) in outcome.selections.iter().enumerate() {
        let colour = step_colour(k + 1, outcome.selections.len().max(2));
        for c in s.choices.iter().take(200) {
            let b = IBox::new(c.lower.clone(), c.upper.clone());
            if let Some(p) = project(&Region::Box(b), dims) {
                panel.shape(&p, Style::outline(colour, 1, false));
            }
        }
    }
    for (_, y) in &samples {
        panel.dots.push(((y[i], y[j]), SAMPLE.mix(0.8), 2));
    }
    if !samples.is_empty() {
        legend.entries.push((
            Swatch::Dot(SAMPLE),
            format!("{} sampled inputs and their outputs", samples.len()),
        ));
    }
    if let Some((p, w)) = cex {
        panel
            .dots
            .push(((w.output[i], w.output[j]), CEX.to_rgba(), 4));
        legend.entries.push((
            Swatch::Dot(CEX),
            format!("counterexample of {} {}", p.kind.as_str(), p.name),
        ));
    }
    if m > 2 {
        legend.notes.push(format!(
            "the output has {m} coordinates: {i} and {j} shown (--plot-dims)"
        ));
    }
    if m > 2 || inputs > 2 {
        legend.notes.push(
            "sets of more than two coordinates: a polygon containing their projection".into(),
        );
    }
    panels.push(panel);
    render(
        &format!("{title} — {}", verdict_word(outcome.verdict)),
        &panels,
        &legend,
    )
}

/// A network of one output: the output `y[0]` against the first input
/// `x[0]`, its certified bounds as a band over the input set's range, the
/// properties as bands, the samples as points of the graph.
fn one_output(
    plan: &NetworkPlan,
    outcome: &NetworkOutcome,
    samples: &[(Vec<f64>, Vec<f64>)],
    legend: &mut Legend,
) -> Panel {
    let (xn, yn) = (&plan.input_name, &plan.output_name);
    let b = &outcome.output;
    // the output's certified interval: the box, or the ±1 directions
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    if let Some(bb) = &b.bbox {
        lo = bb.lo.first().copied().unwrap_or(lo);
        hi = bb.hi.first().copied().unwrap_or(hi);
    }
    for r in 0..b.directions.nrows() {
        let (d, o) = (
            b.directions[(r, 0)],
            b.offsets.get(r).copied().unwrap_or(f64::INFINITY),
        );
        if d > 0.0 {
            hi = hi.min(o / d);
        } else if d < 0.0 {
            lo = lo.max(o / d);
        }
    }
    let xr = plan
        .input
        .as_ref()
        .map(|r| r.bbox())
        .filter(|bb| bb.lo[0].is_finite() && bb.hi[0].is_finite())
        .map(|bb| (bb.lo[0], bb.hi[0]));
    let mut pts: Vec<P> = samples.iter().map(|(x, y)| (x[0], y[0])).collect();
    if let Some((a, c)) = xr {
        for v in [lo, hi] {
            pts.push((a, v));
            pts.push((c, v));
        }
    }
    let cex = outcome
        .properties
        .iter()
        .find_map(|p| p.counterexample.as_ref().map(|c| (p, c)));
    if let Some((_, w)) = cex {
        pts.push((w.input[0], w.output[0]));
    }
    let mut panel = Panel::new(format!("{xn}[0]"), format!("{yn}[0]"), window_of(&pts));
    for (p, r) in plan.properties.iter().zip(&outcome.properties) {
        let status = verdict_word(r.status);
        let lift = |rows: &[(Vec<f64>, f64)]| -> Vec<(Vec<f64>, f64)> {
            rows.iter()
                .map(|(a, c)| (vec![0.0, a.first().copied().unwrap_or(0.0)], *c))
                .collect()
        };
        match &p.kind {
            NetPropertyKind::Require(poly) => {
                draw_set(
                    &mut panel,
                    legend,
                    &format!("require {}: {status}", p.name),
                    &lift(&poly.rows),
                    false,
                    GOAL,
                    yn,
                    (0, 1),
                );
            }
            NetPropertyKind::Avoid(members) => {
                for poly in members {
                    draw_set(
                        &mut panel,
                        legend,
                        &format!("avoid {}: {status}", p.name),
                        &lift(&poly.rows),
                        false,
                        AVOID,
                        yn,
                        (0, 1),
                    );
                }
            }
            NetPropertyKind::Robust(_) => legend.notes.push(format!(
                "robust {}: {status} (one output: not drawn)",
                p.name
            )),
        }
    }
    match xr {
        Some((a, c)) if lo.is_finite() && hi.is_finite() => {
            let colour = step_colour(1, 2);
            panel.shape(
                &[(a, lo), (c, lo), (c, hi), (a, hi)],
                Style::filled(colour, 0.15, 2),
            );
            legend.entries.push((
                Swatch::Fill(colour),
                format!(
                    "certified output bounds: {yn}[0] in [{}, {}]",
                    num(lo),
                    num(hi)
                ),
            ));
        }
        _ => legend
            .notes
            .push("the output has no finite certified bound: not drawn".into()),
    }
    for (x, y) in samples {
        panel.dots.push(((x[0], y[0]), SAMPLE.mix(0.8), 2));
    }
    if !samples.is_empty() {
        legend.entries.push((
            Swatch::Dot(SAMPLE),
            format!("{} sampled inputs: {yn}[0] against {xn}[0]", samples.len()),
        ));
    }
    if let Some((p, w)) = cex {
        panel
            .dots
            .push(((w.input[0], w.output[0]), CEX.to_rgba(), 4));
        legend.entries.push((
            Swatch::Dot(CEX),
            format!("counterexample of {} {}", p.kind.as_str(), p.name),
        ));
    }
    legend.notes.push(format!(
        "one output: {yn}[0] against {xn}[0] (--plot-dims does not apply)"
    ));
    panel
}

fn err<E: std::fmt::Debug>(e: E) -> String {
    format!("drawing failed: {e:?}")
}

/// Words of `text` in lines of at most `width` characters.
fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut line = String::new();
    for w in text.split_whitespace() {
        if !line.is_empty() && line.chars().count() + 1 + w.chars().count() > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line += w;
    }
    if !line.is_empty() {
        lines.push(line);
    }
    lines
}

/// Text safe to draw: control characters replaced.
fn clean(s: &str) -> String {
    s.chars()
        .map(|c| if c.is_control() { '?' } else { c })
        .collect()
}

/// Draw the panels side by side, the legend on the right, the title on
/// top.
fn render(title: &str, panels: &[Panel], legend: &Legend) -> Result<String, String> {
    let width = PANEL * panels.len() as u32 + LEGEND;
    let height = PANEL + TITLE;
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let body = root
            .titled(&clean(title), (FONT, 22).into_font())
            .map_err(err)?;
        let (plots, side) = body.split_horizontally(PANEL * panels.len() as u32);
        let areas = plots.split_evenly((1, panels.len()));
        for (panel, area) in panels.iter().zip(&areas) {
            draw_panel(panel, area)?;
        }
        draw_legend(legend, &side)?;
        root.present().map_err(err)?;
    }
    Ok(buf)
}

fn draw_panel(p: &Panel, area: &DrawingArea<SVGBackend, Shift>) -> Result<(), String> {
    let [x0, x1, y0, y1] = p.window;
    let mut chart = ChartBuilder::on(area)
        .margin(12)
        .x_label_area_size(48)
        .y_label_area_size(64)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(clean(&p.x_desc))
        .y_desc(clean(&p.y_desc))
        .x_labels(8)
        .y_labels(8)
        .x_label_formatter(&|v| tick(*v, x1 - x0))
        .y_label_formatter(&|v| tick(*v, y1 - y0))
        .light_line_style(RGBColor(240, 240, 240))
        .bold_line_style(RGBColor(220, 220, 220))
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 15))
        .draw()
        .map_err(err)?;
    // every shape is clipped to the window; clamping only guards plotters'
    // pixel arithmetic against a point rounding made far off
    let clamp = |q: &P| (q.0.clamp(x0, x1), q.1.clamp(y0, y1));
    for (pts, style) in &p.shapes {
        let pts: &Vec<P> = &pts.iter().map(clamp).collect();
        if let Some(fill) = style.fill {
            chart
                .draw_series(std::iter::once(Polygon::new(pts.clone(), fill.filled())))
                .map_err(err)?;
        }
        if let Some(h) = style.hatch {
            // diagonal lines every 1/40 of the window, clipped to the shape
            let w = x1 - x0;
            let n = 40;
            let mut lines = Vec::new();
            for k in -n..=n {
                let s = k as f64 / n as f64;
                let p0 = (x0 + s * w, y0);
                let p1 = (x0 + (s + 1.0) * w, y1);
                if let Some((a, b)) = clip_segment(p0, p1, pts) {
                    lines.push(PathElement::new(vec![a, b], h.stroke_width(1)));
                }
            }
            chart.draw_series(lines).map_err(err)?;
        }
        if let Some((c, width)) = style.stroke {
            let mut ring = pts.clone();
            ring.push(pts[0]);
            if style.dashed {
                chart
                    .draw_series(std::iter::once(DashedPathElement::new(
                        ring,
                        6,
                        4,
                        c.stroke_width(width),
                    )))
                    .map_err(err)?;
            } else {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        ring,
                        c.stroke_width(width),
                    )))
                    .map_err(err)?;
            }
        }
    }
    for (pts, c, w) in &p.lines {
        for run in visible_runs(pts, p.window) {
            chart
                .draw_series(std::iter::once(PathElement::new(run, c.stroke_width(*w))))
                .map_err(err)?;
        }
    }
    let inside = |q: &P| q.0 >= x0 && q.0 <= x1 && q.1 >= y0 && q.1 <= y1;
    for (q, c, r) in &p.dots {
        if !inside(q) {
            continue;
        }
        chart
            .draw_series(std::iter::once(Circle::new(*q, *r, c.filled())))
            .map_err(err)?;
    }
    for (q, text, c) in &p.labels {
        if inside(q) {
            chart
                .draw_series(std::iter::once(Text::new(
                    text.clone(),
                    *q,
                    (FONT, 13).into_font().color(c),
                )))
                .map_err(err)?;
        }
    }
    Ok(())
}

/// The parts of a polyline inside the window, as polylines (computed in
/// the window's unit square, so that far-off points stay finite; a part
/// that does not come out inside is dropped).
fn visible_runs(pts: &[P], [x0, x1, y0, y1]: [f64; 4]) -> Vec<Vec<P>> {
    let (w, h) = (x1 - x0, y1 - y0);
    let to = |p: &P| ((p.0 - x0) / w, (p.1 - y0) / h);
    let ok = |q: P| (-1e-9..=1.0 + 1e-9).contains(&q.0) && (-1e-9..=1.0 + 1e-9).contains(&q.1);
    let mut runs: Vec<Vec<P>> = Vec::new();
    let mut last: Option<P> = None;
    for k in 1..pts.len() {
        let (a, b) = (to(&pts[k - 1]), to(&pts[k]));
        let Some((c, d)) = clip_unit(a, b).filter(|(c, d)| ok(*c) && ok(*d)) else {
            last = None;
            continue;
        };
        let back = |q: P| (x0 + q.0 * w, y0 + q.1 * h);
        match (last, runs.last_mut()) {
            (Some(l), Some(run)) if l == c => run.push(back(d)),
            _ => runs.push(vec![back(c), back(d)]),
        }
        last = (d == b).then_some(d);
    }
    runs
}

/// The segment `p → q` inside the unit square (Cohen–Sutherland: each
/// crossing is computed from the slope, so a far-off end keeps the part
/// near the square exact).
fn clip_unit(mut p: P, mut q: P) -> Option<(P, P)> {
    let code = |a: P| {
        (a.0 < 0.0) as u8
            | ((a.0 > 1.0) as u8) << 1
            | ((a.1 < 0.0) as u8) << 2
            | ((a.1 > 1.0) as u8) << 3
    };
    for _ in 0..8 {
        let (cp, cq) = (code(p), code(q));
        if cp | cq == 0 {
            return Some((p, q));
        }
        if cp & cq != 0 {
            return None;
        }
        let out = if cp != 0 { cp } else { cq };
        let (a, b) = if cp != 0 { (p, q) } else { (q, p) };
        // move the outside end `a` onto the border it is beyond
        let moved = if out & 8 != 0 {
            (b.0 + (a.0 - b.0) * (1.0 - b.1) / (a.1 - b.1), 1.0)
        } else if out & 4 != 0 {
            (b.0 + (a.0 - b.0) * (0.0 - b.1) / (a.1 - b.1), 0.0)
        } else if out & 2 != 0 {
            (1.0, b.1 + (a.1 - b.1) * (1.0 - b.0) / (a.0 - b.0))
        } else {
            (0.0, b.1 + (a.1 - b.1) * (0.0 - b.0) / (a.0 - b.0))
        };
        if !(moved.0.is_finite() && moved.1.is_finite()) {
            return None;
        }
        if cp != 0 {
            p = moved;
        } else {
            q = moved;
        }
    }
    None
}

fn draw_legend(l: &Legend, area: &DrawingArea<SVGBackend, Shift>) -> Result<(), String> {
    let font = (FONT, 13).into_font();
    let x = 10;
    let mut y = 24;
    area.draw(&Text::new("Legend", (x, y - 6), (FONT, 15).into_font()))
        .map_err(err)?;
    y += 8;
    for (swatch, text) in &l.entries {
        let (sx, sy) = (x, y);
        // the swatch's box, and its outline dashed
        let rect = [(sx, sy), (sx + 28, sy + 14)];
        let ring = vec![
            (sx, sy),
            (sx + 28, sy),
            (sx + 28, sy + 14),
            (sx, sy + 14),
            (sx, sy),
        ];
        let dashed_ring = |style: ShapeStyle| {
            area.draw(&DashedPathElement::new(ring.clone(), 5, 3, style))
                .map_err(err)
        };
        match swatch {
            Swatch::Fill(c) => {
                area.draw(&Rectangle::new(rect, c.mix(0.3).filled()))
                    .map_err(err)?;
                area.draw(&Rectangle::new(rect, c.stroke_width(1)))
                    .map_err(err)?;
            }
            Swatch::Outline(c, dashed) => {
                if *dashed {
                    dashed_ring(c.stroke_width(1))?;
                } else {
                    area.draw(&PathElement::new(ring.clone(), c.stroke_width(1)))
                        .map_err(err)?;
                }
            }
            Swatch::Light(c) => {
                area.draw(&Rectangle::new(rect, c.mix(0.08).filled()))
                    .map_err(err)?;
                dashed_ring(c.mix(0.5).stroke_width(1))?;
            }
            Swatch::Hatch(c) => {
                for k in 0..4 {
                    let a = sx + 7 * k;
                    area.draw(&PathElement::new(
                        vec![(a, sy + 14), (a + 7, sy)],
                        c.mix(0.55).stroke_width(1),
                    ))
                    .map_err(err)?;
                }
                dashed_ring(c.stroke_width(1))?;
            }
            Swatch::Line(c, w) => {
                area.draw(&PathElement::new(
                    vec![(sx, sy + 7), (sx + 28, sy + 7)],
                    c.stroke_width(*w),
                ))
                .map_err(err)?;
            }
            Swatch::Dot(c) => {
                area.draw(&Circle::new((sx + 14, sy + 7), 3, c.filled()))
                    .map_err(err)?;
            }
            Swatch::Ramp(last) => {
                // one block per step (at most 24 blocks), labelled 1 … last
                let n = (*last).min(24);
                let w = 28 * 4 / n.max(1) as i32;
                for k in 0..n {
                    let t = 1 + k * last.saturating_sub(1) / (n - 1).max(1);
                    let bx = sx + w * k as i32;
                    area.draw(&Rectangle::new(
                        [(bx, sy), (bx + w, sy + 14)],
                        step_colour(t, *last).filled(),
                    ))
                    .map_err(err)?;
                }
                area.draw(&Text::new("step 1", (sx, sy + 16), font.clone()))
                    .map_err(err)?;
                area.draw(&Text::new(
                    format!("step {last}"),
                    (sx + w * n as i32 - 44, sy + 16),
                    font.clone(),
                ))
                .map_err(err)?;
                y += 34;
                for line in wrap(&clean(text), 48) {
                    area.draw(&Text::new(line, (x, y), font.clone()))
                        .map_err(err)?;
                    y += 16;
                }
                y += 6;
                continue;
            }
        }
        let lines = wrap(&clean(text), 40);
        for (k, line) in lines.iter().enumerate() {
            area.draw(&Text::new(
                line.clone(),
                (x + 36, y + 16 * k as i32),
                font.clone(),
            ))
            .map_err(err)?;
        }
        y += 16 * lines.len().saturating_sub(1) as i32 + 22;
    }
    if !l.notes.is_empty() {
        y += 6;
        area.draw(&Text::new("Notes", (x, y), (FONT, 15).into_font()))
            .map_err(err)?;
        y += 20;
        for n in &l.notes {
            for (k, line) in wrap(&clean(n), 48).into_iter().enumerate() {
                let s = if k == 0 {
                    format!("• {line}")
                } else {
                    format!("  {line}")
                };
                area.draw(&Text::new(s, (x, y), font.clone()))
                    .map_err(err)?;
                y += 16;
            }
            y += 4;
        }
    }
    Ok(())
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

    #[test]
    fn a_shadow_contains_the_projection_of_its_polytope() {
        // x + y + z ≤ 1 over [0, 1]³: the projection onto (x, y) is the
        // triangle x + y ≤ 1 (z at its smallest, 0)
        let b = IBox::new(vec![0.0; 3], vec![1.0; 3]);
        let poly = shadow(&b, &[(vec![1.0, 1.0, 1.0], 1.0)], (0, 1));
        assert_eq!(poly.len(), 3);
        for p in &poly {
            assert!(p.0 + p.1 <= 1.0 + 1e-12);
        }
        // and x − z ≤ −0.5 (z ≥ x + 0.5): x ≤ 0.5 on the shadow
        let poly = shadow(&b, &[(vec![1.0, 0.0, -1.0], -0.5)], (0, 1));
        let xmax = poly.iter().fold(f64::NEG_INFINITY, |a, p| a.max(p.0));
        assert_eq!(xmax, 0.5);
    }

    #[test]
    fn a_segment_is_cut_to_a_polygon() {
        let sq = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)];
        let (a, b) = clip_segment((-1.0, 0.5), (2.0, 0.5), &sq).expect("crosses");
        assert_eq!((a, b), ((0.0, 0.5), (1.0, 0.5)));
        assert!(clip_segment((-1.0, 2.0), (2.0, 2.0), &sq).is_none());
    }

    #[test]
    fn far_off_lines_are_cut_to_the_window() {
        let w = [0.0, 1.0, 0.0, 1.0];
        let runs = visible_runs(&[(0.5, 0.5), (0.5, 0.9), (0.5, 1e300), (0.5, 0.2)], w);
        assert_eq!(runs.len(), 2);
        assert_eq!(runs[0], vec![(0.5, 0.5), (0.5, 0.9), (0.5, 1.0)]);
        assert!(runs.iter().flatten().all(|p| p.1 <= 1.0));
        assert!(visible_runs(&[(5.0, 5.0), (6.0, 6.0)], w).is_empty());
    }

    #[test]
    fn rows_read_as_written() {
        assert_eq!(row_text(&[0.0, 0.0, 1.0], 0.5, "x"), "x[2] <= 0.5");
        assert_eq!(row_text(&[0.0, -1.0], -2.0, "x"), "x[1] >= 2");
        assert_eq!(row_text(&[1.0, -2.0], 0.0, "y"), "y[0] - 2 y[1] <= 0");
        assert_eq!(row_text(&[0.0, -1.0, 1.0], 0.0, "y"), "y[2] - y[1] <= 0");
    }

    #[test]
    fn the_ramp_runs_from_blue_to_orange() {
        assert_eq!(step_colour(1, 10), RGBColor(8, 48, 107));
        assert_eq!(step_colour(10, 10), RGBColor(230, 97, 1));
    }
}
