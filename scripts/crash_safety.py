#!/usr/bin/env python3
"""Crash safety as a test (issue 49, item 6): SIGKILL `fdimc run`, `sensitivity`, `rare-event` and
`merge` at many points of their runs, then finish each the way a user would, and check:

1. after every kill, no file under a final name is partial: every Parquet file begins and ends with
   its magic and its footer fits, every CSV parses with one width, every JSON file parses (temporary
   files, named `.<name>.tmp-<pid>` or under `parts/`, may be left: the next run removes them);
2. the finished folder's records and tables are byte-identical to an uninterrupted run's.

Each kill point is a fraction of the uninterrupted command's wall time, spread evenly from 2 % to
110 % (the last ones land in the summaries, or after the end), so the kills fall in every phase:
starting, simulating, writing part files, assembling trials.parquet, summarizing. Each cycle kills a
fresh start, then kills its first resume at half that time, then resumes to the end: two kills a cycle.
`run` and `sensitivity` finish with `--resume`; `rare-event` and `merge`, which have no resume, by
running the same command again.

Usage: python3 scripts/crash_safety.py [--cycles 15] [--keep DIR]
  (15 cycles: up to 30 kills per command, fewer where a resume ends before its kill; 109 in all and
  6.4 min on 2 cores, 2026-12-04; CI runs --cycles 2)
Exit 1 on any partial file or any difference, or when no kill landed.
"""

import argparse
import csv
import filecmp
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def target_dir():
    out = subprocess.run(["cargo", "metadata", "--format-version", "1", "--no-deps"], cwd=ROOT,
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out)["target_directory"]


# Files that say when or how a folder was made, not what it holds: left out of the comparison.
VOLATILE = {".fdimc-lock", "manifest.json", "summarize.json", "rare_event.json"}


def is_temporary(rel):
    name = os.path.basename(rel)
    return ".tmp-" in name or rel.startswith("parts" + os.sep)


def partial_files(folder):
    """Files under a final name that are not whole."""
    bad = []
    for base, _, files in os.walk(folder):
        for f in files:
            path = os.path.join(base, f)
            rel = os.path.relpath(path, folder)
            if is_temporary(rel) or f == ".fdimc-lock":
                continue
            try:
                if f.endswith(".parquet"):
                    with open(path, "rb") as h:
                        data = h.read()
                    footer = int.from_bytes(data[-8:-4], "little") if len(data) >= 12 else -1
                    if data[:4] != b"PAR1" or data[-4:] != b"PAR1" or not 0 < footer <= len(data) - 12:
                        bad.append(rel)
                elif f.endswith(".csv"):
                    with open(path, newline="") as h:
                        text = h.read()
                    rows = list(csv.reader(text.splitlines()))
                    if not text.endswith("\n") or not rows or len({len(r) for r in rows}) != 1:
                        bad.append(rel)
                elif f.endswith(".json"):
                    with open(path) as h:
                        json.load(h)
            except (OSError, ValueError, csv.Error):
                bad.append(rel)
    return bad


def compare(reference, folder):
    """Files of `reference` missing from or different in `folder` (volatile and temporary ones aside)."""
    diffs = []
    for base, _, files in os.walk(reference):
        for f in files:
            rel = os.path.relpath(os.path.join(base, f), reference)
            if f in VOLATILE or is_temporary(rel):
                continue
            other = os.path.join(folder, rel)
            if not os.path.exists(other):
                diffs.append(f"{rel}: missing")
            elif not filecmp.cmp(os.path.join(reference, rel), other, shallow=False):
                diffs.append(f"{rel}: differs")
    return diffs


def run(cmd, timeout=None):
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)


def killed_at(cmd, seconds):
    """Starts `cmd`, SIGKILLs it after `seconds` (if still running); whether it was killed."""
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        p.wait(timeout=seconds)
        return False
    except subprocess.TimeoutExpired:
        p.send_signal(signal.SIGKILL)
        p.wait()
        return True


class Case:
    def __init__(self, name, start, finish, out):
        self.name, self.start, self.finish, self.out = name, start, finish, out


