//! End-to-end tests of experiments on the shipped chemostat: a tiny grid (2 models, 2 sizes,
//! 1 replicate, 2 epochs) run in two shards, re-run (skipped), merged, with tables, figures
//! and report; the errors checked against an independent recomputation; the truth model
//! checked against the data it made.

use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use super::execute::claim_directory;
use super::figures::representative;
use super::merge::{publish, weights_in, REPORT_FILE};
use super::reference::truth_along;
use super::results::{read_all, weights_dir};
use super::tables::{RESULTS_CSV, SUMMARY_CSV};
use super::tests::scratch_dir;
use super::{execute, grid, merge, prepare, Prepared, Progress, Shard, Study, StudyModel};
use crate::data::MinRows;
use crate::numeric::mean_std;
use crate::trained::artifacts;
use crate::trained::predict::{predict_in_range, Mode};

fn tiny_study() -> Study {
    let dir = Path::new("models/mm_chemostat");
    Study {
        name: "tiny".into(),
        models: vec![
            StudyModel {
                label: "greybox".into(),
                path: dir.join("greybox.gbm"),
            },
            StudyModel {
                label: "blackbox".into(),
                path: dir.join("blackbox.gbm"),
            },
        ],
        sizes: vec![40, 80],
        replicates: 1,
        settings: crate::train::Settings {
            epochs: 2,
            ..Default::default()
        },
        ..Study::chemostat()
    }
}

fn prepared() -> Prepared {
    match prepare(&tiny_study()) {
        Ok(prepared) => prepared,
        Err(failure) => panic!("the shipped chemostat prepares: {failure:?}"),
    }
}

/// Runs a slice, counting runs started and skipped.
fn run_slice(prepared: &Prepared, dir: &Path, shard: Shard) -> (usize, usize, usize) {
    let runs = grid(&prepared.study);
    let selected = shard.select(&runs);
    let started = AtomicUsize::new(0);
    let skipped = AtomicUsize::new(0);
    let observe = |p: Progress| match p {
        Progress::Started(_) => _ = started.fetch_add(1, Ordering::Relaxed),
        Progress::Skipped(_) => _ = skipped.fetch_add(1, Ordering::Relaxed),
        _ => {}
    };
    let results = execute(prepared, &selected, dir, 2, &observe);
    let count = results.map(|r| r.len()).unwrap_or(usize::MAX);
    (count, started.into_inner(), skipped.into_inner())
}

