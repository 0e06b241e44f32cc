//! Hostile controller files: external data that points outside the
//! controller's folder (by `..`, absolute paths or symbolic links), special
//! files (FIFOs, devices), one file under many spellings, truncated models,
//! overflowing tensor shapes and control characters in names. Each is a
//! diagnostic (exit code 2), in bounded time, and no file outside the
//! controller's folder is ever read.

mod common;

use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::process::Command;

use nalgebra::{DMatrix, DVector};
use prost::Message;
use ravel::onnx::build::{GraphBuilder, Storage};
use ravel::onnx::proto::{ModelProto, StringStringEntryProto};
use ravel::ReadRequest;
use ravel_base::nn::{Activation, Layer, Network};
use ravel_syntax::diag::Code;

/// A fresh folder for one test.
fn folder(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("hostile")
        .join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(d.join("models")).expect("temp folder");
    d
}

fn net() -> Network {
    Network::new(
        2,
        vec![
            Layer::Affine {
                w: DMatrix::from_row_slice(3, 2, &[0.5, -0.2, 0.1, 0.3, -0.4, 0.2]),
                b: DVector::from_column_slice(&[0.0, 0.1, -0.1]),
            },
            Layer::Act(Activation::Relu),
            Layer::Affine {
                w: DMatrix::from_row_slice(1, 3, &[-0.3, 0.2, 0.1]),
                b: DVector::from_column_slice(&[0.0]),
            },
        ],
    )
}

/// A model whose weights are external, in `data_name`, and that data.
fn external_model(data_name: &str) -> (ModelProto, Vec<u8>) {
    let mut g = GraphBuilder::new(2, Storage::External).external_file(data_name);
    g.network(&net(), false);
    let (bytes, data) = g.finish(1);
    (ModelProto::decode(bytes.as_slice()).expect("model"), data)
}

/// Point every external tensor at `location` (the k-th tensor at `locations[k % len]`).
fn relocate(model: &mut ModelProto, locations: &[&str]) {
    let graph = model.graph.as_mut().expect("graph");
    for (k, t) in graph.initializer.iter_mut().enumerate() {
        for e in &mut t.external_data {
            if e.key.as_deref() == Some("location") {
                e.value = Some(locations[k % locations.len()].to_string());
            }
        }
    }
}

const SPEC: &str = r#"
system s {
    state x[2]
    control u[1]
    A = [[1, 1], [0, 1]]
    B = [[0.5], [1]]
    u in box([-1, 1])
}
controller "models/policy.onnx"
initial X0 = box(x[0] in [2.5, 3.0], x[1] in [-0.25, 0.25])
goal G = box(x[0] in [-1.5, 2.0], x[1] in [-1.5, 0.5])
horizon 2
"#;

/// Run the front end on `SPEC` in `dir`, recording every file requested.
fn front(
    dir: &Path,
) -> (
    Result<ravel::check::Checked, Vec<ravel_syntax::diag::Diagnostic>>,
    Vec<ReadRequest>,
) {
    let log = RefCell::new(Vec::new());
    let reader = |r: &ReadRequest| {
        log.borrow_mut().push(r.clone());
        ravel_cli::read_request(r)
    };
    let res = ravel::front_end(SPEC, dir, &reader);
    (res, log.into_inner())
}

fn codes(res: &Result<ravel::check::Checked, Vec<ravel_syntax::diag::Diagnostic>>) -> Vec<Code> {
    match res {
        Ok(_) => Vec::new(),
        Err(d) => d.iter().map(|d| d.code).collect(),
    }
}

fn messages(res: &Result<ravel::check::Checked, Vec<ravel_syntax::diag::Diagnostic>>) -> String {
    match res {
        Ok(_) => String::new(),
        Err(d) => d
            .iter()
            .map(|d| format!("{} | {}", d.message, d.hint.clone().unwrap_or_default()))
            .collect::<Vec<_>>()
            .join("\n"),
    }
}

/// Every requested file lies inside `dir/models` (or is the controller itself).
fn assert_confined(dir: &Path, reqs: &[ReadRequest]) {
    let models = std::fs::canonicalize(dir.join("models")).expect("models folder");
    for r in reqs {
        let parent = r.path.parent().expect("parent");
        let real = std::fs::canonicalize(parent).unwrap_or_else(|_| parent.to_path_buf());
        assert!(
            real.starts_with(&models),
            "requested {} outside {}",
            r.path.display(),
            models.display()
        );
        if r.path.file_name().and_then(|n| n.to_str()) != Some("policy.onnx") {
            assert!(r.inside.is_some(), "external data read without confinement");
        }
    }
}

