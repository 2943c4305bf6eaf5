from __future__ import annotations

import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from twin.cli import main
from twin.core.errors import WorldError
from twin.world import load_model, load_world
from twin.world.types import Box, Cylinder, Mesh, Plane

REPO = Path(__file__).resolve().parents[3]
FIXTURES = REPO.parent / "shared" / "fixtures"


def _fixture_files() -> list[tuple[str, Path]]:
    out = []
    for tree in ("gazebo_classic", "gz_sim"):
        base = FIXTURES / tree
        files = sorted((base / "worlds").glob("*.world")) + sorted((base / "models").rglob("*.sdf"))
        out.extend((tree, f) for f in files)
    return out


@pytest.mark.parametrize(("tree", "path"), _fixture_files(), ids=lambda v: str(v).split("fixtures/")[-1])
def test_every_fixture_world_and_model_loads_with_world_info(
    tree: str, path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["world", "info", str(path), "--model-path", str(FIXTURES / tree / "models")])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "collisions" in out
    assert "Traceback" not in err


def test_world_info_json_counts_house_shapes(capsys: pytest.CaptureFixture[str]) -> None:
    import json

    path = FIXTURES / "gazebo_classic" / "worlds" / "turtlebot3_house.world"
    assert (
        main(["world", "info", str(path), "--model-path", str(FIXTURES / "gazebo_classic" / "models"), "--json"]) == 0
    )
    facts = json.loads(capsys.readouterr().out)
    assert facts["collisions"] == {"box": 100, "cylinder": 4, "mesh": 4, "plane": 1}
    assert facts["obstacles"] == 108  # the ground plane is not an obstacle
    assert facts["warnings"] == []


def test_missing_include_warns_by_default_and_fails_when_strict(capsys: pytest.CaptureFixture[str]) -> None:
    path = FIXTURES / "gz_sim" / "worlds" / "turtlebot3_autorace_2020.world"
    args = ["world", "info", str(path), "--model-path", str(FIXTURES / "gz_sim" / "models")]
    assert main(args) == 0
    assert "model://turtlebot3_autorace_2020/course' not found" in capsys.readouterr().out
    assert main([*args, "--strict"]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "turtlebot3_autorace_2020.world:11: <include> 'model://turtlebot3_autorace_2020/course' not found" in err[0]


def test_library_default_fails_on_missing_include(tmp_path: Path) -> None:
    world = tmp_path / "w.world"
    world.write_text('<sdf version="1.6"><world name="w">\n<include><uri>model://nowhere</uri></include></world></sdf>')
    with pytest.raises(WorldError, match=r"w.world:2: <include> 'model://nowhere' not found in the model path"):
        load_world(world, model_path=[tmp_path])


def test_fuel_ground_plane_and_sun_stand_in_and_other_fuel_models_warn(tmp_path: Path) -> None:
    world = tmp_path / "fuel.sdf"
    world.write_text(
        '<sdf version="1.8"><world name="w">'
        "<include><uri>https://fuel.gazebosim.org/1.0/OpenRobotics/models/Ground Plane</uri></include>"
        "<include><uri>https://fuel.gazebosim.org/1.0/OpenRobotics/models/Sun</uri></include>"
        "<include><uri>https://fuel.gazebosim.org/1.0/OpenRobotics/models/Cardboard box</uri></include>"
        "</world></sdf>"
    )
    loaded = load_world(world)
    assert [m.name for m in loaded.models] == ["ground_plane"]
    assert isinstance(loaded.models[0].links[0].collisions[0].geometry, Plane)
    assert len(loaded.warnings) == 1
    assert "Cardboard box" in loaded.warnings[0]


def _run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "twin", *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
        check=False,
    )


def test_malformed_xml_names_line_and_column_without_traceback(tmp_path: Path) -> None:
    bad = tmp_path / "bad.world"
    bad.write_text(
        '<?xml version="1.0"?>\n<sdf version="1.6">\n  <world name="x">\n    <model name="a">\n  </world>\n</sdf>\n'
    )
    result = _run_cli("world", "info", str(bad))
    assert result.returncode == 3
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1
    assert f"{bad}:5:" in lines[0]
    assert "malformed XML" in lines[0]
    assert "Traceback" not in result.stderr


def test_a_file_that_is_not_sdf_is_one_clear_line(tmp_path: Path) -> None:
    other = tmp_path / "notes.world"
    other.write_text("<html><body>hello</body></html>")
    result = _run_cli("world", "info", str(other))
    assert result.returncode == 3
    assert (
        result.stderr.strip()
        == f"twin: error: {other}: not an SDF file: the root element is <html>, expected <sdf version=...>"
    )


