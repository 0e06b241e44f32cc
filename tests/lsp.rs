//! `ravel lsp` driven over JSON-RPC as an editor drives it: the built
//! binary, its standard input and output, `Content-Length` frames. A whole
//! session (diagnostics as the text changes, formatting, hover, definition,
//! completion, shutdown and exit), then hostile input: every bad request
//! answered with an error, never a crash or a hang.

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{self, Receiver};
use std::time::Duration;

use serde_json::{json, Value};

/// A server and the messages it wrote, in order.
struct Lsp {
    child: Child,
    stdin: Option<ChildStdin>,
    rx: Receiver<Value>,
    /// Notifications received while waiting for something else.
    pending: Vec<Value>,
    next_id: i64,
}

/// A message of the server, or `None` once its output ends.
fn read_frame(r: &mut impl BufRead) -> Option<Value> {
    let mut length = None;
    loop {
        let mut line = String::new();
        if r.read_line(&mut line).ok()? == 0 {
            return None;
        }
        let line = line.trim_end();
        if line.is_empty() {
            break;
        }
        let (name, value) = line.split_once(':').expect("a header");
        if name.eq_ignore_ascii_case("content-length") {
            length = Some(value.trim().parse::<usize>().expect("a length"));
        }
    }
    let mut body = vec![0; length.expect("Content-Length")];
    r.read_exact(&mut body).ok()?;
    Some(serde_json::from_slice(&body).expect("the server writes JSON"))
}

/// Longest wait for one message: only a server that hangs reaches it.
const PATIENCE: Duration = Duration::from_secs(120);

impl Lsp {
    fn start() -> Lsp {
        let mut child = Command::new(env!("CARGO_BIN_EXE_ravel"))
            .arg("lsp")
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("the binary runs");
        let stdout = child.stdout.take().expect("stdout");
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let mut r = BufReader::new(stdout);
            while let Some(v) = read_frame(&mut r) {
                if tx.send(v).is_err() {
                    break;
                }
            }
        });
        Lsp {
            stdin: child.stdin.take(),
            child,
            rx,
            pending: Vec::new(),
            next_id: 1,
        }
    }

    fn send_raw(&mut self, bytes: &[u8]) {
        let w = self.stdin.as_mut().expect("stdin open");
        w.write_all(bytes).expect("the server reads");
        w.flush().expect("flush");
    }

    fn send(&mut self, v: &Value) {
        let body = v.to_string();
        let mut frame = format!("Content-Length: {}\r\n\r\n", body.len()).into_bytes();
        frame.extend_from_slice(body.as_bytes());
        self.send_raw(&frame);
    }

    fn notify(&mut self, method: &str, params: Value) {
        self.send(&json!({ "jsonrpc": "2.0", "method": method, "params": params }));
    }

    fn next(&mut self) -> Value {
        self.rx
            .recv_timeout(PATIENCE)
            .expect("the server answers (and has not hung or died)")
    }

    /// The response to a request; notifications on the way are kept.
    fn request(&mut self, method: &str, params: Value) -> Value {
        let id = self.next_id;
        self.next_id += 1;
        self.send(&json!({ "jsonrpc": "2.0", "id": id, "method": method, "params": params }));
        self.response(json!(id))
    }

    fn response(&mut self, id: Value) -> Value {
        loop {
            let m = self.next();
            if m.get("method").is_some() {
                self.pending.push(m);
            } else {
                assert_eq!(m["jsonrpc"], "2.0", "{m}");
                assert_eq!(m["id"], id, "responses come in order: {m}");
                return m;
            }
        }
    }

    /// The diagnostics published for `uri` at `version`.
    fn diagnostics(&mut self, uri: &str, version: i64) -> Vec<Value> {
        loop {
            let m = match self.pending.iter().position(|m| {
                m["method"] == "textDocument/publishDiagnostics"
                    && m["params"]["uri"] == uri
                    && m["params"]["version"] == version
            }) {
                Some(i) => self.pending.remove(i),
                None => {
                    let m = self.next();
                    self.pending.push(m);
                    continue;
                }
            };
            return m["params"]["diagnostics"]
                .as_array()
                .expect("a list")
                .clone();
        }
    }

    fn initialize(&mut self) -> Value {
        let r = self.request(
            "initialize",
            json!({ "capabilities": {}, "processId": null }),
        );
        self.notify("initialized", json!({}));
        r
    }

    /// `shutdown`, `exit`, and the exit code.
    fn finish(mut self) -> i32 {
        let r = self.request("shutdown", Value::Null);
        assert!(r.get("error").is_none(), "{r}");
        assert_eq!(r["result"], Value::Null);
        self.notify("exit", Value::Null);
        self.wait()
    }

    fn wait(mut self) -> i32 {
        drop(self.stdin.take());
        self.child.wait().expect("exits").code().unwrap_or(-1)
    }
}

