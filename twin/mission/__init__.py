"""Layer 2: the mission: the thesis's and the behaviour demos' BT nodes, and what runs them.

- `bt_nodes`: `SetLocations`, `GetLocationFromQueue`, `GoToPose` (the thesis's mission nodes),
  registered into the engine's factory by `register_mission_nodes`, as Nav2's leaves are by
  `twin.nav.bt_navigator.factory`; the engine (`twin.bt`) knows neither.
- `navigate_to_pose`: `Nav2Navigator`, GoToPose's NavigateToPose client on Nav2's bt_navigator.
- `mission_node`: `MissionNode`, the thesis's autonomy node (ticks the tree, commands the robot).
- `path_follower`: the go-to-point follower of the `waypoints` mission (the twin's own, not Nav2's).

The package imports nothing itself; import the module you need.
"""

__all__: list[str] = []
