//! ONNX controllers: decoding (prost, no code generation), lowering the graph
//! to a [`Network`], and a small writer used by the model generator and tests.
//!
//! Supported graphs are chains on one input: `Gemm` (alpha, beta,
//! transA = 0, transB), `MatMul` (+ `Add`), `Relu`, `LeakyRelu`, `Tanh`,
//! `Sigmoid`, `Clip`, `BatchNormalization` (inference form; per channel
//! on an image), `Add`/`Sub`/`Mul`/`Div` by constants (input normalisation), 2-D `Conv`
//! (NCHW, batch 1: `strides`, `dilations`, `pads` or `auto_pad` of any
//! ONNX value, `group` including depthwise, optional bias; constant
//! weights), `AveragePool` (`ceil_mode` 0; `count_include_pad`) and
//! `GlobalAveragePool` (see [`conv`]), and the
//! shape-only ops `Flatten`, `Reshape`, `Identity`, `Squeeze`, `Unsqueeze`,
//! `Dropout` (inference), plus `Constant`. `MatMul` takes its 2-D constant
//! on either side (`x·W` as Keras writes it, `W·x` on a column as
//! VNN-COMP's test networks do). The loader follows the running value's
//! tensor shape (the batch dimension as 1): `MatMul` and broadcasting
//! follow ONNX's rules on it, and the shape-only ops must keep the flat
//! (row-major) vector — same number of elements, constant target shapes,
//! squeezed axes of size 1 — or are refused, naming the node. A
//! convolution or pooling becomes one dense affine layer on the flat
//! row-major `(C, H, W)` value, checked against the limits on width and on
//! weights (the dense matrices of the convolutions and poolings together at
//! most [`MAX_PARAMETERS`] entries) before it is allocated. Every layer is
//! stored dense (an element-wise constant op as a `width × width`
//! diagonal), and all layers together hold at most [`MAX_LAYER_ENTRIES`]
//! entries, checked after each node. Consecutive affine
//! layers (a pooling before a `Gemm`, normalisation before a `Conv`) are
//! kept as they are, not multiplied together: their product would be
//! rounded, and counterexamples are replayed layer by layer in the stored
//! precision as a runtime evaluates them (the batched CROWN kernel, which
//! needs affine layers and activations to alternate, falls back to its
//! general path; branch and bound on activations puts ReLU pairs between
//! them, `ravel_analysis::dual::alternating`). The network is a chain of layers on one running value; a
//! residual `Add` (`x + F(x)`: the running value and an earlier value `x`
//! of the chain, of one shape) is lowered into it exactly when the branch
//! `F` (the layers since `x`) has only affine layers and ReLUs
//! (`Lowering::residual`): the branch carries `[x; −x]` beside its value
//! (after a ReLU `(relu x, relu −x)`, which later ReLUs keep), and the
//! `Add` takes `x` back as `relu x − relu −x` in extra columns `[I, −I]` of
//! the branch's last affine layer. A one-layer affine branch `x + A x + b`
//! keeps its layer and gets an `Add` layer `[I, I, 0]` of its own (not one
//! layer `I + A`, whose diagonal would be rounded); so does a branch ending
//! in a ReLU. Skips nest and follow each other; a value inside a finished
//! block can no longer be skipped from (its layers now carry the pair).
//! Refused, naming the node: `Tanh`/`Sigmoid` in the branch (the pair does
//! not pass through them), an `Add` of two computed values neither of which
//! is an earlier chain value, `Concat` and other ops on two computed
//! values, shapes that differ, and a widened branch past [`MAX_WIDTH`] or
//! [`MAX_LAYER_ENTRIES`] (checked before it is built). The merged layer's
//! float32 semantics: a runtime computes `fl(fl(W h + b) + x)`, which is
//! one summation order of the merged row `W h + b + 1·relu x − 1·relu −x`
//! (the products by ±1 are exact, and one of the pair is 0, so adding it is
//! exact), so the enclosure of every summation order used to confirm
//! counterexamples (`execute::network`) covers it (an `Add` layer of its
//! own, `h + relu x − relu −x`, is likewise `fl(h + x)`); the identity rows that
//! carry the pair are exact in any order and only widen the enclosure. Weights may be float32, float64
//! (or integer and bool constants), stored in `raw_data`, in the typed
//! fields, or in external data files.
//!
//! Semantics: the network ravel verifies is the real-arithmetic function of
//! the stored weights (float32 values are widened to f64 exactly). `Clip`
//! and `LeakyRelu` become ReLU layers that compute them exactly. `Div` by a
//! constant `c` is read as multiplication by the f64 nearest to `1/c`, so
//! is an average over `k` elements (`AveragePool`, `GlobalAveragePool`:
//! the sum times the f64 nearest to `1/k`; counterexamples are replayed
//! with that weight rounded to the stored precision, as every weight), a
//! `Gemm` with `alpha ≠ 1` or `beta ≠ 1` has its weights scaled in f64, and
//! `BatchNormalization` is the diagonal affine map whose coefficients
//! `scale/√(var + ε)` and `B − mean·scale/√(var + ε)` are computed in f64
//! (each within a few ulps of the exact value).
//!
//! The graph input's element type is recorded as the network's
//! [`InputType`] (`double`: float64; anything else: float32): the type a
//! counterexample's input must have.

// the loader reads untrusted files: no panicking shortcuts
#![deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

pub mod build;
mod conv;
pub mod proto;

use std::collections::{BTreeMap, HashMap};

use nalgebra::{DMatrix, DVector};
use prost::Message;

use proto::{
    dtype, AttributeProto, GraphProto, ModelProto, NodeProto, TensorProto, ValueInfoProto,
};
use ravel_base::limits::{
    MAX_CONTROLLER_BYTES, MAX_LAYER_ENTRIES, MAX_MAGNITUDE, MAX_NODES, MAX_PARAMETERS,
    MAX_TENSOR_ELEMENTS, MAX_WIDTH,
};
use ravel_base::nn::{Activation, InputType, Layer, Network};
use ravel_syntax::diag::sanitize;

/// Contents of external-data files, by their normalised location (see
/// [`normalise_location`]). A read failure is kept as its message so the
/// checker can report it.
pub type ExternalFiles = BTreeMap<String, Result<Vec<u8>, String>>;

/// What went wrong while loading a controller.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OnnxErrorKind {
    /// Not a decodable ONNX protobuf.
    Decode,
    /// An operator, attribute value or data type ravel does not support.
    Unsupported,
    /// A NaN or infinite weight (or a division by zero).
    NonFinite,
    /// A graph that is not a chain on one input, or inconsistent shapes.
    Malformed,
    /// An external-data file that is missing or too short.
    ExternalData,
}

/// A problem with an ONNX file, with a message and a hint for the user.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OnnxError {
    /// The category (mapped to a diagnostic code by `check`).
    pub kind: OnnxErrorKind,
    /// What is wrong, naming the node, tensor or attribute.
    pub message: String,
    /// How to fix it.
    pub hint: String,
}

fn err(kind: OnnxErrorKind, message: impl Into<String>, hint: impl Into<String>) -> OnnxError {
    OnnxError {
        kind,
        message: message.into(),
        hint: hint.into(),
    }
}

/// A controller loaded from ONNX: the network and the declared input and output sizes.
#[derive(Clone, Debug, PartialEq)]
pub struct Controller {
    /// Exporter ops rewritten into the chain (e.g. `clip [-1, 1]`), for reports.
    pub notes: Vec<String>,
    /// The network as a chain of layers.
    pub net: Network,
    /// Number of inputs.
    pub inputs: usize,
    /// Number of outputs.
    pub outputs: usize,
}

/// A tensor shape for a message: at most 8 dimensions are listed.
fn shape_text<T: std::fmt::Display>(dims: &[T]) -> String {
    let shown: Vec<String> = dims.iter().take(8).map(|d| d.to_string()).collect();
    if dims.len() > 8 {
        format!("[{}, … ({} dimensions)]", shown.join(", "), dims.len())
    } else {
        format!("[{}]", shown.join(", "))
    }
}

/// An external-data file the loader will need: its normalised location
/// (relative to the model's folder, without `.` components) and how many
/// bytes from its start the model's tensors need (the largest
/// `offset + length` over the tensors stored in it, each length being what
/// the tensor's declared shape and type need).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ExternalRequest {
    /// The normalised location.
    pub location: String,
    /// Bytes needed from the start of the file.
    pub bytes: u64,
}

/// A tensor's `location` as a plain relative path inside the model's
/// folder: `/`-separated normal components (`.` components dropped, so `./x`
/// and `x` are one file). `None` for an absolute path, a `..` component, a
/// backslash, a NUL, or nothing left.
pub fn normalise_location(location: &str) -> Option<String> {
    if location.starts_with('/') || location.contains('\\') || location.contains('\0') {
        return None;
    }
    let mut parts = Vec::new();
    for c in location.split('/') {
        match c {
            "" | "." => {}
            ".." => return None,
            // a Windows drive prefix such as `C:` is not a plain name either
            c if c.contains(':') => return None,
            c => parts.push(c),
        }
    }
    (!parts.is_empty()).then(|| parts.join("/"))
}

