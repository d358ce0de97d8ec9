#!/usr/bin/env python3
"""A second, independent implementation of fdimc's linear detection-filter study kind (method 000),
issue #86 item 1, first step.

Written from the deck (TOML) and the user documentation only: docs/deck.md, docs/architecture.md
("How a trial is simulated"), docs/outputs.md (the outcome schema), docs/statistics.md, and
/work/shared/methods.md section 000 (the design K = (A F - F Lambda)(C F)^+). No fdimc source was read
and nothing fdimc computes (gains, thresholds, records) is used here: only the deck.

    second_implementation.py DECK --trials N --seed S --out FILE.csv [--analytic] [--calibrate]

writes one row per trial x detector: trial, detector, fault_free, kind, target, size, size_unit,
size_bin, onset_s, noise_scale, noise_bin, false_alarm, false_alarm_s, detected, delay_s,
pre_max_<output> (largest detection statistic before the onset; the whole trial when fault-free; the
Kalman test's one statistic under every output, K5).
`--analytic` also prints, per detector, the fault-free residual's standard deviation at the trial's end
from the covariance recursion (the discrete Lyapunov equation from e(0) = 0) against this simulation's,
and the per-trial false-alarm probability of the |r| test from that exact Gaussian law (Sidak's product
and the union bound). `--calibrate` calibrates each detector's thresholds on this implementation's own
fault-free trials at the deck's `target_pfa` (D13-D15), prints them, flies the same trials again at
them (the same seed gives the same trials: no draw depends on a threshold) and adds the columns
cal_false_alarm, cal_detected, cal_delay_s (`calibrate`, `simulate(extra_sets=...)`).

Environment: Python 3.11 (tomllib) with numpy 2.4.6 and scipy 1.17.1 (polars 1.31.0 for the comparison
script), in the venv $HOME/.cache/fdimc-ref:
    $HOME/.cache/fdimc-ref/bin/pip install numpy==2.4.6 scipy==1.17.1 polars==1.31.0
    $HOME/.cache/fdimc-ref/bin/python scripts/reference/second_implementation.py \
        studies/ci_seed000.toml --trials 3000 --seed 12345 --out /tmp/second.csv

Supported: [plant] a, b, c, d, initial_state; [design_model] a, b; [controller] output_feedback;
[[excitation]] square, sine, step (start_s); [noise] sensor_sigma, sensor_law "gaussian" or
"student_t(N)", process_sigma_per_step; [[detector]] kinds "detection_filter" and "cusum"
(eigenvalues_per_s, fault_directions, thresholds, drift) and "kalman_chi2" (window,
false_alarm_probability, design_process_sigma_per_step; K1-K5, its isolation not); the fmu kind is
skipped with a note; [monte_carlo] trials, fault_free_fraction, outputs, onset_s, noise_scale,
detection_window_s; [[monte_carlo.fault]] sensor kinds bias, gain, stuck, total_failure, drift,
oscillation with size / size_sigma (numbers, ranges with bins, values); [[monte_carlo.parameter_error]]
on matrix a or b of the plant or the design model, relative or absolute. Refused: [truth] (FMUs),
[[faults]] fixed scenarios, actuator faults (`inputs`), empirical noise laws, a controller FMU.

Definitions taken from the docs
-------------------------------
D1 (architecture.md) The true plant is sampled exactly by zero-order hold: expm([[A, B], [0, 0]] dt).
D2 (architecture.md) Order within a sample k (t = k dt): healthy output C x + D u plus white Gaussian
   sensor noise, then the faults, then the control u = r(t) - G y_measured, then the detector, then the
   state update x(k+1) = Ad x + Bd u (+ process noise, `process_sigma_per_step`, per state and step).
D3 (architecture.md) The filter runs in discrete time: gamma(k) = y(k) - C xhat(k) - D u(k),
   xhat(k+1) = Ad xhat(k) + Bd u(k) + Kd gamma(k), (Ad, Bd) the sampled design model, Kd assigned to
   the eigenvalues exp(lambda_i dt) on the same fault directions: Kd = (Ad F - F Lambda_d)(C F)^+
   (methods.md 000's minimum-norm solution, applied to the sampled model); F = I by default.
D4 (statistics.md) The filter starts on the truth: xhat(0) = x(0) (e(0) = 0); x(0) = initial_state.
D5 (deck.md) detection_filter alarm: output j alarms when |gamma_j| > thresholds[j] (strict).
   cusum: g_j = max(0, g_j + |gamma_j| - drift[j]), alarm when g_j > thresholds[j].
D6 (deck.md) Faults act on the healthy noisy output y_in from the onset on: bias y_in + size,
   gain size * y_in, stuck: the reading at the first sample at or after the onset, held (or `size`),
   total_failure 0, drift y_in + size (t - onset), oscillation y_in + size sin(2 pi f (t - onset)).
   size_sigma is in multiples of the faulty output's *nominal* sensor sigma (not scaled by noise_scale).
D7 (deck.md) The loop closes on the measured, possibly faulty, outputs.
D8 (outputs.md) false_alarm: an alarm before the onset (anywhere in the trial when fault-free);
   detected: an alarm at or after the onset (within detection_window_s when given); Pd counts
   detections among faulty trials whatever happened before the onset.
D9 (deck.md) square wave: +amplitude for the first half of each period, -amplitude for the second,
   0 before start_s; excitations on one input add.
D10 (deck.md) fault_free_fraction is the probability that a trial has no fault; sampled faults draw a
   kind, an output from monte_carlo.outputs, a size and an onset (default onset duration_s / 3).
D11 (deck.md) a range factor with k bins labels each trial by its bin's centre; a listed value labels
   itself. Parameter errors scale the listed entries by 1 + relative (or add absolute); "design"
   errors change the model the filter is designed on and runs, "plant" ones the truth flown.
D12 (deck.md) student_t(N) noise is scaled so that its standard deviation is sensor_sigma.

The Kalman chi-square baseline (deck.md "The detector kinds", `kalman_chi2` and its fields `window`,
`false_alarm_probability`, `design_process_sigma_per_step`):
K1 (deck.md) "A steady-state Kalman filter of the design model, designed for [noise].sensor_sigma and
   design_process_sigma_per_step": the sampled design model (Ad, Bd) of D3 with the trial's design-model
   errors (D11); R = diag(sensor_sigma^2), the deck's sigma (not times noise_scale); Q =
   diag(design_process_sigma_per_step^2), noise added per state and step as D2's process noise; P the
   a-priori covariance, the stabilising solution of P = Ad P Ad' - Ad P C' (C P C' + R)^-1 C P Ad' + Q
   (scipy.linalg.solve_discrete_are); S = C P C' + R, the innovation covariance the design expects.
K2 (architecture.md D3's discrete filter; reading) The predictor form, run as D3 runs the detection
   filter: gamma(k) = y(k) - C xhat(k) - D u(k), xhat(k+1) = Ad xhat(k) + Bd u(k) + K gamma(k),
   K = Ad P C' S^-1, xhat(0) = x(0) (D4). The filter form (update with P C' S^-1, then predict) has the
   same innovation gamma, so both readings give the same statistic.
K3 (deck.md "the normalised innovation squared") nis(k) = gamma(k)' S^-1 gamma(k) with the whole S
   (chi-square(p) per sample where the model holds), not sum_j gamma_j^2 / S_jj.
K4 (deck.md "summed over `window` samples ... exceeds the chi-square(window x p) quantile at
   `false_alarm_probability`"; reading) A sliding sum, tested at every sample: the statistic at sample k
   is nis(k - window + 1) + ... + nis(k), the samples before k = 0 counting 0 (during the first
   window - 1 samples, the sum of those so far). Its threshold h = chi2.isf(false_alarm_probability,
   window x p), p the number of outputs (88.379 for 10 x 6 at 0.01); an alarm is the statistic strictly
   above h (D5). The other readings (no statistic until a window is full; disjoint windows, each tested
   at its last sample) are the `KALMAN_WINDOW` values "full" and "block", for trying them.
K5 (deck.md, the fmu kind "recorded under every output as the Kalman test's is"; outputs.md "Every kind
   records a detection statistic") The one window statistic is recorded under every output:
   pre_max_<output> is its largest value before the onset, the same in every column, and h is every
   output's threshold; the calibration (D13, D14) then sees p equal columns and gives one threshold.

Calibrated thresholds (the `--calibrate` option; statistics.md "Thresholds: calibration, validation,
per flight hour", outputs.md "thresholds.csv", the threshold set `calibrated`, deck.md `target_pfa`,
`confidence`):
D13 (deck.md, outputs.md) Calibration uses the detector's fault-free trials (all of them, whatever
   their noise scale or parameter errors; failed ones are in no calibration), at monte_carlo.target_pfa
   (default 0.01); the statistic per output is the one whose largest value before the onset is recorded
   as pre_max_<output> (|gamma_j| for the detection filter, the CUSUM g_j, the Kalman test's window
   sum under every output, K5), over the whole fault-free trial; an alarm is the statistic strictly
   above the threshold (D5).
D14 (statistics.md) Counting rule: of n fault-free trials a calibration lets through m = floor(P n)
   alarms (with `confidence` C: the largest m with P(Binomial(n, P) <= m) <= 1 - C, Wilks), exactly m
   unless trials tie. Per statistic (`per_statistic_threshold`, "the statistic alone at the target
   Pfa") that is the (m+1)-th largest pre_max_<output>; with fewer than 1/P trials (m = 0) the largest
   value seen ("not calibrated"). The whole detector (`detector_threshold`): the per-statistic
   thresholds times a common factor c, chosen so the whole detector lets through m alarms, "raised to
   the largest value of the trials the factor lets through, so rounding cannot add one".
D15 (outputs.md) Pd at the calibrated thresholds counts detections at or after the onset among the
   faulty trials flown to the end (within detection_window_s when given), whatever happened before the
   onset, the statistics as recorded (not flown again: the same statistics at other thresholds).

Choices for the calibration where the docs leave a step open:
C9  The common factor: with h_s the per-statistic thresholds, each trial's z = max_s pre_max_s / h_s;
    c = the (m+1)-th largest z (the trial alarms at thresholds c h_s exactly when z > c). "Raised":
    each detector threshold is max(c h_s, the largest pre_max_s among the trials with z <= c), which
    changes c h_s only by rounding. A statistic with h_s = 0 (never positive) keeps threshold 0.
C10 A calibration set's alarms after the onset are found by flying the same trials again (same seed)
    with the calibrated thresholds as extra threshold sets; the statistics do not depend on a threshold
    (C3), so this equals reading them at other thresholds.

My choices where the docs are silent
------------------------------------
C1 The fault is active at samples with t_k = k dt >= onset_s (k a whole number, t_k computed as k * dt).
C2 delay_s = t_alarm - onset_s (the continuous onset, not the onset sample's time); an alarm at the
   first sample at or after the onset is a detection with delay in [0, dt).
C3 The CUSUM starts at g = 0 at k = 0 and is never reset (neither at an alarm nor at the onset): a
   statistic that does not depend on the threshold, as the docs' replay of recorded statistics at
   other thresholds implies; a CUSUM still above its threshold at the onset thus detects at once.
C4 Samples k = 0 .. round(duration_s / dt_s) - 1; an alarm is looked for on every one of them.
C5 Sampling: my own (numpy default_rng(seed)); the fault-free flag Bernoulli(fault_free_fraction);
   fault kind uniform over [[monte_carlo.fault]]; the faulty output uniform over monte_carlo.outputs;
   a range factor uniform on [lo, hi) (fdimc draws it by Sobol/LHS points: the same law per trial);
   a listed factor uniform over its values (fdimc cycles a grid over the trial index: the same shares
   in expectation). So groups have the same law, not the same trial-by-trial draws.
C6 Stuck without size takes the measured (noisy) reading at its first active sample, before any other
   fault (one fault per trial here).
C7 A detection window: detected when delay_s <= detection_window_s (inclusive).
C8 Discrete design with fewer eigenvalues than states uses the same formula with F n x r.
"""
from __future__ import annotations

