#!/usr/bin/env bash
# Times `gbc diagnose` on every shipped case of models/diagnose/ (README there) and prints
# one line per case: seconds, credited effects, gap before/after.
#   bench/diagnose_cases.sh GBC OUTDIR
# Data are simulated by the same GBC (models/diagnose/README.md, "Making the data"); the
# lab-like cases (overflow, hidden_biomass, campaign) read their shipped records, made by
# bench/diagnose/*_generate.py with scipy.
set -euo pipefail
GBC=$(realpath "$1"); OUT=$2; mkdir -p "$OUT"; cd "$(dirname "$0")/.."
sim() { "$GBC" simulate "$1" --t-end "$2" --dt 1 --input "$3" --noise 0.01 --seed "$4" -o "$OUT/$5.csv" 2>/dev/null; }
C='E0=steps(hold=10..60, seed=4)'; B='u=steps(hold=5..40, seed=3)'
sim models/diagnose/chemostat/truth.gbm 1200 "$C" 7 chemostat
sim models/diagnose/chemostat/truth_inhibition.gbm 1200 "$C" 7 chemostat_inhibition
sim models/diagnose/chemostat/truth_decay.gbm 1200 "$C" 7 chemostat_decay
sim models/bioreactor/truth.gbm 3000 "$B" 11 bioreactor
sim models/diagnose/bioreactor/truth_death.gbm 3000 "$B" 11 bioreactor_death
sim models/diagnose/chemostat/truth_two.gbm 1200 "$C" 7 chemostat_two
sim models/diagnose/expression/truth.gbm 800 "$B" 11 expression
run() {
  local name=$1; shift
  local start end
  start=$(date +%s.%N)
  "$GBC" diagnose "$@" --json "$OUT/$name.json" > "$OUT/$name.txt" 2> "$OUT/$name.err" || true
  end=$(date +%s.%N)
  python3 - "$name" "$OUT/$name.json" "$(echo "$end - $start" | bc)" <<'PY'
import json, sys
name, path, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
try:
    r = json.load(open(path))
    sel = r.get("selection") or {}
    credited = sel.get("credited") or r.get("credited_set") or ([r["credited"]] if r.get("credited") else [])
    after = sel.get("gap_after", r.get("gap_after", float("nan")))
    print(f"{name:14s} {seconds:7.1f} s  credited {credited}  gap {r['gap_before']:.4g} -> {float(after):.4g}")
except Exception as e:
    print(f"{name:14s} {seconds:7.1f} s  failed ({e})")
PY
}
run lag models/diagnose/chemostat/nolag.gbm "$OUT/chemostat.csv"
run inhibition models/diagnose/chemostat/model.gbm "$OUT/chemostat_inhibition.csv"
run decay models/diagnose/chemostat/model.gbm "$OUT/chemostat_decay.csv"
run control models/diagnose/chemostat/model.gbm "$OUT/chemostat.csv"
run burden models/diagnose/bioreactor/noburden.gbm "$OUT/bioreactor.csv"
run death models/diagnose/bioreactor/nodeath.gbm "$OUT/bioreactor_death.csv"
run two models/diagnose/chemostat/model.gbm "$OUT/chemostat_two.csv"
run expression models/diagnose/expression/nolag.gbm "$OUT/expression.csv"
run overflow models/diagnose/overflow/monod.gbm models/diagnose/overflow/data/overflow.csv --holdout B4
run hidden_biomass models/diagnose/hidden_biomass/norepression.gbm models/diagnose/hidden_biomass/data/hidden_biomass.csv
run campaign models/diagnose/campaign/noshift.gbm models/diagnose/campaign/data/campaign.csv --holdout C9
