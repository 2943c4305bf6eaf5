"""Nav2 Humble's velocity_smoother in OPEN_LOOP mode: cmd_vel_nav in, /cmd_vel out at 20 Hz.

TB3's yaml has no velocity_smoother section, so Nav2's code defaults hold (TB3_FACTS §4.2):
max_velocity [0.5, 0, 2.5], min [-0.5, 0, -2.5], max_accel [2.5, 0, 3.2], max_decel [-2.5, 0,
-3.2], deadband 0, velocity_timeout 1.0 s, scale_velocities false. Each cycle clamps the latest
command to the velocity limits and moves the last output (open loop: the smoother's own previous
command is the current velocity) towards it by at most one cycle of acceleration (accelerating
while the speed grows without changing sign, else decelerating); with `scale_velocities` every
component moves by the same fraction of its change, the one the most constrained component allows.
What is published has values inside the deadband zeroed (the next cycle starts from the value
before). Without a command for `velocity_timeout_s` it ramps the target to zero and, once the
output is zero, stops publishing (`step` returns None). `VelocitySmootherNode` is the node.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from twin.bag import TwistEncoder
from twin.node import PRIORITY_COMMAND, Encoded, Node

__all__ = ["SmootherParams", "VelocitySmoother", "VelocitySmootherNode"]


@dataclass(frozen=True, kw_only=True, slots=True)
class SmootherParams:
    """velocity_smoother parameters for (vx, wz); Nav2 Humble code defaults."""

    smoothing_frequency_hz: float = 20.0
    max_velocity: tuple[float, float] = (0.5, 2.5)
    min_velocity: tuple[float, float] = (-0.5, -2.5)
    max_accel: tuple[float, float] = (2.5, 3.2)
    max_decel: tuple[float, float] = (-2.5, -3.2)
    deadband_velocity: tuple[float, float] = (0.0, 0.0)
    velocity_timeout_s: float = 1.0
    scale_velocities: bool = False


def _bounds(current: float, command: float, accel: float, decel: float, rate_hz: float) -> tuple[float, float]:
    if abs(command) >= abs(current) and current * command >= 0.0:
        return -accel / rate_hz, accel / rate_hz
    return decel / rate_hz, -decel / rate_hz


def _eta(current: float, command: float, accel: float, decel: float, rate_hz: float) -> float:
    """findEtaConstraint: the fraction of the change one cycle allows (-1 when all of it)."""
    lo, hi = _bounds(current, command, accel, decel, rate_hz)
    dv = command - current
    if dv > hi:
        return hi / dv
    if dv < lo:
        return lo / dv
    return -1.0


def _limit(current: float, command: float, accel: float, decel: float, rate_hz: float, *, eta: float = 1.0) -> float:
    lo, hi = _bounds(current, command, accel, decel, rate_hz)
    return current + min(max(eta * (command - current), lo), hi)


class VelocitySmoother:
    """One smoother; `command` on each cmd_vel_nav message, `step` at `smoothing_frequency_hz`."""

    def __init__(self, params: SmootherParams | None = None) -> None:
        self.params = params or SmootherParams()
        self._target = (0.0, 0.0)
        self._last_cmd_ns: int | None = None
        self._out = (0.0, 0.0)
        self._stopped = True

    def command(self, vx: float, wz: float, t_ns: int) -> None:
        """Take a new command (cmd_vel_nav) received at `t_ns`."""
        p = self.params
        self._target = (
            min(max(vx, p.min_velocity[0]), p.max_velocity[0]),
            min(max(wz, p.min_velocity[1]), p.max_velocity[1]),
        )
        self._last_cmd_ns = t_ns
        self._stopped = False

    def step(self, t_ns: int) -> tuple[float, float] | None:
        """Return the (vx, wz) to publish on /cmd_vel at `t_ns`, or None when nothing is published."""
        p = self.params
        if self._last_cmd_ns is None:
            return None
        target = self._target
        if t_ns - self._last_cmd_ns > round(p.velocity_timeout_s * 1e9):
            if self._out == (0.0, 0.0) or self._stopped:
                self._stopped = True
                return None
            target = (0.0, 0.0)
        rate = p.smoothing_frequency_hz
        out = self._out
        eta = 1.0
        if p.scale_velocities:
            for i in (0, 1):
                e = _eta(out[i], target[i], p.max_accel[i], p.max_decel[i], rate)
                if e > 0.0 and abs(1.0 - e) > abs(1.0 - eta):
                    eta = e
        self._out = (
            _limit(out[0], target[0], p.max_accel[0], p.max_decel[0], rate, eta=eta),
            _limit(out[1], target[1], p.max_accel[1], p.max_decel[1], rate, eta=eta),
        )
        vx, wz = self._out
        return (
            0.0 if abs(vx) < p.deadband_velocity[0] else vx,
            0.0 if abs(wz) < p.deadband_velocity[1] else wz,
        )


class VelocitySmootherNode(Node):
    """velocity_smoother: `cmd_vel_nav` in, `/cmd_vel` out at its smoothing frequency (open loop)."""

    def __init__(self, params: SmootherParams) -> None:
        super().__init__("velocity_smoother")
        smoother = VelocitySmoother(params)
        pub = self.create_publisher(TwistEncoder.msgtype, "cmd_vel", 10)
        encode = TwistEncoder().encode
        now = self._graph_now

        def on_cmd(msg: Any) -> None:
            if type(msg) is Encoded:
                v, w = msg[2]
            else:
                v, w = float(msg.linear.x), float(msg.angular.z)
            smoother.command(v, w, now())

        def on_timer(t_ns: int) -> None:
            out = smoother.step(t_ns)
            if out is not None:
                pub.publish(Encoded((encode, out, out)))

        self.create_subscription("geometry_msgs/msg/Twist", "cmd_vel_nav", on_cmd, 10, raw=True)
        self.create_rate_timer(params.smoothing_frequency_hz, on_timer, priority=PRIORITY_COMMAND + 1)
