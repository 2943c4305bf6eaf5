"""The drive section `type: fmu`, and what it comes to against its FMU before any instance exists.

`FmuDrive` is the scenario's section: which FMU (a built-in, `auto` for the robot's own motors, or a
file), the profile and the mapping of the drive contract's roles (`twin.cosim.contract`), the motor
model and speed-loop targets, command limits, slip, isolation. `plan_fmu_drive` binds it to the
FMU's model description: the communication step, the contract, the motor constants and the
twin's speed-loop design (`DrivePlan`). `FmuDrivetrain` plans before it creates the wheels, and
`twin scenario check` plans through `check_fmu_drive` without loading the FMU's binary, so both
refuse a drive with the same line.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from twin.core.errors import ConfigError, FmuError
from twin.cosim.build import resolve_fmu
from twin.cosim.contract import Binding, FmuMapping, Profile, bind, load_mapping
from twin.cosim.description import FmuInfo, binary_problem, read_fmu_info, stepping_problem
from twin.robot.chassis import SlipModel
from twin.robot.drive_control import MotorConstants, SpeedLoop, design_speed_pi

__all__ = [
    "CommandLimits",
    "DrivePlan",
    "FmuDrive",
    "MotorModel",
    "MotorModelError",
    "SpeedLoopTargets",
    "builtin_motor",
    "check_fmu_drive",
    "communication_step",
    "motor_constants",
    "plan_fmu_drive",
]


@dataclass(frozen=True, kw_only=True, slots=True)
class CommandLimits:
    """Clamps applied to cmd_vel before the wheels, as the TB3 firmware does (null: no clamp).

    TB3 firmware values: Waffle 0.26 m/s, 1.82 rad/s; Burger 0.22 m/s, 2.84 rad/s; each wheel
    ±337 velocity units = 77.2 rpm = 8.08 rad/s.
    """

    max_linear_mps: float | None = None
    max_angular_radps: float | None = None
    max_wheel_speed_radps: float | None = None


@dataclass(frozen=True, kw_only=True, slots=True)
class MotorModel:
    """The linear motor model for the speed-loop design: each a number (SI) or an FMU parameter's name.

    Defaults name the parameters of the project's FMUs.
    """

    resistance_ohm: float | str = "R"
    inductance_h: float | str = "L"
    torque_constant_nm_per_a: float | str = "Kt"
    back_emf_vs_per_rad: float | str = "Ke"
    rotor_inertia_kgm2: float | str = "J_rotor"
    rotor_friction_nms_per_rad: float | str = "b_rotor"
    gear_ratio: float | str = "N"
    load_inertia_kgm2: float | str = "J_wheel"


@dataclass(frozen=True, kw_only=True, slots=True)
class SpeedLoopTargets:
    """Design targets of the twin's wheel-speed PI (profile `voltage`)."""

    bandwidth_hz: float = 15.0  # open-loop crossover
    phase_margin_deg: float = 60.0
    voltage_limit_v: float = 12.0  # the PI's output clamp (the battery)


