//! A run read back from its directory (`gbc train -o DIR`, or `--ensemble N`): predictions
//! along records ([`SavedRun::predict`], `gbc predict`) and the one-step map as an ONNX file
//! ([`export`], `gbc export`).
//!
//! The model is matched to the weights by its structure: a model whose comments, consts or
//! balances changed is used with notes saying what changed; one whose structure changed is
//! refused (E0416). Offline rows are one-step predictions from the true history; online rows
//! come from one free run driven by the data's inputs (see [`crate::trained::predict`]). A free
//! run that leaves the physical range of the training data stops before the offending row,
//! with a warning saying where and why. An ensemble run gives the members' median of every
//! column and, for free runs, the calibrated band of each measured state (`X_lo`, `X_hi`)
//! with its coverage of the data's measured cells.

use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use super::{ApiError, Model};
use crate::engine::graph::Precision;
use crate::ensemble::{self, CellCount, Loaded};
use crate::record::Record;
use crate::train::History;
use crate::trained::artifacts::{self, Restored};
use crate::trained::predict::{self, Mode};

/// A trained run read back for a model: one network, or an ensemble's members.
pub struct SavedRun {
    model: Model,
    weights: Weights,
}

/// What a run directory holds.
enum Weights {
    /// One trained network.
    Single(Box<Restored>),
    /// An ensemble: its members' directories and its calibration.
    Ensemble(Box<Loaded>),
}

/// How predictions are made (`gbc predict`'s flags).
#[derive(Debug, Clone, PartialEq)]
pub struct PredictSpec {
    /// Offline (one step from the measured history) or online (free runs).
    pub mode: Mode,
    /// Where each experiment's run starts.
    pub history: History,
    /// The level of an ensemble's prediction band.
    pub band: f64,
    /// Members of an ensemble predicting at once (default: the number of cores).
    pub jobs: Option<usize>,
}

impl Default for PredictSpec {
    fn default() -> Self {
        PredictSpec {
            mode: Mode::Offline,
            history: History::Held,
            band: ensemble::DEFAULT_LEVEL,
            jobs: None,
        }
    }
}

/// What a prediction tells its caller while it runs (from the members' threads too).
#[derive(Debug, Clone, PartialEq)]
pub enum PredictEvent {
    /// Something the user should know that changes nothing.
    Note(String),
    /// A free run stopped early (it left the physical range), or a member's did.
    Warning(String),
    /// Experiments to predict.
    Started {
        /// How many.
        experiments: usize,
    },
    /// One experiment predicted.
    Experiment {
        /// Its name.
        name: String,
    },
    /// The members of an ensemble start predicting.
    Members {
        /// Members that predict.
        members: usize,
        /// At once.
        jobs: usize,
    },
    /// One more member is done.
    MemberDone {
        /// Members done.
        done: usize,
        /// Members in all.
        members: usize,
    },
    /// Every experiment is predicted.
    Finished,
}

/// Predictions of a data set: a table with one row per predicted data row, each labelled
/// with its experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct Predictions {
    /// Column names (`t`, states, closure outputs, outputs; an ensemble's band columns).
    pub header: Vec<String>,
    /// Columns, one value per row.
    pub columns: Vec<Vec<f64>>,
    /// The experiment of each row.
    pub experiments: Vec<String>,
    /// Experiments predicted (the table is labelled when there are several).
    pub count: usize,
    /// An ensemble's band: its level and, per state, the measured cells inside it.
    pub coverage: Option<(f64, Vec<CellCount>)>,
}

impl SavedRun {
    /// Reads the run (or ensemble) in `directory` for `model`.
    pub fn load(model: &Model, directory: &Path) -> Result<SavedRun, ApiError> {
        let weights = if ensemble::is_ensemble(directory) {
            let loaded = ensemble::load(model.ir(), &model.source, directory);
            Weights::Ensemble(Box::new(loaded.map_err(ApiError::user)?))
        } else {
            let restored = artifacts::restore_with_notes(model.ir(), &model.source, directory)?;
            Weights::Single(Box::new(restored))
        };
        Ok(SavedRun {
            model: model.clone(),
            weights,
        })
    }

    /// Reads the single run in `directory` for `model`, never as an ensemble (what
    /// [`SavedRun::export`] needs).
    pub fn load_single(model: &Model, directory: &Path) -> Result<SavedRun, ApiError> {
        let restored = artifacts::restore_with_notes(model.ir(), &model.source, directory)?;
        Ok(SavedRun {
            model: model.clone(),
            weights: Weights::Single(Box::new(restored)),
        })
    }

    /// How the model differs from the one trained, outside its structure.
    pub fn notes(&self) -> &[String] {
        match &self.weights {
            Weights::Single(restored) => &restored.notes,
            Weights::Ensemble(loaded) => &loaded.notes,
        }
    }

    /// The model the run is read for.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// Whether the run is an ensemble.
    pub fn is_ensemble(&self) -> bool {
        matches!(self.weights, Weights::Ensemble(_))
    }

