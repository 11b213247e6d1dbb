//! Hand-built IR models for the simulator tests (independent of the front end), and a
//! small operator-overloading builder that keeps their equations readable.

use crate::ir::{
    Balance, BinOp, Const, Definition, Dynamics, Expr, Func, Input, Model, State, Var,
};
use std::ops::{Add, Div, Mul, Neg, Sub};

/// An expression under construction.
#[derive(Debug, Clone)]
pub struct E(pub Expr);

impl E {
    pub fn exp(self) -> E {
        E(Expr::Call(Func::Exp, vec![self.0]))
    }
    pub fn pow(self, exponent: impl Into<E>) -> E {
        binary(BinOp::Pow, self, exponent.into())
    }
}

impl From<f64> for E {
    fn from(value: f64) -> Self {
        E(Expr::Num(value))
    }
}

fn binary(op: BinOp, a: E, b: E) -> E {
    E(Expr::Bin(op, Box::new(a.0), Box::new(b.0)))
}

macro_rules! operator {
    ($trait:ident, $method:ident, $op:expr) => {
        impl<R: Into<E>> $trait<R> for E {
            type Output = E;
            fn $method(self, rhs: R) -> E {
                binary($op, self, rhs.into())
            }
        }
        impl $trait<E> for f64 {
            type Output = E;
            fn $method(self, rhs: E) -> E {
                binary($op, E::from(self), rhs)
            }
        }
    };
}
operator!(Add, add, BinOp::Add);
operator!(Sub, sub, BinOp::Sub);
operator!(Mul, mul, BinOp::Mul);
operator!(Div, div, BinOp::Div);

impl Neg for E {
    type Output = E;
    fn neg(self) -> E {
        E(Expr::Neg(Box::new(self.0)))
    }
}

/// A model with nothing declared yet.
pub fn empty_model(name: &str, dynamics: Dynamics) -> Model {
    Model {
        name: name.into(),
        description: None,
        time_unit: None,
        inputs: vec![],
        states: vec![],
        hidden: vec![],
        consts: vec![],
        params: vec![],
        lets: vec![],
        outputs: vec![],
        closures: vec![],
        dynamics,
        balances: vec![],
        effects: vec![],
        units: Default::default(),
        noise: vec![],
    }
}

/// Declarations added one by one, each returning the expression that refers to it.
pub struct Builder {
    pub model: Model,
}

impl Builder {
    pub fn new(name: &str, dynamics: Dynamics) -> Self {
        Builder {
            model: empty_model(name, dynamics),
        }
    }
    pub fn input(&mut self, name: &str) -> E {
        self.model.inputs.push(Input {
            name: name.into(),
            bounds: None,
        });
        E(Expr::Var(Var::Input(self.model.inputs.len() - 1)))
    }
    pub fn state(&mut self, name: &str, init: Option<f64>) -> E {
        self.model.states.push(declared(name, init));
        E(Expr::Var(Var::State(self.model.states.len() - 1)))
    }
    pub fn hidden(&mut self, name: &str, init: Option<f64>) -> E {
        self.model.hidden.push(declared(name, init));
        E(Expr::Var(Var::Hidden(self.model.hidden.len() - 1)))
    }
    pub fn constant(&mut self, name: &str, value: f64) -> E {
        self.model.consts.push(Const {
            name: name.into(),
            value,
        });
        E(Expr::Var(Var::Const(self.model.consts.len() - 1)))
    }
    /// Records a `let` and returns its (inlined) expression.
    pub fn define(&mut self, name: &str, expr: E) -> E {
        self.model.lets.push(Definition {
            name: name.into(),
            expr: expr.0.clone(),
        });
        expr
    }
    pub fn output(&mut self, name: &str, expr: E) {
        self.model.outputs.push(Definition {
            name: name.into(),
            expr: expr.0,
        });
    }
    /// The balance of the state `state` refers to.
    pub fn balance(&mut self, state: &E, expr: E) {
        let Expr::Var(var) = state.0 else {
            panic!("a balance governs a state")
        };
        self.model.balances.push(Balance {
            state: var,
            expr: expr.0,
        });
    }
}

fn declared(name: &str, init: Option<f64>) -> State {
    State {
        name: name.into(),
        init: init.map(Expr::Num),
        nonnegative: false,
    }
}

/// `dx/dt = -a x - w y`, `dy/dt = w x - a y`: a decaying rotation.
pub fn rotation(decay: f64, frequency: f64, start: [f64; 2]) -> Model {
    let mut b = Builder::new("rotation", Dynamics::Continuous);
    let x = b.state("x", Some(start[0]));
    let y = b.state("y", Some(start[1]));
    let a = b.constant("a", decay);
    let w = b.constant("w", frequency);
    b.balance(&x, -(a.clone() * x.clone()) - w.clone() * y.clone());
    b.balance(&y, w * x.clone() - a * y.clone());
    b.output("radius_squared", x.clone() * x + y.clone() * y);
    b.model
}

