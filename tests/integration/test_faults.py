"""Fault battery: bad inputs and faults through ``python -m cosim``, as a user or a supervisor meets them.

Every case runs the CLI as a subprocess and asserts its exit code, a one-line message that names
the culprit (argparse errors: the usage, then that line), no Python traceback, and where a log
was written, that it is readable (finished, with its outcome) or recoverable (``.partial``).
Cases: options, scenarios, FMUs, paths, signals, stalled and diverging runs, a full disk (a
2 MB tmpfs when this process may mount one, else a file-size limit: the same failed write),
concurrent writers. Short stop times and tiny FMUs keep the whole battery fast.
"""

from __future__ import annotations

import json
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from cli_helpers import cosim, start_cosim, wait_for
from fmu_helpers import SLOW_SCENARIO

from cosim.io.runlog import read_run

pytestmark = pytest.mark.integration

SMALL = """
name: small
components:
  src: {path: "{CosimTSource}"}
  g: {path: "{CosimTGain}", parameters: {k: 2.0}}
connections:
  - {from: src.y, to: g.u}
time: {stop: 0.2, step: 0.01}
"""

LOOP = """
name: loop
components:
  src: {path: "{CosimTSource}"}
  g: {path: "{CosimTGain}"}
  sum: {path: "{CosimTSum}"}
  ctl: {path: "{CosimTGain}", parameters: {k: -5.0}}
  plant: {path: "{CosimTIntegrator}", parameters: {x0: 0.5}}
connections:
  - {from: src.y, to: g.u}
  - {from: g.y, to: sum.a}
  - {from: plant.x, to: sum.b}
  - {from: sum.y, to: ctl.u}
  - {from: ctl.y, to: plant.u}
time: {stop: 400.0, step: 0.001}
logging: {flush_interval: 0.1}
"""  # src and g are feed-forward (the worker's with --parallel on); 400k steps: stopped by the tests

SLOW = SLOW_SCENARIO


def fails(r, code: int, *patterns: str, usage: bool = False) -> str:
    """Exit ``code``, no traceback, one message line matching every pattern (after argparse's usage)."""
    err = r.stderr
    assert "Traceback" not in err, f"traceback on stderr:\n{err}"
    assert r.returncode == code, f"exit {r.returncode} vs {code}; stderr:\n{err}"
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert lines, "no message on stderr"
    if not usage:
        assert len(lines) == 1, f"{len(lines)} lines on stderr, expected one:\n{err}"
    message = lines[-1]
    for p in patterns:
        assert re.search(p, message), f"message does not match {p!r}: {message}"
    return message


def outcome(path: Path) -> dict:
    """The finished log's outcome metadata (the log must be readable)."""
    return read_run(path).metadata.get("outcome", {})


@pytest.fixture
def scen(write_scenario):
    """Write a scenario from one of the templates above, with extra YAML appended."""

    def write(template: str, extra: str = "", name: str = "s.yaml") -> Path:
        return write_scenario(template + extra, name)

    return write


# --------------------------------------------------------------------------- options and the CLI


@pytest.mark.parametrize("args", [("robot", "ik", "--help"), ("robot", "fk", "--help"),
                                  ("run", "--help"), ("--version",)])
def test_help_and_version(args):
    r = cosim(*args)
    assert r.returncode == 0 and "Traceback" not in r.stderr, f"exit {r.returncode}: {r.stderr}"
    if args == ("--version",):
        assert re.search(r"\(delta-cosim\) \d+\.\d+", r.stdout), r.stdout


def test_the_console_script_is_the_same_command():
    """The install's ``delta-cosim`` script (README) runs the same CLI as ``python -m cosim``."""
    script = Path(sys.executable).with_name("delta-cosim")
    if not script.is_file():
        pytest.skip(f"no {script}: the package is not installed into this interpreter's environment")
    got = subprocess.run([str(script), "--version"], capture_output=True, text=True, timeout=120)
    assert got.returncode == 0 and got.stdout == cosim("--version").stdout, (got.stdout, got.stderr)
    helped = subprocess.run([str(script), "fmus", "--help"], capture_output=True, text=True, timeout=120)
    assert helped.returncode == 0 and "info" in helped.stdout, helped.stdout


