"""`twin bag info BAG` and `twin bag recover DIR`: look into rosbag2 bags and repair killed recordings."""

from __future__ import annotations

import argparse
import datetime as dt
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from twin.bag import BagInfo, RecoveryReport
    from twin.bag.qos import QosProfile

from twin.cli.bag_export import add_export_parser

_INFO_EPILOG = """\
examples:
  twin bag info bags/run1
  twin bag info ../shared/fixtures/bags/tb3_waffle_gazebo_humble
  twin bag info bags/run1 --json | jq '.topics[] | {name, message_count}'

Times are UTC. "Definition" says where a topic's message definition comes from: embedded in the
bag, the type store (Humble's standard types, nav2_msgs, twin_msgs), or none (not decodable).
"""

_RECOVER_EPILOG = """\
examples:
  twin bag recover bags/run1        after the recording process was killed

A killed recording leaves its storage file without an end (MCAP: no summary or footer, maybe a
partial chunk; sqlite3: maybe an interrupted transaction) and no metadata.yaml. recover keeps every
complete record and writes metadata.yaml. A damaged file loses only its damaged parts: an MCAP
chunk that does not check out is skipped (not everything after it), a sqlite3 file that fails its
integrity check keeps every row that still reads. A storage file is never changed in place: the
repaired copy is written beside it and read back first, and a damaged original is kept as
<name>.orig. A complete bag is left untouched.
"""


