//! `ravel-models`: regenerate the controllers under `models/`.
//!
//! Each controller is a small network trained (plain Adam on mean squared
//! error, fixed seed) to imitate a saturated LQR law of its plant, then
//! written as ONNX by ravel's own writer; the network specs' classifiers
//! are trained the same way, or (the convolutional one) set by hand. The invalid models used by the
//! diagnostic specs are written here too. Run from the repository root:
//!
//! ```text
//! cargo run --release --bin ravel-models
//! ```

use std::fs;
use std::path::Path;

use nalgebra::{DMatrix, DVector};
use ravel::onnx::build::{GraphBuilder, Storage};
use ravel::onnx::proto::{AttributeProto, NodeProto};
use ravel_base::nn::{Activation, Layer, Network};
use ravel_base::rng::Rng;

/// Discrete-time LQR gain `K` (u = −K x) by Riccati iteration.
fn lqr(a: &DMatrix<f64>, b: &DMatrix<f64>, q: &DMatrix<f64>, r: &DMatrix<f64>) -> DMatrix<f64> {
    let mut p = q.clone();
    for _ in 0..5000 {
        let btp = b.transpose() * &p;
        let inv = (r + &btp * b)
            .try_inverse()
            .expect("R + BᵀPB is invertible for R > 0");
        let next = q + a.transpose() * &p * a - a.transpose() * &p * b * &inv * &btp * a;
        let done = (&next - &p).amax() < 1e-12;
        p = next;
        if done {
            break;
        }
    }
    let btp = b.transpose() * &p;
    (r + &btp * b).try_inverse().expect("invertible") * btp * a
}

struct Mlp {
    w: Vec<DMatrix<f64>>,
    b: Vec<DVector<f64>>,
    act: Activation,
}

impl Mlp {
    fn new(sizes: &[usize], act: Activation, rng: &mut Rng) -> Mlp {
        let mut w = Vec::new();
        let mut b = Vec::new();
        for k in 0..sizes.len() - 1 {
            let (n_in, n_out) = (sizes[k], sizes[k + 1]);
            let scale = (6.0 / n_in as f64).sqrt();
            w.push(DMatrix::from_fn(n_out, n_in, |_, _| {
                rng.uniform(-scale, scale) * 0.5
            }));
            b.push(DVector::from_fn(n_out, |_, _| rng.uniform(-0.1, 0.1)));
        }
        Mlp { w, b, act }
    }

    fn deriv(&self, z: f64) -> f64 {
        match self.act {
            Activation::Relu => {
                if z > 0.0 {
                    1.0
                } else {
                    0.0
                }
            }
            Activation::Tanh => 1.0 - z.tanh().powi(2),
            Activation::Sigmoid => {
                let s = ravel_base::nn::sigmoid(z);
                s * (1.0 - s)
            }
        }
    }

