from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy import ndimage

from tests.conftest import REPO, run_twin
from twin.core.errors import ConfigError
from twin.nav.map_server.map_io import OccupancyMap, load_map, map_from_scene, save_map
from twin.world import build_scene, load_world

TB3_MAP = "nav2/turtlebot3_navigation2_humble/map/map.yaml"


def test_the_turtlebot3_world_slam_map_loads_as_map_server_gives_it(fixtures: Path) -> None:
    occupancy = load_map(fixtures / TB3_MAP)
    assert (occupancy.width, occupancy.height, occupancy.resolution_m) == (384, 384, 0.05)
    assert (occupancy.origin_x_m, occupancy.origin_y_m) == (-10.0, -10.0)
    pixels = np.asarray(Image.open(fixtures / TB3_MAP.replace("yaml", "pgm")), dtype=np.float64)
    occ = 1.0 - pixels / 255.0
    expected = np.where(occ > 0.65, 100, np.where(occ < 0.196, 0, -1))[::-1]
    assert np.array_equal(occupancy.data, expected)
    assert set(np.unique(occupancy.data)) == {-1, 0, 100}
    assert occupancy.occupancy_values().shape == (384 * 384,)


def _write(tmp_path: Path, pixels: np.ndarray, **keys: object) -> Path:
    Image.fromarray(pixels).save(tmp_path / "m.png")
    doc = {"image": "m.png", "resolution": 0.1, "origin": [1.0, 2.0, 0.0], "negate": 0}
    doc |= {"occupied_thresh": 0.65, "free_thresh": 0.196} | keys  # (map_server requires all three)
    (tmp_path / "m.yaml").write_text("\n".join(f"{k}: {v}" for k, v in doc.items()))
    return tmp_path / "m.yaml"


def test_modes_negate_and_row_order(tmp_path: Path) -> None:
    # top image row = last map row; shades 0 (black), 100, 128, 200, 255 (white)
    pixels = np.array([[0, 100, 128, 200, 255], [255, 255, 255, 255, 0]], dtype=np.uint8)
    tri = load_map(_write(tmp_path, pixels, occupied_thresh=0.65, free_thresh=0.25))
    assert tri.data[1].tolist() == [100, -1, -1, 0, 0] and tri.data[0].tolist() == [0, 0, 0, 0, 100]
    neg = load_map(_write(tmp_path, pixels, negate=1, occupied_thresh=0.65, free_thresh=0.25))
    assert neg.data[1].tolist() == [0, -1, -1, 100, 100]
    scale = load_map(_write(tmp_path, pixels, mode="scale", occupied_thresh=0.65, free_thresh=0.25))
    occ = 1.0 - np.array([100, 128]) / 255.0
    assert scale.data[1, 1:3].tolist() == np.rint((occ - 0.25) / 0.4 * 100).astype(int).tolist()
    raw = load_map(_write(tmp_path, np.array([[0, 50, 100, 101, 255]], dtype=np.uint8), mode="raw"))
    assert raw.data[0].tolist() == [0, 50, 100, -1, -1]


@pytest.mark.parametrize("image_mode", ["RGBA", "LA"])
def test_trinary_averages_the_alpha_in_as_map_server_does(tmp_path: Path, image_mode: str) -> None:
    # map_server (Humble): the mean of R, G, B and MaxRGB - alphaQuantum(), GraphicsMagick's opacity
    # (0: opaque): the alpha itself. An opaque white cell is free, as in the RGB image (it was unknown).
    grey = np.array([[0, 60, 100, 200, 255, 255, 255]], dtype=np.uint8)
    alpha = np.array([[255, 255, 255, 255, 255, 128, 0]], dtype=np.uint8)
    planes = [grey, grey, grey, alpha] if image_mode == "RGBA" else [grey, alpha]
    Image.fromarray(np.dstack(planes), mode=image_mode).save(tmp_path / "m.png")
    (tmp_path / "m.yaml").write_text(
        "image: m.png\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n"
    )
    occ = 1.0 - (3.0 * grey[0] + alpha[0]) / 4.0 / 255.0
    expected = np.where(occ > 0.65, 100, np.where(occ < 0.25, 0, -1))
    assert load_map(tmp_path / "m.yaml").data[0].tolist() == expected.tolist()
    assert expected.tolist() == [100, -1, -1, 0, 0, 0, -1]  # (60 is occupied in the grey image, unknown here)


