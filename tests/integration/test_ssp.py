"""SSP 1.0 export and import: the exported helix runs identically in OSP libcosim and in our master,
our master gives the same run from the SSP as from the YAML, the archive validates against the SSP
1.0 schema, SSP files of other tools (other prefixes, inline parameters) run, bad archives fail
with one line and exit code 2, and no temporary directory is left behind."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest

from cosim.cli import main
from cosim.observers.recorders import Probe
from cosim.engine.prepare import prepare
from cosim.run import run_scenario
from cosim.engine.overrides import apply_overrides
from cosim.engine.scenario import load_scenario
from cosim.io.ssp.scenario import open_ssp
from cosim.io.ssp.spec import NS, SspError
from cosim.io.ssp.write import export_ssp

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "scenarios" / "helix_ctc_analytic.yaml"
STOP = 1.0  # s: 1000 steps of 1 ms, enough to cover the start-up and a fifth of a helix turn
OVERRIDES = {("time", "stop"): STOP}
P = ["plant.p.x", "plant.p.y", "plant.p.z"]
# libcosim and our Jacobi master call the same FMU functions with the same values in the same
# order (the FMUs are deterministic Python), so they agree to rounding; the bound is 1e-9 m.
LIBCOSIM_TOL_M = 1e-9
# The same FMUs, start values and algorithm from the SSP as from the YAML: identical to rounding.
SSP_YAML_TOL_M = 1e-12


@pytest.fixture(scope="module")
def ssp(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ssp") / "helix_ctc_analytic.ssp"
    export_ssp(load_scenario(SCENARIO, OVERRIDES), out)
    return out


def _ours(scenario_or_path, overrides=None) -> tuple[list[int], np.ndarray]:
    """Run our master (no log) and return (times ns, plant.p as an (n, 3) array)."""
    probe = Probe(P)
    if str(scenario_or_path).endswith(".ssp"):
        with open_ssp(scenario_or_path, overrides) as sc:
            run_scenario(sc, log=False, observers=[probe])
    else:
        run_scenario(load_scenario(scenario_or_path, overrides), log=False, observers=[probe])
    return probe.t_ns, np.column_stack([probe.values[s] for s in P])


def _libcosim(ssp: Path, step_ns: int, n: int) -> tuple[list[int], np.ndarray]:
    """Run the SSP in OSP libcosim with a fixed step; plant.p at every step from t = 0."""
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.ERROR)
    ex = CosimExecution.from_ssp_file(str(ssp), step_size=step_ns)
    obs = CosimObserver.create_time_series()
    ex.add_observer(obs)
    plant = ex.slave_index_from_instance_name("plant")
    vr = {v.name.decode(): v.reference for v in ex.slave_variables(plant)}
    names = [s.split(".", 1)[1] for s in P]
    for name in names:
        assert obs.start_time_series(plant, vr[name], CosimVariableType.REAL)
    assert ex.simulate_until(n * step_ns)
    cols, times = [], None
    for name in names:
        # libcosimpy 0.0.6 trims its sample buffer by counting step numbers equal to 0, which also
        # drops one sample whenever step 0 is among those read: read step 0 on its own (two asked,
        # one kept), then steps 1..n
        _, s0, v0 = obs.time_series_real_samples(plant, vr[name], from_step=0, sample_count=2)
        t, s, v = obs.time_series_real_samples(plant, vr[name], from_step=1, sample_count=n)
        assert list(s0) == [0] and list(s) == list(range(1, n + 1)), f"libcosim steps {s0}, {s[:3]}..{s[-3:]}"
        cols.append([v0[0], *v])
        times = [0, *t]
    return times, np.column_stack(cols)


# --------------------------------------------------------------------------- the Must show


def test_libcosim_runs_the_exported_ssp_as_our_jacobi_master_from_t0(ssp):
    n = round(STOP / 1e-3)
    t_lc, p_lc = _libcosim(ssp, 1_000_000, n)
    t_us, p_us = _ours(ssp, {("algorithm",): "jacobi"})
    assert t_us == t_lc, f"time grids differ: ours {t_us[:3]}..{t_us[-1]}, libcosim {t_lc[:3]}..{t_lc[-1]}"
    diff = np.abs(p_us - p_lc)
    worst = np.unravel_index(np.argmax(diff), diff.shape)
    print(f"max |ours (jacobi) - libcosim| = {diff.max():.3e} m over {len(t_us)} samples "
          f"(worst at t = {t_us[worst[0]] * 1e-9:g} s, {P[worst[1]]}); first sample {diff[0].max():.3e} m")
    assert diff.max() <= LIBCOSIM_TOL_M, (
        f"at t = {t_us[worst[0]] * 1e-9:g} s {P[worst[1]]}: ours {p_us[worst]!r} vs libcosim {p_lc[worst]!r}")


def test_libcosim_runs_native_fmus_in_the_exported_ssp_as_our_master(tmp_path):
    """The native C FMUs (issue 23), exported with ``fmus: native``: libcosim loads them (no Python in them) and
    reproduces our Jacobi master from t = 0."""
    out = tmp_path / "helix_ctc_analytic_native.ssp"
    export_ssp(load_scenario(SCENARIO, {**OVERRIDES, ("fmus",): "native"}), out)
    with zipfile.ZipFile(out) as zf:
        tools = {n: zf.read(n) for n in zf.namelist() if n.endswith(".fmu")}
    assert tools and all(b"python" not in _description(fmu).lower() for fmu in tools.values()), list(tools)
    n = round(STOP / 1e-3)
    t_lc, p_lc = _libcosim(out, 1_000_000, n)
    t_us, p_us = _ours(out, {("algorithm",): "jacobi"})
    assert t_us == t_lc
    diff = np.abs(p_us - p_lc)
    print(f"native FMUs: max |ours (jacobi) - libcosim| = {diff.max():.3e} m over {len(t_us)} samples")
    assert diff.max() <= LIBCOSIM_TOL_M, f"native FMUs in libcosim differ from our master by {diff.max():.3g} m"


def _description(fmu: bytes) -> bytes:
    import io

    with zipfile.ZipFile(io.BytesIO(fmu)) as zf:
        return zf.read("modelDescription.xml")


@pytest.mark.parametrize("algorithm", ["gauss_seidel", "jacobi"])
def test_our_master_runs_the_ssp_as_the_yaml(ssp, algorithm):
    over = {**OVERRIDES, ("algorithm",): algorithm}
    t_yaml, p_yaml = _ours(SCENARIO, over)
    t_ssp, p_ssp = _ours(ssp, {("algorithm",): algorithm})
    assert t_ssp == t_yaml, f"time grids differ: {len(t_ssp)} vs {len(t_yaml)} samples"
    diff = np.abs(p_ssp - p_yaml).max()
    print(f"{algorithm}: max |SSP - YAML| = {diff:.3e} m over {len(t_ssp)} samples")
    assert diff <= SSP_YAML_TOL_M, f"{algorithm}: SSP and YAML runs differ by {diff:.3e} m"


# --------------------------------------------------------------------------- the archive


def _schema(name: str):
    import fmpy.ssp
    from lxml import etree

    return etree.XMLSchema(file=str(Path(fmpy.ssp.__file__).parent / "schema" / name))


def test_exported_archive_validates_against_the_ssp_1_0_schema(ssp):
    from lxml import etree

    with zipfile.ZipFile(ssp) as z:
        for member in z.namelist():
            xsd = {".ssd": "SystemStructureDescription.xsd", ".ssv": "SystemStructureParameterValues.xsd"}.get(
                Path(member).suffix)
            if xsd is None:
                continue
            schema = _schema(xsd)
            ok = schema.validate(etree.fromstring(z.read(member)))
            assert ok, f"{member}: {[str(e) for e in schema.error_log]}"


def test_exported_archive_holds_what_the_master_sets(ssp):
    """Components, sources, connectors (kind, type, unit), connections, start values, experiment."""
    import xml.etree.ElementTree as ET

    scenario = load_scenario(SCENARIO, OVERRIDES)
    plan, _ = prepare(scenario.structure())
    with zipfile.ZipFile(ssp) as z:
        members = set(z.namelist())
        ssd_text = z.read("SystemStructure.ssd").decode()
        root = ET.fromstring(ssd_text)
        ssv = {m: ET.fromstring(z.read(m)) for m in members if m.endswith(".ssv")}
    # libcosim matches these prefixes literally
    for prefix in ("ssd", "ssc", "ssv", "osp"):
        assert f'xmlns:{prefix}="{NS[prefix]}"' in ssd_text, f"prefix {prefix}: not declared as {NS[prefix]}"
    assert re.search(r"<ssd:Component ", ssd_text) and re.search(r"<ssc:Real ", ssd_text)
    comps = {c.get("name"): c for c in root.iterfind("ssd:System/ssd:Elements/ssd:Component", NS)}
    assert list(comps) == plan.names, f"components {list(comps)} vs scenario {plan.names}"
    units = {u.get("name") for u in root.iterfind("ssd:Units/ssc:Unit", NS)}
    for c, name in enumerate(plan.names):
        el = comps[name]
        assert el.get("source") == f"resources/{name}.fmu" and el.get("source") in members, el.get("source")
        info = plan.infos[c]
        with zipfile.ZipFile(ssp) as z:
            assert z.read(f"resources/{name}.fmu") == info.path.read_bytes(), f"{name}: FMU differs from the build"
        connectors = {k.get("name"): k for k in el.iterfind("ssd:Connectors/ssd:Connector", NS)}
        for var in info.variables.values():
            if var.causality in ("input", "output"):
                k = connectors.get(var.name)
                assert k is not None, f"{name}.{var.name}: no connector"
                assert k.get("kind") == var.causality, f"{name}.{var.name}: kind {k.get('kind')}"
                typed = k.find(f"ssc:{var.fmi_type}", NS)  # our FMUs: Real, Integer, Boolean
                assert typed is not None and typed.get("unit") == var.unit, f"{name}.{var.name}: {ET.tostring(k)}"
                assert var.unit is None or var.unit in units, f"{name}.{var.name}: unit {var.unit} not in ssd:Units"
        # every start value the master sets, exactly (floats written to round-trip)
        want = plan.start_values[c]
        bindings = el.findall("ssd:ParameterBindings/ssd:ParameterBinding", NS)
        if not want:
            assert not bindings, f"{name}: no start values, yet {len(bindings)} parameter bindings"
            continue
        assert [b.get("source") for b in bindings] == [f"resources/{name}.ssv"]
        got = {p.get("name"): float(p.find("ssv:Real", NS).get("value"))
               for p in ssv[f"resources/{name}.ssv"].iterfind("ssv:Parameters/ssv:Parameter", NS)}
        assert got == {k: float(v) for k, v in want.items()}, f"{name}: .ssv {got} vs master {want}"
    # the trajectory section's parameters and the plant's initial state are among them
    assert plan.start_values[plan.names.index("traj")]["helix.rx"] == 0.1
    assert set(plan.start_values[plan.names.index("plant")]) >= {"initial.p.x", "initial.v.y"}
    conns = [(c.get("startElement") + "." + c.get("startConnector"), c.get("endElement") + "." + c.get("endConnector"))
             for c in root.iterfind("ssd:System/ssd:Connections/ssd:Connection", NS)]
    expanded = [(lk.src.label(plan.names), lk.dst.label(plan.names)) for lk in plan.links]  # prefixes expanded
    assert conns == expanded and len(conns) == 27, ("connections differ from the scenario's", conns, expanded)
    exp = root.find("ssd:DefaultExperiment", NS)
    assert (float(exp.get("startTime")), float(exp.get("stopTime"))) == (0.0, STOP)
    algo = exp.find("ssd:Annotations/ssc:Annotation/osp:Algorithm/osp:FixedStepAlgorithm", NS)
    assert algo is not None and float(algo.get("baseStepSize")) == 1e-3, "no osp:FixedStepAlgorithm baseStepSize"


def _rewrite(src: Path, dst: Path, drop: tuple[str, ...] = (), edit=None) -> Path:
    """Copy an archive, dropping members and editing SystemStructure.ssd (text -> text)."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            if item.filename in drop:
                continue
            data = zin.read(item.filename)
            if item.filename == "SystemStructure.ssd" and edit is not None:
                data = edit(data.decode()).encode()
            zout.writestr(item, data)
    return dst


