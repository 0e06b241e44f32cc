//! ravel in the editor: what a language server answers about one document,
//! computed from its text alone (no IO: the front end's files are read
//! through the caller's [`ravel::Reader`], as on the command line).
//!
//! * [`diagnostics`]: the front end's diagnostics (parse and check, the
//!   controller read relative to the spec's folder);
//! * [`hover`]: what the name under the cursor is (a vector and its size,
//!   a matrix and its shape, a set and its kind and dimension, a constant
//!   and its value, a keyword, propagator or partitioner and what it does);
//! * [`definition`]: where a vector, matrix, constant, set or property
//!   named under the cursor is declared;
//! * [`completion`]: keywords, propagators after `propagator`,
//!   partitioners after `partitioner`, and the declared names;
//! * [`format`]: `ravel fmt`'s canonical text, or nothing for a spec that
//!   does not parse.
//!
//! Offsets are byte offsets into the text; [`line_index`] converts them to
//! and from the UTF-16 positions editors use. The protocol itself (JSON-RPC,
//! the Language Server Protocol's types) lives in the command line
//! (`ravel lsp`).
#![forbid(unsafe_code)]

pub mod line_index;
mod symbols;
pub mod words;

use std::path::Path;

use ravel_base::limits;
use ravel_syntax::ast::Span;
use ravel_syntax::diag::{Code, Diagnostic};

pub use symbols::{Symbol, SymbolKind};
use words::WordKind;

/// The front end's diagnostics for a document: none when the spec parses
/// and checks (its controller and data files read through `read`, relative
/// to `spec_dir`). A document larger than a spec file may be is one
/// diagnostic (E0216) and is not parsed.
pub fn diagnostics(source: &str, spec_dir: &Path, read: ravel::Reader) -> Vec<Diagnostic> {
    if source.len() as u64 > limits::MAX_SPEC_BYTES {
        return vec![Diagnostic::new(
            Code::Limit,
            Span::new(0, 0),
            format!(
                "this spec has {} bytes, more than the limit of {} bytes",
                source.len(),
                limits::MAX_SPEC_BYTES
            ),
        )
        .label("too large")
        .hint("a spec file is at most 16 MiB; keep large data in the controller or an observations file")];
    }
    match ravel::front_end_task(source, spec_dir, read, None) {
        Ok(_) => Vec::new(),
        Err(d) => d,
    }
}

/// `ravel fmt`'s text for a document, or `None` when it does not parse
/// (or is too large, or the formatter refuses, which leaves it as it is).
pub fn format(source: &str) -> Option<String> {
    if source.len() as u64 > limits::MAX_SPEC_BYTES {
        return None;
    }
    ravel_syntax::fmt::format(source).ok()
}

/// What hovering over a place shows.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Hover {
    /// The word hovered.
    pub span: Span,
    /// Markdown.
    pub markdown: String,
}

/// What the word at `offset` is: a declared name (with its kind and size)
/// or a fixed word of the language (with what it does); `None` elsewhere.
pub fn hover(source: &str, offset: usize) -> Option<Hover> {
    if source.len() as u64 > limits::MAX_SPEC_BYTES {
        return None;
    }
    let tokens = tokens(source);
    let at = word_at(&tokens, offset)?;
    let word = &source[tokens[at].start..tokens[at].end];
    let span = Span::new(tokens[at].start, tokens[at].end);
    let table = symbols::table(source, &tokens);
    // a name the spec declares, unless the word is a keyword in its place
    // (the word after `propagator` is a propagator even if a set has its name)
    let fixed = words::doc(word);
    let in_option_place = at > 0 && tokens[at - 1].kind == TokKind::Word && {
        let prev = &source[tokens[at - 1].start..tokens[at - 1].end];
        matches!(
            prev,
            "propagator" | "partitioner" | "boundary" | "shape" | "time" | "norm"
        )
    };
    if !in_option_place {
        if let Some(sym) = table.iter().find(|s| s.name == word) {
            let mut md = sym.markdown();
            if let Some(i) = component_index(source, &tokens, at) {
                md.push_str(&match sym.dim {
                    Some(n) if i >= n => format!(
                        "\n\ncomponent {i}: **out of range** (`{word}` has {n} components, 0 … {})",
                        n.saturating_sub(1)
                    ),
                    _ => format!("\n\ncomponent {i}"),
                });
            }
            return Some(Hover { span, markdown: md });
        }
    }
    let (kind, doc) = fixed?;
    let what = match kind {
        WordKind::Keyword => "keyword",
        WordKind::Propagator => "propagator",
        WordKind::Partitioner => "partitioner",
        WordKind::Option => "option",
        WordKind::Function => "built-in",
    };
    let mut markdown = format!("```ravel\n{word}\n```\n{what}: {doc}");
    if let Some(n) = observed(source, word, tokens[at].start) {
        markdown.push_str(&n);
    }
    Some(Hover { span, markdown })
}

