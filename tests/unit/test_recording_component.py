"""A recording as a component (``recording: FILE``): its signals replayed as outputs at the communication points
(hold, linear, an offset), their units from the file or ``units:``, and every bad input one line naming the
scenario's file, line and component. Fast: the scenarios here hold only recordings (no FMU)."""

from __future__ import annotations

import re
import textwrap
from pathlib import Path

import numpy as np
import pytest

from cosim import api
from cosim.engine.plugins import recording_source
from cosim.engine.prepare import input_files, prepare
from cosim.engine.scenario import load_scenario
from cosim.errors import CosimError
from cosim.io.recordings import read_recording
from recording_helpers import joint_states_bag, write_csv

T_REC = np.arange(0.0, 0.0121, 0.004)  # 250 Hz, 0 .. 12 ms
Q_DEG = 1000.0 * T_REC ** 2  # a parabola: linear interpolation is not exact between samples


def _csv(folder: Path) -> Path:
    return write_csv(folder / "r.csv", "time [s],q1 [deg],q2 [rad]",
                     np.column_stack([T_REC, Q_DEG, np.radians(Q_DEG)]), comments=["synthetic"])


def _scenario(folder: Path, component: str, stop: float = 0.01) -> Path:
    """A scenario whose one component ``meas`` is ``component`` (YAML lines of its mapping)."""
    body = "\n".join("    " + line.strip() for line in textwrap.dedent(component).splitlines())
    path = folder / "s.yaml"
    path.write_text(f"name: solo\ncomponents:\n  meas:\n{body}\ntime: {{stop: {stop}, step: 0.001}}\n"
                    "logging: {enabled: false}\n", encoding="utf-8")
    return path


def _run(folder: Path, component: str, **kw) -> api.Result:
    return api.run(_scenario(folder, component, **kw))


def test_hold_and_linear_are_the_readers_samples_at_the_communication_points(tmp_path):
    """Each output at run time t is the reader's sample at t + offset (Recording.sample: the one formula)."""
    rec = read_recording(_csv(tmp_path), {"q1": "q1"})
    for how in ("hold", "linear"):
        for offset in (0.0, 0.0015):
            res = _run(tmp_path, f"""\
                recording: r.csv
                signals: {{"q[1]": q1}}
                interpolation: {how}
                offset: {offset}""")
            t = res.time
            want = rec.sample("q1", t + offset + (0.5e-9 if how == "hold" else 0.0), how)
            # the same formula; the Result's time axis may differ from the grid's double of a point by an ulp
            # (2e-19 s here), which moves a linear sample by far less than 1e-12 deg
            assert np.allclose(res["meas.q[1]"], want, rtol=0, atol=1e-12), (how, offset, res["meas.q[1]"] - want)
    # hold at the recorded stamps (4 ms) takes the sample stamped there, not the one before
    res = _run(tmp_path, 'recording: r.csv\nsignals: {"q[1]": q1}\ninterpolation: hold')
    assert res["meas.q[1]"][4] == Q_DEG[1] and res["meas.q[1]"][3] == Q_DEG[0], res["meas.q[1]"]


def test_units_come_from_the_recording_or_are_asked_for(tmp_path):
    _csv(tmp_path)
    plan, _ = prepare(load_scenario(_scenario(tmp_path, """\
        recording: r.csv
        signals: {"q[1]": q1, "q[2]": q2, "q[3]": q1}
        units: {"q[3]": rad}""")).structure())
    units = {v.name: v.unit for v in plan.infos[0].variables.values()}
    assert units == {"q[1]": "deg", "q[2]": "rad", "q[3]": "rad"}, units
    res = _run(tmp_path, 'recording: r.csv\nsignals: {"a": q1, "b": q2}\nunits: {a: rad}\ninterpolation: hold')
    assert np.allclose(res["meas.a"], res["meas.b"], rtol=1e-15, atol=0), (res["meas.a"], res["meas.b"])


def test_a_bag_replays_by_joint_name_and_the_file_is_an_input_of_the_run(tmp_path):
    t = np.arange(0.0, 0.0201, 0.002)
    q = np.column_stack([t, 2 * t, 3 * t])
    joint_states_bag(tmp_path / "bag", "mcap", t, q)
    path = _scenario(tmp_path, """\
        recording: bag
        signals: {"q[2]": "/joint_states.position[joint2]"}
        units: {"q[2]": rad}""", stop=0.02)
    res = api.run(path)
    assert np.allclose(res["meas.q[2]"], 2 * res.time, rtol=0, atol=1e-15), res["meas.q[2]"]
    assert tmp_path / "bag" in input_files(load_scenario(path).structure()), input_files(load_scenario(path).structure())


