use crate::check::noise::NoiseLevel;
use miette::Diagnostic;

/// A model with units: measured X, S [g/L], DO [%], hidden H, param k, input u, let r,
/// outputs P [g/L] and OD (unit inferred: dimensionless).
const MODEL: &str = "model m\ntime h\ninput u [1/h] in [0, 1]\n\
state X [g/L] = 1, S [g/L] = 5, DO [%] = 30\nhidden H = 1\nparam k = 0.1 [1/h]\n\
const c = 0.3 [L/g]\nlet r = k * X\noutput P [g/L] = X + S\noutput OD = c * X\n\
der X = r - u * X\nder S = -r\nder DO = 0\nder H = -H\n";

/// The levels of `noise` lines added to [`MODEL`], or the codes of the errors.
fn levels(noise: &str) -> Result<Vec<NoiseLevel>, Vec<String>> {
    let source = format!("{MODEL}{noise}\n");
    let model = crate::syntax::parse(&source).map_err(|e| vec![e.to_string()])?;
    crate::check::check(model)
        .map(|checked| checked.noise)
        .map_err(|errors| {
            errors
                .iter()
                .map(|e| e.code().map_or(e.to_string(), |c| c.to_string()))
                .collect()
        })
}

fn level(name: &str, relative: f64, absolute: f64) -> NoiseLevel {
    NoiseLevel {
        name: name.to_string(),
        relative,
        absolute,
    }
}

/// `noise` lines that pass, with the levels they give.
#[test]
fn declarations_give_fractions_and_absolute_terms_in_the_quantity_unit() {
    let cases: [(&str, Vec<NoiseLevel>); 9] = [
        ("noise X = 4 % + 0.01 [g/L]", vec![level("X", 0.04, 0.01)]),
        ("noise X = 0.01 [g/L] + 4%", vec![level("X", 0.04, 0.01)]),
        (
            "noise S, P = 0.02 [g/L]",
            vec![level("S", 0.0, 0.02), level("P", 0.0, 0.02)],
        ),
        ("noise OD = 3 %", vec![level("OD", 0.03, 0.0)]),
        ("noise X = 0.05", vec![level("X", 0.0, 0.05)]),
        ("noise X = 20 [mg/L]", vec![level("X", 0.0, 0.02)]),
        ("noise X = 0.02 [kg/m^3]", vec![level("X", 0.0, 0.02)]),
        ("noise DO = 2 [%] + 5 %", vec![level("DO", 0.05, 2.0)]),
        ("noise DO = 0.02 [-]", vec![level("DO", 0.0, 2.0)]),
    ];
    for (noise, expected) in cases {
        let found = levels(noise).unwrap_or_else(|codes| panic!("{noise}: {codes:?}"));
        assert_eq!(found.len(), expected.len(), "{noise}");
        for (found, expected) in found.iter().zip(&expected) {
            assert_eq!(found.name, expected.name, "{noise}");
            assert!(
                (found.relative - expected.relative).abs() < 1e-15,
                "{noise}"
            );
            assert!(
                (found.absolute - expected.absolute).abs() < 1e-12 * expected.absolute.max(1.0),
                "{noise}: {} for {}",
                found.absolute,
                expected.absolute
            );
        }
    }
}

#[test]
fn a_relative_term_above_100_percent_is_allowed() {
    assert_eq!(levels("noise X = 150 %"), Ok(vec![level("X", 1.5, 0.0)]));
}

#[test]
fn a_model_without_units_takes_absolute_terms_as_written() {
    let source = "model m\nstate X = 1\nder X = -X\nnoise X = 2 % + 0.5 [mg/L]\n";
    let checked = crate::check::check(crate::syntax::parse(source).expect("parses"));
    assert_eq!(checked.expect("checks").noise, [level("X", 0.02, 0.5)]);
}

