#!/usr/bin/env python3
"""Independent reference for fdimc's fault-free replay of a PX4 log by method 003 (tests/replay_cli.rs,
`a_replay_run_records_its_calibration_and_warns_of_a_transient`): the largest residual statistic T
after settle_s, and where it occurs, in each part of studies/replay_px4_calibrated.toml's log
(studies/logs/sample_appended_multiple.ulg, sensor_combined at 100 Hz, window_samples 20, settle_s 1.5).
fdimc pins: evaluated part [4.80, 9.60) s, 3.3 s watched: largest T 394.8 at 9.59 s; training part
[0.00, 4.80) s, 3.3 s watched: largest T 411.2 at 4.77 s. A second check prints the bench log
(studies/logs/sample_log_small.ulg) over its second half, which docs/flight-logs.md says reaches 121.

Written from the spec in NumPy; no code shared with fdimc. The ULog is read by pyulog, not px4-ulog.
Run (pyulog and numpy in a venv):
  python3 -m venv ~/.cache/fdimc-ref && ~/.cache/fdimc-ref/bin/pip install pyulog numpy
  ~/.cache/fdimc-ref/bin/python scripts/reference/replay_attitude_ekf_numpy.py

From the docs/spec (../shared/methods.md 003, docs/findings-seed003.md, docs/deck.md, docs/flight-logs.md,
the decks):
- quaternion EKF, gyro-propagated, state update with the normalised accelerometer as the gravity
  direction; residual e = z - g(qhat); quaternion renormalised after each update;
- the exact transition over each step with the mean of the two gyro samples around it;
- Q = (dt sigma_w / 2)^2 I4 (isotropic); the filter tuned to the nominal sensor noise (filter_noise
  "nominal"), 0.1 deg/s gyro and 0.02 m/s^2 accelerometer;
- T = n |mean of the last n residuals|^2 / sigma_z^2, n = window_samples = 20;
- resampling: step k is the mean of the log's samples within half a step of k dt from the topic's
  first sample; a step without one takes the linear interpolation across the gap; the grid ends at
  the last sample; parts are the steps whose time is in [from, to); settle_s = 1.5; times are seconds
  from the topic's first sample; the filter aligns on the first sample (the deck's comment).
Taken from fdimc's code (definitions only; src/methods/accelerometer/attitude.rs, ekf_svm/detection.rs,
ekf_svm/features.rs, replay.rs, study.rs, src/engine/logs/log_source.rs, flight_log.rs, src/kinematics.rs):
- each part is its own run, filter started (aligned) on the part's first step, not carried over from
  the log's start; sigma_w of Q is exactly the gyro's 0.1 deg/s, sigma_a of R the accelerometer's 0.02;
- quaternion (q0, q1, q2, q3) scalar first, body -> NED, q' = 1/2 q (x) (0, w) (right product);
  g(q) = -(third row of the body->NED rotation matrix) = the body-axes view of NED "up";
- alignment: roll = atan2(-z_y, -z_z), pitch = atan2(z_x, hypot(z_y, z_z)), heading 0, composed
  yaw-pitch-roll; the first sample gets no time update, only the observation update;
- P0 = (sigma_0 / 2)^2 I4 with sigma_0 = 5 deg; R = (sigma_a / g0)^2 I3, g0 = 9.80665;
  sigma_z = sigma_a / g0; the residual is the innovation (before the update, at q(k|k-1));
  Joseph-form covariance update, P not renormalised with q;
- T is NaN (no decision) until n residuals are in; "watched" = the part's steps from
  ceil(settle_s / dt - 1e-9); the first of equal largest values; its time = (part first + index) dt;
- the part's steps: first = ceil(from / dt - 1e-9), end = min(floor(to / dt + 1e-9), grid length);
  grid length = floor((t_last - t0) / dt + 1e-9) + 1; times t = timestamp_us * 1e-6 (boot clock) and
  the bins' edges t0 + k dt -+ dt/2 compared in floating point, a sample on the lower edge belonging
  to the step (the script also bins in integer microseconds and prints how many samples that moves);
- the fields are `timestamp` (not accelerometer_timestamp_relative), topic instance (multi_id) 0.

Printed (numpy 2.4.6, pyulog 1.3.0; the two pinned lines match fdimc's to the printed digits, exit 0):
  sample_appended_multiple.ulg: 2373 samples over 9.6176 s (largest gap 0.0160 s) -> 962 steps at 0.01 s, 1 interpolated; float vs integer-us bins differ at 0 step(s)
  fault-free log, evaluated part [4.80, 9.60) s, 3.3 s watched: largest T 394.8 at 9.59 s    (T = 394.787721; three largest [394.788 394.236 392.317])
  fault-free log, training part [0.00, 4.80) s, 3.3 s watched: largest T 411.2 at 4.77 s    (T = 411.160327; three largest [411.16  407.805 404.418])
  sample_log_small.ulg: 1298 samples over 6.4962 s (largest gap 0.1613 s) -> 650 steps at 0.01 s, 15 interpolated; float vs integer-us bins differ at 0 step(s)
  fault-free log, evaluated (bench, second half) part [3.20, 6.49) s, 1.8 s watched: largest T 120.7 at 5.82 s    (T = 120.714359; three largest [120.714 116.584 114.889])
  evaluated part against fdimc's 394.8 at 9.59 s: match
  training part against fdimc's 411.2 at 4.77 s: match
fdimc's own threshold line (`fdimc validate studies/replay_px4_calibrated.toml`: "threshold
616.7404909918484 (1.5 x the largest T of the fault-free training part)") gives the training part's
largest T as 411.160327327899; this script's is 411.1603273278972 (relative difference 4e-15).
The bench part is a choice: no deck pins it; [3.2, 6.49) is what `fdimc new --replay` would take as the
second half (half_s = floor(span / 2, 0.1 s)), and gives docs/flight-logs.md's "121"; [3.25, 6.50)
gives 119.0. What the check discriminates (tried once, not kept): the resampling (linear interpolation
at k dt instead of bin means: 407.7 at 8.53 s and 427.0 at 3.42 s), sigma_w (0.2 deg/s: 160.6, 162.8),
P0 (sigma_0 = 1 deg: 394.6, 410.7), one filter run from the log's start instead of one per part
(evaluated part: 559.4 at 6.36 s); a level start instead of the alignment moves T by 0.05 only.
"""
import os
import sys

