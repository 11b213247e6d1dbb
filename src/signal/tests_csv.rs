//! `csv(...)` programs: a data file's input column read as any record's input.

use super::tests::{check_error, code_of, generate, input, unit, TestResult};
use crate::io::ScratchDir;
use miette::Diagnostic;

#[test]
fn csv_program_holds_the_named_column() -> TestResult {
    let scratch = ScratchDir::new("signal-csv")?;
    let path = scratch.join("inputs.csv");
    std::fs::write(&path, "t,u,light\n0,0.1,1\n2,0.4,0\n4,0.9,1\n6,0.3,0\n")?;
    let name = path.display();
    let signal = generate(&format!("u=csv({name})"), &unit(), 7.0, 1.0)?;
    assert_eq!(signal.breaks, vec![0.0, 2.0, 4.0, 6.0]);
    assert_eq!(
        signal.sample(&[0.0, 1.9, 2.0, 5.0, 7.5]),
        vec![0.1, 0.1, 0.4, 0.9, 0.3]
    );
    let light = generate(&format!("u=csv(\"{name}\", light)"), &unit(), 7.0, 1.0)?;
    assert_eq!(light.values, vec![1.0, 0.0, 1.0, 0.0]);
    let error = generate(&format!("u=csv({name})"), &unit(), 9.0, 1.0).err();
    assert_eq!(
        error.as_ref().map(|e| code_of(e)).as_deref(),
        Some("gbm::E0314")
    );
    let error = generate(
        &format!("w=csv(file={name}, column=w)"),
        &input("w", None),
        6.0,
        1.0,
    )
    .err();
    let message = error.as_ref().map(|e| e.to_string()).unwrap_or_default();
    assert!(message.contains("expected a column `w`"), "{message}");
    assert_eq!(
        error.as_ref().map(|e| code_of(e)).as_deref(),
        Some("gbm::E0208")
    );
    let error = generate(
        &format!("u=csv({})", scratch.join("none.csv").display()),
        &unit(),
        6.0,
        1.0,
    )
    .err();
    assert_eq!(
        error.as_ref().map(|e| code_of(e)).as_deref(),
        Some("gbm::E0201")
    );
    Ok(())
}

#[test]
fn csv_values_outside_bounds_name_the_row() -> TestResult {
    let scratch = ScratchDir::new("signal-csv-bounds")?;
    let path = scratch.join("u.csv");
    std::fs::write(&path, "t,u\n0,0.1\n1,1.5\n2,0.3\n")?;
    let error = generate(&format!("u=csv({})", path.display()), &unit(), 2.0, 1.0).err();
    let message = error.as_ref().map(|e| e.to_string()).unwrap_or_default();
    assert!(message.contains("found 1.5 in"), "{message}");
    assert!(message.contains("row 3"), "{message}");
    Ok(())
}

#[test]
fn csv_reads_any_time_grid_and_holds_empty_cells() -> TestResult {
    let scratch = ScratchDir::new("signal-csv-irregular")?;
    let path = scratch.join("lab.csv");
    let text = "t [h],u [-],OD\n0,0.1,3\n0.5,,4\n2,0.4,\n2.25,NA,5\n7,0.4,6\n9.5,0.9,\n";
    std::fs::write(&path, text)?;
    let signal = generate(&format!("u=csv({})", path.display()), &unit(), 10.0, 1.0)?;
    assert_eq!(
        signal.breaks,
        vec![0.0, 2.0, 9.5],
        "a break only at each change"
    );
    assert_eq!(signal.values, vec![0.1, 0.4, 0.9]);
    assert_eq!(
        signal.sample(&[0.7, 1.99, 2.1, 8.0, 9.6]),
        vec![0.1, 0.1, 0.4, 0.4, 0.9]
    );
    let short = generate(&format!("u=csv({})", path.display()), &unit(), 13.0, 1.0).err();
    assert_eq!(
        short.as_ref().map(|e| code_of(e)).as_deref(),
        Some("gbm::E0314")
    );
    Ok(())
}

#[test]
fn csv_needs_a_value_at_the_first_row() -> TestResult {
    let scratch = ScratchDir::new("signal-csv-first")?;
    let path = scratch.join("late.csv");
    std::fs::write(&path, "t,u\n0,\n1,0.5\n")?;
    let error = generate(&format!("u=csv({})", path.display()), &unit(), 2.0, 1.0)
        .err()
        .ok_or("expected an error")?;
    assert_eq!(code_of(&error), "gbm::E0222", "{error}");
    assert!(error.to_string().contains("row 2"), "{error}");
    let help = error.help().map(|h| h.to_string()).unwrap_or_default();
    assert!(help.contains("first row"), "{help}");
    Ok(())
}

#[test]
fn csv_picks_one_experiment_of_a_file_that_has_several() -> TestResult {
    let scratch = ScratchDir::new("signal-csv-experiments")?;
    let path = scratch.join("runs.csv");
    let text = "experiment,t,u\nbatch1,0,0.1\nbatch1,5,0.2\nbatch2,0,0.7\nbatch2,1,\n\
                batch2,3,0.3\n";
    std::fs::write(&path, text)?;
    let file = path.display().to_string();
    let chosen = generate(&format!("u=csv({file}, u, batch2)"), &unit(), 4.0, 1.0)?;
    assert_eq!(
        (chosen.breaks, chosen.values),
        (vec![0.0, 3.0], vec![0.7, 0.3])
    );
    let keyed = generate(
        &format!("u=csv({file}, experiment=batch1)"),
        &unit(),
        6.0,
        1.0,
    )?;
    assert_eq!(keyed.values, vec![0.1, 0.2]);
    check_error(&format!("u=csv({file})"), &unit(), "gbm::E0319", &file);
    let error = generate(&format!("u=csv({file})"), &unit(), 4.0, 1.0)
        .err()
        .ok_or("expected an error")?;
    assert!(
        error.to_string().contains("found 2: `batch1`, `batch2`"),
        "{error}"
    );
    let help = error.help().map(|h| h.to_string()).unwrap_or_default();
    assert!(help.contains("experiment=batch1"), "{help}");
    check_error(
        &format!("u=csv({file}, experiment=batch3)"),
        &unit(),
        "gbm::E0320",
        "batch3",
    );
    let error = generate(&format!("u=csv({file}, u, batch3)"), &unit(), 4.0, 1.0)
        .err()
        .ok_or("expected an error")?;
    let help = error.help().map(|h| h.to_string()).unwrap_or_default();
    assert!(help.contains("`batch1`, `batch2`"), "{help}");
    let single = scratch.join("one.csv");
    std::fs::write(&single, "experiment,t,u\nonly,0,0.5\nonly,1,0.6\n")?;
    let signal = generate(&format!("u=csv({})", single.display()), &unit(), 2.0, 1.0)?;
    assert_eq!(
        signal.values,
        vec![0.5, 0.6],
        "one experiment needs no choice"
    );
    let by_stem = generate(
        &format!("u=csv({}, u, one)", single.display()),
        &unit(),
        2.0,
        1.0,
    );
    assert_eq!(
        by_stem.err().map(|e| code_of(&e)).as_deref(),
        Some("gbm::E0320"),
        "the experiment column names it, not the stem"
    );
    Ok(())
}
