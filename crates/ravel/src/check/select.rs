//! `select` blocks: robust action selection (CARRL) for a Q-network — the
//! ε-ball (radius per input, norm) and the observations, inline or from a
//! CSV file the caller read.

use super::{Ctx, DataFiles, SelectSpec, MAX_OBSERVATIONS};
use ravel_analysis::sets::Norm;
use ravel_base::limits::{MAX_MAGNITUDE, MAX_SPEC_NUMBERS};
use ravel_syntax::ast::*;
use ravel_syntax::diag::{compact, sanitize, Code, Diagnostic};

fn bad(cx: &mut Ctx, span: Span, message: String, label: &str, hint: &str) {
    cx.err(
        Diagnostic::new(Code::Observations, span, message)
            .label(label.to_string())
            .hint(hint.to_string()),
    );
}

/// Observations from CSV text: one row per line, comma-separated numbers; a
/// first line without any number is a header; blank lines are skipped.
fn csv(cx: &mut Ctx, text: &str, span: Span, n: usize, file: &str) -> Option<Vec<Vec<f64>>> {
    let mut rows = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        let parsed: Vec<Option<f64>> = cells.iter().map(|c| c.parse::<f64>().ok()).collect();
        if k == 0 && parsed.iter().all(Option::is_none) {
            continue; // a header
        }
        if let Some(col) = parsed.iter().position(Option::is_none) {
            bad(
                cx,
                span,
                format!(
                    "{file}, line {}: cell {} is not a number (`{}`)",
                    k + 1,
                    col + 1,
                    sanitize(cells.get(col).copied().unwrap_or_default())
                ),
                "in this file",
                "every cell of an observation row must be a number; only the first line may be a header",
            );
            return None;
        }
        if cells.len() != n {
            bad(
                cx,
                span,
                format!(
                    "{file}, line {}: {} values, but the network has {n} inputs",
                    k + 1,
                    cells.len()
                ),
                "in this file",
                "every row holds one observation: one value per network input",
            );
            return None;
        }
        let row: Vec<f64> = parsed.into_iter().flatten().collect();
        if let Some(v) = row
            .iter()
            .find(|v| !(v.is_finite() && v.abs() <= MAX_MAGNITUDE))
        {
            bad(
                cx,
                span,
                format!(
                    "{file}, line {}: {} is not a finite number within ±1e15",
                    k + 1,
                    compact(*v)
                ),
                "in this file",
                "observations must be finite and within ±1e15",
            );
            return None;
        }
        rows.push(row);
        if rows.len() > MAX_OBSERVATIONS || rows.len() as u64 * n as u64 > MAX_SPEC_NUMBERS {
            bad(
                cx,
                span,
                format!("{file} holds more than {MAX_OBSERVATIONS} observations (or {MAX_SPEC_NUMBERS} numbers)"),
                "too many observations",
                "split the observations over several files and specs",
            );
            return None;
        }
    }
    Some(rows)
}

/// Check one select block over a network with `n` inputs and `m` outputs.
pub(super) fn select(
    cx: &mut Ctx,
    d: &SelectDef,
    xn: &str,
    n: usize,
    m: usize,
    data: &DataFiles,
) -> Option<SelectSpec> {
    let mut epsilon: Option<Vec<f64>> = None;
    let mut norm = Norm::LInf;
    let mut observations: Option<Vec<Vec<f64>>> = None;
    let mut seen: Vec<(&str, Span)> = Vec::new();
    let mut ok = true;
    if m < 2 {
        bad(
            cx,
            d.name.span,
            format!(
                "selecting an action needs a Q-network with one output per action, but it has {m}"
            ),
            "one output",
            "a Q-network has one output per discrete action",
        );
        ok = false;
    }
    for st in &d.stmts {
        let key = match &st.node {
            SelectStmt::Epsilon(_) => "epsilon",
            SelectStmt::Norm(_) => "norm",
            SelectStmt::Inline(_) | SelectStmt::File(_) => "observations",
        };
        if let Some((_, first)) = seen.iter().find(|(k, _)| *k == key) {
            cx.duplicate(&format!("`{key}`"), *first, st.span);
            ok = false;
            continue;
        }
        seen.push((key, st.span));
        match &st.node {
            SelectStmt::Epsilon(v) => {
                epsilon = ball_radii(cx, v, xn, n);
                ok &= epsilon.is_some();
            }
            SelectStmt::Norm(p) => {
                norm = match p.node.as_str() {
                    "1" => Norm::L1,
                    "2" => Norm::L2,
                    _ => Norm::LInf,
                }
            }
            SelectStmt::Inline(v) => {
                let (rows, all_rows_ok) = inline(cx, v, xn, n);
                observations = rows;
                ok &= all_rows_ok;
            }
            SelectStmt::File(p) => {
                observations = from_file(cx, p, n, data);
                ok &= observations.is_some();
            }
        }
    }
    if epsilon.is_none() && !seen.iter().any(|(k, _)| *k == "epsilon") {
        bad(
            cx,
            d.span,
            "the select block has no ε".into(),
            "no `epsilon`",
            "add `epsilon r` or `epsilon [r, …]`: the radius of the ball around each observation",
        );
        ok = false;
    }
    if observations.is_none() && !seen.iter().any(|(k, _)| *k == "observations") {
        bad(
            cx,
            d.span,
            "the select block has no observations".into(),
            "no `observations`",
            "add `observations [[…], …]` or `observations \"file.csv\"`",
        );
        ok = false;
    }
    if !ok {
        return None;
    }
    Some(SelectSpec {
        name: d.name.node.clone(),
        epsilon: epsilon?,
        norm,
        observations: observations?,
    })
}

