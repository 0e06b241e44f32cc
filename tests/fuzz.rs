//! Mutation fuzzing of the front end (parser and checker, and the formatter:
//! idempotent, never a change of meaning) and of the ONNX
//! loader, in process, with no file-system access (an in-memory reader).
//!
//! Opt-in: the tests are `#[ignore]`d and run for `RAVEL_FUZZ_SECONDS`
//! (default 60) each:
//!
//! ```sh
//! RAVEL_FUZZ_SECONDS=1800 cargo test --release --test fuzz -- --ignored --nocapture
//! ```
//!
//! A finding is a panic, a run over 5 s on one input (over 20 s: a watchdog
//! saves the input and ends the process), or an accepted input
//! that breaks an invariant (a spec that checks must lower, a loaded network
//! must have finite weights within the limits). Findings are written to
//! `target/fuzz-findings/` and fail the test. Seeds are the specs under
//! `specs/` and `tests/corpus/specs/` and the models under `models/` and
//! `tests/corpus/onnx/`; the mutations are byte flips, deletions,
//! duplications, splices and insertions of tokens that reach edge cases
//! (huge and non-finite numbers, brackets, BOMs, CRs, non-ASCII letters).

use std::collections::BTreeMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use ravel::onnx::ExternalFiles;
use ravel::ReadRequest;
use ravel_base::rng::Rng;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn budget() -> Duration {
    let s = std::env::var("RAVEL_FUZZ_SECONDS")
        .ok()
        .and_then(|v| v.parse::<f64>().ok())
        .unwrap_or(60.0);
    Duration::from_secs_f64(s)
}

fn files(dir: &Path, ext: &str) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| {
            d.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == ext))
                .collect()
        })
        .unwrap_or_default();
    out.sort();
    out
}

const TOKENS: &[&str] = &[
    "1e308",
    "-1e308",
    "1e400",
    "1e16",
    "1e-320",
    "nan",
    "inf",
    "0",
    "-0",
    "99999999999999999999",
    "18446744073709551615",
    "100000",
    "1000",
    "[",
    "]",
    "[[",
    "]]",
    "(",
    ")",
    "{",
    "}",
    ",",
    "|",
    "\u{feff}",
    "\r",
    "\n",
    "//",
    "/*",
    "\"",
    "é",
    "\u{1b}",
    "x[",
    "x[0]",
    "u[0]",
    "in",
    "box(",
    "ball(",
    "per_step(",
    "eye(1000)",
    "zeros(1000, 1000)",
    "uniform [",
    "calls 100000",
    "horizon 10000",
    "samples 1000000",
    "optimise_slopes 100",
    "time continuous dt 1e300",
    "polytope 1000",
    "boundary hull",
    "at steps [",
    "norm 1",
    "propagator reach_sdp",
    "partitioner property",
];

fn mutate(rng: &mut Rng, seeds: &[Vec<u8>], input: &[u8], text: bool) -> Vec<u8> {
    let mut v = input.to_vec();
    for _ in 0..1 + rng.below(4) {
        let len = v.len();
        let at = if len == 0 { 0 } else { rng.below(len + 1) };
        match rng.below(if text { 7 } else { 6 }) {
            0 if len > 0 => {
                let i = rng.below(len);
                v[i] ^= 1 << rng.below(8);
            }
            1 if len > 0 => {
                let end = (at + 1 + rng.below(16)).min(len);
                v.drain(at.min(end)..end);
            }
            2 if len > 0 => {
                let end = (at + 1 + rng.below(64)).min(len);
                let chunk = v[at.min(end)..end].to_vec();
                let to = rng.below(v.len() + 1);
                v.splice(to..to, chunk);
            }
            3 => {
                let other = &seeds[rng.below(seeds.len())];
                if !other.is_empty() {
                    let from = rng.below(other.len());
                    let end = (from + 1 + rng.below(256)).min(other.len());
                    v.splice(at..at, other[from..end].iter().copied());
                }
            }
            4 if len > 0 => {
                let i = rng.below(len);
                v[i] = [0u8, 0x7f, 0x80, 0xff, 0x01, 0x08, 0x0a][rng.below(7)];
            }
            5 => v.truncate(at),
            _ => {
                let t = TOKENS[rng.below(TOKENS.len())].as_bytes();
                v.splice(at..at, t.iter().copied());
            }
        }
    }
    v
}

