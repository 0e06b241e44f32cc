//! Network specs: one network on its own (the tutorial's "Analyzing NNs in
//! Isolation"): its input and output vectors, the model, the input set, the
//! properties over the outputs (`require`, `avoid`, `robust`), radius
//! searches, and the analysis block (propagator, partitioner, output shape).

use std::collections::BTreeMap;

use super::analysis_block::{self, AnalysisPart};
use super::{controller, effective_path, file_sha256, ControllerFile, Ctx, WHOLE};
use crate::ir::{NetPropagator, NetProperty, NetPropertyKind, Partitioner, RadiusSpec, SelectSpec};
use crate::onnx::Controller;
use ravel_analysis::sets::{Polytope, Region};
use ravel_analysis::shape::Shape;
use ravel_base::limits::{within, MAX_RADIUS_SCALE, MAX_SDP_DIM, MAX_STORED_NUMBERS};
use ravel_syntax::ast::*;
use ravel_syntax::diag::{compact, Code, Diagnostic};

/// A network spec that passed every check.
#[derive(Clone, Debug)]
pub struct NetworkChecked {
    /// The network's name.
    pub name: String,
    /// The input vector's name and dimension.
    pub input: (String, usize),
    /// The output vector's name and dimension.
    pub output: (String, usize),
    /// The model's path: as written, or as given on the command line.
    pub model_path: String,
    /// SHA-256 of the model file, in hex.
    pub model_sha256: String,
    /// The path the model was read from.
    pub model_resolved: String,
    /// The loaded model.
    pub model: Controller,
    /// The input set's name and region (absent in a spec that only selects actions).
    pub input_set: Option<(String, Region)>,
    /// The robust action selections.
    pub selects: Vec<SelectSpec>,
    /// The properties, in source order.
    pub properties: Vec<NetProperty>,
    /// The radius searches, in source order.
    pub radii: Vec<RadiusSpec>,
    /// The propagator.
    pub propagator: NetPropagator,
    /// How the input set is split.
    pub partitioner: Partitioner,
    /// The output set's shape.
    pub shape: Shape,
    /// Monte Carlo samples.
    pub samples: usize,
    /// Monte Carlo seed.
    pub seed: u64,
    /// Projected-gradient steps on the lower ReLU slopes (0: CROWN's own).
    pub slope_steps: usize,
}

/// The most observations of one select block.
pub const MAX_OBSERVATIONS: usize = 1_000_000;

/// Defaults of a radius search: the declared set's scale, and a bracket of 1e-3 of it.
const DEFAULT_RADIUS_MAX: f64 = 1.0;

/// A system-spec item in a network spec (or the reverse).
fn wrong_kind(cx: &mut Ctx, span: Span, what: &str, network: bool) {
    let instead = match (what, network) {
        ("`goal`", true) => Some("`require NAME = { … }` states what the outputs must satisfy"),
        ("`initial`", true) => Some("`input NAME = …` is the set of inputs"),
        ("`controller`", true) => Some("`model \"path.onnx\"` names the network"),
        ("`model`", false) => Some("`controller \"path.onnx\"` names the closed loop's network"),
        ("`input`", false) => Some("`initial NAME = …` is the closed loop's initial set"),
        ("`require`", false) => Some("`goal NAME = …` states where the final states must be"),
        _ => None,
    };
    if let Some(instead) = instead {
        cx.err(
            Diagnostic::new(
                Code::SpecKind,
                span,
                format!(
                    "{what} belongs to {} spec",
                    if network { "a system" } else { "a network" }
                ),
            )
            .label(if network {
                "in a network spec"
            } else {
                "in a system spec"
            })
            .hint(format!("here {instead}")),
        );
        return;
    }
    let (here, hint) = if network {
        (
            "in a network spec",
            "a network spec has `network`, `model`, `input`, `require`, `avoid`, `robust`, `radius` and `analysis`; closed loops are stated in a system spec",
        )
    } else {
        (
            "in a system spec",
            "a system spec has `system`, `controller`, `initial`, `goal`, `avoid`, `horizon` and `analysis`; a network on its own is stated in a network spec (`network NAME { input x[n] output y[m] }`)",
        )
    };
    cx.err(
        Diagnostic::new(
            Code::SpecKind,
            span,
            format!(
                "{what} belongs to {} spec",
                if network { "a system" } else { "a network" }
            ),
        )
        .label(here)
        .hint(hint),
    );
}

