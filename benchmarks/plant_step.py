"""Microseconds per 1 ms step of each Exudyn plant and fidelity, this checkout against a baseline commit.

Run: ``python benchmarks/plant_step.py [--steps N] [--rounds R] [--baseline COMMIT] [--[no-]reuse-jacobian]``.

``--in-run S`` measures instead what the plant costs in a run (issue 36 item 6): the linear full plant's step as
below (this checkout, per-model settings) and, alternately in the same process, helix_ctc's plant component
(``component_time_s`` per step of ``S`` simulated seconds, serial, no log, the scenario's own FMU build: the
Exudyn plant is a python FMU); printed: the medians, minima and the ratio of the medians (target at most 1.15).
Measured 2026-11-28 (load 2.8, ``--in-run 1 --rounds 5``): 78.0 us against 143.0 us, 1.83x, not met. Where the
difference goes: the benchmark's plant holds still, the run's follows the helix. Replaying the run's efforts into
the same plant (same process), Newton takes 4.22 modified iterations a step against 3.82, but the kept matrix is
refactorised at 0.242 steps in 1 against 0.016 (``it.newtonJacobiCount``), and Exudyn's timers put the
factorisation at a fifth of the moving plant's solver time against 4 % of the still one's. Exudyn's sparse
matrix drops exact zeros when it is filled and re-analyses the pattern whenever its count of nonzeros differs
from the last analysed one (``GeneralMatrixEigenSparse::FactorizeNew``), so ``reuseAnalyzedPattern`` does not
keep one analysis per run once the moving mechanism's Jacobian gains or loses an exact zero. The plant's own step
on those replayed efforts (best of 7, alternated, load 1.0): 100.6 us against 78.4 us still (1.28x); with Eigen's
dense LU (``SolverSettings(sparse=False)``, no pattern to analyse) 92.4 against 77.0 us (1.20x); the rest of the
run's figure (1.65x at load 1-2) is the FMU around the plant (PythonFMU's calls, the adapter, the outputs).
The ``multibody/`` package of ``COMMIT`` (default 288e832, where issue 27's plant work started) is taken
from git into a temporary directory and imported under another name, so both versions run in this one
process on the same ``delta/``; rounds interleave every plant of both versions, so that load from other
processes hits them alike (``--reuse-jacobian`` / ``--no-reuse-jacobian``: this checkout's plants with
``SolverSettings(reuse_jacobian=True / False)`` instead of the per-model default). Printed per plant: the
median and minimum over the rounds of both versions and the ratio of the medians (this / baseline), with
issue 27's target for the full plants (at most 0.5). Efforts: analytic
gravity compensation (constant), from the same pose each round.

Where the time goes (``perf record``; Exudyn's ``solver.timer``), linear / rotary full at 288e832, about
140 / 250 us per step on the 2-core machine: ``SolveSteps`` 115 / 180 us, of which Eigen's sparse LU of
the Newton matrix (95 / 134 unknowns; refactorised on every ``SolveSteps`` entry) about half, the Newton
Jacobian a fifth, two residuals (mass matrix, forces, constraint reactions) a quarter; the Python around
it 20 us linear (efforts in 4 us, outputs 5 us, end-time settings 2 us), 45 us rotary (of which 19 us were
six Exudyn output calls to read the arm angles, now read from the coordinates: 6 us).
With ``reuse_jacobian`` (linear / rotary): factorisation 2 us, Jacobian < 1 us per step; Newton takes
~2.9 iterations instead of ~1, so ~3.9 residual evaluations (56 / 85 us: constraint reactions, forces,
constraints, mass matrix) and ~2.9 solves (12 / 15 us) are most of what is left, plus the Python above.

Since the rotary arms are 1-DOF rotational bodies (e3da3b6) both full models have 95 unknowns and, with
a fresh Newton matrix at every step, cost the same: ~145 us per step, of which ``SolveSteps`` ~122 us
(factorisation about half, Jacobian a sixth, two residuals a quarter) and the Python around it ~21 us.

Since 37fe5f9 both full plants converge every step: ``newton_rel_tol`` 1e-10 (was 1e-6, which accepted
Newton's first iterate: up to 7.3e-7 m off the mechanism's closure at pick_place_ctc's jerk steps) and the
Newton matrix kept across steps (``REUSE_MAX_MODIFIED_ITERATIONS`` 4). A kept matrix takes ~4.4 modified
iterations a step here (static), ~4.9 while the platform moves; each is a residual (mass matrix, forces,
constraint reactions, constraints: ~17 us) and a solve (~4 us), so the linear step is ~90 us of
``SolveSteps`` plus ~20 us of Python. A fresh matrix needs 2.9 iterations to converge (Exudyn's Newton
matrix is not the exact Jacobian: convergence is linear, ~1e-3 a step, with a fresh one too) plus the
factorisation and Jacobian (~80 us). Measured 2026-11-26 on the 2-core machine, quiet (load average 0.6),
baseline 288e832 (139-145 / 248-257 us full):

    python benchmarks/plant_step.py --rounds 5                       (2 runs)
        linear full 0.76-0.77 (110-111 us), rotary full 0.46 (116-119 us); lumped 0.94-0.95 / 0.27-0.29
    python benchmarks/plant_step.py --rounds 5 --no-reuse-jacobian   (1 run: converged, fresh matrix)
        linear full 1.12 (159 us), rotary full 0.63 (160 us)

Whole runs (``python benchmarks/against_commit.py --baseline 8bdb6fc scenarios/X.yaml --rounds 3``, against
the unconverged plant of 8bdb6fc): helix_ctc 0.95x (1.88 s against 1.98 s), pick_place_ctc 1.04-1.11x (its
7 g cycle takes more iterations to converge).

Since 509e323 the rods are masses at their two ends (``multibody.inertia.rod_end_masses``: the cylinder's
kinetic energy as a constant quadratic form of its end velocities) held at their length by one distance
constraint, instead of rigid bodies on Euler parameters; a linear delta's lower rod ends are points of their
carriage, so each leg is one constant mass matrix: 53 unknowns instead of 95 (rotary 89), a residual ~8.5 us
instead of ~13.5 (``solver.ComputeNewtonResidual``), and a kept Newton matrix refactorised once it needs a
4th modified iteration (``REUSE_MAX_MODIFIED_ITERATIONS`` 3: 3.8 iterations a step here). The golden baselines
of the helices hold to 4e-13 m; pick_place_ctc's moved by 7.9e-9 m, the two discretisations' difference
(tests/golden/README.md). Measured 2026-11-26 on the 2-core machine, quiet (load average 0.4-0.5), baseline
288e832 (141-147 / 251-253 us full)::

    python benchmarks/plant_step.py --rounds 5                       (2 runs)
        linear full 0.47-0.48 (68-69 us), rotary full 0.36-0.37 (91-93 us); lumped 0.91-0.92 / 0.26-0.27
    python benchmarks/plant_step.py --rounds 5 --no-reuse-jacobian   (1 run: a fresh matrix every step)
        linear full 0.69 (100 us), rotary full 0.50 (128 us)

Since 83498e2 the platform turns on a rotation-vector node integrated on the rotation group (Exudyn's
``NodeRigidBodyRotVecLG``), whose mass matrix is constant: with the end-point rods every body's is, and Exudyn
builds the system's mass matrix once instead of at every residual; no Euler-parameter constraint (51 / 87
unknowns). The same samples as on Euler parameters within 3e-16 m on pick_place_ctc. Against the commit before
(``--baseline 44ac33c``): linear full 0.94x (64.3 against 68.4 us), rotary 0.98x. Against 288e832::

    python benchmarks/plant_step.py [--rounds 5]                     (3 runs)
        linear full 0.44-0.47 (64-67 us), rotary full 0.34-0.36 (88-94 us); lumped 0.92-0.94 / 0.24-0.26
    python benchmarks/plant_step.py --rounds 5 --no-reuse-jacobian   (1 run)
        linear full 0.72 (101 us), rotary full 0.56 (144 us)

Issue 27's 0.5: met by both full plants. Before 509e323 the linear plant stood at 0.76 (110 us): a converged
step took ~4.4 modified Newton iterations of a 95-unknown residual.

A better predictor cannot be set from Python: Exudyn's generalized-alpha Newton starts every step from
zero accelerations (``ComputeNewtonUpdate(initial=True)`` in CSolverImplicitSecondOrder.cpp), and a
``SetUserFunctionComputeNewtonUpdate`` function cannot call the built-in update (it recurses into
itself) nor set the algorithmic accelerations (a getter, no setter). Measured and dropped: Eigen's dense LU for the full models
(1.15x the sparse LU's time), ``jacobianConnectorDerivative = False`` (no gain measured),
``parallel.numberOfThreads = 2`` (linear full 1.02x in one run; Exudyn warns that its task manager is
still running when a second plant is initialised in the process),
``exudynCPPfast`` (``EXUDYN_MODULE=fast``: ``SolveSteps`` ~8 % faster, a process-wide import choice that
prints on stdout, and not comparable in this one-process benchmark). With the end-point rods: the platform on
Tait-Bryan angles instead of Euler parameters (no faster), Eigen's dense LU (the same time as the sparse at 53
unknowns), refreshing the Newton matrix every k steps (a fresh one costs a Jacobian, 16 us, and an LU, 33 us,
more than the ~2 iterations it saves), and leaving the step-size settings alone when span / n only wanders by
ulps (it moved helix_ctc by 1.1e-9 m at one sample, past its baseline).
"""

