//! A symbolic hint: formulas for the learned correction, found by sparse regression
//! (sequentially thresholded least squares, as in SINDy) on a small library of terms
//! built from the model's variables.
//!
//! Library, in physical units: the constant; for each variable `x` that varies, `x`,
//! `1/(1+x)`, and for non-negative `x` the saturations `x/(K+x)` and decays `exp(-x/K)`
//! with `K` at 0.1, 0.3, 1, 3 and 10 times its median; the products of pairs of variables;
//! and, for a correction of a `let`, that let times every term of the other variables (a
//! missing factor shows up as `let * f(x)`). Columns are scaled to unit root mean square;
//! for each threshold of a sweep, least squares is solved, coefficients below the threshold
//! (relative to the largest) are dropped and the rest refitted until the support settles.
//! Each support found is refitted in physical units and scored by its R^2 on the training
//! rows; the best formula of each size up to [`MAX_TERMS`] is kept when it leaves at most
//! half the unexplained variance of the smaller ones (and none after one reaching R^2
//! 0.999).

use super::locus::Along;
use super::report::Formula;
use crate::numeric::{order_statistic, root_mean_square, solve_spd, NormalEquations};

/// Most terms in a formula.
pub const MAX_TERMS: usize = 4;
/// Thresholds of the sweep (relative to the largest scaled coefficient).
const THRESHOLDS: [f64; 8] = [0.01, 0.02, 0.05, 0.1, 0.2, 0.3, 0.5, 0.7];
/// A larger formula must leave at most this fraction of the smaller one's unexplained
/// variance to be listed.
const MIN_GAIN: f64 = 0.5;
/// No larger formula is listed once one reaches this R^2.
const GOOD_ENOUGH: f64 = 0.999;
/// Multiples of a variable's median used as `K`.
const K_MULTIPLES: [f64; 5] = [0.1, 0.3, 1.0, 3.0, 10.0];

/// A library column.
struct Term {
    text: String,
    values: Vec<f64>,
}

/// The best formulas for `along.values`, smallest first; `target` names what they
/// approximate.
pub fn hints(along: &Along, target: &str) -> Vec<Formula> {
    let library = library(along);
    let y = &along.values;
    if library.is_empty() || y.len() < 2 * MAX_TERMS {
        return Vec::new();
    }
    let gram = Gram::new(&library, y);
    let mut supports = best_subsets(&gram);
    supports.extend(THRESHOLDS.iter().filter_map(|&t| stlsq(&gram, t)));
    let mut best: Vec<Option<Candidate>> = vec![None; MAX_TERMS + 1];
    for support in supports
        .into_iter()
        .filter(|s| !s.is_empty() && s.len() <= MAX_TERMS)
    {
        if let Some((r2, coefficients)) = gram.fit(&support) {
            let slot = &mut best[support.len()];
            if slot.as_ref().is_none_or(|(b, _, _)| r2 > *b) {
                *slot = Some((r2, support, coefficients));
            }
        }
    }
    let mut formulas = Vec::new();
    let mut previous = f64::NEG_INFINITY;
    for (r2, support, coefficients) in best.into_iter().flatten() {
        if previous < GOOD_ENOUGH && 1.0 - r2 < MIN_GAIN * (1.0 - previous) {
            formulas.push(Formula {
                target: target.to_string(),
                text: format_formula(&library, &support, &coefficients),
                r2,
                terms: support.len(),
            });
            previous = r2;
        }
    }
    formulas
}

/// A formula found: its R^2, support and coefficients.
type Candidate = (f64, Vec<usize>, Vec<f64>);

/// Cross products of the unit-scaled library columns and the target.
struct Gram {
    size: usize,
    /// `X^T X` of the scaled columns, row-major.
    xx: Vec<f64>,
    /// `X^T y`.
    xy: Vec<f64>,
    /// Column scales (root mean squares).
    scales: Vec<f64>,
    /// `y^T y` and the total sum of squares about the mean.
    yy: f64,
    total: f64,
}

impl Gram {
    fn new(library: &[Term], y: &[f64]) -> Gram {
        let size = library.len();
        let scales: Vec<f64> = library
            .iter()
            .map(|t| root_mean_square(&t.values).max(1e-300))
            .collect();
        let mut normal = NormalEquations::new(size);
        let mut row = vec![0.0; size];
        for (i, &target) in y.iter().enumerate() {
            for (slot, (term, scale)) in row.iter_mut().zip(library.iter().zip(&scales)) {
                *slot = term.values[i] / scale;
            }
            normal.add(&row, target, 1.0);
        }
        normal.finish();
        let mean = y.iter().sum::<f64>() / y.len() as f64;
        Gram {
            size,
            xx: normal.a,
            xy: normal.b,
            scales,
            yy: y.iter().map(|v| v * v).sum(),
            total: y.iter().map(|v| (v - mean).powi(2)).sum(),
        }
    }

