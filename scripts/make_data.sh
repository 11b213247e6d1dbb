#!/usr/bin/env bash
# Regenerates every shipped data file from the truth models (run from the crate root).
# Each command is also written in the README beside the data it makes.
set -euo pipefail
gbc=${GBC:-target/release/gbc}
chem=models/mm_chemostat
bio=models/bioreactor
# Chemostat, random E0 steps in the paper's range: 1800 samples at 1 s, settled first.
$gbc simulate $chem/truth.gbm --t-end 1799 --dt 1 --warmup 400 \
  --input 'E0=steps(hold=10..60, seed=1)' -o $chem/data/steps.csv
# The same chemostat under a chirp of E0 it never saw in training: 600 samples.
$gbc simulate $chem/truth.gbm --t-end 599 --dt 1 --warmup 400 \
  --input 'E0=chirp(f0=0.002, f1=0.05)' -o $chem/data/chirp.csv
# Stiff chemostat: E0 steps up to 1 (outside the paper's range), for the stiffness check.
$gbc simulate $chem/truth_wide.gbm --t-end 1799 --dt 1 --warmup 400 \
  --input 'E0=steps(lo=0.002, hi=1, hold=10..60, seed=3)' -o $chem/data/stiff.csv
# Bioreactor, random light steps: 3000 samples at 1 h, from the steady state at u = 0.5.
$gbc simulate $bio/truth.gbm --t-end 2999 --dt 1 \
  --input 'u=steps(hold=5..40, seed=1)' -o $bio/data/steps.csv
# A second record with another input seed (validation of free runs).
$gbc simulate $bio/truth.gbm --t-end 2999 --dt 1 \
  --input 'u=steps(hold=5..40, seed=2)' -o $bio/data/steps_seed2.csv
