//! `ravel fmt`: specs in one canonical layout, comments kept.
//!
//! The layout is the house style of the shipped specs. The formatter works
//! on tokens, so nothing a person wrote is lost: every comment stays on its
//! line, line breaks stay where they were (runs of blank lines become one,
//! none at the start or the end) except that every item and statement
//! starts a line of its own, and only the spaces between tokens and the
//! indentation change:
//!
//! * one space between tokens, none inside brackets, before `,`, or
//!   between a name and its index or call (`x[0]`, `box(…)`); a budget is
//!   not a call: `gsg (calls 32)`;
//! * one item or statement per line (`system s { state x[2] control u[1] }`
//!   is split), a block's `}` on a line of its own;
//! * four spaces per open `{` block; a line that continues an open `[` or
//!   `(` starts just after it (matrix rows line up), one that continues a
//!   polytope `{ … }` where its first constraint starts, a `| …` that
//!   continues a union under its item's `=`;
//! * consecutive statements whose keyword is one of `ALIGNED` line up
//!   their values (`state   x[2]` over `control u[1]`), and sets their
//!   names' `=` (`initial X0 = …` over `goal    G  = …`; see `NAMED` and
//!   `NAME_RATIO`);
//! * a matrix written one row per line has its columns aligned (numbers
//!   padded to the widest of their column, a sign column where one of them
//!   is negative);
//! * trailing comments of consecutive lines share one column, as gofmt
//!   aligns them: the rightmost of the columns they were written at, at
//!   least two spaces after the longest code;
//! * `\n` line endings, no byte-order mark, one final newline.
//!
//! It refuses to change meaning: the result must parse to the same syntax
//! tree as the input (spans aside), or the file is left alone and
//! [`Error::Changed`] says so. Formatting is idempotent (tested on every
//! shipped spec).

use std::collections::HashSet;

use crate::diag::Diagnostic;

/// Why a spec was not formatted.
#[derive(Debug)]
pub enum Error {
    /// The spec does not parse.
    Syntax(Vec<Diagnostic>),
    /// The formatted text would parse differently (a formatter bug): the
    /// file must be left as it is.
    Changed,
}

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    /// A word: keyword or name.
    Word(String),
    /// A number, with its sign when the sign is unary.
    Num(String),
    /// A string literal.
    Str(String),
    /// Punctuation or an operator.
    Punct(String),
    /// A unary minus before a name or a bracket (printed against it: `-x[0]`).
    Neg,
    /// `// …` (text without trailing spaces).
    Line(String),
    /// `/* … */`.
    Block(String),
    /// A line break.
    Newline,
}

/// Words after which a `[` is a list, not an index.
const LIST_WORDS: [&str; 9] = [
    "in",
    "steps",
    "uniform",
    "polytope",
    "center",
    "radius",
    "during",
    "epsilon",
    "observations",
];

/// A token with where it was written: its byte offset and its column (in
/// characters from the start of its line).
#[derive(Clone, Debug)]
struct Lexed {
    tok: Tok,
    offset: usize,
    column: usize,
}

