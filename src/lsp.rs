//! `ravel lsp`: a language server over standard input and output (JSON-RPC
//! with the Language Server Protocol's `Content-Length` framing), for any
//! editor with an LSP client.
//!
//! The answers come from `ravel_ide` (pure: text in, spans out); this module
//! holds the protocol: framing (with a size limit, so a hostile length
//! cannot make it allocate without bound), the open documents, UTF-16
//! positions, and the file-system reader the front end uses to read a
//! spec's controller relative to the document's folder (the command line's
//! own [`crate::read_request`]).
//!
//! One thread reads and frames messages; the main thread handles them in
//! order. Diagnostics are published once no message is waiting, so a burst
//! of edits is checked once, at its last version (each publication carries
//! the version it was computed for).

use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, Read, Write};
use std::path::PathBuf;
use std::sync::mpsc;

use lsp_server::{ErrorCode, Message, Notification, Request, Response};
use lsp_types as lt;
use ravel_ide::line_index::{LineIndex, Position};
use serde_json::{json, Value};

/// The largest message read: a spec may have 16 MiB, and JSON may escape
/// each byte of it into several.
pub const MAX_MESSAGE_BYTES: usize = 128 << 20;
/// The longest header line read.
const MAX_HEADER_LINE: usize = 4096;

/// One document the client has opened.
struct Doc {
    text: String,
    version: i32,
    index: LineIndex,
}

/// What the reader thread hands over.
enum Incoming {
    /// A message.
    Message(Message),
    /// A frame whose body is not a JSON-RPC message; `id` when it had one.
    Bad {
        code: ErrorCode,
        why: String,
        id: Value,
    },
    /// The framing itself is broken (or the input failed): nothing further
    /// can be read.
    Broken(String),
    /// The input ended.
    End,
}

/// Read one frame's body: `Ok(None)` at the end of the input.
fn read_frame(input: &mut impl BufRead) -> Result<Option<Vec<u8>>, String> {
    let mut length: Option<usize> = None;
    let mut first = true;
    loop {
        let mut line = Vec::new();
        let n = input
            .by_ref()
            .take(MAX_HEADER_LINE as u64)
            .read_until(b'\n', &mut line)
            .map_err(|e| format!("cannot read the input: {e}"))?;
        if n == 0 {
            return if first {
                Ok(None)
            } else {
                Err("the input ended inside a header".into())
            };
        }
        first = false;
        if !line.ends_with(b"\n") {
            return Err(format!("a header line longer than {MAX_HEADER_LINE} bytes"));
        }
        let line = String::from_utf8_lossy(&line);
        let line = line.trim_end_matches(['\r', '\n']);
        if line.is_empty() {
            break;
        }
        let Some((name, value)) = line.split_once(':') else {
            return Err(format!(
                "a header line without `:`: {}",
                ravel_base::text::sanitize(line)
            ));
        };
        if name.trim().eq_ignore_ascii_case("content-length") {
            let v: usize = value.trim().parse().map_err(|_| {
                format!(
                    "Content-Length is not a number: {}",
                    ravel_base::text::sanitize(value.trim())
                )
            })?;
            length = Some(v);
        }
    }
    let length = length.ok_or("a message without Content-Length")?;
    if length > MAX_MESSAGE_BYTES {
        return Err(format!(
            "a message of {length} bytes, more than the limit of {MAX_MESSAGE_BYTES}"
        ));
    }
    let mut body = Vec::with_capacity(length.min(1 << 20));
    let got = input
        .by_ref()
        .take(length as u64)
        .read_to_end(&mut body)
        .map_err(|e| format!("cannot read the input: {e}"))?;
    if got < length {
        return Err(format!(
            "the input ended after {got} of {length} bytes of a message"
        ));
    }
    Ok(Some(body))
}

