"""`python -m cosim robot ...` end to end, in a subprocess like a user runs it."""

import json

import pytest
from cli_helpers import cosim


def test_ik_json_reproduces_thesis_table_4_row_6():
    out = cosim("robot", "ik", "--robot", "linear_delta_thesis", "0", "-0.05", "-0.64", "--json")
    assert out.returncode == 0, out.stderr
    q_cm = [round(x * 100, 2) for x in json.loads(out.stdout)["q"]]
    assert q_cm == [31.33, 31.33, 35.82], q_cm


def test_unreachable_point_one_line_reason_exit_2():
    out = cosim("robot", "ik", "--robot", "linear_delta_thesis", "0.5", "0", "-0.6")
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "leg 1 has no solution" in lines[0], out.stderr


def test_unknown_preset_lists_valid_names():
    out = cosim("robot", "fk", "--robot", "nope", "0", "0", "0")
    assert out.returncode == 2 and "valid presets: linear_delta_thesis" in out.stderr, out.stderr


@pytest.mark.parametrize("args, expect", [
    (("robot", "ik", "--robot", "rotary_delta_prototype", "0", "0", "-561", "--mm"), "38.1694"),
    (("robot", "fk", "--robot", "rotary_delta_prototype", "0", "0", "0", "--deg"), "-0.410822"),
    (("robot", "workspace", "--robot", "rotary_delta_prototype", "--cylinder", "nan", "150", "250", "--mm",
      "--surface", "--no-limits"), "largest z_below = 0.203"),
    (("robot", "singularity", "--robot", "rotary_delta_3rrr", "--p", "0", "0", "-0.23473389188611"), "type 1"),
])
def test_commands_print_expected_figures(args, expect):
    out = cosim(*args)
    assert out.returncode == 0, out.stderr
    assert expect in out.stdout, out.stdout