fn lex(src: &str) -> Vec<Lexed> {
    let chars: Vec<char> = src.chars().collect();
    // the byte offset of every character (and of the end)
    let mut bytes: Vec<usize> = src.char_indices().map(|(b, _)| b).collect();
    bytes.push(src.len());
    let mut out: Vec<Tok> = Vec::new();
    // the character index each token starts at
    let mut starts: Vec<usize> = Vec::new();
    let mut i = 0;
    // a minus right before a digit is unary unless it follows a `]` or a
    // `)`: in the grammar only a term of a linear expression (ending in
    // `x[i]`) or an operand of an expression is followed by a binary minus
    // (a name before `-1` stays as written: `dt -1` is a signed number)
    let last = |out: &[Tok]| -> Option<Tok> {
        out.iter()
            .rev()
            .find(|t| !matches!(t, Tok::Newline | Tok::Line(_) | Tok::Block(_)))
            .cloned()
    };
    let operand = |out: &[Tok]| matches!(last(out), Some(Tok::Punct(p)) if p == "]" || p == ")");
    // any other minus is binary after an operand (a name, a number, `]` or `)`)
    let binary = |out: &[Tok]| {
        matches!(last(out), Some(Tok::Word(_) | Tok::Num(_)))
            || matches!(last(out), Some(Tok::Punct(p)) if p == "]" || p == ")")
    };
    // the character at `k`, and the characters `a..b` (`a ≤ b ≤ len`) as text
    let at = |k: usize| chars.get(k).copied();
    let between =
        |a: usize, b: usize| -> String { chars.get(a..b).unwrap_or_default().iter().collect() };
    while let Some(c) = at(i) {
        let here = i;
        let before = out.len();
        if c == '\u{feff}' || c == ' ' || c == '\t' {
            i += 1;
        } else if c == '\n' || c == '\r' {
            if c == '\r' && at(i + 1) == Some('\n') {
                i += 1;
            }
            out.push(Tok::Newline);
            i += 1;
        } else if c == '/' && at(i + 1) == Some('/') {
            let start = i;
            while at(i).is_some_and(|d| d != '\n' && d != '\r') {
                i += 1;
            }
            let text = between(start, i);
            out.push(Tok::Line(text.trim_end().to_string()));
        } else if c == '/' && at(i + 1) == Some('*') {
            let start = i;
            i += 2;
            while at(i).is_some_and(|d| !(d == '*' && at(i + 1) == Some('/'))) {
                i += 1;
            }
            i = (i + 2).min(chars.len());
            out.push(Tok::Block(between(start, i)));
        } else if c == '"' {
            let start = i;
            i += 1;
            while at(i).is_some_and(|d| d != '"' && d != '\n' && d != '\r') {
                i += 1;
            }
            i = (i + 1).min(chars.len());
            out.push(Tok::Str(between(start, i)));
        } else if c.is_ascii_alphabetic() || c == '_' {
            let start = i;
            while at(i).is_some_and(|d| d.is_ascii_alphanumeric() || d == '_') {
                i += 1;
            }
            out.push(Tok::Word(between(start, i)));
        } else if c.is_ascii_digit()
            || (c == '.' && chars.get(i + 1).is_some_and(char::is_ascii_digit))
            || (c == '-'
                && chars
                    .get(i + 1)
                    .is_some_and(|d| d.is_ascii_digit() || *d == '.')
                && !operand(&out))
        {
            let start = i;
            if c == '-' {
                i += 1;
            }
            while at(i).is_some_and(|d| d.is_ascii_digit() || d == '.') {
                i += 1;
            }
            if matches!(at(i), Some('e' | 'E')) {
                let mut k = i + 1;
                if matches!(at(k), Some('+' | '-')) {
                    k += 1;
                }
                if at(k).is_some_and(|d| d.is_ascii_digit()) {
                    i = k;
                    while at(i).is_some_and(|d| d.is_ascii_digit()) {
                        i += 1;
                    }
                }
            }
            out.push(Tok::Num(between(start, i)));
        } else if c == '-' && !binary(&out) {
            out.push(Tok::Neg);
            i += 1;
        } else if (c == '<' || c == '>') && chars.get(i + 1) == Some(&'=') {
            out.push(Tok::Punct(format!("{c}=")));
            i += 2;
        } else {
            out.push(Tok::Punct(c.to_string()));
            i += 1;
        }
        if out.len() > before {
            starts.push(here);
        }
    }
    let mut line_start = 0;
    let mut next = 0;
    out.into_iter()
        .zip(starts)
        .map(|(tok, start)| {
            while next < start {
                if matches!(at(next), Some('\n' | '\r')) {
                    line_start = next + 1;
                }
                next += 1;
            }
            Lexed {
                tok,
                offset: bytes.get(start).copied().unwrap_or(src.len()),
                column: start - line_start,
            }
        })
        .collect()
}

/// Spec-language keywords that are followed by a value, not an index.
fn is_keyword(w: &str) -> bool {
    matches!(
        w,
        "system"
            | "state"
            | "control"
            | "time"
            | "dt"
            | "controller"
            | "initial"
            | "goal"
            | "avoid"
            | "at"
            | "step"
            | "horizon"
            | "analysis"
            | "propagator"
            | "partitioner"
            | "boundary"
            | "samples"
            | "seed"
            | "optimise_slopes"
            | "norm"
            | "observe"
            | "actuate"
    )
}

