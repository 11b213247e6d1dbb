//! Why training, prediction or reusing weights failed.

use miette::Diagnostic;
use thiserror::Error;

use crate::engine::graph::BackendError;
use crate::io::IoError;

/// A training or prediction failure.
#[derive(Debug, Error, Diagnostic)]
pub enum TrainError {
    /// An embedding delay shorter than the sampling step would read the target.
    #[error(
        "expected an embedding delay of at least the sampling step {step} in closure `{closure}`, \
         found delay {delay}"
    )]
    #[diagnostic(
        code(gbm::E0411),
        help(
            "a delayed value inside the step being predicted would come from the data it must \
             predict; raise `delay` to a multiple of the sampling step"
        )
    )]
    DelayBelowStep {
        /// Closure name.
        closure: String,
        /// Its delay.
        delay: f64,
        /// The data's sampling step.
        step: f64,
    },
    /// Too few rows for the embedding and one pair.
    #[error("expected at least {needed} rows in `{file}` ({reason}), found {found}")]
    #[diagnostic(code(gbm::E0412), help("use a longer record or a shorter embedding"))]
    TooFewRows {
        /// The data file.
        file: String,
        /// Rows needed.
        needed: usize,
        /// Rows present.
        found: usize,
        /// Why.
        reason: String,
    },
    /// More training pairs asked for than the data holds.
    #[error("expected --train-points of at most {available}, found {requested}")]
    #[diagnostic(
        code(gbm::E0413),
        help(
            "the data yield {available} training pairs after each experiment's embedding history"
        )
    )]
    TooManyTrainPoints {
        /// Pairs available.
        available: usize,
        /// Pairs requested.
        requested: usize,
    },
    /// A hidden state without an initial value.
    #[error("expected an initial value for hidden state `{name}`, found none")]
    #[diagnostic(
        code(gbm::E0414),
        help("hidden states are simulated from their initial value: write `hidden {name} = ...`")
    )]
    HiddenWithoutInit {
        /// Hidden state name.
        name: String,
    },
    /// The loss, a weight or a param became NaN or infinite.
    #[error("training diverged in epoch {epoch}: {what}")]
    #[diagnostic(
        code(gbm::E0415),
        help(
            "lower the learning rate (--lr) or clip the gradient (--clip 1), check the \
             stiffness warnings and add --substeps K, or train in --precision f64"
        )
    )]
    Diverged {
        /// 1-based epoch.
        epoch: usize,
        /// What went non-finite: "the loss became NaN", "weight `...`[3] = inf after the
        /// epoch".
        what: String,
    },
    /// Weights reused with a model whose structure changed since training.
    #[error(
        "expected the model structure the weights in `{run}` were trained with, found a \
         changed one: {}",
        changes.join("; ")
    )]
    #[diagnostic(
        code(gbm::E0416),
        help(
            "weights fit a model by its closures, embeddings, network shapes, states, inputs \
             and params; train the changed model again, or pass the model file the weights \
             came from (a copy is in the run directory as `model.gbm`)"
        )
    )]
    ModelChanged {
        /// The run directory.
        run: String,
        /// Each changed part: `part: expected ..., found ...`.
        changes: Vec<String>,
    },
    /// A run directory that cannot be read back.
    #[error("cannot read trained weights from `{path}`: {reason}")]
    #[diagnostic(
        code(gbm::E0417),
        help("pass the directory written by `gbc train -o DIR`")
    )]
    BadRun {
        /// The file.
        path: String,
        /// What is wrong.
        reason: String,
    },
    /// Validation data sampled differently from the training data.
    #[error("expected `{file}` sampled every {expected}, found a step of {found}")]
    #[diagnostic(
        code(gbm::E0418),
        help("the network steps by the training data's sampling time; resample the file")
    )]
    StepMismatch {
        /// The data file.
        file: String,
        /// Step of the training data.
        expected: f64,
        /// Step of this file.
        found: f64,
    },
    /// A bad option value.
    #[error("expected {expected} for {option}, found {found}")]
    #[diagnostic(code(gbm::E0419), help("see `gbc train --help`"))]
    BadOption {
        /// The option.
        option: String,
        /// What is allowed.
        expected: String,
        /// What was given.
        found: String,
    },
    /// A file that cannot be read.
    #[error("cannot read `{path}`: {reason}")]
    #[diagnostic(code(gbm::E0420), help("check the path and its permissions"))]
    Unreadable {
        /// The file.
        path: String,
        /// What the operating system said.
        reason: String,
    },
    /// A record without a column the model needs.
    #[error("expected a column `{column}` in `{file}`, found none")]
    #[diagnostic(
        code(gbm::E0421),
        help("a record needs `t`, every input and every measured state of the model")
    )]
    MissingColumn {
        /// The data file.
        file: String,
        /// The missing column.
        column: String,
    },
    /// `--params balances` for a model whose balances do not determine its params.
    #[error(
        "expected a model whose balances determine its params (`der` balances, no hidden \
         states, more measured states than closure outputs, at least one param), found \
         `{model}`"
    )]
    #[diagnostic(
        code(gbm::E0422),
        help("train the params with the network instead: `--params train` (or `auto`)")
    )]
    ParamsFromBalances {
        /// The model's name.
        model: String,
    },
    /// A tail split that leaves a part too small.
    #[error(
        "expected at least {needed} rows in each part of experiment `{experiment}` split by \
         --val-fraction {share}, found {train} training and {test} held-out rows"
    )]
    #[diagnostic(
        code(gbm::E0424),
        help("use a --val-fraction that leaves both parts at least {needed} rows, or hold out whole experiments")
    )]
    SplitTooSmall {
        /// The experiment.
        experiment: String,
        /// The share held out.
        share: f64,
        /// Rows each part needs.
        needed: usize,
        /// Rows that would train.
        train: usize,
        /// Rows that would be held out.
        test: usize,
    },
    /// A `next` model on data without one uniform step.
    #[error(
        "expected one uniform time step for a `next` model, found {found} in experiment \
         `{experiment}`"
    )]
    #[diagnostic(
        code(gbm::E0425),
        help(
            "a discrete map steps from row to row; on irregular data use a continuous black \
             box whose closure outputs are the derivatives (`der X = n_X`), as \
             models/bioreactor/blackbox_ode.gbm does"
        )
    )]
    IrregularForNext {
        /// The first experiment that is irregular (or sampled at another step).
        experiment: String,
        /// What its times look like, e.g. "steps from 0.2 to 4" or "a step of 2 (others 1)".
        found: String,
    },
    /// A state that an experiment never measures, with no declared initial value.
    #[error(
        "expected an initial value for state `{state}` in experiment `{experiment}`, found no \
         measured value and no declared one"
    )]
    #[diagnostic(
        code(gbm::E0426),
        help("declare one in the model (`state {state} = ...`) or measure it in the experiment")
    )]
    NoInitialValue {
        /// The state.
        state: String,
        /// The experiment.
        experiment: String,
    },
    /// An experiment shorter than the embedding's history under `--history measured`.
    #[error(
        "expected experiment `{experiment}` to span more than {needed} time units (the \
         embedding's history, with --history measured), found {found}"
    )]
    #[diagnostic(
        code(gbm::E0428),
        help(
            "drop the experiment, use a shorter embedding, or --history held (the history \
             before the first row held at the first values)"
        )
    )]
    ExperimentTooShort {
        /// The experiment.
        experiment: String,
        /// The embedding's span.
        needed: f64,
        /// The experiment's span.
        found: f64,
    },
    /// `gbc train -o DIR` onto a directory that already holds files.
    #[error("expected an empty or new run directory, found files in `{directory}`")]
    #[diagnostic(
        code(gbm::E0429),
        help("choose another -o DIR, or pass --force to replace the run in it")
    )]
    RunExists {
        /// The directory.
        directory: String,
    },
    /// Training stopped between epochs (Ctrl-C, SIGTERM or a planned stop) and left a
    /// checkpoint.
    #[error(
        "training stopped after epoch {epoch} of {epochs}; its checkpoint is in `{directory}`"
    )]
    #[diagnostic(
        code(gbm::E0430),
        help("continue where it stopped with `gbc train --resume {directory}`")
    )]
    Interrupted {
        /// Epochs done.
        epoch: usize,
        /// Epochs planned.
        epochs: usize,
        /// The run directory holding the checkpoint.
        directory: String,
    },
    /// Stopped (Ctrl-C, SIGTERM) before the first epoch of the run itself: nothing to
    /// resume.
    #[error("training was stopped while {phase}, before its first epoch")]
    #[diagnostic(
        code(gbm::E0433),
        help("nothing was trained, so there is no checkpoint to resume: run the command again")
    )]
    StoppedBefore {
        /// What it was doing.
        phase: String,
    },
    /// `gbc train --resume DIR` on a directory without a usable checkpoint.
    #[error("expected a training checkpoint in `{directory}`, found {found}")]
    #[diagnostic(
        code(gbm::E0431),
        help(
            "a run stopped by Ctrl-C, SIGTERM or --checkpoint-every holds checkpoint.json; a \
             finished run has none"
        )
    )]
    NoCheckpoint {
        /// The run directory.
        directory: String,
        /// What was there instead.
        found: String,
    },
    /// The checkpoint does not fit the training being resumed.
    #[error("expected the files and settings the checkpoint was trained with, found {what}")]
    #[diagnostic(
        code(gbm::E0432),
        help("resume with the model and data the run started with, or start a new run")
    )]
    ResumeChanged {
        /// What changed.
        what: String,
    },
    /// `gbc train --resume DIR` with other flags: a resumed run keeps the flags it was
    /// started with.
    #[error("expected no other flag with --resume, found {}", flags.join(", "))]
    #[diagnostic(
        code(gbm::E0434),
        help(
            "a resumed run continues with the flags it was started with (kept in its \
             checkpoint): pass only `--resume DIR`, or start a new run to change them"
        )
    )]
    ResumeFlags {
        /// The flags given with --resume, as spelled on the command line (`--epochs`).
        flags: Vec<String>,
    },
    /// Nothing left to train on.
    #[error("expected at least one training experiment, found none")]
    #[diagnostic(
        code(gbm::E0427),
        help("hold out fewer experiments: training needs at least one")
    )]
    NoTrainingExperiment,
    /// The network failed.
    #[error(transparent)]
    #[diagnostic(transparent)]
    Backend(#[from] BackendError),
    /// Fitting a model without closures by free runs failed.
    #[error(transparent)]
    #[diagnostic(transparent)]
    Mechanism(#[from] crate::solve::fit::FitError),
    /// Writing an artifact failed.
    #[error(transparent)]
    #[diagnostic(transparent)]
    Io(#[from] IoError),
}