def test_missing_collision_mesh_names_file_model_and_link(tmp_path: Path) -> None:
    world = tmp_path / "m.world"
    world.write_text(
        '<sdf version="1.6"><world name="w"><model name="thing"><static>1</static><link name="body">\n'
        "<collision name='c'><geometry><mesh><uri>meshes/gone.stl</uri></mesh></geometry></collision>"
        "</link></model></world></sdf>"
    )
    with pytest.raises(WorldError) as info:
        load_world(world)
    message = str(info.value)
    assert f"{world}:2:" in message
    assert "'meshes/gone.stl'" in message and "link 'body'" in message and "model 'thing'" in message


def test_missing_visual_mesh_is_a_warning(tmp_path: Path) -> None:
    world = tmp_path / "v.world"
    world.write_text(
        '<sdf version="1.6"><world name="w"><model name="thing"><link name="body">'
        "<visual name='v'><geometry><mesh><uri>model://nothing/here.dae</uri></mesh></geometry></visual>"
        "<collision name='c'><geometry><box><size>1 1 1</size></box></geometry></collision>"
        "</link></model></world></sdf>"
    )
    loaded = load_world(world)
    visual = loaded.models[0].links[0].visuals[0]
    assert isinstance(visual.geometry, Mesh) and visual.geometry.path is None
    assert len(loaded.warnings) == 1 and "visual mesh 'model://nothing/here.dae' not found" in loaded.warnings[0]


def test_unknown_elements_warn_once_and_are_kept(tmp_path: Path) -> None:
    world = tmp_path / "u.world"
    world.write_text(
        '<sdf version="1.6"><world name="w"><model name="a"><sparkle>1</sparkle><sparkle>2</sparkle>'
        "<link name='l'><collision name='c'><geometry><box><size>1 1 1</size></box></geometry></collision></link>"
        "</model><model name='b'><sparkle>3</sparkle></model></world></sdf>"
    )
    loaded = load_world(world)
    assert len(loaded.warnings) == 1 and "unknown element <sparkle> in <model>" in loaded.warnings[0]
    assert [n.text for n in loaded.unknown] == ["1", "2", "3"]
    assert len(loaded.all_collisions()) == 1


def test_state_block_overrides_model_and_link_poses(tmp_path: Path) -> None:
    world = tmp_path / "s.world"
    world.write_text(
        """<sdf version="1.6"><world name="w">
        <model name="house"><static>1</static><pose>10 10 0 0 0 0</pose>
          <link name="wall_a"><pose>1 0 0 0 0 0</pose>
            <collision name="c"><pose>0 0 0.5 0 0 0</pose><geometry><box><size>2 0.1 1</size></box></geometry></collision></link>
          <link name="wall_b"><pose>0 1 0 0 0 0</pose>
            <collision name="c"><geometry><box><size>2 0.1 1</size></box></geometry></collision></link>
        </model>
        <state world_name="w">
          <model name="house"><pose>2 3 0 0 0 0</pose>
            <link name="wall_a"><pose>5 6 0 0 0 1.5707963267948966</pose></link>
          </model>
        </state></world></sdf>"""
    )
    loaded = load_world(world)
    house = loaded.model("house")
    assert house.T_world[:3, 3] == pytest.approx([2, 3, 0])
    wall_a = house.link("wall_a")
    assert wall_a.T_world[:3, 3] == pytest.approx([5, 6, 0])  # the link's state is in the world frame
    assert wall_a.collisions[0].T_world[:3, 3] == pytest.approx([5, 6, 0.5])
    assert wall_a.collisions[0].T_world[:2, 0] == pytest.approx([0, 1], abs=1e-12)
    # A link without a state moves with its model.
    assert house.link("wall_b").T_world[:3, 3] == pytest.approx([2, 4, 0])


def test_state_in_a_real_world_file_moves_models() -> None:
    path = FIXTURES / "gz_sim" / "worlds" / "turtlebot3_autorace_2020.world"
    loaded = load_world(path, model_path=[FIXTURES / "gz_sim" / "models"], missing_includes="warn")
    tunnel = loaded.model("tunnel_wall")
    assert tunnel.T_world[:3, 3] == pytest.approx([-0.964699, -1.03574, 0.0])
    assert tunnel.link("Wall_1").T_world[:3, 3] == pytest.approx([-1.91548, -1.005857, 0.0])


