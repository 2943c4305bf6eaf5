"""ROS 2 bridge: what `--ros2` costs a paced run with no peer, and what one message costs on the wire.

Prints JSON with two parts:
  run   the default scenario at --speed 1 for --sim-s sim seconds, as `twin simulate` runs it, with and
        without `--ros2` (no peer on the domain): wall seconds, CPU seconds of the process (user + sys)
        and their ratio. At real time the wall time is the sim time either way; the CPU time is the cost.
  wire  in process: one message handed to the bridge's sink (`Ros2Bridge.write`, the bag's CDR bytes to
        Cyclone DDS) per topic kind, microseconds per message over --messages messages, with no reader
        and with a reader in another participant of the same process.
Everything that starts DDS runs in a network namespace with only loopback up: the script runs itself
again under `unshare --net` (root, or user namespaces) and refuses to run DDS outside one.

    python benchmarks/bench_ros2.py [--sim-s 20] [--messages 20000]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

_INSIDE = "TWIN_BENCH_ROS2_NETNS"


def _run(sim_s: float, ros2: bool) -> dict[str, float]:
    """One `twin simulate` at --speed 1 in a child process: its wall and CPU seconds."""
    with tempfile.TemporaryDirectory() as tmp:
        args = [sys.executable, "-m", "twin", "simulate", "--speed", "1", "--duration", str(sim_s)]
        args += ["--out", str(Path(tmp) / "bag")] + (["--ros2", "--domain-id", "77"] if ros2 else [])
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        wall0 = time.perf_counter()
        subprocess.run(args, cwd=REPO, check=True, capture_output=True, env={**os.environ, "PYTHONPATH": str(REPO)})
        wall = time.perf_counter() - wall0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": round(wall, 3), "cpu_s": round(cpu, 3)}


def _wire(messages: int) -> dict[str, Any]:
    """Microseconds per message through `Ros2Bridge.write`, for a few of the run's topics."""
    from cyclonedds.core import Policy, Qos
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    from twin.bag import QOS_BEST_EFFORT
    from twin.bag.typesys import TypeRegistry
    from twin.msgs import serialize, typestore
    from twin.ros2 import Ros2Bridge
    from twin.ros2.dds_types import struct_type
    from twin.sim.scenario import Ros2Section

    store = typestore()
    t = store.types
    header = t["std_msgs/msg/Header"](t["builtin_interfaces/msg/Time"](1, 2), "base_scan")
    import numpy as np

    samples = {
        "/clock": ("rosgraph_msgs/msg/Clock", t["rosgraph_msgs/msg/Clock"](t["builtin_interfaces/msg/Time"](1, 2))),
        "/scan": (
            "sensor_msgs/msg/LaserScan",
            t["sensor_msgs/msg/LaserScan"](
                header, 0.0, 6.28, 0.0175, 0.0, 0.2, 0.12, 3.5, np.ones(360, np.float32), np.zeros(0, np.float32)
            ),
        ),
    }
    out: dict[str, Any] = {}
    with Ros2Bridge(Ros2Section(enabled=True, domain_id=78)) as bridge:
        for topic, (msgtype, msg) in samples.items():
            data = serialize(msg, msgtype)
            handle = bridge.add_topic(topic, msgtype, qos=(QOS_BEST_EFFORT,))
            row: dict[str, Any] = {"bytes": len(data)}
            for label in ("no_reader", "one_reader"):
                reader = None
                if label == "one_reader":
                    other = DomainParticipant(78)
                    dds_type = struct_type(msgtype, TypeRegistry().store)
                    reader = DataReader(other, Topic(other, "rt" + topic, dds_type), Qos(Policy.History.KeepLast(1)))
                    time.sleep(1.0)  # discovery on loopback
                t0 = time.perf_counter()
                for _ in range(messages):
                    bridge.write(handle, 0, data)
                row[f"{label}_us"] = round((time.perf_counter() - t0) / messages * 1e6, 2)
                del reader
            out[topic] = row
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sim-s", type=float, default=20.0)
    parser.add_argument("--messages", type=int, default=20000)
    args = parser.parse_args()
    if os.environ.get(_INSIDE) != "1":
        script = f"ip link set lo up && exec {sys.executable} {' '.join(sys.argv)}"
        env = {**os.environ, _INSIDE: "1"}
        sys.exit(subprocess.run(["unshare", "--net", "sh", "-c", script], env=env, check=False).returncode)
    plain = _run(args.sim_s, ros2=False)
    bridged = _run(args.sim_s, ros2=True)
    result = {
        "run": {
            "sim_s": args.sim_s,
            "speed": 1,
            "recorder_only": plain,
            "ros2_no_peer": bridged,
            "cpu_ratio": round(bridged["cpu_s"] / plain["cpu_s"], 3),
            "wall_ratio": round(bridged["wall_s"] / plain["wall_s"], 3),
        },
        "wire": _wire(args.messages),
    }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
