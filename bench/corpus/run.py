#!/usr/bin/env python3
"""The corpus runner (issues 35, 43): every command at default flags on every record.

For each case folder of `bench/corpus/real/` and `bench/corpus/scenarios/` (its
`case.json`, see `bench/corpus/README.md`) it runs, one after the other, each under a
wall-time cap of 10x the case's expected seconds:

- `diagnose`: `gbc diagnose MODEL DATA --holdout H --json ...`
- `compare`: `gbc compare GREYBOX DATA --holdout H --mechanism MODEL --json ...`: the
  grey box (3 seeds), the case's own model fitted as its mechanism, the naive forecast;
- `train_mechanism`, `train_greybox`: read from compare's report (its mechanism fit, and
  its grey box trained with the first seed), so nothing trains twice. Only where compare
  does not run (no experiment held out, or `--commands` leaves it out) do they run
  `gbc train MODEL` and `gbc train GREYBOX` themselves.

It writes one row per record and command: its status (ok, failed, capped, n/a), exit code,
seconds, the verdict (for a diagnosis: the credited set), the held-out significance, the
held-out errors of the fitted mechanism, the grey box and the naive forecast, for scenarios
whether the answer is right, and the params identified. `--json FILE` writes the rows;
`--markdown FILE` the table. Python's standard library only: CI runs it without scipy.

Scoring (issue 43): a command that exited 0 without a readable report failed; failed and
capped rows stay in every denominator and are counted apart; a grey box worse than the
naive forecast is not right.

Exit status: 1 when a command panicked, exited with an error or wrote no readable report;
a command stopped at its cap is reported in the table, not failed.
"""

import argparse
import csv
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
# In the order they run: the train rows read compare's report.
COMMANDS = ["diagnose", "compare", "train_mechanism", "train_greybox"]
# The commands whose rows have a right answer (a mechanism's fit is not judged).
JUDGED = {"diagnose", "compare", "train_greybox"}
# Expected seconds where a case does not say (2 cores).
DEFAULT_EXPECTED = {"diagnose": 60, "train_mechanism": 30, "train_greybox": 180, "compare": 400}
CAP_FACTOR = 10
# A grey box is right when its held-out error is at most this many times the mechanism's
# (and not above the naive forecast's).
TOLERANCE = 1.1
# Identified params: right when within this many standard errors of the truth.
WITHIN = 3.0
# How a diagnosis names a constant it refits among the credited candidates.
REFIT = "refit "


def number(value):
    """A float from gbc's JSON (non-finite values are written by name)."""
    if value is None or isinstance(value, bool):
        return None
    try:
        return float(value)
    except (TypeError, ValueError):
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


def experiments(case):
    """The experiments of a case's data files (their `experiment` column), in order."""
    names = []
    for name in case["data"]:
        with open(case["dir"] / name, newline="") as f:
            for row in csv.DictReader(f):
                if row.get("experiment") not in names:
                    names.append(row.get("experiment"))
    return names


def contract_problems(case):
    """What in a case breaks the case contract (bench/corpus/README.md), in words."""
    problems = []
    for key in ("name", "kind", "model", "greybox", "data", "holdout", "quick"):
        if key not in case:
            problems.append(f"no `{key}`")
    names = experiments(case)
    held = case.get("holdout") or []
    if len(names) > 1 and not held:
        problems.append(f"{len(names)} experiments and none held out")
    if held and set(held) >= set(names):
        problems.append("nothing left to train on")
    problems += [f"held-out {h} is not an experiment of the data" for h in held if h not in names]
    quick = case.get("quick")
    if isinstance(quick, list) and not set(quick) <= set(COMMANDS):
        problems.append(f"`quick` names unknown commands: {sorted(set(quick) - set(COMMANDS))}")
    if case.get("kind") == "scenario" and not isinstance(case.get("answer"), dict):
        problems.append("a scenario without an answer")
    return problems


