"""cosim.io.recordings: bags made here with rosbags' writers (ROS 2 MCAP and SQLite, ROS 1), CSV files and our
logs read back exactly, and every bad recording one line naming what was wrong."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from recording_helpers import EPOCH_NS, joint_states_bag, write_bag, typestore, joint_state, write_csv  # noqa: E402

from cosim.errors import CosimError  # noqa: E402
from cosim.io.recordings import RecordingError, read_recording, recording_kind  # noqa: E402
from cosim.io.recordings.units import convert, unit_factor  # noqa: E402

GOLDEN = Path(__file__).resolve().parents[1] / "golden" / "helix_ctc.mcap"
T = np.arange(0.0, 0.5, 0.004)  # 250 Hz, 125 samples
Q = np.column_stack([np.sin(3 * T), np.cos(2 * T), 0.1 * T])
# stamps are integer ns of a float time: a time read back differs from T by at most half a ns
STAMP_ATOL_S = 1e-9
SPECS = {"q1": "/joint_states.position[joint1]", "qd2": "/joint_states.velocity[joint2]",
         "u3": "/joint_states.effort[joint3]", "x": "/tcp_pose.pose.position.x", "q3": "/joint_states.position[2]"}


@pytest.fixture(scope="module", params=["mcap", "sqlite", "ros1"])
def bag(request, tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp(request.param)
    return joint_states_bag(d / ("robot.bag" if request.param == "ros1" else "robot"), request.param, T, Q)


def test_every_bag_format_reads_its_joint_states_and_poses_exactly(bag):
    rec = read_recording(bag, SPECS, time="header")
    assert rec.kind == ("ros1" if bag.suffix == ".bag" else "ros2")
    for name, expected in (("q1", Q[:, 0]), ("qd2", 10 * Q[:, 1]), ("u3", -Q[:, 2]), ("x", Q[:, 0]),
                           ("q3", Q[:, 2])):
        assert np.array_equal(rec.values[name], expected), f"{name}: {rec.values[name][:3]} vs {expected[:3]}"
        np.testing.assert_allclose(rec.times[name], T, rtol=0, atol=STAMP_ATOL_S, err_msg=name)
    assert rec.end_note == "" and rec.origin_s == EPOCH_NS * 1e-9


def test_log_times_and_absolute_origin_are_the_callers_choice(bag):
    rec = read_recording(bag, {"q1": SPECS["q1"]}, time="log", time_origin="absolute")
    # the helper's recorder receives each message 2 ms after its stamp
    expected = (EPOCH_NS + np.round(T * 1e9).astype(np.int64) + 2_000_000) * 1e-9
    np.testing.assert_allclose(rec.times["q1"], expected, rtol=0, atol=1e-6, err_msg="log times, absolute")
    rel = read_recording(bag, {"q1": SPECS["q1"]}, time="log")
    assert rel.times["q1"][0] == 0.0, f"first log time from the origin: {rel.times['q1'][0]}"


@pytest.mark.parametrize("kind", ["mcap", "sqlite"])
def test_a_single_ros2_file_reads_like_its_folder(tmp_path, kind):
    bag = joint_states_bag(tmp_path / "b", kind, T, Q)
    one = next(iter(sorted(bag.glob("*.mcap")) + sorted(bag.glob("*.db3"))))
    assert recording_kind(one) == "ros2"
    a = read_recording(one, {"q1": SPECS["q1"]})
    b = read_recording(bag, {"q1": SPECS["q1"]})
    assert np.array_equal(a.values["q1"], b.values["q1"]) and np.array_equal(a.times["q1"], b.times["q1"])


def test_window_units_and_sampling(bag):
    rec = read_recording(bag, {"q1": SPECS["q1"]}, units={"q1": "rad"}, window=(0.1, 0.2))
    t = rec.times["q1"]
    assert t[0] >= 0.1 - STAMP_ATOL_S and t[-1] <= 0.2 + STAMP_ATOL_S and len(t) == 26, f"window: {t[0]} .. {t[-1]}, {len(t)}"
    assert rec.units["q1"] == "rad"
    np.testing.assert_allclose(rec.converted("q1", "deg"), np.degrees(rec.values["q1"]), rtol=1e-15)
    mid = 0.5 * (t[3] + t[4])
    lin = rec.sample("q1", mid)
    assert lin == pytest.approx(0.5 * (rec.values["q1"][3] + rec.values["q1"][4]), rel=1e-12)
    assert rec.sample("q1", mid, "hold") == rec.values["q1"][3]


def test_transforms_are_selected_by_child_frame(tmp_path):
    store = typestore("ros2")
    Tt = store.types
    msgs = []
    for k in range(5):
        stamp = EPOCH_NS + k * 10_000_000
        hdr = Tt["std_msgs/msg/Header"](stamp=Tt["builtin_interfaces/msg/Time"](sec=stamp // 10**9,
                                                                                nanosec=stamp % 10**9), frame_id="base")
        tfs = [Tt["geometry_msgs/msg/TransformStamped"](
            header=hdr, child_frame_id=child,
            transform=Tt["geometry_msgs/msg/Transform"](
                translation=Tt["geometry_msgs/msg/Vector3"](x=float(k), y=0.0, z=z),
                rotation=Tt["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))
            for child, z in (("link", 1.0), ("tool0", -0.5 - k))]
        msgs.append((stamp + 1000, Tt["tf2_msgs/msg/TFMessage"](transforms=tfs)))
    bag = write_bag(tmp_path / "tf", "mcap", {"/tf": ("tf2_msgs/msg/TFMessage", msgs)})
    rec = read_recording(bag, {"z": "/tf.transforms[tool0].transform.translation.z"})
    assert np.array_equal(rec.values["z"], -0.5 - np.arange(5)), rec.values["z"]
    np.testing.assert_allclose(rec.times["z"], 0.01 * np.arange(5), atol=STAMP_ATOL_S)


def test_csv_with_comments_units_and_a_named_time_column(tmp_path):
    path = write_csv(tmp_path / "m.csv", "q1 [deg],time [ms],ctl.q[1] [rad]",
                     np.column_stack([np.degrees(Q[:, 0]), T * 1e3, Q[:, 1]]), comments=["prototype, Table 8"])
    rec = read_recording(path, {"a": "q1", "b": "ctl.q[1]"}, units={"a": "rad"})
    assert rec.kind == "csv" and rec.units == {"a": "rad", "b": "rad"}
    np.testing.assert_allclose(rec.values["a"], Q[:, 0], rtol=1e-14, err_msg="deg -> rad")
    np.testing.assert_allclose(rec.times["a"], T, rtol=0, atol=STAMP_ATOL_S, err_msg="ms -> s")


def test_our_run_log_reads_through_the_log_reader():
    rec = read_recording(GOLDEN, {"q": "plant.q[1]"})
    from cosim.io.runlog import read_run

    sig = read_run(GOLDEN).signal("plant.q[1]")
    assert rec.kind == "log" and rec.units["q"] == sig.unit
    assert np.array_equal(rec.values["q"], sig.y) and np.array_equal(rec.times["q"], sig.t - sig.t[0])


def test_units_convert_in_one_table():
    assert unit_factor("mm", "m") == 1e-3 and unit_factor("N.m", "N*m") == 1.0
    np.testing.assert_allclose(convert(np.array([180.0]), "deg", "rad"), [np.pi], rtol=1e-15)
    with pytest.raises(RecordingError, match=r"unit 'deg' does not convert to 'm' \(rad is not m\)"):
        unit_factor("deg", "m")
    with pytest.raises(RecordingError, match="unknown unit 'furlong'"):
        unit_factor("furlong", "m")


# --------------------------------------------------------------------------- bad recordings: one line each


def _one_line(exc: pytest.ExceptionInfo) -> str:
    text = str(exc.value)
    assert "\n" not in text and isinstance(exc.value, CosimError), text
    return text


@pytest.mark.parametrize("spec, said", [
    ("/joint_state.position[joint1]", r"no topic '/joint_state'; did you mean /joint_states\? \(topics: "
                                      r"/joint_states \(sensor_msgs/msg/JointState\), /tcp_pose"),
    ("/joint_states.positon[joint1]", r"no field 'positon' in sensor_msgs/msg/JointState \(fields: header, name, "
                                      r"position, velocity, effort\); did you mean position\?"),
    ("/joint_states.position[joint7]", r"no joint named 'joint7' \(names: joint1, joint2, joint3\)"),
    ("/joint_states.position", r"is an array of 3, not a number"),
    ("/joint_states.position[3]", r"index \[3\] out of range: the array has 3 element"),
    ("joint_states", r"a bag signal is /TOPIC.FIELD"),
])
def test_unknown_topic_field_or_joint(tmp_path, spec, said):
    bag = joint_states_bag(tmp_path / "b", "mcap", T[:5], Q[:5])
    with pytest.raises(RecordingError, match=said) as exc:
        read_recording(bag, {"a": spec})
    assert str(bag) in _one_line(exc) or spec == "joint_states"


def test_no_messages_in_range(tmp_path):
    bag = joint_states_bag(tmp_path / "b", "mcap", T, Q)
    with pytest.raises(RecordingError, match=r"no messages in t = 5 .. 6 s \(it has 0 .. 0.496 s\)") as exc:
        read_recording(bag, {"a": SPECS["q1"]}, window=(5.0, 6.0))
    _one_line(exc)


def test_header_stamps_out_of_order_are_named(tmp_path):
    store = typestore("ros2")
    stamps = [0, 10, 20, 15, 30]  # ms: the fourth goes back
    msgs = [(EPOCH_NS + k * 10_000_000 + 1, joint_state(store, EPOCH_NS + s * 1_000_000, ["j"], [float(k)]))
            for k, s in enumerate(stamps)]
    bag = write_bag(tmp_path / "b", "mcap", {"/js": ("sensor_msgs/msg/JointState", msgs)})
    with pytest.raises(RecordingError, match=r"time is not increasing at sample 3 \(t = 0.015 s after 0.02 s\)") as e:
        read_recording(bag, {"a": "/js.position[j]"}, time="header")
    _one_line(e)
    assert len(read_recording(bag, {"a": "/js.position[j]"}, time="log").times["a"]) == 5


def test_nan_is_named_with_its_sample_and_time(tmp_path):
    q = Q.copy()
    q[7, 0] = np.nan
    bag = joint_states_bag(tmp_path / "b", "sqlite", T, q)
    with pytest.raises(RecordingError, match=r"position\[joint1\]: nan at sample 7 \(t = 0.028 s\)") as exc:
        read_recording(bag, {"a": SPECS["q1"]})
    _one_line(exc)


def test_units_that_do_not_convert(tmp_path):
    path = write_csv(tmp_path / "m.csv", "t [s],q1 [deg]", np.column_stack([T, Q[:, 0]]))
    with pytest.raises(RecordingError, match=r"m.csv: q1: unit 'deg' does not convert to 'm'") as exc:
        read_recording(path, {"a": "q1"}, units={"a": "m"})
    _one_line(exc)


@pytest.mark.parametrize("text, said", [
    ("t [s],q2\n0,1\n1,x\n", r"m.csv:3: column 'q2': 'x' is not a number"),
    ("t [s],q2\n0,1\n1\n", r"m.csv:3: 1 cells where the header names 2 columns"),
    ("t [s],q_2\n0,1\n", r"m.csv:1: no column 'q2'; did you mean q_2\? \(columns: t, q_2\)"),
    ("# only a comment\n", r"no header line"),
    ("t [fortnight],q2\n0,1\n", r"time column 't': unknown unit 'fortnight'"),
])
def test_bad_csv(tmp_path, text, said):
    path = tmp_path / "m.csv"
    path.write_text(text)
    with pytest.raises(RecordingError, match=said) as exc:
        read_recording(path, {"a": "q2"})
    _one_line(exc)


def test_a_cut_bag_reads_what_is_readable_and_says_where_it_ends(tmp_path):
    bag = joint_states_bag(tmp_path / "b", "mcap", T, Q, noise_bytes=40_000)  # 5 MB: about 5 chunks of 1 MiB
    whole = next(bag.glob("*.mcap")).read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole[:len(whole) * 2 // 3])
    rec = read_recording(cut, {"a": SPECS["q1"]})
    n = len(rec.values["a"])
    assert 0 < n < len(T), f"{n} of {len(T)} samples read from two thirds of the file"
    assert np.array_equal(rec.values["a"], Q[:n, 0]), "the samples read are the first ones, exact"
    assert f"ends early at byte {len(cut.read_bytes()):,}" in rec.end_note and "read up to t = " in rec.end_note, \
        rec.end_note
    cut.write_bytes(whole[:30])
    with pytest.raises(RecordingError, match="nothing of it is readable") as exc:
        read_recording(cut, {"a": SPECS["q1"]})
    _one_line(exc)


@pytest.mark.parametrize("kind, name, said", [
    ("ros1", "b.bag", r"cannot read the ROS1 bag: .*`rosbag reindex` rebuilds it"),
    ("sqlite", "b", r"cannot read the ROS2 bag: .*malformed.*`sqlite3 FILE .recover`"),
])
def test_a_cut_ros1_or_sqlite_bag_is_one_line_with_the_remedy(tmp_path, kind, name, said):
    """Neither format can be streamed past a cut (ROS 1's index is at its end, SQLite's pages): one line."""
    bag = joint_states_bag(tmp_path / name, kind, T, Q, noise_bytes=20_000)
    whole = bag if kind == "ros1" else next(bag.glob("*.db3"))
    cut = tmp_path / f"cut{whole.suffix}"
    cut.write_bytes(whole.read_bytes()[:whole.stat().st_size // 2])
    with pytest.raises(RecordingError, match=said) as exc:
        read_recording(cut, {"a": SPECS["q1"]})
    _one_line(exc)


def test_a_message_that_does_not_deserialise_is_named(tmp_path):
    from rosbags.rosbag2 import StoragePlugin, Writer

    store = typestore("ros2")
    with Writer(tmp_path / "b", version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection("/js", "sensor_msgs/msg/JointState", typestore=store)
        w.write(c, EPOCH_NS, store.serialize_cdr(joint_state(store, EPOCH_NS, ["j"], [1.0]),
                                                 "sensor_msgs/msg/JointState"))
        w.write(c, EPOCH_NS + 10**7, b"\x00\x01\x00\x00garbage")
    with pytest.raises(RecordingError, match=r"/js: message 1 \(log time 1700000000.010000 s\) is no "
                                             r"sensor_msgs/msg/JointState") as exc:
        read_recording(tmp_path / "b", {"a": "/js.position[j]"})
    _one_line(exc)


def test_a_bag_folder_whose_recorder_was_killed(tmp_path):
    """No metadata.yaml (the recorder writes it last) and its MCAP file cut: read from the file, said so."""
    bag = joint_states_bag(tmp_path / "b", "mcap", T, Q, noise_bytes=40_000)
    (bag / "metadata.yaml").unlink()
    mcap = next(bag.glob("*.mcap"))
    mcap.write_bytes(mcap.read_bytes()[:3_000_000])
    assert recording_kind(bag) == "ros2"
    rec = read_recording(bag, {"a": SPECS["q1"]})
    n = len(rec.values["a"])
    assert 0 < n < len(T) and np.array_equal(rec.values["a"], Q[:n, 0]), n
    assert "metadata.yaml" in rec.end_note and "ends early at byte 3,000,000" in rec.end_note, rec.end_note


def test_not_a_recording(tmp_path):
    path = tmp_path / "x.txt"
    path.write_text("hello")
    with pytest.raises(RecordingError, match="not a recording") as exc:
        read_recording(path, {"a": "q"})
    _one_line(exc)
    with pytest.raises(RecordingError, match="x.bag: ") as exc:
        read_recording(tmp_path / "x.bag", {"a": "q"})
