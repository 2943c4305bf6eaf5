"""Bad `obstacles:` and `blocks:` input: one line naming the file, the line and the key with the fix, exit 2.

Each case runs `twin scenario check` and `twin simulate` in-process (the `twin` command's path);
a refused `simulate` leaves no bag folder.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.robustness.helpers import assert_one_line_error
from twin.cli import main

BOX = "{shape: box, size_m: [0.3, 0.3, 0.4], pose: {x_m: 2.0, y_m: 0.0}}"

# case: (YAML lines after `name:`, what the one error line must hold, the line it must name or None)
CASES: dict[str, tuple[str, str, int | None]] = {
    "unknown_key": (
        "obstacles:\n  - {shape: box, size_m: [0.3, 0.3, 0.4], pose: {x_m: 2.0, y_m: 0.0}, apear_s: 3}\n",
        "obstacles[0].apear_s: unknown key; did you mean 'appear_s'?",
        3,
    ),
    "unit_less_key": (
        "obstacles:\n  - {shape: cylinder, radius: 0.2, height_m: 1.0, pose: {x_m: 2.0, y_m: 0.0}}\n",
        "did you mean 'radius_m'?",
        3,
    ),
    "unknown_shape": (
        "obstacles:\n  - {shape: cone, size_m: [0.3, 0.3, 0.4], pose: {x_m: 2.0, y_m: 0.0}}\n",
        "obstacles[0].shape: 'cone' is not allowed",
        3,
    ),
    "size_as_text": (
        "obstacles:\n  - {shape: box, size_m: [0.3, big, 0.4], pose: {x_m: 2.0, y_m: 0.0}}\n",
        "obstacles[0].size_m[1]: expected a number",
        3,
    ),
    "size_not_three": (
        "obstacles:\n  - {shape: box, size_m: [0.3, 0.3], pose: {x_m: 2.0, y_m: 0.0}}\n",
        "expected a list of 3 values",
        3,
    ),
    "negative_size": (
        "\nobstacles:\n  - {shape: box, size_m: [0.3, -0.3, 0.4], pose: {x_m: 2.0, y_m: 0.0}}\n",
        "obstacles[0]: size_m must be three sizes above 0 m",
        4,
    ),
    "negative_radius": (
        "obstacles:\n  - " + BOX + "\n  - {shape: cylinder, radius_m: -0.2, height_m: 1.7, pose: {x_m: 0, y_m: 2}}\n",
        "obstacles[1]: radius_m and height_m must be above 0 m",
        4,
    ),
    "vanish_before_appear": (
        "obstacles:\n  - {shape: box, size_m: [0.3, 0.3, 0.4], pose: {x_m: 2, y_m: 0}, appear_s: 10, vanish_s: 5}\n",
        "vanish_s (5.0) must be after appear_s (10.0)",
        3,
    ),
    "path_of_one_point": (
        "obstacles:\n  - {shape: cylinder, radius_m: 0.2, height_m: 1.7, path_xy_m: [[1, 1]], speed_mps: 0.5}\n",
        "obstacles[0]: path_xy_m needs at least 2 points",
        3,
    ),
    "path_without_speed": (
        "obstacles:\n  - {shape: cylinder, radius_m: 0.2, height_m: 1.7, path_xy_m: [[1, 1], [2, 1]]}\n",
        "a path needs speed_mps above 0 m/s",
        3,
    ),
    "pose_and_path": (
        "obstacles:\n  - {shape: cylinder, radius_m: 0.2, height_m: 1.7, pose: {x_m: 1, y_m: 1},"
        " path_xy_m: [[1, 1], [2, 1]], speed_mps: 0.5}\n",
        "give either pose",
        3,
    ),
    "box_with_radius": (
        "obstacles:\n  - {shape: box, size_m: [0.3, 0.3, 0.4], radius_m: 0.2, pose: {x_m: 2.0, y_m: 0.0}}\n",
        "a box takes size_m, not radius_m",
        3,
    ),
    "obstacles_not_a_list": ("obstacles: {shape: box}\n", "obstacles: expected a list", 2),
    "negative_block_count": ("blocks: {count: -1}\n", "blocks: count must be 0 (no blocks) or more", 2),
    "block_size_zero": ("blocks: {count: 3, size_m: 0}\n", "blocks: size_m must be above 0 m", 2),
    "more_blocks_than_locations": ("blocks: {count: 5}\n", "blocks.count: 5 blocks need as many locations", None),
    "blocks_without_locations": (
        "blocks: {count: 3}\nmission: {type: none}\n",
        "blocks.count: 3 blocks stand at the mission's locations",
        None,
    ),
    # two obstacles of one name, or one with a block's, were one model in /contacts and the markers
    "two_of_one_name": (
        "obstacles:\n  - {name: a, shape: box, size_m: [0.3, 0.3, 0.4], pose: {x_m: 2.0, y_m: 0.0}}\n"
        "  - {name: a, shape: box, size_m: [0.3, 0.3, 0.4], pose: {x_m: 3.0, y_m: 0.0}}\n",
        "obstacles[1].name: obstacles[0] has the same name 'a'; give each obstacle its own",
        None,
    ),
    "a_blocks_name": (
        "blocks: {count: 1}\nobstacles:\n  - {name: red_block, shape: box, size_m: [0.3, 0.3, 0.4], "
        "pose: {x_m: 2.0, y_m: 0.0}}\n",
        "obstacles[0]: its name 'red_block' is a block's",
        None,
    ),
    "spawn_inside_an_obstacle": (
        "obstacles:\n  - {shape: box, size_m: [1, 1, 1], pose: {x_m: 0.0, y_m: 0.0}}\n",
        "obstacles[0]: obstacle_0 stands on the robot's spawn pose",
        None,
    ),
}


@pytest.mark.parametrize("case", CASES, ids=str)
def test_bad_obstacle_input_is_one_line_with_exit_2_and_no_bag(
    case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    body, contains, line = CASES[case]
    path = tmp_path / "scenario.yaml"
    path.write_text("name: case\n" + body)
    bag = tmp_path / "bag"
    # `scenario check` refuses what the run refuses (it passed an obstacle on the spawn pose)
    commands = [["scenario", "check", str(path)], ["simulate", str(path), "--duration", "0.5", "--out", str(bag)]]
    for argv in commands:
        code = main(argv)
        err = capsys.readouterr().err
        assert code == 2, err
        error = assert_one_line_error(err, contains=contains)
        if line is not None:
            assert re.search(rf"{re.escape(str(path))}:{line}: ", error), error
        elif case != "spawn_inside_an_obstacle":
            assert str(path) in error, error
    assert not bag.exists()
