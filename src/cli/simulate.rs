//! `gbc simulate MODEL --t-end T --dt H -o OUT.csv`: integrate a model without closures
//! and write the sampled record as CSV; with `--weights RUN_DIR`, a what-if run of a trained
//! model. The work is [`gbc::api::simulate`]: noise (`--noise`), ranges (`--range`),
//! initial values (`--init`), fitted params (`--params`) and effects (`--effect`) are its
//! spec's fields; this file parses the flags and prints notes, warnings and progress.

#[cfg(test)]
mod tests_inputs;

use super::progress::{Announce, Count, Reporter};
use super::{CommandError, CommandResult};
use gbc::api::flags::SimulateArgs;
use gbc::api::{self, SimulateEvent};
use std::path::Path;

/// Simulates the model and writes the record.
pub fn run(args: &SimulateArgs) -> CommandResult {
    let mut inputs: Vec<&Path> = vec![&args.model];
    inputs.extend(args.history.as_deref());
    inputs.extend(args.params.as_deref());
    api::ensure_not_input(&args.output, &inputs).map_err(CommandError::user)?;
    let model = api::Model::from_file_with_effects(&args.model, &args.effects)?;
    // The stage starts before the warm-up; its total is known from the first sample on.
    let reporter = Reporter::new();
    let simulation = api::simulate(&model, &args.spec(), &mut |event| show(&reporter, event))?;
    simulation.write_csv(&args.output)?;
    Ok(())
}

