//! What the data says before training: default closure-output magnitudes and a stiffness
//! estimate of the balances.
//!
//! Both evaluate the physics with every network output at zero (the *known part*: the
//! balances with the closure outputs at their priors, or zero without one) at the rows of
//! the training split, the hidden states at their initial values, and compare it with what
//! the data asks of it: the finite-difference derivative `d_i = (x_{i+1} - x_i) / h` for
//! `der` models, the next value `d_i = x_{i+1}` for `next` models.
//!
//! **Default magnitude `s_o`** (an output without `~` and without a `*=` prior): for each
//! measured balance `X` that `o` enters, with sensitivity `J_i = d f_X / d o` (central
//! difference), the data asks `o_i ~ (d_i - known_i) / J_i` of the network; `s_o` is the
//! root mean square of that over the rows (those where `|J_i|` is at least a tenth of its
//! median), taking the smallest over balances (a balance shared with other unknown outputs
//! overstates it). Without any estimate `s_o = 1`.
//!
//! **Stiffness**: RK4 is stable for `h * lambda >= -2.785` on the negative real axis. For
//! each balance the local rate is estimated as the diagonal Jacobian of the known part
//! (central difference) minus, for measured states, the unknown consumption the data shows
//! per unit of the state, `max(0, known_i - d_i) / |x_i|` — a first-order rate law removing
//! that flux would have exactly that eigenvalue, and saturating laws have smaller ones.
//! The estimate is the 1st percentile over the rows; a warning names the balance, the
//! step that would be stable and the `--substeps` that would make it so.

use std::fmt;

use crate::backend::program::{Program, ProgramInputs};
use crate::backend::{initial_raw_params, BackendError};
use crate::ir::{self, Dynamics, PriorKind};
use crate::numeric::order_statistic;

use crate::record::Track;

use super::pairs::PairAt;

/// The RK4 stability limit of `h * lambda` on the negative real axis.
pub const RK4_STABILITY_LIMIT: f64 = 2.785;

/// A balance too stiff for RK4 at the chosen step.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StiffnessWarning {
    /// The state whose balance it is.
    pub balance: String,
    /// Estimated most negative local eigenvalue (1st percentile).
    #[serde(with = "crate::json")]
    pub eigenvalue: f64,
    /// The longest grid step among the training pairs.
    #[serde(with = "crate::json")]
    pub step: f64,
    /// RK4 sub-steps in use.
    pub substeps: usize,
    /// Largest stable step for this eigenvalue.
    #[serde(with = "crate::json")]
    pub stable_step: f64,
    /// Sub-steps per sample that would make the step stable.
    pub substeps_needed: usize,
}

impl fmt::Display for StiffnessWarning {
    fn fmt(&self, formatter: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            formatter,
            "balance of `{}` is stiff: eigenvalue about {} per time unit, so an RK4 step of {} \
             ({} sub-step{} per sample) is unstable; steps up to {} are stable: use --substeps {}",
            self.balance,
            compact(self.eigenvalue),
            compact(self.step / self.substeps as f64),
            self.substeps,
            if self.substeps == 1 { "" } else { "s" },
            compact(self.stable_step),
            self.substeps_needed
        )
    }
}

