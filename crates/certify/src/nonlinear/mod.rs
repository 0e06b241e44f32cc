//! Certificates of nonlinear plants: the checker re-derives every claimed
//! step from the previous one with its own validated integration
//! ([`flow`], in its own arithmetic [`arith`]) and answers VALID only for
//! what that arithmetic proved.
//!
//! # The claims
//!
//! The evidence lists, per cell, its box and one claimed set per step
//! `0..=S`: a zonotope `{c + G s : s ∈ [−1, 1]ᵏ}` whose columns carry
//! symbol ids. Step `t + 1`'s columns are either *kept* (an id of step
//! `t`: the same symbol, the same value along every trajectory) or
//! *fresh* (any other id). Fresh columns must be axis-aligned (one non-zero
//! entry): together they span a box `[−F, F]`.
//!
//! # The check of one step
//!
//! The checker writes the state of step `t` as affine forms over step
//! `t`'s symbols, bounds the controller over the observation set with its
//! own back-substitution (`bounds.rs`; the network preceded by the exact
//! affine layer from the symbols and error intervals to the observation),
//! composes the middle of the two linear bounds, which are linear in the
//! symbols, with the state (the distance to either bound an interval)
//! and integrates the plant over the period (or applies the map). The
//! image `c' + A s + ε` is inside the claim of step `t + 1` when, in every
//! component `i`,
//! `|c'ᵢ − cᵢ| + Σ_kept |Aᵢⱼ − Gᵢⱼ| + Σ_dropped |Aᵢⱼ| + eᵢ ≤ Fᵢ`
//! (outward-rounded; then for every value of the old symbols the kept ones
//! keep their values and the fresh ones take up the rest). Step 0 is the
//! same check with the cell's box as the image. By induction every
//! trajectory from the cell is in every claimed set.
//!
//! Goals are checked on the claimed set of the horizon, avoid sets on the
//! claimed sets of their steps and, for continuous time, on the checker's
//! own enclosures of the periods in the window (the period ending at step
//! `t` when `t − 1` is in it), as the analysis does. A FALSIFIED verdict is
//! replayed: the recorded initial state and noise are checked against
//! their sets and the single trajectory is enclosed by the same
//! integration.

pub mod arith;
pub mod flow;

use nalgebra::DMatrix;
use serde_json::Value;

use super::{
    decide, evidence_cells, get, read_initial, read_properties, slope_steps, uint, vector, Answer,
    CSet, Form, Initial, Prop, Report, FORMAT, R,
};
use crate::bounds::{network_box, Bx, NetBounds};
use crate::cover;
use arith::{Af, Fail, Iv, Num};
use flow::Field;
use ravel_base::nn::{Layer, Network};
use ravel_base::text::sanitize;

/// A nonlinear problem as the checker reads it.
struct Problem {
    field: Field,
    horizon: usize,
    /// `n × q`: `y = Cᵀ x + v`.
    obs: DMatrix<f64>,
    /// Disturbance box (`d`).
    w: Vec<Iv>,
    /// Sensor noise box (`q`).
    v: Vec<Iv>,
    initial: Initial,
    props: Vec<(String, Prop)>,
}

fn iv_box(v: &Value, len: usize, what: &str) -> R<Vec<Iv>> {
    let lo = vector(get(v, "lo")?, len, what)?;
    let hi = vector(get(v, "hi")?, len, what)?;
    if lo.iter().zip(&hi).any(|(l, h)| l > h) {
        return Err(format!("`{what}` is not a box (lo > hi somewhere)"));
    }
    Ok(lo.iter().zip(&hi).map(|(&l, &h)| Iv::new(l, h)).collect())
}

impl Problem {
    fn read(p: &Value, net: &Network) -> R<Problem> {
        let n = uint(get(p, "states")?, "states")?;
        let m = uint(get(p, "controls")?, "controls")?;
        let d = uint(get(p, "disturbances")?, "disturbances")?;
        let q = uint(get(p, "observations")?, "observations")?;
        let horizon = uint(get(p, "horizon")?, "horizon")?;
        let max = ravel_base::limits::MAX_DIM as usize;
        if n == 0 || n > max || m > max || q > max || d > max {
            return Err("dimensions out of range".into());
        }
        if horizon > ravel_base::limits::MAX_HORIZON as usize {
            return Err("horizon out of range".into());
        }
        if net.inputs != q || net.outputs() != m {
            return Err(format!(
                "the controller maps {} inputs to {} outputs; the problem needs {q} → {m}",
                net.inputs,
                net.outputs()
            ));
        }
        Ok(Problem {
            field: Field::read(p, n, m, d)?,
            horizon,
            obs: super::matrix(get(p, "observation")?, n, q, "observation")?,
            w: iv_box(get(p, "disturbance")?, d, "disturbance")?,
            v: iv_box(get(p, "sensor_noise")?, q, "sensor_noise")?,
            initial: read_initial(p, n)?,
            props: read_properties(p, n, horizon)?,
        })
    }

    fn n(&self) -> usize {
        self.field.n
    }

    /// `y = Cᵀ x + v` over the forms (or intervals) `x`, with the noise `v`.
    fn observe<T: Num>(&self, x: &[T], v: &[Iv]) -> Vec<T> {
        observe(&self.obs, x, v)
    }
}

