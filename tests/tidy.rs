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
    rust_files(&root().join("crates"), &mut files);
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
    // the command line's own codes (E04xx: VNN-LIB properties, instance
    // lists, output formats) concern other files than specs, or a spec
    // with a request: their tests name them
    let mut cli_tests = String::new();
    for f in ["tests/vnnlib.rs", "tests/vnncomp.rs", "tests/cli.rs"] {
        cli_tests += &std::fs::read_to_string(root().join(f)).unwrap_or_default();
    }
    for code in ravel_syntax::diag::Code::ALL {
        let c = code.as_str();
        assert!(
            docs.contains(&format!("## {c}:")),
            "{c} is not documented in docs/diagnostics.md"
        );
        if c.starts_with("E04") {
            assert!(
                cli_tests.contains(c),
                "no test of tests/vnnlib.rs, tests/vnncomp.rs or tests/cli.rs expects {c}"
            );
        } else {
            assert!(
                headers.contains(c),
                "no spec under specs/invalid/ expects {c}"
            );
        }
    }
}

#[test]
fn every_grammar_rule_is_documented() {
    let g =
        std::fs::read_to_string(root().join("crates/syntax/grammar/ravel.pest")).expect("grammar");
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

/// The crate graph as designed, written once: each crate's folder, its
/// name, and every crate it may depend on (the workspace's own first). A new
/// dependency is a change of architecture: add it here, in the same commit,
/// and to ARCHITECTURE.md.
const GRAPH: &[(&str, &str, &[&str])] = &[
    ("crates/base", "ravel-base", &["nalgebra"]),
    (
        "crates/syntax",
        "ravel-syntax",
        &["ravel-base", "pest", "pest_derive", "miette"],
    ),
    // the checker trusts nothing of the analysis: it may use the base crate alone
    (
        "crates/certify",
        "ravel-certify",
        &["ravel-base", "nalgebra", "serde_json"],
    ),
    // the only crate with solvers, a thread pool and `unsafe` (loading BLAS);
    // the checker spreads a certificate's independent cells over scoped
    // std threads only
    (
        "crates/analysis",
        "ravel-analysis",
        &[
            "ravel-base",
            "nalgebra",
            "clarabel",
            "faer",
            "dyn-stack",
            "rayon",
            "libc",
        ],
    ),
    (
        "crates/ravel",
        "ravel",
        &[
            "ravel-syntax",
            "ravel-base",
            "ravel-certify",
            "ravel-analysis",
            "nalgebra",
            "prost",
            "serde_json",
            "sha2",
            "mimalloc",
            // plots: its SVG backend only (no fonts, no system libraries)
            "plotters",
        ],
    ),
    // the editor's answers (hover, definitions, completion) over text: no
    // IO and no protocol
    (
        "crates/ide",
        "ravel-ide",
        &["ravel", "ravel-analysis", "ravel-base", "ravel-syntax"],
    ),
    // the file reader of the entry points (the command line and the Python
    // extension): regular files only, confined, limited; `.gz` files
    // decompressed (flate2's pure-Rust backend)
    ("crates/files", "ravel-files", &["ravel", "libc", "flate2"]),
    // the Python extension: an entry point beside the command line, on the
    // library alone (no clap, no protocol); PyO3 its only new dependency
    (
        "crates/python",
        "ravel-python",
        &[
            "ravel",
            "ravel-base",
            "ravel-certify",
            "ravel-files",
            "ravel-syntax",
            "serde_json",
            "pyo3",
        ],
    ),
    // the command line: the only crate with clap and the language server's
    // protocol
    (
        ".",
        "ravel-cli",
        &[
            "ravel",
            "ravel-analysis",
            "ravel-base",
            "ravel-certify",
            "ravel-syntax",
            "ravel-ide",
            "ravel-files",
            "nalgebra",
            "prost",
            "lsp-server",
            "lsp-types",
            "clap",
            "serde_json",
        ],
    ),
];

/// The `[dependencies]` of a manifest (the keys only).
fn dependencies(manifest: &str) -> Vec<String> {
    let mut deps = Vec::new();
    let mut inside = false;
    for line in manifest.lines() {
        let line = line.trim();
        if line.starts_with('[') {
            inside = line == "[dependencies]";
        } else if inside && !line.is_empty() && !line.starts_with('#') {
            let key: String = line
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '-' || *c == '_')
                .collect();
            deps.push(key);
        }
    }
    deps
}

