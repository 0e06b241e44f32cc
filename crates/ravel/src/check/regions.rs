//! Initial and input sets beyond boxes: polytopes (checked bounded and
//! non-empty, with a certified bounding box) and ℓp balls.

use super::Ctx;
use ravel_analysis::lp;
use ravel_analysis::sets::{IBox, Norm, Polytope, Region};
use ravel_base::limits::MAX_POLYTOPE_DIM;
use ravel_syntax::ast::*;
use ravel_syntax::diag::{Code, Diagnostic};

impl Ctx {
    /// The one member of an initial or input set (`set`: "initial set" or
    /// "input set") over the vector `name` of dimension `dim`: a box, a
    /// bounded polytope or a ball.
    pub(super) fn region(
        &mut self,
        atom: &Spanned<SetAtom>,
        name: &str,
        dim: usize,
        set: &str,
    ) -> Option<Region> {
        let role = format!("the {set}");
        match &atom.node {
            SetAtom::Box(b) => {
                let sb = Spanned {
                    node: b.clone(),
                    span: atom.span,
                };
                self.box_set(&sb, name, dim, true, &role).map(Region::Box)
            }
            SetAtom::Polytope(_) | SetAtom::Inequalities(_) if dim > MAX_POLYTOPE_DIM => {
                self.err(
                    Diagnostic::new(
                        Code::Limit,
                        atom.span,
                        format!("a polytope {set} in {dim} dimensions, beyond the limit of {MAX_POLYTOPE_DIM}"),
                    )
                    .label("too many dimensions for a polytope")
                    .hint("use a box or a ball, which are bounded in closed form"),
                );
                None
            }
            SetAtom::Polytope(cs) => self
                .polytope(cs, name, dim)
                .and_then(|p| self.bounded_polytope(p, atom.span, &role)),
            SetAtom::Inequalities(rows) => self
                .linear_rows(rows, name, dim, &role)
                .and_then(|p| self.bounded_polytope(p, atom.span, &role)),
            SetAtom::Ball(b) => self.ball(b, atom.span, name, dim),
        }
    }

    /// A polytope initial set: it must be bounded and not empty. Its bounding
    /// box comes from `2n` certified LP bounds inside a large box; a bound
    /// that reaches the large box's edge means the polytope is unbounded
    /// (a convex set that meets the large box and leaves it must touch its boundary).
    pub(super) fn bounded_polytope(
        &mut self,
        p: Polytope,
        span: Span,
        role: &str,
    ) -> Option<Region> {
        let n = p.rows.first().map_or(0, |r| r.0.len());
        if let Some(d) = unbounded(&p.rows, n, span, role) {
            self.err(d);
            return None;
        }
        // The polytope is bounded: find a box B whose bounds the LP bounds
        // of P ∩ B stay strictly inside; then P ⊆ B (P is convex, so a point
        // of P outside B would put a point of P ∩ B on B's boundary).
        let scale = p.rows.iter().fold(1.0f64, |m, (a, h)| {
            let norm = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            if norm > 0.0 {
                m.max(h.abs() / norm)
            } else {
                m
            }
        });
        // Rows are scaled by powers of two (exactly: the same set) so their
        // largest coefficient is in [½, 1); single-variable rows give exact
        // intervals, which bound those components without any LP and keep
        // the LPs well scaled when the set lies far from the origin.
        let rows: Vec<(Vec<f64>, f64)> = p.rows.iter().map(|(a, h)| pow2_scaled(a, *h)).collect();
        let (fixed_lo, fixed_hi) = single_variable_bounds(&rows, n);
        let p = Polytope { rows };
        // boxes of 1e3·s, 1e6·s, …, 1e18·s (six tries at most, whatever the
        // numbers: a scale that overflows makes the first try the last)
        let mut big = 1e3 * scale;
        for attempt in 0..6 {
            let at_last = attempt == 5 || !(big * 1e3).is_finite();
            let lo: Vec<f64> = fixed_lo
                .iter()
                .map(|l| if l.is_finite() { *l } else { -big })
                .collect();
            let hi: Vec<f64> = fixed_hi
                .iter()
                .map(|h| if h.is_finite() { *h } else { big })
                .collect();
            if lp::separation(&[], &p.rows, &lo, &hi).value > 0.0 {
                // P ∩ B is empty: P is empty, or lies beyond B
                if at_last {
                    self.err(empty_set(role, span));
                    return None;
                }
                big *= 1e3;
                continue;
            }
            let mut bb_lo = Vec::with_capacity(n);
            let mut bb_hi = Vec::with_capacity(n);
            let mut inside = true;
            let mut issue = None;
            for (i, (flo, fhi)) in fixed_lo.iter().zip(&fixed_hi).enumerate() {
                let up = lp::maximize(&axis(n, i, 1.0), &p.rows, &lo, &hi);
                let down = lp::maximize(&axis(n, i, -1.0), &p.rows, &lo, &hi);
                issue = issue.or(up.issue).or(down.issue);
                // a fixed side is a constraint of P itself: nothing to check there
                inside &= (fhi.is_finite() || up.value < 0.5 * big)
                    && (flo.is_finite() || down.value < 0.5 * big);
                bb_hi.push(up.value);
                bb_lo.push(-down.value);
            }
            if issue.is_some() {
                self.err(not_bounded(role, span, issue));
                return None;
            }
            if inside {
                return Some(Region::Polytope {
                    bbox: IBox::new(bb_lo, bb_hi),
                    rows: p.rows,
                });
            }
            if at_last {
                self.err(not_bounded(role, span, None));
                return None;
            }
            big *= 1e3;
        }
        self.err(not_bounded(role, span, None));
        None
    }

