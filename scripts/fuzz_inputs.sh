#!/usr/bin/env bash
# The bad-input fuzz tests at full count (src/methods/bad_input.rs): every bundled deck and flight log
# mutated CASES times (default 20,000 per deck and per log: about 800,000 decks), no panic, every error
# naming the file. `cargo test` runs a sample of them (1,500 per deck, 1,000 per log) on a new seed each
# run; this runs the full count with a new seed each time (printed first, so a failure can be run again
# with FDIMC_FUZZ_SEED=it).
#
#   bash scripts/fuzz_inputs.sh [CASES] [SEED]
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/fdimc-target}"
CASES="${1:-20000}"
SEED="${2:-$(od -An -N6 -tu8 /dev/urandom | tr -d ' ')}"
echo "== fuzzing the bundled decks and logs: $CASES cases each, FDIMC_FUZZ_SEED=$SEED"
LOG=$(mktemp)
FDIMC_FUZZ_CASES="$CASES" FDIMC_FUZZ_SEED="$SEED" \
    cargo test --release --locked --lib bad_input -- --nocapture 2>&1 | tee "$LOG"
# A filter that matches no test passes quietly: the three fuzz tests must have run.
RAN=$(awk '/^test result: ok\./ { n += $4 } END { print n + 0 }' "$LOG")
if [ "$RAN" -lt 3 ]; then
    echo "error: $RAN fuzz tests ran (expected 3): did the filter 'bad_input' stop matching?" >&2
    exit 1
fi
