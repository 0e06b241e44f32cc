//! Repository hygiene: module docs, documented diagnostic codes and grammar
//! rules, and a README whose example output is what ravel prints.

use std::path::{Path, PathBuf};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).expect("readable dir") {
        let p = e.expect("entry").path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

#[test]
fn every_source_file_opens_with_a_module_comment() {
    let mut files = Vec::new();
    rust_files(&root().join("src"), &mut files);
    assert!(files.len() > 15);
    for f in files {
        let text = std::fs::read_to_string(&f).expect("readable");
        assert!(
            text.starts_with("//!"),
            "{} does not start with a `//!` module comment",
            f.display()
        );
    }
}

#[test]
fn every_diagnostic_code_is_documented_and_exemplified() {
    let docs = std::fs::read_to_string(root().join("docs/diagnostics.md")).expect("docs");
    let mut headers = String::new();
    for e in std::fs::read_dir(root().join("specs/invalid")).expect("dir") {
        let text = std::fs::read_to_string(e.expect("entry").path()).expect("spec");
        headers += text.lines().next().unwrap_or_default();
        headers += "\n";
    }
    for code in ravel::diag::Code::ALL {
        let c = code.as_str();
        assert!(
            docs.contains(&format!("## {c}:")),
            "{c} is not documented in docs/diagnostics.md"
        );
        assert!(
            headers.contains(c),
            "no spec under specs/invalid/ expects {c}"
        );
    }
}

#[test]
fn every_grammar_rule_is_documented() {
    let g = std::fs::read_to_string(root().join("grammar/ravel.pest")).expect("grammar");
    let lines: Vec<&str> = g.lines().collect();
    let mut rules = 0;
    for (i, line) in lines.iter().enumerate() {
        let is_rule = line.split_whitespace().nth(1) == Some("=") && !line.starts_with("//");
        if is_rule {
            rules += 1;
            assert!(
                i > 0 && lines[i - 1].starts_with("///"),
                "rule `{line}` has no `///` doc"
            );
        }
    }
    assert!(rules > 30);
}

#[test]
fn readme_example_output_is_what_ravel_prints() {
    let readme = std::fs::read_to_string(root().join("README.md")).expect("README");
    let cmd = "$ cargo run --release -- verify specs/double_integrator.ravel";
    let start = readme.find(cmd).expect("README shows the example run") + cmd.len();
    let block = &readme[start
        ..readme[start..]
            .find("```")
            .map(|e| start + e)
            .expect("block ends")];
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_ravel"))
        .args(["verify", "--no-timing", "specs/double_integrator.ravel"])
        .current_dir(root())
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(0));
    let printed = String::from_utf8_lossy(&out.stdout);
    let mut compared = 0;
    for line in block
        .lines()
        .filter(|l| !l.trim().is_empty() && l.trim() != "…")
    {
        assert!(
            printed.lines().any(|p| p == line),
            "README line not printed by ravel:\n{line}\n--- ravel printed:\n{printed}"
        );
        compared += 1;
    }
    assert!(compared > 10);
}

/// The certificate checker shares no analysis code: outside comments, its
/// files name only the network type, the rounding helpers, the limits and
/// the text sanitiser from the rest of the crate.
#[test]
fn the_checker_imports_no_analysis_code() {
    // `exact`: the exact sums of the property tests (test builds only)
    const ALLOWED: [&str; 5] = ["nn", "num", "limits", "diag", "exact"];
    let mut files = Vec::new();
    rust_files(&root().join("src/certify"), &mut files);
    assert!(files.len() >= 3);
    for f in files {
        let text = std::fs::read_to_string(&f).expect("readable");
        for line in text.lines() {
            let code = line.split("//").next().unwrap_or("");
            for (i, _) in code.match_indices("crate::") {
                let rest = &code[i + "crate::".len()..];
                let name: String = rest
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                assert!(
                    ALLOWED.contains(&name.as_str()),
                    "{} uses crate::{name}: the checker must stay independent of the analysis",
                    f.display()
                );
            }
            assert!(
                !code.contains("clarabel") && !code.contains("super::super"),
                "{}: {line}",
                f.display()
            );
        }
    }
}