@pytest.mark.parametrize("args, patterns", [
    (("robot", "ik", "--robot", "linear_delta_thesis", "1", "2"), ["required: Z"]),
    (("robot", "fk", "--robot", "linear_delta_thesis", "0.1", "0.1"), ["required: Q3"]),
    (("robot", "ik", "--robot", "linear_delta_thesis", "a", "0", "0"), ["invalid float value: 'a'"]),
    (("run", "scenarios/helix_ctc_analytic.yaml", "--outt", "x.mcap"), ["--outt", "did you mean --out"]),
    (("rn", "x.yaml"), ["invalid choice: 'rn'", "did you mean run"]),
    (("robot", "ikk"), ["invalid choice: 'ikk'", "did you mean ik"]),
])
def test_bad_options_name_the_option_and_suggest(args, patterns):
    fails(cosim(*args), 2, *patterns, usage=True)


@pytest.mark.parametrize("args, patterns", [
    (("robot", "fk", "--robot", "linear_delta_thesis", "0.3", "0.3", "0.3", "--deg", "--mm"),
     ["^error: --deg: linear_delta_thesis is a linear delta"]),
    (("robot", "fk", "--robot", "rotary_delta_prototype", "10", "10", "10", "--mm"),
     ["^error: --mm: rotary_delta_prototype is a rotary delta"]),
    (("robot", "singularity", "--robot", "rotary_delta_prototype", "--q", "0", "0", "0", "--mm"),
     ["^error: --mm: rotary_delta_prototype"]),
    (("robot", "ik", "--robot", "linear_delta", "0", "0", "-0.6"),
     ["unknown preset 'linear_delta'", "did you mean linear_delta_thesis"]),
    (("robot", "ik", "--robot", "linear_delta_thesis", "0.5", "0", "-0.6"), ["leg 1 has no solution"]),
])
def test_robot_errors_are_one_line(args, patterns):
    fails(cosim(*args), 2, *patterns)


