"""Records the mission mix at a steady pace until killed (the kill test's stand-in for `twin simulate`).

    python tests/unit/bag/kill_writer.py BAG_DIR WRITE_LOG --storage mcap --speed 10

Every message handed to the recorder is logged to WRITE_LOG (topic, bag time, monotonic wall
time) by the recorder's `write_log` option, one write(2) per line.
"""

from __future__ import annotations

import argparse
import time

from twin.bag import Recorder
from twin.bag.mission_mix import MissionMix


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("bag")
    parser.add_argument("log")
    parser.add_argument("--storage", default="mcap")
    parser.add_argument("--speed", type=float, default=10.0, help="simulated seconds per wall second")
    parser.add_argument("--seconds", type=float, default=600.0, help="simulated seconds to record")
    args = parser.parse_args()
    with Recorder(args.bag, storage=args.storage, write_log=args.log) as rec:
        mix = MissionMix(rec, particles=100, path_poses=30)
        start = time.monotonic()
        for t_ns, emit in mix.schedule(round(args.seconds * 1e9)):
            lag = start + t_ns / 1e9 / args.speed - time.monotonic()
            if lag > 0.002:
                time.sleep(lag)
            emit(t_ns)


if __name__ == "__main__":
    main()