def case_commands(case, commands, quick):
    """The commands to run on `case`: `commands`, and under `--quick` only those its
    `quick` field lists where it lists some (`true` runs them all)."""
    listed = case.get("quick")
    if quick and isinstance(listed, list):
        return [c for c in commands if c in listed]
    return list(commands)


def command_line(gbc, case, command, out):
    """The argv of `command` on `case`, writing into `out`."""
    folder = case["dir"]
    data = [str(folder / d) for d in case["data"]]
    holdout = [f"--holdout={h}" for h in case.get("holdout", [])]
    model, greybox = str(folder / case["model"]), str(folder / case["greybox"])
    if command == "diagnose":
        return [gbc, "diagnose", model, *data, *holdout, "--json", str(out / "diagnose.json")]
    if command == "train_mechanism":
        return [gbc, "train", model, *data, *holdout, "-o", str(out / "mechanism")]
    if command == "train_greybox":
        return [gbc, "train", greybox, *data, *holdout, "-o", str(out / "greybox")]
    # The case's model is the mechanism: the one the diagnosis and the train rows judge by.
    return [gbc, "compare", greybox, *data, *holdout, "--mechanism", model,
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
    """The JSON object at `path`, None when it is missing, unreadable or not an object."""
    try:
        value = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    return value if isinstance(value, dict) else None


def last_lines(log):
    """The last three non-empty lines of a log, joined (the error a command printed)."""
    try:
        text = Path(log).read_text(errors="replace")
    except OSError:
        return None
    lines = [line for line in text.splitlines() if line.strip()]
    return " / ".join(lines[-3:])[:300] or None


# --- rows ---------------------------------------------------------------------------------

def blank_row(case, command, source="run"):
    """A row with nothing known yet; `source`: `run` (a command ran) or `compare` (read
    from compare's report)."""
    return {
        "record": case["name"], "kind": case["kind"], "command": command, "source": source,
        "status": "ok", "finished": None, "exit_code": None, "seconds": 0.0,
        "cap_seconds": 0, "verdict": None, "significant": None, "mechanism_error": None,
        "greybox_error": None, "naive_error": None, "right": None, "undecided": False,
        "params_estimated": 0, "params_identified": 0, "params_within_3se": 0,
        "fits_unreported": 0, "message": None,
        "withheld": (len((case.get("answer") or {}).get("withheld") or [])
                     if case["kind"] != "real" else None),
    }


def fail(row, message):
    """Marks `row` failed with `message`: it stays in every count, as failed."""
    row.update(status="failed", right=None, message=message)
    return row


def skipped(case, command, why):
    """The row of a command that does not apply to a case (outside every count)."""
    row = blank_row(case, command)
    row.update(status="n/a", verdict=why)
    return row


def row_for(case, command, code, seconds, cap, out, log, mechanism_error=None):
    """One row of a command that ran: its status, then what its report says. A command
    that exited 0 but left no readable report failed."""
    row = blank_row(case, command)
    row.update(finished=code is not None, exit_code=code, seconds=round(seconds, 1),
               cap_seconds=cap)
    if code is None:
        row.update(status="capped", message=f"stopped at its cap of {cap} s")
        return row
    if code != 0:
        return fail(row, last_lines(log) or f"exit {code}")
    fill = {"diagnose": fill_diagnose, "compare": fill_compare}.get(command, fill_train)
    report_path = fill(row, case, out, mechanism_error)
    if report_path is not None:
        fail(row, f"exit 0 but no readable report at {report_path.name}")
    return row


def fill_diagnose(row, case, out, _mechanism_error):
    """Fills a diagnose row from its report; the report's path when it is unusable."""
    path = out / "diagnose.json"
    report = load(path)
    if report is None or report.get("partial") or "selection" not in report:
        return path
    row.update(judge_diagnosis(report, case.get("answer")))
    # A diagnosis's "mechanism" is the base model's held-out gap, its "grey box" the
    # credited set's.
    row["mechanism_error"] = number(report.get("gap_before"))
    row["greybox_error"] = number((report.get("selection") or {}).get("gap_after"))
    return None


def fill_compare(row, case, out, _mechanism_error):
    """Fills a compare row from its report; the report's path when it is unusable."""
    path = out / "compare.json"
    report = load(path)
    overall = (report or {}).get("overall")
    if not isinstance(overall, dict):
        return path
    score = lambda key: number((overall.get(key) or {}).get("error"))
    row.update(mechanism_error=score("mechanism"), greybox_error=score("grey_box"),
               naive_error=score("naive"))
    row["verdict"] = (overall.get("verdict") or {}).get("standing")
    row["right"] = judge_greybox(row["greybox_error"], row["mechanism_error"],
                                 row["naive_error"], case.get("answer"))
    return None


def fill_train(row, case, out, mechanism_error):
    """Fills a `gbc train` row from its run.json; the file's path when it is unusable.
    The grey box is judged against `mechanism_error`, the same case model's fit; `gbc
    train` has no naive forecast, so that judgement is left open (unjudged)."""
    folder = out / ("mechanism" if row["command"] == "train_mechanism" else "greybox")
    info = load(folder / "run.json")
    if info is None:
        return folder / "run.json"
    online = (info.get("metrics") or {}).get("online") or {}
    error = number(online.get("overall"))
    truth = (case.get("answer") or {}).get("params") or {}
    estimated, identified, within = param_checks(info.get("estimates"), truth)
    row.update(params_estimated=estimated, params_identified=identified,
               params_within_3se=within)
    if row["command"] == "train_mechanism":
        row.update(mechanism_error=error, verdict="fitted")
    else:
        row.update(greybox_error=error, mechanism_error=mechanism_error,
                   verdict=trained_epochs(info))
        row["right"] = judge_greybox(error, mechanism_error, None, case.get("answer"))
    return None


def trained_epochs(info):
    """What a grey-box run trained: the stop cross-validation chose, or every epoch."""
    epochs = (info.get("training") or {}).get("epochs")
    toward = info.get("toward_mechanism") or {}
    choice = toward.get("choice")
    if choice:
        return f"stopped at epoch {choice.get('chosen')} of {choice.get('epochs')}"
    if toward.get("unchosen"):
        return f"{epochs} epochs (no stop chosen)"
    return f"{epochs} epochs"


# --- the train rows, from compare's report --------------------------------------------------

def mean_error(member):
    """A compare member run's mean held-out error, None when it failed or scored none;
    infinite when a free run diverged."""
    if not member or member.get("failed"):
        return None
    errors = [number((h.get("error") or {}).get("overall")) for h in member.get("held_out") or []]
    errors = [e for e in errors if e is not None]
    return sum(errors) / len(errors) if errors else None


def train_rows_from_compare(case, compare_row, report):
    """The train_mechanism and train_greybox rows of a case, read from compare's report:
    its mechanism fit and its grey box's first seed, judged against that same mechanism
    and the naive forecast. When compare failed or was capped, so are they."""
    rows = [blank_row(case, c, source="compare") for c in ("train_mechanism", "train_greybox")]
    if compare_row["status"] != "ok":
        for row in rows:
            row.update(status=compare_row["status"], message=f"compare {compare_row['status']}")
        return rows
    mechanism_row, greybox_row = rows
    split = ((report or {}).get("splits") or [{}])[0]
    mechanism = split.get("mechanism") or {}
    mechanism_row.update(mechanism_error=mean_error(mechanism), verdict="fitted",
                         seconds=round(number(mechanism.get("seconds")) or 0.0, 1))
    if mechanism.get("failed"):
        fail(mechanism_row, f"the fit failed: {mechanism['failed']}")
    first = (split.get("grey_box") or [{}])[0]
    greybox_row.update(
        greybox_error=mean_error(first), mechanism_error=mechanism_row["mechanism_error"],
        naive_error=compare_row["naive_error"],
        seconds=round(number(first.get("seconds")) or 0.0, 1),
        verdict=f"seed {first.get('seed')}: {first.get('epochs')} epochs")
    greybox_row["right"] = judge_greybox(greybox_row["greybox_error"],
                                         greybox_row["mechanism_error"],
                                         greybox_row["naive_error"], case.get("answer"))
    if first.get("failed") or not first:
        fail(greybox_row, f"the training failed: {first.get('failed', 'no run')}")
    return rows


# --- judging ------------------------------------------------------------------------------

def judge_greybox(greybox, mechanism, naive, answer):
    """Whether a grey box's held-out error is right: finite, not above the naive
    forecast's, within TOLERANCE of the mechanism's, and below it where the truth has
    effects the mechanism lacks. None (unjudged) for a real record, or when the mechanism's
    or the naive forecast's error is unknown; False when the grey box has none."""
    if answer is None:
        return None
    if greybox is None or not math.isfinite(greybox):
        return False
    if mechanism is None or naive is None:
        return None
    if greybox > naive or greybox > TOLERANCE * mechanism:
        return False
    if answer.get("withheld"):
        return greybox < mechanism
    return True


def credited_text(credited, undecided):
    """The verdict of a diagnosis in words: the credited set, or the sets it cannot tell
    apart."""
    if undecided:
        return "undecided: " + " | ".join(undecided)
    return " + ".join(credited) if credited else "nothing credited"


def judge_diagnosis(report, answer):
    """The diagnose row's verdict (the credited set), significance, rightness and
    identified params (over every fit the verdict rests on)."""
    selection = report.get("selection") or {}
    credited = sorted(selection.get("credited") or [])
    undecided = selection.get("undecided") or []
    judged = {"verdict": credited_text(credited, undecided),
              "significant": report.get("significant"), "undecided": bool(undecided)}
    if answer is None:
        return judged
    withheld = sorted(answer.get("withheld") or [])
    guessed = guessed_consts(answer)
    if undecided:
        judged["right"] = withheld in [effects_of(s.split(" + "), guessed) for s in undecided]
    else:
        judged["right"] = effects_of(credited, guessed) == withheld
    # A constant the diagnosis refits is judged against its truth where the case knows it.
    truth = {**guessed, **(answer.get("params") or {})}
    totals = [0, 0, 0]
    fits = verdict_fits(report)
    for estimates in fits:
        for k, count in enumerate(param_checks(estimates, truth)):
            totals[k] += count
    judged.update(params_estimated=totals[0], params_identified=totals[1],
                  params_within_3se=totals[2],
                  fits_unreported=sum(1 for e in fits if e is None))
    return judged


def guessed_consts(answer):
    """The constants a case declares as a modeller's guesses, with their truth: a guessed
    `const`, or the `const` a guessed start reads."""
    guesses = answer.get("guesses") or {}
    truth = {name: g.get("truth") for name, g in (guesses.get("consts") or {}).items()}
    for guess in (guesses.get("starts") or {}).values():
        if guess.get("const"):
            truth[guess["const"]] = guess.get("truth")
    return truth


def effects_of(names, guessed):
    """The effects among a credited set's names, sorted. A constant the diagnosis refits
    (`refit NAME`) that the case declares a guess is a recalibration, not an effect, and
    drops out; a refit of a constant the case holds exact stays in, so the verdict is
    wrong (the data contradict nothing there)."""
    names = [n.strip() for n in names]
    return sorted(n for n in names
                  if not (n.startswith(REFIT) and n[len(REFIT):] in guessed))


def verdict_fits(report):
    """The estimates of every fit a diagnosis's verdict rests on (None for a fit the
    report does not hold): each named set's where it is undecided, the credited set's
    where it credits one (pairs included), the base fit where it credits nothing."""
    selection = report.get("selection") or {}
    undecided = selection.get("undecided") or []
    if undecided:
        return [set_fit(report, s.split(" + ")) for s in undecided]
    credited = selection.get("credited") or []
    if credited:
        return [set_fit(report, credited)]
    return [(report.get("base_fit") or {}).get("estimates")]


def set_fit(report, names):
    """The estimates of the fit of the effects `names` together: a selection step's fit,
    or for one effect its own fit; None when the report holds neither."""
    wanted = sorted(n.strip() for n in names)
    for step in (report.get("selection") or {}).get("steps") or []:
        fit = step.get("fit")
        if sorted(step.get("effects") or []) == wanted and isinstance(fit, dict):
            return fit.get("estimates")
    if len(wanted) == 1:
        for effect in report.get("effects") or []:
            if effect.get("name") == wanted[0] and isinstance(effect.get("fit"), dict):
                return effect["fit"].get("estimates")
    return None


def param_checks(estimates, truth):
    """(estimated, identified, within WITHIN standard errors of the truth) over the params
    whose truth is known. Identified: reported identified, not `held`, with a finite
    positive standard error."""
    estimated = identified = within = 0
    for estimate in estimates or []:
        name = estimate.get("name")
        if name not in truth:
            continue
        estimated += 1
        error = number(estimate.get("std_error"))
        value = number(estimate.get("value"))
        if (not estimate.get("identified") or estimate.get("held")
                or error is None or not math.isfinite(error) or error <= 0):
            continue
        identified += 1
        if value is not None and abs(value - truth[name]) <= WITHIN * error:
            within += 1
    return estimated, identified, within


# --- the table and the summary --------------------------------------------------------------

def fmt(value):
    """A cell: – for nothing, yes/no for a flag, 3 significant digits for a number."""
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.3g}"
    return str(value)


