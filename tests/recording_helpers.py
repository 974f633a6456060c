"""Recordings made in the tests: ROS 2 bags (MCAP, SQLite) and ROS 1 bags written with ``rosbags``' writers,
CSV files, and a SYNTHETIC ROS 2 bag of a delta robot made from a run of this project's plant (noise, another
rate, a time offset, joint names) as a stand-in for a real robot's recording. Nothing here is measured data."""

from __future__ import annotations

from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

EPOCH_NS = 1_700_000_000_000_000_000  # the bags' clock: a wall-clock epoch, as a recorder writes


def typestore(kind: str = "ros2"):
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC if kind == "ros1" else Stores.LATEST)


def header(store, stamp_ns: int, frame: str = "base"):
    """A std_msgs Header stamped ``stamp_ns`` (ROS 1's has a ``seq`` too)."""
    T = store.types
    stamp = T["builtin_interfaces/msg/Time"](sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
    if "seq" in T["std_msgs/msg/Header"].__dataclass_fields__:
        return T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)
    return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)


def joint_state(store, stamp_ns: int, names: Sequence[str], position, velocity=(), effort=()):
    return store.types["sensor_msgs/msg/JointState"](
        header=header(store, stamp_ns), name=list(names), position=np.asarray(position, dtype=float),
        velocity=np.asarray(velocity, dtype=float), effort=np.asarray(effort, dtype=float))


def pose_stamped(store, stamp_ns: int, xyz, frame: str = "base"):
    T = store.types
    pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=xyz[0], y=xyz[1], z=xyz[2]),
                                       orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
    return T["geometry_msgs/msg/PoseStamped"](header=header(store, stamp_ns, frame), pose=pose)


def write_bag(path: Path, kind: str, topics: dict[str, tuple[str, Iterable[tuple[int, object]]]]) -> Path:
    """Write ``topics`` (topic -> (msgtype, [(log time ns, message), ...])) as a bag: kind 'mcap' or 'sqlite'
    (ROS 2, a bag folder at ``path``) or 'ros1' (a .bag file at ``path``). Messages are written in log-time order."""
    store = typestore("ros1" if kind == "ros1" else "ros2")
    rows = sorted(((t, topic, msg) for topic, (_, msgs) in topics.items() for t, msg in msgs), key=lambda r: r[0])
    if kind == "ros1":
        from rosbags.rosbag1 import Writer as Writer1

        with Writer1(path) as w:
            conns = {topic: w.add_connection(topic, mt, typestore=store) for topic, (mt, _) in topics.items()}
            for t, topic, msg in rows:
                w.write(conns[topic], t, store.serialize_ros1(msg, topics[topic][0]))
        return path
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as w:
        conns = {topic: w.add_connection(topic, mt, typestore=store) for topic, (mt, _) in topics.items()}
        for t, topic, msg in rows:
            w.write(conns[topic], t, store.serialize_cdr(msg, topics[topic][0]))
    return path


def noise(store, n_bytes: int, seed: int):
    """A std_msgs/msg/UInt8MultiArray of ``n_bytes`` random bytes (a camera's worth of data a bag also holds)."""
    T = store.types
    data = np.random.default_rng(seed).integers(0, 256, n_bytes, dtype=np.uint8)
    return T["std_msgs/msg/UInt8MultiArray"](layout=T["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0),
                                             data=data)


def joint_states_bag(path: Path, kind: str, t_s: np.ndarray, q: np.ndarray, names=("joint1", "joint2", "joint3"),
                     latency_s: float = 0.002, noise_bytes: int = 0) -> Path:
    """A bag of /joint_states (header stamps at ``EPOCH + t_s``, received ``latency_s`` later) with positions
    ``q`` (n, 3), velocities 10*q and efforts -q, and /tcp_pose (PoseStamped, x = q[:, 0]); with ``noise_bytes``
    a /camera_noise topic of that many random bytes per sample too (a bag of several MCAP chunks)."""
    store = typestore("ros1" if kind == "ros1" else "ros2")
    js, poses, extra = [], [], []
    for k, (t, row) in enumerate(zip(t_s, q)):
        stamp = EPOCH_NS + round(t * 1e9)
        js.append((stamp + round(latency_s * 1e9), joint_state(store, stamp, names, row, 10 * row, -row)))
        poses.append((stamp + round(latency_s * 1e9), pose_stamped(store, stamp, (row[0], 0.0, -0.5))))
        if noise_bytes:
            extra.append((stamp + 1, noise(store, noise_bytes, k)))
    topics = {"/joint_states": ("sensor_msgs/msg/JointState", js),
              "/tcp_pose": ("geometry_msgs/msg/PoseStamped", poses)}
    if noise_bytes:
        topics["/camera_noise"] = ("std_msgs/msg/UInt8MultiArray", extra)
    return write_bag(path, kind, topics)


def synthetic_plant_bag(path: Path, log: str | Path, *, rate_hz: float = 250.0, offset_s: float = 0.2137,
                        noise: float = 1e-6, seed: int = 1, component: str = "plant",
                        names: Sequence[str] = ("delta_joint_1", "delta_joint_2", "delta_joint_3"),
                        kind: str = "mcap", latency_s: float = 0.0015) -> Path:
    """SYNTHETIC ROS 2 bag of a delta robot, not a measurement: ``component``'s q[1..3] from the run log ``log``
    (cubic spline through its samples) at ``rate_hz``, Gaussian noise of std ``noise`` (q's unit) added, published
    as sensor_msgs/msg/JointState under the joint ``names`` (header stamps; received ``latency_s`` later).

    The recording starts ``offset_s`` before the run (the robot at rest in its first pose until the run starts),
    so the recording's time counted from its first message minus the run's time is ``offset_s``: what
    ``compare --align`` must find. Stamps are ``EPOCH_NS`` + that time."""
    from scipy.interpolate import CubicSpline

    from cosim.io.runlog import read_run

    run = read_run(log)
    sigs = [run.signal(f"{component}.q[{i}]") for i in (1, 2, 3)]
    t_run = sigs[0].t
    tau = np.arange(0.0, t_run[-1] + offset_s, 1.0 / rate_hz)  # recording time, from its first message
    t = np.clip(tau - offset_s, t_run[0], t_run[-1])  # the run time of each sample (held before the start)
    rng = np.random.default_rng(seed)
    q = np.column_stack([CubicSpline(s.t, s.y)(t) for s in sigs]) + rng.normal(0.0, noise, (len(t), 3))
    store = typestore("ros2")
    msgs = []
    for tk, row in zip(tau, q):
        stamp = EPOCH_NS + round(tk * 1e9)
        msgs.append((stamp + round(latency_s * 1e9), joint_state(store, stamp, names, row)))
    return write_bag(path, kind, {"/joint_states": ("sensor_msgs/msg/JointState", msgs)})


def write_csv(path: Path, header: str, rows: np.ndarray, comments: Sequence[str] = ()) -> Path:
    lines = [f"# {c}" for c in comments] + [header] + [",".join(f"{v:.17g}" for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
