//! Data sets read right: experiments, columns, units, mappings, delimiters, cells.

use super::*;
use crate::io::ScratchDir;
use miette::Diagnostic;
use std::path::PathBuf;

type TestResult = Result<(), Box<dyn std::error::Error>>;

/// The request of most tests: input `u`, state `X`, optional `OD`.
pub(super) fn request() -> Request {
    Request::new(vec![
        Wanted::input("u"),
        Wanted::state("X"),
        Wanted::optional("OD"),
    ])
}

/// `request()` with `--column` mappings written `NAME=HEADER`.
pub(super) fn mapped(mapping: &[&str]) -> Request {
    let mapping = mapping
        .iter()
        .map(|argument| parse_mapping(argument))
        .collect::<Result<Vec<_>, _>>();
    request().with_mapping(mapping.unwrap_or_else(|error| panic!("{error}")))
}

/// Reads `files` as `(name, text)` pairs.
pub(super) fn read_files(files: &[(&str, &str)], request: &Request) -> Result<DataSet, DataError> {
    let named: Vec<(String, String)> = files
        .iter()
        .map(|(name, text)| (name.to_string(), text.to_string()))
        .collect();
    read_set_str(&named, request)
}

/// Reads `files` with `request`, panicking with the rendered error if it fails.
fn read_ok(files: &[(&str, &str)], request: &Request) -> DataSet {
    match read_files(files, request) {
        Ok(set) => set,
        Err(error) => panic!("{:?}", miette::Report::new(error)),
    }
}

/// Asserts one experiment of `set`: its name, file, times, rows, and for each column given
/// as `(name, values)` its values (`None` = not measured).
fn check_experiment(
    set: &DataSet,
    name: &str,
    file: &str,
    times: &[f64],
    rows: &[usize],
    columns: &[(&str, &[Option<f64>])],
) {
    let experiment = set
        .experiment(name)
        .unwrap_or_else(|| panic!("no experiment `{name}` in {:?}", set.names()));
    assert_eq!(experiment.file, PathBuf::from(file), "{name}");
    assert_eq!(experiment.times, times, "{name}");
    assert_eq!(experiment.rows, rows, "{name}");
    for (column, values) in columns {
        let series = experiment
            .series(column)
            .unwrap_or_else(|| panic!("no column `{column}` in `{name}`"));
        assert_eq!(series.values, *values, "{name}.{column}");
    }
}

/// Asserts that `text` (one file `d.csv`) reads with `request` to times `times` and, for
/// each `(name, values)`, those values.
fn check_file(text: &str, request: &Request, times: &[f64], columns: &[(&str, &[Option<f64>])]) {
    let set = read_ok(&[("d.csv", text)], request);
    assert_eq!(set.names(), vec!["d"]);
    let rows: Vec<usize> = (2..2 + times.len()).collect();
    check_experiment(&set, "d", "d.csv", times, &rows, columns);
}

const S: Option<f64> = None;

#[test]
fn several_files_are_several_experiments_named_by_their_stems() {
    let set = read_ok(
        &[
            ("runs/a.csv", "t,u,X\n0,1,2\n0.5,1,3\n2,0,4\n"),
            ("b.data.csv", "X,t,u\n5,10,0\n6,12.5,1\n"),
        ],
        &request(),
    );
    assert_eq!(set.names(), vec!["a", "b.data"]);
    let a: &[Option<f64>] = &[Some(2.0), Some(3.0), Some(4.0)];
    check_experiment(
        &set,
        "a",
        "runs/a.csv",
        &[0.0, 0.5, 2.0],
        &[2, 3, 4],
        &[("X", a)],
    );
    let u: &[Option<f64>] = &[Some(0.0), Some(1.0)];
    check_experiment(
        &set,
        "b.data",
        "b.data.csv",
        &[10.0, 12.5],
        &[2, 3],
        &[("u", u)],
    );
    let columns: Vec<&str> = set.experiments[1]
        .columns
        .iter()
        .map(|series| series.name.as_str())
        .collect();
    assert_eq!(columns, vec!["u", "X"], "request order, not file order");
    assert!(
        set.experiments[0].series("OD").is_none(),
        "optional, absent"
    );
}