def right_cell(row):
    """The right column: yes/no, unjudged, or why there is no answer."""
    if row["status"] in ("failed", "capped") and row["kind"] != "real":
        return f"no ({row['status']})" if row["command"] in JUDGED else "–"
    if row["kind"] == "real" or row["status"] == "n/a" or row["command"] not in JUDGED:
        return "–"
    if row["undecided"]:
        return "undecided (right set named)" if row["right"] else "no (undecided)"
    return "unjudged" if row["right"] is None else fmt(row["right"])


def params_cell(row):
    """The params column: identified of estimated (truth known), within 3 SE, and the
    fits the report does not hold."""
    if not row["params_estimated"] and not row["fits_unreported"]:
        return "–"
    text = (f"{row['params_identified']} of {row['params_estimated']} "
            f"({row['params_within_3se']} within 3 SE)")
    if row["fits_unreported"]:
        text += f"; {row['fits_unreported']} fit(s) not reported"
    return text


COLUMNS = ["record", "command", "status", "exit", "s", "verdict", "significant",
           "mechanism", "grey box", "naive", "right", "params identified"]


def table_line(row):
    """One row of the markdown table."""
    verdict = row["verdict"] if row["status"] in ("ok", "n/a") else row["message"]
    if row["source"] == "compare" and verdict:
        verdict = f"{verdict} (from compare)"
    cells = [row["record"], row["command"], row["status"], fmt(row["exit_code"]),
             fmt(row["seconds"]), fmt(verdict), fmt(row["significant"]),
             fmt(row["mechanism_error"]), fmt(row["greybox_error"]), fmt(row["naive_error"]),
             right_cell(row), params_cell(row)]
    return "| " + " | ".join(c.replace("|", "/") for c in cells) + " |"


