"""How a bag was made: the resolved scenario, the twin version, the seed and every FMU binary.

A run records its provenance where standard tools keep it without getting in the way: in MCAP an
`twin_provenance` Metadata record (read by `mcap info`, Foxglove and the MCAP libraries); in
sqlite3, which has no such records, a latched `/twin/provenance` topic (`std_msgs/msg/String`,
the values as a JSON object) with one message at t = 0. Every value is a string; `fmus` is a JSON
list of `{file, sha256, model_name, guid}`.
"""

from __future__ import annotations

import contextlib
import json
import os
import sqlite3
import struct
from collections.abc import Mapping
from pathlib import Path

from twin.bag.mcap_file import scan_mcap
from twin.bag.metadata import METADATA_FILE, read_metadata
from twin.bag.sqlite_file import connect_readonly
from twin.core.errors import BagError

__all__ = ["PROVENANCE_NAME", "PROVENANCE_TOPIC", "decode_provenance_message", "read_provenance"]

PROVENANCE_NAME = "twin_provenance"  # the MCAP Metadata record's name
PROVENANCE_TOPIC = "/twin/provenance"  # the sqlite3 bag's topic


def decode_provenance_message(data: bytes) -> dict[str, str]:
    """The values of a `/twin/provenance` message (CDR `std_msgs/msg/String` holding JSON)."""
    (length,) = struct.unpack_from("<I", data, 4)
    text = data[8 : 8 + length].rstrip(b"\0").decode("utf-8")
    values = json.loads(text)
    return {str(k): str(v) for k, v in values.items()}


def _storage_files(bag: Path) -> list[Path]:
    """The storage files of the bag at `bag` (a folder or a single file), as its metadata.yaml lists them."""
    if bag.is_file():
        return [bag]
    if (bag / METADATA_FILE).exists():
        return [bag / Path(rel).name for rel in read_metadata(bag).relative_file_paths]
    files = sorted(p for p in bag.glob("*") if p.suffix in (".mcap", ".db3"))
    if not files:
        msg = f"{bag}: no metadata.yaml, no .mcap or .db3 file (is it a bag folder?)"
        raise BagError(msg)
    return files


def read_provenance(path: str | os.PathLike[str]) -> Mapping[str, str] | None:
    """The provenance a twin run recorded in the bag at `path` (a folder or a storage file), or None.

    Raises:
        BagError: If the bag cannot be read.
    """
    bag = Path(path)
    for file in _storage_files(bag):
        if file.suffix not in (".mcap", ".db3"):
            continue  # a file-compressed bag (`.mcap.zstd`): the twin never writes one
        try:
            if file.suffix == ".mcap":
                for _, _, name, values in scan_mcap(file).metadata:
                    if name == PROVENANCE_NAME:
                        return dict(values)
            else:
                with contextlib.closing(connect_readonly(file)) as db:
                    row = db.execute(
                        "SELECT m.data FROM messages m JOIN topics t ON m.topic_id = t.id WHERE t.name = ? LIMIT 1",
                        (PROVENANCE_TOPIC,),
                    ).fetchone()
                if row is not None:
                    return decode_provenance_message(bytes(row[0]))
        except (OSError, ValueError, sqlite3.Error) as err:
            msg = f"{file}: cannot read the bag's provenance: {err}"
            raise BagError(msg) from None
    return None
