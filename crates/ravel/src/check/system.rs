//! The `system` block: state and control declarations, plant parameters,
//! noise and control bounds, the time declaration; then the plant per step.

use std::collections::BTreeMap;

use nalgebra::{DMatrix, DVector};

use super::nonlinear::{self, Field};
use super::{per_step, Ctx};
use ravel_analysis::closed_loop::Plant;
use ravel_analysis::sets::IBox;
use ravel_base::limits::{within, MAX_PLANT_NUMBERS};
use ravel_syntax::ast::*;
use ravel_syntax::diag::{did_you_mean, Code, Diagnostic};

/// What the system block declares (each part `None` when it had an error).
pub(super) struct SystemPart<'a> {
    pub sys: Option<&'a System>,
    pub state: Option<(String, usize)>,
    pub control: Option<(String, usize)>,
    pub assigns: BTreeMap<&'a str, (&'a Spanned<Value>, Span)>,
    pub bounds: Vec<(&'a Spanned<String>, &'a Spanned<BoxSet>)>,
    pub time_span: Option<Span>,
    pub time: Result<Option<f64>, ()>,
    /// `const NAME = expr`, in order.
    pub consts: Vec<(&'a Spanned<String>, &'a Spanned<Expr>)>,
    /// `der`/`next` lines, in order (empty for a linear plant).
    pub equations: Vec<(&'a Spanned<EquationKind>, &'a Component, &'a Spanned<Expr>)>,
    /// `observe […]` and its span.
    pub observe: Option<(&'a [Spanned<Expr>], Span)>,
    /// `actuate […]` and its span.
    pub actuate: Option<(&'a [Spanned<Expr>], Span)>,
    /// Where the state and the control are declared.
    pub decl_spans: (Option<Span>, Option<Span>),
}

/// Check the declarations of the (first) system block.
pub(super) fn system<'a>(cx: &mut Ctx, systems: &[&'a System]) -> SystemPart<'a> {
    let sys = systems.first().copied();
    let mut part = SystemPart {
        sys,
        state: None,
        control: None,
        assigns: BTreeMap::new(),
        bounds: Vec::new(),
        time_span: None,
        time: Ok(None),
        consts: Vec::new(),
        equations: Vec::new(),
        observe: None,
        actuate: None,
        decl_spans: (None, None),
    };
    let Some(sys) = sys else {
        return part;
    };
    let mut state_span = None;
    let mut control_span = None;
    for st in &sys.stmts {
        match st {
            SystemStmt::State { name, dim, span } => {
                if let Some(first) = state_span {
                    cx.duplicate("the state", first, *span);
                } else {
                    state_span = Some(*span);
                    part.state = cx
                        .positive(dim, "the state dimension")
                        .map(|d| (name.node.clone(), d));
                }
            }
            SystemStmt::Control { name, dim, span } => {
                if let Some(first) = control_span {
                    cx.duplicate("the control", first, *span);
                } else {
                    control_span = Some(*span);
                    part.control = cx
                        .positive(dim, "the control dimension")
                        .map(|d| (name.node.clone(), d));
                }
            }
            SystemStmt::Assign { name, value, .. } => {
                parameter(cx, name, value, &mut part.assigns);
            }
            SystemStmt::Bound { name, set, .. } => part.bounds.push((name, set)),
            SystemStmt::Time { kind, dt, span } => {
                if let Some(first) = part.time_span {
                    cx.duplicate("the time declaration", first, *span);
                } else {
                    part.time_span = Some(*span);
                    part.time = cx.time_decl(kind, dt, *span);
                }
            }
            SystemStmt::Const { name, value, .. } => part.consts.push((name, value)),
            SystemStmt::Equation {
                kind, target, expr, ..
            } => part.equations.push((kind, target, expr)),
            SystemStmt::Observe { exprs, span } => match part.observe {
                Some((_, first)) => cx.duplicate("`observe`", first, *span),
                None => part.observe = Some((exprs, *span)),
            },
            SystemStmt::Actuate { exprs, span } => match part.actuate {
                Some((_, first)) => cx.duplicate("`actuate`", first, *span),
                None => part.actuate = Some((exprs, *span)),
            },
        }
    }
    part.decl_spans = (state_span, control_span);
    let state = part.state.as_ref().zip(state_span);
    let control = part.control.as_ref().zip(control_span);
    let (state_ok, control_ok) = vector_names(cx, state, control);
    // a state or control named like the noise (`control w[1]`) is reported
    // once: without it, what refers to it (the limits `u in box(…)`, the
    // plant, the sets' `x[i]`) is not checked, which would only report the
    // same mistake again as unknown names
    if !state_ok {
        part.state = None;
    }
    if !control_ok {
        part.control = None;
    }
    let linear = part.equations.is_empty();
    declared(cx, sys, state_span, control_span, &part.assigns, linear);
    part
}

