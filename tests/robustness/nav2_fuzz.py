"""Generated Nav2 params files and maps (hypothesis strategies), written beside a scenario that uses them.

A case starts from TurtleBot3's Humble waffle params and map (turtlebot3_world, as the project's
`scenarios/turtlebot3_world.yaml` runs it) and changes one to three things: a parameter the twin
reads set to any value (NaN, infinities, huge, tiny, negative, the wrong type), a node's section
removed or replaced, the whole file emptied or made garbage; the map YAML's numbers, mode and image;
the image itself (a real small PGM/PNG, a header claiming up to 100000 x 100000 pixels over a few
bytes, random bytes). `tests/robustness/test_nav2_generated.py` runs a bounded number of them;
`benchmarks/fuzz_nav2_inputs.py` runs more.
"""

from __future__ import annotations

import functools
import math
import resource
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import yaml
from hypothesis import strategies as st

from tests.conftest import REPO

FIXTURE_MAP = REPO.parent / "shared" / "fixtures" / "nav2" / "turtlebot3_navigation2_humble" / "map"
WAFFLE = REPO / "twin" / "data" / "nav2" / "waffle.yaml"
NODES = (
    ("amcl",),
    ("controller_server",),
    ("planner_server",),
    ("behavior_server",),
    ("bt_navigator",),
    ("velocity_smoother",),
    ("local_costmap", "local_costmap"),
    ("global_costmap", "global_costmap"),
)
WHOLE_RUN_LIMIT_BYTES = 2 << 30  # the address space a whole run may take
WHOLE_RUN_TIMEOUT_S = 60.0


@functools.cache
def waffle() -> dict[str, Any]:
    doc: dict[str, Any] = yaml.safe_load(WAFFLE.read_text(encoding="utf-8"))
    return doc


def _section(doc: dict[str, Any], node: tuple[str, ...]) -> dict[str, Any] | None:
    body: Any = doc
    for part in node:
        if not isinstance(body, dict) or part not in body:
            return None
        body = body[part]
    return body.get("ros__parameters") if isinstance(body, dict) else None


def _flat(prefix: str, value: Any) -> list[str]:
    if isinstance(value, dict):
        return [k for key, item in value.items() for k in _flat(f"{prefix}.{key}" if prefix else str(key), item)]
    return [prefix]


@functools.cache
def parameters() -> tuple[tuple[tuple[str, ...], str], ...]:
    """Every (node, flattened parameter) of TB3's waffle file for the nodes the twin runs."""
    out: list[tuple[tuple[str, ...], str]] = []
    for node in NODES:
        section = _section(waffle(), node)
        out.extend((node, key) for key in _flat("", section or {}))
    return tuple(out)


numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -1.0, -20.0, 1e-9, 1e-5, 1e-300, 1e300, 1e5, 1e9, 0.5, 100000.0]),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.sampled_from([0, 1, -1, 100000, 10**9, 2**31, 2**63]),
)
values = st.one_of(
    numbers,
    numbers,
    st.booleans(),
    st.text(max_size=6),
    st.lists(numbers, max_size=4),
    st.none(),
)


@st.composite
def params_change(draw: st.DrawFn) -> tuple[Any, ...]:
    kind = draw(st.sampled_from(["set", "set", "set", "set", "drop_node", "node_body", "empty", "garbage"]))
    if kind == "set":
        node, key = draw(st.sampled_from(parameters()))
        return ("set", node, key, draw(values))
    if kind == "drop_node":
        return ("drop_node", draw(st.sampled_from(NODES)))
    if kind == "node_body":
        return ("node_body", draw(st.sampled_from(NODES)), draw(st.sampled_from([None, [], 3, "x", {}])))
    if kind == "empty":
        return ("empty",)
    return ("garbage", draw(st.text(max_size=40)))


