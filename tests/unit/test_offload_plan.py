"""Which components run ahead in the worker: the feed-forward group and the auto rules."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.engine import offload
from cosim.fmi import Variable
from cosim.engine.offload import AUTO_MIN_STEPS, choose, feedforward
from cosim.engine.system import Link, Port, SystemPlan


def _var(name: str, causality: str, kind: str = "Real") -> Variable:
    return Variable(name, 0, kind, kind, causality, "continuous", None, None, None, 1)


def _plan(names: list[str], wires: list[tuple[str, str]], order: list[str] | None = None,
          kind: str = "Real") -> SystemPlan:
    """``wires`` as (source component, destination component): y of the source to a fresh input."""
    idx = {n: i for i, n in enumerate(names)}
    links = [Link(Port(idx[a], _var("y", "output", kind)), Port(idx[b], _var(f"u{k}", "input")))
             for k, (a, b) in enumerate(wires)]
    outputs = [[_var("y", "output", kind)] for _ in names]
    return SystemPlan(names, [None] * len(names), links, [idx[n] for n in (order or names)],
                      [{} for _ in names], [[] for _ in names], outputs)


HELIX = (["traj", "ik", "ctl", "plant"], [("traj", "ik"), ("ik", "ctl"), ("plant", "ctl"), ("ctl", "plant")])


def test_feedforward_group_of_the_helix_chain_is_trajectory_and_ik():
    plan = _plan(*HELIX)
    assert [plan.names[c] for c in feedforward(plan)] == ["traj", "ik"]


def test_a_component_fed_by_the_loop_is_not_feedforward():
    names = ["src", "ctl", "plant", "monitor", "ff"]
    wires = [("src", "ctl"), ("plant", "ctl"), ("ctl", "plant"), ("plant", "monitor"), ("src", "ff")]
    plan = _plan(names, wires, order=["plant", "src", "ff", "ctl", "monitor"])
    assert [plan.names[c] for c in feedforward(plan)] == ["src", "ff"]  # in plan order


def test_self_loop_and_pure_loop_have_no_group():
    assert feedforward(_plan(["a"], [("a", "a")])) == []
    assert feedforward(_plan(["a", "b"], [("a", "b"), ("b", "a")])) == []


def _tools(plan: SystemPlan, tool: str | None) -> SystemPlan:
    """Every component's FMU made by ``tool`` (its modelDescription's generationTool)."""
    from types import SimpleNamespace

    plan.infos[:] = [SimpleNamespace(md=SimpleNamespace(generationTool=tool),
                                     structural_parameters=lambda: []) for _ in plan.names]
    return plan


PYTHON_FMU = "PythonFMU 0.7.0"


@pytest.mark.parametrize("mode,steps,cpus,expect", [
    ("off", 10**6, 2, []),
    ("auto", AUTO_MIN_STEPS, 2, ["traj", "ik"]),
    ("auto", AUTO_MIN_STEPS - 1, 2, []),
    ("auto", 10**6, 1, []),
    ("on", 10, 1, ["traj", "ik"]),
])
def test_choose_follows_mode_length_and_cpus(monkeypatch, mode, steps, cpus, expect):
    monkeypatch.setattr(offload, "usable_cpus", lambda: cpus)
    monkeypatch.setattr(offload, "busy_cpus", lambda: 0)
    plan = _tools(_plan(*HELIX), PYTHON_FMU)
    comps, note = choose(plan, mode, steps)
    assert [plan.names[c] for c in comps] == expect, note
    if expect:
        assert note == "parallel: traj, ik run ahead in a worker process", note
    elif mode != "off":
        assert note.startswith(f"parallel: {mode}: serial run ("), note


@pytest.mark.parametrize("tool", [None, "CasADi", "OpenModelica Compiler"])
def test_auto_runs_compiled_fmus_serially(monkeypatch, tool):
    """A feed-forward group of compiled FMUs stays in the master under auto (a worker does not pay for steps of
    about a microsecond: issue 36 item 5); ``on`` still offloads it."""
    monkeypatch.setattr(offload, "usable_cpus", lambda: 4)
    monkeypatch.setattr(offload, "busy_cpus", lambda: 0)
    plan = _tools(_plan(*HELIX), tool)
    comps, note = choose(plan, "auto", 10**6)
    assert comps == [] and note == ("parallel: auto: serial run (traj, ik are compiled FMUs, whose steps a worker "
                                    "would hardly take off the master)"), note
    assert [plan.names[c] for c in choose(plan, "on", 10**6)[0]] == ["traj", "ik"]


@pytest.mark.parametrize("cpus,busy,expect", [(2, 0, ["traj", "ik"]), (2, 1, []), (4, 2, ["traj", "ik"]),
                                              (4, 3, [])])
def test_auto_runs_serially_when_other_processes_keep_the_cpus_busy(monkeypatch, cpus, busy, expect):
    monkeypatch.setattr(offload, "usable_cpus", lambda: cpus)
    monkeypatch.setattr(offload, "busy_cpus", lambda: busy)
    plan = _tools(_plan(*HELIX), PYTHON_FMU)
    comps, note = choose(plan, "auto", 10**6)
    assert [plan.names[c] for c in comps] == expect, note
    if not expect:
        assert note == (f"parallel: auto: serial run ({cpus} CPUs, {busy} kept busy by other processes: no free CPU "
                        "for a worker)"), note


def test_busy_cpus_counts_a_spinning_process(tmp_path):
    """busy_cpus reads the kernel's runnable count: a process spinning on a CPU is counted (Linux only)."""
    import subprocess
    import sys
    import time

    if not Path("/proc/loadavg").exists():
        pytest.skip("no /proc/loadavg (not Linux)")
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        deadline = time.monotonic() + 30  # until both have started spinning (slow on a loaded machine)
        while (busy := offload.busy_cpus()) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        for p in spinners:
            p.kill()
            p.wait()
    assert busy >= 2, f"two spinning processes, busy_cpus() = {busy}"