def markdown(rows):
    """The table, then the summary counts."""
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += [table_line(r) for r in rows]
    return "\n".join(lines + ["", summary(rows)])


def tally(rows):
    """Counts of one command's rows: every run, failed and capped among them; over the
    scenarios (every row that ran, failed and capped included) right, undecided naming the
    right set, and unjudged; the params identified."""
    ran = [r for r in rows if r["status"] != "n/a"]
    judged = [r for r in ran if r["kind"] != "real"]
    count = lambda rs, test: sum(1 for r in rs if test(r))
    ok = lambda r: r["status"] == "ok"
    return {
        "runs": len(ran), "not_applicable": len(rows) - len(ran),
        "failed": count(ran, lambda r: r["status"] == "failed"),
        "capped": count(ran, lambda r: r["status"] == "capped"),
        "scenarios": len(judged),
        "right": count(judged, lambda r: ok(r) and r["right"] and not r["undecided"]),
        "undecided_right": count(judged, lambda r: ok(r) and r["right"] and r["undecided"]),
        "unjudged": count(judged, lambda r: ok(r) and r["right"] is None),
        "failed_scenarios": count(judged, lambda r: r["status"] == "failed"),
        "capped_scenarios": count(judged, lambda r: r["status"] == "capped"),
        "estimated": sum(r["params_estimated"] for r in ran),
        "identified": sum(r["params_identified"] for r in ran),
        "within": sum(r["params_within_3se"] for r in ran),
        "unreported": sum(r["fits_unreported"] for r in ran),
        "classes": {size: (count(judged, lambda r, s=size: ok(r) and r["right"] and not r["undecided"]
                                 and class_of(r) == s),
                           count(judged, lambda r, s=size: class_of(r) == s))
                    for size in ("nothing", "one", "two")},
        "nothing_significant": (count(judged, lambda r: class_of(r) == "nothing"
                                      and r["significant"] is True),
                                count(judged, lambda r: class_of(r) == "nothing")),
    }


