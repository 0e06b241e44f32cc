//! `ravel verify` over many (spec, controller) pairs: parallel jobs with
//! output in a fixed order, deterministic shards, the output formats (text,
//! JSON, JSON lines, JUnit XML), the exit-code gate, and `ravel merge`.
//!
//! Every argument that names nothing and every (spec, controller) pair is
//! one *item* with a fixed index (argument errors first, then the pairs in
//! argument order, folders expanded in sorted order). Items run on `--jobs`
//! worker threads, but their output is written strictly in index order, so
//! it is byte-for-byte the same for every number of jobs. `--shard K/N`
//! keeps the items whose index is `K − 1` modulo `N`; `ravel merge` puts the
//! shards' JSON documents back together in index order.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use serde_json::{json, Value};

use super::{err, exit, load_with, out, progress_due, with_ticker, Format, ProgressLine};
use crate::html::esc;
use ravel::execute::{Run, Verdict};
use ravel_syntax::diag::{render, Code, Diagnostic};

/// Which verdicts fail the run (exit code and JUnit).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum FailOn {
    /// FALSIFIED fails (exit 1); UNSURE passes (exit 0; JUnit: skipped).
    Falsified,
    /// FALSIFIED fails (exit 1) and so does UNSURE (exit 3; JUnit: failure).
    Unsure,
}

/// `--fail-on`'s value as written on the command line.
fn fail_on_name(f: FailOn) -> &'static str {
    match f {
        FailOn::Falsified => "falsified",
        FailOn::Unsure => "unsure",
    }
}

/// What `ravel merge` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum MergeFormat {
    /// The JSON document of the whole batch.
    Json,
    /// The JUnit XML document of the whole batch.
    Junit,
}

/// A shard `K/N`: the items whose index is `K − 1` modulo `N`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// 1-based shard number.
    pub k: usize,
    /// Number of shards.
    pub n: usize,
}

/// Parse `K/N` with `1 ≤ K ≤ N`.
pub fn parse_shard(s: &str) -> Result<Shard, String> {
    let (k, n) = s
        .split_once('/')
        .ok_or_else(|| format!("`{s}` is not K/N (for example 1/4)"))?;
    let k: usize = k
        .trim()
        .parse()
        .map_err(|_| format!("`{k}` is not a shard number"))?;
    let n: usize = n
        .trim()
        .parse()
        .map_err(|_| format!("`{n}` is not a shard count"))?;
    if n == 0 {
        return Err("the shard count must be at least 1".into());
    }
    if k == 0 || k > n {
        return Err(format!(
            "shard {k} of {n} does not exist: shards are numbered 1 to {n}"
        ));
    }
    Ok(Shard { k, n })
}

/// Parse `I,J`: two different state coordinates.
pub fn parse_dims(s: &str) -> Result<(usize, usize), String> {
    let (i, j) = s
        .split_once(',')
        .ok_or_else(|| format!("`{s}` is not I,J (for example 0,1)"))?;
    let i: usize = i
        .trim()
        .parse()
        .map_err(|_| format!("`{i}` is not a coordinate"))?;
    let j: usize = j
        .trim()
        .parse()
        .map_err(|_| format!("`{j}` is not a coordinate"))?;
    if i == j {
        return Err("the two plotted coordinates must differ".into());
    }
    Ok((i, j))
}

/// Parse a positive number of jobs.
pub fn parse_jobs(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(0) => Err("--jobs must be at least 1".into()),
        Ok(n) => Ok(n),
        Err(_) => Err(format!("`{s}` is not a number of jobs")),
    }
}

/// How a batch runs and reports.
pub struct Options {
    /// Output format.
    pub format: Format,
    /// Leave timing out of text output.
    pub no_timing: bool,
    /// Add timing to JSON output.
    pub timing: bool,
    /// Per-item analysis time limit.
    pub time_limit: Option<f64>,
    /// Certificate file or folder.
    pub certificate: Option<PathBuf>,
    /// The gate.
    pub fail_on: FailOn,
    /// Worker threads.
    pub jobs: usize,
    /// A slice of the items.
    pub shard: Option<Shard>,
    /// Progress on standard error.
    pub progress: bool,
    /// Colour in diagnostics.
    pub color: bool,
    /// A folder for one SVG per result.
    pub plot: Option<PathBuf>,
    /// The coordinates plotted.
    pub plot_dims: (usize, usize),
    /// A folder for the HTML report of the batch.
    pub report: Option<PathBuf>,
}

/// What one item is.
enum Work {
    /// An argument that named nothing usable.
    Argument(String),
    /// A (spec, controller) pair and the name of its files (certificate,
    /// plot) without extension, unique in the batch.
    Pair(PathBuf, Option<PathBuf>, String),
}

/// The verdict class of one item.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Class {
    Verdict(Verdict),
    Error,
}

/// What one item produced, in every format.
struct Item {
    class: Class,
    /// Text for standard output (text format).
    stdout: String,
    /// Text for standard error (diagnostics, errors).
    stderr: String,
    /// The JSON result.
    json: Value,
    /// The JUnit `<testsuite>` element.
    junit: String,
    /// CSV rows of robust action selections (no header).
    csv: String,
    /// Its row and plot in the HTML report.
    entry: crate::html::Entry,
}

