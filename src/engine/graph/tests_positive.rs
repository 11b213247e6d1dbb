//! `positive` closure outputs (`backend::program::outputs`): the prior exactly at `n = 0`
//! (0 without one), no floor where the prior vanishes, and gradients against central
//! differences (from above at the kink of an output without a prior).

use crate::engine::program::{Program, ProgramInputs};
use crate::ir;
use crate::numeric::Real;

/// `q *= Monod(S)` and `r += 0.3 u - 0.1`, both `positive`; `c` without a prior.
pub(crate) const POSITIVE_PRIORS: &str = "\
model positive_priors
input u
state X, S
closure rates {
  outputs q positive, r ~ 0.2 positive, c ~ 0.5 positive
  observe X, S, u
  embed delay 1 dim 2
  network hidden [4] tanh
  prior q *= 0.5 * S / (0.1 + S)
  prior r += 0.3 * u - 0.1
}
der X = q * X - r + c
der S = -q * X / 0.5
";

/// The compiled model of [`POSITIVE_PRIORS`].
pub(crate) fn positive_priors() -> ir::Model {
    crate::driver::compile("positive_priors.gbm", POSITIVE_PRIORS, &[])
        .unwrap()
        .model
}

/// Closure outputs `[q, r, c]` per row for states `[X, S]`, input `u` and nets `[n_q, n_r,
/// n_c]`, in precision `E`.
fn outputs<E: Real>(program: &Program, rows: &[([f64; 2], f64, [f64; 3])]) -> Vec<E> {
    let cast = |values: Vec<f64>| values.into_iter().map(E::from_double).collect::<Vec<E>>();
    let states = cast(rows.iter().flat_map(|r| r.0).collect());
    let inputs = cast(rows.iter().map(|r| r.1).collect());
    let nets = cast(rows.iter().flat_map(|r| r.2).collect());
    let values = program.forward(&ProgramInputs {
        rows: rows.len(),
        states: &states,
        inputs: &inputs,
        params: &[],
        nets: &[&nets],
    });
    program.read(&values, rows.len(), &program.closure_outputs)
}

fn monod(s: f64) -> f64 {
    0.5 * s / (0.1 + s)
}

#[test]
fn at_zero_network_output_a_positive_output_is_its_prior_exactly() {
    let program = Program::compile(&positive_priors(), &[vec![1.0, 0.2, 0.5]]).unwrap();
    let rows = [([1.0, 0.0], 0.8, [0.0; 3]), ([2.0, 0.3], 0.8, [0.0; 3])];
    let found = outputs::<f64>(&program, &rows);
    // The prior is computed by the same operations, so the value is bit for bit the prior.
    assert_eq!(found[0], 0.0, "q with no substrate");
    assert_eq!(found[3], monod(0.3));
    assert_eq!(found[1], 0.3 * 0.8 - 0.1);
    assert_eq!(found[4], 0.3 * 0.8 - 0.1);
    // Without a prior a positive output is s |n|: 0 at n = 0.
    assert_eq!(found[2], 0.0);
    let single = outputs::<f32>(&program, &rows);
    assert_eq!(single[0], 0.0);
    assert_eq!(single[3], 0.5_f32 * 0.3_f32 / (0.1_f32 + 0.3_f32));
}

#[test]
fn a_positive_output_vanishes_with_its_prior_and_is_never_negative() {
    let program = Program::compile(&positive_priors(), &[vec![1.0, 0.2, 0.5]]).unwrap();
    for n in [-30.0, -2.0, -0.95, -0.875, -0.4, 0.0, 0.7, 5.0] {
        let rows = [
            ([1.0, 0.0], 0.8, [n; 3]),
            ([1.0, 0.4], 0.1, [n; 3]),
            ([1.0, 0.4], 0.9, [n; 3]),
        ];
        let found = outputs::<f64>(&program, &rows);
        assert_eq!(found[0], 0.0, "q at S = 0, n = {n}");
        // g(n) = 1 + n down to n = -7/8, e^(8 (n + 7/8)) / 8 below.
        let factor = if n >= -0.875 {
            1.0 + n
        } else {
            f64::exp(8.0 * (n + 0.875)) / 8.0
        };
        assert!((found[3] - monod(0.4) * factor).abs() < 1e-15 * (1.0 + factor));
        // r: 0.3 u - 0.1 + 0.2 n clipped at zero (the prior is negative at u = 0.1).
        for (row, u) in [(0, 0.8), (1, 0.1), (2, 0.9)] {
            let expected = (0.3 * u - 0.1 + 0.2 * n).max(0.0);
            assert!(
                (found[3 * row + 1] - expected).abs() < 1e-15,
                "r, u = {u}, n = {n}"
            );
        }
        // c: 0.5 |n|, 0 at the start.
        assert_eq!(found[2], (0.5 * n).abs(), "c, n = {n}");
        assert!(found.iter().all(|&o| o >= 0.0));
    }
}

