"""The sweep file: a base scenario and what varies, expanded into one `RunSpec` per run.

```yaml
scenario: ../scenarios/default.yaml      # the base, relative to this file
runs: 50                                 # seeds 0..49 (or seeds: [3, 7, 11])
vary:                                    # dotted scenario keys: a grid, or zip: true to pair
  robot.model: [turtlebot3_waffle, turtlebot3_burger]
  robots[1]: [{name: robot2, robot: {initial_pose: {x_m: 1.2}}}]   # a whole entry of a list, replaced
zip: false
random:                                  # seeded draws per run
  robot.initial_pose.x_m: {uniform: [-0.2, 0.2]}
  robots[1].robot.initial_pose.y_m: {uniform: [-0.3, 0.3]}   # a fleet's robot: its index in robots:
random_seed: 0                           # seeds the draws (default 0)
timeout_s: 120                           # per run, wall clock
```

Every varied key is checked against the scenario's schema before anything runs. A run's scenario
is the base file with its values set, written out whole with every path made absolute, so the run
reads the same scenario wherever its worker runs.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
import os
import random
import re
import types
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import yaml

from twin.core.code_identity import code_digest
from twin.core.config import NameOrPath, load_yaml, location, suggest
from twin.core.errors import ConfigError
from twin.core.numbers import number_problem

__all__ = ["Draw", "RunSpec", "SweepSpec", "expand_runs", "load_sweep"]

_KEYS = ("name", "scenario", "runs", "seeds", "vary", "zip", "random", "random_seed", "timeout_s")
_DISTRIBUTIONS = ("uniform", "normal", "choice")


@dataclass(frozen=True, kw_only=True, slots=True)
class Draw:
    """A seeded random draw for one scenario key: `uniform: [lo, hi]`, `normal: [mean, std]` or `choice: [...]`."""

    key: str
    distribution: Literal["uniform", "normal", "choice"]
    args: tuple[Any, ...]


@dataclass(frozen=True, kw_only=True, slots=True)
class SweepSpec:
    """A loaded sweep file (see the module docstring)."""

    path: Path
    name: str
    scenario: Path
    seeds: tuple[int | None, ...]
    vary: tuple[tuple[str, tuple[Any, ...]], ...]
    zip: bool
    random: tuple[Draw, ...]
    random_seed: int
    timeout_s: float


#: The most runs one sweep makes (each is a process, a folder and a row).
MAX_RUNS = 100_000


@dataclass(frozen=True, kw_only=True, slots=True)
class RunSpec:
    """One run: its id, seed, the values it sets and the whole scenario it runs (YAML text)."""

    index: int
    run_id: str
    seed: int | None
    values: tuple[tuple[str, Any], ...]
    scenario_yaml: str
    key: str  # a digest of everything that decides the run's result: a finished run with it is not rerun


def load_sweep(path: Path) -> SweepSpec:
    """Load and check a sweep file.

    Raises:
        ConfigError: One line naming file, line and key: an unknown key (with a suggestion), a key to
            vary that the scenario does not have, a value of a section (`robots[1]`, `drive`) that is
            not a mapping of its keys, lists of different lengths with `zip: true`, a bad draw, or a
            base scenario that does not load.
    """
    node = load_yaml(path)
    if not isinstance(node, yaml.MappingNode):
        msg = f"{location(node)}: a sweep file is a mapping with at least `scenario:`"
        raise ConfigError(msg)
    nodes: dict[str, yaml.Node] = {}
    for key_node, value_node in node.value:
        key = str(key_node.value)
        if key not in _KEYS:
            msg = f"{location(key_node)}: {key}: unknown key{suggest(key, list(_KEYS))}"
            raise ConfigError(msg)
        nodes[key] = value_node
    raw = {k: yaml.safe_load(yaml.serialize(v)) for k, v in nodes.items()}
    if "scenario" not in raw:
        msg = f"{path}: scenario: missing; name the base scenario file (relative to {path.name})"
        raise ConfigError(msg)
    base_dir = path.resolve().parent  # the sweep file's paths are relative to it
    scenario = _path(base_dir, nodes["scenario"], raw["scenario"])
    _check_scenario(scenario, nodes["scenario"])
    base = _absolute_scenario(scenario)
    vary_raw = raw.get("vary") or {}
    if not isinstance(vary_raw, dict):
        _fail(nodes["vary"], "vary", "expected a mapping of dotted scenario keys to lists of values")
    zip_flag = raw.get("zip", False)
    if "zip" in vary_raw:  # `vary: {zip: true, ...}` reads naturally too; no scenario key is named zip
        zip_flag = vary_raw.pop("zip")
    if not isinstance(zip_flag, bool):
        _fail(nodes.get("zip", node), "zip", f"expected true or false, got {zip_flag!r}")
    vary: list[tuple[str, tuple[Any, ...]]] = []
    for key, values in vary_raw.items():
        where = _value_node(nodes["vary"], key)
        if not isinstance(values, list) or not values:
            _fail(where, f"vary.{key}", "expected a non-empty list of values")
        kind = _schema_type(str(key), where, "vary", base)
        for value in values:
            _check_value(value, kind, where, f"vary.{key}", str(key))
        vary.append((str(key), tuple(_fix_paths(v, kind, base_dir) for v in values)))
    if zip_flag and len({len(v) for _, v in vary}) > 1:
        lengths = ", ".join(f"{k}: {len(v)}" for k, v in vary)
        _fail(
            nodes["vary"], "vary", f"zip: true pairs the lists, but their lengths differ ({lengths}); make them equal"
        )
    draws = _draws(raw.get("random") or {}, nodes.get("random"), base, base_dir)
    seeds = _seeds(raw, nodes)
    combos = len(vary[0][1]) if zip_flag and vary else math.prod(len(v) for _, v in vary)
    if combos * len(seeds) > MAX_RUNS:
        where = nodes.get("vary", nodes.get("runs", nodes.get("seeds", node)))
        _fail(
            where,
            "vary",
            f"{combos} combinations x {len(seeds)} seeds is more runs than a sweep makes (at most {MAX_RUNS})",
        )
    if seeds != (None,) and "seed" in [k for k, _ in vary] + [d.key for d in draws]:
        _fail(nodes.get("runs", nodes.get("seeds", node)), "seed", "vary the seed or give runs:/seeds:, not both")
    timeout_s = raw.get("timeout_s", 600.0)
    if isinstance(timeout_s, bool) or not isinstance(timeout_s, int | float) or not 0 < timeout_s < math.inf:
        _fail(nodes.get("timeout_s", node), "timeout_s", f"expected a positive number of seconds, got {timeout_s!r}")
    problem = number_problem(timeout_s, "timeout_s")
    if problem is not None:
        _fail(nodes.get("timeout_s", node), "timeout_s", problem)
    random_seed = raw.get("random_seed", 0)
    if isinstance(random_seed, bool) or not isinstance(random_seed, int):
        _fail(nodes.get("random_seed", node), "random_seed", f"expected a whole number, got {random_seed!r}")
    problem = number_problem(random_seed, "random_seed")
    if problem is not None:
        _fail(nodes.get("random_seed", node), "random_seed", problem)
    name = raw.get("name", path.stem)
    return SweepSpec(
        path=path,
        name=str(name),
        scenario=scenario,
        seeds=seeds,
        vary=tuple(vary),
        zip=zip_flag,
        random=draws,
        random_seed=random_seed,
        timeout_s=float(timeout_s),
    )


def expand_runs(spec: SweepSpec) -> list[RunSpec]:
    """Return the sweep's runs in a fixed order: every combination of the varied values, then every seed.

    The random draws of a run depend only on `random_seed`, the combination, the seed and the key,
    so the same sweep file gives the same runs. A run's `key` also covers the twin's code
    (`code_digest`): after a code change a finished run is run again, not read back.
    """
    base = _absolute_scenario(spec.scenario)
    keys = [k for k, _ in spec.vary]
    lists = [v for _, v in spec.vary]
    combos = list(zip(*lists, strict=True)) if spec.zip else list(itertools.product(*lists))
    runs: list[RunSpec] = []
    width = max(4, len(str(len(combos) * len(spec.seeds) - 1)))
    for combo_index, combo in enumerate(combos):
        for seed in spec.seeds:
            values: list[tuple[str, Any]] = list(zip(keys, combo, strict=True))
            for draw in spec.random:
                rng = random.Random(f"{spec.random_seed}:{combo_index}:{seed}:{draw.key}")
                values.append((draw.key, _sample(draw, rng)))
            scenario = _with_values(base, values)
            text = yaml.safe_dump(scenario, sort_keys=False)
            index = len(runs)
            digest = json.dumps(
                {"scenario": text, "seed": seed, "timeout_s": spec.timeout_s, "code": code_digest()}, sort_keys=True
            )
            runs.append(
                RunSpec(
                    index=index,
                    run_id=f"r{index:0{width}d}",
                    seed=seed,
                    values=tuple(values),
                    scenario_yaml=text,
                    key=hashlib.sha256(digest.encode()).hexdigest()[:16],
                )
            )
    return runs


# -- loading ------------------------------------------------------------------------------------


def _fail(node: yaml.Node, key: str, problem: str) -> typing.NoReturn:
    msg = f"{location(node)}: {key}: {problem}"
    raise ConfigError(msg)


def _value_node(mapping: yaml.Node, key: str) -> yaml.Node:
    for k, _ in mapping.value:
        if str(k.value) == key:
            node: yaml.Node = k
            return node
    return mapping


def _path(base_dir: Path, node: yaml.Node, value: Any) -> Path:
    if not isinstance(value, str) or not value:
        _fail(node, "scenario", f"expected a path to a scenario file, got {value!r}")
    path = Path(value).expanduser()
    return Path(os.path.normpath(path if path.is_absolute() else base_dir / path))


def _check_scenario(path: Path, node: yaml.Node) -> None:
    from twin.sim.scenario_file import load_scenario

    if not path.is_file():
        _fail(node, "scenario", f"{path} not found; the path is relative to the sweep file")
    load_scenario(path)


def _seeds(raw: dict[str, Any], nodes: dict[str, yaml.Node]) -> tuple[int | None, ...]:
    if "runs" in raw and "seeds" in raw:
        _fail(nodes["seeds"], "seeds", "give runs: N (seeds 0..N-1) or seeds: [..], not both")
    if "runs" in raw:
        runs = raw["runs"]
        if isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
            _fail(nodes["runs"], "runs", f"expected a whole number of runs (seeds 0..N-1), got {runs!r}")
        if runs > MAX_RUNS:
            _fail(nodes["runs"], "runs", f"{runs} runs is more than a sweep makes (at most {MAX_RUNS})")
        return tuple(range(runs))
    if "seeds" in raw:
        seeds = raw["seeds"]
        if not isinstance(seeds, list) or not seeds or not all(type(s) is int for s in seeds):
            _fail(nodes["seeds"], "seeds", f"expected a non-empty list of whole numbers, got {seeds!r}")
        for seed in seeds:
            problem = number_problem(seed, "seed") if seed >= 0 else "must be a non-negative whole number"
            if problem is not None:
                _fail(nodes["seeds"], "seeds", f"{seed}: {problem}")
        return tuple(seeds)
    return (None,)  # one run per combination, with the scenario's own seed


def _draws(raw: Any, node: yaml.Node | None, base: Mapping[str, Any], base_dir: Path) -> tuple[Draw, ...]:
    if not raw:
        return ()
    assert node is not None
    if not isinstance(raw, dict):
        _fail(node, "random", "expected a mapping of dotted scenario keys to {uniform|normal|choice: [...]}")
    draws = []
    for key, how in raw.items():
        where = _value_node(node, key)
        tp = _schema_type(str(key), where, "random", base)
        if not isinstance(how, dict) or len(how) != 1:
            _fail(where, f"random.{key}", "expected one of {uniform: [lo, hi]}, {normal: [mean, std]}, {choice: [..]}")
        ((kind, args),) = how.items()
        if kind not in _DISTRIBUTIONS:
            _fail(where, f"random.{key}", f"unknown distribution {kind!r}{suggest(str(kind), list(_DISTRIBUTIONS))}")
        if not isinstance(args, list) or not args:
            _fail(where, f"random.{key}.{kind}", "expected a list")
        if kind != "choice" and (
            len(args) != 2 or not all(isinstance(a, int | float) and not isinstance(a, bool) for a in args)
        ):
            _fail(where, f"random.{key}.{kind}", f"expected two numbers, got {args!r}")
        if kind != "choice" and not all(math.isfinite(a) for a in args):
            _fail(where, f"random.{key}.{kind}", f"expected finite numbers, got {args!r}")
        if kind == "uniform" and args[0] > args[1]:
            _fail(where, f"random.{key}.uniform", f"expected [low, high] with low <= high, got {args!r}; swap them")
        if kind == "normal" and args[1] < 0:
            _fail(where, f"random.{key}.normal", f"expected [mean, std] with std >= 0, got {args!r}")
        for value in args if kind == "choice" else args[:1]:  # uniform and normal draw numbers, like their first
            _check_value(value, tp, where, f"random.{key}.{kind}", str(key))
        if kind == "choice":  # paths among the choices are relative to the sweep file, as vary's are
            args = [_fix_paths(value, tp, base_dir) for value in args]
        draws.append(Draw(key=str(key), distribution=kind, args=tuple(args)))
    return tuple(draws)


def _sample(draw: Draw, rng: random.Random) -> Any:
    if draw.distribution == "uniform":
        return rng.uniform(float(draw.args[0]), float(draw.args[1]))
    if draw.distribution == "normal":
        return rng.gauss(float(draw.args[0]), float(draw.args[1]))
    return draw.args[rng.randrange(len(draw.args))]


# -- the scenario schema ------------------------------------------------------------------------


def _members(tp: Any) -> list[Any]:
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        return [a for a in typing.get_args(tp) if a is not type(None)]
    return [tp]


def _is_dataclass(tp: Any) -> bool:
    return isinstance(tp, type) and dataclasses.is_dataclass(tp)


def _fields(tp: Any) -> dict[str, Any] | None:
    """The settings a type takes by name (the union of its variants'), or None if it is not a section."""
    sections = [m for m in _members(tp) if _is_dataclass(m)]
    if not sections:
        return None
    out: dict[str, Any] = {}
    for cls in sections:
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            if f.init and f.name not in out:
                out[f.name] = hints[f.name]
    return out


_PART = re.compile(r"([^.\[\]]+)(?:\[(\d+)\])?\Z")


def _parts(dotted: str) -> list[tuple[str, int | None]]:
    """`robots[1].robot.initial_pose.x_m` as `[("robots", 1), ("robot", None), ...]`; None if it does not parse."""
    out: list[tuple[str, int | None]] = []
    for part in dotted.split("."):
        m = _PART.match(part)
        if m is None:
            return []
        out.append((m.group(1), None if m.group(2) is None else int(m.group(2))))
    return out


def _entries(tp: Any) -> Any:
    """The entry type of a list of sections (`tuple[RobotEntry, ...]`), or None."""
    for m in _members(tp):
        args = typing.get_args(m)
        if typing.get_origin(m) in (tuple, list, Sequence) and args and _fields(args[0]) is not None:
            return args[0]
    return None


def _one_level_down(fields: Mapping[str, Any], walked: Sequence[str], dotted: str) -> str:
    """A hint for a key written a section too high: `robots[1].initial_pose...` is `robots[1].robot.initial_pose...`.

    Names each section of `fields` under which the rest of the key (this part on) is a key, or "".
    """
    rest = dotted.split(".")[len(walked) :]  # this part and what follows it
    owners = []
    for name, section in fields.items():
        tp = section
        for part in rest:
            inner = _fields(tp)
            if inner is None or part not in inner:
                break
            tp = inner[part]
        else:
            owners.append(".".join([*walked, name, *rest]))
    return f"; did you mean {' or '.join(repr(o) for o in owners)}?" if owners else ""


def _schema_type(dotted: str, node: yaml.Node, section: str, base: Mapping[str, Any]) -> Any:
    """Return the type the scenario declares for a dotted key, or fail naming the nearest valid key.

    A list of sections (a fleet's `robots:`) is entered by index, `robots[1].robot.initial_pose.x_m`,
    and the index must name an entry of the base scenario `base`.
    """
    from twin.sim.scenario import Scenario

    parts = _parts(dotted)
    if not parts:
        msg = f"{location(node)}: {section}.{dotted}: not a dotted key (name.name or name[index].name)"
        raise ConfigError(msg)
    tp: Any = Scenario
    walked: list[str] = []
    value: Any = base  # the base scenario's value along the key, while it has one
    for part, index in parts:
        mappings = [m for m in _members(tp) if typing.get_origin(m) in (dict, Mapping)]
        if mappings and index is None:  # a free mapping (e.g. an FMU's start values): any key
            tp = typing.get_args(mappings[0])[1] if typing.get_args(mappings[0]) else Any
            walked.append(part)
            value = value.get(part) if isinstance(value, Mapping) else None
            continue
        fields = _fields(tp)
        where = ".".join(walked) or "the scenario"
        if fields is None:
            msg = f"{location(node)}: {section}.{dotted}: {where} is a value, not a section; vary {where} itself"
            raise ConfigError(msg)
        if part not in fields:
            hint = _one_level_down(fields, walked, dotted) or suggest(part, list(fields))
            msg = f"{location(node)}: {section}.{dotted}: {where} has no key {part!r}{hint}"
            raise ConfigError(msg)
        tp = fields[part]
        value = value.get(part) if isinstance(value, Mapping) else None
        entry = _entries(tp)
        if index is None and entry is not None:
            msg = f"{location(node)}: {section}.{dotted}: {part} is a list; name one entry, e.g. {part}[0]"
            raise ConfigError(msg)
        if index is not None:
            if entry is None:
                msg = f"{location(node)}: {section}.{dotted}: {part} is not a list; write {part} without [{index}]"
                raise ConfigError(msg)
            count = len(value) if isinstance(value, list) else 0
            if index >= count:
                have = f"{part}[0] to {part}[{count - 1}]" if count else f"no {part}"
                msg = f"{location(node)}: {section}.{dotted}: the base scenario has {have}; vary one it has"
                raise ConfigError(msg)
            tp, value = entry, value[index]
        walked.append(part if index is None else f"{part}[{index}]")
    return tp


def _check_value(value: Any, tp: Any, node: yaml.Node, key: str, dotted: str) -> None:
    """Refuse a value of a section (`robots[1]`, `drive`) that is not a mapping of the section's keys.

    The value's keys are checked as a dotted key of the section would be; a type that also takes a
    scalar, or null, takes one. `key` names the value in the sweep file (`vary.robots[1]`).
    """
    fields = _fields(tp)
    if fields is None:
        return
    if not isinstance(value, dict):
        if (value is None and type(None) in typing.get_args(tp)) or not all(map(_is_dataclass, _members(tp))):
            return
        first = next(iter(fields))
        _fail(
            node,
            key,
            f"{dotted} is a section: each value is a mapping of its keys, got {value!r}; "
            f"write e.g. {{{first}: ...}}, or vary one of its keys, e.g. {dotted}.{first}",
        )
    for name, item in value.items():
        if str(name) not in fields:
            _fail(node, key, f"{dotted} has no key {name!r}{suggest(str(name), list(fields))}")
        _check_value(item, fields[str(name)], node, key, f"{dotted}.{name}")


def _fix_paths(value: Any, tp: Any, base_dir: Path) -> Any:
    """Make the relative paths in a value of type `tp` absolute, relative to `base_dir`."""
    members = _members(tp)
    if isinstance(value, str):
        if NameOrPath in members:  # a model's name stays; a path to one beside the file is made absolute
            return str(NameOrPath.beside(value, base_dir))
        if Path in members:
            path = Path(value).expanduser()
            return os.path.normpath(path if path.is_absolute() else base_dir / path)
        return value
    if isinstance(value, dict):
        fields = _fields(tp)
        if fields is not None:
            return {k: _fix_paths(v, fields.get(str(k), Any), base_dir) for k, v in value.items()}
        mappings = [m for m in members if typing.get_origin(m) in (dict, Mapping)]
        item = typing.get_args(mappings[0])[1] if mappings and typing.get_args(mappings[0]) else Any
        return {k: _fix_paths(v, item, base_dir) for k, v in value.items()}
    if isinstance(value, list):
        sequences = [m for m in members if typing.get_origin(m) in (tuple, list, Sequence)]
        args = typing.get_args(sequences[0]) if sequences else ()
        if (len(args) == 2 and args[1] is Ellipsis) or len(args) == 1:
            return [_fix_paths(v, args[0], base_dir) for v in value]
        if args and len(args) == len(value):
            return [_fix_paths(v, a, base_dir) for v, a in zip(value, args, strict=True)]
        return value
    return value


def _absolute_scenario(path: Path) -> dict[str, Any]:
    """The base scenario file as a mapping, with its relative paths made absolute."""
    from twin.sim.scenario import Scenario

    raw = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    fixed: dict[str, Any] = _fix_paths(raw, Scenario, path.parent)
    # Each run's scenario is written into its own folder; its nodes' modules stay those beside this file.
    fixed.setdefault("source_path", str(path.resolve()))
    return fixed


def _with_values(base: dict[str, Any], values: Sequence[tuple[str, Any]]) -> dict[str, Any]:
    out = json.loads(json.dumps(base))  # a deep copy of plain YAML data
    for dotted, value in values:
        *parents, (last, last_index) = _parts(dotted)
        section = out
        for part, index in parents:
            child = section.get(part)
            if index is not None:  # checked against the base scenario when the sweep was loaded
                child = child[index]
            elif not isinstance(child, dict):
                child = section[part] = {}
            section = child
        if last_index is None:
            section[last] = value
        else:  # a whole entry of a list (`robots[1]`): the list's other entries stay
            section[last][last_index] = value
    result: dict[str, Any] = out
    return result
