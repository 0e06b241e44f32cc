//! The `ravel` binary: a thin wrapper over [`ravel::cli`].

fn main() -> std::process::ExitCode {
    ravel_cli::main()
}