/// Every crate depends on exactly the crates the design allows, and the
/// workspace has exactly the designed crates.
#[test]
fn the_crate_graph_is_the_designed_one() {
    let root_manifest = std::fs::read_to_string(root().join("Cargo.toml")).expect("manifest");
    for (dir, name, allowed) in GRAPH {
        let manifest =
            std::fs::read_to_string(root().join(dir).join("Cargo.toml")).expect("crate manifest");
        assert!(
            manifest.contains(&format!("name = \"{name}\"")),
            "{dir} is not the crate {name}"
        );
        let mut deps = dependencies(&manifest);
        deps.sort();
        let mut want: Vec<String> = allowed.iter().map(|s| s.to_string()).collect();
        want.sort();
        assert_eq!(deps, want, "{name}'s dependencies differ from the design");
        if *dir != "." {
            assert!(
                root_manifest.contains(&format!("\"{dir}\"")),
                "{dir} is not a workspace member"
            );
        }
    }
    let mut crates = Vec::new();
    for e in std::fs::read_dir(root().join("crates")).expect("crates") {
        crates.push(e.expect("entry").file_name().to_string_lossy().to_string());
    }
    assert_eq!(
        crates.len(),
        GRAPH.len() - 1,
        "a crate outside the design: {crates:?}"
    );
}

/// `unsafe` is forbidden at every crate's root but the analysis crate's,
/// which denies it and allows it in the one module that loads BLAS, and the
/// Python extension's, which denies it (PyO3's macros expand to `unsafe`
/// code and allow it there); no library crate touches the file system, the
/// process or its environment: only the entry points do (the command line,
/// the Python extension) and the file reader they share.
#[test]
fn only_the_analysis_crate_may_hold_unsafe_code_and_only_the_cli_does_io() {
    for (dir, name, _) in GRAPH {
        let lib = root().join(dir).join("src/lib.rs");
        let text = std::fs::read_to_string(&lib).expect("lib.rs");
        let want = if *name == "ravel-analysis" || *name == "ravel-python" {
            "#![deny(unsafe_code)]"
        } else {
            "#![forbid(unsafe_code)]"
        };
        assert!(text.contains(want), "{} lacks {want}", lib.display());
    }
    let mut files = Vec::new();
    rust_files(&root().join("crates"), &mut files);
    let mut allowed_unsafe = 0;
    for f in files {
        let entry_point = ["crates/files/", "crates/python/"]
            .iter()
            .any(|d| f.starts_with(root().join(d)));
        let text = std::fs::read_to_string(&f).expect("readable");
        // unit tests may read files and the environment
        let code = text.split("#[cfg(test)]").next().unwrap_or("");
        for line in code.lines() {
            let code = line.split("//").next().unwrap_or("");
            for io in ["std::fs", "File::", "std::env", "std::process::Command"] {
                assert!(entry_point || !code.contains(io), "{}: {line}", f.display());
            }
            if code.contains("allow(unsafe_code)") {
                assert!(
                    f.ends_with("crates/analysis/src/blas.rs"),
                    "{}",
                    f.display()
                );
                allowed_unsafe += 1;
            }
        }
    }
    assert!(allowed_unsafe >= 1);
}

/// The phases of the `ravel` crate, in pipeline order: a module may use
/// only modules before it (the library's root, the driver, uses them all).
const PHASES: [&str; 9] = [
    "ir",
    "onnx",
    "vnnlib",
    "check",
    "lower",
    "execute",
    "report",
    "certificate_writer",
    "plot",
];