/// The span of an item, for [`wrong_kind`] reports.
pub(super) fn item_span(item: &Item) -> Span {
    match item {
        Item::System(s) => s.span,
        Item::Network(n) => n.span,
        Item::Controller(p) | Item::Model(p) => p.span,
        Item::Initial(d) | Item::Goal(d) | Item::Input(d) | Item::Require(d) => d.span,
        Item::Avoid(a) => a.span,
        Item::Horizon(h) => h.span,
        Item::Analysis(a) => a.span,
        Item::Robust(r) => r.span,
        Item::Radius(r) => r.span,
        Item::Select(r) => r.span,
    }
}

/// Whether the spec states a network on its own: it has a `network` block,
/// or (without a `system` block) an item only network specs have.
pub fn is_network_spec(spec: &Spec) -> bool {
    let has = |f: fn(&Item) -> bool| spec.items.iter().any(f);
    has(|i| matches!(i, Item::Network(_)))
        || (!has(|i| matches!(i, Item::System(_)))
            && has(|i| {
                matches!(
                    i,
                    Item::Model(_)
                        | Item::Input(_)
                        | Item::Require(_)
                        | Item::Robust(_)
                        | Item::Radius(_)
                        | Item::Select(_)
                )
            }))
}

/// Whether `name` is not taken yet (it is taken now); a duplicate is reported.
fn fresh<'a>(cx: &mut Ctx, names: &mut BTreeMap<&'a str, Span>, name: &'a Spanned<String>) -> bool {
    if let Some(first) = names.get(name.node.as_str()) {
        cx.duplicate(&format!("the name `{}`", name.node), *first, name.span);
        return false;
    }
    names.insert(&name.node, name.span);
    true
}

/// Report the items of a network spec in a system spec.
pub(super) fn network_items_in_system(cx: &mut Ctx, spec: &Spec) {
    for item in &spec.items {
        let what = match item {
            Item::Network(_) => "`network`",
            Item::Model(_) => "`model`",
            Item::Input(_) => "`input`",
            Item::Require(_) => "`require`",
            Item::Robust(_) => "`robust`",
            Item::Radius(_) => "`radius`",
            Item::Select(_) => "`select`",
            _ => continue,
        };
        wrong_kind(cx, item_span(item), what, false);
    }
}

/// The top-level items of a network spec, by kind (items of a system spec,
/// duplicates and missing required items are reported while collecting).
struct NetworkItems<'a> {
    networks: Vec<&'a NetworkDecl>,
    models: Vec<&'a Spanned<String>>,
    inputs: Vec<&'a SetDef>,
    analyses: Vec<&'a Analysis>,
    /// The properties (`require`, `avoid`, `robust`), in source order.
    props: Vec<&'a Item>,
    radii: Vec<&'a RadiusDef>,
    selects: Vec<&'a SelectDef>,
}

