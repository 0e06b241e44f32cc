//! `ravel._ravel`, the extension module of the Python package: `check`,
//! `verify` and `certify` through the library's pipeline, exactly as the
//! command line runs it (`ravel::front_end_task`, `ravel::run`,
//! `ravel::report::json`, `ravel::certificate_writer::build`,
//! `ravel::certified_problem` and `ravel_certify::check`). Files are read by
//! `ravel_files::read_request`, the command line's reader, under the same
//! limits; a controller given as bytes is served to the front end in place
//! of a file. Diagnostics become `ravel.RavelError` with their code, span and
//! hint; the analysis runs with the GIL released. The public API, its
//! documentation and type hints are the pure-Python layer's
//! (`python/ravel/__init__.py`), which turns what this module returns (JSON
//! text, little-endian `f64` buffers with their shapes) into Python objects
//! and NumPy arrays.
//!
//! This crate is an entry point like the command line: it may read files
//! (ARCHITECTURE.md). PyO3's macros expand to `unsafe` code, so the root
//! denies `unsafe_code` (the macros allow it where they expand) instead of
//! forbidding it.
#![deny(unsafe_code)]

use std::path::{Path, PathBuf};
use std::time::Instant;

use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList, PyTuple};
use serde_json::{json, Value};

use ravel::execute::{Control, Run};
use ravel::{ReadError, ReadRequest};
use ravel_base::limits;
use ravel_syntax::diag::{self, Diagnostic};

pyo3::create_exception!(
    _ravel,
    RavelError,
    PyException,
    "A spec, controller or certificate ravel cannot use (its diagnostics)."
);

/// The folder a controller given as bytes seems to lie in, for the front
/// end: nothing is ever read under it.
const BYTES_FOLDER: &str = "<bytes>";

/// The path a controller given as bytes is requested under.
fn bytes_path() -> PathBuf {
    Path::new(BYTES_FOLDER).join("controller.onnx")
}

/// A spec's text, the name it is shown under and the folder its relative
/// paths are read from.
struct Spec {
    name: String,
    text: String,
    dir: PathBuf,
}

/// The controller the caller passes instead of the spec's own.
enum Controller<'a> {
    Spec,
    Path(PathBuf),
    Bytes(&'a [u8]),
}

impl Controller<'_> {
    /// The path the front end is told to read the controller from.
    fn path(&self) -> Option<PathBuf> {
        match self {
            Controller::Spec => None,
            Controller::Path(p) => Some(p.clone()),
            Controller::Bytes(_) => Some(bytes_path()),
        }
    }

    /// Read what the front end asks for: the bytes for the bytes' path,
    /// nothing under their folder (a model in memory has no external data),
    /// every other file through the command line's reader.
    fn read(&self, req: &ReadRequest) -> Result<Vec<u8>, ReadError> {
        if let Controller::Bytes(b) = self {
            if req.path == bytes_path() {
                let len = b.len() as u64;
                if len > req.max_bytes {
                    return Err(ReadError::TooLarge {
                        bytes: len,
                        limit: req.max_bytes,
                    });
                }
                return Ok(b.to_vec());
            }
            if req.path.starts_with(BYTES_FOLDER) {
                return Err(ReadError::Io(
                    "a model given as bytes has no folder to read external data from; pass its path instead".into(),
                ));
            }
        }
        ravel_files::read_request(req)
    }
}

/// A `RavelError` without a diagnostic (an unreadable file, a bad argument).
fn plain_error(py: Python<'_>, message: String) -> PyErr {
    let message = diag::sanitize(&message);
    let err = RavelError::new_err(message.clone());
    let value = err.value(py);
    let set = || -> PyResult<()> {
        value.setattr("code", py.None())?;
        value.setattr("message", &message)?;
        value.setattr("span", py.None())?;
        value.setattr("hint", py.None())?;
        value.setattr("label", py.None())?;
        value.setattr("diagnostics", PyList::empty(py))?;
        Ok(())
    };
    match set() {
        Ok(()) => err,
        Err(e) => e,
    }
}