#[test]
fn the_honest_external_model_loads() {
    let dir = folder("honest");
    let (model, data) = external_model("policy.onnx.data");
    std::fs::write(dir.join("models/policy.onnx"), model.encode_to_vec()).expect("write");
    std::fs::write(dir.join("models/policy.onnx.data"), data).expect("write");
    let (res, reqs) = front(&dir);
    assert!(res.is_ok(), "{}", messages(&res));
    assert_eq!(reqs.len(), 2, "{reqs:?}");
    assert_confined(&dir, &reqs);
}

#[test]
fn locations_that_leave_the_folder_are_refused_unread() {
    for (k, loc) in [
        "../secret.data",
        "sub/../../secret.data",
        "..",
        "/etc/passwd",
        "/proc/self/environ",
        "/dev/zero",
        "C:/secret.data",
        "a\\..\\..\\secret.data",
        "",
        ".",
        "./",
    ]
    .iter()
    .enumerate()
    {
        let dir = folder(&format!("escape{k}"));
        let (mut model, data) = external_model("policy.onnx.data");
        relocate(&mut model, &[loc]);
        std::fs::write(dir.join("models/policy.onnx"), model.encode_to_vec()).expect("write");
        // the bait: a valid data file just outside the folder
        std::fs::write(dir.join("secret.data"), &data).expect("write");
        let (res, reqs) = front(&dir);
        assert_eq!(
            codes(&res),
            vec![Code::ExternalData],
            "{loc:?}: {}",
            messages(&res)
        );
        assert_eq!(
            reqs.len(),
            1,
            "{loc:?}: only the controller is read: {reqs:?}"
        );
        assert_confined(&dir, &reqs);
    }
}

#[cfg(unix)]
#[test]
fn a_symbolic_link_out_of_the_folder_is_refused() {
    let dir = folder("symlink");
    let (model, data) = external_model("policy.onnx.data");
    std::fs::write(dir.join("models/policy.onnx"), model.encode_to_vec()).expect("write");
    std::fs::write(dir.join("outside.data"), data).expect("write");
    std::os::unix::fs::symlink("../outside.data", dir.join("models/policy.onnx.data"))
        .expect("symlink");
    let (res, _) = front(&dir);
    assert_eq!(codes(&res), vec![Code::ExternalData], "{}", messages(&res));
    assert!(messages(&res).contains("outside the controller's folder"));
}

#[cfg(unix)]
fn mkfifo(path: &Path) {
    let ok = Command::new("mkfifo")
        .arg(path)
        .status()
        .expect("mkfifo runs")
        .success();
    assert!(ok, "mkfifo failed");
}

#[cfg(unix)]
#[test]
fn special_files_are_refused_without_blocking() {
    // a FIFO as the controller: opened non-blocking, refused, no hang
    let dir = folder("fifo_controller");
    mkfifo(&dir.join("models/policy.onnx"));
    let (res, _) = front(&dir);
    assert_eq!(codes(&res), vec![Code::ControllerUnreadable]);
    assert!(messages(&res).contains("not a regular file"));

    // a FIFO as external data
    let dir = folder("fifo_data");
    let (model, _) = external_model("policy.onnx.data");
    std::fs::write(dir.join("models/policy.onnx"), model.encode_to_vec()).expect("write");
    mkfifo(&dir.join("models/policy.onnx.data"));
    let (res, _) = front(&dir);
    assert_eq!(codes(&res), vec![Code::ExternalData], "{}", messages(&res));

    // a device (read forever by a naive reader) and a folder
    for target in ["/dev/zero", "/tmp"] {
        let dir = folder("device");
        std::os::unix::fs::symlink(target, dir.join("models/policy.onnx")).expect("symlink");
        let (res, _) = front(&dir);
        assert_eq!(codes(&res), vec![Code::ControllerUnreadable], "{target}");
    }
}

#[test]
fn one_file_under_many_spellings_is_read_once() {
    let dir = folder("spellings");
    let (mut model, data) = external_model("policy.onnx.data");
    relocate(
        &mut model,
        &[
            "./policy.onnx.data",
            "././policy.onnx.data",
            "policy.onnx.data",
            ".//policy.onnx.data",
        ],
    );
    std::fs::write(dir.join("models/policy.onnx"), model.encode_to_vec()).expect("write");
    std::fs::write(dir.join("models/policy.onnx.data"), data).expect("write");
    let (res, reqs) = front(&dir);
    assert!(res.is_ok(), "{}", messages(&res));
    let data_reads = reqs.iter().filter(|r| r.inside.is_some()).count();
    assert_eq!(data_reads, 1, "{reqs:?}");
}

