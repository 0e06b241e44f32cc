//! ONNX loading: the committed models against onnxruntime's outputs, every
//! supported encoding, and every loader error.

use nalgebra::{DMatrix, DVector};
use ravel::onnx::build::{GraphBuilder, Storage};
use ravel::onnx::{load, ExternalFiles, OnnxErrorKind};
use ravel_base::nn::{Activation, Layer, Network};
use serde_json::Value;

fn read_model(name: &str) -> ravel::onnx::Controller {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models");
    let bytes = std::fs::read(dir.join(format!("{name}.onnx"))).expect("model exists");
    let mut ext = ExternalFiles::new();
    for req in ravel::onnx::external_requests(&bytes) {
        let data = std::fs::read(dir.join(&req.location)).map_err(|e| e.to_string());
        ext.insert(req.location, data);
    }
    load(&bytes, &ext).expect("model loads")
}

/// Outputs computed by onnxruntime (float32) with scripts/onnx_reference.py
/// (the convolutional `conv_bars` included).
#[test]
fn committed_models_match_onnxruntime() {
    let text = include_str!("data/onnx_reference.json");
    let reference: Value = serde_json::from_str(text).expect("valid JSON");
    let models = reference.as_object().expect("object");
    assert_eq!(models.len(), 5);
    for (name, data) in models {
        let c = read_model(name);
        let inputs = data["inputs"].as_array().expect("inputs");
        let outputs = data["outputs"].as_array().expect("outputs");
        for (x, y) in inputs.iter().zip(outputs) {
            let x: Vec<f64> = x
                .as_array()
                .expect("row")
                .iter()
                .map(|v| v.as_f64().expect("number"))
                .collect();
            let y: Vec<f64> = y
                .as_array()
                .expect("row")
                .iter()
                .map(|v| v.as_f64().expect("number"))
                .collect();
            let ours = c.net.forward(&x);
            assert_eq!(ours.len(), y.len(), "{name}");
            for (a, b) in ours.iter().zip(&y) {
                // onnxruntime computes in float32
                assert!(
                    (a - b).abs() <= 1e-5 * (1.0 + b.abs()),
                    "{name}: ravel {a} vs onnxruntime {b} at {x:?}"
                );
            }
        }
    }
}

fn small_net(act: Activation) -> Network {
    Network::new(
        2,
        vec![
            Layer::Affine {
                w: DMatrix::from_row_slice(3, 2, &[0.5, -1.25, 2.0, 0.75, -0.5, 1.0]),
                b: DVector::from_column_slice(&[0.25, -0.5, 0.125]),
            },
            Layer::Act(act),
            Layer::Affine {
                w: DMatrix::from_row_slice(1, 3, &[1.5, -0.25, 0.5]),
                b: DVector::from_column_slice(&[-0.375]),
            },
        ],
    )
}

fn by_hand(act: Activation, x: &[f64]) -> f64 {
    // the same network written out by hand
    let z = [
        0.5 * x[0] - 1.25 * x[1] + 0.25,
        2.0 * x[0] + 0.75 * x[1] - 0.5,
        -0.5 * x[0] + x[1] + 0.125,
    ];
    let h: Vec<f64> = z.iter().map(|v| act.eval(*v)).collect();
    1.5 * h[0] - 0.25 * h[1] + 0.5 * h[2] - 0.375
}

#[test]
fn every_storage_and_layer_form_round_trips() {
    let storages = [
        Storage::RawF32,
        Storage::FloatData,
        Storage::RawF64,
        Storage::DoubleData,
        Storage::External,
    ];
    for act in [Activation::Relu, Activation::Tanh, Activation::Sigmoid] {
        let net = small_net(act);
        for storage in storages {
            for keras in [false, true] {
                let mut g = GraphBuilder::new(2, storage);
                g.network(&net, keras);
                g.unary("Flatten");
                g.unary("Identity");
                let (model, data) = g.finish(1);
                let mut ext = ExternalFiles::new();
                for req in ravel::onnx::external_requests(&model) {
                    ext.insert(req.location, Ok(data.clone()));
                }
                let c = load(&model, &ext)
                    .unwrap_or_else(|e| panic!("{storage:?} keras={keras}: {e:?}"));
                assert_eq!((c.inputs, c.outputs), (2, 1));
                for x in [[0.3, -0.7], [-1.5, 2.0], [0.0, 0.0]] {
                    let y = c.net.forward(&x)[0];
                    assert!(
                        (y - by_hand(act, &x)).abs() < 1e-12,
                        "{storage:?} keras={keras} {act:?}: {y}"
                    );
                }
            }
        }
    }
}

#[test]
fn normalisation_nodes_are_affine_layers() {
    let mut g = GraphBuilder::new(2, Storage::RawF32);
    g.elementwise("Sub", &[1.0, -2.0]);
    g.elementwise("Div", &[2.0, 4.0]);
    g.elementwise("Mul", &[3.0, 1.0]);
    g.elementwise("Add", &[0.5, 0.5]);
    let (model, _) = g.finish(2);
    let c = load(&model, &ExternalFiles::new()).expect("loads");
    let y = c.net.forward(&[5.0, 2.0]);
    // ((5-1)/2*3 + 0.5, (2+2)/4*1 + 0.5)
    assert_eq!(y, vec![6.5, 1.5]);
}

#[test]
fn gemm_attributes_are_honoured() {
    use prost::Message;
    use ravel::onnx::proto::*;
    // y = alpha * x Bᵀ... with transB = 0: B is [in, out]
    let t = |name: &str, dims: Vec<i64>, vals: Vec<f32>| TensorProto {
        dims,
        data_type: Some(1),
        float_data: vals,
        name: Some(name.into()),
        ..Default::default()
    };
    let attr_f = |n: &str, v: f32| AttributeProto {
        name: Some(n.into()),
        f: Some(v),
        r#type: Some(1),
        ..Default::default()
    };
    let vi = |n: &str| ValueInfoProto {
        name: Some(n.into()),
        r#type: None,
    };
    let model = ModelProto {
        ir_version: Some(8),
        graph: Some(GraphProto {
            node: vec![NodeProto {
                input: vec!["x".into(), "B".into(), "C".into()],
                output: vec!["y".into()],
                name: Some("gemm".into()),
                op_type: Some("Gemm".into()),
                attribute: vec![attr_f("alpha", 2.0), attr_f("beta", 0.5)],
                domain: None,
            }],
            initializer: vec![
                t("B", vec![2, 1], vec![1.0, 3.0]),
                t("C", vec![1], vec![4.0]),
            ],
            input: vec![vi("x")],
            output: vec![vi("y")],
            name: None,
        }),
        opset_import: vec![ravel::onnx::proto::OperatorSetIdProto {
            domain: Some(String::new()),
            version: Some(17),
        }],
        ..Default::default()
    };
    let c = load(&model.encode_to_vec(), &ExternalFiles::new()).expect("loads");
    // 2 * (1*1 + 2*3) + 0.5 * 4 = 16
    assert_eq!(c.net.forward(&[1.0, 2.0]), vec![16.0]);
    assert_eq!(c.inputs, 2);
}

#[test]
fn loader_errors_name_the_problem() {
    let e = load(b"not protobuf at all \xff\xff", &ExternalFiles::new()).expect_err("garbage");
    assert_eq!(e.kind, OnnxErrorKind::Decode);

    let mut g = GraphBuilder::new(2, Storage::RawF32);
    g.gemm(&DMatrix::from_element(1, 2, 1.0), &DVector::zeros(1));
    g.unary("Elu");
    let e = load(&g.finish(1).0, &ExternalFiles::new()).expect_err("unsupported");
    assert_eq!(e.kind, OnnxErrorKind::Unsupported);
    assert!(e.message.contains("Elu"), "{}", e.message);

    let mut g = GraphBuilder::new(2, Storage::RawF32);
    g.gemm(
        &DMatrix::from_element(1, 2, f64::INFINITY),
        &DVector::zeros(1),
    );
    let e = load(&g.finish(1).0, &ExternalFiles::new()).expect_err("inf");
    assert_eq!(e.kind, OnnxErrorKind::NonFinite);

    let mut g = GraphBuilder::new(2, Storage::RawF32);
    g.elementwise("Div", &[1.0, 0.0]);
    let e = load(&g.finish(2).0, &ExternalFiles::new()).expect_err("div by zero");
    assert_eq!(e.kind, OnnxErrorKind::NonFinite);

    let mut g = GraphBuilder::new(2, Storage::External);
    g.gemm(&DMatrix::from_element(1, 2, 1.0), &DVector::zeros(1));
    let (model, data) = g.finish(1);
    let e = load(&model, &ExternalFiles::new()).expect_err("missing data");
    assert_eq!(e.kind, OnnxErrorKind::ExternalData);
    let mut ext = ExternalFiles::new();
    ext.insert("model.onnx.data".into(), Ok(data[..4].to_vec()));
    let e = load(&model, &ext).expect_err("short data");
    assert_eq!(e.kind, OnnxErrorKind::ExternalData);

    let mut g = GraphBuilder::new(3, Storage::RawF32);
    g.gemm(&DMatrix::from_element(1, 2, 1.0), &DVector::zeros(1));
    let e = load(&g.finish(1).0, &ExternalFiles::new()).expect_err("shape");
    assert_eq!(e.kind, OnnxErrorKind::Malformed);
}