/// `noise` lines that fail, with the codes of their errors.
#[test]
fn every_noise_error_has_its_code() {
    let cases: [(&str, &[&str]); 15] = [
        ("noise Xx = 4 %", &["gbm::E0101"]),
        ("noise H = 4 %", &["gbm::E0140"]),
        ("noise k, u, r, c = 4 %", &["gbm::E0140"; 4]),
        ("noise X = 4 %\nnoise S, X = 1 %", &["gbm::E0141"]),
        ("noise X = -4 % + 0.01 [g/L]", &["gbm::E0142"]),
        ("noise X = - 0.01", &["gbm::E0142"]),
        ("noise X = 1e305 [kg/mL]", &["gbm::E0142"]),
        ("noise X = 1 % + 2 %", &["gbm::E0143"]),
        ("noise X = 0.1 + 0.2 [g/L]", &["gbm::E0143"]),
        ("noise X = 0 % + 0 [g/L]", &["gbm::E0144"]),
        ("noise X = 0", &["gbm::E0144"]),
        ("noise X = 0.1 [1/h]", &["gbm::E0151"]),
        ("noise X = 4 [%]", &["gbm::E0151"]),
        ("noise X = 4 [gr/L]", &["gbm::E0150"]),
        (
            "noise H, X = -1 %\nnoise X = 1 %",
            &["gbm::E0140", "gbm::E0142", "gbm::E0141"],
        ),
    ];
    for (noise, expected) in cases {
        let codes = levels(noise).expect_err(noise);
        assert_eq!(codes, expected, "{noise}");
    }
}

#[test]
fn messages_say_what_was_expected_and_why() {
    let message = |noise: &str| {
        let source = format!("{MODEL}{noise}\n");
        let errors =
            crate::check::check(crate::syntax::parse(&source).expect("parses")).expect_err("fails");
        let error = &errors[0];
        (
            error.to_string(),
            error.help().map(|h| h.to_string()).unwrap_or_default(),
        )
    };
    let (text, help) = message("noise Xx = 4 %");
    assert_eq!(text, "unknown name `Xx`");
    assert_eq!(
        help,
        "did you mean `X`? measured quantities: `DO`, `OD`, `P`, `S`, `X`"
    );
    let (text, help) = message("noise H = 4 %");
    assert_eq!(text, "noise for `H`, which is a hidden state");
    assert!(
        help.contains("make `H` a `state` if it is measured"),
        "{help}"
    );
    let (text, help) = message("noise k = 4 %");
    assert_eq!(text, "noise for `k`, which is a param");
    assert!(
        help.contains("declare it for measured `state`s and `output`s"),
        "{help}"
    );
    let (text, _) = message("noise X = -4 %");
    assert_eq!(text, "expected a noise level >= 0, found -4 %");
    let (text, _) = message("noise X = 1e305 [kg/mL]");
    assert_eq!(text, "expected a finite noise level in g/L, found inf");
    let (text, help) = message("noise X = 0.04 + 0.01");
    assert_eq!(
        text,
        "expected at most one absolute term in a noise declaration, found two"
    );
    assert!(
        help.contains("a relative term is written `4 %`, not `0.04`"),
        "{help}"
    );
    let (text, _) = message("noise X = 0 %");
    assert_eq!(text, "expected a noise level above zero, found 0 %");
    let (text, help) = message("noise X = 4 [%]");
    assert_eq!(text, "absolute noise of `X`: expected g/L, found %");
    assert!(help.contains("a relative term is a bare `%`"), "{help}");
}

#[test]
fn noise_inside_an_effect_is_refused_in_words() {
    let source = format!("{MODEL}effect e {{\n  noise X = 1 %\n}}\n");
    let error = crate::syntax::parse(&source).expect_err("refused");
    assert_eq!(
        error.code().map(|c| c.to_string()),
        Some("gbm::E0005".into())
    );
    assert_eq!(
        error.to_string(),
        "a noise declaration is not allowed inside an effect"
    );
}

#[test]
fn noise_is_a_reserved_word() {
    let error =
        crate::syntax::parse("model m\nstate noise = 1\nder noise = 0\n").expect_err("reserved");
    let help = error.help().map(|h| h.to_string()).unwrap_or_default();
    assert!(help.contains("`noise` is a reserved word"), "{help}");
}