/// Read and decode one message.
fn read_message(input: &mut impl BufRead) -> Incoming {
    let body = match read_frame(input) {
        Ok(Some(b)) => b,
        Ok(None) => return Incoming::End,
        Err(e) => return Incoming::Broken(e),
    };
    let value: Value = match serde_json::from_slice(&body) {
        Ok(v) => v,
        Err(e) => {
            return Incoming::Bad {
                code: ErrorCode::ParseError,
                why: format!("not JSON: {e}"),
                id: Value::Null,
            }
        }
    };
    let id = value.get("id").cloned().unwrap_or(Value::Null);
    match serde_json::from_value::<Message>(value) {
        // a request whose id the message types cannot hold reads as a
        // notification (its id ignored): it must be answered all the same
        Ok(Message::Notification(_)) if !id.is_null() => Incoming::Bad {
            code: ErrorCode::InvalidRequest,
            why: "a request id must be an integer of 32 bits or a string".into(),
            id,
        },
        Ok(m) => Incoming::Message(m),
        Err(_) => Incoming::Bad {
            code: ErrorCode::InvalidRequest,
            why: "not a JSON-RPC request, response or notification (ids are integers of 32 bits or strings)".into(),
            id: if id.is_number() || id.is_string() {
                id
            } else {
                Value::Null
            },
        },
    }
}

/// Write one message, framed.
fn write_value(out: &mut impl Write, v: &Value) -> std::io::Result<()> {
    let body = v.to_string();
    write!(out, "Content-Length: {}\r\n\r\n{body}", body.len())?;
    out.flush()
}

fn write_message(out: &mut impl Write, m: Message) -> std::io::Result<()> {
    let mut v = serde_json::to_value(&m).unwrap_or(Value::Null);
    if let Value::Object(o) = &mut v {
        o.insert("jsonrpc".into(), json!("2.0"));
    }
    write_value(out, &v)
}

/// A request's outcome: a result, or an error code and message.
type Answer = Result<Value, (ErrorCode, String)>;

fn invalid(why: impl Into<String>) -> (ErrorCode, String) {
    (ErrorCode::InvalidParams, why.into())
}

/// The server's state.
struct Server {
    docs: BTreeMap<String, Doc>,
    /// Documents whose diagnostics are due.
    dirty: BTreeSet<String>,
    initialized: bool,
    shutdown: bool,
}

/// The folder of a `file:` URI's path (percent-decoded), or `None` for
/// another scheme or a malformed URI.
fn file_folder(uri: &str) -> Option<PathBuf> {
    let rest = uri.strip_prefix("file://")?;
    // an authority, if any, is `localhost` or empty
    let path = match rest.find('/') {
        Some(0) => rest,
        Some(i) if rest[..i].eq_ignore_ascii_case("localhost") => &rest[i..],
        _ => return None,
    };
    let path = path.split(['?', '#']).next().unwrap_or(path);
    let mut bytes = Vec::with_capacity(path.len());
    let b = path.as_bytes();
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = std::str::from_utf8(b.get(i + 1..i + 3)?).ok()?;
            bytes.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            bytes.push(b[i]);
            i += 1;
        }
    }
    if bytes.contains(&0) {
        return None;
    }
    #[cfg(unix)]
    let file = {
        use std::os::unix::ffi::OsStrExt;
        PathBuf::from(std::ffi::OsStr::from_bytes(&bytes))
    };
    #[cfg(not(unix))]
    let file = PathBuf::from(String::from_utf8(bytes).ok()?);
    file.parent().map(|p| p.to_path_buf())
}

fn range(doc: &Doc, span: ravel_syntax::ast::Span) -> lt::Range {
    let p = |o| {
        let Position { line, character } = doc.index.position(&doc.text, o);
        lt::Position { line, character }
    };
    lt::Range {
        start: p(span.start),
        end: p(span.end.max(span.start)),
    }
}

impl Server {
    fn doc(&self, uri: &lt::Uri) -> Result<&Doc, (ErrorCode, String)> {
        self.docs.get(uri.as_str()).ok_or_else(|| {
            invalid(format!(
                "the document {} is not open",
                ravel_base::text::sanitize(uri.as_str())
            ))
        })
    }

    /// The byte offset of a position in an open document.
    fn offset(
        &self,
        p: &lt::TextDocumentPositionParams,
    ) -> Result<(&Doc, usize), (ErrorCode, String)> {
        let doc = self.doc(&p.text_document.uri)?;
        let pos = Position {
            line: p.position.line,
            character: p.position.character,
        };
        let o = doc
            .index
            .offset(&doc.text, pos)
            .map_err(|e| invalid(e.to_string()))?;
        Ok((doc, o))
    }

