"""map_server and map_saver: Nav2 maps (map.yaml + PGM/PNG) read and written, and a map made from the world.

Reading follows nav2_map_server's `loadMapFromFile` (Humble):

- A pixel's shade is the mean of its colour channels scaled to [0, 1] (in trinary mode an alpha
  channel counts as one more channel, `255 - alpha`); `occ = shade` when `negate`, else `1 - shade`.
- `trinary`: `occ > occupied_thresh` is 100, `occ < free_thresh` is 0, anything else -1 (unknown).
- `scale`: a pixel not fully opaque is -1; then as trinary, but values between the thresholds map
  linearly to `rint((occ - free) / (occupied - free) * 100)`.
- `raw`: the value is `round(shade * 255)` when it lies in 0..100, else -1.
- The image's top row is the map's last row (OccupancyGrid row 0 is at the origin, y up).

Writing follows map_saver's trinary output: occupied (>= occupied_thresh * 100) black 0, free
(<= free_thresh * 100) 254, anything else 205, and a YAML with `mode: trinary`, `negate: 0`
(free_thresh 0.196 by default, as TurtleBot3's map has it, so that 205 reads back as unknown).

`map_from_scene` makes a map as a SLAM run would leave it: the world's cross-section at the
lidar's height rasterised at 0.05 m, free where the robot can reach, walls where that free space
meets them, unknown everywhere else (outside the walls and inside solid objects).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

import numpy as np
import yaml
from numpy.typing import NDArray

from twin.core import yaml_numbers
from twin.core.config import read_text_file
from twin.core.errors import ConfigError
from twin.nav.map_server._native import load_kernel
from twin.nav.param_checks import check_map_fields, check_map_image
from twin.world.scene import Scene

__all__ = ["MapMode", "OccupancyMap", "load_map", "map_from_scene", "save_map"]


class MapMode(Enum):
    """How pixel shades become occupancy values."""

    TRINARY = "trinary"
    SCALE = "scale"
    RAW = "raw"


@dataclass(frozen=True, kw_only=True, slots=True, eq=False)
class OccupancyMap:
    """A map as nav_msgs/OccupancyGrid carries it: `data[row, col]` int8 in -1 (unknown) or 0..100.

    Row 0 is the row at `origin_y_m` (y grows with the row), column 0 at `origin_x_m`.
    """

    resolution_m: float
    origin_x_m: float
    origin_y_m: float
    origin_yaw_rad: float = 0.0
    data: NDArray[np.int8]
    frame_id: str = "map"

    @property
    def width(self) -> int:
        """Cells along x."""
        return int(self.data.shape[1])

    @property
    def height(self) -> int:
        """Cells along y."""
        return int(self.data.shape[0])

    def occupancy_values(self) -> NDArray[np.int8]:
        """Return OccupancyGrid.data (row-major, int8)."""
        return np.ascontiguousarray(self.data).reshape(-1)

    def world_to_cell(self, x_m: float, y_m: float) -> tuple[int, int] | None:
        """Return (row, col) of the cell holding a map-frame point, or None outside (origin yaw ignored)."""
        col = math.floor((x_m - self.origin_x_m) / self.resolution_m)
        row = math.floor((y_m - self.origin_y_m) / self.resolution_m)
        return (row, col) if 0 <= row < self.height and 0 <= col < self.width else None


# --- reading -------------------------------------------------------------------------------------


# What map_saver writes, offered when a map YAML lacks a key map_server requires.
_MAP_SAVER_VALUES = {"free_thresh": "0.25", "occupied_thresh": "0.65", "negate": "0"}


def _required(doc: dict[str, object], key: str, where: str) -> object:
    """The value of a key Nav2's map_server requires (its loadMapYaml fails without it)."""
    if key not in doc:
        usual = _MAP_SAVER_VALUES.get(key)
        fix = f"add '{key}: {usual}' (what map_saver writes)" if usual else f"add '{key}'"
        msg = f"{where}: '{key}' is missing, and Nav2's map_server refuses a map YAML without it; {fix}"
        raise ConfigError(msg)
    return doc[key]


