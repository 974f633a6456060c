"""A scenario's run time on this checkout against an earlier commit, side by side in one run.

    python benchmarks/against_commit.py --baseline 288e832 scenarios/helix_ctc.yaml --rounds 5

The baseline commit is checked out into a temporary git worktree; each runs its own copy of ``SCENARIO`` (the file
as that commit has it) with ``python -m cosim run SCENARIO --no-log --json`` in its own interpreter (the baseline with its own folder first on PYTHONPATH), alternately,
``--rounds`` times, and the stepping loop's wall time (``wall_time_s`` of the run summary) is compared: best and
median per side, and their ratio (this checkout / baseline; below 1 is faster). The whole command's wall time
(start-up, FMU build from the cache, extraction) is printed too. Both sides build their FMUs into their own
cache on the first round, which is not timed.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import record

ROOT = Path(__file__).resolve().parents[1]


def _run(tree: Path, scenario: str, extra: list[str]) -> tuple[float, float]:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "cosim", "run", str(tree / scenario), "--no-log", "--json", *extra],
                          cwd=tree, env=env, capture_output=True, text=True)
    whole = time.perf_counter() - t0
    if proc.returncode not in (0, 1):
        raise SystemExit(f"error: {tree}: run failed (exit {proc.returncode}): "
                         f"{(proc.stderr.strip().splitlines() or ['?'])[-1]}")
    return json.loads(proc.stdout)["wall_time_s"], whole


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenario", help="scenario file, relative to the repository root")
    ap.add_argument("--baseline", required=True, help="commit to compare against (any git revision)")
    ap.add_argument("--rounds", type=int, default=5, help="alternated timed rounds per side (default 5)")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="passed to both runs")
    record.add_options(ap)
    args = ap.parse_args()
    return record.measured(args, "against_commit", _measure)


def _measure(args, rec: record.Recording) -> int:
    """The benchmark proper (see the module docstring); its figures also go to ``rec``."""
    if args.rounds < 1:
        raise SystemExit("error: --rounds must be at least 1")
    if not (ROOT / args.scenario).is_file():
        raise SystemExit(f"error: {args.scenario}: no such scenario file under {ROOT}")
    extra = [a for s in args.set for a in ("--set", s)]
    with tempfile.TemporaryDirectory(prefix="cosim-baseline-") as tmp:
        base = Path(tmp) / "tree"
        made = subprocess.run(["git", "worktree", "add", "--detach", "-q", str(base), args.baseline], cwd=ROOT,
                              capture_output=True, text=True)
        if made.returncode:
            raise SystemExit(f"error: --baseline {args.baseline}: {made.stderr.strip() or 'git worktree failed'}")
        try:
            trees = {"this checkout": ROOT, f"baseline {args.baseline}": base}
            for tree in trees.values():  # warm-up: FMU builds into each tree's cache
                _run(tree, args.scenario, extra)
            loop: dict[str, list[float]] = {k: [] for k in trees}
            whole: dict[str, list[float]] = {k: [] for k in trees}
            for r in range(args.rounds):
                for label, tree in (trees.items() if r % 2 == 0 else reversed(list(trees.items()))):
                    w, t = _run(tree, args.scenario, extra)
                    loop[label].append(w)
                    whole[label].append(t)
                print(f"round {r + 1}/{args.rounds}: " + ", ".join(f"{k} {v[-1]:.3f} s" for k, v in loop.items()),
                      flush=True)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(base)], cwd=ROOT, capture_output=True)
    print(f"\n{args.scenario}, stepping loop wall time (s), {args.rounds} alternated rounds, no log")
    for label in loop:
        print(f"  {label:<30} best {min(loop[label]):.3f}  median {statistics.median(loop[label]):.3f}  "
              f"(whole command: median {statistics.median(whole[label]):.2f})")
    a, b = loop.values()
    rec.put("this_loop_s", a)
    rec.put("baseline_loop_s", b)
    rec.put("ratio_best", min(a) / min(b))
    rec.put("ratio_median", statistics.median(a) / statistics.median(b))
    print(f"  ratio this / baseline: best {min(a) / min(b):.3f}, median {statistics.median(a) / statistics.median(b):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
