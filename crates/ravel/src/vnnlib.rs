//! VNN-LIB import: a property file of the verification competition → the
//! equivalent ravel network specs (text), one per input region.
//!
//! A VNN-LIB file declares the inputs `X_0 … X_{n−1}` and outputs
//! `Y_0 … Y_{m−1}` and asserts constraints whose conjunction describes a
//! *counterexample*: the property holds when no input satisfying the input
//! constraints produces outputs satisfying the output constraints. ravel
//! states that as input sets and `avoid` sets over the outputs:
//!
//! * every constraint is a linear (in)equality over the `X_i` only or the
//!   `Y_j` only, under any nesting of `and` and `or`; the conjunction of
//!   the asserts is expanded into disjunctive normal form (at most
//!   [`MAX_MEMBERS`] disjuncts);
//! * the disjuncts are grouped by their input constraints: each group is
//!   an **input region** (bounds of single variables make a box, anything
//!   else a polytope; every input must be bounded), and the union of the
//!   group's output conjunctions is that region's `avoid` set.
//!
//! **Semantics of input disjunctions.** A property whose input part is a
//! disjunction (ACAS Xu's property 6, or the `(or (and X… Y…) …)` form of
//! VNN-COMP 2022 and later) is a union of input regions: one spec per
//! region. The property holds (`unsat`) only if every region's spec is
//! VERIFIED, and is violated (`sat`) if any region's spec is FALSIFIED;
//! otherwise it is undecided. Without input disjunctions there is one
//! region and one spec, as before.
//!
//! Not supported, each with a message naming the line: constraints mixing
//! `X` and `Y` in one comparison, non-linear terms, other sorts than
//! `Real`, and any other command. Strict comparisons (`<`, `>`)
//! are read as non-strict: the avoid set is then the closure of the unsafe
//! set, which makes VERIFIED (a positive separation) exact, and a
//! FALSIFIED input may lie on the boundary of the unsafe set (the generated
//! spec says so).

// the importer reads untrusted text: no panicking shortcuts
#![deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]

use std::collections::BTreeMap;
use std::fmt::Write;

/// The most members the expanded avoid set may have.
pub const MAX_MEMBERS: usize = 1000;

/// Why a file could not be imported: the 1-based line and column, and what.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportError {
    /// Byte offset in the text (for a span).
    pub offset: usize,
    /// 1-based line.
    pub line: usize,
    /// 1-based column (characters).
    pub column: usize,
    /// What is wrong or unsupported.
    pub message: String,
}

#[derive(Clone, Debug, PartialEq)]
enum Sexp {
    Atom(String, usize),
    List(Vec<Sexp>, usize),
}

impl Sexp {
    fn at(&self) -> usize {
        match self {
            Sexp::Atom(_, p) | Sexp::List(_, p) => *p,
        }
    }
}

struct Ctx<'a> {
    text: &'a str,
}

impl Ctx<'_> {
    fn err(&self, at: usize, message: impl Into<String>) -> ImportError {
        // positions are of ASCII characters (or the end): character boundaries
        let before = self.text.get(..at.min(self.text.len())).unwrap_or_default();
        let line = before.matches('\n').count() + 1;
        let column = before
            .rsplit('\n')
            .next()
            .map_or(1, |l| l.chars().count() + 1);
        ImportError {
            offset: at.min(self.text.len()),
            line,
            column,
            message: message.into(),
        }
    }
}

