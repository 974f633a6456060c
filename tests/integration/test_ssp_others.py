"""SSP files as other tools write them (issue 26, item 2), built here with zipfile and the pythonfmu test FMUs:
names with spaces and dots, system-level parameter bindings with .ssm mappings, OSP's and OMSimulator's
algorithm and step annotations, and one line for each SSP feature the master does not support."""

from __future__ import annotations

import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest

from cosim.cli import main
from cosim.engine.overrides import apply_overrides
from cosim.io.ssp.scenario import open_ssp
from cosim.io.ssp.spec import NS, SspError
from cosim.io.ssp.write import export_ssp
from cosim.observers.recorders import Probe
from cosim.run import run_scenario

pytestmark = pytest.mark.integration

HEAD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    xmlns:ssm="http://ssp-standard.org/SSP1/SystemStructureParameterMapping"
    xmlns:osp="http://opensimulationplatform.com/SSP/OSPAnnotations"
    xmlns:oms="https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd"
    name="others" version="{version}">
  <ssd:System name="root">
    {system_extra}
    <ssd:Elements>
      <ssd:Component name="Ship.Engine" source="resources/source.fmu">
        <ssd:Connectors><ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector></ssd:Connectors>
      </ssd:Component>
      <ssd:Component name="DP Controller" source="resources/gain.fmu">
        <ssd:Connectors>
          <ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
      {elements_extra}
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="Ship.Engine" startConnector="y" endElement="DP Controller" endConnector="u"/>
      {connections_extra}
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="0.5">{experiment}</ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
"""
OSP_STEP = ('<ssd:Annotations><ssc:Annotation type="com.opensimulationplatform"><osp:Algorithm>'
            '<osp:FixedStepAlgorithm baseStepSize="0.1"/></osp:Algorithm></ssc:Annotation></ssd:Annotations>')
OMS_STEP = ('<ssd:Annotations><ssc:Annotation type="org.openmodelica"><oms:Annotations><oms:SimulationInformation>'
            '<oms:FixedStepMaster description="oms-ma" stepSize="0.05" relativeTolerance="1e-4"/>'
            '</oms:SimulationInformation></oms:Annotations></ssc:Annotation></ssd:Annotations>')
SYSTEM_BINDING = ('<ssd:ParameterBindings><ssd:ParameterBinding source="resources/system.ssv">'
                  '<ssd:ParameterMapping source="resources/system.ssm"/></ssd:ParameterBinding></ssd:ParameterBindings>')


def _ssv(params: dict[str, float]) -> str:
    rows = "".join(f'<ssv:Parameter name="{n}"><ssv:Real value="{v!r}"/></ssv:Parameter>' for n, v in params.items())
    return ('<?xml version="1.0"?><ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/'
            f'SystemStructureParameterValues" version="1.0" name="system"><ssv:Parameters>{rows}</ssv:Parameters>'
            '</ssv:ParameterSet>')


def _ssm(entries: str) -> str:
    return ('<?xml version="1.0"?><ssm:ParameterMapping xmlns:ssm="http://ssp-standard.org/SSP1/'
            'SystemStructureParameterMapping" xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
            f'version="1.0">{entries}</ssm:ParameterMapping>')


# the system's set: "gain_value" mapped (x 1.5) onto the controller's k, "Ship.Engine.offset" applied by its name
SSV = _ssv({"gain_value": 2.0, "Ship.Engine.offset": 0.25})
SSM = _ssm('<ssm:MappingEntry source="gain_value" target="DP Controller.k">'
           '<ssc:LinearTransformation factor="1.5" offset="0"/></ssm:MappingEntry>')


def _archive(tmp_path: Path, test_fmus, name: str = "others.ssp", *, version: str = "1.0", system_extra: str = "",
             elements_extra: str = "", connections_extra: str = "", experiment: str = OSP_STEP,
             files: dict[str, str] | None = None, gain: str = "CosimTGain") -> Path:
    ssd = HEAD.format(version=version, system_extra=system_extra, elements_extra=elements_extra,
                      connections_extra=connections_extra, experiment=experiment)
    path = tmp_path / name
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("SystemStructure.ssd", ssd)
        for member, text in (files or {}).items():
            z.writestr(member, text)
        z.write(test_fmus["CosimTSource"], "resources/source.fmu")
        z.write(test_fmus[gain], "resources/gain.fmu")
    return path


def _cli(capsys, *argv) -> tuple[int, str, str]:
    rc = main([str(a) for a in argv])
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_names_with_spaces_and_dots_and_a_system_binding_with_a_mapping(tmp_path, test_fmus):
    """`DP Controller` and `Ship.Engine` connect, take the system-level set through its .ssm (k = 1.5 * 2),
    and are addressed by --set (`'Ship.Engine'.amplitude`, quoted for its dot) and by probes."""
    ssp = _archive(tmp_path, test_fmus, system_extra=SYSTEM_BINDING,
                   files={"resources/system.ssv": SSV, "resources/system.ssm": SSM})
    probe = Probe(["'Ship.Engine'.y", "DP Controller.y"])
    overrides = apply_overrides(["'Ship.Engine'.amplitude=0.5", "DP Controller.u=0"])
    with open_ssp(ssp, overrides) as sc:
        assert sc.components["DP Controller"].parameters == {"k": 3.0, "u": 0}, sc.components["DP Controller"]
        assert sc.components["Ship.Engine"].parameters == {"offset": 0.25, "amplitude": 0.5}, \
            sc.components["Ship.Engine"].parameters
        assert sc.algorithm == "jacobi", sc.algorithm
        res = run_scenario(sc, out=tmp_path / "others.mcap", observers=[probe])
    assert res.steps == 5, res.steps
    src, gain = np.array(probe.values["'Ship.Engine'.y"]), np.array(probe.values["DP Controller.y"])
    assert src[0] == 0.25, src  # the system-level offset reached the source
    # Jacobi (OSP's algorithm): the gain's step k reads the source's output of step k - 1
    np.testing.assert_allclose(gain[1:], 3.0 * src[:-1], rtol=0, atol=1e-15, err_msg="gain.y != k * src.y(t - h)")


def test_names_no_ssp_tool_can_address_are_exported_as_identifiers_and_mapped_back(tmp_path, test_fmus):
    """Our export of that system names its components as every SSP tool can address them (OMSimulator takes a
    component's name as an identifier: `Ship.Engine` and `DP Controller` cannot be added there), and a
    component named as the first part of one of its FMU's variables (`k`, the gain's parameter) gets `_` (its
    import and its Python API read `k.x` of a component `k` as `x`); our import maps the names back, and the run
    is the same."""
    ssp = _archive(tmp_path, test_fmus, system_extra=SYSTEM_BINDING,
                   files={"resources/system.ssv": SSV, "resources/system.ssm": SSM},
                   elements_extra='<ssd:Component name="k" source="resources/gain.fmu"><ssd:Connectors>'
                                  '<ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>'
                                  '<ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector>'
                                  '</ssd:Connectors></ssd:Component>',
                   connections_extra='<ssd:Connection startElement="DP Controller" startConnector="y" '
                                     'endElement="k" endConnector="u"/>')
    signals = ["'Ship.Engine'.y", "DP Controller.y", "k.y"]
    runs = []
    for archive in (ssp, tmp_path / "exported.ssp"):
        probe = Probe(signals)
        with open_ssp(archive) as sc:
            assert list(sc.components) == ["Ship.Engine", "DP Controller", "k"], list(sc.components)
            if archive == ssp:
                export_ssp(sc, tmp_path / "exported.ssp")
            run_scenario(sc, out=archive.with_suffix(".mcap"), observers=[probe])
        runs.append({s: probe.values[s] for s in signals})
    with zipfile.ZipFile(tmp_path / "exported.ssp") as z:
        ssd = ET.fromstring(z.read("SystemStructure.ssd"))
    names = [c.get("name") for c in ssd.iterfind("ssd:System/ssd:Elements/ssd:Component", NS)]
    assert names == ["Ship_Engine", "DP_Controller", "k_"], names
    ends = {(c.get("startElement"), c.get("endElement")) for c in ssd.iterfind("ssd:System/ssd:Connections/*", NS)}
    assert ends == {("Ship_Engine", "DP_Controller"), ("DP_Controller", "k_")}, ends
    assert runs[1] == runs[0], runs
    assert runs[0]["k.y"][-1] != 0.0, runs[0]  # the renamed component took part


def test_the_algebraic_loop_of_an_ssp_is_refused_with_set_advice(tmp_path, test_fmus, capsys):
    """Two gains in a feedthrough loop: OSP's annotation (Jacobi) runs them; without it (Gauss-Seidel)
    the loop is refused and the advice is a --set option, not YAML."""
    loop = ('<ssd:Component name="echo" source="resources/gain.fmu"><ssd:Connectors>'
            '<ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>'
            '<ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector></ssd:Connectors></ssd:Component>')
    conns = '<ssd:Connection startElement="DP Controller" startConnector="y" endElement="echo" endConnector="u"/>'
    ssp = _archive(tmp_path, test_fmus, elements_extra=loop, connections_extra=conns)
    path = tmp_path / "loop.ssp"  # echo drives the controller: DP Controller.y -> echo.u -> echo.y -> DP Controller.u
    with zipfile.ZipFile(ssp) as zin, zipfile.ZipFile(path, "w") as zout:
        for item in zin.namelist():
            data = zin.read(item)
            if item == "SystemStructure.ssd":
                data = data.replace(b'startElement="Ship.Engine" startConnector="y" endElement="DP Controller"',
                                    b'startElement="echo" startConnector="y" endElement="DP Controller"')
            zout.writestr(item, data)
    with open_ssp(path) as sc:
        assert sc.algorithm == "jacobi", sc.algorithm
    rc, _, err = _cli(capsys, "run", path, "--no-log", "--quiet")
    assert rc == 0, err
    rc, _, err = _cli(capsys, "run", path, "--no-log", "--quiet", "--set", "algorithm=gauss_seidel")
    assert rc == 2 and len(err.strip().splitlines()) == 1, err
    assert "algebraic loop" in err and "--set algorithm=jacobi" in err and "algorithm: jacobi" not in err, err


def test_omsimulator_step_annotation_sets_the_base_step(tmp_path, test_fmus):
    """OMSimulator writes its step on the system (oms:FixedStepMaster stepSize); the algorithm stays ours."""
    ssp = _archive(tmp_path, test_fmus, system_extra=OMS_STEP, experiment="")
    with open_ssp(ssp) as sc:
        assert sc.seconds()[2] == 0.05 and sc.n_steps() == 10, sc.seconds()
        assert sc.algorithm == "gauss_seidel", sc.algorithm
    both = _archive(tmp_path, test_fmus, "both.ssp", system_extra=OMS_STEP)  # OSP's 0.1 s against OMS's 0.05 s
    with pytest.raises(SspError) as exc:
        with open_ssp(both):
            pass
    assert "OSP annotation gives the base step 0.1 s, OMSimulator's 0.05 s" in str(exc.value), str(exc.value)


NESTED = '<ssd:System name="inner"><ssd:Elements/></ssd:System>'
BINDING_ERRORS = {
    "no_component": (_ssv({"Rudder.k": 1.0}), _ssm(""),
                     "resources/system.ssv: parameter 'Rudder.k' of a system-level binding names no component"),
    "no_variable": (_ssv({"DP Controller.kp": 1.0}), _ssm(""),
                    "resources/system.ssv: parameter 'DP Controller.kp': component 'DP Controller' has no "
                    "variable 'kp'"),
    "mapped_to_nothing": (_ssv({"g": 1.0}), _ssm('<ssm:MappingEntry source="g" target="Rudder.k"/>'),
                          "parameter 'Rudder.k' of a system-level binding names no component"),
    "unknown_map_value": (_ssv({"g": 1.0}), _ssm(
        '<ssm:MappingEntry source="g" target="DP Controller.k"><ssc:IntegerMappingTransformation>'
        '<ssc:MapEntry source="2" target="3"/></ssc:IntegerMappingTransformation></ssm:MappingEntry>'),
        "resources/system.ssm: parameter g of resources/system.ssv: IntegerMappingTransformation has no MapEntry"),
}
SYSTEM_CONNECTOR = '<ssd:Connectors><ssd:Connector name="x" kind="input"/></ssd:Connectors>'
UNSUPPORTED = {
    "nested_system": (dict(elements_extra=NESTED), "nested systems"),
    # the system's connectors are left out (below); a connection to one would leave its input without a value
    "system_connector_connected": (dict(system_extra=SYSTEM_CONNECTOR, connections_extra=(
        '<ssd:Connection startConnector="x" endElement="DP Controller" endConnector="u"/>')),
        "connections to the system's own connectors are not supported"),
    # signal dictionaries are left out (below); an element referring to one would be missing from the run
    "signal_dictionary_referred": (dict(system_extra='<ssd:SignalDictionaries><ssd:SignalDictionary name="d"/>'
                                                     '</ssd:SignalDictionaries>',
                                        elements_extra='<ssd:SignalDictionaryReference name="r" dictionary="d"/>'),
                                   "nested systems and signal dictionaries are not supported"),
}
LEFT_OUT = {
    "system_connectors": (dict(system_extra=SYSTEM_CONNECTOR),
                          "SystemStructure.ssd: the system's own connectors are left out (no connection uses them)"),
    "signal_dictionary": (dict(system_extra="<ssd:SignalDictionaries/>"),
                          "SystemStructure.ssd: the system's signal dictionaries are left out (no component refers "
                          "to them)"),
    "version_draft": (dict(version="Draft20171219"),
                      "SystemStructure.ssd: SSP version 'Draft20171219' read as SSP 1.0 (its namespaces are SSP "
                      "1.0's)"),
    "version_2_in_ssp1_namespaces": (dict(version="2.0"),
                                     "SystemStructure.ssd: SSP version '2.0' read as SSP 1.0 (its namespaces are SSP "
                                     "1.0's)"),
}


def test_an_empty_mapping_entry_maps_nothing_with_one_warning(tmp_path, test_fmus, capsys):
    """OMSimulator's published example writes ``<ssm:MappingEntry source="" target="..."/>``; OMSimulator reads it
    as no mapping for that target, and so do we (one warning), while the file's other entries apply."""
    ssm = _ssm('<ssm:MappingEntry source="" target="DP Controller.k"/>'
               '<ssm:MappingEntry source="gain_value" target="DP Controller.k">'
               '<ssc:LinearTransformation factor="1.5" offset="0"/></ssm:MappingEntry>')
    ssp = _archive(tmp_path, test_fmus, system_extra=SYSTEM_BINDING,
                   files={"resources/system.ssv": SSV, "resources/system.ssm": ssm})
    rc, _, err = _cli(capsys, "run", ssp, "--no-log", "--quiet")
    assert rc == 0, err
    assert err.strip().splitlines() == [
        "warning: others.ssp: resources/system.ssm: 1 MappingEntry with an empty source or target ('' -> "
        "'DP Controller.k') map nothing, as OMSimulator reads them"], err
    with open_ssp(ssp) as sc:
        assert sc.components["DP Controller"].parameters["k"] == 3.0  # the other entry: 1.5 * gain_value


