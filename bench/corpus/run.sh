#!/usr/bin/env bash
# The corpus runner: `bench/corpus/run.sh [--quick] [--json FILE] [--markdown FILE]`.
# Builds gbc (release) if needed, then runs diagnose, train (mechanism and grey box) and
# compare at default flags on every case of bench/corpus (see run.py and README.md).
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build --release --quiet
exec python3 bench/corpus/run.py "$@"
