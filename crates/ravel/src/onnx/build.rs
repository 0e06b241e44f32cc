//! A small ONNX writer for chains of layers, used by the model generator
//! (`ravel-models`) and by tests that need models with particular encodings.

use nalgebra::{DMatrix, DVector};
use prost::Message;

use super::proto::*;
use ravel_base::nn::{Activation, Layer, Network};

/// How a builder stores tensor data.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Storage {
    /// float32 in `raw_data` (what PyTorch writes).
    RawF32,
    /// float32 in the typed `float_data` field.
    FloatData,
    /// float64 in `raw_data`.
    RawF64,
    /// float64 in the typed `double_data` field.
    DoubleData,
    /// float32 in an external data file (see [`GraphBuilder::external_file`]).
    External,
}

/// Builds a single-input, single-output chain graph node by node.
pub struct GraphBuilder {
    nodes: Vec<NodeProto>,
    initializers: Vec<TensorProto>,
    input: ValueInfoProto,
    current: String,
    counter: usize,
    storage: Storage,
    external_name: String,
    external: Vec<u8>,
}

fn value_info(name: &str, dims: &[Option<i64>]) -> ValueInfoProto {
    ValueInfoProto {
        name: Some(name.into()),
        r#type: Some(TypeProto {
            tensor_type: Some(TypeProtoTensor {
                elem_type: Some(dtype::FLOAT),
                shape: Some(TensorShapeProto {
                    dim: dims
                        .iter()
                        .map(|d| match d {
                            Some(v) => Dimension {
                                dim_value: Some(*v),
                                dim_param: None,
                            },
                            None => Dimension {
                                dim_value: None,
                                dim_param: Some("batch".into()),
                            },
                        })
                        .collect(),
                }),
            }),
        }),
    }
}

/// An integer attribute.
pub fn int_attr(name: &str, v: i64) -> AttributeProto {
    AttributeProto {
        name: Some(name.into()),
        i: Some(v),
        r#type: Some(2),
        ..Default::default()
    }
}

/// A float attribute.
pub fn float_attr(name: &str, v: f32) -> AttributeProto {
    AttributeProto {
        name: Some(name.into()),
        f: Some(v),
        r#type: Some(1),
        ..Default::default()
    }
}

/// The entries of `m` in row-major order (ONNX's layout).
pub fn row_major(m: &DMatrix<f64>) -> Vec<f64> {
    m.transpose().as_slice().to_vec()
}

impl GraphBuilder {
    /// A graph on an input of shape `[batch, n]` called `input`.
    pub fn new(n: usize, storage: Storage) -> GraphBuilder {
        GraphBuilder {
            nodes: Vec::new(),
            initializers: Vec::new(),
            input: value_info("input", &[None, Some(n as i64)]),
            current: "input".into(),
            counter: 0,
            storage,
            external_name: "model.onnx.data".into(),
            external: Vec::new(),
        }
    }

    /// Override the declared input size (to write inconsistent models for tests).
    pub fn declare_input(&mut self, n: usize) {
        self.input = value_info("input", &[None, Some(n as i64)]);
    }

    /// Declare the input's shape (`None`: a symbolic batch dimension).
    pub fn declare_shape(&mut self, dims: &[Option<i64>]) {
        self.input = value_info("input", dims);
    }

    /// The name of the running value (the last node's output).
    pub fn current(&self) -> String {
        self.current.clone()
    }

    /// Append a node with the given inputs in order (name the running
    /// value with [`GraphBuilder::current`]); its output becomes the
    /// running value.
    pub fn node_inputs(&mut self, op: &str, inputs: Vec<String>, attrs: Vec<AttributeProto>) {
        let out = self.fresh(&op.to_lowercase());
        let name = self.fresh(op);
        self.nodes.push(NodeProto {
            input: inputs,
            output: vec![out.clone()],
            name: Some(name),
            op_type: Some(op.into()),
            attribute: attrs,
            domain: None,
        });
        self.current = out;
    }

    /// `MatMul` with the constant `W` (`out × in`) on the left: `W·x`, as
    /// VNN-COMP's test networks write it.
    pub fn matmul_left(&mut self, w: &DMatrix<f64>) {
        let wn = self.constant("weight", &[w.nrows(), w.ncols()], &row_major(w));
        let x = self.current();
        self.node_inputs("MatMul", vec![wn, x], vec![]);
    }

    /// An integer-list attribute (`axes` of `Squeeze`/`Unsqueeze` before opset 13).
    pub fn ints_attr(name: &str, v: &[i64]) -> AttributeProto {
        AttributeProto {
            name: Some(name.into()),
            ints: v.to_vec(),
            r#type: Some(7),
            ..Default::default()
        }
    }

    /// Name of the external-data file (for [`Storage::External`]).
    pub fn external_file(mut self, name: &str) -> GraphBuilder {
        self.external_name = name.into();
        self
    }

    fn fresh(&mut self, stem: &str) -> String {
        self.counter += 1;
        format!("{stem}_{}", self.counter)
    }

