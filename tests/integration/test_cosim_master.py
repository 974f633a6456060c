"""The master on tiny FMUs: exact recurrences, MCAP contents, failures, Ctrl-C, recovery."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import orjson
import pytest
from cli_helpers import wait_for
from fmu_helpers import SLOW_SCENARIO

from cosim.errors import AlgebraicLoopError, FMIError, WiringError
from cosim.observers.recorders import Probe
from cosim.run import run_scenario
from cosim.engine.scenario import load_scenario

pytestmark = pytest.mark.integration
ROOT = Path(__file__).resolve().parents[2]
# The recurrences below are evaluated in the same float64 operations as the FMUs,
# in the same order: the only difference allowed is rounding, far below 1e-12.
EXACT = 1e-12

LOOP = """
name: loop
components:
  ctl: {{path: "{{CosimTGain}}", parameters: {{k: -5.0}}}}
  plant: {{path: "{{CosimTIntegrator}}", parameters: {{x0: 0.5}}, step_multiple: {m}}}
connections:
  - {{from: plant.x, to: ctl.u}}
  - {{from: ctl.y, to: plant.u}}
time: {{stop: {stop}, step: 0.001}}
algorithm: {alg}
logging: {{signals: all}}
"""


def _read_mcap(path: Path):
    """(summary, messages by topic, a component channel's as one per sample); ``_log_time`` is the
    simulation time of the sample (the log's time offset removed; a block's samples: from their ``t``)."""
    from mcap.reader import make_reader

    from cosim.io.runlog import samples, time_offset_ns

    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        offset = time_offset_ns({m.name: dict(m.metadata) for m in reader.iter_metadata()})
        msgs: dict[str, list[dict]] = {}
        for schema, channel, message in reader.iter_messages():
            decoded = orjson.loads(message.data)
            if channel.metadata.get("layout") == "blocks":
                msgs.setdefault(channel.topic, []).extend(s | {"_log_time": round(s["t"] * 1e9)}
                                                          for s in samples(decoded))
            else:
                msgs.setdefault(channel.topic, []).append(decoded | {"_log_time": message.log_time - offset})
    return summary, msgs


def test_gauss_seidel_matches_recurrence_and_log(write_scenario, tmp_path):
    path = write_scenario(LOOP.format(m=1, stop=0.5, alg="gauss_seidel"))
    probe = Probe(["plant.x", "ctl.y"])
    out = tmp_path / "run.mcap"
    res = run_scenario(load_scenario(path), out=out, observers=[probe])
    # Gauss-Seidel, plant (no feedthrough) first: x_{n+1} = x_n + h u_n, then u_{n+1} = -5 x_{n+1}.
    # The test gain computes y only in do_step, so u_0 is its start value 0.
    x, u, h = 0.5, 0.0, 0.001
    for n, value in enumerate(probe.values["plant.x"]):
        assert abs(value - x) <= EXACT, f"step {n}: master {value} vs recurrence {x}"
        x = x + h * u
        u = -5.0 * x
    assert res.steps == 500, f"steps {res.steps} vs 500"

    summary, msgs = _read_mcap(out)
    for ch in summary.channels.values():
        schema = summary.schemas.get(ch.schema_id)
        assert schema is not None, f"channel {ch.topic} has no schema"
        assert orjson.loads(schema.data).get("title"), f"schema of {ch.topic} has no title"
    plant, ctl = msgs["/plant"], msgs["/ctl"]
    assert len(plant) == 501 and len(ctl) == 501, f"messages plant {len(plant)}, ctl {len(ctl)} vs 501 each"
    # logged outputs equal what the master exchanged (the probe read the same buffers after each step)
    for n, (m, v) in enumerate(zip(plant, probe.values["plant.x"])):
        assert m["x"] == v, f"step {n}: logged plant.x {m['x']} vs exchanged {v}"
    # the controller's logged input is the plant's output at the same stamp (Gauss-Seidel)
    for m_p, m_c in zip(plant[1:], ctl[1:]):
        assert m_c["u"] == m_p["x"], f"t={m_c['t']}: ctl.u {m_c['u']} vs plant.x {m_p['x']}"
    # the plant's input over a step is the controller's output at the previous stamp
    for prev_c, m_p in zip(ctl[:-1], plant[1:]):
        assert m_p["u"] == prev_c["y"], f"t={m_p['t']}: plant.u {m_p['u']} vs previous ctl.y {prev_c['y']}"
    stamps = [m["_log_time"] for m in plant]
    assert stamps == [k * 1_000_000 for k in range(501)], "plant stamps are not the integer-ns grid"


def test_jacobi_matches_recurrence(write_scenario):
    path = write_scenario(LOOP.format(m=1, stop=0.2, alg="jacobi"))
    probe = Probe(["plant.x"])
    run_scenario(load_scenario(path), log=False, observers=[probe])
    # Jacobi: both read the previous macro step's outputs: x' = x + h y, y' = -5 x
    x, y, h = 0.5, 0.0, 0.001  # y_0 = 0: the test gain computes only in do_step
    for n, value in enumerate(probe.values["plant.x"]):
        assert abs(value - x) <= EXACT, f"step {n}: master {value} vs recurrence {x}"
        x, y = x + h * y, -5.0 * x


def test_multirate_plant_steps_every_other_base_step(write_scenario, tmp_path):
    path = write_scenario(LOOP.format(m=2, stop=0.1, alg="gauss_seidel"))
    out = tmp_path / "mr.mcap"
    run_scenario(load_scenario(path), out=out)
    _, msgs = _read_mcap(out)
    stamps = [m["_log_time"] for m in msgs["/plant"]]
    assert stamps == [k * 2_000_000 for k in range(51)], f"plant stamps {stamps[:4]}... vs every 2 ms"
    assert len(msgs["/ctl"]) == 101, f"ctl messages {len(msgs['/ctl'])} vs 101"


def test_wiring_errors_name_both_ends_and_candidates(write_scenario):
    path = write_scenario("""
name: bad
components:
  a: {path: "{CosimTSource}"}
  b: {path: "{CosimTGain}", parameters: {kk: 2.0}}
connections:
  - {from: a.yy, to: b.u}
  - {from: a.y, to: b.y}
time: {stop: 0.1, step: 0.01}
""")
    with pytest.raises(WiringError) as exc:
        run_scenario(load_scenario(path), log=False)
    text = str(exc.value)
    assert f"{path}:5: components.b.parameters.kk: " in text and "did you mean k?" in text, text
    assert f"{path}:7: connections[0].from: " in text and "no variable 'yy'; did you mean y?" in text, text
    assert f"{path}:8: connections[1].to: b.y is an output, expected an input" in text, text


def test_algebraic_loop_lists_variables(write_scenario):
    text = """
name: loop
components:
  a: {path: "{GAIN}"}
  b: {path: "{CosimTGain}"}
connections:
  - {from: a.y, to: b.u}
  - {from: b.y, to: a.u}
time: {stop: 0.1, step: 0.01}
"""
    path = write_scenario(text.replace("GAIN", "CosimTGain"), "declared.yaml")
    with pytest.raises(AlgebraicLoopError) as exc:
        run_scenario(load_scenario(path), log=False)
    assert exc.value.loop == ["a.y", "b.u", "b.y", "a.u", "a.y"], f"loop {exc.value.loop}"
    path = write_scenario(text.replace("GAIN", "CosimTGainUndeclared"), "undeclared.yaml")
    with pytest.raises(AlgebraicLoopError) as exc:
        run_scenario(load_scenario(path), log=False)
    assert "a do not declare output dependencies" in str(exc.value), str(exc.value)
    # Jacobi has no ordering problem with the loop
    res = run_scenario(load_scenario(path, {("algorithm",): "jacobi"}), log=False)
    assert res.steps == 10, f"steps {res.steps} vs 10"


def test_raising_fmu_names_component_function_time_and_log_survives(write_scenario, tmp_path):
    path = write_scenario("""
name: fails
components:
  src: {path: "{CosimTSource}"}
  bad: {path: "{CosimTRaiser}", parameters: {fail_time: 0.05}}
connections:
  - {from: src.y, to: bad.u}
time: {stop: 0.1, step: 0.001}
""")
    out = tmp_path / "fail.mcap"
    with pytest.raises(FMIError) as exc:
        run_scenario(load_scenario(path), out=out)
    err = exc.value
    assert (err.component, err.function) == ("bad", "fmi2DoStep"), str(err)
    assert abs(err.time - 0.05) < 1e-9, f"failure time {err.time} vs 0.05"
    summary, msgs = _read_mcap(out)  # finished file: the indexed reader works
    last = msgs["/bad"][-1]["_log_time"]
    assert last == 50_000_000, f"last logged stamp {last} ns vs 50 ms (all data up to the failure)"
    outcome = [m for m in summary.metadata_indexes if m.name == "outcome"]
    assert outcome, "no outcome metadata"


def _slow_scenario(write_scenario) -> Path:
    return write_scenario(SLOW_SCENARIO)


def _wait_for_steps(out: Path) -> None:
    """Until the run has written part of its log (a loaded machine starts it slower than a quiet one)."""
    partial = out.with_name(out.name + ".partial")
    wait_for(lambda: partial.exists() and partial.stat().st_size > 20_000, 60, f"{partial} to grow")
    time.sleep(0.3)


def test_sigint_finishes_the_log(write_scenario, tmp_path):
    path = _slow_scenario(write_scenario)
    out = tmp_path / "int.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "cosim", "run", str(path), "--out", str(out), "--quiet"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    _wait_for_steps(out)  # started, and some steps logged
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, f"exit code {proc.returncode} vs 130; stderr: {err.decode()}"
    summary, msgs = _read_mcap(out)
    stamps = [m["_log_time"] for m in msgs["/g"]]
    assert len(stamps) > 10, f"only {len(stamps)} messages logged before the interrupt"
    assert stamps == [k * 10_000_000 for k in range(len(stamps))], "stamps are not contiguous up to the interrupt"
    outcome = [m for m in summary.metadata_indexes if m.name == "outcome"]
    assert outcome, "no outcome metadata after Ctrl-C"


def test_killed_writer_is_recovered(write_scenario, tmp_path):
    from cosim.io.recover import recover

    path = _slow_scenario(write_scenario)
    out = tmp_path / "killed.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "cosim", "run", str(path), "--out", str(out), "--quiet"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    _wait_for_steps(out)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)
    partial = out.with_name(out.name + ".partial")  # written under this name, renamed only when finished
    assert not out.exists() and partial.exists(), sorted(p.name for p in tmp_path.iterdir())
    with pytest.raises(Exception):
        _read_mcap(partial)  # no summary: the indexed reader fails on an unfinished file
    rep = recover(partial, tmp_path / "fixed.mcap")
    summary, msgs = _read_mcap(Path(rep.out))
    stamps = [m["_log_time"] for m in msgs["/g"]]
    assert rep.messages > 10 and len(stamps) > 5, f"recovered {rep.messages} messages"
    assert stamps == [k * 10_000_000 for k in range(len(stamps))], "recovered stamps are not contiguous"


def test_cli_check_and_unreachable_trajectory(write_scenario):
    ok = write_scenario("""
name: traj
robot: linear_delta_thesis
trajectory: {type: helix, params: {z0: -0.45, duration: 10.0}}
initial_state: {from_trajectory: false}
components:
  g: {path: "{CosimTGain}"}
time: {stop: 1.0, step: 0.01}
""", "ok.yaml")
    r = subprocess.run([sys.executable, "-m", "cosim", "check", str(ok)], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, f"exit {r.returncode}: {r.stderr}"
    bad = write_scenario(ok.read_text().replace("z0: -0.45", "z0: -0.45, rx: 0.6, ry: 0.6"), "bad.yaml")
    r = subprocess.run([sys.executable, "-m", "cosim", "check", str(bad)], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 2, f"exit {r.returncode} vs 2: {r.stderr}"
    assert r.stderr.startswith("error: out of workspace at t = 0.00 s: p = (0.60, 0.00, -0.45) m: leg "), r.stderr
