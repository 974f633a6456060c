"""Hostile inputs, round 2 (issue 25): forged logs, a scheduler that is not Dask, results that must mean what they say.

In the style of ``test_faults.py``: every case runs ``python -m cosim`` in a subprocess and asserts its exit code,
one message line naming the cause, no traceback; each runs with its own temporary folder (``TMPDIR``), which must be
empty afterwards, and writes nowhere but ``tmp_path``.
"""

from __future__ import annotations

import math
import os
import re
import resource
from pathlib import Path

import pytest
from cli_helpers import cosim
from test_faults import SMALL, fails

from cosim.engine.structure import DOCUMENT_ATTACHMENT
from cosim.io.runlog import MAX_CHUNK_BYTES

pytestmark = pytest.mark.integration

MEMORY_LIMIT = 1024 ** 3
"""Address space of a command reading a forged log, bytes: well above what reading a small log takes, well under the
2.5 GiB a bomb inflates to, so a regression fails on the spot instead of exhausting the machine."""


@pytest.fixture
def run(tmp_path):
    """``cosim`` with a temporary folder of its own, which must be left empty."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()

    def call(*args, limit_memory: bool = False, **kw):
        env = {**os.environ, "TMPDIR": str(tmp), **kw.pop("env", {})}
        return cosim(*args, env=env, preexec_fn=_limit_memory if limit_memory else None, **kw)

    yield call
    _left_empty(tmp)


def _limit_memory() -> None:
    """In a child before it runs: at most :data:`MEMORY_LIMIT` of address space."""
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def _left_empty(tmp: Path) -> None:
    """The command's temporary folder is empty."""
    assert not any(tmp.iterdir()), f"left in the temporary folder: {sorted(p.name for p in tmp.iterdir())}"


# --------------------------------------------------------------------------- MCAP decompression bombs

BOMB_BYTES = 5 * 2 ** 29  # 2.5 GiB of zeros: about 80 kB of zstd


def _zeros(compression: str, n: int) -> bytes:
    """``n`` zero bytes compressed as an MCAP chunk is (one zstd or lz4 frame), never held uncompressed."""
    block = bytes(2 ** 22)
    if compression == "zstd":
        import zstandard

        c = zstandard.ZstdCompressor(level=1).compressobj(size=n)
    else:
        import lz4.frame

        c = lz4.frame.LZ4FrameCompressor()
        head = c.begin(source_size=n)
    parts = [] if compression == "zstd" else [head]
    for start in range(0, n, len(block)):
        parts.append(c.compress(block[:n - start]))
    parts.append(c.flush())
    return b"".join(parts)


def forged_log(path: Path, declared: int, inflated: int, compression: str = "zstd") -> int:
    """Write a finished, indexed MCAP log (header, a channel, one chunk, summary with its chunk index, footer)
    whose chunk declares ``declared`` uncompressed bytes and inflates to ``inflated``: a lie when they differ, an
    honest bomb when both are huge. Returns the chunk's byte offset."""
    from mcap.data_stream import RecordBuilder
    from mcap.records import Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Schema
    from mcap.writer import MCAP0_MAGIC

    schema = Schema(id=1, name="s", encoding="jsonschema", data=b"{}")
    channel = Channel(id=1, topic="/plant", message_encoding="json", schema_id=1, metadata={})
    data = _zeros(compression, inflated)
    b = RecordBuilder()
    Header(profile="", library="forged").write(b)
    schema.write(b)
    channel.write(b)
    offset = len(MCAP0_MAGIC) + b.count
    Chunk(compression=compression, data=data, message_start_time=0, message_end_time=0, uncompressed_crc=0,
          uncompressed_size=declared).write(b)
    length = len(MCAP0_MAGIC) + b.count - offset
    DataEnd(data_section_crc=0).write(b)
    summary = len(MCAP0_MAGIC) + b.count
    schema.write(b)
    channel.write(b)
    ChunkIndex(message_start_time=0, message_end_time=0, chunk_start_offset=offset, chunk_length=length,
               message_index_offsets={1: offset + length}, message_index_length=0, compression=compression,
               compressed_size=len(data), uncompressed_size=declared).write(b)
    Footer(summary_start=summary, summary_offset_start=0, summary_crc=0).write(b)
    path.write_bytes(MCAP0_MAGIC + b.end() + MCAP0_MAGIC)
    return offset


def _commands(log: Path, tmp_path: Path) -> list[tuple]:
    """Every command that reads a log."""
    return [("recover", log, "--out", tmp_path / "r.mcap"), ("compare", log, log),
            ("report", log, "--out", tmp_path / "report"), ("table", log),
            ("baseline", log, "--out", tmp_path / "b.mcap")]


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_a_chunk_lying_about_its_size_is_refused_by_every_reader(tmp_path, run, compression):
    log = tmp_path / "lie.mcap"
    at = forged_log(log, 4096, BOMB_BYTES, compression)
    assert log.stat().st_size < 12 * 2 ** 20, log.stat().st_size  # a small file (lz4 compresses zeros less)
    for args in _commands(log, tmp_path):
        fails(run(*args, limit_memory=True), 2, f"lie.mcap: the MCAP chunk at byte {at} ",
              "inflates past the 4,096 bytes it declares")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lie.mcap", "tmp"], "an output was written"


