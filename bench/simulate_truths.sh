#!/usr/bin/env bash
# Simulates every shipped truth model for 400 steps under random input steps with the gbc
# binary GBC into OUTDIR (one CSV per model, hidden states included), for comparing two
# builds with bench/compare_csv.py (docs/performance.md, issue 22).
#   bench/simulate_truths.sh GBC OUTDIR [extra simulate flags]
set -euo pipefail
cd "$(dirname "$0")/.."
GBC=$(realpath "$1"); OUT=$(realpath -m "$2"); shift 2; mkdir -p "$OUT"
for m in models/bioreactor/truth.gbm models/mm_chemostat/truth.gbm models/mm_chemostat/truth_wide.gbm models/diagnose/*/truth*.gbm; do
  inputs=$(grep -E '^input ' $m | awk '{print $2}')
  args=""
  for i in $inputs; do args="$args --input $i=steps(hold=5..40,seed=3)"; done
  tend=400; dt=1
  name=$(echo $m | tr '/' '_')
  /usr/bin/time -f "%e s $name" $GBC simulate $m --t-end $tend --dt $dt $args -o "$OUT/$name.csv" --hidden "$@" 2>&1 | tail -1
done