/// The external-data files the model's tensors use, each once, with the
/// number of bytes needed from each, so the caller reads no file outside the
/// model's folder and nothing beyond what the declared shapes need.
/// Tensors whose location, offset, length or shape is invalid are left out:
/// [`load`] reports them. Undecodable bytes give an empty list.
pub fn external_requests(bytes: &[u8]) -> Vec<ExternalRequest> {
    let Ok(model) = ModelProto::decode(bytes) else {
        return Vec::new();
    };
    let mut need: BTreeMap<String, u64> = BTreeMap::new();
    let mut visit = |t: &TensorProto| {
        if t.data_location != Some(1) {
            return;
        }
        let Ok(ext) = external_entry(t) else {
            return;
        };
        let Some(end) = ext.offset.checked_add(ext.length) else {
            return;
        };
        let e = need.entry(ext.location).or_insert(0);
        *e = (*e).max(end);
    };
    if let Some(g) = &model.graph {
        g.initializer.iter().for_each(&mut visit);
        for n in &g.node {
            for a in &n.attribute {
                if let Some(t) = &a.t {
                    visit(t);
                }
            }
        }
    }
    need.into_iter()
        .map(|(location, bytes)| ExternalRequest { location, bytes })
        .collect()
}

/// Where a tensor's external data is: normalised location, offset, and the
/// length its declared shape and type need.
struct ExternalEntry {
    location: String,
    offset: u64,
    length: u64,
}

/// Validate a tensor's external-data entry before anything is read.
fn external_entry(t: &TensorProto) -> Result<ExternalEntry, OnnxError> {
    let name = tensor_name(t);
    let (numel, width) = tensor_size(t)?;
    let needed = numel
        .checked_mul(width as u64)
        .filter(|b| *b <= MAX_CONTROLLER_BYTES);
    let Some(needed) = needed else {
        return Err(err(
            OnnxErrorKind::Malformed,
            format!("tensor '{name}' is too large"),
            "ravel reads controllers of at most 512 MiB",
        ));
    };
    let mut location = None;
    let (mut offset, mut length) = (0u64, None);
    for e in &t.external_data {
        let v = e.value.clone().unwrap_or_default();
        let number = |what: &str| {
            v.trim().parse::<u64>().map_err(|_| {
                err(
                    OnnxErrorKind::ExternalData,
                    format!(
                        "tensor '{name}' has an external-data {what} '{}' that is not a byte count",
                        sanitize(&v)
                    ),
                    "re-export the model with its data file",
                )
            })
        };
        match e.key.as_deref() {
            Some("location") => location = Some(v.clone()),
            Some("offset") => offset = number("offset")?,
            Some("length") => length = Some(number("length")?),
            _ => {}
        }
    }
    let Some(raw) = location else {
        return Err(err(
            OnnxErrorKind::ExternalData,
            format!("tensor '{name}' is external but has no location"),
            "re-export the model with its data file",
        ));
    };
    let Some(location) = normalise_location(&raw) else {
        return Err(err(
            OnnxErrorKind::ExternalData,
            format!(
                "external data location '{}' of tensor '{name}' is not a file inside the controller's folder",
                sanitize(&raw)
            ),
            "external data must be a relative path without `..` next to the .onnx file; re-export the model",
        ));
    };
    if offset
        .checked_add(needed)
        .is_none_or(|end| end > MAX_CONTROLLER_BYTES)
    {
        return Err(err(
            OnnxErrorKind::ExternalData,
            format!(
                "external data of tensor '{name}' ends beyond 512 MiB (offset {offset}, {needed} bytes)"
            ),
            "ravel reads at most 512 MiB of external data; re-export the model",
        ));
    }
    if let Some(l) = length {
        if l != needed {
            return Err(err(
                OnnxErrorKind::ExternalData,
                format!(
                    "tensor '{name}' declares {l} bytes of external data but its shape needs {needed}"
                ),
                "the .data file does not belong to this model: re-export both together",
            ));
        }
    }
    Ok(ExternalEntry {
        location,
        offset,
        length: needed,
    })
}

/// A tensor's number of elements (checked against the limits, without
/// overflow) and the width in bytes of its element type.
fn tensor_size(t: &TensorProto) -> Result<(u64, usize), OnnxError> {
    let name = tensor_name(t);
    let mut numel = 1u64;
    for &d in &t.dims {
        if d < 0 {
            return Err(err(
                OnnxErrorKind::Malformed,
                format!("tensor '{name}' has a negative dimension {d}"),
                "re-export the model",
            ));
        }
        numel = numel
            .checked_mul(d as u64)
            .filter(|n| *n <= MAX_TENSOR_ELEMENTS)
            .ok_or_else(|| {
                err(
                    OnnxErrorKind::Malformed,
                    format!(
                        "tensor '{name}' has more than {MAX_TENSOR_ELEMENTS} elements (shape {})",
                        shape_text(&t.dims)
                    ),
                    "ravel verifies controllers of at most 16777216 weights per tensor",
                )
            })?;
    }
    let dt = t.data_type.unwrap_or(0);
    let width = match dt {
        dtype::BOOL => 1,
        dtype::FLOAT | dtype::INT32 => 4,
        dtype::DOUBLE | dtype::INT64 => 8,
        other => {
            return Err(err(
                OnnxErrorKind::Unsupported,
                format!(
                    "tensor '{name}' has ONNX data type {other} ({}), which ravel does not read",
                    dtype_name(other)
                ),
                "export the weights as float32 or float64",
            ))
        }
    };
    Ok((numel, width))
}

/// A constant tensor.
#[derive(Clone, Debug)]
struct Tensor {
    dims: Vec<usize>,
    data: Vec<f64>,
}

fn node_label(n: &NodeProto) -> String {
    let op = sanitize(n.op_type.as_deref().unwrap_or_default());
    match n.name.as_deref() {
        Some(name) if !name.is_empty() => format!("node '{}' ({op})", sanitize(name)),
        _ => format!(
            "the {op} node producing '{}'",
            sanitize(n.output.first().map_or("", String::as_str))
        ),
    }
}

/// The tensor's name, made safe to show.
fn tensor_name(t: &TensorProto) -> String {
    t.name
        .as_deref()
        .map_or_else(|| "<unnamed>".into(), sanitize)
}

/// Decode a tensor's values to f64 (integers are converted too).
fn tensor_values(t: &TensorProto, external: &ExternalFiles) -> Result<Tensor, OnnxError> {
    let name = tensor_name(t);
    let (numel, width) = tensor_size(t)?;
    // tensor_size bounds every dimension and their product
    let dims: Vec<usize> = t.dims.iter().map(|d| *d as usize).collect();
    let numel = numel as usize;
    let dt = t.data_type.unwrap_or(0);
    let raw: Option<Vec<u8>> = if t.data_location == Some(1) {
        Some(read_external(t, external)?)
    } else {
        t.raw_data.clone()
    };
    let data: Vec<f64> = match raw {
        Some(bytes) => {
            if bytes.len() != numel * width {
                return Err(err(
                    OnnxErrorKind::Malformed,
                    format!(
                        "tensor '{name}' has {} bytes of data but its shape {} needs {}",
                        bytes.len(),
                        shape_text(&dims),
                        numel * width
                    ),
                    "re-export the model",
                ));
            }
            match dt {
                dtype::BOOL => bytes.iter().map(|b| f64::from(u8::from(*b != 0))).collect(),
                dtype::FLOAT => bytes
                    .chunks_exact(4)
                    .map(|c| f32::from_le_bytes(le(c)) as f64)
                    .collect(),
                dtype::INT32 => bytes
                    .chunks_exact(4)
                    .map(|c| i32::from_le_bytes(le(c)) as f64)
                    .collect(),
                dtype::DOUBLE => bytes
                    .chunks_exact(8)
                    .map(|c| f64::from_le_bytes(le(c)))
                    .collect(),
                _ => bytes
                    .chunks_exact(8)
                    .map(|c| i64::from_le_bytes(le(c)) as f64)
                    .collect(),
            }
        }
        None => match dt {
            dtype::FLOAT => t.float_data.iter().map(|v| *v as f64).collect(),
            dtype::DOUBLE => t.double_data.clone(),
            dtype::INT32 | dtype::BOOL => t.int32_data.iter().map(|v| *v as f64).collect(),
            _ => t.int64_data.iter().map(|v| *v as f64).collect(),
        },
    };
    if data.len() != numel {
        return Err(err(
            OnnxErrorKind::Malformed,
            format!(
                "tensor '{name}' has {} values but its shape {} needs {numel}",
                data.len(),
                shape_text(&dims)
            ),
            "re-export the model",
        ));
    }
    Ok(Tensor { dims, data })
}

/// The first `N` bytes of a chunk (chunks come from `chunks_exact(N)`, so
/// they have exactly `N`; a shorter one would give zeros, never a panic).
fn le<const N: usize>(c: &[u8]) -> [u8; N] {
    let mut a = [0u8; N];
    for (d, s) in a.iter_mut().zip(c) {
        *d = *s;
    }
    a
}

fn dtype_name(d: i32) -> &'static str {
    match d {
        2 => "uint8",
        3 => "int8",
        9 => "bool",
        10 => "float16",
        16 => "bfloat16",
        _ => "unsupported",
    }
}

fn read_external(t: &TensorProto, external: &ExternalFiles) -> Result<Vec<u8>, OnnxError> {
    let name = tensor_name(t);
    let ext = external_entry(t)?;
    let shown = sanitize(&ext.location);
    let bytes = match external.get(&ext.location) {
        Some(Ok(b)) => b,
        Some(Err(msg)) => {
            return Err(err(
                OnnxErrorKind::ExternalData,
                format!(
                    "cannot read external data file '{shown}' of tensor '{name}': {}",
                    sanitize(msg)
                ),
                "keep the .data file next to the .onnx file, as a regular file",
            ))
        }
        None => {
            return Err(err(
                OnnxErrorKind::ExternalData,
                format!("external data file '{shown}' of tensor '{name}' was not provided"),
                "keep the .data file next to the .onnx file",
            ))
        }
    };
    let range = usize::try_from(ext.offset).ok().and_then(|o| {
        let end = o.checked_add(usize::try_from(ext.length).ok()?)?;
        bytes.get(o..end)
    });
    match range {
        Some(r) => Ok(r.to_vec()),
        None => Err(err(
            OnnxErrorKind::ExternalData,
            format!(
                "external data of tensor '{name}' ({} bytes at offset {}) runs past the end of '{shown}' ({} bytes)",
                ext.length,
                ext.offset,
                bytes.len()
            ),
            "the .data file does not belong to this model: re-export both together",
        )),
    }
}

