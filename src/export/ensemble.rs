//! `gbc export` of an ensemble run (`gbc train --ensemble N`): every used member's
//! one-step map as its own ONNX file, and the band's facts in a companion JSON: the
//! members, each measured state's noise (with its floor), the calibration scores and the
//! calibrated factors. From them a controller computes the median and the band exactly as
//! `gbc predict` does (the recipe is [`RECIPE`] and `docs/export.md`, "Ensembles").
//!
//! For `-o gb.onnx` the files are `gb.member-01.onnx`, ... (one per used member, in member
//! order) and `gb.band.json`.

use std::path::{Path, PathBuf};

use crate::engine::graph::Precision;
use crate::ensemble::{self, Coverage, EnsembleError, StateNoise};
use crate::ir;
use crate::trained::artifacts;

use super::{ExportError, Exported, Layout};

/// The levels the companion file gives a factor for (besides the scores, from which any
/// level's factor follows).
pub const LEVELS: [f64; 5] = [0.5, 0.8, 0.9, 0.95, 0.99];

/// How the band is computed from the companion file, in words (the file's `recipe`).
pub const RECIPE: &str = "Step every member's ONNX map along the same inputs from the same \
     start (docs/export.md). At each knot and measured state, with the members' predictions \
     p_1..p_N: the median m is their median (the mean of the two middle ones for even N); \
     sigma_k = sqrt(absolute^2 + (relative p_k)^2); F(y) = (1/N) sum_k Phi((y - p_k) / \
     sigma_k), and, for a state with a floor, F(y) = 0 below the floor (the measurement is \
     censored there); lower = F^-1((1 - base_level) / 2), upper = F^-1((1 + base_level) / 2) \
     (the smallest y with F(y) >= q, so at least the floor); below = max(m - lower, 0), \
     above = max(upper - m, 0); with the state's factor c at the level, lo = m - c below and \
     hi = m + c above, each raised to the floor if the state has one. The factor at level L \
     is the ceil((n + 1) L)-th smallest of the state's n scores (no band where that exceeds \
     n or is infinite).";

/// The companion JSON (`NAME.band.json`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BandFile {
    /// Version of gbc that exported it.
    pub gbc_version: String,
    /// The model's name.
    pub model: String,
    /// How to compute the median and the band from this file, in words.
    pub recipe: String,
    /// Whether the band is calibrated (without out-of-bag experiments it is not, and no
    /// factor is given: the median alone).
    pub calibrated: bool,
    /// Why not, when it is not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// The used members, in the order `gbc predict` takes them.
    pub members: Vec<MemberFile>,
    /// The level of the base band the factors stretch.
    #[serde(with = "crate::json")]
    pub base_level: f64,
    /// The level `factor` is given at (the default band's).
    #[serde(with = "crate::json")]
    pub level: f64,
    /// Per measured state, in the ONNX files' column order.
    pub states: Vec<StateBand>,
    /// The held-out coverage measured when the ensemble was trained.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coverage: Option<Coverage>,
}

/// One member in the companion file.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MemberFile {
    /// 1-based, as in `ensemble.json`.
    pub index: usize,
    /// Its training seed.
    pub seed: u64,
    /// Its ONNX file, relative to the companion file's directory.
    pub onnx: String,
}

/// The band's facts of one measured state.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StateBand {
    /// The state.
    pub state: String,
    /// Its noise: `absolute`, `relative`, where it comes from, and its `floor` if any.
    pub noise: StateNoise,
    /// The factor at [`BandFile::level`] (`null`: no band at that level).
    #[serde(with = "crate::json")]
    pub factor: Option<f64>,
    /// The factor at each of [`LEVELS`], as `[level, factor]`.
    #[serde(with = "crate::json")]
    pub factors: Vec<(f64, Option<f64>)>,
    /// The calibration scores, ascending (empty when not calibrated).
    #[serde(with = "crate::json")]
    pub scores: Vec<f64>,
}

/// What an ensemble export writes: the members' files and the companion file.
#[derive(Debug, Clone, PartialEq)]
pub struct EnsembleExport {
    /// Each used member's path and exported map.
    pub members: Vec<(PathBuf, Exported)>,
    /// The companion file's path.
    pub band_path: PathBuf,
    /// Its content.
    pub band: BandFile,
}