/// A box of the states of a linear plant in continuous time over the
/// period after step `t`, from the claimed box `x` of step `t` (its own
/// symbols) with the controls in the checker's bound of the network over
/// the observation set (sensor noise `v`): the hull of
/// [`intersample_pieces`]' eighths; `None` when the flow cannot be
/// enclosed.
pub(crate) fn intersample(
    flows: &[Field],
    t: usize,
    obs: &DMatrix<f64>,
    v: &Bx,
    net: &Network,
    x: &Bx,
) -> Option<Bx> {
    let pieces = intersample_pieces(flows, t, obs, v, net, x, flow::SUBSTEPS[0])?;
    let (first, rest) = pieces.split_first()?;
    Some(rest.iter().fold(first.clone(), |h, b| Bx {
        lo: h.lo.iter().zip(&b.lo).map(|(p, q)| p.min(*q)).collect(),
        hi: h.hi.iter().zip(&b.hi).map(|(p, q)| p.max(*q)).collect(),
    }))
}

/// The states of a linear plant in continuous time over the period after
/// step `t`, cut into `substeps` pieces in time order, each a box of the
/// states over its `1/substeps` of the period, from the box `x` of step
/// `t` (for a trajectory's replay: its enclosure at step `t`, `v` its
/// recorded sensor noise); `None` when the flow cannot be enclosed or a
/// piece is not finite.
pub(crate) fn intersample_pieces(
    flows: &[Field],
    t: usize,
    obs: &DMatrix<f64>,
    v: &Bx,
    net: &Network,
    x: &Bx,
    substeps: u32,
) -> Option<Vec<Bx>> {
    let field = flows.get(t.min(flows.len().checked_sub(1)?))?;
    let n = x.lo.len();
    let xs: Vec<Af> =
        x.lo.iter()
            .zip(&x.hi)
            .enumerate()
            .map(|(i, (&lo, &hi))| {
                let c = 0.5 * lo + 0.5 * hi;
                let mut g = vec![0.0; n];
                if let Some(gi) = g.get_mut(i) {
                    *gi = (hi - c).max(c - lo).max(0.0).next_up();
                }
                Af::exact(c, g)
            })
            .collect();
    let noise = box_ivs(v);
    let parts = Parts {
        field,
        obs,
        v: &noise,
        w: &[],
    };
    let pieces = compose(&parts, net, xs, 0, substeps).ok()?.between?;
    let boxes: Vec<Bx> = pieces.iter().map(|p| hull_box(p)).collect();
    boxes
        .iter()
        .all(|b| b.lo.iter().chain(&b.hi).all(|v| v.is_finite()))
        .then_some(boxes)
}

/// `y = Cᵀ x + v` over the forms (or intervals) `x`, with the noise `v`.
fn observe<T: Num>(obs: &DMatrix<f64>, x: &[T], v: &[Iv]) -> Vec<T> {
    let Some(zero) = x.first().map(|e| e.cst(0.0)) else {
        return Vec::new();
    };
    obs.column_iter()
        .zip(v)
        .map(|(col, v)| {
            col.iter()
                .zip(x)
                .fold(zero.clone(), |s, (a, xi)| s.add(&xi.scale(*a)))
                .add_iv(v)
        })
        .collect()
}

/// The checker's answer about a nonlinear plant's certificate.
pub fn check(cert: &Value, net: &Network) -> Report {
    let mut report = Report::empty();
    match check_inner(cert, net, &mut report) {
        Ok(answer) => report.answer = answer,
        Err(e) => report.answer = Answer::Unreadable(e),
    }
    report
}

