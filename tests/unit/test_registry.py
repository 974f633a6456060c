"""fmus.registry: one definition per FMU, holding its adapter class and its native model class themselves."""

from __future__ import annotations

import pytest

pytest.importorskip("pythonfmu")

from fmus import registry  # noqa: E402


def test_every_definition_holds_its_adapter_and_native_model_classes():
    from fmus.export2 import Adapter
    from fmus.export3 import AdapterME
    from fmus.native.models import NativeModel

    for fmu in registry.REGISTRY.values():
        assert issubclass(fmu.adapter, AdapterME if fmu.fmi == 3 else Adapter), fmu
        cls = fmu.python_class()
        assert (cls.__name__, cls.KIND, cls.__mro__[1]) == (fmu.name, fmu.kind, fmu.adapter), fmu.name
        if fmu.native is not None:
            assert issubclass(fmu.native, NativeModel), fmu
            assert fmu.native_model().kind == fmu.kind, fmu.name
    assert registry.native_names() == [n for n in registry.names() if not n.endswith("_exudyn_plant")]


def test_an_fmu_whose_modules_are_missing_is_not_available(monkeypatch):
    from dataclasses import replace

    fmu = replace(registry.get("linear_ik"), requires=("no_such_package.plant",))
    monkeypatch.setitem(registry.REGISTRY, "linear_ik", fmu)
    assert "linear_ik" not in registry.available(), registry.available()
    with pytest.raises(ImportError, match="needs no_such_package.plant"):
        registry.adapter(fmu)


def test_an_fmu_without_native_build_says_which_have_one(tmp_path):
    from fmus.native.errors import NativeError

    with pytest.raises(NativeError, match=r"FMU 'linear_exudyn_plant' has no native build; native FMUs: linear_ik, "):
        registry.build("linear_exudyn_plant", tmp_path, native=True)


def test_unknown_fmu_names_the_valid_ones():
    from delta.errors import DeltaError

    with pytest.raises(DeltaError, match=r"unknown FMU 'helx'; did you mean helix\? our FMUs: linear_ik, "):
        registry.get("helx")