    /// Predicts along each of `records` as `spec` asks; `on_event` hears warnings and
    /// progress.
    pub fn predict(
        &self,
        records: &[Record],
        spec: &PredictSpec,
        on_event: &(dyn Fn(PredictEvent) + Sync),
    ) -> Result<Predictions, ApiError> {
        match &self.weights {
            Weights::Single(restored) => self.predict_single(restored, records, spec, on_event),
            Weights::Ensemble(loaded) => self.predict_ensemble(loaded, records, spec, on_event),
        }
    }

    /// One network's predictions, experiment by experiment.
    fn predict_single(
        &self,
        restored: &Restored,
        records: &[Record],
        spec: &PredictSpec,
        on_event: &(dyn Fn(PredictEvent) + Sync),
    ) -> Result<Predictions, ApiError> {
        let range = restored.info.physical_range();
        let mut predictions = Predictions::new(records.len());
        on_event(PredictEvent::Started {
            experiments: records.len(),
        });
        for record in records {
            let how = (spec.mode, spec.history, range.as_ref());
            let network = (&restored.network, &restored.setup);
            let mut table =
                predict::predict_in_range(self.model.ir(), network.0, network.1, record, how)?;
            if let Some(divergence) = &table.divergence {
                on_event(PredictEvent::Warning(format!(
                    "{divergence}; the predictions stop before it"
                )));
            }
            table.cut_at_divergence();
            on_event(PredictEvent::Experiment {
                name: record.name.clone(),
            });
            predictions.append(&record.name, table.header, table.columns);
        }
        on_event(PredictEvent::Finished);
        Ok(predictions)
    }

    /// An ensemble's predictions: every member along every record, then the median and
    /// the band per record.
    fn predict_ensemble(
        &self,
        loaded: &Loaded,
        records: &[Record],
        spec: &PredictSpec,
        on_event: &(dyn Fn(PredictEvent) + Sync),
    ) -> Result<Predictions, ApiError> {
        let (model, source) = (self.model.ir(), self.model.source.as_str());
        let level = ensemble::check_level(spec.band).map_err(ApiError::user)?;
        let calibration = &loaded.info.calibration;
        let banded = spec.mode == Mode::Online && calibration.calibrated;
        if spec.mode != Mode::Online {
            on_event(PredictEvent::Note(
                "the band is calibrated for free runs (--mode online): these are the \
                 members' median predictions alone"
                    .into(),
            ));
        } else if let Some(reason) = &calibration.reason {
            on_event(PredictEvent::Note(format!(
                "the ensemble's band is not calibrated ({reason}): the members' median alone"
            )));
        }
        let members = loaded.members.len();
        let jobs = spec
            .jobs
            .unwrap_or_else(crate::experiment::default_jobs)
            .max(1);
        on_event(PredictEvent::Members { members, jobs });
        let done = AtomicUsize::new(0);
        let on_member = |_member: usize| {
            let done = done.fetch_add(1, Ordering::Relaxed) + 1;
            on_event(PredictEvent::MemberDone { done, members });
        };
        let how = (spec.mode, spec.history, jobs);
        let tables =
            ensemble::predict::member_tables(model, (source, loaded), records, how, &on_member)
                .map_err(ApiError::user)?;
        let mut predictions = Predictions::new(records.len());
        let mut coverage: Vec<CellCount> = Vec::new();
        for (index, record) in records.iter().enumerate() {
            let mine: Vec<_> = tables.iter().map(|m| m[index].clone()).collect();
            let how = (record, mine.as_slice());
            let combined =
                ensemble::predict_table(model, &loaded.info, how, banded.then_some(level))
                    .map_err(ApiError::user)?;
            for stopped in &combined.stopped {
                on_event(PredictEvent::Warning(format!(
                    "{stopped}; its free run stops there"
                )));
            }
            if let Some(time) = combined.ended {
                on_event(PredictEvent::Warning(format!(
                    "{}: fewer than half the members run from t = {time}: the predictions stop before it",
                    record.name
                )));
            }
            add_counts(&mut coverage, &combined.coverage);
            let table = combined.table;
            predictions.append(&record.name, table.header, table.columns);
        }
        predictions.coverage = Some((level, coverage));
        Ok(predictions)
    }

    /// The one-step map of a single run as a file of `format` (see `docs/export.md`).
    pub fn export(&self, format: ExportFormat, precision: Precision) -> Result<Export, ApiError> {
        let Weights::Single(restored) = &self.weights else {
            return Err(ApiError::Internal(
                "an ensemble is exported member by member (`SavedRun::load_single`)".into(),
            ));
        };
        let exported = match format {
            ExportFormat::Onnx => crate::export::onnx(
                self.model.ir(),
                &restored.network,
                &restored.setup,
                precision,
            ),
        };
        exported.map(Export).map_err(|error| match error {
            crate::export::ExportError::Internal(message) => ApiError::Internal(message),
            not_finite => ApiError::user(not_finite),
        })
    }
}

