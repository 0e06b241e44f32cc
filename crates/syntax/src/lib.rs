//! Parsing: spec text → [`ast::Spec`], with the pest grammar in `grammar/ravel.pest`.
//!
//! A syntax error stops parsing and yields one diagnostic (`E0001`) at the
//! first position the grammar cannot continue from, naming what was expected
//! there; everything after the grammar (names, shapes, files) is checked by
//! `ravel::check`, which reports every problem at once.

#![forbid(unsafe_code)]
// the parser reads untrusted text: no panicking shortcuts
#![deny(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
pub mod ast;
pub mod diag;
pub mod fmt;

use pest::iterators::{Pair, Pairs};
use pest::Parser;

use crate::diag::{Code, Diagnostic};
use ast::*;
use ravel_base::limits::{MAX_EXPR_DEPTH, MAX_EXPR_NODES, MAX_NESTING};

/// The pest parser generated from the grammar (its generated items carry no docs).
#[allow(missing_docs)]
mod generated {
    #[derive(pest_derive::Parser)]
    #[grammar = "../grammar/ravel.pest"]
    pub struct Grammar;
}
use generated::{Grammar, Rule};

type P<'a> = Pair<'a, Rule>;

/// The children of a pair, in order.
type Children<'a> = Pairs<'a, Rule>;

/// The language's keywords, for "did you mean" on a parse error.
const KEYWORDS: &[&str] = &[
    "actuate",
    "always",
    "analysis",
    "avoid",
    "ball",
    "boundary",
    "box",
    "const",
    "control",
    "controller",
    "der",
    "during",
    "epsilon",
    "eventually",
    "goal",
    "horizon",
    "initial",
    "input",
    "network",
    "next",
    "observations",
    "observe",
    "optimise_slopes",
    "output",
    "partitioner",
    "propagator",
    "require",
    "samples",
    "seed",
    "select",
    "state",
    "steps",
    "system",
    "time",
];

/// The next child of a pair where the grammar guarantees one (`what`
/// names it).
#[allow(clippy::expect_used)] // pest yields only parse trees the grammar admits
fn child<'a>(children: &mut Children<'a>, what: &str) -> P<'a> {
    children.next().expect(what)
}

/// A quoted path (the grammar's `string`, which starts and ends with `"`)
/// without its quotes.
fn quoted(lit: P) -> Spanned<String> {
    let text = lit.as_str();
    let inside = text
        .strip_prefix('"')
        .and_then(|t| t.strip_suffix('"'))
        .unwrap_or(text);
    Spanned {
        node: inside.to_string(),
        span: span(&lit),
    }
}

fn span(p: &P) -> Span {
    Span::new(p.as_span().start(), p.as_span().end())
}

fn rule_name(r: &Rule) -> Option<&'static str> {
    Some(match r {
        Rule::EOI => "end of file",
        Rule::item => {
            "a top-level item (system, controller, initial, goal, avoid, horizon, analysis; or network, model, input, require, robust, radius)"
        }
        Rule::system_stmt => "a system statement (state, control, NAME = value, NAME in box(…))",
        Rule::state_decl => "`state`",
        Rule::control_decl => "`control`",
        Rule::bound_decl => "`NAME in box(…)`",
        Rule::assign => "`NAME = value`",
        Rule::analysis_stmt => {
            "an analysis statement (propagator, partitioner, boundary, shape, samples, seed)"
        }
        Rule::network_stmt => "a network statement (input x[n], output y[m])",
        Rule::select_stmt => "a select statement (epsilon, norm, observations)",
        Rule::input_decl => "`input`",
        Rule::output_decl => "`output`",
        Rule::value | Rule::matrix | Rule::vector => "a number, vector or matrix",
        Rule::set_expr | Rule::set_atom | Rule::box_set | Rule::polytope => {
            "a set: box(…), { … } or ball(…)"
        }
        Rule::named_intervals | Rule::named_interval | Rule::intervals => "an interval",
        Rule::interval => "an interval `[lo, hi]`",
        Rule::constraint | Rule::lin_expr | Rule::first_term | Rule::term => "a linear inequality",
        Rule::inequality => "an inequality `expr <= expr`",
        Rule::at_time => "`at time T`",
        Rule::always_during | Rule::eventually_during => {
            "`always during [t0, t1]` or `eventually during [t0, t1]`"
        }
        Rule::during => "`during [t0, t1]`",
        Rule::cmp => "`<=` or `>=`",
        Rule::component => "a component such as `x[0]`",
        Rule::ident => "a name",
        Rule::integer => "an integer",
        Rule::number | Rule::unsigned => "a number",
        Rule::string => "a quoted path",
        Rule::steps | Rule::steps_range | Rule::step_single => "`at steps [a, b]` or `at step k`",
        Rule::uniform => "`uniform [k, …]`",
        Rule::ball => "`ball(center […], radius …, norm p)`",
        Rule::norm => "`1`, `2` or `inf`",
        Rule::guided | Rule::guide => "`sg`, `gsg`, `property` or `bab`",
        Rule::budget | Rule::budget_item => "a budget item such as `calls 100`",
        Rule::boundary_polytope => "`polytope K` or `polytope [[…], …]`",
        Rule::per_step => "`per_step(value, …)`",
        Rule::time_decl | Rule::time_kw => "`time continuous dt …` or `time discrete`",
        Rule::const_decl | Rule::const_kw => "`const NAME = …`",
        Rule::der_decl | Rule::der_kw => "`der x[i] = …`",
        Rule::next_decl | Rule::next_kw => "`next x[i] = …`",
        Rule::observe_decl | Rule::observe_kw => "`observe […]`",
        Rule::actuate_decl | Rule::actuate_kw => "`actuate […]`",
        Rule::expr_list => "a list of expressions `[…]`",
        Rule::expr
        | Rule::product
        | Rule::unary
        | Rule::power
        | Rule::exponent
        | Rule::neg
        | Rule::call => "an expression",
        Rule::mul_op => "`*` or `/`",
        Rule::add_op => "`+` or `-`",
        Rule::close => "`]`",
        Rule::comma => "`,`",
        Rule::close_paren => "`)`",
        _ => return None,
    })
}