/// What `torch.onnx.export` writes for saturated, leaky, batch-normalised
/// policies loads as an exact chain: Clip (bounds as inputs, opset ≥ 11, or
/// as attributes, older opsets), LeakyRelu, BatchNormalization in inference
/// form, Dropout in inference mode; training-mode graphs are refused with
/// a message that says what to do.
#[test]
fn exporter_ops_load_as_exact_chains() {
    use prost::Message;
    use ravel::onnx::build::{float_attr, int_attr};
    use ravel::onnx::proto::{dtype, ModelProto};
    let w1 = DMatrix::from_row_slice(3, 2, &[0.5, -0.25, 1.0, 0.75, -1.5, 0.125]);
    let b1 = DVector::from_column_slice(&[0.25, -0.5, 0.0]);
    let w2 = DMatrix::from_row_slice(1, 3, &[1.0, -0.5, 0.25]);
    let b2 = DVector::from_column_slice(&[0.125]);
    let hidden = |x: &[f64], alpha: f64| -> Vec<f64> {
        (0..3)
            .map(|i| {
                let z = w1[(i, 0)] * x[0] + w1[(i, 1)] * x[1] + b1[i];
                if z >= 0.0 {
                    z
                } else {
                    alpha * z
                }
            })
            .collect()
    };
    let out = |h: &[f64]| (0..3).map(|i| w2[(0, i)] * h[i]).sum::<f64>() + b2[0];
    let inputs = [
        [0.3, -0.7],
        [-1.5, 2.0],
        [2.0, 1.0],
        [-3.0, -3.0],
        [0.0, 0.0],
    ];

    // Gemm → LeakyRelu(0.125) → Gemm → Clip(min, max as inputs)
    for opset_inputs in [true, false] {
        let mut g = GraphBuilder::new(2, Storage::RawF32);
        g.gemm(&w1, &b1);
        g.node("LeakyRelu", &[], vec![float_attr("alpha", 0.125)]);
        g.gemm(&w2, &b2);
        if opset_inputs {
            let lo = g.constant("min", &[], &[-0.5]);
            let hi = g.constant("max", &[], &[0.75]);
            g.node("Clip", &[lo, hi], vec![]);
        } else {
            g.node(
                "Clip",
                &[],
                vec![float_attr("min", -0.5), float_attr("max", 0.75)],
            );
        }
        let c = load(&g.finish(1).0, &ExternalFiles::new()).expect("loads");
        assert_eq!((c.inputs, c.outputs), (2, 1));
        assert!(c.notes.iter().any(|n| n.contains("clip")), "{:?}", c.notes);
        for x in inputs {
            let want = out(&hidden(&x, 0.125)).clamp(-0.5, 0.75);
            let y = c.net.forward(&x)[0];
            assert!((y - want).abs() < 1e-12, "{x:?}: {y} vs {want}");
        }
    }

    // an explicit ±FLT_MAX bound (old opsets' default) means no bound
    let mut g = GraphBuilder::new(2, Storage::RawF32);
    g.gemm(&w1, &b1);
    g.node("LeakyRelu", &[], vec![float_attr("alpha", 0.125)]);
    g.gemm(&w2, &b2);
    g.node(
        "Clip",
        &[],
        vec![float_attr("min", f32::MIN), float_attr("max", 0.75)],
    );
    let c = load(&g.finish(1).0, &ExternalFiles::new()).expect("loads");
    for x in inputs {
        let want = out(&hidden(&x, 0.125)).min(0.75);
        let y = c.net.forward(&x)[0];
        assert!((y - want).abs() < 1e-12, "{x:?}: {y} vs {want}");
    }

    // BatchNormalization after the first Gemm, then ReLU, Dropout (inference)
    let (scale, bias, mean, var) = (
        [2.0, 0.5, 1.0],
        [0.1, -0.2, 0.0],
        [0.5, -1.0, 0.25],
        [4.0, 0.25, 1.0],
    );
    let eps = 1e-5f64;
    // the four parameters of a BatchNormalization node, as constants
    let bn_params = |g: &mut GraphBuilder| -> Vec<String> {
        [
            ("scale", scale),
            ("bias", bias),
            ("mean", mean),
            ("var", var),
        ]
        .iter()
        .map(|(n, v)| g.constant(n, &[3], v))
        .collect()
    };
    let mut g = GraphBuilder::new(2, Storage::RawF64);
    g.gemm(&w1, &b1);
    let names = bn_params(&mut g);
    g.node(
        "BatchNormalization",
        &names,
        vec![float_attr("epsilon", eps as f32)],
    );
    g.unary("Relu");
    let ratio = g.constant("ratio", &[], &[0.5]);
    g.node("Dropout", &[ratio], vec![]);
    g.gemm(&w2, &b2);
    let c = load(&g.finish(1).0, &ExternalFiles::new()).expect("loads");
    let eps32 = eps as f32 as f64;
    for x in inputs {
        let h: Vec<f64> = (0..3)
            .map(|i| {
                let z = w1[(i, 0)] * x[0] + w1[(i, 1)] * x[1] + b1[i];
                let d = scale[i] / (var[i] + eps32).sqrt();
                (d * z + (bias[i] - mean[i] * d)).max(0.0)
            })
            .collect();
        let y = c.net.forward(&x)[0];
        assert!((y - out(&h)).abs() < 1e-12, "{x:?}: {y} vs {}", out(&h));
    }

    // training mode: Dropout with training_mode = true (a bool initializer), BatchNormalization with training_mode = 1
    let mut g = GraphBuilder::new(2, Storage::RawF32);
    g.gemm(&w1, &b1);
    let ratio = g.constant("ratio", &[], &[0.5]);
    let flag = g.constant("training_mode", &[], &[1.0]);
    g.node("Dropout", &[ratio, flag.clone()], vec![]);
    g.gemm(&w2, &b2);
    let mut m = ModelProto::decode(g.finish(1).0.as_slice()).expect("model");
    for t in &mut m.graph.as_mut().expect("graph").initializer {
        if t.name.as_deref() == Some(flag.as_str()) {
            t.data_type = Some(dtype::BOOL);
            t.raw_data = Some(vec![1]);
        }
    }
    let e = load(&m.encode_to_vec(), &ExternalFiles::new()).expect_err("training dropout");
    assert!(e.message.contains("training mode"), "{}", e.message);
    assert!(e.hint.contains("model.eval()"), "{}", e.hint);

    let mut g = GraphBuilder::new(2, Storage::RawF32);
    g.gemm(&w1, &b1);
    let names = bn_params(&mut g);
    g.node(
        "BatchNormalization",
        &names,
        vec![int_attr("training_mode", 1)],
    );
    let e = load(&g.finish(3).0, &ExternalFiles::new()).expect_err("training batch norm");
    assert!(e.hint.contains("model.eval()"), "{}", e.hint);
}

/// A policy saturated in the ONNX graph (`Clip`, as `torch.clamp` exports
/// it) is analysed exactly like the same policy saturated by the spec's
/// control limits: the same reachable sets to the bit, the same verdicts.
#[test]
fn an_onnx_clip_equals_spec_saturation() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let c = read_model("double_integrator");
    let mut g = GraphBuilder::new(2, Storage::RawF64);
    g.network(&c.net, false);
    g.node(
        "Clip",
        &[],
        vec![
            ravel::onnx::build::float_attr("min", -1.0),
            ravel::onnx::build::float_attr("max", 1.0),
        ],
    );
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("clip");
    std::fs::create_dir_all(&dir).expect("dir");
    std::fs::write(dir.join("clipped.onnx"), g.finish(1).0).expect("write");
    let original =
        std::fs::read_to_string(root.join("specs/double_integrator.ravel")).expect("spec");
    assert!(original.contains("u in box([-1, 1])"));
    let clipped = original
        .replace("u in box([-1, 1])", "")
        .replace("\"../models/double_integrator.onnx\"", "\"clipped.onnx\"");
    let run = |src: &str, dir: &std::path::Path| {
        let c = ravel::front_end(src, dir, &ravel_cli::read_request).expect("checks");
        let plan = ravel::lower::lower_system(&c);
        ravel::execute::execute_system(&plan, &ravel::execute::Control::unlimited())
    };
    let a = run(&original, &root.join("specs"));
    let b = run(&clipped, &dir);
    assert_eq!(a.reach, b.reach);
    assert_eq!(a.verdict, b.verdict);
    let (pa, pb): (Vec<_>, Vec<_>) = (
        a.properties.iter().map(|p| (p.status, p.margin)).collect(),
        b.properties.iter().map(|p| (p.status, p.margin)).collect(),
    );
    assert_eq!(pa, pb);
}

