//! Profiling helper (`valgrind --tool=callgrind`): Reach-LP on the double integrator, 200 times.
use std::path::Path;
fn main() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("specs/double_integrator.ravel");
    let src = std::fs::read_to_string(&path).unwrap();
    let c = ravel::front_end(&src, path.parent().unwrap(), &ravel::cli::read_request).unwrap();
    let plan = ravel::lower::lower(&c);
    for _ in 0..200 {
        std::hint::black_box(ravel::execute::propagate_cell(&plan, &plan.initial, None));
    }
}
