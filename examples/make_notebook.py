# Writes examples/lab_to_greybox.ipynb (unexecuted); CI executes it with python/run_notebook.py.
import nbformat as nbf
nb = nbf.v4.new_notebook()
md, code = nbf.v4.new_markdown_cell, nbf.v4.new_code_cell
nb.cells = [
md("""# From a DataFrame of batches to a diagnosis and a grey box

A lab's record: four E. coli fed-batches (`models/diagnose/overflow`), on-line biomass,
glucose and acetate assayed a few times a batch at irregular times, empty cells where
nothing was measured. The Monod model the lab has lacks overflow metabolism. This notebook
asks gbc where the model misses the data, trains a grey box that learns the acetate
exchange, and draws its free run on a batch it never saw.

Every call below is the `gbc` command of the same name: keywords are its flags with `_`
for `-`, with the same defaults."""),
code("""import pathlib
import pandas as pd
import matplotlib.pyplot as plt
import gbc

ROOT = pathlib.Path("..").resolve()
record = pd.read_csv(ROOT / "models/diagnose/overflow/data/overflow.csv")
print(record.experiment.unique(), len(record), "rows")
record.head()"""),
md("""## Where does the Monod model miss?

`gbc.diagnose` fits the mechanistic model to three batches, scores it on the fourth (`B4`),
and ranks the candidate effects the model file lists."""),
code("""monod = gbc.Model.from_file(ROOT / "models/diagnose/overflow/monod.gbm")
diagnosis = gbc.diagnose(monod, record, holdout=["B4"], seed=1, restarts=4, progress=False)
print("gap before:", round(diagnosis.gap_before, 4), " credited:", diagnosis.credited)
print("per state (online error):", {s["name"]: round(s["online"], 3) for s in diagnosis.states})"""),
md("""## A grey box that learns the acetate exchange

`overflow_greybox.gbm` keeps the Monod balances and leaves the acetate exchange to a
network. It trains on the same three batches; `B4` validates."""),
code("""greybox = gbc.Model.from_file(ROOT / "bench/training/overflow_greybox.gbm")
run = greybox.train(record, holdout=["B4"], epochs=30, seed=1,
                    output="runs/notebook-greybox", force=True, progress=False)
print("held-out error (online):", round(run.metrics["online"]["overall"], 4))
print("params:", {k: round(v, 4) for k, v in run.params.items()})"""),
md("## Its free run on the held-out batch"),
code("""held_out = record[record.experiment == "B4"]
predicted = run.predict(held_out, mode="online")
measured_all = held_out.rename(columns=lambda c: c.split(" [")[0])  # "X [g/L]" -> "X"
fig, axes = plt.subplots(1, 3, figsize=(12, 3.2))
for axis, state in zip(axes, ["X", "S", "A"]):
    measured = measured_all.dropna(subset=[state])
    axis.plot(measured.t, measured[state], "o", label="measured")
    axis.plot(predicted.t, predicted[state], "-", label="grey box (free run)")
    axis.set_title(state)
    axis.set_xlabel("t [h]")
axes[0].legend()
fig.tight_layout()"""),
md("""Read the acetate panel before trusting the number above: the held-out error says
how far the free run is from the assays, the panel says what it got right and what not
(`gbc compare` puts it beside the fitted mechanism and the naive forecast).

The run's report renders inline:"""),
code("run.report"),
]
nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
nbf.write(nb, "/work/main/examples/lab_to_greybox.ipynb")