import argparse
import csv
import math
import re
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
from scipy.linalg import expm, solve_discrete_are, solve_discrete_lyapunov
from scipy.stats import chi2, norm

KINDS = ("bias", "gain", "stuck", "total_failure", "drift", "oscillation")
KIND_CODE = {k: i + 1 for i, k in enumerate(KINDS)}


class Unsupported(Exception):
    pass


# ---------------------------------------------------------------- deck reading
def mat(x, rows, cols, name):
    a = np.array(x, dtype=float)
    if a.shape != (rows, cols):
        raise ValueError(f"{name}: expected {rows}x{cols}, got {a.shape}")
    return a


class Factor:
    """A deck factor: a number, {range=[lo,hi], bins=k} or {values=[...]}."""

    def __init__(self, spec, name):
        self.name = name
        if isinstance(spec, (int, float)):
            self.kind, self.value = "const", float(spec)
        elif isinstance(spec, dict) and "range" in spec:
            self.kind = "range"
            self.lo, self.hi = map(float, spec["range"])
            self.bins = int(spec.get("bins", 1))
        elif isinstance(spec, dict) and "values" in spec:
            self.kind, self.values = "values", np.array(spec["values"], dtype=float)
        else:
            raise ValueError(f"{name}: not a factor: {spec!r}")

    def draw(self, rng, n):
        if self.kind == "const":
            v = np.full(n, self.value)
            return v, v.copy()
        if self.kind == "range":
            v = rng.uniform(self.lo, self.hi, n)
            w = (self.hi - self.lo) / self.bins
            b = np.clip(np.floor((v - self.lo) / w), 0, self.bins - 1)
            return v, self.lo + (b + 0.5) * w
        v = self.values[rng.integers(0, len(self.values), n)]
        return v, v.copy()