    /// Least squares on `support` with a relative ridge: scaled coefficients and the
    /// residual sum of squares.
    fn solve(&self, support: &[usize], ridge: f64) -> Option<(Vec<f64>, f64)> {
        let n = support.len();
        let mut a = vec![0.0; n * n];
        for (r, &i) in support.iter().enumerate() {
            for (c, &j) in support.iter().enumerate() {
                a[r * n + c] = self.xx[i * self.size + j];
            }
            a[r * n + r] *= 1.0 + ridge;
        }
        let b: Vec<f64> = support.iter().map(|&i| self.xy[i]).collect();
        let x = solve_spd(&a, &b)?;
        let explained: f64 = x.iter().zip(&b).map(|(p, q)| p * q).sum();
        Some((x, (self.yy - explained).max(0.0)))
    }

    /// `(R^2, coefficients in physical units)` of `support`.
    fn fit(&self, support: &[usize]) -> Option<(f64, Vec<f64>)> {
        let (x, residual) = self.solve(support, 1e-12)?;
        let coefficients = x
            .iter()
            .zip(support)
            .map(|(c, &j)| c / self.scales[j])
            .collect();
        (self.total > 0.0).then(|| (1.0 - residual / self.total, coefficients))
    }
}

/// The best single terms, pairs and (for libraries up to [`EXHAUSTIVE`] terms) triples,
/// by exhaustive search.
fn best_subsets(gram: &Gram) -> Vec<Vec<usize>> {
    let n = gram.size;
    let mut found = Vec::new();
    let mut keep_best = |candidates: &mut dyn Iterator<Item = Vec<usize>>| {
        let best = candidates
            .filter_map(|s| gram.solve(&s, 1e-12).map(|(_, rss)| (rss, s)))
            .min_by(|a, b| a.0.total_cmp(&b.0));
        if let Some((_, support)) = best {
            found.push(support);
        }
    };
    keep_best(&mut (0..n).map(|i| vec![i]));
    keep_best(&mut (0..n).flat_map(|i| (i + 1..n).map(move |j| vec![i, j])));
    if n <= EXHAUSTIVE {
        keep_best(
            &mut (0..n)
                .flat_map(|i| (i + 1..n).flat_map(move |j| (j + 1..n).map(move |k| vec![i, j, k]))),
        );
    }
    found
}

/// Libraries up to this size get an exhaustive search of triples.
const EXHAUSTIVE: usize = 200;

fn library(along: &Along) -> Vec<Term> {
    let rows = along.values.len();
    let column = |j: usize| -> Vec<f64> { along.variables.iter().map(|v| v[j]).collect() };
    let varies = |values: &[f64]| {
        let (lo, hi) = values
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        hi - lo > 1e-9 * hi.abs().max(lo.abs())
    };
    let names = &along.names;
    let mut per_variable: Vec<Vec<Term>> = Vec::new();
    for (j, name) in names.iter().enumerate() {
        let x = column(j);
        per_variable.push(if varies(&x) {
            variable_terms(name, &x)
        } else {
            Vec::new()
        });
    }
    let mut terms = vec![Term {
        text: "1".into(),
        values: vec![1.0; rows],
    }];
    terms.extend(per_variable.iter().flatten().map(|t| Term {
        text: t.text.clone(),
        values: t.values.clone(),
    }));
    let plain: Vec<usize> = (0..names.len())
        .filter(|&j| !per_variable[j].is_empty())
        .collect();
    for (a, &i) in plain.iter().enumerate() {
        for &j in &plain[a..] {
            let (xi, xj) = (column(i), column(j));
            terms.push(Term {
                text: if i == j {
                    format!("{}^2", names[i])
                } else {
                    format!("{} * {}", names[i], names[j])
                },
                values: xi.iter().zip(&xj).map(|(p, q)| p * q).collect(),
            });
        }
    }
    let last = names.len().saturating_sub(1);
    if along.let_last && !per_variable[last].is_empty() {
        let l = column(last);
        for term in per_variable[..last]
            .iter()
            .flatten()
            .filter(|t| !t.text.contains('*') && t.text != names[last])
        {
            if term.text.contains('/') || term.text.starts_with("exp") {
                terms.push(Term {
                    text: format!("{} * {}", names[last], term.text),
                    values: l.iter().zip(&term.values).map(|(p, q)| p * q).collect(),
                });
            }
        }
    }
    terms.retain(|t| t.values.iter().all(|v| v.is_finite()));
    terms
}