/// Random values for the reference tests (multiples of 1/64 in [-2, 2]).
fn random_matrix(rng: &mut ravel_base::rng::Rng, r: usize, c: usize) -> DMatrix<f64> {
    DMatrix::from_fn(r, c, |_, _| (rng.uniform(-2.0, 2.0) * 64.0).round() / 64.0)
}

/// The loaded network against a reference evaluation of the graph at
/// random points.
fn agrees(c: &ravel::onnx::Controller, reference: &dyn Fn(&[f64]) -> Vec<f64>, what: &str) {
    let mut rng = ravel_base::rng::Rng::new(7);
    for _ in 0..50 {
        let x: Vec<f64> = (0..c.inputs).map(|_| rng.uniform(-3.0, 3.0)).collect();
        let (ours, want) = (c.net.forward(&x), reference(&x));
        assert_eq!(ours.len(), want.len(), "{what}");
        for (a, b) in ours.iter().zip(&want) {
            assert!(
                (a - b).abs() <= 1e-12 * (1.0 + b.abs()),
                "{what}: ravel {a} vs reference {b} at {x:?}"
            );
        }
    }
}

/// `W·x` with the constant on the left, on a 1-D input and on a column
/// `[k, 1]` (the two ways VNN-COMP's test networks write it), then shape
/// ops back to a row: each against the graph evaluated by hand.
#[test]
fn matmul_with_the_constant_on_the_left() {
    let mut rng = ravel_base::rng::Rng::new(1);
    let w1 = random_matrix(&mut rng, 4, 3);
    let b1 = random_matrix(&mut rng, 4, 1);
    let w2 = random_matrix(&mut rng, 2, 4);
    let by_hand = |x: &[f64]| -> Vec<f64> {
        let h: Vec<f64> = (0..4)
            .map(|i| ((0..3).map(|j| w1[(i, j)] * x[j]).sum::<f64>() + b1[(i, 0)]).max(0.0))
            .collect();
        (0..2)
            .map(|i| (0..4).map(|j| w2[(i, j)] * h[j]).sum::<f64>() - 0.5)
            .collect()
    };
    for column in [false, true] {
        let mut g = GraphBuilder::new(3, Storage::RawF64);
        if column {
            g.declare_shape(&[Some(3), Some(1)]);
        } else {
            g.declare_shape(&[Some(3)]);
        }
        g.matmul_left(&w1);
        let bias_dims: &[usize] = if column { &[4, 1] } else { &[4] };
        let b = g.constant("bias", bias_dims, b1.as_slice());
        g.node("Add", &[b], vec![]);
        g.unary("Relu");
        g.matmul_left(&w2);
        g.elementwise("Sub", &[0.5]);
        if column {
            // [2, 1] → [1, 2]
            let s = g.constant("shape", &[2], &[1.0, -1.0]);
            g.node("Reshape", &[s], vec![]);
        }
        let c = load(&g.finish(2).0, &ExternalFiles::new())
            .unwrap_or_else(|e| panic!("column={column}: {e:?}"));
        assert_eq!((c.inputs, c.outputs), (3, 2));
        agrees(&c, &by_hand, &format!("W·x, column={column}"));
    }
    // W·X on a matrix X of two columns [3, 2]: W times each column
    let by_columns = |x: &[f64]| -> Vec<f64> {
        let mut y = Vec::new();
        for i in 0..4 {
            for c in 0..2 {
                y.push((0..3).map(|j| w1[(i, j)] * x[2 * j + c]).sum::<f64>());
            }
        }
        y
    };
    let mut g = GraphBuilder::new(6, Storage::RawF64);
    g.declare_shape(&[Some(3), Some(2)]);
    g.matmul_left(&w1);
    let c = load(&g.finish(8).0, &ExternalFiles::new()).expect("loads");
    assert_eq!((c.inputs, c.outputs), (6, 8));
    agrees(&c, &by_columns, "W·X by columns");
    // a bias of shape [4] on the column [4, 1] broadcasts to [4, 4]: refused
    let mut g = GraphBuilder::new(3, Storage::RawF64);
    g.declare_shape(&[Some(3), Some(1)]);
    g.matmul_left(&w1);
    g.elementwise("Add", b1.as_slice());
    let e = load(&g.finish(4).0, &ExternalFiles::new()).expect_err("broadcast");
    assert_eq!(e.kind, OnnxErrorKind::Malformed);
    assert!(e.message.contains("larger"), "{}", e.message);
    // W·x with W's columns not matching x's rows
    let mut g = GraphBuilder::new(3, Storage::RawF64);
    g.declare_shape(&[Some(1), Some(3)]);
    g.matmul_left(&w1);
    let e = load(&g.finish(4).0, &ExternalFiles::new()).expect_err("shapes");
    assert_eq!(e.kind, OnnxErrorKind::Malformed);
    assert!(e.message.contains("[1, 3]"), "{}", e.message);
    // a constant of three dimensions
    let mut g = GraphBuilder::new(3, Storage::RawF64);
    let k = g.constant("kernel", &[1, 3, 2], &[1.0; 6]);
    g.node("MatMul", &[k], vec![]);
    let e = load(&g.finish(2).0, &ExternalFiles::new()).expect_err("3-D");
    assert_eq!(e.kind, OnnxErrorKind::Unsupported);
    assert!(e.message.contains("2-D"), "{}", e.message);
}

/// `x·W` on a value of several rows multiplies each row (a block-diagonal
/// map on the flat vector), after shape ops that keep the flat vector.
#[test]
fn matmul_on_rows_after_reshape_squeeze_unsqueeze() {
    let mut rng = ravel_base::rng::Rng::new(2);
    let w = random_matrix(&mut rng, 2, 3); // [in 2, out 3] as stored
    let by_hand = |x: &[f64]| -> Vec<f64> {
        // [[x0, x1], [x2, x3]] · W, flattened
        let mut y = Vec::new();
        for r in 0..2 {
            for j in 0..3 {
                y.push(x[2 * r] * w[(0, j)] + x[2 * r + 1] * w[(1, j)]);
            }
        }
        y
    };
    for opset13 in [false, true] {
        let mut g = GraphBuilder::new(4, Storage::RawF64);
        // [1, 4] → [1, 1, 4] → [1, 4] → [2, 2]
        if opset13 {
            let a = g.constant("axes", &[1], &[0.0]);
            g.node("Unsqueeze", &[a], vec![]);
            let a = g.constant("axes", &[1], &[-2.0]);
            g.node("Squeeze", &[a], vec![]);
        } else {
            g.node(
                "Unsqueeze",
                &[],
                vec![GraphBuilder::ints_attr("axes", &[0])],
            );
            g.node("Squeeze", &[], vec![GraphBuilder::ints_attr("axes", &[1])]);
        }
        let s = g.constant("shape", &[2], &[2.0, -1.0]);
        g.node("Reshape", &[s], vec![]);
        let k = g.constant("kernel", &[2, 3], w.transpose().as_slice());
        g.node("MatMul", &[k], vec![]);
        // [2, 3] → [2, 3] (0 copies a dimension) → [1, 6]
        let s = g.constant("shape", &[2], &[0.0, -1.0]);
        g.node("Reshape", &[s], vec![]);
        g.node(
            "Flatten",
            &[],
            vec![ravel::onnx::build::int_attr("axis", 0)],
        );
        g.unary("Identity");
        let c = load(&g.finish(6).0, &ExternalFiles::new())
            .unwrap_or_else(|e| panic!("opset13={opset13}: {e:?}"));
        assert_eq!((c.inputs, c.outputs), (4, 6));
        agrees(&c, &by_hand, &format!("rows, opset13={opset13}"));
    }
    // without the reshape, the same MatMul reads 4 ≠ 2 columns: refused
    let mut g = GraphBuilder::new(4, Storage::RawF64);
    let k = g.constant("kernel", &[2, 3], &[1.0; 6]);
    g.node("MatMul", &[k], vec![]);
    let e = load(&g.finish(3).0, &ExternalFiles::new()).expect_err("columns");
    assert_eq!(e.kind, OnnxErrorKind::Malformed);
}

