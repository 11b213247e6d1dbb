//! Defects of data sets: each with its code, the file, row and column it names, and what
//! its message says.

use super::tests_set::{mapped, read_files, request};
use super::*;
use miette::Diagnostic;

/// What an error must say: its code, where (file, row, column as 1-based index and header),
/// and phrases of its message and help.
struct Expected<'a> {
    code: &'a str,
    file: &'a str,
    row: usize,
    column: Option<(usize, &'a str)>,
    message: &'a [&'a str],
    help: &'a [&'a str],
}

/// Asserts that reading `files` with `request` fails as `expected`, with a label on the
/// file's text that the renderer can show.
fn check(files: &[(&str, &str)], request: &Request, expected: Expected<'_>) {
    let error = match read_files(files, request) {
        Ok(set) => panic!("expected {}, read {:?}", expected.code, set.names()),
        Err(error) => error,
    };
    let message = error.to_string();
    let code = error.code().map(|c| c.to_string()).unwrap_or_default();
    assert_eq!(code, expected.code, "{message}");
    let location = error
        .location()
        .unwrap_or_else(|| panic!("no location: {message}"));
    assert_eq!(location.file, expected.file, "{message}");
    assert_eq!(location.row, expected.row, "{message}");
    let column = location.column.as_ref().map(|c| (c.index, c.name.as_str()));
    assert_eq!(column, expected.column, "{message}");
    assert!(message.contains(&location.to_string()), "{message}");
    for phrase in expected.message {
        assert!(message.contains(phrase), "`{phrase}` not in: {message}");
    }
    let help = error.help().map(|h| h.to_string()).unwrap_or_default();
    assert!(!help.is_empty(), "{} has a help line", expected.code);
    for phrase in expected.help {
        assert!(help.contains(phrase), "`{phrase}` not in: {help}");
    }
    assert!(error.source_code().is_some(), "{message}");
    assert!(
        error.labels().is_some_and(|mut l| l.next().is_some()),
        "{message}"
    );
    render(&error);
}

/// Asserts that a `--column` defect fails with `code` and says `phrases`.
fn check_mapping(request: &Request, code: &str, phrases: &[&str]) {
    let error = match read_files(&[("d.csv", "t,u,X\n0,0,0\n")], request) {
        Ok(_) => panic!("expected {code}"),
        Err(error) => error,
    };
    let text = format!(
        "{error} {}",
        error.help().map(|h| h.to_string()).unwrap_or_default()
    );
    assert_eq!(
        error.code().map(|c| c.to_string()).as_deref(),
        Some(code),
        "{text}"
    );
    assert_eq!(error.location(), None);
    for phrase in phrases {
        assert!(text.contains(phrase), "`{phrase}` not in: {text}");
    }
}

/// The report as a terminal without colour shows it.
fn render(error: &DataError) -> String {
    let handler =
        miette::GraphicalReportHandler::new_themed(miette::GraphicalTheme::unicode_nocolor())
            .with_width(100);
    let mut out = String::new();
    match handler.render_report(&mut out, error) {
        Ok(()) => out,
        Err(failure) => panic!("rendering failed: {failure}"),
    }
}

/// An error in the single file `d.csv`.
fn check_one(text: &str, expected: Expected<'_>) {
    check(&[("d.csv", text)], &request(), expected);
}