@dataclass(frozen=True, kw_only=True, slots=True)
class FmuDrive:
    """Drive section `type: fmu`: wheels stepped as FMUs (one instance per wheel)."""

    type: Literal["fmu"] = "fmu"
    # A built-in (builtin:NAME), used when `fmu_file` is null; `auto`: the robot's own motors (TurtleBot3
    # Burger: XL430-W250, else the Waffle's XM430-W210), in the profile's variant.
    fmu: str = "builtin:xm430_w210"
    fmu_file: Path | None = None  # a .fmu file (relative to the scenario); overrides `fmu`
    fmi_version: Literal[2, 3] = 2  # for built-ins
    profile: Literal["voltage", "velocity-servo"] = "voltage"
    mapping: FmuMapping | Path = field(default_factory=FmuMapping)  # inline, or a mapping file
    communication_step_s: float | None = None  # null: the physics step
    motor: MotorModel | None = field(default_factory=MotorModel)  # for the PI design; null in servo
    speed_loop: SpeedLoopTargets = field(default_factory=SpeedLoopTargets)
    wheel_inertia_kgm2: float | None = None  # the drive's inertia at the wheel; null: from motor, or probed
    limits: CommandLimits = field(default_factory=CommandLimits)
    # The wheels' rim acceleration limit, as gazebo_ros_diff_drive's max_wheel_acceleration: null takes
    # the robot SDF's diff-drive plugin value, 0 means none.
    max_wheel_acceleration_mps2: float | None = None
    # Clamp wheel-speed commands the motor cannot reach at the supply voltage (speed_loop.voltage_limit_v)
    # to what it can, and report it (needs the motor model); false: pass them on to the FMU as given.
    clamp_to_supply: bool = True
    slip: SlipModel = field(default_factory=SlipModel)
    # none: the FMU's code runs in the twin's process; process: in a child process, so that its crash
    # or hang (a step longer than step_timeout_s of wall time) ends the run with one line and a valid bag.
    # The step loop then runs in Python, one round trip to the child per step for both wheels.
    isolation: Literal["none", "process"] = "none"
    step_timeout_s: float = 10.0
    # native: the per-step path compiled (the fast one); lowlevel: the Python reference path with the
    # FMUs stepped by the compiled shim; convenience: the Python path through FMPy's wrappers.
    api: Literal["native", "lowlevel", "convenience"] = "native"

    def __post_init__(self) -> None:
        if self.fmu_file is None and not (self.fmu.startswith("builtin:") or self.fmu == "auto"):
            msg = f"fmu: {self.fmu!r} is not builtin:NAME or auto; give a file as fmu_file"
            raise ValueError(msg)
        if self.communication_step_s is not None and not self.communication_step_s > 0.0:
            msg = f"communication_step_s must be positive, got {self.communication_step_s}"
            raise ValueError(msg)
        if not self.step_timeout_s > 0.0:
            msg = f"step_timeout_s must be positive, got {self.step_timeout_s}"
            raise ValueError(msg)
        if self.max_wheel_acceleration_mps2 is not None and not self.max_wheel_acceleration_mps2 >= 0.0:
            msg = f"max_wheel_acceleration_mps2 must be 0 (none) or positive, got {self.max_wheel_acceleration_mps2}"
            raise ValueError(msg)

    def resolved_mapping(self) -> FmuMapping:
        """The mapping, read from its file if it is a path.

        Raises:
            ConfigError: If the mapping file is wrong.
        """
        return load_mapping(self.mapping) if isinstance(self.mapping, Path) else self.mapping


def builtin_motor(robot_name: str, profile: str) -> str:
    """The built-in FMU of a TurtleBot3's wheel motors: Burger XL430-W250-T, Waffle (Pi) XM430-W210-T."""
    base = "xl430_w250" if "burger" in robot_name.lower() else "xm430_w210"
    return f"builtin:{base}_servo" if profile == "velocity-servo" else f"builtin:{base}"


class MotorModelError(ConfigError):
    """The motor model does not resolve against the FMU: `key` (`drive.motor.resistance_ohm`) and `problem`.

    The message is `key: problem; fix` in a scenario's terms; `twin fmu step-response` rewords it in its own.
    """

    def __init__(self, key: str, problem: str, fix: str) -> None:
        """Say that `key` fails with `problem`, and the `fix`."""
        super().__init__(f"{key}: {problem}" + (f"; {fix}" if fix else ""))
        self.key = key
        self.problem = problem