def test_unit_flags_that_apply_are_accepted():
    r = cosim("robot", "ik", "--robot", "rotary_delta_prototype", "0", "0", "-561", "--mm", "--deg", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["q_unit"] == "deg" and abs(out["q"][0] - 38.1694) < 1e-3, out  # seed 004: 38 deg at z = -561 mm
    r = cosim("robot", "singularity", "--robot", "rotary_delta_prototype", "--p", "0", "0", "-561", "--mm")
    assert r.returncode == 0 and "proximity" in r.stdout, r.stderr


def test_json_unreachable_pose_prints_a_json_error():
    r = cosim("robot", "ik", "--robot", "linear_delta_thesis", "0.5", "0", "-0.6", "--json")
    fails(r, 2, "leg 1 has no solution")
    out = json.loads(r.stdout)
    assert out["ok"] is False and "leg 1 has no solution" in out["error"], out


# --------------------------------------------------------------------------- scenarios (nothing instantiated)


def test_missing_scenario(tmp_path):
    fails(cosim("check", tmp_path / "nope.yaml"), 2, "nope.yaml", "cannot read scenario")


def test_scenario_not_utf8(tmp_path):
    p = tmp_path / "latin1.yaml"
    p.write_bytes("name: caf\xe9\n".encode("latin-1"))
    fails(cosim("check", p), 2, r"latin1.yaml:1: ", "not UTF-8", "0xe9")


def test_invalid_yaml_names_the_line(scen):
    fails(cosim("check", scen(SMALL, "time: [\n")), 2, r"s.yaml:\d+: ", "invalid YAML")


def test_unknown_key_names_file_line_and_key(scen):
    fails(cosim("check", scen(SMALL, "colour: red\n")), 2, r"s.yaml:\d+: colour: unknown key")


def test_unknown_component_in_a_connection(scen):
    fails(cosim("check", scen(SMALL.replace("to: g.u", "to: gg.u"))), 2, "unknown component 'gg'", "did you mean g")


def test_unknown_variable_in_a_connection(scen):
    fails(cosim("check", scen(SMALL.replace("to: g.u", "to: g.uu"))), 2, "has no variable 'uu'", "did you mean u")


@pytest.mark.parametrize("command", ["check", "run"])
def test_set_value_of_the_wrong_type_cites_the_option(scen, tmp_path, command):
    extra = ["--out", tmp_path / "x.mcap"] if command == "run" else []
    r = cosim(command, scen(SMALL), "--set", "g.k=abc", *extra)
    fails(r, 2, r"^error: --set g\.k=abc: k is Real: expected a number, got 'abc'$")
    assert not list(tmp_path.glob("x.mcap*")), "a failed validation left output files"


@pytest.mark.parametrize("item, patterns", [
    ("gg.k=1", [r"--set gg\.k=1", "unknown .*'gg'", "did you mean g"]),
    ("g.kk=1", [r"--set g\.kk=1", "has no variable 'kk'", "did you mean k"]),
    ("g.k", ["--set", "expected"]),
    ("g.k=[1", [r"--set g\.k=\[1", "invalid value"]),
])
def test_bad_set_items(scen, item, patterns):
    fails(cosim("check", scen(SMALL), "--set", item), 2, *patterns)


def test_set_number_in_exponent_form_is_a_number(scen):
    r = cosim("check", scen(SMALL), "--set", "g.k=1e12")  # YAML 1.1 reads 1e12 as a string
    assert r.returncode == 0, r.stderr


def test_stop_time_off_the_grid_names_the_option(scen):
    fails(cosim("check", scen(SMALL), "--stop-time", "0.105"), 2, "not a whole number of steps",
          r"--stop-time 0\.105")


@pytest.mark.parametrize("param, value, pattern", [
    ("Int8_parameter", "300", r"Int8: expected a whole number in -128\.\.127, got 300"),
    ("Int32_parameter", "1.5", "expected a whole number"),
    ("Boolean_parameter", "abc", "expected true or false"),
    ("Float64_parameter", "true", "expected a number, got True"),
])
def test_third_party_parameter_types(tmp_path, param, value, pattern):
    from cfmus import build

    p = tmp_path / "ft.yaml"
    p.write_text(f"name: ft\ncomponents:\n  ft: {{path: \"{build('Feedthrough', 3)}\"}}\n"
                 f"time: {{stop: 0.1, step: 0.01}}\n")
    fails(cosim("check", p, "--set", f"ft.{param}={value}"), 2, rf"^error: --set ft\.{param}=", pattern)


def test_unreachable_trajectory_is_refused_before_running(tmp_path):
    fails(cosim("run", "scenarios/helix_ctc_analytic.yaml", "--set", "trajectory.params.rx=0.6",
                "--out", tmp_path / "x.mcap"), 2, "out of workspace at t = ")
    assert not list(tmp_path.iterdir()), "a refused run left output files"


def test_algebraic_loop(scen):
    text = SMALL + "  - {from: g.y, to: src.amplitude}\n"
    r = cosim("check", scen(text))
    assert "Traceback" not in r.stderr and r.returncode == 2, r.stderr


# --------------------------------------------------------------------------- FMUs


def test_fmu_file_missing(scen):
    fails(cosim("check", scen(SMALL.replace("{CosimTSource}", "missing.fmu"))), 2, "FMU file not found",
          "missing.fmu")


def test_fmu_file_not_a_zip(scen, tmp_path):
    bad = tmp_path / "bad.fmu"
    bad.write_bytes(b"not a zip archive")
    r = cosim("check", scen(SMALL.replace("{CosimTSource}", str(bad))))
    fails(r, 2, "bad.fmu")


def test_clocked_fmu_is_refused(tmp_path):
    from cfmus import build

    p = tmp_path / "clk.yaml"
    p.write_text(f"name: clk\ncomponents:\n  c: {{path: \"{build('Clocked', 3)}\"}}\ntime: {{stop: 0.1, step: 0.01}}\n")
    fails(cosim("check", p), 2, "[Cc]lock")


def test_rejected_step_names_component_function_and_time(tmp_path):
    from cfmus import build

    p = tmp_path / "stair.yaml"
    p.write_text(f"name: stair\ncomponents:\n  st: {{path: \"{build('Stair', 2)}\", parameters: {{t_reject: 0.55}}}}\n"
                 f"time: {{stop: 1.0, step: 0.1}}\n")
    out = tmp_path / "st.mcap"
    fails(cosim("run", p, "--out", out, "--quiet"), 2, "component 'st'", "fmi2DoStep", r"t = 0\.5 s")
    o = outcome(out)
    assert o.get("status") == "error" and "fmi2DoStep" in o.get("message", ""), o


def test_termination_by_the_fmu_is_a_normal_end(tmp_path):
    from cfmus import build

    p = tmp_path / "stair.yaml"
    p.write_text(f"name: stair\ncomponents:\n  st: {{path: \"{build('Stair', 3)}\", "
                 f"parameters: {{t_terminate: 0.35}}}}\ntime: {{stop: 1.0, step: 0.1}}\n")
    out = tmp_path / "st.mcap"
    r = cosim("run", p, "--out", out)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    assert outcome(out).get("terminated_by") == "st", outcome(out)


def test_exception_inside_an_fmu(scen, tmp_path):
    text = SMALL.replace('g: {path: "{CosimTGain}", parameters: {k: 2.0}}',
                         'g: {path: "{CosimTRaiser}", parameters: {fail_time: 0.1}}')
    out = tmp_path / "r.mcap"
    fails(cosim("run", scen(text), "--out", out, "--quiet"), 2, "component 'g'", r"t = 0\.1")
    assert outcome(out).get("status") == "error", outcome(out)


# --------------------------------------------------------------------------- stalls and diverging runs


def test_stalled_python_step_is_unwound_and_named(scen, tmp_path):
    """A step looping in Python (an ODE solver taking ever smaller steps) is unwound by the watchdog."""
    out = tmp_path / "p.mcap"
    t0 = time.monotonic()
    r = cosim("run", scen(SLOW + "watchdog_s: 1.0\n"), "--out", out, "--quiet", "--set", "ramp.spin=100")
    fails(r, 2, "component 'ramp'", "no progress for 1 s", r"at t = 0 s")
    assert time.monotonic() - t0 < 30, "the watchdog did not unwind the spinning step"
    o = outcome(out)
    assert o.get("status") == "stalled" and "'ramp'" in o.get("message", ""), o


def test_diverging_run_ends_named(tmp_path):
    """Absurd gains on the analytic plant (issue 15: its ODE solver used to hang there): a named end,
    the plant's own error or the watchdog's, and a finished log either way."""
    out = tmp_path / "h.mcap"
    r = cosim("run", "scenarios/helix_ctc_analytic.yaml", "--set", "ctl.limit.u_max=1e300",
              "--set", "ctl.gain.kp[1]=1e12", "--watchdog", "3", "--parallel", "off", "--out", out, "--quiet")
    fails(r, 2, "component 'plant'", r"t = 0\.00\d+ s")
    o = outcome(out)
    assert o.get("status") in ("error", "stalled") and "'plant'" in o.get("message", ""), o


def test_stall_outside_python_finishes_the_log_and_exits(scen, tmp_path):
    """A step that never returns to Python (here: sleeping in C) cannot be unwound: hard exit, log finished."""
    out = tmp_path / "s.mcap"
    t0 = time.monotonic()
    r = cosim("run", scen(SLOW.replace("delay: 0.002", "delay: 0.0") + "watchdog_s: 1.0\n"), "--out", out, "--quiet",
              "--set", "ramp.delay=100")
    fails(r, 2, "component 'ramp'", "no progress for 1 s")
    assert time.monotonic() - t0 < 30, "the hard exit waited for the sleeping step"
    assert outcome(out).get("status") == "stalled", outcome(out)


# --------------------------------------------------------------------------- signals


def _started(proc: subprocess.Popen, partial: Path) -> None:
    wait_for(lambda: partial.exists() and partial.stat().st_size > 4096 or proc.poll() is not None,
             what="the run to log")
    assert proc.poll() is None, f"run ended early: {proc.communicate()}"


@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130), (signal.SIGHUP, 129)])
def test_signal_finishes_and_marks_the_log(scen, tmp_path, sig, code):
    out = tmp_path / "int.mcap"
    proc = start_cosim("run", scen(SLOW), "--out", out, "--quiet")
    _started(proc, out.with_name("int.mcap.partial"))
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=30)
    fails(subprocess.CompletedProcess(proc.args, proc.returncode, "", err), code,
          rf"^interrupted \({signal.Signals(sig).name}\)")
    assert outcome(out).get("status") == "interrupted", outcome(out)