    fn request(&mut self, method: &str, params: Value) -> Answer {
        macro_rules! parse {
            ($t:ty) => {
                serde_json::from_value::<$t>(params)
                    .map_err(|e| invalid(format!("invalid parameters: {e}")))?
            };
        }
        if method == "initialize" {
            if self.initialized {
                return Err((
                    ErrorCode::InvalidRequest,
                    "initialize was already received".into(),
                ));
            }
            self.initialized = true;
            return Ok(json!({
                "capabilities": {
                    "positionEncoding": "utf-16",
                    "textDocumentSync": { "openClose": true, "change": 1, "save": true },
                    "hoverProvider": true,
                    "definitionProvider": true,
                    "completionProvider": { "triggerCharacters": [] },
                    "documentFormattingProvider": true,
                },
                "serverInfo": { "name": "ravel", "version": env!("CARGO_PKG_VERSION") },
            }));
        }
        if !self.initialized {
            return Err((ErrorCode::ServerNotInitialized, "initialize first".into()));
        }
        if self.shutdown {
            return Err((
                ErrorCode::InvalidRequest,
                "the server is shutting down".into(),
            ));
        }
        match method {
            "shutdown" => {
                self.shutdown = true;
                Ok(Value::Null)
            }
            "textDocument/hover" => {
                let p = parse!(lt::HoverParams);
                let (doc, o) = self.offset(&p.text_document_position_params)?;
                Ok(match ravel_ide::hover(&doc.text, o) {
                    None => Value::Null,
                    Some(h) => json!(lt::Hover {
                        contents: lt::HoverContents::Markup(lt::MarkupContent {
                            kind: lt::MarkupKind::Markdown,
                            value: h.markdown,
                        }),
                        range: Some(range(doc, h.span)),
                    }),
                })
            }
            "textDocument/definition" => {
                let p = parse!(lt::GotoDefinitionParams);
                let tdp = &p.text_document_position_params;
                let (doc, o) = self.offset(tdp)?;
                Ok(match ravel_ide::definition(&doc.text, o) {
                    None => Value::Null,
                    Some(span) => json!(lt::Location {
                        uri: tdp.text_document.uri.clone(),
                        range: range(doc, span),
                    }),
                })
            }
            "textDocument/completion" => {
                let p = parse!(lt::CompletionParams);
                let (doc, o) = self.offset(&p.text_document_position)?;
                let items: Vec<lt::CompletionItem> = ravel_ide::completion(&doc.text, o)
                    .into_iter()
                    .map(|c| {
                        use ravel_ide::words::WordKind as W;
                        use ravel_ide::{CompletionKind as C, SymbolKind as S};
                        let kind = match c.kind {
                            C::Word(W::Keyword) => lt::CompletionItemKind::KEYWORD,
                            C::Word(W::Propagator | W::Partitioner | W::Option) => {
                                lt::CompletionItemKind::ENUM_MEMBER
                            }
                            C::Word(W::Function) => lt::CompletionItemKind::FUNCTION,
                            C::Name(S::Block) => lt::CompletionItemKind::MODULE,
                            C::Name(S::Vector | S::Matrix) => lt::CompletionItemKind::VARIABLE,
                            C::Name(S::Constant) => lt::CompletionItemKind::CONSTANT,
                            C::Name(S::Set | S::Property) => lt::CompletionItemKind::STRUCT,
                        };
                        lt::CompletionItem {
                            label: c.label,
                            kind: Some(kind),
                            detail: Some(c.detail),
                            ..Default::default()
                        }
                    })
                    .collect();
                Ok(json!(items))
            }
            "textDocument/formatting" => {
                let p = parse!(lt::DocumentFormattingParams);
                let doc = self.doc(&p.text_document.uri)?;
                let edits: Vec<lt::TextEdit> = match ravel_ide::format(&doc.text) {
                    Some(new) if new != doc.text => vec![lt::TextEdit {
                        range: range(doc, ravel_syntax::ast::Span::new(0, doc.text.len())),
                        new_text: new,
                    }],
                    _ => Vec::new(),
                };
                Ok(json!(edits))
            }
            _ => Err((
                ErrorCode::MethodNotFound,
                format!("unknown method {}", ravel_base::text::sanitize(method)),
            )),
        }
    }

