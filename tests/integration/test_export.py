"""``python -m cosim export RUN.mcap --csv DIR --parquet FILE``: the CSV files' headers and units, their numbers
and the Parquet table's read back exactly, and an output written whole or not at all."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from cli_helpers import cosim  # noqa: E402

from cosim.errors import CosimError  # noqa: E402
from cosim.io.recordings import read_recording  # noqa: E402
from cosim.io.recordings.export import export_csv, export_parquet  # noqa: E402
from cosim.io.runlog import read_run  # noqa: E402

pytestmark = pytest.mark.integration

RUN = Path(__file__).resolve().parents[1] / "golden" / "helix_ctc.mcap"


@pytest.fixture(scope="module")
def log():
    return read_run(RUN)


def test_the_command_writes_one_csv_per_component_and_a_parquet_table(tmp_path, log):
    res = cosim("export", RUN, "--csv", tmp_path / "csv", "--parquet", tmp_path / "run.parquet", "--json")
    assert res.returncode == 0, res.stderr
    written = json.loads(res.stdout)["written"]
    assert sorted(Path(w).name for w in written) == sorted([f"{c}.csv" for c in log.components] + ["run.parquet"])
    assert sorted(p.name for p in tmp_path.rglob("*")) == sorted(["csv", "run.parquet",
                                                                 *(f"{c}.csv" for c in log.components)]), \
        "nothing else (no temporary file) is left"


def test_csv_headers_carry_the_units_and_the_numbers_read_back_exactly(tmp_path, log):
    export_csv(log, tmp_path)
    header = (tmp_path / "plant.csv").read_text().splitlines()[0].split(",")
    assert header[0] == "Time [s]", header
    for variable in ("q[1]", "u[1]", "p.x"):
        sig = log.signal(f"plant.{variable}")
        assert f"{variable} [{sig.unit}]" in header, (variable, sig.unit, header)
        rec = read_recording(tmp_path / "plant.csv", {"v": variable}, time_origin="absolute")
        assert rec.units["v"] == sig.unit
        assert np.array_equal(rec.values["v"], sig.y), f"{variable}: 17 digits read back to the same double"
        # the time column is t_ns * 1e-9 written with 17 digits: back to within a rounding of the stamp
        np.testing.assert_allclose(rec.times["v"], sig.t, rtol=0, atol=1e-15 * max(1.0, sig.t[-1]))


def test_parquet_round_trip(tmp_path, log):
    import pyarrow.parquet as pq

    table = pq.read_table(export_parquet(log, tmp_path / "run.parquet"))
    t_ns = table.column("time_ns").to_numpy()
    numeric = [n for n, s in log.signals.items() if s.y.dtype.kind in "fiub" and s.y.ndim == 1]
    assert numeric and set(numeric) <= set(table.column_names), set(numeric) - set(table.column_names)
    for name in numeric:
        sig = log.signals[name]
        col = table.column(name)
        at = np.searchsorted(t_ns, sig.t_ns)
        assert np.array_equal(t_ns[at], sig.t_ns), name
        assert np.array_equal(col.to_numpy(zero_copy_only=False)[at], sig.y.astype(float)), name
        field = table.schema.field(name)
        assert field.metadata[b"unit"].decode() == sig.unit, name
    assert table.schema.metadata[b"log"].decode() == str(log.path)


def test_a_failed_write_leaves_neither_a_half_file_nor_a_temporary(tmp_path, log, monkeypatch):
    import pyarrow.parquet as pq

    def half(table, where, **kw):
        Path(where).write_bytes(b"PAR1 half")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(pq, "write_table", half)
    with pytest.raises(CosimError, match=r"--parquet: cannot write .*run.parquet: No space left on device"):
        export_parquet(log, tmp_path / "run.parquet")
    assert list(tmp_path.iterdir()) == [], list(tmp_path.iterdir())


def test_bad_outputs_are_one_line(tmp_path, log):
    (tmp_path / "file").write_text("x")
    with pytest.raises(CosimError, match="is a file, not a folder"):
        export_csv(log, tmp_path / "file")
    with pytest.raises(CosimError, match="no folder"):
        export_parquet(log, tmp_path / "missing" / "run.parquet")
    res = cosim("export", RUN)
    assert res.returncode == 2 and res.stderr.strip() == "error: export: give --csv DIR and/or --parquet FILE", \
        res.stderr