/// One diagnostic as a dict: code, message, label, hint, span.
fn diagnostic_dict<'py>(
    py: Python<'py>,
    d: &Diagnostic,
    source: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    out.set_item("code", d.code.as_str())?;
    out.set_item("message", diag::sanitize(&d.message))?;
    out.set_item("label", diag::sanitize(&d.label))?;
    out.set_item("hint", d.hint.as_deref().map(diag::sanitize))?;
    match d.span {
        Some(s) => {
            let span = PyDict::new(py);
            let (line, column) = diag::line_col(source, s.start);
            let (end_line, end_column) = diag::line_col(source, s.end);
            span.set_item("start", s.start)?;
            span.set_item("end", s.end)?;
            span.set_item("line", line)?;
            span.set_item("column", column)?;
            span.set_item("end_line", end_line)?;
            span.set_item("end_column", end_column)?;
            out.set_item("span", span)?;
        }
        None => out.set_item("span", py.None())?,
    }
    Ok(out)
}

/// The front end's diagnostics as one `RavelError`: its text is the
/// command line's rendering without colours, its attributes the first
/// diagnostic's, and `diagnostics` lists them all.
fn diagnostics_error(py: Python<'_>, spec: &Spec, diags: &[Diagnostic]) -> PyErr {
    let text = format!(
        "{}{}: {} error(s)",
        diag::render(diags, &spec.name, &spec.text, 100, false),
        diag::sanitize(&spec.name),
        diags.len()
    );
    let err = RavelError::new_err(text);
    let value = err.value(py);
    let set = || -> PyResult<()> {
        let all = PyList::empty(py);
        for d in diags {
            all.append(diagnostic_dict(py, d, &spec.text)?)?;
        }
        match all.get_item(0) {
            Ok(first) => {
                for key in ["code", "message", "label", "hint", "span"] {
                    value.setattr(key, first.get_item(key)?)?;
                }
            }
            Err(_) => {
                for key in ["code", "message", "label", "hint", "span"] {
                    value.setattr(key, py.None())?;
                }
            }
        }
        value.setattr("diagnostics", all)?;
        Ok(())
    };
    match set() {
        Ok(()) => err,
        Err(e) => e,
    }
}

/// The spec from a path (read under the spec size limit, UTF-8) or a text
/// (its relative paths read from `directory`, else the working folder).
fn load_spec(
    py: Python<'_>,
    path: Option<String>,
    text: Option<String>,
    directory: Option<String>,
) -> PyResult<Spec> {
    match (path, text) {
        (Some(path), None) => {
            let path = PathBuf::from(path);
            let name = diag::sanitize(&path.display().to_string());
            let bytes = ravel_files::read_request(&ReadRequest {
                path: path.clone(),
                inside: None,
                max_bytes: limits::MAX_SPEC_BYTES,
                whole: true,
            })
            .map_err(|e| plain_error(py, format!("cannot read spec `{name}`: {e}")))?;
            let text = String::from_utf8(bytes)
                .map_err(|_| plain_error(py, format!("spec `{name}` is not UTF-8 text")))?;
            let dir = match directory {
                Some(d) => PathBuf::from(d),
                None => path.parent().unwrap_or(Path::new(".")).to_path_buf(),
            };
            Ok(Spec { name, text, dir })
        }
        (None, Some(text)) => {
            if text.len() as u64 > limits::MAX_SPEC_BYTES {
                return Err(plain_error(
                    py,
                    format!(
                        "the spec's text has {} bytes, more than the limit of {}",
                        text.len(),
                        limits::MAX_SPEC_BYTES
                    ),
                ));
            }
            Ok(Spec {
                name: "<text>".into(),
                text,
                dir: PathBuf::from(directory.unwrap_or_else(|| ".".into())),
            })
        }
        _ => Err(plain_error(
            py,
            "give the spec as a path or as `text=`, not both or neither".into(),
        )),
    }
}

/// The controller argument: none, a path or bytes.
fn controller<'a>(
    py: Python<'_>,
    path: Option<String>,
    bytes: Option<&'a [u8]>,
) -> PyResult<Controller<'a>> {
    match (path, bytes) {
        (None, None) => Ok(Controller::Spec),
        (Some(p), None) => Ok(Controller::Path(PathBuf::from(p))),
        (None, Some(b)) => Ok(Controller::Bytes(b)),
        (Some(_), Some(_)) => Err(plain_error(
            py,
            "give the controller as a path or as bytes, not both".into(),
        )),
    }
}

/// The spec as the Python layer passes it: `(path, text, directory)`, one
/// of the first two set.
type SpecArgs = (Option<String>, Option<String>, Option<String>);