/// For `observe` and `actuate` at `start`: how many observations the
/// controller sees, or how many inputs drive the plant.
fn observed(source: &str, word: &str, start: usize) -> Option<String> {
    use ravel_syntax::ast::{Item, SystemStmt};
    if word != "observe" && word != "actuate" {
        return None;
    }
    let spec = ravel_syntax::parse(source).ok()?;
    spec.items.iter().find_map(|i| match i {
        Item::System(s) => s.stmts.iter().find_map(|st| match st {
            SystemStmt::Observe { exprs, span } if span.start == start => Some(format!(
                "\n\nhere: the controller sees {} observations (its input vector)",
                exprs.len()
            )),
            SystemStmt::Actuate { exprs, span } if span.start == start => Some(format!(
                "\n\nhere: {} plant inputs, from the controller's outputs",
                exprs.len()
            )),
            _ => None,
        }),
        _ => None,
    })
}

/// Where the name at `offset` is declared, if it is a declared name.
pub fn definition(source: &str, offset: usize) -> Option<Span> {
    if source.len() as u64 > limits::MAX_SPEC_BYTES {
        return None;
    }
    let tokens = tokens(source);
    let at = word_at(&tokens, offset)?;
    let word = &source[tokens[at].start..tokens[at].end];
    symbols::table(source, &tokens)
        .into_iter()
        .find(|s| s.name == word)
        .map(|s| s.span)
}

/// What a completion inserts, and what kind of thing it is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Completion {
    /// The word.
    pub label: String,
    /// Its kind.
    pub kind: CompletionKind,
    /// One line on what it is.
    pub detail: String,
}

/// The kind of a completion.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CompletionKind {
    /// A fixed word of the language.
    Word(WordKind),
    /// A name the spec declares.
    Name(SymbolKind),
}

/// What may be written at `offset`: after `propagator` the propagators
/// (closed-loop or network ones, as the spec is), after `partitioner` the
/// partitioners, after `boundary`, `shape`, `time` and `norm` their
/// options; elsewhere the keywords, the declared names and the functions.
pub fn completion(source: &str, offset: usize) -> Vec<Completion> {
    if source.len() as u64 > limits::MAX_SPEC_BYTES {
        return Vec::new();
    }
    let tokens = tokens(source);
    let mut offset = offset.min(source.len());
    while !source.is_char_boundary(offset) {
        offset -= 1;
    }
    // the token before the word being typed (if any)
    let before: Vec<&Token> = tokens.iter().filter(|t| t.end < offset).collect();
    let typing = tokens
        .iter()
        .any(|t| t.kind == TokKind::Word && t.start < offset && offset <= t.end);
    let prev = if typing {
        before.last().copied()
    } else {
        tokens.iter().rfind(|t| t.end <= offset)
    };
    let prev_word = prev
        .filter(|t| t.kind == TokKind::Word)
        .map(|t| &source[t.start..t.end]);
    let fixed = |names: &[&str]| -> Vec<Completion> {
        names
            .iter()
            .filter_map(|n| {
                let (kind, doc) = words::doc(n)?;
                Some(Completion {
                    label: n.to_string(),
                    kind: CompletionKind::Word(kind),
                    detail: doc,
                })
            })
            .collect()
    };
    let has = |w: &str| {
        tokens
            .iter()
            .any(|t| t.kind == TokKind::Word && &source[t.start..t.end] == w)
    };
    match prev_word {
        Some("propagator") => {
            let mut names = Vec::new();
            let (network, system) = (has("network"), has("system"));
            if system || !network {
                names.extend(words::propagators());
            }
            if network || !system {
                names.extend(words::net_propagators());
            }
            fixed(&names)
        }
        Some("partitioner") => fixed(&words::partitioners()),
        Some("boundary") => fixed(&["box", "hull", "polytope"]),
        Some("shape") => fixed(&["box", "lower_bounds", "hull", "polytope"]),
        Some("time") => fixed(&["discrete", "continuous"]),
        Some("norm") => fixed(&["inf"]),
        _ => {
            let mut out: Vec<Completion> = symbols::table(source, &tokens)
                .into_iter()
                .map(|s| Completion {
                    detail: s.summary(),
                    label: s.name,
                    kind: CompletionKind::Name(s.kind),
                })
                .collect();
            for (w, kind, doc) in words::all() {
                if matches!(kind, WordKind::Keyword | WordKind::Function)
                    && !out.iter().any(|c| c.label == w)
                {
                    out.push(Completion {
                        label: w.to_string(),
                        kind: CompletionKind::Word(kind),
                        detail: doc,
                    });
                }
            }
            out
        }
    }
}