def test_sdf_17_relative_to_frames_and_nested_scopes(tmp_path: Path) -> None:
    world = tmp_path / "f.sdf"
    world.write_text(
        """<sdf version="1.8"><world name="w">
        <frame name="corner"><pose>10 0 0 0 0 1.5707963267948966</pose></frame>
        <model name="m"><pose relative_to="corner">1 0 0 0 0 0</pose>
          <frame name="mount" attached_to="base"><pose relative_to="base">0 0 1 0 0 0</pose></frame>
          <link name="base"><pose>0 2 0 0 0 0</pose></link>
          <link name="top"><pose relative_to="mount">0 0 0.5 0 0 0</pose>
            <collision name="c"><pose relative_to="__model__">0 0 0 0 0 0</pose><geometry><sphere><radius>0.1</radius></sphere></geometry></collision>
          </link>
          <joint name="j" type="fixed"><parent>base</parent><child>top</child><pose>0 0 0.25 0 0 0</pose></joint>
          <model name="inner"><pose relative_to="top">1 0 0 0 0 0</pose><link name="l"/></model>
          <link name="peer"><pose relative_to="inner::l">0 0 1 0 0 0</pose></link>
        </model></world></sdf>"""
    )
    loaded = load_world(world)
    m = loaded.model("m")
    assert m.T_world[:3, 3] == pytest.approx([10, 1, 0])  # 1 m along the corner's rotated x
    top = m.link("top")
    assert top.T_model[:3, 3] == pytest.approx([0, 2, 1.5])
    assert top.collisions[0].T_world[:3, 3] == pytest.approx([10, 1, 0])  # relative to __model__
    joint = m.joints[0]
    assert joint.T_model[:3, 3] == pytest.approx([0, 2, 1.75])  # joint poses default to the child frame
    assert loaded.model("m::inner").links[0].T_world[:3, 3] == pytest.approx(
        m.T_world[:3, :3] @ [1, 2, 1.5] + [10, 1, 0]
    )
    assert m.link("peer").T_model[:3, 3] == pytest.approx([1, 2, 2.5])


def test_relative_to_an_unknown_frame_is_an_error(tmp_path: Path) -> None:
    world = tmp_path / "e.sdf"
    world.write_text(
        '<sdf version="1.7"><model name="m"><link name="a"><pose relative_to="nope">0 0 0 0 0 0</pose></link></model></sdf>'
    )
    with pytest.raises(WorldError, match=r"e.sdf:1: no frame named 'nope' in model 'm'"):
        load_world(world)


def test_pose_degrees_and_quaternions(tmp_path: Path) -> None:
    world = tmp_path / "q.sdf"
    world.write_text(
        '<sdf version="1.9"><model name="m">'
        '<link name="a"><pose degrees="true">0 0 0 0 0 90</pose></link>'
        '<link name="b"><pose rotation_format="quat_xyzw">0 0 0 0 0 0.7071067811865476 0.7071067811865476</pose></link>'
        "</model></sdf>"
    )
    m = load_world(world).models[0]
    for name in ("a", "b"):
        assert m.link(name).T_model[:2, 0] == pytest.approx([0, 1], abs=1e-12)


@pytest.mark.parametrize(
    ("version", "axis_block", "expected"),
    [
        ("1.4", "<axis><xyz>0 1 0</xyz></axis>", (0, 0, -1)),  # 1.4: axis in the model frame
        ("1.5", "<axis><xyz>0 0 1</xyz></axis>", (0, 0, 1)),  # 1.5+: in the joint frame
        ("1.6", "<axis><xyz>0 1 0</xyz><use_parent_model_frame>true</use_parent_model_frame></axis>", (0, 0, -1)),
        ("1.7", '<axis><xyz expressed_in="__model__">0 1 0</xyz></axis>', (0, 0, -1)),
    ],
)
def test_joint_axis_frame_follows_the_sdf_version(
    version: str, axis_block: str, expected: tuple[int, ...], tmp_path: Path
) -> None:
    # The child link is rolled by +90 deg about x, so the model's y axis is the joint's -z.
    path = tmp_path / "j.sdf"
    path.write_text(
        f'<sdf version="{version}"><model name="m"><link name="p"/><link name="c"><pose>0 0 0 1.5707963267948966 0 0</pose></link>'
        f'<joint name="j" type="revolute"><parent>p</parent><child>c</child>{axis_block}</joint></model></sdf>'
    )
    joint = load_world(path).models[0].joints[0]
    assert joint.axis_xyz == pytest.approx(expected, abs=1e-12)


