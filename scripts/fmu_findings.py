#!/usr/bin/env python3
"""The tables of docs/findings-fmu.md from two runs' summary.csv: per threshold set, detector and
|pitch-stiffness error| bin, Pd over the faulty flights, Pfa over all flights and the isolation
accuracy, each with its 95 % Wilson interval (the interval fdimc's summaries use).

    fdimc run studies/fmu_aircraft.toml && fdimc run studies/fmu_aircraft_lti.toml
    python3 scripts/fmu_findings.py results/fmu_aircraft results/fmu_aircraft_lti

(`python3 scripts/findings.py fmu_aircraft` runs both decks and writes the table into the page.)
"""
import math
import sys

import polars as pl


def wilson(k, n, z=1.959963984540054):
    if n == 0:
        return float("nan"), float("nan"), float("nan")
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return p, max(0.0, c - h), min(1.0, c + h)


def table(run):
    s = pl.read_csv(f"{run}/summary.csv")
    faulty = s.filter(pl.col("kind") != "none")
    keys = ["thresholds", "detector", "param_error_bin"]
    pd = faulty.group_by(keys).agg(pl.col("detected").sum(), pl.col("trials").sum().alias("faulty"),
                                   pl.col("isolation_decided").sum(), pl.col("isolated_correctly").sum())
    fa = s.group_by(keys).agg(pl.col("false_alarms").sum(), pl.col("trials").sum().alias("flights"))
    return pd.join(fa, on=keys).sort(keys)


def rows(runs):
    """The table's lines, one block of rows per run folder (its name is the "truth" column)."""
    out = [
        "| truth | thresholds | detector | \\|error\\| | Pd [95 % CI] | Pfa [95 % CI] | isolated [95 % CI] |",
        "|---|---|---|---|---|---|---|",
    ]
    for run in runs:
        for r in table(run).iter_rows(named=True):
            cells = []
            for k, n in [(r["detected"], r["faulty"]), (r["false_alarms"], r["flights"])]:
                p, lo, hi = wilson(k, n)
                cells.append(f"{p:.3f} [{lo:.3f}, {hi:.3f}]")
            # Isolation is decided at the deck's thresholds only (the calibrated rows replay alarms).
            if r["thresholds"] == "deck" and r["isolation_decided"] > 0:
                p, lo, hi = wilson(r["isolated_correctly"], r["isolation_decided"])
                cells.append(f"{p:.3f} [{lo:.3f}, {hi:.3f}]")
            else:
                cells.append("-")
            out.append(f"| {str(run).rstrip('/').split('/')[-1]} | {r['thresholds']} | {r['detector']} | "
                       f"{r['param_error_bin']:g} | {' | '.join(cells)} |")
    return out


def main():
    runs = sys.argv[1:] or ["results/fmu_aircraft", "results/fmu_aircraft_lti"]
    print("\n".join(rows(runs)))


if __name__ == "__main__":
    main()
