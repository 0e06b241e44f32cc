//! Feed-forward networks as ravel analyses them: a chain of affine maps and
//! element-wise activations.
//!
//! The network that is verified is the real-arithmetic function defined by the
//! weights stored here (ONNX `float` weights are converted to `f64` exactly).
//! [`Network::forward`] evaluates it in `f64` for simulation;
//! [`Network::forward_stored`] evaluates it as a runtime would evaluate the
//! model as stored, in the precision of its input type ([`InputType`]:
//! float32 for a float32 ONNX model), for counterexamples.

use nalgebra::{DMatrix, DVector};

/// An element-wise activation function.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Activation {
    /// `max(0, z)`
    Relu,
    /// `tanh(z)`
    Tanh,
    /// `1 / (1 + e^{-z})`
    Sigmoid,
}

impl Activation {
    /// Evaluate the activation in `f64`.
    pub fn eval(self, z: f64) -> f64 {
        match self {
            Activation::Relu => z.max(0.0),
            Activation::Tanh => z.tanh(),
            Activation::Sigmoid => sigmoid(z),
        }
    }

    /// A bound on the absolute error of [`Activation::eval`] at `z` against the exact function.
    ///
    /// `relu` is exact. For `tanh` (libm) and the sigmoid formula used here the
    /// error is a few units in the last place; 16 ulps plus an absolute
    /// subnormal-range term is a safe over-estimate.
    pub fn eval_error(self, value: f64) -> f64 {
        match self {
            Activation::Relu => 0.0,
            Activation::Tanh | Activation::Sigmoid => 16.0 * f64::EPSILON * value.abs() + 1e-300,
        }
    }

    /// The lowercase name used in reports.
    pub fn name(self) -> &'static str {
        match self {
            Activation::Relu => "relu",
            Activation::Tanh => "tanh",
            Activation::Sigmoid => "sigmoid",
        }
    }
}

/// `out = M x` for `count` vectors at once, stored input-major
/// (`x[j·count + s]` is entry `j` of vector `s`; `out` likewise): each entry
/// summed column by column, `M₀x₀ + M₁x₁ + …`, the order of nalgebra's
/// matrix-vector product, whatever `count` is.
pub fn mat_batch_into(m: &DMatrix<f64>, x: &[f64], count: usize, out: &mut Vec<f64>) {
    let rows = m.nrows();
    out.clear();
    out.resize(rows * count, 0.0);
    if rows == 0 || count == 0 {
        return;
    }
    if count == 1 {
        // one vector: column by column down each (contiguous) column of
        // `M`, every entry still summed in the order j = 0, 1, …
        for (j, (col, &xj)) in m.column_iter().zip(x).enumerate() {
            if j == 0 {
                for (o, &c) in out.iter_mut().zip(col.iter()) {
                    *o = xj * c;
                }
            } else {
                for (o, &c) in out.iter_mut().zip(col.iter()) {
                    *o += xj * c;
                }
            }
        }
        return;
    }
    for (i, o) in out.chunks_exact_mut(count).enumerate() {
        for (j, xj) in x.chunks_exact(count).enumerate().take(m.ncols()) {
            let c = m[(i, j)];
            if j == 0 {
                for (o, &x) in o.iter_mut().zip(xj) {
                    *o = x * c;
                }
            } else {
                for (o, &x) in o.iter_mut().zip(xj) {
                    *o += x * c;
                }
            }
        }
    }
}

/// The logistic sigmoid, evaluated without overflow for large |z|.
pub fn sigmoid(z: f64) -> f64 {
    if z >= 0.0 {
        1.0 / (1.0 + (-z).exp())
    } else {
        let e = z.exp();
        e / (1.0 + e)
    }
}

/// The element type of a network's input, which is also the precision a
/// runtime evaluates the stored model in: a counterexample must be a value of
/// this type ([`InputType::round`]) and must violate the property when the
/// network is evaluated in it ([`Network::forward_stored`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputType {
    /// ONNX `float` (and the default: every value of it is also an `f64`,
    /// and its rounding errors bound an `f64` evaluation's).
    F32,
    /// ONNX `double`.
    F64,
}

