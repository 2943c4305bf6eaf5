"""Layer 2: navigation: Nav2 Humble's parts, and the older grid stand-in for GoToPose.

Nav2's components, pure and array-based, for the node graph to wire: `NavfnPlanner` (navfn),
`DwbController` and `RppController` behind `FollowPathTask` (controller_server's cycle, with the
goal and progress checkers; `controller_for_plugin`), `VelocitySmoother`, the behaviours
(`twin.nav.behaviors`), and Nav2's BT nodes (`nav2_factory`, leaves calling `NavigationServices`).
The grid stand-in (`GridNavigator`, `GridPlanner`) plans on the static world and follows on odometry.
"""

from twin.nav.bt_leaves import NavigationServices
from twin.nav.bt_nodes import nav2_factory
from twin.nav.controller import FollowPathTask, controller_for_plugin
from twin.nav.dwb import DwbController
from twin.nav.grid import NavGrid, build_grid
from twin.nav.navfn import NavfnPlanner
from twin.nav.navigator import GridNavigator
from twin.nav.planner import GridPlanner
from twin.nav.rpp import RppController
from twin.nav.smoother import VelocitySmoother

__all__ = [
    "DwbController",
    "FollowPathTask",
    "GridNavigator",
    "GridPlanner",
    "NavGrid",
    "NavfnPlanner",
    "NavigationServices",
    "RppController",
    "VelocitySmoother",
    "build_grid",
    "controller_for_plugin",
    "nav2_factory",
]
