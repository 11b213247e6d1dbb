//! The report as readable text (what `gbc diagnose` prints).

use super::report::*;
pub use crate::numeric::text::num;
use std::fmt::Write;

/// Renders the report as text answering the three questions.
pub fn text(report: &Report) -> String {
    let mut out = String::new();
    if let Some(partial) = &report.partial {
        let _ = writeln!(out, "PARTIAL REPORT: {partial}\n");
    }
    header(&mut out, report);
    where_section(&mut out, report);
    which_section(&mut out, report);
    how_far_section(&mut out, report);
    out
}

/// An optional number, `-` when absent.
fn maybe(value: Option<f64>) -> String {
    value.map_or("-".into(), num)
}

/// A fraction as a percentage.
pub fn percent(value: f64) -> String {
    if value.is_finite() {
        format!("{:.1} %", 100.0 * value)
    } else {
        "n/a".into()
    }
}

fn header(out: &mut String, report: &Report) {
    let split = &report.split;
    let held = match split.share {
        Some(share) => format!("the last {} of each experiment", percent(share)),
        None => String::new(),
    };
    let whole: Vec<&str> = (split.scored.iter())
        .filter(|p| !split.train_experiments.contains(&p.experiment))
        .map(|p| p.experiment.as_str())
        .collect();
    let held = match (held.is_empty(), whole.is_empty()) {
        (false, false) => format!("{held}, and experiments {}", whole.join(", ")),
        (false, true) => held,
        (true, _) => format!("experiments {}", whole.join(", ")),
    };
    let sparse = if split.sparse() {
        format!(
            "; fewer than {} rows: the held-out score is noisy",
            split.min_rows
        )
    } else {
        String::new()
    };
    let _ = writeln!(
        out,
        "model {}: fitted on {} measured rows ({}), scored on {} ({held}{sparse})\n",
        report.model,
        split.train_rows,
        split.train_experiments.join(", "),
        split.test_rows,
    );
}

/// Section 1: how large the gap is against the noise, the fitted params and starts, each
/// state's share and, for a significant gap, where and when it lies.
fn where_section(out: &mut String, report: &Report) {
    let _ = writeln!(out, "1. Where the gap lies");
    gap_lines(out, report);
    fit_lines(out, "fitted params", &report.base_fit);
    for start in &report.initial_states {
        let _ = writeln!(
            out,
            "   initial {} of {}: {} ({})",
            start.state,
            start.experiment,
            num(start.value),
            start.origin
        );
    }
    state_table(out, &report.states);
    if !report.significant {
        let _ = writeln!(out);
        return;
    }
    loci(out, report);
    when_lines(out, report);
    let _ = writeln!(out);
}

/// The gap before against the noise floor, with its verdict, and the mean error per state.
fn gap_lines(out: &mut String, report: &Report) {
    let spread = report.held_out_spread.unwrap_or(0.0);
    let expected = report.noise_floor + spread;
    let ratio = if !report.gap_before.is_finite() {
        "-".to_string()
    } else if expected > 0.0 {
        format!("{}x", num(report.gap_before / expected))
    } else {
        "noise-free data".to_string()
    };
    let floor = match report.held_out_spread {
        Some(spread) => format!(
            "noise floor {} + {} from the fitted params' uncertainty and the noisy first rows \
             the runs start from = {} for a correct model",
            num(report.noise_floor),
            num(spread),
            num(expected)
        ),
        None => format!(
            "noise floor {} (the spread of the fitted params and starts could not be computed)",
            num(report.noise_floor)
        ),
    };
    let verdict = if !report.gap_before.is_finite() {
        "the fitted model's free run diverges on the held-out part, so the gap cannot be \
         measured: hold out whole experiments (--holdout) or a shorter tail (--val-fraction)"
    } else if report.significant {
        "significant"
    } else {
        "not significant: the model explains the held-out data as well as a correct model would"
    };
    let _ = writeln!(
        out,
        "   gap before {} (held-out free run, normalised MSE); {floor} ({ratio}): {verdict}",
        num(report.gap_before),
    );
    let _ = writeln!(
        out,
        "   error before {} (the mean over states of each state's NMSE, the measure of gbc train and predict; the gap pools cells)",
        num(report.gap_before_per_state)
    );
}

