"""``python -m cosim layout SCENARIO``: a Foxglove layout made with foxglove-sdk's ``foxglove.layouts`` whose panels
name topics, fields and frames that a run of the scenario logs (and serves with --live)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from cosim.cli import main
from cosim.observers.layout import message_path, parse_message_path

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "scenarios" / "helix_ctc_analytic.yaml"
pytestmark = pytest.mark.integration


def _panels(node: dict):
    """Every panel of a layout's content tree."""
    if node.get("type") == "panel":
        yield node
    for item in node.get("items", []):
        yield from _panels(item["content"])


def _logged(path: Path) -> tuple[dict[str, set[str]], set[str]]:
    """({topic: its schema's properties}, the frame ids of its /tf messages) of a run's log."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        topics = {c.topic: set(json.loads(summary.schemas[c.schema_id].data).get("properties", {}))
                  for c in summary.channels.values()}
        frames = {t[k] for _, _, m in reader.iter_messages(topics=["/tf"])
                  for t in json.loads(m.data)["transforms"] for k in ("parent_frame_id", "child_frame_id")}
    return topics, frames


def test_the_layout_names_what_the_log_holds(tmp_path, capsys):
    out, log = tmp_path / "helix.layout.json", tmp_path / "helix.mcap"
    assert main(["layout", str(SCENARIO), "--out", str(out)]) == 0
    assert capsys.readouterr().out.strip() == f"wrote {out} (Foxglove layout)"
    assert main(["run", str(SCENARIO), "--stop-time", "0.1", "--out", str(log), "--quiet"]) == 0
    topics, frames = _logged(log)
    layout = json.loads(out.read_text())
    assert layout["version"] == 1
    panels = list(_panels(layout["content"]))
    scene = [p for p in panels if p["panelType"] == "ThreeDee"]
    plots = {p["title"]: p for p in panels if p["panelType"] == "Plot"}
    assert len(scene) == 1 and set(plots) == {"joint positions", "joint torques and forces"}, panels
    config = scene[0]["config"]
    assert set(config["topics"]) == {"/scene", "/scene/reference"} <= set(topics), config["topics"]
    assert set(config["transforms"]) <= frames and config["followTf"] in frames, (config, frames)
    drawn = {}
    for title, plot in plots.items():
        for series in plot["config"]["paths"]:
            topic, field = parse_message_path(series["value"])
            assert field in topics.get(topic, ()), f"{title}: {series['value']} is not in the log"
            drawn.setdefault(title, []).append(series["value"])
    assert drawn["joint positions"] == [p for i in (1, 2, 3) for p in (f'/plant."q[{i}]"', f'/ctl."q_ref[{i}]"')]
    assert drawn["joint torques and forces"] == [f'/ctl."u[{i}]"' for i in (1, 2, 3)]


def test_the_file_is_what_foxglove_layouts_serialises(tmp_path):
    import foxglove.layouts as fl

    from cosim.engine import plugins
    from cosim.engine.prepare import prepare
    from cosim.engine.scenario import load_scenario
    from cosim.observers.layout import channels_of, layout

    out = tmp_path / "x.json"
    assert main(["layout", str(SCENARIO), "--out", str(out)]) == 0
    scenario = load_scenario(SCENARIO)
    system = scenario.structure()
    made = layout(channels_of(prepare(system)[0]), plugins.scene(system) is not None, scenario.name)
    assert isinstance(made, fl.Layout)
    assert out.read_text(encoding="utf-8") == made.to_json()
    assert [p.name for p in tmp_path.iterdir()] == ["x.json"]  # nothing left beside it


def test_field_names_are_quoted_as_the_message_path_grammar_wants():
    assert message_path("/plant", "q[1]") == '/plant."q[1]"'
    assert message_path("/plant", "p.x") == '/plant."p.x"'
    assert message_path("/ctl", "t") == "/ctl.t"
    assert message_path("/a b", 'say "hi" \\ there') == '"/a b"."say \\"hi\\" \\\\ there"'
    for topic, field in (("/plant", "q[1]"), ("/a b", 'say "hi" \\ there'), ("/scene/reference", "p.x")):
        assert parse_message_path(message_path(topic, field)) == (topic, field)


def test_bad_input_is_one_line(tmp_path, capsys):
    assert main(["layout", str(tmp_path / "missing.yaml")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and "missing.yaml" in err and "\n" not in err, err
    assert main(["layout", str(SCENARIO), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and "is a directory" in err and "\n" not in err, err
    assert list(tmp_path.iterdir()) == []


def test_a_scenario_with_nothing_to_show_is_one_line_and_no_file(tmp_path, capsys):
    import yaml

    from cfmus import build

    scenario = tmp_path / "vdp.yaml"
    scenario.write_text(yaml.safe_dump({"name": "vdp", "components": {"m": {"path": str(build("VanDerPol", 2))}},
                                        "time": {"stop": 1.0, "step": 0.001}}))
    out = tmp_path / "vdp.layout.json"
    assert main(["layout", str(scenario), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "error: layout: vdp has no 3D scene (logging.scene) and no joint signals (q, q_ref, u) to show", err
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["vdp.yaml"]