impl InputType {
    /// The ONNX name.
    pub fn name(self) -> &'static str {
        match self {
            InputType::F32 => "float32",
            InputType::F64 => "float64",
        }
    }

    /// The value of this type nearest to `v` (ties to even), as an `f64`
    /// (infinite when `v` lies beyond the type's range).
    pub fn round(self, v: f64) -> f64 {
        match self {
            InputType::F32 => f64::from(v as f32),
            InputType::F64 => v,
        }
    }

    /// Whether `v` is a finite value of this type.
    pub fn represents(self, v: f64) -> bool {
        v.is_finite() && self.round(v) == v
    }

    /// The smallest value of this type that is `≥ v` (`v` finite and within
    /// the type's range).
    pub fn ceil(self, v: f64) -> f64 {
        match self {
            InputType::F32 => {
                let r = v as f32;
                f64::from(if f64::from(r) < v { r.next_up() } else { r })
            }
            InputType::F64 => v,
        }
    }

    /// The largest value of this type that is `≤ v`.
    pub fn floor(self, v: f64) -> f64 {
        match self {
            InputType::F32 => {
                let r = v as f32;
                f64::from(if f64::from(r) > v { r.next_down() } else { r })
            }
            InputType::F64 => v,
        }
    }

    /// The next value of this type from `v` (a value of it) towards `to`.
    pub fn step_towards(self, v: f64, to: f64) -> f64 {
        match self {
            InputType::F32 if to > v => f64::from((v as f32).next_up()),
            InputType::F32 if to < v => f64::from((v as f32).next_down()),
            InputType::F64 if to > v => v.next_up(),
            InputType::F64 if to < v => v.next_down(),
            _ => v,
        }
    }

    /// The unit roundoff `u` (half the spacing of the values in `[1, 2)`):
    /// a rounded result is `v·(1 + δ)`, `|δ| ≤ u`, outside the subnormals.
    pub fn unit_roundoff(self) -> f64 {
        match self {
            InputType::F32 => f64::from(f32::EPSILON) / 2.0,
            InputType::F64 => f64::EPSILON / 2.0,
        }
    }

    /// The smallest positive (subnormal) value: a rounded product is off by
    /// at most half of it in the subnormal range.
    pub fn min_positive(self) -> f64 {
        match self {
            InputType::F32 => f64::from(f32::from_bits(1)),
            InputType::F64 => f64::from_bits(1),
        }
    }

    /// The largest finite value.
    pub fn max(self) -> f64 {
        match self {
            InputType::F32 => f64::from(f32::MAX),
            InputType::F64 => f64::MAX,
        }
    }

    /// What ravel assumes of a runtime's `tanh` and sigmoid in this
    /// precision: within this absolute distance of the exact function (2⁻¹⁸,
    /// 64 float32 units in the last place at 1, for float32; 2⁻⁴⁰ for
    /// float64). ReLU is exact in every precision.
    pub fn activation_error(self) -> f64 {
        match self {
            InputType::F32 => 2f64.powi(-18),
            InputType::F64 => 2f64.powi(-40),
        }
    }
}

/// One step of a network.
#[derive(Clone, Debug, PartialEq)]
pub enum Layer {
    /// `z = W h + b`, `W` is `out × in`.
    Affine {
        /// Weight matrix (`out × in`).
        w: DMatrix<f64>,
        /// Bias vector (`out`).
        b: DVector<f64>,
    },
    /// `h = σ(z)` element-wise.
    Act(Activation),
}

/// A feed-forward network `R^inputs → R^outputs`.
#[derive(Clone, Debug, PartialEq)]
pub struct Network {
    /// The layers, applied in order.
    pub layers: Vec<Layer>,
    /// Input dimension.
    pub inputs: usize,
    /// The input's element type: the precision of the model as stored
    /// ([`InputType::F32`] unless the loader read `double`).
    pub input_type: InputType,
}

impl Network {
    /// A network with the given input size and layers. Dimensions must chain;
    /// the ONNX loader and the generators guarantee it.
    pub fn new(inputs: usize, layers: Vec<Layer>) -> Network {
        Network {
            layers,
            inputs,
            input_type: InputType::F32,
        }
    }

    /// The same network with the input element type `t`.
    pub fn with_input_type(mut self, t: InputType) -> Network {
        self.input_type = t;
        self
    }

    /// The width of the value after layer `i` (`i = 0` is the input).
    pub fn width_at(&self, position: usize) -> usize {
        let mut n = self.inputs;
        for layer in self.layers.iter().take(position) {
            if let Layer::Affine { w, .. } = layer {
                n = w.nrows();
            }
        }
        n
    }

