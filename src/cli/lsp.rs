//! `gbc lsp`: a language server on stdin/stdout for any editor with an LSP client
//! (VS Code, Neovim, Helix, Emacs, Zed, Sublime Text): diagnostics as you type, go to
//! definition, hover with the kind, unit and doc comment of a name, and formatting.
//! The analysis itself is `gbc::api::ide`; this file is the protocol.

use super::{CommandError, CommandResult};
use gbc::api::ide::{self, LineIndex};
use gbc::api::{format_source, Span};
use lsp_server::{Connection, ErrorCode, Message, Notification, Request, Response};
use lsp_types::{
    Diagnostic, DiagnosticRelatedInformation, DiagnosticSeverity, DidChangeTextDocumentParams,
    DidCloseTextDocumentParams, DidOpenTextDocumentParams, DocumentFormattingParams,
    GotoDefinitionParams, Hover, HoverContents, HoverParams, HoverProviderCapability, Location,
    MarkupContent, MarkupKind, NumberOrString, OneOf, Position, PublishDiagnosticsParams, Range,
    ServerCapabilities, TextDocumentSyncCapability, TextDocumentSyncKind, TextEdit, Uri,
};
use std::collections::HashMap;

/// Arguments of `gbc lsp` (none: it speaks LSP on stdin and stdout).
#[derive(Debug, clap::Args)]
pub struct LspArgs {}

/// Serves until the client asks to shut down.
pub fn run(_args: &LspArgs) -> CommandResult {
    let (connection, threads) = Connection::stdio();
    let capabilities = ServerCapabilities {
        text_document_sync: Some(TextDocumentSyncCapability::Kind(TextDocumentSyncKind::FULL)),
        hover_provider: Some(HoverProviderCapability::Simple(true)),
        definition_provider: Some(OneOf::Left(true)),
        document_formatting_provider: Some(OneOf::Left(true)),
        ..ServerCapabilities::default()
    };
    let capabilities = serde_json::to_value(capabilities).map_err(internal)?;
    connection.initialize(capabilities).map_err(internal)?;
    let mut server = Server {
        connection,
        documents: HashMap::new(),
    };
    server.serve()?;
    drop(server);
    threads.join().map_err(internal)?;
    Ok(())
}

fn internal(error: impl std::fmt::Display) -> CommandError {
    CommandError::Internal(format!("language server: {error}"))
}

struct Server {
    connection: Connection,
    /// Open documents by URI.
    documents: HashMap<String, (Uri, String)>,
}

impl Server {
    fn serve(&mut self) -> CommandResult {
        while let Ok(message) = self.connection.receiver.recv() {
            match message {
                Message::Request(request) => {
                    if self
                        .connection
                        .handle_shutdown(&request)
                        .map_err(internal)?
                    {
                        return Ok(());
                    }
                    let response = self.respond(request);
                    self.send(Message::Response(response))?;
                }
                Message::Notification(notification) => self.notified(notification)?,
                Message::Response(_) => {}
            }
        }
        Ok(())
    }

    fn send(&self, message: Message) -> CommandResult {
        self.connection.sender.send(message).map_err(internal)
    }

    fn respond(&self, request: Request) -> Response {
        let id = request.id.clone();
        let result = match request.method.as_str() {
            "textDocument/hover" => serde_json::from_value::<HoverParams>(request.params)
                .map(|p| self.hover(&p))
                .and_then(serde_json::to_value),
            "textDocument/definition" => {
                serde_json::from_value::<GotoDefinitionParams>(request.params)
                    .map(|p| self.definition(&p))
                    .and_then(serde_json::to_value)
            }
            "textDocument/formatting" => {
                serde_json::from_value::<DocumentFormattingParams>(request.params)
                    .map(|p| self.formatting(&p))
                    .and_then(serde_json::to_value)
            }
            method => {
                let message = format!("expected a request gbc serves, found `{method}`");
                return Response::new_err(id, ErrorCode::MethodNotFound as i32, message);
            }
        };
        match result {
            Ok(value) => Response::new_ok(id, value),
            Err(error) => Response::new_err(id, ErrorCode::InvalidParams as i32, error.to_string()),
        }
    }