def _number(doc: dict[str, object], key: str, where: str) -> float:
    value = _required(doc, key, where)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        msg = f"{where}: '{key}' must be a number, got {value!r}; fix the map YAML"
        raise ConfigError(msg)
    return float(value)


def _read_image(path: Path, where: str) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """Return (mean of colour channels 0..255, alpha 0..255 or None), image rows top first."""
    from PIL import Image, UnidentifiedImageError

    if not path.is_file():
        msg = f"{where}: map image {str(path)!r} not found; check 'image:' (relative to the YAML's folder)"
        raise ConfigError(msg)
    try:
        # Its size was checked against memory before (check_map_image): PIL's own bomb warning is noise here.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(path) as img:
                img.load()
                bands = img.getbands()
                alpha = np.asarray(img.getchannel("A"), dtype=np.float64) if "A" in bands else None
                if img.mode in ("1", "L", "P", "LA", "I", "I;16", "F"):
                    gray = img.convert("L") if img.mode in ("1", "P", "LA") else img
                    shade = np.asarray(gray, dtype=np.float64)
                    if img.mode.startswith("I") and shade.max(initial=0) > 255:
                        shade = shade / 257.0
                else:
                    rgb = np.asarray(img.convert("RGB"), dtype=np.float64)
                    shade = rgb.mean(axis=2)
    except (OSError, UnidentifiedImageError, ValueError, SyntaxError, Image.DecompressionBombError) as err:
        msg = f"{where}: map image {str(path)!r} cannot be read ({err}); give a valid PGM or PNG"
        raise ConfigError(msg) from None
    return shade, alpha


def load_map(yaml_path: str | Path) -> OccupancyMap:
    """Read a map_server map (its YAML and the image it names) into an `OccupancyMap`.

    Raises:
        ConfigError: If the YAML is malformed or lacks a key, or the image is missing or corrupt.
    """
    yaml_path = Path(yaml_path)
    where = str(yaml_path)
    try:
        doc = yaml_numbers.safe_load(read_text_file(yaml_path, ConfigError, what="a map YAML file"))
    except (yaml.YAMLError, RecursionError) as err:
        msg = f"{where}: malformed map YAML ({getattr(err, 'problem', None) or err}); fix the YAML syntax"
        raise ConfigError(msg) from None
    if not isinstance(doc, dict):
        msg = f"{where}: a map YAML must be a mapping with image, resolution, origin, ...; got {type(doc).__name__}"
        raise ConfigError(msg)
    image = doc.get("image")
    if not isinstance(image, str) or not image:
        msg = f"{where}: 'image' must name the map's PGM/PNG file; add it"
        raise ConfigError(msg)
    resolution = _number(doc, "resolution", where)
    if resolution <= 0.0:
        msg = f"{where}: 'resolution' must be > 0, got {resolution}; fix it"
        raise ConfigError(msg)
    origin = doc.get("origin")
    if not (isinstance(origin, list) and len(origin) == 3 and all(isinstance(v, int | float) for v in origin)):
        msg = f"{where}: 'origin' must be [x, y, yaw], got {origin!r}; fix it"
        raise ConfigError(msg)
    occupied = _number(doc, "occupied_thresh", where)
    free = _number(doc, "free_thresh", where)
    negate = _required(doc, "negate", where)
    if negate not in (0, 1, True, False):
        msg = f"{where}: 'negate' must be 0 or 1, got {negate!r}; fix it"
        raise ConfigError(msg)
    mode_text = doc.get("mode", "trinary")
    try:
        mode = MapMode(mode_text)
    except ValueError:
        msg = f"{where}: 'mode' must be trinary, scale or raw, got {mode_text!r}; fix it"
        raise ConfigError(msg) from None
    xyz = (float(origin[0]), float(origin[1]), float(origin[2]))
    check_map_fields(
        where, resolution_m=resolution, origin=xyz, occupied=occupied, free=free, scale=mode is MapMode.SCALE
    )
    image_path = Path(image) if Path(image).is_absolute() else yaml_path.parent / image
    check_map_image(image_path, where)
    shade255, alpha = _read_image(image_path, where)
    data = occupancy_from_image(
        shade255, alpha, mode=mode, negate=bool(negate), occupied_thresh=occupied, free_thresh=free
    )
    return OccupancyMap(
        resolution_m=resolution,
        origin_x_m=float(origin[0]),
        origin_y_m=float(origin[1]),
        origin_yaw_rad=float(origin[2]),
        data=data,
    )


