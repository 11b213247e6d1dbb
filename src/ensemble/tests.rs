//! The band against hand-computed cases, the conformal factor, the resampling, the noise
//! estimate against its generating model, the calibration's data (training experiments
//! only), and an ensemble trained, saved, read back and predicted end to end.

use super::band::{calibrated_factor, inside, mixture_cdf, mixture_quantile, BaseBand};
use super::calibrate::{calibrate, count, MemberRuns};
use super::noise::{estimated, NoiseSource, StateNoise};
use super::resample::{draws, out_of_bag};
use super::*;
use crate::record::Record;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// `Phi^-1(0.95)` and `Phi^-1(0.9)`, the standard normal's quantiles.
const Z95: f64 = 1.644_853_626_951_472_2;
const Z90: f64 = 1.281_551_565_544_600_5;

#[test]
fn noise_free_members_band_from_their_smallest_to_their_largest() {
    // Five members at 1..5 without noise: F jumps by 1/5 at each; its 5 % quantile is 1,
    // its 95 % quantile 5, and the median 3.
    let draws: Vec<(f64, f64)> = (1..=5).map(|k| (f64::from(k), 0.0)).collect();
    let band = BaseBand::of(&draws).unwrap();
    assert_eq!(band.median, 3.0);
    assert!((band.below - 2.0).abs() < 1e-9, "{band:?}");
    assert!((band.above - 2.0).abs() < 1e-9, "{band:?}");
}

#[test]
fn one_noisy_member_bands_by_the_normal_quantile() {
    let band = BaseBand::of(&[(10.0, 2.0)]).unwrap();
    assert_eq!(band.median, 10.0);
    assert!((band.below - Z95 * 2.0).abs() < 1e-5, "{band:?}");
    assert!((band.above - Z95 * 2.0).abs() < 1e-5, "{band:?}");
}

#[test]
fn two_distant_members_put_each_tail_at_a_tenth_of_one_normal() {
    // Members at 0 and 1000 with unit noise: each holds half the mass, so the mixture's 5 %
    // quantile is the 10 % quantile of N(0, 1) and its 95 % that of N(1000, 1) at 90 %.
    let draws = [(0.0, 1.0), (1000.0, 1.0)];
    let band = BaseBand::of(&draws).unwrap();
    assert_eq!(band.median, 500.0);
    assert!((band.below - (500.0 + Z90)).abs() < 1e-4, "{band:?}");
    assert!((band.above - (500.0 + Z90)).abs() < 1e-4, "{band:?}");
}

#[test]
fn the_mixture_quantile_inverts_its_distribution_function() {
    let mut random = ChaCha8Rng::seed_from_u64(7);
    let draws: Vec<(f64, f64)> = (0..7)
        .map(|_| {
            let p: f64 = StandardNormal.sample(&mut random);
            let s: f64 = StandardNormal.sample(&mut random);
            (3.0 * p, 0.1 + s.abs())
        })
        .collect();
    for q in [0.01, 0.05, 0.3, 0.5, 0.95, 0.99] {
        let y = mixture_quantile(&draws, q).unwrap();
        assert!((mixture_cdf(&draws, y) - q).abs() < 1e-9, "q {q}: F({y})");
    }
}

#[test]
fn a_score_counts_half_widths_on_its_side_and_stretching_multiplies_them() {
    let band = BaseBand {
        median: 10.0,
        below: 2.0,
        above: 4.0,
        floor: f64::NEG_INFINITY,
    };
    assert_eq!(band.score(13.0), 0.75);
    assert_eq!(band.score(7.0), 1.5);
    assert_eq!(band.score(10.0), 0.0);
    assert_eq!(band.stretched(1.5), (7.0, 16.0));
    assert!(inside(band.stretched(1.5), 7.0) && inside(band.stretched(1.5), 16.0));
    assert!(!inside(band.stretched(1.5), 16.01));
    let flat = BaseBand {
        median: 1.0,
        below: 0.0,
        above: 0.0,
        floor: f64::NEG_INFINITY,
    };
    assert_eq!(flat.score(1.5), f64::INFINITY);
}