import numpy as np
from pyulog import ULog

HERE = os.path.dirname(os.path.abspath(__file__))
LOGS = os.path.join(HERE, "..", "..", "studies", "logs")
DT = 0.01
G0 = 9.80665
SIGMA_W = np.deg2rad(0.1)          # rad/s: the filter's gyro noise (Q)
SIGMA_A = 0.02                     # m/s^2: the accelerometer noise (R, sigma_z)
SIGMA_0 = np.deg2rad(5.0)          # rad: the prior's attitude spread (P0)
N_WINDOW = 20
SETTLE_S = 1.5
GYRO = [f"gyro_rad[{i}]" for i in range(3)]
ACCEL = [f"accelerometer_m_s2[{i}]" for i in range(3)]


def read_topic(path, topic="sensor_combined", instance=0):
    """Times (integer us, boot clock) and the six IMU columns as float64 (gyro x y z, accel x y z)."""
    d = next(x for x in ULog(path, [topic]).data_list if x.name == topic and x.multi_id == instance)
    t_us = d.data["timestamp"].astype(np.int64)
    x = np.column_stack([d.data[f].astype(np.float64) for f in GYRO + ACCEL])
    assert np.all(np.diff(t_us) > 0) and np.all(np.isfinite(x)), "times must increase, values be finite"
    return t_us, x


