"""Tests of the corpus runner's scoring (issue 43): fabricated reports and rows, and a fake
`gbc` in a temporary folder; no gbc binary is needed.

Run: `python3 -m unittest bench/corpus/test_run.py` (or pytest).
"""

import contextlib
import importlib.util
import io
import json
import stat
import sys
import tempfile
import textwrap
import unittest
from pathlib import Path

HERE = Path(__file__).resolve().parent
_SPEC = importlib.util.spec_from_file_location("corpus_run", HERE / "run.py")
run = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(run)


def scenario(folder, withheld=(), params=None, name="s99"):
    """A scenario case in `folder` with this answer."""
    return {"name": name, "kind": "scenario", "model": "model.gbm", "greybox": "greybox.gbm",
            "data": ["data.csv"], "holdout": ["B2"], "dir": Path(folder),
            "expected_seconds": {c: 5 for c in run.COMMANDS},
            "answer": {"withheld": list(withheld), "params": params or {}}}


def estimate(name, value, std_error, identified=True, held=None):
    """A param estimate as gbc writes it (`held` left out when None: older files)."""
    out = {"name": name, "value": value, "std_error": std_error,
           "relative_error": None, "identified": identified}
    if held is not None:
        out["held"] = held
    return out


def diagnosis(credited=(), undecided=(), significant=True, steps=(), effects=(), base=()):
    """A diagnosis report with the fields the runner reads."""
    return {"model": "m", "gap_before": 0.1, "significant": significant,
            "effects": list(effects), "base_fit": {"estimates": list(base)},
            "selection": {"credited": list(credited), "undecided": list(undecided),
                          "steps": list(steps), "gap_after": 0.05}}


def compare_report(mechanism, greybox, naive, failed=None):
    """A compare report: one split, one seed."""
    def member(seed, error, epochs):
        run_ = {"seed": seed, "seconds": 1.0, "params": [], "epochs": epochs,
                "held_out": [{"experiment": "B2", "error": {"overall": error}}]}
        if failed and seed:
            run_["failed"] = failed
        return run_
    score = lambda e: {"error": e, "runs": 1, "failed": 0}
    return {"splits": [{"held_out": ["B2"], "mechanism": member(0, mechanism, 0),
                        "grey_box": [member(1, greybox, 100)]}],
            "overall": {"mechanism": score(mechanism), "grey_box": score(greybox),
                        "naive": score(naive), "verdict": {"standing": "worse"}}}


class Folder(unittest.TestCase):
    """A temporary folder per test."""

    def setUp(self):
        self._tmp = tempfile.TemporaryDirectory()
        self.dir = Path(self._tmp.name)
        self.log = self.dir / "x.log"
        self.log.write_text("")

    def tearDown(self):
        self._tmp.cleanup()

    def fake_gbc(self, reports):
        """A fake `gbc` that exits 0 and writes, for each subcommand, the report given
        (`reports[subcommand]`, JSON or None for nothing) to the path after --json/-o."""
        (self.dir / "reports.json").write_text(json.dumps(reports))
        script = self.dir / "gbc"
        script.write_text(textwrap.dedent(f"""\
            #!{sys.executable}
            import json, sys, pathlib
            reports = json.loads(pathlib.Path({str(self.dir / 'reports.json')!r}).read_text())
            args = sys.argv[1:]
            report = reports.get(args[0])
            if report is not None:
                if "--json" in args:
                    path = pathlib.Path(args[args.index("--json") + 1])
                else:
                    path = pathlib.Path(args[args.index("-o") + 1]) / "run.json"
                    path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(json.dumps(report))
            """))
        script.chmod(script.stat().st_mode | stat.S_IXUSR)
        return str(script)

    def run_case(self, gbc, case, commands):
        """run.run_case with its progress lines swallowed."""
        with contextlib.redirect_stderr(io.StringIO()):
            return run.run_case(gbc, case, commands, self.dir, "[1/1]")


