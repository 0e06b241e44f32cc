//! `ravel-benchmark-models`: the project's own controllers for the
//! benchmark suite under `benchmarks/` (ReachNN B1–B6, TORA, ACC, unicycle,
//! single and double pendulum, NAV, attitude control, docking, and, with
//! specs under `benchmarks/pending/`, cart-pole, airplane and QUAD; the
//! facts of each benchmark are in `benchmarks/README.md`).
//!
//! For each benchmark: the plant is simulated in `f64` with RK4 over small
//! sub-steps and a zero-order hold on the control; an expert law is tuned by
//! a grid search over a small family (saturated linear feedback, feedback
//! linearisation, a polar parking law) for the largest margin on a probe set
//! of initial states; a small network is trained (Adam on mean squared
//! error, with two rounds of aggregation of the states the network itself
//! visits) to imitate it through the benchmark's controller interface
//! (`u = scale · net + offset`, the published output maps); and the closed
//! loop with the network, as stored in float32, is simulated from 2000
//! sampled initial states and the corners of X0. The margin printed is the
//! smallest, over those runs, of the distance to the property's boundary
//! (positive: the property holds on every run). Deterministic (fixed seeds).
//! Run from the repository root:
//!
//! ```text
//! cargo run --release --bin ravel-benchmark-models
//! ```

use std::f64::consts::PI;
use std::fs;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use nalgebra::{DMatrix, DVector};
use ravel::onnx::build::{GraphBuilder, Storage};
use ravel_base::nn::{Activation, Layer, Network};
use ravel_base::rng::Rng;

/// A vector field `ẋ = f(x, u)`.
type Field = fn(&[f64], &[f64]) -> Vec<f64>;
/// A control law on the state.
type Law<'a> = &'a dyn Fn(&[f64]) -> Vec<f64>;
/// A family of control laws `u(x, p)` over parameters `p`.
type Family<'a> = &'a dyn Fn(&[f64], &[f64]) -> Vec<f64>;
/// A tuned expert law.
type Expert = Box<dyn Fn(&[f64]) -> Vec<f64>>;
/// Tunes a benchmark's expert law.
type Tuner = Box<dyn Fn(&Bench) -> Expert + Send + Sync>;

