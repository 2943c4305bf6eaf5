"""The drive contract: roles an FMU must play, and the mapping from roles to its variables.

Roles and their units (SI, as twin uses them):

| role | direction | unit | meaning |
|---|---|---|---|
| voltage | input | V | motor voltage command (profile `voltage`) |
| speed_setpoint | input | rad/s | wheel-speed setpoint (profile `velocity-servo`) |
| load_torque | input | N.m | torque the chassis and ground apply against the wheel |
| wheel_speed | output | rad/s | wheel speed |
| wheel_angle | output | rad | wheel angle (twin integrates the speed if absent) |
| current | output | A | motor current |
| motor_torque | output | N.m | drive torque at the wheel |
| applied_voltage | output | V | voltage actually applied (after the FMU's own limits) |

A mapping binds each role to a variable name and, optionally, the unit that variable is in (when the
FMU declares none or declares it wrongly). A role not in the mapping binds to the variable named as
the role, if there is one. Parameters and start values are set by variable name, in the FMU's units.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from types import MappingProxyType

from twin.core.config import load_config, suggest
from twin.core.errors import FmuError
from twin.cosim.description import FmuInfo, VariableInfo, stepping_problem
from twin.cosim.units import UNITS, Unit, find_unit

__all__ = [
    "OPTIONAL_ROLES",
    "ROLES",
    "Binding",
    "BoundVariable",
    "ContractReport",
    "FmuMapping",
    "Profile",
    "RoleBinding",
    "RoleMap",
    "RoleReport",
    "RoleSpec",
    "bind",
    "check_contract",
    "infer_profile",
    "load_mapping",
]


class Profile(Enum):
    """How the twin drives the FMU."""

    VOLTAGE = "voltage"  # the FMU takes a voltage; the twin closes the speed loop
    VELOCITY_SERVO = "velocity-servo"  # the FMU takes a speed setpoint and closes its own loop


@dataclass(frozen=True, kw_only=True, slots=True)
class RoleSpec:
    """A role of the drive contract."""

    name: str
    direction: str  # "input" or "output" (of the FMU)
    unit: str  # twin's unit for the role
    description: str


ROLES: Mapping[str, RoleSpec] = MappingProxyType(
    {
        r.name: r
        for r in (
            RoleSpec(name="voltage", direction="input", unit="V", description="motor voltage command"),
            RoleSpec(name="speed_setpoint", direction="input", unit="rad/s", description="wheel-speed setpoint"),
            RoleSpec(name="load_torque", direction="input", unit="N.m", description="load torque at the wheel"),
            RoleSpec(name="wheel_speed", direction="output", unit="rad/s", description="wheel speed"),
            RoleSpec(name="wheel_angle", direction="output", unit="rad", description="wheel angle"),
            RoleSpec(name="current", direction="output", unit="A", description="motor current"),
            RoleSpec(name="motor_torque", direction="output", unit="N.m", description="drive torque at the wheel"),
            RoleSpec(name="applied_voltage", direction="output", unit="V", description="voltage applied"),
        )
    }
)

_REQUIRED: Mapping[Profile, tuple[str, ...]] = MappingProxyType(
    {
        Profile.VOLTAGE: ("voltage", "load_torque", "wheel_speed"),
        Profile.VELOCITY_SERVO: ("speed_setpoint", "load_torque", "wheel_speed"),
    }
)
OPTIONAL_ROLES: tuple[str, ...] = ("wheel_angle", "current", "motor_torque", "applied_voltage")


@dataclass(frozen=True, kw_only=True, slots=True)
class RoleBinding:
    """The FMU variable that plays a role, and the unit it is in (default: as the FMU declares)."""

    name: str
    unit: str | None = None


@dataclass(frozen=True, kw_only=True, slots=True)
class RoleMap:
    """Role → variable (a name, or a name and unit); a role left out binds to the variable of its name."""

    voltage: RoleBinding | str | None = None
    speed_setpoint: RoleBinding | str | None = None
    load_torque: RoleBinding | str | None = None
    wheel_speed: RoleBinding | str | None = None
    wheel_angle: RoleBinding | str | None = None
    current: RoleBinding | str | None = None
    motor_torque: RoleBinding | str | None = None
    applied_voltage: RoleBinding | str | None = None

    def given(self) -> tuple[str, ...]:
        """The roles this map names."""
        return tuple(r for r in ROLES if getattr(self, r) is not None)


@dataclass(frozen=True, kw_only=True, slots=True)
class FmuMapping:
    """How an FMU's variables meet the contract; written inline in a drive or in a mapping file."""

    roles: RoleMap = field(default_factory=RoleMap)
    parameters: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}))
    start_values: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}))

    def binding(self, role: str) -> RoleBinding:
        """The binding for `role` (by the role's own name when the mapping has none)."""
        value = getattr(self.roles, role)
        if value is None:
            return RoleBinding(name=role)
        return RoleBinding(name=value) if isinstance(value, str) else value

    def start(self) -> dict[str, float]:
        """Parameters and start values together, by variable name."""
        return {**self.parameters, **self.start_values}