class MissingReport(Folder):
    def test_exit_zero_without_report_is_a_failure_in_the_denominator(self):
        case = scenario(self.dir)  # nothing withheld: "nothing credited" would be right
        row = run.row_for(case, "diagnose", 0, 1.0, 50, self.dir, self.log)
        self.assertEqual(row["status"], "failed")
        self.assertIsNone(row["right"])
        self.assertIn("no readable report", row["message"])
        (self.dir / "diagnose.json").write_text(json.dumps(diagnosis()))
        ok = run.row_for(case, "diagnose", 0, 1.0, 50, self.dir, self.log)
        self.assertTrue(ok["right"])
        tally = run.tally([row, ok])
        self.assertEqual((tally["right"], tally["scenarios"], tally["failed"]), (1, 2, 1))
        self.assertIn("right 1 of 2 scenarios (1 failed, 0 capped",
                      run.summary([row, ok]))
        self.assertEqual(run.failures([row, ok]), [row])

    def test_classes_and_significance_where_nothing_is_withheld(self):
        case = scenario(self.dir)  # nothing withheld
        (self.dir / "diagnose.json").write_text(json.dumps(diagnosis()))
        quiet = run.row_for(case, "diagnose", 0, 1.0, 50, self.dir, self.log)
        quiet["significant"] = False
        loud = dict(quiet, significant=True)
        wrong_pair = dict(quiet, withheld=2, right=False)
        tally = run.tally([quiet, loud, wrong_pair])
        self.assertEqual(tally["classes"], {"nothing": (2, 2), "one": (0, 0), "two": (0, 1)})
        self.assertEqual(tally["nothing_significant"], (1, 2))
        self.assertIn("nothing withheld 2/2, two withheld 0/1; a gap called significant where "
                      "nothing is withheld: 1 of 2", run.summary([quiet, loud, wrong_pair]))

    def test_unreadable_or_partial_report_is_a_failure(self):
        case = scenario(self.dir)
        (self.dir / "diagnose.json").write_text("{not json")
        row = run.row_for(case, "diagnose", 0, 1.0, 50, self.dir, self.log)
        self.assertEqual(row["status"], "failed")
        (self.dir / "diagnose.json").write_text(json.dumps({**diagnosis(), "partial": "stopped"}))
        row = run.row_for(case, "diagnose", 0, 1.0, 50, self.dir, self.log)
        self.assertEqual(row["status"], "failed")
        (self.dir / "compare.json").write_text("[]")
        row = run.row_for(case, "compare", 0, 1.0, 50, self.dir, self.log)
        self.assertEqual(row["status"], "failed")

    def test_fake_gbc_writing_nothing_fails_every_row(self):
        case = scenario(self.dir)
        gbc = self.fake_gbc({})
        rows = self.run_case(gbc, case, run.COMMANDS)
        self.assertEqual([r["command"] for r in rows], run.COMMANDS)
        self.assertEqual({r["status"] for r in rows}, {"failed"})
        # Only the commands that ran fail the run; the train rows read compare's report.
        self.assertEqual([r["command"] for r in run.failures(rows)], ["diagnose", "compare"])
        self.assertIn("right 0 of 1 scenarios (1 failed", run.summary(rows))

    def test_fake_gbc_runs_the_diagnose_column_alone(self):
        case = scenario(self.dir)
        gbc = self.fake_gbc({"diagnose": diagnosis()})
        rows = self.run_case(gbc, case, ["diagnose"])
        self.assertEqual([(r["command"], r["status"], r["right"]) for r in rows],
                         [("diagnose", "ok", True)])

    def test_fake_gbc_without_compare_runs_train_and_leaves_it_unjudged(self):
        case = scenario(self.dir)
        info = {"metrics": {"online": {"overall": 0.1}}, "training": {"epochs": 5}}
        gbc = self.fake_gbc({"train": info})
        rows = self.run_case(gbc, case, ["train_mechanism", "train_greybox"])
        self.assertEqual([r["status"] for r in rows], ["ok", "ok"])
        self.assertEqual(rows[1]["mechanism_error"], 0.1)
        self.assertIsNone(rows[1]["right"])  # no naive forecast: not counted right
        self.assertIn("right 0 of 1 scenarios (0 failed, 0 capped, 1 unjudged)",
                      run.summary(rows))


