//! Every documented example is true: the fenced blocks of README.md and
//! docs/*.md are run, the limits docs/diagnostics.md and docs/language.md
//! state are the code's, and the README's command-line synopsis lists what
//! `ravel --help` offers.
//!
//! # The convention for fenced blocks
//!
//! Every fenced block of README.md and docs/*.md names its kind in its info
//! string (a block without one fails this test), and each kind is run as
//! follows:
//!
//! * `ravel` — a whole spec whose first line is `// expect: VERDICT` (the
//!   verdict `ravel verify` gives) or `// expect: E0xxx …` (the diagnostic
//!   codes `ravel check` gives). Relative paths in it are read from
//!   `specs/`, or from the folder given as `ravel folder=DIR`.
//!   `ravel excerpt=FILE`: the block is a verbatim part of that shipped
//!   spec (whose own header is tested in tests/specs.rs).
//!   `ravel fragment`: a part of a spec, shown on its own; it must parse, and
//!   check with no diagnostics other than E0103 (the items it leaves out).
//! * `console` — a transcript: lines starting with `$ ` are commands, the
//!   lines after one are (part of) its output; each must be a line of what
//!   it prints (standard output, then standard error; trailing spaces
//!   ignored; a line `…` stands for lines left out). The command exits with
//!   0, or with N when the info string is `console exit=N`.
//! * `sh` — one command per line (a trailing `\` continues it; `#` starts a
//!   comment). A command whose program is `ravel` is run and must exit with
//!   0, or with N when its comment says `exit N`. Commands of other programs
//!   build, install or set up (`cargo`, `bash scripts/…`, `pip`, …: the list
//!   `SET_UP` below) and are not run; any other program fails the test, so
//!   that no command is skipped silently.
//! * `yaml` — a CI job: each step command (the value of `run:`, or a list
//!   item of `script:`) whose program is `ravel` is run and must exit with 0
//!   (a CI step passes only then); steps of the `SET_UP` programs are not run.
//! * `text`, `python`, `json`, `toml` — not run: schematic output, syntax
//!   summaries with placeholders (`NET.onnx`, `exported/`), commands that
//!   need files this repository does not ship, or code in another language.
//!   A command that could run belongs in `sh` or `console`.
//!
//! Commands run through `sh -c` with the built `ravel` first on `PATH`, in a
//! fresh folder per block that holds copies of `specs/`, `models/` and
//! `benchmarks/` and symbolic links to the repository's other top-level
//! entries (so `specs/…` and `models/…` resolve, and whatever the commands
//! write stays out of the repository); `cargo run --release --`
//! at the start of a `console` command stands for `ravel`. Run time: the
//! examples are the shipped specs' few-millisecond analyses; none is long.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Programs of `sh` and `yaml` commands that build, install or set up, and
/// are therefore not run here (the README's set-up commands are run by CI
/// itself).
const SET_UP: &[&str] = &[
    "cargo", "bash", "pip", "pip3", "python", "python3", "maturin", "gunzip", "npm", "npx", "code",
];

/// Kinds of blocks that are not run.
const NOT_RUN: &[&str] = &["text", "python", "json", "toml"];

/// One fenced block.
struct Block {
    /// `file:line` of its opening fence.
    at: String,
    /// The info string's words.
    info: Vec<String>,
    body: String,
}

impl Block {
    fn kind(&self) -> &str {
        self.info.first().map_or("", String::as_str)
    }

    /// The value of `key=VALUE` in the info string.
    fn attr(&self, key: &str) -> Option<&str> {
        self.info
            .iter()
            .find_map(|w| w.strip_prefix(key)?.strip_prefix('='))
    }
}

/// The documents whose examples are tested.
fn documents() -> Vec<PathBuf> {
    let mut files = vec![root().join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root().join("docs"))
        .expect("docs")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    docs.sort();
    files.extend(docs);
    files
}

fn blocks_of(path: &Path) -> Vec<Block> {
    let text = std::fs::read_to_string(path).expect("readable");
    let name = path
        .strip_prefix(root())
        .unwrap_or(path)
        .display()
        .to_string();
    let mut out = Vec::new();
    let mut open: Option<(usize, String, String)> = None;
    for (i, line) in text.lines().enumerate() {
        let t = line.trim_start();
        if let Some(rest) = t.strip_prefix("```") {
            match open.take() {
                Some((at, info, body)) => out.push(Block {
                    at: format!("{name}:{}", at + 1),
                    info: info.split_whitespace().map(str::to_string).collect(),
                    body,
                }),
                None => open = Some((i, rest.trim().to_string(), String::new())),
            }
        } else if let Some((_, _, body)) = open.as_mut() {
            body.push_str(line);
            body.push('\n');
        }
    }
    assert!(open.is_none(), "{name}: a fenced block is not closed");
    out
}

fn all_blocks() -> Vec<Block> {
    documents().iter().flat_map(|p| blocks_of(p)).collect()
}

/// Top-level folders copied into a block's folder (the rest are linked):
/// certificates record paths relative to themselves, which must not lead
/// through a link back into the repository.
const COPIED: &[&str] = &["specs", "models", "benchmarks"];

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("folder");
    for e in std::fs::read_dir(from).expect("folder") {
        let p = e.expect("entry").path();
        let dest = to.join(p.file_name().expect("name"));
        if p.is_dir() {
            copy_dir(&p, &dest);
        } else {
            std::fs::copy(&p, &dest).expect("copy");
        }
    }
}

