"""Microseconds per 1 ms step of each Exudyn plant and fidelity, measured side by side.

Run: ``python benchmarks/plant_step.py [--steps N] [--rounds R]``. Rounds interleave the plants
so that load from other processes hits all of them alike; the median per plant is printed with
its ratio to the lumped linear plant and the issue's target. Efforts: analytic gravity
compensation (constant).

Where the time goes (``python -m cProfile``, Exudyn's ``solver.timer``): in the full models the
per-step Jacobian factorisation dominates (sparse LU of 95 / 134 unknowns, linear / rotary);
the lumped linear plant is ~10 us of solver and the rest Python (efforts in, outputs out).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from delta.dynamics import analytic_model
from delta.robots import linear_delta_thesis, rotary_delta_prototype
from multibody import make_plant

CASES = [
    ("linear full", linear_delta_thesis, "full", (0.03, -0.02, -0.45)),
    ("linear lumped", linear_delta_thesis, "lumped", (0.03, -0.02, -0.45)),
    ("rotary full", rotary_delta_prototype, "full", (0.03, -0.02, -0.45)),
    ("rotary lumped", rotary_delta_prototype, "lumped", (0.03, -0.02, -0.45)),
]
TARGET_US = {"linear full": 300.0, "linear lumped": 30.0, "rotary full": 600.0}
"""Issue 4 targets, us per 1 ms step on the 2-core machine (none for the rotary lumped plant)."""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    plants = {}
    for name, robot, fidelity, p0 in CASES:
        plant = make_plant(robot, fidelity=fidelity, p0=p0)
        u = analytic_model(robot, plant.masses).gravity_term(plant.output.q)
        plants[name] = (plant, u)
    samples = {name: [] for name in plants}
    for _ in range(args.rounds):
        for name, (plant, u) in plants.items():
            plant.reset(plant.output.p if plant.time == 0.0 else CASES[[c[0] for c in CASES].index(name)][3])
            t0 = time.perf_counter()
            for _ in range(args.steps):
                plant.step(plant.time, 1e-3, u)
            samples[name].append((time.perf_counter() - t0) / args.steps * 1e6)
    ref = float(np.median(samples["linear lumped"]))
    print(f"{'plant':15s} {'us/step (median)':>17s} {'min':>8s} {'ratio to linear lumped':>24s} {'target':>8s}")
    for name, vals in samples.items():
        med = float(np.median(vals))
        target = TARGET_US.get(name)
        verdict = "-" if target is None else f"{target:.0f} {'met' if med <= target else 'MISSED'}"
        print(f"{name:15s} {med:17.1f} {min(vals):8.1f} {med / ref:24.2f} {verdict:>8s}")


if __name__ == "__main__":
    main()