def test_step_falls_back_to_the_fmus_default_experiment(ssp, tmp_path):
    no_osp = _rewrite(ssp, tmp_path / "no_osp.ssp", edit=lambda s: re.sub(
        r"<ssd:DefaultExperiment([^>]*)>.*?</ssd:DefaultExperiment>", r"<ssd:DefaultExperiment\1 />", s, flags=re.S))
    with open_ssp(no_osp, {("time", "stop"): 0.01}) as sc:
        assert sc.seconds()[2] == 1e-3, f"step {sc.seconds()[2]} (our FMUs' DefaultExperiment says 1e-3)"
        assert sc.n_steps() == 10


# --------------------------------------------------------------------------- the CLI


def _cli(capsys, *argv) -> tuple[int, str, str]:
    rc = main([str(a) for a in argv])
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_cli_runs_the_ssp_with_stop_time_set_and_json(ssp, capsys):
    rc, out, err = _cli(capsys, "run", ssp, "--no-log", "--json", "--stop-time", "0.01")
    assert rc == 0, err
    base = json.loads(out)
    assert base["status"] == "completed" and base["steps"] == 10, base
    rc, out, err = _cli(capsys, "run", ssp, "--no-log", "--json", "--stop-time", "0.01",
                        "--set", "plant.initial.p.x=0.101")
    moved = json.loads(out)
    # the scenario's acceptance check travels in the archive (our annotation) and now fails: exit 1
    assert rc == 1 and not moved["passed"], (rc, moved["checks"], err)
    e0 = base["errors"][0]["max_error"]
    e1 = moved["errors"][0]["max_error"]
    assert e1 > e0 + 5e-4, f"--set plant.initial.p.x=0.101 should start 1 mm off the path: {e0} -> {e1}"
    rc, out, err = _cli(capsys, "check", ssp)
    assert rc == 0 and "helix_ctc_analytic: ok" in out, err


