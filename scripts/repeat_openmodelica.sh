#!/usr/bin/env bash
# Issue 80's OpenModelica reproductions (tests/data/openmodelica/) at a study's size, repeated: each
# deck run REPEATS times (default 10) with TRIALS trials (default 500, the decks' own count or more) at
# default settings, none dying of a signal, each ending as its model allows (the test's comment says
# how). The tests run the same with 24 trials; a crash that shows in one run of four needs this.
#
#   bash scripts/repeat_openmodelica.sh [REPEATS] [TRIALS]
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/fdimc-target}"
FDIMC_OM_REPEATS="${1:-10}" FDIMC_OM_TRIALS="${2:-500}" \
    cargo test --release --locked --test fmu_thirdparty openmodelica_reproductions -- --nocapture