def occupancy_from_image(
    shade255: NDArray[np.float64],
    alpha255: NDArray[np.float64] | None,
    *,
    mode: MapMode,
    negate: bool,
    occupied_thresh: float,
    free_thresh: float,
) -> NDArray[np.int8]:
    """Turn an image (mean channel value 0..255, rows top first) into occupancy rows (row 0 at the origin)."""
    if mode is MapMode.TRINARY and alpha255 is not None:
        # The alpha channel joins the mean as one more channel (three colours + alpha), as ROS 1's
        # map_server averaged it in: Nav2 adds MaxRGB - alphaQuantum(), and GraphicsMagick's
        # alphaQuantum is the opacity (0: opaque), so what it adds is the alpha, 255 when opaque.
        shade255 = (shade255 * 3.0 + alpha255) / 4.0
    shade = shade255 / 255.0
    occ = shade if negate else 1.0 - shade
    out = np.full(shade.shape, -1, dtype=np.int8)
    if mode is MapMode.RAW:
        value = np.round(shade * 255.0)
        keep = (value >= 0) & (value <= 100)
        out[keep] = value[keep].astype(np.int8)
    else:
        out[occ < free_thresh] = 0
        out[occ > occupied_thresh] = 100
        if mode is MapMode.SCALE:
            between = (occ >= free_thresh) & (occ <= occupied_thresh)
            out[between] = np.rint((occ[between] - free_thresh) / (occupied_thresh - free_thresh) * 100.0).astype(
                np.int8
            )
            if alpha255 is not None:
                out[alpha255 < 255.0] = -1
    return np.ascontiguousarray(out[::-1])


# --- writing -------------------------------------------------------------------------------------


def save_map(
    occupancy: OccupancyMap,
    yaml_path: str | Path,
    *,
    free_thresh: float = 0.196,
    occupied_thresh: float = 0.65,
    image_format: str = "pgm",
) -> Path:
    """Write a map as map_saver does (trinary image + YAML) and return the image's path.

    Args:
        occupancy: The map.
        yaml_path: Where the YAML goes; the image is written beside it with the same stem.
        free_thresh: Cells at or below `free_thresh * 100` are written free. The default is TB3's
            map's 0.196, not map_saver's 0.25: unknown is written as shade 205, whose occupancy
            1 - 205/255 = 0.196 map_server would read back as free under 0.25.
        occupied_thresh: Cells at or above `occupied_thresh * 100` are written occupied.
        image_format: `pgm` or `png`.

    Raises:
        ConfigError: If the folder cannot be written or the format is unknown.
    """
    from PIL import Image

    yaml_path = Path(yaml_path)
    if image_format not in ("pgm", "png"):
        msg = f"map image format must be pgm or png, got {image_format!r}"
        raise ConfigError(msg)
    image_path = yaml_path.with_suffix(f".{image_format}")
    data = occupancy.data.astype(np.int16)
    free_int = round(free_thresh * 100.0)
    occ_int = round(occupied_thresh * 100.0)
    pixels = np.full(data.shape, 205, dtype=np.uint8)
    pixels[(data >= 0) & (data <= free_int)] = 254
    pixels[data >= occ_int] = 0
    doc = {
        "image": image_path.name,
        "mode": "trinary",
        "resolution": float(occupancy.resolution_m),
        "origin": [float(occupancy.origin_x_m), float(occupancy.origin_y_m), float(occupancy.origin_yaw_rad)],
        "negate": 0,
        "occupied_thresh": float(occupied_thresh),
        "free_thresh": float(free_thresh),
    }
    try:
        yaml_path.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(np.ascontiguousarray(pixels[::-1]), mode="L").save(image_path)
        yaml_path.write_text(yaml.safe_dump(doc, sort_keys=False, default_flow_style=None), encoding="utf-8")
    except OSError as err:
        msg = f"{yaml_path}: cannot write the map ({err.strerror or err}); choose a writable --out"
        raise ConfigError(msg) from None
    return image_path