#[test]
fn the_conformal_factor_is_the_ceil_n_plus_one_level_th_score() {
    // 19 scores 1..19 at 90 %: rank ceil(20 * 0.9) = 18.
    let scores: Vec<f64> = (1..=19).rev().map(f64::from).collect();
    assert_eq!(calibrated_factor(&scores, 0.9), Some(18.0));
    assert_eq!(calibrated_factor(&scores, 0.5), Some(10.0));
    // 8 scores cannot calibrate 90 %: ceil(9 * 0.9) = 9 > 8.
    assert_eq!(calibrated_factor(&scores[..8], 0.9), None);
    // A cell no member reached scores infinity: a factor there is not a band.
    let mut unreached = scores.clone();
    unreached.extend([f64::INFINITY; 3]);
    assert_eq!(calibrated_factor(&unreached, 0.9), None);
}

#[test]
fn resampling_is_reproducible_by_seed_and_out_of_bag_is_the_rest() {
    let first = draws(Resample::Experiments, 6, 42);
    assert_eq!(first, draws(Resample::Experiments, 6, 42));
    assert_eq!(first.len(), 6);
    assert!(first.iter().all(|&e| e < 6));
    let others: Vec<Vec<usize>> = (43..53)
        .map(|s| draws(Resample::Experiments, 6, s))
        .collect();
    assert!(others.iter().any(|d| *d != first), "every seed drew alike");
    let out = out_of_bag(&first, 6);
    for e in 0..6 {
        assert_ne!(first.contains(&e), out.contains(&e), "experiment {e}");
    }
    assert_eq!(draws(Resample::None, 4, 42), vec![0, 1, 2, 3]);
    assert!(out_of_bag(&draws(Resample::None, 4, 42), 4).is_empty());
}

#[test]
fn the_noise_estimate_recovers_the_combined_model_that_made_the_residuals() {
    let (absolute, relative) = (0.05, 0.08);
    let mut random = ChaCha8Rng::seed_from_u64(3);
    let pairs: Vec<(f64, f64)> = (0..4000)
        .map(|k| {
            let p = 0.01 * f64::from(k % 400);
            let z: f64 = StandardNormal.sample(&mut random);
            (p, z * f64::hypot(absolute, relative * p))
        })
        .collect();
    let noise = estimated("X", &pairs);
    assert!((noise.absolute / absolute - 1.0).abs() < 0.1, "{noise:?}");
    assert!((noise.relative / relative - 1.0).abs() < 0.1, "{noise:?}");
    assert_eq!(noise.source, NoiseSource::Estimated { residuals: 4000 });
}

/// A record of one state measured at every row from the values given.
fn measured(name: &str, values: &[f64]) -> Record {
    let times: Vec<f64> = (0..values.len()).map(|k| k as f64).collect();
    let mut record = Record::complete(name, times, vec![], vec![values.to_vec()]);
    record.source = name.into();
    record
}

/// A run from row 0 predicting `values`.
fn run(values: &[f64]) -> Run {
    Run {
        start: 0,
        states: vec![values.to_vec()],
    }
}

fn unit_noise() -> Vec<StateNoise> {
    vec![StateNoise {
        state: "X".into(),
        absolute: 1.0,
        relative: 0.0,
        source: NoiseSource::Declared,
        floor: None,
    }]
}

#[test]
fn calibration_scores_only_training_experiments_by_their_out_of_bag_members() {
    // Two training experiments and one held out (run index 2). Member 1 left out experiment
    // 0, member 2 experiment 1. Every measured value is 0.
    let zeros = vec![0.0; 6];
    let training = [measured("T0", &zeros), measured("T1", &zeros)];
    let noise = unit_noise();
    let held_out = |poison: f64| {
        vec![
            MemberRuns {
                index: 1,
                out_of_bag: vec![0],
                runs: vec![
                    run(&[0.0, 1.0, 2.0, 3.0, 4.0, 5.0]),
                    run(&[9.0; 6]),
                    run(&[poison; 6]),
                ],
            },
            MemberRuns {
                index: 2,
                out_of_bag: vec![1],
                runs: vec![
                    run(&[9.0; 6]),
                    run(&[0.0, -2.0, 2.0, -2.0, 2.0, -2.0]),
                    run(&[poison; 6]),
                ],
            },
        ]
    };
    let states = ["X".to_string()];
    let calibration = calibrate(&states, &training, &held_out(1e6), &noise);
    // The held-out runs, however wild, change nothing.
    assert_eq!(
        calibration,
        calibrate(&states, &training, &held_out(-3.0), &noise)
    );
    assert_eq!(
        calibration.experiments,
        vec![("T0".to_string(), vec![1]), ("T1".to_string(), vec![2])]
    );
    // Each out-of-bag member alone: its base half-width is Z95 (unit noise), so a cell
    // scores |prediction| / Z95, from row 1 on (row 0 is the start); the in-bag runs at 9
    // would score 9 / Z95 and are never used.
    let mut expected: Vec<f64> = [1.0, 2.0, 3.0, 4.0, 5.0, 2.0, 2.0, 2.0, 2.0, 2.0]
        .iter()
        .map(|p| p / Z95)
        .collect();
    expected.sort_by(f64::total_cmp);
    let scores = &calibration.states[0];
    assert_eq!((scores.cells, scores.pooled), (10, true));
    for (score, want) in scores.scores.iter().zip(&expected) {
        assert!((score - want).abs() < 1e-5, "{:?}", scores.scores);
    }
    // Ten scores calibrate the 90 % level at rank ceil(11 * 0.9) = 10, the largest.
    let factor = calibration.factor(0, 0.9).unwrap();
    assert!((factor - 5.0 / Z95).abs() < 1e-5);
}

