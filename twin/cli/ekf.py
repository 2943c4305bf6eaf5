"""`twin ekf replay BAG`: run the odometry EKF on a recorded bag's IMU and wheel joint states."""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
import os
import sys
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

from twin.core.errors import BagError, ConfigError, EstimationError

if TYPE_CHECKING:
    from twin.estimation import EstimationSection
    from twin.estimation.replay import Comparison, ReplayInputs, ReplayResult, UnitsDecision

_EPILOG = """\
examples:
  twin ekf replay ../shared/fixtures/bags/tb3_waffle_gazebo_humble
  twin ekf replay my_robot_bag --joint-velocity-units m/s --wheel-separation 0.160 --out /tmp/fused
  twin ekf replay my_robot_bag --no-gyro --json        wheel odometry alone, numbers for a script
  twin ekf replay bags/<fleet run> --namespace robot2   one robot of a fleet: /robot2/imu, its URDF...

The filter steps on every joint state and fuses the gyro samples in between (docs/estimation.md).
It writes DIR/odometry (a rosbag2 with nav_msgs/Odometry, odom -> base_footprint) and
DIR/odometry.csv, and compares the result with the bag's own odometry topic when there is one.
Wheel radius, separation and joint names come from the flags, else from the bag's
/robot_description (URDF: the outermost pair of wheel joints with cylinder links; a skid-steer
robot's front axle), else the
TurtleBot3 Waffle's (0.033 m, 0.287 m, wheel_left_joint/wheel_right_joint); the summary says
which, and from where.
"""

_DEFAULT_GEOMETRY = {
    "wheel_radius": 0.033,
    "wheel_separation": 0.287,
    "left_joint": "wheel_left_joint",
    "right_joint": "wheel_right_joint",
}


