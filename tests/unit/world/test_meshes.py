"""Mesh files for collision: triangles only, read as Gazebo reads them, without trimesh's console noise."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from twin.cli import main
from twin.core.errors import WorldError
from twin.world.meshes import MeshCache, geometry_arrays
from twin.world.types import Mesh

# A unit cube as 6 quads (polylist, vcount 4) around the origin.
_CUBE_POSITIONS = "-.5 -.5 -.5  .5 -.5 -.5  .5 .5 -.5  -.5 .5 -.5  -.5 -.5 .5  .5 -.5 .5  .5 .5 .5  -.5 .5 .5"
_CUBE_QUADS = "0 3 2 1  4 5 6 7  0 1 5 4  1 2 6 5  2 3 7 6  3 0 4 7"

# An effect whose colour, emission and bump map are images outside the mesh folder (as in Gazebo's
# model folders, `../materials/textures/`), none of which exist.
_TEXTURED_EFFECT = """
<library_images>
  <image id="tex"><init_from>../materials/textures/missing_diffuse.png</init_from></image>
  <image id="bump"><init_from>../materials/textures/missing_bump.png</init_from></image>
</library_images>
<library_effects><effect id="fx"><profile_COMMON>
  <newparam sid="tex-surface"><surface type="2D"><init_from>tex</init_from></surface></newparam>
  <newparam sid="tex-sampler"><sampler2D><source>tex-surface</source></sampler2D></newparam>
  <newparam sid="bump-surface"><surface type="2D"><init_from>bump</init_from></surface></newparam>
  <newparam sid="bump-sampler"><sampler2D><source>bump-surface</source></sampler2D></newparam>
  <technique sid="common"><phong>
    <emission><texture texture="tex-sampler" texcoord="UV"/></emission>
    <diffuse><texture texture="tex-sampler" texcoord="UV"/></diffuse>
  </phong>
  <extra><technique profile="FCOLLADA"><bump><texture texture="bump-sampler" texcoord="UV"/></bump></technique></extra>
  </technique>
</profile_COMMON></effect></library_effects>
<library_materials><material id="mat"><instance_effect url="#fx"/></material></library_materials>
"""


_PLAIN_EFFECT = """
<library_effects><effect id="fx"><profile_COMMON><technique sid="common">
  <phong><diffuse><color>0.8 0.8 0.8 1</color></diffuse></phong>
</technique></profile_COMMON></effect></library_effects>
<library_materials><material id="mat"><instance_effect url="#fx"/></material></library_materials>
"""


def _dae(
    nodes: str,
    *,
    unit_m: float = 1.0,
    libraries: str = _PLAIN_EFFECT,
    geometries: tuple[str, ...] = ("cube",),
    material: str = "#mat",
) -> str:
    """Return a COLLADA document with a cube geometry per name in `geometries` and the given scene nodes."""
    geometry = "".join(
        f"""<geometry id="{name}" name="{name}"><mesh>
          <source id="{name}-pos"><float_array id="{name}-arr" count="24">{_CUBE_POSITIONS}</float_array>
            <technique_common><accessor source="#{name}-arr" count="8" stride="3">
              <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
            </accessor></technique_common></source>
          <vertices id="{name}-vtx"><input semantic="POSITION" source="#{name}-pos"/></vertices>
          <polylist material="m" count="6"><input semantic="VERTEX" source="#{name}-vtx" offset="0"/>
            <vcount>4 4 4 4 4 4</vcount><p>{_CUBE_QUADS}</p></polylist>
        </mesh></geometry>"""
        for name in geometries
    )
    return f"""<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="u" meter="{unit_m}"/><up_axis>Z_UP</up_axis></asset>
  {libraries}
  <library_geometries>{geometry}</library_geometries>
  <library_visual_scenes><visual_scene id="scene">{nodes}</visual_scene></library_visual_scenes>
  <scene><instance_visual_scene url="#scene"/></scene>
