//! Check diagnostics (spec section 6): every one has a code, a labelled span and a help line.

use crate::suggest::closest;
use miette::{Diagnostic, SourceSpan};
use thiserror::Error;

/// A problem found by the checks: the file parses but is not a valid model.
#[derive(Debug, Clone, Error, Diagnostic, PartialEq)]
pub enum CheckError {
    /// A name that is not declared.
    #[error("unknown name `{name}`")]
    #[diagnostic(code(gbm::E0101))]
    UnknownName {
        /// The name.
        name: String,
        /// Where it is used.
        #[label("not declared")]
        span: SourceSpan,
        /// Suggestion.
        #[help]
        help: String,
    },
    /// A name declared twice.
    #[error("`{name}` is declared twice")]
    #[diagnostic(
        code(gbm::E0102),
        help("rename one of them; every name in a model is global")
    )]
    Duplicate {
        /// The name.
        name: String,
        /// The second declaration.
        #[label("declared again here")]
        span: SourceSpan,
        /// The first declaration.
        #[label("first declared here")]
        first: SourceSpan,
    },
    /// A state with no balance.
    #[error("state `{name}` has no `der` or `next` equation")]
    #[diagnostic(code(gbm::E0103))]
    NoBalance {
        /// The state.
        name: String,
        /// Its declaration.
        #[label("declared here")]
        span: SourceSpan,
        /// How to fix.
        #[help]
        help: String,
    },
    /// A state with two balances.
    #[error("state `{name}` has two balance equations")]
    #[diagnostic(
        code(gbm::E0104),
        help(
            "keep one equation per state; add terms to it, or use `der X += ...` inside an effect"
        )
    )]
    TwoBalances {
        /// The state.
        name: String,
        /// The second equation.
        #[label("second equation")]
        span: SourceSpan,
        /// The first equation.
        #[label("first equation")]
        first: SourceSpan,
    },
    /// `der`/`next` of something that is not a state.
    #[error("`{keyword} {name}`: `{name}` is {kind}, not a state")]
    #[diagnostic(code(gbm::E0105))]
    BalanceOfNonState {
        /// `der` or `next`.
        keyword: String,
        /// The name.
        name: String,
        /// What it is.
        kind: String,
        /// Where.
        #[label("not a state")]
        span: SourceSpan,
        /// How to fix.
        #[help]
        help: String,
    },
    /// A closure output no equation uses.
    #[error("closure output `{name}` is never used")]
    #[diagnostic(
        code(gbm::E0106),
        help("use it in a balance, a `let`, an `output` or an effect patch, or remove it from `outputs`")
    )]
    UnusedClosureOutput {
        /// The output.
        name: String,
        /// Where declared.
        #[label("declared here, used nowhere")]
        span: SourceSpan,
    },
    /// `let`s (or consts) defined in terms of each other.
    #[error("cycle among definitions: {cycle}")]
    #[diagnostic(
        code(gbm::E0107),
        help("a `let` (or `const`) may not depend on itself, directly or through others")
    )]
    Cycle {
        /// The names around the cycle.
        cycle: String,
        /// The first definition in the cycle.
        #[label("this definition depends on itself")]
        span: SourceSpan,
    },
    /// A model with both `der` and `next`.
    #[error("model mixes `der` and `next` equations")]
    #[diagnostic(
        code(gbm::E0108),
        help("a model is either continuous-time (`der`) or discrete-time (`next`)")
    )]
    MixedDynamics {
        /// A `next` equation.
        #[label("`next` here")]
        span: SourceSpan,
        /// A `der` equation.
        #[label("`der` here")]
        first: SourceSpan,
    },
    /// Bad embedding settings.
    #[error("{message}")]
    #[diagnostic(code(gbm::E0109))]
    BadEmbedding {
        /// What is wrong.
        message: String,
        /// Where.
        #[label("here")]
        span: SourceSpan,
        /// How to fix.
        #[help]
        help: String,
    },
    /// A prior for a name that is not an output of the closure.
    #[error("prior for `{name}`, which is not an output of closure `{closure}`")]
    #[diagnostic(code(gbm::E0110))]
    PriorTarget {
        /// The target name.
        name: String,
        /// The closure.
        closure: String,
        /// Where.
        #[label("not an output of `{closure}`")]
        span: SourceSpan,
        /// The outputs it has.
        #[help]
        help: String,
    },
    /// A `positive` param that starts at or below zero.
    #[error("param `{name}` is `positive` but its initial value is {value}")]
    #[diagnostic(
        code(gbm::E0111),
        help("give a positive initial guess, e.g. the order of magnitude you expect")
    )]
    NonPositiveInit {
        /// The param.
        name: String,
        /// Its initial value.
        value: f64,
        /// Where.
        #[label("not positive")]
        span: SourceSpan,
    },
    /// An activation that does not exist.
    #[error("unknown activation `{name}`")]
    #[diagnostic(code(gbm::E0112))]
    UnknownActivation {
        /// The name.
        name: String,
        /// Where.
        #[label("not an activation")]
        span: SourceSpan,
        /// Suggestion.
        #[help]
        help: String,
    },
    /// A function that does not exist.
    #[error("unknown function `{name}`")]
    #[diagnostic(code(gbm::E0113))]
    UnknownFunction {
        /// The name.
        name: String,
        /// Where.
        #[label("not a function")]
        span: SourceSpan,
        /// Suggestion.
        #[help]
        help: String,
    },
    /// A function called with the wrong number of arguments.
    #[error("`{name}` takes {expected} argument{plural}, found {found}")]
    #[diagnostic(code(gbm::E0114))]
    Arity {
        /// The function.
        name: String,
        /// Arguments it takes.
        expected: usize,
        /// `s` or nothing.
        plural: &'static str,
        /// Arguments given.
        found: usize,
        /// Where.
        #[label("called here")]
        span: SourceSpan,
        /// Its signature.
        #[help]
        help: String,
    },
    /// An effect patching a name that does not exist.
    #[error("effect `{effect}` patches `{name}`, which does not exist")]
    #[diagnostic(code(gbm::E0115))]
    UnknownPatchTarget {
        /// The effect.
        effect: String,
        /// The target.
        name: String,
        /// Where.
        #[label("no such name")]
        span: SourceSpan,
        /// Suggestion.
        #[help]
        help: String,
    },
    /// An effect patching something that cannot be patched.
    #[error("`{name}` is {kind} and cannot be patched")]
    #[diagnostic(code(gbm::E0116))]
    NotPatchable {
        /// The target.
        name: String,
        /// What it is.
        kind: String,
        /// Where.
        #[label("cannot patch this")]
        span: SourceSpan,
        /// What can be patched.
        #[help]
        help: String,
    },
    /// A value that must be constant refers to something that changes.
    #[error("{what} must be a constant expression, but uses `{name}` ({kind})")]
    #[diagnostic(code(gbm::E0117))]
    NotConstant {
        /// What must be constant.
        what: String,
        /// The offending name.
        name: String,
        /// What it is.
        kind: String,
        /// Where.
        #[label("not constant")]
        span: SourceSpan,
        /// What is allowed.
        #[help]
        help: String,
    },
    /// Bounds with lo >= hi, or a non-finite constant value.
    #[error("{message}")]
    #[diagnostic(code(gbm::E0118))]
    BadValue {
        /// What is wrong.
        message: String,
        /// Where.
        #[label("here")]
        span: SourceSpan,
        /// How to fix.
        #[help]
        help: String,
    },
    /// A malformed closure block.
    #[error("{message}")]
    #[diagnostic(code(gbm::E0119))]
    BadClosure {
        /// What is wrong.
        message: String,
        /// Where.
        #[label("here")]
        span: SourceSpan,
        /// How to fix.
        #[help]
        help: String,
    },
    /// A closure observes something that is not measured.
    #[error("closure `{closure}` observes `{name}`, which is {kind}")]
    #[diagnostic(
        code(gbm::E0120),
        help(
            "an embedding is built from measured data: observe inputs and measured `state`s only"
        )
    )]
    BadObserve {
        /// The closure.
        closure: String,
        /// The name.
        name: String,
        /// What it is.
        kind: String,
        /// Where.
        #[label("not measured")]
        span: SourceSpan,
    },
    /// A prior that depends on a closure output.
    #[error("prior for `{target}` uses closure output `{name}`")]
    #[diagnostic(
        code(gbm::E0121),
        help("priors may use states, inputs, consts, params and `let`s of those, not closure outputs")
    )]
    PriorUsesClosure {
        /// The prior target.
        target: String,
        /// The closure output used.
        name: String,
        /// Where.
        #[label("closure output")]
        span: SourceSpan,
    },
    /// A hidden state of a trainable model without an initial value.
    #[error("hidden state `{name}` needs an initial value in a trainable model")]
    #[diagnostic(
        code(gbm::E0122),
        help("hidden states are simulated, never read from data: write `hidden {name} = value`")
    )]
    HiddenWithoutInit {
        /// The state.
        name: String,
        /// Where.
        #[label("no initial value")]
        span: SourceSpan,
    },
    /// A model with no state.
    #[error("model `{name}` declares no state")]
    #[diagnostic(
        code(gbm::E0124),
        help("declare measured states with `state X` and give each a `der` or `next` equation")
    )]
    NoStates {
        /// The model name.
        name: String,
        /// The header.
        #[label("this model")]
        span: SourceSpan,
    },
    /// Noise declared for something that is not measured.
    #[error("noise for `{name}`, which is {kind}")]
    #[diagnostic(code(gbm::E0140))]
    NoiseTarget {
        /// The name.
        name: String,
        /// What it is.
        kind: String,
        /// Where.
        #[label("not measured")]
        span: SourceSpan,
        /// Why only measured quantities have noise.
        #[help]
        help: String,
    },
    /// Two noise declarations for one quantity.
    #[error("`{name}` has two noise declarations")]
    #[diagnostic(
        code(gbm::E0141),
        help("keep one: a quantity has one error model, `noise {name} = REL % + ABS`")
    )]
    DuplicateNoise {
        /// The quantity.
        name: String,
        /// The second declaration.
        #[label("declared again here")]
        span: SourceSpan,
        /// The first declaration.
        #[label("first declared here")]
        first: SourceSpan,
    },
    /// A negative or non-finite noise term.
    #[error("expected {expected}, found {found}")]
    #[diagnostic(code(gbm::E0142))]
    BadNoiseValue {
        /// What a term must be.
        expected: String,
        /// The value found.
        found: String,
        /// Where.
        #[label("this term")]
        span: SourceSpan,
        /// How to fix.
        #[help]
        help: String,
    },
    /// Two relative or two absolute terms in one noise declaration.
    #[error("expected at most one {kind} term in a noise declaration, found two")]
    #[diagnostic(code(gbm::E0143))]
    NoiseTerms {
        /// `relative` or `absolute`.
        kind: String,
        /// The second term.
        #[label("second {kind} term")]
        span: SourceSpan,
        /// The first term.
        #[label("first {kind} term")]
        first: SourceSpan,
        /// The form of a declaration.
        #[help]
        help: String,
    },
    /// A noise declaration whose terms are all zero.
    #[error("expected a noise level above zero, found {found}")]
    #[diagnostic(
        code(gbm::E0144),
        help(
            "a measurement without error cannot weight a fit or bound a gap: give the assay's \
             precision (e.g. `4 % + 0.01 [g/L]`), or leave the declaration out"
        )
    )]
    ZeroNoise {
        /// The terms as written.
        found: String,
        /// Where.
        #[label("zero")]
        span: SourceSpan,
    },
    /// A unit symbol gbc does not know (in a `[...]` annotation or after `time`).
    #[error("unknown unit `{symbol}`")]
    #[diagnostic(code(gbm::E0150))]
    UnknownUnit {
        /// The symbol as written.
        symbol: String,
        /// Where.
        #[label("not a unit")]
        span: SourceSpan,
        /// Suggestion, or the known symbols.
        #[help]
        help: String,
    },
    /// Two units of different dimensions where one unit is needed.
    #[error("{context}: expected {expected}, found {found}")]
    #[diagnostic(code(gbm::E0151))]
    UnitMismatch {
        /// What must agree, in words (`operands of `+``, `balance of `X``).
        context: String,
        /// The unit the place needs.
        expected: String,
        /// The unit found.
        found: String,
        /// The expression with the wrong unit.
        #[label("{found}")]
        span: SourceSpan,
        /// Where the expected unit comes from, if it is written somewhere.
        #[label("{expected}")]
        origin: Option<SourceSpan>,
        /// Both units and their dimensions.
        #[help]
        help: String,
    },
    /// Two units of one dimension but different scales (`g/L` and `mg/L`, `1/h` and `1/min`).
    #[error("{context}: expected {expected}, found {found}, a factor of {factor} apart")]
    #[diagnostic(code(gbm::E0152))]
    UnitScale {
        /// What must agree, in words.
        context: String,
        /// The unit the place needs.
        expected: String,
        /// The unit found.
        found: String,
        /// The conversion factor between them.
        factor: String,
        /// The expression with the wrong unit.
        #[label("{found}")]
        span: SourceSpan,
        /// Where the expected unit comes from, if it is written somewhere.
        #[label("{expected}")]
        origin: Option<SourceSpan>,
        /// The conversion, e.g. `1 g/L = 1000 mg/L`.
        #[help]
        help: String,
    },
    /// A function argument, an exponent or a `*=` factor that must be dimensionless is not.
    #[error("{context} must be dimensionless, found {found}")]
    #[diagnostic(code(gbm::E0153))]
    NotDimensionless {
        /// What must be dimensionless, in words.
        context: String,
        /// The unit found.
        found: String,
        /// Where.
        #[label("{found}")]
        span: SourceSpan,
        /// How to fix.
        #[help]
        help: String,
    },
}

/// A "did you mean" help line for `name` among `candidates`, or a generic hint.
pub fn suggest<'a>(
    name: &str,
    candidates: impl IntoIterator<Item = &'a str>,
    what: &str,
) -> String {
    match closest(name, candidates) {
        Some(best) => format!("did you mean `{best}`?"),
        None => format!("declare it first, or check the spelling of the {what}"),
    }
}
