"""Recording cost: µs per message (build + serialise + write) per topic type and over the mission's mix.

    python benchmarks/bench_bag.py              # prints JSON
    python benchmarks/bench_bag.py --quick      # fewer repetitions
    python benchmarks/bench_bag.py --no-memory  # skip the long-recording memory runs

For each topic type it times `recorder.write(handle, t, encoder.encode(t, ...))` in a loop,
including the recorder's batched flushes (the one-off close is reported apart), in both storages. The mix replays
one simulated second of the default mission's publications (rates from `MIX_RATES_HZ`) and
reports the mean per message and the cost per simulated second against the 10 ms budget of the
whole loop. As a reference within the same run it times rosbags' convenience path (build the
message object, `serialize_cdr`, `Writer.write`) for the same types, and scales the mix by how
much slower this machine runs that path than the 10 + 5 µs usually quoted for it. Memory: the
peak RSS of a child process recording the mix for 1 and for 30 simulated minutes.
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from twin.bag import Recorder  # noqa: E402
from twin.bag import encoders as enc  # noqa: E402
from twin.bag.mission_mix import MIX_RATES_HZ, MissionMix, lds01_scan_encoder  # noqa: E402

NS = 1_000_000_000


def _cases() -> dict[str, tuple[str, str, Callable[[int], bytes]]]:
    """name -> (topic, msgtype, fn(t_ns) -> bytes) with representative values."""
    wheels = ("wheel_left_joint", "wheel_right_joint")
    clock = enc.ClockEncoder()
    imu = enc.ImuEncoder("imu_link", angular_velocity_covariance=np.diag([4e-8] * 3))
    odom = enc.OdometryEncoder("odom", "base_footprint", pose_covariance=np.eye(6) * 1e-5)
    tf_odom = enc.TFEncoder([("odom", "base_footprint")])
    tf_wheels = enc.TFEncoder([("base_link", "wheel_left_link"), ("base_link", "wheel_right_link")])
    tf_map = enc.TFEncoder([("map", "odom")])
    joints = enc.JointStateEncoder(wheels)
    motors = enc.MotorStateEncoder(wheels)
    scan = lds01_scan_encoder()
    ranges = np.linspace(0.2, 3.4, 360).astype(np.float32)
    twist = enc.TwistEncoder()
    amcl = enc.PoseWithCovarianceStampedEncoder("map")
    cloud = enc.ParticleCloudEncoder("map")
    particles = np.random.default_rng(0).normal(size=(500, 3))
    weights = np.full(500, 1 / 500)
    path = enc.PathEncoder("map")
    plan = np.random.default_rng(1).normal(size=(120, 3))
    bt = enc.BehaviorTreeLogEncoder()
    log = enc.LogEncoder("twin")
    wheel_poses = ((0.0, 0.144, 0.023, 0.0, 0.1, 0.0, 0.99), (0.0, -0.144, 0.023, 0.0, 0.1, 0.0, 0.99))
    amcl_tf = ((0.01, -0.02, 0.0, 0.0, 0.0, 0.0, 1.0),)
    return {
        "/clock": ("/clock", clock.msgtype, clock.encode),
        "/imu": ("/imu", imu.msgtype, lambda t: imu.encode(t, 0.0, 0.0, 0.38, 0.92, 0.0, 0.0, 0.2, 0.0, 0.04, 9.81)),
        "/tf": ("/tf", tf_odom.msgtype, lambda t: tf_odom.encode_planar(t, 1.0, 2.0, 0.5)),
        "/tf#wheels": ("/tf", tf_wheels.msgtype, lambda t: tf_wheels.encode(t, wheel_poses)),
        "/tf#amcl": ("/tf", tf_map.msgtype, lambda t: tf_map.encode(t, amcl_tf)),
        "/odom": ("/odom", odom.msgtype, lambda t: odom.encode(t, 1.0, 2.0, 0.5, 0.2, 0.1)),
        "/ground_truth/odom": ("/ground_truth/odom", odom.msgtype, lambda t: odom.encode(t, 1.0, 2.0, 0.5, 0.2, 0.1)),
        "/joint_states": ("/joint_states", joints.msgtype, lambda t: joints.encode(t, (1.0, 1.1), (5.4, 6.6))),
        "/motor_state": (
            "/motor_state",
            motors.msgtype,
            lambda t: motors.encode(t, (4.1, 4.9), (0.31, 0.35), (0.021, 0.024), (5.4, 6.6)),
        ),
        "/scan": ("/scan", scan.msgtype, lambda t: scan.encode(t, ranges)),
        "/amcl_pose": ("/amcl_pose", amcl.msgtype, lambda t: amcl.encode(t, 1.0, 2.0, 0.5)),
        "/particle_cloud": ("/particle_cloud", cloud.msgtype, lambda t: cloud.encode(t, particles, weights)),
        "/cmd_vel": ("/cmd_vel", twist.msgtype, lambda t: twist.encode(0.2, 0.1)),
        "/plan": ("/plan", path.msgtype, lambda t: path.encode(t, plan)),
        "/behavior_tree_log": (
            "/behavior_tree_log",
            bt.msgtype,
            lambda t: bt.encode(t, [(t, "GoToPose", "IDLE", "RUNNING"), (t, "NavigateToPose", "RUNNING", "SUCCESS")]),
        ),
        "/rosout": ("/rosout", log.msgtype, lambda t: log.encode(t, 20, "reached waypoint kitchen")),
    }


def _per_type(storage: str, n: int, repeats: int, tmp: Path) -> dict[str, dict[str, float]]:
    """µs per message for each case alone (best of `repeats`): encode only, and encode + write + flushes."""
    out: dict[str, dict[str, float]] = {}
    for name, (topic, msgtype, fn) in _cases().items():
        count = max(50, n // 20) if name in {"/particle_cloud", "/plan", "/scan"} else n
        encode_s, total_s = math.inf, math.inf
        for r in range(repeats):
            t0 = time.perf_counter()
            for k in range(count):
                fn(k)
            encode_s = min(encode_s, time.perf_counter() - t0)
            bag = tmp / f"{storage}_{r}_{name.strip('/').replace('/', '_').replace('#', '_')}"
            gc.collect()
            with Recorder(bag, storage=storage) as rec:
                h = rec.add_topic(topic, msgtype)
                write = rec.write
                t0 = time.perf_counter()
                for k in range(count):
                    write(h, k, fn(k))
                rec.flush()
                total_s = min(total_s, time.perf_counter() - t0)
            shutil.rmtree(bag)
        out[name] = {
            "encode_us": round(encode_s / count * 1e6, 3),
            "encode_write_us": round(total_s / count * 1e6, 3),
            "bytes": len(fn(0)),
        }
    return out


def _mix_schedule(seconds: int) -> list[tuple[int, str]]:
    events = []
    for name, rate in MIX_RATES_HZ.items():
        period = round(NS / rate)
        events += [(k * period, name) for k in range(math.ceil(seconds * NS / period))]
    events.sort()
    return events


def _mix(storage: str, seconds: int, repeats: int, tmp: Path) -> dict[str, float]:
    """Mean µs per message over the mission's mix, replayed `seconds` simulated seconds."""
    cases = _cases()
    schedule = _mix_schedule(seconds)
    best = math.inf
    close_s = math.inf
    for r in range(repeats):
        bag = tmp / f"mix_{storage}_{r}"
        gc.collect()
        with Recorder(bag, storage=storage) as rec:
            handles = {}
            for topic, msgtype, _ in cases.values():
                if topic not in handles:
                    handles[topic] = rec.add_topic(topic, msgtype)
            plan = [(handles[cases[name][0]], t, cases[name][2]) for t, name in schedule]
            write = rec.write
            t0 = time.perf_counter()
            for h, t, fn in plan:
                write(h, t, fn(t))
            rec.flush()
            t1 = time.perf_counter()
            rec.close()
            best = min(best, t1 - t0)
            close_s = min(close_s, time.perf_counter() - t1)
        shutil.rmtree(bag)
    per_msg_us = best / len(schedule) * 1e6
    per_second = len(schedule) / seconds
    return {
        "messages_per_sim_s": round(per_second, 1),
        "us_per_message": round(per_msg_us, 3),
        "ms_per_sim_s": round(per_msg_us * per_second / 1000, 3),
        "share_of_10ms_budget": round(per_msg_us * per_second / 10_000, 3),
        "close_ms": round(close_s * 1000, 2),
    }


