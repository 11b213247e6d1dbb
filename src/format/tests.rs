use super::*;

fn check(source: &str, expected: &str) {
    let formatted = format_source(source).unwrap_or_else(|e| panic!("{source}: {e}"));
    assert_eq!(formatted, expected, "formatting:\n{source}");
    let again = format_source(&formatted).expect("formats again");
    assert_eq!(again, formatted, "idempotent");
}

#[test]
fn spacing_and_one_declaration_per_line() {
    check(
        "model  m\nstate X=1;der X=-X*2^ -1\n",
        "model m\nstate X = 1\nder X = -X * 2^(-1)\n",
    );
    check(
        "model m \"a model\"\ninput u  [ - ]in[0,1]\nstate X [g L^-1]= 1 , S\n",
        "model m \"a model\"\ninput u [-] in [0, 1]\nstate X [g L^-1] = 1, S\n",
    );
}

#[test]
fn units_move_to_their_canonical_place() {
    check(
        "model m\nstate X = 0.1 [g/L]\nconst D [1/h] = 0.05\nparam k [1/h] = 1 positive\n",
        "model m\nstate X [g/L] = 0.1\nconst D = 0.05 [1/h]\nparam k = 1 [1/h] positive\n",
    );
}

#[test]
fn percent_and_ppm_units_are_kept() {
    check(
        "model m\nstate DO=30 [ % ]\nconst y [%]=20.9\nconst c = 1[ppm /h]\nconst r = 1 [%*g/L]\n",
        "model m\nstate DO [%] = 30\nconst y = 20.9 [%]\nconst c = 1 [ppm/h]\nconst r = 1 [% g/L]\n",
    );
}

#[test]
fn runs_of_one_kind_align_on_the_equals_sign() {
    check(
        "model m\nconst a = 1\nconst bbb = 2 [g]\n\nconst c = 3\nder X = 1\nder Long = 2\n",
        "model m\nconst a   = 1\nconst bbb = 2 [g]\n\nconst c = 3\nder X    = 1\nder Long = 2\n",
    );
}

#[test]
fn comments_and_doc_comments_stay() {
    check(
        "# header comment\n\n\n## the model\nmodel m   # trailing\n## doc of X\nstate X = 1 # x\n\n\n\n# loose\nder X = -X\n",
        "# header comment\n\n## the model\nmodel m # trailing\n## doc of X\nstate X = 1 # x\n\n# loose\nder X = -X\n",
    );
}

#[test]
fn blocks_are_indented_and_keep_their_comments() {
    check(
        "model m\nstate X\nclosure c { # rates\n\n    outputs r~0.1 positive,q\n  # comment\n  embed dim 3 delay 2; network tanh\n prior r*=X\n\n}\nder X = r + q\neffect e \"an {effect}\" {param k = 1 positive\n  r *= k}\n",
        "model m\nstate X\nclosure c { # rates\n  outputs r ~ 0.1 positive, q\n  # comment\n  embed delay 2 dim 3\n  network tanh\n  prior r *= X\n}\nder X = r + q\neffect e \"an {effect}\" {\n  param k = 1 positive\n  r *= k\n}\n",
    );
}

#[test]
fn author_parentheses_and_number_spelling_are_kept() {
    check(
        "model m\nstate X\nder X = ((X)) * (2 * X) - 3e-2 + .5 + (-X)^2\n",
        "model m\nstate X\nder X = (X) * (2 * X) - 3e-2 + .5 + (-X)^2\n",
    );
}

#[test]
fn a_declaration_with_an_inner_comment_is_kept_as_written() {
    check(
        "model m\nstate X\nder X = X +  # why\n      2\n",
        "model m\nstate X\nder X = X +  # why\n      2\n",
    );
}

#[test]
fn long_lines_wrap_after_an_operator() {
    let long = (0..30)
        .map(|i| format!("a{i}"))
        .collect::<Vec<_>>()
        .join(" + ");
    let formatted = format_source(&format!("model m\nstate X\nder X = {long}\n")).expect("formats");
    assert!(
        formatted.lines().all(|l| l.chars().count() <= WIDTH),
        "{formatted}"
    );
    assert!(
        formatted
            .lines()
            .nth(3)
            .is_some_and(|l| l.starts_with("    a")),
        "{formatted}"
    );
    assert_eq!(format_source(&formatted).expect("again"), formatted);
}

#[test]
fn noise_declarations_print_canonically() {
    check(
        "model m\nstate X [g/L], S\nnoise X=4%+0.01[ g / L ]\nnoise S ,X=  1e-2\nnoise X = -.5 %\n",
        "model m\nstate X [g/L], S\nnoise X = 4 % + 0.01 [g/L]\nnoise S, X = 1e-2\nnoise X = -.5 %\n",
    );
    // One target aligns on `=` with its neighbours; a list of targets does not.
    check(
        "model m\nstate X, OD\nnoise X = 1 %\nnoise OD=0.02 + 3 %\nnoise X, OD = 1 %\n",
        "model m\nstate X, OD\nnoise X  = 1 %\nnoise OD = 0.02 + 3 %\nnoise X, OD = 1 %\n",
    );
    // Continuation lines after `,` and `+` join; doc comments and comments stay.
    check(
        "model m\nstate X\n## precision of the assay\nnoise X = 2 % +\n    0.1 [-] # from the lab\n",
        "model m\nstate X\n## precision of the assay\nnoise X = 2 % + 0.1 [-] # from the lab\n",
    );
}

#[test]
fn long_noise_declarations_wrap_after_a_comma_or_a_plus() {
    let names: Vec<String> = (0..20).map(|i| format!("Quantity{i}")).collect();
    let source = format!(
        "model m\nstate {}\nnoise {} = 4 % + 0.01\n",
        names.join(", "),
        names.join(", ")
    );
    let formatted = format_source(&source).expect("formats");
    assert!(
        formatted.lines().all(|l| l.chars().count() <= WIDTH),
        "{formatted}"
    );
    assert_eq!(format_source(&formatted).expect("again"), formatted);
}

#[test]
fn syntax_errors_are_reported_not_formatted() {
    assert!(matches!(
        format_source("model m\nstate X = \n"),
        Err(FormatError::Syntax(_))
    ));
}

#[test]
fn nonnegative_ends_a_state_entry_after_its_value_and_unit() {
    check(
        "model m\nstate S=8 [g/L]   nonnegative,X nonnegative , P\nhidden E=0 nonnegative # e\nder S = -S\n",
        "model m\nstate S [g/L] = 8 nonnegative, X nonnegative, P\nhidden E = 0 nonnegative # e\nder S = -S\n",
    );
    // Aligned on `=` with its neighbours, the keyword after the value.
    check(
        "model m\nstate S = 8 nonnegative\nstate Long = 1\n",
        "model m\nstate S    = 8 nonnegative\nstate Long = 1\n",
    );
}
