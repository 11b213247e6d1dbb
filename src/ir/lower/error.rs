//! What can go wrong while lowering a checked model.

use miette::Diagnostic;
use thiserror::Error;

/// A problem found while lowering a checked model.
#[derive(Debug, Clone, Error, Diagnostic, PartialEq)]
pub enum LowerError {
    /// An effect name that the model does not declare.
    #[error("unknown effect `{name}`")]
    #[diagnostic(code(gbm::E0130))]
    UnknownEffect {
        /// The name asked for.
        name: String,
        /// The effects the model has.
        #[help]
        help: String,
    },
    /// `let`s (or patches) nested deeper than lowering follows.
    #[error("definitions nest more than {limit} levels deep")]
    #[diagnostic(
        code(gbm::E0131),
        help("each `let` used inside another adds a level; flatten the chain of definitions")
    )]
    NestingTooDeep {
        /// The limit.
        limit: usize,
        /// Where the limit was crossed.
        #[label("while inlining this")]
        span: miette::SourceSpan,
    },
    /// Inlining produced an enormous expression.
    #[error("expression too large after inlining `let`s ({nodes} nodes)")]
    #[diagnostic(
        code(gbm::E0132),
        help("a `let` used many times inside other `let`s is copied each time; simplify the definitions")
    )]
    TooLarge {
        /// Node count reached.
        nodes: usize,
        /// Where.
        #[label("inlining this")]
        span: miette::SourceSpan,
    },
    /// A prior that depends on a closure output through a `let`.
    #[error("prior for `{target}` depends on a closure output through `let`s")]
    #[diagnostic(
        code(gbm::E0133),
        help("priors may use states, inputs, consts and params only; the network's output cannot feed its own prior")
    )]
    PriorUsesClosure {
        /// The prior target.
        target: String,
        /// The prior expression.
        #[label("this prior")]
        span: miette::SourceSpan,
    },
    /// A term of a `nonnegative` state's balance that uses a closure output and is not
    /// provably `>= 0` where the state is 0 ([`crate::ir::nonnegative`]).
    #[error(transparent)]
    #[diagnostic(transparent)]
    NegativeLearnedTerm(Box<NegativeLearnedTerm>),
}

/// E0136: a learned term that can drive a `nonnegative` state below zero.
#[derive(Debug, Clone, Error, Diagnostic, PartialEq)]
#[error("a learned term can drive `{state}` below zero{applied}")]
#[diagnostic(code(gbm::E0136))]
pub struct NegativeLearnedTerm {
    /// The state declared `nonnegative`.
    pub state: String,
    /// ` (with effect `E` applied)`, or empty.
    pub applied: String,
    /// Why the term is not proven, in words.
    pub why: String,
    /// The term, as written (in the balance, a `let` it uses, or an effect's patch).
    #[label("{why}")]
    pub span: miette::SourceSpan,
    /// Where the state is declared `nonnegative`.
    #[label("declared `nonnegative` here")]
    pub declared: miette::SourceSpan,
    /// The rewrite that passes.
    #[help]
    pub help: String,
}