fn check_inner(cert: &Value, net: &Network, report: &mut Report) -> R<Answer> {
    if get(cert, "format")?.as_str() != Some(FORMAT) {
        return Err(format!("`format` must be {FORMAT}"));
    }
    let problem = Problem::read(get(cert, "problem")?, net).map_err(|e| format!("problem: {e}"))?;
    let verdicts = get(cert, "verdicts")?
        .as_array()
        .ok_or("`verdicts` must be an array")?;
    if verdicts.len() != problem.props.len() {
        return Err(format!(
            "{} verdicts for {} properties",
            verdicts.len(),
            problem.props.len()
        ));
    }
    let mut invalid: Option<String> = None;
    let mut unsupported: Option<String> = None;
    let mut verified = Vec::new();
    for (i, (v, named)) in verdicts.iter().zip(&problem.props).enumerate() {
        let (name, prop) = named;
        if get(v, "property")?.as_str() != Some(name.as_str()) {
            return Err(format!(
                "verdict {i} is not about property `{}`",
                sanitize(name)
            ));
        }
        let shown = sanitize(name);
        match get(v, "status")?.as_str() {
            Some("VERIFIED") => verified.push(named),
            Some("UNSURE") => report
                .properties
                .push(format!("{shown}: UNSURE (no claim)")),
            Some("FALSIFIED") => {
                let (step, between) = super::falsified_claim(v, i)?;
                let replayed = if between {
                    replay_between(&problem, net, prop, step, get(v, "trajectory")?)?
                } else {
                    replay(&problem, net, prop, step, get(v, "trajectory")?)?
                };
                super::record_replay(report, &mut invalid, &shown, step, between, replayed);
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
        let names = |tail: &str| -> Vec<String> {
            verified
                .iter()
                .map(|(name, _)| format!("{}: VERIFIED{tail}", sanitize(name)))
                .collect()
        };
        match get(ev, "status")?.as_str() {
            Some("checkable") => {
                let needed = verified
                    .iter()
                    .map(|(_, p)| super::needed_step(p, problem.horizon))
                    .max()
                    .unwrap_or(0);
                match evidence(&problem, net, ev, needed, &verified, report)? {
                    Ok(()) => report.properties.extend(names(" (checked)")),
                    Err(msg) => {
                        report.properties.extend(names(" — not established"));
                        report.evidence_failure = Some(msg.clone());
                        invalid.get_or_insert(msg);
                    }
                }
            }
            Some("unsupported") => {
                let why = get(ev, "reason")?.as_str().unwrap_or("no reason given");
                let why = ravel_base::text::sanitize_to(why, 600);
                report
                    .properties
                    .extend(names(&format!(" — not checkable: {why}")));
                unsupported.get_or_insert(why);
            }
            _ => return Err("`evidence.status` must be \"checkable\" or \"unsupported\"".into()),
        }
    }
    Ok(decide(invalid, unsupported))
}

/// One claimed zonotope.
struct Zono {
    c: Vec<f64>,
    /// `n` rows of `ids.len()` coefficients.
    g: Vec<Vec<f64>>,
    ids: Vec<u64>,
}

impl Zono {
    fn read(v: &Value, n: usize) -> R<Zono> {
        let c = vector(get(v, "c")?, n, "claim centre")?;
        let ids: Vec<u64> = get(v, "ids")?
            .as_array()
            .ok_or("`ids` must be an array")?
            .iter()
            .map(|i| i.as_u64().ok_or("an id must be a non-negative integer"))
            .collect::<Result<_, _>>()?;
        let mut sorted = ids.clone();
        sorted.sort_unstable();
        if sorted.windows(2).any(|w| w.first() == w.get(1)) {
            return Err("a claim names one symbol twice".into());
        }
        if ids.len() > 64 * n + 64 {
            return Err("a claim has more symbols than any analysis keeps".into());
        }
        let rows = get(v, "g")?.as_array().ok_or("`g` must be an array")?;
        if rows.len() != n {
            return Err(format!("`g` has {} rows, expected {n}", rows.len()));
        }
        let g = rows
            .iter()
            .map(|r| vector(r, ids.len(), "claim coefficients"))
            .collect::<R<Vec<_>>>()?;
        Ok(Zono { c, g, ids })
    }

    /// The set as affine forms over its own symbols.
    fn forms(&self) -> Vec<Af> {
        self.c
            .iter()
            .zip(&self.g)
            .map(|(&c, g)| Af::exact(c, g.clone()))
            .collect()
    }

    /// An upper bound of `a·x` over the set.
    fn support(&self, a: &[f64]) -> f64 {
        let forms = self.forms();
        let mut acc: Option<Af> = None;
        for (ai, f) in a.iter().zip(&forms) {
            let t = f.scale(*ai);
            acc = Some(match acc {
                None => t,
                Some(s) => s.add(&t),
            });
        }
        acc.map_or(f64::INFINITY, |s| s.range().hi)
    }

    /// A lower bound of `a·x` over the set.
    fn support_lower(&self, a: &[f64]) -> f64 {
        let neg: Vec<f64> = a.iter().map(|v| -v).collect();
        -self.support(&neg)
    }

    /// A box holding the set.
    fn bbox(&self) -> Bx {
        let r: Vec<Iv> = self.forms().iter().map(Num::range).collect();
        Bx {
            lo: r.iter().map(|i| i.lo).collect(),
            hi: r.iter().map(|i| i.hi).collect(),
        }
    }
}

/// Whether `image` (forms over the symbols `prev`) lies in `claim` (see the
/// module's doc); why not, for people.
fn inside(image: &[Af], prev: &[u64], claim: &Zono) -> Result<(), String> {
    let n = claim.c.len();
    // each fresh column: axis-aligned
    let mut room = vec![Vec::new(); n];
    let mut kept: Vec<(usize, usize)> = Vec::new(); // (claim column, image position)
    for (j, id) in claim.ids.iter().enumerate() {
        if let Some(p) = prev.iter().position(|q| q == id) {
            kept.push((j, p));
            continue;
        }
        let nonzero: Vec<usize> = (0..n)
            .filter(|&i| {
                claim
                    .g
                    .get(i)
                    .and_then(|r| r.get(j))
                    .is_some_and(|v| *v != 0.0)
            })
            .collect();
        match nonzero.as_slice() {
            [] => {}
            [i] => {
                if let (Some(r), Some(v)) =
                    (room.get_mut(*i), claim.g.get(*i).and_then(|r| r.get(j)))
                {
                    r.push(v.abs());
                }
            }
            _ => return Err(format!("fresh symbol {id} is not axis-aligned")),
        }
    }
    for (i, ((f, c), g)) in image.iter().zip(&claim.c).zip(&claim.g).enumerate() {
        let mut used_kept = vec![false; f.g.len()];
        let mut terms = Vec::new();
        for &(j, p) in &kept {
            let a = f.g.get(p).copied().unwrap_or(0.0);
            let b = g.get(j).copied().unwrap_or(0.0);
            if a != b {
                terms.push((a - b).abs().next_up());
            }
            if let Some(u) = used_kept.get_mut(p) {
                *u = true;
            }
        }
        for (p, a) in f.g.iter().enumerate() {
            if !used_kept.get(p).copied().unwrap_or(false) {
                terms.push(a.abs());
            }
        }
        // (a sum with a zero term is exact; otherwise one step up)
        let up_add = |a: f64, t: f64| {
            if t == 0.0 {
                a
            } else if a == 0.0 {
                t
            } else {
                (a + t).next_up()
            }
        };
        let spread = terms.iter().fold(0.0, |a, &t| up_add(a, t));
        // the residual c' − c + (A − G)s + ε ∈ [lo, hi]
        let (d_lo, d_hi) = if f.c == *c {
            (0.0, 0.0)
        } else {
            ((f.c - c).next_down(), (f.c - c).next_up())
        };
        // (signed sums rounded up: one step up after any inexact addition)
        let need = up_add(up_add(d_hi, f.hi), spread).max(up_add(up_add(-d_lo, -f.lo), spread));
        let have = room.get(i).into_iter().flatten().fold(0.0, |a: f64, &t| {
            if a == 0.0 {
                t
            } else {
                (a + t).next_down()
            }
        });
        if need.is_nan() || have.is_nan() || need > have {
            return Err(format!(
                "x[{i}]: the checker's image needs a room of {}, the claim leaves {}",
                ravel_base::text::compact(need),
                ravel_base::text::compact(have)
            ));
        }
    }
    Ok(())
}

/// One cell's checked claims and the checker's own period enclosures
/// (`between[t]`: the period ending at step `t`, in pieces; none at step 0).
struct CellChain {
    start: Bx,
    claims: Vec<Zono>,
    between: Vec<Option<Vec<Vec<Iv>>>>,
    /// `forms[t][j]`: forms holding piece `j` of `between[t]`, where the
    /// checker's integration kept them.
    forms: Vec<Vec<Option<Vec<Af>>>>,
}

/// Check the evidence; `Ok(Err(msg))` is the first false claim.
fn evidence(
    problem: &Problem,
    net: &Network,
    ev: &Value,
    needed: usize,
    verified: &[&(String, Prop)],
    report: &mut Report,
) -> R<Result<(), String>> {
    let steps = uint(get(ev, "steps")?, "evidence.steps")?;
    if steps < needed || steps > problem.horizon {
        return Ok(Err(format!(
            "the evidence covers steps 0..={steps}, the verified properties need 0..={needed}"
        )));
    }
    let slopes = slope_steps(ev)?;
    let cells_json = evidence_cells(ev)?;
    let mut chains = Vec::with_capacity(cells_json.len());
    // the cells are independent: re-derived on every core, read in order
    let derived = par_map(cells_json, |cell| {
        cell_chain(problem, net, cell, steps, slopes)
    });
    for (c, chain) in derived.into_iter().enumerate() {
        match chain? {
            Ok(ch) => chains.push(ch),
            Err(why) => return Ok(Err(format!("cell {c}, {why}"))),
        }
    }
    let cells: Vec<Bx> = chains.iter().map(|ch| ch.start.clone()).collect();
    let x0 = &problem.initial;
    match cover::covers(&cells, &x0.bbox(), &|b| x0.misses(b)) {
        Ok(()) => {}
        Err(Some(p)) => {
            return Ok(Err(format!(
                "the cells do not cover the initial set: {p:?} is in no cell"
            )))
        }
        Err(None) => {
            return Err(
                "the cells' coverage of the initial set could not be decided within the work limit"
                    .into(),
            )
        }
    }
    for (name, prop) in verified {
        for (c, chain) in chains.iter().enumerate() {
            if let Err(why) = proves(problem, net, slopes, prop, chain) {
                return Ok(Err(format!(
                    "property `{}`, cell {c}: {why}",
                    sanitize(name)
                )));
            }
        }
    }
    report.cells = cells.len();
    report.steps = steps;
    Ok(Ok(()))
}

/// `f` of every item, in the items' order, computed on every available
/// core (each thread takes the next item not yet taken); the answer is the
/// same whatever the number of threads.
fn par_map<T: Sync, U: Send>(items: &[T], f: impl Fn(&T) -> U + Sync) -> Vec<U> {
    let threads = std::thread::available_parallelism()
        .map_or(1, std::num::NonZeroUsize::get)
        .min(items.len());
    if threads <= 1 {
        return items.iter().map(f).collect();
    }
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut done: Vec<(usize, U)> = std::thread::scope(|s| {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                s.spawn(|| {
                    let mut mine = Vec::new();
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(item) = items.get(i) else {
                            break;
                        };
                        mine.push((i, f(item)));
                    }
                    mine
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|w| w.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    });
    done.sort_by_key(|(i, _)| *i);
    done.into_iter().map(|(_, u)| u).collect()
}

/// Read and check one cell's chain: `Ok(Err(why))` for a false claim.
fn cell_chain(
    problem: &Problem,
    net: &Network,
    cell: &Value,
    steps: usize,
    slopes: usize,
) -> R<Result<CellChain, String>> {
    let n = problem.n();
    let start = super::claimed_box(get(cell, "box")?, n, "cell box")?;
    if !start.is_proper() {
        return Ok(Err("its box is empty".into()));
    }
    let claims_json = get(cell, "claims")?
        .as_array()
        .ok_or("`claims` must be an array")?;
    if claims_json.len() != steps + 1 {
        return Err(format!(
            "a cell has {} claims, expected {}",
            claims_json.len(),
            steps + 1
        ));
    }
    let claims = claims_json
        .iter()
        .map(|z| Zono::read(z, n))
        .collect::<R<Vec<_>>>()?;
    let Some(first) = claims.first() else {
        return Err("a cell has no claims".into());
    };
    // step 0: the cell's box, as forms without symbols around the claim's centre
    let cell_forms: Vec<Af> = start
        .lo
        .iter()
        .zip(&start.hi)
        .zip(&first.c)
        .map(|((&lo, &hi), &c)| Af {
            c,
            g: Vec::new(),
            lo: if lo == c {
                0.0
            } else {
                (lo - c).next_down().min(0.0)
            },
            hi: if hi == c {
                0.0
            } else {
                (hi - c).next_up().max(0.0)
            },
        })
        .collect();
    if let Err(why) = inside(&cell_forms, &[], first) {
        return Ok(Err(format!("step 0: {why}")));
    }
    let mut between = vec![None];
    let mut forms = vec![Vec::new()];
    for (t, pair) in claims.windows(2).enumerate() {
        let (Some(now), Some(next)) = (pair.first(), pair.get(1)) else {
            continue;
        };
        let mut last = String::new();
        let mut proven = None;
        for substeps in flow::SUBSTEPS {
            match advance(problem, net, now, slopes, substeps) {
                Ok(s) => match inside(&s.end, &now.ids, next) {
                    Ok(()) => {
                        proven = Some(s);
                        break;
                    }
                    Err(why) => last = why,
                },
                Err(why) => last = format!("the checker cannot re-derive it ({why})"),
            }
        }
        let Some(stepped) = proven else {
            return Ok(Err(format!("step {}: {last}", t + 1)));
        };
        between.push(stepped.between);
        forms.push(stepped.forms);
    }
    Ok(Ok(CellChain {
        start,
        claims,
        between,
        forms,
    }))
}

/// The checker's image of one claimed set over one period.
fn advance(
    problem: &Problem,
    net: &Network,
    now: &Zono,
    slopes: usize,
    substeps: u32,
) -> Result<flow::Period<Af>, String> {
    let parts = Parts {
        field: &problem.field,
        obs: &problem.obs,
        v: &problem.v,
        w: &problem.w,
    };
    compose(&parts, net, now.forms(), slopes, substeps)
}

/// What one period of a loop needs besides the controller.
struct Parts<'a> {
    field: &'a Field,
    /// `n × q`: `y = Cᵀ x + v`.
    obs: &'a DMatrix<f64>,
    v: &'a [Iv],
    w: &'a [Iv],
}

/// The state `x` (forms over its symbols) over one period: the controls
/// the middle of the checker's two linear bounds of the network over the
/// observation set (see [`over_symbols`]), linear in `x`'s symbols (the
/// distance to either bound an interval), the plant integrated (or mapped)
/// with them held.
fn compose(
    parts: &Parts,
    net: &Network,
    x: Vec<Af>,
    slopes: usize,
    substeps: u32,
) -> Result<flow::Period<Af>, String> {
    let k = x.first().map_or(0, |f| f.g.len());
    let y = observe(parts.obs, &x, parts.v);
    let (snet, sbox) = over_symbols(net, &y, k)?;
    let nb = NetBounds::new(&snet, &sbox, None).map_err(|t| t.to_string())?;
    let (up, up_off, low, low_off) = nb.output_lines(slopes);
    let siv = box_ivs(&sbox);
    let mut u = Vec::with_capacity(up.nrows());
    for r in 0..up.nrows() {
        let (ou, ol) = (up_off.get(r).copied(), low_off.get(r).copied());
        let (Some(ou), Some(ol)) = (ou, ol) else {
            return Err("malformed controller bounds".into());
        };
        let mid: Vec<f64> = up
            .row(r)
            .iter()
            .zip(low.row(r).iter())
            .map(|(a, b)| 0.5 * a + 0.5 * b)
            .collect();
        let m0 = 0.5 * ou + 0.5 * ol;
        // u − (M s + m₀) ∈ [(L − M) s + l − m₀, (U − M) s + ū − m₀] over S
        let hi = gap(up.row(r).iter(), &mid, &siv, ou, m0).hi;
        let lo = gap(low.row(r).iter(), &mid, &siv, ol, m0).lo;
        if !(lo.is_finite() && hi.is_finite()) || lo > hi || mid.len() != siv.len() {
            return Err("the controller's bounds are not finite".into());
        }
        // M s = M_z z + M_ε ε: the first part kept, the second an interval
        let mut rest = Iv::new(lo, hi);
        for (a, e) in mid.iter().zip(&siv).skip(k) {
            rest = rest.add(&e.scale(*a));
        }
        let (Some(mz), true) = (mid.get(..k), rest.is_finite()) else {
            return Err("the controller's bounds are not finite".into());
        };
        u.push(Af::exact(m0, mz.to_vec()).add_iv(&rest));
    }
    let w: Vec<Af> = parts.w.iter().map(|i| Af::of_iv(i, k)).collect();
    flow::period(parts.field, &x, &u, &w, substeps).map_err(|e: Fail| e.to_string())
}

/// The network preceded by the exact affine layer `(s, ε) ↦ c + G s + ε`
/// of the observation's forms `y` over `k` symbols, and the box of its
/// inputs (`s ∈ [−1, 1]ᵏ`, `ε` in each form's error interval): the
/// controller bounded over the observation set itself, not its box, with
/// bounds linear in the symbols.
fn over_symbols(net: &Network, y: &[Af], k: usize) -> Result<(Network, Bx), String> {
    let q = y.len();
    let ok = y
        .iter()
        .all(|f| f.g.len() == k && f.c.is_finite() && f.lo.is_finite() && f.hi.is_finite());
    if !ok || y.iter().any(|f| f.g.iter().any(|v| !v.is_finite())) {
        return Err("the observation is not finite".into());
    }
    let w = DMatrix::from_fn(q, k + q, |j, i| match (y.get(j), i.checked_sub(k)) {
        (Some(f), None) => f.g.get(i).copied().unwrap_or(0.0),
        (_, Some(e)) if e == j => 1.0,
        _ => 0.0,
    });
    let b = nalgebra::DVector::from_iterator(q, y.iter().map(|f| f.c));
    let mut layers = Vec::with_capacity(net.layers.len() + 1);
    layers.push(Layer::Affine { w, b });
    layers.extend(net.layers.iter().cloned());
    let sbox = Bx {
        lo: (0..k).map(|_| -1.0).chain(y.iter().map(|f| f.lo)).collect(),
        hi: (0..k).map(|_| 1.0).chain(y.iter().map(|f| f.hi)).collect(),
    };
    Ok((
        Network::new(k + q, layers).with_input_type(net.input_type),
        sbox,
    ))
}

/// `(A − M)·Y + a − m₀` as an outward-rounded interval.
fn gap<'a>(a: impl Iterator<Item = &'a f64>, mid: &[f64], y: &[Iv], off: f64, m0: f64) -> Iv {
    let mut acc = Iv::point(off).sub(&Iv::point(m0));
    for ((a, m), yj) in a.zip(mid).zip(y) {
        let d = Iv::point(*a).sub(&Iv::point(*m));
        acc = acc.add(&d.mul(yj));
    }
    acc
}

/// A claim as an affine form for the constraints' mean value bound.
fn zono_form(z: &Zono) -> Form<'_> {
    Form {
        c: &z.c,
        g: &z.g,
        e_lo: vec![0.0; z.c.len()],
        e_hi: vec![0.0; z.c.len()],
    }
}

