"""Lidar and scene costs: start-up (load, scene, slice) and per-call (scan, ray casts, collision).

Prints JSON. Compare numbers as ratios within one run; absolute times depend on the machine.
Run from the repository root: `python benchmarks/bench_lidar.py [--fixtures ../shared/fixtures]`.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from twin.robot.lidar import Lidar  # noqa: E402
from twin.world import build_scene, load_robot, load_world  # noqa: E402
from twin.world.obstacles import ObstacleField, ObstacleMonitor, ObstaclePose, ObstacleSpec  # noqa: E402
from twin.world.scene import CollisionMonitor, RobotBody, Scene  # noqa: E402

OBSTACLE_PERIOD_NS = 10_000_000  # the simulation's obstacle update period


def _five_obstacles(x0: float, y0: float) -> list[ObstacleSpec]:
    """Three standing boxes and two walkers (a handful) around (x0, y0)."""
    boxes = [
        ObstacleSpec(shape="box", size_m=(0.3, 0.3, 0.4), pose=ObstaclePose(x_m=x0 + dx, y_m=y0 + dy, yaw_rad=0.3))
        for dx, dy in ((1.0, 0.3), (-0.8, 0.6), (0.4, -1.0))
    ]
    walkers = [
        ObstacleSpec(
            shape="cylinder",
            radius_m=0.2,
            height_m=1.7,
            path_xy_m=((x0 - 1.5, y0 + dy), (x0 + 1.5, y0 + dy)),
            speed_mps=0.5,
            loop=True,
        )
        for dy in (1.2, -1.5)
    ]
    return boxes + walkers


def bench_obstacles(
    scene: Scene, body: RobotBody, lidar_args: tuple[object, ...], track: list[tuple[float, float, float]]
) -> dict[str, object]:
    """What dynamic obstacles cost: a scan and a contact step with none present, and with five (two walking).

    Each scan follows an update (walkers move, so the obstacles' slice is rebuilt for every scan), as
    in a run; the contact step is `ObstacleMonitor.check` along the same 1 kHz track as the world's
    monitor, with an update every 10 steps (the simulation's 10 ms obstacle period).
    """
    robot, caster = lidar_args
    assert isinstance(caster, object)
    x0, y0, yaw0 = track[0]
    out: dict[str, object] = {}
    for label, specs in (("none_present", [_late_box(x0, y0)]), ("five_two_walking", _five_obstacles(x0, y0))):
        field = ObstacleField(specs, body, update_period_ns=OBSTACLE_PERIOD_NS)
        lidar = Lidar.from_robot(robot, scene, np.random.default_rng(0), obstacles=field)  # type: ignore[arg-type]
        field.update(0, track[0])

        def scan(k: int, field: ObstacleField = field, lidar: Lidar = lidar) -> object:
            field.update((k + 1) * 200_000_000, (x0, y0, yaw0))
            return lidar.scan(x0, y0, yaw0)

        out[f"lidar_scan_{label}_us"] = round(per_call_us(scan, 2000), 1)
        field = ObstacleField(specs, body, update_period_ns=OBSTACLE_PERIOD_NS)
        monitor = ObstacleMonitor(CollisionMonitor(scene, body), field)
        start = time.perf_counter()
        for k, pose in enumerate(track):
            if k % 10 == 0:
                field.update(k * 1_000_000, pose)
            monitor.free_m(*pose)
            monitor.check(*pose)
        out[f"contact_step_{label}_us"] = round((time.perf_counter() - start) / len(track) * 1e6, 2)
        out[f"obstacle_fcl_queries_{label}_per_5000_steps"] = field.queries
    return out


def _late_box(x0: float, y0: float) -> ObstacleSpec:
    """A box that appears only after the benchmark (the field exists, nothing is present)."""
    return ObstacleSpec(shape="box", size_m=(0.3, 0.3, 0.4), pose=ObstaclePose(x_m=x0 + 1, y_m=y0), appear_s=1e6)


def per_call_us(fn: Callable[[int], object], calls: int) -> float:
    fn(0)
    start = time.perf_counter()
    for k in range(calls):
        fn(k)
    return (time.perf_counter() - start) / calls * 1e6


def bench_world(name: str, world_path: Path, model_path: list[Path], poses: np.ndarray) -> dict[str, object]:
    t0 = time.perf_counter()
    world = load_world(world_path, model_path=model_path)
    t1 = time.perf_counter()
    scene = build_scene(world)
    t2 = time.perf_counter()
    robot = load_robot("turtlebot3_waffle", model_path=[REPO / "sdf" / "models"])
    assert robot.lidar is not None
    height = robot.base_height_m + robot.lidar.mount.z_m
    caster = scene.ray_caster(height)
    t3 = time.perf_counter()
    numpy_caster = scene.ray_caster(height, native=False)
    lidar = Lidar.from_robot(robot, scene, np.random.default_rng(0))
    n = len(poses)
    step = robot.lidar.angle_increment_rad
    angles = step * np.arange(360)
    body = scene.robot_body(robot.collisions, base_height_m=robot.base_height_m)
    monitor = CollisionMonitor(scene, body)
    # A straight drive at 0.2 m/s sampled at 1 kHz from the freest sampled pose, along its heading
    # (it ends at a contact or after 1 m): what the loop's per-step check costs.
    x0, y0, yaw0 = max(poses, key=lambda p: scene.clearance(body, *p))
    track = [(x0 + 0.0002 * k * math.cos(yaw0), y0 + 0.0002 * k * math.sin(yaw0), yaw0) for k in range(5000)]
    start = time.perf_counter()
    for x, y, yaw in track:
        monitor.check(x, y, yaw)
    check_us = (time.perf_counter() - start) / len(track) * 1e6
    scan_native = per_call_us(lambda k: lidar.scan(*poses[k % n]), 3000)
    fan_native = per_call_us(
        lambda k: caster.cast_fan(tuple(poses[k % n, :2]), poses[k % n, 2], step, 360, 3.5, min_range_m=0.12), 3000
    )
    fan_numpy = per_call_us(
        lambda k: numpy_caster.cast_fan(tuple(poses[k % n, :2]), poses[k % n, 2], step, 360, 3.5, min_range_m=0.12), 300
    )
    rays_native = per_call_us(lambda k: caster.cast_rays(tuple(poses[k % n, :2]), angles + poses[k % n, 2], 3.5), 300)
    start = time.perf_counter()
    for x, y, yaw in track:
        monitor.free_m(x, y, yaw)
        monitor.check(x, y, yaw)
    walls_step_us = (time.perf_counter() - start) / len(track) * 1e6
    obstacles = bench_obstacles(scene, body, (robot, caster), track)
    return {
        "world": name,
        "obstacles": len(scene.obstacles),
        "slice_segments": int(caster.segments.shape[0]),
        "slice_circles": int(caster.circles.shape[0]),
        "load_world_ms": round((t1 - t0) * 1e3, 1),
        "build_scene_ms": round((t2 - t1) * 1e3, 1),
        "slice_ms": round((t3 - t2) * 1e3, 1),
        "lidar_scan_us": round(scan_native, 1),
        "cast_fan_360_us": round(fan_native, 1),
        "cast_fan_360_numpy_us": round(fan_numpy, 1),
        "numpy_over_native": round(fan_numpy / fan_native, 1),
        "cast_rays_360_us": round(rays_native, 1),
        "clearance_us": round(per_call_us(lambda k: scene.clearance(body, *poses[k % n]), 2000), 1),
        "collides_us": round(per_call_us(lambda k: scene.collides(body, *poses[k % n]), 2000), 1),
        "monitor_check_per_step_us": round(check_us, 2),
        "monitor_fcl_queries_per_5000_steps": monitor.queries,
        "lidar_5hz_ms_per_sim_s": round(5 * scan_native / 1e3, 3),
        "contact_step_walls_only_us": round(walls_step_us, 2),
        "dynamic_obstacles": obstacles,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--fixtures", type=Path, default=REPO.parent / "shared" / "fixtures")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    house = np.column_stack([rng.uniform(-1, 5, 200), rng.uniform(-1, 4, 200), rng.uniform(-math.pi, math.pi, 200)])
    results = [bench_world("sdf/worlds/house.sdf", REPO / "sdf" / "worlds" / "house.sdf", [], house)]
    classic = args.fixtures / "gazebo_classic"
    if classic.is_dir():
        big = np.column_stack([rng.uniform(-6, 6, 200), rng.uniform(-4, 4, 200), rng.uniform(-math.pi, math.pi, 200)])
        results.append(
            bench_world(
                "turtlebot3_house.world", classic / "worlds" / "turtlebot3_house.world", [classic / "models"], big
            )
        )
    print(json.dumps({"benchmark": "lidar_and_scene", "results": results}, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
