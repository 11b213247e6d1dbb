"""gbc from Python: grey-box dynamical models (`.gbm`) — known balances, learned rate laws.

The package is a thin layer over gbc's library API, the one the `gbc` command line calls:
keyword names are the CLI's flag names with ``_`` for ``-``, with the same defaults, and
results carry the fields of the CLI's JSON.

    import gbc
    m = gbc.Model.from_file("models/bioreactor/gb1.gbm")
    run = m.train(df, epochs=20, train_points=300, precision="f64", seed=3)
    pred = run.predict(df, mode="online")          # a pandas DataFrame
    rep = gbc.diagnose(m, train_df, val=test_df, seed=1)
    rep.credited, rep.gap_before

Data are pandas DataFrames (or anything with ``columns`` and per-column ``to_numpy``, e.g.
polars): one per experiment, or one with an ``experiment`` column; headers as a CSV file
would have them (``t``, ``t [h]``, ``X [g/L]``); missing cells as NaN.
"""

from __future__ import annotations

import json
import math
import pathlib
from typing import Any, Callable, Iterable, Optional, Sequence, Union

from . import _gbc
from ._gbc import GbcError

__all__ = ["Model", "Run", "Ensemble", "SavedRun", "Diagnosis", "Comparison", "Study", "diagnose",
           "simulate", "compare", "experiment", "load_run", "GbcError"]


def _column(values: Any) -> list:
    """One DataFrame column as floats (missing -> NaN) or, when not numeric, strings."""
    array = values.to_numpy() if hasattr(values, "to_numpy") else list(values)
    try:
        return [float("nan") if v is None else float(v) for v in array]
    except (TypeError, ValueError):
        return ["" if v is None or (isinstance(v, float) and math.isnan(v)) else str(v)
                for v in array]


def _tables(data: Any, name: str) -> list:
    """DataFrames as the native module's tables: ``(name, headers, columns)`` each. A dict
    names its frames (a frame without an ``experiment`` column is the experiment of its
    name, as a CSV file is the experiment of its file's stem); a list gives them the names
    ``data[0]``, ``data[1]``, ..."""
    if data is None:
        return []
    if isinstance(data, dict):
        named = [(str(key), frame) for key, frame in data.items()]
    elif isinstance(data, (list, tuple)):
        named = [(name if len(data) == 1 else f"{name}[{i}]", f) for i, f in enumerate(data)]
    else:
        named = [(name, data)]
    tables = []
    for label, frame in named:
        headers = [str(c) for c in frame.columns]
        columns = [_column(frame[c]) for c in frame.columns]
        tables.append((label, headers, columns))
    return tables


def _flags(keywords: dict) -> list:
    """Keywords as the CLI's flags: ``train_points=300`` -> ``--train-points 300``; True ->
    the flag alone, False/None -> nothing; a list repeats the flag; a dict (``weight``)
    gives ``NAME=VALUE`` entries."""
    flags = []
    for key, value in keywords.items():
        flag = "--" + key.replace("_", "-")
        if value is None or value is False:
            continue
        if value is True:
            flags.append(flag)
        elif isinstance(value, dict):
            for name, entry in value.items():
                flags += [flag, f"{name}={entry}"]
        elif isinstance(value, (list, tuple)):
            for entry in value:
                flags += [flag, str(entry)]
        else:
            flags += [flag, str(value)]
    return flags


def _progress(total_hint: Optional[int], desc: str, progress: Union[bool, Callable, None],
              unit: str = "epoch"):
    """The callback that shows progress: the user's callable, a tqdm bar (updated in place
    in a notebook) when tqdm is installed, else nothing."""
    if callable(progress):
        return progress, None
    if progress is False:
        return None, None
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None, None
    bar = tqdm(total=total_hint, desc=desc, unit=unit, leave=True)

    def on_event(event: dict) -> None:
        kind = event.get("kind")
        if kind == "started":
            bar.reset(total=event["epochs"])
        elif kind == "epoch":
            bar.set_postfix(loss=f"{event['loss']:.3g}", horizon=event["horizon"])
            bar.update(1)
        elif kind == "warning":
            bar.write(f"warning: {event['message']}")
        elif kind == "stage":
            bar.reset(total=event["total"])
            bar.set_description(event["name"])
        elif kind == "round":
            bar.set_postfix_str(f"{event['fit']}: start {event['done']} of at most "
                                f"{event['max']}, best {event['best']:.4g}")
        elif kind == "done":
            bar.update(1)

    return on_event, bar


