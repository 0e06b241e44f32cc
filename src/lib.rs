//! The command line, `ravel`: the only crate that touches the file system,
//! the terminal, the clock and the process exit code. It reads files for
//! the front end through [`read_request`], runs the library's pipeline and
//! writes what it returns.
#![forbid(unsafe_code)]

mod batch;
pub mod demo;
mod html;
pub mod lsp;
pub mod vnncomp;

use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};
use serde_json::{json, Value};

use ravel_syntax::diag::{render, Diagnostic};

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
        /// Spec files (.ravel), or folders searched recursively for them.
        #[arg(required = true)]
        specs: Vec<PathBuf>,
        /// Check each spec with this controller instead of its own (an .onnx
        /// file, or a folder searched recursively for them); repeatable.
        #[arg(long = "controller", value_name = "PATH")]
        controllers: Vec<PathBuf>,
    },
    /// Check, analyse and report a verdict for each spec; or, with
    /// `--network NET.onnx --vnnlib PROP.vnnlib`, run a VNN-LIB property
    /// directly and answer in VNN-COMP's result format.
    Verify {
        /// Spec files (.ravel), or folders searched recursively for them.
        #[arg(required_unless_present = "vnnlib")]
        specs: Vec<PathBuf>,
        /// The direct form: the ONNX network of `--vnnlib` (no spec file).
        #[arg(long, value_name = "NET.onnx", requires = "vnnlib", conflicts_with_all = ["specs", "controllers"])]
        network: Option<PathBuf>,
        /// The direct form: the VNN-LIB property, imported in memory as
        /// `import-vnnlib` does (one spec per input region, all run): the
        /// answer is `sat` (with the counterexample), `unsat`, `timeout` or
        /// `unknown`; exit code 1, 0, 3, 3 (2 for an error, which writes no
        /// result).
        #[arg(long, value_name = "PROP.vnnlib", requires = "network", conflicts_with_all = ["certificate", "shard", "plot", "report"])]
        vnnlib: Option<PathBuf>,
        /// The direct form: write the answer in VNN-COMP's result format to
        /// this file (atomically) instead of standard output.
        #[arg(long, value_name = "OUT", requires = "vnnlib")]
        result_file: Option<PathBuf>,
        /// Verify each spec with this controller instead of its own (an
        /// .onnx file, or a folder searched recursively for them);
        /// repeatable: every (spec, controller) pair is one result.
        #[arg(long = "controller", value_name = "PATH")]
        controllers: Vec<PathBuf>,
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
        /// Write a `ravel-certificate/1` for each result: to this file for a
        /// single result, else into this folder (created if missing), one
        /// `<spec>[--<controller>].cert.json` per (spec, controller) pair
        /// (with folders, `a~<spec>`, where names would collide); written
        /// atomically.
        #[arg(long, value_name = "PATH")]
        certificate: Option<PathBuf>,
        /// Run this many (spec, controller) pairs at once, or a single
        /// pair's cells, guided splits and samples on this many threads
        /// (default: the number of cores); the output is the same for every
        /// number.
        #[arg(long, value_name = "N", value_parser = batch::parse_jobs)]
        jobs: Option<usize>,
        /// Run only shard K of N: the pairs whose index is K − 1 modulo N
        /// (JSON output then records the shard; `ravel merge` joins them).
        #[arg(long, value_name = "K/N", value_parser = batch::parse_shard)]
        shard: Option<batch::Shard>,
        /// Which verdicts fail the run: `unsure` (FALSIFIED exits 1, UNSURE
        /// exits 3) or `falsified` (UNSURE exits 0; JUnit: skipped).
        #[arg(long, value_enum, default_value_t = batch::FailOn::Unsure)]
        fail_on: batch::FailOn,
        /// No progress on standard error.
        #[arg(long)]
        quiet: bool,
        /// Write one SVG per result into this folder (created if missing):
        /// the reachable sets per step, simulated trajectories, X0, goal,
        /// avoid sets and any counterexample, projected on two states (named
        /// as the certificates, with `.svg`).
        #[arg(long, value_name = "DIR")]
        plot: Option<PathBuf>,
        /// The two coordinates a plot shows (default 0,1): state
        /// coordinates of a closed loop, outputs of a network spec.
        #[arg(long, value_name = "I,J", value_parser = batch::parse_dims, default_value = "0,1")]
        plot_dims: (usize, usize),
        /// Write DIR/index.html: a self-contained page with a table of every
        /// pair's verdicts and each pair's plot inline (for CI artifacts).
        /// It needs the whole batch, so it is refused with --shard.
        #[arg(long, value_name = "DIR", conflicts_with = "shard")]
        report: Option<PathBuf>,
    },
    /// Rewrite specs in the canonical layout, comments kept (`--check`:
    /// change nothing, print a diff and exit 1 when a file would change).
    Fmt {
        /// Spec files (.ravel), or folders searched recursively for them.
        #[arg(required = true)]
        specs: Vec<PathBuf>,
        /// Only check: exit 1 and print a diff if a file is not formatted.
        #[arg(long)]
        check: bool,
    },
    /// Join the JSON reports of `verify --shard K/N --format json` into the
    /// report of the whole batch (every pair exactly once, in order).
    Merge {
        /// The shards' JSON reports.
        #[arg(required = true)]
        reports: Vec<PathBuf>,
        /// Which verdicts fail the run (as for `verify`).
        #[arg(long, value_enum, default_value_t = batch::FailOn::Unsure)]
        fail_on: batch::FailOn,
        /// The merged report's format: the JSON document, or the JUnit XML
        /// document of the whole batch (the shards' `--fail-on` must match).
        #[arg(long, value_enum, default_value_t = batch::MergeFormat::Json)]
        format: batch::MergeFormat,
    },
    /// Run every instance `onnx,vnnlib,timeout` of a VNN-COMP instance list
    /// (paths relative to its folder or --root) with its timeout, printing
    /// `network,property,result,seconds` per instance. Every row is checked
    /// first; exit code 2 if a row is unusable (nothing runs) or an
    /// instance gave an error (its result is `error`), else 0.
    Vnncomp {
        /// The instance list (`instances.csv`).
        instances: PathBuf,
        /// The folder the rows' paths are relative to (default: the list's folder).
        #[arg(long, value_name = "DIR")]
        root: Option<PathBuf>,
        /// Also write the results to this file (atomically).
        #[arg(long, value_name = "RESULTS.csv")]
        out: Option<PathBuf>,
        /// Threads for each instance's analysis (default: the number of cores).
        #[arg(long, value_name = "N", value_parser = batch::parse_jobs)]
        jobs: Option<usize>,
    },
    /// Translate a VNN-LIB property into ravel network specs (printed, or
    /// written with --output), checked against the network before they are
    /// shown: one spec, or one per input region when the property's input
    /// is a disjunction (`FILE.1.ravel`, `FILE.2.ravel` …, which --output
    /// then needs). Exit code 0, or 2 with the line of what is not supported.
    ImportVnnlib {
        /// The property file (.vnnlib).
        property: PathBuf,
        /// The ONNX network the property is about.
        #[arg(long, value_name = "NET.onnx")]
        network: PathBuf,
        /// Write the spec to this file (the model path in it is then made
        /// relative to the file's folder) instead of standard output.
        #[arg(long, value_name = "FILE")]
        output: Option<PathBuf>,
    },
    /// Serve the Language Server Protocol on standard input and output
    /// (diagnostics as you type, formatting, hover, go to definition,
    /// completion), for an editor's LSP client.
    Lsp,
    /// Re-check certificates written by `verify --certificate`, without
    /// trusting the analysis: VALID, INVALID (with the first false claim) or
    /// UNSUPPORTED. Exit code 0 (all valid), 1 (some invalid), 2 (some
    /// unreadable or unsupported; takes precedence).
    Certify {
        /// Certificate files.
        #[arg(required = true)]
        certificates: Vec<PathBuf>,
        /// The spec (default: the path recorded in the certificate, relative
        /// to the certificate's folder).
        #[arg(long, value_name = "PATH")]
        spec: Option<PathBuf>,
        /// The controller (default: the path recorded in the certificate,
        /// relative to the certificate's folder).
        #[arg(long, value_name = "PATH")]
        controller: Option<PathBuf>,
    },
}

