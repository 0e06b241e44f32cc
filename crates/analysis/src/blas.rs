//! The system BLAS/LAPACK (OpenBLAS), loaded on first use.
//!
//! Only Clarabel's PSD cone (Reach-SDP, and the SDP propagator of network
//! specs) calls BLAS/LAPACK: nine Fortran routines (`dgemm_`, `dsyrk_`,
//! `dsyr2k_`, `dsyevr_`, `dgesdd_`, `dgesvd_`, `dpotrf_`, `dpotrs_`, and the
//! thread switch). Linking OpenBLAS at build time made every run of ravel
//! map and relocate the 30 MB library and start its worker thread — about
//! 3 ms of a 7 ms `ravel verify` of a Reach-LP spec that never solves an SDP.
//! Instead, this module defines those nine symbols itself (so the link
//! needs no BLAS at all) and forwards each call to the routine of the same
//! name in `libopenblas.so.0`, opened with `dlopen` the first time
//! [`load`] is called. Like dynamic linking, just later: the same library
//! and routines as before, so every SDP result is unchanged.
//!
//! # Contract
//! * [`load`] must succeed before Clarabel solves an SDP (ravel's own
//!   Schur-complement method, `analysis::sdp_ipm`, calls no BLAS);
//!   `analysis::sdp` calls it first and, when it fails, reports the solve as
//!   not done (an
//!   [`Issue`](crate::issue::Issue), so the verdict is at most UNSURE).
//! * Every forwarding function loads the library itself if needed and, if it
//!   still is not there, aborts the process with a message (a function
//!   called from Fortran-style C code cannot return an error or unwind).
//!   That path is unreachable in ravel: only the SDP code calls BLAS, after
//!   [`load`] succeeded.
//! * The library is pinned to one thread once loaded (the SDPs are small,
//!   and `--jobs` runs cells on threads of its own). The threaded OpenBLAS
//!   build is safe to call from several threads; Debian's serial build is
//!   not (`scripts/install-deps.sh` installs the threaded one).
//!
//! This module and its nine forwarders are the crate's only `unsafe` code.
#![allow(unsafe_code)]

use std::ffi::{c_int, c_void, CStr};
use std::sync::OnceLock;

/// The library file names tried, in order.
const NAMES: [&CStr; 2] = [c"libopenblas.so.0", c"libopenblas.so"];

/// The routines forwarded (their C symbol names).
const SYMBOLS: [&CStr; 8] = [
    c"dgemm_", c"dsyrk_", c"dsyr2k_", c"dsyevr_", c"dgesdd_", c"dgesvd_", c"dpotrf_", c"dpotrs_",
];

/// The addresses of [`SYMBOLS`] in the loaded library, in that order.
struct Table([usize; 8]);

static TABLE: OnceLock<Result<Table, LoadError>> = OnceLock::new();

/// Why OpenBLAS could not be used; its `Display` says what to do.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LoadError {
    /// No library of these names could be opened.
    NoLibrary {
        /// The names tried, in order.
        tried: Vec<String>,
    },
    /// The library lacks a routine Clarabel calls.
    NoRoutine {
        /// The routine's name.
        routine: String,
    },
}

impl std::fmt::Display for LoadError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LoadError::NoLibrary { tried } => write!(
                f,
                "the BLAS/LAPACK library could not be loaded (tried {}; run scripts/install-deps.sh)",
                tried.join(", ")
            ),
            LoadError::NoRoutine { routine } => {
                write!(f, "libopenblas.so.0 has no routine {routine}")
            }
        }
    }
}

impl std::error::Error for LoadError {}

/// Opens OpenBLAS (once per process) and resolves the routines Clarabel
/// calls. The error says which library or routine was missing.
pub fn load() -> Result<(), LoadError> {
    match TABLE.get_or_init(open) {
        Ok(_) => Ok(()),
        Err(e) => Err(e.clone()),
    }
}

/// [`open_from`] the usual names of OpenBLAS.
fn open() -> Result<Table, LoadError> {
    open_from(&NAMES)
}

/// [`open`] with the library names to try.
fn open_from(names: &[&CStr]) -> Result<Table, LoadError> {
    let mut handle = std::ptr::null_mut();
    for name in names {
        // SAFETY: `name` is a NUL-terminated constant; dlopen has no other
        // precondition. The handle is never closed (the routines stay valid
        // for the life of the process).
        handle = unsafe { libc::dlopen(name.as_ptr(), libc::RTLD_NOW | libc::RTLD_LOCAL) };
        if !handle.is_null() {
            break;
        }
    }
    if handle.is_null() {
        let tried = names
            .iter()
            .map(|n| n.to_string_lossy().into_owned())
            .collect();
        return Err(LoadError::NoLibrary { tried });
    }
    let mut table = [0usize; 8];
    for (slot, sym) in table.iter_mut().zip(SYMBOLS) {
        // SAFETY: a valid handle and a NUL-terminated name.
        let f = unsafe { libc::dlsym(handle, sym.as_ptr()) };
        if f.is_null() {
            return Err(LoadError::NoRoutine {
                routine: sym.to_string_lossy().into_owned(),
            });
        }
        *slot = f as usize;
    }
    // SAFETY: as above.
    let threads = unsafe { libc::dlsym(handle, c"openblas_set_num_threads".as_ptr()) };
    if !threads.is_null() {
        // SAFETY: OpenBLAS's `void openblas_set_num_threads(int)`; it sets
        // a global thread count and touches no Rust memory.
        let set: extern "C" fn(c_int) = unsafe { std::mem::transmute(threads) };
        set(1);
    }
    Ok(Table(table))
}

