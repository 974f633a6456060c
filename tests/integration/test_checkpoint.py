"""Checkpoints and events on our FMUs, through the command line (issue 34, items 2, 4 and 6).

A run resumed from a checkpoint at T logs, after T, exactly the samples of the run that wrote it (bit for bit):
on native FMUs (helix_ctc_analytic), multi-rate (its controller at half the rate, checkpointed inside the
controller's step) and the Exudyn plant (helix_ctc, python build). A damaged, truncated or foreign checkpoint and
a time outside the run are refused with one line and exit 2, nothing written. Events set tunable parameters (the
payload) at a time or when a signal crosses a value, and the log's /events channel says when.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import cosim

from cosim.io.runlog import read_run

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
ANALYTIC = str(ROOT / "scenarios" / "helix_ctc_analytic.yaml")
EXUDYN = str(ROOT / "scenarios" / "helix_ctc.yaml")


def _after(log: Path, t: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    run = read_run(log)
    t_ns = round(t * 1e9)
    return {name: (s.t_ns[s.t_ns >= t_ns], s.y[s.t_ns >= t_ns]) for name, s in run.signals.items()}


def _assert_same_after(a: Path, b: Path, t: float) -> int:
    sa, sb = _after(a, t), _after(b, t)
    assert sorted(sa) == sorted(sb), f"signals differ: {sorted(set(sa) ^ set(sb))}"
    n = 0
    for name in sa:
        (ta, ya), (tb, yb) = sa[name], sb[name]
        assert np.array_equal(ta, tb), f"{name}: sample times after {t} s differ ({len(ta)} against {len(tb)})"
        diff = np.max(np.abs(ya - yb)) if len(ya) else 0.0
        assert np.array_equal(ya, yb), f"{name}: resumed run differs from the uninterrupted one by up to {diff:.3g}"
        n += len(ya)
    assert n > 0, "no samples after the checkpoint to compare"
    return n


CASES = {
    # scenario, extra options, stop time, checkpoint time
    "native": (ANALYTIC, ["--set", "fmus=native"], 0.4, 0.2),
    "multi_rate": (ANALYTIC, ["--set", "fmus=native", "--set", "components.ctl.step_multiple=2"], 0.4, 0.201),
    "exudyn": (EXUDYN, [], 0.2, 0.1),
    "model_exchange": (str(ROOT / "scenarios" / "helix_ctc_me.yaml"), [], 0.3, 0.15),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_resumed_run_equals_the_uninterrupted_one_after_the_checkpoint(case, tmp_path):
    scenario, extra, stop, t_ck = CASES[case]
    full, ckpt, resumed = tmp_path / "full.mcap", tmp_path / "run.ckpt", tmp_path / "resumed.mcap"
    r = cosim("run", scenario, *extra, "--stop-time", str(stop), "--checkpoint-at", str(t_ck), "--checkpoint-out",
              str(ckpt), "--out", str(full), "--json", "--sim-stamps")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["checkpoint"] == str(ckpt), f"checkpoint {summary['checkpoint']!r}, expected {ckpt}"
    r = cosim("run", "--resume", str(ckpt), "--out", str(resumed), "--json", "--sim-stamps")
    assert r.returncode == 0, r.stderr
    resumed_summary = json.loads(r.stdout)
    t_taken = float(json.loads(zipfile.ZipFile(ckpt).read("checkpoint.json"))["t_ns"]) * 1e-9
    assert t_taken >= t_ck - 1e-12, f"checkpoint at {t_taken} s, asked for {t_ck} s"
    assert abs(resumed_summary["sim_time_s"] - (stop - t_taken)) < 1e-9, (
        f"resumed run simulated {resumed_summary['sim_time_s']} s, expected {stop - t_taken} s")
    _assert_same_after(full, resumed, t_taken)


def test_a_run_of_an_ssp_archive_resumes_from_its_checkpoint_with_the_archive_unpacked_again(tmp_path):
    """The archive's FMUs were unpacked for the run that wrote the checkpoint only: the checkpoint names the archive
    (its SHA-256), and resuming unpacks it again, whether the archive is named or not; the resumed run's samples
    are the uninterrupted run's. Another archive, a changed one or the YAML scenario it came from is refused, and a
    warm sweep of the archive starts from the checkpoint too. Nothing is left in the temporary folder."""
    env = {**__import__("os").environ, "TMPDIR": str(tmp_path)}
    archive, full, ckpt = tmp_path / "helix.ssp", tmp_path / "full.mcap", tmp_path / "run.ckpt"
    assert cosim("ssp", "export", ANALYTIC, "-o", str(archive), env=env).returncode == 0
    r = cosim("run", archive, "--stop-time", "0.4", "--checkpoint-at", "0.2", "--checkpoint-out", str(ckpt),
              "--out", str(full), "--sim-stamps", env=env)
    assert r.returncode == 0, r.stderr
    for named in ([], [str(archive)]):
        resumed = tmp_path / f"resumed{len(named)}.mcap"
        r = cosim("run", *named, "--resume", str(ckpt), "--out", str(resumed), "--sim-stamps", env=env)
        assert r.returncode == 0, r.stderr
        _assert_same_after(full, resumed, 0.2)
    r = cosim("run", ANALYTIC, "--resume", str(ckpt), "--out", str(tmp_path / "x.mcap"), env=env)
    assert r.returncode == 2 and "differs from it: a checkpoint of another scenario" in r.stderr, r.stderr
    r = cosim("sweep", archive, "--from-checkpoint", str(ckpt), "--grid", "plant.mass.payload=0,1e-4", "--out",
              str(tmp_path / "sweep"), "--quiet", env=env)
    assert r.returncode == 0, r.stdout + r.stderr
    with zipfile.ZipFile(archive, "a") as z:  # the archive changed since the run
        z.writestr("extra.txt", "changed")
    r = cosim("run", "--resume", str(ckpt), "--out", str(tmp_path / "y.mcap"), env=env)
    assert r.returncode == 2 and "has changed since" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not list(tmp_path.glob("cosim-ssp-*")), "an unpacked archive is left"


def test_resume_with_set_applies_the_value_as_an_event_at_the_checkpoint_time(tmp_path):
    ckpt, base, heavy = tmp_path / "run.ckpt", tmp_path / "base.mcap", tmp_path / "heavy.mcap"
    r = cosim("run", ANALYTIC, "--set", "fmus=native", "--stop-time", "0.3", "--checkpoint-at", "0.1",
              "--checkpoint-out", str(ckpt), "--out", str(base), "--sim-stamps")
    assert r.returncode == 0, r.stderr
    r = cosim("run", "--resume", str(ckpt), "--set", "plant.mass.payload=2.0", "--out", str(heavy), "--sim-stamps")
    assert r.returncode in (0, 1), r.stderr  # 1: the scenario's tracking check fails under the unannounced payload
    log = read_run(heavy)
    assert log.events == [{"t": 0.1, "event": -1, "set": {"plant.mass.payload": 2.0}}], f"/events: {log.events}"
    z0 = _after(base, 0.1)["plant.p.z"][1]
    z1 = _after(heavy, 0.1)["plant.p.z"][1]
    sag = float(np.min(z1 - z0))
    # 2 kg more under the controller's unchanged efforts: the platform sinks (about g t^2 / 2 * 2 / 3.5 kg of
    # moving mass before the loop reacts; at least tens of micrometres within 0.2 s)
    assert sag < -1e-5, f"the heavier payload did not lower the platform: min dz = {sag:.3g} m"


def _refused(r, *words: str) -> None:
    assert r.returncode == 2, f"exit {r.returncode}, expected 2; stderr: {r.stderr}"
    lines = [ln for ln in r.stderr.strip().splitlines() if ln.strip()]
    assert len(lines) == 1, f"expected one line, got: {r.stderr!r}"
    for w in words:
        assert w in lines[0], f"{w!r} not in {lines[0]!r}"


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("ckpt")
    ckpt = d / "run.ckpt"
    r = cosim("run", ANALYTIC, "--set", "fmus=native", "--stop-time", "0.2", "--checkpoint-at", "0.1",
              "--checkpoint-out", str(ckpt), "--no-log")
    assert r.returncode == 0, r.stderr
    return ckpt


def test_damaged_and_truncated_checkpoints_are_refused(checkpoint, tmp_path):
    data = checkpoint.read_bytes()
    truncated = tmp_path / "truncated.ckpt"
    truncated.write_bytes(data[: len(data) // 2])
    out = tmp_path / "never.mcap"
    _refused(cosim("run", "--resume", str(truncated), "--out", str(out)), str(truncated), "checkpoint")
    damaged = tmp_path / "damaged.ckpt"
    with zipfile.ZipFile(checkpoint) as src, zipfile.ZipFile(damaged, "w") as dst:
        for item in src.infolist():
            blob = src.read(item.filename)
            if item.filename.startswith("states/"):
                blob = blob[:-8] + bytes(8)  # the last double of the state zeroed, the CRC recomputed by zipfile
            dst.writestr(item, blob)
    _refused(cosim("run", "--resume", str(damaged), "--out", str(out)), "damaged")
    assert not out.exists() and not list(tmp_path.glob("*.partial")), "a refused resume wrote a log"


def test_a_checkpoint_of_another_fmu_build_or_scenario_is_refused(checkpoint, tmp_path):
    other = tmp_path / "other.ckpt"
    with zipfile.ZipFile(checkpoint) as src, zipfile.ZipFile(other, "w") as dst:
        for item in src.infolist():
            blob = src.read(item.filename)
            if item.filename == "checkpoint.json":
                header = json.loads(blob)
                header["components"][0]["guid"] = "{00000000-0000-0000-0000-000000000000}"
                blob = json.dumps(header).encode()
            dst.writestr(item, blob)
    _refused(cosim("run", "--resume", str(other), "--no-log"), "another FMU build")
    _refused(cosim("run", EXUDYN, "--resume", str(checkpoint), "--no-log"), "another scenario")


def test_a_checkpoint_time_outside_the_run_is_refused(tmp_path):
    out = tmp_path / "x.ckpt"
    _refused(cosim("run", ANALYTIC, "--set", "fmus=native", "--stop-time", "0.2", "--checkpoint-at", "5",
                   "--checkpoint-out", str(out), "--no-log"), "outside the run")
    assert not out.exists(), "a refused checkpoint was written"


def _scenario_with(tmp_path: Path, events: str, stop: float = 0.3) -> Path:
    text = (ROOT / "scenarios" / "helix_ctc_analytic.yaml").read_text()
    text = text.replace("model: models/", f"model: {ROOT}/scenarios/models/")
    p = tmp_path / "events.yaml"
    p.write_text(text + "\n" + events)
    return p


@pytest.mark.parametrize("events, words", [
    ('events:\n  - {at: 0.1, set: {ctl.mass.platform: 1.0}}\n', ["events.yaml:", "events[0].set", "fixed parameter"]),
    ('events:\n  - {at: 0.1, set: {plant.nope: 1.0}}\n', ["events.yaml:", "plant.nope"]),
    ('events:\n  - {at: 0.1, set: {"ctl.q[1]": 1.0}}\n', ["events.yaml:", "driven by a connection"]),
    ('events:\n  - {when: "plant.p.z <= 0", set: {plant.mass.payload: 1.0}}\n', ["events.yaml:", "when"]),
    ('events:\n  - {at: -1, set: {plant.mass.payload: 1.0}}\n', ["events.yaml:", "events[0].at"]),
])
def test_bad_events_are_refused_before_the_run_with_file_and_line(tmp_path, events, words):
    p = _scenario_with(tmp_path, events)
    _refused(cosim("check", str(p), "--set", "fmus=native", "--stop-time", "0.3"), *words)


def test_time_and_state_events_set_the_payload_and_are_logged(tmp_path):
    events = ('events:\n'
              '  - {at: 0.05, set: {plant.mass.payload: 1.0}}\n'
              '  - {when: "plant.p.x < 0.07", set: {ctl.mass.payload: 1.0}}\n')
    p = _scenario_with(tmp_path, events)
    out = tmp_path / "events.mcap"
    r = cosim("run", str(p), "--set", "fmus=native", "--stop-time", "0.3", "--out", str(out), "--json")
    assert r.returncode in (0, 1), r.stderr
    fired = json.loads(r.stdout)["fired"]
    log = read_run(out)
    assert [e["event"] for e in log.events] == [0, 1], f"/events: {log.events}"
    assert log.events == fired, f"/events {log.events} against the summary's {fired}"
    assert log.events[0] == {"t": 0.05, "event": 0, "set": {"plant.mass.payload": 1.0}}, log.events[0]
    x = log.signals["plant.p.x"]
    t_e = log.events[1]["t"]
    i = int(np.searchsorted(x.t_ns, round(t_e * 1e9)))
    # located inside its step: x is at or above 0.07 m at the sample before the located time, below after it
    # (the located time against an analytic crossing: tests/unit/test_events.py)
    assert x.y[i - 1] >= 0.07 > x.y[i], f"x around {t_e} s: {x.y[i - 1]}, {x.y[i]}"


def test_a_checkpoint_does_not_depend_on_what_the_writing_run_logged(tmp_path):
    """A run without a log reads fewer outputs than a logged one; its checkpoint resumes into a logged run (the
    outputs it lacks read from the restored FMUs), and a logged run's into one without a log."""
    full, quiet_ckpt, logged_ckpt = tmp_path / "full.mcap", tmp_path / "quiet.ckpt", tmp_path / "logged.ckpt"
    r = cosim("run", ANALYTIC, "--set", "fmus=native", "--stop-time", "0.3", "--checkpoint-at", "0.1",
              "--checkpoint-out", str(logged_ckpt), "--out", str(full), "--sim-stamps")
    assert r.returncode == 0, r.stderr
    r = cosim("run", ANALYTIC, "--set", "fmus=native", "--stop-time", "0.3", "--checkpoint-at", "0.1",
              "--checkpoint-out", str(quiet_ckpt), "--no-log")
    assert r.returncode == 0, r.stderr
    resumed = tmp_path / "resumed.mcap"
    r = cosim("run", "--resume", str(quiet_ckpt), "--out", str(resumed), "--sim-stamps")
    assert r.returncode == 0, r.stderr
    _assert_same_after(full, resumed, 0.1)
    r = cosim("run", "--resume", str(logged_ckpt), "--no-log", "--json")
    assert r.returncode == 0, r.stderr


