//! Text made safe to show: untrusted names escaped and cut, numbers written compactly.

/// Untrusted text (an ONNX op type, tensor or node name, a file path)
/// made safe to show: control characters, bidirectional overrides and other
/// invisible format characters are written as `\u{…}` escapes, and text
/// longer than 80 characters is cut in the middle with `…`.
pub fn sanitize(s: &str) -> String {
    sanitize_to(s, 80)
}

/// [`sanitize`], cutting text longer than `keep` characters.
pub fn sanitize_to(s: &str, keep: usize) -> String {
    let escaped: Vec<String> = s
        .chars()
        .map(|c| {
            let invisible = c.is_control()
                || matches!(c, '\u{200b}'..='\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}' | '\u{feff}');
            if invisible {
                format!("\\u{{{:x}}}", c as u32)
            } else {
                c.to_string()
            }
        })
        .collect();
    if escaped.len() <= keep {
        escaped.concat()
    } else {
        let head = escaped[..keep / 2].concat();
        let tail = escaped[escaped.len() - keep / 2..].concat();
        format!("{head}…{tail}")
    }
}

/// A number written compactly for a message: at most about a dozen
/// characters whatever its magnitude (`1e300`, not 301 digits).
pub fn compact(x: f64) -> String {
    let plain = format!("{x}");
    if plain.len() <= 12 {
        plain
    } else if (1e-4..1e7).contains(&x.abs()) {
        let f = format!("{x:.6}");
        f.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        let e = format!("{x:e}");
        // shorten the mantissa to 6 significant digits
        match e.split_once('e') {
            Some((m, exp)) if m.len() > 8 => {
                let m: f64 = m.parse().unwrap_or(0.0);
                format!(
                    "{}e{exp}",
                    format!("{m:.5}")
                        .trim_end_matches('0')
                        .trim_end_matches('.')
                )
            }
            _ => e,
        }
    }
}