def test_include_with_name_pose_and_static_override(tmp_path: Path) -> None:
    models = tmp_path / "models" / "crate"
    models.mkdir(parents=True)
    (models / "model.config").write_text(
        '<model><sdf version="1.5">old.sdf</sdf><sdf version="1.6">model.sdf</sdf></model>'
    )
    (models / "old.sdf").write_text("<sdf version='1.5'><model name='wrong'/></sdf>")
    (models / "model.sdf").write_text(
        "<sdf version='1.6'><model name='crate'><pose>5 5 5 0 0 0</pose><link name='l'>"
        "<collision name='c'><geometry><box><size>1 1 1</size></box></geometry></collision></link></model></sdf>"
    )
    world = tmp_path / "w.world"
    world.write_text(
        "<sdf version='1.6'><world name='w'><include><uri>model://crate</uri><name>crate_2</name>"
        "<pose>1 2 0.5 0 0 0</pose><static>true</static></include></world></sdf>"
    )
    loaded = load_world(world, model_path=[tmp_path / "models"])
    crate = loaded.model("crate_2")
    assert crate.static
    assert crate.T_world[:3, 3] == pytest.approx([1, 2, 0.5])
    assert crate.source == models / "model.sdf"  # model.config's newest supported version


def test_env_model_path_is_searched(tmp_path: Path) -> None:
    (tmp_path / "box_model").mkdir()
    (tmp_path / "box_model" / "model.sdf").write_text(
        "<sdf version='1.6'><model name='box_model'><link name='l'/></model></sdf>"
    )
    world = tmp_path / "w.world"
    world.write_text("<sdf version='1.6'><world name='w'><include><uri>model://box_model</uri></include></world></sdf>")
    loaded = load_world(world, env={"GAZEBO_MODEL_PATH": str(tmp_path)})
    assert loaded.models[0].name == "box_model"


def test_collada_units_and_scale_are_applied() -> None:
    from twin.world.meshes import MeshCache

    world = load_world(FIXTURES / "gazebo_classic" / "models" / "turtlebot3_world" / "model.sdf")
    head = next(c for c in world.all_collisions() if c.name == "head")
    assert isinstance(head.geometry, Mesh)
    mesh = MeshCache().mesh(head.geometry, head.where)
    # hexagon.dae is 100 inches tall (unit meter=0.0254), scaled by 0.8 in the SDF.
    assert mesh.extents[2] == pytest.approx(100 * 0.0254 * 0.8, rel=1e-6)


def test_nested_house_models_keep_static_and_place_children() -> None:
    world = load_world(
        FIXTURES / "gz_sim" / "worlds" / "turtlebot3_house.world", model_path=[FIXTURES / "gz_sim" / "models"]
    )
    classic = load_world(
        FIXTURES / "gazebo_classic" / "worlds" / "turtlebot3_house.world",
        model_path=[FIXTURES / "gazebo_classic" / "models"],
    )
    assert all(m.static for m in world.all_models())
    walls = sorted(tuple(np.round(c.T_world[:3, 3], 6)) for c in world.all_collisions() if isinstance(c.geometry, Box))
    walls_classic = sorted(
        tuple(np.round(c.T_world[:3, 3], 6)) for c in classic.all_collisions() if isinstance(c.geometry, Box)
    )
    assert walls == walls_classic


def test_project_house_world_matches_the_thesis_house() -> None:
    from twin.world.scene import build_scene

    world = load_world(REPO / "sdf" / "worlds" / "house.sdf")
    assert world.warnings == ()
    walls = world.model("sim_house")
    assert len(walls.links) == 30
    assert all(isinstance(c.geometry, Box) and c.geometry.size_m[1:] == (0.15, 1.0) for c in walls.all_collisions())
    bounds = build_scene(world).bounds
    assert bounds is not None
    (xmin, ymin, _), (xmax, ymax, _) = bounds
    # TB3_FACTS 5.4: x in [-1.924, 6.254], y in [-1.462, 5.112] (rounded to the millimetre there).
    assert (xmin, xmax, ymin, ymax) == pytest.approx((-1.924, 6.254, -1.462, 5.112), abs=1.5e-3)


