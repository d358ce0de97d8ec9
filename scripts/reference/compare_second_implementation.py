#!/usr/bin/env python3
"""Hold fdimc's detection-filter results against the second implementation (issue #86 item 1).

    compare_second_implementation.py DECK [--trials 3000] [--fdimc BIN] [--seed 12345]
                                     [--out table.csv] [--fdimc-dir DIR] [--pool-targets] [--alpha 0.01]

Runs `fdimc run DECK --trials N --out TMP --quiet` (its own seed, the deck's unless --fdimc-seed) and
second_implementation.py (beside this file) at the same trial count on its own seed (numpy
default_rng(--seed)), then compares, per detector both implement (kalman_chi2 and fmu detectors are
left out):

  * Pfa: the fault-free trials' false-alarm share; Fisher's exact test, two-sided;
  * Pd per fault kind x target x size bin (the deck's values or bin centres; --pool-targets pools the
    targets, which mixes distributions of very different delays: see the report); Fisher's exact test;
  * detection delay per kind x target x size bin: median and p90 with distribution-free 95 % intervals
    (binomial order statistics), tested by the two-sided Mann-Whitney U test (both sides >= 5 delays);
  * the fault-free trials' largest detection statistic per output (`pre_max_<output>`, the whole
    trial): the two-sample Kolmogorov-Smirnov test (a sharp test of the residual's law);

Holm's step-down correction over every test of the run; a test whose Holm-adjusted p-value is at most
--alpha (0.01) rejects. Prints one table (quantity, fdimc value with its 95 % interval (Wilson for a
rate), the second implementation's, the test, p, Holm-adjusted p, verdict), writes it as CSV (--out),
and exits 1 if any test rejects, 0 otherwise.

Environment (the venv $HOME/.cache/fdimc-ref, Python 3.11):
    $HOME/.cache/fdimc-ref/bin/pip install numpy==2.4.6 scipy==1.17.1 polars==1.31.0
    $HOME/.cache/fdimc-ref/bin/python scripts/reference/compare_second_implementation.py \
        studies/ci_seed000.toml --trials 3000 --out /tmp/compare_ci_seed000.csv
"""
from __future__ import annotations

import argparse
import math
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import polars as pl
from scipy.stats import binom, fisher_exact, ks_2samp, mannwhitneyu, norm

sys.dont_write_bytecode = True  # no __pycache__ beside the scripts
sys.path.insert(0, str(Path(__file__).resolve().parent))
import second_implementation as second  # noqa: E402


def wilson(k, n, z=norm.ppf(0.975)):
    if n == 0:
        return float("nan"), float("nan"), float("nan")
    p = k / n
    den = 1 + z * z / n
    c = (p + z * z / (2 * n)) / den
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return p, max(0.0, c - h), min(1.0, c + h)


def quantile_ci(v, q):
    """Sample quantile (type 7) and a distribution-free 95 % interval from binomial order statistics."""
    v = np.sort(np.asarray(v, dtype=float))
    n = len(v)
    if n == 0:
        return float("nan"), float("nan"), float("nan")
    est = float(np.quantile(v, q))
    lo_r = int(binom.ppf(0.025, n, q))          # 0-based ranks
    hi_r = int(binom.ppf(0.975, n, q))
    return est, float(v[max(lo_r - 1, 0)]), float(v[min(hi_r, n - 1)])


def holm(pvals):
    p = np.asarray(pvals, dtype=float)
    order = np.argsort(p)
    m = len(p)
    adj = np.empty(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[i]))
        adj[i] = running
    return adj


def key_bin(x):
    return None if x is None or (isinstance(x, float) and math.isnan(x)) else round(float(x), 9)


def fdimc_records(args, deck_path, trials):
    if args.fdimc_dir:
        folder = Path(args.fdimc_dir)
    else:
        folder = Path(tempfile.mkdtemp(prefix="fdimc_cmp_")) / "run"
        cmd = [args.fdimc, "run", str(deck_path), "--trials", str(trials), "--out", str(folder), "--quiet",
               "--threads", str(args.threads)]
        if args.fdimc_seed is not None:
            cmd += ["--seed", str(args.fdimc_seed)]
        t0 = time.time()
        res = subprocess.run(cmd, capture_output=True, text=True)
        if res.returncode != 0:
            sys.exit(f"fdimc failed ({res.returncode}): {' '.join(cmd)}\n{res.stderr}")
        print(f"fdimc: {trials} trials in {time.time() - t0:.1f} s", file=sys.stderr)
    d = pl.read_parquet(folder / "trials.parquet")
    d = d.filter(pl.col("failure").is_null())
    if not args.fdimc_dir:
        shutil.rmtree(folder.parent)  # read whole: the run folder is not needed any more
    return d, folder


