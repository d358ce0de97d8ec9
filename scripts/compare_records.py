#!/usr/bin/env python3
"""Are the records of two fdimc binaries the same? Runs every bundled deck (or those named) with both and
compares trials.parquet column by column, through the renames of the one outcome schema (issue 16).

    pip install polars
    python3 scripts/compare_records.py OLD_FDIMC NEW_FDIMC [--trials N] [--keep DIR] [decks ...]

Binaries that write the same schema are compared column for column; across the issue-16 schema change,
through the renames. Both binaries run the same deck, seed and trial count (--trials caps slow decks: a trial's records depend
only on (deck, seed, trial index), so a prefix of a study is compared exactly). Every column of the old
table must be in the new one under its name or its new name, with identical values, except where the
schema changed a representation on purpose (listed in RULES, each checked by its own rule); every new
core column that the old table did not have is checked against the old columns it follows from. Where
the two runs keep their first-passage profiles on different grids (`profile_resolution` in manifest.json;
none before issue 48), the fp_ lists are compared by their exact points, the first and the last. Exit 1
on any difference.
"""
import argparse
import glob
import json
import math
import os
import subprocess
import sys
import tempfile
import tomllib

import polars as pl

# Old column -> new column, per kind (the kind is the new manifest's).
RENAMES = {
    "detection_filter": {"output": "target", "design_error": "failure", "isolated_by_direction": "isolated"},
    "thrust_loss": {"engine": "target", "localised": "isolated", "localised_correctly": "isolated_correctly"},
    "air_data": {"sensors": "target"},
    "accelerometer": {"axis": "target", "predicted": "isolated", "correct": "isolated_correctly"},
    "surface_bank": {"surface": "target", "detection_delay_s": "delay_s", "first_false_alarm_s": "false_alarm_s"},
}

NONE = "none"


def rule(kind, old_name):
    """How an old column must relate to its new one, when not equal value for value."""
    if kind == "detection_filter" and old_name == "size":
        return "sigma_scaled"  # output units before, the deck's unit (sensor sigmas) now
    if kind in ("air_data", "surface_bank") and old_name == "detected":
        return "null_is_false"  # null for unflown rows before, false now
    if kind == "accelerometer" and old_name == "delay_s":
        return "faulty_rows_only"  # a normal trial's alarm has no delay now
    if kind == "surface_bank" and old_name == "isolated":
        return "none_is_null"  # "none" when nothing was declared before, null now
    if kind == "surface_bank" and old_name == "isolated_correctly":
        return "unnamed_is_null"  # false when nothing was declared before, null (not decided) now
    return "equal"


def same(a, b):
    """Element-wise equality with nulls equal and NaN equal to NaN."""
    a, b = a.to_list(), b.to_list()
    if len(a) != len(b):
        return [False]
    out = []
    for x, y in zip(a, b):
        if isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y):
            out.append(True)
        else:
            out.append(x == y)
    return out


def same_ends(a, b):
    """Profiles on different grids (issue 48): the same first and last point (the first post-onset sample
    and the final maximum, exact on every grid), row by row."""
    out = []
    for x, y in zip(a.to_list(), b.to_list()):
        if not x or not y:
            out.append(not x and not y)
        else:
            out.append(x[0] == y[0] and x[-1] == y[-1])
    return out


