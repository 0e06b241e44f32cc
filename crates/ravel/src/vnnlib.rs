//! VNN-LIB import: a property file of the verification competition → the
//! equivalent ravel network spec (text).
//!
//! A VNN-LIB file declares the inputs `X_0 … X_{n−1}` and outputs
//! `Y_0 … Y_{m−1}` and asserts constraints whose conjunction describes a
//! *counterexample*: the property holds when no input satisfying the input
//! constraints produces outputs satisfying the output constraints. ravel
//! states that as an input set and an `avoid` set over the outputs:
//!
//! * input constraints: linear (in)equalities over the `X_i` only, at top
//!   level or in `and`; bounds of single variables make a box, anything
//!   else a polytope (every input must be bounded);
//! * output constraints: linear (in)equalities over the `Y_j` only, under
//!   any nesting of `and` and `or`; they are expanded into a union of
//!   polytopes (at most [`MAX_MEMBERS`] members), the `avoid` set.
//!
//! Not supported, each with a message naming the line: constraints mixing
//! `X` and `Y`, disjunctions involving inputs, non-linear terms, other
//! sorts than `Real`, and any other command. Strict comparisons (`<`, `>`)
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

/// What a constraint constrains.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    /// Inputs only.
    In,
    /// Outputs only.
    Out,
    /// A conjunction of input and output parts.
    Mixed,
}

/// A constraint tree.
enum Tree {
    Row(Row),
    And(Vec<Tree>),
    Or(Vec<Tree>),
    /// A conjunction whose parts constrain different kinds.
    Mixed(Vec<(Kind, Tree)>),
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

    /// A constraint and what it constrains.
    fn constraint(&self, e: &Sexp) -> Result<(Kind, Tree), ImportError> {
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
                let all = |k: Kind| parts.iter().all(|(x, _)| *x == k);
                let kind = if all(Kind::In) {
                    Kind::In
                } else if all(Kind::Out) {
                    Kind::Out
                } else {
                    Kind::Mixed
                };
                if head == "or" {
                    return match kind {
                        Kind::Out => Ok((Kind::Out, Tree::Or(parts.into_iter().map(|p| p.1).collect()))),
                        _ => Err(self.cx.err(*at, "disjunctions involving inputs are not supported (state each input region in its own spec)")),
                    };
                }
                Ok(match kind {
                    Kind::Mixed => (Kind::Mixed, Tree::Mixed(parts)),
                    k => (k, Tree::And(parts.into_iter().map(|p| p.1).collect())),
                })
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
                let tree = match head {
                    "<=" | "<" => Tree::Row(le(&diff, 1.0)),
                    ">=" | ">" => Tree::Row(le(&diff, -1.0)),
                    _ => Tree::And(vec![Tree::Row(le(&diff, 1.0)), Tree::Row(le(&diff, -1.0))]),
                };
                Ok((if out { Kind::Out } else { Kind::In }, tree))
            }
            _ => Err(self.cx.err(*at, format!("`{}` with {} argument(s) is not a supported constraint (supported: <=, >=, <, >, = with two sides; and, or)", clean(head), args.len()))),
        }
    }
}

/// Disjunctive normal form of a tree: a list of conjunctions.
fn dnf(t: Tree, limit: usize) -> Option<Vec<Vec<Row>>> {
    match t {
        Tree::Row(r) => Some(vec![vec![r]]),
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
        Tree::Mixed(_) => None,
        Tree::And(parts) => {
            let mut acc: Vec<Vec<Row>> = vec![Vec::new()];
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

/// Split a tree into its input rows (a conjunction) and its output parts.
fn split(t: Tree, kind: Kind, input: &mut Vec<Row>, output: &mut Vec<Tree>) {
    match (t, kind) {
        (Tree::Mixed(parts), _) => {
            for (k, p) in parts {
                split(p, k, input, output);
            }
        }
        (t, Kind::Out) => output.push(t),
        (Tree::Row(r), _) => input.push(r),
        (Tree::And(parts), _) => {
            for p in parts {
                split(p, Kind::In, input, output);
            }
        }
        // an input disjunction is refused by `constraint`
        (Tree::Or(_), _) => {}
    }
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

/// Import a VNN-LIB property: the ravel network spec that states it, for
/// the network stored at `model_path` (its sizes are the declared `X_i` and
/// `Y_j`, which must run from 0 without gaps; the front end then checks them
/// against the model); `name` names the network and `source` the file.
pub fn import(
    text: &str,
    model_path: &str,
    name: &str,
    source: &str,
) -> Result<String, ImportError> {
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
    if asserted.outputs.is_empty() {
        return Err(im.cx.err(
            0,
            "there is no constraint on the outputs: every input would be a counterexample",
        ));
    }
    let members = dnf(Tree::And(asserted.outputs), MAX_MEMBERS).ok_or_else(|| {
        im.cx.err(
            0,
            format!("the output constraints expand into more than {MAX_MEMBERS} polytopes"),
        )
    })?;
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
    if asserted.strict {
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
        im.inputs, im.outputs
    );
    let _ = writeln!(s, "model \"{}\"\n", model_path.replace('"', "\\\""));
    s += &im.input_set(&asserted.inputs)?;
    let texts: Vec<String> = members
        .iter()
        .map(|m| {
            let rows: Vec<String> = m.iter().map(|r| row_text(r, "y")).collect();
            format!("{{ {} }}", rows.join(", "))
        })
        .collect();
    let _ = writeln!(s, "avoid unsafe = {}\n", texts.join("\n             | "));
    let _ = writeln!(
        s,
        "analysis {{\n    propagator  crown\n    partitioner none\n    shape       box\n    samples     1000\n    seed        0\n}}"
    );
    Ok(s)
}

/// What the asserts say: the input rows (a conjunction), the output
/// constraints (a conjunction), and whether a strict comparison occurs.
#[derive(Default)]
struct Asserted {
    inputs: Vec<Row>,
    outputs: Vec<Tree>,
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
                let (kind, tree) = self.constraint(body)?;
                split(tree, kind, &mut asserted.inputs, &mut asserted.outputs);
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
                [(i, c)] if *c > 0.0 => {
                    if let Some(h) = hi.get_mut(*i) {
                        *h = h.min(r.rhs / c);
                    }
                }
                [(i, c)] if *c < 0.0 => {
                    if let Some(l) = lo.get_mut(*i) {
                        *l = l.max(r.rhs / c);
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
fn contains_strict(e: &Sexp) -> bool {
    match e {
        Sexp::Atom(a, _) => a == "<" || a == ">",
        Sexp::List(items, _) => items.iter().any(contains_strict),
    }
}
