// The ravel extension: highlighting comes from syntaxes/ravel.tmLanguage.json;
// everything else (diagnostics as you type, formatting, hover, go to
// definition, completion) from the language server `ravel lsp`, started
// here over standard input and output.
"use strict";

const vscode = require("vscode");
const { LanguageClient } = require("vscode-languageclient/node");

let client;

function activate(context) {
  const command = vscode.workspace
    .getConfiguration("ravel")
    .get("server.path", "ravel");
  const serverOptions = {
    run: { command, args: ["lsp"] },
    debug: { command, args: ["lsp"] },
  };
  const clientOptions = {
    documentSelector: [
      { scheme: "file", language: "ravel" },
      { scheme: "untitled", language: "ravel" },
    ],
  };
  client = new LanguageClient("ravel", "ravel", serverOptions, clientOptions);
  context.subscriptions.push({ dispose: () => client && client.stop() });
  return client.start();
}

function deactivate() {
  return client ? client.stop() : undefined;
}

module.exports = { activate, deactivate };