#[test]
fn a_sharded_experiment_reruns_nothing_and_merges_into_tables_figures_and_report() {
    let prepared = prepared();
    let (left, right, joined) = (
        scratch_dir("left"),
        scratch_dir("right"),
        scratch_dir("joined"),
    );
    assert_eq!(
        run_slice(&prepared, &left, Shard { index: 1, count: 2 }),
        (2, 2, 0)
    );
    assert_eq!(
        run_slice(&prepared, &right, Shard { index: 2, count: 2 }),
        (2, 2, 0)
    );
    assert_eq!(
        run_slice(&prepared, &left, Shard { index: 1, count: 2 }),
        (2, 0, 2),
        "re-run skips"
    );
    let (found, _) = read_all(&left);
    assert!(found.iter().all(|r| weights_dir(&left, &r.id)
        .join("weights.safetensors")
        .is_file()));

    let merged = merge(&[left.clone(), right.clone()], &joined).map_err(|f| format!("{f:?}"));
    let merged = merged.unwrap_or_else(|f| panic!("{f}"));
    let ids: Vec<&str> = merged.results.iter().map(|r| r.id.as_str()).collect();
    assert_eq!(
        ids,
        [
            "blackbox-n40-r00",
            "blackbox-n80-r00",
            "greybox-n40-r00",
            "greybox-n80-r00"
        ]
    );
    assert!(merged.results.iter().all(|r| r.is_ok() && r.epochs == 2));
    let csv = std::fs::read_to_string(joined.join(RESULTS_CSV)).unwrap_or_default();
    assert_eq!(csv.lines().count(), 5, "header and four runs:\n{csv}");
    assert!(csv
        .lines()
        .next()
        .is_some_and(|h| h.contains("offline_mse,online_mse")));
    let summary = std::fs::read_to_string(joined.join(SUMMARY_CSV)).unwrap_or_default();
    assert_eq!(summary.lines().count(), 5);

    let names: Vec<&str> = merged
        .published
        .figures
        .iter()
        .map(|f| f.name.as_str())
        .collect();
    for expected in [
        "data_S",
        "data_inputs",
        "mse_offline",
        "mse_online",
        "trajectory_S",
        "closure_r",
        "generalisation_chirp_S",
    ] {
        assert!(names.contains(&expected), "{expected} in {names:?}");
        assert!(joined
            .join("figures")
            .join(format!("{expected}.svg"))
            .is_file());
    }
    let figure = |name: &str| {
        merged
            .published
            .figures
            .iter()
            .find(|f| f.name == name)
            .map(|f| f.svg.clone())
    };
    let online = figure("mse_online").unwrap_or_default();
    assert!(online.contains(">greybox<") && online.contains(">blackbox<"));
    assert_eq!(
        online.matches("<polygon").count(),
        2,
        "one min-max band per model"
    );
    let trajectory = figure("trajectory_S").unwrap_or_default();
    assert_eq!(
        trajectory.matches("<polyline").count(),
        3,
        "data and two models"
    );
    let closure = figure("closure_r").unwrap_or_default();
    assert!(
        closure.contains(">truth<")
            && closure.contains(">greybox<")
            && !closure.contains(">blackbox<")
    );
    let report = std::fs::read_to_string(joined.join(REPORT_FILE)).unwrap_or_default();
    assert!(
        report.contains("<svg") && report.contains("trajectory") || report.contains("Free runs")
    );
    assert!(report.contains("<table>") && report.contains("below <b>blackbox</b>"));
    // The verdict paragraph says where the grey box wins, with the same count as the list.
    let list = "below <b>blackbox</b> (median): online at ";
    let counted = report.find(list).map(|at| &report[at + list.len()..]);
    let wins: Option<(usize, usize)> = counted.and_then(|text| {
        let mut words = text.split_whitespace();
        let wins = words.next()?.parse().ok()?;
        let _of = words.next()?;
        Some((wins, words.next()?.parse().ok()?))
    });
    let (wins, sizes) = wins.expect("the comparison list");
    assert!(
        report.contains("<b>greybox</b> against <b>blackbox</b>. <i>Where the grey box wins:</i>")
    );
    assert_eq!(
        report.contains(&format!("the free run at {wins} of {sizes} sizes")),
        wins > 0,
        "{report}"
    );

    let study = tiny_study();
    let changed = prepare(&Study {
        settings: crate::train::Settings {
            epochs: 3,
            ..study.settings
        },
        ..study
    })
    .map(|p| p.record);
    let refused = changed.map(|record| claim_directory(&left, &record).is_err());
    assert_eq!(
        refused.ok(),
        Some(true),
        "a directory of another study is refused"
    );
    for dir in [left, right, joined] {
        let _ = std::fs::remove_dir_all(dir);
    }
}

