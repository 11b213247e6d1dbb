//! The report as readable text (what `gbc diagnose` prints).

use super::report::*;
use std::fmt::Write;

/// Renders the report as text answering the three questions.
pub fn text(report: &Report) -> String {
    let mut out = String::new();
    header(&mut out, report);
    where_section(&mut out, report);
    which_section(&mut out, report);
    how_far_section(&mut out, report);
    out
}

/// A number with 3 significant digits, in plain or scientific notation.
pub fn num(value: f64) -> String {
    if !value.is_finite() {
        return if value.is_nan() {
            "n/a".into()
        } else {
            "diverges".into()
        };
    }
    let magnitude = value.abs();
    if magnitude != 0.0 && !(1e-3..1e5).contains(&magnitude) {
        format!("{value:.2e}")
    } else {
        let decimals = if magnitude == 0.0 {
            0
        } else {
            (2 - magnitude.log10().floor() as i32).max(0) as usize
        };
        format!("{value:.decimals$}")
    }
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
    let held = if split.separate_test {
        "test file"
    } else {
        "held-out tail"
    };
    let _ = writeln!(
        out,
        "model {}: fitted on {} rows, scored on {} rows ({held}, t = {} to {})\n",
        report.model,
        split.train_rows,
        split.test_rows,
        num(split.t_test_start),
        num(split.t_test_end)
    );
}

fn where_section(out: &mut String, report: &Report) {
    let _ = writeln!(out, "1. Where the gap lies");
    let ratio = if report.noise_floor > 0.0 {
        format!("{}x", num(report.gap_before / report.noise_floor))
    } else {
        "noise-free data".to_string()
    };
    let verdict = if report.significant {
        "significant"
    } else {
        "not significant: the model explains the data to the noise level"
    };
    let _ = writeln!(
        out,
        "   gap before {} (held-out free run, normalised MSE); noise floor {} ({ratio}): {verdict}",
        num(report.gap_before),
        num(report.noise_floor),
    );
    let params: Vec<String> = report
        .fitted_params
        .iter()
        .map(|(k, v)| format!("{k} = {}", num(*v)))
        .collect();
    if !params.is_empty() {
        let _ = writeln!(out, "   fitted params: {}", params.join(", "));
    }
    let _ = writeln!(
        out,
        "   {:<12} {:>8} {:>10} {:>10} {:>10}",
        "state", "share", "online", "offline", "noise"
    );
    for state in &report.states {
        let _ = writeln!(
            out,
            "   {:<12} {:>8} {:>10} {:>10} {:>10}",
            state.name,
            percent(state.share),
            num(state.online),
            num(state.offline),
            num(state.noise)
        );
    }
    if !report.significant {
        let _ = writeln!(out);
        return;
    }
    loci(out, report);
    for window in report.windows.iter().take(3) {
        let _ = writeln!(
            out,
            "   window t = {} to {}: {} of the error",
            num(window.t_start),
            num(window.t_end),
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
    let _ = writeln!(out);
}

fn loci(out: &mut String, report: &Report) {
    let _ = writeln!(
        out,
        "   free correction at each rate and balance (held-out gap it leaves):"
    );
    for locus in report.locus.iter().take(6) {
        let kind = match locus.kind {
            LocusKind::Balance => "balance",
            LocusKind::Let => "let",
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
            "     {:<12} {:<8} {:>10}  (present only {}, with history {}){tied}",
            locus.name,
            kind,
            num(locus.bound_after),
            num(locus.bound_present),
            num(locus.bound_history)
        );
    }
    let tied: Vec<&str> = report
        .locus
        .iter()
        .filter(|l| l.tied)
        .map(|l| l.name.as_str())
        .collect();
    if tied.len() > 1 {
        let _ = writeln!(out, "   the data cannot tell apart: {}", tied.join(", "));
    }
    let memory = if report.history_dependent {
        "closing it needs history (hidden dynamics such as a lag)"
    } else {
        "closing it needs no history (an instantaneous term)"
    };
    let _ = writeln!(out, "   memory: {memory}");
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

fn which_section(out: &mut String, report: &Report) {
    let _ = writeln!(out, "2. Which effect causes it");
    if report.effects.is_empty() {
        let _ = writeln!(out, "   the model declares no effect\n");
        return;
    }
    let _ = writeln!(
        out,
        "   {:<4} {:<24} {:>10} {:>9}  params",
        "rank", "effect", "gap after", "shrink"
    );
    for (rank, effect) in report.effects.iter().enumerate() {
        let params: Vec<String> = effect
            .params
            .iter()
            .map(|(k, v)| format!("{k} = {}", num(*v)))
            .collect();
        let _ = writeln!(
            out,
            "   {:<4} {:<24} {:>10} {:>9}  {}",
            rank + 1,
            effect.name,
            num(effect.gap_after),
            percent(effect.shrink),
            params.join(", ")
        );
    }
    let confidence = &report.confidence;
    let halves: Vec<&str> = confidence
        .best_by_half
        .iter()
        .map(|b| b.as_deref().unwrap_or("-"))
        .collect();
    let stability = if confidence.stable {
        "stable"
    } else {
        "not stable"
    };
    let _ = writeln!(
        out,
        "   ranking {stability} over the halves of the training part (best: {}); margin to the second: {} of the gap\n",
        halves.join(" / "),
        percent(confidence.margin)
    );
}

fn how_far_section(out: &mut String, report: &Report) {
    let _ = writeln!(out, "3. How far it shrinks");
    let mut rows: Vec<(String, f64)> = Vec::new();
    if let Some(best) = report.effects.first() {
        rows.push((format!("after {}", best.name), best.gap_after));
    }
    if let Some(combined) = &report.combined {
        rows.push((
            format!("after {}", combined.names.join(" + ")),
            combined.gap_after,
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
    match &report.credited {
        Some(name) => {
            let _ = writeln!(out, "   credited: {name}");
        }
        None if !report.significant => {
            let _ = writeln!(out, "   credited: none (no significant gap)");
        }
        None => {
            let _ = writeln!(out, "   credited: none (no effect closes most of the gap)");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_and_regimes_read_well() {
        assert_eq!(num(0.012345), "0.0123");
        assert_eq!(num(12.345), "12.3");
        assert_eq!(num(1.5e-5), "1.50e-5");
        assert_eq!(num(f64::INFINITY), "diverges");
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
