#!/usr/bin/env python3
"""The tables of figures in the findings pages (docs/findings-*.md), generated from the runs' own output
files instead of typed (issue 50). Each generated table sits between two markers in its page:

    <!-- generated: NAME (scripts/findings.py) -->
    | ... the table ... |
    <!-- end generated: NAME -->

and NAME is a table in TABLES below: its decks (each run with `fdimc run DECK`), and the function that
renders the table from the runs' files. The line above the table in the page names the deck, its seed
and the command (checked too: it is rendered with the table). A deck named "studies/X.toml SECTION.FIELD=V"
is run as a copy of X with that field set (for sweeps over one setting; the copy is written beside the run,
so the deck must not name files relative to itself).

    python3 scripts/findings.py              # run the fast decks, rewrite their tables in the pages
    python3 scripts/findings.py --check      # the same, but fail (exit 1) on any difference, write nothing
    python3 scripts/findings.py --all        # every table, the slow decks included (on demand)
    python3 scripts/findings.py --runs DIR   # keep or reuse the runs in DIR/<deck stem> (fdimc run --out ...)
    python3 scripts/findings.py --list       # the tables, their decks and how long each takes
    python3 scripts/findings.py --jobs 1     # one run at a time (default 2: runs overlap their serial phases)

Needs polars (`pip install polars`) and an fdimc binary: $FDIMC, else the release build under
cargo's target directory (CARGO_TARGET_DIR, or ./target). CI runs `--check` on the fast decks (.ci/run).
"""
import argparse
import concurrent.futures
import decimal
import difflib
import json
import math
import os
import pathlib
import re
import subprocess
import sys
import tempfile
import tomllib

import polars as pl

from fmu_findings import rows as fmu_rows, wilson  # (scripts/ is on the path of a script run from it)

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


def half_up(v, digits=2):
    """`v` to `digits` decimals, halves away from zero, after the float noise below 1e-6 is cleared: the
    medians of delays on a 0.01 s grid often end in a 5 (0.535 held as 0.534999...), and the seed-004
    pages round those up."""
    if v is None:
        return "-"
    q = decimal.Decimal(1).scaleb(-digits)
    return str(decimal.Decimal(repr(round(v, 6))).quantize(q, rounding=decimal.ROUND_HALF_UP))


def seed004_reference_tuning(runs):
    """docs/findings-seed004.md, "Under the seed's own tuning": per variant, over the 20 flights of the
    seed's scenario. Delays are medians over the flights where the faulty surface was declared;
    "isolated" counts the windows whose first declaration named the faulty surface; recovery is the
    median over the windows that recovered; the isolation accuracy is over the windows with a
    declaration; the RMS is the median over every window; non-finite counts flights."""
    run = runs["studies/seed004_reference_tuning.toml"]
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
        return "-" if v is None else half_up(v, 1 if v >= 10 else 2)

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
            f"{digits(ra)}; {digits(re)} ({na}, {ne}) | {half_up(accuracy)} | {half_up(rms)} | {non_finite} |"
        )
    return out


def seed004_surfaces(runs):
    """docs/findings-seed004.md, the seed's scenario under 20 noise draws: per variant and faulty
    surface (left and right aileron, left and right elevator), the median over the draws of the delay
    from the onset to the first declaration, of the clearing delay and of the recovery delay."""
    d = pl.read_parquet(runs["studies/seed004_surfaces.toml"] / "trials.parquet")
    surfaces = ["aileron_left", "aileron_right", "elevator_left", "elevator_right"]
    out = [
        "| variant | detection delay, s (left aileron, right aileron, left elevator, right elevator) | clearing delay, s (same) | recovery delay, s (same; the seed's clearing event) |",
        "|---|---|---|---|",
    ]
    for label, detector in [
        ("EMMAE (EKF, Gaussian)", "emmae"),
        ("EKF + fast probability", "ekf_fast"),
        ("STMMAE", "stmmae"),
        ("improved STMMAE", "improved_stmmae"),
    ]:
        x = d.filter(pl.col("detector") == detector)
        cells = [
            ", ".join(half_up(x.filter(pl.col("target") == t)[column].drop_nulls().median()) for t in surfaces)
            for column in ["delay_s", "clearing_delay_s", "recovery_delay_s"]
        ]
        out.append(f"| {label} | " + " | ".join(cells) + " |")
    return out


def seed003_training(runs):
    """docs/findings-seed003.md, "What the study finds": per deck and classifier, the accuracy over the
    2,000 fresh trials with its Wilson interval (detectors.csv, the deck's thresholds) and each class's
    recall (confusion.csv: the share of a true class named as itself)."""
    out = [
        "| trained on | classifier | accuracy [95 % CI] | recall normal | bias | gain | stuck |",
        "|---|---|---|---|---|---|---|",
    ]
    for deck, label in [
        ("studies/seed003_accelerometer.toml", "nominal noise (`seed003_accelerometer.toml`)"),
        ("studies/seed003_noise_trained.toml", "both noise levels (`seed003_noise_trained.toml`)"),
    ]:
        detectors = pl.read_csv(runs[deck] / "detectors.csv").filter(pl.col("thresholds") == "deck")
        confusion = pl.read_csv(runs[deck] / "confusion.csv")
        for i, c in enumerate(["tree", "flat"]):
            d = detectors.filter(pl.col("detector") == c).row(0, named=True)

            def recall(k):
                r = confusion.filter((pl.col("detector") == c) & (pl.col("truth") == k) & (pl.col("isolated") == k))
                return r["share_of_truth"][0] if r.height else 0.0

            row = (
                f"| {label if i == 0 else ''} | {c} | {d['isolation_accuracy']:.3f} [{d['isolation_accuracy_lo']:.3f}, "
                f"{d['isolation_accuracy_hi']:.3f}] | "
                + " | ".join(f"{recall(k):.3f}" for k in ["normal", "bias", "gain", "stuck"])
                + " |"
            )
            out.append(row.replace("|  |", "| |"))
    return out


def mcnemar(b, c):
    """Exact two-sided McNemar test of b trials right only with one classifier against c only with the
    other: twice the binomial(b + c, 1/2) tail at min(b, c), at most 1."""
    n = b + c
    if n == 0:
        return 1.0
    return min(1.0, 2 * sum(math.comb(n, i) for i in range(min(b, c) + 1)) / 2**n)


def p_text(p):
    return "1" if p >= 0.9995 else (f"{p:.3f}" if p >= 0.001 else f"{p:.0e}")


def correct_by_trial(run):
    """Per trial (and its noise bin), whether each classifier named the true class: one column each."""
    d = pl.read_parquet(run / "trials.parquet").with_columns(pl.col("isolated_correctly").fill_null(False))
    return d.pivot(on="detector", index=["trial", "noise_bin"], values="isolated_correctly").sort("trial")


SEED003_CLASSIFIERS = [
    ("tree", "tree, onset window (the oracle)"),
    ("flat", "flat, onset window"),
    ("tree_online", "tree, alarm window (online)"),
    ("flat_online", "flat, alarm window (online)"),
    ("tree_reversed", "tree, most separable pair first"),
    ("tree_balanced", "tree, balanced weights"),
]


def seed003_online(runs):
    """docs/findings-seed003.md, "Online windows, the tree's order, class weights": each classifier's
    accuracy at nominal and twice the noise (1,000 trials each), paired with the tree on the onset window
    at nominal noise: the trials only one of the two names right, and the exact McNemar p."""
    w = correct_by_trial(runs["studies/seed003_online.toml"])
    nominal, twice = w.filter(pl.col("noise_bin") == 1.0), w.filter(pl.col("noise_bin") == 2.0)
    out = [
        "| classifier | accuracy, nominal noise | trials right only with it / only with the tree | p | accuracy, twice the noise |",
        "|---|---|---|---|---|",
    ]
    for c, label in SEED003_CLASSIFIERS:
        if c == "tree":
            pair, p = "-", "-"
        else:
            b = int((nominal[c] & ~nominal["tree"]).sum())
            t = int((~nominal[c] & nominal["tree"]).sum())
            pair, p = f"{b} / {t}", p_text(mcnemar(b, t))
        out.append(f"| {label} | {nominal[c].mean():.3f} | {pair} | {p} | {twice[c].mean():.3f} |")
    return out


