"""The system structure (cosim.engine.structure): a YAML scenario and the SSP archive exported from it parse into
the same structure, and a structure written in code, with no scenario and no domain plugged in, runs on the
engine and gives the YAML scenario's values bit for bit.

The FMUs are third-party-style C models of ``tests/cfmus`` (VanDerPol driving an Integrator), so nothing of the
robot is involved."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest
import yaml
from cfmus import build

from cosim.engine import plugins
from cosim.engine.assembly import assemble_structure
from cosim.engine.events import resolve_events
from cosim.engine.scenario import load_scenario
from cosim.engine.structure import ComponentStructure, ConnectionStructure, SystemStructure
from cosim.engine.system import build_plan
from cosim.fmi import load_fmu
from cosim.io.ssp.scenario import open_ssp
from cosim.io.ssp.write import export_ssp, write_ssp

pytestmark = pytest.mark.integration

STOP, STEP = 1.0, 0.01


def _scenario(tmp_path: Path) -> Path:
    path = tmp_path / "vdp.yaml"
    path.write_text(yaml.safe_dump({
        "name": "vdp_integrated",
        "components": {"vdp": {"path": str(build("VanDerPol", 2)), "parameters": {"mu": 1.5}},
                       "integ": {"path": str(build("Integrator", 2)), "parameters": {"k": 2.0}}},
        "connections": [{"from": "vdp.x0", "to": "integ.u"}],
        "time": {"stop": STOP, "step": STEP},
    }, sort_keys=False))
    return path


def _digest(path: str | Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _comparable(s: SystemStructure, base: Path) -> dict:
    """What two structures of one system share: everything but where the values were written and the FMU files'
    places (an archive unpacks them elsewhere): the files' bytes instead."""
    comps = {n: (c.fmu, _digest(Path(c.path) if Path(c.path).is_absolute() else base / c.path),
                 {k: float(v) for k, v in c.parameters.items()}, c.step_multiple, c.interface)
             for n, c in s.components.items()}
    return dict(components=comps, connections=s.connections, grid=(s.start_ns, s.stop_ns, s.step_ns),
                algorithm=s.algorithm, events=s.events)


def test_yaml_and_its_ssp_archive_parse_into_one_structure(tmp_path):
    scenario = load_scenario(_scenario(tmp_path))
    archive = tmp_path / "vdp.ssp"
    export_ssp(scenario, archive)
    with open_ssp(archive) as from_ssp:
        a, b = scenario.structure(), from_ssp
        assert _comparable(a, a.folder()) == _comparable(b, b.folder())
        assert b.archive and not a.archive  # advice in errors names options for an archive, YAML keys for a file


def _final(structure: SystemStructure, signals: list[str]) -> list[float]:
    infos = {n: load_fmu(Path(c.path) if Path(c.path).is_absolute() else structure.folder() / c.path)
             for n, c in structure.components.items()}
    plan = build_plan(structure, infos)
    plan.events = resolve_events(structure, plan)
    ex = assemble_structure(plan, structure)
    try:
        ex.initialize()
        ex.simulate_until()
        out = []
        for ref in signals:
            arr, i = ex.where(plan.port(ref))
            out.append(float(arr[i]))
    finally:
        ex.end()
    return out


def _in_code() -> SystemStructure:
    """The scenario of :func:`_scenario`, written in code."""
    return SystemStructure(
        "vdp_integrated",
        {"vdp": ComponentStructure(None, str(build("VanDerPol", 2)), {"mu": 1.5}),
         "integ": ComponentStructure(None, str(build("Integrator", 2)), {"k": 2.0})},
        (ConnectionStructure("vdp.x0", "integ.u"),), 0, round(STOP * 1e9), round(STEP * 1e9), "gauss_seidel")


def test_a_structure_written_in_code_runs_without_scenario_or_plugin(tmp_path):
    scenario = load_scenario(_scenario(tmp_path))
    signals = ["vdp.x0", "vdp.x1", "integ.x"]
    from_yaml = _final(scenario.structure(), signals)
    in_code = _in_code()
    before = plugins.installed()
    plugins.register()  # a master with no domain at all
    try:
        assert _final(in_code, signals) == from_yaml
    finally:
        plugins.register(*before)
    assert from_yaml[2] != 0.0, "the integrator integrated its input"


def test_a_structure_written_in_code_exports_as_its_scenario_does(tmp_path):
    """SSP export writes from the structure: one made in code (no scenario, no domain plugged in) gives an archive
    that reads back into the same structure as the YAML scenario's export, and runs as it does."""
    scenario = load_scenario(_scenario(tmp_path))
    from_yaml = tmp_path / "yaml.ssp"
    export_ssp(scenario, from_yaml)
    structure = _in_code()
    infos = {n: load_fmu(c.path) for n, c in structure.components.items()}
    before = plugins.installed()
    plugins.register()  # a master with no domain at all
    try:
        report = write_ssp(structure, build_plan(structure, infos), tmp_path / "code.ssp")
    finally:
        plugins.register(*before)
    assert report.components == ["vdp", "integ"] and report.connections == 1, report
    with open_ssp(from_yaml) as a, open_ssp(report.path) as b:
        sa, sb = a, b
        assert _comparable(sa, sa.folder()) == _comparable(sb, sb.folder())
        signals = ["vdp.x0", "vdp.x1", "integ.x"]
        assert _final(sb, signals) == _final(sa, signals)


def test_the_run_check_and_export_take_a_structure_written_in_code(tmp_path):
    """``run`` (its tracking, its acceptance check and its log), ``check`` and SSP export take the system structure:
    one written in code, with no scenario and no domain plugged in, runs as its YAML scenario does and logs no
    scenario document (there is none to record)."""
    from dataclasses import replace

    from mcap.reader import make_reader

    from cosim.engine.structure import DOCUMENT_ATTACHMENT, Acceptance, Tracking
    from cosim.run import check_initialization, run_scenario

    text = _scenario(tmp_path).read_text() + "compare: {actual: [integ.x], reference: [vdp.x0]}\n" \
        "checks: {max_rmse: 100.0}\n"
    (tmp_path / "tracked.yaml").write_text(text)
    scenario = load_scenario(tmp_path / "tracked.yaml")
    structure = replace(_in_code(), tracking=Tracking(("integ.x",), ("vdp.x0",)), acceptance=Acceptance(100.0))
    from_yaml = run_scenario(scenario, log=False)
    before = plugins.installed()
    plugins.register()  # a master with no domain at all
    try:
        plan, report = check_initialization(structure)
        assert plan.names == ["vdp", "integ"] and report == "no pre-flight", report
        in_code = run_scenario(structure, out=tmp_path / "code.mcap")
        exported = export_ssp(structure, tmp_path / "code.ssp")
    finally:
        plugins.register(*before)
    assert [e.rmse for e in in_code.errors] == [e.rmse for e in from_yaml.errors] and in_code.errors[0].rmse > 0
    assert in_code.checks == from_yaml.checks and in_code.passed, in_code.checks
    with open(tmp_path / "code.mcap", "rb") as f:
        names = [a.name for a in make_reader(f).iter_attachments()]
    assert DOCUMENT_ATTACHMENT not in names and any(n.startswith("fmu/vdp/") for n in names), names
    assert exported.components == ["vdp", "integ"], exported