UNITS = ('<ssd:Units><ssc:Unit name="m"><ssc:BaseUnit m="1"/></ssc:Unit>'
         '<ssc:Unit name="mm"><ssc:BaseUnit m="1" factor="0.001"/></ssc:Unit>'
         '<ssc:Unit name="s"><ssc:BaseUnit s="1"/></ssc:Unit></ssd:Units>')
UNIT_CASES = {
    "different_dimensions": ("m", "s", "", "the connectors' units 'm' and 's' are of different dimensions"),
    "conversion_needed": ("mm", "m", "", "the connectors' units differ ('mm' -> 'm') and unit conversion on "
                                         "connections is not supported"),
    "suppressed": ("m", "s", ' suppressUnitConversion="true"', None),
    "same": ("m", "m", "", None),
}


@pytest.mark.parametrize("case", list(UNIT_CASES))
def test_connector_units_that_differ_are_refused_unless_conversion_is_suppressed(tmp_path, test_fmus, capsys, case):
    """A connection from a connector in m to one in s was accepted silently; SSP converts between the units of
    two connectors, which this reader does not, so differing units are one line naming the connection (unless the
    connection suppresses the conversion: the numbers pass as they are)."""
    start, end, attr, expected = UNIT_CASES[case]
    ssd = HEAD.format(version="1.0", system_extra="", elements_extra="", connections_extra="", experiment=OSP_STEP)
    ssd = ssd.replace('<ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector></ssd:Connectors>',
                      f'<ssd:Connector name="y" kind="output"><ssc:Real unit="{start}"/></ssd:Connector>'
                      '</ssd:Connectors>', 1)
    ssd = ssd.replace('<ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>',
                      f'<ssd:Connector name="u" kind="input"><ssc:Real unit="{end}"/></ssd:Connector>', 1)
    ssd = ssd.replace('endConnector="u"/>', f'endConnector="u"{attr}/>', 1)
    ssd = ssd.replace("</ssd:System>", "</ssd:System>" + UNITS, 1)
    path = tmp_path / "units.ssp"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("SystemStructure.ssd", ssd)
        z.write(test_fmus["CosimTSource"], "resources/source.fmu")
        z.write(test_fmus["CosimTGain"], "resources/gain.fmu")
    rc, _, err = _cli(capsys, "run", path, "--no-log", "--quiet")
    if expected is None:
        assert rc == 0, err
    else:
        assert rc == 2 and len(err.strip().splitlines()) == 1, err
        assert "connection 'Ship.Engine'.y -> DP Controller.u: " + expected in err, err