/// A spec and the controller given with it: what the front end reads.
struct Inputs<'a> {
    spec: Spec,
    ctrl: Controller<'a>,
}

impl<'a> Inputs<'a> {
    /// The spec (a path or a text) and the controller (none, a path or
    /// bytes) from the arguments.
    fn new(
        py: Python<'_>,
        (path, text, directory): SpecArgs,
        controller_path: Option<String>,
        controller_bytes: Option<&'a [u8]>,
    ) -> PyResult<Inputs<'a>> {
        Ok(Inputs {
            spec: load_spec(py, path, text, directory)?,
            ctrl: controller(py, controller_path, controller_bytes)?,
        })
    }

    /// The front end over the spec, with the controller given in place of
    /// the spec's own (run without the GIL).
    fn front_end(&self) -> Result<ravel::check::Task, Vec<Diagnostic>> {
        ravel::front_end_task(
            &self.spec.text,
            &self.spec.dir,
            &|r| self.ctrl.read(r),
            self.ctrl.path().as_deref(),
        )
    }
}

/// Parse and check a spec with its controller; the kind of spec
/// (`"system"` or `"network"`), or `RavelError`.
#[pyfunction]
#[pyo3(signature = (spec, controller_path=None, controller_bytes=None))]
fn check(
    py: Python<'_>,
    spec: SpecArgs,
    controller_path: Option<String>,
    controller_bytes: Option<&[u8]>,
) -> PyResult<&'static str> {
    let inputs = Inputs::new(py, spec, controller_path, controller_bytes)?;
    match py.allow_threads(|| inputs.front_end()) {
        Ok(ravel::check::Task::System(_)) => Ok("system"),
        Ok(ravel::check::Task::Network(_)) => Ok("network"),
        Err(d) => Err(diagnostics_error(py, &inputs.spec, &d)),
    }
}

/// An array for the Python layer: its name, its `f64` values (row-major,
/// little-endian) and its shape.
struct Array {
    name: &'static str,
    data: Vec<f64>,
    shape: Vec<usize>,
}

impl Array {
    /// Boxes' lower or upper bounds stacked: shape `(boxes, n)`.
    fn rows<'a>(name: &'static str, n: usize, rows: impl Iterator<Item = &'a [f64]>) -> Array {
        let mut data = Vec::new();
        let mut count = 0;
        for r in rows {
            data.extend_from_slice(r);
            count += 1;
        }
        Array {
            name,
            data,
            shape: vec![count, n],
        }
    }
}

/// The run's sets as arrays: a closed loop's reachable boxes per step (all
/// cells' bounding box, and each cell's), a network's output box and its
/// partition's cells.
fn arrays(run: &Run) -> Vec<Array> {
    match run {
        Run::System { outcome, .. } => {
            let n = outcome.reach.first().map_or(0, |b| b.lo.len());
            let mut out = vec![
                Array::rows("lower", n, outcome.reach.iter().map(|b| b.lo.as_slice())),
                Array::rows("upper", n, outcome.reach.iter().map(|b| b.hi.as_slice())),
            ];
            let steps = outcome.reach.len();
            let boxes: Vec<_> = outcome
                .cells
                .iter()
                .flat_map(|c| c.iter().map(|r| r.bbox()))
                .collect();
            for (name, hi) in [("cell_lower", false), ("cell_upper", true)] {
                let mut a = Array::rows(
                    name,
                    n,
                    boxes
                        .iter()
                        .map(|b| if hi { b.hi.as_slice() } else { b.lo.as_slice() }),
                );
                a.shape = vec![outcome.cells.len(), steps, n];
                out.push(a);
            }
            out
        }
        Run::Network { outcome, .. } => {
            let mut out = Vec::new();
            if let Some(b) = &outcome.output.bbox {
                out.push(Array {
                    name: "lower",
                    data: b.lo.clone(),
                    shape: vec![b.lo.len()],
                });
                out.push(Array {
                    name: "upper",
                    data: b.hi.clone(),
                    shape: vec![b.hi.len()],
                });
            }
            let n = outcome.partition.first().map_or(0, |b| b.lo.len());
            out.push(Array::rows(
                "cell_lower",
                n,
                outcome.partition.iter().map(|b| b.lo.as_slice()),
            ));
            out.push(Array::rows(
                "cell_upper",
                n,
                outcome.partition.iter().map(|b| b.hi.as_slice()),
            ));
            out
        }
    }
}