#[test]
fn an_experiment_column_splits_a_file_even_where_its_rows_interleave() {
    let text = "experiment,t,u,X\nb1,0,1,10\nb2,5,0,20\nb1,1,,11\nb2,6,0,\nb1,3,2,12\n";
    let set = read_ok(&[("runs.csv", text)], &request());
    assert_eq!(set.names(), vec!["b1", "b2"]);
    let u: &[Option<f64>] = &[Some(1.0), None, Some(2.0)];
    check_experiment(
        &set,
        "b1",
        "runs.csv",
        &[0.0, 1.0, 3.0],
        &[2, 4, 6],
        &[("u", u)],
    );
    let x: &[Option<f64>] = &[Some(20.0), None];
    check_experiment(&set, "b2", "runs.csv", &[5.0, 6.0], &[3, 5], &[("X", x)]);
}

#[test]
fn files_with_and_without_an_experiment_column_mix() {
    let set = read_ok(
        &[
            ("runs.csv", "t,experiment,u,X\n0,p,1,1\n0,q,1,2\n1,p,1,3\n"),
            ("r.csv", "t,u,X\n0,0,0\n"),
        ],
        &request(),
    );
    assert_eq!(set.names(), vec!["p", "q", "r"]);
    assert_eq!(
        set.experiment("p").map(|e| e.times.clone()),
        Some(vec![0.0, 1.0])
    );
}

#[test]
fn units_in_headers_are_kept() {
    let set = read_ok(
        &[("d.csv", "t [h],u [1/h], X [ g/L ],OD[-]\n0,1,2,3\n")],
        &request(),
    );
    let experiment = &set.experiments[0];
    assert_eq!(experiment.time_unit.as_deref(), Some("h"));
    let describe = |name: &str| {
        experiment
            .series(name)
            .map(|s| (s.header.clone(), s.unit.clone(), s.index))
    };
    assert_eq!(
        describe("u"),
        Some(("u [1/h]".into(), Some("1/h".into()), 2))
    );
    assert_eq!(
        describe("X"),
        Some(("X [ g/L ]".into(), Some("g/L".into()), 3))
    );
    assert_eq!(describe("OD"), Some(("OD[-]".into(), Some("-".into()), 4)));
}

#[test]
fn percent_and_ppm_headers_name_their_column() {
    let text = "t [h],u [%],X [ppm],OD [%]\n0,20.9,3,\n1,21,4,95\n";
    let set = read_ok(&[("d.csv", text)], &request());
    let experiment = &set.experiments[0];
    let describe = |name: &str| {
        experiment
            .series(name)
            .map(|s| (s.unit.clone(), s.values.clone()))
    };
    assert_eq!(
        describe("u"),
        Some((Some("%".into()), vec![Some(20.9), Some(21.0)]))
    );
    assert_eq!(
        describe("X"),
        Some((Some("ppm".into()), vec![Some(3.0), Some(4.0)]))
    );
    assert_eq!(
        describe("OD"),
        Some((Some("%".into()), vec![None, Some(95.0)]))
    );
    let mapped = read_ok(&[("d.csv", text)], &mapped(&["u=u [%]"]));
    assert_eq!(mapped.experiments[0].series("u").map(|s| s.index), Some(2));
}

#[test]
fn split_unit_cases() {
    let cases = [
        ("X [g/L]", ("X", Some("g/L"))),
        ("X[g/L]", ("X", Some("g/L"))),
        ("X", ("X", None)),
        ("[g/L]", ("[g/L]", None)),
        ("X []", ("X", None)),
        ("CO2 [%] [v/v]", ("CO2 [%]", Some("v/v"))),
    ];
    for (text, expected) in cases {
        assert_eq!(header::split_unit(text), expected, "{text}");
    }
}

