"""The planar chassis on two driven wheels: pose from wheel speeds, load torques back to the wheels.

No slip by default: the chassis moves as its wheels roll. An optional kinematic slip model scales the
ground speed of the wheels by `1 - slip` (everywhere, or inside rectangles of floor).

Load torques (wheel side, per wheel) for the next step are
- inertial: the chassis mass and yaw inertia seen by the wheels. The two wheels are coupled through
  the chassis (a common mode with m r²/2 per wheel and a differential mode with 2 I r²/b²). Each
  mode's next acceleration is predicted from the drive torque estimated from the last step, with
  the wheels' own inertia `wheel_inertia_kgm2` (J_w): α = d / (J_w + M), τ = M α. This stays
  stable whatever the ratio M / J_w, and is exact for a steady drive torque when J_w is right.
- rolling resistance: c_rr m g / 2 per wheel at the rim, against the wheel's motion (a linear ramp
  through ±5 mm/s instead of a sign).
- contact: the loop's callable says whether a pose would penetrate the world. A step whose pose
  would penetrate is refused: if turning alone is free the chassis only turns (translation blocked),
  else it stays. A blocked mode gets a holding torque (the estimated drive torque plus damping), so
  the wheels stall and, with the voltage held, the current rises to about V/R. The block lifts when
  the drive pushes the other way (and, `FmuDrivetrain` sees to it, when what blocked it has gone).
  A step that leaves the pose where it is, to the last bit (a stopped wheel's speed decays for
  ever, 1e-18 rad/s and less), is never refused and blocks nothing: the direction of such a speed
  is noise, and a block in it would hold the robot against its next command. It needs no check
  either, even at a pose something else moved into.

`Chassis.update` is the reference of the compiled drive loop (`fmus/common/drive_loop.c`), which
does the same arithmetic in C; `coefficients`, `dynamics` and `set_dynamics` hand a chassis to it
and back. A change here must be made there too (the drivetrain tests compare the two).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

__all__ = [
    "Chassis",
    "ChassisCoefficients",
    "ChassisDynamics",
    "ChassisParams",
    "ChassisState",
    "ContactFn",
    "DistanceFn",
    "SlipModel",
    "SlipRegion",
]

ContactFn = Callable[[float, float, float], bool]
"""`(x_m, y_m, yaw_rad) -> bool`: True if the robot at that pose would penetrate the world."""
DistanceFn = Callable[[float, float, float], float]
"""`(x_m, y_m, yaw_rad) -> m`: how far the robot may move from that pose with no contact possible,
counting translation plus |rotation| times its bounding radius (e.g. `CollisionMonitor.free_m`)."""

_ROLL_SPEED_EPS_MPS = 0.005  # rolling resistance reaches full strength above this rim speed
_HOLD_DAMPING = 0.5  # fraction of a blocked mode's speed removed per step


@dataclass(frozen=True, kw_only=True, slots=True)
class ChassisParams:
    """The robot as the drivetrain needs it (the loop maps the robot's SDF onto this)."""

    wheel_radius_m: float
    wheel_separation_m: float
    mass_kg: float
    yaw_inertia_kgm2: float
    rolling_resistance: float = 0.01  # coefficient c_rr
    gravity_mps2: float = 9.81

    def __post_init__(self) -> None:
        for name in ("wheel_radius_m", "wheel_separation_m", "mass_kg", "yaw_inertia_kgm2"):
            if not getattr(self, name) > 0.0:
                msg = f"{name} must be positive, got {getattr(self, name)}"
                raise ValueError(msg)
        if self.rolling_resistance < 0.0:
            msg = f"rolling_resistance must not be negative, got {self.rolling_resistance}"
            raise ValueError(msg)

    @classmethod
    def tb3_waffle(cls) -> ChassisParams:
        """TurtleBot3 Waffle: r 0.033 m, b 0.287 m, 1.8 kg, base izz from the URDF."""
        return cls(wheel_radius_m=0.033, wheel_separation_m=0.287, mass_kg=1.8, yaw_inertia_kgm2=0.0146)

    @classmethod
    def tb3_burger(cls) -> ChassisParams:
        """TurtleBot3 Burger: r 0.033 m, b 0.160 m, 1.0 kg, base izz from the URDF."""
        return cls(wheel_radius_m=0.033, wheel_separation_m=0.160, mass_kg=1.0, yaw_inertia_kgm2=0.0020)


@dataclass(frozen=True, kw_only=True, slots=True)
class SlipRegion:
    """A rectangle of floor (world frame) where the wheels slip by `slip` (0 to 1)."""

    x_min_m: float
    x_max_m: float
    y_min_m: float
    y_max_m: float
    slip: float

    def __post_init__(self) -> None:
        if not 0.0 <= self.slip < 1.0:
            msg = f"slip must be in [0, 1), got {self.slip}"
            raise ValueError(msg)


@dataclass(frozen=True, kw_only=True, slots=True)
class SlipModel:
    """Kinematic slip: the ground moves at (1 - slip) of the wheels' rim speed."""

    slip: float = 0.0  # everywhere outside the regions
    regions: tuple[SlipRegion, ...] = ()

    def __post_init__(self) -> None:
        if not 0.0 <= self.slip < 1.0:
            msg = f"slip must be in [0, 1), got {self.slip}"
            raise ValueError(msg)

    def at(self, x_m: float, y_m: float) -> float:
        """The slip at a point (the first region containing it wins)."""
        for region in self.regions:
            if region.x_min_m <= x_m <= region.x_max_m and region.y_min_m <= y_m <= region.y_max_m:
                return region.slip
        return self.slip


class ChassisState(NamedTuple):
    """The chassis at one instant (world frame pose, body-frame rates and accelerations)."""

    x_m: float
    y_m: float
    yaw_rad: float
    v_mps: float  # forward speed
    yaw_rate_radps: float
    ax_mps2: float  # longitudinal acceleration
    ay_mps2: float  # lateral (centripetal) acceleration
    yaw_accel_radps2: float
    blocked: bool  # a contact refused some motion in the last step


class ChassisDynamics(NamedTuple):
    """Everything `Chassis.update` carries from one step to the next.

    It hands the chassis to a compiled loop and back (`twin.cosim.drive_loop`).
    """

    x_m: float
    y_m: float
    yaw_rad: float
    v_mps: float
    yaw_rate_radps: float
    ax_mps2: float
    ay_mps2: float
    yaw_accel_radps2: float
    block_common: float  # sign of the blocked forward motion, 0 when free
    block_diff: float
    w_left_prev_radps: float  # the wheel speeds of the last step
    w_right_prev_radps: float
    wheel_angle_left_rad: float
    wheel_angle_right_rad: float
    load_left_nm: float
    load_right_nm: float
    blocked: bool


# The Chassis attribute behind each field of ChassisDynamics, in order (the others are public).
_PRIVATE = {
    "block_common": "_block_common",
    "block_diff": "_block_diff",
    "w_left_prev_radps": "_wl",
    "w_right_prev_radps": "_wr",
}
_DYNAMIC_ATTRIBUTES = tuple(_PRIVATE.get(name, name) for name in ChassisDynamics._fields)


class ChassisCoefficients(NamedTuple):
    """The numbers `Chassis.update` works with, derived once from the parameters (see `Chassis`)."""

    step_s: float
    half_r: float  # r / 2, m
    r_over_b: float
    m_common: float  # per-wheel chassis inertia of the common mode, kg m²
    m_diff: float  # and of the differential mode
    j: float  # the drive's own inertia at the wheel, kg m²
    j_over_h: float
    k_common: float  # share of a mode's drive torque the chassis takes, without slip
    k_diff: float
    roll_nm: float  # rolling resistance torque at the wheel
    roll_gain: float  # its ramp gain per rad/s of wheel speed
    hold_damping: float  # fraction of a blocked mode's speed removed per step


class Chassis:
    """Planar chassis integrated at a fixed step from the wheel speeds."""

    def __init__(
        self,
        params: ChassisParams,
        *,
        step_s: float,
        wheel_inertia_kgm2: float,
        pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
        contact: ContactFn | None = None,
        slip: SlipModel | None = None,
    ) -> None:
        """Set up at rest at `pose` (x_m, y_m, yaw_rad).

        Args:
            params: Robot numbers.
            step_s: Fixed step, s.
            wheel_inertia_kgm2: Each wheel drive's own inertia at the wheel (rotor reflected + wheel).
            pose: Initial pose in the world.
            contact: `(x_m, y_m, yaw_rad) -> bool`, True if that pose would penetrate the world.
            slip: Optional slip model.
        """
        self.params = params
        self._h = step_s
        r, b, m = params.wheel_radius_m, params.wheel_separation_m, params.mass_kg
        self._r = r
        self._half_r = r / 2.0
        self._r_over_b = r / b
        self._m_common = m * r * r / 2.0  # per wheel, common (forward) mode
        self._m_diff = 2.0 * params.yaw_inertia_kgm2 * r * r / (b * b)  # per wheel, differential mode
        self._j = max(wheel_inertia_kgm2, 1e-12)
        self._j_over_h = self._j / step_s
        # Share of a mode's drive torque the chassis takes: M / (J + M) (see the module docstring).
        self._k_common = self._m_common / (self._j + self._m_common)
        self._k_diff = self._m_diff / (self._j + self._m_diff)
        self._roll_nm = params.rolling_resistance * m * params.gravity_mps2 / 2.0 * r
        self._roll_gain = r / _ROLL_SPEED_EPS_MPS
        self._contact = contact
        self._slip = slip if slip is not None and (slip.slip > 0.0 or slip.regions) else None
        self.x_m, self.y_m, self.yaw_rad = pose
        self.v_mps = self.yaw_rate_radps = 0.0
        self.ax_mps2 = self.ay_mps2 = self.yaw_accel_radps2 = 0.0
        self.blocked = False
        self._block_common = 0.0  # sign of the blocked forward motion, 0 when free
        self._block_diff = 0.0
        self._wl = self._wr = 0.0
        self.wheel_angle_left_rad = self.wheel_angle_right_rad = 0.0  # integrated wheel speeds
        self.load_left_nm = self.load_right_nm = 0.0

    def state(self) -> ChassisState:
        """The chassis now."""
        return ChassisState(
            self.x_m,
            self.y_m,
            self.yaw_rad,
            self.v_mps,
            self.yaw_rate_radps,
            self.ax_mps2,
            self.ay_mps2,
            self.yaw_accel_radps2,
            self.blocked,
        )

    @property
    def slip(self) -> SlipModel | None:
        """The slip model, None when nothing slips anywhere."""
        return self._slip

    def coefficients(self) -> ChassisCoefficients:
        """The derived numbers `update` works with."""
        return ChassisCoefficients(
            step_s=self._h,
            half_r=self._half_r,
            r_over_b=self._r_over_b,
            m_common=self._m_common,
            m_diff=self._m_diff,
            j=self._j,
            j_over_h=self._j_over_h,
            k_common=self._k_common,
            k_diff=self._k_diff,
            roll_nm=self._roll_nm,
            roll_gain=self._roll_gain,
            hold_damping=_HOLD_DAMPING,
        )

    def dynamics(self) -> ChassisDynamics:
        """The whole state carried between steps."""
        return ChassisDynamics._make(getattr(self, name) for name in _DYNAMIC_ATTRIBUTES)

    def set_dynamics(self, state: ChassisDynamics) -> None:
        """Continue from `state` (as `dynamics` returned it, or a compiled loop advanced it)."""
        for name, value in zip(_DYNAMIC_ATTRIBUTES, state, strict=True):
            setattr(self, name, value)

    def update(self, w_left: float, w_right: float) -> None:
        """Advance one step with the wheels at these speeds (rad/s); set the next load torques."""
        h = self._h
        self.wheel_angle_left_rad += w_left * h
        self.wheel_angle_right_rad += w_right * h
        if self._slip is None:
            scale = 1.0
            k_common, k_diff = self._k_common, self._k_diff
        else:
            scale = 1.0 - self._slip.at(self.x_m, self.y_m)
            m_common, m_diff = self._m_common * scale * scale, self._m_diff * scale * scale
            k_common, k_diff = m_common / (self._j + m_common), m_diff / (self._j + m_diff)
        v = 0.0 if self._block_common else scale * self._half_r * (w_left + w_right)
        w = 0.0 if self._block_diff else scale * self._r_over_b * (w_right - w_left)
        x, y, yaw = self.x_m, self.y_m, self.yaw_rad
        vh = v * h
        mid = yaw + 0.5 * w * h
        nx, ny, nyaw = x + vh * math.cos(mid), y + vh * math.sin(mid), yaw + w * h
        # Whether the step moves the pose at all: a speed too small to change a coordinate by one
        # float step (a stopped wheel's last 1e-18 rad/s) moves nothing, so nothing can refuse it.
        drives, turns = nx != x or ny != y, nyaw != yaw
        blocked = False
        contact = self._contact
        if contact is not None and (drives or turns) and contact(nx, ny, nyaw):
            blocked = True
            if drives and (not turns or contact(x, y, nyaw)):
                self._block_common = 1.0 if v > 0.0 else -1.0
                v = 0.0
            if turns and contact(x, y, nyaw):
                self._block_diff = 1.0 if w > 0.0 else -1.0
                w = 0.0
            if v and w and drives and turns:  # moving and turning together collide, each alone does not: stop moving
                self._block_common = 1.0 if v > 0.0 else -1.0
                v = 0.0
            mid = yaw + 0.5 * w * h
            nx, ny, nyaw = x + v * h * math.cos(mid), y + v * h * math.sin(mid), yaw + w * h
        self.x_m, self.y_m, self.yaw_rad = nx, ny, nyaw
        self.ax_mps2 = (v - self.v_mps) / h
        self.yaw_accel_radps2 = (w - self.yaw_rate_radps) / h
        self.ay_mps2 = v * w
        self.v_mps, self.yaw_rate_radps = v, w

        # Load torques for the next step. Drive torque of each wheel, estimated from its
        # acceleration over the last step: J dω/dt = drive - load.
        j_h = self._j_over_h
        d_left = j_h * (w_left - self._wl) + self.load_left_nm
        d_right = j_h * (w_right - self._wr) + self.load_right_nm
        self._wl, self._wr = w_left, w_right
        # Rolling resistance against the rim speed (a ramp through zero instead of a sign).
        roll, gain = self._roll_nm, self._roll_gain
        a = w_left * gain
        ext_left = roll * (1.0 if a > 1.0 else (-1.0 if a < -1.0 else a))
        a = w_right * gain
        ext_right = roll * (1.0 if a > 1.0 else (-1.0 if a < -1.0 else a))
        d_common = 0.5 * (d_left + d_right - ext_left - ext_right)
        d_diff = 0.5 * (d_right - d_left - ext_right + ext_left)
        block = self._block_common
        if block and d_common * block < 0.0:  # the drive pulls away from the obstacle
            block = self._block_common = 0.0
        t_common = d_common + _HOLD_DAMPING * j_h * 0.5 * (w_left + w_right) if block else k_common * d_common
        block = self._block_diff
        if block and d_diff * block < 0.0:
            block = self._block_diff = 0.0
        t_diff = d_diff + _HOLD_DAMPING * j_h * 0.5 * (w_right - w_left) if block else k_diff * d_diff
        self.load_left_nm = t_common - t_diff + ext_left
        self.load_right_nm = t_common + t_diff + ext_right
        self.blocked = blocked or bool(self._block_common or self._block_diff)
