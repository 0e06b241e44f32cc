//! `ravel-corpus`: regenerate the malformed-input corpus under `tests/corpus/`.
//!
//! `tests/corpus/specs/*.ravel` are specs that must be refused (exit code 2)
//! with at least the diagnostic codes in their `// expect:` header (`any`:
//! some diagnostic); `tests/corpus/onnx/*.onnx` are controllers that must be
//! refused, with the code listed in `tests/corpus/onnx/EXPECT`. The
//! `tests/corpus.rs` test runs the `ravel` binary on each, with a time and
//! memory limit. Deterministic; run from the repository root:
//!
//! ```text
//! cargo run --release --bin ravel-corpus
//! ```

use std::fs;
use std::path::Path;

use nalgebra::{DMatrix, DVector};
use prost::Message;
use ravel::onnx::build::{float_attr, int_attr, GraphBuilder, Storage};
use ravel::onnx::proto::{
    AttributeProto, GraphProto, ModelProto, NodeProto, StringStringEntryProto, TensorProto,
};
use ravel_base::nn::{Activation, Layer, Network};

/// The spec every mutation starts from: floats are written with a `.` and
/// integers without, so a literal's kind is known from its text.
const BASE: &str = r#"system corpus {
    state   x[2]
    control u[1]
    A = [[1.0, 1.0], [0.0, 1.0]]
    B = [[0.5], [1.0]]
    c = [0.0, 0.0]
    w in box([-0.01, 0.01], [-0.01, 0.01])
    u in box([-1.0, 1.0])
}
controller "../../../models/double_integrator.onnx"
initial X0 = box(x[0] in [2.5, 3.0], x[1] in [-0.25, 0.25])
goal    G  = box(x[0] in [-1.5, 2.0], x[1] in [-1.5, 0.5])
avoid   overshoot = { 1.0 x[0] + 0.5 x[1] <= -2.0 } at steps [1, 5]
horizon 5
analysis {
    propagator  reach_lp
    partitioner gsg (calls 8.0, min_size 0.1)
    boundary    polytope [[1.0, 1.0], [1.0, -1.0]]
    samples     100
    seed        0
}
"#;

/// The numeric literals of `BASE`: (start, end, is_float).
fn literals(text: &str) -> Vec<(usize, usize, bool)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let starts =
            b[i].is_ascii_digit() || (b[i] == b'-' && i + 1 < b.len() && b[i + 1].is_ascii_digit());
        let in_word = i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_');
        if starts && !in_word {
            let mut j = i + 1;
            while j < b.len() && (b[j].is_ascii_digit() || b[j] == b'.') {
                j += 1;
            }
            out.push((i, j, text[i..j].contains('.')));
            i = j;
        } else {
            i += 1;
        }
    }
    out
}

fn spec(dir: &Path, name: &str, expect: &str, why: &str, text: &str) {
    let body = format!("// expect: {expect}\n// {why}\n{text}");
    fs::write(dir.join(format!("{name}.ravel")), body).expect("write spec");
}