fn parse_seconds(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err("expected a non-negative number of seconds".into()),
    }
}

/// Whether a progress line is drawn at `now` (seconds since the run
/// started), last drawn at `last`: not before half a second, then at most
/// four times a second.
fn progress_due(now: f64, last: Option<f64>) -> bool {
    now >= 0.5 && last.is_none_or(|l| now - l >= 0.25)
}

/// A progress line on standard error (only when it is a terminal), drawn
/// once the spec has run for half a second, redrawn at most four times a
/// second, and erased when the spec is done. Execution reports what it is
/// doing now and then; between reports (one long cell, one long sample
/// run) a ticker redraws the last report with the time, so a long run
/// shows the line even when execution says nothing new.
struct ProgressLine<'a> {
    name: &'a str,
    /// Seconds since the run started.
    clock: &'a (dyn Fn() -> f64 + Sync),
    /// Where the line goes (standard error).
    write: &'a (dyn Fn(&str) + Sync),
    /// When the line was last drawn, and the last report.
    state: std::sync::Mutex<(Option<f64>, Option<ravel::execute::Progress>)>,
}

impl ProgressLine<'_> {
    /// Execution's report: drawn if due, kept for the ticker.
    fn show(&self, p: ravel::execute::Progress) {
        self.draw(Some(p));
    }

    /// The ticker: the last report again, if due.
    fn tick(&self) {
        self.draw(None);
    }

    fn draw(&self, report: Option<ravel::execute::Progress>) {
        let now = (self.clock)();
        let mut state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        if report.is_some() {
            state.1 = report;
        }
        if !progress_due(now, state.0) {
            return;
        }
        state.0 = Some(now);
        let what = match state.1 {
            Some(p) => {
                let phase = match p.phase {
                    ravel::execute::Phase::Sampling => "simulating",
                    ravel::execute::Phase::Cells => "propagating cell",
                    ravel::execute::Phase::Observations => "selecting actions, observation",
                };
                let of = p.total.map_or(String::new(), |t| format!(" of {t}"));
                format!("{phase} {}{of}", p.done)
            }
            None => "starting".to_string(),
        };
        (self.write)(&format!("\r\x1b[2K{}: {what} ({now:.0} s)", self.name));
    }

    fn clear(&self) {
        let state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        if state.0.is_some() {
            (self.write)("\r\x1b[2K");
        }
    }
}