/// Each measured state's share of the gap, its errors and its noise.
fn state_table(out: &mut String, states: &[StateGap]) {
    let _ = writeln!(
        out,
        "   {:<12} {:>8} {:>10} {:>10} {:>10}  noise from",
        "state", "share", "online", "offline", "noise"
    );
    for state in states {
        let _ = writeln!(
            out,
            "   {:<12} {:>8} {:>10} {:>10} {:>10}  {}",
            state.name,
            percent(state.share),
            maybe(state.online),
            maybe(state.offline),
            num(state.noise),
            state.noise_estimate
        );
    }
}

/// When and in which regime the error lies, and the formulas proposed for the correction.
fn when_lines(out: &mut String, report: &Report) {
    for window in report.windows.iter().take(3) {
        let _ = writeln!(
            out,
            "   window t = {} to {} ({}): {} of the error",
            num(window.t_start),
            num(window.t_end),
            window.experiment,
            percent(window.share)
        );
    }
    for regime in &report.regime {
        let _ = writeln!(
            out,
            "   regime {}: {} of the error in {} of the rows",
            phrase(regime),
            percent(regime.share),
            percent(regime.row_share)
        );
    }
    for hint in &report.hints {
        let _ = writeln!(
            out,
            "   hint ({}, R^2 {:.3}): {}",
            hint.target, hint.r2, hint.text
        );
    }
}

/// The params of a fit with their standard errors, flags and free direction.
fn fit_lines(out: &mut String, label: &str, fit: &FitSummary) {
    if fit.estimates.is_empty() {
        return;
    }
    let params: Vec<String> = (fit.estimates.iter())
        .map(|e| {
            if e.held || fit.pinned.iter().any(|(name, _)| name == &e.name) {
                return format!("{} = {} (held)", e.name, num(e.value));
            }
            let flag = if e.identified {
                ""
            } else {
                " (not identified)"
            };
            let error = match e.std_error {
                Some(s) if s.is_finite() => num(s),
                _ => "unbounded".to_string(),
            };
            format!("{} = {} +- {error}{flag}", e.name, num(e.value))
        })
        .collect();
    let _ = writeln!(out, "   {label}: {}", params.join(", "));
    if !fit.free_direction.is_empty() {
        let parts: Vec<String> = (fit.free_direction.iter())
            .map(|(name, v)| format!("{name} {}{:.2}", if *v >= 0.0 { "+" } else { "-" }, v.abs()))
            .collect();
        let _ = writeln!(
            out,
            "   the data leave free the direction {} (logarithms of positive params): the fit cannot tell these apart",
            parts.join(", ")
        );
    }
    if !fit.pinned.is_empty() {
        let held: Vec<String> = (fit.pinned.iter())
            .map(|(name, value)| format!("{name} = {}", num(*value)))
            .collect();
        let _ = writeln!(
            out,
            "   held at the declared value (the fit left a direction free along it, the gap is the same): {}",
            held.join(", ")
        );
    }
}