/// Parse a spec. Fails with one diagnostic on a syntax error, or with one per
/// oversized integer literal.
pub fn parse(source: &str) -> Result<Spec, Vec<Diagnostic>> {
    if let Some(d) = too_deep(source) {
        return Err(vec![d]);
    }
    let mut pairs =
        Grammar::parse(Rule::spec, source).map_err(|e| vec![syntax_error(e, source)])?;
    let spec = child(
        &mut pairs,
        "the grammar's `spec` rule always yields one pair",
    );
    let mut b = Builder {
        errors: Vec::new(),
        expr_nodes: 0,
        too_deep: false,
        too_many: false,
    };
    let items = spec
        .into_inner()
        .filter(|p| p.as_rule() != Rule::EOI)
        .map(|p| b.item(p))
        .collect();
    if b.errors.is_empty() {
        Ok(Spec { items })
    } else {
        Err(b.errors)
    }
}

/// Brackets nested deeper than [`MAX_NESTING`] (outside comments and
/// strings), reported at the first bracket beyond the limit before the
/// parser (which recurses once per level) sees them.
fn too_deep(source: &str) -> Option<Diagnostic> {
    let bytes = source.as_bytes();
    let mut depth = 0usize;
    let mut i = 0;
    while let Some(&c) = bytes.get(i) {
        match c {
            b'/' if bytes.get(i + 1) == Some(&b'/') => {
                while bytes.get(i).is_some_and(|d| *d != b'\n' && *d != b'\r') {
                    i += 1;
                }
            }
            b'/' if bytes.get(i + 1) == Some(&b'*') => {
                i += 2;
                while bytes.get(i).is_some() && bytes.get(i..i + 2) != Some(b"*/".as_slice()) {
                    i += 1;
                }
                i += 1;
            }
            b'"' => {
                i += 1;
                while bytes
                    .get(i)
                    .is_some_and(|d| !matches!(d, b'"' | b'\n' | b'\r'))
                {
                    i += 1;
                }
            }
            b'(' | b'[' | b'{' => {
                depth += 1;
                if depth > MAX_NESTING {
                    return Some(
                        Diagnostic::new(
                            Code::Limit,
                            Span::new(i, i + 1),
                            format!("brackets are nested more than {MAX_NESTING} deep"),
                        )
                        .label("too deep")
                        .hint("simplify the expression, or name parts of it with `const`"),
                    );
                }
            }
            b')' | b']' | b'}' => depth = depth.saturating_sub(1),
            _ => {}
        }
        i += 1;
    }
    None
}