def second_records(deck_path, trials, seed):
    t0 = time.time()
    deck, sc, rows = second.run_study(deck_path, trials, seed)
    for name, kind in deck.skipped:
        print(f"note: detector {name} ({kind}) is not in the second implementation: not compared", file=sys.stderr)
    recs = second.to_records(deck, sc, rows)
    print(f"second implementation: {trials} trials in {time.time() - t0:.1f} s (seed {seed})", file=sys.stderr)
    return deck, pl.DataFrame(recs, infer_schema_length=None)


def groups(df, pool_targets):
    """{(detector, kind, target, size_bin): (detected flags, delays)} over faulty trials."""
    out = {}
    det = df["detector"].to_list()
    kind = df["kind"].to_list()
    tgt = df["target"].to_list()
    sb = df["size_bin"].to_list()
    ff = df["fault_free"].to_list()
    dtc = df["detected"].to_list()
    dl = df["delay_s"].to_list()
    for i in range(len(det)):
        if ff[i]:
            continue
        k = (det[i], kind[i], "all" if pool_targets else (tgt[i] or ""), key_bin(sb[i]))
        g = out.setdefault(k, ([], []))
        g[0].append(bool(dtc[i]))
        if dtc[i] and dl[i] is not None and not (isinstance(dl[i], float) and math.isnan(dl[i])):
            g[1].append(float(dl[i]))
    return out


def fmt_rate(k, n):
    p, lo, hi = wilson(k, n)
    return f"{p:.4f} [{lo:.4f}, {hi:.4f}] ({k}/{n})"


def fmt_q(t):
    return f"{t[0]:.4f} [{t[1]:.4f}, {t[2]:.4f}]"