TRANSLATIONS_MPS2 = ["0.5", "1.0", "2.0", "4.0"]


def seed003_translation(runs):
    """docs/findings-seed003.md, manoeuvres with translational acceleration: per amplitude (0: the
    online deck as bundled), at the nominal noise (1,000 trials), the normal trials with a false alarm,
    the faults detected, and the accuracy of the tree on the onset window and on the alarm window, with
    Wilson intervals."""
    decks = ["studies/seed003_online.toml"] + [f"studies/seed003_online.toml imu.translation_mps2={a}" for a in TRANSLATIONS_MPS2]
    out = [
        "| translational acceleration | normal trials with a false alarm | faults detected | tree, onset window | tree, alarm window |",
        "|---|---|---|---|---|",
    ]
    for deck, amplitude in zip(decks, ["0"] + TRANSLATIONS_MPS2):
        d = pl.read_parquet(runs[deck] / "trials.parquet").filter(
            (pl.col("noise_bin") == 1.0) & pl.col("failure").is_null() & (pl.col("detector") == "tree_online")
        )
        normal, faulty = d.filter(pl.col("kind") == "normal"), d.filter(pl.col("kind") != "normal")
        w = correct_by_trial(runs[deck]).filter(pl.col("noise_bin") == 1.0)

        def rate(k, n):
            p, lo, hi = wilson(k, n)
            return f"{k}/{n}, {p:.3f} [{lo:.3f}, {hi:.3f}]"

        out.append(
            f"| {amplitude} m/s^2 | {rate(int(normal['false_alarm'].sum()), normal.height)} | "
            f"{rate(int(faulty['detected'].sum()), faulty.height)} | {rate(int(w['tree'].sum()), w.height)} | "
            f"{rate(int(w['tree_online'].sum()), w.height)} |"
        )
    return out


WINDOWS_S = [0.1, 0.25, 0.5, 1.0]


def seed003_window(runs):
    """docs/findings-seed003.md, "at the first moment": each classifier's accuracy with its Wilson
    interval at nominal noise (1,000 trials) against the classification window (`training.window_s`:
    the residuals' span after the onset or the alarm the features are computed on, trained and
    evaluated alike)."""
    out = [
        "| classifier | " + " | ".join(f"{w} s" for w in WINDOWS_S) + " |",
        "|---" * (len(WINDOWS_S) + 1) + "|",
    ]
    nominal = [
        correct_by_trial(runs[f"studies/seed003_online.toml training.window_s={w}"]).filter(pl.col("noise_bin") == 1.0)
        for w in WINDOWS_S
    ]
    for c, label in SEED003_CLASSIFIERS[:4]:
        cells = []
        for n in nominal:
            p, lo, hi = wilson(int(n[c].sum()), n.height)
            cells.append(f"{p:.3f} [{lo:.3f}, {hi:.3f}]")
        out.append(f"| {label} | " + " | ".join(cells) + " |")
    return out


def paired_accuracy(first, second, header):
    """Each classifier's accuracy in two runs of the same trials, at nominal and twice the noise, and at
    twice the noise the trials only the second / only the first names right, with the exact McNemar p."""
    if first["trial"].to_list() != second["trial"].to_list():
        raise SystemExit("the two runs do not fly the same trials")
    at = lambda w, bin_: w.filter(pl.col("noise_bin") == bin_)
    out = [header, "|---|---|---|---|"]
    for c, label in SEED003_CLASSIFIERS:
        a1, b1, a2, b2 = at(first, 1.0)[c], at(second, 1.0)[c], at(first, 2.0)[c], at(second, 2.0)[c]
        only_second, only_first = int((b2 & ~a2).sum()), int((~b2 & a2).sum())
        out.append(
            f"| {label.replace(' (the oracle)', '')} | {a1.mean():.3f}, {b1.mean():.3f} | {a2.mean():.3f}, "
            f"{b2.mean():.3f} | {only_second} / {only_first} (p = {p_text(mcnemar(only_second, only_first))}) |"
        )
    return out


def seed003_noise_tuned(runs):
    """docs/findings-seed003.md, the noise-tuned filter: [paired_accuracy] of the nominal filter
    (`seed003_online.toml`) and the tuned one (`seed003_noise_tuned.toml`)."""
    return paired_accuracy(
        correct_by_trial(runs["studies/seed003_online.toml"]),
        correct_by_trial(runs["studies/seed003_noise_tuned.toml"]),
        "| classifier | nominal noise: nominal filter, tuned | twice the noise: nominal filter, tuned | trials right only when tuned / only nominal (twice the noise) |",
    )


ESTIMATED_NOISE_DECK = 'studies/seed003_noise_tuned.toml detection.filter_noise="estimated"'


def seed003_noise_estimated(runs):
    """docs/findings-seed003.md, the noise scale estimated instead of known: [paired_accuracy] of the
    filter tuned to the trial's true noise (the oracle, `seed003_noise_tuned.toml`) and to the scale it
    estimates from its residuals before settle_s."""
    return paired_accuracy(
        correct_by_trial(runs["studies/seed003_noise_tuned.toml"]),
        correct_by_trial(runs[ESTIMATED_NOISE_DECK]),
        "| classifier | nominal noise: oracle, estimated | twice the noise: oracle, estimated | trials right only estimated / only with the oracle (twice the noise) |",
    )

