//! The malformed-input corpus (`tests/corpus/`, written by `ravel-corpus`):
//! every spec and every controller there must be refused by the `ravel`
//! binary with exit code 2 and the expected diagnostic codes, without a
//! panic, within a generous time limit and under a 4 GiB address-space limit
//! (so an unchecked size would abort instead of passing).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Run `ravel check FILE` with limits; (exit code, stderr).
fn check(file: &Path) -> (Option<i32>, String) {
    let script = format!(
        "ulimit -v 4194304 2>/dev/null; exec \"{}\" check \"$1\"",
        env!("CARGO_BIN_EXE_ravel")
    );
    // stderr goes to a file: a pipe that nobody reads while the child runs
    // would block a child that writes a long report
    let log = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!(
        "corpus-{}.stderr",
        file.file_name().and_then(|n| n.to_str()).unwrap_or("spec")
    ));
    let sink = std::fs::File::create(&log).expect("log file");
    let mut child = Command::new("sh")
        .args(["-c", &script, "sh"])
        .arg(file)
        .current_dir(root())
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(sink)
        .spawn()
        .expect("sh runs");
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        if let Some(_status) = child.try_wait().expect("wait") {
            break;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("{}: still running after 60 s", file.display());
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let status = child.wait().expect("exit status");
    let stderr = std::fs::read(&log).expect("log");
    (status.code(), String::from_utf8_lossy(&stderr).into_owned())
}

/// `Err(why)` unless `file` is refused with every expected code.
fn refused(file: &Path, expected: &[String]) -> Result<(), String> {
    let (code, stderr) = check(file);
    let f = file.display();
    if code != Some(2) {
        return Err(format!("{f}: exit {code:?}\n{stderr}"));
    }
    if stderr.contains("panicked") {
        return Err(format!("{f}: {stderr}"));
    }
    for e in expected.iter().filter(|e| *e != "any") {
        if !stderr.contains(e.as_str()) {
            return Err(format!("{f}: no {e} in\n{stderr}"));
        }
    }
    if !(stderr.contains("error(s)") || stderr.contains("error:")) {
        return Err(format!("{f}: no diagnostic\n{stderr}"));
    }
    if stderr.contains("\u{1b}[2J") || stderr.contains("\u{1b}[31m") {
        return Err(format!("{f}: raw escape sequences reach the terminal"));
    }
    Ok(())
}

#[test]
fn every_malformed_spec_is_refused() {
    let mut files: Vec<PathBuf> = std::fs::read_dir(root().join("tests/corpus/specs"))
        .expect("corpus")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "ravel"))
        .collect();
    files.sort();
    assert!(files.len() >= 100, "only {} specs", files.len());
    let mut failures = Vec::new();
    for f in &files {
        let text = std::fs::read(f).expect("spec");
        let text = String::from_utf8_lossy(&text);
        let header = text.lines().next().unwrap_or_default();
        let expected: Vec<String> = header
            .strip_prefix("// expect:")
            .unwrap_or_else(|| panic!("{}: no expect header", f.display()))
            .split_whitespace()
            .map(str::to_string)
            .collect();
        if let Err(e) = refused(f, &expected) {
            failures.push(e);
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

#[test]
fn every_malformed_controller_is_refused() {
    let dir = root().join("tests/corpus/onnx");
    let manifest = std::fs::read_to_string(dir.join("EXPECT")).expect("EXPECT");
    let tmp = Path::new(env!("CARGO_TARGET_TMPDIR")).join("corpus");
    std::fs::create_dir_all(&tmp).expect("temp");
    let mut n = 0;
    let mut failures = Vec::new();
    for line in manifest
        .lines()
        .filter(|l| !l.starts_with('#') && !l.is_empty())
    {
        let mut parts = line.split_whitespace();
        let (file, code) = (parts.next().expect("file"), parts.next().expect("code"));
        let onnx = dir.join(file);
        assert!(onnx.exists(), "{file} is listed but missing");
        let spec = tmp.join(format!("{file}.ravel"));
        std::fs::write(
            &spec,
            format!(
                r#"system s {{
    state x[2]
    control u[1]
    A = [[1, 1], [0, 1]]
    B = [[0.5], [1]]
    u in box([-1, 1])
}}
controller "{}"
initial X0 = box(x[0] in [2.5, 3.0], x[1] in [-0.25, 0.25])
goal G = box(x[0] in [-1.5, 2.0], x[1] in [-1.5, 0.5])
horizon 2
"#,
                onnx.display()
            ),
        )
        .expect("spec");
        if let Err(e) = refused(&spec, &[code.to_string()]) {
            failures.push(e);
        }
        n += 1;
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
    assert!(n >= 50, "only {n} controllers");
}
