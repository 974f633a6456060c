"""Scenario validation messages and Gauss-Seidel ordering (pure, no FMUs)."""

import pytest

from cosim.errors import AlgebraicLoopError, ScenarioError
from cosim.engine.scenario import parse_scenario
from cosim.engine.schema import scenario_json_schema
from cosim.engine.system import gauss_seidel_order

GOOD = """name: t
components:
  a: {path: a.fmu}
  b: {path: b.fmu, parameters: {gain.kp: [1, 2, 3]}}
connections:
  - {from: a.y, to: b.u}
time: {stop: 1.0, step: 0.001}
"""


def test_valid_scenario_integer_time():
    s = parse_scenario(GOOD, "x.yaml")
    assert (s.time.step_ns, s.time.stop_ns) == (1_000_000, 1_000_000_000), (s.time.step_ns, s.time.stop_ns)


def test_all_errors_at_once_with_file_line_and_path():
    text = GOOD.replace("b: {path: b.fmu,", "b: {path: b.fmu, bogus: 1,").replace("to: b.u", "to: bb.u") \
        .replace("stop: 1.0", "stop: 1.0005")
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(text, "x.yaml")
    msg = str(exc.value)
    assert "x.yaml:4: components.b.bogus: unknown key" in msg, msg
    assert "x.yaml:7: time: stop - start = 1.0005 s is not a whole number of steps" in msg, msg


def test_unknown_component_suggests_close_name():
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(GOOD.replace("to: b.u", "to: bb.u"), "x.yaml")
    assert "x.yaml:6: connections[0].to: unknown component 'bb'; did you mean b?" in str(exc.value), str(exc.value)


def test_both_or_neither_source_rejected():
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(GOOD.replace("a: {path: a.fmu}", "a: {path: a.fmu, fmu: x}"), "x.yaml")
    assert "x.yaml:3: components.a: give exactly one of 'fmu'" in str(exc.value), str(exc.value)


def test_schema_is_titled_and_closed():
    schema = scenario_json_schema()
    assert schema["title"] == "cosim scenario", schema.get("title")
    assert schema["additionalProperties"] is False, schema.get("additionalProperties")


def test_order_puts_non_feedthrough_first_in_a_loop():
    # 0 = controller (feedthrough), 1 = plant (none): plant -> ctl is hard, ctl -> plant soft
    assert gauss_seidel_order(2, [(1, 0, True), (0, 1, False)]) == [1, 0]
    assert gauss_seidel_order(3, [(2, 1, True), (1, 0, True)]) == [2, 1, 0]
    with pytest.raises(AlgebraicLoopError):
        gauss_seidel_order(2, [(0, 1, True), (1, 0, True)])


def test_a_yaml_alias_bomb_is_refused_at_once():
    """Nine levels of nine aliases (a 1 kB file, 387 million values expanded) fail in one line (issue 25); before,
    the loader expanded them (8 GB, over 90 s)."""
    from cosim.errors import ScenarioError
    from cosim.engine.scenario import parse_scenario

    levels = ["a0: &a0 [x, x, x, x, x, x, x, x, x]"]
    levels += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 10)]
    text = "\n".join(levels) + "\ncomponents: {}\ntime: {stop: 1, step: 0.1}\n"
    with pytest.raises(ScenarioError, match="expands to more than"):
        parse_scenario(text, "bomb.yaml")


def test_a_set_value_alias_bomb_is_refused_as_a_file_is():
    """Every YAML the platform reads goes through one loader with the same bound: a --set value too."""
    from cosim.errors import ScenarioError
    from cosim.engine.overrides import parse_set_value

    levels = "[&a0 [1, 1, 1, 1, 1, 1, 1, 1, 1]" + "".join(
        f", &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 9)) + "]"
    with pytest.raises(ScenarioError, match="expands to more than"):
        parse_set_value(levels, "--set x")


def test_an_unknown_trajectory_type_is_named_with_its_close_match_and_line():
    """The trajectory types come from the domain plugged in (the delta robot's); a wrong one is repeated, with the
    closest valid one, at its line."""
    text = GOOD + "robot: linear_delta_thesis\ntrajectory: {type: helx}\n"
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(text, "x.yaml")
    assert "x.yaml:9: trajectory.type: unknown trajectory type 'helx'; did you mean helix? valid: helix," \
        in str(exc.value), str(exc.value)


def test_a_set_value_is_one_line_and_a_long_one_is_not_echoed_whole():
    """A control character in a --set value: one line (YAML's own text runs over two); a 20 kB value: its start
    and its length, not 20 kB in one error line."""
    from cosim.engine.overrides import SHOWN_CHARS, apply_overrides

    with pytest.raises(ScenarioError) as exc:
        apply_overrides(["ctl.gain.kp[1]=1\x01"])
    assert len(str(exc.value).splitlines()) == 1 and "unacceptable character #x0001" in str(exc.value), exc.value
    with pytest.raises(ScenarioError) as exc:
        apply_overrides(["x." + "k" * 20_000])
    text = str(exc.value)
    assert len(text) < SHOWN_CHARS + 300 and "(20002 characters)" in text, text[:400]


def test_an_integer_too_long_for_python_is_refused_where_it_is_written(tmp_path):
    """Python converts integers of at most 4300 digits from text; a longer one in a --set value or a file raised a
    ValueError inside PyYAML (an internal error): it is refused at its line, its length said, not echoed whole."""
    import sys

    from cosim.engine.overrides import SHOWN_CHARS, apply_overrides
    from cosim.engine.scenario import load_scenario

    digits = sys.get_int_max_str_digits() + 1
    with pytest.raises(ScenarioError) as exc:
        apply_overrides([f"ctl.gain.kp[1]={'9' * digits}"])
    text = str(exc.value)
    assert f"an integer of {digits:,} digits" in text and len(text) < SHOWN_CHARS + 300, text[:400]
    path = tmp_path / "s.yaml"
    path.write_text(f"name: x\nwatchdog_s: {'9' * digits}\ncomponents: {{}}\ntime: {{stop: 1, step: 0.1}}\n")
    with pytest.raises(ScenarioError) as exc:
        load_scenario(path)
    assert f"s.yaml:2: invalid YAML: an integer of {digits:,} digits" in str(exc.value), str(exc.value)[:400]


def test_a_key_given_twice_is_refused_at_its_second_line():
    """PyYAML keeps the last of two equal keys silently: a scenario, a --set value and a model file refuse it."""
    from cosim.engine.bounded_yaml import load_yaml
    from cosim.engine.overrides import parse_set_value

    with pytest.raises(ScenarioError, match=r"x.yaml:8: invalid YAML: duplicate key 'time' \(first given at line 7\)"):
        parse_scenario(GOOD + "time: {stop: 2.0, step: 0.001}\n", "x.yaml")
    with pytest.raises(ScenarioError, match="duplicate key 'a'"):
        parse_set_value("{a: 1, a: 2}", "--set x")
    assert load_yaml("base: &b {a: 1}\nother: {<<: *b, c: 2}\n")[0] == {"base": {"a": 1}, "other": {"a": 1, "c": 2}}
