//! An HTML report of one or more studies: settings, the grey-box against black-box tally,
//! the summary and param tables, and every figure inline (no external files).

use std::fmt::Write;

use super::black_box::is_black_box;
use super::figure::Figure;
use super::figures::representative;
use super::prepare::Prepared;
use super::results::{runs_of, spread, summarise, RunResult, Spread, SummaryRow};
use super::{Study, Validation};
use crate::plot::escape;

/// How often a grey-box model's median error is below a black-box model's.
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    /// The grey-box model.
    pub grey: String,
    /// The black-box model.
    pub black: String,
    /// Online: sizes where the grey box's median is lower, and sizes compared.
    pub online: (usize, usize),
    /// Offline: the same.
    pub offline: (usize, usize),
}

/// Every grey-box model against every black-box model (see [`is_black_box`]).
pub fn compare(prepared: &Prepared, results: &[RunResult]) -> Vec<Comparison> {
    let rows = summarise(&prepared.study, results);
    let median = |label: &str, size: usize, pick: fn(&SummaryRow) -> Option<Spread>| {
        (rows.iter())
            .find(|r| r.model == label && r.size == size)
            .and_then(pick)
            .map(|s| s.median)
    };
    let tally = |grey: &str, black: &str, pick: fn(&SummaryRow) -> Option<Spread>| {
        let mut wins = 0;
        let mut compared = 0;
        for size in prepared.study.sorted_sizes() {
            if let (Some(g), Some(b)) = (median(grey, size, pick), median(black, size, pick)) {
                compared += 1;
                wins += usize::from(g < b);
            }
        }
        (wins, compared)
    };
    let (blacks, greys): (Vec<_>, Vec<_>) =
        prepared.models.iter().partition(|m| is_black_box(&m.model));
    let mut comparisons = Vec::new();
    for grey in &greys {
        for black in &blacks {
            comparisons.push(Comparison {
                grey: grey.label.clone(),
                black: black.label.clone(),
                online: tally(&grey.label, &black.label, |r| r.online),
                offline: tally(&grey.label, &black.label, |r| r.offline),
            });
        }
    }
    comparisons
}

/// A number for a table: 3 significant digits, `diverged` for infinity.
pub fn number(value: f64) -> String {
    if value.is_infinite() {
        "diverged".into()
    } else if value.is_nan() {
        "–".into()
    } else if value != 0.0 && !(1e-3..1e4).contains(&value.abs()) {
        format!("{value:.2e}")
    } else {
        format!("{value:.3}")
    }
}

fn spread_cell(spread: Option<Spread>) -> String {
    spread.map_or("–".into(), |s| {
        format!(
            "{} <small>[{} – {}]</small>",
            number(s.median),
            number(s.min),
            number(s.max)
        )
    })
}

/// The settings of a study in one paragraph.
pub fn describe(study: &Study) -> String {
    let models: Vec<String> = (study.models.iter())
        .map(|m| {
            format!(
                "<code>{}</code> ({})",
                escape(&m.label),
                escape(&m.path.display().to_string())
            )
        })
        .collect();
    let validation = match &study.validation {
        Validation::FromRow(row) => format!("rows from {row} on validate; the rows before train"),
        Validation::File(path) => format!(
            "<code>{}</code> validates",
            escape(&path.display().to_string())
        ),
        Validation::Holdout(names) => format!(
            "experiments {} are held out and free-run whole; the first pairs of the others, \
             in data-set order, train",
            escape(&names.join(", "))
        ),
    };
    format!(
        "<p>Models {}. Data <code>{}</code>: {validation}. Sizes {:?} training pairs, {} \
         replicates (seeds {}..), {} epochs, batch {}, learning rate {}, {:?}, training \
         recipe <code>{}</code>.</p>",
        models.join(", "),
        escape(&study.data.describe()),
        study.sorted_sizes(),
        study.replicates,
        study.first_seed,
        study.settings.epochs,
        study.settings.batch_size,
        study.settings.learning_rate,
        study.settings.precision,
        study.training.name(),
    )
}