fn attr<'a>(n: &'a NodeProto, name: &str) -> Option<&'a AttributeProto> {
    n.attribute.iter().find(|a| a.name.as_deref() == Some(name))
}

fn attr_i(n: &NodeProto, name: &str, default: i64) -> i64 {
    attr(n, name).and_then(|a| a.i).unwrap_or(default)
}

fn attr_f(n: &NodeProto, name: &str, default: f64) -> f64 {
    attr(n, name)
        .and_then(|a| a.f)
        .map(|f| f as f64)
        .unwrap_or(default)
}

/// The ops ravel accepts, for hints.
pub const SUPPORTED_OPS: &str =
    "Gemm, MatMul, Add, Sub, Mul, Div, Relu, LeakyRelu, Tanh, Sigmoid, Clip, BatchNormalization, Conv (2-D), AveragePool, GlobalAveragePool, Flatten, Reshape, Identity, Squeeze, Unsqueeze, Dropout (inference), Constant";

struct Lowering {
    consts: HashMap<String, Tensor>,
    current: String,
    width: Option<usize>,
    /// The running value's tensor shape (symbolic dimensions, such as the
    /// batch, as 1), when known; its product is `width`. Shape-only ops
    /// check against it, and `MatMul` and broadcasting follow it.
    shape: Option<Vec<usize>>,
    layers: Vec<Layer>,
    /// What was rewritten (clips, leaky ReLUs, batch normalisation), for the summary.
    notes: Vec<String>,
    /// Entries of the dense matrices of the convolutions and poolings so
    /// far (see [`Lowering::reserve`]).
    dense: u64,
    /// The values of the chain a residual `Add` may take as its skip: each
    /// value's name, with the number of layers before it and its width
    /// and shape (see [`Lowering::residual`]).
    values: HashMap<String, ChainValue>,
}

/// A value of the layer chain: the input of layer `at` (the chain's output
/// when `at` is the number of layers), of width `width` and shape `shape`.
#[derive(Clone, Debug)]
struct ChainValue {
    at: usize,
    width: Option<usize>,
    shape: Option<Vec<usize>>,
}

impl Lowering {
    /// Split a binary node's inputs into (const, is_const_first).
    fn const_operand(&self, n: &NodeProto) -> Result<(Tensor, bool), OnnxError> {
        if n.input.len() != 2 {
            return Err(err(
                OnnxErrorKind::Malformed,
                format!("{} needs two inputs", node_label(n)),
                "re-export the model",
            ));
        }
        let (Some(a), Some(b)) = (n.input.first(), n.input.get(1)) else {
            return Err(err(
                OnnxErrorKind::Malformed,
                format!("{} needs two inputs", node_label(n)),
                "re-export the model",
            ));
        };
        if a == &self.current {
            self.consts.get(b).cloned().map(|t| (t, false))
        } else if b == &self.current {
            self.consts.get(a).cloned().map(|t| (t, true))
        } else {
            None
        }
        .ok_or_else(|| {
            err(
                OnnxErrorKind::Unsupported,
                format!("{} combines two computed values; ravel supports chains with constant operands and residual Adds", node_label(n)),
                "export a feed-forward network whose only skip connections are residual Adds (x + F(x))",
            )
        })
    }

    fn width(&self) -> Result<usize, OnnxError> {
        self.width.ok_or_else(|| {
            err(
                OnnxErrorKind::Malformed,
                "the input size is unknown before the first element-wise op",
                "give the graph input a static shape",
            )
        })
    }

    /// A per-element vector from a constant of 1 or `width` elements.
    fn broadcast(&self, n: &NodeProto, t: &Tensor) -> Result<DVector<f64>, OnnxError> {
        let w = self.width()?;
        if t.data.len() == 1 {
            Ok(DVector::from_element(
                w,
                t.data.first().copied().unwrap_or(0.0),
            ))
        } else if t.data.len() == w {
            Ok(DVector::from_column_slice(&t.data))
        } else {
            Err(err(
                OnnxErrorKind::Malformed,
                format!(
                    "{} uses a constant of {} elements on a value of width {w}",
                    node_label(n),
                    t.data.len()
                ),
                "the constant must be a scalar or have one entry per element",
            ))
        }
    }

    /// Count the dense `rows × cols` matrix of a convolution or pooling
    /// `n` before it is allocated, refusing the node when the entries of
    /// these matrices together would pass [`MAX_PARAMETERS`] (a
    /// convolution's matrix is far larger than its kernel).
    fn reserve(&mut self, n: &NodeProto, rows: usize, cols: usize) -> Result<(), OnnxError> {
        let total = (rows as u64)
            .checked_mul(cols as u64)
            .and_then(|e| e.checked_add(self.dense));
        match total {
            Some(t) if t <= MAX_PARAMETERS => {
                self.dense = t;
                Ok(())
            }
            _ => Err(too_many_weights(n, rows, cols)),
        }
    }

    /// Append an affine layer; the value's shape is kept when the layer
    /// keeps its width (callers that change the shape set it after).
    fn push_affine(&mut self, w: DMatrix<f64>, b: DVector<f64>) {
        self.width = Some(w.nrows());
        if self.shape.as_deref().and_then(shape_width) != Some(w.nrows()) {
            self.shape = Some(vec![w.nrows()]);
        }
        self.layers.push(Layer::Affine { w, b });
    }

    /// The running value's shape: as tracked, else the flat width.
    fn value_shape(&self, n: &NodeProto) -> Result<Vec<usize>, OnnxError> {
        match (&self.shape, self.width) {
            (Some(s), _) => Ok(s.clone()),
            (None, Some(w)) => Ok(vec![w]),
            (None, None) => Err(err(
                OnnxErrorKind::Malformed,
                format!("{} reads a value of unknown size", node_label(n)),
                "give the graph input a static shape",
            )),
        }
    }

    /// A constant operand of an element-wise op, broadcast (ONNX's
    /// multidirectional broadcasting) over the running value: one entry
    /// per element of the flat value. A constant that would broadcast the
    /// value to a larger shape is refused (the op would not be element-wise
    /// on the value). Without a known shape: a constant of 1 or `width`
    /// elements.
    fn broadcast_shaped(&self, n: &NodeProto, t: &Tensor) -> Result<DVector<f64>, OnnxError> {
        let Some(shape) = self.shape.clone() else {
            return self.broadcast(n, t);
        };
        let refuse = |what: &str| {
            err(
                OnnxErrorKind::Malformed,
                format!(
                    "{} combines a value of shape {} with a constant of shape {}, which {what}",
                    node_label(n),
                    shape_text(&shape),
                    shape_text(&t.dims)
                ),
                "the constant must broadcast to the value's shape (a scalar, or one entry per element or per channel)",
            )
        };
        if t.dims.len() > shape.len()
            && t.dims
                .iter()
                .take(t.dims.len() - shape.len())
                .any(|d| *d != 1)
        {
            return Err(refuse("would make the value larger"));
        }
        // the constant's dimensions aligned with the value's last ones
        let rank = shape.len();
        let mut cdims = vec![1usize; rank];
        for (slot, d) in cdims.iter_mut().rev().zip(t.dims.iter().rev().take(rank)) {
            *slot = *d;
        }
        for (c, d) in cdims.iter().zip(&shape) {
            if c != d && *c != 1 {
                return Err(refuse(if *d == 1 {
                    "would make the value larger"
                } else {
                    "do not broadcast"
                }));
            }
        }
        // row-major strides of the constant, 0 along broadcast dimensions
        let mut strides = vec![0usize; rank];
        let mut acc = 1usize;
        for (s, c) in strides.iter_mut().zip(&cdims).rev() {
            if *c != 1 {
                *s = acc;
            }
            acc = acc.saturating_mul(*c);
        }
        let width = shape_width(&shape).unwrap_or(0);
        let mut out = Vec::with_capacity(width);
        for flat in 0..width {
            let (mut rest, mut at) = (flat, 0usize);
            for (d, s) in shape.iter().zip(&strides).rev() {
                let d = (*d).max(1);
                at += (rest % d) * s;
                rest /= d;
            }
            out.push(t.data.get(at).copied().unwrap_or(0.0));
        }
        Ok(DVector::from_vec(out))
    }

