//! VNN-COMP as a front end, through the binary: `verify --network
//! --vnnlib` (the result file's rules: `sat` with the counterexample's
//! assignments, `unsat`, `timeout`, `unknown`; errors are diagnostics with
//! exit code 2 and no result), `import-vnnlib` over input regions, and
//! `vnncomp` over a tiny generated benchmark folder, hostile rows included.
//! Networks are hand-made here; nothing third-party is used.

use std::path::{Path, PathBuf};

use nalgebra::{DMatrix, DVector};
use ravel::onnx::build::{GraphBuilder, Storage};
use ravel_cli::vnncomp::{parse_instances, result_text, Answer};

#[path = "common/binary.rs"]
mod binary;
use binary::ravel;

fn scratch(name: &str) -> PathBuf {
    binary::scratch("vnncomp", name)
}

/// `y0 = x0 + x1`, `y1 = x0 − x1` (float32, exact weights).
fn linear_net(dir: &Path) -> PathBuf {
    let mut g = GraphBuilder::new(2, Storage::RawF32);
    g.gemm(
        &DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, -1.0]),
        &DVector::zeros(2),
    );
    let p = dir.join("net.onnx");
    std::fs::write(&p, g.finish(2).0).expect("write");
    p
}

fn property(dir: &Path, name: &str, asserts: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(
        &p,
        format!(
            "(declare-const X_0 Real)\n(declare-const X_1 Real)\n\
             (declare-const Y_0 Real)\n(declare-const Y_1 Real)\n\
             (assert (>= X_0 0))\n(assert (<= X_0 1))\n\
             (assert (>= X_1 0))\n(assert (<= X_1 1))\n{asserts}\n"
        ),
    )
    .expect("write");
    p
}

/// `file` gzip-compressed, written beside it as `NAME.gz`.
fn gzip(file: &Path) -> PathBuf {
    use std::io::Write;
    let out = PathBuf::from(format!("{}.gz", file.display()));
    let mut e = flate2::write::GzEncoder::new(
        std::fs::File::create(&out).expect("create"),
        flate2::Compression::default(),
    );
    e.write_all(&std::fs::read(file).expect("read"))
        .expect("compress");
    e.finish().expect("finish");
    out
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// The counterexample of a `sat` result file: the `X_i` and `Y_j` values,
/// after checking the file's layout line by line.
fn assignments(text: &str, inputs: usize, outputs: usize) -> (Vec<f64>, Vec<f64>) {
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 3 + inputs + outputs, "{text}");
    assert_eq!(lines[0], "sat");
    assert_eq!(lines[1], "(");
    assert_eq!(*lines.last().expect("line"), ")");
    let value = |line: &str, name: String| -> f64 {
        let inner = line
            .strip_prefix('(')
            .and_then(|l| l.strip_suffix(')'))
            .unwrap_or_else(|| panic!("{line}"));
        let (n, v) = inner.split_once(' ').expect("name and value");
        assert_eq!(n, name);
        v.parse().expect("a number")
    };
    let x = (0..inputs)
        .map(|i| value(lines[2 + i], format!("X_{i}")))
        .collect();
    let y = (0..outputs)
        .map(|j| value(lines[2 + inputs + j], format!("Y_{j}")))
        .collect();
    (x, y)
}

#[test]
fn the_result_writer_follows_the_format() {
    assert_eq!(result_text(&Answer::Unsat), "unsat\n");
    assert_eq!(result_text(&Answer::Timeout), "timeout\n");
    assert_eq!(result_text(&Answer::Unknown), "unknown\n");
    let x = f64::from(0.1f32);
    let text = result_text(&Answer::Sat {
        input: vec![x, -2.0],
        output: vec![1e-30, 3.0],
    });
    assert_eq!(
        text,
        "sat\n(\n(X_0 0.10000000149011612)\n(X_1 -2.0)\n(Y_0 1e-30)\n(Y_1 3.0)\n)\n"
    );
    // full precision: the values read back to the same bits
    let (xs, ys) = assignments(&text, 2, 2);
    assert_eq!(xs[0].to_bits(), x.to_bits());
    assert_eq!(ys, vec![1e-30, 3.0]);
}