def class_of(row):
    """`nothing`, `one` or `two` (or more) effects withheld from a scenario's model."""
    withheld = row.get("withheld") or 0
    return ("nothing", "one")[withheld] if withheld < 2 else "two"


def summary_line(command, t):
    """One command's summary: every denominator holds its failed and capped rows."""
    apart = [f"{t['failed_scenarios']} failed", f"{t['capped_scenarios']} capped"]
    if t["unjudged"]:
        apart.append(f"{t['unjudged']} unjudged")
    if command == "diagnose":
        apart.append(f"{t['undecided_right']} undecided naming the right set")
    line = (f"- `{command}`: {t['runs']} runs ({t['failed']} failed, {t['capped']} capped"
            + (f", {t['not_applicable']} not applicable" if t["not_applicable"] else "") + ")")
    if command in JUDGED:
        line += f"; right {t['right']} of {t['scenarios']} scenarios ({', '.join(apart)})"
    if command == "diagnose" and t["scenarios"]:
        classes = ", ".join(f"{name} withheld {right}/{total}"
                            for name, (right, total) in t["classes"].items() if total)
        significant, nothing = t["nothing_significant"]
        line += (f"; right by class: {classes}; a gap called significant where nothing is "
                 f"withheld: {significant} of {nothing}")
    if t["estimated"] or t["unreported"]:
        line += (f"; params identified {t['identified']} of {t['estimated']} estimated "
                 f"(truth known), within 3 SE of the truth {t['within']}")
    if t["unreported"]:
        line += f"; {t['unreported']} fit(s) the verdict rests on not in the report"
    return line


