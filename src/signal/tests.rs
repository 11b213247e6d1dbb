use super::*;
use miette::Diagnostic;

pub(super) type TestResult = Result<(), Box<dyn std::error::Error>>;

pub(super) fn input(name: &str, bounds: Option<(f64, f64)>) -> Input {
    Input {
        name: name.to_string(),
        bounds,
    }
}

/// The unit-bounded input `u in [0, 1]`.
pub(super) fn unit() -> Input {
    input("u", Some((0.0, 1.0)))
}

/// Parses `u=PROGRAM` and samples it for `input` on `[0, t_end]` with step `dt`.
pub(super) fn generate(
    argument: &str,
    input: &Input,
    t_end: f64,
    dt: f64,
) -> Result<Signal, SignalError> {
    let parsed = parse_input_argument(argument)?;
    parsed.program.generate(input, 0.0, t_end, dt)
}

/// Asserts that generating `argument` fails with `code`, its first label covering exactly
/// `labelled` in the argument text.
pub(super) fn check_error(argument: &str, input: &Input, code: &str, labelled: &str) {
    let error = match generate(argument, input, 100.0, 1.0) {
        Ok(signal) => panic!("expected {code} for `{argument}`, got {signal:?}"),
        Err(error) => error,
    };
    assert_eq!(code_of(&error), code, "`{argument}`: {error}");
    assert!(error.help().is_some(), "{code} has a help line");
    let label = error
        .labels()
        .and_then(|mut labels| labels.next())
        .unwrap_or_else(|| panic!("{code} has no label"));
    let source = error
        .source_code()
        .unwrap_or_else(|| panic!("{code} has no source"));
    let contents = source
        .read_span(label.inner(), 0, 0)
        .unwrap_or_else(|failure| panic!("label outside the source: {failure}"));
    let text = String::from_utf8_lossy(contents.data());
    assert_eq!(text, labelled, "`{argument}`: {error}");
}

pub(super) fn code_of(error: &dyn Diagnostic) -> String {
    error
        .code()
        .map(|code| code.to_string())
        .unwrap_or_default()
}

/// The durations between consecutive switches.
fn holds(signal: &Signal) -> Vec<f64> {
    signal
        .breaks
        .windows(2)
        .map(|pair| pair[1] - pair[0])
        .collect()
}

#[test]
fn steps_levels_lie_within_bounds_and_holds_on_the_grid() -> TestResult {
    let dt = 0.5;
    let signal = generate(
        "u=steps(lo=0.2, hi=0.7, hold=5..40, seed=2)",
        &unit(),
        20_000.0,
        dt,
    )?;
    assert_eq!(signal.breaks[0], 0.0);
    assert!(
        signal.breaks.len() > 500,
        "{} segments",
        signal.breaks.len()
    );
    assert!(signal.values.iter().all(|v| (0.2..=0.7).contains(v)));
    for hold in holds(&signal) {
        assert!((5.0..=40.0).contains(&hold), "hold {hold}");
        let steps = hold / dt;
        assert!(
            (steps - steps.round()).abs() < 1e-9,
            "hold {hold} off the grid"
        );
    }
    assert!(signal.breaks.last().is_some_and(|&last| last < 20_000.0));
    // Uniform draws: mean near the middle, extremes of the hold range both reached.
    let mean = signal.values.iter().sum::<f64>() / signal.values.len() as f64;
    assert!((mean - 0.45).abs() < 0.02, "mean level {mean}");
    let all = holds(&signal);
    assert!(all.contains(&5.0) && all.contains(&40.0));
    Ok(())
}

#[test]
fn steps_default_to_the_bounds_and_default_holds() -> TestResult {
    let wide = input("E0", Some((0.002, 0.02)));
    let signal = generate("E0=steps()", &wide, 1800.0, 1.0)?;
    assert!(signal.values.iter().all(|v| (0.002..=0.02).contains(v)));
    let (shortest, longest) = DEFAULT_HOLD_STEPS;
    assert!(holds(&signal)
        .iter()
        .all(|&h| (shortest as f64..=longest as f64).contains(&h)));
    Ok(())
}

#[test]
fn steps_are_deterministic_per_seed() -> TestResult {
    let first = generate("u=steps(seed=7)", &unit(), 500.0, 1.0)?;
    let again = generate("u=steps(seed=7)", &unit(), 500.0, 1.0)?;
    let other = generate("u=steps(seed=8)", &unit(), 500.0, 1.0)?;
    let default = generate("u=steps()", &unit(), 500.0, 1.0)?;
    let zero = generate("u = steps(seed = 0) ", &unit(), 500.0, 1.0)?;
    assert_eq!(first, again);
    assert_ne!(first.values, other.values);
    assert_eq!(default, zero);
    Ok(())
}