def zoh(a, b, dt):
    n, m = b.shape
    big = np.zeros((n + m, n + m))
    big[:n, :n], big[:n, n:] = a, b
    e = expm(big * dt)
    return e[:n, :n], e[:n, n:]


def design_gain(a, b, c, eigenvalues, directions, dt):
    """Sampled design model and its detection-filter gain (D3)."""
    ad, bd = zoh(a, b, dt)
    f = directions
    lam_d = np.diag(np.exp(np.asarray(eigenvalues) * dt))
    kd = (ad @ f - f @ lam_d) @ np.linalg.pinv(c @ f)
    return ad, bd, kd


def kalman_design(a, b, c, sensor_sigma, q_sigma, dt):
    """Sampled design model and its steady-state Kalman filter (K1, K2): the predictor gain
    K = Ad P C' S^-1 with P the a-priori covariance of the discrete Riccati equation for
    Q = diag(q_sigma^2), R = diag(sensor_sigma^2), S = C P C' + R; and W = L^-1 (S = L L', Cholesky),
    so that the normalised innovation squared gamma' S^-1 gamma = |W gamma|^2 (K3)."""
    ad, bd = zoh(a, b, dt)
    q = np.diag(np.asarray(q_sigma, dtype=float) ** 2)
    r = np.diag(np.asarray(sensor_sigma, dtype=float) ** 2)
    pp = solve_discrete_are(ad.T, c.T, q, r)
    pp = 0.5 * (pp + pp.T)
    s = c @ pp @ c.T + r
    kd = ad @ pp @ c.T @ np.linalg.inv(s)
    w = np.linalg.inv(np.linalg.cholesky(s))
    return ad, bd, kd, w


