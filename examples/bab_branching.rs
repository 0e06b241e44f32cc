//! Measurement helper: branch and bound with each branching rule on the
//! same network specs, side by side (`cargo run --release --example
//! bab_branching -- [--time-limit S] [--jobs N] SPEC…`, `RULES=smear,widest`
//! to choose the rules). Each spec is run with each [`Branching`] rule; a
//! line per spec gives each rule's verdict, cells bounded and seconds, and
//! the totals close the table. The figures in
//! docs/language.md (branch and bound) were made with it on ACAS Xu.
use std::path::Path;
use std::time::Instant;

use ravel::check::Task;
use ravel::execute::{execute, Control, Run};
use ravel::ir::{Branching, Guide, Partitioner};
use ravel::lower::{lower, Plan};

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut take = |flag: &str| -> Option<f64> {
        let at = args.iter().position(|a| a == flag)?;
        let v = args.get(at + 1).and_then(|v| v.parse().ok());
        args.drain(at..(at + 2).min(args.len()));
        v
    };
    let limit = take("--time-limit").unwrap_or(60.0);
    let jobs = take("--jobs").map_or(1, |j| j as usize);
    let rules: Vec<Branching> = std::env::var("RULES")
        .unwrap_or_else(|_| "smear,widest,look_ahead".into())
        .split(',')
        .map(|r| match r {
            "smear" => Branching::Smear,
            "widest" => Branching::Widest,
            "look_ahead" => Branching::LookAhead,
            other => panic!("unknown rule {other}"),
        })
        .collect();
    let mut totals = vec![(0usize, 0usize, 0.0f64); rules.len()];
    println!("spec | per rule {rules:?}: verdict cells s");
    for spec in &args {
        let path = Path::new(spec);
        let source = std::fs::read_to_string(path).expect("a readable spec");
        let dir = path.parent().unwrap_or(Path::new("."));
        let task = match ravel::front_end_task(&source, dir, &ravel_cli::read_request, None) {
            Ok(t @ Task::Network(_)) => t,
            Ok(_) => panic!("{spec}: not a network spec"),
            Err(d) => panic!("{spec}: {d:?}"),
        };
        let mut line = spec.clone();
        for (r, rule) in rules.iter().enumerate() {
            let Plan::Network(mut plan) = lower(&task) else {
                unreachable!("a network task lowers to a network plan")
            };
            if !matches!(
                plan.partitioner,
                Partitioner::Guided {
                    guide: Guide::Bab,
                    ..
                }
            ) {
                panic!("{spec}: the spec's partitioner is not bab");
            }
            plan.branching = *rule;
            let start = Instant::now();
            let clock = move || start.elapsed().as_secs_f64();
            let mut ctl = Control::new(&clock);
            ctl.time_limit = Some(limit);
            ctl.threads = jobs;
            let run = execute(Plan::Network(plan), &ctl);
            let secs = start.elapsed().as_secs_f64();
            let Run::Network { outcome, .. } = run else {
                unreachable!("a network plan runs as a network")
            };
            let decided = outcome.verdict != ravel::execute::Verdict::Unsure;
            totals[r].0 += usize::from(decided);
            totals[r].1 += outcome.calls;
            totals[r].2 += secs;
            line += &format!(" | {:?} {} {:.2}", outcome.verdict, outcome.calls, secs);
        }
        println!("{line}");
    }
    for (rule, t) in rules.iter().zip(&totals) {
        println!(
            "{rule:?}: {} of {} decided, {} cells, {:.1} s",
            t.0,
            args.len(),
            t.1,
            t.2
        );
    }
}
