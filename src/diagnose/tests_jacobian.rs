//! The fits' Jacobian from forward sensitivities against central differences of the
//! residuals, with every kind of unknown: params in the balances and in a declared initial
//! value, a fitted start of a measured state, and fitted hidden starts; on a stiff stretch
//! and across input switches; and with measured outputs (observables) among the columns.

use crate::record::Record;
use crate::solve::fit::fitter::Objective;
use crate::solve::fit::simulate::Simulator;
use crate::solve::fit::split::{Holdout, Split};
use crate::solve::ode::Tolerances;

/// Monod uptake with a small saturation constant (stiff once S is low), a hidden state
/// driven by the input, and a declared start that depends on a param.
const MODEL: &str = "model culture
input u
state X = x0, S
hidden H = 0.5 * k
param k = 0.3 positive, x0 = 1.2 positive, K = 0.02 positive
der X = k * S / (K + S) * X - 0.1 * X * u
der S = -k * S / (K + S) * X + 0.2 * (3 - S) - H * S
der H = (u - H) / 2
";

/// Two experiments of 40 rows: irregular times, a feed that switches, cells missing; the
/// first has no X at its first row, the second no S.
fn records(model: &crate::ir::Model) -> Vec<Record> {
    (0..2)
        .map(|e| {
            let times: Vec<f64> = (0..40)
                .map(|k| k as f64 * 0.5 + 0.1 * ((k * 7 % 5) as f64))
                .collect();
            let input: Vec<f64> = times
                .iter()
                .map(|t| {
                    if (t / 5.0) as usize % 2 == e {
                        1.0
                    } else {
                        0.2
                    }
                })
                .collect();
            let signal = crate::signal::Signal::new(times.clone(), input.clone()).unwrap();
            let options = crate::solve::ode::SimOptions {
                t_start: times[0],
                initial: vec![None, Some(1.5 + e as f64)],
                ..crate::solve::ode::SimOptions::new(times[39], 0.01)
            };
            let run = crate::solve::ode::simulate(model, &[signal], &options).unwrap();
            let at = |column: &Vec<f64>, t: f64| column[((t - times[0]) / 0.01).round() as usize];
            let states = (run.states.iter())
                .map(|column| times.iter().map(|&t| 1.02 * at(column, t)).collect())
                .collect();
            let mut record = Record::complete(&format!("e{e}"), times.clone(), vec![input], states);
            for (k, column) in record.states.iter_mut().enumerate() {
                for (row, cell) in column.iter_mut().enumerate() {
                    if row > 0 && (row + k) % 3 == 0 {
                        *cell = None;
                    }
                }
            }
            // The first experiment starts X at its declaration `x0`, the second fits S's.
            record.states[e][0] = None;
            record
        })
        .collect()
}

/// The culture read through two outputs: an optical density of X that depends on the
/// input and on a param of its own, and a saturation of S through the balances' `K`.
const OBSERVED: &str = "param c = 0.8 positive
output OD = 0.4 + c * X * (1 + u)
output R = S / (K + S)
";

/// The records of [`records`] with X read only through `OD` and S also through `R`
/// (every third cell of each missing, staggered).
fn observed_records(model: &crate::ir::Model) -> Vec<Record> {
    let mut records = records(model);
    for record in &mut records {
        let rows = record.len();
        let x = std::mem::replace(&mut record.states[0], vec![None; rows]);
        let od = (x.iter().enumerate())
            .map(|(row, cell)| cell.map(|v| 0.4 + 0.8 * v * (1.0 + record.inputs[0][row])))
            .collect();
        let r = (record.states[1].iter().enumerate())
            .map(|(row, cell)| cell.filter(|_| row % 4 != 1).map(|v| v / (0.02 + v)))
            .collect();
        record.observables = vec![
            crate::record::Observable {
                output: 0,
                name: "OD".into(),
                cells: od,
            },
            crate::record::Observable {
                output: 1,
                name: "R".into(),
                cells: r,
            },
        ];
    }
    records
}

fn check(fit_hidden: bool) {
    check_model(MODEL, records, fit_hidden);
}

