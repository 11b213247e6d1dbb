use super::*;

const MODEL: &str =
    "model m\ntime h\n## Biomass in the tank.\nstate X [g/L] = 1\nconst k = 0.1 [1/h]\n\
closure c {\n  outputs mu ~ 0.1\n}\nder X = (mu - k) * X\n";

fn offset_of(source: &str, needle: &str, nth: usize) -> usize {
    source
        .match_indices(needle)
        .nth(nth)
        .map(|(i, _)| i)
        .expect("present")
}

#[test]
fn diagnostics_carry_code_span_help_and_labels() {
    let problems = diagnostics("m.gbm", MODEL);
    assert!(problems.is_empty(), "{problems:?}");
    let broken = MODEL.replace("der X = (mu - k) * X", "der X = k + X + mu");
    let problems = diagnostics("m.gbm", &broken);
    assert_eq!(problems.len(), 1, "{problems:?}");
    let problem = &problems[0];
    assert_eq!(problem.code.as_deref(), Some("gbm::E0151"));
    assert_eq!(&broken[problem.span.start..problem.span.end], "X");
    assert!(problem.message.contains("help:"), "{}", problem.message);
    assert_eq!(problem.related.len(), 1);
}

#[test]
fn definition_and_hover_of_names() {
    let use_of_x = offset_of(MODEL, "X", 2);
    let declared = definition(MODEL, use_of_x).expect("declared");
    assert_eq!(declared.start, offset_of(MODEL, "X [g/L]", 0));
    let text = hover(MODEL, use_of_x).expect("hover");
    assert!(text.contains("state X"), "{text}");
    assert!(text.contains("unit: `g/L`"), "{text}");
    assert!(text.contains("Biomass in the tank."), "{text}");
    let mu = hover(MODEL, offset_of(MODEL, "mu -", 0) + 1).expect("hover");
    assert!(mu.contains("closure output mu"), "{mu}");
    assert!(mu.contains("unit: `1/h` (inferred)"), "{mu}");
    assert_eq!(
        hover(MODEL, offset_of(MODEL, "0.1", 0)),
        None,
        "a number is no name"
    );
    assert_eq!(
        definition(MODEL, offset_of(MODEL, "der", 0)),
        None,
        "a keyword is no name"
    );
}

#[test]
fn hover_shows_percent_units_declared_and_inferred() {
    let source = "model m\ntime h\nstate DO [%] = 30\nconst k = 0.1 [1/h]\nlet loss = k * DO\n\
                  der DO = -loss\n";
    let declared = hover(source, offset_of(source, "DO", 0)).expect("hover");
    assert!(declared.contains("unit: `%`"), "{declared}");
    let inferred = hover(source, offset_of(source, "loss", 0)).expect("hover");
    assert!(inferred.contains("unit: `%/h` (inferred)"), "{inferred}");
}

#[test]
fn line_index_counts_utf16_columns() {
    let text = "ab\nµg x\n";
    let index = LineIndex::new(text);
    let x = text.find('x').expect("x");
    assert_eq!(index.position(x), (1, 3));
    assert_eq!(index.offset(1, 3), x);
    assert_eq!(index.position(0), (0, 0));
    assert_eq!(index.offset(9, 0), text.len());
}

#[test]
fn hover_shows_declared_noise_and_definition_works_from_a_noise_line() {
    let source = format!("{MODEL}noise X = 4 % + 0.01 [g/L]\n");
    let noise_x = offset_of(&source, "X = 4", 0);
    let declared = definition(&source, noise_x).expect("declared");
    assert_eq!(declared.start, offset_of(&source, "X [g/L]", 0));
    let text = hover(&source, noise_x).expect("hover");
    assert!(text.contains("state X"), "{text}");
    assert!(
        text.contains("noise: `4 % + 0.01 [g/L]` (standard deviation"),
        "{text}"
    );
    let plain = hover(MODEL, offset_of(MODEL, "X", 2)).expect("hover");
    assert!(!plain.contains("noise"), "{plain}");
    assert!(diagnostics("m.gbm", &source).is_empty());
    let hidden = source.replace("noise X", "noise k");
    let problems = diagnostics("m.gbm", &hidden);
    assert_eq!(problems.len(), 1, "{problems:?}");
    assert_eq!(problems[0].code.as_deref(), Some("gbm::E0140"));
    assert_eq!(&hidden[problems[0].span.start..problems[0].span.end], "k");
}

#[test]
fn hover_shows_a_nonnegative_state() {
    let source = "model m\nstate S [g/L] = 8 nonnegative, X\nder S = -S * X\nder X = -X\n";
    let text = hover(source, offset_of(source, "S", 2)).expect("hover");
    assert!(text.contains("state S nonnegative"), "{text}");
    let plain = hover(source, offset_of(source, "X", 1)).expect("hover");
    assert!(!plain.contains("nonnegative"), "{plain}");
}
