"""estimate_offset: the recording's time minus the run's, found below the sampling step, for offsets of either
sign, one or several signals; and the --map parser."""

from __future__ import annotations

import numpy as np
import pytest

from cosim.analysis.recording_compare import estimate_offset, parse_maps
from cosim.errors import CosimError

RUN_T = np.arange(0.0, 4.0, 0.001)  # the run: 1 ms
REC_T = np.arange(0.0, 4.5, 0.004)  # the recording: 4 ms, its own clock
# noise-free: what is left is the recording's linear interpolation (4 ms on a 1.3 Hz signal: h^2/8 y'' about
# 2e-5 of the amplitude), which moves the residual's minimum by well under 1 us; the grid alone is up to 2 ms off
OFFSET_ATOL_S = 1e-6


def f(t):
    return np.sin(2 * np.pi * 1.3 * t) + 0.5 * np.sin(2 * np.pi * 0.37 * t + 0.4) + 0.2 * t


def g(t):
    return np.cos(3.0 * t)


@pytest.mark.parametrize("offset", [0.0123456, -0.3141, 0.0])
def test_offset_below_the_step(offset):
    one = estimate_offset([(RUN_T, f(RUN_T))], [(REC_T, f(REC_T - offset))])
    both = estimate_offset([(RUN_T, f(RUN_T)), (RUN_T, g(RUN_T))],
                           [(REC_T, f(REC_T - offset)), (REC_T, g(REC_T - offset))])
    for found in (one, both):
        assert abs(found.offset - offset) < OFFSET_ATOL_S, f"{found.offset} vs {offset} (coarse {found.coarse})"
        assert found.step == pytest.approx(0.001) and found.correlation > 0.99, found


def test_max_offset_bounds_the_search():
    found = estimate_offset([(RUN_T, f(RUN_T))], [(REC_T, f(REC_T - 0.3141))], max_offset=0.1)
    assert abs(found.offset) <= 0.1 + found.step, f"{found.offset}: outside --max-offset 0.1 s"
    with pytest.raises(CosimError, match="share no time span"):
        estimate_offset([(RUN_T[:1], f(RUN_T[:1]))], [(REC_T, f(REC_T))])


def test_maps():
    assert parse_maps(["plant.q[1]=/js.position[j1]", " ctl.q[2] = q2 "]) == {"plant.q[1]": "/js.position[j1]",
                                                                             "ctl.q[2]": "q2"}
    with pytest.raises(CosimError, match="expected RUN_SIGNAL=RECORDING_SIGNAL"):
        parse_maps(["plant.q[1]"])
    with pytest.raises(CosimError, match="mapped twice"):
        parse_maps(["a=b", "a=c"])