    /// An ℓp ball with per-dimension radii.
    pub(super) fn ball(
        &mut self,
        b: &BallSet,
        span: Span,
        name: &str,
        dim: usize,
    ) -> Option<Region> {
        let center: Vec<f64> = b.center.node.iter().map(|x| self.finite(x)).collect();
        let mut ok = true;
        if center.len() != dim {
            self.err(
                Diagnostic::new(
                    Code::Shape,
                    b.center.span,
                    format!(
                        "the ball's centre has {} entries but `{name}` has {dim}",
                        center.len()
                    ),
                )
                .label(format!("{} entries", center.len()))
                .hint(format!(
                    "give one centre coordinate per component of `{name}`"
                )),
            );
            ok = false;
        }
        let radius: Vec<f64> = match &b.radius.node {
            Value::Scalar(r) => vec![*r; dim],
            Value::Vector(rs) => {
                let r: Vec<f64> = rs.iter().map(|x| self.finite(x)).collect();
                if r.len() != dim {
                    self.err(
                        Diagnostic::new(
                            Code::Shape,
                            b.radius.span,
                            format!(
                                "the ball has {} radii but `{name}` has {dim} components",
                                r.len()
                            ),
                        )
                        .label(format!("{} radii", r.len()))
                        .hint("give one radius, or one per component"),
                    );
                    ok = false;
                }
                r
            }
            _ => Vec::new(),
        };
        if radius.iter().any(|r| !r.is_finite()) {
            self.err(
                Diagnostic::new(
                    Code::NonFinite,
                    b.radius.span,
                    "the ball's radius is not finite",
                )
                .label("not a finite number")
                .hint("write a finite radius"),
            );
            ok = false;
        } else if radius.iter().any(|r| *r < 0.0) {
            self.err(
                Diagnostic::new(
                    Code::EmptyOrUnbounded,
                    b.radius.span,
                    "a ball with a negative radius is empty",
                )
                .label("negative radius")
                .hint("radii must be ≥ 0"),
            );
            ok = false;
        }
        let norm = match b.norm.as_ref().map(|n| n.node.as_str()) {
            None | Some("2") => Norm::L2,
            Some("1") => Norm::L1,
            _ => Norm::LInf,
        };
        let _ = span;
        ok.then_some(Region::Ball {
            center,
            radius,
            norm,
        })
    }
}

