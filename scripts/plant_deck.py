#!/usr/bin/env python3
"""Writes an LTI deck (method 000's kind) with a synthetic stable plant of a chosen size, for measuring
how design and trial cost grow with the number of states (README "Plants of realistic size").

    python3 scripts/plant_deck.py --states 24 --outputs 8 --seed 1 > studies/bench_states24.toml

The plant is synthetic, every number a choice (none is a published aircraft's):
- A: diagonal -d_i with d_i log-uniform in [0.5, 50] 1/s (slow airframe modes to fast actuators), plus
  random couplings whose row sums stay below 0.9 d_i; by Gershgorin every principal submatrix of A is
  stable, so the minimum-norm gain's unassigned eigenvalues (those of the unmeasured block) are too.
- C measures the first `outputs` states; the detector's fault directions are those states' unit
  vectors (F = [I; 0], r = outputs <= n), eigenvalues -1, -2, ... per direction.
- B: two inputs, random; a square wave on the first.
- Sensor noise 0.01 per output; thresholds 0.05 per output (5 sigma of the raw noise: a choice, to be
  calibrated with `fdimc summarize --target-pfa`).
Duration and step match studies/bench_seed000.toml (30 s at 100 Hz) so trial rates compare.
"""

import argparse

import numpy as np


def toml_matrix(M, fmt="{:.6g}"):
    """A matrix as a TOML array of rows, one row per line."""
    return "[\n" + "".join("  [" + ", ".join(fmt.format(x) for x in r) + "],\n" for r in M) + "]"


def toml_strings(v):
    """Strings as a TOML array."""
    return "[" + ", ".join(f'"{x}"' for x in v) + "]"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--states", type=int, required=True, help="number of states n (>= 2)")
    ap.add_argument("--outputs", type=int, help="measured states m <= n (default n)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--trials", type=int, default=20000)
    a = ap.parse_args()
    n = a.states
    m = a.outputs or n
    if n < 2 or not 1 <= m <= n:
        ap.error(f"need n >= 2 and 1 <= outputs <= n, got n = {n}, outputs = {m}")
    rng = np.random.default_rng(a.seed)
    d = 0.5 * 100.0 ** rng.random(n)
    A = rng.uniform(-1.0, 1.0, (n, n))
    np.fill_diagonal(A, 0.0)
    A *= (0.9 * d / np.maximum(np.abs(A).sum(axis=1), 1e-300))[:, None]
    np.fill_diagonal(A, -d)
    B = rng.uniform(-1.0, 1.0, (n, 2))
    C = np.eye(m, n)

    def names(prefix, k):
        return toml_strings(f"{prefix}{i + 1}" for i in range(k))

    lam = ", ".join(f"{-(i + 1):.1f}" for i in range(m))
    F = np.eye(n, m).T  # one direction per row, as the deck gives them
    print(f"""# Synthetic {n}-state plant, {m} measured states (scripts/plant_deck.py --states {n} --outputs {m} --seed {a.seed}).
# Every number is a choice of that script (see its docstring), none a published aircraft's: this deck
# measures how cost grows with plant size.

[study]
name = "bench_states{n}"
seed = 7
duration_s = 30.0
dt_s = 0.01

[plant]
states = {names("x", n)}
inputs = ["u1", "u2"]
outputs = {names("y", m)}
a = {toml_matrix(A)}
b = {toml_matrix(B)}
c = {toml_matrix(C)}

[[excitation]]
input = "u1"
shape = "square"
amplitude = 1.0
period_s = 8.0

[noise]
sensor_sigma = [{", ".join(["0.01"] * m)}]

[[detector]]
name = "df"
kind = "detection_filter"
eigenvalues_per_s = [{lam}]
fault_directions = {toml_matrix(F)}
thresholds = [{", ".join(["0.05"] * m)}]

[monte_carlo]
trials = {a.trials}
fault_free_fraction = 0.1
sampler = "random"
onset_s = {{ range = [5.0, 25.0] }}

[[monte_carlo.fault]]
kind = "bias"
size_sigma = {{ range = [2.0, 20.0], bins = 4 }}""")


if __name__ == "__main__":
    main()