def test_thesis_locations_are_free_and_inside_the_house() -> None:
    from twin.world.scene import build_scene

    scene = build_scene(load_world(REPO / "sdf" / "worlds" / "house.sdf"))
    caster = scene.ray_caster(0.2)
    angles = np.linspace(0.0, 2 * math.pi, 7200, endpoint=False)
    locations = {
        "location1": (-1.0, -0.5),
        "location2": (0.5, 4.0),
        "location3": (4.0, 0.5),
        "location4": (2.75, 2.5),
        "spawn": (0.0, 0.0),
    }
    for name, xy in locations.items():
        ranges = caster.cast_rays(xy, angles, 100.0)
        assert np.isfinite(ranges).all(), f"{name} is not enclosed by walls"
        # Distance to the nearest wall: the minimum over a dense fan is within r*dtheta/2 of it.
        assert ranges.min() >= 0.25 + 0.01, f"{name} is {ranges.min():.3f} m from a wall"


def test_load_model_by_name_drops_its_pose_and_finds_cylinders() -> None:
    model = load_model("turtlebot3_burger", model_path=[FIXTURES / "gazebo_classic" / "models"])
    assert model.T_world == pytest.approx(np.eye(4))
    assert sum(isinstance(c.geometry, Cylinder) for c in model.all_collisions()) == 3


def test_load_model_unknown_name_says_where_it_looked(tmp_path: Path) -> None:
    with pytest.raises(WorldError, match=r"model 'ghost' not found.*add the folder holding it to the model path"):
        load_model("ghost", model_path=[tmp_path], env={})


def _crate_models(tmp_path: Path) -> Path:
    crate = tmp_path / "models" / "crate"
    crate.mkdir(parents=True)
    (crate / "model.sdf").write_text(
        "<sdf version='1.6'>\n<model name='crate'><link name='l'/></model></sdf>"  # the name is on line 2
    )
    return tmp_path / "models"


def test_a_second_include_of_a_model_points_at_that_include_and_asks_for_a_name(tmp_path: Path) -> None:
    models = _crate_models(tmp_path)
    world = tmp_path / "w.world"
    world.write_text(
        "<sdf version='1.6'><world name='w'>\n"
        "<include><uri>model://crate</uri></include>\n"
        "<include><uri>model://crate</uri><name>crate_2</name></include>\n"
        "<include>\n<pose>1 0 0 0 0 0</pose><uri>model://crate</uri></include>\n"
        "</world></sdf>"
    )
    with pytest.raises(WorldError) as raised:
        load_world(world, model_path=[models])
    assert str(raised.value) == (
        f"{world}:4: <include> 'model://crate' is a second model named 'crate' in the world "
        f"(the first is at {world}:2); give it a <name>"
    )
    # A <name> given twice (leon's warehouse.world: 'pallet B-1-1-1 support'): another one.
    world.write_text(
        "<sdf version='1.6'><world name='w'>\n"
        "<include><uri>model://crate</uri><name>a</name></include>\n"
        "<include><uri>model://crate</uri><name>a</name></include>\n"
        "</world></sdf>"
    )
    with pytest.raises(
        WorldError,
        match=r"w\.world:3: <include> 'model://crate' is a second model named 'a' .*"
        r"give it another <name>$",
    ):
        load_world(world, model_path=[models])


def test_a_second_nested_include_and_a_second_model_in_place_are_refused_where_they_are(tmp_path: Path) -> None:
    models = _crate_models(tmp_path)
    world = tmp_path / "w.world"
    at = re.escape(str(world))
    world.write_text(
        "<sdf version='1.6'><world name='w'><model name='shelf'>\n"
        "<include><uri>model://crate</uri></include>\n<include><uri>model://crate</uri></include>\n"
        "</model></world></sdf>"
    )
    with pytest.raises(
        WorldError,
        match=rf"^{at}:3: <include> 'model://crate' is a second model named 'crate' in "
        rf"model 'shelf' \(the first is at {at}:2\); give it a <name>$",
    ):
        load_world(world, model_path=[models])
    world.write_text(
        "<sdf version='1.6'><world name='w'>\n<model name='a'><link name='l'/></model>\n"
        "<model name='a'><link name='l'/></model></world></sdf>"
    )
    with pytest.raises(
        WorldError,
        match=rf"^{at}:3: a second model named 'a' in the world \(the first is at "
        rf"{at}:2\); model names must be unique: rename it$",
    ):
        load_world(world)


def _stl(path: Path) -> None:
    """Write a binary STL of one triangle."""
    import struct

    path.parent.mkdir(parents=True, exist_ok=True)
    corners = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0)
    path.write_bytes(b"\0" * 80 + struct.pack("<I", 1) + struct.pack("<12fH", 0, 0, 1, *corners, 0))