/// The address of routine `i` of [`SYMBOLS`], loading the library if needed.
fn routine(i: usize) -> usize {
    match TABLE.get_or_init(open) {
        Ok(t) => t.0[i],
        Err(e) => {
            eprintln!("ravel: internal error: BLAS called but not available: {e}");
            std::process::abort()
        }
    }
}

/// Defines `#[no_mangle] extern "C" fn NAME(args…)` forwarding to routine
/// `INDEX` of [`SYMBOLS`]. Every argument of these Fortran routines is a
/// pointer (characters are passed as `const char*` without hidden lengths,
/// exactly as the `blas-sys`/`lapack-sys` declarations Clarabel calls
/// through), so the arguments are forwarded as untyped pointers: the same
/// C ABI as the typed declarations.
macro_rules! forward {
    ($name:ident, $index:expr, $($arg:ident),+) => {
        #[doc = concat!("Forwards `", stringify!($name), "` to OpenBLAS (see the module docs).")]
        ///
        /// # Safety
        /// The contract of the Fortran routine of the same name.
        #[no_mangle]
        pub unsafe extern "C" fn $name($($arg: *mut c_void),+) {
            // SAFETY: the address was resolved for exactly this symbol, whose
            // C signature takes these pointers and returns nothing.
            let f: unsafe extern "C" fn($(forward!(@ptr $arg)),+) =
                unsafe { std::mem::transmute(routine($index)) };
            unsafe { f($($arg),+) }
        }
    };
    (@ptr $arg:ident) => { *mut c_void };
}

forward!(dgemm_, 0, ta, tb, m, n, k, alpha, a, lda, b, ldb, beta, c, ldc);
forward!(dsyrk_, 1, uplo, trans, n, k, alpha, a, lda, beta, c, ldc);
forward!(dsyr2k_, 2, uplo, trans, n, k, alpha, a, lda, b, ldb, beta, c, ldc);
forward!(
    dsyevr_, 3, jobz, range, uplo, n, a, lda, vl, vu, il, iu, abstol, m, w, z, ldz, isuppz, work,
    lwork, iwork, liwork, info
);
forward!(dgesdd_, 4, jobz, m, n, a, lda, s, u, ldu, vt, ldvt, work, lwork, iwork, info);
forward!(dgesvd_, 5, jobu, jobvt, m, n, a, lda, s, u, ldu, vt, ldvt, work, lwork, info);
forward!(dpotrf_, 6, uplo, n, a, lda, info);
forward!(dpotrs_, 7, uplo, n, nrhs, a, lda, b, ldb, info);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_library_is_an_error_not_a_crash() {
        let e = open_from(&[c"libravel-no-such-blas.so.0"]).err();
        assert!(
            e.is_some_and(|e| e.to_string().contains("libravel-no-such-blas.so.0")),
            "a library that does not exist must not load"
        );
    }

    #[test]
    fn the_forwarders_reach_openblas() {
        load().expect("scripts/install-deps.sh installs OpenBLAS");
        // C = A·B for 2×2 column-major matrices through the forwarded dgemm_
        let (a, b) = ([1.0f64, 3.0, 2.0, 4.0], [5.0f64, 7.0, 6.0, 8.0]);
        let mut c = [0.0f64; 4];
        let (n, one, zero) = (2i32, 1.0f64, 0.0f64);
        let no = b'N';
        let p = |x: &f64| x as *const f64 as *mut c_void;
        let i = |x: &i32| x as *const i32 as *mut c_void;
        // SAFETY: valid 2×2 operands, leading dimensions 2.
        unsafe {
            dgemm_(
                &no as *const u8 as *mut c_void,
                &no as *const u8 as *mut c_void,
                i(&n),
                i(&n),
                i(&n),
                p(&one),
                a.as_ptr() as *mut c_void,
                i(&n),
                b.as_ptr() as *mut c_void,
                i(&n),
                p(&zero),
                c.as_mut_ptr() as *mut c_void,
                i(&n),
            )
        };
        assert_eq!(c, [19.0, 43.0, 22.0, 50.0]);
    }
}
