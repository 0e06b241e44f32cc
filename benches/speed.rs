//! Speed: the targets of the speed issue and how time scales (`cargo bench --bench speed`).
//!
//! Every time is the fastest of repeated runs (at least five, until 1 s
//! have passed): the machine's capability, not its neighbours' load (on a
//! shared 2-core machine a second thread is intermittently slowed by other
//! tenants, so a median of two-thread runs measures them). Analysis only
//! unless the row says otherwise, one thread unless it says `jobs 2`. The
//! tables:
//!
//! 1. the targets (the repository's own controllers), measured and wanted;
//! 2. cells: the double integrator's Reach-LP over k×k grids, 1 … 4096 cells,
//!    with one and two threads;
//! 3. width and depth: CROWN output bounds of random ReLU networks over one
//!    box, with the multiply-adds done and the rate against this machine's
//!    measured matrix-multiply rate;
//! 4. horizon: Reach-LP (linear) and unrolled CROWN (quadratic);
//! 5. the peak memory of the whole run.
//!
//! `--slow` adds the Reach-SDP rows that take minutes (the quadrotor's 12
//! steps, a 2 → 32 → 32 → 3 controller's one step). A substring argument
//! keeps only the tables whose title contains it (`cargo bench --bench speed -- cells`).

mod common;

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use nalgebra::{DMatrix, DVector};
use ravel::check::Checked;
use ravel::execute::{execute_system, propagate_cell, Control};
use ravel::lower::{lower_system, Partitioner, SystemPlan};
use ravel_analysis::closed_loop::{ClosedLoop, Plant, Propagator};
use ravel_analysis::crown::{Mode, Relaxation};
use ravel_analysis::sets::{IBox, Region};
use ravel_base::rng::Rng;

/// The fastest of repeated runs of `f`, in seconds.
fn time(mut f: impl FnMut()) -> f64 {
    best_times(&mut [&mut f])[0]
}

/// The best times of `one` and `two`, run in turn: a speed-up measured under
/// the same conditions for both, when the machine's load drifts.
fn time_pair(mut one: impl FnMut(), mut two: impl FnMut()) -> (f64, f64) {
    let t = best_times(&mut [&mut one, &mut two]);
    (t[0], t[1])
}

/// The fastest run of each of `fs`, in seconds: after a warm-up of each,
/// they run in turn for at least a second and five runs each (at most
/// 20 000 runs or 20 s each).
fn best_times(fs: &mut [&mut dyn FnMut()]) -> Vec<f64> {
    for f in fs.iter_mut() {
        f(); // warm-up
    }
    let start = Instant::now();
    let mut best = vec![f64::INFINITY; fs.len()];
    let mut runs = 0;
    while runs < 5 || (start.elapsed().as_secs_f64() < 1.0 && runs < 20_000) {
        for (f, b) in fs.iter_mut().zip(&mut best) {
            let t = Instant::now();
            f();
            *b = b.min(t.elapsed().as_secs_f64());
        }
        runs += 1;
        if start.elapsed().as_secs_f64() > 20.0 * fs.len() as f64 {
            break;
        }
    }
    best
}

fn show(s: f64) -> String {
    if s < 1e-3 {
        format!("{:.1} µs", s * 1e6)
    } else if s < 1.0 {
        format!("{:.2} ms", s * 1e3)
    } else {
        format!("{s:.2} s")
    }
}

fn checked(spec: &str) -> Checked {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(spec);
    let source = std::fs::read_to_string(&path).expect("spec");
    ravel::front_end(
        &source,
        path.parent().expect("dir"),
        &ravel_cli::read_request,
    )
    .expect("valid spec")
}

fn plan_of(c: &Checked, prop: Propagator, part: Partitioner, samples: usize) -> SystemPlan {
    let mut c = c.clone();
    c.propagator = prop;
    c.partitioner = part;
    c.samples = samples;
    lower_system(&c)
}

fn grid(k: usize, dims: usize) -> Partitioner {
    let mut g = vec![1; dims];
    g[0] = k;
    if dims > 1 {
        g[1] = k;
    }
    Partitioner::Uniform(g)
}

