//! The validated flow of `ẋ = f(x, u, w)` over one control period, and the
//! discrete-time image `x⁺ = f(x, u, w)`.
//!
//! Each substep of size `h` (an interval: the period divided exactly into
//! `substeps·2ᵈ` parts, so the substeps add up to the period in real
//! arithmetic) does:
//!
//! 1. an a-priori enclosure `B` of `x(t)`, `t ∈ [0, h]`, for every initial
//!    state of the current set `X`: Picard iteration `N = X + [0, h]·f(B̃)`
//!    on an inflated candidate `B̃`; when `N` lies in the interior of `B̃`,
//!    every solution stays in `B̃` over `[0, h]` and so in `N`, which is `B`;
//! 2. `x(h) ∈ Σ_{i<k} x_[i]·hⁱ + hᵏ·x_[k](B)`: the coefficients `x_[i]` in
//!    Taylor-model arithmetic from the current models (so the dependency on
//!    the initial set is kept), the Lagrange remainder in interval
//!    arithmetic over `B`;
//! 3. the intersample enclosure `B ∩ (Σ x_[i]·[0, h]ⁱ + [0, h]ᵏ·x_[k](B))`.
//!
//! The period's intersample enclosure is kept in pieces ([`FlowOut::pieces`]):
//! one box per initial substep, `[j·T/s, (j+1)·T/s]` for `s = substeps`
//! (8 by default), the hull of the enclosures of that substep's halvings.
//! The pieces cost nothing beyond the substeps the flow takes anyway, and a
//! property checked on each piece sees how far a fast state moves in an
//! eighth of the period rather than in the whole period. `s` is fixed (not
//! adapted to the pieces' widths) so that the analysis and the
//! certificate's checker cut the period at the same instants.
//!
//! A substep whose enclosure fails (or meets a domain error or an overflow,
//! which a smaller step may avoid) is halved, at most [`MAX_HALVINGS`]
//! times below the initial step; after a success the step grows back when
//! the position allows. The controls and disturbances enter as parameters
//! with zero time derivative.

use super::interval::{DomainError, Interval};
use super::taylor::{check_field, eval_field, taylor_coefficients};
use super::tm::Tm;
use ravel_base::expr::VectorField;
use std::fmt;

/// How many times a substep may be halved below `period / substeps`.
pub const MAX_HALVINGS: u32 = 16;

/// Picard iterations tried for one a-priori enclosure.
const PICARD_ITERATIONS: usize = 10;

/// The integrator's settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Settings {
    /// The Taylor order `k` (clamped to `2..=20`).
    pub order: usize,
    /// The initial number of substeps per period (clamped to `1..=65536`);
    /// each may be halved up to [`MAX_HALVINGS`] times.
    pub substeps: usize,
}

impl Default for Settings {
    /// Order 6, 8 substeps.
    fn default() -> Settings {
        Settings {
            order: 6,
            substeps: 8,
        }
    }
}

/// The result of [`flow`].
#[derive(Clone, Debug, PartialEq)]
pub struct FlowOut {
    /// `x(period)` for every initial state, as models over the input's
    /// symbols.
    pub end: Vec<Tm>,
    /// A box containing `x(t)` for every `t ∈ [0, period]` and every
    /// initial state (the hull of the pieces).
    pub pipe: Vec<Interval>,
    /// `pieces[j]`: a box containing `x(t)` for every
    /// `t ∈ [j·period/s, (j+1)·period/s]` and every initial state, `s` the
    /// settings' initial substeps (clamped); the first piece contains the
    /// initial states' box, the last the end models' ranges.
    pub pieces: Vec<Vec<Interval>>,
    /// `piece_forms[j]`: models over the input's symbols holding `x(t)` for
    /// every `t` of piece `j` (the time expansion over the substep's whole
    /// span, `Σ x_[i]·[0, h]ⁱ + [0, h]ᵏ·x_[k](B)`, in model arithmetic), so
    /// that a property can be checked with the states' correlations;
    /// `None` for a piece made of several substeps (halvings).
    pub piece_forms: Vec<Option<Vec<Tm>>>,
}

/// Why no enclosure of the flow was found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlowError {
    /// A function met an argument outside its smooth domain.
    Domain(DomainError),
    /// No a-priori enclosure, even with the smallest step.
    NoEnclosure,
    /// A value overflowed or was not finite.
    Overflow,
    /// The vector field does not fit the sets (dimensions, a malformed
    /// tape) or the period is not a finite non-negative number.
    Malformed,
}

impl FlowError {
    /// A human reason.
    pub fn as_str(self) -> &'static str {
        match self {
            FlowError::Domain(d) => d.as_str(),
            FlowError::NoEnclosure => {
                "no a-priori enclosure of the flow, even with the smallest step"
            }
            FlowError::Overflow => "the enclosure overflowed or was not finite",
            FlowError::Malformed => {
                "the vector field does not fit the sets, or the period is invalid"
            }
        }
    }
}

impl fmt::Display for FlowError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::error::Error for FlowError {}

