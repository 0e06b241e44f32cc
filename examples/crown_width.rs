//! Profiling helper: CROWN output bounds of a random `6 → w → w → 3` ReLU
//! network over one box, many times (`cargo run --release --example crown_width -- 32`).
use nalgebra::{DMatrix, DVector};
use ravel::analysis::crown::{Analysis, Mode};
use ravel::nn::{Activation, Layer, Network};
use ravel::rng::Rng;
use ravel::sets::IBox;

fn main() {
    let w: usize = std::env::args()
        .nth(1)
        .map_or(32, |a| a.parse().expect("a width"));
    let mut rng = Rng::new(5);
    let widths = [6, w, w, 3];
    let mut layers = Vec::new();
    for (k, p) in widths.windows(2).enumerate() {
        let s = 1.5 / (p[0] as f64).sqrt();
        layers.push(Layer::Affine {
            w: DMatrix::from_fn(p[1], p[0], |_, _| rng.uniform(-s, s)),
            b: DVector::from_fn(p[1], |_, _| rng.uniform(-0.2, 0.2)),
        });
        if k + 2 < widths.len() {
            layers.push(Layer::Act(Activation::Relu));
        }
    }
    let net = Network::new(6, layers);
    let input = IBox::new(vec![-0.5; 6], vec![0.5; 6]);
    let reps = (2_000_000 / (w * w)).max(3);
    let t = std::time::Instant::now();
    for _ in 0..reps {
        let a = Analysis::new(&net, &input, Mode::Crown);
        std::hint::black_box(a.output_box(Mode::Crown));
    }
    eprintln!(
        "{:.2} µs per analysis",
        t.elapsed().as_secs_f64() * 1e6 / reps as f64
    );
}
