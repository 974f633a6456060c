"""Reference figures transcribed from the seed papers, for verification (units as printed).

Tests and reports compare against these; the papers' own units are kept so a reader can
check every number against the source.
"""

from __future__ import annotations

__all__ = ["THESIS_TABLE_4_CM", "THESIS_TABLE_5_M", "SEED004_Z_STEPS_DEG"]

THESIS_TABLE_4_CM: tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...] = (
    ((0, 0, -31.6), (-0.04455, -0.04455, -0.03874)),
    ((5, -3.5, -34), (4.5, -0.4286, 5.08)),
    ((-2, 0.4, -61), (28.55, 30.55, 29.2)),
    ((0, -2, -63), (30.85, 30.85, 32.6)),
    ((-11, -2, -51.5), (16, 27.7, 23.16)),
    ((0, -5, -64), (31.33, 31.33, 35.82)),
)
"""Thesis Table 4: platform position (cm) -> carriage travels L1, L2, L3 (cm)."""

THESIS_TABLE_5_M: dict[str, tuple[float, float, float]] = {
    "pd": (1.1061e-05, 0.0022, 0.0111),
    "pid": (6.6435e-06, 0.0015, 0.0111),
    "ctc": (4.6210e-06, 0.0014, 0.0105),
}
"""Thesis Table 5: RMSE of x, y, z on the helix, m (MATLAB controller, ADAMS prototype)."""

SEED004_Z_STEPS_DEG: dict[float, float] = {-0.561: 38.0, -0.311: -40.0}
"""Seed 004 (Fig. 24, Table 8): platform height (m) -> arm angle of all three legs, deg."""
