use super::*;
use crate::io::ScratchDir;
use miette::Diagnostic;

type TestResult = Result<(), Box<dyn std::error::Error>>;

/// Reads `text` (named `d.csv`) needing columns `u` and `X` and `min_rows` rows.
fn read_ux(text: &str, min_rows: usize) -> Result<Dataset, DataError> {
    read_str("d.csv", text, &["u", "X"], min_rows)
}

/// Asserts that `text` fails with `code` at `row` and, where given, at the 1-based
/// `column` index with that name, and that the message says so.
fn check_error(text: &str, code: &str, row: usize, column: Option<(usize, &str)>) {
    let error = match read_ux(text, 0) {
        Ok(dataset) => panic!("expected {code}, read {dataset:?}"),
        Err(error) => error,
    };
    assert_eq!(code_of(&error), code, "{error}");
    let message = error.to_string();
    let location = error
        .location()
        .unwrap_or_else(|| panic!("no location: {error}"));
    assert_eq!(location.file, "d.csv");
    assert_eq!(location.row, row, "{message}");
    assert!(message.contains(&format!("`d.csv` row {row}")), "{message}");
    match column {
        Some((index, name)) => {
            let found = location.column.as_ref().map(|c| (c.index, c.name.as_str()));
            assert_eq!(found, Some((index, name)), "{message}");
            assert!(message.contains(&format!("column {index}")), "{message}");
            if !name.is_empty() {
                assert!(message.contains(&format!("`{name}`")), "{message}");
            }
        }
        None => assert_eq!(location.column, None, "{message}"),
    }
    assert!(error.help().is_some(), "{code} has a help line");
    assert!(
        error.source_code().is_some(),
        "{code} carries the file's text"
    );
    assert!(error
        .labels()
        .is_some_and(|mut labels| labels.next().is_some()));
}

fn code_of(error: &dyn Diagnostic) -> String {
    error
        .code()
        .map(|code| code.to_string())
        .unwrap_or_default()
}

/// A report rendered as plain text, as a terminal without colour shows it.
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

#[test]
fn reads_a_clean_file_keeping_columns_in_the_order_asked() -> TestResult {
    let dataset = read_ux("t,X,extra,u\n0,1.5,a,0\n0.5,2,b,1\n1,2.5e0,c,0.25\n", 3)?;
    assert_eq!(dataset.times, vec![0.0, 0.5, 1.0]);
    assert_eq!(dataset.step, 0.5);
    assert_eq!(dataset.len(), 3);
    let names: Vec<&str> = dataset.columns.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, vec!["u", "X"]);
    assert_eq!(dataset.column("u"), Some(&[0.0, 1.0, 0.25][..]));
    assert_eq!(dataset.column("X"), Some(&[1.5, 2.0, 2.5][..]));
    assert_eq!(dataset.column("extra"), None);
    Ok(())
}

#[test]
fn tolerates_crlf_bom_whitespace_quotes_and_trailing_blank_lines() -> TestResult {
    let text = "\u{FEFF} t , \"u\",X \r\n 0 ,\t1, 2\r\n1,\" 3 \",4\r\n\r\n  \n";
    let dataset = read_ux(text, 2)?;
    assert_eq!(dataset.times, vec![0.0, 1.0]);
    assert_eq!(dataset.column("u"), Some(&[1.0, 3.0][..]));
    assert_eq!(dataset.column("X"), Some(&[2.0, 4.0][..]));
    Ok(())
}

#[test]
fn step_is_uniform_within_rounding_of_decimal_times() -> TestResult {
    let text: String = std::iter::once("t,u,X\n".to_string())
        .chain((0..1000).map(|i| format!("{},0,0\n", 1000.0 + i as f64 * 0.1)))
        .collect();
    let dataset = read_ux(&text, 1000)?;
    assert!((dataset.step - 0.1).abs() < 1e-9, "{}", dataset.step);
    Ok(())
}

/// Asserts the defect of a data row placed as row 3, between two good rows, of a file
/// with header `t,u,X,note`.
fn check_row(row: &str, code: &str, column: Option<(usize, &str)>) {
    let text = format!("t,u,X,note\n0,0,0,ok\n{row}\n1,0,0,ok\n");
    check_error(&text, code, 3, column);
}