/// Why an ensemble cannot be exported.
#[derive(Debug, thiserror::Error, miette::Diagnostic)]
pub enum EnsembleExportError {
    /// The ensemble or a member does not read back.
    #[error(transparent)]
    #[diagnostic(transparent)]
    Ensemble(#[from] EnsembleError),
    /// A member's map cannot be exported.
    #[error(transparent)]
    #[diagnostic(transparent)]
    Export(#[from] ExportError),
}

impl EnsembleExport {
    /// The layout every member shares (the first member's).
    pub fn layout(&self) -> Option<&Layout> {
        self.members.first().map(|(_, e)| &e.layout)
    }

    /// Writes every member's file and the companion file.
    pub fn write(&self) -> Result<(), crate::io::IoError> {
        for (path, exported) in &self.members {
            crate::io::write_atomic(path, &exported.bytes)?;
        }
        let json =
            serde_json::to_string_pretty(&self.band).map_err(|e| crate::io::IoError::Write {
                path: self.band_path.display().to_string(),
                reason: e.to_string(),
            })?;
        crate::io::write_atomic(&self.band_path, json.as_bytes())
    }
}

/// Member `index`'s file beside `output` (`gb.onnx` -> `gb.member-01.onnx`).
pub fn member_path(output: &Path, index: usize) -> PathBuf {
    sibling(output, &format!("member-{index:02}.onnx"))
}

/// The companion file beside `output` (`gb.onnx` -> `gb.band.json`).
pub fn band_path(output: &Path) -> PathBuf {
    sibling(output, "band.json")
}

/// `output`'s stem (without an `.onnx` extension) with `.tail`.
fn sibling(output: &Path, tail: &str) -> PathBuf {
    let name = output
        .file_name()
        .map_or_else(|| "model".to_string(), |n| n.to_string_lossy().into_owned());
    let stem = name.strip_suffix(".onnx").unwrap_or(&name);
    output.with_file_name(format!("{stem}.{tail}"))
}

/// Exports the ensemble run in `directory` of `model` (file text `source`): each used
/// member's map in `precision` and the band's facts, to be written beside `output`.
pub fn export(
    model: &ir::Model,
    source: &str,
    directory: &Path,
    precision: Precision,
    output: &Path,
) -> Result<EnsembleExport, EnsembleExportError> {
    let loaded = ensemble::load(model, source, directory)?;
    let info = &loaded.info;
    let mut members = Vec::new();
    let mut listed = Vec::new();
    for (member, run) in info.used().zip(&loaded.members) {
        let restored =
            artifacts::restore_with_notes(model, source, run).map_err(EnsembleError::from)?;
        let exported = super::onnx(model, &restored.network, &restored.setup, precision)?;
        let path = member_path(output, member.index);
        listed.push(MemberFile {
            index: member.index,
            seed: member.seed,
            onnx: path
                .file_name()
                .map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
        });
        members.push((path, exported));
    }
    let calibration = &info.calibration;
    let states = (info.band.noise.iter().enumerate())
        .map(|(state, noise)| StateBand {
            state: noise.state.clone(),
            noise: noise.clone(),
            factor: calibration.factor(state, ensemble::DEFAULT_LEVEL),
            factors: (LEVELS.iter())
                .map(|&level| (level, calibration.factor(state, level)))
                .collect(),
            scores: (calibration.calibrated)
                .then(|| calibration.states.get(state).map(|s| s.scores.clone()))
                .flatten()
                .unwrap_or_default(),
        })
        .collect();
    let band = BandFile {
        gbc_version: env!("CARGO_PKG_VERSION").to_string(),
        model: model.name.clone(),
        recipe: RECIPE.into(),
        calibrated: calibration.calibrated,
        reason: calibration.reason.clone(),
        members: listed,
        base_level: info.band.base_level,
        level: ensemble::DEFAULT_LEVEL,
        states,
        coverage: info.coverage.clone(),
    };
    Ok(EnsembleExport {
        members,
        band_path: band_path(output),
        band,
    })
}