    /// Handle a notification; `Some(code)` on `exit`.
    fn notification(&mut self, method: &str, params: Value, out: &mut impl Write) -> Option<i32> {
        if method == "exit" {
            return Some(if self.shutdown { 0 } else { 1 });
        }
        if !self.initialized {
            return None;
        }
        match method {
            "textDocument/didOpen" => {
                if let Ok(p) = serde_json::from_value::<lt::DidOpenTextDocumentParams>(params) {
                    let d = p.text_document;
                    let key = d.uri.as_str().to_string();
                    self.docs.insert(
                        key.clone(),
                        Doc {
                            index: LineIndex::new(&d.text),
                            text: d.text,
                            version: d.version,
                        },
                    );
                    self.dirty.insert(key);
                }
            }
            "textDocument/didChange" => {
                if let Ok(p) = serde_json::from_value::<lt::DidChangeTextDocumentParams>(params) {
                    let key = p.text_document.uri.as_str().to_string();
                    if let Some(doc) = self.docs.get_mut(&key) {
                        for change in p.content_changes {
                            if let Err(e) = apply(doc, change) {
                                log(out, &format!("ravel lsp: a change was not applied: {e}"));
                            }
                        }
                        doc.version = p.text_document.version;
                        self.dirty.insert(key);
                    }
                }
            }
            "textDocument/didSave" => {
                // the controller beside it may have changed too
                if let Ok(p) = serde_json::from_value::<lt::DidSaveTextDocumentParams>(params) {
                    let key = p.text_document.uri.as_str().to_string();
                    if self.docs.contains_key(&key) {
                        self.dirty.insert(key);
                    }
                }
            }
            "textDocument/didClose" => {
                if let Ok(p) = serde_json::from_value::<lt::DidCloseTextDocumentParams>(params) {
                    let key = p.text_document.uri.as_str().to_string();
                    if self.docs.remove(&key).is_some() {
                        self.dirty.remove(&key);
                        let _ = write_message(
                            out,
                            Message::Notification(Notification::new(
                                "textDocument/publishDiagnostics".into(),
                                json!({ "uri": key, "diagnostics": [] }),
                            )),
                        );
                    }
                }
            }
            // everything else (initialized, $/cancelRequest, configuration, …) needs nothing
            _ => {}
        }
        None
    }

    /// Publish the diagnostics of every document changed since the last time.
    fn publish(&mut self, out: &mut impl Write) -> std::io::Result<()> {
        for key in std::mem::take(&mut self.dirty) {
            let Some(doc) = self.docs.get(&key) else {
                continue;
            };
            let folder = file_folder(&key);
            let diags = std::panic::catch_unwind(|| match &folder {
                Some(dir) => ravel_ide::diagnostics(&doc.text, dir, &crate::read_request),
                None => ravel_ide::diagnostics(&doc.text, std::path::Path::new("."), &|_| {
                    Err(ravel::ReadError::Io(
                        "the document is not a file on disk: save it to read its controller".into(),
                    ))
                }),
            });
            let Ok(diags) = diags else {
                log(
                    out,
                    "ravel lsp: internal error while checking (a bug; please report it)",
                );
                continue;
            };
            let list: Vec<Value> = diags
                .iter()
                .map(|d| {
                    let span = d.span.unwrap_or_default();
                    let mut message = d.message.clone();
                    if let Some(h) = &d.hint {
                        message.push_str("\nhelp: ");
                        message.push_str(h);
                    }
                    let related: Vec<Value> = d
                        .related
                        .iter()
                        .map(|(s, label)| {
                            json!({
                                "location": { "uri": key, "range": range(doc, *s) },
                                "message": if label.is_empty() { "here" } else { label },
                            })
                        })
                        .collect();
                    let mut v = json!({
                        "range": range(doc, span),
                        "severity": 1,
                        "code": d.code.as_str(),
                        "source": "ravel",
                        "message": message,
                    });
                    if !related.is_empty() {
                        v["relatedInformation"] = json!(related);
                    }
                    v
                })
                .collect();
            write_message(
                out,
                Message::Notification(Notification::new(
                    "textDocument/publishDiagnostics".into(),
                    json!({ "uri": key, "version": doc.version, "diagnostics": list }),
                )),
            )?;
        }
        Ok(())
    }
}