class Deck:
    def __init__(self, path):
        self.path = Path(path)
        with open(path, "rb") as fh:
            d = tomllib.load(fh)
        self.raw = d
        if "plant" not in d:
            raise Unsupported("not a detection_filter deck (no [plant] table)")
        for t in ("truth", "faults"):
            if t in d:
                raise Unsupported(f"[{t}] is not supported by the second implementation")
        st = d["study"]
        self.name, self.duration, self.dt = st["name"], float(st["duration_s"]), float(st["dt_s"])
        self.steps = int(round(self.duration / self.dt))
        pl = d["plant"]
        self.states, self.inputs, self.outputs = pl["states"], pl["inputs"], pl["outputs"]
        n, m, p = len(self.states), len(self.inputs), len(self.outputs)
        self.n, self.m, self.p = n, m, p
        self.a = mat(pl["a"], n, n, "plant.a")
        self.b = mat(pl["b"], n, m, "plant.b") if m else np.zeros((n, 0))
        self.c = mat(pl["c"], p, n, "plant.c")
        self.d = mat(pl["d"], p, m, "plant.d") if "d" in pl else np.zeros((p, m))
        self.x0 = np.array(pl.get("initial_state", [0.0] * n), dtype=float)
        dm = d.get("design_model", {})
        self.design_a = mat(dm["a"], n, n, "design_model.a") if "a" in dm else self.a.copy()
        self.design_b = mat(dm["b"], n, m, "design_model.b") if "b" in dm else self.b.copy()
        ctl = d.get("controller", {})
        if "fmu" in ctl:
            raise Unsupported("a controller FMU")
        self.g = mat(ctl["output_feedback"], m, p, "controller.output_feedback") if "output_feedback" in ctl else np.zeros((m, p))
        if np.any(self.g != 0) and np.any(self.d != 0):
            raise ValueError("plant.d must be zero with a controller (algebraic loop)")
        self.excitations = []
        for e in d.get("excitation", []):
            shape = e["shape"]
            if shape not in ("square", "sine", "step"):
                raise Unsupported(f"excitation shape {shape}")
            self.excitations.append(dict(i=self.inputs.index(e["input"]), shape=shape, amp=float(e["amplitude"]),
                                         period=float(e.get("period_s", 0.0)), start=float(e.get("start_s", 0.0))))
        nz = d["noise"]
        self.sigma = np.array(nz["sensor_sigma"], dtype=float)
        law = nz.get("sensor_law", "gaussian")
        if not isinstance(law, str):
            raise Unsupported("an empirical sensor_law")
        mt = re.fullmatch(r"student_t\(([0-9.eE+-]+)\)", law)
        self.student_nu = float(mt.group(1)) if mt else None
        if law != "gaussian" and mt is None:
            raise Unsupported(f"sensor_law {law}")
        self.process_sigma = np.array(nz.get("process_sigma_per_step", [0.0] * n), dtype=float)
        self.detectors, self.skipped = [], []
        for det in d.get("detector", []):
            kind = det["kind"]
            if kind == "kalman_chi2":
                w, pf = int(det["window"]), float(det["false_alarm_probability"])
                if not (1 <= w <= 10000 and 0.0 < pf < 1.0):
                    raise ValueError(f"detector {det['name']}: window 1 to 10000, 0 < false_alarm_probability < 1")
                qd = np.array(det["design_process_sigma_per_step"], dtype=float)
                if qd.shape != (n,) or np.any(qd < 0):
                    raise ValueError(f"detector {det['name']}: design_process_sigma_per_step needs {n} numbers >= 0")
                # K1, K4: one threshold, the chi-square(window x p) quantile, under every output (K5).
                h = float(chi2.isf(pf, w * p))
                self.detectors.append(dict(name=det["name"], kind=kind, window=w, pfa_window=pf, q_sigma=qd,
                                           thr=np.full(p, h)))
                continue
            if kind not in ("detection_filter", "cusum"):
                self.skipped.append((det["name"], kind))
                continue
            eig = np.array(det["eigenvalues_per_s"], dtype=float)
            if "fault_directions" in det:
                f = np.array(det["fault_directions"], dtype=float).T  # one direction per eigenvalue -> columns
            else:
                if len(eig) != n:
                    raise ValueError(f"detector {det['name']}: identity directions need {n} eigenvalues")
                f = np.eye(n)
            self.detectors.append(dict(name=det["name"], kind=kind, eig=eig, f=f,
                                       thr=np.array(det["thresholds"], dtype=float),
                                       drift=np.array(det.get("drift", [0.0] * p), dtype=float)))
        mc = d.get("monte_carlo", {})
        self.trials = int(mc.get("trials", 1000))
        self.ff_fraction = float(mc.get("fault_free_fraction", 0.0))
        self.fault_outputs = [self.outputs.index(o) for o in mc.get("outputs", self.outputs)]
        self.onset = Factor(mc.get("onset_s", self.duration / 3.0), "onset_s")
        self.noise_scale = Factor(mc.get("noise_scale", 1.0), "noise_scale")
        self.window = float(mc["detection_window_s"]) if "detection_window_s" in mc else None
        self.target_pfa = float(mc.get("target_pfa", 0.01))
        self.confidence = float(mc["confidence"]) if "confidence" in mc else None
        self.faults = []
        for fl in mc.get("fault", []):
            if "inputs" in fl:
                raise Unsupported("actuator fault populations (`inputs`)")
            kind = fl["kind"]
            if kind not in KINDS:
                raise Unsupported(f"fault kind {kind}")
            size, unit_sigma = None, False
            if "size_sigma" in fl:
                size, unit_sigma = Factor(fl["size_sigma"], "size_sigma"), True
            elif "size" in fl:
                size = Factor(fl["size"], "size")
            self.faults.append(dict(kind=kind, size=size, sigma=unit_sigma, freq=float(fl.get("frequency_hz", 0.0))))
        if not self.faults and self.ff_fraction < 1.0:
            self.ff_fraction = 1.0  # no population: no trial has a fault
        self.perrs = []
        for pe in mc.get("parameter_error", []):
            if "matrix" not in pe:
                raise Unsupported("fmu_parameters errors")
            rows = self.states
            cols = self.states if pe["matrix"] == "a" else self.inputs
            entries = [(rows.index(r), cols.index(c)) for r, c in pe["entries"]]
            rel = "relative" in pe
            self.perrs.append(dict(name=pe["name"], model=pe["model"], matrix=pe["matrix"], entries=entries,
                                   relative=rel, factor=Factor(pe["relative"] if rel else pe["absolute"], pe["name"])))

    def excitation(self, t):
        r = np.zeros(self.m)
        for e in self.excitations:
            if t < e["start"]:
                continue
            tau = t - e["start"]
            if e["shape"] == "square":
                r[e["i"]] += e["amp"] if (tau % e["period"]) < e["period"] / 2.0 else -e["amp"]
            elif e["shape"] == "sine":
                r[e["i"]] += e["amp"] * math.sin(2.0 * math.pi * tau / e["period"])
            else:
                r[e["i"]] += e["amp"]
        return r

    def perturbed(self, model, values):
        """(A, B) of `model` with the parameter errors `values` (one per self.perrs) applied (D11)."""
        a = (self.a if model == "plant" else self.design_a).copy()
        b = (self.b if model == "plant" else self.design_b).copy()
        for pe, v in zip(self.perrs, values):
            if pe["model"] != model:
                continue
            mtx = a if pe["matrix"] == "a" else b
            for i, j in pe["entries"]:
                mtx[i, j] = mtx[i, j] * (1.0 + v) if pe["relative"] else mtx[i, j] + v
        return a, b


