// Checks the extension without VS Code (scripts/test-extension.sh runs it):
//
//   node launch.js EXTENSION_FOLDER RAVEL_BINARY
//
// 1. package.json contributes the language (id `ravel`, `.ravel` files, a
//    language configuration that exists and is JSON), the grammar (for that
//    language, the scope name the grammar file itself declares, a file that
//    exists) and the `ravel.server.path` setting, and names a `main` script
//    that exists;
// 2. extension.js, loaded with stand-ins for the `vscode` and
//    `vscode-languageclient/node` modules (they exist only inside VS Code),
//    reads `ravel.server.path` with the default package.json declares and
//    starts a language client for `ravel` documents (files and untitled)
//    whose server is that command with the argument `lsp`;
// 3. that very command and arguments (the setting pointed at RAVEL_BINARY,
//    as a user would) are started, and answer `initialize` with the
//    capabilities the README promises, then `shutdown` and `exit` (exit code
//    0); `deactivate` stops the client.
// Any failure exits with code 1 and says what.
"use strict";

const fs = require("fs");
const path = require("path");
const Module = require("module");
const { spawn } = require("child_process");

const [folder, binary] = process.argv.slice(2);
if (!folder || !binary) {
  console.error("usage: node launch.js EXTENSION_FOLDER RAVEL_BINARY");
  process.exit(2);
}

function fail(msg) {
  console.error(`launch.js: ${msg}`);
  process.exit(1);
}
function check(cond, msg) {
  if (!cond) fail(msg);
}
function readJson(file) {
  try {
    return JSON.parse(fs.readFileSync(file, "utf8"));
  } catch (e) {
    fail(`${file}: ${e.message}`);
  }
}
// a deadline: a server that never answers is a failure, not a hang
setTimeout(() => fail("no answer from the server within 30 s"), 30000).unref();

// 1. the manifest
const pkg = readJson(path.join(folder, "package.json"));
const c = pkg.contributes || {};
const lang = (c.languages || []).find((l) => l.id === "ravel");
check(lang, "contributes.languages has no `ravel` language");
check(
  (lang.extensions || []).includes(".ravel"),
  "the ravel language does not claim `.ravel` files"
);
check(lang.configuration, "the ravel language has no language configuration");
const conf = readJson(path.join(folder, lang.configuration));
check(
  conf.comments && conf.comments.lineComment === "//",
  "the language configuration's line comment is not `//`"
);
const grammar = (c.grammars || []).find((g) => g.language === "ravel");
check(grammar, "contributes.grammars has no grammar for `ravel`");
const tm = readJson(path.join(folder, grammar.path));
check(
  tm.scopeName === grammar.scopeName,
  `the grammar's scope name ${tm.scopeName} is not the contributed ${grammar.scopeName}`
);
const setting = ((c.configuration || {}).properties || {})["ravel.server.path"];
check(setting && setting.type === "string", "no `ravel.server.path` setting");
check(pkg.main, "package.json names no main script");
const main = path.resolve(folder, pkg.main);
check(fs.existsSync(main), `main script ${pkg.main} is missing`);
check(
  (pkg.activationEvents || []).length === 0 ||
    pkg.activationEvents.includes("onLanguage:ravel"),
  "the activation events leave out onLanguage:ravel"
);

// 2. the extension's script, with stand-ins for VS Code's modules
let asked = null; // the setting the extension read, and its default
let made = null; // the language client it made
let stopped = false;
const vscode = {
  workspace: {
    getConfiguration(section) {
      return {
        get(key, fallback) {
          asked = { key: `${section}.${key}`, fallback };
          // the user's setting: the binary under test
          return binary;
        },
      };
    },
  },
};
class LanguageClient {
  constructor(id, name, serverOptions, clientOptions) {
    made = { id, name, serverOptions, clientOptions };
  }
  start() {
    return launch(made.serverOptions.run);
  }
  stop() {
    stopped = true;
    return Promise.resolve();
  }
}
const realLoad = Module._load;
Module._load = function (request, parent, isMain) {
  if (request === "vscode") return vscode;
  if (request === "vscode-languageclient/node") return { LanguageClient };
  return realLoad.call(this, request, parent, isMain);
};
const ext = require(main);
check(typeof ext.activate === "function", "extension.js exports no activate");
check(typeof ext.deactivate === "function", "extension.js exports no deactivate");