def _frame(experiment: str, header: Sequence[str], columns: Sequence[Sequence[float]],
           several: bool):
    import pandas as pd

    frame = pd.DataFrame({name: list(values) for name, values in zip(header, columns)})
    if several:
        frame.insert(0, "experiment", experiment)
    return frame


class Model:
    """A compiled ``.gbm`` model."""

    def __init__(self, native: "_gbc.Model"):
        self._native = native

    @staticmethod
    def from_file(path: str) -> "Model":
        """Reads and compiles a model file; a bad model raises :class:`GbcError`."""
        return Model(_gbc.Model.from_file(str(path)))

    @staticmethod
    def from_text(text: str, name: str = "<text>") -> "Model":
        """Compiles model text; ``name`` names it in diagnostics."""
        return Model(_gbc.Model.from_text(text, name))

    @property
    def name(self) -> str:
        """The model's name."""
        return self._native.name

    @property
    def states(self) -> list:
        """The measured states."""
        return self._native.states

    @property
    def inputs(self) -> list:
        """The inputs."""
        return self._native.inputs

    @property
    def params(self) -> dict:
        """The params with their declared values."""
        return dict(self._native.params)

    @property
    def source(self) -> str:
        """The model's text."""
        return self._native.source

    def train(self, data: Any, *, val: Any = None, progress: Union[bool, Callable, None] = None,
              resume: Optional[str] = None, **keywords: Any) -> Union["Run", "Ensemble"]:
        """Trains the model on ``data`` (a DataFrame or a list of them) as ``gbc train``
        does; ``val`` validates (``--val``); every other keyword is a ``gbc train`` flag
        (``epochs=20``, ``train_points=300``, ``precision="f64"``, ``seed=3``,
        ``holdout=["B4"]``, ``output="runs/mine"``, ...). Progress goes to ``progress``
        (a callable taking an event dict), else to a tqdm bar when tqdm is installed.
        A keyboard interrupt stops after the current epoch and keeps a checkpoint in the
        run directory; ``resume=DIR`` with the same data and keywords continues it, ending
        where an uninterrupted run ends. ``ensemble=N`` trains ``gbc train --ensemble N``
        (members in parallel, the band calibrated; ``resample``, ``jobs``, ``band``) and
        returns an :class:`Ensemble`; it is not interrupted between members."""
        if keywords.get("ensemble"):
            return self._train_ensemble(data, val, progress, keywords)
        callback, bar = _progress(keywords.get("epochs"), "training", progress)
        try:
            native = _gbc.train(self._native, _tables(data, "data"), _tables(val, "val"),
                                _flags(keywords), callback,
                                None if resume is None else str(resume))
        finally:
            if bar is not None:
                bar.close()
        return Run(native, self)

    def _train_ensemble(self, data: Any, val: Any, progress, keywords: dict) -> "Ensemble":
        callback, bar = _progress(int(keywords["ensemble"]), "ensemble", progress,
                                  unit="member")
        try:
            native = _gbc.train_ensemble(self._native, _tables(data, "data"),
                                         _tables(val, "val"), _flags(keywords), callback)
        finally:
            if bar is not None:
                bar.close()
        return Ensemble(native, self)

    def __repr__(self) -> str:
        return f"gbc.Model({self.name!r})"


