"""Calibrating the payload and the time offset from a SYNTHETIC robot recording (issue 37, item 4's figure).

A run of ``helix_ctc_analytic`` (native FMUs) with a payload of 0.3 kg on the plant, the controller's model keeping
its own 0 kg (a CTC controller told the payload cancels it, and the joints would not show it), is turned into a ROS 2
bag by ``tests/recording_helpers.synthetic_plant_bag``: the joints ``q[1..3]`` at 250 Hz, Gaussian noise of 1e-6 m,
the recording starting 0.2137 s (53.425 samples: no whole number of steps) before the run. Then
``cosim.analysis.calibrate.calibrate`` fits the plant's payload from a wrong start (0.1 kg) and the offset, and
the benchmark prints the recovered values against the truth and the targets (payload within 2 %, offset within
1 ms), the standard errors, the runs of the scenario the fit made, and the wall time (the runs' share of it).

With ``--pool`` it measures what the sweep's pool would do for a Jacobian of two scenario values: two runs of the
scenario one after the other in this process (as the fit runs them) against the same two on the sweep's embedded
pool of two workers (``SweepCluster``, ``run_loaded_case``), the pool started for the pair and kept open.

With ``--linked`` it also fits the payload set on the plant and the controller as one value (``--fit
plant.mass.payload,ctl.mass.payload``): what the joints cannot show, the Jacobian says (its standard error).

    python benchmarks/calibration.py [--stop 2.0] [--rounds 3] [--linked] [--pool] [--json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from recording_helpers import synthetic_plant_bag  # noqa: E402

from cosim import api  # noqa: E402
from cosim.analysis.calibrate import calibrate, parse_fits  # noqa: E402

SCENARIO = ROOT / "scenarios" / "helix_ctc_analytic.yaml"
PAYLOAD, START, OFFSET_S, NOISE_M, RATE_HZ = 0.3, 0.1, 0.2137, 1e-6, 250.0
MAPS = {f"plant.q[{i}]": f"/joint_states.position[delta_joint_{i}]" for i in (1, 2, 3)}


def one(bag: Path, stop: float, fits: list[str], start: float) -> dict:
    t0 = time.perf_counter()
    cal = calibrate(SCENARIO, bag, MAPS, parse_fits(fits), sets=[f"time.stop={stop}", f"plant.mass.payload={start}"]
                    + ([f"ctl.mass.payload={start}"] if "," in fits[0] else []))
    wall = time.perf_counter() - t0
    payload, offset = cal.parameters
    return {"converged": cal.converged, "payload_kg": payload["value"], "payload_stderr": payload["stderr"],
            "payload_error_rel": (payload["value"] - PAYLOAD) / PAYLOAD, "offset_s": offset["value"],
            "offset_stderr": offset["stderr"], "offset_error_s": offset["value"] - OFFSET_S, "runs": cal.runs,
            "evaluations": cal.evaluations, "wall_s": wall, "run_s": cal.run_time, "samples": cal.samples,
            "rms_before_m": max(cal.rms_before.values()), "rms_after_m": max(cal.rms_after.values()),
            "correlation": cal.correlation[0][1] if cal.correlation else None, "notes": cal.notes}


def pool_against_serial(stop: float, rounds: int) -> list[dict]:
    """Two runs here, one after the other, against the same two on the sweep's pool (started / kept open), s."""
    from cosim.analysis.cluster import SweepCluster
    from cosim.analysis.sweep import prebuild, run_loaded_case
    from cosim.engine.overrides import dotted_overrides
    from cosim.engine.scenario import read_scenario
    from cosim.observers.recorders import Probe
    from cosim.run import run_scenario

    src = read_scenario(SCENARIO)
    pair = [src.load(dotted_overrides({"time.stop": stop, "plant.mass.payload": p, "parallel": "off"}))
            for p in (START, START * 1.001)]
    files = prebuild(pair)

    def serial() -> float:
        t0 = time.perf_counter()
        for sc in pair:
            run_scenario(sc, log=False, observers=[Probe(list(MAPS))], read_all=True, fmu_files=files)
        return time.perf_counter() - t0

    def pooled(client) -> float:
        t0 = time.perf_counter()
        for fut in [client.submit(run_loaded_case, sc, files, None) for sc in pair]:
            fut.result()
        return time.perf_counter() - t0

    serial()  # warm: the FMUs extracted, the code loaded
    out = []
    with SweepCluster(2, None) as (client, _):
        pooled(client)
        for _ in range(rounds):
            t0 = time.perf_counter()
            with SweepCluster(2, None) as (fresh, _):
                pooled(fresh)
            out.append({"serial_s": serial(), "pool_started_s": time.perf_counter() - t0,
                        "pool_open_s": pooled(client)})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stop", type=float, default=2.0, help="simulated seconds of the run and of each fit run")
    ap.add_argument("--rounds", type=int, default=3, help="calibrations, each from the same bag")
    ap.add_argument("--linked", action="store_true", help="also fit the payload linked on plant and controller")
    ap.add_argument("--pool", action="store_true", help="also time two runs here against the sweep's pool")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    pool = pool_against_serial(args.stop, args.rounds) if args.pool else None
    with tempfile.TemporaryDirectory(prefix="cosim-calibration-") as tmp:
        log = Path(tmp) / "truth.mcap"
        t0 = time.perf_counter()
        api.run(str(SCENARIO), {"time.stop": args.stop, "plant.mass.payload": PAYLOAD}, log=True, out=log,
                signals=False)
        bag = synthetic_plant_bag(Path(tmp) / "robot_bag", log, rate_hz=RATE_HZ, offset_s=OFFSET_S, noise=NOISE_M)
        made = time.perf_counter() - t0
        rounds = [one(bag, args.stop, ["plant.mass.payload=0:1", "offset"], START) for _ in range(args.rounds)]
        linked = one(bag, args.stop, ["plant.mass.payload,ctl.mass.payload=0:1", "offset"], START) \
            if args.linked else None
    out = {"stop_s": args.stop, "truth": {"payload_kg": PAYLOAD, "offset_s": OFFSET_S, "noise_m": NOISE_M,
                                          "rate_hz": RATE_HZ}, "start_kg": START, "bag_made_s": made,
           "rounds": rounds, "linked": linked, "pool": pool}
    if args.json:
        print(json.dumps(out, indent=2))
        return
    r = rounds[0]
    walls = [x["wall_s"] for x in rounds]
    print(f"helix_ctc_analytic, {args.stop:g} s; synthetic bag: payload {PAYLOAD} kg on the plant, {RATE_HZ:g} Hz, "
          f"noise {NOISE_M:g} m, offset {OFFSET_S} s ({OFFSET_S * RATE_HZ:.3f} samples); made in {made:.1f} s")
    print(f"fit from {START} kg: {'converged' if r['converged'] else 'DID NOT CONVERGE'} over {r['samples']} samples")
    met_p = "met" if abs(r["payload_error_rel"]) <= 0.02 else "NOT met"
    met_o = "met" if abs(r["offset_error_s"]) <= 1e-3 else "NOT met"
    print(f"  payload {r['payload_kg']:.6f} kg (std error {r['payload_stderr']:.2g}): error "
          f"{100 * r['payload_error_rel']:+.3f} % (target 2 %: {met_p})")
    print(f"  offset {r['offset_s']:.9f} s (std error {r['offset_stderr']:.2g}): error "
          f"{1e6 * r['offset_error_s']:+.2f} us (target 1 ms: {met_o}); correlation {r['correlation']:+.3f}")
    print(f"  joints' RMS residual {r['rms_before_m']:.3g} m at the start -> {r['rms_after_m']:.3g} m "
          f"(noise {NOISE_M:g})")
    print(f"  {r['runs']} runs of the scenario, {r['evaluations']} evaluations; wall {statistics.median(walls):.2f} s "
          f"median of {len(walls)} ({min(walls):.2f}-{max(walls):.2f} s), {r['run_s']:.2f} s of it in the runs: "
          f"{r['run_s'] / r['runs']:.3f} s a run")
    if linked is not None:
        print(f"linked plant,ctl payload: {linked['payload_kg']:.4f} kg (std error {linked['payload_stderr']:.2g}); "
              f"{linked['runs']} runs; RMS {linked['rms_before_m']:.3g} -> {linked['rms_after_m']:.3g} m"
              + "".join(f"\n  {n}" for n in linked["notes"] if "identifiable" in n))
    for p in pool or []:
        print(f"two runs of {args.stop:g} s: here {p['serial_s']:.3f} s; on the sweep's pool of 2 started for them "
              f"{p['pool_started_s']:.3f} s ({p['serial_s'] / p['pool_started_s']:.2f}x), kept open "
              f"{p['pool_open_s']:.3f} s ({p['serial_s'] / p['pool_open_s']:.2f}x)")


if __name__ == "__main__":
    main()
