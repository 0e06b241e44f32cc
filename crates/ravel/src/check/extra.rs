//! Checks of the language's second tier: initial sets that are polytopes or
//! ℓp balls, reachable-set boundaries, guided-partitioner budgets, and
//! time-varying or continuous-time plants.

use nalgebra::{DMatrix, DVector};

use super::Ctx;
use ravel_analysis::closed_loop::{Boundary, ModelError, Plant};
use ravel_analysis::lp;
use ravel_analysis::partition::Budget;
use ravel_analysis::sets::{IBox, Norm, Polytope, Region};
use ravel_syntax::ast::*;
use ravel_syntax::diag::{did_you_mean, Code, Diagnostic};

/// Default budget of the guided partitioners.
pub const DEFAULT_BUDGET: Budget = Budget {
    calls: 256,
    min_size: 1.0 / 64.0,
    seconds: None,
};

impl Ctx {
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
        // Boundedness does not depend on the scale of the rows: a non-empty
        // P is bounded iff its recession cone {d | H d ≤ 0} is {0}, decided
        // on the unit box with every row normalised (so tiny coefficients or
        // a large right-hand side cannot mislead it).
        let unit: Vec<(Vec<f64>, f64)> = p
            .rows
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
                let d = if r.issue.is_some() {
                    not_bounded(role, span, r.issue)
                } else {
                    Diagnostic::new(Code::EmptyOrUnbounded, span, format!("{role} is unbounded"))
                        .label(format!(
                            "component {i} has no finite {} bound",
                            if sign > 0.0 { "upper" } else { "lower" }
                        ))
                        .hint("add inequalities that bound every component, or use a box")
                };
                self.err(d);
                return None;
            }
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
        let mut fixed_lo = vec![f64::NEG_INFINITY; n];
        let mut fixed_hi = vec![f64::INFINITY; n];
        for (a, h) in &rows {
            let mut nz = a.iter().enumerate().filter(|(_, v)| **v != 0.0);
            if let (Some((i, &c)), None) = (nz.next(), nz.next()) {
                // c·x_i ≤ h with c a power-of-two multiple: h / c rounded outward
                let q = h / c;
                if c > 0.0 {
                    if let Some(f) = fixed_hi.get_mut(i) {
                        *f = f.min(q.next_up());
                    }
                } else if let Some(f) = fixed_lo.get_mut(i) {
                    *f = f.max(q.next_down());
                }
            }
        }
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

    /// `boundary polytope K` or `boundary polytope [[…], …]`.
    pub(super) fn boundary_polytope(
        &mut self,
        v: &Spanned<Value>,
        name: &str,
        n: usize,
    ) -> Option<Boundary> {
        match &v.node {
            Value::Scalar(k) => {
                let k = *k as usize;
                if n != 2 {
                    self.err(
                        Diagnostic::new(Code::Boundary, v.span, format!("evenly spread directions need a 2-D state, but `{name}` has {n} components"))
                            .label("a count of directions")
                            .hint(format!("give the directions as a matrix with {n} columns: `boundary polytope [[…], …]`")),
                    );
                    return None;
                }
                if k == 0 || k > 1000 {
                    self.err(
                        Diagnostic::new(
                            Code::Boundary,
                            v.span,
                            format!("{k} directions: a polytope boundary needs between 1 and 1000"),
                        )
                        .label("bad count")
                        .hint("8 or 16 directions are typical"),
                    );
                    return None;
                }
                Some(Boundary::spread(k))
            }
            Value::Matrix(rows) => {
                let m = self.matrix(
                    v,
                    "the boundary directions",
                    rows.len(),
                    Some(n),
                    &format!("one direction per row, {n} columns (one per component of `{name}`)"),
                )?;
                for (r, row) in rows.iter().enumerate() {
                    if m.row(r).iter().all(|v| *v == 0.0) {
                        self.err(
                            Diagnostic::new(
                                Code::Boundary,
                                row.span,
                                "a zero direction bounds nothing",
                            )
                            .label("all zeros")
                            .hint("remove the row or give it a non-zero entry"),
                        );
                        return None;
                    }
                }
                Some(Boundary::Polytope(m))
            }
            _ => None,
        }
    }

    /// The budget of a guided partitioner.
    pub(super) fn budget(&mut self, items: &[(Spanned<String>, Spanned<f64>)]) -> Option<Budget> {
        const NAMES: [&str; 3] = ["calls", "min_size", "time"];
        let mut b = DEFAULT_BUDGET;
        let mut ok = true;
        let mut seen: Vec<(&str, Span)> = Vec::new();
        for (k, v) in items {
            if let Some((_, first)) = seen.iter().find(|(s, _)| *s == k.node) {
                self.duplicate(&format!("the budget item `{}`", k.node), *first, k.span);
                ok = false;
                continue;
            }
            seen.push((&k.node, k.span));
            let x = self.finite(v);
            let bad = |cx: &mut Ctx, what: &str, hint: &str| {
                cx.err(
                    Diagnostic::new(Code::Budget, v.span, format!("`{}` {what}", k.node))
                        .label("invalid budget")
                        .hint(hint.to_string()),
                );
            };
            match k.node.as_str() {
                "calls" => {
                    if !((1.0..=ravel_base::limits::MAX_CALLS as f64).contains(&x)
                        && x.fract() == 0.0)
                    {
                        bad(
                            self,
                            "must be a whole number of cell evaluations from 1 to 100000",
                            "e.g. `calls 200`",
                        );
                        ok = false;
                    } else {
                        b.calls = x as usize;
                    }
                }
                "min_size" => {
                    if !(x > 0.0 && x <= 1.0) {
                        bad(
                            self,
                            "must be a fraction of the initial set's width in (0, 1]",
                            "e.g. `min_size 0.01`: cells narrower than 1 % are not split",
                        );
                        ok = false;
                    } else {
                        b.min_size = x;
                    }
                }
                "time" => {
                    if !(x > 0.0 && x.is_finite()) {
                        bad(
                            self,
                            "must be a positive number of seconds",
                            "e.g. `time 2.5`",
                        );
                        ok = false;
                    } else {
                        b.seconds = Some(x);
                    }
                }
                other => {
                    let mut d = Diagnostic::new(
                        Code::UnknownName,
                        k.span,
                        format!("unknown budget item `{other}`"),
                    )
                    .label("not a budget item");
                    d = match did_you_mean(other, NAMES) {
                        Some(s) => d.hint(format!(
                            "did you mean `{s}`? Budget items: calls, min_size, time"
                        )),
                        None => d.hint("budget items: calls N, min_size r, time s"),
                    };
                    self.err(d);
                    ok = false;
                }
            }
        }
        ok.then_some(b)
    }

    /// `time continuous dt …` / `time discrete`: `Some(dt)` for continuous time.
    pub(super) fn time_decl(
        &mut self,
        kind: &Spanned<String>,
        dt: &Option<Spanned<f64>>,
        span: Span,
    ) -> Result<Option<f64>, ()> {
        match (kind.node.as_str(), dt) {
            ("discrete", None) => Ok(None),
            ("discrete", Some(d)) => {
                self.err(
                    Diagnostic::new(
                        Code::TimeStep,
                        d.span,
                        "`dt` applies only to continuous time",
                    )
                    .label("a time step for a discrete-time plant")
                    .hint("write `time continuous dt …` to discretise A, B, c, or drop `dt`"),
                );
                Err(())
            }
            ("continuous", None) => {
                self.err(
                    Diagnostic::new(Code::TimeStep, span, "a continuous-time plant needs a time step")
                        .label("no `dt`")
                        .hint("write `time continuous dt 0.1`: the controller acts every dt seconds (zero-order hold)"),
                );
                Err(())
            }
            ("continuous", Some(d)) => {
                let x = self.finite(d);
                if x > 0.0 && x.is_finite() {
                    Ok(Some(x))
                } else {
                    self.err(
                        Diagnostic::new(
                            Code::TimeStep,
                            d.span,
                            format!(
                                "the time step must be positive, not {}",
                                ravel_syntax::diag::compact(d.node)
                            ),
                        )
                        .label("dt ≤ 0")
                        .hint("the controller's sampling period in seconds, e.g. `dt 0.1`"),
                    );
                    Err(())
                }
            }
            (other, _) => {
                let mut d = Diagnostic::new(
                    Code::UnknownName,
                    kind.span,
                    format!("unknown time kind `{other}`"),
                )
                .label("not a kind of time");
                d = match did_you_mean(other, ["continuous", "discrete"]) {
                    Some(s) => d.hint(format!("did you mean `{s}`?")),
                    None => d.hint("write `time continuous dt …` or `time discrete`"),
                };
                self.err(d);
                Err(())
            }
        }
    }
}

