//! Closure outputs in the physics program: network output, prior and magnitude combined as
//! in spec section 3, then the declared constraint.
//!
//! A `positive` output with a prior keeps the prior exactly at `n = 0` and has no floor:
//! - `prior o *= p`: `o = max(p, 0) * g(n)` with
//!   `g(n) = max(n + 7/8, 0) + exp(8 min(n + 7/8, 0)) / 8`, which is `1 + n` (the
//!   unconstrained form) down to `n = -7/8` and `e^(8 (n + 7/8)) / 8` below, joined with
//!   value and slope: positive, `g(0) = 1` exactly (every constant a power of two), and it
//!   falls to zero about where `1 + n` does (`1/25` at `n = -1.02`), so a prior 25 times
//!   too large is corrected as easily as in the unconstrained form; `o` vanishes with its
//!   prior;
//! - `prior o += p`: `o = max(p + s n, 0)`, the additive form clipped at zero.
//!
//! Without a prior a `positive` output is `s softplus(n)`; a bounded output, and an
//! unconstrained one, is the plain form of spec section 3 through its constraint's map.

use super::{Binary, Compiler, Unary};

/// Where the linear part of a positive factor under `*=` joins its exponential tail:
/// `n = -JOIN`, the factor there `TAIL = 1 - JOIN`.
pub const JOIN: f64 = 0.875;
/// The factor at the join, and the tail's decay length in `n`.
pub const TAIL: f64 = 1.0 - JOIN;
use crate::backend::BackendError;
use crate::ir::{ClosureOutput, Constraint, PriorKind};

impl Compiler<'_> {
    /// Output `output` of closure `closure` (module documentation).
    pub(super) fn closure_output(
        &mut self,
        closure: usize,
        output: usize,
    ) -> Result<usize, BackendError> {
        if let Some(&reg) = self.closure_output_regs.get(&(closure, output)) {
            return Ok(reg);
        }
        if self.in_progress.contains(&(closure, output)) {
            return Err(BackendError::internal(
                "a closure prior depends on its own output".to_string(),
            ));
        }
        let model = self.model;
        let spec = (model.closures.get(closure))
            .and_then(|c| c.outputs.get(output))
            .ok_or_else(|| {
                BackendError::internal(format!("no closure output {closure}.{output}"))
            })?;
        let net = self.push(super::Instr::Net { closure, output });
        self.in_progress.push((closure, output));
        let reg = if self.free_outputs {
            self.known_part_plus(spec, net)
        } else {
            let scale = (self.scales.get(closure))
                .and_then(|s| s.get(output))
                .copied()
                .ok_or_else(|| BackendError::internal(format!("no scale for {}", spec.name)));
            scale.and_then(|scale| self.output_value(spec, net, scale))
        };
        self.in_progress.pop();
        let reg = reg?;
        self.closure_output_regs.insert((closure, output), reg);
        Ok(reg)
    }

    /// [`super::Program::compile_with_free_outputs`]: the output's value at `n = 0` when it
    /// has a prior (0 without one) plus the slot `net`.
    fn known_part_plus(&mut self, spec: &ClosureOutput, net: usize) -> Result<usize, BackendError> {
        if spec.prior.is_none() {
            return Ok(net);
        }
        let silent = self.constant(0.0);
        let known = self.output_value(spec, silent, 1.0)?;
        Ok(self.binary(Binary::Add, known, net))
    }

    /// The value of `spec` from its network output register `net` and magnitude `scale`.
    fn output_value(
        &mut self,
        spec: &ClosureOutput,
        net: usize,
        scale: f64,
    ) -> Result<usize, BackendError> {
        let positive = matches!(spec.constraint, Constraint::Positive);
        let Some(prior) = &spec.prior else {
            let s = self.constant(scale);
            let plain = self.binary(Binary::Mul, s, net);
            return Ok(self.constrain_output(plain, spec.constraint, scale));
        };
        let p = self.expr(&prior.expr)?;
        let zero = self.constant(0.0);
        Ok(match (prior.kind, positive) {
            (PriorKind::Mul, true) => {
                let clipped = self.binary(Binary::Max, p, zero);
                let factor = self.positive_factor(net);
                self.binary(Binary::Mul, clipped, factor)
            }
            (PriorKind::Mul, false) => {
                let one = self.constant(1.0);
                let factor = self.binary(Binary::Add, one, net);
                let combined = self.binary(Binary::Mul, p, factor);
                self.constrain_output(combined, spec.constraint, scale)
            }
            (PriorKind::Add, positive) => {
                let s = self.constant(scale);
                let correction = self.binary(Binary::Mul, s, net);
                let combined = self.binary(Binary::Add, p, correction);
                if positive {
                    self.binary(Binary::Max, combined, zero)
                } else {
                    self.constrain_output(combined, spec.constraint, scale)
                }
            }
        })
    }

    /// `g(n) = max(n + 7/8, 0) + exp(8 min(0, n + 7/8)) / 8`: `1 + n` down to `n = -7/8`,
    /// an exponential tail below with the same value and slope at the join. At `n = 0`
    /// every term is exact (`7/8 + 1/8`).
    fn positive_factor(&mut self, net: usize) -> usize {
        let zero = self.constant(0.0);
        let shift = self.constant(JOIN);
        let shifted = self.binary(Binary::Add, net, shift);
        let upper = self.binary(Binary::Max, shifted, zero);
        let lower = self.binary(Binary::Min, zero, shifted);
        let steep = self.constant(1.0 / TAIL);
        let scaled = self.binary(Binary::Mul, steep, lower);
        let decay = self.unary(Unary::Exp, scaled);
        let tail = self.constant(TAIL);
        let tail = self.binary(Binary::Mul, tail, decay);
        self.binary(Binary::Add, upper, tail)
    }

    /// An output's constraint map: `s softplus(o / s)` for `positive`, and for `in [lo, hi]`
    /// `lo + (hi - lo) sigmoid(4 (o - mid) / (hi - lo))` (unit slope at the middle).
    fn constrain_output(&mut self, combined: usize, constraint: Constraint, scale: f64) -> usize {
        match constraint {
            Constraint::Bounds(lo, hi) => {
                let middle = self.constant(-(lo + hi) / 2.0);
                let centred = self.binary(Binary::Add, combined, middle);
                let slope = self.constant(4.0 / (hi - lo));
                let argument = self.binary(Binary::Mul, slope, centred);
                self.constrain(argument, constraint, 1.0)
            }
            other => self.constrain(combined, other, scale),
        }
    }
}