@st.composite
def map_change(draw: st.DrawFn) -> tuple[Any, ...]:
    kind = draw(st.sampled_from(["resolution", "origin", "thresh", "mode", "negate", "image", "image", "yaml"]))
    if kind == "resolution":
        return ("key", "resolution", draw(values))
    if kind == "origin":
        return ("key", "origin", draw(st.one_of(st.lists(numbers, min_size=0, max_size=4), values)))
    if kind == "thresh":
        return ("key", draw(st.sampled_from(["occupied_thresh", "free_thresh"])), draw(values))
    if kind == "mode":
        return ("key", "mode", draw(st.sampled_from(["trinary", "scale", "raw", "gray", 3])))
    if kind == "negate":
        return ("key", "negate", draw(st.sampled_from([0, 1, 2, True, "yes", None])))
    if kind == "yaml":
        return ("yaml", draw(st.text(max_size=40)))
    image = draw(st.sampled_from(["small", "header", "bytes"]))
    if image == "small":
        fmt = draw(st.sampled_from(["PGM", "PNG"]))
        mode = draw(st.sampled_from(["L", "RGB", "RGBA", "LA", "1", "I;16"] if fmt == "PNG" else ["L"]))
        size = (draw(st.integers(1, 64)), draw(st.integers(1, 64)))
        return ("image_small", fmt, mode, size, draw(st.integers(0, 255)))
    if image == "header":
        return ("image_header", draw(st.integers(1, 100_000)), draw(st.integers(1, 100_000)))
    return ("image_bytes", draw(st.binary(max_size=64)))


# The parameters that size what the twin builds or set the rate its timers fire at, with the values
# that break such things (0, negatives, the tiny and the huge, NaN, the wrong type).
RISKY = (
    (("controller_server",), "controller_frequency"),
    (("controller_server",), "FollowPath.vx_samples"),
    (("controller_server",), "FollowPath.vtheta_samples"),
    (("controller_server",), "FollowPath.sim_time"),
    (("controller_server",), "FollowPath.linear_granularity"),
    (("local_costmap", "local_costmap"), "width"),
    (("local_costmap", "local_costmap"), "resolution"),
    (("local_costmap", "local_costmap"), "update_frequency"),
    (("global_costmap", "global_costmap"), "resolution"),
    (("global_costmap", "global_costmap"), "inflation_layer.inflation_radius"),
    (("amcl",), "max_particles"),
    (("amcl",), "laser_likelihood_max_dist"),
    (("bt_navigator",), "bt_loop_duration"),
)
_BREAKING = [
    0,
    0.0,
    -20.0,
    1e-5,
    1e-9,
    100000,
    10**9,
    10**12,
    1e300,
    math.nan,
    math.inf,
    -math.inf,
    "fast",
    None,
    [1.0],
]
_RUNNING = [1, 3000, 0.5, 5.0, 20.0]  # values that run: the run must stay within its limits too
risky_values = st.sampled_from([*_BREAKING, *_RUNNING])


@st.composite
def risky_change(draw: st.DrawFn) -> tuple[Any, ...]:
    node, key = draw(st.sampled_from(RISKY))
    return ("set", node, key, draw(risky_values))


risky_cases = st.tuples(st.lists(risky_change(), min_size=1, max_size=2), st.just([]))
"""One or two sizing or rate parameters set to a breaking value: what whole runs are tried on."""

cases = st.tuples(st.lists(params_change(), max_size=3), st.lists(map_change(), max_size=2)).filter(
    lambda case: bool(case[0] or case[1])
)


def _apply_params(changes: list[tuple[Any, ...]]) -> str:
    doc = yaml.safe_load(WAFFLE.read_text(encoding="utf-8"))
    text: str | None = None
    for change in changes:
        if change[0] == "set":
            _, node, key, value = change
            section = _section(doc, node)
            if section is None:
                continue
            *parents, leaf = key.split(".")
            for part in parents:
                nxt = section.get(part)
                if not isinstance(nxt, dict):
                    nxt = section[part] = {}
                section = nxt
            section[leaf] = value
        elif change[0] == "drop_node":
            doc.pop(change[1][0], None)
        elif change[0] == "node_body":
            doc[change[1][0]] = change[2]
        elif change[0] == "empty":
            doc = {}
        else:
            text = change[1]
    return text if text is not None else yaml.safe_dump(doc)