def _bookstore(tmp_path: Path, uri: str) -> tuple[Path, Path]:
    """A package folder holding models/shelf, whose collision mesh is named by `uri`; and a world including it."""
    root = tmp_path / "bookstore"
    model = root / "models" / "shelf"
    model.mkdir(parents=True)
    (model / "model.sdf").write_text(
        "<sdf version='1.6'><model name='shelf'><static>1</static><link name='link'><collision name='c'>"
        f"<geometry><mesh><uri>{uri}</uri></mesh></geometry></collision></link></model></sdf>"
    )
    world = root / "worlds" / "w.world"
    world.parent.mkdir()
    world.write_text("<sdf version='1.6'><world name='w'><include><uri>model://shelf</uri></include></world></sdf>")
    return root, world


@pytest.mark.parametrize("scheme", ["package://", "model://"])
def test_a_missing_package_or_model_mesh_names_the_folder_to_add(tmp_path: Path, scheme: str) -> None:
    # package://turtlebot3_description/... resolves once the folder holding turtlebot3_description/ is on the path
    root, world = _bookstore(tmp_path, f"{scheme}turtlebot3_description/meshes/bases/waffle_base.stl")
    with pytest.raises(WorldError) as raised:
        load_world(world, model_path=[root / "models"])
    assert str(raised.value).endswith("; add the folder that holds turtlebot3_description/ to the model path")
    packages = tmp_path / "ros_ws" / "share"
    _stl(packages / "turtlebot3_description" / "meshes" / "bases" / "waffle_base.stl")
    load_world(world, model_path=[root / "models", packages])  # as the message says


def test_a_file_uri_relative_to_the_package_names_the_folder_to_add(tmp_path: Path) -> None:
    root, world = _bookstore(tmp_path, "file://models/shelf/meshes/shelf_collision.stl")
    _stl(root / "models" / "shelf" / "meshes" / "shelf_collision.stl")
    with pytest.raises(WorldError) as raised:
        load_world(world, model_path=[root / "models"])
    mesh = root / "models" / "shelf" / "meshes" / "shelf_collision.stl"
    assert str(raised.value).endswith(f"; it is {mesh}: add {root} to the model path")
    loaded = load_world(world, model_path=[root / "models", root])  # as the message says
    assert loaded.models[0].links[0].collisions[0].geometry == Mesh(
        uri=f"file://models/shelf/meshes/{mesh.name}", path=mesh
    )


def test_a_missing_relative_mesh_says_which_folder_lacks_it(tmp_path: Path) -> None:
    root, world = _bookstore(tmp_path, "file://models/shelf/meshes/gone.stl")
    (root / "models" / "shelf" / "meshes").mkdir()
    with pytest.raises(
        WorldError,
        match=r"'file://models/shelf/meshes/gone.stl' is relative to a folder on the "
        rf"model path, such as {re.escape(str(root))}, which lacks it$",
    ):
        load_world(world, model_path=[root / "models"])


def test_a_mesh_whose_name_differs_only_in_case_is_used_with_one_warning(tmp_path: Path) -> None:
    # aws_robomaker_retail_Spotlight_01 names aws_Spotlight_01_collision.DAE; the file is aws_spotlight_...
    root, world = _bookstore(tmp_path, "file://models/shelf/meshes/Shelf_Collision.STL")
    actual = root / "models" / "shelf" / "meshes" / "shelf_collision.stl"
    _stl(actual)
    loaded = load_world(world, model_path=[root / "models", root])
    geometry = loaded.models[0].links[0].collisions[0].geometry
    assert isinstance(geometry, Mesh) and geometry.path == actual
    (warning,) = loaded.warnings
    assert f"mesh 'file://models/shelf/meshes/Shelf_Collision.STL' not found; using {actual}, whose name" in warning


_FAR_BOX = (
    "<model name='{name}'><static>1</static>\n{pose}<link name='l'><collision name='c'><geometry><box>"
    "<size>1 1 1</size></box></geometry></collision></link></model>\n"
)


