//! Hover, definitions and completion on small specs, at offsets found by
//! searching the text (so the tests read as what a person points at).

use super::*;

const SPEC: &str = "system di {
    state   x[2]
    control u[1]
    const g = 2 * 4.5
    A = [[1, 1],
         [0, 1]]
    B = eye(2)
    u in box([-1, 1])
    w in box([-0.1, 0.1], [0, 0.2])
}

initial X0 = box(x[0] in [2.5, 3.0], x[1] in [-0.25, 0.25])
avoid   bad = { x[0] <= -2.0 } | box([0, 1], [0, 1]) at steps [1, 5]
horizon 5

analysis {
    propagator reach_lp
    partitioner gsg
}
";

/// The offset of the `nth` occurrence of `needle`, plus `into` bytes.
fn at(text: &str, needle: &str, nth: usize, into: usize) -> usize {
    text.match_indices(needle)
        .nth(nth)
        .unwrap_or_else(|| panic!("`{needle}` #{nth} not in the text"))
        .0
        + into
}

fn hover_text(text: &str, offset: usize) -> String {
    hover(text, offset).map(|h| h.markdown).unwrap_or_default()
}

#[test]
fn hover_shows_kinds_and_sizes() {
    let h = hover_text(SPEC, at(SPEC, "x[2]", 0, 0));
    assert!(h.contains("state vector, 2 components"), "{h}");
    let h = hover_text(SPEC, at(SPEC, "u[1]", 0, 0));
    assert!(h.contains("control vector, 1 component"), "{h}");
    assert!(h.contains("saturated to a box of 1 component"), "{h}");
    let h = hover_text(SPEC, at(SPEC, "w in", 0, 0));
    assert!(h.contains("process noise vector, 2 components"), "{h}");
    let h = hover_text(SPEC, at(SPEC, "A =", 0, 0));
    assert!(h.contains("2 × 2 matrix"), "{h}");
    let h = hover_text(SPEC, at(SPEC, "B =", 0, 0));
    assert!(h.contains("2 × 2 identity matrix"), "{h}");
    let h = hover_text(SPEC, at(SPEC, "g =", 0, 0));
    assert!(h.contains("constant `g` = 2 * 4.5 = 9"), "{h}");
    let h = hover_text(SPEC, at(SPEC, "X0", 0, 1));
    assert!(
        h.contains("initial set: box (2 bounded components), over `x` ∈ ℝ²"),
        "{h}"
    );
    let h = hover_text(SPEC, at(SPEC, "bad", 0, 3));
    assert!(h.contains("avoid set: union of 2 sets"), "{h}");
    assert!(h.contains("at steps 1 … 5"), "{h}");
}

#[test]
fn hover_on_a_use_shows_the_component_and_its_range() {
    // x[0] inside X0's box
    let h = hover_text(SPEC, at(SPEC, "x[0]", 0, 0));
    assert!(
        h.contains("state vector") && h.contains("component 0"),
        "{h}"
    );
    let text = SPEC.replace("x[1] in [-0.25", "x[7] in [-0.25");
    let h = hover_text(&text, at(&text, "x[7]", 0, 0));
    assert!(h.contains("component 7: **out of range**"), "{h}");
}

#[test]
fn hover_explains_keywords_propagators_and_partitioners() {
    let h = hover_text(SPEC, at(SPEC, "horizon", 0, 2));
    assert!(h.starts_with("```ravel\nhorizon\n```\nkeyword:"), "{h}");
    let h = hover_text(SPEC, at(SPEC, "reach_lp", 0, 0));
    assert!(h.contains("propagator: Reach-LP"), "{h}");
    let h = hover_text(SPEC, at(SPEC, "gsg", 0, 0));
    assert!(h.contains("partitioner:"), "{h}");
    // nothing in a comment, a number or white space
    assert_eq!(hover(SPEC, at(SPEC, "2.5", 0, 1)), None);
    assert_eq!(hover("// state\n", 4), None);
}

#[test]
fn definitions_lead_from_uses_to_declarations() {
    let decl = at(SPEC, "x[2]", 0, 0);
    let use_ = at(SPEC, "x[0]", 1, 1);
    assert_eq!(definition(SPEC, use_), Some(Span::new(decl, decl + 1)));
    let g = SPEC.replace("horizon 5", "horizon 5\n");
    assert_eq!(
        definition(&g, at(&g, "X0", 0, 0)),
        Some(Span::new(at(&g, "X0", 0, 0), at(&g, "X0", 0, 2)))
    );
    // a keyword has no declaration
    assert_eq!(definition(SPEC, at(SPEC, "horizon", 0, 0)), None);
}

