"""Parallel co-simulation: the feed-forward group in a worker process gives a serial run's values.

The scenario has a feed-forward group (source -> ref, functions of time alone) that the
worker runs, and a feedback loop (sum -> plant -> ctl -> sum) in the master that reads the
group's output. Runs are long enough (3000 steps) for the worker to fill its ring (1024
entries), wrap around and wait for the master.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import orjson
import pytest

from cosim.errors import CosimError, FMIError
from cosim.engine import offload
from cosim.engine.offload import RING
from cosim.run import run_scenario
from cosim.engine.scenario import load_scenario

pytestmark = pytest.mark.integration
ROOT = Path(__file__).resolve().parents[2]

MIXED = """
name: mixed
components:
  src: {{path: "{{CosimTSource}}", parameters: {{amplitude: 0.3, frequency: 2.0}}, step_multiple: {m}}}
  ref: {{path: "{{CosimTSum}}"}}
  sum: {{path: "{{CosimTSum}}"}}
  ctl: {{path: "{{CosimTGain}}", parameters: {{k: -5.0}}}}
  plant: {{path: "{{CosimTIntegrator}}", parameters: {{x0: 0.5}}}}
connections:
  - {{from: src.y, to: ref.a}}
  - {{from: ref.y, to: sum.a}}
  - {{from: ctl.y, to: sum.b}}
  - {{from: sum.y, to: plant.u}}
  - {{from: plant.x, to: ctl.u}}