    /// `Flatten`, `Reshape`, `Squeeze`, `Unsqueeze` (and `Identity`): the
    /// flat value is unchanged; the new shape is computed and checked
    /// (same number of elements, axes in range, squeezed axes of size 1,
    /// a constant target shape), and anything else is refused.
    fn reshape(&mut self, n: &NodeProto, op: &str) -> Result<(), OnnxError> {
        if op == "Identity" {
            return Ok(());
        }
        let shape = self.value_shape(n)?;
        let width = shape_width(&shape).unwrap_or(0);
        let bad = |what: String| {
            err(
                OnnxErrorKind::Malformed,
                format!("{} {what}", node_label(n)),
                "the model's shapes are inconsistent: re-export it",
            )
        };
        let rank = shape.len() as i64;
        // an axis in [-r, r) (or [-r, r] for Flatten and the output rank of Unsqueeze)
        let axis = |a: i64, r: i64, inclusive: bool| -> Result<usize, OnnxError> {
            let top = if inclusive { r } else { r - 1 };
            if a < -r || a > top {
                return Err(bad(format!(
                    "uses axis {a} on a value of shape {}",
                    shape_text(&shape)
                )));
            }
            let a = if a < 0 { a + r } else { a };
            Ok(a as usize)
        };
        // opset ≥ 13: axes as a constant input; before, as an attribute
        let axes = |k: usize| -> Result<Option<Vec<i64>>, OnnxError> {
            match n.input.get(k).filter(|s| !s.is_empty()) {
                Some(name) => {
                    let t = self.named_const(n, name, "axes", "export with constant folding on")?;
                    Ok(Some(t.data.iter().map(|v| *v as i64).collect()))
                }
                None => Ok(attr(n, "axes").map(|a| a.ints.clone())),
            }
        };
        let new: Vec<usize> = match op {
            "Flatten" => {
                let a = axis(attr_i(n, "axis", 1), rank, true)?;
                let (head, tail) = shape.split_at(a.min(shape.len()));
                let p = |d: &[usize]| d.iter().product::<usize>();
                vec![p(head), p(tail)]
            }
            "Reshape" => {
                let name = n.input.get(1).cloned().unwrap_or_default();
                let t = self.consts.get(&name).ok_or_else(|| {
                    err(
                        OnnxErrorKind::Unsupported,
                        format!(
                            "{} reshapes to a computed shape '{}'",
                            node_label(n),
                            sanitize(&name)
                        ),
                        "export with constant folding on (the target shape must be a constant)",
                    )
                })?;
                let allow_zero = attr_i(n, "allowzero", 0) != 0;
                let mut out = Vec::with_capacity(t.data.len());
                let mut infer = None;
                for (i, v) in t.data.iter().enumerate() {
                    let d = *v as i64;
                    if d as f64 != *v || d < -1 || out.len() >= 64 {
                        return Err(bad(format!(
                            "reshapes to {}, which is not a shape",
                            shape_text(&t.data)
                        )));
                    }
                    match d {
                        -1 if infer.is_none() => {
                            infer = Some(i);
                            out.push(1);
                        }
                        -1 => {
                            return Err(bad(format!(
                                "reshapes to {} (two dimensions to infer)",
                                shape_text(&t.data)
                            )))
                        }
                        0 if !allow_zero => match shape.get(i) {
                            Some(s) => out.push(*s),
                            None => {
                                return Err(bad(format!(
                                    "copies dimension {i} of a value of shape {}",
                                    shape_text(&shape)
                                )))
                            }
                        },
                        d => out.push(d as usize),
                    }
                }
                let known = out
                    .iter()
                    .try_fold(1usize, |a, d| a.checked_mul(*d))
                    .unwrap_or(0);
                if let Some(i) = infer {
                    if known == 0 || width % known != 0 {
                        return Err(bad(format!(
                            "cannot reshape a value of shape {} to {}",
                            shape_text(&shape),
                            shape_text(&t.data)
                        )));
                    }
                    if let Some(slot) = out.get_mut(i) {
                        *slot = width / known;
                    }
                }
                if shape_width(&out) != Some(width) {
                    return Err(bad(format!(
                        "reshapes a value of shape {} ({width} elements) to {}",
                        shape_text(&shape),
                        shape_text(&t.data)
                    )));
                }
                out
            }
            "Squeeze" => match axes(1)? {
                None => shape.iter().copied().filter(|d| *d != 1).collect(),
                Some(list) => {
                    let mut drop = Vec::new();
                    for a in list {
                        let a = axis(a, rank, false)?;
                        if shape.get(a) != Some(&1) {
                            return Err(bad(format!(
                                "squeezes axis {a} of a value of shape {}, which is not of size 1",
                                shape_text(&shape)
                            )));
                        }
                        drop.push(a);
                    }
                    shape
                        .iter()
                        .enumerate()
                        .filter(|(i, _)| !drop.contains(i))
                        .map(|(_, d)| *d)
                        .collect()
                }
            },
            // Unsqueeze
            _ => {
                let Some(list) = axes(1)? else {
                    return Err(bad("has no axes".to_string()));
                };
                let out_rank = rank + list.len() as i64;
                let mut at = Vec::new();
                for a in list {
                    let a = axis(a, out_rank, false)?;
                    if at.contains(&a) {
                        return Err(bad(format!("names axis {a} twice")));
                    }
                    at.push(a);
                }
                let mut rest = shape.iter();
                (0..out_rank as usize)
                    .map(|i| {
                        if at.contains(&i) {
                            1
                        } else {
                            rest.next().copied().unwrap_or(1)
                        }
                    })
                    .collect()
            }
        };
        if new.len() > 64 {
            return Err(bad("gives a value of more than 64 dimensions".to_string()));
        }
        self.width = Some(width);
        self.shape = Some(new);
        Ok(())
    }

    /// Refuse a layer wider than [`MAX_WIDTH`] before it is built.
    fn check_width(n: &NodeProto, width: usize) -> Result<(), OnnxError> {
        if width as u64 > MAX_WIDTH {
            return Err(err(
                OnnxErrorKind::Unsupported,
                format!(
                    "{} has width {width}, more than ravel's limit of {MAX_WIDTH}",
                    node_label(n)
                ),
                "ravel verifies controllers whose layers have at most 4096 neurons",
            ));
        }
        Ok(())
    }

    fn add_bias(&mut self, bias: DVector<f64>) {
        let len = self.layers.len();
        if let Some(Layer::Affine { b, .. }) = self.layers.last_mut() {
            if b.iter().all(|v| *v == 0.0) && b.len() == bias.len() {
                *b = bias; // exact: the previous bias is zero
                           // the values after that layer (without the bias) are gone
                self.values.retain(|_, v| v.at != len);
                return;
            }
        }
        let n = bias.len();
        self.push_affine(DMatrix::identity(n, n), bias);
    }

    /// The other operand of an `Add` of the running value and a computed
    /// value (a residual connection): `None` for any other node.
    fn computed_operand(&self, n: &NodeProto, op: &str) -> Option<String> {
        if op != "Add" {
            return None;
        }
        let [a, b] = n.input.as_slice() else {
            return None;
        };
        let other = if a == &self.current { b } else { a };
        (!self.consts.contains_key(other)).then(|| other.clone())
    }