/// Input normalisation `(x − mean)/std` with per-channel constants, then
/// `Flatten` and a layer: against the graph evaluated by hand.
#[test]
fn per_channel_normalisation_and_flatten() {
    let mut rng = ravel_base::rng::Rng::new(3);
    let w = random_matrix(&mut rng, 2, 6);
    let (mean, std) = ([0.25, -1.5], [0.5, 3.0]);
    let by_hand = |x: &[f64]| -> Vec<f64> {
        // x is [1, 2, 3]: channel c holds x[3c..3c+3]
        let z: Vec<f64> = (0..6).map(|i| (x[i] - mean[i / 3]) / std[i / 3]).collect();
        (0..2)
            .map(|r| (0..6).map(|j| w[(r, j)] * z[j]).sum::<f64>())
            .collect()
    };
    let mut g = GraphBuilder::new(6, Storage::RawF64);
    g.declare_shape(&[None, Some(2), Some(3)]);
    let m = g.constant("mean", &[2, 1], &mean);
    g.node("Sub", &[m], vec![]);
    let s = g.constant("std", &[1, 2, 1], &std);
    g.node("Div", &[s], vec![]);
    g.unary("Flatten");
    g.gemm(&w, &DVector::zeros(2));
    let c = load(&g.finish(2).0, &ExternalFiles::new()).expect("loads");
    assert_eq!(c.inputs, 6);
    // Div by c is multiplication by the f64 nearest 1/c (documented)
    let mut rng = ravel_base::rng::Rng::new(9);
    for _ in 0..50 {
        let x: Vec<f64> = (0..6).map(|_| rng.uniform(-3.0, 3.0)).collect();
        let (ours, want) = (c.net.forward(&x), by_hand(&x));
        for (a, b) in ours.iter().zip(&want) {
            assert!((a - b).abs() <= 1e-12 * (1.0 + b.abs()), "{a} vs {b}");
        }
    }
    // a constant that does not broadcast to [1, 2, 3]
    let mut g = GraphBuilder::new(6, Storage::RawF64);
    g.declare_shape(&[None, Some(2), Some(3)]);
    let m = g.constant("mean", &[2], &mean);
    g.node("Sub", &[m], vec![]);
    let e = load(&g.finish(6).0, &ExternalFiles::new()).expect_err("no broadcast");
    assert_eq!(e.kind, OnnxErrorKind::Malformed);
    assert!(e.message.contains("do not broadcast"), "{}", e.message);
}

/// Every refused shape op and division is a named error, never a panic.
#[test]
fn shape_ops_and_divisions_that_are_refused() {
    let refused = |build: &dyn Fn(&mut GraphBuilder), kind: OnnxErrorKind, what: &str| {
        let mut g = GraphBuilder::new(4, Storage::RawF64);
        build(&mut g);
        let e = load(&g.finish(4).0, &ExternalFiles::new()).expect_err(what);
        assert_eq!(e.kind, kind, "{what}: {e:?}");
        assert!(e.message.contains(what), "{what}: {}", e.message);
        assert!(
            e.message.contains("node '") || e.message.contains("initializer '"),
            "names the node or tensor: {}",
            e.message
        );
    };
    refused(
        &|g| {
            let s = g.constant("shape", &[2], &[3.0, 2.0]);
            g.node("Reshape", &[s], vec![]);
        },
        OnnxErrorKind::Malformed,
        "reshapes a value of shape [1, 4] (4 elements) to [3, 2]",
    );
    refused(
        &|g| {
            let s = g.constant("shape", &[2], &[-1.0, -1.0]);
            g.node("Reshape", &[s], vec![]);
        },
        OnnxErrorKind::Malformed,
        "two dimensions to infer",
    );
    refused(
        &|g| {
            // the target shape is the graph's input: computed, not constant
            let x = g.current();
            g.node_inputs("Reshape", vec![x.clone(), x], vec![]);
        },
        OnnxErrorKind::Unsupported,
        "reshapes to a computed shape",
    );
    refused(
        &|g| g.node("Squeeze", &[], vec![GraphBuilder::ints_attr("axes", &[1])]),
        OnnxErrorKind::Malformed,
        "squeezes axis 1",
    );
    refused(
        &|g| {
            g.node(
                "Flatten",
                &[],
                vec![ravel::onnx::build::int_attr("axis", 3)],
            )
        },
        OnnxErrorKind::Malformed,
        "axis 3",
    );
    refused(
        &|g| g.node("Unsqueeze", &[], vec![]),
        OnnxErrorKind::Malformed,
        "has no axes",
    );
    refused(
        &|g| g.elementwise("Div", &[1.0, 0.0, 1.0, 1.0]),
        OnnxErrorKind::NonFinite,
        "divides by zero",
    );
    refused(
        &|g| g.elementwise("Div", &[1e-320]),
        OnnxErrorKind::NonFinite,
        "reciprocal overflows",
    );
    refused(
        &|g| g.elementwise("Div", &[f64::NAN]),
        OnnxErrorKind::NonFinite,
        "non-finite",
    );
}

/// The geometry of one convolution or pooling case: the input `[C, H, W]`,
/// the kernel, strides, dilations and pads `[top, left, bottom, right]`.
#[derive(Clone, Copy, Debug)]
struct Geometry {
    input: [usize; 3],
    kernel: [usize; 2],
    strides: [usize; 2],
    dilations: [usize; 2],
    pads: [usize; 4],
}

impl Geometry {
    /// The output height and width, ONNX's formula with floor.
    fn out(&self) -> [usize; 2] {
        let axis = |a: usize| {
            let padded = self.input[1 + a] + self.pads[a] + self.pads[2 + a];
            let extent = (self.kernel[a] - 1) * self.dilations[a] + 1;
            (padded - extent) / self.strides[a] + 1
        };
        [axis(0), axis(1)]
    }

    /// The input row and column of output `(y, x)` and kernel tap `(ky, kx)`,
    /// `None` on the padding.
    fn at(&self, y: usize, x: usize, ky: usize, kx: usize) -> Option<(usize, usize)> {
        let iy = (y * self.strides[0] + ky * self.dilations[0]) as i64 - self.pads[0] as i64;
        let ix = (x * self.strides[1] + kx * self.dilations[1]) as i64 - self.pads[1] as i64;
        let inside = |v: i64, n: usize| v >= 0 && (v as usize) < n;
        (inside(iy, self.input[1]) && inside(ix, self.input[2]))
            .then_some((iy as usize, ix as usize))
    }

    fn attrs(&self) -> Vec<ravel::onnx::proto::AttributeProto> {
        let ints = |v: &[usize]| v.iter().map(|d| *d as i64).collect::<Vec<_>>();
        vec![
            GraphBuilder::ints_attr("strides", &ints(&self.strides)),
            GraphBuilder::ints_attr("dilations", &ints(&self.dilations)),
            GraphBuilder::ints_attr("pads", &ints(&self.pads)),
        ]
    }
}

/// A reference 2-D convolution by naive loops over NCHW: weight
/// `[M, C/group, kH, kW]` row-major, bias per output channel.
fn reference_conv(
    g: &Geometry,
    m: usize,
    group: usize,
    w: &[f64],
    b: &[f64],
    x: &[f64],
) -> Vec<f64> {
    let [c, h, wd] = g.input;
    let cg = c / group;
    let [oh, ow] = g.out();
    let mut y = vec![0.0; m * oh * ow];
    for mo in 0..m {
        let grp = mo / (m / group);
        for yy in 0..oh {
            for xx in 0..ow {
                let mut s = b[mo];
                for ci in 0..cg {
                    for ky in 0..g.kernel[0] {
                        for kx in 0..g.kernel[1] {
                            if let Some((iy, ix)) = g.at(yy, xx, ky, kx) {
                                let wi = ((mo * cg + ci) * g.kernel[0] + ky) * g.kernel[1] + kx;
                                let xi = ((grp * cg + ci) * h + iy) * wd + ix;
                                s += w[wi] * x[xi];
                            }
                        }
                    }
                }
                y[(mo * oh + yy) * ow + xx] = s;
            }
        }
    }
    y
}

/// A reference average pooling by naive loops (`count_include_pad`: divide
/// by the kernel's size, else by the taps inside the input).
fn reference_pool(g: &Geometry, include_pad: bool, x: &[f64]) -> Vec<f64> {
    let [c, h, wd] = g.input;
    let [oh, ow] = g.out();
    let mut y = Vec::new();
    for ci in 0..c {
        for yy in 0..oh {
            for xx in 0..ow {
                let (mut s, mut count) = (0.0, 0usize);
                for ky in 0..g.kernel[0] {
                    for kx in 0..g.kernel[1] {
                        if let Some((iy, ix)) = g.at(yy, xx, ky, kx) {
                            s += x[(ci * h + iy) * wd + ix];
                            count += 1;
                        }
                    }
                }
                let k = if include_pad {
                    g.kernel[0] * g.kernel[1]
                } else {
                    count
                };
                y.push(s / k as f64);
            }
        }
    }
    y
}

