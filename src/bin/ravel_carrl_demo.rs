//! `ravel-carrl-demo`: does certified robust action selection (CARRL) hold up
//! where the nominal policy collapses? Episodes of the lane-keeping task of
//! `ravel_cli::demo`, controlled by the Q-network `models/lane_q.onnx`, under an
//! observation adversary of growing strength; the average return of the
//! nominal policy (the largest Q-value at the observation) and of CARRL at
//! several robustness radii (the largest certified lower bound over the
//! ε_rob-ball around the observation, bounded by ravel's CROWN).
//!
//! The adversary sees the true state `s` and moves the observation anywhere
//! in the ε_adv-box around it (the corners, the face centres and `s`
//! itself): it picks the observation whose chosen action has the lowest
//! Q-value at the true state.
//!
//! `ravel-carrl-demo [--episodes N] [--steps T] [--seed S] [--model PATH] [--svg FILE]`

use std::process::ExitCode;

use ravel::execute::network::choose;
use ravel::execute::Control;
use ravel::ir::{NetPropagator, Partitioner};
use ravel::lower::NetworkPlan;
use ravel_analysis::sets::Norm;
use ravel_analysis::shape::Shape;
use ravel_base::nn::Network;
use ravel_base::rng::Rng;
use ravel_cli::demo::step;

/// The adversary's strengths (the ε_adv-box's half-width on both inputs).
const ADVERSARY: [f64; 5] = [0.0, 0.1, 0.2, 0.3, 0.4];
/// CARRL's robustness radii.
const ROBUST: [f64; 3] = [0.05, 0.1, 0.2];

fn argmax(y: &[f64]) -> usize {
    (0..y.len()).fold(0, |b, j| if y[j] > y[b] { j } else { b })
}

struct Policy<'a> {
    plan: &'a NetworkPlan,
    /// `None`: nominal; `Some(ε_rob)`: CARRL.
    eps: Option<f64>,
}

impl Policy<'_> {
    fn act(&self, obs: &[f64]) -> usize {
        match self.eps {
            None => argmax(&self.plan.net.forward(obs)),
            Some(e) => {
                let ctl = Control {
                    elapsed: &|| 0.0,
                    time_limit: None,
                    progress: &|_| {},
                    threads: 1,
                };
                choose(self.plan, obs, &[e, e], Norm::LInf, &ctl).robust
            }
        }
    }
}

/// The average return over `episodes` episodes of `steps` steps.
fn average_return(
    net: &Network,
    policy: &Policy,
    adv: f64,
    episodes: usize,
    steps: usize,
    seed: u64,
) -> f64 {
    let mut rng = Rng::new(seed);
    let mut total = 0.0;
    for _ in 0..episodes {
        let mut s = [rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5)];
        for _ in 0..steps {
            let a = if adv == 0.0 {
                policy.act(&s)
            } else {
                // the observation whose action is worst at the true state
                let q = net.forward(&s);
                let mut best: Option<(f64, usize)> = None;
                for dx in [-1.0, 0.0, 1.0] {
                    for dv in [-1.0, 0.0, 1.0] {
                        let obs = [s[0] + dx * adv, s[1] + dv * adv];
                        let a = policy.act(&obs);
                        if best.is_none_or(|b| q[a] < b.0) {
                            best = Some((q[a], a));
                        }
                    }
                }
                best.map_or(0, |b| b.1)
            };
            let (next, r, done) = step(s, a);
            total += r;
            s = next;
            if done {
                break;
            }
        }
    }
    total / episodes as f64
}

fn svg(rows: &[(String, Vec<f64>)]) -> String {
    let (w, h, m) = (560.0, 360.0, 50.0);
    let lo = rows
        .iter()
        .flat_map(|r| r.1.iter())
        .fold(f64::INFINITY, |a, v| a.min(*v));
    let hi = rows
        .iter()
        .flat_map(|r| r.1.iter())
        .fold(f64::NEG_INFINITY, |a, v| a.max(*v));
    let (lo, hi) = (lo.min(0.0), hi.max(lo + 1.0));
    let x = |k: usize| m + (w - 2.0 * m) * k as f64 / (ADVERSARY.len() - 1) as f64;
    let y = |v: f64| h - m - (h - 2.0 * m) * (v - lo) / (hi - lo);
    let colours = ["#000000", "#1f77b4", "#2ca02c", "#d62728"];
    let mut s = format!("<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"{w}\" height=\"{h}\" fill=\"white\"/>\n");
    s += &format!("<line x1=\"{m}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"black\"/>\n<line x1=\"{m}\" y1=\"{m}\" x2=\"{m}\" y2=\"{}\" stroke=\"black\"/>\n", h - m, w - m, h - m, h - m);
    for (k, e) in ADVERSARY.iter().enumerate() {
        s += &format!(
            "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{e}</text>\n",
            x(k),
            h - m + 16.0
        );
    }
    s += &format!(
        "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">adversary ε_adv</text>\n",
        w / 2.0,
        h - 12.0
    );
    s += &format!("<text x=\"{}\" y=\"{}\" text-anchor=\"end\">{hi:.1}</text>\n<text x=\"{}\" y=\"{}\" text-anchor=\"end\">{lo:.1}</text>\n", m - 4.0, m + 4.0, m - 4.0, h - m);
    s += &format!("<text x=\"14\" y=\"{}\" transform=\"rotate(-90 14 {})\" text-anchor=\"middle\">average return</text>\n", h / 2.0, h / 2.0);
    for (i, (name, vals)) in rows.iter().enumerate() {
        let c = colours[i % colours.len()];
        let pts: Vec<String> = vals
            .iter()
            .enumerate()
            .map(|(k, v)| format!("{:.1},{:.1}", x(k), y(*v)))
            .collect();
        s += &format!(
            "<polyline points=\"{}\" fill=\"none\" stroke=\"{c}\" stroke-width=\"2\"/>\n",
            pts.join(" ")
        );
        s += &format!(
            "<text x=\"{}\" y=\"{}\" fill=\"{c}\">{name}</text>\n",
            w - m - 140.0,
            m + 14.0 * i as f64
        );
    }
    s + "</svg>\n"
}