    /// Adam on mean squared error over mini-batches.
    fn train(
        &mut self,
        xs: &[DVector<f64>],
        ys: &[DVector<f64>],
        steps: usize,
        lr: f64,
        rng: &mut Rng,
    ) {
        let layers = self.w.len();
        let mut mw: Vec<DMatrix<f64>> = self.w.iter().map(|w| w.map(|_| 0.0)).collect();
        let mut vw = mw.clone();
        let mut mb: Vec<DVector<f64>> = self.b.iter().map(|b| b.map(|_| 0.0)).collect();
        let mut vb = mb.clone();
        let (b1, b2, eps): (f64, f64, f64) = (0.9, 0.999, 1e-8);
        let batch = 64;
        for step in 1..=steps {
            let mut gw: Vec<DMatrix<f64>> = self.w.iter().map(|w| w.map(|_| 0.0)).collect();
            let mut gb: Vec<DVector<f64>> = self.b.iter().map(|b| b.map(|_| 0.0)).collect();
            for _ in 0..batch {
                let i = rng.below(xs.len());
                let mut hs = vec![xs[i].clone()];
                let mut zs = Vec::new();
                for k in 0..layers {
                    let z = &self.w[k] * hs.last().expect("input") + &self.b[k];
                    let h = if k + 1 < layers {
                        z.map(|v| self.act.eval(v))
                    } else {
                        z.clone()
                    };
                    zs.push(z);
                    hs.push(h);
                }
                let mut delta = (hs.last().expect("output") - &ys[i]) * (2.0 / batch as f64);
                for k in (0..layers).rev() {
                    gw[k] += &delta * hs[k].transpose();
                    gb[k] += &delta;
                    if k > 0 {
                        let back = self.w[k].transpose() * &delta;
                        delta = back.zip_map(&zs[k - 1], |d, z| d * self.deriv(z));
                    }
                }
            }
            let lr_t = lr * (1.0 - b2.powi(step as i32)).sqrt() / (1.0 - b1.powi(step as i32));
            let decay = if step > steps * 3 / 4 { 0.2 } else { 1.0 };
            for k in 0..layers {
                mw[k] = &mw[k] * b1 + &gw[k] * (1.0 - b1);
                vw[k] = &vw[k] * b2 + gw[k].map(|g| g * g) * (1.0 - b2);
                self.w[k] -= mw[k].zip_map(&vw[k], |m, v| decay * lr_t * m / (v.sqrt() + eps));
                mb[k] = &mb[k] * b1 + &gb[k] * (1.0 - b1);
                vb[k] = &vb[k] * b2 + gb[k].map(|g| g * g) * (1.0 - b2);
                self.b[k] -= mb[k].zip_map(&vb[k], |m, v| decay * lr_t * m / (v.sqrt() + eps));
            }
        }
    }

    /// The network with weights rounded to float32, as they will be stored.
    fn network(&self) -> Network {
        let mut layers = Vec::new();
        for k in 0..self.w.len() {
            layers.push(Layer::Affine {
                w: self.w[k].map(|v| v as f32 as f64),
                b: self.b[k].map(|v| v as f32 as f64),
            });
            if k + 1 < self.w.len() {
                layers.push(Layer::Act(self.act));
            }
        }
        Network::new(self.w[0].ncols(), layers)
    }

    fn mse(&self, xs: &[DVector<f64>], ys: &[DVector<f64>]) -> f64 {
        let net = self.network();
        let total: f64 = xs
            .iter()
            .zip(ys)
            .map(|(x, y)| {
                let o = net.forward(x.as_slice());
                o.iter()
                    .zip(y.iter())
                    .map(|(a, b)| (a - b).powi(2))
                    .sum::<f64>()
            })
            .sum();
        total / xs.len() as f64
    }
}

struct Task {
    name: &'static str,
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    q: DMatrix<f64>,
    r: DMatrix<f64>,
    u_eq: DVector<f64>,
    u_lo: Vec<f64>,
    u_hi: Vec<f64>,
    region: Vec<(f64, f64)>,
    hidden: Vec<usize>,
    act: Activation,
    samples: usize,
    steps: usize,
    seed: u64,
}

fn train(task: &Task) -> Network {
    let k = lqr(&task.a, &task.b, &task.q, &task.r);
    let mut rng = Rng::new(task.seed);
    let xs: Vec<DVector<f64>> = (0..task.samples)
        .map(|_| {
            DVector::from_iterator(
                task.region.len(),
                task.region.iter().map(|(l, h)| rng.uniform(*l, *h)),
            )
        })
        .collect();
    let ys: Vec<DVector<f64>> = xs
        .iter()
        .map(|x| {
            let u = &task.u_eq - &k * x;
            DVector::from_iterator(
                u.len(),
                u.iter()
                    .enumerate()
                    .map(|(i, v)| v.clamp(task.u_lo[i], task.u_hi[i])),
            )
        })
        .collect();
    let mut sizes = vec![task.a.nrows()];
    sizes.extend(&task.hidden);
    sizes.push(task.b.ncols());
    let mut mlp = Mlp::new(&sizes, task.act, &mut rng);
    mlp.train(&xs, &ys, task.steps, 3e-3, &mut rng);
    eprintln!(
        "{}: LQR gain {:?}, imitation MSE {:.2e}",
        task.name,
        k.as_slice(),
        mlp.mse(&xs, &ys)
    );
    mlp.network()
}