fn specs(dir: &Path) -> usize {
    let _ = fs::remove_dir_all(dir);
    fs::create_dir_all(dir).expect("folder");
    let mut count = 0;
    let mut put = |name: &str, expect: &str, why: &str, text: &str| {
        spec(dir, name, expect, why, text);
        count += 1;
    };
    // every literal replaced by an overflowing, a huge and a huge negative value
    for (k, (s, e, float)) in literals(BASE).into_iter().enumerate() {
        let (before, after) = (&BASE[..s], &BASE[e..]);
        if float {
            put(
                &format!("literal_{k:02}_overflow"),
                "E0205",
                &format!("literal {k} (`{}`) overflows f64", &BASE[s..e]),
                &format!("{before}1e400{after}"),
            );
            put(
                &format!("literal_{k:02}_huge"),
                "E0216",
                &format!("literal {k} (`{}`) is beyond ±1e15", &BASE[s..e]),
                &format!("{before}1e300{after}"),
            );
            // `+ -c x[i]` is not a term the grammar accepts
            let after_plus = before.ends_with("+ ");
            put(
                &format!("literal_{k:02}_huge_negative"),
                if after_plus { "E0001" } else { "E0216" },
                &format!("literal {k} (`{}`) is beyond ±1e15", &BASE[s..e]),
                &format!("{before}-3.5e17{after}"),
            );
        } else {
            put(
                &format!("literal_{k:02}_too_wide"),
                "E0002",
                &format!("integer {k} (`{}`) does not fit in 64 bits", &BASE[s..e]),
                &format!("{before}18446744073709551616{after}"),
            );
            put(
                &format!("literal_{k:02}_float"),
                "any",
                &format!("integer {k} (`{}`) written as a float", &BASE[s..e]),
                &format!("{before}2.5{after}"),
            );
        }
    }
    // truncations
    for k in 1..=12 {
        let cut = BASE.len() * k / 13;
        let cut = (0..=cut)
            .rev()
            .find(|c| BASE.is_char_boundary(*c))
            .unwrap_or(0);
        put(
            &format!("truncated_{k:02}"),
            "any",
            &format!("the base spec cut after {cut} bytes"),
            &BASE[..cut],
        );
    }
    let sub = |from: &str, to: &str| {
        assert!(BASE.contains(from), "{from}");
        BASE.replacen(from, to, 1)
    };
    let targeted: Vec<(&str, &str, &str, String)> = vec![
        ("empty", "E0103", "an empty file", String::new()),
        (
            "only_comment",
            "E0103",
            "nothing but a comment",
            "// nothing\n".into(),
        ),
        (
            "only_bom",
            "E0103",
            "a byte-order mark alone",
            "\u{feff}".into(),
        ),
        (
            "bom_inside",
            "E0001",
            "a byte-order mark inside the text",
            sub("horizon 5", "horizon \u{feff}5"),
        ),
        (
            "non_ascii_name",
            "E0001",
            "a non-ASCII letter in a name",
            sub("state   x[2]", "state   xé[2]"),
        ),
        (
            "escape_in_name",
            "E0001",
            "an escape character in a name",
            sub("goal    G ", "goal    G\u{1b}[2J "),
        ),
        (
            "nul_byte",
            "E0001",
            "a NUL byte",
            sub("horizon 5", "horizon\u{0} 5"),
        ),
        (
            "cr_only_error",
            "E0001",
            "CR line endings and a missing bracket",
            sub("B = [[0.5], [1.0]]", "B = [[0.5], [1.0]").replace('\n', "\r"),
        ),
        (
            "unterminated_string",
            "E0001",
            "a string without its closing quote",
            sub("double_integrator.onnx\"", "double_integrator.onnx"),
        ),
        (
            "unterminated_comment",
            "E0001",
            "a block comment that never ends",
            sub("horizon 5", "/* horizon 5"),
        ),
        (
            "nan_literal",
            "E0001",
            "`nan` is not a number literal",
            sub("[2.5, 3.0]", "[nan, 3.0]"),
        ),
        (
            "inf_literal",
            "E0001",
            "`inf` is not a number literal",
            sub("[2.5, 3.0]", "[2.5, inf]"),
        ),
        (
            "double_minus",
            "E0001",
            "a doubled sign",
            sub("[-1.0, 1.0]", "[--1.0, 1.0]"),
        ),
        (
            "bare_exponent",
            "E0001",
            "an exponent without digits",
            sub("[2.5, 3.0]", "[2.5e, 3.0]"),
        ),
        (
            "state_zero",
            "E0208",
            "a state of dimension 0",
            sub("x[2]", "x[0]"),
        ),
        (
            "state_huge",
            "E0216",
            "a state of dimension 100000",
            sub("x[2]", "x[100000]"),
        ),
        (
            "control_huge",
            "E0216",
            "a control of dimension 5000",
            sub("u[1]", "u[5000]"),
        ),
        (
            "eye_huge",
            "E0216",
            "eye(100000): 80 GB if allocated",
            sub("A = [[1.0, 1.0], [0.0, 1.0]]", "A = eye(100000)"),
        ),
        (
            "zeros_huge",
            "E0216",
            "zeros(100000, 100000): 80 GB if allocated",
            sub("B = [[0.5], [1.0]]", "B = zeros(100000, 100000)"),
        ),
        (
            "zeros_zero",
            "E0208",
            "zeros with a zero size",
            sub("B = [[0.5], [1.0]]", "B = zeros(2, 0)"),
        ),
        (
            "observation_huge",
            "E0216",
            "an observation matrix with 5000 columns",
            sub("c = [0.0, 0.0]", "C = zeros(2, 5000)"),
        ),
        (
            "horizon_zero",
            "E0204",
            "a horizon of 0",
            sub("horizon 5", "horizon 0"),
        ),
        (
            "horizon_huge",
            "E0204",
            "a horizon beyond 10000",
            sub("horizon 5", "horizon 100000"),
        ),
        (
            "samples_huge",
            "E0216",
            "more than 1000000 samples",
            sub("samples     100", "samples     10000000"),
        ),
        (
            "slopes_huge",
            "E0216",
            "more than 100 slope-optimisation steps",
            sub(
                "samples     100",
                "samples     100\n    optimise_slopes 1000000",
            ),
        ),
        (
            "slopes_without_back_substitution",
            "E0220",
            "optimised slopes with interval arithmetic",
            sub("samples     100", "samples     100\n    optimise_slopes 5")
                .replace("propagator  reach_lp", "propagator  ibp_separate"),
        ),
        (
            "simulated_steps",
            "E0216",
            "samples × horizon beyond 5e7",
            sub("samples     100", "samples     1000000").replace("horizon 5", "horizon 100"),
        ),
        (
            "grid_huge",
            "E0216",
            "a grid of 1e6 cells",
            sub(
                "partitioner gsg (calls 8.0, min_size 0.1)",
                "partitioner uniform [1000, 1000]",
            ),
        ),
        (
            "grid_overflow",
            "E0216",
            "a grid whose cell count overflows 64 bits",
            sub(
                "partitioner gsg (calls 8.0, min_size 0.1)",
                "partitioner uniform [4294967296, 4294967296]",
            ),
        ),
        (
            "grid_times_horizon",
            "E0216",
            "cells × steps beyond the stored-bounds limit",
            sub(
                "partitioner gsg (calls 8.0, min_size 0.1)",
                "partitioner uniform [300, 300]",
            )
            .replace("horizon 5", "horizon 1000"),
        ),
        (
            "grid_zero",
            "E0207",
            "a grid with a zero count",
            sub(
                "partitioner gsg (calls 8.0, min_size 0.1)",
                "partitioner uniform [0, 1]",
            ),
        ),
        (
            "calls_huge",
            "E0214",
            "a call budget beyond 100000",
            sub("calls 8.0", "calls 1000000.0"),
        ),
        (
            "calls_fraction",
            "E0214",
            "a fractional call budget",
            sub("calls 8.0", "calls 8.5"),
        ),
        (
            "calls_times_horizon",
            "E0216",
            "calls × steps beyond the stored-bounds limit",
            sub("calls 8.0", "calls 100000.0").replace("horizon 5", "horizon 1000"),
        ),
        (
            "min_size_underflow",
            "E0214",
            "a min_size that underflows to 0",
            sub("min_size 0.1", "min_size 1e-400"),
        ),
        (
            "time_budget_huge",
            "E0216",
            "a time budget beyond 1e15 seconds",
            sub("min_size 0.1", "min_size 0.1, time 1e300"),
        ),
        (
            "directions_huge",
            "E0211",
            "a million evenly spread directions",
            sub(
                "boundary    polytope [[1.0, 1.0], [1.0, -1.0]]",
                "boundary    polytope 1000000",
            ),
        ),
        (
            "dt_huge",
            "E0216",
            "a time step of 1e300",
            sub(
                "u in box([-1.0, 1.0])",
                "u in box([-1.0, 1.0])\n    time continuous dt 1e300",
            ),
        ),
        (
            "dt_zero",
            "E0213",
            "a time step of 0",
            sub(
                "u in box([-1.0, 1.0])",
                "u in box([-1.0, 1.0])\n    time continuous dt 0.0",
            ),
        ),
        (
            "dt_large_expm_overflow",
            "E0213",
            "e^(A dt) overflows",
            sub(
                "A = [[1.0, 1.0], [0.0, 1.0]]",
                "A = [[800.0, 0.0], [0.0, 1.0]]",
            )
            .replace(
                "u in box([-1.0, 1.0])",
                "u in box([-1.0, 1.0])\n    time continuous dt 1.0",
            ),
        ),
        (
            "ball_radius_huge",
            "E0216",
            "a ball of radius 1e300",
            sub(
                "initial X0 = box(x[0] in [2.5, 3.0], x[1] in [-0.25, 0.25])",
                "initial X0 = ball(center [2.75, 0.0], radius [1e300, 0.25], norm 2)",
            ),
        ),
        (
            "ball_negative_radius",
            "E0210",
            "a negative radius",
            sub(
                "initial X0 = box(x[0] in [2.5, 3.0], x[1] in [-0.25, 0.25])",
                "initial X0 = ball(center [2.75, 0.0], radius [-0.25, 0.25], norm 2)",
            ),
        ),
        (
            "initial_unbounded",
            "E0210",
            "an unbounded initial polytope",
            sub(
                "initial X0 = box(x[0] in [2.5, 3.0], x[1] in [-0.25, 0.25])",
                "initial X0 = { x[0] <= 3.0, x[1] <= 0.25 }",
            ),
        ),
        (
            "initial_empty",
            "E0210",
            "an empty initial polytope",
            sub(
                "initial X0 = box(x[0] in [2.5, 3.0], x[1] in [-0.25, 0.25])",
                "initial X0 = { x[0] <= 1.0, x[0] >= 2.0, x[1] <= 0.25, x[1] >= -0.25 }",
            ),
        ),
        (
            "initial_union",
            "E0209",
            "a union as the initial set",
            sub(
                "initial X0 = box(x[0] in [2.5, 3.0], x[1] in [-0.25, 0.25])",
                "initial X0 = box([2.5, 3.0], [-0.25, 0.25]) | box([0.0, 1.0], [0.0, 1.0])",
            ),
        ),
        (
            "inverted_interval",
            "E0203",
            "an interval with lo > hi",
            sub("[2.5, 3.0]", "[3.0, 2.5]"),
        ),
        (
            "steps_inverted",
            "E0206",
            "an avoid step range [5, 1]",
            sub("at steps [1, 5]", "at steps [5, 1]"),
        ),
        (
            "steps_beyond",
            "E0206",
            "an avoid step beyond the horizon",
            sub("at steps [1, 5]", "at steps [1, 50]"),
        ),
        (
            "index_huge",
            "E0104",
            "a component index far out of range",
            sub("x[1] in [-0.25, 0.25]", "x[99999] in [-0.25, 0.25]"),
        ),
        (
            "controller_missing",
            "E0301",
            "a controller that does not exist",
            sub("double_integrator.onnx", "no_such_controller.onnx"),
        ),
        (
            "controller_folder",
            "E0301",
            "a folder as the controller",
            sub("\"../../../models/double_integrator.onnx\"", "\".\""),
        ),
        (
            "controller_empty_path",
            "E0301",
            "an empty controller path",
            sub("\"../../../models/double_integrator.onnx\"", "\"\""),
        ),
        (
            "controller_dev_zero",
            "E0301",
            "/dev/zero as the controller (read forever by a naive reader)",
            sub(
                "\"../../../models/double_integrator.onnx\"",
                "\"/dev/zero\"",
            ),
        ),
        (
            "controller_dev_null",
            "E0301",
            "/dev/null as the controller",
            sub(
                "\"../../../models/double_integrator.onnx\"",
                "\"/dev/null\"",
            ),
        ),
        (
            "controller_text",
            "E0302",
            "a text file as the controller",
            sub(
                "\"../../../models/double_integrator.onnx\"",
                "\"../../../README.md\"",
            ),
        ),
        (
            "controller_itself",
            "E0302",
            "the spec itself as the controller",
            sub(
                "\"../../../models/double_integrator.onnx\"",
                "\"controller_itself.ravel\"",
            ),
        ),
        (
            "controller_escape",
            "E0301",
            "escape characters in the controller path",
            sub(
                "\"../../../models/double_integrator.onnx\"",
                "\"\u{1b}[31mred\u{1b}[0m.onnx\"",
            ),
        ),
        (
            "unknown_propagator",
            "E0101",
            "an unknown propagator",
            sub("propagator  reach_lp", "propagator  reach_lq"),
        ),
        (
            "sdp_tanh",
            "E0215",
            "Reach-SDP with a tanh network",
            sub("double_integrator.onnx", "double_integrator_tanh.onnx")
                .replace("reach_lp", "reach_sdp"),
        ),
    ];
    for (name, expect, why, text) in &targeted {
        put(name, expect, why, text);
    }
    // memory and time bombs that fit in a few kilobytes of text
    let big_state = |n: usize, body: &str| {
        format!(
            "system bomb {{\n    state x[{n}]\n    control u[1]\n{body}}}\ncontroller \"../../../models/double_integrator.onnx\"\ninitial X0 = box(x[0] in [0.0, 1.0])\ngoal G = box(x[0] in [-1.0, 1.0])\nhorizon 5\n"
        )
    };
    let eyes = ["eye(1000)"; 11].join(", ");
    put(
        "per_step_eyes",
        "E0216",
        "11 per_step copies of eye(1000): 88 MB from 130 bytes",
        &big_state(
            1000,
            &format!("    A = per_step({eyes})\n    B = zeros(1000, 1)\n"),
        ),
    );
    let cs = vec!["zeros(300)"; 2000].join(", ");
    put(
        "per_step_plants",
        "E0216",
        "2000 steps of a 300-state plant: every step keeps its matrices",
        &big_state(
            300,
            &format!("    A = eye(300)\n    B = zeros(300, 1)\n    c = per_step({cs})\n"),
        ),
    );
    let dims: Vec<String> = (0..101)
        .map(|i| format!("x[{i}] <= 1.0, x[{i}] >= 0.0"))
        .collect();
    put(
        "polytope_many_dimensions",
        "E0216",
        "a polytope initial set in 101 dimensions (4n linear programs to bound it)",
        &big_state(101, "    A = eye(101)\n    B = zeros(101, 1)\n").replace(
            "initial X0 = box(x[0] in [0.0, 1.0])",
            &format!("initial X0 = {{ {} }}", dims.join(", ")),
        ),
    );
    put(
        "polytope_scale_overflow",
        "E0210",
        "a polytope whose extent overflows f64 (coefficients 1e-300, right-hand sides 1e15): once a hang (found by the fuzzer)",
        &BASE.replace(
            "initial X0 = box(x[0] in [2.5, 3.0], x[1] in [-0.25, 0.25])",
            "initial X0 = { 1e-300 x[0] <= 1e15, -1e-300 x[0] <= 1e15, 1e-300 x[1] + 1e-300 x[0] <= 1e15, -1e-300 x[1] <= 1e15 }",
        ),
    );
    let rows: Vec<String> = (0..1001)
        .map(|i| format!("{}.0 x[0] + x[1] <= 100.0", i % 7))
        .collect();
    put(
        "polytope_many_rows",
        "E0216",
        "a polytope of 1001 inequalities",
        &BASE.replace(
            "avoid   overshoot = { 1.0 x[0] + 0.5 x[1] <= -2.0 } at steps [1, 5]",
            &format!("avoid   overshoot = {{ {} }}", rows.join(", ")),
        ),
    );
    // a valid but wide ReLU controller: too large for Reach-SDP, and for
    // unrolled CROWN over a long horizon
    let mut layers = Vec::new();
    let mut width = 2;
    for _ in 0..3 {
        layers.push(Layer::Affine {
            w: DMatrix::from_fn(200, width, |r, c| {
                ((r * 7 + c * 3) % 11) as f64 * 0.01 - 0.05
            }),
            b: DVector::zeros(200),
        });
        layers.push(Layer::Act(Activation::Relu));
        width = 200;
    }
    layers.push(Layer::Affine {
        w: DMatrix::from_element(1, 200, 0.001),
        b: DVector::zeros(1),
    });
    let mut g = GraphBuilder::new(2, Storage::RawF32);
    g.network(&Network::new(2, layers), false);
    fs::write(dir.join("relu_600.onnx"), g.finish(1).0).expect("write");
    let wide = BASE.replace("../../../models/double_integrator.onnx", "relu_600.onnx");
    put(
        "sdp_too_large",
        "E0216",
        "Reach-SDP on 600 ReLU neurons: a semidefinite program of dimension 610",
        &wide.replace("reach_lp", "reach_sdp"),
    );
    put(
        "unrolled_too_long",
        "E0216",
        "unrolled CROWN keeping 600 neurons' bounds for 10000 steps",
        &wide
            .replace("reach_lp", "crown_unrolled")
            .replace("horizon 5", "horizon 10000")
            .replace("samples     100", "samples     10"),
    );
    // malformed expressions of a nonlinear plant
    let nl = |rhs: &str| NONLINEAR.replace("RHS", rhs);
    let big = |unit: &str, n: usize| unit.repeat(n);
    let cases: Vec<(&str, &str, &str, String)> = vec![
        (
            "expr_parens_40",
            "E0216",
            "parentheses nested 40 deep",
            format!("{}x[0]{}", big("(", 40), big(")", 40)),
        ),
        (
            "expr_parens_deep",
            "E0216",
            "parentheses nested 100000 deep",
            format!("{}x[0]{}", big("(", 100_000), big(")", 100_000)),
        ),
        (
            "expr_neg_deep",
            "E0216",
            "100000 unary minus signs",
            format!("{}x[0]", big("-", 100_000)),
        ),
        (
            "expr_pow_chain",
            "E0216",
            "a chain of 100000 powers",
            format!("{}2", big("x[0]^", 100_000)),
        ),
        (
            "expr_literal_overflow",
            "E0205",
            "a literal that overflows f64",
            "1e999 * x[0]".to_string(),
        ),
        (
            "expr_index_too_wide",
            "E0002",
            "an index that does not fit in 64 bits",
            "x[99999999999999999999]".to_string(),
        ),
        (
            "expr_index_far",
            "E0104",
            "an index far out of range",
            "x[99999] + w[3]".to_string(),
        ),
        (
            "expr_call_empty",
            "E0222",
            "a function called without an argument",
            "sin()".to_string(),
        ),
        (
            "expr_call_unknown",
            "E0221",
            "an unknown function",
            "sinh(x[0])".to_string(),
        ),
        (
            "expr_fractional_exponent",
            "E0223",
            "a non-integer exponent",
            "x[0]^0.5".to_string(),
        ),
        (
            "expr_huge_exponent",
            "E0223",
            "an exponent beyond i32",
            "x[0]^99999999999".to_string(),
        ),
        (
            "expr_divide_by_zero",
            "E0224",
            "a division by the constant 0",
            "1/0".to_string(),
        ),
        (
            "expr_sqrt_negative",
            "E0225",
            "sqrt of a negative constant",
            "sqrt(-1) + x[0]".to_string(),
        ),
        (
            "expr_log_at_zero",
            "E0225",
            "log of 0 at the initial set's centre",
            "log(x[1])".to_string(),
        ),
        (
            "expr_exp_overflow",
            "E0205",
            "a constant that overflows when folded",
            "exp(1000) * x[0]".to_string(),
        ),
        (
            "expr_megabyte_sum",
            "E0216",
            "a 1 MB sum: more expression nodes than the limit",
            format!("x[0]{}", big(" + 0.5 * x[1]", 80_000)),
        ),
        (
            "expr_unknown_name",
            "E0101",
            "an unknown name",
            "epsilon * x[0]".to_string(),
        ),
    ];
    for (name, code, why, rhs) in cases {
        put(name, code, why, &nl(&rhs));
    }
    // malformed nonlinear sets and time windows (the plant is linear in x)
    let with = |item: &str| {
        NONLINEAR
            .replace("RHS", "-x[0]")
            .replace("horizon 5", &format!("{item}\nhorizon 5"))
    };
    let sets: Vec<(&str, &str, &str, String)> = vec![
        (
            "set_parens_deep",
            "E0216",
            "a set's inequality nested 100000 deep",
            with(&format!(
                "avoid A = {{ {}x[0]{}^2 <= 1 }}",
                big("(", 100_000),
                big(")", 100_000)
            )),
        ),
        (
            "set_pow_chain",
            "E0216",
            "a set's inequality with a chain of 100000 powers",
            with(&format!("avoid A = {{ {}2 <= 1 }}", big("x[0]^", 100_000))),
        ),
        (
            "set_literal_overflow",
            "E0205",
            "a literal that overflows f64 in a set",
            with("avoid A = { x[0]^2 + x[1]^2 <= 1e999 }"),
        ),
        (
            "set_nan_constant",
            "E0225",
            "a constant that is NaN (sqrt of a negative) in a set",
            with("avoid A = { x[0]^2 + sqrt(-1) <= 1 }"),
        ),
        (
            "set_inf_minus_inf",
            "E0205",
            "a constant folding to infinity in a set",
            with("avoid B = { x[0]^2 <= exp(1000) - exp(1000) }"),
        ),
        (
            "set_zero_divisor",
            "E0224",
            "a division by the constant 0 in a set",
            with("avoid A = { x[0]^2 / (1 - 1) <= 1 }"),
        ),
        (
            "set_unknown_vector",
            "E0101",
            "a set over the control",
            with("avoid A = { x[0]^2 + u[0] <= 1 }"),
        ),
        (
            "set_fractional_exponent",
            "E0223",
            "a non-integer exponent in a set",
            with("avoid A = { x[0]^0.5 <= 1 }"),
        ),
        (
            "set_huge_coefficient",
            "E0216",
            "an affine inequality whose folded coefficient is beyond the limits",
            with("avoid A = { 1e10 * 1e10 * x[0] <= 1 }"),
        ),
        (
            "set_nonlinear_initial",
            "E0228",
            "a nonlinear initial set",
            NONLINEAR.replace("RHS", "-x[0]").replace(
                "initial X0 = box(x[0] in [2.5, 3.0], x[1] in [-0.25, 0.25])",
                "initial X0 = { x[0]^2 + x[1]^2 <= 1 }",
            ),
        ),
        (
            "window_overflow",
            "E0205",
            "a time window that overflows f64",
            with("avoid A = { x[0] >= 10 } during [0, 1e999]"),
        ),
        (
            "window_huge",
            "E0216",
            "a time window beyond the limits",
            with("avoid A = { x[0] >= 10 } during [0, 1e308]"),
        ),
        (
            "window_inverted",
            "E0229",
            "an inverted time window",
            with("avoid A = { x[0] >= 10 } during [0.4, 0.1]"),
        ),
        (
            "window_past_horizon",
            "E0229",
            "a time beyond the horizon",
            with("avoid A = { x[0] >= 10 } during [0, 1000000]"),
        ),
        (
            "window_between_instants",
            "E0229",
            "a goal at a time between two sampling instants",
            NONLINEAR
                .replace("RHS", "-x[0]")
                .replace("x[1] in [-1.5, 0.5])", "x[1] in [-1.5, 0.5]) at time 0.25"),
        ),
    ];
    for (name, code, why, text) in sets {
        put(name, code, why, &text);
    }
    count
}

