//! Runs that are never lost (`gbc train`): a run stopped after some epochs and resumed ends
//! bit for bit where the uninterrupted run ends; Ctrl-C leaves a checkpoint; early stopping
//! keeps the best epoch; the renamed flags and their deprecated spellings.

use std::path::Path;

use crate::child::{gbc_command, Running};
use crate::cli::{gbc, scratch};

/// The bioreactor GB1 model and its record, trained by the run tests here and in `runs`.
pub const GB1: &str = "models/bioreactor/gb1.gbm";
/// The bioreactor record.
pub const STEPS: &str = "models/bioreactor/data/steps.csv";

/// A short multi-step training of GB1 that crosses the curriculum's switch to rollouts.
pub const SHORT: [&str; 12] = [
    "--epochs",
    "8",
    "--train-points",
    "200",
    "--horizon",
    "4",
    "--warmup-share",
    "0.5",
    "--ramp",
    "0.25",
    "--seed",
    "3",
];

/// [`SHORT`] with `extra` flags, an `--epochs` among them replacing its 8.
fn short_with<'a>(extra: &[&'a str]) -> Vec<&'a str> {
    let epochs_given = extra.contains(&"--epochs");
    let mut args: Vec<&str> = if epochs_given {
        SHORT[2..].to_vec()
    } else {
        SHORT.to_vec()
    };
    args.extend(extra);
    args
}

fn train(run: &Path, extra: &[&str]) -> std::process::Output {
    let run = run.display().to_string();
    let mut args = vec!["train", GB1, STEPS, "-o", &run];
    args.extend(short_with(extra));
    gbc(&args)
}

fn stderr(output: &std::process::Output) -> String {
    String::from_utf8_lossy(&output.stderr).to_string()
}