/// Keywords whose values line up when statements using them stand on
/// consecutive lines (`state   x[2]` over `control u[1]`, `propagator  …`
/// over `partitioner …`). The others (`der`, `observe`, `controller`,
/// `robust`, `observations`, …) are followed by one space.
const ALIGNED: [&str; 20] = [
    "require",
    "state",
    "control",
    "time",
    "const",
    "input",
    "output",
    "initial",
    "goal",
    "avoid",
    "horizon",
    "propagator",
    "partitioner",
    "boundary",
    "shape",
    "samples",
    "seed",
    "optimise_slopes",
    "epsilon",
    "norm",
];

/// The keywords of set definitions, `KEYWORD NAME = set`, whose names line
/// up on consecutive lines (see `NAME_RATIO`).
const NAMED: [&str; 5] = ["initial", "goal", "avoid", "input", "require"];

/// Names of consecutive `KEYWORD NAME = …` lines are padded so that their
/// `=` line up, unless a name is this many times longer (or shorter) than
/// the one above it: then alignment starts afresh (`goal G  = …` does not
/// stretch to the `=` of `avoid overshoot = …`), as gofmt breaks alignment
/// between keys of very different sizes.
const NAME_RATIO: usize = 4;

/// What the grammar says about the places of a spec that layout needs.
#[derive(Default)]
struct Places {
    /// Byte offsets where an item or a statement of a block starts.
    items: HashSet<usize>,
    /// Byte offsets of the `}` closing a block (`system`, `network`,
    /// `select`, `analysis`).
    closes: HashSet<usize>,
    /// Byte offsets of the `(` opening a partitioner's or a radius search's
    /// budget (`gsg (calls 32)`, written with a space: it is not a call).
    budgets: HashSet<usize>,
    /// Byte offsets of the `{` opening a polytope set.
    polytopes: HashSet<usize>,
    /// Byte ranges of matrix literals.
    matrices: Vec<(usize, usize)>,
}

fn places(source: &str) -> Places {
    use crate::generated::{Grammar, Rule};
    use pest::Parser;
    let mut out = Places::default();
    let Ok(pairs) = Grammar::parse(Rule::spec, source) else {
        return out;
    };
    for p in pairs.flatten() {
        let (start, end) = (p.as_span().start(), p.as_span().end());
        match p.as_rule() {
            Rule::system | Rule::network | Rule::select | Rule::analysis => {
                out.items.insert(start);
                out.closes.insert(end.saturating_sub(1));
            }
            Rule::controller
            | Rule::model
            | Rule::initial
            | Rule::input_set
            | Rule::goal
            | Rule::avoid
            | Rule::require
            | Rule::robust
            | Rule::radius
            | Rule::horizon
            | Rule::input_decl
            | Rule::output_decl
            | Rule::epsilon_stmt
            | Rule::norm_stmt
            | Rule::observations_stmt
            | Rule::state_decl
            | Rule::control_decl
            | Rule::time_decl
            | Rule::const_decl
            | Rule::der_decl
            | Rule::next_decl
            | Rule::observe_decl
            | Rule::actuate_decl
            | Rule::bound_decl
            | Rule::assign
            | Rule::propagator
            | Rule::partitioner
            | Rule::boundary
            | Rule::shape
            | Rule::samples
            | Rule::seed
            | Rule::optimise_slopes => {
                out.items.insert(start);
            }
            Rule::budget => {
                out.budgets.insert(start);
            }
            Rule::polytope => {
                out.polytopes.insert(start);
            }
            Rule::matrix => out.matrices.push((start, end)),
            _ => {}
        }
    }
    out
}

fn is_punct(t: &Tok, s: &str) -> bool {
    matches!(t, Tok::Punct(x) if x == s)
}

