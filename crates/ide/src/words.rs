//! The language's fixed words, each with a one-line explanation for hover
//! and completion: the grammar's keywords, the names the checker knows
//! (propagators, partitioners, boundaries and shapes, time kinds, budget
//! items, functions) and the built-in constant `pi`.

use ravel::ir::{Guide, NetPropagator};
use ravel_analysis::closed_loop::Propagator;
use ravel_base::expr::Func;

/// What kind of fixed word a word is (decides its completion kind).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WordKind {
    /// A keyword of the grammar.
    Keyword,
    /// A closed-loop or network propagator.
    Propagator,
    /// A partitioner.
    Partitioner,
    /// Another name the checker knows: a boundary or shape, a time kind,
    /// a budget item, a norm.
    Option,
    /// A function of a nonlinear plant's expressions, or `pi`.
    Function,
}

/// Every keyword of the grammar (`crates/syntax/grammar/ravel.pest`), with
/// what it introduces. A test checks this list against the grammar.
pub const KEYWORDS: &[(&str, &str)] = &[
    ("system", "`system NAME { … }`: a closed loop: its state, control, plant and limits"),
    ("state", "`state x[n]`: the state vector and its dimension"),
    ("control", "`control u[m]`: the control vector (the controller's output) and its dimension"),
    ("time", "`time discrete` or `time continuous dt T`: how the plant advances (a continuous plant is discretised with zero-order hold); in a budget, the seconds a guided partitioner may spend"),
    ("dt", "`dt T`: the control period of a continuous-time plant, in seconds"),
    ("const", "`const NAME = EXPR`: a named constant of a nonlinear plant's expressions"),
    ("der", "`der x[i] = EXPR`: the time derivative of a state of a continuous-time nonlinear plant"),
    ("next", "`next x[i] = EXPR`: the next value of a state of a discrete-time nonlinear plant"),
    ("observe", "`observe [EXPR, …]`: what the controller sees of the state (instead of `C`)"),
    ("actuate", "`actuate [EXPR, …]`: how the controller's outputs drive the plant"),
    ("in", "`NAME in box(…)`: bounds of the control (limits) or of noise `w` and `v`; `x[i] in [a, b]` inside a box"),
    ("per_step", "`per_step(V0, V1, …)`: a plant matrix or vector that changes from step to step"),
    ("eye", "`eye(n)`: the n × n identity matrix"),
    ("zeros", "`zeros(n)` or `zeros(n, m)`: a matrix of zeros"),
    ("controller", "`controller \"PATH\"`: the ONNX controller, relative to the spec's folder"),
    ("initial", "`initial NAME = SET`: the initial set X0 of the states"),
    ("goal", "`goal NAME = SET`: the set the final (or timed) reachable set must lie in"),
    ("avoid", "`avoid NAME = SET [at steps [a, b] | during [t0, t1]]`: a set no reachable state may touch"),
    ("at", "`at steps [a, b]`, `at step k`, `at time T`: when a set applies"),
    ("steps", "`at steps [a, b]`: an inclusive range of steps (step 0 is the initial set)"),
    ("step", "`at step k`: one step"),
    ("always", "`always during [t0, t1]`: the goal holds at every instant of the window"),
    ("eventually", "`eventually during [t0, t1]`: the goal holds at some instant of the window"),
    ("during", "`during [t0, t1]`: a window of time in seconds"),
    ("horizon", "`horizon N`: the number of steps analysed"),
    ("analysis", "`analysis { … }`: propagator, partitioner, boundary, samples, seed"),
    ("propagator", "`propagator NAME`: the method that bounds each step (closed loops) or the network (network specs)"),
    ("partitioner", "`partitioner NAME`: how the initial (or input) set is split into cells"),
    ("uniform", "`partitioner uniform [k0, k1, …]`: a grid with k_i cells along component i"),
    ("sg", "`partitioner sg`: simulation-guided splitting of the initial set"),
    ("gsg", "`partitioner gsg`: greedy simulation-guided splitting"),
    ("property", "`partitioner property`: splitting guided by the properties' margins"),
    ("bab", "`partitioner bab`: branch and bound over the input set (network specs)"),
    ("boundary", "`boundary box | polytope K | polytope [[…], …] | hull`: the shape of the reachable sets"),
    ("polytope", "`polytope K` (K directions evenly spread, 2-D) or `polytope [[…], …]` (given directions)"),
    ("shape", "`shape box | lower_bounds | hull | polytope …`: the shape of a network's output set"),
    ("samples", "`samples N`: Monte Carlo trajectories (falsification, tightness, guides)"),
    ("seed", "`seed N`: the seed of the Monte Carlo samples"),
    ("optimise_slopes", "`optimise_slopes N`: projected-gradient steps on CROWN's lower ReLU slopes"),
    ("box", "`box(x[0] in [a, b], …)` or `box([a, b], …)`: an axis-aligned box; as a boundary, boxes"),
    ("ball", "`ball(center [...], radius r, norm 1 | 2 | inf)`: an ℓp ball (initial and input sets)"),
    ("center", "`center [...]`: a ball's centre"),
    ("radius", "`radius r` of a ball; `radius NAME for PROPERTY (…)`: search the largest radius for which a property holds"),
    ("norm", "`norm 1 | 2 | inf`: the norm of a ball or of a selection's perturbation"),
    ("inf", "the ∞-norm (a box-shaped ball)"),
    ("network", "`network NAME { input x[n] output y[m] }`: a network on its own, without a plant"),
    ("input", "`input x[n]` in a network block: its input vector; `input NAME = SET`: the input set"),
    ("output", "`output y[m]`: a network's output vector"),
    ("model", "`model \"PATH\"`: the ONNX network of a network spec, relative to the spec's folder"),
    ("require", "`require NAME = SET`: a property of the outputs over the whole input set"),
    ("robust", "`robust NAME [label k]`: the output's arg-max stays the same (or is k) over the input set"),
    ("label", "`label k`: the class a robustness property expects"),
    ("for", "`radius NAME for PROPERTY`: the property whose radius is searched"),
    ("select", "`select NAME { epsilon … norm … observations … }`: robust action selection (CARRL)"),
    ("epsilon", "`epsilon e` or `epsilon [...]`: the perturbation radius of each observation"),
    ("observations", "`observations [[…], …]` or `observations \"FILE.csv\"`: the observations of a selection"),
];

