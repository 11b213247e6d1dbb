//! `nonnegative` states in free runs: a model that passes the compiler's check, run with
//! random network weights from a small substrate concentration, never takes the substrate
//! below zero beyond the step control's tolerance, while the fixed RK4 step of training
//! does; and the physical range takes a declared state's floor from the model.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use crate::engine::graph::{Network, Precision, Setup};
use crate::engine::pairs::stage_fractions;
use crate::ir;
use crate::record::{Normalisation, Record, Track};
use crate::train::evaluate::{simulate, Feed, PhysicalRange, UNDERSHOOT};
use crate::train::stepping::{Stepping, TOLERANCE};

/// A fed batch whose uptake is first order in `S` with a learned, positive rate: it passes
/// the check (`S` and `X` declared `nonnegative`). The rate reaches tens per hour, far
/// beyond what RK4 at the one-hour step keeps stable.
const MODEL: &str = "model fed_batch
input F in [0, 0.2]
state X nonnegative, S nonnegative
const S_F = 5
closure kinetics {
  outputs mu ~ 0.5 positive, k ~ 20 positive
  observe X, S, F
  network hidden [8, 8] tanh
}
der X = (mu - F) * X - 0.5 * X * X
der S = F * (S_F - S) - k * S * X
";

/// [`MODEL`] with the uptake `k X` under a Monod prior that vanishes at `S = 0` (it passes
/// the check too); its growth rate is `0.5 softplus(n)`, written out (the form a
/// `positive` output without a prior had before issue 25, which these seeds were drawn
/// for).
const MONOD: &str = "model fed_batch
input F in [0, 0.2]
state X nonnegative, S nonnegative
const S_F = 5
closure kinetics {
  outputs mu ~ 0.5, k ~ 20 positive
  observe X, S, F
  network hidden [8, 8] tanh
  prior k *= 20 * S / (0.002 + S)
}
der X = (0.5 * softplus(mu / 0.5) - F) * X - 0.5 * X * X
der S = F * (S_F - S) - k * X
";

fn model(source: &str) -> ir::Model {
    crate::driver::compile("fed_batch.gbm", source, &[])
        .expect("compiles")
        .model
}

/// `hours` hours from `S = 0.02`, the feed on for 5 of every 20 hours; the measured cells only
/// set the normalisation and the start of the free run.
fn record(hours: i32) -> Record {
    let times: Vec<f64> = (0..=hours).map(f64::from).collect();
    let feed = times
        .iter()
        .map(|t| if t % 20.0 < 5.0 { 0.1 } else { 0.0 })
        .collect();
    let x = times.iter().map(|t| Some(1.0 + t / 30.0)).collect();
    let s = times
        .iter()
        .map(|t| Some(0.02 * (-t / 5.0).exp()))
        .collect();
    Record {
        name: "fed".into(),
        source: "test".into(),
        times,
        inputs: vec![feed],
        states: vec![x, s],
        observables: Vec::new(),
    }
}

/// A network for `model` on `record` with every weight drawn from N(0, 1) by `seed`.
fn random_network(model: &ir::Model, record: &Record, seed: u64) -> Network {
    let setup = Setup {
        step: 1.0,
        substeps: 1,
        precision: Precision::F64,
        seed,
        normalisation: Normalisation::over(&[(record, 0..record.len())], 2, 1),
        scales: vec![vec![0.5, 20.0]],
    };
    let mut network = Network::build(model, &setup).expect("builds");
    let count: usize = network.weights().iter().map(|t| t.values.len()).sum();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, 1.0).expect("a distribution");
    let weights: Vec<f64> = (0..count).map(|_| normal.sample(&mut rng)).collect();
    network.set_flat_weights(&weights).expect("sets");
    network
}