class Capped(Folder):
    def test_capped_row_stays_in_the_denominator(self):
        case = scenario(self.dir)
        (self.dir / "compare.json").write_text(json.dumps(compare_report(0.1, 0.05, 0.5)))
        right = run.row_for(case, "compare", 0, 1.0, 50, self.dir, self.log)
        capped = run.row_for(case, "compare", None, 50.0, 50, self.dir, self.log)
        self.assertTrue(right["right"])
        self.assertEqual(capped["status"], "capped")
        self.assertIn("right 1 of 2 scenarios (0 failed, 1 capped)",
                      run.summary([right, capped]))
        self.assertEqual(run.failures([right, capped]), [])
        self.assertEqual(run.right_cell(capped), "no (capped)")

    def test_train_rows_of_a_capped_compare_are_capped(self):
        case = scenario(self.dir)
        capped = run.row_for(case, "compare", None, 50.0, 50, self.dir, self.log)
        rows = run.train_rows_from_compare(case, capped, None)
        self.assertEqual([r["status"] for r in rows], ["capped", "capped"])
        self.assertIn("right 0 of 1 scenarios (0 failed, 1 capped)", run.summary(rows))


class Naive(Folder):
    def test_greybox_worse_than_naive_is_not_right(self):
        answer = {"withheld": [], "params": {}}
        # s14: the grey box within the mechanism's tolerance, but worse than naive.
        self.assertFalse(run.judge_greybox(0.057, 0.055, 0.018, answer))
        self.assertTrue(run.judge_greybox(0.057, 0.055, 0.5, answer))
        self.assertIsNone(run.judge_greybox(0.057, 0.055, None, answer))
        self.assertFalse(run.judge_greybox(float("inf"), 0.055, 0.5, answer))
        self.assertIsNone(run.judge_greybox(0.01, 0.055, 0.5, None))

    def test_compare_row_shows_naive_and_judges_by_it(self):
        case = scenario(self.dir)
        (self.dir / "compare.json").write_text(json.dumps(compare_report(0.055, 0.057, 0.018)))
        row = run.row_for(case, "compare", 0, 1.0, 50, self.dir, self.log)
        self.assertEqual(row["naive_error"], 0.018)
        self.assertFalse(row["right"])
        self.assertIn("| 0.018 | no |", run.table_line(row))

    def test_train_rows_judge_against_compares_mechanism(self):
        case = scenario(self.dir)
        report = compare_report(0.0488, 0.05, 0.018)
        (self.dir / "compare.json").write_text(json.dumps(report))
        compare_row = run.row_for(case, "compare", 0, 1.0, 50, self.dir, self.log)
        mechanism, greybox = run.train_rows_from_compare(case, compare_row, report)
        self.assertEqual(mechanism["mechanism_error"], compare_row["mechanism_error"])
        self.assertEqual(greybox["mechanism_error"], 0.0488)
        self.assertFalse(greybox["right"])  # worse than naive
        self.assertEqual(run.command_line("gbc", case, "compare", self.dir)[-4:-2],
                         ["--mechanism", str(self.dir / "model.gbm")])

    def test_failed_seed_fails_the_train_row_not_the_run(self):
        case = scenario(self.dir)
        report = compare_report(0.05, 0.04, 0.5, failed="diverged")
        (self.dir / "compare.json").write_text(json.dumps(report))
        compare_row = run.row_for(case, "compare", 0, 1.0, 50, self.dir, self.log)
        rows = run.train_rows_from_compare(case, compare_row, report)
        self.assertEqual(rows[1]["status"], "failed")
        self.assertEqual(run.failures([compare_row, *rows]), [])


