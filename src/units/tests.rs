use super::*;

fn unit(text: &str) -> Unit {
    Unit::parse(text).unwrap_or_else(|| panic!("`{text}` is a unit"))
}

#[test]
fn written_forms_of_one_unit_are_equal() {
    let cases = [
        ("g/L", "g L^-1"),
        ("g/L", "g*L^-1"),
        ("mol/L/s", "mol/(L s)"),
        ("mol/L/s", "mol L^-1 s^-1"),
        ("1/h", "h^-1"),
        ("-", "g/g"),
        ("-", "1"),
        ("L", "dm^3"),
        ("g/L", "mg/mL"),
        ("kg", "kg g/g"),
    ];
    for (a, b) in cases {
        assert_eq!(unit(a).compare(&unit(b)), Comparison::Equal, "{a} vs {b}");
    }
}

#[test]
fn scale_mismatches_carry_the_factor() {
    let cases = [
        ("g/L", "mg/L", 1000.0),
        ("mg/L", "g/L", 1e-3),
        ("1/min", "1/h", 60.0),
        ("h", "min", 60.0),
        ("d", "h", 24.0),
        ("L", "mL", 1000.0),
        ("m^3", "L", 1000.0),
        ("umol", "mol", 1e-6),
    ];
    for (a, b, factor) in cases {
        match unit(a).compare(&unit(b)) {
            Comparison::Scale(ratio) => {
                assert!((ratio / factor - 1.0).abs() < 1e-12, "{a} vs {b}: {ratio}")
            }
            other => panic!("{a} vs {b}: {other:?}"),
        }
    }
}

#[test]
fn different_dimensions_are_incompatible() {
    for (a, b) in [("g/L", "mol/L"), ("1/h", "-"), ("g", "g/L"), ("K", "s")] {
        assert_eq!(
            unit(a).compare(&unit(b)),
            Comparison::Incompatible,
            "{a} vs {b}"
        );
    }
}

#[test]
fn canonical_text_orders_factors_and_parses_back() {
    let cases = [
        ("L^-1 g", "g/L"),
        ("s^-1 L^-1 mol", "mol/L/s"),
        ("h^-1", "1/h"),
        ("g/g", "-"),
        ("m^2 s^-2", "m^2/s^2"),
        ("g mg", "mg g"),
        ("µg/L", "ug/L"),
    ];
    for (written, canonical) in cases {
        let text = unit(written).to_string();
        assert_eq!(text, canonical, "{written}");
        assert_eq!(unit(&text), unit(written), "{text} parses back");
    }
}

#[test]
fn products_powers_and_roots() {
    let rate = unit("1/h").mul(&unit("g/L"));
    assert!(rate.same(&unit("g/L/h")));
    assert!(unit("g/L").div(&unit("g/L")).is_one());
    assert_eq!(unit("mol/L").powi(2).powf(0.5), Some(unit("mol/L")));
    let root = unit("mol/L").powf(0.5).expect("representable");
    assert_eq!(root.to_string(), "mol^0.5/L^0.5");
    assert!(root.powi(2).same(&unit("mol/L")));
    let hill = unit("g/L").powf(2.7).expect("representable");
    assert!(hill.div(&unit("g/L").powf(2.7).expect("same")).is_one());
    assert_eq!(unit("g").powf(1.0 / 7.0), None);
    assert!(unit("h/min").is_dimensionless());
    assert_eq!(
        unit("h/min").compare(&Unit::dimensionless()),
        Comparison::Scale(60.0)
    );
}

#[test]
fn symbols_with_prefixes() {
    let read = |text: &str| Symbol::parse(text).map(|s| (s.prefix, s.base));
    assert_eq!(read("min"), Some((None, Base::Minute)));
    assert_eq!(read("mmol"), Some((Some(Prefix::Milli), Base::Mole)));
    assert_eq!(read("mol"), Some((None, Base::Mole)));
    assert_eq!(read("d"), Some((None, Base::Day)));
    assert_eq!(read("dL"), Some((Some(Prefix::Deci), Base::Litre)));
    assert_eq!(read("µm"), Some((Some(Prefix::Micro), Base::Metre)));
    assert_eq!(read("kg"), Some((Some(Prefix::Kilo), Base::Gram)));
    for unknown in ["mh", "kmin", "gram", "l", "x", "Lx"] {
        assert_eq!(read(unknown), None, "{unknown}");
    }
}

