//! What the data says before training: default closure-output magnitudes and a stiffness
//! estimate of the balances.
//!
//! Both evaluate the physics at the rows of the training split (hidden states at their
//! initial values) with every closure output split into its *known part* (its value at
//! network output 0 when it has a prior, 0 without one) and an *unknown part* set freely
//! (`Program::compile_with_free_outputs`), and compare the balances with what the data asks
//! of them: the finite-difference derivative `d_i = (x_{i+1} - x_i) / h` for `der` models,
//! the next value `d_i = x_{i+1}` for `next` models. The *residual* of a measured balance
//! `X` is `r_i = d_i - known_i`, the balance with every unknown part at 0. The outputs
//! *sharing* it are those without a `*=` prior whose sensitivity `J_i = d f_X / d o`
//! (exact, by the program's reverse sweep) is not zero at most rows; `m_X` counts them.
//!
//! **Default magnitude `s_o`** (an output without `~` and without a `*=` prior): for each
//! measured balance `X` that `o` shares, the data asks `o_i ~ r_i / (m_X J_i)` of it, its
//! even share of the residual divided by the factor that multiplies it there (`X` itself
//! in `der X = mu * X`), over the rows where `|J_i|` is at least a tenth of its median;
//! `s_o` is the root mean square of that, from the balances with the fewest sharers (the
//! smallest when several tie). Without any estimate `s_o = 1`.
//!
//! **Stiffness**: RK4 is stable for `h * lambda >= -2.7853` on the negative real axis. For
//! each balance the local rate is the diagonal Jacobian `d f_X / d X` of the known part
//! (central difference) plus, for a measured balance whose residual is a consumption at
//! most rows (median below 0), what the unknown part would add if it were a first-order
//! law in `X`: `min(0, r_i) / |x_i|`, times the fraction of the sharers whose closure
//! observes `X` (only those can depend on it). A saturating law has a smaller eigenvalue, a
//! production (a positive residual, as in `der P = q * X`) adds none. The estimate is the
//! 1st percentile over the rows; a warning names the balance, the step that would be
//! stable and the `--substeps` that would make it so.

use std::fmt;

use crate::engine::graph::{initial_raw_params, BackendError};
use crate::engine::program::{Program, ProgramInputs};
use crate::ir::{self, Dynamics, PriorKind, Var};
use crate::numeric::order_statistic;

use crate::record::Track;

use crate::engine::pairs::PairAt;
use crate::solve::ode::tableau::RK4;

/// The RK4 stability limit of `h * lambda` on the negative real axis (about 2.7853),
/// derived from its tableau ([`crate::solve::ode::tableau::Tableau::stability_limit`]).
pub const RK4_STABILITY_LIMIT: f64 = RK4.stability_limit();

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

/// The physics evaluated at the training rows, every closure output its known part plus a
/// free unknown part (module documentation).
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
        (tracks, pairs): (&[Track], &[PairAt]),
        hidden: &[f64],
    ) -> Result<Probe, BackendError> {
        let program = Program::compile_with_free_outputs(model)?;
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

    fn program_inputs<'a>(
        &'a self,
        states: &'a [f64],
        nets: &'a [&'a [f64]],
    ) -> ProgramInputs<'a, f64> {
        ProgramInputs {
            rows: self.rows,
            states,
            inputs: &self.inputs,
            params: &self.params,
            nets,
        }
    }

    /// `rows x states` balances for the given states, every unknown part at 0.
    fn known(&self, states: &[f64]) -> Vec<f64> {
        let silent = self.silent_nets();
        let nets: Vec<&[f64]> = silent.iter().map(Vec::as_slice).collect();
        let values = self.program.forward(&self.program_inputs(states, &nets));
        self.program
            .read(&values, self.rows, &self.program.balances)
    }

    /// Per closure, `rows x outputs`: `d f_state / d o` at every row (unknown parts at 0).
    fn sensitivities(&self, state: usize) -> Vec<Vec<f64>> {
        let silent = self.silent_nets();
        let nets: Vec<&[f64]> = silent.iter().map(Vec::as_slice).collect();
        let inputs = self.program_inputs(&self.states, &nets);
        let values = self.program.forward(&inputs);
        let width = self.state_width();
        let mut seed = vec![0.0; self.rows * width];
        for row in 0..self.rows {
            seed[row * width + state] = 1.0;
        }
        let balances = &self.program.balances;
        (self.program.backward(&inputs, &values, balances, &seed)).nets
    }

    fn silent_nets(&self) -> Vec<Vec<f64>> {
        (self.net_widths.iter())
            .map(|&w| vec![0.0; self.rows * w])
            .collect()
    }
}

/// What one measured balance asks of the outputs sharing it.
struct Demand {
    /// `d_i - known_i` per row.
    residual: Vec<f64>,
    /// The sharing outputs `(closure, output)` with `d f / d o` per row.
    sharers: Vec<((usize, usize), Vec<f64>)>,
}

impl Demand {
    /// The demand on measured balance `state`, given the known balances.
    fn of(probe: &Probe, model: &ir::Model, state: usize, known: &[f64]) -> Demand {
        let (width, measured) = (probe.state_width(), model.states.len());
        let residual = (0..probe.rows)
            .map(|r| probe.targets[r * measured + state] - known[r * width + state])
            .collect();
        let sensitivities = probe.sensitivities(state);
        let mut sharers = Vec::new();
        for (closure, spec) in model.closures.iter().enumerate() {
            let outputs = spec.outputs.len();
            for (output, out) in spec.outputs.iter().enumerate() {
                if matches!(&out.prior, Some(p) if p.kind == PriorKind::Mul) {
                    continue;
                }
                let column: Vec<f64> = (0..probe.rows)
                    .map(|r| sensitivities[closure][r * outputs + output])
                    .collect();
                if median_magnitude(&column) > 0.0 {
                    sharers.push(((closure, output), column));
                }
            }
        }
        Demand { residual, sharers }
    }

