from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import pytest

from twin.core.config import load_config
from twin.core.errors import ConfigError


@dataclass(frozen=True, kw_only=True)
class Inner:
    rate_hz: float = 5.0
    names: tuple[str, ...] = ()


@dataclass(frozen=True, kw_only=True)
class VariantA:
    type: Literal["a"] = "a"
    gain: float = 1.0


@dataclass(frozen=True, kw_only=True)
class VariantB:
    type: Literal["b"] = "b"
    path: Path | None = None


@dataclass(frozen=True, kw_only=True)
class Spec:
    name: str
    count: int = 1
    inner: Inner = field(default_factory=Inner)
    mode: VariantA | VariantB = field(default_factory=VariantA)
    pose: tuple[float, float, float] = (0.0, 0.0, 0.0)


def write(tmp_path: Path, text: str, name: str = "s.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_builds_nested_dataclasses_and_converts_ints_to_floats(tmp_path: Path) -> None:
    spec = load_config(Spec, write(tmp_path, "name: x\ninner: {rate_hz: 10, names: [a, b]}\npose: [1, 2, 3]\n"))
    assert spec == Spec(name="x", inner=Inner(rate_hz=10.0, names=("a", "b")), pose=(1.0, 2.0, 3.0))
    assert isinstance(spec.inner.rate_hz, float)


def test_unknown_key_names_file_line_and_suggestion(tmp_path: Path) -> None:
    path = write(tmp_path, "name: x\ninner:\n  rate_hx: 3\n")
    with pytest.raises(ConfigError, match=rf"^{path}:3: inner.rate_hx: unknown key; did you mean 'rate_hz'\?$"):
        load_config(Spec, path)


def test_wrong_type_names_the_key(tmp_path: Path) -> None:
    path = write(tmp_path, "name: x\ncount: many\n")
    with pytest.raises(ConfigError, match=r":2: count: expected a whole number, got 'many'"):
        load_config(Spec, path)


def test_missing_required_key(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="missing required key.*name"):
        load_config(Spec, write(tmp_path, "count: 2\n"))


def test_invalid_yaml_reports_line_and_column(tmp_path: Path) -> None:
    path = write(tmp_path, "name: x\ncount: [1\n")
    with pytest.raises(ConfigError, match=rf"^{path}:3:1: invalid YAML"):
        load_config(Spec, path)


def test_variant_chosen_by_type_with_suggestion_on_typo(tmp_path: Path) -> None:
    spec = load_config(Spec, write(tmp_path, "name: x\nmode: {type: b, path: sub/file.fmu}\n"))
    assert spec.mode == VariantB(path=tmp_path / "sub" / "file.fmu")
    with pytest.raises(ConfigError, match=r"mode.type: unknown type 'aa'; did you mean 'a'\?"):
        load_config(Spec, write(tmp_path, "name: x\nmode: {type: aa}\n", "t.yaml"))


def test_defaults_merge_and_type_change_replaces_section(tmp_path: Path) -> None:
    defaults = write(
        tmp_path, "name: d\ncount: 4\ninner: {rate_hz: 7, names: [q]}\nmode: {type: a, gain: 3}\n", "d.yaml"
    )
    spec = load_config(Spec, write(tmp_path, "inner: {rate_hz: 8}\nmode: {type: b}\n"), defaults=defaults)
    assert spec == Spec(name="d", count=4, inner=Inner(rate_hz=8.0, names=("q",)), mode=VariantB())


def test_error_in_defaults_file_names_the_defaults_file(tmp_path: Path) -> None:
    defaults = write(tmp_path, "name: d\ncuont: 4\n", "d.yaml")
    with pytest.raises(ConfigError, match=rf"^{defaults}:2: cuont: unknown key; did you mean 'count'\?"):
        load_config(Spec, write(tmp_path, "name: x\n"), defaults=defaults)
