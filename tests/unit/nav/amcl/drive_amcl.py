"""Drive a robot along a path in turtlebot3_world with the project's lidar and noisy odometry, running AMCL."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from twin.nav.amcl.filter import Amcl
from twin.nav.frames import LaserGeometry
from twin.nav.map_server.map_io import OccupancyMap, load_map
from twin.nav.params import AmclParams, default_params_path, load_nav2_params
from twin.robot.lidar import Lidar
from twin.world import build_scene, load_robot, load_world
from twin.world.scene import Scene

REPO = Path(__file__).resolve().parents[4]
FIXTURES = REPO.parent / "shared" / "fixtures"
START = (-2.0, -0.5, math.pi / 2)


@lru_cache(maxsize=1)
def world() -> tuple[Scene, OccupancyMap]:
    w = load_world(
        FIXTURES / "gazebo_classic/worlds/turtlebot3_world.world", model_path=[FIXTURES / "gazebo_classic/models"]
    )
    return build_scene(w), load_map(FIXTURES / "nav2/turtlebot3_navigation2_humble/map/map.yaml")


def amcl_params() -> AmclParams:
    return load_nav2_params(default_params_path("waffle")).amcl


def path_poses(duration_s: float, rate_hz: float = 5.0) -> np.ndarray:
    """Ground-truth poses at the scan rate: a loop around turtlebot3_world's pillars from (-2, -0.5)."""
    # waypoints of a loop through the free ring between the pillars and the outer walls
    ring = [(-2.0, -0.5), (-2.0, 0.6), (-1.2, 1.9), (0.0, 2.05), (1.2, 1.9), (2.0, 0.6), (2.0, -0.6),
            (1.2, -1.9), (0.0, -2.05), (-1.2, -1.9), (-2.0, -0.5)]  # fmt: skip
    pts = np.array(ring)
    seg = np.diff(pts, axis=0)
    lengths = np.hypot(seg[:, 0], seg[:, 1])
    cum = np.concatenate([[0.0], np.cumsum(lengths)])
    speed = 0.2
    t = np.arange(0.0, duration_s + 1e-9, 1.0 / rate_hz)
    s = (speed * t) % cum[-1]
    i = np.minimum(np.searchsorted(cum, s, side="right") - 1, len(seg) - 1)
    frac = (s - cum[i]) / lengths[i]
    xy = pts[i] + seg[i] * frac[:, None]
    yaw = np.arctan2(seg[i, 1], seg[i, 0])
    return np.column_stack([xy, yaw])


@dataclass
class Run:
    truth: np.ndarray  # (n, 3) at each scan
    estimate: np.ndarray  # (n, 3) AMCL's map pose at each scan (map->odom applied to odometry)
    updates: int


def drive(
    seed: int,
    duration_s: float,
    *,
    initial: tuple[float, float, float],
    cov: float = 0.25,
    yaw_var: float = 0.0685,
    odom_noise: float = 0.02,
    native: bool = True,
) -> Run:
    scene, occupancy = world()
    robot = load_robot("turtlebot3_waffle", model_path=[REPO / "sdf" / "models"])
    rng = np.random.default_rng(seed)
    lidar = Lidar.from_robot(robot, scene, np.random.default_rng(seed + 1000))
    spec = lidar.spec
    laser = LaserGeometry.from_spec(spec)
    amcl = Amcl(amcl_params(), occupancy, laser, np.random.default_rng(seed + 2000), native=native)
    amcl.set_initial_pose(*initial, np.diag([cov, cov, yaw_var]))
    truth = path_poses(duration_s)
    odom = np.zeros(3)
    odom[:] = truth[0]  # odometry starts where the robot is, as the EKF does at spawn
    estimates = np.zeros_like(truth)
    updates = 0
    for k, pose in enumerate(truth):
        if k:
            prev = truth[k - 1]
            # body-frame motion since the last scan, with scale and heading noise
            c, s = math.cos(prev[2]), math.sin(prev[2])
            dx, dy = pose[0] - prev[0], pose[1] - prev[1]
            fwd, side = c * dx + s * dy, -s * dx + c * dy
            dyaw = (pose[2] - prev[2] + math.pi) % (2 * math.pi) - math.pi
            fwd *= 1.0 + odom_noise * rng.standard_normal()
            dyaw = dyaw * (1.0 + odom_noise * rng.standard_normal()) + 0.002 * rng.standard_normal()
            oc, os_ = math.cos(odom[2]), math.sin(odom[2])
            odom[0] += oc * fwd - os_ * side
            odom[1] += os_ * fwd + oc * side
            odom[2] += dyaw
        ranges = lidar.scan(*pose)
        if amcl.process_scan((float(odom[0]), float(odom[1]), float(odom[2])), ranges) is not None:
            updates += 1
        tf = amcl.map_odom()
        assert tf is not None
        tx, ty, tyaw = tf
        c, s = math.cos(tyaw), math.sin(tyaw)
        estimates[k] = (tx + c * odom[0] - s * odom[1], ty + s * odom[0] + c * odom[1], tyaw + odom[2])
    return Run(truth=truth, estimate=estimates, updates=updates)


def errors(run: Run) -> tuple[np.ndarray, np.ndarray]:
    pos = np.hypot(*(run.estimate[:, :2] - run.truth[:, :2]).T)
    yaw = np.abs((run.estimate[:, 2] - run.truth[:, 2] + math.pi) % (2 * math.pi) - math.pi)
    return pos, yaw