def fdimc_binary():
    """$FDIMC, else target/release/fdimc where cargo builds (CARGO_TARGET_DIR or ./target), as cargo says."""
    import json
    import os
    if os.environ.get("FDIMC"):
        return os.environ["FDIMC"]
    root = Path(__file__).resolve().parents[2]
    meta = subprocess.run(["cargo", "metadata", "--format-version", "1", "--no-deps"], cwd=root,
                          capture_output=True, text=True, check=True)
    binary = Path(json.loads(meta.stdout)["target_directory"]) / "release" / "fdimc"
    if not binary.exists():
        sys.exit(f"{binary}: no such file; build it first (cargo build --release), or pass --fdimc")
    return str(binary)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("deck")
    ap.add_argument("--trials", type=int, default=3000)
    ap.add_argument("--fdimc", default=None,
                    help="fdimc's binary (default: $FDIMC, else the release build in cargo's target folder)")
    ap.add_argument("--fdimc-seed", type=int, default=None, help="fdimc's seed (default: the deck's)")
    ap.add_argument("--fdimc-dir", default=None, help="use this finished fdimc run folder instead of running fdimc")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=12345, help="the second implementation's seed")
    ap.add_argument("--out", default=None, help="the table as CSV (default /tmp/compare_<study>.csv)")
    ap.add_argument("--alpha", type=float, default=0.01)
    ap.add_argument("--pool-targets", action="store_true")
    ap.add_argument("--min-delays", type=int, default=5)
    ap.add_argument("--min-tests", type=int, default=1,
                    help="fail (exit 2) when fewer tests could be made (CI: what the deck gave when it was set)")
    a = ap.parse_args(argv)
    a.fdimc = a.fdimc or fdimc_binary()

    deck_path = Path(a.deck)
    deck, s = second_records(deck_path, a.trials, a.seed)
    f, _ = fdimc_records(a, deck_path, a.trials)
    names = [d["name"] for d in deck.detectors]
    f = f.filter(pl.col("detector").is_in(names))
    f = f.with_columns(pl.col("target").fill_null(""))
    s = s.with_columns(pl.col("target").fill_null("").cast(pl.Utf8))

    rows = []
    # Pfa
    for det in names:
        fa = f.filter((pl.col("detector") == det) & pl.col("fault_free"))["false_alarm"].to_numpy()
        sa = s.filter((pl.col("detector") == det) & pl.col("fault_free"))["false_alarm"].to_numpy()
        k1, n1, k2, n2 = int(fa.sum()), len(fa), int(sa.sum()), len(sa)
        p = fisher_exact([[k1, n1 - k1], [k2, n2 - k2]])[1] if n1 and n2 else float("nan")
        rows.append(dict(quantity=f"Pfa {det}", fdimc=fmt_rate(k1, n1), second=fmt_rate(k2, n2),
                         test="Fisher exact", p=p))
    # Pd and delays per group
    gf, gs = groups(f, a.pool_targets), groups(s, a.pool_targets)
    for key in sorted(set(gf) | set(gs), key=lambda k: (k[0], k[1], k[2], -1e300 if k[3] is None else k[3])):
        det, kind, tgt, sb = key
        label = f"{det} {kind} {tgt} size {'-' if sb is None else sb:g}" if sb is not None else f"{det} {kind} {tgt}"
        (d1, l1), (d2, l2) = gf.get(key, ([], [])), gs.get(key, ([], []))
        k1, n1, k2, n2 = sum(d1), len(d1), sum(d2), len(d2)
        if n1 == 0 or n2 == 0:
            rows.append(dict(quantity=f"Pd {label}", fdimc=fmt_rate(k1, n1), second=fmt_rate(k2, n2),
                             test="group missing on one side", p=float("nan")))
            continue
        p = fisher_exact([[k1, n1 - k1], [k2, n2 - k2]])[1]
        rows.append(dict(quantity=f"Pd {label}", fdimc=fmt_rate(k1, n1), second=fmt_rate(k2, n2),
                         test="Fisher exact", p=p))
        if len(l1) >= a.min_delays and len(l2) >= a.min_delays:
            p = mannwhitneyu(l1, l2, alternative="two-sided").pvalue
            rows.append(dict(quantity=f"delay p50 {label} (s)", fdimc=fmt_q(quantile_ci(l1, 0.5)),
                             second=fmt_q(quantile_ci(l2, 0.5)), test=f"Mann-Whitney ({len(l1)} v {len(l2)})", p=p))
            rows.append(dict(quantity=f"delay p90 {label} (s)", fdimc=fmt_q(quantile_ci(l1, 0.9)),
                             second=fmt_q(quantile_ci(l2, 0.9)), test="(the same test)", p=float("nan")))
    # fault-free largest statistic per output
    for det in names:
        for o in deck.outputs:
            col = f"pre_max_{o}"
            v1 = f.filter((pl.col("detector") == det) & pl.col("fault_free"))[col].to_numpy()
            v2 = s.filter((pl.col("detector") == det) & pl.col("fault_free"))[col].to_numpy()
            if len(v1) < 5 or len(v2) < 5:
                continue
            p = ks_2samp(v1, v2).pvalue
            rows.append(dict(quantity=f"fault-free max stat {det} {o}", fdimc=fmt_q(quantile_ci(v1, 0.5)),
                             second=fmt_q(quantile_ci(v2, 0.5)), test=f"KS ({len(v1)} v {len(v2)}), shown: median", p=p))

    tested = [i for i, r in enumerate(rows) if not math.isnan(r["p"])]
    if len(tested) < max(a.min_tests, 1):
        # A comparison that tested less than it should must not pass (issue 82: a script CI calls fails
        # when it ran nothing).
        print(f"error: {len(tested)} tests made on {deck_path} at {a.trials} trials, fewer than {a.min_tests}",
              file=sys.stderr)
        return 2
    adj = holm([rows[i]["p"] for i in tested])
    for i, r in enumerate(rows):
        r["p_holm"] = float("nan")
        r["verdict"] = "not tested" if r["test"] != "(the same test)" else "see p50 row"
    for i, pa in zip(tested, adj):
        rows[i]["p_holm"] = pa
        rows[i]["verdict"] = "REJECT" if pa <= a.alpha else "agree"
    reject = sum(r["verdict"] == "REJECT" for r in rows)

    table = pl.DataFrame(rows)
    out = a.out or f"/tmp/compare_{deck.name}.csv"
    table.write_csv(out)
    w = [max(len(str(r[c])) for r in rows + [dict(quantity="quantity", fdimc="fdimc", second="second implementation",
                                                  test="test", p="p", p_holm="Holm p", verdict="verdict")]) for c in
         ("quantity", "fdimc", "second", "test")]
    print(f"{'quantity':<{w[0]}}  {'fdimc [95 %]':<{w[1]}}  {'second implementation [95 %]':<{w[2]}}  "
          f"{'test':<{w[3]}}  {'p':>9}  {'Holm p':>9}  verdict")
    for r in rows:
        ps = "" if math.isnan(r["p"]) else f"{r['p']:.3g}"
        ph = "" if math.isnan(r["p_holm"]) else f"{r['p_holm']:.3g}"
        print(f"{r['quantity']:<{w[0]}}  {r['fdimc']:<{w[1]}}  {r['second']:<{w[2]}}  {r['test']:<{w[3]}}  "
              f"{ps:>9}  {ph:>9}  {r['verdict']}")
    print(f"\n{len(tested)} tests, Holm at family-wise {a.alpha}: {reject} rejected. Table: {out}")
    return 1 if reject else 0


if __name__ == "__main__":
    sys.exit(main())
