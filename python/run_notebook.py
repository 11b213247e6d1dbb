"""Executes a notebook from its own directory and fails on the first cell that raises
(CI: `python python/run_notebook.py examples/lab_to_greybox.ipynb`); `--out FILE` keeps the
executed notebook."""

import pathlib
import sys

import nbformat
from nbclient import NotebookClient

path = pathlib.Path(sys.argv[1]).resolve()
out = sys.argv[sys.argv.index("--out") + 1] if "--out" in sys.argv else None
notebook = nbformat.read(path, as_version=4)
NotebookClient(notebook, timeout=900, kernel_name="python3",
               resources={"metadata": {"path": str(path.parent)}}).execute()
if out:
    nbformat.write(notebook, out)
print(f"{path.name}: {len(notebook.cells)} cells ran")
