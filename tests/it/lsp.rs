//! `gbc lsp` spoken to over pipes: diagnostics on open and change, hover, definition,
//! formatting, shutdown.

use serde_json::{json, Value};
use std::io::{BufRead, BufReader, Read, Write};
use std::process::{ChildStdin, Command, Stdio};
use std::sync::mpsc::{channel, Receiver};
use std::time::Duration;

struct Client {
    stdin: ChildStdin,
    messages: Receiver<Value>,
}

impl Client {
    fn send(&mut self, message: Value) {
        let body = message.to_string();
        write!(self.stdin, "Content-Length: {}\r\n\r\n{body}", body.len()).expect("write");
        self.stdin.flush().expect("flush");
    }

    fn request(&mut self, id: i64, method: &str, params: Value) -> Value {
        self.send(json!({"jsonrpc": "2.0", "id": id, "method": method, "params": params}));
        self.next(|m| m["id"] == id)
    }

    fn notify(&mut self, method: &str, params: Value) {
        self.send(json!({"jsonrpc": "2.0", "method": method, "params": params}));
    }

    /// The next message that matches, skipping others.
    fn next(&mut self, matches: impl Fn(&Value) -> bool) -> Value {
        loop {
            let message = self
                .messages
                .recv_timeout(Duration::from_secs(20))
                .expect("a message from gbc lsp within 20 s");
            if matches(&message) {
                return message;
            }
        }
    }

    fn diagnostics(&mut self) -> Vec<Value> {
        let message = self.next(|m| m["method"] == "textDocument/publishDiagnostics");
        message["params"]["diagnostics"]
            .as_array()
            .cloned()
            .unwrap_or_default()
    }
}

fn read_messages(stdout: impl Read + Send + 'static) -> Receiver<Value> {
    let (sender, receiver) = channel();
    std::thread::spawn(move || {
        let mut reader = BufReader::new(stdout);
        loop {
            let mut length = 0usize;
            loop {
                let mut line = String::new();
                if reader.read_line(&mut line).unwrap_or(0) == 0 {
                    return;
                }
                let line = line.trim();
                if line.is_empty() {
                    break;
                }
                if let Some(value) = line.strip_prefix("Content-Length: ") {
                    length = value.parse().unwrap_or(0);
                }
            }
            let mut body = vec![0; length];
            if reader.read_exact(&mut body).is_err() {
                return;
            }
            let Ok(value) = serde_json::from_slice(&body) else {
                return;
            };
            if sender.send(value).is_err() {
                return;
            }
        }
    });
    receiver
}

const MODEL: &str = "model m\ntime h\n## Biomass in the tank.\nstate X [g/L] = 1\n\
const k = 0.1 [1/h]\nder X = -k * X\n";

#[test]
fn language_server_diagnoses_hovers_jumps_and_formats() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_gbc"))
        .arg("lsp")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("gbc lsp starts");
    let stdout = child.stdout.take().expect("stdout");
    let mut client = Client {
        stdin: child.stdin.take().expect("stdin"),
        messages: read_messages(stdout),
    };
    let init = client.request(1, "initialize", json!({"capabilities": {}}));
    let capabilities = &init["result"]["capabilities"];
    assert_eq!(capabilities["hoverProvider"], true, "{init}");
    assert_eq!(capabilities["definitionProvider"], true, "{init}");
    client.notify("initialized", json!({}));

    let uri = "file:///tmp/m.gbm";
    let broken = MODEL.replace("-k * X", "-k * X + X");
    client.notify(
        "textDocument/didOpen",
        json!({"textDocument": {"uri": uri, "languageId": "gbm", "version": 1, "text": broken}}),
    );
    let diagnostics = client.diagnostics();
    assert_eq!(diagnostics.len(), 1, "{diagnostics:?}");
    assert_eq!(diagnostics[0]["code"], "gbm::E0151", "{diagnostics:?}");
    assert_eq!(
        diagnostics[0]["range"]["start"],
        json!({"line": 5, "character": 17})
    );
    let related = &diagnostics[0]["relatedInformation"][0];
    assert_eq!(related["message"], "g/L/h", "{diagnostics:?}");

    client.notify(
        "textDocument/didChange",
        json!({"textDocument": {"uri": uri, "version": 2}, "contentChanges": [{"text": MODEL}]}),
    );
    assert!(client.diagnostics().is_empty(), "the fixed model is clean");

    let position = json!({"textDocument": {"uri": uri}, "position": {"line": 5, "character": 13}});
    let hover = client.request(2, "textDocument/hover", position.clone());
    let text = hover["result"]["contents"]["value"]
        .as_str()
        .unwrap_or_default();
    assert!(
        text.contains("state X") && text.contains("g/L") && text.contains("Biomass"),
        "{hover}"
    );
    let definition = client.request(3, "textDocument/definition", position);
    assert_eq!(
        definition["result"]["range"]["start"],
        json!({"line": 3, "character": 6}),
        "{definition}"
    );

    let messy = "model  m\nstate X=1;der X=-X\n";
    client.notify(
        "textDocument/didChange",
        json!({"textDocument": {"uri": uri, "version": 3}, "contentChanges": [{"text": messy}]}),
    );
    let formatting = client.request(
        4,
        "textDocument/formatting",
        json!({"textDocument": {"uri": uri}, "options": {"tabSize": 2, "insertSpaces": true}}),
    );
    assert_eq!(
        formatting["result"][0]["newText"], "model m\nstate X = 1\nder X = -X\n",
        "{formatting}"
    );

    let unknown = client.request(5, "textDocument/rename", json!({}));
    assert!(unknown["error"].is_object(), "{unknown}");
    let shutdown = client.request(6, "shutdown", Value::Null);
    assert!(shutdown.get("error").is_none(), "{shutdown}");
    client.notify("exit", Value::Null);
    let status = child.wait().expect("gbc lsp exits");
    assert!(status.success(), "{status:?}");
}