@pytest.fixture
def private_tmp(tmp_path, monkeypatch) -> Path:
    """A temp directory of this test's own, to see that nothing is left in it."""
    d = tmp_path / "tmp"
    d.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(d))
    return d


BAD = {
    "no_ssd": (dict(drop=("SystemStructure.ssd",)), "no SystemStructure.ssd"),
    "missing_connector": (dict(edit=lambda s: s.replace('endElement="plant" endConnector="u[3]"',
                                                          'endElement="plant" endConnector="u[9]"')),
                          "component 'plant' has no connector 'u[9]'"),
    "missing_fmu": (dict(drop=("resources/plant.fmu",)), "its FMU resources/plant.fmu is not in the archive"),
    "missing_ssv": (dict(drop=("resources/traj.ssv",)), "resources/traj.ssv is not in the archive"),
    "bad_xml": (dict(edit=lambda s: s[: len(s) // 2]), "not well-formed XML"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_ssp_fails_with_one_line_and_exit_2(ssp, tmp_path, capsys, private_tmp, case):
    kwargs, expected = BAD[case]
    bad = _rewrite(ssp, tmp_path / f"{case}.ssp", **kwargs)
    rc, _, err = _cli(capsys, "run", bad, "--no-log", "--quiet")
    print(err.strip())
    assert rc == 2, f"exit {rc}: {err}"
    lines = err.strip().splitlines()
    assert len(lines) == 1 and str(bad) in lines[0] and expected in lines[0], f"stderr: {err!r}"
    assert list(private_tmp.iterdir()) == [], f"left behind: {list(private_tmp.iterdir())}"


def test_not_an_archive_fails_in_a_subprocess_without_traceback(tmp_path):
    bad = tmp_path / "plain.ssp"
    bad.write_text("not a zip\n")
    res = subprocess.run([sys.executable, "-m", "cosim", "run", str(bad), "--no-log"], capture_output=True,
                         text=True, cwd=ROOT, env={**os.environ, "TMPDIR": str(tmp_path)})
    assert res.returncode == 2, res.stderr
    assert res.stderr.strip().splitlines() == [f"error: {bad}: not an SSP archive (a zip file): File is not a zip file"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain.ssp"], "temporary files left behind"


def test_run_leaves_no_temporary_directory(ssp, private_tmp):
    _ours(ssp, {("time", "stop"): 0.01})
    assert list(private_tmp.iterdir()) == [], f"left behind: {list(private_tmp.iterdir())}"


# --------------------------------------------------------------------------- another tool's SSP


FOREIGN_SSD = """<?xml version="1.0" encoding="UTF-8"?>
<SystemStructureDescription xmlns="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:c="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:v="http://ssp-standard.org/SSP1/SystemStructureParameterValues" name="foreign" version="1.0">
  <System name="root">
    <Elements>
      <Component name="src" source="./resources/Source%20model.fmu">
        <Connectors><Connector name="y" kind="output"><c:Real/></Connector></Connectors>
        <ParameterBindings><ParameterBinding prefix="">
          <ParameterValues><v:ParameterSet version="1.0" name="p"><v:Parameters>
            <v:Parameter name="offset"><v:Real value="2"/></v:Parameter>
          </v:Parameters></v:ParameterSet></ParameterValues>
        </ParameterBinding></ParameterBindings>
      </Component>
      <Component name="gain" source="resources/gain.fmu" implementation="CoSimulation">
        <Connectors>
          <Connector name="u" kind="input"><c:Real/></Connector>
          <Connector name="y" kind="output"><c:Real/></Connector>
        </Connectors>
        <ParameterBindings><ParameterBinding source="params/gain.ssv"/></ParameterBindings>
      </Component>
    </Elements>
    <Connections>
      <Connection startElement="src" startConnector="y" endElement="gain" endConnector="u"/>
    </Connections>
  </System>
  {experiment}
</SystemStructureDescription>
"""
FOREIGN_SSV = """<?xml version="1.0"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="g">
  <ssv:Parameters><ssv:Parameter name="k"><ssv:Real value="3"/></ssv:Parameter></ssv:Parameters>
</ssv:ParameterSet>
"""


def _foreign(tmp_path: Path, test_fmus, experiment: str) -> Path:
    path = tmp_path / "foreign.ssp"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("SystemStructure.ssd", FOREIGN_SSD.replace("{experiment}", experiment))
        z.writestr("params/gain.ssv", FOREIGN_SSV)
        z.write(test_fmus["CosimTSource"], "resources/Source model.fmu")
        z.write(test_fmus["CosimTGain"], "resources/gain.fmu")
    return path


def test_another_tools_ssp_runs(tmp_path, test_fmus, capsys):
    """Default namespace and other prefixes, inline and file parameter sets, an escaped source URI."""
    ssp = _foreign(tmp_path, test_fmus, '<DefaultExperiment startTime="0" stopTime="0.5"/>')
    rc, out, err = _cli(capsys, "run", ssp, "--no-log", "--json")
    assert rc == 2 and "the base step: neither the SSD's default experiment nor the FMUs give it; pass --step" in err
    probe = Probe(["src.y", "gain.y"])
    with open_ssp(ssp, {("time", "step"): 0.1}) as sc:
        assert sc.components["gain"].interface == "cs"
        assert sc.components["src"].parameters == {"offset": 2.0} and sc.components["gain"].parameters == {"k": 3.0}
        res = run_scenario(sc, out=tmp_path / "foreign.mcap", observers=[probe])  # logged: gain.y is read
    assert res.steps == 5, res.steps
    assert probe.values["src.y"][0] == 2.0, probe.values["src.y"]
    # after each step the gain holds k times the source's output of that macro step (Gauss-Seidel: the
    # gain steps after the source and computes y = k u in its step; at t = 0 it holds its start 0)
    np.testing.assert_allclose(probe.values["gain.y"][1:], 3.0 * np.array(probe.values["src.y"][1:]), rtol=0,
                               atol=1e-15, err_msg="gain.y != k * src.y")
    rc, out, err = _cli(capsys, "run", ssp, "--no-log", "--json", "--step", "0.1")
    assert rc == 0 and json.loads(out)["steps"] == 5, err


@pytest.mark.parametrize("name", ["../../escaped", "/tmp/absolute_escape_of_ssp_test"])
def test_component_names_are_not_paths(ssp, tmp_path, capsys, private_tmp, name, monkeypatch):
    """A component's name never chooses where its FMU is unpacked (issue 25): "../../x" or an absolute name
    wrote outside the work folder, before the name was even checked."""
    monkeypatch.chdir(tmp_path)
    bad = _rewrite(ssp, tmp_path / "names.ssp", edit=lambda s: s.replace('"plant"', f'"{name}"'))
    before = set(Path("/tmp").iterdir())
    rc, _, err = _cli(capsys, "run", bad, "--no-log", "--quiet", "--stop-time", "0.01")
    assert rc == 2 and err.startswith("error:"), err  # the names are refused later, as component names
    assert not (tmp_path.parent / "escaped").exists() and not Path("/tmp/absolute_escape_of_ssp_test").exists()
    # /tmp is shared with whatever else runs on the machine: only what this archive could have named counts
    new = {p for p in set(Path("/tmp").iterdir()) - before - {private_tmp} if "escape" in p.name or "names" in p.name}
    assert not new, f"something was written outside the work folder: {new}"
    assert list(private_tmp.iterdir()) == [], f"left behind: {list(private_tmp.iterdir())}"


def test_an_archive_cannot_choose_where_the_log_goes(ssp, tmp_path, capsys):
    """Our annotation may carry the scenario's logging settings, never its output path (issue 25)."""
    target = tmp_path / "notes.txt"
    target.write_text("a user's notes\n")
    bad = _rewrite(ssp, tmp_path / "out.ssp", edit=lambda s: re.sub(
        r'("logging": \{)', r'\1"out": "' + str(target).replace("\\", "/") + '", ', s, count=1))
    assert str(target) in zipfile.ZipFile(bad).read("SystemStructure.ssd").decode(), "the test did not plant logging.out"
    rc, _, err = _cli(capsys, "run", bad, "--quiet", "--stop-time", "0.01")
    assert rc == 2 and "cannot choose where the log is written" in err, err
    assert target.read_text() == "a user's notes\n"


def test_a_system_name_cannot_move_the_default_log(ssp, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    bad = _rewrite(ssp, tmp_path / "sysname.ssp", edit=lambda s: re.sub(
        r'(<ssd:SystemStructureDescription[^>]*?) name="[^"]*"', r'\1 name="../../escaped_log"', s, count=1))
    rc, out, err = _cli(capsys, "run", bad, "--quiet", "--json", "--stop-time", "0.01")
    assert rc in (0, 1), err
    assert not (tmp_path.parent / "escaped_log.mcap").exists()
    assert list((tmp_path / "runs").glob("*.mcap")), list(tmp_path.rglob("*.mcap"))


def test_an_ssd_that_inflates_too_far_is_refused(ssp, tmp_path, capsys, monkeypatch):
    """The .ssd is read no further than the limit, whatever the archive says (issue 25: a zip bomb's 2.5 GiB)."""
    import cosim.io.ssp.archive as ssp_module

    monkeypatch.setattr(ssp_module, "MAX_XML_BYTES", 4096)  # our .ssd is larger than 4 kB: stands in for a bomb
    rc, _, err = _cli(capsys, "run", ssp, "--no-log", "--quiet")
    assert rc == 2 and "unpacks to more than" in err and len(err.strip().splitlines()) == 1, err


def test_an_archive_unpacked_by_a_killed_run_is_removed_by_the_next(ssp, private_tmp):
    """SIGKILL leaves an SSP run's unpacked archive behind (no handler runs); the next SSP run removes it
    (issue 25), and leaves those of live processes alone."""
    from cosim.fmi.extract import SSP_PREFIX

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    orphan = private_tmp / f"{SSP_PREFIX}{int(dead.stdout)}-helix-abc"
    (orphan / "fmus").mkdir(parents=True)
    alive = private_tmp / f"{SSP_PREFIX}{os.getpid()}-other-xyz"
    alive.mkdir()
    _ours(ssp, {("time", "stop"): 0.01})
    assert not orphan.exists(), "the killed run's archive is still there"
    assert alive.exists(), "a live process's archive was removed"
    alive.rmdir()


def test_an_fmu_member_that_unpacks_too_far_is_refused(ssp, tmp_path, capsys, private_tmp, monkeypatch):
    """Each archive member is bounded, the FMUs too, not only the .ssd (issue 25)."""
    import cosim.io.ssp.components as ssp_module

    monkeypatch.setattr(ssp_module, "MAX_FMU_BYTES", 1000)  # our FMUs are larger: stands in for a bomb
    rc, _, err = _cli(capsys, "run", ssp, "--no-log", "--quiet")
    assert rc == 2 and "unpacks to more than" in err and len(err.strip().splitlines()) == 1, err
    assert list(private_tmp.iterdir()) == [], f"left behind: {list(private_tmp.iterdir())}"


def test_an_fmu_file_that_unpacks_too_far_is_refused(tmp_path, monkeypatch):
    """A zip bomb given as an FMU (a component's path, or extracted from an archive) is refused before it is read."""
    import cosim.fmi.extract as fmu_module
    from cosim.fmi import load_fmu
    from cosim.errors import ComponentSourceError

    bomb = tmp_path / "bomb.fmu"
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("modelDescription.xml", "<fmiModelDescription/>")
        zf.writestr("resources/zeros.bin", b"\0" * 200_000)
    monkeypatch.setattr(fmu_module, "MAX_FMU_BYTES", 100_000)
    with pytest.raises(ComponentSourceError, match="unpacks to"):
        load_fmu(bomb)


def _initialization_loop(ssp: Path) -> list[str]:
    """A cycle (node names) in the archive's initialization graph, or [] when there is none: what
    OMSimulator builds before it initializes (``ComponentFMUCS::initializeDependencyGraph_initialUnknowns``,
    FMI 2.0 section 2.2.8): each InitialUnknown depends on the inputs its ``dependencies`` list, on every
    input of its FMU when it has no ``dependencies`` attribute; each connection links an output to an input."""
    import io

    edges: dict[str, set[str]] = {}
    with zipfile.ZipFile(ssp) as z:
        root = ET.fromstring(z.read("SystemStructure.ssd"))
        for comp in root.iterfind("ssd:System/ssd:Elements/ssd:Component", NS):
            with zipfile.ZipFile(io.BytesIO(z.read(comp.get("source")))) as fmu:
                md = ET.fromstring(fmu.read("modelDescription.xml"))
            names = [v.get("name") for v in md.iter("ScalarVariable")]
            inputs = {n for n, v in zip(names, md.iter("ScalarVariable")) if v.get("causality") == "input"}
            for u in md.iterfind("ModelStructure/InitialUnknowns/Unknown"):
                deps = u.get("dependencies")
                known = inputs if deps is None else {names[int(i) - 1] for i in deps.split()} & inputs
                for d in known:
                    edges.setdefault(f"{comp.get('name')}.{d}", set()).add(f"{comp.get('name')}.{names[int(u.get('index')) - 1]}")
        for c in root.iterfind("ssd:System/ssd:Connections/ssd:Connection", NS):
            edges.setdefault(f"{c.get('startElement')}.{c.get('startConnector')}", set()).add(
                f"{c.get('endElement')}.{c.get('endConnector')}")
    state: dict[str, int] = {}  # 1 on the path, 2 done

    def visit(node: str, path: list[str]) -> list[str]:
        state[node], path = 1, [*path, node]
        for nxt in sorted(edges.get(node, ())):
            if state.get(nxt) == 1:
                return [*path[path.index(nxt):], nxt]
            if nxt not in state and (cycle := visit(nxt, path)):
                return cycle
        state[node] = 2
        return []

    for start in sorted(edges):
        if start not in state and (cycle := visit(start, [])):
            return cycle
    return []


@pytest.mark.parametrize("fmus", ["native", "python"])
def test_export_has_no_algebraic_loop_at_initialization(tmp_path, fmus):
    """Every InitialUnknown of our FMUs lists its dependencies (the inputs it depends on in a step, plus the
    parameters), so the plant's q, computed from its parameters at initialization, does not depend on its
    input u: without them (the native build before) an importer must assume every initial unknown depends
    on every input, and OMSimulator 3.0 stopped on the loop plant.q -> ctl.u -> plant.u -> plant.q
    ("Solution of algebraic loop 0 not within precision")."""
    out = tmp_path / f"helix_ctc_analytic_{fmus}.ssp"
    export_ssp(load_scenario(SCENARIO, {**OVERRIDES, ("fmus",): fmus}), out)
    with zipfile.ZipFile(out) as z:
        for member in z.namelist():
            if member.endswith(".fmu"):
                md = ET.fromstring(_description(z.read(member)))
                bare = [u.get("index") for u in md.iterfind("ModelStructure/InitialUnknowns/Unknown")
                        if u.get("dependencies") is None]
                assert not bare, f"{member} ({fmus}): InitialUnknowns {bare} without dependencies"
    assert _initialization_loop(out) == []
    # the check itself: the same archive with the dependencies dropped has the loop through the plant
    loop = _initialization_loop(_rewrite_fmu(out, tmp_path / "bare.ssp", "resources/plant.fmu",
                                             lambda tail: re.sub(r' dependencies(Kind)?="[^"]*"', "", tail)))
    assert loop and any(n.startswith("plant.u") for n in loop) and any(n.startswith("ctl.u") for n in loop), loop


def _rewrite_fmu(src: Path, dst: Path, member: str, edit) -> Path:
    """Copy an archive, editing one FMU's modelDescription.xml from ``<InitialUnknowns>`` on (text -> text)."""
    import io

    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == member:
                buf = io.BytesIO()
                with zipfile.ZipFile(io.BytesIO(data)) as fin, zipfile.ZipFile(buf, "w") as fout:
                    for f in fin.infolist():
                        body = fin.read(f.filename)
                        if f.filename == "modelDescription.xml":
                            text = body.decode()
                            head, sep, tail = text.partition("<InitialUnknowns>")
                            body = (head + sep + edit(tail)).encode()
                        fout.writestr(f, body)
                data = buf.getvalue()
            zout.writestr(item, data)
    return dst


@pytest.mark.parametrize("fidelity", [None, "full", "lumped"])
def test_a_string_parameter_at_its_start_value_stays_out_of_the_ssv(tmp_path, fidelity):
    """helix_ctc sets the Exudyn plant's ``model.fidelity`` to "full", the FMU's own start value: the export
    leaves it out of the .ssv (OMSimulator 3.0 reads no ssv:String and logs an error for one); a value that
    differs ("lumped") is written as ssv:String, and our master reads it back."""
    sets = [] if fidelity is None else [f"plant.model.fidelity={fidelity}"]
    out = tmp_path / "helix_ctc.ssp"
    export_ssp(load_scenario(ROOT / "scenarios" / "helix_ctc.yaml", apply_overrides(sets, stop_time=0.01)), out)
    with zipfile.ZipFile(out) as z:
        ssv = ET.fromstring(z.read("resources/plant.ssv"))
    strings = {p.get("name"): p.find("ssv:String", NS).get("value")
               for p in ssv.iterfind("ssv:Parameters/ssv:Parameter", NS) if p.find("ssv:String", NS) is not None}
    assert strings == ({"model.fidelity": "lumped"} if fidelity == "lumped" else {}), strings
    assert ssv.find("ssv:Parameters/ssv:Parameter[@name='initial.v.y']", NS) is not None  # the rest is there
    with open_ssp(out) as sc:
        assert sc.components["plant"].parameters.get("model.fidelity") == strings.get("model.fidelity")


def test_export_is_typed_for_omsimulator(ssp):
    """OMSimulator 3.0 (built from source, v3.0.0-158) imports a system only with its own annotation
    (oms:FixedStepMaster: else "[NewSystem] internal error") and refuses ssd:Annotations at the top
    ("wrong xml schema detected"): ours go on the system, OMSimulator's first (it reads only the first).
    Its initialization sorts the FMUs by their InitialUnknowns' dependencies: the archive has no loop there.
    The run itself: tests/integration/test_ssp_omsimulator.py (where OMSIMULATOR_LIB is set)."""
    with zipfile.ZipFile(ssp) as z:
        root = ET.fromstring(z.read("SystemStructure.ssd"))
    assert root.find("ssd:Annotations", NS) is None, "top-level annotations break OMSimulator's import"
    anns = root.findall("ssd:System/ssd:Annotations/ssc:Annotation", NS)
    assert [a.get("type") for a in anns] == ["org.openmodelica", "org.delta-cosim.engine.scenario"], anns
    master = anns[0].find("oms:Annotations/oms:SimulationInformation/oms:FixedStepMaster", NS)
    assert master is not None and float(master.get("stepSize")) == 0.001, ET.tostring(anns[0])
    with open_ssp(ssp) as sc:  # the OSP and OMSimulator steps agree; our annotation keeps the algorithm
        assert sc.seconds()[2] == 0.001 and sc.algorithm == "gauss_seidel", (sc.seconds(), sc.algorithm)
    assert _initialization_loop(ssp) == []


def _with_plant_set(ssp: Path, out: Path, units: str, z: str) -> Path:
    """``ssp`` with the plant's set giving initial.p.z as ``z`` (an ssv:Real element) and ``units`` (ssv:Units)."""
    with zipfile.ZipFile(ssp) as zin, zipfile.ZipFile(out, "w") as zout:
        for item in zin.namelist():
            data = zin.read(item)
            if item == "resources/plant.ssv":
                data = data.replace(b'<ssv:Real value="-0.45" />', z.encode())
                data = data.replace(b"<ssv:Parameters>", units.encode() + b"<ssv:Parameters>")
            zout.writestr(item, data)
    return out


MM = '<ssv:Units><ssc:Unit xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" name="mm">' \
     '<ssc:BaseUnit m="1" factor="0.001"/></ssc:Unit></ssv:Units>'


def test_parameter_values_with_units_are_converted_to_the_fmus(ssp, tmp_path):
    """An ``ssv:Real`` with a ``unit`` is converted to the unit of the FMU variable it is bound to, through the
    base units (mm in the set's ssv:Units -> the FMU's m): -450 mm is -0.45 m. A unit of other base units, or one
    defined nowhere, is one error naming the file and parameter; the FMU's own unit is taken as is."""
    converted = _with_plant_set(ssp, tmp_path / "mm.ssp", MM, '<ssv:Real value="-450" unit="mm"/>')
    with open_ssp(converted) as sc:
        assert sc.components["plant"].parameters["initial.p.z"] == -0.45, sc.components["plant"].parameters
    same = _with_plant_set(ssp, tmp_path / "m.ssp", "", '<ssv:Real value="-0.4" unit="m"/>')  # the SSD defines m
    with open_ssp(same) as sc:
        assert sc.components["plant"].parameters["initial.p.z"] == -0.4
    seconds = MM.replace('name="mm"', 'name="ms"').replace('m="1" factor', 's="1" factor')
    parameter = "resources/plant.ssv: parameter initial.p.z: "
    for units, z, message in (
            (seconds, '<ssv:Real value="-450" unit="ms"/>',
             parameter + "unit 'ms' does not convert to plant.initial.p.z's unit 'm'"),
            ("", '<ssv:Real value="-450" unit="mm"/>',
             parameter + "unit 'mm' is defined in neither the parameter set's ssv:Units"),
            (MM.replace('factor="0.001"', 'factor="0"'), '<ssv:Real value="-450" unit="mm"/>',
             "resources/plant.ssv: unit 'mm': BaseUnit factor 0.0, offset 0.0: a unit needs a finite factor other than 0"),
            (MM.replace("</ssv:Units>", "") + MM.replace("<ssv:Units>", "").replace('factor="0.001"', 'factor="1"'),
             '<ssv:Real value="-1500" unit="mm"/>',  # the last definition won: -1500 mm reached the FMU as -1500 m
             "resources/plant.ssv: unit 'mm' is defined twice, differently (factor 0.001 then 1.0"),
            (MM.replace('name="mm"', 'name="m"').replace('factor="0.001"', 'factor="2"'),
             '<ssv:Real value="-0.4" unit="m"/>', "resources/plant.ssv: unit 'm' is defined twice, differently")):
        bad = _with_plant_set(ssp, tmp_path / "bad.ssp", units, z)
        with pytest.raises(SspError) as exc:
            with open_ssp(bad):
                pass
        assert message in str(exc.value), str(exc.value)


def test_suppress_unit_conversion_passes_numbers_between_different_units(ssp, tmp_path, capsys):
    """A connection between connectors of different units (here traj.a_ref.x, m/s2, to ik.v_ref.x, m/s) is
    refused naming both (the archive's connector units, read before the FMUs' are compared), as the master converts
    no units; with SSP's ``suppressUnitConversion="true"`` the
    numbers pass as they are (``units: as_is``), and an export writes it back."""
    from cosim.cli import main

    def rewired(name: str, extra: str) -> Path:
        out = tmp_path / name
        with zipfile.ZipFile(ssp) as zin, zipfile.ZipFile(out, "w") as zout:
            for item in zin.namelist():
                data = zin.read(item)
                if item == "SystemStructure.ssd":
                    data = data.replace(b'startElement="traj" startConnector="v_ref.x" endElement="ik" '
                                        b'endConnector="v_ref.x"',
                                        b'startElement="traj" startConnector="a_ref.x" endElement="ik" '
                                        b'endConnector="v_ref.x"' + extra.encode())
                zout.writestr(item, data)
        return out

    rc = main(["check", str(rewired("refused.ssp", ""))])
    err = capsys.readouterr().err
    assert rc == 2 and "connection traj.a_ref.x -> ik.v_ref.x: the connectors' units 'm/s2' and 'm/s' are of " \
        "different dimensions" in err, err
    assert 'suppressUnitConversion="true"' in err and len(err.strip().splitlines()) == 1, err
    accepted = rewired("as_is.ssp", ' suppressUnitConversion="true"')
    with open_ssp(accepted) as sc:
        (conn,) = [c for c in sc.connections if c.dst == "ik.v_ref.x"]
        assert (conn.src, conn.units) == ("traj.a_ref.x", "as_is"), conn
        export_ssp(sc, tmp_path / "again.ssp")
    text = zipfile.ZipFile(tmp_path / "again.ssp").read("SystemStructure.ssd").decode()
    assert 'startConnector="a_ref.x" endElement="ik" endConnector="v_ref.x" suppressUnitConversion="true"' in text


def test_events_travel_in_our_annotation_and_the_export_says_other_tools_drop_them(tmp_path):
    scenario = load_scenario(Path(__file__).resolve().parents[2] / "scenarios" / "pick_place_ctc.yaml",
                             apply_overrides(["fmus=native"], 0.6))
    report = export_ssp(scenario, tmp_path / "pp.ssp")
    assert report.events == 8 and "other SSP tools run the system without them" in report.text(), report.text()
    with open_ssp(tmp_path / "pp.ssp") as again:
        assert again.events == scenario.structure().events, f"events after the round trip: {again.events}"
        res = run_scenario(again, log=False)
    assert [e["t"] for e in res.fired] == [0.0, 0.25, 0.5], f"fired {res.fired}"


@pytest.mark.parametrize("argv", [
    ["ssp", "export", "{a}", "-o", "{tmp}/again.ssp"],
    ["calibrate", "{a}", "--measured", "{tmp}/r.csv", "--map", "plant.p.x=x", "--fit", "plant.mass.payload"],
    ["run", "{zip}", "--no-log"],  # an archive not named .ssp
])
def test_an_archive_where_a_yaml_scenario_is_read_is_one_line_naming_what_reads_it(ssp, tmp_path, capsys, argv):
    """Every command that reads a YAML scenario, given an SSP archive (or an archive under another name), says what
    it is and which commands read archives, instead of reporting its bytes as text that is not UTF-8."""
    renamed = tmp_path / "system.zip"
    renamed.write_bytes(ssp.read_bytes())
    (tmp_path / "r.csv").write_text("t,x\n0,0\n0.1,0\n")
    rc, out, err = _cli(capsys, *[x.format(a=ssp, tmp=tmp_path, zip=renamed) for x in argv])
    assert rc == 2 and len(err.strip().splitlines()) == 1, err
    assert "a zip archive, not a YAML scenario" in err and "UTF-8" not in err, err
    assert not (tmp_path / "again.ssp").exists()


def test_table_and_report_read_the_log_of_a_run_from_an_archive(ssp, tmp_path, capsys):
    """The log of a run from an SSP archive attaches the archive (not YAML) and the scenario as run
    (effective/scenario.json): table and report read the latter, and name the plant by its FMU file."""
    from cosim.cli import main

    log = tmp_path / "from_ssp.mcap"
    assert main(["run", str(ssp), "--stop-time", "0.1", "--out", str(log), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["table", str(log)]) == 0
    out = capsys.readouterr().out
    assert "| helix_ctc_analytic | " in out and "| plant.fmu |" in out, out
    assert main(["report", str(log), "--out", str(tmp_path / "report")]) == 0, capsys.readouterr().err
