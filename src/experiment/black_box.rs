//! Grey box or black box, read from the model: continuous balances (`der`) are grey boxes,
//! discrete maps (`next`) and balances learned whole black boxes.

use crate::ir;

/// Whether a model is a black box: a discrete map (`next`), or balances that are each a
/// closure output alone (`der X = dX`).
pub fn is_black_box(model: &ir::Model) -> bool {
    // A continuous model is a black box when every balance is a bare closure output (its
    // derivative learned whole, as `blackbox_ode.gbm`): no physics left in it.
    let learned = |balance: &ir::Balance| {
        matches!(balance.expr, ir::Expr::Var(ir::Var::ClosureOutput { .. }))
    };
    model.dynamics == ir::Dynamics::Discrete
        || (!model.balances.is_empty() && model.balances.iter().all(learned))
}