time: {{stop: {stop}, step: 0.001}}
algorithm: {alg}
parallel: {parallel}
logging: {{signals: all, flush_interval: 0.1}}
"""


def _logged_more_than(partial: Path, topic: str, n: int) -> bool:
    """Whether the log being written, ``partial``, holds more than ``n`` samples of ``topic`` (read from its start
    until it does, or up to where its writer has got)."""
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader

    from cosim.io.runlog import samples

    seen = 0
    try:
        with open(partial, "rb") as f:
            for _, channel, message in NonSeekingReader(f).iter_messages(log_time_order=False):
                if channel.topic == topic:
                    blocks = channel.metadata.get("layout") == "blocks"
                    seen += len(samples(orjson.loads(message.data))) if blocks else 1
                    if seen > n:
                        return True
    except (OSError, McapError):  # not there yet, or its end still being written
        pass
    return False


def _messages(path: Path) -> dict[str, list[tuple[int, bytes]]]:
    """(simulation time, JSON) by topic, one per sample on a component channel (a block's samples each)."""
    from mcap.reader import make_reader

    from cosim.io.runlog import samples, time_offset_ns

    with open(path, "rb") as f:
        reader = make_reader(f)
        offset = time_offset_ns({m.name: dict(m.metadata) for m in reader.iter_metadata()})  # wall-clock start
        out: dict[str, list[tuple[int, bytes]]] = {}
        for _, channel, message in reader.iter_messages():
            if channel.metadata.get("layout") == "blocks":
                out.setdefault(channel.topic, []).extend((round(s["t"] * 1e9), orjson.dumps(s))
                                                         for s in samples(orjson.loads(message.data)))
            else:
                out.setdefault(channel.topic, []).append((message.log_time - offset, bytes(message.data)))
    return out


@pytest.mark.parametrize("alg,m,start", [("gauss_seidel", 1, None), ("jacobi", 1, None), ("gauss_seidel", 2, None),
                                         ("gauss_seidel", 1, "spawn")])
def test_parallel_run_logs_the_serial_values_bit_for_bit(write_scenario, tmp_path, monkeypatch, alg, m, start):
    if start is not None:  # the start method used off Linux and on Python 3.12+ (default here: fork)
        monkeypatch.setattr(offload, "_START_METHOD", start)
    runs = {}
    for parallel in ("off", "on"):
        path = write_scenario(MIXED.format(m=m, stop=3.0, alg=alg, parallel=parallel), f"{parallel}.yaml")
        res = run_scenario(load_scenario(path), out=tmp_path / f"{parallel}.mcap")
        assert res.status == "completed" and res.steps == 3000, f"{parallel}: {res.status} {res.steps} steps"
        runs[parallel] = (res, _messages(tmp_path / f"{parallel}.mcap"))
    (serial, s_msgs), (par, p_msgs) = runs["off"], runs["on"]
    assert not serial.worker_time, f"serial run used a worker: {serial.notes}"
    assert sorted(par.worker_time) == ["ref", "src"], f"offloaded {par.worker_time} vs src, ref; notes {par.notes}"
    assert par.notes == ["parallel: src, ref run ahead in a worker process"], par.notes
    assert sorted(s_msgs) == sorted(p_msgs), f"channels {sorted(s_msgs)} vs {sorted(p_msgs)}"
    for topic in ("/src", "/ref", "/sum", "/ctl", "/plant"):
        assert len(s_msgs[topic]) > RING, f"{topic}: {len(s_msgs[topic])} messages, not enough to wrap the ring"
    for topic, serial_list in s_msgs.items():
        assert p_msgs[topic] == serial_list, f"{topic}: parallel log differs from serial (first of " \
            f"{len(serial_list)}: {next((a, b) for a, b in zip(serial_list, p_msgs[topic]) if a != b)})"
    # the Integer output came through the ring too: ref.n counts the ref's steps
    last_ref = p_msgs["/ref"][-1][1]
    assert b'"n":3000' in last_ref, f"last /ref message {last_ref[:120]!r}"


def test_failure_in_the_worker_is_raised_at_its_step_and_the_log_finished(write_scenario, tmp_path):
    path = write_scenario("""
name: fails
components:
  src: {path: "{CosimTSource}"}
  bad: {path: "{CosimTRaiser}", parameters: {fail_time: 0.05}}
  sum: {path: "{CosimTSum}"}
  plant: {path: "{CosimTIntegrator}"}
connections:
  - {from: src.y, to: bad.u}
  - {from: bad.y, to: sum.a}
  - {from: plant.x, to: sum.b}
  - {from: sum.y, to: plant.u}
time: {stop: 3.0, step: 0.001}
parallel: "on"
""")
    out = tmp_path / "fail.mcap"
    with pytest.raises(FMIError) as exc:
        run_scenario(load_scenario(path), out=out)
    err = exc.value
    assert (err.component, err.function) == ("bad", "fmi2DoStep"), str(err)
    assert abs(err.time - 0.05) < 1e-9, f"failure time {err.time} vs 0.05"
    assert "deliberate failure" in str(err), str(err)
    msgs = _messages(out)  # the indexed reader works: the file was finished
    stamps = [t for t, _ in msgs["/plant"]]
    assert stamps[-1] == 50_000_000, f"last logged stamp {stamps[-1]} ns vs 50 ms (as in a serial run)"


class _KillWorker:
    """Observer that kills the worker process at a given step."""

    def __init__(self, at: int):
        self.at = at
        self.pid = None

    def start(self, rt) -> None:
        import multiprocessing

        workers = [p for p in multiprocessing.active_children() if p.name == "cosim-worker"]
        assert len(workers) == 1, f"{len(workers)} worker processes"
        self.pid = workers[0].pid

    def stepped(self, k, t_ns, active) -> None:
        if k == self.at:
            os.kill(self.pid, signal.SIGKILL)

    def finish(self, rt, error) -> None:
        return None


def test_dead_worker_is_reported(write_scenario, tmp_path):
    path = write_scenario(MIXED.format(m=1, stop=5.0, alg="gauss_seidel", parallel='"on"'))
    killer = _KillWorker(at=100)
    with pytest.raises(CosimError) as exc:
        run_scenario(load_scenario(path), log=False, observers=[killer])
    text = str(exc.value)
    assert "the worker process running src, ref exited (code -9)" in text, text


def _children(pid: int) -> list[int]:
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                out.append(int(entry.name))
    return out


@pytest.mark.skipif(not Path("/proc").exists(), reason="needs /proc to find the worker")
def test_sigint_stops_master_and_worker_and_finishes_the_log(write_scenario, tmp_path):
    path = write_scenario(MIXED.format(m=1, stop=600.0, alg="gauss_seidel", parallel='"on"'))
    out = tmp_path / "int.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "cosim", "run", str(path), "--out", str(out), "--quiet"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    workers: list[int] = []
    deadline = time.monotonic() + 20
    while not workers and time.monotonic() < deadline:  # the worker starts once the plan is built
        time.sleep(0.2)
        workers = _children(proc.pid)
    assert workers, "no worker process appeared"
    partial = out.with_name(out.name + ".partial")  # the worker started and more than 100 steps are logged
    deadline = time.monotonic() + 60
    while not _logged_more_than(partial, "/plant", 100) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.1)
    assert proc.poll() is None, f"the run ended early: {proc.communicate()}"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, f"exit code {proc.returncode} vs 130; stderr: {err.decode()}"
    for pid in workers:
        assert not Path(f"/proc/{pid}").exists() or "zombie" in Path(f"/proc/{pid}/status").read_text(), \
            f"worker {pid} outlived the master"
    msgs = _messages(out)
    stamps = [t for t, _ in msgs["/plant"]]
    assert len(stamps) > 100, f"only {len(stamps)} messages logged before the interrupt"
    assert stamps == [k * 1_000_000 for k in range(len(stamps))], "stamps are not contiguous up to the interrupt"
