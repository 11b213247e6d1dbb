use super::*;

/// States X, S [g/L], hidden H, param k, output OD; X and OD declare noise.
const MODEL: &str = "model m\ntime h\nstate X [g/L] = 1, S [g/L] = 5\nhidden H = 1\n\
param k = 0.1 [1/h]\nconst c = 0.3 [L/g]\noutput OD [-] = c * X\noutput Q [g/L] = X + S\n\
der X = k * X\nder S = -k * X\nder H = -H\n\
noise X = 4 % + 10 [mg/L]\nnoise OD = 3 %\n";

fn model(source: &str) -> Model {
    crate::driver::compile("m.gbm", source, &[])
        .unwrap_or_else(|reports| panic!("{reports:?}"))
        .model
}

fn noise(target: Measured, relative: f64, absolute: f64) -> Noise {
    Noise {
        target,
        relative,
        absolute,
    }
}

fn level(name: Option<&str>, relative: f64, absolute: f64) -> NoiseSpec {
    NoiseSpec::Level {
        name: name.map(str::to_string),
        relative,
        absolute,
    }
}

#[test]
fn sigma_is_the_combined_error_model() {
    let combined = noise(Measured::State(0), 0.04, 0.01);
    // sqrt(0.01^2 + (0.04 * 2)^2) = sqrt(0.0001 + 0.0064) = sqrt(0.0065)
    let by_hand = 0.0065_f64.sqrt();
    assert!((combined.sigma(2.0) - by_hand).abs() < 1e-15);
    assert!((combined.variance(2.0) - 0.0065).abs() < 1e-15);
    assert!((combined.sigma(-2.0) - by_hand).abs() < 1e-15, "even in y");
    assert_eq!(combined.sigma(0.0), 0.01, "the absolute term at zero");
    let relative = noise(Measured::State(0), 0.03, 0.0);
    assert!((relative.sigma(5.0) - 0.15).abs() < 1e-15);
    assert_eq!(noise(Measured::State(0), 0.0, 0.2).sigma(1e9), 0.2);
    let huge = noise(Measured::State(0), 0.5, 1e200);
    assert!(huge.sigma(1e200).is_finite(), "no overflow on the way");
    for y in [0.0, 0.3, -7.0, 1e3] {
        let s = combined.sigma(y);
        assert!((s * s - combined.variance(y)).abs() <= 1e-15 * combined.variance(y).max(1.0));
    }
}

#[test]
fn declarations_are_lowered_with_the_absolute_term_in_the_quantity_unit() {
    let model = model(MODEL);
    assert_eq!(
        model.noise,
        [
            noise(Measured::State(0), 0.04, 0.01),
            noise(Measured::Output(0), 0.03, 0.0),
        ]
    );
    assert_eq!(model.measured_named("OD"), Some(Measured::Output(0)));
    assert_eq!(
        model.measured_named("H"),
        None,
        "hidden states are not measured"
    );
    assert_eq!(model.measured_name(Measured::Output(1)), "Q");
    assert_eq!(
        model
            .measured_unit(Measured::State(1))
            .map(|u| u.text.as_str()),
        Some("g/L")
    );
    assert_eq!(model.noise_of(Measured::State(1)), None);
    assert_eq!(
        model.measured(),
        [Measured::State(0), Measured::State(1), Measured::Output(0)],
        "the states and the outputs that declare noise"
    );
    assert_eq!(model.noise[0].level_text(), "4 % + 0.01");
    assert_eq!(model.noise[1].level_text(), "3 %");
}

#[test]
fn sigma_of_a_quantity_reads_its_level_or_none() {
    let model = model(MODEL);
    // X: 4 % + 0.01 g/L at 2 g/L: sqrt(0.01^2 + 0.08^2)
    let x = model
        .declared_sigma(Measured::State(0), 2.0)
        .expect("declared");
    assert!((x - 0.0065_f64.sqrt()).abs() < 1e-15);
    assert_eq!(
        model.declared_sigma(Measured::State(1), 2.0),
        None,
        "S declares none"
    );
    let od = sigma_of(&model.noise, Measured::Output(0), 0.5).expect("declared");
    assert!((od - 0.015).abs() < 1e-15);
    let merged = merge_noise(&model, &[level(Some("S"), 0.0, 0.2)], &model.measured());
    let merged = merged.expect("merges");
    assert_eq!(sigma_of(&merged, Measured::State(1), 7.0), Some(0.2));
    assert_eq!(sigma_of(&merged, Measured::Output(1), 7.0), None);
}

#[test]
fn effects_keep_the_declared_noise() {
    let source = format!("{MODEL}effect e {{\n  param d = 0.1 positive\n  der X += -d * X\n}}\n");
    let plain = model(&source);
    let checked = crate::driver::compile("m.gbm", &source, &["e"]).expect("compiles");
    assert_eq!(checked.model.noise, plain.noise);
}

#[test]
fn command_line_specs_parse() {
    let cases = [
        ("X=4%+0.01", level(Some("X"), 0.04, 0.01)),
        ("X = 0.01 + 4 %", level(Some("X"), 0.04, 0.01)),
        ("S=0.02", level(Some("S"), 0.0, 0.02)),
        ("OD=3%", level(Some("OD"), 0.03, 0.0)),
        ("4%", level(None, 0.04, 0.0)),
        ("0.01", level(None, 0.01, 0.0)),
        ("0", level(None, 0.0, 0.0)),
        ("0%+0.02", level(None, 0.0, 0.02)),
        ("X=1e+1%+2E-3", level(Some("X"), 0.1, 0.002)),
        ("declared", NoiseSpec::Declared),
    ];
    for (text, expected) in cases {
        assert_eq!(parse_noise_spec(text), Ok(expected), "{text}");
    }
}

