"""Layer 2: navigation: Nav2 Humble's parts, one subpackage per Nav2 package the twin reproduces.

- `map_server` (nav2_map_server): `OccupancyMap`, `load_map`/`save_map`, `map_from_scene`, `MapServerNode`.
- `amcl` (nav2_amcl): the particle filter and likelihood field (`filter`), `AmclNode`, `InitialPoseNode`.
- `costmap_2d` (nav2_costmap_2d): the `CostGrid` layout and cost values (`costmap_2d`), the layered
  costmap with its static, obstacle and inflation layers (`layered_costmap`), the footprint and its
  collision check (`footprint`), `CostmapNode`.
- `planner` (nav2_planner + nav2_navfn_planner): `NavfnPlanner` (`navfn`), `PlannerServer` and its node.
- `controller` (nav2_controller): `ControllerServer` and its node, the goal and progress checkers,
  DWB (`controller.dwb`: trajectory generator, critics, local planner, its C kernel) and Regulated
  Pure Pursuit (`regulated_pure_pursuit`).
- `velocity_smoother` (nav2_velocity_smoother), `smoother` (nav2_smoother's SimpleSmoother).
- `behaviors` (nav2_behaviors): Spin, BackUp, DriveOnHeading, Wait and `BehaviorServer`.
- `bt_navigator` (nav2_bt_navigator + nav2_behavior_tree): Nav2's BT control nodes and leaves,
  `nav2_factory`, the servers as the leaves reach them (`Nav2Servers`), `BtNavigator` and its node.
- Shared: `frames` (the transforms the nodes look up, the laser's mount), `params` (reading a Nav2
  params file), `server_params` (the servers' sections of it), `actions` (a goal's state and result).

Each part's C kernel sits beside the Python that calls it. The package and its subpackages import
nothing themselves, so a command that needs one part (e.g. `twin map`) loads only that part.
"""

__all__: list[str] = []