#[test]
fn fixed_hold_switches_every_hold() -> TestResult {
    let signal = generate("u=steps(hold=3)", &unit(), 30.0, 1.0)?;
    assert_eq!(
        signal.breaks,
        vec![0.0, 3.0, 6.0, 9.0, 12.0, 15.0, 18.0, 21.0, 24.0, 27.0]
    );
    Ok(())
}

#[test]
fn const_holds_its_value() -> TestResult {
    let signal = generate("u=const(0.5)", &unit(), 10.0, 1.0)?;
    assert_eq!(signal, Signal::constant(0.0, 0.5));
    let unbounded = generate("v=const(value=-3)", &input("v", None), 10.0, 1.0)?;
    assert_eq!(unbounded.value_at(5.0), -3.0);
    Ok(())
}

/// Crossings of the middle level among samples with index in `range`.
fn crossings(signal: &Signal, middle: f64, range: std::ops::Range<usize>) -> usize {
    signal.values[range]
        .windows(2)
        .filter(|pair| (pair[0] - middle).signum() != (pair[1] - middle).signum())
        .count()
}

#[test]
fn chirp_frequency_rises_linearly() -> TestResult {
    let (dt, t_end, f0, f1) = (0.1, 400.0, 0.01, 0.2);
    let signal = generate(
        "u=chirp(lo=0.2, hi=0.8, f0=0.01, f1=0.2)",
        &unit(),
        t_end,
        dt,
    )?;
    assert_eq!(signal.breaks.len(), 4000);
    assert!(signal.values.iter().all(|v| (0.2..=0.8).contains(v)));
    let quarter = signal.values.len() / 4;
    let early = crossings(&signal, 0.5, 0..quarter);
    let late = crossings(&signal, 0.5, 3 * quarter..4 * quarter);
    assert!(late > 4 * early, "early {early}, late {late}");
    // Two crossings per cycle; cycles on [a, b] = f0 (b - a) + (f1 - f0) (b^2 - a^2) / (2 T).
    let cycles = |a: f64, b: f64| f0 * (b - a) + (f1 - f0) * (b * b - a * a) / (2.0 * t_end);
    let expected_late = 2.0 * cycles(300.0, 400.0);
    assert!(
        (late as f64 - expected_late).abs() <= 2.0,
        "late {late} vs {expected_late}"
    );
    let expected_early = 2.0 * cycles(0.0, 100.0);
    assert!(
        (early as f64 - expected_early).abs() <= 2.0,
        "early {early} vs {expected_early}"
    );
    // Sampled at the grid and held: the value at t is the sample at floor(t / dt).
    let k: usize = 1234;
    let held = signal.value_at(k as f64 * dt + 0.05);
    let since = k as f64 * dt;
    let phase = 2.0 * std::f64::consts::PI * cycles(0.0, since);
    assert!((held - (0.5 + 0.3 * phase.sin())).abs() < 1e-9);
    Ok(())
}

#[test]
fn extreme_levels_stay_finite() -> TestResult {
    let free = input("v", None);
    for program in [
        "v=chirp(lo=-1e308, hi=1e308)",
        "v=steps(lo=-1e308, hi=1e308)",
    ] {
        let signal = generate(program, &free, 100.0, 1.0)?;
        assert!(signal.values.iter().all(|v| v.is_finite()), "{program}");
    }
    Ok(())
}

#[test]
fn chirp_restarts_each_period() -> TestResult {
    let signal = generate("u=chirp(f0=0.05, f1=0.2, period=50)", &unit(), 200.0, 0.5)?;
    let samples_per_period = 100;
    assert_eq!(
        signal.values[..samples_per_period],
        signal.values[samples_per_period..2 * samples_per_period]
    );
    Ok(())
}

#[test]
fn schedule_switches_at_its_own_times() -> TestResult {
    let signal = generate("u=schedule(0:0.2, 2.5:0.7, 4:0.7, 6:0)", &unit(), 10.0, 1.0)?;
    assert_eq!(
        signal.breaks,
        vec![0.0, 2.5, 6.0],
        "a break only at each change"
    );
    assert_eq!(signal.values, vec![0.2, 0.7, 0.0]);
    let early = generate("u=schedule(-3:0.5, 12:1)", &unit(), 10.0, 1.0)?;
    assert_eq!(early.sample(&[0.0, 11.9, 12.0]), vec![0.5, 0.5, 1.0]);
    let help = generate("u=steps(0:0.2)", &unit(), 10.0, 1.0)
        .err()
        .and_then(|e| e.help().map(|h| h.to_string()))
        .unwrap_or_default();
    assert!(help.contains("schedule(0:0.2"), "{help}");
    Ok(())
}