/// One RK4 step of length `h` with the control held.
fn rk4(f: Field, x: &[f64], u: &[f64], h: f64) -> Vec<f64> {
    let add = |a: &[f64], k: &[f64], s: f64| -> Vec<f64> {
        a.iter().zip(k).map(|(a, k)| a + s * k).collect()
    };
    let k1 = f(x, u);
    let k2 = f(&add(x, &k1, h / 2.0), u);
    let k3 = f(&add(x, &k2, h / 2.0), u);
    let k4 = f(&add(x, &k3, h), u);
    (0..x.len())
        .map(|i| x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
        .collect()
}

/// A property, measured as a margin (positive: holds).
enum Prop {
    /// the state at the last step lies in the box (on the listed components)
    Goal(Vec<(usize, f64, f64)>),
    /// the state lies in the box at every sub-step of control steps `[from, to]`
    Always(Vec<(usize, f64, f64)>, usize, usize),
    /// `a · x + c ≥ 0` at every sub-step
    AlwaysLinear(Vec<f64>, f64),
    /// the state stays out of the box at every sub-step
    AlwaysOutside(Vec<(usize, f64, f64)>),
}

/// The distance inside the box (negative outside); a state that is not
/// finite (a run that blew up) is infinitely outside.
fn box_margin(x: &[f64], b: &[(usize, f64, f64)]) -> f64 {
    if x.iter().any(|v| !v.is_finite()) {
        return f64::NEG_INFINITY;
    }
    b.iter()
        .map(|&(i, lo, hi)| (x[i] - lo).min(hi - x[i]))
        .fold(f64::INFINITY, f64::min)
}

struct Bench {
    name: &'static str,
    f: Field,
    dt: f64,
    sub: usize,
    steps: usize,
    x0: Vec<(f64, f64)>,
    props: Vec<Prop>,
    /// the controller's inputs, from the state
    observe: fn(&[f64]) -> Vec<f64>,
    /// `u = scale · net + offset`
    scale: Vec<f64>,
    offset: Vec<f64>,
    hidden: Vec<usize>,
    act: Activation,
    out_act: Option<Activation>,
    seed: u64,
    /// a network without biases and without centring of its inputs and
    /// outputs: an odd function (for odd activations), exactly 0 at 0, so
    /// that an expert with its equilibrium at the origin keeps it exactly
    odd: bool,
}

impl Bench {
    /// States at every sub-step, `steps · sub + 1` of them.
    fn simulate(&self, x0: &[f64], law: Law) -> Vec<Vec<f64>> {
        let h = self.dt / self.sub as f64;
        let mut xs = vec![x0.to_vec()];
        let mut x = x0.to_vec();
        for _ in 0..self.steps {
            let u = law(&x);
            for _ in 0..self.sub {
                x = rk4(self.f, &x, &u, h);
                xs.push(x.clone());
            }
        }
        xs
    }

    fn margin(&self, xs: &[Vec<f64>]) -> f64 {
        let mut m = f64::INFINITY;
        for p in &self.props {
            let v = match p {
                Prop::Goal(b) => box_margin(xs.last().expect("a state"), b),
                Prop::Always(b, from, to) => xs[from * self.sub..=to * self.sub]
                    .iter()
                    .map(|x| box_margin(x, b))
                    .fold(f64::INFINITY, f64::min),
                Prop::AlwaysOutside(b) => xs
                    .iter()
                    .map(|x| {
                        if x.iter().any(|v| !v.is_finite()) {
                            return f64::NEG_INFINITY;
                        }
                        b.iter()
                            .map(|&(i, lo, hi)| (lo - x[i]).max(x[i] - hi))
                            .fold(f64::NEG_INFINITY, f64::max)
                    })
                    .fold(f64::INFINITY, f64::min),
                Prop::AlwaysLinear(a, c) => xs
                    .iter()
                    .map(|x| {
                        let v = a.iter().zip(x).map(|(a, x)| a * x).sum::<f64>() + c;
                        if v.is_finite() {
                            v
                        } else {
                            f64::NEG_INFINITY
                        }
                    })
                    .fold(f64::INFINITY, f64::min),
            };
            m = m.min(if v.is_nan() { f64::NEG_INFINITY } else { v });
        }
        m
    }

    fn sample_x0(&self, rng: &mut Rng, widen: f64) -> Vec<f64> {
        self.x0
            .iter()
            .map(|&(l, h)| {
                let w = (h - l) * widen;
                rng.uniform(l - w, h + w)
            })
            .collect()
    }

    /// The corners of X0 (its degenerate components held at their value).
    fn corners(&self) -> Vec<Vec<f64>> {
        let free: Vec<usize> = (0..self.x0.len())
            .filter(|&i| self.x0[i].0 < self.x0[i].1)
            .collect();
        (0..1usize << free.len())
            .map(|k| {
                let mut x: Vec<f64> = self.x0.iter().map(|&(l, _)| l).collect();
                for (bit, &i) in free.iter().enumerate() {
                    if k >> bit & 1 == 1 {
                        x[i] = self.x0[i].1;
                    }
                }
                x
            })
            .collect()
    }

    /// Probe initial states for tuning: the corners, the centre and a few samples.
    fn probes(&self) -> Vec<Vec<f64>> {
        let mut ps = self.corners();
        ps.push(self.x0.iter().map(|(l, h)| (l + h) / 2.0).collect());
        let mut rng = Rng::new(self.seed ^ 0x5eed);
        for _ in 0..8 {
            ps.push(self.sample_x0(&mut rng, 0.0));
        }
        ps
    }

    fn net_law<'a>(&'a self, net: &'a Network) -> impl Fn(&[f64]) -> Vec<f64> + 'a {
        move |x: &[f64]| {
            let y = net.forward(&(self.observe)(x));
            (0..self.scale.len())
                .map(|j| self.scale[j] * y[j] + self.offset[j])
                .collect()
        }
    }

    /// The network output that gives the control `u`, inside the output activation's range.
    fn target(&self, u: &[f64]) -> DVector<f64> {
        DVector::from_iterator(
            u.len(),
            u.iter().enumerate().map(|(j, u)| {
                let t = (u - self.offset[j]) / self.scale[j];
                match self.out_act {
                    Some(Activation::Tanh) => t.clamp(-0.97, 0.97),
                    Some(Activation::Sigmoid) => t.clamp(0.03, 0.97),
                    Some(Activation::Relu) => t.max(0.0),
                    None => t,
                }
            }),
        )
    }
}

/// Grid search of `family(x, p)` over the cartesian product of `grid`, for
/// the largest smallest margin over the probe set.
fn tune(b: &Bench, grid: &[Vec<f64>], family: Family) -> Vec<f64> {
    let probes = b.probes();
    let total: usize = grid.iter().map(Vec::len).product();
    let mut best = (f64::NEG_INFINITY, vec![]);
    for k in 0..total {
        let mut r = k;
        let p: Vec<f64> = grid
            .iter()
            .map(|g| {
                let v = g[r % g.len()];
                r /= g.len();
                v
            })
            .collect();
        let law = |x: &[f64]| family(x, &p);
        let m = probes
            .iter()
            .map(|x0| b.margin(&b.simulate(x0, &law)))
            .fold(f64::INFINITY, f64::min);
        if m > best.0 {
            best = (m, p);
        }
    }
    eprintln!(
        "{}: expert parameters {:?}, probe margin {:.4}",
        b.name, best.1, best.0
    );
    best.1
}

fn range(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let n = ((hi - lo) / step).round() as usize;
    (0..=n).map(|i| lo + step * i as f64).collect()
}

struct Mlp {
    w: Vec<DMatrix<f64>>,
    b: Vec<DVector<f64>>,
    act: Activation,
    out_act: Option<Activation>,
    /// biases trained (else held at 0)
    bias: bool,
}

fn deriv(act: Activation, z: f64) -> f64 {
    match act {
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

impl Mlp {
    fn new(
        sizes: &[usize],
        act: Activation,
        out_act: Option<Activation>,
        bias: bool,
        rng: &mut Rng,
    ) -> Mlp {
        let mut w = Vec::new();
        let mut b = Vec::new();
        for k in 0..sizes.len() - 1 {
            let (n_in, n_out) = (sizes[k], sizes[k + 1]);
            let scale = (6.0 / n_in as f64).sqrt() * 0.5;
            w.push(DMatrix::from_fn(n_out, n_in, |_, _| {
                rng.uniform(-scale, scale)
            }));
            let init = DVector::from_fn(n_out, |_, _| rng.uniform(-0.1, 0.1));
            b.push(if bias { init } else { init * 0.0 });
        }
        Mlp {
            w,
            b,
            act,
            out_act,
            bias,
        }
    }

    /// Adam on mean squared error over mini-batches of 64, the step size cut
    /// by 5 for the last quarter.
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
                    } else if let Some(a) = self.out_act {
                        z.map(|v| a.eval(v))
                    } else {
                        z.clone()
                    };
                    zs.push(z);
                    hs.push(h);
                }
                let mut delta = (hs.last().expect("output") - &ys[i]) * (2.0 / batch as f64);
                if let Some(a) = self.out_act {
                    delta = delta.zip_map(&zs[layers - 1], |d, z| d * deriv(a, z));
                }
                for k in (0..layers).rev() {
                    gw[k] += &delta * hs[k].transpose();
                    gb[k] += &delta;
                    if k > 0 {
                        let back = self.w[k].transpose() * &delta;
                        delta = back.zip_map(&zs[k - 1], |d, z| d * deriv(self.act, z));
                    }
                }
            }
            let lr_t = lr * (1.0 - b2.powi(step as i32)).sqrt() / (1.0 - b1.powi(step as i32));
            let decay = if step > steps * 3 / 4 { 0.2 } else { 1.0 };
            for k in 0..layers {
                mw[k] = &mw[k] * b1 + &gw[k] * (1.0 - b1);
                vw[k] = &vw[k] * b2 + gw[k].map(|g| g * g) * (1.0 - b2);
                self.w[k] -= mw[k].zip_map(&vw[k], |m, v| decay * lr_t * m / (v.sqrt() + eps));
                if !self.bias {
                    continue;
                }
                mb[k] = &mb[k] * b1 + &gb[k] * (1.0 - b1);
                vb[k] = &vb[k] * b2 + gb[k].map(|g| g * g) * (1.0 - b2);
                self.b[k] -= mb[k].zip_map(&vb[k], |m, v| decay * lr_t * m / (v.sqrt() + eps));
            }
        }
    }

    /// The network on raw inputs: the input normalisation `(x − μ)/σ` folded
    /// into the first layer and, for a linear output, the output scaling
    /// `σ_y y + μ_y` into the last; weights rounded to float32 as stored.
    fn network(&self, norm: &Norm) -> Network {
        let mut layers = Vec::new();
        let last = self.w.len() - 1;
        for k in 0..self.w.len() {
            let mut w = self.w[k].clone();
            let mut b = self.b[k].clone();
            if k == 0 {
                for j in 0..w.ncols() {
                    let s = norm.in_sd[j];
                    for i in 0..w.nrows() {
                        b[i] -= w[(i, j)] * norm.in_mean[j] / s;
                        w[(i, j)] /= s;
                    }
                }
            }
            if k == last && self.out_act.is_none() {
                for i in 0..w.nrows() {
                    for j in 0..w.ncols() {
                        w[(i, j)] *= norm.out_sd[i];
                    }
                    b[i] = b[i] * norm.out_sd[i] + norm.out_mean[i];
                }
            }
            layers.push(Layer::Affine {
                w: w.map(|v| v as f32 as f64),
                b: b.map(|v| v as f32 as f64),
            });
            if k < last {
                layers.push(Layer::Act(self.act));
            } else if let Some(a) = self.out_act {
                layers.push(Layer::Act(a));
            }
        }
        Network::new(self.w[0].ncols(), layers)
    }
}

struct Norm {
    in_mean: Vec<f64>,
    in_sd: Vec<f64>,
    out_mean: Vec<f64>,
    out_sd: Vec<f64>,
}

fn mean_sd(v: &[DVector<f64>]) -> (Vec<f64>, Vec<f64>) {
    let n = v[0].len();
    let c = v.len() as f64;
    let mean: Vec<f64> = (0..n)
        .map(|j| v.iter().map(|x| x[j]).sum::<f64>() / c)
        .collect();
    let sd = (0..n)
        .map(|j| {
            let s = (v.iter().map(|x| (x[j] - mean[j]).powi(2)).sum::<f64>() / c).sqrt();
            if s < 1e-9 {
                1.0
            } else {
                s
            }
        })
        .collect();
    (mean, sd)
}