/// The JUnit suite of a pair: its spec, and its controller when one was
/// given with `--controller` (pairs of one spec with two controllers are
/// two suites, whether they ran or failed to load). Control characters are
/// escaped, but the name is never cut (a name cut in the middle, as
/// messages cut long paths, could give two pairs the same suite).
fn suite_name(spec: &Path, controller: Option<&Path>) -> String {
    ravel_syntax::diag::sanitize_to(
        &match controller {
            Some(c) => format!("{} with controller {}", spec.display(), c.display()),
            None => spec.display().to_string(),
        },
        usize::MAX,
    )
}

/// A `<testsuite>` holding one erroring test case.
fn junit_error(suite: &str, message: &str, detail: &str) -> String {
    format!(
        "  <testsuite name=\"{s}\" tests=\"1\" failures=\"0\" errors=\"1\" skipped=\"0\">\n    <testcase classname=\"{s}\" name=\"check\">\n      <error message=\"{m}\" type=\"ERROR\">{d}</error>\n    </testcase>\n  </testsuite>\n",
        s = esc(suite),
        m = esc(message),
        d = esc(detail)
    )
}

fn error_item(
    index: usize,
    spec: Option<&Path>,
    controller: Option<&Path>,
    message: &str,
    stderr: String,
    json: Value,
) -> Item {
    let mut json = json;
    json["index"] = json!(index);
    if let Some(c) = controller {
        json["controller"] = json!(c.display().to_string());
    }
    let suite = spec.map_or_else(|| "arguments".to_string(), |p| suite_name(p, controller));
    let entry = crate::html::Entry {
        index,
        spec: spec.map_or_else(|| "(argument)".to_string(), |p| p.display().to_string()),
        controller: controller.map(|c| c.display().to_string()),
        verdict: "ERROR".into(),
        properties: Vec::new(),
        key: String::new(),
        time_ms: None,
        plot: None,
        error: Some(ravel_syntax::diag::sanitize(message)),
    };
    Item {
        class: Class::Error,
        stdout: String::new(),
        stderr,
        json,
        junit: junit_error(&suite, message, message),
        csv: String::new(),
        entry,
    }
}

/// Run one item (no output; everything is returned).
fn run(
    index: usize,
    work: &Work,
    opts: &Options,
    cert_dir: Option<&Path>,
    show: bool,
    cell_threads: usize,
    position: Option<(usize, usize)>,
) -> Item {
    let (path, controller, file_name) = match work {
        Work::Argument(e) => {
            return error_item(
                index,
                None,
                None,
                e,
                format!("error: {e}\n"),
                json!({ "spec": null, "verdict": "ERROR", "errors": [{ "code": null, "message": e }] }),
            )
        }
        Work::Pair(p, c, n) => (p, c.as_deref(), n.as_str()),
    };
    let l = match load_with(path, controller) {
        Ok(l) => l,
        Err(msg) => {
            return error_item(
                index,
                Some(path),
                controller,
                &msg,
                format!("error: {msg}\n"),
                json!({ "spec": path.display().to_string(), "verdict": "ERROR", "errors": [{ "code": null, "message": msg }] }),
            )
        }
    };
    let refused = |d: &[Diagnostic]| {
        let text = render(d, &l.display, &l.source, 100, opts.color);
        let plain = render(d, &l.display, &l.source, 100, false);
        let message = format!("{}: {} error(s)", l.display, d.len());
        error_item(
            index,
            Some(path),
            controller,
            &message,
            format!("{text}{message}\n"),
            super::diag_json(&l.name, &l.source, d),
        )
        .with_junit_detail(&plain)
    };
    let task = match &l.result {
        Ok(task) => task,
        Err(d) => return refused(d),
    };
    // CSV holds robust action selections only: a spec without any is
    // refused before it runs, not a header with no rows and exit 0
    if opts.format == Format::Csv && !has_selections(task) {
        return refused(&[csv_without_select(&l.source)]);
    }
    let started = Instant::now();
    let shown = match position {
        Some((k, n)) if n > 1 => format!("[{k}/{n}] {}", l.display),
        _ => l.display.clone(),
    };
    let clock = || started.elapsed().as_secs_f64();
    let line = ProgressLine {
        name: &shown,
        clock: &clock,
        write: &err,
        state: std::sync::Mutex::new((None, None)),
    };
    // a ticker redraws the line while one long cell or sample run says nothing
    let run = with_ticker(show, &|| line.tick(), || {
        ravel::run(
            task,
            &ravel::execute::Control {
                elapsed: &clock,
                time_limit: opts.time_limit,
                progress: &|p| {
                    if show {
                        line.show(p);
                    }
                },
                threads: cell_threads,
            },
        )
    });
    line.clear();
    let ms = started.elapsed().as_secs_f64() * 1e3;
    let mut stderr = String::new();
    let mut class = Class::Verdict(run.verdict());
    let mut json = ravel::report::json(&l.name, &run, opts.timing.then_some(ms));
    json["index"] = json!(index);
    if let (Run::Network { .. }, Some(c)) = (&run, controller) {
        json["controller"] = json!(c.display().to_string());
    }
    if let Some(target) = &opts.certificate {
        let file = certificate_file(target, cert_dir, file_name);
        let id = identity(&file, path, &l.source);
        let mut cert = ravel::certificate_writer::build(&run, &id);
        record_controller(&mut cert, &file, run.controller_resolved());
        if let Err(msg) = write_certificate(&file, &cert) {
            fail_item(
                (&mut json, &mut stderr, &mut class),
                "certificate_error",
                &msg,
            );
        }
    }
    let svg = (opts.plot.is_some() || opts.report.is_some())
        .then(|| plot_svg(&run, &l.display, opts.plot_dims));
    if let (Some(dir), Some(svg)) = (&opts.plot, &svg) {
        if let Err(msg) = svg
            .as_ref()
            .map_err(Clone::clone)
            .and_then(|s| write_plot(s, dir, file_name))
        {
            fail_item((&mut json, &mut stderr, &mut class), "plot_error", &msg);
        }
    }
    let stdout = match opts.format {
        Format::Text => ravel::report::text(&l.display, &run, (!opts.no_timing).then_some(ms)),
        _ => String::new(),
    };
    // the text report without timing, for JUnit bodies (deterministic)
    let report = ravel::report::text(&l.display, &run, None);
    let junit = junit_cases(
        &suite_name(path, controller),
        &junit_list(&run),
        opts,
        ms,
        &report,
    );
    let csv = match &run {
        Run::System { .. } => String::new(),
        Run::Network { outcome, .. } => ravel::report::network::csv_rows(&l.name, outcome),
    };
    let entry = crate::html::Entry {
        index,
        spec: path.display().to_string(),
        controller: controller.map(|c| c.display().to_string()),
        verdict: match class {
            Class::Verdict(v) => v.as_str().to_string(),
            Class::Error => "ERROR".to_string(),
        },
        properties: report_properties(&run),
        key: key_numbers(&run),
        time_ms: (!opts.no_timing).then_some(ms),
        plot: opts.report.as_ref().and(svg),
        error: json["plot_error"]
            .as_str()
            .or(json["certificate_error"].as_str())
            .map(str::to_string),
    };
    Item {
        class,
        stdout,
        stderr,
        json,
        junit,
        csv,
        entry,
    }
}

