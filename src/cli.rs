//! The command line. This is the only module that touches the file system,
//! the terminal, the clock and the process exit code.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use clap::{Parser, Subcommand, ValueEnum};
use serde_json::{json, Value};

use crate::diag::{render, Diagnostic};
use crate::execute::Status;

/// ravel — verify reach-avoid properties of neural feedback loops.
#[derive(Parser, Debug)]
#[command(name = "ravel", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Parse and check specs (and load their controllers); print diagnostics only.
    Check {
        /// Spec files (.ravel).
        #[arg(required = true)]
        specs: Vec<PathBuf>,
    },
    /// Check, analyse and report a verdict for each spec.
    Verify {
        /// Spec files (.ravel).
        #[arg(required = true)]
        specs: Vec<PathBuf>,
        /// Output format.
        #[arg(long, value_enum, default_value_t = Format::Text)]
        format: Format,
        /// Leave out timing (text output shows it by default; JSON never does unless --timing).
        #[arg(long, conflicts_with = "timing")]
        no_timing: bool,
        /// Include timing in JSON output.
        #[arg(long)]
        timing: bool,
    },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Format {
    Text,
    Json,
}

/// Exit codes (documented in the README).
pub mod exit {
    /// Every property of every spec VERIFIED.
    pub const VERIFIED: u8 = 0;
    /// Some property FALSIFIED.
    pub const FALSIFIED: u8 = 1;
    /// Input or usage error (takes precedence over verdicts).
    pub const INPUT_ERROR: u8 = 2;
    /// Some property UNSURE, none FALSIFIED.
    pub const UNSURE: u8 = 3;
}

fn read_file(path: &Path) -> Result<Vec<u8>, String> {
    std::fs::read(path).map_err(|e| e.to_string())
}

/// A spec's source and the result of its front end.
struct Loaded {
    name: String,
    source: String,
    result: Result<crate::check::Checked, Vec<Diagnostic>>,
}

fn load(path: &Path) -> Result<Loaded, String> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read spec `{name}`: {e}"))?;
    let source =
        String::from_utf8(bytes).map_err(|_| format!("spec `{name}` is not UTF-8 text"))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let result = crate::front_end(&source, dir, &read_file);
    Ok(Loaded {
        name,
        source,
        result,
    })
}

fn diag_json(name: &str, source: &str, diags: &[Diagnostic]) -> Value {
    let errors: Vec<Value> = diags
        .iter()
        .map(|d| {
            let (line, col) = d.span.map_or((0, 0), |s| line_col(source, s.start));
            json!({ "code": d.code.as_str(), "message": d.message, "label": d.label, "hint": d.hint, "line": line, "column": col })
        })
        .collect();
    json!({ "spec": name, "verdict": "ERROR", "errors": errors })
}

/// 1-based line and column (in characters) of a byte offset.
pub fn line_col(source: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(source.len());
    let before = &source[..offset];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

/// Run the CLI with the process arguments.
pub fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let code = if e.use_stderr() {
                exit::INPUT_ERROR
            } else {
                exit::VERIFIED
            };
            let _ = e.print();
            return ExitCode::from(code);
        }
    };
    let color = std::io::stderr().is_terminal();
    let width = 100;
    match cli.cmd {
        Cmd::Check { specs } => {
            let mut code = exit::VERIFIED;
            for path in &specs {
                match load(path) {
                    Err(msg) => {
                        eprintln!("error: {msg}");
                        code = exit::INPUT_ERROR;
                    }
                    Ok(l) => match &l.result {
                        Ok(_) => println!("ok: {}", l.name),
                        Err(d) => {
                            eprint!("{}", render(d, &l.name, &l.source, width, color));
                            eprintln!("{}: {} error(s)", l.name, d.len());
                            code = exit::INPUT_ERROR;
                        }
                    },
                }
            }
            ExitCode::from(code)
        }
        Cmd::Verify {
            specs,
            format,
            no_timing,
            timing,
        } => {
            let mut worst: Option<Status> = None;
            let mut input_error = false;
            let mut results = Vec::new();
            for path in &specs {
                let l = match load(path) {
                    Ok(l) => l,
                    Err(msg) => {
                        input_error = true;
                        match format {
                            Format::Text => eprintln!("error: {msg}"),
                            Format::Json => results.push(json!({ "spec": path.display().to_string(), "verdict": "ERROR", "errors": [{ "code": null, "message": msg }] })),
                        }
                        continue;
                    }
                };
                let checked = match l.result {
                    Ok(c) => c,
                    Err(d) => {
                        input_error = true;
                        match format {
                            Format::Text => {
                                eprint!("{}", render(&d, &l.name, &l.source, width, color));
                                eprintln!("{}: {} error(s)", l.name, d.len());
                            }
                            Format::Json => results.push(diag_json(&l.name, &l.source, &d)),
                        }
                        continue;
                    }
                };
                let started = Instant::now();
                let plan = crate::lower::lower(&checked);
                let outcome = crate::execute::execute(&plan, &|| started.elapsed().as_secs_f64());
                let ms = started.elapsed().as_secs_f64() * 1e3;
                worst = worst.max(Some(outcome.verdict));
                match format {
                    Format::Text => {
                        let t = (!no_timing).then_some(ms);
                        println!("{}", crate::report::text(&l.name, &plan, &outcome, t));
                    }
                    Format::Json => results.push(crate::report::json(
                        &l.name,
                        &plan,
                        &outcome,
                        timing.then_some(ms),
                    )),
                }
            }
            let overall = if input_error {
                "ERROR"
            } else {
                worst.map_or("VERIFIED", Status::as_str)
            };
            if format == Format::Json {
                let doc = json!({ "schema": crate::report::SCHEMA, "version": env!("CARGO_PKG_VERSION"), "verdict": overall, "results": results });
                println!("{}", serde_json::to_string_pretty(&doc).unwrap_or_default());
            }
            ExitCode::from(if input_error {
                exit::INPUT_ERROR
            } else {
                match worst {
                    Some(Status::Falsified) => exit::FALSIFIED,
                    Some(Status::Unsure) => exit::UNSURE,
                    _ => exit::VERIFIED,
                }
            })
        }
    }
}