from __future__ import annotations

import argparse
import importlib.util
import io
import re
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

from delta.dynamics import analytic_model
from delta.robots import linear_delta_thesis, rotary_delta_prototype

import record

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_BASELINE = "288e832"
P0 = (0.03, -0.02, -0.45)
CASES = [
    ("linear full", linear_delta_thesis, "full"),
    ("linear lumped", linear_delta_thesis, "lumped"),
    ("rotary full", rotary_delta_prototype, "full"),
    ("rotary lumped", rotary_delta_prototype, "lumped"),
]
TARGET_RATIO = {"linear full": 0.5, "rotary full": 0.5}
"""Issue 27 item 3: per-step time of the full plants at most half the baseline's."""


_CORE = re.compile(r"^(\s*)(from|import) (delta|multibody)\b", re.M)


def load_baseline(commit: str, into: Path):
    """Import ``multibody/`` as it is in ``commit`` (from ``git archive``) as package ``multibody_baseline``, with
    the ``delta/`` of that commit beside it as ``delta_baseline`` (the core it was written against: today's may no
    longer have what it imports)."""
    proc = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", commit, "multibody", "delta"],
                          capture_output=True)
    if proc.returncode != 0:
        message = proc.stderr.decode(errors="replace").strip().splitlines()
        raise ValueError(f"--baseline {commit!r}: no multibody/ and delta/ at that commit in {ROOT} "
                         f"({message[-1] if message else 'git archive failed'})")
    with tarfile.open(fileobj=io.BytesIO(proc.stdout)) as tar:
        tar.extractall(into, filter="data")
    for name in ("delta", "multibody"):
        package = into / f"{name}_baseline"
        (into / name).rename(package)
        for path in package.rglob("*.py"):  # their absolute imports of each other: the baseline's
            path.write_text(_CORE.sub(lambda m: f"{m[1]}{m[2]} {m[3]}_baseline", path.read_text()))
    for name in ("delta_baseline", "multibody_baseline"):
        package = into / name
        spec = importlib.util.spec_from_file_location(name, package / "__init__.py",
                                                      submodule_search_locations=[str(package)])
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module  # its relative imports resolve inside it
        spec.loader.exec_module(module)
    return module