#[test]
fn column_mapping_names_time_experiment_and_model_columns() {
    let text = "Batch,Hours [h],Feed,Biomass [g/L],Scatter\nA,0,1,2,7\nB,0,1,3,8\nA,1,1,4,\n";
    let request = mapped(&[
        "X=Biomass",
        "t=Hours",
        "experiment=Batch",
        "u=Feed",
        "OD=Scatter [au]",
    ]);
    let set = read_ok(&[("d.csv", text)], &request);
    assert_eq!(set.names(), vec!["A", "B"]);
    let x: &[Option<f64>] = &[Some(2.0), Some(4.0)];
    let od: &[Option<f64>] = &[Some(7.0), None];
    check_experiment(
        &set,
        "A",
        "d.csv",
        &[0.0, 1.0],
        &[2, 4],
        &[("X", x), ("OD", od)],
    );
    let series = set.experiments[0].series("X");
    assert_eq!(series.map(|s| s.header.as_str()), Some("Biomass [g/L]"));
    assert_eq!(set.experiments[0].time_unit.as_deref(), Some("h"));
    // Matched as written too, unit included.
    let set = read_ok(
        &[("d.csv", "t,u,Biomass [g/L]\n0,0,1\n")],
        &mapped(&["X=Biomass [g/L]"]),
    );
    assert!(set.experiments[0].series("X").is_some());
}

#[test]
fn parse_mapping_splits_at_the_first_equals_sign() {
    assert_eq!(parse_mapping(" X = a=b "), Ok(("X".into(), "a=b".into())));
    for bad in ["X", "=a", "X=", " = "] {
        assert!(parse_mapping(bad).is_err(), "{bad}");
    }
}

#[test]
fn time_header_in_any_case_with_or_without_unit() {
    let some: &[Option<f64>] = &[Some(2.0)];
    for header in ["time", "Time", "TIME [min]", "t", "t [s]"] {
        let text = format!("{header},u,X\n4,1,2\n");
        check_file(&text, &request(), &[4.0], &[("X", some)]);
    }
}

#[test]
fn semicolon_and_tab_files_read_decimal_commas() {
    let x: &[Option<f64>] = &[Some(1.5), Some(-0.25), None];
    let times = [0.0, 0.5, 1.25];
    check_file(
        "t;u;X\n0;1;1,5\n0,5;1;-0,25\n1,25;2;\n",
        &request(),
        &times,
        &[("X", x)],
    );
    check_file(
        "t\tu\tX\n0\t1\t1,5\n0,5\t1\t-0.25\n1.25\t2\tNA\n",
        &request(),
        &times,
        &[("X", x)],
    );
    check_file(
        "t;u;X\r\n0;1;1.5\r\n0.5;1;-2.5e-1\r\n1.25;2;nan\r\n",
        &request(),
        &times,
        &[("X", x)],
    );
}

#[test]
fn quoted_fields_may_hold_the_delimiter_and_quotes() {
    let text = "t,\"note, free\",u,X\n0,\"a, b\",\" 1 \",\"2\"\n1,\"say \"\"hi\"\", then\",1,3\n";
    let x: &[Option<f64>] = &[Some(2.0), Some(3.0)];
    check_file(text, &request(), &[0.0, 1.0], &[("X", x)]);
    let text = "t;\"u;v\";X\n0;\"1,5\";\"2;0\"\n";
    let result = read_files(&[("d.csv", text)], &mapped(&["u=u;v"]));
    let message = result.err().map(|e| e.to_string()).unwrap_or_default();
    assert!(message.contains("found `2;0`"), "{message}");
}

#[test]
fn every_spelling_of_not_measured_is_none() {
    let spellings = [
        "", "NA", "na", "N/A", "n/a", "NaN", "nan", " NA ", "\"\"", "\"NA\"",
    ];
    for spelling in spellings {
        let text = format!("t,u,X\n0,1,1\n1,{spelling},{spelling}\n");
        let values: &[Option<f64>] = &[Some(1.0), None];
        check_file(
            &text,
            &request(),
            &[0.0, 1.0],
            &[("u", values), ("X", values)],
        );
    }
}