#[test]
fn the_direct_form_answers_sat_unsat_timeout_and_unknown() {
    let d = scratch("direct");
    let net = linear_net(&d);
    let out = d.join("result.txt");

    // sat: x0 + x1 >= 1.5 somewhere in the box
    let p = property(&d, "sat.vnnlib", "(assert (>= Y_0 1.5))");
    let (code, stdout, stderr) = ravel(&[
        "verify",
        "--network",
        s(&net),
        "--vnnlib",
        s(&p),
        "--result-file",
        s(&out),
    ]);
    assert_eq!(code, 1, "{stdout}{stderr}");
    assert!(stdout.contains(": sat ("), "{stdout}");
    let text = std::fs::read_to_string(&out).expect("result");
    let (x, y) = assignments(&text, 2, 2);
    for v in &x {
        assert!((0.0..=1.0).contains(v), "{text}");
        assert_eq!(f64::from(*v as f32), *v, "a float32 input: {text}");
    }
    // the output the float32 network gives for it
    let (a, b) = (x[0] as f32, x[1] as f32);
    assert_eq!(y, vec![f64::from(a + b), f64::from(a - b)], "{text}");
    assert!(y[0] >= 1.5);

    // unsat: x0 + x1 never reaches 2.5
    let p = property(&d, "unsat.vnnlib", "(assert (>= Y_0 2.5))");
    let (code, ..) = ravel(&[
        "verify",
        "--network",
        s(&net),
        "--vnnlib",
        s(&p),
        "--result-file",
        s(&out),
    ]);
    assert_eq!(code, 0);
    assert_eq!(std::fs::read_to_string(&out).expect("result"), "unsat\n");

    // without --result-file the answer goes to standard output
    let (code, stdout, _) = ravel(&["verify", "--network", s(&net), "--vnnlib", s(&p)]);
    assert_eq!((code, stdout.as_str()), (0, "unsat\n"));

    // the time limit ends the run before anything is decided: timeout
    let (code, stdout, _) = ravel(&[
        "verify",
        "--network",
        s(&net),
        "--vnnlib",
        s(&p),
        "--time-limit",
        "0",
    ]);
    assert_eq!((code, stdout.as_str()), (3, "timeout\n"));

    // x0 + x1 > 2 never holds, but the non-strict reading is met at the
    // corner (1, 1): never `sat`, and undecided without the time limit
    let p = property(&d, "strict.vnnlib", "(assert (> Y_0 2))");
    let (code, stdout, stderr) = ravel(&["verify", "--network", s(&net), "--vnnlib", s(&p)]);
    assert_eq!((code, stdout.as_str()), (3, "unknown\n"), "{stderr}");
}

#[test]
fn regions_are_combined_sat_if_any_unsat_if_all() {
    let d = scratch("regions");
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let classifier = root.join("models/classifier.onnx");
    // the second region is falsified (see tests/vnnlib.rs)
    let p = root.join("tests/data/vnnlib/input_disjunction.vnnlib");
    let out = d.join("r.txt");
    let (code, _, stderr) = ravel(&[
        "verify",
        "--network",
        s(&classifier),
        "--vnnlib",
        s(&p),
        "--result-file",
        s(&out),
    ]);
    assert_eq!(code, 1, "{stderr}");
    let (x, y) = assignments(&std::fs::read_to_string(&out).expect("result"), 2, 3);
    assert!((-0.35..=-0.25).contains(&x[0]) && (0.25..=0.35).contains(&x[1]));
    assert!(y[1] >= y[0]);

    // both regions safe: unsat
    let both = d.join("both.vnnlib");
    std::fs::write(
        &both,
        "(declare-const X_0 Real)\n(declare-const X_1 Real)\n(declare-const Y_0 Real)\n\
         (declare-const Y_1 Real)\n(declare-const Y_2 Real)\n\
         (assert (or (and (>= X_0 0.55) (<= X_0 0.65) (>= X_1 0.25) (<= X_1 0.35) (>= Y_1 Y_0))\n\
                     (and (>= X_0 0.6) (<= X_0 0.7) (>= X_1 0.2) (<= X_1 0.3) (>= Y_1 Y_0))))\n",
    )
    .expect("write");
    let (code, stdout, stderr) =
        ravel(&["verify", "--network", s(&classifier), "--vnnlib", s(&both)]);
    assert_eq!((code, stdout.as_str()), (0, "unsat\n"), "{stderr}");
}