    /// The number of activation neurons (the hidden neurons, and those of
    /// saturation layers): the neurons Reach-SDP's programs may keep.
    pub fn activation_neurons(&self) -> usize {
        let mut n = self.inputs;
        let mut total = 0usize;
        for layer in &self.layers {
            match layer {
                Layer::Affine { w, .. } => n = w.nrows(),
                Layer::Act(_) => total = total.saturating_add(n),
            }
        }
        total
    }

    /// Output dimension.
    pub fn outputs(&self) -> usize {
        self.width_at(self.layers.len())
    }

    /// Evaluate the network in `f64`: each affine layer column by column,
    /// `z = W₀h₀ + W₁h₁ + …` then `+ b` (the order of nalgebra's
    /// matrix-vector product, so simulations keep their bits; see
    /// [`Network::forward_batch`], of which this is the batch of one).
    pub fn forward(&self, x: &[f64]) -> Vec<f64> {
        self.forward_batch(x, 1)
    }

    /// The output at `x` and the gradient of `c · f(x)` with respect to `x`
    /// (reverse mode, in `f64`; a ReLU at exactly 0 takes slope 0). An
    /// attack's search direction, never a bound: nothing here is rounded
    /// outward, and every point it leads to is evaluated and confirmed on
    /// its own.
    pub fn gradient(&self, x: &[f64], c: &[f64]) -> (Vec<f64>, Vec<f64>) {
        // forward, keeping every activation's input
        let mut h = x.to_vec();
        let mut pre: Vec<Vec<f64>> = Vec::with_capacity(self.layers.len());
        for layer in &self.layers {
            match layer {
                Layer::Affine { w, b } => {
                    let z = w * DVector::from_column_slice(&h) + b;
                    h = z.as_slice().to_vec();
                    pre.push(Vec::new());
                }
                Layer::Act(a) => {
                    pre.push(h.clone());
                    h.iter_mut().for_each(|v| *v = a.eval(*v));
                }
            }
        }
        let y = h;
        let mut g = c.to_vec();
        for (layer, z) in self.layers.iter().zip(&pre).rev() {
            match layer {
                Layer::Affine { w, .. } => {
                    g = w
                        .tr_mul(&DVector::from_column_slice(&g))
                        .as_slice()
                        .to_vec();
                }
                Layer::Act(a) => {
                    for (gi, zi) in g.iter_mut().zip(z) {
                        *gi *= match a {
                            Activation::Relu => f64::from(u8::from(*zi > 0.0)),
                            Activation::Tanh => {
                                let t = zi.tanh();
                                1.0 - t * t
                            }
                            Activation::Sigmoid => {
                                let s = sigmoid(*zi);
                                s * (1.0 - s)
                            }
                        };
                    }
                }
            }
        }
        (y, g)
    }

    /// [`Network::forward`] of `count` inputs at once, stored input-major
    /// (`x[i·count + s]` is input `i` of sample `s`; the outputs likewise).
    /// Every output is bit for bit `forward`'s: each sum runs over the same
    /// terms in the same order, only the samples are side by side (so the
    /// loops over them vectorise).
    pub fn forward_batch(&self, x: &[f64], count: usize) -> Vec<f64> {
        let mut h = x.to_vec();
        let mut z = Vec::new();
        for layer in &self.layers {
            match layer {
                Layer::Affine { w, b } => {
                    mat_batch_into(w, &h, count, &mut z);
                    for (zi, bi) in z.chunks_exact_mut(count.max(1)).zip(b.iter()) {
                        for v in zi {
                            *v += bi;
                        }
                    }
                    std::mem::swap(&mut h, &mut z);
                }
                Layer::Act(a) => h.iter_mut().for_each(|v| *v = a.eval(*v)),
            }
        }
        h
    }