/// A `file:` URI for a (possibly not existing) file in the repository.
fn uri(rel: &str) -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(rel);
    let mut s = String::from("file://");
    for b in path.to_string_lossy().bytes() {
        if b.is_ascii_alphanumeric() || b"/-._~".contains(&b) {
            s.push(b as char);
        } else {
            s.push_str(&format!("%{b:02X}"));
        }
    }
    s
}

fn spec() -> String {
    std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/specs/double_integrator.ravel"
    ))
    .expect("the shipped spec")
}

/// The LSP position (line, UTF-16 column) of byte `offset` of `text`.
fn position(text: &str, offset: usize) -> Value {
    let before = &text[..offset];
    let line = before.matches('\n').count();
    let col: usize = before
        .rsplit('\n')
        .next()
        .unwrap_or("")
        .encode_utf16()
        .count();
    json!({ "line": line, "character": col })
}

fn doc_pos(uri: &str, text: &str, offset: usize) -> Value {
    json!({ "textDocument": { "uri": uri }, "position": position(text, offset) })
}

#[test]
fn a_session_edits_checks_formats_and_navigates_a_spec() {
    let mut lsp = Lsp::start();
    let init = lsp.initialize();
    let caps = &init["result"]["capabilities"];
    assert_eq!(caps["textDocumentSync"]["change"], 1, "full sync: {init}");
    for c in [
        "hoverProvider",
        "definitionProvider",
        "documentFormattingProvider",
    ] {
        assert_eq!(caps[c], true, "{c}: {init}");
    }
    assert!(caps["completionProvider"].is_object(), "{init}");

    // a spec beside the shipped ones, so its controller is found relative to it
    let uri = uri("specs/editing.ravel");
    let good = spec();
    // a misspelt keyword after a comment with characters outside the BMP:
    // the range is in UTF-16 units
    let bad = good.replace("horizon 5", "/* ∆𝄞 */ horizn 5");
    lsp.notify(
        "textDocument/didOpen",
        json!({ "textDocument": { "uri": uri, "languageId": "ravel", "version": 1, "text": bad } }),
    );
    let d = lsp.diagnostics(&uri, 1);
    assert_eq!(d.len(), 1, "{d:?}");
    assert_eq!(d[0]["code"], "E0001");
    assert_eq!(d[0]["severity"], 1);
    assert_eq!(d[0]["source"], "ravel");
    let at = bad.find("horizn").expect("there");
    assert_eq!(d[0]["range"]["start"], position(&bad, at), "{d:?}");
    // `/* ∆𝄞 */ ` is 10 UTF-16 units (𝄞 takes two), though 14 bytes
    assert_eq!(d[0]["range"]["start"]["character"], 10);
    let msg = d[0]["message"].as_str().expect("text");
    assert!(
        msg.contains("horizn") && msg.contains("did you mean `horizon`"),
        "{msg}"
    );

    // fixed: the next publication, for version 2, is empty
    lsp.notify(
        "textDocument/didChange",
        json!({ "textDocument": { "uri": uri, "version": 2 }, "contentChanges": [{ "text": good }] }),
    );
    assert_eq!(lsp.diagnostics(&uri, 2), Vec::<Value>::new());

    // a check error (not a parse error) with its hint and related location
    let dup = good.replace("goal    G ", "goal    X0");
    lsp.notify(
        "textDocument/didChange",
        json!({ "textDocument": { "uri": uri, "version": 3 }, "contentChanges": [{ "text": dup }] }),
    );
    let d = lsp.diagnostics(&uri, 3);
    assert_eq!(d.len(), 1, "{d:?}");
    assert_eq!(d[0]["code"], "E0102", "{d:?}");
    assert_eq!(
        d[0]["range"]["start"],
        position(&dup, dup.find("goal    X0").expect("there") + 8),
        "{d:?}"
    );
    assert_eq!(
        d[0]["relatedInformation"][0]["location"]["range"]["start"],
        position(&dup, dup.find("X0").expect("there")),
        "{d:?}"
    );

    // formatting a messy text gives the canonical one (the shipped spec is canonical)
    let messy = good
        .replace("state   x[2]", "state x [ 2 ]")
        .replace("horizon 5", "horizon    5");
    lsp.notify(
        "textDocument/didChange",
        json!({ "textDocument": { "uri": uri, "version": 4 }, "contentChanges": [{ "text": messy }] }),
    );
    assert_eq!(lsp.diagnostics(&uri, 4), Vec::<Value>::new());
    let r = lsp.request(
        "textDocument/formatting",
        json!({ "textDocument": { "uri": uri }, "options": { "tabSize": 4, "insertSpaces": true } }),
    );
    let edits = r["result"].as_array().expect("edits");
    assert_eq!(edits.len(), 1, "{r}");
    assert_eq!(
        edits[0]["range"]["start"],
        json!({ "line": 0, "character": 0 })
    );
    assert_eq!(edits[0]["range"]["end"], position(&messy, messy.len()));
    let canonical = ravel_syntax::fmt::format(&messy).expect("formats");
    assert_ne!(canonical, messy);
    assert_eq!(edits[0]["newText"], canonical);
    // a canonical text needs no edit; one that does not parse gets none
    lsp.notify(
        "textDocument/didChange",
        json!({ "textDocument": { "uri": uri, "version": 5 }, "contentChanges": [{ "text": good }] }),
    );
    let r = lsp.request("textDocument/formatting", json!({ "textDocument": { "uri": uri }, "options": { "tabSize": 4, "insertSpaces": true } }));
    assert_eq!(r["result"], json!([]), "{r}");

    // hover: vectors with their sizes, matrices with their shapes, sets, keywords
    let text = good.clone();
    let hover = |lsp: &mut Lsp, needle: &str, into: usize| -> String {
        let at = text.find(needle).unwrap_or_else(|| panic!("{needle}")) + into;
        let r = lsp.request("textDocument/hover", doc_pos(&uri, &text, at));
        r["result"]["contents"]["value"]
            .as_str()
            .unwrap_or("")
            .to_string()
    };
    let h = hover(&mut lsp, "x[2]", 0);
    assert!(h.contains("state vector, 2 components"), "{h}");
    let h = hover(&mut lsp, "u[1]", 0);
    assert!(h.contains("control vector, 1 component"), "{h}");
    let h = hover(&mut lsp, "A = ", 0);
    assert!(h.contains("2 × 2 matrix"), "{h}");
    let h = hover(&mut lsp, "B = ", 0);
    assert!(h.contains("2 × 1 matrix"), "{h}");
    let h = hover(&mut lsp, "X0 =", 1);
    assert!(
        h.contains("initial set: box (2 bounded components), over `x` ∈ ℝ²"),
        "{h}"
    );
    let h = hover(&mut lsp, "overshoot", 0);
    assert!(
        h.contains("avoid set: polytope of 1 constraints") && h.contains("steps 1 … 5"),
        "{h}"
    );
    let h = hover(&mut lsp, "reach_lp", 2);
    assert!(h.contains("propagator: Reach-LP"), "{h}");
    let h = hover(&mut lsp, "horizon", 0);
    assert!(h.contains("keyword: `horizon N`"), "{h}");
    let at = text.find("horizon").expect("there");
    let r = lsp.request("textDocument/hover", doc_pos(&uri, &text, at));
    assert_eq!(r["result"]["range"]["start"], position(&text, at));
    // nothing to show on a number
    let at = text.find("2.5").expect("there");
    let r = lsp.request("textDocument/hover", doc_pos(&uri, &text, at));
    assert_eq!(r["result"], Value::Null, "{r}");

    // definition: from `x[1]` in the initial set to `state x[2]`
    let use_at = text.find("x[1] in").expect("there");
    let r = lsp.request("textDocument/definition", doc_pos(&uri, &text, use_at));
    let decl = text.find("x[2]").expect("there");
    assert_eq!(r["result"]["uri"], uri, "{r}");
    assert_eq!(r["result"]["range"]["start"], position(&text, decl), "{r}");
    assert_eq!(
        r["result"]["range"]["end"],
        position(&text, decl + 1),
        "{r}"
    );
    let r = lsp.request(
        "textDocument/definition",
        doc_pos(&uri, &text, text.find("horizon").expect("there")),
    );
    assert_eq!(r["result"], Value::Null, "{r}");

    // completion: propagators after `propagator`, partitioners after
    // `partitioner`, keywords and names elsewhere
    let labels = |r: &Value| -> Vec<String> {
        r["result"]
            .as_array()
            .expect("items")
            .iter()
            .map(|i| i["label"].as_str().expect("label").to_string())
            .collect()
    };
    let at = text.find("reach_lp").expect("there") + 3;
    let r = lsp.request("textDocument/completion", doc_pos(&uri, &text, at));
    let l = labels(&r);
    for p in [
        "reach_lp",
        "reach_sdp",
        "crown_unrolled",
        "crown_separate",
        "ibp_separate",
        "sg_ibp_separate",
    ] {
        assert!(l.contains(&p.to_string()), "{p}: {l:?}");
    }
    assert!(!l.contains(&"horizon".to_string()), "{l:?}");
    let at = text.find("partitioner none").expect("there") + 12;
    let r = lsp.request("textDocument/completion", doc_pos(&uri, &text, at));
    assert_eq!(
        labels(&r),
        ["none", "uniform", "sg", "gsg", "property", "bab"]
    );
    let at = text.find("horizon").expect("there");
    let r = lsp.request("textDocument/completion", doc_pos(&uri, &text, at));
    let l = labels(&r);
    for w in [
        "horizon",
        "initial",
        "goal",
        "avoid",
        "analysis",
        "X0",
        "overshoot",
        "x",
        "u",
        "A",
    ] {
        assert!(l.contains(&w.to_string()), "{w}: {l:?}");
    }
    let item = r["result"]
        .as_array()
        .expect("items")
        .iter()
        .find(|i| i["label"] == "horizon")
        .expect("horizon")
        .clone();
    assert_eq!(item["kind"], 14, "a keyword: {item}");

    // closing a document clears its diagnostics
    lsp.notify(
        "textDocument/didClose",
        json!({ "textDocument": { "uri": uri } }),
    );
    let r = lsp.request("textDocument/hover", doc_pos(&uri, &text, 0));
    assert_eq!(r["error"]["code"], -32602, "{r}");
    assert!(lsp
        .pending
        .iter()
        .any(|m| m["method"] == "textDocument/publishDiagnostics"
            && m["params"]["uri"] == uri
            && m["params"]["diagnostics"] == json!([])));

    assert_eq!(lsp.finish(), 0);
}