def _rosbags_reference(n: int, tmp: Path) -> dict[str, float]:
    """rosbags' convenience path for comparison: build the message object, serialize_cdr, Writer.write."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    Quat, Vec = T["geometry_msgs/msg/Quaternion"], T["geometry_msgs/msg/Vector3"]
    cov = np.zeros(9)

    def imu(t: int) -> bytes:
        msg = T["sensor_msgs/msg/Imu"](
            header=Header(stamp=Time(sec=t // NS, nanosec=t % NS), frame_id="imu_link"),
            orientation=Quat(x=0.0, y=0.0, z=0.38, w=0.92),
            orientation_covariance=cov,
            angular_velocity=Vec(x=0.0, y=0.0, z=0.2),
            angular_velocity_covariance=cov,
            linear_acceleration=Vec(x=0.0, y=0.04, z=9.81),
            linear_acceleration_covariance=cov,
        )
        return bytes(ts.serialize_cdr(msg, "sensor_msgs/msg/Imu"))

    def clock(t: int) -> bytes:
        msg = T["rosgraph_msgs/msg/Clock"](clock=Time(sec=t // NS, nanosec=t % NS))
        return bytes(ts.serialize_cdr(msg, "rosgraph_msgs/msg/Clock"))

    out: dict[str, float] = {}
    for name, fn, msgtype in (("imu", imu, "sensor_msgs/msg/Imu"), ("clock", clock, "rosgraph_msgs/msg/Clock")):
        t0 = time.perf_counter()
        for k in range(n):
            fn(k)
        out[f"{name}_build_serialize_us"] = round((time.perf_counter() - t0) / n * 1e6, 3)
        data = fn(0)
        bag = tmp / f"rosbags_{name}"
        with Writer(bag, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
            conn = writer.add_connection("/x", msgtype, typestore=ts)
            t0 = time.perf_counter()
            for k in range(n):
                writer.write(conn, k, data)
        out[f"{name}_write_mcap_us"] = round((time.perf_counter() - t0) / n * 1e6, 3)
        shutil.rmtree(bag)
    return out


def _rss_mib(field: str) -> float:
    """`VmRSS` (now) or `VmHWM` (peak) of this process, MiB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return round(int(line.split()[1]) / 1024, 1)
    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)


