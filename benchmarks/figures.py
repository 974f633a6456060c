"""Render docs/figures.md's tables of benchmark figures from the benchmarks' recorded JSON (benchmarks/results/).

    python benchmarks/figures.py            # rewrite the generated tables in docs/figures.md, list the stale rows
    python benchmarks/figures.py --check    # exit 1 when the page differs from what the JSON renders

Each generated table sits between two marker comments in the page, ``<!-- figures: NAME -->`` and
``<!-- /figures: NAME -->``; everything outside them is hand-written and kept as it is. The tables' layout, the
rows' "what" and targets are the rendering spec (``benchmarks/figures_spec.py``); the measured figures, the command
that measured them, its date and the machine's load come from one JSON file per benchmark run
(``benchmarks/results/NAME.json``), written by the benchmark itself::

    python benchmarks/master_overhead.py --rounds 15 --record     # writes benchmarks/results/master_overhead.json
    python benchmarks/figures.py                                  # renders it into docs/figures.md

A JSON is either *measured* (``"source": "measured"``, written by ``benchmarks/record.py``: its ``figures`` are
formatted into the row's template in the spec) or *transcribed* (``"source": "transcribed from docs/figures.md"``:
the cells' text as the page gave it, with the date it was measured), shown as such in the page's "when" column.
A row is stale when its figures are older than ``--stale-days``, or were recorded on a revision of the measured code
(``cosim``, ``delta``, ``fmus``, ``multibody``, ``benchmarks``) other than the checked-out one or with uncommitted
changes to it (other work in a shared checkout), or when the revision is unknown (transcribed); the script lists
them and leaves them in the page, dated.

Plugging in a benchmark that records its own JSON: ``benchmarks/logged_run.py`` (row ``logged-vs-unlogged`` of
the ``speed`` table, transcribed for now in ``benchmarks/results/logged_run.json``) writes a flat JSON of its own
(its figures by name beside ``command``, ``date`` and ``load``), which is read as measured, its numbers as figures;
the row's template in ``benchmarks/figures_spec.py`` already names them. So:

1. ``python benchmarks/logged_run.py --rounds 5 --json benchmarks/results/logged_run.json`` (it replaces the
   transcription);
2. ``python benchmarks/figures.py``, and commit the page with the JSON.

If the benchmark renames a figure, the rendering stops with a one-line error naming the JSON, the row and the
missing key: rename it in the row's template. Another benchmark is plugged in the same way: a row names the
JSON's stem as its result, with a ``templates`` entry per measured column (``str.format`` over the figures; a list
of numbers prints as a range) and, for a target, ``met_if=(figure, limit)``.

Any benchmark's JSON with ``format``, ``source``, ``command``, ``date`` (UTC, ``YYYY-MM-DD...``), ``machine``
(``cores``, ``load_start``, ``load_end``: the three load averages) and ``figures`` fits; ``revision.commit`` makes
staleness checkable.
"""

from __future__ import annotations

import argparse
import datetime as dt
import difflib
import json
import os
import re
import string
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from figures_spec import TABLES, Table  # noqa: E402
from record import MEASURED_CODE, NOT_MEASURED, ROOT  # noqa: E402

PAGE = ROOT / "docs" / "figures.md"
RESULTS = ROOT / "benchmarks" / "results"
COMMAND = "python benchmarks/figures.py"
BEGIN = re.compile(r"^<!-- figures: ([\w-]+) .*-->$")


class FiguresError(Exception):
    """Bad input: a one-line message naming the file and what was wrong."""


class _Formatter(string.Formatter):
    """``str.format`` where a list of numbers is a range: ``[229.4, 235.1]`` with ``.0f`` gives ``229-235``, and
    ``[537.2, 537.4]`` gives ``537`` (equal at the printed precision); ``None`` (a figure the benchmark could not
    measure that time) prints as ``-``."""

    def format_field(self, value, spec: str) -> str:
        if value is None:
            return "-"
        if isinstance(value, list) and value and all(isinstance(v, (int, float)) for v in value):
            texts = [format(v, spec) for v in (min(value), max(value))]
            return texts[0] if texts[0] == texts[1] else "-".join(texts)
        return super().format_field(value, spec)


FORMATTER = _Formatter()