/// Exact zero-order-hold discretisation of `ẋ = A x + B u + c` over `dt`:
/// `exp([[A, B, c], [0, 0, 0]]·dt) = [[A_d, B_d, c_d], [0, I, 0…]]`, so
/// `A_d = e^{A dt}` and `B_d`, `c_d` are the input integrals `∫₀^dt e^{Aτ} dτ · (B, c)`.
/// The exponential is enclosed rigorously ([`ravel_analysis::expm`]), including the
/// rounding of `big·dt`; the enclosure's radius becomes the plant's
/// [`ModelError`], which every propagator adds to its bounds.
/// `None` when the exponential cannot be enclosed (overflow).
pub fn zero_order_hold(plant: &Plant, dt: f64) -> Option<Plant> {
    let n = plant.a.nrows();
    let m = plant.b.ncols();
    let k = n + m + 1;
    let mut big = DMatrix::<f64>::zeros(k, k);
    big.view_mut((0, 0), (n, n)).copy_from(&plant.a);
    big.view_mut((0, n), (n, m)).copy_from(&plant.b);
    big.view_mut((0, n + m), (n, 1)).copy_from(&plant.c);
    // M = fl(big·dt) is off by at most u·|big·dt| per entry; with Δ = M − big·dt,
    // ‖e^{M−Δ} − e^M‖∞ ≤ ‖Δ‖∞·e^{‖M‖∞+‖Δ‖∞}, which bounds every entry
    let scaled = &big * dt;
    let delta = (ravel_analysis::expm::norm_inf(&scaled) * ravel_base::num::U * 1.0001).next_up();
    let (e, mut err) = ravel_analysis::expm::expm_enclosure(&scaled)?;
    let perturb = delta * (ravel_analysis::expm::norm_inf(&scaled) + delta).exp() * 1.0001;
    err.add_scalar_mut(perturb);
    if e.iter().chain(err.iter()).any(|v| !v.is_finite()) {
        return None;
    }
    Some(Plant {
        a: e.view((0, 0), (n, n)).into_owned(),
        b: e.view((0, n), (n, m)).into_owned(),
        c: DVector::from_iterator(n, e.view((0, n + m), (n, 1)).iter().copied()),
        obs: plant.obs.clone(),
        w: plant.w.clone(),
        v: plant.v.clone(),
        err: Some(ModelError {
            a: err.view((0, 0), (n, n)).into_owned(),
            b: err.view((0, n), (n, m)).into_owned(),
            c: DVector::from_iterator(n, err.view((0, n + m), (n, 1)).iter().copied()),
        }),
    })
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

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn zero_order_hold_of_a_double_integrator() {
        // ẋ = [[0, 1], [0, 0]] x + [0, 1] u: A_d = [[1, dt], [0, 1]], B_d = [dt²/2, dt]
        let p = Plant {
            a: DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, 0.0]),
            b: DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
            c: DVector::from_column_slice(&[0.0, -2.0]),
            obs: DMatrix::identity(2, 2),
            w: IBox::new(vec![0.0; 2], vec![0.0; 2]),
            v: IBox::new(vec![0.0; 2], vec![0.0; 2]),
            err: None,
        };
        let d = zero_order_hold(&p, 0.5).expect("finite");
        let e = d
            .err
            .as_ref()
            .expect("a discretised plant carries its error");
        // exact values inside the enclosure, whose radius is a few ulps of the entries
        let within = |x: f64, want: f64, r: f64| (x - want).abs() <= r && r < 1e-13;
        assert!(within(d.a[(0, 1)], 0.5, e.a[(0, 1)]) && within(d.a[(0, 0)], 1.0, e.a[(0, 0)]));
        assert!(within(d.a[(1, 0)], 0.0, e.a[(1, 0)]) && within(d.a[(1, 1)], 1.0, e.a[(1, 1)]));
        assert!(within(d.b[(0, 0)], 0.125, e.b[(0, 0)]) && within(d.b[(1, 0)], 0.5, e.b[(1, 0)]));
        assert!(within(d.c[0], -0.25, e.c[0]) && within(d.c[1], -1.0, e.c[1]));
    }
}