/// Train the network for `b` imitating `expert`, check it by simulation,
/// write it; returns the network's margin.
fn build(b: &Bench, expert: Law, out: &Path) -> f64 {
    let mut rng = Rng::new(b.seed);
    // states at control instants along expert runs from a slightly widened X0,
    // each with perturbed copies
    let mut states: Vec<Vec<f64>> = Vec::new();
    let mut expert_margin = f64::INFINITY;
    for _ in 0..150 {
        let x0 = b.sample_x0(&mut rng, 0.1);
        let xs = b.simulate(&x0, expert);
        expert_margin = expert_margin.min(b.margin(&xs));
        for k in 0..b.steps {
            states.push(xs[k * b.sub].clone());
        }
    }
    let n = b.x0.len();
    let spread: Vec<f64> = (0..n)
        .map(|i| {
            let lo = states.iter().map(|x| x[i]).fold(f64::INFINITY, f64::min);
            let hi = states
                .iter()
                .map(|x| x[i])
                .fold(f64::NEG_INFINITY, f64::max);
            0.03 * (hi - lo) + 1e-3
        })
        .collect();
    let perturb = |states: &mut Vec<Vec<f64>>, from: usize, rng: &mut Rng| {
        let base: Vec<Vec<f64>> = states[from..].to_vec();
        for x in &base {
            for _ in 0..2 {
                states.push(
                    x.iter()
                        .zip(&spread)
                        .map(|(v, &s)| v + rng.uniform(-s, s))
                        .collect(),
                );
            }
        }
    };
    perturb(&mut states, 0, &mut rng);

    let mut sizes = vec![(b.observe)(&states[0]).len()];
    sizes.extend(&b.hidden);
    sizes.push(b.scale.len());
    let mut mlp = Mlp::new(&sizes, b.act, b.out_act, !b.odd, &mut rng);
    let mut norm = None;
    let mut net = None;
    for round in 0..3 {
        let obs: Vec<DVector<f64>> = states
            .iter()
            .map(|x| DVector::from_vec((b.observe)(x)))
            .collect();
        let tgt: Vec<DVector<f64>> = states.iter().map(|x| b.target(&expert(x))).collect();
        // the normalisation is fixed by the first round's data
        let nz = norm.get_or_insert_with(|| {
            let (mut in_mean, in_sd) = mean_sd(&obs);
            let (mut out_mean, out_sd) = if b.out_act.is_none() {
                mean_sd(&tgt)
            } else {
                (vec![0.0; tgt[0].len()], vec![1.0; tgt[0].len()])
            };
            if b.odd {
                // no centring: the network stays odd (the spreads only scale)
                in_mean.iter_mut().for_each(|m| *m = 0.0);
                out_mean.iter_mut().for_each(|m| *m = 0.0);
            }
            Norm {
                in_mean,
                in_sd,
                out_mean,
                out_sd,
            }
        });
        let xn: Vec<DVector<f64>> = obs
            .iter()
            .map(|o| DVector::from_fn(o.len(), |j, _| (o[j] - nz.in_mean[j]) / nz.in_sd[j]))
            .collect();
        let yn: Vec<DVector<f64>> = tgt
            .iter()
            .map(|t| DVector::from_fn(t.len(), |j, _| (t[j] - nz.out_mean[j]) / nz.out_sd[j]))
            .collect();
        let steps = if round == 0 { 6000 } else { 3000 };
        mlp.train(
            &xn,
            &yn,
            steps,
            if round == 0 { 3e-3 } else { 1e-3 },
            &mut rng,
        );
        let candidate = mlp.network(nz);
        // aggregate the states the network visits (labelled by the expert)
        let from = states.len();
        {
            let law = b.net_law(&candidate);
            for _ in 0..100 {
                let x0 = b.sample_x0(&mut rng, 0.1);
                let xs = b.simulate(&x0, &law);
                for k in 0..b.steps {
                    states.push(xs[k * b.sub].clone());
                }
            }
        }
        perturb(&mut states, from, &mut rng);
        net = Some(candidate);
    }
    let net = net.expect("trained");
    // the check: 2000 sampled initial states and the corners of X0
    let law = b.net_law(&net);
    let mut check = Rng::new(b.seed.wrapping_add(1000));
    let mut inits = b.corners();
    for _ in 0..2000 {
        inits.push(b.sample_x0(&mut check, 0.0));
    }
    let margin = inits
        .iter()
        .map(|x0| b.margin(&b.simulate(x0, &law)))
        .fold(f64::INFINITY, f64::min);
    eprintln!(
        "{}: {:?} {:?}{}, expert margin {:.4}, network margin {:.4} over {} runs{}",
        b.name,
        sizes,
        b.act,
        b.out_act
            .map(|a| format!(" ({a:?} output)"))
            .unwrap_or_default(),
        expert_margin,
        margin,
        inits.len(),
        if margin > 0.0 { "" } else { "  <-- FAILS" }
    );
    let mut g = GraphBuilder::new(net.inputs, Storage::RawF32);
    g.network(&net, false);
    let (model, _) = g.finish(net.outputs());
    fs::write(out.join(format!("{}.onnx", b.name)), model).expect("write model");
    margin
}

fn tora(x: &[f64], u: &[f64]) -> Vec<f64> {
    vec![x[1], -x[0] + 0.1 * x[2].sin(), x[3], u[0]]
}

/// The double pendulum of ARCH-COMP (m = 0.5, L = 0.5, c = 0, g = 1), in
/// the closed form of the JuliaReach model: state [θ1, θ2, θ̇1, θ̇2], torques [T1, T2].
fn double_pendulum_field(x: &[f64], t: &[f64]) -> Vec<f64> {
    let d = x[0] - x[1];
    let c = d.cos();
    let x3sin = x[2] * x[2] * d.sin();
    let x4sin = x[3] * x[3] * d.sin() / 2.0;
    let g1 = 2.0 * x[0].sin();
    let g2 = 2.0 * x[1].sin();
    let t1 = 4.0 * t[0];
    let t2 = 8.0 * t[1];
    let big = x3sin - c * (g1 - x4sin + t1) + g2 + t2;
    let den = c * c / 2.0 - 1.0;
    vec![
        x[2],
        x[3],
        c * big / (2.0 * den) - x4sin + g1 + t1,
        -big / den,
    ]
}

/// Cart-pole of ARCH-COMP 2024 ("balancing"): cart position and velocity,
/// pole angle (0 upright) and angular velocity; force f.
fn cartpole_field(x: &[f64], u: &[f64]) -> Vec<f64> {
    let a = 2.0 * u[0];
    vec![
        x[1],
        a,
        x[3],
        (0.08 * 0.41 * (9.8 * x[2].sin() - a * x[2].cos()) - 0.0021 * x[3]) / 0.0105,
    ]
}

/// The gain `K` (u = −K x) that places the poles of the cart-pole,
/// linearised at the upright position, at the roots of
/// (s² + 2ζ ω1 s + ω1²)(s² + 2ζ ω2 s + ω2²), by Ackermann's formula.
fn cartpole_gain(w1: f64, w2: f64, zeta: f64) -> [f64; 4] {
    use nalgebra::{Matrix4, RowVector4, Vector4};
    let c = 0.08 * 0.41 / 0.0105;
    #[rustfmt::skip]
    let a = Matrix4::new(
        0.0, 1.0, 0.0, 0.0,
        0.0, 0.0, 0.0, 0.0,
        0.0, 0.0, 0.0, 1.0,
        0.0, 0.0, 9.8 * c, -0.0021 / 0.0105,
    );
    let b = Vector4::new(0.0, 2.0, 0.0, -2.0 * c);
    let ctrb = Matrix4::from_columns(&[b, a * b, a * a * b, a * a * a * b]);
    // (s² + p1 s + q1)(s² + p2 s + q2) = s⁴ + c3 s³ + c2 s² + c1 s + c0
    let (p1, q1, p2, q2) = (2.0 * zeta * w1, w1 * w1, 2.0 * zeta * w2, w2 * w2);
    let (c3, c2, c1, c0) = (p1 + p2, q1 + q2 + p1 * p2, p1 * q2 + p2 * q1, q1 * q2);
    let a2 = a * a;
    let a3 = a2 * a;
    let phi = a3 * a + a3 * c3 + a2 * c2 + a * c1 + Matrix4::identity() * c0;
    let k = RowVector4::new(0.0, 0.0, 0.0, 1.0) * ctrb.try_inverse().expect("controllable") * phi;
    [k[0], k[1], k[2], k[3]]
}