fn network_items<'a>(cx: &mut Ctx, spec: &'a Spec, has_override: bool) -> NetworkItems<'a> {
    let mut it = NetworkItems {
        networks: Vec::new(),
        models: Vec::new(),
        inputs: Vec::new(),
        analyses: Vec::new(),
        props: Vec::new(),
        radii: Vec::new(),
        selects: Vec::new(),
    };
    for item in &spec.items {
        match item {
            Item::Select(d) => it.selects.push(d),
            Item::Network(n) => it.networks.push(n),
            Item::Model(m) => it.models.push(m),
            Item::Input(i) => it.inputs.push(i),
            Item::Analysis(a) => it.analyses.push(a),
            Item::Require(_) | Item::Avoid(_) | Item::Robust(_) => it.props.push(item),
            Item::Radius(r) => it.radii.push(r),
            Item::System(_) => wrong_kind(cx, item_span(item), "`system`", true),
            Item::Controller(_) => wrong_kind(cx, item_span(item), "`controller`", true),
            Item::Initial(_) => wrong_kind(cx, item_span(item), "`initial`", true),
            Item::Goal(_) => wrong_kind(cx, item_span(item), "`goal`", true),
            Item::Horizon(_) => wrong_kind(cx, item_span(item), "`horizon`", true),
        }
    }
    let networks: Vec<Span> = it.networks.iter().map(|n| n.name.span).collect();
    cx.duplicates("the network", &networks);
    let models: Vec<Span> = it.models.iter().map(|m| m.span).collect();
    cx.duplicates("the model", &models);
    let inputs: Vec<Span> = it.inputs.iter().map(|i| i.name.span).collect();
    cx.duplicates("the input set", &inputs);
    let analyses: Vec<Span> = it.analyses.iter().map(|a| a.span).collect();
    cx.duplicates("the analysis block", &analyses);
    let missing = |cx: &mut Ctx, what: &str, example: &str| {
        cx.err(
            Diagnostic::new(Code::Missing, WHOLE, format!("the spec has no {what}"))
                .label("required item missing")
                .hint(format!("add {example}")),
        )
    };
    if it.networks.is_empty() {
        missing(
            cx,
            "network block",
            "`network NAME { input x[n] output y[m] }`",
        );
    }
    if it.models.is_empty() && !has_override {
        missing(cx, "model", "`model \"path/to/network.onnx\"`");
    }
    // a spec that only selects actions needs no input set
    if it.inputs.is_empty()
        && (it.selects.is_empty() || !it.props.is_empty() || !it.radii.is_empty())
    {
        missing(cx, "input set", "`input X = box(x[0] in [lo, hi], …)`");
    }
    it
}

/// The network block's input and output vectors (each `None` when missing
/// or in error).
struct Vectors {
    input: Option<(String, usize)>,
    output: Option<(String, usize)>,
}

/// Check the (first) network block.
fn vectors(cx: &mut Ctx, network: Option<&NetworkDecl>) -> Vectors {
    let mut input: Option<(String, usize)> = None;
    let mut output: Option<(String, usize)> = None;
    let Some(n) = network else {
        return Vectors { input, output };
    };
    for (list, role, slot) in [
        (&n.input, "input", &mut input),
        (&n.output, "output", &mut output),
    ] {
        match list.split_first() {
            None => cx.err(
                Diagnostic::new(
                    Code::Missing,
                    n.span,
                    format!("the network block declares no {role} vector"),
                )
                .label(format!("no `{role}`"))
                .hint(format!(
                    "add `{role} {}[n]` with the model's {role} size",
                    if role == "input" { "x" } else { "y" }
                )),
            ),
            Some(((name, dim), rest)) => {
                for (again, _) in rest {
                    cx.duplicate(&format!("the {role} vector"), name.span, again.span);
                }
                *slot = cx
                    .positive(dim, &format!("the {role} dimension"))
                    .map(|d| (name.node.clone(), d));
            }
        }
    }
    if let (Some((a, _)), Some((b, _))) = (&input, &output) {
        if let (true, Some((i, _)), Some((o, _))) = (a == b, n.input.first(), n.output.first()) {
            cx.duplicate(&format!("the vector name `{a}`"), i.span, o.span);
        }
    }
    Vectors { input, output }
}