@pytest.mark.parametrize("case", list(BINDING_ERRORS))
def test_a_system_binding_that_cannot_be_applied_is_one_line(tmp_path, test_fmus, capsys, case):
    ssv, ssm, expected = BINDING_ERRORS[case]
    ssp = _archive(tmp_path, test_fmus, system_extra=SYSTEM_BINDING,
                   files={"resources/system.ssv": ssv, "resources/system.ssm": ssm})
    rc, _, err = _cli(capsys, "run", ssp, "--no-log", "--quiet")
    assert rc == 2 and len(err.strip().splitlines()) == 1 and expected in err, err


@pytest.mark.parametrize("case", list(UNSUPPORTED))
def test_each_unsupported_ssp_feature_is_one_line_naming_it(tmp_path, test_fmus, capsys, case):
    kwargs, expected = UNSUPPORTED[case]
    ssp = _archive(tmp_path, test_fmus, **kwargs)
    rc, _, err = _cli(capsys, "run", ssp, "--no-log", "--quiet")
    assert rc == 2 and len(err.strip().splitlines()) == 1 and expected in err and str(ssp) in err, err


def _names_annotation(names_json: str) -> str:
    return ('<ssd:Annotations><ssc:Annotation type="org.delta-cosim.engine.scenario"><dcs:Scenario '
            f'xmlns:dcs="https://github.com/delta-cosim/ssp">{{"component_names": {names_json}}}</dcs:Scenario>'
            '</ssc:Annotation></ssd:Annotations>')


