//! What an experiment is: the models, the data and its validation split, the grid of
//! training sizes and replicates, and the training settings ([`Study`]), as plain data that
//! reads from and writes to JSON (`experiments/*.json`, `DIR/study.json`). The paper's two
//! studies are built in ([`Study::chemostat`], [`Study::bioreactor`]).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use miette::{NamedSource, SourceSpan};

use super::ExperimentError;
use crate::train::{Recipe, Settings};

/// One model of a study.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StudyModel {
    /// Short name used in run ids, tables and legends (letters, digits, `_`, `-`).
    pub label: String,
    /// The `.gbm` file.
    pub path: PathBuf,
}

/// Which rows validate.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Validation {
    /// Rows before `ROW` train; the rows from `ROW` to the end validate, each model reading
    /// its embedding history from the rows just before `ROW` (so the first validated step
    /// starts at row `ROW` and no training target is ever validated).
    FromRow(usize),
    /// Every row of the training file may train; this whole file validates.
    File(PathBuf),
    /// The study runs on a data set (records spec): the experiments named here (file
    /// stems or values of the experiment column) are held out and free-run whole; every
    /// other experiment trains, its first pairs in data-set order making up a size.
    Holdout(Vec<String>),
}

/// The training data of a study: one record, or the files of a data set.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(untagged)]
pub enum DataFiles {
    /// One CSV file (written as a string: the paper's studies).
    One(PathBuf),
    /// Several files read as one data set (written as a list).
    Many(Vec<PathBuf>),
}

impl DataFiles {
    /// The files, in order.
    pub fn paths(&self) -> Vec<&Path> {
        match self {
            DataFiles::One(path) => vec![path.as_path()],
            DataFiles::Many(paths) => paths.iter().map(PathBuf::as_path).collect(),
        }
    }

    /// The files for messages and reports, comma-separated.
    pub fn describe(&self) -> String {
        let names: Vec<String> = (self.paths().iter())
            .map(|p| p.display().to_string())
            .collect();
        names.join(", ")
    }

    /// One file as [`DataFiles::One`], several as [`DataFiles::Many`].
    pub fn from_paths(mut paths: Vec<PathBuf>) -> DataFiles {
        if paths.len() == 1 {
            DataFiles::One(paths.remove(0))
        } else {
            DataFiles::Many(paths)
        }
    }
}

impl From<PathBuf> for DataFiles {
    fn from(path: PathBuf) -> Self {
        DataFiles::One(path)
    }
}

/// How every run of a study trains.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Training {
    /// The paper's: the one-step loss every epoch, one learning rate, no polish of the params
    /// ([`Recipe::paper`]).
    #[default]
    Paper,
    /// gbc's default recipe: one-step epochs, then free-run rollouts of growing length, the
    /// params polished at the end ([`Recipe::default`]).
    MultiStep,
}

impl Training {
    /// The training recipe.
    pub fn recipe(self) -> Recipe {
        match self {
            Training::Paper => Recipe::paper(),
            Training::MultiStep => Recipe::default(),
        }
    }

    /// The name in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Training::Paper => "paper",
            Training::MultiStep => "multi-step",
        }
    }
}

/// A grid of training runs: every model x training size x replicate.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Study {
    /// Name (file and section names).
    pub name: String,
    /// One line saying what it reproduces.
    #[serde(default)]
    pub title: String,
    /// The models, in legend order.
    pub models: Vec<StudyModel>,
    /// The training record, or the files of a data set (with [`Validation::Holdout`]).
    pub data: DataFiles,
    /// The validation split.
    pub validation: Validation,
    /// Training sizes (number of training pairs, the first ones of the record).
    pub sizes: Vec<usize>,
    /// Replicates per model and size; replicate `r` trains with seed `first_seed + r`.
    pub replicates: usize,
    /// Seed of replicate 0.
    #[serde(default = "default_first_seed")]
    pub first_seed: u64,
    /// The training settings shared with `gbc train` (epochs, batch size, learning rate,
    /// precision, sub-steps, engine), flattened into the file; each left out takes the
    /// default of [`Settings`].
    #[serde(flatten)]
    pub settings: Settings,
    /// The training recipe (default: the paper's).
    #[serde(default)]
    pub training: Training,
    /// The mechanistic model that made the data: true closure values (its outputs named
    /// `<output>_true` or its lets named `<output>`) and true param values (its consts).
    #[serde(default)]
    pub truth: Option<PathBuf>,
    /// Records never trained on, for free runs under other inputs (paper Fig. 2d).
    #[serde(default)]
    pub generalisation: Vec<PathBuf>,
    /// Training size of the trajectory, closure and param figures (default: the size
    /// closest to 500, the paper's choice).
    #[serde(default)]
    pub representative_size: Option<usize>,
}