fn parse_sexps(cx: &Ctx, text: &str) -> Result<Vec<Sexp>, ImportError> {
    let bytes = text.as_bytes();
    let mut stack: Vec<(Vec<Sexp>, usize)> = vec![(Vec::new(), 0)];
    let mut i = 0;
    while let Some(&c) = bytes.get(i) {
        match c {
            b';' => {
                while bytes.get(i).is_some_and(|&b| b != b'\n') {
                    i += 1;
                }
            }
            b'(' => {
                if stack.len() > 64 {
                    return Err(cx.err(i, "expressions nested more than 64 deep"));
                }
                stack.push((Vec::new(), i));
                i += 1;
            }
            b')' => {
                if stack.len() < 2 {
                    return Err(cx.err(i, "`)` without a matching `(`"));
                }
                let (items, start) = stack.pop().unwrap_or_default();
                if let Some(top) = stack.last_mut() {
                    top.0.push(Sexp::List(items, start));
                }
                i += 1;
            }
            c if c.is_ascii_whitespace() => i += 1,
            _ => {
                let start = i;
                while bytes
                    .get(i)
                    .is_some_and(|b| !b.is_ascii_whitespace() && !matches!(b, b'(' | b')' | b';'))
                {
                    i += 1;
                }
                let atom =
                    String::from_utf8_lossy(bytes.get(start..i).unwrap_or_default()).into_owned();
                if let Some(top) = stack.last_mut() {
                    top.0.push(Sexp::Atom(atom, start));
                }
            }
        }
    }
    if stack.len() > 1 {
        let at = stack.last().map_or(0, |s| s.1);
        return Err(cx.err(at, "`(` is never closed"));
    }
    Ok(stack.pop().map(|s| s.0).unwrap_or_default())
}

/// A linear form `Σ coef·var + constant` over `X_i` (`false`) or `Y_j` (`true`).
#[derive(Clone, Debug, Default)]
struct Linear {
    terms: BTreeMap<(bool, usize), f64>,
    constant: f64,
}

impl Linear {
    fn scaled(mut self, k: f64) -> Linear {
        for v in self.terms.values_mut() {
            *v *= k;
        }
        self.constant *= k;
        self
    }
    fn plus(mut self, o: Linear) -> Linear {
        for (k, v) in o.terms {
            *self.terms.entry(k).or_insert(0.0) += v;
        }
        self.constant += o.constant;
        self
    }
}

/// `Σ a·v ≤ b` over inputs or outputs.
#[derive(Clone, Debug, PartialEq)]
struct Row {
    coefs: Vec<(usize, f64)>,
    rhs: f64,
}

/// A constraint tree; each row constrains the inputs (`false`) or the
/// outputs (`true`).
enum Tree {
    Row(bool, Row),
    And(Vec<Tree>),
    Or(Vec<Tree>),
}

struct Importer<'a> {
    cx: Ctx<'a>,
    inputs: usize,
    outputs: usize,
    declared: BTreeMap<(bool, usize), usize>,
}

/// Text from the file, safe to print (control characters escaped, long text cut).
fn clean(s: &str) -> String {
    ravel_syntax::diag::sanitize(s)
}

fn number(s: &str) -> Option<f64> {
    let v: f64 = s.parse().ok()?;
    v.is_finite().then_some(v)
}