NAMES_ERRORS = {
    "not_a_mapping": ('["DP Controller"]', "component_names must map the archive's component names to the "
                                           "scenario's (strings), got a list"),
    "no_such_component": ('{"Nope": "x"}', "component_names names 'Nope', which is no component of the system"),
    "two_alike": ('{"Ship.Engine": "DP Controller"}', "component_names gives two components the name "
                                                      "'DP Controller'"),
}


@pytest.mark.parametrize("case", list(NAMES_ERRORS))
def test_component_names_that_cannot_be_mapped_back_are_one_line(tmp_path, test_fmus, capsys, case):
    names_json, expected = NAMES_ERRORS[case]
    ssp = _archive(tmp_path, test_fmus, system_extra=_names_annotation(names_json))
    rc, _, err = _cli(capsys, "run", ssp, "--no-log", "--quiet")
    assert rc == 2 and len(err.strip().splitlines()) == 1 and expected in err and str(ssp) in err, err


@pytest.mark.parametrize("case", list(LEFT_OUT))
def test_what_libcosim_leaves_out_is_one_warning_and_the_run_goes_on(tmp_path, test_fmus, capsys, case):
    """libcosim's SSP parser (src/cosim/ssp/ssp_parser.cpp) reads the version attribute without checking it and
    never reads the system's own connectors or its signal dictionaries; OMSimulator 2 wrote version="Draft20171219"
    with SSP 1.0's namespaces. Such an archive runs here too, with one warning naming what was read otherwise (a
    connection to a system connector stays refused: UNSUPPORTED)."""
    kwargs, says = LEFT_OUT[case]
    ssp = _archive(tmp_path, test_fmus, **kwargs)
    rc, _, err = _cli(capsys, "run", ssp, "--no-log", "--quiet")
    assert rc == 0, err
    assert err.strip().splitlines() == [f"warning: others.ssp: {says}"], err


