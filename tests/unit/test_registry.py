"""fmus.registry: which adapter class serves which FMU is declared, and checked by importing it."""

from __future__ import annotations

import pytest

pytest.importorskip("pythonfmu")

from fmus import registry  # noqa: E402


def test_every_declared_adapter_is_a_class_of_its_module():
    for entry in registry.REGISTRY.values():
        cls = registry.adapter(entry)
        assert (cls.__name__, cls.__module__) == (entry.cls, f"fmus.adapters.{entry.module}"), \
            f"{entry.name}: {cls.__module__}.{cls.__name__} vs fmus.adapters.{entry.module}.{entry.cls}"


@pytest.mark.parametrize("change,reason", [
    ({"cls": "NoSuchAdapter"}, "fmus.adapters.kinematics has no adapter class NoSuchAdapter"),
    ({"module": "no_such_module"}, "no_such_module"),
    ({"requires": ("no_such_package.plant",)}, "needs no_such_package.plant"),
])
def test_an_entry_without_its_adapter_is_not_available(monkeypatch, change, reason):
    from dataclasses import replace

    entry = replace(registry.get("linear_ik"), **change)
    monkeypatch.setitem(registry.REGISTRY, "linear_ik", entry)
    assert "linear_ik" not in registry.available(), registry.available()
    with pytest.raises(ImportError, match=reason):
        registry.adapter(entry)


def test_unknown_fmu_names_the_valid_ones():
    from delta.errors import DeltaError

    with pytest.raises(DeltaError, match=r"unknown FMU 'helx'; did you mean helix\? our FMUs: linear_ik, "):
        registry.get("helx")
