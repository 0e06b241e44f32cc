//! ravel: a Reach-Avoid Verification Language and its compiler.
#![forbid(unsafe_code)]

/// The allocator of every program that links ravel with its default feature
/// `mimalloc`: mimalloc. The analysis allocates many small vectors per step;
/// glibc's allocator takes an atomic lock on every call once a second thread
/// exists, which cost the parallel cell and batch runs about 40 % per thread
/// (see the speed benchmark). The Python extension turns the feature off: a
/// library loaded into a running interpreter keeps the interpreter's
/// allocator (ARCHITECTURE.md, Decisions).
#[cfg(feature = "mimalloc")]
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

pub mod certificate_writer;
pub mod check;
pub mod execute;
pub mod ir;
pub mod lower;
pub mod onnx;
pub mod plot;
pub mod report;
pub mod vnnlib;

use std::path::{Path, PathBuf};

use check::{Checked, ControllerFile, Task};
use execute::{Control, Run};
use ravel_base::limits;
use ravel_syntax as syntax;
use ravel_syntax::diag::{self, Diagnostic};
use serde_json::Value;

/// One file the front end asks the caller to read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ReadRequest {
    /// The file.
    pub path: PathBuf,
    /// When set, the file (after resolving symbolic links) must lie inside
    /// this folder: external-data files must stay in the controller's folder.
    pub inside: Option<PathBuf>,
    /// Read at most this many bytes from the start: more than this is never
    /// needed (a larger controller file is an error; an external-data file
    /// is read only as far as the model's tensors need).
    pub max_bytes: u64,
    /// Whether a file longer than `max_bytes` is an error (the controller)
    /// or simply read up to `max_bytes` (external data). A whole file whose
    /// name ends in `.gz` is decompressed by the entry points' reader, its
    /// decompressed size limited by `max_bytes`; a prefix (external data) is
    /// read as stored.
    pub whole: bool,
}

/// How the front end reads files; the library does no IO of its own. The CLI
/// passes `ravel_cli::read_request`, which reads regular files only; tests may
/// pass anything.
pub type Reader<'a> = &'a dyn Fn(&ReadRequest) -> Result<Vec<u8>, ReadError>;

/// Why a file the front end asked for was not read. Its `Display` is the
/// reason a diagnostic gives after the file's name.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ReadError {
    /// The operating system refused (not found, permission denied, …), in
    /// its own words.
    Io(String),
    /// The path is a folder.
    Folder,
    /// The path is a FIFO, device or socket (refused before any read).
    Special,
    /// The path resolves, through a symbolic link, to a file outside the
    /// folder the request confines it to.
    Outside,
    /// The file is longer than the request allows.
    TooLarge {
        /// Its length.
        bytes: u64,
        /// The request's limit.
        limit: u64,
    },
    /// The file is compressed (`.gz`) and decompresses to more than the
    /// request allows (reading stopped at the limit).
    DecompressedTooLarge {
        /// The request's limit.
        limit: u64,
    },
    /// The file is named `.gz` but is not a complete, valid gzip stream
    /// (not gzip at all, truncated or corrupt), with the decoder's reason.
    Compressed(String),
}

impl std::fmt::Display for ReadError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ReadError::Io(e) => f.write_str(e),
            ReadError::Folder => f.write_str("it is a folder, not a regular file"),
            ReadError::Special => {
                f.write_str("it is a special file (FIFO, device or socket), not a regular file")
            }
            ReadError::Outside => f.write_str(
                "it resolves (through a symbolic link) to a file outside the controller's folder",
            ),
            ReadError::TooLarge { bytes, limit } => {
                write!(f, "it has {bytes} bytes, more than the limit of {limit}")
            }
            // short: a controller's reason is cut at 80 characters
            ReadError::DecompressedTooLarge { limit } => {
                write!(f, "it decompresses to more than the limit of {limit} bytes")
            }
            ReadError::Compressed(e) => write!(f, "it is not valid gzip ({e})"),
        }
    }
}

