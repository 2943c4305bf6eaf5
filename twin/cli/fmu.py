"""`twin fmu build|check|step-response`: the drivetrain FMUs from the command line.

Build the project's FMUs, check any FMU against the drive contract, compare an FMU's step response
with the linear motor model.
"""

from __future__ import annotations

import argparse
import json
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twin.core.errors import BagError, ConfigError, FmuError

if TYPE_CHECKING:
    from twin.cosim.contract import FmuMapping
    from twin.robot.fmu_drive import FmuDrive

# twin.cosim.contract.Profile's values, spelled here so `--help` need not import fmpy (a test compares).
PROFILES = ("voltage", "velocity-servo")

_BUILD_EPILOG = """\
examples:
  twin fmu build                 build (or reuse) every built-in FMU, FMI 2.0 and 3.0
  twin fmu build --force         rebuild even if the cache is current
  TWIN_CACHE_DIR=/tmp/c twin fmu build
"""

_CHECK_EPILOG = """\
examples:
  twin fmu check builtin:xm430_w210              a voltage-driven motor (profile inferred: voltage)
  twin fmu check builtin:xm430_w210_servo        the default drive's servo (inferred: velocity-servo)
  twin fmu check builtin:xm430_w210 --profile velocity-servo   check against a profile of your choice
  twin fmu check vendor_motor.fmu --map fmus/maps/acme_drive.yaml --json   your FMU, its names mapped
exit status: 0 when the FMU satisfies the contract, 4 when it does not, cannot be read, or has no
loadable binary for this platform (binaries/linux64/NAME.so for FMI 2.0, binaries/x86_64-linux/ for 3.0).
"""

_STEP_EPILOG = """\
examples:
  twin fmu step-response builtin:xl430_w250
  twin fmu step-response builtin:xm430_w210 --fmi 3 --step-ms 5 --out /tmp/step.png
  twin fmu step-response vendor.fmu --scenario vendor.yaml   drive.motor and drive.mapping from a scenario
"""


# No robot motor's step response is asked at more than this (the TB3's DYNAMIXELs take 12 V).
_MAX_VOLTAGE_V = 1000.0