fn write(dir: &Path, name: &str, (model, data): (Vec<u8>, Vec<u8>)) {
    fs::write(dir.join(name), model).expect("write model");
    if !data.is_empty() {
        fs::write(dir.join(format!("{name}.data")), data).expect("write data");
    }
}

/// Encode a network as Gemm(transB=1)/activation nodes (PyTorch style) or MatMul+Add (Keras style).
fn encode(net: &Network, storage: Storage, keras: bool) -> GraphBuilder {
    encode_into(GraphBuilder::new(net.inputs, storage), net, keras)
}

fn encode_into(mut g: GraphBuilder, net: &Network, keras: bool) -> GraphBuilder {
    g.network(net, keras);
    g
}

/// A small convolutional classifier of 1 × 6 × 6 images, with weights set
/// by hand (nothing to train): label 0 for a horizontal bar, 1 for a
/// vertical one. Conv (two 3 × 3 filters, pads 1, bias −0.25) detecting
/// horizontal and vertical lines, ReLU, 2 × 2 AveragePool with stride 2,
/// Flatten, and a Gemm scoring the horizontal channel's sum against the
/// vertical one's: the network of `specs/network/conv_bars.ravel`.
fn conv_bars() -> (Vec<u8>, Vec<u8>) {
    use ravel::onnx::build::int_attr;
    let mut g = GraphBuilder::new(36, Storage::RawF32);
    g.declare_shape(&[None, Some(1), Some(6), Some(6)]);
    let line = [-0.5, -0.5, -0.5, 1.0, 1.0, 1.0, -0.5, -0.5, -0.5];
    // the vertical filter is the horizontal one transposed
    let column: Vec<f64> = (0..9).map(|i| line[(i % 3) * 3 + i / 3]).collect();
    let kernel: Vec<f64> = line.iter().chain(&column).copied().collect();
    let w = g.constant("conv_weight", &[2, 1, 3, 3], &kernel);
    let b = g.constant("conv_bias", &[2], &[-0.25, -0.25]);
    g.node(
        "Conv",
        &[w, b],
        vec![
            GraphBuilder::ints_attr("kernel_shape", &[3, 3]),
            GraphBuilder::ints_attr("pads", &[1, 1, 1, 1]),
            GraphBuilder::ints_attr("strides", &[1, 1]),
            int_attr("group", 1),
        ],
    );
    g.unary("Relu");
    g.node(
        "AveragePool",
        &[],
        vec![
            GraphBuilder::ints_attr("kernel_shape", &[2, 2]),
            GraphBuilder::ints_attr("strides", &[2, 2]),
        ],
    );
    g.unary("Flatten");
    let score = DMatrix::from_fn(2, 18, |i, j| if (j < 9) == (i == 0) { 1.0 } else { -1.0 });
    g.gemm(&score, &DVector::zeros(2));
    g.finish(2)
}