def test_signal_during_a_stalled_step(scen, tmp_path):
    out = tmp_path / "st.mcap"
    stepping = tmp_path / "stepping"  # the ramp creates it as its first step begins its 100 s sleep
    proc = start_cosim("run", scen(SLOW), "--out", out, "--quiet", "--set", "ramp.delay=100", "--watchdog", "0",
                       env={**os.environ, "COSIM_T_SLOW_STEPPING": str(stepping)})
    wait_for(lambda: stepping.exists() or proc.poll() is not None, what="the ramp's first step")
    assert proc.poll() is None, f"run ended early: {proc.communicate()}"
    t0 = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    fails(subprocess.CompletedProcess(proc.args, proc.returncode, "", err), 143, r"interrupted \(SIGTERM\)",
          "component 'ramp' did not return")
    assert time.monotonic() - t0 < 10, "SIGTERM took too long to end a stalled run"
    assert outcome(out).get("status") == "interrupted", outcome(out)


def _children(pid: int) -> list[int]:
    try:
        return [int(x) for x in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[1].split()[0] not in ("Z", "X")
    except OSError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_worker_does_not_outlive_its_master(scen, tmp_path, sig):
    out = tmp_path / "w.mcap"
    proc = start_cosim("run", scen(LOOP), "--out", out, "--quiet", "--parallel", "on")
    _started(proc, out.with_name("w.mcap.partial"))
    workers = _children(proc.pid)
    assert workers, "no worker process"
    partial = out.with_name("w.mcap.partial")
    size = partial.stat().st_size
    wait_for(lambda: partial.stat().st_size > size, what="a flushed chunk of messages")
    proc.send_signal(sig)
    proc.communicate(timeout=30)
    wait_for(lambda: not any(_alive(w) for w in workers), timeout=10, what="the worker to exit")
    if sig == signal.SIGTERM:
        assert proc.returncode == 143 and outcome(out).get("status") == "interrupted", proc.returncode
    else:  # killed: the partial log stays, a new run refuses to overwrite it, recover reads it
        partial = out.with_name("w.mcap.partial")
        assert partial.exists() and not out.exists(), sorted(p.name for p in tmp_path.iterdir())
        fails(cosim("run", scen(SMALL), "--out", out), 2, "w.mcap.partial: left by a run that did not finish")
        r = cosim("recover", partial)
        assert r.returncode == 0 and (tmp_path / "w.recovered.mcap").exists(), r.stderr
        assert len(read_run(tmp_path / "w.recovered.mcap").signals) > 0


# --------------------------------------------------------------------------- output paths


def test_out_parent_is_a_file(scen, tmp_path):
    (tmp_path / "file").write_text("x")
    r = cosim("run", scen(SMALL.replace("{CosimTSource}", "missing.fmu")), "--out", tmp_path / "file" / "x.mcap")
    fails(r, 2, "file is a file, not a directory")  # the output is checked before any FMU is looked at


def test_out_is_a_directory(scen, tmp_path):
    fails(cosim("run", scen(SMALL), "--out", tmp_path), 2, "is a directory")


@pytest.fixture
def read_only_dir(tmp_path):
    d = tmp_path / "ro"
    d.mkdir()
    if os.geteuid() != 0:
        d.chmod(0o555)
        yield d
        d.chmod(0o755)
        return
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=64k", "tmpfs", str(d)], capture_output=True).returncode:
        pytest.skip("running as root without permission to mount a read-only tmpfs")
    yield d
    subprocess.run(["umount", str(d)], capture_output=True)


def test_out_in_a_read_only_directory(scen, read_only_dir):
    r = cosim("run", scen(SMALL.replace("{CosimTSource}", "missing.fmu")), "--out", read_only_dir / "x.mcap")
    fails(r, 2, "x.mcap: cannot write in", "(Read-only file system|Permission denied)")


def test_two_runs_on_one_path(scen, tmp_path):
    out = tmp_path / "c.mcap"
    # 300 steps of 10 ms wall each: long enough for the second command to start on a loaded machine
    first = start_cosim("run", scen(SLOW.replace("stop: 20.0", "stop: 3.0").replace("delay: 0.002", "delay: 0.01")),
                        "--out", out, "--quiet")
    _started(first, out.with_name("c.mcap.partial"))
    second = cosim("run", scen(SMALL, name="other.yaml"), "--out", out)
    fails(second, 2, f"another run \\(pid {first.pid}, started", "is writing it")
    _, err = first.communicate(timeout=60)
    assert first.returncode == 0, err
    assert outcome(out).get("status") == "completed", outcome(out)
    assert not out.with_name("c.mcap.lock").exists() and not out.with_name("c.mcap.partial").exists()


# --------------------------------------------------------------------------- full disk


@pytest.fixture
def small_disk(tmp_path):
    """(directory, preexec_fn): a 2 MB tmpfs when we may mount one; else a 2 MB file-size limit on the
    child (RLIMIT_FSIZE, SIGXFSZ ignored: writes past it fail with EFBIG as they would with ENOSPC)."""
    d = tmp_path / "disk"
    d.mkdir()
    if os.geteuid() == 0 and not subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(d)],
                                                capture_output=True).returncode:
        yield d, None
        subprocess.run(["umount", str(d)], capture_output=True)
        return

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (2 << 20, 2 << 20))

    yield d, limit