#[test]
fn irregular_times_from_any_start_are_accepted() -> TestResult {
    let set = read_ok(
        &[(
            "d.csv",
            "t,u,X\n-3,0,1\n-2.9,0,\n7,0,2\n7.001,0,\n100,0,3\n",
        )],
        &request(),
    );
    let experiment = &set.experiments[0];
    assert_eq!(experiment.times, vec![-3.0, -2.9, 7.0, 7.001, 100.0]);
    assert_eq!(experiment.uniform_step(), None);
    assert!(!experiment.is_complete());
    let series = experiment.series("X").ok_or("no X")?;
    let measured: Vec<(usize, f64)> = series.measured().collect();
    assert_eq!(measured, vec![(0, 1.0), (2, 2.0), (4, 3.0)]);
    let uniform = read_ok(
        &[("d.csv", "t,u,X\n10,0,1\n10.1,0,1\n10.2,0,1\n")],
        &request(),
    );
    let step = uniform.experiments[0].uniform_step().ok_or("uniform")?;
    assert!((step - 0.1).abs() < 1e-12, "{step}");
    assert!(uniform.is_complete());
    let single = read_ok(&[("d.csv", "t,u,X\n0,0,1\n")], &request());
    assert_eq!(single.experiments[0].uniform_step(), None);
    Ok(())
}

#[test]
fn optional_columns_may_be_absent_or_empty_and_are_mapped_where_present() {
    let set = read_ok(
        &[
            ("a.csv", "t,u,X,Scatter\n0,0,1,\n"),
            ("b.csv", "t,u,X\n0,0,1\n"),
        ],
        &mapped(&["OD=Scatter"]),
    );
    let od = set.experiment("a").and_then(|e| e.series("OD"));
    assert_eq!(od.map(|s| s.values.clone()), Some(vec![None]));
    assert!(set.experiment("b").and_then(|e| e.series("OD")).is_none());
}

#[test]
fn inputs_need_only_their_first_row_and_states_one_value() {
    let u: &[Option<f64>] = &[Some(1.0), S, S];
    let x: &[Option<f64>] = &[S, S, Some(3.0)];
    check_file(
        "t,u,X\n0,1,\n1,,\n2,,3\n",
        &request(),
        &[0.0, 1.0, 2.0],
        &[("u", u), ("X", x)],
    );
}

#[test]
fn bom_crlf_blank_lines_around_and_extra_columns() {
    let text = "\u{FEFF}\r\n\r\nt,u,X,note\r\n0,1,2,NaN or text\r\n1,1,3,\r\n\r\n \r\n";
    let set = read_ok(&[("d.csv", text)], &request());
    assert_eq!(set.experiments[0].times, vec![0.0, 1.0]);
    assert_eq!(set.experiments[0].rows, vec![4, 5]);
}

#[test]
fn read_set_reads_files_and_names_experiments_by_stem() -> TestResult {
    let scratch = ScratchDir::new("data-set")?;
    let a = scratch.join("batch 1.csv");
    let b = scratch.join("batch2.tsv");
    std::fs::write(&a, "t,u,X\n0,1,2\n")?;
    std::fs::write(&b, "t\tu\tX\n0\t1\t2,5\n")?;
    let set = read_set(&[a.clone(), b.clone()], &request())?;
    assert_eq!(set.names(), vec!["batch 1", "batch2"]);
    assert_eq!(set.experiments[0].file, a);
    assert_eq!(
        set.experiments[1].series("X").map(|s| s.values.clone()),
        Some(vec![Some(2.5)])
    );
    let missing = read_set(&[a, scratch.join("nope.csv")], &request());
    let message = missing.err().map(|e| e.to_string()).unwrap_or_default();
    assert!(message.contains("nope.csv"), "{message}");
    Ok(())
}