fn syntax_error(e: pest::error::Error<Rule>, source: &str) -> Diagnostic {
    let pos = match e.location {
        pest::error::InputLocation::Pos(p) => p,
        pest::error::InputLocation::Span((s, _)) => s,
    };
    let end = source[pos..]
        .chars()
        .next()
        .map_or(pos, |c| pos + c.len_utf8());
    let (expected, unexpected) = match &e.variant {
        pest::error::ErrorVariant::ParsingError {
            positives,
            negatives,
        } => (positives.clone(), negatives.clone()),
        pest::error::ErrorVariant::CustomError { .. } => (vec![], vec![]),
    };
    let mut names: Vec<&str> = expected.iter().filter_map(rule_name).collect();
    names.dedup();
    // a character that can never start or continue a token (a non-ASCII
    // letter in a name, a stray control character): point at it alone
    // (pest reports the start of the statement that failed, so the rest of
    // its line is searched, up to a comment or a string)
    let rest = &source[pos..];
    let line_end = rest.find(['\n', '\r', '"']).unwrap_or(rest.len());
    let line = &rest[..line_end];
    let line = &line[..line.find("//").unwrap_or(line.len())];
    let line = &line[..line.find("/*").unwrap_or(line.len())];
    let bad = line
        .char_indices()
        .find(|(_, c)| !c.is_ascii() || (c.is_control() && *c != '\t'));
    if let Some((off, c)) = bad {
        let at = pos + off;
        let shown = crate::diag::sanitize(&c.to_string());
        let (message, hint) = if c.is_alphanumeric() {
            (
                format!("`{shown}` cannot appear in a name"),
                "names are ASCII: letters, digits and `_`, starting with a letter or `_`",
            )
        } else {
            (
                format!("unexpected character `{shown}` (U+{:04X})", c as u32),
                "outside comments and strings, specs use ASCII characters only",
            )
        };
        return Diagnostic::new(Code::Syntax, Span::new(at, at + c.len_utf8()), message)
            .label("not allowed here")
            .hint(hint);
    }
    let found = source[pos..]
        .split_whitespace()
        .next()
        .map(|t| crate::diag::sanitize(&t.chars().take(20).collect::<String>()));
    let message = match &found {
        Some(t) => format!("unexpected `{t}`"),
        None => "unexpected end of file".to_string(),
    };
    let label = if names.is_empty() {
        if unexpected.is_empty() {
            "the grammar cannot continue here".to_string()
        } else {
            "not allowed here".to_string()
        }
    } else {
        format!("expected {}", names.join(" or "))
    };
    // a misspelt keyword (`horizn 5`): name the keyword it is closest to
    let word: String = source[pos..]
        .chars()
        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
        .collect();
    // `u = box(…)`: a set after `=`, where the plant takes `in`
    let after_equals = source[..pos].trim_end().ends_with('=');
    let hint = match crate::diag::did_you_mean(&word, KEYWORDS.iter().copied()) {
        _ if after_equals && (word == "box" || word == "ball" || source[pos..].starts_with('{')) => {
            "a name and a set are joined by `in` inside `system` (`u in box([-1, 1])`); `=` takes a number, vector or matrix".to_string()
        }
        Some(k) if !word.is_empty() && k != word => {
            format!("did you mean `{k}`? (see docs/language.md for the syntax of each item)")
        }
        _ => "see docs/language.md for the syntax of each item".to_string(),
    };
    // a box's intervals without the `,` between them: point at the gap
    // where it belongs (pest would name only the place it gave up at)
    if expected.contains(&Rule::comma) && expected.contains(&Rule::close_paren) {
        let next_is_interval = rest.starts_with('[')
            || (word
                .chars()
                .next()
                .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
                && rest[word.len()..].starts_with('['));
        if next_is_interval {
            let gap = source[..pos].trim_end().len();
            let span = if gap < pos {
                Span::new(gap, pos)
            } else {
                Span::new(pos, end)
            };
            return Diagnostic::new(Code::Syntax, span, "a `,` is missing between two intervals")
                .label("expected `,` here")
                .hint("the intervals of a box are separated by commas: `box(x[0] in [2.5, 3.0], x[1] in [-0.25, 0.25])`");
        }
        return Diagnostic::new(Code::Syntax, Span::new(pos, end), message)
            .label(label)
            .hint("a box's intervals are separated by `,` and the box ends with `)`: `box(x[0] in [2.5, 3.0], x[1] in [-0.25, 0.25])`");
    }
    Diagnostic::new(Code::Syntax, Span::new(pos, end), message)
        .label(label)
        .hint(hint)
}

struct Builder {
    errors: Vec<Diagnostic>,
    /// Expression nodes built so far (see [`MAX_EXPR_NODES`]).
    expr_nodes: usize,
    /// Whether an expression deeper than [`MAX_EXPR_DEPTH`] was reported.
    too_deep: bool,
    /// Whether [`MAX_EXPR_NODES`] was reported.
    too_many: bool,
}

/// An expression and the depth of its tree.
type Built = (Spanned<Expr>, usize);

impl Builder {
    fn integer(&mut self, p: P) -> Spanned<u64> {
        let s = span(&p);
        let node = p.as_str().parse::<u64>().unwrap_or_else(|_| {
            self.errors.push(
                Diagnostic::new(
                    Code::IntegerTooLarge,
                    s,
                    format!("integer `{}` is too large", p.as_str()),
                )
                .label("does not fit in 64 bits")
                .hint("use a smaller value"),
            );
            0
        });
        Spanned { node, span: s }
    }

    fn number(&mut self, p: P) -> Spanned<f64> {
        let s = span(&p);
        // The grammar only admits valid float syntax; overflow parses to ±inf and is
        // reported by `check` (E0205).
        let node = p.as_str().parse::<f64>().unwrap_or(f64::NAN);
        Spanned { node, span: s }
    }

    fn ident(&mut self, p: P) -> Spanned<String> {
        Spanned {
            node: p.as_str().to_string(),
            span: span(&p),
        }
    }

    fn item(&mut self, p: P) -> Item {
        let s = span(&p);
        let rule = p.as_rule();
        let mut inner = p.into_inner();
        match rule {
            Rule::system => {
                let name = self.ident(child(&mut inner, "system name"));
                let stmts = inner.map(|st| self.system_stmt(st)).collect();
                Item::System(System {
                    name,
                    stmts,
                    span: s,
                })
            }
            Rule::controller => Item::Controller(quoted(child(&mut inner, "controller path"))),
            Rule::initial | Rule::goal | Rule::input_set | Rule::require => {
                let def = self.set_def(s, &mut inner);
                match rule {
                    Rule::initial => Item::Initial(def),
                    Rule::goal => Item::Goal(def),
                    Rule::input_set => Item::Input(def),
                    _ => Item::Require(def),
                }
            }
            Rule::avoid => Item::Avoid(self.avoid(s, inner)),
            Rule::horizon => Item::Horizon(self.integer(child(&mut inner, "horizon value"))),
            Rule::network => Item::Network(self.network(s, inner)),
            Rule::model => Item::Model(quoted(child(&mut inner, "model path"))),
            Rule::robust => {
                let name = self.ident(child(&mut inner, "property name"));
                let label = inner.next().map(|l| self.integer(l));
                Item::Robust(RobustDef {
                    name,
                    label,
                    span: s,
                })
            }
            Rule::select => {
                let name = self.ident(child(&mut inner, "select name"));
                let stmts = inner.map(|st| self.select_stmt(st)).collect();
                Item::Select(SelectDef {
                    name,
                    stmts,
                    span: s,
                })
            }
            Rule::radius => {
                let name = self.ident(child(&mut inner, "radius name"));
                let property = self.ident(child(&mut inner, "property name"));
                let budget = inner.next().map(|b| self.budget(b)).unwrap_or_default();
                Item::Radius(RadiusDef {
                    name,
                    property,
                    budget,
                    span: s,
                })
            }
            Rule::analysis => {
                let stmts = inner.map(|st| self.analysis_stmt(st)).collect();
                Item::Analysis(Analysis { stmts, span: s })
            }
            other => unreachable!("grammar item rule {other:?}"),
        }
    }