def test_an_honest_chunk_over_the_limit_is_refused_before_it_is_inflated(tmp_path, run):
    log = tmp_path / "bomb.mcap"
    at = forged_log(log, BOMB_BYTES, BOMB_BYTES)
    assert log.stat().st_size < 200_000, log.stat().st_size  # the 82 KB of issue 25
    for args in _commands(log, tmp_path):
        message = fails(run(*args, limit_memory=True), 2, f"bomb.mcap: the MCAP chunk at byte {at} ",
                        f"declares {BOMB_BYTES:,} bytes", f"{MAX_CHUNK_BYTES:,}", "cosim.io.runlog.MAX_CHUNK_BYTES")
        assert "refused" in message, message
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bomb.mcap", "tmp"], "an output was written"


def test_a_chunk_cut_short_is_damage_not_a_record(tmp_path, run):
    """A chunk that inflates to fewer bytes than it declares (a cut frame) is a damaged log, never parsed in part."""
    log = tmp_path / "short.mcap"
    forged_log(log, 8192, 4096)
    fails(run("compare", log, log), 2, "short.mcap: cannot read the MCAP log", "4,096 of the 8,192 bytes")


# --------------------------------------------------------------------------- --scheduler that is not Dask

SWEEP_SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "helix_ctc_analytic.yaml"


class _Server:
    """A TCP server on 127.0.0.1 in a thread: ``http`` answers whatever it is sent with an HTTP 400 page, ``silent``
    accepts and never says a word."""

    def __init__(self, kind: str):
        import socketserver
        import threading

        class Handler(socketserver.BaseRequestHandler):
            def handle(self) -> None:
                if kind == "http":
                    self.request.recv(65536)
                    self.request.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Type: text/html\r\n"
                                         b"Content-Length: 24\r\nConnection: close\r\n\r\n<html>bad request</html>")
                else:
                    stop.wait(60)

        stop = threading.Event()
        self.stop = stop
        self.server = socketserver.ThreadingTCPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        self.address = f"tcp://127.0.0.1:{self.server.server_address[1]}"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.stop.set()
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def server(request):
    s = _Server(request.param)
    yield s
    s.close()


def _sweep_args(tmp_path, scheduler: str) -> tuple:
    return ("sweep", SWEEP_SCENARIO, "--grid", "ctl.gain.kp[1]=1e4,2e4", "--stop-time", "0.05", "--scheduler",
            scheduler, "--out", tmp_path / "sweep", "--quiet")


def _sweep(run, tmp_path, scheduler: str):
    import time

    t0 = time.monotonic()
    r = run(*_sweep_args(tmp_path, scheduler), limit_memory=True, timeout=60)
    return r, time.monotonic() - t0


@pytest.fixture(scope="module")
def waiting_sweeps(tmp_path_factory):
    """The sweeps that wait out :attr:`SweepCluster.CONNECT_TIMEOUT` (10 s, a class constant no option or variable
    sets), started together so their waits overlap instead of following one another: against a silent scheduler,
    against a port that refuses (Dask's connect retries it for the whole timeout), and against ``notaurl``. Each is
    the same ``python -m cosim sweep`` as :func:`_sweep` runs, with its own temporary folder and the memory limit
    of :func:`run`; a thread waits for each and notes when it ended. name -> a function giving (CompletedProcess,
    wall-clock seconds from its start to its end, its temporary folder, its output folder, the scheduler address,
    the silent server or None)."""
    import subprocess
    import threading
    import time

    from cli_helpers import free_port, start_cosim

    silent = _Server("silent")
    schedulers = {"silent": silent.address, "refused": f"tcp://127.0.0.1:{free_port()}", "notaurl": "notaurl"}

    started, done = {}, {}
    for name, scheduler in schedulers.items():
        folder = tmp_path_factory.mktemp(f"sweep_{name}")
        tmp = folder / "tmp"
        tmp.mkdir()
        t0 = time.monotonic()
        proc = start_cosim(*_sweep_args(folder, scheduler), env={**os.environ, "TMPDIR": str(tmp)},
                           preexec_fn=_limit_memory)
        started[name] = (proc, t0, tmp, folder, scheduler)

    def wait(name: str) -> None:
        proc, t0, *_ = started[name]
        try:
            out, err = proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate()
        done[name] = (subprocess.CompletedProcess(proc.args, proc.returncode, out, err), time.monotonic() - t0)

    threads = {name: threading.Thread(target=wait, args=(name,), daemon=True) for name in started}
    for t in threads.values():
        t.start()

    def result(name: str):
        threads[name].join(90)
        assert name in done, f"the sweep against {name} did not end"
        proc, t0, tmp, folder, scheduler = started[name]
        return (*done[name], tmp, folder, scheduler, silent if name == "silent" else None)

    try:
        yield result
    finally:
        for proc, *_ in started.values():
            proc.kill()
        for t in threads.values():
            t.join(90)
        silent.close()