#[test]
fn errors_are_diagnostics_and_write_no_result() {
    let d = scratch("errors");
    let net = linear_net(&d);
    let out = d.join("result.txt");
    let mixed = property(&d, "mixed.vnnlib", "(assert (<= (+ X_0 Y_0) 1))");
    let gz = d.join("p.vnnlib.gz");
    std::fs::write(&gz, b"\x1f\x8b").expect("write");
    let unsat = property(&d, "ok.vnnlib", "(assert (>= Y_0 2.5))");
    for (net, prop, code) in [
        (net.clone(), mixed, "E0401"),
        (net.clone(), gz, "E0401"),
        (net.clone(), d.join("missing.vnnlib"), "E0401"),
        (d.join("missing.onnx"), unsat, "E0301"),
    ] {
        let (exit, stdout, stderr) = ravel(&[
            "verify",
            "--network",
            s(&net),
            "--vnnlib",
            s(&prop),
            "--result-file",
            s(&out),
        ]);
        assert_eq!(exit, 2, "{stdout}{stderr}");
        assert!(stderr.contains(code), "{code}: {stderr}");
        assert!(!out.exists(), "no result for an error");
    }
    // the unsupported construct is shown at its place in the property
    let (_, _, stderr) = ravel(&[
        "import-vnnlib",
        s(&d.join("mixed.vnnlib")),
        "--network",
        s(&net),
    ]);
    assert!(
        stderr.contains("E0401") && stderr.contains("relating inputs and outputs"),
        "{stderr}"
    );
    assert!(stderr.contains("mixed.vnnlib:9:"), "{stderr}");
}

#[test]
fn a_benchmark_folder_runs_row_by_row() {
    let d = scratch("bench");
    std::fs::create_dir_all(d.join("onnx")).expect("dir");
    std::fs::create_dir_all(d.join("vnnlib")).expect("dir");
    let net = linear_net(&d.join("onnx"));
    assert!(net.ends_with("onnx/net.onnx"));
    property(&d.join("vnnlib"), "sat.vnnlib", "(assert (>= Y_0 1.5))");
    property(&d.join("vnnlib"), "unsat.vnnlib", "(assert (>= Y_0 2.5))");
    property(
        &d.join("vnnlib"),
        "mixed.vnnlib",
        "(assert (<= (+ X_0 Y_0) 1))",
    );
    std::fs::write(
        d.join("instances.csv"),
        "onnx/net.onnx,vnnlib/sat.vnnlib,60\r\nonnx/net.onnx,vnnlib/unsat.vnnlib,60\n\n",
    )
    .expect("write");
    let results = d.join("results.csv");
    let (code, stdout, stderr) =
        ravel(&["vnncomp", s(&d.join("instances.csv")), "--out", s(&results)]);
    assert_eq!(code, 0, "{stderr}");
    let written = std::fs::read_to_string(&results).expect("results");
    assert_eq!(written, stdout);
    let rows: Vec<Vec<&str>> = written.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 2, "{written}");
    assert_eq!(rows[0][..3], ["onnx/net.onnx", "vnnlib/sat.vnnlib", "sat"]);
    assert_eq!(
        rows[1][..3],
        ["onnx/net.onnx", "vnnlib/unsat.vnnlib", "unsat"]
    );
    for r in &rows {
        let t: f64 = r[3].parse().expect("seconds");
        assert!((0.0..60.0).contains(&t));
    }

    // the same list elsewhere, with --root; an instance that cannot be
    // imported is `error` (exit 2), and the others still run
    let elsewhere = scratch("bench-list");
    std::fs::write(
        elsewhere.join("list.csv"),
        "onnx/net.onnx,vnnlib/mixed.vnnlib,5\nonnx/net.onnx,vnnlib/unsat.vnnlib,5\n",
    )
    .expect("write");
    let (code, stdout, stderr) =
        ravel(&["vnncomp", s(&elsewhere.join("list.csv")), "--root", s(&d)]);
    assert_eq!(code, 2);
    assert!(stderr.contains("E0401"), "{stderr}");
    let results: Vec<&str> = stdout
        .lines()
        .map(|l| l.split(',').nth(2).expect("result"))
        .collect();
    assert_eq!(results, ["error", "unsat"]);

    // unusable rows: every one reported with its line, nothing runs
    std::fs::write(
        d.join("bad.csv"),
        "onnx/net.onnx,vnnlib/sat.vnnlib\n\
         onnx/net.onnx,vnnlib/sat.vnnlib,sixty\n\
         onnx/none.onnx,vnnlib/sat.vnnlib,60\n\
         onnx/net.onnx.gz,vnnlib/sat.vnnlib,60\n\
         onnx/net.onnx,vnnlib/sat.vnnlib,-1\n\
         \u{1b}[31m,x,1e999\n",
    )
    .expect("write");
    let out = d.join("bad-results.csv");
    let (code, stdout, stderr) = ravel(&["vnncomp", s(&d.join("bad.csv")), "--out", s(&out)]);
    assert_eq!(code, 2);
    assert!(stdout.is_empty(), "nothing ran: {stdout}");
    assert!(!out.exists());
    assert!(stderr.matches("E0402").count() >= 6, "{stderr}");
    assert!(!stderr.contains('\u{1b}'), "no raw escape: {stderr}");
    for what in [
        "3 fields",
        "sixty",
        "is not a file",
        "-1",
        "nothing was run",
    ] {
        assert!(stderr.contains(what), "{what}: {stderr}");
    }
    // a list that does not exist
    let (code, _, stderr) = ravel(&["vnncomp", s(&d.join("none.csv"))]);
    assert_eq!(code, 2);
    assert!(stderr.contains("E0402"), "{stderr}");
}