def load_mapping(path: Path) -> FmuMapping:
    """Read a mapping file (the `FmuMapping` keys: roles, parameters, start_values).

    Raises:
        ConfigError: Naming file, line and key, if the file is unreadable or wrong.
    """
    return load_config(FmuMapping, path)


@dataclass(frozen=True, kw_only=True, slots=True)
class BoundVariable:
    """A role bound to a variable: value reference and conversion `si = factor * x + offset`."""

    role: str
    name: str
    value_reference: int
    unit: str
    factor: float
    offset: float


@dataclass(frozen=True, kw_only=True, slots=True)
class RoleReport:
    """How one role fared in a contract check."""

    role: str
    required: bool
    variable: str
    unit: str | None
    problem: str | None  # None when the role is bound


@dataclass(frozen=True, kw_only=True, slots=True)
class ContractReport:
    """The result of checking an FMU against a profile."""

    profile: Profile
    roles: tuple[RoleReport, ...]
    problems: tuple[str, ...]  # problems not tied to a role (parameters, interface)

    @property
    def missing(self) -> tuple[str, ...]:
        """Required roles that are not bound."""
        return tuple(r.role for r in self.roles if r.required and r.problem is not None)

    @property
    def ok(self) -> bool:
        """Whether the FMU can be driven with this profile."""
        return not self.missing and not self.problems


@dataclass(frozen=True, kw_only=True, slots=True)
class Binding:
    """An FMU bound to a profile: its inputs and outputs in a fixed order, ready to step."""

    profile: Profile
    inputs: tuple[BoundVariable, ...]  # (command, load_torque)
    outputs: Mapping[str, BoundVariable]  # by role; optional roles may be absent
    start: Mapping[str, float]


def _unit_for(info: FmuInfo, name: str | None, role: RoleSpec) -> tuple[Unit | None, str | None]:
    target = UNITS[role.unit]
    if name is None:
        return target, None
    unit = find_unit(name) or info.units.get(name)
    if unit is None:
        known = ", ".join(UNITS)
        return None, f"unit {name!r} is unknown (known: {known}; or declare it in the FMU's UnitDefinitions)"
    if not unit.same_dimension(target):
        return None, f"unit {name!r} cannot be converted to {role.unit}"
    return unit, None