/// Whether one claimed set lies in the set `s` (rows by the zonotope's
/// support, constraints by the mean value form over it).
fn claim_in(z: &Zono, s: &CSet) -> bool {
    s.rows.iter().all(|(a, b)| {
        let top = z.support(a);
        !top.is_nan() && top <= *b
    }) && s.constraints_hold_on_form(&z.bbox(), Some(&zono_form(z)))
}

/// Whether one claimed set misses the set `s` (a row by the zonotope's
/// support, or anything [`CSet::missed_by_form`] shows over its box).
fn claim_misses(z: &Zono, s: &CSet) -> bool {
    s.rows.iter().any(|(a, b)| z.support_lower(a) > *b)
        || s.missed_by_form(&z.bbox(), Some(&zono_form(z)))
}

/// Whether one piece of a period shows the property: over its box, or,
/// for the constraints, by the mean value form over its forms (when kept,
/// over the box of their ranges cut to the piece's: both hold the states).
fn piece_shows(prop: &Prop, piece: &[Iv], forms: Option<&Vec<Af>>) -> bool {
    let b = hull_box(piece);
    let by_box = match prop {
        Prop::Goal { set, .. } => set.holds_on(&b),
        Prop::Avoid { members, .. } => members.iter().all(|m| m.missed_by(&b)),
    };
    if by_box {
        return true;
    }
    let Some(x) = forms else {
        return false;
    };
    if x.len() != piece.len() {
        return false;
    }
    // the forms over one set of symbols (a missing trailing coefficient is 0)
    let k = x.iter().map(|f| f.g.len()).max().unwrap_or(0);
    let c: Vec<f64> = x.iter().map(|f| f.c).collect();
    let g: Vec<Vec<f64>> = x
        .iter()
        .map(|f| {
            let mut row = f.g.clone();
            row.resize(k, 0.0);
            row
        })
        .collect();
    let form = Form {
        c: &c,
        g: &g,
        e_lo: x.iter().map(|f| f.lo).collect(),
        e_hi: x.iter().map(|f| f.hi).collect(),
    };
    let fb = hull_box(&x.iter().map(Num::range).collect::<Vec<_>>());
    let cut = Bx {
        lo: fb.lo.iter().zip(&b.lo).map(|(a, b)| a.max(*b)).collect(),
        hi: fb.hi.iter().zip(&b.hi).map(|(a, b)| a.min(*b)).collect(),
    };
    if !cut.lo.iter().zip(&cut.hi).all(|(l, h)| l <= h) {
        return false;
    }
    match prop {
        Prop::Goal { set, .. } => set.holds_on_form(&cut, Some(&form)),
        Prop::Avoid { members, .. } => members
            .iter()
            .all(|m| m.missed_by(&b) || m.missed_by_form(&cut, Some(&form))),
    }
}