# ---------------------------------------------------------------- simulation
def mv(mtx, v):
    """Per-trial matrix-vector product: mtx (n, k) shared or (T, n, k) per trial; v (T, k)."""
    if mtx.ndim == 2:
        return v @ mtx.T
    return np.einsum("tij,tj->ti", mtx, v)


def per_trial(values_by_trial, build):
    """Build matrices per unique parameter-error tuple and gather them per trial (or one shared)."""
    keys = [tuple(row) for row in values_by_trial]
    uniq = {}
    for k in keys:
        if k not in uniq:
            uniq[k] = build(k)
    if len(uniq) == 1:
        return next(iter(uniq.values()))
    parts = [uniq[k] for k in keys]
    return tuple(np.stack([p[i] for p in parts]) for i in range(len(parts[0])))


def draw_scenarios(deck, trials, rng):
    t = trials
    sc = {}
    sc["fault_free"] = rng.random(t) < deck.ff_fraction
    nf = len(deck.faults)
    kidx = rng.integers(0, max(nf, 1), t)
    sc["out"] = np.array(deck.fault_outputs)[rng.integers(0, len(deck.fault_outputs), t)]
    onset, _ = deck.onset.draw(rng, t)
    sc["onset"] = onset
    sc["noise_scale"], sc["noise_bin"] = deck.noise_scale.draw(rng, t)
    code = np.zeros(t, dtype=int)
    size = np.full(t, np.nan)          # as the deck gives it (sigma multiples, factor, output units)
    size_bin = np.full(t, np.nan)
    size_units = np.full(t, np.nan)    # in output units, for the simulation
    freq = np.zeros(t)
    unit_name = np.array([""] * t, dtype=object)
    kind_name = np.array(["none"] * t, dtype=object)
    for i, fl in enumerate(deck.faults):
        sel = (kidx == i) & ~sc["fault_free"]
        cnt = int(sel.sum())
        code[sel] = KIND_CODE[fl["kind"]]
        kind_name[sel] = fl["kind"]
        freq[sel] = fl["freq"]
        if fl["size"] is not None:
            v, b = fl["size"].draw(rng, cnt)
            size[sel], size_bin[sel] = v, b
            if fl["sigma"]:
                size_units[sel] = v * deck.sigma[sc["out"][sel]]
                unit_name[sel] = "multiples of the sensor sigma"
            else:
                size_units[sel] = v
                unit_name[sel] = "gain factor" if fl["kind"] == "gain" else "output units"
        elif fl["kind"] in ("bias", "gain", "drift", "oscillation"):
            raise ValueError(f"fault kind {fl['kind']} needs size or size_sigma")
    sc.update(code=code, size=size, size_bin=size_bin, size_units=size_units, freq=freq,
              size_unit=unit_name, kind=kind_name)
    sc["onset"] = np.where(sc["fault_free"], np.nan, sc["onset"])
    pe_vals = np.zeros((t, len(deck.perrs)))
    for i, pe in enumerate(deck.perrs):
        pe_vals[:, i], _ = pe["factor"].draw(rng, t)
    sc["perr"] = pe_vals
    return sc


KALMAN_WINDOW = "sliding"   # K4's reading; "full" and "block" are the other readings tried (K4)


def kalman_statistic(dd, gam, k):
    """K3, K4: this sample's normalised innovation squared into the window; the statistic."""
    w = dd["window"]
    wg = mv(dd["w"], gam)
    dd["nis"][:, k % w] = np.einsum("ti,ti->t", wg, wg)
    if KALMAN_WINDOW == "sliding":          # the last `window` samples, fewer (zeros) before k = window - 1
        return dd["nis"].sum(axis=1)
    if KALMAN_WINDOW == "full":             # none (0) until a whole window is in
        return dd["nis"].sum(axis=1) if k >= w - 1 else np.zeros(len(gam))
    if KALMAN_WINDOW == "block":            # disjoint windows, each tested at its last sample
        return dd["nis"].sum(axis=1) if k % w == w - 1 else np.zeros(len(gam))
    raise ValueError(KALMAN_WINDOW)