@pytest.mark.parametrize("server", ["http"], indirect=True)
def test_a_scheduler_that_answers_http_is_not_dask(server, run, tmp_path):
    r, _ = _sweep(run, tmp_path, server.address)
    fails(r, 2, f"--scheduler {server.address}: {server.address} is not a Dask scheduler")
    assert not (tmp_path / "sweep" / "results.csv").exists(), "a case was run"


@pytest.mark.parametrize("kind", ["silent"])
def test_a_silent_scheduler_is_given_up_after_the_timeout(waiting_sweeps, kind):
    from cosim.analysis.cluster import SweepCluster

    r, wall, tmp, _, address, _ = waiting_sweeps(kind)
    fails(r, 2, f"--scheduler {address}: no answer from {address} within "
                f"{SweepCluster.CONNECT_TIMEOUT:g} s")
    assert wall < SweepCluster.CONNECT_TIMEOUT + 30, f"{wall:.1f} s to give up"  # bounded, not for ever
    _left_empty(tmp)


def test_a_scheduler_address_that_refuses_or_is_not_an_address(waiting_sweeps):
    r, _, tmp, _, address, _ = waiting_sweeps("refused")
    # refused, as a rule; on a loaded machine the last attempt may time out instead: a reason is given either way
    fails(r, 2, f"--scheduler {address}: cannot connect to {address} within",
          r"within 10 s \((\[Errno 111\] )?(Connection refused|.*Error: )")
    _left_empty(tmp)
    r, _, tmp, _, _, _ = waiting_sweeps("notaurl")
    fails(r, 2, "--scheduler notaurl: not a scheduler address", "expected tcp://HOST:PORT")
    _left_empty(tmp)


# --------------------------------------------------------------------------- results mean what they say

def test_a_sweep_case_that_misses_its_acceptance_check_is_failed(run, tmp_path):
    """The same run twice, once under a limit it cannot meet: that case is failed (status, summary, exit 1), with
    its metrics and the check that failed; the sweep run again still counts it failed."""
    import csv
    import json

    out = tmp_path / "sweep"
    args = ("sweep", SWEEP_SCENARIO, "--grid", "checks.max_rmse=1,1e-15", "--stop-time", "0.1", "--workers", "1",
            "--out", out)
    r = run(*args, "--quiet", timeout=240)
    assert r.returncode == 1, r.stdout + r.stderr
    assert "Traceback" not in r.stderr, r.stderr
    with (out / "results.csv").open(newline="") as f:
        rows = {row["checks.max_rmse"]: row for row in csv.DictReader(f)}
    strict, loose = rows["1e-15"], rows["1"]
    assert (strict["status"], strict["checks"]) == ("failed", "FAILED"), strict
    assert strict["message"].startswith("acceptance check failed: max_rmse ") and "> 1e-15" in strict["message"], \
        strict["message"]
    assert float(strict["rmse"]) > 1e-15 and strict["rmse"] == loose["rmse"], (strict["rmse"], loose["rmse"])
    assert (loose["status"], loose["checks"], loose["message"]) == ("ok", "ok", ""), loose
    assert "2 cases, 1 ok, 1 failed" in r.stdout and f"FAILED {strict['case']} " in r.stdout, r.stdout
    again = run(*args, "--json", timeout=240)
    summary = json.loads(again.stdout)
    assert again.returncode == 1 and (summary["ran"], summary["skipped"]) == (0, 2), (again.returncode, summary)
    assert not summary["ok"] and len(summary["failed"]) == 1, summary


def _same_signals(a: Path, b: Path) -> int:
    """Assert two logs hold the same signals, stamp for stamp and bit for bit; returns how many."""
    import numpy as np

    from cosim.io.runlog import read_run

    la, lb = read_run(a), read_run(b)
    assert la.signals.keys() == lb.signals.keys(), sorted(set(la.signals) ^ set(lb.signals))
    for name, sa in la.signals.items():
        sb = lb.signals[name]
        assert np.array_equal(sa.t_ns, sb.t_ns), (name, sa.t_ns[:5], sb.t_ns[:5])
        assert np.array_equal(sa.y, sb.y, equal_nan=True), (name, sa.y[:5], sb.y[:5])
    return len(la.signals)