def test_a_step_size_hint_off_the_base_step_is_one_warning_and_rounds_down_as_libcosim(tmp_path, test_fmus, capsys):
    """libcosim's fixed-step algorithm (calculate_decimation_factor) steps a component every max(1, floor(hint /
    base step)) base steps and logs a warning where the hint is no whole multiple; so do we: 0.25 s on a 0.1 s base
    step is a step multiple of 2 (0.2 s), 0.05 s is 1 (0.1 s), each with one warning naming the component."""
    for hint, multiple, every in ((0.25, 2, "0.2"), (0.05, 1, "0.1")):
        annotation = ('<ssd:Annotations><ssc:Annotation type="com.opensimulationplatform">'
                      f'<osp:StepSizeHint value="{hint}"/></ssc:Annotation></ssd:Annotations>')
        ssp = _archive(tmp_path, test_fmus, f"hint{multiple}.ssp")
        ssp = _edited(ssp, lambda ssd: ssd.replace('source="resources/gain.fmu">',
                                                   'source="resources/gain.fmu">' + annotation, 1))
        rc, _, err = _cli(capsys, "run", ssp, "--no-log", "--quiet")
        assert rc == 0, err
        assert err.strip().splitlines() == [
            f"warning: {ssp.name}: component 'DP Controller': osp:StepSizeHint {hint:g} s is not a whole multiple of "
            f"the base step 0.1 s: it steps every {every} s, as libcosim does"], err
        with open_ssp(ssp) as sc:
            assert sc.components["DP Controller"].step_multiple == multiple, sc.components["DP Controller"]
        capsys.readouterr()  # open_ssp's own warning, said again


