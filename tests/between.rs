//! Linear plants in continuous time, between the sampling instants, against
//! an independent dense simulation: random damped oscillators sampled
//! coarsely, whose trajectories swing through a band between two instants,
//! with the band as an avoid set or as an "eventually" goal. Every answer
//! is checked with this file's own fourth-order Runge–Kutta integration of
//! `ẋ = A x + B u` (the control held over each period, as the zero-order
//! hold holds it), at 512 points per period:
//!
//! * an avoid set FALSIFIED between two instants: the recorded trajectory
//!   enters the band in the period it names (the confirming piece is at
//!   least 1/128 of the period, so the dense points see it);
//! * an eventually goal FALSIFIED: the recorded trajectory is never in the
//!   band at an instant of the window or in a period that meets it;
//! * VERIFIED: no simulated trajectory from X0 is in the avoided band in
//!   the window, between the instants included; every one is in the goal
//!   band at some instant of its window.
//!
//! Half the cases have process and sensor noise (the process noise
//! arrives at the next instant, after the period's flow). The cases are
//! seeded; the test also requires that each kind of answer occurs, so
//! that it cannot pass by checking nothing.

use ravel::execute::{Control, Trajectory, Verdict};
use ravel::ir::Window;
use ravel::lower::{PropertyKind, SystemPlan};
use ravel_base::rng::Rng;

/// Dense points per control period.
const DENSE: usize = 512;

/// Runge–Kutta steps between two dense points.
const SUBSTEPS: usize = 8;