def test_a_run_is_repeated_from_its_log_alone(run, tmp_path):
    """The log records the command line and the scenario as run (after --set and --stop-time): run again from it,
    from another folder, it gives the same signals bit for bit; without the override the signals differ (it was
    applied)."""
    import json

    from cosim.io.runlog import read_run
    from cosim.engine.structure import DOCUMENT_ATTACHMENT

    first, again, plain = tmp_path / "first.mcap", tmp_path / "again.mcap", tmp_path / "plain.mcap"
    r = run("run", SWEEP_SCENARIO, "--set", "ctl.gain.kp[1]=2e4", "--stop-time", "0.1", "--out", first, "--quiet")
    assert r.returncode == 0, r.stderr
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    r = run("run", "--from-log", first, "--out", again, "--quiet", cwd=elsewhere)
    assert r.returncode == 0, r.stderr
    assert _same_signals(first, again) > 20
    log = read_run(first)
    argv = json.loads(log.metadata["command"]["argv"])
    assert argv[argv.index("--set") + 1] == "ctl.gain.kp[1]=2e4" and "--stop-time" in argv, argv
    recorded = json.loads(log.attachments[DOCUMENT_ATTACHMENT])
    assert recorded["components"]["ctl"]["parameters"] == {"gain.kp[1]": "2e4"}, recorded["components"]["ctl"]
    assert recorded["time"]["stop"] == 0.1, recorded["time"]
    assert recorded["logging"]["out"] == str(first), recorded["logging"]  # the log it ran to, not the file's
    rerun = json.loads(read_run(again).attachments[DOCUMENT_ATTACHMENT])
    assert rerun == {**recorded, "logging": {**recorded["logging"], "out": str(again)}}, (rerun, recorded)
    assert run("run", SWEEP_SCENARIO, "--stop-time", "0.1", "--out", plain, "--quiet").returncode == 0
    with pytest.raises(AssertionError):
        _same_signals(first, plain)


