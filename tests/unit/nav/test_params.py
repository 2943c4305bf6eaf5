from __future__ import annotations

from pathlib import Path

import pytest

from twin.core.errors import ConfigError
from twin.nav.params import default_params_path, load_nav2_params


def _params_files(fixtures: Path) -> list[Path]:
    return sorted(p for p in (fixtures / "nav2").rglob("*.yaml") if p.name != "map.yaml")


def test_every_tb3_and_nav2_humble_params_file_in_the_fixtures_loads(fixtures: Path) -> None:
    files = _params_files(fixtures)
    assert {f.name for f in files} >= {"burger.yaml", "waffle.yaml", "waffle_pi.yaml", "nav2_params.yaml"}
    for path in files:
        params = load_nav2_params(path)
        assert params.amcl.max_particles == 2000 and params.amcl.min_particles == 500
        assert params.amcl.max_beams == 60 and params.amcl.sigma_hit_m == 0.2
        assert params.global_costmap.global_frame == "map" and params.local_costmap.global_frame == "odom"
        assert params.local_costmap.rolling_window and params.local_costmap.width_m == 3.0
        assert (
            params.global_costmap.inflation is not None and params.global_costmap.inflation.cost_scaling_factor == 3.0
        )
        assert params.node("controller_server")  # the navigation lane's raw section is there


def test_tb3_waffle_values_reach_the_costmaps_as_the_facts_sheet_gives_them(fixtures: Path) -> None:
    params = load_nav2_params(fixtures / "nav2/turtlebot3_navigation2_humble/param/humble/waffle.yaml")
    local, glob = params.local_costmap, params.global_costmap
    assert (local.update_frequency_hz, local.publish_frequency_hz) == (5.0, 2.0)
    assert (glob.update_frequency_hz, glob.publish_frequency_hz) == (1.0, 1.0)
    assert local.robot_radius_m == 0.22 and local.resolution_m == 0.05
    assert local.inflation is not None and local.inflation.inflation_radius_m == 1.0
    assert glob.inflation is not None and glob.inflation.inflation_radius_m == 0.55
    assert glob.track_unknown_space and not local.track_unknown_space
    assert glob.static_layer is not None and local.static_layer is None
    # the local obstacle_layer's scan block sets no ranges: Nav2's defaults 2.5 / 3.0 apply
    scan = local.obstacle_layers[0].sources[0]
    assert (scan.obstacle_max_range_m, scan.raytrace_max_range_m, scan.clearing, scan.marking) == (2.5, 3.0, True, True)
    assert [layer.name for layer in local.obstacle_layers] == ["obstacle_layer", "voxel_layer"]


def test_unused_keys_are_listed_once_in_one_warning_line(fixtures: Path) -> None:
    params = load_nav2_params(fixtures / "nav2/turtlebot3_navigation2_humble/param/humble/burger.yaml")
    line = params.warning()
    assert line is not None and "\n" not in line
    assert "amcl.beam_skip_distance" in line and "map_saver.free_thresh_default" in line
    assert "amcl.alpha1" not in line and "use_sim_time" not in line
    assert line.count("amcl.z_short") == 1
    extra = params.warning({"controller_server": ["controller_frequency"]})
    assert extra is not None and "controller_server.failure_tolerance" in extra
    assert "controller_server.controller_frequency" not in extra


def test_packaged_default_is_tb3_humble_file_per_model(fixtures: Path) -> None:
    for model in ("burger", "turtlebot3_waffle", "waffle_pi"):
        path = default_params_path(model)
        assert path.is_file() and (path.parent / "LICENSE").is_file()
        name = model.removeprefix("turtlebot3_")
        fixture = fixtures / f"nav2/turtlebot3_navigation2_humble/param/humble/{name}.yaml"
        assert path.read_bytes() == fixture.read_bytes()
    assert load_nav2_params(default_params_path("burger")).local_costmap.robot_radius_m == 0.1
    with pytest.raises(ConfigError, match="no packaged Nav2 params"):
        default_params_path("jackal")


def test_wildcard_nested_namespaces_and_overrides(tmp_path: Path) -> None:
    path = tmp_path / "p.yaml"
    path.write_text(
        "/**:\n  ros__parameters:\n    use_sim_time: true\n    max_particles: 900\n"
        "/amcl:\n  ros__parameters:\n    min_particles: 100\n"
        "local_costmap:\n  local_costmap:\n    ros__parameters:\n      resolution: 0.1\n"
        "      plugins: [inflation_layer]\n      inflation_layer: {plugin: nav2_costmap_2d::InflationLayer, inflation_radius: 0.4}\n"
    )
    params = load_nav2_params(
        path, overrides={"amcl.min_particles": 200, "local_costmap": {"inflation_layer": {"cost_scaling_factor": 5.0}}}
    )
    assert params.amcl.max_particles == 900 and params.amcl.min_particles == 200
    local = params.local_costmap
    assert local.resolution_m == 0.1 and local.inflation is not None
    assert (local.inflation.inflation_radius_m, local.inflation.cost_scaling_factor) == (0.4, 5.0)
    assert params.global_costmap.resolution_m == 0.1  # not in the file: Nav2's code default


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("amcl:\n  ros__parameters:\n    alpha1: [0.2\n", r"p\.yaml:\d+: malformed Nav2 params YAML"),
        (
            "amcl:\n  ros__parameters:\n    max_particles: many\n",
            r"p\.yaml:3: amcl\.max_particles: expected an integer",
        ),
        ("amcl:\n  ros__parameters:\n    tf_broadcast: 1\n", r"amcl\.tf_broadcast: expected true or false"),
        (
            "global_costmap:\n  global_costmap:\n    ros__parameters:\n      inflation_layer:\n        cost_scaling_factor: high\n",
            r"p\.yaml:5: global_costmap/global_costmap\.inflation_layer\.cost_scaling_factor: expected a finite number",
        ),
        ("amcl: 3\n", r"'amcl' must be a mapping"),
        ("- a\n- b\n", "must map node names"),
    ],
)
def test_bad_params_fail_with_one_line_naming_file_and_key(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "p.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match) as info:
        load_nav2_params(path)
    assert "\n" not in str(info.value) and ConfigError.exit_code == 2


def test_a_section_given_twice_contributes_both_as_ros2s_parser_reads_it(tmp_path: Path) -> None:
    # A YAML loader kept only the later `amcl:` (max_particles fell back to its default without a
    # word); rcl's parser reads both, the later value winning for a parameter given in each.
    path = tmp_path / "p.yaml"
    path.write_text(
        "amcl:\n  ros__parameters:\n    max_particles: 1234\n    alpha1: 0.3\n"
        "local_costmap:\n  local_costmap:\n    ros__parameters:\n      width: 4\n"
        "amcl:\n  ros__parameters:\n    min_particles: 321\n    alpha1: 0.4\n"
        "local_costmap:\n  local_costmap:\n    ros__parameters:\n      height: 2\n"
    )
    params = load_nav2_params(path)
    assert (params.amcl.max_particles, params.amcl.min_particles, params.amcl.alpha1) == (1234, 321, 0.4)
    assert (params.local_costmap.width_m, params.local_costmap.height_m) == (4.0, 2.0)
    # a bad value in the earlier section is still named at its own line
    path.write_text(path.read_text().replace("max_particles: 1234", "max_particles: -5"))
    with pytest.raises(ConfigError, match=r"p\.yaml:3: amcl\.max_particles"):
        load_nav2_params(path)