def surface_detectors(run, rows, columns):
    """Rows of a surface-bank run's detectors.csv (the deck's thresholds), one per (label, detector),
    in `columns`: names of SURFACE_COLUMNS."""
    d = pl.read_csv(run / "detectors.csv").filter(pl.col("thresholds") == "deck")
    out = ["| variant | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]
    for label, detector in rows:
        r = d.filter(pl.col("detector") == detector)
        if r.height != 1:
            raise SystemExit(f"{run}/detectors.csv: no row of detector {detector}")
        r = r.row(0, named=True)
        out.append(f"| {label} | " + " | ".join(SURFACE_COLUMNS[c](r) for c in columns) + " |")
    return out


def with_interval(r, name, digits=3):
    return f"{half_up(r[name], digits)} [{half_up(r[name + '_lo'], digits)}, {half_up(r[name + '_hi'], digits)}]"


SURFACE_COLUMNS = {
    "Pd [95 % CI]": lambda r: with_interval(r, "pd"),
    "correct isolation": lambda r: with_interval(r, "isolation_accuracy"),
    "delay p50 / p90": lambda r: f"{half_up(r['delay_p50_s'])} / {half_up(r['delay_p90_s'])} s",
    "clearing p50": lambda r: f"{half_up(r['clearing_p50_s'])} s",
    "recovery p50, rate": lambda r: f"{half_up(r['recovery_p50_s'])} s, {half_up(r['recovery_rate'])}",
    "post-fault declarations": lambda r: half_up(r["post_fault_rate"], 3),
    "surface RMS p50": lambda r: f"{half_up(r['estimate_rms_p50_deg'])} deg",
    "false alarms": lambda r: with_interval(r, "pfa"),
    "flights non-finite": lambda r: str(r["flights_diverged"]),
}


def seed004_monte_carlo(runs):
    """docs/findings-seed004.md, the Monte Carlo study: detectors.csv at the deck's thresholds."""
    return surface_detectors(
        runs["studies/seed004_monte_carlo.toml"],
        [
            ("EMMAE", "emmae"),
            ("EKF + fast probability", "ekf_fast"),
            ("STMMAE", "stmmae"),
            ("improved STMMAE", "improved_stmmae"),
        ],
        ["Pd [95 % CI]", "correct isolation", "delay p50 / p90", "clearing p50", "recovery p50, rate",
         "post-fault declarations", "false alarms"],
    )


def seed004_monte_carlo_tunings(runs):
    """docs/findings-seed004.md, the Monte Carlo trials under both tunings: detectors.csv at the deck's
    thresholds."""
    return surface_detectors(
        runs["studies/seed004_monte_carlo_tunings.toml"],
        [
            ("EMMAE, `_seed`", "emmae_seed"),
            ("EKF + fast probability, `_seed`", "ekf_fast_seed"),
            ("STMMAE, `_seed`", "stmmae_seed"),
            ("improved STMMAE, `_seed`", "improved_stmmae_seed"),
            ("STMMAE, `_seed_a3`", "stmmae_seed_a3"),
            ("improved STMMAE, `_seed_a3`", "improved_stmmae_seed_a3"),
            ("improved STMMAE, `_rw_reset_at_zero`", "improved_stmmae_rw_reset_at_zero"),
        ],
        ["Pd [95 % CI]", "correct isolation", "delay p50 / p90", "clearing p50", "recovery p50, rate",
         "surface RMS p50", "false alarms", "flights non-finite"],
    )


def seed003_replay(runs):
    """docs/findings-seed003.md, on a real flight log: each classifier's accuracy over the 400 replayed
    trials with its Wilson interval (detectors.csv, the deck's thresholds), as recorded and with the
    gyro calibrated on the log's first half."""
    decks = ["studies/replay_px4.toml", "studies/replay_px4_gyro_calibrated.toml"]
    tables = [pl.read_csv(runs[d] / "detectors.csv").filter(pl.col("thresholds") == "deck") for d in decks]
    out = [
        "| classifier | trained on | accuracy [95 % CI], as recorded (`replay_px4.toml`) | gyro calibrated (`replay_px4_gyro_calibrated.toml`) |",
        "|---|---|---|---|",
    ]
    for c, trained in [
        ("tree_sim", "simulated flights (the patent's tree)"),
        ("flat_sim", "simulated flights (one-against-one)"),
        ("tree_log", "faults injected into the log's first half"),
        ("flat_log", "the same, one-against-one"),
    ]:
        cells = []
        for t in tables:
            r = t.filter(pl.col("detector") == c).row(0, named=True)
            cells.append(f"{r['isolation_accuracy']:.3f} [{r['isolation_accuracy_lo']:.3f}, {r['isolation_accuracy_hi']:.3f}]")
        out.append(f"| `{c}` | {trained} | " + " | ".join(cells) + " |")
    return out


def seed004_tunings_paired(runs):
    """docs/findings-seed004.md, the tunings' paired comparisons (comparison.csv, the deck's thresholds):
    per pair on the same trials, the windows only one detects or isolates correctly (exact McNemar p),
    the median paired differences of delay, clearing, recovery and surface-estimate RMS (b - a, with
    the 95 % sign-test interval where the summary gives one), and the flights only one alarms on."""
    c = pl.read_csv(runs["studies/seed004_monte_carlo_tunings.toml"] / "comparison.csv").filter(
        pl.col("thresholds") == "deck"
    )
    pairs = [
        ("emmae_seed", "improved_stmmae_seed"),
        ("ekf_fast_seed", "improved_stmmae_seed"),
        ("stmmae_seed", "improved_stmmae_seed"),
        ("stmmae_seed_a3", "improved_stmmae_seed_a3"),
        ("improved_stmmae_seed", "improved_stmmae_seed_a3"),
        ("improved_stmmae_rw", "improved_stmmae_rw_reset_at_zero"),
    ]
    out = [
        "| a, b (same trials) | detected by a only / b only (p) | isolated by a only / b only (p) | delay b - a | clearing b - a | recovery b - a [95 % CI] | surface RMS b - a [95 % CI] | flights alarming with a only / b only (p) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for a, b in pairs:
        r = c.filter((pl.col("detector_a") == a) & (pl.col("detector_b") == b))
        if r.height != 1:
            raise SystemExit(f"comparison.csv: no row for {a} against {b}")
        r = r.row(0, named=True)
        def interval(name, unit, digits=2, r=r):
            return (
                f"{half_up(r[name], digits)}{unit} [{half_up(r[name + '_lo'], digits)}, "
                f"{half_up(r[name + '_hi'], digits)}]"
            )

        out.append(
            f"| `{a}`, `{b}` | {r['detected_by_a_only']} / {r['detected_by_b_only']} ({p_text(r['mcnemar_p_detection'])}) "
            f"| {r['isolated_by_a_only']} / {r['isolated_by_b_only']} ({p_text(r['mcnemar_p_isolation'])}) "
            f"| {half_up(r['median_delay_b_minus_a_s'])} s | {half_up(r['median_clearing_delay_s_b_minus_a'])} s "
            f"| {interval('median_recovery_delay_s_b_minus_a', ' s')} "
            f"| {interval('median_surface_estimate_rms_deg_b_minus_a', ' deg', 3)} "
            f"| {r['false_alarm_a_only']} / {r['false_alarm_b_only']} ({p_text(r['mcnemar_p_false_alarm'])}) |"
        )
    return out


def fmu_aircraft(runs):
    """docs/findings-fmu.md: scripts/fmu_findings.py's table of the FMU study and its LTI twin."""
    return fmu_rows([runs["studies/fmu_aircraft.toml"], runs["studies/fmu_aircraft_lti.toml"]])


def percent_interval(k, n):
    """A rate as the seed-002 page writes it: 0 [0, 0.5 %], 2.1 % [1.3, 3.4], 43 % [40, 47]."""
    p, lo, hi = wilson(k, n)
    if k == 0:
        return f"0 [0, {half_up(100 * hi, 1)} %]"
    digits = 0 if p >= 0.1 else 1
    return f"{half_up(100 * p, digits)} % [{half_up(100 * lo, digits)}, {half_up(100 * hi, digits)}]"


def seed002_air_data(runs):
    """docs/findings-seed002.md: per setting (noise scale, turbulence) and detector, over the flights
    that flew (no `failure`): Pd over the faulty ones and correct isolation over those with an isolated
    set (Wilson intervals), the median delay of the detected, the medians over the faulty flights of the
    bias-estimate error and the air-data error (and of lane 0's raw sensors), and the flights with a
    false alarm."""
    out = [
        "| study, setting | detector | Pd [95 % CI] | correct isolation [95 % CI] | delay p50 | bias error p50 | air data error p50 (raw) | flights with a false alarm [95 % CI] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    settings = [
        # (deck, setting, noise scale, turbulence m/s, detectors, the setting's counts in its label)
        ("studies/seed002_air_data.toml", "best case, noise x1, calm", 1.0, 0.0, ["patent", "patent_wald", "window10"], True),
        ("studies/seed002_air_data.toml", "best case, noise x1, turbulence", 1.0, 0.5, ["patent"], False),
        ("studies/seed002_air_data.toml", "best case, noise x2, calm", 2.0, 0.0, ["patent"], False),
        ("studies/seed002_hifi_truth.toml", "hi-fi truth, calm", 1.0, 0.0, ["patent", "patent_wald", "voting"], True),
        ("studies/seed002_hifi_truth.toml", "hi-fi truth, turbulence", 1.0, 0.5, ["patent", "voting"], False),
    ]
    labels = {"patent": "patent", "patent_wald": "patent + Wald", "window10": "10-sample window", "voting": "voting"}
    for deck, setting, noise, gust, detectors, with_counts in settings:
        d = pl.read_parquet(runs[deck] / "trials.parquet")
        for i, det in enumerate(detectors):
            flown = d.filter(
                (pl.col("detector") == det)
                & (pl.col("noise_scale") == noise)
                & (pl.col("gust_std_mps") == gust)
                & pl.col("failure").is_null()
            )
            faulty = flown.filter(~pl.col("fault_free"))
            detected = faulty.filter(pl.col("detected").fill_null(False))
            decided = faulty.filter(pl.col("isolated").is_not_null())
            correct = int(decided["isolated_correctly"].fill_null(False).sum())
            pd_ = wilson(detected.height, faulty.height)
            iso = wilson(correct, decided.height)
            label = f"{setting} ({faulty.height:,} faulty, {flown.height:,} flights)" if with_counts else setting
            bias = faulty["bias_error_rms_sigma"].median() if det != "voting" else None
            raw = f" ({half_up(faulty['raw_rms_sigma'].median(), 1)} σ)" if i == 0 else ""
            out.append(
                f"| {label if i == 0 else ''} | {labels[det]} | {pd_[0]:.3f} [{pd_[1]:.3f}, {pd_[2]:.3f}] | "
                f"{iso[0]:.3f} [{iso[1]:.3f}, {iso[2]:.3f}] | {half_up(detected['delay_s'].median(), 3)} s | "
                f"{'-' if bias is None else half_up(bias) + ' σ'} | {half_up(faulty['estimate_rms_sigma'].median())} σ{raw} | "
                f"{percent_interval(int(flown['false_alarm'].sum()), flown.height)} |".replace("|  |", "| |")
            )
    return out


def held_s_thresholds(run):
    """Each detector's calibrated hold (s) in RUN's thresholds.csv."""
    holds = pl.read_csv(run / "thresholds.csv").filter(pl.col("statistic") == "held_s")
    return dict(zip(holds["detector"].to_list(), holds["detector_threshold"].to_list()))


def detected_of_lanes(summary, detector, lanes):
    """(detected, flown) of `detector`'s faults on `lanes` faulty lanes in a summary.csv's rows."""
    x = summary.filter((pl.col("detector") == detector) & (pl.col("faulty_lanes") == lanes))
    return int(x["detected"].sum()), int(x["trials"].sum() - x["failed"].sum())


def seed002_equal_pfa(runs):
    """docs/findings-seed002.md, the dual UKF against voting at equal false-alarm rates: each detector's
    hold calibrated at the deck's Pfa (thresholds.csv), and at it Pd per fault (summary.csv's calibrated
    rows, one lane or all three; the detections in brackets) and the median delay (detectors.csv)."""
    run = runs["studies/seed002_hifi_truth.toml"]
    hold = held_s_thresholds(run)
    s = pl.read_csv(run / "summary.csv").filter(pl.col("thresholds") == "calibrated")
    d = pl.read_csv(run / "detectors.csv").filter(pl.col("thresholds") == "calibrated")
    pair = [("patent", "dual UKF (patent), hold"), ("voting", "voting, persistence")]
    out = [
        "| faults | " + " | ".join(f"{label} {half_up(hold[det], 2).rstrip('0').rstrip('.')} s" for det, label in pair) + " |",
        "|---|---|---|",
    ]
    for lanes, label in [(1.0, "one lane"), (3.0, "all three lanes, common mode")]:
        cells, faults = [], None
        for det, _ in pair:
            k, faults = detected_of_lanes(s, det, lanes)
            cells.append(f"{k / faults:.3f} ({k:,})")
        out.append(f"| {label} ({faults:,}) | " + " | ".join(cells) + " |")
    delays = []
    for det, _ in pair:
        v = d.filter(pl.col("detector") == det)["delay_p50_s"][0]
        delays.append(f"{half_up(v, 2 if v < 1 else 1)} s")
    out.append("| delay p50 | " + " | ".join(delays) + " |")
    return out


def seed002_holds_flown(runs):
    """docs/findings-seed002.md, the declaration hold flown: per hold, over the hi-fi deck's flights
    flown, the flights with a false alarm, Pd over the faulty ones (Wilson interval), the median delay
    and the correct isolation over the isolated."""
    d = pl.read_parquet(runs["studies/seed002_hifi_truth.toml"] / "trials.parquet").filter(pl.col("failure").is_null())
    flights = d.filter(pl.col("detector") == "patent").height
    faults = d.filter((pl.col("detector") == "patent") & ~pl.col("fault_free")).height
    out = [
        f"| hold | flights with a false alarm (of {flights:,}) | Pd ({faults:,} faults) [95 % CI] | delay p50 | correct isolation |",
        "|---|---|---|---|---|",
    ]
    for label, det in [("0.1 s (the deck's)", "patent"), ("0.5 s", "patent_hold_500ms"), ("1 s", "patent_hold_1s"), ("3 s", "patent_hold_3s")]:
        x = d.filter(pl.col("detector") == det)
        f = x.filter(~pl.col("fault_free"))
        hit = f.filter(pl.col("detected"))
        decided = f.filter(pl.col("isolated").is_not_null())
        p, lo, hi = wilson(hit.height, f.height)
        delay = hit["delay_s"].median()
        out.append(
            f"| {label} | {half_up(100 * x['false_alarm'].mean(), 1)} % | {p:.3f} [{lo:.3f}, {hi:.3f}] | "
            f"{half_up(delay, 2 if delay < 1 else 1)} s | {decided['isolated_correctly'].mean():.3f} |"
        )
    return out


def seed002_lanes(runs):
    """docs/findings-seed002.md, two and three faulty lanes: per count of faulty lanes and detector, over
    the faulty flights that flew (calm air and turbulence together), Pd and correct isolation (Wilson
    intervals), the median delay of the detected, and the median air-data error of the detector's
    estimate (and of lane 0's raw sensors) over the fault's second half."""
    d = pl.read_parquet(runs["studies/seed002_lanes.toml"] / "trials.parquet").filter(
        pl.col("failure").is_null() & ~pl.col("fault_free")
    )
    labels = {"patent": "patent", "patent_wald": "patent + Wald", "voting": "voting"}
    out = [
        "| faulty lanes | detector | Pd [95 % CI] | correct isolation [95 % CI] | delay p50 | air data error p50 (raw lane 0) |",
        "|---|---|---|---|---|---|",
    ]
    for lanes in sorted(d["faulty_lanes"].unique().to_list()):
        for i, (det, label) in enumerate(labels.items()):
            faulty = d.filter((pl.col("detector") == det) & (pl.col("faulty_lanes") == lanes))
            detected = faulty.filter(pl.col("detected").fill_null(False))
            decided = faulty.filter(pl.col("isolated").is_not_null())
            pd_ = wilson(detected.height, faulty.height)
            iso = wilson(int(decided["isolated_correctly"].fill_null(False).sum()), decided.height)
            raw = f" ({half_up(faulty['raw_rms_sigma'].median(), 1)} σ)" if i == 0 else ""
            isolation = f"{iso[0]:.3f} [{iso[1]:.3f}, {iso[2]:.3f}]" if decided.height else "- (none named)"
            delay = detected["delay_s"].median()
            out.append(
                f"| {f'{lanes} ({faulty.height:,} flights)' if i == 0 else ''} | {label} | "
                f"{pd_[0]:.3f} [{pd_[1]:.3f}, {pd_[2]:.3f}] | {isolation} | "
                f"{'-' if delay is None else half_up(delay, 3) + ' s'} | {half_up(faulty['estimate_rms_sigma'].median())} σ{raw} |"
                .replace("|  |", "| |")
            )
    return out


FACTOR_NAMES = {
    "output": "output", "fault_kind": "fault kind", "size": "size", "onset_s": "onset",
    "noise_scale": "noise scale", "noise_realisation": "noise realisation",
    "pitch_moment": "pitch moment", "elevator": "elevator",
}


def seed000_sensitivity(runs):
    """docs/findings-seed000.md, which factors drive the misses and the false alarms: `fdimc sensitivity`
    on the robustness deck (4,096 base samples) at the thresholds its run calibrated; per outcome and
    detector, the three largest total indices, the two model errors' total indices, and the sum of the
    first-order indices, with 95 % bootstrap intervals (sensitivity.csv)."""
    deck = "studies/seed000_robustness.toml"
    run = runs[deck]
    out_dir = run.parent / f"{run.name}_sensitivity"
    if not (out_dir / "sensitivity.csv").exists():
        cmd = [fdimc_binary(), "sensitivity", str(ROOT / deck), "--base-samples", "4096", "--thresholds",
               str(run / "thresholds.csv"), "--out", str(out_dir), "--force", "--quiet"]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode != 0:
            raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr}")
    s = pl.read_csv(out_dir / "sensitivity.csv")

    def index(r, kind):
        lo, hi = max(r[f"{kind}_lo"], 0.0), r[f"{kind}_hi"]
        return f"{r[kind]:.2f} [{lo:.2f}, {hi:.2f}]"

    out = [
        "Sensitivity: `fdimc sensitivity studies/seed000_robustness.toml --base-samples 4096 --thresholds "
        "results/seed000_robustness/thresholds.csv`.",
        "",
        "| outcome, detector (its mean) | largest total indices ST [95 % CI] | model errors' ST: pitch moment, elevator | sum of S1 |",
        "|---|---|---|---|",
    ]
    labels = {"seed": "seed filter", "fast": "fast filter", "cusum": "CUSUM", "kalman": "Kalman chi-square"}
    for outcome, detectors in [("pd", ["seed", "cusum", "kalman"]), ("pfa", ["seed", "fast", "cusum", "kalman"])]:
        for det in detectors:
            x = s.filter((pl.col("outcome") == outcome) & (pl.col("detector") == det))
            if x.height == 0:
                raise SystemExit(f"{out_dir}/sensitivity.csv: no {outcome} rows of detector {det}")
            rows = sorted(x.iter_rows(named=True), key=lambda r: -r["st"])
            top = ", ".join(f"{FACTOR_NAMES[r['factor']]} {index(r, 'st')}" for r in rows[:3])
            model = ", ".join(index(next(r for r in rows if r["factor"] == f), "st") for f in ["pitch_moment", "elevator"])
            mean = rows[0]["outcome_mean"]
            mean_text = f"{mean:.3f}" if outcome == "pd" else f"{mean:.4f}"
            out.append(
                f"| {outcome.replace('pd', 'Pd').replace('pfa', 'Pfa')}, {labels[det]} ({mean_text}) | {top} | {model} | "
                f"{rows[0]['sum_s1']:.2f} |"
            )
    return out


def seed001_recovering_residual(runs):
    """docs/findings-seed001.md, the recovering residual on noisy flights: per filter and window N, over
    the faulty flights flown, the losses detected (Wilson interval) at the deck's thresholds (calibrated
    at Pfa 0.01 on the first run's fault-free flights and written into the deck), and over the detected
    the median time above the threshold in the detection window, the median loss error (and of its
    absolute value) and the engines named right."""
    d = pl.read_parquet(runs["studies/seed001_recovering_residual.toml"] / "trials.parquet").filter(
        ~pl.col("fault_free") & pl.col("failure").is_null()
    )
    faulty = d.filter(pl.col("detector") == "plain_n1").height
    out = [
        f"| filter | N | detected of {faulty} (Pd [95 % CI]) | time above threshold in the 2 s window, median | loss error, median (abs) | engine named |",
        "|---|---|---|---|---|---|",
    ]
    for label, prefix in [("plain", "plain"), ("slow (0.01)", "slow"), ("fast (0.1)", "fast")]:
        for n in [1, 5, 10]:
            x = d.filter(pl.col("detector") == f"{prefix}_n{n}")
            hit = x.filter(pl.col("detected"))
            p, lo, hi = wilson(hit.height, x.height)
            if hit.height:
                above = f"{half_up(hit['fhat_above_threshold_s'].median())} s"
                error = hit["loss_error_percent"]
                loss = f"{half_up(error.median(), 1)} ({half_up(error.abs().median(), 1)}) points"
                named = str(int(hit["isolated_correctly"].sum()))
            else:
                above = loss = named = "-"
            out.append(
                f"| {label if n == 1 else ''} | {n} | {hit.height} ({p:.3f} [{lo:.3f}, {hi:.3f}]) | {above} | {loss} | {named} |"
                .replace("|  |", "| |")
            )
    return out


GYRO_GRADES = [
    # (label, angle random walk deg/sqrt(h), bias stability deg/h): typical data-sheet figures, choices.
    ("tactical: 0.1 deg/sqrt(h), 1 deg/h", "0.1", "1.0"),
    ("navigation: 0.002 deg/sqrt(h), 0.01 deg/h", "0.002", "0.01"),
]


def gyro_grade_deck(arw, bias):
    return (
        f"studies/seed001_recovering_residual.toml vehicle.gyro_arw_deg_per_sqrt_h={arw} "
        f"vehicle.gyro_bias_stability_deg_per_h={bias}"
    )


def seed001_gyro_grade(runs):
    """docs/findings-seed001.md, the recovering residual per gyro grade: each filter and window's losses
    detected of the faulty flights flown, at thresholds calibrated at Pfa 0.01 on the deck's fault-free
    flights (detectors.csv's calibrated rows, Wilson interval), and the median delay."""
    out = [
        "| gyro grade | filter | N = 1 | N = 5 | N = 10 |",
        "|---|---|---|---|---|",
    ]
    for label, arw, bias in GYRO_GRADES:
        d = pl.read_csv(runs[gyro_grade_deck(arw, bias)] / "detectors.csv").filter(pl.col("thresholds") != "deck")
        for i, (filter_label, prefix) in enumerate(
            [("plain", "plain"), ("slow (0.01)", "slow"), ("fast (0.1)", "fast")]
        ):
            cells = []
            for n in [1, 5, 10]:
                r = d.filter(pl.col("detector") == f"{prefix}_n{n}").row(0, named=True)
                delay = "" if r["delay_p50_s"] is None else f", {half_up(r['delay_p50_s'])} s"
                cells.append(f"{with_interval(r, 'pd')}{delay}")
            row = f"| {label if i == 0 else ''} | {filter_label} | " + " | ".join(cells) + " |"
            out.append(row.replace("|  |", "| |"))
    return out


def validated(run, thresholds_run):
    """`fdimc summarize RUN --thresholds OTHER/thresholds.csv`: RUN's outcomes at OTHER's calibrated
    thresholds, in RUN/validation/."""
    cmd = [fdimc_binary(), "summarize", str(run), "--thresholds", str(thresholds_run / "thresholds.csv")]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr}")
    return run / "validation"