// 3. the server, started as the client would start it
function frame(msg) {
  const body = Buffer.from(JSON.stringify(msg), "utf8");
  return Buffer.concat([
    Buffer.from(`Content-Length: ${body.length}\r\n\r\n`, "ascii"),
    body,
  ]);
}
function launch(run) {
  check(run && run.command === binary, `the server command is ${run && run.command}`);
  check(
    JSON.stringify(run.args) === JSON.stringify(["lsp"]),
    `the server's arguments are ${JSON.stringify(run.args)}, not ["lsp"]`
  );
  return new Promise((resolve) => {
    const child = spawn(run.command, run.args, { stdio: ["pipe", "pipe", "inherit"] });
    child.on("error", (e) => fail(`cannot start ${run.command}: ${e.message}`));
    let buf = Buffer.alloc(0);
    const answers = new Map();
    child.stdout.on("data", (d) => {
      buf = Buffer.concat([buf, d]);
      for (;;) {
        const end = buf.indexOf("\r\n\r\n");
        if (end < 0) return;
        const m = /Content-Length: (\d+)/i.exec(buf.slice(0, end).toString("ascii"));
        check(m, "a frame without Content-Length");
        const len = Number(m[1]);
        if (buf.length < end + 4 + len) return;
        const msg = JSON.parse(buf.slice(end + 4, end + 4 + len).toString("utf8"));
        buf = buf.slice(end + 4 + len);
        if (msg.id !== undefined) answers.set(msg.id, msg);
        if (msg.id === 1) {
          const caps = (msg.result || {}).capabilities || {};
          for (const k of [
            "textDocumentSync",
            "documentFormattingProvider",
            "hoverProvider",
            "definitionProvider",
            "completionProvider",
          ]) {
            check(caps[k], `the server's capabilities lack ${k}`);
          }
          child.stdin.write(frame({ jsonrpc: "2.0", method: "initialized", params: {} }));
          child.stdin.write(frame({ jsonrpc: "2.0", id: 2, method: "shutdown" }));
        }
        if (msg.id === 2) {
          check(msg.result === null, "shutdown answered with an error");
          child.stdin.write(frame({ jsonrpc: "2.0", method: "exit" }));
        }
      }
    });
    child.on("exit", (code) => {
      check(answers.has(1) && answers.has(2), "the server ended before answering");
      check(code === 0, `the server exited with ${code} after shutdown and exit`);
      resolve();
    });
    child.stdin.write(
      frame({
        jsonrpc: "2.0",
        id: 1,
        method: "initialize",
        params: { processId: process.pid, rootUri: null, capabilities: {} },
      })
    );
  });
}

const context = { subscriptions: [] };
Promise.resolve(ext.activate(context))
  .then(() => {
    check(asked, "the extension did not read its setting");
    check(
      asked.key === "ravel.server.path",
      `the extension read ${asked.key}, not ravel.server.path`
    );
    check(
      asked.fallback === setting.default,
      `the extension's default ${asked.fallback} is not package.json's ${setting.default}`
    );
    check(made, "the extension made no language client");
    const sel = made.clientOptions.documentSelector || [];
    for (const scheme of ["file", "untitled"]) {
      check(
        sel.some((s) => s.language === "ravel" && s.scheme === scheme),
        `the client does not serve ${scheme} ravel documents`
      );
    }
    check(context.subscriptions.length > 0, "nothing to dispose of registered");
    return ext.deactivate();
  })
  .then(() => {
    check(stopped, "deactivate did not stop the client");
    console.log(`launch.js: ok (${binary} lsp answered as the extension starts it)`);
  })
  .catch((e) => fail(e.stack || String(e)));
