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
        assert fmu.has_native == (fmu.native is not None), fmu.name  # what native_names() reads unloaded
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


def test_what_an_fmu_is_is_known_without_loading_its_classes():
    """A run of cached FMUs asks the registry what each FMU is and for its cached build: neither loads the
    adapters' pythonfmu3 nor the native models' CasADi (~0.09 s of every run's start)."""
    import subprocess
    import sys

    code = ("import sys; from fmus import registry; e = registry.get('linear_ctc'); "
            "assert (e.role, e.variant, registry.native_names()[0]) == ('controller', 'ctc', 'linear_ik'); "
            "print(sorted(m for m in ('casadi', 'pythonfmu3', 'fmus.native.models', 'fmus.adapters.controllers') "
            "if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]", done.stdout
    assert registry.get("linear_ctc").adapter.__name__ == "CTCController"  # and asked, they load