/// Whether one cell's chain proves the property; why not. A period whose
/// pieces do not show it is enclosed again from the claim before it with
/// the finer substeps of [`flow::SUBSTEPS`] (shorter pieces).
fn proves(
    problem: &Problem,
    net: &Network,
    slopes: usize,
    prop: &Prop,
    chain: &CellChain,
) -> Result<(), String> {
    let (first, last) = match prop {
        Prop::Goal { steps, .. } | Prop::Avoid { steps, .. } => {
            (steps.0, steps.1.min(problem.horizon))
        }
    };
    let claim = |t: usize| chain.claims.get(t).ok_or("a step without a claim");
    match prop {
        Prop::Goal {
            set,
            eventually: true,
            ..
        } => {
            let mut any = false;
            for t in first..=last {
                any |= claim_in(claim(t)?, set);
            }
            if !any {
                return Err(format!(
                    "no claim at steps {first}..={last} is shown to lie in the goal"
                ));
            }
        }
        Prop::Goal { set, .. } => {
            for t in first..=last {
                if !claim_in(claim(t)?, set) {
                    return Err(format!(
                        "the claim at step {t} is not shown to lie in the goal"
                    ));
                }
            }
        }
        Prop::Avoid { members, .. } => {
            for t in first..=last {
                let z = claim(t)?;
                if let Some(k) = members.iter().position(|m| !claim_misses(z, m)) {
                    return Err(format!("step {t}: the claim may meet avoid member {k}"));
                }
            }
        }
    }
    // continuous time: the periods of the window, by the checker's own
    // enclosures (the period p ends at step p); an eventually goal is
    // proven at an instant (above)
    let periods = match prop {
        Prop::Goal {
            eventually: true, ..
        } => return Ok(()),
        Prop::Goal { periods, .. } | Prop::Avoid { periods, .. } => *periods,
    };
    let fine = |pieces: &[Vec<Iv>], forms: &[Option<Vec<Af>>]| {
        pieces
            .iter()
            .enumerate()
            .all(|(j, piece)| piece_shows(prop, piece, forms.get(j).and_then(Option::as_ref)))
    };
    for p in periods.0.max(1)..=periods.1.min(problem.horizon) {
        let pieces = match chain.between.get(p) {
            Some(Some(pieces)) => pieces,
            // discrete time: no states between the instants
            Some(None) => continue,
            None => {
                return Err(format!(
                    "the evidence stops before the period ending at step {p}"
                ))
            }
        };
        let forms = chain.forms.get(p).map_or(&[][..], Vec::as_slice);
        if fine(pieces, forms) {
            continue;
        }
        let finer = flow::SUBSTEPS.iter().any(|&substeps| {
            chain.claims.get(p - 1).is_some_and(|before| {
                advance(problem, net, before, slopes, substeps)
                    .ok()
                    .is_some_and(|s| {
                        s.between
                            .as_ref()
                            .is_some_and(|pieces| fine(pieces, &s.forms))
                    })
            })
        });
        if !finer {
            return Err(format!(
                "between steps {} and {p}: the checker's enclosure is not shown to satisfy the property",
                p - 1
            ));
        }
    }
    Ok(())
}