/// `dx/dt = (gain u - x) / tau`: a first-order lag driven by input `u`.
pub fn first_order_lag(gain: f64, tau: f64, start: f64) -> Model {
    let mut b = Builder::new("lag", Dynamics::Continuous);
    let u = b.input("u");
    let x = b.state("x", Some(start));
    let k = b.constant("gain", gain);
    let tau = b.constant("tau", tau);
    b.balance(&x, (k * u - x.clone()) / tau);
    b.model
}

/// The chemostat truth model of paper section 3.1.
pub fn chemostat() -> Model {
    let mut b = Builder::new("chemostat", Dynamics::Continuous);
    let e0 = b.input("E0");
    let s = b.state("S", Some(0.02));
    let e = b.hidden("E", Some(0.01));
    let s0 = b.constant("S0", 3e-2);
    let theta = b.constant("theta", 20.0);
    let kcat = b.constant("kcat", 0.14);
    let k_m = b.constant("K_M", 1.5e-2);
    let rate = b.define("r", kcat * e.clone() * s.clone() / (k_m + s.clone()));
    b.balance(&s, (s0.clone() - s.clone()) / theta.clone() - rate);
    b.balance(&e, (e0 - e.clone()) / theta);
    b.output("P", s0 - s);
    b.model
}

/// The light-controlled bioreactor truth model of paper section 3.2.
pub fn bioreactor() -> Model {
    let mut b = Builder::new("bioreactor", Dynamics::Continuous);
    let u = b.input("u");
    let x = b.state("X", Some(1.0));
    let a = b.state("A", Some(0.5));
    let bb = b.state("B", Some(0.5));
    let s = b.state("S", Some(10.0));
    let e_a = b.hidden("E_A", Some(0.5));
    let e_b = b.hidden("E_B", Some(0.2));
    let r_a = b.hidden("R_A", Some(0.5));
    let r_b = b.hidden("R_B", Some(0.2));
    let mut c = |name: &str, value: f64| b.constant(name, value);
    let (d, s0, y_x, y_a, y_b) = (
        c("D", 0.05),
        c("S0", 20.0),
        c("Y_X", 0.435),
        c("Y_A", 0.607),
        c("Y_B", 0.3),
    );
    let (mu0, k_s, k_a, k_b, k_eb) = (
        c("mu0", 0.22),
        c("K_S", 1.03),
        c("K_A", 7.12),
        c("K_B", 0.712),
        c("K_EB", 0.5),
    );
    let (r_a1, r_a2, k_sa, k_aa) = (
        c("R_A1", 0.0),
        c("R_A2", 1.79),
        c("K_SA", 1.68),
        c("K_AA", 14.0),
    );
    let (r_b1, r_b2, k_sb, k_bb) = (
        c("R_B1", 0.0985),
        c("R_B2", 0.448),
        c("K_SB", 1.68),
        c("K_BB", 14.0),
    );
    let (tau1, tau2, tau3, tau4) = (
        c("tau1", 5.0),
        c("tau2", 6.0),
        c("tau3", 1.0),
        c("tau4", 1.0),
    );
    let (n_a, n_b, k_ha, k_hb) = (
        c("N_A", 2.7),
        c("N_B", 2.3),
        c("K_HA", 0.08),
        c("K_HB", 0.30),
    );
    let inhibition = (-(a.clone() / k_a) - bb.clone() / k_b - e_b.clone() / k_eb).exp();
    let mu = b.define("mu", mu0 * s.clone() * inhibition / (k_s + s.clone()));
    let mu_a = b.define(
        "mu_A",
        e_a.clone() * s.clone() * (-(a.clone() / k_aa)).exp() / (k_sa + s.clone()),
    );
    let mu_b = b.define(
        "mu_B",
        e_b.clone() * s.clone() * (-(bb.clone() / k_bb)).exp() / (k_sb + s.clone()),
    );
    let light_a = u.clone().pow(n_a);
    let r_a0 = b.define(
        "R_A0",
        r_a1.clone() + (r_a2 - r_a1) * light_a.clone() / (k_ha + light_a),
    );
    let dark_b = (1.0 - u).pow(n_b);
    let r_b0 = b.define(
        "R_B0",
        r_b1.clone() + (r_b2 - r_b1) * dark_b.clone() / (k_hb + dark_b),
    );
    b.balance(&x, (mu.clone() - d.clone()) * x.clone());
    b.balance(&a, mu_a.clone() * x.clone() - d.clone() * a.clone());
    b.balance(&bb, mu_b.clone() * x.clone() - d.clone() * bb.clone());
    let uptake = mu / y_x + mu_a / y_a + mu_b / y_b;
    b.balance(&s, -(uptake * x.clone()) + (s0 - s.clone()) * d);
    b.balance(&e_a, -((e_a.clone() - r_a.clone()) / tau1));
    b.balance(&e_b, -((e_b.clone() - r_b.clone()) / tau2));
    b.balance(&r_a, -((r_a.clone() - r_a0) / tau3));
    b.balance(&r_b, -((r_b.clone() - r_b0) / tau4));
    b.model
}