    /// `NAME = set` of an `initial`, `goal`, `input` or `require` item
    /// spanning `s`.
    fn set_def(&mut self, s: Span, inner: &mut Children) -> SetDef {
        let name = self.ident(child(inner, "set name"));
        let set = self.set_expr(child(inner, "set"));
        let when = inner.next().map(|w| {
            let ws = span(&w);
            let rule = w.as_rule();
            let arg = child(&mut w.into_inner(), "time clause");
            let node = match rule {
                Rule::at_time => GoalWhen::AtTime(self.number(arg)),
                Rule::always_during => GoalWhen::Always(self.window(arg)),
                _ => GoalWhen::Eventually(self.window(arg)),
            };
            Spanned { node, span: ws }
        });
        SetDef {
            name,
            set,
            span: s,
            when,
        }
    }

    /// `during [t0, t1]`.
    fn window(&mut self, p: P) -> Window {
        let ws = span(&p);
        let mut it = p.into_inner();
        let t0 = self.number(child(&mut it, "window start"));
        let t1 = self.number(child(&mut it, "window end"));
        Window { t0, t1, span: ws }
    }

    /// An `avoid` item spanning `s`: `NAME = set`, then optionally the
    /// steps it applies at.
    fn avoid(&mut self, s: Span, mut inner: Children) -> AvoidDef {
        let name = self.ident(child(&mut inner, "set name"));
        let set = self.set_expr(child(&mut inner, "set"));
        let (mut steps, mut during) = (None, None);
        if let Some(st) = inner.next() {
            if st.as_rule() == Rule::during {
                during = Some(self.window(st));
            } else {
                steps = Some(self.steps(st));
            }
        }
        AvoidDef {
            name,
            set,
            steps,
            span: s,
            during,
        }
    }

    /// `at steps [a, b]`, or `at step k` as `(k, k)`.
    fn steps(&mut self, st: P) -> Spanned<(u64, u64)> {
        let ss = span(&st);
        let which = child(&mut st.into_inner(), "steps form");
        let is_range = which.as_rule() == Rule::steps_range;
        let mut nums = which.into_inner();
        let a = self.integer(child(&mut nums, "step")).node;
        let b = if is_range {
            self.integer(child(&mut nums, "step")).node
        } else {
            a
        };
        Spanned {
            node: (a, b),
            span: ss,
        }
    }

    /// A `network` item spanning `s`: its name, then its `input` and
    /// `output` declarations in order.
    fn network(&mut self, s: Span, mut inner: Children) -> NetworkDecl {
        let name = self.ident(child(&mut inner, "network name"));
        let (mut input, mut output) = (Vec::new(), Vec::new());
        for st in inner {
            let is_input = st.as_rule() == Rule::input_decl;
            let mut parts = st.into_inner();
            let n = self.ident(child(&mut parts, "vector name"));
            let d = self.integer(child(&mut parts, "dimension"));
            if is_input {
                input.push((n, d));
            } else {
                output.push((n, d));
            }
        }
        NetworkDecl {
            name,
            input,
            output,
            span: s,
        }
    }

    /// One statement of a `select` item: `epsilon`, `norm`, or the
    /// observations (a file or an inline value).
    fn select_stmt(&mut self, st: P) -> Spanned<SelectStmt> {
        let ss = span(&st);
        let rule = st.as_rule();
        let arg = child(&mut st.into_inner(), "select argument");
        let asp = span(&arg);
        let node = match (rule, arg.as_rule()) {
            (Rule::norm_stmt, _) => SelectStmt::Norm(Spanned {
                node: arg.as_str().to_string(),
                span: asp,
            }),
            (_, Rule::string) => SelectStmt::File(quoted(arg)),
            (Rule::epsilon_stmt, Rule::number) => SelectStmt::Epsilon(Spanned {
                node: Value::Scalar(self.number(arg).node),
                span: asp,
            }),
            (Rule::epsilon_stmt, _) => SelectStmt::Epsilon(Spanned {
                node: Value::Vector(self.numbers(arg)),
                span: asp,
            }),
            _ => SelectStmt::Inline(Spanned {
                node: self.value_of(arg),
                span: asp,
            }),
        };
        Spanned { node, span: ss }
    }