impl std::error::Error for ReadError {}

impl From<std::io::Error> for ReadError {
    fn from(e: std::io::Error) -> ReadError {
        ReadError::Io(e.to_string())
    }
}

/// The front end: parse and check a spec, reading its controller (and any
/// external-data files) through `read`, relative to `spec_dir`.
///
/// External-data locations are checked before anything is read: each must
/// be a plain relative path inside the controller's folder (no `..`, not
/// absolute), each distinct file is read once, and only as many bytes as
/// the tensors stored in it need (their total is limited, see
/// [`limits::MAX_CONTROLLER_BYTES`]).
pub fn front_end(source: &str, spec_dir: &Path, read: Reader) -> Result<Checked, Vec<Diagnostic>> {
    front_end_with(source, spec_dir, read, None)
}

/// [`front_end`] with the spec's controller replaced by `controller` (a
/// path as given on the command line, not relative to the spec), as
/// `ravel verify SPEC --controller PATH` does; the spec then need not name
/// a controller at all.
pub fn front_end_with(
    source: &str,
    spec_dir: &Path,
    read: Reader,
    controller: Option<&Path>,
) -> Result<Checked, Vec<Diagnostic>> {
    match front_end_task(source, spec_dir, read, controller)? {
        Task::System(c) => Ok(*c),
        Task::Network(_) => Err(vec![diag::Diagnostic::new(
            diag::Code::SpecKind,
            syntax::ast::Span::new(0, 0),
            "this is a network spec, not a system spec",
        )
        .label("a network on its own")
        .hint("this entry point reads closed-loop specs; `ravel verify` reads both kinds")]),
    }
}

/// The front end for a spec of either kind (a closed loop or a network on
/// its own); `controller` overrides the spec's controller or model.
pub fn front_end_task(
    source: &str,
    spec_dir: &Path,
    read: Reader,
    controller: Option<&Path>,
) -> Result<Task, Vec<Diagnostic>> {
    let spec = syntax::parse(source)?;
    let path = match controller {
        Some(c) => Some(c.to_path_buf()),
        None => check::controller_path(&spec).map(|p| spec_dir.join(&p.node)),
    };
    let path_override = controller.map(|c| c.display().to_string());
    let controller = path.map(|path| {
        let bytes = read(&ReadRequest {
            path: path.clone(),
            inside: None,
            max_bytes: limits::MAX_CONTROLLER_BYTES,
            whole: true,
        })
        .map_err(|e| e.to_string());
        let mut external = onnx::ExternalFiles::new();
        if let Ok(b) = &bytes {
            let dir = match path.parent() {
                Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
                _ => PathBuf::from("."),
            };
            let mut total = 0u64;
            for req in onnx::external_requests(b) {
                total = total.saturating_add(req.bytes);
                let data = if total > limits::MAX_CONTROLLER_BYTES {
                    Err("the external data of this model exceeds 512 MiB".to_string())
                } else {
                    read(&ReadRequest {
                        path: dir.join(&req.location),
                        inside: Some(dir.clone()),
                        max_bytes: req.bytes,
                        whole: false,
                    })
                    .map_err(|e| e.to_string())
                };
                external.insert(req.location, data);
            }
        }
        ControllerFile {
            path_override: path_override.clone(),
            resolved: path.display().to_string(),
            bytes,
            external,
        }
    });
    let data: check::DataFiles = check::data_paths(&spec)
        .into_iter()
        .map(|p| {
            // observation files stay in the spec's folder, under the same
            // rules as a model's external data (checked before any read)
            let bytes = match onnx::normalise_location(&p) {
                None => Err("observation files must lie in the spec's folder (a relative path without `..`)".to_string()),
                Some(rel) => read(&ReadRequest {
                    path: spec_dir.join(rel),
                    inside: Some(spec_dir.to_path_buf()),
                    max_bytes: limits::MAX_SPEC_BYTES,
                    whole: true,
                })
                .map_err(|e| e.to_string()),
            };
            (p, bytes)
        })
        .collect();
    check::check_task(&spec, controller.as_ref(), &data)
}

