//! A study on a data set (records spec): every model reads the study's files with the one
//! reader ([`crate::data::read_set`]) and binds them to its own columns; the experiments
//! named in [`Validation::Holdout`] are held out and free-run whole, every other one
//! trains. A size is the first pairs over the training experiments in data-set order (as
//! `gbc train --train-points`), and every error is on the scale of the held-out
//! experiments' measured cells.

use super::prepare::LoadedModel;
use super::{ExperimentError, ExperimentFailure, Study, Validation};
use crate::data::MinRows;
use crate::ir;
use crate::numeric::mean_std;
use crate::record::Record;
use crate::train::{Part, TrainingData};

/// The experiments of one model of a study on a data set.
#[derive(Debug, Clone)]
pub struct SetSplit {
    /// The experiments that train, in data-set order.
    pub train: Vec<Record>,
    /// The held-out experiments, in data-set order.
    pub held: Vec<Record>,
}

impl SetSplit {
    /// What a run trains on: the first pairs of the training experiments (the run's size is
    /// set through the options' `train_points`), validated on the held-out experiments.
    pub fn training_data(&self) -> TrainingData<'_> {
        TrainingData {
            train: &self.train,
            validation: &self.held,
            part: Part::All,
        }
    }
}

/// Reads the study's data set for `model` and splits it by the held-out names; an unknown
/// name lists the experiments there are, and holding out every experiment is refused.
pub fn load(study: &Study, model: &ir::Model) -> Result<SetSplit, ExperimentFailure> {
    let Validation::Holdout(names) = &study.validation else {
        return Err(ExperimentFailure::Internal(
            "a data-set split asked of a study without held-out experiments".into(),
        ));
    };
    let request = crate::record::request(model, &[], MinRows::new(2, "one step needs two rows"));
    let files: Vec<std::path::PathBuf> = (study.data.paths().into_iter())
        .map(std::path::Path::to_path_buf)
        .collect();
    let data = crate::data::read_set(&files, &request)?;
    let records = crate::record::bind(model, &data)
        .map_err(|error| ExperimentFailure::User(vec![miette::Report::new(error)]))?;
    let known: Vec<&str> = records.iter().map(|r| r.name.as_str()).collect();
    for name in names {
        if !known.contains(&name.as_str()) {
            return Err(ExperimentError::BadOption {
                option: "--holdout".into(),
                expected: format!(
                    "the name of an experiment ({})",
                    crate::suggest::did_you_mean(name, &known, "experiments")
                ),
                found: name.clone(),
            }
            .into());
        }
    }
    let (held, train): (Vec<Record>, Vec<Record>) =
        records.into_iter().partition(|r| names.contains(&r.name));
    if train.is_empty() {
        return Err(ExperimentError::BadOption {
            option: "--holdout".into(),
            expected: "at least one experiment left to train".into(),
            found: format!("all {} held out", held.len()),
        }
        .into());
    }
    Ok(SetSplit { train, held })
}

/// The standard deviation of each measured state over the held-out experiments' measured
/// cells, by name (the first model that has the state decides): the common scale of every
/// error of the study.
pub fn reference_scale(models: &[LoadedModel]) -> Vec<(String, f64)> {
    let mut scale: Vec<(String, f64)> = Vec::new();
    for loaded in models {
        let Some(set) = &loaded.set else {
            continue;
        };
        for (index, state) in loaded.model.states.iter().enumerate() {
            if scale.iter().any(|(name, _)| name == &state.name) {
                continue;
            }
            let cells: Vec<f64> = (set.held.iter())
                .flat_map(|record| record.states[index].iter().flatten().copied())
                .collect();
            if cells.len() >= 2 {
                scale.push((state.name.clone(), mean_std(&cells).1));
            }
        }
    }
    scale
}

/// The training pairs a model can take from the training experiments (the largest size)
/// under the study's settings.
pub fn available_pairs(
    model: &ir::Model,
    set: &SetSplit,
    options: &crate::train::TrainOptions,
) -> Result<usize, ExperimentFailure> {
    Ok(crate::train::available_pairs(
        model,
        &set.training_data(),
        options,
    )?)
}

/// Free runs of each held-out experiment (from its first row) by the representative run of
/// every model, against the measured cells: one figure per experiment and state.
pub fn held_out_figures(
    prepared: &super::Prepared,
    trained: &[super::figures::TrainedModel],
    size: usize,
) -> Vec<super::figures::Figure> {
    use super::figures::{color, Figure, DATA_COLOR, HEIGHT, WIDTH};
    use crate::plot::{clip, thin, widened_range, Chart, Series, Style, MAX_POINTS};
    use crate::trained::predict::{predict, Mode};
    let mut figures = Vec::new();
    let Some(first) = prepared.models.iter().find_map(|m| m.set.as_ref()) else {
        return figures;
    };
    for (held, record) in first.held.iter().enumerate() {
        let states = &prepared.models[0].model.states;
        for (index, state) in states.iter().enumerate() {
            let cells: Vec<(f64, f64)> = (record.times.iter().zip(&record.states[index]))
                .filter_map(|(t, cell)| cell.map(|v| (*t, v)))
                .collect();
            if cells.is_empty() {
                continue;
            }
            let values: Vec<f64> = cells.iter().map(|(_, v)| *v).collect();
            let range = widened_range(&values);
            let title = format!(
                "{}: free run of held-out {} ({size} training points): {}",
                prepared.study.name, record.name, state.name
            );
            let (time, axis) = super::figures::axis_titles(prepared, &state.name);
            let mut chart = Chart::new(&title, &time, &axis).with(
                Series::line("data", cells)
                    .styled(Style::Markers)
                    .colored(DATA_COLOR),
            );
            for (model, network, setup, _) in trained {
                let loaded = &prepared.models[*model];
                let Some(own) = loaded.set.as_ref().and_then(|s| s.held.get(held)) else {
                    continue;
                };
                let Ok(table) = predict(
                    &loaded.model,
                    network,
                    setup,
                    own,
                    (Mode::Online, crate::train::History::Held),
                ) else {
                    continue;
                };
                let Some(column) = table.header.iter().position(|h| h == &state.name) else {
                    continue;
                };
                let points =
                    (table.columns[0].iter().copied()).zip(table.columns[column].iter().copied());
                let (label, points) = clip(&loaded.label, points, range);
                chart = chart.with(
                    Series::line(&label, thin(points, MAX_POINTS))
                        .styled(Style::Dashed)
                        .colored(color(*model)),
                );
            }
            figures.push(Figure {
                name: format!("heldout_{}_{}", file_safe(&record.name), state.name),
                caption: format!(
                    "Free run of {} over the held-out experiment {}, from its first row and \
                     driven by its inputs alone, by the median replicate of each model trained \
                     on {size} points, against its measured cells.",
                    state.name, record.name
                ),
                svg: chart.to_svg(WIDTH, HEIGHT),
            });
        }
    }
    figures
}

/// `name` with every character but letters, digits, `-` and `_` replaced by `_`.
fn file_safe(name: &str) -> String {
    (name.chars())
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}