#[test]
fn definitions_and_hover_survive_a_spec_that_does_not_parse() {
    let broken = SPEC.replace("horizon 5", "horizon");
    assert!(ravel_syntax::parse(&broken).is_err());
    let decl = at(&broken, "x[2]", 0, 0);
    assert_eq!(
        definition(&broken, at(&broken, "x[0]", 1, 0)),
        Some(Span::new(decl, decl + 1))
    );
    let h = hover_text(&broken, decl);
    assert!(h.contains("state vector"), "{h}");
    let h = hover_text(&broken, at(&broken, "propagator", 0, 0));
    assert!(h.contains("keyword"), "{h}");
}

fn labels(c: &[Completion]) -> Vec<&str> {
    c.iter().map(|c| c.label.as_str()).collect()
}

#[test]
fn completion_knows_what_may_follow() {
    let c = completion(SPEC, at(SPEC, "reach_lp", 0, 3));
    let l = labels(&c);
    assert!(
        l.contains(&"reach_lp") && l.contains(&"reach_sdp") && l.contains(&"crown_unrolled"),
        "{l:?}"
    );
    assert!(!l.contains(&"horizon") && !l.contains(&"fast_lin"), "{l:?}");
    let text = SPEC.replace("partitioner gsg", "partitioner ");
    let c = completion(&text, at(&text, "partitioner ", 0, 12));
    let l = labels(&c);
    assert_eq!(l, ["none", "uniform", "sg", "gsg", "property", "bab"]);
    // elsewhere: keywords and declared names
    let c = completion(SPEC, at(SPEC, "horizon", 0, 3));
    let l = labels(&c);
    for w in [
        "horizon", "initial", "avoid", "analysis", "X0", "bad", "x", "g", "sin",
    ] {
        assert!(l.contains(&w), "{w} missing from {l:?}");
    }
    let x = c.iter().find(|c| c.label == "x").expect("x");
    assert_eq!(x.kind, CompletionKind::Name(SymbolKind::Vector));
    // a network spec's propagators after `propagator`
    let net = "network n { input x[2] output y[1] }\nanalysis { propagator  }\n";
    let l = completion(net, at(net, "propagator ", 0, 11));
    assert_eq!(labels(&l), ["ibp", "fast_lin", "crown", "sdp"]);
}

#[test]
fn formatting_is_fmts_and_nothing_for_broken_specs() {
    let messy = "horizon   5\n";
    assert_eq!(format(messy).as_deref(), Some("horizon 5\n"));
    assert_eq!(format("horizon"), None);
}

#[test]
fn hostile_text_gives_answers_not_panics() {
    let texts = [
        "",
        "\u{feff}",
        "x𝄞[",
        "/* unterminated",
        "\"unterminated\n",
        "1e+",
        ".5.5e-",
        "state \u{202e}x[2]",
        "state x[99999999999999999999999]",
        "system s { const a = a ^ 999999 }",
    ];
    for t in texts {
        for o in 0..=t.len() + 2 {
            let _ = hover(t, o);
            let _ = definition(t, o);
            let _ = completion(t, o);
        }
        let _ = format(t);
    }
    let big = "x".repeat(limits::MAX_SPEC_BYTES as usize + 1);
    let d = diagnostics(&big, Path::new("."), &|_| {
        Err(ravel::ReadError::Io("no files here".into()))
    });
    assert_eq!(d.len(), 1);
    assert_eq!(d[0].code, Code::Limit);
    assert_eq!(hover(&big, 0), None);
}

#[test]
fn diagnostics_are_the_front_ends() {
    let no_file = |_: &ravel::ReadRequest| Err(ravel::ReadError::Io("not found".into()));
    let d = diagnostics("horizn 5\n", Path::new("."), &no_file);
    assert_eq!(d[0].code, Code::Syntax);
    let d = diagnostics(SPEC, Path::new("."), &no_file);
    assert!(
        d.iter()
            .any(|d| d.code == Code::Missing || d.code == Code::ControllerUnreadable),
        "{d:?}"
    );
}

#[test]
fn hover_on_observe_counts_the_observations() {
    let text = "system p {\n    state x[2]\n    control u[1]\n    next x[0] = x[1]\n    next x[1] = u[0]\n    observe [x[0], x[1], x[0] * x[1]]\n}\n";
    let h = hover_text(text, at(text, "observe", 0, 1));
    assert!(h.contains("the controller sees 3 observations"), "{h}");
}