#[test]
fn the_controller_is_read_relative_to_the_document() {
    let mut lsp = Lsp::start();
    lsp.initialize();
    // the same text one folder higher: `../models/…` is then missing
    let elsewhere = uri("editing.ravel");
    lsp.notify(
        "textDocument/didOpen",
        json!({ "textDocument": { "uri": elsewhere, "languageId": "ravel", "version": 7, "text": spec() } }),
    );
    let d = lsp.diagnostics(&elsewhere, 7);
    assert_eq!(d.len(), 1, "{d:?}");
    assert_eq!(d[0]["code"], "E0301", "{d:?}");
    // an unsaved document has no folder: its controller cannot be read
    let untitled = "untitled:Untitled-1";
    lsp.notify(
        "textDocument/didOpen",
        json!({ "textDocument": { "uri": untitled, "languageId": "ravel", "version": 1, "text": spec() } }),
    );
    let d = lsp.diagnostics(untitled, 1);
    assert_eq!(d[0]["code"], "E0301", "{d:?}");
    assert!(
        d[0]["message"]
            .as_str()
            .expect("text")
            .contains("not a file on disk"),
        "{d:?}"
    );
    assert_eq!(lsp.finish(), 0);
}

#[test]
fn hostile_requests_get_errors_and_the_server_goes_on() {
    let mut lsp = Lsp::start();
    // before initialize: not initialized
    let r = lsp.request("textDocument/hover", json!({}));
    assert_eq!(r["error"]["code"], -32002, "{r}");
    lsp.initialize();
    let r = lsp.request("initialize", json!({ "capabilities": {} }));
    assert_eq!(r["error"]["code"], -32600, "{r}");
    let r = lsp.request("no/such/method", json!({}));
    assert_eq!(r["error"]["code"], -32601, "{r}");
    let r = lsp.request("textDocument/hover", json!({ "textDocument": 5 }));
    assert_eq!(r["error"]["code"], -32602, "{r}");
    let uri = uri("specs/hostile.ravel");
    let r = lsp.request("textDocument/hover", doc_pos(&uri, "", 0));
    assert_eq!(r["error"]["code"], -32602, "not open: {r}");
    let text = "// x𝄞y\nhorizon 5\n";
    lsp.notify(
        "textDocument/didOpen",
        json!({ "textDocument": { "uri": uri, "languageId": "ravel", "version": 1, "text": text } }),
    );
    let first = lsp.diagnostics(&uri, 1);
    // a line past the end; a column between the halves of 𝄞
    for pos in [
        json!({ "line": 99, "character": 0 }),
        json!({ "line": 0, "character": 5 }),
    ] {
        for method in [
            "textDocument/hover",
            "textDocument/definition",
            "textDocument/completion",
        ] {
            let r = lsp.request(
                method,
                json!({ "textDocument": { "uri": uri }, "position": pos }),
            );
            assert_eq!(r["error"]["code"], -32602, "{method} {pos}: {r}");
        }
    }
    // a column past the end of its line is the line's end (as the protocol says)
    let r = lsp.request(
        "textDocument/hover",
        json!({ "textDocument": { "uri": uri }, "position": { "line": 1, "character": 4_000_000_000u32 } }),
    );
    assert!(r.get("error").is_none(), "{r}");
    // not JSON; JSON but not a message; an id JSON-RPC allows but the server cannot echo as an integer of 32 bits
    lsp.send_raw(b"Content-Length: 9\r\n\r\n{not json");
    let r = lsp.next();
    assert_eq!(r["error"]["code"], -32700, "{r}");
    assert_eq!(r["id"], Value::Null, "{r}");
    // bytes that are not UTF-8 inside a string
    lsp.send_raw(b"Content-Length: 14\r\n\r\n{\"method\":\"\xff\"}");
    let r = lsp.next();
    assert_eq!(r["error"]["code"], -32700, "{r}");
    lsp.send(&json!([1, 2, 3]));
    let r = lsp.next();
    assert_eq!(r["error"]["code"], -32600, "{r}");
    lsp.send(&json!({ "jsonrpc": "2.0", "id": 1e300, "method": "shutdown" }));
    let r = lsp.next();
    assert_eq!(r["error"]["code"], -32600, "{r}");
    assert_eq!(r["id"], json!(1e300), "{r}");
    // deeply nested JSON
    let deep = format!("{}{}", "[".repeat(100_000), "]".repeat(100_000));
    lsp.send_raw(format!("Content-Length: {}\r\n\r\n{deep}", deep.len()).as_bytes());
    let r = lsp.next();
    assert_eq!(r["error"]["code"], -32700, "{r}");
    // a ranged change outside the document is not applied (and logged)
    lsp.notify(
        "textDocument/didChange",
        json!({ "textDocument": { "uri": uri, "version": 2 }, "contentChanges": [
            { "range": { "start": { "line": 50, "character": 0 }, "end": { "line": 51, "character": 0 } }, "text": "x" }
        ] }),
    );
    assert_eq!(lsp.diagnostics(&uri, 2), first);
    assert!(lsp
        .pending
        .iter()
        .any(|m| m["method"] == "window/logMessage"));
    // a ranged change inside it is
    lsp.notify(
        "textDocument/didChange",
        json!({ "textDocument": { "uri": uri, "version": 3 }, "contentChanges": [
            { "range": { "start": { "line": 1, "character": 0 }, "end": { "line": 1, "character": 7 } }, "text": "horizn" }
        ] }),
    );
    let d = lsp.diagnostics(&uri, 3);
    assert_eq!(d[0]["code"], "E0001", "{d:?}");
    // a document larger than a spec may be: one diagnostic, nothing parsed
    let huge = "/".repeat(17 << 20);
    lsp.notify(
        "textDocument/didChange",
        json!({ "textDocument": { "uri": uri, "version": 4 }, "contentChanges": [{ "text": huge }] }),
    );
    let d = lsp.diagnostics(&uri, 4);
    assert_eq!(d.len(), 1, "{d:?}");
    assert_eq!(d[0]["code"], "E0216", "{d:?}");
    let r = lsp.request("textDocument/formatting", json!({ "textDocument": { "uri": uri }, "options": { "tabSize": 4, "insertSpaces": true } }));
    assert_eq!(r["result"], json!([]), "{r}");
    // still serving
    assert_eq!(lsp.finish(), 0);
}