    fn system_stmt(&mut self, p: P) -> SystemStmt {
        let s = span(&p);
        let rule = p.as_rule();
        let mut inner = p.into_inner();
        if rule == Rule::time_decl {
            let _keyword = inner.next();
            let kind = self.ident(child(&mut inner, "time kind"));
            let dt = inner.next().map(|d| self.number(d));
            return SystemStmt::Time { kind, dt, span: s };
        }
        match rule {
            Rule::const_decl => {
                let _keyword = inner.next();
                let name = self.ident(child(&mut inner, "constant name"));
                let value = self.expr(child(&mut inner, "constant value"));
                return SystemStmt::Const {
                    name,
                    value,
                    span: s,
                };
            }
            Rule::der_decl | Rule::next_decl => {
                let keyword = child(&mut inner, "keyword");
                let kind = Spanned {
                    node: if rule == Rule::der_decl {
                        EquationKind::Der
                    } else {
                        EquationKind::Next
                    },
                    span: span(&keyword),
                };
                let target = self.component(child(&mut inner, "equation target"));
                let expr = self.expr(child(&mut inner, "equation"));
                return SystemStmt::Equation {
                    kind,
                    target,
                    expr,
                    span: s,
                };
            }
            Rule::observe_decl | Rule::actuate_decl => {
                let _keyword = inner.next();
                let list = child(&mut inner, "expression list");
                let exprs = list
                    .into_inner()
                    .filter(|e| e.as_rule() == Rule::expr)
                    .map(|e| self.expr(e))
                    .collect();
                return if rule == Rule::observe_decl {
                    SystemStmt::Observe { exprs, span: s }
                } else {
                    SystemStmt::Actuate { exprs, span: s }
                };
            }
            _ => {}
        }
        let name = self.ident(child(&mut inner, "statement name"));
        match rule {
            Rule::state_decl => SystemStmt::State {
                name,
                dim: self.integer(child(&mut inner, "dim")),
                span: s,
            },
            Rule::control_decl => SystemStmt::Control {
                name,
                dim: self.integer(child(&mut inner, "dim")),
                span: s,
            },
            Rule::bound_decl => {
                let b = child(&mut inner, "box");
                let bs = span(&b);
                SystemStmt::Bound {
                    name,
                    set: Spanned {
                        node: self.box_set(b),
                        span: bs,
                    },
                    span: s,
                }
            }
            Rule::assign => {
                let v = child(&mut inner, "value");
                let vs = span(&v);
                let node = if v.as_rule() == Rule::per_step {
                    Value::PerStep(
                        v.into_inner()
                            .map(|x| {
                                let xs = span(&x);
                                Spanned {
                                    node: self.value(x),
                                    span: xs,
                                }
                            })
                            .collect(),
                    )
                } else {
                    self.value(v)
                };
                SystemStmt::Assign {
                    name,
                    value: Spanned { node, span: vs },
                    span: s,
                }
            }
            other => unreachable!("grammar system rule {other:?}"),
        }
    }

    /// A whole expression (a `Rule::expr` pair), its depth and size limited.
    fn expr(&mut self, p: P) -> Spanned<Expr> {
        self.operand(p).0
    }

    /// A node of `depth` levels at `span`: the node itself, or a
    /// placeholder `0` once a limit is passed (reported once each).
    fn node(&mut self, node: Expr, span: Span, depth: usize) -> Built {
        self.expr_nodes += 1;
        if self.expr_nodes > MAX_EXPR_NODES {
            if !self.too_many {
                self.too_many = true;
                self.errors.push(
                    Diagnostic::new(
                        Code::Limit,
                        span,
                        format!("the spec's expressions have more than {MAX_EXPR_NODES} terms"),
                    )
                    .label("the limit is passed here")
                    .hint("write shorter expressions"),
                );
            }
            return (
                Spanned {
                    node: Expr::Number(0.0),
                    span,
                },
                1,
            );
        }
        if depth > MAX_EXPR_DEPTH {
            if !self.too_deep {
                self.too_deep = true;
                self.errors.push(
                    Diagnostic::new(
                        Code::Limit,
                        span,
                        format!("an expression is nested more than {MAX_EXPR_DEPTH} levels deep"),
                    )
                    .label("too deep")
                    .hint("simplify the expression, or name parts of it with `const`"),
                );
            }
            return (
                Spanned {
                    node: Expr::Number(0.0),
                    span,
                },
                1,
            );
        }
        (Spanned { node, span }, depth)
    }