#[test]
fn coverage_counts_the_cells_inside_the_stretched_band() {
    // One member predicting 0 with unit noise; factor 1 (the calibration's only score is
    // 1, nine more at 0 make rank 10 of 10 the 1): the band is +-Z95.
    let noise = unit_noise();
    let mut scores = vec![0.0; 9];
    scores.push(1.0);
    let calibration = Calibration {
        calibrated: true,
        source: String::new(),
        reason: None,
        experiments: vec![],
        states: vec![StateScores {
            state: "X".into(),
            cells: 10,
            pooled: false,
            scores,
        }],
    };
    let record = measured("V", &[5.0, 0.5, -1.6, 1.7, -3.0]);
    let runs = [run(&[0.0; 5])];
    let runs: Vec<&Run> = runs.iter().collect();
    let (counts, base) = count(&record, &runs, (&noise, &calibration), 0.9);
    // Row 0 is the start; of 0.5, -1.6, 1.7, -3.0 the first two lie within +-1.645.
    assert_eq!(
        (counts[0].cells, counts[0].inside, counts[0].unreached),
        (4, 2, 0)
    );
    assert_eq!((base.cells, base.inside), (4, 2));
    // A run that stopped reaches no cell after its stop: those count outside.
    let stopped = [run(&[0.0, 0.0, f64::NAN, f64::NAN, f64::NAN])];
    let stopped: Vec<&Run> = stopped.iter().collect();
    let (counts, _) = count(&record, &stopped, (&noise, &calibration), 0.9);
    assert_eq!(
        (counts[0].cells, counts[0].inside, counts[0].unreached),
        (4, 1, 3)
    );
}

/// Four chemostat experiments of 80 rows (`run1` to `run4`).
fn chemostat_records(model: &crate::ir::Model) -> Vec<Record> {
    use crate::train::fixtures::{chemostat, record};
    (1..=4)
        .map(|seed| {
            let mut r = record(model, &chemostat::data(80, (0.002, 0.02), seed).0);
            r.name = format!("run{seed}");
            r
        })
        .collect()
}

#[test]
fn an_ensemble_needs_two_members_and_two_whole_experiments_to_resample() {
    use crate::train::{Part, Recipe, TrainOptions, TrainingData};
    let model = crate::train::fixtures::chemostat::grey_box();
    let records = chemostat_records(&model);
    let keep = Keep {
        directory: std::env::temp_dir().join("gbc-ensemble-never-written"),
        model: ("model.gbm", ""),
        data: "fixture",
        recoveries: 0,
    };
    let plan = |members| Plan {
        members,
        resample: Resample::Experiments,
        jobs: 1,
        level: 0.9,
    };
    let attempt = |train: &[Record], part: Part, members: usize| {
        let data = TrainingData {
            train,
            validation: &records[3..],
            part,
        };
        let options = (&TrainOptions::default(), &Recipe::paper());
        train_ensemble(&model, &data, options, &plan(members), &keep, &|_| {})
    };
    let one = attempt(&records[..1], Part::All, 3);
    assert!(matches!(one, Err(EnsembleError::CannotResample { .. })));
    let tail = attempt(&records[..3], Part::Tail(0.3), 3);
    assert!(matches!(tail, Err(EnsembleError::CannotResample { .. })));
    let alone = attempt(&records[..3], Part::All, 1);
    assert!(matches!(
        alone,
        Err(EnsembleError::TooFewMembers { found: 1 })
    ));
    assert!(!keep.directory.exists());
}

