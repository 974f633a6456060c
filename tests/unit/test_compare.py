"""Run logs, baselines and log comparisons (cosim.io.runlog, cosim.analysis.compare) on small synthetic MCAP logs.

The logs are written here in the recorder's format (one JSON channel per component,
``t`` plus the variables, a titled JSON Schema with units), so every expected figure
is known in closed form.
"""

from __future__ import annotations

import math

import numpy as np
import orjson
import pytest

from cosim.cli import main
from cosim.analysis.compare import compare_logs, parse_tolerances, tolerance_for
from cosim.errors import CosimError
from cosim.io.runlog import read_run, write_baseline

EXACT = 1e-15  # values go through JSON as shortest round-trip reprs: exact up to the arithmetic done here


def write_log(path, signals: dict[str, tuple[np.ndarray, np.ndarray]], scenario_yaml: str | None = None):
    """signals: 'comp.var' -> (t_ns (n,), y (n,)); every variable of a component shares its stamps."""
    from mcap.writer import Writer

    comps: dict[str, dict[str, tuple]] = {}
    for name, (t_ns, y) in signals.items():
        comp, var = name.split(".", 1)
        comps.setdefault(comp, {})[var] = (np.asarray(t_ns, dtype=np.int64), np.asarray(y, dtype=float))
    f = open(path, "wb")
    w = Writer(f)
    w.start(profile="", library="test")
    for comp, vars_ in comps.items():
        props = {"t": {"type": "number", "unit": "s"}} | {v: {"type": "number", "unit": "m"} for v in vars_}
        sid = w.register_schema(f"cosim.{comp}", "jsonschema", orjson.dumps({"title": comp, "properties": props}))
        cid = w.register_channel(f"/{comp}", "json", sid)
        t_ns = next(iter(vars_.values()))[0]
        for k, stamp in enumerate(t_ns):
            msg = {"t": float(stamp) * 1e-9} | {v: (None if math.isnan(y[k]) else float(y[k]))
                                                for v, (_, y) in vars_.items()}
            w.add_message(cid, int(stamp), orjson.dumps(msg), int(stamp))
    w.add_metadata("scenario", {"name": "synthetic", "robot": "None"})
    if scenario_yaml is not None:
        w.add_attachment(0, 0, "scenario/synthetic.yaml", "application/yaml", scenario_yaml.encode())
    w.finish()
    f.close()
    return path


def grid(n=101, step_ns=10_000_000):
    return np.arange(n, dtype=np.int64) * step_ns


def test_read_run_returns_every_signal_with_units(tmp_path):
    t = grid()
    y = np.sin(t * 1e-9)
    log = read_run(write_log(tmp_path / "a.mcap", {"plant.p.x": (t, y), "plant.p.y": (t, 2 * y),
                                                   "plant.p.z": (t, 3 * y), "ctl.u[1]": (t, -y)}))
    assert sorted(log.signals) == ["ctl.u[1]", "plant.p.x", "plant.p.y", "plant.p.z"], sorted(log.signals)
    s = log.signal("plant.p.x")
    assert np.array_equal(s.t_ns, t) and s.unit == "m", (s.t_ns[:3], s.unit)
    assert np.max(np.abs(s.y - y)) <= EXACT, np.max(np.abs(s.y - y))
    tt, P = log.vector("plant.p")
    assert P.shape == (101, 3) and np.max(np.abs(P[:, 2] - 3 * y)) <= 4 * EXACT, P.shape
    with pytest.raises(CosimError, match=r"no signal 'plant\.p\.w'.*did you mean plant\.p\."):
        log.signal("plant.p.w")


def test_identical_logs_agree_exactly(tmp_path):
    t = grid()
    sig = {"plant.p.x": (t, np.cos(t * 1e-9)), "ctl.u[1]": (t, t * 1e-9)}
    a, b = write_log(tmp_path / "a.mcap", sig), write_log(tmp_path / "b.mcap", sig)
    cmp = compare_logs(a, b, {"plant": 1e-12, "ctl.u": 1e-12})
    assert cmp.ok and all(d.max_error == 0.0 and d.rmse == 0.0 for d in cmp.diffs), cmp.text()
    assert cmp.t_start == 0.0 and cmp.t_stop == pytest.approx(1.0, abs=1e-12), (cmp.t_start, cmp.t_stop)