/// The states at `DENSE − 1` points strictly inside a period of length
/// `dt`, from `x` with the control `u` held: `ẋ = A x + B u`.
fn dense(a: &[[f64; 2]; 2], b: &[f64; 2], x: &[f64], u: f64, dt: f64) -> Vec<[f64; 2]> {
    let f = |y: [f64; 2]| -> [f64; 2] {
        [
            a[0][0] * y[0] + a[0][1] * y[1] + b[0] * u,
            a[1][0] * y[0] + a[1][1] * y[1] + b[1] * u,
        ]
    };
    let h = dt / (DENSE * SUBSTEPS) as f64;
    let mut y = [x[0], x[1]];
    let mut out = Vec::with_capacity(DENSE);
    for _ in 1..DENSE {
        for _ in 0..SUBSTEPS {
            let k1 = f(y);
            let k2 = f([y[0] + 0.5 * h * k1[0], y[1] + 0.5 * h * k1[1]]);
            let k3 = f([y[0] + 0.5 * h * k2[0], y[1] + 0.5 * h * k2[1]]);
            let k4 = f([y[0] + h * k3[0], y[1] + h * k3[1]]);
            for i in 0..2 {
                y[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
        out.push(y);
    }
    out
}

/// One random case: the spec's text and what this file needs to simulate it.
struct Case {
    text: String,
    a: [[f64; 2]; 2],
    b: [f64; 2],
    dt: f64,
    band: (f64, f64),
}

fn case(seed: u64, goal: bool) -> Case {
    let mut rng = Rng::new(seed);
    let w = rng.uniform(1.0, 6.0);
    let damping = rng.uniform(0.0, 0.4);
    let dt = rng.uniform(0.5, 1.0);
    let beta = rng.uniform(0.0, 0.3);
    let r = rng.uniform(0.8, 1.2);
    let lo = rng.uniform(-0.9, 1.4);
    let band = (lo, lo + rng.uniform(0.05, 0.3));
    let a = [[0.0, w], [-w, -damping]];
    let b = [0.0, beta];
    let model = concat!(env!("CARGO_MANIFEST_DIR"), "/models/double_integrator.onnx");
    let property = if goal {
        let t0 = [0.0, dt][rng.below(2)];
        format!(
            "goal band = {{ x[0] >= {}, x[0] <= {} }} eventually during [{t0}, {}]",
            band.0,
            band.1,
            4.0 * dt
        )
    } else {
        format!(
            "avoid band = {{ x[0] >= {}, x[0] <= {} }} at steps [0, 4]",
            band.0, band.1
        )
    };
    // half the cases (seeds 2 and 3 mod 4: avoid sets and goals alike) have
    // process and sensor noise (the process noise arrives at the instants,
    // after each period's flow)
    let noise = if seed % 4 >= 2 {
        " w in box([-0.01, 0.01], [-0.01, 0.01])\n v in box([-0.02, 0.02], [-0.02, 0.02])\n"
    } else {
        ""
    };
    let text = format!(
        "system s {{\n state x[2]\n control u[1]\n time continuous dt {dt}\n \
         A = [[0, {w}], [{}, {}]]\n B = [[0], [{beta}]]\n u in box([-1, 1])\n{noise}}}\n\
         controller \"{model}\"\n\
         initial X0 = box(x[0] in [{r}, {}], x[1] in [0, 0.02])\n\
         {property}\n\
         horizon 4\n\
         analysis {{\n samples 100\n seed {seed}\n}}\n",
        -w,
        -damping,
        r + 0.02
    );
    Case {
        text,
        a,
        b,
        dt,
        band,
    }
}

fn run(c: &Case) -> (SystemPlan, ravel::execute::SystemOutcome) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let checked =
        ravel::front_end(&c.text, dir, &ravel_cli::read_request).expect("a valid generated spec");
    let plan = ravel::lower::lower_system(&checked);
    let out = ravel::execute::execute_system(&plan, &Control::unlimited());
    (plan, out)
}

/// How far `x` lies inside the band (negative: outside).
fn inside(band: (f64, f64), x: &[f64]) -> f64 {
    (x[0] - band.0).min(band.1 - x[0])
}

/// The deepest point of a trajectory in the band: at the window's instants
/// and, densely, in its periods.
fn deepest(c: &Case, tr: &Trajectory, window: &Window) -> f64 {
    let mut best = f64::NEG_INFINITY;
    for t in window.steps.0..=window.steps.1 {
        best = best.max(inside(c.band, &tr.states[t]));
    }
    for p in window.periods.0..=window.periods.1 {
        for y in dense(&c.a, &c.b, &tr.states[p - 1], tr.controls[p - 1][0], c.dt) {
            best = best.max(inside(c.band, &y));
        }
    }
    best
}

/// A trajectory of the plan from `x0` with noise drawn from its boxes
/// (an end or a uniform value per coordinate and step), controls from the
/// loop's own simulation.
fn trajectory(plan: &SystemPlan, x0: Vec<f64>, rng: &mut Rng) -> Trajectory {
    let cl = &plan.closed_loop;
    let mut draw = |b: &ravel_analysis::sets::IBox| -> Vec<f64> {
        (0..b.dim())
            .map(|i| match rng.below(3) {
                0 => b.lo[i],
                1 => b.hi[i],
                _ => rng.uniform(b.lo[i], b.hi[i]),
            })
            .collect()
    };
    let mut tr = Trajectory {
        states: vec![x0],
        controls: Vec::new(),
        process_noise: Vec::new(),
        sensor_noise: Vec::new(),
    };
    for t in 0..plan.horizon {
        let x = tr.states[t].clone();
        let (w, v) = (draw(cl.w()), draw(cl.v()));
        let (u, next) = cl.simulate(t, &x, &w, &v);
        tr.controls.push(u);
        tr.process_noise.push(w);
        tr.sensor_noise.push(v);
        tr.states.push(next);
    }
    tr
}

#[test]
fn answers_between_the_instants_agree_with_a_dense_simulation() {
    // (falsified between, eventually falsified, verified)
    let mut seen = [0usize; 3];
    for seed in 0..48u64 {
        let goal = seed % 2 == 1;
        let c = case(seed, goal);
        let (plan, out) = run(&c);
        let prop = &plan.properties[0];
        let r = &out.properties[0];
        let window = prop.window();
        match (r.status, &prop.kind) {
            (Verdict::Falsified, PropertyKind::Avoid { .. }) => {
                let tr = r.counterexample.as_ref().expect("a counterexample");
                let depth = if r.between {
                    seen[0] += 1;
                    assert!(window.has_period(r.step), "seed {seed}");
                    dense(
                        &c.a,
                        &c.b,
                        &tr.states[r.step - 1],
                        tr.controls[r.step - 1][0],
                        c.dt,
                    )
                    .iter()
                    .map(|y| inside(c.band, y))
                    .fold(f64::NEG_INFINITY, f64::max)
                } else {
                    inside(c.band, &tr.states[r.step])
                };
                assert!(depth > 0.0, "seed {seed}: FALSIFIED, yet {depth} inside");
            }
            (Verdict::Falsified, PropertyKind::Goal { .. }) => {
                seen[1] += 1;
                let tr = r.counterexample.as_ref().expect("a counterexample");
                let depth = deepest(&c, tr, &window);
                assert!(depth < 1e-9, "seed {seed}: FALSIFIED, yet {depth} inside");
            }
            (Verdict::Verified, PropertyKind::Avoid { .. }) => {
                seen[2] += 1;
                let mut rng = Rng::new(1000 + seed);
                for _ in 0..20 {
                    let b = plan.initial.bbox();
                    let x0 = vec![rng.uniform(b.lo[0], b.hi[0]), rng.uniform(b.lo[1], b.hi[1])];
                    let tr = trajectory(&plan, x0, &mut rng);
                    let depth = deepest(&c, &tr, &window);
                    assert!(depth <= 1e-9, "seed {seed}: VERIFIED, yet {depth} inside");
                }
            }
            (Verdict::Verified, PropertyKind::Goal { .. }) => {
                let mut rng = Rng::new(1000 + seed);
                for _ in 0..20 {
                    let b = plan.initial.bbox();
                    let x0 = vec![rng.uniform(b.lo[0], b.hi[0]), rng.uniform(b.lo[1], b.hi[1])];
                    let tr = trajectory(&plan, x0, &mut rng);
                    let reached = (window.steps.0..=window.steps.1)
                        .map(|t| inside(c.band, &tr.states[t]))
                        .fold(f64::NEG_INFINITY, f64::max);
                    assert!(
                        reached >= -1e-9,
                        "seed {seed}: VERIFIED, yet never in the band"
                    );
                }
            }
            (Verdict::Unsure, _) => {}
        }
    }
    assert!(
        seen.iter().all(|&k| k >= 2),
        "each kind of answer occurs: {seen:?}"
    );
}