def banks_at_equal_pfa(ff, mc, variants):
    """The banks at an equal false-alarm rate: each variant's hold calibrated at Pfa 0.01 per flight on
    `seed004_fault_free.toml`'s fault-free flights (`ff`), applied to the run `mc` (its `validation`
    rows): Pd with its interval and the delay quantiles."""
    v = validated(mc, ff)
    holds = held_s_thresholds(ff)
    d = pl.read_csv(v / "detectors.csv").filter(pl.col("thresholds") == "validation")
    # The faults flown to the end (the paired table's count: detectors.csv's includes failed flights).
    faults = pl.read_csv(v / "comparison.csv").filter(pl.col("thresholds") == "validation")["faulty_units"][0]
    out = [
        f"| variant | hold at 1 % | Pd [95 % CI] ({faults:,} faults) | delay p50 / p90 |",
        "|---|---|---|---|",
    ]
    for label, detector in variants:
        r = d.filter(pl.col("detector") == detector).row(0, named=True)
        out.append(
            f"| {label} | {half_up(holds[detector], 1)} s | {with_interval(r, 'pd')} | "
            f"{half_up(r['delay_p50_s'], 1)} / {half_up(r['delay_p90_s'], 1)} s |"
        )
    return out


def seed004_equal_pfa(runs):
    """docs/findings-seed004.md: [banks_at_equal_pfa] on the Monte Carlo deck."""
    return banks_at_equal_pfa(
        runs["studies/seed004_fault_free.toml"], runs["studies/seed004_monte_carlo.toml"], MONTE_CARLO_VARIANTS
    )


