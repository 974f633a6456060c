"""The SSP 1.0 vocabulary the reader and the writer share: namespaces, annotation and media types, the FMI types
SSP carries, the scenario sections our annotation holds, and :class:`SspError`."""

from __future__ import annotations

import sys
from pathlib import Path
from xml.etree import ElementTree as ET

from ...errors import Issue, ScenarioError, printable

__all__ = ["NS", "SSD_NAME", "SspError", "is_ssp", "warn"]


NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "ssm": "http://ssp-standard.org/SSP1/SystemStructureParameterMapping",
    "ssb": "http://ssp-standard.org/SSP1/SystemStructureSignalDictionary",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
    "dcs": "https://github.com/delta-cosim/ssp",
    "oms": "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd",
}
SSD_NAME = "SystemStructure.ssd"


def is_ssp(path: str | Path) -> bool:
    """Whether ``path`` names an SSP archive (by its suffix, as SSP 1.0 names them)."""
    return Path(path).suffix.lower() == ".ssp"

OSP_ANNOTATION = "com.opensimulationplatform"
OMS_ANNOTATION = "org.openmodelica"
OUR_ANNOTATION = "org.delta-cosim.engine.scenario"
FMU_TYPE = "application/x-fmu-sharedlibrary"
PARAMETER_SET_TYPE = "application/x-ssp-parameter-set"
PARAMETER_MAPPING_TYPE = "application/x-ssp-parameter-mapping"
IMPLEMENTATION = {"cs": "CoSimulation", "me": "ModelExchange"}
INTERFACE = {"CoSimulation": "cs", "ModelExchange": "me", "any": "auto"}
# FMI 2.0 / 3.0 declared types -> SSP 1.0 connector / parameter types
SSP_TYPE = {"Real": "Real", "Float64": "Real", "Float32": "Real", "Integer": "Integer",
            "Int8": "Integer", "Int16": "Integer", "Int32": "Integer", "Int64": "Integer", "UInt8": "Integer",
            "UInt16": "Integer", "UInt32": "Integer", "UInt64": "Integer", "Boolean": "Boolean",
            "String": "String"}
# scenario sections carried in our annotation (SSP has no place for them)
EXTRAS = ("description", "robot", "algorithm", "parallel", "trajectory", "initial_state", "logging", "compare",
          "checks", "regression", "events")
COMPONENT_OPTIONS = ("interface", "feedthrough", "rtol", "solver", "max_step")


class SspError(ScenarioError):
    """An SSP archive cannot be read or written: one line naming the file and the problem."""

    def __init__(self, file: str | Path, message: str):
        super().__init__(Issue("", message, str(file)))


def warn(ssp: Path, message: str) -> None:
    """One line on stderr for what the reader takes as other tools take it (and says so): ``warning: ARCHIVE:
    message``, control characters escaped (the archive's names are outside input)."""
    print(printable(f"warning: {Path(ssp).name}: {message}"), file=sys.stderr)


def num_text(x: float) -> str:
    """A float as the shortest text that reads back to the same double (C strtod included)."""
    return repr(float(x))


def qname(prefix: str, tag: str) -> str:
    """``{namespace}tag`` of a prefixed name (:data:`NS`)."""
    return f"{{{NS[prefix]}}}{tag}"


def local_name(el: ET.Element) -> str:
    return el.tag.rsplit("}", 1)[-1]
