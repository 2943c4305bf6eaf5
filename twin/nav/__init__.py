"""Layer 2: navigation: the grid of the world's obstacles, a global planner, and a navigator for GoToPose.

A stand-in for Nav2 until localisation, costmaps and a local controller land: it plans on the
static world and follows the plan on the robot's odometry.
"""

from twin.nav.grid import NavGrid, build_grid
from twin.nav.navigator import GridNavigator
from twin.nav.planner import GridPlanner

__all__ = ["GridNavigator", "GridPlanner", "NavGrid", "build_grid"]