/// `x`, `1/(1+x)`, and for non-negative `x` its saturations and decays.
fn variable_terms(name: &str, x: &[f64]) -> Vec<Term> {
    let map = |text: String, f: &dyn Fn(f64) -> f64| Term {
        text,
        values: x.iter().map(|&v| f(v)).collect(),
    };
    let mut terms = vec![map(name.to_string(), &|v| v)];
    if x.iter().all(|&v| v > -1.0) {
        terms.push(map(format!("1/(1 + {name})"), &|v| 1.0 / (1.0 + v)));
    }
    if x.iter().all(|&v| v >= 0.0) {
        let median = order_statistic(x, 0.5).unwrap_or(0.0);
        if median > 0.0 {
            for multiple in K_MULTIPLES {
                let k = round_significant(multiple * median, 2);
                terms.push(map(format!("{name}/({} + {name})", number(k)), &|v| {
                    v / (k + v)
                }));
                terms.push(map(format!("exp(-{name}/{})", number(k)), &|v| {
                    (-v / k).exp()
                }));
            }
        }
    }
    terms
}

/// Sequentially thresholded least squares on unit-scaled columns; the final support.
fn stlsq(gram: &Gram, threshold: f64) -> Option<Vec<usize>> {
    let mut support: Vec<usize> = (0..gram.size).collect();
    for _ in 0..10 {
        let (coefficients, _) = gram.solve(&support, 1e-8)?;
        let largest = coefficients.iter().fold(0.0f64, |m, c| m.max(c.abs()));
        let kept: Vec<usize> = (support.iter().zip(&coefficients))
            .filter(|(_, c)| c.abs() >= threshold * largest)
            .map(|(&j, _)| j)
            .collect();
        if kept == support {
            break;
        }
        support = kept;
    }
    Some(support)
}

fn format_formula(library: &[Term], support: &[usize], coefficients: &[f64]) -> String {
    let mut text = String::new();
    for (k, (&j, &c)) in support.iter().zip(coefficients).enumerate() {
        let magnitude = number(round_significant(c.abs(), 3));
        let term = if library[j].text == "1" {
            magnitude
        } else {
            format!("{magnitude} * {}", library[j].text)
        };
        match (k, c < 0.0) {
            (0, true) => text.push_str(&format!("-{term}")),
            (0, false) => text.push_str(&term),
            (_, true) => text.push_str(&format!(" - {term}")),
            (_, false) => text.push_str(&format!(" + {term}")),
        }
    }
    text
}

/// `value` rounded to `digits` significant digits.
pub fn round_significant(value: f64, digits: i32) -> f64 {
    if value == 0.0 || !value.is_finite() {
        return value;
    }
    let power = 10f64.powi(digits - 1 - value.abs().log10().floor() as i32);
    (value * power).round() / power
}

/// A number in its shortest form (no trailing zeros).
fn number(value: f64) -> String {
    crate::data::format_number(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_a_missing_decay_factor() {
        // c = -0.5 * mu * (1 - exp(-E/0.2)) over a range of E and mu: a let times a decay.
        let (mut values, mut variables) = (Vec::new(), Vec::new());
        for i in 0..300 {
            let e = 0.4 * ((i * 37 % 300) as f64 / 300.0);
            let s = 1.0 + (i % 17) as f64;
            let mu = 0.2 * s / (1.0 + s);
            values.push(-0.5 * mu + 0.5 * mu * (-e / 0.2).exp());
            variables.push(vec![e, s, mu]);
        }
        let along = Along {
            values,
            names: vec!["E".into(), "S".into(), "mu".into()],
            variables,
            let_last: true,
        };
        let found = hints(&along, "correction of mu");
        let best = found.last().unwrap();
        assert!(best.r2 > 0.999, "{found:?}");
        // The exact two-term law: -0.5 mu + 0.5 mu exp(-E/0.2).
        let exact = found.iter().find(|f| f.terms == 2).unwrap();
        assert!(exact.r2 > 1.0 - 1e-9, "{found:?}");
        assert_eq!(exact.text, "-0.5 * mu + 0.5 * mu * exp(-E/0.2)");
    }

    #[test]
    fn rounds_to_significant_digits() {
        assert_eq!(round_significant(0.012345, 2), 0.012);
        assert_eq!(round_significant(-1234.5, 3), -1230.0);
    }
}