/// The kind of a token of the editor's own light lexer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum TokKind {
    /// A name or keyword.
    Word,
    /// A number.
    Number,
    /// A string literal.
    Str,
    /// One punctuation character.
    Punct,
}

/// A token: comments and white space are skipped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Token {
    pub(crate) kind: TokKind,
    pub(crate) start: usize,
    pub(crate) end: usize,
}

/// The tokens of a text, read as the grammar reads them (names are ASCII);
/// any text gives tokens, whether it parses or not.
pub(crate) fn tokens(source: &str) -> Vec<Token> {
    let b = source.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    let word = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    while i < b.len() {
        let c = b[i];
        let start = i;
        if c.is_ascii_whitespace() {
            i += 1;
        } else if b[i..].starts_with(b"//") {
            while i < b.len() && b[i] != b'\n' && b[i] != b'\r' {
                i += 1;
            }
        } else if b[i..].starts_with(b"/*") {
            i += 2;
            while i < b.len() && !b[i..].starts_with(b"*/") {
                i += 1;
            }
            i = (i + 2).min(b.len());
        } else if c == b'"' {
            i += 1;
            while i < b.len() && b[i] != b'"' && b[i] != b'\n' && b[i] != b'\r' {
                i += 1;
            }
            if i < b.len() && b[i] == b'"' {
                i += 1;
            }
            out.push(Token {
                kind: TokKind::Str,
                start,
                end: i,
            });
        } else if c.is_ascii_alphabetic() || c == b'_' {
            while i < b.len() && word(b[i]) {
                i += 1;
            }
            out.push(Token {
                kind: TokKind::Word,
                start,
                end: i,
            });
        } else if c.is_ascii_digit() || (c == b'.' && b.get(i + 1).is_some_and(u8::is_ascii_digit))
        {
            while i < b.len() {
                let d = b[i];
                let sign = (d == b'+' || d == b'-') && matches!(b[i - 1], b'e' | b'E');
                if word(d) || d == b'.' || sign {
                    i += 1;
                } else {
                    break;
                }
            }
            out.push(Token {
                kind: TokKind::Number,
                start,
                end: i,
            });
        } else {
            // one character, whole (the text may hold any Unicode)
            i += source[i..].chars().next().map_or(1, char::len_utf8);
            out.push(Token {
                kind: TokKind::Punct,
                start,
                end: i,
            });
        }
    }
    out
}

/// The word token under `offset` (a cursor just after a word is on it).
fn word_at(tokens: &[Token], offset: usize) -> Option<usize> {
    tokens
        .iter()
        .position(|t| t.kind == TokKind::Word && t.start <= offset && offset <= t.end)
}

/// `i` when the word at token `at` is followed by `[i]`.
fn component_index(source: &str, tokens: &[Token], at: usize) -> Option<u64> {
    let text = |k: usize| tokens.get(k).map(|t| &source[t.start..t.end]);
    if text(at + 1)? != "[" || text(at + 3)? != "]" {
        return None;
    }
    text(at + 2)?.parse().ok()
}

#[cfg(test)]
mod tests;