def motor_constants(model: MotorModel, info: FmuInfo, start: Mapping[str, float]) -> MotorConstants:
    """Resolve a motor model against an FMU: numbers as given, names from the start values or the FMU.

    Raises:
        MotorModelError: If a named parameter is missing or the constants are not physical.
    """
    values: dict[str, float] = {}
    fix = "give the number (SI) or the FMU parameter's name"
    for name in MotorModel.__dataclass_fields__:
        ref = getattr(model, name)
        if isinstance(ref, str):
            if ref in start:
                values[name] = float(start[ref])
                continue
            var = info.variables.get(ref)
            if var is None or var.start is None:
                problem = f"the FMU has no parameter {ref!r} with a start value"
                raise MotorModelError(f"drive.motor.{name}", problem, fix)
            try:
                values[name] = float(var.start)
            except ValueError:  # an array's or a Boolean's start (read_fmu_info refuses non-numbers)
                problem = f"the FMU's {ref!r} is a {var.type} with start {var.start!r}, not one number"
                raise MotorModelError(
                    f"drive.motor.{name}", problem, "give the number (SI) or name a scalar parameter"
                ) from None
        else:
            values[name] = float(ref)
    try:
        return MotorConstants(**values)
    except ValueError as err:
        raise MotorModelError("drive.motor", str(err), "") from None


def communication_step(drive: FmuDrive, step_ns: int) -> tuple[float, int]:
    """The communication step (s) and how many physics steps it spans.

    Raises:
        ConfigError: If it is not a whole multiple of the physics step.
    """
    physics_s = step_ns * 1e-9
    comm_s = drive.communication_step_s or physics_s
    ratio = comm_s / physics_s
    if ratio < 1.0 - 1e-9 or abs(ratio - round(ratio)) > 1e-6:
        msg = f"drive.communication_step_s: {comm_s:g} s must be a whole multiple of the physics step {physics_s:g} s"
        raise ConfigError(msg)
    return comm_s, round(ratio)


@dataclass(frozen=True, kw_only=True, slots=True)
class DrivePlan:
    """What an FMU drive section comes to before any instance exists (`plan_fmu_drive`)."""

    communication_step_s: float
    ratio: int  # physics steps per communication step
    profile: Profile
    binding: Binding
    motor: MotorConstants | None  # None: no motor model (a servo FMU without one)
    speed_loop: SpeedLoop | None  # the twin's PI (voltage profile), else None


def plan_fmu_drive(drive: FmuDrive, info: FmuInfo, *, step_ns: int) -> DrivePlan:
    """Check a drive section against its FMU and decide what `FmuDrivetrain` needs, without instantiating it.

    `FmuDrivetrain` runs this before it creates the wheels' instances, and `twin scenario check`
    runs it too (`check_fmu_drive`), so both refuse the same drive with the same line: the
    communication step, the drive contract (roles, parameters, start values), the motor model
    and the speed-loop design, and what isolation needs.

    Args:
        drive: The drive section, `fmu: auto` already resolved.
        info: The FMU's model description.
        step_ns: The physics step, ns.

    Raises:
        ConfigError: If the communication step, the mapping file, the motor model or the speed-loop targets are wrong.
        FmuError: If the FMU does not satisfy the profile's contract with this mapping.
    """
    comm_s, ratio = communication_step(drive, step_ns)
    profile = Profile(drive.profile)
    binding = bind(info, drive.resolved_mapping(), profile)
    motor: MotorConstants | None = None
    if drive.motor is not None:
        try:
            motor = motor_constants(drive.motor, info, binding.start)
        except ConfigError:
            if profile is Profile.VOLTAGE:
                raise
    speed_loop: SpeedLoop | None = None
    if profile is Profile.VOLTAGE:
        if motor is None:
            msg = "drive.motor: the voltage profile needs the motor model to design the speed loop"
            raise ConfigError(msg)
        targets = drive.speed_loop
        speed_loop = design_speed_pi(
            motor, crossover_hz=targets.bandwidth_hz, phase_margin_deg=targets.phase_margin_deg, step_s=comm_s
        )
    if info.instantiated_once and drive.isolation != "process":
        msg = (
            f"drive.isolation: {info.path.name} declares canBeInstantiatedOnlyOncePerProcess, and the drive needs "
            "one instance per wheel; set drive.isolation: process, which runs each instance in its own process "
            "(with drive.motor or drive.wheel_inertia_kgm2)"
        )
        raise ConfigError(msg)
    if drive.wheel_inertia_kgm2 is None and motor is None and drive.isolation == "process":
        msg = (
            "drive.wheel_inertia_kgm2: give it (or drive.motor) with isolation: process; "
            "the twin does not probe an isolated FMU in its own process"
        )
        raise ConfigError(msg)
    return DrivePlan(
        communication_step_s=comm_s,
        ratio=ratio,
        profile=profile,
        binding=binding,
        motor=motor,
        speed_loop=speed_loop,
    )