/// `NAME = value`: a plant parameter (`A`, `B`, `C` or `c`), defined once.
fn parameter<'a>(
    cx: &mut Ctx,
    name: &'a Spanned<String>,
    value: &'a Spanned<Value>,
    assigns: &mut BTreeMap<&'a str, (&'a Spanned<Value>, Span)>,
) {
    const KNOWN: [&str; 4] = ["A", "B", "C", "c"];
    if !KNOWN.contains(&name.node.as_str()) {
        let mut d = Diagnostic::new(
            Code::UnknownName,
            name.span,
            format!("unknown plant parameter `{}`", name.node),
        )
        .label("not a plant parameter");
        d = match did_you_mean(&name.node, KNOWN) {
            Some(s) => d.hint(format!("did you mean `{s}`? The plant is x' = A x + B u + c + w, y = Cᵀ x + v")),
            None => d.hint("the plant is x' = A x + B u + c + w, y = Cᵀ x + v: define A, B and optionally c and C"),
        };
        cx.err(d);
    } else if let Some((_, first)) = assigns.get(name.node.as_str()) {
        cx.duplicate(&format!("`{}`", name.node), *first, name.span);
    } else {
        assigns.insert(&name.node, (value, name.span));
    }
}

/// The state and the control have different names, neither of them the
/// noise's `w` or `v` (each declaration with its span); whether the
/// state's and the control's names are not the noise's.
fn vector_names(
    cx: &mut Ctx,
    state: Option<(&(String, usize), Span)>,
    control: Option<(&(String, usize), Span)>,
) -> (bool, bool) {
    let free = |v: Option<(&(String, usize), Span)>| {
        v.is_none_or(|((name, _), _)| name != "w" && name != "v")
    };
    let (state_ok, control_ok) = (free(state), free(control));
    if let (Some(((xn, _), ss)), Some(((un, _), cs))) = (state, control) {
        if xn == un {
            cx.duplicate(&format!("the name `{xn}`"), ss, cs);
        }
    }
    for ((name, _), span) in [state, control].into_iter().flatten() {
        if name == "w" || name == "v" {
            cx.err(
                Diagnostic::new(
                    Code::Duplicate,
                    span,
                    format!(
                        "the name `{name}` is reserved for {} noise",
                        if name == "w" { "process" } else { "sensor" }
                    ),
                )
                .label("reserved name")
                .hint("`w` and `v` name the process and sensor noise; choose another name"),
            );
        }
    }
    (state_ok, control_ok)
}

/// The system declares its state, its control, and (a linear plant, when
/// `linear`) `A` and `B`; a nonlinear plant defines none of `A`, `B`, `c`.
fn declared(
    cx: &mut Ctx,
    sys: &System,
    state_span: Option<Span>,
    control_span: Option<Span>,
    assigns: &BTreeMap<&str, (&Spanned<Value>, Span)>,
    linear: bool,
) {
    if !linear {
        for (key, (_, span)) in assigns.iter().filter(|(k, _)| ["A", "B", "c"].contains(k)) {
            cx.err(
                Diagnostic::new(
                    Code::PlantKind,
                    *span,
                    format!("`{key}` belongs to a linear plant, but this system's state is defined by `der`/`next` lines"),
                )
                .label("a linear plant's parameter")
                .hint("write the plant either as A, B, c or as one `der`/`next` line per state component (`C` and `observe` work with both)"),
            );
        }
    }
    if state_span.is_none() {
        cx.err(
            Diagnostic::new(Code::Missing, sys.name.span, "the system declares no state")
                .label("in this system")
                .hint("add `state x[n]`"),
        );
    }
    if control_span.is_none() {
        cx.err(
            Diagnostic::new(
                Code::Missing,
                sys.name.span,
                "the system declares no control",
            )
            .label("in this system")
            .hint("add `control u[m]`"),
        );
    }
    for req in ["A", "B"] {
        if linear && !assigns.contains_key(req) {
            cx.err(
                Diagnostic::new(
                    Code::Missing,
                    sys.name.span,
                    format!("the system does not define `{req}`"),
                )
                .label("in this system")
                .hint(format!("add `{req} = [[…], …]`")),
            );
        }
    }
}

