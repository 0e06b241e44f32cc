//! The sets properties refer to ([`StateSet`]: linear rows and nonlinear
//! constraints `g(x) ≤ 0`) measured against reachable sets and simulated
//! states.
//!
//! A constraint is bounded over a set's bounding box in outward-rounded
//! interval arithmetic ([`tape_range`]). Where it is undefined on the box
//! (a divisor that may be 0, `log` or `sqrt` outside its domain, a pole of
//! `tan`) or overflows, nothing is proven: its upper bound is `+∞` and its
//! lower bound `−∞`, so it neither proves containment nor separation.
//! Margins are sound in the direction they are used: a containment margin
//! is a lower bound of `min(hᵣ − Hᵣx, −g(x))` over the set, a separation
//! margin a lower bound of how far one row or one constraint keeps the set
//! out. A NaN never proves anything ([`sane`]).

use ravel_analysis::nonlinear::integrate::elementary::{tape_range, tape_range_affine};
use ravel_analysis::nonlinear::integrate::Interval;
use ravel_analysis::sets::{Affine, IBox, Region};
use ravel_base::expr::Tape;

use super::cells::{containment_margin, sane, separation_margin};
use crate::lower::StateSet;

/// The box as one interval per variable.
fn intervals(b: &IBox) -> Vec<Interval> {
    b.lo.iter()
        .zip(&b.hi)
        .map(|(l, h)| Interval::new(*l, *h))
        .collect()
}

/// A certified upper bound of `g` over the box (`+∞` when `g` cannot be
/// bounded there).
pub(super) fn upper(g: &Tape, b: &[Interval]) -> f64 {
    match tape_range(g, b) {
        Ok(r) if !r.hi.is_nan() => r.hi,
        _ => f64::INFINITY,
    }
}

/// A certified lower bound of `g` over the box (`−∞` when `g` cannot be
/// bounded there).
pub(super) fn lower(g: &Tape, b: &[Interval]) -> f64 {
    match tape_range(g, b) {
        Ok(r) if !r.lo.is_nan() => r.lo,
        _ => f64::NEG_INFINITY,
    }
}

/// The enclosure of `g` over the box, tightened by the mean value form
/// over the region's affine enclosure when there is one (see
/// [`tape_range_affine`]); `None` when `g` cannot be bounded there.
fn range_over(g: &Tape, b: &[Interval], form: Option<&Affine>) -> Option<Interval> {
    match form {
        Some(f) => tape_range_affine(g, f, b),
        None => tape_range(g, b).ok(),
    }
    .filter(|r| !(r.lo.is_nan() || r.hi.is_nan()))
}

/// A certified lower bound of how deep the region lies in the set:
/// non-negative means `region ⊆ set`; whether an LP solver issue weakened
/// it. `form`, an affine enclosure of the same states (a nonlinear plant's
/// models), tightens the nonlinear constraints' bounds.
pub(super) fn containment(set: &StateSet, region: &Region, form: Option<&Affine>) -> (f64, bool) {
    let (m, issue) = if set.poly.rows.is_empty() && !set.nonlinear.is_empty() {
        (f64::INFINITY, false)
    } else {
        containment_margin(&set.poly, region)
    };
    let mut m = sane(m);
    if !set.nonlinear.is_empty() {
        let b = intervals(&region.bbox());
        for g in &set.nonlinear {
            m = m.min(-range_over(g, &b, form).map_or(f64::INFINITY, |r| r.hi));
        }
    }
    (m, issue)
}

/// A certified lower bound of how far one row or one constraint keeps the
/// region out of the set: positive means they are disjoint; whether an LP
/// solver issue weakened it. `form` as for [`containment`].
pub(super) fn separation(set: &StateSet, region: &Region, form: Option<&Affine>) -> (f64, bool) {
    let (m, issue) = if set.poly.rows.is_empty() && !set.nonlinear.is_empty() {
        (f64::NEG_INFINITY, false)
    } else {
        separation_margin(&set.poly, region)
    };
    let mut m = sane(m);
    if !set.nonlinear.is_empty() {
        let b = intervals(&region.bbox());
        for g in &set.nonlinear {
            m = m.max(range_over(g, &b, form).map_or(f64::NEG_INFINITY, |r| r.lo));
        }
    }
    (m, issue)
}

/// Whether the box certainly lies inside the set (every row and every
/// constraint holds on all of it).
pub(super) fn box_inside(set: &StateSet, b: &IBox) -> bool {
    let m = set.poly.containment_margin(b);
    if m.is_nan() || m < 0.0 {
        return false;
    }
    let iv = intervals(b);
    set.nonlinear.iter().all(|g| upper(g, &iv) <= 0.0)
}