/// Attitude control of a rigid body (ARCH-COMP): angular velocities ω and
/// Rodrigues parameters ψ; torques u.
fn attitude_field(x: &[f64], u: &[f64]) -> Vec<f64> {
    let (w1, w2, w3) = (x[0], x[1], x[2]);
    let (p1, p2, p3) = (x[3], x[4], x[5]);
    let s = p1 * p1 + p2 * p2 + p3 * p3;
    vec![
        0.25 * (u[0] + w2 * w3),
        0.5 * (u[1] - 3.0 * w1 * w3),
        u[2] + 2.0 * w1 * w2,
        0.5 * (w2 * (s - p3) + w3 * (s + p2) + w1 * (s + 1.0)),
        0.5 * (w1 * (s + p3) + w3 * (s - p1) + w2 * (s + 1.0)),
        0.5 * (w1 * (s - p2) + w2 * (s + p1) + w3 * (s + 1.0)),
    ]
}

/// The airplane of ARCH-COMP (m = g = 1, I = 1, I_xz = 0): state
/// [x, y, z, u, v, w, φ, θ, ψ, r, p, q], control [Fx, Fy, Fz, Mx, My, Mz].
fn airplane_field(x: &[f64], c: &[f64]) -> Vec<f64> {
    let (u, v, w) = (x[3], x[4], x[5]);
    let (ph, th, ps) = (x[6], x[7], x[8]);
    let (r, p, q) = (x[9], x[10], x[11]);
    let (sf, cf, st, ct, ss, cs) = (ph.sin(), ph.cos(), th.sin(), th.cos(), ps.sin(), ps.cos());
    vec![
        cs * ct * u + (cs * st * sf - ss * cf) * v + (cs * st * cf + ss * sf) * w,
        ss * ct * u + (ss * st * sf + cs * cf) * v + (ss * st * cf - cs * sf) * w,
        -st * u + ct * sf * v + ct * cf * w,
        -st + c[0] - q * w + r * v,
        ct * sf + c[1] - r * u + p * w,
        ct * cf + c[2] - p * v + q * u,
        p + th.tan() * (sf * q + cf * r),
        cf * q - sf * r,
        (sf * q + cf * r) / ct,
        c[5],
        c[3],
        c[4],
    ]
}

/// The quadrotor of ARCH-COMP (g = 9.81, m = 1.4, Jx = Jy = 0.054,
/// Jz = 0.104, no yaw torque): position, body velocity, Euler angles, body
/// rates; control [u1, u2, u3] (thrust g + u1/m, roll and pitch torques).
fn quad_field(x: &[f64], u: &[f64]) -> Vec<f64> {
    let (g, m, jx, jy, jz) = (9.81, 1.4, 0.054, 0.054, 0.104);
    let (sf, cf) = (x[6].sin(), x[6].cos());
    let (st, ct) = (x[7].sin(), x[7].cos());
    let (ss, cs) = (x[8].sin(), x[8].cos());
    let (vx, vy, vz) = (x[3], x[4], x[5]);
    let (p, q, r) = (x[9], x[10], x[11]);
    vec![
        ct * cs * vx + (sf * st * cs - cf * ss) * vy + (cf * st * cs + sf * ss) * vz,
        ct * ss * vx + (sf * st * ss + cf * cs) * vy + (cf * st * ss - sf * cs) * vz,
        st * vx - sf * ct * vy - cf * ct * vz,
        r * vy - q * vz - g * st,
        p * vz - r * vx + g * ct * sf,
        q * vx - p * vy + g * ct * cf - g - u[0] / m,
        p + (sf * q + cf * r) * st / ct,
        cf * q - sf * r,
        (sf * q + cf * r) / ct,
        (jy - jz) / jx * q * r + u[1] / jx,
        (jz - jx) / jy * p * r + u[2] / jy,
        (jx - jy) / jz * p * q,
    ]
}

/// Mean motion of the Clohessy–Wiltshire frame of the docking benchmark.
const DOCKING_N: f64 = 0.001027;

/// Spacecraft docking (Clohessy–Wiltshire in the plane, m = 12): position,
/// velocity; thrust [Fx, Fy].
fn docking_field(x: &[f64], u: &[f64]) -> Vec<f64> {
    let n = DOCKING_N;
    vec![
        x[2],
        x[3],
        2.0 * n * x[3] + 3.0 * n * n * x[0] + u[0] / 12.0,
        -2.0 * n * x[2] + u[1] / 12.0,
    ]
}

fn identity(x: &[f64]) -> Vec<f64> {
    x.to_vec()
}

fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(2.0 * PI) - PI
}