def _as_baseline(robot):
    """``robot`` as the baseline's own core describes it (its classes: its plants check the robot's type)."""
    kind = getattr(sys.modules["delta_baseline.robots"], type(robot).__name__)
    return kind(**{f: getattr(robot, f) for f in robot.__dataclass_fields__})


def _positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text}")
    return value


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=_positive, default=300, help="1 ms steps per plant and round (default 300)")
    ap.add_argument("--rounds", type=_positive, default=7, help="interleaved rounds; medians are printed (default 7)")
    ap.add_argument("--baseline", default=DEFAULT_BASELINE, metavar="COMMIT",
                    help=f"commit whose multibody/ is timed alongside this checkout's (default {DEFAULT_BASELINE})")
    ap.add_argument("--reuse-jacobian", action=argparse.BooleanOptionalAction, default=None,
                    help="time this checkout's plants with SolverSettings(reuse_jacobian=True / False) "
                         "(default: the per-model default)")
    ap.add_argument("--in-run", type=float, default=None, metavar="S",
                    help="compare the linear full plant's step with helix_ctc's plant component over S simulated s")
    record.add_options(ap)
    args = ap.parse_args(argv)
    with record.Recording(args, "plant_step") as rec:
        _measure(args, rec)


def _measure(args, rec: record.Recording) -> None:
    """The benchmark proper (see the module docstring); its figures also go to ``rec``."""
    if args.in_run is not None:
        in_run(args.in_run, args.steps, args.rounds, rec)
        return

    import multibody

    with tempfile.TemporaryDirectory(prefix="plant_step_") as tmp:
        try:
            baseline = load_baseline(args.baseline, Path(tmp))
        except ValueError as exc:
            sys.exit(f"plant_step.py: --baseline {args.baseline}: {exc}")
        versions = {"baseline": baseline, "this": multibody}
        plants = {}
        for name, robot, fidelity in CASES:
            for version, package in versions.items():
                forced = version == "this" and args.reuse_jacobian is not None
                settings = multibody.SolverSettings(reuse_jacobian=args.reuse_jacobian) if forced else None
                own = robot if version == "this" else _as_baseline(robot)
                plant = package.make_plant(own, fidelity=fidelity, p0=P0, settings=settings)
                model = analytic_model if version == "this" else sys.modules["delta_baseline.dynamics"].analytic_model
                u = model(own, plant.masses).gravity_term(plant.output.q)
                plants[name, version] = (plant, u)
        samples = {key: [] for key in plants}
        for _ in range(args.rounds):
            for key, (plant, u) in plants.items():
                plant.reset(P0)
                t0 = time.perf_counter()
                for _ in range(args.steps):
                    plant.step(plant.time, 1e-3, u)
                samples[key].append((time.perf_counter() - t0) / args.steps * 1e6)

    print(f"us per 1 ms step: median (min) over {args.rounds} interleaved rounds of {args.steps} steps; "
          f"baseline = multibody/ at {args.baseline}{f'; this: reuse_jacobian={args.reuse_jacobian}' if args.reuse_jacobian is not None else ''}")
    print(f"{'plant':15s} {'baseline':>17s} {'this':>17s} {'ratio':>7s} {'target':>13s}")
    for name, _, _ in CASES:
        old, new = samples[name, "baseline"], samples[name, "this"]
        ratio = float(np.median(new) / np.median(old))
        target = TARGET_RATIO.get(name)
        verdict = "-" if target is None else f"{target:.2f} {'met' if ratio <= target else 'MISSED'}"
        print(f"{name:15s} {np.median(old):8.1f} ({min(old):6.1f}) {np.median(new):8.1f} ({min(new):6.1f}) "
              f"{ratio:7.2f} {verdict:>13s}")
        rec.put(name.replace(" ", "_"), {"baseline_median_us": float(np.median(old)), "baseline_min_us": min(old),
                                         "median_us": float(np.median(new)), "min_us": min(new), "ratio": ratio})