def register(subparsers: Any, common: argparse.ArgumentParser) -> None:
    """Add the `ekf` command group."""
    parser = subparsers.add_parser(
        "ekf",
        help="run the odometry EKF offline on a bag",
        description="The odometry EKF (wheel encoders and gyro), offline.",
        parents=[common],
    )
    sub = parser.add_subparsers(dest="ekf_command", metavar="SUBCOMMAND", required=True)
    rep = sub.add_parser(
        "replay",
        help="fuse a bag's /imu and /joint_states into odometry, write it, compare it with /odom",
        description=(
            "Run the EKF on a recorded bag's IMU yaw rate and wheel joint states (any rosbag2: sqlite3 or "
            "MCAP, Humble or later, from the twin, Gazebo or a real robot). Write the fused odometry as a "
            "new bag and a CSV and, when the bag has its own odometry, report the errors against it."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    rep.add_argument("bag", type=Path, metavar="BAG", help="rosbag2 folder, or a single .mcap or .db3 file")
    rep.add_argument("--out", type=Path, metavar="DIR", help="output folder (default: bags/<BAG name>_ekf)")
    rep.add_argument(
        "--joint-velocity-units",
        choices=("auto", "rad/s", "m/s"),
        default="auto",
        help="unit of /joint_states velocity: rad/s (Gazebo) or wheel rim m/s (real TurtleBot3); "
        "auto infers it from the joint positions (default)",
    )
    rep.add_argument(
        "--wheel-radius",
        type=float,
        metavar="M",
        help="wheel radius (default: the bag's /robot_description URDF, else 0.033, TurtleBot3)",
    )
    rep.add_argument(
        "--wheel-separation",
        type=float,
        metavar="M",
        help="wheel separation (default: the bag's /robot_description URDF, else 0.287, Waffle)",
    )
    rep.add_argument(
        "--wheel-source",
        choices=("auto", "positions", "velocities"),
        default="auto",
        help="what the filter reads from /joint_states (default: positions when present)",
    )
    rep.add_argument("--no-gyro", action="store_true", help="wheel odometry alone (do not fuse the gyro)")
    rep.add_argument(
        "--start-at-origin",
        action="store_true",
        help="start at (0, 0, 0) instead of the reference odometry's first pose",
    )
    rep.add_argument(
        "--config", type=Path, metavar="FILE", help="YAML with an `estimation:` section (a scenario works)"
    )
    topics = rep.add_argument_group("topics and joints")
    topics.add_argument("--imu-topic", help="sensor_msgs/Imu topic (default /imu; with --namespace /NS/imu)")
    topics.add_argument("--joint-topic", help="sensor_msgs/JointState topic (default /joint_states)")
    topics.add_argument("--odom-topic", help="reference nav_msgs/Odometry topic (default /odom)")
    topics.add_argument("--left-joint", help="left wheel joint name (default: URDF, else wheel_left_joint)")
    topics.add_argument("--right-joint", help="right wheel joint name (default: URDF, else wheel_right_joint)")
    topics.add_argument("--topic", default="/odometry/filtered", help="topic of the fused odometry in the new bag")
    topics.add_argument(
        "--namespace",
        metavar="NS",
        help="a fleet's robot (its topics under /NS/): /NS/imu, /NS/joint_states, /NS/odom and the URDF of "
        "/NS/robot_description, unless a topic flag names another",
    )
    rep.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap", help="storage of the new bag")
    rep.add_argument("--json", action="store_true", help="print the summary as JSON")
    rep.set_defaults(func=_replay)


def _load_config(path: Path | None) -> EstimationSection:
    from twin.core.config import build, load_yaml
    from twin.estimation import EstimationSection

    if path is None:
        return EstimationSection()
    node = load_yaml(path)
    pairs = node.value if node.tag == "tag:yaml.org,2002:map" else []
    section = next((value for key, value in pairs if key.value == "estimation"), None)
    if section is None:
        msg = f"{path}: no `estimation:` section; write the EKF settings under `estimation:`"
        raise ConfigError(msg)
    config: EstimationSection = build(EstimationSection, section, key="estimation")
    return config


def _topic_hint(topics: Any, args: argparse.Namespace, missing: list[str]) -> str:
    """What to pass for the missing topics: the bag's topics of the right type as flags, else its topics."""
    flags = {
        args.imu_topic: ("--imu-topic", "sensor_msgs/msg/Imu"),
        args.joint_topic: ("--joint-topic", "sensor_msgs/msg/JointState"),
    }
    if args.joint_topic in missing and not any(t.msgtype == "sensor_msgs/msg/JointState" for t in topics):
        # Without wheel joint states there is nothing to fuse: --no-gyro would fail the same way.
        listing = ", ".join(sorted(t.name for t in topics)) or "no topics"
        return (
            "the EKF needs the wheels' joint states (sensor_msgs/JointState) and the bag has none "
            f"(it has {listing}); record the robot's /joint_states (or its wheel encoders as JointState)"
        )
    hints = []
    for name in missing:
        flag, msgtype = flags[name]
        found = sorted(t.name for t in topics if t.msgtype == msgtype)
        if found:
            hints.append(f"{flag} {found[0]}" + (f" (or {', '.join(found[1:])})" if len(found) > 1 else ""))
        elif flag == "--imu-topic":
            hints.append("--no-gyro (the bag has no sensor_msgs/Imu topic)")
    if hints:
        return "pass " + " and ".join(hints)
    listing = ", ".join(sorted(t.name for t in topics)) or "no topics"
    return f"the bag has {listing} and no {' or '.join(flags[n][1] for n in missing)} topic"


def _read(args: argparse.Namespace, bag: ModuleType) -> ReplayInputs:
    from twin.estimation.replay import collect_inputs

    info = bag.open_bag(args.bag)
    names = {t.name for t in info.topics}
    missing = [t for t in (args.imu_topic, args.joint_topic) if t not in names]
    if missing and not (args.no_gyro and missing == [args.imu_topic]):
        msg = f"{args.bag}: no {' or '.join(missing)} to replay; " + _topic_hint(info.topics, args, missing)
        raise EstimationError(msg)
    from twin.bag.typesys import message_type_name

    types = {t.name: message_type_name(t.msgtype) for t in info.topics}
    expected = (
        ("--imu-topic", args.imu_topic, ("sensor_msgs/msg/Imu",)),
        ("--joint-topic", args.joint_topic, ("sensor_msgs/msg/JointState",)),
        ("--odom-topic", args.odom_topic, ("nav_msgs/msg/Odometry",)),
    )
    for flag, topic, kinds in expected:
        if topic in types and types[topic] not in kinds and not (flag == "--imu-topic" and args.no_gyro):
            found = sorted(n for n, k in types.items() if k in kinds)
            fix = f"pass {flag} {found[0]}" if found else f"the bag has no {kinds[0]} topic"
            msg = f"{args.bag}: {flag} {topic} is {types[topic]}, not {kinds[0]}; {fix}"
            raise EstimationError(msg)
    wanted = [t for t in (args.imu_topic, args.joint_topic, args.odom_topic) if t in names]
    messages = bag.read_messages(args.bag, wanted)
    return collect_inputs(
        messages,
        imu_topic=args.imu_topic,
        joint_topic=args.joint_topic,
        reference_topic=args.odom_topic if args.odom_topic in names else None,
        left_joint=args.left_joint,
        right_joint=args.right_joint,
    )


def _write_csv(path: Path, result: ReplayResult, comparison: Comparison | None) -> None:
    import numpy as np

    pose, twist = result.pose_covariance, result.twist_covariance
    columns = {
        "t_ns": result.t_ns,
        "x_m": result.x_m,
        "y_m": result.y_m,
        "yaw_rad": result.yaw_rad,
        "v_mps": result.v_mps,
        "yaw_rate_radps": result.yaw_rate_radps,
        "gyro_bias_radps": result.gyro_bias_radps,
        "var_x_m2": pose[:, 0],
        "var_y_m2": pose[:, 7],
        "cov_xy_m2": pose[:, 1],
        "var_yaw_rad2": pose[:, 35],
        "var_v_m2ps2": twist[:, 0],
        "var_yaw_rate_rad2ps2": twist[:, 35],
    }
    if comparison is not None:
        nan = np.where(comparison.compared, 1.0, np.nan)
        columns |= {
            "ref_x_m": comparison.reference_x_m * nan,
            "ref_y_m": comparison.reference_y_m * nan,
            "ref_yaw_rad": comparison.reference_yaw_rad * nan,
            "position_error_m": comparison.position_error_m * nan,
            "yaw_error_rad": comparison.yaw_error_rad * nan,
        }
    table = np.column_stack([np.asarray(v, dtype=float) for v in columns.values()])
    fmt = ["%d"] + ["%.9g"] * (len(columns) - 1)
    np.savetxt(path, table, fmt=fmt, delimiter=",", header=",".join(columns), comments="")


def _write_bag(path: Path, result: ReplayResult, args: argparse.Namespace, bag: ModuleType) -> None:
    encoder = bag.OdometryEncoder("odom", "base_footprint")
    with bag.Recorder(path, storage=args.storage, distro="humble") as recorder:
        handle = recorder.add_topic(args.topic, encoder.msgtype)
        for i, t_ns in enumerate(result.t_ns.tolist()):
            data = encoder.encode(
                t_ns,
                float(result.x_m[i]),
                float(result.y_m[i]),
                float(result.yaw_rad[i]),
                float(result.v_mps[i]),
                float(result.yaw_rate_radps[i]),
                result.pose_covariance[i],
                result.twist_covariance[i],
            )
            recorder.write(handle, t_ns, data)


def _resolve_geometry(args: argparse.Namespace, bag_mod: ModuleType) -> dict[str, str]:
    """Fill the wheel geometry and joint names left unset: the bag's URDF, else the defaults.

    Returns:
        {setting: where it came from}, for the summary.
    """
    from twin.world.urdf_wheels import wheels_from_urdf

    sources = {k: "--" + k.replace("_", "-") for k in _DEFAULT_GEOMETRY if getattr(args, k) is not None}
    if len(sources) == len(_DEFAULT_GEOMETRY):
        return sources
    urdf = None
    info = bag_mod.open_bag(args.bag)
    description = getattr(args, "description_topic", "/robot_description")
    if description in {t.name for t in info.topics}:
        for m in bag_mod.read_messages(args.bag, [description]):
            urdf = wheels_from_urdf(str(m.msg.data))
            break
    found = (
        {}
        if urdf is None
        else {
            "wheel_radius": urdf.wheel_radius_m,
            "wheel_separation": urdf.wheel_separation_m,
            "left_joint": urdf.left_joint,
            "right_joint": urdf.right_joint,
        }
    )
    for key, default in _DEFAULT_GEOMETRY.items():
        if getattr(args, key) is not None:
            continue
        if key in found:
            setattr(args, key, found[key])
            assert urdf is not None
            sources[key] = f"{description} (URDF of {urdf.robot or 'the robot'})"
            if urdf.skid_steer and key in ("left_joint", "right_joint"):
                side = urdf.left_joints if key == "left_joint" else urdf.right_joints
                sources[key] += f"; skid-steer, the front one of {'/'.join(side)}"
        else:
            setattr(args, key, default)
            reason = f"no {description}" if urdf is None and not found else "not in the URDF"
            sources[key] = f"TurtleBot3 Waffle default ({reason})"
    guessed = [f"--{k.replace('_', '-')}" for k in ("wheel_radius", "wheel_separation") if "default" in sources[k]]
    joints = (args.left_joint, args.right_joint)
    if guessed and joints != (_DEFAULT_GEOMETRY["left_joint"], _DEFAULT_GEOMETRY["right_joint"]):
        logging.getLogger("twin.cli.ekf").warning(
            "the wheels %s and %s are not a TurtleBot3's, yet their %s are the TurtleBot3 Waffle's defaults "
            "(nothing in the bag's %s gives them): give %s",
            *joints,
            " and ".join(g.removeprefix("--wheel-") for g in guessed),
            description,
            " and ".join(guessed),
        )
    return sources


_TOPIC_DEFAULTS = {"imu_topic": "/imu", "joint_topic": "/joint_states", "odom_topic": "/odom"}


def _pick_robot(args: argparse.Namespace, bag_mod: ModuleType) -> None:
    """With `--namespace NS`, read that robot's topics and URDF; a fleet's bag without it is refused.

    Raises:
        ConfigError: A namespace the bag has no robot under, or a fleet's bag whose robot is not chosen.
    """
    from twin.analysis.fleet import check_namespace
    from twin.bag import robot_namespaces

    info = bag_mod.open_bag(args.bag)
    args.description_topic = "/robot_description"
    robots = robot_namespaces(info)
    names = {t.name for t in info.topics}
    if args.namespace is None and len(robots) == 1 and "/joint_states" not in names:
        args.namespace = robots[0]  # one robot, all under its namespace: that robot, as analyze reads it
        logging.getLogger("twin.cli.ekf").info("%s: the robot under /%s/", info.path, robots[0])
    if args.namespace is None:
        for key, default in _TOPIC_DEFAULTS.items():
            if getattr(args, key) is None:
                setattr(args, key, default)
        if robots and args.joint_topic not in names:
            msg = (
                f"{info.path}: a fleet's bag (robots {', '.join(robots)}) has no {args.joint_topic}; "
                f"pick a robot with --namespace (e.g. --namespace {robots[0]})"
            )
            raise ConfigError(msg)
        return
    ns = check_namespace(info, args.namespace)
    for key, default in _TOPIC_DEFAULTS.items():
        if getattr(args, key) is None:  # a topic given by its flag is read as given
            setattr(args, key, f"/{ns}{default}")
    args.description_topic = f"/{ns}/robot_description"


def _free_name(base: Path) -> Path:
    """`base`, or `base_2`, `base_3`, ... : the first that does not exist (a default never collides)."""
    path, n = base, 1
    while path.exists():
        n += 1
        path = base.with_name(f"{base.name}_{n}")
    return path


def _check_writable(out: Path, option: str) -> None:
    """Refuse an output folder that cannot be created or written, before any work is done."""
    existing = out
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir() or not os.access(existing, os.W_OK | os.X_OK):
        msg = f"{option} {out}: cannot write in {existing} (read-only or not a folder); choose another {option}"
        raise ConfigError(msg)


_MAX_WHEEL_M = 100.0  # a wheel radius or track this long is a typo (a TurtleBot3's: 0.033 and 0.287 m)


def _replay(args: argparse.Namespace) -> int:
    from twin import bag
    from twin.estimation.replay import UnitsDecision, compare, infer_velocity_units, replay

    for flag, value in (("--wheel-radius", args.wheel_radius), ("--wheel-separation", args.wheel_separation)):
        if value is not None and not (0.0 < value <= _MAX_WHEEL_M):  # NaN and inf too; before the bag is read
            msg = f"{flag} must be a length in metres above 0 and at most {_MAX_WHEEL_M:g}, got {value}"
            raise ConfigError(msg)
    bag.require_readable(args.bag)  # a truncated file: one error line, not a warning per reading first
    _pick_robot(args, bag)
    geometry_sources = _resolve_geometry(args, bag)
    if not (args.wheel_radius > 0.0 and args.wheel_separation > 0.0):
        msg = (
            "--wheel-radius and --wheel-separation must be positive, "
            f"got {args.wheel_radius} and {args.wheel_separation}"
        )
        raise ConfigError(msg)
    config = _load_config(args.config)
    if args.no_gyro:
        config = dataclasses.replace(config, fuse_gyro=False)
    out = args.out if args.out is not None else _free_name(Path("bags") / f"{args.bag.resolve().name}_ekf")
    bag_out = out / "odometry"
    if bag_out.exists() and any(bag_out.iterdir()):
        msg = f"{bag_out} exists and is not empty; choose another --out or remove it"
        raise EstimationError(msg)
    _check_writable(out, "--out")
    inputs = _read(args, bag)
    if args.joint_velocity_units == "auto":
        units = infer_velocity_units(inputs, args.wheel_radius)
    else:
        units = UnitsDecision(units=args.joint_velocity_units, how="given", ratio=None)
    result = replay(
        inputs,
        config,
        wheel_radius_m=args.wheel_radius,
        wheel_separation_m=args.wheel_separation,
        velocity_units=units.units,
        wheel_source=args.wheel_source,
        start_at_reference=not args.start_at_origin,
    )
    comparison = compare(result, inputs.reference) if inputs.reference is not None else None
    try:
        out.mkdir(parents=True, exist_ok=True)
        csv_path = out / "odometry.csv"
        _write_csv(csv_path, result, comparison)
    except OSError as err:
        msg = f"{out}: cannot write the replay's output: {err.strerror}; choose another --out"
        raise BagError(msg) from None
    _write_bag(bag_out, result, args, bag)
    summary = _summary(
        args,
        fused=config.fuse_gyro,
        inputs=inputs,
        units=units,
        result=result,
        comparison=comparison,
        bag_out=bag_out,
        csv_path=csv_path,
    )
    summary["geometry_sources"] = geometry_sources
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        _print_summary(summary)
    return 0


def _summary(
    args: argparse.Namespace,
    *,
    fused: bool,
    inputs: ReplayInputs,
    units: UnitsDecision,
    result: ReplayResult,
    comparison: Comparison | None,
    bag_out: Path,
    csv_path: Path,
) -> dict[str, Any]:
    summary: dict[str, Any] = {
        "bag": str(args.bag),
        "joint_states": len(inputs.joint_t_ns),
        "imu_samples": len(inputs.gyro_t_ns),
        "gyro_fused": fused,
        "gyro_samples_fused": result.gyro_samples if fused else 0,
        "wheel_radius_m": args.wheel_radius,
        "wheel_separation_m": args.wheel_separation,
        "left_joint": args.left_joint,
        "right_joint": args.right_joint,
        "wheel_source": result.wheel_source,
        "joint_velocity_units": units.units,
        "joint_velocity_units_how": units.how,
        "joint_velocity_units_note": units.describe(args.wheel_radius),
        "slip_detections": result.slip_detections,
        "final_gyro_bias_radps": float(result.gyro_bias_radps[-1]),
        "start": "reference" if inputs.reference is not None and not args.start_at_origin else "origin",
        "start_pose": [float(result.x_m[0]), float(result.y_m[0]), float(result.yaw_rad[0])],
        "bag_out": str(bag_out),
        "topic_out": args.topic,
        "csv_out": str(csv_path),
        "reference_topic": args.odom_topic if comparison is not None else None,
    }
    if comparison is not None:
        summary["comparison"] = {
            "samples": comparison.samples,
            "duration_s": comparison.duration_s,
            "distance_m": comparison.distance_m,
            "position_error_mean_m": comparison.position_error_mean_m,
            "position_error_rms_m": comparison.position_error_rms_m,
            "position_error_max_m": comparison.position_error_max_m,
            "position_error_final_m": comparison.position_error_final_m,
            "final_error_percent_of_distance": comparison.final_error_percent_of_distance,
            "yaw_error_mean_deg": math.degrees(comparison.yaw_error_mean_rad),
            "yaw_error_rms_deg": math.degrees(comparison.yaw_error_rms_rad),
            "yaw_error_max_deg": math.degrees(comparison.yaw_error_max_rad),
            "yaw_error_final_deg": math.degrees(comparison.yaw_error_final_rad),
        }
    return summary


def _print_summary(s: dict[str, Any]) -> None:
    x, y, yaw = s["start_pose"]
    gyro = f"fused ({s['gyro_samples_fused']} samples)" if s["gyro_fused"] else "not fused (wheel odometry alone)"
    lines = [
        f"twin ekf replay {s['bag']}",
        f"  inputs     {s['joint_states']} joint states, {s['imu_samples']} IMU samples",
        f"  wheels     radius {s['wheel_radius_m']:g} m, separation {s['wheel_separation_m']:g} m; "
        f"speeds from joint {s['wheel_source']}",
        f"  geometry   radius from {s['geometry_sources']['wheel_radius']}, separation from "
        f"{s['geometry_sources']['wheel_separation']}",
        f"  joints     {s['left_joint']} / {s['right_joint']} from {s['geometry_sources']['left_joint']}",
        f"  velocity   {s['joint_velocity_units_note']}",
        f"  gyro       {gyro}; final bias {s['final_gyro_bias_radps']:.2e} rad/s; "
        f"slip detections {s['slip_detections']}",
        f"  start      at the {s['start']} ({x:.3f} m, {y:.3f} m, {math.degrees(yaw):.2f} deg)",
        f"  wrote      {s['bag_out']} ({s['topic_out']}), {s['csv_out']}",
    ]
    c = s.get("comparison")
    if c is None:
        lines.append("  compare    no reference odometry in the bag")
    else:
        lines += [
            "",
            f"against {s['reference_topic']} over {c['duration_s']:.1f} s and {c['distance_m']:.3f} m travelled:",
            "                 mean       rms       max     final",
            "  position  "
            + "".join(
                f"{c[k] * 1000:8.2f}mm"
                for k in (
                    "position_error_mean_m",
                    "position_error_rms_m",
                    "position_error_max_m",
                    "position_error_final_m",
                )
            ),
            "  yaw       "
            + "".join(
                f"{c[k]:9.3f}°"
                for k in ("yaw_error_mean_deg", "yaw_error_rms_deg", "yaw_error_max_deg", "yaw_error_final_deg")
            ),
            f"  final position error: {c['final_error_percent_of_distance']:.3f} % of the distance travelled",
        ]
    print("\n".join(lines), file=sys.stdout)