class Run:
    """A trained model: ``predict``, ``params``, ``report``, ``export_onnx``, and the
    fields of ``run.json`` as :attr:`info`."""

    def __init__(self, native: "_gbc.Run", model: Model):
        self._native = native
        self.model = model
        self.info: dict = json.loads(native.json())

    @property
    def directory(self) -> str:
        """The run directory (weights.safetensors, run.json, report.html)."""
        return str(self._native.directory)

    @property
    def params(self) -> dict:
        """The trained params."""
        return dict(self._native.params)

    @property
    def metrics(self) -> dict:
        """The validation errors (``run.json``'s ``metrics``)."""
        return self.info.get("metrics", {})

    @property
    def cv(self) -> Optional[dict]:
        """With ``cv=True``: the leave-one-experiment-out folds as ``cv/summary.json``
        holds them (each fold's held-out errors, the pooled errors and the medians)."""
        text = self._native.cv_json()
        return None if text is None else json.loads(text)

    @property
    def cv_table(self) -> Optional[str]:
        """With ``cv=True``: the folds' table as ``gbc train --cv`` prints it."""
        return self._native.cv_table()

    @property
    def report(self) -> "Report":
        """The run's report page; shown inline in Jupyter."""
        return Report(self._native.report_html())

    def predict(self, data: Any, mode: str = "offline", history: str = "held"):
        """Predictions along ``data`` (a DataFrame or a list of them) as ``gbc predict``
        writes them: ``t``, the states, closure and model outputs; an ``experiment`` column
        when there are several. ``mode``: ``offline``, ``online`` or
        ``online-trained-step``. A free run that leaves the training data's range stops
        there, with a warning."""
        import warnings

        import pandas as pd

        tables = self._native.predict(_tables(data, "data"), mode, history)
        several = len(tables) > 1
        frames = []
        for experiment, header, columns, divergence in tables:
            if divergence:
                warnings.warn(f"{experiment}: {divergence}; the predictions stop before it")
            frames.append(_frame(experiment, header, columns, several))
        return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()

    def export_onnx(self, path: str, precision: str = "f32") -> None:
        """Writes the one-step map as an ONNX file (``gbc export``)."""
        self._native.export_onnx(str(path), precision)

    def _repr_html_(self) -> str:
        return self._native.report_html()

    def __repr__(self) -> str:
        return f"gbc.Run({self.directory!r})"


class SavedRun:
    """A run or ensemble directory that ``gbc train`` wrote, read back for its model
    (``gbc predict --weights DIR``): ``predict``, ``export_onnx``, ``is_ensemble``,
    ``notes``."""

    def __init__(self, native: "_gbc.Saved", model: Model, directory: str):
        self._native, self.model, self.directory = native, model, str(directory)

    @property
    def is_ensemble(self) -> bool:
        """Whether it is an ensemble: its predictions carry the median and a band."""
        return self._native.is_ensemble()

    @property
    def notes(self) -> list:
        """How the model differs from the one trained, outside its structure."""
        return self._native.notes()

    def predict(self, data: Any, mode: str = "offline", history: str = "held",
                band: float = 0.9):
        """Predictions along ``data`` (a DataFrame or a list of them) as ``gbc predict``
        writes them: ``t``, the states, closure and model outputs (an ensemble: the median
        and the ``band`` level's ``_lo``/``_hi`` columns); an ``experiment`` column when
        there are several. The band's coverage of the measured cells is ``.attrs["coverage"]``."""
        import pandas as pd

        header, columns, experiments, coverage = self._native.predict(
            _tables(data, "data"), mode, history, band)
        frame = pd.DataFrame(dict(zip(header, columns)), columns=header)
        if len(set(experiments)) > 1:
            frame.insert(0, "experiment", experiments)
        frame.attrs["coverage"] = coverage
        return frame

    def export_onnx(self, path: str, precision: str = "f32") -> list:
        """Writes the one-step map as ONNX to ``path`` as ``gbc export`` does and returns
        the files written (an ensemble: each used member's map beside ``path`` and the
        band's facts, ``NAME.band.json``)."""
        return [pathlib.Path(p) for p in self._native.export_onnx(str(path), precision)]

    def __repr__(self) -> str:
        kind = "ensemble" if self.is_ensemble else "run"
        return f"<gbc.SavedRun {kind} of {self.model.name!r} at {self.directory!r}>"