def seed004_norm_forms_equal_pfa(runs):
    """docs/findings-seed004.md: [banks_at_equal_pfa] on the norm-forms deck."""
    return banks_at_equal_pfa(
        runs["studies/seed004_fault_free.toml"],
        runs["studies/seed004_norm_forms.toml"],
        [
            ("EMMAE (Gaussian density)", "emmae"),
            ("EKF + fast, isotropic", "ekf_fast"),
            ("EKF + fast, 1-D", "ekf_fast_1d"),
            ("improved STMMAE, isotropic", "improved_stmmae"),
            ("improved STMMAE, 1-D", "improved_stmmae_1d"),
        ],
    )


def seed002_lanes_equal_pfa(runs):
    """docs/findings-seed002.md, the lanes at an equal false-alarm rate: the holds calibrated at Pfa 0.01
    on the hi-fi deck's fault-free flights (its thresholds.csv) applied to the lanes run (`summarize
    --thresholds`, summary.csv's validation rows): Pd per count of faulty lanes."""
    hifi, lanes = runs["studies/seed002_hifi_truth.toml"], runs["studies/seed002_lanes.toml"]
    v = validated(lanes, hifi)
    hold = held_s_thresholds(hifi)
    s = pl.read_csv(v / "summary.csv").filter(pl.col("thresholds") == "validation")
    pair = [("patent", "dual UKF (patent)"), ("voting", "voting")]
    out = [
        "| faulty lanes | " + " | ".join(f"{label}, held {hold[det]:g} s: Pd [95 % CI]" for det, label in pair) + " |",
        "|---|---|---|",
    ]
    for lanes_hit in sorted(x for x in s["faulty_lanes"].unique().to_list() if x > 0):
        cells = []
        for det, _ in pair:
            k, n = detected_of_lanes(s, det, lanes_hit)
            p, lo, hi = wilson(k, n)
            cells.append(f"{k}/{n}, {p:.3f} [{lo:.3f}, {hi:.3f}]")
        out.append(f"| {int(lanes_hit)} | " + " | ".join(cells) + " |")
    return out


