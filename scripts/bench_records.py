#!/usr/bin/env python3
"""What the recorded first-passage profiles cost, and what they keep (issue 48): runs one deck at several
profile resolutions (`fdimc run --profile-resolution R`) and, for each, measures the time of each phase
(the trials, the summary, the report), the peak memory of each, the bytes of trials.parquet per trial and
detector, and checks against the first resolution given that the calibrated thresholds are identical to
the byte and that every column of summary.csv but the calibrated sets' delays is equal.

    pip install polars
    python3 scripts/bench_records.py [--fdimc BIN] [--deck DECK] [--trials N] [--resolutions 0,0.05,1]
                                     [--out DIR] [--no-report]

Defaults: the robustness deck (24,000 trials, 4 detectors) at 0 (full profiles), 0.05 (the default) and
1 (lean). A table in Markdown goes to stdout; docs/outputs.md and docs/performance.md give its figures
with the machine and the date. Scaling figures: --trials 100000, 1000000, ... with --resolutions 1.
"""
import argparse
import os
import re
import shutil
import subprocess
import sys
import time

import polars as pl


def timed(cmd):
    """Runs cmd under /usr/bin/time -v: (stdout, wall s, peak RSS MB)."""
    t0 = time.time()
    p = subprocess.run(["/usr/bin/time", "-v"] + cmd, capture_output=True, text=True)
    wall = time.time() - t0
    if p.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({p.returncode}):\n{p.stdout[-2000:]}\n{p.stderr[-2000:]}")
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", p.stderr)
    return p.stdout, wall, int(rss.group(1)) / 1024 if rss else float("nan")


def folder_bytes(d):
    return sum(os.path.getsize(os.path.join(r, f)) for r, _, fs in os.walk(d) for f in fs)


def main():
    default_bin = os.path.join(os.environ.get("CARGO_TARGET_DIR", "target"), "release", "fdimc")
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--fdimc", default=default_bin)
    ap.add_argument("--deck", default="studies/seed000_robustness.toml")
    ap.add_argument("--trials", type=int)
    ap.add_argument("--resolutions", default="0,0.05,1")
    ap.add_argument("--out", default="results/bench_records")
    ap.add_argument("--no-report", action="store_true", help="skip `fdimc report` (its plots)")
    a = ap.parse_args()
    if shutil.which("/usr/bin/time") is None:
        sys.exit("needs /usr/bin/time (Debian: apt-get install time)")
    rows, first = [], None
    for r in a.resolutions.split(","):
        out = os.path.join(a.out, f"r{r}")
        cmd = [a.fdimc, "run", a.deck, "--out", out, "--force", "--profile-resolution", r]
        if a.trials:
            cmd += ["--trials", str(a.trials)]
        stdout, run_wall, run_rss = timed(cmd)
        m = re.search(r"x (\d+) detector\(s\) in ([\d.]+) s", stdout)
        detectors, trials_s = int(m.group(1)), float(m.group(2))
        _, summarize_wall, summarize_rss = timed([a.fdimc, "summarize", out])
        report_wall = report_rss = float("nan")
        if not a.no_report:
            _, report_wall, report_rss = timed([a.fdimc, "report", out])
        records = os.path.getsize(os.path.join(out, "trials.parquet"))
        n_rows = pl.scan_parquet(os.path.join(out, "trials.parquet")).select(pl.len()).collect().item()
        check = ""
        if first is None:
            first = out
        else:
            same = open(os.path.join(first, "thresholds.csv"), "rb").read() == open(
                os.path.join(out, "thresholds.csv"), "rb").read()
            x = pl.read_csv(os.path.join(first, "summary.csv"), infer_schema_length=0)
            y = pl.read_csv(os.path.join(out, "summary.csv"), infer_schema_length=0)
            cal = x["thresholds"] == "calibrated"
            differ = [c for c in x.columns
                      if not (x[c].filter(~cal).equals(y[c].filter(~cal))
                              and (c.startswith("delay_") or x[c].filter(cal).equals(y[c].filter(cal))))]
            check = f"thresholds {'identical' if same else 'DIFFER'}; " + (
                "summary equal but calibrated delays" if not differ else f"summary DIFFERS in {differ}")
        rows.append((r, n_rows, detectors, trials_s, run_wall, run_rss, summarize_wall, summarize_rss,
                     report_wall, report_rss, records, folder_bytes(out), check))
        print(f"resolution {r}: {records / n_rows:.0f} B per row, run {run_wall:.1f} s, {check}", file=sys.stderr)
    print("| profile resolution | rows | trials (s) | run incl. summary: wall s / peak MB | summarize: s / MB "
          "| report: s / MB | trials.parquet | B per trial x detector | folder | against the first |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for (r, n, d, ts, rw, rr, sw, sr, pw, pr, rec, folder, check) in rows:
        print(f"| {r} | {n:,} | {ts:.1f} | {rw:.1f} / {rr:.0f} | {sw:.1f} / {sr:.0f} | {pw:.1f} / {pr:.0f} "
              f"| {rec / 1e6:.1f} MB | {rec / n:.0f} | {folder / 1e6:.1f} MB | {check or '-'} |")


if __name__ == "__main__":
    main()