/// A watchdog: if one case runs for more than 20 s (a hang, which the
/// per-case timing after the fact would never see), save its input and end
/// the process with a failure.
struct Watchdog {
    /// (when the current case started, its input, whether still watching)
    current: std::sync::Arc<std::sync::Mutex<(Instant, Vec<u8>, bool)>>,
}

impl Drop for Watchdog {
    fn drop(&mut self) {
        if let Ok(mut g) = self.current.lock() {
            g.2 = false;
        }
    }
}

impl Watchdog {
    fn start(kind: &'static str) -> Watchdog {
        let current =
            std::sync::Arc::new(std::sync::Mutex::new((Instant::now(), Vec::new(), true)));
        let watched = current.clone();
        std::thread::spawn(move || loop {
            std::thread::sleep(Duration::from_secs(1));
            let Ok(guard) = watched.lock() else {
                return;
            };
            if !guard.2 {
                return;
            }
            if guard.0.elapsed() > Duration::from_secs(20) {
                let msg = report(kind, 0, &guard.1, "hang (over 20 s on one input)");
                eprintln!("{msg}");
                std::process::exit(1);
            }
        });
        Watchdog { current }
    }

    fn case(&self, input: &[u8]) {
        if let Ok(mut g) = self.current.lock() {
            (g.0, g.1) = (Instant::now(), input.to_vec());
        }
    }
}

fn report(kind: &str, k: usize, input: &[u8], why: &str) -> String {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("..")
        .join("fuzz-findings");
    let _ = std::fs::create_dir_all(&dir);
    let file = dir.join(format!("{kind}-{k}.bin"));
    let _ = std::fs::write(&file, input);
    format!("{kind} case {k}: {why} (input saved to {})", file.display())
}

#[test]
#[ignore = "fuzzing campaign: run by hand with RAVEL_FUZZ_SECONDS"]
fn fuzz_front_end() {
    let mut seeds: Vec<Vec<u8>> = Vec::new();
    for dir in [
        "specs",
        "specs/invalid",
        "specs/network",
        "tests/corpus/specs",
    ] {
        for p in files(&root().join(dir), "ravel") {
            seeds.push(std::fs::read(&p).expect("seed"));
        }
    }
    let csv = std::fs::read(root().join("specs/network/lane_observations.csv")).expect("csv");
    let mut models: BTreeMap<String, Vec<u8>> = BTreeMap::new();
    for p in files(&root().join("models"), "onnx") {
        let name = p
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("")
            .to_string();
        models.insert(name, std::fs::read(&p).expect("model"));
    }
    let data =
        std::fs::read(root().join("models/double_integrator_external.onnx.data")).expect("data");
    // every controller path resolves, by file name, to a committed model
    let reader = |r: &ReadRequest| -> Result<Vec<u8>, ravel::ReadError> {
        let name = r.path.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if name.ends_with(".data") {
            return Ok(data.iter().copied().take(r.max_bytes as usize).collect());
        }
        if name.ends_with(".csv") {
            return Ok(csv.clone());
        }
        models
            .get(name)
            .or_else(|| models.get("double_integrator.onnx"))
            .cloned()
            .ok_or_else(|| ravel::ReadError::Io("no such model".to_string()))
    };
    let deadline = Instant::now() + budget();
    let watchdog = Watchdog::start("spec");
    let mut rng = Rng::new(0xF022);
    let mut findings = Vec::new();
    let mut cases = 0usize;
    let mut accepted = 0usize;
    while Instant::now() < deadline && findings.len() < 20 {
        let seed = &seeds[rng.below(seeds.len())];
        let input = mutate(&mut rng, &seeds, seed, true);
        let Ok(source) = String::from_utf8(input.clone()) else {
            continue;
        };
        cases += 1;
        watchdog.case(&input);
        let started = Instant::now();
        let r = catch_unwind(AssertUnwindSafe(|| {
            // the formatter: idempotent, and never a change of meaning
            match ravel_syntax::fmt::format(&source) {
                Ok(f) => assert_eq!(
                    ravel_syntax::fmt::format(&f).ok().as_deref(),
                    Some(f.as_str()),
                    "fmt is not idempotent"
                ),
                Err(ravel_syntax::fmt::Error::Changed) => panic!("fmt would change the meaning"),
                Err(ravel_syntax::fmt::Error::Syntax(_)) => {}
            }
            match ravel::front_end_task(&source, Path::new("specs"), &reader, None) {
                Ok(ravel::check::Task::System(c)) => {
                    let plan = ravel::lower::lower_system(&c);
                    assert!(plan.horizon >= 1);
                    true
                }
                Ok(ravel::check::Task::Network(c)) => {
                    let plan = ravel::lower::lower_network(&c);
                    assert_eq!(plan.net.inputs, c.input.1);
                    true
                }
                Err(d) => {
                    assert!(!d.is_empty(), "an error without a diagnostic");
                    for x in &d {
                        assert!(
                            !x.message.chars().any(|c| c.is_control() && c != '\n'),
                            "control character in {:?}",
                            x.message
                        );
                    }
                    // rendering must not panic either
                    let _ = ravel_syntax::diag::render(&d, "fuzz.ravel", &source, 100, false);
                    false
                }
            }
        }));
        match r {
            Ok(ok) => accepted += usize::from(ok),
            Err(_) => findings.push(report("spec", cases, &input, "panic")),
        }
        if started.elapsed() > Duration::from_secs(5) {
            findings.push(report("spec", cases, &input, "slow"));
        }
    }
    println!(
        "front end: {cases} cases, {accepted} accepted, {} findings",
        findings.len()
    );
    assert!(findings.is_empty(), "{}", findings.join("\n"));
}

