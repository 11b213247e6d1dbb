//! The canonical text form of a compiled model (`gbc compile --emit ir`): deterministic,
//! one fact per line, expressions printed with names. Golden files test this text.

use super::model::{
    var_name, Closure, Constraint, Definition, Dynamics, Expr, Measured, Model, PriorKind,
    QuantityUnit,
};
use crate::ast::{self, format_number, Span, Spanned};
use std::fmt::Write;

/// Prints the model in its canonical text form.
pub fn print(model: &Model) -> String {
    let mut out = String::new();
    // Writing into a String cannot fail.
    let _ = write_model(&mut out, model);
    out
}

/// An expression of `model` as source text.
pub fn expr_text(model: &Model, expr: &Expr) -> String {
    to_ast(model, expr).to_string()
}

fn to_ast(model: &Model, expr: &Expr) -> ast::Expr {
    let boxed = |e: &Expr| Box::new(Spanned::new(to_ast(model, e), Span::default()));
    match expr {
        Expr::Num(value) => ast::Expr::Num(*value),
        Expr::Var(var) => ast::Expr::Name(var_name(model, *var).to_string()),
        Expr::Neg(inner) => ast::Expr::Neg(boxed(inner)),
        Expr::Bin(op, lhs, rhs) => ast::Expr::Binary(*op, boxed(lhs), boxed(rhs)),
        Expr::Call(func, args) => ast::Expr::Call(
            Spanned::new(func.name().to_string(), Span::default()),
            args.iter()
                .map(|a| Spanned::new(to_ast(model, a), Span::default()))
                .collect(),
        ),
    }
}

/// ` [unit]` (or ` [unit, inferred]`) after a name, or nothing.
fn unit_text(unit: Option<&QuantityUnit>) -> String {
    match unit {
        Some(unit) if unit.inferred => format!(" [{}, inferred]", unit.text),
        Some(unit) => format!(" [{}]", unit.text),
        None => String::new(),
    }
}

fn constraint_text(constraint: Constraint) -> String {
    match constraint {
        Constraint::Free => String::new(),
        Constraint::Positive => " positive".to_string(),
        Constraint::Bounds(lo, hi) => {
            format!(" in [{}, {}]", format_number(lo), format_number(hi))
        }
    }
}

fn write_model(out: &mut String, model: &Model) -> std::fmt::Result {
    write!(out, "model {}", model.name)?;
    if let Some(description) = &model.description {
        write!(out, " \"{description}\"")?;
    }
    writeln!(out)?;
    if let Some(unit) = &model.time_unit {
        writeln!(out, "time {unit}")?;
    }
    let dynamics = match model.dynamics {
        Dynamics::Continuous => "continuous (der)",
        Dynamics::Discrete => "discrete (next)",
    };
    writeln!(out, "dynamics {dynamics}")?;
    write_symbols(out, model)?;
    for (index, closure) in model.closures.iter().enumerate() {
        write_closure(out, model, index, closure)?;
    }
    write_definitions(out, model, "lets", &model.lets)?;
    write_definitions(out, model, "outputs", &model.outputs)?;
    write_noise(out, model)?;
    writeln!(out, "\nbalances")?;
    let keyword = match model.dynamics {
        Dynamics::Continuous => "der",
        Dynamics::Discrete => "next",
    };
    for balance in &model.balances {
        let name = var_name(model, balance.state);
        writeln!(
            out,
            "  {keyword} {name} = {}",
            expr_text(model, &balance.expr)
        )?;
    }
    for effect in &model.effects {
        write!(out, "\neffect {}", effect.name)?;
        if let Some(description) = &effect.description {
            write!(out, " \"{description}\"")?;
        }
        writeln!(out)?;
        let effect_units = model.units.effects.get(&effect.name);
        for param in &effect.params {
            let constraint = constraint_text(param.constraint);
            let init = format_number(param.init);
            let unit = unit_text(effect_units.and_then(|units| units.get(&param.name)));
            writeln!(out, "  param {}{unit} = {init}{constraint}", param.name)?;
        }
        for line in &effect.lines {
            writeln!(out, "  {line}")?;
        }
    }
    Ok(())
}