/// A box as one interval per coordinate (the inverse of [`hull_box`]).
fn box_ivs(b: &Bx) -> Vec<Iv> {
    b.lo.iter()
        .zip(&b.hi)
        .map(|(&l, &h)| Iv::new(l, h))
        .collect()
}

/// The box of an interval vector.
fn hull_box(x: &[Iv]) -> Bx {
    Bx {
        lo: x.iter().map(|i| i.lo).collect(),
        hi: x.iter().map(|i| i.hi).collect(),
    }
}

/// A recorded trajectory's start (in the initial set) and its noise
/// sequences, at least `steps` long; `Ok(Err(why))` when it starts outside.
fn trajectory<'a>(problem: &Problem, tr: &'a Value, steps: usize) -> R<Result<Start<'a>, String>> {
    super::trajectory_start(&problem.initial, problem.n(), tr, steps)
}

/// A trajectory's start and its process and sensor noise per step.
type Start<'a> = super::TrajectoryStart<'a>;

/// A replayed step's controls and disturbance, as intervals.
type Inputs = (Vec<Iv>, Vec<Iv>);

/// One step of a replayed trajectory: its recorded disturbance `w` and
/// sensor noise `v` at step `t` read and checked against their boxes, and
/// the enclosure of the controls the network gives at `x` (`y = Cᵀx + v`,
/// the noise as a point) with `w` as points; `Ok(Err(why))` when the noise
/// leaves its box.
fn step_inputs(
    problem: &Problem,
    net: &Network,
    x: &[Iv],
    w: &Value,
    v: &Value,
    t: usize,
) -> R<Result<Inputs, String>> {
    let (d, q) = (problem.w.len(), problem.v.len());
    let w = vector(w, d, "process_noise")?;
    let v = vector(v, q, "sensor_noise")?;
    let within = |p: &[f64], b: &[Iv]| p.iter().zip(b).all(|(x, b)| b.lo <= *x && *x <= b.hi);
    if !within(&w, &problem.w) {
        return Ok(Err(format!(
            "has a disturbance outside its box at step {t}"
        )));
    }
    if !within(&v, &problem.v) {
        return Ok(Err(format!("has sensor noise outside its box at step {t}")));
    }
    let noise: Vec<Iv> = v.iter().map(|&s| Iv::point(s)).collect();
    let y = problem.observe(x, &noise);
    let u = box_ivs(&network_box(net, &hull_box(&y)));
    let wi: Vec<Iv> = w.iter().map(|&s| Iv::point(s)).collect();
    Ok(Ok((u, wi)))
}

