#!/usr/bin/env python3
"""Seed 001's "too large an R gives a second rise", looked for in noise-free traces (issue 50, item 2):
flies `studies/seed001_second_rise.toml` with `fdimc simulate` once per detector (one calm, noise-free
flight, a 50 % loss on engine 1 at 20 s), then draws each detector's fhat over its own peak against time
(docs/seed001_second_rise.svg, plain SVG: no plotting library needed) and prints each trace's peak, the
local maxima after it and the values at chosen times, for docs/findings-seed001.md.

    python3 scripts/second_rise.py            # needs the release build, or FDIMC=path/to/fdimc
"""
import csv
import pathlib
import subprocess
import sys
import tempfile

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from findings import ROOT, fdimc_binary  # noqa: E402

DECK = ROOT / "studies" / "seed001_second_rise.toml"
DETECTORS = [
    ("f100_deg", "plain filter, F = 100 (the seed's top)", "#1f77b4"),
    ("f10000_deg", "plain filter, F = 10000 (data 86x the prior)", "#d62728"),
    ("fast_f10000_deg", "recovering filter, F = 10000 (data 4.5x the prior)", "#2ca02c"),
]
T0, T1 = 19.5, 40.0


def trace(binary, detector, folder):
    out = folder / f"{detector}.csv"
    subprocess.run([binary, "simulate", str(DECK), "--detector", detector, "--out", str(out)], check=True,
                   capture_output=True)
    with out.open() as f:
        rows = [(float(r["t_s"]), float(r[f"{detector}_fhat"])) for r in csv.DictReader(f)]
    return [(t, v) for t, v in rows if T0 <= t <= T1]


def svg(traces):
    w, h, left, right, top, bottom = 760, 360, 60, 20, 20, 90
    x = lambda t: left + (t - T0) / (T1 - T0) * (w - left - right)  # noqa: E731
    y = lambda v: top + (1.1 - v) / 1.2 * (h - top - bottom)  # noqa: E731 (fhat / peak from -0.1 to 1.1)
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">',
             f'<rect width="{w}" height="{h}" fill="white"/>']
    for v in [0.0, 0.5, 1.0]:
        parts.append(f'<line x1="{left}" x2="{w - right}" y1="{y(v):.1f}" y2="{y(v):.1f}" stroke="#ddd"/>')
        parts.append(f'<text x="{left - 8}" y="{y(v) + 4:.1f}" text-anchor="end">{v:g}</text>')
    for t in range(20, 41, 5):
        parts.append(f'<line x1="{x(t):.1f}" x2="{x(t):.1f}" y1="{top}" y2="{h - bottom}" stroke="#eee"/>')
        parts.append(f'<text x="{x(t):.1f}" y="{h - bottom + 16}" text-anchor="middle">{t}</text>')
    parts.append(f'<text x="{(left + w - right) / 2}" y="{h - bottom + 34}" text-anchor="middle">time, s (50 % loss of engine 1 at 20 s; no noise, calm air)</text>')
    parts.append(f'<text x="14" y="{(top + h - bottom) / 2}" transform="rotate(-90 14 {(top + h - bottom) / 2})" text-anchor="middle">fhat / its peak</text>')
    for i, ((detector, label, colour), rows) in enumerate(zip(DETECTORS, traces)):
        peak = max(abs(v) for _, v in rows)
        # Every sample over the jump, every fifth after it (the page stays small).
        kept = [(t, v) for k, (t, v) in enumerate(rows) if t < 21.0 or k % 5 == 0]
        points = " ".join(f"{x(t):.1f},{y(v / peak):.1f}" for t, v in kept)
        parts.append(f'<polyline fill="none" stroke="{colour}" stroke-width="1.5" points="{points}"/>')
        ly = h - bottom + 50 + 14 * i
        parts.append(f'<line x1="{left}" x2="{left + 24}" y1="{ly - 4}" y2="{ly - 4}" stroke="{colour}" stroke-width="2"/>')
        parts.append(f'<text x="{left + 30}" y="{ly}">{detector}: {label}</text>')
    parts.append("</svg>")
    return "\n".join(parts) + "\n"


def main():
    binary = fdimc_binary()
    with tempfile.TemporaryDirectory() as d:
        traces = [trace(binary, det, pathlib.Path(d)) for det, _, _ in DETECTORS]
    (ROOT / "docs" / "seed001_second_rise.svg").write_text(svg(traces))
    for (detector, _, _), rows in zip(DETECTORS, traces):
        peak_t, peak = max(rows, key=lambda r: abs(r[1]))
        vals = [abs(v) for _, v in rows]
        maxima = [(rows[i][0], vals[i] / abs(peak)) for i in range(1, len(rows) - 1)
                  if vals[i] >= vals[i - 1] and vals[i] > vals[i + 1] and vals[i] > 0.05 * abs(peak)]
        at = {t: next(v for u, v in rows if abs(u - t) < 0.004) / peak for t in [20.2, 21, 22, 25, 30, 39.99]}
        print(f"{detector}: peak {peak:.4g} at {peak_t:.2f} s; local maxima over 5 % of it (t, share): "
              + ", ".join(f"({t:.2f}, {s:.3f})" for t, s in maxima)
              + "; at " + ", ".join(f"{t} s {s:.3f}" for t, s in at.items()))


if __name__ == "__main__":
    main()
