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

#[test]
fn percent_and_ppm_are_units_of_pure_numbers() {
    let source = "model aerated\ntime h\ninput kLa [1/h] in [0, 200]\n\
                  state DO [%] = 100, C [ppm] = 5\nconst DO_sat = 100 [%], y_O2 = 20.9 [%]\n\
                  const OUR = 30 [%/h], q = 0.1 [ppm/h]\nlet air [%] = y_O2 / 20.9 * DO_sat\n\
                  der DO = kLa * (air - DO) - OUR\nder C = -q * DO / DO_sat\n";
    checked(source);
    let (text, inferred) = unit_text(source, "air");
    assert_eq!((text.as_str(), inferred), ("%", false));
    let compiled = crate::driver::compile("t.gbm", source, &[]).expect("compiles");
    let ir = crate::ir::print(&compiled.model);
    assert!(ir.contains("DO [%] = 100") && ir.contains("[%/h]"), "{ir}");
}

#[test]
fn a_percentage_where_a_fraction_is_needed_is_a_factor_of_100() {
    let source = "model m\ntime h\nstate X [g/L] = 1\nconst mu = 0.2 [1/h], f = 30 [%]\n\
                  let kept [-] = f\nder X = mu * exp(-f) * X\n";
    let found = errors(source);
    let factors: Vec<(&str, &str)> = found
        .iter()
        .filter_map(|error| match error {
            CheckError::UnitScale { factor, help, .. } => Some((factor.as_str(), help.as_str())),
            _ => None,
        })
        .collect();
    assert_eq!(factors.len(), 2, "{found:#?}");
    for (factor, help) in factors {
        assert_eq!(factor, "100");
        assert!(help.contains("(1 = 100 %)"), "{help}");
    }
    let fixed = source
        .replace("f = 30 [%]", "f = 30 [%], percent = 100 [%]")
        .replace("[-] = f\n", "[-] = f / percent\n")
        .replace("exp(-f)", "exp(-kept)");
    checked(&fixed);
}

#[test]
fn a_prefix_on_percent_is_an_unknown_unit_saying_why() {
    let found = errors("model m\nstate X [m%] = 1\nder X = -X\n");
    let helps: Vec<&str> = found
        .iter()
        .filter_map(|error| match error {
            CheckError::UnknownUnit { symbol, help, .. } if symbol == "m%" => Some(help.as_str()),
            _ => None,
        })
        .collect();
    assert_eq!(helps.len(), 1, "{found:#?}");
    assert!(
        helps[0].starts_with("`%` takes no SI prefix"),
        "{}",
        helps[0]
    );
}