def test_connector_kinds_ssp_does_not_know_are_one_warning_per_component_and_kind(tmp_path, test_fmus, capsys):
    """libcosim's SSP parser stores a connector's kind unchecked and connects the FMU's variables: so do we, with one
    warning per component and kind naming its connectors (not one line per connector)."""
    ssp = _edited(_archive(tmp_path, test_fmus, "kinds.ssp"), lambda ssd: ssd.replace(
        '<ssd:Connector name="u" kind="input">', '<ssd:Connector name="u" kind="signal">').replace(
        '          <ssd:Connector name="y" kind="output">', '          <ssd:Connector name="y" kind="signal">'))
    rc, _, err = _cli(capsys, "run", ssp, "--no-log", "--quiet")
    assert rc == 0, err
    assert err.strip().splitlines() == [
        "warning: kinds.ssp: component 'DP Controller': connectors 'u', 'y': kind 'signal' is not an SSP connector "
        "kind (input, output, inout, parameter, calculatedParameter): its FMU's variable decides"], err


def _edited(ssp: Path, edit) -> Path:
    """``ssp`` with its SystemStructure.ssd rewritten by ``edit`` (in place)."""
    with zipfile.ZipFile(ssp) as z:
        members = {n: z.read(n) for n in z.namelist()}
    members["SystemStructure.ssd"] = edit(members["SystemStructure.ssd"].decode()).encode()
    with zipfile.ZipFile(ssp, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)
    return ssp


def test_ssp_2_namespace_is_named(tmp_path, test_fmus, capsys):
    ssp = tmp_path / "ssp2.ssp"
    with zipfile.ZipFile(ssp, "w") as z:
        z.writestr("SystemStructure.ssd", '<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP2/'
                                          'SystemStructureDescription" version="2.0" name="x"/>')
    rc, _, err = _cli(capsys, "run", ssp, "--no-log", "--quiet")
    assert rc == 2 and "SSP 2.0 is not supported" in err and len(err.strip().splitlines()) == 1, err


def test_an_undeclared_osp_prefix_is_read_as_libcosim_reads_it(tmp_path, test_fmus):
    """Published OSP files use ``osp:`` without declaring it (not well-formed XML); libcosim reads them, and so
    do we: the annotation still makes the algorithm Jacobi with its base step. Another unbound prefix stays an
    error naming the member."""
    undeclared = HEAD.replace('    xmlns:osp="http://opensimulationplatform.com/SSP/OSPAnnotations"\n', "")
    assert "xmlns:osp" not in undeclared
    path = tmp_path / "undeclared.ssp"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("SystemStructure.ssd", undeclared.format(version="1.0", system_extra="", elements_extra="",
                                                            connections_extra="", experiment=OSP_STEP))
        z.write(test_fmus["CosimTSource"], "resources/source.fmu")
        z.write(test_fmus["CosimTGain"], "resources/gain.fmu")
    with open_ssp(path) as sc:
        assert sc.algorithm == "jacobi" and sc.seconds()[2] == 0.1, (sc.algorithm, sc.seconds())
    other = tmp_path / "other.ssp"
    with zipfile.ZipFile(other, "w") as z:
        z.writestr("SystemStructure.ssd", undeclared.format(version="1.0", system_extra="<foo:Bar/>",
                                                            elements_extra="", connections_extra="",
                                                            experiment=OSP_STEP))
    with pytest.raises(SspError, match=r"SystemStructure.ssd: not well-formed XML \(unbound prefix"):
        with open_ssp(other):
            pass