/// A checked nonlinear plant, before it is assembled.
pub(super) struct NonlinearPart {
    /// The right-hand side and the span of each tape node.
    pub field: Field,
    /// The disturbance box.
    pub w: IBox,
    /// The observation matrix (`n × k`).
    pub obs: DMatrix<f64>,
    /// The sensor noise box.
    pub v: IBox,
}

/// The plant per step, its noise boxes and control limits.
pub(super) struct PlantPart {
    pub plant: Option<Vec<Plant>>,
    /// The nonlinear plant (when the system has `der`/`next` lines).
    pub nonlinear: Option<NonlinearPart>,
    /// The named constants, with `pi`.
    pub consts: BTreeMap<String, f64>,
    /// `observe`'s offsets `d` (the controller sees `M x + d`).
    pub observe_offset: Option<DVector<f64>>,
    /// Lengths and spans of `per_step(…)` lists (checked against the horizon).
    pub per_step_lists: Vec<(usize, Span)>,
    pub limits: Option<IBox>,
    /// The observation size (columns of `C`).
    pub p_dim: Option<usize>,
}

/// A parameter's values per step (one when it is constant), and the span of
/// its `per_step(…)` list.
type PerStep<T> = (Vec<T>, Option<Span>);

/// Evaluate `A`, `B`, `c`, `C` and the bounds against the declared sizes.
pub(super) fn plant(cx: &mut Ctx, sp: &SystemPart) -> PlantPart {
    let mut part = PlantPart {
        plant: None,
        nonlinear: None,
        consts: BTreeMap::new(),
        observe_offset: None,
        per_step_lists: Vec::new(),
        limits: None,
        p_dim: None,
    };
    let (Some((xn, n)), Some((un, m))) = (&sp.state, &sp.control) else {
        return part;
    };
    let (n, m, assigns) = (*n, *m, &sp.assigns);
    let vectors = [
        (xn.as_str(), sp.decl_spans.0),
        (un.as_str(), sp.decl_spans.1),
        ("w", None),
        ("v", None),
        ("net", None),
    ];
    part.consts = nonlinear::constants(cx, &sp.consts, &vectors);
    // `observe`: the observation matrix is Mᵀ, the offsets go to the network
    let observed = sp.observe.map(|(exprs, span)| {
        if let Some((_, c_span)) = assigns.get("C") {
            cx.err(
                Diagnostic::new(
                    Code::PlantKind,
                    span,
                    "`observe` and `C` both define what the controller sees",
                )
                .label("the controller's inputs")
                .related(*c_span, "`C` is given here")
                .hint("keep one: `observe [x[0], …]` (affine, any constants) or `C` (the controller sees Cᵀ x + v)"),
            );
        }
        let forbidden = vec![
            (un.as_str(), "the controller's inputs depend on the state only"),
            ("w", "the controller's inputs depend on the state only"),
            ("v", "sensor noise is added to every input: bound it with `v in box(…)`"),
        ];
        nonlinear::affine(cx, exprs, &part.consts, (xn, n), forbidden, "an `observe` entry")
    });
    if !sp.equations.is_empty() {
        nonlinear_plant(cx, sp, &mut part, observed, (xn, n), (un, m));
        return part;
    }
    let observed = match observed {
        Some(o) => match o {
            Some((mat, d)) if !assigns.contains_key("C") => {
                part.observe_offset = Some(d).filter(|d| d.iter().any(|v| *v != 0.0));
                Some(Some(mat.transpose()))
            }
            _ => Some(None),
        },
        None => None,
    };
    let a = assigns.get("A").and_then(|(v, _)| {
        per_step(cx, v, &mut |cx, v| {
            cx.matrix(
                v,
                "A",
                n,
                Some(n),
                &format!("A is n × n with n = {n}, the dimension of `{xn}`"),
            )
        })
    });
    let b = assigns.get("B").and_then(|(v, _)| {
        per_step(cx, v, &mut |cx, v| {
            cx.matrix(
                v,
                "B",
                n,
                Some(m),
                &format!("B is n × m: {n} states by {m} controls"),
            )
        })
    });
    let c = match assigns.get("c") {
        Some((v, _)) => per_step(cx, v, &mut |cx, v| {
            cx.vector(v, "c", n, &format!("c has one entry per state ({n})"))
        }),
        None => Some((vec![DVector::zeros(n)], None)),
    };
    let obs = match (observed, assigns.get("C")) {
        (Some(o), _) => o,
        (None, Some((v, _))) => cx.matrix(
            v,
            "C",
            n,
            None,
            &format!("C is n × p with n = {n}: the controller sees y = Cᵀ x + v"),
        ),
        (None, None) => Some(DMatrix::identity(n, n)),
    };
    let p = obs.as_ref().map(|o| o.ncols());
    part.p_dim = p;
    let bounds = bounds(cx, &sp.bounds, n, (un.as_str(), m), p);
    part.limits = bounds.limits;
    if let (Some(a), Some(b), Some(c), Some(obs), Some(w), Some(v)) =
        (a, b, c, obs, bounds.w, bounds.v)
    {
        for (list, span) in [(a.0.len(), a.1), (b.0.len(), b.1), (c.0.len(), c.1)] {
            if let Some(span) = span {
                part.per_step_lists.push((list, span));
            }
        }
        part.plant = plants(cx, (n, m), &a, &b, &c, obs, (w, v));
    }
    part
}

