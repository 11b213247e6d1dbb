#!/usr/bin/env bash
# The corpus runner: `bench/corpus/run.sh [--quick] [--json FILE] [--markdown FILE]`.
# Builds gbc (release) if needed, then runs diagnose and compare at default flags on every
# case of bench/corpus; the train rows (mechanism and grey box) come from compare's report,
# or from `gbc train` where compare does not run (see run.py and README.md).
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build --release --quiet
exec python3 bench/corpus/run.py "$@"