    /// A residual `Add` of the running value `h` (width `n`) and the
    /// earlier chain value `x` (same width and shape), lowered exactly into
    /// the chain: the layers since `x` (the branch, affine layers and ReLUs
    /// only) carry the pair `[x; −x]` beside their own value — the first
    /// affine layer also outputs it (identity rows; a branch that starts
    /// with a ReLU gets an identity layer `[I; I; −I]` first), every later
    /// affine layer passes it with identity blocks, and every ReLU maps it
    /// to `(relu x, relu −x)`, which later ReLUs keep. The `Add` then takes
    /// `x` back as `relu x − relu −x` (or the pair's first half when the
    /// branch has no ReLU): it joins the branch's last affine layer as the
    /// extra columns `[I, −I]` (`W h' + b + relu x − relu −x`), or is an
    /// affine layer `[I, I, −I]` of its own when that last layer is the
    /// fork's (a purely affine branch of one layer: its weights are not
    /// added to the identity) or a ReLU. Sizes are checked before anything
    /// is allocated.
    fn residual(&mut self, n: &NodeProto, skip: &str) -> Result<(), OnnxError> {
        let refuse = |kind: OnnxErrorKind, what: String, hint: &str| {
            err(kind, format!("{} {what}", node_label(n)), hint)
        };
        let chain_hint = "ravel supports residual Adds whose skip comes from an earlier value of the layer chain (x + F(x), F of affine layers and ReLUs); export other graphs as a plain chain";
        let Some(fork) = self.values.get(skip).cloned() else {
            return Err(refuse(
                OnnxErrorKind::Unsupported,
                format!(
                    "adds '{}', which is not an earlier value of the layer chain (two computed values, neither descending from the other, or a skip across another skip's end)",
                    sanitize(skip)
                ),
                chain_hint,
            ));
        };
        let start = fork.at;
        let branch = self.layers.get(start..).unwrap_or_default();
        if branch.is_empty() {
            return Err(refuse(
                OnnxErrorKind::Unsupported,
                format!(
                    "adds '{}' to a value with no layer between them",
                    sanitize(skip)
                ),
                "fold the doubling into the next layer before export",
            ));
        }
        if let Some(a) = branch.iter().find_map(|l| match l {
            Layer::Act(a) if *a != Activation::Relu => Some(*a),
            _ => None,
        }) {
            return Err(refuse(
                OnnxErrorKind::Unsupported,
                format!(
                    "closes a skip connection across a {} activation, which ravel cannot carry the skipped value through exactly",
                    match a {
                        Activation::Tanh => "Tanh",
                        _ => "Sigmoid",
                    }
                ),
                "ravel supports residual blocks whose branch has only affine layers and ReLU (or LeakyRelu, Clip) activations",
            ));
        }
        let h = self.width()?;
        let first_cols = match branch.first() {
            Some(Layer::Affine { w, .. }) => Some(w.ncols()),
            _ => None,
        };
        let Some(width) = fork.width.or(first_cols) else {
            return Err(refuse(
                OnnxErrorKind::Malformed,
                format!("adds '{}', a value of unknown size", sanitize(skip)),
                "give the graph input a static shape",
            ));
        };
        // the flat layouts agree, and broadcasting cannot enlarge either
        let strip = |s: &[usize]| {
            s.iter()
                .skip_while(|d| **d == 1)
                .copied()
                .collect::<Vec<_>>()
        };
        let shapes_differ = match (&fork.shape, &self.shape) {
            (Some(a), Some(b)) => strip(a) != strip(b),
            _ => false,
        };
        if width != h || shapes_differ {
            let shown = |s: &Option<Vec<usize>>, w: usize| {
                s.as_ref().map_or(format!("of width {w}"), |s| {
                    format!("of shape {}", shape_text(s))
                })
            };
            return Err(refuse(
                OnnxErrorKind::Malformed,
                format!(
                    "adds a value {} to '{}', a value {}",
                    shown(&self.shape, h),
                    sanitize(skip),
                    shown(&fork.shape, width)
                ),
                "a residual connection adds values of one shape",
            ));
        }
        // sizes of the new layers, checked before they are built
        let k = width.checked_mul(2);
        let last = branch.len() - 1;
        let merge = last > 0 && matches!(branch.last(), Some(Layer::Affine { .. }));
        let mut dims: Vec<(Option<usize>, Option<usize>)> = Vec::new();
        for (i, l) in branch.iter().enumerate() {
            match l {
                Layer::Act(_) if i == 0 => {
                    dims.push((k.and_then(|k| k.checked_add(width)), Some(width)))
                }
                Layer::Act(_) => {}
                Layer::Affine { w, .. } if i == 0 => {
                    dims.push((k.and_then(|k| k.checked_add(w.nrows())), Some(w.ncols())))
                }
                Layer::Affine { w, .. } if i == last && merge => {
                    dims.push((Some(w.nrows()), k.and_then(|k| k.checked_add(w.ncols()))))
                }
                Layer::Affine { w, .. } => dims.push((
                    k.and_then(|k| k.checked_add(w.nrows())),
                    k.and_then(|k| k.checked_add(w.ncols())),
                )),
            }
        }
        if !merge {
            dims.push((Some(width), k.and_then(|k| k.checked_add(width))));
        }
        let too_wide = || {
            refuse(
                OnnxErrorKind::Unsupported,
                format!(
                    "carries a skipped value of width {width} beside its branch, which takes a layer past ravel's limit of {MAX_WIDTH} neurons"
                ),
                "ravel verifies small networks: a residual block widens its branch by twice the skipped width",
            )
        };
        let mut entries = self
            .layers
            .get(..start)
            .unwrap_or_default()
            .iter()
            .fold(0u64, |t, l| match l {
                Layer::Affine { w, .. } => {
                    t.saturating_add((w.nrows() as u64).saturating_mul(w.ncols() as u64))
                }
                Layer::Act(_) => t,
            });
        for (r, c) in &dims {
            let (Some(r), Some(c)) = (r, c) else {
                return Err(too_wide());
            };
            if *r as u64 > MAX_WIDTH || *c as u64 > MAX_WIDTH {
                return Err(too_wide());
            }
            entries = entries.saturating_add((*r as u64).saturating_mul(*c as u64));
        }
        if entries > MAX_LAYER_ENTRIES {
            return Err(refuse(
                OnnxErrorKind::Unsupported,
                format!(
                    "carries a skipped value of width {width} beside its branch, which brings the network's layers to {entries} matrix entries, more than ravel's limit of {MAX_LAYER_ENTRIES}"
                ),
                "ravel verifies small networks: a residual block widens its branch by twice the skipped width",
            ));
        }
        let relu = branch.iter().any(|l| matches!(l, Layer::Act(_)));
        let eye = DMatrix::<f64>::identity(width, width);
        // x from the pair: relu x − relu −x after a ReLU, else the first half
        let mut back = DMatrix::<f64>::zeros(width, 2 * width);
        back.view_mut((0, 0), (width, width)).copy_from(&eye);
        if relu {
            back.view_mut((0, width), (width, width))
                .copy_from(&(-&eye));
        }
        let tail = self.layers.split_off(start);
        let mut out = Vec::with_capacity(tail.len() + 2);
        for (i, l) in tail.into_iter().enumerate() {
            match l {
                Layer::Act(a) => {
                    if i == 0 {
                        let mut w = DMatrix::<f64>::zeros(3 * width, width);
                        w.view_mut((0, 0), (width, width)).copy_from(&eye);
                        w.view_mut((width, 0), (width, width)).copy_from(&eye);
                        w.view_mut((2 * width, 0), (width, width))
                            .copy_from(&(-&eye));
                        out.push(Layer::Affine {
                            w,
                            b: DVector::zeros(3 * width),
                        });
                    }
                    out.push(Layer::Act(a));
                }
                Layer::Affine { w, b } if i == 0 => {
                    let (r, c) = (w.nrows(), w.ncols());
                    let mut wide = DMatrix::<f64>::zeros(r + 2 * width, c);
                    wide.view_mut((0, 0), (r, c)).copy_from(&w);
                    wide.view_mut((r, 0), (width, width)).copy_from(&eye);
                    wide.view_mut((r + width, 0), (width, width))
                        .copy_from(&(-&eye));
                    let bias = b.clone().resize_vertically(r + 2 * width, 0.0);
                    out.push(Layer::Affine { w: wide, b: bias });
                }
                Layer::Affine { w, b } if i == last && merge => {
                    let (r, c) = (w.nrows(), w.ncols());
                    let mut wide = DMatrix::<f64>::zeros(r, c + 2 * width);
                    wide.view_mut((0, 0), (r, c)).copy_from(&w);
                    wide.view_mut((0, c), (width, 2 * width)).copy_from(&back);
                    out.push(Layer::Affine { w: wide, b });
                }
                Layer::Affine { w, b } => {
                    let (r, c) = (w.nrows(), w.ncols());
                    let mut wide = DMatrix::<f64>::zeros(r + 2 * width, c + 2 * width);
                    wide.view_mut((0, 0), (r, c)).copy_from(&w);
                    wide.view_mut((r, c), (2 * width, 2 * width))
                        .copy_from(&DMatrix::<f64>::identity(2 * width, 2 * width));
                    let bias = b.resize_vertically(r + 2 * width, 0.0);
                    out.push(Layer::Affine { w: wide, b: bias });
                }
            }
        }
        if !merge {
            let mut w = DMatrix::<f64>::zeros(width, 3 * width);
            w.view_mut((0, 0), (width, width)).copy_from(&eye);
            w.view_mut((0, width), (width, 2 * width)).copy_from(&back);
            out.push(Layer::Affine {
                w,
                b: DVector::zeros(width),
            });
        }
        self.layers.extend(out);
        // the values inside the branch now carry the pair: no later skip
        // may start there
        self.values.retain(|_, v| v.at <= start);
        self.width = Some(width);
        if let (Some(a), Some(b)) = (&fork.shape, &self.shape) {
            if a.len() > b.len() {
                self.shape = Some(a.clone());
            }
        }
        self.notes.push("residual connection".to_string());
        Ok(())
    }

    /// Lower one node onto the chain: a constant is recorded, any other
    /// op must consume the running value and becomes its new producer.
    fn node(&mut self, n: &NodeProto) -> Result<(), OnnxError> {
        let op = n.op_type.clone().unwrap_or_default();
        if n.domain
            .as_deref()
            .is_some_and(|d| !d.is_empty() && d != "ai.onnx")
        {
            return Err(err(
                OnnxErrorKind::Unsupported,
                format!(
                    "{} is in operator domain '{}'",
                    node_label(n),
                    sanitize(n.domain.as_deref().unwrap_or_default())
                ),
                format!("ravel supports the default ONNX domain: {SUPPORTED_OPS}"),
            ));
        }
        let out = n.output.first().cloned().unwrap_or_default();
        if op == "Constant" {
            return self.constant(n, out);
        }
        let first = n.input.first().cloned().unwrap_or_default();
        let uses_current = n.input.iter().any(|i| i == &self.current);
        if !uses_current {
            return Err(err(
                OnnxErrorKind::Unsupported,
                format!(
                    "{} does not consume the running value '{}'",
                    node_label(n),
                    sanitize(&self.current)
                ),
                "export a plain feed-forward network on one input (constant folding on)",
            ));
        }
        let data_first = first == self.current;
        if let Some(skip) = self.computed_operand(n, &op) {
            self.residual(n, &skip)?;
            return self.advance(out);
        }
        match op.as_str() {
            "Gemm" => self.gemm(n, data_first)?,
            "MatMul" => self.matmul(n)?,
            "Add" | "Sub" | "Mul" | "Div" => self.elementwise(n, &op)?,
            "Relu" => self.layers.push(Layer::Act(Activation::Relu)),
            "Tanh" => self.layers.push(Layer::Act(Activation::Tanh)),
            "Sigmoid" => self.layers.push(Layer::Act(Activation::Sigmoid)),
            "Clip" => self.clip(n)?,
            "LeakyRelu" => self.leaky_relu(n)?,
            "BatchNormalization" => self.batch_norm(n)?,
            "Dropout" => self.dropout(n, data_first)?,
            "Conv" => self.conv(n, data_first)?,
            "AveragePool" | "GlobalAveragePool" => self.average_pool(n, &op)?,
            "Flatten" | "Reshape" | "Identity" | "Squeeze" | "Unsqueeze" => {
                if !data_first {
                    return Err(err(
                        OnnxErrorKind::Unsupported,
                        format!("{} reshapes a constant", node_label(n)),
                        "export with constant folding on",
                    ));
                }
                self.reshape(n, &op)?;
            }
            other => {
                return Err(err(
                    OnnxErrorKind::Unsupported,
                    format!(
                        "{} uses operator '{}', which ravel does not support",
                        node_label(n),
                        sanitize(other)
                    ),
                    format!("supported operators: {SUPPORTED_OPS}"),
                ))
            }
        }
        self.advance(out)
    }