def check_contract(info: FmuInfo, mapping: FmuMapping, profile: Profile) -> ContractReport:
    """Check every role and setting of `mapping` against the FMU, without raising."""
    required = _REQUIRED[profile]
    roles = [*required, *OPTIONAL_ROLES]
    reports = []
    problems = []
    bound_to: dict[str, str] = {}  # variable -> the role it is bound to
    by_vr: dict[int, tuple[str, str]] = {}  # value reference -> (variable, role) first bound to it
    given = mapping.roles.given()
    for role in roles:
        spec = ROLES[role]
        bind_to = mapping.binding(role)
        var = info.variables.get(bind_to.name)
        problem: str | None = None
        unit_name = bind_to.unit
        if var is None:
            hint = suggest(bind_to.name, list(info.variables)) if role in mapping.roles.given() else ""
            problem = f"no variable {bind_to.name!r}{hint if hint.startswith('; did') else ''}"
        else:
            unit_name = bind_to.unit or var.unit
            wanted = ("input",) if spec.direction == "input" else ("output", "local")
            if var.causality not in wanted:
                problem = f"{var.name!r} is {_article(var.causality)}, the role needs an {spec.direction}"
            elif var.type not in ("Real", "Float64"):
                problem = f"{var.name!r} is {_article(var.type)}, the role needs a Real/Float64"
            elif var.dimensions:
                problem = f"{var.name!r} is an array ({var.dimensions}-D), the role needs a scalar"
            elif var.name in bound_to:
                problem = f"{var.name!r} is already bound to role {bound_to[var.name]}; a variable serves one role"
            else:
                _, problem = _unit_for(info, unit_name, spec)
                if problem is not None and bind_to.unit is None and var.unit is not None:  # the FMU's own unit
                    problem += (
                        f", the FMU's declared unit; if {var.name!r} is in {spec.unit} all the same, say so in the "
                        f"mapping: {role}: {{name: {var.name}, unit: {spec.unit}}}"
                    )
            if problem is None:
                bound_to[var.name] = role
                other = by_vr.setdefault(var.value_reference, (var.name, role))
                if other[0] != var.name:
                    problems.append(
                        f"roles.{role}: {var.name!r} shares value reference {var.value_reference} with {other[0]!r} "
                        f"(role {other[1]}), so setting or reading one is the other; the FMU's model description "
                        "must give them distinct valueReferences"
                    )
        if problem is not None and role in given and role not in required:
            # An optional role the mapping names explicitly must bind: a wrong name is not silently dropped.
            problems.append(f"roles.{role}: {problem}")
        reports.append(
            RoleReport(role=role, required=role in required, variable=bind_to.name, unit=unit_name, problem=problem)
        )
    interface_problem = stepping_problem(info)
    if interface_problem is not None:
        problems.append(interface_problem)
    for section, values in (("parameters", mapping.parameters), ("start_values", mapping.start_values)):
        for name, value in values.items():
            problem = _setting_problem(info, section, name)
            if problem is None and not math.isfinite(value):
                problem = f"{value} is not a finite number"
            if problem is None:
                problem = _value_problem(info.variables[name], value)
            if problem is not None:
                problems.append(f"{section}.{name}: {problem}")
    return ContractReport(profile=profile, roles=tuple(reports), problems=tuple(problems))


def _article(word: str) -> str:
    """`word` with its indefinite article: `an output`, `a parameter`."""
    return f"{'an' if word[:1].lower() in 'aeiou' else 'a'} {word}"


_PARAMETERS = ("parameter", "structuralParameter")


def _setting_problem(info: FmuInfo, section: str, name: str) -> str | None:
    """Why the mapping cannot set `name` under `section` (parameters or start_values) before initialisation."""
    var = info.variables.get(name)
    if var is None:
        return f"no variable {name!r} to set{suggest(name, list(info.variables))}"
    if var.variability == "constant" or var.causality in ("independent", "calculatedParameter"):
        return f"{name!r} ({var.causality}, {var.variability}) cannot be set"
    if var.dimensions:
        return f"{name!r} is an array ({var.dimensions}-D); the mapping sets scalars only"
    # Outputs and locals without a start value are computed by the FMU (initial="calculated").
    calculated = var.causality in ("output", "local") and var.start is None
    if section == "parameters" and var.causality not in _PARAMETERS:
        fix = (
            "the FMU computes it, it cannot be set"
            if calculated
            else "set it under start_values, or name one of the FMU's parameters"
        )
        return f"{name!r} is {_article(var.causality)}, not a parameter; {fix}"
    if calculated:
        return f"{name!r} is {_article(var.causality)} the FMU computes (it has no start value); it cannot be set"
    return None