fn geometry(
    input: [usize; 3],
    kernel: [usize; 2],
    strides: [usize; 2],
    dilations: [usize; 2],
    pads: [usize; 4],
) -> Geometry {
    Geometry {
        input,
        kernel,
        strides,
        dilations,
        pads,
    }
}

/// `Conv` on random weights and inputs for several pad, stride, dilation
/// and group combinations (with and without bias, `auto_pad` spelled
/// out), each against the naive reference convolution.
#[test]
fn conv_matches_a_reference_convolution() {
    let mut rng = ravel_base::rng::Rng::new(11);
    // (geometry, output channels, group, bias, auto_pad)
    let cases: Vec<(Geometry, usize, usize, bool, Option<&str>)> = vec![
        (
            geometry([1, 5, 5], [3, 3], [1, 1], [1, 1], [0, 0, 0, 0]),
            2,
            1,
            true,
            None,
        ),
        (
            geometry([2, 6, 5], [3, 2], [1, 1], [1, 1], [1, 1, 1, 1]),
            3,
            1,
            true,
            None,
        ),
        (
            geometry([2, 7, 7], [3, 3], [2, 2], [1, 1], [1, 1, 1, 1]),
            2,
            1,
            false,
            None,
        ),
        (
            geometry([3, 8, 6], [2, 3], [2, 1], [1, 1], [0, 2, 1, 0]),
            2,
            1,
            true,
            None,
        ),
        (
            geometry([2, 9, 9], [3, 3], [1, 2], [2, 2], [2, 1, 0, 3]),
            2,
            1,
            true,
            None,
        ),
        (
            geometry([1, 7, 8], [2, 2], [3, 2], [3, 1], [1, 0, 2, 1]),
            4,
            1,
            true,
            None,
        ),
        // grouped and depthwise
        (
            geometry([4, 5, 5], [3, 3], [1, 1], [1, 1], [1, 1, 1, 1]),
            2,
            2,
            true,
            None,
        ),
        (
            geometry([3, 6, 6], [3, 3], [2, 2], [1, 1], [1, 1, 1, 1]),
            3,
            3,
            true,
            None,
        ),
        (
            geometry([2, 4, 4], [1, 1], [1, 1], [1, 1], [0, 0, 0, 0]),
            4,
            2,
            true,
            None,
        ),
        // auto_pad, with the pads it implies written out for the reference:
        // VALID none; SAME_UPPER on 7 with k 3, s 2: out 4, total pad 2 → 1, 1;
        // on 6 with k 2, s 1: total 1 → 0 before, 1 after (SAME_LOWER: 1, 0)
        (
            geometry([1, 7, 6], [3, 2], [2, 1], [1, 1], [0, 0, 0, 0]),
            2,
            1,
            true,
            Some("VALID"),
        ),
        (
            geometry([1, 7, 6], [3, 2], [2, 1], [1, 1], [1, 0, 1, 1]),
            2,
            1,
            true,
            Some("SAME_UPPER"),
        ),
        (
            geometry([1, 7, 6], [3, 2], [2, 1], [1, 1], [1, 1, 1, 0]),
            2,
            1,
            true,
            Some("SAME_LOWER"),
        ),
    ];
    for (k, (g, m, group, bias, auto_pad)) in cases.into_iter().enumerate() {
        let [c, h, wd] = g.input;
        let cg = c / group;
        let w = random_matrix(&mut rng, m * cg * g.kernel[0] * g.kernel[1], 1);
        let b = random_matrix(&mut rng, m, 1);
        let mut gb = GraphBuilder::new(c * h * wd, Storage::RawF64);
        gb.declare_shape(&[None, Some(c as i64), Some(h as i64), Some(wd as i64)]);
        let wn = gb.constant("weight", &[m, cg, g.kernel[0], g.kernel[1]], w.as_slice());
        let mut inputs = vec![wn];
        if bias {
            inputs.push(gb.constant("bias", &[m], b.as_slice()));
        }
        let mut attrs = vec![
            ravel::onnx::build::int_attr("group", group as i64),
            GraphBuilder::ints_attr("kernel_shape", &[g.kernel[0] as i64, g.kernel[1] as i64]),
        ];
        match auto_pad {
            Some(a) => {
                attrs.push(ravel::onnx::proto::AttributeProto {
                    name: Some("auto_pad".into()),
                    s: Some(a.as_bytes().to_vec()),
                    r#type: Some(3),
                    ..Default::default()
                });
                attrs.extend(
                    g.attrs()
                        .into_iter()
                        .filter(|a| a.name.as_deref() != Some("pads")),
                );
            }
            None => attrs.extend(g.attrs()),
        }
        gb.node("Conv", &inputs, attrs);
        let [oh, ow] = g.out();
        let c2 = load(&gb.finish(m * oh * ow).0, &ExternalFiles::new())
            .unwrap_or_else(|e| panic!("case {k}: {e:?}"));
        assert_eq!(
            (c2.inputs, c2.outputs),
            (c * h * wd, m * oh * ow),
            "case {k}"
        );
        let zeros = vec![0.0; m];
        let bb = if bias { b.as_slice() } else { &zeros[..] };
        agrees(
            &c2,
            &|x| reference_conv(&g, m, group, w.as_slice(), bb, x),
            &format!("conv case {k}: {g:?}, group {group}, {auto_pad:?}"),
        );
    }
}

/// `AveragePool` (with and without `count_include_pad`, strides, pads,
/// dilations) and `GlobalAveragePool` against the naive reference.
#[test]
fn average_pools_match_a_reference() {
    let cases = [
        (
            geometry([2, 6, 6], [2, 2], [2, 2], [1, 1], [0, 0, 0, 0]),
            false,
        ),
        (
            geometry([1, 5, 7], [3, 3], [1, 2], [1, 1], [1, 1, 1, 1]),
            false,
        ),
        (
            geometry([1, 5, 7], [3, 3], [1, 2], [1, 1], [1, 1, 1, 1]),
            true,
        ),
        (
            geometry([3, 7, 6], [3, 2], [2, 1], [2, 1], [2, 0, 1, 1]),
            false,
        ),
        (
            geometry([2, 8, 8], [3, 3], [3, 3], [1, 1], [1, 2, 0, 1]),
            true,
        ),
    ];
    for (k, (g, include)) in cases.into_iter().enumerate() {
        let [c, h, wd] = g.input;
        let mut gb = GraphBuilder::new(c * h * wd, Storage::RawF32);
        gb.declare_shape(&[None, Some(c as i64), Some(h as i64), Some(wd as i64)]);
        let mut attrs = g.attrs();
        attrs.push(GraphBuilder::ints_attr(
            "kernel_shape",
            &[g.kernel[0] as i64, g.kernel[1] as i64],
        ));
        attrs.push(ravel::onnx::build::int_attr(
            "count_include_pad",
            i64::from(include),
        ));
        gb.node("AveragePool", &[], attrs);
        let [oh, ow] = g.out();
        let p = load(&gb.finish(c * oh * ow).0, &ExternalFiles::new())
            .unwrap_or_else(|e| panic!("case {k}: {e:?}"));
        assert_eq!(p.outputs, c * oh * ow, "case {k}");
        agrees(
            &p,
            &|x| reference_pool(&g, include, x),
            &format!("pool case {k}: {g:?}, {include}"),
        );
        // every weight is the f64 nearest to 1/k for the k it divides by
        for l in &p.net.layers {
            if let Layer::Affine { w, .. } = l {
                for v in w.iter().filter(|v| **v != 0.0) {
                    let size = (1.0 / v).round();
                    assert_eq!(*v, 1.0 / size, "case {k}");
                }
            }
        }
    }
    // the global mean of each channel
    let mut gb = GraphBuilder::new(2 * 3 * 5, Storage::RawF32);
    gb.declare_shape(&[None, Some(2), Some(3), Some(5)]);
    gb.unary("GlobalAveragePool");
    let p = load(&gb.finish(2).0, &ExternalFiles::new()).expect("loads");
    assert_eq!(p.outputs, 2);
    agrees(
        &p,
        &|x| {
            (0..2)
                .map(|c| x[15 * c..15 * c + 15].iter().sum::<f64>() / 15.0)
                .collect()
        },
        "global average",
    );
}