def simulate(deck: Deck, trials: int, seed: int, keep_residual_var=False, extra_sets=None):
    """extra_sets: {detector name: {label: thresholds (p,)}}: alarms also looked for at those sets (C10)."""
    extra_sets = extra_sets or {}
    rng = np.random.default_rng(seed)
    sc = draw_scenarios(deck, trials, rng)
    T, n, p, dt = trials, deck.n, deck.p, deck.dt
    has_plant_err = any(pe["model"] == "plant" for pe in deck.perrs)
    has_design_err = any(pe["model"] == "design" for pe in deck.perrs)
    plant_keys = sc["perr"] if has_plant_err else np.zeros((T, 0))
    ad, bd = per_trial(plant_keys, lambda k: zoh(*deck.perturbed("plant", k if k else [0.0] * len(deck.perrs)), dt))
    design_keys = sc["perr"] if has_design_err else np.zeros((T, 0))
    dets = []
    for det in deck.detectors:
        def build(k, det=det):
            a, b = deck.perturbed("design", k if k else [0.0] * len(deck.perrs))
            if det["kind"] == "kalman_chi2":
                return kalman_design(a, b, deck.c, deck.sigma, det["q_sigma"], dt)
            return design_gain(a, b, deck.c, det["eig"], det["f"], dt)
        built = per_trial(design_keys, build)
        dad, dbd, kd = built[:3]
        kal = {}
        if det["kind"] == "kalman_chi2":   # K3, K4: the whitening and the last `window` NIS values
            kal = dict(w=built[3], nis=np.zeros((T, det["window"])))
        dets.append(dict(det, **kal, ad=dad, bd=dbd, kd=kd, xhat=np.tile(deck.x0, (T, 1)), g=np.zeros((T, p)),
                         pre_alarm_s=np.full(T, np.nan), post_alarm_s=np.full(T, np.nan),
                         pre_max=np.zeros((T, p)), r_sum=np.zeros(p), r_sq=np.zeros(p),
                         extra={lab: dict(thr=np.asarray(v, dtype=float), pre=np.full(T, np.nan),
                                          post=np.full(T, np.nan))
                                for lab, v in extra_sets.get(det["name"], {}).items()}))
    x = np.tile(deck.x0, (T, 1))
    idx = np.arange(T)
    out = sc["out"]
    code, onset, size_u, freq = sc["code"], sc["onset"], sc["size_units"], sc["freq"]
    onset_cmp = np.where(sc["fault_free"], np.inf, onset)
    held = np.full(T, np.nan)
    noise_sd = sc["noise_scale"][:, None] * deck.sigma[None, :]
    stuck_given = (code == KIND_CODE["stuck"]) & ~np.isnan(size_u)
    nu = deck.student_nu
    proc = deck.process_sigma
    for k in range(deck.steps):
        t = k * dt
        u_ref = deck.excitation(t)
        if nu is None:
            z = rng.standard_normal((T, p))
        else:
            z = rng.standard_t(nu, (T, p)) * math.sqrt((nu - 2.0) / nu)
        y = x @ deck.c.T + noise_sd * z
        if np.any(deck.d):  # G = 0 then (refused otherwise): u = r
            y = y + u_ref @ deck.d.T
        active = t >= onset_cmp
        if active.any():
            yj = y[idx, out]
            newly = active & np.isnan(held)
            held = np.where(newly, np.where(stuck_given, size_u, yj), held)
            tau = t - onset
            f = yj
            f = np.where(code == 1, yj + size_u, f)
            f = np.where(code == 2, size_u * yj, f)
            f = np.where(code == 3, held, f)
            f = np.where(code == 4, 0.0, f)
            f = np.where(code == 5, yj + size_u * tau, f)
            f = np.where(code == 6, yj + size_u * np.sin(2 * np.pi * freq * tau), f)
            y[idx, out] = np.where(active, f, yj)
        u = u_ref[None, :] - y @ deck.g.T
        for dd in dets:
            gam = y - dd["xhat"] @ deck.c.T - u @ deck.d.T
            if keep_residual_var and k == deck.steps - 1:
                ffm = sc["fault_free"]
                dd["r_end"] = gam[ffm].copy()
            if dd["kind"] == "cusum":
                dd["g"] = np.maximum(0.0, dd["g"] + np.abs(gam) - dd["drift"])
                stat = dd["g"]
            elif dd["kind"] == "kalman_chi2":
                stat = np.repeat(kalman_statistic(dd, gam, k)[:, None], p, axis=1)   # K5: under every output
            else:
                stat = np.abs(gam)
            alarm = (stat > dd["thr"]).any(axis=1)
            before = ~active
            dd["pre_max"] = np.where(before[:, None], np.maximum(dd["pre_max"], stat), dd["pre_max"])
            first_pre = before & alarm & np.isnan(dd["pre_alarm_s"])
            dd["pre_alarm_s"][first_pre] = t
            first_post = active & alarm & np.isnan(dd["post_alarm_s"])
            dd["post_alarm_s"][first_post] = t
            for ex in dd["extra"].values():
                al = (stat > ex["thr"]).any(axis=1)
                ex["pre"][before & al & np.isnan(ex["pre"])] = t
                ex["post"][active & al & np.isnan(ex["post"])] = t
            dd["xhat"] = mv(dd["ad"], dd["xhat"]) + mv(dd["bd"], u) + mv(dd["kd"], gam)
        x = mv(ad, x) + mv(bd, u)
        if np.any(proc):
            x = x + proc[None, :] * rng.standard_normal((T, n))
    rows = []
    for dd in dets:
        delay = dd["post_alarm_s"] - onset
        detected = ~np.isnan(dd["post_alarm_s"])
        if deck.window is not None:
            detected &= delay <= deck.window
        extra = {}
        for lab, ex in dd["extra"].items():
            d_ex = ex["post"] - onset
            det_ex = ~np.isnan(ex["post"])
            if deck.window is not None:
                det_ex &= d_ex <= deck.window
            extra[lab] = dict(thr=ex["thr"], false_alarm=~np.isnan(ex["pre"]), detected=det_ex,
                              delay=np.where(det_ex, d_ex, np.nan))
        rows.append(dict(detector=dd["name"], pre_alarm_s=dd["pre_alarm_s"], detected=detected,
                         delay=np.where(detected, delay, np.nan), pre_max=dd["pre_max"], r_end=dd.get("r_end"),
                         extra=extra))
    return sc, rows


