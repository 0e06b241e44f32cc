//! `ravel fmt`: on every spec that parses (valid and invalid ones), the
//! canonical layout keeps the meaning (the formatter itself refuses
//! otherwise, and this file compares the trees again on its own), keeps
//! every comment, and is idempotent; the command line rewrites files in
//! place and `--check` reports a diff with exit code 1. The canonical
//! layout is the house style: every shipped spec that parses, every spec
//! in the README's and the docs' examples, and `import-vnnlib`'s output are
//! already in it.

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

/// Every `.ravel` file under `dir`, recursively.
fn ravel_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for e in std::fs::read_dir(dir).expect("folder") {
        let p = e.expect("entry").path();
        if p.is_dir() {
            ravel_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "ravel") {
            out.push(p);
        }
    }
}

/// A syntax tree's debug form with every span (`@12..34`, `span: 12..34`)
/// taken out: two specs that differ only in layout give the same text.
fn without_spans(ast: &ravel_syntax::ast::Spec) -> String {
    let text = format!("{ast:#?}");
    let mut out = String::new();
    for line in text.lines() {
        let t = line.trim_start();
        if t.starts_with("span: ") {
            continue;
        }
        let kept = match line.rfind(" @") {
            Some(at)
                if line[at + 2..]
                    .trim_end_matches(',')
                    .split("..")
                    .all(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit())) =>
            {
                format!(
                    "{}{}",
                    &line[..at],
                    if line.ends_with(',') { "," } else { "" }
                )
            }
            _ => line.to_string(),
        };
        out.push_str(&kept);
        out.push('\n');
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
fn the_house_style() {
    // keywords and names line up, budgets are spaced, crammed items are
    // split, matrices and trailing comments are aligned
    let src = "system s { state x[2] control u[1]\n A = [[1, 0.1], [0, -1]]\n B = [[0.5, 1],\n[-0.25, 10]] // B\n\n u in box([-1, 1])   // limits\n w in box([0, 0]) // noise\n}\ninitial X0 = box([0, 1], [0, 1])\ngoal G = { x[0] <= 1 }\navoid overshoot = { x[0] >= 9 }\nhorizon 5\ngoal close = { x[0] <= 1 }\navoid overshoot = { x[0] >= 9 }\n   | { x[1] >= 9 }\nanalysis { propagator reach_lp partitioner gsg(calls 8) }\n";
    let out = ravel_syntax::fmt::format(src).expect("formats");
    assert_eq!(
        out,
        "system s {\n    state   x[2]\n    control u[1]\n    A = [[1, 0.1], [0, -1]]\n    B = [[ 0.5,  1 ],\n         [-0.25, 10]]  // B\n\n    u in box([-1, 1])  // limits\n    w in box([0, 0])   // noise\n}\ninitial X0 = box([0, 1], [0, 1])\ngoal    G  = { x[0] <= 1 }\navoid   overshoot = { x[0] >= 9 }\nhorizon 5\ngoal    close     = { x[0] <= 1 }\navoid   overshoot = { x[0] >= 9 }\n                  | { x[1] >= 9 }\nanalysis {\n    propagator  reach_lp\n    partitioner gsg (calls 8)\n}\n"
    );
    assert_eq!(ravel_syntax::fmt::format(&out).expect("formats"), out);
}

#[test]
fn command_line_formats_in_place_and_checks() {
    let dir = std::env::temp_dir().join(format!("ravel-fmt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let file = dir.join("di.ravel");
    let canonical = std::fs::read_to_string("specs/double_integrator.ravel").expect("spec");
    let src = canonical.replace("state   x[2]", "state x[2]");
    assert_ne!(src, canonical);
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
        diff.contains("-    state x[2]") && diff.contains("+    state   x[2]"),
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
    assert_eq!(after, canonical);
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

/// The shipped specs that parse, with their text: `specs/` and the
/// benchmark suite's `benchmarks/` (pending ones included).
fn shipped() -> Vec<(std::path::PathBuf, String)> {
    let mut files = Vec::new();
    ravel_files(Path::new("specs"), &mut files);
    ravel_files(Path::new("benchmarks"), &mut files);
    files.sort();
    files
        .into_iter()
        .filter_map(|p| {
            let src = std::fs::read_to_string(&p).ok()?;
            ravel_syntax::parse(&src).is_ok().then_some((p, src))
        })
        .collect()
}

#[test]
fn every_shipped_spec_is_in_the_house_style() {
    let specs = shipped();
    assert!(
        specs.len() >= 90,
        "only {} shipped specs parse",
        specs.len()
    );
    let mut off = Vec::new();
    for (path, src) in &specs {
        let formatted = ravel_syntax::fmt::format(src).expect("formats");
        if formatted != *src {
            off.push(path.display().to_string());
        }
    }
    assert!(
        off.is_empty(),
        "not in the canonical layout (run `ravel fmt` on them): {off:?}"
    );
}

#[test]
fn formatting_never_changes_a_shipped_spec_s_tree_and_is_idempotent() {
    for (path, src) in shipped() {
        // an indented copy with the items crammed and spaced oddly, so the
        // formatter has work to do even where the spec is canonical
        let messy: String = src
            .lines()
            .map(|l| format!("  {}", l.replace(", ", " ,  ")))
            .collect::<Vec<_>>()
            .join("\n");
        for input in [src.clone(), messy] {
            let Ok(before) = ravel_syntax::parse(&input) else {
                continue;
            };
            let formatted = ravel_syntax::fmt::format(&input).expect("formats");
            assert_eq!(
                ravel_syntax::fmt::format(&formatted).expect("formats again"),
                formatted,
                "{}: not idempotent",
                path.display()
            );
            let after = ravel_syntax::parse(&formatted).expect("the formatted spec parses");
            assert_eq!(
                without_spans(&before),
                without_spans(&after),
                "{}: formatting changed the meaning",
                path.display()
            );
        }
    }
}

#[test]
fn spans_are_what_the_meaning_comparison_ignores() {
    // the comparison above must see a changed number and a changed name
    let a = ravel_syntax::parse("horizon 5\ninitial X0 = box([0, 1])").expect("parses");
    let b = ravel_syntax::parse("horizon   5\n\ninitial X0 = box([0, 1])").expect("parses");
    let c = ravel_syntax::parse("horizon 6\ninitial X0 = box([0, 1])").expect("parses");
    let d = ravel_syntax::parse("horizon 5\ninitial X1 = box([0, 1])").expect("parses");
    assert_eq!(without_spans(&a), without_spans(&b));
    assert_ne!(without_spans(&a), without_spans(&c));
    assert_ne!(without_spans(&a), without_spans(&d));
    assert!(!without_spans(&a).contains("@"), "{}", without_spans(&a));
}

/// The fenced blocks of a Markdown file that parse as specs.
fn documented_specs(path: &str) -> Vec<String> {
    let text = std::fs::read_to_string(path).expect("docs");
    let mut out = Vec::new();
    let mut block: Option<String> = None;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            match block.take() {
                Some(b) => {
                    if ravel_syntax::parse(&b).is_ok() && !b.trim().is_empty() {
                        out.push(b);
                    }
                }
                None => block = Some(String::new()),
            }
        } else if let Some(b) = block.as_mut() {
            b.push_str(line);
            b.push('\n');
        }
    }
    out
}

#[test]
fn the_documented_specs_are_in_the_house_style() {
    let mut files = vec!["README.md".to_string()];
    for e in std::fs::read_dir("docs").expect("docs") {
        let p = e.expect("entry").path();
        if p.extension().is_some_and(|x| x == "md") {
            files.push(p.display().to_string());
        }
    }
    let mut seen = 0;
    let mut off = Vec::new();
    for file in &files {
        for spec in documented_specs(file) {
            seen += 1;
            let formatted = ravel_syntax::fmt::format(&spec).expect("formats");
            if formatted != spec {
                off.push(format!("{file}:\n{spec}\n--- canonical:\n{formatted}"));
            }
        }
    }
    assert!(seen >= 5, "only {seen} documented specs found");
    assert!(off.is_empty(), "{}", off.join("\n=====\n"));
}

#[test]
fn imported_vnnlib_specs_are_in_the_house_style() {
    let mut n = 0;
    let (mut unions, mut polytopes, mut boxes) = (false, false, false);
    for e in std::fs::read_dir("tests/data/vnnlib").expect("folder") {
        let p = e.expect("entry").path();
        if p.extension().is_none_or(|x| x != "vnnlib") {
            continue;
        }
        let text = std::fs::read_to_string(&p).expect("read");
        let Ok(specs) = ravel::vnnlib::import(&text, "../../../models/classifier.onnx", "n", "t")
        else {
            continue;
        };
        // one spec per input region
        for spec in specs {
            let formatted = ravel_syntax::fmt::format(&spec).expect("formats");
            assert_eq!(formatted, spec, "{}", p.display());
            n += 1;
            // the layouts that continue a line are among them: a union under
            // its `=`, a polytope and a box over several lines
            unions |= spec.contains("\n             | { y[0]");
            polytopes |= spec.contains("\n            x[0] >= ");
            boxes |= spec.contains(",\n              x[1] in [");
        }
    }
    assert!(n >= 3, "only {n} imports");
    assert!(unions && polytopes && boxes);
}