/// The nonlinear plant of `der`/`next` lines: its vector field, the
/// disturbance box (of the dimension the box gives), the observation (from
/// `observed`, `C`, or the whole state) and the sensor noise box.
fn nonlinear_plant(
    cx: &mut Ctx,
    sp: &SystemPart,
    part: &mut PlantPart,
    observed: Option<Option<(DMatrix<f64>, DVector<f64>)>>,
    (xn, n): (&str, usize),
    (un, m): (&str, usize),
) {
    let obs = match (observed, sp.assigns.get("C")) {
        (Some(Some((mat, d))), None) => {
            part.observe_offset = Some(d).filter(|d| d.iter().any(|v| *v != 0.0));
            Some(mat.transpose())
        }
        (Some(_), _) => None,
        (None, Some((v, _))) => cx.matrix(
            v,
            "C",
            n,
            None,
            &format!("C is n × p with n = {n}: the controller sees y = Cᵀ x + v"),
        ),
        (None, None) => Some(DMatrix::identity(n, n)),
    };
    let p = obs.as_ref().map(|o| o.ncols());
    part.p_dim = p;
    // the disturbance has the dimension of its box
    let p_w = sp
        .bounds
        .iter()
        .find(|(name, _)| name.node == "w")
        .map_or(0, |(_, set)| match &set.node {
            BoxSet::Positional(ivs) => ivs.len(),
            BoxSet::Named(items) => items
                .iter()
                .map(|(c, _)| {
                    usize::try_from(c.index.node)
                        .unwrap_or(usize::MAX)
                        .saturating_add(1)
                })
                .max()
                .unwrap_or(0)
                .min(ravel_base::limits::MAX_DIM as usize),
        });
    let bounds = bounds(cx, &sp.bounds, p_w, (un, m), p);
    part.limits = bounds.limits;
    let sys_span = sp.sys.map_or(Span::default(), |s| s.name.span);
    let dims = nonlinear::Dims {
        state: (xn, n),
        control: (un, m),
        p: p_w,
    };
    let time = (sp.time.ok().flatten(), sp.time.is_ok(), sp.time_span);
    let field = nonlinear::field(cx, &sp.equations, &part.consts, &dims, time, sys_span);
    if let (Some(field), Some(w), Some(obs), Some(v)) = (field, bounds.w, obs, bounds.v) {
        part.nonlinear = Some(NonlinearPart { field, w, obs, v });
    }
}

