//! A run written by `Run::save` and read back as a [`SavedRun`] predicts and exports what
//! the run in memory does.

use super::*;
use crate::io::ScratchDir;
use crate::train::History;
use crate::trained::predict::Mode;

#[test]
fn a_saved_run_predicts_and_exports_as_the_run_it_was() {
    let root = env!("CARGO_MANIFEST_DIR");
    let model = Model::from_file(format!("{root}/models/mm_chemostat/greybox.gbm")).unwrap();
    let data = [format!("{root}/models/mm_chemostat/data/steps.csv").into()];
    let records = model.records_from_files(&data, &[]).unwrap();
    let mut spec = TrainSpec::default();
    spec.options.epochs = 2;
    spec.options.seed = 3;
    let run = train(
        &model,
        (records.clone(), Vec::new()),
        &spec,
        Control::default(),
        &mut |_| {},
    )
    .unwrap();
    let scratch = ScratchDir::new("api-saved-run").unwrap();
    run.save(&scratch.join("run")).unwrap();
    let saved = SavedRun::load(&model, &scratch.join("run")).unwrap();
    assert!(!saved.is_ensemble() && saved.notes().is_empty());
    for mode in [Mode::Offline, Mode::Online] {
        let expected = run.predict(&records, mode, History::Held).unwrap();
        let asked = PredictSpec {
            mode,
            ..PredictSpec::default()
        };
        let found = saved.predict(&records, &asked, &|_| {}).unwrap();
        assert_eq!(found.header, expected[0].header);
        assert_eq!(found.columns, expected[0].columns, "{mode:?}");
        assert_eq!(found.experiments.len(), found.columns[0].len());
    }
    let precision = crate::engine::graph::Precision::F32;
    let export = saved.export(ExportFormat::Onnx, precision).unwrap();
    assert_eq!(export.0.bytes, run.export_onnx(precision).unwrap());
    let layout = export.layout_text(std::path::Path::new("m.onnx"));
    assert!(
        layout.starts_with("wrote m.onnx: one step of 1"),
        "{layout}"
    );
}