/// Load the model named at `path` from `file` (the caller's read) and check
/// its sizes against the declared vectors.
fn model(
    cx: &mut Ctx,
    path: Option<&Spanned<String>>,
    file: Option<&ControllerFile>,
    vectors: &Vectors,
) -> Option<Controller> {
    let net = controller::controller(
        cx,
        path,
        file,
        (None, controller::Observed::State),
        false,
        &None,
    );
    if let (Some(c), Some(path)) = (&net, path) {
        for (role, have, decl, code) in [
            ("inputs", c.inputs, &vectors.input, Code::ControllerInputs),
            (
                "outputs",
                c.outputs,
                &vectors.output,
                Code::ControllerOutputs,
            ),
        ] {
            if let Some((name, n)) = decl {
                if have != *n {
                    cx.err(
                        Diagnostic::new(
                            code,
                            path.span,
                            format!("the model has {have} {role} but `{name}` has {n} components"),
                        )
                        .label(format!("{have} {role}"))
                        .hint(format!(
                            "declare `{}put {name}[{have}]` in the network block, or use a model with {n} {role}",
                            if role == "inputs" { "in" } else { "out" }
                        )),
                    );
                }
            }
        }
    }
    net
}

/// The (first) input set over the input vector `input`.
fn input_set(
    cx: &mut Ctx,
    input: &Option<(String, usize)>,
    def: Option<&SetDef>,
) -> Option<(String, Region)> {
    let (Some((xn, n)), Some(def)) = (input, def) else {
        return None;
    };
    let members = &def.set.node.members;
    if members.len() > 1 {
        cx.err(
            Diagnostic::new(
                Code::SetKind,
                def.set.span,
                "the input set cannot be a union",
            )
            .label("a union")
            .hint("state each part in its own spec, or use the bounding box"),
        );
        return None;
    }
    let region = cx.region(members.first()?, xn, *n, "input set")?;
    Some((def.name.node.clone(), region))
}

/// The checked properties, in source order, and their indices by name.
struct Properties {
    list: Vec<NetProperty>,
    index: BTreeMap<String, usize>,
}

/// Check the properties over the output vector; `ok` turns false when one
/// of them had an error.
fn properties<'a>(
    cx: &mut Ctx,
    props: &[&'a Item],
    output: &Option<(String, usize)>,
    input_set: &Option<(String, Region)>,
    names: &mut BTreeMap<&'a str, Span>,
    ok: &mut bool,
) -> Properties {
    let mut list = Vec::new();
    let mut index: BTreeMap<String, usize> = BTreeMap::new();
    for &item in props {
        let (name, kind) = match item {
            Item::Require(d) => (&d.name, require(cx, d, output)),
            Item::Avoid(a) => (&a.name, avoid(cx, a, output)),
            Item::Robust(r) => (&r.name, robust(cx, r, output, input_set)),
            _ => continue,
        };
        if !fresh(cx, names, name) {
            *ok = false;
            continue;
        }
        match kind {
            Some(kind) => {
                index.insert(name.node.clone(), list.len());
                list.push(NetProperty {
                    name: name.node.clone(),
                    kind,
                });
            }
            None => *ok = false,
        }
    }
    Properties { list, index }
}

/// `require NAME = …`: one box or polytope over the outputs.
fn require(cx: &mut Ctx, d: &SetDef, output: &Option<(String, usize)>) -> Option<NetPropertyKind> {
    let (yn, m) = output.as_ref()?;
    let members = &d.set.node.members;
    if members.len() > 1 {
        cx.err(
            Diagnostic::new(
                Code::SetKind,
                d.set.span,
                "a `require` set cannot be a union",
            )
            .label("a union")
            .hint("every inequality must hold; to exclude a union, state it with `avoid`"),
        );
        return None;
    }
    members
        .first()
        .and_then(|a| cx.set_atom(a, yn, *m, "a `require` set"))
        .map(NetPropertyKind::Require)
}

/// `avoid NAME = { … }`: a union of boxes and polytopes over the outputs.
fn avoid(cx: &mut Ctx, a: &AvoidDef, output: &Option<(String, usize)>) -> Option<NetPropertyKind> {
    if let Some(s) = &a.steps {
        cx.err(
            Diagnostic::new(Code::SpecKind, s.span, "a network spec has no steps")
                .label("steps of a closed loop")
                .hint("remove `at …`: a network's avoid set constrains its outputs on the whole input set"),
        );
    }
    let (yn, m) = output.as_ref()?;
    let members: Vec<Option<Polytope>> = a
        .set
        .node
        .members
        .iter()
        .map(|x| cx.set_atom(x, yn, *m, "the avoid set"))
        .collect();
    members
        .iter()
        .all(Option::is_some)
        .then(|| NetPropertyKind::Avoid(members.into_iter().flatten().collect()))
}