    /// Evaluate the network as a runtime evaluates the stored model, in the
    /// precision of its input type: for float32, `x` rounded to float32
    /// (callers pass float32 values), every weight and bias rounded to
    /// float32 (stored float32 weights are unchanged), each affine output
    /// summed in a fixed order, `W₀h₀ + W₁h₁ + …` then `+ b`, every product
    /// and sum rounded to float32 (no fused multiply-add), ReLU exact, `tanh`
    /// and the sigmoid computed in `f64` and rounded to float32. For float64
    /// it is [`Network::forward`]. Runtimes may sum in other orders; the
    /// counterexample rule bounds every order (`execute::network`).
    pub fn forward_stored(&self, x: &[f64]) -> Vec<f64> {
        if self.input_type == InputType::F64 {
            return self.forward(x);
        }
        let mut h: Vec<f32> = x.iter().map(|v| *v as f32).collect();
        for layer in &self.layers {
            match layer {
                Layer::Affine { w, b } => {
                    let mut z = vec![0.0f32; w.nrows()];
                    for (i, zi) in z.iter_mut().enumerate() {
                        let mut s = 0.0f32;
                        for (j, hj) in h.iter().enumerate().take(w.ncols()) {
                            let p = (w[(i, j)] as f32) * *hj;
                            s = if j == 0 { p } else { s + p };
                        }
                        *zi = s + b[i] as f32;
                    }
                    h = z;
                }
                Layer::Act(Activation::Relu) => h.iter_mut().for_each(|v| *v = v.max(0.0)),
                Layer::Act(a) => h.iter_mut().for_each(|v| *v = a.eval(f64::from(*v)) as f32),
            }
        }
        h.into_iter().map(f64::from).collect()
    }

    /// The hidden activations used, in order of first appearance (for reports).
    pub fn activations(&self) -> Vec<Activation> {
        let mut out = Vec::new();
        for layer in &self.layers {
            if let Layer::Act(a) = layer {
                if !out.contains(a) {
                    out.push(*a);
                }
            }
        }
        out
    }

    /// Append control saturation `u ↦ min(hi, max(lo, u))` as two ReLU layers
    /// (`lo + relu(u − lo)`, then `hi − relu(hi − ·)`), the construction of Hu et al.
    /// Every bound in `lo`/`hi` must be finite and `lo ≤ hi`.
    pub fn with_saturation(&self, lo: &[f64], hi: &[f64]) -> Network {
        let mut layers = self.layers.clone();
        layers.extend(clamp_layers(lo.len(), Some(lo), Some(hi)));
        Network::new(self.inputs, layers).with_input_type(self.input_type)
    }
}

/// Layers computing `min(max(x, lo), hi)` exactly (either side optional) on
/// `m` values, as affine maps and ReLUs: `max(x, lo) = relu(x − lo) + lo` and
/// `min(y, hi) = hi − relu(hi − y)`. Every bias is a stored bound or its
/// negation, so no rounding changes the function (a bias `hi − lo` would).
/// Used for the spec's control limits and for ONNX `Clip`.
pub fn clamp_layers(m: usize, lo: Option<&[f64]>, hi: Option<&[f64]>) -> Vec<Layer> {
    let eye = DMatrix::<f64>::identity(m, m);
    let mut layers = Vec::new();
    if let Some(lo) = lo {
        // a1 = relu(x − lo) = max(x, lo) − lo, then + lo
        layers.push(Layer::Affine {
            w: eye.clone(),
            b: DVector::from_iterator(m, lo.iter().map(|l| -l)),
        });
        layers.push(Layer::Act(Activation::Relu));
        layers.push(Layer::Affine {
            w: eye.clone(),
            b: DVector::from_column_slice(lo),
        });
    }
    if let Some(hi) = hi {
        // a2 = relu(hi − y), out = hi − a2 = min(y, hi)
        layers.push(Layer::Affine {
            w: -eye.clone(),
            b: DVector::from_column_slice(hi),
        });
        layers.push(Layer::Act(Activation::Relu));
        layers.push(Layer::Affine {
            w: -eye,
            b: DVector::from_column_slice(hi),
        });
    }
    layers
}

