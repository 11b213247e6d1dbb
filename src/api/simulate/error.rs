//! What can be wrong with a simulation's request itself (inputs, ranges, initial values,
//! params files, the history).

use miette::Diagnostic;
use thiserror::Error;

/// A problem with what a simulation is asked for (`gbc simulate`'s arguments).
#[derive(Debug, Clone, PartialEq, Error, Diagnostic)]
pub enum SimulateError {
    /// An input of the model has no `--input` program.
    #[error("input `{name}` has no program")]
    #[diagnostic(
        code(gbm::E0709),
        help(
            "give it one, e.g. `--input {name}=steps(hold=5..40)` or `--input {name}=const(0.5)`"
        )
    )]
    MissingInput {
        /// The input.
        name: String,
    },
    /// Two `--input` arguments name the same input.
    #[error("input `{name}` has two programs")]
    #[diagnostic(code(gbm::E0710), help("keep one `--input {name}=...`"))]
    DuplicateInput {
        /// The input.
        name: String,
    },
    /// `--range` names no measured state of the model.
    #[error("expected a measured state of the model in `--range`, found `{name}`")]
    #[diagnostic(code(gbm::E0718), help("{states}"))]
    UnknownRangeState {
        /// The name given.
        name: String,
        /// The measured states, with a suggestion.
        states: String,
    },
    /// `--init` names no state of the model.
    #[error("expected a state of the model in `--init`, found `{name}`")]
    #[diagnostic(code(gbm::E0715), help("{states}"))]
    UnknownInitState {
        /// The name given.
        name: String,
        /// The states, with a suggestion.
        states: String,
    },
    /// The params file cannot be used.
    #[error("cannot read params from `{path}`: {reason}")]
    #[diagnostic(
        code(gbm::E0716),
        help(
            "pass the run.json of `gbc train -o DIR` (or its `--json` file) or the file of \
             `gbc diagnose --json`"
        )
    )]
    BadParams {
        /// The file.
        path: String,
        /// What is wrong.
        reason: String,
    },
    /// The history holds several experiments.
    #[error("expected one experiment in the history `{path}`, found {found}")]
    #[diagnostic(
        code(gbm::E0717),
        help("pass a file with one experiment, or one without an experiment column")
    )]
    SeveralHistories {
        /// The file.
        path: String,
        /// Experiments found.
        found: usize,
    },
}
