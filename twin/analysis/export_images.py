"""`twin bag export --format png`: the frames of image topics as PNG files, one folder per topic.

`sensor_msgs/Image` in `rgb8`, `bgr8`, `rgba8`, `bgra8`, `mono8` or `mono16` is written as it is
(bgr turned to rgb); `32FC1` depth as 16-bit PNG in millimetres (0 where not finite, as
depth_image_proc's convention for 16UC1); `sensor_msgs/CompressedImage` decoded (JPEG or PNG) and
written as PNG. A frame's file is named by its record time: `<t_ns>.png`.
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.bag import open_bag, read_messages
from twin.core.errors import BagError

__all__ = ["IMAGE_TYPES", "export_images", "image_array", "pick_frames"]

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
_CHANNELS = {"rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4, "mono8": 1}


def image_array(msg: Any, msgtype: str) -> NDArray[Any]:
    """The pixels of an Image or CompressedImage message: (h, w, 3|4) or (h, w) uint8/uint16.

    Raises:
        ValueError: For an encoding this reader does not know, or data of the wrong size.
    """
    data = np.asarray(msg.data, dtype=np.uint8)
    if msgtype.endswith("CompressedImage"):
        from PIL import Image

        return np.asarray(Image.open(io.BytesIO(data.tobytes())))
    h, w, encoding = int(msg.height), int(msg.width), str(msg.encoding)
    step = int(msg.step)
    if encoding in _CHANNELS:
        n = _CHANNELS[encoding]
        rows = data.reshape(h, step)[:, : w * n]
        pixels = rows.reshape(h, w, n) if n > 1 else rows.reshape(h, w)
        return pixels[..., [2, 1, 0, *([3] if n == 4 else [])]] if encoding.startswith("bgr") else pixels
    order = ">" if msg.is_bigendian else "<"
    if encoding == "mono16":
        return np.frombuffer(data.reshape(h, step)[:, : 2 * w].tobytes(), dtype=f"{order}u2").reshape(h, w)
    if encoding == "32FC1":
        depth = np.frombuffer(data.reshape(h, step)[:, : 4 * w].tobytes(), dtype=f"{order}f4").reshape(h, w)
        mm = np.where(np.isfinite(depth), np.clip(np.round(depth * 1000.0), 0, 65535), 0)
        return mm.astype(np.uint16)
    msg_text = f"image encoding {encoding!r} is not one of {', '.join([*_CHANNELS, 'mono16', '32FC1'])}"
    raise ValueError(msg_text)


def export_images(bag: str | os.PathLike[str], topics: Sequence[str], out_dir: Path) -> dict[str, tuple[Path, int]]:
    """Write every frame of each image topic to `out_dir/<topic>/<t_ns>.png`; return {topic: (folder, frames)}.

    Raises:
        BagError: If the bag is unreadable, lacks a topic, a topic is not an image topic, or a frame
            cannot be read.
    """
    from PIL import Image

    info = open_bag(bag)
    types = {t.name: t.msgtype for t in info.topics}
    for topic in topics:
        if topic not in types:
            msg = f"{info.path}: no topic {topic!r}; it has {', '.join(types)}"
            raise BagError(msg)
        if types[topic] not in IMAGE_TYPES:
            msg = (
                f"{info.path}: {topic} is {types[topic]}, not an image; "
                "--format png takes Image or CompressedImage topics"
            )
            raise BagError(msg)
    folders = {t: out_dir / t.strip("/").replace("/", "_") for t in topics}
    counts = dict.fromkeys(topics, 0)
    for folder in folders.values():
        folder.mkdir(parents=True, exist_ok=True)
    for m in read_messages(bag, list(topics)):
        try:
            pixels = image_array(m.msg, types[m.topic])
        except (ValueError, OSError) as err:
            msg = f"{info.path}: {m.topic} at t_ns {m.t_ns}: {err}"
            raise BagError(msg) from None
        Image.fromarray(pixels).save(folders[m.topic] / f"{m.t_ns}.png")
        counts[m.topic] += 1
    return {t: (folders[t], counts[t]) for t in topics}


def pick_frames(
    bag: str | os.PathLike[str], topic: str, msgtype: str, picks: Sequence[tuple[str, int]]
) -> list[tuple[str, NDArray[Any]]]:
    """The frames of `topic` nearest each (label, record time ns) of `picks`, in their order.

    Only the chosen frames are decoded. Frames that cannot be read are left out.
    """
    stamps = [m.t_ns for m in read_messages(bag, [topic], decode=False)]
    if not stamps:
        return []
    times = np.asarray(stamps, dtype=np.int64)
    wanted: dict[int, list[int]] = {}  # frame index -> positions in `picks`
    for position, (_, t_ns) in enumerate(picks):
        index = int(np.clip(np.searchsorted(times, t_ns), 0, len(times) - 1))
        if index > 0 and abs(times[index - 1] - t_ns) <= abs(times[index] - t_ns):
            index -= 1
        wanted.setdefault(index, []).append(position)
    found: dict[int, NDArray[Any]] = {}
    for index, positions in wanted.items():
        t_ns = int(times[index])
        for m in read_messages(bag, [topic], start_ns=t_ns, stop_ns=t_ns + 1):
            try:
                image = image_array(m.msg, msgtype)
            except (ValueError, OSError):
                break
            for position in positions:
                found[position] = image
            break
    return [(label, found[i]) for i, (label, _) in enumerate(picks) if i in found]
