"""How far FCL's distance between two robots' shapes can be from where its contact query finds contact.

A fleet's drive runs in its compiled loop while the robot moves less than its free distance to the
other robots (FCL's distance between their shapes, less 0.1 mm kept back), and on the Python path
with FCL's contact query otherwise (docs/fleet.md). Where the distance is too long, a robot can end
a chunk inside another robot, and the contact is found one step later. This measures by how much.

Each approach stands the two robots at random headings and slides one towards the other along a
random line until FCL's contact query first finds a contact (bisection on the centre distance, to
well below a nanometre), then sets it back by each `--offsets` distance along that line. There the
shapes are at most that offset apart (the way back is free of contact), so FCL's distance less
the offset is at least how much too long it is. Prints JSON: per kind of shape pair (the pair
whose distance is the least), the approaches, the largest and the 99th percentile of that excess,
and how many exceed the 0.1 mm kept back; an accuracy check, not a speed figure.

    python benchmarks/fidelity_robot_distance.py [--scenario scenarios/default.yaml]
                                                 [--approaches 1000] [--seed 0] [--offsets 0.0003 0.001]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import fcl
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from twin.sim.robot_group import scenario_robot
from twin.sim.scenario import default_scenario_path
from twin.sim.scenario_file import load_scenario
from twin.world.scene import RobotBody

KEPT_BACK_M = 1e-4  # twin.sim.fleet._TOLERANCE_M


def nearest_pair(
    a: RobotBody, pa: tuple[float, float, float], b: RobotBody, pb: tuple[float, float, float]
) -> tuple[float, str]:
    """FCL's distance between the two robots and the kind of the shape pair that gives it."""
    best, kind = math.inf, ""
    request = fcl.DistanceRequest()
    for _, i, j in a._near_pairs(pa, b, pb, math.inf):
        a._place_parts(pa, (i,))
        b._place_parts(pb, (j,))
        result = fcl.DistanceResult()
        fcl.distance(a._objects[i], b._objects[j], request, result)
        if result.min_distance < best:
            names = sorted(type(p.collision.geometry).__name__.lower() for p in (a._parts[i], b._parts[j]))
            best, kind = result.min_distance, "-".join(names)
    return max(0.0, best), kind


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", type=Path, default=default_scenario_path())
    parser.add_argument("--approaches", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--offsets", type=float, nargs="+", default=[3e-4, 1e-3])
    args = parser.parse_args()

    robot = scenario_robot(load_scenario(args.scenario))
    a = RobotBody(robot.collisions, base_height_m=robot.base_height_m)
    b = RobotBody(robot.collisions, base_height_m=robot.base_height_m)
    rng = np.random.default_rng(args.seed)
    reach = 2.0 * (a.radius_m + b.radius_m)
    excess: dict[str, list[float]] = {}
    for _ in range(args.approaches):
        other = (0.0, 0.0, float(rng.uniform(-math.pi, math.pi)))
        heading, yaw = float(rng.uniform(-math.pi, math.pi)), float(rng.uniform(-math.pi, math.pi))
        c, s = math.cos(heading), math.sin(heading)
        touching, apart = 0.0, reach  # centre distances: in contact, and free
        while apart - touching > 1e-10:
            mid = 0.5 * (touching + apart)
            if a.contacts_with((mid * c, mid * s, yaw), b, other):
                touching = mid
            else:
                apart = mid
        for offset in args.offsets:
            r = apart + offset
            distance, kind = nearest_pair(a, (r * c, r * s, yaw), b, other)
            excess.setdefault(kind, []).append(distance - (offset + (apart - touching)))
    kinds = {
        kind: {
            "pairs": len(values),
            "max_excess_mm": round(1e3 * max(values), 4),
            "p99_excess_mm": round(1e3 * float(np.percentile(values, 99)), 4),
            "over_kept_back": sum(v > KEPT_BACK_M for v in values),
        }
        for kind, values in sorted(excess.items())
    }
    everything = [v for values in excess.values() for v in values]
    print(
        json.dumps(
            {
                "scenario": str(args.scenario),
                "robot": robot.name,
                "approaches": args.approaches,
                "offsets_m": args.offsets,
                "kept_back_mm": 1e3 * KEPT_BACK_M,
                "max_excess_mm": round(1e3 * max(everything), 4),
                "kinds": kinds,
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
