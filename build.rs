//! Links OpenBLAS (BLAS and LAPACK), which clarabel's SDP support needs;
//! `scripts/install-deps.sh` installs it.
//!
//! Debian's single-threaded build is preferred: ravel runs OpenBLAS on one
//! thread anyway (its SDPs are small), and the threaded build starts a pool
//! of worker threads at load time that spin on `sched_yield` for a while,
//! taking a core from the analysis and from `--jobs` workers. Its static
//! library (`libopenblas-serial-dev`) is linked when installed: loading the
//! shared one resolves about 12 000 symbols at every process start (about
//! 1.5 ms of a 7 ms `ravel verify`). Otherwise the serial shared library is
//! loaded through a run path, and failing that the default one (which
//! `analysis::sdp` pins to one thread).
use std::path::Path;

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    let serial = [
        "/usr/lib/x86_64-linux-gnu/openblas-serial",
        "/usr/lib/aarch64-linux-gnu/openblas-serial",
    ];
    for dir in serial {
        println!("cargo:rerun-if-changed={dir}");
    }
    if let Some(dir) = serial
        .iter()
        .find(|d| Path::new(d).join("libopenblas.a").exists())
    {
        println!("cargo:rustc-link-search=native={dir}");
        println!("cargo:rustc-link-lib=static=openblas");
        // OpenBLAS's LAPACK is Fortran: its runtime, by file name (the
        // unversioned link comes only with the compiler's -dev package)
        println!("cargo:rustc-link-lib=dylib:+verbatim=libgfortran.so.5");
        println!("cargo:rustc-link-lib=dylib=pthread");
        println!("cargo:rustc-link-lib=dylib=m");
        return;
    }
    println!("cargo:rustc-link-lib=dylib=openblas");
    if let Some(dir) = serial
        .iter()
        .find(|d| Path::new(d).join("libopenblas.so.0").exists())
    {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{dir}");
    }
}