/// A number with about four significant digits, without trailing zeros.
pub(crate) fn compact(value: f64) -> String {
    if value != 0.0 && (value.abs() < 1e-3 || value.abs() >= 1e6) {
        return format!("{value:.3e}");
    }
    let text = format!("{value:.4}");
    text.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// The physics evaluated at the training rows.
struct Probe {
    program: Program,
    rows: usize,
    states: Vec<f64>,
    inputs: Vec<f64>,
    params: Vec<f64>,
    net_widths: Vec<usize>,
    /// `rows x measured` values the balances should take: the finite-difference
    /// derivatives of the data (`der`), or the next values (`next`).
    targets: Vec<f64>,
    /// The longest step among the rows.
    largest_step: f64,
}

impl Probe {
    /// The physics at the pairs whose states are known from data at both ends.
    fn new(
        model: &ir::Model,
        scales: &[Vec<f64>],
        (tracks, pairs): (&[Track], &[PairAt]),
        hidden: &[f64],
    ) -> Result<Probe, BackendError> {
        let program = Program::compile(model, scales)?;
        let measured = model.states.len();
        let usable: Vec<PairAt> = (pairs.iter().copied())
            .filter(|&(index, knot)| {
                let track = &tracks[index];
                knot + 1 < track.len()
                    && (0..measured).all(|i| track.known[i][knot] && track.known[i][knot + 1])
            })
            .collect();
        let mut probe = Probe {
            net_widths: program.shape().nets.clone(),
            program,
            rows: usable.len(),
            states: Vec::new(),
            inputs: Vec::new(),
            params: initial_raw_params(model),
            targets: Vec::new(),
            largest_step: 0.0,
        };
        let discrete = model.dynamics == Dynamics::Discrete;
        for &(index, knot) in &usable {
            let track = &tracks[index];
            let step = track.steps[knot];
            probe.largest_step = probe.largest_step.max(step);
            probe.states.extend(track.states.iter().map(|s| s[knot]));
            probe.states.extend_from_slice(hidden);
            probe.inputs.extend(track.inputs.iter().map(|u| u[knot]));
            probe.targets.extend((track.states.iter()).map(|s| {
                if discrete {
                    s[knot + 1]
                } else {
                    (s[knot + 1] - s[knot]) / step
                }
            }));
        }
        Ok(probe)
    }

    fn state_width(&self) -> usize {
        self.program.shape().states
    }

    /// `rows x states` balances for the given states and network outputs.
    fn balances(&self, states: &[f64], nets: &[Vec<f64>]) -> Vec<f64> {
        let net_slices: Vec<&[f64]> = nets.iter().map(Vec::as_slice).collect();
        let inputs = ProgramInputs {
            rows: self.rows,
            states,
            inputs: &self.inputs,
            params: &self.params,
            nets: &net_slices,
        };
        let values = self.program.forward(&inputs);
        self.program
            .read(&values, self.rows, &self.program.balances)
    }

    fn silent_nets(&self) -> Vec<Vec<f64>> {
        (self.net_widths.iter())
            .map(|&w| vec![0.0; self.rows * w])
            .collect()
    }
}

/// `s_o` for every closure output: the `~` magnitude when given, else the data-driven
/// default of the module documentation (1 for outputs with a `*=` prior, where it is unused).
pub fn closure_scales(
    model: &ir::Model,
    tracks: &[Track],
    pairs: &[PairAt],
    hidden: &[f64],
) -> Result<Vec<Vec<f64>>, BackendError> {
    let unit: Vec<Vec<f64>> = (model.closures.iter())
        .map(|c| c.outputs.iter().map(|o| o.scale.unwrap_or(1.0)).collect())
        .collect();
    let probe = Probe::new(model, &unit, (tracks, pairs), hidden)?;
    let known = probe.balances(&probe.states, &probe.silent_nets());
    let mut scales = unit.clone();
    for (closure, spec) in model.closures.iter().enumerate() {
        for (output, out) in spec.outputs.iter().enumerate() {
            let multiplicative = matches!(&out.prior, Some(p) if p.kind == PriorKind::Mul);
            if out.scale.is_some() || multiplicative || probe.rows == 0 {
                continue;
            }
            scales[closure][output] = default_scale(&probe, &known, model, closure, output);
        }
    }
    Ok(scales)
}

fn default_scale(
    probe: &Probe,
    known: &[f64],
    model: &ir::Model,
    closure: usize,
    output: usize,
) -> f64 {
    let delta = 1e-3;
    let shifted = |sign: f64| {
        let mut nets = probe.silent_nets();
        let width = probe.net_widths[closure];
        for row in 0..probe.rows {
            nets[closure][row * width + output] = sign * delta;
        }
        probe.balances(&probe.states, &nets)
    };
    let (up, down) = (shifted(1.0), shifted(-1.0));
    let width = probe.state_width();
    let measured = model.states.len();
    let mut best: Option<f64> = None;
    for state in 0..measured {
        let sensitivity: Vec<f64> = (0..probe.rows)
            .map(|r| (up[r * width + state] - down[r * width + state]) / (2.0 * delta))
            .collect();
        let magnitudes: Vec<f64> = sensitivity.iter().map(|j| j.abs()).collect();
        let median = order_statistic(&magnitudes, 0.5).unwrap_or(0.0);
        if !(median > 0.0 && median.is_finite()) {
            continue;
        }
        let (mut total, mut count) = (0.0, 0usize);
        for (row, &j) in sensitivity.iter().enumerate() {
            if j.abs() >= 0.1 * median {
                let residual = probe.targets[row * measured + state] - known[row * width + state];
                total += (residual / j).powi(2);
                count += 1;
            }
        }
        let rms = (total / count.max(1) as f64).sqrt();
        if rms.is_finite() && rms > 0.0 {
            best = Some(best.map_or(rms, |b: f64| b.min(rms)));
        }
    }
    best.unwrap_or(1.0)
}

/// Stiffness warnings for the balances of a `der` model at step `h / substeps`.
pub fn stiffness(
    model: &ir::Model,
    scales: &[Vec<f64>],
    (tracks, pairs): (&[Track], &[PairAt]),
    hidden: &[f64],
    substeps: usize,
) -> Result<Vec<StiffnessWarning>, BackendError> {
    if model.dynamics == Dynamics::Discrete {
        return Ok(Vec::new());
    }
    let probe = Probe::new(model, scales, (tracks, pairs), hidden)?;
    if probe.rows == 0 {
        return Ok(Vec::new());
    }
    let silent = probe.silent_nets();
    let known = probe.balances(&probe.states, &silent);
    let width = probe.state_width();
    let measured = model.states.len();
    let names = (model.states.iter().chain(&model.hidden)).map(|s| s.name.clone());
    let mut warnings = Vec::new();
    for (state, name) in names.enumerate() {
        let typical = (0..probe.rows)
            .map(|r| probe.states[r * width + state].abs())
            .fold(0.0, f64::max);
        let delta = 1e-6 * typical.max(1e-12);
        let perturbed = |sign: f64| {
            let mut states = probe.states.clone();
            for row in 0..probe.rows {
                states[row * width + state] += sign * delta;
            }
            probe.balances(&states, &silent)
        };
        let (up, down) = (perturbed(1.0), perturbed(-1.0));
        let floor = 1e-3 * typical.max(1e-300);
        let rates: Vec<f64> = (0..probe.rows)
            .map(|r| {
                let index = r * width + state;
                let diagonal = (up[index] - down[index]) / (2.0 * delta);
                if state >= measured {
                    return diagonal;
                }
                let unknown = probe.targets[r * measured + state] - known[index];
                let magnitude = probe.states[index].abs().max(floor);
                diagonal - (-unknown).max(0.0) / magnitude
            })
            .filter(|rate| rate.is_finite())
            .collect();
        let Some(eigenvalue) = order_statistic(&rates, 0.01) else {
            continue;
        };
        let step = probe.largest_step;
        if eigenvalue * step / (substeps as f64) < -RK4_STABILITY_LIMIT {
            let stable_step = RK4_STABILITY_LIMIT / -eigenvalue;
            warnings.push(StiffnessWarning {
                balance: name,
                eigenvalue,
                step,
                substeps,
                stable_step,
                substeps_needed: (step / stable_step).ceil() as usize,
            });
        }
    }
    Ok(warnings)
}