/// `robust NAME [label K]`: the label's output beats every other.
fn robust(
    cx: &mut Ctx,
    r: &RobustDef,
    output: &Option<(String, usize)>,
    input_set: &Option<(String, Region)>,
) -> Option<NetPropertyKind> {
    let (yn, m) = output.as_ref()?;
    if *m < 2 {
        cx.err(
            Diagnostic::new(
                Code::Label,
                r.span,
                format!("robustness compares labels, but `{yn}` has one component"),
            )
            .label("one output, no labels to compare")
            .hint("state a threshold with `require`, e.g. `require P = { y[0] >= 0 }`"),
        );
        return None;
    }
    match &r.label {
        Some(l) if l.node >= *m as u64 => {
            cx.err(
                Diagnostic::new(
                    Code::Label,
                    l.span,
                    format!("label {} is out of range", l.node),
                )
                .label(format!("`{yn}` has {m} components"))
                .hint(format!("labels run from 0 to {}", m - 1)),
            );
            None
        }
        Some(l) => Some(NetPropertyKind::Robust(Some(l.node as usize))),
        None => match input_set {
            Some((_, Region::Polytope { .. })) => {
                cx.err(
                    Diagnostic::new(
                        Code::Label,
                        r.span,
                        "a polytope input set has no centre to take the label from",
                    )
                    .label("which label?")
                    .hint("name the label: `robust NAME label K`"),
                );
                None
            }
            _ => Some(NetPropertyKind::Robust(None)),
        },
    }
}

/// Check the radius searches; `ok` turns false when one of them had an error.
fn radius_searches<'a>(
    cx: &mut Ctx,
    radii: &[&'a RadiusDef],
    props: &[&Item],
    index: &BTreeMap<String, usize>,
    input_set: &Option<(String, Region)>,
    names: &mut BTreeMap<&'a str, Span>,
    ok: &mut bool,
) -> Vec<RadiusSpec> {
    let mut specs = Vec::new();
    for &r in radii {
        if !fresh(cx, names, &r.name) {
            *ok = false;
            continue;
        }
        let property = radius_property(cx, r, props, index);
        if let Some((_, Region::Polytope { .. })) = input_set {
            cx.err(
                Diagnostic::new(Code::Radius, r.span, "a radius is searched by scaling the input set about its centre, and a polytope has none")
                    .label("no centre")
                    .hint("state the input set as a box or a ball around the nominal input"),
            );
            *ok = false;
            continue;
        }
        match (property, radius_budget(cx, r)) {
            (Some(property), Some((max, tolerance))) => specs.push(RadiusSpec {
                name: r.name.node.clone(),
                property,
                max,
                tolerance,
            }),
            _ => *ok = false,
        }
    }
    specs
}

/// The index of the property a radius search names; an unknown name is
/// reported (a property with an error was reported already).
fn radius_property(
    cx: &mut Ctx,
    r: &RadiusDef,
    props: &[&Item],
    index: &BTreeMap<String, usize>,
) -> Option<usize> {
    if let Some(k) = index.get(&r.property.node) {
        return Some(*k);
    }
    let known = props.iter().any(|p| match p {
        Item::Require(d) => d.name.node == r.property.node,
        Item::Avoid(a) => a.name.node == r.property.node,
        Item::Robust(x) => x.name.node == r.property.node,
        _ => false,
    });
    if !known {
        let list: Vec<&str> = index.keys().map(String::as_str).collect();
        let mut d = Diagnostic::new(
            Code::UnknownName,
            r.property.span,
            format!("unknown property `{}`", r.property.node),
        )
        .label("no such property");
        d = match ravel_syntax::diag::did_you_mean(&r.property.node, list.iter().copied()) {
            Some(s) => d.hint(format!("did you mean `{s}`?")),
            None if list.is_empty() => {
                d.hint("define the property first: `require`, `avoid` or `robust`")
            }
            None => d.hint(format!("properties: {}", list.join(", "))),
        };
        cx.err(d);
    }
    None
}