TARGET_IN_RUN = 1.15
"""Issue 36 item 6: helix_ctc's plant component per step at most 1.15x the linear full plant's step here."""


def in_run(stop: float, steps: int, rounds: int, rec: record.Recording) -> None:
    """``--in-run`` (see the module docstring)."""
    import multibody
    from cosim.engine.scenario import load_scenario
    from cosim.run import RunOptions, run_scenario

    if not stop > 0:
        sys.exit(f"--in-run must be a time > 0 s, got {stop}")
    robot = linear_delta_thesis
    plant = multibody.make_plant(robot, fidelity="full", p0=P0)
    u = analytic_model(robot, plant.masses).gravity_term(plant.output.q)
    scenario = load_scenario(ROOT / "scenarios" / "helix_ctc.yaml", {("time", "stop"): stop, ("parallel",): "off"})
    bench, run = [], []
    for r in range(rounds):
        for what in ("bench", "run")[:: 1 if r % 2 == 0 else -1]:
            if what == "bench":
                plant.reset(P0)
                t0 = time.perf_counter()
                for _ in range(steps):
                    plant.step(plant.time, 1e-3, u)
                bench.append((time.perf_counter() - t0) / steps * 1e6)
            else:
                res = run_scenario(scenario, RunOptions(log=False))
                if res.status != "completed":
                    sys.exit(f"helix_ctc did not complete: {res.status} {res.message}")
                run.append(res.component_time["plant"] / res.steps * 1e6)
    ratio = float(np.median(run) / np.median(bench))
    rec.put("bench_step_us", [min(bench), float(np.median(bench))])
    rec.put("run_plant_us", [min(run), float(np.median(run))])
    rec.put("ratio_medians", ratio)
    print(f"us per 1 ms step, median (min) of {rounds} alternated rounds: linear full plant ({steps} steps) "
          f"{np.median(bench):.1f} ({min(bench):.1f}); helix_ctc's plant component ({stop:g} s, serial, no log) "
          f"{np.median(run):.1f} ({min(run):.1f}); ratio {ratio:.2f}, target <= {TARGET_IN_RUN:g}: "
          f"{'met' if ratio <= TARGET_IN_RUN else 'NOT met'}")


if __name__ == "__main__":
    main()
