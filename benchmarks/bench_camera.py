"""Camera frame cost: the house seen by the Waffle's camera, RGB + depth, per frame on one core.

Prints JSON: CPU milliseconds per frame (process time, best of `--repeat` batches, so a shared
machine's other load counts little) for 640x480 and the SDF's 1920x1080, with and without the SDF's
Gaussian noise, through the C kernel and the numpy path, and the JPEG encoding of a 640x480 frame
(Pillow, quality 95) that a compressed image topic would cost. The camera stands at the mission's
four locations in turn with the demos' three blocks in view.

    python benchmarks/bench_camera.py [--frames 40] [--repeat 3]
"""

from __future__ import annotations

import argparse
import io
import json
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from twin.mission.bt_nodes import load_locations
from twin.world import load_robot, load_world
from twin.world.render import CameraModel, Renderer, box_mesh, lighting_of, world_visuals

ROOT = Path(__file__).resolve().parent.parent
COLOURS = ((0.8, 0.0, 0.2), (0.0, 0.8, 0.0), (0.0, 0.0, 0.8))


def _planar(x: float, y: float, yaw: float, z: float = 0.0) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0, x], [s, c, 0, y], [0, 0, 1, z], [0, 0, 0, 1.0]])


def _best_ms(fn: Callable[[int], object], frames: int, repeat: int) -> float:
    best = math.inf
    for _ in range(repeat):
        t0 = time.process_time()
        for i in range(frames):
            fn(i)
        best = min(best, (time.process_time() - t0) / frames * 1e3)
    return round(best, 3)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    world = load_world(ROOT / "sdf" / "worlds" / "house.sdf")
    lighting = lighting_of(world)
    mesh = world_visuals(world, lighting)
    (spec,) = load_robot("turtlebot3_waffle", model_path=[ROOT / "sdf" / "models"]).cameras
    T_base = np.asarray(spec.T_base_sensor)
    locations = list(load_locations(ROOT / "trees" / "sim_house_locations.yaml").values())
    blocks = box_mesh(
        [
            (
                (0.1, 0.1, 0.1),
                _planar(p.x_m + 0.6 * math.cos(p.yaw_rad), p.y_m + 0.6 * math.sin(p.yaw_rad), p.yaw_rad, 0.05),
                rgb,
            )
            for p, rgb in zip(locations, COLOURS, strict=False)
        ],
        lighting,
    )
    poses = [_planar(p.x_m, p.y_m, p.yaw_rad) @ T_base for p in locations]

    def camera(width: int, height: int) -> CameraModel:
        return CameraModel(width=width, height=height, hfov_rad=spec.hfov_rad, near_m=spec.near_m, far_m=spec.far_m)

    out: dict[str, object] = {
        "world": "house.sdf",
        "triangles": len(mesh.faces) + len(blocks.faces),
        "sdf_camera": {
            "width": spec.width,
            "height": spec.height,
            "rate_hz": spec.rate_hz,
            "noise_std": spec.noise_std,
        },
    }
    results: dict[str, float] = {}
    for width, height in ((640, 480), (1920, 1080)):
        renderer = Renderer(camera(width, height), mesh, lighting)
        out["native"] = renderer.native
        key = f"{width}x{height}"
        results[f"{key}_rgb_depth_ms"] = _best_ms(
            lambda i, r=renderer: r.render(poses[i % 4], blocks), args.frames, args.repeat
        )
        results[f"{key}_rgb_depth_noise_ms"] = _best_ms(
            lambda i, r=renderer: r.render(poses[i % 4], blocks, noise_std=spec.noise_std, seed=i),
            args.frames,
            args.repeat,
        )
    slow = Renderer(camera(640, 480), mesh, lighting, native=False)
    results["640x480_numpy_path_ms"] = _best_ms(lambda i: slow.render(poses[i % 4], blocks), 4, 1)

    from PIL import Image

    fast = Renderer(camera(640, 480), mesh, lighting)
    frame = fast.render(poses[0], blocks, noise_std=spec.noise_std, seed=1).rgb
    sizes: list[int] = []

    def jpeg(_: int) -> None:
        buf = io.BytesIO()
        Image.fromarray(frame).save(buf, format="JPEG", quality=95)
        sizes.append(buf.tell())

    results["640x480_jpeg_encode_ms"] = _best_ms(jpeg, args.frames, args.repeat)
    out["640x480_jpeg_bytes"] = sizes[-1]
    out["640x480_raw_bytes"] = frame.nbytes
    out["ms_per_frame"] = results
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