def seed004_norm_forms(runs):
    """docs/findings-seed004.md, the fast probabilities in two readings (section 2.6): detectors.csv at
    the deck's thresholds, then per fault kind the windows detected and those correctly isolated among
    the isolated (trials.parquet; flights flown to the end)."""
    run = runs["studies/seed004_norm_forms.toml"]
    rows = [
        ("EMMAE (Gaussian density)", "emmae"),
        ("EKF + fast, isotropic (`euclidean_norm`)", "ekf_fast"),
        ("EKF + fast, 1-D (`euclidean_norm_1d`)", "ekf_fast_1d"),
        ("improved STMMAE, isotropic", "improved_stmmae"),
        ("improved STMMAE, 1-D", "improved_stmmae_1d"),
    ]
    out = surface_detectors(
        run, rows, ["Pd [95 % CI]", "correct isolation", "delay p50 / p90", "recovery p50, rate", "false alarms"]
    )
    d = pl.read_parquet(run / "trials.parquet").filter(pl.col("failure").is_null() & ~pl.col("fault_free"))
    kinds = sorted(d["kind"].unique().to_list())
    out[0] += "".join(f" {k}: Pd, correct isolation |" for k in kinds)
    out[1] += "---|" * len(kinds)
    for i, (_, detector) in enumerate(rows):
        for k in kinds:
            x = d.filter((pl.col("detector") == detector) & (pl.col("kind") == k))
            decided = x.filter(pl.col("isolated").is_not_null())
            correct = int(decided["isolated_correctly"].fill_null(False).sum())
            out[i + 2] += f" {int(x['detected'].sum())}/{x.height}, {correct}/{decided.height} |"
    return out


def kaplan_meier(times, events):
    """The Kaplan-Meier survival curve of `times` (an event where `events` is true, censored there
    otherwise): [(t, S(t), Greenwood's sum of d / (n (n - d)))] at each event time."""
    order = sorted(zip(times, events))
    at_risk, surviving, greenwood, curve, i = len(order), 1.0, 0.0, [], 0
    while i < len(order):
        t = order[i][0]
        same = [e for u, e in order[i:] if u == t]
        d = sum(same)
        if d:
            surviving *= 1 - d / at_risk
            greenwood += d / (at_risk * (at_risk - d)) if at_risk > d else math.inf
            curve.append((t, surviving, greenwood))
        at_risk -= len(same)
        i += len(same)
    return curve


def survival_at(curve, t):
    """S(t) and its 95 % interval (Greenwood on the log(-log) scale; Kalbfleisch and Prentice)."""
    s, g = 1.0, 0.0
    for u, su, gu in curve:
        if u > t:
            break
        s, g = su, gu
    if s in (0.0, 1.0) or not math.isfinite(g):
        return s, s, s
    w = 1.959963984540054 * math.sqrt(g) / abs(math.log(s))
    return s, s ** math.exp(w), s ** math.exp(-w)


MONTE_CARLO_VARIANTS = [
    ("EMMAE", "emmae"),
    ("EKF + fast probability", "ekf_fast"),
    ("STMMAE", "stmmae"),
    ("improved STMMAE", "improved_stmmae"),
]
SEED_TUNING_VARIANTS = [
    ("EMMAE, `_seed`", "emmae_seed"),
    ("EKF + fast probability, `_seed`", "ekf_fast_seed"),
    ("STMMAE, `_seed`", "stmmae_seed"),
    ("improved STMMAE, `_seed`", "improved_stmmae_seed"),
]


def recovery_censored(run, deck, variants):
    """Recovery counted with the windows that never recover: over the detected fault windows of flights
    flown to the end, the recovery delay (from the window's end to the no-fault model's probability back
    at 0.9), censored at the flight's end where it never came back; the Kaplan-Meier median and the
    share recovered within 2 and 5 s, beside the median over recovered windows only (detectors.csv's
    `recovery_p50_s`)."""
    duration = tomllib.loads((ROOT / deck).read_text())["study"]["duration_s"]
    d = pl.read_parquet(run / "trials.parquet").filter(
        pl.col("failure").is_null() & pl.col("recovered").is_not_null()
    )
    out = [
        "| variant | detected windows | recovered / censored | median, recovered only | Kaplan-Meier median | recovered within 2 s [95 % CI] | within 5 s [95 % CI] |",
        "|---|---|---|---|---|---|---|",
    ]
    for label, detector in variants:
        x = d.filter(pl.col("detector") == detector)
        events = x["recovered"].to_list()
        times = [r if e else duration - end for r, e, end in zip(x["recovery_delay_s"], events, x["end_s"])]
        curve = kaplan_meier(times, events)
        median = next((t for t, s, _ in curve if s <= 0.5), None)
        recovered = sum(events)

        def within(t):
            s, lo, hi = survival_at(curve, t)
            return f"{half_up(1 - s)} [{half_up(1 - hi)}, {half_up(1 - lo)}]"

        only = x.filter(pl.col("recovered"))["recovery_delay_s"].median()
        out.append(
            f"| {label} | {x.height:,} | {recovered:,} / {x.height - recovered:,} | {half_up(only)} s | "
            f"{'not reached' if median is None else half_up(median) + ' s'} | {within(2.0)} | {within(5.0)} |"
        )
    return out


def seed004_recovery_censored(runs):
    """docs/findings-seed004.md: [recovery_censored] on the Monte Carlo deck."""
    deck = "studies/seed004_monte_carlo.toml"
    return recovery_censored(runs[deck], deck, MONTE_CARLO_VARIANTS)


def seed004_recovery_censored_seed_tuning(runs):
    """docs/findings-seed004.md: [recovery_censored] on the Monte Carlo trials under the seed's tuning."""
    deck = "studies/seed004_monte_carlo_tunings.toml"
    return recovery_censored(runs[deck], deck, SEED_TUNING_VARIANTS)


