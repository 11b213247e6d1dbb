//! The training data and its inputs (paper Fig. 2a / 3a): each measured state of the
//! study's record over time and each input programme, with the row where validation starts
//! marked, so a reader sees what the models were given before reading how they did.

use super::figure::{axis_titles, color, Figure, HEIGHT, WIDTH};
use super::prepare::Prepared;
use super::study::Validation;
use crate::plot::{thin, Chart, Series, Style, DATA_COLOR, MAX_POINTS};

/// Colour of the validation rows and of the mark where they start.
const VALIDATION_COLOR: &str = crate::plot::SPLIT_COLOR;

/// One figure per measured state and one of the inputs, over the whole record (empty on a
/// data set, whose held-out figures show each experiment).
pub fn data_figures(prepared: &Prepared) -> Vec<Figure> {
    let Some(first) = prepared.models.first() else {
        return Vec::new();
    };
    if prepared.study.on_data_set() {
        return Vec::new();
    }
    let record = &prepared.validation_source;
    // Where validation starts: a row of the training file, or (validating on another file)
    // nowhere in it.
    let split = match prepared.study.validation {
        Validation::FromRow(row) => record.times.get(row).copied(),
        _ => None,
    };
    let name = &prepared.study.name;
    let source = record.path.display().to_string();
    let mut figures = Vec::new();
    for state in &first.model.states {
        let Some(values) = record.column(&state.name) else {
            continue;
        };
        let (time, axis) = axis_titles(prepared, &state.name);
        let points: Vec<(f64, f64)> = record
            .times
            .iter()
            .copied()
            .zip(values.iter().copied())
            .collect();
        let chart = split_chart(
            Chart::new(&format!("{name}: data, {}", state.name), &time, &axis),
            points,
            split,
        );
        figures.push(Figure {
            name: format!("data_{}", state.name),
            caption: format!(
                "The measured {} of {source} (paper Fig. 2a/3a): the rows before the mark \
                 train (each run takes its training pairs from them), the rows after it \
                 validate.",
                state.name
            ),
            svg: chart.to_svg(WIDTH, HEIGHT),
        });
    }
    if let Some(figure) = input_figure(prepared, split) {
        figures.push(figure);
    }
    figures
}

/// The inputs of the first model, one line each, held between samples as the models see
/// them (zero-order hold).
fn input_figure(prepared: &Prepared, split: Option<f64>) -> Option<Figure> {
    let first = prepared.models.first()?;
    let record = &prepared.validation_source;
    let names: Vec<&str> = (first.model.inputs.iter())
        .map(|input| input.name.as_str())
        .filter(|name| record.column(name).is_some())
        .collect();
    let (time, axis) = match names.as_slice() {
        [] => return None,
        [only] => axis_titles(prepared, only),
        _ => (axis_titles(prepared, names[0]).0, "inputs".to_string()),
    };
    let list = names.join(", ");
    let title = format!("{}: input {list}", prepared.study.name);
    let mut chart = Chart::new(&title, &time, &axis);
    for (index, name) in names.iter().enumerate() {
        let values = record.column(name)?;
        let mut held = Vec::with_capacity(2 * values.len());
        for (row, (&t, &v)) in record.times.iter().zip(values).enumerate() {
            if row > 0 {
                held.push((t, values[row - 1]));
            }
            held.push((t, v));
        }
        let series = Series::line(name, thin(held, 2 * MAX_POINTS)).colored(color(index));
        chart = chart.with(series);
    }
    if let Some(x) = split {
        chart = chart.with_mark("validation starts", x, Style::Dashed, VALIDATION_COLOR);
    }
    Some(Figure {
        name: "data_inputs".to_string(),
        caption: format!(
            "The input {list} the record was driven by, held between samples as the models \
             hold it (paper Fig. 2a/3a); the dashed line marks where validation starts."
        ),
        svg: chart.to_svg(WIDTH, HEIGHT),
    })
}

/// `points` drawn black up to `split` and grey from it, with the split marked.
fn split_chart(chart: Chart, points: Vec<(f64, f64)>, split: Option<f64>) -> Chart {
    let Some(x) = split else {
        return chart.with(Series::line("data", thin(points, MAX_POINTS)).colored(DATA_COLOR));
    };
    let at = points.partition_point(|&(t, _)| t < x);
    // The validation line starts at the last training sample so the two join.
    let (training, validation) = (
        points[..at].to_vec(),
        points[at.saturating_sub(1)..].to_vec(),
    );
    chart
        .with(Series::line("training rows", thin(training, MAX_POINTS)).colored(DATA_COLOR))
        .with(
            Series::line("validation rows", thin(validation, MAX_POINTS)).colored(VALIDATION_COLOR),
        )
        .with_mark("validation starts", x, Style::Dashed, VALIDATION_COLOR)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The record is cut where validation starts: training rows before, validation rows
    /// from the last training sample on (so the line is unbroken), the mark at the split.
    #[test]
    fn the_record_is_drawn_split_where_validation_starts() {
        let points: Vec<(f64, f64)> = (0..10).map(|i| (i as f64, (i * i) as f64)).collect();
        let chart = split_chart(Chart::new("t", "x", "y"), points.clone(), Some(4.0));
        let [training, validation] = chart.series.as_slice() else {
            panic!("two series: {:?}", chart.series);
        };
        assert_eq!(training.points, points[..4]);
        assert_eq!(validation.points, points[3..]);
        assert_eq!((chart.marks.len(), chart.marks[0].x), (1, 4.0));
        // Validating on another file: one series, no mark.
        let whole = split_chart(Chart::new("t", "x", "y"), points.clone(), None);
        assert_eq!((whole.series.len(), whole.marks.len()), (1, 0));
        assert_eq!(whole.series[0].points, points);
    }

    /// The chemostat preset: one figure per measured state and one of the input, axes
    /// titled with units, captions in plain text (they are escaped into HTML, so markdown
    /// backticks would show as written).
    #[test]
    fn the_shipped_record_has_a_figure_per_state_and_input() {
        let prepared = crate::experiment::prepare(&crate::experiment::Study::chemostat())
            .expect("the chemostat preset loads");
        let figures = data_figures(&prepared);
        let names: Vec<&str> = figures.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["data_S", "data_inputs"]);
        for figure in &figures {
            assert!(figure.svg.contains("time [s]"), "{}", figure.name);
            assert!(!figure.caption.contains('`'), "{}", figure.caption);
            if figure.name == "data_S" {
                assert!(figure
                    .caption
                    .contains("models/mm_chemostat/data/steps.csv"));
                assert!(figure.svg.contains("[mol/L]"), "{}", figure.name);
            }
        }
    }
}