def compare(kind, old, new, grids_differ=False):
    problems = []
    if old.height != new.height:
        return [f"rows: {old.height} before, {new.height} now"]
    if "target" in old.columns:
        # Both binaries write the one outcome schema: every column of the old table identical in the new
        # (NaN equal to NaN); a column the new one adds is listed, and a late alarm (issue 46) must be the
        # old detection's delay.
        for c in old.columns:
            if c not in new.columns:
                problems.append(f"column {c!r} is gone")
                continue
            profile = c.startswith("fp_t_s_") or c.startswith("fp_v_")
            ok = same_ends(old[c], new[c]) if grids_differ and profile else same(old[c], new[c])
            bad = [i for i, e in enumerate(ok) if not e]
            if bad:
                problems.append(f"{c!r}: {len(bad)} rows differ, first row {bad[0]}: {old[c][bad[0]]!r} vs {new[c][bad[0]]!r}")
        added = [c for c in new.columns if c not in old.columns]
        if added:
            print(f"    new columns: {', '.join(added)}")
        if "late_alarm_s" in added:
            late = new["late_alarm_s"].to_list()
            bad = [i for i, x in enumerate(late) if x is not None and old["delay_s"][i] != x]
            if bad:
                problems.append(f"'late_alarm_s': {len(bad)} rows are not the old delay, first row {bad[0]}")
        return problems
    renames = RENAMES[kind]
    for c in old.columns:
        n = renames.get(c, c)
        if n not in new.columns:
            problems.append(f"column {c!r} is gone (looked for {n!r})")
            continue
        r = rule(kind, c)
        o, v = old[c], new[n]
        if r == "equal":
            ok = same(o, v)
        elif r == "null_is_false":
            ok = same(o.fill_null(False), v)
        elif r == "none_is_null":
            ok = same(o.replace(NONE, None), v)
        elif r == "unnamed_is_null":
            unnamed = (old["isolated"] == NONE).to_list()
            ok = [e or (u and y is None) for e, u, y in zip(same(o, v), unnamed, v.to_list())]
        elif r == "faulty_rows_only":
            keep = (old["kind"] != "normal").to_list()
            ok = [k is False or e for k, e in zip(keep, same(o, v))]
        elif r == "sigma_scaled":
            # Per target, old / new is one number: 1 (output units) or the output's sensor sigma.
            ok = [True] * old.height
            ratios = {}
            for i, (t, x, y) in enumerate(zip(old["output"].to_list(), o.to_list(), v.to_list())):
                if x is None or y is None:
                    ok[i] = (x is None) == (y is None)
                    continue
                unit = new["size_unit"][i]
                ratio = 1.0 if y == 0 else x / y
                ref = ratios.setdefault((t, unit), ratio)
                ok[i] = abs(ratio - ref) <= 1e-12 * abs(ref) and (unit != "output units" or x == y)
        bad = [i for i, e in enumerate(ok) if not e]
        if bad:
            i = bad[0]
            problems.append(f"{c!r} -> {n!r} ({r}): {len(bad)} rows differ, first row {i}: {o[i]!r} vs {v[i]!r}")
    # New core columns, from the old ones.
    derived = {
        "fault_free": (old["kind"] == ("normal" if kind == "accelerometer" else NONE)),
        "false_alarm": old[[c for c in old.columns if renames.get(c, c) == "false_alarm_s"][0]].is_not_null(),
    }
    if kind == "detection_filter":
        derived["diverged"] = old["diverged_at_s"].is_not_null()
        derived["detected"] = old["delay_s"].is_not_null()
        named = zip(old["isolated_by_direction"].to_list(), old["output"].to_list())
        derived["isolated_correctly"] = pl.Series([None if i is None else i == t for i, t in named])
    if kind == "surface_bank":
        derived["false_alarm"] = old["false_alarms"].fill_null(0) > 0
    if kind in ("thrust_loss", "accelerometer"):
        derived["detected"] = old["delay_s"].is_not_null() & (old["kind"] != "normal")
    for name, expected in derived.items():
        bad = [i for i, e in enumerate(same(expected, new[name])) if not e]
        if bad:
            i = bad[0]
            problems.append(f"new {name!r}: {len(bad)} rows disagree with the old columns, first row {i}")
    return problems


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("old")
    ap.add_argument("new")
    ap.add_argument("decks", nargs="*")
    ap.add_argument("--trials", type=int, default=400, help="at most this many trials per deck (default 400)")
    ap.add_argument("--keep", help="keep the runs in this folder")
    a = ap.parse_intermixed_args()
    decks = a.decks or sorted(glob.glob("studies/*.toml"))
    work = a.keep or tempfile.mkdtemp(prefix="fdimc-compare-")
    failed = 0
    for deck in decks:
        name = os.path.splitext(os.path.basename(deck))[0]
        tables, grids = {}, {}
        for which, binary in (("old", a.old), ("new", a.new)):
            out = os.path.join(work, which, name)
            with open(deck, "rb") as f:
                trials = tomllib.load(f).get("monte_carlo", {}).get("trials", 1000)
            cmd = [binary, "run", deck, "--out", out, "--force", "--quiet", "--trials", str(min(trials, a.trials))]
            r = subprocess.run(cmd, capture_output=True, text=True)
            if r.returncode != 0:
                print(f"{name}: {which} binary failed: {r.stderr.strip()}")
                failed += 1
                break
            tables[which] = pl.read_parquet(os.path.join(out, "trials.parquet"))
            with open(os.path.join(out, "manifest.json")) as f:
                manifest = json.load(f)
            grids[which] = manifest.get("profile_resolution")
            if which == "new":
                kind = manifest["kind"]
        if len(tables) < 2:
            continue
        grids_differ = grids["old"] != grids["new"]
        if grids_differ:
            print(f"    profile grids differ ({grids['old']} before, {grids['new']} now): "
                  "fp_ columns compared by their first and last points")
        problems = compare(kind, tables["old"], tables["new"], grids_differ)
        status = "identical" if not problems else "DIFFERENT"
        print(f"{name} ({kind}): {tables['old'].height} rows, {len(tables['old'].columns)} old columns: {status}")
        for p in problems:
            print(f"    {p}")
        failed += bool(problems)
    print(f"{len(decks) - failed} of {len(decks)} decks: the same records ({work})")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