def test_disk_full_is_one_error_and_a_recoverable_log(small_disk, tmp_path):
    disk, limit = small_disk
    out = disk / "x.mcap"
    r = cosim("run", "scenarios/helix_ctc_analytic.yaml", "--out", out, "--quiet", preexec_fn=limit)
    fails(r, 2, "x.mcap.partial: cannot write the MCAP log", "(no space left on device|File too large)",
          "recover it with")
    partial = disk / "x.mcap.partial"
    assert partial.exists() and not out.exists(), sorted(p.name for p in disk.iterdir())
    # recover onto the full disk: refused, and no empty or truncated file is left behind
    r = cosim("recover", partial, preexec_fn=limit)
    fails(r, 2, "x.recovered.mcap: cannot write the recovered log", "nothing was written")
    assert sorted(p.name for p in disk.iterdir()) == ["x.mcap.lock", "x.mcap.partial"] or \
        sorted(p.name for p in disk.iterdir()) == ["x.mcap.partial"], sorted(p.name for p in disk.iterdir())
    r = cosim("recover", partial, "--out", tmp_path / "fixed.mcap")
    assert r.returncode == 0, r.stderr
    log = read_run(tmp_path / "fixed.mcap")
    assert log.signals["plant.p.x"].t[-1] > 0.5, "less than 0.5 s recovered from the full disk"


