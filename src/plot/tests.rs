use super::frame::{MARGIN_BOTTOM, MARGIN_LEFT, MARGIN_RIGHT, MARGIN_TOP};
use super::*;

/// The numbers in attribute `name` of every element of kind `tag` (e.g. `"<circle"`).
fn attribute(svg: &str, tag: &str, name: &str) -> Vec<f64> {
    (svg.lines().filter(|l| l.starts_with(tag)))
        .filter_map(|l| l.split(&format!(" {name}=\"")).nth(1))
        .filter_map(|rest| rest.split('"').next()?.parse().ok())
        .collect()
}

/// The line that draws text `content`.
fn text_line<'a>(svg: &'a str, content: &str) -> &'a str {
    (svg.lines())
        .find(|l| l.starts_with("<text") && l.ends_with(&format!(">{content}</text>")))
        .unwrap_or_default()
}

/// The number in attribute `name` of one element's line.
fn number(line: &str, name: &str) -> f64 {
    attribute(line, "<", name)
        .first()
        .copied()
        .unwrap_or(f64::NAN)
}

/// The right edge of the plot area (its border rectangle).
fn plot_right(svg: &str) -> f64 {
    let border = (svg.lines())
        .find(|l| l.starts_with("<rect x=") && l.contains(r#"fill="none""#))
        .unwrap_or_default();
    number(border, "x") + number(border, "width")
}

#[test]
fn linear_ticks_are_round_and_cover_the_range() {
    assert_eq!(
        linear_ticks(0.0, 10.0, 5),
        vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
    );
    let ticks = linear_ticks(0.013, 0.047, 4);
    assert!(ticks.iter().all(|t| (0.013..=0.047).contains(t)));
    assert!((ticks[1] - ticks[0] - 0.01).abs() < 1e-12, "{ticks:?}");
}

#[test]
fn log_ticks_are_decades() {
    assert_eq!(log_ticks(0.003, 20.0), vec![0.01, 0.1, 1.0, 10.0]);
    // No range, no ticks (not 2^31 decades).
    assert!(log_ticks(0.0, 1.0).is_empty() && log_ticks(1.0, f64::INFINITY).is_empty());
    // Within about a decade: 1, 2 and 5 times the decades.
    assert_eq!(log_ticks(2.1, 42.6), vec![5.0, 10.0, 20.0]);
    let narrow = log_ticks(3.1, 3.9);
    assert!(narrow.len() >= 2 && narrow.iter().all(|t| (3.1..=3.9).contains(t)));
}

#[test]
fn points_map_inside_the_plot_area() {
    let chart = Chart::new("t", "x", "y").with(Series::line("a", vec![(0.0, 1.0), (10.0, 3.0)]));
    let svg = chart.to_svg(400.0, 300.0);
    let polyline = (svg.lines())
        .find(|l| l.starts_with("<polyline"))
        .unwrap_or_default();
    let numbers: Vec<f64> = (polyline.split(['"', ' ', ',']))
        .filter_map(|s| s.parse().ok())
        .collect();
    assert_eq!(numbers.len(), 5, "{polyline}"); // 4 coordinates and the stroke width
    let (x0, y0, x1, y1) = (numbers[0], numbers[1], numbers[2], numbers[3]);
    assert!(x0 > MARGIN_LEFT && x1 < 400.0 - MARGIN_RIGHT && x0 < x1);
    assert!(y0 > y1, "larger values are drawn higher");
    assert!(y0 < 300.0 - MARGIN_BOTTOM && y1 > MARGIN_TOP);
}

#[test]
fn log_axes_drop_non_positive_values_and_text_is_escaped() {
    let chart = Chart::new("a < b & c", "x", "y")
        .with(Series::line(
            "s",
            vec![(1.0, 0.0), (10.0, 1.0), (100.0, 10.0)],
        ))
        .log_axes(true, true);
    let svg = chart.to_svg(300.0, 200.0);
    assert!(svg.contains("a &lt; b &amp; c"));
    let polyline = (svg.lines())
        .find(|l| l.starts_with("<polyline"))
        .unwrap_or_default();
    assert_eq!(
        polyline.matches(',').count(),
        2,
        "two valid points: {polyline}"
    );
}

/// Both axis titles are drawn inside the figure: the x title under the plot area, the y
/// title (turned a quarter) beside its middle.
#[test]
fn axis_titles_lie_inside_the_figure() {
    let chart = Chart::new("", "t [h]", "X [g/L]").with(Series::line("a", vec![(0.0, 1.0)]));
    let (width, height) = (400.0, 300.0);
    let svg = chart.to_svg(width, height);
    let x_title = text_line(&svg, "t [h]");
    assert!(number(x_title, "y") > height - MARGIN_BOTTOM + 14.0 && number(x_title, "y") < height);
    let y_title = text_line(&svg, "X [g/L]");
    let middle = (MARGIN_TOP + height - MARGIN_BOTTOM) / 2.0;
    assert_eq!(number(y_title, "y"), middle);
    assert!(y_title.contains(&format!("rotate(-90 14 {middle:.1})")));
}

/// The legend stands right of the plot area: every legend element starts beyond its
/// border; a dashed series is keyed by a dashed sample, markers by a dot.
#[test]
fn legends_sit_right_of_the_data_and_key_each_style() {
    let chart = Chart::new("t", "x", "y")
        .with(Series::line("solid", vec![(0.0, 1.0), (1.0, 2.0)]))
        .with(Series::line("dashed", vec![(0.0, 2.0), (1.0, 1.0)]).styled(Style::Dashed))
        .with(Series::line("dots", vec![(0.5, 1.5)]).styled(Style::Markers));
    let svg = chart.to_svg(640.0, 300.0);
    let right = plot_right(&svg);
    for name in ["solid", "dashed", "dots"] {
        assert!(number(text_line(&svg, name), "x") > right, "{name}");
    }
    let samples: Vec<&str> = (svg.lines())
        .filter(|l| l.starts_with("<line") && number(l, "x1") > right)
        .collect();
    assert_eq!(samples.len(), 2, "{samples:?}");
    assert!(!samples[0].contains("dasharray") && samples[1].contains("dasharray"));
    let dots: Vec<f64> = attribute(&svg, "<circle", "cx");
    assert_eq!(dots.len(), 2, "the data point and its legend sample");
    assert!(dots[0] < right && dots[1] > right);
}

/// A name longer than a legend line wraps at spaces, and no legend text runs past the
/// figure's edge.
#[test]
fn long_legend_names_wrap_inside_the_figure() {
    let long = "with product_decay + product_inhibition + substrate_inhibition";
    let chart = Chart::new("t", "x", "y").with(Series::line(long, vec![(0.0, 1.0), (1.0, 2.0)]));
    let width = 640.0;
    let svg = chart.to_svg(width, 300.0);
    let right = plot_right(&svg);
    let lines: Vec<&str> = (svg.lines())
        .filter(|l| l.starts_with("<text") && number(l, "x") > right)
        .collect();
    assert!(lines.len() >= 2, "{lines:?}");
    for line in lines {
        let content = (line.split_once('>'))
            .and_then(|(_, rest)| rest.strip_suffix("</text>"))
            .unwrap_or_default();
        assert!(
            !line.contains("textLength"),
            "wrapped, not squeezed: {line}"
        );
        let end = number(line, "x") + 6.5 * content.chars().count() as f64;
        assert!(end <= width, "{line}");
    }
}

/// A mark stands across the whole plot at its x, keyed in the legend, and leaves the y
/// axis to the data; `including_y` widens it.
#[test]
fn marks_span_the_plot_and_y_can_include_zero() {
    let data = Series::line("a", vec![(0.0, 10.0), (4.0, 12.0)]);
    let chart =
        Chart::new("t", "x", "y")
            .with(data)
            .with_mark("held out from", 3.0, Style::Dashed, "#444");
    let svg = chart.to_svg(640.0, 300.0);
    let mark = (svg.lines())
        .find(|l| l.starts_with("<line") && l.contains(r##"stroke="#444""##))
        .unwrap_or_default();
    assert!(mark.contains("dasharray"), "{mark}");
    assert_eq!(number(mark, "y1"), MARGIN_TOP);
    assert_eq!(number(mark, "y2"), 300.0 - MARGIN_BOTTOM);
    assert!(svg.contains(">held out from</text>"));
    let y_ticks = |svg: &str| -> Vec<f64> {
        (svg.lines())
            .filter(|l| l.starts_with("<text") && l.contains(r#"text-anchor="end""#))
            .filter_map(|l| {
                l.rsplit_once("\">")
                    .and_then(|(_, t)| t.strip_suffix("</text>"))
            })
            .filter_map(|t| t.parse().ok())
            .collect()
    };
    assert!(
        y_ticks(&svg).iter().all(|t| *t >= 9.0),
        "{:?}",
        y_ticks(&svg)
    );
    let zero = chart.including_y(0.0).to_svg(640.0, 300.0);
    assert!(y_ticks(&zero).contains(&0.0), "{:?}", y_ticks(&zero));
}

#[test]
fn markers_take_the_series_radius() {
    let dots = Series::line("d", vec![(0.0, 1.0), (1.0, 2.0)]).styled(Style::Markers);
    let svg = Chart::new("", "", "")
        .with(dots.sized(1.5))
        .to_svg(400.0, 300.0);
    let radii = attribute(&svg, "<circle", "r");
    assert_eq!(radii[..2], [1.5, 1.5]);
    assert!(radii[2] >= 2.5, "the legend's dot stays visible: {radii:?}");
}

#[test]
fn titles_too_long_for_the_figure_are_squeezed_into_it() {
    let title = "x".repeat(200);
    let svg = Chart::new(&title, "", "").to_svg(400.0, 300.0);
    assert!(text_line(&svg, &title).contains(r#"textLength="380""#));
    let short = Chart::new("short", "", "").to_svg(400.0, 300.0);
    assert!(!text_line(&short, "short").contains("textLength"));
}

#[test]
fn bars_have_one_rect_per_finite_value() {
    let bars = BarChart {
        title: "gap".into(),
        y_label: "MSE".into(),
        categories: vec!["before".into(), "after".into()],
        groups: vec![("gap".into(), vec![1.0, 0.2])],
    };
    let svg = bars.to_svg(300.0, 200.0);
    assert_eq!(svg.matches("<rect x=").count(), 3, "frame + two bars");
    // Category names label the x axis; no numeric ticks sit under them.
    let x_labels: Vec<&str> = (svg.lines())
        .filter(|l| l.contains(r#"text-anchor="middle">"#) && !l.contains("font-size"))
        .filter(|l| !l.contains("></text>"))
        .collect();
    assert_eq!(x_labels.len(), 2, "{x_labels:?}");
    assert!(x_labels[0].contains(">before<") && x_labels[1].contains(">after<"));
}

/// On a log axis a bar's length grows with the logarithm of its value: one decade is the
/// same length anywhere; a value the axis cannot show gets its text but no bar; every
/// text after a bar stays inside the figure.
#[test]
fn horizontal_log_bars_measure_decades_and_keep_their_texts_inside() {
    let bars = Bars {
        title: String::new(),
        value_label: "gap (log)".into(),
        log: true,
        rows: vec![
            Bar::new("before", 1.0, "#c0392b", "1.00"),
            Bar::new("after", 0.1, "#2471a3", "0.100 -90 %"),
            Bar::new("floor", 0.01, "#888", "0.0100"),
            Bar::new("lost", f64::INFINITY, "#888", "diverged"),
        ],
    };
    let width = 640.0;
    let svg = bars.to_svg(width);
    assert!(svg.contains(&format!(r#"height="{}""#, bars.height())));
    let lengths: Vec<f64> = (svg.lines())
        .filter(|l| l.starts_with("<rect x=") && l.contains("fill=\"#"))
        .filter(|l| !l.contains(r#"fill="none""#))
        .map(|l| number(l, "width"))
        .collect();
    assert_eq!(
        lengths.len(),
        3,
        "no bar for the infinite value: {lengths:?}"
    );
    let decade = lengths[0] - lengths[1];
    assert!(decade > 20.0 && (lengths[1] - lengths[2] - decade).abs() < 0.2);
    assert!(lengths[2] > 5.0, "the smallest bar is visible");
    for text in ["1.00", "0.100 -90 %", "0.0100", "diverged"] {
        let line = text_line(&svg, text);
        let end = number(line, "x") + 6.5 * text.chars().count() as f64;
        assert!(end <= width, "{line}");
    }
    let bar_start = attribute(&svg, "<rect x=", "x")
        .last()
        .copied()
        .unwrap_or_default();
    let labels = ["before", "after", "floor", "lost"].map(|l| number(text_line(&svg, l), "x"));
    assert!(
        labels.iter().all(|x| *x > 0.0 && *x < bar_start),
        "{labels:?}"
    );
}

#[test]
fn long_series_are_thinned_to_every_kth_point_and_the_last() {
    let short: Vec<(f64, f64)> = (0..MAX_POINTS).map(|i| (i as f64, 0.0)).collect();
    assert_eq!(thin(short.clone(), MAX_POINTS), short);
    let long: Vec<(f64, f64)> = (0..2 * MAX_POINTS + 1).map(|i| (i as f64, 0.0)).collect();
    let kept = thin(long, MAX_POINTS);
    assert!(kept.len() <= MAX_POINTS + 1, "{}", kept.len());
    assert_eq!(kept.first().map(|p| p.0), Some(0.0));
    assert_eq!(kept.last().map(|p| p.0), Some(2.0 * MAX_POINTS as f64));
    assert!(kept.windows(2).all(|w| w[1].0 - w[0].0 <= 3.0));
}

#[test]
fn runaway_trajectories_are_clipped_to_the_data_window_and_say_so() {
    let range = widened_range(&[1.0, 3.0, f64::NAN]);
    assert_eq!(range, (0.0, 4.0));
    assert_eq!(widened_range(&[2.0]), (1.0, 3.0));
    let nothing = widened_range(&[f64::NAN]);
    assert_eq!(nothing, (f64::NEG_INFINITY, f64::INFINITY));
    let (_, kept) = clip("no data", [(0.0, 1e9)].into_iter(), nothing);
    assert_eq!(kept, vec![(0.0, 1e9)]);
    let points = [
        (0.0, 2.0),
        (1.0, 9.0),
        (2.0, f64::NEG_INFINITY),
        (3.0, f64::NAN),
    ];
    let (name, clipped) = clip("bb", points.into_iter(), range);
    assert_eq!(name, "bb (clipped)");
    assert_eq!(clipped, vec![(0.0, 2.0), (1.0, 4.0), (2.0, 0.0)]);
    let (name, kept) = clip("gb", [(0.0, 1.5)].into_iter(), range);
    assert_eq!((name.as_str(), kept), ("gb", vec![(0.0, 1.5)]));
}

#[test]
fn axis_titles_carry_units() {
    assert_eq!(titled("X", Some("g/L")), "X [g/L]");
    assert_eq!(titled("u", None), "u");
    assert_eq!(titled("u", Some("")), "u");
}

#[test]
fn figures_escape_their_captions() {
    assert_eq!(
        figure("<svg/>", "a < b"),
        "<figure><svg/><figcaption>a &lt; b</figcaption></figure>\n"
    );
    assert_eq!(figure("<svg/>", ""), "<figure><svg/></figure>\n");
    assert_eq!(escape("a<b & \"c\">"), "a&lt;b &amp; &quot;c&quot;&gt;");
}

/// A band is one polygon: the upper edge left to right, then the lower edge back; points
/// whose band cannot be drawn (NaN) are left out.
#[test]
fn bands_run_along_the_upper_edge_and_back_along_the_lower() {
    let series = Series::line("m", vec![(0.0, 2.0), (1.0, 2.0), (2.0, 2.0)]).with_band(vec![
        (1.0, 3.0),
        (f64::NAN, 3.0),
        (1.0, 3.0),
    ]);
    let svg = Chart::new("", "", "").with(series).to_svg(400.0, 300.0);
    let polygon = (svg.lines())
        .find(|l| l.starts_with("<polygon"))
        .unwrap_or_default();
    let corners: Vec<(f64, f64)> = (polygon.split('"').nth(1).unwrap_or_default())
        .split(' ')
        .filter_map(|p| p.split_once(','))
        .filter_map(|(a, b)| Some((a.parse().ok()?, b.parse().ok()?)))
        .collect();
    assert_eq!(corners.len(), 4, "{polygon}");
    assert!(corners[0].0 < corners[1].0 && corners[2].0 > corners[3].0);
    assert_eq!(corners[1].0, corners[2].0);
    assert!(
        corners[0].1 < corners[3].1,
        "the upper edge is drawn higher"
    );
}

/// A named band gets its own legend entry, a shaded box right of the plot after its
/// series' line; an unnamed one gets none.
#[test]
fn a_named_band_is_keyed_by_a_shaded_box_in_the_legend() {
    let points = vec![(0.0, 2.0), (1.0, 2.0)];
    let band = vec![(1.0, 3.0), (1.0, 3.0)];
    let named = Series::line("median", points.clone()).with_named_band(band.clone(), "90 % band");
    let svg = Chart::new("", "", "").with(named).to_svg(500.0, 300.0);
    let label = (svg.lines())
        .position(|l| l.contains(">90 % band<"))
        .unwrap_or_else(|| panic!("no band entry in {svg}"));
    let sample = svg.lines().nth(label - 1).unwrap_or_default();
    assert!(
        sample.starts_with("<rect") && sample.contains("fill-opacity"),
        "{sample}"
    );
    let x = |line: &str| -> f64 {
        let at = line.find(" x=\"").map_or(line.len(), |i| i + 4);
        line[at..]
            .split('"')
            .next()
            .unwrap_or("")
            .parse()
            .unwrap_or(f64::NAN)
    };
    let polygon = svg
        .lines()
        .find(|l| l.starts_with("<polygon"))
        .unwrap_or_default();
    let rightmost = (polygon.split('"').nth(1).unwrap_or_default().split(' '))
        .filter_map(|p| p.split_once(',').and_then(|(a, _)| a.parse::<f64>().ok()))
        .fold(f64::MIN, f64::max);
    assert!(
        x(sample) > rightmost,
        "the sample {sample} stands right of the band"
    );
    let median = svg.lines().position(|l| l.contains(">median<")).unwrap();
    assert!(median < label, "the band's entry follows its series'");
    let plain = Series::line("median", points).with_band(band);
    let svg = Chart::new("", "", "").with(plain).to_svg(500.0, 300.0);
    let samples = (svg.lines()).filter(|l| l.starts_with("<rect") && l.contains("fill-opacity"));
    assert_eq!(samples.count(), 0, "no sample for an unnamed band");
    assert_eq!(
        svg.matches("fill-opacity").count(),
        1,
        "the band itself only"
    );
}

/// A text after a bar as long as the plot is wide leaves the bars their share of it: the
/// axis stays finite (it once stretched to infinity and asked for 2^31 ticks).
#[test]
fn a_very_long_bar_text_keeps_a_finite_axis() {
    let long = "0.155 not credited, BIC -279 + 6 (refits) ".repeat(4);
    let bars = Bars {
        title: String::new(),
        value_label: "gap (log)".into(),
        log: true,
        rows: vec![
            Bar::new("before", 0.248, "#c0392b", &long),
            Bar::new("after", 0.0044, "#2471a3", &long),
        ],
    };
    let svg = bars.to_svg(640.0);
    assert!(!svg.contains("inf") && !svg.contains("NaN"), "{svg}");
    assert!(svg.contains(">0.01<") || svg.contains(">0.1<"), "{svg}");
}