class VerdictColumns(Folder):
    def test_verdict_is_the_credited_set_and_significance_is_apart(self):
        case = scenario(self.dir, withheld=["a"])
        (self.dir / "diagnose.json").write_text(json.dumps(
            diagnosis(credited=["a"], significant=False)))
        row = run.row_for(case, "diagnose", 0, 1.0, 50, self.dir, self.log)
        self.assertEqual(row["verdict"], "a")
        self.assertIs(row["significant"], False)
        self.assertTrue(row["right"])
        cells = [c.strip() for c in run.table_line(row).strip("|").split("|")]
        self.assertEqual(cells[run.COLUMNS.index("verdict")], "a")
        self.assertEqual(cells[run.COLUMNS.index("significant")], "no")
        self.assertEqual(cells[run.COLUMNS.index("right")], "yes")

    def test_undecided_and_nothing_credited(self):
        self.assertEqual(run.credited_text([], ["a", "b + c"]), "undecided: a | b + c")
        self.assertEqual(run.credited_text([], []), "nothing credited")
        judged = run.judge_diagnosis(diagnosis(undecided=["a", "b + c"]),
                                     {"withheld": ["c", "b"], "params": {}})
        self.assertTrue(judged["right"] and judged["undecided"])

    def test_a_refitted_constant_is_not_an_effect_and_is_checked_against_its_truth(self):
        fit = {"estimates": [estimate("mu_max", 0.7, 0.01), estimate("X0", 0.5, 0.01)]}
        step = {"effects": ["refit mu_max", "growth_lag", "refit X0"], "fit": fit}
        report = diagnosis(credited=["refit mu_max", "growth_lag", "refit X0"], steps=[step])
        answer = {"withheld": ["growth_lag"], "params": {},
                  "guesses": {"consts": {"mu_max": {"declared": 0.38, "truth": 0.71}},
                              "starts": {"X": {"const": "X0", "declared": 1.0,
                                               "truth": 0.8}}}}
        judged = run.judge_diagnosis(report, answer)
        self.assertTrue(judged["right"])
        self.assertEqual((judged["params_identified"], judged["params_within_3se"]), (2, 1))
        nothing = run.judge_diagnosis(diagnosis(credited=["refit mu_max"], steps=[step]),
                                      {"withheld": [], "params": {}, "guesses": answer["guesses"]})
        self.assertTrue(nothing["right"])
        wrong = run.judge_diagnosis(diagnosis(credited=["refit mu_max"], steps=[step]),
                                    {"withheld": ["growth_lag"], "params": {}})
        self.assertFalse(wrong["right"])
        exact = run.judge_diagnosis(diagnosis(credited=["refit mu_max"], steps=[step]),
                                    {"withheld": [], "params": {}})
        self.assertFalse(exact["right"], "mu_max is exact here: its refit is a wrong credit")

    def test_real_record_shows_the_credited_set_without_right(self):
        case = {**scenario(self.dir), "kind": "real", "answer": None}
        (self.dir / "diagnose.json").write_text(json.dumps(diagnosis(credited=["b", "a"])))
        row = run.row_for(case, "diagnose", 0, 1.0, 50, self.dir, self.log)
        self.assertEqual((row["status"], row["verdict"], row["right"]), ("ok", "a + b", None))
        self.assertEqual(run.right_cell(row), "–")
        self.assertIn("right 0 of 0 scenarios", run.summary([row]))


