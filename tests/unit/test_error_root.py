"""Every error a user can meet derives from the project's root, delta.errors.CosimError, and from the
builtin that matches its meaning (callers may catch either)."""

from __future__ import annotations

import importlib

import pytest

from delta.errors import CosimError


@pytest.mark.parametrize("module,name,builtin", [
    ("fmus.builder", "BuildError", RuntimeError),
    ("fmus.registry", "AdapterError", ImportError),
    ("cosim.fmi.integrators", "IntegratorError", RuntimeError),
    ("cosim.errors", "UnknownSignalError", KeyError),
    ("multibody.plant", "PlantError", RuntimeError),
    ("multibody.plant", "RobotTypeError", TypeError),
])
def test_error_classes_derive_from_the_root_and_their_builtin(module, name, builtin):
    cls = getattr(importlib.import_module(module), name)  # our own modules: a broken one fails, never skips
    assert issubclass(cls, CosimError) and issubclass(cls, builtin), f"{name}.__mro__ = {cls.__mro__}"


def test_unknown_signal_message_is_not_quoted():
    from cosim.errors import UnknownSignalError

    assert str(UnknownSignalError("no signal 'x'")) == "no signal 'x'", str(UnknownSignalError("no signal 'x'"))


@pytest.mark.parametrize("settings", [{"spectral_radius": 1.5}, {"substeps": 0}, {"max_step": 0.0},
                                      {"min_step": -1.0}])
def test_solver_settings_raise_a_parameter_error(settings):
    import multibody.plant as plant
    from delta.errors import ParameterError

    with pytest.raises(ParameterError, match=f"SolverSettings.{next(iter(settings))} must be"):
        plant.SolverSettings(**settings)


def test_unknown_solver_is_a_parameter_error():
    from cosim.fmi.integrators import make_integrator
    from delta.errors import ParameterError

    with pytest.raises(ParameterError, match="unknown solver 'euler'; valid: cvode, dop853"):
        make_integrator("euler", None, 0.0, 1e-6, 1e-3)
