//! Plots and the HTML report through the binary, read back with an XML
//! parser: axes with ticks and labels, the legend's entries, steps in
//! distinct colours, polytope sets as polygons, a set that constrains only
//! coordinates not shown listed instead of filling the plane, network specs'
//! two panels, the same bytes every run, and the report's table and inline
//! plots. (`scripts/test-report.sh` loads the report in a real browser.)

use std::path::{Path, PathBuf};

#[path = "common/binary.rs"]
mod binary;
use binary::ravel;

/// A fresh folder for one test.
fn folder(name: &str) -> PathBuf {
    binary::scratch("ravel-plots", name)
}

/// Plot `spec` (with extra arguments) into a fresh folder; the SVG text.
fn plot(spec: &str, extra: &[&str], expect: i32) -> String {
    // a folder per call: tests run in parallel, some plot the same spec
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = folder(&format!("plot-{n}"));
    let mut args = vec![
        "verify",
        spec,
        "--quiet",
        "--plot",
        dir.to_str().expect("utf-8"),
    ];
    args.extend(extra);
    let (code, out, err) = ravel(&args);
    assert_eq!(code, expect, "{spec}: {out}{err}");
    let name = Path::new(spec)
        .file_stem()
        .and_then(|s| s.to_str())
        .expect("name");
    let text = std::fs::read_to_string(dir.join(format!("{name}.svg"))).expect("plot written");
    let _ = std::fs::remove_dir_all(&dir);
    text
}

/// A drawn shape: its colour, its opacity or width, its points.
type Shape = (String, String, Vec<(f64, f64)>);

/// What a plot draws, as read from its SVG.
struct Facts {
    /// Every text, trimmed.
    texts: Vec<String>,
    /// Filled polygons: (fill, opacity, points).
    polygons: Vec<Shape>,
    /// Polylines: (stroke, stroke width, points).
    lines: Vec<Shape>,
    /// Filled circles' colours.
    dots: Vec<String>,
}

fn points(s: &str) -> Vec<(f64, f64)> {
    s.split_whitespace()
        .filter_map(|p| {
            let (x, y) = p.split_once(',')?;
            Some((x.parse().ok()?, y.parse().ok()?))
        })
        .collect()
}

fn facts(svg: &str) -> Facts {
    let doc = roxmltree::Document::parse(svg).expect("well-formed SVG");
    assert_eq!(doc.root_element().tag_name().name(), "svg");
    let attr = |n: &roxmltree::Node, a: &str| n.attribute(a).unwrap_or("").to_string();
    let mut f = Facts {
        texts: Vec::new(),
        polygons: Vec::new(),
        lines: Vec::new(),
        dots: Vec::new(),
    };
    for n in doc.descendants() {
        match n.tag_name().name() {
            "text" => f.texts.push(n.text().unwrap_or("").trim().to_string()),
            "polygon" => f.polygons.push((
                attr(&n, "fill"),
                attr(&n, "opacity"),
                points(&attr(&n, "points")),
            )),
            "polyline" => f.lines.push((
                attr(&n, "stroke"),
                attr(&n, "stroke-width"),
                points(&attr(&n, "points")),
            )),
            "circle" => f.dots.push(attr(&n, "fill")),
            _ => {}
        }
    }
    f
}

impl Facts {
    fn has_text(&self, part: &str) -> bool {
        self.texts.iter().any(|t| t.contains(part))
    }

    /// Tick marks: short black segments, (vertical ones, horizontal ones).
    fn ticks(&self) -> (usize, usize) {
        let mut v = (0, 0);
        for (stroke, _, p) in &self.lines {
            if stroke != "#000000" || p.len() != 2 {
                continue;
            }
            let (dx, dy) = ((p[1].0 - p[0].0).abs(), (p[1].1 - p[0].1).abs());
            if dx == 0.0 && dy > 0.0 && dy <= 8.0 {
                v.0 += 1;
            }
            if dy == 0.0 && dx > 0.0 && dx <= 8.0 {
                v.1 += 1;
            }
        }
        v
    }

    /// Tick labels: texts that are numbers.
    fn numbers(&self) -> usize {
        self.texts
            .iter()
            .filter(|t| t.parse::<f64>().is_ok())
            .count()
    }

    /// The cells' sets: polygons filled at opacity 0.1, by colour.
    fn cells(&self) -> Vec<&Shape> {
        self.polygons.iter().filter(|p| p.1 == "0.1").collect()
    }
}

