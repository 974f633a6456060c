"""The exact time grid on an FMU that fails any step ending past its stop time (tests/cfmus Horizon).

Horizon (FMI 2 and 3, co-simulation and model exchange: CVode, and DOP853 in the parallel runs) returns Error for a doStep whose own t + h ends past
the stopTime it was given, and for a SetTime past it ("Exceeded model finish time", as 20-sim FMUs say), and
outputs t_reached, the time it is at. On 40 stop/step pairs (among them 2 s / 1e-4 s, which overshot by an ulp
before, and 1/30 s steps, which are no whole number of nanoseconds) every run must complete, every logged
t_reached must be exactly the double of its communication point, and the last one exactly the stop time;
serially and with the components in the parallel worker. No tolerance: the comparisons are of doubles.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from cfmus import build

from cosim.engine.scenario import parse_scenario
from cosim.io.runlog import read_run
from cosim.run import run_scenario

pytestmark = pytest.mark.integration

STOPS = (0.1, 0.3, 0.7, 1.0, 2.0, 2.2, 3.0, 10.0)
STEPS = (1e-4, 1e-3, 0.01, 0.05, 0.1)
THIRTIETH = 1 / 30
PAIRS = [(stop, step) for stop in STOPS for step in STEPS if stop / step <= 10_000] + \
        [(2.0, 1e-4), (1.0, THIRTIETH), (2.0, THIRTIETH), (0.5, THIRTIETH)]  # 40 pairs
# The pairs the master's Python loop and its parallel worker are held to: each overshoots its stop time when the
# grid's points are summed step by step (0.7 / 1e-3 and 0.3 / 0.1 also when computed as (n - 1) h + h, as the
# 2 s / 1e-4 s pair did before, in 700 and 3 steps instead of 20 000: a step through the worker's pipe costs up to
# a millisecond on the loaded 2 cores), or has steps of no whole number of nanoseconds.
HARD_PAIRS = [(0.7, 1e-3), (2.2, 0.1), (1.0, THIRTIETH), (0.3, 0.1)]


def _run(tmp_path: Path, fmi: int, stop: float, step: float, parallel: str = "off", loop: bool = True):
    """cs, me (CVode) and, in the parallel runs, me_dop (DOP853): Horizon in each, logged. ``loop``: with a Jacobi
    loop of two Feedthrough FMUs (a, b), which stays in the master when the two clocks run in the worker, and whose
    String and Binary variables keep the master's steps in its Python loop; without it the master's C loop
    steps the clocks (ten times faster)."""
    fmu = str(build("Horizon", fmi))
    dop = {"me_dop": {"path": fmu, "interface": "me", "solver": "dop853"}} if parallel == "on" else {}
    real = "Float64" if fmi == 3 else "Real"
    comps, connections = {"cs": {"path": fmu, "interface": "cs"}, "me": {"path": fmu, "interface": "me"}, **dop}, []
    if loop:
        feedthrough = str(build("Feedthrough", fmi))
        comps.update({"a": {"path": feedthrough, "interface": "cs"}, "b": {"path": feedthrough, "interface": "cs"}})
        connections = [{"from": f"a.{real}_output", "to": f"b.{real}_input"},
                       {"from": f"b.{real}_output", "to": f"a.{real}_input"}]
    text = yaml.safe_dump({
        "name": "horizon", "time": {"stop": stop, "step": step}, "parallel": parallel, "algorithm": "jacobi",
        "components": comps, "connections": connections, "logging": {"signals": "outputs", "layout": "blocks"}})
    path = tmp_path / f"h{fmi}_{stop}_{step}_{parallel}_{loop}.yaml"
    path.write_text(text)
    out = path.with_suffix(".mcap")
    # only the clocks' channels are read back (the loop's are not checked); "blocks" logs the same samples (each
    # stamp from its point's double, the same nanoseconds) in a few messages instead of one per step: read back
    # in a tenth of the time, which was most of the 40 runs' cost
    return run_scenario(parse_scenario(text, str(path)), out=out), read_run(out, components=("cs", "me", *dop))


def _check(res, log, stop: float, step: float, components=("cs", "me")) -> None:
    n = round(stop / step)
    assert res.status == "completed" and res.steps == n, f"{stop}/{step}: {res.status} after {res.steps} of {n} steps"
    for comp in components:
        sig = log.signal(f"{comp}.t_reached")
        points = np.round(np.asarray(sig.t) * 1e9).astype(np.int64) / 1e9  # the doubles of the logged points
        bad = np.flatnonzero(np.asarray(sig.y, dtype=float) != points)
        assert bad.size == 0, f"{comp} {stop}/{step}: t_reached {sig.y[bad[0]]!r} at the point {points[bad[0]]!r}"
        assert sig.y[-1] == stop and len(sig.y) == n + 1, \
            f"{comp} {stop}/{step}: {len(sig.y)} samples, the last t_reached = {sig.y[-1]!r}, stop time {stop!r}"


@pytest.mark.parametrize("fmi", [2, 3])
def test_every_pair_ends_exactly_on_the_stop_time(tmp_path, fmi):
    """Each pair is a whole run with the FMU that refuses any step past its stop time, which is what catches an
    overshoot of an ulp on the last step; the grid's arithmetic alone (tests/unit/test_grid.py) cannot. Every pair
    in the master's C loop, the hardest pairs in its Python loop too (with the Feedthrough loop: 40 pairs there
    took 25-40 s a version on the 2 cores, a tenth of that without)."""
    assert len(set(PAIRS)) >= 35 and (2.0, 1e-4) in PAIRS, len(set(PAIRS))
    for stop, step in PAIRS:
        res, log = _run(tmp_path, fmi, stop, step, loop=False)
        _check(res, log, stop, step)
    for stop, step in HARD_PAIRS:
        res, log = _run(tmp_path, fmi, stop, step, loop=True)
        _check(res, log, stop, step)


@pytest.mark.parametrize("fmi", [2, 3])
def test_the_parallel_worker_uses_the_same_grid(tmp_path, fmi):
    for stop, step in HARD_PAIRS:
        res, log = _run(tmp_path, fmi, stop, step, parallel="on")
        assert any("worker" in note for note in res.notes), f"{stop}/{step}: nothing ran in the worker: {res.notes}"
        _check(res, log, stop, step, ("cs", "me", "me_dop"))


@pytest.mark.parametrize("fmi", [2, 3])
@pytest.mark.parametrize("interface", ["cs", "me"])
def test_the_fmu_refuses_a_step_past_its_stop_time(tmp_path, fmi, interface):
    """The test FMU can fail: the old grid's last step (1.9999000000000002 + 1e-4 > 2.0) through FMPy's classes."""
    import fmpy
    from fmpy import fmi2, fmi3

    path = build("Horizon", fmi)
    md = fmpy.read_model_description(str(path))
    kind = {(2, "cs"): fmi2.FMU2Slave, (2, "me"): fmi2.FMU2Model, (3, "cs"): fmi3.FMU3Slave,
            (3, "me"): fmi3.FMU3Model}[fmi, interface]
    fmu = kind(guid=md.guid, unzipDirectory=fmpy.extract(str(path), unzipdir=str(tmp_path / "fmu")),
               modelIdentifier="Horizon")
    fmu.instantiate()
    t_last, h = 1.9999000000000002, 1e-4
    if fmi == 2:
        fmu.setupExperiment(startTime=t_last, stopTime=2.0)
        fmu.enterInitializationMode()
    else:
        fmu.enterInitializationMode(startTime=t_last, stopTime=2.0)
    fmu.exitInitializationMode()
    try:
        with pytest.raises(Exception, match="status 3|error"):  # fmpy raises a bare Exception
            if interface == "cs":
                fmu.doStep(t_last, h)
            else:
                if fmi == 2:
                    fmu.newDiscreteStates()
                else:
                    fmu.updateDiscreteStates()
                fmu.enterContinuousTimeMode()
                fmu.setTime(t_last + h)
    finally:
        fmu.freeInstance()