#[test]
fn the_single_record_view_reads_the_new_layouts_but_stays_strict() -> TestResult {
    let dataset = read_str(
        "d.csv",
        "Time [h];u;X [g/L]\n0;1;2,5\n1;1;3\n",
        &["u", "X"],
        2,
    )?;
    assert_eq!(dataset.column("X"), Some(&[2.5, 3.0][..]));
    assert_eq!(dataset.step, 1.0);
    let uneven = read_str(
        "d.csv",
        "t,u,X\n0,0,0\n1,0,0\n2,0,0\n4,0,0\n",
        &["u", "X"],
        2,
    );
    let error = uneven.err().ok_or("expected an error")?;
    assert_eq!(error.location().map(|l| l.row), Some(5));
    assert!(
        error.to_string().contains("expected a time step of 1"),
        "{error}"
    );
    let gappy = read_str("d.csv", "t,u,X\n0,0,1\n1,0,\n", &["u", "X"], 2);
    let error = gappy.err().ok_or("expected an error")?;
    assert_eq!(
        error.code().map(|c| c.to_string()).as_deref(),
        Some("gbm::E0210")
    );
    Ok(())
}

/// A random row: the step from the row before (or from -1), `u` and `X`.
type Row = (f64, Option<f64>, Option<f64>);

/// A data set of random experiments: irregular times, missing cells (never an input's first
/// value, never all of a state), written with `delimiter` and read back.
fn round_trip(
    experiments: &[Vec<Row>],
    delimiter: char,
    missing: &str,
) -> Result<(), proptest::test_runner::TestCaseError> {
    let separator = delimiter.to_string();
    let cell = |value: Option<f64>| match value {
        Some(value) if delimiter != ',' => format_number(value).replace('.', ","),
        Some(value) => format_number(value),
        None => missing.to_string(),
    };
    let mut text = ["experiment", "t", "u", "X"].join(&separator) + "\n";
    for (index, rows) in experiments.iter().enumerate() {
        let mut time = -1.0;
        for &(step, u, x) in rows {
            time += step;
            let line = [format!("e{index}"), cell(Some(time)), cell(u), cell(x)];
            text += &(line.join(&separator) + "\n");
        }
    }
    let set = read_files(&[("d.csv", &text)], &request())
        .map_err(|e| proptest::test_runner::TestCaseError::fail(format!("{e}\n{text}")))?;
    proptest::prop_assert_eq!(set.len(), experiments.len());
    for (experiment, rows) in set.experiments.iter().zip(experiments) {
        let mut time = -1.0;
        let times: Vec<f64> = rows
            .iter()
            .map(|row| {
                time += row.0;
                time
            })
            .collect();
        proptest::prop_assert_eq!(&experiment.times, &times);
        let u: Vec<Option<f64>> = rows.iter().map(|row| row.1).collect();
        let x: Vec<Option<f64>> = rows.iter().map(|row| row.2).collect();
        proptest::prop_assert_eq!(experiment.series("u").map(|s| s.values.clone()), Some(u));
        proptest::prop_assert_eq!(experiment.series("X").map(|s| s.values.clone()), Some(x));
    }
    Ok(())
}

/// A value as a random finite number, or missing.
fn maybe() -> impl proptest::strategy::Strategy<Value = Option<f64>> {
    use proptest::prelude::*;
    prop_oneof![
        1 => Just(None),
        3 => (-1e6..1e6f64).prop_map(Some),
        1 => (proptest::num::f64::NORMAL).prop_map(Some),
    ]
}

proptest::proptest! {
    #[test]
    fn irregular_sets_with_missing_cells_read_back_exactly(
        experiments in proptest::collection::vec(
            proptest::collection::vec((1e-3..10.0f64, maybe(), maybe()), 1..12),
            1..4,
        ),
        delimiter in proptest::sample::select(vec![',', ';', '\t']),
        missing in proptest::sample::select(vec!["", "NA", "nan", "N/A"]),
    ) {
        let mut experiments = experiments;
        for rows in &mut experiments {
            rows[0].1 = rows[0].1.or(Some(0.5));
            if rows.iter().all(|row| row.2.is_none()) {
                rows[0].2 = Some(-2.0);
            }
        }
        round_trip(&experiments, delimiter, missing)?;
    }
}