/// Why a polytope over `n` variables is not bounded, if it is not.
/// Boundedness does not depend on the scale of the rows: a non-empty P is
/// bounded iff its recession cone {d | H d ≤ 0} is {0}, decided on the unit
/// box with every row normalised (so tiny coefficients or a large right-hand
/// side cannot mislead it).
fn unbounded(rows: &[(Vec<f64>, f64)], n: usize, span: Span, role: &str) -> Option<Diagnostic> {
    let unit: Vec<(Vec<f64>, f64)> = rows
        .iter()
        .filter_map(|(a, _)| {
            let norm = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            (norm > 0.0).then(|| (a.iter().map(|v| v / norm).collect(), 0.0))
        })
        .collect();
    let (ulo, uhi) = (vec![-1.0; n], vec![1.0; n]);
    for i in 0..n {
        for sign in [1.0, -1.0] {
            let r = lp::maximize(&axis(n, i, sign), &unit, &ulo, &uhi);
            // the cone is {0} (every maximum is 0) or contains a
            // direction scaled to reach 1 in some ±e_i: the
            // threshold ½ is far from both, whatever the LP's accuracy
            if r.issue.is_none() && r.value < 0.5 {
                continue;
            }
            if r.issue.is_some() {
                return Some(not_bounded(role, span, r.issue));
            }
            return Some(
                Diagnostic::new(Code::EmptyOrUnbounded, span, format!("{role} is unbounded"))
                    .label(format!(
                        "component {i} has no finite {} bound",
                        if sign > 0.0 { "upper" } else { "lower" }
                    ))
                    .hint("add inequalities that bound every component, or use a box"),
            );
        }
    }
    None
}

/// The bounds that single-variable rows (`c·x_i ≤ h`, with `c` a power of
/// two, see [`pow2_scaled`]) put on each of the `n` components: `h / c`
/// rounded outward; infinite where no such row bounds a side.
fn single_variable_bounds(rows: &[(Vec<f64>, f64)], n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut lo = vec![f64::NEG_INFINITY; n];
    let mut hi = vec![f64::INFINITY; n];
    for (a, h) in rows {
        let mut nz = a.iter().enumerate().filter(|(_, v)| **v != 0.0);
        if let (Some((i, &c)), None) = (nz.next(), nz.next()) {
            let q = h / c;
            if c > 0.0 {
                if let Some(f) = hi.get_mut(i) {
                    *f = f.min(q.next_up());
                }
            } else if let Some(f) = lo.get_mut(i) {
                *f = f.max(q.next_down());
            }
        }
    }
    (lo, hi)
}

/// "`role` is empty".
fn empty_set(role: &str, span: Span) -> Diagnostic {
    Diagnostic::new(Code::EmptyOrUnbounded, span, format!("{role} is empty"))
        .label("no state satisfies every inequality")
        .hint("check the directions of `<=` and `>=`")
}

/// "`role` could not be bounded", with the LP solver's issue if there was one.
fn not_bounded(role: &str, span: Span, issue: Option<ravel_analysis::issue::Issue>) -> Diagnostic {
    let message = match issue {
        Some(i) => format!("{role} could not be bounded (LP solver: {i})"),
        None => format!("{role} could not be bounded"),
    };
    Diagnostic::new(Code::EmptyOrUnbounded, span, message)
        .label("bounding box unknown")
        .hint("the inequalities may be nearly parallel or badly scaled; rescale them or use a box")
}

/// The vector `sign·eᵢ` of length `n`.
fn axis(n: usize, i: usize, sign: f64) -> Vec<f64> {
    (0..n).map(|j| if j == i { sign } else { 0.0 }).collect()
}

/// A row `a·x ≤ h` multiplied by the power of two that brings its largest
/// coefficient into `[½, 1)`: exact in binary floating point, so the set is
/// unchanged (barring overflow or underflow, which the magnitude limits on
/// spec numbers rule out).
fn pow2_scaled(a: &[f64], h: f64) -> (Vec<f64>, f64) {
    let m = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if m == 0.0 || !m.is_finite() {
        return (a.to_vec(), h);
    }
    let k = m.log2().floor() as i32 + 1;
    let f = 2f64.powi(-k);
    let scaled: Vec<f64> = a.iter().map(|v| v * f).collect();
    let hs = h * f;
    // exact only without overflow and without underflow into subnormals
    let exact = hs.is_finite()
        && (h == 0.0 || hs.abs() >= f64::MIN_POSITIVE)
        && a.iter()
            .zip(&scaled)
            .all(|(v, w)| *v == 0.0 || (w.is_finite() && w.abs() >= f64::MIN_POSITIVE));
    if exact {
        (scaled, hs)
    } else {
        (a.to_vec(), h)
    }
}
