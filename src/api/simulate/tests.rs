//! The API's simulation on the chemostat truth model and a decaying state: the spec's
//! fields against the numbers they must give.

use super::*;
use crate::io::ScratchDir;

fn chemostat() -> Model {
    Model::from_file(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/models/mm_chemostat/truth.gbm"
    ))
    .unwrap()
}

fn spec(inputs: &[&str]) -> SimulateSpec {
    SimulateSpec {
        t_end: 10.0,
        dt: Some(0.1),
        inputs: inputs.iter().map(|s| s.to_string()).collect(),
        ..SimulateSpec::default()
    }
}

#[test]
fn sample_times_lose_the_rounding_noise_of_the_grid() {
    assert_eq!(format!("{:?}", round_time(3.0 * 0.1)), "0.3");
    assert_eq!(format!("{:?}", round_time(1799.0)), "1799.0");
    assert_eq!(format!("{:?}", round_time(-2.5e-7)), "-2.5e-7");
}

#[test]
fn a_simulation_has_its_columns_and_writes_them_in_full() {
    let simulation = simulate(&chemostat(), &spec(&["E0=const(0.01)"]), &mut |_| {}).unwrap();
    assert_eq!(simulation.header, ["t", "E0", "S", "P", "r_true"]);
    assert_eq!(simulation.len(), 101);
    assert_eq!(simulation.columns[0][3], 0.3);
    let scratch = ScratchDir::new("api-simulate-csv").unwrap();
    let path = scratch.join("out.csv");
    simulation.write_csv(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let row = text.lines().nth(2).unwrap();
    assert!(row.starts_with("0.1,0.01,"), "{row}");
    let json: serde_json::Value = serde_json::from_str(&simulation.json().unwrap()).unwrap();
    assert_eq!(
        json["columns"][2][0].as_f64(),
        Some(simulation.columns[2][0])
    );
}

#[test]
fn events_report_every_sample_and_a_range_stops_the_run() {
    let decay = Model::from_text("model decay\nstate x = 1\nder x = -x\n", "decay").unwrap();
    let mut asked = spec(&[]);
    let mut events = Vec::new();
    let full = simulate(&decay, &asked, &mut |e| events.push(e)).unwrap();
    let samples = (events.iter())
        .filter(|e| matches!(e, SimulateEvent::Samples { .. }))
        .count();
    assert_eq!((samples, full.len()), (101, 101));
    assert!(!events
        .iter()
        .any(|e| matches!(e, SimulateEvent::Warning(_))));
    asked.ranges = vec![("x".into(), 0.5, f64::INFINITY)];
    events.clear();
    let cut = simulate(&decay, &asked, &mut |e| events.push(e)).unwrap();
    // x = e^-t falls below 0.5 after t = ln 2 = 0.69: the samples up to t = 0.6 stay.
    assert_eq!(cut.len(), 7);
    assert!(events
        .iter()
        .any(|e| matches!(e, SimulateEvent::Warning(_))));
}

#[test]
fn defects_of_the_request_are_reported_with_their_codes() {
    let codes = |asked: &SimulateSpec| {
        let error = simulate(&chemostat(), asked, &mut |_| {}).unwrap_err();
        error
            .records()
            .into_iter()
            .filter_map(|r| r.code)
            .collect::<Vec<_>>()
    };
    assert_eq!(codes(&spec(&[])), ["gbm::E0709"]);
    let twice = spec(&["E0=const(0.01)", "E0=const(0.02)"]);
    assert_eq!(codes(&twice), ["gbm::E0710"]);
    let mut unknown = spec(&["E0=const(0.01)"]);
    unknown.init = vec![("Q".into(), 1.0)];
    assert_eq!(codes(&unknown), ["gbm::E0715"]);
    let mut params = spec(&["E0=const(0.01)"]);
    params.params = Some("/nonexistent/run.json".into());
    assert_eq!(codes(&params), ["gbm::E0716"]);
}