/// A folder for one block's commands: copies of `COPIED`, symbolic links
/// to the repository's other top-level entries (not `target`, not `.git`).
fn sandbox(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("ravel-docs-{}-{tag}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp folder");
    for e in std::fs::read_dir(root()).expect("root") {
        let p = e.expect("entry").path();
        let name = p.file_name().expect("name").to_owned();
        if name == "target" || name == ".git" {
            continue;
        }
        if COPIED.iter().any(|c| name == *c) {
            copy_dir(&p, &dir.join(&name));
            continue;
        }
        #[cfg(unix)]
        std::os::unix::fs::symlink(&p, dir.join(&name)).expect("link");
    }
    dir
}

/// `command` through `sh -c` in `dir`, with the built ravel first on PATH:
/// (exit code, standard output then standard error).
fn run_sh(command: &str, dir: &Path) -> (Option<i32>, String) {
    let bin = Path::new(env!("CARGO_BIN_EXE_ravel"))
        .parent()
        .expect("bin folder")
        .to_path_buf();
    let path = std::env::var_os("PATH").unwrap_or_default();
    let mut paths = vec![bin];
    paths.extend(std::env::split_paths(&path));
    let out = Command::new("sh")
        .arg("-c")
        .arg(command)
        .current_dir(dir)
        .env("PATH", std::env::join_paths(paths).expect("PATH"))
        // a command that reads its standard input (a server) sees its end
        .stdin(std::process::Stdio::null())
        .output()
        .expect("sh runs");
    let mut text = String::from_utf8_lossy(&out.stdout).into_owned();
    text.push_str(&String::from_utf8_lossy(&out.stderr));
    (out.status.code(), text)
}

/// The first word of a command, after `VAR=value` assignments.
fn program(command: &str) -> &str {
    command
        .split_whitespace()
        .find(|w| !w.contains('='))
        .unwrap_or("")
}

/// The commands of an `sh` block: (command, comment), continuations joined.
fn sh_commands(body: &str) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut pending = String::new();
    for line in body.lines() {
        let (code, comment) = match line.find(" #").or_else(|| {
            line.trim_start()
                .starts_with('#')
                .then_some(line.len() - line.trim_start().len())
        }) {
            Some(at) => (
                &line[..at],
                line[at..].trim_start_matches([' ', '#']).trim(),
            ),
            None => (line, ""),
        };
        let code = code.trim_end();
        if let Some(cont) = code.strip_suffix('\\') {
            pending.push_str(cont.trim());
            pending.push(' ');
            continue;
        }
        pending.push_str(code.trim());
        let cmd = std::mem::take(&mut pending).trim().to_string();
        if !cmd.is_empty() {
            out.push((cmd, comment.to_string()));
        }
    }
    out
}

/// The step commands of a `yaml` block: values of `run:` and list items
/// under `script:`.
fn yaml_commands(body: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut in_script: Option<usize> = None;
    for line in body.lines() {
        let indent = line.len() - line.trim_start().len();
        let t = line.trim();
        if in_script.is_some_and(|i| indent <= i) {
            in_script = None;
        }
        let item = t.strip_prefix("- ").unwrap_or(t);
        if let Some(cmd) = item.strip_prefix("run:") {
            out.push(cmd.trim().to_string());
        } else if item == "script:" {
            in_script = Some(indent);
        } else if in_script.is_some() && t.starts_with("- ") {
            out.push(item.trim().to_string());
        }
    }
    out
}

fn expected_exit(comment: &str) -> i32 {
    comment
        .split_once("exit ")
        .and_then(|(_, n)| n.split(|c: char| !c.is_ascii_digit()).next()?.parse().ok())
        .unwrap_or(0)
}

/// A `ravel` block: a whole spec with its `// expect:` header, an excerpt
/// of a shipped spec, or a fragment.
fn spec_block(b: &Block) -> Result<(), String> {
    if let Some(file) = b.attr("excerpt") {
        let shipped = std::fs::read_to_string(root().join(file))
            .map_err(|e| format!("excerpt of `{file}`: {e}"))?;
        return if shipped.contains(&b.body) {
            Ok(())
        } else {
            Err(format!("not a verbatim part of {file}"))
        };
    }
    let folder = root().join(b.attr("folder").unwrap_or("specs"));
    let read = &ravel_cli::read_request;
    if b.info.iter().any(|w| w == "fragment") {
        ravel_syntax::parse(&b.body).map_err(|d| format!("does not parse: {d:?}"))?;
        return match ravel::front_end_task(&b.body, &folder, read, None) {
            Ok(_) => Ok(()),
            Err(d) => {
                let other: Vec<&str> = d
                    .iter()
                    .map(|d| d.code.as_str())
                    .filter(|c| *c != "E0103")
                    .collect();
                if other.is_empty() {
                    Ok(())
                } else {
                    Err(format!(
                        "a fragment must miss items only (E0103), but gives {other:?}: {d:#?}"
                    ))
                }
            }
        };
    }
    let first = b.body.lines().next().unwrap_or_default();
    let expect: Vec<&str> = first
        .strip_prefix("// expect:")
        .ok_or("a `ravel` block starts with `// expect: …` (or is an excerpt or fragment)")?
        .split_whitespace()
        .collect();
    if expect.first().is_some_and(|e| e.starts_with('E')) {
        let codes: BTreeSet<&str> = match ravel::front_end_task(&b.body, &folder, read, None) {
            Ok(_) => BTreeSet::new(),
            Err(d) => d.iter().map(|d| d.code.as_str()).collect(),
        };
        let want: BTreeSet<&str> = expect.iter().copied().collect();
        return if codes == want {
            Ok(())
        } else {
            Err(format!("diagnostics {codes:?}, expected {want:?}"))
        };
    }
    let run = ravel::verify(
        &b.body,
        &folder,
        read,
        None,
        &ravel::execute::Control::unlimited(),
    )
    .map_err(|d| format!("does not check: {d:#?}"))?;
    let got = run.verdict().as_str();
    if expect == [got] {
        Ok(())
    } else {
        Err(format!("verdict {got}, expected {expect:?}"))
    }
}