def test_difference_size_time_and_rmse_are_exact(tmp_path):
    t = grid()
    y = np.zeros(101)
    bump = y.copy()
    bump[37] = 2e-3  # one sample off by 2 mm at t = 0.37 s
    a = write_log(tmp_path / "a.mcap", {"plant.p.x": (t, y), "plant.p.y": (t, y)})
    b = write_log(tmp_path / "b.mcap", {"plant.p.x": (t, bump), "plant.p.y": (t, y)})
    cmp = compare_logs(a, b, {"plant.p.x": 1e-3})
    d = {x.name: x for x in cmp.diffs}["plant.p.x"]
    assert d.max_error == 2e-3 and d.t_max == pytest.approx(0.37, abs=1e-12), (d.max_error, d.t_max)
    assert d.rmse == pytest.approx(2e-3 / math.sqrt(101), rel=1e-12), d.rmse
    assert not cmp.ok and [x.name for x in cmp.failed] == ["plant.p.x"], cmp.text()
    text = cmp.text()
    assert "FAILED: plant.p.x: max |A - B| = 0.002 m at t = 0.370 s" in text, text


def test_logs_on_different_grids_are_compared_at_their_common_stamps_in_either_order(tmp_path):
    ta, tb = grid(11, 100_000_000), grid(201, 5_000_000)  # 100 ms and 5 ms over 1 s
    curve = lambda t: np.sin(7.0 * t * 1e-9)  # noqa: E731 - curved: interpolation would differ from it
    a = write_log(tmp_path / "a.mcap", {"c.x": (ta, curve(ta))})
    b = write_log(tmp_path / "b.mcap", {"c.x": (tb, curve(tb))})
    ab, ba = compare_logs(a, b, {"c.x": 1e-12}), compare_logs(b, a, {"c.x": 1e-12})
    for cmp in (ab, ba):
        assert cmp.ok and cmp.diffs[0].samples == 11 and cmp.diffs[0].max_error <= EXACT, cmp.text()
    off = tb[:-1] + 1_000_000  # shares no stamp with A: refused, not interpolated
    c = write_log(tmp_path / "c.mcap", {"c.x": (off, curve(off))})
    for x, y in ((a, c), (c, a)):
        with pytest.raises(CosimError, match="no common grid"):
            compare_logs(x, y)


def test_a_shorter_b_fails_on_coverage(tmp_path):
    t = grid()
    a = write_log(tmp_path / "a.mcap", {"c.x": (t, np.zeros(101))})
    b = write_log(tmp_path / "b.mcap", {"c.x": (t[:50], np.zeros(50))})
    for cmp in (compare_logs(a, b, {"c.x": 1.0}), compare_logs(b, a, {"c.x": 1.0})):  # either order
        assert not cmp.ok and "a run stopped early" in cmp.problems[0], cmp.problems


def test_nan_on_one_side_fails_and_on_both_sides_agrees(tmp_path):
    t = grid(5)
    y = np.array([0.0, 1.0, math.nan, 3.0, 4.0])
    a = write_log(tmp_path / "a.mcap", {"c.x": (t, y), "c.y": (t, y)})
    b = write_log(tmp_path / "b.mcap", {"c.x": (t, y), "c.y": (t, np.arange(5.0))})
    cmp = compare_logs(a, b, {"c": 1e-9})
    d = {x.name: x for x in cmp.diffs}
    assert d["c.x"].ok and d["c.x"].max_error == 0.0, d["c.x"]
    assert not d["c.y"].ok and d["c.y"].max_error == math.inf, d["c.y"]


def test_tolerance_patterns_most_specific_wins():
    tol = {"plant": 1.0, "plant.p": 2.0, "plant.p.x": 3.0, "*.u[*]": 4.0, "ctl.u": 5.0}
    assert tolerance_for("plant.p.x", tol) == 3.0
    assert tolerance_for("plant.p.y", tol) == 2.0
    assert tolerance_for("plant.q[1]", tol) == 1.0
    assert tolerance_for("ctl.u[2]", tol) == 5.0, "a prefix beats a glob"
    assert tolerance_for("plant.u[2]", tol) == 1.0, "prefix 'plant' beats the glob"
    assert tolerance_for("other.u[1]", tol) == 4.0
    assert tolerance_for("plantx.p", tol) is None, "a prefix ends at a name boundary"


def test_a_tolerance_matching_nothing_is_an_error(tmp_path):
    t = grid(3)
    a = write_log(tmp_path / "a.mcap", {"plant.p.x": (t, np.zeros(3))})
    with pytest.raises(CosimError, match=r"tolerance pattern\(s\) plant\.pp match no signal of both logs"):
        compare_logs(a, a, {"plant.pp": 1.0})