impl From<DomainError> for FlowError {
    fn from(e: DomainError) -> FlowError {
        match e {
            DomainError::NotFinite => FlowError::Overflow,
            e => FlowError::Domain(e),
        }
    }
}

/// The ranges of models, checked finite.
fn ranges(x: &[Tm]) -> Result<Vec<Interval>, FlowError> {
    x.iter()
        .map(|t| t.range().checked().map_err(FlowError::from))
        .collect()
}

/// The componentwise hull of two boxes.
fn hull(a: &[Interval], b: &[Interval]) -> Result<Vec<Interval>, FlowError> {
    a.iter()
        .zip(b)
        .map(|(x, y)| x.hull(*y).checked().map_err(FlowError::from))
        .collect()
}

/// The parameters `[u, w]` of the models, checked finite.
fn params(u: &[Tm], w: &[Tm]) -> Result<Vec<Tm>, FlowError> {
    u.iter()
        .chain(w)
        .map(|t| t.clone().checked().map_err(FlowError::from))
        .collect()
}

/// `x⁺ = f(x, u, w)` in Taylor-model arithmetic (discrete time).
pub fn image(field: &VectorField, x: &[Tm], u: &[Tm], w: &[Tm]) -> Result<Vec<Tm>, FlowError> {
    let p = params(u, w)?;
    let x: Vec<Tm> = x
        .iter()
        .map(|t| t.clone().checked())
        .collect::<Result<_, _>>()?;
    let out = eval_field(field, &x, &p)?;
    out.into_iter().map(|t| Ok(t.checked()?)).collect()
}

/// The validated flow over `period` (see the module doc).
pub fn flow(
    field: &VectorField,
    x: &[Tm],
    u: &[Tm],
    w: &[Tm],
    period: f64,
    s: &Settings,
) -> Result<FlowOut, FlowError> {
    flow_scaled(field, x, u, w, period, s, 1.0)
}

/// [`flow`] with every Lagrange remainder's width multiplied by
/// `remainder_scale` around its midpoint: `1.0` in production; the tests
/// shrink it to show that they catch an unsound remainder.
pub(crate) fn flow_scaled(
    field: &VectorField,
    x: &[Tm],
    u: &[Tm],
    w: &[Tm],
    period: f64,
    s: &Settings,
    remainder_scale: f64,
) -> Result<FlowOut, FlowError> {
    let p = params(u, w)?;
    check_field(field, x.len(), p.len())?;
    if !(period.is_finite() && period >= 0.0) {
        return Err(FlowError::Malformed);
    }
    let mut cur: Vec<Tm> = x
        .iter()
        .map(|t| t.clone().checked())
        .collect::<Result<_, _>>()?;
    let pr = ranges(&p)?;
    let start = ranges(&cur)?;
    let substeps = s.substeps.clamp(1, 1 << 16) as u64;
    if period == 0.0 {
        let pieces = vec![start.clone(); substeps as usize];
        return Ok(FlowOut {
            end: cur,
            pipe: start,
            pieces,
            piece_forms: vec![None; substeps as usize],
        });
    }
    // every piece starts as the first enclosure that falls in it
    let mut pieces: Vec<Option<Vec<Interval>>> = vec![None; substeps as usize];
    // per piece: how many substeps fell in it, and the first one's models
    let mut forms: Vec<(u32, Option<Vec<Tm>>)> = vec![(0, None); substeps as usize];
    if let Some(first) = pieces.first_mut() {
        *first = Some(start);
    }
    let order = s.order.clamp(2, 20);
    let total = substeps << MAX_HALVINGS;
    let (mut pos, mut depth) = (0u64, 0u32);
    let ctx = Step {
        field,
        params: &p,
        pr: &pr,
        order,
        scale: remainder_scale,
    };
    while pos < total {
        let units = 1u64 << (MAX_HALVINGS - depth);
        let parts = (substeps << depth) as f64;
        let h = Interval::point(period).div(Interval::point(parts))?;
        match ctx.run(&cur, h) {
            Ok((next, enclosure, form)) => {
                cur = next;
                // a substep `[pos, pos + units)` lies in the initial
                // substep `pos / 2^MAX_HALVINGS` (the halvings are dyadic)
                let slot = forms
                    .get_mut((pos >> MAX_HALVINGS) as usize)
                    .ok_or(FlowError::Malformed)?;
                slot.0 += 1;
                slot.1 = (slot.0 == 1).then_some(form);
                let piece = pieces
                    .get_mut((pos >> MAX_HALVINGS) as usize)
                    .ok_or(FlowError::Malformed)?;
                *piece = Some(match piece.take() {
                    None => enclosure,
                    Some(b) => hull(&b, &enclosure)?,
                });
                pos += units;
                if depth > 0 && pos % (2 * units) == 0 {
                    depth -= 1;
                }
            }
            Err(FlowError::Malformed) => return Err(FlowError::Malformed),
            Err(e) if depth >= MAX_HALVINGS => return Err(e),
            Err(_) => depth += 1,
        }
    }
    let mut pieces: Vec<Vec<Interval>> = pieces
        .into_iter()
        .collect::<Option<_>>()
        .ok_or(FlowError::Malformed)?;
    let last = pieces.last_mut().ok_or(FlowError::Malformed)?;
    *last = hull(last, &ranges(&cur)?)?;
    let mut pipe = pieces.first().cloned().ok_or(FlowError::Malformed)?;
    for b in pieces.iter().skip(1) {
        pipe = hull(&pipe, b)?;
    }
    Ok(FlowOut {
        end: cur,
        pipe,
        pieces,
        piece_forms: forms
            .into_iter()
            .map(|(k, f)| f.filter(|_| k == 1))
            .collect(),
    })
}