/// The row parser on hostile text: never a panic, every problem a
/// diagnostic with a span inside the text.
#[test]
fn instance_rows_are_parsed_without_panics() {
    let root = Path::new("/r");
    let exists = |p: &Path| p.to_str().is_some_and(|s| !s.contains("missing"));
    let ok = parse_instances(" a.onnx , b.vnnlib , 12.5 \n", root, &exists).expect("a row");
    assert_eq!(ok.len(), 1);
    assert_eq!(ok[0].network, Path::new("/r/a.onnx"));
    assert_eq!(ok[0].property_field, "b.vnnlib");
    assert_eq!(ok[0].timeout, 12.5);
    for text in [
        "",
        "\n\n",
        ",,",
        ",,,,,,",
        "a,b,NaN",
        "a,b,inf",
        "a,b,1e400",
        "missing.onnx,b,1",
        "a,b,c\u{0}",
        "é,ü,☃",
        "a,b,-0.5",
        "\r\n,\r\n",
    ] {
        let diags = parse_instances(text, root, &exists).expect_err(text);
        for d in &diags {
            assert_eq!(d.code.as_str(), "E0402");
            if let Some(sp) = d.span {
                assert!(
                    sp.start <= sp.end && sp.end <= text.len() + 1,
                    "{text:?}: {sp:?}"
                );
            }
        }
    }
}

#[test]
fn compressed_files_give_the_plain_files_answers() {
    let d = scratch("gz");
    std::fs::create_dir_all(d.join("onnx")).expect("dir");
    std::fs::create_dir_all(d.join("vnnlib")).expect("dir");
    let net = linear_net(&d.join("onnx"));
    let sat = property(&d.join("vnnlib"), "sat.vnnlib", "(assert (>= Y_0 1.5))");
    let unsat = property(&d.join("vnnlib"), "unsat.vnnlib", "(assert (>= Y_0 2.5))");
    let (net_gz, sat_gz, unsat_gz) = (gzip(&net), gzip(&sat), gzip(&unsat));
    // the direct form: every mix of plain and compressed files, the same
    // answer (the same counterexample for `sat`)
    for (prop, prop_gz, code) in [(&sat, &sat_gz, 1), (&unsat, &unsat_gz, 0)] {
        let plain = ravel(&["verify", "--network", s(&net), "--vnnlib", s(prop)]);
        assert_eq!(plain.0, code, "{}", plain.2);
        for (n, p) in [(&net_gz, prop_gz), (&net, prop_gz), (&net_gz, prop)] {
            let got = ravel(&["verify", "--network", s(n), "--vnnlib", s(p)]);
            assert_eq!((got.0, &got.1), (code, &plain.1), "{}", got.2);
        }
    }
    // an instance list naming compressed files, itself compressed too
    std::fs::write(
        d.join("instances.csv"),
        "onnx/net.onnx.gz,vnnlib/sat.vnnlib.gz,60\nonnx/net.onnx.GZ,vnnlib/unsat.vnnlib.gz,60\n",
    )
    .expect("write");
    std::fs::copy(&net_gz, d.join("onnx/net.onnx.GZ")).expect("copy");
    let list_gz = gzip(&d.join("instances.csv"));
    for list in [d.join("instances.csv"), list_gz] {
        let (code, stdout, stderr) = ravel(&["vnncomp", s(&list)]);
        assert_eq!(code, 0, "{stderr}");
        let results: Vec<&str> = stdout
            .lines()
            .map(|l| l.split(',').nth(2).expect("result"))
            .collect();
        assert_eq!(results, ["sat", "unsat"], "{stdout}");
    }
    // import-vnnlib names the spec after the property without `.gz`, and
    // the spec reads the compressed network
    let (code, stdout, stderr) = ravel(&["import-vnnlib", s(&unsat_gz), "--network", s(&net_gz)]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        stdout.contains("unsat") && !stdout.contains("unsat_vnnlib"),
        "{stdout}"
    );
    assert!(stdout.contains("net.onnx.gz"), "{stdout}");
}