/// Whether a space goes between `a` and `b` on one line (`budget`: `b`
/// opens a budget).
fn space(a: &Tok, b: &Tok, budget: bool) -> bool {
    let p = is_punct;
    if budget {
        return true;
    }
    if *a == Tok::Neg || p(a, "^") || p(b, "^") {
        return false;
    }
    if p(b, ",") || p(b, ")") || p(b, "]") || p(a, "(") || p(a, "[") {
        return false;
    }
    if let Tok::Word(w) = a {
        if (p(b, "[") && !LIST_WORDS.contains(&w.as_str()) && !is_keyword(w)) || p(b, "(") {
            return false;
        }
    }
    true
}

/// One item per line: a line break before every item or statement and
/// before a block's closing `}` that follow code on their line.
fn split_items(toks: Vec<Lexed>, places: &Places) -> Vec<Lexed> {
    let mut out: Vec<Lexed> = Vec::with_capacity(toks.len());
    let mut code_on_line = false;
    for t in toks {
        let starts = places.items.contains(&t.offset)
            || (places.closes.contains(&t.offset) && is_punct(&t.tok, "}"));
        match t.tok {
            Tok::Newline => code_on_line = false,
            Tok::Line(_) | Tok::Block(_) => {}
            _ => {
                if starts && code_on_line {
                    out.push(Lexed {
                        tok: Tok::Newline,
                        offset: t.offset,
                        column: 0,
                    });
                }
                code_on_line = true;
            }
        }
        out.push(t);
    }
    out
}

/// Extra spaces before the cells of a matrix written one row per line, so
/// that its columns line up: every cell as wide as the widest of its column,
/// a column holding a negative number with a sign column (`-0.98` over ` 0`).
/// A matrix of one column, or with a row broken over lines, a comment or
/// anything but a number in a cell, is left as it is.
fn align_matrix(toks: &[Lexed], range: (usize, usize), extra: &mut [usize]) {
    let inside: Vec<usize> = (0..toks.len())
        .filter(|&k| {
            toks.get(k)
                .is_some_and(|t| t.offset >= range.0 && t.offset < range.1)
        })
        .collect();
    let tok = |k: usize| toks.get(k).map(|t| &t.tok);
    if inside
        .iter()
        .any(|&k| matches!(tok(k), Some(Tok::Line(_) | Tok::Block(_))))
    {
        return;
    }
    // rows: (the cells' token indices, the index of the row's `]`)
    let mut rows: Vec<(Vec<usize>, usize)> = Vec::new();
    let mut pos = 1; // after the outer `[`
    let mut newline_before = false;
    while let Some(&k) = inside.get(pos) {
        match tok(k) {
            Some(Tok::Newline) => {
                newline_before = true;
                pos += 1;
            }
            Some(Tok::Punct(p)) if p == "[" => {
                // every row after the first starts a line, the first does not
                if newline_before == rows.is_empty() {
                    return;
                }
                newline_before = false;
                let mut cells = Vec::new();
                pos += 1;
                loop {
                    let Some(&c) = inside.get(pos) else { return };
                    if !matches!(tok(c), Some(Tok::Num(_))) {
                        return;
                    }
                    cells.push(c);
                    let Some(&after) = inside.get(pos + 1) else {
                        return;
                    };
                    pos += 2;
                    match tok(after) {
                        Some(Tok::Punct(p)) if p == "," => {}
                        Some(Tok::Punct(p)) if p == "]" => {
                            rows.push((cells, after));
                            break;
                        }
                        _ => return,
                    }
                }
            }
            Some(Tok::Punct(p)) if p == "," || p == "]" => pos += 1,
            _ => return,
        }
    }
    let cols = rows.first().map_or(0, |r| r.0.len());
    if rows.len() < 2 || cols < 2 || rows.iter().any(|r| r.0.len() != cols) {
        return;
    }
    let text = |k: usize| match tok(k) {
        Some(Tok::Num(s)) => s.as_str(),
        _ => "",
    };
    for j in 0..cols {
        let column: Vec<usize> = rows.iter().filter_map(|r| r.0.get(j).copied()).collect();
        let signed = column.iter().any(|&k| text(k).starts_with('-'));
        let width =
            |k: usize| text(k).chars().count() + usize::from(signed && !text(k).starts_with('-'));
        let widest = column.iter().map(|&k| width(k)).max().unwrap_or(0);
        for (cells, close) in &rows {
            let Some(&k) = cells.get(j) else { continue };
            if signed && !text(k).starts_with('-') {
                if let Some(e) = extra.get_mut(k) {
                    *e += 1;
                }
            }
            let next = cells.get(j + 1).copied().unwrap_or(*close);
            if let Some(e) = extra.get_mut(next) {
                *e += widest - width(k);
            }
        }
    }
}