fn default_first_seed() -> u64 {
    1
}
/// The size the paper shows trajectories for.
pub const PAPER_REPRESENTATIVE_SIZE: usize = 500;

impl Study {
    /// The paper's chemostat study (section 3.1, Fig. 2) at full scale: grey-box, the
    /// paper's black box and the residual black box; 100 epochs; 20 replicates; up to 1500
    /// training points; the chirp record for generalisation.
    pub fn chemostat() -> Study {
        let dir = Path::new("models/mm_chemostat");
        Study {
            name: "chemostat".into(),
            title: "Chemostat with one enzyme reaction (paper section 3.1, Fig. 2)".into(),
            models: models(dir, &["greybox", "blackbox", "blackbox_residual"]),
            data: dir.join("data/steps.csv").into(),
            validation: Validation::FromRow(1550),
            sizes: vec![100, 200, 500, 1000, 1500],
            replicates: 20,
            first_seed: 1,
            settings: Settings::default(),
            training: Training::Paper,
            truth: Some(dir.join("truth.gbm")),
            generalisation: vec![dir.join("data/chirp.csv")],
            representative_size: Some(PAPER_REPRESENTATIVE_SIZE),
        }
    }

    /// The paper's bioreactor study (section 3.2, Fig. 3) at full scale: GB1, GB2, the
    /// paper's black box and the residual black box; 1000 epochs; 10 replicates; up to 2000
    /// training points; a second record under other light steps for generalisation.
    pub fn bioreactor() -> Study {
        let dir = Path::new("models/bioreactor");
        Study {
            name: "bioreactor".into(),
            title: "Light-controlled bioreactor (paper section 3.2, Fig. 3)".into(),
            models: models(dir, &["gb1", "gb2", "blackbox", "blackbox_residual"]),
            data: dir.join("data/steps.csv").into(),
            validation: Validation::FromRow(2100),
            sizes: vec![100, 200, 500, 1000, 2000],
            replicates: 10,
            first_seed: 1,
            settings: Settings {
                epochs: 1000,
                ..Settings::default()
            },
            training: Training::Paper,
            truth: Some(dir.join("truth.gbm")),
            generalisation: vec![dir.join("data/steps_seed2.csv")],
            representative_size: Some(PAPER_REPRESENTATIVE_SIZE),
        }
    }

    /// The chemostat study scaled down for `gbc demo`: 3 replicates instead of 20.
    pub fn chemostat_demo() -> Study {
        Study {
            replicates: 3,
            ..Study::chemostat()
        }
    }

    /// The bioreactor study scaled down for `gbc demo`: 3 replicates instead of 10 and 300
    /// epochs instead of 1000.
    pub fn bioreactor_demo() -> Study {
        let full = Study::bioreactor();
        Study {
            replicates: 3,
            settings: Settings {
                epochs: 300,
                ..full.settings
            },
            ..full
        }
    }

    /// The studies of `gbc demo`: both scaled-down studies with gbc's default recipe, then
    /// both with the paper's recipe (named `<study>-paper`).
    pub fn demo_studies() -> Vec<Study> {
        let base = [Study::chemostat_demo(), Study::bioreactor_demo()];
        let default = base.iter().map(|study| Study {
            title: format!("{} — gbc's default recipe", study.title),
            training: Training::MultiStep,
            ..study.clone()
        });
        let paper = base.iter().map(|study| Study {
            name: format!("{}-paper", study.name),
            title: format!("{} — the paper's recipe", study.title),
            training: Training::Paper,
            ..study.clone()
        });
        default.chain(paper).collect()
    }

    /// Every file the study reads, in the order of [`StudyRecord`](super::StudyRecord)'s
    /// fingerprints.
    pub fn files(&self) -> Vec<&Path> {
        let mut paths: Vec<&Path> = self.models.iter().map(|m| m.path.as_path()).collect();
        paths.extend(self.data.paths());
        if let Validation::File(path) = &self.validation {
            paths.push(path);
        }
        paths.extend(self.truth.as_deref());
        paths.extend(self.generalisation.iter().map(PathBuf::as_path));
        paths
    }

