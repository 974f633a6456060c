"""Checkpoints and state events: what they cost, measured side by side in one process.

For a scenario (default ``scenarios/helix_ctc.yaml``, the Exudyn plant; ``--scenario`` for another):

1. writing a checkpoint at ``--at`` (default 5 s): the time of :func:`cosim.io.checkpoint.write_checkpoint`
   itself, the file's size, and the run's loop (its wall time, start-up excluded) with the checkpoint against the
   same run without it;
2. resuming: ``run --resume`` to one step after the checkpoint against a fresh run of one step (the start-up
   both pay: loading, instantiating, initializing; the resumed one restores every state on top);
3. a state event (``--when``, default ``plant.p.x < 0.0003``: the helix crosses it a little before 0.5 s, in a
   macro step the last save is 9 steps before): re-steps per located event (the steps replayed from the last save
   and the trial steps inside the crossing's step), and the run's wall time against
   the same run with a time event at the located time (what locating costs on top of the event itself).

Run from the repository root: ``python benchmarks/checkpoint.py [--scenario FILE] [--at T] [--rounds N]``.
Figures are medians over ``--rounds`` rounds, the two sides of each ratio alternated within a round.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import record

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim import run as run_module  # noqa: E402
from cosim.engine.execution import STATE_SAVE_INTERVAL  # noqa: E402
from cosim.engine.scenario import load_scenario  # noqa: E402
from cosim.io.checkpoint import read_checkpoint  # noqa: E402
from cosim.run import RunOptions, resumed_scenario, run_scenario  # noqa: E402


def _timed(fn) -> tuple[float, object]:
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "helix_ctc.yaml"))
    ap.add_argument("--at", type=float, default=5.0, help="checkpoint time, s (default 5)")
    ap.add_argument("--stop", type=float, default=None, help="stop time, s (default: the scenario's)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--when", default="plant.p.x < 0.0003",
                    help="the state event's condition (default: the helix's x crossing 0.3 mm, a little before 0.5 s, "
                         "inside a macro step that is not a save's)")
    record.add_options(ap)
    args = ap.parse_args(argv)
    return record.measured(args, "checkpoint", _measure)


def _measure(args, rec: record.Recording) -> int:
    """The benchmark proper (see the module docstring); its figures also go to ``rec``."""
    # serial everywhere: events and checkpoints run serial, and a worker process would confound the ratios
    serial = {("parallel",): "off"}
    overrides = {**serial, ("time", "stop"): args.stop} if args.stop else serial
    scenario = load_scenario(args.scenario, overrides)
    step = scenario.time.step
    tmp = Path(tempfile.mkdtemp(prefix="bench-ckpt-"))
    ckpt = tmp / "run.ckpt"

    writes: list[float] = []
    original = run_module.write_checkpoint

    def timed_write(*a, **k):
        t0 = time.perf_counter()
        size = original(*a, **k)
        writes.append(time.perf_counter() - t0)
        return size

    run_module.write_checkpoint = timed_write
    with_ck, without_ck, resumes, fresh = [], [], [], []
    try:
        for _ in range(args.rounds):
            res = run_scenario(scenario, RunOptions(log=False, checkpoint_at=args.at, checkpoint_out=ckpt))
            with_ck.append(res.wall_time)  # the loop's wall time (the checkpoint is written inside it)
            res = run_scenario(scenario, RunOptions(log=False))
            without_ck.append(res.wall_time)
            checkpoint = read_checkpoint(ckpt)
            resumed = resumed_scenario(checkpoint, checkpoint.time + step)
            t, _ = _timed(lambda: run_scenario(resumed, RunOptions(log=False, resume=checkpoint)))
            resumes.append(t)
            one = load_scenario(args.scenario, {**serial, ("time", "stop"): step})
            t, _ = _timed(lambda: run_scenario(one, RunOptions(log=False)))
            fresh.append(t)
    finally:
        run_module.write_checkpoint = original
    med = statistics.median
    print(f"scenario {scenario.name}, checkpoint at {args.at:g} s of {scenario.time.stop:g} s, {args.rounds} round(s); "
          "medians, this machine")
    print(f"  checkpoint write: {med(writes) * 1e3:.2f} ms, {ckpt.stat().st_size} bytes")
    print(f"  the run's loop with / without the checkpoint: {med(with_ck):.3f} s / {med(without_ck):.3f} s "
          f"(ratio {med(with_ck) / med(without_ck):.3f})")
    print(f"  resume to one step after it / a fresh run of one step: {med(resumes):.3f} s / {med(fresh):.3f} s "
          f"(ratio {med(resumes) / med(fresh):.3f})")
    rec.put("write_ms", med(writes) * 1e3)
    rec.put("bytes", ckpt.stat().st_size)
    rec.put("loop_with_s", med(with_ck))
    rec.put("loop_without_s", med(without_ck))
    rec.put("loop_ratio", med(with_ck) / med(without_ck))
    rec.put("resume_s", med(resumes))
    rec.put("fresh_s", med(fresh))
    rec.put("resume_ratio", med(resumes) / med(fresh))

    # state event: located by re-stepping, against a time event at the located time
    short = {**serial, ("time", "stop"): min(args.at, scenario.time.stop)}
    located, timed_ev, restarts, t_event = [], [], 0, None
    for _ in range(args.rounds):
        ev_sc = load_scenario(args.scenario, {**short, ("events",): [
            {"when": args.when, "set": {"plant.mass.payload": 0.0}}]})
        t, res = _timed(lambda: run_scenario(ev_sc, RunOptions(log=False)))
        located.append(t)
        if not res.fired:
            print(f"  state event {args.when}: never fired before {args.at:g} s")
            return 0
        t_event = res.fired[0]["t"]
        note = next((n for n in res.notes if "re-step" in n), "")
        restarts = int(note.split(" by ")[1].split(" ")[0]) if note else 0
        tev_sc = load_scenario(args.scenario, {**short, ("events",): [
            {"at": t_event, "set": {"plant.mass.payload": 0.0}}]})
        t, _ = _timed(lambda: run_scenario(tev_sc, RunOptions(log=False)))
        timed_ev.append(t)
    print(f"  state event {args.when} located at {t_event:.9f} s by {restarts} re-step(s) of the macro step")
    print(f"  run with it / with a time event at that time: {med(located):.3f} s / {med(timed_ev):.3f} s "
          f"(ratio {med(located) / med(timed_ev):.3f}; while it is armed the system's state is saved every "
          f"{STATE_SAVE_INTERVAL} macro steps)")
    rec.put("event_t_s", t_event)
    rec.put("event_restarts", restarts)
    rec.put("event_run_s", med(located))
    rec.put("time_event_run_s", med(timed_ev))
    rec.put("event_ratio", med(located) / med(timed_ev))
    return 0


if __name__ == "__main__":
    sys.exit(main())
