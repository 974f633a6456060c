"""Connections by prefix and by component (cosim.engine.wiring): same wiring as element by element,
mismatches as file:line errors."""

from pathlib import Path

import pytest

from cosim.errors import CosimError
from cosim.engine.prepare import prepare
from cosim.engine.scenario import load_scenario

pytestmark = pytest.mark.integration
ROOT = Path(__file__).parents[2]


def _links(path) -> set[tuple[str, str]]:
    plan, _ = prepare(load_scenario(path).structure())
    return {(lk.src.label(plan.names), lk.dst.label(plan.names)) for lk in plan.links}


def test_prefixes_wire_what_element_lines_wired(tmp_path):
    text = (ROOT / "scenarios" / "helix_ctc_analytic.yaml").read_text()
    head, rest = text.split("connections:", 1)
    tail = rest[rest.index("time:"):]
    lines = [f'  - {{from: "{s}{suf}", to: "{d}{suf}"}}'
             for s, d, sufs in (("traj.p_ref", "ik.p_ref", ".x .y .z"), ("traj.v_ref", "ik.v_ref", ".x .y .z"),
                                ("traj.a_ref", "ik.a_ref", ".x .y .z"), ("ik.q_ref", "ctl.q_ref", "[1] [2] [3]"),
                                ("ik.qd_ref", "ctl.qd_ref", "[1] [2] [3]"), ("ik.qdd_ref", "ctl.qdd_ref", "[1] [2] [3]"),
                                ("plant.q", "ctl.q", "[1] [2] [3]"), ("plant.qd", "ctl.qd", "[1] [2] [3]"),
                                ("ctl.u", "plant.u", "[1] [2] [3]"))
             for suf in sufs.split()]
    (tmp_path / "a.yaml").write_text(head + "connections:\n" + "\n".join(lines) + "\n" + tail)
    (tmp_path / "a.yaml").write_text((tmp_path / "a.yaml").read_text().replace("../runs/", str(tmp_path) + "/"))
    elementwise = _links(tmp_path / "a.yaml")
    assert len(elementwise) == 27, len(elementwise)
    assert _links(ROOT / "scenarios" / "helix_ctc_analytic.yaml") == elementwise
    assert _links(ROOT / "scenarios" / "helix_ctc.yaml") == elementwise
    n = sum(line.lstrip().startswith("- {from:") for line in (ROOT / "scenarios" / "helix_ctc.yaml").read_text().splitlines())
    assert n <= 8, f"helix_ctc.yaml has {n} connection lines"


@pytest.mark.parametrize("line, expected", [
    ("{from: traj.p_ref, to: ctl.qd}", "connections[3]: prefix connection: traj.p_ref has 3 output(s) (.x .y .z), "
                                       "ctl.qd has 3 input(s) ([1] [2] [3])"),
    ("{from: traj, to: plant}", "connections[3]: traj has no output named like an input of plant"),
    ("{from: traj, to: ctl.qd}", "connections[3]: give both ends as components"),
])
def test_mismatches_are_file_line_errors(tmp_path, line, expected):
    # helix_ctc_thesis: helix_ctc's wiring without its identified model file (not copied to tmp_path)
    original = (ROOT / "scenarios" / "helix_ctc_thesis.yaml").read_text()
    at = 1 + [n for n, text in enumerate(original.splitlines()) if "{from: plant.qd, to: ctl.qd}" in text][0]
    (tmp_path / "s.yaml").write_text(original.replace("{from: plant.qd, to: ctl.qd}", line))
    with pytest.raises(CosimError) as exc:
        prepare(load_scenario(tmp_path / "s.yaml").structure())
    assert at == 23 and f"s.yaml:{at}: {expected}" in str(exc.value), (at, str(exc.value))


@pytest.mark.parametrize("first, second", [
    ("{from: traj.p_ref, to: ik.p_ref}", "{from: traj.p_ref.y, to: ik.p_ref.x}"),
    ("{from: traj.p_ref.y, to: ik.p_ref.x}", "{from: traj.p_ref, to: ik.p_ref}"),
])
def test_an_input_driven_by_a_prefix_and_an_element_line_is_an_error(tmp_path, first, second):
    """Whichever comes first, an element input gets one driver; the second connection is the error."""
    text = (ROOT / "scenarios" / "helix_ctc_analytic.yaml").read_text()
    assert "{from: traj.p_ref, to: ik.p_ref}" in text
    text = text.replace("  - {from: traj.p_ref, to: ik.p_ref}", f"  - {first}\n  - {second}")
    (tmp_path / "s.yaml").write_text(text)
    with pytest.raises(CosimError) as exc:
        prepare(load_scenario(tmp_path / "s.yaml").structure())
    assert "input ik.p_ref.x is already driven by connections[" in str(exc.value), str(exc.value)


@pytest.mark.parametrize("line, flagged", [
    ("{from: traj.p_ref, to: ik.p_rf}", ["to"]),
    ("{from: traj.p_rf, to: ik.p_ref}", ["from"]),
    ("{from: traj.p_rf, to: ik.p_rf}", ["from", "to"]),
])
def test_a_typo_in_one_end_of_a_prefix_connection_flags_that_end_only(tmp_path, line, flagged):
    """A misspelt end is reported with the prefix it meant offered first; the other end, a good prefix, is not
    reported (it was: a typo in ``to`` also flagged the correct ``from``)."""
    text = (ROOT / "scenarios" / "helix_ctc_analytic.yaml").read_text()
    text = text.replace("{from: traj.p_ref, to: ik.p_ref}", line).replace("model: ", f"model: {ROOT}/scenarios/")
    (tmp_path / "s.yaml").write_text(text)
    with pytest.raises(CosimError) as exc:
        prepare(load_scenario(tmp_path / "s.yaml").structure())
    issues = exc.value.issues
    assert [i.path.rsplit(".", 1)[-1] for i in issues] == flagged, [str(i) for i in issues]
    assert all("has no variable 'p_rf'; did you mean p_ref," in i.message for i in issues), [str(i) for i in issues]