fn main() {
    let out = Path::new("models/bench");
    fs::create_dir_all(out).expect("create models/bench");
    let only: Vec<String> = std::env::args().skip(1).collect();
    let wanted = |name: &str| only.is_empty() || only.iter().any(|o| o == name);
    let mut jobs: Vec<(Bench, Tuner)> = Vec::new();
    let relu = Activation::Relu;

    // ReachNN B1: ẋ1 = x2, ẋ2 = u x2² − x1; 35 steps of 0.2; u = 4 tanh(net)
    let b1 = Bench {
        name: "reachnn_b1",
        f: |x, u| vec![x[1], u[0] * x[1] * x[1] - x[0]],
        dt: 0.2,
        sub: 10,
        steps: 35,
        x0: vec![(0.8, 0.9), (0.5, 0.6)],
        props: vec![Prop::Goal(vec![(0, 0.0, 0.2), (1, 0.05, 0.3)])],
        observe: identity,
        scale: vec![4.0],
        offset: vec![0.0],
        hidden: vec![20, 20],
        act: relu,
        out_act: Some(Activation::Tanh),
        seed: 11,
        odd: false,
    };
    jobs.push((
        b1,
        Box::new(|b: &Bench| {
            let fam = |x: &[f64], p: &[f64]| {
                vec![(-p[0] * (x[1] / p[2]).tanh() - p[1] * x[0]).clamp(-3.8, 3.8)]
            };
            let p = tune(
                b,
                &[
                    range(0.0, 4.0, 0.2),
                    range(-2.0, 2.0, 0.25),
                    vec![0.1, 0.3, 1.0],
                ],
                &fam,
            );
            Box::new(move |x: &[f64]| fam(x, &p))
        }),
    ));

    // ReachNN B2: ẋ1 = x2 − x1³, ẋ2 = u; 10 steps of 0.2; u = 4 tanh(net)
    let b2 = Bench {
        name: "reachnn_b2",
        f: |x, u| vec![x[1] - x[0].powi(3), u[0]],
        dt: 0.2,
        sub: 10,
        steps: 10,
        x0: vec![(0.7, 0.9), (0.7, 0.9)],
        props: vec![Prop::Goal(vec![(0, -0.3, 0.1), (1, -0.35, 0.5)])],
        observe: identity,
        scale: vec![4.0],
        offset: vec![0.0],
        hidden: vec![20, 20],
        act: relu,
        out_act: Some(Activation::Tanh),
        seed: 12,
        odd: false,
    };
    jobs.push((
        b2,
        Box::new(|b: &Bench| {
            let fam = |x: &[f64], p: &[f64]| vec![(-p[0] * x[0] - p[1] * x[1]).clamp(-3.8, 3.8)];
            let p = tune(b, &[range(0.5, 10.0, 0.5), range(0.5, 6.0, 0.25)], &fam);
            Box::new(move |x: &[f64]| fam(x, &p))
        }),
    ));

    // ReachNN B3: 60 steps of 0.1; u = 4 sigmoid(net) − 2
    let b3 = Bench {
        name: "reachnn_b3",
        f: |x, u| {
            let s = 0.1 + (x[0] + x[1]).powi(2);
            vec![-x[0] * s, (u[0] + x[0]) * s]
        },
        dt: 0.1,
        sub: 10,
        steps: 60,
        x0: vec![(0.8, 0.9), (0.4, 0.5)],
        props: vec![Prop::Goal(vec![(0, 0.2, 0.3), (1, -0.3, -0.05)])],
        observe: identity,
        scale: vec![4.0],
        offset: vec![-2.0],
        hidden: vec![20, 20],
        act: relu,
        out_act: Some(Activation::Sigmoid),
        seed: 13,
        odd: false,
    };
    jobs.push((
        b3,
        Box::new(|b: &Bench| {
            // feedback linearisation of x2 towards a constant p1
            let fam = |x: &[f64], p: &[f64]| {
                let s = 0.1 + (x[0] + x[1]).powi(2);
                vec![(-x[0] - p[0] * (x[1] - p[1]) / s).clamp(-1.9, 1.9)]
            };
            let p = tune(
                b,
                &[vec![0.25, 0.5, 1.0, 2.0, 4.0], range(-0.4, 0.1, 0.02)],
                &fam,
            );
            Box::new(move |x: &[f64]| fam(x, &p))
        }),
    ));

    // ReachNN B4: 10 steps of 0.1; u = 10 tanh(net)
    let b4 = Bench {
        name: "reachnn_b4",
        f: |x, u| {
            vec![
                -x[0] + x[1] - x[2],
                -x[0] * (x[2] + 1.0) - x[1],
                -x[0] + u[0],
            ]
        },
        dt: 0.1,
        sub: 10,
        steps: 10,
        x0: vec![(0.25, 0.27), (0.08, 0.1), (0.25, 0.27)],
        props: vec![Prop::Goal(vec![(0, -0.2, -0.1), (1, 0.0, 0.05)])],
        observe: identity,
        scale: vec![10.0],
        offset: vec![0.0],
        hidden: vec![20, 20],
        act: relu,
        out_act: Some(Activation::Tanh),
        seed: 14,
        odd: false,
    };
    jobs.push((
        b4,
        Box::new(|b: &Bench| {
            // x3 driven towards p1 + p2 x1 (feedback linearised)
            let fam = |x: &[f64], p: &[f64]| {
                vec![(x[0] - p[0] * (x[2] - p[1] - p[2] * x[0])).clamp(-9.5, 9.5)]
            };
            let p = tune(
                b,
                &[
                    vec![1.0, 2.0, 4.0, 8.0, 16.0],
                    range(-1.0, 2.0, 0.1),
                    range(-4.0, 4.0, 0.5),
                ],
                &fam,
            );
            Box::new(move |x: &[f64]| fam(x, &p))
        }),
    ));

    // ReachNN B5 (POLAR's sign: ẋ1 = x3³ − x2): 10 steps of 0.2; u = 11 tanh(net)
    let b5 = Bench {
        name: "reachnn_b5",
        f: |x, u| vec![x[2].powi(3) - x[1], x[2], u[0]],
        dt: 0.2,
        sub: 10,
        steps: 10,
        x0: vec![(0.38, 0.4), (0.45, 0.47), (0.25, 0.27)],
        props: vec![Prop::Goal(vec![(0, -0.43, -0.15), (1, 0.05, 0.22)])],
        observe: identity,
        scale: vec![11.0],
        offset: vec![0.0],
        hidden: vec![20, 20, 20],
        act: relu,
        out_act: Some(Activation::Tanh),
        seed: 15,
        odd: false,
    };
    jobs.push((
        b5,
        Box::new(|b: &Bench| {
            // cascade: x3 tracks −p1 (x2 − p2)
            let fam = |x: &[f64], p: &[f64]| {
                vec![(-p[0] * (x[2] + p[1] * (x[1] - p[2]))).clamp(-10.5, 10.5)]
            };
            let p = tune(
                b,
                &[
                    vec![1.0, 2.0, 4.0, 8.0],
                    vec![0.25, 0.5, 1.0, 2.0, 4.0],
                    range(-0.2, 0.4, 0.02),
                ],
                &fam,
            );
            Box::new(move |x: &[f64]| fam(x, &p))
        }),
    ));

    // TORA, the heterogeneous setting (ReachNN B6 / ARCH-COMP): 10 steps of 0.5
    let tora_het = |name: &'static str,
                    act: Activation,
                    out_act: Activation,
                    scale: f64,
                    offset: f64,
                    seed: u64| Bench {
        name,
        f: tora,
        dt: 0.5,
        sub: 10,
        steps: 10,
        x0: vec![(-0.77, -0.75), (-0.45, -0.43), (0.51, 0.54), (-0.3, -0.28)],
        props: vec![Prop::Goal(vec![(0, -0.1, 0.2), (1, -0.9, -0.6)])],
        observe: identity,
        scale: vec![scale],
        offset: vec![offset],
        hidden: vec![20, 20, 20],
        act,
        out_act: Some(out_act),
        seed,
        odd: false,
    };
    fn tora_expert(b: &Bench) -> Expert {
        let fam =
            |x: &[f64], p: &[f64]| vec![(-p[0] * (x[2] - p[2]) - p[1] * x[3]).clamp(-10.5, 10.5)];
        let p = tune(
            b,
            &[
                vec![0.25, 0.5, 1.0, 2.0, 4.0],
                vec![0.5, 1.0, 2.0, 4.0],
                range(-3.0, 1.5, 0.05),
            ],
            &fam,
        );
        Box::new(move |x: &[f64]| fam(x, &p))
    }
    jobs.push((
        tora_het("tora_relu_tanh", relu, Activation::Tanh, 11.0, 0.0, 16),
        Box::new(tora_expert),
    ));
    jobs.push((
        tora_het(
            "tora_sigmoid",
            Activation::Sigmoid,
            Activation::Sigmoid,
            22.0,
            -11.0,
            17,
        ),
        Box::new(tora_expert),
    ));

    // TORA (ARCH-COMP benchmark 9): 20 steps of 1, stay in [−2, 2]⁴ throughout; u = net − 10
    let tora_relu = Bench {
        name: "tora_relu",
        f: tora,
        dt: 1.0,
        sub: 20,
        steps: 20,
        x0: vec![(0.6, 0.7), (-0.7, -0.6), (-0.4, -0.3), (0.5, 0.6)],
        props: vec![Prop::Always(
            vec![
                (0, -2.0, 2.0),
                (1, -2.0, 2.0),
                (2, -2.0, 2.0),
                (3, -2.0, 2.0),
            ],
            0,
            20,
        )],
        observe: identity,
        scale: vec![1.0],
        offset: vec![-10.0],
        hidden: vec![20, 20, 20],
        act: relu,
        out_act: None,
        seed: 18,
        odd: false,
    };
    jobs.push((
        tora_relu,
        Box::new(|b: &Bench| {
            let fam = |x: &[f64], p: &[f64]| {
                vec![(-p[0] * x[2] - p[1] * x[3] + p[2] * x[1]).clamp(-9.5, 9.5)]
            };
            let p = tune(
                b,
                &[
                    range(0.05, 0.95, 0.1),
                    range(0.1, 1.9, 0.2),
                    vec![-0.25, 0.0, 0.25],
                ],
                &fam,
            );
            Box::new(move |x: &[f64]| fam(x, &p))
        }),
    ));

    // ACC (ARCH-COMP): 50 steps of 0.1; inputs [30, 1.4, v_ego, D_rel, v_rel]; u = net
    let acc = Bench {
        name: "acc",
        f: |x, u| {
            let mu = 0.0001;
            vec![
                x[1],
                x[2],
                -2.0 * x[2] + 2.0 * -2.0 - mu * x[1] * x[1],
                x[4],
                x[5],
                -2.0 * x[5] + 2.0 * u[0] - mu * x[4] * x[4],
            ]
        },
        dt: 0.1,
        sub: 10,
        steps: 50,
        x0: vec![
            (90.0, 110.0),
            (32.0, 32.2),
            (0.0, 0.0),
            (10.0, 11.0),
            (30.0, 30.2),
            (0.0, 0.0),
        ],
        // D_rel − T_gap v_ego − D_default ≥ 0 at all times
        props: vec![Prop::AlwaysLinear(
            vec![1.0, 0.0, 0.0, -1.0, -1.4, 0.0],
            -10.0,
        )],
        observe: |x| vec![30.0, 1.4, x[4], x[0] - x[3], x[1] - x[4]],
        scale: vec![1.0],
        offset: vec![0.0],
        hidden: vec![20, 20, 20],
        act: relu,
        out_act: None,
        seed: 19,
        odd: false,
    };
    jobs.push((
        acc,
        Box::new(|b: &Bench| {
            let fam = |x: &[f64], p: &[f64]| {
                let gap = x[0] - x[3] - 1.4 * x[4] - 10.0;
                vec![
                    (p[0] * (gap - p[2]) + p[1] * (x[1] - x[4]) - 0.2 * (x[4] - 30.0))
                        .clamp(-5.0, 3.0),
                ]
            };
            let p = tune(
                b,
                &[
                    vec![0.02, 0.05, 0.1, 0.2, 0.5],
                    vec![0.1, 0.25, 0.5, 1.0, 2.0],
                    vec![0.0, 5.0, 10.0, 20.0],
                ],
                &fam,
            );
            Box::new(move |x: &[f64]| fam(x, &p))
        }),
    ));

    // single pendulum (ARCH-COMP): 20 steps of 0.05, θ ∈ [0, 1] for t ∈ [0.5, 1]; u = net
    let pendulum = Bench {
        name: "single_pendulum",
        f: |x, u| vec![x[1], 2.0 * x[0].sin() + 8.0 * u[0]],
        dt: 0.05,
        sub: 10,
        steps: 20,
        x0: vec![(1.0, 1.2), (0.0, 0.2)],
        props: vec![Prop::Always(vec![(0, 0.0, 1.0)], 10, 20)],
        observe: identity,
        scale: vec![1.0],
        offset: vec![0.0],
        hidden: vec![25, 25],
        act: relu,
        out_act: None,
        seed: 20,
        odd: false,
    };
    jobs.push((
        pendulum,
        Box::new(|b: &Bench| {
            // feedback linearisation towards θ = p2
            let fam = |x: &[f64], p: &[f64]| {
                vec![(-2.0 * x[0].sin() - p[0] * (x[0] - p[2]) - p[1] * x[1]) / 8.0]
            };
            let p = tune(
                b,
                &[
                    vec![4.0, 9.0, 16.0, 25.0, 36.0, 64.0],
                    vec![2.0, 4.0, 6.0, 8.0, 10.0, 12.0],
                    vec![0.4, 0.5, 0.6],
                ],
                &fam,
            );
            Box::new(move |x: &[f64]| fam(x, &p))
        }),
    ));

    // double pendulum (ARCH-COMP 2020–2022): every state in a box over 20
    // steps; the less robust setting has period 0.05 and the box
    // [−1, 1.7], the more robust one period 0.02 and [−0.5, 1.5]; T = net
    let double_pendulum = |name: &'static str, dt: f64, lo: f64, hi: f64, seed: u64| Bench {
        name,
        f: double_pendulum_field,
        dt,
        sub: 10,
        steps: 20,
        x0: vec![(1.0, 1.3); 4],
        props: vec![Prop::Always(
            vec![(0, lo, hi), (1, lo, hi), (2, lo, hi), (3, lo, hi)],
            0,
            20,
        )],
        observe: identity,
        scale: vec![1.0, 1.0],
        offset: vec![0.0, 0.0],
        hidden: vec![25, 25],
        act: relu,
        out_act: None,
        seed,
        odd: false,
    };
    fn double_pendulum_expert(b: &Bench) -> Expert {
        // computed torque: the accelerations are affine in the torques, so
        // a(x, T) = a0(x) + M(x) T is read off the vector field itself and
        // inverted for the wanted accelerations −kp (θ − r) − kd θ̇
        let fam = |x: &[f64], p: &[f64]| {
            let a0 = double_pendulum_field(x, &[0.0, 0.0]);
            let a1 = double_pendulum_field(x, &[1.0, 0.0]);
            let a2 = double_pendulum_field(x, &[0.0, 1.0]);
            let m =
                nalgebra::Matrix2::new(a1[2] - a0[2], a2[2] - a0[2], a1[3] - a0[3], a2[3] - a0[3]);
            let want = nalgebra::Vector2::new(
                -p[0] * (x[0] - p[2]) - p[1] * x[2] - a0[2],
                -p[0] * (x[1] - p[2]) - p[1] * x[3] - a0[3],
            );
            let t = m
                .try_inverse()
                .map_or(nalgebra::Vector2::zeros(), |mi| mi * want);
            vec![t[0], t[1]]
        };
        let p = tune(
            b,
            &[
                vec![0.0, 1.0, 4.0, 9.0, 16.0],
                vec![2.0, 5.0, 10.0, 20.0],
                range(0.8, 1.5, 0.05),
            ],
            &fam,
        );
        Box::new(move |x: &[f64]| fam(x, &p))
    }
    jobs.push((
        double_pendulum("double_pendulum_less_robust", 0.05, -1.0, 1.7, 22),
        Box::new(double_pendulum_expert),
    ));
    jobs.push((
        double_pendulum("double_pendulum_more_robust", 0.02, -0.5, 1.5, 23),
        Box::new(double_pendulum_expert),
    ));

    // NAV (ARCH-COMP 2023–2024): 30 steps of 0.2; reach [−0.5, 0.5]² at
    // t = 6, never touch the obstacle [1, 2]²; u = tanh output, unscaled
    let nav = Bench {
        name: "nav",
        f: |x, u| vec![x[2] * x[3].cos(), x[2] * x[3].sin(), u[0], u[1]],
        dt: 0.2,
        sub: 10,
        steps: 30,
        x0: vec![(2.9, 3.1), (2.9, 3.1), (0.0, 0.0), (0.0, 0.0)],
        props: vec![
            Prop::Goal(vec![(0, -0.5, 0.5), (1, -0.5, 0.5)]),
            Prop::AlwaysOutside(vec![(0, 1.0, 2.0), (1, 1.0, 2.0)]),
        ],
        observe: identity,
        scale: vec![1.0, 1.0],
        offset: vec![0.0, 0.0],
        hidden: vec![64, 32],
        act: relu,
        out_act: Some(Activation::Tanh),
        seed: 24,
        odd: false,
    };
    jobs.push((
        nav,
        Box::new(|b: &Bench| {
            // head for a waypoint right of the obstacle while high, for the
            // origin once low (blended over y ∈ [p1, p1 + 0.6]); the speed
            // is capped at p2 and slowed by the heading error
            let fam = |x: &[f64], p: &[f64]| {
                let s = ((x[1] - p[1]) / 0.6).clamp(0.0, 1.0);
                let (tx, ty) = (s * p[0], s * 0.4);
                let dist = x[0].hypot(x[1]);
                let err = wrap((ty - x[1]).atan2(tx - x[0]) - x[3]);
                let v = (p[2].min(p[4] * dist)) * err.cos().max(0.0);
                vec![
                    (2.0 * (v - x[2])).clamp(-0.95, 0.95),
                    (p[3] * err).clamp(-0.95, 0.95),
                ]
            };
            let p = tune(
                b,
                &[
                    vec![2.4, 2.6, 2.8],
                    vec![0.2, 0.5, 0.8, 1.1],
                    vec![1.0, 1.3, 1.6, 2.0],
                    vec![2.0, 4.0],
                    vec![0.5, 1.0, 2.0],
                ],
                &fam,
            );
            Box::new(move |x: &[f64]| fam(x, &p))
        }),
    ));

    // unicycle (ARCH-COMP benchmark 10): 50 steps of 0.2; u_i = net_i − 20
    let unicycle = Bench {
        name: "unicycle",
        f: |x, u| vec![x[3] * x[2].cos(), x[3] * x[2].sin(), u[1], u[0]],
        dt: 0.2,
        sub: 10,
        steps: 50,
        x0: vec![(9.5, 9.55), (-4.5, -4.45), (2.1, 2.11), (1.5, 1.51)],
        props: vec![Prop::Goal(vec![
            (0, -0.6, 0.6),
            (1, -0.2, 0.2),
            (2, -0.06, 0.06),
            (3, -0.3, 0.3),
        ])],
        observe: identity,
        scale: vec![1.0, 1.0],
        offset: vec![-20.0, -20.0],
        hidden: vec![32, 32],
        act: relu,
        out_act: None,
        seed: 21,
        odd: false,
    };
    jobs.push((
        unicycle,
        Box::new(|b: &Bench| {
            // a polar parking law (ρ, α, β) with the speed tracked by the
            // acceleration; within ρ < p4 of the target its turn rate fades into
            // a plain heading regulator (the polar angles are discontinuous at ρ = 0)
            let fam = |x: &[f64], p: &[f64]| {
                let rho = x[0].hypot(x[1]);
                let alpha = wrap((-x[1]).atan2(-x[0]) - x[2]);
                let beta = wrap(-x[2] - alpha);
                let v = p[0] * rho;
                let s = (rho / p[4]).min(1.0);
                let w = s * (p[1] * alpha + p[2] * beta) - (1.0 - s) * 2.0 * x[2];
                vec![(p[3] * (v - x[3])).clamp(-10.0, 10.0), w.clamp(-10.0, 10.0)]
            };
            let p = tune(
                b,
                &[
                    vec![0.3, 0.4, 0.5, 0.7, 1.0],
                    vec![1.0, 1.5, 2.0, 3.0, 4.0],
                    vec![-0.1, -0.3, -0.6, -1.0, -1.5],
                    vec![2.0, 5.0],
                    vec![0.5, 1.0, 2.0],
                ],
                &fam,
            );
            Box::new(move |x: &[f64]| fam(x, &p))
        }),
    ));

    // cart-pole ("balancing", ARCH-COMP 2024): 500 steps of 0.02; x1, x3,
    // x4 ∈ [−0.001, 0.001] for t ∈ [8, 10]; u = tanh output, unscaled
    let cartpole = Bench {
        name: "cartpole",
        f: cartpole_field,
        dt: 0.02,
        sub: 2,
        steps: 500,
        x0: vec![(-0.1, 0.1), (-0.05, 0.05), (-0.1, 0.1), (-0.05, 0.05)],
        props: vec![Prop::Always(
            vec![(0, -0.001, 0.001), (2, -0.001, 0.001), (3, -0.001, 0.001)],
            400,
            500,
        )],
        observe: identity,
        scale: vec![1.0],
        offset: vec![0.0],
        hidden: vec![32, 32],
        act: Activation::Tanh,
        out_act: Some(Activation::Tanh),
        seed: 25,
        odd: true,
    };
    jobs.push((
        cartpole,
        Box::new(|b: &Bench| {
            // linear state feedback placing the poles of the plant linearised
            // at the upright position at the roots of
            // (s² + 2ζ ω1 s + ω1²)(s² + 2ζ ω2 s + ω2²) (Ackermann's formula)
            let fam = |x: &[f64], p: &[f64]| {
                let k = cartpole_gain(p[0], p[1], p[2]);
                vec![(-(0..4).map(|i| k[i] * x[i]).sum::<f64>()).clamp(-0.95, 0.95)]
            };
            let p = tune(
                b,
                // slow enough that |u| stays below 0.9 on X0 (no saturation
                // of the tanh output); on ties the first candidate wins
                &[vec![2.0, 1.5], vec![2.0, 2.5], vec![0.7, 0.85]],
                &fam,
            );
            let k = cartpole_gain(p[0], p[1], p[2]);
            eprintln!("cartpole: gain {k:?}");
            Box::new(move |x: &[f64]| {
                vec![(-(0..4).map(|i| k[i] * x[i]).sum::<f64>()).clamp(-0.95, 0.95)]
            })
        }),
    ));

    // attitude control (ARCH-COMP 2020–2024): 30 steps of 0.1; always avoid
    // a box of angular velocities and Rodrigues parameters; u = net
    let attitude = Bench {
        name: "attitude",
        f: attitude_field,
        dt: 0.1,
        sub: 10,
        steps: 30,
        x0: vec![
            (-0.45, -0.44),
            (-0.55, -0.54),
            (0.65, 0.66),
            (-0.75, -0.74),
            (0.85, 0.86),
            (-0.65, -0.64),
        ],
        props: vec![Prop::AlwaysOutside(vec![
            (0, -0.2, 0.0),
            (1, -0.5, -0.4),
            (2, 0.0, 0.2),
            (3, -0.7, -0.6),
            (4, 0.7, 0.8),
            (5, -0.4, -0.2),
        ])],
        observe: identity,
        scale: vec![1.0; 3],
        offset: vec![0.0; 3],
        hidden: vec![32, 32],
        act: Activation::Tanh,
        out_act: None,
        seed: 26,
        odd: false,
    };
    jobs.push((
        attitude,
        Box::new(|b: &Bench| {
            // each angular velocity driven towards −p2 ψ_i at the rate p1
            let fam = |x: &[f64], p: &[f64]| {
                (0..3)
                    .map(|i| -p[0] * (x[i] + p[1] * x[3 + i]))
                    .collect::<Vec<f64>>()
            };
            let p = tune(
                b,
                &[
                    vec![0.25, 0.5, 1.0, 2.0, 4.0, 8.0],
                    vec![0.0, 0.25, 0.5, 1.0, 2.0],
                ],
                &fam,
            );
            Box::new(move |x: &[f64]| fam(x, &p))
        }),
    ));

    // airplane (ARCH-COMP 2020–2024): 20 steps of 0.1; always y ∈ [−0.5, 0.5]
    // and φ, θ, ψ ∈ [−1, 1] (the angles from the first sampling instant on
    // here: X0 has φ = θ = ψ = 1 on its faces; the spec covers the first
    // period separately); u = net
    let airplane = Bench {
        name: "airplane",
        f: airplane_field,
        dt: 0.1,
        sub: 10,
        steps: 20,
        x0: vec![
            (0.0, 0.0),
            (0.0, 0.0),
            (0.0, 0.0),
            (0.0, 1.0),
            (0.0, 1.0),
            (0.0, 1.0),
            (0.0, 1.0),
            (0.0, 1.0),
            (0.0, 1.0),
            (0.0, 0.0),
            (0.0, 0.0),
            (0.0, 0.0),
        ],
        props: vec![
            Prop::Always(vec![(1, -0.5, 0.5)], 0, 20),
            Prop::Always(vec![(6, -1.0, 1.0), (7, -1.0, 1.0), (8, -1.0, 1.0)], 1, 20),
        ],
        observe: identity,
        scale: vec![1.0; 6],
        offset: vec![0.0; 6],
        hidden: vec![32, 32],
        act: Activation::Tanh,
        out_act: None,
        seed: 27,
        odd: false,
    };
    jobs.push((
        airplane,
        Box::new(|b: &Bench| {
            // forces: gravity compensated to first order, the body
            // velocities damped at the rate p1, y pulled back with p2;
            // moments: the body rates track −p3 times the Euler angles,
            // mapped through the kinematics (p5 = 1) or not (p5 = 0), at the rate p4
            let fam = |x: &[f64], p: &[f64]| {
                let (ph, th, ps) = (x[6], x[7], x[8]);
                let (dph, dth, dps) = (-p[2] * ph, -p[2] * th, -p[2] * ps);
                let (pd, qd, rd) = if p[4] > 0.5 {
                    (
                        dph - th.sin() * dps,
                        ph.cos() * dth + ph.sin() * th.cos() * dps,
                        -ph.sin() * dth + ph.cos() * th.cos() * dps,
                    )
                } else {
                    (dph, dth, dps)
                };
                vec![
                    th - p[0] * x[3],
                    -ph - p[0] * x[4] - p[1] * x[1],
                    -1.0 - p[0] * x[5],
                    p[3] * (pd - x[10]),
                    p[3] * (qd - x[11]),
                    p[3] * (rd - x[9]),
                ]
            };
            let p = tune(
                b,
                &[
                    vec![2.0, 4.0, 8.0],
                    vec![0.0, 2.0, 5.0],
                    vec![1.0, 2.0, 4.0],
                    vec![4.0, 8.0, 16.0],
                    vec![0.0, 1.0],
                ],
                &fam,
            );
            Box::new(move |x: &[f64]| fam(x, &p))
        }),
    ));

    // QUAD (ARCH-COMP 2019–2024): 50 steps of 0.1; altitude x3 ∈ [0.94, 1.06] at t = 5; u = net
    let quad = Bench {
        name: "quad",
        f: quad_field,
        dt: 0.1,
        sub: 10,
        steps: 50,
        x0: (0..12)
            .map(|i| if i < 6 { (-0.4, 0.4) } else { (0.0, 0.0) })
            .collect(),
        props: vec![Prop::Goal(vec![(2, 0.94, 1.06)])],
        observe: identity,
        scale: vec![1.0; 3],
        offset: vec![0.0; 3],
        hidden: vec![32, 32],
        act: Activation::Tanh,
        out_act: None,
        seed: 28,
        odd: false,
    };
    jobs.push((
        quad,
        Box::new(|b: &Bench| {
            // altitude: a PD law towards x3 = 1 (ẍ3 ≈ u1/m); attitude: PD
            // laws on roll and pitch towards 0
            let fam = |x: &[f64], p: &[f64]| {
                vec![
                    1.4 * (p[0] * (1.0 - x[2]) + p[1] * x[5]),
                    0.054 * (-p[2] * x[6] - p[3] * x[9]),
                    0.054 * (-p[2] * x[7] - p[3] * x[10]),
                ]
            };
            let p = tune(
                b,
                &[
                    vec![1.0, 2.0, 4.0, 6.0],
                    vec![1.5, 2.5, 4.0, 6.0],
                    vec![4.0, 16.0],
                    vec![4.0, 8.0],
                ],
                &fam,
            );
            Box::new(move |x: &[f64]| fam(x, &p))
        }),
    ));

    // spacecraft docking (ARCH-COMP 2022–2024): 40 steps of 1; always
    // ‖v‖ ≤ 0.2 + 2n‖p‖, here its linear strengthening
    // |v_i| ≤ 0.2/√2 + n (x + y) (see benchmarks/docking.ravel); F = tanh output, unscaled
    let docking = Bench {
        name: "docking",
        f: docking_field,
        dt: 1.0,
        sub: 10,
        steps: 40,
        x0: vec![(70.0, 106.0), (70.0, 106.0), (-0.28, 0.28), (-0.28, 0.28)],
        props: [(2, 1.0), (2, -1.0), (3, 1.0), (3, -1.0)]
            .iter()
            .map(|&(i, s)| {
                let mut a = vec![DOCKING_N, DOCKING_N, 0.0, 0.0];
                a[i] = -s;
                Prop::AlwaysLinear(a, 0.2 / 2f64.sqrt())
            })
            .collect(),
        observe: identity,
        scale: vec![1.0; 2],
        offset: vec![0.0; 2],
        hidden: vec![32, 32],
        act: Activation::Tanh,
        out_act: Some(Activation::Tanh),
        seed: 29,
        odd: false,
    };
    jobs.push((
        docking,
        Box::new(|b: &Bench| {
            // the CW coupling cancelled, the velocity driven towards −p2 · position at the rate p1
            let fam = |x: &[f64], p: &[f64]| {
                let n = DOCKING_N;
                vec![
                    (12.0 * (-3.0 * n * n * x[0] - 2.0 * n * x[3] - p[0] * (x[2] + p[1] * x[0])))
                        .clamp(-0.95, 0.95),
                    (12.0 * (2.0 * n * x[2] - p[0] * (x[3] + p[1] * x[1]))).clamp(-0.95, 0.95),
                ]
            };
            let p = tune(
                b,
                // fast damping (|F| < 0.95 needs p1 ≤ 0.28 at X0's speeds);
                // on ties the first candidate wins
                &[vec![0.2, 0.25, 0.1], vec![0.0005, 0.0, 0.001]],
                &fam,
            );
            Box::new(move |x: &[f64]| fam(x, &p))
        }),
    ));

    // two workers (the benchmarks are independent and each has its own seed)
    let jobs: Vec<(Bench, Tuner)> = jobs.into_iter().filter(|(b, _)| wanted(b.name)).collect();
    let next = AtomicUsize::new(0);
    let failed = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| {
                while let Some((b, tuner)) = jobs.get(next.fetch_add(1, Ordering::Relaxed)) {
                    let start = std::time::Instant::now();
                    let expert = tuner(b);
                    let margin = build(b, &*expert, out);
                    eprintln!("{}: done in {:.1?}", b.name, start.elapsed());
                    if margin <= 0.0 {
                        failed.lock().expect("not poisoned").push(b.name);
                    }
                }
            });
        }
    });
    let failed = failed.into_inner().expect("not poisoned");
    if failed.is_empty() {
        eprintln!("models written under {}", out.display());
    } else {
        eprintln!("the network misses its property on: {failed:?}");
        std::process::exit(1);
    }
}