    /// `out` becomes the running value, recorded as a value of the chain.
    fn advance(&mut self, out: String) -> Result<(), OnnxError> {
        self.values.insert(
            out.clone(),
            ChainValue {
                at: self.layers.len(),
                width: self.width,
                shape: self.shape.clone(),
            },
        );
        self.current = out;
        Ok(())
    }

    /// A `Constant` node: its tensor, checked finite, under the name `out`.
    fn constant(&mut self, n: &NodeProto, out: String) -> Result<(), OnnxError> {
        let t = attr(n, "value").and_then(|a| a.t.as_ref()).ok_or_else(|| {
            err(
                OnnxErrorKind::Unsupported,
                format!("{} has no tensor 'value'", node_label(n)),
                "use a tensor-valued Constant",
            )
        })?;
        let t = tensor_values(t, &ExternalFiles::new())?;
        check_finite(&format!("constant '{}'", sanitize(&out)), &t)?;
        self.consts.insert(out, t);
        Ok(())
    }

    /// The constant `name` that node `n` takes as its `what` (a weight or
    /// a bias), or the error naming it (`hint`: how to fix it).
    fn named_const(
        &self,
        n: &NodeProto,
        name: &str,
        what: &str,
        hint: &str,
    ) -> Result<Tensor, OnnxError> {
        self.consts.get(name).cloned().ok_or_else(|| {
            err(
                OnnxErrorKind::Unsupported,
                format!(
                    "{} has a non-constant {what} '{}'",
                    node_label(n),
                    sanitize(name)
                ),
                hint,
            )
        })
    }

    /// `Gemm`: `alpha·A·B + beta·C` with the data as `A` (`data_first`,
    /// `transA = 0`), constant `B` (optionally transposed) and `C`.
    fn gemm(&mut self, n: &NodeProto, data_first: bool) -> Result<(), OnnxError> {
        if !data_first || attr_i(n, "transA", 0) != 0 {
            return Err(err(
                OnnxErrorKind::Unsupported,
                format!(
                    "{} must have the data as its first input and transA = 0",
                    node_label(n)
                ),
                "re-export with the input as A",
            ));
        }
        let bname = n.input.get(1).cloned().unwrap_or_default();
        let bt = self.named_const(n, &bname, "weight", "weights must be initializers")?;
        if bt.dims.len() != 2 {
            return Err(err(
                OnnxErrorKind::Malformed,
                format!(
                    "{} has weight of shape {}, expected 2-D",
                    node_label(n),
                    shape_text(&bt.dims)
                ),
                "re-export the model",
            ));
        }
        let &[r, c] = bt.dims.as_slice() else {
            return Err(err(
                OnnxErrorKind::Malformed,
                format!("{} has a weight that is not 2-D", node_label(n)),
                "re-export the model",
            ));
        };
        Self::check_width(n, r.max(c))?;
        let m = DMatrix::from_row_slice(r, c, &bt.data);
        let alpha = attr_f(n, "alpha", 1.0);
        let beta = attr_f(n, "beta", 1.0);
        if !(alpha.is_finite() && beta.is_finite()) {
            return Err(err(
                OnnxErrorKind::NonFinite,
                format!(
                    "{} has a non-finite alpha ({alpha}) or beta ({beta})",
                    node_label(n)
                ),
                "re-export the model",
            ));
        }
        let mut w = if attr_i(n, "transB", 0) != 0 {
            m
        } else {
            m.transpose()
        };
        if alpha != 1.0 {
            w *= alpha;
        }
        self.expect_width(n, w.ncols())?;
        let outputs = w.nrows();
        self.shape = Some(vec![1, outputs]);
        let mut b = DVector::zeros(outputs);
        if let Some(cname) = n.input.get(2).filter(|s| !s.is_empty()) {
            let ct = self.named_const(n, cname, "bias", "biases must be initializers")?;
            self.width = Some(outputs);
            b = self.broadcast(n, &ct)? * beta;
        }
        self.push_affine(w, b);
        Ok(())
    }

    /// `MatMul` with a 2-D constant on either side, as a linear map on the
    /// flat (row-major) value, following ONNX's (numpy's) rules: the data
    /// `x` of shape `[…, K]` times `W` of shape `[K, N]` gives `[…, N]`
    /// (each row of `x` times `W`); `W` of shape `[M, K]` times `x` of
    /// shape `[K]` gives `W·x` of shape `[M]`, and times `x` of shape
    /// `[…, K, C]` gives `[…, M, C]` (`W` times each column). A value of
    /// unknown shape is taken as the vector the constant needs.
    fn matmul(&mut self, n: &NodeProto) -> Result<(), OnnxError> {
        let (t, const_first) = self.const_operand(n)?;
        let &[r, c] = t.dims.as_slice() else {
            return Err(err(
                OnnxErrorKind::Unsupported,
                format!(
                    "{} multiplies by a constant of shape {}; ravel supports 2-D constant matrices",
                    node_label(n),
                    shape_text(&t.dims)
                ),
                "export linear layers as MatMul by a 2-D weight matrix (or Gemm)",
            ));
        };
        Self::check_width(n, r.max(c))?;
        let m = DMatrix::from_row_slice(r, c, &t.data);
        // the contracted dimension and the map on each column: `Wᵀ` for
        // x·W (rows of x are columns of its transpose), `W` for W·x
        let (k, w) = if const_first {
            (c, m)
        } else {
            (r, m.transpose())
        };
        let shape = self.shape.clone().or_else(|| self.width.map(|w| vec![w]));
        let shape = shape.unwrap_or_else(|| vec![k]);
        let mismatch = || {
            err(
                OnnxErrorKind::Malformed,
                format!(
                    "{} multiplies a value of shape {} {} a constant of shape {}",
                    node_label(n),
                    shape_text(&shape),
                    if const_first { "on the right of" } else { "by" },
                    shape_text(&t.dims)
                ),
                "the model's shapes are inconsistent: re-export it",
            )
        };
        let (blocks, cols, out_shape) = match (shape.split_last(), const_first) {
            // a vector: W·x or x·W
            (Some((&d, [])), _) => {
                if d != k {
                    return Err(mismatch());
                }
                (1, 1, vec![w.nrows()])
            }
            // x·W: each row of x
            (Some((&d, lead)), false) => {
                if d != k {
                    return Err(mismatch());
                }
                let mut s = lead.to_vec();
                s.push(w.nrows());
                (shape_width(lead).ok_or_else(mismatch)?, 1, s)
            }
            // W·x: each column of each matrix of x
            (Some((&cols, rest)), true) => {
                let Some((&d, lead)) = rest.split_last() else {
                    return Err(mismatch());
                };
                if d != k {
                    return Err(mismatch());
                }
                let mut s = lead.to_vec();
                s.extend([w.nrows(), cols]);
                (shape_width(lead).ok_or_else(mismatch)?, cols, s)
            }
            (None, _) => return Err(mismatch()),
        };
        let wide = |a: usize| {
            blocks
                .checked_mul(a)
                .and_then(|v| v.checked_mul(cols))
                .filter(|v| *v as u64 <= MAX_WIDTH)
        };
        let (Some(inputs), Some(outputs)) = (wide(w.ncols()), wide(w.nrows())) else {
            return Err(err(
                OnnxErrorKind::Unsupported,
                format!(
                    "{} gives a value of shape {}, wider than ravel's limit of {MAX_WIDTH}",
                    node_label(n),
                    shape_text(&out_shape)
                ),
                "ravel verifies controllers whose layers have at most 4096 neurons",
            ));
        };
        self.expect_width(n, inputs)?;
        let map = if blocks == 1 && cols == 1 {
            w
        } else {
            matmul_matrix(&w, blocks, cols)
        };
        self.push_affine(map, DVector::zeros(outputs));
        self.shape = Some(out_shape);
        Ok(())
    }

    /// `Add`, `Sub`, `Mul` or `Div` (`op`) of the data and a constant of one
    /// or `width` elements (division only by the constant).
    fn elementwise(&mut self, n: &NodeProto, op: &str) -> Result<(), OnnxError> {
        let (t, const_first) = self.const_operand(n)?;
        let v = self.broadcast_shaped(n, &t)?;
        Self::check_width(n, v.len())?;
        let w = v.len();
        match (op, const_first) {
            ("Add", _) => self.add_bias(v),
            ("Sub", false) => self.add_bias(-v),
            ("Sub", true) => self.push_affine(-DMatrix::<f64>::identity(w, w), v),
            ("Mul", _) => self.push_affine(DMatrix::from_diagonal(&v), DVector::zeros(w)),
            (_, false) => {
                if let Some(x) = v.iter().find(|x| !(1.0 / **x).is_finite()) {
                    let what = if *x == 0.0 {
                        "zero".to_string()
                    } else {
                        format!("{x:e}, whose reciprocal overflows")
                    };
                    return Err(err(
                        OnnxErrorKind::NonFinite,
                        format!("{} divides by {what}", node_label(n)),
                        "fix the normalisation constants",
                    ));
                }
                self.push_affine(
                    DMatrix::from_diagonal(&v.map(|x| 1.0 / x)),
                    DVector::zeros(w),
                );
            }
            (_, true) => {
                return Err(err(
                    OnnxErrorKind::Unsupported,
                    format!(
                        "{} divides a constant by the data, which is not affine",
                        node_label(n)
                    ),
                    "only division by constants is supported",
                ));
            }
        }
        Ok(())
    }

