"""Nav2 Humble's velocity_smoother: cmd_vel_nav in, /cmd_vel out at its smoothing frequency.

A velocity is an (x, y, theta) triple, as Nav2's parameters spell it: linear x, linear y (m/s) and
angular z (rad/s). TB3's yaml has no velocity_smoother section, so Nav2's code defaults hold (TB3_FACTS
§4.2): max_velocity [0.5, 0, 2.5], min [-0.5, 0, -2.5], max_accel [2.5, 0, 3.2], max_decel [-2.5, 0,
-3.2], deadband 0, velocity_timeout 1.0 s, scale_velocities false, OPEN_LOOP.

Each cycle clamps the latest valid command (one with a NaN or infinity anywhere is dropped) to the
velocity limits and moves the current velocity towards it by at most one cycle of acceleration
(accelerating while the speed grows without changing sign, else decelerating). The current velocity
is the smoother's own previous output in OPEN_LOOP, and in CLOSED_LOOP the mean of the odometry twists
received within `odom_duration` of the newest one (by their stamps). With `scale_velocities` every
component moves by the same fraction of its change, the one the most constrained component allows.
What is published has values inside the deadband zeroed (the next cycle starts from the value before).
A command older than `velocity_timeout` is replaced by zero, and once the output is zero nothing more
is published (`step` returns None) until a new command comes.

Held to Nav2's own code by the cases in `tests/unit/nav/velocity_smoother/smoother_cases/`, bit for
bit: the operations below are Nav2's, in its order, in doubles. `VelocitySmootherNode` is the node.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from enum import Enum
from typing import Any

from twin.bag import TwistEncoder
from twin.node import PRIORITY_COMMAND, Encoded, Node

__all__ = ["Feedback", "OdomSmoother", "SmootherParams", "Velocity", "VelocitySmoother", "VelocitySmootherNode"]

Velocity = tuple[float, float, float]
"""(linear x m/s, linear y m/s, angular z rad/s)."""

_ZERO: Velocity = (0.0, 0.0, 0.0)
_NS_PER_S = 1000 * 1000 * 1000
_NS_PER_MS = 1000 * 1000


class Feedback(Enum):
    """Where the current velocity comes from: the last output (OPEN_LOOP) or odometry (CLOSED_LOOP)."""

    OPEN_LOOP = "OPEN_LOOP"
    CLOSED_LOOP = "CLOSED_LOOP"


def _duration_ns(seconds: float) -> int:
    """Seconds to nanoseconds as rclcpp's `Duration::from_seconds` does: a double product, truncated."""
    return int(seconds * _NS_PER_S)


@dataclass(frozen=True, kw_only=True, slots=True)
class SmootherParams:
    """velocity_smoother parameters, each triple (x, y, theta); Nav2 Humble code defaults."""

    smoothing_frequency_hz: float = 20.0
    feedback: Feedback = Feedback.OPEN_LOOP
    odom_topic: str = "odom"  # the odometry CLOSED_LOOP reads (relative: under the robot's namespace)
    odom_duration_s: float = 0.1
    max_velocity: Velocity = (0.5, 0.0, 2.5)
    min_velocity: Velocity = (-0.5, 0.0, -2.5)
    max_accel: Velocity = (2.5, 0.0, 3.2)
    max_decel: Velocity = (-2.5, 0.0, -3.2)
    deadband_velocity: Velocity = (0.0, 0.0, 0.0)
    velocity_timeout_s: float = 1.0
    scale_velocities: bool = False

    @property
    def period_ns(self) -> int:
        """The timer's period: Nav2 makes it a whole number of milliseconds (30 Hz ticks every 33 ms)."""
        return int(1000.0 / self.smoothing_frequency_hz) * _NS_PER_MS

    @property
    def timeout_ns(self) -> int:
        """`velocity_timeout` as the rclcpp Duration Nav2 compares the command's age with."""
        return _duration_ns(self.velocity_timeout_s)


class OdomSmoother:
    """The mean odometry twist over a window of stamps (nav2_util's OdomSmoother), kept as a running sum."""

    def __init__(self, duration_s: float) -> None:
        self._window_ns = _duration_ns(duration_s)
        self._history: deque[tuple[int, Velocity]] = deque()
        self._sum = [0.0, 0.0, 0.0]
        self.twist: Velocity = _ZERO

    def add(self, twist: Velocity, stamp_ns: int) -> None:
        """Take one odometry twist stamped `stamp_ns`; drop those older than the window before the newest."""
        history, total = self._history, self._sum
        while history and stamp_ns - history[0][0] > self._window_ns:
            old = history.popleft()[1]
            total[0] -= old[0]
            total[1] -= old[1]
            total[2] -= old[2]
        history.append((stamp_ns, twist))
        total[0] += twist[0]
        total[1] += twist[1]
        total[2] += twist[2]
        n = len(history)
        self.twist = (total[0] / n, total[1] / n, total[2] / n)


class _Axis:
    """One axis' limits per cycle: the change allowed while accelerating, and while decelerating."""

    __slots__ = ("accel_max", "accel_min", "deadband", "decel_max", "decel_min", "high", "low")

    def __init__(self, params: SmootherParams, i: int) -> None:
        rate = params.smoothing_frequency_hz
        self.low, self.high = params.min_velocity[i], params.max_velocity[i]
        self.accel_max, self.accel_min = params.max_accel[i] / rate, -params.max_accel[i] / rate
        self.decel_max, self.decel_min = -params.max_decel[i] / rate, params.max_decel[i] / rate
        self.deadband = params.deadband_velocity[i]

    def bounds(self, current: float, command: float) -> tuple[float, float]:
        if abs(command) >= abs(current) and current * command >= 0.0:
            return self.accel_min, self.accel_max
        return self.decel_min, self.decel_max

    def eta(self, current: float, command: float) -> float:
        """The fraction of the change one cycle allows (-1 when all of it): Nav2's findEtaConstraint."""
        lo, hi = self.bounds(current, command)
        dv = command - current
        if dv > hi:
            return hi / dv
        if dv < lo:
            return lo / dv
        return -1.0

    def limit(self, current: float, command: float, eta: float) -> float:
        lo, hi = self.bounds(current, command)
        change = eta * (command - current)
        return current + (lo if change < lo else hi if hi < change else change)

    def clamp(self, command: float) -> float:
        low, high = self.low, self.high
        return low if command < low else high if high < command else command


