//! The tutorial's Table II, reproduced with ravel (`cargo bench`).
//!
//! For the double integrator and the quadrotor specs, every closed-loop
//! method is run through the whole horizon by [`execute`], the same entry the
//! CLI uses, and the table prints
//!
//! * the runtime of one analysis (the median and, in parentheses, the
//!   fastest of repeated runs, at least three, until a second has passed;
//!   the fastest is the least disturbed by other work): the reachability
//!   analysis of all cells, without Monte Carlo falsification (`samples 0`),
//!   except for the simulation-guided methods and the hull boundary, whose
//!   samples (1000) are part of the method and are timed with it;
//! * the tutorial's final-step error: the volume of the reachable box at the
//!   last step over the volume of the bounding box of 10 000 simulated
//!   trajectories (fixed seed), minus one.
//!
//! Reach-SDP on the quadrotor is left out unless `--slow` is given: its
//! 83-dimensional semidefinite programs take about two minutes per step with
//! Clarabel (see the README). A run longer than ten seconds is not repeated.
//!
//! Pass a substring of a method name to run only the matching rows, e.g.
//! `cargo bench --bench reach -- LP`.

mod common;

use std::path::Path;
use std::time::Instant;

use ravel::execute::{execute_system, Control};
use ravel::lower::{lower_system, Partitioner};
use ravel_analysis::closed_loop::{Boundary, Propagator};

/// One row of the table: a name, a propagator, a partitioner and the samples
/// the method itself needs (0 unless simulation-guided).
struct Method {
    name: &'static str,
    propagator: Propagator,
    partitioner: Partitioner,
    samples: usize,
    boundary: Boundary,
}

fn uniform(grid: &[usize]) -> Partitioner {
    Partitioner::Uniform(grid.to_vec())
}

/// `sdp`: add Reach-SDP; `sdp_cells`: and Reach-SDP-Partition.
fn methods(dims: usize, grid: &[usize], sdp: bool, sdp_cells: bool) -> Vec<Method> {
    let none = vec![1; dims];
    let m = |name, propagator, partitioner, samples| Method {
        name,
        propagator,
        partitioner,
        samples,
        boundary: Boundary::Box,
    };
    let mut v = vec![
        m("CL-CROWN", Propagator::CrownSeparate, uniform(&none), 0),
        m("CL-IBP", Propagator::IbpSeparate, uniform(&none), 0),
        m("CL-SG-IBP", Propagator::SgIbpSeparate, uniform(&none), 0),
    ];
    if sdp {
        v.push(m("Reach-SDP", Propagator::ReachSdp, uniform(&none), 0));
    }
    if sdp_cells {
        v.push(m(
            "Reach-SDP-Partition",
            Propagator::ReachSdp,
            uniform(grid),
            0,
        ));
    }
    v.extend([
        m("Reach-LP", Propagator::ReachLp, uniform(&none), 0),
        m("Reach-LP-Partition", Propagator::ReachLp, uniform(grid), 0),
        m(
            "Reach-LP-GSG (32 calls)",
            Propagator::ReachLp,
            common::gsg32(),
            1000,
        ),
        m(
            "CROWN-unrolled",
            Propagator::CrownUnrolled,
            uniform(&none),
            0,
        ),
        m(
            "CROWN-unrolled-Partition",
            Propagator::CrownUnrolled,
            uniform(grid),
            0,
        ),
    ]);
    if dims == 2 {
        v.push(Method {
            boundary: Boundary::Hull,
            ..m("Reach-LP-Hull", Propagator::ReachLp, uniform(&none), 1000)
        });
    }
    v
}

/// `median (best)` of the runs.
fn fmt_time(median: f64, best: f64) -> String {
    if median < 1.0 {
        format!("{:.3} ms ({:.3})", median * 1e3, best * 1e3)
    } else {
        format!("{median:.2} s ({best:.2})")
    }
}

fn main() {
    let (filter, slow) = common::args();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    println!("machine: {}, one used", common::machine());
    for (spec, grid, sdp, sdp_cells) in [
        ("specs/double_integrator.ravel", vec![4, 4], true, true),
        ("specs/quadrotor.ravel", vec![2, 2, 2, 2, 1, 1], slow, false),
    ] {
        let path = root.join(spec);
        let source = std::fs::read_to_string(&path).expect("spec");
        let mut checked = ravel::front_end(
            &source,
            path.parent().expect("dir"),
            &ravel_cli::read_request,
        )
        .expect("valid spec");

        // the reference hull: 10 000 simulated trajectories
        checked.samples = 10_000;
        checked.propagator = Propagator::IbpSeparate;
        checked.partitioner = uniform(&vec![1; grid.len()]);
        let reference = execute_system(&lower_system(&checked), &Control::unlimited());
        let hull = reference
            .sampled
            .last()
            .cloned()
            .flatten()
            .expect("samples");
        let hull_volume = hull.volume();

        println!();
        println!(
            "{spec}: horizon {}, {} cells in the partitioned rows",
            checked.horizon,
            grid.iter().product::<usize>()
        );
        println!(
            "| {:<26} | {:>24} | {:>12} |",
            "Algorithm", "Runtime: median (best)", "Error"
        );
        println!("|{:-<28}|{:-<26}|{:-<14}|", "", "", "");
        for m in methods(grid.len(), &grid, sdp, sdp_cells) {
            if filter
                .as_ref()
                .is_some_and(|f| !m.name.contains(f.as_str()))
            {
                continue;
            }
            checked.propagator = m.propagator;
            checked.partitioner = m.partitioner.clone();
            checked.samples = m.samples;
            checked.boundary = m.boundary.clone();
            let plan = lower_system(&checked);
            let mut times = Vec::new();
            let start = Instant::now();
            let mut outcome;
            loop {
                let t = Instant::now();
                outcome = execute_system(&plan, &Control::new(&|| t.elapsed().as_secs_f64()));
                times.push(t.elapsed().as_secs_f64());
                let spent = start.elapsed().as_secs_f64();
                if (times.len() >= 3 && spent >= 1.0) || spent >= 10.0 {
                    break;
                }
            }
            times.sort_by(f64::total_cmp);
            let (median, best) = (times[times.len() / 2], times[0]);
            let last = outcome.reach.last().expect("steps");
            let error = last.volume() / hull_volume - 1.0;
            let issues = if outcome.solver_issues.is_empty() {
                ""
            } else {
                " (solver fallbacks)"
            };
            println!(
                "| {:<26} | {:>24} | {:>12} |{issues}",
                m.name,
                fmt_time(median, best),
                if error.abs() < 1e5 {
                    format!("{error:.2}")
                } else {
                    format!("{error:.2e}")
                }
            );
        }
    }
}