/// Parse, check, run and report a spec: `(report JSON text, arrays,
/// certificate JSON text or None)`, each array a `(name, bytes, shape)`.
#[pyfunction]
#[pyo3(signature = (spec, controller_path=None, controller_bytes=None, time_limit=None, jobs=None, certificate=false))]
fn verify<'py>(
    py: Python<'py>,
    spec: SpecArgs,
    controller_path: Option<String>,
    controller_bytes: Option<&[u8]>,
    time_limit: Option<f64>,
    jobs: Option<usize>,
    certificate: bool,
) -> PyResult<Bound<'py, PyTuple>> {
    if time_limit.is_some_and(|t| !(t.is_finite() && t >= 0.0)) {
        return Err(plain_error(
            py,
            "time_limit must be a finite, non-negative number of seconds".into(),
        ));
    }
    if jobs == Some(0) {
        return Err(plain_error(py, "jobs must be at least 1".into()));
    }
    let inputs = Inputs::new(py, spec, controller_path, controller_bytes)?;
    let (spec, override_path) = (&inputs.spec, inputs.ctrl.path());
    let threads =
        jobs.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let ran = py.allow_threads(|| {
        let task = inputs.front_end()?;
        let started = Instant::now();
        let clock = || started.elapsed().as_secs_f64();
        let run = ravel::run(
            &task,
            &Control {
                elapsed: &clock,
                time_limit,
                progress: &|_| {},
                threads,
            },
        );
        let mut report = ravel::report::json(&spec.name, &run, None);
        if let (Run::Network { .. }, Some(c)) = (&run, &override_path) {
            report["controller"] = json!(c.display().to_string());
        }
        let cert = certificate.then(|| {
            let id = ravel::certificate_writer::Identity {
                spec_path: spec.name.clone(),
                spec_sha256: ravel::check::sha256_hex(spec.text.as_bytes()),
            };
            let mut cert = ravel::certificate_writer::build(&run, &id);
            cert["controller"]["path"] = json!(run.controller_resolved());
            cert.to_string()
        });
        Ok((report.to_string(), arrays(&run), cert))
    });
    let (report, arrays, cert) =
        ran.map_err(|d: Vec<Diagnostic>| diagnostics_error(py, spec, &d))?;
    let list = PyList::empty(py);
    for a in arrays {
        let bytes: Vec<u8> = a.data.iter().flat_map(|v| v.to_le_bytes()).collect();
        list.append((a.name, PyBytes::new(py, &bytes), PyTuple::new(py, a.shape)?))?;
    }
    PyTuple::new(
        py,
        [
            report.into_pyobject(py)?.into_any(),
            list.into_any(),
            cert.into_pyobject(py)?.into_any(),
        ],
    )
}

