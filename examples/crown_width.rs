//! Profiling helper: CROWN output bounds of a random `6 → w → w → 3` ReLU
//! network over one box, many times (`cargo run --release --example crown_width -- 32`);
//! `BATCH=1`: the batched CROWN of 256 cells of that box instead (`CELLS=k`: the first k).
#[path = "../benches/common/mod.rs"]
mod common;

use ravel_analysis::crown::{Mode, Relaxation};
use ravel_analysis::sets::IBox;
use ravel_base::rng::Rng;

fn main() {
    let w: usize = std::env::args()
        .nth(1)
        .map_or(32, |a| a.parse().expect("a width"));
    let mut rng = Rng::new(5);
    let widths = [6, w, w, 3];
    let net = common::random_relu(&mut rng, &widths);
    let input = IBox::new(vec![-0.5; 6], vec![0.5; 6]);
    if std::env::var_os("BATCH").is_some() {
        let k: usize = std::env::var("CELLS")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(256);
        let cells: Vec<IBox> = input
            .grid(&[4, 4, 4, 4, 1, 1])
            .into_iter()
            .take(k)
            .collect();
        let dirs = nalgebra::DMatrix::from_fn(6, 3, |r, c| {
            if r % 3 != c {
                0.0
            } else if r < 3 {
                1.0
            } else {
                -1.0
            }
        });
        // the best of ten runs (the first ones touch fresh pages)
        let mut best = f64::INFINITY;
        for _ in 0..10 {
            let t = std::time::Instant::now();
            std::hint::black_box(ravel_analysis::batch::crown_offsets(
                &net,
                &cells,
                &dirs,
                Mode::Crown,
            ));
            best = best.min(t.elapsed().as_secs_f64());
        }
        eprintln!(
            "{:.3} ms per batch of {} cells (best of 10)",
            best * 1e3,
            cells.len()
        );
        return;
    }
    let reps = (2_000_000 / (w * w)).max(10);
    let t = std::time::Instant::now();
    for _ in 0..reps {
        let a = Relaxation::new(&net, &input, Mode::Crown);
        std::hint::black_box(a.output_box(Mode::Crown));
    }
    eprintln!(
        "{:.2} µs per analysis",
        t.elapsed().as_secs_f64() * 1e6 / reps as f64
    );
}