fn main() -> ExitCode {
    let mut episodes = 100usize;
    let mut steps = 100usize;
    let mut seed = 0u64;
    let mut model = "models/lane_q.onnx".to_string();
    let mut svg_file: Option<String> = None;
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let v = it.next();
        let ok = match (a.as_str(), v) {
            ("--episodes", Some(v)) => v.parse().map(|n| episodes = n).is_ok(),
            ("--steps", Some(v)) => v.parse().map(|n| steps = n).is_ok(),
            ("--seed", Some(v)) => v.parse().map(|n| seed = n).is_ok(),
            ("--model", Some(v)) => {
                model = v.clone();
                true
            }
            ("--svg", Some(v)) => {
                svg_file = Some(v.clone());
                true
            }
            _ => false,
        };
        if !ok || episodes == 0 {
            eprintln!("usage: ravel-carrl-demo [--episodes N ≥ 1] [--steps T] [--seed S] [--model PATH] [--svg FILE]");
            return ExitCode::from(2);
        }
    }
    let bytes = match std::fs::read(&model) {
        Ok(b) => b,
        Err(e) => {
            eprintln!("error: cannot read `{model}`: {e}");
            return ExitCode::from(2);
        }
    };
    let net = match ravel::onnx::load(&bytes, &ravel::onnx::ExternalFiles::new()) {
        Ok(c) if c.inputs == 2 && c.outputs == 3 => c.net,
        Ok(_) => {
            eprintln!("error: `{model}` is not a Q-network with 2 inputs and 3 actions");
            return ExitCode::from(2);
        }
        Err(e) => {
            eprintln!("error: `{model}`: {}", e.message);
            return ExitCode::from(2);
        }
    };
    let plan = NetworkPlan {
        name: "lane".into(),
        input_name: "s".into(),
        output_name: "q".into(),
        model_path: model.clone(),
        model_sha256: String::new(),
        model_resolved: model.clone(),
        network_summary: String::new(),
        net: net.clone(),
        input: None,
        input_set_name: String::new(),
        selects: Vec::new(),
        properties: Vec::new(),
        radii: Vec::new(),
        propagator: NetPropagator::Crown,
        partitioner: Partitioner::Uniform(vec![1, 1]),
        shape: Shape::Box,
        samples: 0,
        seed: 0,
        slope_steps: 0,
        branching: Default::default(),
        phases: Default::default(),
    };
    let mut rows: Vec<(String, Vec<f64>)> = Vec::new();
    let policies: Vec<(String, Option<f64>)> = std::iter::once(("nominal".to_string(), None))
        .chain(
            ROBUST
                .iter()
                .map(|e| (format!("CARRL ε_rob = {e}"), Some(*e))),
        )
        .collect();
    for (name, eps) in &policies {
        let p = Policy {
            plan: &plan,
            eps: *eps,
        };
        let vals = ADVERSARY
            .iter()
            .map(|adv| average_return(&net, &p, *adv, episodes, steps, seed))
            .collect();
        rows.push((name.clone(), vals));
    }
    println!(
        "lane keeping, {episodes} episodes of at most {steps} steps (seed {seed}); average return (higher is better)"
    );
    print!("{:<20}", "ε_adv");
    for a in ADVERSARY {
        print!("{a:>9}");
    }
    println!();
    for (name, vals) in &rows {
        print!("{name:<20}");
        for v in vals {
            print!("{v:>9.2}");
        }
        println!();
    }
    if let Some(f) = svg_file {
        if let Err(e) = std::fs::write(&f, svg(&rows)) {
            eprintln!("error: cannot write `{f}`: {e}");
            return ExitCode::from(2);
        }
    }
    ExitCode::SUCCESS
}