def resample(t_us, x, dt=DT, integer_bins=False):
    """Step k = mean of the samples within half a step of t0 + k dt ([lo, hi)); empty: interpolated."""
    n_steps = int(np.floor((t_us[-1] - t_us[0]) * 1e-6 / dt + 1e-9)) + 1
    k = np.arange(n_steps)
    if integer_bins:  # exact: bin of a sample = floor((t - t0 + dt/2) / dt) in microseconds
        step_us = int(round(dt * 1e6))
        b = (t_us - t_us[0] + step_us // 2) // step_us
        lo, hi = np.searchsorted(b, k, "left"), np.searchsorted(b, k, "right")
    else:  # the same in floating-point seconds
        t_s = t_us * 1e-6
        tk = t_s[0] + k * dt
        lo, hi = np.searchsorted(t_s, tk - 0.5 * dt, "left"), np.searchsorted(t_s, tk + 0.5 * dt, "left")
    count = hi - lo
    out = np.empty((n_steps, x.shape[1]))
    full = count > 0
    out[full] = np.array([x[a:b].sum(axis=0) for a, b in zip(lo[full], hi[full])]) / count[full, None]
    if not full.all():  # steps in a gap: the line through the samples either side
        tk_s = (t_us[0] + k[~full] * dt * 1e6) * 1e-6
        out[~full] = np.column_stack([np.interp(tk_s, t_us * 1e-6, x[:, j]) for j in range(x.shape[1])])
    return out, int((~full).sum())


def part(lo_s, hi_s, n_steps, dt=DT):
    return int(np.ceil(lo_s / dt - 1e-9)), min(int(np.floor(hi_s / dt + 1e-9)), n_steps)


def rot_up(q):
    """g(q): gravity's reaction ('up', the specific force at rest) seen in body axes, and dg/dq."""
    q0, q1, q2, q3 = q
    g = -np.array([2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3])
    H = -2.0 * np.array([[-q2, q3, -q0, q1], [q1, q0, q3, q2], [q0, -q1, -q2, q3]])
    return g, H


def right_product_matrix(p):
    """M with q (x) p = M q (Hamilton product, scalar first)."""
    p0, p1, p2, p3 = p
    return np.array([[p0, -p1, -p2, -p3], [p1, p0, p3, -p2], [p2, -p3, p0, p1], [p3, p2, -p1, p0]])


def align(a):
    z = a / np.linalg.norm(a)
    roll, pitch = np.arctan2(-z[1], -z[2]), np.arctan2(z[0], np.hypot(z[1], z[2]))
    cr, sr, cp, sp = np.cos(roll / 2), np.sin(roll / 2), np.cos(pitch / 2), np.sin(pitch / 2)
    return np.array([cr * cp, sr * cp, cr * sp, -sr * sp])  # yaw 0: Rz(0) Ry(pitch) Rx(roll)


def residuals(gyro, accel, dt=DT):
    """Innovations e(k) = z(k) - g(q(k|k-1)) of the attitude EKF run from the first sample."""
    Q = (dt * SIGMA_W / 2) ** 2 * np.eye(4)
    R = (SIGMA_A / G0) ** 2 * np.eye(3)
    q, P = align(accel[0]), (SIGMA_0 / 2) ** 2 * np.eye(4)
    e = np.empty_like(accel)
    for k in range(len(accel)):
        if k > 0:
            w = 0.5 * (gyro[k - 1] + gyro[k])
            angle = np.linalg.norm(w) * dt
            dq = np.r_[np.cos(angle / 2), (np.sin(angle / 2) / np.linalg.norm(w)) * w] if angle > 0 else np.r_[1.0, 0, 0, 0]
            F = right_product_matrix(dq)
            q, P = F @ q, F @ P @ F.T + Q
        g, H = rot_up(q)
        e[k] = accel[k] / np.linalg.norm(accel[k]) - g
        S = H @ P @ H.T + R
        K = np.linalg.solve(S, H @ P).T          # P H' S^-1 (S, P symmetric)
        A = np.eye(4) - K @ H
        P = A @ P @ A.T + K @ R @ K.T
        q = q + K @ e[k]
        q /= np.linalg.norm(q)
    return e


def statistic(e, n=N_WINDOW):
    """T(k) = n |mean(e[k-n+1..k])|^2 / sigma_z^2; NaN for k < n - 1."""
    T = np.full(len(e), np.nan)
    m = np.lib.stride_tricks.sliding_window_view(e, n, axis=0).mean(axis=-1)
    T[n - 1:] = n * (m ** 2).sum(axis=1) / (SIGMA_A / G0) ** 2
    return T


def largest(x, first, end, name, lo_s, hi_s, settle_s=SETTLE_S):
    T = statistic(residuals(x[first:end, :3], x[first:end, 3:]))
    settle = min(int(np.ceil(settle_s / DT - 1e-9)), len(T))
    watched = T[settle:]
    k = int(np.nanargmax(watched))            # the first of equal largest
    at = (first + settle + k) * DT
    top = np.sort(watched[~np.isnan(watched)])[::-1][:3]
    print(f"fault-free log, {name} part [{lo_s:.2f}, {hi_s:.2f}) s, {len(watched) * DT:.1f} s watched: "
          f"largest T {watched[k]:.1f} at {at:.2f} s    (T = {watched[k]:.6f}; three largest {np.round(top, 3)})")
    return watched[k], at


def check_jacobian():
    q = np.array([0.9, 0.2, -0.3, 0.25])
    q /= np.linalg.norm(q)
    num = np.column_stack([(rot_up(q + h)[0] - rot_up(q - h)[0]) / 2e-7 for h in 1e-7 * np.eye(4)])
    assert np.abs(num - rot_up(q)[1]).max() < 1e-7


def main():
    check_jacobian()
    runs = [("sample_appended_multiple.ulg", [("evaluated", 4.8, 9.6), ("training", 0.0, 4.8)]),
            ("sample_log_small.ulg", [("evaluated (bench, second half)", 3.2, 6.49)])]
    results = {}
    for name, parts in runs:
        t_us, raw = read_topic(os.path.join(LOGS, name))
        x, gaps = resample(t_us, raw)
        xi, _ = resample(t_us, raw, integer_bins=True)
        moved = int(np.sum(np.any(x != xi, axis=1)))
        gap = np.diff(t_us).max() * 1e-6
        print(f"{name}: {len(t_us)} samples over {(t_us[-1] - t_us[0]) * 1e-6:.4f} s (largest gap {gap:.4f} s) -> "
              f"{len(x)} steps at {DT} s, {gaps} interpolated; float vs integer-us bins differ at {moved} step(s)")
        for label, lo_s, hi_s in parts:
            first, end = part(lo_s, hi_s, len(x))
            results[(name, label)] = largest(x, first, end, label, lo_s, hi_s)
    pinned = {("sample_appended_multiple.ulg", "evaluated"): (394.8, 9.59),
              ("sample_appended_multiple.ulg", "training"): (411.2, 4.77)}
    ok = True
    for key, (value, at) in pinned.items():
        got = results[key]
        same = f"{got[0]:.1f}" == f"{value:.1f}" and f"{got[1]:.2f}" == f"{at:.2f}"
        ok &= same
        print(f"{key[1]} part against fdimc's {value} at {at} s: {'match' if same else 'MISMATCH'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