/// A `console` block: each `$ ` command's exit code and printed lines.
fn console_block(b: &Block, tag: &str) -> Result<(), String> {
    let want: i32 = b
        .attr("exit")
        .map_or(Ok(0), str::parse)
        .map_err(|e| format!("exit=: {e}"))?;
    let dir = sandbox(tag);
    let mut steps: Vec<(String, Vec<String>)> = Vec::new();
    for line in b.body.lines() {
        if let Some(cmd) = line.strip_prefix("$ ") {
            let cmd = match cmd.strip_prefix("cargo run --release -- ") {
                Some(args) => format!("ravel {args}"),
                None => cmd.to_string(),
            };
            if program(&cmd) != "ravel" {
                return Err(format!("`{cmd}`: a console command runs ravel"));
            }
            steps.push((cmd, Vec::new()));
        } else if let Some((_, out)) = steps.last_mut() {
            let l = line.trim_end();
            if !l.trim().is_empty() && l.trim() != "…" {
                out.push(l.to_string());
            }
        } else if !line.trim().is_empty() {
            return Err("a console block starts with a `$ ` command".into());
        }
    }
    if steps.is_empty() {
        return Err("a console block holds at least one `$ ` command".into());
    }
    let mut result = Ok(());
    for (cmd, lines) in &steps {
        let (code, printed) = run_sh(cmd, &dir);
        if code != Some(want) {
            result = Err(format!(
                "`{cmd}` exited with {code:?}, expected {want}:\n{printed}"
            ));
            break;
        }
        if let Some(l) = lines
            .iter()
            .find(|l| !printed.lines().any(|p| p.trim_end() == l.as_str()))
        {
            result = Err(format!(
                "`{cmd}` does not print the line\n{l}\n--- it printed:\n{printed}"
            ));
            break;
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    result
}

/// Commands of an `sh` or `yaml` block: the ravel ones run, the set-up
/// ones counted.
fn command_block(
    b: &Block,
    tag: &str,
    commands: Vec<(String, i32)>,
    skipped: &mut Vec<String>,
) -> Result<usize, String> {
    let mut to_run = Vec::new();
    for (cmd, want) in commands {
        let prog = program(&cmd);
        if prog == "ravel" {
            to_run.push((cmd, want));
        } else if SET_UP.contains(&prog) {
            skipped.push(format!("{}: {cmd}", b.at));
        } else if b.kind() == "sh" {
            return Err(format!(
                "`{cmd}`: program `{prog}` is neither ravel nor a set-up program (SET_UP in tests/docs.rs); mark the block `text` if it is not meant to run"
            ));
        }
    }
    if to_run.is_empty() {
        return Ok(0);
    }
    let dir = sandbox(tag);
    let mut result = Ok(to_run.len());
    for (cmd, want) in &to_run {
        let (code, printed) = run_sh(cmd, &dir);
        if code != Some(*want) {
            result = Err(format!(
                "`{cmd}` exited with {code:?}, expected {want}:\n{printed}"
            ));
            break;
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    result
}

#[test]
fn every_documented_example_is_true() {
    let blocks = all_blocks();
    assert!(blocks.len() >= 20, "only {} blocks found", blocks.len());
    let mut failures = Vec::new();
    let mut skipped = Vec::new();
    let (mut specs, mut transcripts, mut commands) = (0, 0, 0);
    for (i, b) in blocks.iter().enumerate() {
        let tag = i.to_string();
        let outcome = match b.kind() {
            "ravel" => spec_block(b).map(|()| specs += 1),
            "console" => console_block(b, &tag).map(|()| transcripts += 1),
            "sh" => {
                let cmds = sh_commands(&b.body)
                    .into_iter()
                    .map(|(c, comment)| (c, expected_exit(&comment)))
                    .collect();
                command_block(b, &tag, cmds, &mut skipped).map(|n| commands += n)
            }
            // run by `the_ci_jobs_pass_on_this_repository`, each distinct
            // step once; here their programs are checked
            "yaml" => yaml_commands(&b.body)
                .iter()
                .map(|c| program(c))
                .filter(|p| *p != "ravel")
                .try_for_each(|p| {
                    if SET_UP.contains(&p) {
                        Ok(())
                    } else {
                        Err(format!(
                            "a CI step runs `{p}`, neither ravel nor a set-up program"
                        ))
                    }
                }),
            k if NOT_RUN.contains(&k) => Ok(()),
            "" => Err(
                "a fenced block without a kind: see the convention at the top of tests/docs.rs"
                    .into(),
            ),
            k => Err(format!(
                "unknown kind `{k}`: see the convention at the top of tests/docs.rs"
            )),
        };
        if let Err(e) = outcome {
            failures.push(format!("{}: {e}", b.at));
        }
    }
    eprintln!("not run (set-up programs):");
    for s in &skipped {
        eprintln!("  {s}");
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
    // the README's spec, its two transcripts, the certificate commands, the
    // CI jobs' steps at least
    assert!(specs >= 4, "only {specs} spec blocks ran");
    assert!(transcripts >= 3, "only {transcripts} transcripts ran");
    assert!(commands >= 2, "only {commands} commands ran");
}

/// The convention's parts see what they should (so the test above cannot
/// pass by running nothing).
#[test]
fn the_block_reader_finds_commands_and_kinds() {
    let cmds = sh_commands(
        "ravel verify a.ravel \\\n    --format junit   # exit 3\n# a comment\ncargo build\n",
    );
    assert_eq!(
        cmds,
        [
            (
                "ravel verify a.ravel --format junit".to_string(),
                "exit 3".to_string()
            ),
            ("cargo build".to_string(), String::new())
        ]
    );
    assert_eq!(expected_exit("exit 3"), 3);
    assert_eq!(expected_exit("verifies it"), 0);
    let y = yaml_commands(
        "verify:\n  steps:\n    - uses: actions/checkout@v4\n    - run: ravel verify x/ > r.xml\nlint:\n  script:\n    - cargo install --path .\n    - ravel check x/\n  artifacts:\n    when: always\n",
    );
    assert_eq!(
        y,
        [
            "ravel verify x/ > r.xml",
            "cargo install --path .",
            "ravel check x/"
        ]
    );
    assert_eq!(program("RUST_LOG=1 ravel verify"), "ravel");
    // a wrong verdict and a wrong transcript line are caught
    let spec = std::fs::read_to_string(root().join("specs/double_integrator.ravel")).expect("spec");
    let wrong = Block {
        at: "test".into(),
        info: vec!["ravel".into()],
        body: spec.replacen("// expect: VERIFIED", "// expect: UNSURE", 1),
    };
    assert!(spec_block(&wrong).is_err());
    let right = Block {
        at: "test".into(),
        info: vec!["ravel".into()],
        body: spec,
    };
    assert_eq!(spec_block(&right), Ok(()));
    let transcript = Block {
        at: "test".into(),
        info: vec!["console".into()],
        body: "$ ravel check specs/double_integrator.ravel\nok: specs/double_integrator.ravel\n"
            .into(),
    };
    assert_eq!(console_block(&transcript, "selftest-a"), Ok(()));
    let lying = Block {
        body: transcript.body.replace("ok:", "fine:"),
        ..transcript
    };
    assert!(console_block(&lying, "selftest-b").is_err());
}

/// The CI jobs of the README (and of any document) run on this repository
/// as they are written there, and pass: every `ravel` step of a `yaml`
/// block exits with 0 (each distinct step once), and the README's jobs
/// include a `ravel verify … --format junit` whose report has no failure.
#[test]
fn the_ci_jobs_pass_on_this_repository() {
    let mut steps: Vec<String> = Vec::new();
    let mut junit = false;
    for path in documents() {
        for b in blocks_of(&path).iter().filter(|b| b.kind() == "yaml") {
            for c in yaml_commands(&b.body) {
                if program(&c) == "ravel" && !steps.contains(&c) {
                    junit |= path.ends_with("README.md")
                        && c.starts_with("ravel verify")
                        && c.contains("--format junit > ravel-junit.xml");
                    steps.push(c);
                }
            }
        }
    }
    assert!(
        junit,
        "the README's CI job is a `ravel verify … --format junit`: {steps:?}"
    );
    for step in &steps {
        let dir = sandbox("ci");
        let (code, printed) = run_sh(step, &dir);
        assert_eq!(code, Some(0), "`{step}`:\n{printed}");
        if step.contains("> ravel-junit.xml") {
            let xml = std::fs::read_to_string(dir.join("ravel-junit.xml")).expect("the report");
            assert!(xml.contains("<testsuites"), "{xml}");
            assert!(
                !xml.contains("<failure") && !xml.contains("<error"),
                "{xml}"
            );
            // the job gates more than a spec or two
            assert!(xml.matches("<testsuite ").count() >= 20, "{xml}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}

// ---------------------------------------------------------------------------
// Limits: docs/diagnostics.md and docs/language.md against limits.rs

use ravel_base::limits as l;

/// A number as the docs write it.
fn int(n: impl Into<u64>) -> String {
    n.into().to_string()
}

/// The limits each diagnostic's documentation states, as written, from the
/// constants that the checks use.
fn documented_limits() -> Vec<(&'static str, Vec<String>)> {
    let mag = format!("{:e}", l::MAX_MAGNITUDE);
    let mib = |b: u64| format!("{} MiB", b >> 20);
    vec![
        ("E0204", vec![int(l::MAX_HORIZON)]),
        ("E0207", vec![int(l::MAX_CELLS)]),
        ("E0211", vec![int(l::MAX_BOUNDARY_DIRECTIONS as u64)]),
        ("E0214", vec![int(l::MAX_CALLS)]),
        (
            "E0216",
            vec![
                mag.clone(),
                int(l::MAX_DIM),
                int(l::MAX_SAMPLES),
                int(l::MAX_CELLS),
                int(l::MAX_SIMULATED_STEPS),
                int(l::MAX_STORED_NUMBERS),
                int(l::MAX_SDP_DIM),
                int(l::MAX_UNROLLED_NEURON_STEPS),
                int(l::MAX_SPEC_NUMBERS),
                int(l::MAX_PLANT_NUMBERS),
                int(l::MAX_POLYTOPE_ROWS as u64),
                int(l::MAX_POLYTOPE_DIM as u64),
                int(l::MAX_EXPR_NODES as u64),
                // an editor document larger than a spec file (ravel lsp)
                mib(l::MAX_SPEC_BYTES),
            ],
        ),
        ("E0218", vec![format!("{:e}", l::MAX_RADIUS_SCALE)]),
        (
            "E0219",
            vec![
                format!("±{mag}"),
                int(ravel::check::MAX_OBSERVATIONS as u64),
            ],
        ),
        (
            "E0225",
            vec![format!(
                "10{}",
                superscript(l::MAX_CORNER_EVALUATIONS.ilog10() as i32)
            )],
        ),
        ("E0301", vec![mib(l::MAX_CONTROLLER_BYTES)]),
        (
            "E0303",
            vec![
                int(l::MAX_WIDTH),
                int(l::MAX_NODES as u64),
                int(l::MAX_PARAMETERS),
                int(l::MAX_LAYER_ENTRIES),
            ],
        ),
        ("E0306", vec![format!("±{mag}")]),
        ("E0307", vec![int(l::MAX_TENSOR_ELEMENTS)]),
        ("E0308", vec![mib(l::MAX_CONTROLLER_BYTES)]),
        (
            "E0401",
            vec![
                int(ravel::vnnlib::MAX_MEMBERS as u64),
                // a property file, plain or decompressed
                mib(l::MAX_SPEC_BYTES),
            ],
        ),
    ]
}

/// An exponent as the docs write it: `⁷`, `⁻⁹`.
fn superscript(n: i32) -> String {
    n.to_string()
        .chars()
        .map(|c| match c {
            '-' => '⁻',
            d => "⁰¹²³⁴⁵⁶⁷⁸⁹"
                .chars()
                .nth(d as usize - '0' as usize)
                .expect("digit"),
        })
        .collect()
}

/// Numbers a diagnostic's text states that are not limits of ravel's
/// (the `f64` range, the `i32` range of exponents), with where they come
/// from.
fn not_limits() -> Vec<(&'static str, String)> {
    vec![
        ("E0205", format!("±{:.1e}", f64::MAX)),
        ("E0223", format!("±{}", i32::MAX)),
        (
            "E0229",
            format!(
                "10{}",
                superscript(ravel::check::TIME_TOLERANCE.log10().round() as i32)
            ),
        ),
    ]
}

/// The number tokens of a text (integers of three digits or more, numbers
/// with an exponent, `10⁷`-style powers, `N MiB`), with a leading `±`.
fn big_numbers(text: &str) -> Vec<String> {
    let chars: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let starts = chars[i].is_ascii_digit()
            && (i == 0 || !(chars[i - 1].is_alphanumeric() || chars[i - 1] == '.'));
        if !starts {
            i += 1;
            continue;
        }
        let sign = i > 0 && chars[i - 1] == '±';
        let mut j = i;
        while j < chars.len()
            && (chars[j].is_ascii_digit()
                || "⁰¹²³⁴⁵⁶⁷⁸⁹⁻".contains(chars[j])
                || (chars[j] == '.' && chars.get(j + 1).is_some_and(char::is_ascii_digit))
                || (chars[j] == 'e'
                    && chars
                        .get(j + 1)
                        .is_some_and(|c| c.is_ascii_digit() || *c == '-')))
        {
            j += 1;
        }
        let mut tok: String = chars[i..j].iter().collect();
        if chars[j..].iter().collect::<String>().starts_with(" MiB") {
            tok.push_str(" MiB");
        }
        let digits = tok.chars().filter(char::is_ascii_digit).count();
        let big = tok.contains('e')
            || tok.contains("MiB")
            || tok.chars().any(|c| "⁰¹²³⁴⁵⁶⁷⁸⁹".contains(c))
            || (!tok.contains('.') && digits >= 3);
        if big {
            out.push(if sign { format!("±{tok}") } else { tok });
        }
        i = j.max(i + 1);
    }
    out
}

/// The text of a Markdown paragraph with its `code spans` taken out.
fn prose(text: &str) -> String {
    let mut out = String::new();
    for (k, part) in text.split('`').enumerate() {
        if k % 2 == 0 {
            out.push_str(part);
        }
        out.push(' ');
    }
    out
}

/// docs/diagnostics.md's sections: code → the text of "What it means" and
/// "How to fix it" (the examples left out: they show bad input).
fn diagnostic_sections() -> Vec<(String, String)> {
    let docs = std::fs::read_to_string(root().join("docs/diagnostics.md")).expect("docs");
    let mut out: Vec<(String, String)> = Vec::new();
    for line in docs.lines() {
        if let Some(h) = line.strip_prefix("## ") {
            let code = h.split(':').next().unwrap_or_default().to_string();
            out.push((code, String::new()));
        } else if let Some((_, text)) = out.last_mut() {
            if !line.starts_with("**Example.**") {
                text.push_str(line);
                text.push('\n');
            }
        }
    }
    out
}

#[test]
fn every_code_is_documented_and_every_documented_code_exists() {
    let documented: BTreeSet<String> = diagnostic_sections().into_iter().map(|(c, _)| c).collect();
    let codes: BTreeSet<String> = ravel_syntax::diag::Code::ALL
        .iter()
        .map(|c| c.as_str().to_string())
        .collect();
    assert_eq!(
        documented, codes,
        "docs/diagnostics.md's sections vs diag::Code::ALL"
    );
    assert_eq!(
        codes.len(),
        ravel_syntax::diag::Code::ALL.len(),
        "a code twice"
    );
}

#[test]
fn the_limits_the_diagnostics_state_are_the_code_s() {
    let limits = documented_limits();
    let others = not_limits();
    let sections = diagnostic_sections();
    let mut problems = Vec::new();
    for (code, text) in &sections {
        let found = big_numbers(&prose(text));
        let stated: Vec<&String> = limits
            .iter()
            .filter(|(c, _)| c == code)
            .flat_map(|(_, v)| v)
            .chain(others.iter().filter(|(c, _)| c == code).map(|(_, v)| v))
            .collect();
        for n in &found {
            if !stated.contains(&n) {
                problems.push(format!(
                    "{code}: states {n}, which is no limit of the code's for it"
                ));
            }
        }
        for s in &stated {
            if !found.contains(s) {
                problems.push(format!("{code}: does not state the limit {s}"));
            }
        }
    }
    for (code, _) in &limits {
        assert!(
            sections.iter().any(|(c, _)| c == code),
            "{code} has no section"
        );
    }
    // limits of two digits, which the scan leaves to their phrases
    let e0216 = &sections
        .iter()
        .find(|(c, _)| c == "E0216")
        .expect("E0216")
        .1;
    for phrase in [
        format!("brackets nested more than {} deep", l::MAX_NESTING),
        format!(
            "an expression tree more than {} levels deep",
            l::MAX_EXPR_DEPTH
        ),
    ] {
        if !e0216.contains(&phrase) {
            problems.push(format!("E0216: does not say \"{phrase}\""));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
    // the scanner sees what it must
    assert_eq!(
        big_numbers("above 10000, ±1e15, 512 MiB, 10⁷ and 10⁻⁹, not 0.25 or 64"),
        ["10000", "±1e15", "512 MiB", "10⁷", "10⁻⁹"]
    );
}

#[test]
fn the_limits_table_of_the_language_is_the_code_s() {
    let lang = std::fs::read_to_string(root().join("docs/language.md")).expect("docs");
    let start = lang.find("## Limits").expect("a Limits section");
    let section = &lang[start..];
    let section = &section[..section[3..].find("\n## ").map_or(section.len(), |e| e + 3)];
    // each row by the start of its first cell, with the constants it states
    let mag = format!("{:e}", l::MAX_MAGNITUDE);
    let mib = |b: u64| format!("{} MiB", b >> 20);
    let rows: Vec<(&str, Vec<String>)> = vec![
        ("any number", vec![mag]),
        ("state, control", vec![int(l::MAX_DIM)]),
        ("horizon", vec![int(l::MAX_HORIZON)]),
        ("Monte Carlo samples", vec![int(l::MAX_SAMPLES)]),
        ("`optimise_slopes`", vec![int(l::MAX_SLOPE_STEPS)]),
        ("samples × horizon", vec![int(l::MAX_SIMULATED_STEPS)]),
        ("cells of a uniform grid", {
            assert_eq!(l::MAX_CELLS, l::MAX_CALLS, "one row states both");
            vec![int(l::MAX_CELLS)]
        }),
        ("cells (or calls)", vec![int(l::MAX_STORED_NUMBERS)]),
        ("spec file", vec![mib(l::MAX_SPEC_BYTES)]),
        ("controller file", vec![mib(l::MAX_CONTROLLER_BYTES)]),
        ("elements of one tensor", {
            assert_eq!(
                l::MAX_TENSOR_ELEMENTS,
                l::MAX_PARAMETERS,
                "one row states both"
            );
            vec![int(l::MAX_TENSOR_ELEMENTS)]
        }),
        ("width of a layer", vec![int(l::MAX_WIDTH)]),
        ("nodes of the ONNX graph", vec![int(l::MAX_NODES as u64)]),
        ("numbers in the spec", vec![int(l::MAX_SPEC_NUMBERS)]),
        ("steps × n", vec![int(l::MAX_PLANT_NUMBERS)]),
        (
            "inequalities of one polytope",
            vec![int(l::MAX_POLYTOPE_ROWS as u64)],
        ),
        (
            "dimension of a polytope",
            vec![int(l::MAX_POLYTOPE_DIM as u64)],
        ),
        ("Reach-SDP program", vec![int(l::MAX_SDP_DIM)]),
        ("unrolled CROWN", vec![int(l::MAX_UNROLLED_NEURON_STEPS)]),
        ("nesting of brackets", vec![int(l::MAX_NESTING as u64)]),
        (
            "depth of an expression",
            vec![int(l::MAX_EXPR_DEPTH as u64)],
        ),
        ("expression nodes", vec![int(l::MAX_EXPR_NODES as u64)]),
    ];
    let table: Vec<&str> = section
        .lines()
        .filter(|r| r.starts_with("| ") && !r.starts_with("| what") && !r.starts_with("|---"))
        .collect();
    assert_eq!(
        table.len(),
        rows.len(),
        "rows of the table vs rows tested:\n{}",
        table.join("\n")
    );
    for (prefix, values) in &rows {
        let row = table
            .iter()
            .find(|r| r[2..].starts_with(prefix))
            .unwrap_or_else(|| panic!("no row `{prefix}…` in docs/language.md's Limits"));
        let limit = row.rsplit('|').nth(1).expect("a limit cell");
        let stated: Vec<String> = limit
            .split('≤')
            .nth(1)
            .map(|v| v.trim().trim_end_matches(" each").to_string())
            .into_iter()
            .collect();
        assert_eq!(&stated, values, "{row}");
    }
    // and the horizon's own section
    assert!(
        lang.contains(&format!("1 ≤ N ≤ {} (see [Limits]", l::MAX_HORIZON)),
        "the horizon's section states another limit"
    );
}

/// The documented limits are where the checks draw the line: the value
/// itself is accepted, one more gets the documented code.
#[test]
fn the_documented_limits_are_where_check_refuses() {
    let base = std::fs::read_to_string(root().join("specs/double_integrator.ravel")).expect("spec");
    let folder = root().join("specs");
    let codes = |src: &str| -> BTreeSet<String> {
        match ravel::front_end_task(src, &folder, &ravel_cli::read_request, None) {
            Ok(_) => BTreeSet::new(),
            Err(d) => d.iter().map(|d| d.code.as_str().to_string()).collect(),
        }
    };
    let with = |from: &str, to: &str| {
        assert!(base.contains(from), "{from}");
        base.replacen(from, to, 1)
    };
    let h = l::MAX_HORIZON;
    // samples × horizon must stay within its own limit here
    let few = "samples     2000";
    assert!(
        codes(&with("horizon 5", &format!("horizon {h}")).replace(few, "samples 10")).is_empty()
    );
    assert_eq!(
        codes(&with("horizon 5", &format!("horizon {}", h + 1)).replace(few, "samples 10")),
        BTreeSet::from(["E0204".to_string()])
    );
    let calls = l::MAX_CALLS;
    let gsg = |n: u64| with("partitioner none", &format!("partitioner gsg (calls {n})"));
    assert!(codes(&gsg(calls)).is_empty());
    assert_eq!(
        codes(&gsg(calls + 1)),
        BTreeSet::from(["E0214".to_string()])
    );
    // a grid of MAX_CELLS cells, and one of more (E0216, as E0207 says)
    let cells = l::MAX_CELLS;
    let grid = |a: u64, b: u64| {
        with(
            "partitioner none",
            &format!("partitioner uniform [{a}, {b}]"),
        )
    };
    assert!(codes(&grid(cells / 100, 100)).is_empty());
    assert_eq!(
        codes(&grid(cells / 100 + 1, 100)),
        BTreeSet::from(["E0216".to_string()])
    );
}

// ---------------------------------------------------------------------------
// The README's synopsis against the command line's help

/// `ravel ARGS` as text.
fn help(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_ravel"))
        .args(args)
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(0), "{args:?}");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The README's synopsis: the first block after `## Command line`.
fn synopsis() -> String {
    let readme = std::fs::read_to_string(root().join("README.md")).expect("README");
    let start = readme
        .find("## Command line")
        .expect("a Command line section");
    let b = blocks_of_text(&readme[start..]);
    b.into_iter().next().expect("a synopsis block")
}

fn blocks_of_text(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut open: Option<String> = None;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            match open.take() {
                Some(b) => out.push(b),
                None => open = Some(String::new()),
            }
        } else if let Some(b) = open.as_mut() {
            b.push_str(line);
            b.push('\n');
        }
    }
    out
}

/// The synopsis's lines about `ravel SUB` (every entry that starts with it,
/// up to the next `ravel …` entry).
fn entries(synopsis: &str, sub: &str) -> String {
    let mut out = String::new();
    let mut inside = false;
    for line in synopsis.lines() {
        if line.starts_with("ravel ") {
            inside = line.split_whitespace().nth(1) == Some(sub);
        }
        if inside {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

/// A word of `text` standing alone (not part of a longer word or flag).
fn has_word(text: &str, word: &str) -> bool {
    text.match_indices(word).any(|(at, _)| {
        let before = text[..at].chars().next_back();
        let after = text[at + word.len()..].chars().next();
        let part = |c: Option<char>| c.is_some_and(|c| c.is_alphanumeric() || c == '-' || c == '_');
        !part(before) && !part(after)
    })
}

#[test]
fn the_readme_synopsis_lists_every_subcommand_flag_and_value() {
    let syn = synopsis();
    let top = help(&["--help"]);
    let commands: Vec<String> = top
        .split("Commands:")
        .nth(1)
        .expect("a command list")
        .split("Options:")
        .next()
        .expect("commands")
        .lines()
        .filter_map(|l| {
            let l = l.strip_prefix("  ")?;
            (!l.starts_with(' ')).then(|| l.split_whitespace().next().map(str::to_string))?
        })
        .filter(|c| c != "help")
        .collect();
    assert!(commands.len() >= 7, "{commands:?}");
    let mut missing = Vec::new();
    for sub in &commands {
        let text = entries(&syn, sub);
        if text.is_empty() {
            missing.push(format!("`ravel {sub}`"));
            continue;
        }
        let long = help(&[sub, "--help"]);
        let mut values_of: Option<String> = None;
        for line in long.lines() {
            let t = line.trim_start();
            if t.starts_with("--") || t.starts_with("-h, --help") {
                let flag = t
                    .trim_start_matches("-h, ")
                    .split(|c: char| c.is_whitespace() || c == '<')
                    .next()
                    .unwrap_or_default();
                values_of = Some(flag.to_string());
                if flag != "--help" && !has_word(&text, flag) {
                    missing.push(format!("`ravel {sub} {flag}`"));
                }
            } else if let (Some(flag), Some(v)) = (&values_of, t.strip_prefix("- ")) {
                let value = v.split(':').next().unwrap_or_default();
                let listed = text
                    .lines()
                    .any(|l| l.contains(flag.as_str()) && has_word(l, value))
                    || text.contains(&format!("{flag} {value}"));
                if !listed {
                    missing.push(format!("`ravel {sub} {flag} {value}`"));
                }
            }
        }
    }
    assert!(
        missing.is_empty(),
        "the README's synopsis (## Command line) lacks {}",
        missing.join(", ")
    );
    // the comparison sees a missing value and a missing flag
    assert!(!has_word("[--format text|json]", "jsonl"));
    assert!(has_word("[--format text|json|jsonl]", "json"));
    assert!(!has_word("--fail-on-x", "--fail-on"));
}

// ---------------------------------------------------------------------------
// The README's table of shipped specs

/// The spec files a table cell names: `a.ravel`, `…_b.ravel` (the
/// previous name's stem up to an `_` that makes it a file), `x_{a, b}.ravel`.
fn named_specs(cell: &str) -> Vec<String> {
    let names: Vec<&str> = cell
        .split('`')
        .enumerate()
        .filter(|(k, _)| k % 2 == 1)
        .map(|(_, n)| n)
        .collect();
    let mut out: Vec<String> = Vec::new();
    for name in names {
        if let (Some(open), Some(close)) = (name.find('{'), name.find('}')) {
            for part in name[open + 1..close].split(',') {
                out.push(format!(
                    "{}{}{}",
                    &name[..open],
                    part.trim(),
                    &name[close + 1..]
                ));
            }
        } else if let Some(rest) = name.strip_prefix('…') {
            let first = out.last().cloned().unwrap_or_default();
            let stem = first
                .match_indices('_')
                .map(|(at, _)| format!("{}{rest}", &first[..at]))
                .find(|c| root().join("specs").join(c).is_file())
                .unwrap_or_else(|| format!("?{rest}"));
            out.push(stem);
        } else {
            out.push(name.to_string());
        }
    }
    out
}

#[test]
fn the_readme_s_table_of_specs_gives_their_verdicts() {
    let readme = std::fs::read_to_string(root().join("README.md")).expect("README");
    let start = readme
        .find("| spec | shows | verdict |")
        .expect("the table");
    let mut rows = 0;
    for row in readme[start..]
        .lines()
        .skip(2)
        .take_while(|l| l.starts_with('|'))
    {
        let cells: Vec<&str> = row.split(" | ").collect();
        let (first, verdict) = (
            cells[0].trim_start_matches("| "),
            cells[cells.len() - 1].trim_end_matches(" |"),
        );
        if first == "`invalid/*.ravel`" {
            let n = std::fs::read_dir(root().join("specs/invalid"))
                .expect("folder")
                .filter(|e| {
                    e.as_ref()
                        .expect("entry")
                        .path()
                        .extension()
                        .is_some_and(|x| x == "ravel")
                })
                .count();
            assert!(
                row.contains(&format!("({n} files)")),
                "{row}: there are {n}"
            );
            assert_eq!(verdict, "exit code 2");
            continue;
        }
        for name in named_specs(first) {
            let text = std::fs::read_to_string(root().join("specs").join(&name))
                .unwrap_or_else(|e| panic!("{row}: specs/{name}: {e}"));
            assert_eq!(
                text.lines().next(),
                Some(format!("// expect: {verdict}").as_str()),
                "{row}: specs/{name}"
            );
            rows += 1;
        }
    }
    assert!(rows >= 30, "only {rows} specs named");
    assert_eq!(
        named_specs("`quadrotor_{unrolled, gsg}.ravel`, `double_integrator_sdp.ravel`, `…_sdp_partitioned.ravel`"),
        [
            "quadrotor_unrolled.ravel",
            "quadrotor_gsg.ravel",
            "double_integrator_sdp.ravel",
            "double_integrator_sdp_partitioned.ravel"
        ]
    );
}

// ---------------------------------------------------------------------------
// docs/json-schema.md's examples name fields the reports have

/// Every object key anywhere in `v`.
fn keys(v: &serde_json::Value, out: &mut BTreeSet<String>) {
    match v {
        serde_json::Value::Object(m) => {
            for (k, x) in m {
                out.insert(k.clone());
                keys(x, out);
            }
        }
        serde_json::Value::Array(a) => a.iter().for_each(|x| keys(x, out)),
        _ => {}
    }
}

/// The `"key":` names of a schematic JSON block.
fn documented_keys(body: &str) -> Vec<String> {
    let mut out = Vec::new();
    for (k, part) in body.split('"').enumerate() {
        if k % 2 == 1 {
            let after = body.split('"').nth(k + 1).unwrap_or_default();
            if after.trim_start().starts_with(':') {
                out.push(part.to_string());
            }
        }
    }
    out
}

#[test]
fn the_json_schema_examples_name_real_fields() {
    // a closed loop, a network spec with a radius search, one with
    // selections, and a spec with errors
    let out = Command::new(env!("CARGO_BIN_EXE_ravel"))
        .args([
            "verify",
            "--format",
            "json",
            "specs/double_integrator.ravel",
            "specs/network/classifier_robust.ravel",
            "specs/network/lane_carrl.ravel",
            "specs/invalid/wrong_shape.ravel",
        ])
        .current_dir(root())
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let mut real = BTreeSet::new();
    keys(&doc, &mut real);
    let mut shown = 0;
    for b in blocks_of(&root().join("docs/json-schema.md"))
        .iter()
        .filter(|b| b.kind() == "json")
    {
        for k in documented_keys(&b.body) {
            assert!(real.contains(&k), "{}: `{k}` is in no report", b.at);
            shown += 1;
        }
    }
    assert!(shown >= 50, "only {shown} fields shown");
    assert_eq!(
        documented_keys(r#"{ "a": 1, "b": "c", "d" : [] }"#),
        ["a", "b", "d"]
    );
}

/// Every spec docs/diagnostics.md names for a code exists and expects that
/// code (its `// expect:` header, which tests/specs.rs holds it to).
#[test]
fn the_diagnostics_examples_name_specs_that_give_them() {
    let docs = std::fs::read_to_string(root().join("docs/diagnostics.md")).expect("docs");
    let mut code = String::new();
    let mut named = 0;
    for line in docs.lines() {
        if let Some(h) = line.strip_prefix("## ") {
            code = h.split(':').next().unwrap_or_default().to_string();
            continue;
        }
        for (k, span) in line.split('`').enumerate() {
            if k % 2 == 0 || !span.starts_with("specs/invalid/") || !span.ends_with(".ravel") {
                continue;
            }
            let text = std::fs::read_to_string(root().join(span))
                .unwrap_or_else(|e| panic!("{code}: `{span}`: {e}"));
            let header = text.lines().next().unwrap_or_default();
            assert!(
                header.starts_with("// expect:") && header.split_whitespace().any(|w| w == code),
                "{code} names `{span}`, whose header is `{header}`"
            );
            named += 1;
        }
    }
    assert!(named >= 45, "only {named} specs named");
}