/// The words of the grammar that are not keywords of their own but names
/// the checker accepts after one (time kinds, boundaries and shapes, budget
/// items), with what they mean.
const OPTIONS: &[(&str, &str)] = &[
    (
        "discrete",
        "`time discrete`: the plant's equations give the next state (the default)",
    ),
    (
        "continuous",
        "`time continuous dt T`: the plant's equations give the time derivative",
    ),
    (
        "hull",
        "`boundary hull`: convex hulls of the reachable sets (2-D)",
    ),
    (
        "lower_bounds",
        "`shape lower_bounds`: a lower bound per output only",
    ),
    ("none", "`partitioner none`: the initial set as one cell"),
    (
        "calls",
        "`calls N`: the most analysis calls a guided partitioner may make",
    ),
    (
        "min_size",
        "`min_size r`: the smallest cell a guided partitioner splits",
    ),
];

/// What a propagator does, by name.
fn propagator_doc(p: Propagator) -> &'static str {
    match p {
        Propagator::ReachLp => {
            "Reach-LP: one linear program per facet over CROWN's relaxation of the controller"
        }
        Propagator::CrownSeparate => "CL-CROWN: CROWN's bounds of the control, then the plant",
        Propagator::IbpSeparate => "interval bound propagation of the controller, then the plant",
        Propagator::SgIbpSeparate => "simulation-guided IBP (the baseline of the tutorial)",
        Propagator::CrownUnrolled => "CROWN through every step unrolled back to X0",
        Propagator::ReachSdp => {
            "Reach-SDP: a semidefinite program per facet (quadratic constraints of the activations)"
        }
    }
}

/// What a network propagator does, by name.
fn net_propagator_doc(p: NetPropagator) -> &'static str {
    match p {
        NetPropagator::Ibp => "network specs: interval bound propagation",
        NetPropagator::FastLin => "network specs: Fast-Lin's linear bounds",
        NetPropagator::Crown => "network specs: CROWN's linear bounds",
        NetPropagator::Sdp => "network specs: the SDP relaxation",
    }
}

