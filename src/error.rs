//! The one type of internal errors: an invariant gbc broke, never a problem with the user's
//! input. Every stage's error enum carries it as a transparent variant; the command line
//! recognises it by its code ([`BUG_CODE`]) in one place and exits with code 2, so no
//! stage or command keeps an `is_internal` of its own, and no user code (`gbm::E0xxx`) is
//! spent on a bug.

/// The diagnostic code of every internal error.
pub const BUG_CODE: &str = "gbc::internal";

/// A broken invariant: where it was found and what went wrong.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error, miette::Diagnostic)]
#[error("internal error in {place}: {message}")]
#[diagnostic(code(gbc::internal), help("this is a bug in gbc: please report it"))]
pub struct Bug {
    /// The stage, in words (`the trainable network`).
    pub place: &'static str,
    /// What went wrong.
    pub message: String,
}

impl Bug {
    /// A bug found in `place`.
    pub fn new(place: &'static str, message: impl Into<String>) -> Self {
        Bug {
            place,
            message: message.into(),
        }
    }
}

/// Whether a diagnostic is (or wraps, transparently) an internal error.
pub fn is_bug(diagnostic: &dyn miette::Diagnostic) -> bool {
    diagnostic
        .code()
        .is_some_and(|code| code.to_string() == BUG_CODE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error, miette::Diagnostic)]
    enum StageError {
        #[error("bad input")]
        #[diagnostic(code(gbm::E0001))]
        User,
        #[error(transparent)]
        #[diagnostic(transparent)]
        Internal(#[from] Bug),
    }

    #[test]
    fn a_wrapped_bug_is_recognised_by_its_code_and_a_user_error_is_not() {
        let bug = StageError::from(Bug::new("the network", "rows differ"));
        assert!(is_bug(&bug));
        assert_eq!(
            bug.to_string(),
            "internal error in the network: rows differ"
        );
        assert!(!is_bug(&StageError::User));
    }
}