/// Extra spaces that line up the values of consecutive statements with an
/// [`ALIGNED`] keyword, and the `=` of their names after a [`NAMED`]
/// keyword (see [`NAME_RATIO`]).
fn align_statements(toks: &[Lexed], places: &Places, extra: &mut [usize]) {
    // the runs of statement lines, each line as the index of its first token
    let mut runs: Vec<Vec<usize>> = vec![Vec::new()];
    // brackets open at this point: true for a block's `{`
    let mut open: Vec<bool> = Vec::new();
    let mut line_start = true;
    for (k, t) in toks.iter().enumerate() {
        match &t.tok {
            Tok::Newline => {
                if line_start {
                    // a blank line ends a run
                    runs.push(Vec::new());
                }
                line_start = true;
                continue;
            }
            Tok::Line(_) | Tok::Block(_) => {
                if line_start {
                    // so does a line of comment
                    runs.push(Vec::new());
                    line_start = false;
                }
                continue;
            }
            _ => {}
        }
        if line_start {
            line_start = false;
            let continuation = open.last().is_some_and(|block| !block);
            if !continuation {
                let aligned = places.items.contains(&t.offset)
                    && matches!(&t.tok, Tok::Word(w) if ALIGNED.contains(&w.as_str()));
                if aligned {
                    if let Some(run) = runs.last_mut() {
                        run.push(k);
                    }
                } else {
                    runs.push(Vec::new());
                }
            }
        }
        match &t.tok {
            Tok::Punct(p) if p == "(" || p == "[" => open.push(false),
            Tok::Punct(p) if p == "{" => open.push(!places.polytopes.contains(&t.offset)),
            Tok::Punct(p) if p == ")" || p == "]" || p == "}" => {
                open.pop();
            }
            _ => {}
        }
    }
    let word = |k: usize| match toks.get(k).map(|t| &t.tok) {
        Some(Tok::Word(w)) => Some(w.chars().count()),
        _ => None,
    };
    for run in runs.iter().filter(|r| r.len() > 1) {
        let widest = run.iter().filter_map(|&k| word(k)).max().unwrap_or(0);
        for &k in run {
            let next_on_line = toks
                .get(k + 1)
                .is_some_and(|t| !matches!(t.tok, Tok::Newline | Tok::Line(_)));
            if let (Some(len), true, Some(e)) = (word(k), next_on_line, extra.get_mut(k + 1)) {
                *e += widest - len;
            }
        }
        // sections of `KEYWORD NAME =` lines: (index of the `=`, name length)
        let mut sections: Vec<Vec<(usize, usize)>> = vec![Vec::new()];
        for &k in run {
            let eq = toks.get(k + 2).is_some_and(|t| is_punct(&t.tok, "="))
                && matches!(toks.get(k).map(|t| &t.tok), Some(Tok::Word(w)) if NAMED.contains(&w.as_str()));
            match (word(k + 1), eq) {
                (Some(len), true) => {
                    let fresh = sections
                        .last()
                        .and_then(|s| s.last())
                        .is_some_and(|&(_, prev)| {
                            len >= NAME_RATIO * prev || prev >= NAME_RATIO * len
                        });
                    if fresh {
                        sections.push(Vec::new());
                    }
                    if let Some(s) = sections.last_mut() {
                        s.push((k + 2, len));
                    }
                }
                _ => sections.push(Vec::new()),
            }
        }
        for section in sections {
            let widest = section.iter().map(|s| s.1).max().unwrap_or(0);
            for (eq, len) in section {
                if let Some(e) = extra.get_mut(eq) {
                    *e += widest - len;
                }
            }
        }
    }
}

/// A line of output: its code, and a trailing comment with the column it
/// was written at.
struct Line {
    code: String,
    comment: Option<(String, usize)>,
}