/// Run `work` while a ticker thread calls `tick` every tenth of a second
/// (none when `on` is false); the ticker has stopped when this returns.
fn with_ticker<T>(on: bool, tick: &(dyn Fn() + Sync), work: impl FnOnce() -> T) -> T {
    if !on {
        return work();
    }
    let done = std::sync::atomic::AtomicBool::new(false);
    std::thread::scope(|scope| {
        let ticker = scope.spawn(|| {
            while !done.load(std::sync::atomic::Ordering::Acquire) {
                std::thread::park_timeout(std::time::Duration::from_millis(100));
                if !done.load(std::sync::atomic::Ordering::Acquire) {
                    tick();
                }
            }
        });
        let out = work();
        done.store(true, std::sync::atomic::Ordering::Release);
        ticker.thread().unpark();
        out
    })
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Format {
    /// A report per pair for people, and a summary line.
    Text,
    /// One JSON document (`ravel-report/1`).
    Json,
    /// One JSON result per line, then a summary line.
    Jsonl,
    /// JUnit XML: a test suite per pair, a test case per property.
    Junit,
    /// CSV of robust action selections (network specs with `select`): one
    /// row per observation and action, after a header line.
    Csv,
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

pub use ravel_files::read_request;

/// A spec's source and the result of its front end.
struct Loaded {
    /// The spec's path (as the JSON `spec` field).
    name: String,
    /// The spec's path, and the controller's when it was overridden (for people).
    display: String,
    source: String,
    result: Result<ravel::check::Task, Vec<Diagnostic>>,
}

/// Files with extension `ext` under `path` (a file is itself; a folder is
/// searched recursively, in sorted order, without following symbolic links
/// to folders); an error for a folder without any.
fn expand(path: &Path, ext: &str) -> Result<Vec<PathBuf>, String> {
    fn walk(dir: &Path, ext: &str, depth: usize, out: &mut Vec<PathBuf>) -> Result<(), String> {
        if depth > 32 {
            return Ok(());
        }
        let shown = ravel_syntax::diag::sanitize(&dir.display().to_string());
        let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
            .map_err(|e| format!("cannot read folder `{shown}`: {e}"))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        entries.sort();
        for e in entries {
            let meta = std::fs::symlink_metadata(&e).map_err(|x| x.to_string())?;
            if meta.is_dir() {
                walk(&e, ext, depth + 1, out)?;
            } else if e.extension().is_some_and(|x| x == ext) {
                out.push(e);
            }
        }
        Ok(())
    }
    if !path.is_dir() {
        return Ok(vec![path.to_path_buf()]);
    }
    let mut out = Vec::new();
    walk(path, ext, 0, &mut out)?;
    if out.is_empty() {
        return Err(format!(
            "no .{ext} file in folder `{}`",
            ravel_syntax::diag::sanitize(&path.display().to_string())
        ));
    }
    Ok(out)
}

/// Every (spec, controller) pair the arguments name: each spec with each
/// controller given, or with its own when none is. Errors are collected, so
/// one bad argument never hides the others.
fn pairs(
    specs: &[PathBuf],
    controllers: &[PathBuf],
) -> (Vec<(PathBuf, Option<PathBuf>)>, Vec<String>) {
    let mut errors = Vec::new();
    let mut files = Vec::new();
    for s in specs {
        match expand(s, "ravel") {
            Ok(v) => files.extend(v),
            Err(e) => errors.push(e),
        }
    }
    let mut ctrls = Vec::new();
    for c in controllers {
        match expand(c, "onnx") {
            Ok(v) => ctrls.extend(v.into_iter().map(Some)),
            Err(e) => errors.push(e),
        }
    }
    if controllers.is_empty() {
        ctrls.push(None);
    }
    let pairs = files
        .iter()
        .flat_map(|s| ctrls.iter().map(move |c| (s.clone(), c.clone())))
        .collect();
    (pairs, errors)
}

fn load_with(path: &Path, controller: Option<&Path>) -> Result<Loaded, String> {
    let name = ravel_syntax::diag::sanitize(&path.display().to_string());
    let bytes = read_request(&ravel::ReadRequest {
        path: path.to_path_buf(),
        inside: None,
        max_bytes: ravel_base::limits::MAX_SPEC_BYTES,
        whole: true,
    })
    .map_err(|e| format!("cannot read spec `{name}`: {e}"))?;
    let source =
        String::from_utf8(bytes).map_err(|_| format!("spec `{name}` is not UTF-8 text"))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let result = ravel::front_end_task(&source, dir, &read_request, controller);
    let display = match controller {
        Some(c) => format!(
            "{name} with controller {}",
            ravel_syntax::diag::sanitize(&c.display().to_string())
        ),
        None => name.clone(),
    };
    Ok(Loaded {
        display,
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

pub use ravel_syntax::diag::line_col;

/// A JSON document from a file (a regular file of at most 512 MiB).
fn read_json(file: &Path) -> Result<Value, String> {
    let bytes = read_request(&ravel::ReadRequest {
        path: file.to_path_buf(),
        inside: None,
        max_bytes: ravel_base::limits::MAX_CONTROLLER_BYTES,
        whole: true,
    })
    .map_err(|e| format!("cannot read: {e}"))?;
    serde_json::from_slice(&bytes).map_err(|e| format!("not JSON: {e}"))
}

/// The file names (without extension) of the results of a batch's (spec,
/// controller) pairs, computed from the whole pair list (so a shard names a
/// pair as the whole batch does): `<spec stem>` or `<spec stem>--<controller
/// stem>`; where names collide (compared without case, for file systems that
/// ignore it), the colliding pairs' names take their spec's folders, nearest
/// first, joined by `~` (`a~double_integrator`), one folder at a time until
/// they differ, and then, if the specs' paths alone cannot tell them apart,
/// their controller's folders (`s--x~c`). An error names two pairs that no
/// folder tells apart (the same pair given twice).
fn output_names(pairs: &[(PathBuf, Option<PathBuf>)]) -> Result<Vec<String>, String> {
    /// A path's folders (outermost first; `..` as `up`) and its file stem.
    fn parts(p: &Path, fallback: &str) -> (Vec<String>, String) {
        let stem = p.file_stem().map_or_else(
            || fallback.to_string(),
            |s| s.to_string_lossy().into_owned(),
        );
        let folders = p
            .parent()
            .into_iter()
            .flat_map(Path::components)
            .filter_map(|c| match c {
                std::path::Component::Normal(s) => Some(s.to_string_lossy().into_owned()),
                std::path::Component::ParentDir => Some("up".to_string()),
                _ => None,
            })
            .collect();
        (folders, stem)
    }
    fn join((folders, stem): &(Vec<String>, String), depth: usize) -> String {
        let mut s: Vec<&str> = folders[folders.len() - depth..]
            .iter()
            .map(String::as_str)
            .collect();
        s.push(stem);
        s.join("~")
    }
    let split: Vec<_> = pairs
        .iter()
        .map(|(s, c)| {
            (
                parts(s, "spec"),
                c.as_deref().map(|c| parts(c, "controller")),
            )
        })
        .collect();
    let mut depth = vec![(0usize, 0usize); pairs.len()];
    let name = |i: usize, (ds, dc): (usize, usize)| {
        let (s, c) = &split[i];
        match c {
            Some(c) => format!("{}--{}", join(s, ds), join(c, dc)),
            None => join(s, ds),
        }
    };
    loop {
        let mut groups: BTreeMap<String, Vec<usize>> = BTreeMap::new();
        for (i, &d) in depth.iter().enumerate() {
            groups.entry(name(i, d).to_lowercase()).or_default().push(i);
        }
        let colliding: Vec<&Vec<usize>> = groups.values().filter(|g| g.len() > 1).collect();
        if colliding.is_empty() {
            return Ok((0..pairs.len()).map(|i| name(i, depth[i])).collect());
        }
        // a spec folder more where one is left, else a controller folder more
        let mut grown = false;
        for g in &colliding {
            for &i in *g {
                if depth[i].0 < split[i].0 .0.len() {
                    depth[i].0 += 1;
                    grown = true;
                }
            }
        }
        if !grown {
            for g in &colliding {
                for &i in *g {
                    if split[i].1.as_ref().is_some_and(|c| depth[i].1 < c.0.len()) {
                        depth[i].1 += 1;
                        grown = true;
                    }
                }
            }
        }
        if !grown {
            let (a, b) = (colliding[0][0], colliding[0][1]);
            let show = |i: usize| {
                let (s, c) = &pairs[i];
                let s = ravel_syntax::diag::sanitize(&s.display().to_string());
                match c {
                    Some(c) => format!(
                        "`{s}` with `{}`",
                        ravel_syntax::diag::sanitize(&c.display().to_string())
                    ),
                    None => format!("`{s}`"),
                }
            };
            return Err(format!(
                "{} and {} would write their certificates or plots to the same file, and no folder of their paths tells them apart (the same pair given twice?); nothing was run",
                show(a),
                show(b),
            ));
        }
    }
}

/// Write `bytes` to `file` atomically: into a new temporary file beside it
/// (`.NAME.tmp-PID-N`, `NAME` cut to 64 characters, created exclusively), flushed to disk, then renamed
/// over `file`, so a reader sees the old file or the whole new one, never
/// half of one; an existing file's permissions are kept. On failure the
/// temporary file is removed and `file` is left as it was.
fn write_atomically(file: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let Some(name) = file.file_name() else {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "the path names no file",
        ));
    };
    let dir = match file.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    // the name's start only: a long name must not make the temporary one
    // longer than the file system allows
    let start: String = name.to_string_lossy().chars().take(64).collect();
    let tmp = dir.join(format!(".{start}.tmp-{}-{n}", std::process::id()));
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)?;
    let fill = |f: &mut std::fs::File| {
        f.write_all(bytes)?;
        if let Ok(old) = std::fs::metadata(file) {
            f.set_permissions(old.permissions())?;
        }
        f.sync_all()
    };
    let written = fill(&mut f).and_then(|()| {
        drop(f);
        std::fs::rename(&tmp, file)
    });
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// Where a certificate's recorded path is read: relative to the
/// certificate's own folder (as `verify` records it); a relative path not
/// found there but found in the working folder is read from there (a
/// certificate written before paths were recorded relative to it), with a
/// note saying so. Absolute paths are read as they are.
fn recorded_path(cert_dir: &Path, recorded: &str) -> (PathBuf, Option<String>) {
    let p = Path::new(recorded);
    if p.is_absolute() {
        return (p.to_path_buf(), None);
    }
    let beside = cert_dir.join(p);
    if beside.exists() || !p.exists() {
        return (beside, None);
    }
    let note = format!(
        "note: `{}` is not beside the certificate; read as recorded, from the working folder (a certificate written before paths were recorded relative to it)",
        ravel_syntax::diag::sanitize(recorded)
    );
    (p.to_path_buf(), Some(note))
}

/// The first 12 hex digits of a SHA-256, for people.
fn short_hash(h: &str) -> String {
    ravel_syntax::diag::sanitize(&h.chars().take(12).collect::<String>())
}

/// One certificate being checked: its name, then the files checked and the
/// notes, printed after the answer's line.
struct Certifying {
    /// The certificate file's name, sanitised.
    name: String,
    files: Vec<String>,
    notes: Vec<String>,
}

/// An answer of `certify`: the exit code and the text to print.
type Answered = (u8, String);

impl Certifying {
    /// `head`, then the files and notes, one per line.
    fn with(&self, head: String) -> String {
        let mut text = head;
        for l in self.files.iter().chain(&self.notes) {
            text += &format!("\n  {l}");
        }
        text
    }

    /// UNREADABLE, and why.
    fn unreadable(&self, why: String) -> Answered {
        (
            exit::INPUT_ERROR,
            self.with(format!("UNREADABLE  {}: {why}", self.name)),
        )
    }

    /// INVALID, and why.
    fn invalid(&self, why: String) -> Answered {
        (
            exit::FALSIFIED,
            self.with(format!("INVALID     {}: {why}", self.name)),
        )
    }

    /// The spec and controller paths: as given (relative to the working
    /// folder), else as recorded (relative to the certificate's folder).
    fn paths(
        &mut self,
        cert: &Value,
        file: &Path,
        spec: Option<&Path>,
        controller: Option<&Path>,
    ) -> Result<(PathBuf, PathBuf), Answered> {
        // empty for a certificate in the working folder: paths stay as recorded
        let cert_dir = file.parent().unwrap_or(Path::new(""));
        let mut recorded = |key: &str| {
            let (path, note) = recorded_path(
                cert_dir,
                cert.get(key)
                    .and_then(|v| v.get("path"))
                    .and_then(Value::as_str)?,
            );
            self.notes.extend(note);
            Some(path)
        };
        let spec_path = match spec {
            Some(s) => Some(s.to_path_buf()),
            None => recorded("spec"),
        };
        let ctrl_path = match controller {
            Some(c) => Some(c.to_path_buf()),
            None => recorded("controller"),
        };
        let Some(spec_path) = spec_path else {
            return Err(self.unreadable("no spec path recorded; pass --spec".into()));
        };
        let Some(ctrl_path) = ctrl_path else {
            return Err(self.unreadable("no controller path recorded; pass --controller".into()));
        };
        Ok((spec_path, ctrl_path))
    }

    /// Read the spec and run the front end with the controller; the task
    /// and the spec's SHA-256.
    fn front_end(
        &mut self,
        spec_path: &Path,
        ctrl_path: &Path,
    ) -> Result<(ravel::check::Task, String), Answered> {
        let spec_name = ravel_syntax::diag::sanitize(&spec_path.display().to_string());
        let ctrl_name = ravel_syntax::diag::sanitize(&ctrl_path.display().to_string());
        let source = match read_request(&ravel::ReadRequest {
            path: spec_path.to_path_buf(),
            inside: None,
            max_bytes: ravel_base::limits::MAX_SPEC_BYTES,
            whole: true,
        }) {
            Ok(b) => b,
            Err(e) => return Err(self.unreadable(format!("cannot read spec `{spec_name}`: {e}"))),
        };
        let spec_sha = ravel::check::sha256_hex(&source);
        self.files.push(format!(
            "spec        {spec_name} (SHA-256 {})",
            short_hash(&spec_sha)
        ));
        let Ok(source) = String::from_utf8(source) else {
            return Err(self.unreadable(format!("spec `{spec_name}` is not UTF-8 text")));
        };
        let dir = spec_path.parent().unwrap_or(Path::new("."));
        match ravel::front_end_task(&source, dir, &read_request, Some(ctrl_path)) {
            Ok(t) => Ok((t, spec_sha)),
            Err(d) => Err(self.unreadable(format!(
                "spec `{spec_name}` with controller `{ctrl_name}` does not check ({} error(s); run `ravel check`)",
                d.len()
            ))),
        }
    }

    /// The controller and its network are the certified ones, and the
    /// spec's problem is the recorded one, number for number (the text may
    /// differ: comments, layout; a note says so).
    fn same_problem(
        &mut self,
        cert: &Value,
        plan: &ravel::lower::Plan,
        ctrl_path: &Path,
        spec_sha: &str,
    ) -> Result<(), Answered> {
        let hash = |key: &str, field: &str| {
            cert.get(key)
                .and_then(|v| v.get(field))
                .and_then(Value::as_str)
                .unwrap_or("")
                .to_string()
        };
        let ctrl_name = ravel_syntax::diag::sanitize(&ctrl_path.display().to_string());
        self.files.push(format!(
            "controller  {ctrl_name} (SHA-256 {})",
            short_hash(plan.controller_sha256())
        ));
        let text_differs = spec_sha != hash("spec", "sha256");
        let text_note = format!(
            "note: the spec's text differs from the certified one (SHA-256 {}, certified {})",
            short_hash(spec_sha),
            short_hash(&hash("spec", "sha256"))
        );
        if let Err(why) = ravel::certified_problem(cert, plan) {
            if text_differs && matches!(why, ravel::NotCertified::Problem(_)) {
                self.notes.push(text_note);
            }
            return Err(self.invalid(why.to_string()));
        }
        if text_differs {
            self.notes
                .push(format!("{text_note}; its problem is identical"));
        }
        Ok(())
    }

    /// The checker's answer on the certificate.
    fn check(mut self, cert: &Value, plan: &ravel::lower::Plan, spec_path: &Path) -> Answered {
        use ravel_certify::Answer;
        let spec_name = ravel_syntax::diag::sanitize(&spec_path.display().to_string());
        let report = ravel_certify::check(cert, plan.network());
        let (code, head) = match &report.answer {
            Answer::Valid => (exit::VERIFIED, "VALID      ".to_string()),
            Answer::Invalid(_) => (exit::FALSIFIED, "INVALID    ".to_string()),
            Answer::Unsupported(_) => (exit::INPUT_ERROR, "UNSUPPORTED".to_string()),
            Answer::Unreadable(_) => (exit::INPUT_ERROR, "UNREADABLE ".to_string()),
        };
        let mut text = format!("{head} {} ({spec_name}", self.name);
        if report.cells > 0 && report.steps > 0 {
            text += &format!(", {} cell(s) × {} step(s)", report.cells, report.steps);
        } else if report.cells > 0 {
            text += &format!(", {} cell(s)", report.cells);
        } else if report.subproblems > 0 {
            text += &format!(", {} split subproblem(s)", report.subproblems);
        }
        text += ")";
        match &report.answer {
            Answer::Valid => {}
            Answer::Invalid(m) | Answer::Unsupported(m) | Answer::Unreadable(m) => {
                text += &format!("\n  {}", ravel_syntax::diag::sanitize_to(m, 600));
            }
        }
        self.notes.extend(report.properties.iter().cloned());
        (code, self.with(text))
    }
}

/// Check one certificate file: the exit code it earns and the text to print.
/// Every answer that got that far names the spec and the controller it
/// checked (path and SHA-256 prefix).
fn certify_one(file: &Path, spec: Option<&Path>, controller: Option<&Path>) -> Answered {
    let mut c = Certifying {
        name: ravel_syntax::diag::sanitize(&file.display().to_string()),
        files: Vec::new(),
        notes: Vec::new(),
    };
    let cert = match read_json(file) {
        Ok(v) => v,
        Err(e) => return c.unreadable(e),
    };
    let (spec_path, ctrl_path) = match c.paths(&cert, file, spec, controller) {
        Ok(p) => p,
        Err(answer) => return answer,
    };
    let (task, spec_sha) = match c.front_end(&spec_path, &ctrl_path) {
        Ok(t) => t,
        Err(answer) => return answer,
    };
    let plan = ravel::lower::lower(&task);
    if let Err(answer) = c.same_problem(&cert, &plan, &ctrl_path, &spec_sha) {
        return answer;
    }
    c.check(&cert, &plan, &spec_path)
}

/// A line diff of `a` and `b` (longest common subsequence), `-`/`+` lines
/// with one line of context; a whole-file replacement when the files are
/// too long to compare line by line.
fn diff(name: &str, a: &str, b: &str) -> String {
    let (x, y): (Vec<&str>, Vec<&str>) = (a.lines().collect(), b.lines().collect());
    let mut out = format!("--- {name}\n+++ {name} (formatted)\n");
    if x.len().saturating_mul(y.len()) > 4_000_000 {
        out.extend(x.iter().map(|l| format!("-{l}\n")));
        out.extend(y.iter().map(|l| format!("+{l}\n")));
        return out;
    }
    // lcs[i][j]: common subsequence length of x[i..] and y[j..]
    let mut lcs = vec![vec![0u32; y.len() + 1]; x.len() + 1];
    for i in (0..x.len()).rev() {
        for j in (0..y.len()).rev() {
            lcs[i][j] = if x[i] == y[j] {
                lcs[i + 1][j + 1] + 1
            } else {
                lcs[i + 1][j].max(lcs[i][j + 1])
            };
        }
    }
    let (mut i, mut j) = (0, 0);
    while i < x.len() || j < y.len() {
        if i < x.len() && j < y.len() && x[i] == y[j] {
            i += 1;
            j += 1;
        } else if i < x.len() && (j == y.len() || lcs[i + 1][j] >= lcs[i][j + 1]) {
            out += &format!("{:>5} -{}\n", i + 1, x[i]);
            i += 1;
        } else {
            out += &format!("{:>5} +{}\n", j + 1, y[j]);
            j += 1;
        }
    }
    out
}

/// `ravel fmt`.
fn fmt_files(specs: &[PathBuf], check: bool) -> ExitCode {
    let mut code = exit::VERIFIED;
    let mut files = Vec::new();
    for s in specs {
        match expand(s, "ravel") {
            Ok(v) => files.extend(v),
            Err(e) => {
                err(&format!("error: {e}\n"));
                code = exit::INPUT_ERROR;
            }
        }
    }
    for f in &files {
        let name = ravel_syntax::diag::sanitize(&f.display().to_string());
        let bytes = match read_request(&ravel::ReadRequest {
            path: f.clone(),
            inside: None,
            max_bytes: ravel_base::limits::MAX_SPEC_BYTES,
            whole: true,
        }) {
            Ok(b) => b,
            Err(e) => {
                err(&format!("error: cannot read `{name}`: {e}\n"));
                code = exit::INPUT_ERROR;
                continue;
            }
        };
        let Ok(source) = String::from_utf8(bytes) else {
            err(&format!("error: `{name}` is not UTF-8 text\n"));
            code = exit::INPUT_ERROR;
            continue;
        };
        let formatted = match ravel_syntax::fmt::format(&source) {
            Ok(t) => t,
            Err(ravel_syntax::fmt::Error::Syntax(d)) => {
                err(&render(
                    &d,
                    &name,
                    &source,
                    100,
                    std::io::stderr().is_terminal(),
                ));
                err(&format!("{name}: not formatted (it does not parse)\n"));
                code = exit::INPUT_ERROR;
                continue;
            }
            Err(ravel_syntax::fmt::Error::Changed) => {
                err(&format!(
                    "error: `{name}`: formatting would change its meaning (a ravel bug, please report it); the file is left as it is\n"
                ));
                code = exit::INPUT_ERROR;
                continue;
            }
        };
        if formatted == source {
            continue;
        }
        if check {
            if out(&diff(&name, &source, &formatted)).is_err() {
                return ExitCode::from(exit::BROKEN_PIPE);
            }
            if code == exit::VERIFIED {
                code = exit::FALSIFIED;
            }
            continue;
        }
        // write beside, then rename: a crash never leaves half a spec (and a
        // symbolic link keeps pointing at the formatted file)
        let target = std::fs::canonicalize(f).unwrap_or_else(|_| f.clone());
        if let Err(e) = write_atomically(&target, formatted.as_bytes()) {
            err(&format!("error: cannot write `{name}`: {e}\n"));
            code = exit::INPUT_ERROR;
        } else if out(&format!("formatted {name}")).is_err() {
            return ExitCode::from(exit::BROKEN_PIPE);
        }
    }
    ExitCode::from(code)
}

/// `path` as seen from the folder `dir`, for a file written into `dir`
/// that names `path`: a relative path (`..` where they part) computed from
/// the real folders (symbolic links to folders resolved; the file's own
/// name kept), or `path` made absolute when there is none (different roots)
/// or a folder cannot be resolved.
pub(crate) fn relative_to(dir: &Path, path: &Path) -> PathBuf {
    let absolute = || std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let real = match (path.parent(), path.file_name()) {
        (Some(p), Some(n)) => {
            let p = if p.as_os_str().is_empty() {
                Path::new(".")
            } else {
                p
            };
            p.canonicalize().map(|p| p.join(n))
        }
        _ => path.canonicalize(),
    };
    let (Ok(d), Ok(p)) = (dir.canonicalize(), real) else {
        return absolute();
    };
    let (dc, pc): (Vec<_>, Vec<_>) = (d.components().collect(), p.components().collect());
    if dc.first() != pc.first() {
        return p;
    }
    let common = dc.iter().zip(&pc).take_while(|(a, b)| a == b).count();
    let mut out = PathBuf::new();
    for _ in common..dc.len() {
        out.push("..");
    }
    for c in &pc[common..] {
        out.push(c);
    }
    out
}

/// A file's stem as if it were not compressed: `net.onnx.gz` → `net`, as
/// `net.onnx` → `net`.
fn plain_stem(p: &Path) -> Option<String> {
    let p = if ravel_files::gzip_named(p) {
        p.with_extension("")
    } else {
        p.to_path_buf()
    };
    p.file_stem().map(|s| s.to_string_lossy().into_owned())
}

/// The files `import-vnnlib --output FILE` writes for `count` specs:
/// `FILE` for one, else `STEM.1.EXT`, `STEM.2.EXT` … beside it
/// (`X.ravel` → `X.1.ravel`).
pub fn region_files(file: &Path, count: usize) -> Vec<PathBuf> {
    if count == 1 {
        return vec![file.to_path_buf()];
    }
    let stem = file
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ext = file
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    (1..=count)
        .map(|k| file.with_file_name(format!("{stem}.{k}{ext}")))
        .collect()
}

/// `ravel import-vnnlib`: the specs (one per input region), checked by the
/// front end with the network.
fn import_vnnlib(property: &Path, network: &Path, output: Option<&Path>, color: bool) -> ExitCode {
    let name = ravel_syntax::diag::sanitize(&property.display().to_string());
    let fail = |msg: String| {
        err(&format!("error: {msg}\n"));
        ExitCode::from(exit::INPUT_ERROR)
    };
    let nowhere = |message: String, hint: &str| {
        let d = Diagnostic {
            span: None,
            ..Diagnostic::new(
                ravel_syntax::diag::Code::Vnnlib,
                ravel_syntax::ast::Span::new(0, 0),
                message,
            )
            .hint(hint)
        };
        err(&render(&[d], &name, "", 100, color));
        ExitCode::from(exit::INPUT_ERROR)
    };
    let bytes = match read_request(&ravel::ReadRequest {
        path: property.to_path_buf(),
        inside: None,
        max_bytes: ravel_base::limits::MAX_SPEC_BYTES,
        whole: true,
    }) {
        Ok(b) => b,
        Err(e) => {
            return nowhere(
                format!("cannot read the property `{name}`: {e}"),
                "check the path",
            )
        }
    };
    let Ok(text) = String::from_utf8(bytes) else {
        return nowhere(
            format!("the property `{name}` is not UTF-8 text"),
            "VNN-LIB files are plain text",
        );
    };
    let dir = match output.and_then(Path::parent) {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    // the output's folder must exist (else the network, read relative to
    // it, would be reported missing instead)
    if output.is_some() && !dir.is_dir() {
        return fail(format!(
            "cannot write into `{}`: no such folder (create it first)",
            ravel_syntax::diag::sanitize(&dir.display().to_string())
        ));
    }
    let model = if output.is_some() {
        relative_to(&dir, network)
    } else {
        network.to_path_buf()
    };
    let stem = plain_stem(property).unwrap_or_default();
    let ident: String = stem
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    let ident = match ident.chars().next() {
        Some(c) if c.is_ascii_alphabetic() || c == '_' => ident,
        _ => format!("n_{ident}"),
    };
    let specs = match ravel::vnnlib::import(
        &text,
        &model.display().to_string(),
        &ident,
        &property.display().to_string(),
    ) {
        Ok(s) => s,
        Err(e) => {
            let end = (e.offset + 1).min(text.len()).max(e.offset);
            let d = Diagnostic::new(
                ravel_syntax::diag::Code::Vnnlib,
                ravel_syntax::ast::Span::new(e.offset, end),
                e.message,
            )
            .label("here")
            .hint("ravel imports linear constraints over the X_i or the Y_j under and/or (see the README, VNN-LIB properties)");
            err(&render(&[d], &name, &text, 100, color));
            return ExitCode::from(exit::INPUT_ERROR);
        }
    };
    // each spec must check with the network (sizes included) before anyone sees it
    for (k, spec) in specs.iter().enumerate() {
        if let Err(d) = ravel::front_end_task(spec, &dir, &read_request, None) {
            err(&render(&d, "(imported spec)", spec, 100, color));
            return fail(format!(
                "the spec imported from `{name}` (input region {} of {}) does not check",
                k + 1,
                specs.len()
            ));
        }
    }
    match output {
        Some(file) => {
            let files = region_files(file, specs.len());
            for (f, spec) in files.iter().zip(&specs) {
                if let Err(e) = write_atomically(f, spec.as_bytes()) {
                    return fail(format!(
                        "cannot write `{}`: {e}",
                        ravel_syntax::diag::sanitize(&f.display().to_string())
                    ));
                }
            }
            if files.len() > 1 {
                let mut text = format!(
                    "the property's input is a union of {} regions: one spec per region (the property holds only if every one is VERIFIED; any FALSIFIED one is a counterexample):",
                    files.len()
                );
                for f in &files {
                    text += &format!(
                        "\n  {}",
                        ravel_syntax::diag::sanitize(&f.display().to_string())
                    );
                }
                if out(&text).is_err() {
                    return ExitCode::from(exit::BROKEN_PIPE);
                }
            }
            ExitCode::from(exit::VERIFIED)
        }
        None => match specs.as_slice() {
            [spec] => {
                if out(spec.trim_end()).is_err() {
                    return ExitCode::from(exit::BROKEN_PIPE);
                }
                ExitCode::from(exit::VERIFIED)
            }
            _ => fail(format!(
                "the input of `{name}` is a union of {} regions, one spec each: pass --output FILE.ravel to write them as FILE.1.ravel … FILE.{}.ravel",
                specs.len(),
                specs.len()
            )),
        },
    }
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
        Cmd::Lsp => {
            let code = lsp::serve(
                std::io::BufReader::new(std::io::stdin()),
                &mut std::io::stdout(),
            );
            ExitCode::from(u8::try_from(code).unwrap_or(1))
        }
        Cmd::Check { specs, controllers } => {
            let mut code = exit::VERIFIED;
            let (pairs, errors) = pairs(&specs, &controllers);
            for e in &errors {
                err(&format!("error: {e}\n"));
                code = exit::INPUT_ERROR;
            }
            for (path, controller) in &pairs {
                match load_with(path, controller.as_deref()) {
                    Err(msg) => {
                        err(&format!("error: {msg}\n"));
                        code = exit::INPUT_ERROR;
                    }
                    Ok(l) => match &l.result {
                        Ok(_) => {
                            if out(&format!("ok: {}", l.display)).is_err() {
                                return ExitCode::from(exit::BROKEN_PIPE);
                            }
                        }
                        Err(d) => {
                            err(&render(d, &l.display, &l.source, width, color));
                            err(&format!("{}: {} error(s)\n", l.display, d.len()));
                            code = exit::INPUT_ERROR;
                        }
                    },
                }
            }
            ExitCode::from(code)
        }
        Cmd::Certify {
            certificates,
            spec,
            controller,
        } => {
            let mut worst = exit::VERIFIED;
            for file in &certificates {
                let (code, text) = certify_one(file, spec.as_deref(), controller.as_deref());
                if out(&text).is_err() {
                    return ExitCode::from(exit::BROKEN_PIPE);
                }
                worst = match (worst, code) {
                    (exit::INPUT_ERROR, _) | (_, exit::INPUT_ERROR) => exit::INPUT_ERROR,
                    (exit::FALSIFIED, _) | (_, exit::FALSIFIED) => exit::FALSIFIED,
                    _ => exit::VERIFIED,
                };
            }
            ExitCode::from(worst)
        }
        Cmd::Verify {
            network: Some(network),
            vnnlib: Some(vnnlib),
            result_file,
            time_limit,
            jobs,
            ..
        } => {
            let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
            vnncomp::verify_direct(
                &network,
                &vnnlib,
                time_limit,
                result_file.as_deref(),
                jobs.unwrap_or(cores),
                color,
            )
        }
        Cmd::Vnncomp {
            instances,
            root,
            out,
            jobs,
        } => {
            let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
            vnncomp::vnncomp(
                &instances,
                root.as_deref(),
                out.as_deref(),
                jobs.unwrap_or(cores),
                color,
            )
        }
        Cmd::Verify {
            specs,
            controllers,
            format,
            no_timing,
            timing,
            time_limit,
            certificate,
            jobs,
            shard,
            fail_on,
            quiet,
            plot,
            plot_dims,
            report,
            ..
        } => {
            let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
            let opts = batch::Options {
                format,
                no_timing,
                timing,
                time_limit,
                certificate,
                fail_on,
                jobs: jobs.unwrap_or(cores),
                shard,
                progress: !quiet && std::io::stderr().is_terminal(),
                color,
                plot,
                plot_dims,
                report,
            };
            batch::verify(&specs, &controllers, &opts)
        }
        Cmd::Merge {
            reports,
            fail_on,
            format,
        } => batch::merge(&reports, fail_on, format),
        Cmd::Fmt { specs, check } => fmt_files(&specs, check),
        Cmd::ImportVnnlib {
            property,
            network,
            output,
        } => import_vnnlib(&property, &network, output.as_deref(), color),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_progress_line_waits_half_a_second_then_redraws_four_times_a_second() {
        assert!(!progress_due(0.0, None));
        assert!(!progress_due(0.49, None));
        assert!(progress_due(0.5, None));
        assert!(!progress_due(0.7, Some(0.5)));
        assert!(progress_due(0.75, Some(0.5)));
        // a clock of 1 ms ticks and a line that records what it writes
        let now = std::sync::atomic::AtomicU64::new(0);
        let clock = || now.load(std::sync::atomic::Ordering::Relaxed) as f64 / 1e3;
        let written = std::sync::Mutex::new(Vec::<String>::new());
        let write = |s: &str| written.lock().expect("lock").push(s.to_string());
        let line = ProgressLine {
            name: "spec",
            clock: &clock,
            write: &write,
            state: std::sync::Mutex::new((None, None)),
        };
        let at = |ms: u64| now.store(ms, std::sync::atomic::Ordering::Relaxed);
        let cell = |done| ravel::execute::Progress {
            phase: ravel::execute::Phase::Cells,
            done,
            total: Some(1),
        };
        // execution reports its one cell at once, then nothing for seconds
        at(10);
        line.show(cell(0));
        line.tick();
        assert!(written.lock().expect("lock").is_empty());
        // the ticker draws the last report after half a second, and again
        // only a quarter of a second later
        at(600);
        line.tick();
        at(700);
        line.tick();
        at(3_700);
        line.tick();
        let lines = written.lock().expect("lock").clone();
        assert_eq!(
            lines,
            [
                "\r\x1b[2Kspec: propagating cell 0 of 1 (1 s)",
                "\r\x1b[2Kspec: propagating cell 0 of 1 (4 s)"
            ]
        );
        line.clear();
        assert_eq!(
            written.lock().expect("lock").last().map(String::as_str),
            Some("\r\x1b[2K")
        );
        // a line never drawn is not erased; before any report it says so
        let quiet = ProgressLine {
            name: "pairs",
            clock: &clock,
            write: &write,
            state: std::sync::Mutex::new((None, None)),
        };
        written.lock().expect("lock").clear();
        at(100);
        quiet.tick();
        quiet.clear();
        assert!(written.lock().expect("lock").is_empty());
        at(900);
        quiet.tick();
        assert_eq!(
            written.lock().expect("lock").clone(),
            ["\r\x1b[2Kpairs: starting (1 s)"]
        );
    }

    #[test]
    fn the_ticker_runs_while_the_work_does_and_stops_with_it() {
        let ticks = std::sync::atomic::AtomicUsize::new(0);
        let tick = || {
            ticks.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        };
        // the work waits for the ticker's first tick: a ticker that never
        // ran would hang here, not pass
        let out = with_ticker(true, &tick, || {
            while ticks.load(std::sync::atomic::Ordering::Relaxed) == 0 {
                std::thread::yield_now();
            }
            7
        });
        assert_eq!(out, 7);
        let after = ticks.load(std::sync::atomic::Ordering::Relaxed);
        std::thread::sleep(std::time::Duration::from_millis(300));
        assert_eq!(
            ticks.load(std::sync::atomic::Ordering::Relaxed),
            after,
            "ticks after the work"
        );
        // off: no thread, no tick
        let none = std::sync::atomic::AtomicUsize::new(0);
        let tick = || {
            none.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        };
        assert_eq!(with_ticker(false, &tick, || 3), 3);
        assert_eq!(none.load(std::sync::atomic::Ordering::Relaxed), 0);
    }

    fn pair(s: &str, c: Option<&str>) -> (PathBuf, Option<PathBuf>) {
        (PathBuf::from(s), c.map(PathBuf::from))
    }

    #[test]
    fn names_are_stems_unless_they_collide() {
        // unique stems keep today's names
        let names = output_names(&[pair("specs/di.ravel", None), pair("specs/quad.ravel", None)])
            .expect("distinct");
        assert_eq!(names, ["di", "quad"]);
        // a shared stem takes folders, nearest first, only where needed
        let names = output_names(&[
            pair("x/a/di.ravel", Some("c.onnx")),
            pair("x/b/di.ravel", Some("c.onnx")),
            pair("di.ravel", Some("c.onnx")),
            pair("x/quad.ravel", Some("c.onnx")),
        ])
        .expect("distinct");
        assert_eq!(names, ["a~di--c", "b~di--c", "di--c", "quad--c"]);
        // names that differ only in case collide (case-insensitive file systems)
        let names =
            output_names(&[pair("A/Di.ravel", None), pair("b/di.ravel", None)]).expect("distinct");
        assert_eq!(names, ["A~Di", "b~di"]);
        // one spec, controllers of one name in two folders
        let names = output_names(&[
            pair("s.ravel", Some("x/c.onnx")),
            pair("s.ravel", Some("y/c.onnx")),
        ])
        .expect("distinct");
        assert_eq!(names, ["s--x~c", "s--y~c"]);
        // folders that differ only far up
        let names = output_names(&[pair("p/m/n/di.ravel", None), pair("q/m/n/di.ravel", None)])
            .expect("distinct");
        assert_eq!(names, ["p~m~n~di", "q~m~n~di"]);
    }

    #[test]
    fn a_pair_given_twice_cannot_be_named() {
        let e = output_names(&[pair("a/di.ravel", None), pair("./a/di.ravel", None)])
            .expect_err("the same pair");
        assert!(e.contains("given twice"), "{e}");
        let e = output_names(&[
            pair("s.ravel", Some("c.onnx")),
            pair("s.ravel", Some("c.onnx")),
        ])
        .expect_err("the same pair");
        assert!(e.contains("`s.ravel` with `c.onnx`"), "{e}");
    }

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("ravel-atomic-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("dir");
        d
    }

    #[test]
    fn atomic_writes_replace_whole_files_and_leave_nothing_behind() {
        let d = scratch("ok");
        let f = d.join("x.cert.json");
        write_atomically(&f, b"first").expect("written");
        write_atomically(&f, b"second").expect("replaced");
        assert_eq!(std::fs::read(&f).expect("read"), b"second");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&f, std::fs::Permissions::from_mode(0o600)).expect("chmod");
            write_atomically(&f, b"third").expect("replaced");
            let mode = std::fs::metadata(&f).expect("meta").permissions().mode();
            assert_eq!(mode & 0o777, 0o600, "permissions kept");
        }
        let names: Vec<_> = std::fs::read_dir(&d)
            .expect("list")
            .map(|e| e.expect("entry").file_name())
            .collect();
        assert_eq!(names, ["x.cert.json"]);
        // a name as long as file systems allow (255 bytes) still has room
        // for its temporary file
        let long = d.join("n".repeat(255));
        write_atomically(&long, b"long").expect("written");
        assert_eq!(std::fs::read(&long).expect("read"), b"long");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_failed_atomic_write_leaves_the_target_and_no_temporary_file() {
        let d = scratch("fail");
        // the target is a non-empty folder: the rename fails
        let target = d.join("taken");
        std::fs::create_dir_all(target.join("inside")).expect("dir");
        assert!(write_atomically(&target, b"data").is_err());
        assert!(target.join("inside").is_dir());
        let names: Vec<_> = std::fs::read_dir(&d)
            .expect("list")
            .map(|e| e.expect("entry").file_name())
            .collect();
        assert_eq!(names, ["taken"], "no temporary file left");
        // a folder that does not exist: an error, nothing created
        assert!(write_atomically(&d.join("no/such/file"), b"data").is_err());
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn relative_paths_part_where_the_folders_do() {
        let d = scratch("rel");
        std::fs::create_dir_all(d.join("certs")).expect("dir");
        std::fs::create_dir_all(d.join("specs/x")).expect("dir");
        std::fs::write(d.join("specs/x/s.ravel"), "").expect("file");
        assert_eq!(
            relative_to(&d.join("certs"), &d.join("specs/x/s.ravel")),
            Path::new("../specs/x/s.ravel")
        );
        assert_eq!(
            relative_to(&d.join("specs/x"), &d.join("specs/x/s.ravel")),
            Path::new("s.ravel")
        );
        // an unresolvable folder: the path made absolute, never relative to the cwd
        let r = relative_to(&d.join("certs"), Path::new("no/such/s.ravel"));
        assert!(r.is_absolute(), "{}", r.display());
        let _ = std::fs::remove_dir_all(&d);
    }
}