/// A run's properties for the HTML report: what, verdict, margin and where.
fn report_properties(run: &Run) -> Vec<(String, String, String)> {
    let c = ravel_syntax::diag::compact;
    match run {
        Run::System { outcome, .. } => outcome
            .properties
            .iter()
            .map(|p| {
                let detail = match p.status {
                    Verdict::Falsified => {
                        format!("violated by {} at step {}", c(-p.margin), p.step)
                    }
                    _ => format!("margin {} at step {}", c(p.margin), p.step),
                };
                (
                    format!("{} {}", p.kind.as_str(), p.name),
                    p.status.as_str().to_string(),
                    detail,
                )
            })
            .collect(),
        Run::Network { outcome, .. } => outcome
            .properties
            .iter()
            .map(|p| {
                let detail = match p.status {
                    Verdict::Falsified => format!("violated by {}", c(-p.margin)),
                    _ => format!("margin {}", c(p.margin)),
                };
                (
                    format!("{} {}", p.kind.as_str(), p.name),
                    p.status.as_str().to_string(),
                    detail,
                )
            })
            .chain(outcome.radii.iter().map(|r| {
                (
                    format!("radius {}", r.name),
                    "—".to_string(),
                    format!(
                        "certified scale {}, attacked {}",
                        r.certified.map_or("none".into(), c),
                        r.attacked.as_ref().map_or("none".into(), |a| c(a.0))
                    ),
                )
            }))
            .collect(),
    }
}

/// Key numbers of a run: cells, propagator calls, samples.
fn key_numbers(run: &Run) -> String {
    match run {
        Run::System { plan, outcome } => format!(
            "{} cell{}, {} propagator calls, {} samples, horizon {}",
            outcome.partition.len(),
            if outcome.partition.len() == 1 {
                ""
            } else {
                "s"
            },
            outcome.propagator_calls,
            outcome.samples_drawn,
            plan.horizon
        ),
        Run::Network { outcome, .. } => format!(
            "{} cell{}, {} bounded, {} samples",
            outcome.partition.len(),
            if outcome.partition.len() == 1 {
                ""
            } else {
                "s"
            },
            outcome.calls,
            outcome.samples_drawn
        ),
    }
}

