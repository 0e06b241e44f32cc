//! The library on its own: a front end other than the command line runs a
//! spec end to end through `ravel::verify` (its own reader, its own clock)
//! and gets the report the command line prints, byte for byte.

use std::path::Path;
use std::process::Command;

use ravel::execute::{Control, Run, Verdict};
use ravel::{ReadError, ReadRequest};

/// A reader of whole files, as a front end other than the CLI would write
/// it (no FIFO or confinement checks: the test's files are known).
fn read(req: &ReadRequest) -> Result<Vec<u8>, ReadError> {
    let bytes = std::fs::read(&req.path)?;
    if req.whole && bytes.len() as u64 > req.max_bytes {
        return Err(ReadError::TooLarge {
            bytes: bytes.len() as u64,
            limit: req.max_bytes,
        });
    }
    Ok(bytes.into_iter().take(req.max_bytes as usize).collect())
}

/// `ravel::verify` on a spec, with no time limit.
fn verify(spec: &str) -> Run {
    let source = std::fs::read_to_string(spec).expect("spec");
    let dir = Path::new(spec).parent().expect("folder");
    ravel::verify(&source, dir, &read, None, &Control::unlimited()).expect("the spec checks")
}

/// What the command line prints for a spec, without timing.
fn cli_text(spec: &str) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_ravel"))
        .args(["verify", "--no-timing", spec])
        .output()
        .expect("runs");
    String::from_utf8(out.stdout).expect("UTF-8")
}

#[test]
fn the_library_driver_gives_the_command_lines_report() {
    for (spec, verdict) in [
        ("specs/double_integrator.ravel", Verdict::Verified),
        (
            "specs/double_integrator_falsified.ravel",
            Verdict::Falsified,
        ),
        ("specs/network/classifier_robust.ravel", Verdict::Verified),
    ] {
        let run = verify(spec);
        assert_eq!(run.verdict(), verdict, "{spec}");
        // the command line ends each report with a line break of its own
        let report = ravel::report::text(spec, &run, None) + "\n";
        assert_eq!(report, cli_text(spec), "{spec}");
    }
}

#[test]
fn front_end_diagnostics_reach_the_caller() {
    let source = "system s { horizn 5 }";
    let err = ravel::verify(source, Path::new("."), &read, None, &Control::unlimited())
        .expect_err("does not check");
    assert!(!err.is_empty());
}

/// Robust action selection reports its progress (issue 30: a long CARRL
/// run said nothing): one report per observation over every select block,
/// the count of those done before it, of the total, on one thread and on
/// several.
#[test]
fn action_selection_reports_progress_per_observation() {
    let spec = "specs/network/lane_carrl.ravel";
    let source = std::fs::read_to_string(spec).expect("spec");
    for threads in [1, 3] {
        let seen = std::sync::Mutex::new(Vec::new());
        let progress = |p: ravel::execute::Progress| {
            if p.phase == ravel::execute::Phase::Observations {
                seen.lock().expect("lock").push((p.done, p.total));
            }
        };
        let ctl = Control {
            elapsed: &|| 0.0,
            time_limit: None,
            progress: &progress,
            threads,
        };
        ravel::verify(&source, Path::new("specs/network"), &read, None, &ctl).expect("checks");
        let mut seen = seen.into_inner().expect("lock");
        seen.sort_unstable();
        // 3 inline observations and 6 from the file
        let expected: Vec<(usize, Option<usize>)> = (0..9).map(|k| (k, Some(9))).collect();
        assert_eq!(seen, expected, "{threads} threads");
    }
}

/// A network spec's uniform grid reports its cells as it bounds them: the
/// count started before each report, of the grid's cells, ending at the
/// last group or cell (grouped cells are reported a group at a time).
#[test]
fn a_network_grid_reports_its_cells() {
    let source = std::fs::read_to_string("specs/network/classifier_robust.ravel")
        .expect("spec")
        .replace("partitioner none", "partitioner uniform [6, 5]")
        // one analysis (a radius search runs one per scale it tries)
        .replace("radius eps for sector (max 8, tolerance 0.01)", "");
    assert!(source.contains("uniform [6, 5]") && !source.contains("radius eps"));
    let seen = std::sync::Mutex::new(Vec::new());
    let progress = |p: ravel::execute::Progress| {
        if p.phase == ravel::execute::Phase::Cells {
            seen.lock().expect("lock").push((p.done, p.total));
        }
    };
    let ctl = Control {
        elapsed: &|| 0.0,
        time_limit: None,
        progress: &progress,
        threads: 1,
    };
    ravel::verify(&source, Path::new("specs/network"), &read, None, &ctl).expect("checks");
    let seen = seen.into_inner().expect("lock");
    assert!(!seen.is_empty());
    assert!(seen.iter().all(|&(_, t)| t == Some(30)), "{seen:?}");
    assert_eq!(seen[0].0, 0);
    assert!(seen.windows(2).all(|w| w[0].0 < w[1].0), "{seen:?}");
    assert!(seen.last().is_some_and(|&(d, _)| d < 30), "{seen:?}");
    assert!(seen.len() > 1, "one report for the whole grid: {seen:?}");
}
