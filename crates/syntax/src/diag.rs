//! Diagnostics: plain data produced by the phases, rendered (with miette) only
//! at the edge. Every diagnostic has a stable code documented in
//! `docs/diagnostics.md`.

use std::fmt;

use miette::{GraphicalReportHandler, GraphicalTheme, LabeledSpan, NamedSource, SourceCode};

use crate::ast::Span;
pub use ravel_base::text::{compact, sanitize, sanitize_to};

/// A stable diagnostic code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Code {
    /// E0001: the text does not follow the grammar.
    Syntax,
    /// E0002: an integer literal does not fit in 64 bits.
    IntegerTooLarge,
    /// E0101: a name that is not defined.
    UnknownName,
    /// E0102: something defined twice.
    Duplicate,
    /// E0103: a required item is missing.
    Missing,
    /// E0104: a component index outside the vector.
    IndexOutOfRange,
    /// E0105: a value of the wrong kind (a matrix where a vector is expected, …).
    WrongKind,
    /// E0106: an item or setting of the other kind of spec (system vs network).
    SpecKind,
    /// E0201: a matrix or vector of the wrong shape.
    Shape,
    /// E0202: matrix rows of different lengths.
    Ragged,
    /// E0203: an interval whose lower end exceeds its upper end.
    EmptyInterval,
    /// E0204: a horizon below 1.
    Horizon,
    /// E0205: a number that is not finite (overflow such as `1e400`).
    NonFinite,
    /// E0206: an avoid step range that is inverted or beyond the horizon.
    StepRange,
    /// E0207: a partition grid that does not fit the state.
    Partition,
    /// E0208: a dimension or count that must be positive is zero.
    Zero,
    /// E0209: a set of a kind this role does not accept.
    SetKind,
    /// E0210: a set that is empty, or unbounded where a bounded set is needed.
    EmptyOrUnbounded,
    /// E0211: reachable-set boundary directions that cannot be used.
    Boundary,
    /// E0212: a time-varying plant whose list is shorter than the horizon.
    PerStepLength,
    /// E0213: a bad time declaration (unknown kind, missing or non-positive `dt`).
    TimeStep,
    /// E0214: a partitioner budget item with an invalid value.
    Budget,
    /// E0215: Reach-SDP requested for a network with non-ReLU activations.
    SdpActivation,
    /// E0216: a number, size or count beyond ravel's documented limits.
    Limit,
    /// E0217: a robustness label that is out of range or cannot be determined.
    Label,
    /// E0218: a radius search that cannot be set up.
    Radius,
    /// E0219: observations or ε of a select block that cannot be used (CSV cells, widths, values).
    Observations,
    /// E0220: slope optimisation with a propagator that has no slopes to optimise.
    SlopeSteps,
    /// E0221: a call of a function the language does not have.
    UnknownFunction,
    /// E0222: a function called with other than one argument.
    Arity,
    /// E0223: an exponent that is not a constant integer.
    Exponent,
    /// E0224: a divisor that is the constant 0.
    ZeroDivisor,
    /// E0225: a nonlinear plant undefined at a point of the initial set (a division by 0, `sqrt` of a negative, `log` of a non-positive number).
    Undefined,
    /// E0226: an `observe` or `actuate` entry that is not affine.
    NotAffine,
    /// E0227: a mix of plant forms: `der` with `next`, with the wrong time, or with `A`, `B`, `c`; `C` with `observe`.
    PlantKind,
    /// E0228: an inequality that is not affine in a set that must be linear (initial sets, network specs).
    NonlinearSet,
    /// E0229: a time window or time that cannot be used (no time step, not finite, inverted, beyond the horizon, not a sampling instant, no sampling instant inside).
    TimeWindow,
    /// E0301: the controller file cannot be read.
    ControllerUnreadable,
    /// E0302: the controller file is not an ONNX model.
    NotOnnx,
    /// E0303: an ONNX operator or data type ravel does not support.
    UnsupportedOnnx,
    /// E0304: the controller's input size differs from the observation size.
    ControllerInputs,
    /// E0305: the controller's output size differs from the control size.
    ControllerOutputs,
    /// E0306: a NaN or infinite weight.
    NonFiniteWeights,
    /// E0307: an ONNX graph that is not a chain or has inconsistent shapes.
    MalformedOnnx,
    /// E0308: an external-data file that is missing or too short.
    ExternalData,
    /// E0401: a VNN-LIB property that cannot be read or imported.
    Vnnlib,
    /// E0402: an unusable row of a VNN-COMP instance list.
    Instances,
    /// E0403: `--format csv` asked of a spec without a `select` block (nothing to print).
    CsvWithoutSelect,
}

