"""Reading a robot's joint states from a large ROS 2 MCAP bag (issue 37): seconds, and memory that stays flat.

A ROS 2 bag (MCAP, written with ``rosbags``) is made in a temporary folder: ``sensor_msgs/msg/JointState`` of
three joints at ``--rate-hz`` (1 kHz) for ``--duration`` seconds, plus a ``/camera_noise`` topic
(``std_msgs/msg/UInt8MultiArray`` at 100 Hz) whose messages are sized so that the file reaches ``--size-gb``
(1 GB). A second bag holds the same JointState messages and nothing else. Then, alternately, ``--rounds``
times, a fresh process reads the three joints' positions from one bag or the other through
``cosim.io.recordings.read_recording`` (header stamps), and reports

- the seconds of the read (the call, from opening the bag to the arrays),
- the growth of its peak resident memory over its resident memory before the read (``ru_maxrss`` against
  ``/proc/self/statm``): the samples kept plus the reader's working memory, which must not grow with the bag.

The ratios (large bag / JointState-only bag) say what the other topic costs: time to skip its bytes, no memory.
Both bags are deleted at the end.

    python benchmarks/recording_read.py [--size-gb 1.0] [--rounds 3] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

NOISE_HZ = 100
NAMES = ("joint1", "joint2", "joint3")

_CHILD = r"""
import json, os, resource, sys, time
from cosim.io.recordings import read_recording
page = os.sysconf("SC_PAGE_SIZE")
before = int(open("/proc/self/statm").read().split()[1]) * page
t0 = time.perf_counter()
rec = read_recording(sys.argv[1], {f"q{i}": f"/joint_states.position[joint{i}]" for i in (1, 2, 3)}, time="header")
dt = time.perf_counter() - t0
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
print(json.dumps({"seconds": dt, "rss_before": before, "peak": peak, "samples": len(rec.values["q1"]),
                  "q1_last": float(rec.values["q1"][-1])}))
"""


def make_bags(folder: Path, size_gb: float, rate_hz: float, duration: float) -> tuple[Path, Path]:
    """(the large bag, the JointState-only bag), both ROS 2 MCAP folders."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.LATEST)
    T = store.types
    n_js = int(round(duration * rate_hz))
    n_noise = int(round(duration * NOISE_HZ))
    noise_bytes = max(1, int(size_gb * 1e9 / max(n_noise, 1)))
    block = np.random.default_rng(0).integers(0, 256, noise_bytes, dtype=np.uint8)
    noise = store.serialize_cdr(T["std_msgs/msg/UInt8MultiArray"](
        layout=T["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0), data=block), "std_msgs/msg/UInt8MultiArray")
    epoch = 1_700_000_000_000_000_000
    out = []
    for name, with_noise in (("large", True), ("joint_states_only", False)):
        path = folder / name
        with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
            js = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=store)
            nz = w.add_connection("/camera_noise", "std_msgs/msg/UInt8MultiArray", typestore=store) \
                if with_noise else None
            every = max(1, n_js // max(n_noise, 1))
            for k in range(n_js):
                stamp = epoch + int(round(k * 1e9 / rate_hz))
                t = k / rate_hz
                q = np.array([np.sin(t), np.cos(t), 0.1 * t])
                msg = T["sensor_msgs/msg/JointState"](
                    header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](
                        sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000), frame_id="base"),
                    name=list(NAMES), position=q, velocity=np.zeros(3), effort=np.zeros(3))
                w.write(js, stamp + 500_000, store.serialize_cdr(msg, "sensor_msgs/msg/JointState"))
                if nz is not None and k % every == 0:
                    w.write(nz, stamp + 700_000, noise)
        out.append(path)
    return out[0], out[1]


def bag_bytes(path: Path) -> int:
    return sum(f.stat().st_size for f in path.iterdir())


def read_once(path: Path) -> dict:
    res = subprocess.run([sys.executable, "-c", _CHILD, str(path)], capture_output=True, text=True, cwd=ROOT,
                         check=True)
    out = json.loads(res.stdout)
    out["growth"] = out["peak"] - out["rss_before"]
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size-gb", type=float, default=1.0, help="size of the large bag (default 1.0)")
    ap.add_argument("--rate-hz", type=float, default=1000.0, help="JointState rate (default 1000)")
    ap.add_argument("--duration", type=float, default=60.0, help="recorded seconds (default 60)")
    ap.add_argument("--rounds", type=int, default=3, help="reads of each bag, alternated (default 3)")
    ap.add_argument("--json", action="store_true", help="the figures as JSON")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="recording_read_") as tmp:
        t0 = time.perf_counter()
        large, small = make_bags(Path(tmp), args.size_gb, args.rate_hz, args.duration)
        made = time.perf_counter() - t0
        sizes = {"large": bag_bytes(large), "joint_states_only": bag_bytes(small)}
        runs: dict[str, list[dict]] = {"large": [], "joint_states_only": []}
        for _ in range(args.rounds):
            for name, path in (("large", large), ("joint_states_only", small)):
                runs[name].append(read_once(path))
    figures = {name: {"bytes": sizes[name], "samples": r[0]["samples"],
                      "seconds": [x["seconds"] for x in r], "seconds_median": statistics.median(x["seconds"] for x in r),
                      "rss_growth_bytes": [x["growth"] for x in r],
                      "rss_growth_median": statistics.median(x["growth"] for x in r)} for name, r in runs.items()}
    assert all(x["samples"] == figures["large"]["samples"] for r in runs.values() for x in r), "both bags read whole"
    L, S = figures["large"], figures["joint_states_only"]
    ratio_t = L["seconds_median"] / S["seconds_median"]
    ratio_m = L["rss_growth_median"] / max(S["rss_growth_median"], 1)
    if args.json:
        print(json.dumps({"figures": figures, "ratio_seconds": ratio_t, "ratio_rss_growth": ratio_m,
                          "bags_made_s": made}, indent=2))
        return 0
    mib = 1024 ** 2
    print(f"bags made in {made:.1f} s (deleted): JointState at {args.rate_hz:g} Hz for {args.duration:g} s, "
          f"{L['samples']} samples of 3 joints")
    for name, f in figures.items():
        print(f"{name:>18}: {f['bytes'] / 1e9:7.3f} GB  read {', '.join(f'{s:.2f}' for s in f['seconds'])} s "
              f"(median {f['seconds_median']:.2f} s, {f['bytes'] / 1e6 / f['seconds_median']:.0f} MB/s)  "
              f"peak RSS growth {', '.join(f'{g / mib:.1f}' for g in f['rss_growth_bytes'])} MiB")
    print(f"large / JointState-only: {ratio_t:.2f}x the time, {ratio_m:.2f}x the memory growth, for "
          f"{L['bytes'] / S['bytes']:.0f}x the bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