impl Importer<'_> {
    fn variable(&self, s: &str) -> Option<(bool, usize)> {
        let (out, rest) = if let Some(r) = s.strip_prefix("X_") {
            (false, r)
        } else if let Some(r) = s.strip_prefix("Y_") {
            (true, r)
        } else {
            return None;
        };
        rest.parse::<usize>().ok().map(|k| (out, k))
    }

    fn linear(&self, e: &Sexp) -> Result<Linear, ImportError> {
        match e {
            Sexp::Atom(a, at) => {
                if let Some(v) = number(a) {
                    return Ok(Linear {
                        terms: BTreeMap::new(),
                        constant: v,
                    });
                }
                match self.variable(a) {
                    Some(var) if self.declared.contains_key(&var) => {
                        let mut terms = BTreeMap::new();
                        terms.insert(var, 1.0);
                        Ok(Linear {
                            terms,
                            constant: 0.0,
                        })
                    }
                    Some(_) => Err(self.cx.err(*at, format!("`{}` is not declared", clean(a)))),
                    None => Err(self.cx.err(
                        *at,
                        format!(
                            "`{}` is neither a number nor a variable X_i or Y_j",
                            clean(a)
                        ),
                    )),
                }
            }
            Sexp::List(items, at) => {
                let (head, args) = match items.split_first() {
                    Some((Sexp::Atom(h, _), rest)) => (h.as_str(), rest),
                    _ => return Err(self.cx.err(*at, "expected an arithmetic expression")),
                };
                match (head, args) {
                    ("+", [_, ..]) => {
                        let mut acc = Linear::default();
                        for a in args {
                            acc = acc.plus(self.linear(a)?);
                        }
                        Ok(acc)
                    }
                    ("-", [a]) => Ok(self.linear(a)?.scaled(-1.0)),
                    ("-", [first, rest @ ..]) => {
                        let mut acc = self.linear(first)?;
                        for a in rest {
                            acc = acc.plus(self.linear(a)?.scaled(-1.0));
                        }
                        Ok(acc)
                    }
                    ("*", [a, b]) => {
                        let (a, b) = (self.linear(a)?, self.linear(b)?);
                        if a.terms.is_empty() {
                            Ok(b.scaled(a.constant))
                        } else if b.terms.is_empty() {
                            Ok(a.scaled(b.constant))
                        } else {
                            Err(self.cx.err(*at, "a product of two variables is not linear"))
                        }
                    }
                    _ => Err(self.cx.err(
                        *at,
                        format!("`{}` with {} argument(s) is not a supported linear term (supported: +, -, * by a constant)", clean(head), args.len()),
                    )),
                }
            }
        }
    }

    /// A constraint.
    fn constraint(&self, e: &Sexp) -> Result<Tree, ImportError> {
        let Sexp::List(items, at) = e else {
            return Err(self.cx.err(
                e.at(),
                "expected a constraint `(<= a b)`, `(and …)` or `(or …)`",
            ));
        };
        let (head, args) = match items.split_first() {
            Some((Sexp::Atom(h, _), rest)) => (h.as_str(), rest),
            _ => return Err(self.cx.err(*at, "expected a constraint")),
        };
        match (head, args) {
            ("and" | "or", _) => {
                if args.is_empty() {
                    return Err(self.cx.err(*at, format!("an empty `{head}` is not supported")));
                }
                let mut parts = Vec::new();
                for a in args {
                    parts.push(self.constraint(a)?);
                }
                Ok(if head == "or" { Tree::Or(parts) } else { Tree::And(parts) })
            }
            ("<=" | ">=" | "<" | ">" | "=", [lhs, rhs]) => {
                let mut diff = self.linear(lhs)?.plus(self.linear(rhs)?.scaled(-1.0));
                diff.terms.retain(|_, v| *v != 0.0);
                if diff.terms.is_empty() {
                    return Err(self.cx.err(*at, "a comparison without variables constrains nothing"));
                }
                let out = diff.terms.keys().next().is_some_and(|k| k.0);
                if diff.terms.keys().any(|k| k.0 != out) {
                    return Err(self.cx.err(*at, "a constraint relating inputs and outputs is not supported"));
                }
                let le = |d: &Linear, sign: f64| Row {
                    coefs: d.terms.iter().map(|((_, i), v)| (*i, sign * v)).collect(),
                    rhs: -sign * d.constant,
                };
                Ok(match head {
                    "<=" | "<" => Tree::Row(out, le(&diff, 1.0)),
                    ">=" | ">" => Tree::Row(out, le(&diff, -1.0)),
                    _ => Tree::And(vec![Tree::Row(out, le(&diff, 1.0)), Tree::Row(out, le(&diff, -1.0))]),
                })
            }
            _ => Err(self.cx.err(*at, format!("`{}` with {} argument(s) is not a supported constraint (supported: <=, >=, <, >, = with two sides; and, or)", clean(head), args.len()))),
        }
    }
}

/// A conjunction of rows, each on the inputs (`false`) or the outputs (`true`).
type Conjunction = Vec<(bool, Row)>;

/// Disjunctive normal form of a tree: a list of conjunctions (`None` past
/// `limit` of them).
fn dnf(t: Tree, limit: usize) -> Option<Vec<Conjunction>> {
    match t {
        Tree::Row(out, r) => Some(vec![vec![(out, r)]]),
        Tree::Or(parts) => {
            let mut out = Vec::new();
            for p in parts {
                out.extend(dnf(p, limit)?);
                if out.len() > limit {
                    return None;
                }
            }
            Some(out)
        }
        Tree::And(parts) => {
            let mut acc: Vec<Conjunction> = vec![Vec::new()];
            for p in parts {
                let d = dnf(p, limit)?;
                let mut next = Vec::new();
                for a in &acc {
                    for b in &d {
                        next.push(a.iter().chain(b).cloned().collect());
                        if next.len() > limit {
                            return None;
                        }
                    }
                }
                acc = next;
            }
            Some(acc)
        }
    }
}