fn loci(out: &mut String, report: &Report) {
    if report.locus.is_empty() {
        let _ = writeln!(out, "   loci and memory: {}", report.memory.reason);
        return;
    }
    let _ = writeln!(
        out,
        "   free correction at each rate, group and balance (held-out gap it leaves; time of its fits):"
    );
    for locus in report.locus.iter().take(8) {
        let kind = match locus.kind {
            LocusKind::Balance => "balance",
            LocusKind::Let => "let",
            LocusKind::Group => "group",
            LocusKind::Output => "output",
            LocusKind::Closure => "closure",
        };
        let tied = if locus.tied {
            "  <- best or tied with it"
        } else {
            ""
        };
        let _ = writeln!(
            out,
            "     {:<16} {:<8} {:>10}  (present only {}, with history {}; {:.1} s){tied}",
            locus.name,
            kind,
            num(locus.bound_after),
            num(locus.bound_present),
            num(locus.bound_history),
            locus.seconds
        );
    }
    let tied: Vec<&str> = (report.locus.iter())
        .filter(|l| l.tied)
        .map(|l| l.name.as_str())
        .collect();
    if tied.len() > 1 {
        let _ = writeln!(
            out,
            "   the data cannot tell apart: {} (listed most specific and upstream first)",
            tied.join(", ")
        );
    }
    let memory = &report.memory;
    let taus: Vec<String> = memory.time_constants.iter().map(|t| num(*t)).collect();
    let verdict = if memory.history_needed {
        "closing it needs history (hidden dynamics such as a lag)"
    } else {
        "closing it needs no history (an instantaneous term)"
    };
    let _ = writeln!(out, "   memory: {verdict}: {}", memory.reason);
    let _ = writeln!(
        out,
        "   (history: filters with time constants {}, span chosen from the data)",
        taus.join(", ")
    );
}

/// "u below 0.2", "S above 10", "X between 1 and 2".
pub fn phrase(regime: &Regime) -> String {
    let [lo, hi] = regime.range;
    match (regime.lowest, regime.highest) {
        (true, false) => format!("{} below {}", regime.variable, num(hi)),
        (false, true) => format!("{} above {}", regime.variable, num(lo)),
        _ => format!("{} between {} and {}", regime.variable, num(lo), num(hi)),
    }
}

/// Section 2: every effect ranked, how certain the ranking is, and the sets of effects
/// the selection tried.
fn which_section(out: &mut String, report: &Report) {
    let _ = writeln!(out, "2. Which effects cause it");
    if report.effects.is_empty() {
        let _ = writeln!(out, "   the model declares no effect\n");
        return;
    }
    effect_table(out, &report.effects);
    ranking_line(out, &report.confidence);
    if let Some(best) = report.effects.first() {
        fit_lines(out, &format!("{} params", best.name), &best.fit);
    }
    selection_table(out, &report.selection);
    let _ = writeln!(out);
}

/// The effects, each applied alone, in the ranking's order.
fn effect_table(out: &mut String, effects: &[EffectScore]) {
    let _ = writeln!(
        out,
        "   ranked by BIC of the training fit; the held-out gap scores each choice"
    );
    let _ = writeln!(
        out,
        "   {:<4} {:<24} {:>11} {:>10} {:>9} {:>7} {:>6} {:>7}  params",
        "rank", "effect", "BIC", "gap after", "shrink", "P(best)", "starts", "s"
    );
    for (rank, effect) in effects.iter().enumerate() {
        let params: Vec<String> = (effect.params.iter())
            .map(|(k, v)| format!("{k} = {}", num(*v)))
            .collect();
        let _ = writeln!(
            out,
            "   {:<4} {:<24} {:>11} {:>10} {:>9} {:>7} {:>6} {:>7.1}  {}",
            rank + 1,
            effect.name,
            num(effect.fit.bic),
            num(effect.gap_after),
            percent(effect.shrink),
            percent(effect.probability_best),
            effect.fit.starts,
            effect.fit.seconds,
            params.join(", ")
        );
    }
}

/// Whether the held-out data tell the best effect apart from the others, and how surely.
fn ranking_line(out: &mut String, confidence: &Confidence) {
    let certainty = format!(
        "margin to the second {} +- {} of the gap; best in {} of {} draws over {} blocks",
        percent(confidence.margin),
        percent(confidence.margin_error),
        percent(confidence.probability_best),
        confidence.resamples,
        confidence.blocks
    );
    if confidence.separated {
        let _ = writeln!(
            out,
            "   ranking: the best is told apart from every other ({certainty})"
        );
    } else {
        let _ = writeln!(
            out,
            "   ranking: the held-out data cannot tell apart {} ({certainty})",
            confidence.indistinguishable.join(", ")
        );
    }
}