@pytest.mark.parametrize(("pose", "far"), [("1e30 0 0 0 0 0", "1e+30"), ("0 -2e7 0 0 0 0", "-2e+07")])
def test_a_model_placed_beyond_any_world_is_left_out_and_named(tmp_path: Path, pose: str, far: str) -> None:
    # AWS's hospital world saved furniture that fell through the floor at z = -7.6e8 m: Gazebo loads
    # the world; the twin leaves the model out (1e30 m overflowed the map's cells) and says where.
    world = tmp_path / "far.world"
    world.write_text(
        "<sdf version='1.6'><world name='w'>\n"
        + _FAR_BOX.format(name="far", pose=f"<pose>{pose}</pose>")
        + _FAR_BOX.format(name="near", pose="<pose>1 0 0.5 0 0 0</pose>")
        + "<model name='fallen'><static>1</static>\n<include><uri>model://crate</uri>"
        + f"<pose>{pose}</pose></include></model>\n"
        + "</world></sdf>"
    )
    crate = tmp_path / "models" / "crate"
    crate.mkdir(parents=True)
    (crate / "model.config").write_text("<model><name>crate</name><sdf>model.sdf</sdf></model>")
    (crate / "model.sdf").write_text("<sdf version='1.6'>" + _FAR_BOX.format(name="crate", pose="") + "</sdf>")
    loaded = load_world(world, model_path=[tmp_path / "models"])
    assert [m.name for m in loaded.models] == ["near"]
    assert [w for w in loaded.warnings if "beyond any world" in w] == [
        f"{world}:3: a <pose> {far} m from its frame's origin, beyond any world, places model 'far': left out",
        f"{world}:7: a <pose> {far} m from its frame's origin, beyond any world, places model 'fallen': left out",
    ]


def test_a_world_state_that_puts_a_model_beyond_any_world_leaves_it_out(tmp_path: Path) -> None:
    world = tmp_path / "state.world"
    world.write_text(
        "<sdf version='1.6'><world name='w'>\n"
        + _FAR_BOX.format(name="shelf", pose="<pose>1 0 0.5 0 0 0</pose>")
        + "<state world_name='w'><model name='shelf'>\n<pose>0 0 -7.57769e+08 0 0 0</pose></model></state>"
        + "</world></sdf>"
    )
    loaded = load_world(world)
    assert loaded.models == ()
    assert (
        f"{world}:5: a <pose> -7.57769e+08 m from its frame's origin, beyond any world, places model 'shelf': left out"
        in loaded.warnings
    )


def test_a_model_placed_on_one_beyond_any_world_is_left_out_with_it_and_the_rest_loads(tmp_path: Path) -> None:
    world = tmp_path / "rel.world"
    world.write_text(
        "<sdf version='1.7'><world name='w'>\n<model name='fallen'><pose>0 0 -7e8 0 0 0</pose><link name='l'/></model>\n"
        "<model name='on_it'><pose relative_to='fallen'>0 0 1 0 0 0</pose><link name='l'/></model>\n"
        "<model name='also_on_it'><pose relative_to='fallen'>0 0 2 0 0 0</pose><link name='l'/></model>\n"
        "<model name='fine'><pose>1 0 0 0 0 0</pose><link name='l'/></model>\n</world></sdf>"
    )
    loaded = load_world(world)
    assert [m.name for m in loaded.models] == ["fine"]  # (a second model on it was a relative_to "cycle")
    assert [w.rsplit("places ", 1)[1] for w in loaded.warnings] == [
        "model 'fallen': left out",
        "model 'on_it': left out",
        "model 'also_on_it': left out",
    ]


def test_a_robot_link_beyond_any_world_is_refused_where_it_is(tmp_path: Path) -> None:
    model = tmp_path / "bot.sdf"
    model.write_text(
        "<sdf version='1.6'><model name='bot'>\n<link name='base'>\n<pose>0 0 1e9 0 0 0</pose></link></model></sdf>"
    )
    with pytest.raises(WorldError) as raised:
        load_world(model)
    assert str(raised.value) == (
        f"{model}:3: <pose> puts something 1e+09 m from its frame's origin; no world is larger than 1e7 m"
    )


def _frame_and_model_named_ground(version: str) -> str:
    return (
        f"<sdf version='{version}'><world name='w'>\n<model name='ground'><pose>0 2 0 0 0 0</pose><link name='L'/>"
        "</model>\n<frame name='ground'><pose>0 0 3 0 0 0</pose></frame>\n"
        "<model name='above'><pose relative_to='ground_frame'>1 0 0 0 0 0</pose><link name='L'/></model>\n"
        "</world></sdf>"
    )