def to_records(deck, sc, rows):
    recs = []
    T = len(sc["fault_free"])
    for r in rows:
        for i in range(T):
            ff = bool(sc["fault_free"][i])
            rec = dict(trial=i, detector=r["detector"], fault_free=ff, kind=sc["kind"][i],
                       target="" if ff else deck.outputs[sc["out"][i]],
                       size=sc["size"][i], size_unit=sc["size_unit"][i], size_bin=sc["size_bin"][i],
                       onset_s=sc["onset"][i], noise_scale=sc["noise_scale"][i], noise_bin=sc["noise_bin"][i],
                       false_alarm=not math.isnan(r["pre_alarm_s"][i]), false_alarm_s=r["pre_alarm_s"][i],
                       detected=bool(r["detected"][i]), delay_s=r["delay"][i])
            for j, o in enumerate(deck.outputs):
                rec[f"pre_max_{o}"] = r["pre_max"][i, j]
            for j, pe in enumerate(deck.perrs):
                rec[f"perr_{pe['name']}"] = sc["perr"][i, j]
            for lab, ex in r.get("extra", {}).items():
                pre = "cal" if lab == "own" else f"at_{lab}"
                rec[f"{pre}_false_alarm"] = bool(ex["false_alarm"][i])
                rec[f"{pre}_detected"] = bool(ex["detected"][i])
                rec[f"{pre}_delay_s"] = ex["delay"][i]
            recs.append(rec)
    return recs


def run_study(deck_path, trials, seed, keep_residual_var=False):
    deck = Deck(deck_path)
    sc, rows = simulate(deck, trials, seed, keep_residual_var)
    return deck, sc, rows


# ---------------------------------------------------------------- calibration (D13-D15, C9-C10)
def allowed_alarms(n, target_pfa, confidence=None):
    """m of D14: floor(P n), or Wilks' largest m with P(Binomial(n, P) <= m) <= 1 - C (None: none)."""
    if confidence is None:
        return int(math.floor(target_pfa * n + 1e-9))
    from scipy.stats import binom
    m = -1
    while binom.cdf(m + 1, n, target_pfa) <= 1.0 - confidence:
        m += 1
    return m if m >= 0 else None


def calibrate(pre_max, target_pfa, confidence=None):
    """pre_max: (n, p) fault-free trials' largest statistics. Returns a dict with m, n, per_statistic (h),
    factor (c), detector (thresholds), per-statistic and whole-detector alarms on these trials."""
    x = np.asarray(pre_max, dtype=float)
    n, p = x.shape
    m = allowed_alarms(n, target_pfa, confidence)
    if m is None:
        raise ValueError(f"{n} fault-free trials cannot resolve Pfa {target_pfa} at confidence {confidence}")
    m = min(m, n - 1)
    desc = -np.sort(-x, axis=0)                       # each column descending
    h = desc[m].copy()                                # the (m+1)-th largest: m values strictly above (no ties)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(h > 0, x / np.where(h > 0, h, 1.0), 0.0)
    z = ratio.max(axis=1)
    c = float(-np.sort(-z)[m])
    keep = z <= c
    thr = np.where(h > 0, c * h, 0.0)
    if keep.any():
        thr = np.maximum(thr, x[keep].max(axis=0))   # "raised" (C9)
    return dict(n=n, m=m, per_statistic=h, factor=c, detector=thr,
                statistic_alarms=(x > h).sum(axis=0), detector_alarms=int((x > thr).any(axis=1).sum()),
                calibrated=bool(target_pfa * n >= 1.0))