/// What every substep shares.
struct Step<'a> {
    field: &'a VectorField,
    params: &'a [Tm],
    /// The parameters' ranges.
    pr: &'a [Interval],
    order: usize,
    scale: f64,
}

impl Step<'_> {
    /// One substep of size `h`: the models at its end, the enclosure of
    /// the states over it, and models holding those states.
    #[allow(clippy::type_complexity)]
    fn run(&self, cur: &[Tm], h: Interval) -> Result<(Vec<Tm>, Vec<Interval>, Vec<Tm>), FlowError> {
        let x0 = ranges(cur)?;
        let b = apriori(self.field, &x0, self.pr, h.hi)?;
        // the Lagrange remainder's coefficient x_[k](B)
        let over_b = taylor_coefficients::<Interval>(self.field, &b, self.pr, self.order)?;
        let rem_k: Vec<Interval> = over_b
            .iter()
            .map(|c| c.last().copied().ok_or(FlowError::Malformed))
            .collect::<Result<_, _>>()?;
        let poly = taylor_coefficients::<Tm>(self.field, cur, self.params, self.order - 1)?;
        let order = i32::try_from(self.order).map_err(|_| FlowError::Malformed)?;
        let span = Interval::new(0.0, h.hi);
        let (hk, span_k) = (h.powi(order)?, span.powi(order)?);
        let mut end = Vec::with_capacity(cur.len());
        let mut enclosure = Vec::with_capacity(cur.len());
        let mut forms = Vec::with_capacity(cur.len());
        for ((coeffs, rk), bi) in poly.iter().zip(&rem_k).zip(&b) {
            let rem = self.shrink((hk * *rk).checked()?);
            end.push(horner(coeffs, h)?.add_interval(rem)?);
            let rem_span = self.shrink((span_k * *rk).checked()?);
            let over = horner(coeffs, span)?.add_interval(rem_span)?;
            let inter = over.range().checked()?;
            forms.push(over);
            // both enclose x(t); an empty intersection cannot happen in
            // exact arithmetic, and then B alone is kept
            enclosure.push(inter.intersect(*bi).unwrap_or(*bi));
        }
        Ok((end, enclosure, forms))
    }

    /// The remainder scaled around its midpoint by the test knob.
    fn shrink(&self, r: Interval) -> Interval {
        if self.scale == 1.0 {
            return r;
        }
        let (m, rad) = (r.mid(), r.rad() * self.scale);
        Interval::new(m - rad, m + rad)
    }
}

/// `Σ cᵢ tⁱ` by Horner's rule for every `t ∈ t_iv`.
fn horner(coeffs: &[Tm], t: Interval) -> Result<Tm, FlowError> {
    let mut it = coeffs.iter().rev();
    let mut acc = it.next().cloned().ok_or(FlowError::Malformed)?;
    for c in it {
        acc = acc.mul_interval(t)?.add(c)?;
    }
    Ok(acc)
}

/// A box containing every solution from `x0` over `[0, h]` (Picard
/// iteration with inflation), or [`FlowError::NoEnclosure`].
fn apriori(
    field: &VectorField,
    x0: &[Interval],
    pr: &[Interval],
    h: f64,
) -> Result<Vec<Interval>, FlowError> {
    let t = Interval::new(0.0, h);
    let step = |b: &[Interval]| -> Result<Vec<Interval>, FlowError> {
        let f = eval_field(field, b, pr)?;
        x0.iter()
            .zip(&f)
            .map(|(x, fi)| (*x + t * *fi).checked().map_err(FlowError::from))
            .collect()
    };
    let mut b = step(x0)?;
    for _ in 0..PICARD_ITERATIONS {
        let trial: Vec<Interval> = b.iter().map(|&bi| inflate(bi)).collect();
        let n = step(&trial)?;
        if trial
            .iter()
            .zip(&n)
            .all(|(bt, ni)| bt.strictly_contains(*ni))
        {
            return Ok(n);
        }
        b = n;
    }
    Err(FlowError::NoEnclosure)
}

/// `b` widened by a tenth of its width and `10⁻¹²·(1 + |b|)` on each side.
fn inflate(b: Interval) -> Interval {
    let e = 0.1 * (b.hi - b.lo) + 1e-12 * (1.0 + b.mag());
    Interval::new((b.lo - e).next_down(), (b.hi + e).next_up())
}
