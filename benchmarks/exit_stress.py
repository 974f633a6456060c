"""Consecutive short runs, solver failures included: does every process exit as its run ended?

Issue 15: after an Exudyn solver failure, 2 runs in 129 printed their error, finished their log and
then aborted at interpreter exit (``corrupted double-linked list``, exit 134). Each run here is a
fresh ``python -m cosim run`` process; a run is *abnormal* when its exit code is not the one its
case expects (0 completed, 2 error), when it died from a signal, or when its stderr holds a
traceback or a glibc heap message. Prints the count of each.

    python benchmarks/exit_stress.py [--runs 200] [--jobs 2] [--log] [--plain-exit]

``--log`` writes each run's MCAP log (into a temporary directory) so that finishing a log is part
of every exit. ``--plain-exit`` runs the CLI through ``sys.exit(main())``, the exit path before
``cosim/__main__.py`` skipped the interpreter's finalization, to see the aborts it contains.
About 1.2 s per run on the 2-core machine.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import record

ROOT = Path(__file__).resolve().parents[1]
ABSURD = ["--set", "ctl.gain.kp[1]=1e12", "--set", "ctl.limit.u_max=1e300"]  # Newton fails in the first steps
CASES = [
    # (name, scenario, extra arguments, expected exit code)
    ("linear full: Exudyn solver failure", "helix_ctc.yaml", ["--stop-time", "0.05", *ABSURD], 2),
    ("linear full: carriage into its end stop", "helix_ctc.yaml", ["--stop-time", "0.5", "--set", "ctl.gain.kp[1]=1e12"], 2),
    ("linear full: completed", "helix_ctc.yaml", ["--stop-time", "0.02"], 0),
    ("rotary full: Exudyn solver failure", "rotary_pick_place_ctc.yaml", ["--stop-time", "0.05", *ABSURD], 2),
    ("linear lumped: Exudyn solver failure", "helix_ctc.yaml",
     ["--stop-time", "0.05", *ABSURD, "--set", "plant.model.fidelity=lumped"], 2),
    ("controller parameter refused", "helix_pd.yaml", ["--stop-time", "0.05", "--set", "ctl.gain.kp[1]=-1"], 2),
]
BAD_TEXT = ("Traceback", "corrupted", "double free", "Segmentation fault", "Aborted", "Fatal Python error")


PLAIN_EXIT = ["-c", "import sys; from cosim.cli import main; sys.exit(main(sys.argv[1:]))"]


def run_case(k: int, out_dir: Path | None, plain_exit: bool = False) -> tuple[str, int, int, str]:
    """Run case ``k % len(CASES)``: (case name, expected code, exit code, what was abnormal or "")."""
    name, scenario, extra, expected = CASES[k % len(CASES)]
    cmd = [sys.executable, *(PLAIN_EXIT if plain_exit else ["-m", "cosim"]), "run",
           str(ROOT / "scenarios" / scenario), *extra, "--parallel", "off"]
    cmd += ["--out", str(out_dir / f"run{k}.mcap")] if out_dir is not None else ["--no-log"]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    problem = ""
    if proc.returncode != expected:
        problem = f"exit {proc.returncode}, expected {expected}"
    bad = [b for b in BAD_TEXT if b in proc.stderr]
    if bad:
        problem += ("; " if problem else "") + f"stderr has {bad}"
    if problem:
        problem += f"; stderr tail: {proc.stderr.strip()[-300:]!r}"
    return name, expected, proc.returncode, problem


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--jobs", type=int, default=2, help="runs at the same time (default 2: the machine's cores)")
    ap.add_argument("--log", action="store_true", help="write each run's MCAP log")
    ap.add_argument("--plain-exit", action="store_true", help="exit through sys.exit(main()) (no containment)")
    record.add_options(ap)
    args = ap.parse_args()
    with record.Recording(args, "exit_stress") as rec:
        return _measure(args, rec)  # recorded with abnormal exits too: their count is what it measures


def _measure(args, rec: record.Recording) -> int:
    """The benchmark proper (see the module docstring); its figures also go to ``rec``."""
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(args.jobs) as pool:
        out_dir = Path(tmp) if args.log else None
        results = list(pool.map(lambda k: run_case(k, out_dir, args.plain_exit), range(args.runs)))
    abnormal = [(k, r) for k, r in enumerate(results) if r[3]]
    failures = sum(1 for r in results if r[1] == 2)
    for k, (name, _, code, problem) in abnormal:
        print(f"run {k} ({name}): {problem}")
    print(f"{args.runs} runs ({failures} ending in an error, {failures - sum(r[0].startswith('controller') for r in results)} "
          f"of them solver failures or end stops) in {time.perf_counter() - t0:.0f} s: "
          f"{len(abnormal)} abnormal exits")
    rec.put("runs", args.runs)
    rec.put("abnormal", len(abnormal))
    rec.put("errors", failures)
    rec.put("wall_s", time.perf_counter() - t0)
    return 1 if abnormal else 0


if __name__ == "__main__":
    sys.exit(main())