#[test]
fn external_data_is_read_only_as_far_as_the_shapes_need() {
    let dir = folder("long_data");
    let (model, mut data) = external_model("policy.onnx.data");
    let needed = data.len() as u64;
    data.extend(std::iter::repeat_n(0u8, 1 << 20));
    std::fs::write(dir.join("models/policy.onnx"), model.encode_to_vec()).expect("write");
    std::fs::write(dir.join("models/policy.onnx.data"), data).expect("write");
    let (res, reqs) = front(&dir);
    assert!(res.is_ok(), "{}", messages(&res));
    let r = reqs.iter().find(|r| r.inside.is_some()).expect("data read");
    assert_eq!(r.max_bytes, needed);
}

#[test]
fn lengths_and_offsets_that_do_not_fit_are_refused_unread() {
    for (k, (key, value)) in [
        ("length", "18446744073709551615"),
        ("length", "7"),
        ("offset", "18446744073709551615"),
        ("offset", "-1"),
        ("offset", "1e9"),
        ("length", ""),
    ]
    .iter()
    .enumerate()
    {
        let dir = folder(&format!("length{k}"));
        let (mut model, data) = external_model("policy.onnx.data");
        let t = &mut model.graph.as_mut().expect("graph").initializer[0];
        t.external_data.retain(|e| e.key.as_deref() != Some(key));
        t.external_data.push(StringStringEntryProto {
            key: Some(key.to_string()),
            value: Some(value.to_string()),
        });
        std::fs::write(dir.join("models/policy.onnx"), model.encode_to_vec()).expect("write");
        std::fs::write(dir.join("models/policy.onnx.data"), data).expect("write");
        let (res, _) = front(&dir);
        assert_eq!(
            codes(&res),
            vec![Code::ExternalData],
            "{key} = {value}: {}",
            messages(&res)
        );
    }
}

#[test]
fn truncated_models_and_overflowing_shapes_are_refused() {
    let dir = folder("truncated");
    let (model, _) = external_model("policy.onnx.data");
    let mut g = GraphBuilder::new(2, Storage::RawF32);
    g.network(&net(), false);
    let (full, _) = g.finish(1);
    // without opset_import: what a copy cut just before it leaves
    let mut m = ModelProto::decode(full.as_slice()).expect("model");
    m.opset_import.clear();
    std::fs::write(dir.join("models/policy.onnx"), m.encode_to_vec()).expect("write");
    let (res, _) = front(&dir);
    assert_eq!(codes(&res), vec![Code::NotOnnx], "{}", messages(&res));
    // every prefix of the file is refused, none panics
    for cut in 0..full.len() {
        std::fs::write(dir.join("models/policy.onnx"), &full[..cut]).expect("write");
        let (res, _) = front(&dir);
        assert!(
            res.is_err(),
            "a prefix of {cut} of {} bytes was accepted",
            full.len()
        );
    }
    // dimensions whose product overflows
    let mut m = model;
    let t = &mut m.graph.as_mut().expect("graph").initializer[0];
    t.dims = vec![1 << 40, 1 << 40];
    std::fs::write(dir.join("models/policy.onnx"), m.encode_to_vec()).expect("write");
    let (res, reqs) = front(&dir);
    assert!(!codes(&res).is_empty());
    assert!(reqs.iter().all(|r| r.max_bytes <= 512 << 20));
}

#[test]
fn control_characters_in_names_are_escaped() {
    let dir = folder("names");
    let mut g = GraphBuilder::new(2, Storage::RawF32);
    g.network(&net(), false);
    g.unary("\u{1b}[2J\nverdict: VERIFIED\u{202e}");
    let (bytes, _) = g.finish(1);
    std::fs::write(dir.join("models/policy.onnx"), bytes).expect("write");
    let (res, _) = front(&dir);
    assert_eq!(codes(&res), vec![Code::UnsupportedOnnx]);
    let text = messages(&res);
    assert!(
        !text.chars().any(|c| c.is_control() || c == '\u{202e}'),
        "{text:?}"
    );
    assert!(text.contains("\\u{1b}"), "{text}");
}

