"""Type stubs of the native module `gbc._gbc` (the Rust half of the package)."""

from pathlib import Path
from typing import Any, Callable, Optional, Sequence, Union

Table = tuple[str, list[str], list[Union[list[float], list[str]]]]

class GbcError(Exception):
    """An error of gbc, with the first diagnostic's facts as attributes."""

    code: Optional[str]
    message: Optional[str]
    file: Optional[str]
    line: Optional[int]
    column: Optional[int]
    help: Optional[str]
    diagnostics: list[str]

class Model:
    @staticmethod
    def from_file(path: Union[str, Path]) -> "Model": ...
    @staticmethod
    def from_text(text: str, name: str = "<text>") -> "Model": ...
    @property
    def name(self) -> str: ...
    @property
    def source(self) -> str: ...
    @property
    def states(self) -> list[str]: ...
    @property
    def inputs(self) -> list[str]: ...
    @property
    def params(self) -> list[tuple[str, float]]: ...

class Run:
    @property
    def directory(self) -> Path: ...
    @property
    def params(self) -> list[tuple[str, float]]: ...
    def json(self) -> str: ...
    def report_html(self) -> str: ...
    def predict(
        self, data: Sequence[Table], mode: str = "offline", history: str = "held"
    ) -> list[tuple[str, list[str], list[list[float]], Optional[str]]]: ...
    def export_onnx(self, path: Union[str, Path], precision: str = "f32") -> None: ...

class Diagnosis:
    def text(self) -> str: ...
    def json(self) -> str: ...
    def html(self) -> str: ...

class Comparison:
    def text(self) -> str: ...
    def json(self) -> str: ...
    def html(self) -> str: ...

class Saved:
    def is_ensemble(self) -> bool: ...
    def notes(self) -> list[str]: ...
    def predict(
        self, data: Sequence[Table], mode: str = "offline", history: str = "held",
        band: float = 0.9,
    ) -> tuple[list[str], list[list[float]], list[str], str]: ...

def train(
    model: Model,
    data: Sequence[Table],
    val: Sequence[Table],
    flags: Sequence[str],
    callback: Optional[Callable[[dict[str, Any]], None]] = None,
    resume: Optional[str] = None,
) -> Run: ...
def diagnose(
    model: Model,
    data: Sequence[Table],
    val: Sequence[Table],
    flags: Sequence[str],
    callback: Optional[Callable[[dict[str, Any]], None]] = None,
) -> Diagnosis: ...
def simulate(
    model: Model, flags: Sequence[str]
) -> tuple[list[str], list[list[float]], list[str]]: ...
def compare(
    model: Model,
    data: Sequence[Table],
    flags: Sequence[str],
    mechanism: Optional[Model] = None,
    callback: Optional[Callable[[dict[str, Any]], None]] = None,
) -> Comparison: ...
def load_run(model: Model, directory: Union[str, Path]) -> Saved: ...