/// `epsilon r` or `epsilon [r, …]`: the ball's radius per input (`None`
/// after an error).
fn ball_radii(cx: &mut Ctx, v: &Spanned<Value>, xn: &str, n: usize) -> Option<Vec<f64>> {
    let values: Vec<f64> = match &v.node {
        Value::Scalar(r) => {
            let x = cx.finite(&Spanned {
                node: *r,
                span: v.span,
            });
            vec![x; n]
        }
        Value::Vector(rs) => rs.iter().map(|x| cx.finite(x)).collect(),
        _ => Vec::new(),
    };
    if values.len() != n {
        bad(
            cx,
            v.span,
            format!(
                "ε has {} values, but `{xn}` has {n} components",
                values.len()
            ),
            "wrong length",
            "give one ε, or one per input",
        );
        return None;
    }
    if values.iter().any(|e| *e < 0.0) {
        bad(
            cx,
            v.span,
            "ε is negative".into(),
            "negative radius",
            "ε must be ≥ 0 (0: that input is not perturbed)",
        );
        return None;
    }
    Some(values)
}

/// `observations [[…], …]`: the rows of the right width (`None` when there
/// are too many), and whether every row had it.
fn inline(cx: &mut Ctx, v: &Spanned<Value>, xn: &str, n: usize) -> (Option<Vec<Vec<f64>>>, bool) {
    let rows: Vec<&Spanned<Vec<Spanned<f64>>>> = match &v.node {
        Value::Matrix(rows) => rows.iter().collect(),
        _ => Vec::new(),
    };
    if rows.len() > MAX_OBSERVATIONS {
        bad(
            cx,
            v.span,
            format!("more than {MAX_OBSERVATIONS} observations"),
            "too many",
            "put them in a CSV file and split it",
        );
        return (None, false);
    }
    let mut ok = true;
    let mut obs = Vec::new();
    for r in rows {
        if r.node.len() != n {
            bad(
                cx,
                r.span,
                format!(
                    "an observation of {} values, but `{xn}` has {n} components",
                    r.node.len()
                ),
                "wrong width",
                "every row holds one observation: one value per network input",
            );
            ok = false;
            continue;
        }
        obs.push(r.node.iter().map(|x| cx.finite(x)).collect());
    }
    (Some(obs), ok)
}

/// `observations "file.csv"`: the file's rows (`None` after an error).
fn from_file(
    cx: &mut Ctx,
    p: &Spanned<String>,
    n: usize,
    data: &DataFiles,
) -> Option<Vec<Vec<f64>>> {
    match data.get(&p.node) {
        Some(Ok(bytes)) => match std::str::from_utf8(bytes) {
            Ok(text) => csv(cx, text, p.span, n, &sanitize(&p.node)),
            Err(_) => {
                bad(
                    cx,
                    p.span,
                    format!("`{}` is not UTF-8 text", sanitize(&p.node)),
                    "not a CSV file",
                    "observations are comma-separated numbers, one row per line",
                );
                None
            }
        },
        Some(Err(e)) => {
            bad(
                cx,
                p.span,
                format!("cannot read `{}`: {}", sanitize(&p.node), sanitize(e)),
                "this file",
                "observation files are read from the spec file's folder or a folder below it (no `..`, no absolute path, no link leaving it)",
            );
            None
        }
        None => {
            bad(
                cx,
                p.span,
                format!("`{}` was not read", sanitize(&p.node)),
                "not available",
                "the file must be readable next to the spec",
            );
            None
        }
    }
}
