//! The controller: load it from the bytes the caller read and check its
//! sizes against the plant; an SDP propagator's need for a ReLU network.

use super::{onnx_code, ControllerFile, Ctx};
use crate::onnx::{self, Controller};
use ravel_base::nn::{Activation, Layer};
use ravel_syntax::ast::*;
use ravel_syntax::diag::{Code, Diagnostic};

/// Where the controller's inputs come from.
#[derive(Clone, Copy)]
pub(super) enum Observed {
    /// The whole state.
    State,
    /// `Cᵀ x`.
    C,
    /// `observe […]`, written at the span.
    Observe(Span),
}

/// Load the controller named at `path` from `controller` (the caller's
/// read), and check its input size against the observation size `p_dim`
/// and its outputs against the control (unless `actuate` maps them:
/// `actuated`).
pub(super) fn controller(
    cx: &mut Ctx,
    path: Option<&Spanned<String>>,
    controller: Option<&ControllerFile>,
    (p_dim, observed): (Option<usize>, Observed),
    actuated: bool,
    control: &Option<(String, usize)>,
) -> Option<Controller> {
    let mut ctrl = None;
    let over = controller
        .and_then(|f| f.path_override.as_deref())
        .map(|p| Override {
            who: format!(
                "the controller `{}` (given with --controller)",
                ravel_syntax::diag::sanitize(p)
            ),
        });
    if let Some(path) = path {
        match controller {
            None => cx.err(
                Diagnostic::new(
                    Code::ControllerUnreadable,
                    path.span,
                    format!(
                        "controller `{}` was not read",
                        ravel_syntax::diag::sanitize(&path.node)
                    ),
                )
                .label("not available")
                .hint("the controller file must be readable next to the spec"),
            ),
            Some(file) => match &file.bytes {
                // `--controller PATH` replaced the spec's path: that path
                // is relative to the working folder, and the spec's line is
                // only where it stands in
                Err(msg) if file.path_override.is_some() => cx.err(
                    Diagnostic::new(
                        Code::ControllerUnreadable,
                        path.span,
                        format!(
                            "cannot read controller `{}` (given with --controller): {}",
                            ravel_syntax::diag::sanitize(
                                file.path_override.as_deref().unwrap_or_default()
                            ),
                            ravel_syntax::diag::sanitize(msg)
                        ),
                    )
                    .label("replaced by the --controller path")
                    .hint("--controller paths are relative to the working folder, not the spec's"),
                ),
                Err(msg) => cx.err(
                    Diagnostic::new(
                        Code::ControllerUnreadable,
                        path.span,
                        format!(
                            "cannot read controller `{}`: {}",
                            ravel_syntax::diag::sanitize(&path.node),
                            ravel_syntax::diag::sanitize(msg)
                        ),
                    )
                    .label("this file")
                    .hint("paths are relative to the spec file's folder"),
                ),
                Ok(bytes) => match onnx::load(bytes, &file.external) {
                    Err(e) => cx.err(
                        Diagnostic::new(
                            onnx_code(e.kind),
                            path.span,
                            match &over {
                                Some(o) => format!("{}: {}", o.who, e.message),
                                None => e.message,
                            },
                        )
                        .label(if over.is_some() {
                            "in the --controller file, not the spec's controller".to_string()
                        } else {
                            "in this controller".to_string()
                        })
                        .hint(e.hint),
                    ),
                    Ok(c) => {
                        let who = over.as_ref().map_or("the controller", |o| o.who.as_str());
                        if let (Some(p), Observed::Observe(span)) = (p_dim, observed) {
                            if c.inputs != p {
                                cx.err(
                                    Diagnostic::new(
                                        Code::ControllerInputs,
                                        span,
                                        format!(
                                            "`observe` lists {p} inputs but {who} takes {}",
                                            c.inputs
                                        ),
                                    )
                                    .label(format!("{p} entries"))
                                    .related(
                                        path.span,
                                        at_line(&format!("{} inputs", c.inputs), &over),
                                    )
                                    .hint("write one `observe` entry per network input"),
                                );
                            }
                        } else if let Some(p) = p_dim {
                            if c.inputs != p {
                                let what = if matches!(observed, Observed::C) {
                                    format!("C has {p} columns")
                                } else {
                                    format!("without C the controller sees the full state ({p})")
                                };
                                cx.err(
                                    Diagnostic::new(Code::ControllerInputs, path.span, format!("{who} takes {} inputs but observations have {p} components", c.inputs))
                                        .label(at_line(&format!("{} inputs", c.inputs), &over))
                                        .hint(format!("{what}; the controller's input size must match")),
                                );
                            }
                        }
                        if let (Some((un, m)), false) = (&control, actuated) {
                            if c.outputs != *m {
                                cx.err(
                                    Diagnostic::new(Code::ControllerOutputs, path.span, format!("{who} has {} outputs but `{un}` has {m} components", c.outputs))
                                        .label(at_line(&format!("{} outputs", c.outputs), &over))
                                        .hint(format!("declare `control {un}[{}]` or use a controller with {m} outputs", c.outputs)),
                                );
                            }
                        }
                        ctrl = Some(c);
                    }
                },
            },
        }
    }

    ctrl
}

/// A controller given with `--controller` in place of the spec's own: its
/// problems are the file's, and the spec's `controller` line (or the whole
/// spec) is only where it stands in.
struct Override {
    /// How messages name it.
    who: String,
}

/// A label at the spec's controller line: `what`, said of the
/// `--controller` file when one replaced the spec's.
fn at_line(what: &str, over: &Option<Override>) -> String {
    match over {
        Some(_) => format!("{what}: the --controller file, not the spec's controller"),
        None => what.to_string(),
    }
}

/// The semidefinite program that would encode a network.
#[derive(Clone, Copy)]
pub(super) enum Sdp {
    /// Reach-SDP, over a system spec's controller.
    Reach,
    /// The SDP relaxation, of a network spec's model.
    Relaxation,
}

/// An SDP (named at `span`) encodes ReLU networks only: report the first
/// other activation of `net`.
pub(super) fn sdp_needs_relu(cx: &mut Ctx, span: Span, net: &Controller, sdp: Sdp) {
    let Some(act) = net.net.layers.iter().find_map(|l| match l {
        Layer::Act(a) if *a != Activation::Relu => Some(*a),
        _ => None,
    }) else {
        return;
    };
    let (encoder, network, instead) = match sdp {
        Sdp::Reach => (
            "Reach-SDP",
            "the controller",
            "`reach_lp` or `crown_unrolled`",
        ),
        Sdp::Relaxation => ("the SDP relaxation", "the model", "`crown` or `fast_lin`"),
    };
    cx.err(
        Diagnostic::new(
            Code::SdpActivation,
            span,
            format!(
                "{encoder} encodes ReLU networks only, but {network} uses {}",
                act.name()
            ),
        )
        .label("needs a ReLU network")
        .hint(format!("use {instead}, which handle tanh and sigmoid")),
    );
}