def _error(folder: Path, component: str, **kw) -> str:
    with pytest.raises(CosimError) as exc:
        prepare(load_scenario(_scenario(folder, component, **kw)).structure())
    message = str(exc.value)
    assert "\n" not in message, message
    return message


def test_every_bad_recording_component_is_one_line_at_the_file_line_and_component(tmp_path):
    _csv(tmp_path)
    at = re.escape(str(tmp_path / "s.yaml")) + r":\d+: components\.meas"
    cases = {
        "recording: nope.csv\nsignals: {q: q1}": r"recording file not found: .*nope\.csv",
        "recording: r.csv\nsignals: {q: q9}": r"r\.csv:\d+: no column 'q9'",
        "recording: r.csv\nsignals: {q: q1}\nunits: {q: m}": r"unit 'deg' does not convert to 'm'",
        # the run needs 0.002 .. 0.012 s of the recording (offset 2 ms): it ends at 0.012 s, so this passes ...
        "recording: r.csv\nsignals: {q: q1}\noffset: 0.0021": r"recording .*r\.csv covers t = 0 \.\. 0\.012 s .*, "
                                                             r"the run t = 0 \.\. 0\.01 s needs 0\.0021 \.\. 0\.0121 s "
                                                             r"with offset 0\.0021 s",
        "recording: r.csv\nsignals: {q: q1}\noffset: -0.001": r"needs -0\.001 \.\. 0\.009 s with offset -0\.001 s",
        "recording: r.csv\nsignals: {q: q1}\ninterpolation: cubic": r"interpolation: Input should be 'linear' or "
                                                                    r"'hold'",
        "recording: r.csv\nsignals: {}": r"a recording component needs 'signals'",
        "recording: r.csv\nsignals: {q: q1}\nparameters: {k: 1}": r"parameters: not for a recording",
        "recording: r.csv\nsignals: {q: q1}\nunits: {p: m}": r"units: p not among the signals \(q\)",
    }
    for component, message in cases.items():
        got = _error(tmp_path, component)
        assert re.search(at, got) and re.search(message, got), (component, got)
    assert prepare(load_scenario(_scenario(tmp_path, "recording: r.csv\nsignals: {q: q1}\noffset: 0.002")).structure())


def test_recording_keys_on_an_fmu_component_and_two_sources_are_refused(tmp_path):
    got = _error(tmp_path, "fmu: helix\nsignals: {q: q1}")
    assert "signals: only for a component given by 'recording'" in got, got
    got = _error(tmp_path, "fmu: helix\nrecording: r.csv\nsignals: {q: q1}")
    assert "give exactly one of 'fmu'" in got, got


def test_the_recordings_maker_is_found_through_its_entry_point():
    from cosim.io.recordings.component import recording_info

    assert recording_source() is recording_info


def test_ssp_export_refuses_a_recording_component(tmp_path):
    from cosim.io.ssp import export_ssp

    _csv(tmp_path)
    with pytest.raises(CosimError, match=r"s\.yaml:\d+: components\.meas: replays a recording \(r\.csv\); SSP 1\.0 has "
                                         r"no such component") as exc:
        export_ssp(load_scenario(_scenario(tmp_path, "recording: r.csv\nsignals: {q: q1}")), tmp_path / "x.ssp")
    assert not (tmp_path / "x.ssp").exists(), exc.value


def test_a_run_with_a_recording_runs_again_from_its_log(tmp_path):
    """The log's scenario as run writes every key, defaults too: read back, they are not taken as FMU keys given to
    a recording."""
    import subprocess
    import sys

    _csv(tmp_path)
    path = _scenario(tmp_path, 'recording: r.csv\nsignals: {"q[1]": q1}\ninterpolation: hold')
    path.write_text(path.read_text().replace("logging: {enabled: false}", "logging: {out: s.mcap}"))
    for args in (["s.yaml"], ["--from-log", "s.mcap"]):
        done = subprocess.run([sys.executable, "-m", "cosim", "run", *args, "--quiet"], cwd=tmp_path,
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, (args, done.stderr)
    from cosim.io.runlog import read_run

    first, again = read_run(tmp_path / "s.mcap"), read_run(tmp_path / "s.rerun.mcap")
    assert np.array_equal(first.signal("meas.q[1]").y, again.signal("meas.q[1]").y), again.signal("meas.q[1]").y