#[test]
fn broken_framing_ends_the_server_with_an_error_not_a_hang() {
    // a length past the limit: answered, and the server stops without
    // reading (or allocating) the announced body
    let mut lsp = Lsp::start();
    lsp.initialize();
    lsp.send_raw(b"Content-Length: 99999999999999\r\n\r\n{}");
    let r = lsp.next();
    assert_eq!(r["error"]["code"], -32700, "{r}");
    assert!(
        r["error"]["message"]
            .as_str()
            .expect("text")
            .contains("limit"),
        "{r}"
    );
    assert_eq!(lsp.wait(), 1);
    // no Content-Length
    let mut lsp = Lsp::start();
    lsp.send_raw(b"Content-Type: x\r\n\r\n{}");
    assert_eq!(lsp.next()["error"]["code"], -32700);
    assert_eq!(lsp.wait(), 1);
    // exit without shutdown: exit code 1, as the protocol says
    let mut lsp = Lsp::start();
    lsp.initialize();
    lsp.notify("exit", Value::Null);
    assert_eq!(lsp.wait(), 1);
    // the input ends after shutdown: 0
    let mut lsp = Lsp::start();
    lsp.initialize();
    let r = lsp.request("shutdown", Value::Null);
    assert_eq!(r["result"], Value::Null);
    let r = lsp.request("textDocument/hover", json!({}));
    assert_eq!(r["error"]["code"], -32600, "after shutdown: {r}");
    assert_eq!(lsp.wait(), 0);
}
