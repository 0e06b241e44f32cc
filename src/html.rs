//! `ravel verify … --report DIR`: DIR/index.html, one self-contained page
//! for a CI artifact: a summary table (one row per (spec, controller)
//! pair: its verdict, every property's verdict and margin, key numbers,
//! time) and each pair's plot as inline SVG. Nothing is loaded from
//! elsewhere, and the page is well-formed XML as well as HTML (tests read
//! it with an XML parser); a short inline script marks the page once every plot has a
//! non-empty box (`data-rendered` on `<body>`), which the headless-browser
//! check of `scripts/test-report.sh` reads.

/// One pair's row and plot.
pub struct Entry {
    /// The pair's index in the batch (0-based).
    pub index: usize,
    /// The spec as given (or the argument that named nothing).
    pub spec: String,
    /// The controller given with `--controller`, if any.
    pub controller: Option<String>,
    /// `VERIFIED`, `FALSIFIED`, `UNSURE` or `ERROR`.
    pub verdict: String,
    /// Per property: what (`goal reach`), its verdict, where and by how much.
    pub properties: Vec<(String, String, String)>,
    /// Key numbers of the run (cells, propagator calls, samples).
    pub key: String,
    /// Analysis time (absent with `--no-timing`).
    pub time_ms: Option<f64>,
    /// The plot, or why there is none.
    pub plot: Option<Result<String, String>>,
    /// What went wrong, for an ERROR.
    pub error: Option<String>,
}

/// Text made safe for XML and HTML, the report's page and JUnit documents
/// alike: the five special characters escaped and control characters (not
/// allowed in XML 1.0) written as `\u{…}`.
pub fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&apos;"),
            '\n' | '\t' => o.push(c),
            c if c.is_control() => o.push_str(&format!("\\u{{{:x}}}", c as u32)),
            c => o.push(c),
        }
    }
    o
}

const STYLE: &str = "body{font-family:sans-serif;margin:1.5em;color:#212121}\
table{border-collapse:collapse;margin:1em 0}\
th,td{border:1px solid #bdbdbd;padding:.3em .6em;text-align:left;vertical-align:top}\
th{background:#eeeeee}\
td.num{text-align:right;font-variant-numeric:tabular-nums}\
.VERIFIED{color:#1b5e20;font-weight:bold}.FALSIFIED{color:#b71c1c;font-weight:bold}\
.UNSURE{color:#e65100;font-weight:bold}.ERROR{color:#6a1b9a;font-weight:bold}\
ul{margin:0;padding-left:1.1em}\
section.pair{margin-top:2em;border-top:1px solid #bdbdbd}\
figure{margin:.5em 0}figure svg{max-width:100%;height:auto}\
pre{white-space:pre-wrap}";

/// The script that marks the page rendered: every plot must have a
/// non-empty box in the layout and in its own drawing.
const CHECK: &str = "(function(){var s=document.querySelectorAll('figure svg'),ok=0;\
for(var i=0;i<s.length;i++){var r=s[i].getBoundingClientRect(),b=s[i].getBBox();\
if(r.width>0&&r.height>0&&b.width>0&&b.height>0)ok++;}\
document.body.setAttribute('data-rendered',(ok===s.length?'ok ':'failed ')+ok+'/'+s.length);})();";

/// The page of a batch.
pub fn page(entries: &[Entry], summary: &str) -> String {
    let mut s = String::new();
    s += "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\"/>\n<title>ravel report</title>\n";
    s += &format!("<style>{STYLE}</style>\n</head>\n");
    s += &format!(
        "<body data-pairs=\"{}\">\n<h1>ravel verification report</h1>\n<p>ravel {}: {} pair{}: {}</p>\n",
        entries.len(),
        env!("CARGO_PKG_VERSION"),
        entries.len(),
        if entries.len() == 1 { "" } else { "s" },
        esc(summary)
    );
    let timed = entries.iter().any(|e| e.time_ms.is_some());
    s += "<table id=\"summary\">\n<thead><tr><th>#</th><th>spec</th><th>controller</th><th>verdict</th><th>properties</th><th>key numbers</th>";
    if timed {
        s += "<th>time</th>";
    }
    s += "<th>plot</th></tr></thead>\n<tbody>\n";
    for e in entries {
        let n = e.index + 1;
        s += &format!(
            "<tr class=\"pair\" id=\"row-{n}\"><td class=\"num\">{n}</td><td>{}</td><td>{}</td><td class=\"{v}\">{v}</td><td>",
            esc(&e.spec),
            esc(e.controller.as_deref().unwrap_or("(the spec's own)")),
            v = esc(&e.verdict)
        );
        if let Some(err) = &e.error {
            s += &format!("<pre>{}</pre>", esc(err));
        } else if e.properties.is_empty() {
            s += "—";
        } else {
            s += "<ul>";
            for (what, verdict, detail) in &e.properties {
                s += &format!(
                    "<li>{}: <span class=\"{v}\">{v}</span> {}</li>",
                    esc(what),
                    esc(detail),
                    v = esc(verdict)
                );
            }
            s += "</ul>";
        }
        s += &format!("</td><td>{}</td>", esc(&e.key));
        if timed {
            match e.time_ms {
                Some(ms) => s += &format!("<td class=\"num\">{:.2} s</td>", ms / 1e3),
                None => s += "<td></td>",
            }
        }
        match &e.plot {
            Some(Ok(_)) => s += &format!("<td><a href=\"#pair-{n}\">plot</a></td></tr>\n"),
            _ => s += "<td>—</td></tr>\n",
        }
    }
    s += "</tbody>\n</table>\n";
    for e in entries {
        let n = e.index + 1;
        let Some(plot) = &e.plot else { continue };
        s += &format!(
            "<section class=\"pair\" id=\"pair-{n}\">\n<h2>{n}. {}{}: <span class=\"{v}\">{v}</span></h2>\n",
            esc(&e.spec),
            e.controller
                .as_deref()
                .map(|c| format!(" with {}", esc(c)))
                .unwrap_or_default(),
            v = esc(&e.verdict)
        );
        match plot {
            Ok(svg) => s += &format!("<figure>\n{}</figure>\n", svg.trim_start()),
            Err(why) => s += &format!("<p>No plot: {}</p>\n", esc(why)),
        }
        s += "</section>\n";
    }
    // the script inside a commented CDATA section: the page is HTML and
    // well-formed XML alike
    s += &format!("<script>//<![CDATA[\n{CHECK}\n//]]></script>\n</body>\n</html>\n");
    s
}

#[cfg(test)]
mod tests {
    #[test]
    fn esc_escapes_markup_and_control_characters() {
        assert_eq!(
            super::esc("a<b>&\"c'\u{1b}[2J\n\td"),
            "a&lt;b&gt;&amp;&quot;c&apos;\\u{1b}[2J\n\td"
        );
        assert_eq!(super::esc("x[0] ∈ ℝ²"), "x[0] ∈ ℝ²");
    }
}