#[test]
fn empty_file() {
    check_error("", "gbm::E0203", 1, None);
    check_error("\n \r\n", "gbm::E0203", 1, None);
}

#[test]
fn header_only_file() {
    check_error("t,u,X\n", "gbm::E0204", 1, None);
}

#[test]
fn unnamed_column() {
    check_error("t,u,,X\n0,0,0,0\n", "gbm::E0205", 1, Some((3, "")));
}

#[test]
fn duplicate_column() {
    check_error("t,u,X,u\n0,0,0,0\n", "gbm::E0206", 1, Some((4, "u")));
}

#[test]
fn missing_time_column() {
    check_error("when,u,X\n0,0,0\n", "gbm::E0207", 1, None);
}

#[test]
fn missing_required_column() {
    check_error("t,u,Y\n0,0,0\n", "gbm::E0208", 1, None);
}

#[test]
fn ragged_row_too_few_cells() {
    check_row("1,0,0", "gbm::E0209", Some((4, "note")));
}

#[test]
fn ragged_row_too_many_cells() {
    check_row("1,0,0,ok,surplus", "gbm::E0209", Some((5, "")));
}

#[test]
fn blank_line_inside_the_data() {
    check_row("", "gbm::E0209", Some((1, "t")));
}

#[test]
fn empty_cell() {
    check_row("1,,0,ok", "gbm::E0210", Some((2, "u")));
}

#[test]
fn non_number_cell() {
    check_row("1,0,abc,ok", "gbm::E0211", Some((3, "X")));
    check_row("1,0,1.2.3,ok", "gbm::E0211", Some((3, "X")));
    check_row("x,0,0,ok", "gbm::E0211", Some((1, "t")));
}

#[test]
fn nan_or_infinite_cell() {
    check_row("1,NaN,0,ok", "gbm::E0212", Some((2, "u")));
    check_row("1,0,-inf,ok", "gbm::E0212", Some((3, "X")));
    check_row("1,0,1e999,ok", "gbm::E0212", Some((3, "X")));
}

#[test]
fn extra_columns_are_not_parsed() -> TestResult {
    let dataset = read_ux("t,u,X,note\n0,0,0,NaN\n1,0,0,\n", 2)?;
    assert_eq!(dataset.len(), 2);
    Ok(())
}

#[test]
fn unsorted_time() {
    check_error(
        "t,u,X\n0,0,0\n2,0,0\n1,0,0\n",
        "gbm::E0213",
        4,
        Some((1, "t")),
    );
}

#[test]
fn repeated_time() {
    check_error(
        "t,u,X\n0,0,0\n1,0,0\n1,0,0\n",
        "gbm::E0214",
        4,
        Some((1, "t")),
    );
}

#[test]
fn gapped_time() {
    let text = "t,u,X\n0,0,0\n1,0,0\n2,0,0\n4,0,0\n5,0,0\n";
    check_error(text, "gbm::E0215", 5, Some((1, "t")));
}

#[test]
fn uneven_first_step() {
    check_error(
        "t,u,X\n0,0,0\n2,0,0\n3,0,0\n4,0,0\n",
        "gbm::E0215",
        3,
        Some((1, "t")),
    );
}

#[test]
fn step_deviation_beyond_tolerance() {
    // Times printed to 1e-5, too few steps for a scatter: the tolerance is 1e-5, and a
    // deviation of 3e-5 is beyond it (one of 1e-5, the last decimal, is within it).
    let text = "t,u,X\n0,0,0\n1,0,0\n2.00003,0,0\n3.00003,0,0\n";
    check_error(text, "gbm::E0215", 4, Some((1, "t")));
}

#[test]
fn time_defect_in_a_later_column_names_that_column() {
    let text = "u,X,t\n0,0,0\n0,0,1\n0,0,3\n0,0,4\n";
    check_error(text, "gbm::E0215", 4, Some((3, "t")));
}

