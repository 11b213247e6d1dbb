"""The package against the CLI: the same data, flags and seed give the same numbers.

Run from the repository root after `cargo build --release` (the CLI binary) and
`pip install ./python`:  python -m pytest python/tests
"""

import json
import math
import os
import pathlib
import subprocess

import pandas as pd
import pytest

import gbc

ROOT = pathlib.Path(__file__).resolve().parents[2]
GBC = pathlib.Path(os.environ.get("GBC_BIN", ROOT / "target" / "release" / "gbc"))
GB1 = ROOT / "models" / "bioreactor" / "gb1.gbm"
STEPS = ROOT / "models" / "bioreactor" / "data" / "steps.csv"
MONOD = ROOT / "models" / "diagnose" / "overflow" / "monod.gbm"
OVERFLOW = ROOT / "models" / "diagnose" / "overflow" / "data" / "overflow.csv"
# Small corpus scenarios (a few seconds per command) where the test compares the package
# with the CLI, not a result: two lactic batches with a grey box, five yeast batches.
SCENARIOS = ROOT / "bench" / "corpus" / "scenarios"
S02_GREYBOX, S02_DATA = SCENARIOS / "s02" / "greybox.gbm", SCENARIOS / "s02" / "data.csv"
S29_MODEL, S29_DATA = SCENARIOS / "s29" / "model.gbm", SCENARIOS / "s29" / "data.csv"


def cli(*args):
    assert GBC.exists(), f"the CLI binary {GBC} is missing: run `cargo build --release`"
    return subprocess.run([str(GBC), *map(str, args)], cwd=ROOT, check=True,
                          capture_output=True, text=True)


def read(path):
    # The Python engine parses with float(): the exact doubles of the file, as gbc reads them.
    return pd.read_csv(path, engine="python")


def test_train_and_predict_equal_the_cli(tmp_path):
    flags = ["--epochs", 4, "--train-points", 300, "--precision", "f64", "--seed", 3]
    cli("train", GB1, STEPS, *flags, "-o", tmp_path / "cli")
    cli("predict", GB1, STEPS, "--weights", tmp_path / "cli", "--mode", "online",
        "-o", tmp_path / "cli.csv")
    model = gbc.Model.from_file(GB1)
    run = model.train({"steps": read(STEPS)}, epochs=4, train_points=300, precision="f64",
                      seed=3, output=tmp_path / "py", progress=False)
    expected = json.loads((tmp_path / "cli" / "run.json").read_text())
    for key in ["initial_offline", "initial_online", "offline", "online"]:
        assert run.metrics[key] == expected["metrics"][key], key
    assert run.params == {p["name"]: p["value"] for p in expected["params"]}
    assert (tmp_path / "py" / "weights.safetensors").read_bytes() == \
        (tmp_path / "cli" / "weights.safetensors").read_bytes()
    predicted = run.predict({"steps": read(STEPS)}, mode="online")
    written = read(tmp_path / "cli.csv")
    assert list(predicted.columns) == list(written.columns)
    assert predicted.shape == written.shape
    # The CLI's file holds each value's shortest round-trip text: the same doubles.
    assert (predicted.to_numpy() == written.to_numpy()).all()
    assert "<svg" in run.report._repr_html_()


def test_a_saved_run_predicts_as_gbc_predict(tmp_path):
    flags = ["--epochs", 3, "--train-points", 300, "--precision", "f64", "--seed", 2]
    cli("train", GB1, STEPS, *flags, "-o", tmp_path / "run")
    cli("predict", GB1, STEPS, "--weights", tmp_path / "run", "--mode", "online",
        "-o", tmp_path / "cli.csv")
    saved = gbc.load_run(gbc.Model.from_file(GB1), tmp_path / "run")
    assert not saved.is_ensemble
    predicted = saved.predict(read(STEPS), mode="online")
    written = read(tmp_path / "cli.csv")
    assert list(predicted.columns) == list(written.columns)
    assert (predicted.to_numpy() == written.to_numpy()).all()
    cli("export", GB1, "--weights", tmp_path / "run", "-o", tmp_path / "cli.onnx")
    assert saved.export_onnx(tmp_path / "py.onnx") == [tmp_path / "py.onnx"]
    assert (tmp_path / "py.onnx").read_bytes() == (tmp_path / "cli.onnx").read_bytes()
    with pytest.raises(gbc.GbcError):
        gbc.load_run(gbc.Model.from_file(GB1), tmp_path / "nothing-here")