/// A small convolutional classifier as PyTorch writes it: normalisation,
/// Conv, Relu, a strided depthwise Conv, Relu, AveragePool, Flatten, Gemm
/// (consecutive affine layers kept as they are), against the reference;
/// replay in float32 stays near the real-arithmetic output.
#[test]
fn a_conv_network_loads_as_a_chain() {
    let mut rng = ravel_base::rng::Rng::new(12);
    let g1 = geometry([1, 8, 8], [3, 3], [1, 1], [1, 1], [1, 1, 1, 1]);
    let g2 = geometry([4, 8, 8], [3, 3], [2, 2], [1, 1], [1, 1, 1, 1]);
    let g3 = geometry([4, 4, 4], [2, 2], [2, 2], [1, 1], [0, 0, 0, 0]);
    let w1 = random_matrix(&mut rng, 4 * 9, 1);
    let b1 = random_matrix(&mut rng, 4, 1);
    let w2 = random_matrix(&mut rng, 4 * 9, 1);
    let b2 = random_matrix(&mut rng, 4, 1);
    let fc = random_matrix(&mut rng, 3, 16);
    let fb = random_matrix(&mut rng, 3, 1);
    let reference = |x: &[f64]| -> Vec<f64> {
        let z: Vec<f64> = x.iter().map(|v| (v - 0.5) * 4.0).collect();
        let relu = |v: Vec<f64>| v.into_iter().map(|a| a.max(0.0)).collect::<Vec<_>>();
        let h = relu(reference_conv(&g1, 4, 1, w1.as_slice(), b1.as_slice(), &z));
        let h = relu(reference_conv(&g2, 4, 4, w2.as_slice(), b2.as_slice(), &h));
        let h = reference_pool(&g3, false, &h);
        (0..3)
            .map(|i| fb[i] + (0..16).map(|j| fc[(i, j)] * h[j]).sum::<f64>())
            .collect()
    };
    let mut gb = GraphBuilder::new(64, Storage::RawF32);
    gb.declare_shape(&[None, Some(1), Some(8), Some(8)]);
    gb.elementwise("Sub", &[0.5]);
    gb.elementwise("Div", &[0.25]);
    let conv =
        |gb: &mut GraphBuilder, g: &Geometry, w: &DMatrix<f64>, b: &DMatrix<f64>, group: i64| {
            // [M, C/group, kH, kW]: 4 × 1 × 3 × 3 for both (1 channel, or 4 in 4 groups)
            let wn = gb.constant(
                "weight",
                &[4, g.input[0] / group as usize, 3, 3],
                w.as_slice(),
            );
            let bn = gb.constant("bias", &[4], b.as_slice());
            let mut attrs = g.attrs();
            attrs.push(ravel::onnx::build::int_attr("group", group));
            gb.node("Conv", &[wn, bn], attrs);
        };
    conv(&mut gb, &g1, &w1, &b1, 1);
    gb.unary("Relu");
    conv(&mut gb, &g2, &w2, &b2, 4);
    gb.unary("Relu");
    let mut attrs = g3.attrs();
    attrs.push(GraphBuilder::ints_attr("kernel_shape", &[2, 2]));
    gb.node("AveragePool", &[], attrs);
    gb.unary("Flatten");
    gb.gemm(&fc, &fb.column(0).into_owned());
    let c = load(&gb.finish(3).0, &ExternalFiles::new()).expect("loads");
    assert_eq!((c.inputs, c.outputs), (64, 3));
    agrees(&c, &reference, "conv network");
    let kinds: Vec<bool> = c
        .net
        .layers
        .iter()
        .map(|l| matches!(l, Layer::Affine { .. }))
        .collect();
    // Sub, Div, Conv | Relu | Conv | Relu | AveragePool, Gemm
    assert_eq!(
        kinds,
        [true, true, true, false, true, false, true, true],
        "{kinds:?}"
    );
    let mut rng = ravel_base::rng::Rng::new(13);
    for _ in 0..20 {
        let x: Vec<f64> = (0..64)
            .map(|_| f64::from(rng.uniform(0.0, 1.0) as f32))
            .collect();
        for (a, b) in c.net.forward_stored(&x).iter().zip(c.net.forward(&x)) {
            assert!((a - b).abs() <= 1e-4 * (1.0 + b.abs()), "stored {a} vs {b}");
        }
    }
}

