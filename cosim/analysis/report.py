"""Reports of a run log: figures and a markdown summary, and the controller table (thesis Table 5).

``make_report(run)`` reads a run's MCAP log (:mod:`cosim.io.runlog`) and writes, into
``<log stem>_report/`` next to the log unless told otherwise:

- ``path_3d.png``: the platform path, desired vs actual, in 3D;
- ``position.png``: x, y, z desired vs actual over time;
- ``errors.png``: position error per axis and, when the log has them, velocity error
  per axis (actual ``plant.v`` vs ``traj.v_ref``), scaled to mm / um / nm / pm / fm as suits
  (tick labels are plain numbers: no offset, no exponent);
- ``joints.png``: joint-space tracking: each joint ``q[i]`` of the plant against its reference
  ``q_ref[i]`` (the IK's output, else the controller's input), and the error, in mm or deg;
- ``efforts.png``: the actuator efforts ``u[1..3]`` in the log's unit;
- ``report.md``: scenario, robot, status, duration, per-axis RMSE and max error (with
  its time) and the figures.

With a robot recording (``recording``, ``maps`` and ``compare``'s options), also one
``recording_<signal>.png`` per mapped signal: the run's signal over the recording's (shifted by the
offset given or estimated) and the residual run - recording, the comparison ``compare`` makes
(:func:`cosim.analysis.recording_compare.compared_traces`; the figures:
:mod:`cosim.analysis.recording_figures`), and a section of ``report.md`` with its numbers.

(the signals: :mod:`cosim.analysis.tracking`; the figures: :mod:`cosim.analysis.figures`)

``controller_table(runs)`` (:mod:`cosim.analysis.table`) gives RMSE per axis per run, in m and um, as markdown,
with the thesis's Table 5 values as extra, labelled rows when the runs are the thesis
helix.

The signals compared are those of the ``compare`` section of the scenario attached to
the log (``plant.p`` vs ``traj.p_ref`` when there is none). Errors are ``actual -
reference`` at the time stamps both signals carry: for a single-rate run that is the
start sample and every step, the samples the run's own summary
(:class:`cosim.observers.recorders.ErrorObserver`) used, so the RMSE here equals the summary's.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from ..errors import CosimError, utf8, written_by_rename
from ..io.output import output_dir
from ..io.runlog import RunLog
from ..observers.stats import ErrorStats
from .compare import Comparison
from .figures import figures
from .recording_compare import compared_traces
from .recording_figures import figure_key, recording_figures
from .tracking import Tracking, scenario_doc, tracking

__all__ = ["Report", "make_report"]


@dataclass
class Report:
    """Files written for one run and the numbers in them."""

    run: str  # the log's path
    name: str
    robot: str | None
    status: str
    duration: float  # s simulated (last - first stamp)
    out_dir: Path
    markdown: Path
    figures: dict[str, Path]
    position: list[ErrorStats]
    velocity: list[ErrorStats] = field(default_factory=list)
    source: str = ""
    joints: list[ErrorStats] = field(default_factory=list)
    recording: Comparison | None = None  # against a robot recording (report --recording)

    def as_dict(self) -> dict[str, Any]:
        def axes(stats: list[ErrorStats]) -> list[dict[str, Any]]:
            return [s.as_dict(*_AXIS_KEYS, name="axis") for s in stats]

        out = {"run": self.run, "name": self.name, "robot": self.robot, "status": self.status,
               "duration_s": self.duration, "out_dir": str(self.out_dir), "markdown": str(self.markdown),
               "figures": {k: str(v) for k, v in self.figures.items()}, "compared": self.source,
               "position": axes(self.position), "velocity": axes(self.velocity), "joints": axes(self.joints)}
        if self.recording is not None:  # only then: a report without a recording reads as it always has
            out["recording"] = self.recording.as_dict()
        return out


# one axis in ``report --json`` (its keys since the first release: name as axis; no tolerance)
_AXIS_KEYS = ("name", "actual", "reference", "unit", "rmse", "max_error", "t_max", "samples")


def _stats_table(stats: list[ErrorStats], unit: str) -> list[str]:
    """Markdown rows; lengths (m, m/s) also in um (um/s), other units as logged."""
    micro = unit in ("m", "m/s")
    u, small = unit or "-", f"u{unit}" if micro else unit or "-"
    rows = [f"| axis | actual - reference | RMSE ({u}) |" + (f" RMSE ({small}) |" if micro else "")
            + f" max abs error ({small}) | at t (s) |", "|---|---|---|" + ("---|" if micro else "") + "---|---|"]
    scale = 1e6 if micro else 1.0
    for s in stats:
        rows.append(f"| {s.name} | {s.actual} - {s.reference} | {s.rmse:.6e} |"
                    + (f" {s.rmse * scale:.4g} |" if micro else "") + f" {s.max_error * scale:.4g} | {s.t_max:.4g} |")
    return rows


def _markdown(tr: Tracking, rep: Report) -> str:
    run = tr.run
    sc = run.metadata.get("scenario", {})
    outcome = run.metadata.get("outcome", {})
    att, doc = scenario_doc(run)
    p = tr.position
    lines = [f"# Run report: {rep.name}", ""]
    desc = doc.get("description")
    if desc:
        lines += [str(desc), ""]
    status = rep.status
    if outcome.get("completed_steps"):
        status += f", {outcome['completed_steps']} steps"
    if outcome.get("message"):
        status += f": {outcome['message']}"
    step = sc.get("step_s")
    rows = [("scenario", f"{rep.name}" + (f" (`{sc['file']}`)" if sc.get("file") else "")),
            ("robot", rep.robot or "-"),
            ("status", status),
            ("simulated", f"{p.t[0]:.6g} .. {p.t[-1]:.6g} s ({rep.duration:.6g} s"
                          + (f", step {float(step) * 1e3:.6g} ms" if step else "") + f", {len(p.t)} samples)"),
            ("log", f"`{run.path}`"),
            ("compared", f"{', '.join(p.actual_names)} vs {', '.join(p.reference_names)} ({tr.source})")]
    lines += ["| | |", "|---|---|"] + [f"| {k} | {v} |" for k, v in rows] + [""]
    lines += ["## Position error" if tr.is_platform else "## Error", "",
              f"Error = actual - reference at the {len(p.t)} time stamps both carry (the start sample and every "
              "step, as in the run's summary).", ""]
    lines += _stats_table(rep.position, p.unit) + [""]
    if rep.velocity:
        lines += ["## Velocity error", ""] + _stats_table(rep.velocity, tr.velocity.unit) + [""]
    if rep.joints:
        lines += ["## Joint error", ""] + _stats_table(rep.joints, tr.joints.unit) + [""]
    if rep.recording is not None:
        lines += _recording_section(rep.recording)
    lines += ["## Figures", ""]
    captions = {"path_3d": "Platform path, desired vs actual", "position": "Position, desired vs actual",
                "errors": "Position and velocity errors", "joints": "Joint-space tracking, desired vs actual",
                "efforts": "Actuator efforts"}
    for d in rep.recording.diffs if rep.recording is not None else ():
        captions[figure_key(d.name)] = f"{d.name} against the recording's {d.reference}, and the residual"
    for key, path in rep.figures.items():
        lines += [f"### {captions.get(key, key)}", "", f"![{captions.get(key, key)}]({path.name})", ""]
    if tr.efforts is None:
        lines += ["No actuator efforts (`u[1..3]`) in the log.", ""]
    return "\n".join(lines)


def _recording_section(cmp: Comparison) -> list[str]:
    """report.md's rows of the run against a recording: the offset, the notes, and per signal the residual."""
    lines = ["## Against a recording", "",
             f"Recording `{cmp.b}`; offset (recording - run) {cmp.offset + 0.0:.9g} s, {cmp.offset_how}. Residual = run - "
             "recording at the run's time stamps inside the recording (shifted by the offset; linear interpolation "
             f"between its samples), over run time {cmp.t_start:.6g} .. {cmp.t_stop:.6g} s, as `compare` computes it.",
             ""]
    lines += [f"- {n}" for n in cmp.notes] + ([""] if cmp.notes else [])
    lines += ["| run signal | recorded | unit | RMSE | max abs residual | at t (s) | samples | tolerance |",
              "|---|---|---|---|---|---|---|---|"]
    for d in cmp.diffs:
        tol = "-" if d.tolerance is None else f"{d.tolerance:.4g}" + ("" if d.ok else " (exceeded)")
        lines.append(f"| {d.name} | {d.reference} | {d.unit or '-'} | {d.rmse:.6e} | {d.max_error:.6e} | "
                     f"{d.t_max:.4g} | {d.samples} | {tol} |")
    return lines + [""]