#[test]
fn factors_and_conversions_in_words() {
    assert_eq!(format_factor(1000.0), "1000");
    assert_eq!(format_factor(60.0), "60");
    assert_eq!(format_factor(2.5), "2.5");
    assert_eq!(format_factor(1.0 / 3.0), "0.333333");
    assert_eq!(format_factor(1e-9), "1e-9");
    let (sentence, factor) = conversion(&unit("mg/L"), &unit("g/L"));
    assert_eq!(sentence, "1 g/L = 1000 mg/L");
    assert_eq!(factor, "1000");
    let (sentence, _) = conversion(&unit("1/min"), &unit("1/h"));
    assert_eq!(sentence, "1 1/min = 60 1/h");
}

#[test]
fn dimensions_in_words() {
    assert_eq!(unit("g/L").dimension_words(), "mass per volume");
    assert_eq!(
        unit("mol/L/s").dimension_words(),
        "amount per volume per time"
    );
    assert_eq!(unit("1/h").dimension_words(), "1 per time");
    assert_eq!(unit("m^2").dimension_words(), "length^2");
    assert_eq!(unit("-").dimension_words(), "dimensionless");
}

#[test]
fn unknown_symbols_are_reported_with_their_spans() {
    let source = "model m\nconst c [gram/Lx] = 1\n";
    let model = crate::syntax::parse(source).expect("parses");
    let crate::ast::ItemKind::Const(consts) = &model.items[0].kind else {
        panic!("a const")
    };
    let unit = consts[0].unit.as_ref().expect("a unit");
    let unknown = resolve(unit).expect_err("unknown symbols");
    let texts: Vec<&str> = unknown
        .iter()
        .map(|(span, _)| &source[span.start..span.end])
        .collect();
    assert_eq!(texts, ["gram", "Lx"]);
}

#[test]
fn percent_and_ppm_are_pure_numbers_with_a_scale() {
    for (a, b) in [("%/%", "-"), ("ppm/ppm", "g/g"), ("%/h", "h^-1 %")] {
        assert_eq!(unit(a).compare(&unit(b)), Comparison::Equal, "{a} vs {b}");
    }
    let cases = [
        ("%", "-", 1e-2),
        ("-", "%", 100.0),
        ("%", "ppm", 1e4),
        ("ppm/h", "%/h", 1e-4),
        ("%/min", "%/h", 60.0),
    ];
    for (a, b, factor) in cases {
        match unit(a).compare(&unit(b)) {
            Comparison::Scale(ratio) => {
                assert!((ratio / factor - 1.0).abs() < 1e-12, "{a} vs {b}: {ratio}")
            }
            other => panic!("{a} vs {b}: {other:?}"),
        }
    }
    for (a, b) in [("%", "g/L"), ("%/h", "%"), ("ppm", "1/h")] {
        assert_eq!(
            unit(a).compare(&unit(b)),
            Comparison::Incompatible,
            "{a} vs {b}"
        );
    }
    assert!(unit("%").is_dimensionless() && !unit("%").is_one());
    assert_eq!(unit("ppm").dimension_words(), "dimensionless");
    for (written, canonical) in [("h^-1 %", "%/h"), ("ppm^-1", "1/ppm"), ("% g/L", "g %/L")] {
        let text = unit(written).to_string();
        assert_eq!(text, canonical, "{written}");
        assert_eq!(unit(&text), unit(written), "{text} parses back");
    }
}

#[test]
fn percent_and_ppm_take_no_prefix() {
    let read = |text: &str| Symbol::parse(text).map(|s| (s.prefix, s.base));
    assert_eq!(read("%"), Some((None, Base::Percent)));
    assert_eq!(read("ppm"), Some((None, Base::PartsPerMillion)));
    for refused in ["m%", "k%", "µ%", "mppm", "uppm"] {
        assert_eq!(read(refused), None, "{refused}");
    }
    let refused = |text: &str| Symbol::refused_prefix(text);
    assert_eq!(refused("m%"), Some(Base::Percent));
    assert_eq!(refused("µ%"), Some(Base::Percent));
    assert_eq!(refused("kppm"), Some(Base::PartsPerMillion));
    assert_eq!(refused("mh"), Some(Base::Hour));
    for not_refused in ["mg", "%", "ppm", "gram", "x"] {
        assert_eq!(refused(not_refused), None, "{not_refused}");
    }
    assert_eq!(Unit::parse("m%"), None);
}

#[test]
fn conversions_with_pure_numbers_read_as_numbers() {
    let (sentence, factor) = conversion(&unit("%"), &unit("-"));
    assert_eq!((sentence.as_str(), factor.as_str()), ("1 = 100 %", "100"));
    let (sentence, factor) = conversion(&unit("ppm"), &unit("%"));
    assert_eq!(
        (sentence.as_str(), factor.as_str()),
        ("1 % = 10000 ppm", "10000")
    );
    let (sentence, _) = conversion(&unit("-"), &unit("ppm"));
    assert_eq!(sentence, "1 = 1000000 ppm");
}
