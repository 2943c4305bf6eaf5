"""The FMU drivetrain: one FMU instance per wheel and the chassis, stepped at a fixed step.

`FmuDrivetrain` runs one FMU instance per wheel (left, right) through the drive contract
(`twin.cosim.contract`, bound by `twin.robot.fmu_drive.plan_fmu_drive`): inverse kinematics with
optional firmware clamps (`wheel_setpoints`), then either the twin's wheel-speed PI (profile
`voltage`, gains designed by `twin.robot.drive_control`) or the FMU's own loop (profile
`velocity-servo`), one doStep per wheel per step, and the chassis (`twin.robot.chassis`) turning
wheel speeds into motion and giving each wheel its load torque.

Two implementations of that per-step path give the same numbers: the Python one here (the
reference, `api: lowlevel` or `convenience`) and the compiled one (`api: native`, the default,
`twin.cosim.drive_loop`), which runs a whole batch of steps in one C call. Contact stays in Python:
the compiled loop runs while the robot's motion stays inside the distance the world reports free
(`free_distance`), and the steps near the world run on the Python path with the contact check
each step. A step that leaves the pose where it is, to the last bit, needs no check on either path
(`Chassis.update`): a robot pressed against something often creeps so, below the pose's float
resolution, in the mode its contact does not block, and a stopped wheel's speed decays for ever.
"""

from __future__ import annotations

import ctypes
import dataclasses
import logging
import math
import struct
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from twin.core.closing import Closing
from twin.core.errors import FmuError
from twin.cosim.adapter import Api, Stepper
from twin.cosim.build import resolve_fmu
from twin.cosim.contract import Binding, Profile
from twin.cosim.description import FmuInfo
from twin.cosim.drive_loop import MAX_RUN, DriveLoop
from twin.cosim.fmu import FmuFile
from twin.cosim.isolated import IsolatedGroup
from twin.cosim.step_group import StepGroup
from twin.robot.chassis import Chassis, ChassisDynamics, ChassisParams, ChassisState, ContactFn, DistanceFn
from twin.robot.drive_control import MotorConstants, SpeedLoop
from twin.robot.drivetrain import WheelState
from twin.robot.fmu_drive import CommandLimits, DrivePlan, FmuDrive, builtin_motor, communication_step, plan_fmu_drive

__all__ = ["FmuDrivetrain", "Saturation", "wheel_setpoints"]

_log = logging.getLogger(__name__)

# A blocked mode is probed this far in its direction (rotation: this far at the robot's bounding
# radius); free there, what blocked it has gone and the block lifts, m. More than a refused step
# leaves between the robot and what refused it (0.26 m/s x 1 ms).
_BLOCK_PROBE_M = 2e-3
# ... at the first advance after each multiple of this much drive time, s: a pressed robot's probe
# is an FCL query when the robot it touches has moved, and its block lifts within this of the way
# clearing, which the controller (20 Hz) does not notice.
_BLOCK_PROBE_S = 0.05


def _fixed(value: float, decimals: int) -> str:
    """`value` with `decimals` places, or in 4 significant digits when that would be a wall of digits (1e300)."""
    return f"{value:.{decimals}f}" if abs(value) < 1e6 else f"{value:.4g}"


def wheel_setpoints(v_mps: float, w_radps: float, chassis: ChassisParams, limits: CommandLimits) -> tuple[float, float]:
    """Inverse kinematics with the firmware's clamps: body command → (left, right) wheel speeds, rad/s."""
    if limits.max_linear_mps is not None:
        v_mps = max(-limits.max_linear_mps, min(limits.max_linear_mps, v_mps))
    if limits.max_angular_radps is not None:
        w_radps = max(-limits.max_angular_radps, min(limits.max_angular_radps, w_radps))
    half = w_radps * chassis.wheel_separation_m / 2.0
    left = (v_mps - half) / chassis.wheel_radius_m
    right = (v_mps + half) / chassis.wheel_radius_m
    if not (math.isfinite(left) and math.isfinite(right)):
        # A finite command too large for the arithmetic (1e308 m/s overflows to inf, and a cap's scale
        # then makes NaN of it, which drove the wheels backwards): the same curvature at 1e12 rad/s, far
        # beyond any motor, so the caps below and the supply's reach scale it as any other
        size = max(abs(v_mps), abs(w_radps))
        left, right = wheel_setpoints(v_mps / size, w_radps / size, chassis, CommandLimits())
        peak = max(abs(left), abs(right))
        left, right = left / peak * 1e12, right / peak * 1e12
    if limits.max_wheel_speed_radps is not None:
        cap = limits.max_wheel_speed_radps
        left, right = max(-cap, min(cap, left)), max(-cap, min(cap, right))
    return left, right