def accuracy(run, variants):
    """The surface estimate's accuracy at the fault's onset and after: per variant, the median over fault
    windows of the RMS error over the window's first second, over the whole window and over its second
    half (detectors.csv), and the last variant's median paired difference from each other one with its
    95 % sign-test interval (comparison.csv)."""
    d = pl.read_csv(run / "detectors.csv").filter(pl.col("thresholds") == "deck")
    c = pl.read_csv(run / "comparison.csv").filter(pl.col("thresholds") == "deck")
    spans = [("first second", "first_s_"), ("whole window", "window_"), ("second half", "")]
    last_label, last = variants[-1]
    out = [
        "| variant | " + " | ".join(f"RMS, {n} (p50)" for n, _ in spans) + " | "
        + " | ".join(f"{last_label} minus it, {n} [95 % CI]" for n, _ in spans) + " |",
        "|---" * 7 + "|",
    ]
    for label, detector in variants:
        r = d.filter(pl.col("detector") == detector).row(0, named=True)
        cells = [f"{half_up(r[f'estimate_rms_{k}p50_deg'])} deg" for _, k in spans]
        pair = c.filter((pl.col("detector_a") == detector) & (pl.col("detector_b") == last))
        for _, k in spans:
            if pair.height != 1:
                cells.append("-")
                continue
            q = pair.row(0, named=True)
            name = f"median_surface_estimate_rms_{k}deg_b_minus_a"
            cells.append(f"{half_up(q[name], 3)} [{half_up(q[name + '_lo'], 3)}, {half_up(q[name + '_hi'], 3)}] deg")
        out.append(f"| {label} | " + " | ".join(cells) + " |")
    return out


def seed004_accuracy(runs):
    """docs/findings-seed004.md: [accuracy] on the Monte Carlo deck."""
    return accuracy(runs["studies/seed004_monte_carlo.toml"], MONTE_CARLO_VARIANTS)


def seed004_accuracy_seed_tuning(runs):
    """docs/findings-seed004.md: [accuracy] on the Monte Carlo trials under the seed's tuning."""
    return accuracy(runs["studies/seed004_monte_carlo_tunings.toml"], SEED_TUNING_VARIANTS)

# name -> (page, decks, fast: runs in CI, wall time measured on machine C, renderer)
NOISE_LAWS = ["gaussian", "student_t(9.1)", "student_t(5)"]
NOISE_TAIL_DECKS = [f'studies/seed000_rare_false_alarms.toml noise.sensor_law="{law}"' for law in NOISE_LAWS]
# The same deck with the empirical law of the small log's roll-rate gyro (its own deck: the law names a file).
EMPIRICAL_NOISE_DECK = "studies/seed000_rare_empirical.toml"


def seed000_noise_tails(runs):
    """docs/findings-seed000.md, "Noise with real tails": per sensor-noise law (every output; the last the
    empirical law of a log's channel, from its own deck), the tail
    fit's thresholds of `seed_x124` for 1e-5 and 1e-9 false alarms per flight hour (the hour's 10 s
    segments taken as independent) on alpha and q, each with its 95 % interval, and its multiple of the
    Gaussian threshold."""
    def thresholds(deck):
        d = pl.read_csv(runs[deck] / "tail.csv")
        d = d.filter((pl.col("detector") == "seed_x124") & (pl.col("query") == "threshold_for_pfa"))
        return {(r["statistic"], r["target_pfa_per_hour"]): r for r in d.to_dicts()}
    base = thresholds(NOISE_TAIL_DECKS[0])
    lines = ["| sensor noise | alpha, 1e-5 / h | alpha, 1e-9 / h | q, 1e-5 / h | q, 1e-9 / h |", "|---|---|---|---|---|"]
    rows = [(f"`{law}`", deck) for law, deck in zip(NOISE_LAWS, NOISE_TAIL_DECKS)]
    rows.append(("empirical: the small log's `gyro_rad[0]`", EMPIRICAL_NOISE_DECK))
    for label, deck in rows:
        t = thresholds(deck)
        cells = []
        for statistic in ["alpha_rad", "q_rad_s"]:
            for target in [1e-5, 1e-9]:
                r = t[(statistic, target)]
                times = r["threshold"] / base[(statistic, target)]["threshold"]
                cells.append(f"{r['threshold']:.3g} [{r['threshold_lo']:.3g}, {r['threshold_hi']:.3g}] (x {times:.1f})")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return lines


TABLES = {
    "seed000_noise_tails": (
        "docs/findings-seed000.md",
        NOISE_TAIL_DECKS + [EMPIRICAL_NOISE_DECK],
        True,
        "15 s",
        seed000_noise_tails,
    ),
    "seed004_reference_tuning": (
        "docs/findings-seed004.md",
        ["studies/seed004_reference_tuning.toml"],
        True,
        "10 s",
        seed004_reference_tuning,
    ),
    "seed004_surfaces": (
        "docs/findings-seed004.md",
        ["studies/seed004_surfaces.toml"],
        True,
        "8 s",
        seed004_surfaces,
    ),
    "seed004_monte_carlo": (
        "docs/findings-seed004.md",
        ["studies/seed004_monte_carlo.toml"],
        True,
        "54 s",
        seed004_monte_carlo,
    ),
    "seed004_monte_carlo_tunings": (
        "docs/findings-seed004.md",
        ["studies/seed004_monte_carlo_tunings.toml"],
        False,
        "3 min",
        seed004_monte_carlo_tunings,
    ),
    "seed004_tunings_paired": (
        "docs/findings-seed004.md",
        ["studies/seed004_monte_carlo_tunings.toml"],
        False,
        "3 min (the same run)",
        seed004_tunings_paired,
    ),
    "seed004_equal_pfa": (
        "docs/findings-seed004.md",
        ["studies/seed004_fault_free.toml", "studies/seed004_monte_carlo.toml"],
        False,
        "3 min",
        seed004_equal_pfa,
    ),
    "seed000_sensitivity": (
        "docs/findings-seed000.md",
        ["studies/seed000_robustness.toml"],
        False,
        "1 min",
        seed000_sensitivity,
    ),
    "seed001_recovering_residual": (
        "docs/findings-seed001.md",
        ["studies/seed001_recovering_residual.toml"],
        False,
        "1 min",
        seed001_recovering_residual,
    ),
    "seed001_gyro_grade": (
        "docs/findings-seed001.md",
        [gyro_grade_deck(arw, bias) for _, arw, bias in GYRO_GRADES],
        False,
        "3 min",
        seed001_gyro_grade,
    ),
    "seed002_equal_pfa": (
        "docs/findings-seed002.md",
        ["studies/seed002_hifi_truth.toml"],
        False,
        "1 min",
        seed002_equal_pfa,
    ),
    "seed002_holds_flown": (
        "docs/findings-seed002.md",
        ["studies/seed002_hifi_truth.toml"],
        False,
        "1 min (the same run)",
        seed002_holds_flown,
    ),
    "seed002_lanes": (
        "docs/findings-seed002.md",
        ["studies/seed002_lanes.toml"],
        True,
        "20 s",
        seed002_lanes,
    ),
    "seed004_norm_forms": (
        "docs/findings-seed004.md",
        ["studies/seed004_norm_forms.toml"],
        True,
        "30 s",
        seed004_norm_forms,
    ),
    "seed004_recovery_censored": (
        "docs/findings-seed004.md",
        ["studies/seed004_monte_carlo.toml"],
        True,
        "54 s (the Monte Carlo run)",
        seed004_recovery_censored,
    ),
    "seed004_accuracy": (
        "docs/findings-seed004.md",
        ["studies/seed004_monte_carlo.toml"],
        True,
        "54 s (the Monte Carlo run)",
        seed004_accuracy,
    ),
    "seed004_recovery_censored_seed_tuning": (
        "docs/findings-seed004.md",
        ["studies/seed004_monte_carlo_tunings.toml"],
        False,
        "3 min (the tunings run)",
        seed004_recovery_censored_seed_tuning,
    ),
    "seed004_accuracy_seed_tuning": (
        "docs/findings-seed004.md",
        ["studies/seed004_monte_carlo_tunings.toml"],
        False,
        "3 min (the tunings run)",
        seed004_accuracy_seed_tuning,
    ),
    "seed004_norm_forms_equal_pfa": (
        "docs/findings-seed004.md",
        ["studies/seed004_fault_free.toml", "studies/seed004_norm_forms.toml"],
        False,
        "3 min",
        seed004_norm_forms_equal_pfa,
    ),
    "seed002_lanes_equal_pfa": (
        "docs/findings-seed002.md",
        ["studies/seed002_hifi_truth.toml", "studies/seed002_lanes.toml"],
        False,
        "1.5 min",
        seed002_lanes_equal_pfa,
    ),
    "seed002_air_data": (
        "docs/findings-seed002.md",
        ["studies/seed002_air_data.toml", "studies/seed002_hifi_truth.toml"],
        False,
        "3.5 min",
        seed002_air_data,
    ),
    "fmu_aircraft": (
        "docs/findings-fmu.md",
        ["studies/fmu_aircraft.toml", "studies/fmu_aircraft_lti.toml"],
        True,
        "20 s",
        fmu_aircraft,
    ),
    "seed003_training": (
        "docs/findings-seed003.md",
        ["studies/seed003_accelerometer.toml", "studies/seed003_noise_trained.toml"],
        True,
        "8 s",
        seed003_training,
    ),
    "seed003_replay": (
        "docs/findings-seed003.md",
        ["studies/replay_px4.toml", "studies/replay_px4_gyro_calibrated.toml"],
        True,
        "5 s",
        seed003_replay,
    ),
    "seed003_online": (
        "docs/findings-seed003.md",
        ["studies/seed003_online.toml"],
        True,
        "7 s",
        seed003_online,
    ),
    "seed003_translation": (
        "docs/findings-seed003.md",
        ["studies/seed003_online.toml"] + [f"studies/seed003_online.toml imu.translation_mps2={a}" for a in TRANSLATIONS_MPS2],
        True,
        "25 s",
        seed003_translation,
    ),
    "seed003_window": (
        "docs/findings-seed003.md",
        [f"studies/seed003_online.toml training.window_s={w}" for w in WINDOWS_S],
        True,
        "25 s",
        seed003_window,
    ),
    "seed003_noise_estimated": (
        "docs/findings-seed003.md",
        ["studies/seed003_noise_tuned.toml", ESTIMATED_NOISE_DECK],
        True,
        "15 s",
        seed003_noise_estimated,
    ),
    "seed003_noise_tuned": (
        "docs/findings-seed003.md",
        ["studies/seed003_online.toml", "studies/seed003_noise_tuned.toml"],
        True,
        "15 s",
        seed003_noise_tuned,
    ),
}


