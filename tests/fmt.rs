//! `ravel fmt`: on every spec that parses (valid and invalid ones), the
//! canonical layout keeps the meaning (the formatter itself refuses
//! otherwise), keeps every comment, and is idempotent; the command line
//! rewrites files in place and `--check` reports a diff with exit code 1.

use std::path::Path;

fn comments(src: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in src.lines() {
        if let Some(at) = line.find("//") {
            // not inside a string literal (the specs' strings hold no `//`)
            if line[..at].matches('"').count() % 2 == 0 {
                out.push(line[at..].trim_end().to_string());
            }
        }
    }
    out
}

fn specs() -> Vec<std::path::PathBuf> {
    let mut v = Vec::new();
    for dir in [
        "specs",
        "specs/invalid",
        "specs/network",
        "tests/corpus/specs",
    ] {
        for e in std::fs::read_dir(dir).expect("folder") {
            let p = e.expect("entry").path();
            if p.extension().is_some_and(|x| x == "ravel") {
                v.push(p);
            }
        }
    }
    v.sort();
    v
}

#[test]
fn formatting_keeps_meaning_and_comments_and_is_idempotent() {
    let mut formatted = 0;
    for path in specs() {
        let Ok(src) = std::fs::read_to_string(&path) else {
            continue; // the corpus holds files that are not UTF-8
        };
        if ravel_syntax::parse(&src).is_err() {
            assert!(matches!(
                ravel_syntax::fmt::format(&src),
                Err(ravel_syntax::fmt::Error::Syntax(_))
            ));
            continue;
        }
        let once = match ravel_syntax::fmt::format(&src) {
            Ok(t) => t,
            Err(e) => panic!("{}: {e:?}", path.display()),
        };
        let twice = ravel_syntax::fmt::format(&once).expect("formats again");
        assert_eq!(once, twice, "{}: not idempotent", path.display());
        assert_eq!(
            comments(&src),
            comments(&once),
            "{}: comments changed",
            path.display()
        );
        assert!(once.ends_with('\n') && !once.ends_with("\n\n"));
        formatted += 1;
    }
    assert!(formatted >= 60, "only {formatted} specs formatted");
}

#[test]
fn command_line_formats_in_place_and_checks() {
    let dir = std::env::temp_dir().join(format!("ravel-fmt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let file = dir.join("di.ravel");
    let src = std::fs::read_to_string("specs/double_integrator.ravel").expect("spec");
    std::fs::write(&file, &src).expect("write");
    let ravel = || std::process::Command::new(env!("CARGO_BIN_EXE_ravel"));
    let check = ravel()
        .args(["fmt", "--check"])
        .arg(&file)
        .output()
        .expect("runs");
    assert_eq!(check.status.code(), Some(1));
    let diff = String::from_utf8_lossy(&check.stdout);
    assert!(
        diff.contains("-    state   x[2]") && diff.contains("+    state x[2]"),
        "{diff}"
    );
    assert_eq!(
        std::fs::read_to_string(&file).expect("read"),
        src,
        "--check changed the file"
    );
    let run = ravel().arg("fmt").arg(&dir).output().expect("runs");
    assert_eq!(run.status.code(), Some(0));
    let after = std::fs::read_to_string(&file).expect("read");
    assert_ne!(after, src);
    let again = ravel()
        .args(["fmt", "--check"])
        .arg(&file)
        .output()
        .expect("runs");
    assert_eq!(
        again.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&again.stdout)
    );
    // the formatted spec verifies the same
    let v = ravel()
        .args([
            "verify",
            "--format",
            "json",
            "--controller",
            "models/double_integrator.onnx",
        ])
        .arg(&file)
        .output()
        .expect("runs");
    assert_eq!(v.status.code(), Some(0));
    // a spec that does not parse is left alone, exit 2
    let bad = dir.join("bad.ravel");
    std::fs::write(&bad, "system {").expect("write");
    let o = ravel().arg("fmt").arg(&bad).output().expect("runs");
    assert_eq!(o.status.code(), Some(2));
    assert_eq!(std::fs::read_to_string(&bad).expect("read"), "system {");
    let _ = std::fs::remove_dir_all(Path::new(&dir));
}