#[test]
fn a_closed_loop_plot_has_axes_a_legend_and_steps_in_colour() {
    for (spec, code, cells, counterexample) in [
        ("specs/double_integrator_falsified.ravel", 1, 1, true),
        ("specs/double_integrator_partitioned.ravel", 0, 16, false),
    ] {
        let f = facts(&plot(spec, &[], code));
        // the title names the spec and its verdict
        let verdict = if code == 1 { "FALSIFIED" } else { "VERIFIED" };
        assert!(f.has_text(&format!("{spec} — {verdict}")), "{spec}");
        // axes: labels, at least four ticks each way, numeric tick labels
        assert!(f.texts.iter().any(|t| t == "x[0]") && f.texts.iter().any(|t| t == "x[1]"));
        let (v, h) = f.ticks();
        assert!(v >= 4 && h >= 4, "{spec}: ticks {v} {h}");
        assert!(f.numbers() >= 8, "{spec}: {:?}", f.texts);
        // the legend
        for entry in [
            "Legend",
            "goal G: ",
            "avoid ",
            "initial set X0 (step 0)",
            "simulated trajectories",
            "reachable set per step",
            "step 1",
            "step 5",
        ] {
            assert!(f.has_text(entry), "{spec}: no legend entry {entry}");
        }
        assert_eq!(f.has_text("partition cells"), cells > 1, "{spec}");
        // one polygon per cell and step, every step in its own colour
        assert_eq!(f.cells().len(), cells * 5, "{spec}");
        let mut colours: Vec<&str> = f.cells().iter().map(|p| p.0.as_str()).collect();
        colours.sort();
        colours.dedup();
        assert_eq!(colours.len(), 5, "{spec}: {colours:?}");
        // the steps' numbers, in their colours
        for t in 1..=5 {
            assert!(
                f.texts.iter().any(|x| *x == t.to_string()),
                "{spec}: step {t}"
            );
        }
        // a counterexample: a thick red line, red dots, a legend entry
        let thick = f.lines.iter().any(|l| l.0 == "#B71C1C" && l.1 == "2");
        assert_eq!(thick, counterexample, "{spec}");
        assert_eq!(f.has_text("counterexample of"), counterexample, "{spec}");
        assert_eq!(f.dots.iter().any(|d| d == "#B71C1C"), counterexample);
    }
}

#[test]
fn polytope_and_hull_sets_are_polygons() {
    for spec in [
        "specs/double_integrator_polytope.ravel",
        "specs/double_integrator_hull.ravel",
    ] {
        let f = facts(&plot(spec, &[], 0));
        // some cell's set has a slanted edge: not a box
        let slanted = f.cells().iter().any(|(_, _, p)| {
            (0..p.len()).any(|k| {
                let (a, b) = (p[k], p[(k + 1) % p.len()]);
                (a.0 - b.0).abs() > 1.0 && (a.1 - b.1).abs() > 1.0
            })
        });
        assert!(slanted, "{spec}: every set drawn as a box");
        assert!(f.has_text("polygons"), "{spec}");
    }
}

#[test]
fn a_set_on_coordinates_not_shown_is_listed_not_filled() {
    // quadrotor: `ground = { x[2] <= 0.5 }` on the x[0]/x[1] plot
    let f = facts(&plot("specs/quadrotor_gsg.ravel", &[], 0));
    assert!(
        !f.polygons.iter().any(|p| p.0 == "#C62828"),
        "the ground is filled on a plane it does not constrain"
    );
    assert!(f.has_text("avoid ground: VERIFIED: constrains only"));
    assert!(f.has_text("(x[2] <= 0.5), not drawn"));
    // the goal constrains x[2] too: hatched, with its other inequalities
    assert!(f.has_text("goal G: VERIFIED: also constrains x[2] <= 2.5,"));
    assert!(!f.polygons.iter().any(|p| p.0 == "#2E7D32" && p.1 != "0.3"));
    // on x[0]/x[2] the ground is a set of the plot's coordinates, below
    // every state: outside the view, and said so
    let f = facts(&plot(
        "specs/quadrotor_gsg.ravel",
        &["--plot-dims", "0,2"],
        0,
    ));
    assert!(f.texts.iter().any(|t| t == "x[2]"));
    assert!(f.has_text("avoid ground: VERIFIED: outside the view"));
    assert!(!f.has_text("constrains only"));
}