fn check_model(text: &str, records: impl Fn(&crate::ir::Model) -> Vec<Record>, fit_hidden: bool) {
    let model = crate::driver::compile("culture", text, &[]).unwrap().model;
    let split = Split::new(
        &model,
        records(&model),
        Vec::new(),
        (Holdout::Tail(0.3), fit_hidden),
    )
    .unwrap();
    let tight = Tolerances {
        rtol: 1e-12,
        atol: 1e-14,
    };
    let mut simulator = Simulator::new(&model, &[], tight).unwrap();
    simulator
        .observe(&model, &split.normalisation.observables)
        .unwrap();
    let objective = Objective {
        simulator: &simulator,
        split: &split,
    };
    let fitted = split.fitted_count(simulator.hidden_count());
    assert_eq!(fitted, 1 + if fit_hidden { 2 } else { 0 });
    let mut x = vec![0.35, 1.1, 0.03, 0.7];
    x.truncate(model.params.len());
    x.extend((0..fitted).map(|i| 0.4 + 0.3 * i as f64));
    let exact = objective.jacobian(&x).unwrap();
    let residuals = objective.residuals(&x).unwrap();
    assert_eq!(exact.len(), x.len());
    for (j, column) in exact.iter().enumerate() {
        assert_eq!(column.len(), residuals.len());
        let step = 1e-6 * x[j].abs().max(1e-3);
        let shifted = |sign: f64| {
            let mut moved = x.clone();
            moved[j] += sign * step;
            objective.residuals(&moved).unwrap()
        };
        let (up, down) = (shifted(1.0), shifted(-1.0));
        let size = column.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!(size > 0.0, "unknown {j} moves no residual");
        for (i, &value) in column.iter().enumerate() {
            let numeric = (up[i] - down[i]) / (2.0 * step);
            assert!(
                (value - numeric).abs() < 1e-5 * size,
                "unknown {j}, residual {i}: {value} vs {numeric} (column norm {size})"
            );
        }
    }
}

#[test]
fn jacobian_from_sensitivities_matches_central_differences() {
    check(false);
}

#[test]
fn jacobian_covers_fitted_hidden_starts() {
    check(true);
}

/// Observables' columns: their derivatives by the states through the sensitivities, by
/// their own param directly, and by the input they read (held, so no column).
#[test]
fn jacobian_covers_measured_outputs() {
    let text = format!("{MODEL}{OBSERVED}");
    let model = crate::driver::compile("culture", &text, &[]).unwrap().model;
    let records = observed_records(&model);
    assert!(records
        .iter()
        .all(|r| r.states[0].iter().all(Option::is_none)));
    check_model(&text, observed_records, false);
    check_model(&text, observed_records, true);
}

/// [`MODEL`] with X's start declared as a fixed guess (1.2): read only through `OD`, X
/// starts where the first row's OD puts it, and its start moves with `c` (the OD's own
/// param) and with nothing else; `x0` is moved into S's feed so that it stays an unknown.
fn observed_start_model() -> String {
    let text = MODEL
        .replace("state X = x0, S", "state X = 1.2, S")
        .replace("+ 0.2 * (3 - S)", "+ 0.2 * (x0 + 1.8 - S)");
    format!("{text}{OBSERVED}")
}

/// A state read only through an observable starts where the observable's first cell puts
/// it (the closed form of the OD's inverse), not at its declaration; without a first OD it
/// starts at its declaration.
#[test]
fn a_state_read_only_through_an_output_starts_where_its_first_cell_puts_it() {
    let text = observed_start_model();
    let model = crate::driver::compile("culture", &text, &[]).unwrap().model;
    let records = observed_records(&model);
    let mut simulator = Simulator::new(&model, &[], Tolerances::default()).unwrap();
    simulator.observe(&model, &[0, 1]).unwrap();
    let c = 0.65;
    simulator.set_params(&[0.35, 1.1, 0.03, c]);
    for record in &records {
        let Some(od) = record.observables[0].cells[0] else {
            // No OD at the first row (the first experiment): X starts at its declaration.
            assert_eq!(simulator.start_state(record, &[])[0], 1.2);
            assert!(simulator.observed_start_states(record, &[]).is_empty());
            continue;
        };
        let expected = (od - 0.4) / (c * (1.0 + record.inputs[0][0]));
        assert!((expected - 1.2).abs() > 0.1, "the declaration would pass");
        let start = simulator.start_state(record, &[]);
        assert!(
            (start[0] - expected).abs() < 1e-10 * expected,
            "{}: X starts at {}, its OD says {expected}",
            record.name,
            start[0]
        );
        assert_eq!(simulator.observed_start_states(record, &[]), vec![0]);
    }
}

/// The Jacobian with X's start solved from its OD: the chain through the solved start by
/// `c`, the input and S's fitted start agrees with central differences.
#[test]
fn jacobian_covers_starts_read_through_outputs() {
    check_model(&observed_start_model(), observed_records, false);
}