# --- from the world ------------------------------------------------------------------------------


def _rasterise(
    scene: Scene, height_m: float, origin: tuple[float, float], shape: tuple[int, int], res: float
) -> NDArray[np.bool_]:
    rows, cols = shape
    occupied = np.zeros(shape, dtype=bool)
    caster = scene.ray_caster(height_m)
    seg = np.asarray(caster.segments, dtype=np.float64).reshape(-1, 4)
    if len(seg):
        length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
        counts = np.maximum(2, np.ceil(length / (0.2 * res)).astype(np.int64) + 1)
        idx = np.repeat(np.arange(len(seg)), counts)
        offset = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
        t = offset / np.repeat(counts - 1, counts)
        px = seg[idx, 0] + (seg[idx, 2] - seg[idx, 0]) * t
        py = seg[idx, 1] + (seg[idx, 3] - seg[idx, 1]) * t
        c = np.floor((px - origin[0]) / res).astype(np.int64)
        r = np.floor((py - origin[1]) / res).astype(np.int64)
        keep = (c >= 0) & (c < cols) & (r >= 0) & (r < rows)
        occupied[r[keep], c[keep]] = True
    circles = np.asarray(caster.circles, dtype=np.float64).reshape(-1, 3)
    if len(circles):
        # A circle's outline: cells whose centre lies within half a cell of the circle.
        xs = origin[0] + (np.arange(cols) + 0.5) * res
        ys = origin[1] + (np.arange(rows) + 0.5) * res
        for cx, cy, radius in circles:
            c0 = max(int((cx - radius - origin[0]) // res) - 1, 0)
            c1 = min(int((cx + radius - origin[0]) // res) + 2, cols)
            r0 = max(int((cy - radius - origin[1]) // res) - 1, 0)
            r1 = min(int((cy + radius - origin[1]) // res) + 2, rows)
            if c0 >= c1 or r0 >= r1:
                continue
            d = np.hypot(xs[None, c0:c1] - cx, ys[r0:r1, None] - cy)
            occupied[r0:r1, c0:c1] |= np.abs(d - radius) <= 0.5 * res * math.sqrt(2.0)
    return occupied


def _region_of(walls: NDArray[np.bool_], row: int, col: int) -> NDArray[np.bool_]:
    """The 4-connected free region holding (row, col) (a C flood fill; scipy's labelling without a compiler)."""
    lib = load_kernel()
    if lib is None:
        from scipy import ndimage

        labels, _ = ndimage.label(~walls)
        return np.asarray(labels == labels[row, col])
    blocked = np.ascontiguousarray(walls, dtype=np.uint8)
    region = np.empty(walls.shape, dtype=np.uint8)
    if lib.twin_flood_fill(blocked.ctypes.data, walls.shape[0], walls.shape[1], row * walls.shape[1] + col,
                           region.ctypes.data) < 0:  # fmt: skip
        raise MemoryError("map from world: out of memory")
    return region.astype(bool)


def _dilated(region: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """The region grown by one cell in its 8-neighbourhood (a 3 x 3 binary dilation)."""
    out = region.copy()
    rows, cols = region.shape
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr == 0 and dc == 0:
                continue
            src = region[max(0, -dr) : rows - max(0, dr), max(0, -dc) : cols - max(0, dc)]
            out[max(0, dr) : rows - max(0, -dr), max(0, dc) : cols - max(0, -dc)] |= src
    return out


_OPEN_WORLD_RATIO = 4
"""An enclosed free region this many times smaller than the largest one is not where the robot drives."""


def map_from_scene(
    scene: Scene,
    *,
    height_m: float,
    resolution_m: float = 0.05,
    free_xy_m: tuple[float, float] | None = None,
    bounds_xy_m: tuple[float, float, float, float] | None = None,
    padding_m: float = 0.5,
) -> OccupancyMap:
    """Make a SLAM-like map of the world: its cross-section at `height_m`, unknown outside the walls.

    Cells that obstacles' outlines cross are walls; the free space holding `free_xy_m` (4-connected
    through non-wall cells) is free; walls touching that free space (8-neighbourhood) are occupied;
    everything else is unknown, as a map made by driving a lidar around the inside would be.

    Args:
        scene: The world's static obstacles.
        height_m: Height of the lidar's beam plane above the floor.
        resolution_m: Cell size.
        free_xy_m: A point in the space the robot drives in; default the largest free region not
            touching the map's border (the inside of the outer walls), unless the largest region
            that does is more than four times its size: then the world is open (a floor with
            things on it, a building whose doors open to the outside) and the enclosed region is
            only the inside of a box or a wall, so the largest region is taken.
        bounds_xy_m: (x_min, y_min, x_max, y_max) to cover; default the obstacles' bounds plus `padding_m`.
        padding_m: Margin around the obstacles' bounds.

    Raises:
        ConfigError: If `free_xy_m` lies outside the map or on an obstacle.
    """
    if bounds_xy_m is None:
        box = scene.bounds
        if box is None:
            bounds_xy_m = (-5.0, -5.0, 5.0, 5.0)
        else:
            (x0, y0, _), (x1, y1, _) = box
            bounds_xy_m = (x0 - padding_m, y0 - padding_m, x1 + padding_m, y1 + padding_m)
    x_min, y_min, x_max, y_max = bounds_xy_m
    x_min = round(math.floor(x_min / resolution_m) * resolution_m, 9)
    y_min = round(math.floor(y_min / resolution_m) * resolution_m, 9)
    cols = max(1, math.ceil((x_max - x_min) / resolution_m - 1e-9))
    rows = max(1, math.ceil((y_max - y_min) / resolution_m - 1e-9))
    walls = _rasterise(scene, height_m, (x_min, y_min), (rows, cols), resolution_m)
    if free_xy_m is not None:
        col = math.floor((free_xy_m[0] - x_min) / resolution_m)
        row = math.floor((free_xy_m[1] - y_min) / resolution_m)
        if not (0 <= row < rows and 0 <= col < cols) or walls[row, col]:
            msg = (
                f"map from world: free point {free_xy_m} is outside the map or on an obstacle; "
                "give a point the robot can stand on"
            )
            raise ConfigError(msg)
        region = _region_of(walls, row, col)
    else:
        from scipy import ndimage

        labels, count = ndimage.label(~walls)
        if count == 0:
            region = np.zeros_like(walls)
        else:
            sizes = np.bincount(labels.ravel(), minlength=count + 1)
            sizes[0] = 0
            border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
            inner = sizes.copy()
            inner[border] = 0
            enclosed = inner.any() and inner.max() * _OPEN_WORLD_RATIO >= sizes.max()
            region = labels == int(np.argmax(inner if enclosed else sizes))
    seen_walls = walls & _dilated(region)
    data = np.full((rows, cols), -1, dtype=np.int8)
    data[region] = 0
    data[seen_walls] = 100
    return OccupancyMap(resolution_m=resolution_m, origin_x_m=x_min, origin_y_m=y_min, data=data)
