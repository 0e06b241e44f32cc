//! Benchmark of the closed-loop propagators (`cargo bench`).
//!
//! For each spec and method it times the reachability analysis alone (all
//! cells through the horizon, no Monte Carlo), repeated until at least 0.3 s
//! have passed, and prints the mean time per analysis and the tutorial's
//! final-step error (reachable-box volume over sampled-hull volume, minus 1).

use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use ravel::analysis::closed_loop::Propagator;
use ravel::execute::{execute, propagate_cell};

fn read(p: &Path) -> Result<Vec<u8>, String> {
    std::fs::read(p).map_err(|e| e.to_string())
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    println!(
        "{:<34} {:<16} {:>6} {:>14} {:>12}",
        "spec", "method", "cells", "time/analysis", "final error"
    );
    for (spec, grids) in [
        (
            "specs/double_integrator.ravel",
            vec![vec![1, 1], vec![4, 4]],
        ),
        (
            "specs/quadrotor.ravel",
            vec![vec![1; 6], vec![2, 2, 1, 1, 1, 1]],
        ),
    ] {
        let path = root.join(spec);
        let source = std::fs::read_to_string(&path).expect("spec");
        let mut checked =
            ravel::front_end(&source, path.parent().expect("dir"), &read).expect("valid spec");
        for prop in [
            Propagator::ReachLp,
            Propagator::CrownSeparate,
            Propagator::IbpSeparate,
        ] {
            for grid in &grids {
                checked.propagator = prop;
                checked.partitioner = ravel::lower::Partitioner::Uniform(grid.clone());
                checked.samples = 2000;
                let plan = ravel::lower::lower(&checked);
                let outcome = execute(&plan, &|| 0.0);
                let cells = plan.initial.grid(grid);
                let error = ravel::report::final_error(&outcome).unwrap_or(f64::NAN);
                let mut runs = 0u32;
                let start = Instant::now();
                while start.elapsed().as_secs_f64() < 0.3 {
                    for cell in &cells {
                        black_box(propagate_cell(&plan, black_box(cell), None));
                    }
                    runs += 1;
                }
                let per = start.elapsed().as_secs_f64() / runs as f64;
                let time = if per < 1e-3 {
                    format!("{:.1} µs", per * 1e6)
                } else {
                    format!("{:.2} ms", per * 1e3)
                };
                println!(
                    "{:<34} {:<16} {:>6} {:>14} {:>12.1}",
                    spec,
                    prop.name(),
                    cells.len(),
                    time,
                    error
                );
            }
        }
    }
}
