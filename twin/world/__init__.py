"""Layer 1: SDF worlds and models, the robot read from its SDF, and the Scene it moves and scans in.

Entry points: `load_world`, `load_model`, `load_robot` (a `RobotModelSpec`), `build_scene`
(a `Scene`: ray casting and collision) and `urdf_from_robot`; `ObstacleField` holds obstacles
that appear, vanish and move (`twin.world.obstacles`). The dataclasses live in
`twin.world.types`, `twin.world.robot_model`, `twin.world.scene` and `twin.world.obstacles`.
"""

from twin.world.obstacles import ObstacleField, ObstacleSpec
from twin.world.robot_model import RobotModelSpec, load_robot
from twin.world.scene import Scene, build_scene
from twin.world.sdf import load_model, load_world
from twin.world.types import Model, World
from twin.world.urdf import urdf_from_robot

__all__ = [
    "Model",
    "ObstacleField",
    "ObstacleSpec",
    "RobotModelSpec",
    "Scene",
    "World",
    "build_scene",
    "load_model",
    "load_robot",
    "load_world",
    "urdf_from_robot",
]