/// Observation files of a `select` block are read from the spec's folder
/// only: `..`, absolute paths and (through the CLI's reader) links leaving
/// it are refused before anything is read.
#[test]
fn observation_files_stay_in_the_spec_folder() {
    use std::cell::RefCell;
    let asked: RefCell<Vec<ravel::ReadRequest>> = RefCell::new(Vec::new());
    let model = std::fs::read("models/lane_q.onnx").expect("model");
    let reader = |r: &ravel::ReadRequest| -> Result<Vec<u8>, ravel::ReadError> {
        asked.borrow_mut().push(r.clone());
        if r.path.extension().is_some_and(|e| e == "onnx") {
            Ok(model.clone())
        } else {
            Ok(b"0,0\n".to_vec())
        }
    };
    for path in ["../x.csv", "/etc/passwd", "a/../../x.csv", "C:x.csv"] {
        asked.borrow_mut().clear();
        let spec = format!(
            "network q {{ input s[2] output q[3] }}\nmodel \"m.onnx\"\nselect s {{ epsilon 0.1 observations \"{path}\" }}\n"
        );
        let r = ravel::front_end_task(&spec, std::path::Path::new("specs"), &reader, None);
        let d = r.expect_err(path);
        assert!(
            d.iter().any(|x| x.code.as_str() == "E0219"),
            "{path}: {d:?}"
        );
        assert!(
            asked
                .borrow()
                .iter()
                .all(|q| q.path.extension().is_some_and(|e| e == "onnx")),
            "{path}: a data file was requested"
        );
    }
    // a plain name is requested inside the spec's folder, confined to it
    asked.borrow_mut().clear();
    let spec = "network q { input s[2] output q[3] }\nmodel \"m.onnx\"\nselect s { epsilon 0.1 observations \"./o.csv\" }\n";
    assert!(ravel::front_end_task(spec, std::path::Path::new("specs"), &reader, None).is_ok());
    let csv: Vec<_> = asked
        .borrow()
        .iter()
        .filter(|q| q.path.extension().is_some_and(|e| e == "csv"))
        .cloned()
        .collect();
    assert_eq!(csv.len(), 1);
    assert_eq!(csv[0].path, std::path::Path::new("specs/o.csv"));
    assert_eq!(
        csv[0].inside.as_deref(),
        Some(std::path::Path::new("specs"))
    );
}

/// Reach-SDP's programs are bounded in size when the spec is checked (E0216
/// with the propagator's span), for closed loops and network specs alike: a
/// 2 → 150 → 150 controller is refused, a 2 → 100 → 100 one (beyond what
/// Clarabel alone took) is accepted.
#[test]
fn sdp_programs_beyond_the_size_limit_are_refused() {
    let closed_loop = format!("{SPEC}analysis {{\n    propagator reach_sdp\n}}\n");
    let network = r#"
network n {
    input  x[2]
    output y[2]
}
model "models/policy.onnx"
input X = box(x[0] in [-0.1, 0.1], x[1] in [-0.1, 0.1])
require r = { y[0] <= 10 }
analysis {
    propagator sdp
}
"#;
    for (spec, outputs) in [(closed_loop.as_str(), 1), (network, 2)] {
        for (width, refused) in [(150, true), (100, false)] {
            let dir = folder(&format!("sdp_size_{outputs}_{width}"));
            let mut g = GraphBuilder::new(2, Storage::RawF32);
            let mut rng = ravel_base::rng::Rng::new(5);
            let net = common::relu_network(&mut rng, &[2, width, width, outputs], 1.0, 0.1);
            g.network(&net, false);
            let (bytes, _) = g.finish(outputs);
            std::fs::write(dir.join("models/policy.onnx"), bytes).expect("write");
            let res = ravel::front_end_task(spec, &dir, &ravel_cli::read_request, None);
            let diags = res.err().unwrap_or_default();
            let got: Vec<Code> = diags.iter().map(|d| d.code).collect();
            let expected = if refused { vec![Code::Limit] } else { vec![] };
            assert_eq!(
                got,
                expected,
                "{width}: {:?}",
                diags.iter().map(|d| &d.message).collect::<Vec<_>>()
            );
            if refused {
                let d = &diags[0];
                assert!(
                    d.message.contains("beyond the limit of 300"),
                    "{}",
                    d.message
                );
                let span = d.span.expect("a span");
                let at = &spec[span.start..span.end];
                assert!(at.contains("sdp"), "span {at:?}");
            }
        }
    }
}