/// Re-check a certificate as `ravel certify` does: the spec (given, else
/// recorded relative to `folder`) and the controller (given as a path or
/// bytes, else recorded) through the front end, the certified problem
/// compared with the spec's, then the checker. A dict: `answer` (`VALID`,
/// `INVALID`, `UNSUPPORTED`, `UNREADABLE`), `reason`, `cells`, `steps`,
/// `properties`, `spec_text_differs`.
#[pyfunction]
#[pyo3(signature = (certificate_path, certificate, spec, controller_path=None, controller_bytes=None))]
fn certify<'py>(
    py: Python<'py>,
    certificate_path: Option<String>,
    certificate: Option<&[u8]>,
    spec: SpecArgs,
    controller_path: Option<String>,
    controller_bytes: Option<&[u8]>,
) -> PyResult<Bound<'py, PyDict>> {
    let (spec_path, spec_text, directory) = spec;
    let out = PyDict::new(py);
    let answer = |answer: &str, reason: Option<String>| -> PyResult<Bound<'py, PyDict>> {
        out.set_item("answer", answer)?;
        out.set_item("reason", reason.map(|r| diag::sanitize_to(&r, 600)))?;
        for key in ["cells", "steps"] {
            if !out.contains(key)? {
                out.set_item(key, 0)?;
            }
        }
        if !out.contains("properties")? {
            out.set_item("properties", PyList::empty(py))?;
        }
        if !out.contains("spec_text_differs")? {
            out.set_item("spec_text_differs", py.None())?;
        }
        Ok(out.clone())
    };
    // a certificate file is read as the command line reads it; its
    // recorded paths are relative to its folder
    let (read, folder) = match (&certificate_path, certificate) {
        (Some(p), None) => {
            let path = PathBuf::from(p);
            let read = ravel_files::read_request(&ReadRequest {
                path: path.clone(),
                inside: None,
                max_bytes: limits::MAX_CONTROLLER_BYTES,
                whole: true,
            });
            let folder = path.parent().unwrap_or(Path::new("")).to_path_buf();
            (read.map_err(|e| format!("cannot read: {e}")), folder)
        }
        (None, Some(b)) => (Ok(b.to_vec()), PathBuf::new()),
        _ => {
            return Err(plain_error(
                py,
                "give the certificate as a path or as its JSON, not both or neither".into(),
            ))
        }
    };
    let cert: Value =
        match read.and_then(|b| serde_json::from_slice(&b).map_err(|e| format!("not JSON: {e}"))) {
            Ok(v) => v,
            Err(why) => return answer("UNREADABLE", Some(why)),
        };
    let recorded = |key: &str| {
        cert.get(key)
            .and_then(|v| v.get("path"))
            .and_then(Value::as_str)
            .map(|p| folder.join(p).display().to_string())
    };
    let (spec_path, spec_text) = match (spec_path, spec_text) {
        (None, None) => match recorded("spec") {
            Some(p) => (Some(p), None),
            None => {
                return answer(
                    "UNREADABLE",
                    Some("no spec path recorded; pass spec=".into()),
                )
            }
        },
        given => given,
    };
    let controller_path = match (&controller_path, controller_bytes) {
        (None, None) => match recorded("controller") {
            Some(p) => Some(p),
            None => {
                return answer(
                    "UNREADABLE",
                    Some("no controller path recorded; pass controller=".into()),
                )
            }
        },
        _ => controller_path,
    };
    let inputs = Inputs::new(
        py,
        (spec_path, spec_text, directory),
        controller_path,
        controller_bytes,
    )?;
    let spec = &inputs.spec;
    let checked = py.allow_threads(|| {
        let task = inputs.front_end()?;
        let plan = ravel::lower::lower(&task);
        let recorded_sha = cert
            .get("spec")
            .and_then(|v| v.get("sha256"))
            .and_then(Value::as_str)
            .unwrap_or("");
        let differs = ravel::check::sha256_hex(spec.text.as_bytes()) != recorded_sha;
        Ok(match ravel::certified_problem(&cert, &plan) {
            Err(why) => (differs, Err(why.to_string())),
            Ok(()) => (differs, Ok(ravel_certify::check(&cert, plan.network()))),
        })
    });
    let (differs, report) =
        checked.map_err(|d: Vec<Diagnostic>| diagnostics_error(py, spec, &d))?;
    out.set_item("spec_text_differs", differs)?;
    match report {
        Err(why) => answer("INVALID", Some(why)),
        Ok(report) => {
            use ravel_certify::Answer;
            out.set_item("cells", report.cells)?;
            out.set_item("steps", report.steps)?;
            out.set_item("subproblems", report.subproblems)?;
            let props: Vec<String> = report
                .properties
                .iter()
                .map(|p| diag::sanitize(p))
                .collect();
            out.set_item("properties", props)?;
            match report.answer {
                Answer::Valid => answer("VALID", None),
                Answer::Invalid(m) => answer("INVALID", Some(m)),
                Answer::Unsupported(m) => answer("UNSUPPORTED", Some(m)),
                Answer::Unreadable(m) => answer("UNREADABLE", Some(m)),
            }
        }
    }
}

/// The extension module.
#[pymodule]
fn _ravel(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("RavelError", m.py().get_type::<RavelError>())?;
    m.add("MAX_SPEC_BYTES", limits::MAX_SPEC_BYTES)?;
    m.add("MAX_CONTROLLER_BYTES", limits::MAX_CONTROLLER_BYTES)?;
    m.add_function(wrap_pyfunction!(check, m)?)?;
    m.add_function(wrap_pyfunction!(verify, m)?)?;
    m.add_function(wrap_pyfunction!(certify, m)?)?;
    Ok(())
}