/// The back end: lower a checked task and execute its plan under `ctl`.
///
/// It cannot fail: every problem a spec can have is a diagnostic of the
/// front end, and whatever the analysis cannot decide (a solver issue, an
/// overflow, the time limit) is an UNSURE property of the run, with its
/// reason. Reports ([`report::text`], [`report::json`]) and certificates
/// ([`certificate_writer::build`]) are made from the run.
pub fn run(task: &Task, ctl: &Control) -> Run {
    execute::execute(lower::lower(task), ctl)
}

/// The whole pipeline for one spec: [`front_end_task`] (parse, check, read
/// the controller through `read`), then [`run`].
pub fn verify(
    source: &str,
    spec_dir: &Path,
    read: Reader,
    controller: Option<&Path>,
    ctl: &Control,
) -> Result<Run, Vec<Diagnostic>> {
    let task = front_end_task(source, spec_dir, read, controller)?;
    Ok(run(&task, ctl))
}

/// Why a certificate is not about a plan: its recorded controller, network
/// or problem is not the plan's. `Display` says which, for people.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum NotCertified {
    /// The controller file's SHA-256 is not the recorded one.
    Controller,
    /// The network read (external data included) is not the recorded one.
    Network,
    /// The recorded problem differs from the plan's, first at this path.
    Problem(String),
}

impl std::fmt::Display for NotCertified {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NotCertified::Controller => {
                f.write_str("the controller file is not the one certified (SHA-256 differs)")
            }
            NotCertified::Network => f.write_str(
                "the controller's network (external data included) is not the one certified",
            ),
            NotCertified::Problem(at) => write!(
                f,
                "the recorded problem is not the spec's: `{}` differs",
                diag::sanitize(at)
            ),
        }
    }
}

/// Whether a certificate is about `plan`: the controller and its network
/// are the certified ones, and the spec's problem is the recorded one,
/// number for number (the spec's text may differ: comments, layout). What
/// `ravel certify` and the Python package's `certify` ask before they let
/// [`ravel_certify::check`] read the certificate's claims.
pub fn certified_problem(cert: &Value, plan: &lower::Plan) -> Result<(), NotCertified> {
    let recorded = |field: &str| {
        cert.get("controller")
            .and_then(|v| v.get(field))
            .and_then(Value::as_str)
            .unwrap_or("")
    };
    if plan.controller_sha256() != recorded("sha256") {
        return Err(NotCertified::Controller);
    }
    if certificate_writer::network_sha256(plan.network()) != recorded("network_sha256") {
        return Err(NotCertified::Network);
    }
    let problem = certificate_writer::problem_json(plan);
    match first_difference(
        &problem,
        cert.get("problem").unwrap_or(&Value::Null),
        "problem",
    ) {
        Some(at) => Err(NotCertified::Problem(at)),
        None => Ok(()),
    }
}

/// The first place two JSON values differ, as a path (`problem.plants[0].A[1]`).
pub fn first_difference(a: &Value, b: &Value, path: &str) -> Option<String> {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            for (k, v) in x {
                let p = format!("{path}.{k}");
                match y.get(k) {
                    Some(w) => {
                        if let Some(d) = first_difference(v, w, &p) {
                            return Some(d);
                        }
                    }
                    None => return Some(p),
                }
            }
            y.keys()
                .find(|k| !x.contains_key(*k))
                .map(|k| format!("{path}.{k}"))
        }
        (Value::Array(x), Value::Array(y)) => {
            if x.len() != y.len() {
                return Some(format!("{path} (length {} vs {})", x.len(), y.len()));
            }
            x.iter()
                .zip(y)
                .enumerate()
                .find_map(|(i, (v, w))| first_difference(v, w, &format!("{path}[{i}]")))
        }
        _ => (a != b).then(|| path.to_string()),
    }
}