def test_parse_tolerances_rejects_bad_items():
    assert parse_tolerances(["plant.p=1e-6", "ctl.u = 0.5"]) == {"plant.p": 1e-6, "ctl.u": 0.5}
    for bad in ("plant.p", "plant.p=abc", "plant.p=-1", "=1"):
        with pytest.raises(CosimError, match="SIGNAL_PATTERN=POSITIVE_NUMBER"):
            parse_tolerances([bad])


def test_baseline_keeps_every_period_sample_exactly(tmp_path):
    t = grid(1001, 1_000_000)  # 1 ms for 1 s
    y = np.sin(7 * t * 1e-9)
    src = write_log(tmp_path / "run.mcap", {"plant.p.x": (t, y), "ctl.u[1]": (t, y * y)},
                    scenario_yaml="name: synthetic\nregression: {tolerances: {plant.p: 1.0e-9}}\n")
    out, n = write_baseline(src, tmp_path / "base.mcap", period=0.02)
    assert n == 2 * 51, n
    base = read_run(out)
    assert len(base.signal("plant.p.x").t_ns) == 51, base.signal("plant.p.x").t_ns
    assert base.metadata["baseline"]["period_s"] == "0.02", base.metadata
    cmp = compare_logs(base, src)
    assert all(d.max_error == 0.0 and d.samples == 51 for d in cmp.diffs), cmp.text()
    assert not list(tmp_path.glob(".base.mcap.*")), "a temporary file was left beside the baseline"


def test_unreadable_logs_name_the_file(tmp_path):
    with pytest.raises(CosimError, match="missing.mcap: no such file"):
        read_run(tmp_path / "missing.mcap")
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    with pytest.raises(CosimError, match=r"junk\.mcap: cannot read the MCAP log.*cosim recover"):
        read_run(junk)
    with pytest.raises(CosimError, match=r"junk\.mcap: cannot read"):
        write_baseline(junk, tmp_path / "b.mcap")
    assert not (tmp_path / "b.mcap").exists() and not list(tmp_path.glob(".b.mcap.*")), "a (partial) baseline was left"


def test_cli_exit_codes_and_default_tolerances_from_the_baseline(tmp_path, capsys):
    t = grid()
    scen = "name: synthetic\nregression: {tolerances: {plant.p: 1.0e-3}}\n"
    a = write_log(tmp_path / "a.mcap", {"plant.p.x": (t, np.zeros(101))}, scenario_yaml=scen)
    b = write_log(tmp_path / "b.mcap", {"plant.p.x": (t, np.full(101, 2e-3))}, scenario_yaml=scen)
    assert main(["compare", str(a), str(a)]) == 0
    assert main(["compare", str(a), str(b)]) == 1, "the attached scenario's tolerance applies"
    assert "FAILED: plant.p.x: max |A - B| = 0.002 m" in capsys.readouterr().out
    assert main(["compare", str(a), str(b), "--tol", "plant.p.x=0.01"]) == 0, "--tol overrides it"
    assert main(["compare", str(a), str(b), "--tol", "plant.p.x"]) == 2
    assert "--tol 'plant.p.x'" in capsys.readouterr().err
    assert main(["compare", str(a)]) == 2
    assert main(["compare", str(a), str(b), "--json", "--tol", "plant=1e-3"]) == 1
    payload = orjson.loads(capsys.readouterr().out)
    assert payload["failed"] == ["plant.p.x"] and payload["signals"][0]["max_abs"] == 2e-3, payload


def test_one_error_record_for_runs_reports_and_comparisons():
    from cosim.observers.stats import ErrorStats

    s = ErrorStats(name="plant.p.x", unit="m", rmse=1e-3, max_error=2e-3, t_max=0.37, samples=11, tolerance=1e-3)
    expected = "plant.p.x: max |A - B| = 0.002 m at t = 0.370 s, RMSE 0.001 (tolerance 0.001 m)"
    assert not s.ok and s.message() == expected, f"{s.message()!r} vs {expected!r}"
    keys = list(s.as_dict(max_error="max_abs"))
    assert keys == ["name", "actual", "reference", "unit", "rmse", "max_abs", "t_max", "samples", "tolerance", "ok"], \
        keys
    nan = ErrorStats(name="x", actual="p.x", reference="p_ref.x", rmse=math.nan, max_error=math.nan, samples=0,
                     tolerance=1.0)
    assert not nan.ok and "max |p.x - p_ref.x| = nan" in nan.message(), nan.message()