/// A nonlinear plant whose second equation is `RHS`.
const NONLINEAR: &str = r#"system corpus {
    state   x[2]
    control u[1]
    time    continuous dt 0.1
    der x[0] = x[1]
    der x[1] = RHS
    u in box([-1.0, 1.0])
}
controller "../../../models/double_integrator.onnx"
initial X0 = box(x[0] in [2.5, 3.0], x[1] in [-0.25, 0.25])
goal    G  = box(x[0] in [-1.5, 2.0], x[1] in [-1.5, 0.5])
horizon 5
"#;

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

fn model(storage: Storage) -> (ModelProto, Vec<u8>) {
    let mut g = GraphBuilder::new(2, storage).external_file("ok.data");
    g.network(&net(), false);
    let (bytes, data) = g.finish(1);
    (ModelProto::decode(bytes.as_slice()).expect("model"), data)
}

fn graph(m: &mut ModelProto) -> &mut GraphProto {
    m.graph.as_mut().expect("graph")
}

fn set_external(m: &mut ModelProto, key: &str, value: &str) {
    let t = &mut graph(m).initializer[0];
    t.external_data.retain(|e| e.key.as_deref() != Some(key));
    t.external_data.push(StringStringEntryProto {
        key: Some(key.into()),
        value: Some(value.into()),
    });
}