/// The SVG of a run: a closed loop's reachable sets over state
/// coordinates `(i, j)`, or a network spec's input and output sets (its
/// outputs `(i, j)`).
fn plot_svg(run: &Run, display: &str, dims: (usize, usize)) -> Result<String, String> {
    match run {
        Run::System { plan, outcome } => {
            let n = plan.closed_loop.states();
            if dims.0 >= n || dims.1 >= n {
                return Err(format!(
                    "--plot-dims {},{}: the state has {n} coordinates (0 to {})",
                    dims.0,
                    dims.1,
                    n - 1
                ));
            }
            let samples: Vec<_> = (0..plan.samples.min(100))
                .filter_map(|k| ravel::execute::simulate(plan, k))
                .collect();
            ravel::plot::svg(display, plan, outcome, dims, &samples)
        }
        Run::Network { plan, outcome } => ravel::plot::network_svg(display, plan, outcome, dims),
    }
    .map_err(|e| format!("`{}`: {e}", ravel_syntax::diag::sanitize(display)))
}

/// Write a plot into `dir`.
fn write_plot(svg: &str, dir: &Path, file_name: &str) -> Result<(), String> {
    let file = dir.join(format!("{file_name}.svg"));
    super::write_atomically(&file, svg.as_bytes()).map_err(|e| {
        format!(
            "cannot write plot `{}`: {e}",
            ravel_syntax::diag::sanitize(&file.display().to_string())
        )
    })
}

/// The JUnit test cases of a run: one per property, with the step (closed
/// loop) or the set (network) its margin applies to.
fn junit_list(run: &Run) -> Vec<Case> {
    match run {
        Run::System { outcome, .. } => outcome
            .properties
            .iter()
            .map(|p| Case {
                name: format!("{} {}", p.kind.as_str(), p.name),
                status: p.status,
                margin: p.margin,
                place: format!("at step {}", p.step),
            })
            .collect(),
        Run::Network { outcome, .. } => outcome
            .properties
            .iter()
            .map(|p| Case {
                name: format!("{} {}", p.kind.as_str(), p.name),
                status: p.status,
                margin: p.margin,
                place: "on the input set".to_string(),
            })
            .collect(),
    }
}

impl Item {
    /// Put the plain diagnostics into the JUnit error's body.
    fn with_junit_detail(mut self, detail: &str) -> Item {
        if let Some(start) = self.junit.find("type=\"ERROR\">") {
            let from = start + "type=\"ERROR\">".len();
            if let Some(len) = self.junit[from..].find("</error>") {
                self.junit.replace_range(from..from + len, &esc(detail));
            }
        }
        self
    }
}

/// Whether a checked spec has robust action selections (rows for `--format csv`).
fn has_selections(task: &ravel::check::Task) -> bool {
    match task {
        ravel::check::Task::System(_) => false,
        ravel::check::Task::Network(n) => !n.selects.is_empty(),
    }
}

/// E0403: `--format csv` on a spec that has nothing to print in it, at the
/// spec's name (what it lacks has no place of its own).
fn csv_without_select(source: &str) -> Diagnostic {
    use ravel_syntax::ast::{Item, Span};
    let name = ravel_syntax::parse(source).ok().and_then(|spec| {
        spec.items.iter().find_map(|item| match item {
            Item::System(s) => Some(s.name.span),
            Item::Network(n) => Some(n.name.span),
            _ => None,
        })
    });
    Diagnostic::new(
        Code::CsvWithoutSelect,
        name.unwrap_or(Span::new(0, 0)),
        "`--format csv` prints robust action selections, and this spec has no `select` block",
    )
    .label("this spec selects no actions")
    .hint("use --format text, json, jsonl or junit for its verdicts; CSV rows come from the `select` blocks of network specs")
}

/// Turn an item into an ERROR: the message on standard error and in the
/// JSON result under `key`.
fn fail_item((json, stderr, class): (&mut Value, &mut String, &mut Class), key: &str, msg: &str) {
    *stderr += &format!("error: {msg}\n");
    json[key] = json!(msg);
    json["verdict"] = json!("ERROR");
    *class = Class::Error;
}