class VelocitySmoother:
    """One smoother: `command` per cmd_vel_nav, `odometry` per odom (closed loop), `step` per timer tick."""

    def __init__(self, params: SmootherParams | None = None) -> None:
        self.params = p = params or SmootherParams()
        self._axes = (_Axis(p, 0), _Axis(p, 1), _Axis(p, 2))
        self._timeout_ns = p.timeout_ns
        self._odom = OdomSmoother(p.odom_duration_s) if p.feedback is Feedback.CLOSED_LOOP else None
        self._command: Velocity | None = None
        self._command_ns = 0
        self._last = _ZERO
        self._stopped = True

    def command(self, cmd: Velocity, t_ns: int) -> None:
        """Take a new command (cmd_vel_nav) received at `t_ns`; one with a NaN or infinity is ignored."""
        if not (math.isfinite(cmd[0]) and math.isfinite(cmd[1]) and math.isfinite(cmd[2])):
            return
        self._command = cmd
        self._command_ns = t_ns

    def odometry(self, twist: Velocity, stamp_ns: int) -> None:
        """Take an odometry twist stamped `stamp_ns` (used in CLOSED_LOOP only)."""
        if self._odom is not None:
            self._odom.add(twist, stamp_ns)

    def step(self, t_ns: int) -> Velocity | None:
        """Return the velocity to publish on /cmd_vel at `t_ns`, or None when nothing is published."""
        command = self._command
        if command is None:
            return None
        if t_ns - self._command_ns > self._timeout_ns:
            if self._last == _ZERO or self._stopped:  # == as Nav2's: -0.0 counts as zero
                self._stopped = True
                return None
            command = _ZERO
        self._stopped = False
        current = self._last if self._odom is None else self._odom.twist
        ax, ay, az = self._axes
        command = (ax.clamp(command[0]), ay.clamp(command[1]), az.clamp(command[2]))
        self._command = command  # Nav2 clamps (and zeroes, on a timeout) the command it holds
        eta = 1.0
        if self.params.scale_velocities:
            for axis, cur, cmd in zip(self._axes, current, command, strict=True):
                e = axis.eta(cur, cmd)
                if e > 0.0 and abs(1.0 - e) > abs(1.0 - eta):
                    eta = e
        vx = ax.limit(current[0], command[0], eta)
        vy = ay.limit(current[1], command[1], eta)
        wz = az.limit(current[2], command[2], eta)
        self._last = (vx, vy, wz)
        return (
            0.0 if abs(vx) < ax.deadband else vx,
            0.0 if abs(vy) < ay.deadband else vy,
            0.0 if abs(wz) < az.deadband else wz,
        )


class VelocitySmootherNode(Node):
    """velocity_smoother: `cmd_vel_nav` in (and `odom_topic` in CLOSED_LOOP), `/cmd_vel` out every `period_ns`."""

    def __init__(self, params: SmootherParams) -> None:
        super().__init__("velocity_smoother")
        smoother = VelocitySmoother(params)
        pub = self.create_publisher(TwistEncoder.msgtype, "cmd_vel", 10)
        encode = TwistEncoder().encode_full
        now = self._graph_now

        def on_cmd(msg: Any) -> None:
            if type(msg) is Encoded:
                v, w = msg[2]
                smoother.command((v, 0.0, w), now())
            elif _finite_twist(msg):
                smoother.command((float(msg.linear.x), float(msg.linear.y), float(msg.angular.z)), now())

        def on_odom(msg: Any) -> None:
            if type(msg) is Encoded:
                v, w = msg[2][3:5]
                smoother.odometry((v, 0.0, w), msg[1][0])
            else:
                twist, stamp = msg.twist.twist, msg.header.stamp
                smoother.odometry(
                    (float(twist.linear.x), float(twist.linear.y), float(twist.angular.z)),
                    int(stamp.sec) * _NS_PER_S + int(stamp.nanosec),
                )

        def on_timer(t_ns: int) -> None:
            out = smoother.step(t_ns)
            if out is not None:
                linear, angular = (out[0], out[1], 0.0), (0.0, 0.0, out[2])
                pub.publish(Encoded((encode, (linear, angular), (out[0], out[2]))))

        self.create_subscription("geometry_msgs/msg/Twist", "cmd_vel_nav", on_cmd, 10, raw=True)
        if params.feedback is Feedback.CLOSED_LOOP:
            self.create_subscription("nav_msgs/msg/Odometry", params.odom_topic, on_odom, 10, raw=True)
        self.create_rate_timer(_NS_PER_S / params.period_ns, on_timer, priority=PRIORITY_COMMAND + 1)


def _finite_twist(msg: Any) -> bool:
    """Nav2's validateTwist: a command with a NaN or infinity in any of its six components is dropped."""
    lin, ang = msg.linear, msg.angular
    return all(math.isfinite(float(v)) for v in (lin.x, lin.y, lin.z, ang.x, ang.y, ang.z))