impl Code {
    /// Every code, in order (the documentation test walks this list).
    pub const ALL: [Code; 48] = [
        Code::Syntax,
        Code::IntegerTooLarge,
        Code::UnknownName,
        Code::Duplicate,
        Code::Missing,
        Code::IndexOutOfRange,
        Code::WrongKind,
        Code::SpecKind,
        Code::Shape,
        Code::Ragged,
        Code::EmptyInterval,
        Code::Horizon,
        Code::NonFinite,
        Code::StepRange,
        Code::Partition,
        Code::Zero,
        Code::SetKind,
        Code::EmptyOrUnbounded,
        Code::Boundary,
        Code::PerStepLength,
        Code::TimeStep,
        Code::Budget,
        Code::SdpActivation,
        Code::Limit,
        Code::Label,
        Code::Radius,
        Code::Observations,
        Code::SlopeSteps,
        Code::UnknownFunction,
        Code::Arity,
        Code::Exponent,
        Code::ZeroDivisor,
        Code::Undefined,
        Code::NotAffine,
        Code::PlantKind,
        Code::NonlinearSet,
        Code::TimeWindow,
        Code::ControllerUnreadable,
        Code::NotOnnx,
        Code::UnsupportedOnnx,
        Code::ControllerInputs,
        Code::ControllerOutputs,
        Code::NonFiniteWeights,
        Code::MalformedOnnx,
        Code::ExternalData,
        Code::Vnnlib,
        Code::Instances,
        Code::CsvWithoutSelect,
    ];

    /// The code as written in messages, e.g. `E0201`.
    pub fn as_str(self) -> &'static str {
        match self {
            Code::Syntax => "E0001",
            Code::IntegerTooLarge => "E0002",
            Code::UnknownName => "E0101",
            Code::Duplicate => "E0102",
            Code::Missing => "E0103",
            Code::IndexOutOfRange => "E0104",
            Code::WrongKind => "E0105",
            Code::SpecKind => "E0106",
            Code::Shape => "E0201",
            Code::Ragged => "E0202",
            Code::EmptyInterval => "E0203",
            Code::Horizon => "E0204",
            Code::NonFinite => "E0205",
            Code::StepRange => "E0206",
            Code::Partition => "E0207",
            Code::Zero => "E0208",
            Code::SetKind => "E0209",
            Code::EmptyOrUnbounded => "E0210",
            Code::Boundary => "E0211",
            Code::PerStepLength => "E0212",
            Code::TimeStep => "E0213",
            Code::Budget => "E0214",
            Code::SdpActivation => "E0215",
            Code::Limit => "E0216",
            Code::Label => "E0217",
            Code::Radius => "E0218",
            Code::Observations => "E0219",
            Code::SlopeSteps => "E0220",
            Code::UnknownFunction => "E0221",
            Code::Arity => "E0222",
            Code::Exponent => "E0223",
            Code::ZeroDivisor => "E0224",
            Code::Undefined => "E0225",
            Code::NotAffine => "E0226",
            Code::PlantKind => "E0227",
            Code::NonlinearSet => "E0228",
            Code::TimeWindow => "E0229",
            Code::ControllerUnreadable => "E0301",
            Code::NotOnnx => "E0302",
            Code::UnsupportedOnnx => "E0303",
            Code::ControllerInputs => "E0304",
            Code::ControllerOutputs => "E0305",
            Code::NonFiniteWeights => "E0306",
            Code::MalformedOnnx => "E0307",
            Code::ExternalData => "E0308",
            Code::Vnnlib => "E0401",
            Code::Instances => "E0402",
            Code::CsvWithoutSelect => "E0403",
        }
    }
}

/// One problem in a spec, as data.
#[derive(Clone, Debug, PartialEq)]
pub struct Diagnostic {
    /// The stable code.
    pub code: Code,
    /// What is wrong.
    pub message: String,
    /// Where (absent only for problems without a location, e.g. an unreadable spec).
    pub span: Option<Span>,
    /// The label at the span.
    pub label: String,
    /// How to fix it.
    pub hint: Option<String>,
    /// Further locations that explain the problem (e.g. the first definition of a duplicate).
    pub related: Vec<(Span, String)>,
}

impl Diagnostic {
    /// A diagnostic at `span`.
    pub fn new(code: Code, span: Span, message: impl Into<String>) -> Diagnostic {
        Diagnostic {
            code,
            message: message.into(),
            span: Some(span),
            label: String::new(),
            hint: None,
            related: Vec::new(),
        }
    }