/// One input region and the outputs that must not occur for its inputs:
/// the input rows (a conjunction) and the avoid set's members.
struct Region {
    inputs: Vec<Row>,
    members: Vec<Vec<Row>>,
}

/// The disjuncts grouped by their input rows, in order of first
/// appearance: the counterexamples are the union over the regions of
/// (input in the region, output in one of its members).
fn regions(conjunctions: Vec<Conjunction>) -> Vec<Region> {
    let mut out: Vec<Region> = Vec::new();
    for c in conjunctions {
        let (ins, outs): (Vec<_>, Vec<_>) = c.into_iter().partition(|(o, _)| !*o);
        let inputs: Vec<Row> = ins.into_iter().map(|(_, r)| r).collect();
        let member: Vec<Row> = outs.into_iter().map(|(_, r)| r).collect();
        match out.iter_mut().find(|g| g.inputs == inputs) {
            Some(g) => g.members.push(member),
            None => out.push(Region {
                inputs,
                members: vec![member],
            }),
        }
    }
    out
}

fn fmt_num(v: f64) -> String {
    let v = v + 0.0; // no `-0.0`
                     // `{:?}` prints the shortest text that reads back as the same f64
    let s = format!("{v:?}");
    if s.contains('e') || s.contains('.') {
        s
    } else {
        format!("{s}.0")
    }
}

fn row_text(r: &Row, var: &str) -> String {
    let mut s = String::new();
    for (k, (i, c)) in r.coefs.iter().enumerate() {
        let (sign, mag) = if *c < 0.0 { ("-", -c) } else { ("+", *c) };
        if k == 0 {
            if sign == "-" {
                s.push('-');
            }
        } else {
            let _ = write!(s, " {sign} ");
        }
        if mag == 1.0 {
            let _ = write!(s, "{var}[{i}]");
        } else {
            let _ = write!(s, "{} {var}[{i}]", fmt_num(mag));
        }
    }
    let _ = write!(s, " <= {}", fmt_num(r.rhs));
    s
}

/// Import a VNN-LIB property: the ravel network specs that state it, one
/// per input region, for the network stored at `model_path` (its sizes are
/// the declared `X_i` and `Y_j`, which must run from 0 without gaps; the
/// front end then checks them against the model); `name` names the
/// network and `source` the file.
///
/// The asserts are expanded into disjunctive normal form, and the
/// disjuncts grouped by their input constraints: each group is an input
/// region with the union of its output conjunctions as the avoid set. A
/// property without input disjunctions is one region, one spec (the
/// single-disjunct form `(assert (or (and X… Y…)))` of VNN-COMP 2022 and
/// later included). With several regions, the property holds if and only
/// if every region's spec is VERIFIED, and it is violated if any region's
/// spec is FALSIFIED.
pub fn import(
    text: &str,
    model_path: &str,
    name: &str,
    source: &str,
) -> Result<Vec<String>, ImportError> {
    let cx = Ctx { text };
    let sexps = parse_sexps(&cx, text)?;
    let mut im = Importer {
        cx,
        inputs: ravel_base::limits::MAX_DIM as usize,
        outputs: ravel_base::limits::MAX_DIM as usize,
        declared: BTreeMap::new(),
    };
    let mut asserted = Asserted::default();
    for e in &sexps {
        im.command(e, &mut asserted)?;
    }
    im.count_declared()?;
    let conjunctions = dnf(Tree::And(asserted.trees), MAX_MEMBERS).ok_or_else(|| {
        im.cx.err(
            0,
            format!("the constraints expand into more than {MAX_MEMBERS} disjuncts"),
        )
    })?;
    let regions = regions(conjunctions);
    if regions
        .iter()
        .any(|r| r.members.iter().any(|m| m.is_empty()))
    {
        return Err(im.cx.err(
            0,
            "there is no constraint on the outputs (in some disjunct): every input would be a counterexample",
        ));
    }
    let count = regions.len();
    let mut specs = Vec::with_capacity(count);
    for (k, region) in regions.iter().enumerate() {
        specs.push(im.spec(
            region,
            (k + 1, count),
            model_path,
            name,
            source,
            asserted.strict,
        )?);
    }
    Ok(specs)
}