fn whole(dims: usize) -> Partitioner {
    Partitioner::Uniform(vec![1; dims])
}

fn run(plan: &SystemPlan, threads: usize) {
    std::hint::black_box(execute_system(
        plan,
        &Control {
            elapsed: &|| 0.0,
            time_limit: None,
            progress: &|_| {},
            threads,
        },
    ));
}

/// The multiply-adds of CROWN's products on a `widths` ReLU network whose
/// ReLU layers have `live[k]` neurons not proved inactive (`live[0]` is the
/// input width): each pre-activation bound of hidden layer `j ≥ 1` takes
/// `2·live[j]` rows (a selection of `W`'s rows, no product) through
/// affine layers `j − 2 … 0` (0-based), each as packed (`live` rows and
/// columns); the output bound `2·outputs` rows through all of them. With every
/// neuron live (`live = widths`) this is the dense count.
fn crown_madds(widths: &[usize], live: &[usize]) -> f64 {
    let hidden = widths.len() - 2;
    let mut total = 0.0;
    let through = |rows: f64, top: usize| -> f64 {
        // affine layers top … 0: layer i maps live[i] inputs to live[i + 1]
        (0..=top)
            .map(|i| rows * live[i + 1] as f64 * live[i] as f64)
            .sum::<f64>()
    };
    for j in 1..hidden {
        total += through(2.0 * live[j + 1] as f64, j - 1);
    }
    let outputs = widths[widths.len() - 1];
    total += 2.0 * (outputs * outputs * live[hidden]) as f64;
    total += through(2.0 * outputs as f64, hidden - 1);
    total
}

/// The neurons not proved inactive of each ReLU layer of an analysis
/// (`live[0]`: the inputs, `live[hidden + 1]`: the outputs).
fn live_widths(net: &ravel_base::nn::Network, a: &Relaxation, widths: &[usize]) -> Vec<usize> {
    let mut live = vec![widths[0]];
    for (i, layer) in net.layers.iter().enumerate() {
        if matches!(layer, ravel_base::nn::Layer::Act(_)) {
            live.push(a.boxes()[i].hi.iter().filter(|h| **h > 0.0).count());
        }
    }
    live.push(widths[widths.len() - 1]);
    live
}

/// This machine's matrix-multiply rate (multiply-adds per second, one thread).
fn gemm_rate() -> f64 {
    let n = 512;
    let a = DMatrix::<f64>::from_fn(n, n, |i, j| ((i * 7 + j) % 13) as f64 - 6.0);
    let b = DMatrix::<f64>::from_fn(n, n, |i, j| ((i + 3 * j) % 11) as f64 - 5.0);
    let t = time(|| {
        std::hint::black_box(&a * &b);
    });
    (n * n * n) as f64 / t
}

fn peak_memory() -> String {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM"))
                .map(|l| l.trim_start_matches("VmHWM:").trim().to_string())
        })
        .unwrap_or_else(|| "unknown".into())
}

