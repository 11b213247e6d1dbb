//! Forward sensitivities through each method against a closed form and against finite
//! differences of the integration itself.

use crate::ir::Model;
use crate::solve::ode::{Integrator, Method, ModelSystem, OdeSystem, Tolerances};

fn compile(source: &str) -> Model {
    crate::driver::compile("test.gbm", source, &[])
        .unwrap_or_else(|_| panic!("model does not compile"))
        .model
}

/// A model system differentiated by all its params, at `params`.
fn system(model: &Model, params: &[f64]) -> ModelSystem {
    let mut system = ModelSystem::new(model).unwrap();
    let range = system.layout().param_range();
    system.slots_mut()[range.clone()].copy_from_slice(params);
    let slots: Vec<usize> = range.collect();
    system.differentiate_by(model, &slots, 0).unwrap();
    system
}

/// States and sensitivities at `samples`, from `start` with zero initial sensitivities.
fn integrate(
    model: &Model,
    params: &[f64],
    method: Method,
    tolerances: Tolerances,
    start: &[f64],
    samples: &[f64],
) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let mut system = system(model, params);
    let (n, p) = (start.len(), params.len());
    let mut integrator = Integrator::new(n, tolerances, 1_000_000, method);
    let (mut y, mut s) = (start.to_vec(), vec![0.0; n * p]);
    let (mut states, mut sensitivities) = (Vec::new(), Vec::new());
    let span = (0.0, *samples.last().unwrap());
    integrator
        .integrate_with_sensitivities(&mut system, span, &mut y, &mut s, samples, |_, y, s| {
            states.push(y.to_vec());
            sensitivities.push(s.to_vec());
        })
        .unwrap();
    (states, sensitivities)
}

const DECAY: &str =
    "model decay\nstate y = 2\nparam k = 0.7 positive, c = 0.3\nder y = -k * y + c\n";

#[test]
fn sensitivities_of_a_linear_decay_match_the_closed_form() {
    let model = compile(DECAY);
    let (k, c, y0) = (0.7, 0.3, 2.0);
    let samples: Vec<f64> = (0..=20).map(|i| i as f64 * 0.5).collect();
    let tolerances = Tolerances {
        rtol: 1e-10,
        atol: 1e-12,
    };
    for method in [Method::Explicit, Method::Implicit, Method::Auto] {
        let (states, sensitivities) =
            integrate(&model, &[k, c], method, tolerances, &[y0], &samples);
        for ((y, s), &t) in states.iter().zip(&sensitivities).zip(&samples) {
            let decay = (-k * t).exp();
            let exact = y0 * decay + c / k * (1.0 - decay);
            let by_k = -t * y0 * decay - c / (k * k) * (1.0 - decay) + c / k * t * decay;
            let by_c = (1.0 - decay) / k;
            assert!((y[0] - exact).abs() < 1e-9, "{method:?} t = {t}");
            assert!(
                (s[0] - by_k).abs() < 1e-8,
                "{method:?} t = {t}: {} vs {by_k}",
                s[0]
            );
            assert!(
                (s[1] - by_c).abs() < 1e-8,
                "{method:?} t = {t}: {} vs {by_c}",
                s[1]
            );
        }
    }
}

/// A fed culture whose substrate balance is stiff once the substrate is limiting.
const CULTURE: &str = "model culture
state X = 0.5, S = 4
param mu = 0.4 positive, K = 1e-3 positive, Y = 0.5 positive
const F = 0.05, S_in = 20
der X = mu * S / (K + S) * X - F * X
der S = F * (S_in - S) - mu * S / (K + S) * X / Y
";

#[test]
fn sensitivities_through_a_stiff_stretch_match_finite_differences() {
    let model = compile(CULTURE);
    let params = [0.4, 1e-3, 0.5];
    let samples: Vec<f64> = (0..=30).map(|i| i as f64).collect();
    let tight = Tolerances {
        rtol: 1e-12,
        atol: 1e-14,
    };
    let start = [0.5, 4.0];
    for method in [Method::Implicit, Method::Auto, Method::Explicit] {
        let (_, sensitivities) = integrate(&model, &params, method, tight, &start, &samples);
        for j in 0..params.len() {
            let step = 1e-5 * params[j];
            let shifted = |sign: f64| {
                let mut moved = params;
                moved[j] += sign * step;
                integrate(&model, &moved, method, tight, &start, &samples).0
            };
            let (up, down) = (shifted(1.0), shifted(-1.0));
            for (row, s) in sensitivities.iter().enumerate() {
                for k in 0..2 {
                    let numeric = (up[row][k] - down[row][k]) / (2.0 * step);
                    let exact = s[k * params.len() + j];
                    let scale = numeric
                        .abs()
                        .max(1e-3 * (up[row][k].abs() / params[j]).max(1.0));
                    assert!(
                        (exact - numeric).abs() < 1e-4 * scale,
                        "{method:?} dy{k}/dp{j} at t = {row}: {exact} vs {numeric}"
                    );
                }
            }
        }
    }
}

#[test]
fn sensitivities_do_not_change_the_solution() {
    let model = compile(CULTURE);
    let params = [0.4, 1e-3, 0.5];
    let samples: Vec<f64> = (0..=30).map(|i| i as f64).collect();
    let tolerances = Tolerances::default();
    for method in [Method::Implicit, Method::Auto, Method::Explicit] {
        let (with, _) = integrate(&model, &params, method, tolerances, &[0.5, 4.0], &samples);
        let mut system = system(&model, &params);
        let mut integrator = Integrator::new(2, tolerances, 1_000_000, method);
        let mut y = [0.5, 4.0];
        let mut without = Vec::new();
        integrator
            .integrate(&mut system, (0.0, 30.0), &mut y, &samples, |_, y| {
                without.push(y.to_vec())
            })
            .unwrap();
        assert_eq!(with, without, "{method:?}");
    }
}

#[test]
fn the_culture_turns_stiff_and_the_automatic_choice_sees_it() {
    let model = compile(CULTURE);
    let mut system = system(&model, &[0.4, 1e-3, 0.5]);
    assert_eq!(system.sensitivity_params(), 3);
    let mut integrator = Integrator::new(2, Tolerances::default(), 1_000_000, Method::Auto);
    let mut y = [0.5, 4.0];
    integrator
        .integrate(&mut system, (0.0, 200.0), &mut y, &[], |_, _| {})
        .unwrap();
    let stats = integrator.stats();
    assert!(stats.switches >= 1 && stats.implicit > 0, "{stats:?}");
}
