//! Links the system OpenBLAS (BLAS and LAPACK) that clarabel's SDP support
//! needs; `scripts/install-deps.sh` installs it.
//!
//! The shared, threaded build on purpose: Debian's single-threaded build
//! (`libopenblas-serial-dev`) starts faster and has no idle worker threads,
//! but it is not safe to call from two threads at once, and `--jobs` solves
//! SDPs of different cells concurrently (it made LAPACK's eigenvalue routine
//! fail under the parallel test suite). `analysis::sdp` pins the threaded
//! build to one thread instead.
fn main() {
    println!("cargo:rustc-link-lib=dylib=openblas");
    println!("cargo:rerun-if-changed=build.rs");
}