#[test]
fn validation_errors_match_an_independent_recomputation_on_the_common_scale() {
    let prepared = prepared();
    let dir = scratch_dir("recompute");
    let runs = grid(&prepared.study);
    let greybox: Vec<_> = runs
        .iter()
        .filter(|r| r.model == 0 && r.size == 80)
        .collect();
    let results = execute(&prepared, &greybox, &dir, 1, &|_| {}).unwrap_or_default();
    let run = representative(&results, "greybox", 80).cloned();
    let run = run.unwrap_or_else(|| panic!("one greybox run: {results:?}"));
    let loaded = &prepared.models[0];
    assert_eq!(
        loaded.offset,
        1550 - 40,
        "40 s of history before the window"
    );
    assert_eq!(loaded.validation.len(), 1800 - loaded.offset);
    let restored = artifacts::restore(&loaded.model, &loaded.source, &weights_dir(&dir, &run.id));
    let (network, setup, _) = restored.unwrap_or_else(|e| panic!("{e}"));
    let table = predict_in_range(
        &loaded.model,
        &network,
        &setup,
        &crate::train::record_of(&loaded.model, &loaded.validation).unwrap(),
        (Mode::Online, crate::train::History::Measured, None),
    );
    let table = table.unwrap_or_else(|e| panic!("{e}"));
    let data = loaded.validation.column("S").unwrap_or_default();
    let window = &data[40..];
    let scale = mean_std(window).1;
    let predicted = &table.columns[1];
    let squared: f64 = (predicted.iter().zip(window).skip(1))
        .map(|(p, a)| ((p - a) / scale).powi(2))
        .sum();
    let expected = squared / (predicted.len() - 1) as f64;
    let found = run.online_mse.unwrap_or(f64::NAN);
    assert!(
        (found - expected).abs() <= 1e-6 * expected,
        "{found} vs {expected}"
    );
    assert_eq!(run.validation_pairs, 1800 - 1550 - 1);
    // The training module's own errors, z-scored with the run's training split, agree once
    // put on the window's scale (its free run stays in range here, so nothing stops it).
    let (info, _) = artifacts::load(&weights_dir(&dir, &run.id)).unwrap_or_else(|e| panic!("{e}"));
    let to_window = (info.normalisation.state_std[0] / scale).powi(2);
    let trained_online = info.metrics.online.map(|set| set.overall * to_window);
    let trained_offline = info.metrics.offline.map(|set| set.overall * to_window);
    let close = |a: Option<f64>, b: Option<f64>| match (a, b) {
        (Some(a), Some(b)) => (a - b).abs() <= 1e-6 * b.abs(),
        _ => false,
    };
    assert!(
        close(trained_online, Some(found)),
        "{trained_online:?} vs {found}"
    );
    assert!(
        close(trained_offline, run.offline_mse),
        "{trained_offline:?} vs {:?}",
        run.offline_mse
    );
    let published = publish(&prepared, &results, &dir, &weights_in(&dir));
    assert!(published.is_ok_and(|p| p.figures.iter().any(|f| f.name == "closure_r")));
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn the_truth_model_reproduces_the_rate_recorded_in_the_data() {
    let path = Path::new("models/mm_chemostat/data/steps.csv");
    let data = crate::data::read(path, &["E0", "S", "r_true"], MinRows::new(2, "test"));
    let data = data.unwrap_or_else(|e| panic!("{e}"));
    let truth = crate::driver::compile_file(Path::new("models/mm_chemostat/truth.gbm"), &[]);
    let truth = truth.map(|c| c.model).unwrap_or_else(|e| panic!("{e:?}"));
    let run = truth_along(&truth, &data, 200).unwrap_or_else(|f| panic!("{f:?}"));
    assert_eq!(run.times.len(), data.len());
    assert!(
        run.deviation < 1e-3,
        "S follows the data: {}",
        run.deviation
    );
    let simulated = run.closure_truth("r").unwrap_or_default();
    let recorded = data.column("r_true").unwrap_or_default();
    let scale = mean_std(recorded).1;
    let worst = (simulated.iter().zip(recorded).skip(200))
        .map(|(s, r)| (s - r).abs())
        .fold(0.0, f64::max);
    assert!(
        worst < 1e-3 * scale,
        "r_true reproduced to {worst} (std {scale})"
    );
}

#[test]
fn sizes_beyond_the_training_rows_are_refused_before_training() {
    let too_big = Study {
        sizes: vec![1510],
        ..tiny_study()
    };
    let message = match prepare(&too_big) {
        Err(super::ExperimentFailure::User(reports)) => format!("{:?}", reports),
        other => format!("unexpected: {:?}", other.map(|p| p.study.name)),
    };
    assert!(message.contains("at most 1509"), "{message}");
}

#[test]
fn a_stopped_study_starts_no_further_run_and_the_next_call_reuses_what_finished() {
    let dir = scratch_dir("stopped");
    let prepared = prepared();
    let runs = grid(&prepared.study);
    let selected = Shard::ALL.select(&runs);
    let stop = std::sync::atomic::AtomicBool::new(false);
    // Asked to stop as the first run finishes: with one job no other run starts.
    let on_progress = |progress: Progress| {
        if let Progress::Finished(..) = progress {
            stop.store(true, Ordering::Relaxed);
        }
    };
    let first = super::execute_until(&prepared, &selected, &dir, (1, &stop), &on_progress);
    let first = first.unwrap_or_default();
    assert_eq!(first.len(), 1, "one run finished before the stop");
    let (count, started, skipped) = run_slice(&prepared, &dir, Shard::ALL);
    assert_eq!(count, selected.len());
    assert_eq!((started, skipped), (selected.len() - 1, 1));
    let (all, _) = read_all(&dir);
    assert_eq!(all.len(), selected.len());
    assert!(
        all.iter().any(|result| *result == first[0]),
        "the finished run is kept"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
