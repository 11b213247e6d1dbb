//! A constant the modeller held at a wrong value: the diagnosis names it (`refit NAME`)
//! rather than crediting a look-alike effect, and its refitted value is the truth's.

use super::tests::*;
use super::*;

/// The chemostat's diagnosed model with its Michaelis constant held at `k_m`, written to a
/// directory of its own (returned).
fn with_michaelis_constant(k_m: &str) -> std::path::PathBuf {
    let source = std::fs::read_to_string(root().join("models/diagnose/chemostat/model.gbm"))
        .expect("the shipped model reads");
    let held = source.replace("const K_M = 1.5e-2", &format!("const K_M = {k_m}"));
    assert_ne!(held, source, "the model declares K_M as the test expects");
    let directory = std::env::temp_dir().join(format!("gbc-refit-{}", std::process::id()));
    std::fs::create_dir_all(&directory).unwrap();
    std::fs::write(directory.join("model.gbm"), held).unwrap();
    directory
}

#[test]
fn a_wrong_constant_is_refitted_not_pinned_on_an_effect() {
    let sets = [chemostat("truth.gbm")];
    let directory = with_michaelis_constant("4e-2");
    let model = directory.join("model.gbm");
    let model = model.to_str().unwrap();
    let options = Options {
        locate: false,
        ..Options::default()
    };
    let report = run(model, &sets, &options);
    let text = render::text(&report);
    assert!(report.significant, "{text}");
    assert_eq!(report.selection.credited, ["refit K_M"], "{text}");
    assert_eq!(report.selection.refitted, ["K_M"], "{text}");
    let refit = (report.effects.iter())
        .find(|e| e.name == "refit K_M")
        .expect("the refit is ranked");
    // The truth's K_M (truth.gbm) is 1.5e-2: the refit finds it within a few per cent.
    assert!((refit.params["K_M"] / 1.5e-2 - 1.0).abs() < 0.05, "{text}");
    // With `--hold-constants` no constant is a candidate.
    let held = Options {
        refit_constants: false,
        ..options
    };
    let report = run(model, &sets, &held);
    assert!(report.effects.iter().all(|e| !e.name.starts_with("refit ")));
    std::fs::remove_dir_all(directory).ok();
}
