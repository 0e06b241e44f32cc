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
        /// Stop each spec's analysis after this many seconds, soundly: what
        /// is not finished is UNSURE and the report says so.
        #[arg(long, value_name = "SECONDS", value_parser = parse_seconds)]
        time_limit: Option<f64>,
    },
}

fn parse_seconds(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err("expected a non-negative number of seconds".into()),
    }
}

/// A progress line on standard error (only when it is a terminal), redrawn
/// at most four times a second and erased when the spec is done.
struct ProgressLine<'a> {
    name: &'a str,
    started: Instant,
    last: std::cell::Cell<f64>,
}

impl ProgressLine<'_> {
    fn show(&self, p: crate::execute::Progress) {
        let now = self.started.elapsed().as_secs_f64();
        if now - self.last.get() < 0.25 || now < 0.5 {
            return;
        }
        self.last.set(now);
        let what = match p.phase {
            crate::execute::Phase::Sampling => "simulating",
            crate::execute::Phase::Cells => "propagating cell",
        };
        let of = p.total.map_or(String::new(), |t| format!(" of {t}"));
        err(&format!(
            "\r\x1b[2K{}: {what} {}{of} ({now:.0} s)",
            self.name, p.done
        ));
    }

    fn clear(&self) {
        if self.last.get() > 0.0 {
            err("\r\x1b[2K");
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Format {
    Text,
    Json,
}

/// Write to standard output; `Err(())` when it is closed (e.g. piped into
/// `head`), which ends the run quietly with [`exit::BROKEN_PIPE`].
fn out(text: &str) -> Result<(), ()> {
    use std::io::Write;
    let mut o = std::io::stdout().lock();
    writeln!(o, "{text}")
        .and_then(|_| o.flush())
        .map_err(|_| ())
}

/// Write to standard error, ignoring a closed stream (nothing else can be done).
fn err(text: &str) {
    use std::io::Write;
    let _ = std::io::stderr().lock().write_all(text.as_bytes());
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
    /// Standard output was closed before the report was written (128 + SIGPIPE, as shells report it).
    pub const BROKEN_PIPE: u8 = 141;
}

/// Read a file the front end asks for ([`crate::ReadRequest`]): only a
/// regular file (a FIFO, device or folder is refused without blocking: it is
/// opened non-blocking and inspected before any read), at most
/// `max_bytes` bytes, and, for external data, only if its real path (symbolic
/// links resolved) lies inside the requested folder.
pub fn read_request(req: &crate::ReadRequest) -> Result<Vec<u8>, String> {
    use std::io::Read;
    let mut opts = std::fs::OpenOptions::new();
    opts.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        opts.custom_flags(libc::O_NONBLOCK);
    }
    let file = opts.open(&req.path).map_err(|e| e.to_string())?;
    let meta = file.metadata().map_err(|e| e.to_string())?;
    if !meta.is_file() {
        let kind = if meta.is_dir() {
            "a folder"
        } else {
            "a special file (FIFO, device or socket)"
        };
        return Err(format!("it is {kind}, not a regular file"));
    }
    if let Some(dir) = &req.inside {
        let real = std::fs::canonicalize(&req.path).map_err(|e| e.to_string())?;
        let root = std::fs::canonicalize(dir).map_err(|e| e.to_string())?;
        if !real.starts_with(&root) {
            return Err(
                "it resolves (through a symbolic link) to a file outside the controller's folder"
                    .into(),
            );
        }
    }
    if req.whole && meta.len() > req.max_bytes {
        return Err(format!(
            "it has {} bytes, more than the limit of {}",
            meta.len(),
            req.max_bytes
        ));
    }
    let mut buf = Vec::with_capacity(meta.len().min(req.max_bytes).min(1 << 26) as usize);
    file.take(req.max_bytes)
        .read_to_end(&mut buf)
        .map_err(|e| e.to_string())?;
    Ok(buf)
}

/// A spec's source and the result of its front end.
struct Loaded {
    name: String,
    source: String,
    result: Result<crate::check::Checked, Vec<Diagnostic>>,
}

fn load(path: &Path) -> Result<Loaded, String> {
    let name = crate::diag::sanitize(&path.display().to_string());
    let bytes = read_request(&crate::ReadRequest {
        path: path.to_path_buf(),
        inside: None,
        max_bytes: crate::limits::MAX_SPEC_BYTES,
        whole: true,
    })
    .map_err(|e| format!("cannot read spec `{name}`: {e}"))?;
    let source =
        String::from_utf8(bytes).map_err(|_| format!("spec `{name}` is not UTF-8 text"))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let result = crate::front_end(&source, dir, &read_request);
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

/// 1-based line and column (in characters) of a byte offset; lines end at
/// LF, CRLF or a lone CR.
pub fn line_col(source: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(source.len());
    while !source.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = &source[..offset];
    let line = before.matches('\n').count() + before.matches('\r').count()
        - before.matches("\r\n").count()
        + 1;
    let col = before
        .rsplit(['\n', '\r'])
        .next()
        .map_or(0, |l| l.chars().count())
        + 1;
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
                        err(&format!("error: {msg}\n"));
                        code = exit::INPUT_ERROR;
                    }
                    Ok(l) => match &l.result {
                        Ok(_) => {
                            if out(&format!("ok: {}", l.name)).is_err() {
                                return ExitCode::from(exit::BROKEN_PIPE);
                            }
                        }
                        Err(d) => {
                            err(&render(d, &l.name, &l.source, width, color));
                            err(&format!("{}: {} error(s)\n", l.name, d.len()));
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
            time_limit,
        } => {
            let show_progress = std::io::stderr().is_terminal();
            let mut worst: Option<Status> = None;
            let mut input_error = false;
            let mut results = Vec::new();
            for path in &specs {
                let l = match load(path) {
                    Ok(l) => l,
                    Err(msg) => {
                        input_error = true;
                        match format {
                            Format::Text => err(&format!("error: {msg}\n")),
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
                                err(&render(&d, &l.name, &l.source, width, color));
                                err(&format!("{}: {} error(s)\n", l.name, d.len()));
                            }
                            Format::Json => results.push(diag_json(&l.name, &l.source, &d)),
                        }
                        continue;
                    }
                };
                let started = Instant::now();
                let plan = crate::lower::lower(&checked);
                let line = ProgressLine {
                    name: &l.name,
                    started,
                    last: std::cell::Cell::new(0.0),
                };
                let outcome = crate::execute::execute_with(
                    &plan,
                    &crate::execute::Control {
                        elapsed: &|| started.elapsed().as_secs_f64(),
                        time_limit,
                        progress: &|p| {
                            if show_progress {
                                line.show(p);
                            }
                        },
                    },
                );
                line.clear();
                let ms = started.elapsed().as_secs_f64() * 1e3;
                worst = worst.max(Some(outcome.verdict));
                match format {
                    Format::Text => {
                        let t = (!no_timing).then_some(ms);
                        let text = crate::report::text(&l.name, &plan, &outcome, t);
                        if out(&text).is_err() {
                            return ExitCode::from(exit::BROKEN_PIPE);
                        }
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
                if out(&serde_json::to_string_pretty(&doc).unwrap_or_default()).is_err() {
                    return ExitCode::from(exit::BROKEN_PIPE);
                }
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