#[test]
fn too_few_rows_says_how_many_and_why() {
    let text = "t,u,X\n0,0,0\n1,0,0\n2,0,0\n";
    let needed = MinRows::new(46, "the embedding needs 46 rows of history");
    let error = read_str("d.csv", text, &["u", "X"], needed).err();
    let message = error.as_ref().map(|e| e.to_string()).unwrap_or_default();
    assert!(message.contains("at least 46 data rows"), "{message}");
    assert!(
        message.contains("the embedding needs 46 rows of history"),
        "{message}"
    );
    assert!(message.contains("found 3"), "{message}");
    assert_eq!(
        error.as_ref().and_then(|e| e.location()).map(|l| l.row),
        Some(4)
    );
    assert_eq!(
        error.as_ref().map(|e| code_of(e)).as_deref(),
        Some("gbm::E0216")
    );
    check_error("t,u,X\n0,0,0\n", "gbm::E0216", 2, None);
}

#[test]
fn missing_column_help_lists_columns_and_suggests_near_misses() {
    let error = read_ux("t,u,x,Xs\n0,0,0,0\n1,0,0,0\n", 0).err();
    let help = error
        .as_ref()
        .and_then(|e| e.help())
        .map(|h| h.to_string())
        .unwrap_or_default();
    assert!(help.contains("did you mean `x`?"), "{help}");
    assert!(help.contains("`t`, `u`, `x`, `Xs`"), "{help}");
    let error = read_ux("T,u,X\n0,0,0\n", 0).err();
    let help = error.as_ref().and_then(|e| e.help()).map(|h| h.to_string());
    assert!(help.unwrap_or_default().contains("`--column t=T`"));
}

#[test]
fn rendered_error_shows_the_offending_line() {
    let error = match read_ux("t,u,X\n0,0,0\n1,0,oops\n", 0) {
        Err(error) => error,
        Ok(dataset) => panic!("read {dataset:?}"),
    };
    let rendered = render(&error);
    assert!(rendered.contains("1,0,oops"), "{rendered}");
    assert!(rendered.contains("not a number"), "{rendered}");
    assert!(rendered.contains("gbm::E0211"), "{rendered}");
    assert!(rendered.contains("d.csv:3:5"), "{rendered}");
}

#[test]
fn unreadable_files_are_errors_naming_the_file() -> TestResult {
    let scratch = ScratchDir::new("data-read")?;
    let missing = scratch.join("missing.csv");
    let error = read(&missing, &[], 0).err().ok_or("expected an error")?;
    assert_eq!(code_of(&error), "gbm::E0201");
    assert!(error.to_string().contains("missing.csv"), "{error}");
    assert!(error.to_string().contains("no such file"), "{error}");
    let error = read(&scratch.path, &[], 0)
        .err()
        .ok_or("expected an error")?;
    assert_eq!(code_of(&error), "gbm::E0201");
    Ok(())
}

#[test]
fn binary_garbage_is_a_data_error() -> TestResult {
    let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
    let garbage: Vec<u8> = (0..1 << 20)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 56) as u8
        })
        .collect();
    let scratch = ScratchDir::new("data-garbage")?;
    let path = scratch.join("garbage.csv");
    std::fs::write(&path, &garbage)?;
    let error = read(&path, &["u"], 10).err().ok_or("expected an error")?;
    assert_eq!(code_of(&error), "gbm::E0202");
    assert!(error.to_string().contains("row"), "{error}");
    // Printable garbage is valid UTF-8 and fails on structure instead.
    let printable: String = garbage.iter().map(|b| char::from(b' ' + b % 95)).collect();
    let lined: String = printable
        .as_bytes()
        .chunks(70)
        .map(|chunk| format!("{}\n", String::from_utf8_lossy(chunk)))
        .collect();
    assert!(read_str("g.csv", &lined, &["u"], 10).is_err());
    Ok(())
}

#[test]
fn not_text_error_points_at_the_invalid_byte() -> TestResult {
    let scratch = ScratchDir::new("data-latin1")?;
    let path = scratch.join("latin1.csv");
    std::fs::write(&path, b"t,u,X\n0,0,0\n1,0,\xe9t\xe9\n")?;
    let error = read(&path, &["u", "X"], 0)
        .err()
        .ok_or("expected an error")?;
    let location = error.location().ok_or("expected a location")?;
    assert_eq!(location.row, 3);
    assert_eq!(
        location.column.as_ref().map(|c| (c.index, c.name.as_str())),
        Some((3, "X"))
    );
    Ok(())
}