/// The folder a certificate file is written into.
fn folder_of(file: &Path) -> &Path {
    match file.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// Who a certificate written to `file` is about: the spec's path, relative
/// to the certificate's folder (so that `certify` works from any working
/// folder, and after the folder is moved with the spec), and its hash.
fn identity(file: &Path, spec: &Path, source: &str) -> ravel::certificate_writer::Identity {
    ravel::certificate_writer::Identity {
        spec_path: super::relative_to(folder_of(file), spec)
            .display()
            .to_string(),
        spec_sha256: ravel::check::sha256_hex(source.as_bytes()),
    }
}

/// Record the controller's path (as read) relative to the folder of the
/// certificate `file`, as the spec's.
fn record_controller(cert: &mut Value, file: &Path, resolved: &str) {
    cert["controller"]["path"] = json!(super::relative_to(folder_of(file), Path::new(resolved))
        .display()
        .to_string());
}

/// Where a pair's certificate goes: the `--certificate` file, or the pair's
/// file in the certificate folder.
fn certificate_file(target: &Path, cert_dir: Option<&Path>, file_name: &str) -> PathBuf {
    match cert_dir {
        Some(d) => d.join(format!("{file_name}.cert.json")),
        None => target.to_path_buf(),
    }
}

/// Write a certificate (atomically); the error message for people.
fn write_certificate(file: &Path, cert: &Value) -> Result<(), String> {
    let text = serde_json::to_string(cert).unwrap_or_default();
    super::write_atomically(file, (text + "\n").as_bytes()).map_err(|e| {
        format!(
            "cannot write certificate `{}`: {e}",
            ravel_syntax::diag::sanitize(&file.display().to_string())
        )
    })
}

/// One JUnit test case: a property's result.
struct Case {
    name: String,
    status: Verdict,
    margin: f64,
    /// Where the margin applies, e.g. `at step 5`.
    place: String,
}

/// A `<testsuite>` of cases.
fn junit_cases(suite: &str, list: &[Case], opts: &Options, ms: f64, report: &str) -> String {
    let mut cases = String::new();
    let (mut failures, mut skipped) = (0, 0);
    let time = if opts.timing {
        format!(" time=\"{:.3}\"", ms / 1e3)
    } else {
        String::new()
    };
    for p in list {
        let name = &p.name;
        let margin = ravel_syntax::diag::compact(p.margin);
        let body = match p.status {
            Verdict::Verified => String::new(),
            Verdict::Falsified => {
                failures += 1;
                format!(
                    "\n      <failure message=\"FALSIFIED {} (violated by {})\" type=\"FALSIFIED\">{}</failure>\n    ",
                    p.place,
                    ravel_syntax::diag::compact(-p.margin),
                    esc(report)
                )
            }
            Verdict::Unsure => match opts.fail_on {
                FailOn::Unsure => {
                    failures += 1;
                    format!(
                        "\n      <failure message=\"UNSURE {} (margin {margin})\" type=\"UNSURE\">{}</failure>\n    ",
                        p.place,
                        esc(report)
                    )
                }
                FailOn::Falsified => {
                    skipped += 1;
                    format!(
                        "\n      <skipped message=\"UNSURE {} (margin {margin})\"/>\n    ",
                        p.place
                    )
                }
            },
        };
        cases += &format!(
            "    <testcase classname=\"{s}\" name=\"{n}\"{time}>{body}</testcase>\n",
            s = esc(suite),
            n = esc(name)
        );
    }
    format!(
        "  <testsuite name=\"{s}\" tests=\"{t}\" failures=\"{failures}\" errors=\"0\" skipped=\"{skipped}\"{time}>\n{cases}  </testsuite>\n",
        s = esc(suite),
        t = list.len()
    )
}

/// (VERIFIED, FALSIFIED, UNSURE, ERROR) counts.
type Counts = [usize; 4];

fn count(c: &mut Counts, class: Class) {
    c[match class {
        Class::Verdict(Verdict::Verified) => 0,
        Class::Verdict(Verdict::Falsified) => 1,
        Class::Verdict(Verdict::Unsure) => 2,
        Class::Error => 3,
    }] += 1;
}

/// The exit code of a run with these counts.
fn gate(c: &Counts, fail_on: FailOn) -> u8 {
    if c[3] > 0 {
        exit::INPUT_ERROR
    } else if c[1] > 0 {
        exit::FALSIFIED
    } else if c[2] > 0 && fail_on == FailOn::Unsure {
        exit::UNSURE
    } else {
        exit::VERIFIED
    }
}

/// The overall verdict of a JSON document.
fn overall(c: &Counts) -> &'static str {
    if c[3] > 0 {
        "ERROR"
    } else if c[1] > 0 {
        "FALSIFIED"
    } else if c[2] > 0 {
        "UNSURE"
    } else {
        "VERIFIED"
    }
}

