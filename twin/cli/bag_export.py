"""`twin bag export BAG --topics ... --format csv|parquet`: topics as tables, one file per topic."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

_EPILOG = """\
examples:
  twin bag export ../shared/fixtures/bags/tb3_waffle_gazebo_humble --topics /odom /cmd_vel --out /tmp/csv
  twin bag export bags/run1 --topics /ground_truth/odom --format parquet      needs pip install 'twin[parquet]'

One file per topic (/odom -> odom.csv). Columns: t_ns (the record time), then each field by its ROS
path (pose.pose.position.x, header.stamp.sec). Numeric arrays (ranges, covariance) are one column
(space-separated in CSV, a list in Parquet); sequences of messages (a TFMessage's transforms) one
JSON column. Exit codes: 0 done, 2 bad format or pyarrow missing, 5 unreadable bag or unknown topic.
"""


def add_export_parser(sub: Any, common: argparse.ArgumentParser) -> None:
    """Add `twin bag export` to the `bag` group's subparsers."""
    parser = sub.add_parser(
        "export",
        help="write topics as CSV or Parquet tables (one file per topic, ROS field names as columns)",
        description="Export a bag's topics as tables: one row per message, one column per field.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common],
    )
    parser.add_argument("bag", type=Path, metavar="BAG", help="bag folder, or a single .mcap or .db3 file")
    parser.add_argument("--topics", nargs="+", required=True, metavar="TOPIC", help="topics to export")
    parser.add_argument("--format", choices=("csv", "parquet"), default="csv", help="table format (default: csv)")
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
            print(f"{topic}: {rows} rows -> {path}")
    return 0