def register(subparsers: Any, common: argparse.ArgumentParser) -> None:
    """Add the `bag` command group."""
    parser = subparsers.add_parser(
        "bag",
        help="inspect and repair ROS 2 bags",
        description="ROS 2 bags (rosbag2 folders with MCAP or sqlite3 storage).",
        parents=[common],
    )
    sub = parser.add_subparsers(dest="bag_command", metavar="SUBCOMMAND", required=True)
    info = sub.add_parser(
        "info",
        help="summarise a bag like `ros2 bag info` (files, duration, topics, counts, types, QoS)",
        description="Print what a rosbag2 bag holds: any metadata version (4 to 9), MCAP or sqlite3.",
        epilog=_INFO_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    info.add_argument("bag", type=Path, metavar="BAG", help="bag folder, or a single .mcap or .db3 file")
    info.add_argument("--json", action="store_true", help="print the summary as JSON")
    info.set_defaults(func=_info)
    recover = sub.add_parser(
        "recover",
        help="complete a bag left by a killed recording and rebuild its metadata.yaml",
        description="Make the bag in DIR complete and indexed again after its recording was killed.",
        epilog=_RECOVER_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    recover.add_argument("dir", type=Path, metavar="DIR", help="bag folder, or a single .mcap or .db3 file")
    recover.add_argument("--json", action="store_true", help="print the outcome as JSON")
    recover.set_defaults(func=_recover)
    add_export_parser(sub, common)


def _size(n: int) -> str:
    value = float(n)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if value < 1024 or unit == "GiB":
            return f"{value:.1f} {unit}" if unit != "B" else f"{n} B"
        value /= 1024
    return f"{n} B"  # pragma: no cover


def _stamp(t_ns: int) -> str:
    sec, nsec = divmod(t_ns, 1_000_000_000)
    when = dt.datetime.fromtimestamp(sec, tz=dt.UTC)
    return f"{when:%b %d %Y %H:%M:%S}.{nsec:09d} ({sec}.{nsec:09d})"


def _qos_json(profile: QosProfile) -> dict[str, Any]:
    return {
        "history": profile.history.name.lower(),
        "depth": profile.depth,
        "reliability": profile.reliability.name.lower(),
        "durability": profile.durability.name.lower(),
        "deadline": profile.deadline._asdict(),
        "lifespan": profile.lifespan._asdict(),
        "liveliness": profile.liveliness.name.lower(),
        "liveliness_lease_duration": profile.liveliness_lease_duration._asdict(),
        "avoid_ros_namespace_conventions": profile.avoid_ros_namespace_conventions,
    }


def info_json(info: BagInfo) -> dict[str, Any]:
    """The JSON form of `twin bag info`."""
    return {
        "path": str(info.path),
        "version": info.version,
        "storage": info.storage,
        "ros_distro": info.ros_distro,
        "files": [{"path": f.path, "size_bytes": f.size_bytes, "message_count": f.message_count} for f in info.files],
        "size_bytes": info.size_bytes,
        "start_ns": info.start_ns,
        "end_ns": info.end_ns,
        "duration_ns": info.duration_ns,
        "message_count": info.message_count,
        "compression_format": info.compression_format,
        "compression_mode": info.compression_mode,
        "custom_data": dict(info.custom_data),
        "topics": [
            {
                "name": t.name,
                "type": t.msgtype,
                "message_count": t.message_count,
                "serialization_format": t.serialization_format,
                "qos": [_qos_json(q) for q in t.qos],
                "type_hash": t.type_hash,
                "definition": t.definition,
                "decodable": t.decodable,
            }
            for t in info.topics
        ],
    }


def _provenance_lines(provenance: Any) -> list[str]:
    """`twin bag info`'s lines for a twin run's provenance."""
    lines = [
        f"twin {provenance.get('twin_version', '?')}, seed {provenance.get('seed', '?')}"
        + (f", duration {provenance['duration_s']} s" if provenance.get("duration_s") else "")
        + " (re-run: twin simulate --from-bag BAG)"
    ]
    name = next(
        (line[6:] for line in provenance.get("scenario_yaml", "").splitlines() if line.startswith("name: ")), ""
    )
    if name:
        lines.append(f"scenario {name} (resolved YAML recorded)")
    lines.extend(
        f"FMU {f.get('file')} | model {f.get('model_name')} | GUID {f.get('guid')} | SHA-256 {f.get('sha256')}"
        for f in json.loads(provenance.get("fmus", "[]"))
    )
    return lines


def _info(args: argparse.Namespace) -> int:
    from twin.bag import open_bag, read_provenance
    from twin.bag.qos import qos_summary

    info = open_bag(args.bag)
    provenance = read_provenance(info.path)
    if args.json:
        print(json.dumps({**info_json(info), "provenance": dict(provenance) if provenance else None}, indent=2))
        return 0
    label = "{:<19}".format
    print(label("Files:") + ("\n" + " " * 19).join(f.path for f in info.files))
    print(label("Bag size:") + _size(info.size_bytes))
    print(label("Storage id:") + info.storage)
    print(label("Version:") + (str(info.version) if info.version else "-"))
    print(label("ROS distro:") + (info.ros_distro or "-"))
    print(label("Duration:") + f"{info.duration_ns / 1e9:.9f}s")
    # An empty bag has no first or last message (rosbag2 records the start as INT64_MAX: Apr 11 2262)
    print(label("Start:") + (_stamp(info.start_ns) if info.message_count else "-"))
    print(label("End:") + (_stamp(info.end_ns) if info.message_count else "-"))
    print(label("Messages:") + str(info.message_count))
    if info.compression_format:
        print(label("Compression:") + f"{info.compression_format} ({info.compression_mode})")
    lines = [
        f"Topic: {t.name} | Type: {t.msgtype} | Count: {t.message_count} | "
        f"Serialization Format: {t.serialization_format} | QoS: {qos_summary(t.qos)} | Definition: {t.definition}"
        for t in info.topics
    ]
    print(label("Topic information:") + ("\n" + " " * 19).join(lines or ["(none)"]))
    if provenance is not None:
        print(label("Twin provenance:") + ("\n" + " " * 19).join(_provenance_lines(provenance)))
    undecodable = [t for t in info.topics if not t.decodable]
    if undecodable:
        names = ", ".join(f"{t.name} ({t.msgtype})" for t in undecodable)
        print(f"\nNo definition, cannot decode: {names}")
    return 0


def _recover_json(report: RecoveryReport) -> dict[str, Any]:
    return {
        "path": str(report.path),
        "storage": report.storage,
        "files": list(report.files),
        "message_count": report.message_count,
        "topics": dict(report.topic_counts),
        "was_complete": report.was_complete,
        "dropped_bytes": report.dropped_bytes,
        "kept_originals": dict(report.kept_originals),
        "metadata_version": report.metadata.version,
        "ros_distro": report.metadata.ros_distro,
    }


def _recover(args: argparse.Namespace) -> int:
    from twin.bag import recover_bag

    report = recover_bag(args.dir)
    if args.json:
        print(json.dumps(_recover_json(report), indent=2))
        return 0
    if report.was_complete:
        state = "complete (nothing changed)"
    elif report.kept_originals:
        kept = ", ".join(f"{name} as {orig}" for name, orig in report.kept_originals)
        lost = f"{_size(report.dropped_bytes)} of damaged records skipped; " if report.dropped_bytes else ""
        state = f"recovered from damage ({lost}original kept: {kept})"
    elif report.dropped_bytes:
        state = f"recovered ({_size(report.dropped_bytes)} of partial records cut)"
    else:
        state = "recovered"
    if report.path.is_file():
        form = "a single file: no metadata.yaml needed"
    else:
        distro = report.metadata.ros_distro  # (a version 5 file, Galactic's and Humble's, names none)
        form = f"metadata version {report.metadata.version}{f', {distro}' if distro else ''}"
    print(
        f"{report.path}: {report.storage} bag {state}: {report.message_count} messages on "
        f"{len(report.topic_counts)} topics ({form})"
    )
    return 0