def _memory_child(seconds: float, storage: str) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "mem"
        with Recorder(bag, storage=storage) as rec:
            mix = MissionMix(rec)
            rss_setup = _rss_mib("VmRSS")
            t0 = time.perf_counter()
            n = mix.run(round(seconds * NS))
            wall = time.perf_counter() - t0
            rss_end = _rss_mib("VmRSS")
        size = sum(p.stat().st_size for p in bag.iterdir())
    print(
        json.dumps(
            {
                "messages": n,
                "bag_mib": round(size / 2**20, 1),
                "wall_s": round(wall, 1),
                "rss_after_setup_mib": rss_setup,
                "rss_at_end_mib": rss_end,
                "peak_rss_mib": _rss_mib("VmHWM"),
            }
        )
    )


def _memory(storage: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for label, seconds in (("1_min", 60), ("30_min", 1800)):
        run = subprocess.run(
            [sys.executable, __file__, "--memory-child", str(seconds), storage],
            capture_output=True,
            text=True,
            check=True,
        )
        out[label] = json.loads(run.stdout)
    out["ratio_30min_to_1min"] = round(out["30_min"]["peak_rss_mib"] / out["1_min"]["peak_rss_mib"], 3)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description="Recording cost of twin.bag (JSON on stdout).")
    parser.add_argument("--quick", action="store_true", help="fewer messages and repetitions")
    parser.add_argument("--no-memory", action="store_true", help="skip the 1 and 30 simulated-minute memory runs")
    parser.add_argument("--memory-child", nargs=2, metavar=("SECONDS", "STORAGE"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.memory_child:
        _memory_child(float(args.memory_child[0]), args.memory_child[1])
        return
    n = 5_000 if args.quick else 20_000
    repeats = 2 if args.quick else 5  # timings are the best of the repeats: other load only adds
    result: dict[str, Any] = {"python": sys.version.split()[0]}
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        for storage in ("mcap", "sqlite3"):
            result[storage] = {"mix": _mix(storage, 10, repeats, tmp), "per_type": _per_type(storage, n, repeats, tmp)}
        result["rosbags_reference"] = _rosbags_reference(n // 4, tmp)
    ref = result["rosbags_reference"]
    mine = result["mcap"]["per_type"]
    result["speedup_vs_rosbags"] = {
        "imu": round((ref["imu_build_serialize_us"] + ref["imu_write_mcap_us"]) / mine["/imu"]["encode_write_us"], 1),
        "clock": round(
            (ref["clock_build_serialize_us"] + ref["clock_write_mcap_us"]) / mine["/clock"]["encode_write_us"], 1
        ),
    }
    # This machine against the figures the issue quotes for rosbags' Imu path (10 µs build and
    # serialise + 5 µs write): > 1 means slower. Dividing by it estimates the cost on that machine.
    slowdown = (ref["imu_build_serialize_us"] + ref["imu_write_mcap_us"]) / 15.0
    result["machine_slowdown_vs_quoted_rosbags"] = round(slowdown, 2)
    for storage in ("mcap", "sqlite3"):
        mix = result[storage]["mix"]
        mix["us_per_message_at_quoted_speed"] = round(mix["us_per_message"] / slowdown, 3)
    if not args.no_memory:
        result["memory"] = {storage: _memory(storage) for storage in ("mcap", "sqlite3")}
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