    /// A built-in study by name (`chemostat`, `bioreactor`).
    pub fn preset(name: &str) -> Option<Study> {
        match name {
            "chemostat" => Some(Study::chemostat()),
            "bioreactor" => Some(Study::bioreactor()),
            _ => None,
        }
    }

    /// Names of the built-in studies.
    pub const PRESETS: [&str; 2] = ["chemostat", "bioreactor"];

    /// Reads a study from a JSON file; errors point into the file.
    pub fn load(path: &Path) -> Result<Study, ExperimentError> {
        let text = std::fs::read_to_string(path)
            .map_err(|error| ExperimentError::unreadable_study(path, &error))?;
        Study::parse(&path.display().to_string(), &text)
    }

    /// Parses a study from JSON text named `name` in messages, and checks it.
    pub fn parse(name: &str, text: &str) -> Result<Study, ExperimentError> {
        refuse_unknown_fields(name, text)?;
        let study: Study = serde_json::from_str(text).map_err(|error| {
            let offset = byte_offset(text, error.line(), error.column());
            ExperimentError::BadStudy {
                path: name.to_string(),
                reason: error.to_string(),
                source_code: Some(Arc::new(NamedSource::new(name, text.to_string()))),
                span: Some(SourceSpan::from((offset, 0))),
            }
        })?;
        study.check()?;
        Ok(study)
    }