# --------------------------------------------------------------------------- recover and compare


def test_recover_missing_and_not_mcap(tmp_path):
    fails(cosim("recover", tmp_path / "none.mcap"), 2, "none.mcap: no such file")
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(os.urandom(4096))
    fails(cosim("recover", junk), 2, "junk.mcap: not an MCAP log")
    assert not (tmp_path / "junk.recovered.mcap").exists()


def test_compare_same_verdict_either_order_and_bad_inputs(scen, tmp_path):
    fine, coarse = tmp_path / "fine.mcap", tmp_path / "coarse.mcap"
    assert cosim("run", scen(SMALL), "--out", fine, "--quiet").returncode == 0
    assert cosim("run", scen(SMALL), "--out", coarse, "--quiet", "--step", "0.05").returncode == 0
    ab = cosim("compare", fine, coarse, "--tol", "g.y=1e-12", "--json")
    ba = cosim("compare", coarse, fine, "--tol", "g.y=1e-12", "--json")
    assert ab.returncode == ba.returncode == 0, (ab.stdout, ba.stdout)
    assert json.loads(ab.stdout)["signals"][0]["samples"] == 5, ab.stdout  # the 50 ms stamps
    fails(cosim("compare", fine, tmp_path / "missing.mcap"), 2, "missing.mcap: no such file")
    shutil.copy(fine, tmp_path / "cut.mcap")
    with open(tmp_path / "cut.mcap", "r+b") as f:
        f.truncate(os.path.getsize(fine) // 2)
    fails(cosim("compare", fine, tmp_path / "cut.mcap"), 2, "cut.mcap: cannot read the MCAP log",
          "python -m cosim recover")


def test_a_closed_terminal_stops_every_process_of_the_run_cleanly(tmp_path):
    """SIGHUP reaches the whole process group (master, worker, log writer): the master stops the run and
    finishes the log; its processes leave that to it (issue 25: the class of signals, every process)."""
    import os

    out = tmp_path / "hup.mcap"
    scenario = Path(__file__).resolve().parents[2] / "scenarios" / "helix_ctc_analytic.yaml"
    proc = subprocess.Popen([sys.executable, "-m", "cosim", "run", str(scenario), "--stop-time", "30", "--parallel",
                             "on", "--realtime", "--out", str(out), "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    try:
        _started(proc, out.with_name("hup.mcap.partial"))
        os.killpg(proc.pid, signal.SIGHUP)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 129, err.decode()
    assert "interrupted (SIGHUP)" in err.decode(), err.decode()
    assert out.exists() and not out.with_name("hup.mcap.partial").exists(), sorted(p.name for p in tmp_path.iterdir())
    assert outcome(out).get("status") == "interrupted", outcome(out)