/// Adds one experiment's counts to the totals, state by state.
fn add_counts(totals: &mut Vec<CellCount>, counts: &[CellCount]) {
    for count in counts {
        match totals.iter_mut().find(|t| t.state == count.state) {
            Some(total) => total.add(count),
            None => totals.push(count.clone()),
        }
    }
}

impl Predictions {
    /// An empty table for `count` experiments.
    fn new(count: usize) -> Predictions {
        Predictions {
            header: Vec::new(),
            columns: Vec::new(),
            experiments: Vec::new(),
            count,
            coverage: None,
        }
    }

    /// Appends one experiment's rows.
    fn append(&mut self, experiment: &str, header: Vec<String>, columns: Vec<Vec<f64>>) {
        let rows = columns.first().map_or(0, Vec::len);
        (self.experiments).extend(std::iter::repeat_n(experiment.to_string(), rows));
        if self.columns.is_empty() {
            (self.header, self.columns) = (header, columns);
        } else {
            for (all, part) in self.columns.iter_mut().zip(columns) {
                all.extend(part);
            }
        }
    }

    /// Writes the table as CSV (an `experiment` column first when there are several;
    /// atomically; a value that is not finite is refused, naming where, E0253).
    pub fn write_csv(&self, path: &Path) -> Result<(), ApiError> {
        let labels = (self.count > 1).then_some(("experiment", self.experiments.as_slice()));
        crate::data::write_table(path, labels, &self.header, &self.columns).map_err(ApiError::user)
    }

    /// An ensemble band's coverage of the data's measured cells, overall then per state
    /// (empty without a band or without measured cells).
    pub fn coverage_text(&self) -> String {
        let Some((level, coverage)) = &self.coverage else {
            return String::new();
        };
        let mut overall = CellCount::new("all");
        coverage.iter().for_each(|c| overall.add(c));
        if overall.cells == 0 {
            return String::new();
        }
        let share =
            |c: &CellCount| format!("{} of {} ({:.1} %)", c.inside, c.cells, 100.0 * c.share());
        let mut text = format!(
            "the {} % band holds {} measured cells after each free run's start\n",
            crate::plot::tick_label(100.0 * level),
            share(&overall)
        );
        for count in coverage {
            text.push_str(&format!("  {:<12} {}\n", count.state, share(count)));
        }
        text
    }
}

/// The one-step map of every used member of the ensemble run in `directory` (trained with
/// `model`), each to be written beside `output`, with the band's facts (`NAME.band.json`,
/// docs/export.md); nothing is written until [`EnsembleExport::write`].
pub fn export_ensemble(
    model: &Model,
    directory: &Path,
    precision: Precision,
    output: &Path,
) -> Result<crate::export::ensemble::EnsembleExport, ApiError> {
    let (ir, source) = (model.ir(), &model.source);
    crate::export::ensemble::export(ir, source, directory, precision, output)
        .map_err(ApiError::user)
}

/// The file formats a run exports to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportFormat {
    /// ONNX (IR version 8, opset 17): onnxruntime, tract, MATLAB, CasADi, ...
    Onnx,
}

/// An exported one-step map: the file's bytes and what it holds.
pub struct Export(pub crate::export::Exported);

impl Export {
    /// Writes the file to `path` (atomically).
    pub fn write(&self, path: &Path) -> Result<(), ApiError> {
        crate::io::write_atomic(path, &self.0.bytes).map_err(ApiError::user)
    }

    /// What the file holds, in words: the step, the window and every tensor with its
    /// columns (one line each).
    pub fn layout_text(&self, path: &Path) -> String {
        let layout = &self.0.layout;
        let columns = |names: &[String]| names.join(", ");
        let mut lines = vec![format!(
            "wrote {}: one step of {} ({} RK4 sub-steps) from a window of {} knots",
            path.display(),
            layout.step,
            layout.substeps,
            layout.window
        )];
        let window = layout.window;
        lines.push(format!(
            "  state_window [batch, {window}, {}]: {}",
            layout.states.len(),
            columns(&layout.states)
        ));
        if !layout.inputs.is_empty() {
            lines.push(format!(
                "  input_window [batch, {window}, {}]: {}",
                layout.inputs.len(),
                columns(&layout.inputs)
            ));
        }
        if !layout.hidden.is_empty() {
            let hidden = &layout.hidden;
            lines.push(format!(
                "  hidden [batch, {}]: {}",
                hidden.len(),
                columns(hidden)
            ));
        }
        lines.push(format!("  -> next_state [batch, {}]", layout.states.len()));
        for (name, list) in [
            ("next_hidden", &layout.hidden),
            ("closure_outputs", &layout.closure_outputs),
            ("outputs", &layout.outputs),
        ] {
            if !list.is_empty() {
                lines.push(format!(
                    "  -> {name} [batch, {}]: {}",
                    list.len(),
                    columns(list)
                ));
            }
        }
        lines.iter().map(|line| format!("{line}\n")).collect()
    }
}