def test_an_event_after_the_stop_time_is_not_reached_and_the_summary_says_so(tmp_path):
    p = _scenario_with(tmp_path, 'events:\n  - {at: 0.05, set: {plant.mass.payload: 0.1}}\n'
                                 '  - {at: 5.0, set: {plant.mass.payload: 0.0}}\n')
    r = cosim("run", str(p), "--set", "fmus=native", "--stop-time", "0.1", "--no-log", "--json")
    assert r.returncode in (0, 1), r.stderr
    summary = json.loads(r.stdout)
    assert [e["event"] for e in summary["fired"]] == [0], f"fired {summary['fired']}"
    assert any("events 1 come after the stop time" in n for n in summary["notes"]), summary["notes"]


def test_one_event_of_the_list_is_changed_by_its_index(tmp_path):
    p = _scenario_with(tmp_path, 'events:\n  - {at: 0.05, set: {plant.mass.payload: 0.1}}\n')
    r = cosim("run", str(p), "--set", "fmus=native", "--stop-time", "0.1", "--no-log", "--json",
              "--set", "events[0].at=0.02", "--set", "events[0].set={plant.mass.payload: 0.3}")
    assert r.returncode in (0, 1), r.stderr
    fired = json.loads(r.stdout)["fired"]
    assert fired == [{"t": 0.02, "event": 0, "set": {"plant.mass.payload": 0.3}}], f"fired {fired}"
    r = cosim("check", str(p), "--set", "fmus=native", "--set", "events[3].at=0.02")
    _refused(r, "events has 1 item(s)")


