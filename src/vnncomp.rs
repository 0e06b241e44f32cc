//! VNN-COMP as a front end: `ravel verify --network NET.onnx --vnnlib
//! PROP.vnnlib` runs a property without a spec file (importing it in
//! memory as `import-vnnlib` does, one spec per input region) and writes
//! the competition's result format; `ravel vnncomp INSTANCES.csv` runs
//! every row `onnx,vnnlib,timeout` of an instance list.
//!
//! A property with several input regions is `unsat` only if every region
//! is VERIFIED, `sat` as soon as one is FALSIFIED (its confirmed
//! counterexample is written), and otherwise `timeout` when the time limit
//! ended the analysis, `unknown` when it did not. An error (a file that
//! cannot be read, a property or network outside what ravel supports) is
//! not an answer: it is a diagnostic with its code, and exit code 2.
//!
//! Files named `.gz` (the networks and properties VNN-COMP ships since
//! 2022, the instance list too) are read decompressed, under the same size
//! limits as plain files (`ravel_files::read_request`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use ravel::check::Task;
use ravel::execute::network::execute_network;
use ravel::execute::{Control, Verdict};
use ravel_syntax::ast::Span;
use ravel_syntax::diag::{render, sanitize, Code, Diagnostic};

/// An instance's answer, as VNN-COMP states it.
#[derive(Clone, Debug, PartialEq)]
pub enum Answer {
    /// A counterexample: the input (a value of the network's input type)
    /// and the network's output at it, in the network's own precision.
    Sat {
        /// `X_0 …`
        input: Vec<f64>,
        /// `Y_0 …`
        output: Vec<f64>,
    },
    /// Every input region VERIFIED.
    Unsat,
    /// Undecided because the time limit ended the analysis.
    Timeout,
    /// Undecided before the time limit.
    Unknown,
}

impl Answer {
    /// The result file's first line.
    pub fn word(&self) -> &'static str {
        match self {
            Answer::Sat { .. } => "sat",
            Answer::Unsat => "unsat",
            Answer::Timeout => "timeout",
            Answer::Unknown => "unknown",
        }
    }

    /// The exit code of the direct form (as `verify`'s: 0 unsat, 1 sat,
    /// 3 undecided).
    pub fn exit_code(&self) -> u8 {
        match self {
            Answer::Sat { .. } => crate::exit::FALSIFIED,
            Answer::Unsat => crate::exit::VERIFIED,
            Answer::Timeout | Answer::Unknown => crate::exit::UNSURE,
        }
    }
}

/// A number in full precision: the shortest decimal that reads back as the
/// same `f64` (a float32 value widened to `f64` reads back as itself, and
/// casts back to the same float32).
fn full(v: f64) -> String {
    let s = format!("{:?}", v + 0.0);
    if s.contains(['.', 'e', 'n', 'N']) {
        s
    } else {
        format!("{s}.0")
    }
}

/// The text of a VNN-COMP result file: the answer on the first line and,
/// for `sat`, the counterexample: `(`, one `(X_i v)` line per input, one
/// `(Y_j v)` line per output, `)`.
pub fn result_text(answer: &Answer) -> String {
    let mut s = format!("{}\n", answer.word());
    if let Answer::Sat { input, output } = answer {
        s += "(\n";
        for (i, v) in input.iter().enumerate() {
            s += &format!("(X_{i} {})\n", full(*v));
        }
        for (j, v) in output.iter().enumerate() {
            s += &format!("(Y_{j} {})\n", full(*v));
        }
        s += ")\n";
    }
    s
}

/// A diagnostic without a location (a file that cannot be read).
fn nowhere(code: Code, message: String, hint: &str) -> Diagnostic {
    Diagnostic {
        span: None,
        ..Diagnostic::new(code, Span::new(0, 0), message).hint(hint)
    }
}

