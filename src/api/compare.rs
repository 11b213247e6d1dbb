//! Comparisons (`gbc compare`): a grey box against its fitted mechanism and the naive
//! forecast on the same held-out experiments ([`crate::compare`], `docs/compare.md`).
//! [`compare`] turns a grey box, its records and a [`CompareSpec`] into a
//! [`CompareResult`] that renders itself as text, JSON and HTML.

use super::{ApiError, Model};
use crate::compare::{self, CompareError, Comparison, Event, Options, Splits};
use crate::ir;
use crate::record::Record;
use crate::train::{Recipe, TrainOptions};

/// Everything a comparison is asked for, with the defaults of `gbc compare` (its flags'
/// names are the fields' names).
#[derive(Debug, Clone)]
pub struct CompareSpec {
    /// Experiments held out; empty: the last one (said in a note).
    pub holdout: Vec<String>,
    /// Leave-one-experiment-out: each experiment held out in turn.
    pub cv: bool,
    /// Grey-box trainings per split, seeds `seed`, `seed + 1`, ...
    pub seeds: u64,
    /// The first seed (the mechanism's fit takes it too).
    pub seed: u64,
    /// Trainings at a time (default: every core).
    pub jobs: Option<usize>,
    /// Every training's options (their seed is replaced by each run's).
    pub training: TrainOptions,
    /// Recoveries from a non-finite epoch per training.
    pub recoveries: usize,
    /// The budget of a sparse record (`None` where the epochs or the learning rate were
    /// given: [`crate::train::recipe::SparseBudget`]).
    pub sparse_budget: Option<crate::train::SparseBudget>,
}

impl Default for CompareSpec {
    fn default() -> Self {
        CompareSpec {
            holdout: Vec::new(),
            cv: false,
            seeds: 3,
            seed: 1,
            jobs: None,
            training: TrainOptions::with(&crate::train::Settings::default()),
            recoveries: crate::train::recovery::DEFAULT_RECOVERIES,
            sparse_budget: Some(crate::train::recipe::SPARSE_BUDGET),
        }
    }
}

/// A finished comparison with the grey box's records (its report draws them).
pub struct CompareResult {
    /// The scores, the verdict and every run.
    pub comparison: Comparison,
    /// The records compared on.
    pub records: Vec<Record>,
    /// The grey box's short name (report title).
    pub title: String,
}

/// The mechanism a grey box is compared with: `given` (a model without closures), or the
/// grey box with every closure output at its prior, or zero.
pub fn mechanism_of(grey_box: &Model, given: Option<&Model>) -> Result<ir::Model, ApiError> {
    let ir = grey_box.ir();
    match given {
        Some(model) => Ok(model.ir().clone()),
        None if ir.closures.is_empty() => Err(ApiError::user(CompareError::NoClosure {
            model: ir.name.clone(),
        })),
        None => {
            let mut mechanism = ir.mechanism();
            mechanism.name = format!("{} (mechanism)", ir.name);
            Ok(mechanism)
        }
    }
}

/// Compares `grey_box` (trained on `records`) with `mechanism` (fitted on
/// `mechanism_records`, the same data bound to it) as `spec` asks; `on_note` hears the
/// default split, `on_event` every run's progress (from the worker threads).
pub fn compare(
    (grey_box, mechanism): (&Model, &ir::Model),
    (records, mechanism_records): (Vec<Record>, Vec<Record>),
    spec: &CompareSpec,
    on_note: &mut dyn FnMut(String),
    on_event: &(dyn Fn(Event) + Sync),
) -> Result<CompareResult, ApiError> {
    let splits = if spec.cv {
        Splits::LeaveOneOut
    } else if spec.holdout.is_empty() {
        let last = records.last().map(|r| r.name.clone()).unwrap_or_default();
        on_note(format!(
            "holding out experiment `{last}` (the last one; choose with --holdout NAME or --cv)"
        ));
        Splits::Holdout(vec![last])
    } else {
        Splits::Holdout(spec.holdout.clone())
    };
    let options = Options {
        splits,
        seeds: (0..spec.seeds).map(|k| spec.seed + k).collect(),
        training: spec.training.clone(),
        recipe: Recipe {
            sparse_budget: spec.sparse_budget,
            ..Recipe::default()
        },
        jobs: spec.jobs.unwrap_or_else(crate::experiment::default_jobs),
        recoveries: spec.recoveries,
    };
    let comparison = compare::compare(
        (grey_box.ir(), mechanism),
        (&records, &mechanism_records),
        &options,
        on_event,
    )
    .map_err(|error| ApiError::user(flagged(error)))?;
    Ok(CompareResult {
        comparison,
        records,
        title: grey_box.stem(),
    })
}

/// A training error whose option is a settings field, renamed to its flag.
fn flagged(error: CompareError) -> CompareError {
    match error {
        CompareError::Train(error) => CompareError::Train(crate::train::with_flag(error)),
        other => other,
    }
}

impl CompareResult {
    /// The table and the verdict, as `gbc compare` prints them.
    pub fn text(&self) -> String {
        compare::render::text(&self.comparison)
    }

    /// The comparison as JSON (with a final newline, as `--json` writes it).
    pub fn json(&self) -> Result<String, ApiError> {
        let json = serde_json::to_string_pretty(&self.comparison)
            .map_err(|e| ApiError::Internal(format!("cannot encode the comparison: {e}")))?;
        Ok(format!("{json}\n"))
    }

    /// The report page: the free runs drawn side by side.
    pub fn html(&self) -> String {
        compare::html::page(&self.comparison, &self.records, &self.title)
    }
}