impl Importer<'_> {
    /// The spec of one region (`which`: its number and the count).
    fn spec(
        &self,
        region: &Region,
        which: (usize, usize),
        model_path: &str,
        name: &str,
        source: &str,
        strict: bool,
    ) -> Result<String, ImportError> {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "// Imported from {} by ravel import-vnnlib.",
            ravel_syntax::diag::sanitize(source)
        );
        let _ = writeln!(
            s,
            "// VNN-LIB asserts describe a counterexample; ravel states the property as"
        );
        let _ = writeln!(
            s,
            "// the input set and the outputs that must never occur (the avoid set)."
        );
        if which.1 > 1 {
            let _ = writeln!(
                s,
                "// Input region {} of {}: the property holds only if every region's spec",
                which.0, which.1
            );
            let _ = writeln!(
                s,
                "// is VERIFIED; a FALSIFIED region is a counterexample of the property."
            );
        }
        if strict {
            let _ = writeln!(
                s,
                "// Strict comparisons are read as non-strict: the avoid set is the closure"
            );
            let _ = writeln!(
                s,
                "// of the unsafe set, so a FALSIFIED input may lie on its boundary."
            );
        }
        let _ = writeln!(
            s,
            "\nnetwork {name} {{\n    input  x[{}]\n    output y[{}]\n}}\n",
            self.inputs, self.outputs
        );
        let _ = writeln!(s, "model \"{}\"\n", model_path.replace('"', "\\\""));
        s += &self.input_set(&region.inputs)?;
        let texts: Vec<String> = region
            .members
            .iter()
            .map(|m| {
                let rows: Vec<String> = m.iter().map(|r| row_text(r, "y")).collect();
                format!("{{ {} }}", rows.join(", "))
            })
            .collect();
        let _ = writeln!(s, "avoid unsafe = {}\n", texts.join("\n             | "));
        let _ = writeln!(
            s,
            "analysis {{\n    propagator  crown\n    partitioner bab\n    shape       box\n    samples     1000\n    seed        0\n}}"
        );
        Ok(s)
    }
}

/// What the asserts say: their constraints (a conjunction), and whether a
/// strict comparison occurs.
#[derive(Default)]
struct Asserted {
    trees: Vec<Tree>,
    strict: bool,
}