/// Run one instance: the property `property` on the network `network`,
/// within `time_limit` seconds (counted from the call); `threads` as
/// `verify --jobs`. An error is returned rendered (diagnostics with their
/// codes, `color` for the terminal).
pub fn run_instance(
    network: &Path,
    property: &Path,
    time_limit: Option<f64>,
    threads: usize,
    color: bool,
) -> Result<Answer, String> {
    let started = Instant::now();
    let shown = sanitize(&property.display().to_string());
    let plain = |d: Diagnostic| render(&[d], &shown, "", 100, color);
    let bytes = crate::read_request(&ravel::ReadRequest {
        path: property.to_path_buf(),
        inside: None,
        max_bytes: ravel_base::limits::MAX_SPEC_BYTES,
        whole: true,
    })
    .map_err(|e| {
        plain(nowhere(
            Code::Vnnlib,
            format!("cannot read the property `{shown}`: {e}"),
            "check the path (relative to the working folder, or to the instance list's folder)",
        ))
    })?;
    let text = String::from_utf8(bytes).map_err(|_| {
        plain(nowhere(
            Code::Vnnlib,
            format!("the property `{shown}` is not UTF-8 text"),
            "VNN-LIB files are plain text",
        ))
    })?;
    let model = network.file_name().map_or_else(
        || "network.onnx".into(),
        |n| n.to_string_lossy().into_owned(),
    );
    let specs = ravel::vnnlib::import(&text, &model, "vnnlib", &property.display().to_string())
        .map_err(|e| {
            let d = Diagnostic::new(
                Code::Vnnlib,
                Span::new(e.offset, (e.offset + 1).min(text.len()).max(e.offset)),
                e.message,
            )
            .label("here")
            .hint("ravel imports linear constraints over the X_i or the Y_j under and/or (see the README, VNN-LIB properties)");
            render(&[d], &shown, &text, 100, color)
        })?;
    let strict = ravel::vnnlib::has_strict_comparisons(&text);
    // every region's spec checks (with the network) before any runs
    let mut plans = Vec::with_capacity(specs.len());
    for (k, spec) in specs.iter().enumerate() {
        let name = format!("(spec imported from {shown}, region {})", k + 1);
        match ravel::front_end_task(spec, Path::new("."), &crate::read_request, Some(network)) {
            Ok(Task::Network(c)) => plans.push(ravel::lower::lower_network(&c)),
            Ok(Task::System(_)) => {
                return Err(format!(
                    "error: {name} is not a network spec (a ravel bug, please report it)\n"
                ))
            }
            Err(d) => return Err(render(&d, &name, spec, 100, color)),
        }
    }
    let elapsed = move || started.elapsed().as_secs_f64();
    let out_of_time = || time_limit.is_some_and(|l| elapsed() >= l);
    let ctl = Control {
        elapsed: &elapsed,
        time_limit,
        progress: &|_| {},
        threads,
    };
    let mut timed_out = false;
    let mut undecided = false;
    for plan in &plans {
        if out_of_time() {
            // a region not analysed: undecided because time ran out
            return Ok(Answer::Timeout);
        }
        let out = execute_network(plan, &ctl);
        match out.verdict {
            Verdict::Falsified => {
                let witness = out
                    .properties
                    .iter()
                    .find_map(|p| p.counterexample.as_ref());
                // FALSIFIED always carries its confirmed input; were it
                // missing, the region is only undecided
                match witness {
                    Some(w) => {
                        let output = plan.net.forward_stored(&w.input);
                        if !strict || strictly_inside(plan, &output) {
                            return Ok(Answer::Sat {
                                input: w.input.clone(),
                                output,
                            });
                        }
                        // on the boundary of a strict property: not shown
                        // to be a counterexample of the property as written
                        undecided = true;
                    }
                    None => undecided = true,
                }
            }
            Verdict::Verified => {}
            Verdict::Unsure => {
                undecided = true;
                timed_out |=
                    out.partition_stop == ravel_analysis::partition::Stop::Time || out_of_time();
            }
        }
    }
    Ok(match (undecided, timed_out) {
        (false, _) => Answer::Unsat,
        (true, true) => Answer::Timeout,
        (true, false) => Answer::Unknown,
    })
}

/// Whether `y` lies strictly inside a member of the plan's avoid set, by
/// more than a relative 10⁻⁶ on every row: the specs read a strict
/// comparison as non-strict, so a counterexample of a property with strict
/// comparisons must not lie on (or within rounding of) the boundary.
fn strictly_inside(plan: &ravel::lower::NetworkPlan, y: &[f64]) -> bool {
    plan.properties.iter().any(|p| match &p.kind {
        ravel::ir::NetPropertyKind::Avoid(members) => members.iter().any(|m| {
            m.rows.iter().all(|(a, h)| {
                let dot: f64 = a.iter().zip(y).map(|(a, y)| a * y).sum();
                let scale: f64 = a.iter().zip(y).map(|(a, y)| (a * y).abs()).sum();
                h - dot > 1e-6 * (1.0 + scale + h.abs())
            })
        }),
        _ => false,
    })
}