fn write_symbols(out: &mut String, model: &Model) -> std::fmt::Result {
    writeln!(out, "\ninputs ({})", model.inputs.len())?;
    for (i, input) in model.inputs.iter().enumerate() {
        write!(
            out,
            "  u{i} {}{}",
            input.name,
            unit_text(model.unit(&input.name))
        )?;
        if let Some((lo, hi)) = input.bounds {
            write!(out, " in [{}, {}]", format_number(lo), format_number(hi))?;
        }
        writeln!(out)?;
    }
    for (title, prefix, states) in [
        ("states", "x", &model.states),
        ("hidden", "h", &model.hidden),
    ] {
        writeln!(out, "\n{title} ({})", states.len())?;
        for (i, state) in states.iter().enumerate() {
            write!(
                out,
                "  {prefix}{i} {}{}",
                state.name,
                unit_text(model.unit(&state.name))
            )?;
            if let Some(init) = &state.init {
                write!(out, " = {}", expr_text(model, init))?;
            }
            if state.nonnegative {
                write!(out, " nonnegative")?;
            }
            writeln!(out)?;
        }
    }
    writeln!(out, "\nconsts ({})", model.consts.len())?;
    for (i, constant) in model.consts.iter().enumerate() {
        let value = format_number(constant.value);
        let unit = unit_text(model.unit(&constant.name));
        writeln!(out, "  c{i} {}{unit} = {value}", constant.name)?;
    }
    writeln!(out, "\nparams ({})", model.params.len())?;
    for (i, param) in model.params.iter().enumerate() {
        let constraint = constraint_text(param.constraint);
        let init = format_number(param.init);
        let unit = unit_text(model.unit(&param.name));
        writeln!(out, "  p{i} {}{unit} = {init}{constraint}", param.name)?;
    }
    Ok(())
}

fn write_closure(
    out: &mut String,
    model: &Model,
    index: usize,
    closure: &Closure,
) -> std::fmt::Result {
    let embedding = &closure.embedding;
    let widths: Vec<String> = closure
        .network
        .hidden
        .iter()
        .map(|w| w.to_string())
        .collect();
    writeln!(out, "\nclosure {} (network {index})", closure.name)?;
    writeln!(
        out,
        "  network {} -> [{}] {} -> {} linear",
        embedding.width(),
        widths.join(", "),
        closure.network.activation.name(),
        closure.outputs.len()
    )?;
    writeln!(
        out,
        "  embedding delay {} dim {} ({} observed x {} lags = {} inputs, history {})",
        format_number(embedding.delay),
        embedding.dim,
        embedding.observe.len(),
        embedding.dim,
        embedding.width(),
        format_number(embedding.span())
    )?;
    for (k, (var, lag)) in embedding.layout().into_iter().enumerate() {
        let name = var_name(model, var);
        if lag == 0 {
            writeln!(out, "    in {k}: {name}(t)")?;
        } else {
            let shift = format_number(lag as f64 * embedding.delay);
            writeln!(out, "    in {k}: {name}(t - {shift})")?;
        }
    }
    for (k, output) in closure.outputs.iter().enumerate() {
        let scale = output.scale.map_or("default".to_string(), format_number);
        let constraint = constraint_text(output.constraint);
        let form = match &output.prior {
            None => format!("{} = s * n{k}", output.name),
            Some(prior) => {
                let p = expr_text(model, &prior.expr);
                let positive = matches!(output.constraint, Constraint::Positive);
                match (prior.kind, positive) {
                    (PriorKind::Mul, false) => format!("{} = ({p}) * (1 + n{k})", output.name),
                    (PriorKind::Mul, true) => format!(
                        "{} = max({p}, 0) * (max(n{k} + 0.875, 0) + 0.125 * exp(8 * min(n{k} + 0.875, 0)))",
                        output.name
                    ),
                    (PriorKind::Add, false) => format!("{} = {p} + s * n{k}", output.name),
                    (PriorKind::Add, true) => format!("{} = max({p} + s * n{k}, 0)", output.name),
                }
            }
        };
        let unit = unit_text(model.unit(&output.name));
        writeln!(
            out,
            "  out {k}: {}{unit} ~ {scale}{constraint}; {form}",
            output.name
        )?;
    }
    Ok(())
}

/// The declared measurement noise, when the model declares any.
fn write_noise(out: &mut String, model: &Model) -> std::fmt::Result {
    if model.noise.is_empty() {
        return Ok(());
    }
    writeln!(
        out,
        "\nnoise (sigma(y) = sqrt(absolute^2 + (relative * y)^2))"
    )?;
    for noise in &model.noise {
        let kind = match noise.target {
            Measured::State(_) => "state",
            Measured::Output(_) => "output",
        };
        let name = model.measured_name(noise.target);
        writeln!(
            out,
            "  {kind} {name}{}: relative {}, absolute {}",
            unit_text(model.unit(name)),
            format_number(noise.relative),
            format_number(noise.absolute)
        )?;
    }
    Ok(())
}

fn write_definitions(
    out: &mut String,
    model: &Model,
    title: &str,
    list: &[Definition],
) -> std::fmt::Result {
    if list.is_empty() {
        return Ok(());
    }
    writeln!(out, "\n{title}")?;
    for definition in list {
        writeln!(
            out,
            "  {}{} = {}",
            definition.name,
            unit_text(model.unit(&definition.name)),
            expr_text(model, &definition.expr)
        )?;
    }
    Ok(())
}
