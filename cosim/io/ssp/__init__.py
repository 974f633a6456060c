"""SSP 1.0 (System Structure and Parameterization, ssp-standard.org) export and import.

Export (:func:`~cosim.io.ssp.write.export_ssp`, ``python -m cosim ssp export SCENARIO -o SYSTEM.ssp``) writes a
scenario as an SSP archive that any SSP tool can run:

- ``SystemStructure.ssd``: one ``ssd:Component`` per FMU (``source="resources/<name>.fmu"``,
  ``implementation`` when the scenario fixes the interface, except model exchange of an FMU that also
  offers co-simulation: OMSimulator's Python API loses such a component's connections), its scalar
  inputs and outputs and the parameters its .ssv sets as connectors with kind, type and unit
  (``ssd:Units`` defines the units from the FMUs' own UnitDefinitions), one ``ssd:Connection`` per
  scenario connection (element-wise, as written),
  components and the system named as every SSP tool can address them (identifiers; a component's name is
  never the first part of one of its FMU's variables), our annotation mapping the components' names back,
  the default experiment (``startTime``, ``stopTime``) with the base step in the OSP annotation
  libcosim reads (``osp:FixedStepAlgorithm baseStepSize``) and a component's step multiple as
  ``osp:StepSizeHint``;
- ``resources/<name>.ssv``: per component, every start value our master sets (the plan of
  :func:`cosim.engine.prepare.prepare`: explicit parameters, our trajectory FMUs' parameters from the
  ``trajectory:`` section and the plant's initial state), bound through ``ssd:ParameterBinding``,
  except a String equal to the FMU's own start value (OMSimulator 3.0 reads no ``ssv:String``);
- ``resources/<name>.fmu``: the FMUs;
- a root annotation of type ``org.delta-cosim.engine.scenario`` holding what SSP has no place for
  (algorithm, robot, trajectory for the pre-flight, comparison, checks, logging, per-component
  solver options) as JSON, so our master runs the archive exactly as the YAML. Other tools ignore
  it. ``initial_state.from_trajectory`` is written false: its values are in the plant's .ssv.

Import (:func:`~cosim.io.ssp.scenario.open_ssp`, ``python -m cosim run|check SYSTEM.ssp``) reads any SSP 1.0 archive with
FMU components (ours or another tool's): the .ssd, its parameter bindings (.ssv files or inline
parameter sets), the FMUs from the archive, into a scenario document (:func:`~cosim.io.ssp.read.read_ssp`), which is
validated and overridden (``--set``) as a YAML scenario's is, and gives the same
:class:`cosim.engine.structure.SystemStructure` the YAML loader gives, run by the normal
:func:`cosim.run.run_scenario` (the CLI, ``cosim.api.run`` and ``run --from-log`` of an archive's run take it). The base step comes from
the OSP annotation (``osp:FixedStepAlgorithm baseStepSize``, which also makes the algorithm Jacobi:
libcosim's fixed_step_algorithm steps every FMU from the previous step's values) or OMSimulator's
(``oms:FixedStepMaster stepSize`` on the system; two annotations that disagree are an error), else
from the FMUs' default experiments (the smallest), else ``--step``; the stop time from the default
experiment, else the FMUs', else ``--stop-time``. Our own annotation, when present, sets the algorithm.
Parameter bindings of a component and of the system (``Component.parameter`` names, the longest
component name that fits) are applied, each through its ``.ssm`` parameter mapping (SSP 1.0: a mapped
name goes to the entry's targets through its linear, boolean, integer or enumeration transformation;
an unmapped name stays as it is); the system's come last and win. Component names are SSP's: any text
(``DP Controller``); in dotted names a name with a dot is quoted (:mod:`cosim.engine.names`), and a file
made from a name is made safe first. The archive is
unpacked into a temporary directory that :func:`~cosim.io.ssp.scenario.open_ssp` removes when its block ends (also on
error and Ctrl-C); the structure names the archive and its SHA-256, which a run's log records, so that
``run --from-log`` unpacks the same archive again (:func:`~cosim.io.ssp.scenario.reopen_ssp`). Bad input raises
:class:`~cosim.io.ssp.spec.SspError`: one line naming the file and the problem.
Not supported (a clear error, never a silent change): SSP 2.0, nested systems, signal dictionaries,
system-level connectors, connection transformations, components that are not FMUs, FMI 3 arrays.

Library choice: the standard library's ``xml.etree.ElementTree``, written against the SSP 1.0 XSDs
(those shipped with fmpy in ``fmpy/ssp/schema``; the tests validate every exported file against
them). fmpy's ``fmpy.ssp`` reads but cannot write, rejects any file that fails the schema with a
bare ``Exception`` and reads transformations in the wrong namespace; ``pyssp-standard`` would be a
new dependency with few users. OSP libcosim matches element names by their prefixes literally
(``ssd:``, ``ssc:``, ``ssv:``, ``osp:``), so the writer emits prefixed names itself instead of
relying on ElementTree's namespace registry (a process-wide setting); the reader resolves
namespaces properly, so files of other tools with other prefixes read too.

One module per role: :mod:`.spec` (the vocabulary: namespaces, types, :class:`SspError`), :mod:`.write` (export),
:mod:`.read` (an archive into scenario data), :mod:`.archive` (its members, bounded), :mod:`.components` (its FMU
components), :mod:`.parameters` (parameter sets and mappings), :mod:`.units` (unit definitions and conversions),
:mod:`.scenario` (an archive as a system structure, unpacked for a block). Callers import from those modules; the names
below are offered here for callers outside the package (:mod:`cosim.io.runlog`: ``reopen_ssp``), each imported
from its module when first asked for (PEP 562): ``run`` of a YAML scenario asks whether its file is an archive
(:func:`.spec.is_ssp`) without loading the reader and the writer.
"""

from importlib import import_module

_MODULE = {"read_ssp": "read", "open_ssp": "scenario", "reopen_ssp": "scenario", "is_ssp": "spec", "NS": "spec",
           "SSD_NAME": "spec", "SspError": "spec", "ExportReport": "write", "export_ssp": "write"}


def __getattr__(name: str):
    try:
        module = _MODULE[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    return getattr(import_module(f".{module}", __name__), name)


__all__ = list(_MODULE)
