from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from twin.nav.costmap_2d.costmap_2d import LETHAL_OBSTACLE, NO_INFORMATION
from twin.nav.costmap_2d.footprint import footprint_radii
from twin.nav.costmap_2d.layered_costmap import Costmap, Observation, _bresenham, scan_observation
from twin.nav.map_server.map_io import OccupancyMap, load_map
from twin.nav.params import CostmapParams, default_params_path, load_nav2_params
from twin.robot.lidar import Lidar
from twin.world import build_scene, load_robot, load_world

REPO = Path(__file__).resolve().parents[4]


def _tb3() -> tuple[CostmapParams, CostmapParams]:
    params = load_nav2_params(default_params_path("waffle"))
    return params.global_costmap, params.local_costmap


def _nav2_cost(d_cells: float, res: float, inscribed: float, k: float, radius_cells: int) -> int:
    """InflationLayer::computeCost, written out for one cell."""
    if d_cells > radius_cells:
        return 0
    if d_cells == 0:
        return 254
    if d_cells * res <= inscribed:
        return 253
    return int(252 * math.exp(-k * (d_cells * res - inscribed)))


def test_inscribed_radius_is_the_padded_footprints() -> None:
    glob, _ = _tb3()
    square = dataclasses.replace(glob, footprint=((0.2, 0.15), (0.2, -0.15), (-0.2, -0.15), (-0.2, 0.15)))
    inscribed, circumscribed, _ = footprint_radii(square)
    assert inscribed == pytest.approx(0.16) and circumscribed == pytest.approx(math.hypot(0.21, 0.16))
    # robot_radius 0.22: Nav2's 16-gon of that radius, padded 0.01 along x and y
    inscribed, _, padded = footprint_radii(glob)
    assert len(padded) == 16 and 0.22 * math.cos(math.pi / 16) < inscribed < 0.22 + 0.01 * math.sqrt(2)


def test_global_costs_equal_nav2s_formula_cell_by_cell_on_a_synthetic_map() -> None:
    glob, _ = _tb3()
    data = np.zeros((60, 80), dtype=np.int8)
    data[10, 5:40] = 100  # a wall
    data[30:34, 50:53] = 100  # a block
    data[45, 70] = 100  # a post
    data[50:60, 0:20] = -1  # unknown
    occupancy = OccupancyMap(resolution_m=0.05, origin_x_m=-1.0, origin_y_m=2.0, data=data)
    costmap = Costmap(glob, static_map=occupancy)
    costmap.update(0.0, 3.0, 0.0)
    grid = costmap.grid
    assert (grid.rows, grid.cols, grid.origin_x_m, grid.origin_y_m) == (60, 80, -1.0, 2.0)
    inflation = glob.inflation
    assert inflation is not None
    radius_cells = math.ceil(inflation.inflation_radius_m / 0.05)
    lethal = np.argwhere(data == 100)
    for (row, col), got in np.ndenumerate(grid.cost):
        d = float(np.min(np.hypot(lethal[:, 0] - row, lethal[:, 1] - col)))
        cost = _nav2_cost(d, 0.05, costmap.inscribed_radius_m, inflation.cost_scaling_factor, radius_cells)
        # an unknown cell keeps NO_INFORMATION unless inflation reaches inscribed cost
        expected = (cost if cost >= 253 else NO_INFORMATION) if data[row, col] == -1 else cost
        assert got == expected, (row, col, d)
    assert {0, 253, 254, 255} <= set(np.unique(grid.cost).tolist())
    assert len(set(np.unique(grid.cost).tolist()) - {0, 253, 254, 255}) > 5  # a real gradient