/// Layers computing LeakyReLU with slope `alpha` on `m` values as a chain of
/// ReLUs: `leaky(x) = relu(x) − α·relu(−x)` (exact for any α), through a
/// layer twice as wide. Every propagator, Reach-SDP included, handles it.
pub fn leaky_relu_layers(m: usize, alpha: f64) -> Vec<Layer> {
    let eye = DMatrix::<f64>::identity(m, m);
    let mut split = DMatrix::<f64>::zeros(2 * m, m);
    split.view_mut((0, 0), (m, m)).copy_from(&eye);
    split.view_mut((m, 0), (m, m)).copy_from(&(-&eye));
    let mut join = DMatrix::<f64>::zeros(m, 2 * m);
    join.view_mut((0, 0), (m, m)).copy_from(&eye);
    join.view_mut((0, m), (m, m)).copy_from(&(&eye * -alpha));
    vec![
        Layer::Affine {
            w: split,
            b: DVector::zeros(2 * m),
        },
        Layer::Act(Activation::Relu),
        Layer::Affine {
            w: join,
            b: DVector::zeros(m),
        },
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_vector_and_a_batch_sum_in_the_same_order() {
        // each entry is x₀c₀ + x₁c₁ + … in that order, whether the vector
        // goes alone or beside others (bit for bit)
        let mut rng = crate::rng::Rng::new(3);
        let m = DMatrix::from_fn(7, 13, |_, _| rng.normal() * 1e3);
        let xs: Vec<Vec<f64>> = (0..5)
            .map(|_| (0..13).map(|_| rng.normal()).collect())
            .collect();
        let mut batch_in = vec![0.0; 13 * 5];
        for (s, x) in xs.iter().enumerate() {
            for (j, v) in x.iter().enumerate() {
                batch_in[j * 5 + s] = *v;
            }
        }
        let mut batch = Vec::new();
        mat_batch_into(&m, &batch_in, 5, &mut batch);
        for (s, x) in xs.iter().enumerate() {
            let mut one = Vec::new();
            mat_batch_into(&m, x, 1, &mut one);
            for i in 0..7 {
                let mut by_hand = x[0] * m[(i, 0)];
                for j in 1..13 {
                    by_hand += x[j] * m[(i, j)];
                }
                assert_eq!(one[i].to_bits(), by_hand.to_bits());
                assert_eq!(batch[i * 5 + s].to_bits(), by_hand.to_bits());
            }
        }
    }

    #[test]
    fn saturation_clips() {
        let net = Network::new(
            1,
            vec![Layer::Affine {
                w: DMatrix::from_row_slice(2, 1, &[1.0, -2.0]),
                b: DVector::from_column_slice(&[0.0, 0.5]),
            }],
        );
        let sat = net.with_saturation(&[-1.0, 0.0], &[1.0, 2.0]);
        let y = sat.forward(&[0.3]);
        assert!((y[0] - 0.3).abs() < 1e-15 && y[1] == 0.0);
        assert_eq!(sat.forward(&[5.0]), vec![1.0, 0.0]);
        assert_eq!(sat.forward(&[-5.0]), vec![-1.0, 2.0]);
        assert_eq!(sat.outputs(), 2);
    }

    /// The reverse-mode gradient agrees with central differences on a
    /// network with every activation (away from ReLU kinks).
    #[test]
    fn gradient_matches_differences() {
        let layers = vec![
            Layer::Affine {
                w: DMatrix::from_row_slice(3, 2, &[0.7, -1.2, 0.4, 0.9, -0.3, 0.5]),
                b: DVector::from_column_slice(&[0.1, -0.2, 0.3]),
            },
            Layer::Act(Activation::Relu),
            Layer::Affine {
                w: DMatrix::from_row_slice(3, 3, &[1.0, 0.5, -0.7, 0.2, -1.1, 0.8, 0.6, 0.3, 0.4]),
                b: DVector::from_column_slice(&[0.0, 0.1, -0.1]),
            },
            Layer::Act(Activation::Tanh),
            Layer::Affine {
                w: DMatrix::from_row_slice(2, 3, &[0.9, -0.4, 1.3, -0.6, 0.7, 0.2]),
                b: DVector::from_column_slice(&[0.05, -0.05]),
            },
            Layer::Act(Activation::Sigmoid),
        ];
        let net = Network::new(2, layers);
        let c = [1.5, -0.5];
        for x in [[0.3, 0.2], [-0.4, 0.9], [1.1, -0.7]] {
            let (y, g) = net.gradient(&x, &c);
            assert_eq!(y, net.forward(&x));
            for i in 0..2 {
                let h = 1e-6;
                let (mut a, mut b) = (x, x);
                a[i] += h;
                b[i] -= h;
                let f =
                    |p: &[f64]| -> f64 { net.forward(p).iter().zip(&c).map(|(v, w)| v * w).sum() };
                let d = (f(&a) - f(&b)) / (2.0 * h);
                assert!((d - g[i]).abs() < 1e-6, "{d} vs {}", g[i]);
            }
        }
    }
}