def register(subparsers: Any, common: argparse.ArgumentParser) -> None:
    """Add the `fmu` command group."""
    parser = subparsers.add_parser(
        "fmu",
        help="build, check and step FMUs (drivetrain co-simulation)",
        description="Drive FMUs: the project's DC motor FMUs and vendor FMUs that swap in through a mapping.",
        parents=[common],
    )
    sub = parser.add_subparsers(dest="fmu_command", metavar="SUBCOMMAND", required=True)

    build = sub.add_parser(
        "build",
        help="compile fmus/ into .fmu files in the cache",
        description=(
            "Compile every model under fmus/ with the system C compiler ($CC, cc or gcc) into FMI 2.0 and 3.0 "
            "Co-Simulation FMUs in the cache ($TWIN_CACHE_DIR, $XDG_CACHE_HOME/twin or ~/.cache/twin). "
            "A build is reused until one of its sources, headers or flags changes."
        ),
        epilog=_BUILD_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    build.add_argument("--force", action="store_true", help="rebuild even when the cache is current")
    build.add_argument("--json", action="store_true", help="print the built files as JSON")
    build.set_defaults(func=_build)

    check = sub.add_parser(
        "check",
        help="list an FMU's variables and check it against the drive contract",
        description=(
            "List the FMU's variables (causality, variability, unit) and say whether it satisfies the drive "
            "contract of a profile, naming each missing role. FMU is a .fmu file or builtin:NAME."
        ),
        epilog=_CHECK_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    check.add_argument("fmu", metavar="FMU", help=".fmu file or builtin:NAME")
    check.add_argument(
        "--profile",
        choices=PROFILES,
        default=None,
        help="the contract to check: voltage (the FMU takes a voltage, the twin closes the speed loop) or "
        "velocity-servo (it takes a speed setpoint and closes its own, as a Dynamixel in velocity mode); "
        "default: inferred from the FMU's inputs, and said",
    )
    check.add_argument("--map", type=Path, metavar="FILE", help="mapping file (roles, parameters, start_values)")
    check.add_argument("--fmi", type=int, choices=(2, 3), default=2, help="FMI version of a built-in (default 2)")
    check.add_argument("--json", action="store_true", help="print the report as JSON")
    check.set_defaults(func=_check)

    step = sub.add_parser(
        "step-response",
        help="compare a voltage-profile FMU's no-load voltage step with the linear motor model",
        description=(
            "Step the FMU with a constant voltage and no load torque and print, next to it, python-control's "
            "response of the analytic transfer function w(s)/V(s) built from the FMU's parameters "
            "(R, L, Kt, Ke, J_rotor, b_rotor, N, J_wheel), or from a scenario's drive.motor (--scenario) for an "
            "FMU whose parameters are named otherwise. Supports voltage-profile FMUs only (a voltage input); "
            "a velocity-servo FMU (a speed-setpoint input) is refused, saying so."
        ),
        epilog=_STEP_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    step.add_argument("fmu", metavar="FMU", help=".fmu file or builtin:NAME")
    step.add_argument("--voltage", type=float, default=12.0, help="step voltage, V (default 12)")
    step.add_argument("--step-ms", type=float, default=1.0, help="communication step, ms (default 1)")
    step.add_argument("--duration-s", type=float, default=None, help="length (default 8 mechanical time constants)")
    step.add_argument("--map", type=Path, metavar="FILE", help="mapping file for a vendor FMU")
    step.add_argument(
        "--scenario",
        type=Path,
        metavar="FILE",
        help="scenario whose drive.motor gives the motor model (numbers in SI or the FMU's parameter names) "
        "for an FMU without the project's parameters R, L, Kt, ...; also its drive.mapping unless --map",
    )
    step.add_argument("--fmi", type=int, choices=(2, 3), default=2, help="FMI version of a built-in (default 2)")
    step.add_argument("--out", type=Path, metavar="PNG", help="also plot both responses to this PNG")
    step.add_argument("--json", action="store_true", help="print the summary as JSON")
    step.set_defaults(func=_step_response)


def _build(args: argparse.Namespace) -> int:
    from twin.cosim.build import build_all, cache_dir

    built = build_all(force=args.force)
    if args.json:
        rows = [{"name": b.variant, "fmi": b.fmi_version, "path": str(b.path), "rebuilt": b.rebuilt} for b in built]
        print(json.dumps(rows, indent=2))
        return 0
    for b in built:
        print(f"{b.variant:<20} FMI {b.fmi_version}  {'built ' if b.rebuilt else 'cached'}  {b.path}")
    print(f"{len(built)} FMUs in {cache_dir() / 'fmus'}")
    return 0


def _mapping(path: Path | None) -> FmuMapping:
    from twin.cosim.contract import FmuMapping, load_mapping

    return load_mapping(path) if path is not None else FmuMapping()


def _check(args: argparse.Namespace) -> int:
    from twin.cosim.build import resolve_fmu
    from twin.cosim.contract import Profile, check_contract, infer_profile
    from twin.cosim.description import binary_problem, read_fmu_info, stepping, stepping_problem

    path = resolve_fmu(args.fmu, fmi_version=args.fmi)
    info = read_fmu_info(path)
    problem = binary_problem(info)
    if problem is not None:
        msg = f"{path}: {problem}"
        raise FmuError(msg)
    mapping = _mapping(args.map)
    if args.profile is None:
        profile, profile_reason = infer_profile(info, mapping)
    else:
        profile, profile_reason = Profile(args.profile), "--profile"
    report = check_contract(info, mapping, profile)
    stepped_as = None if stepping_problem(info) is not None else stepping(info)
    if args.json:
        doc = {
            "fmu": str(path),
            "fmi_version": info.fmi_version,
            "model_name": info.model_name,
            "generation_tool": info.generation_tool,
            "co_simulation": info.co_simulation,
            "model_exchange": info.model_exchange,
            "stepped_as": stepped_as,
            "instantiated_once_per_process": info.instantiated_once,
            "variables": [
                {
                    "name": v.name,
                    "value_reference": v.value_reference,
                    "type": v.type,
                    "causality": v.causality,
                    "variability": v.variability,
                    "unit": v.unit,
                    "start": v.start,
                }
                for v in info.variables.values()
            ],
            "profile": report.profile.value,
            "profile_from": "given" if args.profile is not None else "inferred",
            "profile_reason": profile_reason,
            "ok": report.ok,
            "missing_roles": list(report.missing),
            "roles": [
                {"role": r.role, "required": r.required, "variable": r.variable, "unit": r.unit, "problem": r.problem}
                for r in report.roles
            ],
            "problems": list(report.problems),
        }
        print(json.dumps(doc, indent=2))
        return 0 if report.ok else 4
    kinds = (
        ("Co-Simulation", info.co_simulation),
        ("Model Exchange", info.model_exchange),
        ("Scheduled Execution", info.scheduled_execution),
    )
    interfaces = [name for name, identifier in kinds if identifier]
    print(f"{path}")
    print(f"  FMI {info.fmi_version}, {info.model_name!r}, {' + '.join(interfaces) or 'no interface'}")
    if info.generation_tool:
        print(f"  generated by {info.generation_tool}")
    print(f"  stepped as: {stepped_as or 'cannot be stepped (see problems below)'}")
    if info.instantiated_once:
        print("  canBeInstantiatedOnlyOncePerProcess: a drive runs it with isolation: process (a process per wheel)")
    print(f"  {len(info.variables)} variables:")
    rows = [
        (v.name, v.type, v.causality, v.variability, v.unit or "-", v.start if v.start is not None else "")
        for v in info.variables.values()
    ]
    header = ("name", "type", "causality", "variability", "unit", "start")
    # Each column as wide as its longest entry (Enumeration, calculatedParameter, long units).
    widths = [max(len(row[k]) for row in (header, *rows)) for k in range(len(header) - 1)]
    for row in (header, *rows):
        cells = [f"{cell:<{w}}" for cell, w in zip(row, widths, strict=False)]
        print("    " + "  ".join([*cells, row[-1]]).rstrip())
    how = "given with --profile" if args.profile is not None else f"inferred: {profile_reason}"
    print(f"  contract ({report.profile.value}; {how}):")
    for r in report.roles:
        kind = "required" if r.required else "optional"
        if r.problem is None:
            print(f"    {r.role:<16} {kind:<9} -> {r.variable} [{r.unit or 'SI'}]")
        else:
            print(f"    {r.role:<16} {kind:<9} -- {r.problem}")
    for problem in report.problems:
        print(f"    problem: {problem}")
    if report.ok:
        print(f"  satisfies the {report.profile.value} contract")
        return 0
    reasons = []
    if report.missing:
        reasons.append(f"missing roles: {', '.join(report.missing)}")
    if report.problems:
        reasons.append(f"{len(report.problems)} problem(s) above")
    print(f"  does NOT satisfy the {report.profile.value} contract; {'; '.join(reasons)}")
    return 4


def _check_step_response_args(args: argparse.Namespace) -> None:
    if not (math.isfinite(args.step_ms) and 1e-6 <= args.step_ms <= 1000.0):  # at least the clock's 1 ns
        msg = f"--step-ms must be a communication step from 1e-06 ms (1 ns) to 1000 ms, got {args.step_ms}"
        raise ConfigError(msg)
    if args.duration_s is not None and not (math.isfinite(args.duration_s) and args.duration_s > 0.0):
        msg = f"--duration-s must be a positive, finite number of seconds, got {args.duration_s}"
        raise ConfigError(msg)
    if args.duration_s is not None and args.duration_s / (args.step_ms * 1e-3) > 10_000_000:
        msg = f"--duration-s {args.duration_s} at --step-ms {args.step_ms} is over 10 million steps; shorten it"
        raise ConfigError(msg)
    if not (math.isfinite(args.voltage) and abs(args.voltage) <= _MAX_VOLTAGE_V):
        msg = f"--voltage must be a finite number of volts, at most {_MAX_VOLTAGE_V:g} V either way, got {args.voltage}"
        raise ConfigError(msg)
    if args.out is not None:
        if args.out.suffix.lower() != ".png":  # (matplotlib refused other names deep inside: exit 70)
            msg = f"--out {args.out}: the plot is a PNG; give a file name ending in .png"
            raise ConfigError(msg)
        folder = args.out.parent if str(args.out.parent) else Path(".")
        while not folder.exists() and folder != folder.parent:
            folder = folder.parent
        if args.out.is_dir() or not os.access(folder, os.W_OK | os.X_OK):
            msg = f"--out {args.out}: cannot write a PNG there (read-only, or a folder); choose another --out"
            raise ConfigError(msg)


def _step_response(args: argparse.Namespace) -> int:
    from twin.cosim.build import resolve_fmu
    from twin.robot.fmu_drive import MotorModelError
    from twin.robot.step_response import fmu_step_response

    _check_step_response_args(args)

    path = resolve_fmu(args.fmu, fmi_version=args.fmi)
    mapping, motor_model = _mapping(args.map), None
    if args.scenario is not None:
        drive = _scenario_drive(args.scenario)
        motor_model = drive.motor
        if args.map is None:
            try:
                mapping = drive.resolved_mapping()
            except ConfigError as err:
                raise err.with_context(before=f"{args.scenario}: drive.mapping: ") from None
    _refuse_servo(path, mapping, args.fmu)
    try:
        comparison, motor = fmu_step_response(
            path,
            voltage_v=args.voltage,
            step_s=args.step_ms * 1e-3,
            duration_s=args.duration_s,
            mapping=mapping,
            motor_model=motor_model,
        )
    except MotorModelError as err:
        if args.scenario is not None:
            raise err.with_context(before=f"{args.scenario}: ") from None
        # The default motor model names the project's parameters; another FMU needs its own.
        field = err.key.removeprefix("drive.motor").lstrip(".")
        msg = (
            f"{path}: the step response compares the FMU with its linear motor model, but "
            f"{err.problem}{f' (for {field})' if field else ''}; pass --scenario FILE whose drive.motor gives "
            "the motor's constants (numbers in SI or this FMU's parameter names)"
        )
        raise FmuError(msg) from None
    c = comparison
    final_model = float(c.model_speed_radps[-1])
    summary = {
        "fmu": str(path),
        "voltage_v": c.voltage_v,
        "step_s": c.step_s,
        "rms_relative": c.rms_relative,
        "final_speed_fmu_radps": float(c.fmu_speed_radps[-1]),
        "final_speed_model_radps": final_model,
        "no_load_speed_model_rpm": motor.no_load_speed_radps(args.voltage) * 60.0 / (2.0 * math.pi),
        "stall_current_model_a": motor.stall_current_a(args.voltage),
    }
    if args.out is not None:
        try:
            _plot(c, args.out, path.name)
        except OSError as err:
            msg = f"{args.out}: cannot write the plot: {err.strerror}; choose another --out"
            raise BagError(msg) from None
        summary["png"] = str(args.out)
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    print(f"{path.name}: {c.voltage_v:g} V step, no load, {c.step_s * 1e3:g} ms steps")
    print(f"  {'t_s':>8}  {'fmu_radps':>10}  {'model_radps':>11}  {'diff_%':>7}  {'current_a':>9}")
    rows = sorted({round(k) for k in _spread(len(c.t_s), 12)})
    for k in rows:
        diff = 100.0 * (c.fmu_speed_radps[k] - c.model_speed_radps[k]) / abs(final_model)
        print(
            f"  {c.t_s[k]:8.4f}  {c.fmu_speed_radps[k]:10.4f}  {c.model_speed_radps[k]:11.4f}  {diff:7.3f}  "
            f"{c.current_a[k]:9.4f}"
        )
    print(f"  RMS difference: {100.0 * c.rms_relative:.4f} % of the final speed")
    print(
        f"  model: no-load {summary['no_load_speed_model_rpm']:.2f} rpm, stall {summary['stall_current_model_a']:.3f} A"
    )
    if args.out is not None:
        print(f"  plot: {args.out}")
    return 0


def _refuse_servo(path: Path, mapping: FmuMapping, name: str) -> None:
    """Refuse, in words, an FMU that takes a speed setpoint: the step response steps a voltage."""
    from twin.cosim.contract import Profile, infer_profile
    from twin.cosim.description import read_fmu_info

    profile, _ = infer_profile(read_fmu_info(path), mapping)
    if profile is Profile.VELOCITY_SERVO:
        msg = (
            f"{path}: step-response supports voltage-profile FMUs only (it steps the motor voltage, no load), "
            "and this one is a velocity-servo FMU (a speed-setpoint input, no voltage input); "
            f"`twin fmu check {name}` checks it, and a drive runs it with profile: velocity-servo"
        )
        raise FmuError(msg)


def _scenario_drive(path: Path) -> FmuDrive:
    """The FMU drive section of the scenario at `path`, with a motor model.

    Raises:
        ConfigError: If the scenario does not load, its drive is not an FMU drive or has `motor: null`.
    """
    from twin.robot.fmu_drive import FmuDrive
    from twin.sim.scenario_file import load_scenario

    drive = load_scenario(path).drive
    if not isinstance(drive, FmuDrive):
        msg = f"{path}: drive: is {drive.type}; --scenario takes drive.motor from an FMU drive (type: fmu)"
        raise ConfigError(msg)
    if drive.motor is None:
        msg = f"{path}: drive.motor: is null; give the motor's constants (numbers in SI or the FMU's parameter names)"
        raise ConfigError(msg)
    return drive


def _spread(n: int, count: int) -> list[float]:
    return [k * (n - 1) / (count - 1) for k in range(count)]


def _plot(c: Any, out: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(c.t_s, c.model_speed_radps, label="linear model (python-control)", linewidth=2.5, alpha=0.6)
    ax.plot(c.t_s, c.fmu_speed_radps, "--", label="FMU", linewidth=1.5)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("wheel speed [rad/s]")
    ax.set_title(f"{title}: {c.voltage_v:g} V step, RMS diff {100 * c.rms_relative:.3g} %")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    plt.close(fig)
