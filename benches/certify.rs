//! Certificates against analysis (`cargo bench --bench certify`): for every
//! shipped spec whose certificate is checkable, the analysis time (`execute`
//! as the CLI runs it, Monte Carlo included), the time to write the
//! certificate, its size, and the time `certify` spends on it (JSON parsing
//! and [`ravel_certify::check`]; the front end that both commands run is
//! left out). Each time is the median of repeated runs (at least three,
//! until half a second has passed; a run over five seconds is not repeated).

use std::path::Path;
use std::time::Instant;

fn median(mut f: impl FnMut()) -> f64 {
    let mut times = Vec::new();
    let start = Instant::now();
    while times.len() < 3 || (start.elapsed().as_secs_f64() < 0.5 && times.len() < 200) {
        let t = Instant::now();
        f();
        times.push(t.elapsed().as_secs_f64());
        if times[0] > 5.0 {
            break;
        }
    }
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

fn ms(s: f64) -> String {
    if s < 0.01 {
        format!("{:.2} ms", s * 1e3)
    } else {
        format!("{:.1} ms", s * 1e3)
    }
}

fn main() {
    let filter = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    let mut specs: Vec<_> = std::fs::read_dir("specs")
        .expect("specs folder")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "ravel"))
        .collect();
    specs.sort();
    println!("| spec | propagator | cells × steps | analysis | write | size | certify | certify / analysis |");
    println!("|---|---|---|---|---|---|---|---|");
    for path in specs {
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        if filter.as_ref().is_some_and(|f| !name.contains(f.as_str())) {
            continue;
        }
        let source = std::fs::read_to_string(&path).expect("spec");
        let dir = path.parent().unwrap_or(Path::new("."));
        let Ok(checked) = ravel::front_end(&source, dir, &ravel_cli::read_request) else {
            continue;
        };
        let plan = ravel::lower::lower_system(&checked);
        let mut outcome = None;
        let analysis = median(|| {
            outcome = Some(ravel::execute::execute_system(
                &plan,
                &ravel::execute::Control::unlimited(),
            ))
        });
        let outcome = outcome.expect("ran");
        let id = ravel::certificate_writer::Identity {
            spec_path: path.display().to_string(),
            spec_sha256: ravel::check::sha256_hex(source.as_bytes()),
        };
        let mut text = String::new();
        let write = median(|| {
            let cert = ravel::certificate_writer::build_system(&plan, &outcome, &id);
            text = serde_json::to_string(&cert).unwrap_or_default();
        });
        let mut report = None;
        let check = median(|| {
            let cert: serde_json::Value = serde_json::from_str(&text).expect("json");
            report = Some(ravel_certify::check(&cert, plan.closed_loop.net()));
        });
        let report = report.expect("ran");
        if report.answer != ravel_certify::Answer::Valid || report.cells == 0 {
            continue;
        }
        println!(
            "| {name} | {} | {} × {} | {} | {} | {} KiB | {} | {:.2} |",
            plan.propagator.name(),
            report.cells,
            report.steps,
            ms(analysis),
            ms(write),
            text.len().div_ceil(1024),
            ms(check),
            check / analysis
        );
    }
}