#[test]
#[ignore = "fuzzing campaign: run by hand with RAVEL_FUZZ_SECONDS"]
fn fuzz_onnx_loader() {
    let mut seeds: Vec<Vec<u8>> = Vec::new();
    for dir in ["models", "models/invalid", "tests/corpus/onnx"] {
        for p in files(&root().join(dir), "onnx") {
            seeds.push(std::fs::read(&p).expect("seed"));
        }
    }
    let data =
        std::fs::read(root().join("models/double_integrator_external.onnx.data")).expect("data");
    let deadline = Instant::now() + budget();
    let watchdog = Watchdog::start("onnx");
    let mut rng = Rng::new(0x0DD5);
    let mut findings = Vec::new();
    let (mut cases, mut accepted) = (0usize, 0usize);
    while Instant::now() < deadline && findings.len() < 20 {
        let seed = &seeds[rng.below(seeds.len())];
        let input = mutate(&mut rng, &seeds, seed, false);
        cases += 1;
        watchdog.case(&input);
        let started = Instant::now();
        let r =
            catch_unwind(AssertUnwindSafe(|| {
                let mut ext = ExternalFiles::new();
                for req in ravel::onnx::external_requests(&input) {
                    assert!(req.bytes <= ravel_base::limits::MAX_CONTROLLER_BYTES);
                    assert!(ravel::onnx::normalise_location(&req.location).is_some());
                    ext.insert(
                        req.location,
                        Ok(data.iter().copied().take(req.bytes as usize).collect()),
                    );
                }
                match ravel::onnx::load(&input, &ext) {
                    Ok(c) => {
                        for l in &c.net.layers {
                            if let ravel_base::nn::Layer::Affine { w, b } = l {
                                assert!(w.nrows() as u64 <= ravel_base::limits::MAX_WIDTH);
                                assert!(w.iter().chain(b.iter()).all(|v| v.is_finite()
                                    && v.abs() <= ravel_base::limits::MAX_MAGNITUDE));
                            }
                        }
                        let y = c.net.forward(&vec![0.5; c.inputs]);
                        assert_eq!(y.len(), c.outputs);
                        true
                    }
                    Err(e) => {
                        assert!(!e.message.chars().any(char::is_control), "{:?}", e.message);
                        assert!(
                            e.message.chars().count() < 600,
                            "long message {:?}",
                            e.message
                        );
                        false
                    }
                }
            }));
        match r {
            Ok(ok) => accepted += usize::from(ok),
            Err(_) => findings.push(report("onnx", cases, &input, "panic")),
        }
        if started.elapsed() > Duration::from_secs(5) {
            findings.push(report("onnx", cases, &input, "slow"));
        }
    }
    println!(
        "onnx loader: {cases} cases, {accepted} accepted, {} findings",
        findings.len()
    );
    assert!(findings.is_empty(), "{}", findings.join("\n"));
}
