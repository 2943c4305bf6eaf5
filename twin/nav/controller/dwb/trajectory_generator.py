"""dwb_plugins' trajectory generators: the velocity samples (XYThetaIterator) and their trajectories.

`velocity_samples` is StandardTrajectoryGenerator's (or LimitedAccelGenerator's) sampling of the
velocities reachable from the current one; `generate_trajectories` rolls each out over `sim_time`.
The numpy reference of what the C cycle (`dwb_kernel.c`) does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from twin.nav.controller.dwb.dwb_params import EPS, DwbParams

__all__ = ["Trajectories", "generate_trajectories", "velocity_samples"]

F64 = NDArray[np.float64]
Pose = tuple[float, float, float]


@dataclass(frozen=True, kw_only=True, slots=True)
class Trajectories:
    """Sampled trajectories: `velocity[s] = (vx, wz)`, `poses[s, k] = (x, y, yaw)`, `steps[s]` time steps."""

    velocity: F64
    poses: F64
    steps: NDArray[np.int64]


def _project(v0: float, accel: float, decel: float, dt: float, target: float) -> float:
    if v0 < target:
        return min(target, v0 + accel * dt)
    return max(target, v0 + decel * dt)


class _Iter1D:
    """dwb_plugins::OneDVelocityIterator."""

    def __init__(self, current: float, limits: tuple[float, float, float, float], t: float, n: int) -> None:
        lo, hi, acc, dec = limits
        current = min(max(current, lo), hi)
        self.max_vel = _project(current, acc, dec, t, hi)
        self.min_vel = _project(current, acc, dec, t, lo)
        self.reset()
        if abs(self.min_vel - self.max_vel) < EPS:
            self.increment = 1.0
            return
        n = max(2, n)
        self.increment = (self.max_vel - self.min_vel) / max(1, n - 1)

    def reset(self) -> None:
        self.current = self.min_vel
        self.return_zero = True
        self.return_zero_now = False

    def velocity(self) -> float:
        return 0.0 if self.return_zero_now else self.current

    def next(self) -> None:
        c = self.current
        if self.return_zero and c < 0.0 and c + self.increment > 0.0 and c + self.increment <= self.max_vel + EPS:
            self.return_zero_now, self.return_zero = True, False
        else:
            self.current += self.increment
            self.return_zero_now = False

    def finished(self) -> bool:
        return self.current > self.max_vel + EPS


def velocity_samples(p: DwbParams, velocity: tuple[float, float]) -> F64:
    """XYThetaIterator's samples (n, 2) in its order."""
    t = p.window_time_s
    xi = _Iter1D(velocity[0], (p.min_vel_x, p.max_vel_x, p.acc_lim_x, p.decel_lim_x), t, p.vx_samples)
    th_limits = (-p.max_vel_theta, p.max_vel_theta, p.acc_lim_theta, p.decel_lim_theta)
    ti = _Iter1D(velocity[1], th_limits, t, p.vtheta_samples)

    def valid(x: float, th: float) -> bool:
        sq = x * x
        if p.max_speed_xy >= 0.0 and sq > p.max_speed_xy**2 + EPS:
            return False
        if (
            p.min_speed_xy >= 0.0
            and sq + EPS < p.min_speed_xy**2
            and p.min_speed_theta >= 0.0
            and abs(th) + EPS < p.min_speed_theta
        ):
            return False
        return not (sq == 0.0 and th == 0.0)

    out: list[tuple[float, float]] = []
    ok = valid(xi.velocity(), ti.velocity())
    while True:
        while not ok and not xi.finished():
            ti.next()
            if ti.finished():
                ti.reset()
                xi.next()
            ok = valid(xi.velocity(), ti.velocity())
        if xi.finished():
            break
        out.append((xi.velocity(), ti.velocity()))
        ok = False
    return np.array(out, dtype=np.float64).reshape(-1, 2)


def generate_trajectories(p: DwbParams, cmd: F64, pose: Pose, velocity: tuple[float, float]) -> Trajectories:
    """Every sample's trajectory, step by step as StandardTrajectoryGenerator (all samples at once)."""
    n = len(cmd)
    lin = np.abs(cmd[:, 0]) * p.sim_time_s / p.linear_granularity_m
    ang = np.abs(cmd[:, 1]) * p.sim_time_s / p.angular_granularity_rad
    steps = np.maximum(np.ceil(np.maximum(lin, ang)), 1).astype(np.int64)
    dt = p.sim_time_s / steps
    n_max = int(steps.max()) if n else 1
    poses = np.empty((n, n_max + 1, 3))
    x = np.full(n, pose[0])
    y = np.full(n, pose[1])
    th = np.full(n, pose[2])
    v = np.full(n, velocity[0])
    w = np.full(n, velocity[1])
    poses[:, 0] = (pose[0], pose[1], pose[2])
    for k in range(1, n_max + 1):
        if p.limited_accel:
            v, w = cmd[:, 0].copy(), cmd[:, 1].copy()
        else:
            v = np.where(
                v < cmd[:, 0],
                np.minimum(cmd[:, 0], v + p.acc_lim_x * dt),
                np.maximum(cmd[:, 0], v + p.decel_lim_x * dt),
            )
            w = np.where(
                w < cmd[:, 1],
                np.minimum(cmd[:, 1], w + p.acc_lim_theta * dt),
                np.maximum(cmd[:, 1], w + p.decel_lim_theta * dt),
            )
        live = k <= steps
        x = np.where(live, x + (v * np.cos(th)) * dt, x)
        y = np.where(live, y + (v * np.sin(th)) * dt, y)
        th = np.where(live, th + w * dt, th)
        poses[:, k, 0], poses[:, k, 1], poses[:, k, 2] = x, y, th
    return Trajectories(velocity=cmd, poses=poses, steps=steps)