    /// Set the label shown at the span.
    pub fn label(mut self, label: impl Into<String>) -> Diagnostic {
        self.label = label.into();
        self
    }

    /// Set the hint.
    pub fn hint(mut self, hint: impl Into<String>) -> Diagnostic {
        self.hint = Some(hint.into());
        self
    }

    /// Add a related location.
    pub fn related(mut self, span: Span, label: impl Into<String>) -> Diagnostic {
        self.related.push((span, label.into()));
        self
    }
}

/// Adapter that lets miette render a [`Diagnostic`] against its source.
struct Report<'a> {
    d: &'a Diagnostic,
    src: NamedSource<String>,
}

impl fmt::Display for Report<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.d.message)
    }
}

impl fmt::Debug for Report<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.d.message)
    }
}

impl std::error::Error for Report<'_> {}

impl miette::Diagnostic for Report<'_> {
    fn code<'b>(&'b self) -> Option<Box<dyn fmt::Display + 'b>> {
        Some(Box::new(self.d.code.as_str()))
    }

    fn help<'b>(&'b self) -> Option<Box<dyn fmt::Display + 'b>> {
        self.d
            .hint
            .as_ref()
            .map(|h| Box::new(h.as_str()) as Box<dyn fmt::Display>)
    }

    fn source_code(&self) -> Option<&dyn SourceCode> {
        self.d.span.map(|_| &self.src as &dyn SourceCode)
    }

    fn labels(&self) -> Option<Box<dyn Iterator<Item = LabeledSpan> + '_>> {
        let span = self.d.span?;
        let len = self.src.inner().len();
        let clamp = |s: Span| {
            (
                s.start.min(len),
                s.end.min(len).saturating_sub(s.start.min(len)),
            )
        };
        let (start, n) = clamp(span);
        let label = if self.d.label.is_empty() {
            None
        } else {
            Some(self.d.label.clone())
        };
        let mut labels = vec![LabeledSpan::new_primary_with_span(label, (start, n))];
        for (s, l) in &self.d.related {
            labels.push(LabeledSpan::new_with_span(Some(l.clone()), clamp(*s)));
        }
        Some(Box::new(labels.into_iter()))
    }
}

/// 1-based line and column (in characters) of a byte offset; lines end at
/// LF, CRLF or a lone CR.
pub fn line_col(source: &str, offset: usize) -> (usize, usize) {
    let mut offset = offset.min(source.len());
    while !source.is_char_boundary(offset) {
        offset -= 1;
    }
    let before = source.get(..offset).unwrap_or_default();
    let line = before.matches('\n').count() + before.matches('\r').count()
        - before.matches("\r\n").count()
        + 1;
    let col = before
        .rsplit(['\n', '\r'])
        .next()
        .map_or(0, |l| l.chars().count())
        + 1;
    (line, col)
}

/// Render diagnostics for a source file as text.
///
/// `color` turns on ANSI colours; `width` wraps messages. With `color = false`
/// the output is plain Unicode text and deterministic (used by snapshots).
pub fn render(diags: &[Diagnostic], name: &str, source: &str, width: usize, color: bool) -> String {
    let theme = if color {
        GraphicalTheme::unicode()
    } else {
        GraphicalTheme::unicode_nocolor()
    };
    let handler = GraphicalReportHandler::new_themed(theme)
        .with_width(width)
        .with_links(false);
    let mut out = String::new();
    let shown = displayable(source);
    let name = sanitize(name);
    for d in diags.iter().take(MAX_RENDERED) {
        // a very long source line would be printed whole for each diagnostic
        // on it: point at it by line and column instead
        let long_line = d
            .span
            .is_some_and(|s| line_around(source, s.start).len() > MAX_SHOWN_LINE);
        if long_line {
            out.push_str(&plain(d, &name, source));
        } else {
            let report = Report {
                d,
                src: NamedSource::new(name.clone(), shown.clone()),
            };
            if handler.render_report(&mut out, &report).is_err() {
                out.push_str(&plain(d, &name, source));
            }
        }
        out.push('\n');
    }
    if diags.len() > MAX_RENDERED {
        out.push_str(&format!(
            "… and {} more diagnostics (fix the ones above first)\n",
            diags.len() - MAX_RENDERED
        ));
    }
    out
}

/// Diagnostics shown in full; the rest are counted.
const MAX_RENDERED: usize = 50;
/// Source lines longer than this are not quoted in diagnostics.
const MAX_SHOWN_LINE: usize = 400;

