#!/usr/bin/env python3
"""The tables of figures in the findings pages (docs/findings-*.md), generated from the runs' own output
files instead of typed (issue 50). Each generated table sits between two markers in its page:

    <!-- generated: NAME (scripts/findings.py) -->
    | ... the table ... |
    <!-- end generated: NAME -->

and NAME is a table in TABLES below: its deck, the `fdimc` command that runs it, and the function that
renders the table from the run's files. The line above the table in the page names the deck, its seed
and the command (checked too: it is rendered with the table).

    python3 scripts/findings.py              # run the fast decks, rewrite their tables in the pages
    python3 scripts/findings.py --check      # the same, but fail (exit 1) on any difference, write nothing
    python3 scripts/findings.py --all        # every table, the slow decks included (on demand)
    python3 scripts/findings.py --runs DIR   # reuse runs kept in DIR/<name> (fdimc run --out DIR/<name>)
    python3 scripts/findings.py --list       # the tables, their decks and how long each takes

Needs polars (`pip install polars`) and an fdimc binary: $FDIMC, else the release build under
cargo's target directory (CARGO_TARGET_DIR, or ./target). CI runs `--check` on the fast decks (.ci/run).
"""
import argparse
import difflib
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import tomllib

import polars as pl

ROOT = pathlib.Path(__file__).resolve().parent.parent


def fdimc_binary():
    if os.environ.get("FDIMC"):
        return os.environ["FDIMC"]
    # Where cargo builds (CARGO_TARGET_DIR or ./target), as cargo itself says.
    meta = subprocess.run(["cargo", "metadata", "--format-version", "1", "--no-deps"], cwd=ROOT,
                          capture_output=True, text=True, check=True)
    binary = pathlib.Path(json.loads(meta.stdout)["target_directory"]) / "release" / "fdimc"
    if not binary.exists():
        raise SystemExit(f"{binary}: no such file; build it first (cargo build --release), or set FDIMC")
    return str(binary)


def num(v, digits=2):
    return "-" if v is None else f"{v:.{digits}f}"


