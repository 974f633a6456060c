"""Every refusal of outside input in the audited readers says why it is a refusal and not a warning.

Strict where it protects, lenient where other tools are: an error raised on what an SSP archive, an FMU's
modelDescription.xml, a scenario or --set value, a run's log, a checkpoint or a recording holds is either a security
need (a bound on memory or time, a path out of a folder, a file that would be read for ever) or a correctness need
(the run would be silently wrong, a value ambiguous where it is used). Each such ``raise`` carries ``# Refused
(security): why`` or ``# Refused (correctness): why`` on the line above it (or on its own lines); what is neither
is read as other tools read it, with one warning. A new ``raise`` in these modules without that comment fails
here, naming file and line.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
AUDITED = [
    "cosim/io/ssp/archive.py", "cosim/io/ssp/components.py", "cosim/io/ssp/parameters.py", "cosim/io/ssp/read.py",
    "cosim/io/ssp/scenario.py", "cosim/io/ssp/units.py",
    "cosim/fmi/description.py", "cosim/fmi/extract.py",
    "cosim/engine/bounded_yaml.py", "cosim/engine/scenario.py", "cosim/engine/overrides.py", "cosim/engine/system.py",
    "cosim/engine/schema.py", "cosim/engine/grid.py", "cosim/engine/names.py", "cosim/engine/events.py",
    "cosim/engine/prepare.py",
    "cosim/io/runlog.py", "cosim/io/recover.py", "cosim/io/checkpoint.py",
    *(f"cosim/io/recordings/{m}.py" for m in ("bags", "component", "csvfile", "export", "recording", "spec", "units")),
    *(f"cosim/analysis/{m}.py" for m in ("cases", "compare", "recording_compare", "report", "results", "sweep",
                                         "sweep_report", "table", "tracking")),
]
"""The modules audited, whose every ``raise X`` is a refusal. Not listed though audited: cosim/analysis/calibrate.py
(its budget and a number's check raise for control flow) and cosim/analysis/cluster.py (it raises again the error
its thread recorded); their refusals carry the comment all the same."""
SAID = re.compile(r"# Refused \((security|correctness)\): \S")


def unsaid_raises(source: str) -> list[int]:
    """Lines of the ``raise X`` statements of ``source`` (a bare ``raise`` re-raises: not a new refusal) with no
    ``# Refused (security|correctness): ...`` comment on the line above them or on their own lines."""
    lines = source.splitlines()
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Raise) and node.exc is not None:
            span = lines[max(node.lineno - 2, 0):node.end_lineno]
            if not any(SAID.search(line) for line in span):
                out.append(node.lineno)
    return sorted(out)


@pytest.mark.parametrize("module", AUDITED)
def test_every_refusal_says_why(module):
    path = ROOT / module
    missing = unsaid_raises(path.read_text(encoding="utf-8"))
    assert not missing, (f"{module}: a raise without '# Refused (security|correctness): why' above it at line(s) "
                         f"{missing}: say which need the refusal serves, or make it one warning and read on")


def test_the_check_finds_a_refusal_that_does_not_say_why():
    """The checker itself: an unexplained raise is found, one that says why is not, a bare re-raise is not, and a
    comment above another raise does not cover the next one."""
    source = ("def f(x):\n"
              "    if x is None:\n"
              "        # Refused (correctness): nothing to read\n"
              "        raise ValueError('none')\n"
              "    if x < 0:\n"
              "        raise ValueError('negative')\n"
              "    try:\n"
              "        return 1 / x\n"
              "    except ZeroDivisionError:\n"
              "        raise\n"
              "    # Refused (security): bounded\n"
              "    raise ValueError('a')\n"
              "    raise ValueError('b')\n"
              "    raise OverflowError(  # Refused (security): too large\n"
              "        'c')\n")
    assert unsaid_raises(source) == [6, 13], unsaid_raises(source)
