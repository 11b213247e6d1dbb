#!/usr/bin/env python3
"""The corpus runner (issue 35): every command at default flags on every record.

For each case folder of `bench/corpus/real/` and `bench/corpus/scenarios/` (its
`case.json`, see `bench/corpus/README.md`) it runs, one after the other, each under a
wall-time cap of 10x the case's expected seconds:

- `diagnose`: `gbc diagnose MODEL DATA --holdout H --json ...`
- `train_mechanism`: `gbc train MODEL DATA --holdout H -o ...` (the fitted mechanism)
- `train_greybox`: `gbc train GREYBOX DATA --holdout H -o ...`
- `compare`: `gbc compare GREYBOX DATA --holdout H --json ...`

and writes one row per record and command: finished, exit code, seconds, the verdict,
the held-out errors of the fitted mechanism, the grey box and the naive forecast, and for
scenarios whether the answer is right. `--json FILE` writes the rows; `--markdown FILE` the
table `docs/corpus.md` shows. Python's standard library only: CI runs it without scipy.

Exit status: 1 when a command panicked (exit 2) or exited with an error; a command stopped
at its cap is reported in the table, not failed.
"""

import argparse
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
COMMANDS = ["diagnose", "train_mechanism", "train_greybox", "compare"]
# Expected seconds where a case does not say (2 cores).
DEFAULT_EXPECTED = {"diagnose": 60, "train_mechanism": 30, "train_greybox": 180, "compare": 400}
CAP_FACTOR = 10
# A grey box is right when its held-out error is at most this many times the mechanism's.
TOLERANCE = 1.1
# Identified params: right when within this many standard errors of the truth.
WITHIN = 3.0


def number(value):
    """A float from gbc's JSON (non-finite values are written by name)."""
    if value is None:
        return None
    if isinstance(value, (int, float)):
        return float(value)
    try:
        return float(value)
    except ValueError:
        return None


def cases(quick, only):
    """Every case folder with a case.json, real records first."""
    found = []
    for kind in ["real", "scenarios"]:
        for path in sorted((HERE / kind).glob("*/case.json")):
            case = json.loads(path.read_text())
            case["dir"] = path.parent
            if quick and not case.get("quick"):
                continue
            if only and case["name"] not in only:
                continue
            found.append(case)
    return found


def command_line(gbc, case, command, out):
    """The argv of `command` on `case`, writing into `out`."""
    folder = case["dir"]
    data = [str(folder / d) for d in case["data"]]
    holdout = [f"--holdout={h}" for h in case.get("holdout", [])]
    if command == "diagnose":
        return [gbc, "diagnose", str(folder / case["model"]), *data, *holdout,
                "--json", str(out / "diagnose.json")]
    if command == "train_mechanism":
        return [gbc, "train", str(folder / case["model"]), *data, *holdout,
                "-o", str(out / "mechanism")]
    if command == "train_greybox":
        return [gbc, "train", str(folder / case["greybox"]), *data, *holdout,
                "-o", str(out / "greybox")]
    return [gbc, "compare", str(folder / case["greybox"]), *data, *holdout,
            "--json", str(out / "compare.json")]


def run(argv, cap, log):
    """Runs `argv` under `cap` seconds: (exit code or None at the cap, seconds)."""
    start = time.monotonic()
    with open(log, "w") as err:
        process = subprocess.Popen(argv, stdout=err, stderr=subprocess.STDOUT,
                                   cwd=ROOT, start_new_session=True)
        try:
            code = process.wait(timeout=cap)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGTERM)
            try:
                process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()
            code = None
    return code, time.monotonic() - start


def load(path):
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


def online_error(run_dir):
    """The held-out free-run error of a training run (run.json), None without one."""
    info = load(run_dir / "run.json")
    if not info:
        return None, None
    online = (info.get("metrics") or {}).get("online")
    error = number(online.get("overall")) if online else None
    return error, info


def param_checks(estimates, truth):
    """(identified, of which within WITHIN standard errors of the truth), over the params
    whose truth is known."""
    identified = within = 0
    for estimate in estimates or []:
        name = estimate.get("name")
        if name not in truth or not estimate.get("identified"):
            continue
        identified += 1
        error = number(estimate.get("std_error"))
        value = number(estimate.get("value"))
        if error is not None and value is not None and abs(value - truth[name]) <= WITHIN * error:
            within += 1
    return identified, within