@dataclass(frozen=True)
class Result:
    """One benchmark run's JSON."""
    name: str
    path: Path
    doc: dict

    @property
    def transcribed(self) -> bool:
        return self.doc["source"] != "measured"

    def date(self, row_key: str | None = None) -> str:
        row = self.doc.get("rows", {}).get(row_key, {}) if row_key else {}
        return str(row.get("date", self.doc["date"]))[:10]

    def command(self, row_key: str | None = None) -> str:
        row = self.doc.get("rows", {}).get(row_key, {}) if row_key else {}
        return row.get("command", self.doc["command"])

    def how(self, row_key: str, note: str = "") -> str:
        """The "how" cell: the command (with the spec's note), or a transcribed row's cell as the page gave it."""
        verbatim = self.doc.get("rows", {}).get(row_key, {}).get("how")
        sep = "" if note[:1] in (",", ";") else " "
        return verbatim if verbatim else f"`{self.command(row_key)}`" + (sep + note if note else "")

    def when(self, row_key: str | None = None) -> str:
        if self.transcribed:
            return f"{self.date(row_key)}, transcribed"
        m = self.doc["machine"]
        if "load_start" not in m:
            return f"{self.date()}, {m.get('load')}"
        loads = [m["load_start"][0], m["load_end"][0]]
        return f"{self.date()}, load {FORMATTER.format_field(loads, '.1f')} on {m['cores']} cores"


def load_results(folder: Path) -> dict[str, Result]:
    """Every ``*.json`` in ``folder``, checked for the keys the rendering reads."""
    results = {}
    for path in sorted(folder.glob("*.json")):
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise FiguresError(f"{path}: not readable JSON: {exc}") from None
        if not isinstance(doc, dict):
            raise FiguresError(f"{path}: a JSON object was expected, not {type(doc).__name__}")
        if "source" not in doc:
            doc = _flat(doc)
        need = ["source", "command", "date"] + (["machine", "figures"] if doc["source"] == "measured" else ["rows"])
        missing = [k for k in need if k not in doc]
        if missing:
            raise FiguresError(f"{path}: missing {', '.join(missing)}")
        if not re.match(r"\d{4}-\d\d-\d\d", str(doc["date"])):
            raise FiguresError(f"{path}: date {doc['date']!r} is no YYYY-MM-DD date")
        results[path.stem] = Result(path.stem, path, doc)
    return results


def _flat(doc: dict) -> dict:
    """A benchmark's own flat JSON (figures, ``command``, ``date`` and ``load`` side by side, as
    ``benchmarks/logged_run.py --json`` writes) read as a measured one: its numbers are its figures."""
    figures = {k: v for k, v in doc.items() if v is None or isinstance(v, (int, float)) and not isinstance(v, bool)}
    return {"format": 1, "source": "measured", "command": doc.get("command"), "date": doc.get("date"),
            "machine": {"load": doc.get("load", "load not recorded")}, "revision": None, "figures": figures}


def _cell(table: Table, row, column: str, res: Result) -> str:
    if column in row.cells:
        return row.cells[column]
    where = f"{res.path.name}, table {table.name}, row {row.key}, column {column!r}"
    if res.transcribed:
        cells = res.doc["rows"].get(row.key, {}).get("cells", {})
        if column not in cells:
            raise FiguresError(f"{res.path}: no transcribed cell for {where}")
        return cells[column]
    template = row.templates.get(column)
    if template is None:
        raise FiguresError(f"benchmarks/figures_spec.py: {res.path.name} is measured but the spec has no template for "
                           f"table {table.name}, row {row.key}, column {column!r}")
    try:
        return FORMATTER.format(template, **res.doc["figures"])
    except KeyError as exc:
        raise FiguresError(f"{res.path}: no figure {exc} (the template of {where})") from None
    except (ValueError, TypeError, IndexError) as exc:
        raise FiguresError(f"{res.path}: {exc} (the template of {where})") from None


def _verdict(row, res: Result) -> str:
    if row.met_if is None or res.transcribed:
        return ""
    key, op, limit = row.met_if if len(row.met_if) == 3 else (row.met_if[0], "<=", row.met_if[1])
    value = res.doc["figures"]
    for part in key.split("."):
        if not isinstance(value, dict) or part not in value:
            raise FiguresError(f"{res.path}: no figure {key!r} (the target check of row {row.key})")
        value = value[part]
    if value is None:
        return ""
    met = value <= limit if op == "<=" else value >= limit
    return "met: " if met else "**not met**: "


def render_table(table: Table, results: dict[str, Result]) -> str:
    """The markdown of one generated table, with each row's command and date (or the table's, below it)."""

    def result(name: str) -> Result:
        if name not in results:
            raise FiguresError(f"{name}.json: missing from the results folder (table {table.name})")
        return results[name]

    per_row = table.result is None
    columns = list(table.columns) + (["how", "when"] if per_row else [])
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for row in table.rows:
        res = result(row.result or table.result)
        cells = [_cell(table, row, c, res) for c in table.columns]
        first = (table.columns.index(row.met_column) if row.met_column else
                 next((i for i, c in enumerate(table.columns) if c not in row.cells), None))
        if first is not None:
            cells[first] = _verdict(row, res) + cells[first]
        if per_row:
            cells += [res.how(row.key, row.how_note), res.when(row.key)]
        lines.append("| " + " | ".join(c.replace("\n", " ") for c in cells) + " |")
    if not per_row:
        res = result(table.result)
        lines += ["", f"From `{res.command()}` ({res.when()})."]
    return "\n".join(lines)