/// Whether the box certainly misses the set (one row or one constraint is
/// violated on all of it).
pub(super) fn box_outside(set: &StateSet, b: &IBox) -> bool {
    if sane(set.poly.separation_margin(b)) > 0.0 {
        return true;
    }
    let iv = intervals(b);
    set.nonlinear.iter().any(|g| lower(g, &iv) > 0.0)
}

/// How far a simulated state lies inside the set (negative: outside), in
/// `f64`: `min(hᵣ − Hᵣx, −g(x))`; NaN when a constraint is not defined
/// there (such a state decides nothing). For simulated states only.
pub(super) fn depth(set: &StateSet, x: &[f64]) -> f64 {
    let mut d = set.poly.depth(x);
    let mut values = Vec::new();
    for g in &set.nonlinear {
        g.eval_into(x, &mut values);
        let v = values.last().copied().unwrap_or(f64::NAN);
        if v.is_nan() {
            return f64::NAN;
        }
        d = d.min(-v);
    }
    d
}

/// The largest absolute right-hand side of the set's rows (the scale of
/// the simulation tolerance; a constraint counts as 1).
pub(super) fn rhs_scale(set: &StateSet) -> f64 {
    let rows = set.poly.rows.iter().fold(0.0f64, |a, r| a.max(r.1.abs()));
    if set.nonlinear.is_empty() {
        rows
    } else {
        rows.max(1.0)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;
    use ravel_analysis::sets::Polytope;
    use ravel_base::expr::{Func, Node};

    /// `(x0 − 1)² + (x1 − 1)² − r²`
    fn disc(r2: f64) -> StateSet {
        let mut t = Tape::new();
        let x0 = t.push(Node::Var(0));
        let one = t.push(Node::Const(1.0));
        let d0 = t.push(Node::Sub(x0, one));
        let s0 = t.push(Node::Powi(d0, 2));
        let x1 = t.push(Node::Var(1));
        let d1 = t.push(Node::Sub(x1, one));
        let s1 = t.push(Node::Powi(d1, 2));
        let sum = t.push(Node::Add(s0, s1));
        let r = t.push(Node::Const(r2));
        t.push(Node::Sub(sum, r));
        StateSet {
            poly: Polytope { rows: Vec::new() },
            nonlinear: vec![t],
        }
    }

    fn bx(lo: [f64; 2], hi: [f64; 2]) -> IBox {
        IBox::new(lo.to_vec(), hi.to_vec())
    }

    #[test]
    fn a_disc_is_missed_contained_or_undecided_soundly() {
        let d = disc(0.25);
        // far away: separated by a positive margin
        let far = Region::Box(bx([-1.0, -1.0], [0.0, 0.0]));
        let (s, _) = separation(&d, &far, None);
        assert!(s > 0.0 && s <= 2.0 - 0.25, "{s}");
        assert!(containment(&d, &far, None).0 < 0.0);
        // a small box at the centre: contained
        let centre = Region::Box(bx([0.9, 0.9], [1.1, 1.1]));
        let (c, _) = containment(&d, &centre, None);
        assert!(c > 0.0 && c <= 0.25, "{c}");
        assert!(separation(&d, &centre, None).0 <= 0.0);
        // overlapping the rim: neither
        let rim = Region::Box(bx([1.3, 0.9], [1.7, 1.1]));
        assert!(containment(&d, &rim, None).0 < 0.0 && separation(&d, &rim, None).0 <= 0.0);
        assert!(box_inside(&d, &bx([0.9, 0.9], [1.1, 1.1])));
        assert!(!box_inside(&d, &bx([1.3, 0.9], [1.7, 1.1])));
        assert!(box_outside(&d, &bx([-1.0, -1.0], [0.0, 0.0])));
        assert!(!box_outside(&d, &bx([1.3, 0.9], [1.7, 1.1])));
    }

    #[test]
    fn an_undefined_constraint_proves_nothing() {
        // log(x0) ≤ 0 with x0 possibly ≤ 0 on the box
        let mut t = Tape::new();
        let x0 = t.push(Node::Var(0));
        t.push(Node::Func(Func::Log, x0));
        let s = StateSet {
            poly: Polytope { rows: Vec::new() },
            nonlinear: vec![t],
        };
        let b = bx([-1.0, 0.0], [0.5, 1.0]);
        assert_eq!(
            containment(&s, &Region::Box(b.clone()), None).0,
            f64::NEG_INFINITY
        );
        assert_eq!(
            separation(&s, &Region::Box(b.clone()), None).0,
            f64::NEG_INFINITY
        );
        assert!(!box_inside(&s, &b) && !box_outside(&s, &b));
        assert!(depth(&s, &[-1.0, 0.0]).is_nan());
    }
}
