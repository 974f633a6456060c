"""The pick-and-place cycle with a part picked and placed: the controller told of the payload or not.

Runs ``scenarios/pick_place_ctc.yaml`` (a 0.2 kg part picked at the start of each cycle and placed at its far
end: the plant's payload changes at those events, and the controller's model is told at the same events),
``scenarios/pick_place_ctc_untold.yaml`` (the controller is not told) and the empty-gripper cycle (the first
with ``events: []``), and prints, for the half cycle after each event (carrying the part after a pick, empty
after a place), the largest tracking error |p - p_ref| and the largest effort |u|, and over the whole run the
tracking RMSE per axis. These are results of the model, not timings: one run each is enough.

Run from the repository root: ``python benchmarks/pick_place_payload.py [--fmus auto|python|native] [--json FILE |
--record]``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

import record

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.engine.scenario import load_scenario  # noqa: E402
from cosim.io.runlog import read_run  # noqa: E402
from cosim.run import run_scenario  # noqa: E402

WINDOW = 0.25  # s: half a cycle, from an event to the next


def _run(name: str, out: Path, overrides: dict) -> tuple[dict, object]:
    scenario = load_scenario(ROOT / "scenarios" / f"{name}.yaml", overrides)
    res = run_scenario(scenario, out=out, log=True)
    return res, read_run(out)


def _windows(log, events: list[float]) -> list[tuple[float, float, float]]:
    """(event time, max |p - p_ref| in m, max |u| in N) over [t, t + WINDOW) after each event time."""
    s = log.signals
    t = s["plant.p.x"].t
    err = np.sqrt(sum((s[f"plant.p.{a}"].y - s[f"traj.p_ref.{a}"].y) ** 2 for a in "xyz"))
    u = np.max(np.abs(np.stack([s[f"plant.u[{i}]"].y for i in (1, 2, 3)])), axis=0)
    out = []
    for te in events:
        m = (t >= te) & (t < te + WINDOW - 1e-9)
        out.append((te, float(err[m].max()), float(u[m].max())))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--fmus", choices=("auto", "python", "native"), default="auto")
    record.add_options(ap)
    args = ap.parse_args(argv)
    with record.Recording(args, "pick_place_payload") as rec:
        _measure(args, rec)
    return 0


def _measure(args, rec: record.Recording) -> None:
    tmp = Path(tempfile.mkdtemp(prefix="pick-place-"))
    base = {("fmus",): args.fmus}
    runs = {
        "empty gripper": _run("pick_place_ctc", tmp / "empty.mcap", {**base, ("events",): []}),
        "part, controller told": _run("pick_place_ctc", tmp / "told.mcap", base),
        "part, controller not told": _run("pick_place_ctc_untold", tmp / "untold.mcap", base),
    }
    events = [e["t"] for e in runs["part, controller told"][1].events if "event" in e]
    print(f"pick_place_ctc, 0.2 kg part picked at {events[0::2]} s and placed at {events[1::2]} s (fmus={args.fmus})")
    print("tracking RMSE x / y / z (um) over the run:")
    for name, (res, _) in runs.items():
        print(f"  {name:27s} " + " / ".join(f"{e.rmse * 1e6:7.1f}" for e in res.errors))
    table = {name: _windows(log, events) for name, (_, log) in runs.items()}
    print(f"per half cycle after each event: max |p - p_ref| (um) and max |u| (N) over [t, t + {WINDOW} s)")
    print("  event  t (s)   " + "".join(f"{n:>30s}" for n in runs))
    for i, te in enumerate(events):
        kind = "pick " if i % 2 == 0 else "place"
        cells = "".join(f"{table[n][i][1] * 1e6:14.1f} um {table[n][i][2]:10.2f} N" for n in runs)
        print(f"  {kind}  {te:5.2f}  {cells}")
    for key, name in zip(("empty", "told", "untold"), runs):
        picks, places = table[name][0::2], table[name][1::2]
        rec.put(key, {"rmse_um": [e.rmse * 1e6 for e in runs[name][0].errors],
                      "carrying_error_um": _range(w[1] * 1e6 for w in picks),
                      "placed_error_um": _range(w[1] * 1e6 for w in places),
                      "carrying_effort_N": _range(w[2] for w in picks)})


def _range(values) -> list[float]:
    """[smallest, largest]."""
    values = list(values)
    return [min(values), max(values)]


if __name__ == "__main__":
    sys.exit(main())
