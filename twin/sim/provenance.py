"""What a run records about itself so that its bag can be traced and re-run (`twin simulate --from-bag`).

`run_provenance` gives the values `Recorder.add_provenance` writes (see `twin.bag.provenance`): the
twin version, the seed, the duration limit, the resolved scenario as YAML (every path absolute, also
for a scenario run by a relative path; every default filled in: it loads back to the same scenario),
and every FMU the drive loaded with its file name, SHA-256, model name and GUID / instantiation token.
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import json
import types
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from twin import __version__
from twin.sim.scenario import Ros2Section, Scenario, TfSection

__all__ = ["fmu_record", "run_provenance", "scenario_yaml"]


def _plain(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (dict, types.MappingProxyType)):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, Path):
        return str(value.absolute())  # a scenario run by a relative path: its files, from anywhere
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, str):
        return str(value)  # a `NameOrPath` as the text it is
    return value


def scenario_yaml(scenario: Scenario) -> str:
    """The scenario as YAML with every key: `load_scenario` of it gives an equal scenario."""
    dumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)  # libyaml's emitter when built: 10x faster
    plain = _plain(scenario)
    if scenario.ros2 == Ros2Section():  # a run off ROS 2 records what it did before the bridge existed
        del plain["ros2"]
    if scenario.tf == TfSection():  # namespaced TF (the default) records what it did before frame_prefix
        del plain["tf"]
    text: str = yaml.dump(plain, Dumper=dumper, sort_keys=False, allow_unicode=True)
    return text


def fmu_record(path: Path, *, model_name: str, guid: str) -> dict[str, str]:
    """An FMU's entry in the provenance: file name, SHA-256 of the file, model name, GUID / token.

    Not the file's folder: a built-in FMU lives in this machine's cache folder, and a bag carries
    nothing of the machine it was made on (the SHA-256 names the file wherever it is).
    """
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    return {"file": path.name, "sha256": digest, "model_name": model_name, "guid": guid}


def run_provenance(
    scenario: Scenario, *, duration_s: float | None, fmus: Sequence[Mapping[str, str]]
) -> dict[str, str]:
    """The values a run records in its bag (all strings; `fmus` a JSON list)."""
    return {
        "twin_version": __version__,
        "seed": str(scenario.seed),
        "duration_s": "" if duration_s is None else repr(float(duration_s)),
        "scenario_yaml": scenario_yaml(scenario),
        "fmus": json.dumps([dict(f) for f in fmus]),
    }