/// Hostile or inconsistent convolutions and poolings: each a named
/// diagnostic of the right kind, never a panic.
#[test]
fn hostile_convolutions_are_diagnostics() {
    use ravel::onnx::build::int_attr;
    let ints = GraphBuilder::ints_attr;
    // a Conv of a 3×3 kernel from 2 channels to 2 on a [1, 2, 5, 5] value
    let refused = |shape: &[Option<i64>],
                   build: &dyn Fn(&mut GraphBuilder),
                   kind: OnnxErrorKind,
                   what: &str| {
        let n: i64 = shape.iter().map(|d| d.unwrap_or(1)).product();
        let mut g = GraphBuilder::new(n as usize, Storage::RawF64);
        g.declare_shape(shape);
        build(&mut g);
        // not `expect_err`: a wrongly accepted model is not printed (its
        // matrices can hold millions of entries)
        let e = match load(&g.finish(4).0, &ExternalFiles::new()) {
            Ok(c) => panic!("{what}: loaded as {} → {}", c.inputs, c.outputs),
            Err(e) => e,
        };
        assert_eq!(e.kind, kind, "{what}: {e:?}");
        assert!(e.message.contains(what), "{what}: {}", e.message);
        assert!(
            e.message.contains("node '"),
            "names the node: {}",
            e.message
        );
    };
    let image = [None, Some(2), Some(5), Some(5)];
    let conv =
        |g: &mut GraphBuilder, dims: &[usize], attrs: Vec<ravel::onnx::proto::AttributeProto>| {
            let count = dims.iter().product::<usize>();
            let w = g.constant("weight", dims, &vec![0.5; count]);
            g.node("Conv", &[w], attrs);
        };
    let bad = OnnxErrorKind::Malformed;
    let unsupported = OnnxErrorKind::Unsupported;
    refused(
        &image,
        &|g| conv(g, &[2, 2, 3, 3], vec![ints("strides", &[0, 1])]),
        bad,
        "stride 0",
    );
    refused(
        &image,
        &|g| conv(g, &[2, 2, 3, 3], vec![ints("strides", &[1, -2])]),
        bad,
        "stride -2",
    );
    refused(
        &image,
        &|g| conv(g, &[2, 2, 3, 3], vec![ints("dilations", &[1, 0])]),
        bad,
        "dilation 0",
    );
    refused(
        &image,
        &|g| conv(g, &[2, 2, 3, 3], vec![ints("pads", &[0, -1, 0, 0])]),
        bad,
        "negative pad -1",
    );
    refused(
        &image,
        &|g| conv(g, &[2, 2, 3, 3], vec![ints("pads", &[1, 1])]),
        bad,
        "needs 4",
    );
    refused(
        &image,
        &|g| conv(g, &[2, 2, 6, 3], vec![]),
        bad,
        "larger than the padded input",
    );
    refused(
        &image,
        &|g| conv(g, &[2, 2, 3, 3], vec![ints("dilations", &[3, 1])]),
        bad,
        "larger than the padded input",
    );
    refused(
        &image,
        &|g| conv(g, &[2, 2, 3, 3], vec![ints("dilations", &[i64::MAX, 1])]),
        bad,
        "larger than the padded input",
    );
    refused(
        &image,
        &|g| conv(g, &[2, 3, 3, 3], vec![]),
        bad,
        "input channels per group",
    );
    refused(
        &image,
        &|g| conv(g, &[3, 1, 3, 3], vec![int_attr("group", 2)]),
        bad,
        "group 2",
    );
    refused(
        &image,
        &|g| conv(g, &[2, 2, 3, 3], vec![int_attr("group", 0)]),
        bad,
        "group 0",
    );
    refused(
        &image,
        &|g| conv(g, &[2, 1, 3, 3], vec![int_attr("group", -2)]),
        bad,
        "group -2",
    );
    refused(
        &image,
        &|g| conv(g, &[2, 2, 3, 3], vec![ints("kernel_shape", &[3, 2])]),
        bad,
        "kernel_shape [3, 2]",
    );
    refused(
        &image,
        &|g| conv(g, &[2, 2, 3], vec![]),
        unsupported,
        "2-D convolutions",
    );
    refused(
        &image,
        &|g| conv(g, &[2, 2, 0, 3], vec![]),
        bad,
        "empty weight",
    );
    refused(
        &image,
        &|g| {
            let auto = |v: &str| ravel::onnx::proto::AttributeProto {
                name: Some("auto_pad".into()),
                s: Some(v.as_bytes().to_vec()),
                r#type: Some(3),
                ..Default::default()
            };
            conv(
                g,
                &[2, 2, 3, 3],
                vec![auto("SAME_UPPER"), ints("pads", &[1, 1, 1, 1])],
            )
        },
        bad,
        "sets both pads and auto_pad",
    );
    refused(
        &image,
        &|g| {
            let a = ravel::onnx::proto::AttributeProto {
                name: Some("auto_pad".into()),
                s: Some(b"SAME\x1b[31m".to_vec()),
                r#type: Some(3),
                ..Default::default()
            };
            conv(g, &[2, 2, 3, 3], vec![a])
        },
        bad,
        "not an ONNX value",
    );
    // huge attributes: an output too wide, or padding beyond any input
    refused(
        &image,
        &|g| {
            conv(
                g,
                &[2, 2, 3, 3],
                vec![ints("pads", &[i64::MAX, 0, i64::MAX, 0])],
            )
        },
        unsupported,
        "wider than ravel's limit",
    );
    refused(
        &[None, Some(1), Some(64), Some(64)],
        &|g| conv(g, &[2, 1, 1, 1], vec![]),
        unsupported,
        "wider than ravel's limit",
    );
    refused(
        &image,
        &|g| {
            let x = g.current();
            g.node_inputs("Conv", vec![x, "missing".into()], vec![]);
        },
        unsupported,
        "non-constant weight 'missing'",
    );
    refused(
        &image,
        &|g| g.node("Conv", &[], vec![]),
        bad,
        "has no weight input",
    );
    refused(
        &image,
        &|g| {
            let w = g.constant("weight", &[2, 2, 3, 3], &[0.5; 36]);
            let b = g.constant("bias", &[3], &[0.0; 3]);
            g.node("Conv", &[w, b], vec![]);
        },
        bad,
        "bias of shape [3]",
    );
    refused(
        &image,
        &|g| {
            let w = g.constant("weight", &[2, 2, 3, 3], &[0.5; 36]);
            let x = g.current();
            g.node_inputs("Conv", vec![w, x], vec![]);
        },
        unsupported,
        "convolves a constant",
    );
    // not one NCHW image
    refused(
        &[None, Some(50)],
        &|g| conv(g, &[2, 2, 3, 3], vec![]),
        unsupported,
        "shape [1, 50]",
    );
    refused(
        &[Some(2), Some(1), Some(5), Some(5)],
        &|g| conv(g, &[2, 1, 3, 3], vec![]),
        unsupported,
        "shape [2, 1, 5, 5]",
    );
    refused(
        &[None, Some(2), Some(25)],
        &|g| g.unary("GlobalAveragePool"),
        unsupported,
        "[1, C, H, W]",
    );
    // pooling
    refused(
        &image,
        &|g| {
            g.node(
                "AveragePool",
                &[],
                vec![ints("kernel_shape", &[2, 2]), int_attr("ceil_mode", 1)],
            )
        },
        unsupported,
        "ceil_mode",
    );
    refused(
        &image,
        &|g| g.node("AveragePool", &[], vec![]),
        bad,
        "has no kernel_shape",
    );
    refused(
        &image,
        &|g| g.node("AveragePool", &[], vec![ints("kernel_shape", &[0, 2])]),
        bad,
        "kernel extent of 0",
    );
    refused(
        &image,
        &|g| {
            g.node(
                "AveragePool",
                &[],
                vec![ints("kernel_shape", &[1, 1]), ints("pads", &[2, 0, 0, 0])],
            )
        },
        bad,
        "lies in the padding",
    );
    refused(
        &image,
        &|g| {
            g.node(
                "AveragePool",
                &[],
                vec![ints("kernel_shape", &[2, 2]), ints("strides", &[0, 0])],
            )
        },
        bad,
        "stride 0",
    );
    // the dense matrices together past the limit on weights: two
    // 4096 × 4096 convolutions (the second refused before it is built)
    refused(
        &[None, Some(1), Some(64), Some(64)],
        &|g| {
            conv(g, &[1, 1, 1, 1], vec![]);
            conv(g, &[1, 1, 1, 1], vec![]);
        },
        unsupported,
        "dense 4096 × 4096 layer, which brings its convolutions' and poolings' weights past",
    );
    // element-wise constant ops are width × width layers each: nine on a
    // 4096-wide value pass the limit on the layers' entries together
    refused(
        &[None, Some(4096)],
        &|g| {
            for _ in 0..9 {
                let c = g.constant("scale", &[1], &[2.0]);
                g.node("Mul", &[c], vec![]);
            }
        },
        unsupported,
        "matrix entries, more than ravel's limit",
    );
    // a residual connection adding an unpadded convolution's smaller
    // output to its input (with pads it is a supported residual block)
    refused(
        &image,
        &|g| {
            let x = g.current();
            conv(g, &[2, 2, 3, 3], vec![]);
            let y = g.current();
            g.node_inputs("Add", vec![y, x], vec![]);
        },
        bad,
        "adds a value of shape [1, 2, 3, 3] to 'input', a value of shape [1, 2, 5, 5]",
    );
    // a huge stride over huge padding is a valid (mostly padded) layer
    let mut g = GraphBuilder::new(50, Storage::RawF64);
    g.declare_shape(&image);
    conv(
        &mut g,
        &[2, 2, 3, 3],
        vec![
            ints("pads", &[i64::MAX, 0, i64::MAX, 0]),
            ints("strides", &[i64::MAX, 1]),
        ],
    );
    let c = load(&g.finish(4).0, &ExternalFiles::new()).expect("loads");
    // rows: ⌊(5 + 2·(2⁶³ − 1) − 3)/(2⁶³ − 1)⌋ + 1 = 3 outputs, columns 3
    assert_eq!(c.outputs, 2 * 3 * 3);
}

/// `BatchNormalization` after a `Conv` normalises per channel (axis 1 of
/// `[1, C, H, W]`): against the reference convolution, normalised by hand.
#[test]
fn batch_normalisation_per_channel_after_a_conv() {
    let mut rng = ravel_base::rng::Rng::new(14);
    let g = geometry([2, 5, 4], [3, 3], [1, 1], [1, 1], [1, 1, 1, 1]);
    let w = random_matrix(&mut rng, 3 * 2 * 9, 1);
    let b = random_matrix(&mut rng, 3, 1);
    let (scale, shift, mean, var) = (
        [0.5, -2.0, 1.5],
        [0.25, 0.0, -1.0],
        [1.0, -0.5, 0.0],
        [4.0, 0.25, 1.0],
    );
    let eps = 0.5f32;
    let reference = |x: &[f64]| -> Vec<f64> {
        let y = reference_conv(&g, 3, 1, w.as_slice(), b.as_slice(), x);
        y.iter()
            .enumerate()
            .map(|(i, v)| {
                let c = i / 20;
                let z = (v - mean[c]) / (var[c] + f64::from(eps)).sqrt() * scale[c] + shift[c];
                z.max(0.0)
            })
            .collect()
    };
    let mut gb = GraphBuilder::new(40, Storage::RawF64);
    gb.declare_shape(&[None, Some(2), Some(5), Some(4)]);
    let wn = gb.constant("weight", &[3, 2, 3, 3], w.as_slice());
    let bn = gb.constant("bias", &[3], b.as_slice());
    gb.node("Conv", &[wn, bn], g.attrs());
    let params: Vec<String> = [&scale[..], &shift, &mean, &var]
        .iter()
        .map(|p| gb.constant("bn", &[3], p))
        .collect();
    gb.node(
        "BatchNormalization",
        &params,
        vec![ravel::onnx::build::float_attr("epsilon", eps)],
    );
    gb.unary("Relu");
    let c = load(&gb.finish(60).0, &ExternalFiles::new()).expect("loads");
    assert_eq!(c.outputs, 60);
    agrees(&c, &reference, "Conv, BatchNormalization, Relu");
}

/// A reference evaluation of a graph.
type Reference = Box<dyn Fn(&[f64]) -> Vec<f64>>;