    /// Any pair of the expression grammar: a chain (`expr`, `product`), a
    /// `unary` or `exponent` (minus signs, then a power or an atom), a
    /// `power`, or an atom.
    fn operand(&mut self, p: P) -> Built {
        let s = span(&p);
        match p.as_rule() {
            Rule::expr | Rule::product => {
                let mut it = p.into_inner();
                let (first, mut depth) = self.operand(child(&mut it, "operand"));
                let mut rest = Vec::new();
                while let Some(op) = it.next() {
                    let op = match op.as_str() {
                        "+" => BinOp::Add,
                        "-" => BinOp::Sub,
                        "*" => BinOp::Mul,
                        _ => BinOp::Div,
                    };
                    let (e, d) = self.operand(child(&mut it, "operand"));
                    depth = depth.max(d);
                    rest.push((op, e));
                }
                if rest.is_empty() {
                    return (first, depth);
                }
                let first = Box::new(first);
                self.node(Expr::Chain { first, rest }, s, depth + 1)
            }
            Rule::unary | Rule::exponent => {
                let parts: Vec<P> = p.into_inner().collect();
                let negs: Vec<Span> = parts
                    .iter()
                    .filter(|q| q.as_rule() == Rule::neg)
                    .map(span)
                    .collect();
                let Some(last) = parts.into_iter().next_back() else {
                    unreachable!("a unary expression ends in an operand")
                };
                let (mut e, mut depth) = self.operand(last);
                for n in negs.iter().rev() {
                    let at = Span::new(n.start, e.span.end);
                    (e, depth) = self.node(Expr::Neg(Box::new(e)), at, depth + 1);
                }
                (e, depth)
            }
            Rule::power => {
                let mut items: Vec<Built> = p.into_inner().map(|q| self.operand(q)).collect();
                let Some(mut acc) = items.pop() else {
                    unreachable!("a power has a base")
                };
                // right-associative: a ^ (b ^ (c …))
                while let Some((base, bd)) = items.pop() {
                    let at = Span::new(base.span.start, acc.0.span.end);
                    let depth = bd.max(acc.1) + 1;
                    let node = Expr::Pow {
                        base: Box::new(base),
                        exp: Box::new(acc.0),
                    };
                    acc = self.node(node, at, depth);
                }
                acc
            }
            Rule::unsigned => {
                let v = p.as_str().parse::<f64>().unwrap_or(f64::NAN);
                self.node(Expr::Number(v), s, 1)
            }
            Rule::ident => self.node(Expr::Name(p.as_str().to_string()), s, 1),
            Rule::component => {
                let c = self.component(p);
                self.node(Expr::Component(c), s, 1)
            }
            Rule::call => {
                let mut it = p.into_inner();
                let func = self.ident(child(&mut it, "function name"));
                let mut depth = 0;
                let args = it
                    .map(|a| {
                        let (e, d) = self.operand(a);
                        depth = depth.max(d);
                        e
                    })
                    .collect();
                self.node(Expr::Call { func, args }, s, depth + 1)
            }
            other => unreachable!("grammar expression rule {other:?}"),
        }
    }

    fn numbers(&mut self, p: P) -> Vec<Spanned<f64>> {
        p.into_inner()
            .filter(|n| n.as_rule() == Rule::number)
            .map(|n| self.number(n))
            .collect()
    }

    fn value(&mut self, p: P) -> Value {
        let v = child(&mut p.into_inner(), "value kind");
        self.value_of(v)
    }

    /// A value from its inner pair (a matrix, vector, constructor or number).
    fn value_of(&mut self, v: P) -> Value {
        match v.as_rule() {
            Rule::matrix => Value::Matrix(
                v.into_inner()
                    .filter(|row| row.as_rule() == Rule::vector)
                    .map(|row| {
                        let rs = span(&row);
                        Spanned {
                            node: self.numbers(row),
                            span: rs,
                        }
                    })
                    .collect(),
            ),
            Rule::vector => Value::Vector(self.numbers(v)),
            Rule::eye => Value::Eye(self.integer(child(&mut v.into_inner(), "eye size"))),
            Rule::zeros => {
                let mut it = v.into_inner();
                let n = self.integer(child(&mut it, "zeros size"));
                let m = it.next().map(|m| self.integer(m));
                Value::Zeros(n, m)
            }
            Rule::number => Value::Scalar(self.number(v).node),
            other => unreachable!("grammar value rule {other:?}"),
        }
    }

    fn set_expr(&mut self, p: P) -> Spanned<SetExpr> {
        let s = span(&p);
        let members = p
            .into_inner()
            .map(|a| {
                let sa = span(&a);
                let node = match a.as_rule() {
                    Rule::box_set => SetAtom::Box(self.box_set(a)),
                    Rule::polytope => {
                        let rows: Vec<SetRow> = a
                            .into_inner()
                            .map(|c| match c.as_rule() {
                                Rule::constraint => SetRow::Linear(self.constraint(c)),
                                _ => SetRow::General(self.inequality(c)),
                            })
                            .collect();
                        if rows.iter().all(|r| matches!(r, SetRow::Linear(_))) {
                            SetAtom::Polytope(
                                rows.into_iter()
                                    .filter_map(|r| match r {
                                        SetRow::Linear(c) => Some(c),
                                        SetRow::General(_) => None,
                                    })
                                    .collect(),
                            )
                        } else {
                            SetAtom::Inequalities(rows)
                        }
                    }
                    Rule::ball => {
                        let mut it = a.into_inner();
                        let c = child(&mut it, "centre");
                        let cs = span(&c);
                        let center = Spanned {
                            node: self.numbers(c),
                            span: cs,
                        };
                        let r = child(&mut it, "radius");
                        let rs = span(&r);
                        let radius = Spanned {
                            node: match r.as_rule() {
                                Rule::vector => Value::Vector(self.numbers(r)),
                                _ => Value::Scalar(self.number(r).node),
                            },
                            span: rs,
                        };
                        let norm = it.next().map(|n| Spanned {
                            node: n.as_str().to_string(),
                            span: span(&n),
                        });
                        SetAtom::Ball(BallSet {
                            center,
                            radius,
                            norm,
                        })
                    }
                    other => unreachable!("grammar set rule {other:?}"),
                };
                Spanned { node, span: sa }
            })
            .collect();
        Spanned {
            node: SetExpr { members },
            span: s,
        }
    }