/// A radius search's `max` and `tolerance` (defaults where not given).
fn radius_budget(cx: &mut Ctx, r: &RadiusDef) -> Option<(f64, f64)> {
    let (mut max, mut tolerance) = (DEFAULT_RADIUS_MAX, None);
    let mut ok = true;
    let mut seen: Vec<(&str, Span)> = Vec::new();
    for (k, v) in &r.budget {
        if let Some((_, first)) = seen.iter().find(|(s, _)| *s == k.node) {
            cx.duplicate(&format!("the item `{}`", k.node), *first, k.span);
            ok = false;
            continue;
        }
        seen.push((&k.node, k.span));
        let x = cx.finite(v);
        match k.node.as_str() {
            "max" if x > 0.0 && x <= MAX_RADIUS_SCALE => max = x,
            "tolerance" if x > 0.0 => tolerance = Some(x),
            "max" | "tolerance" => {
                cx.err(
                    Diagnostic::new(Code::Radius, v.span, format!("`{}` must be positive{}", k.node, if k.node == "max" { " and at most 1e6" } else { "" }))
                        .label(compact(v.node).to_string())
                        .hint("`max` is the largest scale of the input set tried (1 = the set as declared); `tolerance` the width at which bisection stops"),
                );
                ok = false;
            }
            other => {
                let mut d = Diagnostic::new(
                    Code::UnknownName,
                    k.span,
                    format!("unknown radius item `{other}`"),
                )
                .label("not a radius item");
                d = match ravel_syntax::diag::did_you_mean(other, ["max", "tolerance"]) {
                    Some(s) => d.hint(format!("did you mean `{s}`? Items: max s, tolerance t")),
                    None => d.hint("items: max s (default 1), tolerance t (default max/1000)"),
                };
                cx.err(d);
                ok = false;
            }
        }
    }
    ok.then(|| (max, tolerance.unwrap_or(max * 1e-3)))
}

/// Check the robust action selections; `ok` turns false when one of them
/// had an error.
fn selects<'a>(
    cx: &mut Ctx,
    defs: &[&'a SelectDef],
    vectors: &Vectors,
    data: &super::DataFiles,
    names: &mut BTreeMap<&'a str, Span>,
    ok: &mut bool,
) -> Vec<SelectSpec> {
    let mut selects = Vec::new();
    for &d in defs {
        if !fresh(cx, names, &d.name) {
            *ok = false;
            continue;
        }
        if let (Some((xn, n)), Some((_, m))) = (&vectors.input, &vectors.output) {
            match super::select::select(cx, d, xn, *n, *m, data) {
                Some(s) => selects.push(s),
                None => *ok = false,
            }
        }
    }
    selects
}

/// The SDP relaxation (named at `span`) needs a ReLU model of bounded size.
fn sdp_fits_model(cx: &mut Ctx, span: Span, model: &Controller) {
    controller::sdp_needs_relu(cx, span, model, controller::Sdp::Relaxation);
    // the SDP's matrix: the inputs, every hidden neuron, and 1
    let dim = model.net.inputs as u64 + model.net.activation_neurons() as u64 + 1;
    if dim > MAX_SDP_DIM {
        cx.err(
            Diagnostic::new(
                Code::Limit,
                span,
                format!("the SDP relaxation would solve semidefinite programs of dimension {dim}, beyond the limit of {MAX_SDP_DIM}"),
            )
            .label("too large for the SDP relaxation")
            .hint("use `crown`, or a smaller network"),
        );
    }
}

