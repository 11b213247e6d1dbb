//! Inputs as they are logged (issue 24): a `csv(...)` feed on an irregular time grid and a
//! `schedule(T:V, ...)` programme, each held between its times, integrated by `der x = F`
//! and checked against the exact integral of the piecewise-constant feed.

use super::{run, SimulateArgs};
use crate::cli::tests_scratch::ScratchDir;
use clap::Parser;
use std::path::Path;

#[derive(Debug, Parser)]
struct Command {
    #[command(flatten)]
    args: SimulateArgs,
}

/// A model that integrates its feed: `x(t) = integral of F from 0 to t`.
const INTEGRATOR: &str = "model feed \"integrates its feed\"\ntime h\n\
     input F [g/h] in [0, 1]\nstate x [g] = 0\nder x = F\n";

/// `gbc simulate` of the integrator from 0 to 8 h sampled every hour under `program`: the
/// `x` column.
fn integrate(scratch: &ScratchDir, program: &str) -> Vec<f64> {
    let model = scratch.join("feed.gbm");
    std::fs::write(&model, INTEGRATOR).unwrap();
    let output = scratch.join("out.csv");
    let (model, output) = (model.display().to_string(), output.display().to_string());
    let input = format!("F={program}");
    let words = [
        "simulate", &model, "--t-end", "8", "--dt", "1", "-o", &output,
    ];
    let args = Command::try_parse_from(words.into_iter().chain(["--input", &input]))
        .unwrap()
        .args;
    run(&args).unwrap();
    read_column(Path::new(&output), "x")
}

fn read_column(path: &Path, name: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let column = header.iter().position(|h| *h == name).unwrap();
    lines
        .map(|line| line.split(',').nth(column).unwrap().parse().unwrap())
        .collect()
}

/// The integral from 0 to `t` of the level `levels[i]` held from `breaks[i]` on.
fn exact_integral(breaks: &[f64], levels: &[f64], t: f64) -> f64 {
    (0..breaks.len())
        .map(|i| {
            let end = breaks.get(i + 1).copied().unwrap_or(f64::INFINITY).min(t);
            levels[i] * (end - breaks[i]).max(0.0)
        })
        .sum()
}

fn assert_integral(found: &[f64], breaks: &[f64], levels: &[f64]) {
    assert_eq!(found.len(), 9);
    for (hour, &x) in found.iter().enumerate() {
        let exact = exact_integral(breaks, levels, hour as f64);
        assert!((x - exact).abs() < 1e-9, "t = {hour}: {x} against {exact}");
    }
}

#[test]
fn an_irregular_csv_feed_is_held_between_its_rows() {
    let scratch = ScratchDir::new("simulate-feed-csv").unwrap();
    let feed = scratch.join("feed.csv");
    // A feed log at irregular times, with an empty cell (the pump kept its rate) and a
    // last row held to the end.
    let log = "t,F\n0,0.0\n0.7,0.3\n1.9,0.1\n3.05,\n4.25,0.5\n6,0.2\n7.5,0.2\n";
    std::fs::write(&feed, log).unwrap();
    let found = integrate(&scratch, &format!("csv({})", feed.display()));
    // By hand: x(1) = 0.3 * 0.3 = 0.09; x(2) = 0.09 + 0.3 * 0.9 + 0.1 * 0.1 = 0.37; ...
    assert!((found[1] - 0.09).abs() < 1e-9 && (found[2] - 0.37).abs() < 1e-9);
    let breaks = [0.0, 0.7, 1.9, 4.25, 6.0];
    assert_integral(&found, &breaks, &[0.0, 0.3, 0.1, 0.5, 0.2]);
}

#[test]
fn a_schedule_holds_each_level_from_its_time_on() {
    let scratch = ScratchDir::new("simulate-feed-schedule").unwrap();
    let found = integrate(&scratch, "schedule(0:0.0, 2.5:0.1, 7:0.05)");
    // By hand: x(3) = 0.1 * 0.5 = 0.05, x(7) = 0.1 * 4.5 = 0.45, x(8) = 0.45 + 0.05.
    assert!((found[3] - 0.05).abs() < 1e-9 && (found[8] - 0.5).abs() < 1e-9);
    assert_integral(&found, &[0.0, 2.5, 7.0], &[0.0, 0.1, 0.05]);
}
