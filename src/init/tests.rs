use super::*;

#[test]
fn every_template_checks_clean_and_is_formatted() {
    for template in Template::ALL {
        let files = project(Path::new("demo_project"), template).expect("a project");
        for (path, text) in files
            .iter()
            .filter(|(p, _)| p.extension().is_some_and(|e| e == "gbm"))
        {
            let name = path.display().to_string();
            let compiled = crate::driver::compile(&name, text, &[])
                .unwrap_or_else(|e| panic!("{template:?} {name}: {e:?}"));
            assert!(compiled.model.name.starts_with("demo_project"), "{name}");
            assert!(!compiled.model.units.names.is_empty(), "{name} has units");
            let formatted = crate::format::format_source(text).expect("formats");
            assert_eq!(&formatted, text, "{name} is not in the canonical layout");
        }
    }
}

#[test]
fn the_mechanistic_model_simulates_and_the_greybox_model_trains() {
    for template in Template::ALL {
        let files = project(Path::new("p"), template).expect("a project");
        let mechanistic = crate::driver::compile("m", &files[0].1, &[]).expect("compiles");
        assert!(mechanistic.model.closures.is_empty(), "{template:?}");
        assert!(
            !mechanistic.model.effects.is_empty(),
            "{template:?}: effects to diagnose"
        );
        let greybox = crate::driver::compile("g", &files[1].1, &[]).expect("compiles");
        assert!(!greybox.model.closures.is_empty(), "{template:?}");
        let names = |m: &crate::ir::Model| -> Vec<String> {
            (m.inputs.iter().map(|i| i.name.clone()))
                .chain(m.states.iter().map(|s| s.name.clone()))
                .collect()
        };
        assert_eq!(
            names(&mechanistic.model),
            names(&greybox.model),
            "{template:?}: same columns"
        );
    }
}

#[test]
fn names_that_cannot_be_models_are_refused() {
    for bad in ["1culture", "my culture", "state", ""] {
        assert!(
            matches!(
                project(Path::new(bad), Template::Batch),
                Err(InitError::BadName { .. })
            ),
            "{bad:?}"
        );
    }
    let files = project(Path::new("runs/my-culture"), Template::Batch).expect("a project");
    assert_eq!(files[0].0, Path::new("runs/my-culture/my_culture.gbm"));
    assert!(files[0].1.contains("model my_culture "));
    assert!(files[2]
        .1
        .contains("gbc simulate runs/my-culture/my_culture.gbm"));
}