def load_run(model: Model, directory: str) -> SavedRun:
    """Reads the run or ensemble ``gbc train`` wrote into ``directory`` (for ``model``, the
    model it was trained as, or one that differs only outside its structure)."""
    return SavedRun(_gbc.load_run(model._native, pathlib.Path(directory)), model, directory)


class Report:
    """An HTML report, shown inline in Jupyter (``_repr_html_``)."""

    def __init__(self, html: str):
        self.html = html

    def _repr_html_(self) -> str:
        return self.html

    def save(self, path: str) -> None:
        """Writes the page to ``path``."""
        with open(path, "w", encoding="utf-8") as file:
            file.write(self.html)


class _Report:
    """A finished report read from the native object: the fields of its ``--json`` as
    attributes and in :attr:`info`; ``text``; inline HTML in Jupyter."""

    _kind = "report"

    def __init__(self, native: Any):
        self._native = native
        self.info: dict = json.loads(native.json())

    def __getattr__(self, name: str) -> Any:
        info = self.__dict__.get("info", {})
        if name in info:
            return info[name]
        raise AttributeError(f"a {self._kind} has no field {name!r}; its fields: {sorted(info)}")

    @property
    def text(self) -> str:
        """The text the command prints."""
        return self._native.text()

    def _repr_html_(self) -> str:
        return self._native.html()

    def __repr__(self) -> str:
        return self._native.text()


class Diagnosis(_Report):
    """A finished diagnosis: the fields of ``gbc diagnose --json`` as attributes
    (``credited``, ``gap_before``, ``states``, ...) and in :attr:`info`; ``text`` (the text
    report ``gbc diagnose`` prints); inline HTML in Jupyter."""

    _kind = "diagnosis"


def diagnose(model: Model, data: Any, *, val: Any = None,
             progress: Union[bool, Callable, None] = None, **keywords: Any) -> Diagnosis:
    """Diagnoses ``model`` (a mechanistic model) against ``data`` as ``gbc diagnose`` does;
    ``val`` is scored only; every other keyword is a ``gbc diagnose`` flag (``seed=1``,
    ``holdout=["B4"]``, ``restarts=8``, ``noise=["S=5%"]``, ...)."""
    callback, bar = _progress(None, "diagnosing", progress)
    try:
        native = _gbc.diagnose(model._native, _tables(data, "data"), _tables(val, "val"),
                               _flags(keywords), callback)
    finally:
        if bar is not None:
            bar.close()
    return Diagnosis(native)


def simulate(model: Model, **keywords: Any):
    """Simulates ``model`` as ``gbc simulate`` does and returns the record as a DataFrame
    (the columns of its CSV file). Every keyword is a ``gbc simulate`` flag: ``t_end=200``,
    ``dt=1``, ``input=["u=steps(hold=5..40, seed=1)"]``, ``noise=["0.01"]``, ``seed=3``,
    ``init={"X": 0.2}``, ``params="run.json"``, ``weights="runs/mine"`` (a what-if run),
    ``effect=["decay"]``, ``hidden=True``, ... Notes and warnings (a run that stops at its
    range) are issued as Python warnings."""
    import warnings

    import pandas as pd

    header, columns, messages = _gbc.simulate(model._native, _flags(keywords))
    for message in messages:
        warnings.warn(message)
    return pd.DataFrame({name: list(values) for name, values in zip(header, columns)})


class Comparison(_Report):
    """A finished comparison: the fields of ``gbc compare --json`` as attributes
    (``verdict``, ``mechanism``, ``grey_box``, ...) and in :attr:`info`; ``text`` (the table
    and verdict ``gbc compare`` prints); inline HTML in Jupyter."""

    _kind = "comparison"