fn at<'a>(code: &'a str, row: usize, column: Option<(usize, &'a str)>) -> Expected<'a> {
    Expected {
        code,
        file: "d.csv",
        row,
        column,
        message: &[],
        help: &[],
    }
}

#[test]
fn mixed_delimiters_are_named_as_such() {
    let expected = Expected {
        message: &[
            "expected 6 fields separated by `;`",
            "found 1",
            "mixes delimiters",
        ],
        ..at("gbm::E0217", 3, None)
    };
    check_one("t;u;X;a;b;c\n0;1;2;3;4;5\n1,1,2,3,4,5\n", expected);
    let expected = Expected {
        message: &["separated by `,`", "this row by `;`"],
        ..at("gbm::E0217", 2, None)
    };
    check_one("t,u,X\n0;1;2\n", expected);
    let error = read_files(&[("d.csv", "t,u,X\n0;1;2\n")], &request()).err();
    let rendered = error.as_ref().map(render).unwrap_or_default();
    assert!(rendered.contains("0;1;2"), "{rendered}");
}

#[test]
fn cells_that_are_not_numbers() {
    check_one("t,u,X\n0,1,abc\n", at("gbm::E0211", 2, Some((3, "X"))));
    check_one("t,u,X [g/L]\n0,1,1,5\n", at("gbm::E0209", 2, Some((4, ""))));
    check_one("t;u;X\n0;1;1.000,5\n", at("gbm::E0211", 2, Some((3, "X"))));
    for infinite in ["inf", "-Infinity", "1e999"] {
        let text = format!("t,u,X\n0,1,1\n1,{infinite},1\n");
        let expected = Expected {
            message: &["expected a finite number", infinite],
            ..at("gbm::E0212", 3, Some((2, "u")))
        };
        check_one(&text, expected);
    }
    let rendered = read_files(&[("d.csv", "t,u,X\n0,1,\"  oops\"\n")], &request())
        .err()
        .as_ref()
        .map(render)
        .unwrap_or_default();
    assert!(rendered.contains("d.csv:2:8"), "{rendered}");
}

#[test]
fn missing_time_and_experiment_name() {
    for spelling in ["", "NA", "nan"] {
        let text = format!("t,u,X\n0,1,1\n{spelling},1,1\n");
        let expected = Expected {
            message: &["expected a time"],
            help: &["every row needs its time"],
            ..at("gbm::E0210", 3, Some((1, "t")))
        };
        check_one(&text, expected);
    }
    let expected = Expected {
        message: &["expected an experiment name"],
        ..at("gbm::E0210", 3, Some((1, "experiment")))
    };
    check_one("experiment,t,u,X\na,0,1,1\n ,1,1,1\n", expected);
}

#[test]
fn repeated_and_decreasing_time_within_an_experiment() {
    let expected = Expected {
        message: &["two rows with time 1 in experiment `a`", "repeats row 3"],
        ..at("gbm::E0214", 5, Some((2, "t")))
    };
    check_one(
        "experiment,t,u,X\na,0,1,1\na,1,1,1\nb,1,1,1\na,1,1,1\n",
        expected,
    );
    let expected = Expected {
        message: &["experiment `d`", "found 0.5 after 1 (row 3)"],
        ..at("gbm::E0213", 4, Some((1, "t [h]")))
    };
    check_one("t [h],u,X\n0,1,1\n1,1,1\n0.5,1,1\n", expected);
}

#[test]
fn input_without_a_first_value() {
    let expected = Expected {
        message: &["input `u`", "first row of experiment `b`"],
        help: &["inputs hold their last value until the next one"],
        ..at("gbm::E0222", 3, Some((3, "u")))
    };
    check_one("experiment,t,u,X\na,0,1,1\nb,0,NA,1\nb,1,1,1\n", expected);
}

#[test]
fn state_never_measured_in_an_experiment() {
    let expected = Expected {
        file: "b.csv",
        message: &["state `X`", "experiment `b`", "found none in its 2 rows"],
        help: &["drop the experiment", "--column X=HEADER"],
        ..at("gbm::E0223", 2, Some((3, "X [g/L]")))
    };
    let files = [
        ("a.csv", "t,u,X\n0,1,1\n"),
        ("b.csv", "t,u,X [g/L]\n0,1,\n1,1,NA\n"),
    ];
    check(&files, &request(), expected);
}

#[test]
fn too_short_experiment_says_needed_found_and_why() {
    let request = request().with_min_rows(MinRows::new(4, "the embedding needs 4 rows of history"));
    let expected = Expected {
        message: &[
            "at least 4 data rows (the embedding needs 4 rows of history)",
            "found 2 in experiment `short`",
        ],
        ..at("gbm::E0216", 5, None)
    };
    let text = "experiment,t,u,X\nlong,0,1,1\nlong,1,1,1\nshort,0,1,1\nshort,1,1,1\nlong,2,1,1\nlong,3,1,1\n";
    check(&[("d.csv", text)], &request, expected);
}

#[test]
fn two_experiments_with_one_name() {
    let expected = Expected {
        file: "runs.csv",
        message: &["two experiments named `a`", "one in `x/a.csv`"],
        ..at("gbm::E0221", 3, Some((1, "experiment")))
    };
    let files = [
        ("x/a.csv", "t,u,X\n0,1,1\n"),
        ("runs.csv", "experiment,t,u,X\nb,0,1,1\na,0,1,1\n"),
    ];
    check(&files, &request(), expected);
    let expected = Expected {
        file: "y/a.csv",
        message: &["one in `x/a.csv`"],
        ..at("gbm::E0221", 2, None)
    };
    check(
        &[("x/a.csv", "t,u,X\n0,1,1\n"), ("y/a.csv", "t,u,X\n0,1,1\n")],
        &request(),
        expected,
    );
}

#[test]
fn header_defects() {
    let expected = Expected {
        help: &["`--column t=HEADER`", "`hours`, `u`, `X`"],
        message: &["found none"],
        ..at("gbm::E0207", 1, None)
    };
    check_one("hours,u,X\n0,1,1\n", expected);
    let expected = Expected {
        message: &["`time` and `Time [h]`, each could be time"],
        help: &["--column t=time"],
        ..at("gbm::E0207", 1, None)
    };
    check_one("time,Time [h],u,X\n0,1,1,1\n", expected);
    let expected = Expected {
        help: &["did you mean `x`?", "--column X=x"],
        ..at("gbm::E0208", 1, None)
    };
    check_one("t,u,x\n0,1,1\n", expected);
    let expected = Expected {
        message: &["`X` is also column 3"],
        ..at("gbm::E0206", 1, Some((4, "X [mg/L]")))
    };
    check_one("t,u,X [g/L],X [mg/L]\n0,1,1,1\n", expected);
    check_one("t,u,X\n", at("gbm::E0204", 1, None));
    check_one("\n\n", at("gbm::E0203", 1, None));
}

#[test]
fn blank_line_among_the_rows() {
    let expected = Expected {
        help: &["remove the blank line"],
        ..at("gbm::E0209", 3, Some((1, "t")))
    };
    check_one("t,u,X\n0,1,1\n   \n1,1,1\n", expected);
    check_one(
        "t,u,X\r\n0,1,1\r\n\r\n1,1,1\r\n",
        at("gbm::E0209", 3, Some((1, "t"))),
    );
}

#[test]
fn mapped_header_missing_from_a_file() {
    let expected = Expected {
        message: &["`Biomas` (from `--column X=Biomas`)"],
        help: &["did you mean `Biomass [g/L]`?"],
        ..at("gbm::E0220", 1, None)
    };
    check(
        &[("d.csv", "t,u,Biomass [g/L]\n0,1,1\n")],
        &mapped(&["X=Biomas"]),
        expected,
    );
    // An optional mapping must match in some file of the set.
    let expected = Expected {
        message: &["(from `--column OD=Scatter`)"],
        ..at("gbm::E0220", 1, None)
    };
    check(
        &[("d.csv", "t,u,X\n0,1,1\n")],
        &mapped(&["OD=Scatter"]),
        expected,
    );
    let expected = Expected {
        file: "b.csv",
        ..at("gbm::E0220", 1, None)
    };
    let files = [("a.csv", "Hours,u,X\n0,1,1\n"), ("b.csv", "t,u,X\n0,1,1\n")];
    check(&files, &mapped(&["t=Hours"]), expected);
}

#[test]
fn column_mapping_defects() {
    check_mapping(
        &mapped(&["Q=a"]),
        "gbm::E0218",
        &["unknown `--column` name `Q`"],
    );
    check_mapping(
        &mapped(&["x=a"]),
        "gbm::E0218",
        &["did you mean `X`?", "`t`, `experiment`, `u`, `X`, `OD`"],
    );
    check_mapping(
        &mapped(&["X=a", "u=b", "X=c"]),
        "gbm::E0219",
        &["`--column X=HEADER`", "`a` and `c`"],
    );
}

#[test]
fn single_record_view_refuses_several_experiments() {
    let error = read_str(
        "d.csv",
        "experiment,t,u,X\na,0,1,1\nb,0,1,1\n",
        &["u", "X"],
        0,
    )
    .err();
    let message = error.as_ref().map(|e| e.to_string()).unwrap_or_default();
    let code = error.as_ref().and_then(|e| e.code()).map(|c| c.to_string());
    assert_eq!(code.as_deref(), Some("gbm::E0224"), "{message}");
    assert!(message.contains("2 experiments (`a`, `b`)"), "{message}");
    assert_eq!(
        error.as_ref().and_then(|e| e.location()).map(|l| l.row),
        Some(3)
    );
    let missing = read_str("d.csv", "t,u,X\n0,1,NA\n1,1,2\n", &["u", "X"], 0).err();
    let message = missing.as_ref().map(|e| e.to_string()).unwrap_or_default();
    assert!(message.contains("expected a number"), "{message}");
    assert!(message.contains("found `NA`"), "{message}");
}

#[test]
fn every_new_error_is_small() {
    assert!(std::mem::size_of::<DataError>() < 128);
}