/// Replay a recorded trajectory with the checker's own enclosure.
fn replay(
    problem: &Problem,
    net: &Network,
    prop: &Prop,
    step: usize,
    tr: &Value,
) -> R<Result<(), String>> {
    let (first, last_step, eventually, periods) = match prop {
        Prop::Goal {
            steps,
            eventually,
            periods,
            ..
        } => (steps.0, steps.1.min(problem.horizon), *eventually, *periods),
        Prop::Avoid { steps, periods, .. } => {
            (steps.0, steps.1.min(problem.horizon), false, *periods)
        }
    };
    if !(first <= step && step <= last_step) {
        return Ok(Err(format!(
            "does not certainly violate the property at step {step}: the property does not apply there"
        )));
    }
    // an eventually goal is violated only by the whole window: its instants
    // and, in continuous time, every period that meets it (the last may
    // end after the window's last instant)
    let continuous = problem.field.period.is_some();
    let last = match (eventually, continuous) {
        (true, true) => last_step.max(periods.1.min(problem.horizon)),
        (true, false) => last_step,
        (false, _) => step,
    };
    let (x0, ws, vs) = match trajectory(problem, tr, last)? {
        Ok(t) => t,
        Err(e) => return Ok(Err(e)),
    };
    let mut x: Vec<Iv> = x0.iter().map(|&v| Iv::point(v)).collect();
    // an eventually goal in continuous time: every period that meets the
    // window must miss it, piece by piece, with one of the checker's cuts
    // of the period (finer pieces for a fast trajectory)
    let goal = match prop {
        Prop::Goal { set, .. } if eventually && continuous => Some(set),
        _ => None,
    };
    let mut periods_missed = true;
    // the enclosures at the window's instants
    let mut window: Vec<Bx> = Vec::new();
    for (t, (w, v)) in ws.iter().zip(vs).enumerate().take(last) {
        if t >= first && t <= last_step {
            window.push(hull_box(&x));
        }
        let (u, wi) = match step_inputs(problem, net, &x, w, v, t)? {
            Ok(p) => p,
            Err(e) => return Ok(Err(e)),
        };
        if let Some(set) = goal {
            // every cut of the period (each encloses the same states): one
            // must show the goal missed piece by piece if the period meets
            // the window; the next state is the intersection of the ends
            let mut tries = Vec::with_capacity(flow::SUBSTEPS.len());
            for s in flow::SUBSTEPS {
                match flow::period(&problem.field, &x, &u, &wi, s) {
                    Ok(p) => tries.push(p),
                    Err(e) => {
                        return Ok(Err(format!("cannot be enclosed at step {} ({e})", t + 1)))
                    }
                }
            }
            if (periods.0..=periods.1).contains(&(t + 1)) {
                periods_missed &= tries.iter().any(|p| {
                    p.between.as_deref().is_some_and(|pieces| {
                        pieces.iter().all(|piece| set.missed_by(&hull_box(piece)))
                    })
                });
            }
            let mut ends = tries.into_iter().map(|p| p.end);
            let Some(first_end) = ends.next() else {
                return Ok(Err("no enclosure".into()));
            };
            x = ends.fold(first_end, |a, b| {
                a.iter().zip(&b).map(|(p, q)| p.meet(q)).collect()
            });
            if x.iter()
                .any(|i| i.lo.partial_cmp(&i.hi).is_none_or(|o| o.is_gt()))
            {
                return Ok(Err(format!("empty enclosure at step {}", t + 1)));
            }
            continue;
        }
        match flow::period(&problem.field, &x, &u, &wi, flow::SUBSTEPS[0]) {
            Ok(p) => x = p.end,
            Err(e) => return Ok(Err(format!("cannot be enclosed at step {} ({e})", t + 1))),
        }
    }
    let xb = hull_box(&x);
    if last <= last_step {
        window.push(xb.clone());
    }
    let violated = match prop {
        // every instant and every piece of every period of the window
        Prop::Goal { set, .. } if eventually => {
            periods_missed && window.iter().all(|b| set.missed_by(b))
        }
        Prop::Goal { set, .. } => set.missed_by(&xb),
        Prop::Avoid { members, .. } => members.iter().any(|mb: &CSet| mb.holds_on(&xb)),
    };
    Ok(if violated {
        Ok(())
    } else {
        Err(format!(
            "does not certainly violate the property at step {step} (enclosure {:?} … {:?})",
            xb.lo, xb.hi
        ))
    })
}

