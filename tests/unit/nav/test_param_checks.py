"""twin.nav.param_checks: the servers' parameters, memory bounds, `navigation.set` keys, map numbers."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from twin.core.errors import ConfigError
from twin.nav.param_checks import check_map_fields, check_map_image, check_nav2_inputs, memory_budget_bytes
from twin.nav.params import default_params_path, load_nav2_params
from twin.nav.server_params import nav2_config


@pytest.mark.parametrize("model", ["burger", "waffle", "waffle_pi"])
def test_packaged_params_pass(model: str) -> None:
    check_nav2_inputs(load_nav2_params(default_params_path(model)), physics_step_s=0.001)


# DWB parameters TB3's files set that have no effect in the twin (its DWB samples no y velocity, keeps
# no per-plugin goal checker state, always scores every trajectory, and prints no debug details).
DWB_WITHOUT_EFFECT = {
    "controller_server.FollowPath.debug_trajectory_details",
    "controller_server.FollowPath.vy_samples",
    "controller_server.FollowPath.transform_tolerance",
    "controller_server.FollowPath.short_circuit_trajectory_evaluation",
    "controller_server.FollowPath.stateful",
}


def test_set_takes_what_the_twin_reads_and_refuses_what_it_lists_unused() -> None:
    model = "waffle"  # burger's and waffle_pi's files hold the same keys
    params = load_nav2_params(default_params_path(model))
    warning = params.warning(nav2_config(params).used) or ""
    unused = {key.replace("/global_costmap", "").replace("/local_costmap", "") for key in
              warning.rsplit("by the twin: ", 1)[-1].split(", ")}  # fmt: skip
    refused = set()
    for node, values in params.raw.items():
        short = node.rsplit("/", 1)[-1]
        for key, value in values.items():
            try:
                check_nav2_inputs(load_nav2_params(default_params_path(model), overrides={f"{short}.{key}": value}))
            except ConfigError as err:
                assert "did you mean" in str(err) or "remove it" in str(err) or "`map:`" in str(err), err
                refused.add(f"{short}.{key}")
    not_run = {key for key in refused if key.endswith(".use_sim_time")}  # nodes the twin does not run
    assert unused <= refused
    # map_server's yaml_filename: the scenario's `map:` names the map instead
    assert refused - unused - not_run == {"map_server.yaml_filename"}
    # DWB keys without effect in the twin are named unused too (the whole FollowPath section was taken as used)
    assert unused >= DWB_WITHOUT_EFFECT


def test_set_typo_suggests_the_parameter() -> None:
    params = load_nav2_params(default_params_path("waffle"), overrides={"controller_server.FollowPath.max_vel_xx": 1})
    with pytest.raises(ConfigError, match=r"did you mean 'controller_server\.FollowPath\.max_vel_x'\?"):
        check_nav2_inputs(params)


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ({"planner_server.planner_plugins": []}, "is empty, so planner_server has no plugin"),
        ({"controller_server.controller_plugins": []}, "is empty, so controller_server has"),
        # Nav2 gives a type only to the default name in the default list
        ({"planner_server.planner_plugins": ["Other"]}, "names 'Other', but Other.plugin is not set"),
        ({"controller_server.controller_plugins": ["Fast"]}, "names 'Fast', but Fast.plugin is not set"),
        # a costmap layer without its type was "the twin has no costmap layer ''", blamed on the params file
        ({"local_costmap/local_costmap.plugins": ["voxel_layer", "foo"]}, "names layer 'foo', but foo.plugin is not"),
    ],
)
def test_a_server_loading_no_plugin_or_one_of_no_type_is_refused_where_it_was_set(
    override: dict[str, object], message: str
) -> None:
    # `planner_plugins: []` was an IndexError (exit 70); an empty controller list failed the first goal at run time.
    with pytest.raises(ConfigError, match=rf"^navigation\.set\.{next(iter(override))}: .*{message}"):
        nav2_config(load_nav2_params(default_params_path("waffle"), overrides=override))


@pytest.mark.parametrize(
    ("override", "message"),
    [
        # a source without its block took the lidar's scan; Nav2's layer subscribes to "" and fails
        (
            {"local_costmap/local_costmap.voxel_layer.observation_sources": ["scan", "bump"]},
            r"names source 'bump', but voxel_layer\.bump\.topic is not set; give it a block",
        ),
        ({"global_costmap/global_costmap.obstacle_layer.scan.topic": ""}, "source 'scan' has an empty topic"),
        (
            {"local_costmap/local_costmap.voxel_layer.scan.data_type": "Range"},
            "must be LaserScan or PointCloud2, got 'Range'",
        ),
    ],
)
def test_an_observation_source_nav2_could_not_subscribe_is_refused_where_it_was_set(
    override: dict[str, object], message: str
) -> None:
    with pytest.raises(ConfigError, match=rf"^navigation\.set\.{next(iter(override))}: {message}"):
        nav2_config(load_nav2_params(default_params_path("waffle"), overrides=override))


def test_an_observation_source_without_its_block_names_the_line_of_the_list(tmp_path: Path) -> None:
    text = default_params_path("burger").read_text()
    path = tmp_path / "p.yaml"
    path.write_text(text.replace("observation_sources: scan\n", "observation_sources: scan bumper\n", 1))
    line = next(n for n, ln in enumerate(path.read_text().splitlines(), 1) if "scan bumper" in ln)
    with pytest.raises(ConfigError, match=rf"p\.yaml:{line}: .*observation_sources: names source 'bumper'"):
        nav2_config(load_nav2_params(path))


def test_set_keys_of_servers_are_known_when_nav2_does_not_run() -> None:
    params = load_nav2_params(default_params_path("waffle"), overrides={"controller_server.FollowPath.max_vel_x": 0.2})
    check_nav2_inputs(params, nav2=False)


def test_file_errors_name_the_line(tmp_path: Path) -> None:
    path = tmp_path / "p.yaml"
    path.write_text(
        "controller_server:\n  ros__parameters:\n    controller_plugins: [FollowPath]\n"
        "    FollowPath:\n      plugin: dwb_core::DWBLocalPlanner\n      critics: [BaseObstacle]\n"
        "      vx_samples: -3\n"
    )
    with pytest.raises(ConfigError, match=r"p\.yaml:7: controller_server\.FollowPath\.vx_samples: must be at least 1"):
        check_nav2_inputs(load_nav2_params(path))


def test_wildcard_values_name_their_line(tmp_path: Path) -> None:
    path = tmp_path / "p.yaml"
    path.write_text("/**:\n  ros__parameters:\n    sigma_hit: 0.0\n")
    with pytest.raises(ConfigError, match=r"p\.yaml:3: amcl\.sigma_hit: must be above 0"):
        load_nav2_params(path)


def test_memory_budget_follows_an_address_space_limit() -> None:
    code = (
        "import resource; resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30)); "
        "from twin.nav.param_checks import memory_budget_bytes; print(memory_budget_bytes())"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert int(out) == (3 << 30) // 2
    assert memory_budget_bytes() > 0


def test_map_numbers() -> None:
    ok = {"origin": (0.0, 0.0, 0.0), "occupied": 0.65, "free": 0.25, "scale": False}
    check_map_fields("m.yaml", resolution_m=0.05, **ok)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="'resolution' must be between"):
        check_map_fields("m.yaml", resolution_m=1e-300, **ok)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="'origin' yaw must be a finite number"):
        check_map_fields(
            "m.yaml", resolution_m=0.05, origin=(0.0, 0.0, float("inf")), occupied=0.65, free=0.25, scale=False
        )
    with pytest.raises(ConfigError, match="'occupied_thresh' must be between 0 and 1"):
        check_map_fields("m.yaml", resolution_m=0.05, origin=(0.0, 0.0, 0.0), occupied=1.5, free=0.25, scale=False)


@pytest.mark.parametrize(
    "head", [b"P5\n# a comment\n40000 40000\n255\n", b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\x00\x00\x9c@\x00\x00\x9c@"]
)
def test_image_size_comes_from_the_header(head: bytes, tmp_path: Path) -> None:
    path = tmp_path / "big.img"
    path.write_bytes(head + b"\x00" * 16)
    with pytest.raises(ConfigError, match="40000 x 40000 pixels"):
        check_map_image(path, "m.yaml")


def test_backup_and_drive_on_heading_limits_are_read_and_checked(tmp_path: Path) -> None:
    # Humble's DriveOnHeading / BackUp read <behaviour>.acceleration_limit, .deceleration_limit, .minimum_speed
    params = load_nav2_params(
        default_params_path("waffle"), overrides={"behavior_server.backup.deceleration_limit": -2.5}
    )
    check_nav2_inputs(params)
    path = tmp_path / "p.yaml"
    path.write_text(
        "controller_server:\n  ros__parameters:\n    FollowPath:\n      critics: [BaseObstacle]\n"
        "behavior_server:\n  ros__parameters:\n    drive_on_heading:\n      minimum_speed: -0.1\n"
    )
    with pytest.raises(ConfigError, match=r"p\.yaml:8: behavior_server\.drive_on_heading\.minimum_speed: must be"):
        check_nav2_inputs(load_nav2_params(path))