</COLLADA>""".replace("#mat", material)


def _instance(geometry: str = "cube") -> str:
    return (
        f'<instance_geometry url="#{geometry}"><bind_material><technique_common>'
        '<instance_material symbol="m" target="#mat"/></technique_common></bind_material></instance_geometry>'
    )


def _mesh_file(tmp_path: Path, text: str, name: str = "part.dae") -> Path:
    folder = tmp_path / "model" / "meshes"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(text)
    return path


def _arrays(path: Path, **options: object) -> tuple[np.ndarray, np.ndarray]:
    mesh = geometry_arrays(Mesh(uri=str(path), path=path, **options), MeshCache(), "test")  # type: ignore[arg-type]
    assert mesh is not None
    return mesh.vertices, mesh.faces


def test_collada_whose_textures_cannot_be_found_loads_without_log_records(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = _mesh_file(tmp_path, _dae(f'<node id="n">{_instance()}</node>', libraries=_TEXTURED_EFFECT))
    with caplog.at_level(logging.INFO):
        vertices, faces = _arrays(path)
    assert len(faces) == 12  # 6 quads, each split in two
    assert vertices.min(axis=0) == pytest.approx([-0.5] * 3) and vertices.max(axis=0) == pytest.approx([0.5] * 3)
    assert not caplog.records, [r.getMessage() for r in caplog.records]


def test_world_info_on_a_textured_collision_mesh_prints_no_warning_or_traceback(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _mesh_file(tmp_path, _dae(f'<node id="n">{_instance()}</node>', libraries=_TEXTURED_EFFECT))
    (tmp_path / "model" / "model.sdf").write_text(
        "<sdf version='1.6'><model name='barrel'><static>1</static><link name='l'><collision name='c'>"
        "<geometry><mesh><uri>model://model/meshes/part.dae</uri></mesh></geometry></collision></link></model></sdf>"
    )
    world = tmp_path / "w.world"
    world.write_text("<sdf version='1.6'><world name='w'><include><uri>model://model</uri></include></world></sdf>")
    code = main(["world", "info", str(world), "--model-path", str(tmp_path)])
    captured = capsys.readouterr()
    assert code == 0
    assert "collisions  1 (mesh 1)" in captured.out
    assert "Traceback" not in captured.err and "WARNING" not in captured.err, captured.err


def test_collada_geometry_whose_material_is_missing_still_loads_as_in_gazebo(tmp_path: Path) -> None:
    # pycollada (and so trimesh) dropped this instance and the file then held "no triangles".
    path = _mesh_file(tmp_path, _dae(f'<node id="n">{_instance()}</node>', material="#no_such_material"))
    _, faces = _arrays(path)
    assert len(faces) == 12


def test_collada_unit_and_node_transforms_apply_in_document_order(tmp_path: Path) -> None:
    # Centimetres; the outer node moves by (100, 0, 0) cm, the inner one turns 90 deg about z, then
    # scales x by 2: the cube's x extent (2 units after scaling) ends up along y.
    nodes = (
        '<node id="outer"><translate>100 0 0</translate>'
        f'<node id="inner"><rotate>0 0 1 90</rotate><scale>2 1 1</scale>{_instance()}</node></node>'
    )
    path = _mesh_file(tmp_path, _dae(nodes, unit_m=0.01))
    vertices, _ = _arrays(path)
    assert vertices.min(axis=0) == pytest.approx([0.995, -0.01, -0.005])
    assert vertices.max(axis=0) == pytest.approx([1.005, 0.01, 0.005])


def test_collada_matrix_and_instance_node_are_followed(tmp_path: Path) -> None:
    library = f'{_PLAIN_EFFECT}<library_nodes><node id="shared">{_instance()}</node></library_nodes>'
    nodes = (
        '<node id="a"><matrix>1 0 0 3  0 1 0 0  0 0 1 0  0 0 0 1</matrix><instance_node url="#shared"/></node>'
        '<node id="b"><translate>-3 0 0</translate><instance_node url="#shared"/></node>'
    )
    path = _mesh_file(tmp_path, _dae(nodes, libraries=library))
    vertices, faces = _arrays(path)
    assert len(faces) == 24
    assert vertices[:, 0].min() == pytest.approx(-3.5) and vertices[:, 0].max() == pytest.approx(3.5)


def test_submesh_selects_the_named_node_and_centres_it(tmp_path: Path) -> None:
    nodes = (
        f'<node id="left" name="Left"><translate>-5 0 0</translate>{_instance("a")}</node>'
        f'<node id="right" name="Right"><translate>5 2 0</translate>{_instance("b")}</node>'
    )
    path = _mesh_file(tmp_path, _dae(nodes, geometries=("a", "b")))
    vertices, faces = _arrays(path, submesh="Right")
    assert len(faces) == 12 and vertices.mean(axis=0) == pytest.approx([5, 2, 0])
    vertices, _ = _arrays(path, submesh="Right", center_submesh=True)
    assert vertices.mean(axis=0) == pytest.approx([0, 0, 0])
    with pytest.raises(WorldError, match=r"submesh 'Top' not found .* \(it has: .*Left.*Right"):
        _arrays(path, submesh="Top")


def test_collada_primitives_gazebo_does_not_read_are_skipped(tmp_path: Path) -> None:
    # Gazebo reads <triangles> and <polylist> only; a <polygons> beside them adds nothing.
    text = _dae(f'<node id="n">{_instance()}</node>').replace(
        "</polylist>",
        '</polylist><polygons count="1"><input semantic="VERTEX" source="#cube-vtx" offset="0"/>'
        "<p>0 1 2 3</p></polygons>",
    )
    _, faces = _arrays(_mesh_file(tmp_path, text))
    assert len(faces) == 12


def test_collada_with_an_index_past_its_positions_is_refused(tmp_path: Path) -> None:
    path = _mesh_file(tmp_path, _dae(f'<node id="n">{_instance()}</node>').replace("3 0 4 7</p>", "3 0 4 99</p>"))
    with pytest.raises(WorldError, match=r"test: cannot read mesh .*part\.dae: .*indexes a position"):
        _arrays(path)


def test_obj_with_a_missing_material_library_loads_quietly(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    text = (
        "mtllib nowhere.mtl\nusemtl skin\n"
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
        "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n"
    )
    path = _mesh_file(tmp_path, text, "part.obj")
    with caplog.at_level(logging.INFO):
        vertices, faces = _arrays(path)
    assert len(faces) == 12 and vertices.max(axis=0) == pytest.approx([1, 1, 1])
    assert not [r for r in caplog.records if r.levelno >= logging.INFO]


@pytest.mark.parametrize(
    ("name", "text", "expected"),
    [
        ("notes.txt", "v 0 0 0\n", r"its format '\.txt' is no mesh format twin reads \(\.dae, .*\.stl\); export"),
        ("part", "v 0 0 0\n", r"a file without an extension is no mesh format twin reads"),
        (
            "part.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n",
            r"it is damaged or not valid OBJ \(.*\); export it again$",
        ),
    ],
)
def test_a_mesh_twin_cannot_read_is_named_with_why_and_the_fix(
    tmp_path: Path, name: str, text: str, expected: str
) -> None:
    with pytest.raises(WorldError, match=rf"^test: cannot read mesh .*{name}: {expected}") as err:
        _arrays(_mesh_file(tmp_path, text, name))
    assert "\n" not in str(err.value)