fn targets(slow: bool) {
    println!("\n## Targets (one thread; analysis only unless stated)\n");
    println!("| Problem | measured | target |");
    println!("|---|---|---|");
    let di = checked("specs/double_integrator.ravel");
    let quad = checked("specs/quadrotor.ravel");
    let row = |name: &str, t: f64, target: &str| println!("| {name} | {} | {target} |", show(t));
    let p = plan_of(&di, Propagator::ReachLp, whole(2), 0);
    row(
        "DI Reach-LP, 5 steps",
        time(|| {
            std::hint::black_box(propagate_cell(&p, &p.initial, None));
        }),
        "≤ 15 µs",
    );
    let p = plan_of(&di, Propagator::ReachLp, grid(4, 2), 0);
    row("DI Reach-LP, 16 cells", time(|| run(&p, 1)), "≤ 200 µs");
    let gsg = common::gsg32();
    let p = plan_of(&di, Propagator::ReachLp, gsg.clone(), 1000);
    row(
        "DI Reach-LP + GSG (32 calls, 1000 samples included)",
        time(|| run(&p, 1)),
        "≤ 1 ms",
    );
    let p = plan_of(&di, Propagator::CrownUnrolled, whole(2), 0);
    row(
        "DI unrolled CROWN",
        time(|| {
            std::hint::black_box(propagate_cell(&p, &p.initial, None));
        }),
        "≤ 60 µs",
    );
    let p = plan_of(&di, Propagator::CrownUnrolled, grid(4, 2), 0);
    row("DI unrolled CROWN, 16 cells", time(|| run(&p, 1)), "≤ 1 ms");
    let p = plan_of(&di, Propagator::ReachSdp, whole(2), 0);
    row("DI Reach-SDP", time(|| run(&p, 1)), "≤ 20 ms");
    let p = plan_of(&di, Propagator::ReachSdp, grid(4, 2), 0);
    row("DI Reach-SDP, 16 cells", time(|| run(&p, 1)), "≤ 300 ms");
    let p = plan_of(&quad, Propagator::ReachLp, whole(6), 0);
    row(
        "Quadrotor Reach-LP, 12 steps",
        time(|| {
            std::hint::black_box(propagate_cell(&p, &p.initial, None));
        }),
        "≤ 150 µs",
    );
    let p = plan_of(
        &quad,
        Propagator::ReachLp,
        Partitioner::Uniform(vec![2, 2, 2, 2, 1, 1]),
        0,
    );
    row(
        "Quadrotor Reach-LP, 16 cells",
        time(|| run(&p, 1)),
        "≤ 2.5 ms",
    );
    let p = plan_of(&quad, Propagator::CrownUnrolled, whole(6), 0);
    row(
        "Quadrotor unrolled CROWN",
        time(|| {
            std::hint::black_box(propagate_cell(&p, &p.initial, None));
        }),
        "≤ 2 ms",
    );
    if slow {
        let p = plan_of(&quad, Propagator::ReachSdp, whole(6), 0);
        let t = Instant::now();
        run(&p, 1);
        row(
            "Quadrotor Reach-SDP, 12 steps (one run)",
            t.elapsed().as_secs_f64(),
            "≤ 60 s",
        );
        row(
            "2 → 32 → 32 → 3 ReLU, Reach-SDP, one step (one run)",
            sdp_step(32),
            "≤ 3 s",
        );
    } else {
        println!("| Quadrotor Reach-SDP, 12 steps | not run (`--slow`) | ≤ 60 s |");
        println!("| 2 → 32 → 32 → 3 ReLU, Reach-SDP, one step | not run (`--slow`) | ≤ 3 s |");
    }
    let exe = env!("CARGO_BIN_EXE_ravel");
    let spec = Path::new(env!("CARGO_MANIFEST_DIR")).join("specs/double_integrator.ravel");
    row(
        "Whole process `ravel verify specs/double_integrator.ravel` (2000 samples)",
        time(|| {
            let out = Command::new(exe)
                .arg("verify")
                .arg(&spec)
                .output()
                .expect("ravel runs");
            assert_eq!(out.status.code(), Some(0));
        }),
        "≤ 5 ms",
    );
    jobs_rows();
}