    fn notified(&mut self, notification: Notification) -> CommandResult {
        let params = notification.params;
        let uri = match notification.method.as_str() {
            "textDocument/didOpen" => {
                let Ok(p) = serde_json::from_value::<DidOpenTextDocumentParams>(params) else {
                    return Ok(());
                };
                let key = p.text_document.uri.as_str().to_string();
                self.documents
                    .insert(key, (p.text_document.uri.clone(), p.text_document.text));
                p.text_document.uri
            }
            "textDocument/didChange" => {
                let Ok(p) = serde_json::from_value::<DidChangeTextDocumentParams>(params) else {
                    return Ok(());
                };
                let Some(change) = p.content_changes.into_iter().last() else {
                    return Ok(());
                };
                let key = p.text_document.uri.as_str().to_string();
                self.documents
                    .insert(key, (p.text_document.uri.clone(), change.text));
                p.text_document.uri
            }
            "textDocument/didClose" => {
                let Ok(p) = serde_json::from_value::<DidCloseTextDocumentParams>(params) else {
                    return Ok(());
                };
                self.documents.remove(p.text_document.uri.as_str());
                return self.publish(p.text_document.uri, Vec::new());
            }
            _ => return Ok(()),
        };
        let diagnostics = self.diagnostics(&uri);
        self.publish(uri, diagnostics)
    }

    fn publish(&self, uri: Uri, diagnostics: Vec<Diagnostic>) -> CommandResult {
        let params = PublishDiagnosticsParams {
            uri,
            diagnostics,
            version: None,
        };
        let notification = Notification::new("textDocument/publishDiagnostics".to_string(), params);
        self.send(Message::Notification(notification))
    }

    fn text(&self, uri: &Uri) -> Option<&str> {
        self.documents
            .get(uri.as_str())
            .map(|(_, text)| text.as_str())
    }

    fn diagnostics(&self, uri: &Uri) -> Vec<Diagnostic> {
        let Some(text) = self.text(uri) else {
            return Vec::new();
        };
        let index = LineIndex::new(text);
        let name = uri
            .path()
            .as_str()
            .rsplit('/')
            .next()
            .unwrap_or("model.gbm");
        ide::diagnostics(name, text)
            .into_iter()
            .map(|problem| Diagnostic {
                range: range(&index, problem.span),
                severity: Some(DiagnosticSeverity::ERROR),
                code: problem.code.map(NumberOrString::String),
                source: Some("gbc".to_string()),
                message: problem.message,
                related_information: Some(
                    (problem.related.into_iter())
                        .map(|(span, label)| DiagnosticRelatedInformation {
                            location: Location::new(uri.clone(), range(&index, span)),
                            message: label,
                        })
                        .collect(),
                ),
                ..Diagnostic::default()
            })
            .collect()
    }

    fn hover(&self, params: &HoverParams) -> Option<Hover> {
        let at = &params.text_document_position_params;
        let text = self.text(&at.text_document.uri)?;
        let index = LineIndex::new(text);
        let offset = index.offset(at.position.line, at.position.character);
        let value = ide::hover(text, offset)?;
        Some(Hover {
            contents: HoverContents::Markup(MarkupContent {
                kind: MarkupKind::Markdown,
                value,
            }),
            range: None,
        })
    }

    fn definition(&self, params: &GotoDefinitionParams) -> Option<Location> {
        let at = &params.text_document_position_params;
        let text = self.text(&at.text_document.uri)?;
        let index = LineIndex::new(text);
        let offset = index.offset(at.position.line, at.position.character);
        let span = ide::definition(text, offset)?;
        Some(Location::new(
            at.text_document.uri.clone(),
            range(&index, span),
        ))
    }

    fn formatting(&self, params: &DocumentFormattingParams) -> Option<Vec<TextEdit>> {
        let text = self.text(&params.text_document.uri)?;
        let formatted = format_source(text).ok()?;
        if formatted == text {
            return Some(Vec::new());
        }
        let index = LineIndex::new(text);
        let whole = range(&index, Span::new(0, text.len()));
        Some(vec![TextEdit::new(whole, formatted)])
    }
}

fn range(index: &LineIndex, span: Span) -> Range {
    let (start_line, start_column) = index.position(span.start);
    let (end_line, end_column) = index.position(span.end);
    Range::new(
        Position::new(start_line, start_column),
        Position::new(end_line, end_column),
    )
}