/// `ravel verify --network NET --vnnlib PROP [--time-limit S]
/// [--result-file OUT]`: the answer (to OUT, else to standard output) and
/// the exit code.
pub fn verify_direct(
    network: &Path,
    property: &Path,
    time_limit: Option<f64>,
    result_file: Option<&Path>,
    threads: usize,
    color: bool,
) -> std::process::ExitCode {
    use std::process::ExitCode;
    let started = Instant::now();
    let answer = match run_instance(network, property, time_limit, threads, color) {
        Ok(a) => a,
        Err(rendered) => {
            crate::err(&rendered);
            // no answer: nothing is written to the result file
            return ExitCode::from(crate::exit::INPUT_ERROR);
        }
    };
    let text = result_text(&answer);
    match result_file {
        Some(file) => {
            if let Err(e) = crate::write_atomically(file, text.as_bytes()) {
                crate::err(&format!(
                    "error: cannot write `{}`: {e}\n",
                    sanitize(&file.display().to_string())
                ));
                return ExitCode::from(crate::exit::INPUT_ERROR);
            }
            let line = format!(
                "{}: {} ({:.2} s)",
                sanitize(&property.display().to_string()),
                answer.word(),
                started.elapsed().as_secs_f64()
            );
            if crate::out(&line).is_err() {
                return ExitCode::from(crate::exit::BROKEN_PIPE);
            }
        }
        None => {
            if crate::out(text.trim_end()).is_err() {
                return ExitCode::from(crate::exit::BROKEN_PIPE);
            }
        }
    }
    ExitCode::from(answer.exit_code())
}

/// One usable row of an instance list: the fields as written, the
/// resolved paths and the timeout.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// The network field, as written.
    pub network_field: String,
    /// The property field, as written.
    pub property_field: String,
    /// The network's path.
    pub network: PathBuf,
    /// The property's path.
    pub property: PathBuf,
    /// Seconds.
    pub timeout: f64,
}

/// Parse an instance list (`onnx,vnnlib,timeout` per line; blank lines
/// skipped; paths relative to `root`): the rows, or every problem found
/// (E0402, each with its span). `exists` says whether a path is a file
/// (the caller's file system; the parsing itself does no IO).
pub fn parse_instances(
    text: &str,
    root: &Path,
    exists: &dyn Fn(&Path) -> bool,
) -> Result<Vec<Row>, Vec<Diagnostic>> {
    let mut rows = Vec::new();
    let mut diags = Vec::new();
    let mut at = 0usize;
    for raw in text.split_inclusive('\n') {
        let start = at;
        at += raw.len();
        let line = raw.trim_end_matches(['\n', '\r']);
        if line.trim().is_empty() {
            continue;
        }
        let span = Span::new(start, start + line.len());
        let fields: Vec<(usize, &str)> = {
            let mut off = start;
            line.split(',')
                .map(|f| {
                    let here = off;
                    off += f.len() + 1;
                    let lead = f.len() - f.trim_start().len();
                    (here + lead, f.trim())
                })
                .collect()
        };
        let [(_, onnx), (_, vnnlib), (tat, timeout)] = fields.as_slice() else {
            diags.push(
                Diagnostic::new(
                    Code::Instances,
                    span,
                    format!(
                        "an instance row has {} field(s), not the 3 fields onnx,vnnlib,timeout",
                        fields.len()
                    ),
                )
                .label("this row")
                .hint("write each instance as `network.onnx,property.vnnlib,seconds`"),
            );
            continue;
        };
        let field_span = |off: usize, f: &str| Span::new(off, off + f.len().max(1));
        let seconds = timeout
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v >= 0.0);
        if seconds.is_none() {
            diags.push(
                Diagnostic::new(
                    Code::Instances,
                    field_span(*tat, timeout),
                    format!(
                        "the timeout `{}` is not a non-negative number of seconds",
                        sanitize(timeout)
                    ),
                )
                .label("the timeout")
                .hint("write the timeout in seconds, e.g. 60"),
            );
        }
        let mut paths = Vec::new();
        for (k, f) in [(0usize, *onnx), (1, *vnnlib)] {
            let off = fields.get(k).map_or(start, |x| x.0);
            let path = root.join(f);
            let shown = sanitize(&path.display().to_string());
            if f.is_empty() {
                diags.push(
                    Diagnostic::new(Code::Instances, field_span(off, f), "an empty path")
                        .label("here")
                        .hint("write each instance as `network.onnx,property.vnnlib,seconds`"),
                );
            } else if !exists(&path) {
                diags.push(
                    Diagnostic::new(
                        Code::Instances,
                        field_span(off, f),
                        format!("`{shown}` is not a file"),
                    )
                    .label("missing")
                    .hint("paths are relative to the instance list's folder, or to --root"),
                );
            }
            paths.push(path);
        }
        if let (Some(timeout), [network, property]) = (seconds, paths.as_slice()) {
            rows.push(Row {
                network_field: (*onnx).to_string(),
                property_field: (*vnnlib).to_string(),
                network: network.clone(),
                property: property.clone(),
                timeout,
            });
        }
    }
    if rows.is_empty() && diags.is_empty() {
        diags.push(nowhere(
            Code::Instances,
            "the instance list has no rows".into(),
            "write one instance per line: `network.onnx,property.vnnlib,seconds`",
        ));
    }
    if diags.is_empty() {
        Ok(rows)
    } else {
        Err(diags)
    }
}