#[test]
fn a_compressed_models_external_data_lies_beside_it_uncompressed() {
    let d = scratch("gz-external");
    let mut g = GraphBuilder::new(2, Storage::External).external_file("net.onnx.data");
    g.gemm(
        &DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, -1.0]),
        &DVector::zeros(2),
    );
    let (model, data) = g.finish(2);
    assert!(!data.is_empty());
    std::fs::write(d.join("net.onnx"), model).expect("write");
    std::fs::write(d.join("net.onnx.data"), data).expect("write");
    let net_gz = gzip(&d.join("net.onnx"));
    std::fs::remove_file(d.join("net.onnx")).expect("remove");
    let unsat = property(&d, "unsat.vnnlib", "(assert (>= Y_0 2.5))");
    let sat = property(&d, "sat.vnnlib", "(assert (>= Y_0 1.5))");
    for (prop, code, word) in [(&unsat, 0, "unsat\n"), (&sat, 1, "sat\n")] {
        let (exit, stdout, stderr) =
            ravel(&["verify", "--network", s(&net_gz), "--vnnlib", s(prop)]);
        assert_eq!(exit, code, "{stderr}");
        assert!(stdout.starts_with(word), "{stdout}");
    }
}

/// Writes a gzip stream of `zeros` zero bytes to `path`, a chunk at a time
/// (the decompressed data is never held).
fn gzip_zeros(path: &Path, zeros: u64) {
    use std::io::Write;
    let mut e = flate2::write::GzEncoder::new(
        std::fs::File::create(path).expect("create"),
        flate2::Compression::best(),
    );
    let chunk = vec![0u8; 1 << 16];
    let mut left = zeros;
    while left > 0 {
        let n = left.min(chunk.len() as u64) as usize;
        e.write_all(&chunk[..n]).expect("compress");
        left -= n as u64;
    }
    e.finish().expect("finish");
}

/// A rendered diagnostic's words on one line (the renderer wraps long
/// messages behind a `│`).
fn unwrapped(rendered: &str) -> String {
    rendered
        .split_whitespace()
        .filter(|w| *w != "│")
        .collect::<Vec<_>>()
        .join(" ")
}

#[test]
fn broken_and_oversized_compressed_files_are_diagnostics() {
    let d = scratch("gz-bad");
    let net = linear_net(&d);
    let unsat = property(&d, "unsat.vnnlib", "(assert (>= Y_0 2.5))");
    let net_gz = gzip(&net);
    let unsat_gz = gzip(&unsat);
    // truncated: the property, and the network
    let whole = std::fs::read(&unsat_gz).expect("read");
    let cut = d.join("cut.vnnlib.gz");
    std::fs::write(&cut, &whole[..whole.len() / 2]).expect("write");
    let whole_net = std::fs::read(&net_gz).expect("read");
    let cut_net = d.join("cut.onnx.gz");
    std::fs::write(&cut_net, &whole_net[..whole_net.len() - 3]).expect("write");
    // named .gz but plain text
    let not_gz = d.join("plain.vnnlib.gz");
    std::fs::copy(&unsat, &not_gz).expect("copy");
    // a bomb: 64 MiB of zeros (about 64 KiB compressed), beyond the
    // property limit of 16 MiB
    let limit = ravel_base::limits::MAX_SPEC_BYTES;
    assert!(64 << 20 > limit);
    let bomb = d.join("bomb.vnnlib.gz");
    gzip_zeros(&bomb, 64 << 20);
    assert!(std::fs::metadata(&bomb).expect("bomb").len() < limit);
    let out = d.join("result.txt");
    for (n, p, code, what) in [
        (&net, &cut, "E0401", "is not valid gzip ("),
        (&net, &not_gz, "E0401", "is not valid gzip ("),
        (&cut_net, &unsat, "E0301", "is not valid gzip ("),
        (
            &net,
            &bomb,
            "E0401",
            &format!("decompresses to more than the limit of {limit} bytes") as &str,
        ),
    ] {
        let (exit, stdout, stderr) = ravel(&[
            "verify",
            "--network",
            s(n),
            "--vnnlib",
            s(p),
            "--result-file",
            s(&out),
        ]);
        assert_eq!(exit, 2, "{stdout}{stderr}");
        assert!(
            stderr.contains(code) && unwrapped(&stderr).contains(what),
            "{what}: {stderr}"
        );
        assert!(!out.exists(), "no result for an error");
    }
    // the same bomb as an instance list
    let (exit, _, stderr) = ravel(&["vnncomp", s(&bomb)]);
    assert_eq!(exit, 2, "{stderr}");
    assert!(
        stderr.contains("E0402")
            && unwrapped(&stderr).contains(&format!(
                "decompresses to more than the limit of {limit} bytes"
            )),
        "{stderr}"
    );
}