def judge_diagnosis(report, answer):
    """(verdict text, right, undecided, params identified, within) of a diagnosis."""
    selection = report.get("selection") or {}
    credited = sorted(selection.get("credited") or [])
    undecided = selection.get("undecided") or []
    significant = report.get("significant")
    if not significant:
        verdict = "not significant"
    elif undecided:
        verdict = "undecided: " + " | ".join(undecided)
    else:
        verdict = " + ".join(credited) if credited else "nothing credited"
    if answer is None:
        return verdict, None, False, 0, 0
    withheld = sorted(answer.get("withheld") or [])
    truth = answer.get("params") or {}
    sets = [sorted(s.split(" + ")) for s in undecided]
    if undecided:
        right, is_undecided = withheld in sets, True
    else:
        right, is_undecided = credited == withheld, False
    # The params of the fit whose effects are the truth's: the base fit where nothing is
    # withheld, the single effect's fit where one is.
    estimates = []
    if not withheld:
        estimates = (report.get("base_fit") or {}).get("estimates")
    elif len(withheld) == 1:
        for effect in report.get("effects") or []:
            if effect.get("name") == withheld[0]:
                estimates = (effect.get("fit") or {}).get("estimates")
    identified, within = param_checks(estimates, truth)
    return verdict, right, is_undecided, identified, within


def trained_epochs(info):
    """What a grey-box run trained: the stop cross-validation chose, or every epoch."""
    if not info:
        return None
    epochs = (info.get("training") or {}).get("epochs")
    toward = info.get("toward_mechanism") or {}
    choice = toward.get("choice")
    if choice:
        return f"stopped at epoch {choice.get('chosen')} of {choice.get('epochs')}"
    if toward.get("unchosen"):
        return f"{epochs} epochs (no stop chosen)"
    return f"{epochs} epochs"


def judge_greybox(greybox, mechanism, answer):
    """Whether a grey box's held-out error is right against its mechanism's."""
    if answer is None or greybox is None or mechanism is None:
        return None
    if not math.isfinite(greybox):
        return False
    if greybox > TOLERANCE * mechanism:
        return False
    if answer.get("withheld"):
        return greybox < mechanism
    return True


def row_for(case, command, code, seconds, cap, out, log, mechanism_error):
    """One row of the table: what ran and how it did."""
    answer = case.get("answer")
    row = {
        "record": case["name"], "kind": case["kind"], "command": command,
        "finished": code is not None, "exit_code": code, "seconds": round(seconds, 1),
        "cap_seconds": cap, "verdict": None, "mechanism_error": None,
        "greybox_error": None, "naive_error": None, "right": None, "undecided": False,
        "params_identified": 0, "params_within_3se": 0, "message": None,
    }
    if code not in (0, None):
        lines = [l for l in Path(log).read_text(errors="replace").splitlines() if l.strip()]
        row["message"] = " / ".join(lines[-3:])[:300]
    if code != 0:
        return row
    truth = (answer or {}).get("params") or {}
    if command == "diagnose":
        report = load(out / "diagnose.json") or {}
        verdict, right, undecided, identified, within = judge_diagnosis(report, answer)
        row.update(verdict=verdict, right=right, undecided=undecided,
                   params_identified=identified, params_within_3se=within)
        # A diagnosis's "mechanism" is the base model's held-out gap, its "grey box" the
        # credited set's.
        row["mechanism_error"] = number(report.get("gap_before"))
        row["greybox_error"] = number((report.get("selection") or {}).get("gap_after"))
    elif command == "train_mechanism":
        error, info = online_error(out / "mechanism")
        row["mechanism_error"] = error
        identified, within = param_checks((info or {}).get("estimates"), truth)
        row.update(params_identified=identified, params_within_3se=within)
        row["verdict"] = "fitted" if info else None
    elif command == "train_greybox":
        error, info = online_error(out / "greybox")
        row["greybox_error"] = error
        row["mechanism_error"] = mechanism_error
        identified, within = param_checks((info or {}).get("estimates"), truth)
        row.update(params_identified=identified, params_within_3se=within)
        row["right"] = judge_greybox(error, mechanism_error, answer)
        row["verdict"] = trained_epochs(info)
    else:
        report = load(out / "compare.json") or {}
        overall = report.get("overall") or {}
        score = lambda k: number((overall.get(k) or {}).get("error"))
        row.update(mechanism_error=score("mechanism"), greybox_error=score("grey_box"),
                   naive_error=score("naive"))
        row["verdict"] = ((overall.get("verdict") or {}).get("standing"))
        row["right"] = judge_greybox(row["greybox_error"], row["mechanism_error"], answer)
    return row


def skipped(case, command, why):
    """The row of a command that does not apply to a case."""
    return {
        "record": case["name"], "kind": case["kind"], "command": command,
        "finished": None, "exit_code": None, "seconds": 0.0, "cap_seconds": 0,
        "verdict": why, "mechanism_error": None, "greybox_error": None,
        "naive_error": None, "right": None, "undecided": False,
        "params_identified": 0, "params_within_3se": 0, "message": None,
    }