def test_a_frame_with_missing_cells_reads_as_its_csv_file(tmp_path):
    frame = read(OVERFLOW)
    assert frame.isna().to_numpy().any(), "the lab record has empty cells"
    path = tmp_path / "overflow.csv"
    frame.to_csv(path, index=False)
    model = gbc.Model.from_file(MONOD)
    from_frame = model.train(frame, holdout=["B4"], output=tmp_path / "a", progress=False)
    cli("train", MONOD, OVERFLOW, "--holdout", "B4", "-o", tmp_path / "b")
    expected = json.loads((tmp_path / "b" / "run.json").read_text())
    assert from_frame.params == {p["name"]: p["value"] for p in expected["params"]}
    assert from_frame.metrics["online"] == expected["metrics"]["online"]


def test_diagnose_equals_the_cli(tmp_path):
    flags = ["--holdout", "B4", "--skip-loci", "--restarts", 2, "--seed", 1]
    cli("diagnose", MONOD, OVERFLOW, *flags, "--json", tmp_path / "d.json")
    expected = json.loads((tmp_path / "d.json").read_text())
    report = gbc.diagnose(gbc.Model.from_file(MONOD), read(OVERFLOW).assign(), holdout=["B4"],
                          skip_loci=True, restarts=2, seed=1, progress=False)
    assert report.gap_before == expected["gap_before"]
    assert report.credited == expected["credited"]
    assert report.fitted_params == expected["fitted_params"]
    assert "<html" in report._repr_html_().lower()


def test_errors_carry_the_diagnostic():
    with pytest.raises(gbc.GbcError) as caught:
        gbc.Model.from_text("model m\nstate X\nder X = -k * X\n", "bad.gbm")
    error = caught.value
    assert error.code == "gbm::E0101"
    assert (error.file, error.line, error.column) == ("bad.gbm", 3, 10)
    assert "k" in error.message
    with pytest.raises(gbc.GbcError) as caught:
        gbc.Model.from_file(GB1).train(read(STEPS), epochz=3, progress=False)
    assert caught.value.code == "gbm::E1006"
    assert "--epochz" in caught.value.message


def test_an_interrupt_stops_after_the_epoch_and_keeps_a_checkpoint(tmp_path):
    def interrupt(event):
        if event.get("kind") == "epoch" and event["epoch"] == 2:
            raise KeyboardInterrupt

    model, data = gbc.Model.from_file(GB1), read(STEPS)
    keywords = dict(epochs=6, train_points=300, output=tmp_path / "run")
    with pytest.raises(KeyboardInterrupt):
        model.train(data, progress=interrupt, **keywords)
    checkpoint = json.loads((tmp_path / "run" / "checkpoint.json").read_text())
    assert checkpoint["epoch"] == 2
    resumed = model.train(data, progress=False, resume=tmp_path / "run", **keywords)
    whole = model.train(data, progress=False, **{**keywords, "output": tmp_path / "whole"})
    assert resumed.params == whole.params
    assert (tmp_path / "run" / "weights.safetensors").read_bytes() == \
        (tmp_path / "whole" / "weights.safetensors").read_bytes()
    assert not (tmp_path / "run" / "checkpoint.json").exists()


CHEMOSTAT = ROOT / "models" / "mm_chemostat" / "truth.gbm"


