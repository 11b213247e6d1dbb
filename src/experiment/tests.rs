//! Unit tests of the experiment module: grid and shards, studies as JSON, results on disk,
//! spreads and summaries. End-to-end runs are in `tests_run.rs`.

use std::path::{Path, PathBuf};

use super::grid::{grid, run_id, Shard};
use super::results::{
    read_all, read_result, result_path, spread, summarise, write_result, Measure, RunResult,
    RunStatus,
};
use super::study::{parse_model_argument, parse_sizes, StudyModel};
use super::{ExperimentError, Study, Validation};

/// A fresh, empty directory under the system's temporary directory.
pub(super) fn scratch_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("gbc-experiment-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn small_study() -> Study {
    Study {
        models: vec![
            StudyModel {
                label: "a".into(),
                path: "a.gbm".into(),
            },
            StudyModel {
                label: "b".into(),
                path: "b.gbm".into(),
            },
        ],
        sizes: vec![200, 100, 500],
        replicates: 3,
        first_seed: 7,
        ..Study::chemostat()
    }
}

#[test]
fn the_grid_has_one_run_per_model_size_and_replicate_largest_first() {
    let study = small_study();
    let runs = grid(&study);
    assert_eq!(runs.len(), 2 * 3 * 3);
    let mut ids: Vec<&str> = runs.iter().map(|r| r.id.as_str()).collect();
    ids.sort_unstable();
    ids.dedup();
    assert_eq!(ids.len(), runs.len(), "ids are unique");
    assert!(runs.windows(2).all(|w| w[0].size >= w[1].size));
    for run in &runs {
        assert_eq!(run.seed, 7 + run.replicate as u64);
        let label = &study.models[run.model].label;
        assert_eq!(run.id, run_id(label, run.size, run.replicate));
    }
    assert_eq!(run_id("greybox", 500, 3), "greybox-n500-r03");
}

#[test]
fn shards_partition_the_grid_evenly() {
    let runs = grid(&small_study());
    for count in 1..=7 {
        let mut seen = vec![0; runs.len()];
        let mut lengths = Vec::new();
        for index in 1..=count {
            let shard = Shard { index, count };
            let selected = shard.select(&runs);
            lengths.push(selected.len());
            for run in selected {
                let position = runs
                    .iter()
                    .position(|r| r.id == run.id)
                    .unwrap_or(usize::MAX);
                seen[position] += 1;
            }
        }
        assert!(seen.iter().all(|n| *n == 1), "count {count}: {seen:?}");
        let (least, most) = (lengths.iter().min(), lengths.iter().max());
        assert!(
            most.zip(least).is_some_and(|(m, l)| m - l <= 1),
            "{lengths:?}"
        );
    }
}

#[test]
fn shard_specs_parse_and_bad_ones_are_refused() {
    assert_eq!(
        "3/8".parse::<Shard>().ok(),
        Some(Shard { index: 3, count: 8 })
    );
    assert_eq!(" 1 / 1 ".parse::<Shard>().ok(), Some(Shard::ALL));
    for bad in ["0/3", "4/3", "3", "a/b", "1/0", "-1/2", ""] {
        let error = bad.parse::<Shard>().err().map(|e| e.to_string());
        assert!(
            error.as_deref().is_some_and(|e| e.contains("`K/N`")),
            "{bad}: {error:?}"
        );
    }
    assert_eq!(Shard { index: 2, count: 5 }.to_string(), "2/5");
}

#[test]
fn spread_takes_median_min_and_max_counting_infinities() {
    let check = |values: &[f64], expected: Option<(f64, f64, f64)>| {
        let found = spread(values).map(|s| (s.median, s.min, s.max));
        assert_eq!(found, expected, "{values:?}");
    };
    check(&[3.0, 1.0, 2.0], Some((2.0, 1.0, 3.0)));
    check(&[4.0, 1.0, 2.0, 3.0], Some((2.5, 1.0, 4.0)));
    check(&[1.0, f64::INFINITY, 2.0], Some((2.0, 1.0, f64::INFINITY)));
    check(
        &[f64::INFINITY, f64::INFINITY],
        Some((f64::INFINITY, f64::INFINITY, f64::INFINITY)),
    );
    check(&[f64::NAN], None);
    check(&[], None);
}