/// The HTML section of one study.
pub fn section(
    prepared: &Prepared,
    results: &[RunResult],
    figures: &[Figure],
    notes: &[String],
) -> String {
    let study = &prepared.study;
    let mut html = String::new();
    let _ = writeln!(html, "<section id=\"{}\">", escape(&study.name));
    let _ = writeln!(
        html,
        "<h2>{}</h2>",
        escape(if study.title.is_empty() {
            &study.name
        } else {
            &study.title
        })
    );
    html.push_str(&describe(study));
    let ok = results.iter().filter(|r| r.is_ok()).count();
    let seconds: f64 = results.iter().map(|r| r.wall_seconds).sum();
    let _ = writeln!(
        html,
        "<p>{} runs ({ok} trained, {} failed); {:.0} s of training in all (summed over runs).</p>",
        results.len(),
        results.len() - ok,
        seconds
    );
    html.push_str(&comparison_list(&compare(prepared, results)));
    html.push_str(&verdicts(prepared, results));
    html.push_str(&summary_table(&summarise(study, results)));
    html.push_str(&params_table(prepared, results));
    html.push_str(&representatives(prepared, results));
    for shown in figures {
        html.push_str(&crate::plot::figure(&shown.svg, &shown.caption));
    }
    if !notes.is_empty() {
        html.push_str("<ul class=\"notes\">\n");
        for note in notes {
            let _ = writeln!(html, "<li>{}</li>", escape(note));
        }
        html.push_str("</ul>\n");
    }
    html.push_str("</section>\n");
    html
}

/// One paragraph per grey box against the study's first black box: where it wins and where
/// it loses (by median, size by size) and why.
fn verdicts(prepared: &Prepared, results: &[RunResult]) -> String {
    let rows = summarise(&prepared.study, results);
    let Some(black) = prepared.models.iter().find(|m| is_black_box(&m.model)) else {
        return String::new();
    };
    let sizes = prepared.study.sorted_sizes();
    let mut html = String::new();
    for grey in prepared.models.iter().filter(|m| !is_black_box(&m.model)) {
        let duel = Duel {
            rows: &rows,
            grey: &grey.label,
            black: &black.label,
            sizes: &sizes,
        };
        let _ = writeln!(html, "{}", duel.verdict());
    }
    html
}

/// A grey box against a black box over a study's sizes, by the medians of its summary.
struct Duel<'a> {
    /// The study's summary rows.
    rows: &'a [SummaryRow],
    /// The grey box's label.
    grey: &'a str,
    /// The black box's label.
    black: &'a str,
    /// The study's sizes, smallest first.
    sizes: &'a [usize],
}

/// Where a grey box stands against a black box in one error (online or offline).
struct Tally {
    /// Sizes where the grey box's median is below the black box's.
    wins: Vec<usize>,
    /// The other sizes where both have a median.
    losses: Vec<usize>,
    /// Sizes where each median lies inside the other's replicate range.
    ties: Vec<usize>,
}

