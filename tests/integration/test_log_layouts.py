"""The log's two layouts (``logging.layout``): ``samples`` (the default) writes one message per sample
per component channel, as logs did before blocks (tests/golden: the same schemas, the same message
shape, each message valid against its channel's schema); ``blocks`` writes one message per block of
samples; both read back to the same signals, bit for bit, whether the run writes in its own process
or through the writer process (runs of 2000 steps or more)."""

from __future__ import annotations

from pathlib import Path

import jsonschema
import numpy as np
import orjson
import pytest
from mcap.reader import make_reader

from cosim.cli import main
from cosim.observers.mcap_log import McapRecorder
from cosim.run import run_scenario
from cosim.io.runlog import read_run, time_offset_ns
from cosim.engine.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[2]
GOLDEN = ROOT / "tests" / "golden"
COMPONENTS = ("/traj", "/ik", "/ctl", "/plant")
pytestmark = pytest.mark.integration


def _channels(path: Path) -> tuple[dict, dict[str, list], int]:
    """(topic -> (schema name, schema bytes, metadata), topic -> [(log time, message)], time offset) of a log."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        channels = {c.topic: (summary.schemas[c.schema_id].name, summary.schemas[c.schema_id].data, dict(c.metadata))
                    for c in summary.channels.values()}
        messages: dict[str, list] = {}
        for _, ch, m in reader.iter_messages(topics=list(COMPONENTS)):
            messages.setdefault(ch.topic, []).append((m.log_time, orjson.loads(m.data)))
        offset = time_offset_ns({m.name: dict(m.metadata) for m in reader.iter_metadata()})
    return channels, messages, offset


def test_default_layout_logs_one_message_per_sample_as_the_golden_logs(tmp_path):
    """helix_ctc (the golden baseline's scenario): the same schemas, byte for byte, and messages of the
    same keys, one per sample at its stamp, each valid against its schema."""
    out = tmp_path / "helix_ctc.mcap"
    scenario = load_scenario(ROOT / "scenarios" / "helix_ctc.yaml", {("time", "stop"): 0.05, ("fmus",): "native"})
    assert scenario.logging.layout == "samples", scenario.logging.layout
    run_scenario(scenario, out=out, log=True)
    golden, golden_messages, _ = _channels(GOLDEN / "helix_ctc.mcap")
    channels, messages, offset = _channels(out)
    for topic in COMPONENTS:
        (name, schema, metadata), (g_name, g_schema, g_metadata) = channels[topic], golden[topic]
        assert (name, schema) == (g_name, g_schema), f"{topic}: schema {name} {schema[:200]!r} vs golden's " \
                                                     f"{g_name} {g_schema[:200]!r}"
        assert metadata == {**g_metadata, "layout": "samples"}, f"{topic}: {metadata} vs golden's {g_metadata}"
        validator = jsonschema.validators.validator_for(orjson.loads(schema))(orjson.loads(schema))
        assert len(messages[topic]) == 51, f"{topic}: {len(messages[topic])} messages for 51 samples (0..50 ms)"
        for log_time, msg in messages[topic]:
            errors = list(validator.iter_errors(msg))
            assert not errors, f"{topic} at {log_time} ns: {errors[0].message}"
            assert list(msg) == list(golden_messages[topic][0][1]), f"{topic}: keys {list(msg)} vs golden's"
            assert log_time - offset == round(msg["t"] * 1e9), f"{topic}: log time {log_time} for t = {msg['t']}"
        stamps = [round(m["t"] * 1e9) for _, m in messages[topic]]
        assert stamps == [k * 1_000_000 for k in range(51)], f"{topic}: stamps {stamps[:5]}..."


@pytest.mark.parametrize("stop,writer", [(0.5, "in-process"), (0.5, "forked"), (2.5, "new interpreter")],
                         ids=["in-process", "forked-writer", "exec-writer"])
def test_both_layouts_read_back_to_identical_signals(tmp_path, stop, writer, monkeypatch):
    """helix_ctc_analytic on native FMUs in both layouts (``blocks`` set as on the command line), written in
    the master, by a forked writer and by a new interpreter: the same signals, stamps and values exactly;
    ``blocks`` holds blocks, valid against its schema."""
    from cosim.observers import log_writer
    from cosim.observers.log_writer import process

    steps = round(stop / 0.001)
    if writer == "forked" and not log_writer.writer_forks():
        pytest.skip("the writer cannot be forked here")
    if writer != "forked":  # the other two paths: no fork, then the run's length decides
        monkeypatch.setattr(process._Fork, "possible", classmethod(lambda cls: False))
    assert McapRecorder.writes_in_a_process(steps) == (writer != "in-process"), "each case takes its path"
    scenario = str(ROOT / "scenarios" / "helix_ctc_analytic.yaml")
    logs = {}
    for layout in ("samples", "blocks"):
        logs[layout] = tmp_path / f"{layout}.mcap"
        args = ["run", scenario, "--stop-time", str(stop), "--set", "fmus=native", "--out", str(logs[layout]),
                "--quiet"] + (["--set", "logging.layout=blocks"] if layout == "blocks" else [])
        assert main(args) == 0, f"the {layout} run failed"
    samples, blocks = read_run(logs["samples"]), read_run(logs["blocks"])
    assert list(samples.signals) == list(blocks.signals) and len(samples.signals) > 60, list(samples.signals)
    for name, a in samples.signals.items():
        b = blocks.signals[name]
        assert np.array_equal(a.t_ns, b.t_ns), f"{name}: stamps {a.t_ns[:3]}... vs {b.t_ns[:3]}..."
        assert len(a.t_ns) == steps + 1, f"{name}: {len(a.t_ns)} samples for {steps} steps"
        assert np.array_equal(a.y, b.y, equal_nan=True), f"{name}: values differ, max |A - B| = " \
                                                         f"{np.nanmax(np.abs(a.y - b.y))}"
        assert (a.unit, a.description, a.causality) == (b.unit, b.description, b.causality), name
    channels, messages, _ = _channels(logs["blocks"])
    for topic in COMPONENTS:
        assert channels[topic][2]["layout"] == "blocks", channels[topic][2]
        schema = orjson.loads(channels[topic][1])
        validator = jsonschema.validators.validator_for(schema)(schema)
        assert len(messages[topic]) < steps // 10, f"{topic}: {len(messages[topic])} block messages for {steps} steps"
        for log_time, msg in messages[topic]:
            assert isinstance(msg["t"], list) and not list(validator.iter_errors(msg)), (topic, log_time)
    assert {c[2]["layout"] for t, c in _channels(logs["samples"])[0].items() if t in COMPONENTS} == {"samples"}