/// The source line containing byte `at`.
fn line_around(source: &str, at: usize) -> &str {
    let mut at = at.min(source.len());
    while !source.is_char_boundary(at) {
        at -= 1;
    }
    let start = source[..at].rfind(['\n', '\r']).map_or(0, |i| i + 1);
    let end = source[at..]
        .find(['\n', '\r'])
        .map_or(source.len(), |i| at + i);
    &source[start..end]
}

/// A diagnostic without a quoted source: code, message, position, label, hint.
fn plain(d: &Diagnostic, name: &str, source: &str) -> String {
    let at = d.span.map_or(String::new(), |s| {
        let before = &source[..s.start.min(source.len())];
        let line = before.matches('\n').count() + 1;
        let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
        format!("\n   at {name}:{line}:{col}: {}", d.label)
    });
    let hint = d
        .hint
        .as_ref()
        .map_or(String::new(), |h| format!("\n  help: {h}"));
    format!("{}\n\n  × {}{at}{hint}\n", d.code.as_str(), d.message)
}

/// The source as it may be shown on a terminal: control and invisible
/// format characters (other than line breaks and tabs) are replaced by
/// placeholders of the same UTF-8 length, so every span still points at the
/// same bytes.
fn displayable(source: &str) -> String {
    source
        .chars()
        .map(|c| {
            let invisible = (c.is_control() && !matches!(c, '\n' | '\r' | '\t'))
                || matches!(c, '\u{200b}'..='\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}' | '\u{feff}');
            if !invisible {
                return c.to_string();
            }
            match c.len_utf8() {
                1 => "?".to_string(),
                2 => "\u{bf}".to_string(),
                3 => "\u{fffd}".to_string(),
                n => "?".repeat(n),
            }
        })
        .collect()
}

/// The closest candidate to `name` by edit distance, if it is close enough to be a likely typo.
pub fn did_you_mean<'a>(
    name: &str,
    candidates: impl IntoIterator<Item = &'a str>,
) -> Option<&'a str> {
    let mut best: Option<(usize, &str)> = None;
    for c in candidates {
        let d = edit_distance(&name.to_lowercase(), &c.to_lowercase());
        if d <= (name.len().max(c.len()) / 3).max(1) && best.is_none_or(|(bd, _)| d < bd) {
            best = Some((d, c));
        }
    }
    best.map(|(_, c)| c)
}

fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    // the distances from a prefix of `a` to every prefix of `b`
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut left = i + 1;
        let mut cur = Vec::with_capacity(b.len() + 1);
        cur.push(left);
        for ((diagonal, above), cb) in prev.iter().zip(prev.iter().skip(1)).zip(&b) {
            let sub = diagonal + usize::from(ca != *cb);
            left = sub.min(above + 1).min(left + 1);
            cur.push(left);
        }
        prev = cur;
    }
    prev.last().copied().unwrap_or_default()
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    #[test]
    fn untrusted_text_is_escaped_and_shortened() {
        assert_eq!(sanitize("Relu"), "Relu");
        assert_eq!(
            sanitize("\u{1b}[2J\nverdict: VERIFIED"),
            "\\u{1b}[2J\\u{a}verdict: VERIFIED"
        );
        assert_eq!(sanitize("a\u{202e}b"), "a\\u{202e}b");
        let long = "x".repeat(500);
        assert_eq!(sanitize(&long).chars().count(), 81);
        assert!(!sanitize("\u{7f}\u{9b}").chars().any(char::is_control));
    }

    #[test]
    fn rendering_is_bounded() {
        let long = format!("A = [{}]", vec!["1"; 5000].join(", "));
        let d = Diagnostic::new(Code::Shape, Span::new(4, 10), "bad").label("here");
        let many = vec![d; 120];
        let out = render(&many, "s.ravel", &long, 100, false);
        assert!(out.len() < 20_000, "{} bytes", out.len());
        assert!(out.contains("… and 70 more diagnostics"));
        assert!(out.contains("at s.ravel:1:5: here"));
    }

    #[test]
    fn numbers_are_compact() {
        assert_eq!(compact(0.5), "0.5");
        assert_eq!(compact(1e300), "1e300");
        assert_eq!(compact(-2.5e-300), "-2.5e-300");
        assert_eq!(compact(1.0 / 3.0), "0.333333");
        assert_eq!(compact(1.0 / 3.0e9), "3.33333e-10");
        assert!(compact(f64::MAX).len() <= 14);
    }

    #[test]
    fn suggestions() {
        assert_eq!(
            did_you_mean("reach_lq", ["reach_lp", "ibp_separate"]),
            Some("reach_lp")
        );
        assert_eq!(did_you_mean("zzz", ["reach_lp"]), None);
        assert_eq!(did_you_mean("a", ["A", "B"]), Some("A"));
    }
}