    /// The root mean square of `r_i / (m J_i)` for `output`, if it shares the balance.
    fn magnitude(&self, output: (usize, usize)) -> Option<f64> {
        let (_, sensitivity) = self.sharers.iter().find(|(at, _)| *at == output)?;
        let median = median_magnitude(sensitivity);
        let share = self.sharers.len() as f64;
        let (mut total, mut count) = (0.0, 0usize);
        for (residual, &j) in self.residual.iter().zip(sensitivity) {
            if j.abs() >= 0.1 * median {
                total += (residual / (share * j)).powi(2);
                count += 1;
            }
        }
        let rms = (total / count.max(1) as f64).sqrt();
        (rms.is_finite() && rms > 0.0).then_some(rms)
    }
}

/// The median of `|values|` (0 when there are none or it is not finite).
fn median_magnitude(values: &[f64]) -> f64 {
    let magnitudes: Vec<f64> = values.iter().map(|j| j.abs()).collect();
    let median = order_statistic(&magnitudes, 0.5).unwrap_or(0.0);
    if median.is_finite() {
        median
    } else {
        0.0
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
    let mut scales: Vec<Vec<f64>> = (model.closures.iter())
        .map(|c| c.outputs.iter().map(|o| o.scale.unwrap_or(1.0)).collect())
        .collect();
    let probe = Probe::new(model, (tracks, pairs), hidden)?;
    if probe.rows == 0 {
        return Ok(scales);
    }
    let known = probe.known(&probe.states);
    let demands: Vec<Demand> = (0..model.states.len())
        .map(|state| Demand::of(&probe, model, state, &known))
        .collect();
    for (closure, spec) in model.closures.iter().enumerate() {
        for (output, out) in spec.outputs.iter().enumerate() {
            let multiplicative = matches!(&out.prior, Some(p) if p.kind == PriorKind::Mul);
            if out.scale.is_some() || multiplicative {
                continue;
            }
            let best = (demands.iter())
                .filter_map(|d| Some((d.sharers.len(), d.magnitude((closure, output))?)))
                .min_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
            scales[closure][output] = best.map_or(1.0, |(_, magnitude)| magnitude);
        }
    }
    Ok(scales)
}

/// Stiffness warnings for the balances of a `der` model at step `h / substeps`.
pub fn stiffness(
    model: &ir::Model,
    (tracks, pairs): (&[Track], &[PairAt]),
    hidden: &[f64],
    substeps: usize,
) -> Result<Vec<StiffnessWarning>, BackendError> {
    if model.dynamics == Dynamics::Discrete {
        return Ok(Vec::new());
    }
    let probe = Probe::new(model, (tracks, pairs), hidden)?;
    if probe.rows == 0 {
        return Ok(Vec::new());
    }
    let known = probe.known(&probe.states);
    let names = (model.states.iter().chain(&model.hidden)).map(|s| s.name.clone());
    let mut warnings = Vec::new();
    for (state, name) in names.enumerate() {
        let rates = local_rates(&probe, model, state, &known);
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

/// The local rate of balance `state` at every row (module documentation), finite ones only.
fn local_rates(probe: &Probe, model: &ir::Model, state: usize, known: &[f64]) -> Vec<f64> {
    let width = probe.state_width();
    let typical = (0..probe.rows)
        .map(|r| probe.states[r * width + state].abs())
        .fold(0.0, f64::max);
    let delta = 1e-6 * typical.max(1e-12);
    let perturbed = |sign: f64| {
        let mut states = probe.states.clone();
        for row in 0..probe.rows {
            states[row * width + state] += sign * delta;
        }
        probe.known(&states)
    };
    let (up, down) = (perturbed(1.0), perturbed(-1.0));
    let first_order = if state < model.states.len() {
        consumption(probe, model, state, known)
    } else {
        None
    };
    let floor = 1e-3 * typical.max(1e-300);
    (0..probe.rows)
        .map(|r| {
            let index = r * width + state;
            let diagonal = (up[index] - down[index]) / (2.0 * delta);
            let Some((fraction, residual)) = &first_order else {
                return diagonal;
            };
            let magnitude = probe.states[index].abs().max(floor);
            diagonal + fraction * residual[r].min(0.0) / magnitude
        })
        .filter(|rate| rate.is_finite())
        .collect()
}

/// For a measured balance whose residual is a consumption at most rows: the fraction of
/// its sharers whose closure observes the state, and the residual per row.
fn consumption(
    probe: &Probe,
    model: &ir::Model,
    state: usize,
    known: &[f64],
) -> Option<(f64, Vec<f64>)> {
    let demand = Demand::of(probe, model, state, known);
    let median = order_statistic(&demand.residual, 0.5)?;
    if demand.sharers.is_empty() || median.is_nan() || median >= 0.0 {
        return None;
    }
    let observing = (demand.sharers.iter())
        .filter(|((closure, _), _)| {
            let observe = &model.closures[*closure].embedding.observe;
            observe.contains(&Var::State(state))
        })
        .count();
    let fraction = observing as f64 / demand.sharers.len() as f64;
    (observing > 0).then_some((fraction, demand.residual))
}