/// Prints a simulation's event on stderr: notes, warnings, the progress of its samples.
fn show(reporter: &Reporter, event: SimulateEvent) {
    match event {
        SimulateEvent::Note(note) => eprintln!("note: {note}"),
        SimulateEvent::Warning(warning) => eprintln!("warning: {warning}"),
        SimulateEvent::Started => {
            reporter.stage("simulating", 0, Count::Items("samples"), Announce::IfSlow)
        }
        SimulateEvent::Samples { done, total } => {
            if done == 1 {
                reporter.set_total(total as u64);
            }
            if done.is_multiple_of(1024) || done == total {
                reporter.update(done as u64, String::new());
            }
        }
        SimulateEvent::Finished => reporter.finish(),
        SimulateEvent::Members { members, jobs } => {
            eprintln!("running {members} members ({jobs} at once)")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::tests_scratch::ScratchDir;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Command {
        #[command(flatten)]
        args: SimulateArgs,
    }

    fn chemostat_path() -> String {
        concat!(env!("CARGO_MANIFEST_DIR"), "/models/mm_chemostat/truth.gbm").to_string()
    }

    /// Parses `gbc simulate` arguments for the chemostat truth model writing to `output`.
    fn args(output: &Path, extra: &[&str]) -> SimulateArgs {
        let output = output.display().to_string();
        let model = chemostat_path();
        let mut words = vec!["simulate", model.as_str(), "--t-end", "20", "--dt", "1"];
        words.extend(["-o", output.as_str()]);
        words.extend(extra);
        Command::try_parse_from(words).unwrap().args
    }

    fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
        let mut reader = csv::Reader::from_path(path).unwrap();
        let header = reader.headers().unwrap().iter().map(String::from).collect();
        let rows = reader
            .records()
            .map(|row| row.unwrap().iter().map(|v| v.parse().unwrap()).collect())
            .collect();
        (header, rows)
    }

    /// The chemostat's steady substrate level at inlet enzyme `e0`.
    fn steady_substrate(e0: f64) -> f64 {
        let (s0, theta, kcat, k_m) = (3e-2, 20.0, 0.14, 1.5e-2);
        let b = k_m - s0 + theta * kcat * e0;
        (-b + (b * b + 4.0 * s0 * k_m).sqrt()) / 2.0
    }

    #[test]
    fn default_tolerances_are_the_library_defaults() {
        let parsed = args(Path::new("out.csv"), &[]);
        assert_eq!(parsed.rtol, api::Tolerances::default().rtol);
        assert_eq!(parsed.atol, api::Tolerances::default().atol);
    }

    #[test]
    fn writes_columns_in_order_from_the_settled_state() {
        let scratch = ScratchDir::new("simulate-columns").unwrap();
        let output = scratch.join("chemostat.csv");
        let extra = ["--input", "E0=const(0.01)", "--warmup", "2000", "--hidden"];
        run(&args(&output, &extra)).unwrap();
        let (header, rows) = read_csv(&output);
        assert_eq!(header, ["t", "E0", "S", "E", "P", "r_true"]);
        assert_eq!(rows.len(), 21);
        let steady = steady_substrate(0.01);
        for (k, row) in rows.iter().enumerate() {
            assert_eq!(row[0], k as f64);
            assert_eq!(row[1], 0.01);
            assert!((row[2] / steady - 1.0).abs() < 1e-8, "S = {}", row[2]);
            assert!((row[3] / 0.01 - 1.0).abs() < 1e-8, "E = {}", row[3]);
            assert!((row[4] - (3e-2 - row[2])).abs() < 1e-15);
        }
    }

    #[test]
    fn noise_is_relative_seeded_and_on_measured_states_only() {
        let scratch = ScratchDir::new("simulate-noise").unwrap();
        let clean = scratch.join("clean.csv");
        let noisy = scratch.join("noisy.csv");
        let again = scratch.join("again.csv");
        let input = ["--input", "E0=steps(hold=3..6, seed=4)", "--hidden"];
        run(&args(&clean, &input)).unwrap();
        let with_noise =
            |seed: &'static str| [&input[..], &["--noise", "0.01", "--seed", seed]].concat();
        run(&args(&noisy, &with_noise("9"))).unwrap();
        run(&args(&again, &with_noise("9"))).unwrap();
        let (_, clean) = read_csv(&clean);
        let (_, noisy) = read_csv(&noisy);
        assert_eq!(noisy, read_csv(&again).1, "same seed, same record");
        let mut changed = 0;
        for (c, n) in clean.iter().zip(&noisy) {
            assert_eq!((c[0], c[1], c[3], c[4]), (n[0], n[1], n[3], n[4]));
            let relative = n[2] / c[2] - 1.0;
            assert!(relative.abs() < 0.06, "relative deviation {relative}");
            changed += usize::from(relative != 0.0);
        }
        assert_eq!(changed, clean.len());
    }

    fn codes(error: CommandError) -> Vec<String> {
        match error {
            CommandError::User(reports) => reports
                .iter()
                .filter_map(|r| r.code().map(|c| c.to_string()))
                .collect(),
            CommandError::Internal(message) => vec![message],
        }
    }

    #[test]
    fn input_programs_must_cover_each_input_once() {
        let scratch = ScratchDir::new("simulate-inputs").unwrap();
        let output = scratch.join("never.csv");
        let missing = run(&args(&output, &[])).unwrap_err();
        assert_eq!(codes(missing), ["gbm::E0709"]);
        let twice = ["--input", "E0=const(0.01)", "--input", "E0=const(0.02)"];
        assert_eq!(
            codes(run(&args(&output, &twice)).unwrap_err()),
            ["gbm::E0710"]
        );
        let noise = [
            "--input",
            "E0=const(0.01)",
            "--noise",
            "S=1%",
            "--noise",
            "S=2%",
        ];
        assert_eq!(
            codes(run(&args(&output, &noise)).unwrap_err()),
            ["gbm::E0135"]
        );
        let negative = [
            "simulate", "m.gbm", "--t-end", "1", "--dt", "1", "-o", "o.csv",
        ];
        let refused = Command::try_parse_from([&negative[..], &["--noise", "-1"]].concat());
        let message = refused.err().map(|e| e.to_string()).unwrap_or_default();
        assert!(
            message.contains("expected a finite noise level >= 0, found `-1`"),
            "{message}"
        );
        assert!(!output.exists());
    }

    #[test]
    fn an_output_that_goes_non_finite_is_refused_naming_where() {
        let scratch = ScratchDir::new("simulate-nan").unwrap();
        let model = scratch.join("decay.gbm");
        let source = "model decay\nstate x = 1\noutput y = sqrt(x - 0.5)\nder x = -x\n";
        std::fs::write(&model, source).unwrap();
        let output = scratch.join("decay.csv");
        let (model, out) = (model.display().to_string(), output.display().to_string());
        let words = [
            "simulate", &model, "--t-end", "2", "--dt", "0.25", "-o", &out,
        ];
        let error = run(&Command::try_parse_from(words).unwrap().args).unwrap_err();
        let CommandError::User(reports) = &error else {
            panic!("expected a user error, found {error:?}");
        };
        let message = reports[0].to_string();
        assert_eq!(codes(error), ["gbm::E0253"]);
        // x = e^-t falls below 0.5 after t = ln 2 = 0.69: the first sample past it.
        assert!(
            message.contains("`y` = NaN at t = 0.75 (row 4)"),
            "{message}"
        );
        assert!(!output.exists(), "nothing is written");
    }
}