/// The noise boxes and the control limits, from the bound statements.
struct Bounds {
    /// The process noise box (zero when not given).
    w: Option<IBox>,
    /// The sensor noise box (zero when not given).
    v: Option<IBox>,
    limits: Option<IBox>,
}

/// Check the bounds on `w` (`n` components: the states of a linear plant),
/// `v` (`p` observations) and the control `un` (`m` components).
fn bounds(
    cx: &mut Ctx,
    bounds: &[(&Spanned<String>, &Spanned<BoxSet>)],
    n: usize,
    (un, m): (&str, usize),
    p: Option<usize>,
) -> Bounds {
    let mut w = Some(IBox::new(vec![0.0; n], vec![0.0; n]));
    let mut v = p.map(|p| IBox::new(vec![0.0; p], vec![0.0; p]));
    let mut limits = None;
    let mut seen: BTreeMap<&str, Span> = BTreeMap::new();
    for (name, set) in bounds.iter() {
        let key = name.node.as_str();
        if let Some(first) = seen.get(key) {
            cx.duplicate(&format!("the bound on `{key}`"), *first, name.span);
            continue;
        }
        seen.insert(key, name.span);
        if key == "w" {
            w = cx.box_set(set, "w", n, true, "the process noise box");
        } else if key == "v" {
            match p {
                Some(p) => v = cx.box_set(set, "v", p, true, "the sensor noise box"),
                None => v = None,
            }
        } else if key == un {
            limits = cx.box_set(set, un, m, true, "the control limit box");
        } else {
            let cands = ["w", "v", un];
            let mut d = Diagnostic::new(
                Code::UnknownName,
                name.span,
                format!("unknown bounded quantity `{key}`"),
            )
            .label("not a noise or control name");
            d = match did_you_mean(key, cands) {
                Some(s) => d.hint(format!("did you mean `{s}`? Bounds apply to `w` (process noise), `v` (sensor noise) or `{un}` (control limits)")),
                None => d.hint(format!("bounds apply to `w` (process noise), `v` (sensor noise) or `{un}` (control limits)")),
            };
            cx.err(d);
        }
    }
    Bounds { w, v, limits }
}

/// The plant of each step (`n` states, `m` controls): step k uses entry k
/// of each list, or its last entry. The plants must stay within
/// [`MAX_PLANT_NUMBERS`] (checked before any is built).
fn plants(
    cx: &mut Ctx,
    (n, m): (usize, usize),
    a: &PerStep<DMatrix<f64>>,
    b: &PerStep<DMatrix<f64>>,
    c: &PerStep<DVector<f64>>,
    obs: DMatrix<f64>,
    (w, v): (IBox, IBox),
) -> Option<Vec<Plant>> {
    let len = a.0.len().max(b.0.len()).max(c.0.len());
    // each step's plant holds A, B, c and a copy of C
    let per_step = n as u64 * (n + m + 1 + obs.ncols()) as u64;
    if !within(&[len as u64, per_step], MAX_PLANT_NUMBERS) {
        let span = a.1.or(b.1).or(c.1).unwrap_or_else(|| Span::new(0, 0));
        cx.err(
            Diagnostic::new(
                Code::Limit,
                span,
                format!("{len} steps of a plant with {n} states hold more than {MAX_PLANT_NUMBERS} numbers"),
            )
            .label("too large a time-varying plant")
            .hint("use fewer per_step entries or a smaller state"),
        );
        return None;
    }
    fn pick<T: Clone>(v: &[T], k: usize) -> Option<T> {
        v.get(k).or(v.last()).cloned()
    }
    // lists are never empty (the grammar); `None` would only drop the plant
    (0..len)
        .map(|k| {
            Some(Plant {
                a: pick(&a.0, k)?,
                b: pick(&b.0, k)?,
                c: pick(&c.0, k)?,
                obs: obs.clone(),
                w: w.clone(),
                v: v.clone(),
                err: None,
            })
        })
        .collect::<Option<Vec<Plant>>>()
        .filter(|p| !p.is_empty())
}
