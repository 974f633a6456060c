"""Small inputs that asked for unbounded memory are refused in one line (issue 25)."""

from __future__ import annotations

import pytest

from delta.errors import ParameterError


def test_workspace_grid_too_fine_is_refused_with_the_spacing_that_fits():
    from delta.robots import get_preset
    from delta.workspace import MAX_GRID_POINTS, sample_workspace

    with pytest.raises(ParameterError, match=r"use a spacing of at least") as info:
        sample_workspace(get_preset("linear_delta_thesis"), spacing=0.0005)
    assert f"{MAX_GRID_POINTS:.0e}" in str(info.value), info.value


def test_sweep_with_too_many_cases_is_refused_before_they_are_made():
    from cosim.analysis.cases import SweepError, make_cases
    from cosim.analysis.limits import MAX_CASES

    with pytest.raises(SweepError, match=f"the sweep has {MAX_CASES + 1:,} cases, more than the {MAX_CASES:,}"):
        make_cases({}, {"ctl.gain.kp[1]": ("uniform", 1e4, 2e4)}, MAX_CASES + 1, 1)
    with pytest.raises(SweepError, match="the sweep has 1,002,001 cases"):  # exact: not "1e+06 (at most 1000000)"
        make_cases({"a": list(range(1001)), "b": list(range(1001))}, {}, None, None)


def test_a_spacing_too_fine_to_count_is_refused_with_a_finite_spacing():
    """1e-300 m: the grid's point count overflowed the message's float formatting (a traceback), and the spacing
    that fits came out infinite."""
    import re

    from delta.robots import get_preset
    from delta.workspace import sample_workspace

    with pytest.raises(ParameterError, match=r"use a spacing of at least") as info:
        sample_workspace(get_preset("linear_delta_thesis"), spacing=1e-300)
    fits = float(re.search(r"at least (\S+) m", str(info.value))[1])
    assert 1e-4 < fits < 1e-2, info.value  # a spacing that fits 2e7 points in a box of about 0.6 m a side
    with pytest.raises(ParameterError, match="finite length > 0"):
        sample_workspace(get_preset("linear_delta_thesis"), spacing=float("inf"))


def test_a_grid_axis_of_several_names_sets_them_all_to_each_value():
    """``plant.mass.payload,ctl.mass.payload=0,0.5``: one axis (two cases, not four), both names set alike; a
    name on two axes is refused."""
    from cosim.analysis.cases import SweepError, make_cases, parse_grid

    cases = make_cases(parse_grid(["plant.mass.payload,ctl.mass.payload=0,0.5", "ctl.gain.kp[1]=1e4,2e4"]), {},
                       None, None)
    assert sorted((c.values["plant.mass.payload"], c.values["ctl.mass.payload"], c.values["ctl.gain.kp[1]"])
                  for c in cases) == [(0, 0, 1e4), (0, 0, 2e4), (0.5, 0.5, 1e4), (0.5, 0.5, 2e4)]
    with pytest.raises(SweepError, match="plant.mass.payload: set by more than one --grid or --random"):
        make_cases(parse_grid(["plant.mass.payload,ctl.mass.payload=0,0.5", "plant.mass.payload=1,2"]), {}, None,
                   None)
