//! Issue 43: an unknown the fit holds at its declared value (pinned along a free
//! direction) is reported held, not identified, and without a standard error, in the JSON
//! and the text; the unknown fitted beside it keeps a finite, positive standard error.

use super::*;
use crate::record::Record;

/// Only the product `a b` is seen: the fit leaves `(1, -1)` free in log units and holds
/// `a`, the first declared.
const MODEL: &str = "model decay
state X = 1
param a = 1 positive, b = 0.2 positive
der X = -a * b * X
";

/// `X = exp(-0.1 t)` at 60 rows, times a deterministic 1 % wobble (the fit needs a
/// residual for a standard error).
fn record() -> Record {
    let times: Vec<f64> = (0..60).map(|k| 0.5 * k as f64).collect();
    let states = vec![(times.iter().enumerate())
        .map(|(k, t)| (-0.1 * t).exp() * (1.0 + 0.01 * (1.7 * k as f64).sin()))
        .collect()];
    Record::complete("e0", times, Vec::new(), states)
}

#[test]
fn a_held_param_is_written_held_unidentified_and_without_a_standard_error() {
    let compiled = crate::driver::compile("decay.gbm", MODEL, &[]).unwrap();
    let records = [record()];
    let problem = Problem {
        name: "decay.gbm",
        source: MODEL,
        checked: &compiled.checked,
        model: &compiled.model,
        records: &records,
        held_out: &[],
    };
    let options = Options {
        restarts: 2,
        locate: false,
        ..Options::default()
    };
    let report = diagnose(&problem, &options, &|_| {}).unwrap();
    let text = render::text(&report);
    let json = serde_json::to_value(&report).unwrap();
    let estimates = json["base_fit"]["estimates"].as_array().unwrap();
    let find = |name: &str| estimates.iter().find(|e| e["name"] == name).unwrap();
    let (a, b) = (find("a"), find("b"));
    assert_eq!(a["held"], true, "{a}\n{text}");
    assert_eq!(a["identified"], false, "{a}");
    assert!(
        a["std_error"].is_null() && a["relative_error"].is_null(),
        "{a}"
    );
    assert_eq!(a["value"], 1.0, "{a}");
    assert_eq!(b["held"], false, "{b}");
    let error = b["std_error"].as_f64().unwrap();
    assert!(error.is_finite() && error > 0.0, "{b}");
    assert!(text.contains("a = 1.00 (held)"), "{text}");
    // What is written reads back the same.
    let read: Report = serde_json::from_value(json.clone()).unwrap();
    assert_eq!(serde_json::to_value(&read).unwrap(), json);
}