def seed004_reference_tuning(run):
    """docs/findings-seed004.md, "Under the seed's own tuning": per variant, over the 20 flights of the
    seed's scenario. Delays are medians over the flights where the faulty surface was declared;
    "isolated" counts the windows whose first declaration named the faulty surface; recovery is the
    median over the windows that recovered; the isolation accuracy is over the windows with a
    declaration; the RMS is the median over every window; non-finite counts flights."""
    d = pl.read_parquet(run / "trials.parquet")
    rows = [
        ("EMMAE, `_rw`", "emmae_rw"),
        ("improved STMMAE, `_rw`", "improved_stmmae_rw"),
        ("EMMAE, `_seed`", "emmae_seed"),
        ("EKF + fast, `_seed`", "ekf_fast_seed"),
        ("STMMAE, `_seed`", "stmmae_seed"),
        ("improved STMMAE, `_seed`", "improved_stmmae_seed"),
        ("STMMAE, `_seed_a3`", "stmmae_seed_a3"),
        ("improved STMMAE, `_seed_a3`", "improved_stmmae_seed_a3"),
        ("EMMAE, `_rw_reset_at_zero`", "emmae_rw_reset_at_zero"),
        ("improved STMMAE, `_rw_reset_at_zero`", "improved_stmmae_rw_reset_at_zero"),
    ]
    def digits(v):
        return "-" if v is None else (f"{v:.1f}" if v >= 10 else f"{v:.2f}")

    out = [
        "| variant | left aileron: isolation delay, isolated | rudder (-1 deg): delay, isolated | left elevator: isolated | recovery, s (left aileron; left elevator; flights) | isolation accuracy, five faults (windows with a declaration) | surface-estimate RMS, deg | flights non-finite |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for label, detector in rows:
        x = d.filter(pl.col("detector") == detector)
        if x.height == 0:
            raise SystemExit(f"{run}: no rows of detector {detector}")

        def target(t):
            return x.filter(pl.col("target") == t)

        def isolated(f):
            return f"{int(f['isolated_correctly'].fill_null(False).sum())}/{f.height}"

        def delay(f):
            v = f["isolation_delay_s"].drop_nulls().median()
            return "-" if v is None else f"{digits(v)} s"

        def recovery(f):
            r = f.filter(pl.col("recovered").fill_null(False))
            return r["recovery_delay_s"].median(), r.height

        al, ru, el = target("aileron_left"), target("rudder"), target("elevator_left")
        (ra, na), (re, ne) = recovery(al), recovery(el)
        decided = x.filter(pl.col("isolated").is_not_null())
        accuracy = decided["isolated_correctly"].sum() / decided.height
        rms = x["surface_estimate_rms_deg"].median()
        non_finite = x.filter(pl.col("non_finite_steps") > 0)["trial"].n_unique()
        out.append(
            f"| {label} | {delay(al)}, {isolated(al)} | {delay(ru)}, {isolated(ru)} | {isolated(el)} | "
            f"{digits(ra)}; {digits(re)} ({na}, {ne}) | {accuracy:.2f} | {rms:.2f} | {non_finite} |"
        )
    return out


# name -> (page, deck, fast: runs in CI, wall time measured on machine C, renderer)
TABLES = {
    "seed004_reference_tuning": (
        "docs/findings-seed004.md",
        "studies/seed004_reference_tuning.toml",
        True,
        "10 s",
        seed004_reference_tuning,
    ),
}


def provenance(deck):
    seed = tomllib.loads((ROOT / deck).read_text())["study"]["seed"]
    return f"Deck `{deck}`, seed {seed}, `fdimc run {deck}`; generated by `python3 scripts/findings.py`."


def run_deck(name, deck, runs):
    out = runs / name
    if (out / "trials.parquet").exists():
        return out
    cmd = [fdimc_binary(), "run", str(ROOT / deck), "--quiet", "--force", "--out", str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr}")
    return out


def replace_block(text, name, lines, page):
    begin, end = f"<!-- generated: {name} (scripts/findings.py) -->", f"<!-- end generated: {name} -->"
    if text.count(begin) != 1 or text.count(end) != 1:
        raise SystemExit(f"{page}: needs exactly one '{begin}' and one '{end}'")
    head, rest = text.split(begin, 1)
    _, tail = rest.split(end, 1)
    return head + begin + "\n" + "\n".join(lines) + "\n" + end + tail


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="fail on any difference; write nothing")
    ap.add_argument("--all", action="store_true", help="every table, the slow decks included")
    ap.add_argument("--runs", type=pathlib.Path, help="keep or reuse the runs in this folder")
    ap.add_argument("--list", action="store_true", help="list the tables and stop")
    ap.add_argument("names", nargs="*", help="only these tables")
    args = ap.parse_args()
    if args.list:
        for name, (page, deck, fast, wall, _) in TABLES.items():
            print(f"{name}: {page}, {deck}, {'fast (CI)' if fast else 'on demand'}, {wall}")
        return 0
    unknown = [n for n in args.names if n not in TABLES]
    if unknown:
        raise SystemExit(f"unknown table(s) {unknown}; known: {sorted(TABLES)}")
    chosen = args.names or [n for n, t in TABLES.items() if args.all or t[2]]
    scratch = None
    runs = args.runs
    if runs is None:
        scratch = tempfile.TemporaryDirectory(prefix="fdimc-findings-")
        runs = pathlib.Path(scratch.name)
    runs.mkdir(parents=True, exist_ok=True)
    pages = {}
    for name in chosen:
        page, deck, _, _, render = TABLES[name]
        lines = [provenance(deck), ""] + render(run_deck(name, deck, runs))
        text = pages.get(page) or (ROOT / page).read_text()
        pages[page] = replace_block(text, name, lines, page)
    differ = 0
    for page, text in pages.items():
        old = (ROOT / page).read_text()
        if old == text:
            print(f"{page}: up to date")
            continue
        differ += 1
        if args.check:
            print(f"{page}: differs from what the decks give:")
            sys.stdout.writelines(difflib.unified_diff(old.splitlines(True), text.splitlines(True), page, "generated"))
        else:
            (ROOT / page).write_text(text)
            print(f"{page}: rewritten")
    return 1 if (args.check and differ) else 0


if __name__ == "__main__":
    sys.exit(main())