fn bytes(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Epoch rows of a run's log.csv: (epoch, train loss, online validation).
fn log_rows(run: &Path) -> Vec<(usize, String, String)> {
    let text = std::fs::read_to_string(run.join("log.csv")).unwrap();
    (text.lines().skip(2))
        .map(|line| {
            let cells: Vec<&str> = line.split(',').collect();
            (cells[0].parse().unwrap(), cells[3].into(), cells[5].into())
        })
        .collect()
}

#[test]
fn a_run_stopped_and_resumed_ends_bit_for_bit_where_an_uninterrupted_run_ends() {
    let dir = scratch("resume");
    for engine in ["graph", "fused"] {
        let whole = dir.join(format!("whole-{engine}"));
        // Checkpoints every 3 epochs must not change the run either.
        let output = train(&whole, &["--engine", engine, "--checkpoint-every", "3"]);
        assert!(output.status.success(), "{}", stderr(&output));
        assert!(
            !whole.join("checkpoint.json").exists(),
            "a finished run keeps no checkpoint"
        );
        let stopped = dir.join(format!("stopped-{engine}"));
        let output = train(&stopped, &["--engine", engine, "--stop-after-epochs", "5"]);
        assert_eq!(output.status.code(), Some(1));
        let message = stderr(&output);
        assert!(message.contains("E0430"), "{message}");
        assert!(message.contains("gbc train --resume"), "{message}");
        assert!(stopped.join("checkpoint.json").exists());
        assert!(!stopped.join("weights.safetensors").exists());
        assert_eq!(log_rows(&stopped).len(), 5);
        let resumed = gbc(&["train", "--resume", &stopped.display().to_string()]);
        assert!(resumed.status.success(), "{}", stderr(&resumed));
        assert!(stderr(&resumed).contains("after epoch 5 of 8"));
        assert_eq!(
            bytes(&whole.join("weights.safetensors")),
            bytes(&stopped.join("weights.safetensors")),
            "{engine}: the resumed run's weights differ"
        );
        let losses = |run: &Path| -> Vec<String> {
            log_rows(run).into_iter().map(|(_, loss, _)| loss).collect()
        };
        assert_eq!(losses(&whole), losses(&stopped));
        assert!(!stopped.join("checkpoint.json").exists());
    }
}

#[test]
fn resuming_needs_a_checkpoint_and_the_same_files() {
    let dir = scratch("resume-refused");
    let finished = dir.join("finished");
    assert!(train(&finished, &["--epochs", "1"]).status.success());
    let output = gbc(&["train", "--resume", &finished.display().to_string()]);
    assert_eq!(output.status.code(), Some(1));
    assert!(stderr(&output).contains("E0431"), "{}", stderr(&output));
    // The data changed since the checkpoint: refused, naming the file.
    let data = dir.join("steps.csv");
    std::fs::copy(STEPS, &data).unwrap();
    let stopped = dir.join("stopped").display().to_string();
    let data_text = data.display().to_string();
    let mut args = vec!["train", GB1, &data_text, "-o", &stopped];
    args.extend(short_with(&["--stop-after-epochs", "2"]));
    assert_eq!(gbc(&args).status.code(), Some(1));
    let mut text = std::fs::read_to_string(&data).unwrap();
    text.push('\n');
    std::fs::write(&data, text).unwrap();
    let output = gbc(&["train", "--resume", &stopped]);
    assert_eq!(output.status.code(), Some(1));
    let message = stderr(&output);
    assert!(
        message.contains("E0432") && message.contains("steps.csv"),
        "{message}"
    );
}

/// Every file of a run directory with its bytes, by name.
fn snapshot(run: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> = (std::fs::read_dir(run).unwrap())
        .map(|entry| entry.unwrap().path())
        .map(|path| (path.display().to_string(), bytes(&path)))
        .collect();
    files.sort();
    files
}

#[test]
fn resume_refuses_every_other_flag_and_leaves_the_run_untouched() {
    let dir = scratch("resume-flags");
    let stopped = dir.join("stopped");
    let output = train(&stopped, &["--stop-after-epochs", "2"]);
    assert_eq!(output.status.code(), Some(1), "{}", stderr(&output));
    let before = snapshot(&stopped);
    let run = stopped.display().to_string();
    let elsewhere = dir.join("elsewhere");
    let elsewhere_text = elsewhere.display().to_string();
    let cases: [(&[&str], &[&str]); 4] = [
        (&["--resume", &run, "--epochs", "5"], &["--epochs"]),
        (
            &["--seed=4", "--resume", &run, "--lr", "0.1"],
            &["--seed", "--lr"],
        ),
        (
            &["--resume", &run, "-o", &elsewhere_text, "--force"],
            &["--output", "--force"],
        ),
        (
            &["--resume", &run, "--stop-after-epochs", "3"],
            &["--stop-after-epochs"],
        ),
    ];
    for (args, named) in cases {
        let output = gbc(&[&["train"], args].concat());
        let message = stderr(&output);
        assert_eq!(output.status.code(), Some(1), "{args:?}: {message}");
        assert!(message.contains("gbm::E0434"), "{args:?}: {message}");
        for flag in named {
            assert!(
                message.contains(flag),
                "{args:?} does not name {flag}: {message}"
            );
        }
        assert!(
            message.contains("flags it was started with") && message.contains("start a new run"),
            "{message}"
        );
        assert_eq!(snapshot(&stopped), before, "{args:?} changed the run");
    }
    assert!(!elsewhere.exists());
    // The global --message-format changes only how diagnostics print: it may go along.
    let output = gbc(&["--message-format", "json", "train", "--resume", &run]);
    assert!(output.status.success(), "{}", stderr(&output));
    assert_eq!(log_rows(&stopped).len(), 8);
}

/// [`SHORT`] over 16 epochs with a checkpoint after each one (which changes nothing in the
/// run): a signal can be sent once the first epoch is done.
const SIGNALLED: [&str; 4] = ["--epochs", "16", "--checkpoint-every", "1"];

/// The log without its seconds (the last column).
fn log_without_time(run: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(run.join("log.csv")).unwrap();
    (text.lines())
        .map(|line| {
            line.rsplit_once(',')
                .map_or(line, |(kept, _)| kept)
                .to_string()
        })
        .collect()
}

/// The summary on stdout without its timing (first line) and the run's path (last line).
fn summary_without_time(output: &std::process::Output) -> Vec<String> {
    let text = String::from_utf8_lossy(&output.stdout).to_string();
    let lines: Vec<String> = text.lines().map(String::from).collect();
    let kept = lines.len().saturating_sub(1);
    assert!(kept > 2, "{text}");
    lines[1..kept].to_vec()
}

#[cfg(unix)]
#[test]
fn a_run_stopped_by_sigint_and_resumed_ends_byte_for_byte_where_an_uninterrupted_run_ends() {
    let dir = scratch("signal-resume");
    let whole = dir.join("whole");
    let uninterrupted = train(&whole, &SIGNALLED);
    assert!(uninterrupted.status.success(), "{}", stderr(&uninterrupted));
    let stopped = dir.join("stopped");
    let run = stopped.display().to_string();
    let mut args = vec!["train", GB1, STEPS, "-o", &run];
    args.extend(short_with(&SIGNALLED));
    let mut child = Running::start(&mut gbc_command(&args), false);
    let checkpoint = stopped.join("checkpoint.json");
    child.until("a checkpoint is written", || checkpoint.exists());
    child.signal("INT");
    let end = child.finish();
    let rest = end.stderr.join("\n");
    assert_eq!(end.status.code(), Some(1), "{rest}");
    assert!(rest.contains("E0430"), "{rest}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&checkpoint).unwrap()).unwrap();
    let epoch = json["epoch"].as_u64().unwrap();
    assert!((1..16).contains(&epoch), "stopped after epoch {epoch}");
    let resumed = gbc(&["train", "--resume", &run]);
    assert!(resumed.status.success(), "{}", stderr(&resumed));
    let said = format!("after epoch {epoch} of 16");
    assert!(stderr(&resumed).contains(&said), "{}", stderr(&resumed));
    assert!(!checkpoint.exists());
    for file in [
        "weights.safetensors",
        "run.json",
        "report.html",
        "model.gbm",
    ] {
        let same = bytes(&whole.join(file)) == bytes(&stopped.join(file));
        assert!(
            same,
            "the resumed run's {file} differs (stopped after epoch {epoch})"
        );
    }
    assert_eq!(log_without_time(&whole), log_without_time(&stopped));
    assert_eq!(
        summary_without_time(&uninterrupted),
        summary_without_time(&resumed)
    );
}

#[cfg(unix)]
#[test]
fn ctrl_c_ends_the_epoch_and_leaves_a_checkpoint() {
    let dir = scratch("sigint");
    let run = dir.join("run");
    let mut command = gbc_command(&["train", GB1, STEPS, "--objective", "one-step"]);
    command.args(["--epochs", "1000000", "--train-points", "200", "-o"]);
    let mut child = Running::start(command.arg(&run), false);
    // The first progress line that counts epochs done: at least one whole epoch is done.
    child.line(|line| line.contains("/1000000 epochs,"));
    child.signal("INT");
    let end = child.finish();
    let rest = end.stderr.join("\n");
    assert_eq!(end.status.code(), Some(1), "{rest}");
    assert!(
        rest.contains("stopping: training ends before its next batch"),
        "{rest}"
    );
    assert!(
        rest.contains("E0430") && rest.contains("--resume"),
        "{rest}"
    );
    let checkpoint = std::fs::read_to_string(run.join("checkpoint.json")).unwrap();
    let json: serde_json::Value = serde_json::from_str(&checkpoint).unwrap();
    let epoch = json["epoch"].as_u64().unwrap();
    assert!((1..1_000_000).contains(&epoch), "{epoch}");
    assert_eq!(log_rows(&run).len() as u64, epoch);
}

/// SIGTERM while a diagnosis fits its model: the fits end at their best so far, the report
/// is printed and written marked partial, and the exit code is 1 (E0810).
#[cfg(unix)]
#[test]
fn sigterm_ends_a_diagnosis_with_its_report_marked_partial() {
    let dir = scratch("sigterm-diagnose");
    let files = crate::diagnose::thinned_files(&dir);
    let json = dir.join("report.json");
    let html = dir.join("report.html");
    let mut command = gbc_command(&["diagnose", "models/diagnose/chemostat/model.gbm"]);
    command.args(&files).arg("--json").arg(&json);
    let mut child = Running::start(command.arg("--html").arg(&html), true);
    child.line(|line| line.starts_with("fitting the model"));
    child.signal("TERM");
    let end = child.finish();
    let rest = end.stderr.join("\n");
    assert_eq!(end.status.code(), Some(1), "{rest}");
    assert!(rest.contains("E0810"), "{rest}");
    let stdout = end.stdout;
    assert!(stdout.starts_with("PARTIAL REPORT: stopped"), "{stdout}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let partial = report["partial"].as_str().unwrap_or_default();
    assert!(
        partial.contains("stopped (Ctrl-C or SIGTERM) while"),
        "{report}"
    );
    assert!(
        report["credited"].is_null(),
        "a partial report credits nothing"
    );
    let page = std::fs::read_to_string(&html).unwrap();
    assert!(page.contains("Partial report:"));
}

/// One-step training of GB1 on 100 pairs at a high learning rate: the free run on the
/// validation part worsens after its first epochs while the training loss keeps falling.
fn overfitting(run: &Path, extra: &[&str]) -> std::process::Output {
    let run = run.display().to_string();
    let mut args = vec!["train", GB1, STEPS, "-o", &run, "--objective", "one-step"];
    args.extend(["--train-points", "100", "--lr", "0.01"]);
    args.extend(extra);
    gbc(&args)
}

#[test]
fn early_stopping_ends_a_run_whose_validation_loss_rises_and_keeps_the_best_epoch() {
    let dir = scratch("early-stop");
    let early = dir.join("early");
    let output = overfitting(&early, &["--epochs", "40", "--early-stop", "3"]);
    assert!(output.status.success(), "{}", stderr(&output));
    // The run stops 3 epochs after its best validation loss and keeps the best epoch's
    // weights: the best is read off the log, not assumed.
    let rows = log_rows(&early);
    let online: Vec<f64> = rows.iter().map(|r| r.2.parse().unwrap()).collect();
    let best = (online.iter().enumerate())
        .min_by(|a, b| a.1.total_cmp(b.1))
        .map(|(i, _)| i + 1)
        .unwrap();
    assert!(best < 40, "{online:?}");
    assert_eq!(rows.len(), best + 3, "{rows:?}");
    assert!(
        online[best..].iter().all(|&later| later > online[best - 1]),
        "{online:?}"
    );
    let said = format!(
        "early stop after epoch {}: no better validation loss for 3 epochs; keeping the weights of epoch {best}",
        best + 3
    );
    assert!(stderr(&output).contains(&said), "{}", stderr(&output));
    // The weights kept are the best epoch's: those of a run of that many epochs.
    let first = dir.join("first");
    let epochs = best.to_string();
    assert!(overfitting(&first, &["--epochs", &epochs]).status.success());
    assert_eq!(
        bytes(&early.join("weights.safetensors")),
        bytes(&first.join("weights.safetensors"))
    );
    let without = dir.join("without");
    assert!(overfitting(&without, &["--epochs", "8"]).status.success());
    assert_eq!(log_rows(&without).len(), 8);
}

#[test]
fn renamed_flags_keep_their_old_spelling_with_a_warning() {
    let dir = scratch("renamed");
    let new = dir.join("new");
    let old = dir.join("old");
    assert!(train(&new, &["--epochs", "2"]).status.success());
    let run = old.display().to_string();
    let mut args = vec!["train", GB1, STEPS, "-o", &run];
    let short = short_with(&["--epochs", "2"]);
    args.extend(short.iter().map(|a| {
        if *a == "--warmup-share" {
            "--warmup"
        } else {
            a
        }
    }));
    let output = gbc(&args);
    assert!(output.status.success(), "{}", stderr(&output));
    assert!(stderr(&output).contains("--warmup` is deprecated"));
    assert_eq!(
        bytes(&new.join("weights.safetensors")),
        bytes(&old.join("weights.safetensors"))
    );
    // gbc experiment: --objective (one-step, or `paper`) and -o/--output; --training and
    // --out still read.
    let study = |args: &[&str]| {
        let mut all = vec!["experiment", "--preset", "chemostat", "--print-study"];
        all.extend(args);
        let output = gbc(&all);
        assert!(output.status.success(), "{}", stderr(&output));
        (
            String::from_utf8_lossy(&output.stdout).to_string(),
            stderr(&output),
        )
    };
    let (one_step, quiet) = study(&["--objective", "one-step", "--output", "x"]);
    assert!(quiet.is_empty(), "{quiet}");
    let (multi, _) = study(&["--objective", "multi-step", "-o", "x"]);
    assert_ne!(one_step, multi);
    assert_eq!(study(&["--objective", "paper"]).0, one_step);
    let (old_spelling, warning) = study(&["--training", "one-step", "--out", "x"]);
    assert_eq!(old_spelling, one_step);
    assert!(warning.contains("--training` is deprecated"), "{warning}");
    let help = gbc(&["train", "--help"]);
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(help.contains("--warmup-share") && !help.contains("--warmup <"));
    assert!(help.contains("--resume") && help.contains("--early-stop"));
    let help = gbc(&["simulate", "--help"]);
    let help = String::from_utf8_lossy(&help.stdout);
    for programme in ["steps(lo=", "const(V)", "chirp(lo=", "csv(FILE, COLUMN)"] {
        assert!(
            help.contains(programme),
            "simulate --help lacks {programme}"
        );
    }
}

/// Every value of a CSV file after its header, parsed (`None` for a cell that is no number).
fn cells(path: &Path) -> Vec<Option<f64>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    (text.lines().skip(1))
        .flat_map(|line| {
            line.split(',')
                .map(|cell| cell.parse().ok())
                .collect::<Vec<_>>()
        })
        .collect()
}

/// Issue 22's case: an f32 run whose Adam step overflows every weight while the epoch's
/// loss (computed before the step) stays finite. The run fails with E0415 naming the epoch,
/// and its directory keeps finite weights (here the initial ones) that `gbc predict` reads;
/// a run directory holding NaN weights is refused by name.
#[test]
fn a_run_that_goes_non_finite_exits_1_keeping_finite_weights_that_predict() {
    let dir = scratch("diverged");
    let run = dir.join("run");
    let run_text = run.display().to_string();
    let output = gbc(&[
        "train",
        GB1,
        STEPS,
        "-o",
        &run_text,
        "--epochs",
        "1",
        "--objective",
        "one-step",
        "--train-points",
        "100",
        "--batch",
        "128",
        "--lr",
        "1e39",
        "--precision",
        "f32",
        // Half of 1e39 is within f32's range: a recovery would succeed.
        "--recoveries",
        "0",
    ]);
    let message = stderr(&output);
    assert_eq!(output.status.code(), Some(1), "{message}");
    assert!(message.contains("E0415"), "{message}");
    assert!(
        message.contains("training diverged in epoch 1"),
        "{message}"
    );
    assert!(message.contains("after the epoch"), "{message}");
    assert!(message.contains("keeps the initial weights"), "{message}");
    assert!(
        message.contains("--lr"),
        "the help says what to try: {message}"
    );
    let weights = gbc::api::artifacts::read_tensors(&run.join("weights.safetensors")).unwrap();
    assert!(!weights.is_empty());
    for tensor in &weights {
        assert!(
            tensor.values.iter().all(|v| v.is_finite()),
            "{}",
            tensor.name
        );
    }
    let info = std::fs::read_to_string(run.join("run.json")).unwrap();
    let info: serde_json::Value = serde_json::from_str(&info).unwrap();
    assert_eq!(info["diverged"]["epoch"], 1);
    assert_eq!(info["diverged"]["kept_epoch"], 0);
    let predicted = dir.join("predicted.csv");
    let predicted_text = predicted.display().to_string();
    let args = [
        "predict",
        GB1,
        STEPS,
        "--weights",
        &run_text,
        "-o",
        &predicted_text,
    ];
    let output = gbc(&args);
    assert!(output.status.success(), "{}", stderr(&output));
    let values = cells(&predicted);
    assert!(values.len() > 100);
    assert!(values.iter().all(|v| v.is_some_and(f64::is_finite)));
    // A run directory with a NaN weight (as gbc wrote before this check) is refused.
    let mut broken = weights.clone();
    broken[0].values[2] = f64::NAN;
    gbc::api::artifacts::write_tensors(&run.join("weights.safetensors"), &broken).unwrap();
    std::fs::remove_file(&predicted).unwrap();
    let output = gbc(&args);
    let message = stderr(&output);
    assert_eq!(output.status.code(), Some(1), "{message}");
    assert!(
        message.contains("E0417") && message.contains("= NaN"),
        "{message}"
    );
    assert!(!predicted.exists());
}