#[test]
fn program_errors_carry_a_code_and_a_label() {
    let free = input("v", None);
    let cases: &[(&str, &Input, &str, &str)] = &[
        ("u steps()", &unit(), "gbm::E0301", "u"),
        ("=const(1)", &unit(), "gbm::E0301", "=const(1)"),
        ("u=0.5", &unit(), "gbm::E0303", "0"),
        ("u=steps(lo=0", &unit(), "gbm::E0303", "0"),
        ("u=steps() extra", &unit(), "gbm::E0303", "e"),
        ("u=steps(lo=0,)", &unit(), "gbm::E0303", ")"),
        ("u=steps(lo=)", &unit(), "gbm::E0303", ")"),
        ("u=csv(\"open)", &unit(), "gbm::E0303", "\""),
        ("u=stpes()", &unit(), "gbm::E0304", "stpes"),
        ("u=steps(low=0)", &unit(), "gbm::E0305", "low"),
        ("u=steps(lo=0, lo=1)", &unit(), "gbm::E0306", "lo"),
        ("u=const(1, 2)", &unit(), "gbm::E0307", "2"),
        ("u=steps(hold=5, 0.5)", &unit(), "gbm::E0307", "0.5"),
        ("u=steps(lo=abc)", &unit(), "gbm::E0308", "abc"),
        ("u=steps(lo=inf)", &unit(), "gbm::E0308", "inf"),
        ("u=steps(hold=5-40)", &unit(), "gbm::E0308", "5-40"),
        ("u=steps(seed=-1)", &unit(), "gbm::E0308", "-1"),
        ("u=const()", &unit(), "gbm::E0309", "const"),
        ("v=steps(hold=5..40)", &free, "gbm::E0309", "steps"),
        ("v=chirp(lo=0)", &free, "gbm::E0309", "chirp"),
        ("u=steps(lo=0.8, hi=0.2)", &unit(), "gbm::E0310", "0.8"),
        ("u=steps(lo=0.5, hold=0..4)", &unit(), "gbm::E0311", "0..4"),
        ("u=steps(hold=40..5)", &unit(), "gbm::E0311", "40..5"),
        ("u=steps(hold=0.2..0.8)", &unit(), "gbm::E0311", "0.2..0.8"),
        ("u=const(1.5)", &unit(), "gbm::E0312", "1.5"),
        ("u=steps(lo=-0.1)", &unit(), "gbm::E0312", "-0.1"),
        ("u=chirp(hi=2)", &unit(), "gbm::E0312", "2"),
        ("u=chirp(f1=0.6)", &unit(), "gbm::E0313", "0.6"),
        ("u=chirp(f0=-1)", &unit(), "gbm::E0313", "-1"),
        ("u=chirp(period=0)", &unit(), "gbm::E0313", "0"),
        ("u=schedule()", &unit(), "gbm::E0309", "schedule"),
        ("u=schedule(t=0)", &unit(), "gbm::E0305", "t"),
        ("u=schedule(0-0.2)", &unit(), "gbm::E0308", "0-0.2"),
        ("u=schedule(0:0.2, 5:x)", &unit(), "gbm::E0308", "5:x"),
        ("u=steps(0:0.2)", &unit(), "gbm::E0308", "0:0.2"),
        ("u=schedule(0:2)", &unit(), "gbm::E0312", "0:2"),
        (
            "u=schedule(0:0.2, 5:0.3, 5:0.1)",
            &unit(),
            "gbm::E0317",
            "5:0.1",
        ),
        (
            "u=schedule(0:0.2, 5:0.3, 2:0.1)",
            &unit(),
            "gbm::E0317",
            "2:0.1",
        ),
        ("u=schedule(1:0.2)", &unit(), "gbm::E0318", "1:0.2"),
    ];
    for &(argument, input, code, labelled) in cases {
        check_error(argument, input, code, labelled);
    }
}