impl Duel<'_> {
    /// The verdict's paragraph.
    fn verdict(&self) -> String {
        let online = self.tally(true);
        let offline = self.tally(false);
        let largest = self.sizes.last().copied().unwrap_or(0);
        let at_largest = self.at_largest(largest);
        let (win_note, loss_note) = if online.wins.contains(&largest) {
            (at_largest, String::new())
        } else {
            (String::new(), at_largest)
        };
        let wins = wins_text(&online, &offline, self.sizes.len(), &win_note);
        let losses = losses_text(&online, &offline, &loss_note);
        let ties = ties_text(&online);
        format!(
            "<p><b>{}</b> against <b>{}</b>. <i>Where the grey box wins:</i> {wins}. \
             <i>Where it loses:</i> {losses}.{ties}</p>",
            escape(self.grey),
            escape(self.black)
        )
    }

    /// The spread of model `label`'s online or offline error at `size`.
    fn summary(&self, label: &str, size: usize, online: bool) -> Option<Spread> {
        (self.rows.iter())
            .find(|r| r.model == label && r.size == size)
            .and_then(|r| if online { r.online } else { r.offline })
    }

    /// The sizes the grey box wins, loses and ties in the online or offline error.
    fn tally(&self, online: bool) -> Tally {
        let (mut wins, mut losses, mut ties) = (Vec::new(), Vec::new(), Vec::new());
        for &size in self.sizes {
            let pair = (
                self.summary(self.grey, size, online),
                self.summary(self.black, size, online),
            );
            if let (Some(g), Some(b)) = pair {
                if g.median < b.median {
                    wins.push(size);
                } else {
                    losses.push(size);
                }
                let inside = |x: f64, range: &Spread| range.min <= x && x <= range.max;
                if inside(g.median, &b) && inside(b.median, &g) {
                    ties.push(size);
                }
            }
        }
        Tally { wins, losses, ties }
    }

    /// Both online medians at the `largest` size, as a note to a win or a loss.
    fn at_largest(&self, largest: usize) -> String {
        match (
            self.summary(self.grey, largest, true),
            self.summary(self.black, largest, true),
        ) {
            (Some(g), Some(b)) => format!(
                "; at {largest} points online MSE {} against {}",
                number(g.median),
                number(b.median)
            ),
            _ => String::new(),
        }
    }
}

/// "size 100" or "sizes 100, 200".
fn size_list(sizes: &[usize]) -> String {
    let names: Vec<String> = sizes.iter().map(ToString::to_string).collect();
    let noun = if sizes.len() == 1 { "size" } else { "sizes" };
    format!("{noun} {}", names.join(", "))
}

/// Where the grey box wins, out of `compared` sizes, and why.
fn wins_text(online: &Tally, offline: &Tally, compared: usize, note: &str) -> String {
    match (online.wins.is_empty(), offline.wins.is_empty()) {
        (false, _) => format!(
            "the free run at {} of {} sizes ({}{note}), and one step ahead at {} \
             of them. The balances carry the grey box: the network learns only the \
             unknown rates, and an error in a rate shifts the trajectory without breaking \
             mass conservation, so it does not compound the way a black box's does",
            online.wins.len(),
            compared,
            (online.wins.iter().map(ToString::to_string))
                .collect::<Vec<_>>()
                .join(", "),
            offline.wins.len()
        ),
        (true, false) => format!(
            "one step ahead only, at {}: the balances help the one-step fit, \
             but this grid gives no size where its free run is the better one",
            size_list(&offline.wins)
        ),
        (true, true) => "nowhere in this grid".to_string(),
    }
}

/// Where the grey box loses, and why.
fn losses_text(online: &Tally, offline: &Tally, note: &str) -> String {
    match (online.losses.is_empty(), offline.losses.is_empty()) {
        (true, true) => "nowhere in this grid".to_string(),
        (true, false) => format!(
            "one step ahead at {}: judged from the measured history, the black \
             box's direct map to the next state fits as well or better, and its freedom \
             only costs it in the free run",
            size_list(&offline.losses)
        ),
        (false, _) => format!(
            "the free run at {}{note}: with these training pairs and epochs \
             the learned rates are not yet right over the whole range of states the free \
             run visits, and the balances then carry a wrong rate forward{}",
            size_list(&online.losses),
            if offline.losses.is_empty() {
                String::new()
            } else {
                format!("; one step ahead too at {}", size_list(&offline.losses))
            }
        ),
    }
}

/// The sizes where the free runs tie, as a sentence (empty without any).
fn ties_text(online: &Tally) -> String {
    if online.ties.is_empty() {
        String::new()
    } else {
        format!(
            " At {} the two free-run medians lie inside each other's replicate range: \
             a tie more than a win or a loss.",
            size_list(&online.ties)
        )
    }
}