fn nested_graph(depth: usize) -> GraphProto {
    let mut g = GraphProto::default();
    for _ in 0..depth {
        g = GraphProto {
            node: vec![NodeProto {
                op_type: Some("If".into()),
                attribute: vec![AttributeProto {
                    name: Some("then_branch".into()),
                    g: Some(Box::new(g)),
                    r#type: Some(5),
                    ..Default::default()
                }],
                ..Default::default()
            }],
            ..Default::default()
        };
    }
    g
}

fn onnx(dir: &Path) -> usize {
    let _ = fs::remove_dir_all(dir);
    fs::create_dir_all(dir).expect("folder");
    let mut expect = String::from(
        "# file  code  what (the code the controller must be refused with; `any`: some code)\n",
    );
    let mut put = |name: &str, code: &str, what: &str, bytes: Vec<u8>| {
        fs::write(dir.join(format!("{name}.onnx")), bytes).expect("write");
        expect += &format!("{name}.onnx {code} {what}\n");
    };
    let (raw, _) = model(Storage::RawF32);
    let full = raw.encode_to_vec();
    for k in 1..=12 {
        let cut = full.len() * k / 13;
        put(
            &format!("truncated_{k:02}"),
            "any",
            &format!("cut after {cut} bytes"),
            full[..cut].to_vec(),
        );
    }
    put("empty", "E0302", "an empty file", Vec::new());
    put(
        "random_bytes",
        "E0302",
        "bytes that are not protobuf",
        (0..200u32).map(|i| (i * 97 % 251) as u8 | 0x80).collect(),
    );
    put(
        "png_header",
        "E0302",
        "a PNG signature",
        b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR".to_vec(),
    );
    let mut m = raw.clone();
    m.opset_import.clear();
    put(
        "no_opset",
        "E0302",
        "no opset_import (truncated before it)",
        m.encode_to_vec(),
    );
    let mut m = raw.clone();
    m.graph = None;
    put("no_graph", "E0302", "no graph", m.encode_to_vec());
    let mut m = raw.clone();
    graph(&mut m).node[0].attribute.push(AttributeProto {
        name: Some("deep".into()),
        g: Some(Box::new(nested_graph(200))),
        r#type: Some(5),
        ..Default::default()
    });
    put(
        "deeply_nested",
        "E0302",
        "attribute graphs nested 200 deep",
        m.encode_to_vec(),
    );
    let mut m = raw.clone();
    graph(&mut m).initializer[0].dims = vec![1 << 40, 1 << 40];
    put(
        "dims_overflow",
        "E0307",
        "dimensions whose product overflows",
        m.encode_to_vec(),
    );
    let mut m = raw.clone();
    graph(&mut m).initializer[0].dims = vec![3, -2];
    put(
        "dims_negative",
        "E0307",
        "a negative dimension",
        m.encode_to_vec(),
    );
    let mut m = raw.clone();
    graph(&mut m).initializer[0].dims = vec![3, 3];
    put(
        "data_too_short",
        "E0307",
        "fewer bytes than the shape needs",
        m.encode_to_vec(),
    );
    let mut m = raw.clone();
    graph(&mut m).initializer[0].dims = vec![1 << 25];
    put(
        "tensor_huge",
        "E0307",
        "a tensor beyond 16M elements",
        m.encode_to_vec(),
    );
    let mut m = raw.clone();
    if let Some(t) = graph(&mut m).input[0].r#type.as_mut() {
        if let Some(s) = t.tensor_type.as_mut().and_then(|tt| tt.shape.as_mut()) {
            s.dim[1].dim_value = Some(1 << 40);
        }
    }
    put(
        "input_huge",
        "E0303",
        "an input declared 2^40 wide",
        m.encode_to_vec(),
    );
    let wide = Network::new(
        2,
        vec![Layer::Affine {
            w: DMatrix::from_element(5000, 2, 0.01),
            b: DVector::zeros(5000),
        }],
    );
    let mut g = GraphBuilder::new(2, Storage::RawF32);
    g.network(&wide, false);
    put(
        "layer_too_wide",
        "E0303",
        "a layer of 5000 neurons",
        g.finish(5000).0,
    );
    let mut g = GraphBuilder::new(2, Storage::RawF32);
    g.network(&net(), false);
    for _ in 0..5000 {
        g.unary("Identity");
    }
    put("too_many_nodes", "E0303", "5000 nodes", g.finish(1).0);
    for (name, value, what) in [
        ("weight_nan", f64::NAN, "a NaN weight"),
        ("weight_inf", f64::INFINITY, "an infinite weight"),
        ("weight_huge", 1e30, "a weight of 1e30"),
    ] {
        let mut w = net();
        if let Layer::Affine { w, .. } = &mut w.layers[0] {
            w[(0, 0)] = value;
        }
        let mut g = GraphBuilder::new(2, Storage::RawF32);
        g.network(&w, false);
        put(name, "E0306", what, g.finish(1).0);
    }
    let mut g = GraphBuilder::new(2, Storage::RawF32);
    g.elementwise("Div", &[0.0, 1.0]);
    g.network(&net(), false);
    put("div_by_zero", "E0306", "a division by zero", g.finish(1).0);
    let mut g = GraphBuilder::new(2, Storage::RawF32);
    g.elementwise("Div", &[1e-30, 1.0]);
    g.network(&net(), false);
    put(
        "div_by_tiny",
        "E0306",
        "a division by 1e-30 (weights beyond 1e15)",
        g.finish(1).0,
    );
    for (name, alpha, what) in [
        ("alpha_huge", 1e30f32, "Gemm alpha 1e30"),
        ("alpha_nan", f32::NAN, "Gemm alpha NaN"),
    ] {
        let mut m = raw.clone();
        for a in &mut graph(&mut m).node[0].attribute {
            if a.name.as_deref() == Some("alpha") {
                a.f = Some(alpha);
            }
        }
        put(name, "E0306", what, m.encode_to_vec());
    }
    for (name, dt, what) in [
        ("float16", 10, "float16 weights"),
        ("string", 8, "string weights"),
        ("complex", 14, "complex weights"),
    ] {
        let mut m = raw.clone();
        graph(&mut m).initializer[0].data_type = Some(dt);
        put(name, "E0303", what, m.encode_to_vec());
    }
    // bool constants are read (Dropout's training flag), but a float
    // tensor's bytes declared bool do not fit its shape
    let mut m = raw.clone();
    graph(&mut m).initializer[0].data_type = Some(9);
    put(
        "bool",
        "E0307",
        "float weights declared bool",
        m.encode_to_vec(),
    );
    for op in ["Elu", "Softmax", "MaxPool", "Exp", "Softplus"] {
        let mut g = GraphBuilder::new(2, Storage::RawF32);
        g.network(&net(), false);
        g.unary(op);
        put(
            &format!("op_{}", op.to_lowercase()),
            "E0303",
            &format!("the unsupported op {op}"),
            g.finish(1).0,
        );
    }
    // convolutions and poolings on a [1, 2, 1, 1] image: hostile attributes,
    // a residual connection, an output past the width limit
    let image = || {
        let mut g = GraphBuilder::new(2, Storage::RawF32);
        g.declare_shape(&[None, Some(2), Some(1), Some(1)]);
        g
    };
    let ints = GraphBuilder::ints_attr;
    let conv = |g: &mut GraphBuilder, attrs: Vec<AttributeProto>| {
        let w = g.constant("weight", &[2, 2, 1, 1], &[1.0, 0.5, -0.5, 1.0]);
        g.node("Conv", &[w], attrs);
    };
    let conv_cases: Vec<(&str, &str, &str, Vec<u8>)> = vec![
        ("conv_stride_zero", "E0307", "Conv with stride 0", {
            let mut g = image();
            conv(&mut g, vec![ints("strides", &[0, 1])]);
            g.finish(2).0
        }),
        ("conv_negative_pad", "E0307", "Conv with a negative pad", {
            let mut g = image();
            conv(&mut g, vec![ints("pads", &[0, -3, 0, 0])]);
            g.finish(2).0
        }),
        (
            "conv_huge_pads",
            "E0303",
            "Conv whose pads of 2^63 − 1 make it too wide",
            {
                let mut g = image();
                conv(&mut g, vec![ints("pads", &[i64::MAX, 0, i64::MAX, 0])]);
                g.finish(2).0
            },
        ),
        (
            "conv_residual",
            "E0303",
            "a residual Add of a Conv's output and its input",
            {
                let mut g = image();
                let x = g.current();
                conv(&mut g, vec![]);
                let y = g.current();
                g.node_inputs("Add", vec![y, x], vec![]);
                g.finish(2).0
            },
        ),
        (
            "pool_in_padding",
            "E0307",
            "an AveragePool window entirely in the padding",
            {
                let mut g = image();
                g.node(
                    "AveragePool",
                    &[],
                    vec![ints("kernel_shape", &[1, 1]), ints("pads", &[2, 0, 0, 0])],
                );
                g.finish(2).0
            },
        ),
    ];
    for (name, code, what, bytes) in conv_cases {
        put(name, code, what, bytes);
    }
    // exporter ops with bad parameters
    let bad_ops: Vec<(&str, &str, &str, Vec<u8>)> = vec![
        ("clip_inverted", "E0307", "Clip with min above max", {
            let mut g = GraphBuilder::new(2, Storage::RawF32);
            g.network(&net(), false);
            g.node(
                "Clip",
                &[],
                vec![float_attr("min", 1.0), float_attr("max", -1.0)],
            );
            g.finish(1).0
        }),
        ("clip_nan", "E0306", "Clip with a NaN bound", {
            let mut g = GraphBuilder::new(2, Storage::RawF32);
            g.network(&net(), false);
            let lo = g.constant("min", &[], &[f64::NAN]);
            g.node("Clip", &[lo], vec![]);
            g.finish(1).0
        }),
        ("leaky_relu_nan", "E0306", "LeakyRelu with a NaN slope", {
            let mut g = GraphBuilder::new(2, Storage::RawF32);
            g.network(&net(), false);
            g.node("LeakyRelu", &[], vec![float_attr("alpha", f32::NAN)]);
            g.finish(1).0
        }),
        (
            "batchnorm_negative_variance",
            "E0306",
            "BatchNormalization with a negative variance",
            {
                let mut g = GraphBuilder::new(2, Storage::RawF32);
                g.network(&net(), false);
                let p: Vec<String> = [("scale", 1.0), ("bias", 0.0), ("mean", 0.0), ("var", -4.0)]
                    .iter()
                    .map(|(n, v)| g.constant(n, &[1], &[*v]))
                    .collect();
                g.node("BatchNormalization", &p, vec![]);
                g.finish(1).0
            },
        ),
        (
            "batchnorm_training",
            "E0303",
            "BatchNormalization exported in training mode",
            {
                let mut g = GraphBuilder::new(2, Storage::RawF32);
                g.network(&net(), false);
                let p: Vec<String> = [("scale", 1.0), ("bias", 0.0), ("mean", 0.0), ("var", 1.0)]
                    .iter()
                    .map(|(n, v)| g.constant(n, &[1], &[*v]))
                    .collect();
                g.node("BatchNormalization", &p, vec![int_attr("training_mode", 1)]);
                g.finish(1).0
            },
        ),
        (
            "dropout_training",
            "E0303",
            "Dropout exported in training mode",
            {
                let mut g = GraphBuilder::new(2, Storage::RawF32);
                g.network(&net(), false);
                let ratio = g.constant("ratio", &[], &[0.5]);
                let flag = g.constant("training_mode", &[], &[1.0]);
                g.node("Dropout", &[ratio, flag], vec![]);
                g.finish(1).0
            },
        ),
    ];
    for (name, code, what, bytes) in bad_ops {
        put(name, code, what, bytes);
    }
    let mut g = GraphBuilder::new(2, Storage::RawF32);
    g.network(&net(), false);
    g.unary("\u{1b}[2J\u{1b}[H\nverdict: VERIFIED\n");
    put(
        "op_ansi",
        "E0303",
        "an op type with ANSI escapes and a fake verdict line",
        g.finish(1).0,
    );
    let mut m = raw.clone();
    graph(&mut m).node[0].domain = Some("com.evil\u{202e}".into());
    put(
        "custom_domain",
        "E0303",
        "a custom operator domain",
        m.encode_to_vec(),
    );
    let mut m = raw.clone();
    let extra = graph(&mut m).input[0].clone();
    let mut second = extra;
    second.name = Some("second".into());
    graph(&mut m).input.push(second);
    put("two_inputs", "E0303", "two data inputs", m.encode_to_vec());
    let mut m = raw.clone();
    graph(&mut m).input.clear();
    put("no_inputs", "E0303", "no data input", m.encode_to_vec());
    let mut m = raw.clone();
    let o = graph(&mut m).output[0].clone();
    graph(&mut m).output.push(o);
    put("two_outputs", "E0303", "two outputs", m.encode_to_vec());
    let mut m = raw.clone();
    for a in &mut graph(&mut m).node[0].attribute {
        if a.name.as_deref() == Some("transB") {
            a.name = Some("transA".into());
        }
    }
    put(
        "gemm_trans_a",
        "E0303",
        "Gemm with transA = 1",
        m.encode_to_vec(),
    );
    let mut m = raw.clone();
    let n0 = graph(&mut m).node[0].clone();
    let input = n0.input[0].clone();
    graph(&mut m).node[0].input[1] = input;
    put(
        "gemm_computed_weight",
        "E0303",
        "a Gemm whose weight is computed",
        m.encode_to_vec(),
    );
    let mut m = raw.clone();
    let g0 = graph(&mut m);
    let current = g0.node[1].output[0].clone();
    let first = g0.node[0].output[0].clone();
    g0.node.push(NodeProto {
        input: vec![current, first],
        output: vec!["skip".into()],
        op_type: Some("Add".into()),
        ..Default::default()
    });
    put(
        "skip_connection",
        "E0303",
        "an Add of two computed values",
        m.encode_to_vec(),
    );
    let mut m = raw.clone();
    graph(&mut m).node.insert(
        0,
        NodeProto {
            output: vec!["k".into()],
            op_type: Some("Constant".into()),
            ..Default::default()
        },
    );
    put(
        "constant_without_value",
        "E0303",
        "a Constant node without a value",
        m.encode_to_vec(),
    );
    let mut g = GraphBuilder::new(3, Storage::RawF32);
    g.network(
        &Network::new(
            3,
            vec![Layer::Affine {
                w: DMatrix::from_element(1, 3, 0.1),
                b: DVector::zeros(1),
            }],
        ),
        false,
    );
    put(
        "three_inputs",
        "E0304",
        "3 inputs for a 2-state plant",
        g.finish(1).0,
    );
    let mut g = GraphBuilder::new(2, Storage::RawF32);
    g.network(
        &Network::new(
            2,
            vec![Layer::Affine {
                w: DMatrix::from_element(2, 2, 0.1),
                b: DVector::zeros(2),
            }],
        ),
        false,
    );
    put(
        "two_outputs_wide",
        "E0305",
        "2 outputs for 1 control",
        g.finish(2).0,
    );
    let mut m = raw.clone();
    if let Some(Layer::Affine { .. }) = net().layers.first() {
        let t: &mut TensorProto = &mut graph(&mut m).initializer[0];
        t.dims = vec![3, 2, 1];
    }
    put("weight_3d", "E0307", "a 3-D Gemm weight", m.encode_to_vec());
    // external data: the data file `ok.data` is written next to these models
    let (ext, data) = model(Storage::External);
    fs::write(dir.join("ok.data"), &data).expect("write");
    fs::write(dir.join("short.data"), &data[..8]).expect("write");
    put(
        "external_ok_but_wrong_inputs",
        "E0304",
        "valid external data, 2 inputs: the spec below has 3 observations",
        {
            let mut g = GraphBuilder::new(3, Storage::External).external_file("ok3.data");
            g.network(
                &Network::new(
                    3,
                    vec![Layer::Affine {
                        w: DMatrix::from_element(1, 3, 0.1),
                        b: DVector::zeros(1),
                    }],
                ),
                false,
            );
            let (b, d) = g.finish(1);
            fs::write(dir.join("ok3.data"), d).expect("write");
            b
        },
    );
    for (name, location, what) in [
        (
            "external_parent",
            "../../../Cargo.toml",
            "a location leaving the folder",
        ),
        ("external_absolute", "/etc/passwd", "an absolute location"),
        (
            "external_proc",
            "/proc/self/environ",
            "the process environment",
        ),
        ("external_dev_zero", "/dev/zero", "a device"),
        (
            "external_dotdot_inside",
            "sub/../../ok.data",
            "a `..` hidden inside the path",
        ),
        (
            "external_backslash",
            "..\\ok.data",
            "a Windows-style parent",
        ),
        ("external_drive", "C:/ok.data", "a drive letter"),
        ("external_empty", "", "an empty location"),
        (
            "external_missing",
            "missing.data",
            "a data file that does not exist",
        ),
        (
            "external_short",
            "short.data",
            "a data file shorter than the tensors",
        ),
        ("external_folder", ".", "the folder itself"),
        (
            "external_escape",
            "\u{1b}[31mok.data",
            "escape characters in the location",
        ),
    ] {
        let mut m = ext.clone();
        set_external(&mut m, "location", location);
        put(name, "E0308", what, m.encode_to_vec());
    }
    for (name, key, value, what) in [
        (
            "external_length_mismatch",
            "length",
            "7",
            "a length that differs from the shape",
        ),
        (
            "external_length_huge",
            "length",
            "18446744073709551615",
            "a length of 2^64 − 1",
        ),
        (
            "external_offset_overflow",
            "offset",
            "18446744073709551615",
            "an offset whose end overflows",
        ),
        (
            "external_offset_text",
            "offset",
            "zero",
            "an offset that is not a number",
        ),
        (
            "external_offset_beyond_limit",
            "offset",
            "629145600",
            "an offset beyond 512 MiB (found by the fuzzer)",
        ),
        (
            "external_offset_negative",
            "offset",
            "-8",
            "a negative offset",
        ),
    ] {
        let mut m = ext.clone();
        set_external(&mut m, key, value);
        put(name, "E0308", what, m.encode_to_vec());
    }
    let mut m = ext.clone();
    graph(&mut m).initializer[0]
        .external_data
        .retain(|e| e.key.as_deref() != Some("location"));
    put(
        "external_no_location",
        "E0308",
        "external data without a location",
        m.encode_to_vec(),
    );
    let count = expect.lines().count() - 1;
    fs::write(dir.join("EXPECT"), expect).expect("write");
    count
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus");
    let s = specs(&root.join("specs"));
    let o = onnx(&root.join("onnx"));
    eprintln!(
        "corpus written under {}: {s} specs, {o} ONNX files",
        root.display()
    );
}