fn main() {
    let root = Path::new("models");
    fs::create_dir_all(root.join("invalid")).expect("create models/");

    let di_a = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 0.0, 1.0]);
    let di_b = DMatrix::from_row_slice(2, 1, &[0.5, 1.0]);
    let di = Task {
        name: "double_integrator",
        a: di_a.clone(),
        b: di_b.clone(),
        q: DMatrix::identity(2, 2),
        r: DMatrix::from_element(1, 1, 1.0),
        u_eq: DVector::zeros(1),
        u_lo: vec![-1.0],
        u_hi: vec![1.0],
        region: vec![(-5.0, 5.0), (-4.0, 4.0)],
        hidden: vec![5, 5],
        act: Activation::Relu,
        samples: 4000,
        steps: 6000,
        seed: 1,
    };
    let di_net = train(&di);
    let n = di_net.outputs();
    write(
        root,
        "double_integrator.onnx",
        encode(&di_net, Storage::RawF32, false).finish(n),
    );
    // the same network with its weights in an external data file, as current PyTorch writes them
    write(
        root,
        "double_integrator_external.onnx",
        encode_into(
            GraphBuilder::new(2, Storage::External)
                .external_file("double_integrator_external.onnx.data"),
            &di_net,
            false,
        )
        .finish(n),
    );

    // a tanh controller for the noisy output-feedback loop, with input normalisation nodes
    let di_tanh = Task {
        name: "double_integrator_tanh",
        hidden: vec![8, 8],
        act: Activation::Tanh,
        seed: 2,
        ..di
    };
    let tanh_net = train(&di_tanh);
    let mut g = GraphBuilder::new(2, Storage::FloatData);
    // (y - 0) / 1 normalisation, written out the way exporters do
    g.elementwise("Sub", &[0.0, 0.0]);
    g.elementwise("Div", &[1.0, 1.0]);
    for layer in &tanh_net.layers {
        match layer {
            Layer::Affine { w, b } => g.gemm(w, b),
            Layer::Act(_) => g.unary("Tanh"),
        }
    }
    write(root, "double_integrator_tanh.onnx", g.finish(1));

    // 6-state linearised quadrotor (Reach-LP paper), Euler discretisation with dt = 0.1
    let dt = 0.1;
    let g0 = 9.8;
    let mut ac = DMatrix::<f64>::zeros(6, 6);
    for i in 0..3 {
        ac[(i, i + 3)] = 1.0;
    }
    let mut bc = DMatrix::<f64>::zeros(6, 3);
    bc[(3, 0)] = g0;
    bc[(4, 1)] = -g0;
    bc[(5, 2)] = 1.0;
    let quad = Task {
        name: "quadrotor",
        a: DMatrix::identity(6, 6) + ac * dt,
        b: bc * dt,
        q: DMatrix::from_diagonal(&DVector::from_column_slice(&[1.0, 1.0, 1.0, 0.5, 0.5, 0.5])),
        r: DMatrix::from_diagonal(&DVector::from_column_slice(&[2.0, 2.0, 0.5])),
        u_eq: DVector::from_column_slice(&[0.0, 0.0, g0]),
        u_lo: vec![
            -std::f64::consts::PI / 9.0,
            -std::f64::consts::PI / 9.0,
            0.0,
        ],
        u_hi: vec![
            std::f64::consts::PI / 9.0,
            std::f64::consts::PI / 9.0,
            2.0 * g0,
        ],
        region: vec![
            (3.0, 6.0),
            (3.0, 6.0),
            (1.5, 4.0),
            (-0.5, 1.5),
            (-1.0, 1.0),
            (-1.0, 1.0),
        ],
        hidden: vec![32, 32],
        act: Activation::Relu,
        samples: 6000,
        steps: 8000,
        seed: 3,
    };
    let quad_net = train(&quad);
    write(
        root,
        "quadrotor.onnx",
        encode(&quad_net, Storage::RawF32, true).finish(3),
    );

    // a 3-class classifier of the plane for the network specs: the label of
    // a point of [-1, 1]² is its 120° sector around the origin (sector 0
    // starts at angle 0), learned as one-hot targets by mean squared error
    let mut rng = Rng::new(4);
    let xs: Vec<DVector<f64>> = (0..4000)
        .map(|_| DVector::from_vec(vec![rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)]))
        .collect();
    let ys: Vec<DVector<f64>> = xs
        .iter()
        .map(|x| {
            let angle = x[1].atan2(x[0]).rem_euclid(std::f64::consts::TAU);
            let k = ((angle / (std::f64::consts::TAU / 3.0)) as usize).min(2);
            DVector::from_fn(3, |i, _| if i == k { 1.0 } else { 0.0 })
        })
        .collect();
    let mut clf = Mlp::new(&[2, 16, 16, 3], Activation::Relu, &mut rng);
    clf.train(&xs, &ys, 6000, 3e-3, &mut rng);
    eprintln!("classifier: MSE {:.2e}", clf.mse(&xs, &ys));
    let clf_net = clf.network();
    write(
        root,
        "classifier.onnx",
        encode(&clf_net, Storage::RawF32, false).finish(3),
    );

    // a Q-network for the CARRL demonstration: the optimal action values of
    // the lane-keeping task (ravel_cli::demo), scaled by 1/20, fitted by MSE
    let values = ravel_cli::demo::Values::solve(61, 51, 300);
    let mut rng = Rng::new(5);
    let xs: Vec<DVector<f64>> = (0..6000)
        .map(|_| DVector::from_vec(vec![rng.uniform(-1.5, 1.5), rng.uniform(-2.5, 2.5)]))
        .collect();
    let ys: Vec<DVector<f64>> = xs
        .iter()
        .map(|x| DVector::from_fn(3, |a, _| values.q([x[0], x[1]], a) / 20.0))
        .collect();
    let mut qnet = Mlp::new(&[2, 32, 32, 3], Activation::Relu, &mut rng);
    qnet.train(&xs, &ys, 12000, 2e-3, &mut rng);
    let agree = xs
        .iter()
        .zip(&ys)
        .filter(|(x, y)| {
            let q = qnet.network().forward(x.as_slice());
            let best = |v: &[f64]| (0..3).fold(0, |b, j| if v[j] > v[b] { j } else { b });
            best(&q) == best(y.as_slice())
        })
        .count();
    eprintln!(
        "lane Q-network: MSE {:.2e}, greedy action as the optimal one on {:.1} % of the training states",
        qnet.mse(&xs, &ys),
        100.0 * agree as f64 / xs.len() as f64
    );
    write(
        root,
        "lane_q.onnx",
        encode(&qnet.network(), Storage::RawF32, false).finish(3),
    );

    // a random 2 → 8 → 8 → 2 sigmoid map of the plane, for output sets in
    // two dimensions (hull shapes) of a network spec
    let mut rng = Rng::new(6);
    let planar = Mlp::new(&[2, 8, 8, 2], Activation::Sigmoid, &mut rng).network();
    write(
        root,
        "planar_sigmoid.onnx",
        encode(&planar, Storage::RawF32, true).finish(2),
    );

    write(root, "conv_bars.onnx", conv_bars());

    // invalid models, one per loader diagnostic
    let inv = root.join("invalid");
    fs::write(
        inv.join("not_a_model.onnx"),
        b"this is a text file, not a protobuf\n",
    )
    .expect("write");
    let mut nan = di_net.clone();
    if let Some(Layer::Affine { w, .. }) = nan.layers.get_mut(2) {
        w[(1, 3)] = f64::NAN;
    }
    write(
        &inv,
        "nan_weights.onnx",
        encode(&nan, Storage::RawF32, false).finish(1),
    );
    let mut g = encode(&di_net, Storage::RawF32, false);
    g.node(
        "Softmax",
        &[],
        vec![AttributeProto {
            name: Some("axis".into()),
            i: Some(1),
            r#type: Some(2),
            ..Default::default()
        }],
    );
    let _ = NodeProto::default();
    write(&inv, "softmax_head.onnx", g.finish(1));
    let three = Network::new(
        3,
        vec![Layer::Affine {
            w: DMatrix::from_element(1, 3, 0.5),
            b: DVector::zeros(1),
        }],
    );
    write(
        &inv,
        "three_inputs.onnx",
        encode(&three, Storage::RawF32, false).finish(1),
    );
    // declares 2 inputs but its first layer reads 3
    let wide = Network::new(
        2,
        vec![Layer::Affine {
            w: DMatrix::from_element(1, 3, 0.5),
            b: DVector::zeros(1),
        }],
    );
    let mut g = encode(&wide, Storage::RawF32, false);
    g.declare_input(2);
    write(&inv, "inconsistent_shapes.onnx", g.finish(1));
    let (model, _) = encode_into(
        GraphBuilder::new(2, Storage::External).external_file("missing.onnx.data"),
        &di_net,
        false,
    )
    .finish(1);
    fs::write(inv.join("missing_external_data.onnx"), model).expect("write");
    eprintln!("models written under {}", root.display());
}