def test_a_frame_named_like_a_model_is_renamed_before_sdf_1_7_as_libsdformat_does(tmp_path: Path) -> None:
    world = tmp_path / "w.world"
    world.write_text(_frame_and_model_named_ground("1.6"))
    loaded = load_world(world)
    poses = {m.name: tuple(m.T_world[:3, 3]) for m in loaded.models}
    assert poses == {"ground": (0.0, 2.0, 0.0), "above": (1.0, 0.0, 3.0)}  # the frame is `ground_frame`
    assert any("read as 'ground_frame'" in w and f"{world}:3:" in w for w in loaded.warnings)


def test_a_renamed_frame_takes_a_name_no_sibling_has(tmp_path: Path) -> None:
    # `a` renamed `a_frame` beside a frame already named so: one of the two was lost
    world = tmp_path / "w.world"
    world.write_text(
        "<sdf version='1.6'><world name='w'><model name='m'><link name='a'/>\n"
        "<frame name='a'><pose>5 0 0 0 0 0</pose></frame>\n<frame name='a_frame'><pose>9 0 0 0 0 0</pose></frame>\n"
        "</model></world></sdf>"
    )
    (model,) = load_world(world).models
    frames = {f.name: float(np.asarray(f.T_world)[0, 3]) for f in model.frames}
    assert frames == {"a_frame0": 5.0, "a_frame": 9.0}


def test_a_frame_named_like_a_model_is_refused_from_sdf_1_7_in_one_line(tmp_path: Path) -> None:
    # was an AssertionError (exit 70); libsdformat refuses it (DUPLICATE_NAME)
    world = tmp_path / "w.world"
    world.write_text(_frame_and_model_named_ground("1.7").replace("ground_frame", "ground"))
    with pytest.raises(WorldError) as raised:
        load_world(world)
    assert str(raised.value).startswith(f"{world}:3: <frame name='ground'> has the name of the <model> at {world}:2")
    assert str(raised.value).endswith("must be unique: rename one")


def test_a_nested_model_named_like_a_link_is_refused_in_one_line(tmp_path: Path) -> None:
    world = tmp_path / "w.world"
    world.write_text(
        "<sdf version='1.7'><world name='w'><model name='outer'>\n<link name='inner'/>\n"
        "<model name='inner'><link name='L'/></model></model></world></sdf>"
    )
    with pytest.raises(WorldError, match=rf"^{world}:3: model 'inner' has the name of a <link> at {world}:2"):
        load_world(world)


def test_an_included_actor_is_skipped_with_a_warning_as_an_inline_actor_is(tmp_path: Path) -> None:
    actor = tmp_path / "models" / "walker"
    actor.mkdir(parents=True)
    (actor / "model.config").write_text("<model><name>walker</name><sdf>model.sdf</sdf></model>")
    (actor / "model.sdf").write_text(
        "<sdf version='1.8'><actor name='walker'><skin><filename>w.dae</filename></skin></actor></sdf>"
    )
    world = tmp_path / "w.world"
    world.write_text("<sdf version='1.8'><world name='w'>\n<include><uri>model://walker</uri></include></world></sdf>")
    loaded = load_world(world, model_path=[tmp_path / "models"])
    assert loaded.models == ()
    (warning,) = loaded.warnings
    assert warning.startswith(f"{world}:2: <include> 'model://walker' is an <actor>") and "not simulated" in warning


def test_a_joint_whose_child_is_missing_is_named_with_the_fix(tmp_path: Path) -> None:
    # gazebo_models' drc_practice_handle_wheel_valve_wall names a child 'handle::link' it does not have
    world = tmp_path / "j.world"
    world.write_text(
        "<sdf version='1.6'><world name='w'><model name='m'>\n<link name='base'/>\n"
        "<joint name='hinge' type='revolute'><parent>base</parent>\n<child>handle::link</child></joint>\n"
        "</model></world></sdf>"
    )
    with pytest.raises(WorldError) as raised:
        load_world(world)
    assert str(raised.value) == (
        f"{world}:3: joint 'hinge': its <child> 'handle::link' is no link or frame of model 'm' "
        "(frames here: __model__, base, hinge); name one of them in <child>"
    )


def test_a_file_of_several_worlds_loads_the_first_and_says_so(tmp_path: Path) -> None:
    world = tmp_path / "two.world"
    world.write_text(
        "<sdf version='1.6'>\n<world name='a'><model name='m'><link name='l'/></model></world>\n"
        "<world name='b'/>\n</sdf>"
    )
    loaded = load_world(world)
    assert loaded.name == "a"
    assert f"{world}:3: the file holds 2 worlds; the twin loads the first, 'a', and not 'b'" in loaded.warnings
