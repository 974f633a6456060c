"""The machine-readable output of a benchmark: the figures it prints, with its exact command line, the date (UTC),
the machine (cores, load average at start and at end) and the git revision it ran on.

A benchmark adds the options and records inside a ``with`` block::

    import record

    ap = argparse.ArgumentParser(...)
    record.add_options(ap)
    args = ap.parse_args()
    with record.Recording(args, "helix_ctc") as rec:
        ...
        rec.put("loop_parallel_s", best)          # a figure: a number, a string or a list of them

``--json FILE`` writes the recording to FILE, ``--record`` to ``benchmarks/results/NAME.json`` (the files
``python benchmarks/figures.py`` renders docs/figures.md from). Nothing is written when the benchmark fails: the
file is written whole (a temporary file beside it, renamed) at the end of a successful run, so an old figure is
never half-replaced. The lines the benchmark prints are kept too (``printed``), so a figure not yet put by name is
still in the file.
"""

from __future__ import annotations

import datetime as _dt
import io
import json
import os
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
# the code a benchmark measures: a figure recorded before a commit that changed these is stale
MEASURED_CODE = ("cosim", "delta", "fmus", "multibody", "benchmarks")
NOT_MEASURED = (":(exclude)benchmarks/results", ":(exclude)benchmarks/figures*.py")
"""git pathspecs of what lies in MEASURED_CODE but is not measured: the recorded results, the page's renderer."""
FORMAT = 1


def add_options(ap) -> None:
    """Add ``--json FILE`` and ``--record`` to a benchmark's argparse parser."""
    group = ap.add_mutually_exclusive_group()
    group.add_argument("--json", metavar="FILE", type=Path,
                       help="also write the figures, command, date, machine and git revision to FILE as JSON")
    group.add_argument("--record", action="store_true",
                       help=f"the same, to {RESULTS.relative_to(ROOT)}/NAME.json (what docs/figures.md renders)")


def load_average() -> list[float]:
    """The 1, 5 and 15 minute load averages (what ``uptime`` prints)."""
    return [round(x, 2) for x in os.getloadavg()]


def _git(*argv: str) -> str | None:
    try:
        out = subprocess.run(["git", "-C", str(ROOT), *argv], capture_output=True, text=True, check=False)
    except OSError:
        return None
    return out.stdout.rstrip("\n") if out.returncode == 0 else None


def revision() -> dict:
    """The commit checked out and the measured code's files that differ from it (other work in the checkout)."""
    changed = _git("status", "--porcelain", "--untracked-files=no", "--", *MEASURED_CODE, *NOT_MEASURED)
    return {"commit": _git("rev-parse", "HEAD"),
            "uncommitted": sorted(line[3:] for line in (changed or "").splitlines())}


class _Tee(io.TextIOBase):
    """Writes to the real stdout and keeps a copy."""

    def __init__(self, out):
        self.out, self.kept = out, io.StringIO()

    def write(self, s: str) -> int:
        self.kept.write(s)
        return self.out.write(s)

    def flush(self) -> None:
        self.out.flush()


class Recording:
    """One run of a benchmark; written as JSON on a successful exit from the ``with`` block when asked to."""

    def __init__(self, args, name: str):
        self.name = name
        target = getattr(args, "json", None)
        if getattr(args, "record", False):
            target = RESULTS / f"{name}.json"
        self.path = Path(target) if target is not None else None
        if self.path is not None and not self.path.parent.is_dir():
            sys.exit(f"{name}: --json {self.path}: the folder {self.path.parent} does not exist")
        self.figures: dict = {}
        self._tee = None

    def discard(self) -> None:
        """Write nothing at the end (the benchmark failed without raising: its exit code says so)."""
        self.path = None

    def put(self, key: str, value) -> None:
        """Record one figure (a number, a string, or a list or dict of them) under ``key``."""
        self.figures[key] = value

    def __enter__(self) -> "Recording":
        self.start = _dt.datetime.now(_dt.timezone.utc)
        self.load_start = load_average()
        self.revision = revision()
        if self.path is not None:
            self._tee = _Tee(sys.stdout)
            sys.stdout = self._tee
        return self

    def __exit__(self, kind, value, tb) -> bool:
        if self._tee is not None:
            sys.stdout = self._tee.out
        if kind is None and self.path is not None and self._tee is not None:
            self._write()
        return False

    def document(self) -> dict:
        """The JSON document: what ``--json`` writes."""
        return {
            "format": FORMAT,
            "benchmark": self.name,
            "source": "measured",
            "command": shlex.join(["python", _relative(sys.argv[0]), *sys.argv[1:]]),
            "date": self.start.strftime("%Y-%m-%dT%H:%M:%SZ"),
            "machine": {"cores": os.cpu_count(), "load_start": self.load_start, "load_end": load_average()},
            "revision": self.revision,
            "figures": self.figures,
            "printed": self._tee.kept.getvalue().splitlines() if self._tee is not None else [],
        }

    def _write(self) -> None:
        text = json.dumps(self.document(), indent=1, ensure_ascii=False) + "\n"
        fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.", dir=self.path.parent)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
            os.replace(tmp, self.path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        print(f"recorded: {self.path}", file=sys.stderr)


def _relative(script: str) -> str:
    """The benchmark's path as typed from the repository root."""
    path = Path(script).resolve()
    try:
        return str(path.relative_to(ROOT))
    except ValueError:
        return script


def measured(args, name: str, measure) -> int:
    """``measure(args, rec)`` inside a :class:`Recording` named ``name``: its exit code; a non-zero one (the
    benchmark failed without raising) writes nothing."""
    with Recording(args, name) as rec:
        code = measure(args, rec)
        if code:
            rec.discard()
    return code