fn summary(c: &Counts) -> String {
    let names = ["VERIFIED", "FALSIFIED", "UNSURE", "ERROR"];
    c.iter()
        .zip(names)
        .filter(|(n, _)| **n > 0)
        .map(|(n, name)| format!("{n} {name}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The JUnit document around the suites.
fn junit_document(suites: &str, c: &Counts, skipped: usize) -> String {
    let tests = suites.matches("<testcase ").count();
    let failures = suites.matches("<failure ").count();
    format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<testsuites name=\"ravel\" tests=\"{tests}\" failures=\"{failures}\" errors=\"{}\" skipped=\"{skipped}\">\n{suites}</testsuites>",
        c[3]
    )
}

/// Where finished items go, in index order: standard output in the chosen
/// format (text and CSV as they come; JSON, JUnit gathered for the closing
/// document) and the verdict counts.
struct Sink<'o> {
    opts: &'o Options,
    counts: Counts,
    /// JSON results, for the closing document.
    results: Vec<Value>,
    /// JUnit suites, for the closing document.
    suites: String,
    /// JUnit test cases skipped (UNSURE).
    skipped: usize,
    /// Whether the CSV header was written.
    header: bool,
    /// The HTML report's entries (with `--report`).
    entries: Vec<crate::html::Entry>,
}

impl Sink<'_> {
    /// Write (or keep) one item; false when standard output is gone.
    fn emit(&mut self, item: Item) -> bool {
        count(&mut self.counts, item.class);
        if self.opts.report.is_some() {
            self.entries.push(item.entry);
        }
        self.skipped += item.junit.matches("<skipped ").count();
        match self.opts.format {
            Format::Text => {
                if !item.stderr.is_empty() {
                    err(&item.stderr);
                }
                if !item.stdout.is_empty() && out(&item.stdout).is_err() {
                    return false;
                }
            }
            Format::Json => {
                let mut json = item.json;
                // a shard's results carry their JUnit suites, for `ravel
                // merge --format junit`
                if self.opts.shard.is_some() {
                    json["junit"] = json!(item.junit);
                }
                self.results.push(json);
            }
            Format::Jsonl => {
                if out(&serde_json::to_string(&item.json).unwrap_or_default()).is_err() {
                    return false;
                }
            }
            Format::Junit => self.suites += &item.junit,
            Format::Csv => {
                if !item.stderr.is_empty() {
                    err(&item.stderr);
                }
                // the header comes with the first rows: a batch that has
                // none (every pair refused, exit 2) prints nothing
                if !self.header && !item.csv.is_empty() {
                    self.header = true;
                    if out(ravel::report::network::CSV_HEADER).is_err() {
                        return false;
                    }
                }
                if !item.csv.is_empty() && out(item.csv.trim_end()).is_err() {
                    return false;
                }
            }
        }
        true
    }

    /// Write the closing document (a summary line, the JSON or JUnit
    /// document); false when standard output is gone.
    fn close(self, total: usize, run_started: Instant) -> bool {
        let opts = self.opts;
        let counts = &self.counts;
        let shard_fields = |doc: &mut Value| {
            if let Some(s) = opts.shard {
                doc["shard"] = json!(format!("{}/{}", s.k, s.n));
                doc["total"] = json!(total);
            }
        };
        let written = match opts.format {
            Format::Text if counts.iter().sum::<usize>() > 1 => {
                let time = if opts.no_timing {
                    String::new()
                } else {
                    format!(" in {:.1} s", run_started.elapsed().as_secs_f64())
                };
                out(&format!("summary: {}{time}", summary(counts)))
            }
            Format::Text | Format::Csv => Ok(()),
            Format::Json => {
                let mut doc = json!({ "schema": ravel::report::SCHEMA, "version": env!("CARGO_PKG_VERSION"), "verdict": overall(counts), "results": self.results });
                shard_fields(&mut doc);
                if opts.shard.is_some() {
                    // the gate the results' JUnit suites were written for
                    doc["fail_on"] = json!(fail_on_name(opts.fail_on));
                }
                out(&serde_json::to_string_pretty(&doc).unwrap_or_default())
            }
            Format::Jsonl => {
                let mut doc = json!({ "schema": ravel::report::SCHEMA, "version": env!("CARGO_PKG_VERSION"), "verdict": overall(counts), "summary": summary(counts) });
                shard_fields(&mut doc);
                out(&serde_json::to_string(&doc).unwrap_or_default())
            }
            Format::Junit => out(&junit_document(&self.suites, counts, self.skipped)),
        };
        written.is_ok()
    }
}

/// The work of a batch: every argument error and (spec, controller) pair,
/// the indices this shard runs, and the folder per-pair files go into.
struct Batch {
    work: Vec<Work>,
    /// The indices of `work` this shard runs.
    mine: Vec<usize>,
    /// The folder of per-pair certificates (one file for a single result).
    cert_dir: Option<PathBuf>,
}

/// Expand the arguments into the batch's work and create its output
/// folders; an exit code when that fails (before anything runs).
fn batch(specs: &[PathBuf], controllers: &[PathBuf], opts: &Options) -> Result<Batch, ExitCode> {
    let (pairs, errors) = super::pairs(specs, controllers);
    // file names from the whole batch, so every shard names a pair alike
    let names = super::output_names(&pairs);
    let mut work: Vec<Work> = errors.into_iter().map(Work::Argument).collect();
    let total = work.len() + pairs.len();
    let mine: Vec<usize> = (0..total)
        .filter(|i| opts.shard.is_none_or(|s| i % s.n == s.k - 1))
        .collect();
    // one file for a single result, else a folder of them
    let cert_dir = opts.certificate.clone().filter(|c| total > 1 || c.is_dir());
    let names = match names {
        Ok(n) => n,
        // only files in a folder need names; a collision there is refused
        // before anything runs
        Err(e) if cert_dir.is_some() || opts.plot.is_some() => {
            err(&format!("error: {e}\n"));
            return Err(ExitCode::from(exit::INPUT_ERROR));
        }
        Err(_) => vec![String::new(); pairs.len()],
    };
    work.extend(
        pairs
            .into_iter()
            .zip(names)
            .map(|((s, c), n)| Work::Pair(s, c, n)),
    );
    for d in cert_dir
        .iter()
        .chain(opts.plot.as_ref())
        .chain(opts.report.as_ref())
    {
        if let Err(e) = std::fs::create_dir_all(d) {
            err(&format!(
                "error: cannot create folder `{}`: {e}\n",
                ravel_syntax::diag::sanitize(&d.display().to_string())
            ));
            return Err(ExitCode::from(exit::INPUT_ERROR));
        }
    }
    Ok(Batch {
        work,
        mine,
        cert_dir,
    })
}