/// The `--jobs 2` rows of the targets (also on their own: filter `jobs`).
fn jobs_rows() {
    let di = checked("specs/double_integrator.ravel");
    let quad = checked("specs/quadrotor.ravel");
    let gsg = common::gsg32();
    let exe = env!("CARGO_BIN_EXE_ravel");
    let spec = Path::new(env!("CARGO_MANIFEST_DIR")).join("specs/double_integrator.ravel");
    let p = plan_of(&di, Propagator::ReachLp, grid(16, 2), 0);
    let (one, two) = time_pair(|| run(&p, 1), || run(&p, 2));
    println!(
        "| DI Reach-LP, 256 cells: jobs 1 / jobs 2 | {} / {} ({:.2}×) | ≥ 1.8× |",
        show(one),
        show(two),
        one / two
    );
    let p = plan_of(&quad, Propagator::ReachLp, gsg, 1000);
    let (one, two) = time_pair(|| run(&p, 1), || run(&p, 2));
    println!("| Quadrotor Reach-LP + GSG (32 calls, 1000 samples): jobs 1 / jobs 2 | {} / {} ({:.2}×) | ≥ 1.8× |", show(one), show(two), one / two);
    // a batch: one spec, 256 controllers (copies of the double integrator's)
    let dir = std::env::temp_dir().join(format!("ravel-bench-batch-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temporary directory");
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/double_integrator.onnx");
    for i in 0..256 {
        std::fs::copy(&model, dir.join(format!("c{i:03}.onnx"))).expect("copy a controller");
    }
    let batch = |jobs: usize| {
        let out = Command::new(exe)
            .arg("verify")
            .arg(&spec)
            .arg("--controller")
            .arg(&dir)
            .arg("--jobs")
            .arg(jobs.to_string())
            .output()
            .expect("ravel runs");
        assert_eq!(out.status.code(), Some(0));
    };
    let (one, two) = time_pair(|| batch(1), || batch(2));
    println!(
        "| Batch `ravel verify` of 256 controllers (2000 samples each), whole process: jobs 1 / jobs 2 | {} / {} ({:.2}×) | ≥ 1.8× |",
        show(one),
        show(two),
        one / two
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// One Reach-SDP step (one run, seconds) of a 2-state plant with a random
/// `2 → w → w → 3` ReLU controller over a box where most neurons are
/// unstable.
fn sdp_step(w: usize) -> f64 {
    let mut rng = Rng::new(11);
    let net = common::random_relu(&mut rng, &[2, w, w, 3]);
    let plant = Plant {
        a: DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 0.0, 1.0]),
        b: DMatrix::from_row_slice(2, 3, &[0.5, 0.1, 0.0, 1.0, 0.0, 0.2]),
        c: DVector::zeros(2),
        obs: DMatrix::identity(2, 2),
        w: IBox::point(&[0.0, 0.0]),
        v: IBox::point(&[0.0, 0.0]),
        err: None,
    };
    let cl = ClosedLoop::new(plant, net);
    let x0 = Region::Box(IBox::new(vec![-0.5, -0.5], vec![0.5, 0.5]));
    let t = Instant::now();
    std::hint::black_box(cl.step(
        0,
        &x0,
        Propagator::ReachSdp,
        &ravel_analysis::closed_loop::Boundary::Box,
    ));
    t.elapsed().as_secs_f64()
}

/// Reach-SDP's time against the controller's width (`--slow` only).
fn sdp_width() {
    println!("## Reach-SDP: one step against the controller's width (2 → w → w → 3, one run)");
    println!("| w | time |\n|---|---|");
    for w in [16, 32, 48, 64, 96, 128] {
        println!("| {w} | {} |", show(sdp_step(w)));
    }
}

fn cells() {
    println!("\n## Cells: DI Reach-LP over k × k grids (5 steps, the whole set first)\n");
    println!("| cells | jobs 1 | per cell | jobs 2 | speed-up |");
    println!("|---|---|---|---|---|");
    let di = checked("specs/double_integrator.ravel");
    for k in [1usize, 2, 4, 8, 16, 32, 64] {
        let p = plan_of(&di, Propagator::ReachLp, grid(k, 2), 0);
        let (one, two) = time_pair(|| run(&p, 1), || run(&p, 2));
        let n = k * k;
        println!(
            "| {n} | {} | {} | {} | {:.2}× |",
            show(one),
            show(one / n as f64),
            show(two),
            one / two
        );
    }
}

fn width_and_depth() {
    let rate = gemm_rate();
    println!("\n## Width and depth: CROWN output bounds over one box (random ReLU networks)\n");
    println!("this machine's 512×512 matrix multiply (nalgebra/matrixmultiply, one thread): {:.2} G multiply-adds/s\n", rate / 1e9);
    println!("(multiply-adds: those of the products done, of those a dense pass would do; neurons proved inactive are left out)\n");
    println!("| network | time | multiply-adds | rate | of matmul rate |");
    println!("|---|---|---|---|---|");
    let mut rng = Rng::new(5);
    let mut shapes: Vec<Vec<usize>> = [8usize, 32, 128, 512, 1024]
        .iter()
        .map(|&w| vec![6, w, w, 3])
        .collect();
    shapes.extend([1usize, 2, 4, 8].into_iter().map(|d| {
        let mut s = vec![6];
        s.extend(std::iter::repeat_n(32, d));
        s.push(3);
        s
    }));
    for widths in shapes {
        let net = common::random_relu(&mut rng, &widths);
        let input = IBox::new(vec![-0.5; 6], vec![0.5; 6]);
        let t = time(|| {
            let a = Relaxation::new(&net, &input, Mode::Crown);
            std::hint::black_box(a.output_box(Mode::Crown));
        });
        let a = Relaxation::new(&net, &input, Mode::Crown);
        let live = live_widths(&net, &a, &widths);
        let dense = crown_madds(&widths, &widths);
        let madds = crown_madds(&widths, &live);
        let name = widths
            .iter()
            .map(|w| w.to_string())
            .collect::<Vec<_>>()
            .join(" → ");
        println!(
            "| {name} | {} | {:.2e} of {:.2e} | {:.2} G/s | {:.0} % |",
            show(t),
            madds,
            dense,
            madds / t / 1e9,
            100.0 * madds / t / rate
        );
    }
}

/// CROWN output boxes of 256 cells of one input box through one network,
/// batched (`analysis::batch`: the cells' back-substitutions as shared
/// matrix products) against one cell at a time (`Relaxation`, measured on 16
/// cells and scaled to 256).
fn batched_cells() {
    let rate = gemm_rate();
    println!("\n## Batched cells: CROWN output boxes of 256 cells (4 × 4 × 4 × 4 grid of a 6-input box), one thread\n");
    println!("this machine's 512×512 matrix multiply: {:.2} G multiply-adds/s; \"dense\": the multiply-adds of a dense single-cell CROWN pass (every neuron kept) for 256 cells; \"done\": those of the batched products\n", rate / 1e9);
    println!("| network | one cell at a time (×256) | batched | speed-up | dense multiply-adds | of matmul rate | done multiply-adds | of matmul rate |");
    println!("|---|---|---|---|---|---|---|---|");
    let mut rng = Rng::new(9);
    for w in [8usize, 32, 128, 512, 1024] {
        let widths = [6, w, w, 3];
        let net = common::random_relu(&mut rng, &widths);
        let input = IBox::new(vec![-0.5; 6], vec![0.5; 6]);
        let cells = input.grid(&[4, 4, 4, 4, 1, 1]);
        let dirs = DMatrix::from_fn(6, 3, |r, c| {
            if r % 3 == c {
                if r < 3 {
                    1.0
                } else {
                    -1.0
                }
            } else {
                0.0
            }
        });
        let single = time(|| {
            for c in &cells[..16] {
                std::hint::black_box(ravel_analysis::open_loop::cell_offsets(
                    &net,
                    c,
                    Mode::Crown,
                    &dirs,
                ));
            }
        }) * 16.0;
        let batched = time(|| {
            std::hint::black_box(ravel_analysis::batch::crown_offsets(
                &net,
                &cells,
                &dirs,
                Mode::Crown,
            ));
        });
        let n = cells.len() as f64;
        let dense = n * crown_madds(&widths, &widths);
        let (n0, m) = (7.0, 3.0);
        let wf = w as f64;
        // interval image of z₁ (W·mid, |W|·[rad | mid]), the right-associated
        // products (W·S, |W|·D), the output rows through [W₁ | b₁] and [W₀ | b₀]
        let done = n
            * (3.0 * wf * wf + 2.0 * wf * wf * n0 + 2.0 * m * (wf + 1.0) * wf + 2.0 * m * n0 * wf);
        println!(
            "| 6 → {w} → {w} → 3 | {} | {} | {:.1}× | {:.2e} | {:.0} % | {:.2e} | {:.0} % |",
            show(single),
            show(batched),
            single / batched,
            dense,
            100.0 * dense / batched / rate,
            done,
            100.0 * done / batched / rate
        );
    }
}

fn horizon() {
    println!("\n## Horizon: one cell of the double integrator\n");
    println!("| horizon | Reach-LP | per step | unrolled CROWN | per step |");
    println!("|---|---|---|---|---|");
    let mut di = checked("specs/double_integrator.ravel");
    for h in [5usize, 10, 20, 40] {
        di.horizon = h;
        let lp = plan_of(&di, Propagator::ReachLp, whole(2), 0);
        let un = plan_of(&di, Propagator::CrownUnrolled, whole(2), 0);
        let a = time(|| {
            std::hint::black_box(propagate_cell(&lp, &lp.initial, None));
        });
        let b = time(|| {
            std::hint::black_box(propagate_cell(&un, &un.initial, None));
        });
        println!(
            "| {h} | {} | {} | {} | {} |",
            show(a),
            show(a / h as f64),
            show(b),
            show(b / h as f64)
        );
    }
}

/// Final-step error against analysis time, with and without optimised
/// slopes: the error of one `execute` (1000 samples, not timed), the time
/// of the analysis alone (`propagate_cell` of every cell, fastest run).
fn tightness() {
    println!("\n## Tightness per time: final-step error against analysis time (one thread)\n");
    println!("| problem | method | optimise_slopes | analysis time | final-step error |");
    println!("|---|---|---|---|---|");
    let rows: [(&str, &str, Propagator, usize, &[usize]); 5] = [
        (
            "DI",
            "specs/double_integrator.ravel",
            Propagator::ReachLp,
            1,
            &[0, 1, 2, 3, 5],
        ),
        (
            "DI",
            "specs/double_integrator.ravel",
            Propagator::ReachLp,
            4,
            &[0, 3],
        ),
        (
            "DI",
            "specs/double_integrator.ravel",
            Propagator::CrownUnrolled,
            1,
            &[0, 1, 2, 3, 5],
        ),
        (
            "quadrotor",
            "specs/quadrotor.ravel",
            Propagator::ReachLp,
            1,
            &[0, 1, 3, 10],
        ),
        (
            "quadrotor",
            "specs/quadrotor.ravel",
            Propagator::CrownUnrolled,
            1,
            &[0, 1, 3],
        ),
    ];
    for (name, spec, prop, k, steps) in rows {
        let c = checked(spec);
        let dims = c.state.1;
        for &st in steps {
            let mut plan = plan_of(&c, prop, grid(k, dims), 1000);
            plan.closed_loop
                .linear_mut()
                .expect("a linear plant")
                .slope_steps = st;
            let err = ravel::report::system::final_error(&execute_system(
                &plan,
                &Control {
                    elapsed: &|| 0.0,
                    time_limit: None,
                    progress: &|_| {},
                    threads: 1,
                },
            ));
            let mut timed = plan.clone();
            timed.samples = 0;
            let cells = timed.initial.bbox();
            let parts: Vec<Region> = match &timed.partitioner {
                Partitioner::Uniform(g) => cells.grid(g).into_iter().map(Region::Box).collect(),
                _ => vec![timed.initial.clone()],
            };
            let t = time(|| {
                for cell in &parts {
                    std::hint::black_box(propagate_cell(&timed, cell, None));
                }
            });
            let cells_text = if parts.len() > 1 {
                format!(", {} cells", parts.len())
            } else {
                String::new()
            };
            println!(
                "| {name} | {}{cells_text} | {st} | {} | {} |",
                prop.name(),
                show(t),
                err.map_or("—".into(), |e| if e < 1e-3 {
                    format!("{e:.1e}")
                } else {
                    format!("{e:.4}")
                })
            );
        }
    }
}

fn main() {
    let (filter, slow) = common::args();
    let on = |title: &str| filter.as_ref().is_none_or(|f| title.contains(f.as_str()));
    println!("machine: {}; date: {}", common::machine(), today());
    if on("targets") {
        targets(slow);
    } else if on("jobs") {
        println!("\n## `--jobs 2` rows of the targets\n");
        jobs_rows();
    }
    if on("cells") {
        cells();
    }
    if on("width") {
        width_and_depth();
    }
    if on("batch") {
        batched_cells();
    }
    if on("horizon") {
        horizon();
    }
    if on("tightness") {
        tightness();
    }
    if slow && on("sdp") {
        sdp_width();
    }
    println!(
        "\npeak memory (VmHWM) of this benchmark process: {}",
        peak_memory()
    );
}

/// Today's date from the system clock (UTC), for the table's heading.
fn today() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs()) as i64;
    // civil-from-days (Howard Hinnant's algorithm)
    let z = secs.div_euclid(86_400) + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02}")
}
