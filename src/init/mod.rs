//! `gbc init NAME [--template ...]`: a new project directory with a mechanistic model (to
//! simulate and diagnose), its grey-box twin (to train) and a README with the commands.
//!
//! The templates are `.gbm` files in `src/init/templates/`, embedded at build time; they
//! are annotated with units, check clean and are in the canonical layout (tested).

use miette::Diagnostic;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// A starting point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Template {
    /// A continuous culture on one substrate (dilution rate as input).
    Chemostat,
    /// A continuous bioreactor with product formation.
    Bioreactor,
    /// A batch culture (no input).
    Batch,
    /// A fed-batch culture with a growing volume (feed rate as input).
    Fedbatch,
}

impl Template {
    /// Every template.
    pub const ALL: [Template; 4] = [
        Template::Chemostat,
        Template::Bioreactor,
        Template::Batch,
        Template::Fedbatch,
    ];

    /// The mechanistic model and its grey-box twin, with `template` as the model name.
    pub fn sources(self) -> (&'static str, &'static str) {
        match self {
            Template::Chemostat => (
                include_str!("templates/chemostat.gbm"),
                include_str!("templates/chemostat_greybox.gbm"),
            ),
            Template::Bioreactor => (
                include_str!("templates/bioreactor.gbm"),
                include_str!("templates/bioreactor_greybox.gbm"),
            ),
            Template::Batch => (
                include_str!("templates/batch.gbm"),
                include_str!("templates/batch_greybox.gbm"),
            ),
            Template::Fedbatch => (
                include_str!("templates/fedbatch.gbm"),
                include_str!("templates/fedbatch_greybox.gbm"),
            ),
        }
    }

    /// The `--input` argument that drives a simulation, if the model has an input.
    fn input_program(self) -> Option<&'static str> {
        match self {
            Template::Chemostat => Some("D=steps(hold=10..30, seed=1)"),
            Template::Bioreactor => Some("D=steps(hold=10..30, seed=1)"),
            Template::Batch => None,
            Template::Fedbatch => Some("F=steps(hold=2..6, lo=0, hi=0.05, seed=1)"),
        }
    }

    /// Simulated time and sampling step of the example record.
    fn record(self) -> (&'static str, &'static str) {
        match self {
            Template::Chemostat | Template::Bioreactor => ("200", "0.5"),
            Template::Batch => ("30", "0.1"),
            Template::Fedbatch => ("40", "0.1"),
        }
    }
}

/// Why a project cannot be made.
#[derive(Debug, Clone, Error, Diagnostic, PartialEq)]
pub enum InitError {
    /// The directory exists and holds files.
    #[error("expected a new or empty directory, found `{path}` with files in it")]
    #[diagnostic(
        code(gbm::E1003),
        help("choose another name; gbc init never overwrites files")
    )]
    Exists {
        /// The directory.
        path: String,
    },
    /// The last part of the path cannot be a model name.
    #[error("expected a name of letters, digits and `_`, found `{name}`")]
    #[diagnostic(
        code(gbm::E1004),
        help(
            "the directory's name becomes the model's name: start with a letter, e.g. `my_culture`"
        )
    )]
    BadName {
        /// The name given.
        name: String,
    },
}

/// The files of a new project in `directory`: paths and contents.
pub fn project(directory: &Path, template: Template) -> Result<Vec<(PathBuf, String)>, InitError> {
    let name = model_name(directory)?;
    let (mechanistic, greybox) = template.sources();
    let model_file = directory.join(format!("{name}.gbm"));
    let greybox_file = directory.join(format!("{name}_greybox.gbm"));
    let readme = readme(directory, &name, template);
    Ok(vec![
        (model_file, rename(mechanistic, &name)),
        (greybox_file, rename(greybox, &name)),
        (directory.join("README.md"), readme),
    ])
}

/// The model name: the last part of the path, `-` read as `_`.
fn model_name(directory: &Path) -> Result<String, InitError> {
    let last = directory
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    let name = last.replace('-', "_");
    let valid = name
        .chars()
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        && crate::syntax::parse(&format!("model {name}\n")).is_ok();
    if valid {
        Ok(name)
    } else {
        Err(InitError::BadName { name: last })
    }
}

/// Puts `name` in place of the template's model name (`template`, `template_greybox`).
fn rename(source: &str, name: &str) -> String {
    source
        .replacen(
            "model template_greybox ",
            &format!("model {name}_greybox "),
            1,
        )
        .replacen("model template ", &format!("model {name} "), 1)
}

fn readme(directory: &Path, name: &str, template: Template) -> String {
    let dir = directory.display().to_string();
    let model = format!("{dir}/{name}.gbm");
    let greybox = format!("{dir}/{name}_greybox.gbm");
    let (t_end, dt) = template.record();
    let input = template
        .input_program()
        .map(|program| format!(" --input '{program}'"))
        .unwrap_or_default();
    format!(
        "# {name}\n\n\
         Made by `gbc init` from the `{template:?}` template. Two models:\n\n\
         - `{name}.gbm`: the mechanistic model (rate laws written out, params fitted). It\n  \
           simulates, and `gbc diagnose` compares it with data and ranks its `effect`s.\n\
         - `{name}_greybox.gbm`: the same balances with the unknown rates learned by a\n  \
           network from data (`gbc train`).\n\n\
         Every declaration carries its unit; `gbc check` verifies them. Commands, from the\n\
         directory that holds `{dir}/`:\n\n\
         ```sh\n\
         # check both models (units included)\n\
         gbc check {model} {greybox}\n\n\
         # simulate the mechanistic model: a synthetic record to start with (replace it\n\
         # with your measurements: a CSV with `t` and the inputs and measured states)\n\
         gbc simulate {model} --t-end {t_end} --dt {dt}{input} --noise 0.01 -o {dir}/data.csv\n\n\
         # where the mechanistic model misses the data, and which effect explains it\n\
         gbc diagnose {model} {dir}/data.csv\n\n\
         # learn the unknown rates from the data\n\
         gbc train {greybox} {dir}/data.csv -o {dir}/run\n\n\
         # the learned rates over time\n\
         gbc predict {greybox} {dir}/data.csv --weights {dir}/run -o {dir}/prediction.csv\n\n\
         # keep the files in the canonical layout\n\
         gbc fmt {dir}/\n\
         ```\n\n\
         See `docs/language.md` for the language and `gbc explain CODE` for any diagnostic.\n"
    )
}

#[cfg(test)]
mod tests;