def test_simulate_equals_the_cli(tmp_path):
    flags = ["--t-end", 50, "--dt", 0.5, "--input", "E0=steps(hold=3..6, seed=4)",
             "--noise", "0.02", "--seed", 5, "--hidden"]
    cli("simulate", CHEMOSTAT, *flags, "-o", tmp_path / "cli.csv")
    simulated = gbc.simulate(gbc.Model.from_file(CHEMOSTAT), t_end=50, dt=0.5,
                             input=["E0=steps(hold=3..6, seed=4)"], noise=["0.02"], seed=5,
                             hidden=True)
    written = read(tmp_path / "cli.csv")
    assert list(simulated.columns) == list(written.columns)
    assert simulated.shape == written.shape
    # Times are written rounded to 12 digits; every other column holds the same doubles.
    assert (simulated.drop(columns="t").to_numpy() ==
            written.drop(columns="t").to_numpy()).all()
    assert ((simulated["t"] - written["t"]).abs() < 1e-9).all()
    with pytest.raises(gbc.GbcError) as caught:
        gbc.simulate(gbc.Model.from_file(CHEMOSTAT), t_end=5, dt=1)
    assert caught.value.code == "gbm::E0709"


def test_compare_equals_the_cli(tmp_path):
    flags = ["--holdout", "B2", "--seeds", 1, "--epochs", 2, "--jobs", 1]
    cli("compare", S02_GREYBOX, S02_DATA, *flags, "--json", tmp_path / "c.json")
    expected = json.loads((tmp_path / "c.json").read_text())
    result = gbc.compare(gbc.Model.from_file(S02_GREYBOX), {"data": read(S02_DATA)},
                         holdout=["B2"], seeds=1, epochs=2, jobs=1, progress=False)
    def timeless(value):
        # Wall-clock seconds differ from run to run; every other field is the same.
        if isinstance(value, dict):
            return {k: timeless(v) for k, v in value.items() if k != "seconds"}
        if isinstance(value, list):
            return [timeless(v) for v in value]
        return value

    assert timeless(result.info) == timeless(expected)
    assert "<html" in result._repr_html_().lower()


def _study_flags(out):
    return ["--model", f"gb1={GB1}", "--data", STEPS, "--val-from", 2500, "--sizes", 200,
            "--replicates", 3, "--epochs", 2, "--jobs", 1, "-o", out]


def _results(directory):
    # Wall-clock seconds differ from run to run; every other column is the same.
    frame = read(directory / "results.csv")
    return frame.drop(columns=[c for c in frame.columns if "seconds" in c])


def test_experiment_equals_the_cli(tmp_path):
    cli("experiment", *_study_flags(tmp_path / "cli"))
    study = gbc.experiment(model=[f"gb1={GB1}"], data=[STEPS], val_from=2500, sizes="200",
                           replicates=3, epochs=2, jobs=1, output=tmp_path / "py",
                           progress=False)
    assert study.published and study.finished == 3
    assert study.directory == tmp_path / "py"
    pd.testing.assert_frame_equal(_results(study.directory), _results(tmp_path / "cli"))
    assert "gb1" in study.summary
    assert "<svg" in study._repr_html_()
    with pytest.raises(gbc.GbcError) as caught:
        gbc.experiment(model=[f"gb1={GB1}"], data=[STEPS], val_from=2500, sizes="x",
                       output=tmp_path / "bad", progress=False)
    assert caught.value.code is not None
    with pytest.raises(gbc.GbcError) as caught:
        gbc.experiment(model=[f"gb1={GB1}"], data=[STEPS], val_from=2500, sizes="200",
                       print_study=True, progress=False)
    assert caught.value.code == "gbm::E1006"


