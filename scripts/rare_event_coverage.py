#!/usr/bin/env python3
"""Do `fdimc rare-event`'s 95 % importance-sampling intervals cover? (issue 49, item 1)

Two checks, each over fixed seeds, each counting the intervals that are answers (rare_event.csv's
`answer`) and contain the exact probability; a refusal counts as a miss.

1. White outputs of unequal thresholds (three outputs, 20 samples, thresholds splitting the probability
   about 30/30/40), exact in closed form, at 1e-5 and 1e-8: the library test
   `importance_intervals_cover_on_unequal_outputs` with FDIMC_COVERAGE_SEEDS seeds (CI runs 40).
2. The bundled rare-false-alarm deck (studies/seed000_rare_false_alarms.toml, detector seed_x124, its
   thresholds scaled by 1.12 and 1.14; the scales are our choice), exact from `fdimc design`'s Sidak and
   Bonferroni bounds on a copy of the deck with the thresholds scaled (they agree to 1e-6 there):
   5.2933e-8 and 2.2798e-8 per 10 s trial; 20,000 trials per seed, as the command's default.

Usage: python3 scripts/rare_event_coverage.py [--seeds 200] [--skip-white] [--skip-deck]
Exit 1 when either check covers in fewer than 90 % of the seeds at some level.
Takes about 1 minute (white) and 2.2 s per seed (deck) on 2 cores.
"""

import argparse
import csv
import json
import os
import re
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DECK = os.path.join(ROOT, "studies", "seed000_rare_false_alarms.toml")
DETECTOR = "seed_x124"
SCALES = [1.12, 1.14]


def target_dir():
    out = subprocess.run(["cargo", "metadata", "--format-version", "1", "--no-deps"], cwd=ROOT,
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out)["target_directory"]


def white(seeds):
    env = dict(os.environ, FDIMC_COVERAGE_SEEDS=str(seeds))
    run = subprocess.run(["cargo", "test", "--release", "--locked", "--lib", "importance_intervals_cover",
                          "--", "--nocapture"], cwd=ROOT, env=env, capture_output=True, text=True)
    lines = [l for l in run.stdout.splitlines() if l.startswith("importance sampling,")]
    print("white outputs:", lines[0] if lines else run.stdout[-2000:] + run.stderr[-2000:])
    # A filter that matches no test passes quietly: the check ran only if it printed its line.
    return run.returncode == 0 and len(lines) == 1


def scaled_deck(scale, folder):
    text = open(DECK).read()

    def times(m):
        return "thresholds = [" + ", ".join(repr(float(v) * scale) for v in m.group(1).split(",")) + "]"

    path = os.path.join(folder, f"scaled_{scale}.toml")
    with open(path, "w") as f:
        f.write(re.sub(r"thresholds = \[([^\]]*)\]", times, text))
    return path


def exact(fdimc, scale, folder):
    out = subprocess.run([fdimc, "design", scaled_deck(scale, folder), "--json"], check=True,
                         capture_output=True, text=True).stdout
    d = next(d for d in json.loads(out)["detectors"] if d["name"] == DETECTOR)
    fa = d["false_alarms_at_deck_thresholds"]
    assert fa["upper"] / fa["lower"] < 1.0001, fa
    return 0.5 * (fa["upper"] + fa["lower"])


def deck(fdimc, seeds):
    ok = True
    with tempfile.TemporaryDirectory() as folder:
        truth = {s: exact(fdimc, s, folder) for s in SCALES}
        print("deck: exact per trial", {s: f"{p:.4e}" for s, p in truth.items()})
        covered = {s: 0 for s in SCALES}
        answered = {s: 0 for s in SCALES}
        ratios = {s: [] for s in SCALES}
        out = os.path.join(folder, "run")
        for seed in range(1, seeds + 1):
            subprocess.run([fdimc, "rare-event", DECK, "--levels", ",".join(map(str, SCALES)), "--detector",
                            DETECTOR, "--trials", "20000", "--seed", str(seed), "--quiet", "--out", out],
                           check=True, capture_output=True)
            with open(os.path.join(out, "rare_event.csv")) as f:
                for row in csv.DictReader(f):
                    s = float(row["threshold_scale"])
                    p = truth[s]
                    answer = row["answer"] == "true"
                    answered[s] += answer
                    covered[s] += answer and float(row["pfa_per_trial_lo"]) <= p <= float(row["pfa_per_trial_hi"])
                    ratios[s].append(float(row["pfa_per_trial"]) / p)
        for s in SCALES:
            r = sorted(ratios[s])
            print(f"deck, scale {s}: {covered[s]} of {seeds} answers cover ({answered[s]} answers); "
                  f"estimate / exact: median {r[len(r) // 2]:.3f}, mean {sum(r) / len(r):.3f}, max {r[-1]:.3f}")
            ok &= covered[s] >= 0.9 * seeds
    return ok


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=200)
    ap.add_argument("--skip-white", action="store_true")
    ap.add_argument("--skip-deck", action="store_true")
    a = ap.parse_args()
    ok = True
    if not a.skip_white:
        ok &= white(a.seeds)
    if not a.skip_deck:
        subprocess.run(["cargo", "build", "--release", "--locked", "--bin", "fdimc"], cwd=ROOT, check=True)
        ok &= deck(os.path.join(target_dir(), "release", "fdimc"), a.seeds)
    print("covered" if ok else "NOT COVERED: fewer than 90 % of the seeds")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