#[test]
fn bad_command_line_specs_say_what_was_expected() {
    let cases = [
        ("", "expected a noise level"),
        ("X=", "expected a noise level"),
        ("-1", "expected a finite noise level >= 0, found `-1`"),
        ("X=-2%", ">= 0, found `-2%`"),
        ("X=inf", "expected a finite noise level"),
        ("X=NaN%", "expected a finite noise level"),
        (
            "X=abc",
            "expected a number in the noise level `abc`, found `abc`",
        ),
        ("X=0.01[g/L]", "found `0.01[g/L]`"),
        ("X=1%+2%", "expected at most one relative term"),
        ("X=0.1+0.2", "expected at most one absolute term"),
        ("X=1%+", "expected a number"),
        (
            "2X=1%",
            "expected the name of a measured state or output before `=`",
        ),
        ("=1%", "expected the name"),
    ];
    for (text, expected) in cases {
        let error = parse_noise_spec(text).expect_err(text);
        assert!(error.contains(expected), "{text}: {error}");
    }
}

#[test]
fn named_specs_replace_declarations_and_a_bare_level_covers_the_rest() {
    let model = model(MODEL);
    let measured = model.measured();
    let merged = |specs: &[NoiseSpec]| merge_noise(&model, specs, &measured).expect("merges");
    assert_eq!(merged(&[]), model.noise, "no spec: the declarations");
    assert_eq!(merged(&[NoiseSpec::Declared]), model.noise);
    assert_eq!(
        merged(&[level(Some("X"), 0.0, 0.5), level(Some("Q"), 0.01, 0.0)]),
        [
            noise(Measured::State(0), 0.0, 0.5),
            noise(Measured::Output(0), 0.03, 0.0),
            noise(Measured::Output(1), 0.01, 0.0),
        ],
        "named specs win per name; others keep their declarations"
    );
    assert_eq!(
        merged(&[level(None, 0.02, 0.0), level(Some("S"), 0.0, 0.1)]),
        [
            noise(Measured::State(0), 0.02, 0.0),
            noise(Measured::State(1), 0.0, 0.1),
            noise(Measured::Output(0), 0.02, 0.0),
        ],
        "a bare level covers every measured quantity not named, declared ones too"
    );
    assert_eq!(
        merged(&[level(Some("X"), 0.0, 0.0)]),
        [noise(Measured::Output(0), 0.03, 0.0)],
        "a zero level removes a quantity's noise"
    );
    assert_eq!(merged(&[level(None, 0.0, 0.0)]), []);
    let only_states = merge_noise(&model, &[level(None, 0.1, 0.0)], &[Measured::State(1)]);
    assert_eq!(
        only_states.expect("merges"),
        [
            noise(Measured::State(0), 0.04, 0.01),
            noise(Measured::State(1), 0.1, 0.0),
            noise(Measured::Output(0), 0.03, 0.0),
        ],
        "a bare level covers only the quantities the caller says are measured"
    );
}

#[test]
fn specs_naming_no_measured_quantity_or_one_twice_are_refused() {
    let model = model(MODEL);
    let measured = model.measured();
    let error = |specs: &[NoiseSpec]| merge_noise(&model, specs, &measured).expect_err("refused");
    let unknown = error(&[level(Some("Xx"), 0.01, 0.0)]);
    assert_eq!(
        unknown.to_string(),
        "expected a measured state or output in `--noise`, found `Xx`"
    );
    let NoiseSpecError::NotMeasured { help, .. } = &unknown else {
        panic!("{unknown:?}");
    };
    assert_eq!(
        help,
        "did you mean `X`? measured quantities: `OD`, `Q`, `S`, `X`"
    );
    let hidden = error(&[level(Some("H"), 0.01, 0.0)]);
    assert!(hidden
        .to_string()
        .ends_with("`H`, a hidden state (never measured)"));
    let param = error(&[level(Some("k"), 0.01, 0.0)]);
    assert!(param.to_string().contains("a param"), "{param}");
    let twice = error(&[level(Some("S"), 0.01, 0.0), level(Some("S"), 0.02, 0.0)]);
    assert_eq!(
        twice.to_string(),
        "expected one `--noise` spec for `S`, found two"
    );
    let bare = error(&[level(None, 0.01, 0.0), level(None, 0.02, 0.0)]);
    assert!(bare.to_string().contains("every quantity"), "{bare}");
    use miette::Diagnostic;
    assert_eq!(
        unknown.code().map(|c| c.to_string()),
        Some("gbm::E0134".into())
    );
    assert_eq!(
        twice.code().map(|c| c.to_string()),
        Some("gbm::E0135".into())
    );
}

#[test]
fn the_ir_text_lists_the_noise_only_when_declared() {
    let text = crate::ir::print(&model(MODEL));
    assert!(text.contains(
        "\nnoise (sigma(y) = sqrt(absolute^2 + (relative * y)^2))\n\
         \x20 state X [g/L]: relative 0.04, absolute 0.01\n\
         \x20 output OD [-]: relative 0.03, absolute 0\n"
    ));
    let without = MODEL.replace("noise X = 4 % + 10 [mg/L]\nnoise OD = 3 %\n", "");
    assert!(!crate::ir::print(&model(&without)).contains("noise"));
}