def _copy_log(src: Path, dst: Path, leave_out: str) -> None:
    """A copy of the MCAP log ``src`` without its attachment named ``leave_out``."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(src, "rb") as f, open(dst, "wb") as g:
        reader, writer = make_reader(f), Writer(g)
        writer.start(profile=reader.get_header().profile, library="tests")
        schemas, channels = {}, {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(channel.topic, channel.message_encoding,
                                                               schemas.get(channel.schema_id, 0), channel.metadata)
            writer.add_message(channels[channel.id], message.log_time, message.data, message.publish_time,
                               message.sequence)
        for attachment in reader.iter_attachments():
            if attachment.name != leave_out:
                writer.add_attachment(attachment.create_time, attachment.log_time, attachment.name,
                                      attachment.media_type, attachment.data)
        for metadata in reader.iter_metadata():
            writer.add_metadata(metadata.name, metadata.metadata)
        writer.finish()


def test_run_from_a_log_that_cannot_say_how_it_was_made(run, tmp_path, write_scenario):
    """A log that is missing, not an MCAP file, records no scenario (an older log), or whose FMU files are gone:
    one line naming the log and the cause, exit 2, no log written."""
    import shutil

    fails(run("run", "--from-log", tmp_path / "none.mcap"), 2, "none.mcap: no such log file")
    fails(run("run", "--from-log", SWEEP_SCENARIO), 2, "helix_ctc_analytic.yaml: not a readable MCAP log")
    fails(run("run", SWEEP_SCENARIO, "--from-log", tmp_path / "none.mcap"), 2,
          "a scenario file or --from-log LOG, not both")
    fails(run("run"), 2, "run needs a scenario file \\(or --from-log LOG")
    fmus = tmp_path / "fmus"
    fmus.mkdir()
    text = SMALL.replace("stop: 0.2", "stop: 0.05")
    scenario = write_scenario(text)
    source = scenario.read_text()
    for original in set(re.findall(r'path: "([^"]+)"', source)):  # copies the log refers to, removed below
        copy = fmus / Path(original).name
        shutil.copy(original, copy)
        source = source.replace(original, str(copy))
    scenario.write_text(source)
    small = tmp_path / "small.mcap"
    assert run("run", scenario, "--out", small, "--quiet").returncode == 0
    older = tmp_path / "older.mcap"  # as logs were before they recorded the scenario as run
    _copy_log(small, older, leave_out=DOCUMENT_ATTACHMENT)
    fails(run("run", "--from-log", older, "--out", tmp_path / "g.mcap"), 2,
          "older.mcap: the log records no scenario as run")
    (fmus / "CosimTGain.fmu").unlink()
    fails(run("run", "--from-log", small, "--out", tmp_path / "again.mcap"), 2,
          "small.mcap: components.g.path: FMU file not found: ", re.escape(str(fmus / "CosimTGain.fmu")))
    assert not (tmp_path / "again.mcap").exists() and not (tmp_path / "g.mcap").exists()


def test_a_run_of_an_ssp_archive_is_repeated_from_its_log(run, tmp_path):
    """A run of an SSP archive ran FMUs unpacked into a temporary folder removed after it: its log names the archive
    (and its SHA-256), and --from-log unpacks it again, giving the same signals bit for bit, also from the rerun's
    own log; an archive that has changed since, or is gone, is one line naming the log and the archive, exit 2.
    The fixture checks that no unpacked archive is left in the temporary folder."""
    import json

    from cosim.io.runlog import read_run

    ssp, first, again, third = (tmp_path / n for n in ("h.ssp", "first.mcap", "again.mcap", "third.mcap"))
    assert run("ssp", "export", SWEEP_SCENARIO, "-o", ssp, "--stop-time", "0.05").returncode == 0
    r = run("run", ssp, "--set", "ctl.gain.kp[1]=2e4", "--out", first, "--quiet")
    assert r.returncode == 0, r.stderr
    recorded = read_run(first).metadata["ssp"]
    assert recorded["file"] == str(ssp) and len(recorded["sha256"]) == 64, recorded
    assert run("run", "--from-log", first, "--out", again, "--quiet").returncode == 0
    assert _same_signals(first, again) > 20
    assert run("run", "--from-log", again, "--out", third, "--quiet").returncode == 0  # a rerun's log reruns too
    assert _same_signals(first, third) > 20
    assert json.loads(read_run(again).attachments["effective/scenario.json"])["components"]["ctl"]["parameters"] \
        == {"gain.kp[1]": "2e4"}  # the recorded values, not the archive's
    ssp.write_bytes(ssp.read_bytes() + b"\0")
    fails(run("run", "--from-log", first, "--out", tmp_path / "x.mcap"), 2,
          "first.mcap: the run was made from the SSP archive " + re.escape(str(ssp)) + ", which has changed since")
    ssp.unlink()
    fails(run("run", "--from-log", again, "--out", tmp_path / "x.mcap"), 2,
          "again.mcap: the run was made from the SSP archive " + re.escape(str(ssp)) + ", which is gone")
    assert not (tmp_path / "x.mcap").exists()


END_STOP_REASON = "leg 3 joint limit: q = 0.5832 m > q_max = 0.5800 m"
"""Carriage 3 past its stroke (q_max = 580 mm) where a diverging controller (kp = 1e12) drives it, as each build of the
analytic plant reports it: the joint value and the limit, as :func:`delta.kinematics.joint_limit_reason` writes them."""


def _end_stop(message: str) -> str:
    """The reason of an end stop in an error line: what follows END_STOP."""
    from delta.kinematics import END_STOP

    assert END_STOP in message, message
    return message.split(END_STOP, 1)[1]


def test_the_analytic_plant_stops_at_the_end_stop_as_the_exudyn_plant(run):
    """A diverging controller drives carriage 3 past its stroke at t = 0.138 s: both builds of the analytic plant stop
    there, as the Exudyn plant does, naming the joint, its value and the limit, in the same words (they ran on to 'the
    platform left the workspace', or to 'completed' with a carriage 1.1 m past its stroke; the native build named the
    leg only)."""
    reasons = {}
    for build in ("python", "native"):
        r = run("run", SWEEP_SCENARIO, "--stop-time", "1", "--set", "ctl.gain.kp[1]=1e12", "--set", f"fmus={build}",
                "--no-log")
        message = fails(r, 2, "component 'plant': fmi2DoStep returned discard at t = 0.138 s")
        assert "left the workspace" not in message and "completed" not in r.stdout, (message, r.stdout)
        reasons[build] = _end_stop(message)
    assert reasons["python"] == reasons["native"] == f": {END_STOP_REASON}", reasons


def test_the_model_exchange_plant_stops_at_the_end_stop_as_the_co_simulation_plant(run):
    """The model-exchange builds of the analytic plant stop at the same end stop with the same reason, checked on the
    states the master accepted: at the communication point (t = 0.139 s), where the python build's outputs are read
    and the native build's completedIntegratorStep is called. They ran on past the stroke until DOP853 gave up at
    t = 0.1847 s ('the model is stiff or diverging')."""
    me = SWEEP_SCENARIO.with_name("helix_ctc_me.yaml")
    calls = {"python": "fmi3GetFloat64 returned fatal", "native": "fmi2CompletedIntegratorStep returned error"}
    for build, call in calls.items():
        r = run("run", me, "--stop-time", "1", "--set", "ctl.gain.kp[1]=1e12", "--set", f"fmus={build}", "--no-log")
        message = fails(r, 2, f"component 'plant': {call} at t = 0.139 s")
        assert _end_stop(message) == f": {END_STOP_REASON}", message


@pytest.mark.parametrize("build", ["python", "native"])
def test_the_model_exchange_plant_checks_accepted_states_only(build, tmp_path):
    """The integrator's trial states may pass the stroke (a rejected trial step): the derivatives there are given
    without complaint; the end stop is an error only once such a state is accepted (outputs read, or
    completedIntegratorStep), in the rotary build too (the joint in degrees). Through the master's FMU access, which
    also makes a PythonFMU library safe to unload in this process."""
    from ctypes import c_double

    from cosim.errors import FMIError
    from cosim.fmi import load_fmu, make_slave
    from fmus import registry

    info = load_fmu(registry.build("rotary_analytic_plant_me" if build == "python" else "rotary_analytic_plant",
                                   tmp_path, native=build == "native", fmi=3))
    q_max = float(info.variables["geometry.q_max"].start)
    slave = make_slave("plant", info, "me")
    slave.instantiate()
    try:
        slave.setup_experiment(0.0, 1.0)
        slave.set_start({})
        slave.enter_initialization(0.0, 1.0)
        slave.bind([], [info.variables["p.x"]])
        slave.exit_initialization()
        x, dx = (c_double * 6)(), (c_double * 6)()
        slave.get_x(x)  # the platform's p then v
        x[:3] = _pose_past_the_end_stop(q_max + 0.1, [x[0], x[1], x[2]])  # q[2] 0.1 rad past it, as a trial state
        slave.set_x(x)
        slave.get_dx(dx)  # raises for a failure or a non-finite derivative
        with pytest.raises(FMIError) as failed:
            if build == "native":
                slave._completed_step()
            else:
                slave.get_outputs()
    finally:
        slave.free()
    degrees = f"{math.degrees(q_max + 0.1):.2f} deg > q_max = {math.degrees(q_max):.2f} deg"
    assert f"leg 2 joint limit: q = {degrees}" in str(failed.value), failed.value


def _pose_past_the_end_stop(q2: float, p0: list[float]) -> list[float]:
    """The rotary plant's platform where joint 2 is at ``q2`` and the others as at ``p0`` (forward kinematics)."""
    from delta.kinematics import fk, inverse_kinematics
    from delta.model import build_model
    from fmus import registry
    from fmus.adapters.common import robot_from

    adapter = registry.get("rotary_analytic_plant_me").declared()
    model = build_model(robot_from(adapter, adapter.KIND))
    q = list(inverse_kinematics(model, p0)[0])
    q[1] = q2
    return [float(c) for c in fk(model, q).require()]