class Identified(unittest.TestCase):
    truth = {"k1": 1.0, "k2": 2.0, "k3": 3.0}

    def test_pair_fit_counts_and_held_params_do_not(self):
        pair_fit = {"estimates": [
            estimate("k1", 1.1, 0.1),                    # identified, within 3 SE
            estimate("k2", 5.0, 0.1),                    # identified, not within
            estimate("k3", 3.0, None, False, held=True), # held: not identified
            estimate("X@B1", 1.0, 0.1)]}                 # no truth: not counted
        step = {"effects": ["b", "a"], "fit": pair_fit}
        judged = run.judge_diagnosis(diagnosis(credited=["a", "b"], steps=[step]),
                                     {"withheld": ["a", "b"], "params": self.truth})
        self.assertEqual((judged["params_estimated"], judged["params_identified"],
                          judged["params_within_3se"], judged["fits_unreported"]),
                         (3, 2, 1, 0))

    def test_held_flag_without_identified_false_and_zero_error(self):
        estimates = [estimate("k1", 1.0, 0.1, True, held=True),  # held wins
                     estimate("k2", 2.0, 0.0),                   # zero SE
                     estimate("k3", 3.0, None)]                  # no SE
        self.assertEqual(run.param_checks(estimates, self.truth), (3, 0, 0))

    def test_missing_pair_fit_is_reported_not_credited(self):
        judged = run.judge_diagnosis(diagnosis(credited=["a", "b"]),
                                     {"withheld": ["a"], "params": self.truth})
        self.assertEqual((judged["params_identified"], judged["fits_unreported"]), (0, 1))
        row = {**run.blank_row({"name": "s", "kind": "scenario"}, "diagnose"), **judged}
        self.assertIn("1 fit(s) not reported", run.params_cell(row))

    def test_undecided_counts_each_set_and_nothing_credited_the_base(self):
        single = {"name": "a", "fit": {"estimates": [estimate("k1", 1.0, 0.1)]}}
        pair = {"effects": ["b", "c"], "fit": {"estimates": [estimate("k2", 2.0, 0.1),
                                                             estimate("k3", 3.0, 0.1)]}}
        report = diagnosis(undecided=["a", "b + c"], effects=[single], steps=[pair],
                           base=[estimate("k1", 9.0, 0.1)])
        self.assertEqual(run.param_checks(run.verdict_fits(report)[0], self.truth), (1, 1, 1))
        judged = run.judge_diagnosis(report, {"withheld": ["a"], "params": self.truth})
        self.assertEqual((judged["params_identified"], judged["params_within_3se"]), (3, 3))
        base = diagnosis(base=[estimate("k1", 1.0, 0.1), estimate("k2", 2.0, 0.1, False)])
        judged = run.judge_diagnosis(base, {"withheld": [], "params": self.truth})
        self.assertEqual((judged["params_estimated"], judged["params_identified"]), (2, 1))


class Contract(unittest.TestCase):
    """The case contract (README.md) holds on every case, and a break is named."""

    def test_every_case_of_the_corpus_holds_the_contract(self):
        found = run.cases(False, None)
        self.assertGreaterEqual(len(found), 30)
        for case in found:
            self.assertEqual(run.contract_problems(case), [], case["name"])

    def test_quick_commands_are_the_listed_ones(self):
        case = {"quick": ["diagnose", "train_mechanism"]}
        self.assertEqual(run.case_commands(case, run.COMMANDS, True),
                         ["diagnose", "train_mechanism"])
        self.assertEqual(run.case_commands(case, run.COMMANDS, False), run.COMMANDS)
        self.assertEqual(run.case_commands({"quick": True}, ["diagnose"], True), ["diagnose"])

    def test_a_record_of_several_experiments_holding_none_out_breaks_it(self):
        with tempfile.TemporaryDirectory() as folder:
            Path(folder, "data.csv").write_text("experiment,t [h],X [g/L]\nB1,0,1\nB2,0,1\n")
            case = {**scenario(folder), "quick": False, "holdout": []}
            self.assertIn("2 experiments and none held out", run.contract_problems(case))
            case = {**case, "holdout": ["B3"]}
            self.assertIn("held-out B3 is not an experiment of the data",
                          run.contract_problems(case))
            case = {**case, "holdout": ["B1", "B2"]}
            self.assertIn("nothing left to train on", run.contract_problems(case))
            case = {**case, "holdout": ["B2"], "quick": ["diagnose", "fit"]}
            self.assertEqual(run.contract_problems(case),
                             ["`quick` names unknown commands: ['fit']"])


if __name__ == "__main__":
    unittest.main()