/// Members train on draws of the training experiments only, the band is calibrated on
/// those alone and counted on the held-out one, the run reads back, and its prediction
/// has a band around the median at every row.
#[test]
fn an_ensemble_trains_saves_and_predicts_a_band_around_its_median() {
    use crate::train::{History, Part, Recipe, TrainOptions, TrainingData};
    use crate::trained::predict::Mode;
    let model = crate::train::fixtures::chemostat::grey_box();
    let records = chemostat_records(&model);
    let (train, held) = records.split_at(3);
    let data = TrainingData {
        train,
        validation: held,
        part: Part::All,
    };
    let directory = std::env::temp_dir().join(format!("gbc-ensemble-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&directory);
    let keep = Keep {
        directory: directory.clone(),
        model: ("model.gbm", ""),
        data: "fixture",
        recoveries: 0,
    };
    let plan = Plan {
        members: 4,
        resample: Resample::Experiments,
        jobs: 2,
        level: 0.9,
    };
    let options = TrainOptions {
        epochs: 2,
        seed: 5,
        ..TrainOptions::default()
    };
    // `auto` (the default) chooses the stop once; every member ends there.
    let heard = std::sync::Mutex::new((None, vec![0; plan.members]));
    let listen = |event: MemberEvent| {
        let mut heard = heard.lock().unwrap();
        match event {
            MemberEvent::Chosen { stop, .. } => heard.0 = Some(stop),
            MemberEvent::Epoch { member, epoch, .. } => {
                heard.1[member - 1] = heard.1[member - 1].max(epoch);
            }
            _ => {}
        }
    };
    let trained = train_ensemble(
        &model,
        &data,
        (&options, &Recipe::paper()),
        &plan,
        &keep,
        &listen,
    )
    .unwrap();
    let (stop, last_epochs) = heard.into_inner().unwrap();
    let stop = stop.expect("auto chose a stop");
    assert!(
        last_epochs.iter().all(|&e| e == stop),
        "{stop} {last_epochs:?}"
    );
    let info = &trained.info;
    let names = ["run1", "run2", "run3"];
    for member in &info.members {
        let seed = 5 + member.index as u64 - 1;
        assert_eq!(member.seed, seed);
        let drawn: Vec<String> = (draws(Resample::Experiments, 3, seed).iter())
            .map(|&e| names[e].to_string())
            .collect();
        assert_eq!(member.trained_on, drawn);
        for name in names {
            assert_ne!(
                drawn.contains(&name.to_string()),
                member.out_of_bag.contains(&name.to_string())
            );
        }
        assert!(directory.join(&member.run).join("run.json").is_file());
    }
    let calibrated: Vec<&str> = info
        .calibration
        .experiments
        .iter()
        .map(|(n, _)| n.as_str())
        .collect();
    assert_eq!(calibrated, names);
    assert!(info.calibration.calibrated, "{:?}", info.calibration);
    let coverage = info.coverage.as_ref().unwrap();
    assert_eq!(coverage.experiments, vec!["run4".to_string()]);
    assert_eq!(coverage.overall.cells, 79);
    assert_eq!(info.errors.as_ref().unwrap().members.len(), 4);
    let loaded = load(&model, "", &directory).unwrap();
    assert_eq!(&loaded.info, info);
    let how = (Mode::Online, History::Held, 2);
    let tables = predict::member_tables(&model, ("", &loaded), held, how, &|_| {}).unwrap();
    let mine: Vec<_> = tables.iter().map(|t| t[0].clone()).collect();
    let band = predict_table(&model, info, (&held[0], &mine), Some(0.9)).unwrap();
    let column = |name: &str| {
        let index = band.table.header.iter().position(|h| h == name).unwrap();
        band.table.columns[index].clone()
    };
    let (median, lo, hi) = (column("S"), column("S_lo"), column("S_hi"));
    assert_eq!(median.len(), 80);
    for row in 0..80 {
        assert!(
            lo[row] <= median[row] && median[row] <= hi[row],
            "row {row}"
        );
        assert!(lo[row] < hi[row], "row {row}");
    }
    assert_eq!(band.coverage[0].cells, 79);
    assert_eq!(band.coverage[0].inside, coverage.overall.inside);
    let offline = predict_table(&model, info, (&held[0], &mine), None).unwrap();
    assert!(!offline.table.header.iter().any(|h| h.ends_with("_lo")));
    let _ = std::fs::remove_dir_all(&directory);
}