    /// The study as pretty JSON.
    pub fn to_json(&self) -> String {
        // A plain struct of strings, numbers and vectors always serialises.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// Checks the settings that need no file: labels, sizes, counts.
    pub fn check(&self) -> Result<(), ExperimentError> {
        let bad = |option: &str, expected: &str, found: String| {
            Err(ExperimentError::BadOption {
                option: option.into(),
                expected: expected.into(),
                found,
            })
        };
        if self.models.is_empty() {
            return bad("models", "at least one model", "none".into());
        }
        for (index, model) in self.models.iter().enumerate() {
            if !valid_label(&model.label) {
                let expected = "a label of letters, digits, `_` and `-`";
                return bad("models", expected, format!("`{}`", model.label));
            }
            if self.models[..index].iter().any(|m| m.label == model.label) {
                let expected = "distinct model labels";
                return bad("models", expected, format!("`{}` twice", model.label));
            }
        }
        if self.sizes.is_empty() || self.sizes.contains(&0) {
            return bad(
                "sizes",
                "positive training sizes",
                format!("{:?}", self.sizes),
            );
        }
        if self.replicates == 0 {
            return bad("replicates", "at least one replicate", "0".into());
        }
        if self.settings.epochs == 0 {
            return bad("epochs", "at least one epoch", "0".into());
        }
        if let Err(setting) = self.settings.check() {
            return bad(setting.field, setting.expected, setting.found);
        }
        if let Validation::FromRow(0) = self.validation {
            return bad("validation", "a row after the first", "0".into());
        }
        match (&self.validation, &self.data) {
            (Validation::Holdout(names), _) if names.is_empty() => {
                return bad("--holdout", "the name of an experiment", "none".into());
            }
            (Validation::Holdout(_), _) if !self.generalisation.is_empty() => {
                let expected = "no --generalisation record on a data set (hold the \
                                experiment out with --holdout instead)";
                return bad(
                    "--generalisation",
                    expected,
                    self.generalisation.len().to_string(),
                );
            }
            (Validation::FromRow(_) | Validation::File(_), DataFiles::Many(paths)) => {
                let expected = "one training record, or --holdout NAME to validate on whole \
                                experiments of a data set";
                return bad("--data", expected, format!("{} files", paths.len()));
            }
            _ => {}
        }
        Ok(())
    }

    /// Whether the study runs on a data set of experiments (held-out validation).
    pub fn on_data_set(&self) -> bool {
        matches!(self.validation, Validation::Holdout(_))
    }

    /// The size the trajectory, closure and param figures show: the representative size if
    /// it is in the grid, else the grid's size closest to it (by ratio).
    pub fn figure_size(&self) -> usize {
        let wanted = self
            .representative_size
            .unwrap_or(PAPER_REPRESENTATIVE_SIZE) as f64;
        let distance = |size: &&usize| ((**size as f64) / wanted).ln().abs();
        let mut sizes: Vec<&usize> = self.sizes.iter().collect();
        sizes.sort_by(|a, b| distance(a).total_cmp(&distance(b)).then(a.cmp(b)));
        sizes
            .first()
            .map_or(PAPER_REPRESENTATIVE_SIZE, |size| **size)
    }

    /// Sizes in increasing order without repeats.
    pub fn sorted_sizes(&self) -> Vec<usize> {
        let mut sizes = self.sizes.clone();
        sizes.sort_unstable();
        sizes.dedup();
        sizes
    }

    /// The part of the study that decides what a run computes: everything but the grid's
    /// extent (sizes, replicates) and the presentation (title, representative size). Runs
    /// are reused only between studies with the same identity.
    pub fn identity(&self) -> Study {
        Study {
            title: String::new(),
            sizes: Vec::new(),
            replicates: 0,
            representative_size: None,
            ..self.clone()
        }
    }
}

/// The models of a preset: `dir/<name>.gbm`, labelled by name.
fn models(dir: &Path, names: &[&str]) -> Vec<StudyModel> {
    (names.iter())
        .map(|name| StudyModel {
            label: name.to_string(),
            path: dir.join(format!("{name}.gbm")),
        })
        .collect()
}

/// Whether a label is safe inside file names and run ids.
pub fn valid_label(label: &str) -> bool {
    !label.is_empty() && (label.chars()).all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

/// Refuses a top-level key of the file that names no field of [`Study`] (serde cannot deny
/// unknown fields next to the flattened [`Settings`]): a study written out holds every
/// field, so a key it lacks is unknown.
fn refuse_unknown_fields(name: &str, text: &str) -> Result<(), ExperimentError> {
    let written = serde_json::to_value(Study::chemostat()).unwrap_or_default();
    let read: serde_json::Value = serde_json::from_str(text).unwrap_or_default();
    let (Some(written), Some(read)) = (written.as_object(), read.as_object()) else {
        return Ok(());
    };
    let Some(unknown) = read.keys().find(|key| !written.contains_key(*key)) else {
        return Ok(());
    };
    let mut known: Vec<&str> = written.keys().map(String::as_str).collect();
    known.sort_unstable();
    let offset = text.find(&format!("\"{unknown}\"")).unwrap_or(0);
    Err(ExperimentError::BadStudy {
        path: name.to_string(),
        reason: format!(
            "unknown field `{unknown}`, {}",
            crate::suggest::did_you_mean(unknown, &known, "fields")
        ),
        source_code: Some(Arc::new(NamedSource::new(name, text.to_string()))),
        span: Some(SourceSpan::from((offset, unknown.len() + 2))),
    })
}

/// Byte offset of a 1-based line and column in `text` (clamped to its length).
fn byte_offset(text: &str, line: usize, column: usize) -> usize {
    let line_start: usize = (text.split_inclusive('\n'))
        .take(line.saturating_sub(1))
        .map(str::len)
        .sum();
    (line_start + column.saturating_sub(1)).min(text.len())
}

/// Parses `--model [LABEL=]PATH`: the label defaults to the file stem.
pub fn parse_model_argument(argument: &str) -> Result<StudyModel, ExperimentError> {
    let (label, path) = match argument.split_once('=') {
        Some((label, path)) => (label.to_string(), PathBuf::from(path)),
        None => {
            let path = PathBuf::from(argument);
            let stem = (path.file_stem()).map_or(String::new(), |s| s.to_string_lossy().into());
            (stem, path)
        }
    };
    if !valid_label(&label) {
        return Err(ExperimentError::BadOption {
            option: "--model".into(),
            expected: "`LABEL=PATH` or `PATH` with a label of letters, digits, `_` and `-`".into(),
            found: format!("`{argument}`"),
        });
    }
    Ok(StudyModel { label, path })
}

/// Parses a comma-separated list of training sizes, e.g. `100,200,500`.
pub fn parse_sizes(text: &str) -> Result<Vec<usize>, ExperimentError> {
    (text.split(','))
        .map(|item| {
            let item = item.trim();
            item.parse::<usize>()
                .ok()
                .filter(|size| *size > 0)
                .ok_or_else(|| ExperimentError::BadOption {
                    option: "--sizes".into(),
                    expected: "comma-separated positive whole numbers, e.g. `100,200,500`".into(),
                    found: format!("`{item}`"),
                })
        })
        .collect()
}