def run_calibrated(deck_path, trials, seed, other_sets=None):
    """Fly, calibrate each detector on its own fault-free trials (D13, D14), fly the same trials again
    with the calibrated thresholds as the set "own" (and any other_sets {detector: {label: thr}})."""
    deck = Deck(deck_path)
    sc, rows = simulate(deck, trials, seed)
    ff = sc["fault_free"]
    cal = {}
    for r in rows:
        cal[r["detector"]] = calibrate(r["pre_max"][ff], deck.target_pfa, deck.confidence)
    sets = {name: {"own": c["detector"]} for name, c in cal.items()}
    for name, extra in (other_sets or {}).items():
        if name in sets:
            sets[name].update(extra)
    sc2, rows2 = simulate(deck, trials, seed, extra_sets=sets)
    for r1, r2 in zip(rows, rows2):                   # the same trials (C10)
        if not np.array_equal(r1["pre_max"], r2["pre_max"]):
            raise RuntimeError("the second flight of the same seed differs from the first")
    return deck, sc2, rows2, cal


def write_csv(path, recs):
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(recs[0].keys()))
        w.writeheader()
        for r in recs:
            w.writerow({k: ("" if isinstance(v, float) and math.isnan(v) else v) for k, v in r.items()})


# ---------------------------------------------------------------- analytic check
def analytic(deck: Deck, rows):
    """Fault-free residual law with the design model exact, Gaussian noise, no process noise:
    e(k+1) = Phi e(k) - Kd v(k) (+ w), gamma(k) = C e(k) + v(k), e(0) = 0; the control cancels."""
    dt = deck.dt
    ad, bd = zoh(deck.a, deck.b, dt)
    r = np.diag(deck.sigma ** 2)
    qw = np.diag(deck.process_sigma ** 2)
    for det, row in zip(deck.detectors, rows):
        if det["kind"] == "kalman_chi2":
            _, _, kd, wk = kalman_design(deck.design_a, deck.design_b, deck.c, deck.sigma, det["q_sigma"], dt)
            sk = np.linalg.inv(wk.T @ wk)
            print(f"detector {det['name']}: the innovation sd the Kalman design expects (sqrt diag S): "
                  + ", ".join(f"{v:.5e}" for v in np.sqrt(np.diag(sk))))
        else:
            _, _, kd = design_gain(deck.design_a, deck.design_b, deck.c, det["eig"], det["f"], dt)
        phi = ad - kd @ deck.c
        print(f"detector {det['name']} ({det['kind']}): |eig(Ad - Kd C)| = "
              + ", ".join(f"{v:.9f}" for v in sorted(np.abs(np.linalg.eigvals(phi)), reverse=True)))
        q = kd @ r @ kd.T + qw
        pss = solve_discrete_lyapunov(phi, q)
        sd_ss = np.sqrt(np.diag(deck.c @ pss @ deck.c.T + r))
        # per-sample standard deviations from e(0) = 0
        pk = np.zeros((deck.n, deck.n))
        sds = np.empty((deck.steps, deck.p))
        for k in range(deck.steps):
            sds[k] = np.sqrt(np.diag(deck.c @ pk @ deck.c.T + r))
            pk = phi @ pk @ phi.T + q
        end = sds[-1]
        msg = "  residual sd at the trial's end (exact law) / steady state (Lyapunov) / this simulation's fault-free trials:\n"
        rend = row.get("r_end")
        for j, o in enumerate(deck.outputs):
            sim = float(np.std(rend[:, j])) if rend is not None and len(rend) > 1 else float("nan")
            msg += f"    {o:>10}: {end[j]:.5e}  {sd_ss[j]:.5e}  {sim:.5e}\n"
        print(msg, end="")
        if det["kind"] == "detection_filter" and deck.student_nu is None and not deck.perrs and deck.noise_scale.kind == "const":
            s = deck.noise_scale.value
            pk_ = 2.0 * norm.sf(det["thr"][None, :] / (s * sds))
            union = float(pk_.sum())
            sidak = float(-np.expm1(np.log1p(-pk_).sum()))
            print(f"  per-trial false-alarm probability of |r| > threshold: Sidak {sidak:.4e}, union {union:.4e}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("deck")
    ap.add_argument("--trials", type=int, default=None)
    ap.add_argument("--seed", type=int, default=12345)
    ap.add_argument("--out", required=True)
    ap.add_argument("--analytic", action="store_true", help="print the residual's exact law against the simulation")
    ap.add_argument("--calibrate", action="store_true",
                    help="calibrate at the deck's target_pfa on the own fault-free trials, print the thresholds, "
                         "add cal_false_alarm, cal_detected, cal_delay_s (D13-D15)")
    a = ap.parse_args(argv)
    deck = Deck(a.deck)
    trials = a.trials or deck.trials
    for name, kind in deck.skipped:
        print(f"note: detector {name} of kind {kind} is skipped (not implemented here)", file=sys.stderr)
    t0 = time.time()
    if a.calibrate:
        deck, sc, rows, cal = run_calibrated(a.deck, trials, a.seed)
        for name, c in cal.items():
            print(f"detector {name}: {c['n']} fault-free trials, Pfa {deck.target_pfa}: m = {c['m']} alarms, "
                  f"factor {c['factor']:.6f}, whole-detector alarms {c['detector_alarms']}")
            for j, o in enumerate(deck.outputs):
                print(f"    {o:>10}: per statistic {c['per_statistic'][j]:.9g}  detector {c['detector'][j]:.9g}")
    else:
        sc, rows = simulate(deck, trials, a.seed, keep_residual_var=a.analytic)
    recs = to_records(deck, sc, rows)
    write_csv(a.out, recs)
    print(f"{trials} trials x {len(rows)} detectors in {time.time() - t0:.1f} s -> {a.out}", file=sys.stderr)
    if a.analytic:
        analytic(deck, rows)


if __name__ == "__main__":
    main()