def test_published_values_use_nav2s_0_to_100_scaling() -> None:
    glob, _ = _tb3()
    data = np.zeros((20, 20), dtype=np.int8)
    data[10, 10] = 100
    data[0, 0] = -1
    costmap = Costmap(glob, static_map=OccupancyMap(resolution_m=0.05, origin_x_m=0.0, origin_y_m=0.0, data=data))
    costmap.update(0.7, 0.7, 0.0)  # the footprint clears its own cells, so keep it off the unknown corner
    values = costmap.grid.occupancy_values().reshape(20, 20)
    assert values[10, 10] == 100 and values[0, 0] == -1 and values[10, 11] == 99
    mid = costmap.grid.cost == 100
    assert np.all(values[mid] == 1 + (97 * 99) // 251)


def test_the_tb3_world_map_makes_a_global_costmap_of_its_size(fixtures: Path) -> None:
    glob, _ = _tb3()
    occupancy = load_map(fixtures / "nav2/turtlebot3_navigation2_humble/map/map.yaml")
    costmap = Costmap(glob, static_map=occupancy)
    costmap.update(-2.0, -0.5, 0.0)
    assert costmap.grid.cost.shape == (384, 384) and costmap.grid.frame_id == "map"
    assert np.array_equal(costmap.grid.cost == LETHAL_OBSTACLE, occupancy.data == 100)
    assert costmap.grid.cost_at(-2.0, -0.5) < 253  # the thesis's start is not in collision


def _nav2_raytrace(x0: int, y0: int, x1: int, y1: int, max_length: float) -> list[tuple[int, int]]:
    """Costmap2D::raytraceLine for one ray, step by step (min_length 0)."""
    dx, dy = x1 - x0, y1 - y0
    dist = math.hypot(dx, dy)
    scale = 1.0 if dist == 0.0 else min(1.0, max_length / dist)
    sx, sy = (dx > 0) - (dx < 0), (dy > 0) - (dy < 0)
    cells = []
    x, y = x0, y0
    if abs(dx) >= abs(dy):
        da, db, error = abs(dx), abs(dy), abs(dx) // 2
        for _ in range(min(int(scale * da), da)):
            cells.append((y, x))
            x += sx
            error += db
            if error >= da:
                y += sy
                error -= da
    else:
        da, db, error = abs(dy), abs(dx), abs(dy) // 2
        for _ in range(min(int(scale * da), da)):
            cells.append((y, x))
            y += sy
            error += db
            if error >= da:
                x += sx
                error -= da
    cells.append((y, x))
    return cells


def test_ray_tracing_visits_the_cells_nav2s_bresenham_visits() -> None:
    rng = np.random.default_rng(4)
    x1 = rng.integers(0, 120, 300)
    y1 = rng.integers(0, 120, 300)
    rows, cols = _bresenham(60, 55, x1, y1, max_cells=40, min_cells=0)
    got = sorted(set(zip(rows.tolist(), cols.tolist(), strict=True)))
    expected = sorted(
        {cell for a, b in zip(x1, y1, strict=True) for cell in _nav2_raytrace(60, 55, int(a), int(b), 40)}
    )
    assert got == expected


def _room(tmp_path: Path, box: bool) -> Lidar:
    walls = ""
    for name, (x, y, sx, sy) in {
        "n": (0, 2.5, 5.2, 0.1), "s": (0, -2.5, 5.2, 0.1), "e": (2.5, 0, 0.1, 5.2), "w": (-2.5, 0, 0.1, 5.2)
    }.items():  # fmt: skip
        walls += (
            f'<model name="{name}"><static>1</static><pose>{x} {y} 0.5 0 0 0</pose><link name="l"><collision name="c">'
            f"<geometry><box><size>{sx} {sy} 1</size></box></geometry></collision></link></model>"
        )
    if box:
        walls += (
            '<model name="box"><static>1</static><pose>1.0 0.3 0.25 0 0 0</pose><link name="l"><collision name="c">'
            "<geometry><box><size>0.3 0.3 0.5</size></box></geometry></collision></link></model>"
        )
    path = tmp_path / f"room{int(box)}.sdf"
    path.write_text(f'<sdf version="1.7"><world name="w">{walls}</world></sdf>')
    robot = load_robot("turtlebot3_waffle", model_path=[REPO / "sdf" / "models"])
    spec = robot.lidar
    assert spec is not None
    return Lidar.from_robot(robot, build_scene(load_world(path)), spec=dataclasses.replace(spec, noise_std_m=0.0))


def _observe(lidar: Lidar, x: float, y: float, yaw: float) -> Observation:
    spec = lidar.spec
    c, s = math.cos(yaw), math.sin(yaw)
    return scan_observation(
        lidar.scan(x, y, yaw),
        angle_min_rad=spec.angle_min_rad,
        angle_increment_rad=spec.angle_increment_rad,
        range_min_m=spec.range_min_m,
        range_max_m=spec.range_max_m,
        sensor_x_m=x + c * spec.mount.x_m - s * spec.mount.y_m,
        sensor_y_m=y + s * spec.mount.x_m + c * spec.mount.y_m,
        sensor_yaw_rad=yaw + spec.mount.yaw_rad,
    )


def _box_marked(costmap: Costmap) -> bool:
    """Whether a lethal cell lies on the box's face towards the robot (x 0.85, y 0.15..0.45)."""
    grid = costmap.grid
    cells = [grid.world_to_cell(x, y) for x in (0.82, 0.87) for y in np.arange(0.17, 0.45, 0.05)]
    return any(cell is not None and grid.cost[cell] == LETHAL_OBSTACLE for cell in cells)


def test_a_box_in_the_scan_is_marked_and_cleared_once_removed(tmp_path: Path) -> None:
    _, local = _tb3()
    with_box, without_box = _room(tmp_path, True), _room(tmp_path, False)
    costmap = Costmap(local, robot_xy_m=(0.0, 0.0))
    grid = costmap.grid
    assert (grid.rows, grid.cols, grid.frame_id) == (60, 60, "odom")
    costmap.update(0.0, 0.0, 0.0, [_observe(with_box, 0.0, 0.0, 0.0)])
    assert _box_marked(costmap)
    assert grid.cost_at(0.7, 0.3) >= 253  # inflated in front of it
    costmap.update(0.0, 0.0, 0.0, [_observe(without_box, 0.0, 0.0, 0.0)])
    assert not _box_marked(costmap) and grid.cost_at(0.7, 0.3) == 0
    assert not (grid.cost == LETHAL_OBSTACLE).any()  # the walls lie outside the 3 m window


def test_the_local_window_rolls_with_the_robot_and_keeps_what_it_saw(tmp_path: Path) -> None:
    _, local = _tb3()
    with_box = _room(tmp_path, True)
    costmap = Costmap(local, robot_xy_m=(0.0, 0.0))
    costmap.update(0.0, 0.0, 0.0, [_observe(with_box, 0.0, 0.0, 0.0)])
    costmap.update(-0.4, -0.3, 0.0, [])
    grid = costmap.grid
    # recentred in whole cells (Nav2 truncates the cell shift towards zero, so within one cell)
    for origin, centred, start in ((grid.origin_x_m, -1.9, -1.5), (grid.origin_y_m, -1.8, -1.5)):
        assert abs(origin - centred) <= 0.05 + 1e-9 and origin != start
        assert (origin - start) / 0.05 == pytest.approx(round((origin - start) / 0.05))
    assert _box_marked(costmap)


def test_clear_entirely_and_clear_around_robot_reset_the_obstacle_layer(tmp_path: Path) -> None:
    glob, _ = _tb3()
    with_box = _room(tmp_path, True)
    data = np.zeros((120, 120), dtype=np.int8)
    data[0, :] = 100
    occupancy = OccupancyMap(resolution_m=0.05, origin_x_m=-3.0, origin_y_m=-3.0, data=data)
    costmap = Costmap(glob, static_map=occupancy)
    observation = _observe(with_box, 0.0, 0.0, 0.0)
    costmap.update(0.0, 0.0, 0.0, [observation])
    assert _box_marked(costmap)
    costmap.clear_around_robot(0.0, 0.0, 1.0)  # the box is 0.85 m away: outside the 1 m square
    costmap.update(0.0, 0.0, 0.0)
    assert _box_marked(costmap)
    costmap.clear_around_robot(0.0, 0.0, 2.0)
    costmap.update(0.0, 0.0, 0.0)
    assert not _box_marked(costmap)
    costmap.update(0.0, 0.0, 0.0, [observation])
    assert _box_marked(costmap)
    costmap.clear_entirely()
    costmap.update(0.0, 0.0, 0.0)
    assert not _box_marked(costmap)
    assert costmap.grid.cost_at(0.0, -2.98) == LETHAL_OBSTACLE  # the static map stays


def test_a_partial_update_equals_a_full_rebuild(tmp_path: Path) -> None:
    glob, _ = _tb3()
    with_box, without_box = _room(tmp_path, True), _room(tmp_path, False)
    data = np.full((140, 140), -1, dtype=np.int8)
    data[20:120, 20:120] = 0
    data[30, 30:110] = 100
    occupancy = OccupancyMap(resolution_m=0.05, origin_x_m=-3.5, origin_y_m=-3.5, data=data)
    costmap = Costmap(glob, static_map=occupancy)
    poses = [(0.0, 0.0, 0.0), (0.3, -0.2, 0.5), (-0.5, 0.4, 2.0), (0.2, 0.1, -1.0)]
    for k, pose in enumerate(poses):
        lidar = with_box if k % 2 == 0 else without_box
        costmap.update(*pose, [_observe(lidar, *pose)])
        partial = costmap.grid.cost.copy()
        costmap._full_update = True  # rebuild the whole master from the layers
        costmap.update(*pose)
        assert np.array_equal(partial, costmap.grid.cost)


def test_the_c_kernel_and_numpy_clear_the_same_cells(tmp_path: Path) -> None:
    glob, local = _tb3()
    with_box, without_box = _room(tmp_path, True), _room(tmp_path, False)
    data = np.zeros((140, 140), dtype=np.int8)
    occupancy = OccupancyMap(resolution_m=0.05, origin_x_m=-3.5, origin_y_m=-3.5, data=data)
    for params, static in ((glob, occupancy), (local, None)):
        native = Costmap(params, static_map=static, native=True)
        numpy_only = Costmap(params, static_map=static, native=False)
        assert native._lib is not None and numpy_only._lib is None
        for k, pose in enumerate([(0.0, 0.0, 0.0), (0.4, -0.3, 1.0), (-0.6, 0.5, 2.5)]):
            observation = _observe(with_box if k != 1 else without_box, *pose)
            native.update(*pose, [observation])
            numpy_only.update(*pose, [observation])
            assert np.array_equal(native.grid.cost, numpy_only.grid.cost)


@pytest.mark.parametrize(
    ("inflate_unknown", "around_unknown", "resolution_m"),
    [(False, False, 0.05), (True, False, 0.05), (False, True, 0.05), (True, True, 0.005)],
    ids=["tb3", "inflate_unknown", "inflate_around_unknown", "radius_over_127_cells"],
)
def test_the_c_kernel_and_numpy_compose_and_inflate_alike(
    tmp_path: Path, inflate_unknown: bool, around_unknown: bool, resolution_m: float
) -> None:
    # a static map with unknown space, a wall and posts, seen by a scan and updated partially
    glob, _ = _tb3()
    assert glob.inflation is not None
    inflation = dataclasses.replace(
        glob.inflation, inflate_unknown=inflate_unknown, inflate_around_unknown=around_unknown
    )
    params = dataclasses.replace(glob, inflation=inflation)
    cells = round(5.0 / resolution_m) if resolution_m >= 0.05 else 400
    rng = np.random.default_rng(7)
    data = np.zeros((cells, cells), dtype=np.int8)
    data[rng.integers(0, cells, 6), rng.integers(0, cells, 6)] = 100  # posts
    data[: cells // 5, :] = -1
    data[cells // 2, cells // 4 : cells // 2] = 100
    span_m = cells * resolution_m
    occupancy = OccupancyMap(resolution_m=resolution_m, origin_x_m=-span_m / 2, origin_y_m=-span_m / 2, data=data)
    native = Costmap(params, static_map=occupancy, native=True)
    numpy_only = Costmap(params, static_map=occupancy, native=False)
    lidar = _room(tmp_path, True)
    for pose in [(0.0, 0.0, 0.0), (0.2, -0.3, 1.0), (-0.4, 0.5, 2.5)]:
        observation = _observe(lidar, *pose)
        native.update(*pose, [observation])
        numpy_only.update(*pose, [observation])
        assert np.array_equal(native.grid.cost, numpy_only.grid.cost)
    costs = set(np.unique(native.grid.cost).tolist())
    assert {0, 253, 254} <= costs and len(costs) > 10  # free, a gradient of inflated costs, lethal


@pytest.mark.parametrize("native", [True, False], ids=["native", "python"])
def test_tb3s_voxel_layer_keeps_a_mark_its_shorter_rays_do_not_reach(native: bool) -> None:
    """TB3 runs an obstacle layer and a voxel layer on the scan; the voxel layer stops clearing 2 cells short.

    An obstacle seen at 1.0 m that moves 5 cm further away: the obstacle layer's ray clears its old
    cell, the voxel layer's does not, and the master (their maximum) still holds it, as in Nav2.
    """
    _, local = _tb3()
    assert [layer.voxel for layer in local.obstacle_layers] == [False, True]
    costmap = Costmap(local, robot_xy_m=(0.0, 0.0), native=native)
    (obstacle, _), (voxel, columns) = costmap.layer_grids
    assert columns is not None and (columns == 0xFFFF).all()  # every voxel unknown to start

    def scan_at(x_m: float) -> list[Observation]:
        points = np.array([[x_m, 0.026, 0.132]])
        return [Observation(origin_x_m=0.001, origin_y_m=0.026, origin_z_m=0.132, points_xy_m=points)]

    costmap.update(0.0, 0.0, 0.0, scan_at(1.0))
    old = costmap.grid.world_to_cell(1.0, 0.026)
    assert old is not None and costmap.grid.cost[old] == LETHAL_OBSTACLE
    costmap.update(0.0, 0.0, 0.0, scan_at(1.05))
    assert obstacle[old] == 0 and voxel[old] == LETHAL_OBSTACLE
    assert costmap.grid.cost[old] == LETHAL_OBSTACLE
    costmap.update(0.0, 0.0, 0.0, scan_at(1.3))  # 6 cells further: now the voxel layer's ray clears it too
    assert voxel[old] == 0 and costmap.grid.cost[old] < LETHAL_OBSTACLE


def test_the_obstacle_layer_marks_by_whole_cells_as_nav2() -> None:
    """Nav2 marks a point whose cell lies within cellDistance(obstacle_max_range) = 50 cells of the sensor's."""
    _, local = _tb3()
    params = dataclasses.replace(
        local, rolling_window=False, width_m=8.0, height_m=8.0, origin_x_m=-4.0, origin_y_m=-4.0,
        obstacle_layers=local.obstacle_layers[:1],
    )  # fmt: skip
    costmap = Costmap(params)
    # the sensor in cell 80; 2.52 m on lies in cell 130 (50 cells on: marked, though past 2.5 m),
    # 2.57 m on in cell 131 (51: not)
    points = np.array([[0.001 + 2.52, 0.001, 0.132], [0.001, 0.001 + 2.57, 0.132]])
    observation = Observation(origin_x_m=0.001, origin_y_m=0.001, origin_z_m=0.132, points_xy_m=points)
    costmap.update_layers(0.0, 0.0, 0.0, [observation])
    (cost, _), *_ = costmap.layer_grids
    near, far = (costmap.grid.world_to_cell(float(x), float(y)) for x, y, _ in points)
    assert near == (80, 130) and far == (131, 80)
    assert cost[near] == LETHAL_OBSTACLE and cost[far] != LETHAL_OBSTACLE
