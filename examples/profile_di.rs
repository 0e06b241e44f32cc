//! Profiling helper (`perf record` / `valgrind --tool=callgrind`): one
//! closed-loop cell propagated many times.
//!
//! `cargo run --release --example profile_di -- [SPEC] [PROPAGATOR] [REPEATS]`
//! (defaults: the double integrator, its own propagator, 2000 times;
//! `WHOLE=1` times the whole `execute` instead of one cell).
use std::path::Path;
fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let spec = args
        .first()
        .cloned()
        .unwrap_or_else(|| "specs/double_integrator.ravel".into());
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(spec);
    let src = std::fs::read_to_string(&path).unwrap();
    let mut c = ravel::front_end(&src, path.parent().unwrap(), &ravel_cli::read_request).unwrap();
    if let Some(p) = args.get(1) {
        if p != "-" {
            c.propagator = ravel_analysis::closed_loop::Propagator::from_name(p).unwrap();
        }
    }
    let repeats: usize = args.get(2).map_or(2000, |r| r.parse().unwrap());
    let mut plan = ravel::lower::lower_system(&c);
    // SLOPES=k: k slope-optimisation steps per back-substitution
    if let Some(k) = std::env::var("SLOPES").ok().and_then(|k| k.parse().ok()) {
        plan.closed_loop
            .linear_mut()
            .expect("a linear plant")
            .slope_steps = k;
    }
    if std::env::var_os("SHOW_LAYERS").is_some() {
        for l in &plan.closed_loop.net().layers {
            match l {
                ravel_base::nn::Layer::Affine { w, .. } => eprint!("{}x{} ", w.nrows(), w.ncols()),
                ravel_base::nn::Layer::Act(a) => eprint!("{} ", a.name()),
            }
        }
        eprintln!();
    }
    // WHOLE=1: the whole `execute` (sampling, partition, verdicts)
    let whole = std::env::var_os("WHOLE").is_some();
    // the best of five batches: the least disturbed by other work
    let mut best = f64::INFINITY;
    for _ in 0..5 {
        let t = std::time::Instant::now();
        for _ in 0..repeats.div_ceil(5) {
            if whole {
                std::hint::black_box(ravel::execute::execute_system(
                    &plan,
                    &ravel::execute::Control::unlimited(),
                ));
            } else {
                std::hint::black_box(ravel::execute::propagate_cell(&plan, &plan.initial, None));
            }
        }
        best = best.min(t.elapsed().as_secs_f64() / repeats.div_ceil(5) as f64);
    }
    eprintln!("{:.2} µs per cell (best of 5 batches)", best * 1e6);
    if whole {
        let out = ravel::execute::execute_system(&plan, &ravel::execute::Control::unlimited());
        eprintln!(
            "final-step error {:?}",
            ravel::report::system::final_error(&out)
        );
        if std::env::var_os("SHOW_SETS").is_some() {
            for (r, s) in out.reach.iter().zip(&out.sampled) {
                eprintln!(
                    "  {:?} {:?} | sampled {:?}",
                    r.lo,
                    r.hi,
                    s.as_ref().map(|s| (&s.lo, &s.hi))
                );
            }
        }
    }
}