/// `ravel verify`: run the batch's pairs (one at a time on `--jobs`
/// threads each, or `--jobs` pairs at once), write them in index order,
/// then the closing document; the exit code of the `--fail-on` gate.
pub fn verify(specs: &[PathBuf], controllers: &[PathBuf], opts: &Options) -> ExitCode {
    let run_started = Instant::now();
    let b = match batch(specs, controllers, opts) {
        Ok(b) => b,
        Err(code) => return code,
    };
    let mut sink = Sink {
        opts,
        counts: [0; 4],
        results: Vec::new(),
        suites: String::new(),
        skipped: 0,
        header: false,
        entries: Vec::new(),
    };
    let jobs = opts.jobs.min(b.mine.len()).max(1);
    let broken = if jobs == 1 {
        // one pair at a time, each on `opts.jobs` threads: the workers start
        // while the first spec is read and checked
        ravel_analysis::pool::warm(opts.jobs);
        run_serially(&b, opts, &mut sink)
    } else {
        run_in_parallel(&b, opts, jobs, &mut sink, run_started)
    };
    if broken {
        return ExitCode::from(exit::BROKEN_PIPE);
    }
    let counts = sink.counts;
    if let Some(dir) = &opts.report {
        let page = crate::html::page(&sink.entries, &summary(&counts));
        let file = dir.join("index.html");
        if let Err(e) = super::write_atomically(&file, page.as_bytes()) {
            err(&format!(
                "error: cannot write report `{}`: {e}\n",
                ravel_syntax::diag::sanitize(&file.display().to_string())
            ));
            return ExitCode::from(exit::INPUT_ERROR);
        }
    }
    if !sink.close(b.work.len(), run_started) {
        return ExitCode::from(exit::BROKEN_PIPE);
    }
    ExitCode::from(gate(&counts, opts.fail_on))
}

/// Run the batch's pairs one after another, each on `opts.jobs` threads;
/// true when standard output went away.
fn run_serially(b: &Batch, opts: &Options, sink: &mut Sink) -> bool {
    for (k, &i) in b.mine.iter().enumerate() {
        // a single pair gets the jobs for its cells
        let position = Some((k + 1, b.mine.len()));
        let item = run(
            i,
            &b.work[i],
            opts,
            b.cert_dir.as_deref(),
            opts.progress,
            opts.jobs,
            position,
        );
        if !sink.emit(item) {
            return true;
        }
    }
    false
}

/// Run `jobs` pairs at a time; true when standard output went away.
///
/// Threads take the next index; whichever finishes the pair due next
/// writes it, and every later one already done, in index order. No thread
/// only writes: one did, and woke for every pair, taking a core from a
/// worker each time (740–790 context switches per 256 pairs on two jobs).
fn run_in_parallel(
    b: &Batch,
    opts: &Options,
    jobs: usize,
    sink: &mut Sink,
    run_started: Instant,
) -> bool {
    let next = std::sync::atomic::AtomicUsize::new(0);
    // pairs finished (written or waiting for an earlier one), for the
    // progress line
    let finished = std::sync::atomic::AtomicUsize::new(0);
    let last_drawn: std::sync::Mutex<Option<f64>> = std::sync::Mutex::new(None);
    let order = std::sync::Mutex::new(InOrder {
        sink,
        waiting: BTreeMap::new(),
        written: 0,
        broken: false,
    });
    let pairs = || loop {
        let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let Some(&i) = b.mine.get(k) else { break };
        let item = run(i, &b.work[i], opts, b.cert_dir.as_deref(), false, 1, None);
        finished.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let mut o = order.lock().unwrap_or_else(|e| e.into_inner());
        let InOrder {
            sink,
            waiting,
            written,
            broken,
        } = &mut *o;
        waiting.insert(k, item);
        while let Some(item) = waiting.remove(written) {
            *written += 1;
            if opts.progress
                && last_drawn
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .is_some()
            {
                // the item's messages start a line of their own
                err("\r\x1b[2K");
            }
            if !*broken && !sink.emit(item) {
                *broken = true;
                // stop handing out work; running items finish
                next.store(usize::MAX / 2, std::sync::atomic::Ordering::Relaxed);
            }
        }
    };
    // the progress line: the pairs finished so far, redrawn by a ticker
    // (a slow first pair holds back the writing of every later one, but
    // not their count)
    let tick = || {
        let o = order.lock().unwrap_or_else(|e| e.into_inner());
        let now = run_started.elapsed().as_secs_f64();
        let mut last = last_drawn.lock().unwrap_or_else(|e| e.into_inner());
        if o.broken || !progress_due(now, *last) {
            return;
        }
        *last = Some(now);
        err(&format!(
            "\r\x1b[2K[{}/{} pairs done, {now:.0} s]",
            finished.load(std::sync::atomic::Ordering::Relaxed),
            b.mine.len()
        ));
    };
    // the calling thread runs pairs too
    with_ticker(opts.progress, &tick, || {
        std::thread::scope(|scope| {
            for _ in 1..jobs {
                scope.spawn(pairs);
            }
            pairs();
        })
    });
    let o = order.into_inner().unwrap_or_else(|e| e.into_inner());
    if opts.progress {
        err("\r\x1b[2K");
    }
    o.broken
}

