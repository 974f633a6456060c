"""The python FMUs' state format and the adapters' state hooks, without building an FMU (fmus._names.StateAccess).

The serialized layout keeps every value exactly (floats through ``repr``, non-finite ones named), refuses bytes that
are not one of its states saying why, and is never pickle. Every adapter but the Exudyn plant (an integration test:
tests/integration/test_fmu_state_python.py) is made in Python, stepped, and its state set into a second instance,
which then steps exactly as the first: no tolerance anywhere.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fmus import registry
from fmus._names import (
    STATE_MAGIC,
    FmuStateError,
    decode_state,
    encode_state,
    fmu_guid,
    identical,
    is_plain,
)

VALUES = [0.1, -0.0, 0.0, 5e-324, 1.7976931348623157e308, -1e-300, math.pi, float("nan"), float("inf"),
          float("-inf"), 0, -7, 2**70, True, False, None, "quintic", "ünïcødé \n \"quoted\"", [], {}]


def _state(body) -> dict:  # noqa: ANN001
    return {"format": 1, "fmu": "demo", "guid": "0000-guid", "state": body}


def _same(a, b) -> bool:  # noqa: ANN001
    """Equal plain data, floats bit for bit (NaN equal to NaN)."""
    if type(a) is not type(b):
        return False
    if type(a) is float:
        return identical(a, b)
    if type(a) is list:
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if type(a) is dict:
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return a == b


def test_encoding_keeps_every_value_exactly():
    """Every plain value survives encode and decode with its type and bits; the bytes are reproducible."""
    body = {"values": {str(i): v for i, v in enumerate(VALUES)}, "nested": [VALUES, {"deep": [[1.5, float("nan")]]}]}
    data = encode_state(_state(body))
    back = decode_state(data)
    assert "refused" not in back, back
    assert _same(back["state"], body), f"{body} became {back['state']}"
    assert (back["fmu"], back["guid"], back["format"]) == ("demo", "0000-guid", 1), back
    assert encode_state(back) == data, "re-encoding the decoded state gives other bytes"
    assert data.startswith(STATE_MAGIC), data[:40]


def test_damaged_bytes_are_refused_with_their_reason():
    data = encode_state(_state({"values": {"x": 0.25}}))
    cases = {
        "empty": (b"", "not a delta-cosim FMU state"),
        "another magic": (b"PK\x03\x04" + data[4:], "not a delta-cosim FMU state"),
        "no header end": (data[:len(STATE_MAGIC) + 10], "truncated"),
        "truncated body": (data[:-1], "checksum mismatch"),
        "padded": (data + b"\n", "checksum mismatch"),
        "a digit changed": (data.replace(b"0.25", b"0.35"), "checksum mismatch"),
        "the guid changed": (data.replace(b"0000-guid", b"0001-guid"), "checksum mismatch"),
        "format 2": (data.replace(b'"format":1', b'"format":2'), "format version 2"),
        "header not JSON": (STATE_MAGIC + b"{oops\n{}", "unreadable"),
    }
    for what, (damaged, reason) in cases.items():
        got = decode_state(damaged)
        assert reason in got.get("refused", ""), f"{what}: expected {reason!r}, got {got}"


def test_a_state_that_cannot_be_written_is_refused_when_read_back():
    """encode_state never raises (pythonfmu calls it on the class): an object JSON cannot hold gives bytes that
    decode to a refusal naming it."""
    got = decode_state(encode_state(_state({"values": {"x": object()}})))
    assert "could not be serialized" in got.get("refused", ""), got


def test_plain_data_and_identical_values():
    assert is_plain({"a": [1, 2.5, None, "s", True, {"b": []}]}), "plain data refused"
    for not_plain in (np.zeros(2), np.float64(1.0), (1.0, 2.0), {1: 2.0}, object()):
        assert not is_plain(not_plain), f"{not_plain!r} taken as plain data"
    pairs = {(0.0, -0.0): False, (float("nan"), float("nan")): True, (1, 1.0): False, ("a", "a"): True,
             (0.1 + 0.2, 0.3): False}
    for (a, b), same in pairs.items():
        assert identical(a, b) is same, f"identical({a!r}, {b!r}) is {not same}, expected {same}"


@pytest.mark.parametrize("fmi,attribute", [(2, "guid"), (3, "instantiationToken")])
def test_guid_is_read_beside_the_resources_folder(tmp_path, fmi, attribute):
    """From the path the binary passes, from a file: URI (with an escaped space), else the fallback."""
    root = tmp_path / "unzipped fmu"
    (root / "resources").mkdir(parents=True)
    (root / "modelDescription.xml").write_text(
        f'<?xml version="1.0" ?>\n<fmiModelDescription fmiVersion="{fmi}.0" {attribute}="{{1234-abcd}}">\n'
        '<ModelVariables/></fmiModelDescription>\n')
    resources = root / "resources"
    uri = "file://" + str(resources).replace(" ", "%20")
    for given in (str(resources), str(resources) + "/", uri):
        assert fmu_guid(given, "fallback") == "{1234-abcd}", given
    for given in (None, "", str(tmp_path / "elsewhere" / "resources")):
        assert fmu_guid(given, "fallback") == "fallback", given


# ----------------------------------------------------------------------------- the adapters' hooks, in Python

PYTHON_ADAPTERS = [n for n in registry.available() if not n.endswith("exudyn_plant")]


def _make(name: str):  # noqa: ANN202
    return registry.get(name).python_class()(instance_name=name, resources=None, visible=False)


def _step(fmu, k: int) -> list:  # noqa: ANN001
    """One step of ``fmu`` made in Python with the inputs of step k: (CS) doStep, (ME) an explicit Euler step; every
    output after it (read through its getter, as fmi2GetReal would), and (ME) the states."""
    cs = registry.get(fmu.modelName).fmi == 2
    inputs = [v for v in fmu.vars.values() if v.causality.name == "input"]
    for i, v in enumerate(inputs):
        v.setter(float(v.start) + 1e-3 * max(1.0, abs(float(v.start))) * math.sin(0.7 * k + 1.3 * i))
    states = []
    if cs:
        assert fmu.do_step(k * 1e-3, 1e-3), [m.msg for m in fmu.log_queue]
    else:
        states = list(fmu.get_continuous_states())
        derivatives = fmu.get_continuous_state_derivatives()
        fmu.time = (k + 1) * 1e-3
        fmu.set_continuous_states([x + 1e-3 * d for x, d in zip(states, derivatives)])
    return [float(v.getter()) for v in fmu.vars.values() if v.causality.name == "output"] + states


@pytest.mark.parametrize("name", PYTHON_ADAPTERS)
def test_adapter_state_is_plain_and_continues_exactly_in_another_instance(name):
    """5 steps, the state (plain data, through its bytes), 5 steps; a second instance given that state makes the
    same 5 steps bit for bit."""
    a, b = _make(name), _make(name)
    for fmu in (a, b):
        fmu.exit_initialization_mode()
    for k in range(5):
        _step(a, k)
    state = a._get_fmu_state()
    assert is_plain(state), f"{name}: the state holds something other than plain data: {state}"
    first = [_step(a, k) for k in range(5, 10)]
    b._set_fmu_state(decode_state(encode_state(state)))
    again = [_step(b, k) for k in range(5, 10)]
    assert np.array(first, dtype=float).tobytes() == np.array(again, dtype=float).tobytes(), \
        f"{name}: {first[-1]} vs {again[-1]}"


def test_refusal_in_python_raises_and_changes_nothing():
    """Made in Python (not by an FMU's binary): a foreign or damaged state raises FmuStateError, logged, and the
    instance is as before; a fixed parameter after initialization raises too."""
    from delta.errors import ParameterError

    a = _make("linear_pid")
    a.exit_initialization_mode()
    before = dict(a.values)
    foreign = {**a._get_fmu_state(), "guid": "another-build"}
    for state, reason in ((foreign, "another-build"), (decode_state(b"junk"), "not a delta-cosim FMU state"),
                          ([1, 2], "not an FMU state")):
        with pytest.raises(FmuStateError, match=reason):
            a._set_fmu_state(state)
        assert reason in a.log_queue[-1].msg, a.log_queue[-1].msg
    assert a.values == before, "a refused state changed values"
    vr = next(v.value_reference for v in a.vars.values() if v.name == "limit.u_max")
    a.set_real([vr], [123.0])  # tunable: taken, and the law saturates at it
    ref, u = (next(v.value_reference for v in a.vars.values() if v.name == n) for n in ("q_ref[1]", "u[1]"))
    a.set_real([ref], [a.values["q[1]"] + 1.0])
    assert a.values["limit.u_max"] == 123.0 and a.get_real([u]) == [123.0], (a.values["limit.u_max"], a.get_real([u]))
    ctc = _make("linear_ctc")
    ctc.exit_initialization_mode()
    vr = next(v.value_reference for v in ctc.vars.values() if v.name == "mass.platform")
    with pytest.raises(ParameterError, match='"mass.platform" is fixed'):
        ctc.set_real([vr], [1.0])
    assert ctc.values["mass.platform"] != 1.0, "a refused fixed parameter was stored"