/// A plant in continuous time: each period's enclosure (the states between
/// the sampling instants) drawn lightly behind the steps' sets, in the
/// legend; a discrete-time plant has none.
#[test]
fn intersample_enclosures_are_drawn_lightly_with_a_legend_entry() {
    let entry = "states between the sampling instants";
    let light = |f: &Facts| -> Vec<Vec<(f64, f64)>> {
        f.polygons
            .iter()
            .filter(|p| p.1 == "0.04")
            .map(|p| p.2.clone())
            .collect()
    };
    // one cell, five periods; the band x[0] ∈ [1.9, 2] lies between steps 1
    // and 2, so the enclosure of period 2 reaches across it while no step's
    // set touches it (a trajectory crosses it there: the spec is FALSIFIED)
    let svg = plot("specs/double_integrator_continuous_between.ravel", &[], 1);
    let f = facts(&svg);
    assert!(f.has_text(entry), "{:?}", f.texts);
    let periods = light(&f);
    assert_eq!(periods.len(), 5);
    let width = |p: &Vec<(f64, f64)>| {
        let xs = p.iter().map(|q| q.0);
        xs.clone().fold(f64::MIN, f64::max) - xs.fold(f64::MAX, f64::min)
    };
    // each period's enclosure spans at least its two instants' sets in x
    let cells = f.cells();
    assert_eq!(cells.len(), 5);
    for (k, p) in periods.iter().enumerate().skip(1) {
        assert!(width(p) + 1e-6 >= width(&cells[k].2), "period {}", k + 1);
    }
    // a nonlinear plant in continuous time: one per cell and period
    let f = facts(&plot("specs/damped_pendulum.ravel", &[], 0));
    assert!(f.has_text(entry));
    assert_eq!(light(&f).len(), f.cells().len());
    // a plant in discrete time has nothing between its instants
    let f = facts(&plot("specs/double_integrator.ravel", &[], 0));
    assert!(!f.has_text(entry));
    assert!(light(&f).is_empty());
}

/// A radius search: the input set scaled to the certified scale (a thick
/// green outline) inside the one scaled to the attacked scale (dashed red),
/// with the attack's input as a red dot, and both scales in the legend.
#[test]
fn a_radius_search_draws_its_certified_and_attacked_radii() {
    let f = facts(&plot("specs/network/classifier_robust.ravel", &[], 0));
    assert!(f.has_text("radius eps for sector: certified up to"));
    assert!(f.has_text("radius eps: violated at scale"));
    let extent = |p: &[(f64, f64)]| {
        let xs = p.iter().map(|q| q.0);
        xs.clone().fold(f64::MIN, f64::max) - xs.fold(f64::MAX, f64::min)
    };
    let certified: Vec<&Shape> = f
        .lines
        .iter()
        .filter(|l| l.0 == "#2E7D32" && l.1 == "2" && l.2.len() >= 4)
        .collect();
    assert_eq!(certified.len(), 1, "one certified outline (and its swatch)");
    // the dashed outline is drawn in pieces: its extent is the pieces'
    let attacked: Vec<(f64, f64)> = f
        .lines
        .iter()
        .filter(|l| l.0 == "#C62828")
        .flat_map(|l| l.2.clone())
        .collect();
    assert!(extent(&attacked) > extent(&certified[0].2));
    assert!(f.dots.iter().any(|d| d == "#B71C1C"), "the attack's input");
    // a spec without a radius search has none of it
    let f = facts(&plot("specs/network/policy_output_set.ravel", &[], 0));
    assert!(!f.has_text("certified up to"));
}

#[test]
fn sets_outside_the_view_are_listed() {
    // double_integrator's avoid set `overshoot` lies beyond every state
    let f = facts(&plot("specs/double_integrator.ravel", &[], 0));
    assert!(f.has_text("avoid overshoot: VERIFIED: outside the view"));
}