def test_save_then_load_round_trips_in_map_saver_format(tmp_path: Path) -> None:
    data = np.array([[0, 100, -1], [19, 70, 40]], dtype=np.int8)
    original = OccupancyMap(resolution_m=0.05, origin_x_m=-1.0, origin_y_m=0.5, data=data)
    image = save_map(original, tmp_path / "out" / "map.yaml")
    assert image.name == "map.pgm" and image.read_bytes().startswith(b"P5")
    pixels = np.asarray(Image.open(image))
    assert pixels[::-1].tolist() == [[254, 0, 205], [254, 0, 205]]
    back = load_map(tmp_path / "out" / "map.yaml")
    assert back.data.tolist() == [[0, 100, -1], [0, 100, -1]]
    assert (back.origin_x_m, back.origin_y_m, back.resolution_m) == (-1.0, 0.5, 0.05)


@pytest.mark.parametrize("damage", ["missing", "corrupt"])
def test_missing_or_corrupt_image_is_one_line_exit_2(tmp_path: Path, damage: str) -> None:
    (tmp_path / "map.yaml").write_text(
        "image: map.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n"
    )
    if damage == "corrupt":
        (tmp_path / "map.pgm").write_bytes(b"P5\n10 10\n255\n\x00\x01")
    with pytest.raises(ConfigError, match=r"map\.yaml: map image .*map\.pgm") as info:
        load_map(tmp_path / "map.yaml")
    assert "\n" not in str(info.value) and ConfigError.exit_code == 2


def _world_map(fixtures: Path) -> OccupancyMap:
    world = load_world(
        fixtures / "gazebo_classic/worlds/turtlebot3_world.world", model_path=[fixtures / "gazebo_classic/models"]
    )
    return map_from_scene(build_scene(world), height_m=0.132)


def _on_grid(small: OccupancyMap, big: OccupancyMap) -> np.ndarray:
    out = np.zeros(big.data.shape, dtype=bool)
    c = round((small.origin_x_m - big.origin_x_m) / big.resolution_m)
    r = round((small.origin_y_m - big.origin_y_m) / big.resolution_m)
    out[r : r + small.height, c : c + small.width] = small.data == 100
    return out


def test_map_from_turtlebot3_world_overlaps_the_slam_map(fixtures: Path) -> None:
    slam = load_map(fixtures / TB3_MAP)
    made = _world_map(fixtures)
    assert made.data[(round((-0.5 - made.origin_y_m) / 0.05)), round((-2.0 - made.origin_x_m) / 0.05)] == 0
    ours, theirs = _on_grid(made, slam), slam.data == 100
    near = np.ones((3, 3), dtype=bool)  # tolerance: one cell (5 cm) either way
    ours_d, theirs_d = ndimage.binary_dilation(ours, near), ndimage.binary_dilation(theirs, near)
    iou_exact = (ours & theirs).sum() / (ours | theirs).sum()
    iou_1cell = (ours_d & theirs_d).sum() / (ours_d | theirs_d).sum()
    precision = (ours & theirs_d).sum() / ours.sum()
    recall = (theirs & ours_d).sum() / theirs.sum()
    print(f"IoU exact {iou_exact:.3f}, IoU with 1-cell dilation {iou_1cell:.3f}, P {precision:.3f}, R {recall:.3f}")
    assert precision > 0.95 and recall > 0.95 and iou_1cell > 0.7
    # free space agrees in size within 5 % (the inside of the walls, nothing outside)
    assert abs(int((made.data == 0).sum()) - int((slam.data == 0).sum())) < 0.05 * (slam.data == 0).sum()


