//! The comparison as text: per held-out experiment a table of the three errors (overall
//! and per state), the grey box's range and diverged runs, and the verdict; then the same
//! over every held-out experiment.

use std::fmt::Write;

use super::comparison::{Comparison, ExperimentScore};
use super::score::{number, Score};

/// The text report.
pub fn text(comparison: &Comparison) -> String {
    let mut out = String::new();
    let seeds = &comparison.seeds;
    let _ =
        writeln!(
        out,
        "grey box `{}` against its mechanism `{}` (fitted by free runs) and the naive forecast; \
         {} seed{} ({}), gbc train's defaults (epochs trained below); errors: mean over states of each state's NMSE on the \
         held-out experiments' measured cells (docs/error-measure.md)",
        comparison.grey_box,
        comparison.mechanism,
        seeds.len(),
        if seeds.len() == 1 { "" } else { "s" },
        seeds.iter().map(u64::to_string).collect::<Vec<_>>().join(", "),
    );
    for split in &comparison.splits {
        let _ = writeln!(
            out,
            "\nheld out {} (trained on {})",
            split.held_out.join(", "),
            split.training.join(", ")
        );
        for failed in split.grey_box.iter().filter(|r| r.failed.is_some()) {
            let why = failed.failed.as_deref().unwrap_or_default();
            let _ = writeln!(out, "  seed {} did not train: {why}", failed.seed);
        }
        for score in &split.scores {
            table(&mut out, score, &comparison.states);
        }
        let trained = split.epochs_trained();
        if !trained.is_empty() {
            let _ = writeln!(out, "  grey box epochs trained: {trained}");
        }
    }
    if comparison
        .splits
        .iter()
        .map(|s| s.held_out.len())
        .sum::<usize>()
        > 1
    {
        let _ = writeln!(
            out,
            "\nover every held-out experiment (each run's errors averaged over them)"
        );
        table(&mut out, &comparison.overall, &comparison.states);
    }
    out
}

/// Width of the row labels.
const LABEL: usize = 22;
/// Width of a number column.
const COLUMN: usize = 11;

/// One experiment's table and verdict.
fn table(out: &mut String, score: &ExperimentScore, states: &[String]) {
    let _ = write!(out, "  {:<LABEL$}{:>COLUMN$}", score.experiment, "error");
    for state in states {
        let _ = write!(out, "{state:>COLUMN$}");
    }
    let _ = writeln!(out);
    row(out, "mechanism (fitted)", &score.mechanism, states);
    if let Some(untrained) = &score.untrained {
        row(out, "grey box untrained", untrained, states);
    }
    row(out, "grey box (median)", &score.grey_box, states);
    let grey = &score.grey_box;
    if grey.runs > 1 {
        let _ = writeln!(
            out,
            "  {:<LABEL$}{:>COLUMN$}",
            format!("  min–max, {} seeds", grey.runs),
            format!("{}–{}", number(grey.range.0), number(grey.range.1))
        );
    }
    row(out, "naive forecast", &score.naive, states);
    for diverged in &grey.diverged {
        let _ = writeln!(out, "  diverged: {diverged}");
    }
    if grey.failed > 0 {
        let _ = writeln!(out, "  {} grey-box runs did not score", grey.failed);
    }
    let _ = writeln!(out, "  {}", score.verdict.sentence);
}

/// One model's row: its error and each state's NMSE.
fn row(out: &mut String, label: &str, score: &Score, states: &[String]) {
    let _ = write!(out, "  {label:<LABEL$}{:>COLUMN$}", number(score.error));
    for state in states {
        let value = (score.per_state.iter())
            .find(|(n, _)| n == state)
            .map_or("—".to_string(), |(_, v)| number(*v));
        let _ = write!(out, "{value:>COLUMN$}");
    }
    let _ = writeln!(out);
}