def _apply_map(changes: list[tuple[Any, ...]], folder: Path) -> str:
    doc = yaml.safe_load((FIXTURE_MAP / "map.yaml").read_text(encoding="utf-8"))
    shutil.copy(FIXTURE_MAP / "map.pgm", folder / "map.pgm")
    text: str | None = None
    for change in changes:
        if change[0] == "key":
            doc[change[1]] = change[2]
        elif change[0] == "yaml":
            text = change[1]
        elif change[0] == "image_small":
            from PIL import Image

            _, fmt, mode, size, shade = change
            image = Image.new(mode, size, color=shade if mode in ("L", "1", "I;16") else None)
            name = "gen.pgm" if fmt == "PGM" else "gen.png"
            image.save(folder / name, format="PPM" if fmt == "PGM" else "PNG")
            doc["image"] = name
        elif change[0] == "image_header":
            _, width, height = change
            (folder / "gen.pgm").write_bytes(f"P5\n{width} {height}\n255\n".encode() + b"\xfe" * 64)
            doc["image"] = "gen.pgm"
        else:
            (folder / "gen.pgm").write_bytes(change[1])
            doc["image"] = "gen.pgm"
    return text if text is not None else yaml.safe_dump(doc)


def write_case(case: tuple[list[tuple[Any, ...]], list[tuple[Any, ...]]], folder: Path) -> Path:
    """Write the case's params file, map and scenario into `folder`; return the scenario's path."""
    params_changes, map_changes = case
    navigation: dict[str, Any] = {}
    scenario: dict[str, Any] = {
        "name": "generated",
        "world": {"sdf": str(REPO / "sdf" / "worlds" / "turtlebot3_world.sdf")},
        "robot": {"initial_pose": {"x_m": -2.0, "y_m": -0.5, "yaw_rad": 0.0}},
        "mission": {"locations": str(REPO / "trees" / "turtlebot3_world_locations.yaml")},
        "navigation": navigation,
    }
    if params_changes:
        (folder / "params.yaml").write_text(_apply_params(params_changes), encoding="utf-8")
        navigation["params"] = "params.yaml"
    if map_changes:
        (folder / "map.yaml").write_text(_apply_map(map_changes, folder), encoding="utf-8")
        scenario["map"] = "map.yaml"
    path = folder / "scenario.yaml"
    path.write_text(yaml.safe_dump(scenario), encoding="utf-8")
    return path


def _limit_memory() -> None:  # runs in the child before exec
    resource.setrlimit(resource.RLIMIT_AS, (WHOLE_RUN_LIMIT_BYTES, WHOLE_RUN_LIMIT_BYTES))


def whole_run(scenario: Path, out: Path, *, duration_s: float = 2.0) -> tuple[int, str, float]:
    """`twin simulate` in a process limited to 2 GiB of address space and 60 s: (exit code, stderr, peak RSS MiB).

    A process killed by the limit or the timeout returns a negative code (the signal), as subprocess reports it.
    """
    argv = [sys.executable, "-m", "twin", "simulate", str(scenario), "--duration", str(duration_s), "--out", str(out)]
    try:
        proc = subprocess.run(
            argv,
            capture_output=True,
            text=True,
            timeout=WHOLE_RUN_TIMEOUT_S,
            preexec_fn=_limit_memory,
            check=False,
        )
    except subprocess.TimeoutExpired as err:
        stderr = err.stderr.decode(errors="replace") if isinstance(err.stderr, bytes) else str(err.stderr)
        return -9, stderr + f"\n(timed out after {WHOLE_RUN_TIMEOUT_S:g} s)", math.nan
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0  # the largest child so far, MiB
    return proc.returncode, proc.stderr, peak


def describe(case: tuple[list[tuple[Any, ...]], list[tuple[Any, ...]]]) -> str:
    """A short text of a case for reports (its repr, cut to 200 characters)."""
    return repr(case)[:200]