def summary(rows):
    """Counts per command."""
    lines = []
    for command in COMMANDS:
        mine = [r for r in rows if r["command"] == command]
        if mine:
            lines.append(summary_line(command, tally(mine)))
    return "\n".join(lines)


# --- running the corpus ---------------------------------------------------------------------

def run_command(gbc, case, command, out, mechanism_error, progress):
    """Runs one command on a case under its cap and returns its row."""
    expected = {**DEFAULT_EXPECTED, **(case.get("expected_seconds") or {})}
    cap = CAP_FACTOR * expected[command]
    log = out / f"{command}.log"
    print(f"{progress} {case['name']}: {command} (cap {cap} s)", file=sys.stderr, flush=True)
    code, seconds = run(command_line(gbc, case, command, out), cap, log)
    return row_for(case, command, code, seconds, cap, out, log, mechanism_error)


def run_case(gbc, case, commands, out, progress):
    """The rows of one case: diagnose, compare, then the train rows, read from compare's
    report where compare ran on the case, from `gbc train` otherwise."""
    rows = []
    if "diagnose" in commands:
        rows.append(run_command(gbc, case, "diagnose", out, None, progress))
    compare_runs = "compare" in commands and bool(case.get("holdout"))
    if "compare" in commands and not compare_runs:
        # One experiment: nothing to hold out, `gbc compare` does not apply.
        rows.append(skipped(case, "compare", "not applicable: no experiment held out"))
    if compare_runs:
        compare_row = run_command(gbc, case, "compare", out, None, progress)
        rows.append(compare_row)
        derived = train_rows_from_compare(case, compare_row, load(out / "compare.json"))
        rows += [r for r in derived if r["command"] in commands]
        return rows
    mechanism_error = None
    for command in ("train_mechanism", "train_greybox"):
        if command in commands:
            row = run_command(gbc, case, command, out, mechanism_error, progress)
            if command == "train_mechanism":
                mechanism_error = row["mechanism_error"]
            rows.append(row)
    return rows


