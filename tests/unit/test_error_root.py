"""Every error a user can meet derives from its room's root and from the builtin that matches its meaning
(callers may catch either): the master's from cosim.errors.CosimError, the robot's packages' from
delta.errors.DeltaError, which the robot layer registers with the master as a domain error root."""

from __future__ import annotations

import importlib

import pytest

from cosim.errors import CosimError
from delta.errors import DeltaError


@pytest.mark.parametrize("module,name,builtin,root", [
    ("fmus.builder", "BuildError", RuntimeError, DeltaError),
    ("fmus.registry", "AdapterError", ImportError, DeltaError),
    ("cosim.fmi.integrators", "IntegratorError", RuntimeError, CosimError),
    ("cosim.errors", "UnknownSignalError", KeyError, CosimError),
    ("cosim.errors", "SettingError", ValueError, CosimError),
    ("multibody.errors", "PlantError", RuntimeError, DeltaError),
    ("multibody.errors", "RobotTypeError", TypeError, DeltaError),
])
def test_error_classes_derive_from_the_root_and_their_builtin(module, name, builtin, root):
    cls = getattr(importlib.import_module(module), name)  # our own modules: a broken one fails, never skips
    assert issubclass(cls, root) and issubclass(cls, builtin), f"{name}.__mro__ = {cls.__mro__}"


def test_the_robot_layer_registers_its_error_root_with_the_master():
    from cosim import errors
    from cosim.engine import plugins

    plugins.installed()
    assert DeltaError in errors.user_errors(), errors.user_errors()


def test_unknown_signal_message_is_not_quoted():
    from cosim.errors import UnknownSignalError

    assert str(UnknownSignalError("no signal 'x'")) == "no signal 'x'", str(UnknownSignalError("no signal 'x'"))


@pytest.mark.parametrize("settings", [{"spectral_radius": 1.5}, {"substeps": 0}, {"max_step": 0.0},
                                      {"min_step": -1.0}])
def test_solver_settings_raise_a_parameter_error(settings):
    from delta.errors import ParameterError
    from multibody.settings import SolverSettings

    with pytest.raises(ParameterError, match=f"SolverSettings.{next(iter(settings))} must be"):
        SolverSettings(**settings)


def test_unknown_solver_is_a_setting_error():
    from cosim.errors import SettingError
    from cosim.fmi.integrators import make_integrator

    with pytest.raises(SettingError, match="unknown solver 'euler'; valid: cvode, dop853"):
        make_integrator("euler", None, 0.0, 1e-6, 1e-3)


def test_a_refusal_of_the_system_is_told_from_a_fault_of_the_input(tmp_path):
    """A path inside the folder named, or a full, read-only or over-quota disk: the system refused the folder. A
    sibling whose name only begins like the folder's is not inside it."""
    import errno

    from cosim.errors import refused_by_system

    folder = tmp_path / "work"
    assert refused_by_system(OSError(errno.EACCES, "denied", str(folder / "x")), folder)
    assert refused_by_system(OSError(errno.ENOSPC, "full", "/elsewhere/x"), folder)
    assert not refused_by_system(OSError(errno.EACCES, "denied", str(tmp_path / "work2" / "x")), folder)
    assert not refused_by_system(OSError(errno.EIO, "broken archive"), folder)
