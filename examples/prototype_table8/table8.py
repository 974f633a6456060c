"""The prototype paper's Table 8 (seed 004) against the scenario rotary_z_steps_pid, and what could explain the
difference: docs/prototype_table8.md shows what this prints.

    python -m cosim run scenarios/rotary_z_steps_pid.yaml --out runs/rotary_z_steps_pid.mcap
    python examples/prototype_table8/table8.py runs/rotary_z_steps_pid.mcap

Table 8 (``table8.csv`` beside this file, read by :func:`cosim.io.recordings.read_recording`) gives, for each of
the experiment's 16 rows (home, 14 steps, home), the desired and the detected angle of each motor, in whole
degrees. The scenario moves the platform through the same three poses (home z = -411 mm, -561 mm, -311 mm) under
PID; the settled angle at a pose is ``plant.q`` at the last instant of the dwell at that pose (the reference
``ik.q_ref`` still unchanged). Each row of the table is compared with the settled angle of the scenario's pose
whose reference is the row's desired angle (within :data:`MATCH_DEG`).

Two explanations are fitted per joint by linear least squares (numpy's ``lstsq``; standard errors from the
residual variance and ``(X^T X)^-1``, as for any linear regression):

- ``sensor``: detected = a + b * simulated (an angle sensor's zero offset ``a`` and gain ``b``);
- ``compliance``: detected = simulated + c * (u - u_home) (a joint compliance ``c``, deg/(N*m),
  deflecting under the change of the holding torque ``u`` = ``ctl.u`` from the home pose, where the sensor reads 0).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cosim.io.recordings import read_recording
from cosim.io.runlog import read_run

HERE = Path(__file__).resolve().parent
TABLE = HERE / "table8.csv"
MATCH_DEG = 1.0  # a row's desired angle and the scenario's reference differ by < 0.2 deg (IK of the same poses)
STILL_RAD = 1e-12  # the reference is unchanged between two samples (held by the waypoints' dwell)


def read_table8(path: Path = TABLE) -> dict[str, np.ndarray]:
    """``q_ref``, ``q`` and ``error`` of the table, each (16, 3) in deg, and ``step`` (16,)."""
    specs = {f"{k}[{i}]": f"{k}[{i}]" for k in ("q_ref", "q", "error") for i in (1, 2, 3)}
    rec = read_recording(path, specs, units={n: "deg" for n in specs})
    out = {k: np.column_stack([rec.values[f"{k}[{i}]"] for i in (1, 2, 3)]) for k in ("q_ref", "q", "error")}
    out["step"] = rec.times["q[1]"]
    return out


def settled(log: Path) -> dict[str, np.ndarray]:
    """The scenario's settled poses: ``q_ref``, ``q`` (deg) and ``u`` (N*m), each (n_poses, 3), at the last sample of
    each dwell (the reference unchanged since the sample before and changing at the next), and their times ``t``."""
    run = read_run(log)
    t, q_ref = run.joints("ik.q_ref")
    _, q = run.joints("plant.q")
    _, u = run.joints("ctl.u")
    still = np.all(np.abs(np.diff(q_ref, axis=0)) < STILL_RAD, axis=1)  # sample k+1 equals sample k
    ends = [k + 1 for k in range(len(still)) if still[k] and (k + 1 == len(still) or not still[k + 1])]
    return {"t": t[ends], "q_ref": np.degrees(q_ref[ends]), "q": np.degrees(q[ends]), "u": u[ends]}


@dataclass(frozen=True)
class Fit:
    """One joint's least-squares fit: parameters, standard errors, their correlation (2 parameters) and the RMS of
    the residual before (no correction) and after."""

    params: np.ndarray
    stderr: np.ndarray
    corr: float
    rms_before: float
    rms_after: float
    dof: int


def lstsq_fit(X: np.ndarray, y: np.ndarray, before: np.ndarray) -> Fit:
    """``y ~ X @ p``; ``before``: the residual without the correction (for its RMS)."""
    p, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ p
    dof = len(y) - X.shape[1]
    cov = (r @ r / dof) * np.linalg.inv(X.T @ X)
    se = np.sqrt(np.diag(cov))
    corr = float(cov[0, 1] / (se[0] * se[1])) if len(p) == 2 else float("nan")
    return Fit(p, se, corr, float(np.sqrt(np.mean(before ** 2))), float(np.sqrt(np.mean(r ** 2))), dof)


def compare(log: Path, table: Path = TABLE) -> dict:
    """Table 8 against the run's settled angles: per joint the simulated angle of each row, the residual (detected
    minus simulated: RMS, max), both fits, and ``floor``: the RMS of the residual about its mean at each desired
    angle, which no correction depending on the pose alone can go below (the rows hold three poses)."""
    tab, sim = read_table8(table), settled(log)
    rows = []
    for d in tab["q_ref"][:, 0]:
        match = np.flatnonzero(np.abs(sim["q_ref"][:, 0] - d) < MATCH_DEG)
        if len(match) == 0:
            raise SystemExit(f"error: {log}: no settled pose of the run has the reference {d} deg of Table 8")
        rows.append(match[-1])
    q_sim, u_sim = sim["q"][rows], sim["u"][rows]
    home = np.flatnonzero(np.abs(sim["q_ref"][:, 0]) < MATCH_DEG)[-1]
    out = {"sim": q_sim, "table": tab, "poses": sim, "joints": []}
    for j in range(3):
        det, s = tab["q"][:, j], q_sim[:, j]
        resid = det - s
        sensor = lstsq_fit(np.column_stack([np.ones_like(s), s]), det, resid)
        du = u_sim[:, j] - sim["u"][home, j]
        compliance = lstsq_fit(du[:, None], resid, resid)
        levels = [resid[tab["q_ref"][:, j] == d] for d in np.unique(tab["q_ref"][:, j])]
        floor = float(np.sqrt(sum(np.sum((v - v.mean()) ** 2) for v in levels) / len(resid)))
        out["joints"].append({"resid": resid, "sensor": sensor, "compliance": compliance, "floor": floor})
    return out


def report(result: dict) -> str:
    """The figures docs/prototype_table8.md quotes, as printed lines."""
    poses = result["poses"]
    lines = ["settled poses of the run (reference, angle; deg; holding torque, N*m):"]
    for t, r, q, u in zip(poses["t"], poses["q_ref"][:, 0], poses["q"][:, 0], poses["u"][:, 0]):
        lines.append(f"  t = {t:.3f} s: q_ref {r:.4f}, q {q:.4f}, u {u:.4f}")
    for j, jr in enumerate(result["joints"], start=1):
        r, s, c = jr["resid"], jr["sensor"], jr["compliance"]
        lines.append(f"joint {j}: detected - simulated: RMS {s.rms_before:.3f} deg, max {np.max(np.abs(r)):.3f} deg; "
                     f"scatter within the poses (no model of the pose goes below): RMS {jr['floor']:.3f} deg")
        lines.append(f"  sensor: offset {s.params[0]:.3f} +- {s.stderr[0]:.3f} deg, gain {s.params[1]:.4f} +- "
                     f"{s.stderr[1]:.4f}, correlation {s.corr:.3f}, dof {s.dof}: RMS after {s.rms_after:.3f} deg")
        lines.append(f"  compliance: {c.params[0]:.2f} +- {c.stderr[0]:.2f} deg/(N*m)"
                     f", dof {c.dof}: RMS after {c.rms_after:.3f} deg")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log", type=Path, help="the log of a run of scenarios/rotary_z_steps_pid.yaml")
    ap.add_argument("--table", type=Path, default=TABLE, help="Table 8 as CSV (default: table8.csv beside this)")
    args = ap.parse_args(argv)
    print(report(compare(args.log, args.table)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