def test_an_interrupted_study_keeps_its_runs_and_goes_on(tmp_path):
    def interrupt(event):
        # As Ctrl-C does: the study starts no further run and raises KeyboardInterrupt.
        if event.get("kind") == "done":
            raise KeyboardInterrupt

    keywords = dict(model=[f"gb1={GB1}"], data=[STEPS], val_from=2500, sizes="200",
                    replicates=3, epochs=2, jobs=1, output=tmp_path / "py")
    with pytest.raises(KeyboardInterrupt):
        gbc.experiment(progress=interrupt, **keywords)
    assert not (tmp_path / "py" / "results.csv").exists()
    study = gbc.experiment(progress=False, **keywords)
    assert study.published and study.finished == 3
    assert "reused" in study.summary
    cli("experiment", *_study_flags(tmp_path / "cli"))
    pd.testing.assert_frame_equal(_results(study.directory), _results(tmp_path / "cli"))


def test_an_ensemble_equals_the_cli(tmp_path):
    flags = ["--ensemble", 3, "--holdout", "B1", "--jobs", 1, "--seed", 2]
    cli("train", S29_MODEL, S29_DATA, *flags, "-o", tmp_path / "cli")
    cli("predict", S29_MODEL, S29_DATA, "--weights", tmp_path / "cli", "--mode", "online",
        "-o", tmp_path / "cli.csv")
    model = gbc.Model.from_file(S29_MODEL)
    ensemble = model.train({"data": read(S29_DATA)}, ensemble=3, holdout=["B1"], jobs=1,
                           seed=2, output=tmp_path / "py", progress=False)
    assert isinstance(ensemble, gbc.Ensemble)
    expected = json.loads((tmp_path / "cli" / "ensemble.json").read_text())

    def timeless(value):
        # Wall-clock seconds and the data's description (files or experiments) aside.
        if isinstance(value, dict):
            return {k: timeless(v) for k, v in value.items() if k not in ("seconds", "data")}
        if isinstance(value, list):
            return [timeless(v) for v in value]
        return value

    assert timeless(ensemble.info) == timeless(expected)
    assert "coverage" in ensemble.summary
    predicted = ensemble.predict({"data": read(S29_DATA)}, mode="online")
    written = read(tmp_path / "cli.csv")
    assert list(predicted.columns) == list(written.columns)
    assert (predicted.drop(columns="experiment").to_numpy() ==
            written.drop(columns="experiment").to_numpy()).all()
    assert "<svg" in ensemble._repr_html_()
    cli("export", S29_MODEL, "--weights", tmp_path / "cli", "-o", tmp_path / "cli.onnx")
    files = gbc.load_run(model, tmp_path / "py").export_onnx(tmp_path / "py.onnx")
    written = sorted(tmp_path.glob("cli*.onnx")) + sorted(tmp_path.glob("cli*.band.json"))
    assert len(files) == len(written) == len(ensemble.info["members"]) + 1
    assert [f.read_bytes() for f in files[:-1]] == [f.read_bytes() for f in written[:-1]]


def test_cross_validation_equals_the_cli(tmp_path):
    flags = ["--cv", "--epochs", 2, "--seed", 4]
    cli("train", S29_MODEL, S29_DATA, *flags, "-o", tmp_path / "cli")
    expected = json.loads((tmp_path / "cli" / "cv" / "summary.json").read_text())
    run = gbc.Model.from_file(S29_MODEL).train({"data": read(S29_DATA)}, cv=True, epochs=2,
                                               seed=4, output=tmp_path / "py", progress=False)

    def timeless(value):
        if isinstance(value, dict):
            return {k: timeless(v) for k, v in value.items() if k != "seconds"}
        if isinstance(value, list):
            return [timeless(v) for v in value]
        return value

    assert timeless(run.cv) == timeless(expected)
    batches = sorted(read(S29_DATA)["experiment"].unique())
    assert [f["held_out"] for f in run.cv["folds"]] == batches
    assert "cross-validation" in run.cv_table
    assert (tmp_path / "py" / "cv" / "summary.json").exists()