#[test]
fn write_csv_round_trips_every_value_exactly() -> TestResult {
    let scratch = ScratchDir::new("data-write")?;
    let path = scratch.join("out/sim.csv");
    let times: Vec<f64> = (0..5).map(|i| i as f64 * 0.1).collect();
    let awkward = vec![0.1 + 0.2, 1e-7, -2.5e20, f64::MIN_POSITIVE, -0.0];
    let header = vec!["t".to_string(), "X".to_string()];
    write_csv(&path, &header, &[times.clone(), awkward.clone()])?;
    let dataset = read(&path, &["X"], 5)?;
    assert_eq!(dataset.times, times);
    let back = dataset.column("X").ok_or("no X")?;
    let bits = |values: &[f64]| values.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(back), bits(&awkward));
    let text = std::fs::read_to_string(&path)?;
    assert!(text.starts_with("t,X\n0,0.30000000000000004\n"), "{text}");
    Ok(())
}

#[test]
fn write_csv_refuses_mismatched_columns() -> TestResult {
    let scratch = ScratchDir::new("data-write-bad")?;
    let path = scratch.join("bad.csv");
    let header = vec!["t".to_string(), "X".to_string()];
    let short = write_csv(&path, &header, &[vec![0.0, 1.0], vec![1.0]]);
    let message = short.err().map(|e| e.to_string()).unwrap_or_default();
    assert!(
        message.contains("expected 2 values in column 2 `X`, found 1"),
        "{message}"
    );
    let missing = write_csv(&path, &header, &[vec![0.0]]);
    assert!(missing.is_err());
    assert!(!path.exists(), "nothing is written");
    Ok(())
}

#[test]
fn write_csv_refuses_a_value_that_is_not_finite_naming_where() -> TestResult {
    let scratch = ScratchDir::new("data-write-nan")?;
    let path = scratch.join("pred.csv");
    let header = vec!["t".to_string(), "S".to_string(), "P".to_string()];
    let columns = [
        vec![0.0, 0.5, 1.0],
        vec![1.0, 2.0, 3.0],
        vec![1.0, 2.0, f64::NAN],
    ];
    let error = write_csv(&path, &header, &columns)
        .err()
        .ok_or("expected an error")?;
    assert!(matches!(error, IoError::NotFinite { .. }), "{error:?}");
    let message = error.to_string();
    assert!(message.contains("`P` = NaN at t = 1 (row 3)"), "{message}");
    assert!(!path.exists(), "nothing is written");
    Ok(())
}

#[test]
fn errors_stay_small_enough_to_return_by_value() {
    // clippy's `result_large_err` flags error types of 128 bytes or more in every caller.
    assert!(std::mem::size_of::<DataError>() < 128);
    assert!(std::mem::size_of::<IoError>() < 128);
}

#[test]
fn format_number_is_short_and_exact() {
    let cases = [
        (0.0, "0"),
        (2.0, "2"),
        (0.05, "0.05"),
        (1e-7, "1e-7"),
        (1.5e20, "1.5e20"),
        (-123.25, "-123.25"),
        (f64::NAN, "NaN"),
    ];
    for (value, text) in cases {
        assert_eq!(format_number(value), text);
    }
    for value in [
        std::f64::consts::PI,
        1.0 / 3.0,
        6.02214076e23,
        1e-300,
        9.999e15,
    ] {
        assert_eq!(format_number(value).parse::<f64>().ok(), Some(value));
    }
}

proptest::proptest! {
    #[test]
    fn arbitrary_text_never_panics(text in "\\PC{0,200}") {
        let _ = read_ux(&text, 3);
    }

    #[test]
    fn csv_like_text_never_panics(text in "[t,uX0-9.e\\- \r\n\"]{0,120}") {
        if let Ok(dataset) = read_ux(&text, 0) {
            proptest::prop_assert!(dataset.len() >= 2);
            proptest::prop_assert!(dataset.step > 0.0);
        }
    }
}