def failures(rows):
    """The rows whose command failed (an error exit, a panic, no readable report)."""
    return [r for r in rows if r["status"] == "failed" and r["source"] == "run"]


def main():
    """Parses the flags, runs every selected case and writes the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="only the cases marked quick (CI)")
    parser.add_argument("--json", type=Path, help="write the rows as JSON here")
    parser.add_argument("--markdown", type=Path, help="write the table here")
    parser.add_argument("--only", nargs="*", help="only these cases, by name")
    parser.add_argument("--commands", nargs="+", default=COMMANDS, choices=COMMANDS,
                        help="the columns to run (default: all; the train rows come from "
                             "compare's report when compare runs)")
    parser.add_argument("--gbc", default=str(ROOT / "target/release/gbc"))
    parser.add_argument("--keep", type=Path, help="keep every output under this folder")
    args = parser.parse_args()
    if not Path(args.gbc).exists():
        subprocess.run(["cargo", "build", "--release", "--quiet"], cwd=ROOT, check=True)
    selected = cases(args.quick, args.only)
    if not selected:
        sys.exit("no case found (bench/corpus/real/*/case.json, scenarios/*/case.json)")
    broken = {c["name"]: contract_problems(c) for c in selected}
    if any(broken.values()):
        sys.exit("cases that break the case contract (bench/corpus/README.md): "
                 + "; ".join(f"{n}: {', '.join(p)}" for n, p in broken.items() if p))
    rows = []
    scratch = Path(tempfile.mkdtemp(prefix="gbc-corpus-"))
    for index, case in enumerate(selected, 1):
        out = (args.keep or scratch) / case["name"]
        shutil.rmtree(out, ignore_errors=True)
        out.mkdir(parents=True)
        commands = case_commands(case, args.commands, args.quick)
        for row in run_case(args.gbc, case, commands, out, f"[{index}/{len(selected)}]"):
            rows.append(row)
            print(f"    {row['command']}: {row['status']}, exit {row['exit_code']}, "
                  f"{row['seconds']} s, verdict {row['verdict']}, right {row['right']}"
                  + (f": {row['message']}" if row["message"] else ""),
                  file=sys.stderr, flush=True)
        if args.json:
            write(args.json, json.dumps(rows, indent=1, default=str))
    finish(args, rows, scratch)


def finish(args, rows, scratch):
    """Prints and writes the table, cleans up, and exits 1 when a command failed."""
    table = markdown(rows)
    print(table)
    if args.markdown:
        write(args.markdown, table + "\n")
    if not args.keep:
        shutil.rmtree(scratch, ignore_errors=True)
    failed = failures(rows)
    if failed:
        print(f"{len(failed)} command(s) failed: "
              + ", ".join(f"{r['record']}/{r['command']} ({r['message']})" for r in failed),
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