    /// Add an initializer with row-major values.
    pub fn constant(&mut self, stem: &str, dims: &[usize], values: &[f64]) -> String {
        let name = self.fresh(stem);
        let mut t = TensorProto {
            dims: dims.iter().map(|d| *d as i64).collect(),
            name: Some(name.clone()),
            ..Default::default()
        };
        match self.storage {
            Storage::RawF32 => {
                t.data_type = Some(dtype::FLOAT);
                t.raw_data = Some(
                    values
                        .iter()
                        .flat_map(|v| (*v as f32).to_le_bytes())
                        .collect(),
                );
            }
            Storage::FloatData => {
                t.data_type = Some(dtype::FLOAT);
                t.float_data = values.iter().map(|v| *v as f32).collect();
            }
            Storage::RawF64 => {
                t.data_type = Some(dtype::DOUBLE);
                t.raw_data = Some(values.iter().flat_map(|v| v.to_le_bytes()).collect());
            }
            Storage::DoubleData => {
                t.data_type = Some(dtype::DOUBLE);
                t.double_data = values.to_vec();
            }
            Storage::External => {
                t.data_type = Some(dtype::FLOAT);
                let bytes: Vec<u8> = values
                    .iter()
                    .flat_map(|v| (*v as f32).to_le_bytes())
                    .collect();
                let entry = |k: &str, v: String| StringStringEntryProto {
                    key: Some(k.into()),
                    value: Some(v),
                };
                t.external_data = vec![
                    entry("location", self.external_name.clone()),
                    entry("offset", self.external.len().to_string()),
                    entry("length", bytes.len().to_string()),
                ];
                t.data_location = Some(1);
                self.external.extend(bytes);
            }
        }
        self.initializers.push(t);
        name
    }

    /// Append a node consuming the running value (first) and `extra` inputs.
    pub fn node(&mut self, op: &str, extra: &[String], attrs: Vec<AttributeProto>) {
        let out = self.fresh(&op.to_lowercase());
        let mut input = vec![self.current.clone()];
        input.extend(extra.iter().cloned());
        let name = self.fresh(op);
        self.nodes.push(NodeProto {
            input,
            output: vec![out.clone()],
            name: Some(name),
            op_type: Some(op.into()),
            attribute: attrs,
            domain: None,
        });
        self.current = out;
    }

    /// `Gemm` with `transB = 1` (the PyTorch form): `W` is `out × in`.
    pub fn gemm(&mut self, w: &DMatrix<f64>, b: &DVector<f64>) {
        let wt = row_major(w);
        let wn = self.constant("weight", &[w.nrows(), w.ncols()], &wt);
        let bn = self.constant("bias", &[b.len()], b.as_slice());
        self.node(
            "Gemm",
            &[wn, bn],
            vec![
                float_attr("alpha", 1.0),
                float_attr("beta", 1.0),
                int_attr("transB", 1),
            ],
        );
    }

    /// `MatMul` by `Wᵀ` (the Keras form, weights stored `in × out`), then `Add` of the bias.
    pub fn matmul_add(&mut self, w: &DMatrix<f64>, b: &DVector<f64>) {
        let t = w.transpose();
        let vals = row_major(&t);
        let wn = self.constant("kernel", &[t.nrows(), t.ncols()], &vals);
        self.node("MatMul", &[wn], vec![]);
        let bn = self.constant("bias", &[b.len()], b.as_slice());
        self.node("Add", &[bn], vec![]);
    }

    /// An element-wise op with a constant right operand (`Sub`, `Div`, `Mul`, `Add`).
    pub fn elementwise(&mut self, op: &str, values: &[f64]) {
        let c = self.constant("const", &[values.len()], values);
        self.node(op, &[c], vec![]);
    }

    /// A node with no extra inputs (`Relu`, `Tanh`, `Sigmoid`, `Flatten`, `Identity`, …).
    pub fn unary(&mut self, op: &str) {
        self.node(op, &[], vec![]);
    }

    /// Append every layer of `net`: affine layers as `Gemm` (PyTorch style) or,
    /// with `keras`, as `MatMul` + `Add`; activations as their ONNX ops.
    pub fn network(&mut self, net: &Network, keras: bool) {
        for layer in &net.layers {
            match layer {
                Layer::Affine { w, b } if keras => self.matmul_add(w, b),
                Layer::Affine { w, b } => self.gemm(w, b),
                Layer::Act(Activation::Relu) => self.unary("Relu"),
                Layer::Act(Activation::Tanh) => self.unary("Tanh"),
                Layer::Act(Activation::Sigmoid) => self.unary("Sigmoid"),
            }
        }
    }

    /// Encode the model; the second value is the external-data file (empty unless used).
    pub fn finish(self, outputs: usize) -> (Vec<u8>, Vec<u8>) {
        let graph = GraphProto {
            node: self.nodes,
            name: Some("ravel_controller".into()),
            initializer: self.initializers,
            input: vec![self.input],
            output: vec![value_info(&self.current, &[None, Some(outputs as i64)])],
        };
        let model = ModelProto {
            ir_version: Some(8),
            producer_name: Some("ravel-models".into()),
            producer_version: Some(env!("CARGO_PKG_VERSION").into()),
            graph: Some(graph),
            opset_import: vec![OperatorSetIdProto {
                domain: Some(String::new()),
                version: Some(17),
            }],
        };
        (model.encode_to_vec(), self.external)
    }
}