/// The sets of effects the forward selection tried, with its verdict on each.
fn selection_table(out: &mut String, selection: &Selection) {
    let _ = writeln!(
        out,
        "   sets of effects, chosen by {}:",
        if selection.criterion.is_empty() {
            "BIC"
        } else {
            &selection.criterion
        }
    );
    let _ = writeln!(
        out,
        "     {:<34} {:>10} {:>9} {:>10} {:>9}  verdict",
        "effects", "train gap", "dBIC", "gap after", "shrink"
    );
    for step in &selection.steps {
        let verdict = if step.accepted { "credited" } else { "-" };
        let _ = writeln!(
            out,
            "     {:<34} {:>10} {:>9} {:>10} {:>9}  {verdict}: {}",
            step.effects.join(" + "),
            num(step.gap_train),
            num(step.delta_bic),
            num(step.gap_after),
            percent(step.shrink),
            step.reason
        );
    }
    if !selection.combinations.is_empty() {
        let _ = writeln!(
            out,
            "   combinations tried: {}",
            selection.combinations.join(", ")
        );
    }
    let _ = writeln!(out, "   verdict: {}", selection.stop);
}

fn how_far_section(out: &mut String, report: &Report) {
    let _ = writeln!(out, "3. How far it shrinks");
    let mut rows: Vec<(String, f64)> = Vec::new();
    let credited = &report.selection.credited;
    if !credited.is_empty() {
        rows.push((
            format!("after {}", credited.join(" + ")),
            report.selection.gap_after,
        ));
    } else if let Some(best) = report.effects.first() {
        rows.push((
            format!("after {} (not credited)", best.name),
            best.gap_after,
        ));
    }
    if let Some(locus) = report.locus.first() {
        rows.push((
            format!("free correction at {}", locus.name),
            locus.bound_after,
        ));
    }
    rows.push(("noise floor".into(), report.noise_floor));
    let width = rows.iter().map(|r| r.0.len()).max().unwrap_or(0).max(12);
    let _ = writeln!(
        out,
        "   {:<width$} {:>10}",
        "before",
        num(report.gap_before)
    );
    for (label, gap) in rows {
        let shrink = 1.0 - gap / report.gap_before;
        let _ = writeln!(
            out,
            "   {label:<width$} {:>10}  {:>9}",
            num(gap),
            percent(-shrink)
        );
    }
    match credited.as_slice() {
        [] if !report.significant => {
            let _ = writeln!(out, "   credited: none (no significant gap)");
        }
        [] if !report.selection.undecided.is_empty() => {
            let _ = writeln!(
                out,
                "   credited: undecided between {}",
                report.selection.undecided.join(" and ")
            );
        }
        [] => {
            let _ = writeln!(out, "   credited: none ({})", report.selection.stop);
        }
        [name] => {
            let _ = writeln!(out, "   credited: {name}");
        }
        names => {
            let _ = writeln!(out, "   credited: {} (together)", names.join(" + "));
        }
    }
    let timing = &report.timing;
    let _ = writeln!(
        out,
        "   time: {:.1} s (model fit {:.1} s, effects {:.1} s, selection {:.1} s, corrections {:.1} s) on {} threads",
        timing.total, timing.base_fit, timing.effects, timing.selection, timing.loci, timing.jobs
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_and_regimes_read_well() {
        assert_eq!(num(0.012345), "0.0123");
        assert_eq!(num(12.345), "12.3");
        assert_eq!(num(1.5e-5), "1.50e-5");
        assert_eq!(num(f64::INFINITY), "diverged");
        assert_eq!(percent(0.5), "50.0 %");
        let regime = |lowest, highest| Regime {
            variable: "u".into(),
            range: [0.0, 0.2],
            share: 0.5,
            row_share: 0.2,
            lowest,
            highest,
        };
        assert_eq!(phrase(&regime(true, false)), "u below 0.200");
        assert_eq!(phrase(&regime(false, true)), "u above 0");
        assert_eq!(phrase(&regime(false, false)), "u between 0 and 0.200");
    }
}
