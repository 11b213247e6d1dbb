//! Joining results: [`publish`] writes the tables, figures and report of a set of results,
//! and [`merge`] gathers the runs of several experiment directories of one study (the
//! slices of a job array, or re-runs) and publishes them together.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::execute::claim_directory;
use super::figure::Figure;
use super::figures;
use super::prepare::{prepare, Prepared};
use super::results::{self, RunResult};
use super::{report, tables, ExperimentError, ExperimentFailure};

/// Folder of the figures inside an experiment directory.
pub const FIGURES_DIR: &str = "figures";
/// The report inside an experiment directory.
pub const REPORT_FILE: &str = "report.html";

/// What [`publish`] drew.
#[derive(Debug, Clone, PartialEq)]
pub struct Published {
    /// The figures (also written as SVG).
    pub figures: Vec<Figure>,
    /// What was left out of the figures, and why.
    pub notes: Vec<String>,
    /// The report's HTML section of this study.
    pub section: String,
}

/// Writes `results.csv`, `results.json`, `summary.csv`, `figures/*.svg` and `report.html`
/// into `dir`; `weights` finds each run's weights for the trajectory figures.
pub fn publish(
    prepared: &Prepared,
    results: &[RunResult],
    dir: &Path,
    weights: figures::WeightsLookup,
) -> Result<Published, ExperimentFailure> {
    tables::write_tables(dir, &prepared.study, results)?;
    let (figures, notes) = figures::draw(prepared, results, weights);
    figures::write_figures(&dir.join(FIGURES_DIR), &figures)?;
    let section = report::section(prepared, results, &figures, &notes);
    let title = format!("gbc experiment: {}", prepared.study.name);
    let page = report::page(&title, "", std::slice::from_ref(&section));
    crate::io::write_atomic(&dir.join(REPORT_FILE), page.as_bytes())?;
    Ok(Published {
        figures,
        notes,
        section,
    })
}

/// The weights of runs in `dir`, where present.
pub fn weights_in(dir: &Path) -> impl Fn(&str) -> Option<PathBuf> + '_ {
    move |id: &str| {
        let path = results::weights_dir(dir, id);
        path.is_dir().then_some(path)
    }
}

/// What [`merge`] joined.
#[derive(Debug)]
pub struct Merged {
    /// The study, loaded.
    pub prepared: Prepared,
    /// Every run, by id.
    pub results: Vec<RunResult>,
    /// Run files that did not read back (left out).
    pub unreadable: Vec<PathBuf>,
    /// What was published.
    pub published: Published,
}

/// Joins the runs of `dirs` (one study) and publishes them into `out`: tables, figures
/// and report. A run found in several directories is taken from the first. The merged
/// study covers the union of the sizes and the largest replicate count.
pub fn merge(dirs: &[PathBuf], out: &Path) -> Result<Merged, ExperimentFailure> {
    let mut records = Vec::new();
    for dir in dirs {
        let record =
            results::read_study_record(dir)?.ok_or_else(|| ExperimentError::NotAnExperiment {
                dir: dir.display().to_string(),
            })?;
        records.push(record);
    }
    let Some(first) = records.first() else {
        return Err(ExperimentError::BadOption {
            option: "merge".into(),
            expected: "at least one directory".into(),
            found: "none".into(),
        }
        .into());
    };
    let mut study = first.study.clone();
    for (record, dir) in records.iter().zip(dirs).skip(1) {
        if !record.same_identity(first) {
            return Err(ExperimentError::MergeMismatch {
                first: dirs[0].display().to_string(),
                other: dir.display().to_string(),
            }
            .into());
        }
        study.sizes.extend(&record.study.sizes);
        study.replicates = study.replicates.max(record.study.replicates);
    }
    study.sizes = study.sorted_sizes();
    let prepared = prepare(&study)?;
    if prepared.record.files != first.files {
        return Err(ExperimentError::StudyChanged {
            dir: dirs[0].display().to_string(),
            what: "file contents (a model or data file changed since the runs)".into(),
        }
        .into());
    }
    let mut by_id: BTreeMap<String, (RunResult, PathBuf)> = BTreeMap::new();
    let mut unreadable = Vec::new();
    for dir in dirs {
        let (found, bad) = results::read_all(dir);
        unreadable.extend(bad);
        for result in found {
            by_id
                .entry(result.id.clone())
                .or_insert((result, dir.clone()));
        }
    }
    let homes: BTreeMap<String, PathBuf> = (by_id.iter())
        .map(|(id, (_, dir))| (id.clone(), dir.clone()))
        .collect();
    let results: Vec<RunResult> = by_id.into_values().map(|(result, _)| result).collect();
    claim_directory(out, &prepared.record)?;
    let lookup = |id: &str| {
        let path = results::weights_dir(homes.get(id)?, id);
        path.is_dir().then_some(path)
    };
    let published = publish(&prepared, &results, out, &lookup)?;
    Ok(Merged {
        prepared,
        results,
        unreadable,
        published,
    })
}
