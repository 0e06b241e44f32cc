//! Profiling helper: CROWN output bounds of a random `6 → w → w → 3` ReLU
//! network over one box, many times (`cargo run --release --example crown_width -- 32`).
#[path = "../benches/common/mod.rs"]
mod common;

use ravel::analysis::crown::{Analysis, Mode};
use ravel::rng::Rng;
use ravel::sets::IBox;

fn main() {
    let w: usize = std::env::args()
        .nth(1)
        .map_or(32, |a| a.parse().expect("a width"));
    let mut rng = Rng::new(5);
    let widths = [6, w, w, 3];
    let net = common::random_relu(&mut rng, &widths);
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
