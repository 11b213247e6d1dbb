//! Elementwise operations of the physics program and their derivatives, shared by the
//! forward evaluation, the reverse sweep and compile-time constant folding.

use crate::numeric::Real;

/// Declares an operation enum from one list of its variants, and the macro `$with` that
/// runs a body with a constant of the variant a value holds (so that a loop over a column
/// evaluates one operation without matching it row by row). `$d` is `$`, passed in to
/// write the inner macro's own variables.
macro_rules! operations {
    (
        $(#[$meta:meta])*
        enum $name:ident, with $with:ident, $d:tt {
            $($(#[$doc:meta])* $variant:ident,)*
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum $name {
            $($(#[$doc])* $variant,)*
        }

        /// Runs `$body` with `$op` bound to a constant of the variant `$value` holds.
        macro_rules! $with {
            ($d value:expr, $d op:ident => $d body:expr) => {
                match $d value {
                    $($name::$variant => {
                        const $d op: $name = $name::$variant;
                        $d body
                    })*
                }
            };
        }
    };
}

operations! {
    /// A one-argument operation.
    enum Unary, with with_unary, $ {
        /// `-x`
        Neg,
        /// `e^x`
        Exp,
        /// `ln x`
        Log,
        /// `sqrt x`
        Sqrt,
        /// `|x|`
        Abs,
        /// `tanh x`
        Tanh,
        /// `1 / (1 + e^-x)`
        Sigmoid,
        /// `ln(1 + e^x)`, safe for large |x|
        Softplus,
    }
}

operations! {
    /// A two-argument operation.
    enum Binary, with with_binary, $ {
        /// `a + b`
        Add,
        /// `a - b`
        Sub,
        /// `a * b`
        Mul,
        /// `a / b`
        Div,
        /// `a ^ b`
        Pow,
        /// `min(a, b)`
        Min,
        /// `max(a, b)`
        Max,
    }
}

/// `op(x)`.
#[inline(always)]
pub fn unary<E: Real>(op: Unary, x: E) -> E {
    match op {
        Unary::Neg => -x,
        Unary::Exp => x.exp(),
        Unary::Log => x.ln(),
        Unary::Sqrt => x.sqrt(),
        Unary::Abs => x.abs(),
        Unary::Tanh => x.tanh(),
        Unary::Sigmoid => x.sigmoid(),
        Unary::Softplus => x.softplus(),
    }
}

/// `d op(x) / dx` given the input `x` and the output `y`.
#[inline(always)]
pub fn unary_derivative<E: Real>(op: Unary, x: E, y: E) -> E {
    match op {
        Unary::Neg => -E::ONE,
        Unary::Exp => y,
        Unary::Log => E::ONE / x,
        Unary::Sqrt => E::from_double(0.5) / y,
        Unary::Abs => sign(x),
        Unary::Tanh => E::ONE - y * y,
        Unary::Sigmoid => y * (E::ONE - y),
        Unary::Softplus => x.sigmoid(),
    }
}

fn sign<E: Real>(x: E) -> E {
    if x > E::ZERO {
        E::ONE
    } else if x < E::ZERO {
        -E::ONE
    } else {
        E::ZERO
    }
}

/// `op(a, b)`.
#[inline(always)]
pub fn binary<E: Real>(op: Binary, a: E, b: E) -> E {
    match op {
        Binary::Add => a + b,
        Binary::Sub => a - b,
        Binary::Mul => a * b,
        Binary::Div => a / b,
        Binary::Pow => a.powf(b),
        Binary::Min => {
            if b < a {
                b
            } else {
                a
            }
        }
        Binary::Max => {
            if b > a {
                b
            } else {
                a
            }
        }
    }
}

/// `(d op / da, d op / db)` given the operands and the output `y`. `min`/`max` send the
/// whole derivative to the operand they select; `a^b` has no `b` derivative where `a <= 0`.
#[inline(always)]
pub fn binary_derivatives<E: Real>(op: Binary, a: E, b: E, y: E) -> (E, E) {
    match op {
        Binary::Add => (E::ONE, E::ONE),
        Binary::Sub => (E::ONE, -E::ONE),
        Binary::Mul => (b, a),
        Binary::Div => (E::ONE / b, -y / b),
        Binary::Pow => {
            let da = b * a.powf(b - E::ONE);
            let db = if a > E::ZERO { y * a.ln() } else { E::ZERO };
            (da, db)
        }
        Binary::Min => {
            if b < a {
                (E::ZERO, E::ONE)
            } else {
                (E::ONE, E::ZERO)
            }
        }
        Binary::Max => {
            if b > a {
                (E::ZERO, E::ONE)
            } else {
                (E::ONE, E::ZERO)
            }
        }
    }
}

/// `out[i] = op(x[i])` over a column.
pub fn unary_column<E: Real>(op: Unary, out: &mut [E], x: &[E]) {
    with_unary!(op, OP => {
        for (y, &x) in out.iter_mut().zip(x) {
            *y = unary(OP, x);
        }
    })
}

/// `out[i] = op(a[i], b[i])` over a column.
pub fn binary_column<E: Real>(op: Binary, out: &mut [E], a: &[E], b: &[E]) {
    with_binary!(op, OP => {
        for ((y, &a), &b) in out.iter_mut().zip(a).zip(b) {
            *y = binary(OP, a, b);
        }
    })
}

/// The reverse of [`unary_column`]: `adjoint_x[i] += upstream[i] op'(x[i])` given the
/// column's input `x` and output `y`.
pub fn unary_column_reverse<E: Real>(
    op: Unary,
    adjoint_x: &mut [E],
    upstream: &[E],
    (x, y): (&[E], &[E]),
) {
    with_unary!(op, OP => {
        for (((slot, &up), &x), &y) in adjoint_x.iter_mut().zip(upstream).zip(x).zip(y) {
            *slot += up * unary_derivative(OP, x, y);
        }
    })
}

/// The adjoints a reverse step of a binary column adds to: its two operands' (distinct
/// registers) or one register that is both operands.
pub enum Operands<'a, E> {
    /// `op(a, b)` with `a` and `b` different registers.
    Distinct(&'a mut [E], &'a mut [E]),
    /// `op(a, a)`.
    Same(&'a mut [E]),
}

/// The reverse of [`binary_column`]: adds `upstream * d op / da` and `upstream * d op / db`
/// to the operands' adjoints, given the operand columns and the output `y`.
pub fn binary_column_reverse<E: Real>(
    op: Binary,
    adjoints: Operands<E>,
    upstream: &[E],
    (a, b, y): (&[E], &[E], &[E]),
) {
    with_binary!(op, OP => match adjoints {
        Operands::Distinct(adjoint_a, adjoint_b) => {
            let columns = upstream.iter().zip(a).zip(b).zip(y);
            for ((slot_a, slot_b), (((&up, &a), &b), &y)) in
                adjoint_a.iter_mut().zip(adjoint_b.iter_mut()).zip(columns)
            {
                let (da, db) = binary_derivatives(OP, a, b, y);
                *slot_a += up * da;
                *slot_b += up * db;
            }
        }
        Operands::Same(adjoint) => {
            let columns = upstream.iter().zip(a).zip(b).zip(y);
            for (slot, (((&up, &a), &b), &y)) in adjoint.iter_mut().zip(columns) {
                let (da, db) = binary_derivatives(OP, a, b, y);
                *slot += up * da;
                *slot += up * db;
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const UNARY: [Unary; 8] = [
        Unary::Neg,
        Unary::Exp,
        Unary::Log,
        Unary::Sqrt,
        Unary::Abs,
        Unary::Tanh,
        Unary::Sigmoid,
        Unary::Softplus,
    ];
    const BINARY: [Binary; 7] = [
        Binary::Add,
        Binary::Sub,
        Binary::Mul,
        Binary::Div,
        Binary::Pow,
        Binary::Min,
        Binary::Max,
    ];

    fn close(analytic: f64, numeric: f64) -> bool {
        (analytic - numeric).abs() <= 1e-7 * (1.0 + numeric.abs())
    }

    #[test]
    fn unary_derivatives_match_central_differences() {
        for op in UNARY {
            for x in [0.3, 1.7, 4.0, -2.5] {
                if matches!(op, Unary::Log | Unary::Sqrt) && x < 0.0 {
                    continue;
                }
                let step = 1e-6;
                let numeric = (unary(op, x + step) - unary(op, x - step)) / (2.0 * step);
                let analytic = unary_derivative(op, x, unary(op, x));
                assert!(
                    close(analytic, numeric),
                    "{op:?} at {x}: {analytic} vs {numeric}"
                );
            }
        }
    }

    #[test]
    fn binary_derivatives_match_central_differences() {
        for op in BINARY {
            for (a, b) in [(1.3, 0.4), (0.7, 2.2), (2.5, -1.5)] {
                let step = 1e-6;
                let (da, db) = binary_derivatives(op, a, b, binary(op, a, b));
                let numeric_a = (binary(op, a + step, b) - binary(op, a - step, b)) / (2.0 * step);
                let numeric_b = (binary(op, a, b + step) - binary(op, a, b - step)) / (2.0 * step);
                assert!(close(da, numeric_a), "{op:?} d/da at ({a}, {b})");
                assert!(close(db, numeric_b), "{op:?} d/db at ({a}, {b})");
            }
        }
    }

    #[test]
    fn values_are_the_textbook_ones() {
        assert_eq!(unary(Unary::Neg, 2.0), -2.0);
        assert_eq!(unary(Unary::Abs, -3.0), 3.0);
        assert_eq!(binary(Binary::Pow, 2.0, 3.0), 8.0);
        assert_eq!(binary(Binary::Min, 2.0, -1.0), -1.0);
        assert_eq!(binary(Binary::Max, 2.0, -1.0), 2.0);
        assert_eq!(binary(Binary::Div, 3.0, 4.0), 0.75);
        assert!((unary(Unary::Softplus, 0.0_f64) - 2.0_f64.ln()).abs() < 1e-15);
        // No derivative with respect to a non-positive base's exponent.
        assert_eq!(binary_derivatives(Binary::Pow, -2.0, 2.0, 4.0).1, 0.0);
    }
}
