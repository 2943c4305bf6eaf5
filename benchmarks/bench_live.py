"""Live view: how well pacing holds real time, and what serving a run costs when it runs flat out.

Prints JSON with two parts, for the default scenario run in process (a Simulation whose executor
hands every recorded message to the recorder, then to a `LiveSink`, as `twin simulate --live` wires
it), with a WebSocket client subscribed to /clock and /scan as Foxglove would be:
  pacing    for each speed: sim seconds, wall seconds, the error against sim/speed in percent, and
            the client's view (wall time between the first and last /clock it received against the
            sim time they carry)
  overhead  the same run as fast as possible: plain recorder, live sink with nobody watching, live
            sink with a client subscribed to every topic; wall seconds and their ratios
Speed is compared as ratios within one run (this machine is shared and noisy), never asserted.

    python benchmarks/bench_live.py [--sim-s 30] [--speeds 1 5] [--overhead-sim-s 20]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tests.foxglove_client import Watch, watch
from twin.live import LiveServer, LiveSink, Pacer
from twin.sim.scenario import default_scenario_path
from twin.sim.scenario_file import load_scenario
from twin.sim.simulation import Simulation


class Client(threading.Thread):
    """A WebSocket client on its own thread, noting the wall time each new /clock arrives."""

    def __init__(self, url: str, topics: list[str]) -> None:
        super().__init__(daemon=True)
        self.url, self.topics = url, topics
        self.arrivals: list[tuple[float, int]] = []
        self.seen: Watch | None = None
        self.subscribed = threading.Event()

    def _note(self, w: Watch) -> bool:
        if w.channels:
            self.subscribed.set()
        clock = w.messages.get("/clock")
        if clock and (not self.arrivals or self.arrivals[-1][1] != clock[-1][0]):
            self.arrivals.append((time.perf_counter(), clock[-1][0]))
        return False

    def run(self) -> None:
        self.seen = asyncio.run(watch(self.url, self.topics, stop=self._note, timeout_s=600))


def run(sim_s: float, *, speed: float | None, live: bool, client_topics: list[str] | None) -> dict[str, Any]:
    scenario = load_scenario(default_scenario_path())
    with tempfile.TemporaryDirectory() as tmp:
        server = LiveServer(port=0) if live else None
        try:
            pacer = Pacer(speed) if speed is not None else None
            sinks = [LiveSink(server, pacer=pacer)] if (live or pacer) else []
            with Simulation(scenario, bag_path=Path(tmp) / "bag", duration_s=sim_s, sinks=sinks) as sim:
                client = None
                if server is not None and client_topics is not None:
                    client = Client(server.url, client_topics)
                    client.start()
                    client.subscribed.wait(10)
                    time.sleep(0.2)  # let the subscriptions settle before the run starts
                summary = sim.run()
        finally:
            if server is not None:
                server.close()
        if client is not None:
            client.join(30)
    result: dict[str, Any] = {"sim_s": summary.sim_s, "wall_s": round(summary.wall_s, 4), "messages": summary.messages}
    if speed is not None:
        expected = summary.sim_s / speed
        result["speed"] = speed
        result["expected_wall_s"] = expected
        result["error_pct"] = round(100 * (summary.wall_s - expected) / expected, 3)
    if client is not None and client.seen is not None:
        received = sum(len(v) for v in client.seen.messages.values())
        result["client_messages"] = received
        if len(client.arrivals) > 1 and speed is not None:
            (w0, t0), (w1, t1) = client.arrivals[0], client.arrivals[-1]
            sim_seen = (t1 - t0) / 1e9
            result["client_sim_s"] = round(sim_seen, 3)
            result["client_wall_s"] = round(w1 - w0, 4)
            result["client_error_pct"] = round(100 * ((w1 - w0) - sim_seen / speed) / (sim_seen / speed), 3)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sim-s", type=float, default=30.0, help="sim seconds of each paced run")
    parser.add_argument("--speeds", type=float, nargs="+", default=[1.0, 5.0])
    parser.add_argument("--overhead-sim-s", type=float, default=20.0)
    args = parser.parse_args()
    pacing = [run(args.sim_s, speed=s, live=True, client_topics=["/clock", "/scan"]) for s in args.speeds]
    everything = [
        "/clock", "/scan", "/tf", "/tf_static", "/odom", "/imu", "/joint_states", "/cmd_vel",
        "/robot_description", "/rosout", "/behavior_tree_log", "/plan", "/ground_truth/odom",
    ]  # fmt: skip
    plain = run(args.overhead_sim_s, speed=None, live=False, client_topics=None)
    unwatched = run(args.overhead_sim_s, speed=None, live=True, client_topics=None)
    watched = run(args.overhead_sim_s, speed=None, live=True, client_topics=everything)
    overhead = {
        "recorder_only": plain,
        "live_unwatched": unwatched,
        "live_watched_all_topics": watched,
        "ratio_unwatched": round(unwatched["wall_s"] / plain["wall_s"], 3),
        "ratio_watched": round(watched["wall_s"] / plain["wall_s"], 3),
    }
    print(json.dumps({"pacing": pacing, "overhead": overhead}, indent=2))


if __name__ == "__main__":
    main()