def test_the_python_api_writes_and_resumes_checkpoints(tmp_path):
    from cosim import api

    ckpt = tmp_path / "api.ckpt"
    full = api.run(ANALYTIC, {"time.stop": 0.3, "fmus": "native"}, checkpoint_at=0.1, checkpoint_out=ckpt)
    resumed = api.resume(ckpt)
    i = int(np.searchsorted(full.time, 0.1))
    assert resumed.time[0] == pytest.approx(0.1, abs=1e-12), f"resumed signals start at {resumed.time[0]} s"
    for name in ("plant.p.x", "ctl.u[1]", "traj.p_ref.z"):
        assert np.array_equal(full[name][i:], resumed[name]), f"{name} differs after the checkpoint"
    heavy = api.resume(ckpt, {"plant.mass.payload": 0.5}, stop_time=0.2)
    assert heavy.time[-1] == pytest.approx(0.2, abs=1e-12), f"stopped at {heavy.time[-1]} s"
    assert heavy.run.fired == [{"t": 0.1, "event": -1, "set": {"plant.mass.payload": 0.5}}], heavy.run.fired


def test_a_checkpoint_of_a_system_without_serializable_state_is_refused_before_the_run(tmp_path, write_scenario):
    p = write_scenario(
        "name: loop\n"
        "components:\n"
        "  ctl: {path: '{CosimTGain}', parameters: {k: -5.0}}\n"
        "  plant: {path: '{CosimTIntegrator}', parameters: {x0: 0.5}}\n"
        "connections:\n"
        "  - {from: plant.x, to: ctl.u}\n"
        "  - {from: ctl.y, to: plant.u}\n"
        "time: {stop: 1.0, step: 0.001}\n")
    out = tmp_path / "loop.ckpt"
    r = cosim("run", str(p), "--checkpoint-at", "0.5", "--checkpoint-out", str(out), "--no-log", "--json")
    refusal = json.loads(r.stdout)
    assert r.returncode == 2 and "cannot be serialized" in refusal["error"], (r.returncode, r.stdout)
    assert "ctl, plant" in refusal["error"], refusal["error"]
    assert not out.exists(), "a refused checkpoint was written"


def test_a_member_larger_than_any_checkpoint_holds_is_refused_unread(checkpoint, tmp_path):
    big = tmp_path / "big.ckpt"
    with zipfile.ZipFile(checkpoint) as src, zipfile.ZipFile(big, "w", compression=zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            blob = src.read(item.filename)
            if item.filename == "scenario.json":
                blob = b" " * (65 << 20)  # 65 MiB of blanks, deflated to a few kB: a member past the bound
            dst.writestr(item.filename, blob)
    _refused(cosim("run", "--resume", str(big), "--no-log"), "scenario.json claims", "refused")