    /// `Clip`: a clamp between optional bounds (ReLU layers that compute
    /// it exactly).
    fn clip(&mut self, n: &NodeProto) -> Result<(), OnnxError> {
        let w = self.width()?;
        // ±FLT_MAX (the old opsets' defaults, written out by some
        // exporters) means no bound on that side
        let unbounded =
            |v: Option<Vec<f64>>| v.filter(|v| !v.iter().all(|x| x.abs() >= f32::MAX as f64));
        let lo = unbounded(self.clip_bound(n, w, 1, "min")?);
        let hi = unbounded(self.clip_bound(n, w, 2, "max")?);
        if let (Some(l), Some(h)) = (&lo, &hi) {
            if l.iter().zip(h).any(|(l, h)| l > h) {
                return Err(err(
                    OnnxErrorKind::Malformed,
                    format!("{} has min above max", node_label(n)),
                    "check the clamp bounds of the exported policy",
                ));
            }
        }
        if lo
            .iter()
            .chain(&hi)
            .flatten()
            .any(|v| !v.is_finite() || v.abs() > MAX_MAGNITUDE)
        {
            return Err(err(
                OnnxErrorKind::NonFinite,
                format!("{} has a non-finite or huge bound", node_label(n)),
                "clamp to finite bounds within ±1e15",
            ));
        }
        let shown = |v: &Option<Vec<f64>>| {
            v.as_ref()
                .and_then(|v| v.first())
                .map_or("·".to_string(), |x| ravel_syntax::diag::compact(*x))
        };
        self.notes
            .push(format!("clip [{}, {}]", shown(&lo), shown(&hi)));
        self.layers.extend(ravel_base::nn::clamp_layers(
            w,
            lo.as_deref(),
            hi.as_deref(),
        ));
        Ok(())
    }

    /// A `Clip` bound per element of a value of width `w`: opset ≥ 11's
    /// optional constant input `k`, or before, the attribute `name`.
    fn clip_bound(
        &self,
        n: &NodeProto,
        w: usize,
        k: usize,
        name: &str,
    ) -> Result<Option<Vec<f64>>, OnnxError> {
        match n.input.get(k).filter(|s| !s.is_empty()) {
            Some(c) => {
                let t = self.consts.get(c).ok_or_else(|| {
                    err(
                        OnnxErrorKind::Unsupported,
                        format!("{} has a computed {name}", node_label(n)),
                        "clip bounds must be constants",
                    )
                })?;
                Ok(Some(self.broadcast(n, t)?.iter().copied().collect()))
            }
            None => Ok(attr(n, name).and_then(|a| a.f).map(|f| vec![f as f64; w])),
        }
    }

    /// `LeakyRelu`: pairs of ReLUs that compute it exactly.
    fn leaky_relu(&mut self, n: &NodeProto) -> Result<(), OnnxError> {
        let w = self.width()?;
        let alpha = attr_f(n, "alpha", 0.01);
        if !alpha.is_finite() || alpha.abs() > MAX_MAGNITUDE {
            return Err(err(
                OnnxErrorKind::NonFinite,
                format!("{} has a non-finite slope", node_label(n)),
                "re-export the model",
            ));
        }
        Self::check_width(n, 2 * w)?;
        self.notes.push(format!(
            "leaky_relu {} as relu pairs",
            ravel_syntax::diag::compact(alpha)
        ));
        self.layers
            .extend(ravel_base::nn::leaky_relu_layers(w, alpha));
        Ok(())
    }

    /// `BatchNormalization` in inference form: the diagonal affine map
    /// `scale/√(var + ε)`, `B − mean·scale/√(var + ε)`.
    fn batch_norm(&mut self, n: &NodeProto) -> Result<(), OnnxError> {
        let training =
            attr_i(n, "training_mode", 0) != 0 || n.output.iter().skip(1).any(|o| !o.is_empty());
        if training {
            return Err(training_mode(n));
        }
        let w = self.width()?;
        let param = |k: usize| -> Result<Vec<f64>, OnnxError> {
            let name = n.input.get(k).cloned().unwrap_or_default();
            let t = self.consts.get(&name).ok_or_else(|| {
                err(
                    OnnxErrorKind::Unsupported,
                    format!(
                        "{} has a non-constant parameter '{}'",
                        node_label(n),
                        sanitize(&name)
                    ),
                    "export in eval mode with constant folding on",
                )
            })?;
            // one value per channel (axis 1) of an image [1, C, H, W]
            // (after a Conv), spread over its H·W positions
            if let Some([1, c, rest @ ..]) = self.shape.as_deref() {
                let plane: usize = rest.iter().product();
                if !rest.is_empty() && t.data.len() == *c && plane > 1 {
                    return Ok(t
                        .data
                        .iter()
                        .flat_map(|v| std::iter::repeat_n(*v, plane))
                        .collect());
                }
            }
            Ok(self.broadcast(n, t)?.iter().copied().collect())
        };
        let (scale, bias, mean, var) = (param(1)?, param(2)?, param(3)?, param(4)?);
        let eps = attr_f(n, "epsilon", 1e-5);
        let mut diag = Vec::with_capacity(w);
        let mut shift = Vec::with_capacity(w);
        for (((s, b), m), v) in scale.iter().zip(&bias).zip(&mean).zip(&var) {
            let d = s / (v + eps).sqrt();
            let denominator = v + eps;
            if denominator.is_nan() || denominator <= 0.0 || !d.is_finite() {
                return Err(err(
                    OnnxErrorKind::NonFinite,
                    format!("{} has a non-positive variance", node_label(n)),
                    "re-export the model",
                ));
            }
            diag.push(d);
            shift.push(b - m * d);
        }
        self.notes.push("batch normalisation".to_string());
        self.push_affine(
            DMatrix::from_diagonal(&DVector::from_vec(diag)),
            DVector::from_vec(shift),
        );
        Ok(())
    }

    /// `Dropout` in inference mode (the identity) on the data
    /// (`data_first`).
    fn dropout(&self, n: &NodeProto, data_first: bool) -> Result<(), OnnxError> {
        if !data_first {
            return Err(err(
                OnnxErrorKind::Unsupported,
                format!("{} drops out a constant", node_label(n)),
                "export with constant folding on",
            ));
        }
        // opset ≥ 12: a third input `training_mode`; before 7: `is_test`
        let training = n.input.get(2).filter(|s| !s.is_empty()).is_some_and(|t| {
            self.consts
                .get(t)
                .is_none_or(|c| c.data.iter().any(|v| *v != 0.0))
        }) || attr(n, "is_test").and_then(|a| a.i) == Some(0);
        if training {
            return Err(training_mode(n));
        }
        Ok(())
    }

    fn expect_width(&mut self, n: &NodeProto, k: usize) -> Result<(), OnnxError> {
        match self.width {
            Some(w) if w != k => Err(err(
                OnnxErrorKind::Malformed,
                format!(
                    "{} expects {k} inputs but receives a value of width {w}",
                    node_label(n)
                ),
                "the model's shapes are inconsistent: re-export it",
            )),
            _ => {
                self.width = Some(k);
                Ok(())
            }
        }
    }
}

/// A convolution or pooling whose dense `rows × cols` layer passes the
/// limit on weights.
fn too_many_weights(n: &NodeProto, rows: usize, cols: usize) -> OnnxError {
    err(
        OnnxErrorKind::Unsupported,
        format!(
            "{} is a dense {rows} × {cols} layer, which brings its convolutions' and poolings' weights past ravel's limit of {MAX_PARAMETERS}",
            node_label(n)
        ),
        "ravel verifies small networks: at most 16777216 weights in the dense matrices of its convolutions and poolings together",
    )
}

/// A node exported in training mode (Dropout or BatchNormalization).
fn training_mode(n: &NodeProto) -> OnnxError {
    err(
        OnnxErrorKind::Unsupported,
        format!("{} was exported in training mode", node_label(n)),
        "call model.eval() before torch.onnx.export (training-mode dropout and batch statistics are random or data-dependent)",
    )
}

fn check_finite(what: &str, t: &Tensor) -> Result<(), OnnxError> {
    if let Some((i, v)) = t.data.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(err(
            OnnxErrorKind::NonFinite,
            format!("{what} holds a non-finite value ({v}) at flat index {i}"),
            "the training diverged or the export is corrupt; retrain or re-export",
        ));
    }
    if let Some((i, v)) = t
        .data
        .iter()
        .enumerate()
        .find(|(_, v)| v.abs() > MAX_MAGNITUDE)
    {
        return Err(err(
            OnnxErrorKind::NonFinite,
            format!(
                "{what} holds {} at flat index {i}, beyond the magnitudes ravel analyses (±1e15)",
                ravel_syntax::diag::compact(*v)
            ),
            "the training diverged or the export is corrupt; retrain or re-export",
        ));
    }
    Ok(())
}

/// A prost decode error, cut to its first and last frames: a deeply nested
/// message otherwise names every enclosing field.
fn decode_message(e: &prost::DecodeError) -> String {
    let full = e.to_string();
    let parts: Vec<&str> = full.split(": ").collect();
    let short = if parts.len() > 4 {
        match (parts.first(), parts.get(1), parts.last()) {
            (Some(a), Some(b), Some(z)) => format!("{a}: {b}: …: {z}"),
            _ => full,
        }
    } else {
        full
    };
    sanitize(&short)
}