def check_case(case, reference_cmd, cycles, failures):
    """Reference run, then `cycles` kill cycles; appends failures; returns the kills made."""
    ref_out = case.out + "-reference"
    t0 = time.monotonic()
    r = run(reference_cmd(ref_out))
    wall = time.monotonic() - t0
    if r.returncode != 0:
        failures.append(f"{case.name}: the uninterrupted run failed: {r.stderr[-2000:]}")
        return 0
    kills = 0
    for i in range(cycles):
        at = wall * (0.02 + 1.08 * i / max(cycles - 1, 1))
        shutil.rmtree(case.out, ignore_errors=True)
        for cmd, seconds in ((case.start, at), (case.finish, at / 2)):
            if killed_at(cmd, seconds):
                kills += 1
                bad = partial_files(case.out)
                if bad:
                    failures.append(f"{case.name}, kill at {seconds:.2f} s: partial files {bad}")
        r = run(case.finish)
        if r.returncode != 0:
            failures.append(f"{case.name}, cycle {i} (kill at {at:.2f} s): finishing failed: {r.stderr[-2000:]}")
            continue
        diffs = compare(ref_out, case.out)
        if diffs:
            failures.append(f"{case.name}, cycle {i} (kill at {at:.2f} s): {diffs}")
    print(f"{case.name}: uninterrupted {wall:.1f} s; {cycles} cycles, {kills} kills", flush=True)
    return kills


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cycles", type=int, default=15)
    ap.add_argument("--keep", help="work in this folder and keep it")
    a = ap.parse_args()
    subprocess.run(["cargo", "build", "--release", "--locked", "--bin", "fdimc"], cwd=ROOT, check=True)
    fdimc = os.path.join(target_dir(), "release", "fdimc")
    work = a.keep or tempfile.mkdtemp(prefix="fdimc-crash-")
    os.makedirs(work, exist_ok=True)
    deck = os.path.join(ROOT, "studies", "ci_seed000.toml")
    rare = os.path.join(ROOT, "studies", "seed000_rare_false_alarms.toml")
    d = lambda name: os.path.join(work, name)
    run_cmd = lambda out, *extra: [fdimc, "run", deck, "--trials", "12000", "--quiet", "--out", out, *extra]
    sens_cmd = lambda out, *extra: [fdimc, "sensitivity", deck, "--base-samples", "2048", "--quiet", "--out", out,
                                    *extra]
    rare_cmd = lambda out: [fdimc, "rare-event", rare, "--trials", "20000", "--quiet", "--out", out]
    # The shards merge kills: made once, uninterrupted.
    for i in range(2):
        r = run(run_cmd(d(f"shard{i}"), "--shard", f"{i}/2", "--force"))
        if r.returncode != 0:
            sys.exit(f"shard {i}: {r.stderr}")
    merge_cmd = lambda out: [fdimc, "merge", d("shard0"), d("shard1"), "--out", out, "--force"]
    cases = [
        (Case("run", run_cmd(d("run"), "--force"), run_cmd(d("run"), "--resume"), d("run")),
         lambda out: run_cmd(out, "--force")),
        (Case("sensitivity", sens_cmd(d("sens"), "--force"), sens_cmd(d("sens"), "--resume"), d("sens")),
         lambda out: sens_cmd(out, "--force")),
        (Case("rare-event", rare_cmd(d("rare")), rare_cmd(d("rare")), d("rare")), rare_cmd),
        (Case("merge", merge_cmd(d("merged")), merge_cmd(d("merged")), d("merged")), merge_cmd),
    ]
    failures, kills = [], 0
    for case, reference in cases:
        kills += check_case(case, reference, a.cycles, failures)
    for f in failures:
        print("FAIL", f)
    print(f"{kills} kills; " + ("every finished folder identical, no partial file" if not failures
                                 else f"{len(failures)} failure(s)"))
    if not a.keep:
        shutil.rmtree(work, ignore_errors=True)
    if kills == 0:
        sys.exit("no kill landed: the check ran nothing")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