def deck_and_edits(deck):
    """A deck as TABLES names it: its path, and the `SECTION.FIELD=VALUE`s the run sets on a copy."""
    path, *edits = deck.split()
    return path, edits


def provenance(decks):
    said, values = [], {}
    for deck in decks:
        path, edits = deck_and_edits(deck)
        if len(edits) == 1:
            # One field swept: one entry for the deck, its values listed.
            field, value = edits[0].split("=")
            values.setdefault((path, field), []).append(value)
            if len(values[(path, field)]) > 1:
                continue
        said.append((path, edits))
    text = []
    for path, edits in said:
        seed = tomllib.loads((ROOT / path).read_text())["study"]["seed"]
        if len(edits) == 1:
            field = edits[0].split("=")[0]
            text.append(
                f"`{path}` (seed {seed}) with `{field}` = {', '.join(values[(path, field)])}, "
                "each `fdimc run` on a copy with that line"
            )
        elif edits:
            lines = ", ".join(f"`{e.replace('=', ' = ')}`" for e in edits)
            text.append(f"`{path}` (seed {seed}) with {lines} (`fdimc run` on a copy with those lines)")
        else:
            text.append(f"`{path}` (seed {seed}, `fdimc run {path}`)")
    return f"Deck{'s' if len(text) > 1 else ''} {', '.join(text)}; generated by `python3 scripts/findings.py`."


def edited_deck(path, edits, runs):
    """A copy of deck `path` in `runs` with each `SECTION.FIELD = VALUE` of `edits` set (replaced in its
    section, or added as the section's first line)."""
    lines = (ROOT / path).read_text().splitlines()
    for edit in edits:
        field, value = edit.split("=")
        section, name = field.rsplit(".", 1)
        start = lines.index(f"[{section}]")
        end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("[")), len(lines))
        at = next((i for i in range(start + 1, end) if re.match(rf"{re.escape(name)}\s*=", lines[i])), None)
        if at is None:
            lines.insert(start + 1, f"{name} = {value}")
        else:
            lines[at] = f"{name} = {value}"
    suffix = "__".join(f"{e.split('=')[0].rsplit('.', 1)[1]}_{e.split('=')[1].strip(chr(34))}" for e in edits)
    copy = runs / f"{pathlib.Path(path).stem}__{suffix}.toml"
    copy.write_text("\n".join(lines) + "\n")
    return copy


def build_fmus_for(decks):
    """The test FMUs are built from source, not committed (`cargo run --release --example build_fmus`):
    built once, before any of `decks` that flies them runs."""
    wanted = any("fmu" in pathlib.Path(deck_and_edits(d)[0]).stem for d in decks)
    if wanted and not any((ROOT / "studies" / "fmus").glob("*.fmu")):
        built = subprocess.run(["cargo", "run", "--release", "--locked", "--example", "build_fmus"], cwd=ROOT,
                               capture_output=True, text=True)
        if built.returncode != 0:
            raise SystemExit(f"cargo run --example build_fmus failed:\n{built.stderr}")


def run_deck(deck, runs):
    path, edits = deck_and_edits(deck)
    deck_file = edited_deck(path, edits, runs) if edits else ROOT / path
    out = runs / deck_file.stem
    if (out / "trials.parquet").exists():
        return out
    build_fmus_for([deck])
    cmd = [fdimc_binary(), "run", str(deck_file), "--quiet", "--force", "--out", str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr}")
    return out


def replace_block(text, name, lines, page):
    """`text` with the lines between NAME's markers replaced by `lines`, indented as the markers are (a
    table inside a list item is indented with it)."""
    begin = re.compile(rf"^([ \t]*)<!-- generated: {re.escape(name)} \(scripts/findings.py\) -->\n", re.M)
    end = re.compile(rf"^[ \t]*<!-- end generated: {re.escape(name)} -->\n", re.M)
    b, e = list(begin.finditer(text)), list(end.finditer(text))
    if len(b) != 1 or len(e) != 1 or e[0].start() < b[0].end():
        raise SystemExit(f"{page}: needs exactly one '<!-- generated: {name} (scripts/findings.py) -->' line and, after it, one '<!-- end generated: {name} -->'")
    indent = b[0].group(1)
    body = "".join(f"{indent}{line}\n" if line else "\n" for line in lines)
    return text[: b[0].end()] + body + text[e[0].start():]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="fail on any difference; write nothing")
    ap.add_argument("--all", action="store_true", help="every table, the slow decks included")
    ap.add_argument("--runs", type=pathlib.Path, help="keep or reuse the runs in this folder")
    ap.add_argument("--list", action="store_true", help="list the tables and stop")
    ap.add_argument("--jobs", type=int, default=2, help="runs at a time (default 2)")
    ap.add_argument("names", nargs="*", help="only these tables")
    args = ap.parse_args()
    if args.list:
        for name, (page, decks, fast, wall, _) in TABLES.items():
            print(f"{name}: {page}, {', '.join(decks)}, {'fast (CI)' if fast else 'on demand'}, {wall}")
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
    # Every deck first, `--jobs` at a time: a run's serial phases (the design, the training, the
    # summary) leave a core idle that another run's trials fill; the records do not depend on it.
    decks = list(dict.fromkeys(d for name in chosen for d in TABLES[name][1]))
    build_fmus_for(decks)
    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        list(pool.map(lambda d: run_deck(d, runs), decks))
    pages = {}
    for name in chosen:
        page, decks, _, _, render = TABLES[name]
        lines = [provenance(decks), ""] + render({deck: run_deck(deck, runs) for deck in decks})
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
