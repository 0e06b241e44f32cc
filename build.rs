//! Links the system OpenBLAS (BLAS and LAPACK) that clarabel's SDP support
//! needs; `scripts/install-deps.sh` installs it.
fn main() {
    println!("cargo:rustc-link-lib=dylib=openblas");
    println!("cargo:rerun-if-changed=build.rs");
}