def test_choose_explains_why_not():
    _, note = choose(_plan(["a", "b"], [("a", "b"), ("b", "a")]), "on", 10**6)
    assert note == "parallel: on: serial run (every component is in a feedback loop)", note
    _, note = choose(_plan(["a", "b"], [("a", "b")]), "on", 10**6)
    assert "every component is feed-forward" in note, note
    _, note = choose(_plan(*HELIX, kind="String"), "on", 10**6)
    assert "traj.y, ik.y are strings" in note, note


@pytest.mark.parametrize("cpus,busy,expect", [(2, 0, []), (3, 0, ["traj", "ik"]), (3, 1, [])])
def test_auto_leaves_a_cpu_to_the_log_writer(monkeypatch, cpus, busy, expect):
    """A log written by a writer process takes a CPU: PythonFMU feed-forward components run ahead only when
    another CPU is free besides it; ``on`` is obeyed, and without the writer process auto offloads as before."""
    monkeypatch.setattr(offload, "usable_cpus", lambda: cpus)
    monkeypatch.setattr(offload, "busy_cpus", lambda: busy)
    plan = _tools(_plan(*HELIX), PYTHON_FMU)
    comps, note = choose(plan, "auto", 10**6, writer_process=True)
    assert [plan.names[c] for c in comps] == expect, note
    if not expect:
        assert note == (f"parallel: auto: serial run ({cpus} CPUs, {busy} kept busy by other processes and the log's "
                        "writer process: no free CPU for a worker)"), note
    assert [plan.names[c] for c in choose(plan, "on", 10**6, writer_process=True)[0]] == ["traj", "ik"]
    if busy == 0:
        assert [plan.names[c] for c in choose(plan, "auto", 10**6)[0]] == ["traj", "ik"]