impl Importer<'_> {
    /// One top-level command: a declaration, or an assert added to
    /// `asserted`.
    fn command(&mut self, e: &Sexp, asserted: &mut Asserted) -> Result<(), ImportError> {
        let Sexp::List(items, at) = e else {
            return Err(self.cx.err(
                e.at(),
                "expected a command `(declare-const …)` or `(assert …)`",
            ));
        };
        match items.as_slice() {
            [Sexp::Atom(h, _), ..] if h == "declare-const" => self.declare(items, *at),
            [Sexp::Atom(h, _), body] if h == "assert" => {
                asserted.strict |= contains_strict(body);
                asserted.trees.push(self.constraint(body)?);
                Ok(())
            }
            [Sexp::Atom(h, hat), ..] => Err(self.cx.err(
                *hat,
                format!(
                    "command `{}` is not supported (supported: declare-const, assert)",
                    clean(h)
                ),
            )),
            _ => Err(self.cx.err(*at, "expected a command")),
        }
    }

    /// `(declare-const NAME Real)` (`items`, at `at`) of an input `X_i` or
    /// an output `Y_j`, each once.
    fn declare(&mut self, items: &[Sexp], at: usize) -> Result<(), ImportError> {
        let (var, sort) = match items {
            [_, Sexp::Atom(v, vat), Sexp::Atom(s, sat)] => ((v.as_str(), *vat), (s.as_str(), *sat)),
            _ => return Err(self.cx.err(at, "expected `(declare-const NAME Real)`")),
        };
        if sort.0 != "Real" {
            return Err(self.cx.err(
                sort.1,
                format!("sort `{}` is not supported (only Real)", clean(sort.0)),
            ));
        }
        let Some(v) = self.variable(var.0) else {
            return Err(self.cx.err(
                var.1,
                format!("`{}` is not an input X_i or an output Y_j", clean(var.0)),
            ));
        };
        if v.1 >= self.inputs {
            return Err(self.cx.err(
                var.1,
                format!(
                    "`{}`: ravel analyses at most {} inputs and outputs",
                    clean(var.0),
                    self.inputs
                ),
            ));
        }
        if self.declared.insert(v, var.1).is_some() {
            return Err(self
                .cx
                .err(var.1, format!("`{}` is declared twice", clean(var.0))));
        }
        Ok(())
    }

    /// The numbers of inputs and outputs: the declared `X_i` and `Y_j`,
    /// which must run from 0 without gaps.
    fn count_declared(&mut self) -> Result<(), ImportError> {
        for (out, letter) in [(false, 'X'), (true, 'Y')] {
            let count = self.declared.keys().filter(|k| k.0 == out).count();
            if count == 0 {
                return Err(self.cx.err(0, format!("no {letter}_i is declared")));
            }
            if let Some(((_, k), at)) = self
                .declared
                .iter()
                .find(|((o, k), _)| *o == out && *k >= count)
            {
                return Err(self.cx.err(*at, format!("{letter}_{k} is declared but not every {letter}_i below it: indices must run from 0 without gaps")));
            }
            if out {
                self.outputs = count;
            } else {
                self.inputs = count;
            }
        }
        Ok(())
    }

    /// The input set's item (`input X = …`) from the input rows: a box when
    /// every row bounds one variable (then every input needs both bounds),
    /// else a polytope of the other rows and the bounds.
    fn input_set(&self, input_rows: &[Row]) -> Result<String, ImportError> {
        let mut lo = vec![f64::NEG_INFINITY; self.inputs];
        let mut hi = vec![f64::INFINITY; self.inputs];
        let mut general = Vec::new();
        for r in input_rows {
            // every variable is declared, and the declared indices run
            // from 0 to `inputs` without gaps: `i` is in range
            match r.coefs.as_slice() {
                // a coefficient of ±1 only: `rhs / c` is then exact (any
                // other would round, and the box could lose a sliver of
                // the region); other rows stay rows of a polytope
                [(i, c)] if *c == 1.0 => {
                    if let Some(h) = hi.get_mut(*i) {
                        *h = h.min(r.rhs);
                    }
                }
                [(i, c)] if *c == -1.0 => {
                    if let Some(l) = lo.get_mut(*i) {
                        *l = l.max(-r.rhs);
                    }
                }
                _ => general.push(r.clone()),
            }
        }
        let bounds = lo.iter().zip(&hi).enumerate();
        if general.is_empty() {
            if let Some(i) = lo
                .iter()
                .zip(&hi)
                .position(|(l, h)| !(l.is_finite() && h.is_finite()))
            {
                return Err(self.cx.err(
                    0,
                    format!("X_{i} is not bounded: every input needs a lower and an upper bound"),
                ));
            }
            let parts: Vec<String> = bounds
                .map(|(i, (l, h))| format!("x[{i}] in [{}, {}]", fmt_num(*l), fmt_num(*h)))
                .collect();
            Ok(format!(
                "input X = box({})\n\n",
                parts.join(",\n              ")
            ))
        } else {
            let mut rows: Vec<String> = general.iter().map(|r| row_text(r, "x")).collect();
            for (i, (l, h)) in bounds {
                if l.is_finite() {
                    rows.push(format!("x[{i}] >= {}", fmt_num(*l)));
                }
                if h.is_finite() {
                    rows.push(format!("x[{i}] <= {}", fmt_num(*h)));
                }
            }
            Ok(format!(
                "input X = {{ {} }}\n\n",
                rows.join(",\n            ")
            ))
        }
    }
}
/// Whether a property uses a strict comparison (`<`, `>`), which the
/// specs read as non-strict: a FALSIFIED input may then lie on the
/// boundary of the unsafe set, which is not a counterexample of the
/// property as written. `false` for text that does not parse.
pub fn has_strict_comparisons(text: &str) -> bool {
    parse_sexps(&Ctx { text }, text).is_ok_and(|s| s.iter().any(contains_strict))
}

fn contains_strict(e: &Sexp) -> bool {
    match e {
        Sexp::Atom(a, _) => a == "<" || a == ">",
        Sexp::List(items, _) => items.iter().any(contains_strict),
    }
}