/// The reverse sweep of the balances against central differences in the network outputs
/// and the states, at network outputs on both sides of the join `n = -7/8` and at the join
/// itself (where `g` joins its two pieces with slope 1), and at 0.
#[test]
fn positive_outputs_have_the_gradient_of_central_differences() {
    let program = Program::compile(&positive_priors(), &[vec![1.0, 0.2, 0.5]]).unwrap();
    let rows = [
        ([1.3, 0.4], 0.8, [0.0, 0.3, -0.2]),
        ([0.7, 1.1], 0.6, [-0.875, -1.3, 0.4]),
        ([2.0, 0.2], 0.9, [0.6, 1.5, 0.0]),
    ];
    let seed = [0.7, -1.3, 0.4, 2.0, -0.5, 1.1];
    let objective = |rows: &[([f64; 2], f64, [f64; 3])]| -> f64 {
        let columns = unpack(rows);
        let nets = [columns.2.as_slice()];
        let inputs = inputs_of(&columns, &nets);
        let values = program.forward(&inputs);
        let balances = program.read(&values, rows.len(), &program.balances);
        balances.iter().zip(&seed).map(|(b, s)| b * s).sum()
    };
    let columns = unpack(&rows);
    let nets = [columns.2.as_slice()];
    let inputs = inputs_of(&columns, &nets);
    let values = program.forward(&inputs);
    let gradients = program.backward(&inputs, &values, &program.balances, &seed);
    let h = 1e-6;
    for row in 0..rows.len() {
        for k in 0..3 {
            let shifted = |d: f64| {
                let mut moved = rows;
                moved[row].2[k] += d;
                objective(&moved)
            };
            // c = max(0.5 n, -0.5 n) at its kink n = 0 passes the gradient of 0.5 n (the
            // tie rule that lets a rate starting at 0 grow): the difference from above.
            let at_kink = k == 2 && rows[row].2[k] == 0.0;
            let numeric = if at_kink {
                (shifted(h) - shifted(0.0)) / h
            } else {
                (shifted(h) - shifted(-h)) / (2.0 * h)
            };
            let found = gradients.nets[0][row * 3 + k];
            // At the join the two pieces of g meet with equal slopes but not curvatures: the
            // central difference is off by about 2 h (the tail's curvature 8 over 4) there
            // (a wrong tie rule: by 0.5).
            let tolerance = 1e-5 * (1.0 + numeric.abs());
            assert!(
                (found - numeric).abs() < tolerance,
                "net {k} row {row}: {found} vs {numeric}"
            );
        }
        for i in 0..2 {
            let shifted = |d: f64| {
                let mut moved = rows;
                moved[row].0[i] += d;
                objective(&moved)
            };
            let numeric = (shifted(h) - shifted(-h)) / (2.0 * h);
            let found = gradients.states[row * 2 + i];
            assert!(
                (found - numeric).abs() < 1e-7,
                "state {i} row {row}: {found} vs {numeric}"
            );
        }
    }
}

type Columns = (Vec<f64>, Vec<f64>, Vec<f64>);

fn unpack(rows: &[([f64; 2], f64, [f64; 3])]) -> Columns {
    (
        rows.iter().flat_map(|r| r.0).collect(),
        rows.iter().map(|r| r.1).collect(),
        rows.iter().flat_map(|r| r.2).collect(),
    )
}

/// The program inputs of unpacked rows (no params).
fn inputs_of<'a>(columns: &'a Columns, nets: &'a [&'a [f64]]) -> ProgramInputs<'a, f64> {
    ProgramInputs {
        rows: columns.1.len(),
        states: &columns.0,
        inputs: &columns.1,
        params: &[],
        nets,
    }
}
