#!/usr/bin/env python3
"""Hold fdimc's detection-filter results against the second implementation (issue #86 item 1).

    compare_second_implementation.py DECK [--trials 3000] [--fdimc BIN] [--seed 12345]
                                     [--out table.csv] [--fdimc-dir DIR] [--pool-targets] [--alpha 0.01]
                                     [--calibrated]

Runs `fdimc run DECK --trials N --out TMP --quiet` (its own seed, the deck's unless --fdimc-seed) and
second_implementation.py (beside this file) at the same trial count on its own seed (numpy
default_rng(--seed)), then compares, per detector both implement (detection_filter, cusum and
kalman_chi2; fmu detectors are left out):

  * Pfa: the fault-free trials' false-alarm share; Fisher's exact test, two-sided;
  * Pd per fault kind x target x size bin (the deck's values or bin centres; --pool-targets pools the
    targets, which mixes distributions of very different delays: see the report); Fisher's exact test;
  * detection delay per kind x target x size bin: median and p90 with distribution-free 95 % intervals
    (binomial order statistics), tested by the two-sided Mann-Whitney U test (both sides >= 5 delays);
  * the fault-free trials' largest detection statistic per output (`pre_max_<output>`, the whole
    trial): the two-sample Kolmogorov-Smirnov test (a sharp test of the residual's law). A kalman_chi2
    detector records its one window statistic under every output (K5 in second_implementation.py), so
    it has one such test, on its first output's column, and a check that fdimc's columns are equal;
  * kalman_chi2 only: the fault-free trials' first false-alarm time (`false_alarm_s`), Mann-Whitney
    (both sides >= 5 alarms): the test of K4's reading of the window's start, where the statistic is a
    sum of fewer samples (its deck alarms within the first window under design-model error);

With --calibrated, also at the thresholds each side calibrates on its own fault-free trials at the
deck's target_pfa (the second implementation's calibration, D13-D15 and C9-C10 in its header, is written
from docs/statistics.md, docs/outputs.md and docs/deck.md; fdimc's is read from its thresholds.csv).
fdimc then runs with --profile-resolution 0 (full first-passage profiles: exact alarm times at any
threshold, docs/outputs.md "What the first-passage profiles keep"); the default tests are the same.
Added, per detector:

  * checks (no p-value; a failed check exits 1 like a rejection):
    - the docs' rule (D14, C9) applied to fdimc's own fault-free pre_max_<output> reproduces its
      thresholds.csv (per_statistic_threshold, detector_threshold; largest relative difference), and
      fdimc's detector_false_alarms is floor(P n) (or Wilks' count);
    - replaying fdimc's profiles fp_t_s_<s>, fp_v_<s> at the deck's thresholds reproduces its recorded
      detected and delay_s (R1 below), and at its calibrated thresholds the `calibrated` rows of its
      summary.csv (detected and flown units per kind x target x size bin, summed over the other bins);
    - the second implementation's own calibration lets through exactly its m alarms;
  * per output (one for a kalman_chi2 detector, its outputs' columns being one statistic), the
    per-statistic threshold: fdimc's against the second's, the second's with the
    distribution-free 95 % interval of the (1 - P) quantile from its order statistics (binomial ranks).
    Test (exact, distribution-free; T1): fdimc's threshold is the (m1+1)-th largest of its n1 values;
    if both sides' values have one continuous law, the number X of the second's n2 values above it has
    P(X = x) = C(m1 + x, x) C(n1 - m1 - 1 + n2 - x, n2 - x) / C(n1 + n2, n2) (every interleaving of the
    two samples equally likely); two-sided p = the sum of P(X = x') <= P(X = x), as Fisher's;
  * per output, the whole-detector threshold: fdimc's against the second's with a bootstrap 95 %
    interval (percentiles of 1,000 resamples of the second's fault-free trials, each calibrated again;
    numpy default_rng(1)); tested through the realised Pfa;
  * realised Pfa at the calibrated thresholds: each side's in-sample share (m / n by construction: a
    check), and across (T2): fdimc's thresholds on the second's fault-free trials and the second's on
    fdimc's, each tested against the permutation law of that count: the two sides' fault-free trials
    pooled and split at random 2,000 times (numpy default_rng(2)) into a calibration part of the
    calibrating side's size and the rest, the docs' rule calibrated on the first and its alarms counted
    on the second. Under the null (both sides draw one law) the trials are exchangeable and this is the
    count's exact law whatever the statistics' dependence (T1's placement law holds for one statistic
    only and is too narrow for the whole detector, whose common factor comes from the same trials);
    the p-value is two-sided (twice the smaller tail), from the beta-binomial law with the
    permutations' mean and variance (a binomial whose rate varies with the calibration), since 2,000
    permutations cannot resolve Holm's smallest levels; the permutations as far from their mean as
    the count are printed beside;
  * Pd per kind x target x size bin at fdimc's calibrated thresholds: fdimc's (R1: the first point of
    its profiles above a threshold, from the onset, min over the outputs; delay = that time - onset_s)
    against the second implementation's same trials flown at fdimc's thresholds (Fisher's exact test),
    delays there (Mann-Whitney, p50 and p90 rows). Both sides at the same thresholds, so the tests hold
    with thresholds fixed (T3). The second's Pd and median delay at its own calibrated thresholds are
    shown beside (not tested: that difference holds each side's threshold noise too, which Fisher's
    test does not model; the calibrations themselves are tested by T1 and T2).

Holm's step-down correction over every test of the run; a test whose Holm-adjusted p-value is at most
--alpha (0.01) rejects. Prints one table (quantity, fdimc value with its 95 % interval (Wilson for a
rate), the second implementation's, the test, p, Holm-adjusted p, verdict), writes it as CSV (--out),
and exits 1 if any test rejects, 0 otherwise.

Environment (the venv $HOME/.cache/fdimc-ref, Python 3.11):
    $HOME/.cache/fdimc-ref/bin/pip install numpy==2.4.6 scipy==1.17.1 polars==1.31.0
    $HOME/.cache/fdimc-ref/bin/python scripts/reference/compare_second_implementation.py \
        studies/ci_seed000.toml --trials 3000 --out /tmp/compare_ci_seed000.csv
    $HOME/.cache/fdimc-ref/bin/python scripts/reference/compare_second_implementation.py \
        studies/seed000_robustness.toml --trials 3000 --calibrated --fdimc /tmp/fdimc-head
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
from scipy.special import gammaln
from scipy.stats import betabinom, binom, binomtest, fisher_exact, ks_2samp, mannwhitneyu

sys.dont_write_bytecode = True  # no __pycache__ beside the scripts
sys.path.insert(0, str(Path(__file__).resolve().parent))
import second_implementation as second  # noqa: E402


def wilson(k, n):
    """The share k / n with its 95 % Wilson interval (SciPy's)."""
    if n == 0:
        return float("nan"), float("nan"), float("nan")
    ci = binomtest(k, n).proportion_ci(0.95, method="wilson")
    return k / n, ci.low, ci.high


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


def fdimc_records(args, deck_path, trials, calibrated=False):
    if args.fdimc_dir:
        folder = Path(args.fdimc_dir)
    else:
        folder = Path(tempfile.mkdtemp(prefix="fdimc_cmp_")) / "run"
        cmd = [args.fdimc, "run", str(deck_path), "--trials", str(trials), "--out", str(folder), "--quiet",
               "--threads", str(args.threads)]
        if args.fdimc_seed is not None:
            cmd += ["--seed", str(args.fdimc_seed)]
        if calibrated:
            cmd += ["--profile-resolution", "0"]
        t0 = time.time()
        res = subprocess.run(cmd, capture_output=True, text=True)
        if res.returncode != 0:
            sys.exit(f"fdimc failed ({res.returncode}): {' '.join(cmd)}\n{res.stderr}")
        print(f"fdimc: {trials} trials in {time.time() - t0:.1f} s", file=sys.stderr)
    d = pl.read_parquet(folder / "trials.parquet")
    d = d.filter(pl.col("failure").is_null())
    extra = None
    if calibrated:
        import json
        extra = dict(thresholds=pl.read_csv(folder / "thresholds.csv"),
                     summary=pl.read_csv(folder / "summary.csv", infer_schema_length=None),
                     manifest=json.loads((folder / "manifest.json").read_text()))
    if not args.fdimc_dir:
        shutil.rmtree(folder.parent)  # read whole: the run folder is not needed any more
    if calibrated:
        return d, folder, extra
    return d, folder


def second_records(deck_path, trials, seed):
    t0 = time.time()
    deck, sc, rows = second.run_study(deck_path, trials, seed)
    for name, kind in deck.skipped:
        print(f"note: detector {name} ({kind}) is not in the second implementation: not compared", file=sys.stderr)
    recs = second.to_records(deck, sc, rows)
    print(f"second implementation: {trials} trials in {time.time() - t0:.1f} s (seed {seed})", file=sys.stderr)
    return deck, pl.DataFrame(recs, infer_schema_length=None)


def groups(df, pool_targets, detected="detected", delay="delay_s"):
    """{(detector, kind, target, size_bin): (detected flags, delays)} over faulty trials."""
    out = {}
    det = df["detector"].to_list()
    kind = df["kind"].to_list()
    tgt = df["target"].to_list()
    sb = df["size_bin"].to_list()
    ff = df["fault_free"].to_list()
    dtc = df[detected].to_list()
    dl = df[delay].to_list()
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


# ---------------------------------------------------------------- calibrated thresholds (--calibrated)
def tested_outputs(deck, det):
    """(index, output) pairs whose statistic is tested: every output, but a kalman_chi2 detector's one
    statistic (K5: the same under every output) once, under its first output."""
    kind = next(d["kind"] for d in deck.detectors if d["name"] == det)
    pairs = list(enumerate(deck.outputs))
    return pairs[:1] if kind == "kalman_chi2" else pairs


def placement_pmf(m, n1, n2):
    """T1: law of X, the number of n2 values above the (m+1)-th largest of n1 others, all exchangeable."""
    x = np.arange(n2 + 1)

    def lc(a, b):
        return gammaln(a + 1) - gammaln(b + 1) - gammaln(a - b + 1)
    lp = lc(m + x, x) + lc(n1 - m - 1 + n2 - x, n2 - x) - lc(n1 + n2, n2)
    return np.exp(lp)


def placement_p(m, n1, n2, x):
    pmf = placement_pmf(m, n1, n2)
    return float(min(1.0, pmf[pmf <= pmf[x] * (1 + 1e-7)].sum()))


def permutation_p(cal, other, P, C, x, permutations=2000):
    """T2: the law's words (its mean and standard deviation) and the two-sided p of x, the alarms of
    thresholds calibrated on `cal` counted on `other`, under the permutation law of that count (see the
    module's doc)."""
    pooled, n = np.vstack([cal, other]), len(cal)
    rng = np.random.default_rng(2)
    counts = np.empty(permutations)
    for b in range(permutations):
        idx = rng.permutation(len(pooled))
        thr = second.calibrate(pooled[idx[:n]], P, C)["detector"]
        counts[b] = (pooled[idx[n:]] > thr).any(axis=1).sum()
    mean, var, m = counts.mean(), counts.var(ddof=1), len(other)
    far = int((np.abs(counts - mean) >= abs(x - mean)).sum())
    law = f"permutation law (T2): {mean:.1f} +- {np.sqrt(var):.1f}; {far} of {permutations} as far"
    # The beta-binomial of that mean and variance (a binomial whose rate varies with the calibration).
    q = mean / m
    rho = (var / (m * q * (1.0 - q)) - 1.0) / (m - 1.0) if 0.0 < q < 1.0 else 0.0
    if not 0.0 < q < 1.0:
        return law, 1.0 if x == mean else 0.0
    if rho <= 1e-12:
        lower, upper = binom.cdf(x, m, q), binom.sf(x - 1, m, q)
    else:
        a = q * (1.0 / rho - 1.0)
        b = (1.0 - q) * (1.0 / rho - 1.0)
        lower, upper = betabinom.cdf(x, m, a, b), betabinom.sf(x - 1, m, a, b)
    return law, float(min(1.0, 2.0 * min(lower, upper)))


def order_ci(v, q):
    """Distribution-free 95 % interval of the q quantile from order statistics (as quantile_ci)."""
    return quantile_ci(v, q)[1:]


def replay(df, outputs, thr, window=None):
    """R1: detection and delay from fdimc's first-passage profiles at thresholds thr (one per output):
    the first profile point strictly above its threshold, the earliest over the outputs."""
    onset = df["onset_s"].to_list()
    first = np.full(len(df), np.inf)
    for j, o in enumerate(outputs):
        ts, vs = df[f"fp_t_s_{o}"].to_list(), df[f"fp_v_{o}"].to_list()
        for i in range(len(df)):
            if not vs[i]:
                continue
            v = np.asarray(vs[i])
            k = np.flatnonzero(v > thr[j])
            if len(k):
                first[i] = min(first[i], ts[i][k[0]])
    on = np.array([np.nan if x is None else x for x in onset], dtype=float)
    delay = first - on
    detected = np.isfinite(first)
    if window is not None:
        detected &= delay <= window
    return detected, np.where(detected, delay, np.nan)


def calibrated_rows(a, deck, f, s, fx, cal2, rows, checks):
    """The --calibrated rows (see the module's doc); appends to rows (tests) and checks."""
    outputs = deck.outputs
    names = [d["name"] for d in deck.detectors]
    P, C = deck.target_pfa, deck.confidence
    th = fx["thresholds"]
    res = fx["manifest"].get("profile_resolution")
    if res not in (0, 0.0):
        print(f"warning: fdimc's profiles at resolution {res}: its delays at the calibrated thresholds are "
              f"to within the grid, detections exact", file=sys.stderr)
    f_cal_cols = []
    for det in names:
        t = th.filter((pl.col("detector") == det) & (pl.col("statistic") != "all"))
        t = {r["statistic"]: r for r in t.iter_rows(named=True)}
        h1 = np.array([t[o]["per_statistic_threshold"] for o in outputs], dtype=float)
        T1 = np.array([t[o]["detector_threshold"] for o in outputs], dtype=float)
        tall = th.filter((pl.col("detector") == det) & (pl.col("statistic") == "all")).row(0, named=True)
        fff = f.filter((pl.col("detector") == det) & pl.col("fault_free"))
        sff = s.filter((pl.col("detector") == det) & pl.col("fault_free"))
        X1 = np.column_stack([fff[f"pre_max_{o}"].to_numpy() for o in outputs])
        X2 = np.column_stack([sff[f"pre_max_{o}"].to_numpy() for o in outputs])
        n1, n2 = len(X1), len(X2)
        # check: the docs' rule on fdimc's own statistics gives fdimc's thresholds
        mine = second.calibrate(X1, P, C)
        rel = max(float(np.max(np.abs(mine["per_statistic"] - h1) / np.abs(h1))),
                  float(np.max(np.abs(mine["detector"] - T1) / np.abs(T1))))
        m1 = mine["m"]
        ok = rel <= 1e-12 and int(tall["detector_false_alarms"]) == m1 and int(tall["trials"]) == n1
        checks.append(dict(quantity=f"calibration rule {det}: the docs' rule on fdimc's fault-free pre_max",
                           fdimc=f"thresholds.csv: {int(tall['detector_false_alarms'])} of {int(tall['trials'])} alarm",
                           second=f"m = {m1} of {n1}; largest relative difference {rel:.1e}",
                           test="check", p=float("nan"), check="check ok" if ok else "CHECK FAILS"))
        c2 = cal2[det]
        m2 = c2["m"]
        assert c2["n"] == n2
        ok2 = c2["detector_alarms"] == m2 and bool(np.all(c2["statistic_alarms"] == m2))
        checks.append(dict(quantity=f"calibration {det}: the second's own alarms at its thresholds",
                           fdimc="", second=f"{c2['detector_alarms']} of {n2} (m = {m2}); per statistic "
                           + ",".join(str(int(v)) for v in c2["statistic_alarms"]),
                           test="check", p=float("nan"), check="check ok" if ok2 else "CHECK FAILS"))
        # bootstrap of the second's detector thresholds
        rng = np.random.default_rng(1)
        boot = np.array([second.calibrate(X2[rng.integers(0, n2, n2)], P, C)["detector"] for _ in range(1000)])
        blo, bhi = np.percentile(boot, [2.5, 97.5], axis=0)
        for j, o in tested_outputs(deck, det):
            lo, hi = order_ci(X2[:, j], 1.0 - P)
            x = int((X2[:, j] > h1[j]).sum())
            p = placement_p(m1, n1, n2, x)
            rows.append(dict(quantity=f"cal threshold per statistic {det} {o}",
                             fdimc=f"{h1[j]:.6g} ({m1} of {n1} above)",
                             second=f"{c2['per_statistic'][j]:.6g} [{lo:.6g}, {hi:.6g}] ({x} of {n2} above fdimc's)",
                             test="placement (exact, T1)", p=p))
        for j, o in tested_outputs(deck, det):
            rows.append(dict(quantity=f"cal threshold detector {det} {o}", fdimc=f"{T1[j]:.6g}",
                             second=f"{c2['detector'][j]:.6g} [{blo[j]:.6g}, {bhi[j]:.6g}] (bootstrap)",
                             test="(the Pfa rows)", p=float("nan"), check="see Pfa rows"))
        # realised Pfa: in-sample (checks) and across (tests)
        k1_in = int((X1 > T1).any(axis=1).sum())
        k2_in = int((X2 > c2["detector"]).any(axis=1).sum())
        checks.append(dict(quantity=f"cal Pfa in-sample {det}", fdimc=fmt_rate(k1_in, n1), second=fmt_rate(k2_in, n2),
                           test="check: m / n each", p=float("nan"),
                           check="check ok" if (k1_in == m1 and k2_in == m2) else "CHECK FAILS"))
        x12 = int((X2 > T1).any(axis=1).sum())      # fdimc's thresholds on the second's trials
        x21 = int((X1 > c2["detector"]).any(axis=1).sum())
        law, p = permutation_p(X1, X2, P, C, x12)
        rows.append(dict(quantity=f"cal Pfa of fdimc's thresholds {det}", fdimc=fmt_rate(k1_in, n1) + " in-sample",
                         second=fmt_rate(x12, n2) + " on the second's trials", test=law, p=p))
        law, p = permutation_p(X2, X1, P, C, x21)
        rows.append(dict(quantity=f"cal Pfa of the second's thresholds {det}",
                         fdimc=fmt_rate(x21, n1) + " on fdimc's trials", second=fmt_rate(k2_in, n2) + " in-sample",
                         test=law, p=p))
        # the second's at_fdimc set must be fdimc's thresholds: its fault-free false alarms are x12
        x12b = int(sff["at_fdimc_false_alarm"].sum())
        if x12b != x12:
            checks.append(dict(quantity=f"second at fdimc's thresholds {det}: flown against read", fdimc="",
                               second=f"{x12b} against {x12}", test="check", p=float("nan"), check="CHECK FAILS"))
        # fdimc's replays
        fd = f.filter((pl.col("detector") == det) & ~pl.col("fault_free"))
        deck_thr = np.array(fx["manifest"]["deck_thresholds"][fx["manifest"]["detectors"].index(det)], dtype=float)
        dd, dl = replay(fd, outputs, deck_thr, deck.window)
        rec_det = fd["detected"].to_numpy().astype(bool)
        rec_dl = fd["delay_s"].fill_null(float("nan")).to_numpy()
        bad_det = int((dd != rec_det).sum())
        both = dd & rec_det
        worst = float(np.max(np.abs(dl[both] - rec_dl[both]))) if both.any() else 0.0
        checks.append(dict(quantity=f"replay {det} at the deck's thresholds (R1) against recorded",
                           fdimc=f"{int(rec_det.sum())} of {len(fd)} detected",
                           second=f"replay: {int(dd.sum())}; {bad_det} differ; largest delay difference {worst:.1e} s",
                           test="check", p=float("nan"),
                           check="check ok" if (bad_det == 0 and worst <= 1e-9) else "CHECK FAILS"))
        cd, cl = replay(fd, outputs, T1, deck.window)
        f_cal_cols.append(fd.select("trial", "detector").with_columns(
            pl.Series("cal_detected", cd), pl.Series("cal_delay_s", cl)))
    fc = pl.concat(f_cal_cols)
    f = f.join(fc, on=["trial", "detector"], how="left")
    # check against summary.csv's calibrated rows
    sm = fx["summary"].filter((pl.col("thresholds") == "calibrated") & pl.col("detector").is_in(names)
                              & (pl.col("kind") != "none"))
    sm = sm.with_columns(pl.col("target").fill_null(""), (pl.col("trials") - pl.col("failed")).alias("flown"))
    gsum = {}
    for r in sm.iter_rows(named=True):
        k = (r["detector"], r["kind"], r["target"], key_bin(r["size_bin"]))
        a0 = gsum.setdefault(k, [0, 0])
        a0[0] += int(r["detected"])
        a0[1] += int(r["flown"])
    gf = groups(f, False, "cal_detected", "cal_delay_s")
    diff = [k for k in set(gf) | set(gsum)
            if (sum(gf.get(k, ([], []))[0]), len(gf.get(k, ([], []))[0])) != tuple(gsum.get(k, (0, 0)))]
    checks.append(dict(quantity="replay at fdimc's calibrated thresholds against its summary.csv calibrated rows",
                       fdimc=f"{len(gsum)} groups, {sum(v[0] for v in gsum.values())} detected",
                       second=f"replay: {len(gf)} groups, {sum(sum(v[0]) for v in gf.values())} detected; "
                              f"{len(diff)} groups differ", test="check", p=float("nan"),
                       check="check ok" if not diff else "CHECK FAILS"))
    # Pd and delays at fdimc's calibrated thresholds (T3); the second's own calibration beside
    gf = groups(f, a.pool_targets, "cal_detected", "cal_delay_s")
    gs = groups(s, a.pool_targets, "at_fdimc_detected", "at_fdimc_delay_s")
    go = groups(s, a.pool_targets, "cal_detected", "cal_delay_s")
    for key in sorted(set(gf) | set(gs), key=lambda k: (k[0], k[1], k[2], -1e300 if k[3] is None else k[3])):
        det, kind, tgt, sb = key
        label = f"{det} {kind} {tgt} size {sb:g}" if sb is not None else f"{det} {kind} {tgt}"
        (d1, l1), (d2, l2), (d3, l3) = gf.get(key, ([], [])), gs.get(key, ([], [])), go.get(key, ([], []))
        k1, n1, k2, n2 = sum(d1), len(d1), sum(d2), len(d2)
        own = f"; own thresholds {fmt_rate(sum(d3), len(d3))}"
        if n1 == 0 or n2 == 0:
            rows.append(dict(quantity=f"cal Pd {label}", fdimc=fmt_rate(k1, n1), second=fmt_rate(k2, n2) + own,
                             test="group missing on one side", p=float("nan")))
            continue
        rows.append(dict(quantity=f"cal Pd {label}", fdimc=fmt_rate(k1, n1), second=fmt_rate(k2, n2) + own,
                         test="Fisher exact (T3)", p=fisher_exact([[k1, n1 - k1], [k2, n2 - k2]])[1]))
        if len(l1) >= a.min_delays and len(l2) >= a.min_delays:
            p = mannwhitneyu(l1, l2, alternative="two-sided").pvalue
            own_q = f"; own thresholds {quantile_ci(l3, 0.5)[0]:.4f}" if len(l3) else ""
            rows.append(dict(quantity=f"cal delay p50 {label} (s)", fdimc=fmt_q(quantile_ci(l1, 0.5)),
                             second=fmt_q(quantile_ci(l2, 0.5)) + own_q,
                             test=f"Mann-Whitney ({len(l1)} v {len(l2)}, T3)", p=p))
            rows.append(dict(quantity=f"cal delay p90 {label} (s)", fdimc=fmt_q(quantile_ci(l1, 0.9)),
                             second=fmt_q(quantile_ci(l2, 0.9)), test="(the same test)", p=float("nan")))


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
    ap.add_argument("--calibrated", action="store_true",
                    help="also compare at the thresholds each side calibrates on its own fault-free trials")
    ap.add_argument("--min-tests", type=int, default=1,
                    help="fail (exit 2) when fewer tests could be made (CI: what the deck gave when it was set)")
    a = ap.parse_args(argv)
    a.fdimc = a.fdimc or fdimc_binary()

    deck_path = Path(a.deck)
    fx = cal2 = None
    if a.calibrated:
        f, _, fx = fdimc_records(a, deck_path, a.trials, calibrated=True)
        th = fx["thresholds"]
        deck0 = second.Deck(deck_path)
        other = {}
        for d in deck0.detectors:
            t = {r["statistic"]: r["detector_threshold"] for r in th.filter(pl.col("detector") == d["name"]).iter_rows(named=True)}
            other[d["name"]] = {"fdimc": np.array([t[o] for o in deck0.outputs], dtype=float)}
        t0 = time.time()
        deck, sc, srows, cal2 = second.run_calibrated(deck_path, a.trials, a.seed, other)
        for name, kind in deck.skipped:
            print(f"note: detector {name} ({kind}) is not in the second implementation: not compared", file=sys.stderr)
        s = pl.DataFrame(second.to_records(deck, sc, srows), infer_schema_length=None)
        print(f"second implementation: {a.trials} trials flown twice (calibration) in {time.time() - t0:.1f} s "
              f"(seed {a.seed})", file=sys.stderr)
    else:
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
    # fault-free largest statistic per output (a kalman_chi2 detector's one statistic once, K5)
    checks = []
    kinds = {d["name"]: d["kind"] for d in deck.detectors}
    for det in names:
        fff = f.filter((pl.col("detector") == det) & pl.col("fault_free"))
        sff = s.filter((pl.col("detector") == det) & pl.col("fault_free"))
        if kinds[det] == "kalman_chi2":
            X1 = np.column_stack([fff[f"pre_max_{o}"].to_numpy() for o in deck.outputs])
            same = bool(np.all(X1 == X1[:, :1]))
            checks.append(dict(quantity=f"K5 {det}: fdimc's pre_max_<output> the same in every column",
                               fdimc=f"{len(X1)} fault-free trials x {len(deck.outputs)} columns",
                               second="equal" if same else "columns differ", test="check", p=float("nan"),
                               check="check ok" if same else "CHECK FAILS"))
        for _, o in tested_outputs(deck, det):
            col = f"pre_max_{o}"
            v1, v2 = fff[col].to_numpy(), sff[col].to_numpy()
            if len(v1) < 5 or len(v2) < 5:
                continue
            p = ks_2samp(v1, v2).pvalue
            label = f"{det} {o}" if kinds[det] != "kalman_chi2" else f"{det} (window sum, every output)"
            rows.append(dict(quantity=f"fault-free max stat {label}", fdimc=fmt_q(quantile_ci(v1, 0.5)),
                             second=fmt_q(quantile_ci(v2, 0.5)), test=f"KS ({len(v1)} v {len(v2)}), shown: median", p=p))
        if kinds[det] == "kalman_chi2":
            # K4's start: the first false alarm's time in the fault-free trials
            t1 = fff["false_alarm_s"].drop_nulls().to_numpy().astype(float)
            t2 = sff["false_alarm_s"].drop_nulls().to_numpy().astype(float)
            t1, t2 = t1[np.isfinite(t1)], t2[np.isfinite(t2)]
            if len(t1) >= a.min_delays and len(t2) >= a.min_delays:
                p = mannwhitneyu(t1, t2, alternative="two-sided").pvalue
                rows.append(dict(quantity=f"fault-free first false alarm {det} (s)",
                                 fdimc=fmt_q(quantile_ci(t1, 0.5)) + f" ({len(t1)} of {len(fff)})",
                                 second=fmt_q(quantile_ci(t2, 0.5)) + f" ({len(t2)} of {len(sff)})",
                                 test=f"Mann-Whitney ({len(t1)} v {len(t2)}), shown: median", p=p))

    if a.calibrated:
        calibrated_rows(a, deck, f, s, fx, cal2, rows, checks)
    rows.extend(checks)

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
        if "check" in r:
            r["verdict"] = r.pop("check")
    for i, pa in zip(tested, adj):
        rows[i]["p_holm"] = pa
        rows[i]["verdict"] = "REJECT" if pa <= a.alpha else "agree"
    reject = sum(r["verdict"] == "REJECT" for r in rows)
    failed_checks = sum(r["verdict"] == "CHECK FAILS" for r in rows)

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
    ncheck = sum(r["test"].startswith("check") for r in rows)
    extra = f"; {ncheck} checks, {failed_checks} failed" if (a.calibrated or ncheck) else ""
    print(f"\n{len(tested)} tests, Holm at family-wise {a.alpha}: {reject} rejected{extra}. Table: {out}")
    return 1 if (reject or failed_checks) else 0


if __name__ == "__main__":
    sys.exit(main())