/// Replay a recorded trajectory that violates an "always" goal or an avoid
/// set between the instants, in the period ending at `step` (continuous
/// time; the whole period inside the window): the checker's own enclosure of the trajectory up to step
/// `step − 1`, then of that period in pieces of `1/s` of it for each `s` of
/// [`flow::SUBSTEPS`] in turn; some piece must lie wholly outside the goal
/// (or inside an avoid member).
fn replay_between(
    problem: &Problem,
    net: &Network,
    prop: &Prop,
    step: usize,
    tr: &Value,
) -> R<Result<(), String>> {
    if problem.field.period.is_none() {
        return Ok(Err(
            "claims a violation between the instants of a plant in discrete time".into(),
        ));
    }
    if let Err(why) = super::period_in_window(prop, step, problem.horizon) {
        return Ok(Err(why));
    }
    let (x0, ws, vs) = match trajectory(problem, tr, step)? {
        Ok(t) => t,
        Err(e) => return Ok(Err(e)),
    };
    let mut x: Vec<Iv> = x0.iter().map(|&v| Iv::point(v)).collect();
    for (t, (w, v)) in ws.iter().zip(vs).enumerate().take(step) {
        let (u, wi) = match step_inputs(problem, net, &x, w, v, t)? {
            Ok(p) => p,
            Err(e) => return Ok(Err(e)),
        };
        if t + 1 < step {
            match flow::period(&problem.field, &x, &u, &wi, flow::SUBSTEPS[0]) {
                Ok(p) => x = p.end,
                Err(e) => return Ok(Err(format!("cannot be enclosed at step {} ({e})", t + 1))),
            }
            continue;
        }
        // the period ending at `step`, in ever shorter pieces
        for substeps in flow::SUBSTEPS {
            let Ok(p) = flow::period(&problem.field, &x, &u, &wi, substeps) else {
                continue;
            };
            let violated = p.between.iter().flatten().any(|piece| {
                let b = hull_box(piece);
                match prop {
                    Prop::Goal { set, .. } => set.missed_by(&b),
                    Prop::Avoid { members, .. } => members.iter().any(|m| m.holds_on(&b)),
                }
            });
            if violated {
                return Ok(Ok(()));
            }
        }
    }
    Ok(Err(format!(
        "does not certainly violate the property between steps {} and {step}: no piece of the checker's enclosure of that period lies wholly in the violation",
        step - 1
    )))
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::needless_range_loop
)]
mod tests;