/// The lowest `S` of a free run of `model` along `record` (every knot and the last step's
/// end).
fn lowest_substrate(
    (model, network): (&ir::Model, &Network),
    record: &Record,
    stepping: Stepping,
) -> f64 {
    let grid = crate::train::prepare::grid_for(model, 1.0);
    let track = Track::lay(record, &grid, &[]);
    let fractions = stage_fractions(model.dynamics, 1);
    let last = track.len() - 2;
    let how = (Feed::Own, None, stepping);
    let run = simulate(network, model, &track, &fractions, (0, last), &[], how).expect("runs");
    // A value that is not finite counts as the lowest (`f64::min` would skip a NaN).
    (run.states.iter().chain(&run.next_states))
        .map(|state| {
            if state[1].is_finite() {
                state[1]
            } else {
                f64::NEG_INFINITY
            }
        })
        .fold(f64::INFINITY, f64::min)
}

/// The step control's allowance below zero: [`TOLERANCE`] of the floor, `1e-3` of the
/// largest `|S|` of the record (0.02).
const ALLOWED: f64 = TOLERANCE * 1e-3 * 0.02;

#[test]
fn a_checked_uptake_never_takes_the_substrate_below_zero_in_a_free_run() {
    let model = model(MODEL);
    let record = record(60);
    let (mut reached, mut fixed_crossed) = (0, 0);
    for seed in 0..12 {
        let network = random_network(&model, &record, seed);
        let run = |stepping| lowest_substrate((&model, &network), &record, stepping);
        let controlled = run(Stepping::Controlled);
        assert!(
            controlled >= -ALLOWED,
            "seed {seed}: S = {controlled:e} under step control"
        );
        reached += usize::from(controlled < 1e-3 * 0.02);
        fixed_crossed += usize::from(run(Stepping::Fixed) < -ALLOWED);
    }
    // The runs do reach the boundary: S falls far below its start.
    assert!(reached >= 6, "{reached} of 12 runs came near zero");
    // The trained one-hour step alone crosses zero (and blows up).
    assert!(
        fixed_crossed >= 3,
        "{fixed_crossed} of 12 fixed-step runs crossed zero"
    );
}

#[test]
fn step_doubling_alone_lands_past_a_priors_singularity_the_declaration_refines_it() {
    // Uptake through a Monod prior with a tiny constant: the prior's pole `S = -0.002`
    // sits just below zero. Without the declaration, a step whose `m` and `2m` results
    // agree may land on the smooth branch beyond the pole (S in the hundreds below zero,
    // at these seeds); declared `nonnegative`, the crossing is refined away.
    let declared = model(MONOD);
    let undeclared = model(&MONOD.replace("S nonnegative", "S"));
    let record = record(20);
    for seed in [0, 2] {
        let network = random_network(&declared, &record, seed);
        let run = |model| lowest_substrate((model, &network), &record, Stepping::Controlled);
        let (with, without) = (run(&declared), run(&undeclared));
        assert!(with >= -ALLOWED, "seed {seed}: declared S = {with:e}");
        assert!(without < -1.0, "seed {seed}: undeclared S = {without:e}");
    }
}

#[test]
fn a_declared_state_takes_its_floor_from_the_model_not_from_noisy_cells() {
    // `S` dips below zero in training (noise): from the data alone its floor is wide.
    let range = PhysicalRange::from_extremes(&[0.5, -0.02], &[3.0, 0.4], 10.0).expect("range");
    assert_eq!(range.lower[1], -10.0 * 0.4);
    let declared = range.declared(&model(MODEL));
    assert_eq!(declared.lower[1], -UNDERSHOOT * 0.4);
    // `X` was never negative in training: its floor is the same either way.
    assert_eq!(declared.lower[0], range.lower[0]);
    assert_eq!(declared.upper, range.upper);
    // A model that does not declare `S` keeps the data's floor.
    let undeclared = MODEL.replace("S nonnegative", "S");
    assert_eq!(range.declared(&model(&undeclared)).lower[1], range.lower[1]);
}
