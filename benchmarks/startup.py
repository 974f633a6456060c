"""Start-up (issue 36 item 3): a whole ``python -m cosim run`` process against OSP libcosim's whole process on the same
exported SSP archive, alternated in one run.

Ours: ``python -m cosim run SCENARIO --no-log --stop-time T`` (default: helix_ctc_analytic, 0.01 s, native FMUs: the
default build), a new interpreter each time, timed from the spawn to its exit. libcosim's: a new interpreter that
imports libcosimpy, ``CosimExecution.from_ssp_file`` on the scenario exported once beforehand with ``python -m cosim
ssp export SCENARIO --stop-time T`` (the same FMUs), and ``simulate_until(T)``. Both also simulate T (10 steps of
1 ms by default: what is timed is the start-up). ``--help`` (``python -m cosim --help``) is timed alongside, and the
interpreter alone (``python -c pass``) as the floor all three share. Each of the ``--repeat`` rounds runs the four in
turn (the order rotated each round); medians and the best of each are printed, and the ratio ours / libcosim (target
at most 1.5x).

    python benchmarks/startup.py [--repeat 15] [--scenario scenarios/helix_ctc_analytic.yaml] [--stop 0.01]
                                 [--json FILE | --record]

Every process runs with its bytecode cached, as an installed package's does: ``PYTHONDONTWRITEBYTECODE`` is removed
from their environment (set, as in this project's sessions, no ``__pycache__`` is written for our own modules and
every start compiles some 300 of them again: about 0.4 s more). The first, untimed round writes the caches.

``python -X importtime -m cosim run scenarios/helix_ctc_analytic.yaml --no-log --stop-time 0.01 2>imp.txt`` lists
what the import costs (``--importtime`` prints its largest top-level entries here).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import record

ROOT = Path(__file__).resolve().parents[1]

LIBCOSIM = """
import sys
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
log_output_level(CosimLogLevel.ERROR)
ex = CosimExecution.from_ssp_file(sys.argv[1], step_size=int(sys.argv[2]))
assert ex.simulate_until(int(sys.argv[3]))
"""


ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def _timed(cmd: list[str]) -> float:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=ENV)
    elapsed = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} exited {proc.returncode}: {proc.stderr.strip()[-2000:]}")
    return elapsed


def _import_budget(scenario: str, stop: float, top: int) -> dict[str, float]:
    """The largest top-level imports of one run (``-X importtime``, cumulative), ms by module."""
    proc = subprocess.run([sys.executable, "-X", "importtime", "-m", "cosim", "run", scenario, "--no-log",
                           "--stop-time", repr(stop)], cwd=ROOT, capture_output=True, text=True, env=ENV)
    rows = []
    for line in proc.stderr.splitlines():
        parts = line.split("|")
        if len(parts) == 3 and parts[1].strip().isdigit() and not parts[2].startswith("  "):
            rows.append((int(parts[1]), parts[2].strip()))
    print(f"import budget (top-level modules, cumulative; {sum(r[0] for r in rows) / 1e3:.0f} ms in all):")
    largest = sorted(rows, reverse=True)[:top]
    for us, name in largest:
        print(f"  {us / 1e3:7.1f} ms  {name}")
    return {name: round(us / 1e3, 1) for us, name in largest}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.splitlines()[2:]))
    ap.add_argument("--scenario", default="scenarios/helix_ctc_analytic.yaml")
    ap.add_argument("--stop", type=float, default=0.01, help="simulated time, s (default 0.01)")
    ap.add_argument("--repeat", type=int, default=15, help="rounds (default 15)")
    ap.add_argument("--importtime", type=int, default=12, metavar="N",
                    help="print the N largest top-level imports of one run (0: none; default 12)")
    record.add_options(ap)
    args = ap.parse_args()
    with record.Recording(args, "startup") as rec:
        _measure(args, rec)
    return 0


def _measure(args, rec: record.Recording) -> None:
    py = sys.executable
    with tempfile.TemporaryDirectory(prefix="cosim-startup-") as tmp:
        ssp = str(Path(tmp) / "system.ssp")
        subprocess.run([py, "-m", "cosim", "ssp", "export", args.scenario, "--stop-time", repr(args.stop), "-o", ssp],
                       cwd=ROOT, check=True, stdout=subprocess.DEVNULL)
        step_ns, stop_ns = 1_000_000, round(args.stop * 1e9)
        commands = {
            "ours": [py, "-m", "cosim", "run", args.scenario, "--no-log", "--stop-time", repr(args.stop)],
            "libcosim": [py, "-c", LIBCOSIM, ssp, str(step_ns), str(stop_ns)],
            "--help": [py, "-m", "cosim", "--help"],
            "python": [py, "-c", "pass"],
        }
        for cmd in commands.values():  # untimed: the FMU cache, the page cache
            _timed(cmd)
        times: dict[str, list[float]] = {k: [] for k in commands}
        names = list(commands)
        for i in range(args.repeat):
            for name in names[i % len(names):] + names[:i % len(names)]:
                times[name].append(_timed(commands[name]))
    print(f"{args.scenario}, --stop-time {args.stop:g}; {args.repeat} rounds, alternated; {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.2f} after")
    print(f"{'whole process':34}{'median, s':>10}{'best, s':>10}")
    labels = {"ours": "python -m cosim run", "libcosim": "libcosimpy from_ssp_file + simulate_until",
              "--help": "python -m cosim --help", "python": "python -c pass (the interpreter)"}
    for name, label in labels.items():
        print(f"{label:44}{statistics.median(times[name]):10.3f}{min(times[name]):10.3f}")
        rec.put(f"{name.lstrip('-')}_median_s", statistics.median(times[name]))
        rec.put(f"{name.lstrip('-')}_best_s", min(times[name]))
    med = statistics.median(times["ours"]) / statistics.median(times["libcosim"])
    best = min(times["ours"]) / min(times["libcosim"])
    per_round = statistics.median(a / b for a, b in zip(times["ours"], times["libcosim"]))
    print(f"ours / libcosim: {med:.2f}x of the medians, {best:.2f}x of the best, {per_round:.2f}x median of the "
          f"rounds' ratios (target at most 1.5x)")
    rec.put("ratio_of_medians", med)
    rec.put("ratio_of_best", best)
    rec.put("ratio_median_of_rounds", per_round)
    if args.importtime:
        rec.put("imports_ms", _import_budget(args.scenario, args.stop, args.importtime))


if __name__ == "__main__":
    raise SystemExit(main())