@pytest.fixture(scope="module")
def plain_check(tmp_path_factory):
    """``check SWEEP_SCENARIO`` with no ``--set``: the same command for every case below, so run once for them all,
    as :func:`run` runs it (its own temporary folder, which must be left empty)."""
    tmp = tmp_path_factory.mktemp("plain_check")
    r = cosim("check", SWEEP_SCENARIO, env={**os.environ, "TMPDIR": str(tmp)})
    _left_empty(tmp)
    return r


@pytest.mark.parametrize("item, cause", [
    ("ctl.gain.kp[1]=-1", re.escape("--set ctl.gain.kp[1]=-1: ctl.gain.kp must be > 0 per joint, got [-1.0, ")),
    ("plant.mass.platform=-1", "--set plant.mass.platform=-1: plant.mass.platform must be >= 0, got -1.0"),
    ("plant.solver.max_step=0", "component 'plant': .*solver.max_step must be a time > 0 s"),
])
def test_check_refuses_what_run_refuses_at_t0_with_the_same_message(run, tmp_path, plain_check, item, cause):
    """Parameter values the FMUs refuse when they are initialized: check said ok, run failed at t = 0. The gains
    and masses of our FMUs are now refused in pre-flight (by the scenario's names), the plant's solver setting
    still by the FMU at t = 0: either way check and run say the same."""
    ran = fails(run("run", SWEEP_SCENARIO, "--set", item, "--stop-time", "0.01", "--out", tmp_path / "x.mcap"), 2,
                cause)
    checked = fails(run("check", SWEEP_SCENARIO, "--set", item), 2, cause)
    assert checked == ran, (checked, ran)
    assert plain_check.returncode == 0, plain_check.stderr


def _with_plant_values(tmp_path: Path, lines: str) -> Path:
    """helix_ctc_analytic with ``lines`` (YAML, indented as the plant's ``parameters:``) set on its plant."""
    text = SWEEP_SCENARIO.read_text().replace("  plant:\n    fmu: linear_analytic_plant\n",
                                              "  plant:\n    fmu: linear_analytic_plant\n    parameters:\n" + lines)
    text = text.replace("model: ", f"model: {SWEEP_SCENARIO.parent}/")  # the identified model, from tmp_path
    path = tmp_path / "bad_masses.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("command", ["check", "run"])
def test_a_mass_our_fmus_refuse_is_refused_in_pre_flight_at_its_line_by_its_name(run, tmp_path, command):
    """A negative payload was caught at t = 0 by the FMU, under the mass dataclass's field (``masses.payload``,
    ``LinearDeltaMasses.payload``), without the file's line, the time said twice. The pre-flight now checks our FMUs'
    robot and mass parameters as they will start, by the FMUs' own check, at the scenario's line, by the scenario's
    name; no FMU is instantiated and no log is written."""
    path = _with_plant_values(tmp_path, "      mass.rod: 0.1\n      mass.payload: -0.5\n")
    line = path.read_text().splitlines().index("      mass.payload: -0.5") + 1
    out = tmp_path / "x.mcap"
    args = (command, path) + (("--stop-time", "0.01", "--out", out) if command == "run" else ())
    fails(run(*args), 2, re.escape(f"{path}:{line}: components.plant.parameters.mass.payload: plant.mass.payload "
                                   "must be >= 0, got -0.5"))
    assert not out.exists() and not out.with_name(out.name + ".partial").exists()