/// A chain of `Gemm` (`G`), `Relu` (`R`) and `Tanh` (`T`) nodes from the
/// running value, then the residual `Add` of its end and the value where it
/// started; returns the reference evaluation of the block.
fn gemm_block(
    gb: &mut GraphBuilder,
    rng: &mut ravel_base::rng::Rng,
    width: usize,
    ops: &str,
) -> Reference {
    let skip = gb.current();
    let mut steps: Vec<(DMatrix<f64>, DVector<f64>, char)> = Vec::new();
    let mut w = width;
    let gemms = ops.chars().filter(|c| *c == 'G').count();
    let mut seen = 0;
    for op in ops.chars() {
        match op {
            'G' => {
                seen += 1;
                let out = if seen == gemms { width } else { width + 2 };
                let m = random_matrix(rng, out, w);
                let b = DVector::from_column_slice(random_matrix(rng, out, 1).as_slice());
                gb.gemm(&m, &b);
                steps.push((m, b, 'G'));
                w = out;
            }
            'R' => {
                gb.unary("Relu");
                steps.push((DMatrix::zeros(0, 0), DVector::zeros(0), 'R'));
            }
            _ => {
                gb.unary("Tanh");
                steps.push((DMatrix::zeros(0, 0), DVector::zeros(0), 'T'));
            }
        }
    }
    let h = gb.current();
    gb.node_inputs("Add", vec![h, skip], vec![]);
    Box::new(move |x: &[f64]| {
        let mut v = DVector::from_column_slice(x);
        for (m, b, op) in &steps {
            v = match op {
                'G' => m * &v + b,
                'R' => v.map(|z| z.max(0.0)),
                _ => v.map(f64::tanh),
            };
        }
        (v + DVector::from_column_slice(x)).as_slice().to_vec()
    })
}

/// Residual blocks (`x + F(x)`, `F` of `Gemm`s and ReLUs) load as exact
/// chains: the lowered network against the graph evaluated directly.
#[test]
fn residual_blocks_load_as_exact_chains() {
    let mut rng = ravel_base::rng::Rng::new(21);
    for (ops, layers) in [
        ("GRG", 3),   // the classic block: the Add joins the last Gemm
        ("GRGRG", 5), // a skip across two ReLUs
        ("G", 2),     // purely affine, one layer: x + A x + b, not I + A
        ("GG", 2),    // purely affine, two layers
        ("RG", 3),    // pre-activation: the fork layer [I; I; −I] first
        ("GR", 3),    // ending in a ReLU: an Add layer of its own
    ] {
        let mut gb = GraphBuilder::new(4, Storage::RawF64);
        let reference = gemm_block(&mut gb, &mut rng, 4, ops);
        let c = load(&gb.finish(4).0, &ExternalFiles::new()).expect(ops);
        assert_eq!(c.net.layers.len(), layers, "{ops}");
        agrees(&c, &reference, ops);
    }
    // two blocks in sequence, and a block nested in another
    let mut gb = GraphBuilder::new(3, Storage::RawF64);
    let first = gemm_block(&mut gb, &mut rng, 3, "GRG");
    gb.unary("Relu");
    let second = gemm_block(&mut gb, &mut rng, 3, "GRGRG");
    let c = load(&gb.finish(3).0, &ExternalFiles::new()).expect("two blocks");
    let relu = |v: Vec<f64>| v.into_iter().map(|z| z.max(0.0)).collect::<Vec<_>>();
    agrees(&c, &|x| second(&relu(first(x))), "two blocks in sequence");
    let mut gb = GraphBuilder::new(3, Storage::RawF64);
    let outer = gb.current();
    let inner = gemm_block(&mut gb, &mut rng, 3, "GRG");
    gb.unary("Relu");
    let m = random_matrix(&mut rng, 3, 3);
    let b = DVector::from_column_slice(random_matrix(&mut rng, 3, 1).as_slice());
    gb.gemm(&m, &b);
    let h = gb.current();
    gb.node_inputs("Add", vec![outer, h], vec![]);
    let c = load(&gb.finish(3).0, &ExternalFiles::new()).expect("nested");
    agrees(
        &c,
        &|x| {
            let v = DVector::from_vec(relu(inner(x)));
            (&m * v + &b + DVector::from_column_slice(x))
                .as_slice()
                .to_vec()
        },
        "a block nested in another",
    );
}

/// A convolutional residual block, Conv-BatchNormalization-Relu-Conv plus
/// the input, against naive loops.
#[test]
fn a_convolutional_residual_block() {
    let mut rng = ravel_base::rng::Rng::new(22);
    let g = geometry([2, 4, 3], [3, 3], [1, 1], [1, 1], [1, 1, 1, 1]);
    let (w1, b1) = (
        random_matrix(&mut rng, 36, 1),
        random_matrix(&mut rng, 2, 1),
    );
    let (w2, b2) = (
        random_matrix(&mut rng, 36, 1),
        random_matrix(&mut rng, 2, 1),
    );
    let (scale, shift, mean, var) = ([0.5, -2.0], [0.25, -1.0], [1.0, -0.5], [4.0, 0.25]);
    let reference = |x: &[f64]| -> Vec<f64> {
        let y = reference_conv(&g, 2, 1, w1.as_slice(), b1.as_slice(), x);
        let y: Vec<f64> = y
            .iter()
            .enumerate()
            .map(|(i, v)| {
                let c = i / 12;
                ((v - mean[c]) / (var[c] + 1e-5f32 as f64).sqrt() * scale[c] + shift[c]).max(0.0)
            })
            .collect();
        let z = reference_conv(&g, 2, 1, w2.as_slice(), b2.as_slice(), &y);
        z.iter().zip(x).map(|(a, b)| a + b).collect()
    };
    let mut gb = GraphBuilder::new(24, Storage::RawF64);
    gb.declare_shape(&[None, Some(2), Some(4), Some(3)]);
    let x = gb.current();
    let (wn, bn) = (
        gb.constant("weight", &[2, 2, 3, 3], w1.as_slice()),
        gb.constant("bias", &[2], b1.as_slice()),
    );
    gb.node("Conv", &[wn, bn], g.attrs());
    let params: Vec<String> = [&scale[..], &shift, &mean, &var]
        .iter()
        .map(|p| gb.constant("bn", &[2], p))
        .collect();
    gb.node(
        "BatchNormalization",
        &params,
        vec![ravel::onnx::build::float_attr("epsilon", 1e-5)],
    );
    gb.unary("Relu");
    let (wn, bn) = (
        gb.constant("weight", &[2, 2, 3, 3], w2.as_slice()),
        gb.constant("bias", &[2], b2.as_slice()),
    );
    gb.node("Conv", &[wn, bn], g.attrs());
    let h = gb.current();
    gb.node_inputs("Add", vec![x, h], vec![]);
    gb.unary("Flatten");
    let c = load(&gb.finish(24).0, &ExternalFiles::new()).expect("loads");
    assert_eq!(c.outputs, 24);
    agrees(&c, &reference, "Conv, BatchNormalization, Relu, Conv, + x");
}

/// Skips the pair cannot carry exactly are refused, naming the node,
/// before anything is allocated.
#[test]
fn residuals_that_are_refused() {
    let refused = |n: usize, build: &dyn Fn(&mut GraphBuilder), what: &str| {
        let mut g = GraphBuilder::new(n, Storage::RawF64);
        build(&mut g);
        let e = match load(&g.finish(n).0, &ExternalFiles::new()) {
            Ok(c) => panic!("{what}: loaded as {} → {}", c.inputs, c.outputs),
            Err(e) => e,
        };
        assert!(e.message.contains(what), "{what}: {}", e.message);
        assert!(
            e.message.contains("node '"),
            "names the node: {}",
            e.message
        );
    };
    let mut rng = ravel_base::rng::Rng::new(24);
    let m = random_matrix(&mut rng, 4, 4);
    let b = DVector::zeros(4);
    refused(
        4,
        &|g| {
            let x = g.current();
            g.gemm(&m, &b);
            g.unary("Tanh");
            g.gemm(&m, &b);
            let h = g.current();
            g.node_inputs("Add", vec![h, x], vec![]);
        },
        "across a Tanh activation",
    );
    refused(
        4,
        &|g| {
            let x = g.current();
            g.gemm(&m, &b);
            let h = g.current();
            g.node_inputs("Concat", vec![h, x], vec![]);
        },
        "'Concat', which ravel does not support",
    );
    let narrow = random_matrix(&mut rng, 3, 4);
    refused(
        4,
        &|g| {
            let x = g.current();
            g.gemm(&narrow, &DVector::zeros(3));
            let h = g.current();
            g.node_inputs("Add", vec![h, x], vec![]);
        },
        "adds a value of shape [1, 3] to 'input', a value of shape [1, 4]",
    );
    // a skip from inside a block that has already ended
    refused(
        4,
        &|g| {
            g.gemm(&m, &b);
            let inside = g.current();
            g.gemm(&m, &b);
            g.unary("Relu");
            g.gemm(&m, &b);
            let h = g.current();
            g.node_inputs("Add", vec![h, "input".into()], vec![]);
            let h = g.current();
            g.node_inputs("Add", vec![h, inside], vec![]);
        },
        "not an earlier value of the layer chain",
    );
    // hostile: the doubled width passes the limit; refused before the
    // 6000-row fork layer is built
    refused(
        2000,
        &|g| {
            let x = g.current();
            g.unary("Relu");
            let h = g.current();
            g.node_inputs("Add", vec![h, x], vec![]);
        },
        "past ravel's limit of 4096 neurons",
    );
}