/// Re-emit the tokens in the canonical layout (`extra`: spaces to add
/// before each token, for alignment).
fn layout(toks: &[Lexed], extra: &[usize], places: &Places) -> String {
    let mut lines: Vec<Line> = Vec::new();
    let mut line = String::new();
    let mut comment: Option<(String, usize)> = None;
    let mut prev: Option<&Tok> = None;
    // open brackets: (kind, column of a continuation line); kind `{` is a
    // block, `s` a polytope set's brace
    let mut open: Vec<(char, usize)> = Vec::new();
    let mut blank_run = 0usize;
    let mut at_start = true;
    // the column of the current item's `=` (outside brackets)
    let mut equals: Option<usize> = None;
    let blank = |lines: &[Line]| {
        lines
            .last()
            .map(|l| l.code.is_empty() && l.comment.is_none())
    };
    for (k, lexed) in toks.iter().enumerate() {
        let t = &lexed.tok;
        if *t == Tok::Newline {
            let trimmed = line.trim_end().to_string();
            if trimmed.is_empty() && comment.is_none() {
                blank_run += 1;
                if blank_run == 1 && blank(&lines).is_some() {
                    lines.push(Line {
                        code: String::new(),
                        comment: None,
                    });
                }
            } else {
                blank_run = 0;
                lines.push(Line {
                    code: trimmed,
                    comment: comment.take(),
                });
            }
            line.clear();
            prev = None;
            at_start = true;
            continue;
        }
        if let Tok::Line(text) = t {
            if !at_start && !line.trim().is_empty() {
                comment = Some((text.clone(), lexed.column));
                prev = Some(t);
                continue;
            }
        }
        if at_start {
            let closes_block = is_punct(t, "}");
            let indent = match open.last() {
                Some(('[', col)) | Some(('(', col)) | Some(('s', col)) => *col,
                _ => {
                    let blocks = open.iter().filter(|(c, _)| *c == '{').count();
                    let block = 4 * blocks.saturating_sub(usize::from(closes_block));
                    let continues = !closes_block
                        && !matches!(t, Tok::Line(_) | Tok::Block(_))
                        && !places.items.contains(&lexed.offset);
                    match (continues, equals) {
                        // `| { … }` under the `=` of its item
                        (true, Some(col)) if is_punct(t, "|") => col,
                        (true, _) => block + 4,
                        (false, _) => block,
                    }
                }
            };
            line = " ".repeat(indent);
            at_start = false;
        } else if let Some(a) = prev {
            if space(
                a,
                t,
                places.budgets.contains(&lexed.offset) && is_punct(t, "("),
            ) {
                line.push(' ');
            }
            line.push_str(&" ".repeat(extra.get(k).copied().unwrap_or(0)));
        }
        let text = match t {
            Tok::Word(s)
            | Tok::Num(s)
            | Tok::Str(s)
            | Tok::Punct(s)
            | Tok::Line(s)
            | Tok::Block(s) => s.as_str(),
            Tok::Neg => "-",
            Tok::Newline => "",
        };
        line.push_str(text);
        if places.items.contains(&lexed.offset) {
            equals = None;
        }
        if text == "=" && open.iter().all(|(c, _)| *c == '{') {
            equals = Some(line.chars().count() - 1);
        }
        match t {
            Tok::Punct(p) if p == "[" || p == "(" => {
                let c = if p == "[" { '[' } else { '(' };
                open.push((c, line.chars().count()));
            }
            Tok::Punct(p) if p == "{" => {
                if places.polytopes.contains(&lexed.offset) {
                    // continuation lines start where the first constraint does
                    open.push(('s', line.chars().count() + 1));
                } else {
                    open.push(('{', 0));
                }
            }
            Tok::Punct(p) if p == "]" || p == ")" || p == "}" => {
                open.pop();
            }
            _ => {}
        }
        // a block comment with line breaks: the lines after its first are kept as they are
        if let Tok::Block(b) = t {
            if b.contains('\n') {
                let mut parts: Vec<&str> = line.split('\n').collect();
                let last = parts.pop().unwrap_or("").to_string();
                lines.extend(parts.iter().map(|l| Line {
                    code: l.trim_end().to_string(),
                    comment: None,
                }));
                line = last;
            }
        }
        prev = Some(t);
    }
    let trimmed = line.trim_end().to_string();
    if !trimmed.is_empty() || comment.is_some() {
        lines.push(Line {
            code: trimmed,
            comment,
        });
    }
    while blank(&lines) == Some(true) {
        lines.pop();
    }
    // trailing comments of consecutive lines share one column: the
    // rightmost of the columns they were written at, at least two spaces
    // after the longest code
    let mut out = String::new();
    let mut k = 0;
    while k < lines.len() {
        let mut end = k;
        while lines
            .get(end)
            .is_some_and(|l| l.comment.is_some() && !l.code.is_empty())
        {
            end += 1;
        }
        let group = lines.get(k..end).unwrap_or_default();
        let column = group
            .iter()
            .map(|l| {
                let written = l.comment.as_ref().map_or(0, |c| c.1);
                written.max(l.code.chars().count() + 2)
            })
            .max()
            .unwrap_or(0);
        for l in group.iter().chain(
            lines
                .get(end..end + usize::from(end == k))
                .unwrap_or_default(),
        ) {
            out.push_str(&l.code);
            if let Some((c, _)) = &l.comment {
                if l.code.is_empty() {
                    out.push_str(c);
                } else {
                    let pad = column.saturating_sub(l.code.chars().count());
                    out.push_str(&" ".repeat(pad));
                    out.push_str(c);
                }
            }
            out.push('\n');
        }
        k = end.max(k + 1);
    }
    if out.is_empty() {
        out.push('\n');
    }
    out
}