def compare(model: Model, data: Any, *, mechanism: Optional[Model] = None,
            progress: Union[bool, Callable, None] = None, **keywords: Any) -> Comparison:
    """Compares the grey box ``model`` with its fitted mechanism (``mechanism``, or the grey
    box with every closure at its prior) and the naive forecast on ``data``, as
    ``gbc compare`` does; every other keyword is a ``gbc compare`` flag (``holdout=["B4"]``,
    ``cv=True``, ``seeds=3``, ``seed=1``, ``epochs=20``, ...)."""
    callback, bar = _progress(None, "comparing", progress)
    try:
        native = _gbc.compare(model._native, _tables(data, "data"), _flags(keywords),
                              None if mechanism is None else mechanism._native, callback)
    finally:
        if bar is not None:
            bar.close()
    return Comparison(native)


class Ensemble:
    """A trained ensemble (``gbc train --ensemble N``): ``directory``, the fields of
    ``ensemble.json`` as :attr:`info` (band, noise, calibration, coverage of the held-out
    experiments), ``summary`` (what ``gbc train`` prints), ``predict`` (the median with the
    band, as ``gbc predict --weights DIR``), the report inline in Jupyter."""

    def __init__(self, native: "_gbc.Ensemble", model: Model):
        self._native = native
        self.model = model
        self.directory = pathlib.Path(native.directory())
        self.info: dict = json.loads(native.json())
        self.summary: str = native.summary()

    def predict(self, data: Any, mode: str = "offline", history: str = "held",
                band: float = 0.9):
        """The members' median and its band (``X_lo``, ``X_hi``) along every experiment of
        ``data`` (:meth:`SavedRun.predict`)."""
        return load_run(self.model, self.directory).predict(data, mode=mode, history=history,
                                                             band=band)

    def _repr_html_(self) -> str:
        return self._native.html()

    def __repr__(self) -> str:
        return self.summary


class Study:
    """A study of ``gbc experiment`` that ran: ``directory`` (its runs, ``results.csv``,
    ``results.json``, ``summary.csv``, ``figures/``, ``report.html``), ``summary`` (what
    ``gbc experiment`` prints), ``results`` (``results.csv`` as a DataFrame, one row per
    run), ``published`` (whether the tables and report were written: not for a shard or a
    stopped study); the report inline in Jupyter."""

    def __init__(self, native: "_gbc.Study"):
        self._native = native
        self.directory = pathlib.Path(native.directory())
        self.summary = native.summary()
        self.published = native.published()
        self.finished = native.finished()

    @property
    def results(self):
        """``results.csv`` (one row per run: model, size, seed, errors, params) as a
        DataFrame; a study that published nothing raises :class:`FileNotFoundError`."""
        import pandas as pd

        return pd.read_csv(self.directory / "results.csv")

    @property
    def report_html(self) -> str:
        """The study's ``report.html`` (figures inline)."""
        return (self.directory / "report.html").read_text(encoding="utf-8")

    def _repr_html_(self) -> str:
        return self.report_html if self.published else f"<pre>{self.summary}</pre>"

    def __repr__(self) -> str:
        return self.summary


def experiment(*, progress: Union[bool, Callable, None] = None, **keywords: Any) -> Study:
    """Runs a study as ``gbc experiment`` does: every keyword is one of its flags
    (``preset="gb1-bioreactor"``, ``config="experiments/x.json"``, or ``model=["gb1=m.gbm"]``,
    ``data=["r.csv"]``, ``val_from=2000``, ``sizes="300,1000"``, ``replicates=3``,
    ``epochs=20``, ``jobs=2``, ``output="experiment-x"``, ``shard="1/4"``, ...). Runs
    already finished in the directory are reused. A keyboard interrupt starts no further
    run (the runs under way finish and are kept) and raises ``KeyboardInterrupt``; the same
    call again goes on from there."""
    callback, bar = _progress(None, "study", progress, unit="run")
    try:
        native = _gbc.experiment(_flags(keywords), callback)
    finally:
        if bar is not None:
            bar.close()
    return Study(native)