    fn box_set(&mut self, p: P) -> BoxSet {
        let body = child(&mut p.into_inner(), "box body");
        match body.as_rule() {
            Rule::named_intervals => BoxSet::Named(
                body.into_inner()
                    .filter(|ni| ni.as_rule() == Rule::named_interval)
                    .map(|ni| {
                        let mut it = ni.into_inner();
                        let c = self.component(child(&mut it, "component"));
                        let i = self.interval(child(&mut it, "interval"));
                        (c, i)
                    })
                    .collect(),
            ),
            _ => BoxSet::Positional(
                body.into_inner()
                    .filter(|i| i.as_rule() == Rule::interval)
                    .map(|i| self.interval(i))
                    .collect(),
            ),
        }
    }

    fn interval(&mut self, p: P) -> Interval {
        let s = span(&p);
        let mut it = p.into_inner();
        let lo = self.number(child(&mut it, "lo"));
        let hi = self.number(child(&mut it, "hi"));
        Interval { lo, hi, span: s }
    }

    fn component(&mut self, p: P) -> Component {
        let s = span(&p);
        let mut it = p.into_inner();
        let name = self.ident(child(&mut it, "name"));
        let index = self.integer(child(&mut it, "index"));
        Component {
            name,
            index,
            span: s,
        }
    }

    fn term(&mut self, p: P, sign: f64) -> (f64, Component) {
        let mut coef = sign;
        for part in p.into_inner() {
            match part.as_rule() {
                Rule::unsigned => coef *= part.as_str().parse::<f64>().unwrap_or(f64::NAN),
                // the grammar puts the component last
                Rule::component => return (coef, self.component(part)),
                other => unreachable!("grammar term rule {other:?}"),
            }
        }
        unreachable!("a term has a component")
    }

    fn constraint(&mut self, p: P) -> Constraint {
        let s = span(&p);
        let mut it = p.into_inner();
        let expr = child(&mut it, "expression");
        let cmp = match child(&mut it, "comparison").as_str() {
            "<=" => Cmp::Le,
            _ => Cmp::Ge,
        };
        let rhs = self.number(child(&mut it, "rhs"));
        let mut terms = Vec::new();
        let mut sign = 1.0;
        for part in expr.into_inner() {
            match part.as_rule() {
                Rule::first_term => {
                    let mut sub = part.into_inner();
                    let mut t = child(&mut sub, "term");
                    let mut first_sign = 1.0;
                    if t.as_rule() == Rule::add_op {
                        first_sign = if t.as_str() == "-" { -1.0 } else { 1.0 };
                        t = child(&mut sub, "term");
                    }
                    terms.push(self.term(t, first_sign));
                }
                Rule::add_op => sign = if part.as_str() == "-" { -1.0 } else { 1.0 },
                Rule::term => terms.push(self.term(part, sign)),
                other => unreachable!("grammar expression rule {other:?}"),
            }
        }
        Constraint {
            terms,
            cmp,
            rhs,
            span: s,
        }
    }

    /// `lhs (<= | >=) rhs` between two expressions.
    fn inequality(&mut self, p: P) -> Inequality {
        let s = span(&p);
        let mut it = p.into_inner();
        let lhs = self.expr(child(&mut it, "left-hand side"));
        let cmp = match child(&mut it, "comparison").as_str() {
            "<=" => Cmp::Le,
            _ => Cmp::Ge,
        };
        let rhs = self.expr(child(&mut it, "right-hand side"));
        Inequality {
            lhs,
            cmp,
            rhs,
            span: s,
        }
    }

    /// `(name value, …)` budget items.
    fn budget(&mut self, b: P) -> Vec<(Spanned<String>, Spanned<f64>)> {
        b.into_inner()
            .map(|item| {
                let mut kv = item.into_inner();
                let k = self.ident(child(&mut kv, "budget name"));
                let v = self.number(child(&mut kv, "budget value"));
                (k, v)
            })
            .collect()
    }