@dataclass(kw_only=True, slots=True)
class Saturation:
    """Commands beyond the motor's reach at the supply voltage, as the drive clamped them (a run's tally)."""

    cap_radps: float | None  # the wheel speed the motor reaches at the supply voltage (None: unknown)
    supply_v: float
    count: int = 0  # commands clamped
    first_t_s: float | None = None  # sim time of the first
    max_requested_radps: float = 0.0  # the largest wheel speed asked for
    active: bool = False  # the current command is clamped

    def describe(self) -> str:
        """One phrase for a run's summary ('' when nothing was clamped)."""
        if not self.count or self.cap_radps is None:
            return ""
        return (
            f"{self.count} cmd_vel clamped to the motors' {self.cap_radps:.2f} rad/s at {self.supply_v:g} V "
            f"(first at {self.first_t_s:.2f} s, asked up to {_fixed(self.max_requested_radps, 2)} rad/s)"
        )


_OUTPUT_ORDER = ("wheel_speed", "wheel_angle", "current", "motor_torque", "applied_voltage")
# The wheels' state in the compiled loop (`FmuDrivetrain` keeps each as `_<name>`).
_WHEEL_STATE = (
    "target_left",
    "target_right",
    "ref_left",
    "ref_right",
    "w_left",
    "w_right",
    "int_left",
    "int_right",
    "volt_left",
    "volt_right",
)
_WHEELS = len(_WHEEL_STATE)
_WHEEL_ATTRIBUTES = tuple(f"_{name}" for name in _WHEEL_STATE)
# The wheels' state and then the chassis' (`ChassisDynamics`) follow each other in the loop's structure.
_STATE_SPAN = DriveLoop.span(_WHEEL_STATE + ChassisDynamics._fields)
_STATE_AT = DriveLoop.offset(_WHEEL_STATE[0])