/// Apply one content change: the whole text, or a range replaced.
fn apply(doc: &mut Doc, change: lt::TextDocumentContentChangeEvent) -> Result<(), String> {
    match change.range {
        None => doc.text = change.text,
        Some(r) => {
            let at = |p: lt::Position| {
                doc.index
                    .offset(
                        &doc.text,
                        Position {
                            line: p.line,
                            character: p.character,
                        },
                    )
                    .map_err(|e| e.to_string())
            };
            let (a, b) = (at(r.start)?, at(r.end)?);
            if a > b {
                return Err("the range ends before it starts".into());
            }
            if (doc.text.len() - (b - a)).saturating_add(change.text.len()) > MAX_MESSAGE_BYTES {
                return Err("the document would grow past the message limit".into());
            }
            doc.text.replace_range(a..b, &change.text);
        }
    }
    doc.index = LineIndex::new(&doc.text);
    Ok(())
}

/// A message for the client's log (`window/logMessage`).
fn log(out: &mut impl Write, text: &str) {
    let _ = write_message(
        out,
        Message::Notification(Notification::new(
            "window/logMessage".into(),
            json!({ "type": 1, "message": text }),
        )),
    );
}

fn error_value(id: Value, code: ErrorCode, message: &str) -> Value {
    json!({ "jsonrpc": "2.0", "id": id, "error": { "code": code as i32, "message": message } })
}

/// Serve the protocol on `input` and `output` until `exit` or the end of
/// the input; the process's exit code: 0 after `shutdown` then `exit`, 1
/// otherwise (as the protocol asks).
pub fn serve<R: BufRead + Send + 'static>(mut input: R, output: &mut impl Write) -> i32 {
    let (tx, rx) = mpsc::channel::<Incoming>();
    std::thread::spawn(move || loop {
        let m = read_message(&mut input);
        let last = matches!(m, Incoming::Broken(_) | Incoming::End);
        if tx.send(m).is_err() || last {
            break;
        }
    });
    let mut server = Server {
        docs: BTreeMap::new(),
        dirty: BTreeSet::new(),
        initialized: false,
        shutdown: false,
    };
    loop {
        // handle everything waiting, then check the documents it changed
        let mut next = rx.recv().ok();
        while let Some(incoming) = next {
            if let Some(code) = handle(&mut server, incoming, output) {
                return code;
            }
            next = rx.try_recv().ok();
        }
        if server.publish(output).is_err() {
            return 1;
        }
    }
}

/// Handle one incoming message; `Some(code)` when the server must stop.
fn handle(server: &mut Server, incoming: Incoming, out: &mut impl Write) -> Option<i32> {
    let written = match incoming {
        Incoming::End => {
            return Some(if server.shutdown { 0 } else { 1 });
        }
        Incoming::Broken(why) => {
            let _ = write_value(
                out,
                &error_value(
                    Value::Null,
                    ErrorCode::ParseError,
                    &format!("ravel lsp stops: {why}"),
                ),
            );
            return Some(1);
        }
        Incoming::Bad { code, why, id } => write_value(out, &error_value(id, code, &why)),
        Incoming::Message(Message::Request(Request { id, method, params })) => {
            let answer = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                server.request(&method, params)
            }))
            .unwrap_or_else(|_| {
                Err((
                    ErrorCode::InternalError,
                    "ravel lsp: internal error (a bug; please report it)".into(),
                ))
            });
            let response = match answer {
                Ok(v) => Response::new_ok(id, v),
                Err((code, message)) => Response::new_err(id, code as i32, message),
            };
            write_message(out, Message::Response(response))
        }
        Incoming::Message(Message::Notification(Notification { method, params })) => {
            let code = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                server.notification(&method, params, out)
            }))
            .unwrap_or(None);
            if code.is_some() {
                return code;
            }
            Ok(())
        }
        // the server sends no requests, so a response answers nothing
        Incoming::Message(Message::Response(_)) => Ok(()),
    };
    if written.is_err() {
        return Some(1);
    }
    None
}