def test_twin_map_save_writes_a_map_server_map(fixtures: Path, tmp_path: Path) -> None:
    out = tmp_path / "tb3" / "map.yaml"
    done = run_twin(
        "map", "save", str(fixtures / "gazebo_classic/worlds/turtlebot3_world.world"),
        "--model-path", str(fixtures / "gazebo_classic/models"), "--out", str(out),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert load_map(out).data.tolist() == _world_map(fixtures).data.tolist()
    bad = run_twin(
        "map", "save", str(fixtures / "gazebo_classic/worlds/turtlebot3_world.world"), "--out", str(tmp_path / "x.txt")
    )
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "Traceback" not in bad.stderr


@pytest.mark.parametrize("free", [(0.0, 0.0), (4.0, 0.5)])
def test_the_free_region_and_its_walls_match_scipys_labelling(free: tuple[float, float]) -> None:
    # map_from_scene finds the robot's region with a C flood fill and grows it with numpy: the same
    # cells as scipy's connected-component labelling and 3 x 3 binary dilation
    from twin.nav.map_server import map_io

    scene = build_scene(load_world(REPO / "sdf" / "worlds" / "house.sdf", model_path=[REPO / "sdf" / "models"]))
    occupancy = map_from_scene(scene, height_m=0.17, free_xy_m=free)
    walls = map_io._rasterise(
        scene, 0.17, (occupancy.origin_x_m, occupancy.origin_y_m), occupancy.data.shape, occupancy.resolution_m
    )
    row = int((free[1] - occupancy.origin_y_m) / 0.05)
    col = int((free[0] - occupancy.origin_x_m) / 0.05)
    labels, _ = ndimage.label(~walls)
    region = labels == labels[row, col]
    assert np.array_equal(occupancy.data == 0, region)
    seen = walls & ndimage.binary_dilation(region, structure=np.ones((3, 3), dtype=bool))
    assert np.array_equal(occupancy.data == 100, seen)
    assert region.sum() > 1000 and seen.sum() > 100


def _cell(grid: OccupancyMap, x: float, y: float) -> int:
    return int(
        grid.data[int((y - grid.origin_y_m) / grid.resolution_m), int((x - grid.origin_x_m) / grid.resolution_m)]
    )


def test_an_open_world_maps_the_floor_around_a_closed_box_not_its_inside(tmp_path: Path) -> None:
    # a floor with a closed 1 m box on it and a pillar 5 m away (as gz-sim's shapes.sdf): no outer walls,
    # so the free space touches the map's border and the only enclosed region is the box's inside
    def wall(name: str, x: float, y: float, sx: float, sy: float) -> str:
        return (
            f"<model name='{name}'><static>1</static><pose>{x} {y} 0.5 0 0 0</pose><link name='l'><collision "
            f"name='c'><geometry><box><size>{sx} {sy} 1</size></box></geometry></collision></link></model>"
        )

    walls = wall("s", 0, -0.5, 1.1, 0.1) + wall("n", 0, 0.5, 1.1, 0.1) + wall("w", -0.5, 0, 0.1, 1.1)
    walls += wall("e", 0.5, 0, 0.1, 1.1) + wall("pillar", 5, 5, 0.2, 0.2)
    world = tmp_path / "open.sdf"
    world.write_text(f"<sdf version='1.7'><world name='open'>{walls}</world></sdf>")
    grid = map_from_scene(build_scene(load_world(world)), height_m=0.132)
    assert _cell(grid, 3.0, 2.0) == 0 and _cell(grid, -0.8, -0.8) == 0  # the floor around the box
    assert _cell(grid, 0.0, 0.0) == -1  # the box's inside is not where the robot drives
    assert max(_cell(grid, x, 0.0) for x in np.arange(0.4, 0.7, 0.01)) == 100  # its east wall, seen from outside


def test_a_walled_world_maps_its_inside_and_leaves_the_outside_unknown(tmp_path: Path) -> None:
    def wall(name: str, x: float, y: float, sx: float, sy: float) -> str:
        return (
            f"<model name='{name}'><static>1</static><pose>{x} {y} 0.5 0 0 0</pose><link name='l'><collision "
            f"name='c'><geometry><box><size>{sx} {sy} 1</size></box></geometry></collision></link></model>"
        )

    walls = (
        wall("s", 0, -3, 6.1, 0.1) + wall("n", 0, 3, 6.1, 0.1) + wall("w", -3, 0, 0.1, 6.1) + wall("e", 3, 0, 0.1, 6.1)
    )
    world = tmp_path / "room.sdf"
    world.write_text(f"<sdf version='1.7'><world name='room'>{walls}</world></sdf>")
    grid = map_from_scene(build_scene(load_world(world)), height_m=0.132, padding_m=3.0)
    # the ring outside the walls is larger than a quarter of the inside, yet the inside is the map
    assert _cell(grid, 0.0, 0.0) == 0 and _cell(grid, 4.5, 4.5) == -1


def test_map_save_refuses_a_missing_include_unless_told_to_skip_it_and_says_what_it_left_out(tmp_path: Path) -> None:
    # A world whose furniture is on Fuel (AWS's hospital): the map needs every wall, so the default
    # refuses in one line; --skip-missing maps what is there and names each model it left out.
    world = tmp_path / "room.world"
    world.write_text(
        "<sdf version='1.6'><world name='w'>\n<model name='walls'><static>1</static><pose>0 0 0.5 0 0 0</pose>"
        "<link name='l'><collision name='e'><pose>2 0 0 0 0 0</pose><geometry><box><size>0.2 4 1</size></box>"
        "</geometry></collision><collision name='w'><pose>-2 0 0 0 0 0</pose><geometry><box><size>0.2 4 1</size>"
        "</box></geometry></collision></link></model>\n<include><uri>model://VendingMachine</uri><pose>0 1 0 0 0 0</pose></include>\n"
        "</world></sdf>"
    )
    out = tmp_path / "map" / "map.yaml"
    refused = run_twin("map", "save", str(world), "--out", str(out), "--free", "0", "0")
    assert refused.returncode == 3 and refused.stderr.count("\n") == 1, refused.stderr
    assert f"{world}:3: <include> 'model://VendingMachine' not found" in refused.stderr
    assert "--skip-missing" in refused.stderr and not out.exists()
    done = run_twin("map", "save", str(world), "--out", str(out), "--free", "0", "0", "--skip-missing")
    assert done.returncode == 0, done.stderr
    (warning,) = [line for line in done.stderr.splitlines() if "VendingMachine" in line]
    assert f"{world}:3:" in warning and "skipped" in warning
    assert (load_map(out).data == 100).any()  # the wall is mapped


def test_map_save_warns_when_the_free_point_is_outside_the_walls(tmp_path: Path) -> None:
    # (-2, 1) is outside the house's west wall: its free space is the ring around the house.
    house = REPO / "sdf" / "worlds" / "house.sdf"
    outside = run_twin("map", "save", str(house), "--out", str(tmp_path / "a" / "map.yaml"), "--free", "-2.0", "1.0")
    assert outside.returncode == 0, outside.stderr
    assert "--free -2 1: that point's free space reaches the map's edge" in outside.stderr
    inside = run_twin("map", "save", str(house), "--out", str(tmp_path / "b" / "map.yaml"), "--free", "0", "0")
    assert inside.returncode == 0 and "map's edge" not in inside.stderr, inside.stderr
    assert (load_map(tmp_path / "b" / "map.yaml").data == 0).sum() > (
        load_map(tmp_path / "a" / "map.yaml").data == 0
    ).sum()
    # a world without outer walls: every free point's space reaches the edge, nothing to warn of
    world = tmp_path / "open.sdf"
    boxes = "".join(
        f"<model name='b{i}'><static>1</static><pose>{x} 0 0.5 0 0 0</pose><link name='l'><collision name='c'>"
        "<geometry><box><size>0.5 0.5 1</size></box></geometry></collision></link></model>"
        for i, x in enumerate((-1, 1))
    )
    world.write_text(f"<sdf version='1.6'><world name='w'>{boxes}</world></sdf>")
    open_world = run_twin("map", "save", str(world), "--out", str(tmp_path / "c" / "map.yaml"), "--free", "0", "0")
    assert open_world.returncode == 0 and "map's edge" not in open_world.stderr, open_world.stderr
