#!/usr/bin/env bash
# The conformance suite's studies (tests/fmu_thirdparty.rs) at a longer repeat count: every third-party
# FMU's 2-thread study run REPEATS times (default 100; the tests run 10, the floor) in worker processes
# and as many in process where its runtime allows it (OpenModelica's does not), and issue 80's
# OpenModelica reproductions at TRIALS trials (default 500, the decks' own count or more; the tests run
# 24). A crash that shows in one run of forty needs this.
# The PythonFMU exports are built first (scripts/build_pythonfmu.sh); the one FMPy comparison among these
# tests runs where FMPy is found as tests/support/fmpy.rs says.
#
#   bash scripts/repeat_thirdparty_fmus.sh [REPEATS] [TRIALS]
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/fdimc-target}"
bash scripts/build_pythonfmu.sh "$PWD/target/thirdparty-fmus" >/dev/null
FDIMC_PYTHONFMU_DIR="$PWD/target/thirdparty-fmus" FDIMC_REQUIRE_PYTHONFMU=1 \
    FDIMC_FMU_REPEATS="${1:-100}" FDIMC_OM_TRIALS="${2:-500}" \
    cargo test --release --locked --test fmu_thirdparty -- --nocapture --test-threads 1 \
    openmodelica_reproductions a_two_thread_study every_reference_fmu_flies pythonfmu_exports_fly