/// The syntax tree's debug form without positions, for comparing meaning.
fn shape(source: &str) -> Result<String, Vec<Diagnostic>> {
    let ast = crate::parse(source)?;
    let text = format!("{ast:#?}");
    let mut out = String::with_capacity(text.len());
    for l in text.lines() {
        if l.trim_start().starts_with("span:") {
            continue;
        }
        // drop " @12..34"
        let mut s = l.to_string();
        while let Some(at) = s.find(" @") {
            let rest = &s[at + 2..];
            let len = rest
                .chars()
                .take_while(|c| c.is_ascii_digit() || *c == '.')
                .count();
            if len == 0 {
                break;
            }
            s.replace_range(at..at + 2 + len, "");
        }
        out.push_str(&s);
        out.push('\n');
    }
    Ok(out)
}

/// Format a spec.
pub fn format(source: &str) -> Result<String, Error> {
    let before = shape(source).map_err(Error::Syntax)?;
    let places = places(source);
    let toks = split_items(lex(source), &places);
    let mut extra = vec![0; toks.len()];
    for &range in &places.matrices {
        align_matrix(&toks, range, &mut extra);
    }
    align_statements(&toks, &places, &mut extra);
    let formatted = layout(&toks, &extra, &places);
    match shape(&formatted) {
        Ok(after) if after == before => Ok(formatted),
        _ => Err(Error::Changed),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn spacing_indentation_and_comments() {
        let src = "system   s {\n state x[2]  // two\n\n\n    A = [[1,1],\n  [0, 1]]\n}\navoid  a = {x[0]-2*x[1] <= -1}  at steps [1,2]\n";
        let out = format(src).expect("formats");
        assert_eq!(
            out,
            "system s {\n    state x[2]  // two\n\n    A = [[1, 1],\n         [0, 1]]\n}\navoid a = { x[0] - 2 * x[1] <= -1 } at steps [1, 2]\n"
        );
        assert_eq!(format(&out).expect("formats"), out);
    }

    #[test]
    fn expressions_take_their_canonical_spacing() {
        let src = "system s {\n state x[2]\n const  k=2*pi\n der x[0]=-x[1]^-2 +k*sin( x[0] )/(1+x[1]^2)\n der x[1] = - -x[0]-1\n observe [ x[0] , 30]\n}\n";
        let out = format(src).expect("formats");
        assert_eq!(
            out,
            "system s {\n    state x[2]\n    const k = 2 * pi\n    der x[0] = -x[1]^-2 + k * sin(x[0]) / (1 + x[1]^2)\n    der x[1] = --x[0] - 1\n    observe [x[0], 30]\n}\n"
        );
        assert_eq!(format(&out).expect("formats"), out);
    }
}
