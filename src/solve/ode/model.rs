//! A model's balances as an [`OdeSystem`]: what the simulator, the fits and the diagnosis
//! integrate (or, for a `next` model, iterate).

use super::system::OdeSystem;
use crate::eval::{CompileError, CompiledRhs, JacobianProgram, Layout};
use crate::ir::Model;
use std::ops::Range;

/// A model's balances as an [`OdeSystem`] (or, for a `next` model, as its map): the states
/// are the measured then hidden states, and the other slots (inputs, params) are held at
/// whatever they were last set to. Its Jacobian is the exact derivative of the balances
/// ([`JacobianProgram`]); forward sensitivities are taken with respect to the slots given
/// to [`ModelSystem::differentiate_by`].
#[derive(Debug, Clone)]
pub struct ModelSystem {
    layout: Layout,
    rhs: CompiledRhs,
    jacobian: JacobianProgram,
    sensitivity: Option<JacobianProgram>,
    extra: usize,
    slots: Vec<f64>,
    scratch: Vec<f64>,
    values: Vec<f64>,
    combined: Vec<f64>,
    states: Range<usize>,
}

impl ModelSystem {
    /// Compiles the balances of `model` and their Jacobian; params start at their initial
    /// values, inputs at 0.
    pub fn new(model: &Model) -> Result<Self, CompileError> {
        let layout = Layout::new(model);
        let rhs = CompiledRhs::new(model, &layout)?;
        let states: Vec<usize> = layout.state_range().collect();
        let jacobian = JacobianProgram::balances(model, &layout, &states)?;
        Ok(ModelSystem {
            slots: layout.initial_slots(),
            states: layout.state_range(),
            values: vec![0.0; states.len()],
            layout,
            rhs,
            jacobian,
            sensitivity: None,
            extra: 0,
            scratch: Vec::new(),
            combined: Vec::new(),
        })
    }

    /// Takes forward sensitivities with respect to the quantities in `slots` (params,
    /// closure outputs held as corrections, ...) from now on, followed by `extra` columns
    /// that the balances do not depend on (initial values: their sensitivities only start
    /// non-zero).
    pub fn differentiate_by(
        &mut self,
        model: &Model,
        slots: &[usize],
        extra: usize,
    ) -> Result<(), CompileError> {
        let wrt: Vec<usize> = self.states.clone().chain(slots.iter().copied()).collect();
        self.sensitivity = Some(JacobianProgram::balances(model, &self.layout, &wrt)?);
        self.extra = extra;
        Ok(())
    }

    /// The slot layout of the model.
    pub fn layout(&self) -> &Layout {
        &self.layout
    }

    /// Sets the number of columns after the differentiated slots that the balances do not
    /// depend on (see [`ModelSystem::differentiate_by`]).
    pub fn set_extra_columns(&mut self, extra: usize) {
        self.extra = extra;
    }

    /// All slots, e.g. to set params before integrating.
    pub fn slots_mut(&mut self) -> &mut [f64] {
        &mut self.slots
    }

    /// Holds every input at its entry `index` of `table` (one column per input: a
    /// record's inputs by row, a table of held signal values).
    pub fn hold(&mut self, table: &[Vec<f64>], index: usize) {
        for (slot, column) in self.slots[self.layout.input_range()].iter_mut().zip(table) {
            *slot = column[index];
        }
    }
}

impl OdeSystem for ModelSystem {
    fn dim(&self) -> usize {
        self.rhs.dim()
    }

    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) {
        self.slots[self.states.clone()].copy_from_slice(y);
        self.rhs.eval(&self.slots, &mut self.scratch, dydt);
    }

    fn jacobian(&mut self, _t: f64, y: &[f64], jacobian: &mut [f64]) {
        self.slots[self.states.clone()].copy_from_slice(y);
        let (slots, scratch, values) = (&self.slots, &mut self.scratch, &mut self.values);
        self.jacobian.eval(slots, scratch, values, jacobian);
    }

    fn sensitivity_params(&self) -> usize {
        (self.sensitivity.as_ref()).map_or(0, |program| {
            program.columns() - self.states.len() + self.extra
        })
    }

    fn sensitivity_derivative(&mut self, _t: f64, y: &[f64], s: &[f64], out: &mut [f64]) {
        let width = self.sensitivity_params();
        match &self.sensitivity {
            Some(program) => {
                self.slots[self.states.clone()].copy_from_slice(y);
                program.eval_product(&self.slots, &mut self.scratch, s, width, out);
            }
            None => out.fill(0.0),
        }
    }

    fn sensitivity_jacobians(&mut self, t: f64, y: &[f64], states: &mut [f64], params: &mut [f64]) {
        let Some(program) = &self.sensitivity else {
            return self.jacobian(t, y, states);
        };
        self.slots[self.states.clone()].copy_from_slice(y);
        let (n, columns) = (self.states.len(), program.columns());
        self.combined.resize(n * columns, 0.0);
        program.eval(
            &self.slots,
            &mut self.scratch,
            &mut self.values,
            &mut self.combined,
        );
        let (slots, p) = (columns - n, columns - n + self.extra);
        for i in 0..n {
            let row = &self.combined[i * columns..(i + 1) * columns];
            states[i * n..(i + 1) * n].copy_from_slice(&row[..n]);
            params[i * p..i * p + slots].copy_from_slice(&row[n..]);
            params[i * p + slots..(i + 1) * p].fill(0.0);
        }
    }
}