fn result(id: &str, model: &str, size: usize, online: Option<f64>) -> RunResult {
    RunResult {
        id: id.into(),
        model: model.into(),
        size,
        replicate: 0,
        seed: 1,
        epochs: 2,
        status: RunStatus::Ok,
        error: None,
        offline_mse: Some(1e-4),
        online_mse: online,
        offline_per_state: vec![Measure::new("S", 1e-4)],
        online_per_state: vec![Measure::new("S", online.unwrap_or(f64::INFINITY))],
        generalisation: vec![Measure::new("chirp.csv", 0.5)],
        params: vec![Measure::new("Y_X", 0.43)],
        final_loss: Some(2e-3),
        train_pairs: size,
        validation_pairs: 250,
        wall_seconds: 1.25,
        warnings: vec!["stiff".into()],
        left_range: Some("the free run left the physical range at t = 3".into()),
    }
}

#[test]
fn results_round_trip_through_json_including_diverged_and_failed_runs() {
    let dir = scratch_dir("round-trip");
    let ok = result("a-n100-r00", "a", 100, Some(0.25));
    let diverged = result("a-n100-r01", "a", 100, None);
    let spec = &grid(&small_study())[0];
    let failed = RunResult::failed(spec, "a", 2, "training diverged".into(), 0.5);
    for r in [&ok, &diverged, &failed] {
        assert!(write_result(&dir, r).is_ok());
        assert_eq!(read_result(&dir, &r.id).as_ref(), Some(r));
    }
    assert_eq!(
        read_result(&dir, &diverged.id).and_then(|r| r.online()),
        Some(f64::INFINITY)
    );
    assert_eq!(failed.online(), None, "failed runs have no error");
    assert!(read_result(&dir, "missing").is_none());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn unreadable_and_misnamed_result_files_do_not_count_as_finished() {
    let dir = scratch_dir("unreadable");
    let ok = result("a-n100-r00", "a", 100, Some(0.25));
    assert!(write_result(&dir, &ok).is_ok());
    let corrupt = result_path(&dir, "a-n100-r01");
    assert!(std::fs::write(&corrupt, "{\"id\": \"a-n1").is_ok());
    let misnamed = result_path(&dir, "a-n200-r00");
    assert!(std::fs::copy(result_path(&dir, &ok.id), &misnamed).is_ok());
    assert!(read_result(&dir, "a-n100-r01").is_none());
    assert!(
        read_result(&dir, "a-n200-r00").is_none(),
        "the id inside must match"
    );
    let (found, unreadable) = read_all(&dir);
    assert_eq!(found, vec![ok]);
    unreadable_sorted(unreadable, &[corrupt, misnamed]);
    let _ = std::fs::remove_dir_all(&dir);
}

fn unreadable_sorted(mut found: Vec<PathBuf>, expected: &[PathBuf]) {
    found.sort();
    let mut expected = expected.to_vec();
    expected.sort();
    assert_eq!(found, expected);
}

#[test]
fn summaries_take_the_median_over_replicates_and_count_failures() {
    let study = Study {
        models: vec![StudyModel {
            label: "a".into(),
            path: "a.gbm".into(),
        }],
        sizes: vec![100],
        generalisation: vec!["chirp.csv".into()],
        ..small_study()
    };
    let spec = &grid(&study)[0];
    let results = vec![
        result("a-n100-r00", "a", 100, Some(0.3)),
        result("a-n100-r01", "a", 100, None),
        result("a-n100-r02", "a", 100, Some(0.1)),
        RunResult::failed(spec, "a", 2, "diverged".into(), 0.1),
        result("b-n100-r00", "b", 100, Some(9.0)),
    ];
    let rows = summarise(&study, &results);
    assert_eq!(rows.len(), 1);
    let row = &rows[0];
    assert_eq!((row.ok, row.failed, row.blown_up), (3, 1, 1));
    let online = row.online.map(|s| (s.median, s.min, s.max));
    assert_eq!(online, Some((0.3, 0.1, f64::INFINITY)));
    assert_eq!(row.generalisation[0].1.map(|s| s.median), Some(0.5));
}

#[test]
fn studies_read_back_from_json_and_errors_point_into_the_file() {
    let study = Study::bioreactor();
    let parsed = Study::parse("study.json", &study.to_json());
    assert_eq!(parsed.ok(), Some(study));
    let text = "{\n  \"name\": \"x\",\n  \"epochz\": 3\n}";
    match Study::parse("bad.json", text) {
        Err(ExperimentError::BadStudy { reason, span, .. }) => {
            assert!(reason.contains("epochz"), "{reason}");
            let offset = span.map(|s| s.offset()).unwrap_or(0);
            assert!((text.find("\"epochz\"").unwrap_or(0)..=text.len()).contains(&offset));
        }
        other => panic!("expected a bad study, found {other:?}"),
    }
}

/// The training settings sit flat in the file; a bad one is named by its field, never by
/// a flag, and a misspelt one is refused.
#[test]
fn study_files_name_bad_settings_by_their_field() {
    let mut value = serde_json::to_value(Study::chemostat()).unwrap();
    value["batch_size"] = serde_json::json!(0);
    let text = serde_json::to_string_pretty(&value).unwrap();
    let message = Study::parse("study.json", &text).unwrap_err().to_string();
    assert!(
        message.contains("batch_size") && !message.contains("--batch"),
        "{message}"
    );
    let object = value.as_object_mut().unwrap();
    object.remove("batch_size");
    object.remove("learning_rate");
    object.insert("precision".into(), serde_json::json!("f64"));
    let study = Study::parse("study.json", &serde_json::to_string(&value).unwrap()).unwrap();
    let defaults = crate::train::Settings::default();
    assert_eq!(study.settings.batch_size, defaults.batch_size);
    assert_eq!(study.settings.learning_rate, defaults.learning_rate);
    assert_eq!(
        study.settings.precision,
        crate::engine::graph::Precision::F64
    );
    value["batch"] = serde_json::json!(10);
    match Study::parse("study.json", &serde_json::to_string(&value).unwrap()) {
        Err(ExperimentError::BadStudy { reason, .. }) => {
            assert!(
                reason.contains("`batch`") && reason.contains("batch_size"),
                "{reason}"
            )
        }
        other => panic!("expected an unknown field, found {other:?}"),
    }
}

#[test]
fn study_checks_refuse_bad_settings() {
    let refused = |study: Study, needle: &str| {
        let message = study
            .check()
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(message.contains(needle), "{needle}: {message}");
    };
    refused(
        Study {
            sizes: vec![],
            ..Study::chemostat()
        },
        "sizes",
    );
    refused(
        Study {
            sizes: vec![100, 0],
            ..Study::chemostat()
        },
        "sizes",
    );
    refused(
        Study {
            replicates: 0,
            ..Study::chemostat()
        },
        "replicates",
    );
    refused(
        Study {
            settings: crate::train::Settings {
                epochs: 0,
                ..Default::default()
            },
            ..Study::chemostat()
        },
        "epochs",
    );
    refused(
        Study {
            settings: crate::train::Settings {
                learning_rate: -1.0,
                ..Default::default()
            },
            ..Study::chemostat()
        },
        "learning_rate",
    );
    refused(
        Study {
            validation: Validation::FromRow(0),
            ..Study::chemostat()
        },
        "validation",
    );
    let mut twice = Study::chemostat();
    twice.models[1].label = "greybox".into();
    refused(twice, "twice");
    assert!(Study::chemostat().check().is_ok() && Study::bioreactor_demo().check().is_ok());
}

#[test]
fn identity_ignores_the_grid_extent_but_not_training_settings() {
    let study = Study::chemostat();
    let wider = Study {
        sizes: vec![50],
        replicates: 99,
        title: "other".into(),
        representative_size: Some(50),
        ..study.clone()
    };
    assert_eq!(study.identity(), wider.identity());
    let longer = Study {
        settings: crate::train::Settings {
            epochs: 101,
            ..study.settings
        },
        ..study.clone()
    };
    assert_ne!(study.identity(), longer.identity());
    let retrained = Study {
        training: super::study::Training::MultiStep,
        ..study.clone()
    };
    assert_ne!(study.identity(), retrained.identity());
    let reseeded = Study {
        first_seed: 2,
        ..study.clone()
    };
    assert_ne!(study.identity(), reseeded.identity());
}

#[test]
fn figure_size_is_the_grid_size_closest_to_the_representative_one() {
    let with = |sizes: Vec<usize>, wanted: Option<usize>| {
        Study {
            sizes,
            representative_size: wanted,
            ..Study::chemostat()
        }
        .figure_size()
    };
    assert_eq!(with(vec![100, 500, 1500], Some(500)), 500);
    assert_eq!(with(vec![100, 300, 1000], Some(500)), 300);
    assert_eq!(with(vec![100, 3000], None), 100);
    assert_eq!(with(vec![1000, 2000], Some(1500)), 2000);
}

#[test]
fn command_line_lists_parse() {
    assert_eq!(parse_sizes("100, 200,500").ok(), Some(vec![100, 200, 500]));
    for bad in ["", "100,,200", "0", "1e3", "-5"] {
        assert!(parse_sizes(bad).is_err(), "{bad}");
    }
    let labelled = parse_model_argument("gb=models/bioreactor/gb1.gbm").ok();
    assert_eq!(
        labelled.map(|m| (m.label, m.path)),
        Some(("gb".into(), "models/bioreactor/gb1.gbm".into()))
    );
    let stem = parse_model_argument("models/bioreactor/gb2.gbm").ok();
    assert_eq!(stem.map(|m| m.label), Some("gb2".into()));
    assert!(parse_model_argument("a b=x.gbm").is_err());
}

#[test]
fn shipped_study_files_are_the_presets() {
    for name in Study::PRESETS {
        let path = Path::new("experiments").join(format!("{name}.json"));
        let study = Study::load(&path).map_err(|e| e.to_string());
        assert_eq!(
            study,
            Ok(Study::preset(name).unwrap_or_else(Study::chemostat)),
            "{name}"
        );
        for file in Study::preset(name).iter().flat_map(Study::files) {
            assert!(file.is_file(), "{name}: {} is shipped", file.display());
        }
    }
}

#[test]
fn the_job_queue_runs_every_item_once_and_stops_at_the_first_failure() {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;
    let seen = Mutex::new(Vec::new());
    let outcome = super::execute::run_queue(4, 10, &|item| {
        seen.lock().map(|mut s| s.push(item)).unwrap_or_default();
        Ok(())
    });
    assert!(outcome.is_ok());
    let mut seen = seen.into_inner().unwrap_or_default();
    seen.sort_unstable();
    assert_eq!(seen, (0..10).collect::<Vec<_>>());
    let done = AtomicUsize::new(0);
    let outcome = super::execute::run_queue(1, 10, &|item| {
        done.fetch_add(1, Ordering::Relaxed);
        if item == 2 {
            Err(super::ExperimentFailure::Internal("disk full".into()))
        } else {
            Ok(())
        }
    });
    assert!(matches!(outcome, Err(super::ExperimentFailure::Internal(m)) if m == "disk full"));
    assert_eq!(done.into_inner(), 3, "nothing runs after the failure");
}

/// With two jobs the items run two at a time: no job is left idle while the other drains
/// the queue. Eight items of 50 ms each: nearly every one overlaps another (a queue drained
/// by one job after the first pair overlaps two).
#[test]
fn two_jobs_run_their_items_side_by_side() {
    use std::sync::Mutex;
    use std::time::{Duration, Instant};
    let origin = Instant::now();
    let spans = Mutex::new(Vec::new());
    let outcome = super::execute::run_queue(2, 8, &|_| {
        let start = origin.elapsed();
        std::thread::sleep(Duration::from_millis(50));
        let span = (start, origin.elapsed());
        spans.lock().map(|mut s| s.push(span)).unwrap_or_default();
        Ok(())
    });
    assert!(outcome.is_ok());
    let spans = spans.into_inner().unwrap_or_default();
    assert_eq!(spans.len(), 8);
    let overlapping = (spans.iter().enumerate())
        .filter(|&(i, a)| (spans.iter().enumerate()).any(|(j, b)| i != j && a.0 < b.1 && b.0 < a.1))
        .count();
    assert!(
        overlapping >= 6,
        "{overlapping} of 8 items ran beside another"
    );
}

#[test]
fn studies_on_data_sets_read_back_and_one_file_stays_a_string() {
    // The paper's studies keep `"data": "path"`, so existing experiment directories keep
    // their identity; a data set is a list with held-out experiments.
    let json = Study::chemostat().to_json();
    assert!(json.contains("\"data\": \"models/"), "{json}");
    let lab = Study::load(Path::new("experiments/lab.json")).map_err(|e| e.to_string());
    let lab = lab.expect("the shipped lab study reads");
    assert!(lab.on_data_set());
    assert_eq!(lab.data.paths().len(), 4);
    assert_eq!(lab.validation, Validation::Holdout(vec!["run4".into()]));
    for file in lab.files() {
        assert!(file.is_file(), "{} is shipped", file.display());
    }
    assert_eq!(
        Study::parse("lab.json", &lab.to_json()).ok(),
        Some(lab.clone())
    );
    // Several files need held-out experiments; a data set has no generalisation records.
    let refused = |study: Study, option: &str| match study.check() {
        Err(ExperimentError::BadOption { option: found, .. }) => assert_eq!(found, option),
        other => panic!("expected {option} refused, found {other:?}"),
    };
    refused(
        Study {
            validation: Validation::FromRow(100),
            ..lab.clone()
        },
        "--data",
    );
    refused(
        Study {
            generalisation: vec!["x.csv".into()],
            ..lab.clone()
        },
        "--generalisation",
    );
    refused(
        Study {
            validation: Validation::Holdout(Vec::new()),
            ..lab
        },
        "--holdout",
    );
}
