//! The one error of the API: the diagnostics of a user's input, or an internal error.

use crate::diagnostics::{self, MessageFormat};

/// Why an API call failed: bad input (each report with its code, message, location and
/// help) or a bug in gbc ([`crate::error::Bug`]).
#[derive(Debug)]
pub enum ApiError {
    /// Bad input from the user (model, data, settings).
    User(Vec<miette::Report>),
    /// A bug in gbc.
    Internal(String),
}

impl ApiError {
    /// The error of one diagnostic: a user error, or an internal one when it is a
    /// [`crate::error::Bug`].
    pub fn user(diagnostic: impl miette::Diagnostic + Send + Sync + 'static) -> Self {
        ApiError::from(vec![miette::Report::new(diagnostic)])
    }

    /// The plain facts of each diagnostic (code, message, file, line, column, help); one
    /// record with the message alone for an internal error.
    pub fn records(&self) -> Vec<diagnostics::PlainDiagnostic> {
        match self {
            ApiError::User(reports) => reports.iter().map(diagnostics::record).collect(),
            ApiError::Internal(message) => vec![diagnostics::PlainDiagnostic {
                code: Some("gbc::internal".into()),
                message: message.clone(),
                file: None,
                line: None,
                column: None,
                help: None,
            }],
        }
    }

    /// Whether training stopped between epochs (interrupted or asked to stop) and left a
    /// checkpoint (E0430).
    pub fn is_interrupted(&self) -> bool {
        self.records()
            .iter()
            .any(|r| r.code.as_deref() == Some("gbm::E0430"))
    }

    /// Every diagnostic rendered as a compiler prints it (source excerpt, labels, help),
    /// without colour.
    pub fn rendered(&self) -> String {
        match self {
            ApiError::User(reports) => (reports.iter())
                .map(|r| diagnostics::render(r, MessageFormat::Human, false, 100))
                .collect::<Vec<_>>()
                .join("\n"),
            ApiError::Internal(message) => format!("internal error: {message}"),
        }
    }
}

impl std::fmt::Display for ApiError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ApiError::User(reports) => {
                let messages: Vec<String> = reports.iter().map(|r| r.to_string()).collect();
                write!(f, "{}", messages.join("; "))
            }
            ApiError::Internal(message) => write!(f, "internal error: {message}"),
        }
    }
}

impl std::error::Error for ApiError {}

impl From<Vec<miette::Report>> for ApiError {
    fn from(reports: Vec<miette::Report>) -> Self {
        match reports.iter().find(|r| crate::error::is_bug(r.as_ref())) {
            Some(bug) => ApiError::Internal(bug.to_string()),
            None => ApiError::User(reports),
        }
    }
}

impl From<crate::train::TrainError> for ApiError {
    fn from(error: crate::train::TrainError) -> Self {
        ApiError::user(crate::train::with_flag(error))
    }
}