_WHOLE_TYPES = ("Integer", "Enumeration", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64")


def _value_problem(var: VariableInfo, value: float) -> str | None:
    """Why a number cannot go into this variable as the FMU's setter would take it (None: it can)."""
    kind = var.type
    if kind in ("String", "Binary", "Clock"):
        return f"{var.name!r} is a {kind}; the mapping sets numbers only, so leave it out"
    if kind in _WHOLE_TYPES and value != int(value):
        return f"{value} is not a whole number, which the {kind} {var.name!r} takes (it would be cut to {int(value)})"
    if kind == "Boolean" and value not in (0, 1):  # YAML's true and false are 1 and 0
        return f"{value} is not a Boolean for {var.name!r}; give true or false"
    return None


def bind(info: FmuInfo, mapping: FmuMapping, profile: Profile) -> Binding:
    """Bind the FMU's variables to the profile's roles.

    Raises:
        FmuError: Listing every missing required role and every other problem, before any run.
    """
    report = check_contract(info, mapping, profile)
    if not report.ok:
        parts = []
        if report.missing:
            details = "; ".join(f"{r.role}: {r.problem}" for r in report.roles if r.required and r.problem)
            parts.append(f"missing required role(s) {', '.join(report.missing)} ({details})")
        parts.extend(report.problems)
        msg = f"{info.path}: does not satisfy the {profile.value} drive contract: {'; '.join(parts)}; " + (
            f"map the roles to the FMU's variables (see `twin fmu check {info.path.name}`)"
            if report.missing
            else f"`twin fmu check {info.path.name}` lists the FMU's variables"
        )
        raise FmuError(msg)
    bound: dict[str, BoundVariable] = {}
    for r in report.roles:
        if r.problem is not None:
            continue
        spec = ROLES[r.role]
        unit, _ = _unit_for(info, r.unit, spec)
        assert unit is not None  # checked above
        var = info.variables[r.variable]
        bound[r.role] = BoundVariable(
            role=r.role,
            name=var.name,
            value_reference=var.value_reference,
            unit=unit.name,
            factor=unit.factor,
            offset=unit.offset,
        )
    command = "voltage" if profile is Profile.VOLTAGE else "speed_setpoint"
    inputs = (bound.pop(command), bound.pop("load_torque"))
    for role in ("voltage", "speed_setpoint"):
        bound.pop(role, None)
    return Binding(profile=profile, inputs=inputs, outputs=MappingProxyType(bound), start=mapping.start())


def _other(profile: Profile) -> Profile:
    return Profile.VOLTAGE if profile is Profile.VELOCITY_SERVO else Profile.VELOCITY_SERVO


def infer_profile(info: FmuInfo, mapping: FmuMapping) -> tuple[Profile, str]:
    """The profile an FMU is built for, read from its variables (and the mapping's roles), and why.

    The profile whose contract the FMU satisfies; when both do, `voltage` (the twin's own speed
    loop); when neither does, the one whose required variables the FMU has more of by name (a
    `speed_setpoint` in an unknown unit is a velocity-servo FMU with a unit to fix, not a voltage
    one without `voltage`), then the one missing fewer required roles (`voltage` on a tie).
    """
    reports = {p: check_contract(info, mapping, p) for p in Profile}
    ok = [p for p in Profile if reports[p].ok]
    command = {Profile.VOLTAGE: "voltage", Profile.VELOCITY_SERVO: "speed_setpoint"}
    if len(ok) == 1:
        chosen = ok[0]
        return chosen, f"its {mapping.binding(command[chosen]).name!r} input satisfies only the {chosen.value} contract"
    if len(ok) == 2:
        return Profile.VOLTAGE, "it satisfies both contracts; voltage is the default (the twin closes the speed loop)"

    given = set(mapping.roles.given())
    named = [p for p in Profile if command[p] in given and command[_other(p)] not in given]
    if len(named) == 1:  # the mapping names one profile's command role: that profile, whatever its problems
        chosen = named[0]
        return chosen, f"the mapping names its {command[chosen]} role; it satisfies neither contract (see below)"

    def absent(p: Profile) -> int:  # required roles whose variable the FMU does not have at all
        return sum(1 for r in reports[p].roles if r.required and r.variable not in info.variables)

    chosen = min(Profile, key=lambda p: (absent(p), len(reports[p].missing)))
    if absent(chosen) == 0:
        return chosen, f"it satisfies neither contract; it has every variable {chosen.value} requires (see below)"
    return chosen, f"it satisfies neither contract; it has more of the variables {chosen.value} requires"