#[test]
fn an_overflowing_loop_is_plotted_without_a_panic() {
    // states grow by 1e15 a step until the bounds overflow: trajectories
    // far beyond the window are cut to it, whole-space sets are listed
    let dir = folder("overflow-spec");
    std::fs::create_dir_all(&dir).expect("folder");
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/double_integrator.onnx");
    let spec = format!(
        "system s {{\n    state   x[2]\n    control u[1]\n    A = [[1e15, 1e15], [1e15, 1e15]]\n    B = [[0.5], [1]]\n    u in box([-1, 1])\n}}\n\ncontroller \"{}\"\n\ninitial X0 = box(x[0] in [2.5, 3.0], x[1] in [-0.25, 0.25])\ngoal    G  = box(x[0] in [-1.5, 2.0], x[1] in [-1.5, 0.5])\nhorizon 30\n\nanalysis {{\n    samples 200\n}}\n",
        model.display()
    );
    let path = dir.join("overflow.ravel");
    std::fs::write(&path, spec).expect("spec written");
    let f = facts(&plot(path.to_str().expect("utf-8"), &[], 3));
    assert!(f.has_text("sets are the whole space"), "{:?}", f.texts);
    assert!(f.has_text("sets reach beyond 1e150"), "{:?}", f.texts);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn plots_are_the_same_bytes_every_run() {
    for spec in [
        "specs/double_integrator_partitioned.ravel",
        "specs/network/classifier_falsified.ravel",
    ] {
        let code = if spec.contains("falsified") { 1 } else { 0 };
        assert_eq!(
            plot(spec, &[], code),
            plot(spec, &["--jobs", "1"], code),
            "{spec}"
        );
    }
}

#[test]
fn network_specs_are_plotted_input_and_output() {
    let f = facts(&plot("specs/network/classifier_falsified.ravel", &[], 1));
    for label in ["x[0]", "x[1]", "y[0]", "y[1]"] {
        assert!(f.texts.iter().any(|t| t == label), "no axis {label}");
    }
    let (v, h) = f.ticks();
    assert!(v >= 8 && h >= 8, "two panels' ticks: {v} {h}");
    for entry in [
        "input set X (left)",
        "16 input cells",
        "certified output set (right)",
        "sampled inputs and their outputs",
        "counterexample of robust nominal",
        "avoid not_one (part 1): FALSIFIED",
    ] {
        assert!(f.has_text(entry), "no legend entry {entry}");
    }
    // the avoid set's first part (y[0] >= y[1]) is a region of y[0]/y[1]
    assert!(f.polygons.iter().any(|p| p.0 == "#C62828" && p.1 == "0.15"));
    // its second part (y[2] >= y[1]) involves y[2]: listed
    assert!(f.has_text("avoid not_one (part 2): FALSIFIED: constrains"));
    // the counterexample's input and its output (and the legend's dot)
    assert_eq!(f.dots.iter().filter(|d| *d == "#B71C1C").count(), 3);
    // --plot-dims picks outputs
    let f = facts(&plot(
        "specs/network/classifier_falsified.ravel",
        &["--plot-dims", "2,1"],
        1,
    ));
    assert!(f.texts.iter().any(|t| t == "y[2]"));
    assert!(f.has_text("avoid not_one (part 2): FALSIFIED"));
    // one output: against the first input
    let f = facts(&plot("specs/network/policy_output_set.ravel", &[], 0));
    assert!(f.has_text("certified output bounds: u[0] in ["));
    assert!(f.has_text("require bounded: VERIFIED"));
    // outputs that do not exist: an error naming them
    let dir = folder("dims");
    let (code, _, err) = ravel(&[
        "verify",
        "specs/network/classifier_falsified.ravel",
        "--quiet",
        "--plot-dims",
        "0,3",
        "--plot",
        dir.to_str().expect("utf-8"),
    ]);
    assert_eq!(code, 2);
    assert!(
        err.contains("the output has 3 coordinates (0 to 2)"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn wrong_plot_dims_are_an_error_and_the_other_pairs_still_run() {
    let dir = folder("wrong-dims");
    let (code, _, err) = ravel(&[
        "verify",
        "specs/double_integrator.ravel",
        "--quiet",
        "--plot-dims",
        "0,5",
        "--plot",
        dir.to_str().expect("utf-8"),
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("the state has 2 coordinates"), "{err}");
    let (code, _, _) = ravel(&[
        "verify",
        "specs/double_integrator.ravel",
        "--plot-dims",
        "1,1",
    ]);
    assert_eq!(code, 2);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The report of a batch: `--report DIR` over closed loops, a network spec
/// and a spec that does not check.
fn report(dir: &Path, jobs: &str) -> String {
    let (code, out, err) = ravel(&[
        "verify",
        "specs/double_integrator.ravel",
        "specs/double_integrator_falsified.ravel",
        "specs/invalid/wrong_shape.ravel",
        "specs/network/classifier_falsified.ravel",
        "--quiet",
        "--no-timing",
        "--jobs",
        jobs,
        "--report",
        dir.to_str().expect("utf-8"),
    ]);
    assert_eq!(code, 2, "{out}{err}");
    std::fs::read_to_string(dir.join("index.html")).expect("report written")
}

#[test]
fn the_report_is_one_self_contained_page_with_a_row_and_a_plot_per_pair() {
    let dir = folder("report");
    let page = report(&dir, "1");
    let options = roxmltree::ParsingOptions {
        allow_dtd: true,
        ..Default::default()
    };
    let doc = roxmltree::Document::parse_with_options(&page, options).expect("well-formed");
    let rows: Vec<_> = doc
        .descendants()
        .filter(|n| n.has_tag_name("tr") && n.attribute("class") == Some("pair"))
        .collect();
    assert_eq!(rows.len(), 4);
    let cells = |r: &roxmltree::Node| -> Vec<String> {
        r.children()
            .filter(|c| c.has_tag_name("td"))
            .map(|c| {
                c.descendants()
                    .filter(|d| d.is_text())
                    .filter_map(|d| d.text())
                    .collect::<String>()
            })
            .collect()
    };
    let verdicts: Vec<String> = rows.iter().map(|r| cells(r)[3].clone()).collect();
    assert_eq!(verdicts, ["VERIFIED", "FALSIFIED", "ERROR", "FALSIFIED"]);
    // properties with their margins
    let first = cells(&rows[0]);
    assert!(first[4].contains("goal G: VERIFIED margin"), "{first:?}");
    assert!(first[4].contains("at step 5"), "{first:?}");
    assert!(first[5].contains("propagator calls"), "{first:?}");
    let second = cells(&rows[1]);
    assert!(second[4].contains("violated by"), "{second:?}");
    assert!(
        cells(&rows[2])[4].contains("error"),
        "{:?}",
        cells(&rows[2])
    );
    // every pair that ran has its plot inline, as SVG
    let figures: Vec<_> = doc
        .descendants()
        .filter(|n| n.has_tag_name("figure"))
        .collect();
    assert_eq!(figures.len(), 3);
    for f in &figures {
        let svg = f.first_element_child().expect("an SVG");
        assert_eq!(svg.tag_name().name(), "svg");
        assert!(svg.descendants().any(|n| n.has_tag_name("polygon")));
    }
    // nothing from elsewhere: no links, no external sources, one inline script
    for n in doc.descendants() {
        for a in ["src", "href"] {
            if let Some(v) = n.attribute(a) {
                assert!(v.starts_with('#'), "{a}={v}");
            }
        }
        assert!(!n.has_tag_name("link") && !n.has_tag_name("img"));
    }
    assert_eq!(
        doc.descendants()
            .filter(|n| n.has_tag_name("script"))
            .count(),
        1
    );
    // the same page for any number of jobs
    let other = folder("report-jobs");
    assert_eq!(report(&other, "2"), page);
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&other);
}

#[test]
fn names_with_markup_stay_text() {
    // a spec file named like markup: the page stays well-formed, with one
    // script, and the name appears as text
    let dir = folder("markup");
    let sub = dir.join("a<script>b&c");
    std::fs::create_dir_all(&sub).expect("folder");
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/double_integrator.onnx");
    let spec = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("specs/double_integrator.ravel"),
    )
    .expect("spec")
    .replace(
        "\"../models/double_integrator.onnx\"",
        &format!("\"{}\"", model.display()),
    );
    let path = sub.join("x<y>.ravel");
    std::fs::write(&path, spec).expect("spec written");
    let report = dir.join("report");
    let (code, out, err) = ravel(&[
        "verify",
        path.to_str().expect("utf-8"),
        "--quiet",
        "--report",
        report.to_str().expect("utf-8"),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    let page = std::fs::read_to_string(report.join("index.html")).expect("report");
    let options = roxmltree::ParsingOptions {
        allow_dtd: true,
        ..Default::default()
    };
    let doc = roxmltree::Document::parse_with_options(&page, options).expect("well-formed");
    assert_eq!(
        doc.descendants()
            .filter(|n| n.has_tag_name("script"))
            .count(),
        1
    );
    assert!(doc.descendants().filter(|n| n.is_text()).any(|n| n
        .text()
        .is_some_and(|t| t.contains("a<script>b&c/x<y>.ravel"))));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_report_needs_the_whole_batch() {
    let dir = folder("report-shard");
    let (code, _, err) = ravel(&[
        "verify",
        "specs/double_integrator.ravel",
        "--shard",
        "1/2",
        "--report",
        dir.to_str().expect("utf-8"),
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("--shard"), "{err}");
    assert!(!dir.join("index.html").exists());
}
