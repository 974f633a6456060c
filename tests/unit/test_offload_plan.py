"""Which components run ahead in the worker: the feed-forward group and the auto rules."""

from __future__ import annotations

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


@pytest.mark.parametrize("mode,steps,cpus,expect", [
    ("off", 10**6, 2, []),
    ("auto", AUTO_MIN_STEPS, 2, ["traj", "ik"]),
    ("auto", AUTO_MIN_STEPS - 1, 2, []),
    ("auto", 10**6, 1, []),
    ("on", 10, 1, ["traj", "ik"]),
])
def test_choose_follows_mode_length_and_cpus(monkeypatch, mode, steps, cpus, expect):
    monkeypatch.setattr(offload, "usable_cpus", lambda: cpus)
    plan = _plan(*HELIX)
    comps, note = choose(plan, mode, steps)
    assert [plan.names[c] for c in comps] == expect, note
    if expect:
        assert note == "parallel: traj, ik run ahead in a worker process", note
    elif mode != "off":
        assert note.startswith(f"parallel: {mode}: serial run ("), note


def test_choose_explains_why_not():
    _, note = choose(_plan(["a", "b"], [("a", "b"), ("b", "a")]), "on", 10**6)
    assert note == "parallel: on: serial run (every component is in a feedback loop)", note
    _, note = choose(_plan(["a", "b"], [("a", "b")]), "on", 10**6)
    assert "every component is feed-forward" in note, note
    _, note = choose(_plan(*HELIX, kind="String"), "on", 10**6)
    assert "traj.y, ik.y are strings" in note, note


@pytest.mark.parametrize("cpus,tool,expect", [(2, None, []), (2, "PythonFMU 0.7.0", ["traj", "ik"]),
                                              (3, None, ["traj", "ik"])])
def test_auto_leaves_the_second_cpu_to_the_log_writer_when_the_worker_would_save_little(monkeypatch, cpus, tool,
                                                                                       expect):
    """A log written by a writer process on two CPUs: compiled feed-forward FMUs run in the master (their steps
    cost it about a microsecond), PythonFMU ones still run ahead; ``on`` is obeyed, and without the writer
    process auto offloads as before."""
    from types import SimpleNamespace

    monkeypatch.setattr(offload, "usable_cpus", lambda: cpus)
    plan = _plan(*HELIX)
    plan.infos[:] = [SimpleNamespace(md=SimpleNamespace(generationTool=tool),
                                     structural_parameters=lambda: []) for _ in plan.names]
    comps, note = choose(plan, "auto", 10**6, writer_process=True)
    assert [plan.names[c] for c in comps] == expect, note
    if not expect:
        assert note == ("parallel: auto: serial run (2 CPUs: the log's writer process takes the other one; traj, ik "
                        "are compiled FMUs, whose steps a worker would hardly take off the master)"), note
    assert [plan.names[c] for c in choose(plan, "on", 10**6, writer_process=True)[0]] == ["traj", "ik"]
    assert [plan.names[c] for c in choose(plan, "auto", 10**6)[0]] == ["traj", "ik"]