fn comparison_list(comparisons: &[Comparison]) -> String {
    if comparisons.is_empty() {
        return String::new();
    }
    let mut html = String::from("<ul>\n");
    for c in comparisons {
        let _ = writeln!(
            html,
            "<li><b>{}</b> below <b>{}</b> (median): online at {} of {} sizes, offline at {} of {}.</li>",
            escape(&c.grey),
            escape(&c.black),
            c.online.0,
            c.online.1,
            c.offline.0,
            c.offline.1
        );
    }
    html.push_str("</ul>\n");
    html
}

fn summary_table(rows: &[SummaryRow]) -> String {
    let mut html = String::from(
        "<table><tr><th>model</th><th>points</th><th>ok / failed</th><th>offline MSE \
         [min – max]</th><th>online MSE [min – max]</th><th>free runs blown up</th>",
    );
    let generalisation: Vec<String> = (rows.first())
        .map(|r| {
            r.generalisation
                .iter()
                .map(|(name, _)| name.clone())
                .collect()
        })
        .unwrap_or_default();
    for name in &generalisation {
        let _ = write!(html, "<th>free run on {}</th>", escape(name));
    }
    html.push_str("<th>time [s]</th></tr>\n");
    for row in rows {
        let _ = write!(
            html,
            "<tr><td>{}</td><td>{}</td><td>{} / {}</td><td>{}</td><td>{}</td><td>{}</td>",
            escape(&row.model),
            row.size,
            row.ok,
            row.failed,
            spread_cell(row.offline),
            spread_cell(row.online),
            row.blown_up
        );
        for (_, spread) in &row.generalisation {
            let _ = write!(html, "<td>{}</td>", spread_cell(*spread));
        }
        let time = row.wall_seconds.map_or("–".into(), |s| format!("{s:.1}"));
        let _ = writeln!(html, "<td>{time}</td></tr>");
    }
    html.push_str("</table>\n");
    html
}

fn params_table(prepared: &Prepared, results: &[RunResult]) -> String {
    let size = prepared.study.figure_size();
    let mut html = String::new();
    for loaded in prepared
        .models
        .iter()
        .filter(|m| !m.model.params.is_empty())
    {
        let runs: Vec<&RunResult> = runs_of(results, &loaded.label, size)
            .into_iter()
            .filter(|r| r.is_ok())
            .collect();
        if runs.is_empty() {
            continue;
        }
        let truth = prepared
            .truth
            .as_ref()
            .map(|t| super::reference::true_params(t, &loaded.model));
        let _ = writeln!(
            html,
            "<p>Trained params of <code>{}</code> at {size} points, over {} replicates (median \
             [min – max]):</p><table><tr><th>param</th><th>trained</th><th>truth</th></tr>",
            escape(&loaded.label),
            runs.len()
        );
        for param in &loaded.model.params {
            let values: Vec<f64> = runs
                .iter()
                .filter_map(|r| RunResult::measure(&r.params, &param.name))
                .collect();
            let true_value = (truth.iter().flatten())
                .find(|(name, _)| name == &param.name)
                .map_or("–".into(), |(_, v)| number(*v));
            let _ = writeln!(
                html,
                "<tr><td>{}</td><td>{}</td><td>{true_value}</td></tr>",
                escape(&param.name),
                spread_cell(spread(&values))
            );
        }
        html.push_str("</table>\n");
    }
    html
}

/// Which run of each model the trajectory, closure and param figures show.
fn representatives(prepared: &Prepared, results: &[RunResult]) -> String {
    let size = prepared.study.figure_size();
    let ids: Vec<String> = (prepared.models.iter())
        .filter_map(|m| representative(results, &m.label, size))
        .map(|run| format!("<code>{}</code>", escape(&run.id)))
        .collect();
    if ids.is_empty() {
        return String::new();
    }
    format!(
        "<p>The figures below show, for each model, the replicate with the median online \
         error at {size} training points: {}.</p>\n",
        ids.join(", ")
    )
}

pub use crate::plot::page;
