"""`twin bag export BAG --topics ... --format csv|parquet|png`: topics as tables, one file per topic; images as PNG."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

_EPILOG = """\
examples:
  twin bag export ../shared/fixtures/bags/tb3_waffle_gazebo_humble --topics /odom /cmd_vel --out /tmp/csv
  twin bag export bags/run1 --topics /ground_truth/odom --format parquet      needs pip install 'twin[parquet]'
  twin bag export bags/run1 --topics /camera/image_raw --format png          one PNG per frame

One file per topic (/odom -> odom.csv). Columns: t_ns (the record time), then each field by its ROS
path (pose.pose.position.x, header.stamp.sec). Numeric arrays (ranges, covariance) are one column
(space-separated in CSV, a list in Parquet); sequences of messages (a TFMessage's transforms) one
JSON column. --format png writes each frame of Image/CompressedImage topics as <out>/<topic>/<t_ns>.png
(32FC1 depth as 16-bit millimetres). Exit codes: 0 done, 2 bad format or pyarrow missing, 5 unreadable
bag or unknown topic.
"""


def add_export_parser(sub: Any, common: argparse.ArgumentParser) -> None:
    """Add `twin bag export` to the `bag` group's subparsers."""
    parser = sub.add_parser(
        "export",
        help="write topics as CSV or Parquet tables (one file per topic, ROS field names as columns), or images as PNG",
        description="Export a bag's topics as tables: one row per message, one column per field.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    parser.add_argument("bag", type=Path, metavar="BAG", help="bag folder, or a single .mcap or .db3 file")
    parser.add_argument("--topics", nargs="+", required=True, metavar="TOPIC", help="topics to export")
    parser.add_argument(
        "--format",
        choices=("csv", "parquet", "png"),
        default="csv",
        help="table format, or png for images (default: csv)",
    )
    parser.add_argument("--out", type=Path, metavar="DIR", help="output folder (default: bags/<BAG name>_export)")
    parser.add_argument("--json", action="store_true", help="print the files written as JSON")
    parser.set_defaults(func=_export)


def _export(args: argparse.Namespace) -> int:
    from twin.analysis.export import export_topics
    from twin.core.errors import BagError

    bag: Path = args.bag
    out = args.out if args.out is not None else Path("bags") / f"{bag.resolve().name}_export"
    try:
        written = export_topics(bag, args.topics, out, fmt=args.format)
    except OSError as err:
        msg = f"{out}: cannot write the tables ({err.strerror or err}); choose another --out"
        raise BagError(msg) from None
    if args.json:
        print(json.dumps({t: {"file": str(p), "rows": n} for t, (p, n) in written.items()}, indent=2))
    else:
        for topic, (path, rows) in written.items():
            print(f"{topic}: {rows} {'frames' if args.format == 'png' else 'rows'} -> {path}")
    return 0