def check_fmu_drive(drive: FmuDrive, *, step_ns: int, robot_name: str = "") -> DrivePlan:
    """Refuse what `FmuDrivetrain` would refuse before its first step, without loading the FMU's binary.

    Resolves `fmu: auto`, builds a built-in FMU on first use as a run would, reads the FMU's model
    description, checks its binary and runs `plan_fmu_drive`.

    Raises:
        ConfigError: As `plan_fmu_drive`.
        FmuError: If the FMU cannot be built, read or stepped here, or does not satisfy the contract.
    """
    if drive.fmu == "auto":
        drive = dataclasses.replace(drive, fmu=builtin_motor(robot_name, drive.profile))
    communication_step(drive, step_ns)  # before any build, as a run checks it
    path = resolve_fmu(drive.fmu_file or drive.fmu, fmi_version=drive.fmi_version)
    info = read_fmu_info(path)
    problem = stepping_problem(info) or binary_problem(info)
    if problem is not None:
        msg = f"{path}: {problem}"
        raise FmuError(msg)
    plan = plan_fmu_drive(drive, info, step_ns=step_ns)
    if drive.fmu_file is not None:  # a user's FMU: one instance made and stepped once, as the run's first step
        _try_instance(drive, path, plan)
    return plan


def _try_instance(drive: FmuDrive, path: Path, plan: DrivePlan) -> None:
    """Instantiate the FMU as the run does (its start values set, in its own process with isolation) and step once.

    What only the binary tells (a model description whose GUID or value references the binary does
    not have, a Python FMU's missing module) is refused by `scenario check` as the run refuses it.

    Raises:
        FmuError: As the run's instantiation or first step would.
    """
    binding = plan.binding
    inputs = [b.value_reference for b in binding.inputs]
    outputs = [b.value_reference for b in binding.outputs.values()]
    try:
        _step_one_instance(drive, path, plan, inputs, outputs)
    except FmuError as err:
        found = re.search(r"value reference (\d+)", str(err))
        roles = [
            b for b in (*binding.inputs, *binding.outputs.values()) if found and b.value_reference == int(found[1])
        ]
        if not roles:
            raise
        msg = (
            f"{err}; value reference {found[1] if found else ''} is role {roles[0].role} ({roles[0].name}) in "
            "the model description, and the binary does not take it so: the FMU's modelDescription.xml and "
            "binary disagree (rebuild or re-export the FMU)"
        )
        raise FmuError(msg) from None


def _step_one_instance(drive: FmuDrive, path: Path, plan: DrivePlan, inputs: list[int], outputs: list[int]) -> None:
    from twin.cosim.fmu import FmuFile
    from twin.cosim.isolated import IsolatedGroup

    binding = plan.binding
    with FmuFile(path) as file:  # (its extracted folder goes with it)
        if drive.isolation == "process":
            group = IsolatedGroup(
                path,
                file.label,
                ("left",),
                step_s=plan.communication_step_s,
                inputs=inputs,
                outputs=outputs,
                start=binding.start,
                timeout_s=drive.step_timeout_s,
                process_per_instance=file.info.instantiated_once,
            )
            try:
                group.step()
            finally:
                group.close()
            return
        api = "lowlevel" if drive.api == "native" else drive.api
        stepper = file.instantiate(
            "left", step_s=plan.communication_step_s, inputs=inputs, outputs=outputs, start=binding.start, api=api
        )
        try:
            stepper.step(0.0)
        finally:
            stepper.close()