def render_page(text: str, results: dict[str, Result], page: Path) -> str:
    """``text`` with every marked table replaced by its rendering; the rest untouched."""
    out, lines, i, seen = [], text.split("\n"), 0, set()
    specs = {t.name: t for t in TABLES}
    while i < len(lines):
        out.append(lines[i])
        m = BEGIN.match(lines[i])
        i += 1
        if not m:
            continue
        name = m.group(1)
        if name not in specs:
            raise FiguresError(f"{page}:{i}: table {name!r} is not in benchmarks/figures_spec.py")
        end = f"<!-- /figures: {name} -->"
        try:
            j = lines.index(end, i)
        except ValueError:
            raise FiguresError(f"{page}:{i}: no {end} after the table's start marker") from None
        out += [render_table(specs[name], results), end]
        seen.add(name)
        i = j + 1
    missing = [t.name for t in TABLES if t.name not in seen]
    if missing:
        raise FiguresError(f"{page}: no marker <!-- figures: NAME ... --> for {', '.join(missing)}")
    _check_all_used(results)
    return "\n".join(out)


def _check_all_used(results: dict[str, Result]) -> None:
    """Every JSON, and every transcribed row in one, is rendered somewhere: the folder holds nothing the page does
    not show."""
    used = {(r.result or t.result, r.key) for t in TABLES for r in t.rows}
    for name, res in results.items():
        if not any(n == name for n, _ in used):
            raise FiguresError(f"{res.path}: no row of benchmarks/figures_spec.py renders it")
        if res.transcribed:
            extra = sorted(k for k in res.doc["rows"] if (name, k) not in used)
            if extra:
                raise FiguresError(f"{res.path}: transcribed rows no table renders: {', '.join(extra)}")


def _changed_since(commit: str) -> list[str] | None:
    proc = subprocess.run(["git", "-C", str(ROOT), "diff", "--name-only", commit, "HEAD", "--", *MEASURED_CODE,
                           *NOT_MEASURED],
                          capture_output=True, text=True, check=False)
    return proc.stdout.split() if proc.returncode == 0 else None


def stale_rows(results: dict[str, Result], days: float, today: dt.date) -> list[str]:
    """One line per stale row: table, row, why."""
    lines, changed = [], {}
    for table in TABLES:
        for row in table.rows:
            res = results.get(row.result or table.result)
            if res is None:
                continue
            why = []
            age = (today - dt.date.fromisoformat(res.date(row.key))).days
            if age > days:
                why.append(f"{age} days old")
            commit = (res.doc.get("revision") or {}).get("commit")
            dirty = (res.doc.get("revision") or {}).get("uncommitted") or []
            if dirty:
                why.append(f"recorded with {len(dirty)} uncommitted files of the measured code")
            if commit is None:
                why.append("revision unknown (transcribed)" if res.transcribed else "revision unknown")
            else:
                if commit not in changed:
                    changed[commit] = _changed_since(commit)
                files = changed[commit]
                if files is None:
                    why.append("recorded on a revision not in this history")
                elif files:
                    why.append(f"measured code changed since ({len(files)} files, e.g. {files[0]})")
            if why:
                lines.append(f"{table.name} / {row.key} ({res.path.name}): {'; '.join(why)}")
    return lines


def _write(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog="\n\n".join(__doc__.split("\n\n")[1:]),
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="change nothing; exit 1 when the page differs from its JSON")
    ap.add_argument("--stale-days", type=float, default=14, metavar="N",
                    help="a row older than N days is listed as stale (default 14)")
    ap.add_argument("--page", type=Path, default=PAGE, help="the page (default docs/figures.md)")
    ap.add_argument("--results", type=Path, default=RESULTS, help="the JSON folder (default benchmarks/results)")
    args = ap.parse_args(argv)
    try:
        text = args.page.read_text(encoding="utf-8")
        results = load_results(args.results)
        rendered = render_page(text, results, args.page)
    except OSError as exc:
        print(f"figures: {exc.filename}: {exc.strerror}", file=sys.stderr)
        return 2
    except FiguresError as exc:
        print(f"figures: {exc}", file=sys.stderr)
        return 2
    if args.check:
        if rendered == text:
            return 0
        diff = difflib.unified_diff(text.splitlines(), rendered.splitlines(), str(args.page), "rendered", n=0,
                                    lineterm="")
        print(f"{args.page} differs from what {args.results} renders (run {COMMAND}):", file=sys.stderr)
        print("\n".join(list(diff)[:40]), file=sys.stderr)
        return 1
    if rendered != text:
        _write(args.page, rendered)
        print(f"rendered {args.page}")
    stale = stale_rows(results, args.stale_days, dt.datetime.now(dt.timezone.utc).date())
    print(f"{len(stale)} stale rows (older than {args.stale_days:g} days or not measured on this revision):")
    for line in stale:
        print("  " + line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