#[test]
fn suggestions_name_the_closest_program_key_and_input() -> TestResult {
    let help = |result: Result<Signal, SignalError>| {
        result
            .err()
            .and_then(|e| e.help().map(|h| h.to_string()))
            .unwrap_or_default()
    };
    assert!(help(generate("u=chrip()", &unit(), 10.0, 1.0)).contains("did you mean `chirp`?"));
    assert!(help(generate("u=steps(hodl=5)", &unit(), 10.0, 1.0)).contains("did you mean `hold`?"));
    let argument = parse_input_argument("E_0=const(0.01)")?;
    let inputs = [input("E0", Some((0.0, 1.0))), input("u", None)];
    let error = argument.resolve(&inputs).err().ok_or("expected an error")?;
    assert_eq!(code_of(&error), "gbm::E0302");
    assert!(error
        .help()
        .map(|h| h.to_string())
        .unwrap_or_default()
        .contains("did you mean `E0`?"));
    let argument = parse_input_argument("u=const(0.01)")?;
    assert_eq!(argument.resolve(&inputs)?.name, "u");
    Ok(())
}

#[test]
fn input_arguments_split_into_name_and_program() -> TestResult {
    let argument = parse_input_argument("  E0 = steps(lo=0.002, hi=0.02) ")?;
    assert_eq!(argument.name, "E0");
    assert_eq!(argument.program.text(), "steps(lo=0.002, hi=0.02)");
    assert_eq!(parse_program("const(2)")?.text(), "const(2)");
    Ok(())
}

#[test]
fn bad_horizons_are_errors() {
    let program = parse_program("const(0.5)");
    let check = |t_end: f64, dt: f64| match &program {
        Ok(program) => program
            .generate(&unit(), 0.0, t_end, dt)
            .err()
            .map(|e| code_of(&e)),
        Err(error) => panic!("{error}"),
    };
    assert_eq!(check(0.0, 1.0).as_deref(), Some("gbm::E0315"));
    assert_eq!(check(10.0, 0.0).as_deref(), Some("gbm::E0315"));
    assert_eq!(check(10.0, f64::NAN).as_deref(), Some("gbm::E0315"));
    assert_eq!(check(1e12, 1e-6).as_deref(), Some("gbm::E0315"));
    assert_eq!(check(10.0, 1.0), None);
}

#[test]
fn errors_stay_small_enough_to_return_by_value() {
    // clippy's `result_large_err` flags error types of 128 bytes or more in every caller.
    assert!(std::mem::size_of::<SignalError>() < 128);
}

#[test]
fn signal_new_checks_its_invariant() {
    assert!(Signal::new(vec![0.0, 1.0], vec![1.0, 2.0]).is_ok());
    assert!(Signal::new(vec![], vec![]).is_err());
    assert!(Signal::new(vec![0.0], vec![1.0, 2.0]).is_err());
    assert!(Signal::new(vec![0.0, 0.0], vec![1.0, 2.0]).is_err());
    assert!(Signal::new(vec![0.0, f64::NAN], vec![1.0, 2.0]).is_err());
    assert!(Signal::new(vec![0.0, 1.0], vec![1.0, f64::INFINITY]).is_err());
}

#[test]
fn value_at_holds_and_never_panics() {
    let signal = Signal {
        breaks: vec![0.0, 1.0, 3.0],
        values: vec![10.0, 20.0, 30.0],
    };
    let times = [-5.0, 0.0, 0.999, 1.0, 2.5, 3.0, 100.0];
    assert_eq!(
        signal.sample(&times),
        vec![10.0, 10.0, 10.0, 20.0, 20.0, 30.0, 30.0]
    );
    let empty = Signal {
        breaks: vec![],
        values: vec![],
    };
    assert!(empty.value_at(1.0).is_nan());
    let lopsided = Signal {
        breaks: vec![0.0, 1.0, 2.0],
        values: vec![5.0],
    };
    assert_eq!(lopsided.value_at(1.5), 5.0);
}

proptest::proptest! {
    #[test]
    fn arbitrary_arguments_never_panic(argument in "\\PC{0,60}") {
        if let Ok(parsed) = parse_input_argument(&argument) {
            let _ = parsed.program.generate(&unit(), 0.0, 50.0, 1.0);
        }
    }

    #[test]
    fn program_like_arguments_never_panic(argument in "u=(steps|const|chirp|schedule)\\([a-z0-9=.,:\\- ]{0,30}\\)") {
        if let Ok(parsed) = parse_input_argument(&argument) {
            if let Ok(signal) = parsed.program.generate(&unit(), 0.0, 50.0, 1.0) {
                proptest::prop_assert!(signal.values.iter().all(|v| (0.0..=1.0).contains(v)));
            }
        }
    }
}