def make_report(run: RunLog | str | Path, out_dir: str | Path | None = None, recording: str | Path | None = None,
                maps: Mapping[str, str] | None = None, **options: Any) -> Report:
    """Write the figures and ``report.md`` of one run; return what was written.

    Parameters
    ----------
    run
        A run log path (MCAP written by :mod:`cosim.observers.mcap_log`) or a :class:`RunLog`.
    out_dir
        Where to write (created); default ``<log stem>_report/`` next to the log.
    recording, maps, options
        A robot recording, run signal -> recorded signal, and the keyword arguments of
        :func:`cosim.analysis.recording_compare.compare_recording` (``units``, ``time``, ``time_origin``,
        ``align``, ``offset``, ``max_offset``, ``tolerances``): the run against it, drawn per mapped signal.

    Raises
    ------
    CosimError
        The log cannot be read; ReportError when a compared signal is missing (named); RecordingError for the
        recording; a map without a recording. Every check is made before the first file is written.
    """
    if recording is None and (maps or options):
        # Refused (correctness): options for a comparison without its recording would be dropped silently
        raise CosimError(f"{', '.join(['maps'] * bool(maps) + sorted(options))}: need a recording to compare with")
    tr = tracking(run)
    log = tr.run
    against = compared_traces(log, recording, maps or {}, **options) if recording is not None else None
    out = output_dir(Path(out_dir) if out_dir is not None else log.path.with_name(f"{log.path.stem}_report"))
    title = log.name
    p = tr.position
    drawn = figures(tr, title, out)
    if against is not None:
        drawn.update(recording_figures(tr, *against, title, out))
    rep = Report(str(log.path), title, log.robot, log.status, float(p.t[-1] - p.t[0]), out, out / "report.md",
                 drawn, tr.position_stats(), tr.velocity_stats(), tr.source, tr.joint_stats(),
                 against[0] if against is not None else None)
    with written_by_rename(rep.markdown) as tmp:
        tmp.write_text(utf8(_markdown(tr, rep)), encoding="utf-8")
    return rep
