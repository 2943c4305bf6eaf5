"""`twin fmu check` speaks the user's terms: the variable table stays aligned for any type or causality,
and a mapping file's errors name its keys, never the Python classes behind them."""

from __future__ import annotations

import zipfile
from pathlib import Path

import pytest

from twin.cli import main
from twin.core.errors import ConfigError
from twin.cosim.build import resolve_fmu
from twin.cosim.contract import load_mapping


def _with_an_enumeration(tmp_path: Path) -> Path:
    """The built-in XM430 (FMI 3) with its gear ratio N an Enumeration and V_max a calculatedParameter."""
    source = resolve_fmu("builtin:xm430_w210", fmi_version=3)
    target = tmp_path / "enum.fmu"
    with zipfile.ZipFile(source) as src, zipfile.ZipFile(target, "w") as dst:
        for name in src.namelist():
            data = src.read(name)
            if name == "modelDescription.xml":
                text = data.decode()
                text = text.replace(
                    "<DefaultExperiment",
                    '<TypeDefinitions><EnumerationType name="Gear"><Item name="one" value="1"/></EnumerationType>'
                    "</TypeDefinitions>\n  <DefaultExperiment",
                )
                text = text.replace('<Float64 name="N"', '<Enumeration name="N" declaredType="Gear"', 1)
                text = text.replace(
                    'name="V_max" valueReference="18" causality="parameter"',
                    'name="V_max" valueReference="18" causality="calculatedParameter"',
                )
                data = text.encode()
            dst.writestr(name, data)
    return target


def test_the_variable_table_stays_aligned_for_long_types_and_causalities(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    main(["fmu", "check", str(_with_an_enumeration(tmp_path))])
    out = capsys.readouterr().out.splitlines()
    start = next(
        k for k, line in enumerate(out) if line.split() == ["name", "type", "causality", "variability", "unit", "start"]
    )
    header = out[start]
    rows = out[start + 1 : next(k for k, line in enumerate(out) if line.startswith("  contract"))]
    columns = [header.index(word) for word in ("type", "causality", "variability", "unit")]
    n_row = next(row for row in rows if row.split()[0] == "N")
    assert n_row.split()[1] == "Enumeration"
    v_row = next(row for row in rows if row.split()[0] == "V_max")
    assert v_row.split()[2] == "calculatedParameter"
    for row in rows:
        fields = row.split()
        for column, value in zip(columns, fields[1:5], strict=True):
            assert row[column:].startswith(value), (row, value)
            assert row[column - 1] == " "


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (
            "roles: [U, T_load, n]\n",
            "roles: expected a mapping (keys: voltage, speed_setpoint, load_torque, wheel_speed, wheel_angle, "
            "current, motor_torque, applied_voltage), got a list",
        ),
        ("roles: {voltage: {unit: V}}\n", "roles.voltage: missing required key(s): name"),
        ("roles: {voltage: [U, V]}\n", "roles.voltage: expected text or a mapping (keys: name, unit), got a list"),
    ],
)
def test_mapping_file_errors_use_the_files_terms(tmp_path: Path, text: str, expected: str) -> None:
    path = tmp_path / "map.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_mapping(path)
    message = str(err.value)
    assert message == f"{path}:1: {expected}"
    assert "RoleMap" not in message and "RoleBinding" not in message and "settings" not in message