def test_a_share_out_of_range_is_named_by_its_parameter_in_both_builds(run, tmp_path):
    """The class of it: every mass and geometry check of our FMUs names the FMU's parameter, in pre-flight and at
    run time (an event during the run), in the python and the native build, and says the time once."""
    fails(run("check", SWEEP_SCENARIO, "--set", "ctl.model.w_gravity=1.5"), 2,
          re.escape("--set ctl.model.w_gravity=1.5: ctl.model.w_gravity must be in [0, 1], got 1.5"))
    fails(run("check", SWEEP_SCENARIO, "--set", "ctl.geometry.rod_length=0", "--set", "fmus=python"), 2,
          re.escape("ctl.geometry.rod_length must be > 0, got 0.0"))
    # the Exudyn plant, whose model.* parameters include a String (model.fidelity)
    fails(run("check", SWEEP_SCENARIO.with_name("helix_ctc.yaml"), "--set", "plant.mass.payload=-1"), 2,
          re.escape("--set plant.mass.payload=-1: plant.mass.payload must be >= 0, got -1.0"))
    path = tmp_path / "event.yaml"
    path.write_text(SWEEP_SCENARIO.read_text() + "events:\n  - {at: 0.005, set: {plant.mass.payload: -1.0}}\n")
    path.write_text(path.read_text().replace("model: ", f"model: {SWEEP_SCENARIO.parent}/"))
    for build in ("native", "python"):
        message = fails(run("run", path, "--stop-time", "0.01", "--no-log", "--set", f"fmus={build}"), 2,
                        "component 'plant'", "mass.payload must be >= 0")
        assert message.count("t = 0.005 s") == 1 and "masses.payload" not in message \
            and "LinearDeltaMasses" not in message, message


# --------------------------------------------------------------------------- a viewer that stops reading

class _StalledViewer:
    """A WebSocket client (websockets' sans-I/O protocol on a plain socket with a small receive buffer) that speaks
    the Foxglove protocol to ``--live``'s server, subscribes to every channel it advertises, then never reads."""

    def __init__(self, port: int):
        import threading

        self.port = port
        self.subscribed = threading.Event()
        self.sock = None
        threading.Thread(target=self._run, daemon=True).start()

    def _run(self) -> None:
        import json
        import socket
        import time

        from websockets.client import ClientProtocol
        from websockets.frames import Frame, Opcode
        from websockets.typing import Subprotocol
        from websockets.uri import parse_uri

        deadline = time.monotonic() + 60
        while True:
            try:
                self.sock = socket.create_connection(("127.0.0.1", self.port), timeout=1)
                break
            except OSError:
                if time.monotonic() > deadline:
                    return
                time.sleep(0.05)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        proto = ClientProtocol(parse_uri(f"ws://127.0.0.1:{self.port}"),
                               subprotocols=[Subprotocol("foxglove.sdk.v1")], max_size=None)
        proto.send_request(proto.connect())
        self.sock.sendall(b"".join(proto.data_to_send()))
        self.sock.settimeout(10)
        subscriptions = 0
        while subscriptions < 5:  # the plant's and the scene's channels, at least
            proto.receive_data(self.sock.recv(65536))
            for event in proto.events_received():
                if isinstance(event, Frame) and event.opcode == Opcode.TEXT:
                    msg = json.loads(event.data)
                    if msg.get("op") == "advertise":
                        new = [{"id": subscriptions + i + 1, "channelId": ch["id"]}
                               for i, ch in enumerate(msg["channels"])]
                        subscriptions += len(new)
                        proto.send_text(json.dumps({"op": "subscribe", "subscriptions": new}).encode())
                        self.sock.sendall(b"".join(proto.data_to_send()))
        self.subscribed.set()  # and from here on, never a read

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()


LIVE_STOP = 3.0  # s simulated, at wall-clock pace


def test_a_viewer_that_stops_reading_does_not_hold_the_run(tmp_path):
    """The run ends on time, exit 0, its log finished; the viewer is dropped with one warning line (it held a 10 s
    run 51 s, until the viewer disconnected), beside at most a few lines of what the server logged of it."""
    import time

    from cli_helpers import free_port

    from cosim.observers.live import STOP_TIMEOUT, ViewerMessages
    from cosim.io.runlog import read_run

    port, out = free_port(), tmp_path / "live.mcap"
    viewer = _StalledViewer(port)
    t0 = time.monotonic()
    try:
        r = cosim("run", SWEEP_SCENARIO, "--stop-time", LIVE_STOP, "--live", port, "--realtime", "--out", out,
                  "--quiet", timeout=60)
        wall = time.monotonic() - t0
    finally:
        viewer.close()
    assert viewer.subscribed.is_set(), "the viewer never subscribed"
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    lines = r.stderr.strip().splitlines()
    dropped = [ln for ln in lines if ln.startswith(f"warning: live view on ws://localhost:{port}: a viewer did not "
                                                   f"take the end of the run within {STOP_TIMEOUT:g} s")]
    # besides: what the server logged of the viewer (it subscribes to a channel that is gone), a few escaped lines
    server = [ln for ln in lines if ln.startswith("warning: live view: ")]
    assert len(dropped) == 1 and len(lines) == 1 + len(server) <= 2 + ViewerMessages.SHOWN_LINES, r.stderr
    assert wall < LIVE_STOP + STOP_TIMEOUT + 30, f"{wall:.1f} s for a {LIVE_STOP} s run"  # start-up included
    assert read_run(out).status == "completed"