class FmuDrivetrain(Closing):
    """Two FMU wheel drives and the chassis, stepped at a fixed step (a context manager)."""

    def __init__(
        self,
        drive: FmuDrive,
        chassis: ChassisParams,
        *,
        step_ns: int,
        pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
        contact: ContactFn | None = None,
        free_distance: DistanceFn | None = None,
        probe: Callable[[float, float, float], object] | None = None,
        bounding_radius_m: float = 0.0,
        plugin_wheel_acceleration_mps2: float | None = None,
        robot_name: str = "",
        log_name: str = "fmu",
    ) -> None:
        """Build (on first use), load and bind the FMU, design the speed loop, instantiate both wheels.

        Args:
            drive: The scenario's drive section.
            chassis: Robot numbers (from the robot's SDF).
            step_ns: The loop's physics step, ns.
            pose: Initial pose (x_m, y_m, yaw_rad).
            contact: `(x_m, y_m, yaw_rad) -> bool`, True if that pose would penetrate the world.
            free_distance: `(x_m, y_m, yaw_rad) -> m` the robot may move from there with no
                contact possible (e.g. `CollisionMonitor.free_m`). With `contact` and without it,
                every moving step checks contact on the Python path.
            probe: `(x_m, y_m, yaw_rad) -> truthy` when that pose would penetrate the world, with no
                side effect (the contact monitor's own check; default `contact`). Every 50 ms of
                drive time a blocked mode is probed 2 mm further in its direction and lifts when
                that is free: a robot pushing against another one that leaves follows it.
            bounding_radius_m: The radius `free_distance` counts rotation with (the farthest point
                of the robot's collision shape from its base frame).
            plugin_wheel_acceleration_mps2: The robot SDF diff-drive plugin's `max_wheel_acceleration`
                (rim, m/s²), used when `drive.max_wheel_acceleration_mps2` is null; None or 0: none.
            robot_name: The robot model's name, for `fmu: auto`.
            log_name: Where the FMU instances' own log messages go (`twin.cosim.adapter.fmu_logger`):
                `robot1.fmu` in a fleet, so their lines name the robot.

        Raises:
            FmuError: If the FMU cannot be built, loaded, bound to the profile or initialised.
            ConfigError: If the mapping file, motor model or speed-loop targets are wrong.
            ValueError: If `bounding_radius_m` is negative.
        """
        self.step_ns = step_ns
        if drive.fmu == "auto":
            drive = dataclasses.replace(drive, fmu=builtin_motor(robot_name, drive.profile))
        if bounding_radius_m < 0.0:
            msg = f"bounding_radius_m must not be negative, got {bounding_radius_m}"
            raise ValueError(msg)
        self._contact = contact
        self._free = free_distance
        self._touching = probe if probe is not None else contact
        self._next_probe = 0  # the communication step from which a blocked mode is probed again
        self._reach_m = bounding_radius_m
        comm_s, self._ratio = communication_step(drive, step_ns)
        self._pending = 0
        self._h = comm_s
        self._probe_period = max(1, round(_BLOCK_PROBE_S / comm_s))  # communication steps between probes
        accel = drive.max_wheel_acceleration_mps2
        if accel is None:
            accel = plugin_wheel_acceleration_mps2
        self.max_wheel_acceleration_mps2 = accel if accel else math.inf
        self._ramp_radps = self.max_wheel_acceleration_mps2 / chassis.wheel_radius_m * comm_s
        self.drive = drive
        self.params = chassis
        self.profile = Profile(drive.profile)
        path = resolve_fmu(drive.fmu_file or drive.fmu, fmi_version=drive.fmi_version)
        self._file = FmuFile(path)
        name = drive.fmu.removeprefix("builtin:") if drive.fmu_file is None else path.name
        self._fmu_name = name
        self.label = f"fmu {name} (FMI {self._file.info.major_version}, {drive.profile})"
        self._isolated: IsolatedGroup | None = None
        self._log_name = log_name
        try:
            self._setup(drive, chassis, pose, contact, plan_fmu_drive(drive, self._file.info, step_ns=step_ns))
        except BaseException:
            self.close()
            raise

    def _setup(
        self,
        drive: FmuDrive,
        chassis: ChassisParams,
        pose: tuple[float, float, float],
        contact: ContactFn | None,
        plan: DrivePlan,
    ) -> None:
        binding = plan.binding
        self.binding = binding
        self.motor: MotorConstants | None = plan.motor
        self.speed_loop: SpeedLoop | None = plan.speed_loop
        if self.speed_loop is not None:
            _log.info("speed loop: %s", self.speed_loop)
        outputs = [binding.outputs[r] for r in _OUTPUT_ORDER if r in binding.outputs]
        # Per optional output role: (index in the outputs, factor, offset) to twin units, or None.
        self._reading = {
            role: next(((k, b.factor, b.offset) for k, b in enumerate(outputs) if b.role == role), None)
            for role in _OUTPUT_ORDER[1:]
        }
        # Without a motor_torque output, the effort is the current times the torque constant at the wheel
        # (N Kt) when the FMU gives the current and the motor model is known; else there is none.
        self._torque_per_amp: float | None = None
        if self._reading["motor_torque"] is None and self._reading["current"] is not None and self.motor is not None:
            self._torque_per_amp = self.motor.gear_ratio * self.motor.torque_constant_nm_per_a
        in_vrs = [b.value_reference for b in binding.inputs]
        out_vrs = [b.value_reference for b in outputs]
        wheel_inertia = drive.wheel_inertia_kgm2
        if wheel_inertia is None:
            wheel_inertia = self.motor.wheel_inertia_kgm2 if self.motor is not None else self._probe(binding)
        self.wheel_inertia_kgm2 = wheel_inertia
        api: Api = "lowlevel" if drive.api == "native" else drive.api
        self._group: StepGroup | IsolatedGroup
        self._left: Stepper
        self._right: Stepper
        if drive.isolation == "process":
            self._isolated = self._group = IsolatedGroup(
                self._file.path,
                self._file.label,
                ("left", "right"),
                step_s=self._h,
                inputs=in_vrs,
                outputs=out_vrs,
                start=binding.start,
                timeout_s=drive.step_timeout_s,
                process_per_instance=self._file.info.instantiated_once,
                log_name=self._log_name,
            )
            self._left, self._right = self._isolated.steppers
        else:
            self._left, self._right = (
                self._file.instantiate(
                    side,
                    step_s=self._h,
                    inputs=in_vrs,
                    outputs=out_vrs,
                    start=binding.start,
                    api=api,
                    log_name=self._log_name,
                )
                for side in ("left", "right")
            )
            self._group = StepGroup((self._left, self._right), step_s=self._h)
        self._chassis = Chassis(
            chassis, step_s=self._h, wheel_inertia_kgm2=wheel_inertia, pose=pose, contact=contact, slip=drive.slip
        )
        cmd, load = binding.inputs
        self._cmd_scale, self._cmd_offset = 1.0 / cmd.factor, cmd.offset
        self._load_scale, self._load_offset = 1.0 / load.factor, load.offset
        speed = binding.outputs["wheel_speed"]
        self._speed_factor, self._speed_offset = speed.factor, speed.offset
        self._target_left = self._target_right = 0.0
        self._ref_left = self._ref_right = 0.0
        self._int_left = self._int_right = 0.0
        self.supply_speed_radps = self._supply_speed(drive)
        self.saturation = Saturation(cap_radps=self.supply_speed_radps, supply_v=drive.speed_loop.voltage_limit_v)
        self.log = _log
        """Where its run-time lines go: its drive node's logger (`[robot1.diff_drive]` in a fleet)."""
        self.command_radps = (0.0, 0.0)  # the last command's wheel speeds, before the supply clamp
        self._volt_left = self._volt_right = 0.0
        self._w_left = self._speed(self._left)
        self._w_right = self._speed(self._right)
        self._kp = self._ki = self._v_max = 0.0
        if self.speed_loop is not None:
            self._kp = self.speed_loop.kp_v_per_radps
            self._ki = self.speed_loop.ki_v_per_rad
            self._v_max = drive.speed_loop.voltage_limit_v
            self._run_python = self._run_voltage
        else:
            self._run_python = self._run_servo
        self._run = self._run_python
        self._loop: DriveLoop | None = None
        if drive.api == "native" and isinstance(self._group, StepGroup):
            try:
                self._loop = self._native_loop()
            except FmuError as err:
                _log.warning("running the drivetrain's step loop in Python: %s", err)
            else:
                self._run = self._run_native
                self._bind_native()

    def _native_loop(self) -> DriveLoop:
        """Set up the compiled loop with this drive's numbers and state."""
        slip = self._chassis.slip
        regions = None
        if slip is not None:
            regions = [(r.x_min_m, r.x_max_m, r.y_min_m, r.y_max_m, r.slip) for r in slip.regions]
        assert isinstance(self._group, StepGroup)
        loop = DriveLoop(self._group, slip_regions=regions)
        loop.write(
            servo=self.speed_loop is None,
            kp=self._kp,
            ki=self._ki,
            v_max=self._v_max,
            cmd_scale=self._cmd_scale,
            cmd_offset=self._cmd_offset,
            load_scale=self._load_scale,
            load_offset=self._load_offset,
            speed_scale=self._speed_factor,
            speed_offset=self._speed_offset,
            slip=slip.slip if slip is not None else 0.0,
            reach_m=self._reach_m,
            ramp_radps=self._ramp_radps,
            **self._chassis.coefficients()._asdict(),
        )
        self._loop = loop
        self._to_native()
        return loop

    def _bind_native(self) -> None:
        """Give `advance`, `chassis_state` and `wheel_state` their compiled-loop forms, one closure each.

        Each does its method's arithmetic, reading several fields of the loop's structure (and the
        FMUs' outputs) per `struct` call. The executor calls them for every event (hundreds a
        simulated second); the methods stay the reference and the path without the compiled loop.
        """
        loop = self._loop
        assert loop is not None
        state, step, raise_failure = loop.state, loop.step, loop.raise_failure
        contact, free, near_world, ratio, inf = self._contact, self._free, self._near_world, self._ratio, math.inf
        release_blocks = self._release_blocks

        def advance(n_steps: int) -> None:
            count = n_steps
            if ratio != 1:
                pending = self._pending + n_steps
                count = pending // ratio
                self._pending = pending - count * ratio
            if count and (state.block_common or state.block_diff):
                release_blocks()
            while count:
                if contact is None:
                    budget = inf
                else:
                    budget = free(state.x_m, state.y_m, state.yaw_rad) if free is not None else 0.0
                state.budget_m = budget
                done: int = step(count if count < MAX_RUN else MAX_RUN)
                if done < count and state.failed >= 0:
                    raise_failure()
                count -= done
                if state.stopped_on_budget:
                    count = near_world(count)

        buffer, new = loop.buffer, tuple.__new__
        # ChassisState's eight numbers are consecutive doubles of the structure, `blocked` its last field.
        at = loop.offset("x_m")
        blocked_at = loop.offset("blocked")
        unpack_chassis = struct.Struct(f"<8d{blocked_at - at - 64}x?").unpack_from

        def chassis_state() -> ChassisState:
            state: ChassisState = new(ChassisState, unpack_chassis(buffer, at))
            return state

        unpack_pose = struct.Struct("<3d").unpack_from

        def pose() -> tuple[float, float, float]:
            xy_yaw: tuple[float, float, float] = unpack_pose(buffer, at)
            return xy_yaw

        self.advance = advance  # type: ignore[method-assign]
        self.chassis_state = chassis_state  # type: ignore[method-assign]
        self.pose = pose  # type: ignore[method-assign]
        self.wheel_state = self._native_wheel_state()  # type: ignore[method-assign]

    def _native_wheel_state(self) -> Callable[[], WheelState]:
        """`wheel_state` with the compiled loop: the FMUs' outputs and the loop's wheel fields read at once."""
        loop = self._loop
        assert loop is not None
        buffer, new, nan = loop.buffer, tuple.__new__, math.nan
        wheels_at = loop.offset("w_left")  # w, int, volt: (left, right) each
        unpack_wheels = struct.Struct("<6d").unpack_from
        angles_at = loop.offset("wheel_angle_left_rad")
        unpack_pair = struct.Struct("<2d").unpack_from
        n = len(self._left.outputs)
        unpack_outputs = struct.Struct(f"<{n}d").unpack_from
        left, right = memoryview(self._left.outputs).cast("B"), memoryview(self._right.outputs).cast("B")
        voltage_profile = self.profile is Profile.VOLTAGE
        nans = (nan, nan)
        angle, current, torque, volts = (
            self._reading[role] for role in ("wheel_angle", "current", "motor_torque", "applied_voltage")
        )
        per_amp = self._torque_per_amp if torque is None else None

        def wheel_state() -> WheelState:
            lo, ro = unpack_outputs(left), unpack_outputs(right)
            w_left, w_right, _, _, v_left, v_right = unpack_wheels(buffer, wheels_at)
            if angle is None:
                angles = unpack_pair(buffer, angles_at)
            else:
                k, factor, offset = angle
                angles = (factor * lo[k] + offset, factor * ro[k] + offset)
            if current is None:
                amps = nans
            else:
                k, factor, offset = current
                amps = (factor * lo[k] + offset, factor * ro[k] + offset)
            if torque is not None:
                k, factor, offset = torque
                effort = (factor * lo[k] + offset, factor * ro[k] + offset)
            elif per_amp is not None:
                effort = (per_amp * amps[0], per_amp * amps[1])
            else:
                effort = nans
            if volts is not None:
                k, factor, offset = volts
                voltage = (factor * lo[k] + offset, factor * ro[k] + offset)
            else:
                voltage = (v_left, v_right) if voltage_profile else nans
            ws: WheelState = new(WheelState, (angles, (w_left, w_right), effort, voltage, amps))
            return ws

        return wheel_state

    def _to_native(self) -> None:
        """Hand the wheels' and the chassis' state to the compiled loop (one `struct` call)."""
        assert self._loop is not None
        wheels = (getattr(self, name) for name in _WHEEL_ATTRIBUTES)
        _STATE_SPAN.pack_into(self._loop.buffer, _STATE_AT, *wheels, *self._chassis.dynamics())

    def _to_python(self) -> None:
        """Take the wheels' and the chassis' state back from the compiled loop (one `struct` call)."""
        assert self._loop is not None
        values = _STATE_SPAN.unpack_from(self._loop.buffer, _STATE_AT)
        for name, value in zip(_WHEEL_ATTRIBUTES, values[:_WHEELS], strict=True):
            setattr(self, name, value)
        self._chassis.set_dynamics(ChassisDynamics._make(values[_WHEELS:]))

    def _probe(self, binding: Binding) -> float:
        """Estimate the drive's inertia at the wheel from one step under a small load torque."""
        in_vrs = [b.value_reference for b in binding.inputs]
        speed = binding.outputs["wheel_speed"]
        probe_nm, h = 0.01, self._h
        stepper = self._file.instantiate(
            "probe",
            step_s=h,
            inputs=in_vrs,
            outputs=[speed.value_reference],
            start=binding.start,
            purpose=(
                "a third instance the twin steps once before the run, under a small load torque, to estimate "
                "the drive's inertia at the wheel; drive.wheel_inertia_kgm2 or drive.motor skips it"
            ),
            log_name=self._log_name,
        )
        try:
            cmd, load = binding.inputs
            stepper.inputs[0] = (0.0 - cmd.offset) / cmd.factor
            stepper.inputs[1] = (probe_nm - load.offset) / load.factor
            w0 = speed.factor * stepper.outputs[0] + speed.offset
            stepper.step(0.0)
            change = speed.factor * stepper.outputs[0] + speed.offset - w0
        finally:
            stepper.close()
        dw = abs(change)
        inertia = probe_nm * h / dw if dw > 0.0 else 1.0
        if change > 0.0:  # a load torque slows a wheel at rest (an ideal servo's does not move: fine)
            _log.warning(
                "%s: a load torque of %g N m on %r sped up %r in one step: the mapping's load_torque or "
                "wheel_speed names the wrong variable or sign (the wheels would speed up against an obstacle); "
                "the drive's inertia at the wheel is taken as %.3g kg m^2 (drive.wheel_inertia_kgm2 gives it)",
                self._file.label,
                probe_nm,
                load.name,
                speed.name,
                inertia,
            )
        else:
            _log.info("probed drive inertia at the wheel: %.3g kg m^2", inertia)
        return inertia

    def _speed(self, stepper: Stepper) -> float:
        return self._speed_factor * stepper.outputs[0] + self._speed_offset

    @property
    def native(self) -> bool:
        """Whether the compiled loop runs the steps (`api: native` and the shim built)."""
        return self._loop is not None

    @property
    def chassis_address(self) -> int | None:
        """Address of the chassis in the compiled loop's structure (None without it), for compiled readers.

        Eight doubles, as `chassis_state` returns them: x, y, yaw, v, yaw rate, ax, ay, yaw
        acceleration. They hold the chassis between `advance` calls, as long as the drive is open.
        """
        if self._loop is None:
            return None
        return ctypes.addressof(self._loop.state) + self._loop.offset("x_m")

    # --- the Drivetrain protocol ---

    @property
    def t_ns(self) -> int:
        """Time of the last communication point, ns."""
        return round(self._group.index * self._h * 1e9)

    def set_cmd_vel(self, v_mps: float, w_radps: float) -> None:
        """Take a body velocity command: the velocity limits, then the motor's reach at the supply voltage.

        The wheels' setpoints then follow the result under the acceleration limit, step by step.
        A command beyond what the motor can reach is scaled down (both wheels alike, so the path's
        curvature stays) and counted in `saturation`; the first one is logged as a warning.
        """
        left, right = wheel_setpoints(v_mps, w_radps, self.params, self.drive.limits)
        self.command_radps = (left, right)
        cap = self.supply_speed_radps
        if cap is not None and self.drive.clamp_to_supply:
            peak = max(abs(left), abs(right))
            if peak > cap:
                scale = cap / peak
                left, right = left * scale, right * scale
                self._report_saturation(v_mps, w_radps, peak)
            else:
                self.saturation.active = False
        self._target_left, self._target_right = left, right
        if self._loop is not None:
            self._loop.state.target_left = left
            self._loop.state.target_right = right

    def _report_saturation(self, v_mps: float, w_radps: float, peak_radps: float) -> None:
        sat = self.saturation
        sat.active = True
        sat.count += 1
        sat.max_requested_radps = max(sat.max_requested_radps, peak_radps)
        if sat.count == 1:
            sat.first_t_s = self.t_ns * 1e-9
            self.log.warning(
                "drive: cmd_vel (%s m/s, %s rad/s) at t = %.3f s asks %s rad/s of a wheel, but %s reaches "
                "%.2f rad/s (%.3f m/s) at %g V: clamped to that (reported once per run; /motor_state marks "
                "every clamped command)",
                _fixed(v_mps, 3),
                _fixed(w_radps, 3),
                sat.first_t_s,
                _fixed(peak_radps, 2),
                self._fmu_name,
                sat.cap_radps or 0.0,
                (sat.cap_radps or 0.0) * self.params.wheel_radius_m,
                sat.supply_v,
            )

    def _supply_speed(self, drive: FmuDrive) -> float | None:
        """The wheel speed the motor reaches at the supply voltage against rolling resistance (None: unknown)."""
        m = self.motor
        if m is None:
            return None
        n, kt, ke, r = m.gear_ratio, m.torque_constant_nm_per_a, m.back_emf_vs_per_rad, m.resistance_ohm
        volts = drive.speed_loop.voltage_limit_v
        rolling_nm = self._chassis.coefficients().roll_nm
        return (n * kt * volts - r * rolling_nm) / (r * m.wheel_friction_nms_per_rad + n * n * kt * ke)

    def advance(self, n_steps: int) -> None:
        """Run `n_steps` physics steps (one FMU step per wheel each `communication_step_s`).

        Raises:
            FmuError: If an FMU fails; names the FMU, instance, sim time and status.
        """
        self._pending += n_steps
        count = self._pending // self._ratio
        self._pending -= count * self._ratio
        if count:
            self._release_blocks()
            self._run(count)

    def _release_blocks(self) -> None:
        """Lift a blocked mode whose motion is free again (`_free_blocks`), when a probe is due."""
        if self._touching is None or self._group.index < self._next_probe:
            return
        if self._loop is not None:
            s = self._loop.state
            if s.block_common or s.block_diff:
                self._probed()
                s.block_common, s.block_diff = self._free_blocks(s.x_m, s.y_m, s.yaw_rad, s.block_common, s.block_diff)
            return
        d = self._chassis.dynamics()
        if d.block_common or d.block_diff:
            self._probed()
            common, diff = self._free_blocks(d.x_m, d.y_m, d.yaw_rad, d.block_common, d.block_diff)
            self._chassis.set_dynamics(d._replace(block_common=common, block_diff=diff))

    def _probed(self) -> None:
        """Set the next probe to the first communication step of the next `_BLOCK_PROBE_S` period."""
        period = self._probe_period
        index = self._group.index
        self._next_probe = index - index % period + period

    def _free_blocks(self, x: float, y: float, yaw: float, common: float, diff: float) -> tuple[float, float]:
        """The block flags with each mode lifted whose motion, probed `_BLOCK_PROBE_M` on, touches nothing.

        Asked at most every `_BLOCK_PROBE_S` of drive time (`_release_blocks`). Without it, a block
        held as long as the drive pushed into it, whatever had gone: a robot blocked turning left
        by another robot could never turn left again after that robot left.
        """
        probe = self._touching
        assert probe is not None
        step = _BLOCK_PROBE_M
        if common and not probe(x + common * step * math.cos(yaw), y + common * step * math.sin(yaw), yaw):
            common = 0.0
        if diff and not probe(x, y, yaw + diff * step / max(self._reach_m, step)):
            diff = 0.0
        return common, diff

    def _run_native(self, count: int) -> None:
        """Run `count` steps in the compiled loop, and on the Python path where contact is possible."""
        assert self._loop is not None
        run, state = self._loop.run, self._loop.state
        contact, free = self._contact, self._free
        while count:
            if contact is None:
                budget = math.inf
            else:
                budget = free(state.x_m, state.y_m, state.yaw_rad) if free is not None else 0.0
            count -= run(count, budget)
            if state.stopped_on_budget:
                count = self._near_world(count)

    def _near_world(self, count: int) -> int:
        """Finish the step the compiled loop stopped in, and go on in Python while the robot moves near the world.

        The compiled loop has stepped this step's FMUs; its chassis update, with the contact checks,
        runs on the Python path, and so do the following steps while the chassis moves and
        `free_distance` reports no free motion. A chassis at rest (stalled against a wall) goes
        back to the compiled loop, which takes steps without motion and no contact check; so does
        a chassis whose last step left its pose where it was (creeping below the pose's float
        resolution): the compiled loop takes such steps without a check, as this path does.
        Returns the steps left for the compiled loop.
        """
        self._to_python()
        chassis, free = self._chassis, self._free
        try:
            before = (chassis.x_m, chassis.y_m, chassis.yaw_rad)
            chassis.update(self._w_left, self._w_right)
            count -= 1
            while (
                count
                and (chassis.v_mps or chassis.yaw_rate_radps)
                and (free is None or free(chassis.x_m, chassis.y_m, chassis.yaw_rad) <= 0.0)
            ):
                pose = (chassis.x_m, chassis.y_m, chassis.yaw_rad)
                if pose == before:
                    break  # creeping in place: the compiled loop's steps
                before = pose
                self._run_python(1)
                count -= 1
            return count
        finally:
            self._to_native()

    # The two step loops below are the Python reference of the per-step path: everything they need
    # is bound to locals once per batch, and the loop body is straight-line code (one compiled call
    # steps both FMUs).

    def _run_voltage(self, count: int) -> None:
        h, kp, ki, v_max = self._h, self._kp, self._ki, self._v_max
        cs, co, ls, lo = self._cmd_scale, self._cmd_offset, self._load_scale, self._load_offset
        sf, so = self._speed_factor, self._speed_offset
        in_left, in_right = self._left.inputs, self._right.inputs
        out_left, out_right = self._left.outputs, self._right.outputs
        group = self._group
        step_next, chassis = group.step_next, self._chassis
        update = chassis.update
        ref_left, ref_right = self._ref_left, self._ref_right
        target_left, target_right, ramp = self._target_left, self._target_right, self._ramp_radps
        w_left, w_right = self._w_left, self._w_right
        int_left, int_right = self._int_left, self._int_right
        v_left = self._volt_left
        v_right = self._volt_right
        try:
            for _ in range(count):
                e = target_left - ref_left
                ref_left = target_left if abs(e) <= ramp else ref_left + math.copysign(ramp, e)
                e = target_right - ref_right
                ref_right = target_right if abs(e) <= ramp else ref_right + math.copysign(ramp, e)
                # PI per wheel with conditional integration (no wind-up while saturated).
                e = ref_left - w_left
                u = kp * e + ki * int_left
                v_left = v_max if u > v_max else (-v_max if u < -v_max else u)
                if v_left == u or (u > 0.0) != (e > 0.0):
                    int_left += e * h
                e = ref_right - w_right
                u = kp * e + ki * int_right
                v_right = v_max if u > v_max else (-v_max if u < -v_max else u)
                if v_right == u or (u > 0.0) != (e > 0.0):
                    int_right += e * h
                in_left[0] = (v_left - co) * cs
                in_left[1] = (chassis.load_left_nm - lo) * ls
                in_right[0] = (v_right - co) * cs
                in_right[1] = (chassis.load_right_nm - lo) * ls
                failed = step_next()
                if failed >= 0:
                    group.raise_failure(failed)
                w_left = sf * out_left[0] + so
                w_right = sf * out_right[0] + so
                update(w_left, w_right)
        finally:
            self._ref_left, self._ref_right = ref_left, ref_right
            self._w_left, self._w_right = w_left, w_right
            self._int_left, self._int_right = int_left, int_right
            self._volt_left, self._volt_right = v_left, v_right

    def _run_servo(self, count: int) -> None:
        cs, co, ls, lo = self._cmd_scale, self._cmd_offset, self._load_scale, self._load_offset
        sf, so = self._speed_factor, self._speed_offset
        in_left, in_right = self._left.inputs, self._right.inputs
        out_left, out_right = self._left.outputs, self._right.outputs
        group = self._group
        step_next, chassis = group.step_next, self._chassis
        update = chassis.update
        ref_left, ref_right = self._ref_left, self._ref_right
        target_left, target_right, ramp = self._target_left, self._target_right, self._ramp_radps
        w_left, w_right = self._w_left, self._w_right
        try:
            for _ in range(count):
                e = target_left - ref_left
                ref_left = target_left if abs(e) <= ramp else ref_left + math.copysign(ramp, e)
                e = target_right - ref_right
                ref_right = target_right if abs(e) <= ramp else ref_right + math.copysign(ramp, e)
                in_left[0] = (ref_left - co) * cs
                in_right[0] = (ref_right - co) * cs
                in_left[1] = (chassis.load_left_nm - lo) * ls
                in_right[1] = (chassis.load_right_nm - lo) * ls
                failed = step_next()
                if failed >= 0:
                    group.raise_failure(failed)
                w_left = sf * out_left[0] + so
                w_right = sf * out_right[0] + so
                update(w_left, w_right)
        finally:
            self._ref_left, self._ref_right = ref_left, ref_right
            self._w_left, self._w_right = w_left, w_right

    def pose(self) -> tuple[float, float, float]:
        """The chassis' (x_m, y_m, yaw_rad) now: `chassis_state()[:3]`, cheaper (a fleet reads it at every event)."""
        if self._loop is None:
            c = self._chassis
            return (c.x_m, c.y_m, c.yaw_rad)
        s = self._loop.state
        return (s.x_m, s.y_m, s.yaw_rad)

    def chassis_state(self) -> ChassisState:
        """Pose, rates and accelerations of the chassis now."""
        if self._loop is None:
            return self._chassis.state()
        s = self._loop.state
        return ChassisState(
            s.x_m, s.y_m, s.yaw_rad, s.v_mps, s.yaw_rate_radps, s.ax_mps2, s.ay_mps2, s.yaw_accel_radps2, s.blocked
        )

    def _signal(self, role: str, fallback: tuple[float, float]) -> tuple[float, float]:
        reading = self._reading[role]
        if reading is None:
            return fallback
        k, factor, offset = reading
        return factor * self._left.outputs[k] + offset, factor * self._right.outputs[k] + offset

    def wheel_state(self) -> WheelState:
        """Wheel angles, speeds, efforts, voltages and currents now (NaN where the FMU has none)."""
        nan = math.nan
        if self._loop is None:
            c = self._chassis
            speeds = (self._w_left, self._w_right)
            own_volts = (self._volt_left, self._volt_right)
            angles = (c.wheel_angle_left_rad, c.wheel_angle_right_rad)
        else:
            s = self._loop.state
            speeds = (s.w_left, s.w_right)
            own_volts = (s.volt_left, s.volt_right)
            angles = (s.wheel_angle_left_rad, s.wheel_angle_right_rad)
        if self.profile is not Profile.VOLTAGE:
            own_volts = (nan, nan)
        effort = self._signal("motor_torque", (nan, nan))
        if self._reading["motor_torque"] is None and self._torque_per_amp is not None:
            current = self._signal("current", (nan, nan))
            effort = (self._torque_per_amp * current[0], self._torque_per_amp * current[1])
        return WheelState(
            angle_rad=self._signal("wheel_angle", angles),
            speed_radps=speeds,
            effort_nm=effort,
            voltage_v=self._signal("applied_voltage", own_volts),
            current_a=self._signal("current", (nan, nan)),
        )

    @property
    def fmu_info(self) -> FmuInfo:
        """The FMU's model description."""
        return self._file.info

    @property
    def has_effort(self) -> bool:
        """Whether the wheels report a drive torque: the FMU's motor_torque, or current x the torque constant."""
        return self._reading["motor_torque"] is not None or self._torque_per_amp is not None

    @property
    def fmu_path(self) -> Path:
        """The .fmu file the wheels run."""
        return self._file.path

    def close(self) -> None:
        """Terminate and free both instances (stop their process when isolated) and remove the extracted FMU."""
        if self._isolated is not None:
            self._isolated.close()
        self._file.close()