/// A hull shape and a guided partitioner take their directions or their
/// guidance from Monte Carlo samples.
fn samples_drawn(cx: &mut Ctx, an: &AnalysisPart) {
    if let (Some(span), true) = (an.hull_span, an.samples == 0) {
        cx.err(
            Diagnostic::new(
                Code::Boundary,
                span,
                "a convex-hull shape takes its directions from Monte Carlo samples, but `samples` is 0",
            )
            .label("no samples to shape it")
            .hint("draw samples (e.g. `samples 1000`) or use `shape polytope 8`"),
        );
    }
    if let (Some((g, span)), true) = (an.guided_span, an.samples == 0) {
        cx.err(
            Diagnostic::new(
                Code::Partition,
                span,
                format!(
                    "the `{}` partitioner is guided by Monte Carlo samples, but `samples` is 0",
                    g.name()
                ),
            )
            .label("no samples to guide it")
            .hint("draw samples (e.g. `samples 1000`)"),
        );
    }
}

/// The bounds the partition's cells store (cells × directions), reported
/// at the analysis block.
fn stored_bounds(cx: &mut Ctx, span: Span, m: usize, part: &Partitioner) {
    let cells = match part {
        Partitioner::Uniform(grid) => grid.iter().map(|k| *k as u64).collect::<Vec<_>>(),
        Partitioner::Guided { budget, .. } => vec![budget.calls as u64],
    };
    let mut factors = cells;
    factors.push(2 * m as u64 + 48);
    if !within(&factors, MAX_STORED_NUMBERS) {
        cx.err(
            Diagnostic::new(
                Code::Limit,
                span,
                format!("the partition's cells would store more than {MAX_STORED_NUMBERS} bounds"),
            )
            .label("too many cells")
            .hint("use fewer cells or a smaller call budget"),
        );
    }
}

/// Check a network spec. `model` is the model file as read by the caller.
pub(super) fn check_network(
    cx: &mut Ctx,
    spec: &Spec,
    model_file: Option<&ControllerFile>,
    data: &super::DataFiles,
) -> Option<NetworkChecked> {
    let has_override = model_file.is_some_and(|f| f.path_override.is_some());
    let it = network_items(cx, spec, has_override);
    let vectors = vectors(cx, it.networks.first().copied());
    let path = effective_path(model_file, it.models.first().copied());
    let net = model(cx, path.as_ref(), model_file, &vectors);
    let sha = file_sha256(model_file);
    let input_set = input_set(cx, &vectors.input, it.inputs.first().copied());

    // names are unique across the input set, properties, radii and selections
    let mut names: BTreeMap<&str, Span> = BTreeMap::new();
    if let Some(i) = it.inputs.first() {
        names.insert(&i.name.node, i.name.span);
    }
    let mut all_ok = true;
    let properties = properties(
        cx,
        &it.props,
        &vectors.output,
        &input_set,
        &mut names,
        &mut all_ok,
    );
    let radii = radius_searches(
        cx,
        &it.radii,
        &it.props,
        &properties.index,
        &input_set,
        &mut names,
        &mut all_ok,
    );
    let selects = selects(cx, &it.selects, &vectors, data, &mut names, &mut all_ok);

    let an =
        analysis_block::analysis_block(cx, &it.analyses, &vectors.input, Some(&vectors.output));
    if let (Some(span), Some(c)) = (an.sdp_span, &net) {
        sdp_fits_model(cx, span, c);
    }
    samples_drawn(cx, &an);
    if let (Some((_, m)), Some(part)) = (&vectors.output, &an.partition) {
        let span = it.analyses.first().map_or(WHOLE, |a| a.span);
        stored_bounds(cx, span, *m, part);
    }

    if !cx.diags.is_empty() || !all_ok {
        return None;
    }
    Some(NetworkChecked {
        name: it.networks.first()?.name.node.clone(),
        input: vectors.input?,
        output: vectors.output?,
        model_path: path?.node,
        model_sha256: sha,
        model_resolved: model_file.map(|f| f.resolved.clone()).unwrap_or_default(),
        model: net?,
        input_set,
        selects,
        properties: properties.list,
        radii,
        propagator: an.net_propagator?,
        partitioner: an.partition?,
        shape: an.shape?,
        samples: an.samples,
        seed: an.seed,
        slope_steps: an.slope_steps,
    })
}