/// Decode an ONNX model and lower it to a network.
pub fn load(bytes: &[u8], external: &ExternalFiles) -> Result<Controller, OnnxError> {
    let model = decode(bytes)?;
    let graph = model.graph.as_ref().ok_or_else(|| {
        err(
            OnnxErrorKind::Decode,
            "the file is not an ONNX model (it has no graph)",
            "check that the path points to an .onnx file",
        )
    })?;
    check_size(graph)?;
    let consts = initializers(graph, external)?;
    let input = data_input(graph, &consts)?;
    let declared = declared_width(input)?;
    let mut low = Lowering {
        consts,
        current: input.name.clone().unwrap_or_default(),
        width: declared,
        shape: declared.and(declared_shape(input)),
        layers: Vec::new(),
        notes: Vec::new(),
        dense: 0,
        values: HashMap::new(),
    };
    low.values.insert(
        low.current.clone(),
        ChainValue {
            at: 0,
            width: low.width,
            shape: low.shape.clone(),
        },
    );
    for n in &graph.node {
        low.node(n)?;
        // every layer is a dense matrix (a normalisation's diagonal too):
        // the model's memory is bounded by their entries together, checked
        // after each node (one layer is at most MAX_WIDTH² entries)
        let entries = low.layers.iter().fold(0u64, |t, l| match l {
            Layer::Affine { w, .. } => {
                t.saturating_add((w.nrows() as u64).saturating_mul(w.ncols() as u64))
            }
            Layer::Act(_) => t,
        });
        if entries > MAX_LAYER_ENTRIES {
            return Err(err(
                OnnxErrorKind::Unsupported,
                format!(
                    "{} brings the network's layers to {entries} matrix entries, more than ravel's limit of {MAX_LAYER_ENTRIES}",
                    node_label(n)
                ),
                "ravel verifies small networks; element-wise constant ops (Add, Sub, Mul, Div, BatchNormalization) each count as a full width × width layer: fold them into the neighbouring layers before export",
            ));
        }
    }
    let output = graph
        .output
        .first()
        .and_then(|o| o.name.clone())
        .unwrap_or_default();
    if graph.output.len() != 1 || output != low.current {
        return Err(err(
            OnnxErrorKind::Unsupported,
            format!(
                "the graph output '{}' is not the end of the layer chain ('{}')",
                sanitize(&output),
                sanitize(&low.current)
            ),
            "export the controller with a single output",
        ));
    }
    let inputs = declared.or(match low.layers.first() {
        Some(Layer::Affine { w, .. }) => Some(w.ncols()),
        _ => None,
    });
    let Some(inputs) = inputs else {
        return Err(err(
            OnnxErrorKind::Malformed,
            "cannot determine the input size",
            "give the graph input a static shape",
        ));
    };
    check_scaled(&low.layers)?;
    let net = Network::new(inputs, low.layers).with_input_type(input_type(input));
    let outputs = net.outputs();
    Ok(Controller {
        net,
        inputs,
        outputs,
        notes: low.notes,
    })
}

/// The decoded model, which must record its operator set.
fn decode(bytes: &[u8]) -> Result<ModelProto, OnnxError> {
    let model = ModelProto::decode(bytes).map_err(|e| {
        err(
            OnnxErrorKind::Decode,
            format!("the file is not a valid ONNX model ({})", decode_message(&e)),
            "check that the path points to an .onnx file exported by PyTorch, Keras or similar, and that it is complete",
        )
    })?;
    if model.opset_import.is_empty() {
        return Err(err(
            OnnxErrorKind::Decode,
            "the file has no opset_import: it is truncated or not an ONNX model",
            "every ONNX exporter writes the operator set version; re-export or re-copy the file",
        ));
    }
    Ok(model)
}

/// Refuse a graph with more nodes or weights than ravel's limits.
fn check_size(graph: &GraphProto) -> Result<(), OnnxError> {
    if graph.node.len() > MAX_NODES {
        return Err(err(
            OnnxErrorKind::Unsupported,
            format!(
                "the graph has {} nodes, more than ravel's limit of {MAX_NODES}",
                graph.node.len()
            ),
            "ravel verifies small feed-forward controllers",
        ));
    }
    let mut parameters = 0u64;
    for t in &graph.initializer {
        parameters = parameters.saturating_add(tensor_size(t)?.0);
    }
    if parameters > MAX_PARAMETERS {
        return Err(err(
            OnnxErrorKind::Unsupported,
            format!("the controller has {parameters} weights, more than ravel's limit of {MAX_PARAMETERS}"),
            "ravel verifies small feed-forward controllers",
        ));
    }
    Ok(())
}

/// The graph's initializers by name, each decoded and checked finite.
fn initializers(
    graph: &GraphProto,
    external: &ExternalFiles,
) -> Result<HashMap<String, Tensor>, OnnxError> {
    let mut consts = HashMap::new();
    for t in &graph.initializer {
        let name = tensor_name(t);
        let v = tensor_values(t, external)?;
        check_finite(&format!("initializer '{name}'"), &v)?;
        consts.insert(name, v);
    }
    Ok(consts)
}

/// The graph's one data input (an input that is not an initializer).
fn data_input<'g>(
    graph: &'g GraphProto,
    consts: &HashMap<String, Tensor>,
) -> Result<&'g ValueInfoProto, OnnxError> {
    let data_inputs: Vec<_> = graph
        .input
        .iter()
        .filter(|i| !consts.contains_key(i.name.as_deref().unwrap_or("")))
        .collect();
    if data_inputs.len() != 1 {
        return Err(err(
            OnnxErrorKind::Unsupported,
            format!(
                "the graph has {} data inputs; ravel needs exactly one (the observation vector)",
                data_inputs.len()
            ),
            "export the controller with a single input tensor",
        ));
    }
    let [input] = data_inputs.as_slice() else {
        return Err(err(
            OnnxErrorKind::Unsupported,
            "the graph needs exactly one data input",
            "export the controller with a single input tensor",
        ));
    };
    Ok(input)
}

/// The input's declared width: the product of its fixed dimensions
/// (symbolic ones, such as the batch, count as 1); `None` without a shape.
fn declared_width(input: &ValueInfoProto) -> Result<Option<usize>, OnnxError> {
    let declared = input
        .r#type
        .as_ref()
        .and_then(|t| t.tensor_type.as_ref())
        .and_then(|t| t.shape.as_ref())
        .map(|s| {
            s.dim
                .iter()
                .map(|d| d.dim_value.filter(|v| *v > 0).unwrap_or(1) as u64)
                .try_fold(1u64, |a, d| a.checked_mul(d).filter(|p| *p <= MAX_WIDTH))
        });
    match declared {
        Some(None) => Err(err(
            OnnxErrorKind::Unsupported,
            format!("the graph input is wider than ravel's limit of {MAX_WIDTH}"),
            "ravel verifies controllers with at most 4096 inputs",
        )),
        Some(Some(w)) => Ok(Some(w as usize)),
        None => Ok(None),
    }
}

/// The input's declared shape, symbolic dimensions (the batch) as 1;
/// `None` without a shape. Called after [`declared_width`] accepted it.
fn declared_shape(input: &ValueInfoProto) -> Option<Vec<usize>> {
    input
        .r#type
        .as_ref()
        .and_then(|t| t.tensor_type.as_ref())
        .and_then(|t| t.shape.as_ref())
        .map(|s| {
            s.dim
                .iter()
                .map(|d| d.dim_value.filter(|v| *v > 0).unwrap_or(1) as usize)
                .collect()
        })
}

/// The product of a shape's dimensions, `None` past [`MAX_WIDTH`].
fn shape_width(dims: &[usize]) -> Option<usize> {
    dims.iter()
        .try_fold(1u64, |a, d| {
            a.checked_mul(*d as u64).filter(|p| *p <= MAX_WIDTH)
        })
        .map(|p| p as usize)
}

/// The matrix of `Y[b, m, c] = Σ_k W[m, k]·X[b, k, c]` on row-major flat
/// vectors (`blocks` values of `b`, `cols` of `c`): the flat form of every
/// `MatMul` by a 2-D constant.
fn matmul_matrix(w: &DMatrix<f64>, blocks: usize, cols: usize) -> DMatrix<f64> {
    let (m, k) = (w.nrows(), w.ncols());
    let (rows, columns) = (blocks * m * cols, blocks * k * cols);
    // column-major, as nalgebra stores it
    let mut data = vec![0.0; rows * columns];
    for b in 0..blocks {
        for ((i, j), v) in (0..k)
            .flat_map(|j| (0..m).map(move |i| (i, j)))
            .zip(w.iter())
        {
            if *v == 0.0 {
                continue;
            }
            for c in 0..cols {
                let (r, q) = ((b * m + i) * cols + c, (b * k + j) * cols + c);
                if let Some(e) = data.get_mut(q * rows + r) {
                    *e = *v;
                }
            }
        }
    }
    DMatrix::from_vec(rows, columns, data)
}

/// Refuse a network whose weights left the limits: alpha, beta and `Div`
/// by small constants can scale weights past the checked initializers.
fn check_scaled(layers: &[Layer]) -> Result<(), OnnxError> {
    for l in layers {
        if let Layer::Affine { w, b } = l {
            if let Some(v) = w
                .iter()
                .chain(b.iter())
                .find(|v| !v.is_finite() || v.abs() > MAX_MAGNITUDE)
            {
                return Err(err(
                    OnnxErrorKind::NonFinite,
                    format!(
                        "a weight of the network is {} after its scaling (Gemm alpha/beta, Mul, Div), beyond the magnitudes ravel analyses (±1e15)",
                        ravel_syntax::diag::compact(*v)
                    ),
                    "check the normalisation constants and Gemm attributes; re-export the model",
                ));
            }
        }
    }
    Ok(())
}

/// The stored model's precision, from the input's element type: float64
/// for `double`, float32 otherwise (the stricter rule: every float32 value
/// is a float64 one, and float32's rounding errors bound float64's).
fn input_type(input: &ValueInfoProto) -> InputType {
    match input
        .r#type
        .as_ref()
        .and_then(|t| t.tensor_type.as_ref())
        .and_then(|t| t.elem_type)
    {
        Some(dtype::DOUBLE) => InputType::F64,
        _ => InputType::F32,
    }
}
