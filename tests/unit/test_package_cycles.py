"""The robot's packages have no import cycle either: ``delta`` (the pure core, which also runs inside FMUs) and
``multibody`` (the Exudyn plants), every import counted (module level, inside functions, under TYPE_CHECKING,
through a package's ``__init__``). ``cosim`` and ``fmus`` have their own tests (test_layers.py,
test_fmus_definitions.py)."""

from __future__ import annotations

from pathlib import Path

import pytest
from import_graph import imports_anywhere, package_cycles, package_modules

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("package", ["delta", "multibody"])
def test_the_package_has_no_import_cycle(package):
    assert len(package_modules(ROOT, package)) > 3, f"{package}: no modules found under {ROOT / package}"
    found = package_cycles(ROOT, package)
    assert not found, "\n".join(found)


def test_the_cycle_check_sees_a_cycle_through_a_function_and_a_package(tmp_path):
    """A planted package whose ``__init__`` re-exports a module that imports a name of the package back, inside a
    function: the check finds the cycle. A module importing its sibling directly is no cycle."""
    pkg = tmp_path / "planted"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("from .a import f\nVALUE = 1\n")
    (pkg / "a.py").write_text("from .b import g\n\n\ndef f():\n    from planted import VALUE\n    return VALUE + g()\n")
    (pkg / "b.py").write_text("def g():\n    return 1\n")
    modules = package_modules(tmp_path, "planted")
    assert imports_anywhere(modules, "planted.a") == {"planted", "planted.b"}
    assert imports_anywhere(modules, "planted.b") == set()
    assert package_cycles(tmp_path, "planted") == ["planted -> planted.a -> planted"]