/// The pairs finished out of order, until their turn to be written.
struct InOrder<'s, 'o> {
    /// Writes items; false when the output is gone.
    sink: &'s mut Sink<'o>,
    /// Items done, waiting for an earlier one.
    waiting: BTreeMap<usize, Item>,
    /// Items written so far.
    written: usize,
    /// The output is gone.
    broken: bool,
}

/// `ravel merge`: the shards' JSON documents as one, identical to the
/// unsharded run's; every item must be present exactly once. As JUnit, the
/// suites the shards recorded, in index order: the unsharded run's JUnit
/// document (the shards must have been run with the same `--fail-on`).
pub fn merge(files: &[PathBuf], fail_on: FailOn, format: MergeFormat) -> ExitCode {
    let fail = |msg: String| {
        err(&format!("error: {msg}\n"));
        ExitCode::from(exit::INPUT_ERROR)
    };
    let mut total: Option<u64> = None;
    let mut version: Option<Value> = None;
    let mut seen: BTreeMap<u64, Value> = BTreeMap::new();
    for f in files {
        let name = ravel_syntax::diag::sanitize(&f.display().to_string());
        let doc = match super::read_json(f) {
            Ok(v) => v,
            Err(e) => return fail(format!("`{name}`: {e}")),
        };
        if doc["schema"] != ravel::report::SCHEMA {
            return fail(format!(
                "`{name}` is not a {} document",
                ravel::report::SCHEMA
            ));
        }
        let t = match doc["total"].as_u64() {
            Some(t) => t,
            None => return fail(format!("`{name}` is not a shard (written without --shard)")),
        };
        if total.is_some_and(|x| x != t) || version.as_ref().is_some_and(|v| *v != doc["version"]) {
            return fail(format!(
                "`{name}` comes from a different batch (item count or version differs)"
            ));
        }
        total = Some(t);
        version = Some(doc["version"].clone());
        if format == MergeFormat::Junit {
            let wanted = fail_on_name(fail_on);
            match doc["fail_on"].as_str() {
                Some(f) if f == wanted => {}
                Some(f) => {
                    return fail(format!(
                        "`{name}` was run with --fail-on {f}: its JUnit suites follow that gate; merge with --fail-on {f}, or run the shards with --fail-on {wanted}"
                    ))
                }
                None => {
                    return fail(format!(
                        "`{name}` holds no JUnit suites (written by an older ravel): run the shard again"
                    ))
                }
            }
        }
        for r in doc["results"].as_array().into_iter().flatten() {
            let Some(i) = r["index"].as_u64() else {
                return fail(format!("`{name}`: a result has no index"));
            };
            if i >= t || seen.insert(i, r.clone()).is_some() {
                return fail(format!(
                    "`{name}`: item {i} is out of range or appears twice"
                ));
            }
        }
    }
    let total = total.unwrap_or(0);
    if let Some(missing) = (0..total).find(|i| !seen.contains_key(i)) {
        return fail(format!(
            "item {missing} of {total} is in no shard: a shard is missing"
        ));
    }
    let mut counts: Counts = [0; 4];
    for r in seen.values() {
        let class = match r["verdict"].as_str() {
            Some("VERIFIED") => Class::Verdict(Verdict::Verified),
            Some("FALSIFIED") => Class::Verdict(Verdict::Falsified),
            Some("UNSURE") => Class::Verdict(Verdict::Unsure),
            _ => Class::Error,
        };
        count(&mut counts, class);
    }
    let mut suites = String::new();
    let mut results: Vec<Value> = Vec::with_capacity(seen.len());
    for (i, mut r) in seen {
        let junit = r.as_object_mut().and_then(|o| o.remove("junit"));
        if format == MergeFormat::Junit {
            match junit.as_ref().and_then(Value::as_str) {
                Some(suite) if is_suite(suite) => suites += suite,
                _ => return fail(format!("item {i} has no JUnit suite")),
            }
        }
        results.push(r);
    }
    let text = match format {
        MergeFormat::Json => {
            let doc = json!({ "schema": ravel::report::SCHEMA, "version": version.unwrap_or(Value::Null), "verdict": overall(&counts), "results": results });
            serde_json::to_string_pretty(&doc).unwrap_or_default()
        }
        MergeFormat::Junit => {
            let skipped = suites.matches("<skipped ").count();
            junit_document(&suites, &counts, skipped)
        }
    };
    if out(&text).is_err() {
        return ExitCode::from(exit::BROKEN_PIPE);
    }
    ExitCode::from(gate(&counts, fail_on))
}

/// Whether a shard's `junit` text is one `<testsuite>` element as `verify`
/// writes them (a file edited by hand or by another program could hold
/// anything; it is copied into the document only when it has this form).
fn is_suite(text: &str) -> bool {
    text.starts_with("  <testsuite name=\"")
        && text.ends_with("  </testsuite>\n")
        && text.matches("<testsuite ").count() == 1
        && text.matches("</testsuite>").count() == 1
        && !text.contains("<?")
        && !text
            .chars()
            .any(|c| c.is_control() && c != '\n' && c != '\t')
}
