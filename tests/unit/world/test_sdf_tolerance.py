"""What real Gazebo worlds do that strict XML and SDF readers refuse, and the twin loads as Gazebo does.

Each case comes from worlds shipped with gz-sim and turtlebot3_simulations: undeclared `gz:` and
`experimental:` prefixes, `--` inside comments, blank lines before the XML declaration, a visual
with no geometry, the model's own name used as a frame, Fuel URIs (served from Gazebo's local Fuel
cache when it holds them), and joints to an include that could not be resolved.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import trimesh

from twin.core.errors import WorldError
from twin.world import load_world
from twin.world.types import Box, Cone, Mesh


@pytest.fixture(autouse=True)
def _no_real_fuel_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # Whatever Fuel cache this machine has must not change the results.
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.delenv("GZ_FUEL_CACHE_PATH", raising=False)
    monkeypatch.delenv("IGN_FUEL_CACHE_PATH", raising=False)


_BOX_LINK = "<link name='l'><collision name='c'><geometry><box><size>1 2 3</size></box></geometry></collision></link>"


def test_undeclared_prefixes_and_double_hyphen_comments_load(tmp_path: Path) -> None:
    world = tmp_path / "gz.sdf"
    world.write_text(
        '<?xml version="1.0" ?>\n<sdf version="1.9"><world name="w">\n'
        "<!-- try: gz service -s /world/w/create --reqtype gz.msgs.EntityFactory -->\n"
        "<physics name='1ms' type='ignored'><gz:policies><solver>x</solver></gz:policies></physics>\n"
        "<plugin filename='gz-sim-sensors-system' name='gz::sim::systems::Sensors'>"
        "<gz:system_priority>10</gz:system_priority><experimental:params a='1'/></plugin>\n"
        f"<model name='m' gz:type='x'><static>true</static>{_BOX_LINK}</model>\n"
        "</world></sdf>\n"
    )
    loaded = load_world(world)
    assert [m.name for m in loaded.models] == ["m"]
    assert isinstance(loaded.models[0].links[0].collisions[0].geometry, Box)
    plugin = loaded.plugins[0]
    assert [c.tag for c in plugin.element.children] == ["gz:system_priority", "experimental:params"]


def test_custom_elements_are_kept_and_named_as_such(tmp_path: Path) -> None:
    world = tmp_path / "custom.sdf"
    world.write_text('<sdf version="1.9"><world name="w">\n<gz:policies><p>1</p></gz:policies></world></sdf>')
    loaded = load_world(world)
    assert [n.tag for n in loaded.unknown] == ["gz:policies"]
    assert len(loaded.warnings) == 1
    assert f"{world}:2: custom element <gz:policies> in <world>" in loaded.warnings[0]


def test_blank_lines_before_the_declaration_are_accepted_and_counted(tmp_path: Path) -> None:
    world = tmp_path / "lead.sdf"
    world.write_text(
        '\n\n <?xml version="1.0" ?>\n<sdf version="1.6"><world name="w">\n<model name="a">\n</world></sdf>'
    )
    with pytest.raises(WorldError, match=r"lead\.sdf:6:\d+: malformed XML: Opening and ending tag mismatch"):
        load_world(world)


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ('<sdf version="1.6"><world name="w"></sdf>', "Opening and ending tag mismatch"),
        ('<sdf version="1.6"><world name=w/></sdf>', "AttValue"),
        ('<sdf version="1.6"><world name="w" name="v"/></sdf>', "Attribute name redefined"),
        ('<sdf version="1.6"><world name="w">&nbsp;</world></sdf>', "Entity 'nbsp' not defined"),
        ('<sdf version="1.6"/><sdf version="1.6"/>', "Extra content at the end of the document"),
        ('?xml version="1.0"?>\n<sdf version="1.6"/>', "Start tag expected"),
    ],
)
def test_errors_gazebo_also_refuses_still_fail_with_line_and_column(tmp_path: Path, text: str, reason: str) -> None:
    world = tmp_path / "bad.sdf"
    world.write_text(text)
    with pytest.raises(WorldError, match=rf"bad\.sdf:\d+:\d+: malformed XML: {reason}"):
        load_world(world)


def test_a_bare_ampersand_in_model_config_does_not_refuse_the_model(tmp_path: Path) -> None:
    # Six AWS hospital models describe themselves as "portal, door & car"; tinyxml2 reads that.
    model = tmp_path / "models" / "elevator_door"
    model.mkdir(parents=True)
    (model / "model.config").write_text(
        '<?xml version="1.0" ?>\n<model><name>door</name><sdf version="1.6">door.sdf</sdf>\n'
        "<description>3 parts: portal, door & car; &amp; &#38; &#x26; stay entities</description></model>\n"
    )
    (model / "door.sdf").write_text(f"<sdf version='1.6'><model name='door'>{_BOX_LINK}</model></sdf>")
    world = tmp_path / "w.world"
    world.write_text(
        "<sdf version='1.6'><world name='w'><include><uri>model://elevator_door</uri></include></world></sdf>"
    )
    loaded = load_world(world, model_path=[tmp_path / "models"])
    assert [m.name for m in loaded.models] == ["door"] and not loaded.warnings


def test_a_model_config_broken_otherwise_still_fails_with_its_line(tmp_path: Path) -> None:
    # Only a stray `&` is forgiven: a model.config that is otherwise broken still names its line.
    model = tmp_path / "models" / "m"
    model.mkdir(parents=True)
    (model / "model.config").write_text('<model>\n<sdf version="1.6">model.sdf</sdf>\n<description>a & b</model>\n')
    world = tmp_path / "w.world"
    world.write_text("<sdf version='1.6'><world name='w'><include><uri>model://m</uri></include></world></sdf>")
    with pytest.raises(WorldError, match=r"m/model\.config:3:\d+: malformed XML: Opening and ending tag mismatch"):
        load_world(world, model_path=[tmp_path / "models"])


def test_sdf_1_11_inertia_elements_and_cones_load_without_warnings(tmp_path: Path) -> None:
    # gz-sim's auto-inertia examples: <density> and <auto_inertia_params> in <collision> and <inertial>.
    world = tmp_path / "shapes.sdf"
    world.write_text(
        '<sdf version="1.11"><world name="w"><model name="cone"><link name="l">'
        '<inertial auto="true"><density>500</density></inertial>'
        "<collision name='c'><density>1240.0</density><auto_inertia_params><gz:voxel_size>0.01</gz:voxel_size>"
        "</auto_inertia_params><geometry><cone><radius>0.5</radius><length>1.0</length></cone></geometry>"
        "</collision></link></model></world></sdf>"
    )
    loaded = load_world(world)
    assert loaded.warnings == () and loaded.unknown == ()
    (collision,) = loaded.all_collisions()
    assert collision.geometry == Cone(radius_m=0.5, length_m=1.0)


def test_a_visual_without_geometry_warns_and_a_collision_without_one_fails(tmp_path: Path) -> None:
    world = tmp_path / "v.sdf"
    world.write_text(
        '<sdf version="1.6"><world name="w"><model name="box"><link name="l">\n'
        "<visual name='v'/><collision name='c'><geometry><box><size>1 1 1</size></box></geometry></collision>"
        "</link></model></world></sdf>"
    )
    loaded = load_world(world)
    assert loaded.models[0].links[0].visuals == ()
    assert len(loaded.models[0].links[0].collisions) == 1
    assert len(loaded.warnings) == 1 and "visual 'v' of link 'l' in model 'box' has no <geometry>" in loaded.warnings[0]
    world.write_text(world.read_text().replace("<visual name='v'/>", "<collision name='bare'/>"))
    with pytest.raises(WorldError, match=r"v\.sdf:2: collision 'bare' of link 'l' in model 'box' has no <geometry>"):
        load_world(world)


def test_the_model_name_stands_for_its_own_frame(tmp_path: Path) -> None:
    world = tmp_path / "own.sdf"
    world.write_text(
        '<sdf version="1.9"><world name="w"><model name="probe"><pose>1 0 0 0 0 0</pose>'
        "<link name='l'><pose relative_to='probe'>0 2 0 0 0 0</pose>"
        "<collision name='c'><geometry><sphere><radius>0.1</radius></sphere></geometry></collision></link>"
        "</model></world></sdf>"
    )
    link = load_world(world).models[0].links[0]
    assert link.T_world[:3, 3].tolist() == pytest.approx([1.0, 2.0, 0.0])


def _fuel_model(cache: Path, owner: str, name: str, version: int, size: float) -> None:
    folder = cache / "fuel.gazebosim.org" / owner.lower() / "models" / name.lower() / str(version)
    (folder / "meshes").mkdir(parents=True)
    trimesh.creation.box(extents=(size, size, size)).export(folder / "meshes" / "body.stl")
    (folder / "model.config").write_text(f'<model><name>{name}</name><sdf version="1.6">model.sdf</sdf></model>')
    (folder / "model.sdf").write_text(
        f'<sdf version="1.6"><model name="{name}"><static>true</static><link name="link">'
        f"<collision name='c'><geometry><box><size>{size} {size} {size}</size></box></geometry></collision>"
        "</link></model></sdf>"
    )


def test_fuel_includes_and_meshes_resolve_from_the_local_fuel_cache(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    cache = tmp_path / "fuel"
    monkeypatch.setenv("GZ_FUEL_CACHE_PATH", str(cache))
    _fuel_model(cache, "OpenRobotics", "Cardboard box", 1, 0.5)
    _fuel_model(cache, "OpenRobotics", "Cardboard box", 2, 0.7)
    _fuel_model(cache, "OpenRobotics", "Radio", 4, 0.2)
    world = tmp_path / "fuel.sdf"
    base = "https://fuel.gazebosim.org/1.0/OpenRobotics/models"
    world.write_text(
        '<sdf version="1.8"><world name="w">'
        f"<include><uri>{base}/Cardboard%20box</uri><name>newest</name></include>"
        f"<include><uri>{base}/Cardboard box/1</uri><name>first</name><pose>3 0 0 0 0 0</pose></include>"
        "<model name='radio'><static>true</static><link name='l'><collision name='c'><geometry><mesh>"
        f"<uri>{base}/Radio/4/files/meshes/body.stl</uri></mesh></geometry></collision></link></model>"
        "</world></sdf>"
    )
    loaded = load_world(world)
    assert loaded.warnings == ()
    sizes = {m.name: m.links[0].collisions[0].geometry for m in loaded.models}
    assert sizes["newest"] == Box(size_m=(0.7, 0.7, 0.7))
    assert sizes["first"] == Box(size_m=(0.5, 0.5, 0.5))
    mesh = sizes["radio"]
    assert isinstance(mesh, Mesh) and mesh.path is not None and mesh.path.is_file()


def test_an_uncached_fuel_collision_mesh_is_one_warning_and_skipped(tmp_path: Path) -> None:
    world = tmp_path / "fuel.sdf"
    uri = "https://fuel.gazebosim.org/1.0/OpenRobotics/models/Radio/4/files/meshes/Radio.dae"
    world.write_text(
        '<sdf version="1.8"><world name="w"><model name="radio"><static>true</static><link name="l">'
        f"<collision name='c'><geometry><mesh><uri>{uri}</uri></mesh></geometry></collision>"
        "</link></model></world></sdf>"
    )
    loaded = load_world(world)
    assert len(loaded.warnings) == 1
    assert f"cannot fetch collision mesh '{uri}' offline" in loaded.warnings[0]
    assert "link 'l' in model 'radio'" in loaded.warnings[0]
    assert loaded.models[0].links[0].collisions == ()


def test_joints_to_a_skipped_include_are_skipped_with_it(tmp_path: Path) -> None:
    world = tmp_path / "wings.sdf"
    world.write_text(
        '<sdf version="1.9"><world name="w"><model name="plane">'
        "<link name='body'><collision name='c'><geometry><box><size>1 1 1</size></box></geometry></collision></link>"
        "<include><uri>file://lift_drag_wing</uri><name>wing_1</name></include>\n"
        "<joint name='wing_joint' type='fixed'><parent>body</parent><child>wing_1::base_link</child></joint>\n"
        "<frame name='tip' attached_to='wing_1::base_link'/>"
        "</model></world></sdf>"
    )
    with pytest.raises(WorldError, match="'file://lift_drag_wing' not found in the model path"):
        load_world(world)
    loaded = load_world(world, missing_includes="warn")
    model = loaded.models[0]
    assert model.joints == () and model.frames == ()
    assert len(model.links) == 1
    assert any(f"{world}:2: <joint> 'wing_joint' refers to 'wing_1::base_link'" in w for w in loaded.warnings)
    assert any("<frame> 'tip' refers to 'wing_1::base_link'" in w for w in loaded.warnings)