/// Every fixed word with its kind and explanation: keywords first, then
/// propagators, partitioners, options and functions.
pub fn all() -> Vec<(&'static str, WordKind, String)> {
    let mut v: Vec<(&'static str, WordKind, String)> = Vec::new();
    let mut push = |w: &'static str, k: WordKind, d: String| {
        if !v.iter().any(|(x, _, _)| *x == w) {
            v.push((w, k, d));
        }
    };
    for g in Guide::ALL {
        let doc = KEYWORDS
            .iter()
            .find(|(k, _)| *k == g.name())
            .map_or("", |(_, d)| d);
        push(g.name(), WordKind::Partitioner, doc.to_string());
    }
    for (k, d) in KEYWORDS {
        let kind = if *k == "uniform" {
            WordKind::Partitioner
        } else {
            WordKind::Keyword
        };
        push(k, kind, d.to_string());
    }
    for p in Propagator::ALL {
        push(
            p.name(),
            WordKind::Propagator,
            propagator_doc(p).to_string(),
        );
    }
    for p in NetPropagator::ALL {
        push(
            p.name(),
            WordKind::Propagator,
            net_propagator_doc(p).to_string(),
        );
    }
    for (k, d) in OPTIONS {
        let kind = if *k == "none" {
            WordKind::Partitioner
        } else {
            WordKind::Option
        };
        push(k, kind, d.to_string());
    }
    for f in Func::ALL {
        push(
            f.name(),
            WordKind::Function,
            format!(
                "`{}(…)`: a function of a nonlinear plant's expressions",
                f.name()
            ),
        );
    }
    push("pi", WordKind::Function, "the constant π".to_string());
    v
}

/// The explanation of a fixed word, if `word` is one.
pub fn doc(word: &str) -> Option<(WordKind, String)> {
    all()
        .into_iter()
        .find(|(w, _, _)| *w == word)
        .map(|(_, k, d)| (k, d))
}

/// The names a propagator may have in a closed-loop spec.
pub fn propagators() -> Vec<&'static str> {
    Propagator::ALL.iter().map(|p| p.name()).collect()
}

/// The names a propagator may have in a network spec.
pub fn net_propagators() -> Vec<&'static str> {
    NetPropagator::ALL.iter().map(|p| p.name()).collect()
}

/// Every partitioner's name.
pub fn partitioners() -> Vec<&'static str> {
    let mut v = vec!["none", "uniform"];
    v.extend(Guide::ALL.iter().map(|g| g.name()));
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The grammar's keywords: its quoted words (not `^"e"`, the exponent).
    fn grammar_keywords() -> Vec<String> {
        let text = include_str!("../../syntax/grammar/ravel.pest");
        let mut out: Vec<String> = Vec::new();
        for line in text.lines().filter(|l| !l.trim_start().starts_with("//")) {
            let mut rest = line;
            while let Some(i) = rest.find('"') {
                let caret = rest[..i].ends_with('^');
                let after = &rest[i + 1..];
                let Some(j) = after.find('"') else { break };
                let word = &after[..j];
                let ident = word.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
                    && word.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
                if ident && !caret && !out.iter().any(|w| w == word) {
                    out.push(word.to_string());
                }
                rest = &after[j + 1..];
            }
        }
        out
    }

    #[test]
    fn every_keyword_of_the_grammar_is_explained() {
        let words = grammar_keywords();
        assert!(words.len() > 50, "{words:?}");
        for w in &words {
            assert!(
                KEYWORDS.iter().any(|(k, _)| k == w),
                "the grammar's keyword `{w}` has no explanation"
            );
        }
        for (k, _) in KEYWORDS {
            assert!(words.iter().any(|w| w == k), "`{k}` is not in the grammar");
        }
    }

    #[test]
    fn every_checker_name_is_explained() {
        for w in propagators()
            .into_iter()
            .chain(net_propagators())
            .chain(partitioners())
            .chain([
                "box",
                "hull",
                "polytope",
                "lower_bounds",
                "discrete",
                "continuous",
            ])
        {
            let (_, d) = doc(w).unwrap_or_else(|| panic!("`{w}` has no explanation"));
            assert!(!d.is_empty(), "{w}");
        }
    }
}