    fn analysis_stmt(&mut self, p: P) -> Spanned<AnalysisStmt> {
        let s = span(&p);
        let rule = p.as_rule();
        let arg = child(&mut p.into_inner(), "analysis argument");
        let node = match rule {
            Rule::propagator => AnalysisStmt::Propagator(self.ident(arg)),
            Rule::partitioner => match arg.as_rule() {
                Rule::uniform => {
                    AnalysisStmt::Uniform(arg.into_inner().map(|i| self.integer(i)).collect())
                }
                Rule::guided => {
                    let mut it = arg.into_inner();
                    let g = child(&mut it, "guide");
                    let guide = Spanned {
                        node: g.as_str().to_string(),
                        span: span(&g),
                    };
                    let budget = it.next().map(|b| self.budget(b)).unwrap_or_default();
                    AnalysisStmt::Guided { guide, budget }
                }
                _ => AnalysisStmt::Partitioner(self.ident(arg)),
            },
            Rule::boundary | Rule::shape => match arg.as_rule() {
                Rule::boundary_polytope => {
                    let d = child(&mut arg.into_inner(), "directions");
                    let ds = span(&d);
                    let node = match d.as_rule() {
                        Rule::integer => Value::Scalar(self.integer(d).node as f64),
                        _ => Value::Matrix(
                            d.into_inner()
                                .filter(|row| row.as_rule() == Rule::vector)
                                .map(|row| {
                                    let rs = span(&row);
                                    Spanned {
                                        node: self.numbers(row),
                                        span: rs,
                                    }
                                })
                                .collect(),
                        ),
                    };
                    let node = Spanned { node, span: ds };
                    if rule == Rule::shape {
                        AnalysisStmt::ShapePolytope(node)
                    } else {
                        AnalysisStmt::BoundaryPolytope(node)
                    }
                }
                _ if rule == Rule::shape => AnalysisStmt::Shape(self.ident(arg)),
                _ => AnalysisStmt::Boundary(self.ident(arg)),
            },
            Rule::samples => AnalysisStmt::Samples(self.integer(arg)),
            Rule::seed => AnalysisStmt::Seed(self.integer(arg)),
            Rule::optimise_slopes => AnalysisStmt::OptimiseSlopes(self.integer(arg)),
            other => unreachable!("grammar analysis rule {other:?}"),
        };
        Spanned { node, span: s }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    fn avoid_set(src: &str) -> SetExpr {
        let spec = parse(src).unwrap_or_else(|d| panic!("{d:?}"));
        match &spec.items[0] {
            Item::Avoid(a) => a.set.node.clone(),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn inequalities_between_expressions_and_time_clauses() {
        // the linear form stays a polytope, spans as before (no trailing space)
        let set = avoid_set("avoid A = { x[0] <= 2 , x[1] >= -1 }\n");
        let SetAtom::Polytope(cs) = &set.members[0].node else {
            panic!("polytope expected: {set:?}")
        };
        assert_eq!((cs[0].span.start, cs[0].span.end), (12, 21));
        // an expression on either side makes the whole set general, row by row
        let set =
            avoid_set("avoid A = { (x[0] - 1)^2 + x[1]^2 <= 0.25, x[0] <= 2, y[1] >= y[0] }\n");
        let SetAtom::Inequalities(rows) = &set.members[0].node else {
            panic!("inequalities expected: {set:?}")
        };
        assert!(matches!(rows[0], SetRow::General(_)));
        assert!(matches!(rows[1], SetRow::Linear(_)));
        let SetRow::General(g) = &rows[2] else {
            panic!("{rows:?}")
        };
        assert_eq!(g.cmp, Cmp::Ge);
        assert!(matches!(g.rhs.node, Expr::Component(_)));
        // time clauses
        let spec = parse(
            "goal G = box([0, 1]) eventually during [0.5, 2e0]\navoid A = box([0, 1]) during [0, 3]\n",
        )
        .unwrap_or_else(|d| panic!("{d:?}"));
        let Item::Goal(g) = &spec.items[0] else {
            panic!("{spec:?}")
        };
        let Some(GoalWhen::Eventually(w)) = g.when.as_ref().map(|w| &w.node) else {
            panic!("{g:?}")
        };
        assert_eq!((w.t0.node, w.t1.node), (0.5, 2.0));
        let Item::Avoid(a) = &spec.items[1] else {
            panic!("{spec:?}")
        };
        assert!(a.steps.is_none() && a.during.as_ref().is_some_and(|w| w.t1.node == 3.0));
        let spec = parse("goal G = box([0, 1]) at time 4\n").unwrap_or_else(|d| panic!("{d:?}"));
        let Item::Goal(g) = &spec.items[0] else {
            panic!("{spec:?}")
        };
        assert!(
            matches!(g.when.as_ref().map(|w| &w.node), Some(GoalWhen::AtTime(t)) if t.node == 4.0)
        );
        // a goal without a clause prints as it always did
        let spec = parse("goal G = box([0, 1])\n").unwrap_or_else(|d| panic!("{d:?}"));
        assert!(!format!("{spec:?}").contains("when"));
    }

    #[test]
    fn linear_terms_keep_their_signs_and_coefficients() {
        let set = avoid_set(
            "avoid A = { -x[0] + 2 x[1] - 0.5*x[0] >= -1e-1 } | box([0, 1]) /* block */ // line\n",
        );
        assert_eq!(set.members.len(), 2);
        let SetAtom::Polytope(cs) = &set.members[0].node else {
            panic!("polytope expected")
        };
        let coefs: Vec<(f64, u64)> = cs[0]
            .terms
            .iter()
            .map(|(c, comp)| (*c, comp.index.node))
            .collect();
        assert_eq!(coefs, vec![(-1.0, 0), (2.0, 1), (-0.5, 0)]);
        assert_eq!(cs[0].cmp, Cmp::Ge);
        assert_eq!(cs[0].rhs.node, -0.1);
    }

    #[test]
    fn values_and_steps() {
        let spec = parse("system s { state x[2] control u[1] A = eye(2) B = zeros(2, 1) c = zeros(2) C = [[1e0], [.5]] }\navoid A = box(x[1] in [-1, 1]) at step 3\n").expect("parses");
        let Item::System(sys) = &spec.items[0] else {
            panic!("system expected")
        };
        assert_eq!(sys.stmts.len(), 6);
        let Item::Avoid(a) = &spec.items[1] else {
            panic!("avoid expected")
        };
        assert_eq!(a.steps.as_ref().map(|s| s.node), Some((3, 3)));
    }

    #[test]
    fn syntax_errors_point_at_the_problem() {
        let d = parse("horizon 5\nhorizon").expect_err("incomplete");
        assert_eq!(d[0].code, Code::Syntax);
        assert_eq!(d[0].span.map(|s| s.start), Some(17));
        let d = parse("horizon 99999999999999999999").expect_err("too large");
        assert_eq!(d[0].code, Code::IntegerTooLarge);
    }
}
