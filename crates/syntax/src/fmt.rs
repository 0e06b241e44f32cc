//! `ravel fmt`: specs in one canonical layout, comments kept.
//!
//! The formatter works on tokens, so nothing a person wrote is lost:
//! every comment stays where it was (a trailing comment two spaces after
//! the code), line breaks stay where they were (runs of blank lines become
//! one, none at the start or the end), and only the spaces between tokens
//! and the indentation change:
//!
//! * one space between tokens, none inside brackets, before `,`, or
//!   between a name and its index or call (`x[0]`, `box(…)`);
//! * four spaces per open `{` block; a line that continues an open `[` or
//!   `(` starts just after it (matrix rows line up);
//! * `\n` line endings, no byte-order mark, one final newline.
//!
//! It refuses to change meaning: the result must parse to the same syntax
//! tree as the input (spans aside), or the file is left alone and
//! [`Error::Changed`] says so. Formatting is idempotent (tested on every
//! shipped spec).

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
const LIST_WORDS: [&str; 7] = [
    "in", "steps", "uniform", "polytope", "center", "radius", "during",
];

fn lex(src: &str) -> Vec<Tok> {
    let chars: Vec<char> = src.chars().collect();
    let mut out = Vec::new();
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
    }
    out
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

/// Whether a space goes between `a` and `b` on one line.
fn space(a: &Tok, b: &Tok) -> bool {
    let p = |t: &Tok, s: &str| matches!(t, Tok::Punct(x) if x == s);
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

/// Re-emit the tokens in the canonical layout.
fn layout(toks: &[Tok]) -> String {
    let mut lines: Vec<String> = Vec::new();
    let mut line = String::new();
    let mut prev: Option<&Tok> = None;
    // open brackets: (char, column just after it in the output)
    let mut open: Vec<(char, usize)> = Vec::new();
    let mut blank_run = 0usize;
    let mut at_start = true;
    for t in toks {
        if *t == Tok::Newline {
            let trimmed = line.trim_end().to_string();
            if trimmed.is_empty() {
                blank_run += 1;
                if blank_run == 1 && !lines.is_empty() {
                    lines.push(String::new());
                }
            } else {
                blank_run = 0;
                lines.push(trimmed);
            }
            line.clear();
            prev = None;
            at_start = true;
            continue;
        }
        if at_start {
            let closes_block = matches!(t, Tok::Punct(x) if x == "}");
            let indent = match open.last() {
                Some(('[', col)) | Some(('(', col)) => *col,
                _ => {
                    let blocks = open.iter().filter(|(c, _)| *c == '{').count();
                    4 * blocks.saturating_sub(usize::from(closes_block))
                }
            };
            line = " ".repeat(indent);
            at_start = false;
        } else if let Some(a) = prev {
            if matches!(t, Tok::Line(_)) {
                line.push_str("  ");
            } else if space(a, t) {
                line.push(' ');
            }
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
        match text {
            "[" | "(" | "{" => {
                let c = text.chars().next().unwrap_or('[');
                open.push((c, line.chars().count()));
            }
            "]" | ")" | "}" => {
                open.pop();
            }
            _ => {}
        }
        // a block comment with line breaks: the lines after its first are kept as they are
        if let Tok::Block(b) = t {
            if b.contains('\n') {
                let mut parts: Vec<&str> = line.split('\n').collect();
                let last = parts.pop().unwrap_or("").to_string();
                lines.extend(parts.iter().map(|l| l.trim_end().to_string()));
                line = last;
            }
        }
        prev = Some(t);
    }
    let trimmed = line.trim_end().to_string();
    if !trimmed.is_empty() {
        lines.push(trimmed);
    }
    while lines.last().is_some_and(String::is_empty) {
        lines.pop();
    }
    let mut out = lines.join("\n");
    out.push('\n');
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
    let formatted = layout(&lex(source));
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
