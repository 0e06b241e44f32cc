//! Links the system OpenBLAS (BLAS and LAPACK) that clarabel's SDP support
//! needs; `scripts/install-deps.sh` installs it.
//!
//! When Debian's single-threaded build (`libopenblas0-serial`) is installed,
//! the binaries load it first (a run path to its folder): ravel runs
//! OpenBLAS on one thread anyway (its SDPs are small), and the threaded
//! build starts a pool of worker threads at load time that spin on
//! `sched_yield` for a while, taking a core from the analysis and from
//! `--jobs` workers. Without the serial build the threaded one is used, and
//! `analysis::sdp` pins it to one thread.
use std::path::Path;

fn main() {
    println!("cargo:rustc-link-lib=dylib=openblas");
    println!("cargo:rerun-if-changed=build.rs");
    for dir in [
        "/usr/lib/x86_64-linux-gnu/openblas-serial",
        "/usr/lib/aarch64-linux-gnu/openblas-serial",
    ] {
        println!("cargo:rerun-if-changed={dir}");
        if Path::new(dir).join("libopenblas.so.0").exists() {
            println!("cargo:rustc-link-arg=-Wl,-rpath,{dir}");
            break;
        }
    }
}