def fmt(value):
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.3g}"
    return str(value)


def markdown(rows):
    """The table of `docs/corpus.md`, then the summary counts."""
    lines = ["| record | command | finished | exit | s | verdict | mechanism | grey box | naive | right |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        right = "undecided (right set named)" if r["undecided"] and r["right"] else fmt(r["right"])
        verdict = r["verdict"] or (r["message"] or "–")
        lines.append("| " + " | ".join([
            r["record"], r["command"], fmt(r["finished"]), fmt(r["exit_code"]),
            fmt(r["seconds"]), verdict.replace("|", "/"), fmt(r["mechanism_error"]),
            fmt(r["greybox_error"]), fmt(r["naive_error"]), right]) + " |")
    return "\n".join(lines + ["", summary(rows)])


def summary(rows):
    """Counts per command: finished, failed, right among judged, identified params."""
    out = []
    for command in COMMANDS:
        mine = [r for r in rows if r["command"] == command]
        if not mine:
            continue
        judged = [r for r in mine if r["right"] is not None]
        right = sum(1 for r in judged if r["right"] and not r["undecided"])
        undecided = sum(1 for r in judged if r["undecided"])
        failed = sum(1 for r in mine if r["exit_code"] not in (0, None))
        capped = sum(1 for r in mine if r["finished"] is False)
        identified = sum(r["params_identified"] for r in mine)
        within = sum(r["params_within_3se"] for r in mine)
        out.append(
            f"- `{command}`: {len(mine)} runs, {capped} stopped at the cap, {failed} failed; "
            f"right {right} of {len(judged)} judged"
            + (f" ({undecided} undecided)" if command == "diagnose" else "")
            + f"; params reported identified {identified}, within 3 SE of the truth {within}")
    return "\n".join(out)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="only the cases marked quick (CI)")
    parser.add_argument("--json", type=Path, help="write the rows as JSON here")
    parser.add_argument("--markdown", type=Path, help="write the table here")
    parser.add_argument("--only", nargs="*", help="only these cases, by name")
    parser.add_argument("--commands", nargs="*", default=COMMANDS, choices=COMMANDS)
    parser.add_argument("--gbc", default=str(ROOT / "target/release/gbc"))
    parser.add_argument("--keep", type=Path, help="keep every output under this folder")
    args = parser.parse_args()
    if not Path(args.gbc).exists():
        subprocess.run(["cargo", "build", "--release", "--quiet"], cwd=ROOT, check=True)
    selected = cases(args.quick, args.only)
    if not selected:
        sys.exit("no case found (bench/corpus/real/*/case.json, scenarios/*/case.json)")
    rows = []
    scratch = Path(tempfile.mkdtemp(prefix="gbc-corpus-"))
    for index, case in enumerate(selected, 1):
        out = (args.keep or scratch) / case["name"]
        shutil.rmtree(out, ignore_errors=True)
        out.mkdir(parents=True)
        expected = {**DEFAULT_EXPECTED, **(case.get("expected_seconds") or {})}
        mechanism_error = None
        for command in args.commands:
            cap = CAP_FACTOR * expected[command]
            if command == "compare" and not case.get("holdout"):
                # One experiment: nothing to hold out, `gbc compare` does not apply.
                rows.append(skipped(case, command, "not applicable: no experiment held out"))
                continue
            log = out / f"{command}.log"
            argv = command_line(args.gbc, case, command, out)
            print(f"[{index}/{len(selected)}] {case['name']}: {command} (cap {cap} s)",
                  file=sys.stderr, flush=True)
            code, seconds = run(argv, cap, log)
            row = row_for(case, command, code, seconds, cap, out, log, mechanism_error)
            if command == "train_mechanism":
                mechanism_error = row["mechanism_error"]
            rows.append(row)
            print(f"    exit {code}, {seconds:.1f} s, verdict {row['verdict']}, "
                  f"right {row['right']}" + (f": {row['message']}" if row["message"] else ""),
                  file=sys.stderr, flush=True)
            if args.json:
                write(args.json, json.dumps(rows, indent=1, default=str))
    table = markdown(rows)
    print(table)
    if args.markdown:
        write(args.markdown, table + "\n")
    if not args.keep:
        shutil.rmtree(scratch, ignore_errors=True)
    failed = [r for r in rows if r["exit_code"] not in (0, None)]
    if failed:
        print(f"{len(failed)} command(s) failed: "
              + ", ".join(f"{r['record']}/{r['command']} (exit {r['exit_code']})" for r in failed),
              file=sys.stderr)
        sys.exit(1)


def write(path, text):
    """Writes atomically (a temporary file beside it, then a rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(path.name + ".tmp")
    temporary.write_text(text)
    temporary.replace(path)


if __name__ == "__main__":
    main()