/// Inside the `ravel` crate the phases import forward only: no module
/// names a later phase outside comments.
#[test]
fn the_phases_import_forward_only() {
    let src = root().join("crates/ravel/src");
    for (k, phase) in PHASES.iter().enumerate() {
        let mut files = Vec::new();
        let dir = src.join(phase);
        if dir.is_dir() {
            rust_files(&dir, &mut files);
        } else {
            files.push(src.join(format!("{phase}.rs")));
        }
        for f in files {
            let text = std::fs::read_to_string(&f).expect("readable");
            for line in text.lines() {
                let code = line.split("//").next().unwrap_or("");
                for (i, _) in code.match_indices("crate::") {
                    let name: String = code[i + "crate::".len()..]
                        .chars()
                        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                        .collect();
                    if let Some(j) = PHASES.iter().position(|p| *p == name) {
                        assert!(
                            j <= k,
                            "{} ({phase}) uses crate::{name}, a later phase",
                            f.display()
                        );
                    }
                }
            }
        }
    }
    let mut on_disk: Vec<String> = std::fs::read_dir(&src)
        .expect("src")
        .map(|e| {
            let name = e.expect("entry").file_name().to_string_lossy().to_string();
            name.trim_end_matches(".rs").to_string()
        })
        .filter(|n| n != "lib")
        .collect();
    on_disk.sort();
    let mut listed: Vec<String> = PHASES.iter().map(|p| p.to_string()).collect();
    listed.sort();
    assert_eq!(
        on_disk, listed,
        "a module of the ravel crate outside PHASES"
    );
}

/// Every keyword of the grammar is highlighted by the VS Code extension's
/// TextMate grammar (it appears in one of its `match` patterns) and is
/// annotated in its samples (`scripts/test-grammar.sh` checks the scopes),
/// so the two grammars cannot drift apart. The keywords are the language
/// server's list, `ravel_ide::words::KEYWORDS`, which its own test holds
/// equal to the pest grammar's quoted words: one list, not a second reading
/// of the grammar here.
#[test]
fn the_textmate_grammar_knows_every_keyword() {
    let dir = root().join("editors/vscode");
    let tm: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("syntaxes/ravel.tmLanguage.json")).expect("grammar"),
    )
    .expect("JSON");
    fn matches(v: &serde_json::Value, out: &mut Vec<String>) {
        match v {
            serde_json::Value::Object(o) => {
                for (k, x) in o {
                    match (k.as_str(), x.as_str()) {
                        ("match" | "begin", Some(s)) => out.push(s.to_string()),
                        _ => matches(x, out),
                    }
                }
            }
            serde_json::Value::Array(a) => a.iter().for_each(|x| matches(x, out)),
            _ => {}
        }
    }
    let mut patterns = Vec::new();
    matches(&tm, &mut patterns);
    let words: Vec<&str> = patterns
        .iter()
        .flat_map(|p| p.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_')))
        .collect();
    let mut samples = String::new();
    for e in std::fs::read_dir(dir.join("test")).expect("samples") {
        let p = e.expect("entry").path();
        if p.extension().is_some_and(|x| x == "ravel-test") {
            samples.push_str(&std::fs::read_to_string(&p).expect("sample"));
        }
    }
    let sample_words: Vec<&str> = samples
        .lines()
        .filter(|l| !l.starts_with("//"))
        .flat_map(|l| l.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_')))
        .collect();
    let keywords: Vec<&str> = ravel_ide::words::KEYWORDS.iter().map(|(k, _)| *k).collect();
    assert!(keywords.len() > 50, "{keywords:?}");
    for k in &keywords {
        assert!(
            words.contains(k),
            "the keyword `{k}` is not in editors/vscode/syntaxes/ravel.tmLanguage.json"
        );
        assert!(
            sample_words.contains(k),
            "the keyword `{k}` is in no sample of editors/vscode/test/"
        );
    }
}
