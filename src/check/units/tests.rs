use crate::check::{check, CheckError};

fn checked(source: &str) -> crate::check::Checked {
    let model = crate::syntax::parse(source).expect("parses");
    check(model).unwrap_or_else(|errors| panic!("{source}\n{errors:#?}"))
}

fn errors(source: &str) -> Vec<CheckError> {
    let model = crate::syntax::parse(source).expect("parses");
    check(model).err().unwrap_or_default()
}

fn unit_text(source: &str, name: &str) -> (String, bool) {
    let compiled = crate::driver::compile("t.gbm", source, &[]).expect("compiles");
    let unit = compiled
        .model
        .unit(name)
        .unwrap_or_else(|| panic!("{name} has a unit"));
    (unit.text.clone(), unit.inferred)
}

#[test]
fn a_model_without_units_is_never_checked() {
    let source = "model m\ntime h\nstate X = 1, S = 2\nconst k = 3\n\
                  der X = exp(X) + S^k - sqrt(X)\nder S = softplus(S) * log(X) + 1\n";
    let checked = checked(source);
    assert!(checked.units.names.is_empty());
    assert_eq!(checked.units.time, None);
}

#[test]
fn undeclared_units_are_inferred_from_the_equations() {
    let source = "model m\ntime h\ninput D [1/h] in [0, 1]\nstate X [g/L] = 1, S [g/L] = 2\n\
                  state P = 0\nconst K = 0.5, Y = 0.5 [g/g]\nclosure c {\n  outputs mu ~ 0.1\n}\n\
                  let uptake = mu / Y * X\nder X = (mu - D) * X\nder S = -uptake * S / (K + S)\n\
                  der P = mu * X\n";
    assert_eq!(unit_text(source, "mu"), ("1/h".to_string(), true));
    assert_eq!(unit_text(source, "uptake"), ("g/L/h".to_string(), true));
    assert_eq!(unit_text(source, "K"), ("g/L".to_string(), true));
    assert_eq!(unit_text(source, "P"), ("g/L".to_string(), true));
    assert_eq!(unit_text(source, "Y"), ("g/g".to_string(), false));
}

#[test]
fn an_inferred_unit_is_checked_where_it_is_used_again() {
    let source = "model m\ntime h\nstate X [g/L] = 1\nconst D = 0.1 [1/h], k = 0.2 [1/min]\n\
                  let mu = D\nder X = (mu - k) * X\n";
    let found = errors(source);
    assert!(
        matches!(&found[..], [CheckError::UnitScale { factor, .. }] if factor == "60"),
        "{found:#?}"
    );
}

#[test]
fn numbers_take_the_unit_their_place_needs() {
    let source = "model m\ntime h\nstate X [g/L] = 1, B [g/L] = 1\n\
                  der X = 0.1 * X - 2 + 0.3 * exp(-B / 7) * X / (1 + B)\nder B = -B / 10\n";
    checked(source);
}

#[test]
fn roots_and_powers_keep_units() {
    let ok = "model m\ntime s\nstate S [mol/L] = 1\nconst a = 1 [mol/L], n = 2.5 [-]\n\
              param h = 2 [-] positive\nlet hill [-] = S^n / (a^n + S^n)\n\
              let other = S^h / (a^h + S^h)\n\
              der S = (sqrt(S^2 + a^2) - S) * hill * other / (1 [s])\n";
    assert!(
        crate::syntax::parse(ok).is_err(),
        "a unit is not an expression"
    );
    let ok = ok.replace(" / (1 [s])", "");
    let found = errors(&ok);
    assert!(
        matches!(&found[..], [CheckError::UnitMismatch { context, .. }] if context == "balance of `S`"),
        "{found:#?}"
    );
    let ok = ok
        .replace("const a = 1 [mol/L]", "const a = 1 [mol/L], tau = 1 [s]")
        .replace("* other\n", "* other / tau\n");
    checked(&ok);
}

#[test]
fn next_updates_keep_the_unit_of_their_state() {
    let source = "model m\nstate X [g/L] = 1\nconst dX = 0.1 [mg/L]\nnext X = X + dX\n";
    let found = errors(source);
    assert!(
        matches!(&found[..], [CheckError::UnitScale { .. }]),
        "{found:#?}"
    );
    let fixed = source.replace("[mg/L]", "[g/L]");
    checked(&fixed);
}