/// One line of the results: `network,property,result,seconds` (fields as
/// written in the list, control characters escaped; `error` for an
/// instance that gave a diagnostic instead of an answer).
pub fn result_line(row: &Row, result: &str, seconds: f64) -> String {
    format!(
        "{},{},{result},{seconds:.3}",
        sanitize(&row.network_field),
        sanitize(&row.property_field)
    )
}

/// `ravel vnncomp INSTANCES.csv [--root DIR] [--out RESULTS.csv]`.
pub fn vnncomp(
    list: &Path,
    root: Option<&Path>,
    out_file: Option<&Path>,
    threads: usize,
    color: bool,
) -> std::process::ExitCode {
    use std::process::ExitCode;
    let shown = sanitize(&list.display().to_string());
    let fail = |d: Diagnostic, source: &str| {
        crate::err(&render(&[d], &shown, source, 100, color));
        ExitCode::from(crate::exit::INPUT_ERROR)
    };
    let bytes = match crate::read_request(&ravel::ReadRequest {
        path: list.to_path_buf(),
        inside: None,
        max_bytes: ravel_base::limits::MAX_SPEC_BYTES,
        whole: true,
    }) {
        Ok(b) => b,
        Err(e) => {
            return fail(
                nowhere(
                    Code::Instances,
                    format!("cannot read the instance list `{shown}`: {e}"),
                    "name the benchmark's instances.csv",
                ),
                "",
            )
        }
    };
    let Ok(text) = String::from_utf8(bytes) else {
        return fail(
            nowhere(
                Code::Instances,
                format!("the instance list `{shown}` is not UTF-8 text"),
                "name the benchmark's instances.csv",
            ),
            "",
        );
    };
    let root = match root {
        Some(r) => r.to_path_buf(),
        None => list
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .map_or_else(|| PathBuf::from("."), Path::to_path_buf),
    };
    let rows = match parse_instances(&text, &root, &|p: &Path| p.is_file()) {
        Ok(r) => r,
        Err(d) => {
            crate::err(&render(&d, &shown, &text, 100, color));
            crate::err(&format!(
                "{shown}: {} unusable row(s); nothing was run\n",
                d.len()
            ));
            return ExitCode::from(crate::exit::INPUT_ERROR);
        }
    };
    let mut lines = String::new();
    let mut code = crate::exit::VERIFIED;
    for row in &rows {
        let started = Instant::now();
        let result = match run_instance(
            &row.network,
            &row.property,
            Some(row.timeout),
            threads,
            color,
        ) {
            Ok(a) => a.word(),
            Err(rendered) => {
                crate::err(&rendered);
                code = crate::exit::INPUT_ERROR;
                "error"
            }
        };
        let line = result_line(row, result, started.elapsed().as_secs_f64());
        if crate::out(&line).is_err() {
            return ExitCode::from(crate::exit::BROKEN_PIPE);
        }
        lines += &line;
        lines.push('\n');
    }
    if let Some(file) = out_file {
        if let Err(e) = crate::write_atomically(file, lines.as_bytes()) {
            crate::err(&format!(
                "error: cannot write `{}`: {e}\n",
                sanitize(&file.display().to_string())
            ));
            return ExitCode::from(crate::exit::INPUT_ERROR);
        }
    }
    ExitCode::from(code)
}
