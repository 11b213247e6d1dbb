//! The diagnosis JSON reads back: a report whose every number is infinite or NaN, with an
//! unidentified param, is written with each number by name (never `null`, which a number
//! field without `#[serde(with = "crate::json")]` would write) and reads back to the same
//! text.

use super::*;
use std::collections::BTreeMap;

const INF: f64 = f64::INFINITY;
const NAN: f64 = f64::NAN;
const NEG: f64 = f64::NEG_INFINITY;

/// Names paired with a non-finite number each.
fn named(names: &[&str]) -> Vec<(String, f64)> {
    let values = [INF, NAN, NEG];
    (names.iter().zip(values.iter().cycle()))
        .map(|(name, value)| (name.to_string(), *value))
        .collect()
}

/// A param the data do not determine: infinite standard error.
fn unidentified(name: &str) -> ParamEstimate {
    ParamEstimate {
        name: name.into(),
        value: NAN,
        std_error: Some(INF),
        relative_error: Some(INF),
        identified: false,
        held: false,
    }
}

fn fit() -> FitSummary {
    FitSummary {
        estimates: vec![unidentified("kcat")],
        free_direction: named(&["kcat", "K_P"]),
        gap_train: NAN,
        aic: NEG,
        bic: INF,
        unknowns: 2,
        starts: 3,
        seconds: NAN,
        pinned: vec![("X0".into(), INF)],
    }
}

/// A report with every list holding an entry, every option set and every number infinite
/// or NaN.
fn every_number_non_finite() -> Report {
    Report {
        model: "chemostat".into(),
        gap_before: INF,
        gap_before_per_state: NAN,
        noise_floor: NAN,
        held_out_spread: Some(NAN),
        significant: true,
        states: vec![StateGap {
            name: "S".into(),
            share: NAN,
            online: Some(INF),
            offline: Some(NEG),
            noise: NAN,
            noise_estimate: "declared".into(),
            cells: 40,
        }],
        locus: vec![Locus {
            name: "P".into(),
            kind: LocusKind::Balance,
            members: vec!["P".into()],
            bound_after: INF,
            bound_present: NAN,
            bound_history: NEG,
            tied: true,
            depth: 0,
            seconds: NAN,
        }],
        history_dependent: false,
        memory: Memory {
            history_needed: false,
            probe: true,
            span: INF,
            time_constants: vec![1.0, NAN, INF],
            reason: "no history".into(),
        },
        windows: vec![Window {
            experiment: "e1".into(),
            t_start: NEG,
            t_end: INF,
            share: NAN,
        }],
        regime: vec![Regime {
            variable: "S".into(),
            range: [NEG, INF],
            share: NAN,
            row_share: INF,
            lowest: true,
            highest: false,
        }],
        effects: vec![EffectScore {
            name: "product_decay".into(),
            description: Some("P decays".into()),
            gap_after: INF,
            shrink: NEG,
            params: named(&["k_P", "K_P"])
                .into_iter()
                .collect::<BTreeMap<_, _>>(),
            fit: fit(),
            adds_hidden: vec!["E".into()],
            probability_best: NAN,
            spread: INF,
            tied: false,
        }],
        credited: Some("product_decay".into()),
        selection: Selection {
            steps: vec![SelectionStep {
                added: "product_decay".into(),
                effects: vec!["product_decay".into()],
                gap_train: NAN,
                gap_after: INF,
                shrink: NAN,
                delta_bic: NEG,
                aic: NEG,
                bic: INF,
                unknowns: 2,
                spread: NAN,
                alternatives: named(&[
                    "enzyme_saturation",
                    "product_inhibition",
                    "substrate_inhibition",
                ]),
                accepted: true,
                reason: "diverged".into(),
                fit: Some(fit()),
            }],
            credited: vec!["product_decay".into()],
            refitted: Vec::new(),
            gap_after: INF,
            stop: "no effect left".into(),
            criterion: "BIC".into(),
            combinations: vec!["a + b".into()],
            undecided: vec!["a".into(), "b".into()],
        },
        confidence: Confidence {
            separated: false,
            margin: NAN,
            margin_error: INF,
            probability_best: NEG,
            indistinguishable: vec!["product_inhibition".into()],
            blocks: 8,
            resamples: 200,
        },
        hints: vec![Formula {
            target: "dP/dt".into(),
            text: "-0.01 * P".into(),
            r2: NAN,
            terms: 1,
        }],
        fitted_params: named(&["kcat"]).into_iter().collect(),
        base_fit: fit(),
        initial_states: vec![InitialState {
            experiment: "e1".into(),
            state: "P".into(),
            value: NAN,
            origin: "fitted".into(),
        }],
        split: SplitSummary {
            train_rows: 100,
            test_rows: 40,
            train_experiments: vec!["e1".into()],
            scored: vec![ScoredPart {
                experiment: "e1".into(),
                t_start: NEG,
                t_end: INF,
                rows: 40,
            }],
            holdout: "tail".into(),
            share: Some(NAN),
            min_rows: 10,
        },
        partial: None,
        timing: Timing {
            total: INF,
            base_fit: NAN,
            effects: NAN,
            selection: NAN,
            loci: NAN,
            jobs: 1,
        },
        series: Vec::new(),
    }
}

#[test]
fn a_report_of_infinities_nans_and_an_unidentified_param_reads_back() {
    let report = every_number_non_finite();
    let written = serde_json::to_string_pretty(&report).unwrap();
    // A number field without `crate::json` writes a non-finite value as `null`.
    assert!(!written.contains("null"), "{written}");
    assert!(written.contains(r#""std_error": "inf""#), "{written}");
    let read: Report = serde_json::from_str(&written).unwrap();
    assert_eq!(serde_json::to_string_pretty(&read).unwrap(), written);
    let param = &read.base_fit.estimates[0];
    assert!(param.std_error == Some(INF) && param.value.is_nan() && !param.identified);
    assert!(read.gap_before == INF && read.noise_floor.is_nan());
    assert_eq!(read.selection.steps[0].alternatives[2].1, NEG);
    assert_eq!(read.regime[0].range, [NEG, INF]);
}

/// Every `f64` in the JSON is a name here: the JSON holds no plain number but integer
/// counts, so no number field escaped the rule by holding a finite value.
#[test]
fn the_non_finite_report_holds_no_plain_float() {
    fn floats(value: &serde_json::Value) -> usize {
        match value {
            serde_json::Value::Number(n) => usize::from(n.is_f64()),
            serde_json::Value::Array(items) => items.iter().map(floats).sum(),
            serde_json::Value::Object(map) => map.values().map(floats).sum(),
            _ => 0,
        }
    }
    let value = serde_json::to_value(every_number_non_finite()).unwrap();
    // The one finite value: a time constant of 1.
    assert_eq!(floats(&value), 1);
}