def _logged_span_s(partial: Path) -> float:
    """Seconds between the first and the last message the log being written, ``partial``, holds so far (read up
    to where its writer has got; 0 before it has two). Chunks are read by their headers' message times, not
    decompressed: under the suite's load, decoding every message of the growing file took over a second a look,
    and the signal then came after the end's wait it is meant to land in."""
    from mcap.exceptions import McapError
    from mcap.records import Chunk, Message
    from mcap.stream_reader import StreamReader

    first = last = None
    try:
        with open(partial, "rb") as f:
            for record in StreamReader(f, emit_chunks=True).records:
                if isinstance(record, Chunk):
                    start, end = record.message_start_time, record.message_end_time
                elif isinstance(record, Message):
                    start = end = record.log_time
                else:
                    continue
                first = start if first is None else min(first, start)
                last = end if last is None else max(last, end)
    except (OSError, McapError):  # not there yet, or its end still being written
        pass
    return 0.0 if first is None else (last - first) / 1e9


@pytest.mark.parametrize("sig, code", [("SIGTERM", 143), ("SIGINT", 130)])
def test_a_signal_at_the_end_with_a_stalled_viewer_stops_it_and_keeps_the_log(tmp_path, sig, code):
    """A signal once a 3 s run at wall-clock pace has logged its end, while the server waits for the stalled viewer
    (or, at worst, within its last 0.05 s): the process stops with the signal's exit code and keeps its
    finished log (the wait ignored SIGINT, and after SIGTERM the finished log was deleted)."""
    import signal
    import time

    from cli_helpers import free_port, start_cosim

    from cosim.io.runlog import read_run

    port, out = free_port(), tmp_path / "live.mcap"
    viewer = _StalledViewer(port)
    proc = start_cosim("run", SWEEP_SCENARIO, "--stop-time", LIVE_STOP, "--live", port, "--realtime", "--out", out,
                       "--quiet")
    try:
        assert viewer.subscribed.wait(60), "the viewer never subscribed"  # seen up to a second into the loop
        partial = out.with_name(out.name + ".partial")
        deadline = time.monotonic() + 60
        # until the log holds the loop's last 0.05 s: the loop has ended (or ends within 0.05 s at wall-clock pace)
        # and the end's wait for the viewer (2 s) has begun at most the writer's lag (about 0.5 s) ago. Not a fixed
        # sleep after an earlier point: under the suite's load, 1 s more once the log reached 2.5 s was past the wait
        while _logged_span_s(partial) < LIVE_STOP - 0.05 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert proc.poll() is None, f"the run ended before its log reached {LIVE_STOP - 0.05} s: {proc.communicate()}"
        proc.send_signal(getattr(signal, sig))
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
        viewer.close()
    assert proc.returncode == code and "Traceback" not in err, (proc.returncode, err)
    assert f"interrupted ({sig})" in err.strip().splitlines()[-1], err
    assert out.exists() and not out.with_name(out.name + ".partial").exists(), sorted(os.listdir(tmp_path))
    assert read_run(out).status in ("completed", "interrupted"), read_run(out).status


def test_sigterm_with_a_stalled_viewer_keeps_the_log(tmp_path):
    """SIGTERM while a viewer has stopped reading: the run stops, says so, finishes and keeps its log (the finished
    log was deleted)."""
    import signal
    import time

    from cli_helpers import free_port, start_cosim

    from cosim.io.runlog import read_run

    port, out = free_port(), tmp_path / "live.mcap"
    viewer = _StalledViewer(port)
    proc = start_cosim("run", SWEEP_SCENARIO, "--stop-time", "30", "--live", port, "--realtime", "--out", out,
                       "--quiet")
    try:
        assert viewer.subscribed.wait(60), "the viewer never subscribed"
        time.sleep(0.5)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
        viewer.close()
    assert proc.returncode == 143 and "Traceback" not in err, err
    assert "interrupted (SIGTERM)" in err.strip().splitlines()[-1], err
    assert out.exists() and not out.with_name(out.name + ".partial").exists(), sorted(os.listdir(tmp_path))
    assert read_run(out).status == "interrupted"
